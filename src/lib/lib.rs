//! # dbms — the database authoring library
//!
//! Builds the terrain-and-object database of a height-field / voxel ray-casting visual and
//! sensor simulator (the system of US patent 5,317,689). Every algorithm lives here and is
//! testable without the command line; `src/bin/dbms.rs` is a thin CLI over it.
//!
//! Units: world coordinates are `f64` in the CRS's units (metres for projected CRSs); heights
//! are metres; angles are degrees at public interfaces and radians inside.
//!
//! Stages, each a module:
//! * [`ingest`]: DEM + orthophoto onto one database grid ([`db`] holds the result).
//! * [`sun`]: solar position; [`shadow`]: cast-shadow masks over a height field;
//!   [`shadow_mask`]: the `dbms shadows` stage (a database's mask as a GeoTIFF).
//! * [`shadow_height`]: building heights from their shadows, refined over the terrain.
//! * [`sample_scene`]: the generated sample scene.
//! * [`voxel`]: sculpted and synthetic voxel objects.
//! * [`standing`]: what stands on the terrain (building prisms and placed voxel objects, and
//!   the polygon fill that rasterises footprints), read by shadow-height, the shadows command
//!   and the pyramid.
//! * [`pyramid`] and [`tiles`]: the render database; [`render`]: the ray-casting preview.
//! * [`scene`]: a scene file naming the inputs, objects, placements and products of a build.
//!
//! Shared by the stages: [`walk`], the one grid traversal (cells a ray crosses, explicit corner rule).

pub mod backscatter;
pub mod choice;
pub mod crs;
pub mod db;
pub mod error;
pub mod geojson;
pub mod grid;
pub mod ingest;
pub mod inset;
pub mod io;
pub mod lights;
pub mod manifest;
pub mod material;
pub mod mesh;
pub mod moon;
pub mod num;
pub mod progress;
pub mod pyramid;
pub mod radar_map;
pub mod raster;
pub mod reading;
pub mod render;
pub mod roof;
pub mod sample_scene;
pub mod scene;
pub mod shadow;
pub mod shadow_height;
pub mod shadow_mask;
pub mod standing;
pub mod sun;
#[cfg(feature = "testing")]
#[doc(hidden)]
pub mod testing;
pub mod thermal;
pub mod thermal_map;
pub mod tiles;
pub mod voxel;
pub mod walk;

pub use error::{Error, Result};
