//! The generated sample scene (`dbms sample`): a scene a new user runs at once, no download.
//!
//! Invariant: the scene is a pure function of `(seed, size)`; the same options give
//! byte-identical files (seeded hashing only, no clocks, ordered JSON maps).
//!
//! What it holds, in EPSG:32632 (UTM 32N, around x 500 000, y 5 300 000; about 47.9° N, 9° E):
//! * `dem.tif`: bare-earth terrain (no buildings), float32, [`DEM_CELL_M`] cells, `size × size`,
//!   three octaves of value noise (slopes mostly under 20 %), with a small triangle of nodata
//!   cells in the south-east corner (real DEMs have voids).
//! * `ortho.tif`: an orthophoto-like RGBA8 image (alpha 255) at [`ORTHO_CELL_M`] over the same
//!   extent: grass/soil texture, two asphalt roads with a dashed centre line, flat roofs and
//!   houses' gable and hip roofs (each face lit by the sun at its own incidence), and the
//!   shadows cast over terrain + buildings (pitched roofs at their real shape) for the sun at
//!   [`SUN_TIME`] over the scene centre, shadowed colour multiplied by [`SHADOW_FACTOR`].
//! * `buildings.geojson`: footprints (polygons, property `id`, no heights): shadow-height's input.
//! * `truth.json`: each building's height and roof z (a pitched roof's ridge, with its form,
//!   eaves and ridge direction in `crate::roof`'s convention), the sun and the shadow factor (schema
//!   `schemas/sample-truth.schema.json`); `scene.json`: the scene and how to run the pipeline
//!   (schema `schemas/sample-scene.schema.json`). See docs/sample.md.

mod layout;
mod noise;

pub use layout::Shape;

use crate::crs::Crs;
use crate::error::{Error, Result};
use crate::grid::Grid;
use crate::io::atomic::{commit_all, AtomicFile, Staged};
use crate::io::geotiff::GeoTiffWriter;
use crate::raster::{Colour, Elevation, Raster};
use crate::roof::{Extent, Pitch, RoofShape};
use crate::shadow::{cast_shadows_slice, SHADOW};
use crate::standing::{rasterise_prisms, Prism};
use crate::sun::Sun;
use layout::{PlannedBuilding, Road, ROAD_HALF_WIDTH};
use noise::{mix, octaves};
use rayon::prelude::*;
use serde::Serialize;
use serde_json::json;
use std::io::Write;
use std::path::{Path, PathBuf};

/// The scene's CRS: WGS 84 / UTM zone 32N.
pub const EPSG: u32 = 32632;
/// West edge of the scene, metres (UTM easting).
pub const MIN_X: f64 = 500_000.0;
/// South edge of the scene, metres (UTM northing).
pub const MIN_Y: f64 = 5_300_000.0;
/// DEM cell size, metres.
pub const DEM_CELL_M: f64 = 0.5;
/// Orthophoto cell size, metres.
pub const ORTHO_CELL_M: f64 = 0.25;
/// DEM cells per side by default (512 m).
pub const DEFAULT_SIZE: usize = 1024;
/// Smallest DEM size accepted (cells per side): room for four 36 m lots.
pub const MIN_SIZE: usize = 160;
/// Largest DEM size accepted (cells per side).
pub const MAX_SIZE: usize = 8192;
/// The UTC time the orthophoto's shadows are cast for (sun about 40° high in the south-east).
pub const SUN_TIME: &str = "2026-09-15T08:30:00Z";
/// Shadowed orthophoto colour = lit colour × this.
pub const SHADOW_FACTOR: f64 = 0.45;
/// Terrain height at the noise's mean, metres.
const BASE_Z: f64 = 380.0;
/// Terrain octaves (wavelength m, amplitude m).
const TERRAIN: [(f64, f64); 3] = [(260.0, 8.0), (95.0, 2.5), (32.0, 0.5)];
/// Nodata triangle in the DEM's south-east corner: cells with `i + j < this` from the corner.
const NODATA_CORNER: usize = 9;

/// What to generate.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SampleOptions {
    /// Seed of every random choice.
    pub seed: u64,
    /// DEM cells per side ([`MIN_SIZE`]..=[`MAX_SIZE`]); the orthophoto has twice as many.
    pub size: usize,
}

