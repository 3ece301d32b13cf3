//! The scene file: a TOML description of what a database holds and which products to build
//! from it (`schemas/scene.schema.json`, `docs/scene.md`).
//!
//! Invariant: a [`Scene`] that [`Scene::read`] returns is complete and consistent before any
//! step runs: every key is known, every value is in its range, every placement names a declared
//! object, every inset's parent is a declared inset and no inset nests in itself, every product
//! names a sensor this dbms builds and at most one sun, no output is also an input or another
//! step's output, and relative paths are resolved against the scene file's directory. A problem is one line naming the file, the key (`products.dusk.time`) and, where
//! TOML gives one, the line.

use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

mod check;
pub(super) use check::key_error;

/// The format version this dbms reads.
pub const VERSION: u32 = 1;
/// Most shards a product may be cut into (`[build] shards`).
pub const MAX_SHARDS: usize = 4096;

/// A scene, as written in its file (paths as given).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scene {
    /// Format version, [`VERSION`].
    pub version: u32,
    /// The database the build writes.
    pub database: DatabaseSpec,
    /// The terrain: elevation and orthophoto.
    pub terrain: Terrain,
    /// Finer grids nested in the base grid or in each other, by name (`dbms ingest --inset`).
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub insets: BTreeMap<String, Inset>,
    /// Buildings whose heights are measured from the orthophoto's shadows.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub buildings: Option<Buildings>,
    /// Synthetic voxel objects, by name.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub objects: BTreeMap<String, ObjectSpec>,
    /// Objects placed on the terrain, in order.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub placements: Vec<Placement>,
    /// How the sensor products' materials step classifies (`dbms materials`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub materials: Option<MaterialsSpec>,
    /// What the build delivers, by name: one tile file each.
    pub products: BTreeMap<String, Product>,
    /// How the build is cut into jobs.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub build: Option<BuildSpec>,
}

/// `[build]`: how the build is cut into jobs.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BuildSpec {
    /// Build each visual product as this many shards over windows of level-0 pages, merged at
    /// the end (`dbms pyramid --shard I/N`, `--merge`); 1: one `dbms pyramid`.
    pub shards: usize,
}

impl Scene {
    /// How many shards each visual product is built as (1: unsharded).
    pub fn shards(&self) -> usize {
        self.build.map_or(1, |b| b.shards)
    }

    /// This scene with each visual product cut into `n` shards (`--shards N`: the scene's
    /// `[build] shards` overridden), checked as the key is.
    pub fn with_shards(mut self, n: usize) -> Result<Scene> {
        self.build = Some(BuildSpec { shards: n });
        self.check()?;
        super::plan::check_written(&self)?;
        Ok(self)
    }
}

/// `[materials]`: options of the materials step the sensor products read.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MaterialsSpec {
    /// The material of the cells placed objects stand on, as `dbms materials --objects` takes
    /// it: `"MATERIAL"` or a list of `"MATERIAL"` and `"NAME=MATERIAL"`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub objects: Option<ObjectMaterials>,
    /// GeoJSON features with a `material` (`--features`, in paint order); inputs of the step.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub features: Vec<PathBuf>,
    /// A land-cover raster (`--landcover`), with `legend`; an input of the step.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub landcover: Option<PathBuf>,
    /// The legend the land-cover codes follow (`--legend`: `esa_worldcover`, `nlcd`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub legend: Option<String>,
    /// A material table instead of the shipped one (`--table`); an input of the step.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub table: Option<PathBuf>,
}

impl MaterialsSpec {
    /// The files the step reads, with their keys, in option order.
    pub fn inputs(&self) -> Vec<(String, &PathBuf)> {
        let features = self.features.iter().enumerate();
        let features = features.map(|(k, p)| (format!("materials.features[{k}]"), p));
        let landcover = self
            .landcover
            .iter()
            .map(|p| ("materials.landcover".into(), p));
        let table = self.table.iter().map(|p| ("materials.table".into(), p));
        features.chain(landcover).chain(table).collect()
    }
}

/// `[materials] objects`: one `--objects` value or several.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(untagged)]
pub enum ObjectMaterials {
    /// One material for every placed object.
    Every(String),
    /// `--objects` values, each `MATERIAL` or `NAME=MATERIAL`.
    Each(Vec<String>),
}

