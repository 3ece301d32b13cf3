//! `dbms build`: run the out-of-date steps of a scene's plan, independent ones side by side.
//!
//! Invariant: a step runs only after every step it runs after has succeeded in this build or
//! was up to date; its stamp is written only after all its command lines succeeded; the first
//! failure stops the build (steps already running finish, no new one starts) and the error
//! names the step and the command. Each command line is the `dbms` binary run as a child, the
//! same line the Makefile of `dbms plan --makefile` runs, so both ways build the same bytes.

use super::file::Scene;
use super::plan::{plan, stamp_planned, PlannedStep};
use crate::error::{Error, Result};
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
/// `exe ARGS` (the dbms binary). `progress` counts steps.
pub fn build(scene: &Scene, exe: &Path, jobs: usize, progress: &Progress) -> Result<Built> {
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
                    let result = run_step(step, exe)
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

/// Run a step's command lines in order; an error names the step, the command and what it said.
fn run_step(step: &PlannedStep, exe: &Path) -> Result<()> {
    for out in &step.step.outputs {
        if let Some(dir) = out.parent().filter(|p| !p.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
        }
    }
    for args in &step.step.commands {
        let out = Command::new(exe)
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
