//! One module per subcommand: its clap `Args` and its `run`. Each stays thin: parse, call the
//! library, report. Shared output rules live in [`Ctx`].

pub mod info;
pub mod ingest;
pub mod object;
pub mod place;
pub mod pyramid;
pub mod render;
pub mod sample;
pub mod sculpt;
pub mod shadow_height;
pub mod shadows;
pub mod sun;
pub mod tiles;

use dbms::progress::Progress;
use std::fmt::Display;

/// What every subcommand needs from the global options.
pub struct Ctx {
    /// `--quiet`: print nothing but errors.
    pub quiet: bool,
    /// `--json`: print a JSON summary on stdout instead of human text.
    pub json: bool,
}

impl Ctx {
    /// Print the result of a command on stdout: `json` with `--json`, else `human` unless quiet.
    pub fn report(&self, human: impl Display, json: serde_json::Value) {
        if self.json {
            println!("{}", serde_json::to_string_pretty(&json).expect("JSON value serialises"));
        } else if !self.quiet {
            println!("{human}");
        }
    }

    /// A log line on stderr, unless `--quiet`.
    pub fn log(&self, msg: impl Display) {
        if !self.quiet {
            eprintln!("{msg}");
        }
    }

    /// A progress bar on stderr (drawn only on a terminal, never with `--quiet` or `--json`).
    pub fn progress(&self, total: u64, what: &str) -> Progress {
        Progress::new(total, what, !self.quiet && !self.json)
    }
}
