//! The `dbms radar` stage (issue 18, item 5): every cell's radar backscatter σ⁰ for a radar far
//! off in a given direction, with radar shadow, layover and the dihedral returns where walls
//! facing the radar meet the ground.
//!
//! Invariant: a cell's σ⁰ (linear, m²/m²) comes from its material's published model for the
//! band at the cell's local incidence angle, and only from there; a cell whose material has no
//! model for the band is NaN (class [`Class::NoModel`]), never a guess. The radar is a plane
//! wave from `azimuth_deg` (grid azimuth, from the scene toward the radar) and `elevation_deg`
//! above the horizon (the radar's depression angle):
//! * **shadow**: cells the same sweep as `dbms shadows` finds in cast shadow for a source in the
//!   radar's direction (terrain, buildings and objects casting), and cells facing away from the
//!   radar; σ⁰ 0 (no return);
//! * **layover**: terrain sloping toward the radar more steeply than the radar's incidence on
//!   level ground (`90° − elevation`): such a slope's top is nearer in range than its foot; σ⁰
//!   as its model gives;
//! * **dihedral**: a ground cell whose neighbour toward the radar across a cell edge is a raised
//!   cell (a wall faces the radar there): the wall and the ground form a corner reflector; σ⁰
//!   of the ground as its model gives (the corner's own return is not modelled: it is marked);
//! * **specular** materials (calm water, flat roofs) have no return away from normal incidence:
//!   σ⁰ 0, marked.
//!
//! Surfaces: terrain normals ([`crate::raster::surface_normal`]), roofs' faces (a pitched roof
//! slopes, [`crate::standing::Raised::top_normal`]); objects' tops are level.

use crate::backscatter::grey_db;
use crate::db::Database;
use crate::error::{Error, Result};
use crate::material::surface::TopSurface;
use crate::material::table::{Band, RadarModel};
use crate::raster::Raster;
use crate::shadow::ShadowBits;
use crate::sun::Sun;
use rayon::prelude::*;
use serde::Serialize;
use std::path::Path;

/// What `dbms radar` is asked for.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RadarOptions {
    /// Grid azimuth from the scene toward the radar, degrees clockwise from grid north.
    pub azimuth_deg: f64,
    /// The radar's elevation above the horizon seen from the scene (its depression angle),
    /// degrees, in (0, 90).
    pub elevation_deg: f64,
    /// The band whose σ⁰ models are used.
    pub band: Band,
}

/// What each cell of a radar map is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
#[repr(u8)]
pub enum Class {
    /// No surface (nodata elevation).
    Nodata = 0,
    /// Lit by the radar, σ⁰ from the material's model.
    Lit = 1,
    /// In radar shadow or facing away: no return.
    Shadow = 2,
    /// Terrain in layover (sloping toward the radar beyond its incidence on level ground).
    Layover = 3,
    /// Ground at the foot of a wall facing the radar: a corner reflector.
    Dihedral = 4,
    /// Mirror-like material: no return away from normal incidence.
    Specular = 5,
    /// The material has no σ⁰ model for the band (or the cell is unclassified).
    NoModel = 6,
}

/// Every class, in id order.
pub const CLASSES: [Class; 7] = [
    Class::Nodata,
    Class::Lit,
    Class::Shadow,
    Class::Layover,
    Class::Dihedral,
    Class::Specular,
    Class::NoModel,
];

/// The radar map: σ⁰ and class per cell.
pub struct RadarMap {
    /// σ⁰, linear (m²/m²); 0 in shadow and on specular surfaces; NaN without a model or data.
    pub sigma0: Raster<f32>,
    /// [`Class`] ids.
    pub class: Raster<u8>,
}

/// The summary of a run, for the CLI and `--json`.
#[derive(Debug, Clone, Serialize)]
pub struct RadarSummary {
    /// The options, as given.
    pub azimuth_deg: f64,
    /// The radar's elevation above the horizon, degrees.
    pub elevation_deg: f64,
    /// The band, its letter.
    pub band: String,
    /// Cells per class, by name.
    pub cells: std::collections::BTreeMap<&'static str, u64>,
    /// Materials present without a σ⁰ model for the band.
    pub no_model: Vec<String>,
}

impl std::fmt::Display for RadarSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "radar at azimuth {}°, elevation {}°, {} band:",
            self.azimuth_deg, self.elevation_deg, self.band
        )?;
        for (name, n) in &self.cells {
            write!(f, " {n} {name}")?;
        }
        if !self.no_model.is_empty() {
            write!(
                f,
                "\nno σ⁰ model for the band: {}",
                self.no_model.join(", ")
            )?;
        }
        Ok(())
    }
}

