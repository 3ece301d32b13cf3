//! From the Moon's ecliptic place to where an observer sees it: apparent geocentric right
//! ascension and declination (Meeus ch. 13 with the nutation Δψ and the true obliquity ε), the
//! topocentric place (Meeus ch. 40, parallax for the observer's latitude and height) and the local
//! horizon (elevation, azimuth).
//!
//! Invariant: all the parallax is here. The Moon's horizontal parallax reaches 1.02°, so every
//! direction this module returns is topocentric (from the observer, not the Earth's centre)
//! except [`apparent_equatorial`]'s, which is geocentric by definition. Radians inside.

/// Right ascension α and declination δ, radians, with the distance in km.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(super) struct Equatorial {
    pub alpha: f64,
    pub delta: f64,
    pub distance_km: f64,
}

/// Apparent geocentric α, δ (Meeus 13.3, 13.4) of ecliptic longitude `lambda` (already with Δψ)
/// and latitude `beta`, for the true obliquity `eps` (all radians).
pub(super) fn apparent_equatorial(
    lambda: f64,
    beta: f64,
    eps: f64,
    distance_km: f64,
) -> Equatorial {
    let (sl, cl) = lambda.sin_cos();
    let (sb, cb) = beta.sin_cos();
    let (se, ce) = eps.sin_cos();
    Equatorial {
        alpha: (sl * ce - sb / cb * se)
            .atan2(cl)
            .rem_euclid(std::f64::consts::TAU),
        delta: (sb * ce + cb * se * sl).clamp(-1.0, 1.0).asin(),
        distance_km,
    }
}

/// The observer's place relative to the Earth's centre (Meeus ch. 11): ρ sin φ′ and ρ cos φ′ in
/// equatorial Earth radii, for geodetic latitude `phi` (radians) and height `height_m` (metres).
pub(super) fn observer_rho(phi: f64, height_m: f64) -> (f64, f64) {
    const B_OVER_A: f64 = 0.99664719;
    const A_M: f64 = 6378140.0;
    let u = (B_OVER_A * phi.tan()).atan();
    (
        B_OVER_A * u.sin() + height_m / A_M * phi.sin(),
        u.cos() + height_m / A_M * phi.cos(),
    )
}

/// Topocentric hour angle H′, declination δ′ (radians) and distance (km) of a body at geocentric
/// hour angle `h` and declination `delta` (radians), `distance_km` from the Earth's centre, seen
/// from an observer at (ρ sin φ′, ρ cos φ′). The vector difference body − observer in the
/// equator-and-meridian frame: the same as Meeus 40.2–40.3 (rigorous method), and it also gives
/// the distance from the observer, which the light model needs.
pub(super) fn topocentric(
    h: f64,
    delta: f64,
    distance_km: f64,
    rho_sin_phi: f64,
    rho_cos_phi: f64,
) -> (f64, f64, f64) {
    let r = distance_km / super::elp::EARTH_RADIUS_KM;
    let (sh, ch) = h.sin_cos();
    let (sd, cd) = delta.sin_cos();
    let x = r * cd * ch - rho_cos_phi;
    let y = r * cd * sh;
    let z = r * sd - rho_sin_phi;
    let horizontal = x.hypot(y);
    (
        y.atan2(x),
        z.atan2(horizontal),
        horizontal.hypot(z) * super::elp::EARTH_RADIUS_KM,
    )
}

