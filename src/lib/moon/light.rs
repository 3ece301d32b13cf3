//! Light on the ground at night: the Moon's direct illuminance on a horizontal surface
//! (Krisciunas & Schaefer 1991) and the clear moonless sky's (stars, airglow, zodiacal light).
//!
//! Invariant: every number is photopic (V band) illuminance in lux, each piece is returned
//! separately (above the air, through the air, on the ground), and moonlight is exactly 0 with
//! the Moon's centre at or below the horizon, continuous as it rises.
//!
//! Sources:
//! * K. Krisciunas & B. E. Schaefer, "A model of the brightness of moonlight", PASP 103, 1033
//!   (1991): the Moon's illuminance above the atmosphere at its mean distance,
//!   I* = 10^(−0.4 (3.84 + 0.026 |i| + 4×10⁻⁹ i⁴)) foot-candles for phase angle i in degrees (from
//!   the V magnitude −12.73 + 0.026 |i| + 4×10⁻⁹ i⁴, Allen 1973); the airmass
//!   X = (1 − 0.96 sin² Z)^(−1/2) (theirs); and the V-band extinction k = 0.172 mag per
//!   airmass they use (Mauna Kea).
//! * The moonless clear sky: the natural zenith sky luminance 174 µcd/m² (22.0 mag/arcsec², F.
//!   Falchi et al., "The new world atlas of artificial night sky brightness", Science Advances 2,
//!   e1600377, 2016), on a horizontal surface under a sky of that luminance: π × 174 µcd/m².

use crate::{Error, Result};

/// Lux in one foot-candle (lumen per square foot).
const LUX_PER_FOOTCANDLE: f64 = 10.763_910_4;
/// The Moon's mean distance (semi-major axis of its orbit), km: K&S's I* is for this distance.
pub const MEAN_DISTANCE_KM: f64 = 384_400.0;
/// Default V-band extinction coefficient, magnitudes per airmass (Krisciunas & Schaefer 1991,
/// Mauna Kea). Lower-lying, hazier air has more: about 0.25–0.3 at sea level.
pub const DEFAULT_EXTINCTION_MAG_PER_AIRMASS: f64 = 0.172;
/// Natural zenith luminance of a clear moonless sky, cd/m² (Falchi et al. 2016).
const NATURAL_SKY_LUMINANCE_CD_M2: f64 = 174e-6;

/// Illuminance of a clear moonless night sky (stars, airglow, zodiacal light; no artificial light)
/// on a horizontal surface, lux: π × the natural zenith luminance 174 µcd/m² ≈ 5.5e-4 lux. A
/// uniform sky at the zenith's luminance, so a lower estimate: the real sky brightens toward the
/// horizon, and the figure often quoted for a clear moonless night is about 1e-3 lux.
pub fn night_sky_lux() -> f64 {
    std::f64::consts::PI * NATURAL_SKY_LUMINANCE_CD_M2
}

/// The Moon's direct light, in pieces.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct Moonlight {
    /// Illuminance above the atmosphere on a surface facing the Moon, lux (K&S's I* scaled by
    /// (mean distance / distance)²); about 0.31 lux at full moon, 0.03 at quarter.
    pub exoatmospheric_lux: f64,
    /// Relative air mass along the line of sight, X = (1 − 0.96 sin² Z)^(−1/2), in [1, 5]; 5 at
    /// and below the horizon.
    pub airmass: f64,
    /// Fraction of direct moonlight through the air, 10^(−0.4 k X), in (0, 1].
    pub transmittance: f64,
    /// Illuminance on a horizontal surface at the ground, lux: exoatmospheric × transmittance ×
    /// sin(elevation); exactly 0 with the Moon at or below the horizon.
    pub horizontal_lux: f64,
}