impl ObjectMaterials {
    /// The `--objects` values.
    pub fn specs(&self) -> &[String] {
        match self {
            ObjectMaterials::Every(m) => std::slice::from_ref(m),
            ObjectMaterials::Each(v) => v,
        }
    }
}

/// `[database]`: where the database goes and its grid.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DatabaseSpec {
    /// The database directory.
    pub dir: PathBuf,
    /// Cell size, metres; default the orthophoto's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cell: Option<f64>,
    /// Extent `[min_x, min_y, max_x, max_y]` in the DEM's CRS; default where DEM and photo
    /// overlap.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bounds: Option<[f64; 4]>,
}

/// `[terrain]`: the inputs of ingest.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Terrain {
    /// The elevation raster (GeoTIFF or ASCII grid).
    pub dem: PathBuf,
    /// The orthophoto.
    pub ortho: PathBuf,
    /// When the orthophoto was taken (RFC 3339 UTC): its sun, whose shadows are in the photo.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub photo_time: Option<String>,
}

/// `[insets.NAME]`: a finer grid over a window of its parent's cells, each split into `factor ×
/// factor` cells (`dbms ingest --inset NAME:FACTOR:BOUNDS` or `--corridor NAME:FACTOR:BUFFER
/// --route ROUTE`; docs/database.md, "Insets").
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Inset {
    /// Parent cells per inset cell along each axis: a whole number in
    /// [`crate::inset::FACTORS`] (read as a number so that `2.5` is this key's error).
    pub factor: f64,
    /// The window `[min_x, min_y, max_x, max_y]` (CRS units), on the parent's cell edges;
    /// exactly one of `bounds` and `corridor`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub bounds: Option<[f64; 4]>,
    /// The window around a route instead: its bounding rectangle buffered, snapped outward to
    /// the parent's cells.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub corridor: Option<Corridor>,
    /// The inset it refines (a name in `[insets]`); none: the base grid.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub parent: Option<String>,
    /// Its elevation raster; default the terrain's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dem: Option<PathBuf>,
    /// Its orthophoto; default the terrain's.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ortho: Option<PathBuf>,
    /// When its orthophoto was taken (RFC 3339); default the terrain's `photo_time`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub photo_time: Option<String>,
}

/// `[insets.NAME] corridor`: an inset's window along a route.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Corridor {
    /// GeoJSON LineString features in the database's CRS (`--route`).
    pub route: PathBuf,
    /// Metres on every side of the route, ≥ 0.
    pub buffer: f64,
}

impl Inset {
    /// The factor as a whole number (after `Scene::check`).
    pub fn factor(&self) -> usize {
        self.factor as usize
    }

    /// Its DEM, orthophoto and photo time, each the terrain's when not its own.
    pub fn inputs<'a>(&'a self, terrain: &'a Terrain) -> (&'a Path, &'a Path, Option<&'a str>) {
        (
            self.dem.as_deref().unwrap_or(&terrain.dem),
            self.ortho.as_deref().unwrap_or(&terrain.ortho),
            self.photo_time.as_deref().or(terrain.photo_time.as_deref()),
        )
    }
}

/// `[buildings]`: footprints whose heights shadow-height measures in the orthophoto.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Buildings {
    /// GeoJSON FeatureCollection of footprint polygons.
    pub footprints: PathBuf,
    /// How the orthophoto's bytes encode light (`shadow-height --photo-encoding`; `None`: its
    /// default, sRGB). Pitched roofs' faces are read as light.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub photo_encoding: Option<crate::shadow_height::shading::PhotoEncoding>,
}

/// `[objects.NAME]`: a synthetic voxel object, as `dbms object KIND` makes it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum ObjectSpec {
    /// A cone tree on a trunk (`dbms object cone`).
    Cone {
        /// Nominal total height, metres, > 0.
        height: f64,
        /// Crown radius at its base, metres, > 0.
        radius: f64,
        /// Voxel edge, metres, > 0.
        voxel: f64,
        /// Seed of the variation.
        #[serde(default = "one")]
        seed: u64,
        /// Relative variation of size and shade, in [0, 1).
        #[serde(default = "default_vary")]
        vary: f64,
    },
    /// A surface of revolution (`dbms object revolve`).
    Revolve {
        /// The profile, `[radius, z]` pairs in metres from bottom to top.
        profile: Vec<[f64; 2]>,
        /// Voxel edge, metres, > 0.
        voxel: f64,
    },
}

