//! What stands on the terrain, as meshes: every building a prism coloured by the photo under
//! its roof, every placed voxel object; each with the level-0 cell whose tile holds it.

use super::{mean_opaque, BAND_ROWS};
use crate::db::Database;
use crate::error::{Error, Result};
use crate::grid::Grid;
use crate::mesh::prisms::prism_mesh;
use crate::mesh::voxels::object_mesh;
use crate::mesh::Mesh;
use crate::raster::RowSource;
use crate::standing::{polygon_cells, read_buildings, CellSample, TerrainSample};
use std::collections::BTreeMap;

/// Buildings and objects as meshes, each with the level-0 cell it belongs to.
pub(super) struct Things {
    /// `(cell column, cell row, mesh, wall base)`: the cell each belongs to, and for a building
    /// the height (metres) its walls start from, the lowest terrain under it, which each level
    /// lowers by its own bound.
    pub(super) meshes: Vec<(usize, usize, Mesh, Option<f64>)>,
    pub(super) buildings: usize,
    pub(super) over_nodata: usize,
    pub(super) objects: usize,
}

/// Read and mesh what stands on the terrain: buildings (walls from the lowest valid terrain
/// under the footprint), placed objects.
pub(super) fn standing_meshes(
    db: &Database,
    elevation: &dyn RowSource<f32>,
    photo: &dyn RowSource<[u8; 4]>,
) -> Result<Things> {
    let grid = db.grid();
    let mut out = Things {
        meshes: Vec::new(),
        buildings: 0,
        over_nodata: 0,
        objects: 0,
    };
    if db.manifest.layers.contains_key(crate::db::BUILDINGS) {
        let path = db.layer_path(crate::db::BUILDINGS)?;
        let prisms = read_buildings(&path)?;
        let cells: Vec<Vec<usize>> = prisms
            .iter()
            .map(|p| {
                let mut c = polygon_cells(grid, &p.rings);
                // Small outlines may hold no cell centre: their corners' cells stand in.
                c.extend(
                    p.rings
                        .iter()
                        .flatten()
                        .filter_map(|&(x, y)| grid.cell_at(x, y))
                        .map(|(col, row)| grid.index(col, row)),
                );
                c
            })
            .collect();
        let terrain = TerrainSample::read(elevation, cells.concat(), BAND_ROWS)?;
        let colour = CellSample::read(photo, cells.concat(), BAND_ROWS)?;
        for (i, (prism, under)) in prisms.iter().zip(&cells).enumerate() {
            let lowest = under
                .iter()
                .map(|&c| crate::standing::TerrainAt::at(&terrain, c))
                .filter(|z| z.is_finite())
                .fold(f32::INFINITY, f32::min);
            if !lowest.is_finite() {
                out.over_nodata += 1;
                continue;
            }
            let rgb = mean_opaque(under.iter().map(|&c| colour.get(c)));
            let mesh = prism_mesh(prism, lowest as f64, rgb).map_err(|e| {
                Error::file(&path, format!("building {i}: {e}"))
                    .fix("correct the outline (a simple polygon, holes inside it) and export again")
            })?;
            let (lo, hi) = mesh.bounds().expect("a prism has vertices");
            let (col, row) = clamp_cell(grid, (lo[0] + hi[0]) / 2.0, (lo[1] + hi[1]) / 2.0);
            out.meshes.push((col, row, mesh, Some(lowest as f64)));
            out.buildings += 1;
        }
    }
    let mut objects: BTreeMap<&str, crate::voxel::object::VoxelObject> = BTreeMap::new();
    for p in &db.manifest.objects {
        if !objects.contains_key(p.file.as_str()) {
            let (obj, _) = crate::voxel::format::read(&db.dir.join(&p.file))?;
            objects.insert(&p.file, obj);
        }
        let mesh = object_mesh(&objects[p.file.as_str()], p);
        if mesh.is_empty() {
            continue;
        }
        let (col, row) = clamp_cell(grid, p.x, p.y);
        out.meshes.push((col, row, mesh, None));
        out.objects += 1;
    }
    Ok(out)
}

/// The grid cell nearest world `(x, y)` (the cell holding it, or the edge cell beside it).
fn clamp_cell(grid: &Grid, x: f64, y: f64) -> (usize, usize) {
    let (px, py) = grid.transform.world_to_pixel(x, y);
    let clamp = |p: f64, n: usize| (p.floor().max(0.0) as usize).min(n - 1);
    (clamp(px, grid.width), clamp(py, grid.height))
}
