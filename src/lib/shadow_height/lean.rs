//! The height a frame photo's lean gives, a second estimate beside the shadow's.
//!
//! A roof `h` above the ground at `r` from the nadir of a camera `Z` above that ground is seen
//! leaning `L = r·h / (Z − h)` radially outward ([`super::register::with_camera`]), so
//! `h = Z·L / (r + L)`. The lean is the registration's: the outline's, which is a pitched
//! roof's eaves; good to [`LEAN_CELLS`] of a cell, one standard error, which is
//! `Z·r / (r + L)² · LEAN_CELLS · cell` of height (from 500 m and `r` = 300 m, ~0.4 m at
//! 0.5 m cells; from 3000 m, ~2.5 m).
//!
//! Invariant: the lean is used only where it is *precise* — its 95 % range within
//! [`PRECISE_CELLS`] cells either side — from a clear registration estimate that fits its roof
//! (not `footprint_off_photo`), so it never replaces a shadow by a guess. Then:
//! * a flat roof whose shadow height the lean's agrees with (within the 95 % range of their
//!   difference) is confirmed by independent evidence: the flags that only doubt the shadow
//!   (lines dropped on a neighbour or the grid's edge, lines that disagree, a poor match) are
//!   cleared, and its intervals are the shadow's within the lean's;
//! * one they disagree on is flagged `lean_disagrees`, its intervals widened to hold the
//!   lean's 95 % range, and a flat roof whose shadow was doubted already (lines dropped on a
//!   neighbour, lines that disagree, a poor match) reports the lean's height (the interval
//!   still holds the shadow's);
//! * a lean sought again along its line alone ([`super::register::off_the_leans`]) only
//!   confirms or doubts: it never reports its height in place of the shadow's, nor gives one;
//! * a footprint without a shadow height takes the lean's, flagged `height_from_lean` (and
//!   `pitched_roof` still when it looks pitched, the 95 % interval then reaching the ridge of
//!   the steepest pitch over it); a lower bound seen is kept in its 95 % interval.

use super::footprint::Footprint;
use super::register::PerspectiveCentre;
use super::Measurement;

/// The lean's standard error, cells: the registration's plateau centre (a sharp edge reads the
/// same over ±¼ cell) and the scene's shift. (At 0.35 the POV-Ray hard case from 500 m had a
/// tall roof's lean 0.7 cell long and a height from the lean 0.3 m high, outside its 95 %
/// interval.)
pub const LEAN_CELLS: f64 = 0.5;

/// The lean's height is used only when its 95 % range is within this many cells of height
/// either side: a height it confirms, or gives, is then within the gross-error bound.
pub const PRECISE_CELLS: f64 = 2.0;

/// A lean's height more than this many times the top of the shadow's 95 % interval (above the
/// ground) is not taken for the shadow's, only flagged: on the town bench from 500 m a gable's
/// outline matched another building's edges 70 m out and reported 107 m for a 10 m roof,
/// while every lean's height there that corrected a doubted shadow was within twice its top.
pub const FAR_LEAN: f64 = 2.0;

/// The standard error (metres) of the height a lean `l` gives at `r` from the nadir of a camera
/// `z` above the ground, in a photo of `cell`-metre cells (all metres).
fn sigma_m(z: f64, r: f64, l: f64, cell: f64) -> f64 {
    z * r / (r + l).powi(2) * LEAN_CELLS * cell
}

/// Whether a lean `l` at `r` from the nadir of a camera `z` above the ground, in a photo of
/// `cell`-metre cells (all metres), gives a height [`PRECISE_CELLS`]-precise: its 95 % range
/// within that many cells either side. Shorter leans are the less precise (`l` = 0 the least).
pub fn precise(z: f64, r: f64, l: f64, cell: f64) -> bool {
    SIGMAS[1] * sigma_m(z, r, l, cell) <= PRECISE_CELLS * cell
}

/// Two-sided 68 % and 95 % normal quantiles.
const SIGMAS: [f64; 2] = [1.0, 1.96];

/// The roof a lean gives.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LeanHeight {
    /// The outline's (a pitched roof's eaves) absolute height, metres.
    pub z: f64,
    /// Its standard error, metres.
    pub sigma_m: f64,
}

