//! `dbms sun`: where the sun is, seen from a point or from a database's centre.

use super::Ctx;
use chrono::SecondsFormat;
use dbms::db::Database;
use dbms::sun::{self, Atmosphere, Observer, SunOptions, SunPosition};
use dbms::Error;
use std::path::PathBuf;

/// Sun elevation, azimuth (clockwise from true north) and zenith in degrees, by NREL SPA; with
/// --db also the azimuth from grid north (true azimuth less the meridian convergence); with
/// --moon also the moon's place, phase and light on the ground (docs/moon.md).
#[derive(clap::Args)]
#[command(group = clap::ArgGroup::new("place").required(true).args(["lat", "db"]))]
pub struct Args {
    /// Observer latitude, degrees north (-90..90).
    #[arg(
        long,
        value_name = "DEG",
        allow_negative_numbers = true,
        requires = "lon"
    )]
    lat: Option<f64>,
    /// Observer longitude, degrees east (-180..180).
    #[arg(
        long,
        value_name = "DEG",
        allow_negative_numbers = true,
        requires = "lat"
    )]
    lon: Option<f64>,
    /// Use the centre of this database instead of --lat/--lon.
    #[arg(long, value_name = "DB", conflicts_with_all = ["lat", "lon"])]
    db: Option<PathBuf>,
    /// The instant, RFC 3339 with a UTC offset: 2026-06-21T10:00:00Z or 2026-06-21T12:00:00+02:00.
    #[arg(long, value_name = "RFC3339")]
    time: String,
    /// Observer height above the ellipsoid, metres (only the parallax uses it: 1e-7° per 100 m).
    #[arg(
        long,
        value_name = "M",
        default_value_t = 0.0,
        allow_negative_numbers = true
    )]
    height: f64,
    /// The geometric sun, without atmospheric refraction.
    #[arg(long)]
    no_refraction: bool,
    /// TT - UT1 in seconds [default: Espenak & Meeus model].
    #[arg(long, value_name = "S", allow_negative_numbers = true)]
    delta_t: Option<f64>,
    /// UT1 - UTC in seconds, |dUT1| < 1 (IERS Bulletin A).
    #[arg(
        long,
        value_name = "S",
        default_value_t = 0.0,
        allow_negative_numbers = true
    )]
    delta_ut1: f64,
    /// Station air pressure for refraction, millibar (hPa).
    #[arg(long, value_name = "MBAR", default_value_t = Atmosphere::default().pressure_mbar, allow_negative_numbers = true)]
    pressure: f64,
    /// Air temperature for refraction, degrees Celsius.
    #[arg(long, value_name = "C", default_value_t = Atmosphere::default().temperature_c, allow_negative_numbers = true)]
    temperature: f64,
    /// Also the moon (Meeus ch. 47, same options): elevation, azimuth, distance, phase, and the
    /// illuminance of moonlight and of the moonless night sky on a horizontal surface.
    #[arg(long)]
    moon: bool,
    /// Atmospheric extinction for the moonlight, magnitudes per air mass (0.172: a high site;
    /// 0.25–0.3 at sea level).
    #[arg(long, value_name = "MAG", default_value_t = dbms::moon::DEFAULT_EXTINCTION_MAG_PER_AIRMASS, requires = "moon")]
    extinction: f64,
}

