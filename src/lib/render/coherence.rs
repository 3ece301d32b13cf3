//! Column coherence (the patent's vertical scan lines): a ray starts where the rays below it in
//! the same vertical plane prove it cannot have hit anything yet.
//!
//! When the camera has zero roll and pitch, the rays of one image column lie in one vertical
//! half-plane through the eye and share one horizontal direction, so they cross the same cells
//! at the same horizontal distances; a ray B above a ray A is above A at every one of them. The
//! column is marched bottom-up with one [`Coherence`] record, which each ray reads before it
//! starts and writes while it steps.
//!
//! Invariant (exactness): let X be the cell [`Coherence::start`] picks for ray B. The traversal
//! from the eye ([`super::march::march`] without coherence) of B has no hit before X's entry,
//! and every coarse cell B would descend into before X and around X's entry is one the rays
//! below descended into. Then B's march restarted at X's entry returns the same hit, bit for
//! bit: cells entered at X's entry are tested over the same crossings as from the eye, and a
//! coarse cell holding X's entry is tested over the rest of its crossing, which skips it
//! exactly when the whole crossing would have produced no hit, and cannot stop the ray on its
//! coarse top because its range there is below the level's threshold (else the cell itself
//! would be X). The restart steps the finest level at which no coarser cell around X's entry
//! could stop B on its top ([`restart_level`]; level 0 without range thresholds): a coarse cell
//! it does not test as a whole is one B would either descend into or skip, and the finer cells
//! of a skipped one are skipped too. X is the earliest of:
//! * the **barrier** of the ray below (the first cell it could not vouch for): its hit or last
//!   cell, a voxel column it passed under or through (a floating run it cleared can stop B), a
//!   cell it cleared by less than [`CLOSE_CALL`] (rounding could put B below it), a step within
//!   [`NEAR_CORNER`] of a cell corner (B, whose direction differs from A's by rounding, may
//!   take the corner the other way and meet a side cell A never tested);
//! * with range thresholds, the first coarse cell the rays below descended into whose exit is,
//!   at B's range, far enough for the level's colour to count ([`super::march::blend_weight`]
//!   above 0): B, reaching it at a longer range than A, may stop on its top where A went down.
//!
//! A coarse cell B may hit is a cell A may hit (A is lower), and A, having no hit before its
//! barrier, either descended into it — it is in the list — or skipped its parent, which B then
//! skips too. So the invariant carries from ray to ray up the column.

use super::march::{blend_weight, Face, Plan, Span};
use super::ray::Ray;

/// Relative gap in time under which a step counts as passing a cell corner: many orders above
/// the rounding by which two rays of one image column differ in direction (a few ulps), many
/// below any gap a real ray path makes.
pub const NEAR_CORNER: f64 = 1e-9;

/// Clearance over a cell's top, relative to the heights involved (`1 + |z0| + |z|` metres),
/// under which a ray that passed over the cell does not vouch for the rays above it.
pub const CLOSE_CALL: f64 = 1e-9;

/// Whether a ray that is at least `lo` metres high over a cell whose top is `max_z` passed it by
/// less than [`CLOSE_CALL`] (or not at all); false for a cell without data.
#[inline]
pub fn close_call(ray: &Ray, lo: f64, max_z: f32) -> bool {
    lo - max_z as f64 <= CLOSE_CALL * (1.0 + ray.z0.abs() + lo.abs())
}

/// What the rays already marched up one image column prove about the next ray up.
#[derive(Debug, Default, Clone)]
pub struct Coherence {
    /// The first cell `(level, [column, row])` the rays below could not vouch for; `None`
    /// before the column's first ray and while a ray is still looking for it.
    barrier: Option<(usize, [i64; 2])>,
    /// Per level, the coarse cells the rays below descended into before the barrier, in path
    /// order (only kept with range thresholds).
    descended: Vec<Vec<[i64; 2]>>,
}

/// Where a ray's march begins.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Start {
    /// At the start of its span, as without coherence.
    Span,
    /// At range `t` metres, entering a cell through `face`, stepping cells of `level`.
    At(f64, Face, usize),
    /// Nowhere: its span ends before the first cell it could hit.
    Nothing,
}

