//! How sure a measured roof is: its plausible range at 68 % and 95 %, and a lower bound where
//! only a lower bound is seen.
//!
//! Invariant: every interval holds the reported roof, the 95 % one holds the 68 % one, and
//! evidence the refinement did not follow widens them rather than being dropped:
//! * **the fit** ([`refine::Refined::plausible`]): the heights whose synthetic shadow explains
//!   the photo within its noise (a profile likelihood over every height, so an interval can be
//!   lopsided, or wide where the photo cannot tell heights apart: a faint shadow, a shadow a
//!   cell or two long under a high sun);
//! * **the edges' place**: a footprint is registered to the photo in eighths of a cell and an
//!   edge's cover is read from mixed cells, so the wall the shadow starts from is known to
//!   about [`EDGE_CELLS`] of a cell — `EDGE_CELLS · cell · tan(e)` of height, one standard
//!   error, added in quadrature on each side;
//! * **the checks** that flag a height: a refinement away from the scan lines' roof
//!   (`estimates_disagree`) takes that roof into both intervals; lines that disagree with each
//!   other (`lines_disagree`) put their middle half into the 95 % one; a poor match of the
//!   shadows (`poor_shadow_match`) widens the 95 % one by [`AGREE_CELLS`] cells of shadow each
//!   way. So a flag is a reason attached to a wide interval.
//!
//! A lower bound ([`at_least`]) comes from the scan lines whose shadow ran into something that
//! hides its end — another building, the grid's edge, nodata: the shadow reached at least
//! there.
//!
//! The constants ([`EDGE_CELLS`], [`refine::NOISE_INFLATION`]) are calibrated on the POV-Ray
//! harnesses so that truth falls outside the 95 % interval for at most 5 % of the buildings
//! (docs/shadow-height.md, "Heights with their uncertainty").

use super::refine::{self, PLAUSIBLE_SIGMAS};
use super::scan::{self, Scan};
use super::{Measurement, AGREE_CELLS, MIN_VALID_LINES};

/// How well the walls a shadow starts from are placed, in cells, one standard error: the
/// registration's eighth of a cell and the cover read from the edge's mixed cells.
pub const EDGE_CELLS: f64 = 0.15;

/// The 68 % and 95 % intervals of the roof of `m` (absolute metres), measured with `m.flags`
/// set, from the refinement `r` and the roofs its valid scan lines imply (`line_roofs`,
/// absolute metres, finite).
pub fn intervals(m: &Measurement, r: &refine::Refined, line_roofs: &[f64]) -> [(f64, f64); 2] {
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
    if m.flags.estimates_disagree {
        if let Some(ray_roof) = scan::median(line_roofs) {
            out.iter_mut().for_each(|iv| take(iv, ray_roof));
        }
    }
    if m.flags.lines_disagree {
        for q in [0.25, 0.75] {
            if let Some(z) = scan::quantile(line_roofs, q) {
                take(&mut out[1], z);
            }
        }
    }
    if m.flags.poor_shadow_match {
        let tol = AGREE_CELLS * m.uncertainty_m;
        out[1] = (out[1].0 - tol, out[1].1 + tol);
    }
    // Nested: the 95 % interval holds the 68 % one.
    let inner = out[0];
    take(&mut out[1], inner.0);
    take(&mut out[1], inner.1);
    out
}

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
            threshold: None,
            roof_z_intervals: None,
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
        let lines = [110.0; 8];
        // The fit pins the height to a point: the edges' place is all that is left.
        let [a, b] = intervals(&m, &refined([(10.0, 10.0); 2]), &lines);
        let edge = EDGE_CELLS * 0.5;
        assert!((a.0 - (110.0 - edge)).abs() < 1e-12 && (a.1 - (110.0 + edge)).abs() < 1e-12);
        assert!((b.1 - (110.0 + 1.96 * edge)).abs() < 1e-12);
        // A lopsided fit stays lopsided, widened a little by the edges.
        let [a, b] = intervals(&m, &refined([(9.0, 13.0), (7.0, 16.0)]), &lines);
        assert!(
            a.0 < 109.0 && a.0 > 108.99 && a.1 > 113.0 && a.1 < 113.01,
            "{a:?}"
        );
        assert!(b.0 < 107.0 && b.1 > 116.0, "{b:?}");
    }

    #[test]
    fn a_flag_widens_the_interval_to_hold_the_evidence_it_names() {
        let lines = [104.0, 104.5, 105.0, 110.0, 111.0, 118.0];
        let tight = refined([(10.0, 10.0); 2]);
        let disagree = Flags {
            estimates_disagree: true,
            ..Flags::default()
        };
        let [a, b] = intervals(&measured(disagree), &tight, &lines);
        let ray_roof = scan::median(&lines).unwrap();
        assert!(a.0 <= ray_roof && b.0 <= ray_roof, "{a:?} {b:?}");
        let scattered = Flags {
            lines_disagree: true,
            ..Flags::default()
        };
        let [a, b] = intervals(&measured(scattered), &tight, &lines);
        assert!(a.0 > 109.0, "{a:?}");
        assert!(b.0 <= 104.5 && b.1 >= 111.0, "{b:?}");
        let poor = Flags {
            poor_shadow_match: true,
            ..Flags::default()
        };
        let [_, b] = intervals(&measured(poor), &tight, &lines);
        assert!(b.0 <= 110.0 - AGREE_CELLS * 0.5 && b.1 >= 110.0 + AGREE_CELLS * 0.5);
    }

    #[test]
    fn a_lower_bound_needs_enough_lines_above_the_ground() {
        let mut s = Scan::default();
        s.reached_roofs = vec![99.0, 112.0, 115.0];
        assert_eq!(at_least(&s, 100.0), None);
        s.reached_roofs.push(113.0);
        assert_eq!(at_least(&s, 100.0), Some(113.0));
    }
}
