//! Resampling a raster onto another grid of the same CRS.
//!
//! Both grids are axis-aligned, so the weights of a target cell factor into one list of
//! source-column taps per target column and one list of source-row taps per target row; they
//! are computed once and the 2-D pass is a separable weighted sum. This is exact, fast and
//! trivially parallel over rows, and it streams: [`Resampler`] makes any band of target rows
//! from just the source rows its taps name, bit-identical to the whole result.
//!
//! # Rules (the invariants the tests check)
//! * A value is a sample at its cell centre. A target cell takes data only when its centre lies
//!   inside the source extent (`nearest`, `bilinear`, `cubic`) or its footprint overlaps it
//!   (`average`); otherwise it is nodata. Nothing is extrapolated.
//! * Nodata never enters a result: nodata taps get no weight and the valid weights are
//!   renormalised. For `nearest`, `bilinear` and `cubic` a target cell whose centre falls in a
//!   nodata source cell is nodata, whatever its neighbours (this is `gdalwarp`'s rule, so void
//!   outlines agree cell for cell); for `average`, a cell is nodata when less than
//!   [`MIN_VALID_WEIGHT`] of its footprint has valid data.
//! * Cubic (Keys, a = −0.5, GDAL's `cubic`) falls back to bilinear for a cell whose 4×4
//!   support touches nodata or the edge, so negative lobes are never renormalised.
//! * When the target is coarser than the source, bilinear and cubic kernels are widened by the
//!   scale ratio (as GDAL's warper does), so they low-pass instead of aliasing.
//! * `average` weights each source cell by its area of overlap with the target cell.

use crate::grid::Grid;
use crate::raster::{Colour, Elevation, Raster};
use rayon::prelude::*;
use std::ops::Range;

/// Fraction of a cell's full kernel weight that must come from valid samples.
pub const MIN_VALID_WEIGHT: f64 = 1e-5;

crate::choice! {
    /// How values are interpolated onto the target grid.
    #[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
    #[serde(rename_all = "lowercase")]
    pub enum Resampling {
        /// The source cell containing the target centre.
        Nearest = "nearest",
        /// Triangle kernel: bilinear interpolation between the four nearest centres.
        Bilinear = "bilinear",
        /// Keys cubic convolution (a = −0.5) over the 4×4 nearest centres.
        Cubic = "cubic",
        /// Area-weighted mean of the source cells the target cell overlaps.
        Average = "average",
    }
}

/// A list of `(source index, weight)` for one target index along one axis.
type Taps = Vec<(u32, f64)>;

/// The source index containing each target centre along one axis, if inside the source.
fn axis_homes(
    n_target: usize,
    n_source: usize,
    centre_px: impl Fn(usize) -> f64,
) -> Vec<Option<u32>> {
    (0..n_target)
        .map(|i| {
            let p = centre_px(i);
            (p >= 0.0 && p < n_source as f64).then_some(p.floor() as u32)
        })
        .collect()
}

/// The taps of every target index along one axis.
///
/// `centre_px(i)` is target index `i`'s centre in source pixel space (corner convention);
/// `scale` is target cell / source cell along this axis (> 1 when coarsening).
fn axis_taps(
    method: Resampling,
    n_target: usize,
    n_source: usize,
    scale: f64,
    centre_px: impl Fn(usize) -> f64,
) -> Vec<Taps> {
    let n = n_source as i64;
    let widen = scale.max(1.0);
    (0..n_target)
        .map(|i| {
            let p = centre_px(i);
            let inside = p >= 0.0 && p < n_source as f64;
            match method {
                Resampling::Nearest => {
                    if inside {
                        vec![(p.floor() as u32, 1.0)]
                    } else {
                        Vec::new()
                    }
                }
                Resampling::Bilinear | Resampling::Cubic if !inside => Vec::new(),
                Resampling::Bilinear => {
                    kernel_taps(p - 0.5, widen, 1.0, n, |x| (1.0 - x.abs()).max(0.0))
                }
                Resampling::Cubic => kernel_taps(p - 0.5, widen, 2.0, n, keys_cubic),
                Resampling::Average => {
                    let (lo, hi) = (p - scale / 2.0, p + scale / 2.0);
                    let first = lo.floor().max(0.0) as i64;
                    let last = (hi.ceil() as i64).min(n);
                    (first..last)
                        .filter_map(|j| {
                            let w = hi.min(j as f64 + 1.0) - lo.max(j as f64);
                            (w > 1e-12).then_some((j as u32, w))
                        })
                        .collect()
                }
            }
        })
        .collect()
}

