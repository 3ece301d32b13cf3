//! `dbms pyramid`: the max-Z / average-colour hierarchy of a database as a paged tile file.

use super::Ctx;
use dbms::db::Database;
use dbms::pyramid::{build_pyramid, PyramidOptions, DEFAULT_FACTOR, DEFAULT_PAGE};
use dbms::tiles::Compression;
use std::path::PathBuf;

/// Build the render database: every level (max Z, average colour, occupancy) in one tile file,
/// with shadows and shading for a sun when one is given.
#[derive(clap::Args)]
pub struct Args {
    /// The database directory.
    #[arg(long)]
    db: PathBuf,
    /// Ratio of cell sizes between levels: 4 (cells of 1, 4, 16, 64) or 2.
    #[arg(long, default_value_t = DEFAULT_FACTOR)]
    factor: usize,
    /// Number of levels (default: down to the first level that fits in one page).
    #[arg(long)]
    levels: Option<usize>,
    /// Page edge in cells (a multiple of the factor).
    #[arg(long, default_value_t = DEFAULT_PAGE)]
    page: usize,
    #[command(flatten)]
    sun: super::SunArgs,
    /// Fraction of full-sun brightness left in shadow (the patent's F), in (0, 1].
    #[arg(long, default_value_t = dbms::pyramid::shade::DEFAULT_SHADOW_FACTOR)]
    shadow_factor: f64,
    /// Per-page compression: none or lz4.
    #[arg(long, default_value = "none")]
    compression: String,
    /// Also write every level as GeoTIFF here (level<N>_maxz.tif, level<N>_colour.tif).
    #[arg(long)]
    export_levels: Option<PathBuf>,
    /// Keep a ledger beside the tile file (TILES.ledger.json) and make again only the pages
    /// that buildings or placements changed since the build it records touch; the rest are
    /// copied. The tile file is byte for byte a full build's; without a usable ledger (or with
    /// --export-levels) every page is made, and the summary says why.
    #[arg(long)]
    incremental: bool,
    /// Output tile file.
    #[arg(short, long)]
    output: PathBuf,
}

pub fn run(args: Args, ctx: &Ctx) -> dbms::Result<()> {
    let db = Database::open(&args.db)?;
    // No sun given: no shadow or shading work at all.
    let sun = args.sun.resolve(&db)?;
    let opts = PyramidOptions {
        factor: args.factor,
        levels: args.levels,
        page_size: args.page,
        sun,
        shadow_factor: args.shadow_factor,
        compression: Compression::parse(&args.compression)?,
        export_levels: args.export_levels,
        incremental: args.incremental,
    };
    let progress = ctx.progress(0, "pyramid");
    ctx.report(&build_pyramid(
        &db,
        ctx.wait,
        &args.output,
        &opts,
        &progress,
    )?);
    Ok(())
}
