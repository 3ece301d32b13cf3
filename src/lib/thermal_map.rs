//! The `dbms thermal` stage: a database's surface temperature and 8–12 µm band radiance at a
//! time, for the thermal-infrared sensor (issue 18, docs/thermal.md "The database's map").
//!
//! Every cell is a one-dimensional column of its material ([`crate::material`]) under the
//! weather of one clear day, repeated until periodic ([`crate::thermal::Column::run_periodic`]:
//! the preceding diurnal cycles), ending at the product's time. Each step of the day forces it
//! with:
//! * the sun (NREL SPA over the database centre) through a clear sky: direct normal irradiance
//!   `1353 · 0.7^(AM^0.678)` W/m² (Meinel & Meinel 1976, *Applications of Solar Energy*, as
//!   given by Honsberg & Bowden, PVEducation, "Air Mass"), air mass of Kasten & Young (1989,
//!   *Applied Optics* 28(22)), on the cell's plane (the terrain's normal, a roof's face: [`crate::material::surface`]) when the
//!   cell is lit in the step's cast shadow (terrain, buildings and placed objects, the
//!   `dbms shadows` cast); diffuse light on a horizontal plane of a tenth of the direct normal
//!   (the same source's clear-sky rule), times the sky-view factor `(1 + n_z) / 2`;
//! * the sky's long-wave from the air temperature and humidity (Brutsaert 1975), the air
//!   temperature a sinusoid with its minimum at 03:00 and maximum at 15:00 local solar time,
//!   convection from the wind (McAdams), saturation vapour pressure by Magnus' formula
//!   (Alduchov & Eskridge 1996, *J. Appl. Meteor.* 35(4), eq. 21).
//!
//! Ground materials sit on deep ground at the day's mean air temperature; roofs over a room at
//! the table's room temperature. Materials with a surface resistance (vegetation, water)
//! evaporate (FAO-56's Penman–Monteith latent heat, [`crate::thermal`]). Each column starts
//! from its steady state under the day's mean forcing; each step is forced by the weather at
//! its end (where backward Euler balances it).
//!
//! Cells that share a material, a terrain normal (to 0.01 in each horizontal component) and a
//! history of lit and shadowed steps share one column ("clusters"), so the cost grows with the
//! variety of the scene, not its size.
//!
//! Invariant: the map is a pure function of the database (elevation, buildings, placements,
//! materials and table), the time, the conditions and the numerical knobs; a nodata elevation
//! or an unclassified cell is nodata (NaN) in both outputs.

use crate::db::Database;
use crate::error::{Error, Result};
use crate::grid::Grid;
use crate::material::surface::TopSurface;
use crate::material::table;
use crate::raster::Raster;
use crate::shadow::ShadowBits;
use crate::standing::Raised;
use crate::sun::{self, Observer, Sun, SunOptions};
use crate::thermal::{self, planck, Column, Forcing, GridSpec, Surface};
use chrono::{DateTime, Duration, Utc};
use rayon::prelude::*;
use serde::Serialize;
use std::collections::{BTreeMap, HashMap};

/// The most steps a day may have (one lit/shadowed bit per step and cell).
pub const MAX_STEPS: usize = 128;
/// The fewest: an hour a step (the sun moves 15° an hour).
pub const MIN_STEPS: usize = 24;

/// The weather of the product's day.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Conditions {
    /// Mean air temperature over the day, °C (also the deep-ground temperature).
    pub air_mean_c: f64,
    /// Daily air temperature range (maximum − minimum), K.
    pub air_range_k: f64,
    /// Wind speed, m/s.
    pub wind_m_per_s: f64,
    /// Relative humidity, 0..=1.
    pub relative_humidity: f64,
}

impl Conditions {
    /// Each value in its range, or a one-line error naming the `dbms thermal` option.
    pub fn check(&self) -> Result<()> {
        self.check_named(["--air-temp", "--air-range", "--wind", "--humidity"])
    }

