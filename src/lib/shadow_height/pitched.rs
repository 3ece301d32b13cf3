//! Pitched roofs measured from their shadows (issue 39): the refinement of [`super::refine`]
//! with the footprint raised to a gable or hip roof ([`crate::roof`]'s convention) instead of
//! a flat one.
//!
//! Invariant (the threshold): a roof with eaves `E` metres above `ground_z`, rise `Δ` (ridge −
//! eaves) and profile `P` in [0, 1] ([`crate::roof::Extent::profile`]) shadows a ground point
//! at terrain `z` exactly when, for some distance `t` along its ray toward the sun inside the
//! footprint, `E + Δ·P(t) > z − ground_z + t·tan e`: when `E` is above the point's threshold
//! `z − ground_z + min_t (t·tan e − Δ·P(t))`. For one form, direction and `Δ` that is one
//! threshold per sub-point, so `refine::best_fit`'s sweep scores every `E` at once, as for a
//! flat roof (`Δ = 0`). The minimum is exact, not sampled: a gable's or hip's profile is the
//! least of its planes, so concave over the footprint's extent, and `t·tan e − Δ·P` is convex
//! along the ray; its minimum over the parts of the ray inside the footprint lies where the ray
//! enters or leaves it (a wall crossing) or where it crosses a crease inside
//! ([`RoofShape::creases`], the only places the slope changes).
//!
//! What is fitted: gable and hip, each with its ridge along the footprint's minimum-area
//! rectangle's long axis and across it, and rises from one cell of shadow as height
//! (`cell · tan e`, the least the shadow resolves) in steps of one up to the ridge a
//! [`MAX_PITCH_DEG`] pitch would give, then in quarter steps around the best of each. The best
//! pitched fit ([`MIN_PREFERENCE`]) replaces the flat one only when it explains the photo
//! clearly better ([`MIN_IMPROVEMENT`]): the flat roof stays
//! the answer wherever the shadow cannot tell the two apart — a pitch shallower than the sun
//! with the sun across the ridge, or any hip roof shallower than the sun, casts exactly its
//! eaves' shadow.

use super::footprint::Footprint;
use super::local::Local;
use super::refine::{self, best_fit, cross, Buckets, Event, LineFit, Refined, SubPoints, Walls};
use super::shading;
use crate::roof::{Pitch, RoofForm, RoofShape};

/// A pitched fit is taken only when its unexplained variance of brightness (1 − R² of
/// `refine::best_fit`'s line) is at most `1 − MIN_IMPROVEMENT` of the flat fit's.
pub const MIN_IMPROVEMENT: f64 = 0.4;
/// … and when its rise is at least this many cells of shadow as height (`cell · tan e`
/// each): a pitch of a cell of shadow is within the flat fit's own uncertainty. (On POV-Ray
/// hip roofs pitched 50°, whose ridges lay above the search's ceiling, the only silent error
/// was a one-cell "gable".)
pub const MIN_RISE_CELLS: f64 = 2.0;
/// … and when it raises the R² by at least this much (a perfect flat fit is not improved on
/// by rounding).
pub const MIN_GAIN: f64 = 1e-6;
/// The roofs are tried in order of preference — ridge along the long axis before across it,
/// gable before hip — and a later one replaces the best so far only when its unexplained
/// variance is at most `1 − MIN_PREFERENCE` of the best's: where the shadow hardly tells two
/// shapes apart (a cell or two of it), the usual one is taken.
pub const MIN_PREFERENCE: f64 = 0.1;
/// A pitch the faces' shading tells ([`shading`]) is taken, where the shadow cannot tell one,
/// unless the shadow of that roof leaves more than `1 + MAX_CONTRADICTION` times the flat
/// roof's unexplained variance of brightness: a ridge that high would show in the shadow.
pub const MAX_CONTRADICTION: f64 = 0.25;
/// Least pitch, degrees, the faces' shading must show (the low end of its 95 % interval) for a
/// roof to be taken as pitched on the shading alone ([`shading_tells`]).
pub const MIN_SHADED_PITCH_DEG: f64 = 5.0;
/// Steepest pitch tried, degrees from horizontal.
pub const MAX_PITCH_DEG: f64 = 60.0;
/// The forms fitted.
const FORMS: [RoofForm; 2] = [RoofForm::Gable, RoofForm::Hip];

