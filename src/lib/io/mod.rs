//! Reading and writing rasters: GeoTIFF, Esri ASCII grid, PNG/JPEG with a world file, and (with
//! feature `gdal`) anything GDAL opens.
//!
//! # Invariant
//! Every reader returns a [`SourceRaster`] whose grid is in the **corner** (PixelIsArea)
//! convention of [`crate::grid`]: inputs that georeference pixel centres (GeoTIFF PixelIsPoint,
//! world files, `xllcenter` ASCII grids) are shifted by half a cell on read, exactly as GDAL does.
//! Samples are kept in the file's own type until [`SourceRaster::to_elevation`] or
//! [`SourceRaster::to_colour`] converts them, so no value is rounded before we know its use.
//! Formats are recognised by content (magic bytes), never by extension alone.

pub mod ascii_grid;
pub mod atomic;
mod chunks;
#[cfg(feature = "gdal")]
pub mod gdal;
pub mod geotiff;
pub mod image_world;
pub mod input;
pub mod lock;
pub mod mosaic;
pub mod png;

pub use crate::reading::{
    open_regular, read_bytes, read_settings, read_text, require_regular_file, MAX_SETTINGS_BYTES,
    MAX_TEXT_BYTES,
};

use crate::crs::Crs;
use crate::error::{Error, Result};
use crate::grid::Grid;
use crate::raster::{Colour, Elevation, Raster};
use rayon::prelude::*;
use std::io::Read;
use std::path::{Path, PathBuf};

/// The samples of a raster in the file's own type, pixel-interleaved.
#[derive(Debug, Clone, PartialEq)]
pub enum Samples {
    /// Unsigned 8-bit (images, masks).
    U8(Vec<u8>),
    /// Unsigned 16-bit (images, some DEMs).
    U16(Vec<u16>),
    /// Signed 16-bit (most integer DEMs: SRTM, DTED).
    I16(Vec<i16>),
    /// Unsigned 32-bit.
    U32(Vec<u32>),
    /// Signed 32-bit (integer ASCII grids, centimetre DEMs).
    I32(Vec<i32>),
    /// 32-bit float.
    F32(Vec<f32>),
    /// 64-bit float (decimal ASCII grids, Float64 GeoTIFFs).
    F64(Vec<f64>),
}

/// Run `$body` with `$v` bound to the typed sample vector, whatever its type.
macro_rules! with_samples {
    ($samples:expr, $v:ident => $body:expr) => {
        match $samples {
            Samples::U8($v) => $body,
            Samples::U16($v) => $body,
            Samples::I16($v) => $body,
            Samples::U32($v) => $body,
            Samples::I32($v) => $body,
            Samples::F32($v) => $body,
            Samples::F64($v) => $body,
        }
    };
}

impl Samples {
    /// Number of samples (pixels × bands).
    pub fn len(&self) -> usize {
        with_samples!(self, v => v.len())
    }

    /// True when there are no samples.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// GDAL's name of the sample type: `Byte`, `UInt16`, `Int16`, `UInt32`, `Int32`, `Float32`, `Float64`.
    pub fn type_name(&self) -> &'static str {
        match self {
            Samples::U8(_) => "Byte",
            Samples::U16(_) => "UInt16",
            Samples::I16(_) => "Int16",
            Samples::U32(_) => "UInt32",
            Samples::I32(_) => "Int32",
            Samples::F32(_) => "Float32",
            Samples::F64(_) => "Float64",
        }
    }

    /// Samples `range` as a new buffer of the same type.
    pub fn slice(&self, range: std::ops::Range<usize>) -> Samples {
        match self {
            Samples::U8(v) => Samples::U8(v[range].to_vec()),
            Samples::U16(v) => Samples::U16(v[range].to_vec()),
            Samples::I16(v) => Samples::I16(v[range].to_vec()),
            Samples::U32(v) => Samples::U32(v[range].to_vec()),
            Samples::I32(v) => Samples::I32(v[range].to_vec()),
            Samples::F32(v) => Samples::F32(v[range].to_vec()),
            Samples::F64(v) => Samples::F64(v[range].to_vec()),
        }
    }

    /// `n` samples of this buffer's type, each `v` (converted as `as` converts: saturating).
    pub fn filled(&self, n: usize, v: f64) -> Samples {
        match self {
            Samples::U8(_) => Samples::U8(vec![v as u8; n]),
            Samples::U16(_) => Samples::U16(vec![v as u16; n]),
            Samples::I16(_) => Samples::I16(vec![v as i16; n]),
            Samples::U32(_) => Samples::U32(vec![v as u32; n]),
            Samples::I32(_) => Samples::I32(vec![v as i32; n]),
            Samples::F32(_) => Samples::F32(vec![v as f32; n]),
            Samples::F64(_) => Samples::F64(vec![v; n]),
        }
    }

    /// Sample `i` as f64 (exact for every type but nothing is rounded: f32 widens exactly).
    #[inline]
    #[allow(clippy::useless_conversion)] // the Float64 arm converts f64 to itself
    pub fn get(&self, i: usize) -> f64 {
        with_samples!(self, v => v[i].into())
    }
}

