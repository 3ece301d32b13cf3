//! Rasters: a [`Grid`] plus one value per cell, row-major.
//!
//! The two typed layers of a database:
//! * [`Elevation`]: `f32` metres above the vertical datum; **NaN is nodata** (declared nodata
//!   values are turned into NaN on read and back into the file's nodata value on write).
//! * [`Colour`]: `[r, g, b, a]` 8-bit; **alpha 0 is nodata**, alpha 255 is valid (no partial
//!   alpha is produced by dbms).

use crate::error::Result;
use crate::grid::Grid;
use std::borrow::Cow;

/// A grid of values, one per cell, row-major (`data[row * width + col]`).
#[derive(Debug, Clone, PartialEq)]
pub struct Raster<T> {
    /// Geometry of the data.
    pub grid: Grid,
    /// One value per cell; `data.len() == grid.len()`.
    pub data: Vec<T>,
}

/// Elevation in metres; NaN = nodata.
pub type Elevation = Raster<f32>;

/// 8-bit RGBA colour; alpha 0 = nodata.
pub type Colour = Raster<[u8; 4]>;

/// The colour value of a nodata cell.
pub const NODATA_COLOUR: [u8; 4] = [0, 0, 0, 0];

impl<T: Clone> Raster<T> {
    /// A raster with every cell set to `value`.
    pub fn filled(grid: Grid, value: T) -> Raster<T> {
        let n = grid.len();
        Raster {
            grid,
            data: vec![value; n],
        }
    }
}

impl<T> Raster<T> {
    /// Wrap `data` (row-major, `grid.len()` values) on `grid`. Panics on a length mismatch,
    /// which is a programming error, never a user one.
    pub fn new(grid: Grid, data: Vec<T>) -> Raster<T> {
        assert_eq!(
            data.len(),
            grid.len(),
            "raster data does not match its grid"
        );
        Raster { grid, data }
    }

    /// The value of cell `(col, row)`.
    #[inline]
    pub fn get(&self, col: usize, row: usize) -> &T {
        &self.data[row * self.grid.width + col]
    }

    /// Mutable access to cell `(col, row)`.
    #[inline]
    pub fn get_mut(&mut self, col: usize, row: usize) -> &mut T {
        let w = self.grid.width;
        &mut self.data[row * w + col]
    }

    /// Width in cells.
    pub fn width(&self) -> usize {
        self.grid.width
    }

    /// Height in cells.
    pub fn height(&self) -> usize {
        self.grid.height
    }

    /// Rows as slices, top (row 0) first.
    pub fn rows(&self) -> std::slice::ChunksExact<'_, T> {
        self.data.chunks_exact(self.grid.width.max(1))
    }
}

/// Cells in a band of a layer read at once by the stages that stream one ([`band_rows`]).
const STREAMED_BAND_CELLS: usize = 1 << 22;

/// Rows in a band of about 4 M cells of a grid `width` cells wide (at least 1): how many rows
/// the stages that stream a layer read at a time.
pub fn band_rows(width: usize) -> usize {
    rows_in(STREAMED_BAND_CELLS, width)
}

/// Whole rows of a grid `width` cells wide in `cells` cells (at least 1): the rows of a band
/// with that budget.
pub fn rows_in(cells: usize, width: usize) -> usize {
    (cells / width.max(1)).max(1)
}

/// Rows of a layer on demand: a raster held in memory, or a file decoded band by band, so a
/// stage can stream a grid larger than memory. Shared between threads.
pub trait RowSource<T: Clone>: Sync {
    /// The grid the rows lie on.
    fn grid(&self) -> &Grid;

    /// Rows `row0 .. row0 + rows`, row-major (`rows × width` values). Panics when the rows are
    /// not inside the grid (a programming error); errors when they cannot be read.
    fn read_rows(&self, row0: usize, rows: usize) -> Result<Cow<'_, [T]>>;
}

impl<T: Clone + Sync> RowSource<T> for Raster<T> {
    fn grid(&self) -> &Grid {
        &self.grid
    }

