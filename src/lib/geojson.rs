//! GeoJSON polygon features, as the footprint and building files hold them (plain serde_json).
//!
//! Invariant: a polygon comes back as rings of finite `(x, y)` vertices in the file's CRS, in
//! file order (outer ring first, then holes); a non-numeric or non-finite coordinate is an
//! error, never silently dropped. Validation beyond that (ring sizes, areas, crossings) belongs
//! to the caller, which knows what it needs.

use crate::error::{Error, Result};
use crate::grid::{Bounds, Grid};
use serde_json::Value;
use std::path::Path;

/// A ring of `(x, y)` vertices, CRS units.
pub type Ring = Vec<(f64, f64)>;

/// The features of a GeoJSON FeatureCollection file; `fix` is the advice when the file is not one.
/// A leading UTF-8 byte order mark is skipped ([`crate::io::read_text`]).
pub fn read_features(path: &Path, fix: &str) -> Result<Vec<Value>> {
    let text = crate::io::read_text(path)?;
    let mut doc: Value = serde_json::from_str(&text)
        .map_err(|e| Error::file(path, format!("not valid JSON ({e})")).fix(fix))?;
    // Moved out, not cloned: a city's footprints are hundreds of MB as JSON values.
    match doc.get_mut("features").map(Value::take) {
        Some(Value::Array(features)) => Ok(features),
        _ => Err(Error::file(path, "not a GeoJSON FeatureCollection (no features array)").fix(fix)),
    }
}

/// Refuse the vertices `points` of the vector file `path` when they look like longitude and
/// latitude on a projected `grid`: all within ±180, ±90 while the grid lies wholly outside
/// that range (a UTM grid's coordinates are hundreds of thousands of metres). GeoJSON is
/// lon/lat by its standard (RFC 7946), so this is the usual mistake, and without this check
/// every feature would fail on its own as outside the grid. No points: nothing to check.
pub fn require_grid_crs(
    path: &Path,
    grid: &Grid,
    points: impl IntoIterator<Item = (f64, f64)>,
) -> Result<()> {
    let degrees = Bounds {
        min_x: -180.0,
        min_y: -90.0,
        max_x: 180.0,
        max_y: 90.0,
    };
    let inside = |b: &Bounds, (x, y): (f64, f64)| {
        (b.min_x..=b.max_x).contains(&x) && (b.min_y..=b.max_y).contains(&y)
    };
    let db = grid.bounds();
    let mut points = points.into_iter().peekable();
    let some = points.peek().is_some();
    if grid.crs.geographic
        || db.intersection(&degrees).is_some()
        || !(some && points.all(|p| inside(&degrees, p)))
    {
        return Ok(());
    }
    let crs = grid.crs.name();
    Err(Error::file(
        path,
        format!(
            "coordinates look like longitude/latitude degrees (all within ±180, ±90), but the database is in {crs}, extent [{}, {}, {}, {}]",
            db.min_x, db.min_y, db.max_x, db.max_y
        ),
    )
    .fix(format!(
        "reproject the file to the database's CRS: ogr2ogr -t_srs {} out.geojson {}",
        grid.crs.epsg.map_or("<the database's CRS>".to_string(), |c| format!("EPSG:{c}")),
        path.display()
    )))
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

/// The polylines of a LineString or MultiLineString geometry, each as its vertices (at least
/// two); or why it has none.
pub fn lines(geometry: &Value) -> std::result::Result<Vec<Ring>, String> {
    let coords = geometry
        .get("coordinates")
        .ok_or("geometry has no coordinates")?;
    let parts = match geometry.get("type").and_then(Value::as_str) {
        Some("LineString") => Some(vec![coords.clone()]),
        Some("MultiLineString") => coords.as_array().cloned(),
        other => {
            return Err(format!(
                "geometry type {other:?} is not LineString or MultiLineString"
            ))
        }
    };
    let bad = || "bad line coordinates (need [[x, y], [x, y], ...] of finite numbers)".to_string();
    let lines = rings(&Value::Array(parts.ok_or_else(bad)?)).ok_or_else(bad)?;
    match lines.iter().all(|l| l.len() >= 2) {
        true => Ok(lines),
        false => Err("a line has fewer than two vertices".into()),
    }
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
    fn lines_and_multilines() {
        let one = json!({"type": "LineString", "coordinates": [[0, 0], [1, 2]]});
        assert_eq!(lines(&one).unwrap(), vec![vec![(0.0, 0.0), (1.0, 2.0)]]);
        let two = json!({"type": "MultiLineString", "coordinates": [[[0, 0], [1, 0]], [[5, 5], [6, 6], [7, 5]]]});
        assert_eq!(lines(&two).unwrap().len(), 2);
        let short = json!({"type": "LineString", "coordinates": [[0, 0]]});
        assert!(lines(&short).unwrap_err().contains("fewer than two"));
        let text = json!({"type": "LineString", "coordinates": [[0, "a"], [1, 2]]});
        assert!(lines(&text).unwrap_err().contains("finite numbers"));
        let point = json!({"type": "Point", "coordinates": [0, 0]});
        assert!(lines(&point).unwrap_err().contains("not LineString"));
    }

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

    /// Lon/lat vertices on a UTM grid are one CRS error; on a geographic grid, or a local grid
    /// near the origin, they are not.
    #[test]
    fn lon_lat_on_a_projected_grid_is_a_crs_error() {
        use crate::crs::Crs;
        let utm = Grid::north_up(500_000.0, 5_300_000.0, 1.0, 100, 100, Crs::epsg(32632));
        let lon_lat = [(9.0, 47.85), (9.001, 47.85), (9.001, 47.851)];
        let e = require_grid_crs(Path::new("f.geojson"), &utm, lon_lat)
            .unwrap_err()
            .to_string();
        assert!(
            e.starts_with("f.geojson: coordinates look like longitude/latitude degrees"),
            "{e}"
        );
        assert!(
            e.contains("EPSG:32632") && e.contains("ogr2ogr -t_srs EPSG:32632"),
            "{e}"
        );
        let geo = Grid::north_up(9.0, 48.0, 0.001, 100, 100, Crs::epsg(4326));
        let local = Grid::north_up(0.0, 100.0, 1.0, 100, 100, Crs::unknown());
        for g in [&geo, &local] {
            assert!(require_grid_crs(Path::new("f"), g, lon_lat).is_ok());
        }
        let metres = [(500_010.0, 5_299_990.0), (5.0, 5.0)];
        assert!(require_grid_crs(Path::new("f"), &utm, metres).is_ok());
        assert!(require_grid_crs(Path::new("f"), &utm, []).is_ok());
    }

    /// A file that starts with a UTF-8 byte order mark reads like one without.
    #[test]
    fn a_byte_order_mark_is_skipped() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("bom.geojson");
        std::fs::write(
            &p,
            "\u{feff}{\"type\": \"FeatureCollection\", \"features\": [{}]}",
        )
        .unwrap();
        assert_eq!(read_features(&p, "fix").unwrap().len(), 1);
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