/// A pitched roof fitted to a footprint's shadow.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fitted {
    /// Form, eaves (absolute metres) and ridge direction (degrees clockwise from grid north).
    pub pitch: Pitch,
    /// The ridge above `ground_z`, metres.
    pub top_m: f64,
    /// IoU of the synthetic shadow and the observed one, in [0, 1].
    pub overlap: f64,
    /// The fit's R², and the flat roof's (in [0, 1]).
    pub score: f64,
    /// See `score`.
    pub flat_score: f64,
    /// The ridge's 68 % and 95 % plausible ranges above `ground_z`, metres, from what chose the
    /// rise: half a cell and a cell of shadow as height (`cell · tan e`) around it where the
    /// shadow did, the pitch's intervals where the faces' shading did ([`shading`]).
    pub top_plausible_m: [(f64, f64); 2],
}

/// The best pitched roof for footprint `fp`, or `None` when none explains the photo clearly
/// better than a flat roof (see the module docs) and the faces' shading (`shaded_by`,
/// [`shaded_roofs`]) does not tell a pitch either. The other arguments are [`refine::refine`]'s;
/// `cell` is the cell edge (metres). Tops up to `z_hi` metres above `ground_z` are tried.
#[allow(clippy::too_many_arguments)]
pub fn fit(
    shaded_by: &[ShadedRoof],
    local: &Local,
    fp: &Footprint,
    keep: &[bool],
    u: (f64, f64),
    tan_e: f64,
    ground_z: f64,
    z_hi: f64,
    sub: usize,
    cell: f64,
) -> Option<Fitted> {
    let n_sub = sub * sub;
    let mut c = refine::corridor(local, fp, keep, u, tan_e, ground_z, z_hi, sub);
    let line = LineFit::new(&c.brightness, 1.0 / n_sub as f64)?;
    let flat = Trial::new(std::mem::take(&mut c.events), z_hi, &c, &line, n_sub)?;
    let rays = Rays::new(local, fp, &c.members, u, tan_e, ground_z, z_hi, sub);
    let step = cell * tan_e;
    let mut best: Option<(Trial, Pitch, f64, Option<FacesRise>)> = None;
    let mut shaded: Option<Shaded> = None;
    for azimuth_deg in axes(fp) {
        for form in FORMS {
            let pitch = Pitch {
                form,
                eave_z: 0.0,
                azimuth_deg,
            };
            let shape = RoofShape::new(&fp.rings, 1.0, Some(pitch));
            let Some((_, extent)) = shape.pitch else {
                continue;
            };
            let candidates = rays.candidates(&shape);
            let highest = (extent.half.1 * MAX_PITCH_DEG.to_radians().tan()).min(z_hi - step);
            let trial = |rise: f64| {
                Trial::new(
                    candidates.events(&rays, rise, z_hi - rise),
                    z_hi - rise,
                    &c,
                    &line,
                    n_sub,
                )
                .map(|t| (t, rise))
            };
            let better = |a: &Option<(Trial, f64)>, b: Option<(Trial, f64)>| match (a, b) {
                (Some(a), Some(b)) if b.0.score > a.0.score => Some(b),
                (None, b) => b,
                (a, _) => *a,
            };
            let mut own: Option<(Trial, f64)> = None;
            let coarse = (highest / step).floor() as usize;
            for k in 1..=coarse {
                own = better(&own, trial(k as f64 * step));
            }
            if let Some((_, rise)) = own {
                for j in (-3..=3).filter(|j| *j != 0) {
                    let r = rise + j as f64 * step / 4.0;
                    if r >= step && r <= highest {
                        own = better(&own, trial(r));
                    }
                }
            }
            let told = shaded_by
                .iter()
                .find(|s| s.form == form && s.azimuth_deg == azimuth_deg)
                .map(|s| FacesRise::new(&s.estimate, &extent));
            if let Some((t, rise)) = own {
                if best.is_none_or(|b| (1.0 - t.score) < (1.0 - MIN_PREFERENCE) * (1.0 - b.0.score))
                {
                    best = Some((t, pitch, rise, told));
                }
            }
            let Some(faces) = told else {
                continue;
            };
            if shaded.is_none_or(|b| {
                1.0 - faces.explained < (1.0 - MIN_PREFERENCE) * (1.0 - b.faces.explained)
            }) {
                let rise = faces.rise;
                if let Some((t, _)) = (rise <= z_hi - step).then(|| trial(rise)).flatten() {
                    shaded = Some(Shaded {
                        trial: t,
                        pitch,
                        faces,
                    });
                }
            }
        }
    }
    let flat_unexplained = (1.0 - flat.score).max(0.0);
    let from_shadow = best.filter(|(t, _, rise, _)| {
        let unexplained = (1.0 - t.score).max(0.0);
        *rise >= MIN_RISE_CELLS * step
            && unexplained < (1.0 - MIN_IMPROVEMENT) * flat_unexplained
            && flat_unexplained - unexplained >= MIN_GAIN
    });
    if let Some((t, pitch, rise, told)) = from_shadow {
        // The rise is sought in steps of a cell of shadow as height, then quarter steps around
        // the best; the shadow's outline places it to about half that cell (one standard
        // error), and the faces' shading of the same roof, where it tells one, as well.
        let faces = told.map(|f| (f.rise, (f.rises[0].1 - f.rises[0].0) / 2.0));
        let (rise, sd) = combined((rise, step / 2.0), faces);
        let top_m = t.refined.height_m + rise;
        return Some(Fitted {
            pitch: Pitch {
                eave_z: ground_z + t.refined.height_m,
                ..pitch
            },
            top_m,
            overlap: t.refined.overlap,
            score: t.score,
            flat_score: flat.score,
            top_plausible_m: [1.0, 2.0].map(|k| (top_m - k * sd, top_m + k * sd)),
        });
    }
    // The shadow cannot tell: the faces' shading may, unless the shadow of the roof it
    // tells leaves clearly more of the photo unexplained than the flat roof's.
    let s = shaded.filter(|s| {
        (1.0 - s.trial.score).max(0.0) <= (1.0 + MAX_CONTRADICTION) * flat_unexplained
    })?;
    let eave_m = s.trial.refined.height_m;
    Some(Fitted {
        pitch: Pitch {
            eave_z: ground_z + eave_m,
            ..s.pitch
        },
        top_m: eave_m + s.faces.rise,
        overlap: s.trial.refined.overlap,
        score: s.trial.score,
        flat_score: flat.score,
        top_plausible_m: s.faces.rises.map(|(lo, hi)| (eave_m + lo, eave_m + hi)),
    })
}

