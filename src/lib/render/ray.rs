//! A ray in the database's local cell space, and its exact integer-boundary crossings.
//!
//! Local frame: `u` = level-0 column coordinate (east for north-up grids), `v` = level-0 row
//! coordinate, both in cells from the grid's corner origin; `z` in metres. The ray parameter `t`
//! is the distance from the eye in world metres (the world direction is a unit vector), so `t`
//! at a hit *is* the range. Working relative to the grid origin keeps UTM-sized eyes exact.
//!
//! Invariant: the time the ray crosses a cell boundary `b` is one pure function,
//! [`Axis::cross`] (which is [`crate::walk::cross`]), used by every traversal and every level
//! (a level-`k` boundary is the level-0 boundary `K · f^k`). The stepping itself is the crate's
//! one grid walk, [`crate::walk::Walk`], under [`crate::walk::Corner::Exact`] (see
//! [`super::march`]): the cell the ray is in at time `t` is a pure function of `t`
//! ([`crate::walk::cell_at`]: a boundary crossed at exactly `t` counts as crossed; through a
//! corner both crossings are, and the ray is in the diagonal cell). So any two traversals that
//! visit a cell agree bit for bit on its entry and exit times.

/// One horizontal axis of a ray: origin and rate of change in cells (per metre of range).
#[derive(Debug, Clone, Copy)]
pub struct Axis {
    /// Position at `t = 0`, cells.
    pub o: f64,
    /// Cells per metre of range (signed; 0 for a ray parallel to this axis' boundaries).
    pub d: f64,
}

impl Axis {
    /// The axis at `o` cells moving `d` cells per metre.
    pub fn new(o: f64, d: f64) -> Axis {
        let d = if d == 0.0 { 0.0 } else { d }; // no -0.0: one parallel case
        Axis { o, d }
    }

    /// Time (metres of range) at which the ray crosses boundary `b` (cells); `+inf` when the
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

/// A ray from the eye: horizontal axes in cells, height in metres, `t` in metres.
#[derive(Debug, Clone, Copy)]
pub struct Ray {
    /// Column axis.
    pub u: Axis,
    /// Row axis.
    pub v: Axis,
    /// Eye height, metres.
    pub z0: f64,
    /// Height change per metre of range (the sine of the ray's elevation).
    pub dz: f64,
}

impl Ray {
    /// Height of the ray at time `t`, metres (monotone in `t`).
    #[inline]
    pub fn z(&self, t: f64) -> f64 {
        self.z0 + t * self.dz
    }

    /// Time at which the ray reaches height `z`, metres (`None` for a level ray).
    #[inline]
    pub fn time_at_height(&self, z: f64) -> Option<f64> {
        (self.dz != 0.0).then(|| (z - self.z0) / self.dz)
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

    proptest! {
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
