//! Level-0 merge: what stands on the terrain — raised buildings and placed voxel objects.
//!
//! Invariant: a [`Raised`] set holds at most one [`RaisedCell`] per grid cell, sorted by cell
//! index, and only cells whose top is above valid terrain (a building or object over a DEM hole
//! stays a hole: nodata never becomes data). Each cell's column is a list of solid runs (case 3
//! of the Hughes patent: the height field plus voxels above it): the **ground run** from `−inf`
//! up to the terrain or to the top of whatever stands on it without a gap, then any floating
//! runs, sorted, apart, merged where they touch. A cell is **partial** exactly when it has a
//! floating run (a hole or an overhang), and then [`Raised::runs`] holds its runs; otherwise it
//! is an opaque column from the ground to `top_z`. Merging into level 0 is then a per-cell
//! rule: `max_z = top_z` (the last run's top), the state partial or opaque, and the colour of an
//! object cell is its top voxel's (the orthophoto never saw objects placed afterwards), while a
//! building cell keeps the photo's roof colour.
//!
//! * Buildings are prisms (GeoJSON polygons with an absolute `roof_z` in metres, the
//!   `buildings` layer that `dbms shadow-height --apply` writes), flat-roofed or pitched
//!   (gable, hip, shed: [`crate::roof`], whose `roof_z` is the ridge): a cell is inside when its
//!   **centre** is inside the polygon (even-odd rule, so holes work), like `gdal_rasterize`.
//!   A building cell is one piece from the ground to the roof at the cell's centre
//!   ([`RoofShape::z_at`]; `roof_z` everywhere for a flat roof), so a pitched roof's columns
//!   rise from the eaves to the ridge, and shading, cast shadows and the pyramid see its
//!   slopes through the cells alone.
//! * A voxel object marks every cell whose centre lies inside one of its voxels' footprints (the
//!   voxel's square rotated by the heading), and always the cell holding the voxel's centre, so
//!   voxels smaller than a cell are not lost. Each voxel is a piece `[bottom, top]` in every
//!   cell it marks; a voxel starting within half a voxel of the ground stands on it (joins the
//!   ground run), one starting higher floats (an overhang). Voxels and runs wholly at or below
//!   the ground are buried and dropped.
//! * Sources combine by [`Raised::union`]: the union of their pieces per cell, so a lintel over
//!   a taller roof disappears into it and a lintel above a roof leaves a gap.

use crate::db::{Database, PlacedObject};
use crate::error::{Error, Result};
use crate::grid::Grid;
use crate::raster::{Elevation, RowSource};
use crate::roof::{self, Pitch, RoofShape};
use crate::voxel::object::VoxelObject;
use rayon::prelude::*;
use std::collections::BTreeMap;
use std::ops::Range;
use std::path::Path;
use std::sync::Arc;

/// The terrain height of a cell by row-major index (metres, NaN = nodata), for the cells
/// something stands on: a whole raster in memory, or a [`TerrainSample`] of just those cells.
pub trait TerrainAt: Sync {
    /// Height of cell `index`. Panics for a cell the source does not hold (a programming error).
    fn at(&self, index: usize) -> f32;
}

impl TerrainAt for Elevation {
    fn at(&self, index: usize) -> f32 {
        self.data[index]
    }
}

/// A layer's values at selected cells, read band by band from a [`RowSource`]: what raising
/// needs of the terrain, and the mesh export of the photo under each roof, when the layer is
/// too large to hold. Sorted by index, one entry per cell.
pub struct CellSample<T> {
    cells: Vec<(usize, T)>,
}

/// The terrain heights of selected cells (metres, NaN = nodata).
pub type TerrainSample = CellSample<f32>;

impl<T: Clone> CellSample<T> {
    /// Sample `layer` at `indices` (any order, repeats allowed), reading only the bands of
    /// `band_rows` rows that hold one of them.
    pub fn read(
        layer: &dyn RowSource<T>,
        mut indices: Vec<usize>,
        band_rows: usize,
    ) -> Result<CellSample<T>> {
        indices.par_sort_unstable();
        indices.dedup();
        let (w, h) = (layer.grid().width, layer.grid().height);
        let band_rows = band_rows.max(1);
        let mut cells = Vec::with_capacity(indices.len());
        for chunk in indices.chunk_by(|a, b| a / w / band_rows == b / w / band_rows) {
            let row0 = chunk[0] / w / band_rows * band_rows;
            let rows = layer.read_rows(row0, band_rows.min(h - row0))?;
            cells.extend(chunk.iter().map(|&i| (i, rows[i - row0 * w].clone())));
        }
        Ok(CellSample { cells })
    }

    /// The value of cell `index`. Panics for a cell not sampled (a programming error).
    pub fn get(&self, index: usize) -> &T {
        let k = self
            .cells
            .binary_search_by_key(&index, |c| c.0)
            .expect("the cell was sampled");
        &self.cells[k].1
    }
}

impl TerrainAt for TerrainSample {
    fn at(&self, index: usize) -> f32 {
        *self.get(index)
    }
}

/// One level-0 cell with something standing on it: the summary of its column.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RaisedCell {
    /// Row-major cell index in the database grid.
    pub index: usize,
    /// Top of the column, metres (above the terrain height of the cell).
    pub top_z: f32,
    /// Colour of the top surface when it is not the photo's (objects); `None` keeps the photo's.
    pub colour: Option<[u8; 4]>,
    /// True when the column has holes or overhangs (state partial; [`Raised::runs`] has its
    /// runs). Output only: [`Raised::new`] takes its cells as solid columns and ignores it.
    pub partial: bool,
}

/// One solid run of a column as the merge knows it, absolute metres; the first run of a column
/// is the ground (bottom `−inf`). It becomes the tile format's
/// [`Run`](crate::voxel::columns::Run) once the photo's colour is known.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RaisedRun {
    /// Bottom, metres; `−inf` = from the ground.
    pub bottom: f32,
    /// Top, metres.
    pub top: f32,
    /// Colour of the run's highest piece; `None` = the orthophoto's colour (terrain, roofs).
    pub colour: Option<[u8; 4]>,
}

/// A solid piece a source puts in a cell, `bottom ..= top` metres (bottom `−inf`: from the
/// ground), before merging.
#[derive(Debug, Clone, Copy)]
struct Piece {
    index: usize,
    bottom: f32,
    top: f32,
    colour: Option<[u8; 4]>,
}

/// The raised cells of a database grid, sorted by index, one per cell, and the runs of the
/// partial ones.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Raised {
    cells: Vec<RaisedCell>,
    /// `(index, runs)` of exactly the partial cells, sorted by index; the runs obey
    /// [`crate::voxel::columns::check_runs`] (ground run first, then apart and ascending).
    columns: Vec<(usize, Vec<RaisedRun>)>,
}

impl Raised {
    /// Cells from any sources, each a solid column from the ground to its `top_z`: per cell the
    /// highest top wins (with its colour). Cells not above valid terrain are dropped.
    pub fn new(cells: Vec<RaisedCell>, terrain: &impl TerrainAt) -> Raised {
        let pieces = cells
            .into_iter()
            .map(|c| Piece {
                index: c.index,
                bottom: f32::NEG_INFINITY,
                top: c.top_z,
                colour: c.colour,
            })
            .collect();
        Raised::merge(pieces, terrain)
    }