/// A raster as read from a file, before conversion to a typed layer. Samples are pixel-interleaved
/// (`samples[(row*width + col)*bands + band]`). The grid is ALWAYS in the corner (PixelIsArea)
/// convention: PixelIsPoint inputs are shifted by half a cell on read (as GDAL does), and
/// `pixel_is_point` records it.
#[derive(Debug, Clone, PartialEq)]
pub struct SourceRaster {
    /// The file it was read from (for messages).
    pub path: PathBuf,
    /// Size, corner-convention geotransform (CRS units) and CRS.
    pub grid: Grid,
    /// Number of bands (samples per pixel), ≥ 1.
    pub bands: usize,
    /// `grid.len() * bands` samples, pixel-interleaved.
    pub samples: Samples,
    /// The declared nodata value (GDAL_NODATA, NODATA_value, GDAL's band nodata), same for all bands.
    pub nodata: Option<f64>,
    /// The band (0-based) that is an alpha mask, if the file says so.
    pub alpha_band: Option<usize>,
    /// True when the file georeferenced pixel centres (the grid has already been shifted).
    pub pixel_is_point: bool,
    /// The format read: `GTiff`, `AAIGrid`, `PNG`, `JPEG` or `GDAL:<driver>`.
    pub format: &'static str,
}

impl SourceRaster {
    /// Its metadata (path, grid, bands, nodata, alpha band, format) with no samples.
    pub fn clone_meta(&self) -> SourceRaster {
        SourceRaster {
            path: self.path.clone(),
            grid: self.grid.clone(),
            bands: self.bands,
            samples: self.samples.slice(0..0),
            nodata: self.nodata,
            alpha_band: self.alpha_band,
            pixel_is_point: self.pixel_is_point,
            format: self.format,
        }
    }
}

/// A sample type's notion of "equals the declared nodata value": compared in the sample's own
/// type, as GDAL does (a Float32 band with nodata -9999.0 matches `-9999.0f32`).
trait SampleValue: Copy + Send + Sync + Into<f64> {
    /// Largest magnitude that converts to f32 exactly (integers), or `None` for floats.
    const EXACT_F32_LIMIT: Option<f64>;
    fn is_nodata(self, nodata: f64) -> bool {
        let v: f64 = self.into();
        v == nodata || (v.is_nan() && nodata.is_nan())
    }
}

macro_rules! int_sample {
    ($($t:ty),*) => {$(
        impl SampleValue for $t {
            const EXACT_F32_LIMIT: Option<f64> = Some(16_777_216.0);
        }
    )*};
}
int_sample!(u8, u16, i16, u32, i32);

impl SampleValue for f32 {
    const EXACT_F32_LIMIT: Option<f64> = None;
    fn is_nodata(self, nodata: f64) -> bool {
        self == nodata as f32 || (self.is_nan() && nodata.is_nan())
    }
}

impl SampleValue for f64 {
    const EXACT_F32_LIMIT: Option<f64> = None;
}

impl SourceRaster {
    /// Sample of `band` at pixel index `pixel` (= `row * width + col`), as f64.
    #[inline]
    pub fn sample(&self, pixel: usize, band: usize) -> f64 {
        self.samples.get(pixel * self.bands + band)
    }

    /// Band 0 as elevation (metres, or whatever unit the file holds): declared nodata, NaN and ±inf
    /// become NaN. Errors if the raster has no valid cell ("all cells are nodata"). Integer types
    /// convert exactly (values beyond ±2^24 cannot and are an error); Float64 rounds to nearest f32.
    pub fn to_elevation(&self) -> Result<Elevation> {
        let e = self.to_elevation_band()?;
        if e.data.iter().all(|v| v.is_nan()) {
            return Err(Error::file(&self.path, "all cells are nodata")
                .fix("check the nodata value and the data (gdalinfo -stats)"));
        }
        Ok(e)
    }

