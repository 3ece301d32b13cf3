//! Grid traversal: the cells a ray crosses, in order, with an explicit corner rule.
//!
//! One traversal for every place that walks a line across cells (shadow-height's scan lines,
//! the reference shadow march, the voxel-colour visibility ray, the renderer's stepping through
//! every level of its max-Z hierarchy): a line in continuous cell coordinates — cell `k` of an
//! axis spans `[k, k + 1)` — from `start`, moving `dir` cells per unit of the caller's parameter
//! `t` (metres, or cells).
//!
//! [`Walk`] takes the corner rule as a value; under [`Corner::Exact`] it is an [`ExactWalk`],
//! which callers that step many rays (the renderer) use directly: that rule needs no state
//! beyond the cell and the next crossings, and the walk is small enough to copy.
//!
//! A walk may also run over a coarser grid whose cells are `scale` cells wide ([`Walk::resume`]):
//! its boundary `K` is the fine boundary `K · scale`, and its crossing time is
//! `cross(start, dir, K · scale)`, the same f64 as the fine walk's for that boundary.
//!
//! # Invariants
//! * **Crossing times are one pure function.** The ray crosses boundary `b` of axis `a` at
//!   `t = (b − start[a]) / dir[a]` ([`cross`]), computed afresh for every boundary (no running
//!   sum that drifts over thousands of cells), so two walks over the same ray agree bit for bit.
//! * **Start cell.** On each axis the cell holding `start`; a start exactly on a boundary is in
//!   the cell the ray moves into (`floor` moving up or parallel, `ceil − 1` moving down).
//! * **Corners.** The ray passes *through a corner* when, at the time it crosses the nearest
//!   boundary, it is within [`CORNER_EPS`] cells of a boundary of another axis too: exact
//!   diagonals, and directions a few ulps off them, all count. The [`Corner`] rule then says what
//!   is visited:
//!   - [`Corner::Diagonal`]: the ray steps straight into the diagonal cell. The side cells touch
//!     the ray at one point only, so they are not crossed (a zero-area contact is no contact).
//!   - [`Corner::Touching`]: the side cells are visited too, each with zero length
//!     (`t_in == t_out`), before the diagonal cell: the *supercover* of the line, every cell the
//!     closed line touches — for marking the cells a polygon edge covers in part.
//!   - [`Corner::Exact`]: no tolerance. A corner is where the crossing times of two axes are the
//!     same f64; there the ray steps straight into the diagonal cell, as `Diagonal` does. A ray
//!     a few ulps off a diagonal visits the side cell it clips, for the (tiny, positive) time it
//!     spends there. In exchange the walk has no memory: the cell it is in at `t` is
//!     [`cell_at`] on each axis (every boundary crossed at or before `t`), whatever path led
//!     there. So a walk resumed at `(cell_at(t), t)` continues exactly as one that stepped
//!     there, and a walk over `scale`-wide cells is in the floor-division by `scale` of the fine
//!     walk's cell at every `t`, entering and leaving it at bit-identical times (the renderer's
//!     hierarchy relies on both). The tolerant rules cannot promise this: a ray grazing a
//!     boundary line within `CORNER_EPS` is stepped across it at the first crossing of another
//!     axis, which depends on which boundaries the walk visits.
//! * **Visits.** Each [`Visit`] holds the cell and the times the ray enters and leaves it. In
//!   `Diagonal` mode the visits tile the ray: each `t_in` is the previous `t_out`, and every
//!   visit has positive length (but the start cell's, when `start` sits on its exit boundary).
//!   A ray parallel to an axis never crosses that axis' boundaries; a ray with no direction at
//!   all visits its start cell once, to `t = +∞`.
//!
//! The walk is an unbounded iterator: callers stop it (`take_while` on `t_in`, or on leaving
//! their grid).

/// How close (cells) the ray must pass to a boundary of another axis, when it crosses one, to
/// count as passing through their corner. Far above the rounding of `cross` for coordinates up
/// to 10⁶ cells, far below any distance that matters.
pub const CORNER_EPS: f64 = 1e-9;

/// What a walk visits where the ray passes exactly through a cell corner.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Corner {
    /// Step into the diagonal cell only (the cells the ray crosses with positive length).
    Diagonal,
    /// Also visit the side cells, with zero length (every cell the line touches).
    Touching,
    /// A corner only where two crossing times are equal (no tolerance), then the diagonal cell:
    /// the cell at `t` is a pure function of `t` ([`cell_at`]).
    Exact,
}

/// One cell of a walk and the parameter interval the ray spends in it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Visit<const N: usize> {
    /// The cell's index on each axis.
    pub cell: [i64; N],
    /// Parameter at which the ray enters the cell (0 for the start cell).
    pub t_in: f64,
    /// Parameter at which it leaves (`+∞` if never).
    pub t_out: f64,
}

/// The parameter at which a ray at `o` moving `d` cells per unit crosses boundary `b` (cells):
/// `(b − o) / d`, `+∞` when `d == 0`.
#[inline]
pub fn cross(o: f64, d: f64, b: i64) -> f64 {
    if d == 0.0 {
        f64::INFINITY
    } else {
        cross_moving(o, d, b)
    }
}

/// [`cross`] for a ray that moves along the axis (`d != 0`): the same f64, without the test
/// (a walk's step, the hottest use).
#[inline]
fn cross_moving(o: f64, d: f64, b: i64) -> f64 {
    (b as f64 - o) / d
}

