//! GeoTIFF reading (any layout the `tiff` crate decodes) and writing (our three layer kinds).
//!
//! This module reads the pixels; `geokeys` turns the georeferencing tags into a [`Crs`] and a
//! grid (and writes them), `mask` reads an internal mask on the shared chunk walk
//! (`io::chunks`), `write` holds the writers.
//!
//! # Invariant
//! [`read`] returns the corner-convention grid GDAL reports for the same file: ModelTiepoint +
//! ModelPixelScale or a non-rotated ModelTransformation, shifted by half a cell when
//! GTRasterTypeGeoKey says PixelIsPoint (GDAL's default, `GTIFF_POINT_GEO_IGNORE=NO`). Anything we
//! cannot represent exactly (rotation, ground control points, scale/offset metadata, palettes) is
//! an error with a fix, never an approximation. The writers produce byte-identical files for
//! identical rasters: Deflate tiles, no timestamps, georeference and CRS from the [`Grid`];
//! [`GeoTiffWriter`] writes them band by band, so no raster has to be whole in memory.

mod geokeys;
mod mask;
mod write;

pub use write::{write_f32, write_rgba8, write_u8, GeoTiffWriter, F32_NODATA};

use super::{image_world, Samples, SourceRaster};
#[cfg(doc)]
use crate::crs::Crs;
use crate::error::{Error, Result};
use crate::grid::Grid;
use geokeys::GeoTags;
use rayon::prelude::*;
use std::io::BufReader;
use std::ops::Range;
use std::path::Path;
use tiff::decoder::{Decoder, DecodingResult, Limits};
use tiff::tags::{ExtraSamples, Tag};
use tiff::TiffError;

/// Largest decoded image we accept, bytes: generous for DEMs, but a corrupt header claiming a
/// gigantic size must fail cleanly instead of exhausting memory.
const MAX_DECODED_BYTES: usize = 16 << 30;

const PHOTOMETRIC_WHITE_IS_ZERO: u16 = 0;
const PHOTOMETRIC_PALETTE: u16 = 3;
const PHOTOMETRIC_YCBCR: u16 = 6;
const COMPRESSION_JPEG: u16 = 7;

pub(super) fn corrupt(path: &Path, e: TiffError) -> Error {
    match e {
        TiffError::IoError(io) if io.kind() == std::io::ErrorKind::UnexpectedEof => {
            Error::file(path, "corrupt or truncated TIFF: file ends early")
                .fix("re-create or re-download the file")
        }
        TiffError::LimitsExceeded => Error::file(path, "image too large to read into memory")
            .fix("cut it into tiles with gdal_retile.py or gdal_translate -srcwin"),
        TiffError::UnsupportedError(u) => {
            Error::file(path, format!("unsupported TIFF layout: {u}")).fix(
                "convert it: gdal_translate -co COMPRESS=DEFLATE -co PREDICTOR=1 in.tif out.tif",
            )
        }
        other => Error::file(
            path,
            format!(
                "corrupt or truncated TIFF: {}",
                other.to_string().replace('\n', " ")
            ),
        )
        .fix("re-create the file, or check it with gdalinfo"),
    }
}

/// Read a GeoTIFF (or a plain TIFF with a `.tfw` world file): int8/16/32, uint8/16/32,
/// float16/32/64; stripped or tiled; chunky or planar; any compression and predictor the `tiff`
/// crate decodes (none, LZW, Deflate, PackBits, JPEG; predictors 2 and 3). Uncompressed, LZW and
/// Deflate images of 8- to 64-bit samples decode their strips or tiles in parallel
/// (`io::chunks`); the rest go through the `tiff` crate on one thread.
pub fn read(path: &Path) -> Result<SourceRaster> {
    read_impl(path, None)
}

/// Read only image rows `rows` (all columns) of a GeoTIFF, as [`read`] reads the whole: the
/// result's grid is the rows' sub-grid. Uncompressed, LZW and Deflate images of 8- to 64-bit
/// samples decode only the strips or tiles those rows overlap, so memory is the window's plus
/// one chunk row; other layouts decode the whole image and keep the rows. Rows beyond the image
/// are an error.
pub fn read_rows(path: &Path, rows: Range<usize>) -> Result<SourceRaster> {
    read_impl(path, Some(rows))
}

