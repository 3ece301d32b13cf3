//! Cast-shadow masks over a height field for a sun direction, and shadows detected in a photo's
//! colours ([`detect`]: the index and threshold shadow-height and the pyramid share).
//!
//! # Model (the invariant)
//! The surface of each cell is the point at its centre, at its height. A valid cell is **in
//! shadow** when the ray from its centre toward the sun passes below the surface of another valid
//! cell it crosses: the ray is compared with that cell's height where it comes nearest to the
//! cell's centre (for rays along a grid axis: at whole cell distances). GRASS `r.sunmask`
//! samples the same surface at slightly different distances (see below and docs/shadows.md).
//! On smooth terrain a slope facing away from the sun is shadowed only when it is steeper than
//! the sun, and a vertical step of height `h` shades the cells whose centres are closer than
//! `h / tan(elevation)` to the step's top cell. Nodata
//! cells (NaN) cast no shadow, are not shadowed, and are marked [`NODATA`]; rays cross them.
//! Cells outside the grid cast nothing.
//!
//! Two implementations of that model:
//! * [`cast_shadows`] / [`cast_shadows_slice`]: the O(n) sweep. The grid is cut into parallel
//!   *digital lines* along the sun azimuth (one cell per step along the major axis, the minor axis
//!   rounded to the nearest cell, every line a translate of the same pattern, so each cell lies on
//!   exactly one line). Walking a line away from the sun it carries the shadow horizon
//!   `H = max over cells k steps ahead (z_k − k·L·tan e)`, with `L` the horizontal metres per
//!   step; a cell is shadowed when `z < H`. For azimuths along the grid axes and the diagonals of
//!   square cells the digital line *is* the ray and the sweep equals the reference; elsewhere a
//!   line stays within one cell of the ray, so only cells near shadow edges can differ (measured
//!   agreement in docs/shadows.md). [`RowSweep`] runs it one grid row at a time in
//!   O(width + height) memory, so a caller can stream a grid larger than memory through it;
//!   [`cast_shadows_slice`] is that loop over a slice held in memory.
//! * [`cast_shadows_reference`]: marches every cell's ray exactly, cell by cell
//!   (the shared [`crate::walk::Walk`] with [`crate::walk::Corner::Diagonal`]: a ray through a
//!   cell corner steps diagonally and touches neither side cell). O(n · shadow length); used by
//!   tests and benchmarks to check the sweep.
//!
//! And GRASS `r.sunmask`'s rule, [`cast_shadows_sunmask`]: the same surface, but each step of a
//! ray compares the height of the cell *containing* the step point at the *step's* distance, a
//! bias toward shadow off the axes. It reproduces GRASS's masks cell for cell, for comparisons
//! and for modellers who must match GRASS; the casts above stay the default.
//!
//! Units: heights in metres; cell sizes from the grid, in metres (a geographic grid is rejected;
//! non-square cells are allowed); sun angles in degrees, azimuth clockwise from north toward the
//! sun, elevation above the horizon in (0, 90]. A sun at or below the horizon is an error: the
//! whole grid would be in night shadow, which is almost always a wrong `--time`.

mod bits;
pub mod detect;
mod reference;
mod sunmask;
mod sweep;

pub use bits::ShadowBits;
pub use reference::cast_shadows_reference;
pub use sunmask::{cast_shadows_sunmask, cast_shadows_sunmask_slice};
pub use sweep::RowSweep;

use crate::error::{Error, Result};
use crate::grid::Grid;
use crate::raster::{Elevation, Raster};
use crate::sun::Sun;

/// Mask value of a lit cell.
pub const LIT: u8 = 0;
/// Mask value of a cell in cast shadow.
pub const SHADOW: u8 = 1;
/// Mask value of a nodata cell (nodata height).
pub const NODATA: u8 = 255;

