//! Buildings as triangle meshes: each prism of the `buildings` layer becomes its roof,
//! triangulated in the roof's planes, and one wall per outline edge from a base below the
//! terrain up to the roof.
//!
//! Invariant: every roof vertex is at the roof's height there ([`RoofShape::z_at`]), and is an
//! outline vertex, the end of a crease inside the outline, or a point where a crease meets the
//! outline ([`super::creases`]); nothing else is added or moved. A flat roof's vertices are
//! thus its outline's corners at the layer's `roof_z`, so the mesh's building heights are the
//! layer's, as exactly as the file that stores them keeps coordinates. The roof is a
//! constrained Delaunay triangulation (spade) of the outline with the creases cut to it as
//! constrained edges, so no triangle crosses a crease and each lies in one roof plane; its
//! triangles inside the polygon by the even-odd rule (an odd number of outline edges from
//! outside, so holes stay open, as [`crate::standing::polygon_cells`] rasterises them) are
//! kept. Walls face out of the solid (an outer ring's walls away from its inside, a hole's walls
//! into the hole) and reach the roof along each edge of the split outline, at the same points
//! the roof has there: a gable wall is two quads meeting under the ridge, and walls and roof
//! close without a gap.

use super::creases::{cut, Cut};
use super::Mesh;
use crate::roof::RoofShape;
use crate::standing::Prism;
use spade::handles::DirectedEdgeHandle;
use spade::{CdtEdge, ConstrainedDelaunayTriangulation, Point2, Triangulation};
use std::collections::HashSet;

/// A building prism as triangles: its roof ([`Prism::roof`], heights in metres) and a wall per
/// outline edge from `base_z` (metres, below the terrain under the building) to the roof, all
/// in `colour` (sRGB). An outline that crosses itself, or that has no area, is an `Err` with
/// the problem in words.
pub fn prism_mesh(prism: &Prism, base_z: f64, colour: [u8; 3]) -> Result<Mesh, String> {
    let rings: Vec<Vec<(f64, f64)>> = prism.rings.iter().map(|r| open_ring(r)).collect();
    if rings.iter().all(|r| r.len() < 3) {
        return Err("its outline has fewer than three corners".into());
    }
    let outline = cut(&rings, &prism.roof);
    let mut mesh = Mesh::default();
    roof(&outline, &prism.roof, colour, &mut mesh)?;
    if mesh.is_empty() {
        return Err("its outline encloses no area".into());
    }
    let rings = &outline.rings;
    for (k, ring) in rings.iter().enumerate() {
        // A ring inside an odd number of the others is a hole: the solid lies outside it.
        let depth = rings
            .iter()
            .enumerate()
            .filter(|&(j, other)| j != k && inside(std::slice::from_ref(other), ring[0]))
            .count();
        let solid_on_left = (signed_area(ring) > 0.0) == (depth % 2 == 0);
        walls(ring, solid_on_left, base_z, &prism.roof, colour, &mut mesh);
    }
    Ok(mesh)
}

/// The ring without its closing vertex (GeoJSON repeats the first) and without consecutive
/// repeats.
fn open_ring(ring: &[(f64, f64)]) -> Vec<(f64, f64)> {
    let mut out: Vec<(f64, f64)> = Vec::with_capacity(ring.len());
    for &p in ring {
        if out.last() != Some(&p) {
            out.push(p);
        }
    }
    while out.len() > 1 && out.first() == out.last() {
        out.pop();
    }
    out
}

/// The signed area of a ring (positive when counter-clockwise, x east, y north).
fn signed_area(ring: &[(f64, f64)]) -> f64 {
    let (x0, y0) = ring[0];
    let n = ring.len();
    (0..n)
        .map(|i| {
            let (a, b) = (ring[i], ring[(i + 1) % n]);
            (a.0 - x0) * (b.1 - y0) - (b.0 - x0) * (a.1 - y0)
        })
        .sum::<f64>()
        / 2.0
}

/// Whether `p` is inside the polygon `rings` by the even-odd rule (a point on an edge counts as
/// the scanline fill counts it: half-open in y).
pub(super) fn inside(rings: &[Vec<(f64, f64)>], p: (f64, f64)) -> bool {
    let mut odd = false;
    for ring in rings {
        for (k, &(x0, y0)) in ring.iter().enumerate() {
            let (x1, y1) = ring[(k + 1) % ring.len()];
            if (y0 <= p.1) != (y1 <= p.1) && p.0 < x0 + (p.1 - y0) / (y1 - y0) * (x1 - x0) {
                odd = !odd;
            }
        }
    }
    odd
}

