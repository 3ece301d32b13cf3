//! Atomic file output: write to a temporary file in the destination's own directory, flush,
//! then rename over the destination. A killed run leaves either the old file or nothing, never a
//! half-written file that `make` would take as up to date.

use crate::error::{Error, Result};
use crate::manifest::{Manifest, MANIFEST_FILE};
use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use tempfile::TempPath;

/// An output being written: a temporary file in the destination's directory that
/// [`AtomicFile::commit`] syncs and renames over the destination. Dropped without a commit (an
/// error, a panic), it is removed and the destination is untouched.
pub struct AtomicFile {
    path: PathBuf,
    file: BufWriter<File>,
    tmp: TempPath,
}

impl AtomicFile {
    /// Start writing `path` (its directory must exist), after [`check_output`]: a device, a
    /// FIFO, a symlink, a directory or a database's own file is refused, never replaced.
    pub fn create(path: &Path) -> Result<AtomicFile> {
        check_output(path)?;
        Self::create_unchecked(path)
    }

    /// [`AtomicFile::create`] without [`check_output`], for the database's own files, which
    /// only a [`crate::db::Change`] writes.
    pub(crate) fn create_unchecked(path: &Path) -> Result<AtomicFile> {
        let (file, tmp) = temp_beside(path)?.into_parts();
        Ok(AtomicFile {
            path: path.to_path_buf(),
            file: BufWriter::with_capacity(1 << 20, file),
            tmp,
        })
    }

    /// The destination path (for error messages).
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The buffered temporary file, positioned where writing left off.
    pub fn writer(&mut self) -> &mut BufWriter<File> {
        &mut self.file
    }

    /// Flush, make the file world-readable, sync it to disk and rename it over the destination.
    pub fn commit(self) -> Result<()> {
        self.stage()?.commit()
    }

    /// Flush, make the file world-readable and sync it to disk, but leave it under its
    /// temporary name: a run with several outputs stages every one, then renames them all with
    /// [`commit_all`], so a failure while writing any of them leaves none.
    pub fn stage(self) -> Result<Staged> {
        let path = self.path;
        let file = self
            .file
            .into_inner()
            .map_err(|e| Error::io(&path, e.into_error()))?;
        injected_full_disk(&path)?;
        // tempfile creates 0600; outputs are ordinary files other users and tools may read.
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            file.set_permissions(std::fs::Permissions::from_mode(0o644))
                .map_err(|e| Error::io(&path, e))?;
        }
        file.sync_all().map_err(|e| Error::io(&path, e))?;
        Ok(Staged {
            path,
            tmp: self.tmp,
        })
    }
}

/// An output written in full and synced under its temporary name, waiting to be renamed over
/// its destination ([`Staged::commit`], or [`commit_all`] for a run's outputs together).
/// Dropped without a commit (another output failed), it is removed and the destination is
/// untouched.
pub struct Staged {
    path: PathBuf,
    tmp: TempPath,
}

impl Staged {
    /// A temporary file its writer has already written, made readable and synced: renamed to
    /// `path` by [`Staged::commit`].
    pub(crate) fn new(path: &Path, tmp: TempPath) -> Result<Staged> {
        injected_full_disk(path)?;
        Ok(Staged {
            path: path.to_path_buf(),
            tmp,
        })
    }

    /// The destination path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Where the file is until it is renamed: to read back what was written.
    pub fn written(&self) -> &Path {
        &self.tmp
    }

    /// Rename the file over its destination (unless the build that started this process has
    /// ended: [`super::lock::check_owner`]).
    pub fn commit(self) -> Result<()> {
        super::lock::check_owner()?;
        self.tmp
            .persist(&self.path)
            .map_err(|e| Error::io(&self.path, e.error))
    }
}

/// Rename a run's staged outputs into place, in order: give the one `make` waits for (the
/// run's main output) last, so that if a rename fails, that one is not left looking up to date.
/// All the writing is done before (a full disk fails [`AtomicFile::stage`], not this); a rename
/// within one directory fails only when something replaced the destination in the meantime.
pub fn commit_all(staged: Vec<Staged>) -> Result<()> {
    staged.into_iter().try_for_each(Staged::commit)
}

/// Fail as a full disk would when `DBMS_FAULT` is `enospc:NAME` and `path`'s file name is NAME:
/// how the tests make one output of a run fail after others were written (no effect otherwise).
fn injected_full_disk(path: &Path) -> Result<()> {
    let name = path.file_name().map(|n| n.to_string_lossy());
    let fault = std::env::var_os("DBMS_FAULT");
    let fault = fault
        .as_ref()
        .and_then(|f| f.to_str()?.strip_prefix("enospc:"));
    match (fault, name) {
        (Some(f), Some(n)) if f == n => Err(Error::io(
            path,
            std::io::Error::from(std::io::ErrorKind::StorageFull),
        )),
        _ => Ok(()),
    }
}

