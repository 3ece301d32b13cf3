//! The per-sensor layers a tile set may carry after the standard three (issue 18): one
//! geometry, with the cell attributes each sensor needs beside it.
//!
//! Invariant: a tile set's layer table is the standard layers followed by any of
//! [`SensorLayer::ALL`] in that order, each with the [`LayerInfo`] [`SensorLayer::info`] gives;
//! a page holds exactly those sensor layers, in table order, each `P²` cells. Padding cells
//! (beyond the level's edge) hold the layer's nodata, like the standard layers.

use super::info::LayerInfo;
use serde::{Deserialize, Serialize};

/// A per-cell layer for sensors other than the visual one.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum SensorLayer {
    /// Material id of the material table (u8): 0 unclassified, [`MATERIAL_NODATA`] where the
    /// cell has no data. A coarse cell holds the id most of the valid level-0 cells of its
    /// block have (ties to the lower id).
    Material,
    /// Surface temperature, kelvin (f32, NaN nodata). A coarse cell holds the mean over the
    /// valid level-0 cells of its block.
    Temperature,
    /// Band radiance 8–12 µm, W·m⁻²·sr⁻¹ (f32, NaN nodata); coarse cells the block's mean.
    Radiance,
    /// Radar backscatter σ⁰, linear m²/m² (f32, NaN nodata: no model), for one radar's look;
    /// coarse cells the block's mean power.
    Backscatter,
    /// Unit surface normal (world x east, y north, z up), packed by [`pack_normal`]
    /// ([`NORMAL_NODATA`] nodata). Level 0 holds the normal of the cell's top surface; a coarse
    /// cell the sum of its block's valid level-0 normals, renormalised.
    Normal,
}

/// What a material cell holds where the cell has no data (the materials layer's own nodata).
pub const MATERIAL_NODATA: u8 = 255;

impl SensorLayer {
    /// Every sensor layer, in the order a layer table lists them.
    pub const ALL: [SensorLayer; 5] = [
        SensorLayer::Material,
        SensorLayer::Temperature,
        SensorLayer::Radiance,
        SensorLayer::Backscatter,
        SensorLayer::Normal,
    ];

    /// The layer's name in the header's table.
    pub fn name(self) -> &'static str {
        match self {
            SensorLayer::Material => "material",
            SensorLayer::Temperature => "temperature",
            SensorLayer::Radiance => "radiance",
            SensorLayer::Backscatter => "backscatter",
            SensorLayer::Normal => "normal",
        }
    }

    /// The layer's entry in the header's table.
    pub fn info(self) -> LayerInfo {
        match self {
            SensorLayer::Material => LayerInfo::new(
                self.name(),
                "u8",
                1,
                "255",
                "material id of the database's material table (0 unclassified); coarse levels hold the id most valid level-0 cells of the block have, ties to the lower id",
            ),
            SensorLayer::Temperature => LayerInfo::new(
                self.name(),
                "f32",
                4,
                "NaN",
                "surface temperature, kelvin; coarse levels hold the mean over the block's valid level-0 cells",
            ),
            SensorLayer::Radiance => LayerInfo::new(
                self.name(),
                "f32",
                4,
                "NaN",
                "surface radiance 8-12 um, W m-2 sr-1; coarse levels hold the mean over the block's valid level-0 cells",
            ),
            SensorLayer::Backscatter => LayerInfo::new(
                self.name(),
                "f32",
                4,
                "NaN",
                "radar backscatter sigma0, linear m2/m2, for the tile set's radar look; coarse levels hold the mean power over the block's valid level-0 cells",
            ),
            SensorLayer::Normal => LayerInfo::new(
                self.name(),
                "oct16",
                4,
                "0x80008000",
                "unit surface normal (x east, y north, z up) as two snorm16 octahedral coordinates, x in the low 16 bits; coarse levels hold the sum of the block's valid level-0 normals, renormalised",
            ),
        }
    }

    /// The sensor layer named `name`, if it is one.
    pub fn named(name: &str) -> Option<SensorLayer> {
        SensorLayer::ALL.into_iter().find(|l| l.name() == name)
    }

    /// The cells of this layer for `n` cells of nodata.
    pub fn nodata(self, n: usize) -> SensorCells {
        match self {
            SensorLayer::Material => SensorCells::Ids(vec![MATERIAL_NODATA; n]),
            SensorLayer::Temperature | SensorLayer::Radiance | SensorLayer::Backscatter => {
                SensorCells::Values(vec![f32::NAN; n])
            }
            SensorLayer::Normal => SensorCells::Normals(vec![NORMAL_NODATA; n]),
        }
    }
}

