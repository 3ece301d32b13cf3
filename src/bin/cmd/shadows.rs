//! `dbms shadows`: the cast-shadow mask of a database for one sun.

use super::Ctx;
use dbms::db::{self, Database};
use dbms::pyramid::raised::{rasterise_prisms, read_buildings, Raised};
use dbms::shadow::{cast_shadows, LIT, NODATA, SHADOW};
use serde_json::json;
use std::path::PathBuf;

/// Write the cast-shadow mask (byte GeoTIFF: 1 = shadow, 0 = lit, 255 = nodata) of a database's
/// elevation, with its raised buildings when it has a `buildings` layer.
#[derive(clap::Args)]
pub struct Args {
    /// The database directory.
    #[arg(long)]
    db: PathBuf,
    #[command(flatten)]
    sun: super::SunArgs,
    /// Output mask GeoTIFF.
    #[arg(short, long)]
    output: PathBuf,
}

pub fn run(args: Args, ctx: &Ctx) -> dbms::Result<()> {
    let db = Database::open(&args.db)?;
    let sun = args.sun.resolve(&db)?.ok_or_else(|| {
        dbms::Error::msg("a shadow mask needs a sun")
            .fix("give --time, or --sun-elevation and --sun-azimuth")
    })?;
    let elevation_path = db.layer_path(db::ELEVATION)?;
    let terrain = db.read_elevation()?;
    // Raised buildings stand in the sun's way only when shadow-height has written them.
    let (heights, building_cells) = if db.manifest.layers.contains_key("buildings") {
        let prisms = read_buildings(&db.layer_path("buildings")?)?;
        let raised = Raised::new(rasterise_prisms(&terrain.grid, &prisms), &terrain);
        (raised.heights(&terrain), raised.len())
    } else {
        (terrain, 0)
    };
    let mask = cast_shadows(&heights, sun.elevation_deg, sun.azimuth_deg)
        .map_err(|e| e.in_file(&elevation_path))?;
    dbms::io::geotiff::write_u8(&args.output, &mask, Some(NODATA))?;

    let count = |v: u8| mask.data.iter().filter(|&&m| m == v).count();
    let (shadow, lit, nodata) = (count(SHADOW), count(LIT), count(NODATA));
    let valid = (shadow + lit).max(1) as f64;
    ctx.report(
        format!(
            "{}: sun elevation {:.3}°, azimuth {:.3}°: {shadow} cells in shadow ({:.2} %), {lit} lit, {nodata} nodata{}",
            args.output.display(),
            sun.elevation_deg,
            sun.azimuth_deg,
            100.0 * shadow as f64 / valid,
            if building_cells > 0 { format!(", {building_cells} building cells raised") } else { String::new() }
        ),
        json!({
            "output": args.output,
            "sun": { "elevation_deg": sun.elevation_deg, "azimuth_deg": sun.azimuth_deg, "time": args.sun.time },
            "cells": { "shadow": shadow, "lit": lit, "nodata": nodata },
            "shadow_fraction": shadow as f64 / valid,
            "building_cells": building_cells,
        }),
    );
    Ok(())
}
