//! PNG and JPEG images georeferenced by a world file (and an optional `.prj`).
//!
//! # Invariant
//! A world file's six lines `A D B E C F` give the **centre** of the top-left pixel at `(C, F)`;
//! we return the corner-convention grid, origin `(C − A/2, F − E/2)`, and refuse rotation terms
//! (`D`, `B` ≠ 0) rather than drop them.

use super::{read_prj, sibling, Samples, SourceRaster};
use crate::error::{Error, Result};
use crate::grid::{GeoTransform, Grid, NotNorthUp};
use image::DynamicImage;
use std::path::{Path, PathBuf};

/// Largest image we decode, bytes (a corrupt header must not make us allocate without bound).
const MAX_DECODED_BYTES: u64 = 16 << 30;

/// Read a PNG or JPEG (8- or 16-bit grey, grey+alpha, RGB, RGBA) and its world file.
/// Errors: corrupt data, or no world file (fix: write one or use a GeoTIFF).
pub fn read(path: &Path) -> Result<SourceRaster> {
    let reader = image::ImageReader::open(path)
        .map_err(|e| Error::io(path, e))?
        .with_guessed_format()
        .map_err(|e| Error::io(path, e))?;
    let format = match reader.format() {
        Some(image::ImageFormat::Png) => "PNG",
        Some(image::ImageFormat::Jpeg) => "JPEG",
        _ => {
            return Err(Error::file(path, "not a PNG or JPEG image")
                .fix("give a PNG or JPEG with a world file"))
        }
    };
    let mut reader = reader;
    let mut limits = image::Limits::default();
    limits.max_alloc = Some(MAX_DECODED_BYTES);
    reader.limits(limits);
    let img = reader
        .decode()
        .map_err(|e| Error::file(path, format!("corrupt or truncated {format} image: {e}")))?;
    let (width, height) = (img.width() as usize, img.height() as usize);
    let (samples, bands, alpha_band) = samples_of(path, img)?;
    let transform = read_world_file(path)?.ok_or_else(|| {
        Error::file(path, "no georeference (no world file beside the image)").fix(format!(
            "write a world file {} (six lines: cell width, 0, 0, -cell height, centre x and centre y of the top-left pixel) or convert to a GeoTIFF with gdal_translate -a_ullr",
            path.with_extension("wld").display()
        ))
    })?;
    let crs = read_prj(path)?;
    Ok(SourceRaster {
        path: path.to_path_buf(),
        grid: Grid {
            width,
            height,
            transform,
            crs,
        },
        bands,
        samples,
        nodata: None,
        alpha_band,
        pixel_is_point: false,
        format,
    })
}

/// The samples, band count and alpha band of a decoded image.
fn samples_of(path: &Path, img: DynamicImage) -> Result<(Samples, usize, Option<usize>)> {
    Ok(match img {
        DynamicImage::ImageLuma8(i) => (Samples::U8(i.into_raw()), 1, None),
        DynamicImage::ImageLumaA8(i) => (Samples::U8(i.into_raw()), 2, Some(1)),
        DynamicImage::ImageRgb8(i) => (Samples::U8(i.into_raw()), 3, None),
        DynamicImage::ImageRgba8(i) => (Samples::U8(i.into_raw()), 4, Some(3)),
        DynamicImage::ImageLuma16(i) => (Samples::U16(i.into_raw()), 1, None),
        DynamicImage::ImageLumaA16(i) => (Samples::U16(i.into_raw()), 2, Some(1)),
        DynamicImage::ImageRgb16(i) => (Samples::U16(i.into_raw()), 3, None),
        DynamicImage::ImageRgba16(i) => (Samples::U16(i.into_raw()), 4, Some(3)),
        other => {
            return Err(
                Error::file(path, format!("unsupported pixel type {:?}", other.color()))
                    .fix("convert it to 8-bit RGB or RGBA"),
            )
        }
    })
}

