//! Analytic test solids (sphere, cylinder, cone, L-shaped block) with exact point and ray tests:
//! the ground truth the carver is measured against. [`render`] draws a solid's silhouette with
//! the same camera models the carver uses (one ray per pixel centre); [`exact_hull`] is the
//! visual hull with no pixels at all (a voxel is in it when every camera's ray through its
//! centre meets the solid), so carving error splits into hull error and pixel error.
//!
//! # Invariant
//! Solids are closed sets in world metres with z up; cylinder and cone axes are vertical.

use crate::voxel::camera::{Camera, Ray};
use crate::voxel::carve::{CarveOptions, Unseen};
use crate::voxel::grid::VoxelGrid;
use crate::voxel::occupancy::Occupancy;
use crate::voxel::silhouette::Silhouette;
use crate::voxel::vec3::{dot, sub};
use rayon::prelude::*;

/// A closed solid in world metres.
#[derive(Debug, Clone, PartialEq)]
pub enum Solid {
    /// Ball of `radius` metres around `centre`.
    Sphere {
        /// Centre, metres.
        centre: [f64; 3],
        /// Radius, metres.
        radius: f64,
    },
    /// Vertical cylinder standing on `base` (centre of its bottom disc).
    Cylinder {
        /// Centre of the bottom disc, metres.
        base: [f64; 3],
        /// Radius, metres.
        radius: f64,
        /// Height, metres.
        height: f64,
    },
    /// Vertical cone standing on `base` (centre of its bottom disc), apex `height` above.
    Cone {
        /// Centre of the bottom disc, metres.
        base: [f64; 3],
        /// Radius of the bottom disc, metres.
        radius: f64,
        /// Height of the apex above the base, metres.
        height: f64,
    },
    /// Union of axis-aligned boxes `(min, max)`, metres (e.g. an L-shaped block).
    Boxes(Vec<([f64; 3], [f64; 3])>),
}

impl Solid {
    /// Is world point `p` (metres) in the solid?
    pub fn contains(&self, p: [f64; 3]) -> bool {
        match self {
            Solid::Sphere { centre, radius } => {
                let w = sub(p, *centre);
                dot(w, w) <= radius * radius
            }
            Solid::Cylinder {
                base,
                radius,
                height,
            } => {
                let w = sub(p, *base);
                (0.0..=*height).contains(&w[2]) && w[0] * w[0] + w[1] * w[1] <= radius * radius
            }
            Solid::Cone {
                base,
                radius,
                height,
            } => {
                let w = sub(p, *base);
                let r = radius * (height - w[2]) / height;
                (0.0..=*height).contains(&w[2]) && w[0] * w[0] + w[1] * w[1] <= r * r
            }
            Solid::Boxes(boxes) => boxes
                .iter()
                .any(|(lo, hi)| (0..3).all(|a| lo[a] <= p[a] && p[a] <= hi[a])),
        }
    }

    /// Does the ray meet the solid anywhere on `t_min..=t_max`?
    pub fn hit(&self, ray: &Ray) -> bool {
        let (o, d) = (ray.origin, ray.dir);
        let span = (ray.t_min, ray.t_max);
        match self {
            Solid::Sphere { centre, radius } => {
                let w = sub(o, *centre);
                somewhere_nonneg(
                    -dot(d, d),
                    -2.0 * dot(w, d),
                    radius * radius - dot(w, w),
                    span,
                )
            }
            Solid::Cylinder {
                base,
                radius,
                height,
            } => {
                let w = sub(o, *base);
                let span = slab(w[2], d[2], 0.0, *height, span);
                let (a, b, c) = radial(w, d);
                somewhere_nonneg(-a, -b, radius * radius - c, span)
            }
            Solid::Cone {
                base,
                radius,
                height,
            } => {
                let w = sub(o, *base);
                let span = slab(w[2], d[2], 0.0, *height, span);
                // k²(h − z(t))² − radial²(t) ≥ 0 on the lower nappe (z ≤ h, from the slab).
                let k2 = (radius / height).powi(2);
                let g = height - w[2];
                let (a, b, c) = radial(w, d);
                somewhere_nonneg(
                    k2 * d[2] * d[2] - a,
                    -2.0 * k2 * g * d[2] - b,
                    k2 * g * g - c,
                    span,
                )
            }
            Solid::Boxes(boxes) => boxes.iter().any(|(lo, hi)| {
                let mut s = span;
                for a in 0..3 {
                    s = slab(o[a], d[a], lo[a], hi[a], s);
                }
                s.0 <= s.1
            }),
        }
    }
}

/// Coefficients of `x(t)² + y(t)²` for the horizontal part of `w + t·d`.
fn radial(w: [f64; 3], d: [f64; 3]) -> (f64, f64, f64) {
    (
        d[0] * d[0] + d[1] * d[1],
        2.0 * (w[0] * d[0] + w[1] * d[1]),
        w[0] * w[0] + w[1] * w[1],
    )
}

/// Narrow `span` to the `t` where `lo ≤ w + t·d ≤ hi`.
fn slab(w: f64, d: f64, lo: f64, hi: f64, span: (f64, f64)) -> (f64, f64) {
    if d == 0.0 {
        return if (lo..=hi).contains(&w) {
            span
        } else {
            (1.0, 0.0)
        };
    }
    let (t0, t1) = ((lo - w) / d, (hi - w) / d);
    (span.0.max(t0.min(t1)), span.1.min(t0.max(t1)))
}

