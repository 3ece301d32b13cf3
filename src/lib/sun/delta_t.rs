//! ΔT = TT − UT1, the clock difference SPA needs to place the Earth in its orbit, modelled by the
//! Espenak & Meeus (2006) polynomials ("Five Millennium Canon of Solar Eclipses", NASA
//! TP-2006-214141; eclipse.gsfc.nasa.gov/SEcat5/deltatpoly.html).
//!
//! Invariant: [`delta_t_s`] is finite for every finite decimal year and follows the published
//! piecewise polynomials exactly; it is evaluated at the continuous decimal year (not the
//! month-centre approximation), so it changes smoothly with time inside each piece. The pieces
//! meet to within about a second, which moves the sun by under 0.00002°.

use super::spa::poly;

/// ΔT in seconds at the decimal (Gregorian) year `year` (e.g. 2026.5 = early July 2026).
///
/// Measured values agree to a few seconds over 1900–2025 (the 2005–2050 piece over-predicts
/// the real ΔT, about 69 s in 2025, by ~4 s: 0.00005° of solar longitude). Give the
/// observed value through [`super::SunOptions::delta_t_s`] when it matters.
pub fn delta_t_s(year: f64) -> f64 {
    let y = year;
    let long_term = |y: f64| {
        let u = (y - 1820.0) / 100.0;
        -20.0 + 32.0 * u * u
    };
    if y < -500.0 {
        long_term(y)
    } else if y < 500.0 {
        let u = y / 100.0;
        poly(
            u,
            &[
                10583.6,
                -1014.41,
                33.78311,
                -5.952053,
                -0.1798452,
                0.022174192,
                0.0090316521,
            ],
        )
    } else if y < 1600.0 {
        let u = (y - 1000.0) / 100.0;
        poly(
            u,
            &[
                1574.2,
                -556.01,
                71.23472,
                0.319781,
                -0.8503463,
                -0.005050998,
                0.0083572073,
            ],
        )
    } else if y < 1700.0 {
        poly(y - 1600.0, &[120.0, -0.9808, -0.01532, 1.0 / 7129.0])
    } else if y < 1800.0 {
        poly(
            y - 1700.0,
            &[8.83, 0.1603, -0.0059285, 0.00013336, -1.0 / 1_174_000.0],
        )
    } else if y < 1860.0 {
        let c = [
            13.72,
            -0.332447,
            0.0068612,
            0.0041116,
            -0.00037436,
            0.0000121272,
            -0.0000001699,
            0.000000000875,
        ];
        poly(y - 1800.0, &c)
    } else if y < 1900.0 {
        poly(
            y - 1860.0,
            &[
                7.62,
                0.5737,
                -0.251754,
                0.01680668,
                -0.0004473624,
                1.0 / 233_174.0,
            ],
        )
    } else if y < 1920.0 {
        poly(
            y - 1900.0,
            &[-2.79, 1.494119, -0.0598939, 0.0061966, -0.000197],
        )
    } else if y < 1941.0 {
        poly(y - 1920.0, &[21.20, 0.84493, -0.076100, 0.0020936])
    } else if y < 1961.0 {
        poly(y - 1950.0, &[29.07, 0.407, -1.0 / 233.0, 1.0 / 2547.0])
    } else if y < 1986.0 {
        poly(y - 1975.0, &[45.45, 1.067, -1.0 / 260.0, -1.0 / 718.0])
    } else if y < 2005.0 {
        poly(
            y - 2000.0,
            &[
                63.86,
                0.3345,
                -0.060374,
                0.0017275,
                0.000651814,
                0.00002373599,
            ],
        )
    } else if y < 2050.0 {
        poly(y - 2000.0, &[62.92, 0.32217, 0.005589])
    } else if y < 2150.0 {
        long_term(y) - 0.5628 * (2150.0 - y)
    } else {
        long_term(y)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Values from the NASA ΔT table (Espenak & Meeus), observed where available.
    #[test]
    fn matches_published_values() {
        // (year, ΔT s, tolerance s): the polynomials are fits, so compare within their stated error.
        let cases = [
            (1900.0, -2.8, 0.5),
            (1950.0, 29.1, 0.5),
            (1980.0, 50.5, 0.5),
            (2000.0, 63.8, 0.5),
            (2005.0, 64.7, 0.5),
            (1800.0, 13.7, 0.5),
            (1700.0, 8.8, 0.5),
        ];
        for (y, want, tol) in cases {
            let got = delta_t_s(y);
            assert!(
                (got - want).abs() <= tol,
                "ΔT({y}) = {got}, want {want}±{tol}"
            );
        }
    }

    #[test]
    fn pieces_meet_within_a_few_seconds() {
        for b in [
            -500.0, 500.0, 1600.0, 1700.0, 1800.0, 1860.0, 1900.0, 1920.0, 1941.0, 1961.0, 1986.0,
            2005.0, 2050.0, 2150.0,
        ] {
            let jump = delta_t_s(b) - delta_t_s(b - 1e-9);
            assert!(jump.abs() < 3.0, "ΔT jumps by {jump} s at {b}");
        }
    }
}