impl Default for SampleOptions {
    fn default() -> SampleOptions {
        SampleOptions {
            seed: 1,
            size: DEFAULT_SIZE,
        }
    }
}

/// One building of the scene with its truth.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Building {
    /// 1-based id, as in `buildings.geojson`.
    pub id: u32,
    /// Kind of footprint.
    pub shape: Shape,
    /// Exterior ring in scene CRS metres, counter-clockwise, closed (first = last).
    pub footprint: Vec<[f64; 2]>,
    /// Roof above the highest ground under the footprint, metres (a flat roof's lowest wall;
    /// a pitched roof's ridge).
    pub height_m: f64,
    /// Absolute height of the flat roof or of the pitched roof's ridge, metres.
    pub roof_z: f64,
    /// A pitched roof's form, eaves (absolute metres) and ridge direction; `None` when flat.
    #[serde(skip)]
    pub pitch: Option<Pitch>,
    /// Lowest and highest terrain under the footprint (DEM cell centres inside it), metres.
    pub ground_min_z: f64,
    /// See `ground_min_z`.
    pub ground_max_z: f64,
}

/// A generated scene, in memory.
pub struct Scene {
    /// The options it was made with.
    pub options: SampleOptions,
    /// Bare-earth DEM (metres, NaN = nodata).
    pub dem: Elevation,
    /// Orthophoto (alpha 255 everywhere).
    pub ortho: Colour,
    /// What the generator painted in each orthophoto cell, as an index into
    /// [`TRUTH_MATERIALS`]: the labels a material classification is scored against.
    pub truth_materials: Raster<u8>,
    /// Buildings, by id.
    pub buildings: Vec<Building>,
    /// The sun of the orthophoto's shadows (azimuth from grid north, as they were cast).
    pub sun: Sun,
    /// Meridian convergence at the scene centre, degrees: the sun's true azimuth is
    /// `sun.azimuth_deg + grid_convergence_deg`.
    pub grid_convergence_deg: f64,
    /// Latitude and longitude of the scene centre, degrees.
    pub centre_lat_lon: (f64, f64),
    /// Largest terrain slope between neighbouring DEM cells, percent.
    pub max_slope_percent: f64,
    /// Fraction of orthophoto cells in cast shadow.
    pub shadow_fraction: f64,
}

/// Generate the scene in memory. Errors on a size outside [`MIN_SIZE`]..=[`MAX_SIZE`].
pub fn generate(options: SampleOptions) -> Result<Scene> {
    let n = options.size;
    if !(MIN_SIZE..=MAX_SIZE).contains(&n) {
        return Err(Error::msg(format!(
            "--size {n}: the sample needs {MIN_SIZE} to {MAX_SIZE} DEM cells per side"
        ))
        .fix(format!("the default is {DEFAULT_SIZE} (512 m)")));
    }
    let extent = n as f64 * DEM_CELL_M;
    let crs = Crs::epsg(EPSG);
    let (cx, cy) = (MIN_X + extent / 2.0, MIN_Y + extent / 2.0);
    let (lat, lon) = crs.to_lat_lon(cx, cy).expect("UTM 32N converts");
    let grid_convergence_deg = crs.grid_convergence_deg(cx, cy).expect("UTM 32N converts");
    let sun = sun_at_time(lat, lon, grid_convergence_deg)?;
    let terrain_seed = mix(options.seed ^ 0x7e44);
    let ground = |x: f64, y: f64| BASE_Z + octaves(terrain_seed, x, y, &TERRAIN);

    let dem_grid = Grid::north_up(MIN_X, MIN_Y + extent, DEM_CELL_M, n, n, crs.clone());
    let mut dem = Elevation::new(
        dem_grid.clone(),
        sample_grid(&dem_grid, |x, y| ground(x, y) as f32),
    );
    let max_slope_percent = max_slope(&dem) * 100.0;
    cut_nodata_corner(&mut dem);

    let plans = layout::buildings(mix(options.seed ^ 0xb1d), extent);
    let buildings: Vec<Building> = plans
        .iter()
        .enumerate()
        .map(|(i, plan)| building(i as u32 + 1, plan, &dem_grid, &ground))
        .collect();

    let (ortho, truth_materials, shadow_fraction) = render_ortho(
        options.seed,
        extent,
        &crs,
        &sun,
        &ground,
        &plans,
        &buildings,
    );
    Ok(Scene {
        options,
        dem,
        ortho,
        truth_materials,
        buildings,
        sun,
        grid_convergence_deg,
        centre_lat_lon: (lat, lon),
        max_slope_percent,
        shadow_fraction,
    })
}

