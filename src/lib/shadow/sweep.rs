//! The O(n) shadow sweep, fed one grid row at a time, so a mask can be cast over a grid streamed
//! from disk in O(width + height) memory.
//!
//! # The digital lines
//! Think of the grid flipped and/or transposed into a *frame* whose row 0 lies toward the sun
//! and in which, moving one frame row away from the sun, a ray moves `drift ∈ [0, 1]` frame
//! columns (the minor axis over the major axis). Line `l` holds, in frame row `i`, the cell of
//! frame column `l + offset(i) − offset(last row)`, with `offset(i) = round(i · drift)`: every
//! frame cell lies on exactly one line, and every line is a translate of the same pattern. For
//! azimuths along the grid axes and the diagonals of square cells the line *is* the ray.
//!
//! Walking a line away from the sun the sweep carries the shadow horizon of the line's next cell,
//! `H = max over cells k steps back toward the sun (z_k − k · rise)`, `rise` being the ray's rise
//! in metres per frame row; a valid cell is shadowed when `z < H`.
//!
//! # The invariant that makes streaming possible
//! Each line's cells are visited in order away from the sun, so the state of the whole sweep is
//! one horizon per line. [`RowSweep::next_row`] hands out grid rows in an order that keeps this
//! true: when frame rows are grid rows (the sun nearer north or south), the rows from the sun's
//! side; when frame rows are grid columns (nearer east or west), the rows in the direction lines
//! drift, each walked from the sun's side. Either way the result is the same mask, bit for bit,
//! whatever the order of arithmetic across lines.

use super::{Sun, LIT, NODATA, SHADOW};
use crate::error::Result;
use crate::grid::Grid;
use rayon::prelude::*;

/// Cells per parallel chunk of a row across the lines (about 1 ns a cell: narrower chunks cost
/// more in scheduling than they save).
const CHUNK: usize = 16 * 1024;

/// A shadow sweep over a `width × height` grid for one sun, fed rows in [`next_row`](Self::next_row)
/// order. Holds one `f64` horizon per digital line and one offset per frame row:
/// `16 · (width + height)` bytes at most.
pub struct RowSweep {
    width: usize,
    height: usize,
    /// Frame rows are grid columns (the sun nearer east or west).
    transposed: bool,
    /// Frame row index runs against the grid's (rows, or columns when transposed).
    flip_row: bool,
    /// Frame column index runs against the grid's.
    flip_col: bool,
    /// `offset(i)` of every frame row `i` (see [`offset`]), so the sweep needs no rounding per cell.
    offsets: Vec<usize>,
    /// `offset(frame height − 1)`.
    max_offset: usize,
    /// Frame columns a line moves per frame row, [0, 1].
    drift: f64,
    /// Rise of the ray toward the sun per frame row, metres.
    rise: f64,
    /// The sun at the zenith: no column can block a vertical ray.
    overhead: bool,
    /// Shadow horizon of the next cell of each line, metres.
    horizon: Vec<f64>,
    /// Rows pushed so far.
    pushed: usize,
    /// Cells per parallel chunk of a row across the lines: [`CHUNK`], smaller in tests.
    chunk: usize,
}

impl RowSweep {
    /// A sweep for `sun` over `grid` (only its size, cell size and CRS are used). Errors when
    /// the cells are not positive sizes in metres (a geographic grid).
    pub fn new(grid: &Grid, sun: &Sun) -> Result<RowSweep> {
        super::check_cells(grid)?;
        let (width, height) = (grid.width, grid.height);
        let overhead = sun.elevation_deg >= 90.0;
        let (east, north) = sun.direction();
        // Grid cells per metre toward the sun.
        let dc = east / grid.transform.cell_x;
        let dr = north / grid.transform.cell_y;
        let transposed = dc.abs() > dr.abs();
        let (major, minor) = if transposed { (dc, dr) } else { (dr, dc) };
        let mut drift = if overhead { 0.0 } else { (minor / major).abs() };
        if drift > 1.0 - 1e-12 {
            drift = 1.0; // the diagonal of square cells, exactly
        }
        let (frame_w, frame_h) = if transposed {
            (height, width)
        } else {
            (width, height)
        };
        let offsets: Vec<usize> = (0..frame_h).map(|i| offset(i, drift)).collect();
        let max_offset = offsets.last().copied().unwrap_or(0);
        let step_m = 1.0 / major.abs();
        Ok(RowSweep {
            width,
            height,
            transposed,
            flip_row: major > 0.0,
            flip_col: minor > 0.0,
            offsets,
            max_offset,
            drift,
            rise: step_m * sun.elevation_deg.to_radians().tan(),
            overhead,
            horizon: if overhead {
                Vec::new()
            } else {
                vec![f64::NEG_INFINITY; frame_w + max_offset]
            },
            pushed: 0,
            chunk: CHUNK,
        })
    }

