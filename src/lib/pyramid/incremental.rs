//! Rebuilding only the pages an edit touches (`dbms pyramid --incremental`).
//!
//! Invariant: an incremental build writes, byte for byte, the tile file a full build of the
//! same database and options writes. It may do so only from a tile file its **ledger** (the
//! JSON beside it, [`ledger_path`]) describes: the ledger records what the tile file was built
//! from (the options, the sun, the layers' hashes: its [`Ledger::key`]), every building and
//! placement with the cells it can mark and its top ([`Thing`]), the terrain's height range,
//! and each level-0 page's counts ([`PageStats`], whose sums are the summary's and the effects
//! record's). Anything else — no ledger, a ledger of another tile file, another key, a change to
//! which effects run — makes a full build, and the summary says why.
//!
//! What an edit touches: the cells of every building or placement added, removed or changed
//! (old and new), and, when the sun's effects are prepared, everything their shadows can reach
//! (the cells swept away from the sun, for the requested sun and the photo's, as far as a
//! shadow from the thing's top can fall onto the lowest terrain), with two cells of margin for
//! normals and walls. Those level-0 pages are made again from what can stand on them or shade
//! them ([`crate::standing::Standing::read_window`], [`super::shade::prepare_window`]); a
//! coarse cell over a rebuilt page is folded again from its children (max Z, state) and its
//! level-0 block (colour sums); every other page is copied as stored.

use super::base::Level0;
use super::cascade::{emit_page_row, Band};
use super::reduce::{average, Block};
use super::shade::{self, Counts, Effects};
use super::PyramidOptions;
use crate::db::Database;
use crate::error::{Error, Result};
use crate::grid::Grid;
use crate::io::atomic::{AtomicFile, Staged};
use crate::progress::Progress;
use crate::raster::{band_rows, CachedRows, RowSource};
use crate::standing::{
    box_cells, object_reach, read_buildings, Prism, Raised, RaisedCell, Standing,
};
use crate::sun::Sun;
use crate::tiles::{Page, TileReader, TileSetInfo, TileWriter};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

/// The ledger's `format`.
pub const LEDGER_FORMAT: &str = "dbms-pyramid-ledger";
/// Cells of margin around what an edit touches: normals and walls look one cell away, and
/// rounding of the swept shadow gets the other.
const MARGIN: i64 = 2;
/// Most terrain cells an incremental build keeps decoded while it makes a run of page rows
/// again (64 M cells, 256 MB).
const KEPT_TERRAIN_CELLS: usize = 64 << 20;

/// The ledger of tile file `tiles`: `TILES.ledger.json` beside it.
pub fn ledger_path(tiles: &Path) -> PathBuf {
    let mut name = tiles.file_name().unwrap_or_default().to_os_string();
    name.push(".ledger.json");
    tiles.with_file_name(name)
}

/// What a tile file was built from (see the module doc); schema
/// `schemas/pyramid-ledger.schema.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Ledger {
    /// Always [`LEDGER_FORMAT`].
    pub format: String,
    /// 1.
    pub version: u32,
    /// What must be the same for pages to be reused: the tile set's description, the sun, the
    /// photo's sun, the shadow factor and the layers' SHA-256.
    pub key: serde_json::Value,
    /// Whether buildings and placed objects raise any cell, `[buildings, objects]`: which
    /// effects run depends on it.
    pub raised: [bool; 2],
    /// The tile file described: its length and the CRC-32 of its header and of its index.
    pub tiles: [u64; 3],
    /// Lowest and highest valid terrain height, metres.
    pub terrain: [f64; 2],
    /// Every building and placement.
    pub things: Vec<Thing>,
    /// Each level-0 page's counts, row-major over the pages.
    pub pages: Vec<PageStats>,
    /// Lower-case hex SHA-256 of the ledger without this member, as the manifest's
    /// ([`crate::manifest::content_checksum`]); [`stage_ledger`] sets it. A ledger without one,
    /// or whose content does not match it, is not trusted.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub checksum: Option<String>,
}

impl Ledger {
    /// SHA-256 of the ledger's content without its `checksum` member.
    pub fn content_sha256(&self) -> String {
        crate::manifest::content_checksum(&Ledger {
            checksum: None,
            ..self.clone()
        })
    }