/// Width and height of a TIFF's first image, in pixels, without decoding it.
pub fn size(path: &Path) -> Result<(usize, usize)> {
    let file = super::open_regular(path)?;
    let mut dec = Decoder::new(BufReader::new(file)).map_err(|e| corrupt(path, e))?;
    let (w, h) = dec.dimensions().map_err(|e| corrupt(path, e))?;
    Ok((w as usize, h as usize))
}

fn read_impl(path: &Path, window: Option<Range<usize>>) -> Result<SourceRaster> {
    let file = super::open_regular(path)?;
    let limits = {
        let mut l = Limits::default();
        l.decoding_buffer_size = MAX_DECODED_BYTES;
        l.intermediate_buffer_size = MAX_DECODED_BYTES;
        l.ifd_value_size = 64 << 20;
        l
    };
    let chunk_file = file.try_clone().map_err(|e| Error::io(path, e))?;
    let mut dec = Decoder::new(BufReader::new(file))
        .map_err(|e| corrupt(path, e))?
        .with_limits(limits);
    let err = |e| corrupt(path, e);
    let (width, height) = dec.dimensions().map_err(err)?;
    let (width, height) = (width as usize, height as usize);
    let layout = PixelFormat::of(path, &mut dec)?;
    let tags = GeoTags::read(&mut dec).map_err(err)?;
    let rows = window.clone().unwrap_or(0..height);
    if rows.start > rows.end || rows.end > height {
        return Err(Error::file(
            path,
            format!("rows {rows:?} are outside the image's {height} rows"),
        )
        .fix("ask for rows within the image"));
    }
    let nodata = tags.nodata(path)?;
    let mut samples = decode_rows(path, &mut dec, &chunk_file, &layout, nodata, rows.clone())?;
    // An internal mask on grey or RGB colour becomes its alpha band (masks on other images are
    // not looked for: their nodata is the GDAL_NODATA value).
    let (mut bands, mut alpha_band) = (layout.bands, layout.alpha_band);
    if matches!(samples, Samples::U8(_) | Samples::U16(_))
        && alpha_band.is_none()
        && matches!(bands, 1 | 3)
    {
        if let Some(mask) = mask::read(path, &mut dec, &chunk_file, rows)? {
            samples = match samples {
                Samples::U8(v) => Samples::U8(with_band(v, bands, &mask, u8::MAX)),
                Samples::U16(v) => Samples::U16(with_band(v, bands, &mask, u16::MAX)),
                other => other,
            };
            (bands, alpha_band) = (bands + 1, Some(bands));
        }
    }
    let (grid, pixel_is_point) = georeference(path, &tags, width, height)?;
    let grid = match window {
        Some(rows) => grid.window_grid(&crate::grid::Window {
            col: 0,
            row: rows.start,
            width,
            height: rows.len(),
        }),
        None => grid,
    };
    Ok(SourceRaster {
        path: path.to_path_buf(),
        grid,
        bands,
        samples,
        nodata,
        alpha_band,
        pixel_is_point,
        format: "GTiff",
    })
}

/// How an image's pixels are made, as far as reading them needs: checked to be something we
/// read exactly (no WhiteIsZero, no palette, YCbCr only as JPEG, 8- to 64-bit samples).
struct PixelFormat {
    /// Samples per pixel.
    bands: usize,
    /// The band ExtraSamples marks as alpha (associated or not).
    alpha_band: Option<usize>,
    /// JPEG-compressed YCbCr, which the decoder leaves as stored.
    ycbcr: bool,
}

