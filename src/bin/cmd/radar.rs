//! `dbms radar`: a database's radar backscatter σ⁰ for a radar far off in a given direction,
//! with shadow, layover and dihedral returns (issue 18, docs/sensors.md).

use super::Ctx;
use dbms::db::Database;
use dbms::radar_map::{parse_band, radar_map, RadarOptions};
use std::path::PathBuf;

/// Every cell's radar backscatter σ⁰ (linear) for a distant radar, from the materials' published
/// σ⁰ models at the cell's local incidence, as Float32 GeoTIFF; NaN where the material has no
/// model for the band.
#[derive(clap::Args)]
pub struct Args {
    /// The database directory (with a materials layer: `dbms materials`).
    #[arg(long)]
    db: PathBuf,
    /// Grid azimuth from the scene toward the radar, degrees clockwise from grid north.
    #[arg(long, allow_negative_numbers = true)]
    azimuth: f64,
    /// The radar's elevation above the horizon seen from the scene (its depression angle),
    /// degrees, between 0 and 90.
    #[arg(long, allow_negative_numbers = true)]
    elevation: f64,
    /// Radar band: L, S, C, X, Ku, Ka or W (the material table's models for it are used).
    #[arg(long, default_value = "X")]
    band: String,
    /// Also write each cell's class as a byte GeoTIFF: 0 nodata, 1 lit, 2 shadow, 3 layover,
    /// 4 dihedral, 5 specular, 6 no model.
    #[arg(long, value_name = "TIF")]
    class_out: Option<PathBuf>,
    /// Also write a picture: σ⁰ from −30 dB (black) to 0 dB (white), dihedral yellow, layover
    /// magenta, no model dark red.
    #[arg(long, value_name = "PNG")]
    preview: Option<PathBuf>,
    /// Output σ⁰ GeoTIFF (linear, m²/m²).
    #[arg(short, long)]
    output: PathBuf,
}

pub fn run(args: Args, ctx: &Ctx) -> dbms::Result<()> {
    let db = Database::open(&args.db)?;
    let opts = RadarOptions {
        azimuth_deg: args.azimuth,
        elevation_deg: args.elevation,
        band: parse_band(&args.band)?,
    };
    let progress = ctx.progress(0, "radar");
    let (map, summary) = radar_map(&db, &opts)?;
    map.write(
        &args.output,
        args.class_out.as_deref(),
        args.preview.as_deref(),
    )?;
    progress.finish();
    ctx.report(&summary);
    Ok(())
}