    /// Why this ledger of a tile set on `grid` cannot be trusted, if it cannot: no checksum, or
    /// one its content does not match (edited outside dbms, or damaged), a thing whose cells
    /// are not a box inside the grid (`col0 ≤ col1 ≤ width`, `row0 ≤ row1 ≤ height`) or a
    /// terrain range that is not `lowest ≤ highest`. Trusting such a ledger would leave pages
    /// an edit touches as they were.
    pub fn distrust(&self, grid: &Grid) -> Option<String> {
        match &self.checksum {
            None => return Some("it has no checksum (written by an older dbms)".into()),
            Some(sum) if *sum != self.content_sha256() => {
                return Some(
                    "its checksum does not match its content (changed outside dbms or damaged)"
                        .into(),
                )
            }
            Some(_) => {}
        }
        let inside = |[c0, r0, c1, r1]: [usize; 4]| {
            c0 <= c1 && c1 <= grid.width && r0 <= r1 && r1 <= grid.height
        };
        if let Some(t) = self.things.iter().find(|t| !inside(t.cells)) {
            return Some(format!(
                "the cells {:?} of {:?} are not a box inside the {}×{} grid",
                t.cells, t.what, grid.width, grid.height
            ));
        }
        let [low, high] = self.terrain;
        match low <= high {
            true => None,
            false => Some(format!(
                "its terrain range {:?} is not low to high",
                self.terrain
            )),
        }
    }
}

/// A building or a placement as the ledger keeps it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Thing {
    /// What it is, to the last digit: `building <SHA-256 of its rings and roof>` or
    /// `placement <id> <file> <SHA-256> <x> <y> <z> <heading> <scale>`; two things are the same
    /// exactly when these are.
    pub what: String,
    /// The cells it can mark, `[col0, row0, col1, row1]` (ends exclusive, within the grid).
    pub cells: [usize; 4],
    /// Its highest point, metres.
    pub top: f64,
}

/// One level-0 page's share of the summary's counts and the effects record's.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct PageStats {
    /// Cells raised by buildings.
    pub building_cells: usize,
    /// Cells covered by placed objects.
    pub object_cells: usize,
    /// Partial cells.
    pub partial_cells: usize,
    /// Cells with only one of elevation and colour valid.
    pub half_valid_cells: usize,
    /// The effects record's counts, when effects were prepared.
    pub effects: Option<Counts>,
}

impl std::ops::Add for PageStats {
    type Output = PageStats;
    fn add(self, o: PageStats) -> PageStats {
        PageStats {
            building_cells: self.building_cells + o.building_cells,
            object_cells: self.object_cells + o.object_cells,
            partial_cells: self.partial_cells + o.partial_cells,
            half_valid_cells: self.half_valid_cells + o.half_valid_cells,
            effects: shade::add_optional(self.effects, o.effects),
        }
    }
}

/// The counts of level-0 page `(tx, ty)` of `info`: its cells in `standing`, its half-valid
/// cells from `level0`, and the effects' counts from `effects` (whose rows must cover it).
pub fn page_stats(
    info: &TileSetInfo,
    (tx, ty): (usize, usize),
    standing: &Standing,
    level0: &Level0,
    effects: Option<&Effects>,
) -> PageStats {
    let (cols, rows) = page_cells(info, tx, ty);
    let w = info.grid.width;
    let count = |set: &Raised, keep: fn(&RaisedCell) -> bool| -> usize {
        rows.clone()
            .map(|r| {
                let row = set.range(r * w + cols.start, r * w + cols.end);
                row.iter().filter(|c| keep(c)).count()
            })
            .sum()
    };
    PageStats {
        building_cells: count(&standing.buildings, |_| true),
        object_cells: count(&standing.objects, |_| true),
        partial_cells: count(&standing.all, |c| c.partial),
        half_valid_cells: level0.half_valid_in_page(tx, ty),
        effects: effects.map(|fx| fx.counts_in(cols, rows)),
    }
}

/// The level-0 columns and rows of page `(tx, ty)` that lie inside the grid.
fn page_cells(info: &TileSetInfo, tx: usize, ty: usize) -> (Range<usize>, Range<usize>) {
    let (p, g) = (info.page_size, &info.grid);
    (
        tx * p..((tx + 1) * p).min(g.width),
        ty * p..((ty + 1) * p).min(g.height),
    )
}

/// The key of a build (see [`Ledger::key`]).
pub fn key(
    db: &Database,
    info: &TileSetInfo,
    opts: &PyramidOptions,
    photo_sun: Option<Sun>,
) -> serde_json::Value {
    let mut described = info.clone();
    described.effects = serde_json::Value::Null;
    let sha = |name: &str| db.manifest.layers.get(name).map(|l| l.sha256.clone());
    let angles = |s: Option<Sun>| s.map(|s| [s.elevation_deg, s.azimuth_deg]);
    serde_json::json!({
        "tiles": described,
        "sun": angles(opts.sun),
        "photo_sun": angles(photo_sun),
        "shadow_factor": opts.shadow_factor,
        "elevation": sha(crate::db::ELEVATION),
        "colour": sha(crate::db::COLOUR),
        // A cell without a photo takes its material's colour (`material::layer::ColourRows`).
        "materials": sha(crate::material::layer::MATERIALS),
        "material_table": sha(crate::material::layer::MATERIAL_TABLE),
    })
}

