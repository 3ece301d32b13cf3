//! Seeded hashing, a small deterministic RNG and value noise: the only randomness of the sample.
//! Everything is a pure function of its inputs (no global state, no platform dependence).

/// SplitMix64 finaliser: a well-mixed 64-bit hash of `x`.
#[inline]
pub fn mix(mut x: u64) -> u64 {
    x = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    x = (x ^ (x >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    x ^ (x >> 31)
}

/// Hash of a lattice point and a seed, uniform in [−1, 1].
#[inline]
fn lattice(seed: u64, ix: i64, iy: i64) -> f64 {
    let h = mix(seed
        ^ mix((ix as u64).wrapping_mul(0xA24B_AED4_963E_E407)
            ^ (iy as u64).wrapping_mul(0x9FB2_1C65_1E98_DF25)));
    (h >> 11) as f64 / (1u64 << 52) as f64 - 1.0
}

/// Value noise in [−1, 1] with unit lattice spacing: lattice values blended by the quintic fade
/// `6t⁵ − 15t⁴ + 10t³`, so the surface has continuous slope. The steepest slope is
/// at most 3.75 per unit (1.875 × the lattice range 2).
pub fn value_noise(seed: u64, x: f64, y: f64) -> f64 {
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let fade = |t: f64| t * t * t * (t * (t * 6.0 - 15.0) + 10.0);
    let (u, v) = (fade(fx), fade(fy));
    let (ix, iy) = (x0 as i64, y0 as i64);
    let a = lattice(seed, ix, iy) + u * (lattice(seed, ix + 1, iy) - lattice(seed, ix, iy));
    let b =
        lattice(seed, ix, iy + 1) + u * (lattice(seed, ix + 1, iy + 1) - lattice(seed, ix, iy + 1));
    a + v * (b - a)
}

/// Sum of value-noise octaves `(wavelength, amplitude)` at `(x, y)` (same units as the
/// wavelengths); each octave has its own seed.
pub fn octaves(seed: u64, x: f64, y: f64, bands: &[(f64, f64)]) -> f64 {
    bands
        .iter()
        .enumerate()
        .map(|(i, &(wavelength, amplitude))| {
            amplitude * value_noise(mix(seed ^ i as u64), x / wavelength, y / wavelength)
        })
        .sum()
}

/// A small deterministic random number generator (SplitMix64 stream).
pub struct Rng(u64);

impl Rng {
    /// A stream for `seed`.
    pub fn new(seed: u64) -> Rng {
        Rng(mix(seed))
    }

    /// Next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        mix(self.0)
    }

    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * ((self.next_u64() >> 11) as f64 / (1u64 << 53) as f64)
    }

    /// Uniform in [lo, hi) rounded down to a multiple of `step`.
    pub fn stepped(&mut self, lo: f64, hi: f64, step: f64) -> f64 {
        (self.range(lo, hi) / step).floor() * step
    }

    /// Fisher–Yates shuffle.
    pub fn shuffle<T>(&mut self, v: &mut [T]) {
        for i in (1..v.len()).rev() {
            let j = (self.next_u64() % (i as u64 + 1)) as usize;
            v.swap(i, j);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn noise_is_bounded_continuous_and_seeded() {
        let mut max_step: f64 = 0.0;
        for i in 0..2000 {
            let (x, y) = (i as f64 * 0.0137 - 7.0, i as f64 * 0.0291 - 3.0);
            let v = value_noise(5, x, y);
            assert!((-1.0..=1.0).contains(&v));
            max_step = max_step.max((value_noise(5, x + 1e-4, y) - v).abs() / 1e-4);
        }
        assert!(max_step <= 3.75 + 1e-3, "{max_step}");
        // Lattice points take the lattice values; different seeds differ.
        assert_ne!(value_noise(1, 0.5, 0.5), value_noise(2, 0.5, 0.5));
        assert_eq!(value_noise(1, 3.25, -2.5), value_noise(1, 3.25, -2.5));
    }

    #[test]
    fn rng_ranges_and_shuffle_are_deterministic() {
        let (mut a, mut b) = (Rng::new(9), Rng::new(9));
        for _ in 0..100 {
            let v = a.range(3.0, 25.0);
            assert!((3.0..25.0).contains(&v));
            assert_eq!(v, b.range(3.0, 25.0));
        }
        let mut v: Vec<u32> = (0..20).collect();
        Rng::new(1).shuffle(&mut v);
        let mut sorted = v.clone();
        sorted.sort();
        assert_eq!(sorted, (0..20).collect::<Vec<_>>());
        assert_ne!(v, sorted);
    }
}
