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
    /// List every warning (by default a run prints a count and the first few of a kind).
    #[arg(long, short, global = true, conflicts_with = "quiet")]
    verbose: bool,
    /// Print a machine-readable JSON summary on stdout.
    #[arg(long, global = true)]
    json: bool,
    /// Seconds to wait for another dbms changing the same database (one writer at a time) before
    /// giving up with an error.
    #[arg(long, global = true, value_name = "SECONDS", default_value = "60", value_parser = parse_wait)]
    wait: std::time::Duration,
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Build a scene file's products: run the steps `dbms plan` lists as out of date.
    Build(cmd::build::Args),
    /// Register a DEM and an orthophoto onto one database grid (creates the database).
    Ingest(cmd::ingest::Args),
    /// Export a database for other tools: `mesh`, a 3D Tiles tileset of glTF binaries.
    Export(cmd::export::Args),
    /// Show what a database holds: grid, layers, checksums, stages run.
    Info(cmd::info::Args),
    /// The per-cell material layer: from roofs, vector features, land cover, then the photo.
    Materials(cmd::materials::Args),
    /// Make a synthetic voxel object: revolved tank, cone tree, or buildings extruded from footprints.
    Object(cmd::object::Args),
    /// List the steps that build a scene file's products and which are out of date (--makefile: as make rules).
    Plan(cmd::plan::Args),
    /// Place a voxel object in a database at X,Y[,Z] with a heading (recorded in the manifest).
    Place(cmd::place::Args),
    /// Build the render database: max-Z / average-colour levels as a paged tile file, shaded for a sun.
    Pyramid(cmd::pyramid::Args),
    /// Ray-cast a view of a tile set (or --top, a map of all of it) to PNG, with optional range EXR.
    Render(cmd::render::Args),
    /// Carve a coloured voxel object from calibrated silhouettes (visual hull).
    Sculpt(cmd::sculpt::Args),
    /// Generate the sample scene: terrain, orthophoto with shadows, building footprints, truth.
    Sample(cmd::sample::Args),
    /// Building heights from their shadows in the photo, refined over the terrain (--apply: into the database).
    ShadowHeight(cmd::shadow_height::Args),
    /// Write the cast-shadow mask of a database for a sun (time or angles).
    Shadows(cmd::shadows::Args),
    /// What every shard of a sharded pyramid must know about the whole database (--shard, --merge).
    Survey(cmd::survey::Args),
    /// Sun elevation, azimuth and zenith for a place (or a database's centre) and time (NREL SPA).
    Sun(cmd::sun::Args),
    /// Surface temperature and 8–12 µm radiance of every cell at a time (thermal infrared).
    Thermal(cmd::thermal::Args),
    /// Radar backscatter of every cell for a distant radar, with shadow, layover and dihedrals.
    Radar(cmd::radar::Args),
    /// Describe a paged tile file; --verify checks every page's checksum.
    Tiles(cmd::tiles::Args),
}

/// `--wait SECONDS`: a number of seconds ≥ 0 (`inf`: wait as long as it takes).
fn parse_wait(s: &str) -> Result<std::time::Duration, String> {
    match s.parse::<f64>() {
        Ok(v) if v == f64::INFINITY => Ok(std::time::Duration::MAX),
        Ok(v) => std::time::Duration::try_from_secs_f64(v)
            .map_err(|_| format!("{s} is not a number of seconds ≥ 0")),
        Err(_) => Err(format!("{s} is not a number of seconds")),
    }
}

fn main() -> ExitCode {
    keep_freed_memory();
    let cli = match Cli::try_parse() {
        Ok(cli) => cli,
        Err(e) => return usage_error(e),
    };
    let ctx = cmd::Ctx {
        quiet: cli.quiet,
        verbose: cli.verbose,
        json: cli.json,
        wait: cli.wait,
    };
    let result: dbms::Result<()> = match cli.command {
        Command::Build(a) => cmd::build::run(a, &ctx),
        Command::Ingest(a) => cmd::ingest::run(a, &ctx),
        Command::Export(a) => cmd::export::run(a, &ctx),
        Command::Info(a) => cmd::info::run(a, &ctx),
        Command::Materials(a) => cmd::materials::run(a, &ctx),
        Command::Object(a) => cmd::object::run(a, &ctx),
        Command::Place(a) => cmd::place::run(a, &ctx),
        Command::Plan(a) => cmd::plan::run(a, &ctx),
        Command::Pyramid(a) => cmd::pyramid::run(a, &ctx),
        Command::Render(a) => cmd::render::run(a, &ctx),
        Command::Sculpt(a) => cmd::sculpt::run(a, &ctx),
        Command::Sample(a) => cmd::sample::run(a, &ctx),
        Command::ShadowHeight(a) => cmd::shadow_height::run(a, &ctx),
        Command::Shadows(a) => cmd::shadows::run(a, &ctx),
        Command::Sun(a) => cmd::sun::run(a, &ctx),
        Command::Survey(a) => cmd::survey::run(a, &ctx),
        Command::Thermal(a) => cmd::thermal::run(a, &ctx),
        Command::Radar(a) => cmd::radar::run(a, &ctx),
        Command::Tiles(a) => cmd::tiles::run(a, &ctx),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("dbms: error: {e}");
            ExitCode::FAILURE
        }
    }
}

