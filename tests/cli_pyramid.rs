//! `dbms pyramid` end to end on small databases made here with the library.

use dbms::crs::Crs;
use dbms::db::{Database, PlacedObject, Stage};
use dbms::grid::Grid;
use dbms::raster::{Colour, Elevation};
use dbms::tiles::{TileReader, STATE_OPAQUE, STATE_PARTIAL};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::process::Command;
#[path = "support/cli.rs"]
mod cli;
use cli::dbms;

const W: usize = 150;
const H: usize = 110;

/// A database: a 12 m plateau in the west (a north–south cliff at column 40), a gentle slope
/// elsewhere, a nodata hole, one cell with height but no colour; optionally a photo time.
fn make_db(dir: &Path, photo_time: Option<&str>) -> Database {
    let grid = Grid::north_up(500_000.0, 5_300_000.0, 1.0, W, H, Crs::epsg(32632));
    let z: Vec<f32> = (0..W * H)
        .map(|i| {
            let (c, r) = (i % W, i / W);
            if (70..75).contains(&c) && (50..53).contains(&r) {
                f32::NAN
            } else if c < 40 {
                212.0
            } else {
                200.0 + r as f32 * 0.05
            }
        })
        .collect();
    let colour: Vec<[u8; 4]> = (0..W * H)
        .map(|i| {
            if i == 5 {
                [0, 0, 0, 0]
            } else {
                [100 + (i % 7) as u8, 120, 90 + (i % 13) as u8, 255]
            }
        })
        .collect();
    let db_dir = dir.join("db");
    let mut db = Database::create(&db_dir, grid.clone(), vec![]).unwrap();
    dbms::io::geotiff::write_f32(
        &db_dir.join("elevation.tif"),
        &Elevation::new(grid.clone(), z),
    )
    .unwrap();
    dbms::io::geotiff::write_rgba8(&db_dir.join("colour.tif"), &Colour::new(grid, colour)).unwrap();
    db.set_layer("elevation", "elevation", "elevation.tif", None)
        .unwrap();
    db.set_layer("colour", "colour", "colour.tif", None)
        .unwrap();
    db.record_stage(Stage::now("ingest", json!({ "photo_time": photo_time })));
    db.save().unwrap();
    db
}

/// A 10 × 10 m flat-roofed building 20 m tall on the slope, as shadow-height --apply records it.
fn add_building(db: &mut Database) {
    let (x0, y0) = (500_100.0, 5_300_000.0 - 60.0);
    let ring = json!([
        [x0, y0],
        [x0 + 10.0, y0],
        [x0 + 10.0, y0 + 10.0],
        [x0, y0 + 10.0],
        [x0, y0]
    ]);
    let doc = json!({"type": "FeatureCollection", "features": [
        {"type": "Feature", "properties": {"id": 1, "roof_z": 225.0}, "geometry": {"type": "Polygon", "coordinates": [ring]}}]});
    std::fs::write(db.dir.join("buildings.geojson"), doc.to_string()).unwrap();
    db.set_layer("buildings", "buildings", "buildings.geojson", None)
        .unwrap();
    db.save().unwrap();
}

fn pyramid(db: &Path, out: &Path, extra: &[&str]) -> Value {
    let summary = pyramid_json(db, out, extra);
    check_effects_schema(&summary["effects"]);
    summary
}

/// Every effects record matches schemas/pyramid-effects.schema.json.
fn check_effects_schema(effects: &Value) {
    check_schema("pyramid-effects", effects);
}

/// `doc` matches schemas/NAME.schema.json.
fn check_schema(name: &str, doc: &Value) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join(format!("schemas/{name}.schema.json"));
    let schema: Value = serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    let v = jsonschema::validator_for(&schema).unwrap();
    let errors: Vec<String> = v
        .iter_errors(doc)
        .map(|e| format!("{e} at {}", e.instance_path()))
        .collect();
    assert!(
        errors.is_empty(),
        "{name} does not match its schema: {errors:?}\n{doc}"
    );
}

fn applied(summary: &Value) -> Vec<String> {
    summary["effects"]["applied"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap().to_string())
        .collect()
}

#[test]
fn builds_every_level_with_exact_maxima_and_records_the_stage() {
    let dir = tempfile::tempdir().unwrap();
    let db = make_db(dir.path(), None);
    let out = dir.path().join("t.dbt");
    let s = pyramid(&db.dir, &out, &[]);
    // 150×110 → 38×28 → 10×7 (fits one 32-cell page).
    assert_eq!(s["levels"], json!([[150, 110], [38, 28], [10, 7]]));
    // The 15 hole cells have colour but no height; one cell has height but no colour.
    assert_eq!(s["half_valid_cells"], json!(16));
    let r = TileReader::open(&out, 64).unwrap();
    let elevation = Database::open(&db.dir).unwrap().read_elevation().unwrap();
    for level in 1..3 {
        let span = 4usize.pow(level as u32);
        let l = &r.info().levels[level];
        for row in 0..l.height {
            for col in 0..l.width {
                let mut want = f32::NAN;
                for rr in row * span..((row + 1) * span).min(H) {
                    for cc in col * span..((col + 1) * span).min(W) {
                        let z = *elevation.get(cc, rr);
                        // The cell with no colour is nodata at level 0.
                        if rr * W + cc != 5 && !z.is_nan() {
                            want = if want.is_nan() { z } else { want.max(z) };
                        }
                    }
                }
                let got = r.cell(level, col, row).unwrap().unwrap();
                assert_eq!(
                    got.max_z.to_bits(),
                    want.to_bits(),
                    "level {level} ({col}, {row})"
                );
            }
        }
    }
    // The hole is nodata at level 0 and does not leak into level 1.
    let hole = r.cell(0, 72, 51).unwrap().unwrap();
    assert!(hole.max_z.is_nan() && hole.colour[3] == 0 && hole.state == 0);
    assert_eq!(
        r.cell(1, 18, 12).unwrap().unwrap().state,
        STATE_PARTIAL,
        "block mixing the hole and terrain"
    );
    assert_eq!(
        r.cell(1, 1, 0).unwrap().unwrap().state,
        STATE_PARTIAL,
        "block holding the colourless cell (5, 0)"
    );
    assert_eq!(r.cell(1, 2, 2).unwrap().unwrap().state, STATE_OPAQUE);
    let m = Database::open(&db.dir).unwrap();
    let stage = m.manifest.stages.last().unwrap();
    assert_eq!(stage.name, "pyramid");
    assert_eq!(stage.params["tiles"], json!(out));
    let v = dbms(&["tiles", out.to_str().unwrap(), "--verify"]);
    assert!(v.status.success(), "{}", String::from_utf8_lossy(&v.stderr));
}

#[test]
fn no_sun_means_no_effect_work_at_all() {
    let dir = tempfile::tempdir().unwrap();
    let db = make_db(dir.path(), None);
    let out = dir.path().join("t.dbt");
    let s = pyramid(&db.dir, &out, &[]);
    assert!(applied(&s).is_empty());
    assert!(s["effects"]["sun"].is_null());
    assert_eq!(s["effects"]["reason"], json!("no sun given"));
    // No shadow mask was cast: the record has no shadow counts at all.
    assert!(s["effects"].get("shadow_cells").is_none());
    let r = TileReader::open(&out, 8).unwrap();
    assert_eq!(r.info().effects, s["effects"]);
    // Colours are the photo's, untouched.
    let c = Database::open(&db.dir).unwrap().read_colour().unwrap();
    assert_eq!(r.cell(0, 60, 20).unwrap().unwrap().colour, *c.get(60, 20));
}

#[test]
fn a_sun_casts_the_cliffs_shadow_and_shades_by_the_factor() {
    let dir = tempfile::tempdir().unwrap();
    let db = make_db(dir.path(), None);
    let out = dir.path().join("t.dbt");
    // Sun in the west at 45°: the cliff at column 40 shades 6 to 12 columns east of it.
    let s = pyramid(
        &db.dir,
        &out,
        &[
            "--sun-elevation",
            "45",
            "--sun-azimuth",
            "270",
            "--shadow-factor",
            "0.5",
        ],
    );
    assert_eq!(applied(&s), vec!["cast_shadows", "terrain_lambert"]);
    // The drop is 12 m in row 0 and 6.5 m in the last row (the slope rises southward).
    let shadow = s["effects"]["shadow_cells"].as_u64().unwrap();
    assert!((6 * H as u64..13 * H as u64).contains(&shadow), "{shadow}");
    let r = TileReader::open(&out, 64).unwrap();
    let c = Database::open(&db.dir).unwrap().read_colour().unwrap();
    let (shadowed, lit) = (
        r.cell(0, 45, 20).unwrap().unwrap(),
        r.cell(0, 120, 20).unwrap().unwrap(),
    );
    let photo = *c.get(45, 20);
    assert_eq!(shadowed.colour[1], (photo[1] as f64 * 0.5).round() as u8);
    assert!(
        lit.colour[1] >= c.get(120, 20)[1] - 1,
        "gentle slope, nearly unchanged"
    );
}

