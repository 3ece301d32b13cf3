//! One tile file built as independent jobs over page-aligned windows, then merged
//! (`dbms survey`, `dbms pyramid --shard I/N`, `dbms pyramid --merge`).
//!
//! Invariant: the tile file [`merge`] writes from the parts of shards `1..=N` is, byte for
//! byte, the one a single `dbms pyramid` of the same database and options writes.
//!
//! How: the level-0 pages are cut into `N` rectangular windows of whole pages ([`windows`]).
//! A shard makes its window's level-0 pages as an incremental build makes pages again
//! ([`super::incremental::make_level0`]: only what stands or shades near the window is read,
//! the sun's casts sweep in from as far as a shadow reaches) and writes them as a one-level
//! tile file of the window, its **part**, with a record of its counts beside it
//! (`PART.shard.json`, [`ShardRecord`]). What a window cannot see but its pages depend on —
//! whether buildings and objects stand anywhere (which effects run), the terrain's height range
//! and the highest surface (how far a shadow reaches) — comes from one [`Survey`] of the whole
//! database, taken first. The merge copies every level-0 page from its part as stored, and
//! streams the coarse levels from them through the same cascade a full build runs (coarse
//! cells are exact maxima and integer colour sums of level 0, so they need nothing else).
//!
//! Each shard reads the database; none writes it. The merge records the `pyramid` stage.
//! With insets, every shard makes the insets again for their covers on its level 0, and the
//! merge makes them once more for their tile files ([`super::regions`]).
//! Not yet: sensor layers and light points (their level-0 sums are not all in the pages), an
//! incremental ledger for the merged file, insets made once for all shards.

use super::cascade::{self, Band};
use super::incremental::{self, PageStats, WholeGrid};
use super::reduce::BaseRows;
use super::shade::{self, EffectsRecord};
use super::{PyramidOptions, PyramidSummary, Timings};
use crate::db::Database;
use crate::error::{Error, Result};
use crate::grid::Window;
use crate::io::atomic::{AtomicFile, Staged};
use crate::progress::Progress;
use crate::sun::Sun;
use crate::tiles::{TileReader, TileSetInfo, TileWriter};
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

/// The survey's `format`.
pub const SURVEY_FORMAT: &str = "dbms-pyramid-survey";
/// The shard record's `format`.
pub const SHARD_FORMAT: &str = "dbms-pyramid-shard";

/// What every shard must know about the whole database (`dbms survey`; schema
/// `schemas/pyramid-survey.schema.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Survey {
    /// Always [`SURVEY_FORMAT`].
    pub format: String,
    /// 1.
    pub version: u32,
    /// What was surveyed: SHA-256 over the elevation layer's SHA-256 and every building and
    /// placement to the last digit ([`database_digest`]); a shard refuses a survey of anything
    /// else.
    pub database: String,
    /// Lowest and highest valid terrain height, metres (`[0, 0]` when none is valid).
    pub terrain: [f64; 2],
    /// No surface (terrain, roof, object) is higher, metres.
    pub top: f64,
    /// Whether buildings and placed objects raise any cell, `[buildings, objects]`.
    pub raised: [bool; 2],
}

/// The record a shard leaves beside its part (`PART.shard.json`; schema
/// `schemas/pyramid-shard.schema.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ShardRecord {
    /// Always [`SHARD_FORMAT`].
    pub format: String,
    /// 1.
    pub version: u32,
    /// The key of the whole build (the tile set's description, the suns, the shadow factor, the
    /// layers' SHA-256): every part of one merge has the same.
    pub key: serde_json::Value,
    /// `[I, N]`: shard `I` of `N`, from 1.
    pub shard: [usize; 2],
    /// The window, in level-0 pages of the whole tile set: `[tx0, ty0, tx1, ty1]`, ends exclusive.
    pub pages: [usize; 4],
    /// The survey's `database`: the state of the database the part was made of (the key does
    /// not cover buildings and placements).
    pub database: String,
    /// The survey's `raised`.
    pub raised: [bool; 2],
    /// The window's counts (their sums are the whole file's).
    pub stats: PageStats,
}

