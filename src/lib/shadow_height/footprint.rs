//! Building footprints read from GeoJSON and validated.
//!
//! Invariant: a [`Footprint`] has rings of at least 3 distinct vertices (repeated and closing
//! vertices dropped), no two edges touch except neighbours in one ring at their shared vertex,
//! and its area (outer rings minus holes, square CRS units) is positive. Inside is decided by
//! the even-odd rule over all rings, so holes and MultiPolygon parts need no bookkeeping.
//!
//! A whole-file problem (not JSON, not a FeatureCollection) is an
//! [`Error`](crate::error::Error); a bad feature is a per-feature message, so one bad footprint
//! does not stop the others.

use crate::error::Result;
use crate::geojson;
use crate::grid::Grid;
use crate::standing::{rasterise_prisms, Prism};
use std::path::Path;

/// The widest footprint taken for a building, metres (east–west or north–south). The largest
/// buildings on Earth are about 1 km across; a footprint spanning more is a data error — most
/// often one stray vertex (`[0, 0]`, or a coordinate in the wrong unit) — and measuring it
/// would cost memory and time by its extent, not by the building's.
pub const MAX_SPAN_M: f64 = 5000.0;

/// A validated footprint: polygon rings in the database CRS (metres).
#[derive(Debug, Clone, PartialEq)]
pub struct Footprint {
    /// Rings of `(x, y)` vertices, open (first vertex not repeated); even-odd inside rule.
    pub rings: Vec<Vec<(f64, f64)>>,
    /// Area in square CRS units (outer rings minus holes), > 0.
    pub area: f64,
}

/// One input feature: its properties and geometry as given, and the footprint or why it is bad.
#[derive(Debug, Clone)]
pub struct InputFeature {
    /// The feature's `properties` (an object, or `null`), kept for the output.
    pub properties: serde_json::Value,
    /// The feature's `geometry`, kept for the output.
    pub geometry: serde_json::Value,
    /// The validated footprint, or a one-line reason it is unusable.
    pub footprint: std::result::Result<Footprint, String>,
}

/// Read a GeoJSON FeatureCollection of Polygon / MultiPolygon footprints.
pub fn read_footprints(path: &Path) -> Result<Vec<InputFeature>> {
    let features = geojson::read_features(
        path,
        "give a GeoJSON FeatureCollection of footprint polygons",
    )?;
    Ok(features
        .iter()
        .map(|f| {
            let geometry = f
                .get("geometry")
                .cloned()
                .unwrap_or(serde_json::Value::Null);
            InputFeature {
                properties: f
                    .get("properties")
                    .cloned()
                    .unwrap_or(serde_json::Value::Null),
                footprint: footprint_of(&geometry),
                geometry,
            }
        })
        .collect())
}

/// The footprint of a GeoJSON geometry, or why it is unusable.
pub fn footprint_of(geometry: &serde_json::Value) -> std::result::Result<Footprint, String> {
    Footprint::new(geojson::polygons(geometry)?)
}

impl Footprint {
    /// Validate polygons (each: outer ring, then holes) into one footprint.
    pub fn new(polygons: Vec<Vec<Vec<(f64, f64)>>>) -> std::result::Result<Footprint, String> {
        if polygons.iter().all(|p| p.is_empty()) {
            return Err("empty geometry".into());
        }
        let mut rings = Vec::new();
        let mut area = 0.0;
        for poly in polygons {
            for (k, ring) in poly.into_iter().enumerate() {
                let ring = distinct_vertices(ring);
                if ring.len() < 3 {
                    return Err(format!(
                        "a ring has {} distinct points, fewer than 3",
                        ring.len()
                    ));
                }
                if collinear(&ring) {
                    return Err("zero area (all points of a ring on one line)".into());
                }
                let a = signed_area(&ring).abs();
                area += if k == 0 { a } else { -a };
                rings.push(ring);
            }
        }
        let b = bbox_of(&rings);
        let span = (b.2 - b.0).max(b.3 - b.1);
        if span.is_nan() || span > MAX_SPAN_M {
            return Err(format!(
                "spans {span:.0} m, and no building is over {MAX_SPAN_M:.0} m across: a stray vertex? (vertices from ({:.1}, {:.1}) to ({:.1}, {:.1}); fix or drop it)",
                b.0, b.1, b.2, b.3
            ));
        }
        if let Some((i, j)) = first_crossing(&rings) {
            return Err(format!(
                "self-intersecting (edges {i} and {j} touch or cross)"
            ));
        }
        if area.is_nan() || area <= 0.0 {
            return Err("zero area (the holes cover the outer ring)".into());
        }
        Ok(Footprint { rings, area })
    }

