//! The max-Z / average-colour hierarchy with shadows and shading (`dbms pyramid`).
//!
//! Invariant: every cell of every coarse level holds the exact max of the heights of its level-0
//! block (a conservative bound for ray marching), the rounded average colour of the block's valid
//! level-0 cells, and an occupancy state; nodata never becomes data. Same database and options →
//! byte-identical tile file. See `docs/pyramid.md`.
//!
//! The stages, each a module:
//! * [`crate::standing`] (read here): buildings (GeoJSON prisms) and placed voxel objects
//!   standing on the terrain;
//! * [`shade`]: the sun effects prepared for the whole grid (shadow masks, what to apply);
//! * [`base`]: level-0 bands with both merged in;
//! * [`reduce`] and [`cascade`]: the coarser levels, streamed page-row by page-row to the
//!   tile writer ([`crate::tiles::TileWriter`]);
//! * [`export`]: every level as GeoTIFF (`--export-levels`);
//! * [`incremental`]: only the pages an edit touches made again (`--incremental`), the rest
//!   copied from the earlier tile file its ledger describes;
//! * [`regions`]: a database's insets, each its own tile file, the parent's cells covering them;
//! * [`shard`]: one tile file built as independent jobs over windows of pages, then merged.

pub mod base;
pub mod cascade;
pub mod effects;
pub mod export;
pub mod incremental;
pub mod reduce;
pub mod regions;
pub mod sensor;
pub mod shade;
pub mod shard;
mod summary;
pub use summary::{PyramidSummary, Timings};

use crate::db::{Database, Stage};
use crate::error::{Error, Result};
use crate::progress::Progress;
use crate::raster::RowSource;
use crate::standing::Raised;
use crate::sun::Sun;
use crate::tiles::{Compression, SensorLayer, TileSetInfo, TileWriter};
use std::path::{Path, PathBuf};

/// Default page edge, cells.
pub const DEFAULT_PAGE: usize = 256;
/// Default ratio of cell sizes between levels.
pub const DEFAULT_FACTOR: usize = 4;

/// How `dbms pyramid` is asked to build.
#[derive(Debug, Clone)]
pub struct PyramidOptions {
    /// Ratio of cell sizes between consecutive levels: 2 or 4.
    pub factor: usize,
    /// Number of levels; `None` goes down to the first level that fits in one page.
    pub levels: Option<usize>,
    /// Page edge in cells.
    pub page_size: usize,
    /// The sun to shade for; `None` applies no effect at all.
    pub sun: Option<Sun>,
    /// Shadow factor `F` in (0, 1] (see [`shade`]).
    pub shadow_factor: f64,
    /// Per-page compression of the tile file.
    pub compression: Compression,
    /// Write every level as GeoTIFF into this directory.
    pub export_levels: Option<PathBuf>,
    /// Keep a ledger beside the tile file and, when the earlier tile file's ledger allows,
    /// make again only the pages changed since ([`incremental`]).
    pub incremental: bool,
    /// The sensor layers to carry beside the geometry ([`sensor`]); none by default.
    pub sensor: SensorInputs,
}

/// Where the sensor layers of a tile set come from: each one asked for is a layer of the tile
/// file ([`crate::tiles::SensorLayer`]).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct SensorInputs {
    /// Carry the database's `materials` layer (`dbms materials`) as `material`.
    pub material: bool,
    /// A temperature map on the database grid, kelvin (`dbms thermal -o`), as `temperature`.
    pub temperature: Option<PathBuf>,
    /// A radiance map on the database grid, W·m⁻²·sr⁻¹ (`dbms thermal --radiance-out`), as
    /// `radiance`.
    pub radiance: Option<PathBuf>,
    /// A radar σ⁰ map on the database grid, linear (`dbms radar -o`), as `backscatter`.
    pub backscatter: Option<PathBuf>,
    /// Carry each cell's surface normal (from the terrain, level on what stands on it) as
    /// `normal`: coarse cells take the renormalised sum.
    pub normals: bool,
    /// Light points (GeoJSON, [`crate::lights`]) for the header's `lights`.
    pub lights: Option<PathBuf>,
}

