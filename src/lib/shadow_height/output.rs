//! The heights GeoJSON (`dbms shadow-height -o`) and the database's `buildings` layer (`--apply`).
//!
//! Invariant: one output feature per input feature, in input order, geometry as given moved by
//! the registration shift that was applied (none: unchanged), input properties kept (ours
//! replace same-named ones); the added properties are those of `schemas/heights.schema.json`.
//! The `buildings` layer holds only the measured features, each with a numeric `roof_z` (what
//! [`crate::standing::read_buildings`] reads).

use super::{InputFeature, Measurement, Registration};
use crate::db::{Database, Stage};
use crate::error::{Error, Result};
use crate::io::atomic::write_bytes_atomic;
use crate::sun::Sun;
use serde_json::{json, Map, Value};

/// The output FeatureCollection. `results[k]` belongs to `features[k]`: a measurement, or why
/// the feature could not be measured (bad footprint or outside the grid). `registration` has
/// one estimate per *valid* feature, in order; its applied shift is recorded at the top and
/// in each measured feature (`footprint_shift_m`), the geometry is moved by it (where the
/// heights were measured), and each building's own estimate is `own_shift_m`.
pub fn heights_geojson(
    features: &[InputFeature],
    results: &[std::result::Result<Measurement, String>],
    registration: &Registration,
    sun: &Sun,
    epsg: Option<u32>,
) -> Value {
    let (east, north) = registration.applied();
    let mut own = registration.buildings.iter().zip(&registration.leans);
    let out: Vec<Value> = features
        .iter()
        .zip(results)
        .map(|(f, r)| {
            let mut p: Map<String, Value> = f.properties.as_object().cloned().unwrap_or_default();
            let (own, lean) = match f.footprint.is_ok().then(|| own.next()).flatten() {
                Some((s, l)) => (*s, *l),
                None => (None, (0.0, 0.0)),
            };
            let mut geometry = f.geometry.clone();
            if f.footprint.is_ok() {
                translate(&mut geometry, east, north);
            }
            match r {
                Ok(m) => {
                    p.insert("footprint_shift_m".into(), json!([east, north]));
                    p.insert("lean_m".into(), json!([lean.0, lean.1]));
                    p.insert(
                        "own_shift_m".into(),
                        json!(own.map(|s| json!({ "east": s.east_m, "north": s.north_m, "peak_ratio": s.peak_ratio }))),
                    );
                    p.insert("height_m".into(), json!(m.height_m));
                    p.insert("roof_z".into(), json!(m.roof_z));
                    let [i68, i95] = m.roof_z_intervals.map_or([None; 2], |iv| iv.map(Some));
                    p.insert("roof_z_interval_68".into(), json!(i68.map(|(a, b)| [a, b])));
                    p.insert("roof_z_interval_95".into(), json!(i95.map(|(a, b)| [a, b])));
                    p.insert("roof_z_at_least".into(), json!(m.roof_z_at_least));
                    p.insert("initial_height_m".into(), json!(m.initial_height_m));
                    p.insert("overlap".into(), json!(m.overlap));
                    p.insert("uncertainty_m".into(), json!(m.uncertainty_m));
                    p.insert("ground_z".into(), json!(m.ground_z));
                    p.insert("shadow_length_m".into(), json!(m.shadow_length_m));
                    p.insert(
                        "scan_lines".into(),
                        json!({ "total": m.lines_total, "used": m.lines_used, "roof_z_quartiles": m.line_roofs }),
                    );
                    p.insert("shadow_threshold".into(), json!(m.threshold));
                    p.insert("flags".into(), json!(m.flags.names()));
                    if let Some(pitch) = m.pitch {
                        pitch.to_properties(&mut p);
                    }
                }
                Err(e) => {
                    p.insert("height_m".into(), Value::Null);
                    p.insert("roof_z".into(), Value::Null);
                    p.insert("error".into(), json!(e));
                }
            }
            json!({ "type": "Feature", "properties": p, "geometry": geometry })
        })
        .collect();
    let mut doc = json!({
        "type": "FeatureCollection",
        "name": "heights",
        "sun": { "elevation_deg": sun.elevation_deg, "azimuth_deg": sun.azimuth_deg },
        "footprint_shift": registration.scene.map(|(e, n, k)| json!({ "east_m": e, "north_m": n, "buildings": k })),
        "camera": registration.camera.map(|(c, estimated)| json!({ "east": c.east, "north": c.north, "z": c.z, "estimated": estimated })),
        "features": out,
    });
    if let Some(code) = epsg {
        doc["crs"] = json!({ "type": "name", "properties": { "name": format!("urn:ogc:def:crs:EPSG::{code}") } });
    }
    doc
}