#[test]
fn the_photos_own_sun_shades_only_what_the_photo_did_not_see() {
    let dir = tempfile::tempdir().unwrap();
    let t = "2026-06-21T10:00:00Z";
    let mut db = make_db(dir.path(), Some(t));
    let out = dir.path().join("t.dbt");
    let s = pyramid(&db.dir, &out, &["--time", t]);
    assert!(applied(&s).is_empty(), "{s}");
    assert!(s["effects"]["reason"]
        .as_str()
        .unwrap()
        .contains("photo's own sun"));
    add_building(&mut db);
    let s = pyramid(&db.dir, &out, &["--time", t]);
    assert_eq!(applied(&s), vec!["wall_shading"]);
    assert_eq!(s["building_cells"], json!(100));
    let r = TileReader::open(&out, 64).unwrap();
    // Building cells: columns 100..110, rows 50..60; the roof is at 225 m.
    assert_eq!(r.cell(0, 105, 55).unwrap().unwrap().max_z, 225.0);
    assert_eq!(r.cell(0, 105, 55).unwrap().unwrap().state, STATE_OPAQUE);
    // A different time: the photo's shadows are compensated and new ones cast.
    let s = pyramid(&db.dir, &out, &["--time", "2026-06-21T16:00:00Z"]);
    let a = applied(&s);
    assert!(
        a.contains(&"photo_shadow_compensation".to_string())
            && a.contains(&"cast_shadows".to_string()),
        "{a:?}"
    );
}

#[test]
fn placed_voxel_objects_are_merged_with_partial_cells_for_overhangs() {
    use dbms::voxel::{format, grid::VoxelGrid, object::VoxelObject};
    let dir = tempfile::tempdir().unwrap();
    let mut db = make_db(dir.path(), None);
    // A 4 × 1 × 3 m arch of 1 m voxels: legs at x = 0 and 3, a lintel at z = 2.
    let grid = VoxelGrid::new([0.0, 0.0, 0.0], 1.0, [4, 1, 3]).unwrap();
    let obj = VoxelObject::from_fn(grid, |p, _| {
        let (x, z) = (p[0], p[2]);
        (z > 2.0 || !(1.0..=3.0).contains(&x)).then_some([200, 10, 10])
    });
    format::write(&db.dir.join("arch.dvox"), &obj, "test arch").unwrap();
    let sha256 = dbms::db::sha256_file(&db.dir.join("arch.dvox")).unwrap();
    // Anchor (bottom-face centre) at world (500 120.0, 5 299 980.5, ground 201.0).
    let id = db.manifest.new_placement_id();
    db.manifest.objects.push(PlacedObject {
        id,
        file: "arch.dvox".into(),
        sha256,
        x: 500_120.0,
        y: 5_299_980.5,
        z: 201.0,
        heading_deg: 0.0,
        scale: 1.0,
    });
    db.save().unwrap();
    let out = dir.path().join("t.dbt");
    let s = pyramid(&db.dir, &out, &[]);
    assert_eq!(s["object_cells"], json!(4));
    assert_eq!(
        s["partial_cells"],
        json!(2),
        "the two cells under the lintel"
    );
    let r = TileReader::open(&out, 64).unwrap();
    // Voxel x 0..1 → world 500 118..500 119 → column 118; row 19 holds y 5 299 980.5.
    let leg = r.cell(0, 118, 19).unwrap().unwrap();
    let under = r.cell(0, 119, 19).unwrap().unwrap();
    assert_eq!(
        (leg.state, leg.max_z, leg.colour),
        (STATE_OPAQUE, 204.0, [200, 10, 10, 255])
    );
    assert_eq!((under.state, under.max_z), (STATE_PARTIAL, 204.0));
}

#[test]
fn export_levels_are_georeferenced_geotiffs() {
    let dir = tempfile::tempdir().unwrap();
    let db = make_db(dir.path(), None);
    let out = dir.path().join("t.dbt");
    let exp = dir.path().join("levels");
    let s = pyramid(
        &db.dir,
        &out,
        &[
            "--factor",
            "2",
            "--levels",
            "3",
            "--export-levels",
            exp.to_str().unwrap(),
        ],
    );
    assert_eq!(s["exported"].as_array().unwrap().len(), 6);
    let r = TileReader::open(&out, 64).unwrap();
    for level in 0..3 {
        let z = dbms::io::read_raster(&exp.join(format!("level{level}_maxz.tif")))
            .unwrap()
            .to_elevation()
            .unwrap();
        let c = dbms::io::read_raster(&exp.join(format!("level{level}_colour.tif")))
            .unwrap()
            .to_colour()
            .unwrap();
        let cell = 2f64.powi(level);
        assert_eq!(z.grid.transform.origin_x, 500_000.0);
        assert_eq!(z.grid.transform.origin_y, 5_300_000.0);
        assert_eq!(z.grid.cell_size(), (cell, cell));
        assert_eq!(c.grid.width, W.div_ceil(1 << level));
        for (col, row) in [(0, 0), (7, 3), (z.grid.width - 1, z.grid.height - 1)] {
            let t = r.cell(level as usize, col, row).unwrap().unwrap();
            assert_eq!(z.get(col, row).to_bits(), t.max_z.to_bits());
            assert_eq!(*c.get(col, row), t.colour);
        }
    }
    match Command::new("gdalinfo")
        .arg("-json")
        .arg(exp.join("level2_maxz.tif"))
        .output()
    {
        Ok(o) if o.status.success() => {
            let info: Value = serde_json::from_slice(&o.stdout).unwrap();
            assert_eq!(
                info["geoTransform"],
                json!([500000.0, 4.0, 0.0, 5300000.0, 0.0, -4.0])
            );
            assert_eq!(info["size"], json!([38, 28]));
        }
        _ => {
            eprintln!("skipped: gdalinfo not found");
            return;
        }
    }
    // The colour is RGB with an internal mask: GDAL sees three bands sharing a per-dataset mask,
    // and the mask it extracts is 0 exactly on the tiles' nodata cells.
    let colour = exp.join("level0_colour.tif");
    let o = Command::new("gdalinfo")
        .arg("-json")
        .arg(&colour)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let info: Value = serde_json::from_slice(&o.stdout).unwrap();
    let bands = info["bands"].as_array().unwrap();
    let interp: Vec<_> = bands.iter().map(|b| &b["colorInterpretation"]).collect();
    assert_eq!(interp, [&json!("Red"), &json!("Green"), &json!("Blue")]);
    for b in bands {
        assert_eq!(b["mask"]["flags"], json!(["PER_DATASET"]), "{b}");
    }
    let mask = dir.path().join("mask.tif");
    let o = Command::new("gdal_translate")
        .args(["-q", "-b", "mask"])
        .args([&colour, &mask])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let mask = dbms::io::read_raster(&mask).unwrap();
    let mut nodata = 0;
    for row in 0..H {
        for col in 0..W {
            let valid = r.cell(0, col, row).unwrap().unwrap().colour[3] != 0;
            nodata += usize::from(!valid);
            let m = mask.sample(row * W + col, 0);
            assert_eq!(m, if valid { 255.0 } else { 0.0 }, "({col}, {row})");
        }
    }
    assert!(nodata > 0, "the database has nodata cells");
}