/// Every building and placement of `db` as the ledger keeps it, buildings first.
pub fn things(db: &Database) -> Result<Vec<Thing>> {
    let grid = db.grid();
    let mut out = Vec::new();
    if db.manifest.layers.contains_key(crate::db::BUILDINGS) {
        for prism in read_buildings(&db.layer_path(crate::db::BUILDINGS)?)? {
            out.push(building(grid, &prism));
        }
    }
    let mut objects: BTreeMap<&str, (f64, f64)> = BTreeMap::new();
    for p in &db.manifest.objects {
        if !objects.contains_key(p.file.as_str()) {
            let (obj, _) = crate::voxel::format::read(&db.dir.join(&p.file))?;
            let a = obj.anchor();
            let height = obj.voxels().fold(0.0f64, |h, ([x, y, z], _)| {
                h.max(obj.grid.centre(x, y, z)[2] - a[2] + obj.grid.voxel_size / 2.0)
            });
            objects.insert(&p.file, (object_reach(&obj), height));
        }
        let (reach, height) = objects[p.file.as_str()];
        let r = reach * p.scale;
        out.push(Thing {
            what: format!(
                "placement {} {} {} {:?} {:?} {:?} {:?} {:?}",
                p.id, p.file, p.sha256, p.x, p.y, p.z, p.heading_deg, p.scale
            ),
            cells: box_cells(grid, [p.x - r, p.y - r, p.x + r, p.y + r]),
            top: p.z + height * p.scale,
        });
    }
    Ok(out)
}

fn building(grid: &Grid, prism: &Prism) -> Thing {
    use sha2::{Digest, Sha256};
    // A flat roof's text is what it was before roofs could be pitched (ledgers stay valid); a
    // pitched one adds its pitch and extent, so a change of form, eaves or direction, or of
    // another part of the same feature (the extent), touches the building's pages.
    let text = match prism.roof.pitch {
        None => format!("{:?} {:?}", prism.rings, prism.roof.top_z),
        Some(pitch) => format!("{:?} {:?} {:?}", prism.rings, prism.roof.top_z, pitch),
    };
    let pts = prism.rings.iter().flatten();
    let b = pts.fold([f64::MAX, f64::MAX, f64::MIN, f64::MIN], |b, &(x, y)| {
        [b[0].min(x), b[1].min(y), b[2].max(x), b[3].max(y)]
    });
    Thing {
        what: format!(
            "building {}",
            crate::manifest::hex(&Sha256::digest(text.as_bytes()))
        ),
        cells: box_cells(grid, b),
        top: prism.roof.top_z,
    }
}

/// Lowest and highest valid height of `terrain`, metres (`[0, 0]` when none is valid), read
/// band by band.
pub fn terrain_range(terrain: &dyn RowSource<f32>) -> Result<[f64; 2]> {
    let g = terrain.grid();
    let per = band_rows(g.width);
    let mut range = [f64::INFINITY, f64::NEG_INFINITY];
    for row0 in (0..g.height).step_by(per) {
        let rows = terrain.read_rows(row0, per.min(g.height - row0))?;
        for &z in rows.iter().filter(|z| !z.is_nan()) {
            range = [range[0].min(z as f64), range[1].max(z as f64)];
        }
    }
    Ok(match range[0] <= range[1] {
        true => range,
        false => [0.0, 0.0],
    })
}

/// What an incremental build starts from: the earlier tile file and its ledger.
pub struct Earlier {
    /// The tile file as built before.
    pub tiles: TileReader,
    /// Its ledger.
    pub ledger: Ledger,
}

/// Why an incremental build makes every page, and whether to warn of it: a ledger or earlier
/// tile file found edited or damaged is warned of, the usual reasons (no ledger yet, options
/// changed) are not.
#[derive(Debug, Clone, PartialEq)]
pub struct FullBuild {
    /// The reason, in words (the summary's `full_build`).
    pub why: String,
    /// Whether it is a warning: something beside the tile file was found edited or damaged.
    pub warn: bool,
}

impl FullBuild {
    /// A full build because something was found edited or damaged: warned of.
    pub fn warning(why: String) -> FullBuild {
        FullBuild { why, warn: true }
    }
}

impl From<String> for FullBuild {
    fn from(why: String) -> FullBuild {
        FullBuild { why, warn: false }
    }
}

