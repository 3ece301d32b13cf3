//! Colours that do not come from the database: the sky, haze and wall shading.
//!
//! Invariant: every function here is a pure function of its arguments (no state, no
//! randomness), so the same frame renders to the same bytes.

use super::march::Face;

/// Haze colour at the horizon, RGB.
pub const HORIZON: [f64; 3] = [206.0, 216.0, 228.0];
/// Sky colour at the zenith, RGB.
pub const ZENITH: [f64; 3] = [58.0, 108.0, 190.0];
/// Elevation over which the horizon haze fades into the zenith blue, radians (e-folding).
const HAZE_BAND_RAD: f64 = 0.12;

/// Sky colour for a ray whose direction has vertical component `dz` (sine of its elevation):
/// haze at and below the horizon blending into blue overhead ([`sky_formula`]).
///
/// Read from a table of the sines at which the formula's colour changes (a few hundred, found
/// once per process by bisection over the f64s in `(0, 1]`), so a sky pixel costs a lookup
/// instead of an arcsine and an exponential. Equal to [`sky_formula`] at every `dz` because
/// each channel of the formula is monotone in `dz` (the test checks the breakpoints, an ulp
/// either side of them, and random sines).
pub fn sky(dz: f64) -> [u8; 3] {
    if dz.is_nan() || dz <= 0.0 {
        return sky_formula(0.0); // at or below the horizon (NaN too, as the formula has it)
    }
    let table = SkyTable::get();
    // The breakpoints at or below dz: all those at or below its bucket's start, then a few.
    let s = dz.min(1.0);
    let mut k = table.before[(s * SKY_BUCKETS as f64) as usize] as usize;
    while table.changes.get(k).is_some_and(|c| c.0 <= s) {
        k += 1;
    }
    match k {
        0 => table.first,
        k => table.changes[k - 1].1,
    }
}

/// Buckets of equal width in `(0, 1]` that index the sky's breakpoints.
const SKY_BUCKETS: usize = 4096;

/// The sky's colour as a step function of the sine of the elevation in `(0, 1]`.
struct SkyTable {
    /// The colour just above the horizon (at the smallest positive sine).
    first: [u8; 3],
    /// Every sine where the colour changes, with the colour from there on, ascending.
    changes: Vec<(f64, [u8; 3])>,
    /// For bucket `b` (and one past the last), how many breakpoints lie at or below
    /// `b / SKY_BUCKETS` (exact: a power-of-two fraction).
    before: Vec<u16>,
}

impl SkyTable {
    fn get() -> &'static SkyTable {
        static TABLE: std::sync::OnceLock<SkyTable> = std::sync::OnceLock::new();
        TABLE.get_or_init(|| {
            let colour = |bits: u64| sky_formula(f64::from_bits(bits));
            // Over positive f64s, bit order is numeric order: bisect on the bits.
            fn changes(
                a: u64,
                ca: [u8; 3],
                b: u64,
                cb: [u8; 3],
                colour: &dyn Fn(u64) -> [u8; 3],
                out: &mut Vec<(f64, [u8; 3])>,
            ) {
                if ca == cb {
                    return; // monotone channels: no change between equal ends
                }
                if b == a + 1 {
                    out.push((f64::from_bits(b), cb));
                    return;
                }
                let m = a + (b - a) / 2;
                let cm = colour(m);
                changes(a, ca, m, cm, colour, out);
                changes(m, cm, b, cb, colour, out);
            }
            let (lo, hi) = (1u64, 1.0f64.to_bits());
            let mut out = Vec::new();
            changes(lo, colour(lo), hi, colour(hi), &colour, &mut out);
            let before = (0..=SKY_BUCKETS)
                .map(|b| {
                    let start = b as f64 / SKY_BUCKETS as f64;
                    out.partition_point(|c| c.0 <= start) as u16
                })
                .collect();
            SkyTable {
                first: colour(lo),
                changes: out,
                before,
            }
        })
    }
}

/// The sky's colour by its defining formula: the zenith blue mixed into the horizon haze by
/// `1 − exp(−asin(dz) / 0.12)` (0 at and below the horizon, `dz` clamped to 1).
pub fn sky_formula(dz: f64) -> [u8; 3] {
    // asin is positive exactly when dz is: below the horizon no arcsine is needed.
    let w = if dz > 0.0 {
        1.0 - (-dz.min(1.0).asin() / HAZE_BAND_RAD).exp()
    } else {
        0.0
    };
    std::array::from_fn(|k| channel(HORIZON[k] + (ZENITH[k] - HORIZON[k]) * w))
}

/// A colour channel: `x` rounded half away from zero into `0 ..= 255`, exactly
/// `x.round().clamp(0.0, 255.0) as u8` without a library call ([`crate::num::round_i64`]).
#[inline]
pub fn channel(x: f64) -> u8 {
    crate::num::round_i64(x).clamp(0, 255) as u8
}

/// Brightness factor of a face, so that walls read against the tops they stand under.
pub fn face_factor(face: Face) -> f64 {
    match face {
        Face::Top | Face::Step => 1.0,
        Face::WallU => 0.8,
        Face::WallV => 0.65,
        Face::Bottom => 0.5,
    }
}