/// Blank the DEM's south-east corner (a triangle [`NODATA_CORNER`] cells on a side) to nodata,
/// so every run exercises nodata handling.
fn cut_nodata_corner(dem: &mut Elevation) {
    let n = dem.grid.width;
    for i in 0..NODATA_CORNER {
        for j in 0..NODATA_CORNER - i {
            *dem.get_mut(n - 1 - i, n - 1 - j) = f32::NAN;
        }
    }
}

impl Building {
    /// The building's roof over its footprint (`crate::roof`'s convention).
    pub fn roof(&self) -> RoofShape {
        let ring: Vec<(f64, f64)> = self.footprint.iter().map(|p| (p[0], p[1])).collect();
        RoofShape::new(&[ring], self.roof_z, self.pitch)
    }

    /// The building as truth.json states it: its fields and its roof's properties
    /// (`roof_form`, and for a pitched roof `eave_z` and `roof_azimuth_deg`).
    fn truth_json(&self) -> serde_json::Value {
        let mut v = serde_json::to_value(self).expect("a building serialises");
        let map = v.as_object_mut().expect("a building is an object");
        match self.pitch {
            Some(p) => p.to_properties(map),
            None => {
                map.insert(crate::roof::property::FORM.into(), "flat".into());
            }
        }
        v
    }
}

/// The building `id` stands on `plan`'s footprint: its ground is the lowest and highest
/// terrain (metres) under the DEM cells the footprint covers; its flat roof, or its pitched
/// roof's eaves, stand `plan.height_m` above the highest, and a pitched roof's ridge rises
/// from them at the plan's pitch over half the footprint's width across the ridge.
fn building(
    id: u32,
    plan: &PlannedBuilding,
    dem_grid: &Grid,
    ground: &impl Fn(f64, f64) -> f64,
) -> Building {
    let prism = Prism {
        rings: vec![world_ring(&plan.ring)],
        roof: crate::roof::RoofShape::flat(0.0),
    };
    let n = dem_grid.width;
    let under: Vec<f64> = rasterise_prisms(dem_grid, std::slice::from_ref(&prism))
        .iter()
        .map(|c| {
            let (col, row) = (c.index % n, c.index / n);
            let (x, y) = dem_grid.cell_centre(col, row);
            ground(x - MIN_X, y - MIN_Y)
        })
        .collect();
    let (lo, hi) = under
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &z| {
            (a.min(z), b.max(z))
        });
    let mut footprint: Vec<[f64; 2]> = prism.rings[0].iter().map(|&(x, y)| [x, y]).collect();
    footprint.push(footprint[0]);
    let eave_z = hi + plan.height_m;
    let (pitch, rise) = match plan.pitch {
        None => (None, 0.0),
        Some(house) => {
            let extent = Extent::new(&prism.rings, house.azimuth_deg).expect("a ring has vertices");
            let pitch = Pitch {
                form: house.form,
                eave_z,
                azimuth_deg: house.azimuth_deg,
            };
            (
                Some(pitch),
                extent.half.1 * house.pitch_deg.to_radians().tan(),
            )
        }
    };
    Building {
        id,
        shape: plan.shape,
        footprint,
        height_m: plan.height_m + rise,
        roof_z: eave_z + rise,
        pitch,
        ground_min_z: lo,
        ground_max_z: hi,
    }
}

/// File names inside a sample directory.
pub const FILES: [&str; 5] = [
    "dem.tif",
    "ortho.tif",
    "buildings.geojson",
    "truth.json",
    "scene.json",
];

