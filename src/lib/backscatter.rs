//! Published empirical radar backscatter models: σ⁰ of a surface against the incidence angle,
//! per band (and polarisation), as the material table stores them and the radar stage and the
//! radar view evaluate them (issue 18).
//!
//! Invariant: a model is evaluated exactly as its source publishes it, at the incidence angle
//! from the surface normal; no model is extrapolated to another band. σ⁰ is drawn on one grey
//! scale ([`grey_db`]): `dbms radar`'s preview and the radar views of `dbms render` share it.

use serde::{Deserialize, Serialize};

/// A radar band, by its IEEE letter designation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Band {
    L,
    S,
    C,
    X,
    Ku,
    Ka,
    W,
}

/// Transmit/receive polarisation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Polarisation {
    Hh,
    Vv,
    Hv,
}

/// A published empirical σ⁰ model for one band (and polarisation).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "model", rename_all = "snake_case", deny_unknown_fields)]
pub enum RadarModel {
    /// Ulaby & Dobson (1989): σ⁰(θ) dB = P1 + P2·exp(−P3·θ) + P4·cos(P5·θ + P6), θ the
    /// incidence angle in radians, valid over `incidence_deg`.
    UlabyDobson {
        band: Band,
        polarisation: Polarisation,
        /// P1..P6 as published.
        p: [f64; 6],
        /// The incidence angles the fit covers, degrees, `[min, max]` within 0..=90.
        incidence_deg: [f64; 2],
        /// Source id of the coefficients.
        source: String,
    },
    /// Constant γ: σ⁰ = γ·sin(grazing) = γ·cos(incidence).
    ConstantGamma {
        band: Band,
        /// γ in dB.
        gamma_db: f64,
        /// Source id of γ.
        source: String,
    },
}

/// The σ⁰ model for `band` among `models`: the first for it (any polarisation), if any.
pub fn model_for(models: &[RadarModel], band: Band) -> Option<&RadarModel> {
    models.iter().find(|m| m.band() == band)
}

impl RadarModel {
    /// σ⁰, linear (m²/m², rounded to f32), on a surface whose normal is at `cos_incidence`
    /// (0..=1, clamped above) to the direction toward the radar: [`sigma0_db`](Self::sigma0_db)
    /// at that incidence, out of decibels.
    pub fn sigma0(&self, cos_incidence: f64) -> f32 {
        let incidence_deg = cos_incidence.min(1.0).acos().to_degrees();
        10f64.powf(self.sigma0_db(incidence_deg) / 10.0) as f32
    }

    /// σ⁰ in dB at incidence angle `incidence_deg` (degrees from the surface normal).
    pub fn sigma0_db(&self, incidence_deg: f64) -> f64 {
        match self {
            RadarModel::UlabyDobson { p, .. } => {
                let t = incidence_deg.to_radians();
                p[0] + p[1] * (-p[2] * t).exp() + p[3] * (p[4] * t + p[5]).cos()
            }
            RadarModel::ConstantGamma { gamma_db, .. } => {
                gamma_db + 10.0 * incidence_deg.to_radians().cos().log10()
            }
        }
    }

    /// The band the model is for.
    pub fn band(&self) -> Band {
        match self {
            RadarModel::UlabyDobson { band, .. } | RadarModel::ConstantGamma { band, .. } => *band,
        }
    }

    /// The polarisation the model is for (constant γ: any).
    pub fn polarisation(&self) -> Option<Polarisation> {
        match self {
            RadarModel::UlabyDobson { polarisation, .. } => Some(*polarisation),
            RadarModel::ConstantGamma { .. } => None,
        }
    }

    /// The id of the source the model's numbers come from.
    pub fn source(&self) -> &str {
        match self {
            RadarModel::UlabyDobson { source, .. } | RadarModel::ConstantGamma { source, .. } => {
                source
            }
        }
    }
}

/// Lowest σ⁰ [`grey_db`] draws above black, dB; 0 dB is white.
pub const GREY_FLOOR_DB: f64 = -30.0;

/// σ⁰ (linear) as grey: [`GREY_FLOOR_DB`] and below black (0: no return, too), 0 dB and
/// above white, linear in dB between.
pub fn grey_db(s: f32) -> u8 {
    if s.is_nan() || s <= 0.0 {
        return 0;
    }
    let db = 10.0 * f64::from(s).log10();
    (255.0 * (db / -GREY_FLOOR_DB + 1.0).clamp(0.0, 1.0)).round() as u8
}
