//! Solar position (NREL SPA) for shading and shadow-height.
//!
//! [`sun_position`] gives the topocentric elevation, zenith and azimuth of the sun's centre for
//! an observer on the Earth at a UTC instant, by the NREL Solar Position Algorithm (Reda &
//! Andreas 2004; stated accuracy ±0.0003° for years −2000..6000). [`SunPosition::from_angles`]
//! lets a stage give the sun directly instead.
//!
//! Invariants and conventions:
//! * azimuth is degrees clockwise from geographic north, always in [0, 360);
//! * elevation is degrees above the horizon in [−90, 90], zenith = 90 − elevation, and elevation
//!   includes atmospheric refraction unless [`SunOptions::refraction`] is off;
//! * elevation and the direction vector are continuous in time (see `spa` for the one place
//!   this departs from SPA: well below the horizon, where SPA's refraction switches off in a step);
//! * [`SunPosition::direction_enu`] points from the ground TO the sun, x east, y north, z up.

mod delta_t;
pub(crate) mod spa;
mod terms;

use crate::db::Database;
use crate::{Error, Result};
use chrono::{DateTime, Datelike, Utc};

/// A validated sun direction over a grid: what shadows and shading are cast for.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sun {
    /// Elevation above the horizon, degrees, in (0, 90].
    pub elevation_deg: f64,
    /// Azimuth toward the sun, degrees clockwise from grid north (the grid's +y axis), in
    /// [0, 360). A sun model's azimuth is from true north: subtract the grid's meridian
    /// convergence ([`crate::crs::Crs::grid_convergence_deg`]) first, as [`on_grid`] does.
    pub azimuth_deg: f64,
}

impl Sun {
    /// Check and normalise a sun direction (degrees). Errors on non-finite angles, an elevation
    /// at or below the horizon (night: everything would be shadow) or above 90°.
    pub fn new(elevation_deg: f64, azimuth_deg: f64) -> Result<Sun> {
        if !elevation_deg.is_finite() || !azimuth_deg.is_finite() {
            return Err(Error::msg(format!(
                "sun elevation {elevation_deg}° / azimuth {azimuth_deg}° is not a finite direction"
            ))
            .fix("give numbers in degrees"));
        }
        if elevation_deg <= 0.0 {
            return Err(Error::msg(format!(
                "sun elevation {elevation_deg:.3}° is at or below the horizon: the whole grid is in night shadow"
            ))
            .fix("choose a daytime --time or a --sun-elevation above 0"));
        }
        if elevation_deg > 90.0 {
            return Err(
                Error::msg(format!("sun elevation {elevation_deg}° is above 90°"))
                    .fix("give an elevation in (0, 90]"),
            );
        }
        Ok(Sun {
            elevation_deg,
            azimuth_deg: azimuth_deg.rem_euclid(360.0),
        })
    }

    /// Horizontal length in metres of the shadow cast by a vertical edge `height_m` metres tall
    /// on flat ground: `height / tan(elevation)`.
    pub fn shadow_length(&self, height_m: f64) -> f64 {
        height_m / self.elevation_deg.to_radians().tan()
    }

    /// Unit vector toward the sun in the grid's frame, `[east, north, up]` (east and north along
    /// the grid's axes): `[cos e sin a, cos e cos a, sin e]`.
    pub fn direction_enu(&self) -> [f64; 3] {
        enu(self.elevation_deg, self.azimuth_deg)
    }

    /// Horizontal unit vector toward the sun, `(east, north)`. Components within 1e-12 of 0 are
    /// snapped to 0 so azimuths 0, 90, 180 and 270 are exactly axis-aligned.
    pub fn direction(&self) -> (f64, f64) {
        let a = self.azimuth_deg.to_radians();
        let snap = |v: f64| if v.abs() < 1e-12 { 0.0 } else { v };
        (snap(a.sin()), snap(a.cos()))
    }
}

/// An azimuth from true north (a sun model's) turned to grid north, degrees in [0, 360):
/// `convergence_deg` is grid north's angle clockwise from true north (the meridian convergence,
/// [`crate::crs::Crs::grid_convergence_deg`]); near a UTM zone's edge it is 2° or more.
pub fn grid_azimuth_deg(true_azimuth_deg: f64, convergence_deg: f64) -> f64 {
    (true_azimuth_deg - convergence_deg).rem_euclid(360.0)
}

/// The sun `obs` sees at `utc` (NREL SPA, default options) as a grid direction: its azimuth
/// turned to grid north ([`grid_azimuth_deg`]). Errors as [`Sun::new`] does (a sun at or below
/// the horizon).
pub fn on_grid(obs: &Observer, utc: DateTime<Utc>, convergence_deg: f64) -> Result<Sun> {
    let pos = sun_position(obs, utc, &SunOptions::default())?;
    Sun::new(
        pos.elevation_deg,
        grid_azimuth_deg(pos.azimuth_deg, convergence_deg),
    )
}

/// The sun over the database centre at an RFC 3339 time (`--time`), on the grid ([`on_grid`],
/// seen from height 0).
pub fn at_database_centre(db: &Database, time: &str) -> Result<Sun> {
    let utc = parse_time(time)?;
    let (latitude_deg, longitude_deg, convergence_deg) = db.centre_on_globe().ok_or_else(|| {
        Error::file(
            &db.dir,
            format!(
                "cannot place the grid centre on the globe ({})",
                db.grid().crs.name()
            ),
        )
        .fix("give --sun-elevation and --sun-azimuth instead of a time")
    })?;
    let obs = Observer {
        latitude_deg,
        longitude_deg,
        height_m: 0.0,
    };
    on_grid(&obs, utc, convergence_deg)
        .map_err(|e| Error::msg(format!("at {time}: {}", e.problem)).fix(e.fix.unwrap_or_default()))
}

