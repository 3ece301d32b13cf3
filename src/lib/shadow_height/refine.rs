//! Refinement over the real terrain (the Hughes patent's loop): extrude the footprint to a
//! trial height over the DEM, cast its shadow, compare with the observed shadow, and keep the
//! height whose shadow overlaps the observed one best.
//!
//! Invariant: the synthetic shadow is cast with exact rays toward the sun over the real terrain,
//! against the footprint *polygon* (not its raster): a ray from a ground point at terrain height
//! `z` first meets the footprint's walls `t` metres away, so the point is in the shadow of a roof
//! at `ground_z + Z` exactly when `Z > z + t·tan(elevation) − ground_z`, the point's *threshold*.
//! (Cells the bare terrain shadows are unusable, so nothing else blocks the ray.) Each open cell
//! holds `sub × sub` points (`Options::sub_points`, laid out as a lattice with one point in each
//! row and each column of `sub²`: `lattice`), so the synthetic shadow covers it in fractions.
//! A prism's shadow only grows with its height; the *corridor* is the kept cells with a point
//! whose threshold is up to `z_hi`. The observed shadow is the corridor's shadow cells
//! connected to the footprint (shadow beyond lit ground belongs to something else) and the
//! cells touching them. The score of `Z` is how well the photo's brightness over the corridor
//! is a mix of two levels in the synthetic fractions — the R² of the least-squares line
//! `b ≈ lit + (shadow − lit)·s`, darker in shadow — with both levels fitted, not estimated
//! beforehand: a shadow a cell or two wide (a high sun) has no cell of pure shadow to read its
//! level from. It changes only at thresholds, so every height in `(0, z_hi]` is scored by one
//! sweep over the sorted thresholds, and the answer is the middle of the first best interval
//! (the unbiased choice). Exact polygons and fractions make the answer finer than a cell of
//! shadow length, which matters most where a cell of shadow is metres of height (high sun,
//! coarse cells).

use super::footprint::Footprint;
use super::local::{Class, Local};

/// The refined height above `ground_z` (metres), its IoU with the observed shadow, and the
/// heights the photo cannot tell from it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Refined {
    /// Height above `ground_z`, metres.
    pub height_m: f64,
    /// IoU of synthetic and observed shadow at that height, in [0, 1].
    pub overlap: f64,
    /// The plausible heights at 68 % and 95 % (metres above `ground_z`, low and high): the
    /// hull of the heights whose fit is within the noise of the best ([`plausible_level`]).
    pub plausible: [(f64, f64); 2],
}

/// How many standard errors each of [`Refined::plausible`]'s intervals spans: the two-sided
/// 68 % and 95 % points of a normal distribution (χ² with one degree of freedom: 1 and 3.84).
pub const PLAUSIBLE_SIGMAS: [f64; 2] = [1.0, 1.96];

/// How much more the photo's brightness varies, as evidence, than its per-cell scatter about
/// the fitted line says: neighbouring cells are not independent (texture, blur and JPEG blocks
/// span several cells), so a likelihood that counted every cell as a separate measurement
/// would be too sure. Calibrated on the POV-Ray harnesses (docs/shadow-height.md, "Heights
/// with their uncertainty").
pub const NOISE_INFLATION: f64 = 4.0;

/// The score a height's fit must reach to be plausible at `sigmas` standard errors, given the
/// best score `best` (R², 0–1) over `n` cells: the profile likelihood of a least-squares fit
/// with two fitted levels, `ΔRSS ≤ sigmas² · σ̂²` with the noise variance `σ̂² = RSS_best / (n
/// − 2)` inflated by [`NOISE_INFLATION`]; as scores, `best − sigmas² · κ · (1 − best) / (n −
/// 2)`. Every height is plausible (the level is at most 0) with three cells or fewer.
pub fn plausible_level(best: f64, n: f64, sigmas: f64) -> f64 {
    if n <= 3.0 {
        return f64::NEG_INFINITY;
    }
    best - sigmas * sigmas * NOISE_INFLATION * (1.0 - best) / (n - 2.0)
}

/// Search heights in `(0, z_hi]` metres above `ground_z` (absolute metres) for footprint `fp`,
/// with `sub × sub` points per cell (1..=15),
/// whose cells are [`Class::Own`] in `local`. `u` is the unit shadow direction (east, north),
/// `tan_e` the tangent of the sun elevation. Only cells with `keep[i]` can be in the corridor
/// (the caller drops the bands of scan lines that met other buildings or disagreed with the
/// median length). `None` when the corridor holds no observed shadow, or no height's synthetic
/// shadow falls where the photo is darker.
#[allow(clippy::too_many_arguments)] // the corridor's inputs, passed through
pub fn refine(
    local: &Local,
    fp: &Footprint,
    keep: &[bool],
    u: (f64, f64),
    tan_e: f64,
    ground_z: f64,
    z_hi: f64,
    sub: usize,
) -> Option<Refined> {
    let c = corridor(local, fp, keep, u, tan_e, ground_z, z_hi, sub);
    best_fit(
        &mut Buckets::new(c.events, z_hi),
        &c.brightness,
        &c.observed,
        z_hi,
        sub * sub,
    )
}

/// What [`refine`] compares, before any height is tried: the corridor's cells (`members`,
/// indices of `local`'s cells in cell order), the flat roof's events (threshold, member), and
/// per member the brightness fitted (on its surface) and the shadow observed (NaN on a
/// neighbour's roof: the overlap is the ground's).
pub(super) struct Corridor {
    pub(super) members: Vec<usize>,
    pub(super) events: Vec<Event>,
    pub(super) brightness: Brightness,
    pub(super) observed: Vec<f64>,
}

/// The [`Corridor`] of [`refine`]'s search (same arguments).
///
/// Its cells are the kept open cells and the kept cells of neighbours whose roof is known
/// ([`Local::roof`]): a point on such a roof, at the roof's height `z`, is in this
/// footprint's shadow exactly as a ground point is, when `Z > z + t·tan e − ground_z` — so a
/// shadow lying on a lower neighbour's roof is evidence of the height, fitted on that roof's
/// own levels ([`Brightness`]).
#[allow(clippy::too_many_arguments)]
pub(super) fn corridor(
    local: &Local,
    fp: &Footprint,
    keep: &[bool],
    u: (f64, f64),
    tan_e: f64,
    ground_z: f64,
    z_hi: f64,
    sub: usize,
) -> Corridor {
    let w = local.grid.width;
    let n_sub = sub * sub;
    let points = SubPoints::new(n_sub);
    let t = &local.grid.transform;
    let walls = Walls::new(fp, (-u.0, -u.1));
    let mut rays = walls.for_cells((t.cell_x, 0.0), (0.0, t.cell_y));
    // The corridor: the kept cells with a point whose threshold is up to `z_hi` (also listed
    // in `members`, in cell order); the events: (threshold, member) of those points. `th`
    // holds a cell's points' thresholds (NaN: never shadowed).
    let mut corridor = vec![false; local.class.len()];
    let mut members: Vec<usize> = Vec::new();
    let mut events: Vec<Event> = Vec::new();
    let mut th = vec![f64::NAN; n_sub];
    for i in 0..local.class.len() {
        let roof = local.roof(i);
        if !keep[i] || !(matches!(local.class[i], Class::Lit | Class::Shadow) || roof.is_some()) {
            continue;
        }
        let (c, r) = (i % w, i / w);
        rays.first_each(t.pixel_to_world(c as f64, r as f64), &points.at, &mut th);
        let around = heights_around(local, c, r);
        for (k, v) in th.iter_mut().enumerate() {
            if !v.is_nan() {
                let z = roof.map_or_else(|| points.terrain(k, &around), |r| r.z as f64);
                *v = (z + *v * tan_e - ground_z).max(0.0);
            }
        }
        if th.iter().any(|&v| v <= z_hi) {
            corridor[i] = true;
            let member = members.len();
            members.push(i);
            events.extend(
                th.iter()
                    .filter(|&&v| v <= z_hi)
                    .map(|&v| Event::new(v, member)),
            );
        }
    }
    let attached = attached_shadow(local, &corridor, keep);
    let touching = touching(local, &corridor, &attached);
    // The local lit level: the median of the corridor's lit cells away from the shadow.
    let lit = super::scan::median(
        &(0..corridor.len())
            .filter(|&i| corridor[i] && !touching[i] && local.class[i] == Class::Lit)
            .map(|i| local.index[i] as f64)
            .collect::<Vec<_>>(),
    );
    let observed = observed_fraction(local, &attached, &touching, lit);
    let brightness = fitted_brightness(local, &corridor, &touching, lit);
    // Only the corridor is compared (its brightness is the finite one, its cells all there
    // is observed), so the fit runs over the members: a few thousand cells, not the window.
    let of_members = |v: &[f64]| members.iter().map(|&i| v[i]).collect::<Vec<_>>();
    Corridor {
        brightness: Brightness {
            value: of_members(&brightness),
            surface: surfaces(local, &members),
        },
        observed: of_members(&observed),
        members,
        events,
    }
}