impl SensorInputs {
    /// The tile layers these give, in the tile set's order.
    pub fn layers(&self) -> Vec<SensorLayer> {
        let given = |l: &SensorLayer| match l {
            SensorLayer::Material => self.material,
            SensorLayer::Temperature => self.temperature.is_some(),
            SensorLayer::Radiance => self.radiance.is_some(),
            SensorLayer::Backscatter => self.backscatter.is_some(),
            SensorLayer::Normal => self.normals,
        };
        SensorLayer::ALL.into_iter().filter(given).collect()
    }

    /// Whether any sensor layer or the light points are asked for.
    pub fn any(&self) -> bool {
        !self.layers().is_empty() || self.lights.is_some()
    }

    /// The inputs as the stage records them: each map's path and SHA-256.
    fn record(&self, db: &Database) -> Result<serde_json::Value> {
        let file = |p: &Option<PathBuf>| -> Result<serde_json::Value> {
            Ok(match p {
                Some(p) => serde_json::json!({ "file": p, "sha256": crate::db::sha256_file(p)? }),
                None => serde_json::Value::Null,
            })
        };
        // The layer's hash as the manifest records it: a layer file is written once, under a
        // name of its content, so it is the file's (`dbms info --verify` checks it).
        let layer = crate::material::layer::MATERIALS;
        let material = match (self.material, db.manifest.layers.get(layer)) {
            (true, Some(l)) => serde_json::json!({ "layer": layer, "sha256": l.sha256 }),
            _ => serde_json::Value::Null,
        };
        Ok(serde_json::json!({
            "material": material,
            "temperature": file(&self.temperature)?,
            "radiance": file(&self.radiance)?,
            "backscatter": file(&self.backscatter)?,
            "normals": self.normals,
            "lights": file(&self.lights)?,
        }))
    }
}

impl Default for PyramidOptions {
    fn default() -> PyramidOptions {
        PyramidOptions {
            factor: DEFAULT_FACTOR,
            levels: None,
            page_size: DEFAULT_PAGE,
            sun: None,
            shadow_factor: shade::DEFAULT_SHADOW_FACTOR,
            compression: Compression::None,
            export_levels: None,
            incremental: false,
            sensor: SensorInputs::default(),
        }
    }
}

/// One product of a pyramid run: a tile file shaded for one sun.
#[derive(Debug, Clone, PartialEq)]
pub struct Product {
    /// The tile file.
    pub tiles: PathBuf,
    /// The sun to shade for; `None` applies no effect at all.
    pub sun: Option<Sun>,
}

/// Build the tile file `out` for the database `db` and record a `pyramid` stage in its manifest
/// (one change at the end, waiting up to `wait` for the database's lock: changes made while the
/// pyramid was built are kept).
pub fn build_pyramid(
    db: &Database,
    wait: std::time::Duration,
    out: &Path,
    opts: &PyramidOptions,
    progress: &Progress,
) -> Result<PyramidSummary> {
    let product = Product {
        tiles: out.to_path_buf(),
        sun: opts.sun,
    };
    let mut built = build_pyramids(db, wait, &[product], opts, progress)?;
    Ok(built.remove(0))
}

/// [`build_pyramid`] for several products of `db` in one run, in order, each with `opts` but its
/// own sun: what stands on the terrain is read once, and a cast or the photo's detected shadows
/// one product made serve every later product that needs the same ([`shade::Shared`]); each
/// summary's `reused` says what it took from an earlier one. Every product's outputs are
/// checked before any work (`check_products`) and committed together once all are built (one
/// change of the database records a stage for each): an error at any point leaves none of them.
pub fn build_pyramids(
    db: &Database,
    wait: std::time::Duration,
    products: &[Product],
    opts: &PyramidOptions,
    progress: &Progress,
) -> Result<Vec<PyramidSummary>> {
    if products.len() > 1 && opts.export_levels.is_some() {
        return Err(Error::msg("--export-levels with more than one product")
            .fix("export the levels of one product at a time"));
    }
    check_products(db, products, opts, &[])?;
    let shared = Shared::default();
    let ready = products
        .iter()
        .map(|p| {
            let opts = PyramidOptions {
                sun: p.sun,
                ..opts.clone()
            };
            build_product(db, &p.tiles, &opts, &shared, progress)
        })
        .collect::<Result<Vec<_>>>()?;
    commit(db, wait, ready)
}

