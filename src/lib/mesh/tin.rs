//! Terrain as a triangulated irregular network (TIN) simplified to a stated vertical error.
//!
//! A window of grid points ([`Heights`]) becomes a [`Tin`] by greedy insertion (Garland &
//! Heckbert, "Fast polygonal approximation of terrains and height fields", 1995): the
//! window's four edges are simplified on their own ([`edge_points`]), their kept points are
//! triangulated (Delaunay, spade), and the interior point farthest (vertically) from the
//! current TIN is inserted until every valid point is within the bound.
//!
//! Invariants of [`simplify`]'s result:
//! - **Bound.** Every valid point inside or on an emitted triangle is within `max_error`
//!   metres of the triangle's interpolation ([`measure`] computes it independently).
//! - **Crack-free tiles.** The border carries exactly each edge's [`edge_points`], which depend
//!   on that edge's heights alone, and no border point is ever inserted, so the hull edges are
//!   the consecutive edge points (a Delaunay triangulation has no degenerate triangle, so a
//!   hull edge never skips a vertex lying on it). Two windows that share an edge of points
//!   therefore interpolate it identically — to the bit: every interpolation here is
//!   `z_base + Σ (w_k / area2) · (z_k − z_base)` over the corners with a nonzero weight, the
//!   base being the lowest (row, column) of them, and integer weights over an integer area
//!   round to the same `f64` as the 1-D `(i − lo) / (hi − lo)` along an edge.
//! - **Nodata.** Only triangles whose three corners are valid and which hold no nodata point
//!   (inside or on an edge) are emitted. Nodata points are never inserted (a nodata vertex
//!   would pull the Delaunay triangles towards it); a triangle holding both valid and nodata
//!   points counts as infinitely wrong and gets its first insertable valid point inserted,
//!   until no such triangle has one left. Valid points next to a hole may so stay uncovered.
//! - **Determinism.** The result depends on the heights and the bound alone: the error ties
//!   are broken by the lowest (row, column), vertices are numbered in (row, column) order and
//!   triangles are sorted.
//!
//! Efficiency: every triangle's worst point (or the point to insert, for one that holds
//! nodata) is found once, when the triangle is made, by walking the grid points inside it row
//! by row (exact integer spans). The candidates wait in a priority queue with the triangle's
//! corners; an entry whose face no longer has those corners is stale and skipped. Inserting a
//! vertex only makes triangles around it (spade legalises by flips, which rewrite faces in
//! place), so only those are re-examined: the work per insertion is the area of the triangles
//! it makes, not the window.

use spade::handles::{FixedFaceHandle, FixedVertexHandle, InnerTag};
use spade::{DelaunayTriangulation, Point2, Triangulation};
use std::cmp::{Ordering, Reverse};
use std::collections::BinaryHeap;

/// Heights on a window of grid *points* (not cells), metres; NaN = nodata.
///
/// Point (column, row) is `z[row * width + column]`: row-major, row 0 first, rows running
/// south, columns east.
#[derive(Debug, Clone, Copy)]
pub struct Heights<'a> {
    /// Points per row.
    pub width: usize,
    /// Rows.
    pub height: usize,
    /// `width * height` heights, metres; NaN = nodata.
    pub z: &'a [f32],
}

impl Heights<'_> {
    /// The height at grid point `q` = [column, row].
    fn at(&self, q: [i64; 2]) -> f32 {
        self.z[q[1] as usize * self.width + q[0] as usize]
    }

    /// Whether `q` lies on the window's border (never an interior candidate).
    fn on_border(&self, q: [i64; 2]) -> bool {
        q[0] == 0
            || q[1] == 0
            || q[0] as usize == self.width - 1
            || q[1] as usize == self.height - 1
    }
}