/// The earlier build of `out` if its pages can serve this one, else why not (a full build
/// follows).
pub fn earlier(out: &Path, key: &serde_json::Value) -> std::result::Result<Earlier, FullBuild> {
    let path = ledger_path(out);
    let text = (crate::io::read_text(&path))
        .map_err(|e| format!("no ledger {} ({})", path.display(), e.problem))?
        .into_bytes();
    let ledger: Ledger = serde_json::from_slice(&text).map_err(|e| {
        FullBuild::warning(format!("the ledger {} cannot be read: {e}", path.display()))
    })?;
    if ledger.format != LEDGER_FORMAT || ledger.version != 1 {
        return Err(format!("{} is not a version 1 ledger", path.display()).into());
    }
    let tiles = TileReader::open(out, 64).map_err(|e| e.to_string())?;
    if let Some(why) = ledger.distrust(&tiles.info().grid) {
        let why = format!("the ledger {} is not trusted: {why}", path.display());
        return Err(FullBuild::warning(why));
    }
    let (h, i) = tiles.checksums();
    if ledger.tiles != [tiles.file_len(), h as u64, i as u64] {
        return Err(format!(
            "{} is not the tile file its ledger describes",
            out.display()
        )
        .into());
    }
    let level0 = &tiles.info().levels[0];
    if ledger.pages.len() != level0.pages_x * level0.pages_y {
        return Err(format!(
            "{} counts {} level-0 pages, the tile file has {}",
            path.display(),
            ledger.pages.len(),
            level0.pages_x * level0.pages_y
        )
        .into());
    }
    if &ledger.key != key {
        let why = "the options, the sun or the database's terrain or photo changed";
        return Err(why.to_string().into());
    }
    Ok(Earlier { tiles, ledger })
}

/// The level-0 pages an edit from `old` to `new` things touches. `suns`: the suns whose
/// shadows the effects cast (none without effects); `detect`: whether the photo's shadows are
/// detected (a building's roof cells are not judged, so its edit moves the detector's
/// thresholds within [`shade::DETECTION_REACH`] cells of it).
pub fn touched_pages(
    info: &TileSetInfo,
    old: &[Thing],
    new: &[Thing],
    terrain_min: f64,
    suns: &[Sun],
    detect: bool,
) -> BTreeSet<(usize, usize)> {
    let (was, is) = (tally(old), tally(new));
    let changed = old
        .iter()
        .filter(|t| is.get(t.what.as_str()) != was.get(t.what.as_str()))
        .chain(
            new.iter()
                .filter(|t| is.get(t.what.as_str()) != was.get(t.what.as_str())),
        );
    let (p, g) = (info.page_size, &info.grid);
    let mut pages = BTreeSet::new();
    for t in changed {
        let judged = match detect && t.what.starts_with("building") {
            true => shade::DETECTION_REACH as i64,
            false => 0,
        };
        let [c0, r0, c1, r1] = touched_cells(g, t, terrain_min, suns, judged);
        if c0 >= c1 || r0 >= r1 {
            continue;
        }
        for ty in r0 / p..=(r1 - 1) / p {
            for tx in c0 / p..=(c1 - 1) / p {
                pages.insert((tx, ty));
            }
        }
    }
    pages
}

/// How many times each thing stands in `things`.
fn tally(things: &[Thing]) -> BTreeMap<&str, i64> {
    let mut m: BTreeMap<&str, i64> = BTreeMap::new();
    for t in things {
        *m.entry(t.what.as_str()).or_default() += 1;
    }
    m
}

/// The cells `thing` marks (and `around` cells more each side) and, for each of `suns`, the
/// cells its shadow can fall on, with [`MARGIN`]: `[col0, row0, col1, row1]` within the grid.
fn touched_cells(
    g: &Grid,
    thing: &Thing,
    terrain_min: f64,
    suns: &[Sun],
    around: i64,
) -> [usize; 4] {
    let [c0, r0, c1, r1] = thing.cells.map(|v| v as i64);
    let mut b = [c0 - around, r0 - around, c1 + around, r1 + around];
    let t = &g.transform;
    for sun in suns {
        let (el, az) = (sun.elevation_deg.to_radians(), sun.azimuth_deg.to_radians());
        // Horizontal reach of the shadow of the top onto the lowest ground, metres.
        let d = ((thing.top - terrain_min).max(0.0) / el.tan()).min(1e12);
        let (dc, dr) = (-az.sin() * d / t.cell_x, -az.cos() * d / t.cell_y);
        let (dc, dr) = (dc.clamp(-1e12, 1e12), dr.clamp(-1e12, 1e12));
        b[0] = b[0].min(c0 + dc.floor() as i64);
        b[2] = b[2].max(c1 + dc.ceil() as i64);
        b[1] = b[1].min(r0 + dr.floor() as i64);
        b[3] = b[3].max(r1 + dr.ceil() as i64);
    }
    let clip = |v: i64, n: usize| v.clamp(0, n as i64) as usize;
    [
        clip(b[0] - MARGIN, g.width),
        clip(b[1] - MARGIN, g.height),
        clip(b[2] + MARGIN, g.width),
        clip(b[3] + MARGIN, g.height),
    ]
}