impl PixelFormat {
    fn of<R: std::io::Read + std::io::Seek>(
        path: &Path,
        dec: &mut Decoder<R>,
    ) -> Result<PixelFormat> {
        let err = |e| corrupt(path, e);
        let photometric: Option<u16> = dec
            .find_tag_unsigned(Tag::PhotometricInterpretation)
            .map_err(err)?;
        let compression: Option<u16> = dec.find_tag_unsigned(Tag::Compression).map_err(err)?;
        let ycbcr = match (photometric, compression) {
            (Some(PHOTOMETRIC_WHITE_IS_ZERO), _) => {
                // The tiff crate inverts such samples; GDAL returns them as stored. Refuse the
                // ambiguity.
                return Err(Error::file(path, "WhiteIsZero photometric interpretation")
                    .fix("rewrite it: gdal_translate -co PHOTOMETRIC=MINISBLACK in.tif out.tif"));
            }
            (Some(PHOTOMETRIC_PALETTE), _) => {
                return Err(Error::file(path, "palette (colour-mapped) TIFF")
                    .fix("expand it: gdal_translate -expand rgba in.tif out.tif"));
            }
            (Some(PHOTOMETRIC_YCBCR), Some(COMPRESSION_JPEG)) => true,
            (Some(PHOTOMETRIC_YCBCR), _) => {
                return Err(Error::file(
                    path,
                    "YCbCr colour without JPEG compression is not supported",
                )
                .fix("rewrite it: gdal_translate -co PHOTOMETRIC=RGB in.tif out.tif"));
            }
            _ => false,
        };
        let color = dec.colortype().map_err(err)?;
        if !matches!(color.bit_depth(), 8 | 16 | 32 | 64) {
            return Err(Error::file(
                path,
                format!("{}-bit samples are not supported", color.bit_depth()),
            )
            .fix("convert it: gdal_translate -ot Byte in.tif out.tif"));
        }
        let bands = color.num_samples() as usize;
        let extra: Vec<u16> = dec
            .find_tag_unsigned_vec(Tag::ExtraSamples)
            .map_err(err)?
            .unwrap_or_default();
        let alpha_band = extra
            .iter()
            .position(|&e| {
                e == ExtraSamples::AssociatedAlpha.to_u16()
                    || e == ExtraSamples::UnassociatedAlpha.to_u16()
            })
            .map(|i| bands - extra.len() + i);
        Ok(PixelFormat {
            bands,
            alpha_band,
            ycbcr,
        })
    }
}

/// The samples of image rows `rows`, pixel-interleaved, YCbCr turned to RGB: strips or tiles
/// decoded in parallel where [`chunks`](super::chunks) reads the layout (sparse ones as
/// `nodata`), else the whole image through the `tiff` crate and the rows kept.
fn decode_rows<R: std::io::Read + std::io::Seek>(
    path: &Path,
    dec: &mut Decoder<R>,
    file: &std::fs::File,
    layout: &PixelFormat,
    nodata: Option<f64>,
    rows: Range<usize>,
) -> Result<Samples> {
    let err = |e| corrupt(path, e);
    let (width, height) = dec.dimensions().map_err(err)?;
    let bands = layout.bands;
    let (buf, planes, whole) = match super::chunks::layout(dec)
        .map_err(err)?
        .map(|p| p.with_fill(nodata))
    {
        Some(plan) if plan.decoded_bytes() > MAX_DECODED_BYTES as u64 => {
            return Err(corrupt(path, TiffError::LimitsExceeded))
        }
        Some(plan) => (
            super::chunks::decode(path, file, &plan, rows.clone())?,
            plan.planes(),
            false,
        ),
        None => {
            let mut buf = DecodingResult::U8(Vec::new());
            let layout = dec.read_image_to_buffer(&mut buf).map_err(err)?;
            (buf, layout.planes, true)
        }
    };
    let pixels = width as usize * if whole { height as usize } else { rows.len() };
    let mut samples = samples_from(path, buf)?;
    if samples.len() != pixels * bands {
        return Err(Error::file(
            path,
            format!(
                "decoded {} samples, expected {width} × {height} × {bands}",
                samples.len()
            ),
        )
        .fix("convert it: gdal_translate -co INTERLEAVE=PIXEL in.tif out.tif"));
    }
    if planes > 1 {
        samples = interleave(samples, bands);
    }
    if whole && rows.len() != height as usize {
        let row = width as usize * bands;
        samples = samples.slice(rows.start * row..rows.end * row);
    }
    if layout.ycbcr {
        // The decoder leaves JPEG's YCbCr as stored; GDAL (libjpeg) returns RGB.
        match &mut samples {
            Samples::U8(v) if bands >= 3 => v.par_chunks_mut(bands).for_each(ycbcr_to_rgb),
            _ => {
                return Err(
                    Error::file(path, "YCbCr TIFF that is not 8-bit with 3 colour bands")
                        .fix("rewrite it: gdal_translate -co PHOTOMETRIC=RGB in.tif out.tif"),
                )
            }
        }
    }
    Ok(samples)
}

