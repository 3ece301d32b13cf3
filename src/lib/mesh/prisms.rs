//! Buildings as triangle meshes: each flat-roofed prism of the `buildings` layer becomes its
//! roof, triangulated at exactly `roof_z`, and one wall per outline edge from a base below the
//! terrain up to the roof.
//!
//! Invariant: every roof vertex is an outline vertex at the layer's `roof_z` (no vertex is
//! added or moved), so the mesh's building heights are the layer's, as exactly as the file
//! that stores them keeps coordinates. The roof is a constrained Delaunay triangulation of the
//! outline (spade) whose triangles with a centre inside the polygon (even-odd rule, so holes
//! stay open, as [`crate::standing::polygon_cells`] rasterises them) are kept. Walls face out
//! of the solid: an outer ring's walls away from its inside, a hole's walls into the hole.

use super::Mesh;
use crate::standing::Prism;
use spade::{ConstrainedDelaunayTriangulation, Point2, Triangulation};

/// A building prism as triangles: its roof at the prism's `roof_z` (metres) and a wall per
/// outline edge from `base_z` (metres, below the terrain under the building) to the roof, all
/// in `colour` (sRGB). An outline that crosses itself, or that has no area, is an `Err` with
/// the problem in words.
pub fn prism_mesh(prism: &Prism, base_z: f64, colour: [u8; 3]) -> Result<Mesh, String> {
    let rings: Vec<Vec<(f64, f64)>> = prism.rings.iter().map(|r| open_ring(r)).collect();
    if rings.iter().all(|r| r.len() < 3) {
        return Err("its outline has fewer than three corners".into());
    }
    let mut mesh = Mesh::default();
    roof(&rings, prism.roof.top_z, colour, &mut mesh)?;
    if mesh.is_empty() {
        return Err("its outline encloses no area".into());
    }
    for (k, ring) in rings.iter().enumerate() {
        // A ring inside an odd number of the others is a hole: the solid lies outside it.
        let depth = rings
            .iter()
            .enumerate()
            .filter(|&(j, other)| j != k && inside(std::slice::from_ref(other), ring[0]))
            .count();
        let solid_on_left = (signed_area(ring) > 0.0) == (depth % 2 == 0);
        walls(
            ring,
            solid_on_left,
            base_z,
            prism.roof.top_z,
            colour,
            &mut mesh,
        );
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
fn inside(rings: &[Vec<(f64, f64)>], p: (f64, f64)) -> bool {
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

/// Triangulate the roof: every outline edge a constraint, the triangles inside kept.
fn roof(
    rings: &[Vec<(f64, f64)>],
    roof_z: f64,
    colour: [u8; 3],
    mesh: &mut Mesh,
) -> Result<(), String> {
    // Coordinates relative to the first corner: spade works on small numbers, and adding the
    // corner back gives each world coordinate exactly (the differences are exact, Sterbenz).
    let (x0, y0) = rings.iter().flatten().next().copied().unwrap_or_default();
    let mut cdt: ConstrainedDelaunayTriangulation<Point2<f64>> = Default::default();
    for ring in rings.iter().filter(|r| r.len() >= 3) {
        let handles = ring
            .iter()
            .map(|&(x, y)| cdt.insert(Point2::new(x - x0, y - y0)))
            .collect::<Result<Vec<_>, _>>()
            .map_err(|e| format!("a corner cannot be triangulated ({e:?})"))?;
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
    let mut index = vec![u32::MAX; cdt.num_vertices()];
    for face in cdt.inner_faces() {
        let [a, b, c] = face.positions();
        let centre = ((a.x + b.x + c.x) / 3.0 + x0, (a.y + b.y + c.y) / 3.0 + y0);
        if !inside(rings, centre) {
            continue;
        }
        let tri = face.vertices().map(|v| {
            let i = v.fix().index();
            if index[i] == u32::MAX {
                index[i] = mesh.positions.len() as u32;
                let p = v.position();
                mesh.positions.push([p.x + x0, p.y + y0, roof_z]);
                mesh.colours.push(colour);
            }
            index[i]
        });
        mesh.triangles.push(tri);
    }
    Ok(())
}

/// One quad per edge of `ring` from `base_z` to `roof_z`, facing away from the solid (which
/// lies left of each edge when `solid_on_left`).
fn walls(
    ring: &[(f64, f64)],
    solid_on_left: bool,
    base_z: f64,
    roof_z: f64,
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
            [q.0, q.1, roof_z],
            [p.0, p.1, roof_z],
        ]);
        mesh.colours.extend([colour; 4]);
        mesh.triangles
            .extend([[i, i + 1, i + 2], [i, i + 2, i + 3]]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
                roof: crate::roof::RoofShape::flat(roof_z),
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
                roof: crate::roof::RoofShape::flat(12.0),
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
            roof: crate::roof::RoofShape::flat(5.0),
        };
        assert_eq!(
            prism_mesh(&bow, 0.0, [0; 3]).unwrap_err(),
            "its outline crosses itself"
        );
        let flat = Prism {
            rings: vec![vec![(0.0, 0.0), (4.0, 0.0), (8.0, 0.0)]],
            roof: crate::roof::RoofShape::flat(5.0),
        };
        assert!(prism_mesh(&flat, 0.0, [0; 3]).is_err());
        let two = Prism {
            rings: vec![vec![(0.0, 0.0), (4.0, 0.0)]],
            roof: crate::roof::RoofShape::flat(5.0),
        };
        assert!(prism_mesh(&two, 0.0, [0; 3]).is_err());
    }
}
