//! `dbms shadows` end to end: a database made with the library, the mask read back.

use dbms::crs::Crs;
use dbms::db::{Database, ELEVATION};
use dbms::grid::Grid;
use dbms::raster::Elevation;
use std::path::{Path, PathBuf};
use std::process::Output;
#[path = "support/cli.rs"]
mod cli;
use cli::dbms;

/// A 60 × 40 database at 1 m cells in UTM 32N (about 47.9° N) with a 6 m wall along row 10
/// and a nodata hole; `buildings` adds a `buildings` layer with one 20 m block.
fn database(dir: &Path, buildings: bool) -> Elevation {
    let grid = Grid::north_up(500_000.0, 5_300_000.0, 1.0, 60, 40, Crs::epsg(32632));
    let mut e = Elevation::filled(grid.clone(), 100.0);
    for c in 0..60 {
        *e.get_mut(c, 10) = 106.0;
    }
    *e.get_mut(30, 30) = f32::NAN;
    let mut db = Database::create(dir, grid, vec![]).unwrap();
    dbms::io::geotiff::write_f32(&dir.join("elevation.tif"), &e).unwrap();
    db.set_layer(ELEVATION, "elevation", "elevation.tif", Some(1))
        .unwrap();
    if buildings {
        let block = r#"{"type":"FeatureCollection","features":[{"type":"Feature","properties":{"id":1,"roof_z":120.0},
            "geometry":{"type":"Polygon","coordinates":[[[500040,5299970],[500045,5299970],[500045,5299965],[500040,5299965],[500040,5299970]]]}}]}"#;
        std::fs::write(dir.join("buildings.geojson"), block).unwrap();
        db.set_layer("buildings", "buildings", "buildings.geojson", None)
            .unwrap();
    }
    db.save().unwrap();
    e
}

/// `dbms shadows --db DIR ARGS -o DIR/mask.tif`, which must succeed: its output and the mask.
fn shadows(dir: &Path, args: &[&str]) -> (Output, PathBuf) {
    let out = dir.join("mask.tif");
    let mut all = vec!["shadows", "--db", dir.to_str().unwrap()];
    all.extend(args);
    all.extend(["-o", out.to_str().unwrap()]);
    let o = dbms(&all);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    (o, out)
}

fn read_mask(path: &Path) -> (Vec<u8>, Option<f64>, Grid) {
    let r = dbms::io::read_raster(path).unwrap();
    let v = (0..r.grid.len()).map(|i| r.sample(i, 0) as u8).collect();
    (v, r.nodata, r.grid)
}

#[test]
fn mask_matches_the_library_and_declares_nodata() {
    let dir = tempfile::tempdir().unwrap();
    let e = database(dir.path(), false);
    let (o, out) = shadows(dir.path(), &["--sun-elevation", "45", "--sun-azimuth", "0"]);
    let (mask, nodata, grid) = read_mask(&out);
    assert_eq!(nodata, Some(255.0));
    assert_eq!(grid, e.grid);
    assert_eq!(
        mask,
        dbms::shadow::cast_shadows(&e, 45.0, 0.0).unwrap().data
    );
    // The 6 m wall at 45° shades the 5 rows whose centres are closer than 6 m; the hole (row 30) is nodata.
    assert_eq!(mask.iter().filter(|&&v| v == 1).count(), 5 * 60);
    assert_eq!(mask[30 * 60 + 30], 255);
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(stdout.contains("300 cells in shadow"), "{stdout}");
}

#[test]
fn time_gives_the_sun_over_the_centre_and_json_reports_it() {
    let dir = tempfile::tempdir().unwrap();
    database(dir.path(), false);
    let noon = ["--json", "--time", "2026-06-21T11:00:00Z"];
    let (o, out) = shadows(dir.path(), &noon);
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    // Near local noon at midsummer, 48° N: the sun is high in the south.
    let el = v["sun"]["elevation_deg"].as_f64().unwrap();
    let az = v["sun"]["azimuth_deg"].as_f64().unwrap();
    assert!(
        (60.0..66.0).contains(&el) && (150.0..210.0).contains(&az),
        "{el} {az}"
    );
    assert_eq!(v["cells"]["nodata"], 1);
    // Same inputs, same bytes.
    let first = std::fs::read(&out).unwrap();
    shadows(dir.path(), &noon);
    assert_eq!(first, std::fs::read(&out).unwrap());
}

#[test]
fn buildings_layer_casts_shadows_too() {
    let dir = tempfile::tempdir().unwrap();
    database(dir.path(), true);
    let args = ["--json", "--sun-elevation", "45", "--sun-azimuth", "0"];
    let (o, out) = shadows(dir.path(), &args);
    let v: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(v["building_cells"], 25);
    // The 20 m block (5 × 5 cells at rows 30..35) shades every row south of it, to the grid's edge.
    let (mask, _, _) = read_mask(&out);
    assert!((35..40).all(|r| (40..45).all(|c| mask[r * 60 + c] == 1)));
    assert!(v["cells"]["shadow"].as_u64().unwrap() > 300);
}

