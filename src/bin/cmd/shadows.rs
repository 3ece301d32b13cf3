//! `dbms shadows`: the cast-shadow mask of a database for one sun.

use super::Ctx;
use dbms::db::Database;
use dbms::shadow_mask::{write_shadow_mask, MaskCounts, Rule};
use serde_json::json;
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
    let MaskCounts {
        shadow,
        lit,
        nodata,
        building_cells,
        object_cells,
    } = counts;
    let valid = (shadow + lit).max(1) as f64;
    let rule = rule.name();
    let standing_text = match (building_cells, object_cells) {
        (0, 0) => String::new(),
        (b, o) => format!(", {b} building and {o} object cells raised"),
    };
    ctx.report(
        format!(
            "{}: sun elevation {:.3}°, azimuth {:.3}°, {rule} rule: {shadow} cells in shadow ({:.2} %), {lit} lit, {nodata} nodata{standing_text}",
            args.output.display(),
            sun.elevation_deg,
            sun.azimuth_deg,
            100.0 * shadow as f64 / valid,
        ),
        json!({
            "output": args.output,
            "sun": { "elevation_deg": sun.elevation_deg, "azimuth_deg": sun.azimuth_deg, "time": args.sun.time },
            "rule": rule,
            "terrain_only": args.terrain_only,
            "cells": { "shadow": shadow, "lit": lit, "nodata": nodata },
            "shadow_fraction": shadow as f64 / valid,
            "building_cells": building_cells,
            "object_cells": object_cells,
        }),
    );
    Ok(())
}
