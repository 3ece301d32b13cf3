//! The Moon's phase: the phase angle i (Sun–Moon–observer) and the illuminated fraction
//! k = (1 + cos i) / 2 of its disc, by Meeus, *Astronomical Algorithms*, ch. 48 (formulas 48.2,
//! 48.3 and 48.1).
//!
//! Invariant: the Sun's place comes from the caller (the NREL SPA in `crate::sun`: apparent
//! geocentric α₀, δ₀ and distance R, far better than Meeus's low-precision sun, and already
//! computed for the sidereal time), so both bodies are in the same frame (apparent, true equinox
//! of date). The result is geocentric, as Meeus's and PyEphem's are.

use super::sky::Equatorial;

/// Phase angle i, radians in [0, π] (0 = full), and illuminated fraction k in [0, 1], of the Moon
/// `moon` with the Sun at `sun` (geocentric, distances in km).
pub(super) fn phase(moon: &Equatorial, sun: &Equatorial) -> (f64, f64) {
    // 48.2: geocentric elongation ψ of the Moon from the Sun.
    let cos_psi = sun.delta.sin() * moon.delta.sin()
        + sun.delta.cos() * moon.delta.cos() * (sun.alpha - moon.alpha).cos();
    let psi = cos_psi.clamp(-1.0, 1.0).acos();
    // 48.3 in its atan2 form, so i is in [0, π] without a quadrant rule.
    let i = (sun.distance_km * psi.sin()).atan2(moon.distance_km - sun.distance_km * psi.cos());
    (i, (1.0 + i.cos()) / 2.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Meeus example 48.a (1992 April 12, 0h TD) from the book's own inputs: the Sun at
    /// α₀ = 1h22m37.9s, δ₀ = +8°41′47″, R = 149 971 520 km; the Moon at α = 8h58m45.2s,
    /// δ = +13°46′06″, Δ = 368 410 km. The book gives i = 69.0756°, k = 0.6786, computed from
    /// unrounded places: its inputs' rounding (0.1 s of α is 0.0004°) allows 5e-4° in i.
    #[test]
    fn meeus_example_48a() {
        let hms = |h: f64, m: f64, s: f64| ((h + m / 60.0 + s / 3600.0) * 15.0).to_radians();
        let dms = |d: f64, m: f64, s: f64| (d + m / 60.0 + s / 3600.0).to_radians();
        let sun = Equatorial {
            alpha: hms(1.0, 22.0, 37.9),
            delta: dms(8.0, 41.0, 47.0),
            distance_km: 149_971_520.0,
        };
        let moon = Equatorial {
            alpha: hms(8.0, 58.0, 45.2),
            delta: dms(13.0, 46.0, 6.0),
            distance_km: 368_410.0,
        };
        let (i, k) = phase(&moon, &sun);
        assert!(
            (i.to_degrees() - 69.0756).abs() < 5e-4,
            "i = {}",
            i.to_degrees()
        );
        assert!((k - 0.6786).abs() < 5e-5, "k = {k}");
    }

    #[test]
    fn full_and_new() {
        let at = |alpha: f64, distance_km: f64| Equatorial {
            alpha,
            delta: 0.0,
            distance_km,
        };
        let sun = at(0.0, 1.496e8);
        let (i, k) = phase(&at(std::f64::consts::PI, 384_400.0), &sun);
        assert!(i.abs() < 1e-12 && (k - 1.0).abs() < 1e-15);
        let (i, k) = phase(&at(0.0, 384_400.0), &sun);
        assert!((i - std::f64::consts::PI).abs() < 1e-12 && k.abs() < 1e-15);
    }
}
