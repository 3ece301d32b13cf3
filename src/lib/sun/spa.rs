//! The NREL Solar Position Algorithm (Reda & Andreas 2004, NREL/TP-560-34302, revised 2008),
//! steps 3.1–3.14: from a time and an observer to the topocentric zenith and azimuth.
//!
//! Invariant: this is SPA term for term (same tables, same constants, same order of operations
//! as NREL's `spa.c`), so above the refraction cut-off it reproduces SPA's own output to
//! floating-point rounding. The one deliberate departure is below that cut-off (geometric
//! elevation < −0.83337°), where SPA drops refraction to zero in one step; here it fades
//! linearly to zero over [`REFRACTION_FADE_DEG`] so elevation stays continuous in time.
//! Angles are radians inside except where SPA itself works in degrees (its polynomials).

use super::terms::{B, L, NUTATION_ABCD, NUTATION_Y, R};

/// Apparent radius of the sun, degrees (SPA's `SUN_RADIUS`).
const SUN_RADIUS_DEG: f64 = 0.26667;
/// Refraction at the horizon, degrees (SPA's default `atmos_refract`).
const HORIZON_REFRACTION_DEG: f64 = 0.5667;
/// Width, degrees of geometric elevation, over which refraction fades to zero below SPA's cut-off.
pub(super) const REFRACTION_FADE_DEG: f64 = 1.0;
/// Julian day of the J2000.0 epoch.
const J2000: f64 = 2451545.0;

/// SPA inputs, in SPA's units. Validated by the caller.
pub(crate) struct Input {
    /// UT1 days since J2000.0 (JD − 2451545), split off so no precision is lost in the JD's
    /// large integer part.
    pub days_j2000: f64,
    /// TT − UT1, seconds.
    pub delta_t_s: f64,
    /// Geodetic latitude, degrees, +north.
    pub latitude_deg: f64,
    /// Longitude, degrees, +east.
    pub longitude_deg: f64,
    /// Height above the ellipsoid (SPA: above sea level), metres.
    pub height_m: f64,
    /// `Some((pressure mbar, temperature °C))` to apply refraction, `None` for the geometric sun.
    pub refraction: Option<(f64, f64)>,
}

/// Every intermediate SPA value the paper tabulates (Table A5.1), degrees unless stated. The
/// public API needs only the last four; the rest are kept so the tests can check each SPA step
/// against the paper.
#[derive(Debug, Clone, Copy)]
#[cfg_attr(not(test), allow(dead_code))]
pub(crate) struct Output {
    /// Julian day (UT1).
    pub jd: f64,
    /// Earth heliocentric longitude L, latitude B, degrees; radius vector R, AU.
    pub l: f64,
    pub b: f64,
    pub r: f64,
    /// Nutation in longitude Δψ and obliquity Δε; true obliquity ε.
    pub delta_psi: f64,
    pub delta_eps: f64,
    pub epsilon: f64,
    /// Apparent sun longitude λ, apparent sidereal time ν at Greenwich.
    pub lambda: f64,
    pub nu: f64,
    /// Geocentric right ascension α [0,360) and declination δ.
    pub alpha: f64,
    pub delta: f64,
    /// Observer local hour angle H [0,360).
    pub hour_angle: f64,
    /// Topocentric elevation without and with refraction.
    pub e0: f64,
    pub e: f64,
    /// Topocentric zenith angle 90 − e.
    pub zenith: f64,
    /// Topocentric azimuth, clockwise from north, [0,360).
    pub azimuth: f64,
}

