//! GDAL-backed reading of any raster GDAL opens (DTED, SRTM HGT, VRT, JPEG 2000, ...) and
//! reprojection onto a target grid (feature `gdal`, needs libgdal).
//!
//! # Invariant
//! Results obey the [`SourceRaster`] contract of [`crate::io`]: corner-convention grid (GDAL's own
//! geotransform, already corrected for PixelIsPoint), pixel-interleaved samples in a type that
//! holds every input value exactly, nodata and alpha as GDAL reports them. Reprojection is
//! `gdalwarp` itself (GDAL's warp utility called as a library) onto a destination whose
//! geotransform and CRS are set from the target [`Grid`] exactly, so its cells are the grid's cells.

use super::{crs_from_wkt, Samples, SourceRaster};
use crate::crs::Crs;
use crate::error::{Error, Result};
use crate::grid::{GeoTransform, Grid, NotNorthUp};
use gdal::cpl::CslStringList;
use gdal::raster::{ColorInterpretation, GdalDataType, GdalType};
use gdal::spatial_ref::SpatialRef;
use gdal::{Dataset, DriverManager, Metadata};
use std::ffi::{c_char, c_int, c_void, CStr};
use std::path::Path;
use std::sync::Mutex;

// GDAL's warp utility as a library (gdal_utils.h). The `gdal` crate links libgdal but does not
// wrap these; declaring the three functions avoids depending on gdal-sys directly.
extern "C" {
    fn GDALWarpAppOptionsNew(argv: *mut *mut c_char, for_binary: *mut c_void) -> *mut c_void;
    fn GDALWarpAppOptionsFree(options: *mut c_void);
    fn GDALWarp(
        dest: *const c_char,
        dst_ds: *mut c_void,
        n_src: c_int,
        src_ds: *mut *mut c_void,
        options: *const c_void,
        usage_error: *mut c_int,
    ) -> *mut c_void;
    fn CPLGetLastErrorMsg() -> *const c_char;
    fn CPLErrorReset();
}

/// Read any raster GDAL can open. EPSG code from the SRS's authority code, WKT kept.
pub fn read(path: &Path) -> Result<SourceRaster> {
    let ds = Dataset::open(path).map_err(|e| {
        // GDAL says nothing when no driver recognises the file: say what was tried instead.
        let why = match &e {
            gdal::errors::GdalError::NullPointer { msg, .. } if msg.trim().is_empty() => {
                String::new()
            }
            _ => format!(" ({})", one_line(&e.to_string())),
        };
        Error::file(
            path,
            format!("not a TIFF, ASCII grid, PNG or JPEG file, nor a raster GDAL can open{why}"),
        )
        .fix("check the file with gdalinfo")
    })?;
    let transform = geotransform(path, &ds)?;
    let (w, h) = ds.raster_size();
    let crs = crs_of(path, &ds)?;
    let pixel_is_point = ds
        .metadata_item("AREA_OR_POINT", "")
        .is_some_and(|v| v.eq_ignore_ascii_case("Point"));
    from_dataset(
        path,
        &ds,
        Grid {
            width: w,
            height: h,
            transform,
            crs,
        },
        pixel_is_point,
    )
}

