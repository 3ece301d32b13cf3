//! Sparse voxel objects: carving from silhouettes, synthetic objects, export.
//!
//! World units are metres; an object's voxels are axis-aligned with the world (x east, y north,
//! z up) and addressed by [`grid::VoxelGrid`].

pub mod camera;
pub mod carve;
pub mod colour;
pub mod columns;
pub mod export;
pub mod format;
pub mod grid;
pub mod object;
pub mod occupancy;
pub mod picture;
pub mod place;
pub mod sculpt;
pub mod silhouette;
pub mod synth;
pub(crate) mod vec3;
pub mod views;
