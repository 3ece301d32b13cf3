//! `dbms shadow-height`: building heights from their shadows in the database's orthophoto.

use super::{Ctx, SunUsed};
use dbms::choice::Choice;
use dbms::db::Database;
use dbms::error::Error;
use dbms::io::atomic::AtomicFile;
use dbms::raster::RowSource;
use dbms::shadow_height::shading::PhotoEncoding;
use dbms::shadow_height::{self as sh, output};
use dbms::sun::Sun;
use serde_json::json;
use std::path::{Path, PathBuf};

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
    /// Joint passes (0 for none): the buildings whose shadow ran into a neighbour, or that got
    /// no height, measured again with every other building at its measured roof — its shadow
    /// hiding the ground, its flat roof a surface their shadow is fitted on. Each pass costs
    /// about a pass over those buildings; see docs/shadow-height.md.
    #[arg(long, default_value_t = sh::Options::default().joint_passes)]
    joint_passes: usize,
    /// How the photo's bytes encode light: `srgb` (the usual photo) or `linear`. Pitched roofs'
    /// faces are compared as light: a wrong encoding misreads their pitch.
    #[arg(long, value_parser = super::choice::<PhotoEncoding>(), default_value = "srgb")]
    photo_encoding: PhotoEncoding,
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
    /// (prisms with their roofs, flat or the gable or hip the shadow showed, for `dbms pyramid`,
    /// `dbms shadows` and `dbms export mesh`).
    #[arg(long)]
    apply: bool,
    /// Output heights GeoJSON.
    #[arg(short, long)]
    output: PathBuf,
}

pub fn run(args: Args, ctx: &Ctx) -> dbms::Result<()> {
    let db = Database::open(&args.db)?;
    let sun = resolve_sun(&args, &db)?;
    let inputs: Vec<&Path> = std::iter::once(args.footprints.as_path())
        .chain(args.shadow_mask.as_deref())
        .collect();
    dbms::io::atomic::check_outputs(&[&args.output], &inputs)?;
    let features = read_features(&args.footprints, &db)?;
    // Read band by band while measuring: a city's grid need not fit in memory.
    let terrain = db.elevation_rows()?;
    let colour = db.colour_rows()?;
    let mask = args
        .shadow_mask
        .as_deref()
        .map(|p| sh::read_mask(p, db.grid()))
        .transpose()?;
    check_max_shift(args.max_shift)?;
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
        joint_passes: args.joint_passes,
        photo_encoding: args.photo_encoding,
        ..sh::Options::default()
    };
    let (registration, results) = sh::measure_features(
        &inputs,
        &features,
        &sun,
        &opts,
        args.max_shift,
        camera.as_ref(),
    )?;
    log_registration(ctx, &registration);
    ctx.warn_all(&skipped(&args.footprints, &results));

    let doc = output::heights_geojson(&features, &results, &registration, &sun, db.grid().crs.epsg);
    let summary = Measured::new(&args, &sun, &results, &db);
    let apply = args
        .apply
        .then(|| stage_params(&args, &sun, &registration, summary.measured));
    write_heights(
        &args.output,
        &doc,
        apply.map(|params| (&db, params)),
        ctx.wait,
    )?;
    ctx.report(&summary);
    Ok(())
}

/// The sun the options give, or by default the photo's own, from the time ingest recorded.
fn resolve_sun(args: &Args, db: &Database) -> dbms::Result<Sun> {
    match args.sun.resolve(db)? {
        Some(sun) => Ok(sun),
        None => dbms::sun::photo_sun(db)?.ok_or_else(|| {
            Error::file(
                &args.db,
                "no sun given and the database records no photo time",
            )
            .fix("give --time or --sun-elevation and --sun-azimuth")
        }),
    }
}

/// The features of the footprint file `path`, whose footprints must be in `db`'s CRS.
fn read_features(path: &Path, db: &Database) -> dbms::Result<Vec<sh::InputFeature>> {
    let features = sh::read_footprints(path)?;
    let vertices = features.iter().filter_map(|f| f.footprint.as_ref().ok());
    dbms::geojson::require_grid_crs(
        path,
        db.grid(),
        vertices.flat_map(|f| f.rings.iter().flatten().copied()),
    )?;
    Ok(features)
}