/// Before any work: every file the run of `products` writes (each tile file, its regions' files
/// and, with `--incremental`, its ledger) is one [`check_request`] accepts, in a directory that
/// exists, none is written twice and none is one of `inputs`.
fn check_products(
    db: &Database,
    products: &[Product],
    opts: &PyramidOptions,
    inputs: &[&Path],
) -> Result<()> {
    let mut outputs = Vec::new();
    for p in products {
        check_request(&p.tiles, opts)?;
        outputs.push(p.tiles.clone());
        let regions = db.insets().into_iter();
        outputs.extend(regions.map(|spec| regions::region_file(&p.tiles, &spec.name)));
        if opts.incremental {
            outputs.push(incremental::ledger_path(&p.tiles));
        }
    }
    let outputs: Vec<&Path> = outputs.iter().map(PathBuf::as_path).collect();
    crate::io::atomic::check_outputs(&outputs, inputs)
}

/// What the products of one run share: the sun effects' work and what stands on the terrain.
#[derive(Default)]
struct Shared {
    effects: shade::Shared,
    standing: std::sync::OnceLock<crate::standing::Standing>,
}

/// One product of [`build_pyramids`], built, not yet committed.
fn build_product(
    db: &Database,
    out: &Path,
    opts: &PyramidOptions,
    shared: &Shared,
    progress: &Progress,
) -> Result<Ready> {
    let has_insets = !db.insets().is_empty();
    let mut full_build = None;
    if opts.incremental {
        let not_yet = |why: &str| Err(incremental::FullBuild::from(why.to_string()));
        let attempt = match &opts.export_levels {
            _ if has_insets => not_yet("the database has insets, not in the ledger yet"),
            Some(_) => not_yet("--export-levels writes every level"),
            None if opts.sensor.any() => {
                not_yet("sensor layers and light points are not in the incremental ledger yet")
            }
            None => incremental_build(db, out, opts, &tile_info(db, opts)?, progress)?,
        };
        match attempt {
            Ok(ready) => return Ok(ready),
            Err(why) => full_build = Some(why),
        }
    }
    // The insets first, finest first: each parent's cells over them are their reductions.
    let made = match has_insets {
        true => regions::make_regions(db, out, opts, progress)?,
        false => regions::Made::default(),
    };
    let (staged, params, mut summary) = make_product(db, db, out, opts, shared, progress, made)?;
    if let Some(full) = full_build {
        if full.warn {
            let tiles = out.display();
            summary
                .warnings
                .push(format!("{tiles}: every page made again: {}", full.why));
        }
        summary.full_build = Some(full.why);
    }
    Ok(Ready {
        outputs: Outputs::Staged(staged),
        params,
        summary,
    })
}

/// A product built and waiting for [`commit`]: its outputs, the `pyramid` stage's params and
/// its summary.
struct Ready {
    outputs: Outputs,
    params: serde_json::Value,
    summary: PyramidSummary,
}

/// The outputs of a [`Ready`] product.
enum Outputs {
    /// Written and staged, its tile file last.
    Staged(Vec<crate::io::atomic::Staged>),
    /// The earlier tile file to change in place (under the database's lock, so it is away from
    /// its name only while it is changed, not while the run waits for another), and the
    /// ledger staged.
    InPlace(crate::tiles::InPlace, crate::io::atomic::Staged),
}