    /// [`check`](Self::check), the error naming the value by `names` (air temperature, air
    /// range, wind, humidity): how the caller's user gave it.
    pub fn check_named(&self, names: [&str; 4]) -> Result<()> {
        let [air_temp, air_range, wind, humidity] = names;
        let bad = |option: &str, v: f64, want: &str| {
            Err(
                Error::msg(format!("{option} {v}: give it {want}")).fix(format!(
                    "e.g. the defaults: {}",
                    Conditions::default().options()
                )),
            )
        };
        if !(self.air_mean_c.is_finite() && self.air_mean_c.abs() <= 100.0) {
            return bad(air_temp, self.air_mean_c, "in °C, within ±100");
        }
        if !(0.0..=60.0).contains(&self.air_range_k) {
            return bad(air_range, self.air_range_k, "in K, from 0 to 60");
        }
        if self.air_mean_c - self.air_range_k / 2.0 <= -100.0 {
            return bad(
                air_range,
                self.air_range_k,
                "so the minimum stays above −100 °C",
            );
        }
        if !(0.0..=60.0).contains(&self.wind_m_per_s) {
            return bad(wind, self.wind_m_per_s, "in m/s, from 0 to 60");
        }
        if !(self.relative_humidity > 0.0 && self.relative_humidity <= 1.0) {
            return bad(humidity, self.relative_humidity, "as a fraction in (0, 1]");
        }
        Ok(())
    }

    /// The conditions as `dbms thermal` options.
    fn options(&self) -> String {
        format!(
            "--air-temp {} --air-range {} --wind {} --humidity {}",
            self.air_mean_c, self.air_range_k, self.wind_m_per_s, self.relative_humidity
        )
    }
}

impl Default for Conditions {
    /// A mild clear day: 15 °C ± 5 K, 2 m/s, 60 % humidity.
    fn default() -> Conditions {
        Conditions {
            air_mean_c: 15.0,
            air_range_k: 10.0,
            wind_m_per_s: 2.0,
            relative_humidity: 0.6,
        }
    }
}

/// What to compute, and how finely.
#[derive(Debug, Clone, PartialEq)]
pub struct ThermalOptions {
    /// The product's time (the end of the simulated day).
    pub time: DateTime<Utc>,
    /// The weather.
    pub conditions: Conditions,
    /// Length of a step, s; a day must be a whole number of steps, at most [`MAX_STEPS`].
    pub step_s: f64,
    /// The columns' grid.
    pub grid: GridSpec,
    /// Days are repeated until the surface temperature at every step changes less than this
    /// between two days, K.
    pub tolerance_k: f64,
    /// ... or this many days have run.
    pub max_days: usize,
}

impl ThermalOptions {
    /// Defaults for `time`: 15-minute steps, the thermal module's default grid, 0.01 K, 30 days.
    pub fn at(time: DateTime<Utc>) -> ThermalOptions {
        ThermalOptions {
            time,
            conditions: Conditions::default(),
            step_s: 900.0,
            grid: GridSpec::default(),
            tolerance_k: 0.01,
            max_days: 30,
        }
    }
}

/// Surface temperature per material, K.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MaterialTemperature {
    /// Cells of the material.
    pub cells: u64,
    /// Mean, minimum and maximum surface temperature, K.
    pub mean_k: f64,
    /// See `mean_k`.
    pub min_k: f64,
    /// See `mean_k`.
    pub max_k: f64,
}

/// What [`thermal_map`] did.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ThermalSummary {
    /// The product's time, RFC 3339.
    pub time: String,
    /// The weather used.
    pub conditions: Conditions,
    /// Steps in the day, and how many had the sun up.
    pub steps: usize,
    /// See `steps`.
    pub sunlit_steps: usize,
    /// Distinct columns simulated.
    pub clusters: usize,
    /// The most days a column needed, and the largest change left between its last two, K.
    pub days_max: usize,
    /// See `days_max`.
    pub change_k_max: f64,
    /// Per material name.
    pub materials: BTreeMap<String, MaterialTemperature>,
    /// Cells left nodata (no elevation, or unclassified).
    pub nodata_cells: u64,
}

/// The map: temperature (K) and band radiance (W·m⁻²·sr⁻¹, 8–12 µm) per cell, NaN = nodata.
pub struct ThermalMap {
    /// Surface temperature, K.
    pub temperature_k: Raster<f32>,
    /// Band radiance leaving the surface (emitted and reflected sky), W·m⁻²·sr⁻¹.
    pub radiance: Raster<f32>,
    /// The summary.
    pub summary: ThermalSummary,
}

