//! Tile sets made from a height-and-colour function: analytic scenes for tests and benchmarks.
//!
//! Invariant: the levels are built by the pyramid's own cascade ([`build_levels`]) from level-0
//! cells the function defines, so a synthetic tile set obeys every rule a real one does (exact
//! coarse maxima, averaged colours, nodata padding) while its hits are known analytically.

use crate::error::Result;
use crate::grid::Grid;
use crate::pyramid::cascade::build_levels;
use crate::pyramid::reduce::BaseRows;
use crate::tiles::{Compression, TileSetInfo, TileWriter, STATE_OPAQUE};
use rayon::prelude::*;
use std::path::Path;

/// Write the tile set over `grid` (pages of `page_size²` cells, levels `factor` apart) whose
/// level-0 cell `(col, row)` is the column `cell(col, row) = (max_z metres, RGBA colour)`; a NaN
/// height is nodata. Memory stays at one page-row of level 0.
pub fn write_tiles<F>(path: &Path, grid: Grid, page_size: usize, factor: usize, compression: Compression, cell: F) -> Result<()>
where
    F: Fn(usize, usize) -> (f32, [u8; 4]) + Sync,
{
    let mut info = TileSetInfo::new(grid, page_size, factor, None)?;
    info.compression = compression;
    let width = info.grid.width;
    let writer = TileWriter::create(path, info.clone())?;
    build_levels(
        &info,
        |row0, rows| {
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
            Ok(band)
        },
        &|level, tx, ty, page| writer.write_page(level, tx, ty, page),
    )?;
    writer.finish()
}
