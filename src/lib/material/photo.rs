//! The orthophoto classification: a material for a cell from its colour alone, by fixed rules
//! taken from the literature, never fitted to a scene.
//!
//! It is the last source of a cell's material (after vector features and a land-cover raster,
//! [`super::layer`]). The rules, in order (chromatic coordinates `r, g, b` are each band over
//! the sum of the three; `V` is the largest band over 255; `S` is (largest − smallest) over
//! the largest, HSV saturation):
//!
//! * open ground:
//!   1. water when blue leads (`b > 0.38`, `b > g`, `b > r`) and the cell is not bright (`V <
//!      0.6`): [`WATER`] (first: dark blue-green water can pass the vegetation index);
//!   2. vegetation when the excess green minus excess red index `ExG − ExR = (2g − r − b) −
//!      (1.4r − g)` is above 0 (Meyer & Neto 2008, *Verification of color vegetation indices for
//!      automated crop imaging applications*, Computers and Electronics in Agriculture 63(2),
//!      the zero threshold): [`GRASS`] (colour cannot tell grass from crops, shrubs or trees:
//!      land cover or vector features can);
//!   3. grey (`S < 0.2`): [`CONCRETE`] when bright (`V ≥ 0.6`), else [`ASPHALT`];
//!   4. warm (`r ≥ b`): [`SAND`] when bright and pale (`V > 0.65`, `S < 0.45`), else
//!      [`BARE_SOIL`];
//!   5. anything else (cool and coloured): [`ROCK`].
//! * under a building footprint (roofs):
//!   1. red-dominant and saturated (`r > g`, `r > b`, `S ≥ 0.3`): [`ROOF_TILE`];
//!   2. other saturated colours (`S ≥ 0.2`; painted sheet): [`ROOF_METAL`];
//!   3. grey: [`ROOF_BITUMEN`] when dark (`V < 0.35`), else [`ROOF_CONCRETE`].
//!
//! Chromatic coordinates do not change when a cell is darkened by a cast shadow, so rules on
//! them (vegetation, water, warm or cool) hold in shadow; the brightness rules (concrete against
//! asphalt, sand, bitumen against concrete roofs) do not, and a shadowed cell takes the darker
//! class. A cell with no photo (alpha 0) or black has no class here ([`None`]).
//!
//! Invariant: a pure function of the colour and whether the cell is a roof.

/// Material names the rules give; the material table maps them to ids.
pub const ASPHALT: &str = "asphalt";
/// See [`ASPHALT`].
pub const CONCRETE: &str = "concrete";
/// See [`ASPHALT`].
pub const BARE_SOIL: &str = "bare_soil";
/// See [`ASPHALT`].
pub const SAND: &str = "sand";
/// See [`ASPHALT`].
pub const ROCK: &str = "rock";
/// See [`ASPHALT`].
pub const GRASS: &str = "grass";
/// See [`ASPHALT`].
pub const WATER: &str = "water";
/// See [`ASPHALT`].
pub const ROOF_BITUMEN: &str = "roof_bitumen";
/// See [`ASPHALT`].
pub const ROOF_METAL: &str = "roof_metal";
/// See [`ASPHALT`].
pub const ROOF_TILE: &str = "roof_tile";
/// See [`ASPHALT`].
pub const ROOF_CONCRETE: &str = "roof_concrete";

/// Every name [`classify`] can give, for checking a material table has them all.
pub const NAMES: [&str; 11] = [
    ASPHALT,
    CONCRETE,
    BARE_SOIL,
    SAND,
    ROCK,
    GRASS,
    WATER,
    ROOF_BITUMEN,
    ROOF_METAL,
    ROOF_TILE,
    ROOF_CONCRETE,
];