/// Bands of the layers are read one page-row at a time: a page-row that is all nodata (a void
/// or the corner of a rotated footprint across the whole width) is nodata in the tiles, not an
/// error, with or without a sun.
/// Issue 14, defect 11: the tile file and `--export-levels`' GeoTIFFs are renamed into place
/// together, after the manifest recorded the stage. A level that fails (a full disk as it is
/// finished, injected by `DBMS_FAULT`), the tile file failing after the levels, or the database's
/// lock held past `--wait`: the run fails in one line and leaves no tile file — the make target
/// — to look up to date, no level, and no pyramid stage in the manifest.
#[test]
fn a_failed_level_export_leaves_no_tile_file() {
    let dir = tempfile::tempdir().unwrap();
    let db = make_db(dir.path(), None);
    let manifest = || std::fs::read(db.dir.join("manifest.json")).unwrap();
    let before = manifest();
    let out = dir.path().join("t.dbt");
    let exp = dir.path().join("levels");
    let run = |extra: &[&str], fault: &str| {
        Command::new(env!("CARGO_BIN_EXE_dbms"))
            .args(extra)
            .args(["pyramid", "--db", db.dir.to_str().unwrap(), "--page", "32"])
            .args(["--factor", "2", "--levels", "3", "--export-levels"])
            .args([exp.to_str().unwrap(), "-o", out.to_str().unwrap()])
            .env("DBMS_FAULT", fault)
            .output()
            .unwrap()
    };
    let lock = std::fs::OpenOptions::new()
        .create(true)
        .truncate(false)
        .write(true)
        .open(db.dir.join(".dbms.lock"))
        .unwrap();
    for (extra, fault, says) in [
        (
            &[][..],
            "enospc:level1_colour.tif",
            "level1_colour.tif: no space left on the device",
        ),
        (&[], "enospc:t.dbt", "t.dbt: no space left on the device"),
        (
            &["--wait", "0.1"],
            "",
            "another dbms is changing this database",
        ),
    ] {
        if fault.is_empty() {
            lock.lock().unwrap();
        }
        let o = run(extra, fault);
        lock.unlock().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{err}");
        assert!(
            err.starts_with("dbms: error: ")
                && err.contains(says)
                && err.trim_end().lines().count() == 1,
            "{says}: {err}"
        );
        assert!(!out.exists(), "{says}: the tile file was left behind");
        let left: Vec<_> = std::fs::read_dir(&exp).unwrap().collect();
        assert!(
            left.is_empty(),
            "{says}: levels or temporaries left: {left:?}"
        );
        assert_eq!(manifest(), before, "{says}: a pyramid stage was recorded");
    }
    let s = pyramid(
        &db.dir,
        &out,
        &[
            "--factor",
            "2",
            "--levels",
            "3",
            "--export-levels",
            exp.to_str().unwrap(),
        ],
    );
    assert_eq!(s["exported"].as_array().unwrap().len(), 6);
    // A level's file is an output too: it may not be the tile file.
    let o = dbms(&[
        "pyramid",
        "--db",
        db.dir.to_str().unwrap(),
        "--export-levels",
        exp.to_str().unwrap(),
        "-o",
        exp.join("level0_maxz.tif").to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("level0_maxz.tif: is given as two outputs"),
        "{err}"
    );
}

#[test]
fn a_page_row_of_nodata_is_nodata_not_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let mut db = make_db(dir.path(), None);
    // A new file: a database's own files are never written over (docs/database.md).
    let path = db.dir.join("elevation-voids.tif");
    let mut z = db.read_elevation().unwrap();
    z.data[..40 * W].fill(f32::NAN);
    dbms::io::geotiff::write_f32(&path, &z).unwrap();
    db.set_layer("elevation", "elevation", "elevation-voids.tif", None)
        .unwrap();
    db.save().unwrap();
    for sun in [
        &[][..],
        &["--sun-elevation", "20", "--sun-azimuth", "250"][..],
    ] {
        let out = dir.path().join("t.dbt");
        pyramid(&db.dir, &out, sun); // pages of 32 rows: the first page-row is all nodata
        let r = TileReader::open(&out, 64).unwrap();
        assert!(r.cell(0, 3, 5).unwrap().unwrap().max_z.is_nan());
        assert_eq!(r.cell(0, 3, 45).unwrap().unwrap().max_z, 212.0);
    }
}

#[test]
fn same_inputs_give_byte_identical_tiles() {
    let dir = tempfile::tempdir().unwrap();
    let db = make_db(dir.path(), None);
    let (a, b) = (dir.path().join("a.dbt"), dir.path().join("b.dbt"));
    let sun = [
        "--sun-elevation",
        "30",
        "--sun-azimuth",
        "135",
        "--compression",
        "lz4",
    ];
    pyramid(&db.dir, &a, &sun);
    pyramid(&db.dir, &b, &sun);
    assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
}