/// Reproject the raster at `path` onto `grid` (cells and CRS) with `resampling` one of
/// `nearest`, `bilinear`, `cubic`, `average` (gdalwarp's `near`, `bilinear`, `cubic`, `average`).
///
/// Byte and UInt16 rasters (imagery) come back in their type with an added alpha band (the last)
/// that is 0 outside the source and where the source was nodata or transparent. Every other type
/// comes back as Float64, nodata NaN outside the source and where the source was nodata.
pub fn warp_to_grid(path: &Path, grid: &Grid, resampling: &str) -> Result<SourceRaster> {
    let alg = match resampling {
        "nearest" => "near",
        "bilinear" | "cubic" | "average" => resampling,
        other => {
            return Err(Error::msg(format!("unknown resampling '{other}'"))
                .fix("use nearest, bilinear, cubic or average"));
        }
    };
    let src = Dataset::open(path).map_err(|e| {
        Error::file(
            path,
            format!("GDAL cannot open it ({})", one_line(&e.to_string())),
        )
    })?;
    if src.spatial_ref().is_err() {
        return Err(
            Error::file(path, "has no coordinate system to reproject from")
                .fix("assign one: gdal_translate -a_srs EPSG:CODE in out.tif"),
        );
    }
    let dst_wkt = target_wkt(&grid.crs)?;
    let kind = band_kind(path, &src)?;
    let src_alpha = alpha_band(&src)?;
    if src_alpha.is_some_and(|a| a + 1 != src.raster_count()) {
        return Err(Error::file(path, "the alpha band is not the last band")
            .fix("reorder: gdal_translate -b 1 -b 2 -b 3 -b 4 in out.tif"));
    }
    let colour_bands = src.raster_count() - usize::from(src_alpha.is_some());
    let imagery = matches!(kind, GdalDataType::UInt8 | GdalDataType::UInt16);
    let mem = DriverManager::get_driver_by_name("MEM")
        .map_err(|e| Error::msg(format!("GDAL has no MEM driver: {e}")))?;
    let (w, h) = (grid.width, grid.height);
    let mut dst = match (imagery, kind) {
        (true, GdalDataType::UInt8) => {
            mem.create_with_band_type::<u8, _>("", w, h, colour_bands + 1)
        }
        (true, _) => mem.create_with_band_type::<u16, _>("", w, h, colour_bands + 1),
        _ => mem.create_with_band_type::<f64, _>("", w, h, src.raster_count()),
    }
    .map_err(|e| Error::msg(format!("cannot create a {w} × {h} warp destination: {e}")))?;
    let gdal_err = |e: gdal::errors::GdalError| {
        Error::file(path, format!("GDAL: {}", one_line(&e.to_string())))
    };
    dst.set_geo_transform(&grid.transform.to_gdal())
        .map_err(gdal_err)?;
    dst.set_projection(&dst_wkt).map_err(gdal_err)?;

    let mut args = vec!["-r", alg, "-wo", "INIT_DEST=NO_DATA"];
    if imagery {
        args.push("-dstalpha");
        if src_alpha.is_some() {
            args.push("-srcalpha");
        }
        let mut band = dst.rasterband(colour_bands + 1).map_err(gdal_err)?;
        band.set_color_interpretation(ColorInterpretation::AlphaBand)
            .map_err(gdal_err)?;
    } else {
        args.extend(["-dstnodata", "nan"]);
        // gdalwarp leaves the destination untouched when it does not overlap the source at all.
        for i in 1..=dst.raster_count() {
            let mut band = dst.rasterband(i).map_err(gdal_err)?;
            band.set_no_data_value(Some(f64::NAN)).map_err(gdal_err)?;
            band.fill(f64::NAN, None).map_err(gdal_err)?;
        }
    }
    run_gdalwarp(path, &src, &dst, &args)?;

    let alpha = imagery.then_some(colour_bands);
    let mut out = from_dataset(path, &dst, grid.clone(), false)?;
    out.alpha_band = alpha;
    out.nodata = if imagery { None } else { Some(f64::NAN) };
    out.format = intern(format!("GDAL:{}", src.driver().short_name()));
    Ok(out)
}

/// Call GDAL's warp utility with `args` from `src` into the existing `dst`.
fn run_gdalwarp(path: &Path, src: &Dataset, dst: &Dataset, args: &[&str]) -> Result<()> {
    let mut argv = CslStringList::new();
    for a in args {
        argv.add_string(a)
            .map_err(|e| Error::msg(format!("bad gdalwarp option {a}: {e}")))?;
    }
    // SAFETY: argv, src and dst outlive the calls; GDAL copies what it keeps from argv; the options
    // are freed exactly once; GDALWarp returns `dst` (owned by `dst`) or null, never a new handle
    // we would have to close, because a destination dataset is given.
    let ok = unsafe {
        CPLErrorReset();
        let options = GDALWarpAppOptionsNew(argv.as_ptr(), std::ptr::null_mut());
        if options.is_null() {
            return Err(Error::msg(format!(
                "gdalwarp rejected options {args:?}: {}",
                last_gdal_error()
            )));
        }
        let mut src_handle = src.c_dataset();
        let mut usage_error: c_int = 0;
        let out = GDALWarp(
            std::ptr::null(),
            dst.c_dataset(),
            1,
            &mut src_handle,
            options,
            &mut usage_error,
        );
        GDALWarpAppOptionsFree(options);
        !out.is_null()
    };
    if !ok {
        return Err(
            Error::file(path, format!("reprojection failed: {}", last_gdal_error()))
                .fix("check that gdalwarp can reproject it"),
        );
    }
    Ok(())
}

