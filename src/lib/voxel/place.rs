//! Placing a voxel object in a database (`dbms place`).
//!
//! # Rules
//! * The object's **anchor** (centre of the bottom face of its grid, [`VoxelObject::anchor`])
//!   goes to world `(x, y, z)`; the object turns about the vertical through the anchor by
//!   `heading` degrees clockwise seen from above (0 = the object's +y stays north).
//! * `z` is the given absolute height, or else the terrain height at `(x, y)`: bilinear between
//!   the four nearest elevation cell centres (clamped at the grid edge); nodata there is an error.
//! * A given `z` must lie within [`Z_MARGIN_M`] of the terrain's range (its lowest and highest
//!   valid cell): room for any structure on a roof or a bridge, or sunk in a pit, while a unit
//!   slip or a missing decimal point (`1e8`) is refused before anything is written. Heights are
//!   `f32` in the tile set; far from the terrain they would lose the voxels' resolution.
//! * The object file is copied into `DB/objects/` under a content-addressed name
//!   (`<stem>-<first 12 hex of its SHA-256>.dvox`), so placing one tree many times stores it once,
//!   and the placement is appended to the manifest's `objects` with a `place` stage record.

use super::format;
use super::object::VoxelObject;
use crate::db::{sha256_file, Database, PlacedObject, Stage};
use crate::error::{Error, Result};
use crate::raster::{Elevation, RowSource};
use std::path::Path;

/// How far (metres) a placement's given height may lie below the lowest or above the highest
/// terrain of the database: a kilometre, more than any structure is tall.
pub const Z_MARGIN_M: f64 = 1000.0;

/// Terrain height (metres) at world `(x, y)`, bilinear on cell centres; `None` outside the grid
/// or where a contributing cell is nodata.
pub fn ground_height(dem: &Elevation, x: f64, y: f64) -> Option<f64> {
    let g = &dem.grid;
    g.cell_at(x, y)?;
    let (cx, cy) = g.world_to_centre_space(x, y);
    let (w, h) = (g.width as f64, g.height as f64);
    let (cx, cy) = (cx.clamp(0.0, w - 1.0), cy.clamp(0.0, h - 1.0));
    let (c0, r0) = (cx.floor() as usize, cy.floor() as usize);
    let (c1, r1) = ((c0 + 1).min(g.width - 1), (r0 + 1).min(g.height - 1));
    let (fx, fy) = (cx - c0 as f64, cy - r0 as f64);
    let v = |c: usize, r: usize| *dem.get(c, r) as f64;
    let z = (v(c0, r0) * (1.0 - fx) + v(c1, r0) * fx) * (1.0 - fy)
        + (v(c0, r1) * (1.0 - fx) + v(c1, r1) * fx) * fy;
    (!z.is_nan()).then_some(z)
}