/// Write a scene's files ([`FILES`]) into `dir` (created if missing), all or none: each is
/// written and synced under a temporary name, then all are renamed into place, scene.json (what
/// `make` waits for) last. Returns their paths.
pub fn write(scene: &Scene, dir: &Path) -> Result<Vec<PathBuf>> {
    std::fs::create_dir_all(dir)
        .map_err(|e| Error::io(dir, e).fix("choose a writable output directory"))?;
    let paths: Vec<PathBuf> = FILES.iter().map(|f| dir.join(f)).collect();
    let mut dem = GeoTiffWriter::create_f32(&paths[0], &scene.dem.grid)?;
    dem.push_rows(&scene.dem.data)?;
    let mut ortho = GeoTiffWriter::create_rgba8(&paths[1], &scene.ortho.grid)?;
    ortho.push_rows(&scene.ortho.data)?;
    let staged = vec![
        dem.stage()?,
        ortho.stage()?,
        stage_json(&paths[2], &footprints_geojson(&scene.buildings))?,
        stage_json(&paths[3], &truth_json(scene))?,
        stage_json(&paths[4], &scene_json(scene))?,
    ];
    commit_all(staged)?;
    Ok(paths)
}

fn stage_json(path: &Path, value: &serde_json::Value) -> Result<Staged> {
    let mut text = serde_json::to_string_pretty(value).expect("JSON value serialises");
    text.push('\n');
    let mut out = AtomicFile::create(path)?;
    out.writer()
        .write_all(text.as_bytes())
        .map_err(|e| Error::io(path, e))?;
    out.stage()
}

/// The scene's sun as scene.json, truth.json and `dbms sample --json` state it: the azimuth
/// from true north (what `dbms sun` prints) and from grid north (what the shadows were cast for).
pub fn sun_json(scene: &Scene) -> serde_json::Value {
    json!({
        "time": SUN_TIME,
        "elevation_deg": scene.sun.elevation_deg,
        "azimuth_deg": (scene.sun.azimuth_deg + scene.grid_convergence_deg).rem_euclid(360.0),
        "grid_azimuth_deg": scene.sun.azimuth_deg,
    })
}

/// GeoJSON footprints with only an `id` (the legacy `crs` member tells GDAL the UTM zone).
fn footprints_geojson(buildings: &[Building]) -> serde_json::Value {
    let features: Vec<serde_json::Value> = buildings
        .iter()
        .map(|b| json!({ "type": "Feature", "properties": { "id": b.id }, "geometry": { "type": "Polygon", "coordinates": [b.footprint] } }))
        .collect();
    json!({
        "type": "FeatureCollection",
        "name": "buildings",
        "crs": { "type": "name", "properties": { "name": format!("urn:ogc:def:crs:EPSG::{EPSG}") } },
        "features": features,
    })
}

fn truth_json(scene: &Scene) -> serde_json::Value {
    json!({
        "format": "dbms-sample-truth",
        "format_version": 1,
        "seed": scene.options.seed,
        "crs": format!("EPSG:{EPSG}"),
        "sun": sun_json(scene),
        "shadow_factor": SHADOW_FACTOR,
        "buildings": scene.buildings.iter().map(Building::truth_json).collect::<Vec<_>>(),
    })
}

fn scene_json(scene: &Scene) -> serde_json::Value {
    let b = scene.dem.grid.bounds();
    let (lat, lon) = scene.centre_lat_lon;
    json!({
        "format": "dbms-sample-scene",
        "format_version": 1,
        "seed": scene.options.seed,
        "size": scene.options.size,
        "crs": format!("EPSG:{EPSG}"),
        "bounds": { "min_x": b.min_x, "min_y": b.min_y, "max_x": b.max_x, "max_y": b.max_y },
        "centre": { "latitude_deg": lat, "longitude_deg": lon },
        "dem": {
            "file": FILES[0], "cell_m": DEM_CELL_M, "width": scene.dem.width(), "height": scene.dem.height(),
            "nodata_cells": scene.dem.nodata_count(), "max_slope_percent": scene.max_slope_percent, "contains_buildings": false,
        },
        "ortho": {
            "file": FILES[1], "cell_m": ORTHO_CELL_M, "width": scene.ortho.width(), "height": scene.ortho.height(),
            "shadow_fraction": scene.shadow_fraction,
        },
        "buildings": { "file": FILES[2], "count": scene.buildings.len() },
        "truth": FILES[3],
        "sun": sun_json(scene),
        "shadow_factor": SHADOW_FACTOR,
        "pipeline": {
            "run_from": "this directory",
            "commands": [
                format!("dbms ingest --dem {} --ortho {} --photo-time {SUN_TIME} -o db", FILES[0], FILES[1]),
                format!("dbms shadows --db db --time {SUN_TIME} -o shadows.tif"),
            ],
        },
    })
}