/// The index of the `scale`-wide cell holding the ray `o + t·d` (cells) at `t` on one axis under
/// [`Corner::Exact`]: every boundary `K · scale` whose crossing time [`cross`] is at or before
/// `t` is behind the ray (so a boundary crossed at exactly `t` is). At `t = 0` this is
/// [`Walk::new`]'s start cell. `scale >= 1`; `guess` is any nearby index (the answer does not
/// depend on it, only the time taken to find it).
#[inline]
pub fn cell_at(o: f64, d: f64, t: f64, scale: i64, guess: i64) -> i64 {
    locate(o, d, t, scale, guess).0
}

/// [`cell_at`], and the time the ray crosses that cell's exit boundary on this axis (`+∞` if it
/// does not move along it): the walk's next crossing from there, from the same division
/// `cell_at` checks it with.
#[inline]
fn locate(o: f64, d: f64, t: f64, scale: i64, guess: i64) -> (i64, f64) {
    // floor division by a power of two is an arithmetic shift (a division costs tens of cycles)
    let div = |k: i64| match (scale as u64).is_power_of_two() {
        true => k >> scale.trailing_zeros(),
        false => k.div_euclid(scale),
    };
    if d == 0.0 || !d.is_finite() {
        return (div(o.floor() as i64), f64::INFINITY);
    }
    // Start from the position's cell (right but for rounding), else from the guess.
    let est = o + t * d;
    let mut k = if est.is_finite() && est.abs() < 9.0e15 {
        div(crate::num::floor_i64(est))
    } else {
        guess
    };
    if d > 0.0 {
        // the largest k whose boundary is crossed
        while cross(o, d, k * scale) > t {
            k -= 1;
        }
        loop {
            let exit = cross(o, d, (k + 1) * scale);
            if exit > t {
                return (k, exit);
            }
            k += 1;
        }
    } else {
        // boundary k + 1 crossed, boundary k not
        while cross(o, d, (k + 1) * scale) > t {
            k += 1;
        }
        loop {
            let exit = cross(o, d, k * scale);
            if exit > t {
                return (k, exit);
            }
            k -= 1;
        }
    }
}

/// `dir` with its non-finite components (and `-0.0`) taken as 0: the axes the ray does not
/// move along.
fn moving<const N: usize>(dir: [f64; N]) -> [f64; N] {
    dir.map(|d| if d.is_finite() && d != 0.0 { d } else { 0.0 })
}

/// The cells a ray crosses; see the module doc. `N` is 2 (raster cells) or 3 (voxels).
#[derive(Debug, Clone)]
pub struct Walk<const N: usize> {
    rule: Rule<N>,
}

/// A walk's state under its corner rule: the exact rule needs no memory of its path.
#[derive(Debug, Clone)]
enum Rule<const N: usize> {
    Tolerant(Tolerant<N>),
    Exact(ExactWalk<N>),
}

/// The start cell on each axis: the cell holding `start`, or on a boundary the one the ray
/// moves into.
fn start_cell<const N: usize>(start: [f64; N], dir: [f64; N]) -> [i64; N] {
    std::array::from_fn(|a| {
        if dir[a] < 0.0 {
            start[a].ceil() as i64 - 1
        } else {
            start[a].floor() as i64
        }
    })
}

/// The step on each axis: +1, −1, or 0 where the ray does not move along it.
fn steps<const N: usize>(dir: [f64; N]) -> [i64; N] {
    dir.map(|d| {
        if d > 0.0 {
            1
        } else if d < 0.0 {
            -1
        } else {
            0
        }
    })
}

impl<const N: usize> Walk<N> {
    /// The walk of the ray from `start` moving `dir` cells per unit of `t`, first visit the
    /// start cell from `t = 0`.
    pub fn new(start: [f64; N], dir: [f64; N], corner: Corner) -> Walk<N> {
        let dir = moving(dir);
        Walk::resume(start, dir, corner, 1, start_cell(start, dir), 0.0)
    }

    /// A walk over cells `scale` of the caller's cells wide (cell `K` spans
    /// `[K · scale, (K + 1) · scale)`), taken up at time `t` in `cell`, for the same ray as
    /// [`Walk::new`]`(start, dir, corner)`: crossing times are still `cross(start, dir, b)` of
    /// the fine boundary `b = K · scale`, so they agree bit for bit with a fine walk's. The
    /// first visit is `cell` from `t`. `cell` must be the cell holding the ray at `t` under the
    /// corner rule — under [`Corner::Exact`] that is [`cell_at`] on each axis, and the walk then
    /// continues exactly as one that stepped there from `start`. `scale >= 1`.
    pub fn resume(
        start: [f64; N],
        dir: [f64; N],
        corner: Corner,
        scale: i64,
        cell: [i64; N],
        t: f64,
    ) -> Walk<N> {
        assert!((1..=3).contains(&N), "walks are 1-, 2- or 3-dimensional");
        let rule = match corner {
            Corner::Exact => Rule::Exact(ExactWalk::resume(start, dir, scale, cell, t)),
            tolerant => Rule::Tolerant(Tolerant::resume(start, dir, tolerant, scale, cell, t)),
        };
        Walk { rule }
    }

