//! Placed voxel objects as triangle meshes with merged faces.
//!
//! Invariant: the mesh is exactly the boundary between an object's solid and empty voxels
//! (outside the grid counts as empty), each face facing the empty side, and coplanar
//! neighbouring faces of one colour are merged into rectangles ("greedy meshing": in each
//! slice, a face is grown first along one axis, then along the other, as far as the colour
//! holds). A solid cube of n³ voxels of one colour is 12 triangles, not 12 n². The object is
//! placed as [`crate::standing`] places it for the pyramid: voxel offsets from the anchor
//! scaled by the placement's scale, turned by its heading (clockwise from north), put at its
//! position.

use super::Mesh;
use crate::db::PlacedObject;
use crate::voxel::object::VoxelObject;

/// The surface of `obj` as merged, coloured faces, placed by `placed` (world metres).
pub fn object_mesh(obj: &VoxelObject, placed: &PlacedObject) -> Mesh {
    let dims = obj.grid.dims;
    // Dense colours: 0 = empty, else 0x01RRGGBB.
    let mut colour = vec![0u32; obj.grid.len()];
    for ([x, y, z], [r, g, b]) in obj.voxels() {
        colour[obj.grid.index(x, y, z)] = 1 << 24 | (r as u32) << 16 | (g as u32) << 8 | b as u32;
    }
    let at = |p: [i64; 3]| -> u32 {
        if (0..3).any(|k| p[k] < 0 || p[k] >= dims[k] as i64) {
            0
        } else {
            colour[obj.grid.index(p[0] as u32, p[1] as u32, p[2] as u32)]
        }
    };
    let place = Placement::new(obj, placed);
    let mut mesh = Mesh::default();
    for a in 0..3 {
        // The face's own axes, cyclic after a: b × c = a.
        let (b, c) = ((a + 1) % 3, (a + 2) % 3);
        let (nb, nc) = (dims[b] as usize, dims[c] as usize);
        let mut mask = vec![0u32; nb * nc];
        for step in [1i64, -1] {
            for k in 0..dims[a] as i64 {
                for j in 0..nc {
                    for i in 0..nb {
                        let mut p = [0i64; 3];
                        (p[a], p[b], p[c]) = (k, i as i64, j as i64);
                        let here = at(p);
                        p[a] += step;
                        mask[j * nb + i] = if here != 0 && at(p) == 0 { here } else { 0 };
                    }
                }
                // The face plane: the voxel's far side for +a, its near side for −a.
                let plane = if step > 0 { k + 1 } else { k };
                for (i0, j0, w, h, rgb) in rectangles(&mut mask, nb, nc) {
                    let corner = |i: usize, j: usize| {
                        let mut p = [0i64; 3];
                        (p[a], p[b], p[c]) = (plane, i as i64, j as i64);
                        place.world(p)
                    };
                    let quad = [
                        corner(i0, j0),
                        corner(i0 + w, j0),
                        corner(i0 + w, j0 + h),
                        corner(i0, j0 + h),
                    ];
                    let n = mesh.positions.len() as u32;
                    mesh.positions.extend(quad);
                    mesh.colours.extend([rgb; 4]);
                    // Counter-clockwise seen from +a; reversed for faces looking down −a.
                    mesh.triangles.extend(match step > 0 {
                        true => [[n, n + 1, n + 2], [n, n + 2, n + 3]],
                        false => [[n, n + 2, n + 1], [n, n + 3, n + 2]],
                    });
                }
            }
        }
    }
    mesh
}

/// The maximal rectangles of one colour in `mask` (`nb` × `nc`, row j, column i; 0 = no face),
/// greedily from the first face in row-major order: widest run first, then as many rows as the
/// whole run repeats. Clears the mask. Each is `(i, j, width, height, colour)`.
fn rectangles(
    mask: &mut [u32],
    nb: usize,
    nc: usize,
) -> Vec<(usize, usize, usize, usize, [u8; 3])> {
    let mut out = Vec::new();
    for j in 0..nc {
        let mut i = 0;
        while i < nb {
            let c = mask[j * nb + i];
            if c == 0 {
                i += 1;
                continue;
            }
            let w = (i..nb).take_while(|&x| mask[j * nb + x] == c).count();
            let h = (j..nc)
                .take_while(|&y| (i..i + w).all(|x| mask[y * nb + x] == c))
                .count();
            for y in j..j + h {
                mask[y * nb + i..y * nb + i + w].fill(0);
            }
            out.push((i, j, w, h, [(c >> 16) as u8, (c >> 8) as u8, c as u8]));
            i += w;
        }
    }
    out
}

/// Voxel-grid corners to world metres for one placement.
struct Placement {
    /// The grid's origin relative to the anchor, metres (unscaled).
    origin: [f64; 3],
    voxel: f64,
    scale: f64,
    sin: f64,
    cos: f64,
    at: [f64; 3],
}

