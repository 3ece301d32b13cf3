//! `dbms shadow-height` end to end: generated scenes through `dbms ingest`, the sample scene,
//! `--apply` into the database, bad footprints, and whole-run errors.

use dbms::choice::Choice;
use dbms::io::geotiff;
use dbms::roof::{Pitch, RoofForm};
use dbms::sun::Sun;
use dbms::testing::shadow_scene::{synth_scene, SynthBuilding, SynthSpec};
use serde_json::{json, Value};
use std::path::Path;
use std::process::Output;
#[path = "support/cli.rs"]
mod cli;
use cli::dbms_in;

fn ok(args: &[&str], dir: &Path) -> Output {
    let out = dbms_in(dir, args);
    assert!(
        out.status.success(),
        "dbms {args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// Check a document against `schemas/heights.schema.json`.
fn assert_schema(doc: &Value) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("schemas/heights.schema.json");
    let schema = read_json(&path);
    let v = jsonschema::validator_for(&schema).expect("heights.schema.json compiles");
    let errors: Vec<String> = v
        .iter_errors(doc)
        .map(|e| format!("{e} at {}", e.instance_path()))
        .collect();
    assert!(
        errors.is_empty(),
        "not valid against heights.schema.json: {errors:?}"
    );
}

/// Every flag dbms can write is one the schema allows: all set, listed without `..` (a new
/// flag must be added here, and so to the schema's enum).
#[test]
fn every_flag_is_in_the_heights_schema() {
    let all = dbms::shadow_height::Flags {
        no_shadow: true,
        shadow_cut_by_edge_or_nodata: true,
        shadow_on_other_building: true,
        low_sun: true,
        high_sun: true,
        pitched_roof: true,
        footprint_off_photo: true,
        lines_disagree: true,
        estimates_disagree: true,
        poor_shadow_match: true,
        shadow_reaches_further: true,
        lean_disagrees: true,
        height_from_lean: true,
    };
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("schemas/heights.schema.json");
    let text = std::fs::read_to_string(path).unwrap();
    for name in all.names() {
        assert!(
            text.contains(&format!("\"{name}\"")),
            "{name} not in heights.schema.json"
        );
    }
}

fn read_json(p: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(p).unwrap()).unwrap()
}

/// A database of two buildings (12 m and 7 m) on a 5 % slope, sun 40° from the south-east,
/// and a footprint file with those two plus a self-intersecting one.
fn generated_db(dir: &Path) -> Vec<f64> {
    let spec = SynthSpec {
        cell: 0.5,
        size: (160, 160),
        slope: (0.05, 0.0),
        sun: Sun::new(40.0, 135.0).unwrap(),
        buildings: vec![
            SynthBuilding {
                centre: (30.0, 50.0),
                size: (12.0, 9.0),
                rotation_deg: 10.0,
                height_m: 12.0,
            },
            SynthBuilding {
                centre: (55.0, 30.0),
                size: (8.0, 8.0),
                rotation_deg: 0.0,
                height_m: 7.0,
            },
        ],
        supersample: 3,
    };
    let scene = synth_scene(&spec);
    geotiff::write_f32(&dir.join("dem.tif"), &scene.terrain).unwrap();
    geotiff::write_rgba8(&dir.join("ortho.tif"), &scene.colour).unwrap();
    let mut features: Vec<Value> = scene
        .footprints
        .iter()
        .enumerate()
        .map(|(i, f)| {
            let mut ring: Vec<[f64; 2]> = f.rings[0].iter().map(|&(x, y)| [x, y]).collect();
            ring.push(ring[0]);
            json!({"type": "Feature", "properties": {"name": format!("b{i}")}, "geometry": {"type": "Polygon", "coordinates": [ring]}})
        })
        .collect();
    let (x, y) = (500_010.0, 5_300_010.0);
    features.push(
        json!({"type": "Feature", "properties": {"name": "bowtie"}, "geometry": {"type": "Polygon",
        "coordinates": [[[x, y], [x + 5.0, y + 5.0], [x + 5.0, y], [x, y + 5.0], [x, y]]]}}),
    );
    std::fs::write(
        dir.join("fp.geojson"),
        json!({"type": "FeatureCollection", "features": features}).to_string(),
    )
    .unwrap();
    ok(
        &[
            "ingest",
            "--dem",
            "dem.tif",
            "--ortho",
            "ortho.tif",
            "-o",
            "db",
        ],
        dir,
    );
    scene.height_m
}