/// The sun at [`SUN_TIME`] over a point where grid north is `grid_convergence_deg` clockwise
/// from true north, its azimuth from grid north.
fn sun_at_time(latitude_deg: f64, longitude_deg: f64, grid_convergence_deg: f64) -> Result<Sun> {
    let obs = crate::sun::Observer {
        latitude_deg,
        longitude_deg,
        height_m: BASE_Z,
    };
    crate::sun::on_grid(
        &obs,
        crate::sun::parse_time(SUN_TIME)?,
        grid_convergence_deg,
    )
}

/// Local ring (metres from the south-west corner) to scene CRS coordinates.
fn world_ring(ring: &[(f64, f64)]) -> Vec<(f64, f64)> {
    ring.iter().map(|&(x, y)| (MIN_X + x, MIN_Y + y)).collect()
}

/// `f(local x, local y)` at every cell centre of `grid`, row-major, in parallel.
fn sample_grid<T: Send>(grid: &Grid, f: impl Fn(f64, f64) -> T + Sync) -> Vec<T> {
    let mut out = Vec::with_capacity(grid.len());
    out.par_extend((0..grid.height).into_par_iter().flat_map_iter(|row| {
        let f = &f;
        (0..grid.width).map(move |col| {
            let (x, y) = grid.cell_centre(col, row);
            f(x - MIN_X, y - MIN_Y)
        })
    }));
    out
}

/// Largest slope (rise over run) between 4-neighbour cells of a DEM with no nodata.
fn max_slope(dem: &Elevation) -> f64 {
    let (cx, cy) = dem.grid.cell_size();
    let (w, h) = (dem.width(), dem.height());
    (0..h)
        .into_par_iter()
        .map(|r| {
            let mut m: f64 = 0.0;
            for c in 0..w {
                let z = *dem.get(c, r) as f64;
                if c + 1 < w {
                    m = m.max((*dem.get(c + 1, r) as f64 - z).abs() / cx);
                }
                if r + 1 < h {
                    m = m.max((*dem.get(c, r + 1) as f64 - z).abs() / cy);
                }
            }
            m
        })
        .reduce(|| 0.0, f64::max)
}

/// The material names of the generator's surfaces, indexed by [`Scene::truth_materials`]:
/// road asphalt (its painted centre line included), grass where the grass–soil blend is under
/// half soil, bare soil elsewhere, then one per roof colour of `layout::ROOFS` (terracotta
/// and slate are tiles, tar is bitumen, concrete, weathered copper is sheet metal).
pub const TRUTH_MATERIALS: [&str; 8] = [
    "asphalt",
    "grass",
    "bare_soil",
    "roof_tile",
    "roof_tile",
    "roof_bitumen",
    "roof_concrete",
    "roof_metal",
];

/// The index into [`TRUTH_MATERIALS`] of roof colour `k` of `layout::ROOFS`.
const ROOF_TRUTH: usize = 3;