    /// The placed voxel objects rasterised (see the module doc for footprints and the ground
    /// tolerance) and merged per cell into runs.
    ///
    /// Merged one band of [`OBJECT_BAND_ROWS`] rows at a time, each from the objects that can
    /// reach it: the pieces of every object at once are 24 bytes per voxel and cell it marks,
    /// gigabytes for a forest. A cell's runs depend only on its own pieces, all of which fall
    /// in its band, so the result is the same as one merge of everything.
    pub fn objects(grid: &Grid, objects: &[PlacedVoxels], terrain: &impl TerrainAt) -> Raised {
        let w = grid.width;
        let reach: Vec<Range<usize>> = objects.iter().map(|o| object_rows(grid, o)).collect();
        let mut out = Raised::default();
        for row0 in (0..grid.height).step_by(OBJECT_BAND_ROWS) {
            let rows = row0..(row0 + OBJECT_BAND_ROWS).min(grid.height);
            let (a, b) = (rows.start * w, rows.end * w);
            let pieces: Vec<Piece> = objects
                .iter()
                .zip(&reach)
                .filter(|(_, r)| r.start < rows.end && rows.start < r.end)
                .flat_map(|(o, _)| object_pieces(grid, o, terrain))
                .filter(|p| (a..b).contains(&p.index))
                .collect();
            if pieces.is_empty() {
                continue;
            }
            let band = Raised::merge(pieces, terrain);
            out.cells.extend(band.cells);
            out.columns.extend(band.columns);
        }
        out
    }

    /// Everything of `self` and `other` in one set: per cell the union of their solid runs.
    pub fn union(&self, other: &Raised, terrain: &impl TerrainAt) -> Raised {
        let mut pieces = self.pieces();
        pieces.extend(other.pieces());
        Raised::merge(pieces, terrain)
    }

    /// The solid pieces this set is made of (a ground run only as high as the terrain is
    /// dropped again by merging: the merge adds it back).
    fn pieces(&self) -> Vec<Piece> {
        let mut out = Vec::with_capacity(self.cells.len());
        let mut cols = self.columns.iter().peekable();
        for c in &self.cells {
            match cols.next_if(|(i, _)| *i == c.index) {
                Some((index, runs)) => out.extend(runs.iter().map(|r| Piece {
                    index: *index,
                    bottom: r.bottom,
                    top: r.top,
                    colour: r.colour,
                })),
                None => out.push(Piece {
                    index: c.index,
                    bottom: f32::NEG_INFINITY,
                    top: c.top_z,
                    colour: c.colour,
                }),
            }
        }
        out
    }

    /// Merge pieces per cell into runs: pieces over a nodata cell or not above its ground are
    /// dropped, a piece reaching down to the ground joins the ground run, overlapping or
    /// touching pieces join (a run's colour is its highest piece's; ties: the last in the sort
    /// by bottom, top, colour). Heights are compared as the `f32` they are stored as, so runs
    /// that touch in storage are always merged.
    fn merge(mut pieces: Vec<Piece>, terrain: &impl TerrainAt) -> Raised {
        pieces.retain(|p| {
            let g = terrain.at(p.index);
            !g.is_nan() && p.top > g
        });
        for p in &mut pieces {
            if p.bottom <= terrain.at(p.index) {
                p.bottom = f32::NEG_INFINITY;
            }
        }
        pieces.par_sort_by(|a, b| {
            (a.index.cmp(&b.index))
                .then(a.bottom.total_cmp(&b.bottom))
                .then(a.top.total_cmp(&b.top))
                .then(a.colour.cmp(&b.colour))
        });
        let merged: Vec<(RaisedCell, Option<Vec<RaisedRun>>)> = pieces
            .par_chunk_by(|a, b| a.index == b.index)
            .map(|col| {
                let index = col[0].index;
                let ground = RaisedRun {
                    bottom: f32::NEG_INFINITY,
                    top: terrain.at(index),
                    colour: None,
                };
                let mut runs = vec![ground];
                for p in col {
                    let last = runs.last_mut().expect("the ground run");
                    if p.bottom <= last.top {
                        if p.top >= last.top {
                            (last.top, last.colour) = (p.top, p.colour);
                        }
                    } else {
                        runs.push(RaisedRun {
                            bottom: p.bottom,
                            top: p.top,
                            colour: p.colour,
                        });
                    }
                }
                let top = *runs.last().expect("the ground run");
                let partial = runs.len() > 1;
                let cell = RaisedCell {
                    index,
                    top_z: top.top,
                    colour: top.colour,
                    partial,
                };
                (cell, partial.then_some(runs))
            })
            .collect();
        let mut out = Raised::default();
        for (cell, runs) in merged {
            if let Some(runs) = runs {
                out.columns.push((cell.index, runs));
            }
            out.cells.push(cell);
        }
        out
    }

    /// The runs of partial cell `index`, ground first; `None` for a solid column or no cell.
    pub fn runs(&self, index: usize) -> Option<&[RaisedRun]> {
        let k = self.columns.binary_search_by_key(&index, |c| c.0).ok()?;
        Some(&self.columns[k].1)
    }

    /// Number of raised cells.
    pub fn len(&self) -> usize {
        self.cells.len()
    }

    /// True when nothing is raised.
    pub fn is_empty(&self) -> bool {
        self.cells.is_empty()
    }

    /// Every raised cell, sorted by index.
    pub fn cells(&self) -> &[RaisedCell] {
        &self.cells
    }

    /// Whether cell `index` is raised.
    pub fn contains(&self, index: usize) -> bool {
        self.cells.binary_search_by_key(&index, |c| c.index).is_ok()
    }

    /// The raised cells with index in `start..end`, sorted.
    pub fn range(&self, start: usize, end: usize) -> &[RaisedCell] {
        let a = self.cells.partition_point(|c| c.index < start);
        let b = self.cells.partition_point(|c| c.index < end);
        &self.cells[a..b]
    }

    /// Lay the raised cells of the row starting at cell `start` over its terrain `heights`
    /// (their tops replace the terrain): the overlay of [`crate::shadow::ShadowBits::cast`].
    pub fn lay_over(&self, start: usize, heights: &mut [f32]) {
        for c in self.range(start, start + heights.len()) {
            heights[c.index - start] = c.top_z;
        }
    }

    /// The raised cell at `index`, if any.
    pub fn get(&self, index: usize) -> Option<&RaisedCell> {
        self.range(index, index + 1).first()
    }

    /// The unit upward normal `[east, north, up]` of the tops at raised cell `index` on `grid`
    /// ([`crate::raster::normal_from`]): a pitched roof's face, from the neighbouring raised
    /// cells whose top lies within [`roof::MAX_PITCH_DEG`] of this one's over the cell
    /// between them. A steeper drop or rise is a wall (an eave over the ground, a neighbour's
    /// taller roof), not part of this face, so a flat roof is level up to its edges.
    pub fn top_normal(&self, grid: &Grid, index: usize) -> [f64; 3] {
        let Some(here) = self.get(index).map(|c| f64::from(c.top_z)) else {
            return [0.0, 0.0, 1.0];
        };
        let (dx, dy) = grid.cell_size();
        let steepest = roof::MAX_PITCH_DEG.to_radians().tan() * dx.min(dy);
        crate::raster::normal_from(grid, index, |c, r| {
            let z = f64::from(self.get(r * grid.width + c)?.top_z);
            ((z - here).abs() <= steepest).then_some(z)
        })
    }

    /// The terrain with every raised cell at its top: the surface shadows are cast over.
    pub fn heights(&self, terrain: &Elevation) -> Elevation {
        let mut h = terrain.clone();
        for c in &self.cells {
            h.data[c.index] = c.top_z;
        }
        h
    }
}

