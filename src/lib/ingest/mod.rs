//! `dbms ingest`: a DEM and an orthophoto registered onto one database grid.
//!
//! The database grid is, by default, in the DEM's CRS with the orthophoto's cell size over the
//! intersection of both extents, snapped to the orthophoto's cell lattice so that at its own
//! resolution the photo is copied, not resampled. `--cell` and `--bounds` override. The DEM is
//! resampled (bilinear by default); colour is area-averaged when coarsening and bilinear when
//! refining ([`resample`]). Nodata never enters a result; `--fill-voids` fills DEM voids by
//! Delaunay interpolation ([`fill`]).

pub mod fill;
pub mod inset;
#[cfg(feature = "gdal")]
pub mod reproject;
pub mod resample;

use crate::crs::Crs;
use crate::db::{self, Database, InputFile, Stage};
use crate::error::{Error, Result};
use crate::grid::{Bounds, GeoTransform, Grid};
use crate::io::input::RasterInput;
use crate::io::{self, SourceRaster};
use crate::progress::Progress;
use resample::{Resampler, Resampling};
use serde::Serialize;
use std::path::{Path, PathBuf};

/// Default `--max-cells`: 400 million cells (20 000²; about 3.2 GB of layers), far above any
/// sample and far below a typo such as `--cell 0.0005`.
pub const DEFAULT_MAX_CELLS: u64 = 400_000_000;

/// What `dbms ingest` was asked to do.
#[derive(Debug, Clone)]
pub struct IngestOptions {
    /// The elevation raster.
    pub dem: PathBuf,
    /// The orthophoto.
    pub ortho: PathBuf,
    /// Database cell size in CRS units (metres for a projected CRS); default the photo's.
    pub cell: Option<f64>,
    /// Database extent; default the intersection of the DEM's and the photo's.
    pub bounds: Option<Bounds>,
    /// How the DEM is interpolated onto the database grid.
    pub dem_resampling: Resampling,
    /// Fill DEM voids by interpolation.
    pub fill_voids: bool,
    /// Refuse grids with more cells than this.
    pub max_cells: u64,
    /// UTC time the orthophoto was taken (RFC 3339), when known: later stages use its sun to
    /// tell the photo's own shadows from new ones.
    pub photo_time: Option<String>,
    /// The database CRS (`EPSG:NNNN`, WKT or PROJ), when not the DEM's; needs feature `gdal`.
    pub t_srs: Option<String>,
    /// How long to wait for another dbms changing the database ([`Database::begin_create`]).
    pub wait: std::time::Duration,
    /// Replace a database on another grid in `out`, dropping what later stages added to it;
    /// without it that is an error. (On the same grid they are kept.)
    pub overwrite: bool,
    /// The database grid, when it is given rather than planned from the inputs (an inset's,
    /// [`inset::add_inset`]): `cell`, `bounds` and `t_srs` are then unused, and the inputs
    /// must be in its CRS (or, with feature `gdal`, are warped onto it).
    pub grid: Option<Grid>,
}

/// What ingest produced, for the summary and `--json`.
#[derive(Debug, Clone, Serialize)]
pub struct IngestSummary {
    /// The database directory.
    pub database: PathBuf,
    /// The database grid.
    pub grid: Grid,
    /// Elevation statistics.
    pub elevation: LayerSummary,
    /// Colour statistics.
    pub colour: LayerSummary,
}

/// Per-layer counts of a summary.
#[derive(Debug, Clone, Serialize)]
pub struct LayerSummary {
    /// Cells left without valid data.
    pub nodata_cells: u64,
    /// Voids filled by `--fill-voids` (elevation only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub filled_cells: Option<u64>,
    /// Lowest and highest valid elevation, metres (elevation only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub range_m: Option<(f32, f32)>,
}

