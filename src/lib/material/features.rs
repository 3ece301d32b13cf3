//! Vector features that say what the ground is made of: GeoJSON polygons (fields, water,
//! car parks) and lines with a width (roads, runways, rivers), each with a `material`.
//!
//! A feature is a GeoJSON Feature in the database's CRS with a string property `material`
//! (a name in the material table) and either a Polygon / MultiPolygon geometry (the cells
//! whose centres are inside it, even-odd: [`crate::standing::polygon_cells`]) or a LineString /
//! MultiLineString with a numeric `width_m` property (metres, > 0: the cells whose centres lie
//! within half the width of the line).
//!
//! Invariant (precedence among features): polygons are painted first, then lines, each in the
//! order given (files in order, features in file order); a later feature paints over an earlier
//! one. So a road drawn as a line crosses the field polygon under it.

use crate::error::{Error, Result};
use crate::grid::Grid;
use serde_json::Value;
use std::path::Path;

/// What one feature paints: a material name and the cells (indices into the grid) it covers.
#[derive(Debug, Clone, PartialEq)]
pub struct Painted {
    /// The feature's `material` property.
    pub material: String,
    /// Where it came from, for errors: `FILE: feature N`.
    pub origin: String,
    /// Indices of the cells it covers, row-major.
    pub cells: Vec<usize>,
}

/// The features of the GeoJSON files `paths`, in paint order (polygons, then lines; see the
/// module doc), rasterised onto `grid`.
pub fn read(paths: &[impl AsRef<Path>], grid: &Grid) -> Result<Vec<Painted>> {
    let (mut areas, mut lines) = (Vec::new(), Vec::new());
    for path in paths {
        let path = path.as_ref();
        let fix = "give a GeoJSON FeatureCollection of Polygon or LineString features, each with a material property (and width_m for lines)";
        let features = crate::geojson::read_features(path, fix)?;
        let mut points = Vec::new();
        for (i, f) in features.iter().enumerate() {
            let bad = |what: String| Error::file(path, format!("feature {i}: {what}")).fix(fix);
            let material = f
                .pointer("/properties/material")
                .and_then(Value::as_str)
                .ok_or_else(|| bad("no string material property".into()))?
                .to_string();
            let geometry = f
                .get("geometry")
                .filter(|g| !g.is_null())
                .ok_or_else(|| bad("no geometry".into()))?;
            let origin = format!("{}: feature {i}", path.display());
            let kind = geometry.get("type").and_then(Value::as_str).unwrap_or("");
            if kind.ends_with("LineString") {
                let width = f
                    .pointer("/properties/width_m")
                    .and_then(Value::as_f64)
                    .filter(|w| w.is_finite() && *w > 0.0)
                    .ok_or_else(|| {
                        bad("a line needs a positive numeric width_m property (metres)".into())
                    })?;
                let parts = crate::geojson::lines(geometry).map_err(bad)?;
                points.extend(parts.iter().flatten().copied());
                let cells = parts
                    .iter()
                    .flat_map(|line| line_cells(grid, line, width / 2.0))
                    .collect();
                lines.push(Painted {
                    material,
                    origin,
                    cells,
                });
            } else {
                let polygons = crate::geojson::polygons(geometry).map_err(bad)?;
                points.extend(polygons.iter().flatten().flatten().copied());
                let cells = polygons
                    .iter()
                    .flat_map(|rings| crate::standing::polygon_cells(grid, rings))
                    .collect();
                areas.push(Painted {
                    material,
                    origin,
                    cells,
                });
            }
        }
        crate::geojson::require_grid_crs(path, grid, points)?;
    }
    areas.append(&mut lines);
    Ok(areas)
}

