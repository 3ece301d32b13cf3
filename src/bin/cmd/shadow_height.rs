//! `dbms shadow-height`: building heights from their shadows in the database's orthophoto.

use super::{Ctx, SunUsed};
use dbms::db::Database;
use dbms::error::Error;
use dbms::io::atomic::AtomicFile;
use dbms::raster::RowSource;
use dbms::shadow_height::{self as sh, output};
use serde_json::json;
use std::path::PathBuf;

/// Measure building heights from their shadows (first estimate L·tan(elevation), refined by
/// casting each footprint's shadow over the real terrain) and write them as GeoJSON.
#[derive(clap::Args)]
pub struct Args {
    /// The database directory (elevation and colour layers from `dbms ingest`).
    #[arg(long)]
    db: PathBuf,
    /// Building footprints: GeoJSON Polygon / MultiPolygon features in the database CRS.
    #[arg(long)]
    footprints: PathBuf,
    #[command(flatten)]
    sun: super::SunArgs,
    /// Observed shadow mask on the database grid (byte GeoTIFF: 0 lit, 255 nodata, else
    /// shadow) instead of detecting shadows in the colour.
    #[arg(long)]
    shadow_mask: Option<PathBuf>,
    /// Tallest building sought, metres.
    #[arg(long, default_value_t = sh::Options::default().max_height_m)]
    max_height: f64,
    /// Scan-line spacing across the shadow, cells: smaller is more lines (a more robust median,
    /// slower); see docs/shadow-height.md for what each setting costs.
    #[arg(long, default_value_t = sh::Options::default().line_spacing_cells)]
    line_spacing: f64,
    /// Refinement points per cell side (1 to 15): the synthetic shadow covers a cell in
    /// (N × N)ths; more resolves heights finer than a cell of shadow, slower.
    #[arg(long, default_value_t = sh::Options::default().sub_points)]
    sub_points: usize,
    /// Largest footprint misregistration sought, metres: the footprints are moved by the
    /// scene's robust shift onto their roofs in the photo (median of the buildings' clear
    /// estimates); 0 takes them as given.
    #[arg(long, default_value_t = 3.0)]
    max_shift: f64,
    /// The photo's perspective centre when it is a frame photo rectified on the bare ground
    /// (not a true orthophoto): EAST,NORTH,Z in the database CRS, Z absolute metres. Roofs
    /// lean away from the nadir; the cells a building covers on its way from base to roof are
    /// not read as ground, and only the radial part of each roof's offset is taken as lean.
    #[arg(long, value_name = "EAST,NORTH,Z")]
    camera: Option<String>,
    /// Also write the measured buildings into the database as its `buildings` layer
    /// (flat-roofed prisms for `dbms pyramid` and `dbms shadows`).
    #[arg(long)]
    apply: bool,
    /// Output heights GeoJSON.
    #[arg(short, long)]
    output: PathBuf,
}

