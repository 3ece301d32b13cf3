//! GeoTIFF reading (any layout the `tiff` crate decodes) and writing (our three layer kinds).
//!
//! # Invariant
//! [`read`] returns the corner-convention grid GDAL reports for the same file: ModelTiepoint +
//! ModelPixelScale or a non-rotated ModelTransformation, shifted by half a cell when
//! GTRasterTypeGeoKey says PixelIsPoint (GDAL's default, `GTIFF_POINT_GEO_IGNORE=NO`). Anything we
//! cannot represent exactly (rotation, ground control points, scale/offset metadata, palettes) is
//! an error with a fix, never an approximation. The writers produce byte-identical files for
//! identical rasters: Deflate tiles, no timestamps, georeference and CRS from the [`Grid`];
//! [`GeoTiffWriter`] writes them band by band, so no raster has to be whole in memory.

use super::atomic::{AtomicFile, Staged};
use super::{crs_from_wkt, image_world, Samples, SourceRaster};
use crate::crs::Crs;
use crate::error::{Error, Result};
use crate::grid::{GeoTransform, Grid, NotNorthUp};
use crate::raster::{Colour, Raster};
use rayon::prelude::*;
use std::io::{BufReader, Seek, Write};
use std::marker::PhantomData;
use std::os::unix::fs::FileExt;
use std::path::Path;
use tiff::decoder::{Decoder, DecodingResult, Limits};
use tiff::encoder::compression::{CompressionAlgorithm, Deflate, DeflateLevel};
use tiff::tags::{ExtraSamples, Tag};
use tiff::{TiffError, TiffResult};

/// Largest decoded image we accept, bytes: generous for DEMs, but a corrupt header claiming a
/// gigantic size must fail cleanly instead of exhausting memory.
const MAX_DECODED_BYTES: usize = 16 << 30;

/// GeoKey IDs (GeoTIFF 1.1, section 7).
mod key {
    pub const GT_MODEL_TYPE: u16 = 1024;
    pub const GT_RASTER_TYPE: u16 = 1025;
    pub const GT_CITATION: u16 = 1026;
    pub const GEOGRAPHIC_TYPE: u16 = 2048;
    pub const GEOG_CITATION: u16 = 2049;
    pub const GEOG_ANGULAR_UNITS: u16 = 2054;
    pub const PROJECTED_CS_TYPE: u16 = 3072;
    pub const PCS_CITATION: u16 = 3073;
    pub const PROJ_LINEAR_UNITS: u16 = 3076;
    pub const PROJ_LINEAR_UNIT_SIZE: u16 = 3077;
    pub const VERTICAL_UNITS: u16 = 4099;
    /// Value meaning "user-defined" for any code key.
    pub const USER_DEFINED: u16 = 32767;
    pub const MODEL_PROJECTED: u16 = 1;
    pub const MODEL_GEOGRAPHIC: u16 = 2;
    pub const RASTER_PIXEL_IS_AREA: u16 = 1;
    pub const RASTER_PIXEL_IS_POINT: u16 = 2;
    pub const LINEAR_METRE: u16 = 9001;
    pub const ANGULAR_DEGREE: u16 = 9102;
}

const PHOTOMETRIC_WHITE_IS_ZERO: u16 = 0;
const PHOTOMETRIC_PALETTE: u16 = 3;
const PHOTOMETRIC_YCBCR: u16 = 6;
const COMPRESSION_JPEG: u16 = 7;

/// GDAL's private TIFF tag holding band metadata as XML (scale, offset, statistics).
const TAG_GDAL_METADATA: Tag = Tag::Unknown(42112);

/// Prefix GDAL (and we) use to carry a WKT CRS in GTCitationGeoKey.
const ESRI_PE_STRING: &str = "ESRI PE String = ";

/// The nodata value [`write_f32`] writes for NaN cells.
pub const F32_NODATA: f32 = -9999.0;

