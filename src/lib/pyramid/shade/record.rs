//! The record of what a pyramid baked into its level-0 colours for a sun: asked for, applied,
//! skipped and why (the tile header's `effects`, the manifest's pyramid stage;
//! `schemas/pyramid-effects.schema.json`).

use super::situation;
use crate::pyramid::effects::{self, Situation, Skipped};
use crate::standing::Raised;
use crate::sun::Sun;
use serde::Serialize;

/// What the pyramid baked into the level-0 colours for a sun: the tile header's `effects` and
/// the manifest's pyramid stage hold it as JSON (`schemas/pyramid-effects.schema.json`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct EffectsRecord {
    /// The sun asked for; `None` when none was given.
    pub sun: Option<SunAngles>,
    /// The orthophoto's own sun, when the database records it (and a sun was asked for).
    pub photo_sun: Option<SunAngles>,
    /// Fraction of full-sun brightness left in shadow, (0, 1].
    pub shadow_factor: f64,
    /// The effects applied, in the order they are applied; empty when nothing was done.
    pub applied: Vec<&'static str>,
    /// The effects not applied, each with why ([`effects::decide`]).
    pub skipped: Vec<Skipped>,
    /// Why nothing was done, or the cells the prepared effects cover.
    #[serde(flatten)]
    pub outcome: Outcome,
}

/// A sun's direction in an [`EffectsRecord`], degrees.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct SunAngles {
    /// Above the horizon.
    pub elevation_deg: f64,
    /// Clockwise from grid north, toward the sun.
    pub azimuth_deg: f64,
}

impl From<Sun> for SunAngles {
    fn from(s: Sun) -> SunAngles {
        SunAngles {
            elevation_deg: s.elevation_deg,
            azimuth_deg: s.azimuth_deg,
        }
    }
}

/// The cell counts of an [`EffectsRecord`] whose effects were prepared, over the whole grid or a
/// part of it ([`Effects::counts_in`](super::Effects::counts_in)): the whole grid's are the sums of its parts'.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, serde::Deserialize)]
pub struct Counts {
    /// Cells in the new surface's cast shadow; `None` when not cast.
    pub shadow_cells: Option<usize>,
    /// Cells in the cast for the photo's sun over the surface the photo saw; `None` when not
    /// cast.
    pub photo_shadow_cells: Option<usize>,
    /// Cells of the photo's shadows as found in the photo; `None` when not detected.
    pub detected_photo_shadow_cells: Option<usize>,
    /// Raised cells with an exposed vertical face.
    pub wall_cells: usize,
}

impl std::ops::Add for Counts {
    type Output = Counts;
    fn add(self, o: Counts) -> Counts {
        let add = add_optional;
        Counts {
            shadow_cells: add(self.shadow_cells, o.shadow_cells),
            photo_shadow_cells: add(self.photo_shadow_cells, o.photo_shadow_cells),
            detected_photo_shadow_cells: add(
                self.detected_photo_shadow_cells,
                o.detected_photo_shadow_cells,
            ),
            wall_cells: self.wall_cells + o.wall_cells,
        }
    }
}

/// The sum of two counts either of which may be absent (not made): absent only when both are.
pub fn add_optional<T: std::ops::Add<Output = T> + Default>(
    a: Option<T>,
    b: Option<T>,
) -> Option<T> {
    match (a, b) {
        (None, None) => None,
        (a, b) => Some(a.unwrap_or_default() + b.unwrap_or_default()),
    }
}

/// How an [`EffectsRecord`] ends: nothing to do and why, or cell counts of what was prepared.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(untagged)]
pub enum Outcome {
    /// No sun given, or the photo's own sun with nothing the photo did not see.
    Skipped {
        /// Why, in words.
        reason: &'static str,
    },
    /// Effects were prepared: the cells they cover.
    Prepared(Counts),
}

impl EffectsRecord {
    /// This record with the sensor layers `asked` for (in the tile set's order) and the light
    /// points when there are `lights` among the applied, after the sun's effects, and the
    /// others among the skipped ([`effects::decide_layers`]).
    pub fn with_layers(
        mut self,
        asked: &[crate::tiles::SensorLayer],
        lights: bool,
    ) -> EffectsRecord {
        let (made, not) = effects::decide_layers(asked, lights);
        self.applied.extend(made);
        self.skipped.extend(not);
        self
    }

    /// The record when no sun was given or nothing was needed: which sun, nothing applied, and
    /// why each effect was not (over `buildings` and `objects`).
    pub fn none(
        sun: Option<Sun>,
        photo_sun: Option<Sun>,
        shadow_factor: f64,
        buildings: &Raised,
        objects: &Raised,
    ) -> EffectsRecord {
        let seen = situation(sun, photo_sun, buildings, objects);
        EffectsRecord::decided(sun, photo_sun, shadow_factor, &seen, None)
    }

    /// The record of what the registry decided on, `seen`: with the `counts` of the effects
    /// prepared, or `None` when nothing was (and why).
    pub fn decided(
        sun: Option<Sun>,
        photo_sun: Option<Sun>,
        shadow_factor: f64,
        seen: &Situation,
        counts: Option<Counts>,
    ) -> EffectsRecord {
        let (applied, skipped) = effects::decide(seen);
        let outcome = match counts {
            Some(counts) => Outcome::Prepared(counts),
            None => {
                debug_assert!(applied.is_empty(), "prepare runs whenever an effect would");
                Outcome::Skipped {
                    reason: match sun {
                        None => "no sun given",
                        Some(_) => "the photo's own sun and nothing the photo did not see",
                    },
                }
            }
        };
        EffectsRecord {
            sun: sun.map(SunAngles::from),
            photo_sun: photo_sun.map(SunAngles::from),
            shadow_factor,
            applied,
            skipped,
            outcome,
        }
    }
}
