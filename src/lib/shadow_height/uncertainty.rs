//! How sure a measured roof is: its plausible range at 68 % and 95 %, and a lower bound where
//! only a lower bound is seen.
//!
//! Invariant: every interval holds the reported roof and lies above the footprint's ground,
//! the 95 % one holds the 68 % one, and
//! evidence the refinement did not follow widens them rather than being dropped:
//! * **the fit** ([`refine::Refined::plausible`]): the heights whose synthetic shadow explains
//!   the photo within its noise (a profile likelihood over every height, so an interval can be
//!   lopsided, or wide where the photo cannot tell heights apart: a faint shadow, a shadow a
//!   cell or two long under a high sun);
//! * **the edges' place**: a footprint is registered to the photo in eighths of a cell and an
//!   edge's cover is read from mixed cells, so the wall the shadow starts from is known to
//!   about [`EDGE_CELLS`] of a cell — `EDGE_CELLS · cell · tan(e)` of height, one standard
//!   error, added in quadrature on each side;
//! * **the scan lines**: each valid line implies a roof over the real terrain; their middle
//!   half is in the 68 % interval and [`LINE_FENCE`] interquartile ranges beyond it in the
//!   95 % one (lines that agree add nothing; lines split by a neighbour, a tree or a car
//!   widen it; a refinement away from their median, `estimates_disagree`, so has the median
//!   in its 68 % interval);
//! * **a poor match** of the synthetic and the observed shadow (`poor_shadow_match`): the fit
//!   explains little of the photo, so the 95 % interval is every height sought, from the
//!   ground to `--max-height`;
//! * **a roof that looks pitched but whose pitch neither the shadow nor the faces' shading
//!   tells** (`pitched_roof` still set): the height measured is the eaves' or between eaves
//!   and ridge, so the 95 % interval reaches the highest roof the refinement searched, or the
//!   ridge of the steepest pitch sought over it if higher;
//! * **a shadow seen to reach further** (`shadow_reaches_further`): lines dropped where the
//!   shadow ran into a neighbour or the grid's edge saw it reach a higher roof ([`at_least`])
//!   than the valid lines say: that roof enters the 68 % interval, and the 95 % one is every
//!   height sought. So a flag is a reason attached to a wide interval.
//!
//! A lower bound ([`at_least`]) comes from the scan lines whose shadow ran into something that
//! hides its end — another building, the grid's edge, nodata: the shadow reached at least
//! there.
//!
//! The constants ([`EDGE_CELLS`], [`LINE_FENCE`], [`refine::NOISE_INFLATION`]) are calibrated
//! on the POV-Ray harnesses so that truth falls outside the 95 % interval for at most 5 % of
//! the buildings (docs/shadow-height.md, "Heights with their uncertainty").

use super::refine::{self, PLAUSIBLE_SIGMAS};
use super::scan::{self, Scan};
use super::{Measurement, MIN_VALID_LINES};

/// How well the walls a shadow starts from are placed, in cells, one standard error: the
/// registration's eighth of a cell and the cover read from the edge's mixed cells.
pub const EDGE_CELLS: f64 = 0.15;

/// The 68 % and 95 % intervals of the roof of `m` (absolute metres), measured with `m.flags`
/// and `m.line_roofs` set, from the refinement `r` and the dropped lines' lower bound `least`
/// ([`at_least`], absolute metres); `[searched_m, max_height_m]` are the highest roof a
/// pitched-looking roof may have (what the refinement searched, or a steep pitch's ridge) and
/// the tallest building sought (metres above the ground).
pub fn intervals(
    m: &Measurement,
    r: &refine::Refined,
    least: Option<f64>,
    [searched_m, max_height_m]: [f64; 2],
) -> [(f64, f64); 2] {
    let roof = m.ground_z + r.height_m;
    let edge = EDGE_CELLS * m.uncertainty_m;
    let mut out: [(f64, f64); 2] = std::array::from_fn(|k| {
        let (lo, hi) = r.plausible[k];
        let pad = PLAUSIBLE_SIGMAS[k] * edge;
        (
            roof - (roof - m.ground_z - lo).max(0.0).hypot(pad),
            roof + (m.ground_z + hi - roof).max(0.0).hypot(pad),
        )
    });
    let take = |iv: &mut (f64, f64), z: f64| *iv = (iv.0.min(z), iv.1.max(z));
    if let Some([q1, _, q3]) = m.line_roofs {
        take(&mut out[0], q1);
        take(&mut out[0], q3);
        let fence = LINE_FENCE * (q3 - q1);
        take(&mut out[1], q1 - fence);
        take(&mut out[1], q3 + fence);
    }
    if m.flags.shadow_reaches_further {
        if let Some(z) = least {
            take(&mut out[0], z);
        }
    }
    if m.flags.pitched_roof {
        take(&mut out[1], m.ground_z + searched_m);
    }
    if m.flags.poor_shadow_match || m.flags.shadow_reaches_further {
        take(&mut out[1], m.ground_z);
        take(&mut out[1], m.ground_z + max_height_m);
    }
    // Nested: the 95 % interval holds the 68 % one.
    let inner = out[0];
    take(&mut out[1], inner.0);
    take(&mut out[1], inner.1);
    above_ground(out, m.ground_z)
}

/// `ivs` (absolute metres) with no end below `ground_z`: a roof is not below its own ground,
/// however far the lines' fences or a second estimate reach.
pub fn above_ground(ivs: [(f64, f64); 2], ground_z: f64) -> [(f64, f64); 2] {
    ivs.map(|(lo, hi)| (lo.max(ground_z), hi.max(ground_z)))
}