    /// The cell the walk is in and the time it entered it (before the first `next`: the start
    /// cell and the start time).
    #[inline]
    pub fn position(&self) -> ([i64; N], f64) {
        match &self.rule {
            Rule::Tolerant(w) => (w.cell, w.t_in),
            Rule::Exact(w) => w.position(),
        }
    }

    /// The axes the last step crossed (all `false` before the first step).
    #[inline]
    pub fn stepped(&self) -> [bool; N] {
        match &self.rule {
            Rule::Tolerant(w) => w.stepped,
            Rule::Exact(w) => w.stepped(),
        }
    }
}

impl<const N: usize> Iterator for Walk<N> {
    type Item = Visit<N>;

    fn next(&mut self) -> Option<Visit<N>> {
        match &mut self.rule {
            Rule::Tolerant(w) => w.next(),
            Rule::Exact(w) => w.next(),
        }
    }
}

/// A walk under [`Corner::Diagonal`] or [`Corner::Touching`]: corners within [`CORNER_EPS`],
/// and for `Touching` the side cells queued to visit with zero length.
#[derive(Debug, Clone)]
struct Tolerant<const N: usize> {
    start: [f64; N],
    dir: [f64; N],
    corner: Corner,
    /// Width of a cell in the caller's cells.
    scale: i64,
    cell: [i64; N],
    step: [i64; N],
    /// Which axes the last step crossed.
    stepped: [bool; N],
    t_in: f64,
    /// The time the ray crosses the next boundary of each axis (`+∞` for an axis it does not
    /// move along).
    next_times: [f64; N],
    /// Zero-length side cells still to visit (`Touching`), last first.
    pending: [[i64; N]; 8],
    n_pending: usize,
    pending_t: f64,
    done: bool,
}

impl<const N: usize> Tolerant<N> {
    fn resume(
        start: [f64; N],
        dir: [f64; N],
        corner: Corner,
        scale: i64,
        cell: [i64; N],
        t: f64,
    ) -> Tolerant<N> {
        assert!(scale >= 1, "a walk's cells are at least one cell wide");
        let dir = moving(dir);
        let mut w = Tolerant {
            start,
            dir,
            corner,
            scale,
            cell,
            step: steps(dir),
            stepped: [false; N],
            t_in: t,
            next_times: [f64::INFINITY; N],
            pending: [[0; N]; 8],
            n_pending: 0,
            pending_t: 0.0,
            done: false,
        };
        w.next_times = std::array::from_fn(|a| w.crossing(a));
        w
    }

    /// The time the ray crosses the next boundary of axis `a` (`+∞` if it does not move along it).
    #[inline]
    fn crossing(&self, a: usize) -> f64 {
        cross(self.start[a], self.dir[a], self.next_boundary(a))
    }

    /// The next boundary (in the caller's cells) of axis `a` in the direction of travel.
    #[inline]
    fn next_boundary(&self, a: usize) -> i64 {
        next_boundary(self.cell[a], self.step[a], self.scale)
    }

    /// Queue the side cells of a corner the ray passes through at `t_out` on the `tied` axes:
    /// every proper, non-empty subset of them stepped.
    fn queue_side_cells(&mut self, tied: [bool; N], t_out: f64) {
        let mut axes = [0usize; 3];
        let mut n_axes = 0;
        for a in (0..N).filter(|&a| tied[a]) {
            axes[n_axes] = a;
            n_axes += 1;
        }
        let axes = &axes[..n_axes];
        let full = (1usize << axes.len()) - 1;
        self.n_pending = 0;
        for mask in (1..full).rev() {
            let mut c = self.cell;
            for (k, &a) in axes.iter().enumerate() {
                if mask & (1 << k) != 0 {
                    c[a] += self.step[a];
                }
            }
            self.pending[self.n_pending] = c;
            self.n_pending += 1;
        }
        self.pending_t = t_out;
    }

    fn next(&mut self) -> Option<Visit<N>> {
        if self.n_pending > 0 {
            self.n_pending -= 1;
            let t = self.pending_t;
            return Some(Visit {
                cell: self.pending[self.n_pending],
                t_in: t,
                t_out: t,
            });
        }
        if self.done {
            return None;
        }
        // The nearest crossing, and every axis the ray meets a boundary of at that time.
        let times = self.next_times;
        let (m, t_out) = nearest(&times);
        let here = Visit {
            cell: self.cell,
            t_in: self.t_in,
            t_out,
        };
        if t_out == f64::INFINITY {
            self.done = true;
            return Some(here);
        }
        let tied: [bool; N] = std::array::from_fn(|a| {
            a == m
                || (self.dir[a] != 0.0
                    && (self.start[a] + t_out * self.dir[a] - self.next_boundary(a) as f64).abs()
                        <= CORNER_EPS)
        });
        if self.corner == Corner::Touching {
            self.queue_side_cells(tied, t_out);
        }
        for (a, &t) in tied.iter().enumerate() {
            if t {
                self.cell[a] += self.step[a];
            }
        }
        self.stepped = tied;
        for a in (0..N).filter(|&a| tied[a]) {
            self.next_times[a] = self.crossing(a);
        }
        self.t_in = t_out;
        Some(here)
    }
}

