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
