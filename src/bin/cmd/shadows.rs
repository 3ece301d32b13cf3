//! `dbms shadows`: the cast-shadow mask of a database for one sun.

use super::Ctx;
use dbms::db::{self, Database};
use dbms::pyramid::raised::{rasterise_prisms, read_buildings, Raised};
use dbms::shadow::{cast_shadows, Sun, LIT, NODATA, SHADOW};
use serde_json::json;
use std::path::PathBuf;

/// Write the cast-shadow mask (byte GeoTIFF: 1 = shadow, 0 = lit, 255 = nodata) of a database's
/// elevation, with its raised buildings when it has a `buildings` layer.
#[derive(clap::Args)]
pub struct Args {
    /// The database directory.
    #[arg(long)]
    db: PathBuf,
    /// UTC time (RFC 3339, e.g. 2026-06-21T10:00:00Z): the sun over the database centre.
    #[arg(long, required_unless_present_all = ["sun_elevation", "sun_azimuth"], conflicts_with_all = ["sun_elevation", "sun_azimuth"])]
    time: Option<String>,
    /// Sun elevation above the horizon, degrees (0, 90].
    #[arg(long, requires = "sun_azimuth", allow_negative_numbers = true)]
    sun_elevation: Option<f64>,
    /// Sun azimuth, degrees clockwise from north, toward the sun.
    #[arg(long, requires = "sun_elevation", allow_negative_numbers = true)]
    sun_azimuth: Option<f64>,
    /// Output mask GeoTIFF.
    #[arg(short, long)]
    output: PathBuf,
}

pub fn run(args: Args, ctx: &Ctx) -> dbms::Result<()> {
    let db = Database::open(&args.db)?;
    let sun = match (&args.time, args.sun_elevation, args.sun_azimuth) {
        (Some(t), _, _) => dbms::pyramid::sun_at(&db, t)?,
        (None, Some(e), Some(a)) => Sun::new(e, a)?,
        _ => unreachable!("clap requires --time or both sun angles"),
    };
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
    let mask = cast_shadows(&heights, sun.elevation_deg, sun.azimuth_deg).map_err(|e| e.in_file(&elevation_path))?;
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
            "sun": { "elevation_deg": sun.elevation_deg, "azimuth_deg": sun.azimuth_deg, "time": args.time },
            "cells": { "shadow": shadow, "lit": lit, "nodata": nodata },
            "shadow_fraction": shadow as f64 / valid,
            "building_cells": building_cells,
        }),
    );
    Ok(())
}
