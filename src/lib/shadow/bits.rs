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
        let h = terrain.grid().height;
        ShadowBits::cast_rows(terrain, sun, overlay, 0..h, f64::INFINITY)
    }

    /// [`cast`](Self::cast) for the cells of grid rows `rows` only, bit for bit what the whole
    /// cast gives there (other cells are left unset), when no surface height (terrain and
    /// overlay, metres) anywhere exceeds `top`.
    ///
    /// The sweep starts where nothing farther toward the sun can reach the rows: a cell `k`
    /// steps up a line contributes `z − k · rise` to the horizons below it ([`RowSweep`]), and
    /// the sweep's `max(h, z) − rise` carries exactly one such chain, so a chain that starts
    /// below `top` and has fallen under the lowest valid height in `rows` by the time it gets
    /// there shadows nothing in them (a millimetre of margin covers the chains' rounding).
    /// `top = +inf` sweeps from the grid's edge.
    ///
    /// # Panics
    /// When `rows` reaches past the grid's last row (a programming error).
    pub fn cast_rows(
        terrain: &dyn RowSource<f32>,
        sun: &Sun,
        overlay: impl Fn(usize, &mut [f32]),
        rows: std::ops::Range<usize>,
        top: f64,
    ) -> Result<ShadowBits> {
        let g = terrain.grid();
        let (w, h) = (g.width, g.height);
        let mut bits = vec![0u64; (w * h).div_ceil(64)];
        assert!(rows.end <= h, "cast_rows: rows {rows:?} of a grid of {h}");
        let mut sweep = RowSweep::new(g, sun)?;
        if rows.is_empty() {
            return Ok(ShadowBits { bits });
        }
        let upward = h > 1 && sweep.next_row() == Some(h - 1);
        // Rows swept before the first of `rows` in the sweep's order.
        let before = match upward {
            true => h - rows.end,
            false => rows.start,
        };
        let upstream = match before > 0 && top.is_finite() {
            false => before,
            true => match lowest_valid(terrain, &overlay, rows.clone())? {
                None => 0,
                Some(z) => sweep.rows_upstream(top - z + 1e-3).min(before),
            },
        };
        sweep.skip(before - upstream);
        // The grid rows swept: only these are read.
        let span = match upward {
            true => rows.start..rows.end + upstream,
            false => rows.start - upstream..rows.end,
        };
        let per_band = band_rows(w);
        let (mut heights, mut mask) = (vec![0f32; w], vec![0u8; w]);
        let mut band: (usize, Vec<f32>) = (0, Vec::new());
        while let Some(r) = sweep.next_row() {
            // Past the last of `rows` in the sweep's order: done.
            if (upward && r < rows.start) || (!upward && r >= rows.end) {
                break;
            }
            let (b0, data) = &band;
            if !(r >= *b0 && (r - b0) * w < data.len()) {
                let b0 = if upward {
                    (r + 1).saturating_sub(per_band).max(span.start)
                } else {
                    r
                };
                let n = if upward {
                    r + 1 - b0
                } else {
                    per_band.min(span.end - r)
                };
                band = (b0, terrain.read_rows(b0, n)?.into_owned());
            }
            let (b0, data) = &band;
            let start = r * w;
            heights.copy_from_slice(&data[(r - b0) * w..(r - b0 + 1) * w]);
            overlay(start, &mut heights);
            sweep.push(&heights, &mut mask);
            if !rows.contains(&r) {
                continue;
            }
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

/// The lowest valid surface height (metres) in grid rows `rows` of `terrain` with `overlay`
/// laid over it; `None` when every cell there is nodata.
fn lowest_valid(
    terrain: &dyn RowSource<f32>,
    overlay: &impl Fn(usize, &mut [f32]),
    rows: std::ops::Range<usize>,
) -> Result<Option<f64>> {
    let w = terrain.grid().width;
    let per_band = band_rows(w);
    let mut lowest: Option<f64> = None;
    for b0 in rows.clone().step_by(per_band) {
        let n = per_band.min(rows.end - b0);
        let mut band = terrain.read_rows(b0, n)?.into_owned();
        for (k, row) in band.chunks_mut(w).enumerate() {
            overlay((b0 + k) * w, row);
        }
        for &z in band.iter().filter(|z| !z.is_nan()) {
            lowest = Some(lowest.map_or(z as f64, |l| l.min(z as f64)));
        }
    }
    Ok(lowest)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::crs::Crs;
    use crate::grid::Grid;
    use crate::raster::Elevation;
    use proptest::prelude::*;
    use std::borrow::Cow;
    use std::sync::atomic::{AtomicUsize, Ordering};

    /// A terrain that counts the rows read from it.
    struct Counted {
        dem: Elevation,
        rows: AtomicUsize,
    }

    impl RowSource<f32> for Counted {
        fn grid(&self) -> &crate::grid::Grid {
            &self.dem.grid
        }
        fn read_rows(&self, row0: usize, rows: usize) -> Result<Cow<'_, [f32]>> {
            self.rows.fetch_add(rows, Ordering::Relaxed);
            self.dem.read_rows(row0, rows)
        }
    }

    fn same_in_rows(dem: &Elevation, sun: &Sun, rows: std::ops::Range<usize>) {
        let top = dem.data.iter().fold(
            f64::MIN,
            |m, &z| if z.is_nan() { m } else { m.max(z as f64) },
        );
        let raise = |start: usize, row: &mut [f32]| {
            // A tower laid over the terrain, as buildings are.
            if start == 0 {
                row[0] = top as f32 + 7.0;
            }
        };
        let whole = ShadowBits::cast(dem, sun, raise).unwrap();
        let part = ShadowBits::cast_rows(dem, sun, raise, rows.clone(), top + 7.0).unwrap();
        let w = dem.grid.width;
        for i in 0..dem.data.len() {
            let want = rows.contains(&(i / w)) && whole.get(i);
            assert_eq!(
                part.get(i),
                want,
                "cell {i} ({}, {}), rows {rows:?}, {sun:?}",
                i % w,
                i / w
            );
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(200))]
        /// Any window of rows, any sun (the axes, the diagonals, a few ulps off them, low and
        /// high), rough terrain with nodata: the window's cast is the whole cast's there.
        #[test]
        fn a_window_of_rows_casts_what_the_whole_grid_casts_there(
            w in 1usize..40,
            h in 1usize..40,
            seed in any::<u64>(),
            az_pick in 0usize..12,
            az_free in 0.0f64..360.0,
            el in prop::sample::select(vec![0.5, 3.0, 20.0, 45.0, 80.0, 89.99, 90.0]),
            a in 0usize..40,
            b in 0usize..40,
        ) {
            let azimuths = [0.0, 90.0, 180.0, 270.0, 45.0, 135.0, 225.0, 315.0];
            let az = match az_pick {
                k if k < 8 => azimuths[k],
                8 => f64::from_bits(45f64.to_bits() + 3),
                9 => f64::from_bits(90f64.to_bits() - 2),
                _ => az_free,
            };
            let g = Grid::north_up(500_000.0, 5_300_000.0, 2.0, w, h, Crs::epsg(32632));
            let data = (0..w * h)
                .map(|i| {
                    let u = crate::voxel::place::uniform(seed, i as u64, 0);
                    if u < 0.05 { f32::NAN } else { (u * 30.0) as f32 }
                })
                .collect();
            let dem = Elevation::new(g, data);
            let (a, b) = (a.min(h), b.min(h));
            same_in_rows(&dem, &Sun::new(el, az).unwrap(), a.min(b)..a.max(b));
        }
    }

    /// A lone tower's shadow tip falls in the window, many rows from the tower: the window's
    /// cast sweeps far enough toward the sun to find it, whichever way the lines run.
    #[test]
    fn a_far_tower_still_shadows_the_window() {
        let n = 300;
        let g = Grid::north_up(0.0, 0.0, 1.0, n, n, Crs::epsg(32632));
        let mut data = vec![0.0f32; n * n];
        data[150 * n + 150] = 100.0;
        let dem = Elevation::new(g, data);
        for az in [
            0.0, 30.0, 45.0, 60.0, 120.0, 135.0, 180.0, 240.0, 300.0, 330.0,
        ] {
            let sun = Sun::new(45.0, az).unwrap();
            // The tip, 100 m from the tower away from the sun: rows grow southward.
            let tip = 150.0 + 95.0 * az.to_radians().cos();
            let rows = (tip as usize - 3)..(tip as usize + 4);
            let whole = ShadowBits::cast(&dem, &sun, |_, _| ()).unwrap();
            let part = ShadowBits::cast_rows(&dem, &sun, |_, _| (), rows.clone(), 100.0).unwrap();
            let cells = rows.start * n..rows.end * n;
            assert!(
                cells.clone().any(|i| whole.get(i)),
                "the tip is in the window, azimuth {az}"
            );
            for i in cells {
                assert_eq!(part.get(i), whole.get(i), "cell {i}, azimuth {az}");
            }
        }
    }

    /// On gentle terrain under a high sun, a window far from the sun's edge reads only the rows
    /// a shadow can come from, not the grid from its edge.
    #[test]
    fn a_window_reads_only_the_rows_that_can_shadow_it() {
        let (w, h) = (50, 400);
        let g = Grid::north_up(0.0, 0.0, 1.0, w, h, Crs::epsg(32632));
        let data = (0..w * h).map(|i| ((i / w) % 7) as f32).collect();
        let dem = Elevation::new(g, data);
        for az in [0.0, 180.0, 60.0, 300.0] {
            let sun = Sun::new(45.0, az).unwrap();
            let counted = Counted {
                dem: dem.clone(),
                rows: AtomicUsize::new(0),
            };
            let part = ShadowBits::cast_rows(&counted, &sun, |_, _| (), 190..210, 6.0).unwrap();
            let read = counted.rows.load(Ordering::Relaxed);
            // The window twice (its lowest height, then the sweep) and the rows before it a
            // shadow can come from: 6 m at a rise of 1 m a step (fewer rows off the axes).
            assert!(
                read <= 2 * 20 + 12,
                "{read} rows read for a 20-row window, azimuth {az}"
            );
            let whole = ShadowBits::cast(&dem, &sun, |_, _| ()).unwrap();
            for i in 190 * w..210 * w {
                assert_eq!(part.get(i), whole.get(i), "cell {i}, azimuth {az}");
            }
        }
    }
}