/// Taps of a symmetric kernel of `radius` (in kernel units) centred at centre-space coordinate
/// `c`, widened by `widen` source pixels per kernel unit; source indices outside `0..n` are dropped.
fn kernel_taps(c: f64, widen: f64, radius: f64, n: i64, kernel: impl Fn(f64) -> f64) -> Taps {
    let reach = radius * widen;
    let first = (c - reach).ceil() as i64;
    let last = (c + reach).floor() as i64;
    (first..=last)
        .filter(|&j| (0..n).contains(&j))
        .filter_map(|j| {
            let w = kernel((j as f64 - c) / widen);
            (w != 0.0).then_some((j as u32, w))
        })
        .collect()
}

/// Keys (1981) cubic convolution kernel with a = −0.5, GDAL's `cubic`.
fn keys_cubic(x: f64) -> f64 {
    let x = x.abs();
    if x < 1.0 {
        (1.5 * x - 2.5) * x * x + 1.0
    } else if x < 2.0 {
        ((-0.5 * x + 2.5) * x - 4.0) * x + 2.0
    } else {
        0.0
    }
}

/// Per target cell along one axis, the source cell containing its centre (`None` off the source).
type Homes = Vec<Option<u32>>;

/// Per-axis taps from `src` onto `dst` for one method.
struct AxisTaps {
    cols: Vec<Taps>,
    rows: Vec<Taps>,
    /// Source cell containing each target centre, per axis; `None` for `average`, which has no home.
    homes: Option<(Homes, Homes)>,
}

impl AxisTaps {
    fn new(method: Resampling, src: &Grid, dst: &Grid) -> AxisTaps {
        let (st, dt) = (&src.transform, &dst.transform);
        let scale_x = (dt.cell_x / st.cell_x).abs();
        let scale_y = (dt.cell_y / st.cell_y).abs();
        let col_px =
            |c: usize| (dt.origin_x + (c as f64 + 0.5) * dt.cell_x - st.origin_x) / st.cell_x;
        let row_px =
            |r: usize| (dt.origin_y + (r as f64 + 0.5) * dt.cell_y - st.origin_y) / st.cell_y;
        let cols = axis_taps(method, dst.width, src.width, scale_x, col_px);
        let rows = axis_taps(method, dst.height, src.height, scale_y, row_px);
        let homes = (method != Resampling::Average).then(|| {
            (
                axis_homes(dst.width, src.width, col_px),
                axis_homes(dst.height, src.height, row_px),
            )
        });
        AxisTaps { cols, rows, homes }
    }

    /// Is the source cell containing target cell `(c, r)`'s centre valid (methods with a home)?
    fn home_valid<T>(
        &self,
        src: &Window<'_, T>,
        c: usize,
        r: usize,
        valid: impl Fn(&T) -> bool,
    ) -> bool {
        match &self.homes {
            None => true,
            Some((hx, hy)) => match (hx[c], hy[r]) {
                (Some(x), Some(y)) => valid(src.get(x as usize, y as usize)),
                _ => false,
            },
        }
    }

    /// The full (all-valid) weight of the taps of a cell, for the validity threshold.
    fn full_weight(xt: &Taps, yt: &Taps) -> f64 {
        xt.iter().map(|t| t.1).sum::<f64>() * yt.iter().map(|t| t.1).sum::<f64>()
    }

    /// The source rows target rows `rows` read (their row taps and home rows).
    fn source_rows(&self, rows: &Range<usize>) -> Range<usize> {
        let taps = self.rows[rows.clone()].iter().flatten().map(|t| t.0);
        let homes = self
            .homes
            .iter()
            .flat_map(|(_, hy)| hy[rows.clone()].iter().flatten().copied());
        let (lo, hi) = taps
            .chain(homes)
            .fold((u32::MAX, 0), |(lo, hi), y| (lo.min(y), hi.max(y + 1)));
        if lo < hi {
            lo as usize..hi as usize
        } else {
            0..0
        }
    }
}

