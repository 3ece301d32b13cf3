//! GRASS GIS `r.sunmask`'s rule, reproduced so its masks can be matched cell for cell.
//!
//! # The rule (GRASS 8 `raster/r.sunmask/main.c`)
//! From the centre of each valid cell the ray steps `(sin a, cos a)` cells east and north at a
//! time (`a` the azimuth; `L = |(sin a · cell_x, cos a · cell_y)|` metres a step; the point is
//! moved by repeated addition in world coordinates, as GRASS moves it). At step `k` it
//! looks up the cell *containing* the step point and shades the start cell when that cell's
//! height exceeds the start's by more than `k · L · tan e`, the ray's rise at the *step's*
//! distance. It stops when the point leaves the grid or the rise exceeds the highest cell. Off
//! the axes a step point can lie up to 0.7 cells short of the centre of the cell it samples, so
//! this rule shades more than [`super::cast_shadows`]'s, which compares at the cell centre's
//! distance (measured in docs/shadows.md). With non-square cells the steps follow `a` in *cells*,
//! as GRASS's do, not in metres. Nodata cells are marked [`NODATA`], cast nothing and are never
//! shadowed; a height of exactly 0 is a height (`r.sunmask -z`; without `-z` GRASS never
//! shades a 0 m cell).
//!
//! # Fast, and still exact
//! Each cell's test is a march of up to the shadow length `(top − z) / (L tan e)` steps, so it
//! is not marched unless it can be in shadow. A sample at step `k` lies within half a frame row
//! of the row it falls in and within two cells, across the lines, of the cell the O(n) sweep's
//! digital line has in that row (a line stays within one cell of its ray, the sample within one
//! of the same ray). So the sweep ([`RowSweep`]) of the surface max-filtered over five cells
//! across the lines (padded by two cells at those edges) gives every cell a horizon `H'` that no
//! sample exceeds by more than half a row's rise: a cell with `z ≥ H' + rise / 2` is lit under
//! this rule, and only the others are marched. Cost O(n) plus the marches of the cells near
//! shadow. Memory beyond the mask: the filtered row the sweep is fed and its horizons (12 bytes
//! a cell of one row), the sweep's `16 · (width + height)` bytes and the step table.

use super::{check_grid, RowSweep, Sun, LIT, NODATA, SHADOW};
use crate::error::Result;
use crate::grid::Grid;
use crate::raster::{Elevation, Raster};
use rayon::prelude::*;

/// Cells across the lines on each side that the bound's max filter covers (see the module doc).
const SPREAD: usize = 2;

/// Temporary mask value of a cell that may be in shadow and is still to be marched.
const MAYBE: u8 = 2;

/// Cast shadows over a height field (metres, NaN = nodata) with GRASS `r.sunmask`'s rule (see
/// the module doc). Returns a mask on the same grid: [`SHADOW`] (1), [`LIT`] (0) or [`NODATA`]
/// (255). Errors when the grid is not in metres.
pub fn cast_shadows_sunmask(height: &Elevation, sun: &Sun) -> Result<Raster<u8>> {
    let data = cast_shadows_sunmask_slice(&height.data, &height.grid, sun)?;
    Ok(Raster::new(height.grid.clone(), data))
}

/// [`cast_shadows_sunmask`] on a bare row-major height slice (metres, NaN = nodata) described by
/// `grid` (only its size, cell size and CRS are used). Errors when `heights.len() !=
/// grid.len()` or the grid is not in metres.
pub fn cast_shadows_sunmask_slice(heights: &[f32], grid: &Grid, sun: &Sun) -> Result<Vec<u8>> {
    check_grid(heights, grid)?;
    if grid.transform.cell_y > 0.0 {
        return Err(crate::error::Error::msg(
            "r.sunmask's rule needs a north-up grid; this one's rows run south to north",
        )
        .fix("warp the elevation north-up (gdalwarp) first"));
    }
    let mut mask: Vec<u8> = heights
        .iter()
        .map(|z| if z.is_nan() { NODATA } else { LIT })
        .collect();
    let Some(top) = heights
        .iter()
        .copied()
        .filter(|z| !z.is_nan())
        .reduce(f32::max)
    else {
        return Ok(mask);
    };
    let bottom = heights
        .iter()
        .copied()
        .filter(|z| !z.is_nan())
        .fold(top, f32::min);
    if sun.elevation_deg >= 90.0 || top == bottom {
        return Ok(mask);
    }
    mark_maybe(heights, grid, sun, &mut mask)?;
    let march = March::new(grid, sun, top);
    let w = grid.width;
    mask.par_chunks_mut(w).enumerate().for_each(|(row, out)| {
        for (col, m) in out.iter_mut().enumerate() {
            if *m == MAYBE {
                *m = march.cast(heights, col, row);
            }
        }
    });
    Ok(mask)
}