/// SHA-256 (hex) over the elevation layer's SHA-256 and every building and placement of `db`
/// ([`incremental::things`]): what a [`Survey`] depends on.
pub fn database_digest(db: &Database) -> Result<String> {
    let mut h = Sha256::new();
    let elevation = db.manifest.layers.get(crate::db::ELEVATION);
    h.update(elevation.map_or("", |l| l.sha256.as_str()).as_bytes());
    for t in incremental::things(db)? {
        h.update(b"\n");
        h.update(t.what.as_bytes());
    }
    Ok(crate::manifest::hex(&h.finalize()))
}

/// Survey `db` (see [`Survey`]): the terrain read band by band once; whether buildings and
/// objects raise a cell, from what stands in each one's own box, stopping at the first that
/// does (a whole-grid read of what stands would hold every building cell at once).
pub fn survey(db: &Database) -> Result<Survey> {
    let terrain = db.elevation_rows()?;
    let range = incremental::terrain_range(&terrain)?;
    let things = incremental::things(db)?;
    let top = things.iter().map(|t| t.top).fold(range[1], f64::max);
    let raises = |building: bool| -> Result<bool> {
        let kind = if building { "building" } else { "placement" };
        for t in things.iter().filter(|t| t.what.starts_with(kind)) {
            let [c0, r0, c1, r1] = t.cells;
            if c0 >= c1 || r0 >= r1 {
                continue;
            }
            let p = super::DEFAULT_PAGE;
            let s = crate::standing::Standing::read_window(db, &terrain, p, r0..r1, c0..c1)?;
            let raised = if building { &s.buildings } else { &s.objects };
            if !raised.is_empty() {
                return Ok(true);
            }
        }
        Ok(false)
    };
    Ok(Survey {
        format: SURVEY_FORMAT.into(),
        version: 1,
        database: database_digest(db)?,
        terrain: range,
        top,
        raised: [raises(true)?, raises(false)?],
    })
}

/// Write `value` as JSON to `path`, atomically.
pub fn write_json<T: Serialize>(path: &Path, value: &T) -> Result<()> {
    stage_json(path, value)?.commit()
}

fn stage_json<T: Serialize>(path: &Path, value: &T) -> Result<Staged> {
    use std::io::Write;
    let mut file = AtomicFile::create(path)?;
    let w = file.writer();
    serde_json::to_writer_pretty(&mut *w, value).map_err(|e| Error::file(path, e.to_string()))?;
    w.write_all(b"\n").map_err(|e| Error::io(path, e))?;
    file.stage()
}

fn read_json<T: serde::de::DeserializeOwned>(path: &Path, what: &str, fix: &str) -> Result<T> {
    let text = crate::io::read_text(path)
        .map_err(|e| e.fix(fix.to_string()))?
        .into_bytes();
    serde_json::from_slice(&text)
        .map_err(|e| Error::file(path, format!("not a {what}: {e}")).fix(fix.to_string()))
}

/// Read a survey written by `dbms survey`, checked against `db`.
pub fn read_survey(path: &Path, db: &Database) -> Result<Survey> {
    let fix = format!(
        "run dbms survey --db {} -o {}",
        db.dir.display(),
        path.display()
    );
    let s: Survey = read_json(path, "survey", &fix)?;
    if s.format != SURVEY_FORMAT || s.version != 1 {
        return Err(Error::file(path, "not a version 1 survey of dbms").fix(fix));
    }
    if s.database != database_digest(db)? {
        return Err(Error::file(
            path,
            "surveys another state of the database (its terrain, buildings or placements changed since)",
        )
        .fix(fix));
    }
    Ok(s)
}

/// The record beside part `part`: `PART.shard.json`.
pub fn record_path(part: &Path) -> PathBuf {
    let mut name = part.file_name().unwrap_or_default().to_os_string();
    name.push(".shard.json");
    part.with_file_name(name)
}