/// Cast shadows over a height field (metres, NaN = nodata) for a sun at `sun_elevation_deg`
/// above the horizon and `sun_azimuth_deg` clockwise from north (toward the sun). Returns a mask
/// on the same grid: [`SHADOW`] (1), [`LIT`] (0) or [`NODATA`] (255). O(n), parallel.
/// Errors on an invalid sun (see [`Sun::new`]) or a grid not in metres.
pub fn cast_shadows(
    height: &Elevation,
    sun_elevation_deg: f64,
    sun_azimuth_deg: f64,
) -> Result<Raster<u8>> {
    let sun = Sun::new(sun_elevation_deg, sun_azimuth_deg)?;
    let data = cast_shadows_slice(&height.data, &height.grid, &sun)?;
    Ok(Raster::new(height.grid.clone(), data))
}

/// [`cast_shadows`] on a bare row-major height slice described by `grid` (only its size, cell
/// size and CRS are used): the cheap form for repeated casts over small windows, e.g. a crop of
/// terrain around one building (`grid.window_grid(&window)` gives the window's grid).
/// Errors when `heights.len() != grid.len()` or the grid is not in metres.
pub fn cast_shadows_slice(heights: &[f32], grid: &Grid, sun: &Sun) -> Result<Vec<u8>> {
    check_grid(heights, grid)?;
    if grid.is_empty() {
        return Ok(Vec::new());
    }
    let w = grid.width;
    let mut mask = vec![NODATA; heights.len()];
    let mut sweep = RowSweep::new(grid, sun)?;
    while let Some(r) = sweep.next_row() {
        sweep.push(&heights[r * w..(r + 1) * w], &mut mask[r * w..(r + 1) * w]);
    }
    Ok(mask)
}

/// The checks every cast shares: data matches the grid, cells are positive metres.
fn check_grid(heights: &[f32], grid: &Grid) -> Result<()> {
    if heights.len() != grid.len() {
        return Err(Error::msg(format!(
            "height data has {} values but its grid is {} × {}",
            heights.len(),
            grid.width,
            grid.height
        )));
    }
    check_cells(grid)
}