impl Outputs {
    /// Everything staged, the tile file last (an in-place change applied now).
    fn stage(self) -> Result<Vec<crate::io::atomic::Staged>> {
        match self {
            Outputs::Staged(staged) => Ok(staged),
            Outputs::InPlace(change, ledger) => Ok(vec![ledger, change.apply()?]),
        }
    }
}

/// The tile set `opts` describe over `db`'s grid (no effects, no regions yet).
fn tile_info(db: &Database, opts: &PyramidOptions) -> Result<TileSetInfo> {
    let mut info = TileSetInfo::new(db.grid().clone(), opts.page_size, opts.factor, opts.levels)?
        .with_sensor_layers(&opts.sensor.layers());
    info.compression = opts.compression;
    Ok(info)
}

/// Every page of the tile file `out` of `db` with the buildings and placements of `stands` on
/// it (`db` itself, or for an inset its base: they stand in world coordinates and are
/// rasterised on `db`'s grid), and `made`'s regions (their files, header entries and covers),
/// written and staged with what `opts` add (levels, ledger): the staged outputs, the tile file
/// last, the stage's params and the summary. Nothing is renamed and no database is changed.
fn make_product(
    db: &Database,
    stands: &Database,
    out: &Path,
    opts: &PyramidOptions,
    shared: &Shared,
    progress: &Progress,
    made: regions::Made,
) -> Result<(
    Vec<crate::io::atomic::Staged>,
    serde_json::Value,
    PyramidSummary,
)> {
    let mut info = tile_info(db, opts)?;
    info.regions = made.list;
    if let Some(dir) = &opts.export_levels {
        // The levels' files are outputs too: none may be the tile file, or a special file.
        let levels = export::LevelExporter::paths(&info, dir);
        let outputs: Vec<&Path> = std::iter::once(out)
            .chain(levels.iter().map(PathBuf::as_path))
            .collect();
        crate::io::atomic::check_outputs(&outputs, &[])?;
    }
    let (mut staged_regions, built_regions, covers) = (made.staged, made.built, made.covers);
    let mut lap = stopwatch();
    let mut seconds = Timings::default();
    // The layers are read band by band (each band's tiles decoded in parallel), never whole.
    let (terrain, colour) = (
        db.elevation_rows()?,
        crate::material::layer::colour_rows(db)?,
    );
    let sensor = SensorReaders::open(db, &opts.sensor)?;
    if let Some(path) = &opts.sensor.lights {
        info.lights = crate::lights::read(path, &terrain)?;
    }
    if let Some((_, counted)) = &sensor.material {
        info.materials = sensor::attributes(&crate::material::layer::table_of(db)?, counted);
    }
    seconds.read = lap();

    // What stands on the terrain needs it only under itself: those cells are sampled first.
    let mut reused = Vec::new();
    let standing = match shared.standing.get() {
        Some(s) => {
            reused.push("what stands on the terrain (buildings and placed objects)".to_string());
            s
        }
        None => {
            let read = crate::standing::Standing::read(stands, &terrain, opts.page_size)?;
            shared.standing.get_or_init(|| read)
        }
    };
    let (buildings, objects, all) = (&standing.buildings, &standing.objects, &standing.all);

    let raised = [buildings, objects, all];
    let (effects, effects_record) =
        sun_effects(db, opts, &terrain, &colour, raised, &shared.effects)?;
    let effects_record =
        effects_record.with_layers(&opts.sensor.layers(), opts.sensor.lights.is_some());
    reused.extend(shared.effects.take_reused());
    info.effects = serde_json::to_value(&effects_record).expect("the effects record serialises");
    seconds.prepare = lap();

    let level0 = base::Level0::new(&terrain, &colour, all, effects.as_ref(), opts.page_size)
        .with_sensor(sensor.sources(opts.sensor.normals, &terrain, standing));
    let (writer, exporter) = write_levels(&info, &level0, &covers, out, opts, progress)?;
    seconds.levels = lap();
    // Every output is finished under its temporary name, and all are renamed together once the
    // database has recorded the stage: a run that fails at any point leaves no tile file (the
    // make target) to look up to date, no level, and no stage.
    let mut staged = match exporter {
        Some(x) => x.stage()?,
        None => Vec::new(),
    };
    let exported: Vec<PathBuf> = staged.iter().map(|s| s.path().to_path_buf()).collect();
    let tiles = writer.stage()?;
    if opts.incremental {
        // The ledger of what the tile file was built from, for the next incremental build.
        let pages = (0..info.levels[0].pages_y)
            .flat_map(|ty| (0..info.levels[0].pages_x).map(move |tx| (tx, ty)))
            .map(|page| incremental::page_stats(&info, page, standing, &level0, effects.as_ref()))
            .collect();
        let ledger = incremental::Ledger {
            format: incremental::LEDGER_FORMAT.into(),
            version: 1,
            key: incremental::key(db, &info, opts, photo_sun_for(db, opts)?),
            raised: [!buildings.is_empty(), !objects.is_empty()],
            tiles: incremental::stamp(&tiles)?,
            terrain: incremental::terrain_range(&terrain)?,
            things: incremental::things(db)?,
            pages,
            checksum: None,
        };
        staged.push(incremental::stage_ledger(out, &ledger)?);
    }
    // The base's tile file last: renamed after its regions' (`commit_all` keeps the order).
    staged.append(&mut staged_regions);
    staged.push(tiles);
    progress.finish();
    seconds.finish = lap();

    let total = incremental::PageStats {
        building_cells: buildings.len(),
        object_cells: objects.len(),
        partial_cells: all.cells().iter().filter(|c| c.partial).count(),
        half_valid_cells: level0.half_valid_cells(),
        effects: None,
    };
    let summary = PyramidSummary {
        reused,
        exported,
        regions: built_regions,
        ..PyramidSummary::of_pages(out, &info, total, effects_record, seconds)
    };
    let mut params = stage_params(out, opts, &info, &summary);
    if opts.sensor.any() {
        params["sensor"] = opts.sensor.record(db)?;
    }
    Ok((staged, params, summary))
}