/// The orthophoto's own sun: from the last ingest stage's `photo_time` and the grid centre.
/// `None` when the database does not record the photo's time.
pub fn photo_sun(db: &Database) -> Result<Option<Sun>> {
    let time = db
        .manifest
        .stages
        .iter()
        .rev()
        .find(|s| s.name == "ingest")
        .and_then(|s| s.params.get("photo_time"));
    let Some(time) = time.and_then(|t| t.as_str()) else {
        return Ok(None);
    };
    let sun = at_database_centre(db, time)
        .map_err(|e| e.in_file(db.dir.join(crate::db::MANIFEST_FILE)))?;
    Ok(Some(sun))
}

/// Where the sun is seen from.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Observer {
    /// Geodetic latitude, degrees, positive north, in [−90, 90].
    pub latitude_deg: f64,
    /// Longitude, degrees, positive east, in [−180, 180].
    pub longitude_deg: f64,
    /// Height above the ellipsoid, metres, in [−11 000, 100 000] (SPA calls it elevation;
    /// it only enters the parallax, where a geoid-height error of 100 m moves the sun by 1e−7°).
    pub height_m: f64,
}

/// The air at the observer, used for refraction only.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Atmosphere {
    /// Local (station, not sea-level) pressure, millibar = hPa, in [0, 2000].
    pub pressure_mbar: f64,
    /// Air temperature, degrees Celsius, in [−100, 100].
    pub temperature_c: f64,
}

impl Default for Atmosphere {
    /// The standard atmosphere at sea level: 1013.25 mbar, 15 °C.
    fn default() -> Atmosphere {
        Atmosphere {
            pressure_mbar: 1013.25,
            temperature_c: 15.0,
        }
    }
}

/// How to compute the sun's position.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SunOptions {
    /// Add atmospheric refraction to the elevation (the sun as seen); default true. Off gives
    /// the geometric (airless) direction.
    pub refraction: bool,
    /// ΔT = TT − UT1 in seconds, |ΔT| ≤ 8000; `None` uses the Espenak & Meeus (2006)
    /// polynomial model ([`delta_t_model_s`]).
    pub delta_t_s: Option<f64>,
    /// UT1 − UTC in seconds, |ΔUT1| < 1 (IERS Bulletin A); default 0. Ignoring it costs up to
    /// 0.004° of hour angle.
    pub delta_ut1_s: f64,
    /// Pressure and temperature for refraction.
    pub atmosphere: Atmosphere,
}

impl Default for SunOptions {
    fn default() -> SunOptions {
        SunOptions {
            refraction: true,
            delta_t_s: None,
            delta_ut1_s: 0.0,
            atmosphere: Atmosphere::default(),
        }
    }
}

/// Direction of the sun's centre as seen by an observer.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize)]
pub struct SunPosition {
    /// Degrees above the horizon, [−90, 90] (negative: below the horizon).
    pub elevation_deg: f64,
    /// Degrees clockwise from north, [0, 360).
    pub azimuth_deg: f64,
    /// Degrees from the zenith, 90 − elevation, [0, 180].
    pub zenith_deg: f64,
}

impl SunPosition {
    /// The sun given directly: `elevation_deg` in [−90, 90], `azimuth_deg` any finite value
    /// (clockwise from north), normalised to [0, 360).
    pub fn from_angles(elevation_deg: f64, azimuth_deg: f64) -> Result<SunPosition> {
        if !(-90.0..=90.0).contains(&elevation_deg) {
            return Err(Error::msg(format!(
                "sun elevation {elevation_deg}° is outside [-90, 90]"
            ))
            .fix("give degrees above the horizon, -90 to 90"));
        }
        if !azimuth_deg.is_finite() {
            return Err(
                Error::msg(format!("sun azimuth {azimuth_deg} is not a number"))
                    .fix("give degrees clockwise from north, e.g. 135"),
            );
        }
        Ok(SunPosition {
            elevation_deg,
            azimuth_deg: spa::wrap_deg(azimuth_deg),
            zenith_deg: 90.0 - elevation_deg,
        })
    }

    /// Unit vector from the ground TO the sun in the local east-north-up frame:
    /// `[x east, y north, z up]` = `[cos e sin a, cos e cos a, sin e]` for elevation e, azimuth a.
    pub fn direction_enu(&self) -> [f64; 3] {
        enu(self.elevation_deg, self.azimuth_deg)
    }
}

/// `[cos e sin a, cos e cos a, sin e]` for elevation `e` and azimuth `a` (degrees): the unit
/// vector toward a direction in an east-north-up frame.
fn enu(elevation_deg: f64, azimuth_deg: f64) -> [f64; 3] {
    let (e, a) = (elevation_deg.to_radians(), azimuth_deg.to_radians());
    [e.cos() * a.sin(), e.cos() * a.cos(), e.sin()]
}