/// Write `path` atomically; `fill` writes the whole content to the given writer.
pub fn write_atomic<F>(path: &Path, fill: F) -> Result<()>
where
    F: FnOnce(&mut BufWriter<File>) -> Result<()>,
{
    let mut out = AtomicFile::create(path)?;
    fill(out.writer())?;
    out.commit()
}

/// Write bytes to `path` atomically.
pub fn write_bytes_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    write_atomic(path, |w| w.write_all(bytes).map_err(|e| Error::io(path, e)))
}

/// The name prefix of this process's temporary outputs: `.dbms-<host>-<pid>-`, so that a
/// later run can tell a killed run's leftovers (same host, no such process) from a running
/// one's — also on a disk shared between machines.
pub(crate) fn temp_prefix() -> String {
    format!(".dbms-{}-{}-", host(), std::process::id())
}

/// The directory an output `path` is written in (`.` for a bare file name).
pub(crate) fn output_dir(path: &Path) -> &Path {
    match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    }
}

/// A new temporary file in `path`'s directory, named [`temp_prefix`]`….tmp` so a later run can
/// clear it if this one is killed (after clearing what killed runs left there).
pub(crate) fn temp_beside(path: &Path) -> Result<tempfile::NamedTempFile> {
    let dir = output_dir(path);
    clear_stale_temps(dir);
    tempfile::Builder::new()
        .prefix(&temp_prefix())
        .suffix(".tmp")
        .tempfile_in(dir)
        .map_err(|e| {
            Error::io(dir, e).fix("check that the output directory exists and is writable")
        })
}

/// This machine's host name (Linux; empty elsewhere, where nothing is ever cleared).
fn host() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .map(|h| h.trim().replace(['-', '/'], "_"))
        .unwrap_or_default()
}

/// Remove the temporary outputs in `dir` that runs killed on this machine left behind
/// ([`temp_prefix`] with a process id that no longer runs). Best effort: errors are ignored.
pub(crate) fn clear_stale_temps(dir: &Path) {
    let host = host();
    if host.is_empty() || !Path::new("/proc/self").exists() {
        return;
    }
    let mine = format!(".dbms-{host}-");
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        let pid = name
            .strip_prefix(&mine)
            .filter(|_| name.ends_with(".tmp"))
            .and_then(|rest| rest.split('-').next())
            .and_then(|p| p.parse::<u32>().ok());
        if let Some(pid) = pid {
            if !Path::new(&format!("/proc/{pid}")).exists() {
                let _ = std::fs::remove_file(e.path());
            }
        }
    }
}

/// [`write_bytes_atomic`] for a database's own file (its manifest), by a
/// [`crate::db::Change`].
pub(crate) fn write_database_file(path: &Path, bytes: &[u8]) -> Result<()> {
    let mut out = AtomicFile::create_unchecked(path)?;
    out.writer()
        .write_all(bytes)
        .map_err(|e| Error::io(path, e))?;
    out.commit()
}

/// Refuse to write `path` when that would destroy something rather than replace a file: it is
/// a symlink (the link would be replaced, not its target), a device, a FIFO, a socket or a
/// directory, or a file of a database directory (its manifest, lock or a file the manifest
/// names: a database changes only through its own commit protocol, docs/database.md).
pub fn check_output(path: &Path) -> Result<()> {
    if let Ok(m) = std::fs::symlink_metadata(path) {
        let t = m.file_type();
        let what = if t.is_symlink() {
            Some("a symbolic link")
        } else if t.is_dir() {
            Some("a directory")
        } else if !t.is_file() {
            Some("a device, FIFO or socket, not a regular file")
        } else {
            None
        };
        if let Some(what) = what {
            return Err(Error::file(path, format!("the output is {what}"))
                .fix("give the path of a regular file to write"));
        }
    }
    let dir = match path.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    if dir.join(MANIFEST_FILE).is_file() {
        let name = path.file_name().map(|n| n.to_string_lossy().into_owned());
        let owned = match Manifest::read(dir) {
            Ok(manifest) => manifest.owns(name.as_deref().unwrap_or("")),
            Err(_) => true,
        };
        if owned {
            return Err(Error::file(
                path,
                "the output is a file of the database in its directory",
            )
            .fix("write outputs outside the database directory, or to a name it does not use"));
        }
    }
    Ok(())
}