/// How far (cells) anything standing can shade: the shadow of the highest surface `top` onto
/// the lowest terrain for the lowest of `suns`, plus [`MARGIN`].
fn shade_reach(g: &Grid, top: f64, terrain_min: f64, suns: &[Sun]) -> usize {
    let cell = g.transform.cell_x.abs().min(g.transform.cell_y.abs());
    let d = suns
        .iter()
        .map(|s| (top - terrain_min).max(0.0) / s.elevation_deg.to_radians().tan() / cell)
        .fold(0.0f64, f64::max);
    (d.min(1e9).ceil() as usize).saturating_add(MARGIN as usize)
}

/// The level-0 pages of `touched`, made again: each page and its counts (see
/// [`make_level0`]).
#[allow(clippy::too_many_arguments)]
pub fn rebuild_level0(
    db: &Database,
    info: &TileSetInfo,
    opts: &PyramidOptions,
    photo_sun: Option<Sun>,
    touched: &BTreeSet<(usize, usize)>,
    suns: &[Sun],
    terrain_range: [f64; 2],
    top: f64,
    raised_anywhere: [bool; 2],
) -> Result<HashMap<(usize, usize), (Page, PageStats)>> {
    let out = Mutex::new(HashMap::new());
    let keep = |at: (usize, usize), page: &Page, stats: PageStats| {
        let mut out = out.lock().unwrap_or_else(|e| e.into_inner());
        out.insert(at, (page.clone(), stats));
        Ok(())
    };
    // An incremental build never runs on a database with insets (it builds in full): no covers.
    let facts = WholeGrid {
        suns,
        terrain_range,
        top,
        raised_anywhere,
        covers: &[],
    };
    make_level0(db, info, opts, photo_sun, touched, &facts, &keep)?;
    Ok(out.into_inner().unwrap_or_else(|e| e.into_inner()))
}

/// What making pages of a window needs to know about the whole grid: the suns the effects
/// cast (for how far a shadow reaches), the lowest and highest valid terrain height and the
/// highest surface (metres), and whether buildings and objects stand anywhere on it.
#[derive(Debug, Clone, Copy)]
pub struct WholeGrid<'s> {
    /// The suns the effects cast: the requested one and, when it is cast, the photo's.
    pub suns: &'s [Sun],
    /// Lowest and highest valid terrain height, metres.
    pub terrain_range: [f64; 2],
    /// No surface (terrain, building or object) is higher, metres.
    pub top: f64,
    /// Whether buildings and placed objects raise any cell of the grid, `[buildings, objects]`.
    pub raised_anywhere: [bool; 2],
    /// The covers of the database's insets on its level 0 ([`super::regions`]).
    pub covers: &'s [crate::tiles::region::Cover],
}

/// Takes a made page `(tx, ty)` with its counts ([`make_level0`]), from any thread.
pub type EmitPage<'a> = dyn Fn((usize, usize), &Page, PageStats) -> Result<()> + Sync + 'a;