/// Topocentric position of the sun for `obs` at the UTC instant `utc` (years −2000..6000).
///
/// Errors (one line, with the fix) when an input is out of range or not a number.
pub fn sun_position(obs: &Observer, utc: DateTime<Utc>, opts: &SunOptions) -> Result<SunPosition> {
    let out = spa::spa(&spa_input(obs, utc, opts)?);
    Ok(SunPosition {
        elevation_deg: out.e,
        azimuth_deg: out.azimuth,
        zenith_deg: out.zenith,
    })
}

/// The ΔT (TT − UT1, seconds) the model gives at `utc`: Espenak & Meeus (2006) polynomials at
/// the decimal year. This is what [`sun_position`] uses when [`SunOptions::delta_t_s`] is `None`.
pub fn delta_t_model_s(utc: DateTime<Utc>) -> f64 {
    delta_t::delta_t_s(2000.0 + (days_since_j2000(utc) + 0.5) / 365.2425)
}

/// Parses an RFC 3339 time (`2026-06-21T10:00:00Z`, `2026-06-21T12:00:00+02:00`, fractional
/// seconds allowed) into UTC. A time without a UTC offset is refused: it would be ambiguous.
pub fn parse_time(s: &str) -> Result<DateTime<Utc>> {
    DateTime::parse_from_rfc3339(s.trim()).map(|t| t.with_timezone(&Utc)).map_err(|e| {
        Error::msg(format!("time {s:?} is not an RFC 3339 time ({e})"))
            .fix("write it like 2026-06-21T10:00:00Z or 2026-06-21T12:00:00+02:00 (the offset is required)")
    })
}

/// UTC days since J2000.0 (2000-01-01T12:00:00Z), exact to the nanosecond before rounding to f64.
fn days_since_j2000(utc: DateTime<Utc>) -> f64 {
    const J2000_UNIX_S: i64 = 946_728_000;
    let secs = utc.timestamp() - J2000_UNIX_S;
    secs as f64 / 86400.0 + f64::from(utc.timestamp_subsec_nanos()) / 86400e9
}

/// `v` if it lies in `lo..=hi`, else an error naming `what` with the `fix`.
fn within(what: &str, v: f64, lo: f64, hi: f64, fix: &str) -> Result<f64> {
    if (lo..=hi).contains(&v) {
        Ok(v)
    } else {
        Err(Error::msg(format!("{what} {v} is outside [{lo}, {hi}]")).fix(fix))
    }
}

/// Validates every input and converts it to SPA's.
pub(crate) fn spa_input(
    obs: &Observer,
    utc: DateTime<Utc>,
    opts: &SunOptions,
) -> Result<spa::Input> {
    let latitude_deg = within(
        "latitude",
        obs.latitude_deg,
        -90.0,
        90.0,
        "give degrees north, -90 to 90",
    )?;
    let longitude_deg = within(
        "longitude",
        obs.longitude_deg,
        -180.0,
        180.0,
        "give degrees east, -180 to 180",
    )?;
    let height_m = within(
        "observer height (m)",
        obs.height_m,
        -11_000.0,
        100_000.0,
        "give metres above the ellipsoid",
    )?;
    let year = utc.year();
    if !(-2000..=6000).contains(&year) {
        return Err(
            Error::msg(format!("year {year} is outside SPA's range -2000..6000"))
                .fix("give a time between the years -2000 and 6000"),
        );
    }
    let delta_t_s = match opts.delta_t_s {
        Some(dt) => within(
            "delta T (s)",
            dt,
            -8000.0,
            8000.0,
            "give TT - UT1 in seconds, about 69 in 2025",
        )?,
        None => delta_t_model_s(utc),
    };
    let delta_ut1_s = within(
        "delta UT1 (s)",
        opts.delta_ut1_s,
        -1.0,
        1.0,
        "give UT1 - UTC in seconds, |dUT1| < 1",
    )?;
    Ok(spa::Input {
        days_j2000: days_since_j2000(utc) + delta_ut1_s / 86400.0,
        delta_t_s,
        latitude_deg,
        longitude_deg,
        height_m,
        refraction: refraction_input(opts)?,
    })
}

/// The checked atmosphere (pressure in mbar, temperature in °C) SPA corrects refraction for,
/// `None` when refraction is off.
fn refraction_input(opts: &SunOptions) -> Result<Option<(f64, f64)>> {
    if !opts.refraction {
        return Ok(None);
    }
    let p = within(
        "pressure (mbar)",
        opts.atmosphere.pressure_mbar,
        0.0,
        2000.0,
        "give the station pressure in millibar (hPa), about 1013 at sea level",
    )?;
    let t = within(
        "temperature (°C)",
        opts.atmosphere.temperature_c,
        -100.0,
        100.0,
        "give the air temperature in degrees Celsius",
    )?;
    Ok(Some((p, t)))
}

#[cfg(test)]
mod tests {
    use super::*;
    use chrono::{Duration, TimeZone};
    use proptest::prelude::*;

    fn at(s: &str) -> DateTime<Utc> {
        parse_time(s).unwrap()
    }

    fn obs(latitude_deg: f64, longitude_deg: f64) -> Observer {
        Observer {
            latitude_deg,
            longitude_deg,
            height_m: 0.0,
        }
    }

    fn geometric() -> SunOptions {
        SunOptions {
            refraction: false,
            ..SunOptions::default()
        }
    }

