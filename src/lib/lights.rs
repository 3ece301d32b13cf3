//! Light points from a GeoJSON point layer, stood on the terrain: the runway and street lights the
//! night sensors show (issue 18).
//!
//! Invariant: every light read lies inside the grid, over valid terrain, with a finite height and
//! a positive intensity; a feature that breaks a rule is a one-line error naming the file, the
//! feature and the fix, never skipped.
//!
//! A feature is a `Point` or `MultiPoint` with properties `intensity_cd` (candela, > 0,
//! required), `height_m` (metres above the terrain, ≥ 0, default 0) and `colour` (`[r, g, b]`,
//! 0–255, default white) and `beam` (a directional lamp: `azimuth_deg`, `elevation_deg`,
//! `spread_deg` as [`Beam`] defines them; default: the same intensity every way). A third
//! coordinate is the lamp's height itself (metres), and then `height_m` must be absent.

use crate::error::{Error, Result};
use crate::raster::{band_rows, RowSource};
use crate::standing::{TerrainAt, TerrainSample};
use crate::tiles::{Beam, LightPoint};
use serde_json::Value;
use std::path::Path;

/// The lights of the GeoJSON file `path`, their heights over `terrain` (metres, NaN nodata).
pub fn read(path: &Path, terrain: &dyn RowSource<f32>) -> Result<Vec<LightPoint>> {
    let fix = "give a GeoJSON FeatureCollection of Point features with intensity_cd (candela)";
    let features = crate::geojson::read_features(path, fix)?;
    let grid = terrain.grid();
    let mut lights = Vec::new();
    // Each light's feature, cell and height rule, for the terrain read below.
    let mut placed = Vec::new();
    for (k, f) in features.iter().enumerate() {
        let bad = |problem: String| Error::file(path, format!("feature {k}: {problem}"));
        let props = f.get("properties").cloned().unwrap_or(Value::Null);
        let intensity_cd = props
            .get("intensity_cd")
            .and_then(Value::as_f64)
            .filter(|v| *v > 0.0 && v.is_finite())
            .ok_or_else(|| {
                bad("has no positive number intensity_cd".into())
                    .fix("give each light its luminous intensity in candela, e.g. \"intensity_cd\": 1500")
            })?;
        let height_m = match props.get("height_m") {
            None | Some(Value::Null) => None,
            Some(v) => Some(
                v.as_f64()
                    .filter(|h| *h >= 0.0 && h.is_finite())
                    .ok_or_else(|| {
                        bad(format!("height_m {v} is not a number of metres ≥ 0"))
                            .fix("e.g. \"height_m\": 8")
                    })?,
            ),
        };
        let colour = match props.get("colour") {
            None | Some(Value::Null) => [255, 255, 255],
            Some(v) => colour_of(v).ok_or_else(|| {
                bad(format!("colour {v} is not [r, g, b] of 0–255"))
                    .fix("e.g. \"colour\": [255, 200, 120]")
            })?,
        };
        let beam = match props.get("beam") {
            None | Some(Value::Null) => None,
            Some(v) => Some(beam_of(v).ok_or_else(|| {
                bad(format!("beam {v} is not {{azimuth_deg, elevation_deg (−90 to 90), spread_deg (a number or [horizontal, vertical], each > 0 and ≤ 360)}}"))
                    .fix("e.g. \"beam\": {\"azimuth_deg\": 270, \"elevation_deg\": 3, \"spread_deg\": [12, 8]}")
            })?),
        };
        let points = points(f.get("geometry").unwrap_or(&Value::Null))
            .map_err(|e| bad(e).fix("lights are Point or MultiPoint features"))?;
        crate::geojson::require_grid_crs(path, grid, points.iter().map(|p| (p[0], p[1])))?;
        for p in points {
            let (x, y) = (p[0], p[1]);
            let (col, row) = grid.cell_at(x, y).ok_or_else(|| {
                bad(format!(
                    "the light at ({x}, {y}) is outside the database grid"
                ))
                .fix("remove it, or give the database's CRS coordinates")
            })?;
            let height = match (p.get(2), height_m) {
                (Some(_), Some(_)) => {
                    return Err(bad("has both a third coordinate and height_m".into())
                        .fix("give the lamp's height one way: z in the coordinates or height_m above the terrain"))
                }
                (Some(&z), None) => Height::Absolute(z),
                (None, h) => Height::AboveTerrain(h.unwrap_or(0.0)),
            };
            placed.push((k, row * grid.width + col, height));
            lights.push(LightPoint {
                x,
                y,
                z: f64::NAN,
                intensity_cd,
                colour,
                beam,
            });
        }
    }
    // The terrain under the lights, each band that holds one read once.
    let under = placed.iter().filter_map(|&(_, i, h)| match h {
        Height::AboveTerrain(_) => Some(i),
        Height::Absolute(_) => None,
    });
    let under = under.collect();
    let ground = TerrainSample::read(terrain, under, band_rows(grid.width))?;
    for (light, &(k, i, height)) in lights.iter_mut().zip(&placed) {
        light.z = match height {
            Height::Absolute(z) => z,
            Height::AboveTerrain(h) if !ground.at(i).is_nan() => f64::from(ground.at(i)) + h,
            Height::AboveTerrain(_) => {
                return Err(Error::file(
                    path,
                    format!(
                        "feature {k}: the light at ({}, {}) stands on nodata terrain",
                        light.x, light.y
                    ),
                )
                .fix("move it onto the terrain, or give its height as a third coordinate"))
            }
        };
    }
    Ok(lights)
}