/// Two estimates `(value, standard error)` of one rise (metres) combined by their inverse
/// variances; `a` alone without `b` (or where either error is not positive and finite).
fn combined(a: (f64, f64), b: Option<(f64, f64)>) -> (f64, f64) {
    let usable = |e: f64| e.is_finite() && e > 0.0;
    match b {
        Some(b) if usable(a.1) && usable(b.1) => {
            let (wa, wb) = (1.0 / (a.1 * a.1), 1.0 / (b.1 * b.1));
            ((wa * a.0 + wb * b.0) / (wa + wb), (wa + wb).sqrt().recip())
        }
        _ => a,
    }
}

/// The pitched roof the faces' shading tells best ([`shading`]), its eaves fitted to the
/// shadow.
#[derive(Clone, Copy)]
struct Shaded {
    trial: Trial,
    pitch: Pitch,
    faces: FacesRise,
}

/// What the faces' shading tells of one roof tried ([`ShadedRoof`]) as heights over its
/// `extent`.
#[derive(Clone, Copy)]
struct FacesRise {
    /// Ridge above the eaves, metres, and its 68 % and 95 % ranges.
    rise: f64,
    rises: [(f64, f64); 2],
    /// The share of the roof's brightness the faces' model explains.
    explained: f64,
}

impl FacesRise {
    fn new(estimate: &shading::Estimate, extent: &crate::roof::Extent) -> FacesRise {
        let rise_at = |deg: f64| extent.half.1 * deg.to_radians().tan();
        FacesRise {
            rise: rise_at(estimate.pitch_deg),
            rises: estimate
                .intervals_deg
                .map(|(lo, hi)| (rise_at(lo), rise_at(hi))),
            explained: estimate.explained,
        }
    }
}

/// A pitch the faces' shading tells for one of the roofs [`fit`] tries.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ShadedRoof {
    /// The roof tried: its form and ridge direction (degrees clockwise from grid north).
    pub form: RoofForm,
    /// See `form`.
    pub azimuth_deg: f64,
    /// What the faces tell.
    pub estimate: shading::Estimate,
}