#[test]
fn measures_generated_buildings_keeps_properties_and_reports_the_bad_one() {
    let t = tempfile::tempdir().unwrap();
    let truth = generated_db(t.path());
    let args = [
        "shadow-height",
        "--db",
        "db",
        "--footprints",
        "fp.geojson",
        "--sun-elevation",
        "40",
        "--sun-azimuth",
        "135",
        "-o",
        "h.geojson",
    ];
    let out = ok(&args, t.path());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("feature 2: self-intersecting"), "{stderr}");
    let h = read_json(&t.path().join("h.geojson"));
    assert_schema(&h);
    let fs = h["features"].as_array().unwrap();
    assert_eq!(fs.len(), 3);
    for (f, want) in fs.iter().zip(&truth) {
        let p = &f["properties"];
        let got = p["height_m"].as_f64().unwrap();
        assert!((got - want).abs() <= 0.5, "{got} vs {want}: {p}");
        assert!(p["name"].as_str().unwrap().starts_with('b'));
        assert!(p["overlap"].as_f64().unwrap() > 0.8);
        assert!(
            (p["roof_z"].as_f64().unwrap() - p["ground_z"].as_f64().unwrap() - got).abs() < 1e-9
        );
        assert_eq!(p["flags"], json!([]));
    }
    assert_eq!(fs[2]["properties"]["height_m"], Value::Null);
    assert!(fs[2]["properties"]["error"]
        .as_str()
        .unwrap()
        .contains("self-intersecting"));
    // Same inputs, same bytes.
    let first = std::fs::read(t.path().join("h.geojson")).unwrap();
    ok(&args, t.path());
    assert_eq!(first, std::fs::read(t.path().join("h.geojson")).unwrap());
}

#[test]
fn each_degenerate_footprint_fails_alone_with_its_reason() {
    let t = tempfile::tempdir().unwrap();
    let truth = generated_db(t.path());
    let good = read_json(&t.path().join("fp.geojson"))["features"][0].clone();
    let (x, y) = (500_010.0, 5_300_010.0);
    let poly = |name: &str, ring: Value| json!({"type": "Feature", "properties": {"name": name}, "geometry": {"type": "Polygon", "coordinates": [ring]}});
    let features = vec![
        poly(
            "two points",
            json!([[x, y], [x + 5.0, y], [x + 5.0, y], [x, y]]),
        ),
        poly(
            "collinear",
            json!([[x, y], [x + 5.0, y], [x + 9.0, y], [x, y]]),
        ),
        good,
        json!({"type": "Feature", "properties": {"name": "no geometry"}, "geometry": null}),
        poly(
            "bowtie",
            json!([
                [x, y],
                [x + 5.0, y + 5.0],
                [x + 5.0, y],
                [x, y + 5.0],
                [x, y]
            ]),
        ),
        // Issue 14: one stray vertex made the run abort allocating by the footprint's extent.
        poly(
            "stray vertex at 1e15",
            json!([
                [x, y],
                [x + 5.0, y],
                [1e15, 1e15],
                [x + 5.0, y + 5.0],
                [x, y + 5.0],
                [x, y]
            ]),
        ),
        poly(
            "stray vertex at the origin",
            json!([
                [x, y],
                [x + 5.0, y],
                [0, 0],
                [x + 5.0, y + 5.0],
                [x, y + 5.0],
                [x, y]
            ]),
        ),
    ];
    std::fs::write(
        t.path().join("bad.geojson"),
        json!({"type": "FeatureCollection", "features": features}).to_string(),
    )
    .unwrap();
    let out = ok(
        &[
            "--verbose", // every warning, not the first five
            "shadow-height",
            "--db",
            "db",
            "--footprints",
            "bad.geojson",
            "--sun-elevation",
            "40",
            "--sun-azimuth",
            "135",
            "-o",
            "h.geojson",
        ],
        t.path(),
    );
    let stderr = String::from_utf8_lossy(&out.stderr);
    let h = read_json(&t.path().join("h.geojson"));
    assert_schema(&h);
    let fs = h["features"].as_array().unwrap();
    assert_eq!(fs.len(), 7);
    for (k, reason) in [
        (0, "fewer than 3"),
        (1, "zero area"),
        (3, "geometry"),
        (4, "self-intersecting"),
        (5, "stray vertex"),
        (6, "stray vertex"),
    ] {
        let p = &fs[k]["properties"];
        assert_eq!(p["height_m"], Value::Null, "{p}");
        assert!(p["error"].as_str().unwrap().contains(reason), "{k}: {p}");
        assert!(stderr.contains(&format!("feature {k}: ")), "{k}: {stderr}");
    }
    // The good one among them is measured as when it stood with its own kind.
    let got = fs[2]["properties"]["height_m"].as_f64().unwrap();
    assert!((got - truth[0]).abs() <= 0.5, "{got} vs {}", truth[0]);
}

