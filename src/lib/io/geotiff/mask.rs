//! A TIFF's internal mask (GDAL's `GDAL_TIFF_INTERNAL_MASK=YES`), read on the shared chunk
//! walk of [`crate::io::chunks`].

use super::corrupt;
use crate::error::{Error, Result};
use crate::io::chunks;
use std::io::{Read, Seek};
use std::ops::Range;
use std::path::Path;
use tiff::decoder::{Decoder, DecodingResult};
use tiff::tags::Tag;

/// NewSubfileType bits: a reduced-resolution copy (an overview), and a transparency mask.
const SUBFILE_REDUCED: u32 = 1;
const SUBFILE_MASK: u32 = 4;

/// The internal mask of image rows `rows`, one byte a cell, 0 where masked (nodata); `None`
/// when the file has none. The mask is the first IFD after the decoder's current one with
/// NewSubfileType's mask bit and not its reduced-resolution bit, as GDAL finds it. Only the
/// strips or tiles the rows overlap are read; a sparse one (byte count 0) is all masked, as
/// GDAL reads it. 1- or 8-bit, one sample, the image's size, uncompressed, LZW or Deflate
/// without predictor; other masks are an error with a fix.
pub(super) fn read<R: Read + Seek>(
    path: &Path,
    dec: &mut Decoder<R>,
    file: &std::fs::File,
    rows: Range<usize>,
) -> Result<Option<Vec<u8>>> {
    let err = |e| corrupt(path, e);
    let image = dec.dimensions().map_err(err)?;
    loop {
        if !dec.more_images() {
            return Ok(None);
        }
        dec.next_image().map_err(err)?;
        let kind: u32 = dec
            .find_tag_unsigned(Tag::NewSubfileType)
            .map_err(err)?
            .unwrap_or(0);
        if kind & SUBFILE_MASK != 0 && kind & SUBFILE_REDUCED == 0 {
            break;
        }
    }
    let mut unsigned = |tag, default: u64| -> Result<u64> {
        Ok(dec.find_tag_unsigned(tag).map_err(err)?.unwrap_or(default))
    };
    let bits = unsigned(Tag::BitsPerSample, 1)?;
    let spp = unsigned(Tag::SamplesPerPixel, 1)?;
    let compression = unsigned(Tag::Compression, 1)?;
    let predictor = unsigned(Tag::Predictor, 1)?;
    let size = dec.dimensions().map_err(err)?;
    let unsupported = || {
        Error::file(
            path,
            format!(
                "unsupported internal mask ({} × {} cells, {spp} sample(s) of {bits} bit(s), \
                 compression {compression}, predictor {predictor}; the image is {} × {})",
                size.0, size.1, image.0, image.1
            ),
        )
        .fix("make the mask an alpha band: gdal_translate -b 1 -b 2 -b 3 -b mask -co ALPHA=YES in.tif out.tif")
    };
    if size != image
        || spp != 1
        || !matches!(bits, 1 | 8)
        || !matches!(compression, 1 | 5 | 8 | 32946)
        || predictor != 1
    {
        return Err(unsupported());
    }
    let plan = chunks::layout(dec)
        .map_err(err)?
        .ok_or_else(|| {
            Error::file(path, "corrupt internal mask: no strip or tile offsets")
                .fix("re-create the file, or check it with gdalinfo")
        })?
        .with_fill(None);
    match chunks::decode(path, file, &plan, rows)? {
        DecodingResult::U8(mask) => Ok(Some(mask)),
        _ => Err(unsupported()),
    }
}
