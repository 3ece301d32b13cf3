//! Every JSON file dbms writes validates against its schema in `schemas/`, and every schema
//! there is itself a valid JSON Schema.

use dbms::crs::Crs;
use dbms::grid::Grid;
use dbms::io::geotiff;
use dbms::raster::Raster;
use std::path::Path;
use std::process::Command;

fn schema(name: &str) -> jsonschema::Validator {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("schemas")
        .join(name);
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let value: serde_json::Value =
        serde_json::from_str(&text).unwrap_or_else(|e| panic!("{name}: {e}"));
    jsonschema::validator_for(&value)
        .unwrap_or_else(|e| panic!("{name} is not a valid schema: {e}"))
}

fn assert_valid(v: &jsonschema::Validator, doc: &serde_json::Value, what: &str) {
    let errors: Vec<String> = v
        .iter_errors(doc)
        .map(|e| format!("{} at {}", e, e.instance_path()))
        .collect();
    assert!(
        errors.is_empty(),
        "{what} does not match its schema:\n{}",
        errors.join("\n")
    );
}

#[test]
fn every_schema_compiles() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("schemas");
    let mut n = 0;
    for entry in std::fs::read_dir(dir).unwrap() {
        let name = entry.unwrap().file_name().into_string().unwrap();
        if name.ends_with(".json") {
            schema(&name);
            n += 1;
        }
    }
    assert!(n >= 1);
}

