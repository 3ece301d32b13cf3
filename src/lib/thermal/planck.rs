//! Blackbody radiance integrated over a wavelength band, and a surface's band radiance.
//!
//! With x = h·c/(λ·k·T), the band radiance of a blackbody is
//!   L = 2·k⁴·T⁴/(h³·c²) · ∫ x³/(eˣ − 1) dx   over the band's x range,
//! and the integral from x to ∞ is summed exactly (Widger & Woodall 1976, *Bull. Am. Meteorol.
//! Soc.* 57(10), 1217–1219): for x ≥ 2 the series Σₙ e^(−n·x)·(x³/n + 3x²/n² + 6x/n³ + 6/n⁴),
//! for x < 2 the complement π⁴/15 − ∫₀ˣ, expanded in Bernoulli numbers. Both converge to full
//! f64 precision within 18 terms at the x = 2 switch, and faster away from it.
//!
//! Invariant: `band_radiance(T, 0..∞) = σ·T⁴/π` to round-off; every function here returns an
//! error, not NaN, for a non-positive temperature or an empty band.

use crate::{Error, Result};

/// The Planck constant h, J·s (exact in the SI since 2019; CODATA 2018).
pub const PLANCK_J_S: f64 = 6.626_070_15e-34;
/// The speed of light in vacuum c, m/s (exact).
pub const SPEED_OF_LIGHT_M_PER_S: f64 = 299_792_458.0;
/// The Boltzmann constant k, J/K (exact in the SI since 2019; CODATA 2018).
pub const BOLTZMANN_J_PER_K: f64 = 1.380_649e-23;

/// A wavelength band, m: `low_m` < `high_m`; `high_m` may be infinite, `low_m` may be 0.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Band {
    /// The short-wavelength end, m (≥ 0).
    pub low_m: f64,
    /// The long-wavelength end, m (> `low_m`; may be infinite).
    pub high_m: f64,
}

/// The 8–12 µm thermal-infrared window the IR sensor images.
pub const BAND_8_12_UM: Band = Band {
    low_m: 8e-6,
    high_m: 12e-6,
};

impl Default for Band {
    /// [`BAND_8_12_UM`].
    fn default() -> Band {
        BAND_8_12_UM
    }
}

/// Planck's law: spectral radiance of a blackbody at wavelength `wavelength_m` (> 0) and
/// temperature `temperature_k` (> 0), W·m⁻²·sr⁻¹ per m of wavelength.
pub fn spectral_radiance(wavelength_m: f64, temperature_k: f64) -> f64 {
    let (h, c, k) = (PLANCK_J_S, SPEED_OF_LIGHT_M_PER_S, BOLTZMANN_J_PER_K);
    2.0 * h * c * c / wavelength_m.powi(5) / (h * c / (wavelength_m * k * temperature_k)).exp_m1()
}

/// Blackbody radiance at `temperature_k` (> 0) integrated over `band`, W·m⁻²·sr⁻¹.
pub fn band_radiance(temperature_k: f64, band: Band) -> Result<f64> {
    if !(temperature_k > 0.0 && temperature_k.is_finite()) {
        return Err(
            Error::msg(format!("temperature {temperature_k} K is not above 0 K"))
                .fix("give the temperature in kelvin"),
        );
    }
    if !(band.low_m >= 0.0 && band.high_m > band.low_m) {
        return Err(Error::msg(format!(
            "wavelength band {} m .. {} m is empty or negative",
            band.low_m, band.high_m
        ))
        .fix("give the band's ends in metres, short first (8e-6 .. 12e-6)"));
    }
    let (h, c, k) = (PLANCK_J_S, SPEED_OF_LIGHT_M_PER_S, BOLTZMANN_J_PER_K);
    let kt = k * temperature_k;
    let scale = 2.0 * kt.powi(4) / (h.powi(3) * c * c);
    let x = |wavelength_m: f64| h * c / (wavelength_m * kt); // 1/0 = ∞, 1/∞ = 0
    Ok(scale * (tail(x(band.high_m)) - tail(x(band.low_m))))
}

