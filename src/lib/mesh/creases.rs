//! A pitched roof's creases cut to a building's outline, and the outline split where they
//! meet it: what a triangulation needs so that each of its triangles lies in one roof plane.
//!
//! Invariant of a [`Cut`]: its rings are the outline's rings, in order, with a vertex added on
//! an edge wherever a crease ([`RoofShape::creases`]) meets it; its creases are the parts of the
//! roof's creases inside the outline, end to end, each ending at an outline vertex (old or
//! added) or at a crease's own end inside. Points closer than [`SNAP`] are one point, the same
//! `f64` pair wherever it is used, so a triangulation joins them exactly. Between the cut
//! creases and the split outline the roof is one plane, and along each split edge linear: a
//! wall's top edge between two outline vertices lies in the roof. A flat or shed roof has no
//! crease: its outline comes back as it was.

use super::prisms::inside;
use crate::roof::RoofShape;

/// Points this close (metres) are one point: a hip ending at an outline corner, a ridge ending
/// on a gable wall. Far below any survey's precision, far above the rounding of world metres.
pub const SNAP: f64 = 1e-6;

/// The outline split at the creases and the creases cut to it (module docs), world metres.
#[derive(Debug, Clone, PartialEq)]
pub struct Cut {
    /// The outline's rings (open: the first vertex not repeated), creases' ends added.
    pub rings: Vec<Vec<(f64, f64)>>,
    /// The parts of the creases inside the outline.
    pub creases: Vec<[(f64, f64); 2]>,
}

/// Cut `roof`'s creases to the outline `rings` (open rings, world metres).
pub fn cut(rings: &[Vec<(f64, f64)>], roof: &RoofShape) -> Cut {
    let creases = roof.creases();
    if creases.is_empty() {
        return Cut {
            rings: rings.to_vec(),
            creases: Vec::new(),
        };
    }
    let mut points = Points(rings.iter().flatten().copied().collect());
    // Along each crease: (parameter from its start, point) where it meets the outline.
    let mut along: Vec<Vec<(f64, (f64, f64))>> = vec![Vec::new(); creases.len()];
    let mut split = Vec::with_capacity(rings.len());
    for ring in rings {
        let mut out = Vec::with_capacity(ring.len());
        for (k, &a) in ring.iter().enumerate() {
            let b = ring[(k + 1) % ring.len()];
            out.push(a);
            let mut on_edge: Vec<(f64, (f64, f64))> = Vec::new();
            for (crease, list) in creases.iter().zip(&mut along) {
                for (s, t) in meet(a, b, crease[0], crease[1]) {
                    let p = points.snap(lerp(a, b, s));
                    list.push((t, p));
                    if p != a && p != b && !on_edge.iter().any(|e| e.1 == p) {
                        on_edge.push((s, p));
                    }
                }
            }
            on_edge.sort_by(|x, y| x.0.total_cmp(&y.0));
            out.extend(on_edge.into_iter().map(|e| e.1));
        }
        split.push(out);
    }
    let mut pieces = Vec::new();
    for (&[p, q], mut list) in creases.iter().zip(along) {
        // A crease's own ends, unless they are on the outline (then they snap to it).
        list.push((0.0, points.snap(p)));
        list.push((1.0, points.snap(q)));
        list.sort_by(|x, y| x.0.total_cmp(&y.0));
        for w in list.windows(2) {
            let (u, v) = (w[0].1, w[1].1);
            if u == v {
                continue;
            }
            let mid = ((u.0 + v.0) / 2.0, (u.1 + v.1) / 2.0);
            if inside(&split, mid) && !on_outline(&split, mid) {
                pieces.push([u, v]);
            }
        }
    }
    pieces.dedup();
    Cut {
        rings: split,
        creases: pieces,
    }
}

/// The distinct points met so far: a new point within [`SNAP`] of one is that one.
struct Points(Vec<(f64, f64)>);

impl Points {
    fn snap(&mut self, p: (f64, f64)) -> (f64, f64) {
        match self.0.iter().find(|q| dist(p, **q) <= SNAP) {
            Some(&q) => q,
            None => {
                self.0.push(p);
                p
            }
        }
    }
}

fn dist(a: (f64, f64), b: (f64, f64)) -> f64 {
    (a.0 - b.0).hypot(a.1 - b.1)
}

fn lerp(a: (f64, f64), b: (f64, f64), s: f64) -> (f64, f64) {
    (a.0 + s * (b.0 - a.0), a.1 + s * (b.1 - a.1))
}

fn cross(u: (f64, f64), v: (f64, f64)) -> f64 {
    u.0 * v.1 - u.1 * v.0
}

/// Where segment `a → b` meets segment `p → q`, within [`SNAP`]: `(s, t)`, the parameters
/// along each (`[0, 1]`): one point for a crossing or a touch, the overlap's ends for
/// collinear segments.
fn meet(a: (f64, f64), b: (f64, f64), p: (f64, f64), q: (f64, f64)) -> Vec<(f64, f64)> {
    let (d, e, w) = (
        (b.0 - a.0, b.1 - a.1),
        (q.0 - p.0, q.1 - p.1),
        (p.0 - a.0, p.1 - a.1),
    );
    let (ld, le) = (d.0.hypot(d.1), e.0.hypot(e.1));
    if ld == 0.0 || le == 0.0 {
        return Vec::new();
    }
    let (ts, tt) = (SNAP / ld, SNAP / le);
    let near = |s: f64, t: f64| (-ts..=1.0 + ts).contains(&s) && (-tt..=1.0 + tt).contains(&t);
    let den = cross(d, e);
    if den.abs() > 1e-12 * ld * le {
        let (s, t) = (cross(w, e) / den, cross(w, d) / den);
        return match near(s, t) {
            true => vec![(s.clamp(0.0, 1.0), t.clamp(0.0, 1.0))],
            false => Vec::new(),
        };
    }
    if cross(d, w).abs() / ld > SNAP {
        return Vec::new();
    }
    // Collinear: each segment's ends that lie on the other.
    let on_ab = |r: (f64, f64)| ((r.0 - a.0) * d.0 + (r.1 - a.1) * d.1) / (ld * ld);
    let on_pq = |r: (f64, f64)| ((r.0 - p.0) * e.0 + (r.1 - p.1) * e.1) / (le * le);
    [
        (on_ab(p), 0.0),
        (on_ab(q), 1.0),
        (0.0, on_pq(a)),
        (1.0, on_pq(b)),
    ]
    .into_iter()
    .filter(|&(s, t)| near(s, t))
    .map(|(s, t)| (s.clamp(0.0, 1.0), t.clamp(0.0, 1.0)))
    .collect()
}

