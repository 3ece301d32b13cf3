//! `dbms shadows`: the cast-shadow mask of a database for one sun.

use super::{Ctx, SunUsed};
use dbms::db::Database;
use dbms::shadow_mask::{write_shadow_mask, Rule};
use std::path::PathBuf;

/// Write the cast-shadow mask (byte GeoTIFF: 1 = shadow, 0 = lit, 255 = nodata) of a database's
/// elevation, with its raised buildings and placed voxel objects when it has them.
#[derive(clap::Args)]
pub struct Args {
    /// The database directory.
    #[arg(long)]
    db: PathBuf,
    #[command(flatten)]
    sun: super::SunArgs,
    /// Which cells a ray tests, and at what distance (docs/shadows.md): `geometric` compares
    /// each crossed cell at the distance of the ray's point nearest its centre (streamed, the
    /// pyramid's rule); `sunmask` is GRASS r.sunmask's rule, the cell containing each step point
    /// at the step's distance, to match GRASS cell for cell (holds the elevation in memory).
    #[arg(long, value_enum, default_value = "geometric")]
    rule: RuleArg,
    /// Cast from the bare terrain: ignore the database's buildings and placed objects.
    #[arg(long)]
    terrain_only: bool,
    /// Output mask GeoTIFF.
    #[arg(short, long)]
    output: PathBuf,
}

/// The shadow rule `--rule` names.
#[derive(Clone, Copy, PartialEq, clap::ValueEnum)]
enum RuleArg {
    Geometric,
    Sunmask,
}

pub fn run(args: Args, ctx: &Ctx) -> dbms::Result<()> {
    let db = Database::open(&args.db)?;
    let sun = args.sun.resolve(&db)?.ok_or_else(|| {
        dbms::Error::msg("a shadow mask needs a sun")
            .fix("give --time, or --sun-elevation and --sun-azimuth")
    })?;
    let rule = match args.rule {
        RuleArg::Geometric => Rule::Geometric,
        RuleArg::Sunmask => Rule::Sunmask,
    };
    let progress = ctx.progress(0, "shadows");
    let counts = write_shadow_mask(&db, &sun, rule, args.terrain_only, &args.output, &progress)?;
    progress.finish();
    ctx.report(&Shadows {
        sun: SunUsed::new(&sun, &args.sun),
        output: args.output,
        rule: rule.name(),
        terrain_only: args.terrain_only,
        cells: Cells {
            shadow: counts.shadow,
            lit: counts.lit,
            nodata: counts.nodata,
        },
        shadow_fraction: counts.shadow as f64 / (counts.shadow + counts.lit).max(1) as f64,
        building_cells: counts.building_cells,
        object_cells: counts.object_cells,
    });
    Ok(())
}

/// `dbms shadows`' summary.
#[derive(serde::Serialize)]
struct Shadows {
    output: PathBuf,
    sun: SunUsed,
    rule: &'static str,
    terrain_only: bool,
    cells: Cells,
    /// Shadow cells over valid cells.
    shadow_fraction: f64,
    building_cells: usize,
    object_cells: usize,
}

/// The mask's cells by value.
#[derive(serde::Serialize)]
struct Cells {
    shadow: usize,
    lit: usize,
    nodata: usize,
}

impl std::fmt::Display for Shadows {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let Cells {
            shadow,
            lit,
            nodata,
        } = self.cells;
        write!(
            f,
            "{}: sun elevation {:.3}°, azimuth {:.3}°, {} rule: {shadow} cells in shadow ({:.2} %), {lit} lit, {nodata} nodata",
            self.output.display(),
            self.sun.elevation_deg,
            self.sun.azimuth_deg,
            self.rule,
            100.0 * shadow as f64 / (shadow + lit).max(1) as f64,
        )?;
        match (self.building_cells, self.object_cells) {
            (0, 0) => Ok(()),
            (b, o) => write!(f, ", {b} building and {o} object cells raised"),
        }
    }
}