    /// [`to_elevation`](Self::to_elevation) for a band of a larger raster (read with
    /// `geotiff::read_rows`): the same conversion, but a band may be all nodata (a void or the
    /// corner of a rotated footprint spanning the band) — only a whole raster may not.
    pub fn to_elevation_band(&self) -> Result<Elevation> {
        let data = with_samples!(&self.samples, v => self.elevation_values(v))?;
        Ok(Raster::new(self.grid.clone(), data))
    }

    /// [`to_elevation_band`](Self::to_elevation_band), converting in place when the samples are
    /// already one band of `f32` (a database's elevation layer): no second copy of the band.
    pub fn into_elevation_band(self) -> Result<Elevation> {
        match self.samples {
            Samples::F32(mut v) if self.bands == 1 => {
                let nodata = self.nodata;
                v.par_chunks_mut(CHUNK).for_each(|chunk| {
                    for x in chunk {
                        if !x.is_finite() || nodata.is_some_and(|nd| x.is_nodata(nd)) {
                            *x = f32::NAN;
                        }
                    }
                });
                Ok(Raster::new(self.grid, v))
            }
            _ => self.to_elevation_band(),
        }
    }

    fn elevation_values<T: SampleValue>(&self, v: &[T]) -> Result<Vec<f32>> {
        let (bands, nodata) = (self.bands, self.nodata);
        let limit = T::EXACT_F32_LIMIT.unwrap_or(f32::MAX as f64);
        // NaN for nodata; `None` for a value f32 cannot hold (found again below, first one reported).
        let convert = |i: usize| -> Option<f32> {
            let s = v[i * bands];
            let x: f64 = s.into();
            if !x.is_finite() || nodata.is_some_and(|nd| s.is_nodata(nd)) {
                Some(f32::NAN)
            } else {
                (x.abs() <= limit).then_some(x as f32)
            }
        };
        let bad = std::sync::atomic::AtomicBool::new(false);
        let mut out = vec![0f32; self.grid.len()];
        out.par_chunks_mut(CHUNK)
            .enumerate()
            .for_each(|(k, chunk)| {
                for (j, o) in chunk.iter_mut().enumerate() {
                    *o = convert(k * CHUNK + j).unwrap_or_else(|| {
                        bad.store(true, std::sync::atomic::Ordering::Relaxed);
                        f32::NAN
                    });
                }
            });
        if bad.into_inner() {
            let i = (0..out.len())
                .into_par_iter()
                .position_first(|i| convert(i).is_none())
                .unwrap_or(0);
            let width = self.grid.width.max(1);
            return Err(Error::file(
                &self.path,
                format!(
                    "value {} at column {}, row {} is out of range for an f32 elevation",
                    v[i * bands].into(),
                    i % width,
                    i / width
                ),
            )
            .fix("declare it as nodata or convert the file (gdal_translate -ot Float32 -scale)"));
        }
        Ok(out)
    }

    /// As RGBA8 colour: 1 band = grey (r=g=b), 2 bands = grey+alpha, 3 = RGB, 4 = RGBA (or
    /// `alpha_band`). 16-bit samples scale to 8 bit by rounding v*255/65535. A cell is nodata
    /// (alpha 0) when its alpha is 0 or when ALL its colour bands equal the declared nodata value
    /// (GDAL's per-band nodata convention). Valid cells get alpha 255. Other sample types are an
    /// error with a fix (convert to 8/16-bit).
    pub fn to_colour(&self) -> Result<Colour> {
        let (colour_bands, alpha) = self.colour_layout()?;
        let data = match &self.samples {
            Samples::U8(v) => self.colour_values(v, colour_bands, alpha, |s| s),
            Samples::U16(v) => self.colour_values(v, colour_bands, alpha, |s| {
                ((s as u32 * 255 + 32767) / 65535) as u8
            }),
            other => {
                return Err(Error::file(
                    &self.path,
                    format!(
                        "{} samples cannot be used as colour (8- or 16-bit unsigned only)",
                        other.type_name()
                    ),
                )
                .fix("convert it: gdal_translate -ot Byte -scale in.tif out.tif"))
            }
        };
        Ok(Raster::new(self.grid.clone(), data))
    }