/// Consecutive whole rows of a source raster: rows `row0 ..` of a grid `width` cells wide.
struct Window<'a, T> {
    data: &'a [T],
    width: usize,
    row0: usize,
}

impl<T> Window<'_, T> {
    /// Cell `(col, row)` in source coordinates; the row must be inside the window.
    fn get(&self, col: usize, row: usize) -> &T {
        &self.data[(row - self.row0) * self.width + col]
    }

    /// Source row `row`.
    fn row(&self, row: usize) -> &[T] {
        let start = (row - self.row0) * self.width;
        &self.data[start..start + self.width]
    }
}

/// Weighted sum of `N` channels over the taps of one cell, skipping invalid samples.
/// Returns the renormalised mean, or `None` when too little valid weight remains.
/// `all_valid` reports whether every tap was valid (for the cubic fallback).
#[inline]
fn accumulate<T, const N: usize>(
    src: &Window<'_, T>,
    xt: &Taps,
    yt: &Taps,
    sample: impl Fn(&T) -> Option<[f64; N]>,
) -> (Option<[f64; N]>, bool) {
    let mut acc = [0.0f64; N];
    let mut wsum = 0.0;
    let mut all_valid = true;
    for &(sy, wy) in yt {
        let row = src.row(sy as usize);
        for &(sx, wx) in xt {
            match sample(&row[sx as usize]) {
                Some(v) => {
                    let wt = wy * wx;
                    for k in 0..N {
                        acc[k] += wt * v[k];
                    }
                    wsum += wt;
                }
                None => all_valid = false,
            }
        }
    }
    let full = AxisTaps::full_weight(xt, yt);
    if full == 0.0 || wsum.abs() < MIN_VALID_WEIGHT * full.abs() {
        return (None, all_valid);
    }
    (Some(acc.map(|a| a / wsum)), all_valid)
}

/// Resampling from one grid onto another (same CRS) band by band, so neither raster has to be
/// whole in memory. The taps are planned once for the whole grids, so a band's cells are
/// bit-identical to the same cells resampled whole, whatever the band size.
pub struct Resampler {
    source: Grid,
    target: Grid,
    plan: AxisTaps,
    /// Cubic's bilinear fallback near nodata and edges.
    fallback: Option<AxisTaps>,
}

impl Resampler {
    /// Resample `source` onto `target` with `method`.
    pub fn new(method: Resampling, source: &Grid, target: &Grid) -> Resampler {
        Resampler {
            source: source.clone(),
            target: target.clone(),
            plan: AxisTaps::new(method, source, target),
            fallback: (method == Resampling::Cubic)
                .then(|| AxisTaps::new(Resampling::Bilinear, source, target)),
        }
    }

    /// The colour rule ([`colour_method`]) from `source` onto `target`.
    pub fn colour(source: &Grid, target: &Grid) -> Resampler {
        let (st, dt) = (&source.transform, &target.transform);
        let method = colour_method((dt.cell_x / st.cell_x).abs(), (dt.cell_y / st.cell_y).abs());
        Resampler::new(method, source, target)
    }

    /// The source rows that target rows `rows` read: pass at least these to
    /// [`elevation`](Self::elevation) or [`colours`](Self::colours). Empty when the rows lie
    /// outside the source.
    pub fn source_rows(&self, rows: Range<usize>) -> Range<usize> {
        let mut r = self.plan.source_rows(&rows);
        if let Some(fb) = &self.fallback {
            let f = fb.source_rows(&rows);
            if !f.is_empty() {
                r = if r.is_empty() {
                    f
                } else {
                    r.start.min(f.start)..r.end.max(f.end)
                };
            }
        }
        r
    }