pub fn run(args: Args, ctx: &Ctx) -> dbms::Result<()> {
    let utc = sun::parse_time(&args.time)?;
    // With --db, also the meridian convergence at the centre: grid north's angle from true north.
    let (latitude_deg, longitude_deg, convergence_deg) = match (&args.db, args.lat, args.lon) {
        (Some(dir), _, _) => {
            let db = Database::open(dir)?;
            let (lat, lon, gamma) = db.centre_on_globe().ok_or_else(|| {
                Error::file(
                    dir,
                    format!(
                        "cannot convert the grid centre to latitude/longitude ({}: dbms converts geographic and UTM CRSs)",
                        db.grid().crs.name()
                    ),
                )
                .fix("give --lat and --lon of the centre instead")
            })?;
            (lat, lon, Some(gamma))
        }
        (None, Some(lat), Some(lon)) => (lat, lon, None),
        _ => unreachable!("clap requires --db or both --lat and --lon"),
    };
    let observer = Observer {
        latitude_deg,
        longitude_deg,
        height_m: args.height,
    };
    let opts = SunOptions {
        refraction: !args.no_refraction,
        delta_t_s: args.delta_t,
        delta_ut1_s: args.delta_ut1,
        atmosphere: Atmosphere {
            pressure_mbar: args.pressure,
            temperature_c: args.temperature,
        },
    };
    let p = sun::sun_position(&observer, utc, &opts)?;
    let delta_t_s = args.delta_t.unwrap_or_else(|| sun::delta_t_model_s(utc));
    let time = utc.to_rfc3339_opts(SecondsFormat::AutoSi, true);
    let moon = match args.moon {
        false => None,
        true => {
            let position = dbms::moon::moon_position(&observer, utc, &opts)?;
            Some(MoonReport {
                grid_azimuth_deg: convergence_deg
                    .map(|g| sun::grid_azimuth_deg(position.azimuth_deg, g)),
                light: position.light(args.extinction)?,
                night_sky_lux: dbms::moon::night_sky_lux(),
                position,
            })
        }
    };

    ctx.report(&SunReport {
        position: p,
        grid_azimuth_deg: convergence_deg.map(|g| sun::grid_azimuth_deg(p.azimuth_deg, g)),
        grid_convergence_deg: convergence_deg,
        time,
        latitude_deg,
        longitude_deg,
        height_m: args.height,
        db: args.db.as_ref().map(|d| d.display().to_string()),
        refraction: opts.refraction,
        pressure_mbar: args.pressure,
        temperature_c: args.temperature,
        delta_t_s,
        delta_t_source: match args.delta_t {
            Some(_) => "given",
            None => "Espenak & Meeus 2006 model",
        },
        delta_ut1_s: args.delta_ut1,
        moon,
    });
    Ok(())
}

/// The moon, with `--moon`.
#[derive(serde::Serialize)]
struct MoonReport {
    /// Elevation, azimuth from true north, distance, phase angle and lit fraction.
    #[serde(flatten)]
    position: dbms::moon::MoonPosition,
    /// Azimuth from grid north (with `--db`), degrees.
    grid_azimuth_deg: Option<f64>,
    /// Moonlight above the air and on the ground.
    light: dbms::moon::Moonlight,
    /// The moonless clear night sky's illuminance on a horizontal surface, lux.
    night_sky_lux: f64,
}

/// `dbms sun`'s summary: the position and everything it was computed from.
#[derive(serde::Serialize)]
struct SunReport {
    /// Elevation, azimuth from true north and zenith, degrees.
    #[serde(flatten)]
    position: SunPosition,
    /// Azimuth from grid north (with `--db`), degrees.
    grid_azimuth_deg: Option<f64>,
    /// Grid north's angle from true north at the database centre (with `--db`), degrees.
    grid_convergence_deg: Option<f64>,
    /// The time, RFC 3339 UTC.
    time: String,
    latitude_deg: f64,
    longitude_deg: f64,
    height_m: f64,
    db: Option<String>,
    refraction: bool,
    pressure_mbar: f64,
    temperature_c: f64,
    delta_t_s: f64,
    delta_t_source: &'static str,
    delta_ut1_s: f64,
    #[serde(skip_serializing_if = "Option::is_none")]
    moon: Option<MoonReport>,
}

impl std::fmt::Display for SunReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let p = &self.position;
        write!(
            f,
            "sun at {} seen from {:.6} N, {:.6} E, {} m ({}):\n  elevation {:11.6} deg\n  azimuth   {:11.6} deg (clockwise from true north)\n  zenith    {:11.6} deg",
            self.time,
            self.latitude_deg,
            self.longitude_deg,
            self.height_m,
            if self.refraction { "with refraction" } else { "geometric, no refraction" },
            p.elevation_deg,
            p.azimuth_deg,
            p.zenith_deg,
        )?;
        if let (Some(a), Some(g)) = (self.grid_azimuth_deg, self.grid_convergence_deg) {
            write!(
                f,
                "\n  grid azimuth {a:8.6} deg (clockwise from grid north; convergence {g:+.6} deg)"
            )?;
        }
        if let Some(m) = &self.moon {
            let p = &m.position;
            write!(
                f,
                "\nmoon:\n  elevation {:11.6} deg\n  azimuth   {:11.6} deg (clockwise from true north)\n  distance  {:11.1} km\n  phase angle {:9.4} deg, {:.1} % lit\n  moonlight {:.3e} lux on the ground (horizontal), {:.3e} lux above the air; moonless sky {:.1e} lux",
                p.elevation_deg,
                p.azimuth_deg,
                p.distance_km,
                p.phase_angle_deg,
                100.0 * p.illuminated_fraction,
                m.light.horizontal_lux,
                m.light.exoatmospheric_lux,
                m.night_sky_lux,
            )?;
        }
        Ok(())
    }
}