/// Parse a band letter (`L`, `S`, `C`, `X`, `Ku`, `Ka`, `W`).
pub fn parse_band(s: &str) -> Result<Band> {
    serde_json::from_value(serde_json::Value::String(s.to_string())).map_err(|_| {
        Error::msg(format!("--band {s}: not a radar band")).fix("give one of L, S, C, X, Ku, Ka, W")
    })
}

/// The radar map of `db` for `opts`, and its summary.
pub fn radar_map(db: &Database, opts: &RadarOptions) -> Result<(RadarMap, RadarSummary)> {
    let (az, el) = (opts.azimuth_deg, opts.elevation_deg);
    check_look(az, el)?;
    let surface = TopSurface::read(db)?;
    let grid = surface.grid();
    let radar = Sun::new(el, az)?;
    let toward = radar.direction_enu();
    let look = Look {
        surface: &surface,
        shadow: ShadowBits::cast(&surface.terrain, &radar, |s, row| {
            surface.standing.all.lay_over(s, row)
        })?,
        toward,
        facing: facing(grid, toward),
        models: (0..=255u8)
            .map(|id| {
                let m = surface.table.by_id(id)?;
                Some((m.radar.specular, m.radar.model_for(opts.band)))
            })
            .collect(),
        level_incidence: 90.0 - el,
    };
    let cells: Vec<(f32, u8)> = (0..grid.len())
        .into_par_iter()
        .map(|i| look.cell(i))
        .collect();
    let (sigma0, class): (Vec<f32>, Vec<u8>) = cells.into_iter().unzip();
    let summary = summarise(opts, &surface, &class);
    let map = RadarMap {
        sigma0: Raster::new(grid.clone(), sigma0),
        class: Raster::new(grid.clone(), class),
    };
    Ok((map, summary))
}

/// An error unless the radar's azimuth (degrees) is finite and its elevation (degrees) is
/// above the horizon and below the zenith.
fn check_look(az: f64, el: f64) -> Result<()> {
    let at = format!("radar at azimuth {az}°, elevation {el}°");
    if !az.is_finite() {
        return Err(Error::msg(format!(
            "{at}: the azimuth must be a finite number of degrees"
        ))
        .fix("give the grid azimuth from the scene toward the radar, e.g. --azimuth 135"));
    }
    if !(el > 0.0 && el < 90.0) {
        return Err(Error::msg(format!(
            "{at}: the elevation must be between 0 and 90 degrees"
        ))
        .fix("give the radar's depression angle, e.g. --elevation 30"));
    }
    Ok(())
}

/// The 4-neighbour offsets `(column, row)` that point away from a radar in direction `toward`
/// (east, north, up): a ground cell whose neighbour there is raised stands in front of a wall
/// that faces the radar.
fn facing(grid: &crate::grid::Grid, toward: [f64; 3]) -> Vec<(i64, i64)> {
    [(1i64, 0i64), (-1, 0), (0, -1), (0, 1)]
        .into_iter()
        .filter(|&(dc, dr)| {
            // World x grows with the column; world y with −row when north-up.
            let (dx, dy) = (dc as f64, dr as f64 * grid.transform.cell_y.signum());
            dx * toward[0] + dy * toward[1] < -1e-12
        })
        .collect()
}

/// What every cell of one radar look reads.
struct Look<'a> {
    surface: &'a TopSurface,
    /// The radar's shadow: cells it cannot see.
    shadow: ShadowBits,
    /// Unit vector toward the radar (east, north, up).
    toward: [f64; 3],
    /// [`facing`]'s offsets.
    facing: Vec<(i64, i64)>,
    /// Per material id: whether it is specular, and its σ⁰ model at the band; `None` for an id
    /// the table lacks.
    models: Vec<Option<(bool, Option<&'a RadarModel>)>>,
    /// The incidence on level ground, degrees.
    level_incidence: f64,
}

impl Look<'_> {
    /// Cell `i`'s σ⁰ (linear; NaN without a model or a height) and its class.
    fn cell(&self, i: usize) -> (f32, u8) {
        let (surface, toward) = (self.surface, self.toward);
        if surface.heights[i].is_nan() {
            return (f32::NAN, Class::Nodata as u8);
        }
        let n = surface.normal(i);
        let cos_inc = n[0] * toward[0] + n[1] * toward[1] + n[2] * toward[2];
        if self.shadow.get(i) || cos_inc <= 0.0 {
            return (0.0, Class::Shadow as u8);
        }
        let (specular, model) = match self.models[surface.material[i] as usize] {
            Some(m) => m,
            None => return (f32::NAN, Class::NoModel as u8),
        };
        if specular {
            return (0.0, Class::Specular as u8);
        }
        let Some(model) = model else {
            return (f32::NAN, Class::NoModel as u8);
        };
        let sigma0 = model.sigma0(cos_inc);
        let grid = surface.grid();
        let (w, h) = (grid.width as i64, grid.height as i64);
        let (col, row) = ((i % grid.width) as i64, (i / grid.width) as i64);
        let on_top = &surface.on_top;
        let wall = !on_top[i]
            && self.facing.iter().any(|&(dc, dr)| {
                let (c, r) = (col + dc, row + dr);
                (0..w).contains(&c) && (0..h).contains(&r) && on_top[(r * w + c) as usize]
            });
        // Tilt toward the radar: the slope angle of the normal in the radar's vertical plane.
        let horizontal = (toward[0] * toward[0] + toward[1] * toward[1]).sqrt();
        let along = (n[0] * toward[0] + n[1] * toward[1]) / horizontal;
        let tilt_deg = along.atan2(n[2]).to_degrees();
        let class = if wall {
            Class::Dihedral
        } else if tilt_deg > self.level_incidence {
            Class::Layover
        } else {
            Class::Lit
        };
        (sigma0, class as u8)
    }
}

