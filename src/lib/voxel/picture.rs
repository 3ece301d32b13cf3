//! Plain (not georeferenced) view images: PNG, JPEG or TIFF, recognised by their magic bytes,
//! as 8-bit RGBA. Photos of an object carry no world file, so this is separate from
//! [`crate::io::read_raster`].
//!
//! # Invariant
//! `pixels.len() == width · height`, row-major, row 0 at the top; grey becomes `r = g = b`,
//! a missing alpha is 255 and 16-bit samples are scaled to 8 bits by rounding `v · 255 / 65535`.

use crate::error::{Error, Result};
use std::path::Path;

/// Largest view image decoded, pixels: 100 million, a 100-megapixel camera's frame. A view is
/// held as RGBA8 (4 bytes a pixel) beside its silhouette, so this bounds a view's memory near
/// 1 GB. The size is read from the header and checked before anything is decoded: a small,
/// highly compressed file (a 389 KB PNG of 20000²) cannot make us allocate gigabytes.
pub const MAX_PIXELS: u64 = 100_000_000;

/// Refuse an image of more than [`MAX_PIXELS`], before it is decoded.
fn within_budget(width: u32, height: u32) -> Result<()> {
    let pixels = width as u64 * height as u64;
    if pixels <= MAX_PIXELS {
        return Ok(());
    }
    Err(Error::msg(format!(
        "is {width} x {height} pixels ({} megapixels), more than the {}-megapixel budget of a view image",
        pixels.div_ceil(1_000_000),
        MAX_PIXELS / 1_000_000
    ))
    .fix("downscale it, and its camera (fx, fy, cx, cy or scale) by the same factor: gdal_translate -outsize 50% 50% in.png out.png"))
}

/// An RGBA8 image.
#[derive(Debug, Clone, PartialEq)]
pub struct Picture {
    /// Width, pixels.
    pub width: u32,
    /// Height, pixels.
    pub height: u32,
    /// `[r, g, b, a]` per pixel, row-major.
    pub pixels: Vec<[u8; 4]>,
}

impl Picture {
    /// The pixel at `(col, row)`.
    #[inline]
    pub fn get(&self, col: u32, row: u32) -> [u8; 4] {
        self.pixels[row as usize * self.width as usize + col as usize]
    }

    /// Read a PNG, JPEG or TIFF file.
    pub fn read(path: &Path) -> Result<Picture> {
        let bytes = crate::io::read_bytes(path)?;
        match bytes.get(..4) {
            Some([b'I', b'I', 42, 0]) | Some([b'M', b'M', 0, 42]) => {
                read_tiff(&bytes).map_err(|e| e.in_file(path))
            }
            Some([0x89, b'P', b'N', b'G']) | Some([0xff, 0xd8, 0xff, _]) => {
                let bad = |e: image::ImageError| {
                    Error::file(path, format!("cannot decode the image: {e}"))
                        .fix("give a valid PNG, JPEG or TIFF")
                };
                let reader = || {
                    image::ImageReader::new(std::io::Cursor::new(&bytes))
                        .with_guessed_format()
                        .map_err(|e| Error::io(path, e))
                };
                let (w, h) = reader()?.into_dimensions().map_err(bad)?;
                within_budget(w, h).map_err(|e| e.in_file(path))?;
                let img = reader()?.decode().map_err(bad)?.to_rgba8();
                let (width, height) = img.dimensions();
                Ok(Picture {
                    width,
                    height,
                    pixels: img.pixels().map(|p| p.0).collect(),
                })
            }
            _ => Err(Error::file(
                path,
                "not a PNG, JPEG or TIFF image (unrecognised magic bytes)",
            )
            .fix("convert the view image to PNG")),
        }
    }
}

