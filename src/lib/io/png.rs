//! 8-bit RGB PNG encoding: no alpha, no metadata, the same bytes for the same pixels.

use crate::error::{Error, Result};
use image::ImageEncoder;

/// `rgb` (row-major, 3 bytes a pixel, `width × height` pixels) as PNG bytes.
pub fn encode_rgb(width: usize, height: usize, rgb: &[u8]) -> Result<Vec<u8>> {
    let mut out = Vec::new();
    image::codecs::png::PngEncoder::new(&mut out)
        .write_image(
            rgb,
            width as u32,
            height as u32,
            image::ExtendedColorType::Rgb8,
        )
        .map_err(|e| Error::msg(format!("encoding the PNG failed: {e}")))?;
    Ok(out)
}

/// `rgb` ([`encode_rgb`]) written to a temporary file beside `path`, staged for
/// [`crate::io::atomic::commit_all`].
pub fn stage_rgb(
    path: &std::path::Path,
    width: usize,
    height: usize,
    rgb: &[u8],
) -> Result<crate::io::atomic::Staged> {
    let bytes = encode_rgb(width, height, rgb)?;
    let mut file = crate::io::atomic::AtomicFile::create(path)?;
    std::io::Write::write_all(file.writer(), &bytes).map_err(|e| Error::io(path, e))?;
    file.stage()
}