impl Coherence {
    /// Where `ray`, the next ray up the column, begins, and the record made ready for it to
    /// write.
    pub fn start(&mut self, ray: &Ray, span: Span, plan: &Plan) -> Start {
        self.descended.resize(plan.top + 1, Vec::new());
        let Some((level, cell)) = self.barrier else {
            return self.restart_at_span();
        };
        let entry = |l: usize, [c, r]: [i64; 2]| {
            let s = plan.scales[l];
            let (eu, ev) = (ray.u.entry(c, s), ray.v.entry(r, s));
            if eu >= ev {
                (eu, Face::WallU)
            } else {
                (ev, Face::WallV)
            }
        };
        let mut at = entry(level, cell);
        if let Some(th) = &plan.thresholds {
            for (l, cells) in self.descended.iter().enumerate().skip(1) {
                let s = plan.scales[l];
                // Exits along the path are non-decreasing, and so is the blend weight: when the
                // last cell is safe, all are (the usual case, one test).
                let safe = |&[c, r]: &[i64; 2]| {
                    blend_weight(ray.u.exit(c, s).min(ray.v.exit(r, s)), th[l], plan.blend) == 0.0
                };
                if cells.last().is_none_or(safe) {
                    continue;
                }
                let risky = cells[cells.partition_point(safe)];
                let e = entry(l, risky);
                if e.0 < at.0 {
                    at = e;
                }
            }
        }
        if at.0 >= span.t1 {
            return Start::Nothing; // the record stands for the next ray
        }
        if at.0 <= span.t0 {
            return self.restart_at_span();
        }
        // Forget the cells entered at or after the restart (usually none or a few at the end).
        for (l, cells) in self.descended.iter_mut().enumerate() {
            while cells.last().is_some_and(|&c| entry(l, c).0 >= at.0) {
                cells.pop();
            }
        }
        self.barrier = None;
        Start::At(at.0, at.1, restart_level(ray, at.0, plan))
    }

    fn restart_at_span(&mut self) -> Start {
        self.barrier = None;
        self.descended.iter_mut().for_each(Vec::clear);
        Start::Span
    }

    /// Whether the ray being marched is still looking for its barrier (records are wanted).
    #[inline]
    pub fn recording(&self) -> bool {
        self.barrier.is_none()
    }

    /// The ray being marched cannot vouch for cell `cell` of `level` (nor anything after it);
    /// only the first such cell counts.
    #[inline]
    pub fn barrier(&mut self, level: usize, cell: [i64; 2]) {
        self.barrier.get_or_insert((level, cell));
    }

    /// The ray being marched descended into coarse cell `cell` of `level` before its barrier
    /// (call only while [`Coherence::recording`]).
    #[inline]
    pub fn descended(&mut self, level: usize, cell: [i64; 2]) {
        debug_assert!(
            self.recording(),
            "descents after the barrier are not needed"
        );
        let cells = &mut self.descended[level];
        if cells.last() != Some(&cell) {
            cells.push(cell);
        }
    }
}

/// The level a ray restarted at range `t` steps from: the finest one below every level whose
/// cell around `t` the ray might leave far enough away for that level's colour to count (where
/// the march from the eye could stop on a coarse top). Finer is exact (coarse cells around `t`
/// that the ray would skip whole have no cell the ray may hit) and saves the descent; the bound
/// on a level-`k` cell's exit, `t + f^k / max(|du|, |dv|)` widened by 1e-9, is never below the
/// true one. Without range thresholds, level 0.
fn restart_level(ray: &Ray, t: f64, plan: &Plan) -> usize {
    let Some(th) = &plan.thresholds else {
        return 0;
    };
    let per_cell = 1.0 / ray.u.d.abs().max(ray.v.d.abs()); // metres per cell on the major axis
    (1..=plan.top)
        .rev()
        .find(|&k| {
            let exit = (t + plan.scales[k] as f64 * per_cell) * (1.0 + 1e-9);
            blend_weight(exit, th[k], plan.blend) > 0.0
        })
        .unwrap_or(0)
}