fn last_gdal_error() -> String {
    // SAFETY: CPLGetLastErrorMsg returns a valid NUL-terminated string owned by GDAL (never null).
    let msg = unsafe { CStr::from_ptr(CPLGetLastErrorMsg()) };
    one_line(&msg.to_string_lossy())
}

fn one_line(s: &str) -> String {
    s.split_whitespace().collect::<Vec<_>>().join(" ")
}

/// A `&'static` copy of a format name (one per GDAL driver, so the set stays tiny).
fn intern(name: String) -> &'static str {
    static NAMES: Mutex<Vec<&'static str>> = Mutex::new(Vec::new());
    let mut names = NAMES.lock().unwrap_or_else(|p| p.into_inner());
    if let Some(n) = names.iter().find(|n| **n == name) {
        return n;
    }
    let leaked: &'static str = Box::leak(name.into_boxed_str());
    names.push(leaked);
    leaked
}

/// The north-up geotransform; rotation and missing georeference are errors.
fn geotransform(path: &Path, ds: &Dataset) -> Result<GeoTransform> {
    let gt = ds.geo_transform().map_err(|_| {
        Error::file(path, "no georeference")
            .fix("assign one: gdal_translate -a_ullr ULX ULY LRX LRY -a_srs EPSG:CODE in out.tif")
    })?;
    GeoTransform::north_up([gt[0], gt[3]], [gt[1], gt[5]], [gt[2], gt[4]]).map_err(|e| match e {
        NotNorthUp::Sheared => Error::file(
            path,
            format!(
                "rotated or sheared georeference (terms {}, {})",
                gt[2], gt[4]
            ),
        )
        .fix("make it north-up first: gdalwarp in out.tif"),
        NotNorthUp::BadGeometry => Error::file(path, format!("bad georeference {gt:?}")),
    })
}

/// The dataset's CRS: EPSG code when the SRS's authority is EPSG, WKT always.
fn crs_of(path: &Path, ds: &Dataset) -> Result<Crs> {
    let Ok(srs) = ds.spatial_ref() else {
        return Ok(Crs::unknown());
    };
    let wkt = srs
        .to_wkt()
        .map_err(|e| Error::file(path, format!("cannot express its CRS as WKT: {e}")))?;
    let epsg = match srs.auth_name() {
        Some(a) if a.eq_ignore_ascii_case("EPSG") => {
            srs.auth_code().ok().and_then(|c| u32::try_from(c).ok())
        }
        _ => None,
    };
    let mut crs = crs_from_wkt(&wkt).unwrap_or_default();
    crs.epsg = epsg;
    crs.wkt = Some(wkt);
    crs.geographic = srs.is_geographic();
    Ok(crs)
}

/// The WKT of a target CRS, for the warp destination.
fn target_wkt(crs: &Crs) -> Result<String> {
    let srs = match (crs.epsg, &crs.wkt) {
        (Some(code), _) => SpatialRef::from_epsg(code),
        (None, Some(wkt)) => SpatialRef::from_definition(wkt),
        (None, None) => {
            return Err(Error::msg("the target grid has no CRS to reproject to")
                .fix("give the database a CRS (e.g. --crs EPSG:32614)"))
        }
    };
    srs.and_then(|s| s.to_wkt()).map_err(|e| {
        Error::msg(format!(
            "GDAL does not know the target CRS {}: {e}",
            crs.name()
        ))
    })
}

/// The one sample type that holds every band exactly (mixed types widen to Float64).
fn band_kind(path: &Path, ds: &Dataset) -> Result<GdalDataType> {
    let mut kind = None;
    for i in 1..=ds.raster_count() {
        let band = ds
            .rasterband(i)
            .map_err(|e| Error::file(path, format!("band {i}: {e}")))?;
        let t = band.band_type();
        if band.scale().is_some_and(|s| s != 1.0) || band.offset().is_some_and(|o| o != 0.0) {
            return Err(Error::file(
                path,
                format!("band {i} has a scale/offset (values are not in their final units)"),
            )
            .fix("apply it: gdal_translate -unscale -ot Float32 in out.tif"));
        }
        kind = Some(match kind {
            None => t,
            Some(k) if k == t => k,
            Some(_) => GdalDataType::Float64,
        });
    }
    kind.ok_or_else(|| Error::file(path, "has no raster bands"))
}