    /// The SPA paper's example through the public API. The paper prints 5 decimals, so the
    /// tolerance is half a unit of the last digit, 5e-6°; NREL's spa.c and pvlib give
    /// 50.111622024 / 194.340240510, and we match those to 1e-8° (rounding only).
    #[test]
    fn spa_paper_example() {
        let o = Observer {
            latitude_deg: 39.742476,
            longitude_deg: -105.1786,
            height_m: 1830.14,
        };
        let opts = SunOptions {
            delta_t_s: Some(67.0),
            atmosphere: Atmosphere {
                pressure_mbar: 820.0,
                temperature_c: 11.0,
            },
            ..SunOptions::default()
        };
        let p = sun_position(&o, at("2003-10-17T12:30:30-07:00"), &opts).unwrap();
        assert!(
            (p.zenith_deg - 50.11162).abs() <= 5e-6,
            "zenith {}",
            p.zenith_deg
        );
        assert!(
            (p.azimuth_deg - 194.34024).abs() <= 5e-6,
            "azimuth {}",
            p.azimuth_deg
        );
        assert!((p.zenith_deg - 50.11162202403697).abs() <= 1e-8);
        assert!((p.azimuth_deg - 194.34024051024002).abs() <= 1e-8);
        assert_eq!(p.elevation_deg, 90.0 - p.zenith_deg);
    }

