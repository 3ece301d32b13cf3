//! Reading and writing rasters: GeoTIFF, Esri ASCII grid, PNG/JPEG with a world file.

pub mod atomic;
