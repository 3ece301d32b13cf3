//! Sparse voxel objects: carving from silhouettes, synthetic objects, export.