    fn read_rows(&self, row0: usize, rows: usize) -> Result<Cow<'_, [T]>> {
        assert!(
            row0 + rows <= self.grid.height,
            "rows {row0}..{} outside the grid",
            row0 + rows
        );
        let w = self.grid.width;
        Ok(Cow::Borrowed(&self.data[row0 * w..(row0 + rows) * w]))
    }
}

/// Rows `rows` of a raster on `grid`, held in memory while a band-by-band stage works on
/// them, addressed by the *whole* grid's cell index and column/row (so code written for the
/// whole raster reads a band unchanged, with the same coordinates to the last bit).
///
/// Invariant: `data` holds exactly the rows `rows` (`rows.len() × grid.width` values); reading
/// a cell outside them panics (a programming error: the band was planned too small).
pub struct RowBand<'a, T: Clone> {
    /// The whole grid the band is part of.
    pub grid: &'a Grid,
    rows: std::ops::Range<usize>,
    data: Cow<'a, [T]>,
}

impl<'a, T: Clone> RowBand<'a, T> {
    /// Rows `rows` of `src` (borrowed when it is held in memory).
    pub fn read(src: &'a dyn RowSource<T>, rows: std::ops::Range<usize>) -> Result<Self> {
        let data = src.read_rows(rows.start, rows.len())?;
        Ok(RowBand {
            grid: src.grid(),
            rows,
            data,
        })
    }

    /// Rows `rows` of `grid` from their values, row-major.
    pub fn new(grid: &'a Grid, rows: std::ops::Range<usize>, data: Vec<T>) -> Self {
        assert_eq!(data.len(), rows.len() * grid.width, "one value per cell");
        RowBand {
            grid,
            rows,
            data: Cow::Owned(data),
        }
    }

    /// All of `raster`, borrowed.
    pub fn whole(raster: &'a Raster<T>) -> Self {
        RowBand {
            grid: &raster.grid,
            rows: 0..raster.grid.height,
            data: Cow::Borrowed(&raster.data),
        }
    }

    /// The grid rows held.
    pub fn rows(&self) -> std::ops::Range<usize> {
        self.rows.clone()
    }

    /// The value of cell `i` (row-major index in the whole grid).
    pub fn at(&self, i: usize) -> &T {
        &self.data[i - self.rows.start * self.grid.width]
    }

    /// The `len` values from cell `i` on (row-major index in the whole grid).
    pub fn span(&self, i: usize, len: usize) -> &[T] {
        let at = i - self.rows.start * self.grid.width;
        &self.data[at..at + len]
    }

    /// The value at column `col`, row `row` of the whole grid.
    pub fn get(&self, col: usize, row: usize) -> &T {
        self.at(row * self.grid.width + col)
    }

    /// Whether grid row `row` is held.
    pub fn holds_row(&self, row: usize) -> bool {
        self.rows.contains(&row)
    }

    /// The values held, row-major from the first row held.
    pub fn values(&self) -> &[T] {
        &self.data
    }
}

/// A row source that keeps rows of another in memory: a read within them is a slice of what
/// was read once, any other goes to the source. For a stage that reads the same rows several
/// times (casts, walls, level 0 of an incremental pyramid).
pub struct CachedRows<'a, T: Clone> {
    band: RowBand<'a, T>,
    src: &'a dyn RowSource<T>,
}

impl<'a, T: Clone> CachedRows<'a, T> {
    /// `src` with its rows `rows` read now and kept.
    pub fn new(src: &'a dyn RowSource<T>, rows: std::ops::Range<usize>) -> Result<Self> {
        Ok(CachedRows {
            band: RowBand::read(src, rows)?,
            src,
        })
    }
}

impl<T: Clone + Sync> RowSource<T> for CachedRows<'_, T> {
    fn grid(&self) -> &Grid {
        self.src.grid()
    }

    fn read_rows(&self, row0: usize, rows: usize) -> Result<Cow<'_, [T]>> {
        let kept = self.band.rows();
        if kept.start <= row0 && row0 + rows <= kept.end {
            let w = self.src.grid().width;
            return Ok(Cow::Borrowed(self.band.span(row0 * w, rows * w)));
        }
        self.src.read_rows(row0, rows)
    }
}

