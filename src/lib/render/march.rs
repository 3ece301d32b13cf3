//! Stepping one ray through the max-Z hierarchy (the patent's stepping loop).
//!
//! A level-0 column is solid from −∞ up to its cell's `max_z` (NaN = no column), except a
//! partial cell (`state` 1), whose column is the solid runs of its voxel column
//! ([`crate::voxel::columns`]): the ground run from −∞, then floating runs with gaps between. A
//! ray hits a run when its heights while crossing the cell, `z(t_in) .. z(t_out)`, overlap the
//! run's: on the wall it enters through if it enters within the run's heights, else on the
//! run's top (falling) or its underside (rising) where `z(t)` reaches it. The first run met
//! wins; a ray that meets none passes under the overhang or through the hole, on to the ground
//! in the same cell or the next cells. A partial cell's `max_z` is its last run's top, so the
//! `may_hit` bound below holds for every cell.
//!
//! Hierarchical traversal starts at the coarsest level. A coarse cell whose `max_z` is below the
//! ray over the whole crossing is skipped in one step; otherwise the ray descends a level at the
//! same `t`; after a step it climbs back to the coarsest level whose cell changed.
//!
//! Stepping, at every level, is the crate's one grid walk under the exact corner rule,
//! [`ExactWalk`]: a level-`k` walk has cells `f^k` level-0 cells wide and crosses boundary `K` at
//! `cross(o, d, K · f^k)` ([`crate::walk::cross`]), so a boundary shared by several levels is
//! crossed at the same f64 on each. **Corner rule:
//! [`Corner::Exact`](crate::walk::Corner::Exact).** Where the ray passes through a cell
//! corner — its two crossing times are the same f64 — it steps straight into the diagonal cell,
//! and the two side cells are not visited (they touch the ray at one point). A ray a few ulps
//! off a corner visits the side cell it clips, for the tiny time it is in it;
//! there is no [`crate::walk::CORNER_EPS`] tolerance, because the tolerant rules are
//! path-dependent (a ray grazing a boundary line is stepped across it at the first crossing of
//! another axis, and a coarse walk sees fewer crossings than a fine one). Under `Exact` the cell
//! at `t` on each level is [`crate::walk::cell_at`], whatever the path, so descending and
//! climbing at `t` land where a level-0 walk is at `t`.
//!
//! Invariant (exactness): the level-0 hit test is a pure function of the cell, and a coarse
//! skip is conservative (a coarse `max_z` is the max of its block and `z(t)` is monotone, so the
//! coarse test over a crossing that contains a child's crossing passes whenever the child's
//! does). So without range thresholds the hierarchy finds exactly the hit of level-0 stepping,
//! bit for bit ([`Traversal::Level0`] runs the same loop with one level). A coarse cell's stop
//! under range thresholds (`coarse_test`) is a pure function of the cell too (its entry face is
//! the cell's own, not the finer walk's last step), so any traversal that tests a ray on the same
//! cells finds the same hit: that is what lets [`super::column`] march a whole image column at
//! once.

use super::ray::Ray;
use super::regions::{self, Entered};
use super::sampler::Sampler;
use crate::error::Result;
use crate::tiles::{Cell, STATE_PARTIAL};
use crate::voxel::columns::Run;
use crate::walk::{ExactWalk, Visit};

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
    /// The underside of a floating voxel run (a ray rising under an overhang).
    Bottom,
    /// The side of a column that rises less than one cell width above the neighbour the ray
    /// came from: the stair step of a sampled slope, not a wall (drawn like a top).
    Step,
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

/// The part of the ray worth stepping: `τ ∈ [t0, t1)` (the ray's parameter, [`super::ray`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Span {
    /// Where the ray enters the box (0 when the eye is inside).
    pub t0: f64,
    /// Where the ray leaves the box (or stops looking).
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
    /// Blend the colours of two levels around each range threshold (Cohen-Or's soft
    /// transition, see [`blend_weight`]) instead of switching at it.
    pub blend: bool,
    /// Width of a level-0 cell along the column and row axes, metres: a column side that rises
    /// less than its cell's width above the neighbour the ray came from is a [`Face::Step`].
    pub cell_m: [f64; 2],
}

/// Width of each level's cells in level-0 cells, finest first: `factor^k`.
pub fn level_scales(info: &crate::tiles::TileSetInfo) -> Vec<i64> {
    (0..info.levels.len())
        .map(|k| (info.factor as i64).pow(k as u32))
        .collect()
}

