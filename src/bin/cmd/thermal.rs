//! `dbms thermal`: a database's surface temperature and 8–12 µm radiance at a time (issue 18,
//! docs/thermal.md).

use super::Ctx;
use dbms::db::Database;
use dbms::thermal_map::{thermal_map, Conditions, ThermalOptions};
use std::path::PathBuf;

/// The surface temperature of every cell at a time, from its material's heat balance through a
/// clear day (sun, shadows, sky, air, wind), as Float32 GeoTIFF in kelvin.
#[derive(clap::Args)]
pub struct Args {
    /// The database directory (with a materials layer: `dbms materials`).
    #[arg(long)]
    db: PathBuf,
    /// UTC time of the product (RFC 3339), the end of the simulated day.
    #[arg(long)]
    time: String,
    /// Mean air temperature of the day, °C (also the deep-ground temperature).
    #[arg(long, default_value_t = Conditions::default().air_mean_c, allow_negative_numbers = true)]
    air_temp: f64,
    /// Daily air temperature range (max − min), K; the minimum falls at 03:00, the maximum at
    /// 15:00 local solar time.
    #[arg(long, default_value_t = Conditions::default().air_range_k)]
    air_range: f64,
    /// Wind speed, m/s (convection: McAdams).
    #[arg(long, default_value_t = Conditions::default().wind_m_per_s)]
    wind: f64,
    /// Relative humidity, a fraction in (0, 1] (the sky's long-wave: Brutsaert; evaporation).
    #[arg(long, default_value_t = Conditions::default().relative_humidity)]
    humidity: f64,
    /// Time step, s (a day must be a whole number of steps, 24 to 128).
    #[arg(long, default_value_t = 900.0)]
    step: f64,
    /// Also write the 8–12 µm band radiance, W·m⁻²·sr⁻¹, as Float32 GeoTIFF.
    #[arg(long, value_name = "TIF")]
    radiance_out: Option<PathBuf>,
    /// Also write a picture of the temperature (white hot, linear from the coldest cell).
    #[arg(long, value_name = "PNG")]
    preview: Option<PathBuf>,
    /// Output temperature GeoTIFF (kelvin, nodata −9999).
    #[arg(short, long)]
    output: PathBuf,
}

pub fn run(args: Args, ctx: &Ctx) -> dbms::Result<()> {
    let db = Database::open(&args.db)?;
    let mut opts = ThermalOptions::at(dbms::sun::parse_time(&args.time)?);
    opts.conditions = Conditions {
        air_mean_c: args.air_temp,
        air_range_k: args.air_range,
        wind_m_per_s: args.wind,
        relative_humidity: args.humidity,
    };
    opts.step_s = args.step;
    let progress = ctx.progress(0, "thermal");
    let map = thermal_map(&db, &opts)?;
    map.write(
        &args.output,
        args.radiance_out.as_deref(),
        args.preview.as_deref(),
    )?;
    progress.finish();
    ctx.report(&map.summary);
    Ok(())
}