    /// Target rows `rows` of elevation (metres, NaN = nodata) from `src`, source rows
    /// `src_row0 ..` (covering [`source_rows`](Self::source_rows)), row-major.
    pub fn elevation(&self, src: &[f32], src_row0: usize, rows: Range<usize>) -> Vec<f32> {
        let src = self.window(src, src_row0);
        let full_support = |xt: &Taps, yt: &Taps| xt.len() >= 4 && yt.len() >= 4;
        let sample = |v: &f32| (!v.is_nan()).then_some([*v as f64]);
        let w = self.target.width.max(1);
        let mut out = vec![f32::NAN; rows.len() * self.target.width];
        out.par_chunks_mut(w).enumerate().for_each(|(k, row)| {
            let r = rows.start + k;
            for (c, cell) in row.iter_mut().enumerate() {
                if !self.plan.home_valid(&src, c, r, |v| !v.is_nan()) {
                    continue;
                }
                let (xt, yt) = (&self.plan.cols[c], &self.plan.rows[r]);
                let (mut v, all_valid) = accumulate(&src, xt, yt, sample);
                if let Some(fb) = &self.fallback {
                    if !(all_valid && full_support(xt, yt)) {
                        v = accumulate(&src, &fb.cols[c], &fb.rows[r], sample).0;
                    }
                }
                *cell = v.map_or(f32::NAN, |v| v[0] as f32);
            }
        });
        out
    }

    /// Target rows `rows` of colour (alpha 0 = nodata; channel means rounded to nearest) from
    /// `src`, source rows `src_row0 ..`, as [`elevation`](Self::elevation).
    pub fn colours(&self, src: &[[u8; 4]], src_row0: usize, rows: Range<usize>) -> Vec<[u8; 4]> {
        let src = self.window(src, src_row0);
        let sample = |p: &[u8; 4]| (p[3] != 0).then(|| [p[0] as f64, p[1] as f64, p[2] as f64]);
        let w = self.target.width.max(1);
        let mut out = vec![[0u8; 4]; rows.len() * self.target.width];
        out.par_chunks_mut(w).enumerate().for_each(|(k, row)| {
            let r = rows.start + k;
            for (c, cell) in row.iter_mut().enumerate() {
                if !self.plan.home_valid(&src, c, r, |p| p[3] != 0) {
                    continue;
                }
                if let Some(v) = accumulate(&src, &self.plan.cols[c], &self.plan.rows[r], sample).0
                {
                    let q = |x: f64| (x + 0.5).floor().clamp(0.0, 255.0) as u8;
                    *cell = [q(v[0]), q(v[1]), q(v[2]), 255];
                }
            }
        });
        out
    }

    fn window<'a, T>(&self, data: &'a [T], row0: usize) -> Window<'a, T> {
        Window {
            data,
            width: self.source.width,
            row0,
        }
    }
}

/// Resample an elevation raster onto `dst` (same CRS). NaN is nodata in and out.
pub fn resample_elevation(src: &Elevation, dst: &Grid, method: Resampling) -> Elevation {
    let out = Resampler::new(method, &src.grid, dst).elevation(&src.data, 0, 0..dst.height);
    Raster::new(dst.clone(), out)
}

/// How the orthophoto is resampled, from the ratio of target to source cell size along x and y
/// (> 1 when coarsening): `Average` when the target is as coarse as the source or coarser on both
/// axes, `Bilinear` when it is finer. The one rule for native and reprojected photos.
pub fn colour_method(scale_x: f64, scale_y: f64) -> Resampling {
    if scale_x >= 1.0 - 1e-9 && scale_y >= 1.0 - 1e-9 {
        Resampling::Average
    } else {
        Resampling::Bilinear
    }
}