/// Move every position of a GeoJSON geometry by `(east, north)` (nested coordinate arrays,
/// down to the `[x, y, ...]` positions).
fn translate(geometry: &mut Value, east: f64, north: f64) {
    fn walk(v: &mut Value, east: f64, north: f64) {
        if let Some(a) = v.as_array_mut() {
            if a.first().is_some_and(Value::is_number) {
                if let (Some(x), Some(y)) = (a[0].as_f64(), a.get(1).and_then(Value::as_f64)) {
                    a[0] = json!(x + east);
                    a[1] = json!(y + north);
                }
            } else {
                a.iter_mut().for_each(|x| walk(x, east, north));
            }
        }
    }
    if east != 0.0 || north != 0.0 {
        if let Some(c) = geometry.get_mut("coordinates") {
            walk(c, east, north);
        }
    }
}

/// The `buildings` layer: the features of a heights document that have a numeric `roof_z`.
pub fn buildings_layer(heights: &Value) -> Value {
    let mut doc = heights.clone();
    if let Some(fs) = doc.get_mut("features").and_then(|f| f.as_array_mut()) {
        fs.retain(|f| f.pointer("/properties/roof_z").is_some_and(|z| z.is_f64()));
    }
    doc["name"] = json!(crate::db::BUILDINGS);
    doc
}

/// One result per input feature, in input order: the measurement of each valid footprint
/// (`measured` holds them in the order of the valid footprints), or the reason a feature's
/// footprint is unusable.
pub fn per_feature(
    features: &[InputFeature],
    measured: Vec<std::result::Result<Measurement, String>>,
) -> Vec<std::result::Result<Measurement, String>> {
    let mut measured = measured.into_iter();
    features
        .iter()
        .map(|f| {
            f.footprint
                .as_ref()
                .map_err(|e| e.clone())
                .and_then(|_| measured.next().expect("one result per valid footprint"))
        })
        .collect()
}

/// Record measured buildings in the database at `measured_from.dir`: its `buildings` layer
/// ([`buildings_layer`] of the heights document `heights`) and a `shadow-height` stage with
/// `params`, as one change under the database's lock (waiting up to `wait`), from the manifest
/// as it is now — changes made while the heights were measured are kept, unless they replaced
/// the elevation or colour layer measured from (`measured_from`'s), which is an error.
pub fn apply_buildings(
    measured_from: &Database,
    heights: &Value,
    params: Value,
    wait: std::time::Duration,
) -> Result<()> {
    let mut change = Database::begin(&measured_from.dir, wait, &[])?;
    for layer in [crate::db::ELEVATION, crate::db::COLOUR] {
        if change.db.manifest.layers.get(layer) != measured_from.manifest.layers.get(layer) {
            return Err(Error::file(
                &measured_from.dir,
                format!("its {layer} layer was replaced while the heights were measured"),
            )
            .fix("run shadow-height again"));
        }
    }
    let layer = to_text(&buildings_layer(heights));
    change.write_layer(crate::db::BUILDINGS, "buildings", "geojson", |path| {
        write_bytes_atomic(path, layer.as_bytes())?;
        Ok(None)
    })?;
    change.db.record_stage(Stage::now("shadow-height", params));
    change.commit()
}

/// Write `doc` to `out` as the files hold it: pretty JSON with a final newline, streamed
/// (the text is never held whole).
pub fn write_text(doc: &Value, out: &mut impl std::io::Write) -> std::io::Result<()> {
    serde_json::to_writer_pretty(&mut *out, doc)?;
    out.write_all(b"\n")
}

/// [`write_text`]'s text as a string.
pub fn to_text(doc: &Value) -> String {
    let mut bytes = Vec::new();
    write_text(doc, &mut bytes).expect("a Vec takes every write");
    String::from_utf8(bytes).expect("serde_json writes UTF-8")
}