    /// The grid row to [`push`](Self::push) next; `None` once every row has been pushed.
    pub fn next_row(&self) -> Option<usize> {
        let k = self.pushed;
        if k >= self.height {
            return None;
        }
        // Non-transposed: frame row k; transposed: frame column k.
        let flip = if self.transposed {
            self.flip_col
        } else {
            self.flip_row
        };
        Some(if flip { self.height - 1 - k } else { k })
    }

    /// Sweep the row [`next_row`](Self::next_row) named: `heights` are its `width` heights
    /// (metres, NaN = nodata); `mask` receives [`SHADOW`], [`LIT`] or [`NODATA`] for each.
    ///
    /// # Panics
    /// When every row has been pushed already, or on slices not `width` long.
    pub fn push(&mut self, heights: &[f32], mask: &mut [u8]) {
        self.push_with(heights, mask, step);
    }

    /// Like [`push`](Self::push), but each cell receives its shadow horizon instead of a mask
    /// value: the height in metres the ray from its centre must clear,
    /// `max over the cells k steps ahead on its line (z_k − k · rise)`, `−inf` when nothing
    /// ahead is valid (and at the zenith). A valid cell is shadowed exactly when its height is
    /// below it. Same panics.
    pub(crate) fn push_horizons(&mut self, heights: &[f32], horizons: &mut [f64]) {
        self.push_with(heights, horizons, |h, z, rise| {
            let before = *h;
            step(h, z, rise);
            before
        });
    }

    /// Pass over the next `n` rows without sweeping them: the lines they hold start on the
    /// rows after with an empty horizon, as if those `n` rows were nodata and far below.
    ///
    /// # Panics
    /// When fewer than `n` rows are left.
    pub fn skip(&mut self, n: usize) {
        assert!(
            self.pushed + n <= self.height,
            "RowSweep: skipping past the last row"
        );
        self.pushed += n;
    }

    /// How many grid rows, in the order rows are pushed, a chain `z − k · rise` falling by
    /// `drop` metres can span: rows farther toward the sun than this cannot lift a horizon
    /// by `drop` over the cells it reaches. `usize::MAX` for an infinite drop; 0 at the zenith.
    pub fn rows_upstream(&self, drop: f64) -> usize {
        if self.overhead || drop <= 0.0 {
            return 0;
        }
        if !drop.is_finite() {
            return usize::MAX;
        }
        // Steps along a line (frame rows) before the chain has fallen by `drop`.
        let steps = (drop / self.rise).ceil() + 1.0;
        if steps >= self.height.max(self.width) as f64 {
            return usize::MAX;
        }
        let steps = steps as usize;
        match self.transposed {
            // One frame row a step: one grid row.
            false => steps,
            // A step is a grid column; between two frame rows `steps` apart a line moves at
            // most offset(steps) + 1 frame columns (grid rows).
            true => offset(steps, self.drift) + 1,
        }
    }

    /// Rise of the ray toward the sun per frame row, metres (0 at the zenith): where a cell
    /// sits along its row moves its distance to another row by at most half of this.
    pub(crate) fn rise(&self) -> f64 {
        if self.overhead {
            0.0
        } else {
            self.rise
        }
    }

    /// Frame rows are grid columns: the lines run nearer east–west, so they drift across rows.
    pub(crate) fn transposed(&self) -> bool {
        self.transposed
    }

