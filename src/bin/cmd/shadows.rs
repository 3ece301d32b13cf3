//! `dbms shadows`: the cast-shadow mask of a database for one sun.

use super::Ctx;
use dbms::db::{self, Database};
use dbms::io::geotiff::GeoTiffWriter;
use dbms::pyramid::raised::{rasterise_prisms, read_buildings, Raised, TerrainSample};
use dbms::pyramid::shade::{band_rows, ShadowBits};
use dbms::raster::RowSource;
use dbms::shadow::{LIT, NODATA, SHADOW};
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
    // The terrain is streamed band by band, never whole: memory is the one-bit-a-cell mask
    // plus a band (docs/shadows.md).
    let terrain = db.elevation_rows()?;
    let grid = terrain.grid().clone();
    // Raised buildings stand in the sun's way only when shadow-height has written them.
    let prisms = if db.manifest.layers.contains_key("buildings") {
        rasterise_prisms(&grid, &read_buildings(&db.layer_path("buildings")?)?)
    } else {
        Vec::new()
    };
    let band = band_rows(grid.width);
    let progress = ctx.progress(1 + grid.height.div_ceil(band) as u64, "shadows");
    let under = prisms.iter().map(|c| c.index).collect();
    let raised = Raised::new(prisms, &TerrainSample::read(&terrain, under, band)?);
    let bits = ShadowBits::cast(&terrain, &raised, &sun).map_err(|e| e.in_file(&elevation_path))?;
    progress.inc(1);

    let mut out = GeoTiffWriter::create_u8(&args.output, &grid, Some(NODATA))?;
    let (mut nodata, mut mask) = (0, Vec::new());
    for row0 in (0..grid.height).step_by(band) {
        let rows = band.min(grid.height - row0);
        let heights = terrain.read_rows(row0, rows)?;
        let first = row0 * grid.width;
        mask.clear();
        mask.extend(heights.iter().enumerate().map(|(k, z)| match () {
            _ if z.is_nan() => NODATA,
            _ if bits.get(first + k) => SHADOW,
            _ => LIT,
        }));
        nodata += heights.iter().filter(|z| z.is_nan()).count();
        out.push_rows(&mask)?;
        progress.inc(1);
    }
    out.finish()?;
    progress.finish();
    let (shadow, building_cells) = (bits.count(), raised.len());
    let lit = grid.len() - shadow - nodata;
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
