//! Running the `dbms` binary from tests and benchmarks: the one helper they all use.

#![allow(dead_code)]

use std::path::Path;
use std::process::{Command, Output};

/// The `dbms` binary under test, to be given arguments.
pub fn command() -> Command {
    Command::new(env!("CARGO_BIN_EXE_dbms"))
}

/// Run `dbms` with `args` in the test's working directory.
pub fn dbms(args: &[&str]) -> Output {
    command().args(args).output().expect("run dbms")
}

/// Run `dbms` with `args` in directory `dir` (relative paths in `args` are under it).
pub fn dbms_in(dir: &Path, args: &[&str]) -> Output {
    command()
        .args(args)
        .current_dir(dir)
        .output()
        .expect("run dbms")
}

/// [`dbms_in`], but the run must end within `limit`: a run still going then is killed and the
/// test fails (a read that blocks on a FIFO or never ends on `/dev/zero`).
pub fn dbms_in_within(dir: &Path, args: &[&str], limit: std::time::Duration) -> Output {
    use std::process::Stdio;
    let mut child = command()
        .args(args)
        .current_dir(dir)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run dbms");
    let start = std::time::Instant::now();
    while child.try_wait().expect("wait for dbms").is_none() {
        if start.elapsed() > limit {
            let _ = child.kill();
            let _ = child.wait();
            panic!("dbms {args:?} still ran after {limit:?}: killed");
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    child.wait_with_output().expect("collect dbms's output")
}
