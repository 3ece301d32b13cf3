//! A database's top surface cell by cell, as the sensor stages read it (`dbms thermal`,
//! `dbms radar`): each cell's material, terrain height, whether something stands on it, and
//! the surface's normal.
//!
//! Invariant: every vector holds one value per grid cell, row-major; a roof has its own faces'
//! normal (a pitched roof's slope, [`crate::standing::Raised::top_normal`]), a placed object's
//! top is level, and any other cell has the terrain's normal
//! ([`crate::raster::surface_normal`]).

use super::layer::{table_of, MATERIALS};
use super::table::MaterialTable;
use crate::db::{Database, LayerRows};
use crate::error::{Error, Result};
use crate::grid::Grid;
use crate::raster::{band_rows, RowSource};
use crate::standing::Standing;

/// The top surface of a database, read whole.
pub struct TopSurface {
    /// The database's material table.
    pub table: MaterialTable,
    /// The terrain layer, for the casts that read it band by band.
    pub terrain: LayerRows<f32>,
    /// Buildings and placed objects over the terrain.
    pub standing: Standing,
    /// Material id of every cell (the `materials` layer).
    pub material: Vec<u8>,
    /// Terrain height of every cell, metres; NaN nodata.
    pub heights: Vec<f32>,
    /// Whether something stands on the cell (a roof or an object's top).
    pub on_top: Vec<bool>,
}

impl TopSurface {
    /// Read `db`'s surface; one line naming the fix when it has no materials layer yet.
    pub fn read(db: &Database) -> Result<TopSurface> {
        if !db.manifest.layers.contains_key(MATERIALS) {
            return Err(Error::file(&db.dir, "has no materials layer")
                .fix("run `dbms materials --db DB` first"));
        }
        let table = table_of(db)?;
        let terrain = db.elevation_rows()?;
        let grid = terrain.grid().clone();
        let standing = Standing::read(db, &terrain, band_rows(grid.width))?;
        let material = db
            .byte_rows(MATERIALS)?
            .read_rows(0, grid.height)?
            .into_owned();
        let heights = terrain.read_rows(0, grid.height)?.into_owned();
        let mut on_top = vec![false; grid.len()];
        standing
            .all
            .cells()
            .iter()
            .for_each(|c| on_top[c.index] = true);
        Ok(TopSurface {
            table,
            terrain,
            standing,
            material,
            heights,
            on_top,
        })
    }

    /// The grid every vector lies on.
    pub fn grid(&self) -> &Grid {
        self.terrain.grid()
    }

    /// The unit upward normal `[east, north, up]` of cell `i`: a roof's face on a building,
    /// level on a placed object, the terrain's elsewhere.
    pub fn normal(&self, i: usize) -> [f64; 3] {
        let s = &self.standing;
        match self.on_top[i] {
            true if s.objects.contains(i) => [0.0, 0.0, 1.0],
            true => s.buildings.top_normal(self.grid(), i),
            false => crate::raster::surface_normal(&self.heights, self.grid(), i),
        }
    }
}