    /// Reference values from pvlib 0.16.1 `pvlib.spa.solar_position` (a separate SPA
    /// implementation; generated once with `pip install pvlib`, atmos_refract 0.5667, ΔUT1 0),
    /// random sites, heights, atmospheres and times over 1900–2100 plus hand-picked poles,
    /// date line and near-zenith cases. Columns: time, lat, lon, height m, pressure mbar,
    /// temperature °C, ΔT s, geometric elevation, apparent elevation, azimuth. None lies in the
    /// refraction fade band (see `spa`), where we depart from SPA on purpose.
    type PvlibCase = (&'static str, f64, f64, f64, f64, f64, f64, f64, f64, f64);
    const PVLIB: [PvlibCase; 25] = [
        (
            "2003-10-17T19:30:30Z",
            39.742476,
            -105.1786,
            1830.14,
            820.0,
            11.0,
            67.0,
            39.872045903839926,
            39.88837797596303,
            194.34024051024002,
        ),
        (
            "1900-01-01T00:00:00Z",
            89.5,
            0.0,
            0.0,
            1013.25,
            15.0,
            -2.8,
            -23.565110164521514,
            -23.565110164521514,
            359.1390657004449,
        ),
        (
            "2100-12-31T23:59:59Z",
            -89.5,
            179.9,
            2800.0,
            700.0,
            -40.0,
            203.0,
            23.52134735343093,
            23.5536697201647,
            0.8795637080573329,
        ),
        (
            "2026-06-21T08:24:00Z",
            23.44,
            54.0,
            10.0,
            1013.25,
            30.0,
            69.0,
            89.59063651951035,
            89.59072009094365,
            90.19564867383656,
        ),
        (
            "2024-02-29T12:00:00Z",
            0.0,
            -180.0,
            0.0,
            1010.0,
            10.0,
            69.2,
            -81.72905234855287,
            -81.72905234855287,
            201.8624234246131,
        ),
        (
            "2045-07-16T02:14:41Z",
            -47.1155,
            -41.5375,
            2468.5,
            628.1,
            -2.9,
            -0.8,
            -63.093806162482956,
            -63.093806162482956,
            199.65127385490175,
        ),
        (
            "2011-07-13T08:47:39Z",
            39.1608,
            -98.337,
            1449.0,
            779.4,
            -11.7,
            82.1,
            -21.983132257352807,
            -21.983132257352807,
            32.17785449863959,
        ),
        (
            "2032-07-02T03:12:33Z",
            73.1508,
            -58.8269,
            3465.5,
            776.0,
            6.3,
            42.4,
            6.462248854281653,
            6.564816564538827,
            349.1516389991857,
        ),
        (
            "2077-06-19T11:58:36Z",
            17.7051,
            98.1011,
            2217.8,
            862.2,
            36.5,
            102.2,
            0.5211996283305468,
            0.8445087481681743,
            294.48266870120375,
        ),
        (
            "2096-08-23T15:59:49Z",
            -17.3112,
            60.952,
            405.9,
            940.5,
            2.1,
            19.4,
            -31.962722076986786,
            -31.962722076986786,
            272.2459866933963,
        ),
        (
            "1976-10-22T04:00:46Z",
            31.0733,
            -38.2497,
            737.4,
            855.2,
            21.1,
            117.9,
            -58.85421562625741,
            -58.85421562625741,
            55.70930986723607,
        ),
        (
            "1955-06-24T23:27:31Z",
            -75.0072,
            127.3494,
            1289.0,
            660.2,
            2.1,
            66.2,
            -15.668263376182573,
            -15.668263376182573,
            56.74325217587523,
        ),
        (
            "1992-10-04T09:25:01Z",
            53.1273,
            -47.4049,
            3669.2,
            779.9,
            0.4,
            16.9,
            0.38064932922419653,
            0.7254787995363146,
            98.0492874530969,
        ),
        (
            "1971-06-13T12:31:55Z",
            -72.7706,
            96.2448,
            486.2,
            682.4,
            4.2,
            31.9,
            -26.313546743568807,
            -26.313546743568807,
            263.618344195269,
        ),
        (
            "2019-09-30T10:18:35Z",
            -47.1365,
            -118.4596,
            1610.0,
            682.4,
            -20.4,
            55.9,
            -29.68329462016151,
            -29.68329462016151,
            134.08667630236414,
        ),
        (
            "2069-05-05T13:24:59Z",
            -75.647,
            57.3991,
            1715.5,
            726.4,
            -14.4,
            7.6,
            -13.418235153891233,
            -13.418235153891233,
            284.2982134731146,
        ),
        (
            "1999-04-05T13:47:48Z",
            -51.1628,
            31.6985,
            867.9,
            914.5,
            -5.6,
            72.0,
            14.416725427016425,
            14.477760334929314,
            299.50523374879447,
        ),
        (
            "2095-03-06T03:48:14Z",
            25.3269,
            65.9117,
            3526.5,
            783.4,
            19.6,
            3.8,
            24.24708848641645,
            24.27494679673709,
            109.34309430634733,
        ),
        (
            "2023-11-25T03:22:34Z",
            -33.5308,
            170.8783,
            275.7,
            878.1,
            15.4,
            84.5,
            48.43312946410337,
            48.44590425532767,
            276.2502501470477,
        ),
        (
            "1904-07-01T13:22:24Z",
            -45.8993,
            171.7461,
            1813.0,
            693.8,
            8.2,
            26.1,
            -65.4084761999512,
            -65.4084761999512,
            153.953645808597,
        ),
        (
            "2003-08-08T03:24:31Z",
            16.1816,
            -166.4213,
            2267.5,
            854.6,
            34.7,
            97.8,
            29.51572135419641,
            29.538809355161003,
            279.8516116394964,
        ),
        (
            "2068-01-12T00:09:37Z",
            -85.0734,
            -72.5938,
            3927.7,
            623.5,
            -1.0,
            4.3,
            20.11408292116487,
            20.14325221864271,
            250.39102925129384,
        ),
        (
            "2099-11-26T04:36:43Z",
            -36.6467,
            -63.591,
            1090.1,
            817.5,
            -15.3,
            89.8,
            -31.78061464585382,
            -31.78061464585382,
            170.33023560850256,
        ),
        (
            "1949-07-21T09:22:11Z",
            -7.8952,
            -53.9521,
            2535.9,
            939.3,
            -2.9,
            64.2,
            -7.383337389526977,
            -7.383337389526977,
            70.19511916315139,
        ),
        (
            "2100-05-24T03:29:41Z",
            46.7861,
            -74.8433,
            3724.1,
            815.8,
            -18.7,
            55.7,
            -19.671625384301077,
            -19.671625384301077,
            338.50029450899063,
        ),
    ];

    /// Matches pvlib's SPA to 3e-7°, a thousandth of SPA's accuracy. The differences seen (up to
    /// 1.2e-7°) are pvlib's: it forms the Julian day as unix/86400 + 2440587.5, whose f64 rounding
    /// (up to 2.3e-10 day) moves sidereal time by up to 8e-8°; we count days from J2000 exactly.
    #[test]
    fn matches_pvlib_spa() {
        const TOL: f64 = 3e-7;
        for (t, lat, lon, h, p, temp, dt, e0, e, az) in PVLIB {
            let o = Observer {
                latitude_deg: lat,
                longitude_deg: lon,
                height_m: h,
            };
            let opts = SunOptions {
                delta_t_s: Some(dt),
                atmosphere: Atmosphere {
                    pressure_mbar: p,
                    temperature_c: temp,
                },
                ..SunOptions::default()
            };
            let seen = sun_position(&o, at(t), &opts).unwrap();
            let geo = sun_position(
                &o,
                at(t),
                &SunOptions {
                    refraction: false,
                    ..opts
                },
            )
            .unwrap();
            // Azimuth is ill-conditioned near the poles: the same error on the sky is a larger
            // azimuth difference there.
            let az_tol = TOL / lat.to_radians().cos().max(0.01);
            assert!(
                (geo.elevation_deg - e0).abs() < TOL,
                "{t}: geometric elevation {} vs {e0}",
                geo.elevation_deg
            );
            assert!(
                (seen.elevation_deg - e).abs() < TOL,
                "{t}: apparent elevation {} vs {e}",
                seen.elevation_deg
            );
            assert!(
                (seen.azimuth_deg - az).abs() < az_tol,
                "{t}: azimuth {} vs {az}",
                seen.azimuth_deg
            );
        }
    }

    /// Largest sun motion per second, degrees: Earth rotation 15.04°/h, times 1.62 for the
    /// steepest refraction change (the fade band below the horizon).
    const MAX_RATE_DEG_PER_S: f64 = 15.05 / 3600.0 * 1.62;

    fn angle_between(a: [f64; 3], b: [f64; 3]) -> f64 {
        let dot: f64 = a.iter().zip(b.iter()).map(|(x, y)| x * y).sum();
        dot.clamp(-1.0, 1.0).acos().to_degrees()
    }

    /// Sweep: latitudes −90..90 by 10°, every month, years 1900–2100, a day in 10-minute steps.
    /// Range always holds; the sun's direction moves at most the rotation-plus-refraction bound,
    /// elevation likewise, and azimuth (away from the zenith, where it is undefined) moves at most
    /// bound / cos(elevation). Azimuth wrap at 0/360 and the poles are handled by comparing
    /// wrapped differences and direction vectors.
    #[test]
    fn sweep_range_and_continuity() {
        let step = 600.0;
        let bound = MAX_RATE_DEG_PER_S * step;
        for year in [1900, 1933, 1966, 2000, 2033, 2066, 2100] {
            for month in 1..=12 {
                let day0 = Utc.with_ymd_and_hms(year, month, 15, 0, 0, 0).unwrap();
                for lat in (-9..=9).map(|k| f64::from(k) * 10.0) {
                    let o = obs(lat, 37.5);
                    let mut prev: Option<SunPosition> = None;
                    for k in 0..=144 {
                        let p = sun_position(
                            &o,
                            day0 + Duration::seconds(600 * k),
                            &SunOptions::default(),
                        )
                        .unwrap();
                        assert!((-90.0..=90.0).contains(&p.elevation_deg), "{p:?}");
                        assert!((0.0..360.0).contains(&p.azimuth_deg), "{p:?}");
                        assert!((p.zenith_deg + p.elevation_deg - 90.0).abs() < 1e-12);
                        if let Some(q) = prev {
                            let moved = angle_between(p.direction_enu(), q.direction_enu());
                            assert!(
                                moved <= bound,
                                "{year}-{month} lat {lat} step {k}: moved {moved}°"
                            );
                            assert!((p.elevation_deg - q.elevation_deg).abs() <= bound);
                            let daz = (p.azimuth_deg - q.azimuth_deg).abs();
                            let daz = daz.min(360.0 - daz);
                            let cos_e = p
                                .elevation_deg
                                .to_radians()
                                .cos()
                                .min(q.elevation_deg.to_radians().cos());
                            if cos_e > 0.2 && lat.abs() < 90.0 {
                                assert!(
                                    daz * cos_e <= 1.2 * bound,
                                    "{year}-{month} lat {lat} step {k}: azimuth jumped {daz}°"
                                );
                            }
                        }
                        prev = Some(p);
                    }
                }
            }
        }
    }

    /// Hard case: SPA switches refraction off in one step when the sun sets; ours must not jump.
    /// One-second steps through a Denver sunset, from well above to well below the horizon.
    #[test]
    fn no_jump_at_sunset() {
        let o = Observer {
            latitude_deg: 39.742476,
            longitude_deg: -105.1786,
            height_m: 1830.14,
        };
        // Sunset that day is about 00:30 UTC on the 18th; cover 23:50..01:20.
        let start = at("2003-10-17T23:50:00Z");
        let mut prev = sun_position(&o, start, &SunOptions::default()).unwrap();
        let (mut crossed_zero, mut reached_deep) = (false, false);
        for s in 1..=5400 {
            let p = sun_position(&o, start + Duration::seconds(s), &SunOptions::default()).unwrap();
            let de = (p.elevation_deg - prev.elevation_deg).abs();
            assert!(
                de <= MAX_RATE_DEG_PER_S,
                "elevation jumped {de}° at {s} s ({prev:?} -> {p:?})"
            );
            crossed_zero |= prev.elevation_deg > 0.0 && p.elevation_deg <= 0.0;
            reached_deep |= p.elevation_deg < -3.0;
            prev = p;
        }
        assert!(
            crossed_zero && reached_deep,
            "the sweep must cover the whole sunset"
        );
    }

    #[test]
    fn polar_day_and_polar_night() {
        for (lat, day, up) in [
            (80.0, "2026-06-21", true),
            (80.0, "2026-12-21", false),
            (-80.0, "2026-12-21", true),
            (-80.0, "2026-06-21", false),
            (90.0, "2026-06-21", true),
            (-90.0, "2026-06-21", false),
        ] {
            let t0 = at(&format!("{day}T00:00:00Z"));
            for k in 0..=144 {
                let p = sun_position(
                    &obs(lat, 15.0),
                    t0 + Duration::minutes(10 * k),
                    &SunOptions::default(),
                )
                .unwrap();
                assert_eq!(
                    p.elevation_deg > 0.0,
                    up,
                    "lat {lat} {day} +{}min: {p:?}",
                    10 * k
                );
            }
        }
    }

    /// At the 2026 March equinox (14:46 UTC, USNO) the sun crosses the equator; at longitude
    /// −40° local noon falls within two minutes of it, so the noon sun is within 0.01° of the zenith.
    #[test]
    fn equator_equinox_noon_is_overhead() {
        let t0 = at("2026-03-20T14:30:00Z");
        let highest = (0..=1800)
            .map(|s| {
                sun_position(&obs(0.0, -40.0), t0 + Duration::seconds(s), &geometric())
                    .unwrap()
                    .elevation_deg
            })
            .fold(f64::MIN, f64::max);
        assert!(
            highest > 89.99,
            "highest equinox sun at the equator {highest}°"
        );
    }

    /// At the 2026 June solstice (08:24 UTC) the sun stands over the Tropic of Cancer
    /// (23.436°N, the obliquity of the ecliptic) at longitude 54.43°E (54° from the hour, 0.43° from
    /// the −1.7 min equation of time).
    #[test]
    fn solstice_sun_over_tropic_of_cancer() {
        let t = at("2026-06-21T08:24:00Z");
        let p = sun_position(&obs(23.436, 54.43), t, &geometric()).unwrap();
        assert!(p.zenith_deg < 0.1, "{p:?}");
        // 1° north of the tropic the noon sun is 1° from the zenith, to the south.
        let q = sun_position(&obs(24.436, 54.43), t, &geometric()).unwrap();
        assert!(
            (q.zenith_deg - 1.0).abs() < 0.1 && (q.azimuth_deg - 180.0).abs() < 10.0,
            "{q:?}"
        );
    }

    /// CI found this instant: at the subsolar point the sine of the elevation rounded to
    /// 1 + 2.2e-16 and `asin` gave NaN. The elevation must be 90°, not NaN.
    #[test]
    fn sun_exactly_overhead_is_not_nan() {
        let t = Utc.timestamp_opt(946_728_000 - 908_093_361, 0).unwrap();
        let geo = spa::spa(&spa_input(&obs(0.0, 0.0), t, &geometric()).unwrap());
        let lon = spa::wrap_deg(geo.alpha - geo.nu + 180.0) - 180.0;
        let p = sun_position(&obs(geo.delta, lon), t, &geometric()).unwrap();
        assert!(p.elevation_deg.is_finite() && p.zenith_deg < 1e-4, "{p:?}");
        assert!((0.0..360.0).contains(&p.azimuth_deg), "{p:?}");
    }

    proptest! {
        /// At the subsolar point (geodetic latitude = declination, longitude = right ascension −
        /// sidereal time) the sun is at the zenith, whatever the instant.
        #[test]
        fn subsolar_point_has_sun_overhead(secs in -3_155_760_000i64..3_155_760_000i64) {
            let t = Utc.timestamp_opt(946_728_000 + secs, 0).unwrap();
            let geo = spa::spa(&spa_input(&obs(0.0, 0.0), t, &geometric()).unwrap());
            let lon = spa::wrap_deg(geo.alpha - geo.nu + 180.0) - 180.0;
            let p = sun_position(&obs(geo.delta, lon), t, &geometric()).unwrap();
            // Residual: topocentric parallax along the tilted (geodetic) vertical, < 1e-5°.
            prop_assert!(p.zenith_deg < 1e-4, "{:?} at {} ({}, {})", p, t, geo.delta, lon);
        }

        /// Anywhere, any time in 1900–2100: results are in range, and over a short step the sun
        /// moves no faster than the rotation-plus-refraction bound (no jumps, wrap or poles aside,
        /// which the direction vector does not see).
        #[test]
        fn continuous_and_in_range_everywhere(
            lat in -90.0f64..=90.0,
            lon in -180.0f64..=180.0,
            secs in -3_155_760_000i64..3_155_760_000i64,
            step in 1i64..=120,
        ) {
            let o = obs(lat, lon);
            let t = Utc.timestamp_opt(946_728_000 + secs, 0).unwrap();
            let a = sun_position(&o, t, &SunOptions::default()).unwrap();
            let b = sun_position(&o, t + Duration::seconds(step), &SunOptions::default()).unwrap();
            for p in [a, b] {
                prop_assert!((-90.0..=90.0).contains(&p.elevation_deg) && (0.0..360.0).contains(&p.azimuth_deg), "{:?}", p);
            }
            let moved = angle_between(a.direction_enu(), b.direction_enu());
            prop_assert!(moved <= MAX_RATE_DEG_PER_S * step as f64, "moved {}° in {} s: {:?} -> {:?}", moved, step, a, b);
        }

        /// Direction vectors are unit length and agree with elevation and azimuth.
        #[test]
        fn direction_is_unit_and_consistent(e in -90.0f64..=90.0, a in -720.0f64..720.0) {
            let p = SunPosition::from_angles(e, a).unwrap();
            let d = p.direction_enu();
            prop_assert!((d.iter().map(|x| x * x).sum::<f64>() - 1.0).abs() < 1e-12);
            prop_assert!((d[2].asin().to_degrees() - e).abs() < 1e-6);
            prop_assert!((0.0..360.0).contains(&p.azimuth_deg));
            if e.abs() < 89.0 {
                let back = spa::wrap_deg(d[0].atan2(d[1]).to_degrees());
                let diff = (back - p.azimuth_deg).abs();
                prop_assert!(diff.min(360.0 - diff) < 1e-9);
            }
        }
    }

    /// Refraction lifts the sun by about half a degree at the horizon and almost nothing high up.
    #[test]
    fn refraction_on_off() {
        let o = obs(39.74, -105.18);
        let t0 = at("2026-06-21T00:00:00Z");
        let (mut horizon, mut high) = (0, 0);
        for k in 0..288 {
            let t = t0 + Duration::minutes(5 * k);
            let seen = sun_position(&o, t, &SunOptions::default())
                .unwrap()
                .elevation_deg;
            let geo = sun_position(&o, t, &geometric()).unwrap().elevation_deg;
            let lift = seen - geo;
            assert!(lift >= 0.0);
            if (0.0..1.0).contains(&geo) {
                horizon += 1;
                assert!((0.3..0.5).contains(&lift), "lift {lift} at geometric {geo}");
            }
            if geo > 45.0 {
                high += 1;
                assert!(lift < 0.017, "lift {lift} at geometric {geo}");
            }
            if geo < -2.0 {
                assert_eq!(lift, 0.0);
            }
        }
        assert!(horizon > 0 && high > 0);
        // No air, no refraction.
        let airless = Atmosphere {
            pressure_mbar: 0.0,
            ..Atmosphere::default()
        };
        assert_eq!(
            sun_position(
                &o,
                t0,
                &SunOptions {
                    atmosphere: airless,
                    ..SunOptions::default()
                }
            )
            .unwrap(),
            sun_position(&o, t0, &geometric()).unwrap()
        );
    }

    #[test]
    fn default_delta_t_is_near_observed() {
        // IERS: ΔT was 63.8 s in 2000.0 and 69.2 s in 2024.0; the 2005–2050 polynomial drifts high.
        assert!((delta_t_model_s(at("2000-01-01T00:00:00Z")) - 63.8).abs() < 0.5);
        assert!((delta_t_model_s(at("2024-01-01T00:00:00Z")) - 69.2).abs() < 6.0);
        // Using the model or the observed ΔT changes the sun by far less than SPA's 0.0003°.
        let t = at("2024-01-01T12:00:00Z");
        let model = sun_position(&obs(45.0, 0.0), t, &SunOptions::default()).unwrap();
        let observed = sun_position(
            &obs(45.0, 0.0),
            t,
            &SunOptions {
                delta_t_s: Some(69.2),
                ..SunOptions::default()
            },
        )
        .unwrap();
        assert!((model.elevation_deg - observed.elevation_deg).abs() < 1e-4);
        assert!(model != observed, "ΔT must reach the computation");
    }

    #[test]
    fn parse_time_accepts_offsets_and_refuses_garbage() {
        assert_eq!(at("2026-06-21T12:00:00+02:00"), at("2026-06-21T10:00:00Z"));
        assert_eq!(
            at("2026-06-21t10:00:00.500z").timestamp_subsec_millis(),
            500
        );
        for bad in [
            "2026-06-21T10:00:00",
            "yesterday",
            "2026-13-01T00:00:00Z",
            "",
        ] {
            let e = parse_time(bad).unwrap_err().to_string();
            assert!(
                e.contains("RFC 3339") && e.contains("2026-06-21T10:00:00Z") && !e.contains('\n'),
                "{e}"
            );
        }
    }

    #[test]
    fn bad_inputs_are_one_line_errors() {
        let t = at("2026-06-21T10:00:00Z");
        let d = SunOptions::default();
        let cases: [(Observer, SunOptions, &str); 8] = [
            (obs(90.5, 0.0), d, "latitude"),
            (obs(f64::NAN, 0.0), d, "latitude"),
            (obs(0.0, 180.5), d, "longitude"),
            (
                Observer {
                    height_m: 1e7,
                    ..obs(0.0, 0.0)
                },
                d,
                "height",
            ),
            (
                obs(0.0, 0.0),
                SunOptions {
                    delta_t_s: Some(9000.0),
                    ..d
                },
                "delta T",
            ),
            (
                obs(0.0, 0.0),
                SunOptions {
                    delta_ut1_s: 1.5,
                    ..d
                },
                "delta UT1",
            ),
            (
                obs(0.0, 0.0),
                SunOptions {
                    atmosphere: Atmosphere {
                        pressure_mbar: -1.0,
                        temperature_c: 15.0,
                    },
                    ..d
                },
                "pressure",
            ),
            (
                obs(0.0, 0.0),
                SunOptions {
                    atmosphere: Atmosphere {
                        pressure_mbar: 1000.0,
                        temperature_c: f64::INFINITY,
                    },
                    ..d
                },
                "temperature",
            ),
        ];
        for (o, opts, what) in cases {
            let e = sun_position(&o, t, &opts).unwrap_err().to_string();
            assert!(
                e.contains(what) && e.contains("; ") && !e.contains('\n'),
                "{e}"
            );
        }
        // Refraction off: the atmosphere is not used, so not checked.
        let no_air = SunOptions {
            refraction: false,
            atmosphere: Atmosphere {
                pressure_mbar: -1.0,
                temperature_c: 0.0,
            },
            ..d
        };
        assert!(sun_position(&obs(0.0, 0.0), t, &no_air).is_ok());
        let far = Utc.with_ymd_and_hms(7000, 1, 1, 0, 0, 0).unwrap();
        assert!(sun_position(&obs(0.0, 0.0), far, &d)
            .unwrap_err()
            .to_string()
            .contains("year 7000"));
    }

    #[test]
    fn from_angles_validates_and_normalises() {
        assert_eq!(
            SunPosition::from_angles(30.0, -90.0).unwrap().azimuth_deg,
            270.0
        );
        assert_eq!(
            SunPosition::from_angles(30.0, 360.0).unwrap().azimuth_deg,
            0.0
        );
        assert_eq!(
            SunPosition::from_angles(30.0, 720.5).unwrap().azimuth_deg,
            0.5
        );
        assert_eq!(
            SunPosition::from_angles(30.0, 10.0).unwrap().zenith_deg,
            60.0
        );
        for (e, a) in [
            (90.1, 0.0),
            (-91.0, 0.0),
            (f64::NAN, 0.0),
            (10.0, f64::NAN),
            (10.0, f64::INFINITY),
        ] {
            let err = SunPosition::from_angles(e, a).unwrap_err().to_string();
            assert!(err.contains("; ") && !err.contains('\n'), "{err}");
        }
        // The frame: east, north, up.
        let close =
            |a: [f64; 3], b: [f64; 3]| a.iter().zip(b.iter()).all(|(x, y)| (x - y).abs() < 1e-12);
        assert!(close(
            SunPosition::from_angles(0.0, 0.0).unwrap().direction_enu(),
            [0.0, 1.0, 0.0]
        ));
        assert!(close(
            SunPosition::from_angles(0.0, 90.0).unwrap().direction_enu(),
            [1.0, 0.0, 0.0]
        ));
        assert!(close(
            SunPosition::from_angles(90.0, 123.0)
                .unwrap()
                .direction_enu(),
            [0.0, 0.0, 1.0]
        ));
    }
}