    /// Bounding box `(min_x, min_y, max_x, max_y)`.
    pub fn bbox(&self) -> (f64, f64, f64, f64) {
        bbox_of(&self.rings)
    }

    /// The centre of the bounding box `(x, y)`, world metres.
    pub fn bbox_centre(&self) -> (f64, f64) {
        let b = self.bbox();
        ((b.0 + b.2) / 2.0, (b.1 + b.3) / 2.0)
    }

    /// Row-major indices of the cells of `grid` whose centre is inside (the database's
    /// rasterisation rule, as `gdal_rasterize`'s).
    pub fn cells(&self, grid: &Grid) -> Vec<usize> {
        let prism = Prism {
            rings: self.rings.clone(),
            roof: crate::roof::RoofShape::flat(0.0),
        };
        rasterise_prisms(grid, &[prism])
            .into_iter()
            .map(|c| c.index)
            .collect()
    }

    /// Whether `(x, y)` is inside (even-odd rule over every ring's edges).
    pub fn contains(&self, x: f64, y: f64) -> bool {
        self.edges()
            .filter(|&(a, b)| {
                (a.1 > y) != (b.1 > y) && x < (b.0 - a.0) * (y - a.1) / (b.1 - a.1) + a.0
            })
            .count()
            % 2
            == 1
    }

    /// The convex hull (counter-clockwise) of the vertices and the same moved by `along`
    /// (metres east, north): it holds every point of the polygon swept along `along`.
    pub fn swept_hull(&self, along: (f64, f64)) -> Vec<(f64, f64)> {
        let mut pts: Vec<(f64, f64)> = self
            .rings
            .iter()
            .flatten()
            .flat_map(|&(x, y)| [(x, y), (x + along.0, y + along.1)])
            .collect();
        pts.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.total_cmp(&b.1)));
        pts.dedup();
        if pts.len() < 3 {
            return pts;
        }
        let cross = |o: (f64, f64), a: (f64, f64), b: (f64, f64)| {
            (a.0 - o.0) * (b.1 - o.1) - (a.1 - o.1) * (b.0 - o.0)
        };
        // Andrew's monotone chain: the lower chain left to right, the upper right to left,
        // each without its last point (the other chain's first).
        let chain = |points: &mut dyn Iterator<Item = &(f64, f64)>| {
            let mut c: Vec<(f64, f64)> = Vec::new();
            for &p in points {
                while c.len() >= 2 && cross(c[c.len() - 2], c[c.len() - 1], p) <= 0.0 {
                    c.pop();
                }
                c.push(p);
            }
            c.pop();
            c
        };
        let mut hull = chain(&mut pts.iter());
        hull.extend(chain(&mut pts.iter().rev()));
        hull
    }

    /// Every edge `(a, b)` of every ring.
    pub fn edges(&self) -> impl Iterator<Item = ((f64, f64), (f64, f64))> + '_ {
        self.rings
            .iter()
            .flat_map(|r| (0..r.len()).map(move |k| (r[k], r[(k + 1) % r.len()])))
    }
}

/// The x range a convex polygon (`hull`, from [`Footprint::swept_hull`]) covers at height `y`,
/// `None` when it does not reach `y`.
pub fn hull_span(hull: &[(f64, f64)], y: f64) -> Option<(f64, f64)> {
    let n = hull.len();
    let mut span: Option<(f64, f64)> = None;
    let mut take = |x: f64| {
        span = Some(span.map_or((x, x), |(a, b)| (a.min(x), b.max(x))));
    };
    for k in 0..n {
        let (a, b) = (hull[k], hull[(k + 1) % n]);
        if (a.1 <= y && y <= b.1) || (b.1 <= y && y <= a.1) {
            if a.1 == b.1 {
                take(a.0);
                take(b.0);
            } else {
                take(a.0 + (b.0 - a.0) * (y - a.1) / (b.1 - a.1));
            }
        }
    }
    span
}

