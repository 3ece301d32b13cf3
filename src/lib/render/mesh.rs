//! Ray-casting a triangle mesh with the tile renderer's camera rays: the check that an exported
//! mesh ([`crate::mesh`]) shows what the tiles show. A test and benchmark tool (`cargo bench
//! --bench mesh`), compiled only with the `testing` feature, as `crate::testing` is.
//!
//! Each pixel `(i, j)` casts the ray [`render_view`](super::render_view) casts: from the eye along
//! `forward + x′·right + y′·up` with `x′`, `y′` the terms of the pixel's centre
//! ([`Basis::through_terms`]), not normalised. Its range is the ray parameter times the
//! direction's length (metres, as [`super::ray::Ray::range`]), stored as `f32` with `+inf` for
//! rays that hit nothing (the tile renderer's range image). A hit's colour is the triangle's
//! vertex colours interpolated barycentrically, or, on a part with a [`Drape`], its image sampled
//! as a viewer samples it: texture coordinates interpolated, then the four nearest texels
//! blended (bilinear, clamped at the edges; in sRGB bytes, no shading or haze). A miss takes the
//! daylight sky of the tile renderer.
//!
//! Geometry is held in f64 relative to a local origin (the centre of the mesh's box), so UTM-sized
//! coordinates keep sub-micrometre precision. Triangles are tested with the watertight
//! algorithm of Woop, Benthin & Wald (JCGT 2013): the ray's dominant axis is made `z`, the
//! vertices sheared so the ray runs along it, and the signs of the three 2-D edge functions
//! decide the hit, inclusive of zero.
//!
//! Invariants: an edge function of an edge shared by two triangles is computed from the same
//! two transformed vertices in the same order of operations, so the two triangles get exactly
//! opposite values (and, when the value rounds to zero, the exact sign of the products'
//! difference from their rounding errors): a ray through a shared edge or vertex of a closed
//! surface hits at least one of its triangles, never falls through. The bounding volume
//! hierarchy culls only boxes that the ray misses by more than a margin of rounding (each box
//! padded by `1e-12` of the coordinates' size, the slab times widened by `1 + 2γ₃`, Ize 2013),
//! so it reports a hit exactly when testing every triangle would, at the nearest range to
//! rounding.

use super::camera::{Basis, Viewpoint};
use super::sky::Backdrop;
use crate::error::Result;
use crate::mesh::{Drape, Mesh, Part};
use rayon::prelude::*;

/// Most triangles a leaf of the hierarchy holds.
const LEAF: usize = 4;

/// Relative size of a box's padding against rounding in the triangle test (see the module docs).
const PAD: f64 = 1e-12;

/// A mesh prepared for ray casting: positions relative to a local origin and a bounding volume
/// hierarchy over its triangles.
#[derive(Debug, Clone)]
pub struct MeshScene {
    /// World position of the local frame's origin, metres.
    origin: [f64; 3],
    /// Vertex positions relative to `origin`, metres.
    positions: Vec<[f64; 3]>,
    colours: Vec<[u8; 3]>,
    /// Texture coordinates of each vertex of a draped part (unused for the others).
    uv: Vec<[f32; 2]>,
    /// The drapes' images.
    drapes: Vec<Drape>,
    /// Per stored triangle: the index of its drape in `drapes`, or `NO_DRAPE`.
    drape_of: Vec<u32>,
    /// The triangles in the order the leaves hold them.
    triangles: Vec<[u32; 3]>,
    /// Index into the mesh's triangles of each of `triangles`.
    ids: Vec<u32>,
    /// Nodes, root first; an inner node's children are adjacent.
    nodes: Vec<Node>,
    /// Largest absolute local coordinate, metres (the scale of the boxes' padding).
    scale: f64,
}

/// A box of the hierarchy: an inner node (`count == 0`, children at `start` and `start + 1`) or
/// a leaf holding `triangles[start..start + count]`.
#[derive(Debug, Clone, Copy)]
struct Node {
    lo: [f64; 3],
    hi: [f64; 3],
    start: u32,
    count: u32,
}

/// Where a ray met the mesh.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MeshHit {
    /// Distance from the eye along the ray, metres.
    pub range: f64,
    /// Index of the triangle hit in the mesh given to [`MeshScene::new`] (the parts' triangles
    /// one after the other for [`MeshScene::of_parts`]).
    pub triangle: u32,
    /// The triangle's vertex colours interpolated at the hit, or its drape sampled there, sRGB.
    pub colour: [u8; 3],
}

