//! Carving the visual hull: keep the voxels whose centre projects inside every silhouette.
//!
//! # The rule (what both carvers compute, bit for bit)
//! A voxel is kept when, for every view, its **centre** `c` passes:
//! * `c` behind a pinhole camera (depth ≤ [`super::camera::NEAR`]): the `behind` option decides;
//! * `c` projects outside the image: the `outside` option decides;
//! * otherwise: kept iff pixel `(⌊u⌋, ⌊v⌋)` is in the silhouette.
//!
//! Both options default to [`Unseen::Keep`]: a view removes only what it sees, so the hull
//! always contains the object even when a camera sits inside the bounds or the object leaves
//! the frame.
//!
//! [`carve`] is hierarchical: a box of voxels is classified per view from the pixel rectangle
//! that bounds the projections of its corner voxel centres, padded by a rounding margin, using
//! the silhouette's summed-area table: all silhouette → the view keeps the whole box, no
//! silhouette → the box is carved, else the box is split in eight (empty and solid space
//! cost one test). Small boxes and single voxels use the exact rule above. [`carve_dense`] applies
//! the rule to every voxel and is the reference the hierarchical carver must equal.

use super::camera::{Camera, NEAR};
use super::grid::VoxelGrid;
use super::occupancy::{AtomicOccupancy, Occupancy};
use super::silhouette::Silhouette;
use crate::error::{Error, Result};
use rayon::prelude::*;

/// One calibrated view: a camera and the object's silhouette in its image.
#[derive(Debug, Clone)]
pub struct View {
    /// How world points map to this view's pixels.
    pub camera: Camera,
    /// The object's pixels.
    pub silhouette: Silhouette,
}

crate::choice! {
    /// What a view does with a voxel it cannot see (behind it or outside its image).
    #[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
    #[serde(rename_all = "lowercase")]
    pub enum Unseen {
        /// The view gives no evidence: the voxel stays (default).
        Keep = "keep",
        /// The view removes the voxel.
        Carve = "carve",
    }
}

/// The geometry rules of carving (see the module docs).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CarveOptions {
    /// Voxels whose centre projects outside a view's image.
    pub outside: Unseen,
    /// Voxels whose centre is behind a pinhole camera.
    pub behind: Unseen,
}

impl Default for CarveOptions {
    fn default() -> Self {
        CarveOptions {
            outside: Unseen::Keep,
            behind: Unseen::Keep,
        }
    }
}

/// Boxes of at most this many voxels (4³) are tested voxel by voxel: classifying a box costs 8
/// corner projections per view, as much as testing 8 voxels. 64 beat 8 and 512 at 256³ (docs/sculpt.md).
const LEAF_VOXELS: u64 = 64;
/// Boxes of at least this many voxels split their children across threads.
const PARALLEL_VOXELS: u64 = 16 * 16 * 16;

/// The exact rule for one voxel centre `c` (metres) against one view.
#[inline]
pub fn keeps(view: &View, c: [f64; 3], opts: &CarveOptions) -> bool {
    match view.camera.project(c) {
        None => opts.behind == Unseen::Keep,
        Some([u, v]) => {
            let s = &view.silhouette;
            if u >= 0.0 && v >= 0.0 && u < s.width() as f64 && v < s.height() as f64 {
                s.contains(u as u32, v as u32)
            } else {
                opts.outside == Unseen::Keep
            }
        }
    }
}

fn check(views: &[View]) -> Result<()> {
    if views.is_empty() {
        return Err(Error::msg("no views to carve from").fix("give at least one view"));
    }
    if let Some(i) = views.iter().position(|v| v.silhouette.area() == 0) {
        return Err(Error::msg(format!(
            "view {i}: the silhouette is empty, so it would carve away everything"
        ))
        .fix("check the mask or the background key and tolerance"));
    }
    Ok(())
}