/// Bounding box `(min_x, min_y, max_x, max_y)` of `rings`' vertices.
fn bbox_of(rings: &[Vec<(f64, f64)>]) -> (f64, f64, f64, f64) {
    rings.iter().flatten().fold(
        (
            f64::INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
        ),
        |b, &(x, y)| (b.0.min(x), b.1.min(y), b.2.max(x), b.3.max(y)),
    )
}

/// Drop consecutive repeats and the closing vertex.
fn distinct_vertices(mut ring: Vec<(f64, f64)>) -> Vec<(f64, f64)> {
    ring.dedup();
    while ring.len() > 1 && ring.first() == ring.last() {
        ring.pop();
    }
    ring
}

fn cross(o: (f64, f64), a: (f64, f64), b: (f64, f64)) -> f64 {
    (a.0 - o.0) * (b.1 - o.1) - (a.1 - o.1) * (b.0 - o.0)
}

fn collinear(ring: &[(f64, f64)]) -> bool {
    ring.iter().all(|&p| cross(ring[0], ring[1], p) == 0.0)
}

/// Shoelace area, positive counter-clockwise; relative to the first vertex for precision.
fn signed_area(ring: &[(f64, f64)]) -> f64 {
    let o = ring[0];
    let mut s = 0.0;
    for k in 1..ring.len() - 1 {
        s += cross(o, ring[k], ring[k + 1]);
    }
    s / 2.0
}

/// Closed segments `ab` and `cd` share a point.
fn segments_touch(a: (f64, f64), b: (f64, f64), c: (f64, f64), d: (f64, f64)) -> bool {
    let (d1, d2, d3, d4) = (
        cross(c, d, a),
        cross(c, d, b),
        cross(a, b, c),
        cross(a, b, d),
    );
    let on = |p: (f64, f64), q: (f64, f64), r: (f64, f64)| {
        r.0 >= p.0.min(q.0) && r.0 <= p.0.max(q.0) && r.1 >= p.1.min(q.1) && r.1 <= p.1.max(q.1)
    };
    if ((d1 > 0.0 && d2 < 0.0) || (d1 < 0.0 && d2 > 0.0))
        && ((d3 > 0.0 && d4 < 0.0) || (d3 < 0.0 && d4 > 0.0))
    {
        return true;
    }
    (d1 == 0.0 && on(c, d, a))
        || (d2 == 0.0 && on(c, d, b))
        || (d3 == 0.0 && on(a, b, c))
        || (d4 == 0.0 && on(a, b, d))
}