/// A TIN over a [`Heights`] window.
///
/// Invariant: every vertex is a valid point of the window, every triangle has three distinct
/// vertices and a nonzero area; vertices are sorted by (row, column), each triangle starts at
/// its lowest index and the triangles are sorted.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Tin {
    /// Vertices as [column, row] of the window's points.
    pub vertices: Vec<[u32; 2]>,
    /// Triangles as indices into `vertices`, counter-clockwise seen from above in world terms
    /// (x = column east, y = −row north), which is clockwise in (column, row).
    pub triangles: Vec<[u32; 3]>,
}

/// How far a TIN is from the heights it was made from, over the valid points it covers.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct TinError {
    /// The largest vertical error, metres (0 when no point is covered).
    pub max: f64,
    /// The root mean square vertical error, metres (0 when no point is covered).
    pub rms: f64,
    /// Valid points inside or on an emitted triangle, each counted once.
    pub points: usize,
}

/// The points of one window edge that a TIN keeps: indices along the edge, ascending.
///
/// 1-D greedy simplification of the polyline of heights `z` (metres, NaN = nodata) to
/// `max_error` metres: the kept points always include both ends, every nodata point and every
/// valid point next to a nodata point; between two consecutive kept valid points, the linear
/// interpolation is within `max_error` (`<=`) of every point. Deterministic from the heights
/// alone (ties broken by the lowest index), so two windows that share an edge keep the same
/// points on it.
///
/// # Panics
/// If `max_error` is negative or NaN.
pub fn edge_points(z: &[f32], max_error: f64) -> Vec<usize> {
    assert!(max_error >= 0.0, "max_error {max_error} is not >= 0");
    let n = z.len();
    let nodata = |i: usize| z[i].is_nan();
    let mut keep: Vec<bool> = (0..n)
        .map(|i| {
            i == 0
                || i == n - 1
                || nodata(i)
                || (i > 0 && nodata(i - 1))
                || (i + 1 < n && nodata(i + 1))
        })
        .collect();
    // Consecutive kept points with points between them are both valid (a nodata point's
    // neighbours are kept), and so is everything between them.
    let kept: Vec<usize> = (0..n).filter(|&i| keep[i]).collect();
    let mut spans: Vec<(usize, usize)> = kept
        .windows(2)
        .map(|w| (w[0], w[1]))
        .filter(|&(lo, hi)| hi > lo + 1)
        .collect();
    while let Some((lo, hi)) = spans.pop() {
        let (z_lo, z_hi) = (z[lo] as f64, z[hi] as f64);
        let mut worst: Option<(f64, usize)> = None;
        for (i, &zi) in z.iter().enumerate().take(hi).skip(lo + 1) {
            // The same expression as `Facet::interpolate` on an edge: bit-identical.
            let t = (i - lo) as f64 / (hi - lo) as f64;
            let e = (zi as f64 - (z_lo + t * (z_hi - z_lo))).abs();
            if worst.is_none_or(|(w, _)| e > w) {
                worst = Some((e, i));
            }
        }
        if let Some((e, i)) = worst {
            if e > max_error {
                keep[i] = true;
                spans.push((lo, i));
                spans.push((i, hi));
            }
        }
    }
    (0..n).filter(|&i| keep[i]).collect()
}

/// Greedy insertion to `max_error` metres: start from the four edges' [`edge_points`] (Delaunay
/// via spade), then repeatedly insert the interior point farthest (vertically) from the
/// current TIN — ties broken by the lowest (row, column) — until every valid point is within
/// `max_error` (`<=`). See the module doc for the invariants (bound, crack-free borders,
/// nodata, determinism). A window less than 2 points wide or high gives an empty TIN.
///
/// # Panics
/// If `h.z.len() != h.width * h.height`, or `max_error` is negative or NaN.
pub fn simplify(h: &Heights, max_error: f64) -> Tin {
    assert_eq!(
        h.z.len(),
        h.width * h.height,
        "heights do not fill the window"
    );
    assert!(max_error >= 0.0, "max_error {max_error} is not >= 0");
    if h.width < 2 || h.height < 2 {
        return Tin::default();
    }
    let mut refiner = Refiner::new(h, max_error);
    while let Some(c) = refiner.queue.pop() {
        if refiner.stamps[c.face.index()] == c.stamp {
            let at = c.point.0 as i64;
            let w = h.width as i64;
            let near = refiner.tri.face(c.face).vertices()[0].fix();
            refiner.insert([at % w, at / w], near);
        }
    }
    refiner.into_tin()
}