/// A surface's band radiance, W·m⁻²·sr⁻¹: its emission ε·B(T) plus the sky's band radiance
/// `sky_band_radiance` (W·m⁻²·sr⁻¹, ≥ 0) reflected by (1 − ε), for emissivity ε in (0, 1].
pub fn surface_band_radiance(
    temperature_k: f64,
    emissivity: f64,
    sky_band_radiance: f64,
    band: Band,
) -> Result<f64> {
    if !(emissivity > 0.0 && emissivity <= 1.0) {
        return Err(
            Error::msg(format!("emissivity {emissivity} is outside (0, 1]"))
                .fix("give the material's band emissivity"),
        );
    }
    if !(sky_band_radiance >= 0.0 && sky_band_radiance.is_finite()) {
        return Err(Error::msg(format!(
            "sky band radiance {sky_band_radiance} W/(m²·sr) is negative or not a number"
        ))
        .fix("give the sky's radiance over the same band"));
    }
    Ok(emissivity * band_radiance(temperature_k, band)? + (1.0 - emissivity) * sky_band_radiance)
}

/// B_{2k}/(2k)! for k = 1..=18: the Bernoulli coefficients of t/(eᵗ − 1).
const BERNOULLI_OVER_FACTORIAL: [f64; 18] = [
    0.083_333_333_333_333_33,
    -0.001_388_888_888_888_889,
    3.306_878_306_878_307e-5,
    -8.267_195_767_195_768e-7,
    2.087_675_698_786_81e-8,
    -5.284_190_138_687_493e-10,
    1.338_253_653_068_467_9e-11,
    -3.389_680_296_322_582_7e-13,
    8.586_062_056_277_845e-15,
    -2.174_868_698_558_062e-16,
    5.509_002_828_360_229_5e-18,
    -1.395_446_468_581_252_2e-19,
    3.534_707_039_629_467e-21,
    -8.953_517_427_037_546e-23,
    2.267_952_452_337_683e-24,
    -5.744_790_668_872_202e-26,
    1.455_172_475_614_865e-27,
    -3.685_994_940_665_310_3e-29,
];

/// ∫ₓ^∞ t³/(eᵗ − 1) dt for x ≥ 0 (∞ gives 0): each series where it converges fastest.
fn tail(x: f64) -> f64 {
    if x < 2.0 {
        tail_by_complement(x)
    } else if x > 700.0 {
        0.0 // e^(−700)·700³ < 1e-295: nothing a radiance can hold
    } else {
        tail_by_exponentials(x)
    }
}

/// π⁴/15 − ∫₀ˣ, with t³/(eᵗ − 1) = t² − t³/2 + Σ b_k·t^(2k+2) integrated term by term
/// (converges for x < 2π; 18 terms reach f64 precision up to x = 2).
fn tail_by_complement(x: f64) -> f64 {
    let x2 = x * x;
    let mut power = x2 * x2 * x; // x^(2k+3) for k = 1
    let mut head = x2 * x / 3.0 - x2 * x2 / 8.0;
    for (i, b) in BERNOULLI_OVER_FACTORIAL.iter().enumerate() {
        head += b * power / (2 * i + 5) as f64;
        power *= x2;
    }
    std::f64::consts::PI.powi(4) / 15.0 - head
}

/// Σₙ e^(−n·x)·(x³/n + 3x²/n² + 6x/n³ + 6/n⁴) until a term no longer counts (x > 0; at
/// x = 2 about 18 terms).
fn tail_by_exponentials(x: f64) -> f64 {
    let mut sum = 0.0;
    for n in 1..=64 {
        let n = n as f64;
        let term = (-n * x).exp() * (x * x * x + (3.0 * x * x + (6.0 * x + 6.0 / n) / n) / n) / n;
        sum += term;
        if term < sum * 1e-18 {
            break;
        }
    }
    sum
}

#[cfg(test)]
mod tests {
    use super::super::STEFAN_BOLTZMANN;
    use super::*;

    /// σ from the exact h, c, k: the Stefan–Boltzmann constant we use is CODATA 2018's.
    #[test]
    fn sigma_is_the_one_the_exact_constants_give() {
        let (h, c, k) = (PLANCK_J_S, SPEED_OF_LIGHT_M_PER_S, BOLTZMANN_J_PER_K);
        let sigma = 2.0 * std::f64::consts::PI.powi(5) * k.powi(4) / (15.0 * h.powi(3) * c * c);
        assert!((sigma / STEFAN_BOLTZMANN - 1.0).abs() < 1e-15, "{sigma}");
        assert!((STEFAN_BOLTZMANN - 5.670_374_419e-8).abs() < 1e-17);
    }

