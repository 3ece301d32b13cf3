//! Materials: what each database cell, building and voxel is made of, for the sensor
//! databases (issue 18). Filled in by the submodules as they land.
//!
//! Ids: 0 is unclassified, 255 nodata, 1..=254 the materials of a [`table::MaterialTable`].

pub mod table;
