//! CLI tests of `dbms ingest --inset` and `--corridor` (issue 19 item 1): nested insets and a
//! corridor added to a database and verified through it, every bad inset definition a one-line
//! error that leaves the database as it was, and a run killed before its commit leaving no inset.

use dbms::crs::Crs;
use dbms::grid::Grid;
use dbms::io::geotiff;
use dbms::raster::Raster;
use std::path::{Path, PathBuf};
use std::process::Output;
#[path = "support/cli.rs"]
mod cli;
use cli::{command, dbms};

const X0: f64 = 500_000.0;
const Y0: f64 = 5_300_000.0;

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// A 60 x 60 DEM at 1 m (a tilted plane with 1 m ripples the 2 m base smooths away) and a
/// 120 x 120 photo at 0.5 m over the same area, both in UTM 32N.
fn write_inputs(dir: &Path) -> (PathBuf, PathBuf) {
    let g = Grid::north_up(X0, Y0, 1.0, 60, 60, Crs::epsg(32632));
    let dem = Raster::new(
        g.clone(),
        (0..g.len())
            .map(|i| {
                let (c, r) = (i % 60, i / 60);
                let ripple = if (c + r) % 2 == 0 { 1.0 } else { -1.0 };
                300.0 + c as f32 * 0.5 - r as f32 * 0.25 + ripple
            })
            .collect(),
    );
    let pg = Grid::north_up(X0, Y0, 0.5, 120, 120, Crs::epsg(32632));
    let photo = Raster::new(
        pg.clone(),
        (0..pg.len())
            .map(|i| [(i % 256) as u8, (i / 120 % 256) as u8, 77, 255])
            .collect(),
    );
    let (d, o) = (dir.join("dem.tif"), dir.join("ortho.tif"));
    geotiff::write_f32(&d, &dem).unwrap();
    geotiff::write_rgba8(&o, &photo).unwrap();
    (d, o)
}

/// The base database: the inputs at 2 m, 30 x 30 cells.
fn base(dir: &Path) -> (PathBuf, PathBuf, PathBuf) {
    let (d, o) = write_inputs(dir);
    let db = dir.join("db");
    let out = dbms(&[
        "ingest",
        "--dem",
        s(&d),
        "--ortho",
        s(&o),
        "--cell",
        "2",
        "-o",
        s(&db),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    (d, o, db)
}

/// `dbms ingest --dem D --ortho O -o DB` with `extra`.
fn add(d: &Path, o: &Path, db: &Path, extra: &[&str]) -> Output {
    let mut args = vec!["ingest", "--dem", s(d), "--ortho", s(o), "-o", s(db)];
    args.extend_from_slice(extra);
    dbms(&args)
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

fn info_json(db: &Path) -> serde_json::Value {
    let out = dbms(&["info", s(db), "--verify", "--json"]);
    assert!(out.status.success(), "{}", stderr(&out));
    serde_json::from_slice(&out.stdout).unwrap()
}

/// A GeoJSON route at `path`: one LineString through `coordinates` (a JSON array of `[x, y]`).
fn write_route(path: &Path, coordinates: &str) {
    let doc = format!(
        r#"{{"type": "FeatureCollection", "features": [{{"type": "Feature", "properties": {{}},
            "geometry": {{"type": "LineString", "coordinates": {coordinates}}}}}]}}"#
    );
    std::fs::write(path, doc).unwrap();
}

/// The command failed cleanly: exit status 1, one line on stderr containing `needle`, no panic.
fn assert_clean_failure(o: &Output, needle: &str) {
    let err = stderr(o);
    assert_eq!(o.status.code(), Some(1), "exit code: {err}");
    assert!(!err.contains("panicked"), "panic: {err}");
    assert_eq!(err.trim_end().lines().count(), 1, "want one line: {err}");
    assert!(err.starts_with("dbms: error: "), "{err}");
    assert!(err.contains(needle), "want {needle:?} in: {err}");
}

