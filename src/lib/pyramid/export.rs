//! Whole levels out of pages: `--export-levels DIR` (GeoTIFFs GDAL and QGIS open) and tests.
//!
//! Invariant: a collected level holds exactly the cells of the pages given to it (padding is
//! dropped), on the level's own grid — the database's corner, cell size `c · f^N` — so the
//! GeoTIFFs line up with the database in any GIS. Memory: every level whole, 9 bytes a cell
//! (about 9.6 · W · H bytes for factor 4); only used when asked for.

use crate::error::{Error, Result};
use crate::io::geotiff;
use crate::raster::{Colour, Elevation, Raster};
use crate::tiles::{Page, TileSetInfo};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// One level as whole rasters.
#[derive(Debug, Clone, PartialEq)]
pub struct LevelRasters {
    /// Max Z, metres; NaN = nodata.
    pub max_z: Elevation,
    /// Average colour; alpha 0 = nodata.
    pub colour: Colour,
    /// Occupancy state.
    pub state: Raster<u8>,
}

/// Gathers pages (from any thread) into whole levels.
pub struct LevelCollector {
    info: TileSetInfo,
    levels: Vec<Mutex<LevelRasters>>,
}

impl LevelCollector {
    /// Empty (nodata) rasters for every level of `info`.
    pub fn new(info: &TileSetInfo) -> LevelCollector {
        let levels = (0..info.levels.len())
            .map(|k| {
                let g = info.level_grid(k);
                Mutex::new(LevelRasters {
                    max_z: Raster::filled(g.clone(), f32::NAN),
                    colour: Raster::filled(g.clone(), [0; 4]),
                    state: Raster::filled(g, 0),
                })
            })
            .collect();
        LevelCollector {
            info: info.clone(),
            levels,
        }
    }

    /// Copy page `(level, tx, ty)` into its level.
    pub fn put(&self, level: usize, tx: usize, ty: usize, page: &Page) {
        let p = self.info.page_size;
        let (cols, rows) = self.info.page_extent(level, tx, ty);
        let mut l = self.levels[level]
            .lock()
            .expect("no panics while holding the lock");
        let w = l.max_z.grid.width;
        for r in 0..rows {
            let (src, dst) = (r * p, (ty * p + r) * w + tx * p);
            l.max_z.data[dst..dst + cols].copy_from_slice(&page.max_z[src..src + cols]);
            l.colour.data[dst..dst + cols].copy_from_slice(&page.colour[src..src + cols]);
            l.state.data[dst..dst + cols].copy_from_slice(&page.state[src..src + cols]);
        }
    }

    /// The collected levels, finest first.
    pub fn into_levels(self) -> Vec<LevelRasters> {
        self.levels
            .into_iter()
            .map(|m| m.into_inner().expect("no panics while holding the lock"))
            .collect()
    }

    /// Write `level<N>_maxz.tif` (float32, nodata −9999) and `level<N>_colour.tif` (RGBA8, alpha
    /// = mask) for every level into `dir` (created if missing). Returns the files written.
    pub fn write(self, dir: &Path) -> Result<Vec<PathBuf>> {
        std::fs::create_dir_all(dir)
            .map_err(|e| Error::io(dir, e).fix("choose a writable --export-levels directory"))?;
        let mut files = Vec::new();
        for (k, l) in self.into_levels().into_iter().enumerate() {
            let (z, c) = (
                dir.join(format!("level{k}_maxz.tif")),
                dir.join(format!("level{k}_colour.tif")),
            );
            geotiff::write_f32(&z, &l.max_z)?;
            geotiff::write_rgba8(&c, &l.colour)?;
            files.extend([z, c]);
        }
        Ok(files)
    }
}
