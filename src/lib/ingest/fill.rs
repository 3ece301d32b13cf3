//! Filling DEM voids (`--fill-voids`) by linear interpolation over a Delaunay triangulation.
//!
//! The valid cells that border a void (8-neighbourhood) are triangulated (spade); each void
//! cell takes the barycentric interpolation of the triangle containing its centre. The result is
//! continuous with the surrounding terrain and never overshoots it. Void cells outside the
//! convex hull of the border cells (a void that reaches the grid edge beyond any data) stay
//! nodata: we do not extrapolate.

use crate::raster::Elevation;
use rayon::prelude::*;
use spade::{DelaunayTriangulation, FloatTriangulation, HasPosition, Point2, Triangulation};

/// A valid border cell: its centre in cell units and its height.
struct Sample {
    at: Point2<f64>,
    z: f64,
}

impl HasPosition for Sample {
    type Scalar = f64;
    fn position(&self) -> Point2<f64> {
        self.at
    }
}

/// Fill the voids (NaN cells) of `dem` in place; returns how many cells were filled.
/// Works in cell-index space, so the triangulation is well conditioned at any CRS offset.
pub fn fill_voids(dem: &mut Elevation) -> usize {
    let (w, h) = (dem.width(), dem.height());
    let nan = |c: i64, r: i64| {
        c >= 0 && r >= 0 && c < w as i64 && r < h as i64 && dem.get(c as usize, r as usize).is_nan()
    };
    let mut border = Vec::new();
    for r in 0..h as i64 {
        for c in 0..w as i64 {
            let v = *dem.get(c as usize, r as usize);
            if v.is_nan() {
                continue;
            }
            let touches_void = (-1..=1).any(|dy| (-1..=1).any(|dx| nan(c + dx, r + dy)));
            if touches_void {
                border.push(Sample {
                    at: Point2::new(c as f64, r as f64),
                    z: v as f64,
                });
            }
        }
    }
    if border.len() < 3 {
        return 0;
    }
    let Ok(tri) = DelaunayTriangulation::<Sample>::bulk_load(border) else {
        return 0;
    };
    let filled: Vec<(usize, f32)> = dem
        .data
        .par_iter()
        .enumerate()
        .filter(|(_, v)| v.is_nan())
        .map_init(
            || tri.barycentric(),
            |bary, (i, _)| {
                let p = Point2::new((i % w) as f64, (i / w) as f64);
                bary.interpolate(|v| v.data().z, p).map(|z| (i, z as f32))
            },
        )
        .flatten()
        .collect();
    for &(i, z) in &filled {
        dem.data[i] = z;
    }
    filled.len()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::crs::Crs;
    use crate::grid::Grid;
    use crate::raster::Raster;

    #[test]
    fn fills_an_interior_hole_exactly_on_a_plane() {
        let g = Grid::north_up(500_000.0, 5_000_000.0, 1.0, 12, 10, Crs::epsg(32632));
        let z = |c: usize, r: usize| 100.0 + 0.5 * c as f32 - 0.25 * r as f32;
        let mut dem = Raster::new(g, (0..120).map(|i| z(i % 12, i / 12)).collect());
        for (c, r) in [(4, 4), (5, 4), (4, 5), (5, 5), (6, 5)] {
            *dem.get_mut(c, r) = f32::NAN;
        }
        assert_eq!(fill_voids(&mut dem), 5);
        for r in 0..10 {
            for c in 0..12 {
                assert!((dem.get(c, r) - z(c, r)).abs() < 1e-4);
            }
        }
    }

    #[test]
    fn a_void_beyond_all_data_stays_nodata() {
        let g = Grid::north_up(0.0, 5.0, 1.0, 5, 5, Crs::unknown());
        let mut dem = Raster::filled(g, f32::NAN);
        *dem.get_mut(0, 0) = 1.0;
        *dem.get_mut(1, 0) = 2.0;
        // Two points: no triangle, nothing filled, nothing invented.
        assert_eq!(fill_voids(&mut dem), 0);
        assert_eq!(dem.nodata_count(), 23);
        // A corner void outside the hull of the data stays nodata.
        let g = Grid::north_up(0.0, 5.0, 1.0, 5, 5, Crs::unknown());
        let mut dem = Raster::filled(g, 7.0f32);
        *dem.get_mut(4, 4) = f32::NAN;
        *dem.get_mut(2, 2) = f32::NAN;
        assert_eq!(fill_voids(&mut dem), 1);
        assert_eq!(*dem.get(2, 2), 7.0);
        assert!(dem.get(4, 4).is_nan());
    }
}