/// The summary of a look from `opts` over `surface` whose cells are `class`: each class's
/// count, and the materials with no model at the band (by id; every id the table lacks is
/// "unclassified", named once).
fn summarise(opts: &RadarOptions, surface: &TopSurface, class: &[u8]) -> RadarSummary {
    let mut counts = [0u64; 7];
    class.iter().for_each(|&c| counts[c as usize] += 1);
    let ids = (0..class.len())
        .filter(|&i| class[i] == Class::NoModel as u8)
        .map(|i| surface.material[i])
        .collect::<std::collections::BTreeSet<u8>>();
    let mut no_model: Vec<String> = Vec::new();
    for id in ids {
        let name = surface
            .table
            .by_id(id)
            .map_or("unclassified".to_string(), |m| m.name.clone());
        if !no_model.contains(&name) {
            no_model.push(name);
        }
    }
    RadarSummary {
        azimuth_deg: opts.azimuth_deg,
        elevation_deg: opts.elevation_deg,
        band: format!("{:?}", opts.band),
        cells: CLASSES
            .iter()
            .zip(counts)
            .map(|(c, n)| (class_name(*c), n))
            .collect(),
        no_model,
    }
}

/// A class's name in summaries.
pub fn class_name(c: Class) -> &'static str {
    match c {
        Class::Nodata => "nodata",
        Class::Lit => "lit",
        Class::Shadow => "shadow",
        Class::Layover => "layover",
        Class::Dihedral => "dihedral",
        Class::Specular => "specular",
        Class::NoModel => "no_model",
    }
}

impl RadarMap {
    /// Write σ⁰ (linear, Float32 GeoTIFF) at `sigma0`, and when asked the classes (byte
    /// GeoTIFF, [`Class`] ids) and a picture: σ⁰ on the grey scale of [`grey_db`] (dB from
    /// [`GREY_FLOOR_DB`](crate::backscatter::GREY_FLOOR_DB) black to 0 dB white); shadow and
    /// specular black; dihedral cells yellow, layover magenta, cells without a model dark red.
    /// All staged, then renamed together.
    pub fn write(&self, sigma0: &Path, class: Option<&Path>, preview: Option<&Path>) -> Result<()> {
        let paths: Vec<&Path> = [Some(sigma0), class, preview]
            .into_iter()
            .flatten()
            .collect();
        crate::io::atomic::check_outputs(&paths, &[])?;
        let mut tiff = crate::io::geotiff::GeoTiffWriter::create_f32(sigma0, &self.sigma0.grid)?;
        tiff.push_rows(&self.sigma0.data)?;
        let mut staged = vec![tiff.stage()?];
        if let Some(path) = class {
            let mut t = crate::io::geotiff::GeoTiffWriter::create_u8(path, &self.class.grid, None)?;
            t.push_rows(&self.class.data)?;
            staged.push(t.stage()?);
        }
        if let Some(path) = preview {
            let rgb: Vec<u8> = self
                .sigma0
                .data
                .iter()
                .zip(&self.class.data)
                .flat_map(|(&s, &c)| preview_colour(s, c))
                .collect();
            let g = &self.sigma0.grid;
            staged.push(crate::io::png::stage_rgb(path, g.width, g.height, &rgb)?);
        }
        crate::io::atomic::commit_all(staged)
    }
}

/// The preview's colour of a cell of σ⁰ `s` (linear) and class `c`.
fn preview_colour(s: f32, c: u8) -> [u8; 3] {
    match CLASSES.get(c as usize) {
        Some(Class::Dihedral) => [255, 220, 0],
        Some(Class::NoModel) => [96, 0, 0],
        Some(Class::Nodata) => [0, 0, 0],
        Some(Class::Layover) => {
            let g = grey_db(s);
            [g.max(160), g / 2, g.max(160)]
        }
        _ => [grey_db(s); 3],
    }
}
