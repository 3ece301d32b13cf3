//! The tile set of a database with insets: one tile file per inset beside the base's, each
//! parent's level-0 cells over an inset holding its reduction (issue 19 item 2).
//!
//! Invariant: a tile set's regions are its database's insets, parents first in the base
//! header's `regions`; each region's file is the tile file a `dbms pyramid` of the inset's
//! database with the same options writes, except for its cells over its own insets; and every
//! parent cell under a region's window is covered ([`cover_band`]): its `max_z` is at least the
//! highest region cell under it, so the parent's max-Z hierarchy bounds the region. Regions are
//! built finest first, before their parents.
//!
//! What a region does not get yet: the parent's terrain outside its window does not shade it
//! (each region casts its own shadows), sensor layers, and the base's `--export-levels`.

use super::cascade::Band;
use super::{make_product, PyramidOptions, SensorInputs, Shared};
use crate::db::Database;
use crate::error::Result;
use crate::io::atomic::Staged;
use crate::progress::Progress;
use crate::tiles::region::{Cover, Region};
use crate::tiles::{TileReader, STATE_OPAQUE, STATE_PARTIAL};
use serde::Serialize;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// One region built with a tile file, for the summary.
#[derive(Debug, Clone, Serialize)]
pub struct RegionBuilt {
    /// The inset's name.
    pub name: String,
    /// Its tile file.
    pub tiles: PathBuf,
    /// `(width, height)` of each of its levels, finest first.
    pub levels: Vec<(usize, usize)>,
    /// Its pages.
    pub pages: usize,
}

impl std::fmt::Display for RegionBuilt {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let (w, h) = self.levels.first().copied().unwrap_or_default();
        write!(
            f,
            "{}: {} ({} levels from {w}×{h}, {} pages)",
            self.name,
            self.tiles.display(),
            self.levels.len(),
            self.pages
        )
    }
}

/// What the regions under one tile file give it: their staged files (renamed with it), the
/// summary of each, the header's `regions` and the covers of its own level 0.
#[derive(Default)]
pub struct Made {
    /// The regions' tile files, written, not yet renamed.
    pub staged: Vec<Staged>,
    /// What each is.
    pub built: Vec<RegionBuilt>,
    /// The header's `regions`, parents first (empty below the base).
    pub list: Vec<Region>,
    /// The reductions of this tile file's own regions onto its level 0.
    pub covers: Vec<Cover>,
}

/// The tile file of region `name` beside the base tile file `out`: `STEM.NAME.EXT`
/// (`tiles.dbt` → `tiles.town.dbt`).
pub fn region_file(out: &Path, name: &str) -> PathBuf {
    let stem = out.file_stem().unwrap_or_default().to_string_lossy();
    let file = match out.extension() {
        Some(ext) => format!("{stem}.{name}.{}", ext.to_string_lossy()),
        None => format!("{stem}.{name}"),
    };
    out.with_file_name(file)
}

/// Make the tile file of every inset of `db` for the base tile file `out`, finest first, each
/// with `opts`' geometry and sun (no sensor layers, levels exported or ledger) and the base's
/// buildings and placements standing on it at its resolution: what the base needs of them
/// ([`Made`]).
pub fn make_regions(
    db: &Database,
    out: &Path,
    opts: &PyramidOptions,
    progress: &Progress,
) -> Result<Made> {
    let specs = db.insets();
    let inset_opts = PyramidOptions {
        export_levels: None,
        incremental: false,
        sensor: SensorInputs::default(),
        ..opts.clone()
    };
    let mut covers: HashMap<Option<String>, Vec<Cover>> = HashMap::new();
    let mut made = Made::default();
    for spec in specs.iter().rev() {
        let path = region_file(out, &spec.name);
        crate::io::atomic::check_output(&path)?;
        let inset = db.open_inset(&spec.name)?;
        let below = Made {
            covers: covers.remove(&Some(spec.name.clone())).unwrap_or_default(),
            ..Made::default()
        };
        let (mut staged, _, summary) = make_product(
            &inset,
            db,
            &path,
            &inset_opts,
            &Shared::default(),
            progress,
            below,
        )?;
        let tiles = staged.pop().expect("the tile file is staged last");
        let reader = TileReader::open(tiles.written(), 16)?;
        covers
            .entry(spec.parent.clone())
            .or_default()
            .push(Cover::of(spec, &reader)?);
        made.list.push(Region {
            name: spec.name.clone(),
            parent: spec.parent.clone(),
            factor: spec.factor,
            window: spec.window,
            file: path
                .file_name()
                .unwrap_or_default()
                .to_string_lossy()
                .into_owned(),
            tiles: super::incremental::stamp(&tiles)?,
        });
        made.built.push(RegionBuilt {
            name: spec.name.clone(),
            tiles: path,
            levels: summary.levels,
            pages: summary.pages,
        });
        made.staged.push(tiles);
    }
    made.list.reverse();
    made.built.reverse();
    made.covers = covers.remove(&None).unwrap_or_default();
    Ok(made)
}

/// Put `covers` into the level-0 band at grid row `row0` ([`crate::tiles::region`]): a cell
/// under a region whose own column is lower than the region's highest cell there (or has no
/// data) is raised to it, opaque, without a voxel column; it keeps its own colour, or takes
/// the region's average where it had none. Every other cell stays as it is.
pub fn cover_band(covers: &[Cover], row0: usize, band: &mut Band) {
    let rows = &mut band.rows;
    let w = rows.width;
    let n = rows.max_z.len() / w.max(1);
    let mut dropped = Vec::new();
    for c in covers {
        let win = &c.window;
        for row in win.row0.max(row0)..win.row1.min(row0 + n) {
            for col in win.col0..win.col1 {
                let Some((top, colour)) = c.at(col, row) else {
                    continue; // no data of the region here: the cell's own column stands
                };
                let i = (row - row0) * w + col;
                let own = rows.max_z[i];
                if own >= top {
                    continue; // its own column already bounds the region
                }
                if rows.state[i] == STATE_PARTIAL {
                    dropped.push(i);
                }
                if own.is_nan() {
                    rows.colour[i] = colour;
                }
                (rows.max_z[i], rows.state[i]) = (top, STATE_OPAQUE);
            }
        }
    }
    if !dropped.is_empty() {
        dropped.sort_unstable();
        band.columns
            .retain(|(i, _)| dropped.binary_search(i).is_err());
    }
}
