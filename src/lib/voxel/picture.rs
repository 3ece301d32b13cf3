//! Plain (not georeferenced) view images: PNG, JPEG or TIFF, recognised by their magic bytes,
//! as 8-bit RGBA. Photos of an object carry no world file, so this is separate from
//! [`crate::io::read_raster`].
//!
//! # Invariant
//! `pixels.len() == width · height`, row-major, row 0 at the top; grey becomes `r = g = b`,
//! a missing alpha is 255 and 16-bit samples are scaled to 8 bits by rounding `v · 255 / 65535`.

use crate::error::{Error, Result};
use std::path::Path;

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
        let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
        match bytes.get(..4) {
            Some([b'I', b'I', 42, 0]) | Some([b'M', b'M', 0, 42]) => {
                read_tiff(&bytes).map_err(|e| e.in_file(path))
            }
            Some([0x89, b'P', b'N', b'G']) | Some([0xff, 0xd8, 0xff, _]) => {
                let img = image::load_from_memory(&bytes)
                    .map_err(|e| {
                        Error::file(path, format!("cannot decode the image: {e}"))
                            .fix("give a valid PNG, JPEG or TIFF")
                    })?
                    .to_rgba8();
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
}