impl Plan {
    /// The plan for stepping the levels `0 ..= top` of the tile set `info` with `traversal`,
    /// blending or not, and with range thresholds (`lod`) for pixels `per_pixel` radians wide:
    /// `TH_k` = level `k`'s widest cell side, metres, over the pixel's angle.
    pub fn of_levels(
        info: &crate::tiles::TileSetInfo,
        top: usize,
        traversal: Traversal,
        lod: bool,
        blend: bool,
        per_pixel: f64,
    ) -> Plan {
        let t = &info.grid.transform;
        let cell_m = [t.cell_x.abs(), t.cell_y.abs()];
        let widest = cell_m[0].max(cell_m[1]);
        let scales = level_scales(info);
        Plan {
            traversal,
            top,
            thresholds: lod.then(|| {
                (scales.iter())
                    .map(|&s| s as f64 * widest / per_pixel)
                    .collect()
            }),
            scales,
            blend,
            cell_m,
        }
    }

    /// Level-`l − 1` cells along each axis of a level-`l` cell (`l ≥ 1`): the pyramid's factor.
    #[inline]
    pub(super) fn children(&self, l: usize) -> i64 {
        self.scales[l] / self.scales[l - 1]
    }
}

/// Result of one ray: the hit, if any, and the number of cells visited.
pub type Marched = (Option<Hit>, u64);

/// The lowest height of the ray over `[t, t_far]`, metres.
#[inline]
pub(super) fn lowest(ray: &Ray, t: f64, t_far: f64) -> f64 {
    ray.z(t).min(ray.z(t_far))
}

/// Whether a ray whose lowest height over a cell is `lo` metres may hit the cell's column.
#[inline]
pub(super) fn may_hit(lo: f64, max_z: f32) -> bool {
    !max_z.is_nan() && lo <= max_z as f64
}

/// The hit of level-0 cell `(c, r)` within `span`, if the ray hits its column: a solid column
/// up to `max_z`, or for a partial cell the solid `runs` of its voxel column (ground run from
/// `−inf` first). Returns the time `τ` of the hit, the face and the index of the run hit (0
/// for a solid column). A pure function of the cell.
#[inline]
fn level0_hit(
    ray: &Ray,
    span: Span,
    c: i64,
    r: i64,
    max_z: f32,
    runs: Option<&[Run]>,
) -> Option<(f64, Face, usize)> {
    let (t_in, face) = entry(ray, span, c, r, 1);
    let t_out = ray.u.exit(c, 1).min(ray.v.exit(r, 1)).min(span.t1);
    if !may_hit(lowest(ray, t_in, t_out), max_z) {
        return None;
    }
    match runs {
        None => {
            run_hit(ray, t_in, face, t_out, f64::NEG_INFINITY, max_z as f64).map(|(t, f)| (t, f, 0))
        }
        // z is monotone along the ray, so the earliest entry over the runs is the first run met.
        Some(runs) => runs
            .iter()
            .enumerate()
            .filter_map(|(k, run)| {
                run_hit(ray, t_in, face, t_out, run.bottom as f64, run.top as f64)
                    .map(|(t, f)| (t, f, k))
            })
            .min_by(|a, b| a.0.total_cmp(&b.0)),
    }
}

/// Where the ray, crossing a cell over `[t_in, t_out]` (entering through `face`), first meets
/// the solid run `bottom ..= top` metres: on the entry face when it enters inside the run's
/// heights, else on the run's top (falling) or bottom (rising) if it reaches it in the cell.
#[inline]
fn run_hit(
    ray: &Ray,
    t_in: f64,
    face: Face,
    t_out: f64,
    bottom: f64,
    top: f64,
) -> Option<(f64, Face)> {
    let (z_in, z_out) = (ray.z(t_in), ray.z(t_out));
    if z_in.min(z_out) > top || z_in.max(z_out) < bottom {
        return None;
    }
    let at = |z: f64| ray.time_at_height(z).unwrap_or(t_in).max(t_in).min(t_out);
    if z_in > top {
        Some((at(top), Face::Top))
    } else if z_in < bottom {
        Some((at(bottom), Face::Bottom))
    } else {
        Some((t_in, face))
    }
}

/// What a ray's test of one coarse cell decides.
pub(super) enum Coarse {
    /// The ray passes over the whole cell (its lowest height there is above the cell's top).
    Skip,
    /// The ray may hit the cell's column and needs the finer level.
    Descend,
    /// The ray stops on the cell's top or wall, taking its average colour (range thresholds).
    Stop(Hit),
}