/// Per corridor member (`members`: cells of `local`), its surface for [`Brightness`]: 0 on
/// the open ground, and 1, 2, … for the neighbours' roofs in the order their first cell
/// comes.
fn surfaces(local: &Local, members: &[usize]) -> Vec<u16> {
    let mut owners: Vec<u32> = Vec::new();
    members
        .iter()
        .map(|&i| match local.roof(i) {
            None => 0,
            Some(r) => {
                let k = owners
                    .iter()
                    .position(|&o| o == r.owner)
                    .unwrap_or_else(|| {
                        owners.push(r.owner);
                        owners.len() - 1
                    });
                (k + 1).min(u16::MAX as usize) as u16
            }
        })
        .collect()
}

/// How much more than the best so far a score must be to count as better ([`best_fit`]).
const SCORE_TIE: f64 = 1e-12;
/// How far below the best score at a bucket's end a bucket's bound must be for [`best_fit`]
/// to skip it: far more than the sums' rounding and [`SCORE_TIE`], far less than a score.
const SCORE_SKIP: f64 = 1e-9;

/// A refinement point's threshold and cell as one sortable key: the threshold (metres, as
/// an `f32`: micrometres at 100 m) in the high 32 bits, the cell in the low 32.
///
/// Invariant: the threshold is never negative, so the keys ascend with the thresholds, then
/// the cells (the bits of non-negative floats ascend with their values).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub(super) struct Event(u64);

impl Event {
    /// The event of a point of `cell` (below 2³²: a window is at most
    /// [`super::MAX_SHADOW_CELLS`] cells across and as wide) at `threshold` metres (≥ 0).
    pub(super) fn new(threshold: f64, cell: usize) -> Event {
        // `+ 0.0` makes a −0 threshold +0, whose bits sort first.
        let bits = (threshold as f32 + 0.0).to_bits();
        Event((bits as u64) << 32 | cell as u32 as u64)
    }

    /// The threshold, metres.
    pub(super) fn threshold(self) -> f64 {
        f32::from_bits((self.0 >> 32) as u32) as f64
    }

    pub(super) fn cell(self) -> usize {
        self.0 as u32 as usize
    }
}

/// Events grouped by threshold: bucket `b` holds `events[start[b]..start[b + 1]]`, every
/// threshold in it below every threshold of the buckets after it (buckets by a monotone
/// function of the threshold, spread evenly over `[0, z_hi]`), in no order within. Events
/// with one threshold share a bucket.
pub(super) struct Buckets {
    pub(super) events: Vec<Event>,
    start: Vec<usize>,
}

impl Buckets {
    /// `events` (thresholds in `[0, z_hi]` metres) in about four events a bucket.
    pub(super) fn new(events: Vec<Event>, z_hi: f64) -> Buckets {
        let n = events.len();
        let buckets = (n / 4).max(1);
        let scale = buckets as f64 / z_hi;
        let bucket = |e: Event| ((e.threshold() * scale) as usize).min(buckets - 1);
        let mut start = vec![0usize; buckets + 1];
        for &e in &events {
            start[bucket(e) + 1] += 1;
        }
        for b in 0..buckets {
            start[b + 1] += start[b];
        }
        let mut next = start.clone();
        let mut out = vec![Event(0); n];
        for e in events {
            let b = bucket(e);
            out[next[b]] = e;
            next[b] += 1;
        }
        Buckets { events: out, start }
    }

    fn of(&self, b: usize) -> std::ops::Range<usize> {
        self.start[b]..self.start[b + 1]
    }
}

/// The corridor cells that are attached shadow or touch it (8-neighbours): the shadow and its
/// mixed edge.
fn touching(local: &Local, corridor: &[bool], attached: &[bool]) -> Vec<bool> {
    let (w, h) = (local.grid.width, local.grid.height);
    (0..corridor.len())
        .map(|i| {
            let mut near = false;
            if corridor[i] {
                around(i, w, h, |j| near |= attached[j]);
            }
            near
        })
        .collect()
}

/// The brightness (shadow index) each corridor cell is fitted with, NaN outside the corridor:
/// the photo's on the attached shadow, its mixed edge (`touching`), lit ground and the
/// neighbours' known roofs; elsewhere (shadow not attached to this footprint is someone else's: this one casts none there) the
/// `lit` level, where there is one.
fn fitted_brightness(
    local: &Local,
    corridor: &[bool],
    touching: &[bool],
    lit: Option<f64>,
) -> Vec<f64> {
    (0..corridor.len())
        .map(|i| {
            let own = touching[i] || local.class[i] == Class::Lit || local.roof(i).is_some();
            match (corridor[i], own, lit) {
                (false, _, _) => f64::NAN,
                (true, false, Some(l)) => l,
                _ => local.index[i] as f64,
            }
        })
        .collect()
}

/// The best fit over `Z` in `(0, z_hi]`: `buckets` hold sub-point thresholds `(Z, cell)`,
/// `per_cell` sub-points to a cell (a sub-point is in the synthetic shadow when `Z` is above
/// it); `brightness` is each cell's, on its surface. The score is the pooled R² of the
/// least-squares lines through each surface's cells' (synthetic fraction, brightness), a
/// surface counting only where its line falls (shadow darker than lit; [`LineFit`]); the
/// answer is the middle of the first interval reaching the best (a score counts as better
/// only by more than [`SCORE_TIE`]), with the IoU of its synthetic fractions and `observed`
/// as the overlap. `None` without observed shadow, without any spread of brightness, or when
/// no height fits at all.
///
/// The answer is that of sweeping every threshold in ascending order, but only the buckets
/// that can hold it are sorted and swept: a first sweep takes the sums at each bucket's end
/// (exact scores there, in any order within) and, from the sums at both ends, a bound on the
/// score inside; a bucket whose bound is below the best end score by more than
/// [`SCORE_SKIP`] cannot hold the answer, nor change which earlier score is taken.
pub(super) fn best_fit(
    buckets: &mut Buckets,
    brightness: &Brightness,
    observed: &[f64],
    z_hi: f64,
    per_cell: usize,
) -> Option<Refined> {
    let step = 1.0 / per_cell as f64;
    if observed.iter().filter(|o| o.is_finite()).sum::<f64>() == 0.0 {
        return None;
    }
    let fit = LineFit::new(brightness, step)?;
    let (at_start, floor) = fit.bucket_starts(buckets);
    // Every height plausible for the best is plausible for the best end score at least as
    // widely (the level only rises with the best), so the buckets that can reach that level
    // hold all of them.
    let widest = plausible_level(floor, fit.cells_for_noise(), PLAUSIBLE_SIGMAS[1]).min(floor);
    let swept = fit.best_end(buckets, &at_start, widest - SCORE_SKIP)?;
    let (score, next) = swept.best;
    if score <= 0.0 {
        return None;
    }
    let (lo, hi) = answer_interval(buckets, next, z_hi);
    let mut answer = refined(lo, hi, &buckets.events[..next], observed, step);
    answer.plausible = PLAUSIBLE_SIGMAS.map(|sigmas| {
        let level = plausible_level(score, fit.cells_for_noise(), sigmas);
        swept.reaching(level, buckets, z_hi)
    });
    Some(answer)
}