fn corrupt(path: &Path, e: TiffError) -> Error {
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
/// ([`super::chunks`]); the rest go through the `tiff` crate on one thread.
pub fn read(path: &Path) -> Result<SourceRaster> {
    read_impl(path, None)
}

/// Read only image rows `rows` (all columns) of a GeoTIFF, as [`read`] reads the whole: the
/// result's grid is the rows' sub-grid. Uncompressed, LZW and Deflate images of 8- to 64-bit
/// samples decode only the strips or tiles those rows overlap, so memory is the window's plus
/// one chunk row; other layouts decode the whole image and keep the rows. Rows beyond the image
/// are an error.
pub fn read_rows(path: &Path, rows: std::ops::Range<usize>) -> Result<SourceRaster> {
    read_impl(path, Some(rows))
}

fn read_impl(path: &Path, window: Option<std::ops::Range<usize>>) -> Result<SourceRaster> {
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
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
    let photometric: Option<u16> = dec
        .find_tag_unsigned(Tag::PhotometricInterpretation)
        .map_err(err)?;
    let compression: Option<u16> = dec.find_tag_unsigned(Tag::Compression).map_err(err)?;
    let ycbcr = match (photometric, compression) {
        (Some(PHOTOMETRIC_WHITE_IS_ZERO), _) => {
            // The tiff crate inverts such samples; GDAL returns them as stored. Refuse the ambiguity.
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
    let tags = GeoTags::read(&mut dec).map_err(err)?;

    let rows = window.clone().unwrap_or(0..height as usize);
    if rows.start > rows.end || rows.end > height as usize {
        return Err(Error::file(
            path,
            format!("rows {rows:?} are outside the image's {height} rows"),
        )
        .fix("ask for rows within the image"));
    }
    let nodata = tags.nodata(path)?;
    let planned = super::chunks::plan(&mut dec).map_err(err)?;
    let (buf, planes, whole) = match planned.map(|p| p.with_fill(nodata)) {
        Some(plan) if plan.decoded_bytes() > MAX_DECODED_BYTES as u64 => {
            return Err(corrupt(path, TiffError::LimitsExceeded))
        }
        Some(plan) => (
            super::chunks::decode(path, &chunk_file, &plan, rows.clone())?,
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
    if ycbcr {
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
    // An internal mask on grey or RGB colour becomes its alpha band (masks on other images are
    // not looked for: their nodata is the GDAL_NODATA value).
    let mask = match samples {
        Samples::U8(_) | Samples::U16(_) if alpha_band.is_none() && matches!(bands, 1 | 3) => {
            read_mask(path, &mut dec, &chunk_file, rows.clone())?
        }
        _ => None,
    };
    let (bands, alpha_band) = match mask {
        Some(mask) => {
            samples = match samples {
                Samples::U8(v) => Samples::U8(with_band(v, bands, &mask, u8::MAX)),
                Samples::U16(v) => Samples::U16(with_band(v, bands, &mask, u16::MAX)),
                other => other,
            };
            (bands + 1, Some(bands))
        }
        None => (bands, alpha_band),
    };

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
        width: width as usize,
        height: height as usize,
        transform,
        crs,
    };
    let grid = match window {
        Some(rows) => grid.window_grid(&crate::grid::Window {
            col: 0,
            row: rows.start,
            width: width as usize,
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

/// The TIFF internal mask of image rows `rows` — the first later IFD with NewSubfileType bit 4
/// (mask) and not bit 1 (reduced resolution), as GDAL writes for `GDAL_TIFF_INTERNAL_MASK=YES`
/// and finds it — one byte a cell, 0 where masked (nodata); `None` when the file has none. Only
/// the strips or tiles the rows overlap are read. 1- or 8-bit, one sample, the image's size,
/// uncompressed, LZW or Deflate without predictor; other masks are an error with a fix.
fn read_mask<R: std::io::Read + Seek>(
    path: &Path,
    dec: &mut Decoder<R>,
    file: &std::fs::File,
    rows: std::ops::Range<usize>,
) -> Result<Option<Vec<u8>>> {
    let err = |e| corrupt(path, e);
    let (width, height) = dec.dimensions().map_err(err)?;
    let (width, height) = (width as usize, height as usize);
    loop {
        if !dec.more_images() {
            return Ok(None);
        }
        dec.next_image().map_err(err)?;
        let kind: u32 = dec
            .find_tag_unsigned(Tag::NewSubfileType)
            .map_err(err)?
            .unwrap_or(0);
        if kind & 4 != 0 && kind & 1 == 0 {
            break;
        }
    }
    let unsigned = |dec: &mut Decoder<R>, tag, default: u64| -> Result<u64> {
        Ok(dec.find_tag_unsigned(tag).map_err(err)?.unwrap_or(default))
    };
    let (w, h) = dec.dimensions().map_err(err)?;
    let bits = unsigned(dec, Tag::BitsPerSample, 1)?;
    let spp = unsigned(dec, Tag::SamplesPerPixel, 1)?;
    let compression = unsigned(dec, Tag::Compression, 1)?;
    let predictor = unsigned(dec, Tag::Predictor, 1)?;
    let layout = format!(
        "{w} × {h} cells, {spp} sample(s) of {bits} bit(s), compression {compression}, predictor {predictor}"
    );
    if (w as usize, h as usize) != (width, height)
        || spp != 1
        || !matches!(bits, 1 | 8)
        || !matches!(compression, 1 | 5 | 8 | 32946)
        || predictor != 1
    {
        return Err(Error::file(
            path,
            format!("unsupported internal mask ({layout}; the image is {width} × {height})"),
        )
        .fix("make the mask an alpha band: gdal_translate -b 1 -b 2 -b 3 -b mask -co ALPHA=YES in.tif out.tif"));
    }
    let tiled = dec.find_tag(Tag::TileWidth).map_err(err)?.is_some();
    let (cw, ch, offsets, counts) = if tiled {
        (
            unsigned(dec, Tag::TileWidth, 0)? as usize,
            unsigned(dec, Tag::TileLength, 0)? as usize,
            dec.find_tag_unsigned_vec::<u64>(Tag::TileOffsets),
            dec.find_tag_unsigned_vec::<u64>(Tag::TileByteCounts),
        )
    } else {
        let rows_per_strip = unsigned(dec, Tag::RowsPerStrip, height as u64)?;
        (
            width,
            rows_per_strip.min(height as u64) as usize,
            dec.find_tag_unsigned_vec::<u64>(Tag::StripOffsets),
            dec.find_tag_unsigned_vec::<u64>(Tag::StripByteCounts),
        )
    };
    let bad = |what: String| {
        Error::file(path, format!("corrupt internal mask: {what}"))
            .fix("re-create the file, or check it with gdalinfo")
    };
    let (offsets, counts) = (
        offsets.map_err(err)?.unwrap_or_default(),
        counts.map_err(err)?.unwrap_or_default(),
    );
    let across = width.div_ceil(cw.max(1));
    if cw == 0
        || ch == 0
        || offsets.len() < across * height.div_ceil(ch)
        || counts.len() < offsets.len()
    {
        return Err(bad(format!(
            "{layout}, {cw} × {ch} chunks, {} offsets",
            offsets.len()
        )));
    }
    let file_len = file.metadata().map_err(|e| Error::io(path, e))?.len();
    let row_bytes = (cw * bits as usize).div_ceil(8);
    let mut mask = vec![0u8; width * rows.len()];
    for cy in rows.start / ch..rows.end.div_ceil(ch) {
        for cx in 0..across {
            let i = cy * across + cx;
            if counts[i] > file_len {
                return Err(bad(format!(
                    "chunk {i} of {} bytes in a file of {file_len}",
                    counts[i]
                )));
            }
            let mut stored = vec![0u8; counts[i] as usize];
            file.read_exact_at(&mut stored, offsets[i])
                .map_err(|e| bad(format!("chunk {i}: {e}")))?;
            let want = row_bytes * ch;
            let raw = match compression {
                1 => stored,
                5 => weezl::decode::Decoder::with_tiff_size_switch(weezl::BitOrder::Msb, 8)
                    .decode(&stored)
                    .map_err(|e| bad(format!("chunk {i}: LZW data: {e}")))?,
                _ => super::chunks::inflate_zlib(&stored, want)
                    .map_err(|e| bad(format!("chunk {i}: {e}")))?,
            };
            for y in (cy * ch).max(rows.start)..((cy + 1) * ch).min(rows.end) {
                let src = (y - cy * ch) * row_bytes;
                let out = &mut mask[(y - rows.start) * width..][..width];
                for x in cx * cw..((cx + 1) * cw).min(width) {
                    let c = x - cx * cw;
                    let v = if bits == 1 {
                        raw.get(src + c / 8).map(|b| b >> (7 - c % 8) & 1)
                    } else {
                        raw.get(src + c).copied()
                    };
                    out[x] =
                        v.ok_or_else(|| bad(format!("chunk {i} decodes to {} bytes", raw.len())))?;
                }
            }
        }
    }
    Ok(Some(mask))
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

/// The georeferencing tags of a TIFF, raw.
#[derive(Debug, Default)]
struct GeoTags {
    pixel_scale: Option<Vec<f64>>,
    tiepoints: Option<Vec<f64>>,
    transformation: Option<Vec<f64>>,
    geokeys: Option<Vec<u16>>,
    doubles: Option<Vec<f64>>,
    ascii: Option<String>,
    nodata: Option<String>,
    metadata: Option<String>,
}

/// A GeoKey's value: a short, doubles, or text.
#[derive(Debug, Clone, PartialEq)]
enum KeyValue {
    Short(u16),
    Doubles(Vec<f64>),
    Ascii(String),
}

impl GeoTags {
    fn read<R: std::io::Read + Seek>(dec: &mut Decoder<R>) -> TiffResult<GeoTags> {
        let f64s = |dec: &mut Decoder<R>, t| {
            dec.find_tag(t)
                .and_then(|v| v.map(|v| v.into_f64_vec()).transpose())
        };
        let text = |dec: &mut Decoder<R>, t| {
            dec.find_tag(t)
                .and_then(|v| v.map(|v| v.into_string()).transpose())
        };
        Ok(GeoTags {
            pixel_scale: f64s(dec, Tag::ModelPixelScaleTag)?,
            tiepoints: f64s(dec, Tag::ModelTiepointTag)?,
            transformation: f64s(dec, Tag::ModelTransformationTag)?,
            geokeys: dec.find_tag_unsigned_vec(Tag::GeoKeyDirectoryTag)?,
            doubles: f64s(dec, Tag::GeoDoubleParamsTag)?,
            ascii: text(dec, Tag::GeoAsciiParamsTag)?,
            nodata: text(dec, Tag::GdalNodata)?,
            metadata: text(dec, TAG_GDAL_METADATA)?,
        })
    }

    /// The GeoKeys as (id, value), in file order. Malformed directories are an error.
    fn keys(&self, path: &Path) -> Result<Vec<(u16, KeyValue)>> {
        let Some(dir) = &self.geokeys else {
            return Ok(Vec::new());
        };
        let bad = |what: &str| {
            Error::file(path, format!("corrupt GeoKeyDirectory: {what}"))
                .fix("re-create the georeference with gdal_translate -a_srs")
        };
        if dir.len() < 4 {
            return Err(bad("too short"));
        }
        let n = dir[3] as usize;
        let entries = dir
            .get(4..4 + 4 * n)
            .ok_or_else(|| bad("fewer keys than it declares"))?;
        entries
            .chunks_exact(4)
            .map(|e| {
                let (id, loc, count, off) = (e[0], e[1], e[2] as usize, e[3] as usize);
                let value = match loc {
                    0 => KeyValue::Short(off as u16),
                    34736 => KeyValue::Doubles(
                        self.doubles
                            .as_ref()
                            .and_then(|d| d.get(off..off + count))
                            .ok_or_else(|| bad("double out of range"))?
                            .to_vec(),
                    ),
                    34737 => {
                        let s = self
                            .ascii
                            .as_deref()
                            .and_then(|a| a.get(off..off + count))
                            .ok_or_else(|| bad("text out of range"))?;
                        KeyValue::Ascii(s.trim_end_matches(['|', '\0']).to_string())
                    }
                    34735 => {
                        KeyValue::Short(*dir.get(off).ok_or_else(|| bad("short out of range"))?)
                    }
                    _ => return Err(bad("unknown value location")),
                };
                Ok((id, value))
            })
            .collect()
    }

    /// The CRS from the GeoKeys, and whether the raster type is PixelIsPoint.
    ///
    /// EPSG codes come from ProjectedCSTypeGeoKey (projected) or GeographicTypeGeoKey
    /// (geographic). A user-defined CRS (code 32767) has no EPSG code: it keeps the WKT carried in
    /// an `ESRI PE String = ` citation if there is one, else a `LOCAL_CS["<citation>"]` WKT that
    /// names it (so it compares unequal to every EPSG CRS instead of matching anything).
    /// Length units other than the metre (ProjLinearUnitsGeoKey, with ProjLinearUnitSizeGeoKey
    /// for a user-defined one, and VerticalUnitsGeoKey) are kept in the CRS's `foreign_unit` and
    /// `vertical_unit` so ingest can refuse them.
    fn crs(&self, path: &Path) -> Result<(Crs, bool)> {
        let (mut crs, point) = self.crs_without_units(path)?;
        let keys = self.keys(path)?;
        let short = |id| {
            keys.iter().find_map(|(k, v)| match v {
                KeyValue::Short(s) if *k == id => Some(*s),
                _ => None,
            })
        };
        let unit = |code: u16| match code {
            key::USER_DEFINED => keys.iter().find_map(|(k, v)| match v {
                KeyValue::Doubles(d)
                    if *k == key::PROJ_LINEAR_UNIT_SIZE
                        && d.len() == 1
                        && (d[0] - 1.0).abs() > 1e-9 =>
                {
                    Some(crate::crs::ForeignUnit {
                        name: "a user-defined unit".into(),
                        metres: d[0],
                    })
                }
                _ => None,
            }),
            code => crate::crs::foreign_unit_from_epsg(code),
        };
        if !crs.geographic && crs.foreign_unit.is_none() {
            crs.foreign_unit = short(key::PROJ_LINEAR_UNITS).and_then(unit);
        }
        if let Some(v) = short(key::VERTICAL_UNITS).and_then(crate::crs::foreign_unit_from_epsg) {
            crs.vertical_unit = Some(v);
        }
        Ok((crs, point))
    }

    /// [`crs`](Self::crs) before units are looked at.
    fn crs_without_units(&self, path: &Path) -> Result<(Crs, bool)> {
        let keys = self.keys(path)?;
        let short = |id| {
            keys.iter().find(|(k, _)| *k == id).and_then(|(_, v)| {
                if let KeyValue::Short(s) = v {
                    Some(*s)
                } else {
                    None
                }
            })
        };
        let text = |id| {
            keys.iter().find(|(k, _)| *k == id).and_then(|(_, v)| {
                if let KeyValue::Ascii(s) = v {
                    Some(s.clone())
                } else {
                    None
                }
            })
        };
        let point = short(key::GT_RASTER_TYPE) == Some(key::RASTER_PIXEL_IS_POINT);
        if let Some(wkt) =
            text(key::GT_CITATION).and_then(|c| c.strip_prefix(ESRI_PE_STRING).map(str::to_string))
        {
            if let Some(crs) = crs_from_wkt(&wkt) {
                return Ok((crs, point));
            }
        }
        let projected = short(key::PROJECTED_CS_TYPE);
        let geographic = short(key::GEOGRAPHIC_TYPE);
        let model = short(key::GT_MODEL_TYPE).or(match (projected, geographic) {
            (Some(_), _) => Some(key::MODEL_PROJECTED),
            (None, Some(_)) => Some(key::MODEL_GEOGRAPHIC),
            _ => None,
        });
        let (code, citation_keys, is_geo) = match model {
            Some(key::MODEL_PROJECTED) => (projected, [key::PCS_CITATION, key::GT_CITATION], false),
            Some(key::MODEL_GEOGRAPHIC) => {
                (geographic, [key::GEOG_CITATION, key::GT_CITATION], true)
            }
            Some(other) => {
                return Err(Error::file(
                    path,
                    format!("unsupported GeoTIFF model type {other} (geocentric?)"),
                )
                .fix("reproject it: gdalwarp -t_srs EPSG:CODE in.tif out.tif"))
            }
            None => return Ok((Crs::unknown(), point)),
        };
        let crs = match code {
            Some(c) if c != key::USER_DEFINED && c != 0 => Crs {
                geographic: is_geo,
                ..Crs::epsg(c as u32)
            },
            _ => {
                let name = citation_keys
                    .iter()
                    .find_map(|&k| text(k))
                    .unwrap_or_else(|| "user-defined".to_string());
                let name = name.replace('"', "'");
                Crs {
                    epsg: None,
                    wkt: Some(format!("LOCAL_CS[\"{name}\"]")),
                    geographic: is_geo,
                    ..Crs::default()
                }
            }
        };
        Ok((crs, point))
    }

    /// The corner-convention transform, or `None` when the file has no georeferencing tags.
    fn transform(&self, path: &Path, pixel_is_point: bool) -> Result<Option<GeoTransform>> {
        let (origin, cell, shear) = match (&self.transformation, &self.tiepoints, &self.pixel_scale)
        {
            (Some(m), _, _) => {
                if m.len() < 8 {
                    return Err(
                        Error::file(path, "ModelTransformation has fewer than 16 values")
                            .fix("re-create the georeference with gdal_translate"),
                    );
                }
                ([m[3], m[7]], [m[0], m[5]], [m[1], m[4]])
            }
            (None, Some(tp), Some(sc)) if tp.len() == 6 && sc.len() >= 2 => (
                [tp[3] - tp[0] * sc[0], tp[4] + tp[1] * sc[1]],
                [sc[0], -sc[1]],
                [0.0, 0.0],
            ),
            (None, Some(tp), _) if tp.len() >= 6 => {
                return Err(Error::file(
                    path,
                    format!(
                        "georeferenced by {} ground control points, not a grid",
                        tp.len() / 6
                    ),
                )
                .fix("warp it onto a north-up grid first: gdalwarp in.tif out.tif"))
            }
            _ => return Ok(None),
        };
        let t = GeoTransform::north_up(origin, cell, shear).map_err(|e| match e {
            NotNorthUp::Sheared => Error::file(
                path,
                format!(
                    "rotated or sheared georeference (ModelTransformation terms {}, {})",
                    shear[0], shear[1]
                ),
            )
            .fix("make it north-up first: gdalwarp in.tif out.tif"),
            NotNorthUp::BadGeometry => Error::file(
                path,
                format!(
                    "bad georeference (origin {}, {}; cell {} × {})",
                    origin[0], origin[1], cell[0], cell[1]
                ),
            )
            .fix("assign one: gdal_translate -a_ullr ULX ULY LRX LRY in.tif out.tif"),
        })?;
        Ok(Some(if pixel_is_point {
            // The tiepoint is a pixel centre: the corner is half a cell up and left (GDAL does the same).
            GeoTransform {
                origin_x: t.origin_x - 0.5 * t.cell_x,
                origin_y: t.origin_y - 0.5 * t.cell_y,
                ..t
            }
        } else {
            t
        }))
    }

    /// The GDAL_NODATA value: a number, `nan`, `inf` or `-inf`.
    fn nodata(&self, path: &Path) -> Result<Option<f64>> {
        let Some(s) = &self.nodata else {
            return Ok(None);
        };
        let s = s.trim_matches(|c: char| c == '\0' || c.is_whitespace());
        if s.is_empty() {
            return Ok(None);
        }
        s.parse::<f64>().map(Some).map_err(|_| {
            Error::file(path, format!("GDAL_NODATA tag '{s}' is not a number"))
                .fix("set it: gdal_edit.py -a_nodata VALUE in.tif")
        })
    }

    /// GDAL stores band scale/offset in its metadata XML; values would need `v·scale + offset`,
    /// which we do not apply, so refuse rather than return unscaled numbers.
    fn check_no_scale_offset(&self, path: &Path) -> Result<()> {
        let Some(xml) = &self.metadata else {
            return Ok(());
        };
        for (role, identity) in [("scale", 1.0), ("offset", 0.0)] {
            let needle = format!("role=\"{role}\">");
            for (at, _) in xml.match_indices(&needle) {
                let rest = &xml[at + needle.len()..];
                let value = rest.split('<').next().unwrap_or("").trim();
                if value.parse::<f64>() != Ok(identity) {
                    return Err(Error::file(
                        path,
                        format!("band {role} {value} is set (values are not in their final units)"),
                    )
                    .fix("apply it: gdal_translate -unscale -ot Float32 in.tif out.tif"));
                }
            }
        }
        Ok(())
    }
}

/// Write a Float32 GeoTIFF (elevation, metres): NaN is written as [`F32_NODATA`] (-9999) with the
/// GDAL_NODATA tag "-9999". Tiled 256 × 256, Deflate with the floating-point predictor (3).
/// A valid cell that equals -9999 exactly would read back as nodata, so it is an error.
pub fn write_f32(path: &Path, r: &Raster<f32>) -> Result<()> {
    let mut w = GeoTiffWriter::create_f32(path, &r.grid)?;
    w.push_rows(&r.data)?;
    w.finish()
}

/// Write an RGBA8 GeoTIFF (ExtraSamples = unassociated alpha, so GDAL/QGIS treat band 4 as the
/// mask); same georeference as [`write_f32`]. Tiled, Deflate with horizontal predictor.
pub fn write_rgba8(path: &Path, r: &Colour) -> Result<()> {
    let mut w = GeoTiffWriter::create_rgba8(path, &r.grid)?;
    w.push_rows(&r.data)?;
    w.finish()
}

/// Write a single-band 8-bit GeoTIFF with an optional nodata value (used for masks: 1 = shadow,
/// 0 = lit, 255 nodata). Tiled, Deflate with horizontal predictor.
pub fn write_u8(path: &Path, r: &Raster<u8>, nodata: Option<u8>) -> Result<()> {
    let mut w = GeoTiffWriter::create_u8(path, &r.grid, nodata)?;
    w.push_rows(&r.data)?;
    w.finish()
}

/// A sample type our GeoTIFFs hold: how a row of cells becomes little-endian bytes.
pub trait TiffSample: Copy + Send + Sync {
    /// Write `cells` into `out` (exactly `size_of::<Self>()` bytes a cell); `Err(k)` when
    /// `cells[k]` cannot be written (it would read back as nodata).
    fn encode(cells: &[Self], out: &mut [u8]) -> std::result::Result<(), usize>;
}

impl TiffSample for f32 {
    /// NaN becomes [`F32_NODATA`]; a valid cell equal to it is refused.
    fn encode(cells: &[f32], out: &mut [u8]) -> std::result::Result<(), usize> {
        for (k, (&v, o)) in cells.iter().zip(out.chunks_exact_mut(4)).enumerate() {
            if v == F32_NODATA {
                return Err(k);
            }
            o.copy_from_slice(&if v.is_nan() { F32_NODATA } else { v }.to_le_bytes());
        }
        Ok(())
    }
}

impl TiffSample for u8 {
    fn encode(cells: &[u8], out: &mut [u8]) -> std::result::Result<(), usize> {
        out.copy_from_slice(cells);
        Ok(())
    }
}

impl TiffSample for [u8; 4] {
    fn encode(cells: &[[u8; 4]], out: &mut [u8]) -> std::result::Result<(), usize> {
        out.copy_from_slice(cells.as_flattened());
        Ok(())
    }
}

/// A tiled, Deflate-compressed, predicted GeoTIFF written top to bottom, a band of rows at a
/// time, so a raster never has to be whole in memory: the writer holds at most one tile row
/// (256 grid rows) of raw samples and that tile row's compressed tiles, whatever the height.
/// [`write_f32`], [`write_rgba8`] and [`write_u8`] are this writer fed a whole raster, so a file
/// written band by band is byte-identical to one written whole.
///
/// Invariant: rows `0..rows_done` have been pushed; those of complete tile rows are in the file
/// (tiles compressed in parallel, written in order), the rest are in `buf`. The output is
/// atomic: nothing appears at the path until [`finish`](GeoTiffWriter::finish) succeeds.
pub struct GeoTiffWriter<T> {
    out: AtomicFile,
    grid: Grid,
    spec: Spec,
    big: bool,
    /// Raw sample bytes of the pushed rows not yet in the file (fewer than a tile row).
    buf: Vec<u8>,
    rows_done: usize,
    /// File offset and length of every tile written, in tile order.
    offsets: Vec<u64>,
    counts: Vec<u64>,
    /// The same for the tiles of the internal mask (empty unless `spec.mask`).
    mask_offsets: Vec<u64>,
    mask_counts: Vec<u64>,
    /// Bytes in the file so far.
    pos: u64,
    sample: PhantomData<T>,
}

impl GeoTiffWriter<f32> {
    /// A Float32 GeoTIFF on `grid` (see [`write_f32`]).
    pub fn create_f32(path: &Path, grid: &Grid) -> Result<Self> {
        Self::create(path, grid, Spec::float32())
    }
}

impl GeoTiffWriter<[u8; 4]> {
    /// An RGBA8 GeoTIFF on `grid` (see [`write_rgba8`]).
    pub fn create_rgba8(path: &Path, grid: &Grid) -> Result<Self> {
        Self::create(path, grid, Spec::rgba8())
    }

    /// An RGB8 GeoTIFF on `grid` (PhotometricInterpretation RGB, 3 bands, tiled, Deflate with
    /// horizontal predictor) fed RGBA cells: the alpha is not stored as a band but as a TIFF
    /// internal mask, as GDAL writes one with `GDAL_TIFF_INTERNAL_MASK=YES` — a second IFD after
    /// the image's (NewSubfileType 4, PhotometricInterpretation 4 = transparency mask, 1 bit a
    /// cell, same size and 256 × 256 tiles, Deflate), bit 1 where alpha ≠ 0. GDAL reports it as
    /// "Mask Flags: PER_DATASET" (masked cells are nodata to every GDAL tool) and [`read`] returns
    /// it as a 4th (alpha) band, so no colour value has to be given up as nodata.
    pub fn create_rgb8_masked(path: &Path, grid: &Grid) -> Result<Self> {
        Self::create(path, grid, Spec::rgb8_masked())
    }
}

impl GeoTiffWriter<u8> {
    /// A single-band byte GeoTIFF on `grid` (see [`write_u8`]).
    pub fn create_u8(path: &Path, grid: &Grid, nodata: Option<u8>) -> Result<Self> {
        Self::create(path, grid, Spec::byte(nodata))
    }
}

impl<T: TiffSample> GeoTiffWriter<T> {
    /// Classic TIFF, or BigTIFF when the padded samples would pass [`BIGTIFF_ABOVE`] bytes.
    fn create(path: &Path, grid: &Grid, spec: Spec) -> Result<Self> {
        let tiles = grid.width.div_ceil(TILE) as u64 * grid.height.div_ceil(TILE) as u64;
        let mask = if spec.mask { TILE * TILE / 8 } else { 0 };
        let big = tiles * (TILE * TILE * spec.pixel_bytes() + mask) as u64 > BIGTIFF_ABOVE;
        Self::create_layout(path, grid, spec, big)
    }

    /// [`create`](Self::create) with the TIFF flavour chosen by the caller.
    fn create_layout(path: &Path, grid: &Grid, spec: Spec, big: bool) -> Result<Self> {
        debug_assert_eq!(spec.cell_bytes(), std::mem::size_of::<T>());
        let (w, h) = (grid.width, grid.height);
        if w == 0 || h == 0 {
            return Err(Error::file(path, "cannot write an empty raster"));
        }
        if u32::try_from(w).is_err() || u32::try_from(h).is_err() {
            return Err(Error::file(
                path,
                format!("{w} × {h} cells is too large for a TIFF"),
            ));
        }
        let mut out = AtomicFile::create(path)?;
        // The first IFD's offset is patched in by `finish`.
        let header: &[u8] = if big {
            b"II\x2b\x00\x08\x00\x00\x00\0\0\0\0\0\0\0\0"
        } else {
            b"II\x2a\x00\0\0\0\0"
        };
        out.writer()
            .write_all(header)
            .map_err(|e| Error::io(path, e))?;
        let tiles = w.div_ceil(TILE) * h.div_ceil(TILE);
        Ok(GeoTiffWriter {
            out,
            grid: grid.clone(),
            spec,
            big,
            buf: Vec::new(),
            rows_done: 0,
            offsets: Vec::with_capacity(tiles),
            counts: Vec::with_capacity(tiles),
            mask_offsets: Vec::new(),
            mask_counts: Vec::new(),
            pos: header.len() as u64,
            sample: PhantomData,
        })
    }

    /// Append whole rows (`cells.len()` a multiple of the width, row-major) below those pushed
    /// before. Every complete tile row is compressed and written at once.
    pub fn push_rows(&mut self, mut cells: &[T]) -> Result<()> {
        let (w, h) = (self.grid.width, self.grid.height);
        let n = cells.len() / w;
        if cells.len() % w != 0 || self.rows_done + n > h {
            return Err(Error::file(
                self.out.path(),
                format!(
                    "internal: {} cells pushed after row {} of a {w} × {h} raster",
                    cells.len(),
                    self.rows_done
                ),
            ));
        }
        let row_len = w * self.spec.cell_bytes();
        while !cells.is_empty() {
            let room = TILE - self.buf.len() / row_len;
            let (now, rest) = cells.split_at(room.min(cells.len() / w) * w);
            let start = self.buf.len();
            self.buf.resize(start + now.len() / w * row_len, 0);
            let bad = self.buf[start..]
                .par_chunks_mut(row_len)
                .zip(now.par_chunks(w))
                .enumerate()
                .find_map_first(|(r, (out, row))| T::encode(row, out).err().map(|c| (c, r)));
            if let Some((col, r)) = bad {
                return Err(Error::file(
                    self.out.path(),
                    format!(
                        "cell ({col}, {}) holds {}, the nodata value of our GeoTIFFs",
                        self.rows_done + r,
                        self.spec.nodata.as_deref().unwrap_or("?")
                    ),
                )
                .fix("offset the heights or mark that cell as nodata"));
            }
            self.rows_done += now.len() / w;
            if self.buf.len() == TILE * row_len {
                self.flush_tile_row()?;
            }
            cells = rest;
        }
        Ok(())
    }

    /// Compress the buffered rows (one tile row, or the last, shorter one) as tiles in parallel,
    /// padded with zeros beyond the grid, and append them in order (then the tiles of the
    /// internal mask of those rows, if the spec has one).
    fn flush_tile_row(&mut self) -> Result<()> {
        let (w, spec) = (self.grid.width, &self.spec);
        let (pixel, cell) = (spec.pixel_bytes(), spec.cell_bytes());
        let (row_len, tile_row_len) = (w * cell, TILE * pixel);
        let (buf, rows) = (&self.buf, self.buf.len() / row_len);
        let tiles: Vec<(Vec<u8>, Option<Vec<u8>>)> = (0..w.div_ceil(TILE))
            .into_par_iter()
            .map(|tx| {
                let (mut raw, mut scratch) = (
                    Vec::with_capacity(TILE * tile_row_len),
                    Vec::with_capacity(tile_row_len),
                );
                let cols = tx * TILE * cell..((tx + 1) * TILE).min(w) * cell;
                let src = |r: usize| &buf[r * row_len..][cols.clone()];
                for r in 0..TILE {
                    let start = raw.len();
                    if r < rows && spec.mask {
                        raw.extend(src(r).chunks_exact(cell).flat_map(|c| &c[..pixel]));
                    } else if r < rows {
                        raw.extend_from_slice(src(r));
                    }
                    raw.resize(start + tile_row_len, 0);
                    spec.predict(&mut raw[start..], &mut scratch);
                }
                let mask = spec.mask.then(|| {
                    // 1 bit a cell, most significant first; 0 (nodata) beyond the grid.
                    let mut bits = vec![0u8; TILE * TILE / 8];
                    for r in 0..rows {
                        for (i, c) in src(r).chunks_exact(cell).enumerate() {
                            if c[pixel] != 0 {
                                bits[r * TILE / 8 + i / 8] |= 0x80 >> (i % 8);
                            }
                        }
                    }
                    deflate(&bits)
                });
                (deflate(&raw), mask)
            })
            .collect();
        let path = self.out.path().to_path_buf();
        let (image, masks): (Vec<_>, Vec<_>) = tiles.into_iter().unzip();
        for (t, mask) in image
            .iter()
            .map(|t| (t, false))
            .chain(masks.iter().flatten().map(|t| (t, true)))
        {
            let (offsets, counts) = if mask {
                (&mut self.mask_offsets, &mut self.mask_counts)
            } else {
                (&mut self.offsets, &mut self.counts)
            };
            offsets.push(self.pos);
            counts.push(t.len() as u64);
            self.out
                .writer()
                .write_all(t)
                .map_err(|e| Error::io(&path, e))?;
            self.pos += t.len() as u64;
        }
        self.buf.clear();
        Ok(())
    }

    /// Write the last tiles and the directory, then move the file into place. Every row of the
    /// grid must have been pushed.
    pub fn finish(self) -> Result<()> {
        self.stage()?.commit()
    }

    /// [`finish`](Self::finish) but leave the file under its temporary name, for a run that
    /// renames all its outputs together ([`crate::io::atomic::commit_all`]).
    pub fn stage(mut self) -> Result<Staged> {
        let (w, h) = (self.grid.width, self.grid.height);
        if self.rows_done != h {
            return Err(Error::file(
                self.out.path(),
                format!(
                    "internal: {} of the {h} rows of a {w} × {h} raster were written",
                    self.rows_done
                ),
            ));
        }
        if !self.buf.is_empty() {
            self.flush_tile_row()?;
        }
        let path = self.out.path().to_path_buf();
        let io = |e| Error::io(&path, e);
        let (big, mut pos) = (self.big, self.pos);
        let out = self.out.writer();
        if pos % 2 == 1 {
            out.write_all(&[0]).map_err(io)?;
            pos += 1;
        }
        let entries = ifd_entries(&self.grid, &self.spec, self.offsets, self.counts, big);
        let mut ifd = ifd_bytes(&entries, pos, big, 0);
        if self.spec.mask {
            // GDAL finds the mask by scanning the IFDs after the image's: chain it second.
            let at = pos + ifd.len() as u64;
            let mask = mask_ifd_entries(&self.grid, self.mask_offsets, self.mask_counts, big);
            ifd = ifd_bytes(&entries, pos, big, at);
            ifd.extend(ifd_bytes(&mask, at, big, 0));
        }
        if !big && pos + ifd.len() as u64 > u32::MAX as u64 {
            return Err(
                Error::file(&path, "compressed data exceeds the 4 GiB of a classic TIFF")
                    .fix("write a smaller raster (tile it)"),
            );
        }
        out.write_all(&ifd).map_err(io)?;
        out.seek(std::io::SeekFrom::Start(if big { 8 } else { 4 }))
            .map_err(io)?;
        if big {
            out.write_all(&pos.to_le_bytes()).map_err(io)?;
        } else {
            out.write_all(&(pos as u32).to_le_bytes()).map_err(io)?;
        }
        self.out.stage()
    }
}

/// Tile edge of the GeoTIFFs we write, cells (GDAL's and Cloud-Optimised GeoTIFF's default).
const TILE: usize = 256;

/// The sample layout of an image we write.
struct Spec {
    /// Samples per pixel.
    samples: u16,
    /// Bytes per sample.
    bytes: u16,
    /// IEEE float samples (predictor 3) rather than unsigned integers (predictor 2).
    float: bool,
    /// Photometric RGB rather than MinIsBlack.
    rgb: bool,
    /// The last sample is unassociated alpha.
    alpha: bool,
    /// Each cell arrives with one more byte after its samples (RGBA's alpha) that is written
    /// not as a sample but as the TIFF internal mask (bit 1 where the byte is not 0).
    mask: bool,
    /// GDAL_NODATA text.
    nodata: Option<String>,
}

impl Spec {
    /// Float32 elevation, nodata -9999.
    fn float32() -> Spec {
        Spec {
            samples: 1,
            bytes: 4,
            float: true,
            rgb: false,
            alpha: false,
            mask: false,
            nodata: Some(F32_NODATA.to_string()),
        }
    }

    /// RGB with an unassociated alpha band as the mask.
    fn rgba8() -> Spec {
        Spec {
            samples: 4,
            bytes: 1,
            float: false,
            rgb: true,
            alpha: true,
            mask: false,
            nodata: None,
        }
    }

    /// RGB, the cells' alpha written as the internal mask.
    fn rgb8_masked() -> Spec {
        Spec {
            samples: 3,
            bytes: 1,
            float: false,
            rgb: true,
            alpha: false,
            mask: true,
            nodata: None,
        }
    }

    /// One byte band with an optional nodata value.
    fn byte(nodata: Option<u8>) -> Spec {
        Spec {
            samples: 1,
            bytes: 1,
            float: false,
            rgb: false,
            alpha: false,
            mask: false,
            nodata: nodata.map(|v| v.to_string()),
        }
    }

    /// Bytes of a stored pixel.
    fn pixel_bytes(&self) -> usize {
        self.samples as usize * self.bytes as usize
    }

    /// Bytes of a cell as pushed: the stored pixel and the mask byte, if any.
    fn cell_bytes(&self) -> usize {
        self.pixel_bytes() + self.mask as usize
    }

    /// Apply the predictor to one row of a tile, in place (TIFF 6 section 14 and Adobe's
    /// floating-point predictor technical note 3, as libtiff writes them).
    fn predict(&self, row: &mut [u8], scratch: &mut Vec<u8>) {
        let stride = self.samples as usize;
        if self.float {
            // Byte planes, most significant first, then byte differences along the whole row.
            let bps = self.bytes as usize;
            let n = row.len() / bps;
            scratch.clear();
            scratch.extend_from_slice(row);
            for i in 0..n {
                for b in 0..bps {
                    row[(bps - 1 - b) * n + i] = scratch[i * bps + b];
                }
            }
        }
        // Horizontal differencing of bytes (8-bit samples, or the float byte planes).
        for i in (stride..row.len()).rev() {
            row[i] = row[i].wrapping_sub(row[i - stride]);
        }
    }
}

/// Classic TIFF offsets are 32-bit: beyond this many bytes of (padded) samples we write BigTIFF.
const BIGTIFF_ABOVE: u64 = 0xF000_0000;

/// A TIFF field value.
enum Field {
    Short(Vec<u16>),
    Long(Vec<u32>),
    Long8(Vec<u64>),
    Double(Vec<f64>),
    Ascii(String),
}

impl Field {
    /// TIFF type code, count and little-endian bytes.
    fn encode(&self) -> (u16, u64, Vec<u8>) {
        match self {
            Field::Short(v) => (
                3,
                v.len() as u64,
                v.iter().flat_map(|x| x.to_le_bytes()).collect(),
            ),
            Field::Long(v) => (
                4,
                v.len() as u64,
                v.iter().flat_map(|x| x.to_le_bytes()).collect(),
            ),
            Field::Long8(v) => (
                16,
                v.len() as u64,
                v.iter().flat_map(|x| x.to_le_bytes()).collect(),
            ),
            Field::Double(v) => (
                12,
                v.len() as u64,
                v.iter().flat_map(|x| x.to_le_bytes()).collect(),
            ),
            Field::Ascii(s) => {
                let mut b = s.as_bytes().to_vec();
                b.push(0);
                (2, b.len() as u64, b)
            }
        }
    }
}

/// The tags of an image we write, sorted by tag number as TIFF requires.
fn ifd_entries(
    grid: &Grid,
    spec: &Spec,
    offsets: Vec<u64>,
    counts: Vec<u64>,
    big: bool,
) -> Vec<(u16, Field)> {
    let n = spec.samples as usize;
    let long = |v: u64| Field::Long(vec![v as u32]);
    let chunks = |v| chunk_field(v, big);
    let t = &grid.transform;
    let mut e = vec![
        (256, long(grid.width as u64)),
        (257, long(grid.height as u64)),
        (258, Field::Short(vec![spec.bytes * 8; n])),
        (259, Field::Short(vec![8])), // Deflate
        (262, Field::Short(vec![if spec.rgb { 2 } else { 1 }])),
        (277, Field::Short(vec![spec.samples])),
        (284, Field::Short(vec![1])), // chunky
        (317, Field::Short(vec![if spec.float { 3 } else { 2 }])),
        (322, long(TILE as u64)),
        (323, long(TILE as u64)),
        (324, chunks(offsets)),
        (325, chunks(counts)),
        (339, Field::Short(vec![if spec.float { 3 } else { 1 }; n])),
    ];
    if spec.alpha {
        e.push((
            338,
            Field::Short(vec![ExtraSamples::UnassociatedAlpha.to_u16()]),
        ));
    }
    if t.cell_y < 0.0 {
        e.push((33550, Field::Double(vec![t.cell_x, -t.cell_y, 0.0])));
        e.push((
            33922,
            Field::Double(vec![0.0, 0.0, 0.0, t.origin_x, t.origin_y, 0.0]),
        ));
    } else {
        let m = vec![
            t.cell_x, 0.0, 0.0, t.origin_x, 0.0, t.cell_y, 0.0, t.origin_y, 0.0, 0.0, 0.0, 0.0,
            0.0, 0.0, 0.0, 1.0,
        ];
        e.push((34264, Field::Double(m)));
    }
    let (keys, ascii) = geokeys(&grid.crs);
    e.push((34735, Field::Short(keys)));
    if let Some(a) = ascii {
        e.push((34737, Field::Ascii(a)));
    }
    if let Some(nd) = &spec.nodata {
        e.push((42113, Field::Ascii(nd.clone())));
    }
    e.sort_by_key(|(tag, _)| *tag);
    e
}

/// Tile offsets or byte counts: LONG in a classic TIFF, LONG8 in a BigTIFF.
fn chunk_field(v: Vec<u64>, big: bool) -> Field {
    if big {
        Field::Long8(v)
    } else {
        Field::Long(v.into_iter().map(|x| x as u32).collect())
    }
}

/// The tags of the internal mask's IFD, as GDAL writes them for `GDAL_TIFF_INTERNAL_MASK=YES`:
/// a transparency mask (NewSubfileType 4; PhotometricInterpretation 4),
/// 1 bit a cell, tiled like the image, Deflate without predictor, no georeference of its own.
fn mask_ifd_entries(
    grid: &Grid,
    offsets: Vec<u64>,
    counts: Vec<u64>,
    big: bool,
) -> Vec<(u16, Field)> {
    let long = |v: u64| Field::Long(vec![v as u32]);
    vec![
        (254, long(4)), // NewSubfileType: transparency mask
        (256, long(grid.width as u64)),
        (257, long(grid.height as u64)),
        (258, Field::Short(vec![1])),
        (259, Field::Short(vec![8])), // Deflate
        (262, Field::Short(vec![4])), // transparency mask
        (277, Field::Short(vec![1])),
        (284, Field::Short(vec![1])),
        (322, long(TILE as u64)),
        (323, long(TILE as u64)),
        (324, chunk_field(offsets, big)),
        (325, chunk_field(counts, big)),
    ]
}

/// Deflate (zlib) of one tile's bytes.
fn deflate(raw: &[u8]) -> Vec<u8> {
    let mut packed = Vec::with_capacity(raw.len() / 2);
    // Writing into a Vec cannot fail.
    let _ = Deflate::with_level(DeflateLevel::Balanced).write_to(&mut packed, raw);
    packed
}

/// An IFD placed at file offset `at`, followed by its out-of-line values (word-aligned), that
/// chains to the IFD at offset `next` (0: none).
fn ifd_bytes(entries: &[(u16, Field)], at: u64, big: bool, next: u64) -> Vec<u8> {
    let (entry_len, inline) = if big { (20u64, 8usize) } else { (12, 4) };
    let head = if big { 8 } else { 2 };
    let mut data_pos = at + head + entries.len() as u64 * entry_len + inline as u64;
    let (mut ifd, mut data) = (Vec::new(), Vec::new());
    if big {
        ifd.extend_from_slice(&(entries.len() as u64).to_le_bytes());
    } else {
        ifd.extend_from_slice(&(entries.len() as u16).to_le_bytes());
    }
    for (tag, field) in entries {
        let (ty, count, mut bytes) = field.encode();
        ifd.extend_from_slice(&tag.to_le_bytes());
        ifd.extend_from_slice(&ty.to_le_bytes());
        if big {
            ifd.extend_from_slice(&count.to_le_bytes());
        } else {
            ifd.extend_from_slice(&(count as u32).to_le_bytes());
        }
        if bytes.len() <= inline {
            bytes.resize(inline, 0);
            ifd.extend_from_slice(&bytes);
        } else {
            if big {
                ifd.extend_from_slice(&data_pos.to_le_bytes());
            } else {
                ifd.extend_from_slice(&(data_pos as u32).to_le_bytes());
            }
            if bytes.len() % 2 == 1 {
                bytes.push(0);
            }
            data_pos += bytes.len() as u64;
            data.extend_from_slice(&bytes);
        }
    }
    if big {
        ifd.extend_from_slice(&next.to_le_bytes());
    } else {
        ifd.extend_from_slice(&(next as u32).to_le_bytes());
    }
    ifd.extend_from_slice(&data);
    ifd
}

/// The GeoKeyDirectory (sorted by key, as the spec requires) and GeoAsciiParams for a CRS:
/// EPSG codes as ProjectedCSType (linear unit metre) or GeographicType (angular unit degree);
/// a WKT-only CRS as user-defined with the WKT in an `ESRI PE String = ` citation (GDAL reads it).
fn geokeys(crs: &Crs) -> (Vec<u16>, Option<String>) {
    let mut entries: Vec<[u16; 4]> = vec![[key::GT_RASTER_TYPE, 0, 1, key::RASTER_PIXEL_IS_AREA]];
    let mut ascii = None;
    let wkt = crs
        .wkt
        .as_deref()
        .filter(|w| w.is_ascii() && !w.contains('|'));
    let code = match (crs.epsg, wkt) {
        (Some(c), _) if c < key::USER_DEFINED as u32 => Some(c as u16),
        (_, Some(w)) => {
            let citation = format!("{ESRI_PE_STRING}{w}|");
            entries.push([key::GT_CITATION, 34737, citation.len() as u16, 0]);
            ascii = Some(citation);
            Some(key::USER_DEFINED)
        }
        _ => None,
    };
    if let Some(code) = code {
        if crs.geographic {
            entries.push([key::GT_MODEL_TYPE, 0, 1, key::MODEL_GEOGRAPHIC]);
            entries.push([key::GEOGRAPHIC_TYPE, 0, 1, code]);
            entries.push([key::GEOG_ANGULAR_UNITS, 0, 1, key::ANGULAR_DEGREE]);
        } else {
            entries.push([key::GT_MODEL_TYPE, 0, 1, key::MODEL_PROJECTED]);
            entries.push([key::PROJECTED_CS_TYPE, 0, 1, code]);
            entries.push([key::PROJ_LINEAR_UNITS, 0, 1, key::LINEAR_METRE]);
        }
    }
    entries.sort_by_key(|e| e[0]);
    let mut dir = vec![1, 1, 0, entries.len() as u16];
    dir.extend(entries.into_iter().flatten());
    (dir, ascii)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::raster::NODATA_COLOUR;

    fn grid(crs: Crs) -> Grid {
        Grid::north_up(500_000.25, 5_000_000.75, 0.5, 5, 3, crs)
    }

    #[test]
    fn f32_round_trip_is_bit_exact_with_nan_as_nodata() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("e.tif");
        let data = vec![
            1.0,
            f32::NAN,
            -3.5,
            1e-7,
            8848.86,
            0.0,
            -0.0,
            f32::MIN_POSITIVE,
            12.0,
            1e30,
            2.0,
            3.0,
            4.0,
            5.0,
            f32::NAN,
        ];
        let r = Raster::new(grid(Crs::epsg(32614)), data.clone());
        write_f32(&p, &r).unwrap();
        let s = read(&p).unwrap();
        assert_eq!(s.grid, r.grid);
        assert_eq!(s.nodata, Some(-9999.0));
        let e = s.to_elevation().unwrap();
        for (a, b) in e.data.iter().zip(&data) {
            assert!(
                a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()),
                "{a} vs {b}"
            );
        }
        let again = dir.path().join("e2.tif");
        write_f32(&again, &r).unwrap();
        assert_eq!(
            std::fs::read(&p).unwrap(),
            std::fs::read(&again).unwrap(),
            "output must be deterministic"
        );
    }

    #[test]
    fn bigtiff_layout_reads_back() {
        // Real BigTIFFs need > 3.75 GiB of samples; the layout is the same for a small image.
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("big.tif");
        let g = Grid::north_up(0.0, 600.0, 1.0, 300, 270, Crs::epsg(32614));
        let data: Vec<u8> = (0..g.len()).map(|i| (i * 7 % 251) as u8).collect();
        let mut w =
            GeoTiffWriter::<u8>::create_layout(&p, &g, Spec::byte(Some(255)), true).unwrap();
        w.push_rows(&data).unwrap();
        w.finish().unwrap();
        assert_eq!(&std::fs::read(&p).unwrap()[..4], b"II\x2b\x00");
        let s = read(&p).unwrap();
        assert_eq!(
            (s.grid, s.samples, s.nodata),
            (g, Samples::U8(data), Some(255.0))
        );
    }

    /// A raster pushed in uneven bands (crossing tile rows mid-band) is the same file, byte for
    /// byte, as the raster written whole; an unfinished writer leaves nothing behind.
    #[test]
    fn banded_writes_equal_whole_writes() {
        let dir = tempfile::tempdir().unwrap();
        let g = Grid::north_up(500_000.0, 5_000_000.0, 0.5, 300, 600, Crs::epsg(32614));
        let z: Vec<f32> = (0..g.len())
            .map(|i| {
                if i % 97 == 0 {
                    f32::NAN
                } else {
                    (i % 1013) as f32 * 0.25
                }
            })
            .collect();
        let whole = dir.path().join("whole.tif");
        write_f32(&whole, &Raster::new(g.clone(), z.clone())).unwrap();
        let banded = dir.path().join("banded.tif");
        let mut w = GeoTiffWriter::create_f32(&banded, &g).unwrap();
        let mut row = 0;
        for n in [7, 113, 1, 255, 224].into_iter().cycle() {
            let n = n.min(600 - row);
            w.push_rows(&z[row * 300..(row + n) * 300]).unwrap();
            row += n;
            if row == 600 {
                break;
            }
        }
        w.finish().unwrap();
        assert_eq!(
            std::fs::read(&whole).unwrap(),
            std::fs::read(&banded).unwrap()
        );

        let short = dir.path().join("short.tif");
        let mut w = GeoTiffWriter::create_f32(&short, &g).unwrap();
        w.push_rows(&z[..300 * 599]).unwrap();
        let e = w.finish().unwrap_err().to_string();
        assert!(e.contains("599 of the 600 rows"), "{e}");
        assert!(w_dir_names(dir.path())
            .iter()
            .all(|n| n == "whole.tif" || n == "banded.tif"));
        assert!(GeoTiffWriter::create_f32(&short, &g)
            .unwrap()
            .push_rows(&z[..301])
            .is_err());
    }

    fn w_dir_names(dir: &Path) -> Vec<String> {
        std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect()
    }

    #[test]
    fn f32_refuses_a_valid_nodata_value() {
        let dir = tempfile::tempdir().unwrap();
        let r = Raster::new(grid(Crs::unknown()), vec![F32_NODATA; 15]);
        assert!(write_f32(&dir.path().join("x.tif"), &r).is_err());
    }

    #[test]
    fn rgba_and_u8_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let g = grid(Crs::epsg(4326));
        let c = Raster::new(
            g.clone(),
            (0..15u8)
                .map(|i| {
                    if i == 3 {
                        NODATA_COLOUR
                    } else {
                        [i, 2 * i, 255 - i, 255]
                    }
                })
                .collect(),
        );
        let p = dir.path().join("c.tif");
        write_rgba8(&p, &c).unwrap();
        let s = read(&p).unwrap();
        assert_eq!((s.bands, s.alpha_band), (4, Some(3)));
        assert_eq!(s.grid, g);
        assert!(s.grid.crs.geographic);
        assert_eq!(s.to_colour().unwrap(), c);

        let m = Raster::new(g.clone(), (0..15u8).map(|i| i % 3).collect());
        let p = dir.path().join("m.tif");
        write_u8(&p, &m, Some(255)).unwrap();
        let s = read(&p).unwrap();
        assert_eq!(s.samples, Samples::U8(m.data.clone()));
        assert_eq!(s.nodata, Some(255.0));
    }

    /// RGB8 with the alpha as internal mask: masked cells read back as nodata whatever their
    /// RGB (black stays a valid colour), whole or by rows across a tile row, and the mask is the
    /// second IFD as GDAL expects (NewSubfileType 4, transparency mask, 1 bit).
    #[test]
    fn rgb8_masked_round_trips_mask_as_nodata() {
        let dir = tempfile::tempdir().unwrap();
        let g = Grid::north_up(500_000.0, 5_000_000.0, 0.5, 300, 270, Crs::epsg(32614));
        let cells: Vec<[u8; 4]> = (0..g.len())
            .map(|i| match i % 7 {
                0 => [(i % 251) as u8, 9, 9, 0],
                1 => [0, 0, 0, 255],
                _ => [(i % 251) as u8, (i % 13) as u8, 7, 255],
            })
            .collect();
        let p = dir.path().join("c.tif");
        let mut w = GeoTiffWriter::create_rgb8_masked(&p, &g).unwrap();
        for band in cells.chunks(300 * 100) {
            w.push_rows(band).unwrap();
        }
        w.finish().unwrap();
        let want: Vec<[u8; 4]> = cells
            .iter()
            .map(|&[r, g, b, a]| {
                if a == 0 {
                    NODATA_COLOUR
                } else {
                    [r, g, b, 255]
                }
            })
            .collect();
        let s = read(&p).unwrap();
        assert_eq!((s.bands, s.alpha_band, &s.grid), (4, Some(3), &g));
        assert_eq!(s.to_colour().unwrap().data, want);
        let rows = read_rows(&p, 250..262).unwrap();
        assert_eq!(rows.to_colour().unwrap().data, want[250 * 300..262 * 300]);

        let again = dir.path().join("again.tif");
        let mut w = GeoTiffWriter::create_rgb8_masked(&again, &g).unwrap();
        w.push_rows(&cells).unwrap();
        w.finish().unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), std::fs::read(&again).unwrap());

        let mut dec = Decoder::new(std::fs::File::open(&p).unwrap()).unwrap();
        let tag = |dec: &mut Decoder<_>, t| dec.find_tag_unsigned::<u32>(t).unwrap();
        assert_eq!(tag(&mut dec, Tag::SamplesPerPixel), Some(3));
        assert_eq!(tag(&mut dec, Tag::PhotometricInterpretation), Some(2));
        dec.next_image().unwrap();
        assert_eq!(tag(&mut dec, Tag::NewSubfileType), Some(4));
        assert_eq!(tag(&mut dec, Tag::PhotometricInterpretation), Some(4));
        assert_eq!(tag(&mut dec, Tag::BitsPerSample), Some(1));
        assert!(!dec.more_images());
    }

    #[test]
    fn wkt_only_crs_round_trips_through_citation() {
        let dir = tempfile::tempdir().unwrap();
        let wkt =
            r#"PROJCS["Local_Grid",GEOGCS["GCS_WGS_1984",DATUM["D_WGS_1984"]],UNIT["Meter",1.0]]"#;
        let crs = Crs {
            epsg: None,
            wkt: Some(wkt.to_string()),
            geographic: false,
            ..Crs::default()
        };
        let r = Raster::new(grid(crs.clone()), vec![1.0; 15]);
        let p = dir.path().join("w.tif");
        write_f32(&p, &r).unwrap();
        assert_eq!(read(&p).unwrap().grid.crs, crs);
    }

    #[test]
    fn tiepoint_scale_and_pixel_is_point() {
        let tags = GeoTags {
            tiepoints: Some(vec![2.0, 1.0, 0.0, 100.0, 200.0, 0.0]),
            pixel_scale: Some(vec![10.0, 5.0, 0.0]),
            ..Default::default()
        };
        let t = tags.transform(Path::new("x"), false).unwrap().unwrap();
        assert_eq!(
            t,
            GeoTransform {
                origin_x: 80.0,
                origin_y: 205.0,
                cell_x: 10.0,
                cell_y: -5.0
            }
        );
        let t = tags.transform(Path::new("x"), true).unwrap().unwrap();
        assert_eq!(
            t,
            GeoTransform {
                origin_x: 75.0,
                origin_y: 207.5,
                cell_x: 10.0,
                cell_y: -5.0
            }
        );
    }

    #[test]
    fn rotation_and_gcps_are_errors() {
        let mut m = vec![0.0; 16];
        (m[0], m[1], m[3], m[4], m[5], m[7]) = (1.0, 0.2, 0.0, 0.0, -1.0, 0.0);
        let tags = GeoTags {
            transformation: Some(m),
            ..Default::default()
        };
        let e = tags
            .transform(Path::new("r.tif"), false)
            .unwrap_err()
            .to_string();
        assert!(e.starts_with("r.tif: rotated"), "{e}");
        let tags = GeoTags {
            tiepoints: Some(vec![0.0; 18]),
            ..Default::default()
        };
        let e = tags
            .transform(Path::new("g.tif"), false)
            .unwrap_err()
            .to_string();
        assert!(e.contains("3 ground control points"), "{e}");
    }

    #[test]
    fn geokeys_user_defined_citation() {
        let keys = [
            1u16, 1, 0, 3, 1024, 0, 1, 1, 1026, 34737, 8, 0, 3072, 0, 1, 32767,
        ];
        let tags = GeoTags {
            geokeys: Some(keys.to_vec()),
            ascii: Some("My Grid|".into()),
            ..Default::default()
        };
        let (crs, point) = tags.crs(Path::new("x")).unwrap();
        assert!(!point);
        assert_eq!(crs.epsg, None);
        assert_eq!(crs.name(), "\"My Grid\"");
        assert!(!crs.same_as(&Crs::epsg(32614)));
    }

    /// GDAL writes ProjLinearUnitsGeoKey 9003 for EPSG:2277 (Texas Central, US survey feet):
    /// the unit is kept so ingest refuses feet; metres and degrees leave nothing to refuse.
    #[test]
    fn geokeys_linear_and_vertical_units() {
        let tags = |keys: &[u16]| GeoTags {
            geokeys: Some(keys.to_vec()),
            ..Default::default()
        };
        let feet = tags(&[
            1, 1, 0, 3, 1024, 0, 1, 1, 3072, 0, 1, 2277, 3076, 0, 1, 9003,
        ]);
        let (crs, _) = feet.crs(Path::new("x")).unwrap();
        assert_eq!(crs.epsg, Some(2277));
        assert_eq!(crs.foreign_unit.as_ref().unwrap().name, "US survey foot");
        let e = crs
            .require_metric_coordinates(Path::new("dem.tif"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("US survey foot") && e.contains("gdalwarp -t_srs"),
            "{e}"
        );
        let metres = tags(&[
            1, 1, 0, 3, 1024, 0, 1, 1, 3072, 0, 1, 32614, 3076, 0, 1, 9001,
        ]);
        let (crs, _) = metres.crs(Path::new("x")).unwrap();
        assert!(
            crs.require_metric_coordinates(Path::new("x")).is_ok()
                && crs.require_metric_heights(Path::new("x")).is_ok()
        );
        let heights_in_feet = tags(&[
            1, 1, 0, 3, 1024, 0, 1, 1, 3072, 0, 1, 32614, 4099, 0, 1, 9002,
        ]);
        let (crs, _) = heights_in_feet.crs(Path::new("x")).unwrap();
        assert_eq!(
            (
                crs.foreign_unit.is_none(),
                crs.vertical_unit.unwrap().metres
            ),
            (true, 0.3048)
        );
    }

    #[test]
    fn scale_offset_metadata_is_refused() {
        let xml =
            r#"<GDALMetadata><Item name="SCALE" sample="0" role="scale">0.1</Item></GDALMetadata>"#;
        let tags = GeoTags {
            metadata: Some(xml.into()),
            ..Default::default()
        };
        assert!(tags.check_no_scale_offset(Path::new("x")).is_err());
        let xml = r#"<GDALMetadata><Item name="OFFSET" sample="0" role="offset">0</Item><Item name="SCALE" sample="0" role="scale">1</Item></GDALMetadata>"#;
        let tags = GeoTags {
            metadata: Some(xml.into()),
            ..Default::default()
        };
        assert!(tags.check_no_scale_offset(Path::new("x")).is_ok());
    }
}