/// The entry of the ray into cell `(c, r)` of a level whose cells are `s` level-0 cells wide,
/// within `span`: the time `τ` and the face it enters through (the later of its two entry
/// crossings; [`Face::Top`] where the span starts inside the cell). A pure function of the cell.
#[inline]
fn entry(ray: &Ray, span: Span, c: i64, r: i64, s: i64) -> (f64, Face) {
    let (eu, ev) = (ray.u.entry(c, s), ray.v.entry(r, s));
    if eu >= ev && eu >= span.t0 {
        (eu, Face::WallU)
    } else if ev >= span.t0 {
        (ev, Face::WallV)
    } else {
        (span.t0, Face::Top)
    }
}

/// Test `ray` against coarse cell `cell` (`(cc, rr)` of level `l`), which a walk visits over
/// `τ ∈ [t_in, t_out]`: skip, descend or (past the level's range threshold) stop. A pure
/// function of the ray, its span and the cell: `t_in` is the cell's entry crossing or where a
/// walk started in it, and the ray's own time there is `max(t_in, span.t0)`.
#[allow(clippy::too_many_arguments)]
#[inline]
pub(super) fn coarse_test(
    ray: &Ray,
    span: Span,
    l: usize,
    [cc, rr]: [i64; 2],
    [t_in, t_out]: [f64; 2],
    cell: &Cell,
    sampler: &mut Sampler,
    plan: &Plan,
) -> Result<Coarse> {
    let t = t_in.max(span.t0);
    let t_far = t_out.min(span.t1);
    if !may_hit(lowest(ray, t, t_far), cell.max_z) {
        return Ok(Coarse::Skip);
    }
    let Some(th) = &plan.thresholds else {
        return Ok(Coarse::Descend);
    };
    // The stop below would be at or before `t_out` (the cell's entry is at or before the
    // visit's start, which the ray's span overlaps), so at most this range: within the
    // threshold, the level's colour would not be taken whole (blend weight at most ½).
    if ray.range(t_out) <= th[l] {
        return Ok(Coarse::Descend);
    }
    coarse_stop(ray, span, l, [cc, rr], t_far, th[l], cell, sampler, plan)
}

/// The rest of [`coarse_test`] for a ray that may hit the cell's column past the level's range
/// threshold `th` (`t_far`: the end of the visit within the span): the cell's hit, or descend
/// where its blend weight is not 1. Out of line: most coarse tests end before it.
#[allow(clippy::too_many_arguments)]
#[inline(never)]
fn coarse_stop(
    ray: &Ray,
    span: Span,
    l: usize,
    [cc, rr]: [i64; 2],
    t_far: f64,
    th: f64,
    cell: &Cell,
    sampler: &mut Sampler,
    plan: &Plan,
) -> Result<Coarse> {
    let s = plan.scales[l];
    let mz = cell.max_z as f64;
    let (te, fe) = entry(ray, span, cc, rr, s);
    let (tc, fc) = if ray.z(te) <= mz {
        (te, fe)
    } else {
        let at = ray.time_at_height(mz).unwrap_or(te);
        (at.max(te).min(t_far), Face::Top)
    };
    let range = ray.range(tc);
    if blend_weight(range, th, plan.blend) != 1.0 {
        return Ok(Coarse::Descend);
    }
    let face = step_or_wall(fc, ray, l, [cc, rr], cell.max_z, sampler, plan)?;
    let hit = Hit {
        t: range,
        colour: cell.colour,
        face,
        level: l,
    };
    Ok(Coarse::Stop(blend_parent(
        hit,
        cc * s,
        rr * s,
        sampler,
        plan,
    )?))
}

/// Test `ray` against level-0 cell `(cc, rr)`, whose tile value is `cell`: its hit, coloured
/// (the run's colour, a step or a wall, a coarse level's colour or a blend as the plan says),
/// or `None`. A pure function of the ray, its span and the cell.
pub(super) fn level0_test(
    ray: &Ray,
    span: Span,
    [cc, rr]: [i64; 2],
    cell: &Cell,
    sampler: &mut Sampler,
    plan: &Plan,
) -> Result<Option<Hit>> {
    let runs = if cell.state == STATE_PARTIAL {
        Some(sampler.column(cc, rr)?)
    } else {
        None
    };
    let Some((t_hit, f, k)) = level0_hit(ray, span, cc, rr, cell.max_z, runs) else {
        return Ok(None); // passed over the top, under a floating run or through a gap
    };
    let (colour, top) = match runs {
        Some(runs) => (runs[k].colour, runs[k].top),
        None => (cell.colour, cell.max_z),
    };
    // Only the ground run of a voxel column can be a step; floating runs are objects.
    let face = match k {
        0 => step_or_wall(f, ray, 0, [cc, rr], top, sampler, plan)?,
        _ => f,
    };
    let hit = Hit {
        t: ray.range(t_hit),
        colour,
        face,
        level: 0,
    };
    let hit = coarse_colour(hit, cc, rr, sampler, plan)?;
    Ok(Some(blend_parent(hit, cc, rr, sampler, plan)?))
}