/// The pitches the faces' shading of `roof` under `light` tells over `fp`: one per gable or
/// hip along either axis of its minimum-area rectangle whose faces tell one.
pub fn shaded_roofs(
    fp: &Footprint,
    roof: &shading::Roof,
    light: &shading::Light,
) -> Vec<ShadedRoof> {
    let mut out = Vec::new();
    for azimuth_deg in axes(fp) {
        let Some(extent) = crate::roof::Extent::new(&fp.rings, azimuth_deg) else {
            continue;
        };
        for form in FORMS {
            let faces = shading::Faces::new(roof, &extent, form);
            if let Some(estimate) = shading::estimate(&faces, light) {
                out.push(ShadedRoof {
                    form,
                    azimuth_deg,
                    estimate,
                });
            }
        }
    }
    out
}

/// Whether the faces' shading tells a pitched roof (`roofs`, from [`shaded_roofs`]): a pitch
/// whose 95 % interval lies at or above [`MIN_SHADED_PITCH_DEG`]. It sees faces whose
/// brightnesses differ too little for [`super::roof::looks_pitched`] (a low pitch, the sun
/// nearly along the ridge).
pub fn shading_tells(roofs: &[ShadedRoof]) -> bool {
    roofs
        .iter()
        .any(|s| s.estimate.intervals_deg[1].0 >= MIN_SHADED_PITCH_DEG)
}

/// The highest a pitched roof over `fp` may rise above its eaves, metres: the steepest pitch
/// ([`MAX_PITCH_DEG`]) over half its minimum-area rectangle's width.
pub fn highest_rise(fp: &Footprint) -> f64 {
    crate::roof::Extent::new(&fp.rings, axes(fp)[0])
        .map_or(0.0, |e| e.half.1 * MAX_PITCH_DEG.to_radians().tan())
}

/// The directions (degrees clockwise from grid north, in `[0, 180)`) of the long axis of the
/// footprint's minimum-area bounding rectangle and of its short one. The rectangle has a side
/// along an edge of the convex hull, so those are the directions tried.
fn axes(fp: &Footprint) -> [f64; 2] {
    let hull = fp.swept_hull((0.0, 0.0));
    let mut best = (f64::INFINITY, 0.0);
    for k in 0..hull.len() {
        let (a, b) = (hull[k], hull[(k + 1) % hull.len()]);
        let az = (b.0 - a.0).atan2(b.1 - a.1).to_degrees();
        if let Some(e) = crate::roof::Extent::new(&fp.rings, az) {
            let area = e.half.0 * e.half.1;
            if area < best.0 {
                best = (area, if e.half.0 >= e.half.1 { az } else { az + 90.0 });
            }
        }
    }
    let long = best.1.rem_euclid(180.0);
    [long, (long + 90.0).rem_euclid(180.0)]
}

/// One roof's best flat-roof-style fit over its eaves: [`refine::best_fit`]'s answer and its
/// score (R², recomputed at the answer from the events: the fit returns only the height).
#[derive(Clone, Copy)]
struct Trial {
    refined: Refined,
    score: f64,
}

impl Trial {
    /// The best eaves in `(0, z_top]` metres for the events `events` (thresholds up to
    /// `z_top`) over the corridor `c`; `None` when nothing fits.
    fn new(
        events: Vec<Event>,
        z_top: f64,
        c: &refine::Corridor,
        line: &LineFit,
        n_sub: usize,
    ) -> Option<Trial> {
        let mut buckets = Buckets::new(events, z_top);
        let refined = best_fit(&mut buckets, &c.brightness, &c.observed, z_top, n_sub)?;
        let mut sums = refine::Sums::default();
        let mut covered = vec![0u32; c.brightness.len()];
        for e in &buckets.events {
            if e.threshold() <= refined.height_m {
                line.add(&mut sums, &mut covered, e.cell());
            }
        }
        Some(Trial {
            refined,
            score: line.score(&sums),
        })
    }
}

/// The rays toward the sun from the corridor's sub-points that meet the footprint (the only
/// ones a roof can shadow): where each starts, its terrain above `ground_z`, and the distances
/// to the walls it crosses.
struct Rays {
    /// Unit vector toward the sun (east, north).
    d: (f64, f64),
    tan_e: f64,
    rays: Vec<Ray>,
    /// Wall crossings, metres along the ray, ascending per ray.
    crossings: Vec<f64>,
}

