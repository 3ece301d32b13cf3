//! Column coherence (the patent's vertical scan lines): all the rays of one image column
//! marched by one walk.
//!
//! With zero roll and pitch an image column is a vertical half-plane through the eye, and its
//! rays, parameterised along the unnormalised pixel direction ([`super::ray`]), share their
//! horizontal motion bit for bit: they cross every cell boundary at the same `τ` and differ
//! only in height rate. So the cells of the column's path, at every level, are walked once for
//! all of them: [`march_column`] visits a cell, tests every ray still looking there, and walks
//! the cell's children only for the rays that need them.
//!
//! Invariant (exactness): each ray is tested on exactly the cells [`super::march::march`] would
//! test it on, in the same order, with the same pure per-cell tests
//! (`march::coarse_test`, `march::level0_test`), so it gets the same hit bit
//! for bit. A ray takes part in a visited cell from the cell holding its span's start; it is
//! tested on a coarse cell's children exactly when its own test there says descend (the walk
//! of the children is the one `march` takes after descending at the cell's entry `τ`, and ends
//! where `march` would climb out); it is done after a hit or on a cell outside the database,
//! and takes no part in cells entered at or after its span's end (`march` stops after the cell
//! whose exit reaches it). Rays whose horizontal motion is not the
//! column's (a camera with roll or pitch) are not given to it.

use super::march::{coarse_test, eye_cell, level0_test, may_hit, top_level, walk_from};
use super::march::{Coarse, Hit};
use super::march::{Plan, Span};
use super::ray::Ray;
use super::sampler::Sampler;
use crate::error::Result;
use crate::walk::{ExactWalk, Visit};
use std::ops::Range;

/// Whether `rays` can be marched as one column: every ray moves horizontally exactly as the
/// first does (same origin and rate on both axes, bit for bit).
pub fn shares_path(rays: &[Ray]) -> bool {
    let same = |a: &Ray, b: &Ray| {
        [a.u.o, a.u.d, a.v.o, a.v.d].map(f64::to_bits)
            == [b.u.o, b.u.d, b.v.o, b.v.d].map(f64::to_bits)
    };
    rays.iter().all(|r| same(r, &rays[0]))
}

/// March every ray of one image column (`rays` sharing one horizontal path, [`shares_path`];
/// `spans[j]` is ray `j`'s span, `None` when it misses the box): each ray's hit, the same as
/// [`super::march::march`] gives it, and the number of cells the walk visited.
pub fn march_column(
    rays: &[Ray],
    spans: &[Option<Span>],
    sampler: &mut Sampler,
    plan: &Plan,
) -> Result<(Vec<Option<Hit>>, u64)> {
    debug_assert!(shares_path(rays) && rays.len() == spans.len());
    let looking: Vec<usize> = (0..rays.len()).filter(|&j| spans[j].is_some()).collect();
    let lanes = rays
        .iter()
        .zip(spans)
        .map(|(ray, span)| Lane {
            z0: ray.z0,
            dz: ray.dz,
            t0: span.map_or(f64::INFINITY, |s| s.t0),
            t1: span.map_or(f64::NEG_INFINITY, |s| s.t1),
        })
        .collect();
    let Some(t0) = looking
        .iter()
        .map(|&j| spans[j].expect("looking rays have spans").t0)
        .min_by(f64::total_cmp)
    else {
        return Ok((vec![None; rays.len()], 0));
    };
    let n = looking.len();
    let mut column = Column {
        rays,
        spans,
        lanes,
        hits: vec![None; rays.len()],
        steps: 0,
        sampler,
        plan,
        stack: looking,
    };
    let top = top_level(plan);
    let ray = &rays[column.stack[0]];
    let walk = walk_from(ray, plan, top, t0, eye_cell(ray, plan, top));
    column.walk(top, walk, None, 0..n)?;
    Ok((column.hits, column.steps))
}

/// What a visit's first test needs of one ray, side by side for the walk's inner loop.
#[derive(Debug, Clone, Copy)]
struct Lane {
    /// The ray's height at `τ = 0` and its rate, metres ([`Ray::z`]).
    z0: f64,
    dz: f64,
    /// Its span, `[t0, t1)`; `t1` is `−∞` once the ray needs no more cells (hit, or off the
    /// database), and for a ray without a span.
    t0: f64,
    t1: f64,
}

impl Lane {
    /// Whether the ray takes part in a visit over `[t_in, t_out]`: its remaining span overlaps it.
    #[inline]
    fn overlaps(&self, t_in: f64, t_out: f64) -> bool {
        self.t0 < t_out && self.t1 > t_in
    }

