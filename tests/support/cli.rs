//! Running the `dbms` binary from the CLI tests: the one helper every `tests/cli_*.rs` uses.

#![allow(dead_code)]

use std::path::Path;
use std::process::{Command, Output};

/// Run `dbms` with `args` in the test's working directory.
pub fn dbms(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_dbms"))
        .args(args)
        .output()
        .expect("run dbms")
}

/// Run `dbms` with `args` in directory `dir` (relative paths in `args` are under it).
pub fn dbms_in(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_dbms"))
        .args(args)
        .current_dir(dir)
        .output()
        .expect("run dbms")
}