/// Place the object at `object_path` in the database in `dir` with its anchor at `(x, y)` and
/// height `z` (absolute metres, or the ground's when `None`), turned by `heading_deg`: one
/// change under the database's lock (waiting up to `wait` for it), so placements made at the
/// same time are all kept.
pub fn place(
    dir: &Path,
    wait: std::time::Duration,
    object_path: &Path,
    x: f64,
    y: f64,
    z: Option<f64>,
    heading_deg: f64,
) -> Result<PlacedObject> {
    if !(x.is_finite() && y.is_finite() && z.is_none_or(f64::is_finite) && heading_deg.is_finite())
    {
        return Err(Error::msg("--at and --heading must be finite numbers")
            .fix("e.g. --at 500120.5,5000340,0 --heading 30"));
    }
    let mut change = Database::begin(dir, wait)?;
    let db = &mut change.db;
    if db.grid().crs.geographic {
        return Err(Error::file(
            &db.dir,
            "the database is in geographic coordinates (degrees) but voxel objects are in metres",
        )
        .fix("ingest onto a projected CRS (e.g. UTM)"));
    }
    // Read (and so check) the object before touching the database.
    let (obj, _): (VoxelObject, _) = format::read(object_path)?;
    if db.grid().cell_at(x, y).is_none() {
        let b = db.grid().bounds();
        return Err(Error::msg(format!(
            "--at {x},{y} is outside the database extent [{}, {}, {}, {}]",
            b.min_x, b.min_y, b.max_x, b.max_y
        ))
        .fix("give a position inside the database"));
    }
    let z = match z {
        Some(z) => require_near_terrain(db, z)?,
        None => ground_height(&db.read_elevation()?, x, y).ok_or_else(|| {
            Error::file(&db.dir, format!("no terrain height at {x},{y} (nodata)"))
                .fix("give the height as --at X,Y,Z")
        })?,
    };
    let sha256 = sha256_file(object_path)?;
    let stem = object_path
        .file_stem()
        .and_then(|s| s.to_str())
        .unwrap_or("object");
    let file = format!("objects/{stem}-{}.dvox", &sha256[..12]);
    let dest = db.dir.join(&file);
    if !dest.exists() {
        let dir = db.dir.join("objects");
        std::fs::create_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
        let bytes = std::fs::read(object_path).map_err(|e| Error::io(object_path, e))?;
        crate::io::atomic::write_bytes_atomic(&dest, &bytes)?;
        change.wrote(&file);
    }
    let db = &mut change.db;
    let placed = PlacedObject {
        file,
        sha256,
        x,
        y,
        z,
        heading_deg: heading_deg.rem_euclid(360.0),
    };
    db.manifest.objects.push(placed.clone());
    db.record_stage(Stage::now(
        "place",
        serde_json::json!({ "object": placed.file, "x": x, "y": y, "z": z, "heading_deg": placed.heading_deg, "voxels": obj.len() }),
    ));
    change.commit()?;
    Ok(placed)
}

/// `z` (absolute metres), when within [`Z_MARGIN_M`] of the terrain's range in `db`.
fn require_near_terrain(db: &Database, z: f64) -> Result<f64> {
    let rows = db.elevation_rows()?;
    let (w, h) = (db.grid().width, db.grid().height);
    let band = ((1 << 22) / w.max(1)).max(1);
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for r0 in (0..h).step_by(band) {
        for &v in rows.read_rows(r0, band.min(h - r0))?.iter() {
            if !v.is_nan() {
                lo = lo.min(v as f64);
                hi = hi.max(v as f64);
            }
        }
    }
    if lo - Z_MARGIN_M <= z && z <= hi + Z_MARGIN_M {
        return Ok(z);
    }
    Err(Error::msg(format!(
        "--at height {z} m is more than {Z_MARGIN_M} m outside the terrain's range, {lo} to {hi} m"
    ))
    .fix("give Z in metres on the elevation layer's datum, or leave it out to stand the object on the ground"))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::crs::Crs;
    use crate::grid::Grid;

    #[test]
    fn ground_height_is_bilinear_between_centres() {
        // 3×2 cells of 10 m; values rise 1 m per cell east and 10 m per cell south.
        let g = Grid::north_up(1000.0, 2000.0, 10.0, 3, 2, Crs::epsg(32632));
        let dem = Elevation::new(g, vec![0.0, 1.0, 2.0, 10.0, 11.0, 12.0]);
        assert_eq!(ground_height(&dem, 1005.0, 1995.0), Some(0.0));
        assert!((ground_height(&dem, 1010.0, 1990.0).unwrap() - 5.5).abs() < 1e-9);
        assert_eq!(
            ground_height(&dem, 1001.0, 1999.0),
            Some(0.0),
            "clamped at the edge"
        );
        assert_eq!(ground_height(&dem, 999.0, 1995.0), None);
        let mut holes = dem.clone();
        holes.data[1] = f32::NAN;
        assert_eq!(ground_height(&holes, 1010.0, 1990.0), None);
    }
}