impl std::fmt::Display for IngestSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let g = &self.grid;
        let (cx, cy) = g.cell_size();
        let b = g.bounds();
        write!(
            f,
            "{}: {} x {} cells of {} x {} {} in {}, extent [{}, {}, {}, {}]\n  elevation: {} nodata cells",
            self.database.display(), g.width, g.height, cx, cy, g.crs.unit(), g.crs.name(),
            b.min_x, b.min_y, b.max_x, b.max_y, self.elevation.nodata_cells,
        )?;
        if let Some(n) = self.elevation.filled_cells {
            write!(f, ", {n} filled")?;
        }
        if let Some((lo, hi)) = self.elevation.range_m {
            write!(f, ", {lo} to {hi} m")?;
        }
        write!(f, "\n  colour: {} nodata cells", self.colour.nodata_cells)
    }
}

/// Read both inputs, register them onto one grid and write the database to `out`.
pub fn ingest(opts: &IngestOptions, out: &Path, progress: &Progress) -> Result<IngestSummary> {
    // Checked now with the parser later stages use on the recorded value, so they cannot disagree.
    if let Some(t) = &opts.photo_time {
        crate::sun::parse_time(t).map_err(|e| Error {
            problem: format!("--photo-time: {}", e.problem),
            ..e
        })?;
    }
    if out.exists() && !out.is_dir() {
        return Err(Error::file(out, "is a file, not a database directory")
            .fix("give -o a new or existing database directory"));
    }
    progress.phase(6, "ingest");
    let dem = RasterInput::open(&opts.dem)?;
    require_one_band(dem.meta())?;
    progress.inc(1);
    let ortho = RasterInput::open(&opts.ortho)?;
    progress.inc(1);
    let target = match &opts.grid {
        Some(g) => g.crs.clone(),
        None => target_crs(opts, dem.grid(), ortho.grid())?,
    };
    // dbms works in metres: a State Plane grid in feet, or heights in feet, would be read wrong.
    let target_from = match &opts.t_srs {
        Some(_) => Path::new("--t-srs"),
        None => opts.dem.as_path(),
    };
    target.require_metric_coordinates(target_from)?;
    dem.grid().crs.require_metric_heights(&opts.dem)?;
    let grid = match &opts.grid {
        Some(g) => given_grid(g, &dem, &ortho, opts)?,
        None => plan_grid(&dem, &ortho, opts, &target)?,
    };

    // Each file read: a mosaic's tiles one by one.
    let mut inputs = Vec::new();
    for (role, input) in [("dem", &dem), ("ortho", &ortho)] {
        for file in input.files() {
            inputs.push(input_file(role, &file)?);
        }
    }
    let created = !out.exists();
    let written = write_database(&dem, &ortho, &grid, opts, out, inputs, progress);
    if written.is_err() && created {
        // Leave no directory behind either (the change removed what it wrote).
        let _ = std::fs::remove_file(out.join(db::LOCK_FILE));
        let _ = std::fs::remove_dir(out);
    }
    let (elevation, colour_nodata) = written?;
    progress.inc(1);
    progress.finish();
    Ok(IngestSummary {
        database: out.to_path_buf(),
        grid,
        elevation,
        colour: LayerSummary {
            nodata_cells: colour_nodata,
            filled_cells: None,
            range_m: None,
        },
    })
}