/// What [`LineFit::best_end`] swept: the best score and the number of events up to the
/// answer's end, and every swept score with the number of events it counts (ascending).
struct Swept {
    best: (f64, usize),
    scores: Vec<(f64, usize)>,
}

impl Swept {
    /// The hull of the heights (metres) whose score is at least `level`: from the threshold at
    /// which the first such score begins to where the last one ends ([`answer_interval`]);
    /// `(0, z_hi)` when every height reaches it. Only the swept scores are looked at: the
    /// caller swept every bucket that can reach `level`.
    fn reaching(&self, level: f64, buckets: &Buckets, z_hi: f64) -> (f64, f64) {
        if level <= 0.0 {
            return (0.0, z_hi);
        }
        let mut above = self.scores.iter().filter(|&&(s, _)| s >= level);
        let first = above.next().map_or(self.best.1, |&(_, k)| k);
        let last = above.next_back().map_or(first, |&(_, k)| k).max(first);
        let lo = answer_interval(buckets, first, z_hi).0;
        let hi = answer_interval(buckets, last, z_hi).1;
        (lo.min(hi), hi)
    }
}

/// The sums over one surface's covered sub-points: of fractions, squared fractions (per
/// cell), and fraction × brightness.
#[derive(Clone, Copy, Default)]
pub(super) struct GroupSums {
    s: f64,
    ss: f64,
    sb: f64,
}

/// The sums over the covered sub-points, per surface ([`Brightness::surface`]); a surface
/// not listed yet has none covered.
#[derive(Clone, Default)]
pub(super) struct Sums {
    of: Vec<GroupSums>,
}

/// The brightness (shadow index) each corridor cell is fitted with, and the surface it lies
/// on: the open ground (0) or a neighbour's roof (1, 2, …), each with its own lit and shadow
/// level (a roof's tiles are not the ground's grass).
#[derive(Debug, Clone, Default, PartialEq)]
pub(super) struct Brightness {
    /// Per cell, its brightness.
    pub(super) value: Vec<f64>,
    /// Per cell, its surface.
    pub(super) surface: Vec<u16>,
}

impl Brightness {
    /// Every cell on the open ground.
    #[cfg(test)]
    pub(super) fn ground(value: Vec<f64>) -> Brightness {
        let surface = vec![0; value.len()];
        Brightness { value, surface }
    }

    /// The number of cells.
    pub(super) fn len(&self) -> usize {
        self.value.len()
    }
}

/// One surface's share of [`LineFit`]: its cells' count and summed brightness.
#[derive(Clone, Copy)]
struct Surface {
    n: f64,
    sb: f64,
}

/// [`best_fit`]'s least-squares lines through the cells' (synthetic fraction, brightness), one
/// per surface, each with its own two levels: the brightness and its sums, which every
/// height's score shares. The score is the share of the brightness's variance about each
/// surface's mean that the lines explain (R², pooled), a surface counting only where its line
/// falls (darker in shadow). With one surface this is the plain line's R².
pub(super) struct LineFit<'a> {
    /// Each cell's brightness and surface.
    brightness: &'a Brightness,
    /// What one sub-point adds to its cell's synthetic fraction: 1 / sub-points a cell.
    step: f64,
    /// The number of cells.
    n: f64,
    /// Per surface, its cells and their summed brightness.
    surfaces: Vec<Surface>,
    /// The brightness's sum of squares about each surface's mean, summed.
    syy: f64,
}