/// The reference carver: the exact rule for every voxel of `grid`.
pub fn carve_dense(grid: &VoxelGrid, views: &[View], opts: &CarveOptions) -> Result<Occupancy> {
    check(views)?;
    Ok(Occupancy::from_fn(grid, |c| {
        views.iter().all(|v| keeps(v, c, opts))
    }))
}

/// The hierarchical carver; its result equals [`carve_dense`]'s exactly.
pub fn carve(grid: &VoxelGrid, views: &[View], opts: &CarveOptions) -> Result<Occupancy> {
    check(views)?;
    let out = AtomicOccupancy::new(grid);
    let all: Vec<usize> = (0..views.len()).collect();
    let ctx = Carver {
        grid,
        views,
        opts,
        out: &out,
    };
    ctx.carve_box([0; 3], grid.dims, &all);
    Ok(out.finish())
}

#[derive(Clone, Copy, PartialEq)]
enum Verdict {
    Keep,
    Carve,
    Partial,
}

struct Carver<'a> {
    grid: &'a VoxelGrid,
    views: &'a [View],
    opts: &'a CarveOptions,
    out: &'a AtomicOccupancy,
}

impl Carver<'_> {
    /// Carve voxels `lo..hi` (per axis, exclusive) against the views in `active`.
    fn carve_box(&self, lo: [u32; 3], hi: [u32; 3], active: &[usize]) {
        let mut partial = Vec::with_capacity(active.len());
        for &vi in active {
            match self.classify(&self.views[vi], lo, hi) {
                Verdict::Carve => return,
                Verdict::Keep => {}
                Verdict::Partial => partial.push(vi),
            }
        }
        if partial.is_empty() {
            self.fill(lo, hi);
            return;
        }
        let volume: u64 = (0..3).map(|a| (hi[a] - lo[a]) as u64).product();
        if volume <= LEAF_VOXELS {
            self.per_voxel(lo, hi, &partial);
            return;
        }
        let mid = [0, 1, 2].map(|a| lo[a] + (hi[a] - lo[a]).div_ceil(2));
        let mut children = Vec::with_capacity(8);
        for oct in 0..8 {
            let mut clo = lo;
            let mut chi = hi;
            for a in 0..3 {
                if oct >> a & 1 == 0 {
                    chi[a] = mid[a];
                } else {
                    clo[a] = mid[a];
                }
            }
            if (0..3).all(|a| clo[a] < chi[a]) {
                children.push((clo, chi));
            }
        }
        if volume >= PARALLEL_VOXELS {
            children
                .par_iter()
                .for_each(|&(l, h)| self.carve_box(l, h, &partial));
        } else {
            for (l, h) in children {
                self.carve_box(l, h, &partial);
            }
        }
    }

    fn fill(&self, lo: [u32; 3], hi: [u32; 3]) {
        for y in lo[1]..hi[1] {
            for x in lo[0]..hi[0] {
                self.out
                    .set_run(self.grid.index(x, y, lo[2]), (hi[2] - lo[2]) as usize);
            }
        }
    }

    fn per_voxel(&self, lo: [u32; 3], hi: [u32; 3], active: &[usize]) {
        for y in lo[1]..hi[1] {
            for x in lo[0]..hi[0] {
                for z in lo[2]..hi[2] {
                    let c = self.grid.centre(x, y, z);
                    if active
                        .iter()
                        .all(|&vi| keeps(&self.views[vi], c, self.opts))
                    {
                        self.out.set(self.grid.index(x, y, z));
                    }
                }
            }
        }
    }

    /// What one view says about every voxel centre in `lo..hi`: conservative, so `Keep` and
    /// `Carve` hold for each voxel under the exact rule.
    fn classify(&self, view: &View, lo: [u32; 3], hi: [u32; 3]) -> Verdict {
        // The voxel centres of the box span the box between its first and last centres; depth is
        // affine and perspective maps segments to segments, so the corners bound everything.
        let (a, b) = (
            self.grid.centre(lo[0], lo[1], lo[2]),
            self.grid.centre(hi[0] - 1, hi[1] - 1, hi[2] - 1),
        );
        match project_box(&view.camera, a, b) {
            Projected::Behind if self.opts.behind == Unseen::Keep => Verdict::Keep,
            Projected::Behind => Verdict::Carve,
            Projected::AcrossNear => Verdict::Partial,
            Projected::Within(bounds) => self.verdict_within(&view.silhouette, bounds),
        }
    }

    /// What a silhouette says about points that project inside `bounds` (`[umin, umax, vmin,
    /// vmax]`, pixels): every covered pixel in the silhouette keeps them, none carves them,
    /// unless part of the bounds leaves the image and the options treat outside otherwise.
    fn verdict_within(&self, s: &Silhouette, [umin, umax, vmin, vmax]: [f64; 4]) -> Verdict {
        let pad = |x: f64| 1e-6 + 1e-9 * x.abs();
        let (w, h) = (s.width() as f64, s.height() as f64);
        // Pixel columns/rows any centre can fall in, clamped to one past the image on each side.
        let c0 = (umin - pad(umin)).floor().clamp(-1.0, w);
        let c1 = (umax + pad(umax)).floor().clamp(-1.0, w);
        let r0 = (vmin - pad(vmin)).floor().clamp(-1.0, h);
        let r1 = (vmax + pad(vmax)).floor().clamp(-1.0, h);
        let leaves_image = c0 < 0.0 || r0 < 0.0 || c1 >= w || r1 >= h;
        let (ic0, ic1, ir0, ir1) = (
            c0.max(0.0) as u32,
            (c1 + 1.0).min(w) as u32,
            r0.max(0.0) as u32,
            (r1 + 1.0).min(h) as u32,
        );
        let area = if ic0 < ic1 && ir0 < ir1 {
            (ic1 - ic0) as u64 * (ir1 - ir0) as u64
        } else {
            0
        };
        let inside = if area > 0 {
            s.count(ic0, ir0, ic1, ir1)
        } else {
            0
        };
        let outside_keeps = self.opts.outside == Unseen::Keep;
        if inside == area && (!leaves_image || outside_keeps) {
            Verdict::Keep
        } else if inside == 0 && (!leaves_image || !outside_keeps) {
            Verdict::Carve
        } else {
            Verdict::Partial
        }
    }
}