/// The orthophoto, what it shows (indices into [`TRUTH_MATERIALS`]) and the fraction of it in
/// cast shadow.
fn render_ortho(
    seed: u64,
    extent: f64,
    crs: &Crs,
    sun: &Sun,
    ground: &(impl Fn(f64, f64) -> f64 + Sync),
    plans: &[PlannedBuilding],
    buildings: &[Building],
) -> (Colour, Raster<u8>, f64) {
    let m = (extent / ORTHO_CELL_M).round() as usize;
    let grid = Grid::north_up(MIN_X, MIN_Y + extent, ORTHO_CELL_M, m, m, crs.clone());
    // Which building (index + 1) covers each cell centre; 0 = none.
    let mut owner = vec![0u32; grid.len()];
    let roofs: Vec<RoofShape> = buildings.iter().map(Building::roof).collect();
    for (i, b) in buildings.iter().enumerate() {
        let prism = Prism {
            rings: vec![b.footprint.iter().map(|p| (p[0], p[1])).collect()],
            roof: roofs[i],
        };
        for c in rasterise_prisms(&grid, &[prism]) {
            owner[c.index] = i as u32 + 1;
        }
    }
    let terrain = sample_grid(&grid, |x, y| ground(x, y) as f32);
    let at = |i: usize| grid.cell_centre(i % grid.width, i / grid.width);
    let surface: Vec<f32> = terrain
        .iter()
        .zip(&owner)
        .enumerate()
        .map(|(i, (&z, &o))| match o {
            0 => z,
            o => roofs[o as usize - 1].z_at(at(i)) as f32,
        })
        .collect();
    let shadow = cast_shadows_slice(&surface, &grid, sun)
        .expect("the sample grid is metric and matches its data");
    let roads = layout::roads(extent);
    let texture_seed = mix(seed ^ 0x0c01);
    let lit = sample_grid(&grid, |x, y| ground_colour(texture_seed, &roads, x, y));
    let data: Vec<[u8; 4]> = (0..grid.len())
        .into_par_iter()
        .map(|i| {
            let (rgb, k) = match owner[i] {
                0 => (lit[i].0, 1.0),
                o => (
                    roof_colour(texture_seed, plans[o as usize - 1].roof, i),
                    roof_light(&roofs[o as usize - 1], sun, at(i)),
                ),
            };
            let k = if shadow[i] == SHADOW {
                SHADOW_FACTOR
            } else {
                k
            };
            let c = |v: u8| (v as f64 * k).round().min(255.0) as u8;
            [c(rgb[0]), c(rgb[1]), c(rgb[2]), 255]
        })
        .collect();
    let truth = (0..grid.len())
        .map(|i| match owner[i] {
            0 => lit[i].1,
            o => {
                let roof = plans[o as usize - 1].roof;
                let k = layout::ROOFS.iter().position(|&c| c == roof);
                (ROOF_TRUTH + k.expect("roofs come from ROOFS")) as u8
            }
        })
        .collect();
    let shadowed = shadow.iter().filter(|&&s| s == SHADOW).count();
    (
        Raster::new(grid.clone(), data),
        Raster::new(grid, truth),
        shadowed as f64 / shadow.len() as f64,
    )
}

/// Lit colour of open ground at local `(x, y)`: asphalt with a dashed white centre line on the
/// roads, elsewhere grass blending into bare soil, with fine texture; and what it is (an index
/// into [`TRUTH_MATERIALS`]).
fn ground_colour(seed: u64, roads: &[Road], x: f64, y: f64) -> ([u8; 3], u8) {
    let grain = noise::value_noise(seed ^ 1, x / 0.6, y / 0.6);
    for r in roads {
        let (across, along) = r.local(x, y);
        if across.abs() < ROAD_HALF_WIDTH {
            if across.abs() < 0.08 && along.rem_euclid(6.0) < 3.0 {
                return ([222, 222, 214], 0);
            }
            let g = 92.0 + 8.0 * grain;
            return ([g as u8, g as u8, (g + 4.0) as u8], 0);
        }
    }
    let soil = (0.5 + 0.9 * octaves(seed ^ 2, x, y, &[(40.0, 1.0), (9.0, 0.35)])).clamp(0.0, 1.0);
    let tuft = 14.0 * octaves(seed ^ 3, x, y, &[(1.5, 0.7), (0.5, 0.3)]) + 6.0 * grain;
    let grass = [74.0, 112.0, 48.0];
    let dirt = [132.0, 108.0, 78.0];
    let mix = |k: usize| (grass[k] + soil * (dirt[k] - grass[k]) + tuft).clamp(0.0, 255.0) as u8;
    ([mix(0), mix(1), mix(2)], if soil < 0.5 { 1 } else { 2 })
}

/// The sun's light on a roof at world point `p`, relative to a flat roof's (1 for a flat
/// roof): a face of unit normal `n` gets `F + (1 − F) · max(0, n·s) / s_z`, `F` the skylight
/// ([`SHADOW_FACTOR`], what a shadowed surface keeps), `s` the unit vector to the sun. The
/// normal is the roof's slope by central differences 1 mm apart (a cell centre on a crease
/// gets the mean of its faces' slopes).
fn roof_light(roof: &RoofShape, sun: &Sun, p: (f64, f64)) -> f64 {
    if roof.pitch.is_none() {
        return 1.0;
    }
    const H: f64 = 1e-3;
    let dz = |dx: f64, dy: f64| roof.z_at((p.0 + dx, p.1 + dy));
    let (gx, gy) = (
        (dz(H, 0.0) - dz(-H, 0.0)) / (2.0 * H),
        (dz(0.0, H) - dz(0.0, -H)) / (2.0 * H),
    );
    let s = sun.direction_enu();
    let ns = (s[2] - gx * s[0] - gy * s[1]) / (gx * gx + gy * gy + 1.0).sqrt();
    SHADOW_FACTOR + (1.0 - SHADOW_FACTOR) * ns.max(0.0) / s[2]
}

