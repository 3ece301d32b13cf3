//! Reading an input file: regular files only, and text within a cap.
//!
//! Invariant: every file dbms reads as input is opened through [`open_regular`], which refuses
//! a FIFO, a device, a socket or a directory from its metadata before opening it (so nothing
//! blocks, and `/dev/zero` is never read); text is read through [`read_text`] or
//! [`read_settings`], which stop after their cap plus one byte whatever the file's stated
//! length. Below `manifest` and `io`, so that both read this way.

use crate::error::{Error, Result};
use std::io::Read;
use std::path::Path;

/// The most bytes [`read_text`] reads: 1 GiB. Data files (GeoJSON footprints, features, light
/// points and routes; flight paths; incremental ledgers; shard surveys) grow with the area and
/// the number of things in it: OpenStreetMap's buildings of a whole country as GeoJSON are a
/// few hundred MB, and a file held as text and parsed into values needs several times its size
/// in memory. Beyond this a wrong path (a disk image, a log) is likelier than a real input.
pub const MAX_TEXT_BYTES: u64 = 1 << 30;

/// The most bytes [`read_settings`] reads: 64 MiB. Settings files (scene files, material
/// tables, views files, tile lists and VRTs, `.prj` and world files, build stamps) are written
/// by hand or hold one line per tile or placement: the largest real ones are well under 1 MB
/// (a scene of 100 000 placements is about 6 MB).
pub const MAX_SETTINGS_BYTES: u64 = 64 << 20;

/// The metadata of `path` (following symbolic links) if it is a regular file; else a one-line
/// error naming what it is. Asks the file system only: nothing is opened, so a FIFO cannot
/// block and a device cannot be read from.
pub fn require_regular_file(path: &Path) -> Result<std::fs::Metadata> {
    let meta = std::fs::metadata(path).map_err(|e| Error::io(path, e))?;
    if meta.is_file() {
        return Ok(meta);
    }
    Err(not_regular(path, &meta))
}

/// The error for `path`, whose metadata `meta` is not a regular file's.
fn not_regular(path: &Path, meta: &std::fs::Metadata) -> Error {
    if meta.is_dir() {
        return Error::io(path, std::io::ErrorKind::IsADirectory.into());
    }
    #[cfg(unix)]
    let what = {
        use std::os::unix::fs::FileTypeExt;
        let t = meta.file_type();
        if t.is_fifo() {
            "a FIFO (named pipe)"
        } else if t.is_char_device() {
            "a character device"
        } else if t.is_block_device() {
            "a block device"
        } else if t.is_socket() {
            "a socket"
        } else {
            "a special file"
        }
    };
    #[cfg(not(unix))]
    let what = "a special file";
    Error::file(path, format!("is {what}, not a regular file")).fix(
        "give the path of a regular file (dbms reads no pipe, device or socket: save what it gives to a file first)",
    )
}

/// `path` opened for reading, refused unless it is a regular file
/// ([`require_regular_file`], checked before opening). On Linux it is opened non-blocking and
/// checked again through the open handle, so a FIFO put in its place between the check and the
/// open cannot block either (the flag changes nothing for a regular file).
pub fn open_regular(path: &Path) -> Result<std::fs::File> {
    require_regular_file(path)?;
    let mut options = std::fs::OpenOptions::new();
    options.read(true);
    #[cfg(target_os = "linux")]
    {
        use std::os::unix::fs::OpenOptionsExt;
        options.custom_flags(libc::O_NONBLOCK);
    }
    let file = options.open(path).map_err(|e| Error::io(path, e))?;
    let meta = file.metadata().map_err(|e| Error::io(path, e))?;
    if !meta.is_file() {
        return Err(not_regular(path, &meta));
    }
    Ok(file)
}

/// The bytes of the regular file `path` ([`open_regular`]), whole: for binary inputs (voxel
/// objects, pictures, ASCII grids), whose size the file system states and bounds.
pub fn read_bytes(path: &Path) -> Result<Vec<u8>> {
    let mut bytes = Vec::new();
    (open_regular(path)?.read_to_end(&mut bytes)).map_err(|e| Error::io(path, e))?;
    Ok(bytes)
}

/// A data file (GeoJSON, a flight path, a ledger, a survey) as text, at most
/// [`MAX_TEXT_BYTES`] of it; see `read_text_at_most`.
pub fn read_text(path: &Path) -> Result<String> {
    read_text_at_most(path, MAX_TEXT_BYTES, "data file")
}

/// A settings file (a scene, a material table, a views file, a tile list, a `.prj` or world
/// file, a stamp) as text, at most [`MAX_SETTINGS_BYTES`] of it; see `read_text_at_most`.
pub fn read_settings(path: &Path) -> Result<String> {
    read_text_at_most(path, MAX_SETTINGS_BYTES, "settings file")
}

/// The text of the regular file `path` ([`open_regular`]), without the UTF-8 byte order mark
/// that Windows editors and some GIS exports put first (JSON parsers refuse it). A file over
/// `cap` bytes is refused from its stated length before anything is read, and the read stops
/// after `cap + 1` bytes whatever the length said (a file of `/proc` states 0), so no input
/// can make it run without bound. `what` names the kind of file in the error.
fn read_text_at_most(path: &Path, cap: u64, what: &str) -> Result<String> {
    let file = open_regular(path)?;
    let stated = file.metadata().map_err(|e| Error::io(path, e))?.len();
    let too_big = |size: String| {
        Error::file(
            path,
            format!("is {size} bytes, over the {} dbms reads of a {what}", binary_size(cap)),
        )
        .fix("check that this is the file meant (text inputs are capped so that a wrong path cannot exhaust memory; docs/reliability.md)")
    };
    if stated > cap {
        return Err(too_big(stated.to_string()));
    }
    let bytes = read_at_most(file, cap).map_err(|e| Error::io(path, e))?;
    let Some(bytes) = bytes else {
        return Err(too_big(format!("more than {cap}")));
    };
    let text = String::from_utf8(bytes).map_err(|e| {
        let at = e.utf8_error().valid_up_to();
        Error::file(
            path,
            format!("not a text file (invalid UTF-8 at byte {at})"),
        )
        .fix("save it as UTF-8")
    })?;
    Ok(match text.strip_prefix('\u{feff}') {
        Some(rest) => rest.to_string(),
        None => text,
    })
}

/// All of `r` if it ends within `cap` bytes, else `None` (having read `cap + 1`).
fn read_at_most(r: impl Read, cap: u64) -> std::io::Result<Option<Vec<u8>>> {
    let mut bytes = Vec::new();
    r.take(cap.saturating_add(1)).read_to_end(&mut bytes)?;
    Ok((bytes.len() as u64 <= cap).then_some(bytes))
}

/// `bytes` in words when it is a whole number of GiB or MiB, else in bytes.
fn binary_size(bytes: u64) -> String {
    match bytes {
        b if b >= 1 << 30 && b % (1 << 30) == 0 => format!("{} GiB", b >> 30),
        b if b >= 1 << 20 && b % (1 << 20) == 0 => format!("{} MiB", b >> 20),
        b => format!("{b} bytes"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_text_read_stops_after_its_cap_whatever_the_reader() {
        assert_eq!(read_at_most(std::io::repeat(7), 10).unwrap(), None);
        assert_eq!(read_at_most(&b"abc"[..], 3).unwrap(), Some(b"abc".to_vec()));
        assert_eq!(binary_size(1 << 30), "1 GiB");
        assert_eq!(binary_size(64 << 20), "64 MiB");
        assert_eq!(binary_size(1000), "1000 bytes");
    }
}
