//! Tile sets made from a height-and-colour function: analytic scenes for tests and benchmarks.
//!
//! Invariant: the levels are built by the pyramid's own cascade ([`build_levels`]) from level-0
//! cells the function defines, so a synthetic tile set obeys every rule a real one does (exact
//! coarse maxima, averaged colours, nodata padding, voxel columns in the level-0 bricks) while
//! its hits are known analytically.

use crate::error::Result;
use crate::grid::Grid;
use crate::pyramid::cascade::{build_levels, Band};
use crate::pyramid::reduce::BaseRows;
use crate::tiles::{Compression, TileSetInfo, TileWriter, STATE_OPAQUE, STATE_PARTIAL};
use crate::voxel::columns::Run;
use rayon::prelude::*;
use std::path::Path;

/// Write the tile set over `grid` (pages of `page_size²` cells, levels `factor` apart) whose
/// level-0 cell `(col, row)` is the column `cell(col, row) = (max_z metres, RGBA colour)`; a NaN
/// height is nodata. Memory stays at one page-row of level 0.
pub fn write_tiles<F>(
    path: &Path,
    grid: Grid,
    page_size: usize,
    factor: usize,
    compression: Compression,
    cell: F,
) -> Result<()>
where
    F: Fn(usize, usize) -> (f32, [u8; 4]) + Sync,
{
    write_bands(
        path,
        grid,
        page_size,
        factor,
        compression,
        |width, row0, rows| {
            let mut band = BaseRows::nodata(width, rows);
            band.max_z
                .par_chunks_mut(width)
                .zip(band.colour.par_chunks_mut(width))
                .zip(band.state.par_chunks_mut(width))
                .enumerate()
                .for_each(|(r, ((zs, cs), ss))| {
                    for col in 0..width {
                        let (z, c) = cell(col, row0 + r);
                        if !z.is_nan() {
                            zs[col] = z;
                            cs[col] = [c[0], c[1], c[2], 255];
                            ss[col] = STATE_OPAQUE;
                        }
                    }
                });
            band.into()
        },
    )
}

/// Like [`write_tiles`], with each level-0 cell given as its voxel column: no runs = nodata,
/// one run (the ground, bottom `−inf`) = a height-field column, more = a partial cell whose runs
/// go into the page's bricks. The colour of a cell is its top run's.
pub fn write_columns<F>(
    path: &Path,
    grid: Grid,
    page_size: usize,
    factor: usize,
    cell: F,
) -> Result<()>
where
    F: Fn(usize, usize) -> Vec<Run> + Sync,
{
    write_bands(
        path,
        grid,
        page_size,
        factor,
        Compression::None,
        |width, row0, rows| {
            let mut band = Band::from(BaseRows::nodata(width, rows));
            for i in 0..width * rows {
                let runs = cell(i % width, row0 + i / width);
                let Some(top) = runs.last() else { continue };
                band.rows.max_z[i] = top.top;
                band.rows.colour[i] = top.colour;
                band.rows.state[i] = if runs.len() > 1 {
                    STATE_PARTIAL
                } else {
                    STATE_OPAQUE
                };
                if runs.len() > 1 {
                    band.columns.push((i, runs));
                }
            }
            band
        },
    )
}

/// Write a tile set whose level-0 band `(width, row0, rows)` is `band`'s.
fn write_bands<B>(
    path: &Path,
    grid: Grid,
    page_size: usize,
    factor: usize,
    compression: Compression,
    band: B,
) -> Result<()>
where
    B: Fn(usize, usize, usize) -> Band + Sync,
{
    let mut info = TileSetInfo::new(grid, page_size, factor, None)?;
    info.compression = compression;
    let width = info.grid.width;
    let writer = TileWriter::create(path, info.clone())?;
    build_levels(
        &info,
        |row0, rows| Ok(band(width, row0, rows)),
        &|level, tx, ty, page| writer.write_page(level, tx, ty, page),
    )?;
    writer.finish()
}
