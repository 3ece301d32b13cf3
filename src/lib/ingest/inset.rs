//! `dbms ingest --inset` and `--corridor`: a DEM and a photo registered onto a new inset of an
//! existing database, or onto each inset of a corridor's chain ([`crate::inset::corridor`]).
//!
//! An inset's grid is derived from its parent's ([`crate::inset`]); [`super::ingest`] writes
//! the inset database `DB/insets/NAME/` on that grid, exactly as it writes a base; its border
//! is blended into the parent's surface ([`crate::inset::seam`]: the elevation layer rewritten
//! band by band, recorded as the inset's stage `seam`); then the database records the inset.
//! A corridor's insets go through that same path one after another. All of it is one change of
//! the database: it holds the database's lock throughout, and its manifest's rename is the
//! commit point — before it the database has none of the new insets (a killed run leaves
//! directories the next change removes), after it they are all there, whole.

use super::{ingest, IngestOptions, IngestSummary};
use crate::db::{self, Change, Database, InsetRecord, Stage, MANIFEST_FILE};
use crate::error::{Error, Result};
use crate::grid::{Bounds, Grid};
use crate::inset::corridor::corridor_cover;
use crate::inset::seam::{self, ParentSurface};
use crate::inset::{self, CellWindow, InsetSpec};
use crate::progress::Progress;
use crate::raster::RowSource;
use serde::Serialize;
use std::path::{Path, PathBuf};

/// Where a new inset lies in its parent.
#[derive(Debug, Clone)]
pub enum InsetArea {
    /// A world rectangle (CRS units) on the parent's cell edges (`--inset`).
    Bounds(Bounds),
    /// A route's lines buffered by `buffer_m` metres (CRS units) on every side, covered by a
    /// chain of insets ([`inset::corridor`]; `--corridor`, `--route`).
    Corridor {
        /// GeoJSON file of LineString or MultiLineString features, in the database's CRS.
        route: PathBuf,
        /// Buffer either side of the route, CRS units (metres), > 0.
        buffer_m: f64,
    },
}

/// A new inset as asked for.
#[derive(Debug, Clone)]
pub struct InsetRequest {
    /// Its name ([`inset::check_name`]).
    pub name: String,
    /// The inset it refines, `None` for the base grid.
    pub parent: Option<String>,
    /// Parent cells per inset cell along each axis, in [`inset::FACTORS`].
    pub factor: usize,
    /// Where it lies.
    pub area: InsetArea,
}

/// What adding an inset produced, for the summary and `--json`.
#[derive(Debug, Clone, Serialize)]
pub struct InsetSummary {
    /// The inset as recorded.
    pub inset: InsetSpec,
    /// The ingest into its directory (its database, grid and layers).
    pub ingest: IngestSummary,
}

impl std::fmt::Display for InsetSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let s = &self.inset;
        writeln!(
            f,
            "inset {} of {}: factor {}, parent {}",
            s.name,
            s.parent.as_deref().unwrap_or("the base grid"),
            s.factor,
            s.window
        )?;
        write!(f, "{}", self.ingest)
    }
}

/// What adding insets produced: one inset (`--inset`), or a corridor's chain.
#[derive(Debug, Clone, Serialize)]
#[serde(untagged)]
pub enum AddedInsets {
    /// One inset.
    Inset(InsetSummary),
    /// A corridor's chain of insets.
    Corridor(CorridorSummary),
}

impl std::fmt::Display for AddedInsets {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            AddedInsets::Inset(s) => s.fmt(f),
            AddedInsets::Corridor(s) => s.fmt(f),
        }
    }
}

/// What adding a corridor produced.
#[derive(Debug, Clone, Serialize)]
pub struct CorridorSummary {
    /// The corridor's name; its insets are `NAME-1`, `NAME-2`, ….
    pub corridor: String,
    /// The inset its insets refine, `None` for the base grid.
    pub parent: Option<String>,
    /// Parent cells per inset cell along each axis.
    pub factor: usize,
    /// Buffer either side of the route, metres.
    pub buffer_m: f64,
    /// Side of the blocks the cover is made of, parent cells.
    pub block_cells: usize,
    /// Parent cells the insets cover.
    pub parent_cells: u64,
    /// Cells of the insets (`parent_cells · factor²`).
    pub inset_cells: u64,
    /// The buffered route's bounding rectangle of parent cells (clipped to the parent).
    pub bounding: CellWindow,
    /// Parent cells of that rectangle.
    pub bounding_cells: u64,
    /// `parent_cells / bounding_cells`.
    pub area_ratio: f64,
    /// Each inset, north to south then west to east.
    pub insets: Vec<InsetSummary>,
}