impl Rays {
    /// The rays of the corridor `members` (cells of `local`) with `sub × sub` points a cell,
    /// for the footprint `fp`, shadows falling along `u`; rays whose flat-roof threshold is
    /// above `z_hi` are left out (no roof up to `z_hi` shadows them).
    #[allow(clippy::too_many_arguments)]
    fn new(
        local: &Local,
        fp: &Footprint,
        members: &[usize],
        u: (f64, f64),
        tan_e: f64,
        ground_z: f64,
        z_hi: f64,
        sub: usize,
    ) -> Rays {
        let d = (-u.0, -u.1);
        let walls = Walls::new(fp, d);
        let points = SubPoints::new(sub * sub);
        let t = &local.grid.transform;
        let w = local.grid.width;
        let mut rays = Vec::new();
        let mut crossings = Vec::new();
        let mut here = Vec::new();
        for (m, &i) in members.iter().enumerate() {
            let (c, r) = (i % w, i / w);
            let around = refine::heights_around(local, c, r);
            for (k, &(fx, fy)) in points.at.iter().enumerate() {
                let p = t.pixel_to_world(c as f64 + fx, r as f64 + fy);
                walls.crossings(p, &mut here);
                let z = points.terrain(k, &around) - ground_z;
                if here.first().is_some_and(|&t0| z + t0 * tan_e <= z_hi) {
                    let start = crossings.len();
                    crossings.extend_from_slice(&here);
                    rays.push(Ray {
                        member: m as u32,
                        start: p,
                        z,
                        walls: start..crossings.len(),
                    });
                }
            }
        }
        Rays {
            d,
            tan_e,
            rays,
            crossings,
        }
    }

    /// Per ray, the points where `t·tan e − Δ·P(t)` may be least for the roof `shape` (top
    /// 1, eaves 0: its height is the profile): its wall crossings, and its crease crossings
    /// inside the footprint — as `(t·tan e, P)`.
    fn candidates(&self, shape: &RoofShape) -> Candidates {
        let creases = shape.creases();
        let d = self.d;
        let mut at = Vec::new();
        let mut start = Vec::with_capacity(self.rays.len() + 1);
        for ray in &self.rays {
            start.push(at.len());
            let (p, walls) = (ray.start, &self.crossings[ray.walls.clone()]);
            let point = |t: f64| (p.0 + t * d.0, p.1 + t * d.1);
            for &t in walls {
                at.push((t * self.tan_e, shape.z_at(point(t))));
            }
            for [a, b] in &creases {
                let e = (b.0 - a.0, b.1 - a.1);
                let den = cross(d, e);
                if den == 0.0 {
                    continue;
                }
                let ap = (a.0 - p.0, a.1 - p.1);
                let (t, s) = (cross(ap, e) / den, cross(ap, d) / den);
                // Inside: an odd number of crossings from outside (the ray's far end).
                let after = walls.len() - walls.partition_point(|&w| w < t);
                if t >= 0.0 && (0.0..=1.0).contains(&s) && after % 2 == 1 {
                    at.push((t * self.tan_e, shape.z_at(point(t))));
                }
            }
        }
        start.push(at.len());
        Candidates { at, start }
    }
}

/// One of [`Rays`].
struct Ray {
    /// The corridor cell (index into its members).
    member: u32,
    /// Where it starts, world metres.
    start: (f64, f64),
    /// The terrain there above `ground_z`, metres.
    z: f64,
    /// Its wall crossings' range in [`Rays::crossings`].
    walls: std::ops::Range<usize>,
}

/// [`Rays::candidates`]: ray `j`'s are `at[start[j]..start[j + 1]]`.
struct Candidates {
    at: Vec<(f64, f64)>,
    start: Vec<usize>,
}