/// A mesh rendered with [`render_mesh`]: row-major from the top-left, as [`super::Frame`].
#[derive(Debug, Clone)]
pub struct MeshFrame {
    /// Width, pixels.
    pub width: usize,
    /// Height, pixels.
    pub height: usize,
    /// Colour of each pixel: the hit's interpolated vertex colour, or the sky.
    pub rgb: Vec<[u8; 3]>,
    /// Range of each pixel's hit, metres; `+inf` where the ray hit nothing.
    pub range: Vec<f32>,
    /// Pixels whose ray hit the mesh.
    pub hits: u64,
}

impl MeshFrame {
    /// The frame as PNG bytes (8-bit RGB).
    pub fn png(&self) -> Result<Vec<u8>> {
        crate::io::png::encode_rgb(self.width, self.height, self.rgb.as_flattened())
    }
}

/// Render `scene` through `camera`: the rays of [`render_view`](super::render_view) (module docs),
/// image rows in parallel.
pub fn render_mesh(scene: &MeshScene, camera: &Viewpoint) -> Result<MeshFrame> {
    camera.validate()?;
    let basis: Basis = camera.basis();
    let (w, h) = (camera.width, camera.height);
    let x_terms: Vec<f64> = (0..w).map(|i| basis.x_term(i as f64 + 0.5)).collect();
    let rows: Vec<(Vec<[u8; 3]>, Vec<f32>)> = (0..h)
        .into_par_iter()
        .map(|j| {
            let y = basis.y_term(j as f64 + 0.5);
            x_terms
                .iter()
                .map(|&x| {
                    let d = basis.through_terms(x, y);
                    match scene.intersect(camera.eye, d) {
                        Some(hit) => (hit.colour, hit.range as f32),
                        None => {
                            let norm = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                            (Backdrop::Daylight.sky(d[2] / norm), f32::INFINITY)
                        }
                    }
                })
                .unzip()
        })
        .collect();
    let (mut rgb, mut range) = (Vec::with_capacity(w * h), Vec::with_capacity(w * h));
    for (c, r) in rows {
        rgb.extend(c);
        range.extend(r);
    }
    let hits = range.iter().filter(|r| r.is_finite()).count() as u64;
    Ok(MeshFrame {
        width: w,
        height: h,
        rgb,
        range,
        hits,
    })
}

/// A ray in the local frame with what the watertight test precomputes from its direction.
struct LocalRay {
    org: [f64; 3],
    dir: [f64; 3],
    /// Axes permuted so `kz` is the direction's largest component (`kx`, `ky` swapped when it
    /// is negative, to keep the triangles' winding).
    k: [usize; 3],
    /// Shear `(d_x/d_z, d_y/d_z, 1/d_z)` in the permuted axes.
    shear: [f64; 3],
    inv: [f64; 3],
    /// The boxes' padding for this ray, metres.
    pad: f64,
}

impl LocalRay {
    fn new(org: [f64; 3], dir: [f64; 3], scale: f64) -> LocalRay {
        let a = dir.map(f64::abs);
        let kz = match (a[0] >= a[1], a[0] >= a[2], a[1] >= a[2]) {
            (true, true, _) => 0,
            (false, _, true) => 1,
            _ => 2,
        };
        let (mut kx, mut ky) = ((kz + 1) % 3, (kz + 2) % 3);
        if dir[kz] < 0.0 {
            std::mem::swap(&mut kx, &mut ky);
        }
        let norm = org.iter().fold(0.0f64, |m, c| m.max(c.abs()));
        LocalRay {
            org,
            dir,
            k: [kx, ky, kz],
            shear: [dir[kx] / dir[kz], dir[ky] / dir[kz], 1.0 / dir[kz]],
            inv: dir.map(|c| 1.0 / c),
            pad: PAD * (scale + norm),
        }
    }

    /// The ray's parameter where it enters the box `lo..hi` (padded), if it meets it in
    /// `[0, t_max]`. Conservative: a ray in the plane of a face (`0 · ∞ = NaN`) is not limited
    /// by that axis, and the exit time is widened by `1 + 2γ₃`.
    #[inline]
    fn enters(&self, lo: [f64; 3], hi: [f64; 3], t_max: f64) -> Option<f64> {
        let (mut near, mut far) = (0.0f64, t_max);
        for k in 0..3 {
            let (a, b) = (
                lo[k] - self.pad - self.org[k],
                hi[k] + self.pad - self.org[k],
            );
            let (n, f) = match self.inv[k].is_sign_negative() {
                false => (a * self.inv[k], b * self.inv[k]),
                true => (b * self.inv[k], a * self.inv[k]),
            };
            near = near.max(n); // f64::max ignores a NaN
            far = far.min(f + f.abs() * 2.0 * GAMMA3);
        }
        (near <= far).then_some(near)
    }