/// A roof colour with a little per-cell grain (cell index `i` seeds it).
fn roof_colour(seed: u64, base: [u8; 3], i: usize) -> [u8; 3] {
    let g = (mix(seed ^ i as u64) % 9) as i32 - 4;
    base.map(|v| (v as i32 + g).clamp(0, 255) as u8)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn small(seed: u64) -> Scene {
        generate(SampleOptions {
            seed,
            size: MIN_SIZE,
        })
        .unwrap()
    }

    #[test]
    fn same_seed_same_scene_other_seed_other_scene() {
        let (a, b, c) = (small(3), small(3), small(4));
        let bits = |s: &Scene| s.dem.data.iter().map(|v| v.to_bits()).collect::<Vec<_>>();
        assert!(bits(&a) == bits(&b), "DEMs differ (NaN compared by bits)");
        assert!(a.ortho == b.ortho, "orthophotos differ");
        assert_eq!(a.buildings, b.buildings);
        assert!(bits(&a) != bits(&c));
        assert_ne!(a.buildings, c.buildings);
    }

    #[test]
    fn stated_sun_slopes_and_nodata() {
        let s = small(1);
        assert!((30.0..=50.0).contains(&s.sun.elevation_deg), "{:?}", s.sun);
        assert!(
            s.max_slope_percent > 3.0 && s.max_slope_percent < 22.0,
            "{}",
            s.max_slope_percent
        );
        assert_eq!(
            s.dem.nodata_count(),
            NODATA_CORNER * (NODATA_CORNER + 1) / 2
        );
        assert!(s.dem.get(MIN_SIZE - 1, MIN_SIZE - 1).is_nan() && !s.dem.get(0, 0).is_nan());
        assert_eq!(
            (s.ortho.width(), s.ortho.height()),
            (2 * MIN_SIZE, 2 * MIN_SIZE)
        );
        assert_eq!(s.ortho.grid.bounds(), s.dem.grid.bounds());
        assert!(s.ortho.data.iter().all(|p| p[3] == 255));
    }

    #[test]
    fn dem_is_bare_earth_and_roofs_sit_on_the_highest_ground() {
        let s = small(2);
        assert_eq!(s.buildings.len(), 5);
        for b in &s.buildings {
            assert!((b.roof_z - b.ground_max_z - b.height_m).abs() < 1e-9);
            assert!(
                b.ground_min_z <= b.ground_max_z && b.ground_max_z - b.ground_min_z < 0.3 * 30.0
            );
            // The DEM under the footprint is terrain, far below the roof.
            let [x, y] = b.footprint[0];
            let (c, r) = s.dem.grid.cell_at(x + 0.3, y + 0.3).unwrap();
            let z = *s.dem.get(c, r) as f64;
            assert!(
                z >= b.ground_min_z - 0.5 && z <= b.ground_max_z + 0.5,
                "{z} vs {b:?}"
            );
        }
    }

    #[test]
    fn ortho_is_darkened_by_the_factor_in_a_building_shadow_only() {
        let s = small(5);
        let (east, north) = s.sun.direction();
        let texture_seed = mix(5 ^ 0x0c01);
        let roads = layout::roads(MIN_SIZE as f64 * DEM_CELL_M);
        let tallest = s
            .buildings
            .iter()
            .max_by(|a, b| a.height_m.total_cmp(&b.height_m))
            .unwrap();
        let [x0, x1, y0, y1] = bounds(&tallest.footprint);
        // Leave the footprint's bounding box 1 m beyond its corner, away from the sun (in its
        // shadow) and toward the sun (lit).
        let corner = |toward: f64| {
            let x = if east * toward > 0.0 { x1 } else { x0 };
            let y = if north * toward > 0.0 { y1 } else { y0 };
            (x + toward * east * 1.5, y + toward * north * 1.5)
        };
        for (toward, expect_shadow) in [(-1.0, true), (1.0, false)] {
            let (x, y) = corner(toward);
            let (c, r) = s.ortho.grid.cell_at(x, y).unwrap();
            let (cx, cy) = s.ortho.grid.cell_centre(c, r);
            let lit = ground_colour(texture_seed, &roads, cx - MIN_X, cy - MIN_Y).0;
            let k = if expect_shadow { SHADOW_FACTOR } else { 1.0 };
            let want = lit.map(|v| (v as f64 * k).round() as u8);
            assert_eq!(
                s.ortho.get(c, r)[..3],
                want[..],
                "toward {toward}: building {}",
                tallest.id
            );
        }
        assert!(
            s.shadow_fraction > 0.01 && s.shadow_fraction < 0.3,
            "{}",
            s.shadow_fraction
        );
    }

    /// A footprint's `[min x, max x, min y, max y]`, metres.
    fn bounds(footprint: &[[f64; 2]]) -> [f64; 4] {
        let (xs, ys) = (
            footprint.iter().map(|p| p[0]),
            footprint.iter().map(|p| p[1]),
        );
        [
            xs.clone().fold(f64::INFINITY, f64::min),
            xs.fold(f64::NEG_INFINITY, f64::max),
            ys.clone().fold(f64::INFINITY, f64::min),
            ys.fold(f64::NEG_INFINITY, f64::max),
        ]
    }

    /// The houses' faces in the orthophoto: each lit at its own incidence (the roof convex, a
    /// face's point is lit exactly when its normal is toward the sun), checked at the middle of
    /// each face 1 m inside the eaves against the normal the truth's pitch gives.
    #[test]
    fn a_house_roof_is_lit_face_by_face() {
        let s = small(1);
        let texture_seed = mix(1 ^ 0x0c01);
        let plans = layout::buildings(mix(1 ^ 0xb1d), MIN_SIZE as f64 * DEM_CELL_M);
        let sv = s.sun.direction_enu();
        let houses: Vec<_> = s.buildings.iter().filter(|b| b.pitch.is_some()).collect();
        assert_eq!(houses.len(), 2);
        for b in houses {
            let p = b.pitch.unwrap();
            let [x0, x1, y0, y1] = bounds(&b.footprint);
            // Across the ridge: east for a north–south ridge, north for an east–west one.
            let across = if p.azimuth_deg == 0.0 {
                (1.0, 0.0)
            } else {
                (0.0, 1.0)
            };
            let half = if p.azimuth_deg == 0.0 {
                x1 - x0
            } else {
                y1 - y0
            } / 2.0;
            let slope = (b.roof_z - p.eave_z) / half;
            let (pitch, mid) = (slope.atan(), ((x0 + x1) / 2.0, (y0 + y1) / 2.0));
            for side in [-1.0, 1.0] {
                let at = (
                    mid.0 + side * across.0 * (half - 1.0),
                    mid.1 + side * across.1 * (half - 1.0),
                );
                let (c, r) = s.ortho.grid.cell_at(at.0, at.1).unwrap();
                let n = [
                    side * across.0 * pitch.sin(),
                    side * across.1 * pitch.sin(),
                    pitch.cos(),
                ];
                let ns = n[0] * sv[0] + n[1] * sv[1] + n[2] * sv[2];
                let k = SHADOW_FACTOR + (1.0 - SHADOW_FACTOR) * ns.max(0.0) / sv[2];
                let base = roof_colour(
                    texture_seed,
                    plans[b.id as usize - 1].roof,
                    r * s.ortho.width() + c,
                );
                let want = base.map(|v| (v as f64 * k).round().min(255.0) as u8);
                assert_eq!(
                    s.ortho.get(c, r)[..3],
                    want[..],
                    "house {} side {side}: k {k}",
                    b.id
                );
            }
        }
    }

    #[test]
    fn sizes_out_of_range_are_errors() {
        for size in [0, MIN_SIZE - 1, MAX_SIZE + 1] {
            let e = generate(SampleOptions { seed: 1, size })
                .err()
                .unwrap()
                .to_string();
            assert!(e.contains("--size") && e.contains("default"), "{e}");
        }
    }
}