/// A prism: a polygon (outer ring and holes, CRS units) raised to its roof, flat or pitched.
#[derive(Debug, Clone, PartialEq)]
pub struct Prism {
    /// Rings of `(x, y)` vertices; the even-odd rule decides inside, so holes are just rings.
    pub rings: Vec<Vec<(f64, f64)>>,
    /// The roof: its top (`roof_z`, absolute metres: the ridge of a pitched roof) and pitch,
    /// over the extent of the whole feature (every part of a MultiPolygon).
    pub roof: RoofShape,
}

/// Read the `buildings` layer: a GeoJSON FeatureCollection of Polygon / MultiPolygon features
/// in the database CRS, each with a numeric `roof_z` property (absolute metres: the top of the
/// roof) and, for a pitched roof, `roof_form`, `eave_z` and `roof_azimuth_deg` together
/// ([`crate::roof::Pitch::from_properties`]). A MultiPolygon is a prism per part, all under
/// one roof.
pub fn read_buildings(path: &Path) -> Result<Vec<Prism>> {
    let features = crate::geojson::read_features(path, "re-run `dbms shadow-height --apply`")?;
    let mut prisms = Vec::new();
    for (i, f) in features.iter().enumerate() {
        let bad = |what: &str| {
            Error::file(path, format!("feature {i}: {what}"))
                .fix("each building needs a Polygon or MultiPolygon and a numeric roof_z")
        };
        let roof_z = f
            .pointer("/properties/roof_z")
            .and_then(|v| v.as_f64())
            .ok_or_else(|| bad("no numeric roof_z property"))?;
        if !roof_z.is_finite() {
            return Err(bad("roof_z is not finite"));
        }
        let pitch = Pitch::from_properties(&f["properties"], roof_z).map_err(|e| {
            Error::file(path, format!("feature {i}: {e}")).fix(format!(
                "a pitched roof states {}, {} (metres, at most roof_z) and {} (degrees) \
                 together; leave {} out for a flat roof",
                roof::property::FORM,
                roof::property::EAVE_Z,
                roof::property::AZIMUTH,
                roof::property::FORM
            ))
        })?;
        let geometry = f.get("geometry").ok_or_else(|| bad("no geometry"))?;
        let parts = crate::geojson::polygons(geometry).map_err(|e| bad(&e))?;
        let outline: Vec<Vec<(f64, f64)>> = parts.iter().flatten().cloned().collect();
        let roof = RoofShape::new(&outline, roof_z, pitch);
        prisms.extend(parts.into_iter().map(|rings| Prism { rings, roof }));
    }
    Ok(prisms)
}

/// The cells of `grid` whose centres are inside each prism ([`polygon_cells`]), raised to its
/// roof at the cell's centre ([`RoofShape::z_at`]: a pitched roof's columns rise with it),
/// opaque, photo colour.
pub fn rasterise_prisms(grid: &Grid, prisms: &[Prism]) -> Vec<RaisedCell> {
    prisms
        .par_iter()
        .flat_map_iter(|prism| {
            polygon_cells(grid, &prism.rings)
                .into_iter()
                .map(|index| RaisedCell {
                    index,
                    top_z: prism
                        .roof
                        .z_at(grid.cell_centre(index % grid.width, index / grid.width))
                        as f32,
                    colour: None,
                    partial: false,
                })
        })
        .collect()
}

/// The indices of the cells of `grid` whose centres are inside the polygon `rings` (CRS units;
/// even-odd rule, so holes are just rings), row by row. Scanline fill per row: the crossings of
/// every ring edge with the row's centre line, sorted, filled pairwise; a centre exactly on a
/// left edge is inside, on a right edge outside.
pub fn polygon_cells(grid: &Grid, rings: &[Vec<(f64, f64)>]) -> Vec<usize> {
    let mut out = Vec::new();
    let t = &grid.transform;
    // Only the rows the polygon's y extent can reach.
    let ys = rings.iter().flatten().map(|p| p.1);
    let (y_lo, y_hi) = ys.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), y| {
        (a.min(y), b.max(y))
    });
    let (p0, p1) = (
        grid.transform.world_to_pixel(0.0, y_lo).1,
        grid.transform.world_to_pixel(0.0, y_hi).1,
    );
    let first = (p0.min(p1).floor().max(0.0) as usize).min(grid.height);
    let last = (p0.max(p1).ceil().max(0.0) as usize).min(grid.height);
    let mut xs: Vec<f64> = Vec::new();
    for row in first..last {
        let y = t.origin_y + (row as f64 + 0.5) * t.cell_y;
        xs.clear();
        for ring in rings {
            for (k, &(x0, y0)) in ring.iter().enumerate() {
                let (x1, y1) = ring[(k + 1) % ring.len()];
                // Half-open in y so a vertex on the line is counted once.
                if (y0 <= y) != (y1 <= y) {
                    xs.push(x0 + (y - y0) / (y1 - y0) * (x1 - x0));
                }
            }
        }
        xs.sort_by(f64::total_cmp);
        for pair in xs.chunks_exact(2) {
            // Columns whose centre x is in [pair[0], pair[1]).
            let c0 = ((pair[0] - t.origin_x) / t.cell_x - 0.5).ceil().max(0.0) as usize;
            let c1 = ((pair[1] - t.origin_x) / t.cell_x - 0.5)
                .ceil()
                .clamp(0.0, grid.width as f64) as usize;
            out.extend((c0..c1.max(c0)).map(|col| grid.index(col, row)));
        }
    }
    out
}

/// A voxel object placed in the world: cubic voxels of `voxel_size` metres at local centres
/// `(u, v, w)` (metres; u right, v forward, w up), the local origin at world `origin`, the
/// object's +v axis pointing `heading_deg` clockwise from north.
#[derive(Debug, Clone, PartialEq)]
pub struct PlacedVoxels {
    /// World position of the local origin (CRS units; z metres, absolute).
    pub origin: [f64; 3],
    /// Degrees clockwise from north of the object's +v axis.
    pub heading_deg: f64,
    /// Voxel edge, metres (scaled).
    pub voxel_size: f64,
    /// Occupied voxels: centre relative to the local origin before scaling (metres) and RGB
    /// colour; one list shared by every placement of an object ([`anchored_voxels`]).
    pub voxels: Arc<[([f64; 3], [u8; 3])]>,
    /// Factor on the voxels' offsets ([`PlacedVoxels::local`]).
    pub scale: f64,
}

impl PlacedVoxels {
    /// The local centre (metres) of a voxel at `offset` from the origin: scaled.
    #[inline]
    pub fn local(&self, offset: [f64; 3]) -> [f64; 3] {
        offset.map(|d| d * self.scale)
    }
}

/// An object's voxels relative to its anchor (the centre of its grid's bottom face, which
/// `dbms place` puts at the placement point), metres, with their colours: what every placement
/// of the object shares.
pub fn anchored_voxels(obj: &VoxelObject) -> Arc<[([f64; 3], [u8; 3])]> {
    let a = obj.anchor();
    obj.voxels()
        .map(|([x, y, z], rgb)| {
            let c = obj.grid.centre(x, y, z);
            ([c[0] - a[0], c[1] - a[1], c[2] - a[2]], rgb)
        })
        .collect()
}

/// A placed object's voxels (`anchored`: [`anchored_voxels`] of `obj`) scaled about its anchor
/// by the placement's `scale`: local centres in metres, world origin in CRS units with z in
/// metres.
pub fn placed_voxels(
    obj: &VoxelObject,
    anchored: &Arc<[([f64; 3], [u8; 3])]>,
    placed: &PlacedObject,
) -> PlacedVoxels {
    PlacedVoxels {
        origin: [placed.x, placed.y, placed.z],
        heading_deg: placed.heading_deg,
        voxel_size: obj.grid.voxel_size * placed.scale,
        voxels: anchored.clone(),
        scale: placed.scale,
    }
}

