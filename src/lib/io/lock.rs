//! Exclusive locks on files (a database's write lock, a scene build's lock), and the check that
//! a step a build started still belongs to it before it renames an output into place.
//!
//! Invariant: [`wait_for_lock`] returns only holding the lock (`flock`, released when the file
//! is closed or its process ends, also when killed). A process given a build's owner
//! ([`OWNER_ENV`]: the token its build wrote in its lock file, and that file's path) commits an
//! output only while that lock is held and holds that token ([`check_owner`]): a step orphaned
//! by a killed build never renames a stale file over a newer build's.

use crate::error::{Error, Result};
use std::fs::File;
use std::io::Read;
use std::path::Path;
use std::time::Duration;

/// The environment variable a build gives its steps: `TOKEN:LOCK_PATH`, the token the build
/// wrote in its lock file and that file's path ([`check_owner`]).
pub const OWNER_ENV: &str = "DBMS_BUILD_OWNER";

/// Take the exclusive lock on the file at `path` (created if missing), retrying every 50 ms for
/// up to `wait`. `subject` and `busy` word the error when another process keeps it: `subject:
/// busy (waited N s for its lock)`.
pub fn wait_for_lock(path: &Path, wait: Duration, subject: &Path, busy: &str) -> Result<File> {
    let file = std::fs::OpenOptions::new()
        .create(true)
        .truncate(false)
        .read(true)
        .write(true)
        .open(path)
        .map_err(|e| Error::io(path, e).fix("check that its directory is writable"))?;
    let start = std::time::Instant::now();
    loop {
        match file.try_lock() {
            Ok(()) => return Ok(file),
            Err(std::fs::TryLockError::WouldBlock) if start.elapsed() < wait => {
                std::thread::sleep(Duration::from_millis(50));
            }
            Err(std::fs::TryLockError::WouldBlock) => {
                return Err(Error::file(
                    subject,
                    format!("{busy} (waited {:.0} s for its lock)", wait.as_secs_f64()),
                )
                .fix("wait for it to finish, or give a longer --wait SECONDS"))
            }
            Err(std::fs::TryLockError::Error(e)) => return Err(Error::io(path, e)),
        }
    }
}

/// An error unless this process may commit outputs: always, unless [`OWNER_ENV`] names a build
/// (`TOKEN:LOCK_PATH`); then only while some process holds that lock file's lock and the file
/// holds `TOKEN` (the build that started this step is still running: not killed, nor replaced
/// by a later build). What [`super::atomic::Staged::commit`] checks before each rename.
pub fn check_owner() -> Result<()> {
    let Some(owner) = std::env::var_os(OWNER_ENV) else {
        return Ok(());
    };
    let owner = owner.to_string_lossy();
    let (token, path) = owner.split_once(':').unwrap_or(("-", &owner));
    let path = Path::new(path);
    let ended = || {
        Error::file(
            path,
            "the dbms build that started this step has ended: its output is not committed",
        )
        .fix("run dbms build again")
    };
    let mut file = File::open(path).map_err(|_| ended())?;
    let mut held = String::new();
    file.read_to_string(&mut held)
        .map_err(|e| Error::io(path, e))?;
    match file.try_lock_shared() {
        // Nobody holds it: the build was killed.
        Ok(()) => Err(ended()),
        Err(std::fs::TryLockError::WouldBlock) if held.trim() == token => Ok(()),
        Err(std::fs::TryLockError::WouldBlock) => Err(ended()),
        Err(std::fs::TryLockError::Error(e)) => Err(Error::io(path, e)),
    }
}
