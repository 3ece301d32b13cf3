//! `dbms build`: run the out-of-date steps of a scene's plan, independent ones side by side.
//!
//! Invariant: a step runs only after every step it runs after has succeeded in this build or
//! was up to date; its stamp is written only after all its command lines succeeded; the first
//! failure stops the build (steps already running finish, no new one starts) and the error
//! names the step and the command. Each command line is the `dbms` binary run as a child, the
//! same line the Makefile of `dbms plan --makefile` runs, so both ways build the same bytes.
//!
//! A build holds the scene's lock (`<database>.steps/build.lock`) from before it plans until
//! its last step ends, so two builds of one scene run one after the other (the second finds
//! the first's steps up to date). Its steps end when it ends (on Linux each child is sent
//! SIGTERM when the build dies), and a step commits its outputs only while the build that
//! started it holds the lock with the token it wrote there ([`crate::io::lock::check_owner`]).

use super::file::Scene;
use super::plan::{lock_path, plan, stamp_planned, steps_dir, PlannedStep};
use crate::error::{Error, Result};
use crate::io::lock::{wait_for_lock, OWNER_ENV};
use crate::progress::Progress;
use serde::Serialize;
use std::collections::BTreeSet;
use std::path::Path;
use std::process::Command;
use std::sync::mpsc;

/// What a build did.
#[derive(Debug, Clone, Serialize)]
pub struct Built {
    /// Steps that ran, in the order they finished.
    pub ran: Vec<String>,
    /// Steps that were up to date.
    pub up_to_date: Vec<String>,
}

/// Run every out-of-date step of `scene`, at most `jobs` at a time, each command line as
/// `exe ARGS` (the dbms binary), under the scene's lock (waiting up to `wait` for another
/// build of it to end). `progress` counts steps.
pub fn build(
    scene: &Scene,
    exe: &Path,
    jobs: usize,
    wait: std::time::Duration,
    progress: &Progress,
) -> Result<Built> {
    let (_lock, owner) = lock(scene, wait)?;
    let owner = owner.as_str();
    let steps = plan(scene)?;
    let mut done: BTreeSet<String> = steps
        .iter()
        .filter(|s| s.up_to_date)
        .map(|s| s.step.name.clone())
        .collect();
    let up_to_date: Vec<String> = done.iter().cloned().collect();
    let mut waiting: Vec<&PlannedStep> = steps.iter().filter(|s| !s.up_to_date).collect();
    progress.phase(waiting.len() as u64, "steps");
    let mut ran = Vec::new();
    let (tx, rx) = mpsc::channel::<(String, Result<()>)>();
    std::thread::scope(|scope| -> Result<()> {
        let mut running = 0;
        let mut failed: Option<Error> = None;
        loop {
            while failed.is_none() && running < jobs.max(1) {
                let Some(k) = waiting
                    .iter()
                    .position(|s| s.step.after.iter().all(|a| done.contains(a)))
                else {
                    break;
                };
                let step = waiting.remove(k);
                let tx = tx.clone();
                running += 1;
                scope.spawn(move || {
                    let clock = std::time::Instant::now();
                    let result = run_step(step, exe, owner)
                        .and_then(|()| stamp_planned(scene, step, clock.elapsed().as_secs_f64()));
                    let _ = tx.send((step.step.name.clone(), result));
                });
            }
            if running == 0 {
                break;
            }
            let (name, result) = rx.recv().expect("a running step reports");
            running -= 1;
            match result {
                Ok(()) => {
                    progress.inc(1);
                    done.insert(name.clone());
                    ran.push(name);
                }
                Err(e) => {
                    failed.get_or_insert(e);
                }
            }
        }
        match failed {
            Some(e) => Err(e),
            None => Ok(()),
        }
    })?;
    debug_assert!(waiting.is_empty());
    Ok(Built { ran, up_to_date })
}

/// Take the lock of `scene`'s builds, waiting up to `wait`, and write a new token in it; returns
/// the lock (held until dropped) and the owner its steps are given ([`OWNER_ENV`]).
fn lock(scene: &Scene, wait: std::time::Duration) -> Result<(std::fs::File, String)> {
    let dir = steps_dir(scene);
    std::fs::create_dir_all(&dir).map_err(|e| Error::io(&dir, e))?;
    let path = std::path::absolute(lock_path(scene)).map_err(|e| Error::io(&dir, e))?;
    let busy = "another dbms build of this scene is running";
    let mut file = wait_for_lock(&path, wait, &scene.database.dir, busy)?;
    let since = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_nanos());
    let token = format!("{}-{since}", std::process::id());
    let write = |f: &mut std::fs::File| {
        use std::io::{Seek, Write};
        f.set_len(0)?;
        f.rewind()?;
        f.write_all(token.as_bytes())?;
        f.sync_all()
    };
    write(&mut file).map_err(|e| Error::io(&path, e))?;
    Ok((file, format!("{token}:{}", path.display())))
}

/// `exe` as a child that ends when this process (the thread that starts it) ends: on Linux it
/// is sent SIGTERM then, so a killed build leaves no step running.
fn child(exe: &Path) -> Command {
    #[allow(unused_mut)]
    let mut command = Command::new(exe);
    #[cfg(target_os = "linux")]
    {
        use std::os::unix::process::CommandExt;
        let parent = std::process::id() as libc::pid_t;
        // SAFETY: between fork and exec the closure calls only prctl and getppid, both
        // async-signal-safe, and allocates nothing. If the build died before prctl took
        // effect the child was re-parented already: getppid differs and it does not run.
        unsafe {
            command.pre_exec(move || {
                if libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM) != 0 {
                    return Err(std::io::Error::last_os_error());
                }
                if libc::getppid() != parent {
                    return Err(std::io::Error::other("the build ended"));
                }
                Ok(())
            });
        }
    }
    command
}

/// Run a step's command lines in order, each given the build's `owner` ([`OWNER_ENV`]); an
/// error names the step, the command and what it said.
fn run_step(step: &PlannedStep, exe: &Path, owner: &str) -> Result<()> {
    for out in &step.step.outputs {
        if let Some(dir) = out.parent().filter(|p| !p.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
        }
    }
    for args in &step.step.commands {
        let out = child(exe)
            .env(OWNER_ENV, owner)
            .arg("--quiet")
            .args(args)
            .output()
            .map_err(|e| Error::io(exe, e))?;
        if !out.status.success() {
            let said = String::from_utf8_lossy(&out.stderr);
            let said = said.trim().lines().last().unwrap_or("").trim();
            let said = said.strip_prefix("dbms: error: ").unwrap_or(said);
            return Err(Error::msg(format!(
                "step {} failed: dbms {}: {said}",
                step.step.name,
                args.join(" ")
            )));
        }
    }
    Ok(())
}
