//! GeoJSON polygon features, as the footprint and building files hold them (plain serde_json).
//!
//! Invariant: a polygon comes back as rings of finite `(x, y)` vertices in the file's CRS, in
//! file order (outer ring first, then holes); a non-numeric or non-finite coordinate is an
//! error, never silently dropped. Validation beyond that (ring sizes, areas, crossings) belongs
//! to the caller, which knows what it needs.

use crate::error::{Error, Result};
use serde_json::Value;
use std::path::Path;

/// A ring of `(x, y)` vertices, CRS units.
pub type Ring = Vec<(f64, f64)>;

/// The features of a GeoJSON FeatureCollection file; `fix` is the advice when the file is not one.
pub fn read_features(path: &Path, fix: &str) -> Result<Vec<Value>> {
    let text = std::fs::read_to_string(path).map_err(|e| Error::io(path, e))?;
    let doc: Value = serde_json::from_str(&text)
        .map_err(|e| Error::file(path, format!("not valid JSON ({e})")).fix(fix))?;
    match doc.get("features").and_then(Value::as_array) {
        Some(features) => Ok(features.clone()),
        None => {
            Err(Error::file(path, "not a GeoJSON FeatureCollection (no features array)").fix(fix))
        }
    }
}

/// The polygons of a Polygon or MultiPolygon geometry, each as its rings; or why it has none.
pub fn polygons(geometry: &Value) -> std::result::Result<Vec<Vec<Ring>>, String> {
    let coords = geometry
        .get("coordinates")
        .ok_or("geometry has no coordinates")?;
    let parts: Vec<&Value> = match geometry.get("type").and_then(Value::as_str) {
        Some("Polygon") => vec![coords],
        Some("MultiPolygon") => coords
            .as_array()
            .ok_or("bad MultiPolygon coordinates")?
            .iter()
            .collect(),
        other => {
            return Err(format!(
                "geometry type {other:?} is not Polygon or MultiPolygon"
            ))
        }
    };
    parts
        .into_iter()
        .map(|p| {
            rings(p).ok_or_else(|| {
                "bad polygon coordinates (need [[[x, y], ...], ...] of finite numbers)".to_string()
            })
        })
        .collect()
}

fn rings(poly: &Value) -> Option<Vec<Ring>> {
    poly.as_array()?
        .iter()
        .map(|ring| {
            ring.as_array()?
                .iter()
                .map(|p| {
                    let p = p.as_array()?;
                    let (x, y) = (p.first()?.as_f64()?, p.get(1)?.as_f64()?);
                    (x.is_finite() && y.is_finite()).then_some((x, y))
                })
                .collect()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn polygons_and_multipolygons_keep_rings_in_order() {
        let sq = json!([
            [[0, 0], [2, 0], [2, 2], [0, 2], [0, 0]],
            [[0.5, 0.5], [1, 0.5], [1, 1], [0.5, 0.5]]
        ]);
        let p = polygons(&json!({"type": "Polygon", "coordinates": sq})).unwrap();
        assert_eq!(p.len(), 1);
        assert_eq!(p[0].len(), 2);
        assert_eq!(p[0][1][1], (1.0, 0.5));
        let m = polygons(&json!({"type": "MultiPolygon", "coordinates": [sq, sq]})).unwrap();
        assert_eq!(m.len(), 2);
    }

    #[test]
    fn bad_coordinates_are_errors_not_dropped_points() {
        for g in [
            json!({"type": "Polygon", "coordinates": [[[0, 0], ["a", 1], [1, 1]]]}),
            json!({"type": "Polygon", "coordinates": [[[0, 0], [1], [1, 1]]]}),
            json!({"type": "Point", "coordinates": [0, 0]}),
            json!({"type": "Polygon"}),
            Value::Null,
        ] {
            assert!(polygons(&g).is_err(), "{g}");
        }
    }
}