/// Triangulate the roof: every edge of the split outline and every cut crease a constraint,
/// the triangles inside kept ([`inside_faces`]), each vertex at the roof's height there.
fn roof(outline: &Cut, shape: &RoofShape, colour: [u8; 3], mesh: &mut Mesh) -> Result<(), String> {
    // Coordinates relative to the first corner: spade works on small numbers. Each vertex
    // keeps the world point it was inserted as, so the roof and the walls share exact points.
    let rings = &outline.rings;
    let (x0, y0) = rings.iter().flatten().next().copied().unwrap_or_default();
    let mut cdt: ConstrainedDelaunayTriangulation<Point2<f64>> = Default::default();
    let mut world: Vec<(f64, f64)> = Vec::new();
    let mut insert = |cdt: &mut ConstrainedDelaunayTriangulation<Point2<f64>>, (x, y)| {
        let h = cdt
            .insert(Point2::new(x - x0, y - y0))
            .map_err(|e| format!("a corner cannot be triangulated ({e:?})"))?;
        if h.index() == world.len() {
            world.push((x, y));
        }
        Ok::<_, String>(h)
    };
    for ring in rings.iter().filter(|r| r.len() >= 3) {
        let handles = ring
            .iter()
            .map(|&p| insert(&mut cdt, p))
            .collect::<Result<Vec<_>, _>>()?;
        for (k, &a) in handles.iter().enumerate() {
            let b = handles[(k + 1) % handles.len()];
            if a == b {
                continue;
            }
            if !cdt.can_add_constraint(a, b) {
                return Err("its outline crosses itself".into());
            }
            cdt.add_constraint(a, b);
        }
    }
    let mut creases = HashSet::new();
    for &[p, q] in &outline.creases {
        let (a, b) = (insert(&mut cdt, p)?, insert(&mut cdt, q)?);
        if !cdt.can_add_constraint(a, b) {
            return Err("its roof's ridge or hips cross its outline".into());
        }
        cdt.add_constraint(a, b);
        creases.insert(edge_key(a.index(), b.index()));
    }
    let inside = inside_faces(&cdt, &creases);
    let mut index = vec![u32::MAX; cdt.num_vertices()];
    for face in cdt.inner_faces() {
        if !inside[face.fix().index()] {
            continue;
        }
        let tri = face.vertices().map(|v| {
            let i = v.fix().index();
            if index[i] == u32::MAX {
                index[i] = mesh.positions.len() as u32;
                let (x, y) = world[i];
                mesh.positions.push([x, y, shape.z_at((x, y))]);
                mesh.colours.push(colour);
            }
            index[i]
        });
        mesh.triangles.push(tri);
    }
    Ok(())
}

/// An undirected edge by its vertices' indices.
fn edge_key(a: usize, b: usize) -> [usize; 2] {
    [a.min(b), a.max(b)]
}

/// Which faces of `cdt` (by index) are inside the outline: those an odd number of outline
/// edges (the constraints that are not among `creases`) away from outside, walking face to
/// face. Exact, where a test of each face's centre is not: a sliver along an outline edge split
/// where a crease meets it lies on the side the split point fell to, by rounding.
fn inside_faces(
    cdt: &ConstrainedDelaunayTriangulation<Point2<f64>>,
    creases: &HashSet<[usize; 2]>,
) -> Vec<bool> {
    let outline = |e: DirectedEdgeHandle<'_, Point2<f64>, (), CdtEdge<()>, ()>| {
        let [a, b] = e.vertices().map(|v| v.fix().index());
        e.is_constraint_edge() && !creases.contains(&edge_key(a, b))
    };
    let mut inside = vec![None; cdt.num_all_faces()];
    let mut stack = Vec::new();
    for e in cdt.convex_hull() {
        for side in [e, e.rev()] {
            if let Some(f) = side.face().as_inner() {
                stack.push((f, outline(e)));
            }
        }
    }
    while let Some((f, odd)) = stack.pop() {
        if inside[f.fix().index()].is_some() {
            continue;
        }
        inside[f.fix().index()] = Some(odd);
        for e in f.adjacent_edges() {
            if let Some(g) = e.rev().face().as_inner() {
                if inside[g.fix().index()].is_none() {
                    stack.push((g, odd != outline(e)));
                }
            }
        }
    }
    inside.into_iter().map(|f| f == Some(true)).collect()
}

