use super::*;
use serde_json::{json, Value};

fn default_json() -> Value {
    serde_json::from_str(DEFAULT_TEXT).unwrap()
}

/// The error the default table gives after `edit`, as the one line a user sees.
fn broken(edit: impl FnOnce(&mut Value)) -> String {
    let mut v = default_json();
    edit(&mut v);
    let text = serde_json::to_string(&v).unwrap();
    let e = MaterialTable::parse(&text, Path::new("my-materials.json"))
        .expect_err("the edited table should be refused");
    let line = e.to_string();
    assert!(!line.contains('\n'), "{line}");
    assert!(line.starts_with("my-materials.json: "), "{line}");
    assert!(e.fix.is_some(), "no fix: {line}");
    line
}

fn material<'a>(v: &'a mut Value, name: &str) -> &'a mut Value {
    v["materials"]
        .as_array_mut()
        .unwrap()
        .iter_mut()
        .find(|m| m["name"] == name)
        .unwrap()
}

#[test]
fn the_default_table_loads_with_the_names_and_ids_the_classifier_uses() {
    let t = MaterialTable::default_table();
    let names = [
        "asphalt",
        "concrete",
        "gravel",
        "bare_soil",
        "sand",
        "rock",
        "grass",
        "cropland",
        "shrubland",
        "forest",
        "wetland",
        "water",
        "snow_ice",
        "roof_bitumen",
        "roof_metal",
        "roof_tile",
        "roof_concrete",
    ];
    assert_eq!(t.materials.len(), names.len());
    for (i, name) in names.iter().enumerate() {
        let id = i as u8 + 1;
        assert_eq!(t.id_of(name), Some(id), "{name}");
        assert_eq!(t.by_id(id).unwrap().name, *name);
        assert_eq!(t.by_name(name).unwrap().id, id);
    }
    assert!(t.by_id(UNCLASSIFIED).is_none());
    assert!(t.by_id(NODATA).is_none());
    assert!(t.by_id(18).is_none());
    assert!(t.by_name("lava").is_none());
}

#[test]
fn water_and_flat_roofs_are_specular_and_roofs_sit_over_a_room() {
    let t = MaterialTable::default_table();
    for m in &t.materials {
        let flat = ["water", "roof_bitumen", "roof_concrete"].contains(&m.name.as_str());
        assert_eq!(m.radar.specular, flat, "{}", m.name);
        let roof = m.name.starts_with("roof_");
        assert_eq!(
            matches!(m.bottom, Bottom::Interior { .. }),
            roof,
            "{}",
            m.name
        );
    }
    // The bitumen roof is layered as the RADC study's FLIR model treats roofs: membrane,
    // insulation, deck.
    let roof = t.by_name("roof_bitumen").unwrap();
    assert_eq!(roof.layers.len(), 3);
    assert!(roof.layers[1].conductivity_w_per_m_k < 0.1);
}

#[test]
fn landcover_codes_map_to_their_materials() {
    let t = MaterialTable::default_table();
    let id = |n| t.id_of(n);
    assert_eq!(t.landcover_material("esa_worldcover", 10), id("forest"));
    assert_eq!(t.landcover_material("esa_worldcover", 80), id("water"));
    assert_eq!(t.landcover_material("esa_worldcover", 100), id("grass"));
    assert_eq!(t.landcover_material("nlcd", 11), id("water"));
    assert_eq!(t.landcover_material("nlcd", 82), id("cropland"));
    assert_eq!(t.landcover_material("nlcd", 95), id("wetland"));
    assert_eq!(t.landcover_material("nlcd", 10), None);
    assert_eq!(t.landcover_material("corine", 111), None);
    // Every class of both legends is mapped.
    let codes = |legend: &str| -> Vec<u32> {
        let l = t.landcover.iter().find(|l| l.legend == legend).unwrap();
        l.classes.iter().map(|c| c.code).collect()
    };
    assert_eq!(
        codes("esa_worldcover"),
        [10, 20, 30, 40, 50, 60, 70, 80, 90, 95, 100]
    );
    assert_eq!(
        codes("nlcd"),
        [11, 12, 21, 22, 23, 24, 31, 41, 42, 43, 51, 52, 71, 72, 73, 74, 81, 82, 90, 95]
    );
}

