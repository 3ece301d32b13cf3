//! Materials: what each database cell, building and voxel is made of, for the sensor
//! databases (issue 18).
//!
//! * [`photo`]: a cell's material from its orthophoto colour, by fixed published rules.

pub mod photo;
