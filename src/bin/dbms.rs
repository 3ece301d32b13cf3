//! `dbms`: the command-line front end. Thin by design: every algorithm is in the library.

mod cmd;

use clap::{Parser, Subcommand};
use std::process::ExitCode;

/// Author the terrain-and-object database of a height-field / voxel ray-casting simulator.
#[derive(Parser)]
#[command(name = "dbms", version, about, propagate_version = true)]
struct Cli {
    /// Print nothing but errors.
    #[arg(long, short, global = true)]
    quiet: bool,
    /// Print a machine-readable JSON summary on stdout.
    #[arg(long, global = true)]
    json: bool,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let ctx = cmd::Ctx { quiet: cli.quiet, json: cli.json };
    let result: dbms::Result<()> = match cli.command {
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("dbms: error: {e}");
            ExitCode::FAILURE
        }
    }
}