/// Write the database in `out` as one change ([`Database::begin_create`]): both layers, then
/// the manifest. Re-ingest into a database on the same grid keeps what later stages added to
/// it (layers, placed objects, stages); on another grid that is an error unless
/// `opts.overwrite`. Returns the elevation's summary and the colour's nodata cells.
fn write_database(
    dem: &RasterInput,
    ortho: &RasterInput,
    grid: &Grid,
    opts: &IngestOptions,
    out: &Path,
    inputs: Vec<db::InputFile>,
    progress: &Progress,
) -> Result<(LayerSummary, u64)> {
    let (mut change, old) = Database::begin_create(out, grid.clone(), inputs, opts.wait)?;
    if let Some(old) = old {
        let added = old.layers.len().saturating_sub(2) + old.objects.len() + old.insets.len();
        if old.grid == *grid && !opts.overwrite {
            let m = &mut change.db.manifest;
            m.layers = old.layers;
            m.objects = old.objects;
            m.last_placement_id = old.last_placement_id;
            m.insets = old.insets;
            m.stages = old.stages;
        } else if !opts.overwrite && added > 0 {
            return Err(Error::file(
                out,
                format!(
                    "holds a database on another grid with {} more layer(s), {} placed object(s) and {} inset(s), which re-ingest would drop",
                    old.layers.len().saturating_sub(2),
                    old.objects.len(),
                    old.insets.len()
                ),
            )
            .fix("give --overwrite to start it over, or ingest into a new directory"));
        }
    }
    let mut z = None;
    change.write_layer(db::ELEVATION, "elevation", "tif", |path| {
        let s = write_elevation(dem, grid, opts, path)?;
        let nodata = s.nodata_cells;
        z = Some(s);
        Ok(Some(nodata))
    })?;
    progress.inc(1);
    let mut colour_nodata = 0;
    change.write_layer(db::COLOUR, "colour", "tif", |path| {
        colour_nodata = write_colour(dem, ortho, grid, opts, path)?;
        Ok(Some(colour_nodata))
    })?;
    progress.inc(2);
    change.db.record_stage(Stage::now(
        "ingest",
        serde_json::json!({
            "dem": opts.dem, "ortho": opts.ortho, "cell": opts.cell, "bounds": opts.bounds,
            "dem_resampling": opts.dem_resampling, "fill_voids": opts.fill_voids,
            "photo_time": opts.photo_time, "t_srs": opts.t_srs,
            "dem_format": dem.meta().format, "dem_pixel_is_point": dem.meta().pixel_is_point,
        }),
    ));
    change.commit()?;
    Ok((z.expect("elevation written"), colour_nodata))
}

/// The rows of `grid` resampled and written per band: bands of [`crate::raster::band_rows`]
/// (about 4 M cells), like every stage that streams a layer.
fn bands(grid: &Grid) -> impl Iterator<Item = std::ops::Range<usize>> + Clone + '_ {
    let band = crate::raster::band_rows(grid.width);
    (0..grid.height)
        .step_by(band)
        .map(move |r0| r0..(r0 + band).min(grid.height))
}

/// Resample (or warp) the DEM onto `grid` and write it to `path` (float32 GeoTIFF), band by
/// band: memory is a band of the grid and the source rows it reads, except with
/// `--fill-voids` (the elevation is filled whole) and for inputs read whole ([`RasterInput`])
/// or warped by GDAL.
fn write_elevation(
    dem: &RasterInput,
    grid: &Grid,
    opts: &IngestOptions,
    path: &Path,
) -> Result<LayerSummary> {
    let mut z_file = io::geotiff::GeoTiffWriter::create_f32(path, grid)?;
    let mut z_stats = ElevationStats::default();
    let mut whole = opts.fill_voids.then(Vec::new);
    let mut put = |z: Vec<f32>| -> Result<()> {
        match &mut whole {
            Some(all) => all.extend(z),
            None => {
                z_stats.add(&z);
                z_file.push_rows(&z)?;
            }
        }
        Ok(())
    };
    if dem.grid().crs.same_as(&grid.crs) {
        let r = Resampler::new(opts.dem_resampling, dem.grid(), grid);
        for rows in bands(grid) {
            let src = r.source_rows(rows.clone());
            let s = dem.rows(src.clone())?.to_elevation_band()?;
            put(r.elevation(&s.data, src.start, rows))?;
        }
    } else {
        put(warp(&opts.dem, grid, opts.dem_resampling)?
            .to_elevation()?
            .data)?;
    }
    let filled = match whole {
        Some(all) => {
            let mut e = crate::raster::Raster::new(grid.clone(), all);
            let n = fill::fill_voids(&mut e) as u64;
            z_stats.add(&e.data);
            z_file.push_rows(&e.data)?;
            Some(n)
        }
        None => None,
    };
    let range_m = z_stats.range.ok_or_else(|| {
        Error::file(
            &opts.dem,
            "no valid elevation falls inside the database grid",
        )
        .fix("check --bounds, or the DEM's nodata value and extent")
    })?;
    z_file.finish()?;
    Ok(LayerSummary {
        nodata_cells: z_stats.nodata,
        filled_cells: filled,
        range_m: Some(range_m),
    })
}