/// How far beyond the scan lines' middle half the 95 % interval reaches, in interquartile
/// ranges (Tukey's fences): lines that disagree are evidence the refinement may have followed
/// the wrong ones.
pub const LINE_FENCE: f64 = 1.5;

/// The lowest roof (absolute metres) the dropped scan lines of `s` show, for a footprint on
/// ground `ground_z` (metres) whose shadow could not be measured to its end: the median of
/// the lines' [`Scan::reached_roofs`], when at least [`MIN_VALID_LINES`] lines reached above
/// the ground. `None` otherwise.
pub fn at_least(s: &Scan, ground_z: f64) -> Option<f64> {
    let above: Vec<f64> = s
        .reached_roofs
        .iter()
        .copied()
        .filter(|&z| z > ground_z)
        .collect();
    (above.len() >= MIN_VALID_LINES)
        .then(|| scan::median(&above))
        .flatten()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shadow_height::Flags;

    fn measured(flags: Flags) -> Measurement {
        Measurement {
            height_m: Some(10.0),
            roof_z: Some(110.0),
            initial_height_m: Some(10.0),
            overlap: Some(0.9),
            uncertainty_m: 0.5,
            ground_z: 100.0,
            shadow_length_m: Some(10.0),
            lines_total: 10,
            lines_used: 10,
            line_roofs: None,
            threshold: None,
            roof_z_intervals: None,
            pitch: None,
            roof_z_at_least: None,
            flags,
        }
    }

    fn refined(plausible: [(f64, f64); 2]) -> refine::Refined {
        refine::Refined {
            height_m: 10.0,
            overlap: 0.9,
            plausible,
        }
    }

    #[test]
    fn a_sharp_fit_is_as_sure_as_its_edges_and_a_loose_one_as_its_fit() {
        let m = measured(Flags::default());
        // The fit pins the height to a point: the edges' place is all that is left.
        let [a, b] = intervals(&m, &refined([(10.0, 10.0); 2]), None, [150.0; 2]);
        let edge = EDGE_CELLS * 0.5;
        assert!((a.0 - (110.0 - edge)).abs() < 1e-12 && (a.1 - (110.0 + edge)).abs() < 1e-12);
        assert!((b.1 - (110.0 + 1.96 * edge)).abs() < 1e-12);
        // A lopsided fit stays lopsided, widened a little by the edges.
        let [a, b] = intervals(&m, &refined([(9.0, 13.0), (7.0, 16.0)]), None, [150.0; 2]);
        assert!(
            a.0 < 109.0 && a.0 > 108.99 && a.1 > 113.0 && a.1 < 113.01,
            "{a:?}"
        );
        assert!(b.0 < 107.0 && b.1 > 116.0, "{b:?}");
    }

    #[test]
    fn the_lines_and_the_flags_widen_the_interval_to_hold_their_evidence() {
        let tight = refined([(10.0, 10.0); 2]);
        let mut m = measured(Flags::default());
        m.line_roofs = Some([108.0, 111.0, 112.0]);
        let [a, b] = intervals(&m, &tight, None, [150.0; 2]);
        assert_eq!((a.0, a.1), (108.0, 112.0));
        assert_eq!((b.0, b.1), (108.0 - 6.0, 112.0 + 6.0));
        // Lines that agree add nothing.
        m.line_roofs = Some([110.0; 3]);
        let [a, _] = intervals(&m, &tight, None, [150.0; 2]);
        assert!(a.1 - a.0 < 0.2, "{a:?}");
        // A refinement away from the lines takes their median into the 68 % interval.
        m.line_roofs = Some([104.0, 104.5, 105.0]);
        m.flags.estimates_disagree = true;
        let [a, b] = intervals(&m, &tight, None, [150.0; 2]);
        assert!(a.0 <= 104.0 && b.0 <= 102.5, "{a:?} {b:?}");
        // A poor match of the shadows: anything from the ground to the tallest sought.
        let poor = Flags {
            poor_shadow_match: true,
            ..Flags::default()
        };
        let [a, b] = intervals(&measured(poor), &tight, None, [150.0; 2]);
        assert!(a.1 - a.0 < 0.2, "{a:?}");
        assert_eq!((b.0, b.1), (100.0, 250.0));
        // Dropped lines saw the shadow reach a higher roof: it is in the 68 % interval.
        let further = Flags {
            shadow_reaches_further: true,
            ..Flags::default()
        };
        let [a, b] = intervals(&measured(further), &tight, Some(117.0), [150.0; 2]);
        assert_eq!(a.1, 117.0);
        assert_eq!((b.0, b.1), (100.0, 250.0));
        // Lines split far apart: their fences stop at the ground (a roof is not below it).
        m.flags = Flags::default();
        m.line_roofs = Some([101.0, 110.0, 116.0]);
        let [a, b] = intervals(&m, &tight, None, [150.0; 2]);
        assert_eq!((a.0, b.0), (101.0, 100.0));
        assert_eq!(b.1, 116.0 + 1.5 * 15.0);
    }

    #[test]
    fn a_lower_bound_needs_enough_lines_above_the_ground() {
        let mut s = Scan {
            reached_roofs: vec![99.0, 112.0, 115.0],
            ..Scan::default()
        };
        assert_eq!(at_least(&s, 100.0), None);
        s.reached_roofs.push(113.0);
        assert_eq!(at_least(&s, 100.0), Some(113.0));
    }
}