/// The `n` windows of whole level-0 pages the shards of `info` build, shard 1 first, row by row:
/// `[tx0, ty0, tx1, ty1]` (ends exclusive). The pages are cut into `a` columns and `b` rows of
/// windows, `a · b = n`, the pair whose largest window holds the fewest pages (then the one
/// whose windows are squarest); each window differs from the others of its row or column by
/// at most one page.
pub fn windows(info: &TileSetInfo, n: usize) -> Result<Vec<[usize; 4]>> {
    let (px, py) = (info.levels[0].pages_x, info.levels[0].pages_y);
    let best = (1..=n)
        .filter(|a| n.is_multiple_of(*a) && *a <= px && n / a <= py)
        .min_by_key(|&a| {
            let (wx, wy) = (px.div_ceil(a), py.div_ceil(n / a));
            (wx * wy, wx.abs_diff(wy))
        });
    let Some(a) = best else {
        return Err(Error::msg(format!(
            "{n} shards: the tile set has {px} × {py} level-0 pages, which cannot be cut into {n} windows of whole pages"
        ))
        .fix(format!("ask for at most {} shards, or a number that divides into {px} columns and {py} rows", px * py)));
    };
    let b = n / a;
    let cut = |k: usize, parts: usize, total: usize| k * total / parts;
    Ok((0..b)
        .flat_map(|j| {
            (0..a).map(move |i| {
                [
                    cut(i, a, px),
                    cut(j, b, py),
                    cut(i + 1, a, px),
                    cut(j + 1, b, py),
                ]
            })
        })
        .collect())
}

/// The tile set of `db` that `opts` describe, for a sharded build: only the geometry layers
/// (refused with why: sensor layers, light points, exported levels, a ledger).
fn tile_set(db: &Database, opts: &PyramidOptions, what: &str) -> Result<TileSetInfo> {
    let refuse = |option: &str| {
        Err(Error::msg(format!(
            "{what} with {option}: sharded builds make the visual layers only"
        ))
        .fix(format!(
            "leave {option} out, or build this product with one dbms pyramid"
        )))
    };
    if opts.sensor.any() {
        return refuse("sensor layers or light points");
    }
    if opts.export_levels.is_some() {
        return refuse("--export-levels");
    }
    if opts.incremental {
        return refuse("--incremental");
    }
    // No sensor layers (refused above): the tile set of every build of these options.
    super::tile_info(db, opts)
}

/// The suns the effects cast (none without a sun or effects): the requested one and the
/// photo's when it is cast too.
fn cast_suns(opts: &PyramidOptions, photo_sun: Option<Sun>, raised: [bool; 2]) -> Vec<Sun> {
    match (shade::casts_for(opts.sun, photo_sun, raised), opts.sun) {
        ((_, Some(c)), Some(sun)) => c.suns(sun),
        _ => Vec::new(),
    }
}

/// What one shard made.
#[derive(Debug, Clone, Serialize)]
pub struct ShardSummary {
    /// The part: a one-level tile file of the window.
    pub part: PathBuf,
    /// Its record.
    pub record: PathBuf,
    /// `[I, N]`.
    pub shard: [usize; 2],
    /// The window in level-0 pages, `[tx0, ty0, tx1, ty1]`.
    pub pages: [usize; 4],
    /// Level-0 pages made.
    pub pages_made: usize,
    /// Wall-clock seconds.
    pub seconds: f64,
}

impl std::fmt::Display for ShardSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let [tx0, ty0, tx1, ty1] = self.pages;
        write!(
            f,
            "{}: shard {} of {}, level-0 pages {tx0}..{tx1} × {ty0}..{ty1} ({} pages) in {:.1} s",
            self.part.display(),
            self.shard[0],
            self.shard[1],
            self.pages_made,
            self.seconds
        )
    }
}