/// The opened sources of the sensor layers a build carries.
struct SensorReaders {
    material: Option<(crate::db::LayerRows<u8>, std::sync::Arc<sensor::Counted>)>,
    temperature: Option<crate::db::LayerRows<f32>>,
    radiance: Option<crate::db::LayerRows<f32>>,
    backscatter: Option<crate::db::LayerRows<f32>>,
}

impl SensorReaders {
    /// Open what `inputs` asks for, checked against the database grid; the materials layer is
    /// scanned once for the ids it holds.
    fn open(db: &Database, inputs: &SensorInputs) -> Result<SensorReaders> {
        let material = match inputs.material {
            true => {
                let rows = db.byte_rows(crate::material::layer::MATERIALS)?;
                let counted = sensor::Counted::scan(&rows)?;
                Some((rows, std::sync::Arc::new(counted)))
            }
            false => None,
        };
        let map = |p: &Option<PathBuf>, l| {
            (p.as_deref().map(|p| sensor::open_values(db, p, l))).transpose()
        };
        Ok(SensorReaders {
            material,
            temperature: map(&inputs.temperature, SensorLayer::Temperature)?,
            radiance: map(&inputs.radiance, SensorLayer::Radiance)?,
            backscatter: map(&inputs.backscatter, SensorLayer::Backscatter)?,
        })
    }

    /// The level-0 sources, in the tile set's order; the normals, when asked for, of `terrain`
    /// with what stands on it (`standing`: roofs' faces, objects' level tops).
    fn sources<'a>(
        &'a self,
        normals: bool,
        terrain: &'a dyn crate::raster::RowSource<f32>,
        standing: &'a crate::standing::Standing,
    ) -> Vec<sensor::SensorSource<'a>> {
        let material = self
            .material
            .iter()
            .map(|(rows, c)| sensor::SensorSource::Material(rows, c.clone()));
        let values = [
            (SensorLayer::Temperature, &self.temperature),
            (SensorLayer::Radiance, &self.radiance),
            (SensorLayer::Backscatter, &self.backscatter),
        ];
        let values = values.into_iter().filter_map(|(l, rows)| {
            let rows = rows.as_ref()?;
            Some(sensor::SensorSource::Values(l, rows))
        });
        let normals = normals.then_some(sensor::SensorSource::Normals(terrain, standing));
        material.chain(values).chain(normals).collect()
    }
}