fn read_tiff(bytes: &[u8]) -> Result<Picture> {
    use tiff::decoder::{Decoder, DecodingResult};
    use tiff::ColorType;
    let bad = |e: tiff::TiffError| {
        Error::msg(format!("cannot decode the TIFF: {e}"))
            .fix("give an 8- or 16-bit grey, RGB or RGBA TIFF")
    };
    let mut dec = Decoder::new(std::io::Cursor::new(bytes)).map_err(bad)?;
    let (width, height) = dec.dimensions().map_err(bad)?;
    within_budget(width, height)?;
    let channels = match dec.colortype().map_err(bad)? {
        ColorType::Gray(8 | 16) => 1,
        ColorType::GrayA(8 | 16) => 2,
        ColorType::RGB(8 | 16) => 3,
        ColorType::RGBA(8 | 16) => 4,
        other => {
            return Err(Error::msg(format!(
                "TIFF colour type {other:?} is not supported for view images"
            ))
            .fix("convert it to 8-bit RGB: gdal_translate -ot Byte -scale in.tif out.tif"))
        }
    };
    let samples: Vec<u8> = match dec.read_image().map_err(bad)? {
        DecodingResult::U8(v) => v,
        DecodingResult::U16(v) => v
            .iter()
            .map(|&s| ((s as u32 * 255 + 32767) / 65535) as u8)
            .collect(),
        _ => {
            return Err(Error::msg("TIFF samples are not 8- or 16-bit unsigned")
                .fix("convert it: gdal_translate -ot Byte -scale in.tif out.tif"))
        }
    };
    if samples.len() != width as usize * height as usize * channels {
        return Err(Error::msg(
            "TIFF holds fewer samples than its size says (truncated?)",
        ));
    }
    let pixels = samples
        .chunks_exact(channels)
        .map(|p| match p {
            [g] => [*g, *g, *g, 255],
            [g, a] => [*g, *g, *g, *a],
            [r, g, b] => [*r, *g, *b, 255],
            [r, g, b, a] => [*r, *g, *b, *a],
            _ => unreachable!("chunks of 1..=4"),
        })
        .collect();
    Ok(Picture {
        width,
        height,
        pixels,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn png_and_tiff_read_the_same_pixels() {
        let dir = tempfile::tempdir().unwrap();
        let (w, h) = (5u32, 3u32);
        let rgb: Vec<u8> = (0..w * h * 3).map(|i| (i * 7) as u8).collect();
        let png = dir.path().join("a.png");
        image::save_buffer(&png, &rgb, w, h, image::ExtendedColorType::Rgb8).unwrap();
        let tif = dir.path().join("a.tif");
        let mut f = std::fs::File::create(&tif).unwrap();
        let mut enc = tiff::encoder::TiffEncoder::new(&mut f).unwrap();
        enc.write_image::<tiff::encoder::colortype::RGB8>(w, h, &rgb)
            .unwrap();
        drop(f);
        let (a, b) = (Picture::read(&png).unwrap(), Picture::read(&tif).unwrap());
        assert_eq!(a, b);
        assert_eq!(a.get(1, 0), [3 * 7, 4 * 7, 5 * 7, 255]);
        let txt = dir.path().join("a.txt");
        std::fs::write(&txt, "hello").unwrap();
        assert!(Picture::read(&txt)
            .unwrap_err()
            .to_string()
            .contains("magic"));
    }

    /// A small file declaring a huge image is refused from its header, before any decoding
    /// allocates for it.
    #[test]
    fn an_image_over_the_pixel_budget_is_refused_before_decoding() {
        let dir = tempfile::tempdir().unwrap();
        // A PNG whose header says 20000 x 20000 grey pixels: signature, IHDR, the start of a
        // zlib stream in IDAT, IEND.
        let chunk = |kind: &[u8], data: &[u8]| {
            let mut c = (data.len() as u32).to_be_bytes().to_vec();
            c.extend_from_slice(kind);
            c.extend_from_slice(data);
            let crc = crc32fast::hash(&c[4..]);
            c.extend_from_slice(&crc.to_be_bytes());
            c
        };
        let mut ihdr = [20_000u32.to_be_bytes(), 20_000u32.to_be_bytes()].concat();
        ihdr.extend_from_slice(&[8, 0, 0, 0, 0]);
        let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
        png.extend(chunk(b"IHDR", &ihdr));
        png.extend(chunk(b"IDAT", &[0x78, 0x9c, 0x03, 0x00]));
        png.extend(chunk(b"IEND", &[]));
        let big_png = dir.path().join("big.png");
        std::fs::write(&big_png, png).unwrap();
        // A 1 x 1 TIFF whose width and height tags are patched to 20000.
        let mut tif = std::io::Cursor::new(Vec::new());
        tiff::encoder::TiffEncoder::new(&mut tif)
            .unwrap()
            .write_image::<tiff::encoder::colortype::Gray8>(1, 1, &[0])
            .unwrap();
        let mut tif = tif.into_inner();
        let ifd = u32::from_le_bytes(tif[4..8].try_into().unwrap()) as usize;
        let n = u16::from_le_bytes(tif[ifd..ifd + 2].try_into().unwrap()) as usize;
        for e in (0..n).map(|k| ifd + 2 + 12 * k) {
            let tag = u16::from_le_bytes(tif[e..e + 2].try_into().unwrap());
            if tag == 256 || tag == 257 {
                tif[e + 8..e + 12].copy_from_slice(&20_000u32.to_le_bytes());
            }
        }
        let big_tif = dir.path().join("big.tif");
        std::fs::write(&big_tif, tif).unwrap();
        for p in [big_png, big_tif] {
            let e = Picture::read(&p).unwrap_err().to_string();
            assert!(
                e.contains(
                    "is 20000 x 20000 pixels (400 megapixels), more than the 100-megapixel budget"
                ),
                "{e}"
            );
            assert!(e.starts_with(p.to_str().unwrap()), "{e}");
        }
    }
}