/// What a normal cell holds where the cell has no data: both octahedral coordinates at
/// `i16::MIN`, which [`pack_normal`] never writes.
pub const NORMAL_NODATA: u32 = 0x8000_8000;

/// The octahedral packing of a normal (Cigolle et al. 2014, "A Survey of Efficient
/// Representations for Independent Unit Vectors", JCGT 3(2), the "oct" map): `n` (any length
/// but 0, finite) is projected onto the octahedron |x| + |y| + |z| = 1, the lower half folded
/// over the upper, and the two coordinates stored as snorm16 (x in the low 16 bits). The
/// direction is kept to within 0.004° ([`unpack_normal`]; the worst of 100 000 random
/// directions in the test is 0.0036°); `n`'s length does not matter, so a sum of normals packs
/// as its mean direction. The axes and straight up pack exactly.
pub fn pack_normal(n: [f64; 3]) -> u32 {
    let s = n[0].abs() + n[1].abs() + n[2].abs();
    let (u, v) = fold(n[0] / s, n[1] / s, n[2] < 0.0);
    let q = |a: f64| u32::from((a.clamp(-1.0, 1.0) * 32767.0).round() as i16 as u16);
    q(u) | q(v) << 16
}

/// The unit normal [`pack_normal`] packed; `None` for [`NORMAL_NODATA`].
pub fn unpack_normal(p: u32) -> Option<[f64; 3]> {
    if p == NORMAL_NODATA {
        return None;
    }
    let d = |b: u32| f64::from(b as u16 as i16).max(-32767.0) / 32767.0;
    let (u, v) = (d(p), d(p >> 16));
    let z = 1.0 - u.abs() - v.abs();
    let (x, y) = fold(u, v, z < 0.0);
    let len = (x * x + y * y + z * z).sqrt();
    Some([x / len, y / len, z / len])
}

/// The octahedral fold of the lower half (`lower`) onto the outer triangles, its own inverse.
fn fold(u: f64, v: f64, lower: bool) -> (f64, f64) {
    let sign = |a: f64| if a >= 0.0 { 1.0 } else { -1.0 };
    match lower {
        true => ((1.0 - v.abs()) * sign(u), (1.0 - u.abs()) * sign(v)),
        false => (u, v),
    }
}

/// The cells of one sensor layer of a page, row-major like the standard layers.
#[derive(Debug, Clone, PartialEq)]
pub enum SensorCells {
    /// Material ids ([`SensorLayer::Material`]).
    Ids(Vec<u8>),
    /// Physical values ([`SensorLayer::Temperature`], [`SensorLayer::Radiance`],
    /// [`SensorLayer::Backscatter`]); NaN nodata.
    Values(Vec<f32>),
    /// Packed normals ([`SensorLayer::Normal`], [`pack_normal`]); [`NORMAL_NODATA`] nodata.
    Normals(Vec<u32>),
}

impl SensorCells {
    /// Number of cells.
    pub fn len(&self) -> usize {
        match self {
            SensorCells::Ids(v) => v.len(),
            SensorCells::Values(v) => v.len(),
            SensorCells::Normals(v) => v.len(),
        }
    }