#[test]
fn bad_input_is_one_line_error_and_no_output() {
    let dir = tempfile::tempdir().unwrap();
    database(dir.path(), false);
    let db = dir.path().to_str().unwrap();
    let out = dir.path().join("mask.tif");
    let o = out.to_str().unwrap();
    let cases: [(&[&str], &str); 4] = [
        (
            &[
                "shadows",
                "--db",
                db,
                "--sun-elevation",
                "-2",
                "--sun-azimuth",
                "90",
                "-o",
                o,
            ],
            "night",
        ),
        (
            &[
                "shadows",
                "--db",
                db,
                "--time",
                "2026-06-21T23:00:00Z",
                "-o",
                o,
            ],
            "night",
        ),
        (
            &[
                "shadows",
                "--db",
                "/nonexistent/db",
                "--sun-elevation",
                "30",
                "--sun-azimuth",
                "90",
                "-o",
                o,
            ],
            "no such database",
        ),
        (
            &["shadows", "--db", db, "--time", "yesterday", "-o", o],
            "RFC 3339",
        ),
    ];
    for (args, needle) in cases {
        let r = dbms(args);
        let err = String::from_utf8_lossy(&r.stderr);
        assert!(
            !r.status.success() && err.contains(needle) && err.trim().lines().count() == 1,
            "{args:?}: {err}"
        );
    }
    // Half a sun, or both forms at once, is a usage error.
    assert!(
        !dbms(&["shadows", "--db", db, "--sun-elevation", "30", "-o", o])
            .status
            .success()
    );
    assert!(!dbms(&[
        "shadows",
        "--db",
        db,
        "--time",
        "2026-06-21T11:00:00Z",
        "--sun-elevation",
        "30",
        "--sun-azimuth",
        "1",
        "-o",
        o
    ])
    .status
    .success());
    assert!(!out.exists());
}

/// `dbms shadows` with extra arguments on `dir`'s database, sun 40° high in the north (no distance is a tie); the mask
/// and the `--json` summary.
fn shadows_40_north(dir: &Path, extra: &[&str]) -> (Vec<u8>, serde_json::Value) {
    let mut args = vec!["--json", "--sun-elevation", "40", "--sun-azimuth", "0"];
    args.extend(extra);
    let (o, out) = shadows(dir, &args);
    (
        read_mask(&out).0,
        serde_json::from_slice(&o.stdout).unwrap(),
    )
}

#[test]
fn placed_objects_cast_shadows_unless_terrain_only() {
    use dbms::db::PlacedObject;
    use dbms::voxel::{format, grid::VoxelGrid, object::VoxelObject};
    let dir = tempfile::tempdir().unwrap();
    database(dir.path(), false);
    // A 1 × 1 × 10 m tower of 1 m voxels standing on cell (50, 25) (ground 100 m).
    let tower = VoxelObject::from_fn(
        VoxelGrid::new([0.0, 0.0, 0.0], 1.0, [1, 1, 10]).unwrap(),
        |_, _| Some([90, 90, 90]),
    );
    let file = dir.path().join("tower.dvox");
    format::write(&file, &tower, "test tower").unwrap();
    let mut db = Database::open(dir.path()).unwrap();
    let id = db.manifest.new_placement_id();
    db.manifest.objects.push(PlacedObject {
        id,
        file: "tower.dvox".into(),
        sha256: dbms::db::sha256_file(&file).unwrap(),
        x: 500_050.5,
        y: 5_300_000.0 - 25.5,
        z: 100.0,
        heading_deg: 0.0,
        scale: 1.0,
    });
    db.save().unwrap();

    let (mask, v) = shadows_40_north(dir.path(), &[]);
    assert_eq!(
        (v["object_cells"].as_u64(), v["rule"].as_str()),
        (Some(1), Some("geometric"))
    );
    // The 110 m top shades the 11 cells of column 50 whose centres are closer than
    // 10 m / tan 40° = 11.9 m south; the tower's own cell is lit, and so is every cell beside.
    let col: Vec<u8> = (24..40).map(|r| mask[r * 60 + 50]).collect();
    assert_eq!(col, [0, 0, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 1, 0, 0, 0]);
    assert!((26..37).all(|r| mask[r * 60 + 49] == 0 && mask[r * 60 + 51] == 0));
    // The 6 m wall's 7 rows (closer than 7.2 m) and the tower's 11 cells.
    assert_eq!(v["cells"]["shadow"], 7 * 60 + 11);

    let (bare, v) = shadows_40_north(dir.path(), &["--terrain-only"]);
    assert_eq!(v["object_cells"], 0);
    assert_eq!(v["cells"]["shadow"], 7 * 60);
    assert!((26..37).all(|r| bare[r * 60 + 50] == 0));

    // r.sunmask's rule sees the same tower; along the north axis it equals the geometric one.
    let (sunmask, v) = shadows_40_north(dir.path(), &["--rule", "sunmask"]);
    assert_eq!(v["rule"], "sunmask");
    assert_eq!(sunmask, mask);
}

#[test]
fn sunmask_rule_matches_the_library_off_the_axes() {
    let dir = tempfile::tempdir().unwrap();
    let e = database(dir.path(), false);
    let args = [
        "--sun-elevation",
        "20",
        "--sun-azimuth",
        "33",
        "--rule",
        "sunmask",
    ];
    let (_, out) = shadows(dir.path(), &args);
    let sun = dbms::sun::Sun::new(20.0, 33.0).unwrap();
    let expected = dbms::shadow::cast_shadows_sunmask(&e, &sun).unwrap().data;
    assert!(expected.contains(&1));
    assert_eq!(read_mask(&out).0, expected);
}
