//! A land-cover raster's class codes at the database's cells: the pixel holding each cell's
//! centre (nearest neighbour: class codes are labels, never averaged).
//!
//! The raster may be in the database's CRS, or geographic (longitude/latitude, as ESA
//! WorldCover is distributed) over a database whose CRS converts to latitude/longitude (UTM);
//! anything else is refused with the `gdalwarp` command that fixes it.
//!
//! Invariant: a cell gets `Some(code)` only from a pixel that contains its centre and holds a
//! non-nodata, integer, non-negative value; every other cell gets `None` (its material comes
//! from the next source).

use crate::error::{Error, Result};
use crate::grid::Grid;
use rayon::prelude::*;
use std::path::Path;

/// The class code under each cell centre of `grid` (row-major), from the land-cover raster
/// `path` (band 1); `None` outside the raster and on its nodata. A raster without a CRS over a
/// grid with one, or one under no cell centre of the grid, is refused.
pub fn sample_codes(path: &Path, grid: &Grid) -> Result<Vec<Option<u32>>> {
    let raster = crate::io::read_raster(path)?;
    let src = &raster.grid;
    let geographic = is_geographic(path, src, grid)?;
    // The raster's pixel holding cell `i`'s centre, if any.
    let pixel_of = |i: usize| {
        let (x, y) = grid.cell_centre(i % grid.width, i / grid.width);
        let at = match geographic {
            false => Some((x, y)),
            true => grid.crs.to_lat_lon(x, y).map(|(lat, lon)| (lon, lat)),
        };
        at.and_then(|(x, y)| src.cell_at(x, y))
    };
    if !(0..grid.len())
        .into_par_iter()
        .any(|i| pixel_of(i).is_some())
    {
        return Err(Error::file(
            path,
            format!(
                "covers {} ({}), no cell of the database's {} ({})",
                src.bounds(),
                src.crs.name(),
                grid.bounds(),
                grid.crs.name()
            ),
        )
        .fix("give the land cover of the database's area"));
    }
    let band = raster.bands;
    let is_nodata = |v: f64| {
        raster
            .nodata
            .is_some_and(|n| n == v || (n.is_nan() && v.is_nan()))
    };
    // Each cell's pixel value, when its centre is on the raster: a code, nodata, or (Err) a
    // value no class raster holds. Only the pixels under the grid are judged.
    let sampled: Vec<std::result::Result<Option<u32>, f64>> = (0..grid.len())
        .into_par_iter()
        .map(|i| {
            let Some((col, row)) = pixel_of(i) else {
                return Ok(None);
            };
            let v = raster.samples.get(src.index(col, row) * band);
            match () {
                _ if is_nodata(v) => Ok(None),
                _ if v >= 0.0 && v.fract() == 0.0 && v <= u32::MAX as f64 => Ok(Some(v as u32)),
                _ => Err(v),
            }
        })
        .collect();
    if let Some(bad) = sampled.iter().find_map(|r| r.err()) {
        return Err(Error::file(
            path,
            format!("holds {bad}, not a class code (land cover holds non-negative integers)"),
        )
        .fix(
            "give a land-cover class raster (e.g. ESA WorldCover or NLCD), or set its nodata value",
        ));
    }
    Ok(sampled.into_iter().map(|r| r.unwrap_or(None)).collect())
}