/// Build shard `i` of `n` (from 1) of the tile file `opts` describe over `db`, with the
/// `survey` of `db`, into the part `out` and its record (see the module doc).
pub fn build_shard(
    db: &Database,
    opts: &PyramidOptions,
    survey: &Survey,
    [i, n]: [usize; 2],
    out: &Path,
    progress: &Progress,
) -> Result<ShardSummary> {
    let clock = std::time::Instant::now();
    crate::io::atomic::check_output(out)?;
    if n == 0 || i == 0 || i > n {
        return Err(
            Error::msg(format!("--shard {i}/{n}: no such shard")).fix("give I/N with 1 ≤ I ≤ N")
        );
    }
    let info = tile_set(db, opts, "--shard")?;
    let window = windows(&info, n)?[i - 1];
    let [tx0, ty0, tx1, ty1] = window;
    let photo_sun = super::photo_sun_for(db, opts)?;
    let suns = cast_suns(opts, photo_sun, survey.raised);
    let p = info.page_size;
    let g = &info.grid;
    let cells = Window {
        col: tx0 * p,
        row: ty0 * p,
        width: (tx1 * p).min(g.width) - tx0 * p,
        height: (ty1 * p).min(g.height) - ty0 * p,
    };
    let mut part_info = TileSetInfo::new(g.window_grid(&cells), p, opts.factor, Some(1))?;
    part_info.compression = opts.compression;
    // The effects' counts are the record's (they are the whole file's only when summed).
    part_info.effects = serde_json::json!({ "shard": { "index": i, "of": n, "pages": window } });
    let touched: BTreeSet<(usize, usize)> = (ty0..ty1)
        .flat_map(|ty| (tx0..tx1).map(move |tx| (tx, ty)))
        .collect();
    let writer = TileWriter::create(out, part_info)?;
    let stats = std::sync::Mutex::new(PageStats::default());
    progress.phase(touched.len() as u64, "shard");
    // The insets' covers of the base: every shard makes the insets again for them (their files
    // are the merge's to write).
    let covers = match db.insets().is_empty() {
        true => Vec::new(),
        false => super::regions::make_regions(db, out, opts, progress)?.covers,
    };
    let whole = WholeGrid {
        suns: &suns,
        terrain_range: survey.terrain,
        top: survey.top,
        raised_anywhere: survey.raised,
        covers: &covers,
    };
    incremental::make_level0(
        db,
        &info,
        opts,
        photo_sun,
        &touched,
        &whole,
        &|(tx, ty), page, s| {
            writer.write_page(0, tx - tx0, ty - ty0, page)?;
            let mut total = stats.lock().unwrap_or_else(|e| e.into_inner());
            *total = *total + s;
            progress.inc(1);
            Ok(())
        },
    )?;
    let record = ShardRecord {
        format: SHARD_FORMAT.into(),
        version: 1,
        key: incremental::key(db, &info, opts, photo_sun),
        shard: [i, n],
        pages: window,
        database: survey.database.clone(),
        raised: survey.raised,
        stats: stats.into_inner().unwrap_or_else(|e| e.into_inner()),
    };
    // The part and its record appear together: the record is renamed first, and a record
    // without its part (killed in between) is the next run's to overwrite.
    let part = writer.stage()?;
    crate::io::atomic::commit_all(vec![stage_json(&record_path(out), &record)?, part])?;
    progress.finish();
    Ok(ShardSummary {
        part: out.to_path_buf(),
        record: record_path(out),
        shard: [i, n],
        pages: window,
        pages_made: touched.len(),
        seconds: clock.elapsed().as_secs_f64(),
    })
}

/// One part opened for the merge.
struct Part {
    tiles: TileReader,
    record: ShardRecord,
}