impl<'a> LineFit<'a> {
    /// The fit to `brightness` with sub-points `step` of a cell each; `None` without any
    /// spread of brightness on any surface.
    pub(super) fn new(brightness: &'a Brightness, step: f64) -> Option<LineFit<'a>> {
        let count = brightness.surface.iter().map(|&g| g as usize + 1).max()?;
        let mut surfaces = vec![Surface { n: 0.0, sb: 0.0 }; count];
        let mut sum_sq = 0.0;
        for (&b, &g) in brightness.value.iter().zip(&brightness.surface) {
            let s = &mut surfaces[g as usize];
            s.n += 1.0;
            s.sb += b;
            sum_sq += b * b;
        }
        let syy = sum_sq
            - surfaces
                .iter()
                .filter(|s| s.n > 0.0)
                .map(|s| s.sb * s.sb / s.n)
                .sum::<f64>();
        if syy.is_nan() || syy <= 0.0 {
            return None;
        }
        Some(LineFit {
            brightness,
            step,
            n: brightness.len() as f64,
            surfaces,
            syy,
        })
    }

    /// The cells the fit's noise is estimated from, as [`plausible_level`] counts them (it
    /// takes two fitted levels off): every cell less two for each surface past the first.
    fn cells_for_noise(&self) -> f64 {
        self.n - 2.0 * (self.surfaces.len() - 1) as f64
    }

    /// The score of the fractions summed in `m`: the lines' pooled R² (0 to 1), each surface
    /// counting only where its line falls.
    pub(super) fn score(&self, m: &Sums) -> f64 {
        m.of.iter()
            .zip(&self.surfaces)
            .map(|(g, s)| {
                let sxx = g.ss - g.s * g.s / s.n;
                let sxy = g.sb - g.s * s.sb / s.n;
                if sxy < 0.0 && sxx > 0.0 {
                    sxy * sxy / (sxx * self.syy)
                } else {
                    0.0
                }
            })
            .sum()
    }

    /// A bound on the score anywhere between the sums `a` and `z` at a bucket's two ends:
    /// every sum lies between its values there (they only grow), so each surface's share is
    /// at most its largest |sxy|² over its smallest sxx.
    fn bound(&self, a: &[GroupSums], z: &[GroupSums]) -> f64 {
        let mut total = 0.0;
        for ((a, z), s) in a.iter().zip(z).zip(&self.surfaces) {
            let sxy = a.sb - z.s * s.sb / s.n;
            let sxx = a.ss - z.s * z.s / s.n;
            if sxy >= 0.0 {
                continue;
            }
            if sxx <= 0.0 {
                return f64::INFINITY;
            }
            total += sxy * sxy / (sxx * self.syy) * (1.0 + 1e-9);
        }
        total
    }

    /// One more sub-point of cell `i` in the synthetic shadow: added to `m`, counted in
    /// `covered` (sub-points covered per cell).
    pub(super) fn add(&self, m: &mut Sums, covered: &mut [u32], i: usize) {
        if m.of.len() < self.surfaces.len() {
            m.of.resize(self.surfaces.len(), GroupSums::default());
        }
        let step = self.step;
        let before = covered[i] as f64 * step;
        let after = before + step;
        covered[i] += 1;
        let g = &mut m.of[self.brightness.surface[i] as usize];
        g.s += step;
        g.ss += after * after - before * before;
        g.sb += step * self.brightness.value[i];
    }

    /// The first sweep, bucket by bucket in any order within: the sums at each bucket's start
    /// (and after the last), and the best score at the end of a bucket with events.
    fn bucket_starts(&self, buckets: &Buckets) -> (BucketStarts, f64) {
        let count = buckets.start.len() - 1;
        let width = self.surfaces.len();
        let mut covered = vec![0u32; self.brightness.len()];
        let mut at_start = BucketStarts {
            sums: Vec::with_capacity((count + 1) * width),
            width,
        };
        let mut sums = Sums {
            of: vec![GroupSums::default(); width],
        };
        let mut floor = 0.0f64;
        for b in 0..count {
            at_start.sums.extend_from_slice(&sums.of);
            for k in buckets.of(b) {
                self.add(&mut sums, &mut covered, buckets.events[k].cell());
            }
            if !buckets.of(b).is_empty() {
                floor = floor.max(self.score(&sums));
            }
        }
        at_start.sums.extend_from_slice(&sums.of);
        (at_start, floor)
    }

    /// The second sweep: the buckets that may hold a score of `sweep` or more (their
    /// [`Self::bound`] not below it; the caller passes at most the best end score less
    /// [`SCORE_SKIP`], so the answer is among them) sorted and scored event by event from
    /// their sums `at_start`. Returns the best score and the number of events up to the
    /// answer's end, in the buckets' new order, and every score swept; `None` when no event is
    /// swept.
    fn best_end(
        &self,
        buckets: &mut Buckets,
        at_start: &BucketStarts,
        sweep: f64,
    ) -> Option<Swept> {
        let mut covered = vec![0u32; self.brightness.len()];
        let mut best: Option<(f64, usize)> = None;
        let mut scores = Vec::new();
        let mut sums = Sums::default();
        for b in 0..buckets.start.len() - 1 {
            let range = buckets.of(b);
            if self.bound(at_start.of(b), at_start.of(b + 1)) < sweep {
                for k in range {
                    covered[buckets.events[k].cell()] += 1;
                }
                continue;
            }
            buckets.events[range.clone()].sort_unstable();
            sums.of.clear();
            sums.of.extend_from_slice(at_start.of(b));
            for k in range.clone() {
                let e = buckets.events[k];
                self.add(&mut sums, &mut covered, e.cell());
                if k + 1 < range.end && buckets.events[k + 1].0 >> 32 == e.0 >> 32 {
                    continue;
                }
                let s = self.score(&sums);
                scores.push((s, k + 1));
                if best.is_none_or(|b| s > b.0 + SCORE_TIE) {
                    best = Some((s, k + 1));
                }
            }
        }
        Some(Swept {
            best: best?,
            scores,
        })
    }
}

/// [`LineFit::bucket_starts`]'s sums at each bucket's start, every surface's in a row.
struct BucketStarts {
    sums: Vec<GroupSums>,
    /// Surfaces a bucket.
    width: usize,
}

impl BucketStarts {
    /// The sums at bucket `b`'s start, per surface.
    fn of(&self, b: usize) -> &[GroupSums] {
        &self.sums[b * self.width..(b + 1) * self.width]
    }
}

/// The heights (metres) of the answer whose synthetic shadow is the first `next` events of
/// `buckets` (sorted up to there): from their last threshold to the next one — the smallest
/// after the answer in its bucket (sorted: the next event), or in the next bucket with events
/// (maybe unsorted) when the answer ended its own — or `z_hi` after the last.
fn answer_interval(buckets: &Buckets, next: usize, z_hi: f64) -> (f64, f64) {
    let events = &buckets.events;
    let lo = events[next - 1].threshold();
    let hi = if next == events.len() {
        z_hi
    } else {
        let b = buckets.start.partition_point(|&s| s <= next) - 1;
        events[next..buckets.start[b + 1]]
            .iter()
            .map(|e| e.threshold())
            .fold(f64::INFINITY, f64::min)
    }
    .max(lo);
    (lo, hi)
}

/// The answer between thresholds `lo` and `hi` (metres): their middle, with the IoU of the
/// synthetic fractions the `covered` events give (each `step` of its cell) and `observed`
/// where it is finite (the ground's).
fn refined(lo: f64, hi: f64, covered: &[Event], observed: &[f64], step: f64) -> Refined {
    let mut s = vec![0.0; observed.len()];
    for e in covered {
        s[e.cell()] += step;
    }
    let ground = || s.iter().zip(observed).filter(|(_, b)| b.is_finite());
    let num: f64 = ground().map(|(a, b)| a.min(*b)).sum();
    let den: f64 = ground().map(|(a, b)| a.max(*b)).sum();
    Refined {
        height_m: (lo + hi) / 2.0,
        overlap: (num / den).clamp(0.0, 1.0),
        plausible: [(lo, hi); 2],
    }
}

/// `n` points in the unit cell, a rank-1 lattice: point `k` at `((k + ½)/n, ((k·g) mod n + ½)/n)`
/// with the generator `g` (coprime to `n`) that spreads them farthest apart (the largest
/// smallest distance, wrapping around the cell; the smallest such `g` on ties).
///
/// Invariant: the points take `n` distinct values on each axis, one in each `1/n` of the cell.
/// So an edge parallel to a grid axis moving across the cell covers them one at a time — the
/// synthetic shadow's length steps by `1/n` cell, not by the `1/√n` of a square grid of
/// points, whose whole rows enter together. An axis-aligned footprint at an 80° sun on 1 m
/// cells is the case: with 4 × 4 points in a square grid, heights came only in steps of
/// 1.4 m.
fn lattice(n: usize) -> Vec<(f64, f64)> {
    let gcd = |mut a: usize, mut b: usize| {
        while b != 0 {
            (a, b) = (b, a % b);
        }
        a
    };
    // The lattice is a group, so its smallest distance is that from point 0 to the others.
    let spread = |g: usize| {
        (1..n)
            .map(|k| {
                let wrap = |v: usize| v.min(n - v) as f64;
                wrap(k).hypot(wrap(k * g % n))
            })
            .fold(f64::INFINITY, f64::min)
    };
    let g = (1..n.max(2))
        .filter(|&g| gcd(g, n) == 1)
        .fold((1, f64::NEG_INFINITY), |best, g| {
            let s = spread(g);
            if s > best.1 {
                (g, s)
            } else {
                best
            }
        })
        .0;
    let nf = n as f64;
    (0..n)
        .map(|k| ((k as f64 + 0.5) / nf, ((k * g % n) as f64 + 0.5) / nf))
        .collect()
}

/// The `n` points of a cell ([`lattice`]) and, for each, the terrain between the cell
/// centres around it.
///
/// Invariant: [`SubPoints::terrain`] is the terrain at point `k` of a cell bilinear between
/// the four cell centres around it, taken from the cell's 3 × 3 neighbourhood
/// ([`heights_around`]); the cell's own height where one of the four is outside or nodata.
pub(super) struct SubPoints {
    /// The points, as fractions of the cell (column, row) from its first corner.
    pub(super) at: Vec<(f64, f64)>,
    /// Per point, the index into the 3 × 3 neighbourhood of the first of the four centres
    /// around it, and the point's fractions from that centre (column, row).
    bilinear: Vec<(usize, f64, f64)>,
}

impl SubPoints {
    pub(super) fn new(n: usize) -> SubPoints {
        let at = lattice(n);
        let bilinear = at
            .iter()
            .map(|&(fx, fy)| {
                // From the cell's centre; the first centre around is this cell's or the one
                // before it on each axis.
                let (x, y) = (fx - 0.5, fy - 0.5);
                let (c0, r0) = (x.floor(), y.floor());
                let first = ((r0 + 1.0) * 3.0 + (c0 + 1.0)) as usize;
                (first, x - c0, y - r0)
            })
            .collect();
        SubPoints { at, bilinear }
    }