/// One quad per edge of `ring` from `base_z` up to the roof `shape` at its ends, facing away
/// from the solid (which lies left of each edge when `solid_on_left`).
fn walls(
    ring: &[(f64, f64)],
    solid_on_left: bool,
    base_z: f64,
    shape: &RoofShape,
    colour: [u8; 3],
    mesh: &mut Mesh,
) {
    for (k, &a) in ring.iter().enumerate() {
        let b = ring[(k + 1) % ring.len()];
        // Counter-clockwise seen from the right of a → b: a low, b low, b high, a high.
        let (p, q) = if solid_on_left { (a, b) } else { (b, a) };
        let i = mesh.positions.len() as u32;
        mesh.positions.extend([
            [p.0, p.1, base_z],
            [q.0, q.1, base_z],
            [q.0, q.1, shape.z_at(q)],
            [p.0, p.1, shape.z_at(p)],
        ]);
        mesh.colours.extend([colour; 4]);
        mesh.triangles
            .extend([[i, i + 1, i + 2], [i, i + 2, i + 3]]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::choice::Choice;
    use crate::roof::{Pitch, RoofForm};

    fn normal(m: &Mesh, t: [u32; 3]) -> [f64; 3] {
        let [a, b, c] = t.map(|i| m.positions[i as usize]);
        let (u, v) = (
            [0, 1, 2].map(|k| b[k] - a[k]),
            [0, 1, 2].map(|k| c[k] - a[k]),
        );
        [
            u[1] * v[2] - u[2] * v[1],
            u[2] * v[0] - u[0] * v[2],
            u[0] * v[1] - u[1] * v[0],
        ]
    }

    /// The point 1 cm in front of wall triangle `t`'s centre, on the side its normal faces.
    fn in_front(m: &Mesh, t: [u32; 3]) -> (f64, f64) {
        let n = normal(m, t);
        let c = t.map(|i| m.positions[i as usize]);
        let mid = [0, 1].map(|k| (c[0][k] + c[1][k] + c[2][k]) / 3.0);
        let len = n[0].hypot(n[1]);
        (mid[0] + n[0] / len * 0.01, mid[1] + n[1] / len * 0.01)
    }

    fn area_up(m: &Mesh) -> f64 {
        m.triangles
            .iter()
            .map(|&t| normal(m, t)[2] / 2.0)
            .filter(|a| *a > 0.0)
            .sum()
    }

    fn l_shape() -> Vec<(f64, f64)> {
        // The sample's first building, closed as GeoJSON closes it.
        vec![
            (500369.0, 5300333.0),
            (500384.0, 5300333.0),
            (500384.0, 5300339.5),
            (500375.25, 5300339.5),
            (500375.25, 5300353.25),
            (500369.0, 5300353.25),
            (500369.0, 5300333.0),
        ]
    }

    /// An L-shaped outline at UTM coordinates: the roof covers exactly the polygon's area, at
    /// exactly roof_z, with the outline's corners as its only vertices; every wall faces out.
    #[test]
    fn l_shaped_roof_is_exact_and_walls_face_out() {
        let roof_z = 391.37;
        let m = prism_mesh(
            &Prism {
                rings: vec![l_shape()],
                roof: RoofShape::flat(roof_z),
            },
            370.0,
            [200, 100, 50],
        )
        .unwrap();
        let area = 15.0 * 6.5 + 6.25 * 13.75;
        assert!((area_up(&m) - area).abs() < 1e-6, "{}", area_up(&m));
        let roofs: Vec<_> = m.positions.iter().filter(|p| p[2] == roof_z).collect();
        for p in &roofs {
            assert!(l_shape().contains(&(p[0], p[1])), "{p:?} is not a corner");
        }
        // Walls: horizontal normals pointing away from the polygon's inside.
        let ring = open_ring(&l_shape());
        for &t in &m.triangles {
            let n = normal(&m, t);
            if n[2].abs() > 1e-9 {
                assert!(n[2] > 0.0, "a roof triangle faces down");
                continue;
            }
            let out = in_front(&m, t);
            assert!(
                !inside(std::slice::from_ref(&ring), out),
                "a wall faces in at {out:?}"
            );
        }
        assert_eq!(m.triangles.len(), 4 + 2 * 6);
    }

    /// A courtyard (a hole) stays open, and its walls face into it, whichever way each ring
    /// winds.
    #[test]
    fn courtyard_stays_open_either_winding() {
        let outer = vec![(0.0, 0.0), (10.0, 0.0), (10.0, 10.0), (0.0, 10.0)];
        let hole = vec![(3.0, 3.0), (7.0, 3.0), (7.0, 7.0), (3.0, 7.0)];
        for (o, h) in [(false, false), (true, false), (false, true), (true, true)] {
            let rev = |r: &Vec<(f64, f64)>, flip: bool| {
                let mut r = r.clone();
                if flip {
                    r.reverse();
                }
                r
            };
            let p = Prism {
                rings: vec![rev(&outer, o), rev(&hole, h)],
                roof: RoofShape::flat(12.0),
            };
            let m = prism_mesh(&p, 0.0, [1, 2, 3]).unwrap();
            assert!(
                (area_up(&m) - 84.0).abs() < 1e-9,
                "{o} {h}: {}",
                area_up(&m)
            );
            for &t in &m.triangles {
                let n = normal(&m, t);
                if n[2] != 0.0 {
                    continue;
                }
                let out = in_front(&m, t);
                assert!(
                    !inside(&p.rings, out),
                    "{o} {h}: a wall faces into the solid"
                );
            }
        }
    }

    /// A bow-tie outline and a flat one are errors in words, never a panic.
    #[test]
    fn crossing_and_empty_outlines_are_errors() {
        let bow = Prism {
            rings: vec![vec![(0.0, 0.0), (4.0, 4.0), (4.0, 0.0), (0.0, 4.0)]],
            roof: RoofShape::flat(5.0),
        };
        assert_eq!(
            prism_mesh(&bow, 0.0, [0; 3]).unwrap_err(),
            "its outline crosses itself"
        );
        let flat = Prism {
            rings: vec![vec![(0.0, 0.0), (4.0, 0.0), (8.0, 0.0)]],
            roof: RoofShape::flat(5.0),
        };
        assert!(prism_mesh(&flat, 0.0, [0; 3]).is_err());
        let two = Prism {
            rings: vec![vec![(0.0, 0.0), (4.0, 0.0)]],
            roof: RoofShape::flat(5.0),
        };
        assert!(prism_mesh(&two, 0.0, [0; 3]).is_err());
    }

    /// The outlines the pitched tests raise, world metres at UTM size: a rectangle along the
    /// axes, the same turned 30°, the L shape, a block with a courtyard.
    fn outlines() -> Vec<Vec<Vec<(f64, f64)>>> {
        let turned = |x: f64, y: f64| {
            let (s, c) = 30f64.to_radians().sin_cos();
            (500_100.0 + x * c - y * s, 5_300_100.0 + x * s + y * c)
        };
        vec![
            vec![vec![
                (500_000.0, 5_300_000.0),
                (500_012.0, 5_300_000.0),
                (500_012.0, 5_300_007.0),
                (500_000.0, 5_300_007.0),
            ]],
            vec![vec![
                turned(0.0, 0.0),
                turned(12.0, 0.0),
                turned(12.0, 7.0),
                turned(0.0, 7.0),
            ]],
            vec![l_shape()],
            vec![
                vec![
                    (500_200.0, 5_300_200.0),
                    (500_220.0, 5_300_200.0),
                    (500_220.0, 5_300_216.0),
                    (500_200.0, 5_300_216.0),
                ],
                vec![
                    (500_205.0, 5_300_205.0),
                    (500_205.0, 5_300_211.0),
                    (500_215.0, 5_300_211.0),
                    (500_215.0, 5_300_205.0),
                ],
            ],
        ]
    }

    fn pitched(rings: &[Vec<(f64, f64)>], form: RoofForm, azimuth_deg: f64) -> Prism {
        let pitch = Pitch {
            form,
            eave_z: 395.5,
            azimuth_deg,
        };
        Prism {
            rings: rings.to_vec(),
            roof: RoofShape::new(rings, 401.25, Some(pitch)),
        }
    }

    /// Every pitched form over every outline, at several directions: each roof vertex is at
    /// the roof's height there; no roof triangle crosses a crease (the roof at its centre is
    /// the plane through its corners); the roof covers the outline's area; walls face out;
    /// and the mesh is closed but for its open bottom: every edge above the base is used once
    /// each way (walls meet the roof at the same points, a gable wall's apex included).
    #[test]
    fn pitched_roofs_lie_in_their_planes_and_close_with_the_walls() {
        let base = 380.0;
        for rings in outlines() {
            let open: Vec<_> = rings.iter().map(|r| open_ring(r)).collect();
            let area: f64 = {
                let a: Vec<f64> = open.iter().map(|r| signed_area(r).abs()).collect();
                a[0] - a[1..].iter().sum::<f64>()
            };
            for form in RoofForm::ALL.iter().copied() {
                for az in [0.0, 30.0, 90.0, 120.0, 257.0] {
                    let p = pitched(&rings, form, az);
                    let m = prism_mesh(&p, base, [9, 9, 9]).unwrap();
                    let what = format!("{form:?} {az} over {:?}", rings[0][0]);
                    assert!((area_up(&m) - area).abs() < 1e-6, "{what}: {}", area_up(&m));
                    let mut edges: std::collections::HashMap<[[u64; 3]; 2], i32> =
                        Default::default();
                    for &t in &m.triangles {
                        let c = t.map(|i| m.positions[i as usize]);
                        let n = normal(&m, t);
                        if c.iter().all(|v| v[2] > base) {
                            // A roof triangle (every wall triangle has a corner at the base).
                            assert!(n[2] > 0.0, "{what}: a roof triangle faces down");
                            for v in c {
                                assert_eq!(v[2], p.roof.z_at((v[0], v[1])), "{what}");
                            }
                            // A sliver along an edge split where a crease meets it (the split
                            // point off the line by rounding) has no plane to check.
                            if n[2] > 1e-6 {
                                let mid = [0, 1, 2].map(|k| (c[0][k] + c[1][k] + c[2][k]) / 3.0);
                                let z = p.roof.z_at((mid[0], mid[1]));
                                assert!((z - mid[2]).abs() < 1e-7, "{what}: crosses a crease");
                            }
                        } else {
                            assert!(n[2].abs() < 1e-6, "{what}: a wall leans");
                            let out = in_front(&m, t);
                            assert!(!inside(&open, out), "{what}: a wall faces in");
                        }
                        for k in 0..3 {
                            let (a, b) = (c[k], c[(k + 1) % 3]);
                            if a[2] == base && b[2] == base {
                                continue;
                            }
                            let (key, sign) = match a.map(f64::to_bits) < b.map(f64::to_bits) {
                                true => ([a, b].map(|v| v.map(f64::to_bits)), 1),
                                false => ([b, a].map(|v| v.map(f64::to_bits)), -1),
                            };
                            *edges.entry(key).or_default() += sign;
                        }
                    }
                    let open_edges = edges.values().filter(|&&n| n != 0).count();
                    assert_eq!(open_edges, 0, "{what}: open edges");
                }
            }
        }
    }

    /// The volume the mesh encloses with its floor at the base (divergence theorem over its
    /// triangles, the floor's share added) is the analytic volume of each roof over a
    /// rectangle: walls to the eaves plus a gable's half box, a shed's half box, or a hip's
    /// `rise · W · (3L − W) / 6`.
    #[test]
    fn a_pitched_prism_holds_the_analytic_volume() {
        let rings = &outlines()[1];
        let (l, w, base, eave, top) = (12.0, 7.0, 380.0, 395.5, 401.25);
        // The outline's long side points 60° east of north. A hip whose azimuth is across it
        // is as wide as long: its crest is lower, `rise · w / l`, its pitch the same.
        let hip = |rise: f64| rise * w * (3.0 * l - w) / 6.0;
        for (form, az, roof) in [
            (RoofForm::Gable, 60.0, (top - eave) * l * w / 2.0),
            (RoofForm::Gable, 150.0, (top - eave) * l * w / 2.0),
            (RoofForm::Shed, 240.0, (top - eave) * l * w / 2.0),
            (RoofForm::Hip, 60.0, hip(top - eave)),
            (RoofForm::Hip, 150.0, hip((top - eave) * w / l)),
        ] {
            let m = prism_mesh(&pitched(rings, form, az), base, [0; 3]).unwrap();
            // Relative to a corner at the base, where the floor adds nothing.
            let o = [rings[0][0].0, rings[0][0].1, base];
            let v: f64 = (m.triangles.iter())
                .map(|t| {
                    let [a, b, c] = t.map(|i| {
                        let p = m.positions[i as usize];
                        [p[0] - o[0], p[1] - o[1], p[2] - o[2]]
                    });
                    (a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
                        + a[2] * (b[0] * c[1] - b[1] * c[0]))
                        / 6.0
                })
                .sum();
            let want = l * w * (eave - base) + roof;
            assert!((v - want).abs() < 1e-6, "{form:?} {az}: {v} against {want}");
        }
    }

    /// A gable wall is a pentagon: its edge under the ridge gains the ridge's end, at the top.
    #[test]
    fn a_gable_wall_rises_to_the_ridge() {
        let rings = &outlines()[0];
        let p = pitched(rings, RoofForm::Gable, 90.0);
        let m = prism_mesh(&p, 380.0, [0; 3]).unwrap();
        for x in [500_000.0, 500_012.0] {
            let apex = (m.positions.iter()).filter(|q| q[0] == x && q[1] == 5_300_003.5);
            assert_eq!(apex.map(|q| q[2]).fold(0.0, f64::max), 401.25);
        }
        // Two roof planes of two triangles each; eight wall quads (two per gable end).
        assert_eq!(m.triangles.len(), 4 + 2 * 6);
    }
}
