//! Input rasters read band by band, so a stage can stream an input larger than memory.
//!
//! Invariant: [`RasterInput::rows`] returns exactly what [`super::read_raster`]
//! would hold for those rows — same samples, same metadata, the rows' sub-grid — whether the
//! file is decoded band by band or was read whole.

use super::mosaic::{is_mosaic, Mosaic};
use super::{geotiff, kind_of, read_raster, Kind, SourceRaster};
use crate::error::{Error, Result};
use crate::grid::{Grid, Window};
use std::borrow::Cow;
use std::ops::Range;
use std::path::Path;

/// An input raster opened for reading by rows. A GeoTIFF whose strips or tiles decode one by
/// one (uncompressed, LZW or Deflate) is decoded band by band on demand: memory is the band's.
/// Anything else (ASCII grids, PNG/JPEG with a world file, other TIFF codecs, GDAL's formats) is
/// read whole once, as [`super::read_raster`] reads it.
pub struct RasterInput {
    /// The whole raster, or for a streamed GeoTIFF its first row (whose metadata — path, bands,
    /// nodata, alpha band, format, PixelIsPoint — are the file's).
    head: SourceRaster,
    /// The whole raster's grid.
    grid: Grid,
    /// Rows are decoded from the file on demand.
    streamed: bool,
    /// Tiles read as one ([`Mosaic`]); then `head` and `grid` are the mosaic's.
    mosaic: Option<Box<Mosaic>>,
}

impl RasterInput {
    /// Open `path` (any format [`super::read_raster`] reads, or a directory or list file of
    /// tiles: [`super::mosaic`]), checking its header and georeference now.
    pub fn open(path: &Path) -> Result<RasterInput> {
        if is_mosaic(path) {
            let mosaic = Mosaic::open(path)?;
            return Ok(RasterInput {
                head: mosaic.meta().clone_meta(),
                grid: mosaic.grid().clone(),
                streamed: true,
                mosaic: Some(Box::new(mosaic)),
            });
        }
        if kind_of(path)?.0 == Kind::Tiff {
            if let Some(height) = chunked_height(path) {
                let head = geotiff::read_rows(path, 0..1)?;
                let grid = Grid {
                    height,
                    ..head.grid.clone()
                };
                return Ok(RasterInput {
                    head,
                    grid,
                    streamed: true,
                    mosaic: None,
                });
            }
        }
        let head = read_raster(path)?;
        Ok(RasterInput {
            grid: head.grid.clone(),
            head,
            streamed: false,
            mosaic: None,
        })
    }

    /// The whole raster's grid (size, corner-convention geotransform, CRS).
    pub fn grid(&self) -> &Grid {
        &self.grid
    }

    /// The file's metadata: path, bands, nodata, alpha band, format, PixelIsPoint. Its samples
    /// and grid are those of the first row only when the input is streamed: use
    /// [`grid`](Self::grid) and [`rows`](Self::rows) for the data.
    pub fn meta(&self) -> &SourceRaster {
        &self.head
    }

    /// The files read: the file itself, or a mosaic's tiles.
    pub fn files(&self) -> Vec<std::path::PathBuf> {
        match &self.mosaic {
            Some(m) => m.files(),
            None => vec![self.head.path.clone()],
        }
    }

    /// Rows `rows` (all columns), on their sub-grid. Rows beyond the raster are an error.
    pub fn rows(&self, rows: Range<usize>) -> Result<Cow<'_, SourceRaster>> {
        let (w, h) = (self.grid.width, self.grid.height);
        if rows.start > rows.end || rows.end > h {
            return Err(Error::file(
                &self.head.path,
                format!(
                    "internal: rows {}..{} of a raster of {h} rows",
                    rows.start, rows.end
                ),
            ));
        }
        if let Some(m) = &self.mosaic {
            return Ok(Cow::Owned(m.rows(rows)?));
        }
        if self.streamed && !rows.is_empty() {
            return Ok(Cow::Owned(geotiff::read_rows(&self.head.path, rows)?));
        }
        if rows == (0..h) {
            return Ok(Cow::Borrowed(&self.head));
        }
        // A slice of the whole raster (or, streamed, an empty band: no samples from row 0).
        let b = self.head.bands;
        let samples = match self.streamed {
            true => self.head.samples.slice(0..0),
            false => self
                .head
                .samples
                .slice(rows.start * w * b..rows.end * w * b),
        };
        let window = Window {
            col: 0,
            row: rows.start,
            width: w,
            height: rows.len(),
        };
        Ok(Cow::Owned(SourceRaster {
            grid: self.grid.window_grid(&window),
            samples,
            ..self.head.clone_meta()
        }))
    }
}

/// The height of a TIFF whose strips or tiles decode one by one ([`super::chunks`]); `None`
/// when its layout must be decoded whole, or when its header does not read (the whole read
/// then reports the problem in the words every reader uses).
fn chunked_height(path: &Path) -> Option<usize> {
    let file = super::open_regular(path).ok()?;
    let mut dec = tiff::decoder::Decoder::new(std::io::BufReader::new(file)).ok()?;
    let height = dec.dimensions().ok()?.1 as usize;
    super::chunks::layout(&mut dec).ok()?.map(|_| height)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::crs::Crs;
    use crate::raster::Raster;

    /// Rows from a streamed GeoTIFF and from a whole ASCII grid equal the whole file's rows.
    #[test]
    fn rows_equal_the_whole_files_rows() {
        let dir = tempfile::tempdir().unwrap();
        let g = Grid::north_up(500_000.0, 5_000_000.0, 2.0, 7, 300, Crs::epsg(32614));
        let z: Vec<f32> = (0..g.len()).map(|i| (i % 101) as f32).collect();
        let tif = dir.path().join("z.tif");
        geotiff::write_f32(&tif, &Raster::new(g.clone(), z)).unwrap();
        let asc = dir.path().join("z.asc");
        let mut text = String::from("ncols 3\nnrows 4\nxllcorner 0\nyllcorner 0\ncellsize 1\n");
        for r in 0..4 {
            text += &format!("{} {} {}\n", r, r + 10, r + 20);
        }
        std::fs::write(&asc, text).unwrap();
        for (path, streamed) in [(&tif, true), (&asc, false)] {
            let input = RasterInput::open(path).unwrap();
            assert_eq!(input.streamed, streamed);
            let whole = read_raster(path).unwrap();
            assert_eq!(input.grid(), &whole.grid);
            let h = whole.grid.height;
            for rows in [0..h, 0..1, 1..3, h - 1..h, 2..2] {
                let got = input.rows(rows.clone()).unwrap();
                let n = whole.grid.width * whole.bands;
                assert_eq!(
                    got.samples,
                    whole.samples.slice(rows.start * n..rows.end * n)
                );
                assert_eq!(got.grid.height, rows.len());
                let (x, y) = whole.grid.transform.pixel_to_world(0.0, rows.start as f64);
                assert_eq!(
                    (got.grid.transform.origin_x, got.grid.transform.origin_y),
                    (x, y)
                );
                assert_eq!(
                    (got.nodata, got.bands, got.format),
                    (whole.nodata, whole.bands, whole.format)
                );
            }
            assert!(input.rows(0..h + 1).is_err());
        }
    }
}