fn one() -> u64 {
    1
}

fn default_vary() -> f64 {
    0.2
}

/// `[[placements]]`: one object stood on the terrain at `at`, or one per point of a GeoJSON
/// point layer `points` (exactly one of the two).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Placement {
    /// The name of an object in `[objects]` (with `points`: for points without an `object`).
    pub object: String,
    /// Where its anchor goes, `[x, y]` in the database CRS, or `[x, y, z]` with `z` absolute
    /// metres (default the ground's), as `dbms place --at X,Y[,Z]`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub at: Option<Vec<f64>>,
    /// Rotation clockwise from grid north, degrees (with `at`; default 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub heading: Option<f64>,
    /// Size factor about the anchor, > 0 (with `at`; default 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scale: Option<f64>,
    /// A GeoJSON FeatureCollection of Points: one object each (`dbms place --points`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub points: Option<PathBuf>,
    /// With `points`: points without a `heading` get a random one (default false).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub random_heading: Option<bool>,
    /// With `points`: points without a `scale` get one uniform in `[min, max]`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub scale_range: Option<[f64; 2]>,
    /// With `points`: the seed of `random_heading` and `scale_range` (default 0).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub seed: Option<u64>,
}

impl Placement {}

/// `[products.NAME]`: one tile file for one sensor under one sun and its conditions.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Product {
    /// The sensor the product is for ([`SENSORS`]).
    pub sensor: String,
    /// The tile file the build writes.
    pub tiles: PathBuf,
    /// The sun by time (RFC 3339 UTC, over the database centre); exclusive with `sun`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub time: Option<String>,
    /// The sun by its angles; exclusive with `time`. Neither: no sun effects at all.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub sun: Option<SunAngles>,
    /// What the scene is like when the product is seen.
    #[serde(default)]
    pub conditions: Conditions,
    /// Night vision only: light points (GeoJSON, `dbms pyramid --lights`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub lights: Option<PathBuf>,
    /// Radar only: where the radar looks from (`dbms radar`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub radar: Option<RadarLook>,
}

/// `[products.NAME.radar]`: a distant radar's direction and band.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RadarLook {
    /// Grid azimuth from the scene toward the radar, degrees.
    pub azimuth: f64,
    /// The radar's elevation above the horizon, degrees, in (0, 90).
    pub elevation: f64,
    /// The band, `L` … `W`; default `X`.
    #[serde(default = "default_band")]
    pub band: String,
}

fn default_band() -> String {
    "X".into()
}

/// A sun given by its angles.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SunAngles {
    /// Elevation above the horizon, degrees, in (0, 90].
    pub elevation: f64,
    /// Azimuth clockwise from grid north, degrees.
    pub azimuth: f64,
}

/// `[products.NAME.conditions]`.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Conditions {
    /// Meteorological visibility, metres (haze), > 0; none: clear air.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub visibility_m: Option<f64>,
    /// ir: mean air temperature of the day, °C (`dbms thermal --air-temp`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub air_temp_c: Option<f64>,
    /// ir: daily air temperature range, K (`--air-range`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub air_range_k: Option<f64>,
    /// ir: wind speed, m/s (`--wind`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub wind_m_s: Option<f64>,
    /// ir: relative humidity, a fraction in (0, 1] (`--humidity`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub humidity: Option<f64>,
}

impl Conditions {
    /// The weather keys given, with their `dbms thermal` options, in the options' order.
    pub fn weather(&self) -> Vec<(&'static str, &'static str, f64)> {
        let all = [
            ("air_temp_c", "--air-temp", self.air_temp_c),
            ("air_range_k", "--air-range", self.air_range_k),
            ("wind_m_s", "--wind", self.wind_m_s),
            ("humidity", "--humidity", self.humidity),
        ];
        all.into_iter()
            .filter_map(|(k, o, v)| Some((k, o, v?)))
            .collect()
    }