impl Placement {
    fn new(obj: &VoxelObject, placed: &PlacedObject) -> Placement {
        let a = obj.anchor();
        let (sin, cos) = placed.heading_deg.to_radians().sin_cos();
        Placement {
            origin: [0, 1, 2].map(|k| obj.grid.origin[k] - a[k]),
            voxel: obj.grid.voxel_size,
            scale: placed.scale,
            sin,
            cos,
            at: [placed.x, placed.y, placed.z],
        }
    }

    /// World position of voxel-grid corner `p` (integer voxel coordinates).
    fn world(&self, p: [i64; 3]) -> [f64; 3] {
        let [u, v, w] = [0, 1, 2].map(|k| (self.origin[k] + p[k] as f64 * self.voxel) * self.scale);
        // Local u → world (cos h, −sin h); local v → world (sin h, cos h), as standing does.
        [
            self.at[0] + u * self.cos + v * self.sin,
            self.at[1] - u * self.sin + v * self.cos,
            self.at[2] + w,
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::voxel::grid::VoxelGrid;

    fn placed(heading_deg: f64, scale: f64) -> PlacedObject {
        serde_json::from_value(serde_json::json!({
            "file": "x.dvox", "sha256": "", "x": 500000.0, "y": 5300000.0, "z": 400.0,
            "heading_deg": heading_deg, "scale": scale
        }))
        .unwrap()
    }

    fn object(
        dims: [u32; 3],
        solid: impl Fn(u32, u32, u32) -> Option<[u8; 3]> + Sync,
    ) -> VoxelObject {
        let grid = VoxelGrid::new([0.0, 0.0, 0.0], 0.5, dims).unwrap();
        let g = grid;
        VoxelObject::from_fn(grid, move |_, i| {
            let [x, y, z] = g.coords(i);
            solid(x, y, z)
        })
    }

    /// Signed volume by the divergence theorem: the mesh is closed and faces out exactly when
    /// this equals the solid voxels' volume.
    fn volume(m: &Mesh) -> f64 {
        let o = m.positions[0];
        m.triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| [0, 1, 2].map(|k| m.positions[i as usize][k] - o[k]));
                (a[0] * (b[1] * c[2] - b[2] * c[1]) - a[1] * (b[0] * c[2] - b[2] * c[0])
                    + a[2] * (b[0] * c[1] - b[1] * c[0]))
                    / 6.0
            })
            .sum()
    }

    /// A one-colour solid block is 12 triangles whatever its size; its volume is the voxels'.
    #[test]
    fn solid_block_is_twelve_triangles() {
        let obj = object([5, 4, 3], |_, _, _| Some([10, 20, 30]));
        for heading in [0.0, 90.0, 33.0, 180.0 + 1e-9] {
            let m = object_mesh(&obj, &placed(heading, 2.0));
            assert_eq!(m.triangles.len(), 12, "heading {heading}");
            let expect = 5.0 * 4.0 * 3.0 * (0.5f64 * 2.0).powi(3);
            assert!(
                (volume(&m) - expect).abs() < 1e-6,
                "{} vs {expect}",
                volume(&m)
            );
        }
    }

    /// A hollow shell and a two-colour checker: closed, outward (volume exact), every face
    /// between solid and empty, colours kept per face.
    #[test]
    fn hollow_and_checkered_objects_are_closed_and_outward() {
        let hollow = object([4, 4, 4], |x, y, z| {
            let edge = |v: u32| v == 0 || v == 3;
            (edge(x) || edge(y) || edge(z)).then_some([9, 9, 9])
        });
        let m = object_mesh(&hollow, &placed(47.0, 1.0));
        assert!(
            (volume(&m) - (64.0 - 8.0) * 0.125).abs() < 1e-6,
            "{}",
            volume(&m)
        );
        let checker = object([3, 3, 3], |x, y, z| {
            Some(if (x + y + z) % 2 == 0 {
                [255, 0, 0]
            } else {
                [0, 0, 255]
            })
        });
        let m = object_mesh(&checker, &placed(0.0, 1.0));
        // Every outer face is its own voxel's colour: 54 unit faces, none merged.
        assert_eq!(m.triangles.len(), 2 * 54);
        assert!((volume(&m) - 27.0 * 0.125).abs() < 1e-9);
    }

    /// The heading turns the object as the pyramid does: +v (north at 0°) points east at 90°.
    #[test]
    fn heading_matches_standing() {
        // A column of voxels along +y (local v).
        let obj = object([1, 4, 1], |_, _, _| Some([1, 1, 1]));
        let m = object_mesh(&obj, &placed(90.0, 1.0));
        let (lo, hi) = m.bounds().unwrap();
        assert!(
            (hi[0] - lo[0] - 2.0).abs() < 1e-9,
            "long axis should run east"
        );
        assert!((hi[1] - lo[1] - 0.5).abs() < 1e-9);
        assert_eq!(lo[2], 400.0, "the anchor is the grid's bottom face");
    }
}
