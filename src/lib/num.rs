//! Exact numeric helpers for hot loops, and the one reproducible random generator.

/// ⌊x⌋ as an integer: exactly `x.floor() as i64` (saturating beyond the `i64` range, 0 for
/// NaN), without a library call. Baseline x86-64 has no rounding instruction, so `f64::floor`
/// calls the C library there: 3 % of `shadow-height`'s time in a city, measured.
#[inline]
pub fn floor_i64(x: f64) -> i64 {
    let t = x as i64; // toward zero, saturating
    t.saturating_sub(((t as f64) > x) as i64)
}

/// `x` rounded half away from zero, as an integer: exactly `x.round() as i64` (saturating
/// beyond the `i64` range, 0 for NaN), without a library call (see [`floor_i64`]).
#[inline]
pub fn round_i64(x: f64) -> i64 {
    let t = x as i64; // toward zero, saturating
                      // Exact: x and t share a sign and differ by less than 1 (or x is an integer).
                      // Without a branch: which way a pixel rounds is a coin toss.
    let frac = x - t as f64;
    t.saturating_add((frac >= 0.5) as i64 - (frac <= -0.5) as i64)
}

/// Added to a SplitMix64 state before each output (the golden ratio's fraction of 2⁶⁴).
const GOLDEN_GAMMA: u64 = 0x9E37_79B9_7F4A_7C15;

/// The SplitMix64 output for state `z`: the state advanced by the golden gamma, then mixed
/// (Steele, Lea & Flood, OOPSLA 2014). Written out rather than taken from a generator crate,
/// whose streams may change between versions: seeded results stay the same on every machine
/// and dbms version.
pub fn splitmix64(z: u64) -> u64 {
    let z = z.wrapping_add(GOLDEN_GAMMA);
    let z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    let z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// A SplitMix64 stream from a seed (its state): a tiny, well-mixed, reproducible generator.
pub struct SplitMix(pub u64);

impl SplitMix {
    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        let out = splitmix64(self.0);
        self.0 = self.0.wrapping_add(GOLDEN_GAMMA);
        out
    }

    /// Uniform in `[-1, 1)`.
    pub fn signed(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 52) as f64 - 1.0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_i64_is_round_at_halves_ulps_off_them_and_the_extremes() {
        let half_below = 0.5 - f64::EPSILON / 4.0; // 0.49999999999999994
        let cases = [
            0.0,
            -0.0,
            0.5,
            -0.5,
            half_below,
            -half_below,
            1.5,
            2.5,
            -2.5,
            254.5,
            254.5 - 254.5 * f64::EPSILON,
            255.49999999999997,
            5_310_000.5,
            2f64.powi(52) + 1.0,
            2f64.powi(53) - 1.0,
            1e19,
            -1e19,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
        ];
        for x in cases {
            assert_eq!(round_i64(x), x.round() as i64, "{x:e}");
        }
        for k in 0..100_000 {
            let x = k as f64 * 0.0025 - 100.0;
            assert_eq!(round_i64(x), x.round() as i64, "{x:e}");
        }
    }

    #[test]
    fn floor_i64_is_floor_at_integers_halves_ulps_and_the_extremes() {
        let cases = [
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.0,
            -1.0,
            1.0 - f64::EPSILON / 2.0,
            -1.0 + f64::EPSILON / 2.0,
            -1.0 - f64::EPSILON,
            5_310_000.25,
            -5_310_000.25,
            2f64.powi(52) + 1.0,
            -(2f64.powi(52) + 1.0),
            1e19,
            -1e19,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
            f64::MIN_POSITIVE,
            -f64::MIN_POSITIVE,
        ];
        for x in cases {
            assert_eq!(floor_i64(x), x.floor() as i64, "{x:e}");
        }
    }

    #[test]
    fn splitmix_matches_the_reference_generator() {
        // The first outputs of Vigna's splitmix64.c seeded with 0.
        let mut g = SplitMix(0);
        assert_eq!(g.next_u64(), 0xE220_A839_7B1D_CDAF);
        assert_eq!(g.next_u64(), 0x6E78_9E6A_A1B9_65F4);
        assert_eq!(splitmix64(0), 0xE220_A839_7B1D_CDAF);
    }
}
