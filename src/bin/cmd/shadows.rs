//! `dbms shadows`: the cast-shadow mask of a database for one sun.

use super::Ctx;
use dbms::db::{self, Database};
use dbms::io::geotiff::GeoTiffWriter;
use dbms::pyramid::shade::{band_rows, ShadowBits};
use dbms::raster::RowSource;
use dbms::shadow::{cast_shadows_sunmask_slice, LIT, NODATA, SHADOW};
use dbms::standing::{Raised, Standing};
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
    rule: Rule,
    /// Cast from the bare terrain: ignore the database's buildings and placed objects.
    #[arg(long)]
    terrain_only: bool,
    /// Output mask GeoTIFF.
    #[arg(short, long)]
    output: PathBuf,
}

/// The shadow rule `--rule` names.
#[derive(Clone, Copy, PartialEq, clap::ValueEnum)]
enum Rule {
    Geometric,
    Sunmask,
}

/// A cast mask: one bit a cell (the streamed geometric cast) or one byte (the sunmask rule).
enum Cast {
    Bits(ShadowBits),
    Mask(Vec<u8>),
}

impl Cast {
    fn shadowed(&self, i: usize) -> bool {
        match self {
            Cast::Bits(b) => b.get(i),
            Cast::Mask(m) => m[i] == SHADOW,
        }
    }
}

pub fn run(args: Args, ctx: &Ctx) -> dbms::Result<()> {
    let db = Database::open(&args.db)?;
    let sun = args.sun.resolve(&db)?.ok_or_else(|| {
        dbms::Error::msg("a shadow mask needs a sun")
            .fix("give --time, or --sun-elevation and --sun-azimuth")
    })?;
    let elevation_path = db.layer_path(db::ELEVATION)?;
    // The geometric cast streams the terrain band by band, never whole: memory is the
    // one-bit-a-cell mask plus a band (docs/shadows.md).
    let terrain = db.elevation_rows()?;
    let grid = terrain.grid().clone();
    let band = band_rows(grid.width);
    // What stands on the terrain (buildings, placed objects), as the pyramid raises it.
    let standing = if args.terrain_only {
        None
    } else {
        Some(Standing::read(&db, &terrain, band)?)
    };
    let empty = Raised::default();
    let raised = standing.as_ref().map_or(&empty, |s| &s.all);
    let progress = ctx.progress(1 + grid.height.div_ceil(band) as u64, "shadows");
    let cast = match args.rule {
        Rule::Geometric => Cast::Bits(
            ShadowBits::cast(&terrain, &sun, |s, row| raised.lay_over(s, row))
                .map_err(|e| e.in_file(&elevation_path))?,
        ),
        Rule::Sunmask => {
            let mut heights = terrain.read_rows(0, grid.height)?.into_owned();
            for c in raised.cells() {
                heights[c.index] = c.top_z;
            }
            Cast::Mask(
                cast_shadows_sunmask_slice(&heights, &grid, &sun)
                    .map_err(|e| e.in_file(&elevation_path))?,
            )
        }
    };
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
            _ if cast.shadowed(first + k) => SHADOW,
            _ => LIT,
        }));
        nodata += heights.iter().filter(|z| z.is_nan()).count();
        out.push_rows(&mask)?;
        progress.inc(1);
    }
    out.finish()?;
    progress.finish();
    let shadow = match &cast {
        Cast::Bits(b) => b.count(),
        Cast::Mask(m) => m.iter().filter(|&&v| v == SHADOW).count(),
    };
    let (building_cells, object_cells) = standing
        .as_ref()
        .map_or((0, 0), |s| (s.buildings.len(), s.objects.len()));
    let lit = grid.len() - shadow - nodata;
    let valid = (shadow + lit).max(1) as f64;
    let rule = match args.rule {
        Rule::Geometric => "geometric",
        Rule::Sunmask => "sunmask",
    };
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