/// How high a lamp is.
#[derive(Debug, Clone, Copy)]
enum Height {
    /// Metres, as given.
    Absolute(f64),
    /// Metres above the terrain under it.
    AboveTerrain(f64),
}

/// A beam: `azimuth_deg`, `elevation_deg` and `spread_deg` (one number for both directions or
/// `[horizontal, vertical]`), within [`Beam::is_valid`]'s ranges.
fn beam_of(v: &Value) -> Option<Beam> {
    let num = |k: &str| v.get(k).and_then(Value::as_f64);
    let spread = match v.get("spread_deg")? {
        Value::Array(a) if a.len() == 2 => [a[0].as_f64()?, a[1].as_f64()?],
        s => [s.as_f64()?; 2],
    };
    let beam = Beam {
        azimuth_deg: num("azimuth_deg")?,
        elevation_deg: num("elevation_deg")?,
        spread_deg: spread,
    };
    let known = ["azimuth_deg", "elevation_deg", "spread_deg"];
    let only_known = v.as_object()?.keys().all(|k| known.contains(&k.as_str()));
    (only_known && beam.is_valid()).then_some(beam)
}

/// `[r, g, b]` of integers 0–255.
fn colour_of(v: &Value) -> Option<[u8; 3]> {
    let a = v.as_array().filter(|a| a.len() == 3)?;
    let c = |k: usize| a[k].as_u64().filter(|c| *c <= 255).map(|c| c as u8);
    Some([c(0)?, c(1)?, c(2)?])
}