/// Exit status of a usage error (arguments that do not parse); 1 is every other failure.
const EXIT_USAGE: u8 = 2;

/// The arguments did not parse. `--help` and `--version` print as clap prints them (exit 0);
/// every other outcome is an error in the one-line form of all dbms errors, exit status 2:
/// `dbms: error: <clap's message>; <its tip>; see `dbms <command> --help``.
fn usage_error(e: clap::Error) -> ExitCode {
    use clap::error::ErrorKind;
    if matches!(e.kind(), ErrorKind::DisplayHelp | ErrorKind::DisplayVersion) {
        let _ = e.print();
        return ExitCode::SUCCESS;
    }
    let text = e.render().to_string();
    let problem = match e.kind() {
        // Clap renders the whole help here: say what is missing instead.
        ErrorKind::DisplayHelpOnMissingArgumentOrSubcommand => "no command given".to_string(),
        _ => usage_problem(&text),
    };
    eprintln!("dbms: error: {problem}; see `{} --help`", usage_command());
    ExitCode::from(EXIT_USAGE)
}

/// Clap's message as one line: its `error:` line with the indented lines under it (a list of
/// missing arguments) joined by commas, then its tips, without the usage and help lines.
fn usage_problem(text: &str) -> String {
    let mut head = String::new();
    let mut list = Vec::new();
    let mut tips = Vec::new();
    for line in text.lines().map(str::trim).filter(|l| !l.is_empty()) {
        if line.starts_with("Usage:") || line.starts_with("For more information") {
            break;
        }
        match (line.strip_prefix("error:"), line.strip_prefix("tip:")) {
            (Some(e), _) => head = e.trim().to_string(),
            (_, Some(t)) => tips.push(t.trim()),
            _ => list.push(line),
        }
    }
    if !list.is_empty() {
        head = format!("{head} {}", list.join(", "));
    }
    std::iter::once(head.as_str())
        .chain(tips)
        .collect::<Vec<_>>()
        .join("; ")
}

/// The command whose `--help` applies: `dbms` and the subcommands named on the command line
/// (`dbms object cone`), found by walking clap's command tree.
fn usage_command() -> String {
    let mut cmd = <Cli as clap::CommandFactory>::command();
    let mut path = vec!["dbms".to_string()];
    for arg in std::env::args().skip(1) {
        if let Some(sub) = cmd.find_subcommand(&arg).cloned() {
            path.push(arg);
            cmd = sub;
        }
    }
    path.join(" ")
}

/// Let the allocator keep memory it gets back, up to 1 GiB, and serve blocks up to 32 MiB from
/// its heap. The stages stream rasters band by band, allocating and freeing the same few large
/// buffers (8 MB a band and layer on an 8192-wide grid) hundreds of times; by default glibc
/// returns such blocks to the system at every free and the next band faults them in again, page
/// by page: a tenth of `dbms pyramid`'s time on the 8192² benchmark (docs/pyramid.md). Peak
/// memory is unchanged in kind (still bounded by the bands in flight).
#[cfg(all(target_os = "linux", target_env = "gnu"))]
fn keep_freed_memory() {
    // SAFETY: mallopt only sets allocator parameters; called before any thread starts.
    unsafe {
        libc::mallopt(libc::M_MMAP_THRESHOLD, 32 << 20);
        libc::mallopt(libc::M_TRIM_THRESHOLD, 1 << 30);
    }
}

#[cfg(not(all(target_os = "linux", target_env = "gnu")))]
fn keep_freed_memory() {}

#[cfg(test)]
mod tests {
    /// Clap's own consistency checks (duplicate short flags, bad defaults, ...) over every command.
    #[test]
    fn the_command_line_is_consistent() {
        <super::Cli as clap::CommandFactory>::command().debug_assert();
    }
}