/// The sun of a step when it is up.
struct Sunlit {
    /// The sun on the grid (what shadows are cast for).
    sun: Sun,
    /// `sun.direction_enu()` (grid east, north, up), kept for the columns' forcing.
    toward: [f64; 3],
    /// Direct normal irradiance, W/m².
    dni: f64,
}

/// One step of the day, shared by every cell.
struct Step {
    /// The sun, when it is up.
    sun: Option<Sunlit>,
    /// Diffuse irradiance on a horizontal plane, W/m².
    diffuse: f64,
    air_k: f64,
    /// The air's water vapour pressure, Pa.
    vapour: f64,
    longwave: f64,
}

/// Kasten & Young's (1989) relative air mass at zenith angle `zenith_deg`.
fn air_mass(zenith_deg: f64) -> f64 {
    1.0 / (zenith_deg.to_radians().cos() + 0.50572 * (96.07995 - zenith_deg).powf(-1.6364))
}

/// The day's steps: step `k` ends at `time − (n − 1 − k) · step`, and is forced by the
/// weather there (backward Euler balances the step's end: docs/thermal.md).
fn steps(db: &Database, opts: &ThermalOptions, n: usize) -> Result<Vec<Step>> {
    let (lat, lon, convergence) = db.centre_on_globe().ok_or_else(|| {
        Error::file(&db.dir, "cannot place the grid centre on the globe").fix(
            "a thermal map needs the sun through the day: give the database a CRS dbms can convert (UTM)",
        )
    })?;
    let obs = Observer {
        latitude_deg: lat,
        longitude_deg: lon,
        height_m: 0.0,
    };
    let c = opts.conditions;
    let step = Duration::milliseconds((opts.step_s * 1000.0).round() as i64);
    (0..n)
        .map(|k| {
            let at = opts.time - step * (n - 1 - k) as i32;
            let pos = sun::sun_position(&obs, at, &SunOptions::default())?;
            let sun = match pos.elevation_deg > 0.0 {
                true => {
                    let grid_sun = Sun::new(
                        pos.elevation_deg,
                        sun::grid_azimuth_deg(pos.azimuth_deg, convergence),
                    )?;
                    Some(Sunlit {
                        sun: grid_sun,
                        toward: grid_sun.direction_enu(),
                        dni: 1353.0 * 0.7f64.powf(air_mass(pos.zenith_deg).powf(0.678)),
                    })
                }
                false => None,
            };
            let diffuse = sun.as_ref().map_or(0.0, |s| 0.1 * s.dni);
            // Local solar hours (longitude only: the equation of time is a quarter hour at most).
            let seconds = at.timestamp() as f64 + lon / 15.0 * 3600.0;
            let hour = (seconds / 3600.0).rem_euclid(24.0);
            let air_c = c.air_mean_c
                + c.air_range_k / 2.0 * (std::f64::consts::TAU * (hour - 15.0) / 24.0).cos();
            let air_k = air_c + 273.15;
            let vapour = c.relative_humidity * thermal::saturation_vapour_pressure_pa(air_k).0;
            Ok(Step {
                sun,
                diffuse,
                air_k,
                vapour,
                longwave: thermal::brutsaert_clear_sky_longwave(air_k, vapour)?,
            })
        })
        .collect()
}

/// The thermal column of `m`, with deep ground at `deep_k`.
fn surface_of(m: &table::Material, deep_k: f64) -> Surface {
    Surface {
        albedo: m.solar_albedo,
        emissivity: m.emissivity,
        layers: m
            .layers
            .iter()
            .map(|l| thermal::Layer {
                thickness_m: l.thickness_m,
                conductivity_w_per_m_k: l.conductivity_w_per_m_k,
                density_kg_per_m3: l.density_kg_per_m3,
                specific_heat_j_per_kg_k: l.specific_heat_j_per_kg_k,
            })
            .collect(),
        surface_resistance_s_per_m: m.surface_resistance_s_per_m,
        bottom: match &m.bottom {
            table::Bottom::Deep => thermal::Bottom::Fixed {
                temperature_k: deep_k,
            },
            table::Bottom::Interior {
                temperature_k,
                h_w_per_m2_k,
                ..
            } => thermal::Bottom::Convective {
                coefficient_w_per_m2_k: *h_w_per_m2_k,
                temperature_k: *temperature_k,
            },
        },
    }
}