    /// Whether there are no cells.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Whether cell `i` holds its layer's nodata.
    pub fn is_nodata(&self, i: usize) -> bool {
        match self {
            SensorCells::Ids(v) => v[i] == MATERIAL_NODATA,
            SensorCells::Values(v) => v[i].is_nan(),
            SensorCells::Normals(v) => v[i] == NORMAL_NODATA,
        }
    }

    /// Set cells `range` to nodata.
    pub fn clear(&mut self, range: std::ops::Range<usize>) {
        match self {
            SensorCells::Ids(v) => v[range].fill(MATERIAL_NODATA),
            SensorCells::Values(v) => v[range].fill(f32::NAN),
            SensorCells::Normals(v) => v[range].fill(NORMAL_NODATA),
        }
    }

    /// The values, when this is a value layer.
    pub fn values(&self) -> Option<&[f32]> {
        match self {
            SensorCells::Values(v) => Some(v),
            _ => None,
        }
    }

    /// The ids, when this is the material layer.
    pub fn ids(&self) -> Option<&[u8]> {
        match self {
            SensorCells::Ids(v) => Some(v),
            _ => None,
        }
    }

    /// The packed normals, when this is the normal layer.
    pub fn normals(&self) -> Option<&[u32]> {
        match self {
            SensorCells::Normals(v) => Some(v),
            _ => None,
        }
    }
}

/// A light point the night sensors show (runway and street lights), in the tile header.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LightPoint {
    /// Easting, CRS units.
    pub x: f64,
    /// Northing, CRS units.
    pub y: f64,
    /// Height of the lamp, metres (the terrain's plus its height above it).
    pub z: f64,
    /// Luminous intensity, candela: on the beam's axis, or in every direction without a beam.
    pub intensity_cd: f64,
    /// Colour, sRGB.
    pub colour: [u8; 3],
    /// The beam of a directional lamp (approach, runway edge, PAPI); `None`: the same
    /// intensity in every direction (a street light seen from above the road).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub beam: Option<Beam>,
}

/// A directional lamp's beam: an elliptical Gaussian around its axis. Toward a direction `θ`
/// degrees off the axis, at angle `ψ` around it from the beam's horizontal right (toward the
/// up at right angles to both), `h = θ·cos ψ` and `v = θ·sin ψ`, and the lamp's intensity is `I₀ · 2^−((2h / spread_h)² + (2v / spread_v)²)`: half of it at half the
/// spread from the axis, as runway light specifications state beam spreads (ICAO Annex 14,
/// Vol. I, Appendix 2, takes the beam's ellipse at the minimum average intensity and an outer
/// one at 50 %; one Gaussian per axis is dbms's simplification of those isocandela diagrams).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Beam {
    /// Direction of the axis, degrees clockwise from grid north.
    pub azimuth_deg: f64,
    /// Elevation of the axis above the horizontal, degrees, −90 to 90.
    pub elevation_deg: f64,
    /// Full widths at half intensity, degrees: horizontal, vertical (each > 0, at most 360).
    pub spread_deg: [f64; 2],
}

impl Beam {
    /// Whether the beam is one [`Beam`] describes: a finite azimuth, an elevation in −90..=90°
    /// and each spread in (0, 360]°.
    pub fn is_valid(&self) -> bool {
        let spread_ok = self.spread_deg.iter().all(|s| *s > 0.0 && *s <= 360.0);
        let axis_ok = self.azimuth_deg.is_finite() && (-90.0..=90.0).contains(&self.elevation_deg);
        axis_ok && spread_ok
    }