    /// The thermal conditions: the given weather over `dbms thermal`'s defaults.
    pub fn thermal(&self) -> crate::thermal_map::Conditions {
        let d = crate::thermal_map::Conditions::default();
        crate::thermal_map::Conditions {
            air_mean_c: self.air_temp_c.unwrap_or(d.air_mean_c),
            air_range_k: self.air_range_k.unwrap_or(d.air_range_k),
            wind_m_per_s: self.wind_m_s.unwrap_or(d.wind_m_per_s),
            relative_humidity: self.humidity.unwrap_or(d.relative_humidity),
        }
    }
}

/// The sensors a product may name: `visual` (colour shaded for a sun), `ir` (temperature at
/// `time`), `nvg` (materials and light points) and `radar` (σ⁰ for `radar`) (docs/sensors.md).
pub const SENSORS: [&str; 4] = ["visual", "ir", "nvg", "radar"];

impl Scene {
    /// Read and check the scene file at `path`; relative paths in it become relative to its
    /// directory.
    pub fn read(path: &Path) -> Result<Scene> {
        let text = crate::io::read_settings(path)
            .map_err(|e| e.fix("give the path of a scene file (TOML)"))?;
        let mut scene = Scene::parse(&text).map_err(|e| e.in_file(path))?;
        let base = path.parent().unwrap_or(Path::new(""));
        scene.resolve_paths(base);
        scene.check_paths().map_err(|e| e.in_file(path))?;
        Ok(scene)
    }

    /// Parse and check a scene file's text (paths left as written).
    pub fn parse(text: &str) -> Result<Scene> {
        let scene: Scene = toml::from_str(text).map_err(|e| toml_error(text, &e))?;
        scene.check()?;
        Ok(scene)
    }

    /// The insets' names in the order they are added: in name order, each after its parent
    /// (a parent declared later comes first, with its own parents). An error when insets nest
    /// in each other in a cycle. Parents are declared (`Scene::check`).
    pub fn inset_order(&self) -> Result<Vec<&String>> {
        let mut done: Vec<&String> = Vec::new();
        for name in self.insets.keys() {
            // The chain of parents not added yet, from `name` up.
            let mut chain: Vec<&String> = Vec::new();
            let mut at = Some(name);
            while let Some(n) = at.filter(|n| !done.contains(n)) {
                if chain.contains(&n) {
                    chain.push(n);
                    let names: Vec<&str> = chain.iter().map(|n| n.as_str()).collect();
                    return Err(key_error(
                        &format!("insets.{name}.parent"),
                        format!("nests insets in themselves: {}", names.join(" in ")),
                        "give each inset a parent that is coarser than it, or none (the base grid)",
                    ));
                }
                chain.push(n);
                at = self.insets.get(n).and_then(|i| i.parent.as_ref());
            }
            done.extend(chain.into_iter().rev());
        }
        Ok(done)
    }

    /// Make every relative path relative to `base` (the scene file's directory).
    fn resolve_paths(&mut self, base: &Path) {
        let resolve = |p: &mut PathBuf| {
            if p.is_relative() {
                *p = base.join(&*p);
            }
        };
        resolve(&mut self.database.dir);
        resolve(&mut self.terrain.dem);
        resolve(&mut self.terrain.ortho);
        for inset in self.insets.values_mut() {
            inset.dem.iter_mut().for_each(resolve);
            inset.ortho.iter_mut().for_each(resolve);
            if let Some(c) = &mut inset.corridor {
                resolve(&mut c.route);
            }
        }
        if let Some(b) = &mut self.buildings {
            resolve(&mut b.footprints);
        }
        for p in self.products.values_mut() {
            resolve(&mut p.tiles);
            if let Some(lights) = &mut p.lights {
                resolve(lights);
            }
        }
        for p in &mut self.placements {
            if let Some(points) = &mut p.points {
                resolve(points);
            }
        }
        if let Some(m) = &mut self.materials {
            m.features.iter_mut().for_each(resolve);
            m.landcover.iter_mut().for_each(resolve);
            m.table.iter_mut().for_each(resolve);
        }
    }

