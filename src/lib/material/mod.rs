//! Materials: what each database cell, building and voxel is made of, for the sensor
//! databases (issue 18).
//!
//! Ids: 0 is unclassified, 255 nodata, 1..=254 the materials of a [`table::MaterialTable`].
//!
//! * [`table`]: the material table (format, checks, the shipped default with its sources).
//! * [`cover`]: a land-cover raster's class codes at the database's cells.
//! * [`features`]: vector features (polygons, lines with a width) naming a material.
//! * [`layer`]: the material layer of a database (`dbms materials`), sources in precedence.
//! * [`photo`]: a cell's material from its orthophoto colour, by fixed published rules.
//! * [`surface`]: a database's top surface cell by cell (material, height, normal), as the
//!   sensor stages read it.

pub mod cover;
pub mod features;
pub mod layer;
pub mod photo;
pub mod surface;
pub mod table;