    /// The watertight test against triangle `p`: the ray parameter `t > 0` of the hit and the
    /// barycentric weights of the three vertices.
    #[inline]
    fn hit(&self, p: [[f64; 3]; 3]) -> Option<(f64, [f64; 3])> {
        let [kx, ky, kz] = self.k;
        let [sx, sy, sz] = self.shear;
        let q = p.map(|v| {
            let a = [v[0] - self.org[0], v[1] - self.org[1], v[2] - self.org[2]];
            [a[kx] - sx * a[kz], a[ky] - sy * a[kz], sz * a[kz]]
        });
        let [a, b, c] = q;
        let u = edge(c, b);
        let v = edge(a, c);
        let w = edge(b, a);
        if (u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0) {
            return None;
        }
        let det = u + v + w;
        if det == 0.0 {
            return None; // the ray is in the triangle's plane, or the triangle has no area
        }
        let t = (u * a[2] + v * b[2] + w * c[2]) / det;
        if t.is_nan() || t <= 0.0 {
            return None;
        }
        Some((t, [u / det, v / det, w / det]))
    }
}

/// `γ₃ = 3ε / (1 − 3ε)`: the relative error bound of three rounded operations (ε = 2⁻⁵³).
const GAMMA3: f64 = 3.0 * (f64::EPSILON / 2.0) / (1.0 - 3.0 * (f64::EPSILON / 2.0));

/// The 2-D edge function `q_x·p_y − q_y·p_x` of the sheared points `p → q`; where it rounds to
/// zero, the difference of the two products' rounding errors, whose sign is the exact one. So
/// `edge(q, p) == -edge(p, q)` bit for bit.
#[inline]
fn edge(q: [f64; 3], p: [f64; 3]) -> f64 {
    let (m, n) = (q[0] * p[1], q[1] * p[0]);
    let e = m - n;
    if e != 0.0 {
        return e;
    }
    q[0].mul_add(p[1], -m) - q[1].mul_add(p[0], -n)
}

/// A triangle without a drape.
const NO_DRAPE: u32 = u32::MAX;

impl MeshScene {
    /// Prepare `mesh` (world coordinates) for ray casting, coloured by its vertex colours.
    pub fn new(mesh: &Mesh) -> MeshScene {
        let none = vec![NO_DRAPE; mesh.triangles.len()];
        MeshScene::build(
            mesh,
            vec![[0.0; 2]; mesh.positions.len()],
            Vec::new(),
            &none,
        )
    }

    /// Prepare `parts` (world coordinates; a tile's, or several tiles') for ray casting, each
    /// coloured by its drape where it has one.
    pub fn of_parts(parts: &[Part]) -> MeshScene {
        let (mut mesh, mut uv, mut drapes, mut drape_of) =
            (Mesh::default(), vec![], vec![], vec![]);
        for p in parts {
            mesh.append(&p.mesh);
            let tag = match &p.drape {
                Some(d) => {
                    uv.extend_from_slice(&d.uv);
                    // The image only: the coordinates are in `uv` now.
                    drapes.push(Drape {
                        width: d.width,
                        height: d.height,
                        texels: d.texels.clone(),
                        uv: Vec::new(),
                    });
                    drapes.len() as u32 - 1
                }
                None => {
                    uv.resize(mesh.positions.len(), [0.0; 2]);
                    NO_DRAPE
                }
            };
            drape_of.resize(mesh.triangles.len(), tag);
        }
        MeshScene::build(&mesh, uv, drapes, &drape_of)
    }

    /// The scene of `mesh` with texture coordinates `uv`, images `drapes` and each triangle's
    /// drape `drape_of` (mesh order).
    fn build(mesh: &Mesh, uv: Vec<[f32; 2]>, drapes: Vec<Drape>, drape_of: &[u32]) -> MeshScene {
        let origin = match mesh.bounds() {
            Some((lo, hi)) => std::array::from_fn(|k| (lo[k] + hi[k]) / 2.0),
            None => [0.0; 3],
        };
        let positions: Vec<[f64; 3]> = mesh
            .positions
            .iter()
            .map(|p| std::array::from_fn(|k| p[k] - origin[k]))
            .collect();
        let scale = positions
            .iter()
            .flatten()
            .fold(0.0f64, |m, c| m.max(c.abs()));
        let mut ids: Vec<u32> = (0..mesh.triangles.len() as u32).collect();
        let boxes: Vec<([f64; 3], [f64; 3])> = mesh
            .triangles
            .iter()
            .map(|t| {
                let p = t.map(|i| positions[i as usize]);
                (
                    std::array::from_fn(|k| p[0][k].min(p[1][k]).min(p[2][k])),
                    std::array::from_fn(|k| p[0][k].max(p[1][k]).max(p[2][k])),
                )
            })
            .collect();
        let mut nodes = Vec::new();
        if !ids.is_empty() {
            nodes.push(Node {
                lo: [0.0; 3],
                hi: [0.0; 3],
                start: 0,
                count: 0,
            });
            build(&mut nodes, 0, &mut ids, 0, &boxes);
        }
        MeshScene {
            origin,
            triangles: ids.iter().map(|&i| mesh.triangles[i as usize]).collect(),
            drape_of: ids.iter().map(|&i| drape_of[i as usize]).collect(),
            colours: mesh.colours.clone(),
            uv,
            drapes,
            positions,
            ids,
            nodes,
            scale,
        }
    }