    /// The files the scene names as inputs, each with its key (`terrain.dem`).
    pub fn inputs(&self) -> Vec<(String, PathBuf)> {
        let mut inputs = vec![
            ("terrain.dem".to_string(), self.terrain.dem.clone()),
            ("terrain.ortho".to_string(), self.terrain.ortho.clone()),
        ];
        for (name, i) in &self.insets {
            let key = |k: &str| format!("insets.{name}.{k}");
            let files = [
                (key("dem"), i.dem.as_ref()),
                (key("ortho"), i.ortho.as_ref()),
                (key("corridor.route"), i.corridor.as_ref().map(|c| &c.route)),
            ];
            inputs.extend(files.into_iter().filter_map(|(k, p)| Some((k, p?.clone()))));
        }
        if let Some(b) = &self.buildings {
            inputs.push(("buildings.footprints".into(), b.footprints.clone()));
        }
        for (k, p) in self.placements.iter().enumerate() {
            if let Some(points) = &p.points {
                inputs.push((format!("placements[{k}].points"), points.clone()));
            }
        }
        for (name, p) in &self.products {
            if let Some(lights) = &p.lights {
                inputs.push((format!("products.{name}.lights"), lights.clone()));
            }
        }
        let materials = self.materials.as_ref().map_or(vec![], |m| m.inputs());
        inputs.extend(materials.into_iter().map(|(k, p)| (k, p.clone())));
        inputs
    }
}

/// TOML's error as one line: the line number, the key path when TOML names it, the message.
fn toml_error(text: &str, e: &toml::de::Error) -> Error {
    let line = e
        .span()
        .map(|s| text[..s.start.min(text.len())].matches('\n').count() + 1);
    let message = e.message().trim().replace('\n', " ");
    match line {
        Some(n) => Error::msg(format!("line {n}: {message}")),
        None => Error::msg(message),
    }
    .fix("see schemas/scene.schema.json and samples/scene.toml")
}

#[cfg(test)]
mod tests {
    use super::*;

    const GOOD: &str = r#"
version = 1

[database]
dir = "db"

[terrain]
dem = "dem.tif"
ortho = "ortho.tif"
photo_time = "2026-09-15T08:30:00Z"

[buildings]
footprints = "buildings.geojson"

[objects.tree]
kind = "cone"
height = 10
radius = 2.5
voxel = 0.25

[[placements]]
object = "tree"
at = [500066, 5300130]
heading = 50

[products.day]
sensor = "visual"
tiles = "day.dbt"
time = "2026-09-15T08:30:00Z"

[products.low-sun]
sensor = "visual"
tiles = "low.dbt"
sun = { elevation = 5, azimuth = 250 }
conditions = { visibility_m = 2000 }
"#;

    fn error_of(text: &str) -> String {
        Scene::parse(text).unwrap_err().to_string()
    }

    #[test]
    fn a_complete_scene_reads_with_its_defaults() {
        let s = Scene::parse(GOOD).unwrap();
        assert_eq!(s.products.len(), 2);
        assert_eq!(
            s.objects["tree"],
            ObjectSpec::Cone {
                height: 10.0,
                radius: 2.5,
                voxel: 0.25,
                seed: 1,
                vary: 0.2
            }
        );
        assert_eq!(s.placements[0].heading, Some(50.0));
        assert_eq!(s.products["low-sun"].conditions.visibility_m, Some(2000.0));
        assert_eq!(s.products["day"].conditions, Conditions::default());
    }

    #[test]
    fn an_unknown_key_is_named_with_its_line() {
        let text = GOOD.replace("heading = 50", "heading = 50\nheadnig = 3");
        let e = error_of(&text);
        let line = text.lines().position(|l| l.contains("headnig")).unwrap() + 1;
        assert!(
            e.contains("`headnig`") && e.contains(&format!("line {line}:")),
            "{e}"
        );
        assert!(!e.contains('\n'), "one line: {e}");
    }

    #[test]
    fn a_placement_of_an_undeclared_object_names_the_key() {
        let e = error_of(&GOOD.replace("object = \"tree\"", "object = \"oak\""));
        assert!(
            e.contains("placements[0].object") && e.contains("\"oak\""),
            "{e}"
        );
    }

