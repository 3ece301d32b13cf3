//! A cast-shadow mask held as one bit a cell, cast from terrain streamed band by band.

use super::{RowSweep, Sun, SHADOW};
use crate::error::Result;
use crate::raster::{band_rows, RowSource};

/// A cast-shadow mask, one bit per cell, row-major: set = in cast shadow (nodata cells are
/// never set). `W · H / 8` bytes: the only whole-grid state of a streamed cast.
pub struct ShadowBits {
    bits: Vec<u64>,
}

impl ShadowBits {
    /// Cast `sun` over `terrain`, each row's heights first passed to `overlay(start, heights)`
    /// (`start`: the row's first cell index) to lay raised surfaces over it (`|_, _| ()` for
    /// the bare terrain). The sweep takes rows in the sun's order, so the terrain is read in
    /// bands of [`band_rows`] in that order (down the grid or up it).
    pub fn cast(
        terrain: &dyn RowSource<f32>,
        sun: &Sun,
        overlay: impl Fn(usize, &mut [f32]),
    ) -> Result<ShadowBits> {
        let g = terrain.grid();
        let (w, h) = (g.width, g.height);
        let mut bits = vec![0u64; (w * h).div_ceil(64)];
        let mut sweep = RowSweep::new(g, sun)?;
        let upward = h > 1 && sweep.next_row() == Some(h - 1);
        let per_band = band_rows(w);
        let (mut heights, mut mask) = (vec![0f32; w], vec![0u8; w]);
        let mut band: (usize, Vec<f32>) = (0, Vec::new());
        while let Some(r) = sweep.next_row() {
            let (b0, data) = &band;
            if !(r >= *b0 && (r - b0) * w < data.len()) {
                let b0 = if upward {
                    (r + 1).saturating_sub(per_band)
                } else {
                    r
                };
                let n = if upward {
                    r + 1 - b0
                } else {
                    per_band.min(h - r)
                };
                band = (b0, terrain.read_rows(b0, n)?.into_owned());
            }
            let (b0, data) = &band;
            let start = r * w;
            heights.copy_from_slice(&data[(r - b0) * w..(r - b0 + 1) * w]);
            overlay(start, &mut heights);
            sweep.push(&heights, &mut mask);
            for (k, _) in mask.iter().enumerate().filter(|(_, &m)| m == SHADOW) {
                let i = start + k;
                bits[i / 64] |= 1 << (i % 64);
            }
        }
        Ok(ShadowBits { bits })
    }

    /// A mask from its bits (`bits[i / 64] >> (i % 64) & 1` for cell `i`).
    pub fn from_bits(bits: Vec<u64>) -> ShadowBits {
        ShadowBits { bits }
    }

    /// Whether cell `i` (row-major index) is in cast shadow.
    pub fn get(&self, i: usize) -> bool {
        self.bits[i / 64] >> (i % 64) & 1 == 1
    }

    /// Cells in cast shadow.
    pub fn count(&self) -> usize {
        self.bits.iter().map(|b| b.count_ones() as usize).sum()
    }
}