impl std::fmt::Display for CorridorSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let n = self.insets.len();
        let last = self
            .insets
            .last()
            .map(|s| s.inset.name.as_str())
            .unwrap_or("");
        let nodata = |z: bool| -> u64 {
            self.insets
                .iter()
                .map(|s| match z {
                    true => s.ingest.elevation.nodata_cells,
                    false => s.ingest.colour.nodata_cells,
                })
                .sum()
        };
        writeln!(
            f,
            "corridor {} of {}: {n} insets {}-1 to {last}, factor {}, {} m either side of the route in blocks of {} parent cells",
            self.corridor,
            self.parent.as_deref().unwrap_or("the base grid"),
            self.corridor,
            self.factor,
            self.buffer_m,
            self.block_cells
        )?;
        writeln!(
            f,
            "  {} parent cells ({} inset cells), {:.1}% of the buffered route's bounding rectangle ({}, {} cells)",
            self.parent_cells,
            self.inset_cells,
            100.0 * self.area_ratio,
            self.bounding,
            self.bounding_cells
        )?;
        for s in &self.insets {
            let g = &s.ingest.grid;
            writeln!(
                f,
                "  {}: parent {}, {} x {} cells",
                s.inset.name, s.inset.window, g.width, g.height
            )?;
        }
        write!(
            f,
            "  elevation: {} nodata cells, colour: {} nodata cells",
            nodata(true),
            nodata(false)
        )
    }
}

/// Add inset `req` to the database in `db_dir` — for a corridor, its chain of insets
/// `NAME-1`, `NAME-2`, … ([`inset::corridor`]) — registering `opts.dem` and `opts.ortho` onto
/// each one's grid in `DB/insets/NAME/` and recording them in the database, as one change
/// (module docs): all of them or none. `opts.cell`, `bounds`, `t_srs`, `grid` and `overwrite`
/// must be unset: an inset's grid is its parent's refined.
pub fn add_inset(
    opts: &IngestOptions,
    db_dir: &Path,
    req: &InsetRequest,
    progress: &Progress,
) -> Result<AddedInsets> {
    let unused = [
        (opts.cell.is_some(), "--cell"),
        (opts.bounds.is_some(), "--bounds"),
        (opts.t_srs.is_some(), "--t-srs"),
        (opts.grid.is_some(), "a grid"),
        (opts.overwrite, "--overwrite"),
    ];
    if let Some((_, what)) = unused.iter().find(|(set, _)| *set) {
        return Err(Error::msg(format!(
            "inset {}: {what} does not apply to an inset, whose grid is its parent's refined",
            req.name
        ))
        .fix("leave it out; give the inset's factor and bounds in --inset"));
    }
    let mut change = Database::begin(db_dir, opts.wait, &[&opts.dem, &opts.ortho])?;
    let base = change.db.grid().clone();
    let mut specs = change.db.insets();
    inset::check_name(&req.name)?;
    let parent = inset::parent_grid(req.parent.as_deref(), &specs, &base)?;
    inset::check_factor(&req.name, req.factor)?;
    let (new, cover, area) = match &req.area {
        InsetArea::Bounds(b) => {
            let spec =
                InsetSpec::from_bounds(&req.name, req.parent.as_deref(), req.factor, b, &parent)?;
            (vec![spec], None, serde_json::json!({"bounds": b}))
        }
        InsetArea::Corridor { route, buffer_m } => {
            let lines = read_route(route, &parent)?;
            let cover = corridor_cover(&req.name, &lines, *buffer_m, &parent)?;
            let new = cover.specs(&req.name, req.parent.as_deref(), req.factor)?;
            let area = serde_json::json!({
                "route": route, "buffer_m": buffer_m, "corridor": req.name,
                "block_cells": cover.block_cells,
            });
            (new, Some(cover), area)
        }
    };
    // Every member is checked before any is written: a bad one refuses the chain at once.
    let mut grids = Vec::with_capacity(new.len());
    for spec in &new {
        grids.push(inset::check_new(spec, &specs, &base)?);
        specs.push(spec.clone());
    }
    let mut added = Vec::with_capacity(new.len());
    for (spec, grid) in new.into_iter().zip(grids) {
        added.push(add_one(&mut change, spec, grid, &area, opts, progress)?);
    }
    change.commit()?;
    let (Some(cover), InsetArea::Corridor { buffer_m, .. }) = (cover, &req.area) else {
        return Ok(AddedInsets::Inset(added.pop().expect("one inset")));
    };
    Ok(AddedInsets::Corridor(CorridorSummary {
        corridor: req.name.clone(),
        parent: req.parent.clone(),
        factor: req.factor,
        buffer_m: *buffer_m,
        block_cells: cover.block_cells,
        parent_cells: cover.cells(),
        inset_cells: cover.cells() * (req.factor * req.factor) as u64,
        bounding: cover.bounding,
        bounding_cells: cover.bounding_cells(),
        area_ratio: cover.area_ratio(),
        insets: added,
    }))
}