    #[test]
    fn impossible_products_name_the_key() {
        let e = error_of(&GOOD.replace(
            "sensor = \"visual\"\ntiles = \"day.dbt\"",
            "sensor = \"sonar\"\ntiles = \"day.dbt\"",
        ));
        assert!(
            e.contains("products.day.sensor") && e.contains("sonar"),
            "{e}"
        );
        // Each sensor's needs and refusals, each naming its key.
        let product = |body: &str| {
            let text = GOOD.replace(
                "sensor = \"visual\"\ntiles = \"day.dbt\"\ntime = \"2026-09-15T08:30:00Z\"",
                body,
            );
            Scene::parse(&text).map(|_| ()).map_err(|e| e.to_string())
        };
        let t = "time = \"2026-09-15T13:00:00Z\"";
        let look = "radar = { azimuth = 220, elevation = 20 }";
        assert_eq!(
            product(&format!("sensor = \"ir\"\ntiles = \"ir.dbt\"\n{t}")),
            Ok(())
        );
        assert_eq!(
            product(&format!("sensor = \"radar\"\ntiles = \"r.dbt\"\n{look}")),
            Ok(())
        );
        assert_eq!(
            product("sensor = \"nvg\"\ntiles = \"n.dbt\"\nlights = \"l.geojson\""),
            Ok(())
        );
        let weather =
            "conditions = { air_temp_c = -5, air_range_k = 12, wind_m_s = 0, humidity = 1 }";
        assert_eq!(
            product(&format!(
                "sensor = \"ir\"\ntiles = \"ir.dbt\"\n{t}\n{weather}"
            )),
            Ok(())
        );
        for (body, want) in [
            ("sensor = \"ir\"\ntiles = \"ir.dbt\"".to_string(), "without a time"),
            ("sensor = \"radar\"\ntiles = \"r.dbt\"".into(), "without a radar look"),
            (format!("sensor = \"nvg\"\ntiles = \"n.dbt\"\n{t}"), "products.day.time is given"),
            (format!("sensor = \"visual\"\ntiles = \"v.dbt\"\n{look}"), "products.day.radar"),
            ("sensor = \"ir\"\ntiles = \"v.dbt\"\nsun = { elevation = 5, azimuth = 1 }".into(), "products.day.sun"),
            ("sensor = \"radar\"\ntiles = \"r.dbt\"\nradar = { azimuth = 1, elevation = 95 }".into(), "products.day.radar.elevation is 95"),
            ("sensor = \"radar\"\ntiles = \"r.dbt\"\nradar = { azimuth = nan, elevation = 30 }".into(), "products.day.radar.azimuth is NaN"),
            ("sensor = \"visual\"\ntiles = \"v.dbt\"\nsun = { azimuth = inf, elevation = 30 }".into(), "products.day.sun.azimuth is inf"),
            ("sensor = \"radar\"\ntiles = \"r.dbt\"\nradar = { azimuth = 1, elevation = 9, band = \"Q\" }".into(), "products.day.radar.band"),
            ("sensor = \"visual\"\ntiles = \"v.dbt\"\nconditions = { wind_m_s = 3 }".into(), "products.day.conditions.wind_m_s is given"),
            (format!("sensor = \"ir\"\ntiles = \"ir.dbt\"\n{t}\nconditions = {{ humidity = 0 }}"), "products.day.conditions.humidity 0"),
            (format!("sensor = \"ir\"\ntiles = \"ir.dbt\"\n{t}\nconditions = {{ air_range_k = 61 }}"), "products.day.conditions.air_range_k 61"),
        ] {
            let e = product(&body).unwrap_err();
            assert!(e.contains(want), "{body}: {e}");
        }
        let both = GOOD.replace(
            "sun = { elevation = 5, azimuth = 250 }",
            "sun = { elevation = 5, azimuth = 250 }\ntime = \"2026-09-15T18:00:00Z\"",
        );
        assert!(error_of(&both).contains("products.low-sun gives both time and sun"));
        let below = GOOD.replace("elevation = 5,", "elevation = -2,");
        assert!(error_of(&below).contains("products.low-sun.sun"));
        let bad_time = GOOD.replace(
            "time = \"2026-09-15T08:30:00Z\"\n\n[products.low",
            "time = \"noon\"\n\n[products.low",
        );
        assert!(
            error_of(&bad_time).contains("products.day.time"),
            "{}",
            error_of(&bad_time)
        );
        let none = GOOD[..GOOD.find("[products.day]").unwrap()].to_string() + "[products]\n";
        assert!(error_of(&none).contains("products is empty"));
    }