/// Runs SPA for one instant and observer.
pub(crate) fn spa(inp: &Input) -> Output {
    let jd = J2000 + inp.days_j2000;
    let jc = inp.days_j2000 / 36525.0;
    let jce = (inp.days_j2000 + inp.delta_t_s / 86400.0) / 36525.0;
    let jme = jce / 10.0;

    // 3.2 Earth heliocentric position.
    let l = wrap_deg(earth_series(&L, jme).to_degrees());
    let b = earth_series(&B, jme).to_degrees();
    let r = earth_series(&R, jme);

    // 3.3 Geocentric position.
    let theta = wrap_deg(l + 180.0);
    let beta = -b;

    // 3.4 Nutation.
    let (delta_psi, delta_eps) = nutation(jce);

    // 3.5 True obliquity of the ecliptic.
    let u = jme / 10.0;
    let eps0 = poly(
        u,
        &[
            84381.448, -4680.93, -1.55, 1999.25, -51.38, -249.67, -39.05, 7.12, 27.87, 5.79, 2.45,
        ],
    );
    let epsilon = eps0 / 3600.0 + delta_eps;

    // 3.6–3.7 Aberration and apparent sun longitude.
    let delta_tau = -20.4898 / (3600.0 * r);
    let lambda = theta + delta_psi + delta_tau;

    // 3.8 Apparent sidereal time at Greenwich.
    let nu0 = wrap_deg(
        280.46061837 + 360.98564736629 * inp.days_j2000 + jc * jc * (0.000387933 - jc / 38710000.0),
    );
    let nu = nu0 + delta_psi * epsilon.to_radians().cos();

    // 3.9–3.10 Geocentric right ascension and declination.
    let (lam, eps, bet) = (lambda.to_radians(), epsilon.to_radians(), beta.to_radians());
    let alpha = wrap_deg(
        (lam.sin() * eps.cos() - bet.tan() * eps.sin())
            .atan2(lam.cos())
            .to_degrees(),
    );
    // Clamped: rounding can carry the sine of an overhead sun a few ulps past 1 (asin → NaN).
    let delta = (bet.sin() * eps.cos() + bet.cos() * eps.sin() * lam.sin())
        .clamp(-1.0, 1.0)
        .asin()
        .to_degrees();

    // 3.11 Observer local hour angle.
    let hour_angle = wrap_deg(nu + inp.longitude_deg - alpha);

    // 3.12 Topocentric right ascension and declination (parallax).
    let xi = (8.794 / (3600.0 * r)).to_radians();
    let phi = inp.latitude_deg.to_radians();
    let uu = (0.99664719 * phi.tan()).atan();
    let x = uu.cos() + inp.height_m / 6378140.0 * phi.cos();
    let y = 0.99664719 * uu.sin() + inp.height_m / 6378140.0 * phi.sin();
    let (h, dl) = (hour_angle.to_radians(), delta.to_radians());
    let delta_alpha = (-x * xi.sin() * h.sin()).atan2(dl.cos() - x * xi.sin() * h.cos());
    let delta_prime =
        ((dl.sin() - y * xi.sin()) * delta_alpha.cos()).atan2(dl.cos() - x * xi.sin() * h.cos());

    // 3.13 Topocentric local hour angle.
    let h_prime = h - delta_alpha;

    // 3.14 Topocentric elevation, refraction, zenith and azimuth.
    // Clamped for the same reason: at the subsolar point the sum rounds to 1 + 2e-16.
    let e0 = (phi.sin() * delta_prime.sin() + phi.cos() * delta_prime.cos() * h_prime.cos())
        .clamp(-1.0, 1.0)
        .asin()
        .to_degrees();
    let e = e0
        + inp
            .refraction
            .map_or(0.0, |(p, t)| refraction_deg(e0, p, t));
    let gamma = h_prime
        .sin()
        .atan2(h_prime.cos() * phi.sin() - delta_prime.tan() * phi.cos());
    let azimuth = wrap_deg(gamma.to_degrees() + 180.0);

    Output {
        jd,
        l,
        b,
        r,
        delta_psi,
        delta_eps,
        epsilon,
        lambda,
        nu,
        alpha,
        delta,
        hour_angle,
        e0,
        e,
        zenith: 90.0 - e,
        azimuth,
    }
}

/// Atmospheric refraction, degrees, at geometric elevation `e0` (degrees) for pressure `p`
/// (mbar) and temperature `t` (°C): SPA's (Bennett-type) formula down to the cut-off where the
/// sun's upper limb sets, then a linear fade to zero over [`REFRACTION_FADE_DEG`].
pub(crate) fn refraction_deg(e0: f64, p: f64, t: f64) -> f64 {
    let cutoff = -(SUN_RADIUS_DEG + HORIZON_REFRACTION_DEG);
    let bennett = |e: f64| {
        (p / 1010.0) * (283.0 / (273.0 + t)) * 1.02
            / (60.0 * (e + 10.3 / (e + 5.11)).to_radians().tan())
    };
    if e0 >= cutoff {
        bennett(e0)
    } else {
        bennett(cutoff) * (1.0 + (e0 - cutoff) / REFRACTION_FADE_DEG).max(0.0)
    }
}

/// Σᵢ τⁱ Σⱼ Aⱼ cos(Bⱼ + Cⱼ τ) / 10⁸: one of L, B, R (radians or AU).
fn earth_series(series: &[&[[f64; 3]]], jme: f64) -> f64 {
    let horner = series.iter().rev().fold(0.0, |acc, terms| {
        acc * jme
            + terms
                .iter()
                .map(|[a, b, c]| a * (b + c * jme).cos())
                .sum::<f64>()
    });
    horner / 1e8
}

