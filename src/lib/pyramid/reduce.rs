//! One step of the hierarchy: rows of a level → rows of the next coarser level.
//!
//! Invariant (what makes every coarse level exact, not an average of averages): a coarse cell
//! holds the max of its children's `max_z` (NaN children ignored, NaN when all are NaN), the
//! sums of the red, green and blue of the **valid level-0 cells** under it and their count, and
//! the state rule (empty when every child is empty, opaque when every child is opaque, partial
//! otherwise). Max and sums are associative, so the cascade level 0 → 1 → 2 … gives, at every
//! level, exactly the max and the sums over the cell's whole level-0 block; the displayed colour
//! is the sum divided by the count, rounded to nearest (halves up), computed once from the
//! integers — rounding never compounds across levels. Blocks at the right and bottom edges have
//! fewer children (`ceil(W / f)` coarse cells), and only the children that exist count.

use crate::tiles::{STATE_EMPTY, STATE_OPAQUE, STATE_PARTIAL};
use rayon::prelude::*;

/// Read access to the cells of a band of rows of one level (row-major, `width` cells a row).
pub trait LevelRows: Sync {
    /// Cells per row.
    fn width(&self) -> usize;
    /// Number of rows held.
    fn rows(&self) -> usize;
    /// Maximum height of cell `i`, metres; NaN = nodata.
    fn max_z(&self, i: usize) -> f32;
    /// Sums of red, green, blue over the valid level-0 cells under cell `i`, and their count.
    fn colour_sum(&self, i: usize) -> ([u64; 3], u64);
    /// Displayed colour of cell `i`: the rounded average, alpha 255; alpha 0 when no valid cell.
    fn colour(&self, i: usize) -> [u8; 4];
    /// Occupancy state of cell `i` (`tiles::STATE_*`).
    fn state(&self, i: usize) -> u8;
}

/// Level-0 rows: the database cells themselves (after merging objects and applying effects).
#[derive(Debug, Clone, PartialEq)]
pub struct BaseRows {
    /// Cells per row.
    pub width: usize,
    /// Top of each column, metres; NaN = nodata.
    pub max_z: Vec<f32>,
    /// Colour of each cell's top surface; alpha 0 = nodata, else 255.
    pub colour: Vec<[u8; 4]>,
    /// Occupancy state of each cell.
    pub state: Vec<u8>,
}

impl BaseRows {
    /// `rows` rows of `width` nodata cells.
    pub fn nodata(width: usize, rows: usize) -> BaseRows {
        let n = width * rows;
        BaseRows {
            width,
            max_z: vec![f32::NAN; n],
            colour: vec![[0; 4]; n],
            state: vec![STATE_EMPTY; n],
        }
    }
}

impl LevelRows for BaseRows {
    fn width(&self) -> usize {
        self.width
    }
    fn rows(&self) -> usize {
        self.max_z.len() / self.width.max(1)
    }
    #[inline]
    fn max_z(&self, i: usize) -> f32 {
        self.max_z[i]
    }
    #[inline]
    fn colour_sum(&self, i: usize) -> ([u64; 3], u64) {
        let [r, g, b, a] = self.colour[i];
        if a == 0 {
            ([0; 3], 0)
        } else {
            ([r as u64, g as u64, b as u64], 1)
        }
    }
    #[inline]
    fn colour(&self, i: usize) -> [u8; 4] {
        self.colour[i]
    }
    #[inline]
    fn state(&self, i: usize) -> u8 {
        self.state[i]
    }
}

/// Rows of a coarse level: exact maxima, integer colour sums and counts, states.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct CoarseRows {
    /// Cells per row.
    pub width: usize,
    /// Exact max of the level-0 block's heights, metres; NaN when the block has no valid cell.
    pub max_z: Vec<f32>,
    /// Σ red, green, blue over the block's valid level-0 cells (u64: no overflow at any level).
    pub sum: Vec<[u64; 3]>,
    /// Number of valid level-0 cells in the block.
    pub count: Vec<u64>,
    /// Occupancy state.
    pub state: Vec<u8>,
}