/// The whole image's grid from its GeoTIFF tags (or a `.tfw` world file, and a `.prj` for an
/// unknown CRS), and whether the raster type is PixelIsPoint.
fn georeference(path: &Path, tags: &GeoTags, width: usize, height: usize) -> Result<(Grid, bool)> {
    let (crs, pixel_is_point) = tags.crs(path)?;
    let transform = match tags.transform(path, pixel_is_point)? {
        Some(t) => t,
        None => image_world::read_world_file(path)?.ok_or_else(|| {
            Error::file(path, "no georeference (no GeoTIFF tags and no .tfw world file)")
                .fix("assign one: gdal_translate -a_ullr ULX ULY LRX LRY -a_srs EPSG:CODE in.tif out.tif")
        })?,
    };
    tags.check_no_scale_offset(path)?;
    let crs = if crs.is_unknown() {
        super::read_prj(path)?
    } else {
        crs
    };
    let grid = Grid {
        width,
        height,
        transform,
        crs,
    };
    Ok((grid, pixel_is_point))
}

/// Pixels of `bands` samples with `mask` appended as one more sample: 0 where the mask is 0,
/// `on` elsewhere.
fn with_band<T: Copy + Default + Send + Sync>(
    v: Vec<T>,
    bands: usize,
    mask: &[u8],
    on: T,
) -> Vec<T> {
    v.par_chunks(bands)
        .zip(mask.par_iter())
        .flat_map_iter(|(px, &m)| {
            let alpha = if m == 0 { T::default() } else { on };
            px.iter().copied().chain([alpha])
        })
        .collect()
}

/// Full-range (JFIF) YCbCr to RGB in place, on the first three samples of a pixel, as libjpeg does.
fn ycbcr_to_rgb(px: &mut [u8]) {
    let (y, cb, cr) = (px[0] as f64, px[1] as f64 - 128.0, px[2] as f64 - 128.0);
    let to8 = |v: f64| v.round().clamp(0.0, 255.0) as u8;
    px[0] = to8(y + 1.402 * cr);
    px[1] = to8(y - 0.344_136 * cb - 0.714_136 * cr);
    px[2] = to8(y + 1.772 * cb);
}

/// Our sample vector from the decoder's; small types widen exactly (int8 → Int16, float16 → Float32).
fn samples_from(path: &Path, buf: DecodingResult) -> Result<Samples> {
    Ok(match buf {
        DecodingResult::U8(v) => Samples::U8(v),
        DecodingResult::U16(v) => Samples::U16(v),
        DecodingResult::I16(v) => Samples::I16(v),
        DecodingResult::U32(v) => Samples::U32(v),
        DecodingResult::I32(v) => Samples::I32(v),
        DecodingResult::F32(v) => Samples::F32(v),
        DecodingResult::F64(v) => Samples::F64(v),
        DecodingResult::I8(v) => Samples::I16(v.into_iter().map(i16::from).collect()),
        DecodingResult::F16(v) => Samples::F32(v.into_iter().map(|x| x.to_f32()).collect()),
        DecodingResult::U64(_) | DecodingResult::I64(_) => {
            return Err(
                Error::file(path, "64-bit integer samples are not supported")
                    .fix("convert it: gdal_translate -ot Float64 in.tif out.tif"),
            )
        }
    })
}

/// Planar (band-sequential) samples to pixel-interleaved.
fn interleave(samples: Samples, bands: usize) -> Samples {
    fn go<T: Copy + Send + Sync>(v: Vec<T>, bands: usize) -> Vec<T> {
        let n = v.len() / bands;
        (0..v.len())
            .into_par_iter()
            .map(|i| v[(i % bands) * n + i / bands])
            .collect()
    }
    match samples {
        Samples::U8(v) => Samples::U8(go(v, bands)),
        Samples::U16(v) => Samples::U16(go(v, bands)),
        Samples::I16(v) => Samples::I16(go(v, bands)),
        Samples::U32(v) => Samples::U32(go(v, bands)),
        Samples::I32(v) => Samples::I32(go(v, bands)),
        Samples::F32(v) => Samples::F32(go(v, bands)),
        Samples::F64(v) => Samples::F64(go(v, bands)),
    }
}