/// Nutation in longitude and obliquity (Δψ, Δε), degrees, at `jce` Julian ephemeris centuries.
fn nutation(jce: f64) -> (f64, f64) {
    // Mean elongation of the Moon, mean anomalies of Sun and Moon, Moon's argument of latitude,
    // longitude of the Moon's ascending node: degrees.
    let x = [
        poly(jce, &[297.85036, 445267.111480, -0.0019142, 1.0 / 189474.0]),
        poly(jce, &[357.52772, 35999.050340, -0.0001603, -1.0 / 300000.0]),
        poly(jce, &[134.96298, 477198.867398, 0.0086972, 1.0 / 56250.0]),
        poly(jce, &[93.27191, 483202.017538, -0.0036825, 1.0 / 327270.0]),
        poly(jce, &[125.04452, -1934.136261, 0.0020708, 1.0 / 450000.0]),
    ];
    let (mut psi, mut eps) = (0.0, 0.0);
    for (y, [a, b, c, d]) in NUTATION_Y.iter().zip(NUTATION_ABCD.iter()) {
        let arg: f64 = y
            .iter()
            .zip(x.iter())
            .map(|(&yi, xi)| f64::from(yi) * xi)
            .sum();
        let arg = arg.to_radians();
        psi += (a + b * jce) * arg.sin();
        eps += (c + d * jce) * arg.cos();
    }
    (psi / 36_000_000.0, eps / 36_000_000.0)
}

/// Horner evaluation of `c[0] + c[1] x + c[2] x² + …`.
pub(crate) fn poly(x: f64, c: &[f64]) -> f64 {
    c.iter().rev().fold(0.0, |acc, &k| acc * x + k)
}

/// Degrees reduced to [0, 360) (never 360.0 itself, even after rounding).
pub(crate) fn wrap_deg(d: f64) -> f64 {
    let w = d.rem_euclid(360.0);
    if w >= 360.0 {
        0.0
    } else {
        w
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The worked example of the SPA paper (Reda & Andreas 2004, Table A5.1): 2003-10-17
    /// 12:30:30 local time, UTC−7, so 19:30:30 UTC.
    fn paper_example() -> Output {
        // Days from J2000.0 (2000-01-01T12:00Z) to 2003-10-17T19:30:30Z.
        let days = (1385 * 86400 + 7 * 3600 + 30 * 60 + 30) as f64 / 86400.0;
        spa(&Input {
            days_j2000: days,
            delta_t_s: 67.0,
            latitude_deg: 39.742476,
            longitude_deg: -105.1786,
            height_m: 1830.14,
            refraction: Some((820.0, 11.0)),
        })
    }

    /// Each intermediate value matches the paper to half a unit of its last printed digit
    /// (the paper rounds; SPA's own C output is the same to 1e-10).
    #[test]
    fn paper_intermediate_values() {
        let o = paper_example();
        let cases = [
            ("JD", o.jd, 2452930.312847, 5e-7),
            ("L", o.l, 24.0182616917, 5e-11),
            ("B", o.b, -0.0001011219, 5e-11),
            ("R", o.r, 0.9965422974, 5e-11),
            ("H", o.hour_angle, 11.105902, 5e-7),
            ("delta_psi", o.delta_psi, -0.00399840, 5e-9),
            ("delta_eps", o.delta_eps, 0.00166657, 5e-9),
            ("epsilon", o.epsilon, 23.440465, 5e-7),
            ("lambda", o.lambda, 204.0085519281, 5e-11),
            ("alpha", o.alpha, 202.22741, 5e-6),
            ("delta", o.delta, -9.31434, 5e-6),
            ("e0", o.e0, 39.872046, 5e-7),
            ("zenith", o.zenith, 50.11162, 5e-6),
            ("azimuth", o.azimuth, 194.34024, 5e-6),
        ];
        for (name, got, want, tol) in cases {
            assert!(
                (got - want).abs() <= tol,
                "{name}: got {got}, paper {want} (tolerance {tol})"
            );
        }
    }

    /// Refraction is SPA's formula above the cut-off, continuous through it, fades to zero
    /// below it, and is exactly zero once faded.
    #[test]
    fn refraction_is_continuous_through_the_cutoff() {
        let cutoff = -(SUN_RADIUS_DEG + HORIZON_REFRACTION_DEG);
        let (above, below) = (
            refraction_deg(cutoff, 1013.25, 15.0),
            refraction_deg(cutoff - 1e-9, 1013.25, 15.0),
        );
        assert!(
            (above - below).abs() < 1e-8,
            "step at the cut-off: {above} vs {below}"
        );
        assert!(
            above > 0.5 && above < 0.7,
            "refraction at the cut-off {above}"
        );
        assert_eq!(
            refraction_deg(cutoff - REFRACTION_FADE_DEG, 1013.25, 15.0),
            0.0
        );
        assert_eq!(refraction_deg(-30.0, 1013.25, 15.0), 0.0);
        let half = refraction_deg(cutoff - REFRACTION_FADE_DEG / 2.0, 1013.25, 15.0);
        assert!((half - above / 2.0).abs() < 1e-12);
        // Zero pressure: no air, no refraction.
        assert_eq!(refraction_deg(10.0, 0.0, 15.0), 0.0);
    }

    #[test]
    fn wrap_never_returns_360() {
        assert_eq!(wrap_deg(-1e-17), 0.0);
        assert_eq!(wrap_deg(360.0), 0.0);
        assert_eq!(wrap_deg(-90.0), 270.0);
        assert_eq!(wrap_deg(725.0), 5.0);
    }
}