impl LeanHeight {
    /// The roof of `fp` on ground `ground_z` (absolute metres) seen leaning `lean` metres (east,
    /// north) from `camera` in a photo of `cell`-metre cells; `None` without a lean (0 when
    /// the estimate was unclear), with the camera not above the ground, or when the lean is
    /// not [`PRECISE_CELLS`]-precise.
    pub fn new(
        fp: &Footprint,
        lean: (f64, f64),
        camera: &PerspectiveCentre,
        ground_z: f64,
        cell: f64,
    ) -> Option<LeanHeight> {
        let (x, y) = fp.bbox_centre();
        let r = (x - camera.east).hypot(y - camera.north);
        let l = lean.0.hypot(lean.1);
        let z = camera.z - ground_z;
        if !(l > 0.0 && r > 0.0 && z > 0.0) {
            return None;
        }
        precise(z, r, l, cell).then_some(LeanHeight {
            z: ground_z + z * l / (r + l),
            sigma_m: sigma_m(z, r, l, cell),
        })
    }

    /// The 68 % and 95 % ranges, absolute metres.
    fn ranges(&self) -> [(f64, f64); 2] {
        SIGMAS.map(|k| (self.z - k * self.sigma_m, self.z + k * self.sigma_m))
    }
}

/// Meet the shadow's measurement `m` of `fp` with the lean's height `lean` (see the module
/// doc); `rise_m` is the highest a pitched roof over `fp` may rise above its eaves, metres.
/// A lean found `along_lean` (sought again along the lean alone,
/// [`super::register::off_the_leans`]) confirms or doubts the shadow's height but never stands
/// for it: a narrower search always finds a best, on the roof or not.
pub fn meet(m: &mut Measurement, lean: &LeanHeight, rise_m: f64, along_lean: bool) {
    if m.flags.footprint_off_photo {
        return;
    }
    let lean_iv = lean.ranges();
    let Some(roof) = m.roof_z else {
        if !along_lean {
            given_by_lean(m, lean, rise_m);
        }
        return;
    };
    let eaves = m.pitch.map_or(roof, |p| p.eave_z);
    let shadow_sigma = m
        .roof_z_intervals
        .map_or(0.0, |[iv68, _]| 0.5 * (iv68.1 - iv68.0));
    let tol = SIGMAS[1] * lean.sigma_m.hypot(shadow_sigma.min(lean.sigma_m));
    let flat = m.pitch.is_none() && !m.flags.pitched_roof;
    if (eaves - lean.z).abs() <= tol {
        if flat {
            let f = &mut m.flags;
            f.shadow_on_other_building = false;
            f.shadow_cut_by_edge_or_nodata = false;
            f.lines_disagree = false;
            f.estimates_disagree = false;
            f.poor_shadow_match = false;
            f.shadow_reaches_further = false;
            if let Some(ivs) = m.roof_z_intervals.as_mut() {
                for (iv, l) in ivs.iter_mut().zip(lean_iv) {
                    *iv = (iv.0.max(l.0).min(roof), iv.1.min(l.1).max(roof));
                }
            }
        }
    } else if !(m.flags.pitched_roof && lean.z <= roof + tol) {
        // A roof left pitched-looking is measured between its eaves and its ridge: eaves
        // below that agree.
        m.flags.lean_disagrees = true;
        // The shadow's own evidence, before the lean widens it: a lean far above it is a match
        // on something else (a neighbour's edges far along the radial direction).
        let shadow_allows = m
            .roof_z_intervals
            .is_none_or(|[_, iv95]| lean.z - m.ground_z <= FAR_LEAN * (iv95.1 - m.ground_z));
        if let Some(ivs) = m.roof_z_intervals.as_mut() {
            for (iv, l) in ivs.iter_mut().zip(lean_iv) {
                *iv = (iv.0.min(l.0), iv.1.max(l.1));
            }
            let inner = ivs[0];
            ivs[1] = (ivs[1].0.min(inner.0), ivs[1].1.max(inner.1));
            *ivs = super::uncertainty::above_ground(*ivs, m.ground_z);
        }
        if flat && doubted(&m.flags) && shadow_allows && !along_lean {
            // A shadow the town doubted already, against a clear lean it does not rule out: the
            // lean is the likelier (the town bench from 500 m: right in 9 of 11 such flat roofs).
            m.roof_z = Some(lean.z);
            m.height_m = Some(lean.z - m.ground_z);
        }
    }
}