/// Read and check the parts of one sharded build of `info` with `key`: every shard of `1..=N`
/// once, each window the one [`windows`] gives, each part the one-level tile file of its window.
fn open_parts(
    info: &TileSetInfo,
    key: &serde_json::Value,
    database: &str,
    parts: &[PathBuf],
) -> Result<Vec<Part>> {
    let n = parts.len();
    let windows = windows(info, n)?;
    let mut by_index: Vec<Option<Part>> = (0..n).map(|_| None).collect();
    for path in parts {
        let rec_path = record_path(path);
        let fix = "build it again with dbms pyramid --shard I/N and the merge's options";
        let record: ShardRecord = read_json(&rec_path, "shard record", fix)?;
        let bad = |problem: String| Err(Error::file(path, problem).fix(fix));
        if record.format != SHARD_FORMAT || record.version != 1 {
            return bad(format!(
                "{} is not a version 1 shard record",
                rec_path.display()
            ));
        }
        let [i, of] = record.shard;
        if of != n {
            return bad(format!("is shard {i} of {of}, but {n} parts are merged"));
        }
        if &record.key != key {
            return bad("was built with other options, another sun or another database".into());
        }
        if record.database != database {
            return bad("was built from another state of the database (its terrain, buildings or placements changed since)".into());
        }
        if i == 0 || i > n || record.pages != windows[i - 1] {
            return bad(format!(
                "shard {i}'s window {:?} is not this tile set's",
                record.pages
            ));
        }
        if by_index[i - 1].is_some() {
            return bad(format!("shard {i} of {n} is given twice"));
        }
        let tiles = TileReader::open(path, 4)?;
        let [tx0, ty0, tx1, ty1] = record.pages;
        let l = &tiles.info().levels;
        if l.len() != 1 || l[0].pages_x != tx1 - tx0 || l[0].pages_y != ty1 - ty0 {
            return bad("is not the one-level tile file of its window".into());
        }
        by_index[i - 1] = Some(Part { tiles, record });
    }
    let missing: Vec<String> = (1..=n)
        .filter(|i| by_index[i - 1].is_none())
        .map(|i| i.to_string())
        .collect();
    if !missing.is_empty() {
        return Err(Error::msg(format!(
            "--merge: shards {} of {n} are missing",
            missing.join(", ")
        ))
        .fix("give every part once"));
    }
    Ok(by_index.into_iter().flatten().collect())
}