/// Make the level-0 pages `touched` of `info` as a full build makes them, bit for bit, and hand
/// each with its counts to `emit((tx, ty), page, stats)` (from many threads, each page once,
/// page row by page row top to bottom): only what stands or shades near them is read.
pub fn make_level0(
    db: &Database,
    info: &TileSetInfo,
    opts: &PyramidOptions,
    photo_sun: Option<Sun>,
    touched: &BTreeSet<(usize, usize)>,
    whole: &WholeGrid,
    emit: &EmitPage<'_>,
) -> Result<()> {
    let WholeGrid {
        suns,
        terrain_range,
        top,
        raised_anywhere,
        covers,
    } = *whole;
    let (terrain, colour) = (
        db.elevation_rows()?,
        crate::material::layer::colour_rows(db)?,
    );
    let g = &info.grid;
    let p = info.page_size;
    let reach = shade_reach(g, top, terrain_range[0], suns);
    let mut by_row: BTreeMap<usize, BTreeSet<usize>> = BTreeMap::new();
    for &(tx, ty) in touched {
        by_row.entry(ty).or_default().insert(tx);
    }
    // Runs of consecutive touched page rows: each run's placements are read and its effects
    // prepared once, for all its rows and columns.
    let mut runs: Vec<Vec<(usize, BTreeSet<usize>)>> = Vec::new();
    for (ty, txs) in by_row {
        match runs.last_mut() {
            Some(run) if run.last().is_some_and(|(last, _)| last + 1 == ty) => run.push((ty, txs)),
            _ => runs.push(vec![(ty, txs)]),
        }
    }
    // The photo's detected shadows (when they run) are the same for every run of rows.
    let shared = shade::Shared::default();
    for run in runs {
        let rows = run[0].0 * p..((run[run.len() - 1].0 + 1) * p).min(g.height);
        let txs = run.iter().flat_map(|(_, txs)| txs.iter().copied());
        let (lo, hi) = txs.fold((usize::MAX, 0), |(lo, hi), tx| (lo.min(tx), hi.max(tx)));
        let cols = lo * p..((hi + 1) * p).min(g.width);
        // `r` grown by `m` each side, within `0..n`.
        let grow = |r: &Range<usize>, n: usize, m: usize| {
            r.start.saturating_sub(m)..r.end.saturating_add(m).min(n)
        };
        // Every step below reads the terrain of these rows (the casts as far up-sun as a
        // shadow reaches): decoded once, when that is not more than a few bands.
        let around = grow(&rows, g.height, reach);
        let kept = match around.len() * g.width <= KEPT_TERRAIN_CELLS {
            true => Some(CachedRows::new(&terrain, around.clone())?),
            false => None,
        };
        let terrain: &dyn RowSource<f32> = match &kept {
            Some(k) => k,
            None => &terrain,
        };
        // What stands within a shadow's reach, and the roofs the photo's shadow detector skips
        // around the window (its thresholds there depend on them).
        let m = reach.max(shade::DETECTION_REACH);
        let (stand_rows, stand_cols) = (grow(&rows, g.height, m), grow(&cols, g.width, m));
        let standing = Standing::read_window(db, terrain, p, stand_rows, stand_cols)?;
        let window = shade::Window {
            rows: rows.clone(),
            top,
            raised_anywhere: Some(raised_anywhere),
        };
        let raised = [&standing.buildings, &standing.objects, &standing.all];
        let fx = shade::prepare_window(
            opts.sun,
            photo_sun,
            opts.shadow_factor,
            terrain,
            &colour,
            raised,
            window,
            Some(&shared),
        )?;
        let level0 =
            Level0::new(terrain, &colour, &standing.all, fx.as_ref(), p).only_columns(cols.clone());
        for (ty, keep) in run {
            let band_rows = ty * p..((ty + 1) * p).min(g.height);
            let mut band = level0.band(band_rows.start, band_rows.len())?;
            super::regions::cover_band(covers, band_rows.start, &mut band);
            let Band {
                rows: base,
                columns,
            } = band;
            emit_page_row(
                info,
                0,
                ty,
                &base,
                Some(&columns),
                &|_, tx, _, page| match keep.contains(&tx) {
                    true => {
                        let stats = page_stats(info, (tx, ty), &standing, &level0, fx.as_ref());
                        emit((tx, ty), page, stats)
                    }
                    false => Ok(()),
                },
            )?;
        }
    }
    Ok(())
}

/// The pages of every level, new where a level-0 page in `level0` was made again (coarse
/// pages: the cells over them folded again) and the earlier file's elsewhere (`None`: copy it).
pub struct NewPages<'a> {
    info: &'a TileSetInfo,
    earlier: &'a TileReader,
    /// `(level, tx, ty)` → page.
    pages: HashMap<(usize, usize, usize), Arc<Page>>,
}