/// The Moon's direct light at elevation `elevation_deg` (degrees; as seen, so with refraction if
/// the position had it), phase angle `phase_angle_deg` (degrees, 0 = full, 180 = new) and distance
/// `distance_km` from the observer, through air of extinction `extinction_mag_per_airmass`
/// (magnitudes per airmass, V band; [`DEFAULT_EXTINCTION_MAG_PER_AIRMASS`] for a clear night).
///
/// Errors on non-finite input, an elevation outside [−90, 90], a phase angle outside [0, 180],
/// a distance outside 300 000..450 000 km or an extinction outside [0, 5].
pub fn moonlight(
    elevation_deg: f64,
    phase_angle_deg: f64,
    distance_km: f64,
    extinction_mag_per_airmass: f64,
) -> Result<Moonlight> {
    let check = |what: &str, v: f64, lo: f64, hi: f64, fix: &str| {
        if (lo..=hi).contains(&v) {
            Ok(v)
        } else {
            Err(Error::msg(format!("{what} {v} is outside [{lo}, {hi}]")).fix(fix))
        }
    };
    let e = check(
        "moon elevation (deg)",
        elevation_deg,
        -90.0,
        90.0,
        "give degrees above the horizon",
    )?;
    let i = check(
        "phase angle (deg)",
        phase_angle_deg,
        0.0,
        180.0,
        "give the Sun-Moon-observer angle in degrees, 0 at full moon",
    )?;
    let d = check(
        "moon distance (km)",
        distance_km,
        300_000.0,
        450_000.0,
        "give the observer-Moon distance in km, about 384 400",
    )?;
    let k = check(
        "extinction (mag/airmass)",
        extinction_mag_per_airmass,
        0.0,
        5.0,
        "give the V-band extinction coefficient, about 0.17 (high site) to 0.3 (sea level)",
    )?;
    let footcandles = 10f64.powf(-0.4 * (3.84 + 0.026 * i + 4e-9 * i.powi(4)));
    let exoatmospheric_lux = footcandles * LUX_PER_FOOTCANDLE * (MEAN_DISTANCE_KM / d).powi(2);
    let sin_e = e.to_radians().sin().max(0.0);
    // sin Z = cos e; below the horizon the horizon's airmass (the light is 0 there anyway).
    let cos_e = if sin_e > 0.0 {
        e.to_radians().cos()
    } else {
        1.0
    };
    let airmass = (1.0 - 0.96 * cos_e * cos_e).powf(-0.5);
    let transmittance = 10f64.powf(-0.4 * k * airmass);
    Ok(Moonlight {
        exoatmospheric_lux,
        airmass,
        transmittance,
        horizontal_lux: exoatmospheric_lux * transmittance * sin_e,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// K&S's I* at full moon, mean distance: 10^(−0.4 × 3.84) fc = 0.02911 fc = 0.3133 lux; at
    /// the zenith through k = 0.172 (X = 1): × 10^(−0.0688) = 0.2674 lux.
    #[test]
    fn full_moon_overhead_at_mean_distance() {
        let m = moonlight(90.0, 0.0, MEAN_DISTANCE_KM, 0.172).unwrap();
        assert!((m.exoatmospheric_lux - 0.31334).abs() < 5e-5, "{m:?}");
        assert!((m.airmass - 1.0).abs() < 1e-12);
        assert!((m.horizontal_lux - 0.26745).abs() < 5e-5, "{m:?}");
    }

    /// Quarter moon (i = 90°) is about a tenth of full (2.5 magnitudes fainter: the opposition
    /// surge K&S's fit carries), and the crescent fades fast.
    #[test]
    fn phase_law() {
        let lux = |i: f64| {
            moonlight(90.0, i, MEAN_DISTANCE_KM, 0.0)
                .unwrap()
                .exoatmospheric_lux
        };
        let ratio = lux(90.0) / lux(0.0);
        assert!((0.07..0.12).contains(&ratio), "quarter/full {ratio}");
        assert!(lux(150.0) < 0.01 * lux(0.0));
        assert!((1..180).all(|i| lux(f64::from(i)) < lux(f64::from(i - 1))));
    }

    /// Zero at and below the horizon, continuous as the Moon rises, and airmass near 5 there.
    #[test]
    fn zero_below_horizon_and_continuous() {
        for e in [-90.0, -10.0, -0.001, 0.0] {
            assert_eq!(
                moonlight(e, 0.0, MEAN_DISTANCE_KM, 0.2)
                    .unwrap()
                    .horizontal_lux,
                0.0
            );
        }
        let low = moonlight(1e-6, 0.0, MEAN_DISTANCE_KM, 0.2).unwrap();
        assert!(low.horizontal_lux > 0.0 && low.horizontal_lux < 1e-8);
        assert!((low.airmass - 5.0).abs() < 1e-6, "{low:?}");
        let mut prev = 0.0;
        for k in 1..=900 {
            let l = moonlight(k as f64 * 0.1, 0.0, MEAN_DISTANCE_KM, 0.2)
                .unwrap()
                .horizontal_lux;
            assert!(
                l > prev && l - prev < 0.001,
                "step at {} deg",
                k as f64 * 0.1
            );
            prev = l;
        }
    }

    /// Closer is brighter by the inverse square; more haze is darker.
    #[test]
    fn distance_and_extinction() {
        let near = moonlight(60.0, 10.0, 356_500.0, 0.2).unwrap();
        let far = moonlight(60.0, 10.0, 406_700.0, 0.2).unwrap();
        let want = (406_700.0f64 / 356_500.0).powi(2);
        assert!((near.horizontal_lux / far.horizontal_lux - want).abs() < 1e-12);
        let hazy = moonlight(60.0, 10.0, 356_500.0, 0.5).unwrap();
        assert!(hazy.horizontal_lux < near.horizontal_lux);
    }

    #[test]
    fn night_sky_is_about_half_a_millilux() {
        assert!(
            (night_sky_lux() - 5.466e-4).abs() < 1e-6,
            "{}",
            night_sky_lux()
        );
    }

    #[test]
    fn bad_inputs_are_one_line_errors() {
        for (e, i, d, k, what) in [
            (91.0, 0.0, 384_400.0, 0.2, "elevation"),
            (f64::NAN, 0.0, 384_400.0, 0.2, "elevation"),
            (10.0, -1.0, 384_400.0, 0.2, "phase angle"),
            (10.0, 0.0, 1.0, 0.2, "distance"),
            (10.0, 0.0, 384_400.0, f64::INFINITY, "extinction"),
        ] {
            let err = moonlight(e, i, d, k).unwrap_err().to_string();
            assert!(
                err.contains(what) && err.contains("; ") && !err.contains('\n'),
                "{err}"
            );
        }
    }
}