    /// How many leading bands are colour (1 = grey or 3 = RGB) and which band is alpha (the last).
    fn colour_layout(&self) -> Result<(usize, Option<usize>)> {
        let alpha = self
            .alpha_band
            .or(matches!(self.bands, 2 | 4).then(|| self.bands - 1));
        let colour = match alpha {
            Some(a) if a + 1 == self.bands => a,
            Some(_) => 0,
            None => self.bands,
        };
        if matches!(colour, 1 | 3) {
            return Ok((colour, alpha));
        }
        Err(Error::file(
            &self.path,
            format!(
                "{} bands cannot be used as colour (expected grey, grey+alpha, RGB or RGBA)",
                self.bands
            ),
        )
        .fix("select the bands: gdal_translate -b 1 -b 2 -b 3 in.tif out.tif"))
    }

    /// The first band of a byte raster (a class or id layer), in place when it has one band.
    /// Errors on other sample types.
    pub fn into_bytes(self) -> Result<Raster<u8>> {
        let (grid, bands) = (self.grid, self.bands);
        match self.samples {
            Samples::U8(v) if bands == 1 => Ok(Raster::new(grid, v)),
            Samples::U8(v) => Ok(Raster::new(grid, v.into_iter().step_by(bands).collect())),
            other => Err(Error::msg(format!(
                "holds {} samples, not the bytes of a class layer",
                other.type_name()
            ))
            .fix("write the layer as a Byte raster")),
        }
    }

    /// [`to_colour`](Self::to_colour), converting in place when the samples are RGBA bytes (a
    /// database's colour layer): no second copy of the band.
    pub fn into_colour(self) -> Result<Colour> {
        let (colour, alpha) = self.colour_layout()?;
        let rgba = self.bands == 4 && colour == 3 && alpha == Some(3);
        match self.samples {
            Samples::U8(v) if rgba => {
                // Same size and alignment: the bytes become pixels without a copy (the copy is
                // only for an allocation whose capacity is not a whole number of pixels).
                let mut px: Vec<[u8; 4]> = bytemuck::allocation::try_cast_vec(v)
                    .unwrap_or_else(|(_, v)| bytemuck::cast_slice(&v).to_vec());
                let nodata = self.nodata;
                px.par_chunks_mut(CHUNK).for_each(|chunk| {
                    for p in chunk {
                        *p = pixel_colour(p, 3, Some(3), nodata, |s| s);
                    }
                });
                Ok(Raster::new(self.grid, px))
            }
            _ => self.to_colour(),
        }
    }

    fn colour_values<T: SampleValue>(
        &self,
        v: &[T],
        colour: usize,
        alpha: Option<usize>,
        to8: impl Fn(T) -> u8 + Sync,
    ) -> Vec<[u8; 4]> {
        let (bands, nodata) = (self.bands, self.nodata);
        (0..self.grid.len())
            .into_par_iter()
            .map(|i| pixel_colour(&v[i * bands..(i + 1) * bands], colour, alpha, nodata, &to8))
            .collect()
    }
}

/// One pixel's colour from its samples `px`: the first `colour` bands (1 = grey, 3 = RGB)
/// through `to8`, alpha 255; [`NODATA_COLOUR`](crate::raster::NODATA_COLOUR) when band `alpha`
/// is 0 or every colour band equals `nodata`.
#[inline]
fn pixel_colour<T: SampleValue>(
    px: &[T],
    colour: usize,
    alpha: Option<usize>,
    nodata: Option<f64>,
    to8: impl Fn(T) -> u8,
) -> [u8; 4] {
    let masked = alpha.is_some_and(|a| px[a].into() == 0.0);
    let is_nd = nodata.is_some_and(|nd| px[..colour].iter().all(|s| s.is_nodata(nd)));
    if masked || is_nd {
        return crate::raster::NODATA_COLOUR;
    }
    let g = |b: usize| to8(px[b]);
    if colour == 1 {
        let y = g(0);
        [y, y, y, 255]
    } else {
        [g(0), g(1), g(2), 255]
    }
}

/// Cells per parallel work item in the conversions.
const CHUNK: usize = 1 << 15;

/// The kinds of file [`read_raster`] recognises by content.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Kind {
    Tiff,
    AsciiGrid,
    Png,
    Jpeg,
    Other,
}

