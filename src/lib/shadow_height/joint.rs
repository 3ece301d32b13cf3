//! The joint passes (issue 39): a town's footprints measured together, each with the others
//! at the roofs measured so far.
//!
//! Invariant: a joint pass reads only the results of the pass before it, for every footprint
//! at once (never a result of the same pass), so the order of the footprints changes nothing.
//! What it knows of each other footprint ([`Known`]) enters a footprint's measurement two
//! ways: the ground its shadow covers is unusable (it hides this footprint's shadow, it does
//! not end it), and its roof, where measured flat and sure, is a surface this footprint's
//! shadow may lie on (`super::refine::corridor`). So a shadow that climbs a lower
//! neighbour's wall and lies on its roof is evidence of the height, not a reason to drop the
//! scan line; and a shadow that disappears into a taller neighbour's is censored, its fit
//! free over every height the hidden part allows (the interval says how far).

use super::{Measurement, MIN_OVERLAP};

/// Whether a footprint measured in the second pass is measured again in the joint passes:
/// its shadow ran into another footprint, or it got no height while some of its scan lines
/// were dropped (a shadow cut by a neighbour's shadow, which the neighbours' measured roofs
/// place better than their first sketch).
pub fn wanted(m: &Measurement) -> bool {
    m.flags.shadow_on_other_building || (m.roof_z.is_none() && m.flags.shadow_cut_by_edge_or_nodata)
}

/// How many cells of shadow, as height, a roof's 95 % interval may span for the roof to be a
/// surface others' shadows are fitted on ([`Known::surfaces`]): a roof known to about a cell.
pub const SURFACE_INTERVAL_CELLS: f64 = 4.0;

/// What a joint pass knows of every footprint, from the pass before it.
#[derive(Debug, Clone, PartialEq)]
pub struct Known<'a> {
    /// Per footprint, the roof (absolute metres) whose shadow makes the ground unusable for
    /// the others: the one measured plus its uncertainty (one cell of shadow), else the first
    /// pass's sketch (as given).
    pub shading: Vec<Option<f64>>,
    /// Per footprint, its roof (absolute metres) where it is a surface others' shadows are
    /// fitted on: measured flat, unflagged by anything that makes the roof itself doubtful
    /// (a pitch, a poor match, a shadow reaching further, an outline off its roof), and its
    /// 95 % interval at most [`SURFACE_INTERVAL_CELLS`] cells of shadow wide.
    pub surfaces: Vec<Option<f64>>,
    /// Per footprint, its result in the pass before: what a joint pass keeps for a footprint
    /// whose corridor holds no known roof (the ground alone says nothing new there; measured
    /// again over the whole corridor, the town's 12° photos got more heights, but fewer
    /// right).
    pub previous: &'a [std::result::Result<Measurement, String>],
}

impl<'a> Known<'a> {
    /// What the results `measured` (one per footprint) say, with `sketched` the first pass's
    /// shading roofs for the footprints measured without a height.
    pub fn from(
        measured: &'a [std::result::Result<Measurement, String>],
        sketched: &[Option<f64>],
    ) -> Known<'a> {
        let ok = |k: usize| measured[k].as_ref().ok();
        let shading = (0..measured.len())
            .map(|k| {
                ok(k)
                    .and_then(|m| Some(m.roof_z? + m.uncertainty_m))
                    .or(sketched[k])
            })
            .collect();
        let surfaces = (0..measured.len())
            .map(|k| ok(k).and_then(surface))
            .collect();
        Known {
            shading,
            surfaces,
            previous: measured,
        }
    }
}

/// The roof of `m` (absolute metres) where it is a surface for the others ([`Known::surfaces`]).
fn surface(m: &Measurement) -> Option<f64> {
    let f = &m.flags;
    let doubtful = m.pitch.is_some()
        || f.pitched_roof
        || f.poor_shadow_match
        || f.shadow_reaches_further
        || f.footprint_off_photo
        || m.overlap.is_some_and(|o| o < MIN_OVERLAP);
    let [_, (lo, hi)] = m.roof_z_intervals?;
    let sure = hi - lo <= SURFACE_INTERVAL_CELLS * m.uncertainty_m;
    (!doubtful && sure).then_some(m.roof_z?)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shadow_height::Flags;

    fn measured(roof_z: Option<f64>, flags: Flags, interval: (f64, f64)) -> Measurement {
        Measurement {
            height_m: roof_z.map(|z| z - 100.0),
            roof_z,
            initial_height_m: None,
            overlap: Some(0.9),
            uncertainty_m: 0.5,
            ground_z: 100.0,
            shadow_length_m: None,
            lines_total: 10,
            lines_used: 10,
            line_roofs: None,
            threshold: None,
            roof_z_intervals: roof_z.map(|_| [interval; 2]),
            roof_z_at_least: None,
            flags,
            pitch: None,
        }
    }

    #[test]
    fn only_sure_flat_roofs_are_surfaces_and_every_roof_shades() {
        let sure = measured(Some(110.0), Flags::default(), (109.5, 110.5));
        let wide = measured(Some(112.0), Flags::default(), (105.0, 119.0));
        let poor = measured(
            Some(114.0),
            Flags {
                poor_shadow_match: true,
                ..Flags::default()
            },
            (113.9, 114.1),
        );
        let none = measured(None, Flags::default(), (0.0, 0.0));
        let results = [
            Ok(sure),
            Ok(wide),
            Ok(poor),
            Ok(none),
            Err("off the grid".into()),
        ];
        let known = Known::from(&results, &[None, None, None, Some(120.0), Some(130.0)]);
        assert_eq!(known.surfaces, vec![Some(110.0), None, None, None, None]);
        assert_eq!(
            known.shading,
            vec![
                Some(110.5),
                Some(112.5),
                Some(114.5),
                Some(120.0),
                Some(130.0)
            ]
        );
    }

    #[test]
    fn wanted_are_the_shadows_that_met_a_neighbour_and_the_cut_ones_without_a_height() {
        let flags = |on_other, cut| Flags {
            shadow_on_other_building: on_other,
            shadow_cut_by_edge_or_nodata: cut,
            ..Flags::default()
        };
        let i = (109.5, 110.5);
        assert!(wanted(&measured(Some(110.0), flags(true, false), i)));
        assert!(wanted(&measured(None, flags(false, true), i)));
        assert!(!wanted(&measured(Some(110.0), flags(false, true), i)));
        assert!(!wanted(&measured(None, flags(false, false), i)));
    }
}