/// Shadows are cast in metres: the grid's cells must be positive sizes in a projected CRS.
fn check_cells(grid: &Grid) -> Result<()> {
    if grid.crs.geographic {
        return Err(Error::msg(format!(
            "cannot cast shadows on a grid in degrees ({})",
            grid.crs.name()
        ))
        .fix("reproject the elevation to a projected CRS in metres (e.g. UTM) first"));
    }
    let (cx, cy) = grid.cell_size();
    if !(cx.is_finite() && cy.is_finite() && cx > 0.0 && cy > 0.0) {
        return Err(Error::msg(format!("cell size {cx} × {cy} is not positive"))
            .fix("fix the grid's geotransform"));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::crs::Crs;
    use proptest::prelude::*;

    /// Axis-aligned and diagonal azimuths: the digital line is the ray, sweep == reference.
    const EXACT_AZIMUTHS: [f64; 8] = [0.0, 45.0, 90.0, 135.0, 180.0, 225.0, 270.0, 315.0];

    fn grid(w: usize, h: usize, cell_x: f64, cell_y: f64) -> Grid {
        let mut g = Grid::north_up(500_000.0, 5_300_000.0, cell_x, w, h, Crs::epsg(32632));
        g.transform.cell_y = -cell_y;
        g
    }

    fn raster(w: usize, h: usize, f: impl Fn(usize, usize) -> f32) -> Elevation {
        let g = grid(w, h, 1.0, 1.0);
        let data = (0..h)
            .flat_map(|r| (0..w).map(move |c| (c, r)))
            .map(|(c, r)| f(c, r))
            .collect();
        Elevation::new(g, data)
    }

    fn count(mask: &Raster<u8>, v: u8) -> usize {
        mask.data.iter().filter(|&&m| m == v).count()
    }

    /// Deterministic rugged terrain (hills of ±20 m every ~30 cells, 0.5 m of per-cell noise)
    /// with about 1 % nodata holes.
    fn rugged(w: usize, h: usize, seed: u64) -> Elevation {
        let hash = |c: usize, r: usize| {
            let mut x = (c as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
                ^ (r as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F)
                ^ seed;
            x ^= x >> 29;
            x = x.wrapping_mul(0xBF58_476D_1CE4_E5B9);
            x ^= x >> 32;
            (x % 10_000) as f32 / 10_000.0
        };
        raster(w, h, |c, r| {
            let v = hash(c, r);
            if v < 0.01 {
                f32::NAN
            } else {
                20.0 * ((c as f32 * 0.21).sin() + (r as f32 * 0.17).cos()) + 0.5 * v
            }
        })
    }

    /// Rows go to the sweep each exactly once, from the sun's side when the sun is nearer
    /// north or south.
    #[test]
    fn row_sweep_takes_every_row_once_from_the_sun_side() {
        let g = grid(7, 5, 1.0, 1.0);
        for (az, first) in [
            (0.0, 0),
            (20.0, 0),
            (180.0, 4),
            (200.0, 4),
            (90.0, 0),
            (270.0, 0),
            (80.0, 0),
            (100.0, 4),
        ] {
            let mut sweep = RowSweep::new(&g, &Sun::new(30.0, az).unwrap()).unwrap();
            let mut order = Vec::new();
            while let Some(r) = sweep.next_row() {
                order.push(r);
                sweep.push(&[1.0; 7], &mut [0; 7]);
            }
            assert_eq!(order[0], first, "az {az}");
            order.sort();
            assert_eq!(order, (0..5).collect::<Vec<_>>(), "az {az}");
        }
    }

    #[test]
    fn flat_grid_has_no_shadows_at_any_sun() {
        let e = raster(37, 23, |_, _| 312.25);
        for az in [0.0, 13.0, 45.0, 90.0, 180.0, 222.2, 270.0, 359.9] {
            for el in [0.5, 10.0, 89.9, 90.0] {
                let m = cast_shadows(&e, el, az).unwrap();
                assert_eq!(count(&m, LIT), e.data.len(), "az {az} el {el}");
            }
        }
    }

    #[test]
    fn cliff_shadow_length_is_height_over_tan_elevation() {
        // A 10 m wall across the grid; the sun behind it at each exact azimuth.
        let (n, wall) = (201usize, 100usize);
        for az in EXACT_AZIMUTHS {
            for el in [8.0, 30.0, 60.0, 89.9] {
                let sun = Sun::new(el, az).unwrap();
                let (east, north) = sun.direction();
                // Cells on the sun side of the wall line (through the centre, perpendicular to the sun) are 10 m.
                let e = raster(n, n, |c, r| {
                    let (x, y) = (c as f64 - wall as f64, wall as f64 - r as f64);
                    if x * east + y * north > 0.0 {
                        10.0
                    } else {
                        0.0
                    }
                });
                let m = cast_shadows(&e, el, az).unwrap();
                // Walk from the centre cell away from the sun: shadow length in whole steps.
                let step = if az % 90.0 == 0.0 {
                    1.0
                } else {
                    std::f64::consts::SQRT_2
                };
                let (dc, dr) = (
                    (-east).signum() as isize * (east != 0.0) as isize,
                    (north.signum() as isize) * (north != 0.0) as isize,
                );
                // Start on the last wall cell before the centre; count the shadowed cells after it.
                let (mut c, mut r, mut k) = (wall as isize - dc, wall as isize - dr, 0);
                loop {
                    c += dc;
                    r += dr;
                    if c < 0
                        || r < 0
                        || c >= n as isize
                        || r >= n as isize
                        || *m.get(c as usize, r as usize) != SHADOW
                    {
                        break;
                    }
                    k += 1;
                }
                let expected = sun.shadow_length(10.0);
                // The last shadowed cell's centre is within one step of the true shadow edge.
                assert!(
                    (k as f64 * step - expected).abs() <= step,
                    "az {az} el {el}: {k} steps vs {expected} m"
                );
                assert_eq!(
                    m,
                    cast_shadows_reference(&e, &sun).unwrap(),
                    "az {az} el {el}"
                );
            }
        }
    }

    #[test]
    fn low_sun_shadow_is_longer_than_the_grid() {
        // At 0.5° a 5 m step shades 573 m: every cell behind it in a 40-cell grid.
        let e = raster(17, 40, |_, r| if r == 0 { 5.0 } else { 0.0 });
        let m = cast_shadows(&e, 0.5, 0.0).unwrap();
        assert_eq!(count(&m, SHADOW), 17 * 39);
        assert!(m.rows().next().unwrap().iter().all(|&v| v == LIT));
    }

    #[test]
    fn nodata_is_marked_casts_nothing_and_is_skipped_over() {
        // A NaN "tower" between a lit cell and the sun casts no shadow; a real wall beyond the
        // hole still shades across it.
        let mut e = raster(3, 9, |_, _| 0.0);
        *e.get_mut(1, 2) = f32::NAN;
        let m = cast_shadows(&e, 45.0, 0.0).unwrap();
        assert_eq!(*m.get(1, 2), NODATA);
        assert_eq!(count(&m, SHADOW), 0);
        *e.get_mut(1, 0) = 3.5;
        let m = cast_shadows(&e, 45.0, 0.0).unwrap();
        // Rows 1..=3 are closer than 3.5 m / tan 45° to the wall; row 2 is the hole.
        let col: Vec<u8> = (0..9).map(|r| *m.get(1, r)).collect();
        assert_eq!(
            col,
            vec![LIT, SHADOW, NODATA, SHADOW, LIT, LIT, LIT, LIT, LIT]
        );
        let all_nan = raster(4, 4, |_, _| f32::NAN);
        assert_eq!(
            count(&cast_shadows(&all_nan, 30.0, 10.0).unwrap(), NODATA),
            16
        );
    }

    #[test]
    fn sweep_equals_reference_at_exact_azimuths_on_odd_sizes() {
        for (w, h) in [(1, 1), (1, 7), (7, 1), (37, 23), (23, 37), (64, 3)] {
            let e = rugged(w, h, 7);
            for az in EXACT_AZIMUTHS {
                for el in [0.5, 8.0, 35.0, 89.9] {
                    let fast = cast_shadows(&e, el, az).unwrap();
                    let exact = cast_shadows_reference(&e, &Sun::new(el, az).unwrap()).unwrap();
                    assert_eq!(fast, exact, "{w}×{h} az {az} el {el}");
                }
            }
        }
    }

    #[test]
    fn sweep_agrees_with_reference_at_any_azimuth() {
        // Off the axes the digital line is within a cell of the ray: only shadow edges may differ.
        let e = rugged(150, 110, 3);
        for az in [10.0, 33.3, 60.0, 100.0, 161.0, 200.5, 250.0, 291.0, 344.0] {
            let sun = Sun::new(25.0, az).unwrap();
            let fast = cast_shadows(&e, 25.0, az).unwrap();
            let exact = cast_shadows_reference(&e, &sun).unwrap();
            let same = fast
                .data
                .iter()
                .zip(&exact.data)
                .filter(|(a, b)| a == b)
                .count();
            let shadowed = count(&exact, SHADOW);
            assert!(
                shadowed > 1000,
                "az {az}: test terrain casts too little shadow ({shadowed})"
            );
            let agreement = same as f64 / e.data.len() as f64;
            // Measured 0.944–0.984 on this very steep terrain (slopes to 400 %); a sweep along a
            // mirrored direction agrees about 0.82.
            assert!(agreement > 0.93, "az {az}: agreement {agreement}");
        }
    }

    #[test]
    fn non_square_cells_use_metres_not_cells() {
        // 1 m × 3 m cells: a 5.5 m wall at 45° elevation shades the cells closer than 5.5 m:
        // 5 columns east–west but only 1 row (3 m) north–south.
        let mut g = grid(40, 40, 1.0, 3.0);
        g.transform.cell_y = -3.0;
        let e = Elevation::new(
            g.clone(),
            (0..1600)
                .map(|i| if i % 40 == 0 || i < 40 { 5.5 } else { 0.0 })
                .collect(),
        );
        let west = cast_shadows(&e, 45.0, 270.0).unwrap();
        assert_eq!((1..40).filter(|&c| *west.get(c, 20) == SHADOW).count(), 5);
        let north = cast_shadows(&e, 45.0, 0.0).unwrap();
        assert_eq!((1..40).filter(|&r| *north.get(20, r) == SHADOW).count(), 1);
        for az in [0.0, 90.0, 180.0, 270.0] {
            assert_eq!(
                west_or(&e, az),
                cast_shadows_reference(&e, &Sun::new(45.0, az).unwrap()).unwrap()
            );
        }
        fn west_or(e: &Elevation, az: f64) -> Raster<u8> {
            cast_shadows(e, 45.0, az).unwrap()
        }
    }

    #[test]
    fn bad_suns_and_grids_are_errors() {
        let e = raster(3, 3, |_, _| 1.0);
        for (el, az) in [
            (0.0, 10.0),
            (-3.0, 10.0),
            (90.5, 0.0),
            (f64::NAN, 0.0),
            (30.0, f64::INFINITY),
        ] {
            let err = cast_shadows(&e, el, az).unwrap_err().to_string();
            assert!(!err.contains('\n'), "{err}");
        }
        assert!(cast_shadows(&e, -1.0, 0.0)
            .unwrap_err()
            .to_string()
            .contains("night"));
        let mut geo = e.clone();
        geo.grid.crs = Crs::epsg(4326);
        assert!(cast_shadows(&geo, 30.0, 0.0)
            .unwrap_err()
            .to_string()
            .contains("degrees"));
        assert!(cast_shadows_slice(&[1.0; 4], &e.grid, &Sun::new(30.0, 0.0).unwrap()).is_err());
        assert_eq!(Sun::new(10.0, -90.0).unwrap().azimuth_deg, 270.0);
    }

    #[test]
    fn window_cast_matches_the_cropped_raster() {
        let e = rugged(60, 50, 11);
        let w = crate::grid::Window {
            col: 7,
            row: 5,
            width: 31,
            height: 19,
        };
        let sub = e.grid.window_grid(&w);
        let crop: Vec<f32> = (w.row..w.row + w.height)
            .flat_map(|r| (w.col..w.col + w.width).map(move |c| (c, r)))
            .map(|(c, r)| *e.get(c, r))
            .collect();
        let sun = Sun::new(20.0, 123.0).unwrap();
        let slice = cast_shadows_slice(&crop, &sub, &sun).unwrap();
        assert_eq!(
            slice,
            cast_shadows(&Elevation::new(sub, crop), 20.0, 123.0)
                .unwrap()
                .data
        );
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(48))]

        #[test]
        fn sweep_is_exact_on_axes_and_diagonals(
            w in 1usize..24, h in 1usize..24, seed in any::<u64>(),
            az_i in 0usize..8, el in 0.5f64..89.9,
        ) {
            let e = rugged(w, h, seed);
            let az = EXACT_AZIMUTHS[az_i];
            let fast = cast_shadows(&e, el, az).unwrap();
            let exact = cast_shadows_reference(&e, &Sun::new(el, az).unwrap()).unwrap();
            prop_assert_eq!(fast, exact);
        }

        #[test]
        fn every_valid_cell_is_lit_or_shadowed_and_shadow_needs_a_higher_cell(
            w in 1usize..30, h in 1usize..30, seed in any::<u64>(), az in 0.0f64..360.0, el in 0.5f64..89.9,
        ) {
            let e = rugged(w, h, seed);
            let m = cast_shadows(&e, el, az).unwrap();
            let top = e.min_max().map(|(_, t)| t);
            for (z, v) in e.data.iter().zip(&m.data) {
                if z.is_nan() {
                    prop_assert_eq!(*v, NODATA);
                } else {
                    prop_assert!(*v == LIT || *v == SHADOW);
                    // The highest cell is never shadowed.
                    if Some(*z) == top { prop_assert_eq!(*v, LIT); }
                }
            }
        }
    }
}
