//! The one error type of the library.
//!
//! Every error a user can cause renders as a single line that names the file (when there is
//! one), the problem and, where we know it, the fix:
//! `dem.tif: not a TIFF file (bad magic bytes); give a GeoTIFF or an Esri ASCII grid`.
//! The CLI prints it after `dbms: error: ` and exits non-zero; nothing panics on bad input.

use std::fmt;
use std::path::{Path, PathBuf};

/// A user-facing error: which file, what is wrong, how to fix it.
#[derive(Debug, Clone, PartialEq)]
pub struct Error {
    /// The file the problem is in, if any.
    pub path: Option<PathBuf>,
    /// What is wrong, in a few words.
    pub problem: String,
    /// What the user can do about it, if we know.
    pub fix: Option<String>,
}

/// Result with the library's [`Error`].
pub type Result<T, E = Error> = std::result::Result<T, E>;

impl Error {
    /// A problem not tied to one file (bad option values, inconsistent inputs).
    pub fn msg(problem: impl Into<String>) -> Error {
        Error {
            path: None,
            problem: problem.into(),
            fix: None,
        }
    }

    /// A problem in a named file.
    pub fn file(path: impl AsRef<Path>, problem: impl Into<String>) -> Error {
        Error {
            path: Some(path.as_ref().to_path_buf()),
            problem: problem.into(),
            fix: None,
        }
    }

    /// Attach the advice that tells the user how to fix the problem.
    pub fn fix(mut self, fix: impl Into<String>) -> Error {
        self.fix = Some(fix.into());
        self
    }

    /// Attach a path to an error that has none yet (keeps an existing one).
    pub fn in_file(mut self, path: impl AsRef<Path>) -> Error {
        if self.path.is_none() {
            self.path = Some(path.as_ref().to_path_buf());
        }
        self
    }

    /// An I/O error while reading or writing `path`: the common kinds in words, with a fix;
    /// others as std words them.
    pub fn io(path: impl AsRef<Path>, err: std::io::Error) -> Error {
        use std::io::ErrorKind as K;
        let (problem, fix) = match err.kind() {
            K::NotFound => ("no such file or directory", "check the path"),
            K::PermissionDenied => ("permission denied", "check the file's permissions"),
            K::UnexpectedEof => (
                "file ends early (truncated?)",
                "re-create or re-download it",
            ),
            K::IsADirectory => (
                "is a directory, not a file",
                "give the path of a file (a directory is not replaced or read as one)",
            ),
            K::NotADirectory => (
                "a part of the path is a file, not a directory",
                "check the path",
            ),
            K::AlreadyExists => ("already exists", "remove it or choose another path"),
            K::StorageFull => (
                "no space left on the device",
                "free some space or write to another disk, then run again",
            ),
            K::QuotaExceeded => (
                "disk quota exceeded",
                "free some space or write to another disk, then run again",
            ),
            K::ReadOnlyFilesystem => (
                "the file system is read-only",
                "write to a writable location",
            ),
            // std's message carries " (os error N)"; keep it, it helps.
            _ => {
                return Error {
                    path: Some(path.as_ref().to_path_buf()),
                    problem: err.to_string(),
                    fix: None,
                }
            }
        };
        Error::file(path, problem).fix(fix)
    }
}

/// Always one line: a problem or fix quoting another library's multi-line message (a decoder's
/// error, say) has each run of white space that holds a line break folded into one space.
impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if let Some(p) = &self.path {
            write!(f, "{}: ", p.display())?;
        }
        write!(f, "{}", one_line(&self.problem))?;
        if let Some(fix) = &self.fix {
            write!(f, "; {}", one_line(fix))?;
        }
        Ok(())
    }
}

/// `s` with line breaks and the white space around them folded into single spaces, and no
/// trailing white space left by a final break.
fn one_line(s: &str) -> std::borrow::Cow<'_, str> {
    if !s.contains(['\n', '\r']) {
        return s.into();
    }
    let mut out = String::with_capacity(s.len());
    for (i, line) in s
        .lines()
        .map(str::trim)
        .filter(|l| !l.is_empty())
        .enumerate()
    {
        if i > 0 {
            out.push(' ');
        }
        out.push_str(line);
    }
    out.into()
}

impl std::error::Error for Error {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_quoted_multi_line_message_still_renders_one_line() {
        let e = Error::file(
            "dem.tif",
            "chunk 3: Deflate data: Mismatched Adler,\n\n  expected 1",
        )
        .fix("re-create the file\r\n");
        assert_eq!(
            e.to_string(),
            "dem.tif: chunk 3: Deflate data: Mismatched Adler, expected 1; re-create the file"
        );
    }

    #[test]
    fn renders_one_line_with_path_problem_and_fix() {
        let e = Error::file("dem.tif", "not a TIFF file").fix("give a GeoTIFF");
        assert_eq!(e.to_string(), "dem.tif: not a TIFF file; give a GeoTIFF");
        let io = Error::io("x.tif", std::io::Error::from(std::io::ErrorKind::NotFound));
        assert_eq!(
            io.to_string(),
            "x.tif: no such file or directory; check the path"
        );
        assert!(!io.to_string().contains('\n'));
    }

    /// The raw "os error 21/17/28" of a directory, an existing file and a full disk become words
    /// with a fix.
    #[test]
    fn common_io_errors_are_words_with_a_fix() {
        for (code, want) in [
            (
                21,
                "out: is a directory, not a file; give the path of a file",
            ),
            (17, "out: already exists; remove it or choose another path"),
            (28, "out: no space left on the device; free some space"),
        ] {
            let e = Error::io("out", std::io::Error::from_raw_os_error(code)).to_string();
            assert!(e.starts_with(want), "{code}: {e}");
            assert!(!e.contains("os error"), "{e}");
        }
    }
}
