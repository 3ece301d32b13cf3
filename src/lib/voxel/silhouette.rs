//! A silhouette: which pixels of a view show the object, with a summed-area table so the number
//! of silhouette pixels in any pixel rectangle is known in constant time (what lets the carver
//! decide a whole cell at once).
//!
//! # Invariant
//! `sat[(r) · (w+1) + c]` is the number of silhouette pixels in columns `0..c`, rows `0..r`.

/// A binary mask over a `width × height` image (row-major, row 0 at the top).
#[derive(Debug, Clone, PartialEq)]
pub struct Silhouette {
    width: u32,
    height: u32,
    inside: Vec<bool>,
    sat: Vec<u32>,
}

impl Silhouette {
    /// A silhouette from one flag per pixel, row-major; panics when `inside` has the wrong
    /// length (a programming error).
    pub fn new(width: u32, height: u32, inside: Vec<bool>) -> Silhouette {
        let (w, h) = (width as usize, height as usize);
        assert_eq!(inside.len(), w * h, "silhouette size");
        let mut sat = vec![0u32; (w + 1) * (h + 1)];
        for r in 0..h {
            let mut row = 0u32;
            for c in 0..w {
                row += inside[r * w + c] as u32;
                sat[(r + 1) * (w + 1) + c + 1] = sat[r * (w + 1) + c + 1] + row;
            }
        }
        Silhouette {
            width,
            height,
            inside,
            sat,
        }
    }

    /// Image width, pixels.
    pub fn width(&self) -> u32 {
        self.width
    }

    /// Image height, pixels.
    pub fn height(&self) -> u32 {
        self.height
    }

    /// Is pixel `(col, row)` part of the object? (Both must be inside the image.)
    #[inline]
    pub fn contains(&self, col: u32, row: u32) -> bool {
        self.inside[row as usize * self.width as usize + col as usize]
    }

    /// Number of silhouette pixels in columns `c0..c1`, rows `r0..r1` (clipped to the image).
    #[inline]
    pub fn count(&self, c0: u32, r0: u32, c1: u32, r1: u32) -> u64 {
        let (c1, r1) = (c1.min(self.width) as usize, r1.min(self.height) as usize);
        let (c0, r0) = ((c0 as usize).min(c1), (r0 as usize).min(r1));
        let w = self.width as usize + 1;
        let s = &self.sat;
        (s[r1 * w + c1] as u64 + s[r0 * w + c0] as u64)
            - (s[r0 * w + c1] as u64 + s[r1 * w + c0] as u64)
    }

    /// Number of silhouette pixels.
    pub fn area(&self) -> u64 {
        self.count(0, 0, self.width, self.height)
    }

    /// Does the silhouette reach the image border (the object may extend outside the view)?
    pub fn touches_border(&self) -> bool {
        let (w, h) = (self.width, self.height);
        self.count(0, 0, w, 1)
            + self.count(0, h.saturating_sub(1), w, h)
            + self.count(0, 0, 1, h)
            + self.count(w.saturating_sub(1), 0, w, h)
            > 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn rectangle_counts_match_brute_force(w in 1u32..20, h in 1u32..20, seed in any::<u64>(), c0 in 0u32..22, r0 in 0u32..22, c1 in 0u32..22, r1 in 0u32..22) {
            let inside: Vec<bool> = (0..w * h).map(|i| (seed.rotate_left(i % 64) ^ (i as u64 * 0x9E37)) & 3 == 0).collect();
            let s = Silhouette::new(w, h, inside.clone());
            let mut n = 0;
            for r in r0..r1.min(h) {
                for c in c0..c1.min(w) {
                    n += inside[(r * w + c) as usize] as u64;
                }
            }
            prop_assert_eq!(s.count(c0, r0, c1, r1), n);
        }
    }

    #[test]
    fn border_detection() {
        let mut m = vec![false; 25];
        m[12] = true;
        assert!(!Silhouette::new(5, 5, m.clone()).touches_border());
        m[4] = true;
        assert!(Silhouette::new(5, 5, m).touches_border());
        assert_eq!(Silhouette::new(5, 5, vec![true; 25]).area(), 25);
    }
}