/// Placements with the cells each marks, in manifest order ([`Standing::read_placed`]).
pub type Marked<'a> = Vec<(&'a PlacedObject, Vec<usize>)>;

/// What stands on a database's terrain: the buildings of its `buildings` layer (when it has
/// one) and its placed voxel objects, each merged, and both together. The surface shadows are
/// cast over is the terrain with `all` laid over it.
pub struct Standing {
    /// Raised buildings (prisms, each cell at its roof).
    pub buildings: Raised,
    /// Placed voxel objects.
    pub objects: Raised,
    /// Their union.
    pub all: Raised,
}

impl Standing {
    /// Read the database's buildings and objects and raise them over `terrain` (metres, NaN =
    /// nodata), sampled only under them, in bands of `band_rows` rows. Errors name the
    /// buildings layer or object file that cannot be read.
    pub fn read(db: &Database, terrain: &dyn RowSource<f32>, band_rows: usize) -> Result<Standing> {
        let g = terrain.grid();
        Standing::read_window(db, terrain, band_rows, 0..g.height, 0..g.width)
    }

    /// [`read`](Self::read) for the cells of grid rows `rows` and columns `cols`: there, cell
    /// for cell what the whole read gives (placed objects outside may be missing). Only the
    /// placements whose footprint can reach the window ([`reaches`]) are rasterised, each
    /// object file read once however often it is placed, and only the buildings whose box meets
    /// it (a caller whose results depend on roofs farther away, as the photo's shadow detector's
    /// do within [`crate::pyramid::shade::DETECTION_REACH`], widens the window).
    pub fn read_window(
        db: &Database,
        terrain: &dyn RowSource<f32>,
        band_rows: usize,
        rows: Range<usize>,
        cols: Range<usize>,
    ) -> Result<Standing> {
        Ok(Standing::read_placed(db, terrain, band_rows, rows, cols)?.0)
    }

    /// [`read_window`](Self::read_window), and each placement it rasterised (manifest order)
    /// with the cells it marks ([`object_cells`]; its own, before the merge drops cells over
    /// nodata terrain): for a caller that needs to tell the objects apart.
    pub fn read_placed<'a>(
        db: &'a Database,
        terrain: &dyn RowSource<f32>,
        band_rows: usize,
        rows: Range<usize>,
        cols: Range<usize>,
    ) -> Result<(Standing, Marked<'a>)> {
        let grid = terrain.grid();
        let prism_cells = match db.manifest.layers.contains_key(crate::db::BUILDINGS) {
            true => {
                let mut prisms = read_buildings(&db.layer_path(crate::db::BUILDINGS)?)?;
                prisms.retain(|p| reaches_window(grid, p, &rows, &cols));
                rasterise_prisms(grid, &prisms)
            }
            false => Vec::new(),
        };
        let (placements, placed): (Vec<&PlacedObject>, Vec<PlacedVoxels>) =
            placed_objects(db, grid, &rows, &cols)?.into_iter().unzip();
        let marked: Vec<Vec<usize>> = placed.iter().map(|o| object_cells(grid, o)).collect();
        let mut under: Vec<usize> = prism_cells.iter().map(|c| c.index).collect();
        marked.iter().for_each(|cells| under.extend(cells));
        let ground = TerrainSample::read(terrain, under, band_rows)?;
        let buildings = Raised::new(prism_cells, &ground);
        let objects = Raised::objects(grid, &placed, &ground);
        let all = buildings.union(&objects, &ground);
        let standing = Standing {
            buildings,
            objects,
            all,
        };
        Ok((standing, placements.into_iter().zip(marked).collect()))
    }
}

/// The database's placements, in the manifest's order, whose footprint can reach grid rows
/// `rows` and columns `cols` ([`reaches`]), each with its voxels placed; each object file is
/// read once however often it is placed.
fn placed_objects<'a>(
    db: &'a Database,
    grid: &Grid,
    rows: &Range<usize>,
    cols: &Range<usize>,
) -> Result<Vec<(&'a PlacedObject, PlacedVoxels)>> {
    type Read = (VoxelObject, Arc<[([f64; 3], [u8; 3])]>, f64);
    let mut files: BTreeMap<&str, Read> = BTreeMap::new();
    let mut placed = Vec::new();
    for p in &db.manifest.objects {
        if !files.contains_key(p.file.as_str()) {
            let (obj, _) = crate::voxel::format::read(&db.dir.join(&p.file))?;
            let (anchored, reach) = (anchored_voxels(&obj), object_reach(&obj));
            files.insert(&p.file, (obj, anchored, reach));
        }
        let (obj, anchored, reach) = &files[p.file.as_str()];
        if reaches(grid, [p.x, p.y], reach * p.scale, rows, cols) {
            placed.push((p, placed_voxels(obj, anchored, p)));
        }
    }
    Ok(placed)
}

/// How far (metres) the cells an object marks can lie from its anchor, horizontally: its
/// farthest voxel centre plus half a voxel's diagonal (times the placement's scale).
pub fn object_reach(obj: &VoxelObject) -> f64 {
    let a = obj.anchor();
    let far = obj.voxels().fold(0.0f64, |far, ([x, y, z], _)| {
        let c = obj.grid.centre(x, y, z);
        far.max((c[0] - a[0]).hypot(c[1] - a[1]))
    });
    far + obj.grid.voxel_size * std::f64::consts::FRAC_1_SQRT_2
}

/// Whether something within `reach` metres of world point `[x, y]` can mark a cell of grid
/// rows `rows` and columns `cols` (a cell of margin on every side for rounding).
pub fn reaches(
    grid: &Grid,
    [x, y]: [f64; 2],
    reach: f64,
    rows: &Range<usize>,
    cols: &Range<usize>,
) -> bool {
    let [c0, r0, c1, r1] = box_cells(grid, [x - reach, y - reach, x + reach, y + reach]);
    r0 < rows.end && rows.start < r1 && c0 < cols.end && cols.start < c1
}

/// Whether building `prism` can mark a cell of grid rows `rows` and columns `cols`: its
/// bounding box's cells ([`box_cells`], a cell of margin each side) meet them.
fn reaches_window(grid: &Grid, prism: &Prism, rows: &Range<usize>, cols: &Range<usize>) -> bool {
    let pts = prism.rings.iter().flatten();
    let b = pts.fold([f64::MAX, f64::MAX, f64::MIN, f64::MIN], |b, &(x, y)| {
        [b[0].min(x), b[1].min(y), b[2].max(x), b[3].max(y)]
    });
    let [c0, r0, c1, r1] = box_cells(grid, b);
    c0 < cols.end && cols.start < c1 && r0 < rows.end && rows.start < r1
}

/// The cells something inside the world box `[min_x, min_y, max_x, max_y]` can mark, with a
/// cell of margin on every side for rounding, clipped to the grid: `[col0, row0, col1, row1]`,
/// ends exclusive (empty when the box is off the grid).
pub fn box_cells(grid: &Grid, [x0, y0, x1, y1]: [f64; 4]) -> [usize; 4] {
    let t = &grid.transform;
    let (ca, cb) = ((x0 - t.origin_x) / t.cell_x, (x1 - t.origin_x) / t.cell_x);
    let (ra, rb) = ((y0 - t.origin_y) / t.cell_y, (y1 - t.origin_y) / t.cell_y);
    let clip = |v: f64, n: usize| v.clamp(0.0, n as f64) as usize;
    [
        clip(ca.min(cb).floor() - 1.0, grid.width),
        clip(ra.min(rb).floor() - 1.0, grid.height),
        clip(ca.max(cb).floor() + 2.0, grid.width),
        clip(ra.max(rb).floor() + 2.0, grid.height),
    ]
}