/// Elevation above the astronomical horizon and azimuth (clockwise from north, [0, 2π)), radians,
/// of hour angle `h` and declination `delta` for geodetic latitude `phi` (radians). Written with
/// sin δ and cos δ rather than tan δ, so a body at a celestial pole is not a division by zero.
pub(super) fn horizon(h: f64, delta: f64, phi: f64) -> (f64, f64) {
    let (sh, ch) = h.sin_cos();
    let (sd, cd) = delta.sin_cos();
    let (sp, cp) = phi.sin_cos();
    let elevation = (sp * sd + cp * cd * ch).clamp(-1.0, 1.0).asin();
    // Azimuth from the south, westward (Meeus 13.5), turned to from the north, eastward.
    let from_south = (cd * sh).atan2(cd * ch * sp - sd * cp);
    let azimuth = (from_south + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU);
    (elevation, azimuth)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::moon::elp::{geocentric, tests::T_47A};
    use crate::sun::spa;

    /// Meeus example 47.a, apparent place. With the book's Δψ = +0.004610° and ε = 23.440636°
    /// (23°26′26.29″), α and δ match its printed digits to 1e-6° (ε printed to 0.01″, 2.8e-6°,
    /// moves α by up to 1e-6°); with the SPA's (the same IAU 1980
    /// nutation, but Laskar's mean obliquity: ε is 0.004″ lower) they move by under 2e-6°.
    #[test]
    fn meeus_example_47a_apparent() {
        let g = geocentric(T_47A);
        let place = |delta_psi: f64, eps: f64| {
            let q = apparent_equatorial(
                (g.lambda_deg + delta_psi).to_radians(),
                g.beta_deg.to_radians(),
                eps.to_radians(),
                g.distance_km,
            );
            (q.alpha.to_degrees(), q.delta.to_degrees())
        };
        let (alpha, delta) = place(0.004610, 23.0 + 26.0 / 60.0 + 26.29 / 3600.0);
        assert!((alpha - 134.688470).abs() <= 1e-6, "alpha {alpha}");
        assert!((delta - 13.768368).abs() <= 1e-6, "delta {delta}");
        // SPA at JDE 2448724.5: days from J2000 with ΔT = 0 so that UT1 = TT.
        let sun = spa::spa(&spa::Input {
            days_j2000: T_47A * 36525.0,
            delta_t_s: 0.0,
            latitude_deg: 0.0,
            longitude_deg: 0.0,
            height_m: 0.0,
            refraction: None,
        });
        assert!((sun.delta_psi - 0.004610).abs() < 5e-7, "{}", sun.delta_psi);
        let (alpha, delta) = place(sun.delta_psi, sun.epsilon);
        assert!((alpha - 134.688470).abs() <= 2e-6, "alpha {alpha}");
        assert!((delta - 13.768368).abs() <= 2e-6, "delta {delta}");
    }

    /// Meeus ch. 11's example: Palomar (33°21′22″ N, 1706 m) has ρ sin φ′ = 0.546861 and
    /// ρ cos φ′ = 0.836339.
    #[test]
    fn observer_rho_palomar() {
        let (s, c) = observer_rho((33.0 + 21.0 / 60.0 + 22.0 / 3600.0f64).to_radians(), 1706.0);
        assert!(
            (s - 0.546861).abs() < 5e-7 && (c - 0.836339).abs() < 5e-7,
            "{s} {c}"
        );
    }

    /// A body on the geocentric horizon is seen lower by atan(a/Δ) (its parallax, to second
    /// order) and farther; one at the observer's zenith stays there, one Earth radius closer.
    #[test]
    fn parallax_geometry() {
        let d = 384400.0;
        let r = crate::moon::elp::EARTH_RADIUS_KM;
        // Equator, no height: ρ sin φ′ = 0, ρ cos φ′ = 1. Body on the geocentric horizon (H = 90°).
        let (h1, d1, dist) = topocentric(90f64.to_radians(), 0.0, d, 0.0, 1.0);
        let (e, _) = horizon(h1, d1, 0.0);
        let drop = (r / d).atan();
        assert!(
            (e + drop).abs() < 1e-12,
            "{} vs {}",
            e.to_degrees(),
            -drop.to_degrees()
        );
        assert!((dist - d.hypot(r)).abs() < 1e-6);
        // Overhead.
        let (h0, d0, dist0) = topocentric(0.0, 0.0, d, 0.0, 1.0);
        assert!(h0.abs() < 1e-15 && d0.abs() < 1e-15 && (dist0 - (d - r)).abs() < 1e-9);
    }
}
