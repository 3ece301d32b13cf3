//! `dbms sculpt` as a library call: load the views, carve the visual hull inside the bounds,
//! colour it with visibility. Same inputs → the same object, bit for bit.

use super::carve::{carve, CarveOptions};
use super::colour::{colour, ColourStats};
use super::grid::VoxelGrid;
use super::object::VoxelObject;
use super::views::{load, ViewsFile};
use crate::error::{Error, Result};
use std::path::Path;

/// Parameters of a sculpt run.
#[derive(Debug, Clone)]
pub struct SculptOptions {
    /// Voxel edge, metres.
    pub voxel: f64,
    /// `[minx, miny, minz, maxx, maxy, maxz]` metres; overrides the views file's `bounds`.
    pub bounds: Option<[f64; 6]>,
    /// Behind-camera and outside-image rules.
    pub carve: CarveOptions,
    /// Colour of interior voxels and of surface voxels no view sees.
    pub fill: [u8; 3],
}

/// What a sculpt run did.
#[derive(Debug, Clone, serde::Serialize)]
pub struct SculptReport {
    /// Number of views.
    pub views: usize,
    /// Grid dimensions.
    pub dims: [u32; 3],
    /// Solid voxels kept.
    pub voxels: usize,
    /// Surface colouring counts.
    pub colour: ColourStats,
    /// Things the user should know (silhouettes touching the border...).
    pub warnings: Vec<String>,
}

/// Carve and colour the object described by the views file at `path`.
pub fn sculpt(path: &Path, opts: &SculptOptions) -> Result<(VoxelObject, SculptReport)> {
    let file = ViewsFile::read(path)?;
    let b = opts.bounds.or(file.bounds).ok_or_else(|| {
        Error::file(path, "no bounds to carve")
            .fix("give --bounds MINX,MINY,MINZ,MAXX,MAXY,MAXZ or \"bounds\" in the views file")
    })?;
    let grid = VoxelGrid::covering([b[0], b[1], b[2]], [b[3], b[4], b[5]], opts.voxel)?;
    let loaded = load(path, &file)?;
    let warnings = loaded
        .iter()
        .enumerate()
        .filter(|(_, l)| l.view.silhouette.touches_border())
        .map(|(i, l)| {
            format!(
                "{}: view {i}: the silhouette touches the image border; the object may extend outside this view, which then cannot carve it there",
                l.silhouette_path.display()
            )
        })
        .collect();
    let (views, images): (Vec<_>, Vec<_>) = loaded.into_iter().map(|l| (l.view, l.image)).unzip();
    let occ = carve(&grid, &views, &opts.carve)?;
    if occ.count() == 0 {
        return Err(Error::file(path, "no voxel survives carving: the silhouettes do not agree anywhere inside the bounds")
            .fix("check the cameras and bounds, or use a smaller --voxel if the object is smaller than one voxel"));
    }
    let (obj, stats) = colour(grid, occ, &views, &images, opts.fill);
    let report = SculptReport {
        views: views.len(),
        dims: grid.dims,
        voxels: obj.len(),
        colour: stats,
        warnings,
    };
    Ok((obj, report))
}