/// Nested insets (2 m → 1 m → 0.25 m) and a corridor: each a database of its own on the derived
/// grid, listed in the base's manifest (valid against the schema) and verified through it.
#[test]
fn nested_insets_and_a_corridor_join_the_database() {
    let dir = tempfile::tempdir().unwrap();
    let (d, o, db) = base(dir.path());
    let route = dir.path().join("route.geojson");
    write_route(&route, "[[500004, 5299940], [500040, 5299935]]");
    for extra in [
        &["--inset", "town:2:500010,5299970,500050,5299990"][..],
        &[
            "--inset",
            "yard:4:500020,5299976,500030,5299984",
            "--inset-parent",
            "town",
        ],
        &["--corridor", "road:2:3", "--route", s(&route)],
    ] {
        let out = add(&d, &o, &db, extra);
        assert!(out.status.success(), "{extra:?}: {}", stderr(&out));
    }
    let m = info_json(&db);
    let insets = m["insets"].as_array().unwrap();
    let summary: Vec<(String, serde_json::Value, u64)> = insets
        .iter()
        .map(|i| {
            let name = i["name"].as_str().unwrap().to_string();
            (name, i["parent"].clone(), i["factor"].as_u64().unwrap())
        })
        .collect();
    assert_eq!(
        summary,
        vec![
            ("town".to_string(), serde_json::Value::Null, 2),
            ("yard".to_string(), serde_json::json!("town"), 4),
            ("road-1".to_string(), serde_json::Value::Null, 2),
        ]
    );
    // The route leaves the base's south edge eastward: the blocks within 3 m of it are the
    // first two of the last block row (clipped to 6 rows).
    assert_eq!(
        insets[2]["window"],
        serde_json::json!({"col0": 0, "row0": 24, "col1": 16, "row1": 30})
    );
    // Each inset is an ordinary database on its derived grid.
    let yard = info_json(&db.join("insets/yard"));
    let t = &yard["grid"]["transform"];
    assert_eq!(
        (
            t["origin_x"].as_f64(),
            t["origin_y"].as_f64(),
            t["cell_x"].as_f64()
        ),
        (Some(500_020.0), Some(5_299_984.0), Some(0.25))
    );
    assert_eq!(
        (
            yard["grid"]["width"].as_u64(),
            yard["grid"]["height"].as_u64()
        ),
        (Some(40), Some(32))
    );
    let schema: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(
            Path::new(env!("CARGO_MANIFEST_DIR")).join("schemas/manifest.schema.json"),
        )
        .unwrap(),
    )
    .unwrap();
    let v = jsonschema::validator_for(&schema).unwrap();
    let manifest: serde_json::Value =
        serde_json::from_slice(&std::fs::read(db.join("manifest.json")).unwrap()).unwrap();
    assert!(v.is_valid(&manifest), "{manifest}");
    let mut bad = manifest.clone();
    bad["insets"][0]["factor"] = serde_json::json!(11);
    assert!(!v.is_valid(&bad));
    // Changing an inset behind the database's back is caught by the base's --verify.
    std::fs::write(db.join("insets/yard/manifest.json"), b"{}").unwrap();
    let out = dbms(&["info", s(&db), "--verify"]);
    assert_clean_failure(
        &out,
        "is not the manifest of inset yard that the database recorded",
    );
}