/// Whether `f` doubts the shadow's height: its lines ran into something, disagree, or its
/// synthetic shadow matches poorly.
fn doubted(f: &super::Flags) -> bool {
    f.shadow_on_other_building
        || f.shadow_cut_by_edge_or_nodata
        || f.lines_disagree
        || f.estimates_disagree
        || f.poor_shadow_match
        || f.shadow_reaches_further
}

/// `m`, without a shadow height, given the lean's: flagged `height_from_lean`, a lower bound
/// seen kept in the 95 % interval, a pitched-looking roof's ridge up to `rise_m` above.
fn given_by_lean(m: &mut Measurement, lean: &LeanHeight, rise_m: f64) {
    let mut ivs = lean.ranges();
    if m.flags.pitched_roof {
        ivs[1].1 += rise_m;
    }
    if let Some(least) = m.roof_z_at_least.take() {
        ivs[1].1 = ivs[1].1.max(least);
    }
    m.roof_z = Some(lean.z);
    m.height_m = Some(lean.z - m.ground_z);
    m.roof_z_intervals = Some(super::uncertainty::above_ground(ivs, m.ground_z));
    m.flags.height_from_lean = true;
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shadow_height::Flags;

    /// A 10 m square footprint centred 300 m east of the nadir of a camera 500 m above ground
    /// at 100 m.
    fn setting() -> (Footprint, PerspectiveCentre) {
        let ring = vec![
            (295.0, -5.0),
            (305.0, -5.0),
            (305.0, 5.0),
            (295.0, 5.0),
            (295.0, -5.0),
        ];
        let camera = PerspectiveCentre {
            east: 0.0,
            north: 0.0,
            z: 600.0,
        };
        (Footprint::new(vec![vec![ring]]).unwrap(), camera)
    }

    /// The lean's height in [`setting`] of a roof `h` metres above the ground, whose lean is
    /// `300·h / (500 − h)` metres east.
    fn leaning(h: f64) -> LeanHeight {
        let (fp, cam) = setting();
        LeanHeight::new(&fp, (300.0 * h / (500.0 - h), 0.0), &cam, 100.0, 0.5).unwrap()
    }

    fn measured(roof_z: Option<f64>, flags: Flags) -> Measurement {
        Measurement {
            height_m: roof_z.map(|z| z - 100.0),
            roof_z,
            initial_height_m: None,
            overlap: None,
            uncertainty_m: 0.42,
            ground_z: 100.0,
            shadow_length_m: None,
            lines_total: 10,
            lines_used: 5,
            line_roofs: None,
            threshold: None,
            roof_z_intervals: roof_z.map(|z| [(z - 0.1, z + 0.1), (z - 0.2, z + 0.2)]),
            roof_z_at_least: None,
            flags,
            pitch: None,
        }
    }

    #[test]
    fn the_lean_gives_the_height_precisely_from_low_and_not_from_high() {
        let (fp, cam) = setting();
        // A 12 m roof leans 300·12/488 m.
        let l = 300.0 * 12.0 / 488.0;
        let h = LeanHeight::new(&fp, (l, 0.0), &cam, 100.0, 0.5).unwrap();
        assert!((h.z - 112.0).abs() < 1e-9, "{h:?}");
        assert!(h.sigma_m > 0.3 && h.sigma_m < 0.5, "{h:?}");
        // No lean, or from 3000 m: nothing.
        assert_eq!(LeanHeight::new(&fp, (0.0, 0.0), &cam, 100.0, 0.5), None);
        let high = PerspectiveCentre { z: 3100.0, ..cam };
        assert_eq!(LeanHeight::new(&fp, (1.2, 0.0), &high, 100.0, 0.5), None);
    }

    #[test]
    fn agreement_confirms_a_flat_roof_and_disagreement_flags_it() {
        let h = leaning(12.0);
        let doubted = Flags {
            shadow_on_other_building: true,
            shadow_cut_by_edge_or_nodata: true,
            ..Flags::default()
        };
        // The shadow says 112.2: confirmed, the doubts cleared, the interval still holds it.
        let mut m = measured(Some(112.2), doubted);
        meet(&mut m, &h, 3.0, false);
        assert!(m.flags.names().is_empty(), "{:?}", m.flags);
        let [a, b] = m.roof_z_intervals.unwrap();
        assert!(a.0 <= 112.2 && a.1 >= 112.2 && b.0 <= a.0 && b.1 >= a.1);
        // The shadow says 116: flagged, and the intervals reach the lean's height.
        let mut m = measured(Some(116.0), doubted);
        meet(&mut m, &h, 3.0, false);
        assert!(m.flags.lean_disagrees && m.flags.shadow_on_other_building);
        let [a, b] = m.roof_z_intervals.unwrap();
        assert!(a.0 < 112.0 && b.0 < a.0 && a.1 >= 116.0, "{a:?} {b:?}");
        // The shadow was doubted: the lean's height is reported, the interval holds both.
        assert_eq!(m.roof_z, Some(112.0));
        // An undoubted shadow keeps its height, flagged.
        let mut m = measured(Some(116.0), Flags::default());
        meet(&mut m, &h, 3.0, false);
        assert!(m.flags.lean_disagrees && m.roof_z == Some(116.0));
        // A pitched-looking roof is not confirmed by its eaves.
        let pitched = Flags {
            pitched_roof: true,
            ..doubted
        };
        let mut m = measured(Some(112.2), pitched);
        meet(&mut m, &h, 3.0, false);
        assert!(m.flags.shadow_on_other_building && !m.flags.lean_disagrees);
        // A footprint off its roof: its lean says nothing.
        let off = Flags {
            footprint_off_photo: true,
            ..doubted
        };
        let mut m = measured(Some(116.0), off);
        meet(&mut m, &h, 3.0, false);
        assert!(!m.flags.lean_disagrees);
    }

    /// A lean found on something else far out (the town from 500 m: 107 m for a 10 m gable)
    /// is flagged, never reported in place of a doubted shadow more than [`FAR_LEAN`] × lower.
    #[test]
    fn a_lean_far_above_the_shadow_s_evidence_is_not_taken_for_it() {
        let doubted = Flags {
            shadow_on_other_building: true,
            ..Flags::default()
        };
        // The shadow says 107 (7 m, 95 % up to 107.2: leans up to 14.4 m are taken); a 12 m
        // lean is taken.
        let h12 = leaning(12.0);
        let mut m = measured(Some(107.0), doubted);
        meet(&mut m, &h12, 3.0, false);
        assert_eq!(m.roof_z, Some(h12.z));
        // A 15 m one is not.
        let h = leaning(15.0);
        let mut m = measured(Some(107.0), doubted);
        meet(&mut m, &h, 3.0, false);
        assert!(m.flags.lean_disagrees && m.roof_z == Some(107.0), "{m:?}");
        assert!(m.roof_z_intervals.unwrap()[1].1 >= h.z);
    }

    /// A lean found by the narrow search along the line from the scene's misregistration
    /// ([`super::super::register::off_the_leans`]) confirms or doubts, never stands for a height.
    #[test]
    fn a_lean_sought_again_along_its_line_confirms_or_doubts_only() {
        let h = leaning(12.0);
        let doubted = Flags {
            shadow_on_other_building: true,
            ..Flags::default()
        };
        let mut m = measured(Some(112.2), doubted);
        meet(&mut m, &h, 3.0, true);
        assert!(m.flags.names().is_empty(), "{:?}", m.flags);
        let mut m = measured(Some(116.0), doubted);
        meet(&mut m, &h, 3.0, true);
        assert!(m.flags.lean_disagrees && m.roof_z == Some(116.0), "{m:?}");
        assert!(m.roof_z_intervals.unwrap()[1].0 <= h.z);
        let mut m = measured(None, doubted);
        meet(&mut m, &h, 3.0, true);
        assert!(m.roof_z.is_none() && !m.flags.height_from_lean, "{m:?}");
    }

    #[test]
    fn without_a_shadow_height_the_lean_gives_one_flagged() {
        let h = leaning(12.0);
        let cut = Flags {
            shadow_cut_by_edge_or_nodata: true,
            pitched_roof: true,
            ..Flags::default()
        };
        let mut m = measured(None, cut);
        m.roof_z_at_least = Some(130.0);
        meet(&mut m, &h, 3.0, false);
        assert_eq!(m.roof_z, Some(112.0));
        assert!(m.flags.height_from_lean && m.flags.shadow_cut_by_edge_or_nodata);
        let [a, b] = m.roof_z_intervals.unwrap();
        assert!(a.0 < 112.0 && a.1 > 112.0 && a.1 < 113.0, "{a:?}");
        // The ridge may be up to 3 m above the eaves, and the shadow was seen to reach 130.
        assert!(b.1 >= 130.0 && m.roof_z_at_least.is_none(), "{b:?}");
    }
}