/// Vertical error of `tin` against `h` at every valid point inside or on an emitted triangle
/// (each point counted once), by barycentric interpolation over the triangle's corners,
/// computed from the triangles alone (not from [`simplify`]'s bookkeeping). A valid point in a
/// triangle with a nodata corner counts as infinitely wrong; zero-area triangles cover nothing.
///
/// # Panics
/// If a vertex lies outside the window or a triangle index outside `tin.vertices`.
pub fn measure(h: &Heights, tin: &Tin) -> TinError {
    assert_eq!(
        h.z.len(),
        h.width * h.height,
        "heights do not fill the window"
    );
    let mut seen = vec![false; h.z.len()];
    let (mut max, mut sum2, mut points) = (0.0f64, 0.0f64, 0usize);
    for t in &tin.triangles {
        let corners = t.map(|i| {
            let [c, r] = tin.vertices[i as usize];
            assert!((c as usize) < h.width && (r as usize) < h.height);
            [c as i64, r as i64]
        });
        let facet = Facet::new(corners, h);
        if facet.area2 == 0 {
            continue;
        }
        for q in facet.points() {
            let i = q[1] as usize * h.width + q[0] as usize;
            let z = h.z[i];
            if seen[i] || z.is_nan() {
                continue;
            }
            seen[i] = true;
            let e = (z as f64 - facet.interpolate(facet.weights(q))).abs();
            let e = if e.is_nan() { f64::INFINITY } else { e };
            max = max.max(e);
            sum2 += e * e;
            points += 1;
        }
    }
    let rms = if points == 0 {
        0.0
    } else {
        (sum2 / points as f64).sqrt()
    };
    TinError { max, rms, points }
}