    /// Number of triangles.
    pub fn len(&self) -> usize {
        self.triangles.len()
    }

    /// Whether the scene has no triangle.
    pub fn is_empty(&self) -> bool {
        self.triangles.is_empty()
    }

    /// The nearest hit of the ray from world point `eye` along world direction `dir` (any
    /// nonzero length; the range is in metres whatever it is), or `None`.
    pub fn intersect(&self, eye: [f64; 3], dir: [f64; 3]) -> Option<MeshHit> {
        let ray = self.local_ray(eye, dir);
        let mut best: Option<(f64, usize, [f64; 3])> = None;
        // Nodes to visit with the ray's entry time into their box; the nearer child on top.
        let mut stack = [(0.0f64, 0u32); 64];
        let mut top = 0;
        let root = self.nodes.first()?;
        if let Some(t) = ray.enters(root.lo, root.hi, f64::INFINITY) {
            stack[0] = (t, 0);
            top = 1;
        }
        while top > 0 {
            top -= 1;
            let (entry, n) = stack[top];
            let t_max = best.map_or(f64::INFINITY, |b| b.0);
            if entry > t_max {
                continue;
            }
            let node = self.nodes[n as usize];
            if node.count > 0 {
                let first = node.start as usize;
                for s in first..first + node.count as usize {
                    if let Some((t, w)) = ray.hit(self.corners(s)) {
                        if best.is_none_or(|b| t < b.0) {
                            best = Some((t, s, w));
                        }
                    }
                }
                continue;
            }
            let enter = |c: u32| {
                let child = &self.nodes[c as usize];
                ray.enters(child.lo, child.hi, t_max).map(|t| (t, c))
            };
            match (enter(node.start), enter(node.start + 1)) {
                (Some(a), Some(b)) => {
                    let (near, far) = if a.0 <= b.0 { (a, b) } else { (b, a) };
                    stack[top] = far;
                    stack[top + 1] = near;
                    top += 2;
                }
                (Some(a), None) | (None, Some(a)) => {
                    stack[top] = a;
                    top += 1;
                }
                (None, None) => {}
            }
        }
        best.map(|(t, s, w)| self.hit_of(&ray, t, s, w))
    }

    /// [`MeshScene::intersect`] by testing every triangle: the reference the hierarchy is
    /// checked against.
    #[cfg(test)]
    fn intersect_all(&self, eye: [f64; 3], dir: [f64; 3]) -> Option<MeshHit> {
        let ray = self.local_ray(eye, dir);
        let mut best: Option<(f64, usize, [f64; 3])> = None;
        for s in 0..self.triangles.len() {
            if let Some((t, w)) = ray.hit(self.corners(s)) {
                if best.is_none_or(|b| t < b.0) {
                    best = Some((t, s, w));
                }
            }
        }
        best.map(|(t, s, w)| self.hit_of(&ray, t, s, w))
    }

    fn local_ray(&self, eye: [f64; 3], dir: [f64; 3]) -> LocalRay {
        debug_assert!(dir.iter().any(|&c| c != 0.0), "a ray needs a direction");
        let org = std::array::from_fn(|k| eye[k] - self.origin[k]);
        LocalRay::new(org, dir, self.scale)
    }

    fn corners(&self, s: usize) -> [[f64; 3]; 3] {
        self.triangles[s].map(|i| self.positions[i as usize])
    }

    /// The hit at ray parameter `t` on stored triangle `s` with barycentric weights `w`.
    fn hit_of(&self, ray: &LocalRay, t: f64, s: usize, w: [f64; 3]) -> MeshHit {
        let d = ray.dir;
        let norm = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        let tri = self.triangles[s];
        let colour = match self.drape_of[s] {
            NO_DRAPE => {
                let c = tri.map(|i| self.colours[i as usize]);
                std::array::from_fn(|k| {
                    let v = w[0] * c[0][k] as f64 + w[1] * c[1][k] as f64 + w[2] * c[2][k] as f64;
                    v.round().clamp(0.0, 255.0) as u8
                })
            }
            d => {
                let t = tri.map(|i| self.uv[i as usize]);
                let uv = [0, 1]
                    .map(|k| w[0] * t[0][k] as f64 + w[1] * t[1][k] as f64 + w[2] * t[2][k] as f64);
                bilinear(&self.drapes[d as usize], uv)
            }
        };
        MeshHit {
            range: t * norm,
            triangle: self.ids[s],
            colour,
        }
    }
}

