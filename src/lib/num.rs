//! Exact numeric helpers for hot loops.

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
}
