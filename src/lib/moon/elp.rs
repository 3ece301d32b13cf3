//! The Moon's geocentric ecliptic place by Meeus, *Astronomical Algorithms* (2nd ed., 1998),
//! chapter 47: the truncated ELP-2000/82 theory (Chapront), all terms of Tables 47.A and 47.B with
//! the eccentricity factor E and the additive terms A1, A2, A3.
//!
//! Invariant: [`geocentric`] is chapter 47 term for term, so it reproduces Meeus's example 47.a to
//! its printed digits; its result is referred to the mean equinox of date (no nutation: the caller
//! adds Δψ for the apparent place). Angles are degrees in the polynomials (as Meeus prints them),
//! radians in the series.

use super::terms::{B, LR};
use crate::sun::spa::poly;

/// The Moon seen from the Earth's centre, mean equinox of date.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Geocentric {
    /// Geocentric ecliptic longitude λ, degrees, [0, 360).
    pub lambda_deg: f64,
    /// Geocentric ecliptic latitude β, degrees, within ±5.3.
    pub beta_deg: f64,
    /// Distance between the centres of the Earth and the Moon Δ, km (356 000..407 000).
    pub distance_km: f64,
}

/// Equatorial radius of the Earth Meeus uses for the lunar parallax, km.
pub(super) const EARTH_RADIUS_KM: f64 = 6378.14;

/// The Moon's place at `t` Julian centuries of TT (dynamical time) from J2000.0.
pub(super) fn geocentric(t: f64) -> Geocentric {
    // 47.1–47.5: mean longitude L′, mean elongation D, Sun's mean anomaly M, Moon's mean anomaly
    // M′, argument of latitude F (degrees).
    let l1 = poly(
        t,
        &[
            218.3164477,
            481267.88123421,
            -0.0015786,
            1.0 / 538841.0,
            -1.0 / 65194000.0,
        ],
    );
    let d = poly(
        t,
        &[
            297.8501921,
            445267.1114034,
            -0.0018819,
            1.0 / 545868.0,
            -1.0 / 113065000.0,
        ],
    );
    let m = poly(
        t,
        &[357.5291092, 35999.0502909, -0.0001536, 1.0 / 24490000.0],
    );
    let m1 = poly(
        t,
        &[
            134.9633964,
            477198.8675055,
            0.0087414,
            1.0 / 69699.0,
            -1.0 / 14712000.0,
        ],
    );
    let f = poly(
        t,
        &[
            93.2720950,
            483202.0175233,
            -0.0036539,
            -1.0 / 3526000.0,
            1.0 / 863310000.0,
        ],
    );
    let a1 = (119.75 + 131.849 * t).to_radians();
    let a2 = (53.09 + 479264.290 * t).to_radians();
    let a3 = (313.45 + 481266.484 * t).to_radians();
    // 47.6: the decreasing eccentricity of the Earth's orbit, applied once per power of M.
    let e = poly(t, &[1.0, -0.002516, -0.0000074]);
    let args = [d, m, m1, f].map(|x| x.rem_euclid(360.0).to_radians());
    let arg = |k: &[i8; 4]| -> f64 {
        k.iter()
            .zip(args.iter())
            .map(|(&ki, a)| f64::from(ki) * a)
            .sum()
    };
    let ecc = |k: &[i8; 4]| e.powi(i32::from(k[1].abs()));

    let (mut sl, mut sr) = (0.0, 0.0);
    for (k, cl, cr) in LR.iter() {
        let (s, c) = arg(k).sin_cos();
        sl += cl * ecc(k) * s;
        sr += cr * ecc(k) * c;
    }
    let mut sb: f64 = B.iter().map(|(k, cb)| cb * ecc(k) * arg(k).sin()).sum();

    let (l1r, m1r, fr) = (l1.rem_euclid(360.0).to_radians(), args[2], args[3]);
    sl += 3958.0 * a1.sin() + 1962.0 * (l1r - fr).sin() + 318.0 * a2.sin();
    sb += -2235.0 * l1r.sin()
        + 382.0 * a3.sin()
        + 175.0 * (a1 - fr).sin()
        + 175.0 * (a1 + fr).sin()
        + 127.0 * (l1r - m1r).sin()
        - 115.0 * (l1r + m1r).sin();

    Geocentric {
        lambda_deg: (l1 + sl / 1e6).rem_euclid(360.0),
        beta_deg: sb / 1e6,
        distance_km: 385000.56 + sr / 1e3,
    }
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;

    /// Julian centuries of TT from J2000.0 to 1992 April 12, 0h TD (JDE 2448724.5).
    pub(in crate::moon) const T_47A: f64 = (2448724.5 - 2451545.0) / 36525.0;

    /// Meeus's example 47.a, to half a unit of each printed digit.
    #[test]
    fn meeus_example_47a() {
        let g = geocentric(T_47A);
        let cases = [
            ("lambda", g.lambda_deg, 133.162655, 5e-7),
            ("beta", g.beta_deg, -3.229126, 5e-7),
            ("distance km", g.distance_km, 368409.7, 0.05),
            (
                "parallax",
                // Equatorial horizontal parallax: sin π = a / Δ.
                (EARTH_RADIUS_KM / g.distance_km).asin().to_degrees(),
                0.991990,
                5e-7,
            ),
        ];
        for (name, got, want, tol) in cases {
            assert!(
                (got - want).abs() <= tol,
                "{name}: got {got}, Meeus {want} (tolerance {tol})"
            );
        }
    }
}
