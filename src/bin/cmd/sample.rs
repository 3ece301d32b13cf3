//! `dbms sample`: generate the sample scene.

use super::Ctx;
use dbms::sample_scene::{self, SampleOptions};
use std::path::PathBuf;

/// Generate the sample scene (DEM, orthophoto with cast shadows, building footprints, truth).
#[derive(clap::Args)]
pub struct Args {
    /// Output directory (created if missing).
    #[arg(short, long, value_name = "DIR")]
    output: PathBuf,
    /// Seed of the terrain, layout and textures; the same seed gives byte-identical files.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// DEM cells per side at 0.5 m (the orthophoto has twice as many at 0.25 m).
    #[arg(long, default_value_t = sample_scene::DEFAULT_SIZE)]
    size: usize,
}

pub fn run(args: Args, ctx: &Ctx) -> dbms::Result<()> {
    let scene = sample_scene::generate(SampleOptions {
        seed: args.seed,
        size: args.size,
    })?;
    let files = sample_scene::write(&scene, &args.output)?;
    ctx.report(&Generated {
        sun: sample_scene::sun_json(&scene),
        buildings: scene.buildings.len(),
        max_slope_percent: scene.max_slope_percent,
        shadow_fraction: scene.shadow_fraction,
        output: args.output,
        files,
        scene: &scene,
    });
    Ok(())
}

/// `dbms sample`'s summary.
#[derive(serde::Serialize)]
struct Generated<'a> {
    output: PathBuf,
    files: Vec<PathBuf>,
    buildings: usize,
    /// The sun as scene.json states it.
    sun: serde_json::Value,
    max_slope_percent: f64,
    shadow_fraction: f64,
    #[serde(skip)]
    scene: &'a sample_scene::Scene,
}

impl std::fmt::Display for Generated<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let scene = self.scene;
        write!(
            f,
            "{}: {} × {} DEM at {} m, {} × {} orthophoto at {} m, {} buildings; sun {} (elevation {:.2}°, azimuth {:.2}° from grid north)",
            self.output.display(),
            scene.dem.width(),
            scene.dem.height(),
            sample_scene::DEM_CELL_M,
            scene.ortho.width(),
            scene.ortho.height(),
            sample_scene::ORTHO_CELL_M,
            self.buildings,
            sample_scene::SUN_TIME,
            scene.sun.elevation_deg,
            scene.sun.azimuth_deg
        )
    }
}
