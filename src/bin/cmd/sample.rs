//! `dbms sample`: generate the sample scene.

use super::Ctx;
use dbms::sample::{self, SampleOptions};
use serde_json::json;
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
    #[arg(long, default_value_t = sample::DEFAULT_SIZE)]
    size: usize,
}

pub fn run(args: Args, ctx: &Ctx) -> dbms::Result<()> {
    let scene = sample::generate(SampleOptions {
        seed: args.seed,
        size: args.size,
    })?;
    let files = sample::write(&scene, &args.output)?;
    ctx.report(
        format!(
            "{}: {} × {} DEM at {} m, {} × {} orthophoto at {} m, {} buildings; sun {} (elevation {:.2}°, azimuth {:.2}° from grid north)",
            args.output.display(),
            scene.dem.width(),
            scene.dem.height(),
            sample::DEM_CELL_M,
            scene.ortho.width(),
            scene.ortho.height(),
            sample::ORTHO_CELL_M,
            scene.buildings.len(),
            sample::SUN_TIME,
            scene.sun.elevation_deg,
            scene.sun.azimuth_deg
        ),
        json!({
            "output": args.output,
            "files": files,
            "buildings": scene.buildings.len(),
            "sun": sample::sun_json(&scene),
            "max_slope_percent": scene.max_slope_percent,
            "shadow_fraction": scene.shadow_fraction,
        }),
    );
    Ok(())
}