impl<'a> NewPages<'a> {
    /// The level-0 pages made again, and the coarse pages over them folded again from them.
    pub fn new(
        info: &'a TileSetInfo,
        earlier: &'a TileReader,
        level0: HashMap<(usize, usize), Page>,
    ) -> Result<NewPages<'a>> {
        let touched: Vec<(usize, usize)> = level0.keys().copied().collect();
        let pages = level0
            .into_iter()
            .map(|((tx, ty), page)| ((0, tx, ty), Arc::new(page)))
            .collect();
        let mut new = NewPages {
            info,
            earlier,
            pages,
        };
        for level in 1..info.levels.len() {
            new.fold_level(level, &touched)?;
        }
        Ok(new)
    }

    /// The page made again, if it was.
    pub fn get(&self, level: usize, tx: usize, ty: usize) -> Option<&Page> {
        self.pages.get(&(level, tx, ty)).map(|p| &**p)
    }

    /// Every page made again, with its `(level, tx, ty)`.
    pub fn iter(&self) -> impl Iterator<Item = ((usize, usize, usize), &Page)> {
        self.pages.iter().map(|(&k, p)| (k, &**p))
    }

    /// How many pages were made again.
    pub fn len(&self) -> usize {
        self.pages.len()
    }

    /// Whether no page was made again.
    pub fn is_empty(&self) -> bool {
        self.pages.is_empty()
    }

    /// Page `(level, tx, ty)`: made again or the earlier file's.
    fn page(&self, level: usize, tx: usize, ty: usize) -> Result<Arc<Page>> {
        match self.pages.get(&(level, tx, ty)) {
            Some(p) => Ok(p.clone()),
            None => self.earlier.page(level, tx, ty),
        }
    }

    /// Fold again, at `level`, every cell over the level-0 pages `touched`.
    fn fold_level(&mut self, level: usize, touched: &[(usize, usize)]) -> Result<()> {
        let (p, f) = (self.info.page_size, self.info.factor);
        let scale = f.pow(level as u32);
        let l = &self.info.levels[level];
        // Cells of this level over each touched level-0 page, grouped by this level's page.
        let mut cells: BTreeMap<(usize, usize), BTreeSet<(usize, usize)>> = BTreeMap::new();
        for &(tx, ty) in touched {
            let (cols, rows) = page_cells(self.info, tx, ty);
            let c = cols.start / scale..(cols.end.div_ceil(scale)).min(l.width);
            let r = rows.start / scale..(rows.end.div_ceil(scale)).min(l.height);
            for row in r {
                for col in c.clone() {
                    cells
                        .entry((col / p, row / p))
                        .or_default()
                        .insert((col, row));
                }
            }
        }
        let folded: Vec<((usize, usize, usize), Arc<Page>)> = cells
            .into_par_iter()
            .map(|((tx, ty), cells)| {
                let mut page = (*self.page(level, tx, ty)?).clone();
                for (col, row) in cells {
                    let (z, colour, state) = self.fold(level, col, row)?;
                    let i = (row % p) * p + col % p;
                    (page.max_z[i], page.colour[i], page.state[i]) = (z, colour, state);
                }
                Ok(((level, tx, ty), Arc::new(page)))
            })
            .collect::<Result<_>>()?;
        self.pages.extend(folded);
        Ok(())
    }

    /// Cell `(col, row)` of coarse `level` from its children one level finer (max Z and state,
    /// folded in the cascade's order: row by row) and its level-0 block (the colour).
    fn fold(&self, level: usize, col: usize, row: usize) -> Result<(f32, [u8; 4], u8)> {
        let f = self.info.factor;
        let fine = &self.info.levels[level - 1];
        let mut block = Block::EMPTY;
        let mut cells = Cells::new(self, level - 1);
        for r in row * f..((row + 1) * f).min(fine.height) {
            for c in col * f..((col + 1) * f).min(fine.width) {
                let child = cells.at(c, r)?;
                block.add(child.max_z, child.state);
            }
        }
        let scale = f.pow(level as u32);
        let g = &self.info.grid;
        let mut base = Cells::new(self, 0);
        for r in row * scale..((row + 1) * scale).min(g.height) {
            for c in col * scale..((col + 1) * scale).min(g.width) {
                let [red, green, blue, a] = base.at(c, r)?.colour;
                if a != 0 {
                    block.sum[0] += red as u64;
                    block.sum[1] += green as u64;
                    block.sum[2] += blue as u64;
                    block.count += 1;
                }
            }
        }
        Ok((block.max_z, average(block.sum, block.count), block.state()))
    }
}

/// Cells of one level of [`NewPages`], keeping the page last read.
struct Cells<'n, 'a> {
    pages: &'n NewPages<'a>,
    level: usize,
    held: Option<((usize, usize), Arc<Page>)>,
}

impl<'n, 'a> Cells<'n, 'a> {
    fn new(pages: &'n NewPages<'a>, level: usize) -> Cells<'n, 'a> {
        Cells {
            pages,
            level,
            held: None,
        }
    }

    fn at(&mut self, col: usize, row: usize) -> Result<crate::tiles::Cell> {
        let p = self.pages.info.page_size;
        let key = (col / p, row / p);
        if self.held.as_ref().is_none_or(|(k, _)| *k != key) {
            let page = self.pages.page(self.level, key.0, key.1)?;
            self.held = Some((key, page));
        }
        let (_, page) = self.held.as_ref().expect("just read");
        Ok(page.cell(p, col % p, row % p))
    }
}

/// Write every page of `info` to `writer`: the pages made again from `new`, every other one
/// copied as stored from `earlier`.
pub fn write_pages(
    info: &TileSetInfo,
    new: &NewPages,
    earlier: &TileReader,
    writer: &TileWriter,
    progress: &Progress,
) -> Result<()> {
    (0..info.page_count()).into_par_iter().try_for_each(|pos| {
        let (level, tx, ty) = info.page_at(pos).expect("a position of the tile set");
        progress.inc(1);
        match new.get(level, tx, ty) {
            Some(page) => writer.write_page(level, tx, ty, page),
            None => {
                let (entry, bytes) = earlier.stored(level, tx, ty)?;
                writer.write_stored(level, tx, ty, entry, bytes)
            }
        }
    })
}

/// Check every page of `earlier` that `new` does not make again against its CRC (read, not
/// decoded): a change in place keeps those pages as they are on disk, so one damaged since it
/// was written must be found here, not kept (the copy into a new file, [`write_pages`], checks
/// each page it copies the same way).
pub fn check_kept(info: &TileSetInfo, new: &NewPages, earlier: &TileReader) -> Result<()> {
    (0..info.page_count()).into_par_iter().try_for_each(|pos| {
        let (level, tx, ty) = info.page_at(pos).expect("a position of the tile set");
        match new.get(level, tx, ty) {
            Some(_) => Ok(()),
            None => earlier.stored(level, tx, ty).map(|_| ()),
        }
    })
}

