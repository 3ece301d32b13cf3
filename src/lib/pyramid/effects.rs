//! The effects registry: every effect the pyramid can bake into a database, what it needs, which
//! sensors call for it and what it produces, and the one decision of which run for a build;
//! likewise the sensor layers a tile file may carry ([`LAYERS`]).
//!
//! Invariant: [`decide`] is the only place that says whether an effect runs, and
//! [`decide_layers`] whether a sensor layer is made; an effect runs exactly when every one of
//! its needs holds, in the order of [`EFFECTS`], a layer exactly when it is asked for, and
//! every effect or layer that is not is reported with why, in words. The sensor column is
//! `../shared/reference/README.md`'s effect-by-sensor table (RADC-TR-81-190): the day visual
//! channel calls for all the effects; the infrared, night-vision and radar channels for the
//! layers.

use crate::tiles::SensorLayer;
use serde::Serialize;

/// What an effect needs of a build.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Need {
    /// A sun was asked for.
    Sun,
    /// The sun differs from the orthophoto's own (or the photo's sun is unknown).
    NewSun,
    /// The sun is the orthophoto's own.
    PhotosOwnSun,
    /// The orthophoto's sun is known (the database records when it was taken).
    PhotoSunKnown,
    /// Objects are placed in the database.
    Objects,
    /// Something stands on the terrain: buildings or placed objects.
    Raised,
}

impl Need {
    /// Whether the need holds in `s`.
    fn holds(self, s: &Situation) -> bool {
        match self {
            Need::Sun => s.sun,
            Need::NewSun => !s.same_sun,
            Need::PhotosOwnSun => s.same_sun,
            Need::PhotoSunKnown => s.photo_sun,
            Need::Objects => s.objects,
            Need::Raised => s.buildings || s.objects,
        }
    }

    /// Why an effect with this need does not run when it fails.
    fn unmet(self) -> &'static str {
        match self {
            Need::Sun => "no sun given",
            Need::NewSun => "the photo's own sun: the photo already shows it",
            Need::PhotosOwnSun => {
                "a new sun: cast_shadows casts the objects' shadows with the rest"
            }
            Need::PhotoSunKnown => "the photo's sun is unknown (no photo time in the database)",
            Need::Objects => "no objects placed",
            Need::Raised => "nothing stands on the terrain",
        }
    }
}

/// One effect.
#[derive(Debug, Clone, Copy)]
pub struct Effect {
    /// Its name in effects records.
    pub name: &'static str,
    /// What it does, in a few words.
    pub does: &'static str,
    /// What must hold for it to run.
    pub needs: &'static [Need],
    /// The sensors whose products call for it.
    pub sensors: &'static [&'static str],
    /// What it changes in the database.
    pub produces: &'static str,
}

/// Every effect, in the order the pyramid applies them.
pub const EFFECTS: [Effect; 8] = [
    Effect {
        name: "cast_shadows",
        does: "shadows of terrain, buildings and objects for the sun",
        needs: &[Need::Sun, Need::NewSun],
        sensors: &["visual"],
        produces: "level-0 colour darkened by the shadow factor",
    },
    Effect {
        name: "terrain_lambert",
        does: "slopes shaded for the sun",
        needs: &[Need::Sun, Need::NewSun],
        sensors: &["visual"],
        produces: "level-0 colour scaled by the illumination",
    },
    Effect {
        name: "photo_shadow_detection",
        does: "the photo's own shadows found in its colours",
        needs: &[Need::Sun, Need::NewSun, Need::PhotoSunKnown],
        sensors: &["visual"],
        produces: "a mask of the photo's ground shadows",
    },
    Effect {
        name: "photo_shadow_compensation",
        does: "the photo's shadows brightened away",
        needs: &[Need::Sun, Need::NewSun, Need::PhotoSunKnown],
        sensors: &["visual"],
        produces: "level-0 colour brightened by the inverse shadow factor",
    },
    Effect {
        name: "photo_shading_compensation",
        does: "the photo's slope shading divided out",
        needs: &[Need::Sun, Need::NewSun, Need::PhotoSunKnown],
        sensors: &["visual"],
        produces: "level-0 colour divided by the photo's illumination",
    },
    Effect {
        name: "object_shadows",
        does: "shadows of placed objects, which the photo does not show",
        needs: &[Need::Sun, Need::PhotosOwnSun, Need::Objects],
        sensors: &["visual"],
        produces: "level-0 colour darkened where objects cast",
    },
    Effect {
        name: "wall_shading",
        does: "walls of buildings and objects shaded by their facing",
        needs: &[Need::Sun, Need::Raised],
        sensors: &["visual"],
        produces: "wall cells' colour",
    },
    Effect {
        name: "object_shading",
        does: "placed objects' tops shaded for the sun",
        needs: &[Need::Sun, Need::Objects],
        sensors: &["visual"],
        produces: "object cells' colour",
    },
];

/// A sensor layer a tile file may carry (or its light points), as the registry lists it
/// beside the effects.
#[derive(Debug, Clone, Copy)]
pub struct LayerEffect {
    /// The tile layer; `None` for the light points of the header.
    pub layer: Option<SensorLayer>,
    /// Its name in effects records.
    pub name: &'static str,
    /// The sensors whose products call for it.
    pub sensors: &'static [&'static str],
    /// Why it is not made when not asked for.
    pub unasked: &'static str,
}

