//! What a surface is made of: its optical properties and its material column, top layer first.
//!
//! Invariant: a [`Surface`] that passed [`Surface::validate`] has at least one layer, every
//! thickness and material property positive and finite, albedo in [0, 1], emissivity in (0, 1]
//! and a bottom boundary with a positive temperature and a non-negative coefficient.

use crate::{Error, Result};

/// One homogeneous layer of a material column.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Layer {
    /// Thickness, m (> 0).
    pub thickness_m: f64,
    /// Thermal conductivity k, W/(m·K) (> 0).
    pub conductivity_w_per_m_k: f64,
    /// Density ρ, kg/m³ (> 0).
    pub density_kg_per_m3: f64,
    /// Specific heat capacity c, J/(kg·K) (> 0).
    pub specific_heat_j_per_kg_k: f64,
}

impl Layer {
    /// Volumetric heat capacity ρ·c, J/(m³·K).
    pub fn heat_capacity_j_per_m3_k(&self) -> f64 {
        self.density_kg_per_m3 * self.specific_heat_j_per_kg_k
    }

    /// Thermal inertia I = √(k·ρ·c), J/(m²·K·s^½): what sets a half-space's diurnal swing.
    pub fn thermal_inertia(&self) -> f64 {
        (self.conductivity_w_per_m_k * self.heat_capacity_j_per_m3_k()).sqrt()
    }

    /// Thermal diffusivity κ = k/(ρ·c), m²/s.
    pub fn diffusivity_m2_per_s(&self) -> f64 {
        self.conductivity_w_per_m_k / self.heat_capacity_j_per_m3_k()
    }
}

/// What lies under the last layer.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Bottom {
    /// Ground: the bottom of the last layer is held at this temperature, K (> 0).
    Fixed {
        /// The deep temperature, K.
        temperature_k: f64,
    },
    /// A roof or wall over an interior: the bottom exchanges h·(T_interior − T_bottom), W/m².
    Convective {
        /// Interior heat-transfer coefficient h, W/(m²·K) (≥ 0; 0 is an insulated bottom).
        coefficient_w_per_m2_k: f64,
        /// Interior (room) temperature, K (> 0).
        temperature_k: f64,
    },
}

/// A surface: broadband optical properties over a column of layers.
#[derive(Debug, Clone, PartialEq)]
pub struct Surface {
    /// Broadband solar albedo, the reflected fraction of shortwave (0..=1).
    pub albedo: f64,
    /// Thermal (long-wave) emissivity ε, in (0, 1]; by Kirchhoff also its long-wave absorptance.
    pub emissivity: f64,
    /// The material column, top layer first.
    pub layers: Vec<Layer>,
    /// The boundary under the last layer.
    pub bottom: Bottom,
    /// Bulk surface resistance to evaporation r_s, s/m (FAO-56's surface resistance, Allen et
    /// al. 1998, eq. 3): `None` for a dry surface (no latent heat), 0 for open water, 70 for
    /// FAO's well-watered reference grass.
    pub surface_resistance_s_per_m: Option<f64>,
}

impl Surface {
    /// Checks every value a user can give; the error names the bad one.
    pub fn validate(&self) -> Result<()> {
        let fix = "give the surface's values in SI units from the material table";
        if !(0.0..=1.0).contains(&self.albedo) {
            return Err(Error::msg(format!("albedo {} is outside 0..1", self.albedo)).fix(fix));
        }
        if !(self.emissivity > 0.0 && self.emissivity <= 1.0) {
            return Err(
                Error::msg(format!("emissivity {} is outside (0, 1]", self.emissivity)).fix(fix),
            );
        }
        if let Some(r) = self.surface_resistance_s_per_m {
            if !(r >= 0.0 && r.is_finite()) {
                return Err(Error::msg(format!(
                    "surface resistance {r} s/m is negative or not a number"
                ))
                .fix(fix));
            }
        }
        if self.layers.is_empty() {
            return Err(Error::msg("a surface with no layers").fix("give at least one layer"));
        }
        for (i, l) in self.layers.iter().enumerate() {
            for (name, v) in [
                ("thickness", l.thickness_m),
                ("conductivity", l.conductivity_w_per_m_k),
                ("density", l.density_kg_per_m3),
                ("specific heat", l.specific_heat_j_per_kg_k),
            ] {
                if !(v > 0.0 && v.is_finite()) {
                    return Err(Error::msg(format!(
                        "layer {} has {name} {v}, not a positive number",
                        i + 1
                    ))
                    .fix(fix));
                }
            }
        }
        let (h, t) = match self.bottom {
            Bottom::Fixed { temperature_k } => (0.0, temperature_k),
            Bottom::Convective {
                coefficient_w_per_m2_k,
                temperature_k,
            } => (coefficient_w_per_m2_k, temperature_k),
        };
        if !(h >= 0.0 && h.is_finite()) {
            return Err(Error::msg(format!(
                "bottom coefficient {h} W/(m²·K) is negative or not a number"
            ))
            .fix(fix));
        }
        if !(t > 0.0 && t.is_finite()) {
            return Err(Error::msg(format!("bottom temperature {t} K is not above 0 K")).fix(fix));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn soil() -> Surface {
        Surface {
            albedo: 0.2,
            emissivity: 0.95,
            surface_resistance_s_per_m: None,
            layers: vec![Layer {
                thickness_m: 1.0,
                conductivity_w_per_m_k: 1.0,
                density_kg_per_m3: 1600.0,
                specific_heat_j_per_kg_k: 800.0,
            }],
            bottom: Bottom::Fixed {
                temperature_k: 285.0,
            },
        }
    }

    /// Each bad value is refused with a message naming it (mutation check: dropping the
    /// emissivity test lets `emissivity 0` through and fails here).
    #[test]
    fn bad_values_are_errors_that_name_them() {
        assert!(soil().validate().is_ok());
        type Break = fn(&mut Surface);
        let cases: [(Break, &str); 7] = [
            (|s| s.albedo = 1.5, "albedo"),
            (|s| s.emissivity = 0.0, "emissivity"),
            (|s| s.layers.clear(), "no layers"),
            (|s| s.layers[0].thickness_m = -1.0, "thickness"),
            (
                |s| s.layers[0].specific_heat_j_per_kg_k = f64::NAN,
                "specific heat",
            ),
            (
                |s| {
                    s.bottom = Bottom::Convective {
                        coefficient_w_per_m2_k: -1.0,
                        temperature_k: 293.0,
                    }
                },
                "coefficient",
            ),
            (
                |s| s.bottom = Bottom::Fixed { temperature_k: 0.0 },
                "temperature",
            ),
        ];
        for (break_it, word) in cases {
            let mut s = soil();
            break_it(&mut s);
            let e = s.validate().expect_err(word).to_string();
            assert!(e.contains(word), "{e}");
        }
    }

    #[test]
    fn inertia_and_diffusivity_follow_their_definitions() {
        let l = soil().layers[0];
        assert_eq!(l.thermal_inertia(), (1.0f64 * 1600.0 * 800.0).sqrt());
        assert_eq!(l.diffusivity_m2_per_s(), 1.0 / 1.28e6);
    }
}