    /// The fraction of the axis intensity sent along `to` (any length but 0), 0 to 1.
    pub fn fraction_toward(&self, to: [f64; 3]) -> f64 {
        let (az, el) = (
            self.azimuth_deg.to_radians(),
            self.elevation_deg.to_radians(),
        );
        let axis = [az.sin() * el.cos(), az.cos() * el.cos(), el.sin()];
        // The horizontal unit vector 90° clockwise of the azimuth: defined for every
        // elevation, straight up included, and continuous through it.
        let right = [az.cos(), -az.sin(), 0.0];
        let up = [
            right[1] * axis[2] - right[2] * axis[1],
            right[2] * axis[0] - right[0] * axis[2],
            right[0] * axis[1] - right[1] * axis[0],
        ];
        let dot = |a: [f64; 3]| a[0] * to[0] + a[1] * to[1] + a[2] * to[2];
        let (x, y) = (dot(right), dot(up));
        let across = x.hypot(y);
        // Off the axis by `theta`, split between sideways and up by the direction around it.
        let theta = across.atan2(dot(axis)).to_degrees();
        let (h, v) = match across > 0.0 {
            true => (theta * x / across, theta * y / across),
            false => (theta, theta),
        };
        let e = (2.0 * h / self.spread_deg[0]).powi(2) + (2.0 * v / self.spread_deg[1]).powi(2);
        (-e).exp2()
    }
}

impl LightPoint {
    /// Luminous intensity toward `to` (from the lamp; any length but 0), candela.
    pub fn intensity_toward(&self, to: [f64; 3]) -> f64 {
        self.intensity_cd * self.beam.map_or(1.0, |b| b.fraction_toward(to))
    }
}

/// What the sensor views need to know of one material of the `material` layer, in the tile
/// header: the tile set is drawn without the database's material table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MaterialAttributes {
    /// The id the `material` layer holds.
    pub id: u8,
    /// The material's name in the table.
    pub name: String,
    /// Reflectance in the 0.6–0.9 µm band of image intensifiers, dimensionless.
    pub nir_reflectance: f64,
    /// Where `nir_reflectance` comes from: `"nir_reflectance"` (the table's published value) or
    /// `"solar_albedo"` (the table has none for the material: its broadband albedo stands in).
    pub nir_from: String,
    /// Mirror-like for radar (calm water, flat roofs): no backscatter away from the normal.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub radar_specular: bool,
    /// The table's published σ⁰ models, for a radar view that takes its own incidence from the
    /// `normal` layer (`dbms render --sensor radar --band`); empty where none is published.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub radar: Vec<crate::backscatter::RadarModel>,
}