/// Recognise a file by its first bytes.
fn sniff(head: &[u8]) -> Kind {
    match head {
        [b'I', b'I', 42 | 43, 0, ..] | [b'M', b'M', 0, 42 | 43, ..] => Kind::Tiff,
        [0x89, b'P', b'N', b'G', 0x0d, 0x0a, 0x1a, 0x0a, ..] => Kind::Png,
        [0xff, 0xd8, 0xff, ..] => Kind::Jpeg,
        _ if ascii_grid::looks_like(head) => Kind::AsciiGrid,
        _ => Kind::Other,
    }
}

/// Open any supported raster by content (magic bytes), not just extension: TIFF (`II*\0` /
/// `MM\0*` and BigTIFF) → GeoTIFF; text starting with an Esri header keyword such as `ncols`
/// (case-insensitive) → Esri ASCII grid; PNG / JPEG magic → image + world file. With feature
/// `gdal`, anything else GDAL can open (DTED, HGT, VRT, JP2...).
///
/// Errors: missing file, not a raster, truncated/corrupt data, no georeference.
pub fn read_raster(path: &Path) -> Result<SourceRaster> {
    match kind_of(path)? {
        (Kind::Tiff, _) => geotiff::read(path),
        (Kind::AsciiGrid, _) => ascii_grid::read(path),
        (Kind::Png | Kind::Jpeg, _) => image_world::read(path),
        (Kind::Other, n) => read_other(path, n),
    }
}

/// What kind of raster a file is, by its first bytes, and how many of those were there (< 64
/// only for a tiny file). Refused unless it is a regular file ([`open_regular`]).
fn kind_of(path: &Path) -> Result<(Kind, usize)> {
    let mut head = [0u8; 64];
    let n = {
        let mut f = open_regular(path)?;
        read_up_to(&mut f, &mut head).map_err(|e| Error::io(path, e))?
    };
    Ok((sniff(&head[..n]), n))
}

#[cfg(feature = "gdal")]
fn read_other(path: &Path, _len: usize) -> Result<SourceRaster> {
    gdal::read(path)
}

#[cfg(not(feature = "gdal"))]
fn read_other(path: &Path, len: usize) -> Result<SourceRaster> {
    let problem = if len == 0 {
        "empty file"
    } else {
        "not a TIFF, ASCII grid, PNG or JPEG file"
    };
    Err(Error::file(path, problem)
        .fix("give a GeoTIFF, Esri ASCII grid or PNG/JPEG with a world file, or build with --features gdal"))
}

/// Fill as much of `buf` as the reader has; returns the count (short only at end of file).
fn read_up_to(r: &mut impl Read, buf: &mut [u8]) -> std::io::Result<usize> {
    let mut n = 0;
    while n < buf.len() {
        match r.read(&mut buf[n..]) {
            Ok(0) => break,
            Ok(k) => n += k,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
            Err(e) => return Err(e),
        }
    }
    Ok(n)
}

/// The sibling file of `path` with extension `ext`, trying it as given, lower- and upper-case.
pub(crate) fn sibling(path: &Path, exts: &[&str]) -> Option<PathBuf> {
    exts.iter()
        .flat_map(|e| [e.to_string(), e.to_lowercase(), e.to_uppercase()])
        .map(|e| path.with_extension(e))
        .find(|p| p.is_file())
}

/// The error for the input `path`, which has no CRS, used with the `other` input (or the
/// database) in `crs`: an input without a CRS is never assumed to be in another's, and the fix
/// states the CRS beside the file, where every reader looks for it.
pub fn no_crs(path: &Path, other: &str, crs: &Crs) -> Error {
    let prj = path.with_extension("prj");
    Error::file(
        path,
        format!(
            "has no CRS (no GeoKeys, no .prj beside it) while the {other} is in {}",
            crs.name()
        ),
    )
    .fix(format!(
        "if it is in that CRS too, say so beside it: gdalsrsinfo -o wkt1 {} > {}",
        crs.epsg
            .map_or("EPSG:CODE".to_string(), |c| format!("EPSG:{c}")),
        prj.display()
    ))
}