/// The world-file names tried beside `path`: the conventional `<first><last>w` (`.pgw`, `.jgw`,
/// `.tfw`), `<ext>w` (`.pngw`, `.jpgw`, `.tifw`), the common ones for PNG/JPEG/TIFF, and `.wld`.
fn world_file_candidates(path: &Path) -> Vec<String> {
    let mut exts = Vec::new();
    if let Some(ext) = path
        .extension()
        .and_then(|e| e.to_str())
        .filter(|e| e.len() >= 2)
    {
        let (first, last) = (&ext[..1], &ext[ext.len() - 1..]);
        exts.push(format!("{first}{last}w"));
        exts.push(format!("{ext}w"));
    }
    for e in [
        "pgw", "pngw", "jgw", "jpgw", "jpegw", "tfw", "tifw", "tiffw", "wld",
    ] {
        if !exts.iter().any(|x| x.eq_ignore_ascii_case(e)) {
            exts.push(e.to_string());
        }
    }
    exts
}

/// The world file beside `path`, if there is one.
pub fn find_world_file(path: &Path) -> Option<PathBuf> {
    let exts = world_file_candidates(path);
    let refs: Vec<&str> = exts.iter().map(String::as_str).collect();
    sibling(path, &refs)
}

/// The corner-convention transform from the world file beside `path`, or `None` if there is none.
pub fn read_world_file(path: &Path) -> Result<Option<GeoTransform>> {
    let Some(wf) = find_world_file(path) else {
        return Ok(None);
    };
    let text = super::read_settings(&wf)?;
    parse_world_file(&text)
        .map(Some)
        .map_err(|e| e.in_file(&wf))
}

/// Parse the six lines `A D B E C F` of a world file into a corner-convention transform.
pub fn parse_world_file(text: &str) -> Result<GeoTransform> {
    let mut v = [0.0f64; 6];
    let mut lines = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty());
    for slot in v.iter_mut() {
        let (n, line) = lines.next().ok_or_else(|| {
            Error::msg("world file has fewer than six lines")
                .fix("give A, D, B, E, C, F one per line")
        })?;
        *slot = line
            .trim()
            .parse::<f64>()
            .ok()
            .filter(|x| x.is_finite())
            .ok_or_else(|| {
                Error::msg(format!("line {}: '{}' is not a number", n + 1, line.trim()))
            })?;
    }
    let [a, d, b, e, c, f] = v;
    // The world file gives the centre of the top-left pixel: the corner is half a cell off.
    GeoTransform::north_up([c - 0.5 * a, f - 0.5 * e], [a, e], [d, b]).map_err(|p| match p {
        NotNorthUp::Sheared => Error::msg(format!(
            "world file is rotated or sheared (D = {d}, B = {b})"
        ))
        .fix("make the image north-up first: gdalwarp in.png out.tif"),
        NotNorthUp::BadGeometry => {
            Error::msg(format!("world file has a bad cell size (A = {a}, E = {e})"))
                .fix("A must be the positive cell width and E the (usually negative) cell height")
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn world_file_centre_becomes_corner() {
        let t = parse_world_file("2.0\n0\n0\n-2.0\n500001.0\n4999999.0\n").unwrap();
        assert_eq!(
            t,
            GeoTransform {
                origin_x: 500_000.0,
                origin_y: 5_000_000.0,
                cell_x: 2.0,
                cell_y: -2.0
            }
        );
    }

    #[test]
    fn world_file_errors_name_the_problem() {
        let e = parse_world_file("1\n0.1\n0\n-1\n0\n0\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("rotated"), "{e}");
        let e = parse_world_file("1\n0\n0\n-1\nx\n0\n")
            .unwrap_err()
            .to_string();
        assert!(e.contains("line 5") && e.contains("'x'"), "{e}");
        assert!(parse_world_file("1\n0\n0\n-1\n").is_err());
        assert!(parse_world_file("0\n0\n0\n-1\n0\n0\n").is_err());
    }

    #[test]
    fn world_file_names() {
        let c = world_file_candidates(Path::new("a/ortho.png"));
        assert_eq!(&c[..2], &["pgw", "pngw"]);
        assert!(c.contains(&"wld".to_string()));
        let c = world_file_candidates(Path::new("ortho.jpeg"));
        assert_eq!(&c[..2], &["jgw", "jpegw"]);
    }
}