/// Write inset `spec` (checked, on `grid`) into the database `change` makes: its directory,
/// registered and seam-blended, its record and its stage `inset` (with `area`, where it came
/// from). The one path every inset, corridor members too, is added by.
fn add_one(
    change: &mut Change,
    spec: InsetSpec,
    grid: Grid,
    area: &serde_json::Value,
    opts: &IngestOptions,
    progress: &Progress,
) -> Result<InsetSummary> {
    change.wrote_inset(&spec.name)?;
    let dir = change.db.inset_dir(&spec.name);
    let summary = ingest(
        &IngestOptions {
            grid: Some(grid),
            ..opts.clone()
        },
        &dir,
        progress,
    )?;
    blend_seam(&change.db, &spec, &dir, opts.wait)?;
    let manifest_sha256 = db::sha256_file(&dir.join(MANIFEST_FILE))?;
    change.db.manifest.insets.push(InsetRecord {
        spec: spec.clone(),
        manifest_sha256,
    });
    change.db.record_stage(Stage::now(
        "inset",
        serde_json::json!({
            "inset": spec, "area": area, "dem": opts.dem, "ortho": opts.ortho,
            "dem_resampling": opts.dem_resampling, "fill_voids": opts.fill_voids,
            "photo_time": opts.photo_time,
        }),
    ));
    Ok(InsetSummary {
        inset: spec,
        ingest: summary,
    })
}

/// Blend the border of inset `spec`, just ingested into `dir`, into its parent's surface (the
/// parent read from `db`, the database it joins): the inset's elevation layer is rewritten band
/// by band through a change of the inset database, which records the stage `seam`.
fn blend_seam(
    db: &Database,
    spec: &InsetSpec,
    dir: &Path,
    wait: std::time::Duration,
) -> Result<()> {
    let parent_db = match &spec.parent {
        None => db.clone(),
        Some(p) => db.open_inset(p)?,
    };
    let parent = parent_db.grid();
    let (_, rows) = ParentSurface::needs(spec, parent);
    let parent_rows = parent_db.elevation_rows()?;
    let parent_z = parent_rows.read_rows(rows.start, rows.len())?;
    let surface = ParentSurface::new(spec, parent, &parent_z);
    let mut change = Database::begin(dir, wait, &[])?;
    let source = change.db.elevation_rows()?;
    let grid = change.db.grid().clone();
    let nodata = change.db.manifest.layers[db::ELEVATION].nodata_cells;
    change.write_layer(db::ELEVATION, "elevation", "tif", |path| {
        let mut out = crate::io::geotiff::GeoTiffWriter::create_f32(path, &grid)?;
        for rows in super::bands(&grid) {
            let mut z = source.read_rows(rows.start, rows.len())?.into_owned();
            surface.blend_rows(rows, &mut z);
            out.push_rows(&z)?;
        }
        out.finish()?;
        Ok(nodata)
    })?;
    change.db.record_stage(Stage::now(
        "seam",
        serde_json::json!({
            "parent": spec.parent, "ring_cells": seam::ring_cells(spec.factor),
            "blend": "linear from the parent's bilinear surface at the outer edge to the inset's own",
        }),
    ));
    change.commit()
}

/// The lines of the route file `path` (GeoJSON LineString or MultiLineString features, CRS
/// units), checked to be in `grid`'s CRS rather than longitude/latitude.
fn read_route(path: &Path, grid: &Grid) -> Result<Vec<Vec<(f64, f64)>>> {
    let fix = "give the route as GeoJSON LineString features in the database's CRS";
    let mut lines = Vec::new();
    for (k, feature) in crate::geojson::read_features(path, fix)?.iter().enumerate() {
        let geometry = feature.get("geometry").unwrap_or(&serde_json::Value::Null);
        let found = crate::geojson::lines(geometry)
            .map_err(|why| Error::file(path, format!("feature {k}: {why}")).fix(fix))?;
        lines.extend(found);
    }
    if lines.is_empty() {
        return Err(Error::file(path, "has no route: no LineString feature").fix(fix));
    }
    crate::geojson::require_grid_crs(path, grid, lines.iter().flatten().copied())?;
    Ok(lines)
}