/// The CRS of a raster from its sibling `.prj` (WKT), or unknown when there is none.
/// The EPSG code is taken from a final `AUTHORITY["EPSG","nnnn"]` (the CRS's own, not a
/// component's); geographic-ness from the WKT's outer keyword.
pub(crate) fn read_prj(raster: &Path) -> Result<Crs> {
    let Some(prj) = sibling(raster, &["prj"]) else {
        return Ok(Crs::unknown());
    };
    let text = read_settings(&prj)?;
    crs_from_wkt(text.trim()).ok_or_else(|| {
        Error::file(&prj, "not a WKT coordinate system")
            .fix("replace it with WKT, e.g. gdalsrsinfo -o wkt1 EPSG:32614 > file.prj")
    })
}

/// A CRS from OGC/Esri WKT (WKT1 or WKT2), or `None` if the text is not WKT.
pub(crate) fn crs_from_wkt(wkt: &str) -> Option<Crs> {
    let kind: String = wkt
        .chars()
        .take_while(|c| c.is_ascii_alphanumeric() || *c == '_')
        .collect();
    let kind = kind.to_ascii_uppercase();
    const PROJECTED: &[&str] = &[
        "PROJCS",
        "PROJCRS",
        "PROJECTEDCRS",
        "COMPD_CS",
        "COMPOUNDCRS",
    ];
    const GEOGRAPHIC: &[&str] = &[
        "GEOGCS",
        "GEOGCRS",
        "GEOGRAPHICCRS",
        "GEODCRS",
        "GEODETICCRS",
        "GEOCCS",
        "BOUNDCRS",
    ];
    if !(PROJECTED.contains(&kind.as_str()) || GEOGRAPHIC.contains(&kind.as_str()))
        || !wkt[kind.len()..].trim_start().starts_with('[')
    {
        return None;
    }
    let epsg = final_epsg(wkt);
    let geographic = matches!(kind.as_str(), "GEOGCS" | "GEOGCRS" | "GEOGRAPHICCRS")
        || (matches!(kind.as_str(), "GEODCRS" | "GEODETICCRS") && !wkt.contains("CARTESIAN"));
    let (foreign_unit, vertical_unit) = crate::crs::foreign_units_in_wkt(wkt);
    Some(Crs {
        epsg,
        wkt: Some(wkt.to_string()),
        geographic,
        foreign_unit: foreign_unit.filter(|_| !geographic),
        vertical_unit,
    })
}