    /// [`super::march::lowest`] of the ray over `[t, t_far]`, the same f64.
    #[inline]
    fn lowest(&self, t: f64, t_far: f64) -> f64 {
        (self.z0 + t * self.dz).min(self.z0 + t_far * self.dz)
    }
}

/// The state of one column's march.
struct Column<'r, 's, 'a> {
    rays: &'r [Ray],
    spans: &'r [Option<Span>],
    /// Per ray, its heights and what is left of its span ([`Lane`]).
    lanes: Vec<Lane>,
    hits: Vec<Option<Hit>>,
    steps: u64,
    sampler: &'s mut Sampler<'a>,
    plan: &'r Plan,
    /// The rays of each walk in progress, ascending up the image: the top walk's first, then
    /// each descent's above its parent's (a descent's are pushed at the end and popped when it
    /// returns).
    stack: Vec<usize>,
}

impl Column<'_, '_, '_> {
    /// Ray `j` needs no more cells.
    fn finish(&mut self, j: usize) {
        self.lanes[j].t1 = f64::NEG_INFINITY;
    }

    /// Walk level-`l` cells with `walk` while they lie in `parent` (a level-`l + 1` cell given as
    /// its first level-`l` child and its children per axis; `None` at the top level: to the
    /// end), testing the rays `stack[rows]` (ascending up the image) on each.
    ///
    /// A ray takes part in a visit over `[t_in, t_out]` while its span overlaps it. Heights at
    /// every `τ ≥ 0` grow along the rows, so once a ray passes over the column over the whole
    /// visit (whatever part of it its span covers), every later ray does too, and the tests
    /// of those rays there would skip: the visit's tests stop.
    fn walk(
        &mut self,
        l: usize,
        mut walk: ExactWalk<2>,
        parent: Option<([i64; 2], i64)>,
        rows: Range<usize>,
    ) -> Result<()> {
        let plan = self.plan;
        // Children per axis of a cell of this level (for descents).
        let f = if l > 0 { plan.children(l) } else { 1 };
        let (mut first, end) = (rows.start, rows.end); // rows before `first` are finished
        loop {
            // The cell the walk visits next is where it stands: a child walk leaving its parent
            // stops before stepping out of it (where `march` climbs out).
            if let Some(([c0, r0], n)) = parent {
                let [c, r] = walk.position().0;
                if !((c0..c0 + n).contains(&c) && (r0..r0 + n).contains(&r)) {
                    return Ok(());
                }
            }
            let entered = walk.stepped(); // the axes crossed into the cell visited next
            let Some(Visit {
                cell: [cc, rr],
                t_in,
                t_out,
            }) = walk.next()
            else {
                return Ok(());
            };
            while first < end && self.lanes[self.stack[first]].t1 <= t_in {
                first += 1;
            }
            if first == end {
                return Ok(());
            }
            self.steps += 1;
            let Some(cell) = self.sampler.cell(l, cc, rr)? else {
                for k in first..end {
                    let j = self.stack[k];
                    if self.lanes[j].overlaps(t_in, t_out) {
                        self.finish(j); // off the database
                    }
                }
                continue;
            };
            for k in first..end {
                let j = self.stack[k];
                let lane = self.lanes[j];
                if !lane.overlaps(t_in, t_out) {
                    continue; // hit already, or starts later, or ended earlier
                }
                if !may_hit(lane.lowest(t_in, t_out), cell.max_z) {
                    break; // this ray and all above it pass over the whole visit
                }
                let (ray, span) = (
                    &self.rays[j],
                    self.spans[j].expect("looking rays have spans"),
                );
                if l == 0 {
                    if let Some(hit) = level0_test(ray, span, [cc, rr], &cell, self.sampler, plan)?
                    {
                        self.hits[j] = Some(hit);
                        self.finish(j);
                    }
                    continue;
                }
                let at = [t_in, t_out];
                match coarse_test(ray, span, l, [cc, rr], at, &cell, self.sampler, plan)? {
                    Coarse::Stop(hit) => {
                        self.hits[j] = Some(hit);
                        self.finish(j);
                    }
                    Coarse::Descend => self.stack.push(j),
                    Coarse::Skip => {}
                }
            }
            if self.stack.len() > end {
                // Descend at the same τ, into the child holding the ray then.
                let corner = [cc * f, rr * f];
                let child = walk.descended(plan.scales[l - 1], t_in, corner, entered);
                self.walk(l - 1, child, Some((corner, f)), end..self.stack.len())?;
                self.stack.truncate(end);
            }
        }
    }
}