impl Elevation {
    /// Number of nodata (NaN) cells.
    pub fn nodata_count(&self) -> usize {
        self.data.iter().filter(|v| v.is_nan()).count()
    }

    /// Minimum and maximum of the valid cells, or `None` when every cell is nodata.
    pub fn min_max(&self) -> Option<(f32, f32)> {
        self.data
            .iter()
            .filter(|v| !v.is_nan())
            .fold(None, |acc, &v| match acc {
                None => Some((v, v)),
                Some((lo, hi)) => Some((lo.min(v), hi.max(v))),
            })
    }
}

/// The unit upward normal `[east, north, up]` of the height field `heights` (metres, NaN
/// nodata, row-major on `grid`) at cell `i`: the slope along each axis from the neighbours
/// before and after the cell, central where both are valid, one-sided where one is, level where
/// neither is (nor off the grid).
pub fn surface_normal(heights: &[f32], grid: &Grid, i: usize) -> [f64; 3] {
    let w = grid.width;
    normal_from(grid, i, |c, r| {
        Some(f64::from(heights[r * w + c])).filter(|v| v.is_finite())
    })
}

/// [`surface_normal`] of any surface: `z(col, row)` is its height at a cell (metres), `None`
/// where the cell is not part of it. Cell `i` itself must be part of it.
pub fn normal_from(grid: &Grid, i: usize, z: impl Fn(usize, usize) -> Option<f64>) -> [f64; 3] {
    let (w, h) = (grid.width, grid.height);
    let (col, row) = (i % w, i / w);
    let here = z(col, row).unwrap_or(f64::NAN);
    let slope = |before: Option<f64>, after: Option<f64>, step: f64| match (before, after) {
        (Some(a), Some(b)) => (b - a) / (2.0 * step),
        (Some(a), None) => (here - a) / step,
        (None, Some(b)) => (b - here) / step,
        (None, None) => 0.0,
    };
    let west = col.checked_sub(1).and_then(|c| z(c, row));
    let east = (col + 1 < w).then(|| z(col + 1, row)).flatten();
    let up = row.checked_sub(1).and_then(|r| z(col, r));
    let down = (row + 1 < h).then(|| z(col, row + 1)).flatten();
    // World x grows with the column by cell_x, world y with the row by cell_y (< 0 north-up).
    let dzdx = slope(west, east, grid.transform.cell_x);
    let dzdy = slope(up, down, grid.transform.cell_y);
    let norm = (dzdx * dzdx + dzdy * dzdy + 1.0).sqrt();
    [-dzdx / norm, -dzdy / norm, 1.0 / norm]
}

impl Colour {
    /// Number of nodata (alpha 0) cells.
    pub fn nodata_count(&self) -> usize {
        self.data.iter().filter(|p| p[3] == 0).count()
    }
}

/// sRGB byte → linear light, in [0, 1] (IEC 61966-2-1).
pub fn srgb_to_linear(v: u8) -> f64 {
    let c = f64::from(v) / 255.0;
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Linear in [0, 1] → the nearest sRGB byte.
pub fn linear_to_srgb(l: f64) -> u8 {
    let c = if l <= 0.003_130_8 {
        12.92 * l
    } else {
        1.055 * l.powf(1.0 / 2.4) - 0.055
    };
    (c * 255.0).round().clamp(0.0, 255.0) as u8
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::crs::Crs;

    #[test]
    fn nodata_counts_and_range_ignore_nodata() {
        let g = Grid::north_up(0.0, 2.0, 1.0, 2, 2, Crs::unknown());
        let e = Elevation::new(g.clone(), vec![1.0, f32::NAN, -3.0, 7.5]);
        assert_eq!(e.nodata_count(), 1);
        assert_eq!(e.min_max(), Some((-3.0, 7.5)));
        let all_nan = Elevation::filled(g.clone(), f32::NAN);
        assert_eq!(all_nan.min_max(), None);
        let c = Colour::new(
            g,
            vec![
                [1, 2, 3, 255],
                NODATA_COLOUR,
                [0, 0, 0, 255],
                [9, 9, 9, 255],
            ],
        );
        assert_eq!(c.nodata_count(), 1);
        assert_eq!(*c.get(0, 1), [0, 0, 0, 255]);
    }
}