#[test]
fn apply_writes_the_buildings_layer_that_shadows_and_pyramid_read() {
    let t = tempfile::tempdir().unwrap();
    generated_db(t.path());
    let out = ok(
        &[
            "--json",
            "shadow-height",
            "--db",
            "db",
            "--footprints",
            "fp.geojson",
            "--sun-elevation",
            "40",
            "--sun-azimuth",
            "135",
            "-o",
            "h.geojson",
            "--apply",
        ],
        t.path(),
    );
    let summary: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(
        (
            summary["measured"].as_u64(),
            summary["failed"].as_u64(),
            summary["applied"].as_bool()
        ),
        (Some(2), Some(1), Some(true))
    );
    let manifest = read_json(&t.path().join("db/manifest.json"));
    let file = manifest["layers"]["buildings"]["file"].as_str().unwrap();
    assert!(
        file.starts_with("buildings-") && file.ends_with(".geojson"),
        "{file}"
    );
    let buildings = t.path().join("db").join(file);
    assert!(manifest["stages"]
        .as_array()
        .unwrap()
        .iter()
        .any(|s| s["name"] == "shadow-height"));
    let layer = read_json(&buildings);
    assert_schema(&layer);
    assert_eq!(
        layer["features"].as_array().unwrap().len(),
        2,
        "only measured buildings go in"
    );
    let prisms = dbms::standing::read_buildings(&buildings).unwrap();
    assert_eq!(prisms.len(), 2);
    // The raised buildings now cast shadows in `dbms shadows`.
    let out = ok(
        &[
            "--json",
            "shadows",
            "--db",
            "db",
            "--sun-elevation",
            "40",
            "--sun-azimuth",
            "135",
            "-o",
            "s.tif",
        ],
        t.path(),
    );
    let s: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(s["building_cells"].as_u64().unwrap() > 500, "{s}");
}