impl CoarseRows {
    /// An empty band of `width`-cell rows.
    pub fn new(width: usize) -> CoarseRows {
        CoarseRows {
            width,
            ..CoarseRows::default()
        }
    }

    /// Append the rows of `other` (same width) below these.
    pub fn append(&mut self, other: CoarseRows) {
        debug_assert_eq!(self.width, other.width);
        self.max_z.extend(other.max_z);
        self.sum.extend(other.sum);
        self.count.extend(other.count);
        self.state.extend(other.state);
    }

    /// Drop the first `rows` rows.
    pub fn drain_rows(&mut self, rows: usize) {
        let n = rows * self.width;
        self.max_z.drain(..n);
        self.sum.drain(..n);
        self.count.drain(..n);
        self.state.drain(..n);
    }
}

impl LevelRows for CoarseRows {
    fn width(&self) -> usize {
        self.width
    }
    fn rows(&self) -> usize {
        self.max_z.len() / self.width.max(1)
    }
    #[inline]
    fn max_z(&self, i: usize) -> f32 {
        self.max_z[i]
    }
    #[inline]
    fn colour_sum(&self, i: usize) -> ([u64; 3], u64) {
        (self.sum[i], self.count[i])
    }
    #[inline]
    fn colour(&self, i: usize) -> [u8; 4] {
        average(self.sum[i], self.count[i])
    }
    #[inline]
    fn state(&self, i: usize) -> u8 {
        self.state[i]
    }
}

/// The rounded average colour `sum / count` (halves round up), alpha 255; nodata when `count == 0`.
#[inline]
pub fn average(sum: [u64; 3], count: u64) -> [u8; 4] {
    if count == 0 {
        return [0; 4];
    }
    let ch = |s: u64| ((2 * s + count) / (2 * count)) as u8;
    [ch(sum[0]), ch(sum[1]), ch(sum[2]), 255]
}