/// The axis of the nearest crossing among `times` (the first of equals) and its time; `+∞`
/// (axis 0) when the ray crosses nothing.
#[inline]
fn nearest<const N: usize>(times: &[f64; N]) -> (usize, f64) {
    let mut best = (0, f64::INFINITY);
    for (a, &t) in times.iter().enumerate() {
        if t < best.1 {
            best = (a, t);
        }
    }
    best
}

/// The next boundary (in the caller's cells) along an axis from `cell` of cells `scale` wide,
/// moving `step`.
#[inline]
fn next_boundary(cell: i64, step: i64, scale: i64) -> i64 {
    if step > 0 {
        (cell + 1) * scale
    } else {
        cell * scale
    }
}

/// A walk under [`Corner::Exact`], as a type of its own: it holds only what the exact rule
/// needs (no corner tolerance, no queue), so the renderer, which steps hundreds of thousands
/// of cells a frame, takes it directly. [`Walk`] with `Corner::Exact` is this walk.
#[derive(Debug, Clone, Copy)]
pub struct ExactWalk<const N: usize> {
    start: [f64; N],
    dir: [f64; N],
    step: [i64; N],
    /// Width of a cell in the caller's cells.
    scale: i64,
    cell: [i64; N],
    stepped: [bool; N],
    t_in: f64,
    /// The time the ray crosses the next boundary of each axis (`+∞` for an axis it does not
    /// move along).
    next_times: [f64; N],
    done: bool,
}

impl<const N: usize> ExactWalk<N> {
    /// See [`Walk::resume`] (under [`Corner::Exact`]).
    pub fn resume(
        start: [f64; N],
        dir: [f64; N],
        scale: i64,
        cell: [i64; N],
        t: f64,
    ) -> ExactWalk<N> {
        let mut w = ExactWalk::unplaced(start, dir, scale);
        w.restart(scale, cell, t);
        w
    }

    /// [`ExactWalk::resume`] in the cell holding the ray at `t` ([`cell_at`] on each axis;
    /// `guess` is any nearby cell), finding the cell and the walk's first crossings with the
    /// same divisions.
    pub fn at(start: [f64; N], dir: [f64; N], scale: i64, t: f64, guess: [i64; N]) -> ExactWalk<N> {
        ExactWalk::unplaced(start, dir, scale).placed(scale, t, guess)
    }

    /// This walk's ray taken up at `t` over cells `scale` wide, in the cell holding it then:
    /// [`ExactWalk::at`] with this walk's start and direction, without preparing the ray's
    /// steps again.
    #[inline]
    pub fn placed(&self, scale: i64, t: f64, guess: [i64; N]) -> ExactWalk<N> {
        self.descended(scale, t, guess, [false; N])
    }

    /// [`ExactWalk::placed`] for a descent (the renderer's, hundreds of thousands a frame): this
    /// walk's ray taken up at `t` over cells `scale` wide (a divisor of this walk's), in the
    /// block of this walk's cell whose first fine cell is `corner`, which the ray entered at
    /// exactly `t` across the axes `entered` ([`ExactWalk::stepped`] before the step that
    /// left it; none for a walk's first cell). On an entered axis the fine cell is the block's
    /// first along the ray's motion: its entry boundary is the coarse cell's, crossed at `t`
    /// (the same f64, [`cross`] of the same boundary), so only its exit crossing is computed,
    /// and checked to lie after `t` (else the cell is located as `placed` does). The same
    /// walk as `placed`.
    #[inline]
    pub fn descended(
        &self,
        scale: i64,
        t: f64,
        corner: [i64; N],
        entered: [bool; N],
    ) -> ExactWalk<N> {
        assert!(scale >= 1, "a walk's cells are at least one cell wide");
        let f = self.scale / scale;
        let mut w = *self;
        w.scale = scale;
        w.t_in = t;
        w.stepped = [false; N];
        w.done = false;
        for a in 0..N {
            let (o, d) = (w.start[a], w.dir[a]);
            let first = match w.step[a] > 0 {
                true => corner[a],
                false => corner[a] + f - 1,
            };
            let exit =
                entered[a].then(|| cross_moving(o, d, next_boundary(first, w.step[a], scale)));
            (w.cell[a], w.next_times[a]) = match exit {
                Some(exit) if exit > t => (first, exit),
                _ => locate(o, d, t, scale, corner[a]),
            };
        }
        debug_assert!((0..N).all(|a| w.next_times[a].to_bits() == w.crossing(a).to_bits()));
        debug_assert!((0..N).all(|a| w.cell[a] == cell_at(w.start[a], w.dir[a], t, scale, 0)));
        w
    }

    /// The axes the last step crossed (all `false` before the first step and after a walk is
    /// placed or restarted).
    #[inline]
    pub fn stepped(&self) -> [bool; N] {
        self.stepped
    }

    fn unplaced(start: [f64; N], dir: [f64; N], scale: i64) -> ExactWalk<N> {
        assert!(scale >= 1, "a walk's cells are at least one cell wide");
        let dir = moving(dir);
        ExactWalk {
            start,
            dir,
            step: steps(dir),
            scale,
            cell: [0; N],
            stepped: [false; N],
            t_in: 0.0,
            next_times: [f64::INFINITY; N],
            done: false,
        }
    }