/// A diagonal corridor across the base (2 m cells, 2 m either side, blocks of 8 cells): a chain
/// of insets diag-1 … diag-4, one per block row, added in one change, listed by `dbms info`,
/// verified through the base, each registered and seam-blended like any inset; the chain covers
/// well under its bounding rectangle (the whole base). A second corridor over it is refused
/// whole, naming both insets, and leaves the database as it was.
#[test]
fn a_diagonal_corridor_is_a_chain_of_insets() {
    let dir = tempfile::tempdir().unwrap();
    let (d, o, db) = base(dir.path());
    let route = dir.path().join("diag.geojson");
    write_route(&route, "[[500001, 5299999], [500059, 5299941]]");
    // Killed after the first member's own commit: the base has none of the chain; the next
    // run clears what it left and adds them all.
    let corridor = ["--corridor", "diag:2:2", "--route", s(&route)];
    let mut args = vec!["ingest", "--dem", s(&d), "--ortho", s(&o), "-o", s(&db)];
    args.extend_from_slice(&corridor);
    let killed = command()
        .args(&args)
        .env("DBMS_FAULT", "after-commit")
        .output()
        .unwrap();
    assert!(!killed.status.success());
    assert!(db.join("insets/diag-1/manifest.json").exists());
    assert!(!db.join("insets/diag-2").exists());
    assert!(info_json(&db).get("insets").is_none());
    let out = add(&d, &o, &db, &[&corridor[..], &["--json"]].concat());
    assert!(out.status.success(), "{}", stderr(&out));
    let summary: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(summary["corridor"], "diag");
    assert_eq!(summary["block_cells"], 8);
    assert_eq!(summary["bounding_cells"], 900);
    let windows: Vec<serde_json::Value> = summary["insets"]
        .as_array()
        .unwrap()
        .iter()
        .map(|i| i["inset"]["window"].clone())
        .collect();
    let w = |c0, r0, c1, r1| serde_json::json!({"col0": c0, "row0": r0, "col1": c1, "row1": r1});
    assert_eq!(
        windows,
        vec![
            w(0, 0, 16, 8),
            w(0, 8, 24, 16),
            w(8, 16, 30, 24),
            w(16, 24, 30, 30)
        ]
    );
    let cells = 16 * 8 + 24 * 8 + 22 * 8 + 14 * 6;
    assert_eq!(summary["parent_cells"], cells);
    assert_eq!(summary["inset_cells"], cells * 4);
    let ratio = summary["area_ratio"].as_f64().unwrap();
    assert!(
        (ratio - cells as f64 / 900.0).abs() < 1e-12 && ratio < 0.7,
        "{ratio}"
    );
    // dbms info lists the chain, --verify passes (info_json runs it), each member is on its grid.
    let m = info_json(&db);
    let listed: Vec<(&str, &serde_json::Value)> = m["insets"]
        .as_array()
        .unwrap()
        .iter()
        .map(|i| (i["name"].as_str().unwrap(), &i["window"]))
        .collect();
    let names = ["diag-1", "diag-2", "diag-3", "diag-4"];
    assert_eq!(
        listed,
        names.iter().copied().zip(&windows).collect::<Vec<_>>()
    );
    let text = dbms(&["info", s(&db), "--verify"]);
    assert!(text.status.success(), "{}", stderr(&text));
    let text = String::from_utf8_lossy(&text.stdout);
    for name in names {
        assert!(
            text.contains(&format!("  {name}: factor 2 of the base grid")),
            "{text}"
        );
        let one = dbms::db::Database::open(&db)
            .unwrap()
            .open_inset(name)
            .unwrap();
        assert_eq!(one.stages_run(), vec!["ingest", "seam"]);
    }
    let g = info_json(&db.join("insets/diag-2"))["grid"].clone();
    assert_eq!(
        (g["width"].as_u64(), g["height"].as_u64()),
        (Some(48), Some(16))
    );
    // A second corridor crossing the first: refused whole, the database unchanged.
    let before = std::fs::read(db.join("manifest.json")).unwrap();
    let cross = dir.path().join("cross.geojson");
    write_route(&cross, "[[500059, 5299999], [500001, 5299941]]");
    let out = add(&d, &o, &db, &["--corridor", "x:2:2", "--route", s(&cross)]);
    // (x-1, columns 16..30 of block row 0, is beside diag-1; x-2 is the first that overlaps.)
    assert_clean_failure(
        &out,
        "inset x-2 overlaps inset diag-2 (both refine the base grid)",
    );
    assert_eq!(std::fs::read(db.join("manifest.json")).unwrap(), before);
    let mut left: Vec<String> = std::fs::read_dir(db.join("insets"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    left.sort();
    assert_eq!(left, names);
}

/// Every bad inset definition is one line naming the problem and the fix, exit 1, and leaves
/// the database byte for byte as it was, with no inset directory behind.
#[test]
fn bad_inset_definitions_are_one_line_errors_that_change_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let (d, o, db) = base(dir.path());
    assert!(add(
        &d,
        &o,
        &db,
        &["--inset", "town:2:500010,5299970,500050,5299990"]
    )
    .status
    .success());
    let lonlat = dir.path().join("lonlat.geojson");
    write_route(&lonlat, "[[9.0, 47.8], [9.01, 47.81]]");
    let far = dir.path().join("far");
    std::fs::create_dir(&far).unwrap();
    let g = Grid::north_up(X0 + 5000.0, Y0, 1.0, 10, 10, Crs::epsg(32632));
    geotiff::write_f32(&far.join("dem.tif"), &Raster::filled(g, 1.0)).unwrap();
    let before = std::fs::read(db.join("manifest.json")).unwrap();
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (vec!["--inset", "bad:2:500011,5299970,500050,5299990"],
         "inset bad: bounds 500011,5299970,500050,5299990 are not on the cell edges of its parent (the base grid, 2 x 2 metre cells): MINX by 1 m off; give the bounds snapped outward to them: 500010,5299970,500050,5299990"),
        (vec!["--inset", "bad:2.5:500010,5299950,500050,5299960"], "inset bad: factor 2.5 is not a whole number from 2 to 10"),
        (vec!["--inset", "bad:11:500010,5299950,500050,5299960"], "factor 11 is not a whole number"),
        (vec!["--inset", "bad:2:499990,5299950,500050,5299960"], "reach outside its parent (the base grid, extent 500000,5299940,500060,5300000); give bounds inside the parent, e.g. the part that is: 500000,5299950,500050,5299960"),
        (vec!["--inset", "bad:2:500040,5299980,500060,5300000"], "inset bad overlaps inset town (both refine the base grid) over 500040,5299980,500050,5299990"),
        (vec!["--inset", "bad:2:500010,5299950,500050,5299960", "--inset-parent", "nope"], "inset parent nope is not an inset of this database (it has town)"),
        (vec!["--inset", "town:2:500010,5299950,500050,5299960"], "inset town already exists in this database"),
        (vec!["--inset", "../x:2:500010,5299950,500050,5299960"], "inset name \"../x\" is not a plain name"),
        (vec!["--inset", "bad:2"], "expected NAME:FACTOR:MINX,MINY,MAXX,MAXY"),
        (vec!["--inset-parent", "town"], "--inset-parent town without an inset to add"),
        (vec!["--corridor", "road:2:3", "--route", s(&lonlat)], "coordinates look like longitude/latitude degrees"),
        (vec!["--corridor", "road:2:-3", "--route", s(&lonlat)], "buffer -3 is not a distance above 0"),
    ];
    for (extra, needle) in &cases {
        assert_clean_failure(&add(&d, &o, &db, extra), needle);
        assert_eq!(
            std::fs::read(db.join("manifest.json")).unwrap(),
            before,
            "{extra:?}"
        );
        let mut left: Vec<String> = std::fs::read_dir(db.join("insets"))
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        left.sort();
        assert_eq!(left, vec!["town"], "{extra:?}");
    }
    // A DEM that misses the inset; a database that does not exist.
    let out = add(
        &far.join("dem.tif"),
        &o,
        &db,
        &["--inset", "bad:2:500010,5299950,500050,5299960"],
    );
    assert_clean_failure(&out, "dem.tif: the DEM's extent [505000, 5299990, 505010, 5300000] does not reach the database grid's");
    let out = add(
        &d,
        &o,
        &dir.path().join("none"),
        &["--inset", "a:2:500010,5299950,500050,5299960"],
    );
    assert_clean_failure(&out, "no such database directory");
    // Options that make no sense for an inset are usage errors (exit 2, one line).
    let out = add(
        &d,
        &o,
        &db,
        &[
            "--inset",
            "a:2:500010,5299950,500050,5299960",
            "--cell",
            "1",
        ],
    );
    assert_eq!(out.status.code(), Some(2), "{}", stderr(&out));
    assert_eq!(stderr(&out).trim_end().lines().count(), 1);
}