/// The cells of `grid` whose centres lie within `half_width` (CRS units) of the polyline
/// `line`: for each segment, the centres in its box widened by the half width, by their
/// distance to the segment. A cell near a vertex shared by two segments is listed twice
/// (painting is idempotent).
pub fn line_cells(grid: &Grid, line: &[(f64, f64)], half_width: f64) -> Vec<usize> {
    let mut out = Vec::new();
    for seg in line.windows(2) {
        let [(x0, y0), (x1, y1)] = [seg[0], seg[1]];
        let (lo_x, hi_x) = (x0.min(x1) - half_width, x0.max(x1) + half_width);
        let (lo_y, hi_y) = (y0.min(y1) - half_width, y0.max(y1) + half_width);
        let t = &grid.transform;
        let (ca, ra) = t.world_to_pixel(lo_x, lo_y);
        let (cb, rb) = t.world_to_pixel(hi_x, hi_y);
        let span = |a: f64, b: f64, n: usize| {
            let lo = (a.min(b) - 0.5).floor().max(0.0).min(n as f64) as usize;
            let hi = (a.max(b) + 0.5).ceil().max(0.0).min(n as f64) as usize;
            lo..hi
        };
        let (dx, dy) = (x1 - x0, y1 - y0);
        let len2 = dx * dx + dy * dy;
        for row in span(ra, rb, grid.height) {
            for col in span(ca, cb, grid.width) {
                let (x, y) = grid.cell_centre(col, row);
                // The nearest point of the segment: clamp the projection to its ends.
                let k = match len2 > 0.0 {
                    true => (((x - x0) * dx + (y - y0) * dy) / len2).clamp(0.0, 1.0),
                    false => 0.0,
                };
                let (ex, ey) = (x - (x0 + k * dx), y - (y0 + k * dy));
                if ex * ex + ey * ey <= half_width * half_width {
                    out.push(grid.index(col, row));
                }
            }
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::crs::Crs;
    use std::collections::BTreeSet;

    /// 20 × 10 cells of 1 m, corner (1000, 2010), north-up.
    fn grid() -> Grid {
        Grid::north_up(1000.0, 2010.0, 1.0, 20, 10, Crs::epsg(32632))
    }

    fn write(dir: &Path, name: &str, features: Value) -> std::path::PathBuf {
        let path = dir.join(name);
        let doc = serde_json::json!({"type": "FeatureCollection", "features": features});
        std::fs::write(&path, doc.to_string()).unwrap();
        path
    }

    /// Every cell whose centre is within the half width, by brute force over the grid with the
    /// distance to each segment computed in another form (the perpendicular foot and the ends).
    fn brute(g: &Grid, line: &[(f64, f64)], hw: f64) -> BTreeSet<usize> {
        let mut out = BTreeSet::new();
        for row in 0..g.height {
            for col in 0..g.width {
                let (x, y) = g.cell_centre(col, row);
                let near = line.windows(2).any(|s| {
                    let (a, b) = (s[0], s[1]);
                    let d_end = |p: (f64, f64)| (x - p.0).hypot(y - p.1);
                    let (ux, uy) = (b.0 - a.0, b.1 - a.1);
                    let len = ux.hypot(uy);
                    let along = ((x - a.0) * ux + (y - a.1) * uy) / len;
                    let d = if (0.0..=len).contains(&along) {
                        ((x - a.0) * uy - (y - a.1) * ux).abs() / len
                    } else {
                        d_end(a).min(d_end(b))
                    };
                    d <= hw
                });
                if near {
                    out.insert(g.index(col, row));
                }
            }
        }
        out
    }

    #[test]
    fn line_cells_are_the_centres_within_half_the_width() {
        let g = grid();
        for (line, hw) in [
            (vec![(1002.3, 2001.0), (1017.9, 2008.2)], 1.5),
            (vec![(1000.0, 2005.0), (1020.0, 2005.0)], 0.5), // centres exactly at ±0.5 m
            (
                vec![(995.0, 1995.0), (1010.0, 2004.0), (1030.0, 2000.0)],
                2.2,
            ),
            (vec![(1005.5, 2005.5), (1005.5, 2005.5)], 1.0), // a point: a disc
        ] {
            let got: BTreeSet<usize> = line_cells(&g, &line, hw).into_iter().collect();
            assert_eq!(got, brute(&g, &line, hw), "{line:?} ± {hw}");
            assert!(!got.is_empty());
        }
    }

    #[test]
    fn polygons_first_then_lines_in_order() {
        let t = tempfile::tempdir().unwrap();
        let field = serde_json::json!({"type": "Feature", "properties": {"material": "grass"},
            "geometry": {"type": "Polygon", "coordinates": [[[1000, 2000], [1020, 2000], [1020, 2010], [1000, 2010], [1000, 2000]]]}});
        let road = serde_json::json!({"type": "Feature", "properties": {"material": "asphalt", "width_m": 2.0},
            "geometry": {"type": "LineString", "coordinates": [[1000, 2005], [1020, 2005]]}});
        // The road comes first in the file and still paints over the field.
        let path = write(t.path(), "f.geojson", serde_json::json!([road, field]));
        let painted = read(&[&path], &grid()).unwrap();
        let names: Vec<&str> = painted.iter().map(|p| p.material.as_str()).collect();
        assert_eq!(names, ["grass", "asphalt"]);
        assert_eq!(painted[0].cells.len(), 200);
        // Rows whose centres are 2004.5 and 2005.5: within 1 m of y = 2005.
        assert_eq!(painted[1].cells.len(), 40);
        assert!(painted[1].origin.ends_with("f.geojson: feature 0"));
    }

    #[test]
    fn bad_features_are_one_line_errors() {
        let t = tempfile::tempdir().unwrap();
        let g = grid();
        let poly = serde_json::json!({"type": "Polygon", "coordinates": [[[1000, 2000], [1005, 2000], [1005, 2005], [1000, 2000]]]});
        let line =
            serde_json::json!({"type": "LineString", "coordinates": [[1000, 2005], [1020, 2005]]});
        let cases = [
            (
                serde_json::json!({"type": "Feature", "properties": {}, "geometry": poly}),
                "no string material",
            ),
            (
                serde_json::json!({"type": "Feature", "properties": {"material": "grass"}, "geometry": null}),
                "no geometry",
            ),
            (
                serde_json::json!({"type": "Feature", "properties": {"material": "asphalt"}, "geometry": line.clone()}),
                "width_m",
            ),
            (
                serde_json::json!({"type": "Feature", "properties": {"material": "asphalt", "width_m": -1}, "geometry": line}),
                "width_m",
            ),
            (
                serde_json::json!({"type": "Feature", "properties": {"material": "x"}, "geometry": {"type": "Point", "coordinates": [1000, 2000]}}),
                "not Polygon",
            ),
        ];
        for (k, (feature, expect)) in cases.into_iter().enumerate() {
            let path = write(
                t.path(),
                &format!("bad{k}.geojson"),
                serde_json::json!([feature]),
            );
            let e = read(&[&path], &g).unwrap_err();
            let text = e.to_string();
            assert!(
                text.contains(expect) && text.contains("feature 0"),
                "{text}"
            );
            assert!(!text.contains('\n'));
        }
        // Longitude/latitude on a projected grid.
        let lonlat = serde_json::json!({"type": "Feature", "properties": {"material": "grass"},
            "geometry": {"type": "Polygon", "coordinates": [[[8.1, 47.2], [8.2, 47.2], [8.2, 47.3], [8.1, 47.2]]]}});
        let path = write(t.path(), "ll.geojson", serde_json::json!([lonlat]));
        assert!(read(&[&path], &g)
            .unwrap_err()
            .to_string()
            .contains("longitude/latitude"));
    }
}
