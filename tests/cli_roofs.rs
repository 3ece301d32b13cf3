//! Pitched roofs end to end: a buildings layer with a gable-roofed and a hip-roofed house goes
//! through `dbms pyramid`, `dbms render` and `dbms export mesh`. The pyramid's columns rise with
//! the roofs (each cell at the roof over its centre); the export's ridges are at the layer's
//! `roof_z` and its eaves at `eave_z`, to the centimetre, at every level.

use dbms::crs::Crs;
use dbms::db::{Database, COLOUR, ELEVATION};
use dbms::grid::Grid;
use dbms::mesh::gltf::read_glb;
use dbms::mesh::tileset::content_origins;
use dbms::mesh::Lighting;
use dbms::raster::{Colour, Elevation};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};
#[path = "support/cli.rs"]
mod cli;
use cli::dbms;

const W: usize = 120;
const H: usize = 100;
const CELL: f64 = 0.5;
const X0: f64 = 500_000.0;
const Y0: f64 = 5_300_000.0;

/// The gable house: 14 × 9 m, its ridge east–west along a row of cell centres.
const GABLE: [f64; 4] = [500_010.0, 5_300_010.25, 500_024.0, 5_300_019.25];
const GABLE_EAVE: f64 = 312.0;
const GABLE_RIDGE: f64 = 316.5;

/// The hip house: 12 × 8 m centred at `HIP_CENTRE`, its ridge pointing 30° east of north.
const HIP_CENTRE: (f64, f64) = (500_045.0, 5_300_030.0);
const HIP_AZIMUTH: f64 = 30.0;
const HIP_EAVE: f64 = 305.0;
const HIP_RIDGE: f64 = 309.0;

fn terrain(c: usize, r: usize) -> f32 {
    (300.0 + 0.02 * c as f64 - 0.01 * r as f64) as f32
}

/// The hip house's point `a` metres along its ridge and `c` across (clockwise), world.
fn hip_point(a: f64, c: f64) -> (f64, f64) {
    let (s, k) = HIP_AZIMUTH.to_radians().sin_cos();
    (HIP_CENTRE.0 + a * s + c * k, HIP_CENTRE.1 + a * k - c * s)
}

/// A database of W × H cells: a gentle slope, a photo of stripes, the two houses.
fn make_db(dir: &Path) -> PathBuf {
    let grid = Grid::north_up(X0, Y0 + H as f64 * CELL, CELL, W, H, Crs::epsg(32632));
    let z: Vec<f32> = (0..W * H).map(|i| terrain(i % W, i / W)).collect();
    let photo: Vec<[u8; 4]> = (0..W * H)
        .map(|i| {
            [
                120 + (i % W % 16) as u8 * 4,
                130,
                110 + (i / W % 8) as u8 * 8,
                255,
            ]
        })
        .collect();
    let db_dir = dir.join("db");
    let mut db = Database::create(&db_dir, grid.clone(), vec![]).unwrap();
    dbms::io::geotiff::write_f32(&db_dir.join("e.tif"), &Elevation::new(grid.clone(), z)).unwrap();
    dbms::io::geotiff::write_rgba8(&db_dir.join("c.tif"), &Colour::new(grid, photo)).unwrap();
    db.set_layer(ELEVATION, "elevation", "e.tif", None).unwrap();
    db.set_layer(COLOUR, "colour", "c.tif", None).unwrap();
    let [x0, y0, x1, y1] = GABLE;
    let gable = json!([[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]]);
    let hip: Vec<[f64; 2]> = [
        (-6.0, -4.0),
        (6.0, -4.0),
        (6.0, 4.0),
        (-6.0, 4.0),
        (-6.0, -4.0),
    ]
    .iter()
    .map(|&(a, c)| {
        let p = hip_point(a, c);
        [p.0, p.1]
    })
    .collect();
    let doc = json!({"type": "FeatureCollection", "features": [
        {"type": "Feature",
         "properties": {"id": 1, "roof_z": GABLE_RIDGE, "roof_form": "gable", "eave_z": GABLE_EAVE, "roof_azimuth_deg": 90.0},
         "geometry": {"type": "Polygon", "coordinates": [gable]}},
        {"type": "Feature",
         "properties": {"id": 2, "roof_z": HIP_RIDGE, "roof_form": "hip", "eave_z": HIP_EAVE, "roof_azimuth_deg": HIP_AZIMUTH},
         "geometry": {"type": "Polygon", "coordinates": [hip]}}]});
    std::fs::write(db_dir.join("b.geojson"), doc.to_string()).unwrap();
    db.set_layer("buildings", "buildings", "b.geojson", None)
        .unwrap();
    db.save().unwrap();
    db_dir
}

fn ok(args: &[&str]) -> Value {
    let all = [&["--json"], args].concat();
    let o = dbms(&all);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    serde_json::from_slice(&o.stdout).unwrap()
}

