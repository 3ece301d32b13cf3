//! One module per subcommand: its clap `Args` and its `run`. Each stays thin: parse, call the
//! library, report. Shared output rules live in [`Ctx`].

pub mod build;
pub mod export;
pub mod info;
pub mod ingest;
pub mod materials;
pub mod object;
pub mod place;
pub mod plan;
pub mod pyramid;
pub mod radar;
pub mod render;
pub mod sample;
pub mod sculpt;
pub mod shadow_height;
pub mod shadows;
pub mod sun;
pub mod survey;
pub mod thermal;
pub mod tiles;

use dbms::choice::Choice;
use dbms::db::Database;
use dbms::progress::Progress;
use dbms::sun::Sun;
use serde::Serialize;
use std::fmt::Display;

/// Print `text` and a newline on stdout. A reader that stopped reading (`dbms ... | head`) ends
/// the process quietly with success, as it would a filter; any other write error is reported.
pub fn stdout(text: &str) {
    use std::io::Write;
    let mut out = std::io::stdout().lock();
    if let Err(e) = writeln!(out, "{text}").and_then(|()| out.flush()) {
        if e.kind() != std::io::ErrorKind::BrokenPipe {
            eprintln!("dbms: error: cannot write the summary to stdout: {e}");
            std::process::exit(1);
        }
        std::process::exit(0);
    }
}

/// What every subcommand needs from the global options.
pub struct Ctx {
    /// `--quiet`: print nothing but errors.
    pub quiet: bool,
    /// `--verbose`: list every warning, not a count and the first few.
    pub verbose: bool,
    /// `--json`: print a JSON summary on stdout instead of human text.
    pub json: bool,
    /// `--wait`: how long a change to a database waits for another's lock.
    pub wait: std::time::Duration,
}

impl Ctx {
    /// Print a command's summary on stdout: as JSON with `--json` (keys sorted, pretty), else
    /// as its human text unless `--quiet`. Every command reports through here, once.
    pub fn report<S: Serialize + Display>(&self, summary: &S) {
        if self.json {
            let json = serde_json::to_value(summary).expect("summaries serialise");
            stdout(&serde_json::to_string_pretty(&json).expect("JSON value serialises"));
        } else if !self.quiet {
            stdout(&summary.to_string());
        }
    }

    /// A log line on stderr, unless `--quiet`.
    pub fn log(&self, msg: impl Display) {
        if !self.quiet {
            eprintln!("{msg}");
        }
    }

    /// Warnings of one kind on stderr, `dbms: warning: <line>`: every one with `--verbose`, else
    /// the first [`WARNINGS_SHOWN`] and a line counting the rest (a city's footprint file can
    /// skip thousands of features). Nothing with `--quiet`, which prints errors only.
    pub fn warn_all(&self, warnings: &[String]) {
        if self.quiet {
            return;
        }
        let shown = if self.verbose {
            warnings.len()
        } else {
            WARNINGS_SHOWN.min(warnings.len())
        };
        for w in &warnings[..shown] {
            eprintln!("dbms: warning: {w}");
        }
        if shown < warnings.len() {
            eprintln!(
                "dbms: warning: {} more like these (--verbose lists them all)",
                warnings.len() - shown
            );
        }
    }

    /// A progress bar on stderr (drawn only on a terminal, never with `--quiet` or `--json`).
    pub fn progress(&self, total: u64, what: &str) -> Progress {
        Progress::new(total, what, !self.quiet && !self.json)
    }
}

/// Warnings of one kind printed without `--verbose` before the rest are counted.
pub const WARNINGS_SHOWN: usize = 5;