    /// The walk behind [`push`](Self::push): `cell(horizon, z, rise)` gives a cell's output and
    /// moves its line's horizon on to the next cell.
    fn push_with<T: Send>(
        &mut self,
        heights: &[f32],
        out: &mut [T],
        cell: impl Fn(&mut f64, f32, f64) -> T + Sync,
    ) {
        assert!(
            self.pushed < self.height,
            "RowSweep: every row was pushed already"
        );
        assert!(
            heights.len() == self.width && out.len() == self.width,
            "RowSweep: row length"
        );
        let k = self.pushed;
        self.pushed += 1;
        if self.overhead {
            // Nothing can block a vertical ray: every cell starts its own empty horizon.
            for (o, z) in out.iter_mut().zip(heights) {
                let mut empty = f64::NEG_INFINITY;
                *o = cell(&mut empty, *z, 0.0);
            }
            return;
        }
        let rise = self.rise;
        if !self.transposed {
            // Frame row k: frame column j is on line j + base, one cell per line, so the row
            // splits into independent chunks.
            let base = self.max_offset - self.offsets[k];
            let lines = &mut self.horizon[base..base + self.width];
            let chunk = self.chunk;
            if self.flip_col {
                lines
                    .par_chunks_mut(chunk)
                    .zip(heights.par_rchunks(chunk).zip(out.par_rchunks_mut(chunk)))
                    .for_each(|(h, (z, o))| {
                        for ((h, z), o) in h.iter_mut().zip(z.iter().rev()).zip(o.iter_mut().rev())
                        {
                            *o = cell(h, *z, rise);
                        }
                    });
            } else {
                lines
                    .par_chunks_mut(chunk)
                    .zip(heights.par_chunks(chunk).zip(out.par_chunks_mut(chunk)))
                    .for_each(|(h, (z, o))| {
                        for ((h, z), o) in h.iter_mut().zip(z).zip(o.iter_mut()) {
                            *o = cell(h, *z, rise);
                        }
                    });
            }
        } else {
            // Frame column k: frame row i (grid column, walked from the sun's side) is on line
            // k + max_offset − offsets[i]. A line's cells here are consecutive, so the row is
            // walked in order: about 3 ns a cell. (Cutting it into parallel chunks at line
            // starts measured slower, the scheduling outweighing a row's work, on 2 busy cores.)
            let base = k + self.max_offset;
            for (i, &o) in self.offsets.iter().enumerate() {
                let c = if self.flip_row { self.width - 1 - i } else { i };
                out[c] = cell(&mut self.horizon[base - o], heights[c], rise);
            }
        }
    }
}

/// One cell of a line: its mask value against horizon `h`, and `h` moved on to the next cell.
#[inline]
fn step(h: &mut f64, z: f32, rise: f64) -> u8 {
    if z.is_nan() {
        *h -= rise;
        NODATA
    } else {
        let z = z as f64;
        let m = if z < *h { SHADOW } else { LIT };
        *h = z.max(*h) - rise;
        m
    }
}

/// Column offset of a line in frame row `i`: the minor-axis drift rounded to the nearest cell.
#[inline]
fn offset(i: usize, drift: f64) -> usize {
    (i as f64 * drift).round() as usize
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::crs::Crs;
    use proptest::prelude::*;

    fn sweep_all(heights: &[f32], grid: &Grid, sun: &Sun, chunk: usize) -> Vec<u8> {
        let w = grid.width;
        let mut sweep = RowSweep::new(grid, sun).unwrap();
        sweep.chunk = chunk;
        let mut mask = vec![0; heights.len()];
        while let Some(r) = sweep.next_row() {
            sweep.push(&heights[r * w..(r + 1) * w], &mut mask[r * w..(r + 1) * w]);
        }
        mask
    }

    proptest! {
        /// Cutting a row across the lines into parallel chunks never changes the mask.
        #[test]
        fn chunked_rows_give_the_same_mask(
            w in 1usize..60, h in 1usize..60, chunk in 1usize..9, az in 0.0f64..360.0,
            el in 1.0f64..60.0, cell_x in 0.3f64..3.0, seed in any::<u64>(),
        ) {
            let mut g = Grid::north_up(500_000.0, 5_300_000.0, cell_x, w, h, Crs::epsg(32632));
            g.transform.cell_y = -1.0;
            let mut x = seed | 1;
            let heights: Vec<f32> = (0..w * h).map(|_| {
                x ^= x << 13; x ^= x >> 7; x ^= x << 17;
                if x % 50 == 0 { f32::NAN } else { (x % 1000) as f32 / 100.0 }
            }).collect();
            let sun = Sun::new(el, az).unwrap();
            prop_assert_eq!(sweep_all(&heights, &g, &sun, chunk), sweep_all(&heights, &g, &sun, usize::MAX / 2));
        }
    }
}
