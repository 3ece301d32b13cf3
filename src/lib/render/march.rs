//! Stepping one ray through the max-Z hierarchy (the patent's stepping loop).
//!
//! Every column is solid from −∞ up to its cell's `max_z` (NaN = no column). A ray hits a
//! level-0 cell when its lowest height while crossing the cell, `min(z(t_in), z(t_out))`, is at
//! or below the cell's `max_z`: on a wall if it enters the cell already below the top, else on
//! the top where `z(t) = max_z`.
//!
//! Hierarchical traversal starts at the coarsest level. A coarse cell whose `max_z` is below the
//! ray over the whole crossing is skipped in one step; otherwise the ray descends a level at the
//! same `t`; after a step it climbs back to the coarsest level whose cell changed. Level 0 uses
//! the exact boundary crossings of [`super::ray`].
//!
//! Invariant (exactness): the level-0 hit test is a pure function of the cell, and a coarse
//! skip is conservative (a coarse `max_z` is the max of its block and `z(t)` is monotone, so the
//! coarse test over a crossing that contains a child's crossing passes whenever the child's
//! does). So without range thresholds the hierarchy finds exactly the hit of level-0 stepping,
//! bit for bit ([`Traversal::Level0`] runs the same loop with one level).

use super::ray::Ray;
use super::sampler::Sampler;
use crate::error::Result;

/// How rays step through the levels.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Traversal {
    /// Coarse steps through empty space, descending where the ray may hit.
    Hierarchical,
    /// Level-0 cell-by-cell stepping only (the reference; slow).
    Level0,
}

/// Which face of a column a ray hit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Face {
    /// The top, `z = max_z`.
    Top,
    /// A wall facing along the column axis (east or west for north-up grids).
    WallU,
    /// A wall facing along the row axis (north or south).
    WallV,
}

/// Where a ray stopped.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Hit {
    /// Range from the eye, metres.
    pub t: f64,
    /// Colour of the cell that terminated the ray (a coarse level's average under range thresholds).
    pub colour: [u8; 4],
    /// Face hit.
    pub face: Face,
    /// Level whose colour was used.
    pub level: usize,
}

/// The part of the ray inside the database box: `[t0, t1)` metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Span {
    /// Range where the ray enters the box (0 when the eye is inside).
    pub t0: f64,
    /// Range where the ray leaves the box (or stops looking).
    pub t1: f64,
}

/// What the marcher needs to know about the levels.
#[derive(Debug, Clone)]
pub struct Plan {
    /// Traversal strategy.
    pub traversal: Traversal,
    /// Levels usable, `0 ..= top` (all levels, or those that tile the plane when repeating).
    pub top: usize,
    /// Width of a level-`k` cell in level-0 cells: `factor^k`.
    pub scales: Vec<i64>,
    /// Range thresholds `TH_k` per level, metres (`None`: no level of detail).
    pub thresholds: Option<Vec<f64>>,
}

/// Result of one ray: the hit, if any, and the number of cells visited.
pub type Marched = (Option<Hit>, u64);

#[inline]
fn may_hit(ray: &Ray, t: f64, t_far: f64, max_z: f32) -> bool {
    !max_z.is_nan() && ray.z(t).min(ray.z(t_far)) <= max_z as f64
}

/// The hit of level-0 cell `(c, r)`, if the ray hits its column within `span`: pure in the cell.
#[inline]
fn level0_hit(ray: &Ray, span: Span, c: i64, r: i64, max_z: f32) -> Option<(f64, Face)> {
    let (eu, ev) = (ray.u.entry(c), ray.v.entry(r));
    let (t_in, face) = if eu >= ev && eu >= span.t0 {
        (eu, Face::WallU)
    } else if ev >= span.t0 {
        (ev, Face::WallV)
    } else {
        (span.t0, Face::Top)
    };
    let t_out = ray.u.exit(c, 1).min(ray.v.exit(r, 1)).min(span.t1);
    if !may_hit(ray, t_in, t_out, max_z) {
        return None;
    }
    let mz = max_z as f64;
    if ray.z(t_in) <= mz {
        Some((t_in, face))
    } else {
        let t = ray.time_at_height(mz).unwrap_or(t_in).max(t_in).min(t_out);
        Some((t, Face::Top))
    }
}

/// Step `ray` through `span` of the tile set behind `sampler`.
pub fn march(ray: &Ray, span: Span, sampler: &mut Sampler, plan: &Plan) -> Result<Marched> {
    let top = match plan.traversal {
        Traversal::Hierarchical => plan.top,
        Traversal::Level0 => 0,
    };
    let mut t = span.t0;
    let mut c = ray.u.cell_at(t, ray.u.o.floor() as i64);
    let mut r = ray.v.cell_at(t, ray.v.o.floor() as i64);
    let mut l = top;
    let mut face = Face::Top;
    let mut steps = 0u64;
    loop {
        steps += 1;
        let s = plan.scales[l];
        let (cc, rr) = (c.div_euclid(s), r.div_euclid(s));
        let Some(cell) = sampler.cell(l, cc, rr)? else {
            return Ok((None, steps));
        };
        let exit_u = ray.u.exit(cc, s);
        let t_exit = exit_u.min(ray.v.exit(rr, s));
        if l == 0 {
            if let Some((t_hit, f)) = level0_hit(ray, span, c, r, cell.max_z) {
                let hit = Hit { t: t_hit, colour: cell.colour, face: f, level: 0 };
                return Ok((Some(coarse_colour(hit, c, r, sampler, plan)?), steps));
            }
        } else if may_hit(ray, t, t_exit.min(span.t1), cell.max_z) {
            if let Some(th) = &plan.thresholds {
                let mz = cell.max_z as f64;
                let (tc, fc) = if ray.z(t) <= mz {
                    (t, face)
                } else {
                    (ray.time_at_height(mz).unwrap_or(t).max(t).min(t_exit.min(span.t1)), Face::Top)
                };
                if tc > th[l] {
                    return Ok((Some(Hit { t: tc, colour: cell.colour, face: fc, level: l }), steps));
                }
            }
            l -= 1;
            continue;
        }
        if t_exit >= span.t1 {
            return Ok((None, steps));
        }
        face = if exit_u == t_exit { Face::WallU } else { Face::WallV };
        let (oc, or) = (c, r);
        t = t_exit;
        c = ray.u.cell_at(t, c);
        r = ray.v.cell_at(t, r);
        while l < top {
            let s2 = plan.scales[l + 1];
            if oc.div_euclid(s2) == c.div_euclid(s2) && or.div_euclid(s2) == r.div_euclid(s2) {
                break;
            }
            l += 1;
        }
    }
}

/// Under level-0 traversal with range thresholds, recolour a level-0 hit with the coarsest
/// level whose threshold its range exceeds (the hierarchical traversal stops at that level).
fn coarse_colour(hit: Hit, c: i64, r: i64, sampler: &mut Sampler, plan: &Plan) -> Result<Hit> {
    let (Traversal::Level0, Some(th)) = (plan.traversal, &plan.thresholds) else {
        return Ok(hit);
    };
    let Some(l) = (1..=plan.top).rev().find(|&l| hit.t > th[l]) else {
        return Ok(hit);
    };
    let s = plan.scales[l];
    Ok(match sampler.cell(l, c.div_euclid(s), r.div_euclid(s))? {
        Some(cell) => Hit { colour: cell.colour, level: l, ..hit },
        None => hit,
    })
}