/// Check the header's light points and material attributes: finite positions, positive
/// intensities, material ids unique and neither 0 nor [`MATERIAL_NODATA`], reflectances in
/// [0, 1]. `Err` says what is wrong.
pub(crate) fn check_attributes(
    lights: &[LightPoint],
    materials: &[MaterialAttributes],
) -> Result<(), String> {
    for (k, l) in lights.iter().enumerate() {
        let placed = [l.x, l.y, l.z].iter().all(|v| v.is_finite());
        if !(placed && l.intensity_cd > 0.0 && l.intensity_cd.is_finite()) {
            return Err(format!(
                "light {k} has a position that is not finite or an intensity that is not positive"
            ));
        }
        if let Some(b) = l.beam {
            if !b.is_valid() {
                return Err(format!(
                    "light {k} has a beam with an azimuth that is not finite, an elevation outside −90..90° or a spread outside (0, 360]°"
                ));
            }
        }
    }
    for (k, m) in materials.iter().enumerate() {
        if m.id == 0 || m.id == MATERIAL_NODATA || materials[..k].iter().any(|o| o.id == m.id) {
            return Err(format!("material id {} is reserved or listed twice", m.id));
        }
        if !["nir_reflectance", "solar_albedo"].contains(&m.nir_from.as_str()) {
            return Err(format!(
                "material {} has nir_from {:?}, expected \"nir_reflectance\" or \"solar_albedo\"",
                m.id, m.nir_from
            ));
        }
        if !(0.0..=1.0).contains(&m.nir_reflectance) {
            return Err(format!(
                "material {} has nir_reflectance {}, expected 0 to 1",
                m.id, m.nir_reflectance
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_round_trip_and_types_match_the_cells() {
        for l in SensorLayer::ALL {
            assert_eq!(SensorLayer::named(l.name()), Some(l));
            let info = l.info();
            assert_eq!(info.name, l.name());
            let cells = l.nodata(3);
            let width = match cells {
                SensorCells::Ids(_) => 1,
                SensorCells::Values(_) | SensorCells::Normals(_) => 4,
            };
            assert_eq!(info.bytes_per_cell, width);
            assert!((0..3).all(|i| cells.is_nodata(i)));
        }
        assert_eq!(SensorLayer::named("max_z"), None);
    }

    fn angle(a: [f64; 3], b: [f64; 3]) -> f64 {
        let dot: f64 = (0..3).map(|k| a[k] * b[k]).sum();
        let cross = [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ];
        (cross.iter().map(|c| c * c).sum::<f64>().sqrt()).atan2(dot)
    }

    #[test]
    fn packed_normals_keep_their_direction_to_four_thousandths_of_a_degree() {
        let unit = |v: [f64; 3]| {
            let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            [v[0] / l, v[1] / l, v[2] / l]
        };
        // The axes, straight up and down and the diagonals exactly, and an ulp off them.
        let mut hard = vec![];
        for a in [-1.0f64, 0.0, 1.0] {
            for b in [-1.0f64, 0.0, 1.0] {
                for c in [-1.0f64, 0.0, 1.0] {
                    if (a, b, c) != (0.0, 0.0, 0.0) {
                        hard.push([a, b, c]);
                        hard.push([a + 1e-16, b - 1e-16, c + f64::EPSILON]);
                    }
                }
            }
        }
        for v in [
            [1.0, 0.0, 0.0],
            [0.0, -1.0, 0.0],
            [0.0, 0.0, 1.0],
            [0.0, 0.0, -1.0],
        ] {
            assert_eq!(
                unpack_normal(pack_normal(v)),
                Some(v),
                "{v:?} packs exactly"
            );
        }
        let mut rng = crate::num::SplitMix(7);
        let mut r = || rng.next_u64() as f64 / u64::MAX as f64 * 2.0 - 1.0;
        let random = (0..100_000).map(|_| [r(), r(), r()]);
        let mut worst = 0.0f64;
        for v in hard.into_iter().chain(random) {
            let p = pack_normal(v);
            assert_ne!(p, NORMAL_NODATA);
            let back = unpack_normal(p).unwrap();
            worst = worst.max(angle(unit(v), back));
            // A sum of normals packs as its direction: scale does not matter.
            let scaled = unpack_normal(pack_normal([v[0] * 7.5, v[1] * 7.5, v[2] * 7.5]));
            worst = worst.max(angle(unit(v), scaled.unwrap()));
        }
        assert!(worst.to_degrees() < 0.004, "worst {}°", worst.to_degrees());
        assert_eq!(unpack_normal(NORMAL_NODATA), None);
    }

    /// The beam's half-intensity points sit at half its spread off the axis, sideways and up
    /// alike, at any azimuth, straight up included; its back gets nothing.
    #[test]
    fn beams_fall_to_half_at_half_their_spread() {
        let dir = |az: f64, el: f64| {
            let (az, el) = (f64::to_radians(az), f64::to_radians(el));
            [az.sin() * el.cos(), az.cos() * el.cos(), el.sin()]
        };
        for az in [0.0, 45.0, 90.0, 180.0, 270.0, 359.999_999_999_9, -90.0] {
            let b = Beam {
                azimuth_deg: az,
                elevation_deg: 3.0,
                spread_deg: [20.0, 8.0],
            };
            let close = |got: f64, want: f64| (got - want).abs() < 1e-12;
            assert!(
                close(b.fraction_toward(dir(az, 3.0)), 1.0),
                "on the axis at {az}"
            );
            // Up by 4°: in the vertical plane of the axis, so off by 4° vertically only.
            assert!(close(b.fraction_toward(dir(az, 7.0)), 0.5), "4° up at {az}");
            assert!(
                close(b.fraction_toward(dir(az, -1.0)), 0.5),
                "4° down at {az}"
            );
            // 10° sideways in the beam's frame: the axis turned about the beam's up.
            let (a, r) = (
                dir(az, 3.0),
                [az.to_radians().cos(), -az.to_radians().sin(), 0.0],
            );
            let t = 10f64.to_radians();
            let side: Vec<f64> = (0..3).map(|k| a[k] * t.cos() + r[k] * t.sin()).collect();
            assert!(
                close(b.fraction_toward([side[0], side[1], side[2]]), 0.5),
                "10° right at {az}"
            );
            assert!(
                b.fraction_toward(dir(az + 180.0, -3.0)) < 1e-90,
                "behind at {az}"
            );
            // Length does not matter.
            assert!(close(
                b.fraction_toward(dir(az, 7.0).map(|c| c * 40.0)),
                0.5
            ));
        }
        // A lamp pointing straight up: 4° off it (at any azimuth) falls by the spreads' rule.
        let up = Beam {
            azimuth_deg: 30.0,
            elevation_deg: 90.0,
            spread_deg: [8.0, 8.0],
        };
        for az in [0.0, 30.0, 77.0, 210.0] {
            let f = up.fraction_toward(dir(az, 86.0));
            assert!((f - 0.5).abs() < 1e-9, "{az}: {f}");
        }
        let lamp = LightPoint {
            x: 0.0,
            y: 0.0,
            z: 0.0,
            intensity_cd: 200.0,
            colour: [255; 3],
            beam: Some(up),
        };
        assert!((lamp.intensity_toward(dir(5.0, 86.0)) - 100.0).abs() < 1e-7);
        let round = LightPoint { beam: None, ..lamp };
        assert_eq!(round.intensity_toward([0.0, -1.0, 0.0]), 200.0);
    }

    #[test]
    fn header_attributes_are_checked() {
        let lamp = LightPoint {
            x: 1.0,
            y: 2.0,
            z: 3.0,
            intensity_cd: 10.0,
            colour: [1, 2, 3],
            beam: None,
        };
        let grass = MaterialAttributes {
            id: 7,
            name: "grass".into(),
            nir_reflectance: 0.31,
            nir_from: "nir_reflectance".into(),
            radar_specular: false,
            radar: vec![],
        };
        check_attributes(&[lamp], std::slice::from_ref(&grass)).unwrap();
        let bad_lamps = [
            LightPoint {
                z: f64::NAN,
                ..lamp
            },
            LightPoint {
                intensity_cd: 0.0,
                ..lamp
            },
            LightPoint {
                beam: Some(Beam {
                    azimuth_deg: 0.0,
                    elevation_deg: 91.0,
                    spread_deg: [10.0, 5.0],
                }),
                ..lamp
            },
            LightPoint {
                beam: Some(Beam {
                    azimuth_deg: 0.0,
                    elevation_deg: 3.0,
                    spread_deg: [0.0, 5.0],
                }),
                ..lamp
            },
        ];
        for l in bad_lamps {
            assert!(check_attributes(&[l], &[]).unwrap_err().contains("light 0"));
        }
        let bad = [
            vec![grass.clone(), grass.clone()],
            vec![MaterialAttributes {
                id: 0,
                ..grass.clone()
            }],
            vec![MaterialAttributes {
                id: MATERIAL_NODATA,
                ..grass.clone()
            }],
            vec![MaterialAttributes {
                nir_reflectance: 1.5,
                ..grass.clone()
            }],
            vec![MaterialAttributes {
                nir_from: "guess".into(),
                ..grass.clone()
            }],
        ];
        for m in bad {
            assert!(check_attributes(&[], &m).is_err(), "{m:?}");
        }
    }
}