/// The material of a cell of photo colour `rgba` (alpha 0 = no photo); `roof`: the cell lies
/// under a building footprint. `None` where the photo says nothing (no photo, or black).
pub fn classify(rgba: [u8; 4], roof: bool) -> Option<&'static str> {
    let [r8, g8, b8, a] = rgba;
    let sum = r8 as f64 + g8 as f64 + b8 as f64;
    if a == 0 || sum == 0.0 {
        return None;
    }
    let (r, g, b) = (r8 as f64 / sum, g8 as f64 / sum, b8 as f64 / sum);
    let (hi, lo) = (r8.max(g8).max(b8) as f64, r8.min(g8).min(b8) as f64);
    let v = hi / 255.0;
    let s = (hi - lo) / hi;
    if roof {
        return Some(if r > g && r > b && s >= 0.3 {
            ROOF_TILE
        } else if s >= 0.2 {
            ROOF_METAL
        } else if v < 0.35 {
            ROOF_BITUMEN
        } else {
            ROOF_CONCRETE
        });
    }
    let exg_minus_exr = (2.0 * g - r - b) - (1.4 * r - g);
    Some(if b > 0.38 && b > g && b > r && v < 0.6 {
        WATER
    } else if exg_minus_exr > 0.0 {
        GRASS
    } else if s < 0.2 {
        if v >= 0.6 {
            CONCRETE
        } else {
            ASPHALT
        }
    } else if r >= b {
        if v > 0.65 && s < 0.45 {
            SAND
        } else {
            BARE_SOIL
        }
    } else {
        ROCK
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ground(rgb: [u8; 3]) -> Option<&'static str> {
        classify([rgb[0], rgb[1], rgb[2], 255], false)
    }

    fn roof(rgb: [u8; 3]) -> Option<&'static str> {
        classify([rgb[0], rgb[1], rgb[2], 255], true)
    }

    /// Colours read off real orthophotos (typical values, not a scene's generator).
    #[test]
    fn typical_ground_colours() {
        assert_eq!(ground([74, 112, 48]), Some(GRASS)); // lawn
        assert_eq!(ground([38, 62, 34]), Some(GRASS)); // forest canopy, dark
        assert_eq!(ground([92, 92, 96]), Some(ASPHALT)); // road
        assert_eq!(ground([200, 198, 192]), Some(CONCRETE)); // pavement
        assert_eq!(ground([132, 108, 78]), Some(BARE_SOIL)); // ploughed field
        assert_eq!(ground([214, 196, 160]), Some(SAND)); // beach
        assert_eq!(ground([30, 52, 78]), Some(WATER)); // lake
        assert_eq!(ground([96, 110, 150]), Some(WATER)); // lake, bright sky reflected
        assert_eq!(ground([120, 128, 160]), Some(ROCK)); // bluish, not dark enough for water
    }

    #[test]
    fn typical_roof_colours() {
        assert_eq!(roof([156, 74, 58]), Some(ROOF_TILE));
        assert_eq!(roof([104, 140, 120]), Some(ROOF_METAL));
        assert_eq!(roof([62, 60, 64]), Some(ROOF_BITUMEN));
        assert_eq!(roof([176, 172, 160]), Some(ROOF_CONCRETE));
        // A red-brown ground colour under a footprint is a roof class, never soil.
        assert_eq!(roof([132, 108, 78]), Some(ROOF_TILE));
    }

    /// A cast shadow scales the three bands alike: the vegetation, water and warm/cool rules
    /// keep their class (up to rounding), brightness rules may not.
    #[test]
    fn shadow_keeps_the_chromatic_classes() {
        for rgb in [[74, 112, 48], [30, 52, 78], [132, 108, 78], [156, 74, 58]] {
            let dark = rgb.map(|v: u8| (v as f64 * 0.45).round() as u8);
            for is_roof in [false, true] {
                let (lit, shade) = (
                    classify([rgb[0], rgb[1], rgb[2], 255], is_roof),
                    classify([dark[0], dark[1], dark[2], 255], is_roof),
                );
                assert_eq!(lit, shade, "{rgb:?} roof {is_roof}");
            }
        }
    }

    #[test]
    fn no_photo_and_black_have_no_class() {
        assert_eq!(classify([90, 90, 90, 0], false), None);
        assert_eq!(classify([0, 0, 0, 255], false), None);
        assert_eq!(classify([0, 0, 0, 255], true), None);
    }

    /// The thresholds sit where the rules say: one step either side of the grey limit and of
    /// the vegetation index's zero.
    #[test]
    fn thresholds_are_where_documented() {
        // S = 0.2 exactly is not grey: (100 − 80) / 100.
        assert_eq!(ground([100, 90, 80]), Some(BARE_SOIL));
        assert_eq!(ground([100, 90, 81]), Some(ASPHALT));
        // ExG − ExR = (3G − 2.4R − B) / (R + G + B): zero at G = 100 for R = 100, B = 60.
        assert_eq!(ground([100, 99, 60]), Some(BARE_SOIL));
        assert_eq!(ground([100, 101, 60]), Some(GRASS));
        // Blue share 0.38: B = 0.38 · 200 / 0.62 ≈ 122.6 over R = G = 100.
        assert_eq!(ground([100, 100, 123]), Some(WATER));
        assert_eq!(ground([100, 100, 122]), Some(ASPHALT));
        // Every name the rules give is in NAMES.
        for r in (0..=255).step_by(17) {
            for g in (0..=255).step_by(17) {
                for b in (0..=255).step_by(17) {
                    for is_roof in [false, true] {
                        if let Some(n) = classify([r, g, b, 255], is_roof) {
                            assert!(NAMES.contains(&n), "{n}");
                        }
                    }
                }
            }
        }
    }
}
