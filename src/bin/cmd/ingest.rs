//! `dbms ingest`: register a DEM and an orthophoto onto one database grid.

use super::Ctx;
use dbms::grid::Bounds;
use dbms::ingest::inset::{add_inset, InsetArea, InsetRequest};
use dbms::ingest::{self, resample::Resampling, IngestOptions};
use std::path::PathBuf;

/// Register a DEM and an orthophoto onto one database grid and write the database directory.
#[derive(clap::Args)]
pub struct Args {
    /// Elevation raster: GeoTIFF (int16/uint16/int32/float32/float64) or Esri ASCII grid; or
    /// many GeoTIFF tiles on one cell lattice, read band by band as one: a directory of them,
    /// a list file (.txt, .list) naming one a line, or a gdalbuildvrt mosaic (.vrt).
    #[arg(long, value_name = "DEM")]
    dem: PathBuf,
    /// Orthophoto: GeoTIFF (RGB, RGBA or grey, 8/16 bit) or PNG/JPEG with a world file; or
    /// tiles, as for --dem.
    #[arg(long, value_name = "ORTHO")]
    ortho: PathBuf,
    /// Database cell size in metres [default: the orthophoto's].
    #[arg(long, value_name = "METRES")]
    cell: Option<f64>,
    /// Database extent in the DEM's CRS [default: the intersection of both inputs].
    #[arg(long, value_name = "MINX,MINY,MAXX,MAXY", value_parser = parse_bounds, allow_hyphen_values = true)]
    bounds: Option<Bounds>,
    /// How the DEM is resampled onto the database grid.
    #[arg(long, value_parser = super::choice::<Resampling>(), default_value = "bilinear")]
    dem_resampling: Resampling,
    /// Fill DEM voids by Delaunay interpolation from their borders.
    #[arg(long)]
    fill_voids: bool,
    /// Refuse a database grid with more cells than this (a guard against typos).
    #[arg(long, default_value_t = ingest::DEFAULT_MAX_CELLS)]
    max_cells: u64,
    /// UTC time the orthophoto was taken (RFC 3339): lets later stages tell its shadows from new ones.
    #[arg(long, value_name = "TIME")]
    photo_time: Option<String>,
    /// Database CRS when not the DEM's (EPSG:NNNN, WKT or PROJ); inputs in other CRSs are
    /// reprojected with GDAL. Needs a build with --features gdal.
    #[arg(long, value_name = "SRS")]
    t_srs: Option<String>,
    /// Output database directory. A database there on the same grid keeps what later stages
    /// added (buildings, placed objects, insets), unless --overwrite; on another grid see
    /// --overwrite. With --inset or --corridor: the existing database the inset joins.
    #[arg(short, long, value_name = "DB")]
    output: PathBuf,
    /// Start over the database in the output directory (on any grid), dropping its buildings
    /// layer, placed objects, insets and stage records.
    #[arg(long)]
    overwrite: bool,
    /// Add an inset to the existing database DB instead of making one: the DEM and photo are
    /// registered onto the parent's cells inside the bounds (on the parent's cell edges, CRS
    /// units), each split into FACTOR x FACTOR cells (FACTOR 2 to 10), in DB/insets/NAME/.
    #[arg(long, value_name = "NAME:FACTOR:MINX,MINY,MAXX,MAXY", allow_hyphen_values = true,
          conflicts_with_all = ["cell", "bounds", "t_srs", "overwrite", "corridor"])]
    inset: Option<String>,
    /// Add a corridor along --route: a chain of insets NAME-1, NAME-2, … (FACTOR 2 to 10) over
    /// the parent's cells within BUFFER_M metres (> 0) of the route, made of square blocks of
    /// parent cells, all added or none.
    #[arg(long, value_name = "NAME:FACTOR:BUFFER_M", requires = "route",
          conflicts_with_all = ["cell", "bounds", "t_srs", "overwrite"])]
    corridor: Option<String>,
    /// The corridor's route: GeoJSON LineString features in the database's CRS.
    #[arg(long, value_name = "GEOJSON", requires = "corridor")]
    route: Option<PathBuf>,
    /// The inset that --inset or --corridor refines [default: the base grid].
    #[arg(long, value_name = "NAME")]
    inset_parent: Option<String>,
}

fn parse_bounds(s: &str) -> Result<Bounds, String> {
    Bounds::parse(s).map_err(|e| e.to_string())
}

pub fn run(args: Args, ctx: &Ctx) -> dbms::Result<()> {
    let opts = IngestOptions {
        dem: args.dem,
        ortho: args.ortho,
        cell: args.cell,
        bounds: args.bounds,
        dem_resampling: args.dem_resampling,
        fill_voids: args.fill_voids,
        max_cells: args.max_cells,
        photo_time: args.photo_time,
        t_srs: args.t_srs,
        wait: ctx.wait,
        overwrite: args.overwrite,
        grid: None,
    };
    let progress = ctx.progress(6, "ingest");
    let request = match (&args.inset, &args.corridor, args.route) {
        (Some(arg), _, _) => {
            let (name, factor, bounds) = dbms::inset::parse_inset_arg(arg)?;
            Some((name, factor, InsetArea::Bounds(bounds)))
        }
        (None, Some(arg), Some(route)) => {
            let (name, factor, buffer_m) = dbms::inset::parse_corridor_arg(arg)?;
            Some((name, factor, InsetArea::Corridor { route, buffer_m }))
        }
        _ => None,
    };
    let Some((name, factor, area)) = request else {
        if let Some(p) = args.inset_parent {
            return Err(
                dbms::Error::msg(format!("--inset-parent {p} without an inset to add"))
                    .fix("give --inset or --corridor with it, or leave it out"),
            );
        }
        ctx.report(&ingest::ingest(&opts, &args.output, &progress)?);
        return Ok(());
    };
    let request = InsetRequest {
        name,
        parent: args.inset_parent,
        factor,
        area,
    };
    ctx.report(&add_inset(&opts, &args.output, &request, &progress)?);
    Ok(())
}