    #[test]
    fn materials_sources_are_read_and_a_landcover_needs_its_legend() {
        let with = |m: &str| GOOD.to_string() + "\n[materials]\n" + m;
        let s = Scene::parse(&with(
            "objects = [\"forest\", \"tank=roof_metal\"]\nfeatures = [\"a.geojson\", \"b.geojson\"]\nlandcover = \"wc.tif\"\nlegend = \"esa_worldcover\"\ntable = \"t.json\"",
        ))
        .unwrap();
        let m = s.materials.unwrap();
        let keys: Vec<String> = m.inputs().into_iter().map(|(k, _)| k).collect();
        assert_eq!(
            keys,
            [
                "materials.features[0]",
                "materials.features[1]",
                "materials.landcover",
                "materials.table"
            ]
        );
        assert_eq!(m.objects.unwrap().specs(), ["forest", "tank=roof_metal"]);
        for half in ["landcover = \"wc.tif\"", "legend = \"nlcd\""] {
            let e = error_of(&with(half));
            assert!(
                e.contains("materials gives one of landcover and legend"),
                "{e}"
            );
        }
    }

    const INSETS: &str = r#"
[insets.town]
factor = 4
bounds = [500360, 5300264, 500432, 5300400]

[insets.yard]
factor = 2
bounds = [500380, 5300300, 500390, 5300310]
parent = "town"
photo_time = "2026-09-15T09:00:00Z"

[insets.road]
factor = 10
corridor = { route = "road.geojson", buffer = 30 }
dem = "lidar.tif"
"#;

    #[test]
    fn insets_read_with_their_parents_first() {
        let s = Scene::parse(&(GOOD.to_string() + INSETS)).unwrap();
        assert_eq!(s.inset_order().unwrap(), ["road", "town", "yard"]);
        let text = (GOOD.to_string() + INSETS)
            .replace("[insets.town]", "[insets.zone]")
            .replace("parent = \"town\"", "parent = \"zone\"");
        let s = Scene::parse(&text).unwrap();
        // A parent whose name sorts after its child's comes first.
        assert_eq!(s.inset_order().unwrap(), ["road", "zone", "yard"]);
        assert_eq!(s.insets["yard"].factor(), 2);
        let (dem, ortho, time) = s.insets["road"].inputs(&s.terrain);
        assert_eq!(
            (dem, ortho, time),
            (
                Path::new("lidar.tif"),
                Path::new("ortho.tif"),
                Some("2026-09-15T08:30:00Z")
            )
        );
        assert_eq!(
            s.insets["yard"].inputs(&s.terrain).2,
            Some("2026-09-15T09:00:00Z")
        );
    }

    #[test]
    fn bad_insets_are_one_line_errors_naming_the_key() {
        let with = |from: &str, to: &str| {
            let text = GOOD.to_string() + INSETS;
            assert!(text.contains(from), "{from}");
            error_of(&text.replacen(from, to, 1))
        };
        for (from, to, want) in [
            (
                "factor = 4",
                "factor = 2.5",
                "insets.town.factor is 2.5, not a whole number from 2 to 10",
            ),
            ("factor = 4", "factor = 11", "insets.town.factor is 11"),
            (
                "factor = 4",
                "factor = 4\nfactr = 3",
                "unknown field `factr`",
            ),
            (
                "parent = \"town\"",
                "parent = \"city\"",
                "insets.yard.parent names \"city\", which [insets] does not declare",
            ),
            (
                "factor = 4\n",
                "factor = 4\nparent = \"yard\"\n",
                "insets.town.parent nests insets in themselves: town in yard in town",
            ),
            (
                "bounds = [500360,",
                "corridor = { route = \"r.geojson\", buffer = 5 }\nbounds = [500360,",
                "insets.town needs exactly one of bounds and corridor",
            ),
            (
                "bounds = [500360, 5300264, 500432, 5300400]\n",
                "",
                "insets.town needs exactly one of bounds and corridor",
            ),
            (
                "500432, 5300400",
                "500300, 5300400",
                "insets.town.bounds is not [min_x",
            ),
            (
                "buffer = 30",
                "buffer = -1",
                "insets.road.corridor.buffer is -1",
            ),
            (
                "500390, 5300310]",
                "500390, 5300410]",
                "insets.yard.bounds reach outside insets.town.bounds",
            ),
            (
                "[insets.yard]",
                "[insets.\"../yard\"]",
                "insets.../yard is not a plain inset name",
            ),
            ("2026-09-15T09:00:00Z", "nine", "insets.yard.photo_time"),
        ] {
            let e = with(from, to);
            assert!(e.contains(want), "{to}: {e}");
            assert!(!e.contains('\n'), "one line: {e}");
        }
        // Siblings apart: a second inset of the base over the town.
        let e = error_of(
            &(GOOD.to_string()
                + INSETS
                + "[insets.mill]\nfactor = 2\nbounds = [500420, 5300200, 500440, 5300270]\n"),
        );
        assert!(
            e.contains("insets.town.bounds overlap insets.mill.bounds (both refine the base grid)"),
            "{e}"
        );
        // Sharded builds make the insets too.
        let s = Scene::parse(&(GOOD.to_string() + INSETS + "[build]\nshards = 2\n")).unwrap();
        assert_eq!(s.shards(), 2);
    }