/// `[file length, header CRC, index CRC]` of a tile file written but not yet renamed.
pub fn stamp(tiles: &Staged) -> Result<[u64; 3]> {
    let written = TileReader::open(tiles.written(), 0)?;
    let (h, i) = written.checksums();
    Ok([written.file_len(), h as u64, i as u64])
}

/// The ledger of tile file `tiles`, written and staged to be renamed with it.
pub fn stage_ledger(tiles: &Path, ledger: &Ledger) -> Result<Staged> {
    use std::io::Write;
    let path = ledger_path(tiles);
    let ledger = Ledger {
        checksum: Some(ledger.content_sha256()),
        ..ledger.clone()
    };
    let mut file = AtomicFile::create(&path)?;
    let w = file.writer();
    serde_json::to_writer(&mut *w, &ledger).map_err(|e| Error::file(&path, e.to_string()))?;
    w.write_all(b"\n").map_err(|e| Error::io(&path, e))?;
    file.stage()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::crs::Crs;
    use crate::roof::{Pitch, RoofForm, RoofShape};

    /// A ledger is trusted only with its checksum matching its content, every thing's cells a
    /// box inside the grid and its terrain range low to high.
    #[test]
    fn a_ledger_is_trusted_only_sealed_and_with_boxes_inside_the_grid() {
        let grid = Grid::north_up(0.0, 20.0, 1.0, 20, 10, Crs::unknown());
        let thing = |cells| Thing {
            what: "placement 1 t.dvox 00 1.0 2.0 3.0 0.0 1.0".into(),
            cells,
            top: 4.0,
        };
        let ledger = |cells, terrain| {
            let l = Ledger {
                format: LEDGER_FORMAT.into(),
                version: 1,
                key: serde_json::json!({}),
                raised: [false, true],
                tiles: [0; 3],
                terrain,
                things: vec![thing([0, 0, 3, 3]), thing(cells)],
                pages: vec![PageStats::default()],
                checksum: None,
            };
            Ledger {
                checksum: Some(l.content_sha256()),
                ..l
            }
        };
        let good = ledger([2, 3, 20, 10], [1.0, 5.0]);
        assert_eq!(good.distrust(&grid), None);
        let why = |l: &Ledger| l.distrust(&grid).unwrap_or_default();
        for bad in [[5, 3, 4, 6], [2, 7, 20, 6], [2, 3, 21, 6], [2, 3, 4, 11]] {
            assert!(why(&ledger(bad, [1.0, 5.0])).contains("not a box inside the 20×10 grid"));
        }
        assert!(why(&ledger([2, 3, 4, 6], [5.0, 1.0])).contains("terrain range"));
        assert!(why(&ledger([2, 3, 4, 6], [f64::NAN, 1.0])).contains("terrain range"));
        let mut edited = good.clone();
        edited.things[1].top = 40.0;
        assert!(why(&edited).contains("checksum does not match"));
        edited.checksum = None;
        assert!(why(&edited).contains("no checksum"));
    }

    /// A building's ledger entry changes with its roof's form, eaves or direction, so the pages
    /// it touches are made again; a flat roof's entry is what it was before roofs could be
    /// pitched, so ledgers written then stay valid.
    #[test]
    fn a_roof_change_is_a_building_change() {
        use sha2::{Digest, Sha256};
        let grid = Grid::north_up(0.0, 20.0, 1.0, 20, 20, Crs::unknown());
        let rings = vec![vec![(2.0, 2.0), (12.0, 2.0), (12.0, 8.0), (2.0, 8.0)]];
        let prism = |pitch| Prism {
            roof: RoofShape::new(&rings, 30.0, pitch),
            rings: rings.clone(),
        };
        let gable = Pitch {
            form: RoofForm::Gable,
            eave_z: 25.0,
            azimuth_deg: 90.0,
        };
        let roofs = [
            None,
            Some(gable),
            Some(Pitch {
                form: RoofForm::Hip,
                ..gable
            }),
            Some(Pitch {
                eave_z: 26.0,
                ..gable
            }),
            Some(Pitch {
                azimuth_deg: 0.0,
                ..gable
            }),
        ];
        let whats: Vec<String> = (roofs.iter())
            .map(|&p| building(&grid, &prism(p)).what)
            .collect();
        for (i, a) in whats.iter().enumerate() {
            for b in &whats[i + 1..] {
                assert_ne!(a, b);
            }
        }
        let before = format!("{:?} {:?}", rings, 30.0);
        let before = crate::manifest::hex(&Sha256::digest(before.as_bytes()));
        assert_eq!(whats[0], format!("building {before}"));
    }
}