/// Every number in the default table has a source, and every source says where in the
/// publication the number is (checked on the raw JSON, independently of the loader).
#[test]
fn every_number_in_the_default_table_has_a_source() {
    let v = default_json();
    let ids: Vec<&str> = v["sources"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["id"].as_str().unwrap())
        .collect();
    let mut numbers = 0;
    // Walk each object: every numeric (or numeric-array) field but `id` and `code` needs an
    // entry in the object's own `sources` naming a listed source.
    fn walk(v: &Value, ids: &[&str], at: &str, numbers: &mut usize) {
        match v {
            Value::Object(o) => {
                for (k, x) in o {
                    let numeric = x.is_number()
                        || x.as_array()
                            .is_some_and(|a| !a.is_empty() && a.iter().all(Value::is_number));
                    if numeric && k != "id" && k != "version" && k != "code" {
                        *numbers += 1;
                        // A radar model names one `source` for all its coefficients.
                        let src = if o.contains_key("model") {
                            o.get("source").and_then(Value::as_str)
                        } else {
                            o.get("sources")
                                .and_then(|s| s.get(k))
                                .and_then(Value::as_str)
                        };
                        assert!(
                            src.is_some_and(|s| ids.contains(&s)),
                            "{at}.{k} has no listed source"
                        );
                    }
                    walk(x, ids, &format!("{at}.{k}"), numbers);
                }
            }
            Value::Array(a) => {
                for (i, x) in a.iter().enumerate() {
                    walk(x, ids, &format!("{at}[{i}]"), numbers);
                }
            }
            _ => {}
        }
    }
    walk(&v["materials"], &ids, "materials", &mut numbers);
    assert!(numbers > 17 * 7, "only {numbers} numbers seen");
    for l in v["landcover"].as_array().unwrap() {
        assert!(ids.contains(&l["source"].as_str().unwrap()));
    }
}

#[test]
fn a_table_file_is_read_and_a_missing_one_is_one_line() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("m.json");
    std::fs::write(&path, DEFAULT_TEXT).unwrap();
    assert_eq!(
        &MaterialTable::read(&path).unwrap(),
        MaterialTable::default_table()
    );
    let e = MaterialTable::read(&dir.path().join("none.json")).unwrap_err();
    assert!(e.to_string().contains("none.json: no such file"), "{e}");
    std::fs::write(&path, "{\"version\": 1,").unwrap();
    let e = MaterialTable::read(&path).unwrap_err().to_string();
    assert!(e.contains("not a valid material table"), "{e}");
}

#[test]
fn ids_must_be_in_1_to_254_and_unique() {
    for reserved in [0, 255] {
        let e = broken(|v| material(v, "sand")["id"] = json!(reserved));
        assert!(
            e.contains(&format!(
                "material `sand` (id {reserved}): id {reserved} is reserved"
            )),
            "{e}"
        );
    }
    let e = broken(|v| material(v, "sand")["id"] = json!(1));
    assert!(
        e.contains("material `sand` (id 1): id 1 is used by another material"),
        "{e}"
    );
}

#[test]
fn names_must_be_unique_snake_case() {
    for name in ["Sand", "sand-dune", "2sand", "sand_", ""] {
        let e = broken(|v| material(v, "sand")["name"] = json!(name));
        assert!(e.contains("name is not snake_case"), "{name}: {e}");
    }
    let e = broken(|v| material(v, "sand")["name"] = json!("rock"));
    assert!(
        e.contains("material `rock` (id 6): name is used by another material"),
        "{e}"
    );
}

#[test]
fn values_outside_their_physical_range_are_refused() {
    let cases: [(&str, Value, &str); 5] = [
        (
            "solar_albedo",
            json!(1.2),
            "solar_albedo is 1.2, outside [0, 1]",
        ),
        (
            "solar_albedo",
            json!(-0.1),
            "solar_albedo is -0.1, outside [0, 1]",
        ),
        ("emissivity", json!(0.0), "emissivity is 0, outside (0, 1]"),
        (
            "emissivity",
            json!(1.01),
            "emissivity is 1.01, outside (0, 1]",
        ),
        (
            "nir_reflectance",
            json!(2.0),
            "nir_reflectance is 2, outside [0, 1]",
        ),
    ];
    for (field, value, message) in cases {
        let e = broken(|v| {
            let m = material(v, "grass");
            m[field] = value;
            m["sources"][field] = json!("choice");
        });
        assert!(
            e.contains(&format!("material `grass` (id 7): {message}")),
            "{e}"
        );
    }
    for field in LAYER_NUMBERS {
        for value in [0.0, -1.0] {
            let e = broken(|v| material(v, "asphalt")["layers"][1][field] = json!(value));
            assert!(
                e.contains(&format!("material `asphalt` (id 1): layers[1].{field} is {value}, not a positive number")),
                "{e}"
            );
        }
    }
    let e = broken(|v| material(v, "roof_tile")["bottom"]["temperature_k"] = json!(20.0));
    assert!(
        e.contains("bottom.temperature_k is 20 K, outside [200, 350]"),
        "{e}"
    );
    let e = broken(|v| material(v, "roof_tile")["bottom"]["h_w_per_m2_k"] = json!(0.0));
    assert!(
        e.contains("bottom.h_w_per_m2_k is 0, not a positive number"),
        "{e}"
    );
}

#[test]
fn a_material_needs_a_layer() {
    let e = broken(|v| material(v, "rock")["layers"] = json!([]));
    assert!(e.contains("material `rock` (id 6): has no layers"), "{e}");
}