/// `orient(a, b, c)`: twice the signed area of triangle abc, positive when counter-clockwise
/// in (x, y) = (column, row) with y taken as up.
fn orient(a: [i64; 2], b: [i64; 2], c: [i64; 2]) -> i64 {
    (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
}

/// A triangle of grid points with its corner heights, for walking and interpolating it.
struct Facet {
    /// Corners as [column, row], sorted by (row, column).
    p: [[i64; 2]; 3],
    /// The corners' heights (NaN = nodata).
    z: [f64; 3],
    /// Twice the area, >= 0.
    area2: i64,
    /// The orientation's sign, making every weight >= 0 inside.
    sign: i64,
}

impl Facet {
    fn new(mut p: [[i64; 2]; 3], h: &Heights) -> Facet {
        p.sort_by_key(|q| (q[1], q[0]));
        let o = orient(p[0], p[1], p[2]);
        Facet {
            p,
            z: p.map(|q| h.at(q) as f64),
            area2: o.abs(),
            sign: o.signum(),
        }
    }

    /// Integer barycentric weights of `q` (twice the sub-areas opposite each corner): all >= 0
    /// inside or on the triangle, summing to `area2`.
    fn weights(&self, q: [i64; 2]) -> [i64; 3] {
        let p = self.p;
        [
            self.sign * orient(p[1], p[2], q),
            self.sign * orient(p[2], p[0], q),
            self.sign * orient(p[0], p[1], q),
        ]
    }

    /// The height at weights `w` (not all zero): `z_base + Σ (w_k / area2) (z_k − z_base)` over
    /// the corners with a nonzero weight, base the first of them. On an edge this is exactly
    /// [`edge_points`]' 1-D interpolation, whatever the third corner.
    fn interpolate(&self, w: [i64; 3]) -> f64 {
        let b = w
            .iter()
            .position(|&x| x != 0)
            .expect("weights of a point in the triangle");
        let mut z = self.z[b];
        for (&wk, &zk) in w.iter().zip(&self.z).skip(b + 1) {
            if wk != 0 {
                z += (wk as f64 / self.area2 as f64) * (zk - self.z[b]);
            }
        }
        z
    }

    /// The interpolation's slopes (metres per column, per row) from corner `p[0]`, in `f64`
    /// (off [`Facet::interpolate`] by rounding only). Corners must be valid.
    fn gradient(&self) -> (f64, f64) {
        let [p0, p1, p2] = self.p;
        let (d1, d2) = (self.z[1] - self.z[0], self.z[2] - self.z[0]);
        let (s, area2) = (self.sign as f64, self.area2 as f64);
        let gx = s * (-((p0[1] - p2[1]) as f64) * d1 - ((p1[1] - p0[1]) as f64) * d2) / area2;
        let gy = s * (((p0[0] - p2[0]) as f64) * d1 + ((p1[0] - p0[0]) as f64) * d2) / area2;
        (gx, gy)
    }

    /// The columns of row `y` inside or on the triangle (empty when `lo > hi`).
    fn span(&self, y: i64) -> (i64, i64) {
        let xs = self.p.map(|q| q[0]);
        let (mut lo, mut hi) = (*xs.iter().min().unwrap(), *xs.iter().max().unwrap());
        for k in 0..3 {
            let (a, b) = (self.p[(k + 1) % 3], self.p[(k + 2) % 3]);
            // The weight opposite corner k along row y: kx * x + m >= 0.
            let kx = -self.sign * (b[1] - a[1]);
            let m = self.sign * ((b[0] - a[0]) * (y - a[1]) + (b[1] - a[1]) * a[0]);
            match kx.cmp(&0) {
                Ordering::Greater => lo = lo.max(-m.div_euclid(kx)),
                Ordering::Less => hi = hi.min(m.div_euclid(-kx)),
                Ordering::Equal if m < 0 => hi = lo - 1,
                Ordering::Equal => {}
            }
        }
        (lo, hi)
    }

    /// Whether a nodata point of `h` lies inside or on the triangle.
    fn holds_nodata(&self, h: &Heights) -> bool {
        (self.p[0][1]..=self.p[2][1]).any(|y| {
            let (lo, hi) = self.span(y);
            let row = y as usize * h.width;
            lo <= hi
                && h.z[row + lo as usize..=row + hi as usize]
                    .iter()
                    .any(|z| z.is_nan())
        })
    }

    /// The grid points inside or on the triangle, row by row (ascending (row, column)).
    fn points(&self) -> impl Iterator<Item = [i64; 2]> + '_ {
        (self.p[0][1]..=self.p[2][1]).flat_map(move |y| {
            let (lo, hi) = self.span(y);
            (lo..=hi).map(move |x| [x, y])
        })
    }
}

/// A point waiting to be inserted: the worst of its triangle when that was examined.
///
/// Ordered (derived, field by field) by error, largest first, then by (row, column), lowest
/// first, then by stamp.
#[derive(PartialEq, Eq, PartialOrd, Ord)]
struct Candidate {
    /// The error's bits, metres: errors are >= 0 (infinite for a triangle that holds valid
    /// and nodata points), so their bits order as their values.
    error: u64,
    /// The point's row-major index, reversed: the lowest (row, column) ranks highest.
    point: Reverse<u32>,
    /// When the face was examined: the entry is stale once the face is examined again.
    stamp: u32,
    face: FixedFaceHandle<InnerTag>,
}

/// Greedy insertion's state: the triangulation, which points are vertices, the queue.
struct Refiner<'a> {
    h: &'a Heights<'a>,
    max_error: f64,
    tri: DelaunayTriangulation<Point2<f64>>,
    is_vertex: Vec<bool>,
    queue: BinaryHeap<Candidate>,
    /// Per face index, the stamp of its latest examination.
    stamps: Vec<u32>,
    /// Examinations so far.
    examined: u32,
}