/// Merge the parts of shards `1..=N` (in any order) into the tile file `out` of `db` that
/// `opts` describe, and record the `pyramid` stage (see the module doc).
pub fn merge(
    db: &Database,
    wait: std::time::Duration,
    opts: &PyramidOptions,
    parts: &[PathBuf],
    out: &Path,
    progress: &Progress,
) -> Result<PyramidSummary> {
    let mut lap = super::stopwatch();
    let mut seconds = Timings::default();
    // Nothing it writes (the tile file, its regions' files) may be a part or a part's record.
    let records: Vec<PathBuf> = parts.iter().map(|p| record_path(p)).collect();
    let inputs: Vec<&Path> = parts.iter().chain(&records).map(PathBuf::as_path).collect();
    let product = super::Product {
        tiles: out.to_path_buf(),
        sun: opts.sun,
    };
    super::check_products(db, &[product], opts, &inputs)?;
    let mut info = tile_set(db, opts, "--merge")?;
    let photo_sun = super::photo_sun_for(db, opts)?;
    let key = incremental::key(db, &info, opts, photo_sun);
    let parts = open_parts(&info, &key, &database_digest(db)?, parts)?;
    let raised = parts[0].record.raised;
    if let Some(other) = parts.iter().find(|p| p.record.raised != raised) {
        return Err(Error::file(
            other.tiles.path(),
            "was built from another survey than the other parts",
        )
        .fix("build every shard with the same survey"));
    }
    let total = parts
        .iter()
        .fold(PageStats::default(), |a, part| a + part.record.stats);
    seconds.read = lap();

    let (seen, casts) = shade::casts_for(opts.sun, photo_sun, raised);
    let counts = casts.map(|_| total.effects.unwrap_or_default());
    let record = EffectsRecord::decided(opts.sun, photo_sun, opts.shadow_factor, &seen, counts)
        .with_layers(&[], false);
    info.effects = serde_json::to_value(&record).expect("the effects record serialises");
    // The insets' tile files, made here once; the shards applied their covers.
    let made = match db.insets().is_empty() {
        true => super::regions::Made::default(),
        false => super::regions::make_regions(db, out, opts, progress)?,
    };
    info.regions = made.list;
    seconds.prepare = lap();

    // Which part holds level-0 page (tx, ty), and where in it.
    let (p, px) = (info.page_size, info.levels[0].pages_x);
    let mut owner = vec![0usize; px * info.levels[0].pages_y];
    for (k, part) in parts.iter().enumerate() {
        let [tx0, ty0, tx1, ty1] = part.record.pages;
        for ty in ty0..ty1 {
            owner[ty * px + tx0..ty * px + tx1].fill(k);
        }
    }
    let at = |tx: usize, ty: usize| {
        let part = &parts[owner[ty * px + tx]];
        let [tx0, ty0, ..] = part.record.pages;
        (part, tx - tx0, ty - ty0)
    };
    let writer = TileWriter::create(out, info.clone())?;
    progress.phase(info.page_count() as u64, "merge");
    let width = info.grid.width;
    cascade::build_levels(
        &info,
        |row0, rows| -> Result<Band> {
            let ty = row0 / p;
            let mut band = BaseRows::nodata(width, rows);
            for tx in 0..px {
                let (part, ltx, lty) = at(tx, ty);
                let page = part.tiles.page(0, ltx, lty)?;
                let cols = p.min(width - tx * p);
                for r in 0..rows {
                    let (from, to) = (r * p, r * width + tx * p);
                    band.max_z[to..to + cols].copy_from_slice(&page.max_z[from..from + cols]);
                    band.colour[to..to + cols].copy_from_slice(&page.colour[from..from + cols]);
                    band.state[to..to + cols].copy_from_slice(&page.state[from..from + cols]);
                }
            }
            Ok(band.into())
        },
        &|level, tx, ty, page| {
            progress.inc(1);
            match level {
                // Level 0 as the shard stored it: its bricks and compression untouched.
                0 => {
                    let (part, ltx, lty) = at(tx, ty);
                    let (entry, bytes) = part.tiles.stored(0, ltx, lty)?;
                    writer.write_stored(0, tx, ty, entry, bytes)
                }
                _ => writer.write_page(level, tx, ty, page),
            }
        },
    )?;
    seconds.levels = lap();
    let mut staged = made.staged;
    staged.push(writer.stage()?);
    progress.finish();
    seconds.finish = lap();
    let summary = PyramidSummary {
        regions: made.built,
        ..PyramidSummary::of_pages(out, &info, total, record, seconds)
    };
    let ready = super::Ready {
        outputs: super::Outputs::Staged(staged),
        params: super::stage_params(out, opts, &info, &summary),
        summary,
    };
    Ok(super::commit(db, wait, vec![ready])?.remove(0))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::crs::Crs;
    use crate::grid::Grid;

    fn info(w: usize, h: usize, p: usize) -> TileSetInfo {
        let g = Grid::north_up(500_000.0, 5_300_000.0, 1.0, w, h, Crs::epsg(32632));
        TileSetInfo::new(g, p, 4, None).unwrap()
    }

    /// Every level-0 page is in exactly one window, for every count that fits; windows of a
    /// row or column differ by at most one page; the shape minimises the largest window.
    #[test]
    fn windows_cover_every_page_once() {
        let t = info(1000, 700, 64); // 16 × 11 pages
        for n in 1..=40 {
            let Ok(ws) = windows(&t, n) else {
                continue;
            };
            assert_eq!(ws.len(), n);
            let mut seen = [0u8; 16 * 11];
            for [x0, y0, x1, y1] in &ws {
                assert!(x0 < x1 && y0 < y1, "{n}: empty window");
                for y in *y0..*y1 {
                    for x in *x0..*x1 {
                        seen[y * 16 + x] += 1;
                    }
                }
            }
            assert!(seen.iter().all(|&k| k == 1), "{n} shards: {ws:?}");
            let widths: Vec<usize> = ws.iter().map(|w| w[2] - w[0]).collect();
            let (lo, hi) = (widths.iter().min().unwrap(), widths.iter().max().unwrap());
            assert!(hi - lo <= 1, "{n}: {widths:?}");
        }
        // 4 shards of 16 × 11 pages: 4 × 1 (windows of 4 × 11 = 44 pages), not 2 × 2 (8 × 6 =
        // 48) or 1 × 4 (16 × 3 = 48).
        assert_eq!(windows(&t, 4).unwrap()[3], [12, 0, 16, 11]);
        // 16 × 16 pages: 2 × 2, the squarer of the equal ones.
        assert_eq!(
            windows(&info(1024, 1024, 64), 4).unwrap()[3],
            [8, 8, 16, 16]
        );
        // A prime count cuts one way only.
        assert_eq!(windows(&t, 13).unwrap().len(), 13);
        let err = windows(&t, 17).unwrap_err().to_string();
        assert!(err.contains("16 × 11 level-0 pages"), "{err}");
        assert!(windows(&t, 16 * 11).is_ok());
        assert!(windows(&t, 16 * 11 + 1).is_err());
    }
}