/// The first pair of edges (global edge numbers) that touch other than at a shared ring vertex.
fn first_crossing(rings: &[Vec<(f64, f64)>]) -> Option<(usize, usize)> {
    // (ring, index in ring, a, b) for every edge.
    type Edge = (usize, usize, (f64, f64), (f64, f64));
    let edges: Vec<Edge> = rings
        .iter()
        .enumerate()
        .flat_map(|(r, ring)| {
            (0..ring.len()).map(move |k| (r, k, ring[k], ring[(k + 1) % ring.len()]))
        })
        .collect();
    for i in 0..edges.len() {
        for j in i + 1..edges.len() {
            let (ri, ki, a, b) = edges[i];
            let (rj, kj, c, d) = edges[j];
            if ri == rj {
                let n = rings[ri].len();
                let adjacent = kj == ki + 1 || (ki == 0 && kj == n - 1);
                if adjacent {
                    // Neighbours share one vertex; they are bad only if they fold back over each other.
                    let (shared, p, q) = if kj == ki + 1 { (b, a, d) } else { (a, b, c) };
                    if cross(shared, p, q) == 0.0
                        && (p.0 - shared.0) * (q.0 - shared.0) + (p.1 - shared.1) * (q.1 - shared.1)
                            > 0.0
                    {
                        return Some((i, j));
                    }
                    continue;
                }
            }
            if segments_touch(a, b, c, d) {
                return Some((i, j));
            }
        }
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn poly(coords: serde_json::Value) -> std::result::Result<Footprint, String> {
        footprint_of(&json!({"type": "Polygon", "coordinates": coords}))
    }

    #[test]
    fn square_with_hole_has_outer_minus_hole_area() {
        let f = poly(json!([
            [[0, 0], [10, 0], [10, 10], [0, 10], [0, 0]],
            [[2, 2], [2, 4], [4, 4], [4, 2], [2, 2]]
        ]))
        .unwrap();
        assert_eq!(f.area, 96.0);
        assert_eq!(f.rings.len(), 2);
        assert_eq!(f.rings[0].len(), 4);
        assert!(f.contains(1.0, 1.0) && f.contains(9.5, 5.0));
        assert!(!f.contains(3.0, 3.0) && !f.contains(-0.5, 5.0) && !f.contains(5.0, 10.5));
    }

    #[test]
    fn concave_l_shape_is_valid() {
        let f = poly(json!([[
            [0, 0],
            [10, 0],
            [10, 4],
            [4, 4],
            [4, 10],
            [0, 10],
            [0, 0]
        ]]))
        .unwrap();
        assert_eq!(f.area, 64.0);
    }

    #[test]
    fn hard_case_a_stray_vertex_is_refused_before_anything_is_sized_by_it() {
        // A 10 m building at UTM coordinates with one vertex at [0, 0] or near 1e15 m (issue
        // 14: shadow-height aborted allocating 1.8e17 bytes by such a footprint's extent).
        let (x, y) = (500_000.0, 5_300_000.0);
        for stray in [json!([0, 0]), json!([1e15, 1e15]), json!([x + 5001.0, y])] {
            let e = poly(json!([[
                [x, y],
                [x + 10.0, y],
                stray,
                [x + 10.0, y + 10.0],
                [x, y + 10.0],
                [x, y]
            ]]))
            .unwrap_err();
            assert!(e.contains("stray vertex"), "{e}");
        }
        // The widest building accepted: 5 km.
        assert!(poly(json!([[
            [x, y],
            [x + 5000.0, y],
            [x + 5000.0, y + 10.0],
            [x, y + 10.0],
            [x, y]
        ]]))
        .is_ok());
    }

    #[test]
    fn degenerate_footprints_say_why() {
        let two = poly(json!([[[0, 0], [1, 1], [0, 0], [0, 0]]])).unwrap_err();
        assert!(two.contains("fewer than 3"), "{two}");
        let line = poly(json!([[[0, 0], [1, 1], [2, 2], [0, 0]]])).unwrap_err();
        assert!(line.contains("zero area"), "{line}");
        let bowtie = poly(json!([[[0, 0], [2, 2], [2, 0], [0, 2], [0, 0]]])).unwrap_err();
        assert!(bowtie.contains("self-intersecting"), "{bowtie}");
        let spike = poly(json!([[[0, 0], [4, 0], [4, 4], [4, 8], [4, 2], [0, 4]]])).unwrap_err();
        assert!(spike.contains("self-intersecting"), "{spike}");
        assert!(
            footprint_of(&json!({"type": "Point", "coordinates": [0, 0]}))
                .unwrap_err()
                .contains("not Polygon")
        );
        assert!(poly(json!([[[0, "a"], [1, 0], [1, 1]]]))
            .unwrap_err()
            .contains("bad polygon"));
    }

    #[test]
    fn multipolygon_parts_that_cross_are_rejected() {
        let g = json!({"type": "MultiPolygon", "coordinates": [
            [[[0, 0], [4, 0], [4, 4], [0, 4]]], [[[2, 2], [6, 2], [6, 6], [2, 6]]]]});
        assert!(footprint_of(&g).unwrap_err().contains("self-intersecting"));
        let ok = json!({"type": "MultiPolygon", "coordinates": [
            [[[0, 0], [4, 0], [4, 4], [0, 4]]], [[[5, 5], [6, 5], [6, 6], [5, 6]]]]});
        assert_eq!(footprint_of(&ok).unwrap().area, 17.0);
    }
}