#[test]
fn every_number_must_name_a_listed_source() {
    let e = broken(|v| {
        material(v, "water")["sources"]
            .as_object_mut()
            .unwrap()
            .remove("emissivity");
    });
    assert!(
        e.contains("material `water` (id 12): emissivity has no source"),
        "{e}"
    );
    let e = broken(|v| material(v, "water")["sources"]["emissivity"] = json!("nobody2020"));
    assert!(
        e.contains("sources.emissivity names `nobody2020`, which is not in `sources`"),
        "{e}"
    );
    let e =
        broken(|v| material(v, "water")["layers"][0]["sources"]["density_kg_per_m3"] = json!("x"));
    assert!(
        e.contains("layers[0].sources.density_kg_per_m3 names `x`"),
        "{e}"
    );
    let e = broken(|v| material(v, "water")["nir_reflectance"] = json!(0.05));
    assert!(
        e.contains("material `water` (id 12): nir_reflectance has no source"),
        "{e}"
    );
    let e = broken(|v| material(v, "water")["sources"]["albedo"] = json!("choice"));
    assert!(
        e.contains("sources names `albedo`, which is not a number here"),
        "{e}"
    );
    let e = broken(|v| {
        material(v, "roof_metal")["bottom"]["sources"]
            .as_object_mut()
            .unwrap()
            .remove("h_w_per_m2_k");
    });
    assert!(
        e.contains("material `roof_metal` (id 15): bottom.h_w_per_m2_k has no source"),
        "{e}"
    );
    let e = broken(|v| v["sources"][1]["id"] = json!("cook2013"));
    assert!(e.contains("source id `cook2013` is given twice"), "{e}");
}

#[test]
fn radar_models_are_checked_and_evaluated() {
    let ud = json!({"model": "ulaby_dobson", "band": "X", "polarisation": "vv",
        "p": [-10.0, 5.0, 1.0, 2.0, 1.0, 0.0], "incidence_deg": [0.0, 70.0], "source": "choice"});
    let gamma =
        json!({"model": "constant_gamma", "band": "C", "gamma_db": -15.0, "source": "choice"});
    let mut v = default_json();
    material(&mut v, "grass")["radar"]["models"] = json!([ud, gamma]);
    let t = MaterialTable::parse(&v.to_string(), Path::new("m.json")).unwrap();
    let models = &t.by_name("grass").unwrap().radar.models;
    // P1 + P2·e^0 + P4·cos 0 at normal incidence.
    assert!((models[0].sigma0_db(0.0) - -3.0).abs() < 1e-12);
    let t1 = 1.0f64;
    let want = -10.0 + 5.0 * (-t1).exp() + 2.0 * t1.cos();
    assert!((models[0].sigma0_db(t1.to_degrees()) - want).abs() < 1e-12);
    // γ·cos 60° is γ − 3.01 dB.
    assert!((models[1].sigma0_db(60.0) - (-15.0 - 3.0103)).abs() < 1e-4);

    let with = |model: Value| {
        move |v: &mut Value| material(v, "grass")["radar"]["models"] = json!([model])
    };
    let mut bad = ud.clone();
    bad["incidence_deg"] = json!([40.0, 10.0]);
    assert!(broken(with(bad)).contains("radar.models[0].incidence_deg is [40, 10]"));
    let mut bad = ud.clone();
    bad["source"] = json!("folklore");
    assert!(broken(with(bad)).contains("radar.models[0].source `folklore` is not in `sources`"));
    let e =
        broken(|v| material(v, "grass")["radar"]["models"] = json!([gamma.clone(), gamma.clone()]));
    assert!(
        e.contains("radar.models[1]: a second model for the same band"),
        "{e}"
    );
    let mut bad = gamma.clone();
    bad["band"] = json!("Q");
    assert!(broken(with(bad)).contains("not a valid material table"));
}

#[test]
fn landcover_mappings_must_name_materials_and_sources() {
    let e = broken(|v| v["landcover"][1]["classes"][0]["material"] = json!("ocean"));
    assert!(
        e.contains("land-cover legend `nlcd`: class 11 maps to `ocean`, which is not a material"),
        "{e}"
    );
    let e = broken(|v| v["landcover"][0]["classes"][1]["code"] = json!(10));
    assert!(
        e.contains("land-cover legend `esa_worldcover`: class 10 is given twice"),
        "{e}"
    );
    let e = broken(|v| v["landcover"][0]["source"] = json!("esa"));
    assert!(
        e.contains("land-cover legend `esa_worldcover`: source `esa` is not in `sources`"),
        "{e}"
    );
    let e = broken(|v| v["landcover"][1]["legend"] = json!("esa_worldcover"));
    assert!(
        e.contains("land-cover legend `esa_worldcover` is given twice"),
        "{e}"
    );
}

#[test]
fn the_version_and_unknown_fields_are_checked() {
    let e = broken(|v| v["version"] = json!(2));
    assert!(e.contains("version is 2, not 1"), "{e}");
    let e = broken(|v| material(v, "sand")["albedo"] = json!(0.3));
    assert!(e.contains("unknown field `albedo`"), "{e}");
}