/// The cells an object marks (see the module doc for the footprint), sorted: the cells whose
/// terrain [`Raised::objects`] needs.
pub fn object_cells(grid: &Grid, obj: &PlacedVoxels) -> Vec<usize> {
    let mut cells: Vec<usize> = obj
        .voxels
        .par_iter()
        .flat_map_iter(|v| voxel_cells(grid, obj, obj.local(v.0)))
        .collect();
    cells.par_sort_unstable();
    cells.dedup();
    cells
}

/// The pieces an object puts in the cells it stands on: one per voxel and cell, its bottom
/// dropped to the ground when within half a voxel of it.
fn object_pieces(grid: &Grid, obj: &PlacedVoxels, terrain: &impl TerrainAt) -> Vec<Piece> {
    let half = obj.voxel_size / 2.0;
    obj.voxels
        .par_iter()
        .flat_map_iter(|&(offset, [r, g, b])| {
            let local = obj.local(offset);
            let (bottom, top) = (
                obj.origin[2] + local[2] - half,
                obj.origin[2] + local[2] + half,
            );
            voxel_cells(grid, obj, local).into_iter().map(move |index| {
                let grounded = bottom <= terrain.at(index) as f64 + half;
                Piece {
                    index,
                    bottom: if grounded {
                        f32::NEG_INFINITY
                    } else {
                        bottom as f32
                    },
                    top: top as f32,
                    colour: Some([r, g, b, 255]),
                }
            })
        })
        .collect()
}

/// Rows per band in which [`Raised::objects`] merges placed objects' pieces.
pub const OBJECT_BAND_ROWS: usize = 256;

/// The grid rows (clipped to the grid) holding every cell `obj` can mark: its anchor's row
/// give or take its farthest voxel centre plus half a voxel's diagonal, and a row of margin.
fn object_rows(grid: &Grid, obj: &PlacedVoxels) -> Range<usize> {
    let far = obj.voxels.iter().fold(0.0f64, |far, (d, _)| {
        let l = obj.local(*d);
        far.max(l[0].hypot(l[1]))
    });
    let reach = far + obj.voxel_size * std::f64::consts::FRAC_1_SQRT_2;
    let [x, y] = [obj.origin[0], obj.origin[1]];
    let [_, r0, _, r1] = box_cells(grid, [x - reach, y - reach, x + reach, y + reach]);
    r0..r1
}

