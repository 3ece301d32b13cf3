//! `dbms plan`: a scene's build steps, and which of them are out of date.

use super::Ctx;
use dbms::scene::plan::{self, PlannedStep};
use dbms::scene::{makefile, snakefile};
use std::path::PathBuf;

/// List the steps that build a scene file's products, each with its inputs and whether it is
/// up to date (docs/scene.md).
#[derive(clap::Args)]
pub struct Args {
    /// The scene file (TOML, schemas/scene.schema.json).
    scene: PathBuf,
    /// Print the steps as a Makefile instead (make runs the same commands).
    #[arg(long, conflicts_with_all = ["stamp", "snakefile"])]
    makefile: bool,
    /// Print the steps as a Snakefile instead (Snakemake runs the same commands, here with -j or
    /// on a cluster with an executor).
    #[arg(long, conflicts_with = "stamp")]
    snakefile: bool,
    /// Record that step STEP has just run (what the Makefile's rules call after a step): the
    /// stamp --begin STEP recorded when it started, or else one taken now.
    #[arg(long, value_name = "STEP", conflicts_with = "begin")]
    stamp: Option<String>,
    /// Record that step STEP starts now, its inputs hashed now (what the Makefile's rules call
    /// before a step): an input changed while it runs is not recorded as built.
    #[arg(long, value_name = "STEP", conflicts_with_all = ["makefile", "snakefile"])]
    begin: Option<String>,
    /// Build each visual product as N shards merged at the end, instead of the scene's
    /// `[build] shards` (1: one dbms pyramid).
    #[arg(long, value_name = "N")]
    shards: Option<usize>,
}

pub fn run(args: Args, ctx: &Ctx) -> dbms::Result<()> {
    let scene = super::scene(&args.scene, args.shards)?;
    if let Some(step) = &args.stamp {
        return plan::stamp(&scene, step);
    }
    if let Some(step) = &args.begin {
        return plan::begin(&scene, step);
    }
    if args.snakefile {
        super::stdout(snakefile::snakefile(&scene, &args.scene)?.trim_end());
        return Ok(());
    }
    if args.makefile {
        super::stdout(makefile::makefile(&scene, &args.scene)?.trim_end());
        return Ok(());
    }
    ctx.report(&Planned {
        scene: args.scene,
        steps: plan::plan(&scene)?,
    });
    Ok(())
}

/// `dbms plan`'s summary.
#[derive(serde::Serialize)]
struct Planned {
    scene: PathBuf,
    steps: Vec<PlannedStep>,
}

impl Planned {
    /// The cost of the steps to run by their last builds: ` (about 21.0 s by their last
    /// builds)`, saying how many were never timed; empty when none was.
    fn estimate(&self) -> String {
        let to_run = self.steps.iter().filter(|s| !s.up_to_date);
        let timed: Vec<f64> = to_run.clone().filter_map(|s| s.last_seconds).collect();
        let untimed = to_run.count() - timed.len();
        match (timed.is_empty(), untimed) {
            (true, _) => String::new(),
            (false, 0) => format!(
                " (about {:.1} s by their last builds)",
                timed.iter().sum::<f64>()
            ),
            (false, n) => format!(
                " (at least {:.1} s by their last builds; {n} never timed)",
                timed.iter().sum::<f64>()
            ),
        }
    }
}

impl std::fmt::Display for Planned {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let to_run = self.steps.iter().filter(|s| !s.up_to_date).count();
        write!(
            f,
            "{}: {} steps, {}",
            self.scene.display(),
            self.steps.len(),
            match to_run {
                0 => "all up to date".to_string(),
                n => format!("{n} to run{}", self.estimate()),
            }
        )?;
        let width = self
            .steps
            .iter()
            .map(|s| s.step.name.len())
            .max()
            .unwrap_or(0);
        for s in &self.steps {
            let status = match s.up_to_date {
                true => "up to date".to_string(),
                false => format!("runs: {}", s.why.join("; ")),
            };
            let took = match s.last_seconds {
                Some(t) => format!("; took {t:.1} s last time"),
                None => String::new(),
            };
            write!(
                f,
                "\n  {:width$}  {}  ({}{took})",
                s.step.name, status, s.step.does
            )?;
        }
        Ok(())
    }
}
