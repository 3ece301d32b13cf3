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

    /// An I/O error while reading or writing `path`.
    pub fn io(path: impl AsRef<Path>, err: std::io::Error) -> Error {
        let fix = match err.kind() {
            std::io::ErrorKind::NotFound => Some("check the path".to_string()),
            std::io::ErrorKind::PermissionDenied => {
                Some("check the file's permissions".to_string())
            }
            _ => None,
        };
        Error {
            path: Some(path.as_ref().to_path_buf()),
            problem: io_problem(&err),
            fix,
        }
    }
}

fn io_problem(err: &std::io::Error) -> String {
    match err.kind() {
        std::io::ErrorKind::NotFound => "no such file or directory".to_string(),
        std::io::ErrorKind::UnexpectedEof => "file ends early (truncated?)".to_string(),
        _ => {
            // std's message carries " (os error N)"; keep it, it helps.
            let s = err.to_string();
            s.replace('\n', " ")
        }
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if let Some(p) = &self.path {
            write!(f, "{}: ", p.display())?;
        }
        write!(f, "{}", self.problem)?;
        if let Some(fix) = &self.fix {
            write!(f, "; {fix}")?;
        }
        Ok(())
    }
}

impl std::error::Error for Error {}

#[cfg(test)]
mod tests {
    use super::*;

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
}