/// r.sunmask's march of one cell, in world coordinates with the step point moved by repeated
/// addition exactly as `main.c` moves it: where a step point falls exactly on a cell edge
/// (azimuths whose sine or cosine is ±0.5, e.g. 30° or 300°), which cell GRASS samples depends
/// on how the sums round, and only the same sums reproduce it.
struct March {
    width: usize,
    height: usize,
    /// Grid edges, CRS units: west, north, east, south.
    west: f64,
    north: f64,
    east: f64,
    south: f64,
    /// Cell size, metres: east–west, north–south (positive).
    ew: f64,
    ns: f64,
    /// Step, metres: east, north.
    estep: f64,
    nstep: f64,
    tan_e: f64,
    /// Highest valid height of the grid, metres.
    top: f64,
}

impl March {
    fn new(grid: &Grid, sun: &Sun, top: f32) -> March {
        let t = &grid.transform;
        let (ew, ns) = (t.cell_x, -t.cell_y);
        // Degrees to radians as r.sunmask converts them, for the same rounding.
        let azimuth = 2.0 * std::f64::consts::PI * sun.azimuth_deg / 360.0;
        let elevation = 2.0 * std::f64::consts::PI * sun.elevation_deg / 360.0;
        March {
            width: grid.width,
            height: grid.height,
            west: t.origin_x,
            north: t.origin_y,
            east: t.origin_x + grid.width as f64 * ew,
            south: t.origin_y - grid.height as f64 * ns,
            ew,
            ns,
            estep: azimuth.sin() * ew,
            nstep: azimuth.cos() * ns,
            tan_e: elevation.tan(),
            top: top as f64,
        }
    }

    /// The mask value of valid cell `(col, row)`: step until the point leaves the grid or the
    /// ray's rise exceeds the highest cell, shadowed when a sampled cell is higher than the start
    /// by more than the rise.
    fn cast(&self, heights: &[f32], col: usize, row: usize) -> u8 {
        let z = heights[row * self.width + col] as f64;
        let (e1, n1) = (
            self.west + (col as f64 + 0.5) * self.ew,
            self.north - (row as f64 + 0.5) * self.ns,
        );
        let (mut e, mut n) = (e1, n1);
        loop {
            e += self.estep;
            n += self.nstep;
            if n > self.north || n < self.south || e > self.east || e < self.west {
                return LIT;
            }
            let rise = self.tan_e * ((n1 - n) * (n1 - n) + (e1 - e) * (e1 - e)).sqrt();
            if rise > self.top - z {
                return LIT;
            }
            // A point exactly on the east or south edge is inside for GRASS, which then reads
            // one cell past its buffer (the fixture shows it does not shade there): no sample.
            let c = ((e - self.west) / self.ew) as usize;
            let r = ((self.north - n) / self.ns) as usize;
            if c < self.width && r < self.height && heights[r * self.width + c] as f64 - z > rise {
                return SHADOW;
            }
        }
    }
}