/// Whether `p` is within [`SNAP`] of an edge of `rings`.
fn on_outline(rings: &[Vec<(f64, f64)>], p: (f64, f64)) -> bool {
    rings.iter().any(|ring| {
        (0..ring.len()).any(|k| {
            let (a, b) = (ring[k], ring[(k + 1) % ring.len()]);
            let d = (b.0 - a.0, b.1 - a.1);
            let len2 = d.0 * d.0 + d.1 * d.1;
            let s = match len2 > 0.0 {
                true => (((p.0 - a.0) * d.0 + (p.1 - a.1) * d.1) / len2).clamp(0.0, 1.0),
                false => 0.0,
            };
            dist(p, lerp(a, b, s)) <= SNAP
        })
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::roof::{Pitch, RoofForm};

    fn pitched(rings: &[Vec<(f64, f64)>], form: RoofForm, azimuth_deg: f64) -> RoofShape {
        RoofShape::new(
            rings,
            110.0,
            Some(Pitch {
                form,
                eave_z: 104.0,
                azimuth_deg,
            }),
        )
    }

    /// A gable over a rectangle along its long side: the ridge is one crease from gable wall to
    /// gable wall, and each gable wall gains the ridge's end as a vertex.
    #[test]
    fn a_gable_ridge_runs_from_gable_wall_to_gable_wall() {
        let rect = vec![vec![
            (500_000.0, 5_300_000.0),
            (500_012.0, 5_300_000.0),
            (500_012.0, 5_300_007.0),
            (500_000.0, 5_300_007.0),
        ]];
        let c = cut(&rect, &pitched(&rect, RoofForm::Gable, 90.0));
        assert_eq!(c.rings[0].len(), 6);
        assert_eq!(c.creases.len(), 1);
        let [p, q] = c.creases[0];
        for end in [p, q] {
            assert!(c.rings[0].contains(&end), "{end:?} is an outline vertex");
            assert!((end.1 - 5_300_003.5).abs() < 1e-9);
        }
        assert!((p.0 - q.0).abs() > 12.0 - 1e-9);
    }

    /// A hip over a rectangle: a ridge and four hips ending at the corners exactly; the outline
    /// gains nothing.
    #[test]
    fn a_hips_ends_are_the_corners() {
        let rect = vec![vec![(0.0, 0.0), (12.0, 0.0), (12.0, 7.0), (0.0, 7.0)]];
        let c = cut(&rect, &pitched(&rect, RoofForm::Hip, 90.0));
        assert_eq!(c.rings, rect);
        assert_eq!(c.creases.len(), 5);
        let corners = (c.creases.iter().flatten())
            .filter(|p| rect[0].contains(p))
            .count();
        assert_eq!(corners, 4);
    }

    /// An L-shaped outline under a gable along its long arm: the ridge leaves the outline
    /// through the inner corner's wall and comes back: cut into pieces inside only, each end
    /// on the outline or at the ridge's end.
    #[test]
    fn creases_outside_the_outline_are_dropped() {
        let l = vec![vec![
            (0.0, 0.0),
            (15.0, 0.0),
            (15.0, 6.5),
            (6.25, 6.5),
            (6.25, 20.25),
            (0.0, 20.25),
        ]];
        for az in [0.0, 90.0, 30.0] {
            let roof = pitched(&l, RoofForm::Hip, az);
            let c = cut(&l, &roof);
            for &[p, q] in &c.creases {
                for t in 1..10 {
                    let m = lerp(p, q, t as f64 / 10.0);
                    assert!(inside(&c.rings, m), "{az}: {m:?} outside");
                }
                for end in [p, q] {
                    let on = c.rings[0].contains(&end);
                    let crease_end = roof
                        .creases()
                        .iter()
                        .flatten()
                        .any(|e| dist(*e, end) < 1e-9);
                    assert!(on || crease_end, "{az}: {end:?} ends nowhere");
                }
            }
        }
        let c = cut(&l, &pitched(&l, RoofForm::Gable, 90.0));
        // The ridge at y = 10.125 crosses only the long arm (x 0..6.25).
        assert_eq!(c.creases.len(), 1);
        let [p, q] = c.creases[0];
        assert_eq!((p.0.min(q.0), p.0.max(q.0)), (0.0, 6.25));
    }

    /// A flat or shed roof leaves the outline as it was.
    #[test]
    fn no_crease_no_cut() {
        let rect = vec![vec![(0.0, 0.0), (12.0, 0.0), (12.0, 7.0), (0.0, 7.0)]];
        for roof in [RoofShape::flat(9.0), pitched(&rect, RoofForm::Shed, 10.0)] {
            assert_eq!(
                cut(&rect, &roof),
                Cut {
                    rings: rect.clone(),
                    creases: Vec::new()
                }
            );
        }
    }
}