/// Whether the land cover `path` on `src` is sampled through longitude/latitude (a geographic
/// raster over a grid whose CRS converts to them) rather than in the grid's own CRS. Refused: a
/// raster without a CRS over a grid with one ([`crate::io::no_crs`]: never assumed), and any
/// other CRS, with the `gdalwarp` that fixes it.
fn is_geographic(path: &Path, src: &Grid, grid: &Grid) -> Result<bool> {
    if src.crs.is_unknown() && !grid.crs.is_unknown() {
        return Err(crate::io::no_crs(path, "database", &grid.crs));
    }
    if src.crs.same_as(&grid.crs) {
        return Ok(false);
    }
    let (x, y) = grid.centre();
    if src.crs.geographic && grid.crs.to_lat_lon(x, y).is_some() {
        return Ok(true);
    }
    Err(Error::file(
        path,
        format!(
            "the land cover is in {}, the database in {}",
            src.crs.name(),
            grid.crs.name()
        ),
    )
    .fix(format!(
        "warp it onto the database's CRS with nearest or mode resampling: gdalwarp -t_srs {} -r mode {} out.tif",
        grid.crs.epsg.map_or("<the database's CRS>".into(), |c| format!("EPSG:{c}")),
        path.display()
    )))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::crs::Crs;
    use crate::io::geotiff;
    use crate::raster::Raster;

    #[test]
    fn nearest_pixel_nodata_and_outside() {
        let t = tempfile::tempdir().unwrap();
        // 4 × 2 pixels of 10 m; nodata 0 in the last one.
        let lc_grid = Grid::north_up(500_000.0, 5_300_020.0, 10.0, 4, 2, Crs::epsg(32632));
        let lc = Raster::new(lc_grid, vec![10, 20, 30, 40, 50, 60, 80, 0]);
        let path = t.path().join("lc.tif");
        geotiff::write_u8(&path, &lc, Some(0)).unwrap();
        // Cells of 4 m from 4 m west of the raster: the first column is outside it.
        let db = Grid::north_up(499_996.0, 5_300_020.0, 4.0, 11, 5, Crs::epsg(32632));
        let codes = sample_codes(&path, &db).unwrap();
        let at = |c: usize, r: usize| codes[db.index(c, r)];
        assert_eq!(at(0, 0), None); // centre x 499 998: outside
        assert_eq!(at(1, 0), Some(10)); // centre 500 002
        assert_eq!(at(3, 0), Some(20)); // centre 500 010: on the pixel edge, the east pixel
        assert_eq!(at(10, 0), Some(40)); // centre 500 038
        assert_eq!(at(1, 3), Some(50)); // centre y 5 300 006: second row
        assert_eq!(at(10, 3), None); // nodata
        assert_eq!(at(1, 2), Some(50)); // centre y 5 300 010: on the row edge, the south pixel
        assert_eq!(at(1, 4), Some(50));
    }

    /// A lon/lat raster (as WorldCover ships) over a UTM database: each cell centre goes to
    /// latitude and longitude first.
    #[test]
    fn geographic_land_cover_over_utm() {
        let t = tempfile::tempdir().unwrap();
        let db = Grid::north_up(499_000.0, 5_301_000.0, 100.0, 20, 20, Crs::epsg(32632));
        let (lat, lon) = db.crs.to_lat_lon(500_000.0, 5_300_000.0).unwrap();
        // 2 × 2 pixels of 0.1° with their shared corner at the database's centre.
        let lc_grid = Grid::north_up(lon - 0.1, lat + 0.1, 0.1, 2, 2, Crs::epsg(4326));
        let path = t.path().join("lc.tif");
        geotiff::write_u8(&path, &Raster::new(lc_grid, vec![10, 20, 30, 40]), None).unwrap();
        let codes = sample_codes(&path, &db).unwrap();
        // Cells (9, 9) and (10, 10) are the centre's north-west and south-east neighbours
        // (on the central meridian, so grid north is true north).
        assert_eq!(codes[db.index(9, 9)], Some(10));
        assert_eq!(codes[db.index(10, 9)], Some(20));
        assert_eq!(codes[db.index(9, 10)], Some(30));
        assert_eq!(codes[db.index(10, 10)], Some(40));
        // Another projected CRS is refused with the gdalwarp that fixes it.
        let other = Grid::north_up(0.0, 100.0, 10.0, 2, 2, Crs::epsg(32633));
        geotiff::write_u8(&path, &Raster::new(other, vec![1, 2, 3, 4]), None).unwrap();
        let e = sample_codes(&path, &db).unwrap_err().to_string();
        assert!(e.contains("gdalwarp -t_srs EPSG:32632"), "{e}");
    }

    #[test]
    fn non_integer_values_are_refused() {
        let t = tempfile::tempdir().unwrap();
        let g = Grid::north_up(500_000.0, 5_300_010.0, 10.0, 1, 1, Crs::epsg(32632));
        let path = t.path().join("lc.tif");
        geotiff::write_f32(&path, &Raster::new(g.clone(), vec![1.5f32])).unwrap();
        let e = sample_codes(&path, &g).unwrap_err().to_string();
        assert!(e.contains("not a class code"), "{e}");
    }
}