/// Resample (or warp) the orthophoto onto `grid` and write it to `path` (RGBA8 GeoTIFF), band
/// by band as [`write_elevation`]; returns its nodata cells.
fn write_colour(
    dem: &RasterInput,
    ortho: &RasterInput,
    grid: &Grid,
    opts: &IngestOptions,
    path: &Path,
) -> Result<u64> {
    let mut c_file = io::geotiff::GeoTiffWriter::create_rgba8(path, grid)?;
    let mut c_nodata = 0u64;
    let mut put = |c: Vec<[u8; 4]>| -> Result<()> {
        c_nodata += c.iter().filter(|p| p[3] == 0).count() as u64;
        c_file.push_rows(&c)
    };
    if ortho.grid().crs.same_as(&grid.crs) {
        let r = Resampler::colour(ortho.grid(), grid);
        for rows in bands(grid) {
            let src = r.source_rows(rows.clone());
            let s = ortho.rows(src.clone())?.to_colour()?;
            put(r.colours(&s.data, src.start, rows))?;
        }
    } else {
        // The photo's lattice has no exact size in the target CRS: its extent over its columns
        // and rows there decides coarsening against refining, as for a native photo.
        let ob = extent_in(ortho, &grid.crs, &dem.grid().crs)?;
        let (px, py) = (
            ob.width() / ortho.grid().width as f64,
            ob.height() / ortho.grid().height as f64,
        );
        let method = resample::colour_method(
            grid.transform.cell_x.abs() / px,
            grid.transform.cell_y.abs() / py,
        );
        put(warp(&opts.ortho, grid, method)?.to_colour()?.data)?;
    }
    c_file.finish()?;
    Ok(c_nodata)
}

/// Nodata count and valid range of elevation cells seen so far.
#[derive(Default)]
struct ElevationStats {
    nodata: u64,
    /// Lowest and highest valid height, metres.
    range: Option<(f32, f32)>,
}

impl ElevationStats {
    fn add(&mut self, z: &[f32]) {
        for &v in z {
            if v.is_nan() {
                self.nodata += 1;
            } else {
                let (lo, hi) = self.range.unwrap_or((v, v));
                self.range = Some((lo.min(v), hi.max(v)));
            }
        }
    }
}

fn input_file(role: &str, path: &Path) -> Result<InputFile> {
    Ok(InputFile {
        role: role.to_string(),
        path: path.display().to_string(),
        sha256: db::sha256_file(path)?,
    })
}

/// A DEM has one band of heights. A raster of several (an RGB or RGBA photo, grey + alpha)
/// given as the DEM is refused: reading its first band as heights would make the terrain the
/// photo's red channel, silently.
fn require_one_band(dem: &SourceRaster) -> Result<()> {
    if dem.bands == 1 {
        return Ok(());
    }
    let p = dem.path.display();
    Err(Error::file(
        &dem.path,
        format!(
            "has {} bands of {} samples (an image?), but a DEM has one band of heights",
            dem.bands,
            dem.samples.type_name()
        ),
    )
    .fix(format!(
        "give the elevation raster as --dem and the photo as --ortho, or select the height band: gdal_translate -b 1 {p} dem.tif"
    )))
}

/// The database CRS: `--t-srs` (GDAL builds), else the DEM's. An input without a CRS is never
/// assumed to be in the other's: when only one of the two has a CRS, that is an error naming the
/// one without (both without: the database has no CRS, and nothing was assumed).
fn target_crs(opts: &IngestOptions, dem: &Grid, ortho: &Grid) -> Result<Crs> {
    if let Some(def) = &opts.t_srs {
        #[cfg(feature = "gdal")]
        return reproject::crs_from_definition(def);
        #[cfg(not(feature = "gdal"))]
        return Err(Error::msg(format!(
            "--t-srs {def} needs reprojection, which this build lacks"
        ))
        .fix("build dbms with --features gdal, or reproject the inputs with gdalwarp -t_srs"));
    }
    match (dem.crs.is_unknown(), ortho.crs.is_unknown()) {
        (true, false) => Err(crate::io::no_crs(&opts.dem, "orthophoto", &ortho.crs)),
        (false, true) => Err(crate::io::no_crs(&opts.ortho, "DEM", &dem.crs)),
        _ => Ok(dem.crs.clone()),
    }
}