/// Resample colour onto `dst` (same CRS): area-weighted average where the target is as coarse
/// as the source or coarser, bilinear where it is finer. Alpha 0 is nodata in and out; channel
/// means round to nearest.
pub fn resample_colour(src: &Colour, dst: &Grid) -> Colour {
    let out = Resampler::colour(&src.grid, dst).colours(&src.data, 0, 0..dst.height);
    Raster::new(dst.clone(), out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::crs::Crs;
    use proptest::prelude::*;

    fn grid(x0: f64, y0: f64, cell: f64, w: usize, h: usize) -> Grid {
        Grid::north_up(x0, y0, cell, w, h, Crs::epsg(32632))
    }

    /// A plane z = a + b·x + c·y sampled at cell centres.
    fn plane(g: &Grid, a: f64, b: f64, c: f64) -> Elevation {
        let mut data = Vec::with_capacity(g.len());
        for r in 0..g.height {
            for col in 0..g.width {
                let (x, y) = g.cell_centre(col, r);
                data.push(
                    (a + b * (x - g.transform.origin_x) + c * (y - g.transform.origin_y)) as f32,
                );
            }
        }
        Raster::new(g.clone(), data)
    }

    #[test]
    fn bilinear_and_cubic_reproduce_a_plane_at_utm_coordinates() {
        let src = plane(
            &grid(500_000.0, 5_300_000.0, 1.0, 20, 20),
            100.0,
            0.1,
            -0.05,
        );
        let dst = grid(500_002.0, 5_299_998.0, 0.25, 60, 60);
        for m in [Resampling::Bilinear, Resampling::Cubic] {
            let out = resample_elevation(&src, &dst, m);
            let truth = plane(&dst, 100.0, 0.1, -0.05 * 1.0);
            // The truth plane is anchored at src's origin; shift it.
            let off = 0.1 * (dst.transform.origin_x - src.grid.transform.origin_x)
                - 0.05 * (dst.transform.origin_y - src.grid.transform.origin_y);
            for (o, t) in out.data.iter().zip(&truth.data) {
                assert!(
                    (*o as f64 - (*t as f64 + off)).abs() < 1e-3,
                    "{m:?}: {o} vs {}",
                    *t as f64 + off
                );
            }
        }
    }

    #[test]
    fn nodata_never_enters_and_centres_on_nodata_stay_nodata() {
        let g = grid(0.0, 4.0, 1.0, 4, 4);
        let mut src = Raster::filled(g.clone(), 10.0f32);
        *src.get_mut(1, 1) = f32::NAN;
        *src.get_mut(2, 1) = 1e30; // a huge valid value next to the hole: must not leak into it
        for m in [Resampling::Nearest, Resampling::Bilinear, Resampling::Cubic] {
            let same = resample_elevation(&src, &g, m);
            assert!(same.get(1, 1).is_nan(), "{m:?}");
            assert_eq!(*same.get(0, 0), 10.0, "{m:?}");
        }
        // A target cell between the hole and valid cells takes only valid values.
        let half = grid(0.0, 4.0, 0.5, 8, 8);
        let out = resample_elevation(
            &Raster::new(g.clone(), {
                let mut d = vec![10.0f32; 16];
                d[5] = f32::NAN;
                d
            }),
            &half,
            Resampling::Bilinear,
        );
        assert!(out.data.iter().all(|v| v.is_nan() || *v == 10.0));
    }

    #[test]
    fn outside_the_source_is_nodata_not_extrapolated() {
        let src = Raster::filled(grid(0.0, 4.0, 1.0, 4, 4), 5.0f32);
        let dst = grid(-2.0, 6.0, 1.0, 8, 8);
        for m in [
            Resampling::Nearest,
            Resampling::Bilinear,
            Resampling::Cubic,
            Resampling::Average,
        ] {
            let out = resample_elevation(&src, &dst, m);
            assert_eq!(out.data.iter().filter(|v| !v.is_nan()).count(), 16, "{m:?}");
            assert!(out.get(0, 0).is_nan() && *out.get(2, 2) == 5.0);
        }
    }

    #[test]
    fn colour_average_is_exact_area_mean_and_ignores_nodata() {
        let g = grid(0.0, 2.0, 1.0, 2, 2);
        let src = Raster::new(
            g,
            vec![
                [0, 0, 0, 255],
                [255, 255, 255, 255],
                [100, 50, 0, 255],
                [9, 9, 9, 0],
            ],
        );
        let out = resample_colour(&src, &grid(0.0, 2.0, 2.0, 1, 1));
        // Mean of the three valid cells: r (0+255+100)/3 = 118.3, g 305/3 = 101.7, b 255/3 = 85.
        assert_eq!(out.data[0], [118, 102, 85, 255]);
        let copy = resample_colour(&src, &src.grid);
        assert_eq!(
            copy.data,
            src.data
                .iter()
                .map(|p| if p[3] == 0 { [0; 4] } else { *p })
                .collect::<Vec<_>>()
        );
    }

    proptest! {
        /// Band by band, each band given only the source rows it asks for, is the whole result
        /// bit for bit: every method, refining and coarsening, grids offset from each other.
        #[test]
        fn banded_resampling_equals_whole(
            method in 0usize..4, cell in 0.2f64..3.0, dx in -3.0f64..3.0, dy in -3.0f64..3.0,
            band in 1usize..9, seed in 0u64..1000,
        ) {
            let method = [Resampling::Nearest, Resampling::Bilinear, Resampling::Cubic, Resampling::Average][method];
            let sg = grid(500_000.0, 5_000_000.0, 1.0, 23, 17);
            let dg = grid(500_000.0 + dx, 5_000_000.0 + dy, cell, (23.0 / cell) as usize + 1, (17.0 / cell) as usize + 1);
            let mut s = seed | 1;
            let mut next = || { s ^= s << 13; s ^= s >> 7; s ^= s << 17; s };
            let z: Vec<f32> = (0..sg.len()).map(|_| { let v = next(); if v % 9 == 0 { f32::NAN } else { (v % 5000) as f32 * 0.1 } }).collect();
            let c: Vec<[u8; 4]> = (0..sg.len()).map(|_| { let v = next(); [v as u8, (v >> 8) as u8, (v >> 16) as u8, if v % 7 == 0 { 0 } else { 255 }] }).collect();
            let whole_z = resample_elevation(&Raster::new(sg.clone(), z.clone()), &dg, method);
            let whole_c = resample_colour(&Raster::new(sg.clone(), c.clone()), &dg);
            let (rz, rc) = (Resampler::new(method, &sg, &dg), Resampler::colour(&sg, &dg));
            let (mut bz, mut bc) = (Vec::new(), Vec::new());
            for r0 in (0..dg.height).step_by(band) {
                let rows = r0..(r0 + band).min(dg.height);
                let src = rz.source_rows(rows.clone());
                bz.extend(rz.elevation(&z[src.start * 23..src.end * 23], src.start, rows.clone()));
                let src = rc.source_rows(rows.clone());
                bc.extend(rc.colours(&c[src.start * 23..src.end * 23], src.start, rows));
            }
            prop_assert!(bz.iter().zip(&whole_z.data).all(|(a, b)| a.to_bits() == b.to_bits()));
            prop_assert_eq!(bz.len(), whole_z.data.len());
            prop_assert_eq!(bc, whole_c.data);
        }

        /// Aligned integer coarsening by `average` is the plain block mean of the valid cells.
        #[test]
        fn average_coarsening_is_the_block_mean(f in 1usize..5, w in 1usize..6, h in 1usize..6, seed in 0u64..1000) {
            let g = grid(500_000.0, 5_000_000.0, 0.5, w * f, h * f);
            let mut s = seed;
            let data: Vec<f32> = (0..g.len()).map(|_| {
                s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                if s >> 60 == 0 { f32::NAN } else { ((s >> 40) % 1000) as f32 / 10.0 }
            }).collect();
            let src = Raster::new(g, data);
            let out = resample_elevation(&src, &grid(500_000.0, 5_000_000.0, 0.5 * f as f64, w, h), Resampling::Average);
            for r in 0..h { for c in 0..w {
                let vals: Vec<f64> = (0..f).flat_map(|dy| (0..f).map(move |dx| (dx, dy)))
                    .map(|(dx, dy)| *src.get(c * f + dx, r * f + dy) as f64).filter(|v| !v.is_nan()).collect();
                let got = *out.get(c, r);
                if vals.is_empty() { prop_assert!(got.is_nan()); }
                else { prop_assert!((got as f64 - vals.iter().sum::<f64>() / vals.len() as f64).abs() < 1e-3); }
            }}
        }
    }
}