/// A column's identity: material, quantised normal and lit history (bit k: lit in step k).
#[derive(Hash, PartialEq, Eq, Clone, Copy)]
struct Key {
    material: u8,
    normal: [i16; 2],
    lit: u128,
}

/// The thermal map of `db` for `opts`.
pub fn thermal_map(db: &Database, opts: &ThermalOptions) -> Result<ThermalMap> {
    let n = steps_a_day(opts.step_s)?;
    let c = opts.conditions;
    c.check()?;
    let surface = TopSurface::read(db)?;
    let grid: Grid = surface.grid().clone();
    let days = steps(db, opts, n)?;
    let lit = lit_history(&surface, &days)?;
    let clusters = Clusters::of(&surface, &lit);

    // One periodic column per cluster: its temperature at the time, and its band radiance.
    let sky_band = {
        // The sky as a blackbody at the temperature that emits its long-wave.
        let t_sky = (days[n - 1].longwave / thermal::STEFAN_BOLTZMANN).powf(0.25);
        planck::band_radiance(t_sky, planck::BAND_8_12_UM)?
    };
    let solved: Vec<Solved> = clusters
        .keys
        .par_iter()
        .map(|key| solve(key, &surface.table, &days, opts, sky_band))
        .collect::<Result<_>>()?;

    let value = |i: usize, f: fn(&Solved) -> f64| match clusters.cluster[i] {
        u32::MAX => f32::NAN,
        k => f(&solved[k as usize]) as f32,
    };
    let temperature: Vec<f32> = (0..grid.len()).map(|i| value(i, |s| s.0)).collect();
    let radiance: Vec<f32> = (0..grid.len()).map(|i| value(i, |s| s.1)).collect();
    let summary = ThermalSummary {
        time: opts.time.to_rfc3339_opts(chrono::SecondsFormat::Secs, true),
        conditions: c,
        steps: n,
        sunlit_steps: days.iter().filter(|s| s.sun.is_some()).count(),
        clusters: clusters.keys.len(),
        days_max: solved.iter().map(|s| s.2).max().unwrap_or(0),
        change_k_max: solved.iter().map(|s| s.3).fold(0.0, f64::max),
        materials: per_material(&surface, &clusters.cluster, &solved),
        nodata_cells: clusters.nodata_cells,
    };
    Ok(ThermalMap {
        temperature_k: Raster::new(grid.clone(), temperature),
        radiance: Raster::new(grid, radiance),
        summary,
    })
}

/// The number of steps in a day of `step_s` seconds: an error unless it is whole and from
/// [`MIN_STEPS`] to [`MAX_STEPS`].
fn steps_a_day(step_s: f64) -> Result<usize> {
    let per_day = 86_400.0 / step_s;
    let n = per_day.round() as usize;
    let whole = per_day.is_finite() && (per_day - n as f64).abs() <= 1e-9;
    if step_s <= 0.0 || !whole || !(MIN_STEPS..=MAX_STEPS).contains(&n) {
        return Err(Error::msg(format!(
            "--step {step_s} s: a day must be a whole number of steps, {MIN_STEPS} to {MAX_STEPS}"
        ))
        .fix("e.g. --step 900 (96 steps) or 1800"));
    }
    Ok(n)
}

/// Each cell's lit history over `days`: bit `k` set when the cell is lit at step `k` (one cast
/// of the terrain and what stands on it per step with the sun up).
fn lit_history(surface: &TopSurface, days: &[Step]) -> Result<Vec<u128>> {
    let raised: &Raised = &surface.standing.all;
    let mut lit = vec![0u128; surface.grid().len()];
    for (k, step) in days.iter().enumerate() {
        let Some(sunlit) = &step.sun else { continue };
        let bits = ShadowBits::cast(&surface.terrain, &sunlit.sun, |s, row| {
            raised.lay_over(s, row)
        })?;
        lit.par_iter_mut().enumerate().for_each(|(i, l)| {
            if !bits.get(i) {
                *l |= 1 << k;
            }
        });
    }
    Ok(lit)
}

