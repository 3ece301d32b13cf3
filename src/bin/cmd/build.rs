//! `dbms build`: run what a scene's plan says is out of date.

use super::Ctx;
use dbms::scene::build;
use std::path::PathBuf;

/// Build a scene file's products: run the steps `dbms plan` lists as out of date, independent
/// ones side by side, stopping at the first error (docs/scene.md).
#[derive(clap::Args)]
pub struct Args {
    /// The scene file (TOML, schemas/scene.schema.json).
    scene: PathBuf,
    /// Steps run at once, at most (independent steps only; each step uses every core itself).
    #[arg(long, short, default_value_t = 2)]
    jobs: usize,
    /// Build each visual product as N shards merged at the end, instead of the scene's
    /// `[build] shards` (1: one dbms pyramid).
    #[arg(long, value_name = "N")]
    shards: Option<usize>,
}

pub fn run(args: Args, ctx: &Ctx) -> dbms::Result<()> {
    let scene = super::scene(&args.scene, args.shards)?;
    let exe = std::env::current_exe()
        .map_err(|e| dbms::Error::msg(format!("cannot find the dbms binary to run steps: {e}")))?;
    let progress = ctx.progress(0, "steps");
    let built = build::build(&scene, &exe, args.jobs, ctx.wait, &progress)?;
    progress.finish();
    ctx.report(&Summary {
        scene: args.scene,
        built,
    });
    Ok(())
}

/// `dbms build`'s summary.
#[derive(serde::Serialize)]
struct Summary {
    scene: PathBuf,
    #[serde(flatten)]
    built: build::Built,
}

impl std::fmt::Display for Summary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let b = &self.built;
        match b.ran.is_empty() {
            true => write!(
                f,
                "{}: all {} steps up to date, nothing to do",
                self.scene.display(),
                b.up_to_date.len()
            ),
            false => write!(
                f,
                "{}: ran {} ({}), {} up to date",
                self.scene.display(),
                b.ran.len(),
                b.ran.join(", "),
                b.up_to_date.len()
            ),
        }
    }
}