/// The EPSG code of a WKT's outermost object: an `AUTHORITY["EPSG","n"]` (WKT1) or `ID["EPSG",n]`
/// (WKT2) followed only by closing brackets.
fn final_epsg(wkt: &str) -> Option<u32> {
    let body = wkt.trim_end().strip_suffix(']')?.trim_end();
    let body = body.strip_suffix(']')?;
    let start = body.rfind('[')?;
    let keyword = body[..start].trim_end();
    if !(keyword.ends_with("AUTHORITY") || keyword.ends_with("ID")) {
        return None;
    }
    let mut parts = body[start + 1..]
        .split(',')
        .map(|s| s.trim().trim_matches('"'));
    if !parts.next()?.eq_ignore_ascii_case("EPSG") {
        return None;
    }
    parts.next()?.parse().ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn raster(bands: usize, samples: Samples, nodata: Option<f64>) -> SourceRaster {
        let n = samples.len() / bands;
        SourceRaster {
            path: "t.tif".into(),
            grid: Grid::north_up(0.0, 0.0, 1.0, n, 1, Crs::unknown()),
            bands,
            samples,
            nodata,
            alpha_band: None,
            pixel_is_point: false,
            format: "GTiff",
        }
    }

    #[test]
    fn elevation_maps_nodata_nan_and_inf_to_nan() {
        let r = raster(
            1,
            Samples::F32(vec![1.5, -9999.0, f32::NAN, f32::INFINITY, -7.25]),
            Some(-9999.0),
        );
        let e = r.to_elevation().unwrap();
        assert_eq!(e.data[0], 1.5);
        assert!(e.data[1].is_nan() && e.data[2].is_nan() && e.data[3].is_nan());
        assert_eq!(e.data[4], -7.25);
        let r = raster(1, Samples::I16(vec![-32768, 12, -32767]), Some(-32768.0));
        let e = r.to_elevation().unwrap();
        assert!(e.data[0].is_nan());
        assert_eq!(&e.data[1..], &[12.0, -32767.0]);
    }

    #[test]
    fn in_place_elevation_band_equals_the_copying_one() {
        let nd = -3.4e38f64;
        let values = vec![
            1.5,
            -9999.0,
            f32::NAN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            nd as f32,
            -7.25,
        ];
        for nodata in [None, Some(-9999.0), Some(nd), Some(f64::NAN)] {
            let r = raster(1, Samples::F32(values.clone()), nodata);
            let copied = r.to_elevation_band().unwrap();
            let in_place = r.into_elevation_band().unwrap();
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(
                bits(&in_place.data),
                bits(&copied.data),
                "nodata {nodata:?}"
            );
        }
    }

    #[test]
    fn in_place_colour_equals_the_copying_one() {
        // RGBA (in place, also from a vector whose capacity is not whole pixels), and layouts
        // that take the copying path: RGB, grey + alpha, 16-bit RGBA.
        let rgba: Vec<u8> = vec![
            10, 20, 30, 255, 1, 2, 3, 0, 7, 7, 7, 128, 0, 0, 0, 255, 9, 9, 9, 9,
        ];
        let mut odd = Vec::with_capacity(rgba.len() + 3);
        odd.extend_from_slice(&rgba);
        let cases = [
            (4, Samples::U8(rgba.clone()), None),
            (4, Samples::U8(rgba.clone()), Some(9.0)),
            (4, Samples::U8(odd), Some(0.0)),
            (3, Samples::U8(rgba[..15].to_vec()), Some(7.0)),
            (2, Samples::U8(rgba.clone()), None),
            (
                4,
                Samples::U16(rgba.iter().map(|&s| s as u16 * 257).collect()),
                None,
            ),
        ];
        for (bands, samples, nodata) in cases {
            let r = raster(bands, samples, nodata);
            let copied = r.to_colour().unwrap();
            let in_place = r.into_colour().unwrap();
            assert_eq!(
                in_place.data, copied.data,
                "{bands} bands, nodata {nodata:?}"
            );
            assert_eq!(in_place.grid, copied.grid);
        }
    }

    #[test]
    fn float32_nodata_compares_in_float32() {
        // A nodata declared as text "-3.4e38" is not exactly representable: GDAL compares in f32.
        let nd = -3.4e38f64;
        let r = raster(1, Samples::F32(vec![nd as f32, 1.0]), Some(nd));
        assert!(r.to_elevation().unwrap().data[0].is_nan());
    }

    #[test]
    fn nan_nodata_matches_nan() {
        let r = raster(1, Samples::F64(vec![f64::NAN, 2.0]), Some(f64::NAN));
        let e = r.to_elevation().unwrap();
        assert!(e.data[0].is_nan());
        assert_eq!(e.data[1], 2.0);
    }

    #[test]
    fn all_nodata_is_an_error_naming_the_file() {
        let r = raster(1, Samples::I16(vec![-32768; 4]), Some(-32768.0));
        let e = r.to_elevation().unwrap_err().to_string();
        assert!(e.starts_with("t.tif: all cells are nodata"), "{e}");
    }

    #[test]
    fn int32_beyond_f32_precision_is_an_error() {
        let r = raster(1, Samples::I32(vec![16_777_217, 1]), None);
        assert!(r.to_elevation().is_err());
        let r = raster(1, Samples::I32(vec![16_777_216, -16_777_216]), None);
        assert_eq!(
            r.to_elevation().unwrap().data,
            vec![16_777_216.0, -16_777_216.0]
        );
    }

    #[test]
    fn colour_grey_rgb_rgba_and_16_bit() {
        let grey = raster(1, Samples::U8(vec![7, 200]), None)
            .to_colour()
            .unwrap();
        assert_eq!(grey.data, vec![[7, 7, 7, 255], [200, 200, 200, 255]]);
        let ga = raster(2, Samples::U8(vec![7, 0, 9, 128]), None)
            .to_colour()
            .unwrap();
        assert_eq!(ga.data, vec![[0, 0, 0, 0], [9, 9, 9, 255]]);
        let rgba = raster(4, Samples::U8(vec![1, 2, 3, 255, 4, 5, 6, 0]), None)
            .to_colour()
            .unwrap();
        assert_eq!(rgba.data, vec![[1, 2, 3, 255], [0, 0, 0, 0]]);
        let rgb16 = raster(
            3,
            Samples::U16(vec![0, 65535, 128, 32767, 32768, 257]),
            None,
        )
        .to_colour()
        .unwrap();
        // 128·255/65535 = 0.498 → 0; 32767·255/65535 = 127.498 → 127; 32768 → 127.502 → 128.
        assert_eq!(rgb16.data, vec![[0, 255, 0, 255], [127, 128, 1, 255]]);
    }

    #[test]
    fn colour_nodata_needs_all_colour_bands() {
        let r = raster(3, Samples::U8(vec![0, 0, 0, 0, 5, 0]), Some(0.0))
            .to_colour()
            .unwrap();
        assert_eq!(r.data, vec![[0, 0, 0, 0], [0, 5, 0, 255]]);
    }

    #[test]
    fn colour_rejects_floats_and_odd_band_counts() {
        let e = raster(1, Samples::F32(vec![0.5]), None)
            .to_colour()
            .unwrap_err()
            .to_string();
        assert!(e.contains("Float32") && e.contains("gdal_translate"), "{e}");
        assert!(raster(5, Samples::U8(vec![0; 5]), None)
            .to_colour()
            .is_err());
        let mut r = raster(4, Samples::U8(vec![1, 2, 3, 4]), None);
        r.alpha_band = Some(1);
        assert!(r.to_colour().is_err(), "alpha must follow the colour bands");
    }

    #[cfg(target_os = "linux")]
    #[test]
    fn fifos_and_devices_are_refused_by_every_reader_without_blocking() {
        let dir = tempfile::tempdir().unwrap();
        let fifo = dir.path().join("f.tif");
        let c = std::ffi::CString::new(fifo.as_os_str().as_encoded_bytes()).unwrap();
        assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o644) }, 0);
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            for (p, what) in [
                (fifo.as_path(), "a FIFO"),
                (Path::new("/dev/zero"), "a character device"),
            ] {
                let errors = [
                    read_text(p).err(),
                    read_settings(p).err(),
                    read_bytes(p).err(),
                    read_raster(p).err(),
                    input::RasterInput::open(p).err(),
                    geotiff::size(p).err(),
                ];
                for e in errors {
                    let e = e.expect("refused").to_string();
                    let _ = tx.send(e.contains(&format!("is {what}")).then_some(()).ok_or(e));
                }
            }
        });
        for _ in 0..12 {
            let got = rx.recv_timeout(std::time::Duration::from_secs(10));
            got.expect("a reader blocked")
                .unwrap_or_else(|e| panic!("{e}"));
        }
    }

    #[test]
    fn sniff_recognises_magic_bytes() {
        assert_eq!(sniff(b"II*\0rest"), Kind::Tiff);
        assert_eq!(sniff(b"MM\0*rest"), Kind::Tiff);
        assert_eq!(sniff(b"II+\0rest"), Kind::Tiff);
        assert_eq!(sniff(b"\x89PNG\r\n\x1a\nxx"), Kind::Png);
        assert_eq!(sniff(b"\xff\xd8\xff\xe0"), Kind::Jpeg);
        assert_eq!(sniff(b"NCOLS 3\n"), Kind::AsciiGrid);
        assert_eq!(sniff(b"hello"), Kind::Other);
        assert_eq!(sniff(b""), Kind::Other);
    }

    #[test]
    fn wkt_epsg_and_kind() {
        let utm = r#"PROJCS["WGS 84 / UTM zone 14N",GEOGCS["WGS 84",AUTHORITY["EPSG","4326"]],UNIT["metre",1,AUTHORITY["EPSG","9001"]],AUTHORITY["EPSG","32614"]]"#;
        let c = crs_from_wkt(utm).unwrap();
        assert_eq!((c.epsg, c.geographic), (Some(32614), false));
        let esri = r#"PROJCS["WGS_1984_UTM_Zone_14N",GEOGCS["GCS_WGS_1984",DATUM["D_WGS_1984"]],UNIT["Meter",1.0]]"#;
        assert_eq!(
            crs_from_wkt(esri).unwrap().epsg,
            None,
            "a component's AUTHORITY is not the CRS's"
        );
        let geo = r#"GEOGCS["WGS 84",DATUM["WGS_1984"],AUTHORITY["EPSG","4326"]]"#;
        let c = crs_from_wkt(geo).unwrap();
        assert_eq!((c.epsg, c.geographic), (Some(4326), true));
        let wkt2 = r#"GEOGCRS["WGS 84",DATUM["World Geodetic System 1984"],ID["EPSG",4326]]"#;
        assert_eq!(crs_from_wkt(wkt2).unwrap().epsg, Some(4326));
        assert!(crs_from_wkt("Projection UTM\nZone 14").is_none());
    }
}