impl<'a> Refiner<'a> {
    /// The triangulation of the four edges' kept points, every triangle examined.
    fn new(h: &'a Heights<'a>, max_error: f64) -> Refiner<'a> {
        let (w, ht) = (h.width, h.height);
        let row = |r: usize| &h.z[r * w..(r + 1) * w];
        let column = |c: usize| (0..ht).map(|r| h.z[r * w + c]).collect::<Vec<f32>>();
        let mut border: Vec<[i64; 2]> = Vec::new();
        for r in [0, ht - 1] {
            border.extend(
                edge_points(row(r), max_error)
                    .into_iter()
                    .map(|c| [c as i64, r as i64]),
            );
        }
        for c in [0, w - 1] {
            border.extend(
                edge_points(&column(c), max_error)
                    .into_iter()
                    .map(|r| [c as i64, r as i64]),
            );
        }
        border.sort_by_key(|q| (q[1], q[0]));
        border.dedup();
        let mut refiner = Refiner {
            h,
            max_error,
            tri: DelaunayTriangulation::new(),
            is_vertex: vec![false; w * ht],
            queue: BinaryHeap::new(),
            stamps: Vec::new(),
            examined: 0,
        };
        for &q in &border {
            refiner.is_vertex[q[1] as usize * w + q[0] as usize] = true;
            refiner
                .tri
                .insert(Point2::new(q[0] as f64, q[1] as f64))
                .expect("grid coordinates are finite and small");
        }
        let faces: Vec<_> = refiner.tri.fixed_inner_faces().collect();
        for f in faces {
            refiner.examine(f);
        }
        refiner
    }

    /// Insert interior point `q`, which lies in a triangle with corner `near` (where spade's
    /// point location starts walking), and examine the triangles it made (all around it).
    fn insert(&mut self, q: [i64; 2], near: FixedVertexHandle) {
        self.is_vertex[q[1] as usize * self.h.width + q[0] as usize] = true;
        let v = self
            .tri
            .insert_with_hint(Point2::new(q[0] as f64, q[1] as f64), near)
            .expect("grid coordinates are finite and small");
        let faces: Vec<_> = self
            .tri
            .vertex(v)
            .out_edges()
            .filter_map(|e| e.face().as_inner().map(|f| f.fix()))
            .collect();
        for f in faces {
            self.examine(f);
        }
    }

    fn facet(&self, face: FixedFaceHandle<InnerTag>) -> Facet {
        let p = self.tri.face(face).vertices().map(|v| {
            let at = v.position();
            [at.x as i64, at.y as i64]
        });
        Facet::new(p, self.h)
    }

    /// Queue the point `face` needs inserted, if any: its worst point when that is beyond the
    /// bound, or, when it holds both valid and nodata points, its first insertable valid point.
    fn examine(&mut self, face: FixedFaceHandle<InnerTag>) {
        let facet = self.facet(face);
        let pick = if facet.z.iter().any(|z| z.is_nan()) {
            self.first_valid(&facet)
        } else {
            self.worst(&facet)
        };
        self.examined += 1;
        let stamp = self.examined;
        if self.stamps.len() <= face.index() {
            self.stamps.resize(face.index() + 1, 0);
        }
        self.stamps[face.index()] = stamp;
        if let Some((error, at)) = pick {
            self.queue.push(Candidate {
                error: error.to_bits(),
                point: Reverse((at[1] * self.h.width as i64 + at[0]) as u32),
                stamp,
                face,
            });
        }
    }

    /// Whether `q` may be inserted: an interior point that is not yet a vertex.
    fn insertable(&self, q: [i64; 2]) -> bool {
        !self.h.on_border(q) && !self.is_vertex[q[1] as usize * self.h.width + q[0] as usize]
    }

    /// A triangle holding nodata: its first insertable valid point, infinitely wrong.
    fn first_valid(&self, facet: &Facet) -> Option<(f64, [i64; 2])> {
        facet
            .points()
            .find(|&q| !self.h.at(q).is_nan() && self.insertable(q))
            .map(|q| (f64::INFINITY, q))
    }

    /// A triangle with valid corners: its insertable point farthest from it when beyond the
    /// bound (ties: the lowest (row, column)), or its first insertable valid point if it holds
    /// nodata after all.
    ///
    /// The points are ranked by the triangle's plane (one multiply-add a point), within
    /// `margin` of [`Facet::interpolate`]; the exact interpolation decides near the bound.
    fn worst(&self, facet: &Facet) -> Option<(f64, [i64; 2])> {
        let (w, h) = (self.h.width as i64, self.h.height as i64);
        let [x0, y0] = facet.p[0];
        let (gx, gy) = facet.gradient();
        let margin = 1e-9 * (1.0 + facet.z.iter().fold(0.0f64, |m, z| m.max(z.abs())));
        let mut worst: Option<(f64, [i64; 2])> = None;
        // Border points between corners are valid, and never inserted.
        for y in facet.p[0][1].max(1)..=facet.p[2][1].min(h - 2) {
            let (lo, hi) = facet.span(y);
            let row = &self.h.z[(y * w) as usize..((y + 1) * w) as usize];
            let is_vertex = &self.is_vertex[(y * w) as usize..((y + 1) * w) as usize];
            let z_row = facet.z[0] + gy * (y - y0) as f64;
            for x in lo.max(1)..=hi.min(w - 2) {
                let z = row[x as usize];
                if z.is_nan() {
                    return self.first_valid(facet);
                }
                if is_vertex[x as usize] {
                    continue;
                }
                let e = (z as f64 - (z_row + gx * (x - x0) as f64)).abs();
                if worst.is_none_or(|(w, _)| e > w) {
                    worst = Some((e, [x, y]));
                }
            }
        }
        let exact = |q: [i64; 2]| (self.h.at(q) as f64 - facet.interpolate(facet.weights(q))).abs();
        let (e, q) = worst?;
        if e <= self.max_error - margin {
            None
        } else if e > self.max_error + margin {
            Some((exact(q), q))
        } else {
            facet
                .points()
                .filter(|&q| self.insertable(q))
                .map(|q| (exact(q), q))
                .filter(|&(e, _)| e > self.max_error)
                .fold(None, |worst, (e, q)| match worst {
                    Some((w, _)) if w >= e => worst,
                    _ => Some((e, q)),
                })
        }
    }

    /// The emitted triangles (valid corners, no nodata point held), numbered and sorted.
    fn into_tin(self) -> Tin {
        let h = self.h;
        let any_nodata = h.z.iter().any(|z| z.is_nan());
        let kept: Vec<[[i64; 2]; 3]> = self
            .tri
            .fixed_inner_faces()
            .map(|f| self.facet(f))
            .filter(|f| !any_nodata || !f.holds_nodata(h))
            .map(|f| f.p)
            .collect();
        // Vertices numbered in (row, column) order: row-major over the window.
        let mut index = vec![u32::MAX; h.z.len()];
        for q in kept.iter().flatten() {
            index[q[1] as usize * h.width + q[0] as usize] = 0;
        }
        let mut vertices = Vec::new();
        for (i, slot) in index.iter_mut().enumerate() {
            if *slot == 0 {
                *slot = vertices.len() as u32;
                vertices.push([(i % h.width) as u32, (i / h.width) as u32]);
            }
        }
        let index = |q: [i64; 2]| index[q[1] as usize * h.width + q[0] as usize];
        let mut triangles: Vec<[u32; 3]> = kept
            .iter()
            .map(|p| {
                // Clockwise in (column, row): counter-clockwise seen from above.
                let p = if orient(p[0], p[1], p[2]) > 0 {
                    [p[0], p[2], p[1]]
                } else {
                    *p
                };
                let mut t = p.map(index);
                let first = (0..3).min_by_key(|&k| t[k]).unwrap();
                t.rotate_left(first);
                t
            })
            .collect();
        triangles.sort_unstable();
        Tin {
            vertices,
            triangles,
        }
    }
}

#[cfg(test)]
#[path = "tin_tests.rs"]
mod tests;