/// Take the database's lock (waiting up to `wait`), finish the outputs of every product of
/// the run (an in-place change is applied now), record a `pyramid` stage for each in one
/// change, then rename the outputs into place: the first product's last, and each product's
/// tile file after its levels, regions and ledger (a rename that fails leaves it out, not the
/// others without it). Returns the summaries, in the products' order.
fn commit(
    db: &Database,
    wait: std::time::Duration,
    ready: Vec<Ready>,
) -> Result<Vec<PyramidSummary>> {
    let mut change = Database::begin(&db.dir, wait, &[])?;
    let (mut staged, mut summaries) = (Vec::new(), Vec::new());
    for mut r in ready {
        let clock = std::time::Instant::now();
        let mut outputs = r.outputs.stage()?;
        r.summary.seconds.finish += clock.elapsed().as_secs_f64();
        outputs.append(&mut staged);
        staged = outputs;
        change.db.record_stage(Stage::now("pyramid", r.params));
        summaries.push(r.summary);
    }
    change.commit()?;
    crate::io::atomic::commit_all(staged)?;
    Ok(summaries)
}

/// The sun effects `opts` asks for over the terrain and what stands on it (`standing`:
/// buildings, placed objects, both), prepared for the whole grid, and their record (also when
/// there are none).
fn sun_effects<'a>(
    db: &Database,
    opts: &PyramidOptions,
    terrain: &'a dyn RowSource<f32>,
    colour: &dyn RowSource<[u8; 4]>,
    [buildings, objects, all]: [&'a Raised; 3],
    shared: &shade::Shared,
) -> Result<(Option<shade::Effects<'a>>, shade::EffectsRecord)> {
    let photo_sun = photo_sun_for(db, opts)?;
    let effects = shade::prepare(
        opts.sun,
        photo_sun,
        opts.shadow_factor,
        terrain,
        colour,
        [buildings, objects, all],
        Some(shared),
    )?;
    let record = match &effects {
        Some(fx) => fx.record(),
        None => {
            shade::EffectsRecord::none(opts.sun, photo_sun, opts.shadow_factor, buildings, objects)
        }
    };
    Ok((effects, record))
}

/// The photo's sun when it matters: only against a requested one (a night-time photo_time
/// must not stop a build without a sun).
fn photo_sun_for(db: &Database, opts: &PyramidOptions) -> Result<Option<Sun>> {
    match opts.sun {
        Some(_) => crate::sun::photo_sun(db),
        None => Ok(None),
    }
}

