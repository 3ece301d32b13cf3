//! A ray in the database's local cell space, and its exact integer-boundary crossings.
//!
//! Local frame: `u` = level-0 column coordinate (east for north-up grids), `v` = level-0 row
//! coordinate, both in cells from the grid's corner origin; `z` in metres. The ray parameter `τ`
//! runs along the camera's *unnormalised* direction through the pixel (the image plane at unit
//! distance ahead of the eye): range in metres is `τ · norm`. So the rays of one image column of
//! a level camera share their horizontal motion bit for bit (only their height rate differs),
//! and cross every cell boundary at the same `τ` ([`super::column`]). Working relative to the
//! grid origin keeps UTM-sized eyes exact.
//!
//! Invariant: the time the ray crosses a cell boundary `b` is one pure function,
//! [`Axis::cross`] (which is [`crate::walk::cross`]), used by every traversal and every level
//! (a level-`k` boundary is the level-0 boundary `K · f^k`). The stepping itself is the crate's
//! one grid walk under [`crate::walk::Corner::Exact`], [`crate::walk::ExactWalk`] (see
//! [`super::march`]): the cell the ray is in at time `τ` is a pure function of `τ`
//! ([`crate::walk::cell_at`]: a boundary crossed at exactly `τ` counts as crossed; through a
//! corner both crossings are, and the ray is in the diagonal cell). So any two traversals that
//! visit a cell agree bit for bit on its entry and exit times.

/// One horizontal axis of a ray: origin and rate of change in cells (per unit of `τ`).
#[derive(Debug, Clone, Copy)]
pub struct Axis {
    /// Position at `t = 0`, cells.
    pub o: f64,
    /// Cells per unit of `τ` (signed; 0 for a ray parallel to this axis' boundaries).
    pub d: f64,
}

impl Axis {
    /// The axis at `o` cells moving `d` cells per metre.
    pub fn new(o: f64, d: f64) -> Axis {
        let d = if d == 0.0 { 0.0 } else { d }; // no -0.0: one parallel case
        Axis { o, d }
    }

    /// Time `τ` at which the ray crosses boundary `b` (cells); `+inf` when the
    /// ray is parallel to the boundaries. The crate's one crossing function,
    /// [`crate::walk::cross`] (`(b − o) / d`), shared with every other grid walk.
    #[inline]
    pub fn cross(&self, b: i64) -> f64 {
        crate::walk::cross(self.o, self.d, b)
    }

    /// Time the ray enters cell `kk` of a level whose cells are `s` level-0 cells wide on this
    /// axis (`-inf` if parallel).
    #[inline]
    pub fn entry(&self, kk: i64, s: i64) -> f64 {
        if self.d > 0.0 {
            self.cross(kk * s)
        } else if self.d < 0.0 {
            self.cross((kk + 1) * s)
        } else {
            f64::NEG_INFINITY
        }
    }

    /// Time the ray leaves cell `kk` of a level whose cells are `s` level-0 cells wide (`+inf`
    /// if parallel).
    #[inline]
    pub fn exit(&self, kk: i64, s: i64) -> f64 {
        if self.d > 0.0 {
            self.cross((kk + 1) * s)
        } else {
            self.cross(kk * s) // +inf when parallel
        }
    }

    /// The times the ray is inside `[0, n]` cells on this axis, `(t_in, t_out)`; empty
    /// (`t_in >= t_out`) when a parallel ray lies outside `[0, n)`.
    pub fn slab(&self, n: i64) -> (f64, f64) {
        if self.d > 0.0 {
            (self.cross(0), self.cross(n))
        } else if self.d < 0.0 {
            (self.cross(n), self.cross(0))
        } else if self.o >= 0.0 && self.o < n as f64 {
            (f64::NEG_INFINITY, f64::INFINITY)
        } else {
            (f64::INFINITY, f64::NEG_INFINITY)
        }
    }
}

/// A ray from the eye: horizontal axes in cells, height in metres, parameter `τ` (module doc).
#[derive(Debug, Clone, Copy)]
pub struct Ray {
    /// Column axis.
    pub u: Axis,
    /// Row axis.
    pub v: Axis,
    /// Eye height, metres.
    pub z0: f64,
    /// Height change per unit of `τ`, metres.
    pub dz: f64,
    /// Range per unit of `τ`, metres (the length of the direction the ray was made from).
    pub norm: f64,
}