/// The 0-based index of the band GDAL marks as alpha, which must be the last.
fn alpha_band(ds: &Dataset) -> Result<Option<usize>> {
    let n = ds.raster_count();
    let alpha = (1..=n).find(|&i| {
        ds.rasterband(i)
            .is_ok_and(|b| b.color_interpretation() == ColorInterpretation::AlphaBand)
    });
    Ok(alpha.map(|i| i - 1))
}

/// Read every band of `ds` (pixel-interleaved, in the narrowest exact type) onto `grid`.
fn from_dataset(
    path: &Path,
    ds: &Dataset,
    grid: Grid,
    pixel_is_point: bool,
) -> Result<SourceRaster> {
    let bands = ds.raster_count();
    let samples = match band_kind(path, ds)? {
        GdalDataType::UInt8 => Samples::U8(read_bands(path, ds)?),
        GdalDataType::UInt16 => Samples::U16(read_bands(path, ds)?),
        GdalDataType::Int16 => Samples::I16(read_bands(path, ds)?),
        GdalDataType::UInt32 => Samples::U32(read_bands(path, ds)?),
        GdalDataType::Int32 => Samples::I32(read_bands(path, ds)?),
        GdalDataType::Float32 => Samples::F32(read_bands(path, ds)?),
        GdalDataType::Float64 => Samples::F64(read_bands(path, ds)?),
        other => {
            return Err(
                Error::file(path, format!("unsupported sample type {other:?}"))
                    .fix("convert it: gdal_translate -ot Float64 in out.tif"),
            )
        }
    };
    let first = ds
        .rasterband(1)
        .map_err(|e| Error::file(path, format!("band 1: {e}")))?;
    let alpha = alpha_band(ds)?;
    if alpha.is_some_and(|a| a + 1 != bands) {
        return Err(Error::file(path, "the alpha band is not the last band")
            .fix("reorder: gdal_translate -b 1 -b 2 -b 3 -b 4 in out.tif"));
    }
    Ok(SourceRaster {
        path: path.to_path_buf(),
        grid,
        bands,
        samples,
        nodata: first.no_data_value(),
        alpha_band: alpha,
        pixel_is_point,
        format: intern(format!("GDAL:{}", ds.driver().short_name())),
    })
}

/// All bands as `T` (GDAL converts exactly: `T` is wide enough for every band), interleaved.
fn read_bands<T: GdalType + Copy + Default + Send + Sync>(
    path: &Path,
    ds: &Dataset,
) -> Result<Vec<T>> {
    let (w, h) = ds.raster_size();
    let bands = ds.raster_count();
    let mut planes = Vec::with_capacity(bands);
    for i in 1..=bands {
        let band = ds
            .rasterband(i)
            .map_err(|e| Error::file(path, format!("band {i}: {e}")))?;
        let mut plane = vec![T::default(); w * h];
        band.read_into_slice::<T>((0, 0), (w, h), (w, h), &mut plane, None)
            .map_err(|e| {
                Error::file(
                    path,
                    format!(
                        "corrupt or truncated data in band {i}: {}",
                        one_line(&e.to_string())
                    ),
                )
            })?;
        planes.push(plane);
    }
    if bands == 1 {
        return Ok(planes.pop().unwrap_or_default());
    }
    Ok((0..w * h * bands)
        .map(|i| planes[i % bands][i / bands])
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn intern_returns_the_same_str() {
        let a = intern("GDAL:DTED".to_string());
        let b = intern("GDAL:DTED".to_string());
        assert!(std::ptr::eq(a, b));
    }

    #[test]
    fn unknown_resampling_is_an_error() {
        let g = Grid::north_up(0.0, 1.0, 1.0, 1, 1, Crs::epsg(4326));
        let e = warp_to_grid(Path::new("x.tif"), &g, "lanczos")
            .unwrap_err()
            .to_string();
        assert!(e.contains("nearest, bilinear, cubic or average"), "{e}");
    }
}