/// Reduce the rows `fine` by `factor` in both directions: coarse row `r` is made of fine rows
/// `r·f .. r·f + f` (fewer at the bottom), coarse column `c` of fine columns `c·f .. c·f + f`
/// (fewer at the right edge). Output width `ceil(width / f)`, rows `ceil(rows / f)`. Parallel
/// over coarse rows.
pub fn reduce<R: LevelRows>(fine: &R, factor: usize) -> CoarseRows {
    let (w, h) = (fine.width(), fine.rows());
    let (cw, ch) = (w.div_ceil(factor), h.div_ceil(factor));
    let mut out = CoarseRows {
        width: cw,
        max_z: vec![f32::NAN; cw * ch],
        sum: vec![[0; 3]; cw * ch],
        count: vec![0; cw * ch],
        state: vec![STATE_EMPTY; cw * ch],
    };
    if cw == 0 {
        return out;
    }
    out.max_z
        .par_chunks_mut(cw)
        .zip(out.sum.par_chunks_mut(cw))
        .zip(out.count.par_chunks_mut(cw))
        .zip(out.state.par_chunks_mut(cw))
        .enumerate()
        .for_each(|(r, (((zs, sums), counts), states))| {
            let rows = (r * factor)..((r + 1) * factor).min(h);
            for c in 0..cw {
                let cols = (c * factor)..((c + 1) * factor).min(w);
                let (mut z, mut sum, mut count) = (f32::NAN, [0u64; 3], 0u64);
                let (mut any_filled, mut all_opaque) = (false, true);
                for fr in rows.clone() {
                    for i in cols.clone().map(|fc| fr * w + fc) {
                        // f32::max ignores a NaN operand: NaN only when every child is NaN.
                        z = z.max(fine.max_z(i));
                        let (s, n) = fine.colour_sum(i);
                        sum = [sum[0] + s[0], sum[1] + s[1], sum[2] + s[2]];
                        count += n;
                        let st = fine.state(i);
                        any_filled |= st != STATE_EMPTY;
                        all_opaque &= st == STATE_OPAQUE;
                    }
                }
                zs[c] = z;
                sums[c] = sum;
                counts[c] = count;
                states[c] = if !any_filled {
                    STATE_EMPTY
                } else if all_opaque {
                    STATE_OPAQUE
                } else {
                    STATE_PARTIAL
                };
            }
        });
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn base(width: usize, z: &[f32], colour: &[[u8; 4]], state: &[u8]) -> BaseRows {
        BaseRows {
            width,
            max_z: z.to_vec(),
            colour: colour.to_vec(),
            state: state.to_vec(),
        }
    }

    #[test]
    fn max_ignores_nodata_and_all_nodata_stays_nodata() {
        let n = f32::NAN;
        let c = [10, 20, 30, 255];
        let x = [0, 0, 0, 0];
        // 3×2 fine cells, factor 2: coarse cells cover columns {0,1} and {2}.
        let b = base(
            3,
            &[n, 5.0, n, -1.0, n, n],
            &[x, c, x, c, x, x],
            &[0, 2, 0, 2, 0, 0],
        );
        let r = reduce(&b, 2);
        assert_eq!((r.width, r.rows()), (2, 1));
        assert_eq!(r.max_z[0], 5.0);
        assert!(r.max_z[1].is_nan());
        assert_eq!(r.state, vec![STATE_PARTIAL, STATE_EMPTY]);
        assert_eq!((r.sum[0], r.count[0]), ([20, 40, 60], 2));
        assert_eq!(r.colour(1), [0; 4]);
    }

    #[test]
    fn state_is_opaque_only_when_every_child_is() {
        let c = [1, 1, 1, 255];
        let b = base(2, &[1.0; 4], &[c; 4], &[2, 2, 2, 2]);
        assert_eq!(reduce(&b, 2).state, vec![STATE_OPAQUE]);
        let b = base(2, &[1.0; 4], &[c; 4], &[2, 1, 2, 2]);
        assert_eq!(reduce(&b, 2).state, vec![STATE_PARTIAL]);
        let b = base(2, &[f32::NAN; 4], &[[0; 4]; 4], &[0; 4]);
        assert_eq!(reduce(&b, 2).state, vec![STATE_EMPTY]);
    }

    #[test]
    fn average_rounds_half_up_and_is_weighted_by_valid_level0_cells() {
        assert_eq!(average([1, 2, 3], 2), [1, 1, 2, 255]); // 0.5 → 1, 1.0 → 1, 1.5 → 2
        assert_eq!(average([0; 3], 0), [0; 4]);
        // Level 2 from level 1: a child covering 3 valid cells weighs 3 times one covering 1.
        let fine = CoarseRows {
            width: 2,
            max_z: vec![1.0, 2.0],
            sum: vec![[300, 0, 0], [0, 0, 0]],
            count: vec![3, 1],
            state: vec![2, 2],
        };
        let r = reduce(&fine, 4);
        assert_eq!(r.colour(0), [75, 0, 0, 255]);
        assert_eq!(r.max_z, vec![2.0]);
    }

    #[test]
    fn edge_blocks_use_only_existing_children() {
        // 5×5 with factor 4: coarse 2×2; the corner block is the single cell (4, 4).
        let z: Vec<f32> = (0..25).map(|i| i as f32).collect();
        let b = base(5, &z, &[[2, 4, 6, 255]; 25], &[2; 25]);
        let r = reduce(&b, 4);
        assert_eq!(r.max_z, vec![18.0, 19.0, 23.0, 24.0]);
        assert_eq!(r.count, vec![16, 4, 4, 1]);
        assert_eq!(r.state, vec![STATE_OPAQUE; 4]);
    }
}
