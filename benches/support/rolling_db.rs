//! The generated benchmark database of `benches/pyramid.rs` and `benches/incremental.rs`:
//! an n × n grid of 1 m cells (rolling terrain with a nodata hole, a textured colour layer),
//! both layers written as ingest writes them.

use dbms::crs::Crs;
use dbms::db::{Database, Stage};
use dbms::grid::Grid;
use dbms::raster::{Colour, Elevation};
use rayon::prelude::*;
use std::path::Path;

/// A rolling terrain (metres) with a few nodata holes, and a textured colour.
pub fn make_database(dir: &Path, n: usize) {
    let grid = Grid::north_up(500_000.0, 5_300_000.0, 1.0, n, n, Crs::epsg(32632));
    let z: Vec<f32> = (0..n * n)
        .into_par_iter()
        .map(|i| {
            let (x, y) = ((i % n) as f64, (i / n) as f64);
            let hole = ((x - 0.3 * n as f64).powi(2) + (y - 0.6 * n as f64).powi(2)).sqrt()
                < n as f64 / 40.0;
            if hole {
                return f32::NAN;
            }
            let h = 300.0
                + 40.0 * (x / 700.0).sin() * (y / 900.0).cos()
                + 8.0 * (x / 97.0 + y / 131.0).sin()
                + hash(i) as f64 * 0.5;
            h as f32
        })
        .collect();
    let c: Vec<[u8; 4]> = (0..n * n)
        .into_par_iter()
        .map(|i| {
            let v = hash(i ^ 0x5bd1e995);
            [
                (90.0 + 60.0 * v) as u8,
                (110.0 + 50.0 * v) as u8,
                (70.0 + 40.0 * v) as u8,
                255,
            ]
        })
        .collect();
    std::fs::create_dir_all(dir).expect("db dir");
    let mut db = Database::create(dir, grid.clone(), vec![]).expect("create");
    dbms::io::geotiff::write_f32(&dir.join("elevation.tif"), &Elevation::new(grid.clone(), z))
        .expect("write elevation");
    dbms::io::geotiff::write_rgba8(&dir.join("colour.tif"), &Colour::new(grid, c))
        .expect("write colour");
    db.set_layer("elevation", "elevation", "elevation.tif", None)
        .expect("layer");
    db.set_layer("colour", "colour", "colour.tif", None)
        .expect("layer");
    db.record_stage(Stage::now("ingest", serde_json::json!({})));
    db.save().expect("save");
}

/// A value in [0, 1) from a cell index (deterministic).
fn hash(i: usize) -> f32 {
    let mut x = (i as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
    x ^= x >> 31;
    x = x.wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x ^= x >> 29;
    (x >> 40) as f32 / (1u64 << 24) as f32
}