/// `--max-shift`: a distance in metres, 0 or more.
fn check_max_shift(max_shift: f64) -> dbms::Result<()> {
    if !(max_shift.is_finite() && max_shift >= 0.0) {
        return Err(Error::msg(format!(
            "--max-shift {max_shift} is not a distance in metres"
        ))
        .fix("give 0 (footprints as given) or the largest misregistration, e.g. 3"));
    }
    Ok(())
}

/// Log what the registration found: the footprints' shift onto the photo, and a perspective
/// centre estimated from the buildings' leans.
fn log_registration(ctx: &Ctx, registration: &sh::Registration) {
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
}

/// One warning for each feature of the footprint file `file` that could not be measured
/// (`results`: one per feature).
fn skipped(file: &Path, results: &[Result<sh::Measurement, String>]) -> Vec<String> {
    let file = file.display();
    (results.iter().enumerate())
        .filter_map(|(k, r)| r.as_ref().err().map(|e| (k, e)))
        .map(|(k, e)| format!("{file}: feature {k}: {e}; skipped, the others go on"))
        .collect()
}

/// The `shadow-height` stage's record for `--apply`: the options and the sun used, the
/// `buildings` written, and what the registration found.
fn stage_params(
    args: &Args,
    sun: &Sun,
    registration: &sh::Registration,
    buildings: usize,
) -> serde_json::Value {
    json!({
        "footprints": args.footprints, "sun": SunUsed::new(sun, &args.sun),
        "shadow_mask": args.shadow_mask, "max_height_m": args.max_height, "buildings": buildings,
        "line_spacing_cells": args.line_spacing, "sub_points": args.sub_points, "joint_passes": args.joint_passes,
        "photo_encoding": args.photo_encoding.name(),
        "max_shift_m": args.max_shift, "camera": args.camera,
        "camera_estimated": registration.camera.filter(|c| c.1).map(|(c, _)| json!({ "east": c.east, "north": c.north, "z": c.z })),
        "footprint_shift": registration.scene.map(|(e, n, k)| json!({ "east_m": e, "north_m": n, "buildings": k })),
    })
}

/// Write the heights document `doc` to `path` and, with `apply` (the database measured and
/// the stage's record), its buildings into the database ([`output::apply_buildings`]). The
/// file is written and synced first (a full disk fails there, before the database changes)
/// and renamed into place only after the database's change committed: a failed apply leaves
/// no heights file for `make` to take as up to date.
fn write_heights(
    path: &Path,
    doc: &serde_json::Value,
    apply: Option<(&Database, serde_json::Value)>,
    wait: std::time::Duration,
) -> dbms::Result<()> {
    let mut heights_file = AtomicFile::create(path)?;
    output::write_text(doc, heights_file.writer()).map_err(|e| Error::io(path, e))?;
    let heights_file = heights_file.stage()?;
    if let Some((db, params)) = apply {
        output::apply_buildings(db, doc, params, wait)?;
    }
    heights_file.commit()
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

impl Measured {
    /// The summary of `results` (one per feature of the footprint file) for `args`, measured
    /// in `db` with `sun`.
    fn new(
        args: &Args,
        sun: &Sun,
        results: &[Result<sh::Measurement, String>],
        db: &Database,
    ) -> Measured {
        let count = |f: &dyn Fn(&sh::Measurement) -> bool| {
            results.iter().filter(|r| r.as_ref().is_ok_and(f)).count()
        };
        Measured {
            sun: SunUsed::new(sun, &args.sun),
            output: args.output.clone(),
            features: results.len(),
            measured: count(&|m| m.height_m.is_some()),
            flagged: count(&|m| !m.flags.names().is_empty()),
            failed: results.iter().filter(|r| r.is_err()).count(),
            applied: args.apply,
            db: db.dir.clone(),
        }
    }
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