    #[test]
    fn buildings_need_the_photo_time() {
        let e = error_of(&GOOD.replace("photo_time = \"2026-09-15T08:30:00Z\"\n", ""));
        assert!(
            e.contains("buildings") && e.contains("terrain.photo_time"),
            "{e}"
        );
    }

    #[test]
    fn values_out_of_range_name_the_key() {
        assert!(error_of(&GOOD.replace("voxel = 0.25", "voxel = 0")).contains("objects.tree.voxel"));
        assert!(error_of(&GOOD.replace("version = 1", "version = 2")).contains("version is 2"));
        let e = error_of(&GOOD.replace("dir = \"db\"", "dir = \"db\"\ncell = -1"));
        assert!(e.contains("database.cell"), "{e}");
    }

    #[test]
    fn paths_resolve_against_the_scene_and_outputs_must_not_clash() {
        let dir = tempfile::tempdir().unwrap();
        for f in ["dem.tif", "ortho.tif", "buildings.geojson"] {
            std::fs::write(dir.path().join(f), b"x").unwrap();
        }
        let path = dir.path().join("scene.toml");
        std::fs::write(&path, GOOD).unwrap();
        let s = Scene::read(&path).unwrap();
        assert_eq!(s.terrain.dem, dir.path().join("dem.tif"));
        assert_eq!(s.products["day"].tiles, dir.path().join("day.dbt"));

        std::fs::write(
            &path,
            GOOD.replace("tiles = \"low.dbt\"", "tiles = \"day.dbt\""),
        )
        .unwrap();
        let e = Scene::read(&path).unwrap_err().to_string();
        assert!(
            e.contains("products.low-sun.tiles") && e.contains("products.day.tiles"),
            "{e}"
        );
        std::fs::write(
            &path,
            GOOD.replace("tiles = \"low.dbt\"", "tiles = \"dem.tif\""),
        )
        .unwrap();
        let e = Scene::read(&path).unwrap_err().to_string();
        assert!(e.contains("terrain.dem"), "a cycle: {e}");

        // An inset's own inputs resolve and must exist too.
        std::fs::write(&path, GOOD.to_string() + INSETS).unwrap();
        let e = Scene::read(&path).unwrap_err().to_string();
        assert!(
            e.contains("insets.road.dem") && e.contains("lidar.tif does not exist"),
            "{e}"
        );
        std::fs::write(dir.path().join("lidar.tif"), b"x").unwrap();
        let e = Scene::read(&path).unwrap_err().to_string();
        assert!(e.contains("insets.road.corridor.route"), "{e}");
        std::fs::write(dir.path().join("road.geojson"), b"x").unwrap();
        let s = Scene::read(&path).unwrap();
        assert_eq!(
            s.insets["road"].corridor.as_ref().unwrap().route,
            dir.path().join("road.geojson")
        );

        std::fs::remove_file(dir.path().join("ortho.tif")).unwrap();
        std::fs::write(&path, GOOD).unwrap();
        let e = Scene::read(&path).unwrap_err().to_string();
        assert!(
            e.contains("terrain.ortho") && e.contains("does not exist"),
            "{e}"
        );
        assert!(e.contains("scene.toml"), "names the file: {e}");
    }
}