/// `drape`'s image at texture coordinates `uv` as a viewer's linear, edge-clamped sampler gives
/// it: the four texels around, blended by distance to their centres.
fn bilinear(drape: &Drape, [u, v]: [f64; 2]) -> [u8; 3] {
    let (w, h) = (drape.width as usize, drape.height as usize);
    let (x, y) = (u * w as f64 - 0.5, v * h as f64 - 0.5);
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let at = |xi: f64, yi: f64| {
        let c = (xi.max(0.0) as usize).min(w - 1);
        let r = (yi.max(0.0) as usize).min(h - 1);
        drape.texels[r * w + c].map(f64::from)
    };
    let (a, b, c, d) = (
        at(x0, y0),
        at(x0 + 1.0, y0),
        at(x0, y0 + 1.0),
        at(x0 + 1.0, y0 + 1.0),
    );
    std::array::from_fn(|k| {
        let top = a[k] + (b[k] - a[k]) * fx;
        let bottom = c[k] + (d[k] - c[k]) * fx;
        (top + (bottom - top) * fy).round().clamp(0.0, 255.0) as u8
    })
}

/// Fill node `n` with the triangles `ids` (the slice of the order starting at `offset`): its box,
/// and either a leaf or two children split at the median centroid along the axis where the
/// centroids spread most.
fn build(
    nodes: &mut Vec<Node>,
    n: usize,
    ids: &mut [u32],
    offset: usize,
    boxes: &[([f64; 3], [f64; 3])],
) {
    let (mut lo, mut hi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    let (mut clo, mut chi) = ([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]);
    for &i in ids.iter() {
        let (a, b) = boxes[i as usize];
        for k in 0..3 {
            lo[k] = lo[k].min(a[k]);
            hi[k] = hi[k].max(b[k]);
            let c = a[k] + b[k];
            clo[k] = clo[k].min(c);
            chi[k] = chi[k].max(c);
        }
    }
    nodes[n].lo = lo;
    nodes[n].hi = hi;
    if ids.len() <= LEAF {
        nodes[n].start = offset as u32;
        nodes[n].count = ids.len() as u32;
        return;
    }
    let axis = (0..3)
        .max_by(|&a, &b| (chi[a] - clo[a]).total_cmp(&(chi[b] - clo[b])))
        .expect("three axes");
    let mid = ids.len() / 2;
    let key = |i: &u32| {
        let (a, b) = boxes[*i as usize];
        a[axis] + b[axis]
    };
    ids.select_nth_unstable_by(mid, |x, y| key(x).total_cmp(&key(y)));
    let child = nodes.len();
    let empty = Node {
        lo,
        hi,
        start: 0,
        count: 0,
    };
    nodes.extend([empty, empty]);
    nodes[n].start = child as u32;
    let (left, right) = ids.split_at_mut(mid);
    build(nodes, child, left, offset, boxes);
    build(nodes, child + 1, right, offset + mid, boxes);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::num::SplitMix;
    use crate::render::{render_view, Attitude, ViewOptions};

    fn mesh(positions: Vec<[f64; 3]>, triangles: Vec<[u32; 3]>) -> Mesh {
        let colours = (0..positions.len())
            .map(|i| {
                [
                    (i * 7 % 256) as u8,
                    (i * 13 % 256) as u8,
                    (i * 29 % 256) as u8,
                ]
            })
            .collect();
        Mesh {
            positions,
            colours,
            triangles,
        }
    }

    /// A height field over `n × n` unit cells with corners at `(x0 + i, y0 + j)`, two triangles
    /// a cell (counter-clockwise from above), heights from `z`.
    fn grid(n: usize, x0: f64, y0: f64, z: impl Fn(usize, usize) -> f64) -> Mesh {
        let mut positions = Vec::new();
        for j in 0..=n {
            for i in 0..=n {
                positions.push([x0 + i as f64, y0 + j as f64, z(i, j)]);
            }
        }
        let v = |i: usize, j: usize| (j * (n + 1) + i) as u32;
        let mut triangles = Vec::new();
        for j in 0..n {
            for i in 0..n {
                triangles.push([v(i, j), v(i + 1, j), v(i + 1, j + 1)]);
                triangles.push([v(i, j), v(i + 1, j + 1), v(i, j + 1)]);
            }
        }
        mesh(positions, triangles)
    }

    /// The cube `[-1, 1]³`: two triangles a face, counter-clockwise from outside.
    fn cube() -> Mesh {
        let positions = (0..8)
            .map(|c| [0, 1, 2].map(|k| if c >> k & 1 == 1 { 1.0 } else { -1.0 }))
            .collect();
        let quads: [[u32; 4]; 6] = [
            [0, 2, 3, 1], // z = -1, seen from below
            [4, 5, 7, 6], // z = 1
            [0, 1, 5, 4], // y = -1
            [2, 6, 7, 3], // y = 1
            [0, 4, 6, 2], // x = -1
            [1, 3, 7, 5], // x = 1
        ];
        let triangles = quads
            .iter()
            .flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]])
            .collect();
        mesh(positions, triangles)
    }

    /// Hit or miss the same, ranges within `1e-9` relative.
    fn agree(a: Option<MeshHit>, b: Option<MeshHit>, what: &str) {
        match (a, b) {
            (None, None) => {}
            (Some(a), Some(b)) => assert!(
                (a.range - b.range).abs() <= 1e-9 * b.range,
                "{what}: {} vs {}",
                a.range,
                b.range
            ),
            _ => panic!("{what}: hierarchy {a:?}, every triangle {b:?}"),
        }
    }

    #[test]
    fn the_hierarchy_agrees_with_testing_every_triangle_on_random_soups() {
        let mut rng = SplitMix(7);
        for round in 0..20 {
            let n = 50 + 40 * round;
            let mut positions = Vec::new();
            let mut triangles = Vec::new();
            for _ in 0..n {
                let c = [0; 3].map(|_| 10.0 * rng.signed());
                let base = positions.len() as u32;
                for _ in 0..3 {
                    positions.push(std::array::from_fn(|k| c[k] + rng.signed()));
                }
                triangles.push([base, base + 1, base + 2]);
            }
            let scene = MeshScene::new(&mesh(positions, triangles));
            for r in 0..400 {
                let eye = [0; 3].map(|_| 14.0 * rng.signed());
                let dir = match r % 4 {
                    0 => [0; 3].map(|_| rng.signed()),
                    1 => {
                        let mut d = [0.0; 3];
                        d[r / 4 % 3] = if rng.signed() < 0.0 { -1.0 } else { 2.5 };
                        d
                    }
                    2 => [1.0, -1.0, 1.0].map(|s| s * rng.signed().signum()),
                    _ => {
                        // aimed at a random vertex of the soup
                        let p = scene.positions[r % scene.positions.len()];
                        std::array::from_fn(|k| p[k] + scene.origin[k] - eye[k])
                    }
                };
                let what = format!("round {round} ray {r}: {eye:?} {dir:?}");
                agree(
                    scene.intersect(eye, dir),
                    scene.intersect_all(eye, dir),
                    &what,
                );
            }
        }
    }

    #[test]
    fn the_hierarchy_agrees_through_the_vertices_and_edges_of_a_height_field() {
        let mut rng = SplitMix(11);
        let heights: Vec<f64> = (0..33 * 33).map(|_| 2.0 * rng.signed()).collect();
        let field = grid(32, 600_000.0, 5_200_000.0, |i, j| heights[j * 33 + i]);
        let scene = MeshScene::new(&field);
        let (mut hits, mut rays) = (0, 0);
        for i in 0..=32 {
            for j in 0..=32 {
                let (x, y) = (600_000.0 + i as f64, 5_200_000.0 + j as f64);
                // straight down on a vertex, along grid lines, along cell diagonals, and
                // diagonals dipping through vertices
                let dirs = [
                    [0.0, 0.0, -1.0],
                    [1.0, 0.0, 0.0],
                    [0.0, -1.0, 0.0],
                    [1.0, 1.0, 0.0],
                    [-1.0, 1.0, 0.0],
                    [1.0, 1.0, -0.25],
                    [-1.0, -1.0, -0.125],
                    [0.5, 0.0, -0.5],
                ];
                for (k, dir) in dirs.into_iter().enumerate() {
                    let z = match k {
                        1..=4 => 0.0, // through the surface sideways
                        _ => 3.0,
                    };
                    let eye = [x, y, z];
                    let a = scene.intersect(eye, dir);
                    agree(
                        a,
                        scene.intersect_all(eye, dir),
                        &format!("{i} {j} {dir:?}"),
                    );
                    rays += 1;
                    hits += usize::from(a.is_some());
                }
            }
        }
        // every ray straight down lands on the surface, edges and vertices included
        assert!(hits >= 33 * 33, "{hits} of {rays}");
        for i in 0..=32 {
            for j in 0..=32 {
                let eye = [600_000.0 + i as f64, 5_200_000.0 + j as f64, 3.0];
                let hit = scene.intersect(eye, [0.0, 0.0, -1.0]).expect("a vertex");
                assert!((hit.range - (3.0 - heights[j * 33 + i])).abs() < 1e-9);
            }
        }
    }

    #[test]
    fn a_triangle_is_hit_on_its_vertices_and_edges_and_missed_just_outside() {
        let tri = mesh(
            vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
            vec![[0, 1, 2]],
        );
        let scene = MeshScene::new(&tri);
        for (k, p) in tri.positions.iter().enumerate() {
            let hit = scene
                .intersect([p[0], p[1], 2.0], [0.0, 0.0, -1.0])
                .expect("vertex");
            assert_eq!(hit.range, 2.0);
            assert_eq!(hit.colour, tri.colours[k], "the vertex's own colour");
            // from below, slanted
            let eye = [p[0] + 0.5, p[1] - 0.25, -1.0];
            let d = [p[0] - eye[0], p[1] - eye[1], p[2] - eye[2]];
            assert!(scene.intersect(eye, d).is_some(), "vertex {k} from below");
        }
        for (x, y) in [(0.5, 0.0), (0.0, 0.5), (0.5, 0.5), (0.25, 0.75), (0.0, 0.0)] {
            let hit = scene.intersect([x, y, 1.5], [0.0, 0.0, -3.0]);
            assert_eq!(hit.map(|h| h.range), Some(1.5), "edge point {x} {y}");
        }
        for (x, y) in [
            (0.5, -1e-12),
            (-1e-12, 0.5),
            (0.5 + 1e-12, 0.5),
            (1.0 + 1e-12, 0.0),
        ] {
            assert_eq!(scene.intersect([x, y, 1.5], [0.0, 0.0, -1.0]), None);
        }
        // behind the eye
        assert_eq!(scene.intersect([0.2, 0.2, -1.0], [0.0, 0.0, -1.0]), None);
    }

    #[test]
    fn a_ray_in_or_parallel_to_a_triangles_plane_misses() {
        let tri = mesh(
            vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]],
            vec![[0, 1, 2]],
        );
        let scene = MeshScene::new(&tri);
        for z in [0.0, 1e-9, 1.0] {
            for d in [[1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, -1.0, 0.0]] {
                let eye = [0.25 - d[0], 0.25 - d[1], z];
                assert_eq!(scene.intersect(eye, d), None, "{z} {d:?}");
                assert_eq!(scene.intersect_all(eye, d), None);
            }
        }
    }

    #[test]
    fn a_closed_cube_does_not_leak_through_its_edges_or_corners() {
        let scene = MeshScene::new(&cube());
        let steps: Vec<f64> = (0..=16).map(|k| -1.0 + k as f64 / 8.0).collect();
        // every point of a grid on the surface (its edges, corners and face diagonals among them)
        let mut targets = Vec::new();
        for &a in &steps {
            for &b in &steps {
                for s in [-1.0, 1.0] {
                    targets.extend([[s, a, b], [a, s, b], [a, b, s]]);
                }
            }
        }
        let eyes = [
            [0.0, 0.0, 0.0],
            [0.25, -0.5, 0.125],
            [0.9, 0.9, -0.9],
            [3.0, 3.0, 3.0],
            [-4.0, 0.5, 2.0],
            [0.0, 0.0, 5.0],
        ];
        for eye in eyes {
            let inside = eye.iter().all(|c: &f64| c.abs() < 1.0);
            for t in &targets {
                let d: [f64; 3] = std::array::from_fn(|k| t[k] - eye[k]);
                let hit = scene.intersect(eye, d);
                agree(hit, scene.intersect_all(eye, d), "cube");
                // from outside, a ray that only grazes an edge or a corner may miss
                let beyond = t.iter().zip(&d).all(|(c, dc)| (c + 1e-6 * dc).abs() < 1.0);
                assert!(
                    hit.is_some() || !(inside || beyond),
                    "{eye:?} to {t:?} fell through"
                );
                if inside {
                    let dist = d.iter().map(|c| c * c).sum::<f64>().sqrt();
                    assert!((hit.unwrap().range - dist).abs() < 1e-12 * dist.max(1.0));
                }
            }
        }
        // from the centre, a sweep of directions: every one leaves through the surface
        for yaw in (0..360).step_by(5) {
            for pitch in (-90..=90).step_by(5) {
                let (y, p) = ((yaw as f64).to_radians(), (pitch as f64).to_radians());
                let d = [y.sin() * p.cos(), y.cos() * p.cos(), p.sin()];
                assert!(scene.intersect([0.0; 3], d).is_some(), "{yaw} {pitch}");
            }
        }
    }

    #[test]
    fn utm_sized_coordinates_keep_their_precision() {
        let (x0, y0) = (500_000.0, 5_300_000.0);
        let plane = grid(20, x0, y0, |_, _| 380.0);
        let scene = MeshScene::new(&plane);
        let camera = Viewpoint {
            eye: [x0 + 10.3, y0 + 9.7, 381.5],
            attitude: Attitude {
                roll: 3.0,
                pitch: -60.0,
                yaw: 17.0,
            },
            hfov: 40.0,
            width: 21,
            height: 15,
        };
        let basis = camera.basis();
        for j in 0..camera.height {
            for i in 0..camera.width {
                let d = basis.direction(i, j);
                let hit = scene.intersect(camera.eye, d).expect("the plane");
                let exact = 1.5 / -d[2];
                assert!((hit.range - exact).abs() < 1e-9 * exact, "{i} {j}");
            }
        }
    }

    #[test]
    fn the_mesh_render_casts_the_tile_renderers_rays() {
        let grey = [120u8, 120, 120, 255];
        let (_dir, reader) =
            super::super::tests::tiles(0.0, 256.0, 256, 256, 64, 4, |_, _| (10.0, grey));
        let square = Mesh {
            positions: vec![
                [0.0, 0.0, 10.0],
                [256.0, 0.0, 10.0],
                [256.0, 256.0, 10.0],
                [0.0, 256.0, 10.0],
            ],
            colours: vec![[120, 120, 120]; 4],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
        };
        let camera = Viewpoint {
            eye: [128.25, 60.5, 30.0],
            attitude: Attitude {
                roll: 0.0,
                pitch: -10.0,
                yaw: 20.0,
            },
            hfov: 60.0,
            width: 64,
            height: 48,
        };
        let opts = ViewOptions {
            lod: false,
            ..ViewOptions::default()
        };
        let tiles = render_view(&reader, &camera, &opts).unwrap();
        let mesh = render_mesh(&MeshScene::new(&square), &camera).unwrap();
        assert!(mesh.hits > 0 && mesh.hits < 64 * 48, "ground and sky");
        assert_eq!(mesh.hits, tiles.stats.hits);
        for (k, (a, b)) in mesh.range.iter().zip(&tiles.range).enumerate() {
            assert_eq!(a.is_finite(), b.is_finite(), "pixel {k}");
            if a.is_finite() {
                assert!((a - b).abs() <= 1e-6 * b, "pixel {k}: {a} vs {b}");
            }
        }
        assert_eq!(mesh.rgb, tiles.rgb, "the same grey and the same sky");
    }

    /// A draped square seen from straight above: a ray at a texel's centre gets that texel, one
    /// half-way between two texels their mean, one past the last texel's centre the edge texel
    /// (clamped); an undraped part beside it keeps its vertex colours.
    #[test]
    fn a_drape_is_sampled_as_a_viewers_linear_sampler_does() {
        use crate::mesh::Lighting;
        // 2 × 1 texels over a 2 m × 1 m square at UTM coordinates; uv (0,0) at the north-west.
        let (x0, y0, z) = (500_000.0, 5_300_000.0, 300.0);
        let square = Mesh {
            positions: vec![
                [x0, y0, z],
                [x0 + 2.0, y0, z],
                [x0 + 2.0, y0 + 1.0, z],
                [x0, y0 + 1.0, z],
            ],
            colours: vec![[0; 3]; 4],
            triangles: vec![[0, 1, 2], [0, 2, 3]],
        };
        let drape = Drape {
            width: 2,
            height: 1,
            texels: vec![[0, 100, 200], [200, 50, 0]],
            uv: vec![[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]],
        };
        let mut beside = square.clone();
        beside.positions.iter_mut().for_each(|p| p[0] += 10.0);
        beside.colours = vec![[7, 8, 9]; 4];
        let scene = MeshScene::of_parts(&[
            Part {
                mesh: square,
                lighting: Lighting::Unlit,
                drape: Some(drape),
            },
            Part {
                mesh: beside,
                lighting: Lighting::Lit,
                drape: None,
            },
        ]);
        let down = [0.0, 0.0, -1.0];
        let at = |x: f64| {
            scene
                .intersect([x0 + x, y0 + 0.5, z + 10.0], down)
                .unwrap()
                .colour
        };
        assert_eq!(at(0.5), [0, 100, 200]);
        assert_eq!(at(1.5), [200, 50, 0]);
        assert_eq!(at(1.0), [100, 75, 100]);
        assert_eq!(at(0.1), [0, 100, 200], "clamped at the edge");
        assert_eq!(at(10.5), [7, 8, 9]);
    }

    #[test]
    fn an_empty_mesh_shows_only_sky() {
        let scene = MeshScene::new(&Mesh::default());
        assert!(scene.is_empty());
        assert_eq!(scene.intersect([0.0; 3], [0.0, 0.0, -1.0]), None);
    }
}