#[test]
fn bad_input_is_one_line_naming_the_problem() {
    let dir = tempfile::tempdir().unwrap();
    let db = make_db(dir.path(), None);
    let out: PathBuf = dir.path().join("t.dbt");
    let run = |extra: &[&str]| {
        let mut args = vec![
            "pyramid",
            "--db",
            db.dir.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
        ];
        args.extend_from_slice(extra);
        let o = dbms(&args);
        assert!(!o.status.success());
        let e = String::from_utf8_lossy(&o.stderr).to_string();
        assert_eq!(e.trim_end().lines().count(), 1, "{e}");
        e
    };
    assert!(run(&["--factor", "3"]).contains("factor must be 2 or 4"));
    assert!(run(&["--shadow-factor", "0"]).contains("--shadow-factor 0"));
    assert!(run(&["--page", "30"]).contains("multiple of the factor"));
    assert!(run(&["--sun-elevation", "-5", "--sun-azimuth", "90"]).contains("below the horizon"));
    assert!(run(&["--time", "noon"]).contains("RFC 3339"));
    assert!(!out.exists(), "no partial tile file after an error");
    let o = dbms(&[
        "pyramid",
        "--db",
        dir.path().join("none").to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(String::from_utf8_lossy(&o.stderr).contains("no such database directory"));
}

/// The arch of `placed_voxel_objects_are_merged_with_partial_cells_for_overhangs` in a database,
/// or none; returns the database.
fn arch_db(dir: &Path, with_arch: bool) -> Database {
    use dbms::voxel::{format, grid::VoxelGrid, object::VoxelObject};
    let mut db = make_db(dir, None);
    if with_arch {
        let grid = VoxelGrid::new([0.0, 0.0, 0.0], 1.0, [4, 1, 3]).unwrap();
        let obj = VoxelObject::from_fn(grid, |p, _| {
            let (x, z) = (p[0], p[2]);
            (z > 2.0 || !(1.0..=3.0).contains(&x)).then_some([200, 10, 10])
        });
        format::write(&db.dir.join("arch.dvox"), &obj, "test arch").unwrap();
        let sha256 = dbms::db::sha256_file(&db.dir.join("arch.dvox")).unwrap();
        let id = db.manifest.new_placement_id();
        db.manifest.objects.push(PlacedObject {
            id,
            file: "arch.dvox".into(),
            sha256,
            x: 500_120.0,
            y: 5_299_980.5,
            z: 201.0,
            heading_deg: 0.0,
            scale: 1.0,
        });
        db.save().unwrap();
    }
    db
}

#[test]
fn partial_cells_carry_their_voxel_runs_in_the_level0_bricks() {
    use dbms::voxel::columns::{PageColumns, Run};
    let dir = tempfile::tempdir().unwrap();
    let db = arch_db(dir.path(), true);
    let (a, b) = (dir.path().join("a.dbt"), dir.path().join("b.dbt"));
    pyramid(&db.dir, &a, &[]);
    pyramid(&db.dir, &b, &["--compression", "lz4"]);
    let r = TileReader::open(&a, 64).unwrap();
    assert_eq!(r.info().bricks, dbms::tiles::BRICKS_FORMAT);
    // Columns 119 and 120 of row 19 are under the lintel: page (3, 0) with --page 32.
    let page = r.page(0, 3, 0).unwrap();
    let cols = PageColumns::decode(page.bricks.as_deref().unwrap(), 32 * 32).unwrap();
    cols.check_layers(&page.state, &page.max_z).unwrap();
    assert_eq!(cols.len(), 2);
    for col in [119, 120] {
        let i = 19 * W + col;
        let photo = [100 + (i % 7) as u8, 120, 90 + (i % 13) as u8, 255];
        let runs = cols.runs(19 * 32 + col % 32).unwrap();
        let terrain = 200.0 + 19.0 * 0.05f32;
        assert_eq!(
            runs,
            &[
                Run {
                    bottom: f32::NEG_INFINITY,
                    top: terrain,
                    colour: photo
                },
                Run {
                    bottom: 203.0,
                    top: 204.0,
                    colour: [200, 10, 10, 255]
                }
            ],
            "column {col}: the ground (photo colour), a gap, the lintel voxel"
        );
    }
    assert!(
        cols.runs(19 * 32 + 118 % 32).is_none(),
        "a leg is a plain column"
    );
    // Pages without partial cells carry no bricks; lz4 stores the same blob.
    assert!(r.page(0, 0, 0).unwrap().bricks.is_none());
    let rb = TileReader::open(&b, 64).unwrap();
    assert_eq!(rb.page(0, 3, 0).unwrap().bricks, page.bricks);
    // Same inputs, same bytes.
    let c = dir.path().join("c.dbt");
    pyramid(&db.dir, &c, &[]);
    assert!(std::fs::read(&a).unwrap() == std::fs::read(&c).unwrap());
}

#[test]
fn a_pyramid_arch_renders_open_under_its_lintel() {
    let dir = tempfile::tempdir().unwrap();
    let (with, without) = (dir.path().join("with"), dir.path().join("without"));
    std::fs::create_dir_all(&with).unwrap();
    std::fs::create_dir_all(&without).unwrap();
    let (dw, dn) = (arch_db(&with, true), arch_db(&without, false));
    let (tw, tn) = (dir.path().join("w.dbt"), dir.path().join("n.dbt"));
    pyramid(&dw.dir, &tw, &[]);
    pyramid(&dn.dir, &tn, &[]);
    let range = |tiles: &Path, eye: &str, attitude: &str| -> f32 {
        let (png, exr) = (dir.path().join("v.png"), dir.path().join("v.exr"));
        let o = dbms(&[
            "render",
            "--tiles",
            tiles.to_str().unwrap(),
            "--eye",
            eye,
            "--attitude",
            attitude,
            "--size",
            "5x5",
            "--no-lod",
            "-o",
            png.to_str().unwrap(),
            "--range-out",
            exr.to_str().unwrap(),
        ]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let img = exr::prelude::read_first_flat_layer_from_file(&exr).unwrap();
        let exr::prelude::FlatSamples::F32(z) = &img.layer_data.channel_data.list[0].sample_data
        else {
            panic!("f32 samples")
        };
        z[12]
    };
    // From 10.25 m south of the arch (row 19, y 5 299 980..981), 202.5 m up, looking north and
    // down at the ground under the lintel (y 5 299 980.5, 200.95 m): the same range with and
    // without the arch. 1 m higher the ray meets the lintel's south face instead.
    let pitch = -(1.55f64 / 10.25).atan().to_degrees();
    let att = format!("0,{pitch},0");
    let eye = "500119.5,5299970.25,202.5";
    let open = range(&tw, eye, &att);
    assert!((open as f64 - 10.25f64.hypot(1.55)).abs() < 1e-3, "{open}");
    assert_eq!(open.to_bits(), range(&tn, eye, &att).to_bits());
    assert_eq!(range(&tw, "500119.5,5299970.25,203.5", "0,0,0"), 9.75);
}

/// One edit of what stands on the terrain, for the incremental property test.
#[derive(Debug, Clone)]
enum Edit {
    /// Place the mushroom at a cell, turned by a heading, scaled.
    Add(usize, usize, f64, f64),
    /// Move the placement at this position in the list (modulo its length) to a cell.
    Move(usize, usize, usize),
    /// Remove the placement at this position (modulo).
    Remove(usize),
    /// Replace the buildings layer: squares at cells with roof heights above the slope.
    Buildings(Vec<(usize, usize, f64)>),
}

fn edit() -> impl proptest::strategy::Strategy<Value = Edit> {
    use proptest::prelude::*;
    prop_oneof![
        (0..W, 0..H, 0.0..360.0f64, 0.5..2.0f64).prop_map(|(c, r, h, k)| Edit::Add(c, r, h, k)),
        (0..8usize, 0..W, 0..H).prop_map(|(i, c, r)| Edit::Move(i, c, r)),
        (0..8usize).prop_map(Edit::Remove),
        proptest::collection::vec((0..W - 8, 0..H - 8, 3.0..30.0f64), 0..3)
            .prop_map(Edit::Buildings),
    ]
}

/// A 3 × 3 m cap on a 1 m stem, 4 m tall: an overhang, so its cells are partial.
fn mushroom(dir: &Path) -> (String, String) {
    use dbms::voxel::{format, grid::VoxelGrid, object::VoxelObject};
    let grid = VoxelGrid::new([0.0, 0.0, 0.0], 1.0, [3, 3, 4]).unwrap();
    let obj = VoxelObject::from_fn(grid, |p, _| {
        let (x, y, z) = (p[0], p[1], p[2]);
        let stem = (1.0..2.0).contains(&x) && (1.0..2.0).contains(&y);
        (z >= 3.0 || stem).then_some([150, 40, 30])
    });
    format::write(&dir.join("mushroom.dvox"), &obj, "test mushroom").unwrap();
    let sha = dbms::db::sha256_file(&dir.join("mushroom.dvox")).unwrap();
    ("mushroom.dvox".into(), sha)
}

/// Apply `edit` to the database's placements and buildings layer.
fn apply(db: &mut Database, edit: &Edit, object: &(String, String)) {
    let world = |c: usize, r: usize| (500_000.5 + c as f64, 5_300_000.0 - 0.5 - r as f64);
    let ground = |r: usize| 200.0 + r as f64 * 0.05;
    let objects = &mut db.manifest.objects;
    match edit {
        Edit::Add(c, r, heading, scale) => {
            let (x, y) = world(*c, *r);
            let id = db.manifest.last_placement_id + 1;
            db.manifest.last_placement_id = id;
            db.manifest.objects.push(PlacedObject {
                id,
                file: object.0.clone(),
                sha256: object.1.clone(),
                x,
                y,
                z: if *c < 40 { 212.0 } else { ground(*r) },
                heading_deg: *heading,
                scale: *scale,
            });
        }
        Edit::Move(i, c, r) if !objects.is_empty() => {
            let n = objects.len();
            let p = &mut objects[i % n];
            (p.x, p.y) = world(*c, *r);
            p.z = if *c < 40 { 212.0 } else { ground(*r) };
        }
        Edit::Remove(i) if !objects.is_empty() => {
            let n = objects.len();
            objects.remove(i % n);
        }
        Edit::Move(..) | Edit::Remove(_) => {}
        Edit::Buildings(squares) => {
            let features: Vec<Value> = squares
                .iter()
                .enumerate()
                .map(|(k, &(c, r, h))| {
                    let (x0, y0) = (500_000.0 + c as f64, 5_300_000.0 - r as f64 - 6.0);
                    let ring = json!([
                        [x0, y0],
                        [x0 + 6.0, y0],
                        [x0 + 6.0, y0 + 6.0],
                        [x0, y0 + 6.0],
                        [x0, y0]
                    ]);
                    json!({"type": "Feature", "properties": {"id": k, "roof_z": 212.0 + h},
                           "geometry": {"type": "Polygon", "coordinates": [ring]}})
                })
                .collect();
            let doc = json!({"type": "FeatureCollection", "features": features});
            std::fs::write(db.dir.join("buildings.geojson"), doc.to_string()).unwrap();
            db.set_layer("buildings", "buildings", "buildings.geojson", None)
                .unwrap();
        }
    }
    db.save().unwrap();
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig { cases: 24, ..Default::default() })]

    /// An incremental pyramid after any sequence of edits (placements added, moved, removed;
    /// buildings replaced) is byte for byte the full build of the edited database, under no
    /// sun, the photo's own sun and another sun (photo shadows detected), for factors 2 and 4.
    #[test]
    fn incremental_builds_are_byte_identical_to_full_builds(
        trees in proptest::collection::vec((0..W, 0..H, 0.0..360.0f64, 0.5..2.0f64), 2..5),
        buildings in proptest::collection::vec((0..W - 8, 0..H - 8, 3.0..30.0f64), 0..3),
        edits in proptest::collection::vec(edit(), 1..4),
        sun in 0..3usize,
        factor in proptest::sample::select(vec!["2", "4"]),
    ) {
        let dir = tempfile::tempdir().unwrap();
        let t = "2026-06-21T10:00:00Z";
        let mut db = make_db(dir.path(), Some(t));
        let object = mushroom(&db.dir);
        let sun_args: &[&str] = match sun {
            0 => &[],
            1 => &["--time", t],
            _ => &["--sun-elevation", "25", "--sun-azimuth", "200"],
        };
        let mut extra = vec!["--factor", factor];
        extra.extend_from_slice(sun_args);
        let mut incremental = extra.clone();
        incremental.push("--incremental");
        for &(c, r, heading, scale) in &trees {
            apply(&mut db, &Edit::Add(c, r, heading, scale), &object);
        }
        apply(&mut db, &Edit::Buildings(buildings.clone()), &object);
        let (a, b) = (dir.path().join("a.dbt"), dir.path().join("b.dbt"));
        let s = pyramid(&db.dir, &a, &incremental);
        proptest::prop_assert!(s["full_build"].as_str().unwrap().contains("no ledger"));
        for e in &edits {
            let had = db.manifest.objects.len();
            apply(&mut db, e, &object);
            let s = pyramid(&db.dir, &a, &incremental);
            let full = pyramid(&db.dir, &b, &extra);
            proptest::prop_assert!(
                std::fs::read(&a).unwrap() == std::fs::read(&b).unwrap(),
                "after {:?} ({}): incremental and full tile files differ", e, s
            );
            for key in ["building_cells", "object_cells", "partial_cells", "effects"] {
                proptest::prop_assert_eq!(&s[key], &full[key]);
            }
            // Not vacuous: a placement edit that leaves objects standing is incremental.
            if !matches!(e, Edit::Buildings(_)) && had > 1 {
                proptest::prop_assert!(s.get("full_build").is_none(), "after {:?}: {}", e, s);
            }
        }
    }
}

/// Moving one placement rebuilds only the pages near it; options that change make a full
/// build that says why; a ledger of another tile file is not trusted.
#[test]
fn an_edit_rebuilds_only_its_pages_and_a_changed_option_everything() {
    let dir = tempfile::tempdir().unwrap();
    let mut db = make_db(dir.path(), None);
    let object = mushroom(&db.dir);
    apply(&mut db, &Edit::Add(120, 20, 0.0, 1.0), &object);
    apply(&mut db, &Edit::Add(20, 90, 0.0, 1.0), &object);
    let out = dir.path().join("t.dbt");
    let args = [
        "--incremental",
        "--sun-elevation",
        "40",
        "--sun-azimuth",
        "90",
    ];
    let s = pyramid(&db.dir, &out, &args);
    assert_eq!(s["pages_rebuilt"], s["pages"]);
    let ledger_path = dir.path().join("t.dbt.ledger.json");
    let ledger: Value = serde_json::from_slice(&std::fs::read(&ledger_path).unwrap()).unwrap();
    check_schema("pyramid-ledger", &ledger);
    apply(&mut db, &Edit::Move(0, 125, 24), &object);
    let s = pyramid(&db.dir, &out, &args);
    assert!(s.get("full_build").is_none(), "{s}");
    // Page 32: the mushroom's page and, west of it, where its shadow falls; one page per
    // coarse level above them (5 × 4 pages at level 0, 3 × 2 at level 1, one at level 2).
    let rebuilt = s["pages_rebuilt"].as_u64().unwrap();
    assert!((2..=5).contains(&rebuilt), "{s}");
    // A move by one cell within its page keeps every page's length: the file changes in place,
    // still byte for byte a full build.
    apply(&mut db, &Edit::Move(0, 126, 24), &object);
    let s = pyramid(&db.dir, &out, &args);
    assert_eq!(s["in_place"], json!(true), "{s}");
    let full = dir.path().join("full.dbt");
    pyramid(&db.dir, &full, &args[1..]);
    assert_eq!(std::fs::read(&out).unwrap(), std::fs::read(&full).unwrap());
    // Nothing changed: nothing made again, the same bytes.
    let before = std::fs::read(&out).unwrap();
    let s = pyramid(&db.dir, &out, &args);
    assert_eq!(s["pages_rebuilt"], json!(0));
    assert_eq!(std::fs::read(&out).unwrap(), before);
    // Another sun: every page.
    let s = pyramid(
        &db.dir,
        &out,
        &[
            "--incremental",
            "--sun-elevation",
            "41",
            "--sun-azimuth",
            "90",
        ],
    );
    assert!(s["full_build"].as_str().unwrap().contains("sun"), "{s}");
    // A tile file replaced behind the ledger's back: not trusted.
    pyramid(&db.dir, &out, &[]);
    let s = pyramid(&db.dir, &out, &["--incremental"]);
    assert!(
        s["full_build"]
            .as_str()
            .unwrap()
            .contains("not the tile file its ledger describes"),
        "{s}"
    );
}

/// A run killed while it changes the tile file in place leaves no tile file (a make target
/// missing, not stale) and temporary files the next run clears; that run builds every page
/// again, byte for byte a full build.
#[test]
fn a_run_killed_while_changing_the_file_in_place_leaves_none() {
    let dir = tempfile::tempdir().unwrap();
    let mut db = make_db(dir.path(), None);
    let object = mushroom(&db.dir);
    apply(&mut db, &Edit::Add(120, 20, 0.0, 1.0), &object);
    let out = dir.path().join("t.dbt");
    pyramid(&db.dir, &out, &["--incremental"]);
    apply(&mut db, &Edit::Move(0, 121, 20), &object);
    let args = [
        "pyramid",
        "--db",
        db.dir.to_str().unwrap(),
        "--incremental",
        "--page",
        "32",
        "-o",
        out.to_str().unwrap(),
    ];
    let killed = Command::new(env!("CARGO_BIN_EXE_dbms"))
        .args(args)
        .env("DBMS_FAULT", "tiles-in-place")
        .output()
        .unwrap();
    assert!(!killed.status.success());
    assert!(!out.exists(), "no half-changed tile file under its name");
    let temps = || {
        std::fs::read_dir(dir.path())
            .unwrap()
            .filter(|e| {
                e.as_ref()
                    .unwrap()
                    .file_name()
                    .to_string_lossy()
                    .ends_with(".tmp")
            })
            .count()
    };
    assert_eq!(
        temps(),
        2,
        "the killed run's tile file and ledger are left under temporary names"
    );
    let s = pyramid(&db.dir, &out, &["--incremental"]);
    assert!(s["full_build"].is_string(), "{s}");
    assert_eq!(
        temps(),
        0,
        "the next run clears the dead run's temporary file"
    );
    let full = dir.path().join("full.dbt");
    pyramid(&db.dir, &full, &[]);
    assert_eq!(std::fs::read(&out).unwrap(), std::fs::read(&full).unwrap());
}

/// A building removed under another sun than the photo's, whose shadows are detected in the
/// photo: the detector's thresholds move within `shade::DETECTION_REACH` of the roof, and the
/// incremental build makes those pages again (not every page), byte for byte a full build. On
/// the generated sample (2048² cells, 25 buildings raised from their shadows, pages of 64) and
/// the 13th building removed: taking no detection reach makes the files differ.
#[test]
fn a_building_removed_under_another_sun_rebuilds_the_detectors_reach() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let photo = "2026-09-15T08:30:00Z";
    let run = |args: &[&str]| {
        let o = cli::dbms_in(d, args);
        assert!(
            o.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
        o.stdout
    };
    run(&["-q", "sample", "--size", "1024", "-o", "scene"]);
    let ingest = [
        "-q",
        "ingest",
        "--dem",
        "scene/dem.tif",
        "--ortho",
        "scene/ortho.tif",
    ];
    run(&[&ingest[..], &["--photo-time", photo, "-o", "db"]].concat());
    let heights = |footprints: &str| {
        run(&[
            "-q",
            "shadow-height",
            "--db",
            "db",
            "--footprints",
            footprints,
            "--time",
            photo,
            "--photo-encoding",
            "linear",
            "--apply",
            "-o",
            "heights.geojson",
        ]);
    };
    heights("scene/buildings.geojson");
    let pyramid = |out: &str, more: &[&str]| -> Value {
        let args = [
            "--json",
            "pyramid",
            "--db",
            "db",
            "--time",
            "2026-09-15T15:00:00Z",
        ];
        let args = [&args[..], &["--page", "64", "-o", out], more].concat();
        serde_json::from_slice(&run(&args)).unwrap()
    };
    let s = pyramid("t.dbt", &["--incremental"]);
    assert!(
        applied(&s).contains(&"photo_shadow_detection".to_string()),
        "{s}"
    );
    let text = std::fs::read_to_string(d.join("scene/buildings.geojson")).unwrap();
    let mut doc: Value = serde_json::from_str(&text).unwrap();
    doc["features"].as_array_mut().unwrap().remove(12);
    std::fs::write(d.join("fewer.geojson"), doc.to_string()).unwrap();
    heights("fewer.geojson");
    let s = pyramid("t.dbt", &["--incremental"]);
    assert!(s.get("full_build").is_none(), "{s}");
    assert!(s["pages_rebuilt"].as_u64() < s["pages"].as_u64(), "{s}");
    pyramid("full.dbt", &[]);
    assert!(
        std::fs::read(d.join("t.dbt")).unwrap() == std::fs::read(d.join("full.dbt")).unwrap(),
        "incremental and full tile files differ"
    );
}

/// `dbms survey --db DB -o OUT`, its JSON checked against its schema.
fn survey(db: &Path, out: &Path) {
    let o = dbms(&[
        "-q",
        "survey",
        "--db",
        db.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    check_schema(
        "pyramid-survey",
        &serde_json::from_slice(&std::fs::read(out).unwrap()).unwrap(),
    );
}

/// The parts of shards 1..=n of `extra`'s tile file, each with its record checked.
fn shards(db: &Path, dir: &Path, n: usize, extra: &[&str]) -> Vec<PathBuf> {
    let s = dir.join("survey.json");
    survey(db, &s);
    (1..=n)
        .map(|i| {
            let part = dir.join(format!("part-{i}.dbt"));
            let shard = format!("{i}/{n}");
            let mut args = vec!["--shard", shard.as_str(), "--survey", s.to_str().unwrap()];
            args.extend_from_slice(extra);
            pyramid_json(db, &part, &args);
            let record = dir.join(format!("part-{i}.dbt.shard.json"));
            check_schema(
                "pyramid-shard",
                &serde_json::from_slice(&std::fs::read(record).unwrap()).unwrap(),
            );
            part
        })
        .collect()
}

/// `dbms pyramid` with `args`, pages of 32, its `--json` summary (a shard's has no effects
/// record to check).
fn pyramid_json(db: &Path, out: &Path, args: &[&str]) -> Value {
    let mut all = vec![
        "--json",
        "pyramid",
        "--db",
        db.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
        "--page",
        "32",
    ];
    all.extend_from_slice(args);
    let o = dbms(&all);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    serde_json::from_slice(&o.stdout).unwrap()
}

proptest::proptest! {
    #![proptest_config(proptest::prelude::ProptestConfig { cases: 16, ..Default::default() })]

    /// A tile file merged from shards (any count the 5 × 4 level-0 pages can be cut into, parts
    /// given in any order) is byte for byte the single build's, with the same summary counts
    /// and effects: under no sun, the photo's own sun and another (photo shadows detected,
    /// casts reaching across windows), with overhanging objects, for factors 2 and 4, with lz4.
    #[test]
    fn sharded_builds_are_byte_identical_to_one_build(
        trees in proptest::collection::vec((0..W, 0..H, 0.0..360.0f64, 0.5..2.0f64), 0..5),
        buildings in proptest::collection::vec((0..W - 8, 0..H - 8, 3.0..30.0f64), 0..3),
        n in proptest::sample::select(vec![1usize, 2, 3, 4, 5, 6, 8, 10, 20]),
        sun in 0..3usize,
        factor in proptest::sample::select(vec!["2", "4"]),
        lz4 in proptest::bool::ANY,
        reverse in proptest::bool::ANY,
    ) {
        let dir = tempfile::tempdir().unwrap();
        let t = "2026-06-21T10:00:00Z";
        let mut db = make_db(dir.path(), Some(t));
        let object = mushroom(&db.dir);
        for &(c, r, heading, scale) in &trees {
            apply(&mut db, &Edit::Add(c, r, heading, scale), &object);
        }
        apply(&mut db, &Edit::Buildings(buildings.clone()), &object);
        let mut extra = vec!["--factor", factor];
        let sun_args: &[&str] = match sun {
            0 => &[],
            1 => &["--time", t],
            _ => &["--sun-elevation", "12", "--sun-azimuth", "300"],
        };
        extra.extend_from_slice(sun_args);
        if lz4 {
            extra.extend_from_slice(&["--compression", "lz4"]);
        }
        let (one, merged) = (dir.path().join("one.dbt"), dir.path().join("merged.dbt"));
        let single = pyramid(&db.dir, &one, &extra);
        let mut parts = shards(&db.dir, dir.path(), n, &extra);
        if reverse {
            parts.reverse();
        }
        let mut args = extra.clone();
        args.push("--merge");
        args.extend(parts.iter().map(|p| p.to_str().unwrap()));
        let m = pyramid_json(&db.dir, &merged, &args);
        check_effects_schema(&m["effects"]);
        proptest::prop_assert!(
            std::fs::read(&one).unwrap() == std::fs::read(&merged).unwrap(),
            "{} shards: merged and single tile files differ", n
        );
        for key in ["building_cells", "object_cells", "partial_cells", "half_valid_cells", "effects", "levels", "pages"] {
            proptest::prop_assert_eq!(&m[key], &single[key]);
        }
        let v = dbms(&["-q", "tiles", merged.to_str().unwrap(), "--verify"]);
        proptest::prop_assert!(v.status.success(), "{}", String::from_utf8_lossy(&v.stderr));
    }
}

/// A merge refuses, in one line, parts that are missing, doubled, of other options or of a
/// database changed since; a shard refuses a stale survey and sensor layers.
#[test]
fn bad_shards_and_merges_are_one_line_errors() {
    let dir = tempfile::tempdir().unwrap();
    let mut db = make_db(dir.path(), None);
    add_building(&mut db);
    let dir_db = db.dir.clone();
    let d = dir_db.to_str().unwrap();
    let parts = shards(&db.dir, dir.path(), 4, &[]);
    let p: Vec<&str> = parts.iter().map(|p| p.to_str().unwrap()).collect();
    let out = dir.path().join("m.dbt");
    let o = out.to_str().unwrap();
    let fails = |args: &[&str], want: &str| {
        let r = dbms(args);
        let err = String::from_utf8_lossy(&r.stderr);
        assert!(!r.status.success(), "{args:?} succeeded");
        assert_eq!(err.trim().lines().count(), 1, "{err}");
        assert!(err.contains(want), "{args:?}: {err}");
        assert!(!out.exists());
    };
    let merge = |extra: &[&str], given: &[&str]| {
        let mut a = vec!["pyramid", "--db", d, "-o", o, "--page", "32"];
        a.extend_from_slice(extra);
        a.push("--merge");
        a.extend_from_slice(given);
        a.into_iter().map(String::from).collect::<Vec<_>>()
    };
    let run =
        |a: Vec<String>, want: &str| fails(&a.iter().map(String::as_str).collect::<Vec<_>>(), want);
    run(
        merge(&[], &[p[0], p[1], p[2]]),
        "shard 1 of 4, but 3 parts are merged",
    );
    run(
        merge(&[], &[p[0], p[1], p[2], p[2]]),
        "shard 3 of 4 is given twice",
    );
    run(merge(&["--factor", "2"], &p), "other options");
    run(
        merge(&["--materials"], &p),
        "sharded builds make the visual layers only",
    );
    let shard = |i: &str| {
        let part = dir.path().join("x.dbt");
        let s = dir.path().join("survey.json");
        let args: Vec<String> = [
            "pyramid",
            "--db",
            d,
            "-o",
            part.to_str().unwrap(),
            "--page",
            "32",
            "--shard",
            i,
            "--survey",
            s.to_str().unwrap(),
        ]
        .map(String::from)
        .to_vec();
        args
    };
    run(shard("5/4"), "I/N");
    apply(
        &mut db,
        &Edit::Buildings(vec![(60, 60, 9.0)]),
        &mushroom(&dir_db),
    );
    run(shard("1/4"), "surveys another state of the database");
    let s = dir.path().join("s2.json");
    survey(&db.dir, &s);
    run(merge(&[], &p), "another state of the database");
    let many = [
        "pyramid",
        "--db",
        d,
        "-o",
        o,
        "--page",
        "32",
        "--shard",
        "21/21",
        "--survey",
        s.to_str().unwrap(),
    ];
    fails(&many, "cannot be cut into 21 windows");
}

/// A sample database (`dbms sample --size 160`: a 320² grid of 0.25 m, buildings raised from
/// its truth's heights are not needed here) with its trees' twin: one tree placed.
fn sample_db(dir: &Path) -> PathBuf {
    let scene = dir.join("scene");
    let run = |args: &[&str]| {
        let o = dbms(args);
        assert!(
            o.status.success(),
            "{args:?}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
    };
    run(&[
        "-q",
        "sample",
        "--size",
        "160",
        "-o",
        scene.to_str().unwrap(),
    ]);
    let db = dir.join("db");
    let (dem, ortho) = (scene.join("dem.tif"), scene.join("ortho.tif"));
    let ingest = |extra: &[&str]| {
        let mut a = vec![
            "-q",
            "ingest",
            "--dem",
            dem.to_str().unwrap(),
            "--ortho",
            ortho.to_str().unwrap(),
        ];
        a.extend_from_slice(&[
            "--photo-time",
            "2026-09-15T08:30:00Z",
            "-o",
            db.to_str().unwrap(),
        ]);
        a.extend_from_slice(extra);
        run(&a);
    };
    ingest(&[]);
    let tree = dir.join("tree.dvox");
    run(&[
        "-q",
        "object",
        "cone",
        "--height",
        "6",
        "--radius",
        "2",
        "--voxel",
        "0.5",
        "-o",
        tree.to_str().unwrap(),
    ]);
    run(&[
        "-q",
        "place",
        "--db",
        db.to_str().unwrap(),
        "--object",
        tree.to_str().unwrap(),
        "--at",
        "500030,5300030",
    ]);
    db
}

/// With insets the pyramid writes a tile file per inset beside the base's, listed in the base
/// header; every parent cell over an inset holds its cover (max Z bounding every inset cell
/// under it), pages away from the insets are those of a build without them, and `dbms tiles
/// --verify` checks all of it, refusing a region file built apart.
#[test]
fn insets_get_their_own_tile_files_and_their_parents_cover_them() {
    let dir = tempfile::tempdir().unwrap();
    let db = sample_db(dir.path());
    let d = db.to_str().unwrap();
    let scene = dir.path().join("scene");
    let sun = ["--sun-elevation", "30", "--sun-azimuth", "135"];
    let before = dir.path().join("before.dbt");
    pyramid(&db, &before, &sun);
    let inset = |spec: &str, parent: Option<&str>| {
        let mut a = vec![
            "-q", "ingest", "--dem", "", "--ortho", "", "-o", d, "--inset", spec,
        ];
        let (dem, ortho) = (scene.join("dem.tif"), scene.join("ortho.tif"));
        a[3] = dem.to_str().unwrap();
        a[5] = ortho.to_str().unwrap();
        a.extend_from_slice(&["--photo-time", "2026-09-15T08:30:00Z"]);
        if let Some(p) = parent {
            a.extend_from_slice(&["--inset-parent", p]);
        }
        let o = dbms(&a);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    };
    // A 4× inset around the tree, and a 2× one nested in it.
    inset("town:4:500020,5300020,500040,5300040", None);
    inset("yard:2:500028,5300028,500032,5300032", Some("town"));
    let out = dir.path().join("t.dbt");
    let s = pyramid(&db, &out, &sun);
    let names: Vec<&str> = s["regions"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["name"].as_str().unwrap())
        .collect();
    assert_eq!(names, ["town", "yard"]);
    let base = TileReader::open(&out, 64).unwrap();
    check_schema("tiles-header", &serde_json::to_value(base.info()).unwrap());
    let regions = &base.info().regions;
    assert_eq!(regions[1].parent.as_deref(), Some("town"));
    let town = TileReader::open(&dir.path().join("t.town.dbt"), 64).unwrap();
    let yard = TileReader::open(&dir.path().join("t.yard.dbt"), 64).unwrap();
    assert_eq!(town.info().grid.width, 80 * 4);
    assert_eq!(yard.info().grid.width, 16 * 4 * 2);
    // The max Z of every parent cell bounds each region cell under it, nested too.
    for (parent, child, r) in [(&base, &town, &regions[0]), (&town, &yard, &regions[1])] {
        let g = &child.info().grid;
        let mut highest_seen = false;
        for row in 0..g.height {
            for col in 0..g.width {
                let (pc, pr) = r.spec().parent_cell(col, row);
                let p = parent.cell(0, pc, pr).unwrap().unwrap();
                let c = child.cell(0, col, row).unwrap().unwrap();
                if !c.max_z.is_nan() {
                    assert!(
                        p.max_z >= c.max_z,
                        "{}: ({col}, {row}) {} over {}",
                        r.name,
                        p.max_z,
                        c.max_z
                    );
                    highest_seen |= p.max_z == c.max_z;
                }
            }
        }
        assert!(
            highest_seen,
            "{}: the parent holds the region's maxima, not some higher bound",
            r.name
        );
    }
    // The tree (6 m) stands in every region, at each one's resolution.
    let top = |t: &TileReader| {
        let levels = &t.info().levels;
        let (k, l) = (levels.len() - 1, &levels[levels.len() - 1]);
        let cells = (0..l.height).flat_map(|r| (0..l.width).map(move |c| (c, r)));
        cells.fold(f32::MIN, |m, (c, r)| {
            m.max(t.cell(k, c, r).unwrap().unwrap().max_z)
        })
    };
    assert!(
        top(&yard) > 380.0 && top(&yard) == top(&town),
        "{} {}",
        top(&yard),
        top(&town)
    );
    // Away from the insets the base's level-0 pages are those of the build without them: the
    // 320² grid has 10 × 10 pages of 32 and the town covers its columns 80..160 and rows
    // 160..240: pages 2..5 × 5..8, no other.
    let old = TileReader::open(&before, 4).unwrap();
    let same = |tx, ty| old.stored(0, tx, ty).unwrap().1 == base.stored(0, tx, ty).unwrap().1;
    let differ: Vec<(usize, usize)> = (0..10)
        .flat_map(|y| (0..10).map(move |x| (x, y)))
        .filter(|&(x, y)| !same(x, y))
        .collect();
    let under: Vec<(usize, usize)> = (5..8).flat_map(|y| (2..5).map(move |x| (x, y))).collect();
    assert_eq!(differ, under);

    render_descends_into_regions(&out, &[&base, &town, &yard], regions);

    // Built in 4 shards and merged, the tile set is the same, region files too.
    let sharded = dir.path().join("sharded");
    std::fs::create_dir(&sharded).unwrap();
    let parts = shards(&db, &sharded, 4, &sun);
    let merged = sharded.join("t.dbt");
    let mut args = sun.to_vec();
    args.push("--merge");
    args.extend(parts.iter().map(|p| p.to_str().unwrap()));
    pyramid_json(&db, &merged, &args);
    for name in ["t.dbt", "t.town.dbt", "t.yard.dbt"] {
        let bytes = |d: &Path| std::fs::read(d.join(name)).unwrap();
        assert!(
            bytes(dir.path()) == bytes(&sharded),
            "{name}: sharded and single builds differ"
        );
    }

    let v = dbms(&["--json", "tiles", out.to_str().unwrap(), "--verify"]);
    assert!(v.status.success(), "{}", String::from_utf8_lossy(&v.stderr));
    let v: Value = serde_json::from_slice(&v.stdout).unwrap();
    assert_eq!(v["verified_regions"]["regions"], 2);
    assert_eq!(
        v["verified_regions"]["covered_cells"],
        80 * 80 + 16 * 4 * 16 * 4
    );
    // A region file built apart (here: the town alone, without the yard's cover) is refused.
    let o = dbms(&[
        "-q",
        "pyramid",
        "--db",
        db.join("insets/town").to_str().unwrap(),
        "-o",
        dir.path().join("t.town.dbt").to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v = dbms(&["tiles", out.to_str().unwrap(), "--verify"]);
    let err = String::from_utf8_lossy(&v.stderr);
    assert!(
        !v.status.success() && err.trim().lines().count() == 1,
        "{err}"
    );
    assert!(err.contains("is not the region town"), "{err}");
}

/// Level-0 `max_z` and `state` of a whole tile file, row-major.
fn level0(t: &TileReader) -> (usize, Vec<f32>, Vec<u8>) {
    let g = &t.info().grid;
    let (mut z, mut st) = (Vec::new(), Vec::new());
    for r in 0..g.height {
        for c in 0..g.width {
            let cell = t.cell(0, c, r).unwrap().unwrap();
            z.push(cell.max_z);
            st.push(cell.state);
        }
    }
    (g.width, z, st)
}

/// Views of the tile set `out` (base, then its regions in header order, `tiles`) descend into
/// the regions: hierarchical and level-0 traversals give the same frame bit for bit, with and
/// without range thresholds; and every pixel's range is what a brute-force march of the finest
/// surface gives (each point resolved at the finest region holding it, stepping 5 mm), so a ray
/// crossing a region's border meets no gap and no step. Pixels whose hit is on an object's
/// voxel column (partial cells, whose runs the brute force does not model) are left out.
fn render_descends_into_regions(
    out: &Path,
    tiles: &[&TileReader],
    regions: &[dbms::tiles::region::Region],
) {
    use dbms::render::{render_view, Attitude, Traversal, ViewOptions, Viewpoint};
    let reader = TileReader::open(out, 256).unwrap();
    // From east of the town, low, looking west across its border at the tree.
    let camera = Viewpoint {
        eye: [500_046.0, 5_300_031.0, 376.5],
        attitude: Attitude {
            roll: 0.0,
            pitch: -8.0,
            yaw: 270.0,
        },
        hfov: 60.0,
        width: 120,
        height: 75,
    };
    let view = |traversal, lod| {
        let opts = ViewOptions {
            traversal,
            lod,
            ..ViewOptions::default()
        };
        render_view(&reader, &camera, &opts).unwrap()
    };
    for lod in [false, true] {
        let (a, b) = (
            view(Traversal::Hierarchical, lod),
            view(Traversal::Level0, lod),
        );
        assert!(
            a.rgb == b.rgb,
            "lod {lod}: hierarchical and level-0 colours differ"
        );
        let bits =
            |f: &dbms::render::Frame| f.range.iter().map(|r| r.to_bits()).collect::<Vec<_>>();
        assert!(bits(&a) == bits(&b), "lod {lod}: ranges differ");
    }
    // The finest surface: each tile set's level 0, the deepest region holding a point wins.
    let grids: Vec<_> = tiles
        .iter()
        .map(|t| (t.info().grid.clone(), level0(t)))
        .collect();
    let finest = |x: f64, y: f64| -> Option<(usize, f32, u8)> {
        let mut found = None;
        for (k, (g, (w, z, st))) in grids.iter().enumerate() {
            if let Some((c, r)) = g.cell_at(x, y) {
                found = Some((k, z[r * w + c], st[r * w + c]));
            }
        }
        found
    };
    let frame = view(Traversal::Hierarchical, false);
    let basis = camera.basis();
    let [ex, ey, ez] = camera.eye;
    let (mut checked, mut in_region) = (0, [0usize; 3]);
    for j in 0..camera.height {
        for i in 0..camera.width {
            let d = basis.through(i as f64 + 0.5, j as f64 + 0.5);
            let n = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            let d = d.map(|c| c / n);
            let got = frame.range[j * camera.width + i] as f64;
            let (mut s, mut brute) = (0.0, None);
            while s < 120.0 {
                let (x, y, z) = (ex + d[0] * s, ey + d[1] * s, ez + d[2] * s);
                match finest(x, y) {
                    Some((k, h, st)) if z <= h as f64 => {
                        brute = Some((s, k, st));
                        break;
                    }
                    _ => s += 0.005,
                }
            }
            let Some((want, k, state)) = brute else {
                assert!(
                    got.is_infinite(),
                    "pixel ({i}, {j}): sky by brute force, {got} m rendered"
                );
                continue;
            };
            let hit = (ex + d[0] * got, ey + d[1] * got);
            let partial = state == dbms::tiles::STATE_PARTIAL
                || finest(hit.0, hit.1).is_some_and(|(_, _, st)| st == dbms::tiles::STATE_PARTIAL);
            if partial {
                continue;
            }
            // No gap: the ray meets nothing the brute force meets first; and what it meets is
            // the finest surface: just before the hit it is in the open, just after inside.
            // (A ray that touches a top at its edge leaves the cell at once: on it is enough.)
            let inside = |s: f64, tol: f64| {
                let (x, y, z) = (ex + d[0] * s, ey + d[1] * s, ez + d[2] * s);
                finest(x, y).is_some_and(|(_, h, _)| z <= h as f64 + tol)
            };
            let met = inside(got + 1e-4, 0.0) || inside(got, 1e-4);
            assert!(
                got <= want + 1e-6 && !inside(got - 1e-4, 0.0) && met,
                "pixel ({i}, {j}): rendered {got} m, brute force {want} m (tile set {k}); hit at {hit:?}: {:?}; before {:?} z {}, after {:?} z {}",
                finest(hit.0, hit.1),
                finest(ex + d[0] * (got - 1e-4), ey + d[1] * (got - 1e-4)), ez + d[2] * (got - 1e-4),
                finest(ex + d[0] * (got + 1e-4), ey + d[1] * (got + 1e-4)), ez + d[2] * (got + 1e-4),
            );
            checked += 1;
            in_region[k] += 1;
        }
    }
    assert!(
        checked > 5000,
        "{checked} pixels checked, per tile set {in_region:?}"
    );
    assert!(
        in_region[1] > 500 && in_region[2] > 20,
        "hits per tile set {in_region:?}"
    );
    let _ = regions;
}

/// The `pyramid` stages a database records.
fn pyramid_stages(db: &Path) -> usize {
    let m = Database::open(db).unwrap();
    m.manifest
        .stages
        .iter()
        .filter(|s| s.name == "pyramid")
        .count()
}

/// The products of one run commit together or not at all: a second product in a directory
/// that does not exist is refused before any work, and one whose writing fails (a full disk)
/// leaves neither product, ledger nor stage.
#[test]
fn a_failing_product_leaves_no_other_product() {
    let dir = tempfile::tempdir().unwrap();
    let db = make_db(dir.path(), None);
    let (a, b) = (dir.path().join("a.dbt"), dir.path().join("b.dbt"));
    let nodir = dir.path().join("nodir/b.dbt");
    let run = |second: &Path, fault: Option<&str>| {
        let product = format!("{}@none", second.display());
        let mut c = cli::command();
        c.args(["pyramid", "--db", db.dir.to_str().unwrap(), "--page", "32"]);
        c.args([
            "--incremental",
            "-o",
            a.to_str().unwrap(),
            "--product",
            &product,
        ]);
        if let Some(f) = fault {
            c.env("DBMS_FAULT", f);
        }
        let o = c.output().unwrap();
        assert!(!o.status.success());
        let e = String::from_utf8_lossy(&o.stderr).to_string();
        assert_eq!(e.trim_end().lines().count(), 1, "{e}");
        e
    };
    let e = run(&nodir, None);
    assert!(
        e.contains("nodir") && e.contains("no such directory"),
        "{e}"
    );
    let e = run(&b, Some("enospc:b.dbt"));
    assert!(e.contains("b.dbt"), "{e}");
    let names: Vec<String> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(names, ["db"], "nothing but the database");
    assert_eq!(pyramid_stages(&db.dir), 0);
    // Both built: one stage each.
    pyramid_json(
        &db.dir,
        &a,
        &["--product", &format!("{}@none", b.display())],
    );
    assert!(a.exists() && b.exists());
    assert_eq!(pyramid_stages(&db.dir), 2);
}

/// A merge refuses to write over one of its parts (or a part's record), before any work.
#[test]
fn a_merge_never_overwrites_a_part() {
    let dir = tempfile::tempdir().unwrap();
    let db = make_db(dir.path(), None);
    let parts = shards(&db.dir, dir.path(), 2, &[]);
    let before: Vec<Vec<u8>> = parts.iter().map(|p| std::fs::read(p).unwrap()).collect();
    let p: Vec<&str> = parts.iter().map(|p| p.to_str().unwrap()).collect();
    for out in [p[0], p[1]] {
        let o = dbms(&[
            "pyramid",
            "--db",
            db.dir.to_str().unwrap(),
            "--page",
            "32",
            "-o",
            out,
            "--merge",
            p[0],
            p[1],
        ]);
        let e = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "merged over {out}");
        assert_eq!(e.trim_end().lines().count(), 1, "{e}");
        assert!(e.contains("also an input"), "{e}");
    }
    for (part, bytes) in parts.iter().zip(&before) {
        assert_eq!(&std::fs::read(part).unwrap(), bytes, "{}", part.display());
    }
    assert_eq!(pyramid_stages(&db.dir), 0);
}

/// A ledger edited outside dbms (one digit of a placement's cells changed: its box inside out)
/// is not trusted: its checksum no longer matches, and moving that placement makes a full
/// build that says why, byte for byte the full build (trusting it left the placement's old
/// cells standing). A ledger without its checksum is not trusted either.
#[test]
fn an_edited_ledger_is_not_trusted() {
    let dir = tempfile::tempdir().unwrap();
    let mut db = make_db(dir.path(), None);
    let object = mushroom(&db.dir);
    apply(&mut db, &Edit::Add(120, 20, 0.0, 1.0), &object);
    apply(&mut db, &Edit::Add(20, 90, 0.0, 1.0), &object);
    let (out, full) = (dir.path().join("t.dbt"), dir.path().join("full.dbt"));
    let args = [
        "--incremental",
        "--sun-elevation",
        "40",
        "--sun-azimuth",
        "90",
    ];
    let ledger_path = dir.path().join("t.dbt.ledger.json");
    let edit_ledger = |edit: &dyn Fn(&mut Value)| {
        let mut ledger: Value =
            serde_json::from_slice(&std::fs::read(&ledger_path).unwrap()).unwrap();
        edit(&mut ledger);
        std::fs::write(&ledger_path, ledger.to_string()).unwrap();
    };
    let inside_out = |ledger: &mut Value| {
        let cells = &mut ledger["things"][0]["cells"];
        cells[0] = json!(cells[2].as_u64().unwrap() + 5);
    };
    for (k, edit) in [&inside_out as &dyn Fn(&mut Value), &|l: &mut Value| {
        l.as_object_mut().unwrap().remove("checksum");
    }]
    .into_iter()
    .enumerate()
    {
        pyramid(&db.dir, &out, &args);
        check_schema(
            "pyramid-ledger",
            &serde_json::from_slice(&std::fs::read(&ledger_path).unwrap()).unwrap(),
        );
        edit_ledger(edit);
        apply(&mut db, &Edit::Move(0, 60 + k, 70), &object);
        let o = cli::command()
            .args([
                "--json",
                "pyramid",
                "--db",
                db.dir.to_str().unwrap(),
                "--page",
                "32",
            ])
            .args(["-o", out.to_str().unwrap()])
            .args(args)
            .output()
            .unwrap();
        assert!(o.status.success());
        let s: Value = serde_json::from_slice(&o.stdout).unwrap();
        let why = s["full_build"].as_str().unwrap_or_default();
        assert!(why.contains("checksum"), "{s}");
        let warning = String::from_utf8_lossy(&o.stderr);
        assert_eq!(warning.lines().count(), 1, "{warning}");
        assert!(
            warning.starts_with("dbms: warning: ") && warning.contains("checksum"),
            "{warning}"
        );
        pyramid(&db.dir, &full, &args[1..]);
        assert!(
            std::fs::read(&out).unwrap() == std::fs::read(&full).unwrap(),
            "{why}"
        );
    }
}

/// A page damaged on disk since the last build is not kept: an incremental build that would
/// change the file in place checks every page it keeps, finds the damage and builds every page
/// (one warning line), byte for byte a full build, and the file verifies.
#[test]
fn an_incremental_build_does_not_keep_a_damaged_page() {
    let dir = tempfile::tempdir().unwrap();
    let mut db = make_db(dir.path(), None);
    let object = mushroom(&db.dir);
    apply(&mut db, &Edit::Add(120, 20, 0.0, 1.0), &object);
    let (out, full) = (dir.path().join("t.dbt"), dir.path().join("full.dbt"));
    pyramid(&db.dir, &out, &["--incremental"]);
    // Damage a level-0 page far from the placement: one byte of its stored data.
    let at = TileReader::open(&out, 0)
        .unwrap()
        .entry(0, 0, 3)
        .unwrap()
        .offset
        + 7;
    let mut bytes = std::fs::read(&out).unwrap();
    bytes[at as usize] ^= 0x5a;
    std::fs::write(&out, &bytes).unwrap();
    apply(&mut db, &Edit::Move(0, 121, 20), &object);
    let o = cli::command()
        .args([
            "--json",
            "pyramid",
            "--db",
            db.dir.to_str().unwrap(),
            "--page",
            "32",
        ])
        .args(["--incremental", "-o", out.to_str().unwrap()])
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let s: Value = serde_json::from_slice(&o.stdout).unwrap();
    let why = s["full_build"].as_str().unwrap_or_default();
    assert!(
        why.contains("page (level 0, 0, 3) checksum mismatch"),
        "{s}"
    );
    let warning = String::from_utf8_lossy(&o.stderr);
    assert_eq!(warning.lines().count(), 1, "{warning}");
    pyramid(&db.dir, &full, &[]);
    assert!(std::fs::read(&out).unwrap() == std::fs::read(&full).unwrap());
    let v = dbms(&["-q", "tiles", out.to_str().unwrap(), "--verify"]);
    assert!(v.status.success(), "{}", String::from_utf8_lossy(&v.stderr));
}