/// What a view shows where a ray hits nothing, and the colour range haze fades toward.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Backdrop {
    /// Daylight: blue sky over the horizon haze ([`sky`]); haze fades to [`HORIZON`].
    Daylight,
    /// One colour for the whole sky and one for haze (a sensor's view).
    Flat {
        /// The sky, RGB.
        sky: [u8; 3],
        /// What haze fades toward, RGB.
        haze: [f64; 3],
    },
}

impl Backdrop {
    /// The thermal-infrared backdrop for white-hot `scale`: a black sky (a clear sky's
    /// brightness temperature lies tens of kelvin below any surface under it) and haze fading
    /// toward the grey of the scale's middle, standing in for air near the ground's temperature.
    pub fn infrared(scale: &super::sensor::IrScale) -> Backdrop {
        let mid = scale.grey(((scale.min_k + scale.max_k) / 2.0) as f32)[0];
        Backdrop::Flat {
            sky: [0, 0, 0],
            haze: [f64::from(mid); 3],
        }
    }

    /// The sky's colour for a ray whose direction has vertical component `dz`.
    pub fn sky(&self, dz: f64) -> [u8; 3] {
        match self {
            Backdrop::Daylight => sky(dz),
            Backdrop::Flat { sky, .. } => *sky,
        }
    }

    /// The colour of a hit seen at `range` metres: the face-shaded cell colour, blended toward
    /// the haze colour by `1 − exp(−range / visibility)` when a visibility (metres) is given.
    ///
    /// Without haze the blend's weight is 0 and the haze colour finite, so `c + (haze − c)·0`
    /// is `c` and an undarkened face keeps the cell's own bytes: those return at once.
    #[inline]
    pub fn shade(
        &self,
        colour: [u8; 4],
        face: Face,
        range: f64,
        visibility: Option<f64>,
    ) -> [u8; 3] {
        let f = face_factor(face);
        let Some(v) = visibility else {
            return match f == 1.0 {
                true => [colour[0], colour[1], colour[2]],
                false => std::array::from_fn(|k| channel(colour[k] as f64 * f)),
            };
        };
        let haze = match self {
            Backdrop::Daylight => HORIZON,
            Backdrop::Flat { haze, .. } => *haze,
        };
        let a = 1.0 - (-range / v).exp();
        std::array::from_fn(|k| {
            let c = colour[k] as f64 * f;
            channel(c + (haze[k] - c) * a)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sky_is_haze_at_the_horizon_and_bluer_overhead() {
        assert_eq!(sky(0.0), [206, 216, 228]);
        assert_eq!(sky(-0.5), sky(0.0));
        let up = sky(1.0);
        assert!(up[2] as i32 - up[0] as i32 > sky(0.1)[2] as i32 - sky(0.1)[0] as i32);
    }

    #[test]
    fn sky_table_gives_the_formula_at_its_breakpoints_next_to_them_and_anywhere() {
        let changes = &SkyTable::get().changes;
        assert!(
            changes.len() > 100 && changes.len() < 400,
            "{}",
            changes.len()
        );
        let ulp = |s: f64, k: i64| f64::from_bits((s.to_bits() as i64 + k) as u64);
        for &(s, _) in changes {
            for x in [ulp(s, -1), s, ulp(s, 1)] {
                assert_eq!(sky(x), sky_formula(x), "{x:e}");
            }
        }
        let mut x = 0x2545_f491_4f6c_dd1d_u64; // xorshift: random sines, uniform and tiny
        for _ in 0..200_000 {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            let s = (x >> 11) as f64 / (1u64 << 53) as f64;
            for s in [s, s * 1e-3, s * 1e-9, 1.0 + s] {
                assert_eq!(sky(s), sky_formula(s), "{s:e}");
            }
        }
        for s in [
            0.0,
            -0.0,
            -0.5,
            f64::MIN_POSITIVE,
            5e-324,
            1.0,
            f64::NAN,
            f64::INFINITY,
        ] {
            assert_eq!(sky(s), sky_formula(s), "{s:e}");
        }
    }

    #[test]
    fn channel_is_round_then_clamp() {
        for x in [
            -1.0,
            -0.5,
            -0.0,
            0.0,
            0.49999999999999994,
            0.5,
            1.5,
            2.5,
            254.49,
            254.5,
            255.0,
            300.0,
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
        ] {
            assert_eq!(channel(x), x.round().clamp(0.0, 255.0) as u8, "{x}");
        }
    }

    #[test]
    fn haze_grows_with_range() {
        let c = [0, 0, 0, 255];
        let day = Backdrop::Daylight;
        assert_eq!(day.shade(c, Face::Top, 100.0, None), [0, 0, 0]);
        assert!(
            day.shade(c, Face::Top, 100.0, Some(1000.0))[0]
                < day.shade(c, Face::Top, 5000.0, Some(1000.0))[0]
        );
        assert_eq!(
            day.shade([100, 100, 100, 255], Face::WallV, 0.0, None),
            [65, 65, 65]
        );
        // A flat backdrop's haze takes over at long range; its sky is one colour.
        let ir = Backdrop::Flat {
            sky: [0, 0, 0],
            haze: [128.0; 3],
        };
        assert_eq!(ir.shade(c, Face::Top, 1e9, Some(1000.0)), [128, 128, 128]);
        assert_eq!(ir.sky(0.3), [0, 0, 0]);
    }
}