/// The extent of an input in the database CRS: its own, or (GDAL builds) carried across CRSs.
fn extent_in(src: &RasterInput, target: &Crs, dem_crs: &Crs) -> Result<Bounds> {
    let (grid, path) = (src.grid(), &src.meta().path);
    if grid.crs.same_as(target) {
        return Ok(grid.bounds());
    }
    #[cfg(feature = "gdal")]
    {
        let _ = dem_crs;
        reproject::transform_bounds(&grid.bounds(), &grid.crs, target).map_err(|e| e.in_file(path))
    }
    #[cfg(not(feature = "gdal"))]
    Err(Error::file(path, format!("orthophoto CRS {} differs from the DEM's {}", grid.crs.name(), dem_crs.name())).fix(format!(
        "reproject the photo onto the DEM's CRS (gdalwarp -t_srs {} ...), or build dbms with --features gdal",
        dem_crs.name()
    )))
}

/// Warp an input in another CRS onto the database grid with GDAL.
fn warp(path: &Path, grid: &Grid, method: Resampling) -> Result<SourceRaster> {
    #[cfg(feature = "gdal")]
    {
        let name = serde_json::to_value(method).expect("enum serialises");
        io::gdal::warp_to_grid(path, grid, name.as_str().unwrap_or("bilinear"))
    }
    #[cfg(not(feature = "gdal"))]
    {
        let _ = (grid, method);
        Err(
            Error::file(path, "is in another CRS and this build cannot reproject")
                .fix("build dbms with --features gdal"),
        )
    }
}

/// Decide the database grid from the inputs and options (see the module docs), checking CRSs,
/// overlap, cell size and `max_cells`.
pub fn plan_grid(
    dem: &RasterInput,
    ortho: &RasterInput,
    opts: &IngestOptions,
    target: &Crs,
) -> Result<Grid> {
    let crs = target.clone();
    let db = extent_in(dem, target, &dem.grid().crs)?;
    let ob = extent_in(ortho, target, &dem.grid().crs)?;
    // A photo carried across CRSs has no lattice in the target; its cell there is estimated.
    let photo_native = ortho.grid().crs.same_as(target);
    check_cell(opts, &crs)?;
    let overlap = db.intersection(&ob).ok_or_else(|| {
        Error::file(
            &opts.ortho,
            format!("orthophoto extent {ob} does not overlap the DEM's {db}"),
        )
        .fix("check that both files cover the same area in the same CRS")
    })?;
    let ot = &ortho.grid().transform;
    let photo_cell = if photo_native {
        ot.cell_x.abs()
    } else {
        ob.width() / ortho.grid().width as f64
    };
    let grid = match (opts.bounds, opts.cell) {
        (Some(b), cell) => {
            let cell = cell.unwrap_or(photo_cell);
            with_cells(&b, cell, cell, crs)?
        }
        (None, Some(cell)) => with_cells(&overlap, cell, cell, crs)?,
        (None, None) if !photo_native => with_cells(&overlap, photo_cell, photo_cell, crs)?,
        (None, None) => {
            // Snap the overlap inward to the photo's lattice: the photo is then copied 1:1.
            let b = snap_to_photo(&overlap, &ob, ot, opts)?;
            with_cells(&b, ot.cell_x.abs(), ot.cell_y.abs(), crs)?
        }
    };
    check_size(&grid, opts.max_cells)?;
    Ok(grid)
}

/// An error when `grid` has more than `max_cells` cells (`--max-cells`).
fn check_size(grid: &Grid, max_cells: u64) -> Result<()> {
    let cells = grid.width as u64 * grid.height as u64;
    if cells > max_cells {
        return Err(Error::msg(format!(
            "the database grid would be {} x {} = {cells} cells, more than --max-cells {max_cells}",
            grid.width, grid.height
        ))
        .fix("check --cell, --bounds or the inset's size and factor, or raise --max-cells if this is really wanted"));
    }
    Ok(())
}