/// Every sensor layer, in the tile set's order. None is made unless asked for: a visual
/// product does no sensor work, and its record says so.
pub const LAYERS: [LayerEffect; 6] = [
    LayerEffect {
        layer: Some(SensorLayer::Material),
        name: "material_layer",
        sensors: &["ir", "nvg", "radar"],
        unasked: "not asked for (--materials)",
    },
    LayerEffect {
        layer: Some(SensorLayer::Temperature),
        name: "temperature_layer",
        sensors: &["ir"],
        unasked: "no temperature map given (--temperature)",
    },
    LayerEffect {
        layer: Some(SensorLayer::Radiance),
        name: "radiance_layer",
        sensors: &["ir"],
        unasked: "no radiance map given (--radiance)",
    },
    LayerEffect {
        layer: Some(SensorLayer::Backscatter),
        name: "backscatter_layer",
        sensors: &["radar"],
        unasked: "no backscatter map given (--backscatter)",
    },
    LayerEffect {
        layer: Some(SensorLayer::Normal),
        name: "normal_layer",
        sensors: &["radar"],
        unasked: "not asked for (--normals)",
    },
    LayerEffect {
        layer: None,
        name: "light_points",
        sensors: &["nvg"],
        unasked: "no light points given (--lights)",
    },
];

/// Which sensor layers a build makes (those `asked`, in order, and the light points when it
/// has `lights`) and which not, with why.
pub fn decide_layers(asked: &[SensorLayer], lights: bool) -> (Vec<&'static str>, Vec<Skipped>) {
    let (made, not): (Vec<&LayerEffect>, Vec<_>) = LAYERS.iter().partition(|l| match l.layer {
        Some(layer) => asked.contains(&layer),
        None => lights,
    });
    let skipped = not.iter().map(|l| Skipped {
        effect: l.name,
        why: l.unasked,
    });
    (made.iter().map(|l| l.name).collect(), skipped.collect())
}

/// What a build has to work with.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Situation {
    /// A sun was asked for.
    pub sun: bool,
    /// The orthophoto's sun is known.
    pub photo_sun: bool,
    /// The sun asked for is the photo's own.
    pub same_sun: bool,
    /// Buildings stand on the terrain.
    pub buildings: bool,
    /// Objects are placed.
    pub objects: bool,
}

/// An effect that does not run, and why.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Skipped {
    /// The effect's name.
    pub effect: &'static str,
    /// The first of its needs that failed, in words.
    pub why: &'static str,
}

/// Which effects run in `situation` (in order) and which do not, with why.
pub fn decide(situation: &Situation) -> (Vec<&'static str>, Vec<Skipped>) {
    let mut run = Vec::new();
    let mut skipped = Vec::new();
    for e in &EFFECTS {
        match e.needs.iter().find(|n| !n.holds(situation)) {
            None => run.push(e.name),
            Some(n) => skipped.push(Skipped {
                effect: e.name,
                why: n.unmet(),
            }),
        }
    }
    (run, skipped)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn situation(bits: u8) -> Situation {
        Situation {
            sun: bits & 1 != 0,
            photo_sun: bits & 2 != 0,
            same_sun: bits & 4 != 0 && bits & 2 != 0 && bits & 1 != 0,
            buildings: bits & 8 != 0,
            objects: bits & 16 != 0,
        }
    }

    /// The rule the pyramid applied before the registry, written out as it was.
    fn as_before(s: &Situation) -> Vec<&'static str> {
        let mut applied = Vec::new();
        if !s.sun || (s.same_sun && !s.buildings && !s.objects) {
            return applied;
        }
        if !s.same_sun {
            applied.extend(["cast_shadows", "terrain_lambert"]);
            if s.photo_sun {
                applied.extend([
                    "photo_shadow_detection",
                    "photo_shadow_compensation",
                    "photo_shading_compensation",
                ]);
            }
        } else if s.objects {
            applied.push("object_shadows");
        }
        if s.buildings || s.objects {
            applied.push("wall_shading");
        }
        if s.objects {
            applied.push("object_shading");
        }
        applied
    }

    #[test]
    fn every_situation_runs_what_the_pyramid_ran_and_says_why_the_rest_did_not() {
        for bits in 0..32 {
            let s = situation(bits);
            let (run, skipped) = decide(&s);
            assert_eq!(run, as_before(&s), "{s:?}");
            assert_eq!(run.len() + skipped.len(), EFFECTS.len());
            if !s.sun {
                assert!(skipped.iter().all(|k| k.why == "no sun given"));
            }
        }
    }

    #[test]
    fn layers_are_made_only_when_asked_for_and_in_the_tile_sets_order() {
        let (made, skipped) = decide_layers(&[], false);
        assert!(made.is_empty());
        assert_eq!(skipped.len(), LAYERS.len());
        let asked = [SensorLayer::Temperature, SensorLayer::Material];
        let (made, skipped) = decide_layers(&asked, true);
        assert_eq!(
            made,
            ["material_layer", "temperature_layer", "light_points"]
        );
        assert_eq!(skipped[0].effect, "radiance_layer");
        let order: Vec<SensorLayer> = LAYERS.iter().filter_map(|l| l.layer).collect();
        assert_eq!(order, SensorLayer::ALL);
    }

    #[test]
    fn the_photos_own_sun_over_a_bare_photo_runs_nothing() {
        let s = Situation {
            sun: true,
            photo_sun: true,
            same_sun: true,
            buildings: false,
            objects: false,
        };
        let (run, skipped) = decide(&s);
        assert!(run.is_empty());
        assert_eq!(
            skipped[0],
            Skipped {
                effect: "cast_shadows",
                why: "the photo's own sun: the photo already shows it"
            }
        );
        assert_eq!(skipped[6].why, "nothing stands on the terrain");
    }
}