/// Refuse a run's `outputs` that [`check_output`] refuses, that name the same file twice, or
/// that are one of its `inputs` (the run would overwrite what it reads).
pub fn check_outputs(outputs: &[&Path], inputs: &[&Path]) -> Result<()> {
    let same = |a: &Path, b: &Path| match (std::fs::canonicalize(a), std::fs::canonicalize(b)) {
        (Ok(a), Ok(b)) => a == b,
        _ => a == b,
    };
    for (k, &out) in outputs.iter().enumerate() {
        check_output(out)?;
        if let Some(other) = outputs[..k].iter().find(|&&o| same(o, out)) {
            return Err(Error::file(
                out,
                format!("is given as two outputs (also as {})", other.display()),
            )
            .fix("give each output its own path"));
        }
        if inputs.iter().any(|&i| same(i, out)) {
            return Err(Error::file(out, "the output is also an input of this run")
                .fix("write the output to another path"));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn failed_write_leaves_old_file_and_no_temp() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("out.bin");
        write_bytes_atomic(&p, b"first").unwrap();
        let r = write_atomic(&p, |w| {
            w.write_all(b"partial").unwrap();
            Err(Error::msg("boom"))
        });
        assert!(r.is_err());
        assert_eq!(std::fs::read(&p).unwrap(), b"first");
        let names: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names.len(), 1, "temp file left behind: {names:?}");
    }

    #[test]
    fn staged_outputs_appear_together_at_commit_and_not_at_all_when_dropped() {
        let dir = tempfile::tempdir().unwrap();
        let (a, b) = (dir.path().join("a.ply"), dir.path().join("a.dvox"));
        let stage = |p: &Path, bytes: &[u8]| {
            let mut f = AtomicFile::create(p).unwrap();
            f.writer().write_all(bytes).unwrap();
            f.stage().unwrap()
        };
        let names = || {
            let mut n: Vec<String> = std::fs::read_dir(dir.path())
                .unwrap()
                .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .collect();
            n.sort();
            n
        };
        // Staged, then dropped (a later output failed): nothing appears, no temporary stays.
        drop(vec![stage(&a, b"export"), stage(&b, b"object")]);
        assert!(names().is_empty(), "{:?}", names());
        // Committed: both.
        let staged = vec![stage(&a, b"export"), stage(&b, b"object")];
        assert!(!a.exists() && !b.exists(), "nothing before the commit");
        commit_all(staged).unwrap();
        assert_eq!(names(), ["a.dvox", "a.ply"]);
        assert_eq!(std::fs::read(&b).unwrap(), b"object");
        // A rename that fails (its destination replaced by a directory after the checks) stops
        // the commit: the outputs after it, the main one last, keep their old content.
        let staged = vec![stage(&a, b"export 2"), stage(&b, b"object 2")];
        std::fs::remove_file(&a).unwrap();
        std::fs::create_dir(&a).unwrap();
        std::fs::write(a.join("x"), b"").unwrap();
        assert!(commit_all(staged).is_err());
        assert_eq!(std::fs::read(&b).unwrap(), b"object");
        assert_eq!(names(), ["a.dvox", "a.ply"], "no temporary left");
    }

    #[test]
    fn a_killed_runs_temporary_files_are_cleared_by_the_next_run_but_not_a_running_ones() {
        if !Path::new("/proc/sys/kernel/hostname").exists() {
            return; // Linux only
        }
        let dir = tempfile::tempdir().unwrap();
        // A process that has ended: its pid names no running process (killed runs leave such
        // files behind, and they can be large).
        let mut child = std::process::Command::new("true").spawn().unwrap();
        let dead = child.id();
        child.wait().unwrap();
        let stale = dir
            .path()
            .join(format!(".dbms-{}-{dead}-AbC123.tmp", host()));
        let running = dir.path().join(format!("{}XyZ789.tmp", temp_prefix()));
        let other_host = dir.path().join(format!(".dbms-elsewhere-{dead}-q.tmp"));
        for f in [&stale, &running, &other_host] {
            std::fs::write(f, b"partial").unwrap();
        }
        write_bytes_atomic(&dir.path().join("out.bin"), b"x").unwrap();
        assert!(!stale.exists());
        assert!(running.exists() && other_host.exists());
    }

    #[cfg(unix)]
    #[test]
    fn outputs_are_world_readable() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("out.bin");
        write_bytes_atomic(&p, b"x").unwrap();
        assert_eq!(
            std::fs::metadata(&p).unwrap().permissions().mode() & 0o777,
            0o644
        );
    }
}