/// Where the box between corners `a` and `b` (world metres) lands in a camera's image.
enum Projected {
    /// Wholly behind a pinhole camera's near plane.
    Behind,
    /// Partly behind the near plane: no bound on the image holds.
    AcrossNear,
    /// In front (or seen by a camera without a near plane): the projected corners' bounds,
    /// `[umin, umax, vmin, vmax]` in pixels (infinite when no corner projects).
    Within([f64; 4]),
}

/// Project the eight corners of the box between `a` and `b` with `camera`.
fn project_box(camera: &Camera, a: [f64; 3], b: [f64; 3]) -> Projected {
    let corners = (0..8).map(|k| {
        [
            if k & 1 == 0 { a[0] } else { b[0] },
            if k & 2 == 0 { a[1] } else { b[1] },
            if k & 4 == 0 { a[2] } else { b[2] },
        ]
    });
    // Rounding margin on depths (metres): far above f64 noise at UTM magnitudes.
    const DEPTH_EPS: f64 = 1e-7;
    let mut depth = (f64::INFINITY, f64::NEG_INFINITY);
    let (mut umin, mut umax, mut vmin, mut vmax) = (
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
    );
    let pinhole = matches!(camera, Camera::Pinhole(_));
    for c in corners {
        if pinhole {
            let d = camera.depth(c);
            depth = (depth.0.min(d), depth.1.max(d));
            if d <= NEAR + DEPTH_EPS {
                continue;
            }
        }
        if let Some([u, v]) = camera.project(c) {
            umin = umin.min(u);
            umax = umax.max(u);
            vmin = vmin.min(v);
            vmax = vmax.max(v);
        }
    }
    if pinhole && depth.1 <= NEAR - DEPTH_EPS {
        Projected::Behind
    } else if pinhole && depth.0 <= NEAR + DEPTH_EPS {
        Projected::AcrossNear
    } else {
        Projected::Within([umin, umax, vmin, vmax])
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::testing::solids::{self, Solid};
    use proptest::prelude::*;

    fn ring(n: usize, dist: f64, elev_deg: f64, size: u32) -> Vec<Camera> {
        (0..n)
            .map(|i| {
                let az = (i as f64 / n as f64) * std::f64::consts::TAU;
                let e = elev_deg.to_radians();
                let pos = [
                    dist * e.cos() * az.cos(),
                    dist * e.cos() * az.sin(),
                    dist * e.sin(),
                ];
                let f = size as f64 * 1.2;
                Camera::look_at(
                    f,
                    f,
                    size as f64 / 2.0,
                    size as f64 / 2.0,
                    pos,
                    [0.0; 3],
                    None,
                )
                .unwrap()
            })
            .collect()
    }

    fn views_of(solid: &Solid, cams: Vec<Camera>, size: u32) -> Vec<View> {
        cams.into_iter()
            .map(|camera| View {
                silhouette: solids::render(solid, &camera, size, size),
                camera,
            })
            .collect()
    }

    fn unit_grid(n: u32) -> VoxelGrid {
        VoxelGrid::covering([-1.0; 3], [1.0; 3], 2.0 / n as f64).unwrap()
    }

    #[test]
    fn hierarchical_equals_dense_and_contains_the_solid() {
        for solid in solids::benchmark_solids() {
            let views = views_of(&solid, ring(8, 4.0, 25.0, 96), 96);
            let g = unit_grid(40);
            let h = carve(&g, &views, &CarveOptions::default()).unwrap();
            let d = carve_dense(&g, &views, &CarveOptions::default()).unwrap();
            assert_eq!(h, d, "{solid:?}");
            let truth = solids::voxelize(&solid, &g);
            assert!(truth.iou(&h) > 0.5, "{solid:?}: iou {}", truth.iou(&h));
        }
    }

    #[test]
    fn utm_sized_coordinates_carve_the_same_as_near_the_origin() {
        // The same scene 500 km east, 5000 km north: the carvers still agree and still find the sphere.
        let c = [500_123.25, 5_000_456.75, 312.5];
        let solid = Solid::Sphere {
            centre: c,
            radius: 0.8,
        };
        let cams: Vec<Camera> = ring(8, 4.0, 25.0, 96)
            .into_iter()
            .map(|cam| {
                let Camera::Pinhole(p) = cam else {
                    unreachable!()
                };
                let pos = [0, 1, 2].map(|a| p.centre[a] + c[a]);
                Camera::look_at(p.fx, p.fy, p.cx, p.cy, pos, c, None).unwrap()
            })
            .collect();
        let views = views_of(&solid, cams, 96);
        let g = VoxelGrid::covering(
            [c[0] - 1.0, c[1] - 1.0, c[2] - 1.0],
            [c[0] + 1.0, c[1] + 1.0, c[2] + 1.0],
            2.0 / 40.0,
        )
        .unwrap();
        let h = carve(&g, &views, &CarveOptions::default()).unwrap();
        assert_eq!(
            h,
            carve_dense(&g, &views, &CarveOptions::default()).unwrap()
        );
        let near_origin = carve(
            &unit_grid(40),
            &views_of(&solids::benchmark_solids()[0], ring(8, 4.0, 25.0, 96), 96),
            &CarveOptions::default(),
        )
        .unwrap();
        assert!(h.iou(&near_origin) > 0.99, "iou {}", h.iou(&near_origin));
    }

    #[test]
    fn empty_silhouette_is_an_error() {
        let cam = Camera::orthographic([0.0, 0.0, -1.0], None, 10.0, [0.0; 3], 8.0, 8.0).unwrap();
        let views = vec![View {
            camera: cam,
            silhouette: Silhouette::new(16, 16, vec![false; 256]),
        }];
        let e = carve(&unit_grid(8), &views, &CarveOptions::default()).unwrap_err();
        assert!(
            e.to_string().contains("view 0: the silhouette is empty"),
            "{e}"
        );
        assert!(carve(&unit_grid(8), &[], &CarveOptions::default()).is_err());
    }

    #[test]
    fn camera_inside_the_bounds_behind_rule() {
        // A camera at the centre of the box looking east: half the box is behind it.
        let cam = Camera::look_at(20.0, 20.0, 16.0, 16.0, [0.0; 3], [1.0, 0.0, 0.0], None).unwrap();
        let sil = Silhouette::new(32, 32, (0..1024).map(|i| i % 32 < 16).collect());
        let views = vec![View {
            camera: cam,
            silhouette: sil,
        }];
        let g = unit_grid(16);
        for behind in [Unseen::Keep, Unseen::Carve] {
            let opts = CarveOptions {
                behind,
                outside: Unseen::Keep,
            };
            let h = carve(&g, &views, &opts).unwrap();
            assert_eq!(h, carve_dense(&g, &views, &opts).unwrap());
            let west_kept = h.get(2, 8, 8);
            assert_eq!(west_kept, behind == Unseen::Keep);
        }
    }

    #[test]
    fn outside_rule_decides_voxels_off_the_image() {
        // A tiny top view that sees only the middle of the box, silhouette everywhere.
        let cam = Camera::orthographic([0.0, 0.0, -1.0], None, 4.0, [0.0; 3], 2.0, 2.0).unwrap();
        let views = vec![View {
            camera: cam,
            silhouette: Silhouette::new(4, 4, vec![true; 16]),
        }];
        let g = unit_grid(16);
        let keep = carve(&g, &views, &CarveOptions::default()).unwrap();
        assert_eq!(keep.count(), g.len());
        let opts = CarveOptions {
            outside: Unseen::Carve,
            behind: Unseen::Keep,
        };
        let cut = carve(&g, &views, &opts).unwrap();
        assert_eq!(cut, carve_dense(&g, &views, &opts).unwrap());
        assert_eq!(
            cut.count(),
            8 * 8 * 16,
            "only the 1 m × 1 m the image covers survives"
        );
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(24))]
        #[test]
        fn hierarchical_equals_dense_for_random_views(
            which in 0usize..4, n in 5u32..28, size in 16u32..64, nviews in 1usize..6,
            dist in 0.3f64..6.0, elev in -80.0f64..89.0, ortho in any::<bool>(),
            outside in any::<bool>(), behind in any::<bool>(),
        ) {
            let solid = solids::benchmark_solids()[which].clone();
            let cams: Vec<Camera> = if ortho {
                (0..nviews).map(|i| {
                    let a = i as f64 * 1.1 + elev.to_radians();
                    Camera::orthographic([a.cos(), a.sin(), (elev / 90.0) - 0.2], None, size as f64 / 2.5, [0.1, 0.0, 0.0], size as f64 / 2.0, size as f64 / 2.0).unwrap()
                }).collect()
            } else {
                ring(nviews, dist, elev, size)
            };
            let views = views_of(&solid, cams, size);
            prop_assume!(views.iter().all(|v| v.silhouette.area() > 0));
            let opts = CarveOptions {
                outside: if outside { Unseen::Keep } else { Unseen::Carve },
                behind: if behind { Unseen::Keep } else { Unseen::Carve },
            };
            let g = unit_grid(n);
            prop_assert_eq!(carve(&g, &views, &opts).unwrap(), carve_dense(&g, &views, &opts).unwrap());
        }
    }
}