/// The cells one voxel (local centre `[u, v, _]`) marks: the cell holding its centre and every
/// cell whose centre lies in its footprint rotated by the heading; sorted, no repeats.
fn voxel_cells(grid: &Grid, obj: &PlacedVoxels, [u, v, _]: [f64; 3]) -> Vec<usize> {
    let (s, c) = obj.heading_deg.to_radians().sin_cos();
    let half = obj.voxel_size / 2.0;
    // Local u → world (cos h, −sin h); local v → world (sin h, cos h).
    let (wx, wy) = (obj.origin[0] + u * c + v * s, obj.origin[1] - u * s + v * c);
    let mut cells: Vec<usize> = Vec::new();
    if let Some((col, row)) = grid.cell_at(wx, wy) {
        cells.push(grid.index(col, row));
    }
    // Cells whose centre lies in the rotated footprint: scan its bounding box.
    let rad = half * std::f64::consts::SQRT_2;
    let (px0, py0) = grid.transform.world_to_pixel(wx - rad, wy + rad);
    let (px1, py1) = grid.transform.world_to_pixel(wx + rad, wy - rad);
    let lo = |a: f64, b: f64| (a.min(b) - 0.5).ceil().max(0.0) as usize;
    let hi =
        |a: f64, b: f64, n: usize| ((a.max(b) - 0.5).floor() + 1.0).clamp(0.0, n as f64) as usize;
    for row in lo(py0, py1)..hi(py0, py1, grid.height) {
        for col in lo(px0, px1)..hi(px0, px1, grid.width) {
            let (x, y) = grid.cell_centre(col, row);
            let (dx, dy) = (x - wx, y - wy);
            // Back into the object's frame: u = dx·cos h − dy·sin h, v = dx·sin h + dy·cos h.
            let (lu, lv) = (dx * c - dy * s, dx * s + dy * c);
            if lu.abs() <= half && lv.abs() <= half {
                cells.push(grid.index(col, row));
            }
        }
    }
    cells.sort_unstable();
    cells.dedup();
    cells
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::crs::Crs;

    fn flat(w: usize, h: usize, z: f32) -> Elevation {
        Elevation::filled(Grid::north_up(0.0, h as f64, 1.0, w, h, Crs::unknown()), z)
    }

    fn square(x0: f64, y0: f64, x1: f64, y1: f64) -> Vec<(f64, f64)> {
        vec![(x0, y0), (x1, y0), (x1, y1), (x0, y1), (x0, y0)]
    }

    #[test]
    fn prism_covers_the_cells_whose_centres_are_inside_and_holes_stay_terrain() {
        let t = flat(10, 10, 100.0);
        // 2..8 × 2..8 with a hole 4..6 × 4..6: 36 − 4 = 32 cells.
        let p = Prism {
            rings: vec![square(2.0, 2.0, 8.0, 8.0), square(4.0, 4.0, 6.0, 6.0)],
            roof: crate::roof::RoofShape::flat(110.0),
        };
        let raised = Raised::new(rasterise_prisms(&t.grid, &[p]), &t);
        assert_eq!(raised.len(), 32);
        // Cell (2, 2) has centre (2.5, 7.5): inside. Cell (4, 4) centre (4.5, 5.5): in the hole.
        assert_eq!(raised.get(t.grid.index(2, 2)).unwrap().top_z, 110.0);
        assert!(raised.get(t.grid.index(4, 4)).is_none());
        assert!(raised.get(t.grid.index(1, 2)).is_none());
        let h = raised.heights(&t);
        assert_eq!(h.data.iter().filter(|&&z| z == 110.0).count(), 32);
    }

    #[test]
    fn buried_roofs_and_nodata_terrain_are_not_raised() {
        let mut t = flat(4, 4, 100.0);
        t.data[5] = f32::NAN;
        let low = Prism {
            rings: vec![square(0.0, 0.0, 4.0, 4.0)],
            roof: crate::roof::RoofShape::flat(99.0),
        };
        assert!(Raised::new(rasterise_prisms(&t.grid, &[low]), &t).is_empty());
        let high = Prism {
            rings: vec![square(0.0, 0.0, 4.0, 4.0)],
            roof: crate::roof::RoofShape::flat(101.0),
        };
        let r = Raised::new(rasterise_prisms(&t.grid, &[high]), &t);
        assert_eq!(r.len(), 15);
        assert!(r.get(5).is_none());
    }

    #[test]
    fn overlapping_sources_keep_the_highest_top() {
        let t = flat(4, 4, 0.0);
        let a = Prism {
            rings: vec![square(0.0, 0.0, 3.0, 3.0)],
            roof: crate::roof::RoofShape::flat(5.0),
        };
        let b = Prism {
            rings: vec![square(1.0, 1.0, 4.0, 4.0)],
            roof: crate::roof::RoofShape::flat(9.0),
        };
        let r = Raised::new(rasterise_prisms(&t.grid, &[a, b]), &t);
        assert_eq!(r.get(t.grid.index(0, 3)).unwrap().top_z, 5.0);
        assert_eq!(r.get(t.grid.index(1, 2)).unwrap().top_z, 9.0);
        assert_eq!(r.len(), 9 + 9 - 4);
    }

    #[test]
    fn geojson_buildings_parse_and_bad_ones_name_the_feature() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("b.geojson");
        std::fs::write(&p, r#"{"type":"FeatureCollection","features":[
            {"type":"Feature","properties":{"id":1,"roof_z":12.5},"geometry":{"type":"Polygon","coordinates":[[[0,0],[2,0],[2,2],[0,0]]]}},
            {"type":"Feature","properties":{"roof_z":3},"geometry":{"type":"MultiPolygon","coordinates":[[[[0,0],[1,0],[1,1],[0,0]]],[[[5,5],[6,5],[6,6],[5,5]]]]}}]}"#).unwrap();
        let b = read_buildings(&p).unwrap();
        assert_eq!(b.len(), 3);
        assert_eq!(b[0].roof, RoofShape::flat(12.5));
        assert_eq!(b[2].rings[0][0], (5.0, 5.0));
        std::fs::write(&p, r#"{"type":"FeatureCollection","features":[{"type":"Feature","properties":{},"geometry":{"type":"Polygon","coordinates":[]}}]}"#).unwrap();
        let e = read_buildings(&p).unwrap_err().to_string();
        assert!(
            e.contains("b.geojson") && e.contains("feature 0") && e.contains("roof_z"),
            "{e}"
        );
    }

    /// A gable roof 8 m wide (eaves 104, ridge 110 along the east–west centre line y = 5) on
    /// 1 m cells: each cell's column reaches the roof at its centre, exactly; the cells under
    /// the ridge are the highest, those by the eaves the lowest.
    #[test]
    fn a_pitched_roof_raises_each_cell_to_the_roof_at_its_centre() {
        let t = flat(12, 10, 100.0);
        let rings = vec![square(1.0, 1.0, 11.0, 9.0)];
        let pitch = Pitch {
            form: roof::RoofForm::Gable,
            eave_z: 104.0,
            azimuth_deg: 90.0,
        };
        let p = Prism {
            roof: RoofShape::new(&rings, 110.0, Some(pitch)),
            rings,
        };
        let raised = Raised::new(rasterise_prisms(&t.grid, &[p]), &t);
        assert_eq!(raised.len(), 80);
        for c in raised.cells() {
            let (_, y) = t.grid.cell_centre(c.index % 12, c.index / 12);
            // Across the ridge: 1.5 m of rise per metre from the centre line.
            let want = 110.0 - 1.5 * (y - 5.0).abs();
            assert_eq!(c.top_z, want as f32, "cell {}", c.index);
        }
        let top = |row: usize| raised.get(t.grid.index(5, row)).unwrap().top_z;
        // Rows 4 and 5 have centres half a metre from the ridge; rows 1 and 8 by the eaves.
        assert_eq!(
            (top(4), top(5), top(1), top(8)),
            (109.25, 109.25, 104.75, 104.75)
        );
    }

    /// A MultiPolygon's parts are one building under one roof: its extent spans both parts.
    /// A bad pitch names the file, the feature and the property.
    #[test]
    fn pitched_buildings_parse_under_one_roof_and_bad_pitches_name_the_property() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("b.geojson");
        std::fs::write(&p, r#"{"type":"FeatureCollection","features":[
            {"type":"Feature","properties":{"roof_z":12,"roof_form":"shed","eave_z":8,"roof_azimuth_deg":90},"geometry":{"type":"MultiPolygon","coordinates":[[[[0,0],[2,0],[2,2],[0,0]]],[[[6,0],[8,0],[8,2],[6,0]]]]}}]}"#).unwrap();
        let b = read_buildings(&p).unwrap();
        assert_eq!(b.len(), 2);
        assert_eq!(b[0].roof, b[1].roof);
        // Rising east over x 0..8: 0.5 m per metre, the parts on the same plane.
        assert_eq!(b[0].roof.z_at((0.0, 1.0)), 8.0);
        assert_eq!(b[1].roof.z_at((8.0, 1.0)), 12.0);
        assert_eq!(b[1].roof.z_at((6.0, 1.0)), 11.0);
        for (props, property) in [
            (
                r#""roof_form":"dome","eave_z":8,"roof_azimuth_deg":0"#,
                "roof_form",
            ),
            (r#""roof_form":"gable","roof_azimuth_deg":0"#, "eave_z"),
            (r#""roof_form":"hip","eave_z":8"#, "roof_azimuth_deg"),
            (
                r#""roof_form":"hip","eave_z":13,"roof_azimuth_deg":0"#,
                "eave_z",
            ),
        ] {
            std::fs::write(&p, format!(r#"{{"type":"FeatureCollection","features":[{{"type":"Feature","properties":{{"roof_z":12,{props}}},"geometry":{{"type":"Polygon","coordinates":[[[0,0],[2,0],[2,2],[0,0]]]}}}}]}}"#)).unwrap();
            let e = read_buildings(&p).unwrap_err().to_string();
            assert!(
                e.contains("b.geojson") && e.contains("feature 0") && e.contains(property),
                "{e}"
            );
            assert!(!e.contains('\n'), "one line: {e}");
        }
    }

    fn object(voxels: Vec<([f64; 3], [u8; 3])>, heading_deg: f64) -> PlacedVoxels {
        PlacedVoxels {
            origin: [5.0, 5.0, 100.0],
            heading_deg,
            voxel_size: 1.0,
            voxels: voxels.into(),
            scale: 1.0,
        }
    }

    #[test]
    fn solid_voxel_column_is_opaque_and_takes_the_top_voxel_colour() {
        let t = flat(10, 10, 100.0);
        // A 1×1×3 column centred on cell (5, 4) (centre x 5.5, y 5.5 → origin + (0.5, 0.5)).
        let vox = (0..3)
            .map(|k| ([0.5, 0.5, 0.5 + k as f64], [k as u8, 0, 0]))
            .collect();
        let r = Raised::objects(&t.grid, &[object(vox, 0.0)], &t);
        assert_eq!(r.len(), 1);
        let c = r.get(t.grid.index(5, 4)).unwrap();
        assert_eq!(
            (c.top_z, c.partial, c.colour),
            (103.0, false, Some([2, 0, 0, 255]))
        );
    }

    #[test]
    fn overhangs_and_holes_make_partial_cells() {
        let t = flat(10, 10, 100.0);
        // An arch: two legs (u = 0.5 and 2.5) and a lintel at w = 2.5 spanning u = 0.5..2.5.
        let mut vox = vec![([0.5, 0.5, 0.5], [1, 1, 1]), ([2.5, 0.5, 0.5], [1, 1, 1])];
        vox.extend((0..3).map(|u| ([0.5 + u as f64, 0.5, 2.5], [9, 9, 9])));
        let r = Raised::objects(&t.grid, &[object(vox, 0.0)], &t);
        assert_eq!(r.len(), 3);
        let leg = r.get(t.grid.index(5, 4)).unwrap();
        let gap = r.get(t.grid.index(6, 4)).unwrap();
        assert!(leg.partial, "leg column has a hole between w 1 and 2");
        assert!(gap.partial, "the lintel floats over the ground");
        assert_eq!((leg.top_z, gap.top_z), (103.0, 103.0));
        // The runs are exactly the voxels: the leg stands on the ground up to 101, the lintel
        // 102..103 floats; under the gap only the terrain (photo colour) is below the lintel.
        let run = |bottom: f32, top: f32, colour: Option<[u8; 4]>| RaisedRun {
            bottom,
            top,
            colour,
        };
        let ninf = f32::NEG_INFINITY;
        assert_eq!(
            r.runs(t.grid.index(5, 4)).unwrap(),
            &[
                run(ninf, 101.0, Some([1, 1, 1, 255])),
                run(102.0, 103.0, Some([9, 9, 9, 255]))
            ]
        );
        assert_eq!(
            r.runs(t.grid.index(6, 4)).unwrap(),
            &[
                run(ninf, 100.0, None),
                run(102.0, 103.0, Some([9, 9, 9, 255]))
            ]
        );
        assert!(r.runs(t.grid.index(4, 4)).is_none());
        for (i, runs) in r.columns.iter() {
            let as_runs: Vec<_> = runs
                .iter()
                .map(|x| crate::voxel::columns::Run {
                    bottom: x.bottom,
                    top: x.top,
                    colour: x.colour.unwrap_or([0, 0, 0, 255]),
                })
                .collect();
            crate::voxel::columns::check_runs(&as_runs).unwrap_or_else(|e| panic!("cell {i}: {e}"));
        }
    }

    #[test]
    fn stacked_voxels_merge_into_one_run_and_buried_ones_vanish() {
        let t = flat(10, 10, 100.0);
        // Cell (5, 4): voxels at w 2.5, 3.5 (touching: one run 102..104), 5.5 (apart), and
        // one at w −1.5 wholly underground.
        let vox = [2.5, 3.5, 5.5, -1.5]
            .map(|w| ([0.5, 0.5, w], [w as u8, 0, 0]))
            .to_vec();
        let r = Raised::objects(&t.grid, &[object(vox, 0.0)], &t);
        let runs = r.runs(t.grid.index(5, 4)).unwrap();
        let spans: Vec<_> = runs.iter().map(|x| (x.bottom, x.top)).collect();
        assert_eq!(
            spans,
            vec![(f32::NEG_INFINITY, 100.0), (102.0, 104.0), (105.0, 106.0)]
        );
        assert_eq!(
            runs[1].colour,
            Some([3, 0, 0, 255]),
            "a run takes its highest voxel's colour"
        );
    }

    #[test]
    fn union_with_a_building_fills_or_keeps_the_gap() {
        let t = flat(10, 10, 100.0);
        // A lintel 102..103 over cells (5..8, 4); a roof at (5, 4) up to 102.5 swallows the gap,
        // one at (7, 4) up to 101 leaves it (above the roof).
        let lintel = (0..3)
            .map(|u| ([0.5 + u as f64, 0.5, 2.5], [9, 9, 9]))
            .collect();
        let objects = Raised::objects(&t.grid, &[object(lintel, 0.0)], &t);
        let roofs = Raised::new(
            vec![
                RaisedCell {
                    index: t.grid.index(5, 4),
                    top_z: 102.5,
                    colour: None,
                    partial: false,
                },
                RaisedCell {
                    index: t.grid.index(7, 4),
                    top_z: 101.0,
                    colour: None,
                    partial: false,
                },
            ],
            &t,
        );
        let all = roofs.union(&objects, &t);
        assert_eq!(all.len(), 3);
        let a = all.get(t.grid.index(5, 4)).unwrap();
        assert_eq!(
            (a.partial, a.top_z, a.colour),
            (false, 103.0, Some([9, 9, 9, 255]))
        );
        let spans: Vec<_> = all
            .runs(t.grid.index(7, 4))
            .unwrap()
            .iter()
            .map(|x| (x.bottom, x.top, x.colour))
            .collect();
        assert_eq!(
            spans,
            vec![
                (f32::NEG_INFINITY, 101.0, None),
                (102.0, 103.0, Some([9, 9, 9, 255]))
            ]
        );
        assert_eq!(all.runs(t.grid.index(6, 4)).unwrap().len(), 2);
        // Union is idempotent: merging a set with itself changes nothing.
        assert_eq!(all.union(&all, &t), all);
    }

    #[test]
    fn heading_rotates_the_footprint_clockwise() {
        let t = flat(10, 10, 100.0);
        // A voxel 2 m along +v: heading 90° puts it 2 m east of the origin.
        let vox = vec![([0.0, 2.0, 0.5], [5, 5, 5])];
        let r = Raised::objects(&t.grid, &[object(vox, 90.0)], &t);
        let (col, row) = t.grid.cell_at(7.0 + 1e-9, 5.0 + 1e-9).unwrap();
        assert!(r.get(t.grid.index(col, row)).is_some(), "{:?}", r);
        assert!(r.range(0, 100).iter().all(|c| {
            let (cx, _) = t.grid.cell_centre(c.index % 10, c.index / 10);
            cx > 6.0
        }));
    }

    #[test]
    fn big_voxels_cover_several_cells() {
        let t = flat(10, 10, 100.0);
        let obj = PlacedVoxels {
            origin: [5.0, 5.0, 100.0],
            heading_deg: 0.0,
            voxel_size: 3.0,
            voxels: vec![([0.0, 0.0, 1.5], [1, 2, 3])].into(),
            scale: 1.0,
        };
        let r = Raised::objects(&t.grid, &[obj], &t);
        // Footprint 3.5..6.5: centres 3.5 (edge, inside), 4.5, 5.5, 6.5 (edge) → 4 × 4 cells.
        assert_eq!(r.len(), 16);
        assert!(r
            .range(0, 100)
            .iter()
            .all(|c| c.top_z == 103.0 && !c.partial));
    }

    /// Raising from a sample of just the cells something stands on gives the same set as from
    /// the whole terrain (what the pyramid does to stream a layer larger than memory).
    #[test]
    fn a_terrain_sample_raises_the_same_as_the_whole_terrain() {
        let g = Grid::north_up(0.0, 30.0, 1.0, 30, 30, Crs::unknown());
        let t = Elevation::new(
            g.clone(),
            (0..900)
                .map(|i| {
                    if i % 97 == 0 {
                        f32::NAN
                    } else {
                        100.0 + (i % 7) as f32 * 0.3
                    }
                })
                .collect(),
        );
        let arch = PlacedVoxels {
            origin: [12.3, 17.8, 100.0],
            heading_deg: 33.0,
            voxel_size: 0.7,
            voxels: (0..40)
                .map(|k| {
                    (
                        [
                            (k % 8) as f64 * 0.7 - 2.5,
                            (k / 8) as f64 * 0.7,
                            if k % 3 == 0 { 3.2 } else { 0.35 },
                        ],
                        [k as u8, 1, 2],
                    )
                })
                .collect(),
            scale: 1.0,
        };
        let prism = Prism {
            rings: vec![square(2.0, 2.0, 9.0, 6.0)],
            roof: crate::roof::RoofShape::flat(106.0),
        };
        let prism_cells = rasterise_prisms(&g, &[prism]);
        let mut wanted: Vec<usize> = prism_cells.iter().map(|c| c.index).collect();
        wanted.extend(object_cells(&g, &arch));
        for band_rows in [1, 4, 64] {
            let sample = TerrainSample::read(&t, wanted.clone(), band_rows).unwrap();
            let from_sample = Raised::new(prism_cells.clone(), &sample).union(
                &Raised::objects(&g, std::slice::from_ref(&arch), &sample),
                &sample,
            );
            let from_whole = Raised::new(prism_cells.clone(), &t)
                .union(&Raised::objects(&g, std::slice::from_ref(&arch), &t), &t);
            assert_eq!(from_sample, from_whole, "bands of {band_rows} rows");
            assert!(
                from_whole.cells().iter().any(|c| c.partial),
                "the test needs an overhang"
            );
        }
    }

    proptest::proptest! {
        /// Random voxel stacks in one cell, with or without a roof: at every height the runs
        /// are solid exactly where a voxel, the roof or the ground is, and they obey the
        /// tile format's rules.
        #[test]
        fn runs_are_solid_exactly_where_the_voxels_are(
            slots in proptest::collection::btree_set(0u32..12, 1..8),
            roof in proptest::option::of(0u32..10),
        ) {
            let t = flat(10, 10, 100.0);
            let vox = slots.iter().map(|&k| ([0.5, 0.5, k as f64 + 0.5], [k as u8, 0, 0])).collect();
            let objects = Raised::objects(&t.grid, &[object(vox, 0.0)], &t);
            let i = t.grid.index(5, 4);
            let roofs = roof.map(|h| RaisedCell { index: i, top_z: 100.0 + h as f32 + 0.5, colour: None, partial: false });
            let all = Raised::new(roofs.into_iter().collect(), &t).union(&objects, &t);
            let cell = *all.get(i).unwrap();
            let runs: Vec<RaisedRun> = match all.runs(i) {
                Some(r) => r.to_vec(),
                None => vec![RaisedRun { bottom: f32::NEG_INFINITY, top: cell.top_z, colour: cell.colour }],
            };
            proptest::prop_assert_eq!(cell.partial, runs.len() > 1);
            proptest::prop_assert_eq!(cell.top_z, runs.last().unwrap().top);
            let as_runs: Vec<_> = runs
                .iter()
                .map(|x| crate::voxel::columns::Run { bottom: x.bottom, top: x.top, colour: x.colour.unwrap_or([0, 0, 0, 255]) })
                .collect();
            proptest::prop_assert!(crate::voxel::columns::check_runs(&as_runs).is_ok());
            for j in 0..60 {
                let z = 99.0 + j as f64 * 0.25 + 0.125;
                let by_runs = runs.iter().any(|r| z >= r.bottom as f64 && z <= r.top as f64);
                let k = (z - 100.0).floor();
                let truth = z <= 100.0
                    || (k >= 0.0 && slots.contains(&(k as u32)))
                    || roof.is_some_and(|h| z <= 100.5 + h as f64);
                proptest::prop_assert_eq!(by_runs, truth, "z {}", z);
            }
        }
    }

    /// A 6 m cone tree of 0.5 m voxels, seeded (its crown varies).
    fn test_tree(seed: u64) -> VoxelObject {
        let p = crate::voxel::synth::TreeParams {
            height: 6.0,
            radius: 2.0,
            trunk_fraction: 0.25,
            trunk_radius: 0.3,
            vary: 0.2,
            crown: [30, 90, 40],
            trunk: [80, 60, 40],
            seed,
        };
        crate::voxel::synth::cone_tree(&p, 0.5).unwrap().0
    }

    /// Merging objects band by band gives what one merge of all their pieces gives: trees of
    /// several scales and headings straddling band edges (rows 255/256, 511/512) and the grid's.
    #[test]
    fn objects_merged_by_bands_are_one_merge_of_everything() {
        let tree = test_tree(9);
        let g = Grid::north_up(500_000.0, 5_300_300.0, 0.5, 40, 600, Crs::epsg(32632));
        let t = Elevation::new(
            g.clone(),
            (0..40 * 600).map(|i| (i / 40) as f32 * 0.01).collect(),
        );
        let rows = [
            0.3, 127.6, 128.0, 252.0, 255.5, 256.0, 260.0, 300.0, 505.0, 511.9, 599.0,
        ];
        let placed: Vec<PlacedVoxels> = rows
            .iter()
            .enumerate()
            .map(|(i, &row)| {
                let placement = PlacedObject {
                    id: i as u64 + 1,
                    file: "tree.dvox".into(),
                    sha256: String::new(),
                    x: 500_005.0 + 2.5 * i as f64,
                    y: 5_300_300.0 - row * 0.5,
                    z: 1.0,
                    heading_deg: [0.0, 45.0, 90.0, 33.0][i % 4],
                    scale: [1.0, 0.5, 1.7][i % 3],
                };
                placed_voxels(&tree, &anchored_voxels(&tree), &placement)
            })
            .collect();
        let banded = Raised::objects(&g, &placed, &t);
        let pieces = placed
            .iter()
            .flat_map(|o| object_pieces(&g, o, &t))
            .collect();
        let whole = Raised::merge(pieces, &t);
        assert!(banded.len() > 100);
        assert_eq!(banded, whole);
    }

    /// The placements [`reaches`] keeps for a window raise, in it, exactly the cells and runs
    /// all placements raise: trees of several scales and headings (the axes, diagonals and
    /// others), some straddling the window's edges, on sloping ground.
    #[test]
    fn placements_that_reach_a_window_raise_all_of_it() {
        let tree = test_tree(5);
        let reach = object_reach(&tree);
        let g = Grid::north_up(500_000.0, 5_300_040.0, 0.5, 80, 80, Crs::epsg(32632));
        let t = Elevation::new(
            g.clone(),
            (0..80 * 80).map(|i| (i % 80) as f32 * 0.05).collect(),
        );
        let placements: Vec<PlacedObject> = (0..40u64)
            .map(|i| PlacedObject {
                id: i + 1,
                file: "tree.dvox".into(),
                sha256: String::new(),
                x: 500_000.0 + 40.0 * crate::num::splitmix64(i) as f64 / u64::MAX as f64,
                y: 5_300_000.0 + 40.0 * crate::num::splitmix64(i + 100) as f64 / u64::MAX as f64,
                z: 1.0,
                heading_deg: [0.0, 45.0, 90.0, 33.0, 180.0][i as usize % 5],
                scale: [1.0, 0.5, 1.7][i as usize % 3],
            })
            .collect();
        let placed = |keep: &dyn Fn(&PlacedObject) -> bool| -> Raised {
            let kept: Vec<PlacedVoxels> = placements
                .iter()
                .filter(|p| keep(p))
                .map(|p| placed_voxels(&tree, &anchored_voxels(&tree), p))
                .collect();
            Raised::objects(&g, &kept, &t)
        };
        let all = placed(&|_| true);
        let windows = [
            (0..80, 0..80),
            (10..20, 0..80),
            (0..1, 0..80),
            (79..80, 0..80),
            (35..36, 0..80),
            (50..80, 0..80),
            (10..20, 30..45),
            (0..80, 20..21),
            (30..31, 20..40),
            (20..60, 60..80),
        ];
        for (rows, cols) in windows {
            let part = placed(&|p| reaches(&g, [p.x, p.y], reach * p.scale, &rows, &cols));
            let inside = |c: &&RaisedCell| cols.contains(&(c.index % 80));
            let (lo, hi) = (rows.start * 80, rows.end * 80);
            let want: Vec<&RaisedCell> = all.range(lo, hi).iter().filter(inside).collect();
            let got: Vec<&RaisedCell> = part.range(lo, hi).iter().filter(inside).collect();
            assert!(
                !want.is_empty(),
                "window {rows:?} × {cols:?} holds something"
            );
            assert_eq!(got, want, "window {rows:?} × {cols:?}");
            for c in want {
                assert_eq!(part.runs(c.index), all.runs(c.index), "cell {}", c.index);
            }
        }
        // Not vacuous: a window drops the placements far from it.
        let few = placements
            .iter()
            .filter(|p| reaches(&g, [p.x, p.y], reach * p.scale, &(10..20), &(30..45)));
        assert!(few.count() < placements.len() / 3);
    }
}