/// A run killed after the inset's own database is written but before the base records it
/// leaves the base without the inset (and verifiable); the next run clears the directory it
/// left and adds the inset. Re-ingest on the same grid keeps the insets; --overwrite drops
/// them, directories too.
#[test]
fn insets_are_added_atomically_and_dropped_with_overwrite() {
    let dir = tempfile::tempdir().unwrap();
    let (d, o, db) = base(dir.path());
    let town = ["--inset", "town:2:500010,5299970,500050,5299990"];
    let mut args = vec!["ingest", "--dem", s(&d), "--ortho", s(&o), "-o", s(&db)];
    args.extend_from_slice(&town);
    let killed = command()
        .args(&args)
        .env("DBMS_FAULT", "after-commit")
        .output()
        .unwrap();
    assert!(!killed.status.success());
    assert!(
        db.join("insets/town/manifest.json").exists(),
        "the inset's own commit ran"
    );
    assert!(info_json(&db).get("insets").is_none());
    assert!(add(&d, &o, &db, &town).status.success());
    assert_eq!(info_json(&db)["insets"].as_array().unwrap().len(), 1);
    let reingest = add(&d, &o, &db, &["--cell", "2"]);
    assert!(reingest.status.success(), "{}", stderr(&reingest));
    assert_eq!(info_json(&db)["insets"].as_array().unwrap().len(), 1);
    let over = add(&d, &o, &db, &["--cell", "2", "--overwrite"]);
    assert!(over.status.success(), "{}", stderr(&over));
    assert!(info_json(&db).get("insets").is_none());
    assert!(!db.join("insets/town").exists());
}