/// The levels a traversal steps: `0 ..= top`.
pub(super) fn top_level(plan: &Plan) -> usize {
    match plan.traversal {
        Traversal::Hierarchical => plan.top,
        Traversal::Level0 => 0,
    }
}

/// A walk over level-`l` cells starting at `τ = t` in the cell holding the ray then (`guess`:
/// a nearby cell index of that level).
pub(super) fn walk_from(ray: &Ray, plan: &Plan, l: usize, t: f64, guess: [i64; 2]) -> ExactWalk<2> {
    let (o, d) = ([ray.u.o, ray.v.o], [ray.u.d, ray.v.d]);
    ExactWalk::at(o, d, plan.scales[l], t, guess)
}

/// The level-`l` cell of the eye (a guess for [`walk_from`]).
pub(super) fn eye_cell(ray: &Ray, plan: &Plan, l: usize) -> [i64; 2] {
    let s = plan.scales[l];
    [
        (ray.u.o.floor() as i64).div_euclid(s),
        (ray.v.o.floor() as i64).div_euclid(s),
    ]
}

/// Step `ray` through `span` of the tile set behind `sampler`.
///
/// Every level is stepped by one [`ExactWalk`] over that level's cells
/// ([`Corner::Exact`](crate::walk::Corner::Exact): crossing times `cross(o, d, K · f^k)`, the
/// same f64 at every level; through a corner where both crossings are the same f64 the ray
/// steps straight into the diagonal cell). Descending takes a finer walk up at the same `τ` in
/// [`crate::walk::cell_at`]; climbing takes a coarser one up in the parent of the cell just
/// entered, which is the cell `cell_at` gives there.
pub fn march(ray: &Ray, span: Span, sampler: &mut Sampler, plan: &Plan) -> Result<Marched> {
    let top = top_level(plan);
    let mut l = top;
    let mut w = walk_from(ray, plan, l, span.t0, eye_cell(ray, plan, l));
    let mut steps = 0u64;
    loop {
        steps += 1;
        let entered = w.stepped(); // the axes crossed into the cell visited next
        let Visit {
            cell: [cc, rr],
            t_in: t,
            t_out: t_exit,
        } = w.next().expect("a walk never ends by itself");
        let Some(cell) = sampler.cell(l, cc, rr)? else {
            return Ok((None, steps));
        };
        if l == 0 {
            // A cell over a region: the region's cells decide, unless only its cover is wanted.
            let region = match sampler.children.is_empty() {
                true => None,
                false => sampler.child_at(cc, rr),
            };
            let entered = match region {
                Some(k) => {
                    let child = &mut sampler.children[k];
                    regions::enter(ray, span, t, child, plan, &mut steps)?
                }
                None => Entered::Coarse,
            };
            match entered {
                Entered::Hit(hit) => return Ok((Some(hit), steps)),
                Entered::Passed(t_out) => {
                    if t_out >= span.t1 {
                        return Ok((None, steps));
                    }
                    // On in this tile set from where the ray left the region, at level 0.
                    w = walk_from(ray, plan, 0, t_out, [cc, rr]);
                    l = 0;
                    continue;
                }
                Entered::Left => {}
                Entered::Coarse => {
                    if let Some(hit) = level0_test(ray, span, [cc, rr], &cell, sampler, plan)? {
                        return Ok((Some(hit), steps));
                    }
                }
            }
        } else {
            match coarse_test(ray, span, l, [cc, rr], [t, t_exit], &cell, sampler, plan)? {
                Coarse::Stop(hit) => return Ok((Some(hit), steps)),
                Coarse::Descend => {
                    // Descend at the same τ, into the child holding the ray then.
                    let f = plan.children(l);
                    l -= 1;
                    w = w.descended(plan.scales[l], t, [cc * f, rr * f], entered);
                    continue;
                }
                Coarse::Skip => {}
            }
        }
        if t_exit >= span.t1 {
            return Ok((None, steps));
        }
        // Climb to the coarsest level whose cell changed with this step.
        let (mut old, mut new) = ([cc, rr], w.position().0);
        let l0 = l;
        while l < top {
            let f = plan.children(l + 1);
            let (po, pn) = (old.map(|k| k.div_euclid(f)), new.map(|k| k.div_euclid(f)));
            if po == pn {
                break;
            }
            (old, new) = (po, pn);
            l += 1;
        }
        if l != l0 {
            w.restart(plan.scales[l], new, t_exit);
        }
    }
}

