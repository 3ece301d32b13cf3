//! What a pyramid run reports: the tile file's levels and pages, the effects baked in, the
//! sensor layers, and each step's wall-clock time (the CLI's summary, `--json`, the manifest's
//! stage record).

use super::{incremental, regions, shade};
use crate::tiles::TileSetInfo;
use serde::Serialize;
use std::path::{Path, PathBuf};

/// What was built, for the CLI summary, `--json` and the manifest's stage record.
#[derive(Debug, Clone, Serialize)]
pub struct PyramidSummary {
    /// The tile file.
    pub tiles: PathBuf,
    /// `(width, height)` of each level, finest first.
    pub levels: Vec<(usize, usize)>,
    /// Pages written.
    pub pages: usize,
    /// Pages made (the others were copied from the earlier tile file): all of them in a full
    /// build.
    pub pages_rebuilt: usize,
    /// Whether the earlier tile file was changed in place (only the pages made again and its
    /// front written: every other page kept its offset) rather than written anew.
    pub in_place: bool,
    /// With `--incremental`, why every page was made (no ledger, options changed, ...);
    /// absent when only the changed pages were.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub full_build: Option<String>,
    /// What the user is warned of on stderr (not in `--json`: `full_build` says it there): a
    /// ledger or earlier tile file found edited or damaged, so every page was made again.
    #[serde(skip)]
    pub warnings: Vec<String>,
    /// In a run of several products ([`build_pyramids`](super::build_pyramids)), what this one took from an earlier
    /// one instead of making it again, in words (casts, detected shadows, what stands).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub reused: Vec<String>,
    /// Level-0 cells raised by buildings.
    pub building_cells: usize,
    /// Level-0 cells covered by placed objects.
    pub object_cells: usize,
    /// Level-0 cells with state partial (object overhangs or holes).
    pub partial_cells: usize,
    /// Cells dropped to nodata because only one of elevation and colour was valid.
    pub half_valid_cells: usize,
    /// The effects record (also in the tile header and the manifest).
    pub effects: shade::EffectsRecord,
    /// GeoTIFFs written by `--export-levels`.
    pub exported: Vec<PathBuf>,
    /// The tile files of the database's insets, written with this one ([`regions`]).
    #[serde(skip_serializing_if = "Vec::is_empty")]
    pub regions: Vec<regions::RegionBuilt>,
    /// Where the time went (not recorded in the manifest: it would break reproducibility).
    pub seconds: Timings,
}

impl std::fmt::Display for PyramidSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let sizes: Vec<String> = self
            .levels
            .iter()
            .map(|(w, h)| format!("{w}×{h}"))
            .collect();
        write!(
            f,
            "{}: {} levels ({}), {} pages",
            self.tiles.display(),
            self.levels.len(),
            sizes.join(", "),
            self.pages
        )?;
        if self.pages_rebuilt < self.pages {
            let rest = match self.in_place {
                true => "the file changed in place",
                false => "the rest copied",
            };
            write!(f, " ({} made again, {rest})", self.pages_rebuilt)?;
        }
        if let Some(why) = &self.full_build {
            write!(f, "\nfull build: {why}")?;
        }
        if !self.reused.is_empty() {
            write!(f, "\nshared: {}", self.reused.join("; "))?;
        }
        let applied = &self.effects.applied;
        match applied.is_empty() {
            true => write!(f, "\neffects: none")?,
            false => write!(f, "\neffects: {}", applied.join(", "))?,
        }
        if self.building_cells + self.object_cells > 0 {
            write!(
                f,
                "\nraised: {} building cells, {} object cells ({} partial)",
                self.building_cells, self.object_cells, self.partial_cells
            )?;
        }
        if self.half_valid_cells > 0 {
            write!(
                f,
                "\nnodata: {} cells had only one of elevation and colour",
                self.half_valid_cells
            )?;
        }
        if !self.exported.is_empty() {
            write!(f, "\nexported {} GeoTIFFs", self.exported.len())?;
        }
        for r in &self.regions {
            write!(f, "\nregion {r}")?;
        }
        Ok(())
    }
}

impl PyramidSummary {
    /// The summary of the tile file `out` described by `info`, every page made, whose counts
    /// are `total` (for a build that makes pages apart from the whole grid, incremental or
    /// merged from shards, the sums of its level-0 pages') and whose effects record is
    /// `effects`; nothing reused, exported or in regions.
    pub(super) fn of_pages(
        out: &Path,
        info: &TileSetInfo,
        total: incremental::PageStats,
        effects: shade::EffectsRecord,
        seconds: Timings,
    ) -> PyramidSummary {
        PyramidSummary {
            tiles: out.to_path_buf(),
            levels: info.levels.iter().map(|l| (l.width, l.height)).collect(),
            pages: info.page_count(),
            pages_rebuilt: info.page_count(),
            in_place: false,
            full_build: None,
            warnings: Vec::new(),
            reused: Vec::new(),
            building_cells: total.building_cells,
            object_cells: total.object_cells,
            partial_cells: total.partial_cells,
            half_valid_cells: total.half_valid_cells,
            effects,
            exported: Vec::new(),
            regions: Vec::new(),
            seconds,
        }
    }
}

/// Wall-clock seconds of each step of [`build_pyramid`](super::build_pyramid).
#[derive(Debug, Clone, Copy, Default, Serialize)]
pub struct Timings {
    /// Opening the elevation and colour layers (they are decoded band by band in `levels`).
    pub read: f64,
    /// Buildings, objects and sun effects (shadow casts) prepared for the whole grid.
    pub prepare: f64,
    /// The hierarchy: level-0 bands (the layers decoded band by band), reductions, pages encoded
    /// and written by the tile writer. Incremental: the pages made again (coarse cells folded).
    pub levels: f64,
    /// The tile writer's finish (index and fsync; a copy into canonical order only with lz4 or
    /// bricks) and the export's (the renames come after the manifest's change). Incremental:
    /// the file changed in place or written anew, and the ledger.
    pub finish: f64,
}