    /// Terrain height (metres) at point `k` of the cell whose neighbourhood is `around`.
    pub(super) fn terrain(&self, k: usize, around: &[f64; 9]) -> f64 {
        let (i, fx, fy) = self.bilinear[k];
        let (a, b, c, d) = (around[i], around[i + 1], around[i + 3], around[i + 4]);
        let z = (1.0 - fy) * ((1.0 - fx) * a + fx * b) + fy * ((1.0 - fx) * c + fx * d);
        if z.is_finite() {
            z
        } else {
            around[4]
        }
    }
}

/// The terrain heights (metres) of cell `(c, r)` of `local` and its eight neighbours, row by
/// row from the north-west; NaN off the window.
pub(super) fn heights_around(local: &Local, c: usize, r: usize) -> [f64; 9] {
    let (w, h) = (local.grid.width, local.grid.height);
    let mut out = [f64::NAN; 9];
    for (k, v) in out.iter_mut().enumerate() {
        let (cc, rr) = ((c + k % 3).wrapping_sub(1), (r + k / 3).wrapping_sub(1));
        if cc < w && rr < h {
            *v = local.heights[rr * w + cc] as f64;
        }
    }
    out
}

/// How much of each corridor cell the photo shows in this footprint's shadow, in [0, 1] (for
/// the reported overlap): the attached shadow cells and the cells touching them (the shadow's
/// mixed edge) read their shadow index between the `lit` level and the shadow level; every
/// other cell is 0. Without both levels, the attached cells are 1. A neighbour's known roof
/// is NaN: its levels are its own, and the overlap is read on the ground.
fn observed_fraction(
    local: &Local,
    attached: &[bool],
    touching: &[bool],
    lit: Option<f64>,
) -> Vec<f64> {
    // The shadow's own tone: the lower quartile of the attached cells, not their median. A
    // shadow a cell or two wide (a high sun) is mostly cells it covers in part, whose median
    // reads lighter than shadow.
    let shadow = super::scan::quantile(
        &(0..attached.len())
            .filter(|&i| attached[i])
            .map(|i| local.index[i] as f64)
            .collect::<Vec<_>>(),
        0.25,
    );
    (0..attached.len())
        .map(|i| match (shadow, lit) {
            _ if local.roof(i).is_some() => f64::NAN,
            (Some(s), Some(l)) if l > s && touching[i] => {
                ((l - local.index[i] as f64) / (l - s)).clamp(0.0, 1.0)
            }
            _ => attached[i] as u8 as f64,
        })
        .collect()
}

/// A footprint's walls as rays in one direction meet them: per edge its start, its vector and
/// the direction's cross product with it, computed once for the many rays cast.
pub(super) struct Walls {
    d: (f64, f64),
    /// The edges not parallel to `d` (a ray meets those nowhere or along their length, never
    /// first at one point), nor so close to parallel that `1 / cross(d, along)` overflows.
    edges: Vec<Wall>,
    /// A vertex, and the range of `cross(v − it, d)` over the vertices `v`, widened by
    /// [`ACROSS_SLACK`]: a ray whose start is outside it passes beside the footprint.
    across: ((f64, f64), f64, f64),
}

/// How far (metres) beside a footprint's outermost vertices, across the rays, [`Walls::first`]
/// still tries its walls: far more than the rounding of the two ways of telling (1e-9 m at
/// UTM coordinates), far less than a cell.
const ACROSS_SLACK: f64 = 1e-6;

/// One edge of a footprint, for rays along one direction `d`.
struct Wall {
    /// The edge's first vertex (world metres).
    start: (f64, f64),
    /// From the first vertex to the second.
    along: (f64, f64),
    /// `1 / cross(d, along)`, finite.
    inv_den: f64,
}

impl Walls {
    /// The walls of `fp` for rays along the unit vector `d` (east, north).
    pub(super) fn new(fp: &Footprint, d: (f64, f64)) -> Walls {
        let edges = fp
            .edges()
            .filter_map(|(a, b)| {
                let along = (b.0 - a.0, b.1 - a.1);
                let inv_den = 1.0 / cross(d, along);
                inv_den.is_finite().then_some(Wall {
                    start: a,
                    along,
                    inv_den,
                })
            })
            .collect();
        let o = fp.edges().next().map_or((0.0, 0.0), |e| e.0);
        let (lo, hi) = fp
            .edges()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), e| {
                let q = cross((e.0 .0 - o.0, e.0 .1 - o.1), d);
                (lo.min(q), hi.max(q))
            });
        Walls {
            d,
            edges,
            across: (o, lo - ACROSS_SLACK, hi + ACROSS_SLACK),
        }
    }

    /// Distance (metres) from `p` along the direction to the first wall, `None` when the ray
    /// misses the footprint.
    pub(super) fn first(&self, p: (f64, f64)) -> Option<f64> {
        let d = self.d;
        let (o, lo, hi) = self.across;
        let q = cross((p.0 - o.0, p.1 - o.1), d);
        if !(lo..=hi).contains(&q) {
            return None;
        }
        self.edges
            .iter()
            .filter_map(|w| {
                let (t, s) = w.meet(p, d);
                (t >= 0.0 && (0.0..=1.0).contains(&s)).then_some(t)
            })
            .min_by(f64::total_cmp)
    }

    /// The distances (metres) from `p` along the direction to every wall the ray crosses, in
    /// ascending order, into `out` (cleared first): [`Self::first`] is the first of them.
    pub(super) fn crossings(&self, p: (f64, f64), out: &mut Vec<f64>) {
        out.clear();
        let d = self.d;
        let (o, lo, hi) = self.across;
        if !(lo..=hi).contains(&cross((p.0 - o.0, p.1 - o.1), d)) {
            return;
        }
        out.extend(self.edges.iter().filter_map(|w| {
            let (t, s) = w.meet(p, d);
            (t >= 0.0 && (0.0..=1.0).contains(&s)).then_some(t)
        }));
        out.sort_unstable_by(f64::total_cmp);
    }

    /// The walls for rays from the points of grid cells whose sides are the vectors `ex`
    /// (from a cell's first corner to the next column's, metres east and north) and `ey` (to
    /// the next row's).
    pub(super) fn for_cells(&self, ex: (f64, f64), ey: (f64, f64)) -> CellRays<'_> {
        let slopes = self
            .edges
            .iter()
            .map(|w| {
                // Moving the ray's start by `e` moves `start − p` by `−e`.
                let along = |e: (f64, f64)| -cross(e, w.along) * w.inv_den;
                let across = |e: (f64, f64)| -cross(e, self.d) * w.inv_den;
                [along(ex), along(ey), across(ex), across(ey)]
            })
            .collect();
        CellRays {
            walls: self,
            slopes,
            near: Vec::new(),
        }
    }
}

/// A footprint's [`Walls`] as the rays from many points of one grid cell meet them.
///
/// Invariant: a wall's distance `t` and crossing `s` along it ([`Walls::first`]) are affine in
/// the ray's start, so over a cell they are their values at its first corner plus the
/// point's fractions times fixed slopes; a wall no point of the cell can meet (`s` outside
/// [0, 1] or `t` below 0 over the whole cell) is not tried for its points.
pub(super) struct CellRays<'a> {
    walls: &'a Walls,
    /// Per wall: `t` and `s` per cell of column and of row.
    slopes: Vec<[f64; 4]>,
    /// Scratch: the walls the current cell's rays may meet (`t`, `s` at its first corner,
    /// wall).
    near: Vec<(f64, f64, usize)>,
}

impl CellRays<'_> {
    /// For each point `(fx, fy)` of `points` (fractions of the cell, in [0, 1]) of the cell
    /// whose first corner is `corner` (world metres), the distance (metres) to the first wall
    /// along the direction, NaN where the ray misses the footprint, into `out`.
    pub(super) fn first_each(
        &mut self,
        corner: (f64, f64),
        points: &[(f64, f64)],
        out: &mut [f64],
    ) {
        self.near.clear();
        let d = self.walls.d;
        for (k, (w, sl)) in self.walls.edges.iter().zip(&self.slopes).enumerate() {
            let (t, s) = w.meet(corner, d);
            let t_max = t + sl[0].max(0.0) + sl[1].max(0.0);
            let s_min = s + sl[2].min(0.0) + sl[3].min(0.0);
            let s_max = s + sl[2].max(0.0) + sl[3].max(0.0);
            if t_max >= 0.0 && s_min <= 1.0 && s_max >= 0.0 {
                self.near.push((t, s, k));
            }
        }
        for (v, &(fx, fy)) in out.iter_mut().zip(points) {
            *v = f64::NAN;
            for &(t0, s0, k) in &self.near {
                let sl = &self.slopes[k];
                let t = t0 + fx * sl[0] + fy * sl[1];
                let s = s0 + fx * sl[2] + fy * sl[3];
                if t >= 0.0 && (0.0..=1.0).contains(&s) && (v.is_nan() || t < *v) {
                    *v = t;
                }
            }
        }
    }
}