impl Ray {
    /// The ray from local eye `(u0, v0)` (cells) at height `z0` (metres) along world direction
    /// `d` (metres east, north, up; any length), over level-0 cells `cell` metres wide
    /// (signed: a north-up grid's rows run south).
    pub fn new(u0: f64, v0: f64, z0: f64, d: [f64; 3], cell: [f64; 2]) -> Ray {
        Ray {
            u: Axis::new(u0, d[0] / cell[0]),
            v: Axis::new(v0, d[1] / cell[1]),
            z0,
            dz: d[2],
            norm: (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt(),
        }
    }

    /// The ray with `self`'s eye and axes rising `dz` metres per unit of `τ`: [`Ray::new`] for a
    /// direction whose horizontal components are those `self` was made from, whose squared
    /// length is `horizontal_sq` (the same f64 operations in the same order).
    #[inline]
    fn with_rise(&self, horizontal_sq: f64, dz: f64) -> Ray {
        Ray {
            dz,
            norm: (horizontal_sq + dz * dz).sqrt(),
            ..*self
        }
    }

    /// Range at `τ`, metres.
    #[inline]
    pub fn range(&self, tau: f64) -> f64 {
        tau * self.norm
    }

    /// Sine of the ray's elevation.
    #[inline]
    pub fn sin_elevation(&self) -> f64 {
        self.dz / self.norm
    }

    /// Height of the ray at `τ = t`, metres (monotone in `t`).
    #[inline]
    pub fn z(&self, t: f64) -> f64 {
        self.z0 + t * self.dz
    }

    /// The `τ` at which the ray reaches height `z` metres (`None` for a level ray).
    #[inline]
    pub fn time_at_height(&self, z: f64) -> Option<f64> {
        (self.dz != 0.0).then(|| (z - self.z0) / self.dz)
    }
}

/// Rays from one eye that remember the last ray's horizontal direction: a ray whose direction
/// shares it (the rays of an image column of a level camera) reuses its axes, so it costs no
/// division. Invariant: [`Rays::ray`] is bit for bit [`Ray::new`].
pub struct Rays {
    eye: [f64; 3],
    cell: [f64; 2],
    /// The last ray, the bits of its direction's horizontal components and their squared length.
    last: Option<(Ray, [u64; 2], f64)>,
}

impl Rays {
    /// Rays from local eye `eye` (cells, cells, metres) over level-0 cells `cell` metres wide
    /// (as for [`Ray::new`]).
    pub fn new(eye: [f64; 3], cell: [f64; 2]) -> Rays {
        Rays {
            eye,
            cell,
            last: None,
        }
    }

    /// `Ray::new(eye, d, cell)`, and whether its horizontal direction is the previous ray's.
    #[inline]
    pub fn ray(&mut self, d: [f64; 3]) -> (Ray, bool) {
        let key = [d[0].to_bits(), d[1].to_bits()];
        if let Some((last, k, sq)) = &self.last {
            if *k == key {
                return (last.with_rise(*sq, d[2]), true);
            }
        }
        let [u0, v0, z0] = self.eye;
        let ray = Ray::new(u0, v0, z0, d, self.cell);
        self.last = Some((ray, key, d[0] * d[0] + d[1] * d[1]));
        (ray, false)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn cell_at(a: Axis, t: f64) -> i64 {
        crate::walk::cell_at(a.o, a.d, t, 1, 0)
    }

    #[test]
    fn eye_on_a_boundary_starts_in_the_cell_it_looks_into() {
        assert_eq!(cell_at(Axis::new(3.0, 0.5), 0.0), 3);
        assert_eq!(cell_at(Axis::new(3.0, -0.5), 0.0), 2);
        assert_eq!(cell_at(Axis::new(3.0, 0.0), 0.0), 3);
    }

    #[test]
    fn parallel_axis_never_crosses() {
        let a = Axis::new(2.5, -0.0);
        assert_eq!(a.cross(7), f64::INFINITY);
        assert_eq!(a.exit(2, 1), f64::INFINITY);
        assert_eq!(a.entry(2, 1), f64::NEG_INFINITY);
        assert_eq!(a.slab(4), (f64::NEG_INFINITY, f64::INFINITY));
        assert!(Axis::new(4.0, 0.0).slab(4).0 >= Axis::new(4.0, 0.0).slab(4).1);
    }

    fn bits(r: &Ray) -> [u64; 7] {
        [r.u.o, r.u.d, r.v.o, r.v.d, r.z0, r.dz, r.norm].map(f64::to_bits)
    }

    proptest! {
        #[test]
        fn rays_sharing_a_heading_are_the_rays_ray_new_makes(
            eye in prop::array::uniform3(-1e6f64..1e6),
            cell in prop::array::uniform2(prop_oneof![0.25f64..30.0, -30.0f64..-0.25]),
            dirs in prop::collection::vec(
                (prop::array::uniform2(prop_oneof![Just(0.0), Just(-0.0), -2.0f64..2.0]), -3.0f64..3.0, 1usize..4),
                1..20,
            ),
        ) {
            let mut rays = Rays::new(eye, cell);
            for (h, dz0, repeat) in dirs {
                for k in 0..repeat {
                    let d = [h[0], h[1], dz0 + k as f64 * 0.37];
                    let (ray, same) = rays.ray(d);
                    prop_assert_eq!(bits(&ray), bits(&Ray::new(eye[0], eye[1], eye[2], d, cell)));
                    if k > 0 {
                        prop_assert!(same);
                    }
                }
            }
        }

        #[test]
        fn entry_and_exit_bracket_the_time_in_the_cell_the_walk_is_in(
            o in -50.0f64..50.0, d in -3.0f64..3.0, t in 0.0f64..100.0
        ) {
            let a = Axis::new(o, d);
            let k = cell_at(a, t);
            prop_assert!(a.entry(k, 1) <= t && t < a.exit(k, 1) || d == 0.0);
            // a coarse exit is the exit of the coarse cell's last level-0 cell on the way
            let kk = k.div_euclid(4);
            let last = if d > 0.0 { kk * 4 + 3 } else { kk * 4 };
            prop_assert_eq!(a.exit(kk, 4), a.exit(last, 1));
        }
    }
}