/// The valid cells grouped by [`Key`]: one column is solved per key.
struct Clusters {
    /// The distinct keys, in the order first met (row-major).
    keys: Vec<Key>,
    /// Each cell's index into `keys`; `u32::MAX` for nodata.
    cluster: Vec<u32>,
    /// Cells with a nodata height or no material in the table.
    nodata_cells: u64,
}

impl Clusters {
    /// The cells of `surface` into clusters by material, normal and `lit` history.
    fn of(surface: &TopSurface, lit: &[u128]) -> Clusters {
        // A valid cell's unit normal's east and north components, quantised to 0.01 (a roof's
        // face, level on objects' tops).
        let normal = |i: usize| -> [i16; 2] {
            let [e, n, _] = surface.normal(i);
            [e, n].map(|v| (v * 100.0).round() as i16)
        };
        let len = surface.grid().len();
        let mut index: HashMap<Key, u32> = HashMap::new();
        let mut out = Clusters {
            keys: Vec::new(),
            cluster: vec![u32::MAX; len],
            nodata_cells: 0,
        };
        for (i, &history) in lit.iter().enumerate() {
            let m = surface.material[i];
            if surface.heights[i].is_nan() || surface.table.by_id(m).is_none() {
                out.nodata_cells += 1;
                continue;
            }
            let key = Key {
                material: m,
                normal: normal(i),
                lit: history,
            };
            out.cluster[i] = *index.entry(key).or_insert_with(|| {
                out.keys.push(key);
                out.keys.len() as u32 - 1
            });
        }
        out
    }
}

/// A cluster's column at the product's time: surface temperature (K), band radiance
/// (W/m²/sr), the days it took to become periodic and its last day-to-day change (K).
type Solved = (f64, f64, usize, f64);

/// The periodic column of `key` under `days`, ending at the product's time.
fn solve(
    key: &Key,
    table: &table::MaterialTable,
    days: &[Step],
    opts: &ThermalOptions,
    sky_band: f64,
) -> Result<Solved> {
    let c = opts.conditions;
    let deep_k = c.air_mean_c + 273.15;
    let h_conv = thermal::mcadams_convection(c.wind_m_per_s)?;
    let m = table
        .by_id(key.material)
        .expect("clustered cells have materials");
    let [a, b] = key.normal.map(|v| v as f64 / 100.0);
    let nz = (1.0 - a * a - b * b).max(0.0).sqrt();
    let nrm = [a, b, nz];
    let forcing: Vec<Forcing> = days
        .iter()
        .enumerate()
        .map(|(k, s)| {
            let direct = match &s.sun {
                Some(Sunlit { toward: d, dni, .. }) if key.lit >> k & 1 == 1 => {
                    dni * (d[0] * nrm[0] + d[1] * nrm[1] + d[2] * nrm[2]).max(0.0)
                }
                _ => 0.0,
            };
            Forcing {
                shortwave_w_per_m2: direct + s.diffuse * (1.0 + nz) / 2.0,
                longwave_down_w_per_m2: s.longwave,
                air_temperature_k: s.air_k,
                convection_w_per_m2_k: h_conv,
                vapour_pressure_pa: s.vapour,
            }
        })
        .collect();
    let mut column = Column::new(&surface_of(m, deep_k), opts.grid, 1e-6, |_| deep_k)
        .map_err(|e| Error::msg(format!("material {}: {}", m.name, e.problem)))?;
    // Start from the steady state under the day's mean: about half the days to periodic.
    let n = days.len();
    let mean = |f: fn(&Forcing) -> f64| forcing.iter().map(f).sum::<f64>() / n as f64;
    column.settle(&Forcing {
        shortwave_w_per_m2: mean(|f| f.shortwave_w_per_m2),
        longwave_down_w_per_m2: mean(|f| f.longwave_down_w_per_m2),
        air_temperature_k: mean(|f| f.air_temperature_k),
        convection_w_per_m2_k: h_conv,
        vapour_pressure_pa: mean(|f| f.vapour_pressure_pa),
    })?;
    let run = column.run_periodic(&forcing, opts.step_s, opts.tolerance_k, opts.max_days)?;
    let t = *run.surface_k.last().expect("a day has steps");
    let radiance = planck::surface_band_radiance(t, m.emissivity, sky_band, planck::BAND_8_12_UM)?;
    Ok((t, radiance, run.cycles, run.change_k))
}