    /// 0..∞ is σT⁴/π (the complement's π⁴/15 and the temperature scale).
    #[test]
    fn the_whole_spectrum_is_stefan_boltzmann() {
        for t in [3.0, 77.0, 250.0, 300.0, 1000.0, 5772.0] {
            let all = band_radiance(
                t,
                Band {
                    low_m: 0.0,
                    high_m: f64::INFINITY,
                },
            )
            .unwrap();
            let want = STEFAN_BOLTZMANN * t.powi(4) / std::f64::consts::PI;
            assert!((all / want - 1.0).abs() < 1e-14, "{t}: {all} {want}");
        }
    }

    /// The two series agree where both converge, around the x = 2 switch, to 1e-15 of the
    /// whole (mutation check: the coefficient B₆/6! as 3.307e-5 instead of 3.3069e-5, or the
    /// exponential series' 6/n⁴ as 6/n³, fails).
    #[test]
    fn both_series_agree_around_the_switch() {
        let whole = std::f64::consts::PI.powi(4) / 15.0;
        for x in [0.5, 1.0, 1.5, 1.9, 2.0, 2.1] {
            let (a, b) = (tail_by_complement(x), tail_by_exponentials(x));
            assert!((a - b).abs() < 1e-15 * whole, "{x}: {a} {b}");
        }
    }

    /// The series against a brute-force trapezoid of Planck's law (10⁶ panels: error ~1e-11),
    /// and against references (here rounded to f64) made with mpmath 1.3.0 (30 digits) as
    /// `mp.quad(lambda l: 2*h*c**2/l**5/(mp.exp(h*c/(l*k*T))-1), [a, b])` with the exact
    /// CODATA 2018 h, c, k (mutation check: k = 1.380 648 52e-23, CODATA 2014, fails the
    /// references at 1e-12).
    #[test]
    fn bands_match_a_trapezoid_and_independent_references() {
        for (t, a, b, reference) in [
            (300.0, 8e-6, 12e-6, 38.500_423_933_347_87),
            (300.0, 8e-6, 14e-6, 54.933_461_376_839_69),
            (300.0, 3e-6, 5e-6, 1.865_956_208_161_690_5),
            (250.0, 8e-6, 12e-6, 14.559_300_975_419_022),
            (300.0, 20e-6, 100e-6, 37.646_713_615_289_556), // x from 2.4 to 0.48
            (1000.0, 8e-6, 12e-6, 1_602.829_863_463_345_4), // x from 1.8 to 1.2
        ] {
            let band = Band {
                low_m: a,
                high_m: b,
            };
            let series = band_radiance(t, band).unwrap();
            assert!(
                (series / reference - 1.0).abs() < 1e-13,
                "{series} {reference}"
            );
            let n = 1_000_000;
            let dl = (b - a) / n as f64;
            let inner: f64 = (1..n)
                .map(|i| spectral_radiance(a + i as f64 * dl, t))
                .sum();
            let trapezoid =
                dl * (inner + 0.5 * (spectral_radiance(a, t) + spectral_radiance(b, t)));
            assert!(
                (trapezoid / series - 1.0).abs() < 1e-10,
                "{trapezoid} {series}"
            );
        }
        assert_eq!(
            band_radiance(300.0, Band::default()).unwrap(),
            band_radiance(300.0, BAND_8_12_UM).unwrap()
        );
    }

    /// ε·B + (1 − ε)·sky: a blackbody ignores the sky, a grey body mixes; bad values are errors.
    #[test]
    fn a_surface_emits_and_reflects_the_sky() {
        let b = band_radiance(300.0, BAND_8_12_UM).unwrap();
        assert_eq!(
            surface_band_radiance(300.0, 1.0, 20.0, BAND_8_12_UM).unwrap(),
            b
        );
        let grey = surface_band_radiance(300.0, 0.9, 20.0, BAND_8_12_UM).unwrap();
        assert!((grey - (0.9 * b + 0.1 * 20.0)).abs() < 1e-12);
        assert!(surface_band_radiance(300.0, 0.0, 20.0, BAND_8_12_UM).is_err());
        assert!(surface_band_radiance(300.0, 0.9, -1.0, BAND_8_12_UM).is_err());
        assert!(band_radiance(0.0, BAND_8_12_UM).is_err());
        assert!(band_radiance(
            300.0,
            Band {
                low_m: 12e-6,
                high_m: 8e-6
            }
        )
        .is_err());
        assert!(band_radiance(
            300.0,
            Band {
                low_m: -1e-6,
                high_m: 8e-6
            }
        )
        .is_err());
    }
}