/// The sun, as the stages that shade or cast shadows take it: a UTC time (the sun over the
/// database centre, NREL SPA) or both angles. Each command decides what giving neither means.
#[derive(clap::Args)]
pub struct SunArgs {
    /// UTC time (RFC 3339, e.g. 2026-06-21T10:00:00Z): the sun over the database centre (NREL
    /// SPA), its azimuth turned to grid north by the meridian convergence there.
    #[arg(long, conflicts_with_all = ["sun_elevation", "sun_azimuth"])]
    pub time: Option<String>,
    /// Sun elevation above the horizon, degrees (0, 90].
    #[arg(long, requires = "sun_azimuth", allow_negative_numbers = true)]
    pub sun_elevation: Option<f64>,
    /// Sun azimuth, degrees clockwise from grid north (the grid's +y axis, as GRASS r.sunmask
    /// takes it), toward the sun. `dbms sun --db DB` prints it for a time.
    #[arg(long, requires = "sun_elevation", allow_negative_numbers = true)]
    pub sun_azimuth: Option<f64>,
}

impl SunArgs {
    /// The sun the options give for `db`, or `None` when neither a time nor angles were given.
    pub fn resolve(&self, db: &Database) -> dbms::Result<Option<Sun>> {
        match (&self.time, self.sun_elevation, self.sun_azimuth) {
            (Some(t), _, _) => Ok(Some(dbms::sun::at_database_centre(db, t)?)),
            (None, Some(e), Some(a)) => Ok(Some(Sun::new(e, a)?)),
            _ => Ok(None),
        }
    }
}

/// The sun a command worked with, as its summary reports it: the angles, and the `--time`
/// they came from (`None` when given as angles or taken from the photo).
#[derive(Serialize)]
pub struct SunUsed {
    /// Degrees above the horizon.
    pub elevation_deg: f64,
    /// Degrees clockwise from grid north.
    pub azimuth_deg: f64,
    /// The `--time` given.
    pub time: Option<String>,
}

impl SunUsed {
    /// `sun`, from `args`.
    pub fn new(sun: &Sun, args: &SunArgs) -> SunUsed {
        SunUsed {
            elevation_deg: sun.elevation_deg,
            azimuth_deg: sun.azimuth_deg,
            time: args.time.clone(),
        }
    }
}

/// Parse three comma-separated numbers given to option `name` (`what` says what they are, for
/// the error's fix).
pub fn triple(name: &str, s: &str, what: &str) -> dbms::Result<[f64; 3]> {
    numbers(name, s, what)
}

/// Parse `N` comma-separated numbers given to option `name` (`what` says what they are, for
/// the error's fix).
pub fn numbers<const N: usize>(name: &str, s: &str, what: &str) -> dbms::Result<[f64; N]> {
    let v: Vec<f64> = s
        .split(',')
        .map(|p| p.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .unwrap_or_default();
    let count = ["none", "one", "two", "three", "four"].get(N).copied();
    v.try_into().map_err(|_| {
        dbms::Error::msg(format!(
            "{name} {s}: expected {} comma-separated numbers",
            count.map_or(N.to_string(), str::to_string)
        ))
        .fix(format!("give {what}"))
    })
}

/// The clap parser of a library [`Choice`]: its names as the possible values, each with its
/// description (without a closing full stop, as clap shows doc comments).
pub fn choice<T: Choice>() -> impl clap::builder::TypedValueParser<Value = T> {
    use clap::builder::{PossibleValue, PossibleValuesParser, TypedValueParser};
    PossibleValuesParser::new(
        T::ALL
            .iter()
            .map(|v| PossibleValue::new(v.name()).help(v.help().trim_end_matches('.'))),
    )
    .map(|name| T::named(&name).expect("clap accepts only the names listed"))
}

/// The scene file at `path`, with `--shards` over its `[build] shards` when given.
pub fn scene(path: &std::path::Path, shards: Option<usize>) -> dbms::Result<dbms::scene::Scene> {
    let scene = dbms::scene::Scene::read(path)?;
    match shards {
        Some(n) => scene.with_shards(n).map_err(|e| e.in_file(path)),
        None => Ok(scene),
    }
}