/// Per material name, the cells of each cluster's temperature: count, mean, least and most.
fn per_material(
    surface: &TopSurface,
    cluster: &[u32],
    solved: &[Solved],
) -> BTreeMap<String, MaterialTemperature> {
    let mut per_id = [(); 256].map(|_| MaterialTemperature {
        cells: 0,
        mean_k: 0.0,
        min_k: f64::INFINITY,
        max_k: f64::NEG_INFINITY,
    });
    for i in (0..cluster.len()).filter(|&i| cluster[i] != u32::MAX) {
        let t = solved[cluster[i] as usize].0;
        let e = &mut per_id[surface.material[i] as usize];
        e.cells += 1;
        e.mean_k += t;
        e.min_k = e.min_k.min(t);
        e.max_k = e.max_k.max(t);
    }
    per_id
        .into_iter()
        .enumerate()
        .filter(|(_, e)| e.cells > 0)
        .map(|(id, mut e)| {
            e.mean_k /= e.cells as f64;
            let name = &surface
                .table
                .by_id(id as u8)
                .expect("clustered cells have materials")
                .name;
            (name.clone(), e)
        })
        .collect()
}

impl std::fmt::Display for ThermalSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "thermal map at {}: {} steps a day ({} with the sun up), {} columns, up to {} days (last change {:.3} K)",
            self.time, self.steps, self.sunlit_steps, self.clusters, self.days_max, self.change_k_max
        )?;
        for (name, m) in &self.materials {
            writeln!(
                f,
                "  {name:<16} {:>9} cells  mean {:6.2} K ({:6.2} °C), {:6.2} .. {:6.2} K",
                m.cells,
                m.mean_k,
                m.mean_k - 273.15,
                m.min_k,
                m.max_k
            )?;
        }
        if self.nodata_cells > 0 {
            writeln!(
                f,
                "  nodata (no elevation or unclassified): {} cells",
                self.nodata_cells
            )?;
        }
        Ok(())
    }
}

impl ThermalMap {
    /// Write the temperature (K) as a Float32 GeoTIFF at `temperature`, and when asked the
    /// band radiance likewise and a picture of the temperature ("white hot": the coldest cell
    /// black, the hottest white, linear in K; nodata dark red). All are written and staged
    /// first, then renamed into place together: a run that fails leaves none of them.
    pub fn write(
        &self,
        temperature: &std::path::Path,
        radiance: Option<&std::path::Path>,
        preview: Option<&std::path::Path>,
    ) -> Result<()> {
        let paths: Vec<&std::path::Path> = [Some(temperature), radiance, preview]
            .into_iter()
            .flatten()
            .collect();
        crate::io::atomic::check_outputs(&paths, &[])?;
        let tiff = |path: &std::path::Path, r: &Raster<f32>| {
            let mut w = crate::io::geotiff::GeoTiffWriter::create_f32(path, &r.grid)?;
            w.push_rows(&r.data)?;
            w.stage()
        };
        let mut staged = vec![tiff(temperature, &self.temperature_k)?];
        if let Some(path) = radiance {
            staged.push(tiff(path, &self.radiance)?);
        }
        if let Some(path) = preview {
            let valid = self.temperature_k.data.iter().filter(|t| !t.is_nan());
            let (lo, hi) = valid.fold((f32::INFINITY, f32::NEG_INFINITY), |(a, b), &t| {
                (a.min(t), b.max(t))
            });
            let span = (hi - lo).max(1e-6);
            let rgb: Vec<u8> = self
                .temperature_k
                .data
                .iter()
                .flat_map(|&t| match t.is_nan() {
                    true => [96, 0, 0],
                    false => [((t - lo) / span * 255.0).round() as u8; 3],
                })
                .collect();
            let g = &self.temperature_k.grid;
            staged.push(crate::io::png::stage_rgb(path, g.width, g.height, &rgb)?);
        }
        crate::io::atomic::commit_all(staged)
    }
}
