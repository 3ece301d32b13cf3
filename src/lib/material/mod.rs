//! Materials: what each database cell, building and voxel is made of, for the sensor
//! databases (issue 18). Filled in by the submodules as they land.