impl Wall {
    /// Where the ray from `p` along `d` meets the edge's line: the distance `t` along the ray
    /// (metres) and the fraction `s` along the edge (in [0, 1] on it).
    #[inline]
    fn meet(&self, p: (f64, f64), d: (f64, f64)) -> (f64, f64) {
        let ap = (self.start.0 - p.0, self.start.1 - p.1);
        (
            cross(ap, self.along) * self.inv_den,
            cross(ap, d) * self.inv_den,
        )
    }
}

/// The cross product `a × b` of two plane vectors.
pub(super) fn cross(a: (f64, f64), b: (f64, f64)) -> f64 {
    a.0 * b.1 - a.1 * b.0
}

/// The observed shadow this footprint casts: the corridor's [`Class::Shadow`] cells connected
/// (8-neighbours, through corridor shadow cells) to the footprint's own cells. Shadow further
/// along the corridor beyond lit ground is someone else's (a neighbour's, a tree's) and would
/// pull the search toward a height whose shadow reaches it. The connection may also run through
/// kept [`Class::Unusable`] cells (another building's shadow over the start of this one's):
/// they hide the shadow, they do not end it; and over a neighbour's known roof in the
/// corridor, or its roof read shaded ([`Class::Crossed`]), which it may cross.
fn attached_shadow(local: &Local, corridor: &[bool], keep: &[bool]) -> Vec<bool> {
    let (w, h) = (local.grid.width, local.grid.height);
    let open = |i: usize| corridor[i] && local.class[i] == Class::Shadow;
    // Unusable cells hide the shadow; the footprint's edge cells mix it with the roof; a
    // neighbour's known roof carries it on (fitted on its own levels) to the ground beyond.
    let through: Vec<bool> = (0..corridor.len())
        .map(|i| {
            open(i)
                || local.class[i] == Class::Edge
                || (keep[i] && local.class[i] == Class::Unusable)
                || corridor[i] && (local.roof(i).is_some() || local.class[i] == Class::Crossed)
        })
        .collect();
    let mut seen = vec![false; corridor.len()];
    let mut stack = Vec::new();
    let reach = |j: usize, seen: &mut [bool], stack: &mut Vec<usize>| {
        if through[j] && !seen[j] {
            seen[j] = true;
            stack.push(j);
        }
    };
    // The seeds: the edge cells, and the cells to pass through beside the footprint's own.
    for i in 0..corridor.len() {
        match local.class[i] {
            Class::Edge => reach(i, &mut seen, &mut stack),
            Class::Own => around(i, w, h, |j| reach(j, &mut seen, &mut stack)),
            _ => {}
        }
    }
    while let Some(i) = stack.pop() {
        around(i, w, h, |j| reach(j, &mut seen, &mut stack));
    }
    (0..seen.len()).map(|i| seen[i] && open(i)).collect()
}

