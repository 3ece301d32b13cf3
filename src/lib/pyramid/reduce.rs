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

use super::sensor::SensorRows;
use crate::tiles::{STATE_EMPTY, STATE_OPAQUE, STATE_PARTIAL};
use rayon::prelude::*;

/// Read access to the cells of a band of rows of one level (row-major, `width` cells a row).
pub trait LevelRows: Sync {
    /// Cells per row.
    fn width(&self) -> usize;
    /// Number of rows held.
    fn rows(&self) -> usize;
    /// Fold cells `i .. i + n` (within one row) into `block`.
    fn fold_run(&self, i: usize, n: usize, block: &mut Block);
    /// Cells `i .. i + max_z.len()` (within one row) into `max_z` (metres, NaN = nodata),
    /// `colour` (the displayed colour: alpha 255, or `[0; 4]` when no valid cell) and `state`
    /// (`tiles::STATE_*`), all as long.
    fn copy_run(&self, i: usize, max_z: &mut [f32], colour: &mut [[u8; 4]], state: &mut [u8]);
    /// The sensor layers of these rows ([`super::sensor`]), in the tile set's order.
    fn sensor(&self) -> &[SensorRows];
}

/// What a coarse cell gathers from its children: see the module doc for the rules.
#[derive(Debug, Clone, Copy)]
pub struct Block {
    /// Max of the children's `max_z`, NaN while no child is valid.
    pub max_z: f32,
    /// Σ red, green, blue over the valid level-0 cells under the children.
    pub sum: [u64; 3],
    /// Number of those cells.
    pub count: u64,
    /// Some child is not empty.
    pub any_filled: bool,
    /// Every child is opaque.
    pub all_opaque: bool,
}

impl Block {
    /// A block with no children yet.
    pub const EMPTY: Block = Block {
        max_z: f32::NAN,
        sum: [0; 3],
        count: 0,
        any_filled: false,
        all_opaque: true,
    };

    /// One child's height and state.
    #[inline]
    pub(super) fn add(&mut self, max_z: f32, state: u8) {
        // f32::max ignores a NaN operand: NaN only when every child is NaN.
        self.max_z = self.max_z.max(max_z);
        self.any_filled |= state != STATE_EMPTY;
        self.all_opaque &= state == STATE_OPAQUE;
    }

    /// The occupancy state: empty when every child is, opaque when every child is, else partial.
    pub fn state(&self) -> u8 {
        if !self.any_filled {
            STATE_EMPTY
        } else if self.all_opaque {
            STATE_OPAQUE
        } else {
            STATE_PARTIAL
        }
    }
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
    /// The sensor layers' level-0 values (none for a visual-only tile set).
    pub sensor: Vec<SensorRows>,
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
            sensor: Vec::new(),
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
    fn fold_run(&self, i: usize, n: usize, block: &mut Block) {
        let cells = self.max_z[i..i + n].iter().zip(&self.colour[i..i + n]);
        for ((&z, &[r, g, b, a]), &st) in cells.zip(&self.state[i..i + n]) {
            block.add(z, st);
            // A level-0 cell counts when its colour is valid (alpha not 0).
            let valid = u64::from(a != 0);
            block.sum[0] += valid * r as u64;
            block.sum[1] += valid * g as u64;
            block.sum[2] += valid * b as u64;
            block.count += valid;
        }
    }
    fn copy_run(&self, i: usize, max_z: &mut [f32], colour: &mut [[u8; 4]], state: &mut [u8]) {
        let n = max_z.len();
        max_z.copy_from_slice(&self.max_z[i..i + n]);
        colour.copy_from_slice(&self.colour[i..i + n]);
        state.copy_from_slice(&self.state[i..i + n]);
    }
    fn sensor(&self) -> &[SensorRows] {
        &self.sensor
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
    /// The sensor layers' exact reductions ([`super::sensor`]).
    pub sensor: Vec<SensorRows>,
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
        if self.sensor.is_empty() {
            self.sensor = other.sensor;
        } else {
            for (s, o) in self.sensor.iter_mut().zip(other.sensor) {
                s.append(o);
            }
        }
    }

    /// Displayed colour of cell `i`: the rounded average, alpha 255; `[0; 4]` when no valid cell.
    #[inline]
    pub fn colour(&self, i: usize) -> [u8; 4] {
        average(self.sum[i], self.count[i])
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
    fn fold_run(&self, i: usize, n: usize, block: &mut Block) {
        let cells = self.max_z[i..i + n].iter().zip(&self.sum[i..i + n]);
        for ((&z, s), (&count, &st)) in
            cells.zip(self.count[i..i + n].iter().zip(&self.state[i..i + n]))
        {
            block.add(z, st);
            block.sum = [
                block.sum[0] + s[0],
                block.sum[1] + s[1],
                block.sum[2] + s[2],
            ];
            block.count += count;
        }
    }
    fn copy_run(&self, i: usize, max_z: &mut [f32], colour: &mut [[u8; 4]], state: &mut [u8]) {
        let n = max_z.len();
        max_z.copy_from_slice(&self.max_z[i..i + n]);
        state.copy_from_slice(&self.state[i..i + n]);
        for (k, c) in colour.iter_mut().enumerate() {
            *c = self.colour(i + k);
        }
    }
    fn sensor(&self) -> &[SensorRows] {
        &self.sensor
    }
}

/// The rounded average colour of a coarse cell (the tile format's rule, [`crate::tiles::average_colour`]).
pub use crate::tiles::average_colour as average;

/// Reduce the rows `fine` by `factor` in both directions: coarse row `r` is made of fine rows
/// `r·f .. r·f + f` (fewer at the bottom), coarse column `c` of fine columns `c·f .. c·f + f`
/// (fewer at the right edge). Output width `ceil(width / f)`, rows `ceil(rows / f)`. Parallel
/// over coarse rows; each coarse row gathers its fine rows one after another, a run of `f`
/// cells per coarse cell.
pub fn reduce<R: LevelRows>(fine: &R, factor: usize) -> CoarseRows {
    let (w, h) = (fine.width(), fine.rows());
    let (cw, ch) = (w.div_ceil(factor), h.div_ceil(factor));
    let mut out = CoarseRows {
        width: cw,
        max_z: vec![f32::NAN; cw * ch],
        sum: vec![[0; 3]; cw * ch],
        count: vec![0; cw * ch],
        state: vec![STATE_EMPTY; cw * ch],
        sensor: fine.sensor().iter().map(|s| s.reduce(w, factor)).collect(),
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
        .for_each_init(Vec::new, |blocks, (r, (((zs, sums), counts), states))| {
            blocks.clear();
            blocks.resize(cw, Block::EMPTY);
            for fr in (r * factor)..((r + 1) * factor).min(h) {
                for (c, block) in blocks.iter_mut().enumerate() {
                    let c0 = c * factor;
                    fine.fold_run(fr * w + c0, factor.min(w - c0), block);
                }
            }
            for (c, block) in blocks.iter().enumerate() {
                zs[c] = block.max_z;
                sums[c] = block.sum;
                counts[c] = block.count;
                states[c] = block.state();
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
            sensor: Vec::new(),
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
            sensor: Vec::new(),
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