/// [`build_pyramid`] making again only the pages changed since the earlier build of `out`
/// ([`incremental`]), or why it cannot (a full build follows).
fn incremental_build(
    db: &Database,
    out: &Path,
    opts: &PyramidOptions,
    info: &TileSetInfo,
    progress: &Progress,
) -> Result<std::result::Result<Ready, incremental::FullBuild>> {
    use incremental::PageStats;
    let mut lap = stopwatch();
    let mut seconds = Timings::default();
    let photo_sun = photo_sun_for(db, opts)?;
    let key = incremental::key(db, info, opts, photo_sun);
    let earlier = match incremental::earlier(out, &key) {
        Ok(e) => e,
        Err(why) => return Ok(Err(why)),
    };
    let before = &earlier.ledger;
    let things = incremental::things(db)?;
    seconds.read = lap();

    let (seen, casts) = shade::casts_for(opts.sun, photo_sun, before.raised);
    let effects_run = casts.is_some();
    let suns: Vec<Sun> = match (casts, opts.sun) {
        (Some(c), Some(sun)) => c.suns(sun),
        _ => Vec::new(),
    };
    let detect = casts.is_some_and(|c| c.detect);
    let [low, high] = before.terrain;
    let touched = incremental::touched_pages(info, &before.things, &things, low, &suns, detect);
    let top = things.iter().map(|t| t.top).fold(high, f64::max);
    let made = incremental::rebuild_level0(
        db,
        info,
        opts,
        photo_sun,
        &touched,
        &suns,
        before.terrain,
        top,
        before.raised,
    )?;
    let mut pages = before.pages.clone();
    let mut level0 = std::collections::HashMap::new();
    for ((tx, ty), (page, stats)) in made {
        pages[ty * info.levels[0].pages_x + tx] = stats;
        level0.insert((tx, ty), page);
    }
    let total = pages.iter().fold(PageStats::default(), |a, &b| a + b);
    let raised = [total.building_cells > 0, total.object_cells > 0];
    if raised != before.raised {
        let why = "buildings or objects now raise cells where none did, or none where some did (the effects that run change)";
        return Ok(Err(why.to_string().into()));
    }
    let counts = effects_run.then(|| total.effects.unwrap_or_default());
    let effects_record =
        shade::EffectsRecord::decided(opts.sun, photo_sun, opts.shadow_factor, &seen, counts)
            .with_layers(&opts.sensor.layers(), opts.sensor.lights.is_some());
    let mut info = info.clone();
    info.effects = serde_json::to_value(&effects_record).expect("the effects record serialises");
    seconds.prepare = lap();

    // A page of the earlier file damaged on disk (found when a coarse page is folded, a page
    // copied, or a page kept in place is checked) makes a full build, warned of.
    let damaged = |e: Error| {
        incremental::FullBuild::warning(format!("the earlier tile file cannot serve: {e}"))
    };
    let new = match incremental::NewPages::new(&info, &earlier.tiles, level0) {
        Ok(new) => new,
        Err(e) => return Ok(Err(damaged(e))),
    };
    seconds.levels = lap();
    let ledger = incremental::Ledger {
        format: incremental::LEDGER_FORMAT.into(),
        version: 1,
        key,
        raised,
        tiles: [0; 3],
        terrain: before.terrain,
        things,
        pages,
        checksum: None,
    };
    let mut summary = PyramidSummary {
        pages_rebuilt: new.len(),
        ..PyramidSummary::of_pages(out, &info, total, effects_record, seconds)
    };
    let outputs = match incremental_outputs(out, &info, &new, &earlier.tiles, ledger, progress)? {
        Ok((outputs, in_place)) => {
            summary.in_place = in_place;
            outputs
        }
        Err(e) => return Ok(Err(damaged(e))),
    };
    summary.seconds.finish = lap();
    progress.finish();
    Ok(Ok(Ready {
        outputs,
        params: stage_params(out, opts, &info, &summary),
        summary,
    }))
}

/// The outputs of an incremental build of `out` whose pages made again are `new`, the rest the
/// `earlier` file's, with its `ledger` (stamped here), and whether the file changes in place:
/// in place when every other page keeps its offset (each kept page checked first), else a new
/// file with them copied (each checked as it is copied). `Ok(Err)`: a page of the earlier file
/// is damaged.
fn incremental_outputs(
    out: &Path,
    info: &TileSetInfo,
    new: &incremental::NewPages,
    earlier: &crate::tiles::TileReader,
    mut ledger: incremental::Ledger,
    progress: &Progress,
) -> Result<std::result::Result<(Outputs, bool), Error>> {
    let replaced: Vec<_> = new.iter().collect();
    if let Some(change) = crate::tiles::InPlace::plan(out, info, earlier, &replaced)? {
        if let Err(e) = incremental::check_kept(info, new, earlier) {
            return Ok(Err(e));
        }
        ledger.tiles = change.stamp();
        let ledger = incremental::stage_ledger(out, &ledger)?;
        return Ok(Ok((Outputs::InPlace(change, ledger), true)));
    }
    let writer = TileWriter::create(out, info.clone())?;
    progress.phase(info.page_count() as u64, "pyramid");
    if let Err(e) = incremental::write_pages(info, new, earlier, &writer, progress) {
        return Ok(Err(e));
    }
    let tiles = writer.stage()?;
    ledger.tiles = incremental::stamp(&tiles)?;
    let staged = vec![incremental::stage_ledger(out, &ledger)?, tiles];
    Ok(Ok((Outputs::Staged(staged), false)))
}