/// A wall hit on the side of level-`level` cell `cell`, whose column top there is `top` metres,
/// as drawn: [`Face::Step`] when the top rises less than one cell width (along the wall's axis)
/// above the neighbour the ray entered from, else the wall. A neighbour outside the database or
/// without data leaves a wall (the database's cut edge). Other faces are returned unchanged.
fn step_or_wall(
    face: Face,
    ray: &Ray,
    level: usize,
    [c, r]: [i64; 2],
    top: f32,
    sampler: &mut Sampler,
    plan: &Plan,
) -> Result<Face> {
    let (from, width) = match face {
        Face::WallU => ([c - ray.u.d.signum() as i64, r], plan.cell_m[0]),
        Face::WallV => ([c, r - ray.v.d.signum() as i64], plan.cell_m[1]),
        _ => return Ok(face),
    };
    let width = width * plan.scales[level] as f64;
    Ok(match sampler.cell(level, from[0], from[1])? {
        Some(n) if (top as f64 - n.max_z as f64) < width => Face::Step,
        // A region's edge lies on its parent's surface (the seam): no cut edge there.
        None if sampler.seam_edges => Face::Step,
        _ => face,
    })
}

/// Blend band half-width around a range threshold, as a factor: level `k`'s colour takes over
/// from level `k − 1`'s between `TH_k / BLEND_BAND` and `TH_k · BLEND_BAND`.
pub const BLEND_BAND: f64 = std::f64::consts::SQRT_2;

/// How much of a level's colour a hit at range `t` takes against the finer level's, for the
/// level's range threshold `th`: without `blend` a switch at `th` (0 up to it, 1 beyond); with
/// it, linear in `log t` across `[th / BLEND_BAND, th · BLEND_BAND]` (½ at `th`, so the mean
/// switch stays where the pixel footprint puts it), 0 before and 1 after.
pub fn blend_weight(t: f64, th: f64, blend: bool) -> f64 {
    match blend {
        false => f64::from(u8::from(t > th)),
        true => (0.5 + (t / th).ln() / (2.0 * BLEND_BAND.ln())).clamp(0.0, 1.0),
    }
}

/// With blending, mix a hit's colour with its cell's parent's (level `hit.level + 1`) by
/// [`blend_weight`] of the parent's threshold; `(c, r)` is a level-0 cell under the hit's cell.
/// The face and range stay the hit's.
#[inline]
fn blend_parent(hit: Hit, c: i64, r: i64, sampler: &mut Sampler, plan: &Plan) -> Result<Hit> {
    let (true, Some(th)) = (plan.blend, &plan.thresholds) else {
        return Ok(hit);
    };
    let up = hit.level + 1;
    if up > plan.top {
        return Ok(hit);
    }
    let w = blend_weight(hit.t, th[up], true);
    if w == 0.0 {
        return Ok(hit);
    }
    let s = plan.scales[up];
    Ok(match sampler.cell(up, c.div_euclid(s), r.div_euclid(s))? {
        Some(parent) if parent.colour[3] > 0 => Hit {
            colour: std::array::from_fn(|k| {
                let (a, b) = (hit.colour[k] as f64, parent.colour[k] as f64);
                super::sky::channel(a + (b - a) * w)
            }),
            ..hit
        },
        _ => hit,
    })
}

/// Under level-0 traversal with range thresholds, recolour a level-0 hit with the coarsest
/// level whose colour it takes whole ([`blend_weight`] 1; the hierarchical traversal stops at
/// that level).
#[inline]
fn coarse_colour(hit: Hit, c: i64, r: i64, sampler: &mut Sampler, plan: &Plan) -> Result<Hit> {
    let (Traversal::Level0, Some(th)) = (plan.traversal, &plan.thresholds) else {
        return Ok(hit);
    };
    let Some(l) = (1..=plan.top)
        .rev()
        .find(|&l| blend_weight(hit.t, th[l], plan.blend) == 1.0)
    else {
        return Ok(hit);
    };
    let s = plan.scales[l];
    Ok(match sampler.cell(l, c.div_euclid(s), r.div_euclid(s))? {
        Some(cell) => Hit {
            colour: cell.colour,
            level: l,
            ..hit
        },
        None => hit,
    })
}