/// Mark [`MAYBE`] the valid cells the bound of the module doc cannot clear: one sweep, fed the
/// surface max-filtered over `2 · SPREAD + 1` cells across the lines a row at a time.
fn mark_maybe(heights: &[f32], grid: &Grid, sun: &Sun, mask: &mut [u8]) -> Result<()> {
    // The sun whose direction in metres follows r.sunmask's steps in cells.
    let a = sun.azimuth_deg.to_radians();
    let (cell_x, cell_y) = grid.cell_size();
    let along = Sun::new(
        sun.elevation_deg,
        (a.sin() * cell_x).atan2(a.cos() * cell_y).to_degrees(),
    )?;
    let (w, h) = (grid.width, grid.height);
    // Lines run across the rows (transposed) or across the columns: pad and filter that axis.
    let across_rows = RowSweep::new(grid, &along)?.transposed();
    let mut padded = grid.clone();
    if across_rows {
        padded.height += 2 * SPREAD;
    } else {
        padded.width += 2 * SPREAD;
    }
    let mut sweep = RowSweep::new(&padded, &along)?;
    let slack = sweep.rise() / 2.0;
    let pw = padded.width;
    let (mut filtered, mut horizon) = (vec![f32::NAN; pw], vec![0f64; pw]);
    let max = |a: f32, b: f32| if a.is_nan() || b > a { b } else { a };
    while let Some(pr) = sweep.next_row() {
        // Grid row of padded row `pr`, when it is one.
        let row = if across_rows {
            pr.checked_sub(SPREAD).filter(|&r| r < h)
        } else {
            Some(pr)
        };
        if across_rows {
            let lo = pr.saturating_sub(2 * SPREAD);
            let hi = pr.min(h - 1);
            filtered.fill(f32::NAN);
            for r in lo..=hi {
                for (f, &z) in filtered.iter_mut().zip(&heights[r * w..(r + 1) * w]) {
                    *f = max(*f, z);
                }
            }
        } else {
            let src = &heights[pr * w..(pr + 1) * w];
            for (pc, f) in filtered.iter_mut().enumerate() {
                let lo = pc.saturating_sub(2 * SPREAD);
                let hi = pc.min(w - 1);
                *f = src[lo..=hi].iter().copied().fold(f32::NAN, max);
            }
        }
        sweep.push_horizons(&filtered, &mut horizon);
        let Some(row) = row else { continue };
        let pad = if across_rows { 0 } else { SPREAD };
        for (col, m) in mask[row * w..(row + 1) * w].iter_mut().enumerate() {
            let z = heights[row * w + col] as f64;
            // A little more than half a row's rise: the sweep's sums round.
            let bound = horizon[col + pad] + slack + 1e-6 * (1.0 + z.abs());
            if *m == LIT && z < bound {
                *m = MAYBE;
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::crs::Crs;
    use crate::shadow::cast_shadows_slice;
    use proptest::prelude::*;

    fn grid(w: usize, h: usize, cell_x: f64, cell_y: f64) -> Grid {
        let mut g = Grid::north_up(500_000.0, 5_300_000.0, cell_x, w, h, Crs::epsg(32614));
        g.transform.cell_y = -cell_y;
        g
    }

    /// r.sunmask's loop as `main.c` writes it, every cell marched in world coordinates, the
    /// step point moved by repeated addition: the oracle for the fast cast.
    fn literal_sunmask(heights: &[f32], g: &Grid, sun: &Sun) -> Vec<u8> {
        let (w, h) = (g.width, g.height);
        let t = &g.transform;
        let (west, north_edge) = (t.origin_x, t.origin_y);
        let (ew, ns) = (t.cell_x, -t.cell_y);
        let (east_edge, south) = (west + w as f64 * ew, north_edge - h as f64 * ns);
        let dmax = heights
            .iter()
            .copied()
            .filter(|z| !z.is_nan())
            .fold(f64::NEG_INFINITY, |a, z| a.max(z as f64));
        let azi = 2.0 * std::f64::consts::PI * sun.azimuth_deg / 360.0;
        let alti = 2.0 * std::f64::consts::PI * sun.elevation_deg / 360.0;
        let (nstep, estep) = (azi.cos() * ns, azi.sin() * ew);
        let mut out = vec![NODATA; w * h];
        for row in 0..h {
            for col in 0..w {
                let dvalue = heights[row * w + col] as f64;
                if dvalue.is_nan() {
                    continue;
                }
                out[row * w + col] = LIT;
                let (e1, n1) = (
                    west + (col as f64 + 0.5) * ew,
                    north_edge - (row as f64 + 0.5) * ns,
                );
                let (mut e, mut n) = (e1, n1);
                loop {
                    e += estep;
                    n += nstep;
                    if n > north_edge || n < south || e > east_edge || e < west {
                        break;
                    }
                    let maxh = alti.tan() * ((n1 - n).powi(2) + (e1 - e).powi(2)).sqrt();
                    if maxh > dmax - dvalue {
                        break;
                    }
                    let (c, r) = (((e - west) / ew) as usize, ((north_edge - n) / ns) as usize);
                    // On the east or south edge GRASS reads past its buffer: no sample here.
                    if c < w && r < h && heights[r * w + c] as f64 - dvalue > maxh {
                        out[row * w + col] = SHADOW;
                        break;
                    }
                }
            }
        }
        out
    }

    /// Hand-worked: at azimuth 45° the first step from (0, 2)'s centre lands in (1, 1) at 1 m;
    /// that diagonal neighbour's centre is √2 m away. 1.2 m above the start with the sun at 45°
    /// (rise = distance) it shades the start by r.sunmask's rule (1.2 > 1) but not by ours
    /// (1.2 < 1.414).
    #[test]
    fn sunmask_rule_compares_at_the_step_distance() {
        let g = grid(3, 3, 1.0, 1.0);
        let mut z = vec![0.0f32; 9];
        z[3 + 1] = 1.2; // (1, 1)
        let sun = Sun::new(45.0, 45.0).unwrap();
        let m = cast_shadows_sunmask_slice(&z, &g, &sun).unwrap();
        assert_eq!(m, vec![0, 0, 0, 0, 0, 0, 1, 0, 0]);
        assert_eq!(cast_shadows_slice(&z, &g, &sun).unwrap()[6], LIT);
        // Steps from (0, 2): k = 1, 2 both in (1, 1) (1 m, 2 m); k = 3 in (2, 0) at 3 m.
        // 2.9 m at (2, 0) is below the 3 m rise there: lit; 3.1 m shades.
        let mut z = vec![0.0f32; 9];
        z[2] = 2.9;
        assert_eq!(cast_shadows_sunmask_slice(&z, &g, &sun).unwrap()[6], LIT);
        z[2] = 3.1;
        assert_eq!(cast_shadows_sunmask_slice(&z, &g, &sun).unwrap()[6], SHADOW);
    }

    #[test]
    fn flat_grid_and_zenith_are_lit_and_nodata_is_marked() {
        let g = grid(9, 7, 1.0, 1.0);
        let mut z = vec![5.0f32; 63];
        z[10] = f32::NAN;
        for (el, az) in [(0.5, 10.0), (30.0, 200.0), (90.0, 0.0)] {
            let m = cast_shadows_sunmask_slice(&z, &g, &Sun::new(el, az).unwrap()).unwrap();
            assert_eq!(m[10], NODATA);
            assert_eq!(m.iter().filter(|&&v| v == LIT).count(), 62);
        }
        let all_nan = vec![f32::NAN; 63];
        let m = cast_shadows_sunmask_slice(&all_nan, &g, &Sun::new(9.0, 1.0).unwrap()).unwrap();
        assert!(m.iter().all(|&v| v == NODATA));
    }

    /// GRASS 8.2.1 `r.sunmask -z` on a 24 × 18 grid (tests/data/sunmask/, made by
    /// tests/data/make_sunmask_fixture.sh): equal cell for cell at every sun, two of them (300°, 30°) with steps landing exactly on cell edges.
    #[test]
    fn agrees_with_grass_r_sunmask_fixture() {
        let text = include_str!("../../../tests/data/sunmask/fixture.txt");
        let mut lines = text.lines().filter(|l| !l.starts_with('#'));
        let head: Vec<f64> = lines
            .next()
            .unwrap()
            .split_whitespace()
            .map(|v| v.parse().unwrap())
            .collect();
        let (w, h) = (head[0] as usize, head[1] as usize);
        let g = grid(w, h, head[2], head[3]);
        let heights: Vec<f32> = (0..h)
            .flat_map(|_| {
                let l = lines.next().unwrap();
                l.split_whitespace()
                    .map(|v| v.parse::<f32>().unwrap_or(f32::NAN))
                    .collect::<Vec<_>>()
            })
            .collect();
        let mut suns = 0;
        while let Some(l) = lines.next() {
            let sun: Vec<f64> = l
                .split_whitespace()
                .skip(1)
                .map(|v| v.parse().unwrap())
                .collect();
            let sun = Sun::new(sun[0], sun[1]).unwrap();
            let grass: Vec<u8> = (0..h)
                .flat_map(|_| {
                    let l = lines.next().unwrap();
                    l.bytes()
                        .map(|b| match b {
                            b'1' => SHADOW,
                            b'0' => LIT,
                            _ => NODATA,
                        })
                        .collect::<Vec<_>>()
                })
                .collect();
            let ours = cast_shadows_sunmask_slice(&heights, &g, &sun).unwrap();
            assert_eq!(ours, grass, "{sun:?}");
            assert!(ours.contains(&SHADOW), "{sun:?}: the fixture should cast");
            suns += 1;
        }
        assert!(suns >= 5);
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(160))]

        /// The bound only skips cells the march would light: the fast cast equals r.sunmask's
        /// loop on random terrain with holes, any sun and non-square cells.
        #[test]
        fn fast_cast_equals_the_literal_loop(
            w in 1usize..40, h in 1usize..40, cell_x in 0.5f64..3.0, cell_y in 0.5f64..3.0,
            az in 0.0f64..360.0, el in 0.5f64..70.0, seed in any::<u64>(), axis in 0usize..10,
        ) {
            // Some cases on an axis, a diagonal, or where steps land exactly on cell edges
            // (sine or cosine ±0.5).
            let special = [0.0, 45.0, 90.0, 135.0, 180.0, 225.0, 270.0, 315.0, 30.0, 60.0, 120.0, 150.0, 210.0, 240.0, 300.0, 330.0];
            let az = if axis < 6 { az } else { special[(seed % 16) as usize] };
            let g = grid(w, h, cell_x, cell_y);
            let mut x = seed | 1;
            let heights: Vec<f32> = (0..w * h).map(|i| {
                x ^= x << 13; x ^= x >> 7; x ^= x << 17;
                let (c, r) = ((i % w) as f32, (i / w) as f32);
                if x % 37 == 0 { f32::NAN } else { 8.0 * (c * 0.4).sin() + 6.0 * (r * 0.3).cos() + (x % 300) as f32 / 100.0 }
            }).collect();
            let sun = Sun::new(el, az).unwrap();
            prop_assert_eq!(
                cast_shadows_sunmask_slice(&heights, &g, &sun).unwrap(),
                literal_sunmask(&heights, &g, &sun)
            );
        }
    }
}