/// The finite coordinates (2 or 3 each) of a Point or MultiPoint geometry, or why there are none.
fn points(geometry: &Value) -> std::result::Result<Vec<Vec<f64>>, String> {
    let coords = geometry.get("coordinates");
    let one = |c: &Value| -> std::result::Result<Vec<f64>, String> {
        let v: Option<Vec<f64>> = c
            .as_array()
            .filter(|a| (2..=3).contains(&a.len()))
            .and_then(|a| a.iter().map(Value::as_f64).collect());
        v.filter(|v| v.iter().all(|x| x.is_finite()))
            .ok_or_else(|| format!("coordinate {c} is not 2 or 3 finite numbers"))
    };
    match (geometry.get("type").and_then(Value::as_str), coords) {
        (Some("Point"), Some(c)) => Ok(vec![one(c)?]),
        (Some("MultiPoint"), Some(Value::Array(cs))) => cs.iter().map(one).collect(),
        (t, _) => Err(format!(
            "geometry {} is not a Point or MultiPoint",
            t.unwrap_or("(none)")
        )),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::crs::Crs;
    use crate::grid::Grid;
    use crate::raster::Raster;

    fn terrain() -> Raster<f32> {
        let grid = Grid::north_up(1000.0, 2010.0, 1.0, 10, 10, Crs::epsg(32632));
        let mut z: Vec<f32> = (0..100).map(|i| 50.0 + i as f32).collect();
        z[0] = f32::NAN;
        Raster::new(grid, z)
    }

    fn file(dir: &Path, features: Value) -> std::path::PathBuf {
        let path = dir.join("l.geojson");
        let doc = serde_json::json!({"type": "FeatureCollection", "features": features});
        std::fs::write(&path, doc.to_string()).unwrap();
        path
    }

    #[test]
    fn lights_stand_on_the_terrain_or_at_their_given_height() {
        let t = tempfile::tempdir().unwrap();
        let path = file(
            t.path(),
            serde_json::json!([
                {"type": "Feature", "properties": {"intensity_cd": 1500, "height_m": 8},
                 "geometry": {"type": "Point", "coordinates": [1003.5, 2008.5]}},
                {"type": "Feature", "properties": {"intensity_cd": 40, "colour": [255, 0, 0],
                 "beam": {"azimuth_deg": 270, "elevation_deg": 3, "spread_deg": [12, 8]}},
                 "geometry": {"type": "MultiPoint", "coordinates": [[1001.2, 2002.2, 99.5], [1009.9, 2000.1]]}}
            ]),
        );
        let lights = read(&path, &terrain()).unwrap();
        assert_eq!(lights.len(), 3);
        // (1003.5, 2008.5): column 3, row 1 → 50 + 13, plus 8 m.
        assert_eq!((lights[0].z, lights[0].colour), (71.0, [255, 255, 255]));
        assert_eq!((lights[1].z, lights[1].colour), (99.5, [255, 0, 0]));
        let beam = Beam {
            azimuth_deg: 270.0,
            elevation_deg: 3.0,
            spread_deg: [12.0, 8.0],
        };
        assert_eq!((lights[0].beam, lights[2].beam), (None, Some(beam)));
        assert_eq!(lights[2].z, 50.0 + 99.0);
    }

    #[test]
    fn every_broken_rule_is_a_one_line_error_naming_the_feature() {
        let t = tempfile::tempdir().unwrap();
        let point = |props: Value, coords: Value| {
            serde_json::json!([{"type": "Feature", "properties": props,
                "geometry": {"type": "Point", "coordinates": coords}}])
        };
        for (features, want) in [
            (
                point(serde_json::json!({}), serde_json::json!([1003.0, 2005.0])),
                "intensity_cd",
            ),
            (
                point(
                    serde_json::json!({"intensity_cd": -1}),
                    serde_json::json!([1003.0, 2005.0]),
                ),
                "intensity_cd",
            ),
            (
                point(
                    serde_json::json!({"intensity_cd": 5, "height_m": -2}),
                    serde_json::json!([1003.0, 2005.0]),
                ),
                "height_m",
            ),
            (
                point(
                    serde_json::json!({"intensity_cd": 5, "colour": [1, 2]}),
                    serde_json::json!([1003.0, 2005.0]),
                ),
                "colour",
            ),
            (
                point(
                    serde_json::json!({"intensity_cd": 5}),
                    serde_json::json!([5.0, 2005.0]),
                ),
                "outside",
            ),
            (
                point(
                    serde_json::json!({"intensity_cd": 5}),
                    serde_json::json!([1000.5, 2009.5]),
                ),
                "nodata",
            ),
            (
                point(
                    serde_json::json!({"intensity_cd": 5, "height_m": 1}),
                    serde_json::json!([1003.0, 2005.0, 9.0]),
                ),
                "both",
            ),
            (
                point(
                    serde_json::json!({"intensity_cd": 5, "beam": {"azimuth_deg": 0, "elevation_deg": 95, "spread_deg": 10}}),
                    serde_json::json!([1003.0, 2005.0]),
                ),
                "beam",
            ),
            (
                point(
                    serde_json::json!({"intensity_cd": 5, "beam": {"azimuth_deg": 0, "elevation_deg": 5, "spread_deg": [10, 0]}}),
                    serde_json::json!([1003.0, 2005.0]),
                ),
                "beam",
            ),
            (
                point(
                    serde_json::json!({"intensity_cd": 5, "beam": {"azimuth": 0, "elevation_deg": 5, "spread_deg": 10}}),
                    serde_json::json!([1003.0, 2005.0]),
                ),
                "beam",
            ),
            (
                serde_json::json!([{"type": "Feature", "properties": {"intensity_cd": 5},
                "geometry": {"type": "LineString", "coordinates": [[1003.0, 2005.0], [1004.0, 2005.0]]}}]),
                "Point",
            ),
        ] {
            let e = read(&file(t.path(), features), &terrain())
                .unwrap_err()
                .to_string();
            assert!(
                e.contains("feature 0") && e.contains(want) && !e.contains('\n'),
                "{e}"
            );
        }
    }
}
