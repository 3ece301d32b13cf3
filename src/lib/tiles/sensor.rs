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
}

/// What a material cell holds where the cell has no data (the materials layer's own nodata).
pub const MATERIAL_NODATA: u8 = 255;

impl SensorLayer {
    /// Every sensor layer, in the order a layer table lists them.
    pub const ALL: [SensorLayer; 4] = [
        SensorLayer::Material,
        SensorLayer::Temperature,
        SensorLayer::Radiance,
        SensorLayer::Backscatter,
    ];

    /// The layer's name in the header's table.
    pub fn name(self) -> &'static str {
        match self {
            SensorLayer::Material => "material",
            SensorLayer::Temperature => "temperature",
            SensorLayer::Radiance => "radiance",
            SensorLayer::Backscatter => "backscatter",
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
        }
    }
}

/// The cells of one sensor layer of a page, row-major like the standard layers.
#[derive(Debug, Clone, PartialEq)]
pub enum SensorCells {
    /// Material ids ([`SensorLayer::Material`]).
    Ids(Vec<u8>),
    /// Physical values ([`SensorLayer::Temperature`], [`SensorLayer::Radiance`]); NaN nodata.
    Values(Vec<f32>),
}

impl SensorCells {
    /// Number of cells.
    pub fn len(&self) -> usize {
        match self {
            SensorCells::Ids(v) => v.len(),
            SensorCells::Values(v) => v.len(),
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
        }
    }

    /// Set cells `range` to nodata.
    pub fn clear(&mut self, range: std::ops::Range<usize>) {
        match self {
            SensorCells::Ids(v) => v[range].fill(MATERIAL_NODATA),
            SensorCells::Values(v) => v[range].fill(f32::NAN),
        }
    }

    /// The values, when this is a value layer.
    pub fn values(&self) -> Option<&[f32]> {
        match self {
            SensorCells::Values(v) => Some(v),
            SensorCells::Ids(_) => None,
        }
    }

    /// The ids, when this is the material layer.
    pub fn ids(&self) -> Option<&[u8]> {
        match self {
            SensorCells::Ids(v) => Some(v),
            SensorCells::Values(_) => None,
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
    /// Luminous intensity, candela, the same in every direction.
    pub intensity_cd: f64,
    /// Colour, sRGB.
    pub colour: [u8; 3],
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
}

/// Check the header's light points and material attributes: finite positions, positive
/// intensities, material ids unique and neither 0 nor [`MATERIAL_NODATA`], reflectances in
/// [0, 1]. `Err` says what is wrong.
pub(crate) fn check_attributes(
    lights: &[LightPoint],
    materials: &[MaterialAttributes],
) -> Result<(), String> {
    for (k, l) in lights.iter().enumerate() {
        if ![l.x, l.y, l.z].iter().all(|v| v.is_finite())
            || !(l.intensity_cd > 0.0 && l.intensity_cd.is_finite())
        {
            return Err(format!(
                "light {k} has a position that is not finite or an intensity that is not positive"
            ));
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
                SensorCells::Values(_) => 4,
            };
            assert_eq!(info.bytes_per_cell, width);
            assert!((0..3).all(|i| cells.is_nodata(i)));
        }
        assert_eq!(SensorLayer::named("max_z"), None);
    }

    #[test]
    fn header_attributes_are_checked() {
        let lamp = LightPoint {
            x: 1.0,
            y: 2.0,
            z: 3.0,
            intensity_cd: 10.0,
            colour: [1, 2, 3],
        };
        let grass = MaterialAttributes {
            id: 7,
            name: "grass".into(),
            nir_reflectance: 0.31,
            nir_from: "nir_reflectance".into(),
        };
        check_attributes(&[lamp], &[grass.clone()]).unwrap();
        let bad_lamps = [
            LightPoint {
                z: f64::NAN,
                ..lamp
            },
            LightPoint {
                intensity_cd: 0.0,
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
