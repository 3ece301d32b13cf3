//! Exact numeric helpers for hot loops.

/// ⌊x⌋ as an integer: exactly `x.floor() as i64` (saturating beyond the `i64` range, 0 for
/// NaN), without a library call. Baseline x86-64 has no rounding instruction, so `f64::floor`
/// calls the C library there: 3 % of `shadow-height`'s time in a city, measured.
#[inline]
pub fn floor_i64(x: f64) -> i64 {
    let t = x as i64; // toward zero, saturating
    t.saturating_sub(((t as f64) > x) as i64)
}

#[cfg(test)]
mod tests {
    use super::*;

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