/// Before any work: the tile file must not be a special file or one of the database's, its
/// directory must exist, and the shadow factor must be in (0, 1].
fn check_request(out: &Path, opts: &PyramidOptions) -> Result<()> {
    crate::io::atomic::check_output(out)?;
    let dir = crate::io::atomic::output_dir(out);
    if !dir.is_dir() {
        return Err(Error::file(dir, "no such directory for the tile file")
            .fix("create the directory first, or give another path"));
    }
    if !(opts.shadow_factor > 0.0 && opts.shadow_factor <= 1.0) {
        return Err(Error::msg(format!(
            "--shadow-factor {}: must be in (0, 1]",
            opts.shadow_factor
        ))
        .fix(format!("the default is {}", shade::DEFAULT_SHADOW_FACTOR)));
    }
    Ok(())
}

/// Seconds since the previous call (the first: since this was made).
fn stopwatch() -> impl FnMut() -> f64 {
    let clock = std::time::Instant::now();
    let mut last = 0.0;
    move || {
        let now = clock.elapsed().as_secs_f64();
        let d = now - last;
        last = now;
        d
    }
}

/// What the manifest's `pyramid` stage records: the request and what it made, without times
/// (a rebuild from the same inputs records the same).
fn stage_params(
    out: &Path,
    opts: &PyramidOptions,
    info: &TileSetInfo,
    summary: &PyramidSummary,
) -> serde_json::Value {
    let mut params = serde_json::json!({
        "tiles": out, "factor": opts.factor, "page_size": opts.page_size, "levels": summary.levels,
        "compression": opts.compression.name(), "export_levels": opts.export_levels,
        "effects": info.effects,
        "building_cells": summary.building_cells, "object_cells": summary.object_cells,
        "reused": summary.reused,
        "partial_cells": summary.partial_cells, "half_valid_cells": summary.half_valid_cells,
    });
    if !info.regions.is_empty() {
        params["regions"] = serde_json::to_value(&info.regions).expect("regions serialise");
    }
    params
}

/// Every page of every level of the tile file `out` (and with `--export-levels` each level's
/// GeoTIFFs) from `level0`, page row by page row: the writers, every page written, their files
/// not yet finished.
fn write_levels(
    info: &TileSetInfo,
    level0: &base::Level0,
    covers: &[crate::tiles::region::Cover],
    out: &Path,
    opts: &PyramidOptions,
    progress: &Progress,
) -> Result<(TileWriter, Option<export::LevelExporter>)> {
    let writer = TileWriter::create(out, info.clone())?;
    let exporter = match &opts.export_levels {
        Some(dir) => Some(export::LevelExporter::create(info, dir)?),
        None => None,
    };
    progress.phase(info.page_count() as u64, "pyramid");
    cascade::build_levels_by_page_row(
        info,
        |row0, rows| {
            let mut band = level0.band(row0, rows)?;
            regions::cover_band(covers, row0, &mut band);
            Ok::<_, Error>(band)
        },
        &|level, tx, ty, page| {
            if let Some(x) = &exporter {
                x.put(level, tx, ty, page);
            }
            writer.write_page(level, tx, ty, page)?;
            progress.inc(1);
            Ok(())
        },
        &mut |level, ty| match &exporter {
            Some(x) => x.page_row_done(level, ty),
            None => Ok(()),
        },
    )?;
    Ok((writer, exporter))
}