/// The parent's bilinear surface at world point `(x, y)`, from its cell-centre samples
/// (clamped at its edges): computed here through world coordinates, independently of the
/// library's integer path.
fn bilinear(z: &Raster<f32>, x: f64, y: f64) -> f64 {
    let (u, v) = z.grid.world_to_centre_space(x, y);
    let (w, h) = (z.grid.width as f64 - 1.0, z.grid.height as f64 - 1.0);
    let (u, v) = (u.clamp(0.0, w), v.clamp(0.0, h));
    let (c, r) = (u.floor().min(w - 1.0), v.floor().min(h - 1.0));
    let (tu, tv) = (u - c, v - r);
    let at = |dc: f64, dr: f64| *z.get((c + dc) as usize, (r + dr) as usize) as f64;
    (1.0 - tv) * ((1.0 - tu) * at(0.0, 0.0) + tu * at(1.0, 0.0))
        + tv * ((1.0 - tu) * at(0.0, 1.0) + tu * at(1.0, 1.0))
}

/// The seam through the CLI: the outermost cells of an inset (and of an inset nested in it)
/// lie on the parent's bilinear surface to 1 mm, cells a ring (= factor cells) in keep the
/// DEM's own heights, and the border did need blending (the 1 m inset keeps the DEM's ±1 m
/// ripple, which the 2 m base smooths away).
#[test]
fn the_inset_border_lies_on_the_parent_surface() {
    use dbms::db::Database;
    let dir = tempfile::tempdir().unwrap();
    let (d, o, db) = base(dir.path());
    for extra in [
        &["--inset", "town:2:500010,5299970,500050,5299990"][..],
        &[
            "--inset",
            "yard:4:500020,5299976,500030,5299984",
            "--inset-parent",
            "town",
        ],
    ] {
        let out = add(&d, &o, &db, extra);
        assert!(out.status.success(), "{extra:?}: {}", stderr(&out));
    }
    let base_db = Database::open(&db).unwrap();
    let town = base_db.open_inset("town").unwrap();
    let yard = base_db.open_inset("yard").unwrap();
    assert_eq!(town.stages_run(), vec!["ingest", "seam"]);
    let dem = |x: f64, y: f64| {
        let (c, r) = ((x - X0).floor(), (Y0 - y).floor());
        let ripple = if (c + r) as i64 % 2 == 0 { 1.0 } else { -1.0 };
        300.0 + c * 0.5 - r * 0.25 + ripple
    };
    for (parent, child, factor) in [(&base_db, &town, 2usize), (&town, &yard, 4)] {
        let (pz, z) = (
            parent.read_elevation().unwrap(),
            child.read_elevation().unwrap(),
        );
        let g = &z.grid;
        let mut needed_blending = false;
        for r in 0..g.height {
            for c in 0..g.width {
                let depth = c.min(r).min(g.width - 1 - c).min(g.height - 1 - r);
                let (x, y) = g.cell_centre(c, r);
                let v = *z.get(c, r) as f64;
                if depth == 0 {
                    let p = bilinear(&pz, x, y);
                    assert!((v - p).abs() < 1e-3, "({c},{r}): {v} vs parent {p}");
                    if factor == 2 {
                        needed_blending |= (dem(x, y) - p).abs() > 0.5;
                    }
                } else if depth >= factor && factor == 2 {
                    assert!((v - dem(x, y)).abs() < 1e-4, "({c},{r}): {v} vs DEM");
                }
            }
        }
        assert!(factor != 2 || needed_blending);
    }
}

/// Issue 40, defect 8 (an input removed as a leftover): an inset's sources kept in a directory
/// of `DB/insets/` that names no inset were removed with it by the change that adds the inset,
/// before they were read. A run's inputs are never cleared.
#[test]
fn an_insets_sources_kept_inside_the_database_are_not_cleared() {
    let dir = tempfile::tempdir().unwrap();
    let (d, o, db) = base(dir.path());
    let sources = db.join("insets/sources");
    std::fs::create_dir_all(&sources).unwrap();
    let (d2, o2) = (sources.join("dem.tif"), sources.join("ortho.tif"));
    std::fs::copy(&d, &d2).unwrap();
    std::fs::copy(&o, &o2).unwrap();
    let out = add(
        &d2,
        &o2,
        &db,
        &["--inset", "town:2:500010,5299970,500050,5299990"],
    );
    assert!(out.status.success(), "{}", stderr(&out));
    assert!(d2.exists() && o2.exists(), "the inset's sources went");
    info_json(&db);
}