/// Is `a t² + b t + c ≥ 0` for some `t` in the closed (possibly unbounded) `span`?
fn somewhere_nonneg(a: f64, b: f64, c: f64, (t0, t1): (f64, f64)) -> bool {
    if t0 > t1 {
        return false;
    }
    let f = |t: f64| a * t * t + b * t + c;
    if (t0.is_finite() && f(t0) >= 0.0) || (t1.is_finite() && f(t1) >= 0.0) {
        return true;
    }
    if a > 0.0 {
        !(t0.is_finite() && t1.is_finite())
    } else if a < 0.0 {
        let tv = -b / (2.0 * a);
        (t0..=t1).contains(&tv) && f(tv) >= 0.0
    } else if b != 0.0 {
        (b > 0.0 && t1.is_infinite()) || (b < 0.0 && t0.is_infinite())
    } else {
        c >= 0.0
    }
}

/// The silhouette of `solid` in a `width × height` image of `camera`: pixel `(col, row)` is set
/// when the ray through its centre meets the solid.
pub fn render(solid: &Solid, camera: &Camera, width: u32, height: u32) -> Silhouette {
    let inside: Vec<bool> = (0..width as usize * height as usize)
        .into_par_iter()
        .map(|i| {
            let (c, r) = (i % width as usize, i / width as usize);
            solid.hit(&camera.ray(c as f64 + 0.5, r as f64 + 0.5))
        })
        .collect();
    Silhouette::new(width, height, inside)
}

/// Voxels whose centre is in the solid.
pub fn voxelize(solid: &Solid, grid: &VoxelGrid) -> Occupancy {
    Occupancy::from_fn(grid, |p| solid.contains(p))
}

/// The exact (pixel-free) visual hull on `grid`: a voxel is kept when, for every camera (with
/// its image size `(camera, width, height)`), the ray through its centre meets the solid; voxels
/// behind a camera or off its image follow `opts` exactly as in carving.
pub fn exact_hull(
    solid: &Solid,
    cameras: &[(Camera, u32, u32)],
    grid: &VoxelGrid,
    opts: &CarveOptions,
) -> Occupancy {
    Occupancy::from_fn(grid, |p| {
        cameras.iter().all(|(cam, w, h)| match cam.project(p) {
            None => opts.behind == Unseen::Keep,
            Some([u, v]) if u < 0.0 || v < 0.0 || u >= *w as f64 || v >= *h as f64 => {
                opts.outside == Unseen::Keep
            }
            Some([u, v]) => solid.hit(&cam.ray(u, v)),
        })
    })
}

/// The four benchmark solids, each inside the box `[-1, 1]³` metres: sphere, cylinder, cone and a
/// concave L-shaped block (an L in plan, 1 m tall).
pub fn benchmark_solids() -> Vec<Solid> {
    vec![
        Solid::Sphere {
            centre: [0.0; 3],
            radius: 0.8,
        },
        Solid::Cylinder {
            base: [0.0, 0.0, -0.8],
            radius: 0.5,
            height: 1.6,
        },
        Solid::Cone {
            base: [0.0, 0.0, -0.8],
            radius: 0.7,
            height: 1.6,
        },
        Solid::Boxes(vec![
            ([-0.8, -0.8, -0.5], [0.8, -0.1, 0.5]),
            ([-0.8, -0.1, -0.5], [-0.1, 0.8, 0.5]),
        ]),
    ]
}

/// Short names of [`benchmark_solids`], in order.
pub const BENCHMARK_NAMES: [&str; 4] = ["sphere", "cylinder", "cone", "L-block"];

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn a_ray_hits_iff_a_sampled_point_on_it_is_inside(which in 0usize..4, o in prop::array::uniform3(-2.0f64..2.0), d in prop::array::uniform3(-1.0f64..1.0)) {
            let s = &benchmark_solids()[which];
            let ray = Ray { origin: o, dir: d, t_min: 0.0, t_max: 10.0 };
            // Dense sampling finds a hit only if the analytic test does (samples are exact points).
            let sampled = (0..=20_000).any(|i| s.contains(crate::voxel::vec3::add_scaled(o, i as f64 * 10.0 / 20_000.0, d)));
            if sampled {
                prop_assert!(s.hit(&ray));
            }
        }
    }

    #[test]
    fn hits_and_misses_on_named_rays() {
        let [sphere, cyl, cone, l] = <[Solid; 4]>::try_from(benchmark_solids()).unwrap();
        let down = |x: f64, y: f64| Ray {
            origin: [x, y, 5.0],
            dir: [0.0, 0.0, -1.0],
            t_min: 0.0,
            t_max: f64::INFINITY,
        };
        assert!(sphere.hit(&down(0.79, 0.0)) && !sphere.hit(&down(0.81, 0.0)));
        assert!(cyl.hit(&down(0.49, 0.0)) && !cyl.hit(&down(0.51, 0.0)));
        assert!(cone.hit(&down(0.69, 0.0)) && !cone.hit(&down(0.71, 0.0)));
        // The L's notch (x > -0.1, y > -0.1) is empty from above.
        assert!(!l.hit(&down(0.4, 0.4)) && l.hit(&down(-0.4, 0.4)) && l.hit(&down(0.4, -0.4)));
        // Horizontal ray above the cone's apex misses; one through its middle hits.
        let side = |z: f64| Ray {
            origin: [-5.0, 0.0, z],
            dir: [1.0, 0.0, 0.0],
            t_min: f64::NEG_INFINITY,
            t_max: f64::INFINITY,
        };
        assert!(!cone.hit(&side(0.81)) && cone.hit(&side(0.0)));
        // A ray pointing away does not hit behind its origin.
        let away = Ray {
            origin: [0.0, 0.0, 5.0],
            dir: [0.0, 0.0, 1.0],
            t_min: 0.0,
            t_max: f64::INFINITY,
        };
        assert!(!sphere.hit(&away) && !cyl.hit(&away) && !cone.hit(&away));
    }
}
