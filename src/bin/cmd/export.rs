//! `dbms export`: a database for other tools (`mesh`: a 3D Tiles tileset of glTF binaries).

use super::Ctx;
use dbms::db::Database;
use dbms::mesh::export::{export_mesh, MeshOptions};
use std::path::PathBuf;

/// Export a database for other tools.
#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    what: What,
}

#[derive(clap::Subcommand)]
enum What {
    /// Terrain (a TIN to a vertical error bound), buildings and placed objects as glTF 2.0
    /// binaries per tile under a 3D Tiles 1.1 tileset.json, with levels of detail.
    Mesh(MeshArgs),
}

#[derive(clap::Args)]
struct MeshArgs {
    /// The database directory.
    #[arg(long)]
    db: PathBuf,
    /// The output directory: tileset.json and tiles/LEVEL/X_Y.glb (created if missing).
    #[arg(short, long)]
    output: PathBuf,
    /// Vertical error bound of the finest terrain, metres (each coarser level: times the factor).
    #[arg(long, default_value_t = MeshOptions::default().max_error_m)]
    max_error: f64,
    /// Cells along a finest tile's side.
    #[arg(long, default_value_t = MeshOptions::default().tile_cells)]
    tile_cells: usize,
    /// How many times wider each coarser level's tiles are (2–8), as the pyramid's factor.
    #[arg(long, default_value_t = MeshOptions::default().factor)]
    factor: usize,
}

pub fn run(args: Args, ctx: &Ctx) -> dbms::Result<()> {
    match args.what {
        What::Mesh(a) => {
            let db = Database::open(&a.db)?;
            let opts = MeshOptions {
                max_error_m: a.max_error,
                tile_cells: a.tile_cells,
                factor: a.factor,
            };
            let progress = ctx.progress(0, "mesh");
            let summary = export_mesh(&db, &a.output, &opts, &progress)?;
            progress.finish();
            ctx.report(&summary);
            Ok(())
        }
    }
}
