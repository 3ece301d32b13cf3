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

use super::march::{coarse_test, eye_cell, level0_test, lowest, may_hit, top_level, walk_from};
use super::march::{Coarse, Hit};
use super::march::{Plan, Span};
use super::ray::Ray;
use super::sampler::Sampler;
use crate::error::Result;
use crate::walk::{ExactWalk, Visit};

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
    let mut column = Column {
        rays,
        spans,
        hits: vec![None; rays.len()],
        done: vec![false; rays.len()],
        steps: 0,
        sampler,
        plan,
        descending: vec![Vec::new(); plan.top + 1],
    };
    let looking: Vec<usize> = (0..rays.len()).filter(|&j| spans[j].is_some()).collect();
    let Some(t0) = looking
        .iter()
        .map(|&j| spans[j].expect("looking rays have spans").t0)
        .min_by(f64::total_cmp)
    else {
        return Ok((column.hits, 0));
    };
    let top = top_level(plan);
    let ray = &rays[looking[0]];
    let walk = walk_from(ray, plan, top, t0, eye_cell(ray, plan, top));
    column.walk(top, walk, None, &looking)?;
    Ok((column.hits, column.steps))
}

/// The state of one column's march.
struct Column<'r, 's, 'a> {
    rays: &'r [Ray],
    spans: &'r [Option<Span>],
    hits: Vec<Option<Hit>>,
    /// Rays that need no more cells (hit, or off the database).
    done: Vec<bool>,
    steps: u64,
    sampler: &'s mut Sampler<'a>,
    plan: &'r Plan,
    /// Per level, a buffer for the rays descending into a cell of it (reused).
    descending: Vec<Vec<usize>>,
}

impl Column<'_, '_, '_> {
    /// Whether ray `j` needs no cell entered at `t_in` or later.
    fn finished(&self, j: usize, t_in: f64) -> bool {
        self.done[j] || self.spans[j].is_some_and(|s| s.t1 <= t_in)
    }

    /// Walk level-`l` cells with `walk` while they lie in `parent` (a level-`l + 1` cell given as
    /// its first level-`l` child and its children per axis; `None` at the top level: to the
    /// end), testing the rays `rows` (ascending up the image) on each.
    ///
    /// A ray takes part in a visit over `[t_in, t_out]` while its span overlaps it. Heights at
    /// every `τ ≥ 0` grow along `rows`, so once a ray passes over the column over the whole
    /// visit (whatever part of it its span covers), every later ray does too, and the tests
    /// of those rays there would skip: the visit's tests stop.
    fn walk(
        &mut self,
        l: usize,
        walk: ExactWalk<2>,
        parent: Option<([i64; 2], i64)>,
        rows: &[usize],
    ) -> Result<()> {
        let plan = self.plan;
        // Children per axis of a cell of this level (for descents).
        let f = if l > 0 { plan.children(l) } else { 1 };
        let mut first = 0; // rows before it are finished
        for Visit {
            cell: [cc, rr],
            t_in,
            t_out,
        } in walk
        {
            if let Some(([c0, r0], n)) = parent {
                if !((c0..c0 + n).contains(&cc) && (r0..r0 + n).contains(&rr)) {
                    return Ok(()); // where `march` climbs out
                }
            }
            while first < rows.len() && self.finished(rows[first], t_in) {
                first += 1;
            }
            if first == rows.len() {
                return Ok(());
            }
            self.steps += 1;
            let cell = self.sampler.cell(l, cc, rr)?;
            let mut descend = std::mem::take(&mut self.descending[l]);
            descend.clear();
            for &j in &rows[first..] {
                let span = self.spans[j].expect("looking rays have spans");
                if self.done[j] || span.t0 >= t_out || span.t1 <= t_in {
                    continue; // hit already, or starts later, or ended earlier
                }
                let ray = &self.rays[j];
                let Some(cell) = &cell else {
                    self.done[j] = true; // off the database
                    continue;
                };
                if !may_hit(lowest(ray, t_in, t_out), cell.max_z) {
                    break; // this ray and all above it pass over the whole visit
                }
                if l == 0 {
                    if let Some(hit) = level0_test(ray, span, [cc, rr], cell, self.sampler, plan)? {
                        (self.hits[j], self.done[j]) = (Some(hit), true);
                    }
                    continue;
                }
                let at = [t_in, t_out];
                match coarse_test(ray, span, l, [cc, rr], at, cell, self.sampler, plan)? {
                    Coarse::Stop(hit) => (self.hits[j], self.done[j]) = (Some(hit), true),
                    Coarse::Descend => descend.push(j),
                    Coarse::Skip => {}
                }
            }
            if !descend.is_empty() {
                let ray = &self.rays[descend[0]];
                let corner = [cc * f, rr * f];
                let child = walk_from(ray, plan, l - 1, t_in, corner);
                self.walk(l - 1, child, Some((corner, f)), &descend)?;
            }
            self.descending[l] = descend;
        }
        Ok(())
    }
}