#[test]
fn pitched_roofs_go_through_pyramid_render_and_export() {
    let dir = tempfile::tempdir().unwrap();
    let db = make_db(dir.path());
    let db_s = db.to_str().unwrap();
    let tiles = dir.path().join("t.dbt");
    let levels = dir.path().join("levels");
    ok(&[
        "pyramid",
        "--db",
        db_s,
        "-o",
        tiles.to_str().unwrap(),
        "--export-levels",
        levels.to_str().unwrap(),
    ]);

    // Level 0: the gable's cells step down from the ridge row (row 70, centre y 5300014.75) by
    // a metre of roof per metre across, half a metre a row, to the eaves.
    let z = dbms::io::read_raster(&levels.join("level0_maxz.tif"))
        .unwrap()
        .to_elevation()
        .unwrap();
    for col in [21, 30, 47] {
        for k in 0..9 {
            for row in [70 - k, 70 + k] {
                let want = (GABLE_RIDGE - 0.5 * k as f64) as f32;
                assert_eq!(*z.get(col, row), want, "gable cell ({col}, {row})");
            }
        }
        assert_eq!(*z.get(col, 60), terrain(col, 60), "outside the gable");
    }
    // The hip's cells: each at the hip roof over its centre (its four faces of one pitch, a
    // metre of roof a metre), the highest along the ridge.
    let (s, k) = HIP_AZIMUTH.to_radians().sin_cos();
    let mut top = f32::MIN;
    for row in 0..H {
        for col in 0..W {
            let (x, y) = (
                X0 + (col as f64 + 0.5) * CELL,
                Y0 + H as f64 * CELL - (row as f64 + 0.5) * CELL,
            );
            let (dx, dy) = (x - HIP_CENTRE.0, y - HIP_CENTRE.1);
            let (a, c) = (dx * s + dy * k, dx * k - dy * s);
            if a.abs() >= 6.0 || c.abs() >= 4.0 {
                continue;
            }
            let profile = ((4.0 - c.abs()) / 4.0).min((6.0 - a.abs()) / 4.0);
            let want = HIP_EAVE + (HIP_RIDGE - HIP_EAVE) * profile;
            let got = *z.get(col, row) as f64;
            assert!(
                (got - want).abs() < 1e-4,
                "hip cell ({col}, {row}): {got} against {want}"
            );
            top = top.max(got as f32);
        }
    }
    assert!(
        top > (HIP_RIDGE - 0.25) as f32,
        "the hip's ridge is raised: {top}"
    );

    // A low oblique view from the south-west renders.
    let view = dir.path().join("view.png");
    let s = ok(&[
        "render",
        "--tiles",
        tiles.to_str().unwrap(),
        "-o",
        view.to_str().unwrap(),
        "--eye",
        "500002,5300002,318",
        "--attitude",
        "0,-12,50",
        "--size",
        "160x100",
    ]);
    assert!(s["stats"]["hits"].as_u64().unwrap() > 1000, "{s}");

    // The export: at every level, the ridge's ends and the eaves' corners at the layer's.
    let mesh = dir.path().join("mesh");
    let summary = ok(&[
        "export",
        "mesh",
        "--db",
        db_s,
        "-o",
        mesh.to_str().unwrap(),
        "--tile-cells",
        "32",
        "--factor",
        "2",
    ]);
    assert_eq!(summary["buildings"], 2, "{summary}");
    let levels = summary["levels"].as_array().unwrap().len();
    assert!(levels >= 3, "{summary}");
    let tileset: Value =
        serde_json::from_slice(&std::fs::read(mesh.join("tileset.json")).unwrap()).unwrap();
    let decoded: Vec<(String, Vec<dbms::mesh::Part>)> = content_origins(&tileset)
        .into_iter()
        .map(|(uri, origin)| {
            let parts = read_glb(&std::fs::read(mesh.join(&uri)).unwrap(), origin).unwrap();
            (uri, parts)
        })
        .collect();
    let [x0, y0, x1, y1] = GABLE;
    let ridge_y = (y0 + y1) / 2.0;
    let mut points = vec![
        ((x0, ridge_y), GABLE_RIDGE),
        ((x1, ridge_y), GABLE_RIDGE),
        ((x0, y0), GABLE_EAVE),
        ((x1, y1), GABLE_EAVE),
        (hip_point(-2.0, 0.0), HIP_RIDGE),
        (hip_point(2.0, 0.0), HIP_RIDGE),
    ];
    for (a, c) in [(-6.0, -4.0), (6.0, -4.0), (6.0, 4.0), (-6.0, 4.0)] {
        points.push((hip_point(a, c), HIP_EAVE));
    }
    for level in 0..levels {
        for &((x, y), want) in &points {
            let top = (decoded.iter())
                .filter(|(uri, _)| uri.starts_with(&format!("tiles/{level}/")))
                .flat_map(|(_, parts)| parts.iter().filter(|p| p.lighting == Lighting::Lit))
                .flat_map(|p| p.mesh.positions.iter())
                .filter(|p| (p[0] - x).abs() < 0.01 && (p[1] - y).abs() < 0.01)
                .map(|p| p[2])
                .fold(f64::NEG_INFINITY, f64::max);
            assert!(
                (top - want).abs() <= 0.01,
                "level {level}: the roof at ({x}, {y}) is {top}, the layer says {want}"
            );
        }
    }
}
