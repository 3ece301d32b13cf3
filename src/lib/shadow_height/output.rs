//! The heights GeoJSON (`dbms shadow-height -o`) and the database's `buildings` layer (`--apply`).
//!
//! Invariant: one output feature per input feature, in input order, geometry unchanged, input
//! properties kept (ours replace same-named ones); the added properties are those of
//! `schemas/heights.schema.json`. The `buildings` layer holds only the measured features, each
//! with a numeric `roof_z` (what [`crate::pyramid::raised::read_buildings`] reads).

use super::{InputFeature, Measurement};
use crate::shadow::Sun;
use serde_json::{json, Map, Value};

/// The output FeatureCollection. `results[k]` belongs to `features[k]`: a measurement, or why
/// the feature could not be measured (bad footprint or outside the grid).
pub fn heights_geojson(
    features: &[InputFeature],
    results: &[std::result::Result<Measurement, String>],
    sun: &Sun,
    epsg: Option<u32>,
) -> Value {
    let out: Vec<Value> = features
        .iter()
        .zip(results)
        .map(|(f, r)| {
            let mut p: Map<String, Value> = f.properties.as_object().cloned().unwrap_or_default();
            match r {
                Ok(m) => {
                    p.insert("height_m".into(), json!(m.height_m));
                    p.insert("roof_z".into(), json!(m.roof_z));
                    p.insert("initial_height_m".into(), json!(m.initial_height_m));
                    p.insert("overlap".into(), json!(m.overlap));
                    p.insert("uncertainty_m".into(), json!(m.uncertainty_m));
                    p.insert("ground_z".into(), json!(m.ground_z));
                    p.insert("shadow_length_m".into(), json!(m.shadow_length_m));
                    p.insert(
                        "scan_lines".into(),
                        json!({ "total": m.lines_total, "used": m.lines_used }),
                    );
                    p.insert("shadow_threshold".into(), json!(m.threshold));
                    p.insert("flags".into(), json!(m.flags.names()));
                }
                Err(e) => {
                    p.insert("height_m".into(), Value::Null);
                    p.insert("roof_z".into(), Value::Null);
                    p.insert("error".into(), json!(e));
                }
            }
            json!({ "type": "Feature", "properties": p, "geometry": f.geometry })
        })
        .collect();
    let mut doc = json!({
        "type": "FeatureCollection",
        "name": "heights",
        "sun": { "elevation_deg": sun.elevation_deg, "azimuth_deg": sun.azimuth_deg },
        "features": out,
    });
    if let Some(code) = epsg {
        doc["crs"] = json!({ "type": "name", "properties": { "name": format!("urn:ogc:def:crs:EPSG::{code}") } });
    }
    doc
}

/// The `buildings` layer: the features of a heights document that have a numeric `roof_z`.
pub fn buildings_layer(heights: &Value) -> Value {
    let mut doc = heights.clone();
    if let Some(fs) = doc.get_mut("features").and_then(|f| f.as_array_mut()) {
        fs.retain(|f| f.pointer("/properties/roof_z").is_some_and(|z| z.is_f64()));
    }
    doc["name"] = json!("buildings");
    doc
}

/// Pretty JSON text with a final newline (what the files hold).
pub fn to_text(doc: &Value) -> String {
    let mut s = serde_json::to_string_pretty(doc).expect("JSON value serialises");
    s.push('\n');
    s
}