/// Call `f` with cell `i` of a `w` × `h` window and each of its 8 neighbours in the window.
fn around(i: usize, w: usize, h: usize, mut f: impl FnMut(usize)) {
    let (c, r) = (i % w, i / w);
    for rr in r.saturating_sub(1)..=(r + 1).min(h - 1) {
        for cc in c.saturating_sub(1)..=(c + 1).min(w - 1) {
            f(rr * w + cc);
        }
    }
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use crate::crs::Crs;
    use crate::grid::{Grid, Window};
    use crate::raster::Raster;
    use crate::shadow::{cast_shadows_reference, SHADOW};
    use crate::sun::Sun;

    /// 40 × 40 m of 1 m cells on flat ground at 100 m with a 6 × 6 m footprint at x, y 10..16,
    /// its shadow observed as a photo would show it for a roof at `roof_z` and `sun`: cast by the
    /// shared caster on a grid 8 × 8 finer, a cell in shadow when most of it is.
    fn scene(sun: &Sun, roof_z: f32) -> (Local, Footprint) {
        let square = [(10.0, 10.0), (16.0, 10.0), (16.0, 16.0), (10.0, 16.0)];
        scene_of(sun, &square, |_| roof_z)
    }

    /// [`scene`] with the footprint `ring` (world metres, inside the 40 × 40 m) and the roof
    /// `roof(p)` metres high at each point `p` inside it.
    pub(in crate::shadow_height) fn scene_of(
        sun: &Sun,
        ring: &[(f64, f64)],
        roof: impl Fn((f64, f64)) -> f32,
    ) -> (Local, Footprint) {
        let g = Grid::north_up(0.0, 40.0, 1.0, 40, 40, Crs::epsg(32632));
        let w = Window {
            col: 0,
            row: 0,
            width: 40,
            height: 40,
        };
        let fp = Footprint::new(vec![vec![ring.to_vec()]]).unwrap();
        let inside = |(x, y): (f64, f64)| fp.contains(x, y);
        let fine = Grid::north_up(0.0, 40.0, 0.125, 320, 320, Crs::epsg(32632));
        let raised: Vec<f32> = (0..fine.len())
            .map(|i| {
                let p = fine.cell_centre(i % 320, i / 320);
                match inside(p) {
                    true => roof(p),
                    false => 100.0,
                }
            })
            .collect();
        let cast = cast_shadows_reference(&Raster::new(fine, raised), sun).unwrap();
        let dark: Vec<usize> = (0..1600)
            .map(|i| {
                let (c, r) = (i % 40, i / 40);
                (0..64)
                    .filter(|k| cast.data[(r * 8 + k / 8) * 320 + c * 8 + k % 8] == SHADOW)
                    .count()
            })
            .collect();
        let class = (0..1600)
            .map(
                |i| match (inside(g.cell_centre(i % 40, i / 40)), dark[i] > 32) {
                    (true, _) => Class::Own,
                    (false, true) => Class::Shadow,
                    (false, false) => Class::Lit,
                },
            )
            .collect();
        // The photo: lit ground 100, shadow 40, mixed cells in between.
        let index = dark
            .iter()
            .map(|&d| 100.0 - 60.0 * d as f32 / 64.0)
            .collect();
        let local = Local {
            win: w,
            grid: g.window_grid(&w),
            class,
            heights: vec![100.0; 1600],
            index,
            roofs: Vec::new(),
        };
        (local, fp)
    }

    #[test]
    fn recovers_the_height_whose_shadow_the_shared_caster_cast() {
        // Sun from the south at 45°: a 6.5 m roof's shadow covers most of the 6 cells north of
        // the wall; every height in (5.5, 6.5] shadows those cell centres: the answer is 6 ± 0.5.
        let sun = Sun::new(45.0, 180.0).unwrap();
        let (l, fp) = scene(&sun, 106.5);
        let r = refine(&l, &fp, &[true; 1600], (0.0, 1.0), 1.0, 100.0, 20.0, 4).unwrap();
        assert!((r.height_m - 6.0).abs() <= 0.5, "{r:?}");
        assert!(r.overlap > 0.95, "{r:?}");
    }

    #[test]
    fn hard_case_oblique_sun_resolves_less_than_a_cell_of_shadow() {
        // Sun from the south-south-east at 60°: cells along the wall see it at many distances,
        // so the best interval is much narrower than one cell of shadow (1.73 m of height).
        let sun = Sun::new(60.0, 160.0).unwrap();
        let (dx, dy) = sun.direction();
        let tan_e = 60f64.to_radians().tan();
        let (l, fp) = scene(&sun, 109.0);
        let r = refine(&l, &fp, &[true; 1600], (-dx, -dy), tan_e, 100.0, 30.0, 4).unwrap();
        assert!((r.height_m - 9.0).abs() <= 0.5, "{r:?}");
    }

    #[test]
    fn no_observed_shadow_is_no_refinement() {
        let sun = Sun::new(45.0, 180.0).unwrap();
        let (mut l, fp) = scene(&sun, 106.5);
        l.class
            .iter_mut()
            .filter(|c| **c == Class::Shadow)
            .for_each(|c| *c = Class::Lit);
        assert_eq!(
            refine(&l, &fp, &[true; 1600], (0.0, 1.0), 1.0, 100.0, 20.0, 4),
            None
        );
    }

    #[test]
    fn best_fit_fits_both_tones_and_takes_the_middle_of_the_first_best() {
        // Cell 0 all shadow, cell 1 half, cells 2 and 3 lit: b = 70 − 50·s exactly when cell 0
        // is covered and half of cell 1 — heights in (2, 3]; any lit and shadow level fits as
        // well (the levels are fitted, not given).
        let mut ev: Vec<Event> = (0..16).map(|_| Event::new(1.0, 0)).collect();
        ev.extend((0..16).map(|k| Event::new(2.0 + (k / 8) as f64, 1)));
        ev.extend((0..16).map(|_| Event::new(4.0, 2)));
        let observed = [1.0, 0.5, 0.0, 0.0];
        let fit = |b: &[f64], o: &[f64]| {
            let b = Brightness::ground(b.to_vec());
            best_fit(&mut Buckets::new(ev.clone(), 5.0), &b, o, 5.0, 16)
        };
        for (lit, shadow) in [(70.0, 20.0), (200.0, 190.0), (1.0, 0.0)] {
            let b: Vec<f64> = observed.iter().map(|o| lit + (shadow - lit) * o).collect();
            let r = fit(&b, &observed).unwrap();
            assert_eq!((r.height_m, r.overlap), (2.5, 1.0), "{lit} {shadow}");
        }
        // Brighter wherever the synthetic shadow falls is no fit, however straight the line.
        let b = [70.0, 45.0, 20.0, 20.0];
        assert_eq!(fit(&b, &observed), None);
        // No observed shadow, or no spread of brightness: nothing to fit.
        assert_eq!(fit(&b, &[0.0; 4]), None);
        assert_eq!(fit(&[50.0; 4], &observed), None);
    }

    /// [`best_fit`] the plain way: every threshold swept in ascending order, and scored at
    /// each from the cells' fractions: per surface, the least-squares line of brightness on
    /// fraction, its explained sum of squares counted where it falls.
    fn best_fit_by_full_sweep(
        events: &[Event],
        brightness: &Brightness,
        observed: &[f64],
        z_hi: f64,
        per_cell: usize,
    ) -> Option<Refined> {
        let mut events = events.to_vec();
        events.sort_unstable();
        let step = 1.0 / per_cell as f64;
        let (b, g) = (&brightness.value, &brightness.surface);
        let surfaces = g.iter().map(|&k| k as usize + 1).max()?;
        let mean_of = |v: &[f64], k: usize| {
            let of: Vec<f64> = (0..v.len())
                .filter(|&i| g[i] as usize == k)
                .map(|i| v[i])
                .collect();
            of.iter().sum::<f64>() / of.len().max(1) as f64
        };
        let syy: f64 = (0..surfaces)
            .map(|k| {
                let m = mean_of(b, k);
                (0..b.len())
                    .filter(|&i| g[i] as usize == k)
                    .map(|i| (b[i] - m).powi(2))
                    .sum::<f64>()
            })
            .sum();
        if observed.iter().filter(|o| o.is_finite()).sum::<f64>() == 0.0 || syy <= 1e-9 {
            return None;
        }
        let score_of = |x: &[f64]| -> f64 {
            (0..surfaces)
                .map(|k| {
                    let (mx, mb) = (mean_of(x, k), mean_of(b, k));
                    let on = (0..b.len()).filter(|&i| g[i] as usize == k);
                    let sxx: f64 = on.clone().map(|i| (x[i] - mx).powi(2)).sum();
                    let sxy: f64 = on.map(|i| (x[i] - mx) * (b[i] - mb)).sum();
                    if sxy < 0.0 && sxx > 1e-12 {
                        sxy * sxy / (sxx * syy)
                    } else {
                        0.0
                    }
                })
                .sum()
        };
        let mut x = vec![0.0; b.len()];
        let mut best: Option<(f64, usize)> = None;
        let mut scores = Vec::new();
        for (k, e) in events.iter().enumerate() {
            x[e.cell()] += step;
            if events.get(k + 1).is_some_and(|f| f.0 >> 32 == e.0 >> 32) {
                continue;
            }
            let score = score_of(&x);
            scores.push((score, k + 1));
            if best.is_none_or(|b| score > b.0 + 1e-9) {
                best = Some((score, k + 1));
            }
        }
        let (score, next) = best?;
        if score <= 0.0 {
            return None;
        }
        let end = |k: usize| events.get(k).map_or(z_hi, |e| e.threshold());
        let lo = events[next - 1].threshold();
        let hi = end(next).max(lo);
        let mut r = refined(lo, hi, &events[..next], observed, step);
        let cells = b.len() as f64 - 2.0 * (surfaces - 1) as f64;
        r.plausible = PLAUSIBLE_SIGMAS.map(|sigmas| {
            let level = plausible_level(score, cells, sigmas);
            if level <= 0.0 {
                return (0.0, z_hi);
            }
            let above: Vec<usize> = scores
                .iter()
                .filter(|&&(s, _)| s >= level)
                .map(|&(_, k)| k)
                .collect();
            let (first, last) = (above[0], *above.last().unwrap());
            (events[first - 1].threshold(), end(last))
        });
        Some(r)
    }

    #[test]
    fn the_bucketed_fit_is_the_full_sweeps() {
        // Shadows of a building of height h over cells of a strip, seen with noise; points
        // per cell at thresholds spread around the cell's; ties and zeros too.
        let mut seed = 12345u64;
        let mut rnd = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut answered = 0;
        for case in 0..200 {
            let cells = 20 + case % 60;
            let per_cell = [1, 4, 9, 16][case % 4];
            let z_hi = 10.0 + 30.0 * rnd();
            let h = z_hi * (0.2 + 0.6 * rnd());
            let mut events = Vec::new();
            let mut brightness = Brightness::default();
            let mut observed = Vec::new();
            // One surface, or the strip's far part on one or two roofs with their own levels.
            let surfaces = 1 + case % 3;
            for i in 0..cells {
                let at = z_hi * i as f64 / cells as f64;
                for k in 0..per_cell {
                    let t = if case % 7 == 0 {
                        (at / 2.0).round() * 2.0 // many ties
                    } else {
                        (at + (k as f64 / per_cell as f64 - 0.5) * z_hi / cells as f64).max(0.0)
                    };
                    if t <= z_hi {
                        events.push(Event::new(t, i));
                    }
                }
                let shadowed = (at < h) as u8 as f64;
                let surface = (i * surfaces / cells).min(surfaces - 1) as u16;
                let (lit, dark) = [(150.0, 50.0), (230.0, 120.0), (90.0, 40.0)][surface as usize];
                observed.push(if surface == 0 { shadowed } else { f64::NAN });
                brightness
                    .value
                    .push(lit + (dark - lit) * shadowed + 20.0 * rnd());
                brightness.surface.push(surface);
            }
            let want = best_fit_by_full_sweep(&events, &brightness, &observed, z_hi, per_cell);
            let got = best_fit(
                &mut Buckets::new(events, z_hi),
                &brightness,
                &observed,
                z_hi,
                per_cell,
            );
            match (got, want) {
                (Some(g), Some(w)) => {
                    answered += 1;
                    assert!(
                        (g.height_m - w.height_m).abs() < 1e-9,
                        "{case}: {g:?} {w:?}"
                    );
                    assert!((g.overlap - w.overlap).abs() < 1e-9, "{case}: {g:?} {w:?}");
                    for (a, b) in g.plausible.iter().zip(&w.plausible) {
                        assert!(
                            (a.0 - b.0).abs() < 1e-9 && (a.1 - b.1).abs() < 1e-9,
                            "{case}: {g:?} {w:?}"
                        );
                    }
                    let [p68, p95] = g.plausible;
                    assert!(
                        p95.0 <= p68.0
                            && p68.0 <= g.height_m
                            && g.height_m <= p68.1
                            && p68.1 <= p95.1,
                        "{case}: {g:?}"
                    );
                }
                (g, w) => assert_eq!(g, w, "{case}"),
            }
        }
        assert!(answered > 150, "{answered}");
    }

    #[test]
    fn terrain_between_cell_centres_is_bilinear() {
        let sun = Sun::new(45.0, 180.0).unwrap();
        let (mut l, _) = scene(&sun, 106.5);
        // Rises 1 m per column and 0.25 m per row.
        l.heights = (0..1600)
            .map(|i| (i % 40) as f32 + 0.25 * (i / 40) as f32)
            .collect();
        let points = SubPoints::new(16);
        for (c, r) in [(10, 5), (1, 1), (38, 38)] {
            let around = heights_around(&l, c, r);
            for (k, &(fx, fy)) in points.at.iter().enumerate() {
                let want = (c as f64 + fx - 0.5) + 0.25 * (r as f64 + fy - 0.5);
                assert!(
                    (points.terrain(k, &around) - want).abs() < 1e-9,
                    "{c} {r} {k}"
                );
            }
        }
        // West of the first centre and south of the last: the cell's own height.
        for (c, r) in [(0, 5), (39, 39)] {
            let around = heights_around(&l, c, r);
            let own = l.heights[r * 40 + c] as f64;
            for (k, &(fx, fy)) in points.at.iter().enumerate() {
                if (c == 0 && fx < 0.5) || (c == 39 && fx > 0.5) || (r == 39 && fy > 0.5) {
                    assert_eq!(points.terrain(k, &around), own, "{c} {r} {k}");
                }
            }
        }
    }

    #[test]
    fn rays_from_a_cells_points_meet_the_walls_single_rays_meet() {
        // An L-shaped footprint (a ray can cross four walls) and a diagonal one, rays along
        // the axes, the diagonals and a few ulps off them, from cells all around, on a grid of
        // 0.7 × 0.4 m cells.
        let l_shape = Footprint::new(vec![vec![vec![
            (0.0, 0.0),
            (6.0, 0.0),
            (6.0, 2.0),
            (2.0, 2.0),
            (2.0, 6.0),
            (0.0, 6.0),
        ]]])
        .unwrap();
        let diamond = Footprint::new(vec![vec![vec![
            (3.0, 0.0),
            (6.0, 3.0),
            (3.0, 6.0),
            (0.0, 3.0),
        ]]])
        .unwrap();
        let points = SubPoints::new(16).at;
        let (ex, ey) = ((0.7, 0.0), (0.0, -0.4));
        let off = f64::EPSILON * 4.0;
        let directions = [
            (1.0, 0.0),
            (0.0, 1.0),
            (-1.0, 0.0),
            (0.0, -1.0),
            (1.0, off),
            (-off, 1.0),
            (0.6, 0.8),
            (
                -std::f64::consts::FRAC_1_SQRT_2,
                std::f64::consts::FRAC_1_SQRT_2,
            ),
        ];
        let mut met = 0;
        for fp in [&l_shape, &diamond] {
            for d in directions {
                let walls = Walls::new(fp, d);
                let mut rays = walls.for_cells(ex, ey);
                let mut out = vec![0.0; points.len()];
                for (c, r) in (0..20).flat_map(|c| (0..30).map(move |r| (c, r))) {
                    let corner = (-4.0 + c as f64 * ex.0, 9.0 + r as f64 * ey.1);
                    rays.first_each(corner, &points, &mut out);
                    for (&(fx, fy), &got) in points.iter().zip(&out) {
                        let p = (corner.0 + fx * ex.0, corner.1 + fy * ey.1);
                        match walls.first(p) {
                            Some(want) => {
                                met += 1;
                                assert!((got - want).abs() < 1e-9, "{d:?} {p:?}: {got} {want}")
                            }
                            None => assert!(got.is_nan(), "{d:?} {p:?}: {got}"),
                        }
                    }
                }
            }
        }
        assert!(met > 10_000, "{met}");
    }

    #[test]
    fn buckets_sorted_each_are_the_full_sort() {
        // Ties, both zeros, the range's ends, values crowded into one bucket and values one
        // f32 ulp apart.
        let mut v: Vec<(f64, usize)> = (0..2000)
            .map(|k| (((k * 7919) % 1000) as f64 / 999.0 * 30.0, k % 37))
            .collect();
        v.extend([
            (0.0, 5),
            (-0.0, 5),
            (-0.0, 2),
            (30.0, 1),
            (30.0, 0),
            (1e-300, 3),
            (1e-30, 3),
        ]);
        v.extend((0..50).map(|k| (15.0 + k as f64 * 1e-13, 50 - k)));
        let ulp = |k: u32| f32::from_bits(15.0f32.to_bits() + k) as f64;
        v.extend((0..50).map(|k| (ulp(k % 7), 3 * k as usize)));
        // The full sort of the thresholds as kept (f32, −0 as +0), then cells.
        let mut full: Vec<(f32, usize)> = v.iter().map(|&(t, c)| (t as f32 + 0.0, c)).collect();
        full.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        let mut buckets = Buckets::new(v.iter().map(|&(t, c)| Event::new(t, c)).collect(), 30.0);
        for b in 0..buckets.start.len() - 1 {
            let range = buckets.of(b);
            buckets.events[range].sort_unstable();
        }
        let got: Vec<(f32, usize)> = buckets
            .events
            .iter()
            .map(|e| (e.threshold() as f32, e.cell()))
            .collect();
        assert_eq!(got.len(), full.len());
        for (k, (g, f)) in got.iter().zip(&full).enumerate() {
            assert!(
                g.0.to_bits() == f.0.to_bits() && g.1 == f.1,
                "event {k}: {g:?}, the full sort has {f:?}"
            );
        }
        assert!(Buckets::new(Vec::new(), 1.0).events.is_empty());
    }

    #[test]
    fn lattice_points_take_every_row_and_column_once() {
        for n in [1, 4, 9, 16, 25, 64, 225] {
            let pts = lattice(n);
            assert_eq!(pts.len(), n);
            for axis in [0, 1] {
                let mut v: Vec<usize> = pts
                    .iter()
                    .map(|p| ((if axis == 0 { p.0 } else { p.1 }) * n as f64) as usize)
                    .collect();
                v.sort();
                assert_eq!(v, (0..n).collect::<Vec<_>>(), "n {n} axis {axis}");
            }
        }
        // Spread over the cell, not along a line: 16 points nearly a square grid's spacing
        // (¼) apart — the best 16-point rank-1 lattice has √10/16 ≈ 0.198.
        let p = lattice(16);
        let min = (0..16)
            .flat_map(|i| (0..i).map(move |j| (i, j)))
            .map(|(i, j)| (p[i].0 - p[j].0).hypot(p[i].1 - p[j].1))
            .fold(f64::INFINITY, f64::min);
        assert!(min >= 0.19, "{min}");
    }

    #[test]
    fn first_wall_is_the_nearest_edge_along_the_ray() {
        let fp = Footprint::new(vec![vec![vec![
            (0.0, 0.0),
            (4.0, 0.0),
            (4.0, 4.0),
            (0.0, 4.0),
        ]]])
        .unwrap();
        let walls = Walls::new(&fp, (0.0, -1.0));
        assert_eq!(walls.first((2.0, 7.0)), Some(3.0));
        assert_eq!(walls.first((9.0, 7.0)), None);
    }
}