#[test]
fn ingest_manifest_matches_its_schema() {
    let t = tempfile::tempdir().unwrap();
    let g = Grid::north_up(500_000.0, 5_300_000.0, 1.0, 20, 10, Crs::epsg(32632));
    let (d, o) = (t.path().join("dem.tif"), t.path().join("ortho.tif"));
    geotiff::write_f32(&d, &Raster::filled(g.clone(), 3.0f32)).unwrap();
    geotiff::write_rgba8(&o, &Raster::filled(g, [1, 2, 3, 255])).unwrap();
    let db = t.path().join("db");
    let out = Command::new(env!("CARGO_BIN_EXE_dbms"))
        .args([
            "ingest",
            "-q",
            "--photo-time",
            "2026-06-21T10:00:00Z",
            "--dem",
        ])
        .arg(&d)
        .arg("--ortho")
        .arg(&o)
        .arg("-o")
        .arg(&db)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // With a scaled placement in it.
    let tree = t.path().join("tree.dvox");
    let (tree, db_arg) = (tree.to_str().unwrap(), db.to_str().unwrap());
    let cone = [
        "object", "cone", "--height", "2", "--radius", "1", "--voxel", "0.5", "-o", tree,
    ];
    let place = [
        "place",
        "--db",
        db_arg,
        "--object",
        tree,
        "--at",
        "500010,5299995",
        "--scale",
        "1.5",
    ];
    for args in [&cone[..], &place[..]] {
        let out = Command::new(env!("CARGO_BIN_EXE_dbms"))
            .args(args)
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
    let manifest: serde_json::Value =
        serde_json::from_slice(&std::fs::read(db.join("manifest.json")).unwrap()).unwrap();
    assert_eq!(manifest["objects"][0]["scale"], 1.5);
    assert_valid(&schema("manifest.schema.json"), &manifest, "manifest.json");
    // And a broken manifest is caught: the schema is not vacuous.
    let mut bad = manifest.clone();
    bad["layers"]["elevation"]["sha256"] = serde_json::json!("not-a-hash");
    assert!(!schema("manifest.schema.json").is_valid(&bad));
    let mut bad = manifest.clone();
    bad["objects"][0]["scale"] = serde_json::json!(0);
    assert!(!schema("manifest.schema.json").is_valid(&bad));
}

/// `dbms sample` writes `truth.json` and `scene.json` that match their schemas.
#[test]
fn sample_truth_and_scene_match_their_schemas() {
    let t = tempfile::tempdir().unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_dbms"))
        .args(["--quiet", "sample", "--size", "160", "--seed", "2", "-o"])
        .arg(t.path())
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    for (file, name) in [
        ("truth.json", "sample-truth.schema.json"),
        ("scene.json", "sample-scene.schema.json"),
    ] {
        let doc: serde_json::Value =
            serde_json::from_slice(&std::fs::read(t.path().join(file)).unwrap()).unwrap();
        assert_valid(&schema(name), &doc, file);
    }
}

/// A GeoJSON flight path that `dbms render --path` reads matches its schema, and what the
/// schema refuses dbms refuses too.
#[test]
fn flight_paths_dbms_reads_match_their_schema() {
    let v = schema("flight-path.schema.json");
    let dir = tempfile::tempdir().unwrap();
    let good = [
        serde_json::json!({"type": "LineString", "coordinates": [[500000.5, 5300000, 430], [500010, 5300020, 431]]}),
        serde_json::json!({"type": "FeatureCollection", "features": [{"type": "Feature",
            "properties": {"times": [0, 4]},
            "geometry": {"type": "LineString", "coordinates": [[1, 2, 3], [4, 5, 6]]}}]}),
    ];
    let bad = [
        serde_json::json!({"type": "LineString", "coordinates": [[1, 2], [3, 4]]}),
        serde_json::json!({"type": "Point", "coordinates": [1, 2, 3]}),
        serde_json::json!({"type": "LineString", "coordinates": [[1, 2, 3]]}),
    ];
    for (k, doc) in good.iter().chain(&bad).enumerate() {
        let path = dir.path().join(format!("p{k}.geojson"));
        std::fs::write(&path, doc.to_string()).unwrap();
        let read = dbms::render::path::read(&path);
        if k < good.len() {
            assert_valid(&v, doc, "a flight path");
            assert!(read.is_ok(), "{doc}: {:?}", read.err());
        } else {
            assert!(!v.is_valid(doc) && read.is_err(), "{doc}");
        }
    }
}

/// The sample scene file validates against the scene schema and reads in dbms; documents the
/// schema refuses, dbms refuses too.
#[test]
fn scene_files_match_their_schema() {
    let v = schema("scene.schema.json");
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("samples/scene.toml");
    let text = std::fs::read_to_string(&path).unwrap();
    let doc: serde_json::Value = toml::from_str(&text).unwrap();
    assert_valid(&v, &doc, "samples/scene.toml");
    dbms::scene::Scene::parse(&text).unwrap();
    let bad = [
        text.replace("heading = 50", "heading = 50\nheadnig = 3"),
        text.replace("sensor = \"visual\"", "sensor = \"sonar\""),
        text.replace("voxel = 0.25\nseed = 1", "voxel = 0\nseed = 1"),
        text.replace(
            "tiles.dbt\"\ntime = \"2026-09-15T08:30:00Z\"\n",
            "tiles.dbt\"\ntime = \"2026-09-15T08:30:00Z\"\nsun = { elevation = 30, azimuth = 100 }\n",
        ),
        text.replace("version = 1", "version = 2"),
        text.replace("heading = 50", "heading = 50\nscale = 0"),
        text.replace("heading = 50", "heading = 50\nseed = 4"),
        text.replace("heading = 50", "heading = 50\npoints = \"trees.geojson\""),
        text.replace(
            "at = [500066, 5300130]\nheading = 50",
            "points = \"trees.geojson\"\nheading = 50",
        ),
        // Present keys count, whatever their value: as the schema says.
        text.replace("heading = 50", "heading = 50\nseed = 0"),
        text.replace("heading = 50", "heading = 50\nrandom_heading = false"),
        text.replace(
            "at = [500066, 5300130]\nheading = 50",
            "points = \"trees.geojson\"\nheading = 0",
        ),
        text.replace(
            "at = [500066, 5300130]\nheading = 50",
            "points = \"trees.geojson\"\nscale = 1",
        ),
        // Insets: a factor that is not a whole number from 2 to 10, an unknown key, both or
        // neither of bounds and corridor, a name that is not a directory name.
        text.replace("factor = 4", "factor = 2.5"),
        text.replace("factor = 4", "factor = 11"),
        text.replace("factor = 4", "factor = 4\nfactr = 3"),
        text.replace(
            "factor = 4",
            "factor = 4\ncorridor = { route = \"road.geojson\", buffer = 30 }",
        ),
        text.replace("bounds = [500360, 5300264, 500432, 5300400]\n", ""),
        text.replace("[insets.town]", "[insets.\"-town\"]"),
        text.replace(
            "bounds = [500360, 5300264, 500432, 5300400]",
            "corridor = { route = \"road.geojson\", buffer = -1 }",
        ),
    ];
    // Sensor products: both accept a radar look; both refuse one outside (0, 90) or on ir.
    let day =
        "sensor = \"visual\"\ntiles = \"out/build/tiles.dbt\"\ntime = \"2026-09-15T08:30:00Z\"";
    assert!(text.contains(day));
    let radar = text.replace(
        day,
        "sensor = \"radar\"\ntiles = \"out/build/sar.dbt\"\nradar = { azimuth = 220, elevation = 20, band = \"C\" }",
    );
    assert_valid(&v, &toml::from_str(&radar).unwrap(), "a radar product");
    // An inset along a route, nested in the town, with its own photo: both accept it.
    let corridor = text.clone()
        + "\n[insets.road]\nfactor = 2\nparent = \"town\"\ncorridor = { route = \"road.geojson\", buffer = 30 }\northo = \"fine.tif\"\nphoto_time = \"2026-09-15T09:00:00Z\"\n";
    assert_valid(&v, &toml::from_str(&corridor).unwrap(), "a corridor inset");
    dbms::scene::Scene::parse(&corridor).unwrap();
    dbms::scene::Scene::parse(&radar).unwrap();
    for b in [
        radar.replace("elevation = 20", "elevation = 90"),
        radar.replace("band = \"C\"", "band = \"Q\""),
    ] {
        assert!(
            !v.is_valid(&toml::from_str(&b).unwrap()),
            "the schema accepts:\n{b}"
        );
        assert!(dbms::scene::Scene::parse(&b).is_err(), "dbms accepts:\n{b}");
    }
    for b in &bad {
        assert_ne!(b, &text, "each bad document changes the sample");
        let doc: serde_json::Value = toml::from_str(b).unwrap();
        assert!(!v.is_valid(&doc), "the schema accepts:\n{b}");
        assert!(dbms::scene::Scene::parse(b).is_err(), "dbms accepts:\n{b}");
    }
}

/// The built-in material table matches its schema, and the schema is not vacuous.
#[test]
fn default_material_table_matches_its_schema() {
    let path =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("src/lib/material/default-materials.json");
    let table: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    let v = schema("materials.schema.json");
    assert_valid(&v, &table, "default-materials.json");
    let mut bad = table.clone();
    bad["materials"][0]["id"] = serde_json::json!(255);
    assert!(!v.is_valid(&bad));
    let mut bad = table.clone();
    bad["materials"][3]["layers"][0]["sources"]
        .as_object_mut()
        .unwrap()
        .remove("conductivity_w_per_m_k");
    assert!(!v.is_valid(&bad));
    let mut bad = table.clone();
    bad["materials"][13]["bottom"]["h_w_per_m2_k"] = serde_json::json!(0);
    assert!(!v.is_valid(&bad));
    let mut bad = table;
    bad["materials"][2]["name"] = serde_json::json!("Gravel");
    assert!(!v.is_valid(&bad));
}

/// The sample's light points match the lights schema, and the schema refuses what dbms refuses:
/// no intensity, a negative height, a line, a beam above the zenith, of no spread or with a
/// misspelt key; a good beam, with one spread or two, passes.
#[test]
fn light_points_match_their_schema() {
    let v = schema("lights.schema.json");
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("samples/lights.geojson");
    let doc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    assert_valid(&v, &doc, "samples/lights.geojson");
    let with = |f: &dyn Fn(&mut serde_json::Value)| {
        let mut d = doc.clone();
        f(&mut d["features"][0]);
        d
    };
    let beam = |b: serde_json::Value| with(&|f| f["properties"]["beam"] = b.clone());
    for spread in [serde_json::json!(10), serde_json::json!([12, 8])] {
        let good =
            serde_json::json!({"azimuth_deg": 270, "elevation_deg": 3, "spread_deg": spread});
        assert_valid(&v, &beam(good), "a beam");
    }
    for bad in [
        with(&|f| {
            drop(
                f["properties"]
                    .as_object_mut()
                    .unwrap()
                    .remove("intensity_cd"),
            )
        }),
        with(&|f| f["properties"]["height_m"] = serde_json::json!(-1)),
        with(&|f| {
            f["geometry"] =
                serde_json::json!({"type": "LineString", "coordinates": [[0, 0], [1, 1]]})
        }),
        beam(serde_json::json!({"azimuth_deg": 0, "elevation_deg": 95, "spread_deg": 10})),
        beam(serde_json::json!({"azimuth_deg": 0, "elevation_deg": 5, "spread_deg": [10, 0]})),
        beam(serde_json::json!({"azimuth": 0, "elevation_deg": 5, "spread_deg": 10})),
    ] {
        assert!(
            !v.is_valid(&bad),
            "the schema accepts {}",
            bad["features"][0]
        );
    }
}