impl Candidates {
    /// The events of the roof with rise `rise` (metres): each ray's threshold on the eaves
    /// (module docs), those up to `z_top`.
    fn events(&self, rays: &Rays, rise: f64, z_top: f64) -> Vec<Event> {
        let mut out = Vec::with_capacity(rays.rays.len());
        for (j, ray) in rays.rays.iter().enumerate() {
            let least = self.at[self.start[j]..self.start[j + 1]]
                .iter()
                .map(|&(tt, p)| tt - rise * p)
                .fold(f64::INFINITY, f64::min);
            let th = (ray.z + least).max(0.0);
            if th <= z_top {
                out.push(Event::new(th, ray.member as usize));
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::roof::Extent;
    use crate::sun::Sun;
    use refine::tests::scene_of;

    /// A 12 × 6 m house centred at (20, 20) with its long side along x (ridge azimuth 90°) on
    /// flat ground at 100 m, eaves at 103 m, the roof `form` (`None`: flat at the eaves) rising
    /// `rise` metres, seen under a sun at 35° from `az`; fitted.
    fn fitted(form: Option<RoofForm>, rise: f64, az: f64) -> Option<Fitted> {
        let ring = [(14.0, 17.0), (26.0, 17.0), (26.0, 23.0), (14.0, 23.0)];
        let rings = vec![ring.to_vec()];
        let pitch = form.map(|form| Pitch {
            form,
            eave_z: 103.0,
            azimuth_deg: 90.0,
        });
        let shape = RoofShape::new(&rings, 103.0 + rise, pitch);
        let sun = Sun::new(35.0, az).unwrap();
        let (local, fp) = scene_of(&sun, &ring, |p| shape.z_at(p) as f32);
        let (dx, dy) = sun.direction();
        let tan_e = 35f64.to_radians().tan();
        let keep = vec![true; local.class.len()];
        fit(
            &[],
            &local,
            &fp,
            &keep,
            (-dx, -dy),
            tan_e,
            100.0,
            15.0,
            4,
            1.0,
        )
    }

    /// The fit is `form`, eaves and ridge each within `tol` metres of the truth (eaves 3 m,
    /// ridge 3 m + `rise` above the ground), the ridge along x.
    fn assert_fits(f: Option<Fitted>, form: RoofForm, rise: f64, tol: f64) {
        let f = f.unwrap_or_else(|| panic!("{form:?} rise {rise}: no pitch fitted"));
        assert_eq!(f.pitch.form, form, "{f:?}");
        assert!((f.pitch.eave_z - 103.0).abs() <= tol, "eaves: {f:?}");
        assert!((f.top_m - 3.0 - rise).abs() <= tol, "ridge: {f:?}");
        assert!((f.pitch.azimuth_deg - 90.0).abs() < 1e-6, "{f:?}");
        assert!(f.score > f.flat_score, "{f:?}");
    }

    #[test]
    fn hard_case_gable_with_the_sun_along_its_ridge() {
        // The gable end's triangle is the shadow's tip: its height and its eaves both show.
        // 56° against a 35° sun. (Shallower, on this scene's 1 m cells the triangle is two or
        // three cells long, and a steep hip across the long axis fits them as well.)
        let f = fitted(Some(RoofForm::Gable), 4.5, 90.0);
        assert_fits(f, RoofForm::Gable, 4.5, 0.7);
    }

    #[test]
    fn hard_case_gable_with_the_sun_exactly_on_a_diagonal() {
        for rise in [4.5, 1.5] {
            assert_fits(
                fitted(Some(RoofForm::Gable), rise, 135.0),
                RoofForm::Gable,
                rise,
                0.7,
            );
        }
    }

    #[test]
    fn hard_case_sun_exactly_across_the_ridge_tells_no_pitch() {
        // The shadow is a rectangle whatever the roof: at 27° (shallower than the sun, the far
        // face lit) the eaves', at 56° (the far face in shadow) the ridge's, as long as a flat
        // roof between the two would cast. Nothing tells the pitch, so the flat answer stays
        // (flagged by the caller).
        for rise in [1.5, 4.5] {
            assert_eq!(
                fitted(Some(RoofForm::Gable), rise, 180.0),
                None,
                "rise {rise}"
            );
        }
        // A little off across, the gable ends' triangles show.
        let f = fitted(Some(RoofForm::Gable), 4.5, 160.0);
        assert_fits(f, RoofForm::Gable, 4.5, 0.7);
    }

    #[test]
    fn hip_roofs_fit_where_steeper_than_the_sun_and_not_where_shallower() {
        let steep = fitted(Some(RoofForm::Hip), 4.5, 150.0);
        assert_fits(steep, RoofForm::Hip, 4.5, 0.7);
        // Every face shallower than the sun: the eaves' shadow, whichever the sun.
        assert_eq!(fitted(Some(RoofForm::Hip), 1.5, 150.0), None);
    }

    #[test]
    fn a_flat_roof_is_not_turned_pitched() {
        for az in [90.0, 135.0, 180.0, 200.0] {
            assert_eq!(fitted(None, 0.0, az), None, "sun from {az}");
        }
    }

    #[test]
    fn the_axes_are_the_minimum_rectangles() {
        for rot in [0.0, 30.0, 90.0, 161.0] {
            let (s, c) = f64::to_radians(rot).sin_cos();
            // 10 × 4 m, long side along `rot` degrees from north, a corner cut off.
            let at = |a: f64, b: f64| (500.0 + a * s + b * c, 300.0 + a * c - b * s);
            let fp = Footprint::new(vec![vec![vec![
                at(0.0, 0.0),
                at(10.0, 0.0),
                at(10.0, 3.0),
                at(9.0, 4.0),
                at(0.0, 4.0),
            ]]])
            .unwrap();
            let [long, short] = axes(&fp);
            let diff = |a: f64, b: f64| ((a - b).rem_euclid(180.0)).min((b - a).rem_euclid(180.0));
            assert!(diff(long, rot) < 1e-9, "{rot}: {long}");
            assert!(diff(short, rot + 90.0) < 1e-9, "{rot}: {short}");
            let e = Extent::new(&fp.rings, long).unwrap();
            assert!((e.half.0 - 5.0).abs() < 1e-9 && (e.half.1 - 2.0).abs() < 1e-9);
        }
    }

    #[test]
    fn thresholds_are_the_least_over_the_ray_by_brute_force() {
        // An L-shaped outline (a ray leaves and re-enters it) under a hip roof, rays every way:
        // the candidates' least `t·tan e − Δ·P` is the least over the ray sampled finely
        // inside the footprint.
        let ring = vec![
            (0.0, 0.0),
            (12.0, 0.0),
            (12.0, 3.0),
            (4.0, 3.0),
            (4.0, 8.0),
            (0.0, 8.0),
        ];
        let fp = Footprint::new(vec![vec![ring.clone()]]).unwrap();
        for form in FORMS {
            for az in [0.0, 33.0, 90.0] {
                let shape = RoofShape::new(
                    &fp.rings,
                    1.0,
                    Some(Pitch {
                        form,
                        eave_z: 0.0,
                        azimuth_deg: az,
                    }),
                );
                for dir_deg in [10.0f64, 100.0, 200.0, 290.0, 45.0] {
                    let (s, c) = dir_deg.to_radians().sin_cos();
                    let d = (s, c);
                    let walls = Walls::new(&fp, d);
                    let mut rays = Rays {
                        d,
                        tan_e: 0.7,
                        rays: Vec::new(),
                        crossings: Vec::new(),
                    };
                    let mut here = Vec::new();
                    for (i, j) in (0..15).flat_map(|i| (0..15).map(move |j| (i, j))) {
                        let p = (-8.0 + 2.0 * i as f64 + 0.1, -8.0 + 1.7 * j as f64 + 0.2);
                        walls.crossings(p, &mut here);
                        if !here.is_empty() && !fp.contains(p.0, p.1) {
                            let k = rays.crossings.len();
                            rays.crossings.extend_from_slice(&here);
                            rays.rays.push(Ray {
                                member: 0,
                                start: p,
                                z: 0.0,
                                walls: k..rays.crossings.len(),
                            });
                        }
                    }
                    let cand = rays.candidates(&shape);
                    for (j, ray) in rays.rays.iter().enumerate() {
                        let p = ray.start;
                        for rise in [0.5, 3.0, 9.0] {
                            let got = cand.at[cand.start[j]..cand.start[j + 1]]
                                .iter()
                                .map(|&(tt, pr)| tt - rise * pr)
                                .fold(f64::INFINITY, f64::min);
                            let want = (0..40_000)
                                .map(|k| k as f64 * 0.001)
                                .map(|t| (t, (p.0 + t * d.0, p.1 + t * d.1)))
                                .filter(|(_, q)| fp.contains(q.0, q.1))
                                .map(|(t, q)| t * 0.7 - rise * shape.z_at(q))
                                .fold(f64::INFINITY, f64::min);
                            // Sampled every millimetre: within the slope's millimetre.
                            assert!(
                                got <= want + 1e-9 && got >= want - 0.02,
                                "{form:?} {az} {dir_deg} {p:?} {rise}: {got} {want}"
                            );
                        }
                    }
                }
            }
        }
    }
}