pub fn run(args: Args, ctx: &Ctx) -> dbms::Result<()> {
    let db = Database::open(&args.db)?;
    // Default: the photo's own sun, from the time ingest recorded.
    let sun = match args.sun.resolve(&db)? {
        Some(sun) => sun,
        None => dbms::sun::photo_sun(&db)?.ok_or_else(|| {
            Error::file(
                &args.db,
                "no sun given and the database records no photo time",
            )
            .fix("give --time or --sun-elevation and --sun-azimuth")
        })?,
    };
    let inputs: Vec<&std::path::Path> = std::iter::once(args.footprints.as_path())
        .chain(args.shadow_mask.as_deref())
        .collect();
    dbms::io::atomic::check_outputs(&[&args.output], &inputs)?;
    let features = sh::read_footprints(&args.footprints)?;
    let vertices = features.iter().filter_map(|f| f.footprint.as_ref().ok());
    dbms::geojson::require_grid_crs(
        &args.footprints,
        db.grid(),
        vertices.flat_map(|f| f.rings.iter().flatten().copied()),
    )?;
    // Read band by band while measuring: a city's grid need not fit in memory.
    let terrain = db.elevation_rows()?;
    let colour = db.colour_rows()?;
    let mask = args
        .shadow_mask
        .as_deref()
        .map(|p| sh::read_mask(p, db.grid()))
        .transpose()?;
    let given: Vec<sh::Footprint> = features
        .iter()
        .filter_map(|f| f.footprint.clone().ok())
        .collect();
    if !(args.max_shift.is_finite() && args.max_shift >= 0.0) {
        return Err(Error::msg(format!(
            "--max-shift {} is not a distance in metres",
            args.max_shift
        ))
        .fix("give 0 (footprints as given) or the largest misregistration, e.g. 3"));
    }
    let camera = args.camera.as_deref().map(parse_camera).transpose()?;
    let inputs = sh::Inputs {
        terrain: &terrain,
        colour: &colour,
        mask: mask.as_ref().map(|m| m as &dyn RowSource<u8>),
        leans: None,
    };
    let opts = sh::Options {
        max_height_m: args.max_height,
        line_spacing_cells: args.line_spacing,
        sub_points: args.sub_points,
        ..sh::Options::default()
    };
    let (registration, measured) = sh::register_and_measure(
        &inputs,
        &given,
        &sun,
        &opts,
        args.max_shift,
        camera.as_ref(),
    )?;
    if let Some((e, n, k)) = registration.scene {
        ctx.log(format!(
            "footprints moved {e:+.2} m east, {n:+.2} m north onto the photo (median of {k} buildings)"
        ));
    }
    if let Some((c, true)) = registration.camera {
        ctx.log(format!(
            "the buildings lean as in a perspective photo taken from {:.0} m east, {:.0} m north, {:.0} m high (estimated; give --camera if known)",
            c.east, c.north, c.z
        ));
    }
    let results = output::per_feature(&features, measured);
    let file = args.footprints.display();
    let skipped: Vec<String> = (results.iter().enumerate())
        .filter_map(|(k, r)| r.as_ref().err().map(|e| (k, e)))
        .map(|(k, e)| format!("{file}: feature {k}: {e}; skipped, the others go on"))
        .collect();
    ctx.warn_all(&skipped);

    let doc = output::heights_geojson(&features, &results, &registration, &sun, db.grid().crs.epsg);
    // Written and synced now (a full disk fails here, before the database changes), renamed
    // into place only after --apply's change committed: a failed apply leaves no heights file
    // for `make` to take as up to date.
    let mut heights_file = AtomicFile::create(&args.output)?;
    output::write_text(&doc, heights_file.writer()).map_err(|e| Error::io(&args.output, e))?;
    let heights_file = heights_file.stage()?;
    let count = |f: &dyn Fn(&sh::Measurement) -> bool| {
        results.iter().filter(|r| r.as_ref().is_ok_and(f)).count()
    };
    let heights = count(&|m| m.height_m.is_some());
    let flagged = count(&|m| !m.flags.names().is_empty());
    let failed = results.iter().filter(|r| r.is_err()).count();
    if args.apply {
        let params = json!({
            "footprints": args.footprints, "sun": SunUsed::new(&sun, &args.sun),
            "shadow_mask": args.shadow_mask, "max_height_m": args.max_height, "buildings": heights,
            "line_spacing_cells": args.line_spacing, "sub_points": args.sub_points,
            "max_shift_m": args.max_shift, "camera": args.camera,
            "camera_estimated": registration.camera.filter(|c| c.1).map(|(c, _)| json!({ "east": c.east, "north": c.north, "z": c.z })),
            "footprint_shift": registration.scene.map(|(e, n, k)| json!({ "east_m": e, "north_m": n, "buildings": k })),
        });
        output::apply_buildings(&db, &doc, params, ctx.wait)?;
    }
    heights_file.commit()?;
    ctx.report(&Measured {
        sun: SunUsed::new(&sun, &args.sun),
        output: args.output,
        features: results.len(),
        measured: heights,
        flagged,
        failed,
        applied: args.apply,
        db: db.dir.clone(),
    });
    Ok(())
}

/// `EAST,NORTH,Z` metres.
fn parse_camera(text: &str) -> dbms::Result<sh::register::PerspectiveCentre> {
    const WHAT: &str = "the perspective centre as EAST,NORTH,Z in metres, e.g. 500100,5300100,1250";
    let [east, north, z] = super::triple("--camera", text, WHAT)?;
    if ![east, north, z].iter().all(|x| x.is_finite()) {
        return Err(
            Error::msg(format!("--camera {text}: not finite numbers")).fix(format!("give {WHAT}"))
        );
    }
    Ok(sh::register::PerspectiveCentre { east, north, z })
}

/// `dbms shadow-height`'s summary.
#[derive(serde::Serialize)]
struct Measured {
    output: PathBuf,
    sun: SunUsed,
    /// Features in the footprint file.
    features: usize,
    /// Heights measured.
    measured: usize,
    flagged: usize,
    failed: usize,
    /// `--apply` wrote the heights to the database's buildings layer.
    applied: bool,
    #[serde(skip)]
    db: PathBuf,
}

impl std::fmt::Display for Measured {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{}: {} footprints, {} heights measured, {} flagged, {} bad; sun elevation {:.3}°, azimuth {:.3}°",
            self.output.display(),
            self.features,
            self.measured,
            self.flagged,
            self.failed,
            self.sun.elevation_deg,
            self.sun.azimuth_deg,
        )?;
        if self.applied {
            write!(
                f,
                "; {} buildings written to the database's buildings layer in {}",
                self.measured,
                self.db.display()
            )?;
        }
        Ok(())
    }
}
