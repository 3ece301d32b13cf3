//! The exact reference cast: march every cell's ray through the columns it crosses.

use super::{check_grid, Sun, LIT, NODATA, SHADOW};
use crate::error::Result;
use crate::raster::{Elevation, Raster};
use crate::walk::{Corner, Walk};
use rayon::prelude::*;

/// Cast shadows by marching each valid cell's ray toward the sun cell by cell (the shared
/// [`crate::walk::Walk`], in metres along the ray), exactly as the module's model states:
/// shadowed when, at the point nearest a crossed valid cell's centre, the ray is below that
/// cell's height. A ray through a cell corner (within [`crate::walk::CORNER_EPS`] cells)
/// steps diagonally, touching neither side cell ([`Corner::Diagonal`]: a side cell meets the
/// ray at one point, which is not a crossing). Stops a ray once it is above the highest cell.
/// Cost O(n · shadow length in cells): a check for [`super::cast_shadows`], not a production
/// path. Same errors.
pub fn cast_shadows_reference(height: &Elevation, sun: &Sun) -> Result<Raster<u8>> {
    let grid = &height.grid;
    check_grid(&height.data, grid)?;
    let top = height
        .min_max()
        .map_or(f64::NEG_INFINITY, |(_, hi)| hi as f64);
    let tan_e = sun.elevation_deg.to_radians().tan();
    let (east, north) = sun.direction();
    // Cells per metre toward the sun, along columns and rows.
    let (dc, dr) = (east / grid.transform.cell_x, north / grid.transform.cell_y);
    let (w, h) = (grid.width as isize, grid.height as isize);
    let (cell_x, cell_y) = (grid.transform.cell_x, grid.transform.cell_y);
    // A crossed cell's centre is at most half a diagonal behind the ray's entry point.
    let half_diagonal = 0.5 * cell_x.hypot(cell_y);
    let mut data = vec![NODATA; grid.len()];
    data.par_chunks_mut(grid.width.max(1))
        .enumerate()
        .for_each(|(row, out)| {
            for (col, v) in out.iter_mut().enumerate() {
                let z0 = *height.get(col, row);
                if z0.is_nan() {
                    continue;
                }
                let z0 = z0 as f64;
                let mut shadowed = false;
                if sun.elevation_deg < 90.0 {
                    let centre = [col as f64 + 0.5, row as f64 + 0.5];
                    // The cells after the start one, each with the metres at which it is entered.
                    let walk = Walk::new(centre, [dc, dr], Corner::Diagonal).skip(1);
                    for visit in walk {
                        let ([c, r], t) = (visit.cell.map(|i| i as isize), visit.t_in);
                        if c < 0 || r < 0 || c >= w || r >= h {
                            break;
                        }
                        if z0 + (t - half_diagonal) * tan_e > top {
                            break;
                        }
                        // Metres along the ray to the point nearest the cell's centre.
                        let d = (c - col as isize) as f64 * cell_x * east
                            + (r - row as isize) as f64 * cell_y * north;
                        if z0 + d * tan_e < *height.get(c as usize, r as usize) as f64 {
                            shadowed = true;
                            break;
                        }
                    }
                }
                *v = if shadowed { SHADOW } else { LIT };
            }
        });
    Ok(Raster::new(grid.clone(), data))
}