    /// Take the same ray up again, as [`ExactWalk::resume`] with this walk's start and
    /// direction, without building a new walk (the renderer does this on every change of
    /// level).
    #[inline]
    pub fn restart(&mut self, scale: i64, cell: [i64; N], t: f64) {
        assert!(scale >= 1, "a walk's cells are at least one cell wide");
        self.scale = scale;
        self.cell = cell;
        self.t_in = t;
        self.stepped = [false; N];
        self.next_times = std::array::from_fn(|a| self.crossing(a));
        self.done = false;
    }

    /// See [`Walk::position`].
    #[inline]
    pub fn position(&self) -> ([i64; N], f64) {
        (self.cell, self.t_in)
    }

    /// The time the ray crosses the next boundary of axis `a` (`+∞` if it does not move along it).
    #[inline]
    fn crossing(&self, a: usize) -> f64 {
        cross(
            self.start[a],
            self.dir[a],
            next_boundary(self.cell[a], self.step[a], self.scale),
        )
    }
}

impl<const N: usize> Iterator for ExactWalk<N> {
    type Item = Visit<N>;

    /// The next visit: the cell until the nearest crossing; every axis crossed at exactly that
    /// f64 steps (a corner when several do).
    #[inline]
    fn next(&mut self) -> Option<Visit<N>> {
        if self.done {
            return None;
        }
        // the nearest crossing (crossing times are never NaN)
        let t_out = self.next_times.iter().fold(f64::INFINITY, |m, &t| m.min(t));
        let here = Visit {
            cell: self.cell,
            t_in: self.t_in,
            t_out,
        };
        if t_out == f64::INFINITY {
            self.done = true;
            return Some(here);
        }
        for a in 0..N {
            let tied = self.next_times[a] == t_out;
            self.stepped[a] = tied;
            if tied {
                // a crossing is finite, so the ray moves along this axis
                self.cell[a] += self.step[a];
                let b = next_boundary(self.cell[a], self.step[a], self.scale);
                self.next_times[a] = cross_moving(self.start[a], self.dir[a], b);
            }
        }
        self.t_in = t_out;
        Some(here)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn cells<const N: usize>(w: Walk<N>, n: usize) -> Vec<[i64; N]> {
        w.take(n).map(|v| v.cell).collect()
    }

    /// Every cell the segment `[0, t_end]` crosses with positive length, by brute force: all
    /// boundary crossings sorted, the cell at the middle of each interval between them.
    fn brute<const N: usize>(start: [f64; N], dir: [f64; N], t_end: f64) -> Vec<[i64; N]> {
        let mut ts = vec![0.0, t_end];
        for a in 0..N {
            if dir[a] == 0.0 {
                continue;
            }
            let (lo, hi) = (
                start[a].min(start[a] + dir[a] * t_end),
                start[a].max(start[a] + dir[a] * t_end),
            );
            for b in lo.ceil() as i64..=hi.floor() as i64 {
                let t = cross(start[a], dir[a], b);
                if t > 0.0 && t < t_end {
                    ts.push(t);
                }
            }
        }
        ts.sort_by(f64::total_cmp);
        ts.windows(2)
            .filter(|w| w[1] - w[0] > 1e-7)
            .map(|w| {
                let t = (w[0] + w[1]) / 2.0;
                std::array::from_fn(|a| (start[a] + t * dir[a]).floor() as i64)
            })
            .collect()
    }

    #[test]
    fn hard_case_exact_axes_walk_one_row_or_column() {
        for (d, step) in [
            ([1.0, 0.0], [1, 0]),
            ([-1.0, 0.0], [-1, 0]),
            ([0.0, 1.0], [0, 1]),
            ([0.0, -1.0], [0, -1]),
        ] {
            let got = cells(Walk::new([2.5, 3.5], d, Corner::Diagonal), 4);
            let want: Vec<[i64; 2]> = (0..4).map(|k| [2 + step[0] * k, 3 + step[1] * k]).collect();
            assert_eq!(got, want, "{d:?}");
            // Along a boundary: the cell on the + side, both rules alike.
            let on = cells(Walk::new([2.0, 3.0], [1.0, 0.0], Corner::Touching), 3);
            assert_eq!(on, [[2, 3], [3, 3], [4, 3]]);
        }
    }

    #[test]
    fn hard_case_exact_diagonals_step_corner_to_corner() {
        for (sx, sy) in [(1.0, 1.0), (-1.0, 1.0), (1.0, -1.0), (-1.0, -1.0)] {
            let d = [sx * 0.7, sy * 0.7];
            // From a corner: straight down the diagonal, never a side cell.
            let got = cells(Walk::new([5.0, 5.0], d, Corner::Diagonal), 4);
            let first = [if sx > 0.0 { 5 } else { 4 }, if sy > 0.0 { 5 } else { 4 }];
            let want: Vec<[i64; 2]> = (0..4)
                .map(|k| [first[0] + sx as i64 * k, first[1] + sy as i64 * k])
                .collect();
            assert_eq!(got, want, "{d:?}");
            // Touching: each corner adds its two side cells, zero length.
            let v: Vec<Visit<2>> = Walk::new([5.0, 5.0], d, Corner::Touching).take(7).collect();
            assert_eq!(v[0].cell, want[0]);
            assert_eq!(v[3].cell, want[1]);
            assert_eq!(v[6].cell, want[2]);
            for side in [&v[1], &v[2], &v[4], &v[5]] {
                assert_eq!(side.t_in, side.t_out);
            }
            let mut sides = [v[1].cell, v[2].cell];
            sides.sort();
            let mut expect = [
                [want[0][0] + sx as i64, want[0][1]],
                [want[0][0], want[0][1] + sy as i64],
            ];
            expect.sort();
            assert_eq!(sides, expect);
        }
    }

    #[test]
    fn hard_case_a_few_ulps_off_a_diagonal_walks_it_exactly() {
        let d = 0.5f64;
        for k in 1..=4 {
            let mut off = d;
            for _ in 0..k {
                off = f64::from_bits(off.to_bits() + 1);
            }
            let mut under = d;
            for _ in 0..k {
                under = f64::from_bits(under.to_bits() - 1);
            }
            for dir in [[d, off], [off, d], [d, under], [-under, d]] {
                let got = cells(Walk::new([10.0, 20.0], dir, Corner::Diagonal), 2000);
                let sx = dir[0].signum() as i64;
                let x0 = if sx > 0 { 10 } else { 9 };
                let want: Vec<[i64; 2]> = (0..2000).map(|i| [x0 + sx * i, 20 + i]).collect();
                assert_eq!(got, want, "{dir:?}");
            }
        }
    }

    #[test]
    fn hard_case_utm_sized_start_stays_exact() {
        // A start 5·10⁶ cells out, along the diagonal: every crossing still found a corner.
        let got = cells(
            Walk::new([5.0e6, 5.3e6], [0.5, 0.5], Corner::Diagonal),
            1000,
        );
        assert!(got
            .iter()
            .enumerate()
            .all(|(i, c)| *c == [5_000_000 + i as i64, 5_300_000 + i as i64]));
    }

    #[test]
    fn no_direction_visits_the_start_cell_once() {
        let v: Vec<Visit<2>> = Walk::new([1.5, -0.5], [0.0, f64::NAN], Corner::Diagonal)
            .take(3)
            .collect();
        assert_eq!(v.len(), 1);
        assert_eq!((v[0].cell, v[0].t_out), ([1, -1], f64::INFINITY));
    }

    #[test]
    fn three_axes_through_a_voxel_corner() {
        let d = [1.0, 1.0, 1.0];
        assert_eq!(
            cells(Walk::new([0.0, 0.0, 0.0], d, Corner::Diagonal), 3),
            [[0, 0, 0], [1, 1, 1], [2, 2, 2]]
        );
        // Touching: the six side voxels of the corner, then the diagonal one.
        let v: Vec<[i64; 3]> = cells(Walk::new([0.0, 0.0, 0.0], d, Corner::Touching), 8);
        assert_eq!(v[7], [1, 1, 1]);
        let mut sides = v[1..7].to_vec();
        sides.sort();
        assert_eq!(
            sides,
            [
                [0, 0, 1],
                [0, 1, 0],
                [0, 1, 1],
                [1, 0, 0],
                [1, 0, 1],
                [1, 1, 0]
            ]
        );
    }

    #[test]
    fn hard_case_exact_rule_steps_diagonally_only_where_crossing_times_are_equal() {
        // An exact diagonal: both crossings at the same f64, straight into the diagonal cell.
        for d in [[0.5, 0.5], [-0.5, 0.5], [0.5, -0.5], [-0.5, -0.5]] {
            let exact = cells(Walk::new([5.0, 5.0], d, Corner::Exact), 50);
            assert_eq!(exact, cells(Walk::new([5.0, 5.0], d, Corner::Diagonal), 50));
        }
        // One ulp steeper: the row boundary is crossed first (1/off < 2), so the side cell is
        // visited for the time the ray really spends in it; Diagonal steps over it.
        let off = f64::from_bits(0.5f64.to_bits() + 1);
        let v: Vec<Visit<2>> = Walk::new([10.0, 20.0], [0.5, off], Corner::Exact)
            .take(3)
            .collect();
        assert_eq!(v[1].cell, [10, 21]);
        assert!(v[1].t_out > v[1].t_in && v[1].t_out - v[1].t_in < 1e-12);
        assert_eq!(v[2].cell, [11, 21]);
        let d = cells(Walk::new([10.0, 20.0], [0.5, off], Corner::Diagonal), 2);
        assert_eq!(d, [[10, 20], [11, 21]]);
        // The walk's first step reports the axes it crossed.
        let mut w = Walk::new([5.0, 5.0], [0.5, 0.5], Corner::Exact);
        assert_eq!(w.stepped(), [false, false]);
        w.next();
        assert_eq!(w.stepped(), [true, true]);
        assert_eq!(w.position(), ([6, 6], 2.0));
    }

    #[test]
    fn hard_case_coarse_walk_from_a_utm_sized_start() {
        // 4-wide cells 5·10⁶ cells out, a few ulps off the diagonal: the coarse walk is the fine
        // walk's cells divided by 4, at the fine walk's times.
        let o = [5.0e6 + 0.25, 5.3e6 + 0.25];
        let d = [0.5, f64::from_bits(0.5f64.to_bits() + 2)];
        let fine: Vec<Visit<2>> = Walk::new(o, d, Corner::Exact).take(400).collect();
        let coarse = Walk::resume(o, d, Corner::Exact, 4, [1_250_000, 1_325_000], 0.0);
        let want = group(&fine, 4);
        let got: Vec<Visit<2>> = coarse.take(want.len() - 1).collect();
        assert_eq!(got, want[..want.len() - 1]);
    }

    /// The fine visits grouped by their `scale`-wide cell: one visit per run of fine visits in
    /// the same coarse cell, from the first one's `t_in` to the last one's `t_out`.
    fn group(fine: &[Visit<2>], scale: i64) -> Vec<Visit<2>> {
        let mut out: Vec<Visit<2>> = Vec::new();
        for v in fine {
            let c = v.cell.map(|k| k.div_euclid(scale));
            match out.last_mut() {
                Some(last) if last.cell == c => last.t_out = v.t_out,
                _ => out.push(Visit { cell: c, ..*v }),
            }
        }
        out
    }

    /// The exact walk by brute force: every boundary crossing in `(0, t_end)` of both axes,
    /// sorted, equal times merged; from each one on, the cell is the start cell moved one cell
    /// per crossing already passed on each axis. Returns each cell with the time it is entered.
    fn brute_exact(start: [f64; 2], dir: [f64; 2], t_end: f64) -> Vec<([i64; 2], f64)> {
        let mut crossings: Vec<(f64, usize)> = Vec::new();
        for a in 0..2 {
            if dir[a] == 0.0 {
                continue;
            }
            let end = start[a] + dir[a] * t_end;
            let (lo, hi) = (
                start[a].min(end).floor() as i64 - 1,
                start[a].max(end).ceil() as i64 + 1,
            );
            for b in lo..=hi {
                let t = cross(start[a], dir[a], b);
                if t > 0.0 && t < t_end {
                    crossings.push((t, a));
                }
            }
        }
        crossings.sort_by(|x, y| x.0.total_cmp(&y.0));
        let first: [i64; 2] = std::array::from_fn(|a| {
            if dir[a] < 0.0 {
                start[a].ceil() as i64 - 1
            } else {
                start[a].floor() as i64
            }
        });
        let mut out = vec![(first, 0.0)];
        let mut cell = first;
        for (k, &(t, a)) in crossings.iter().enumerate() {
            cell[a] += if dir[a] > 0.0 { 1 } else { -1 };
            if crossings.get(k + 1).is_some_and(|next| next.0 == t) {
                continue; // a corner: the other axis steps at the same time
            }
            out.push((cell, t));
        }
        out
    }

    /// A direction: arbitrary, or exactly on an axis or a diagonal, or a few ulps off one.
    fn direction() -> impl Strategy<Value = [f64; 2]> {
        let any = (-3.0f64..3.0, -3.0f64..3.0).prop_map(|(x, y)| [x, y]);
        let special = (0usize..8, 0.05f64..3.0, -4i64..=4).prop_map(|(k, s, ulps)| {
            let (x, y) = [
                (1.0, 0.0),
                (0.0, 1.0),
                (-1.0, 0.0),
                (0.0, -1.0),
                (1.0, 1.0),
                (-1.0, 1.0),
                (1.0, -1.0),
                (-1.0, -1.0),
            ][k];
            let nudge = |v: f64| {
                if v == 0.0 {
                    v
                } else {
                    f64::from_bits((v.to_bits() as i64 + ulps) as u64)
                }
            };
            [x * s, nudge(y * s)]
        });
        prop_oneof![any, special]
    }

    fn start() -> impl Strategy<Value = [f64; 2]> {
        let any = (-50.0f64..50.0, -50.0f64..50.0).prop_map(|(x, y)| [x, y]);
        let on_grid = (-50i64..50, -50i64..50, 0usize..3).prop_map(|(x, y, k)| match k {
            0 => [x as f64, y as f64],             // a corner
            1 => [x as f64, y as f64 + 0.5],       // a boundary
            _ => [x as f64 + 0.5, y as f64 + 0.5], // a centre
        });
        prop_oneof![any, on_grid]
    }

    proptest! {
        #[test]
        fn diagonal_walk_is_the_brute_force_cell_sequence(o in start(), d in direction(), t_end in 0.5f64..40.0) {
            let visits: Vec<Visit<2>> = Walk::new(o, d, Corner::Diagonal)
                .take_while(|v| v.t_in < t_end)
                .collect();
            // Tiled: each entry is the previous exit; steps of one cell per axis at most.
            for w in visits.windows(2) {
                prop_assert_eq!(w[1].t_in, w[0].t_out);
                prop_assert!(w[0].t_out >= w[0].t_in);
                prop_assert!((0..2).all(|a| (w[1].cell[a] - w[0].cell[a]).abs() <= 1));
            }
            // The cells with positive length are exactly the brute-force ones (the brute force
            // merges crossings closer than 1e-7, as the walk merges corners).
            let got: Vec<[i64; 2]> = visits
                .iter()
                .filter(|v| v.t_out.min(t_end) - v.t_in > 1e-7)
                .map(|v| v.cell)
                .collect();
            prop_assert_eq!(got, brute(o, d, t_end));
        }

        #[test]
        fn touching_walk_is_the_diagonal_walk_plus_zero_length_side_cells(o in start(), d in direction()) {
            let diag: Vec<[i64; 2]> = cells(Walk::new(o, d, Corner::Diagonal), 50);
            let touch: Vec<Visit<2>> = Walk::new(o, d, Corner::Touching).take(150).collect();
            let long: Vec<[i64; 2]> = touch.iter().filter(|v| v.t_out > v.t_in || v.t_out == f64::INFINITY).map(|v| v.cell).collect();
            prop_assert_eq!(&long[..long.len().min(50)], &diag[..long.len().min(50)]);
            // Every side cell is 4-adjacent to the cell before it and to the next long cell.
            for (k, v) in touch.iter().enumerate() {
                let Some(next) = touch[k..].iter().find(|x| x.t_out > x.t_in) else {
                    break; // the last corner's diagonal cell is past the 150 taken
                };
                if v.t_in == v.t_out {
                    let prev = touch[..k].iter().rev().find(|x| x.t_out > x.t_in || x.t_in == 0.0).unwrap();
                    let dist = |a: [i64; 2], b: [i64; 2]| (a[0] - b[0]).abs() + (a[1] - b[1]).abs();
                    prop_assert_eq!(dist(v.cell, next.cell), 1);
                    prop_assert_eq!(dist(v.cell, prev.cell), 1);
                }
            }
        }

        #[test]
        fn exact_walk_is_the_sorted_crossings_and_cell_at_of_its_times(o in start(), d in direction(), t_end in 0.5f64..40.0) {
            let visits: Vec<Visit<2>> = Walk::new(o, d, Corner::Exact)
                .take_while(|v| v.t_in < t_end)
                .collect();
            let got: Vec<([i64; 2], f64)> = visits.iter().map(|v| (v.cell, v.t_in)).collect();
            prop_assert_eq!(got, brute_exact(o, d, t_end));
            for w in visits.windows(2) {
                prop_assert_eq!(w[1].t_in, w[0].t_out);
                prop_assert!(w[0].t_out > w[0].t_in || w[0].t_in == 0.0);
            }
            for v in &visits {
                for a in 0..2 {
                    prop_assert_eq!(v.cell[a], cell_at(o[a], d[a], v.t_in, 1, 0));
                }
            }
        }

        #[test]
        fn exact_walks_resumed_or_coarse_agree_with_the_fine_walk(
            o in start(), d in direction(), k in 0usize..40, scale in 1i64..6
        ) {
            let fine: Vec<Visit<2>> = Walk::new(o, d, Corner::Exact).take(120).collect();
            let k = k.min(fine.len() - 1);
            let t = fine[k].t_in;
            // Resumed at (cell_at(t), t), at any scale: the fine walk from visit k, grouped.
            let cell = std::array::from_fn(|a| cell_at(o[a], d[a], t, scale, 0));
            let want = group(&fine[k..], scale);
            let got: Vec<Visit<2>> = Walk::resume(o, d, Corner::Exact, scale, cell, t)
                .take(want.len() - 1)
                .collect();
            // (the last group may continue past the 120 fine visits taken)
            prop_assert_eq!(&got[..], &want[..want.len() - 1]);
            if scale == 1 {
                prop_assert_eq!(cell, fine[k].cell);
            }
        }

        #[test]
        fn a_walk_placed_at_t_is_the_walk_resumed_in_the_cell_at_t(
            o in start(), d in direction(), t in 0.0f64..50.0, scale in 1i64..9,
            guess in prop::array::uniform2(-400i64..400)
        ) {
            let cell = [cell_at(o[0], d[0], t, scale, 0), cell_at(o[1], d[1], t, scale, 0)];
            let want: Vec<Visit<2>> = Walk::resume(o, d, Corner::Exact, scale, cell, t).take(20).collect();
            let got: Vec<Visit<2>> = ExactWalk::at(o, d, scale, t, guess).take(20).collect();
            prop_assert_eq!(got, want);
        }

        #[test]
        fn cell_at_is_the_cell_between_crossed_and_uncrossed_boundaries(
            o in -50.0f64..50.0, d in -3.0f64..3.0, t in 0.0f64..100.0, guess in -400i64..400,
            scale in 1i64..6
        ) {
            let k = cell_at(o, d, t, scale, guess);
            prop_assert_eq!(k, cell_at(o, d, t, scale, 0));
            let (lo, hi) = (cross(o, d, k * scale), cross(o, d, (k + 1) * scale));
            if d > 0.0 {
                prop_assert!(lo <= t && hi > t);
            } else if d < 0.0 {
                prop_assert!(hi <= t && lo > t);
            } else {
                prop_assert_eq!(k, (o.floor() as i64).div_euclid(scale));
            }
            // At t = 0 it is the walk's start cell.
            if scale == 1 {
                prop_assert_eq!(cell_at(o, d, 0.0, 1, guess), Walk::new([o], [d], Corner::Exact).position().0[0]);
            }
        }

        #[test]
        fn reversed_segment_visits_the_same_cells_backwards(o in start(), d in direction(), t_end in 0.5f64..30.0) {
            let end = [o[0] + d[0] * t_end, o[1] + d[1] * t_end];
            let fwd: Vec<[i64; 2]> = Walk::new(o, d, Corner::Diagonal)
                .take_while(|v| v.t_in < t_end)
                .filter(|v| v.t_out.min(t_end) - v.t_in > 1e-6)
                .map(|v| v.cell)
                .collect();
            let mut back: Vec<[i64; 2]> = Walk::new(end, [-d[0], -d[1]], Corner::Diagonal)
                .take_while(|v| v.t_in < t_end)
                .filter(|v| v.t_out.min(t_end) - v.t_in > 1e-6)
                .map(|v| v.cell)
                .collect();
            back.reverse();
            prop_assert_eq!(fwd, back);
        }
    }
}