/// The given database grid `grid` (an inset's), checked against the inputs: each has a CRS
/// when the grid does and is in it (other CRSs need feature `gdal`), each reaches into the grid,
/// and the grid fits `--max-cells`.
fn given_grid(
    grid: &Grid,
    dem: &RasterInput,
    ortho: &RasterInput,
    opts: &IngestOptions,
) -> Result<Grid> {
    let db = grid.bounds();
    for (input, what) in [(dem, "DEM"), (ortho, "orthophoto")] {
        let (crs, path) = (&input.grid().crs, &input.meta().path);
        if crs.is_unknown() != grid.crs.is_unknown()
            || (!cfg!(feature = "gdal") && !crs.same_as(&grid.crs))
        {
            return Err(Error::file(
                path,
                format!(
                    "the {what} is in {}, but the database is in {}",
                    crs.name(),
                    grid.crs.name()
                ),
            )
            .fix(format!(
                "reproject it onto the database's CRS (gdalwarp -t_srs {} ...){}",
                grid.crs
                    .epsg
                    .map_or("<the database's CRS>".to_string(), |c| format!("EPSG:{c}")),
                if cfg!(feature = "gdal") {
                    ""
                } else {
                    ", or build dbms with --features gdal"
                }
            )));
        }
        let extent = extent_in(input, &grid.crs, &dem.grid().crs)?;
        if extent.intersection(&db).is_none() {
            return Err(Error::file(
                path,
                format!("the {what}'s extent {extent} does not reach the database grid's {db}"),
            )
            .fix(format!("give a {what} that covers it")));
        }
    }
    check_size(grid, opts.max_cells)?;
    Ok(grid.clone())
}

/// An error unless `--cell`, if given, is a positive size in the metres of a projected `crs`.
fn check_cell(opts: &IngestOptions, crs: &Crs) -> Result<()> {
    if let Some(cell) = opts.cell {
        if !(cell.is_finite() && cell > 0.0) {
            return Err(Error::msg(format!("--cell {cell} is not a positive size"))
                .fix("give the cell size in metres, e.g. --cell 0.5"));
        }
        if crs.geographic {
            return Err(Error::file(&opts.dem, format!("the database CRS is geographic (degrees, {}) but --cell is in metres", crs.name()))
                .fix("reproject the DEM to a projected CRS first (gdalwarp -t_srs EPSG:326NN for UTM), or build dbms with --features gdal"));
        }
    }
    Ok(())
}

/// `overlap` shrunk to the photo's cell lattice (`ot`, whose extent is `ob`): each edge moves
/// inward to the nearest cell edge (within 1e-9 of a cell). An error when less than one photo
/// cell is left.
fn snap_to_photo(
    overlap: &Bounds,
    ob: &Bounds,
    ot: &GeoTransform,
    opts: &IngestOptions,
) -> Result<Bounds> {
    let (cx, cy) = (ot.cell_x.abs(), ot.cell_y.abs());
    let snap = |v: f64, origin: f64, c: f64, up: bool| {
        let k = (v - origin) / c;
        let k = if up {
            (k - 1e-9).ceil()
        } else {
            (k + 1e-9).floor()
        };
        origin + k * c
    };
    let b = Bounds {
        min_x: snap(overlap.min_x, ob.min_x, cx, true),
        max_x: snap(overlap.max_x, ob.min_x, cx, false),
        min_y: snap(overlap.min_y, ob.max_y, cy, true),
        max_y: snap(overlap.max_y, ob.max_y, cy, false),
    };
    if !(b.min_x < b.max_x && b.min_y < b.max_y) {
        return Err(Error::file(
            &opts.ortho,
            "the DEM and orthophoto overlap by less than one photo cell",
        )
        .fix("check that both files cover the same area"));
    }
    Ok(b)
}

/// The grid of `cell_x` × `cell_y` cells covering `b`, top-left at `(min_x, max_y)`.
fn with_cells(b: &Bounds, cell_x: f64, cell_y: f64, crs: crate::crs::Crs) -> Result<Grid> {
    let mut g = Grid::covering(b, cell_x, crs)?;
    if cell_y != cell_x {
        g.height = ((b.height() / cell_y) - 1e-9).ceil().max(1.0) as usize;
        g.transform.cell_y = -cell_y;
    }
    Ok(g)
}