#[test]
fn sun_below_the_horizon_or_missing_is_an_error_for_the_run() {
    let t = tempfile::tempdir().unwrap();
    generated_db(t.path());
    let out = dbms_in(
        t.path(),
        &[
            "shadow-height",
            "--db",
            "db",
            "--footprints",
            "fp.geojson",
            "--sun-elevation",
            "-3",
            "--sun-azimuth",
            "135",
            "-o",
            "h.geojson",
        ],
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("below the horizon") && err.lines().count() == 1,
        "{err}"
    );
    assert!(!t.path().join("h.geojson").exists());
    // Night at the database's place: an error too.
    let out = dbms_in(
        t.path(),
        &[
            "shadow-height",
            "--db",
            "db",
            "--footprints",
            "fp.geojson",
            "--time",
            "2026-06-21T23:00:00Z",
            "-o",
            "h.geojson",
        ],
    );
    assert!(
        !out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let out = dbms_in(
        t.path(),
        &[
            "shadow-height",
            "--db",
            "db",
            "--footprints",
            "fp.geojson",
            "-o",
            "h.geojson",
        ],
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("records no photo time") && err.contains("--time"),
        "{err}"
    );
    let out = dbms_in(
        t.path(),
        &[
            "shadow-height",
            "--db",
            "db",
            "--footprints",
            "nope.geojson",
            "--sun-elevation",
            "40",
            "--sun-azimuth",
            "0",
            "-o",
            "h.geojson",
        ],
    );
    assert!(String::from_utf8_lossy(&out.stderr).contains("nope.geojson: no such file"));
    std::fs::write(t.path().join("bad.geojson"), "{\"type\": \"Feature\"}").unwrap();
    let out = dbms_in(
        t.path(),
        &[
            "shadow-height",
            "--db",
            "db",
            "--footprints",
            "bad.geojson",
            "--sun-elevation",
            "40",
            "--sun-azimuth",
            "0",
            "-o",
            "h.geojson",
        ],
    );
    assert!(String::from_utf8_lossy(&out.stderr).contains("not a GeoJSON FeatureCollection"));
}

#[test]
fn shadow_mask_on_another_grid_is_refused() {
    let t = tempfile::tempdir().unwrap();
    generated_db(t.path());
    let g = dbms::grid::Grid::north_up(0.0, 10.0, 1.0, 10, 10, dbms::crs::Crs::epsg(32632));
    geotiff::write_u8(
        &t.path().join("m.tif"),
        &dbms::raster::Raster::filled(g, 0u8),
        Some(255),
    )
    .unwrap();
    let out = dbms_in(
        t.path(),
        &[
            "shadow-height",
            "--db",
            "db",
            "--footprints",
            "fp.geojson",
            "--sun-elevation",
            "40",
            "--sun-azimuth",
            "135",
            "--shadow-mask",
            "m.tif",
            "-o",
            "h.geojson",
        ],
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("m.tif") && err.contains("not the database grid"),
        "{err}"
    );
}

/// A pitched house of the sample: its id, its true form, and its ridge and eaves errors
/// (metres), `None` when it was left flagged.
type PitchedHouse = (u64, String, Option<(f64, f64)>);

/// Run `dbms sample --size SIZE` (seed 1) → ingest → shadow-height (the photo's own sun) and
/// check the goal: every building either measured, or null with a flag saying why; the measured
/// flat roofs within one orthophoto cell RMSE of truth.json and never turned pitched; at least
/// `min_measured` buildings measured. The houses' gable and hip roofs (truth.json's `roof_form`,
/// `eave_z`, `roof_azimuth_deg`, dbms's roof convention) are checked apart: fitted as pitched,
/// their form and ridge direction right, the ridge within [`RIDGE_CELLS`] and the eaves within
/// [`EAVES_CELLS`] cells of truth; or, where the fit did not take, flagged `pitched_roof`,
/// measured between the true eaves and ridge (the shadow of a roof pitched below the sun is
/// its eaves') and with the true ridge inside the reported 95 % interval. At least
/// `min_pitched` of them must be fitted. Returns the pitched ones.
fn sample_within_a_cell(size: usize, min_measured: usize, min_pitched: usize) -> Vec<PitchedHouse> {
    let t = tempfile::tempdir().unwrap();
    let size = size.to_string();
    ok(
        &["sample", "--size", &size, "--seed", "1", "-o", "s"],
        t.path(),
    );
    let s = t.path().join("s");
    let truth = read_json(&s.join("truth.json"));
    let time = truth["sun"]["time"].as_str().unwrap().to_string();
    ok(
        &[
            "ingest",
            "--dem",
            "dem.tif",
            "--ortho",
            "ortho.tif",
            "--photo-time",
            &time,
            "-o",
            "db",
        ],
        &s,
    );
    // No sun given: the photo time recorded by ingest. The sample's photo is shaded in its
    // byte values: linear in light.
    ok(
        &[
            "shadow-height",
            "--db",
            "db",
            "--footprints",
            "buildings.geojson",
            "--photo-encoding",
            "linear",
            "-o",
            "heights.geojson",
        ],
        &s,
    );
    let cell = dbms::sample_scene::ORTHO_CELL_M;
    let h = read_json(&s.join("heights.geojson"));
    let features = h["features"].as_array().unwrap();
    let truths = truth["buildings"].as_array().unwrap();
    assert_eq!(features.len(), truths.len());
    let (mut errors, mut pitched) = (Vec::new(), Vec::new());
    for (f, b) in features.iter().zip(truths) {
        let p = &f["properties"];
        assert_eq!(p["id"], b["id"]);
        let id = b["id"].as_u64().unwrap();
        let roof_z = b["roof_z"].as_f64().unwrap();
        let want = Pitch::from_properties(b, roof_z).unwrap();
        let got = p["roof_z"]
            .as_f64()
            .map(|z| Pitch::from_properties(p, z).unwrap());
        match (want, p["height_m"].as_f64(), got) {
            (_, None, _) => assert!(
                !p["flags"].as_array().unwrap().is_empty() || p.get("error").is_some(),
                "building {id} has no height and no flag saying why: {p}"
            ),
            (None, Some(got), fit) => {
                assert_eq!(fit, Some(None), "flat building {id} came back pitched: {p}");
                errors.push((id, got - b["height_m"].as_f64().unwrap()));
            }
            (Some(w), Some(_), Some(Some(g))) => {
                let ridge = p["roof_z"].as_f64().unwrap() - roof_z;
                let eaves = g.eave_z - w.eave_z;
                let turn = (g.azimuth_deg - w.azimuth_deg).rem_euclid(180.0);
                let ridge_cells = match w.form {
                    RoofForm::Hip => HIP_RIDGE_CELLS,
                    _ => RIDGE_CELLS,
                };
                let [lo, hi] = [0, 1].map(|k| p["roof_z_interval_95"][k].as_f64().unwrap());
                assert!(
                    (lo..=hi).contains(&roof_z),
                    "house {id}: ridge {roof_z} outside its 95 % interval [{lo}, {hi}]"
                );
                assert!(
                    g.form == w.form
                        && turn.min(180.0 - turn) <= 5.0
                        && ridge.abs() <= ridge_cells * cell
                        && eaves.abs() <= EAVES_CELLS * cell,
                    "house {id}: fitted {g:?} ridge {ridge:+.3} m, eaves {eaves:+.3} m; truth {w:?}"
                );
                pitched.push((id, w.form.name().to_string(), Some((ridge, eaves))));
            }
            (Some(w), Some(_), _) => {
                let flags = p["flags"].as_array().unwrap();
                let [lo, hi] = [0, 1].map(|k| p["roof_z_interval_95"][k].as_f64().unwrap());
                let got = p["roof_z"].as_f64().unwrap();
                let tol = EAVES_CELLS * cell;
                assert!(
                    flags.contains(&"pitched_roof".into())
                        && (w.eave_z - tol..=roof_z + tol).contains(&got)
                        && lo <= roof_z
                        && roof_z <= hi,
                    "house {id} ({w:?}, ridge {roof_z}) measured flat at {got}: flags {flags:?}, 95 % [{lo}, {hi}]"
                );
                pitched.push((id, w.form.name().to_string(), None));
            }
        }
    }
    let rmse = (errors.iter().map(|(_, e)| e * e).sum::<f64>() / errors.len() as f64).sqrt();
    let measured = errors.len() + pitched.len();
    assert!(
        measured >= min_measured,
        "{measured} of {} buildings measured, want at least {min_measured}: {errors:?} {pitched:?}",
        truths.len()
    );
    assert!(
        rmse <= cell,
        "sample RMSE {rmse:.3} m > one cell ({cell} m); (id, error m): {errors:?}"
    );
    let fitted = pitched.iter().filter(|(_, _, e)| e.is_some()).count();
    assert!(
        fitted >= min_pitched,
        "{fitted} houses fitted as pitched, want at least {min_pitched}: {pitched:?}"
    );
    eprintln!("sample --size {size}: pitched (id, form, ridge and eaves error m): {pitched:?}");
    pitched
}

/// How close (orthophoto cells) a house's fitted ridge must come to truth: what the pitched fit
/// achieves on the sample (seed 1, 0.25 m cells, sun 32° from 127°; the gables of 30–31°, five
/// at the default size and one at `--size 200`, all came back low, by 0.06–0.14 m, 0.23–0.57
/// cells; the goal is 2 cells).
const RIDGE_CELLS: f64 = 1.0;
/// The same for a hip roof: pitched below the sun, its shadow shows only its eaves, and its
/// ridge comes from its faces' shading (issue 39; the goal, 2 cells).
const HIP_RIDGE_CELLS: f64 = 2.0;
/// How close (orthophoto cells) a house's fitted eaves, or a flagged house's flat measurement
/// below its eaves, must come to truth: the fit's eaves were 0.01–0.03 m low on the sample, the
/// flagged hips measured 0.01–0.05 m from their eaves (0.2 cells).
const EAVES_CELLS: f64 = 0.25;

#[test]
fn the_small_sample_scene_buildings_come_back_within_a_cell() {
    let houses = sample_within_a_cell(200, 5, 1);
    let forms: Vec<&str> = houses.iter().map(|(_, f, _)| f.as_str()).collect();
    assert_eq!(
        forms,
        ["gable", "hip"],
        "the small sample has one house of each"
    );
}

/// The scene `samples/Makefile` builds (seed 1, 25 buildings, adjacent pairs, shadows crossing
/// neighbours and roads): the goal, checked on every `cargo test`.
#[test]
fn the_full_sample_scene_buildings_come_back_within_a_cell() {
    sample_within_a_cell(dbms::sample_scene::DEFAULT_SIZE, 25, 5);
}
