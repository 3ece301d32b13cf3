//! The tile set header: geometry of the levels, the layer table and what the pyramid applied.
//!
//! Invariant: `levels[k]` is exactly what [`TileSetInfo::new`] derives from `grid`, `page_size`
//! and `factor` (width `ceil(W / f^k)`, cell size `c · f^k`, pages `ceil(width / P)`), and
//! [`TileSetInfo::validate`] checks it on write and on read, so a reader never trusts a size it
//! could not recompute. The header JSON *is* this struct serialised (schema:
//! `schemas/tiles-header.schema.json`).

use super::sensor::{LightPoint, MaterialAttributes, SensorLayer};
use crate::error::{Error, Result};
use crate::grid::{GeoTransform, Grid};
use serde::{Deserialize, Serialize};

/// Largest page edge in cells (a page of 4096² cells is 151 MB raw: larger is never useful).
pub const MAX_PAGE_SIZE: usize = 4096;
/// Most levels a tile set may have (factor 2 reaches one cell from 2³¹ cells in 32 levels).
pub const MAX_LEVELS: usize = 32;
/// Largest grid side in cells: keeps page coordinates within u32 (Morton codes) and all index
/// arithmetic exact.
const MAX_GRID_SIDE: usize = 1 << 31;
/// Most pages a tile set may have (the writer keeps 32 bytes of bookkeeping per page in memory).
const MAX_PAGES: usize = 1 << 28;
/// Largest JSON header a reader accepts, bytes (a real one is a few kilobytes; light points
/// take about 110 bytes each), and so the largest a writer writes.
pub const MAX_HEADER_LEN: u64 = 16 << 20;
/// Alignment of every page's offset in the file, bytes (a memory page; direct I/O friendly).
pub const PAGE_ALIGN: u64 = 4096;

/// How page bytes are stored. The header records the writer's policy; each page's index flags
/// record what was actually done (a page that lz4 does not shrink is stored raw).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum Compression {
    /// Pages stored raw: a page can be used straight from a mapping.
    #[default]
    None,
    /// Each page compressed as one lz4 block (`lz4_flex::block`, no size prefix).
    Lz4,
}

impl Compression {
    /// Parse a `--compression` value: `none` or `lz4`.
    pub fn parse(s: &str) -> Result<Compression> {
        match s {
            "none" => Ok(Compression::None),
            "lz4" => Ok(Compression::Lz4),
            _ => Err(
                Error::msg(format!("--compression {s}: unknown compression"))
                    .fix("use none or lz4"),
            ),
        }
    }

    /// The name used in the header and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Compression::None => "none",
            Compression::Lz4 => "lz4",
        }
    }
}

/// Order of page data in the file (the index is always level-major, row-major).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize, Default)]
pub enum PageOrder {
    /// Coarsest level first, down to level 0; within a level, Z-order (Morton) of `(tx, ty)`.
    #[default]
    #[serde(rename = "coarse-first-morton")]
    CoarseFirstMorton,
}

/// One level of the hierarchy.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LevelInfo {
    /// Level number: 0 is the database grid, each next level is `factor` times coarser.
    pub level: usize,
    /// Width in cells: `ceil(W / factor^level)`.
    pub width: usize,
    /// Height in cells: `ceil(H / factor^level)`.
    pub height: usize,
    /// Cell width in CRS units (level 0's `cell_x · factor^level`).
    pub cell_x: f64,
    /// Cell height in CRS units (negative for north-up, like [`GeoTransform::cell_y`]).
    pub cell_y: f64,
    /// Pages across: `ceil(width / page_size)`.
    pub pages_x: usize,
    /// Pages down: `ceil(height / page_size)`.
    pub pages_y: usize,
}

impl LevelInfo {
    /// Number of pages of this level.
    pub fn pages(&self) -> usize {
        self.pages_x * self.pages_y
    }
}

/// One fixed-size per-cell layer of a page, as listed in the header's layer table. Pages store
/// the layers one after the other, in table order, each `page_size² · bytes_per_cell` bytes.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct LayerInfo {
    /// Layer name; readers look layers up by name and skip those they do not know.
    pub name: String,
    /// Cell type: `f32` (little-endian IEEE 754), `rgba8` (4 bytes r, g, b, a) or `u8`.
    #[serde(rename = "type")]
    pub kind: String,
    /// Bytes per cell (lets a reader skip a layer whose type it does not know).
    pub bytes_per_cell: usize,
    /// What a nodata cell holds.
    pub nodata: String,
    /// What the value means, with its unit.
    pub description: String,
}

impl LayerInfo {
    pub(crate) fn new(
        name: &str,
        kind: &str,
        bytes_per_cell: usize,
        nodata: &str,
        description: &str,
    ) -> LayerInfo {
        LayerInfo {
            name: name.into(),
            kind: kind.into(),
            bytes_per_cell,
            nodata: nodata.into(),
            description: description.into(),
        }
    }
}

/// The layer table of format version 1: `max_z`, `colour`, `state`, in this order.
pub fn standard_layers() -> Vec<LayerInfo> {
    vec![
        LayerInfo::new("max_z", "f32", 4, "NaN", "maximum height in the cell, metres; coarse levels hold the exact max of their children"),
        LayerInfo::new("colour", "rgba8", 4, "alpha 0", "average colour of the visible top surface, 8-bit RGBA"),
        LayerInfo::new("state", "u8", 1, "0", "voxel occupancy: 0 empty/nodata, 1 partial (consult the page's bricks), 2 opaque height-field column"),
    ]
}

/// Format of the per-page `bricks` blob: level-0 partial cells' solid z-runs, as
/// [`crate::voxel::columns`] encodes them (spec: `docs/tile-format.md`, "Bricks"). A reader that
/// meets another string must not interpret the blobs.
pub const BRICKS_FORMAT: &str = "dbms voxel columns 1";

/// Everything a tile file's header says: the description of the whole tile set.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct TileSetInfo {
    /// Version of dbms that wrote the file (informative).
    pub dbms_version: String,
    /// Page edge in cells: every page holds `page_size × page_size` cells.
    pub page_size: usize,
    /// Ratio of cell sizes between consecutive levels: 2 or 4.
    pub factor: usize,
    /// Level 0's georeference: the database grid (size, corner transform, CRS).
    pub grid: Grid,
    /// The levels, finest (0) first.
    pub levels: Vec<LevelInfo>,
    /// Per-cell layers, in the order they are stored in a page.
    pub layers: Vec<LayerInfo>,
    /// Format of the optional per-page `bricks` blob (see [`BRICKS_FORMAT`]).
    pub bricks: String,
    /// The writer's compression policy (each page's flags say what was done to it).
    pub compression: Compression,
    /// Order of page data in the file.
    pub page_order: PageOrder,
    /// Every page offset is a multiple of this many bytes.
    pub alignment: u64,
    /// The shading and shadow effects baked into the colours (free-form object the pyramid fills).
    pub effects: serde_json::Value,
    /// Light points for the night sensors; absent (empty) unless the pyramid was given some.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub lights: Vec<LightPoint>,
    /// What the sensor views need of each material of the `material` layer; absent (empty)
    /// without that layer.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub materials: Vec<MaterialAttributes>,
    /// The tile set's finer regions (the database's insets), parents first, each its own tile
    /// file beside this one ([`super::region`]); absent (empty) without insets.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub regions: Vec<super::region::Region>,
}

impl TileSetInfo {
    /// The tile set over `grid` with pages of `page_size²` cells and levels `factor` apart.
    /// `levels: None` makes levels down to the first that fits in one page; `Some(n)` makes
    /// exactly `n` levels. Compression is `none` and effects `{}` until the caller sets them.
    pub fn new(
        grid: Grid,
        page_size: usize,
        factor: usize,
        levels: Option<usize>,
    ) -> Result<TileSetInfo> {
        check_params(&grid, page_size, factor)?;
        let n = match levels {
            None => natural_levels(grid.width, grid.height, page_size, factor),
            Some(n) if (1..=MAX_LEVELS).contains(&n) => n,
            Some(n) => {
                return Err(Error::msg(format!(
                    "--levels {n}: must be 1 to {MAX_LEVELS}"
                )))
            }
        };
        let levels = derive_levels(
            &grid.transform,
            grid.width,
            grid.height,
            page_size,
            factor,
            n,
        );
        check_page_count(&levels)?;
        Ok(TileSetInfo {
            dbms_version: env!("CARGO_PKG_VERSION").to_string(),
            page_size,
            factor,
            grid,
            levels,
            layers: standard_layers(),
            bricks: BRICKS_FORMAT.to_string(),
            compression: Compression::None,
            page_order: PageOrder::CoarseFirstMorton,
            alignment: PAGE_ALIGN,
            effects: serde_json::json!({}),
            lights: Vec::new(),
            materials: Vec::new(),
            regions: Vec::new(),
        })
    }

    /// Check every derived field against the parameters (see the module invariant). The error
    /// has no path; callers attach the file's.
    pub fn validate(&self) -> Result<()> {
        check_params(&self.grid, self.page_size, self.factor)?;
        let n = self.levels.len();
        if !(1..=MAX_LEVELS).contains(&n) {
            return Err(Error::msg(format!(
                "header lists {n} levels, expected 1 to {MAX_LEVELS}"
            )));
        }
        let g = &self.grid;
        let want = derive_levels(
            &g.transform,
            g.width,
            g.height,
            self.page_size,
            self.factor,
            n,
        );
        if let Some(k) = (0..n).find(|&k| want[k] != self.levels[k]) {
            return Err(Error::msg(format!(
                "header's level {k} does not follow from the grid, page size and factor"
            )));
        }
        check_page_count(&self.levels)?;
        super::region::check(&self.regions, &self.grid)?;
        for (i, l) in self.layers.iter().enumerate() {
            if self.layers[..i].iter().any(|other| other.name == l.name) {
                return Err(Error::msg(format!(
                    "the layer table lists {} twice",
                    l.name
                )));
            }
            if l.bytes_per_cell == 0 || l.bytes_per_cell > 64 {
                return Err(Error::msg(format!(
                    "layer {} has {} bytes per cell, expected 1 to 64",
                    l.name, l.bytes_per_cell
                )));
            }
        }
        // A sensor layer is optional, but when present it has its own type.
        let sensor = self.sensor_layers().into_iter().map(SensorLayer::info);
        for want in standard_layers().into_iter().chain(sensor) {
            match self.layers.iter().find(|l| l.name == want.name) {
                Some(l) if l.kind == want.kind && l.bytes_per_cell == want.bytes_per_cell => {}
                Some(l) => {
                    return Err(Error::msg(format!(
                        "layer {} has type {} of {} bytes per cell, expected {} of {}",
                        l.name, l.kind, l.bytes_per_cell, want.kind, want.bytes_per_cell
                    )));
                }
                None => {
                    return Err(Error::msg(format!(
                        "the layer table has no {} layer",
                        want.name
                    )))
                }
            }
        }
        if !self.alignment.is_power_of_two() || self.alignment < 8 {
            return Err(Error::msg(format!(
                "alignment {} is not a power of two of at least 8",
                self.alignment
            )));
        }
        if !self.effects.is_object() {
            return Err(Error::msg("header's effects is not a JSON object"));
        }
        super::sensor::check_attributes(&self.lights, &self.materials)
            .map_err(|e| Error::msg(format!("header: {e}")))?;
        Ok(())
    }

    /// The sensor layers the layer table holds, in table order.
    pub fn sensor_layers(&self) -> Vec<SensorLayer> {
        let named = self
            .layers
            .iter()
            .filter_map(|l| SensorLayer::named(&l.name));
        named.collect()
    }

    /// This tile set with `layers` added after the standard layers, in [`SensorLayer::ALL`]'s
    /// order (the only layer tables this dbms writes).
    pub fn with_sensor_layers(mut self, layers: &[SensorLayer]) -> TileSetInfo {
        let wanted = SensorLayer::ALL.into_iter().filter(|l| layers.contains(l));
        self.layers = standard_layers();
        self.layers.extend(wanted.map(SensorLayer::info));
        self
    }

    /// Whether the layer table is one this dbms writes: the standard layers, then sensor
    /// layers in [`SensorLayer::ALL`]'s order.
    pub fn writable_layers(&self) -> bool {
        let sensor = self.sensor_layers();
        self.clone().with_sensor_layers(&sensor).layers == self.layers
    }

    /// The georeferenced grid of `level` (same corner as level 0, cells `factor^level` larger).
    pub fn level_grid(&self, level: usize) -> Grid {
        let l = &self.levels[level];
        Grid {
            width: l.width,
            height: l.height,
            transform: GeoTransform {
                cell_x: l.cell_x,
                cell_y: l.cell_y,
                ..self.grid.transform
            },
            crs: self.grid.crs.clone(),
        }
    }

    /// Cells per page: `page_size²`.
    pub fn page_cells(&self) -> usize {
        self.page_size * self.page_size
    }

    /// Total number of pages over all levels.
    pub fn page_count(&self) -> usize {
        self.levels.iter().map(LevelInfo::pages).sum()
    }

    /// Position in the index of the first page of `level`: the pages of all finer levels.
    pub fn level_base(&self, level: usize) -> usize {
        self.levels[..level].iter().map(LevelInfo::pages).sum()
    }

    /// Position of page `(level, tx, ty)` in the index — `level_base + ty · pages_x + tx` — or
    /// `None` when there is no such page.
    pub fn index_position(&self, level: usize, tx: usize, ty: usize) -> Option<usize> {
        let l = self.levels.get(level)?;
        (tx < l.pages_x && ty < l.pages_y).then(|| self.level_base(level) + ty * l.pages_x + tx)
    }

    /// [`index_position`](Self::index_position), or the error of the tile file `path` for a
    /// page outside the tile set.
    pub(crate) fn page_position(
        &self,
        path: &std::path::Path,
        (level, tx, ty): (usize, usize, usize),
    ) -> Result<usize> {
        self.index_position(level, tx, ty).ok_or_else(|| {
            Error::file(
                path,
                format!("page (level {level}, {tx}, {ty}) is outside the tile set"),
            )
        })
    }

    /// The page `(level, tx, ty)` at index position `pos` (inverse of
    /// [`index_position`](Self::index_position)), or `None` beyond the last page.
    pub fn page_at(&self, mut pos: usize) -> Option<(usize, usize, usize)> {
        for l in &self.levels {
            if pos < l.pages() {
                return Some((l.level, pos % l.pages_x, pos / l.pages_x));
            }
            pos -= l.pages();
        }
        None
    }

    /// Number of valid (non-padding) columns and rows of page `(level, tx, ty)`.
    pub fn page_extent(&self, level: usize, tx: usize, ty: usize) -> (usize, usize) {
        let l = &self.levels[level];
        let p = self.page_size;
        (p.min(l.width - tx * p), p.min(l.height - ty * p))
    }
}

fn check_params(grid: &Grid, page_size: usize, factor: usize) -> Result<()> {
    if !(1..=MAX_PAGE_SIZE).contains(&page_size) {
        return Err(Error::msg(format!(
            "--page {page_size}: page size must be 1 to {MAX_PAGE_SIZE} cells"
        ))
        .fix("the default is 256"));
    }
    if factor != 2 && factor != 4 {
        return Err(Error::msg(format!(
            "--factor {factor}: factor must be 2 or 4"
        )));
    }
    let (w, h) = (grid.width, grid.height);
    if !(1..=MAX_GRID_SIDE).contains(&w) || !(1..=MAX_GRID_SIDE).contains(&h) {
        return Err(Error::msg(format!(
            "the grid is {w}×{h} cells, expected 1 to {MAX_GRID_SIDE} on each side"
        )));
    }
    let t = &grid.transform;
    let finite = [t.origin_x, t.origin_y, t.cell_x, t.cell_y]
        .iter()
        .all(|v| v.is_finite());
    if !finite || t.cell_x <= 0.0 || t.cell_y == 0.0 {
        return Err(Error::msg(format!(
            "the grid's transform (origin {}, {}; cell {}, {}) is not a north-up grid with finite non-zero cells",
            t.origin_x, t.origin_y, t.cell_x, t.cell_y
        )));
    }
    Ok(())
}

fn check_page_count(levels: &[LevelInfo]) -> Result<()> {
    let n: usize = levels.iter().map(LevelInfo::pages).sum();
    if n > MAX_PAGES {
        return Err(Error::msg(format!(
            "the tile set would have {n} pages, over the limit of {MAX_PAGES}"
        ))
        .fix("use a larger --page"));
    }
    Ok(())
}

/// Levels needed until one fits in a single page.
fn natural_levels(width: usize, height: usize, page_size: usize, factor: usize) -> usize {
    let (mut w, mut h, mut n) = (width, height, 1);
    while (w > page_size || h > page_size) && n < MAX_LEVELS {
        w = w.div_ceil(factor);
        h = h.div_ceil(factor);
        n += 1;
    }
    n
}

fn derive_levels(
    t: &GeoTransform,
    width: usize,
    height: usize,
    page: usize,
    factor: usize,
    n: usize,
) -> Vec<LevelInfo> {
    let (mut w, mut h, mut scale) = (width, height, 1.0f64);
    (0..n)
        .map(|level| {
            // ceil(ceil(W / f^k) / f) = ceil(W / f^(k+1)); scale is a power of two: exact.
            let l = LevelInfo {
                level,
                width: w,
                height: h,
                cell_x: t.cell_x * scale,
                cell_y: t.cell_y * scale,
                pages_x: w.div_ceil(page),
                pages_y: h.div_ceil(page),
            };
            w = w.div_ceil(factor);
            h = h.div_ceil(factor);
            scale *= factor as f64;
            l
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::crs::Crs;

    fn grid(w: usize, h: usize) -> Grid {
        Grid::north_up(500_000.0, 5_000_000.0, 0.5, w, h, Crs::epsg(32614))
    }

    #[test]
    fn levels_go_down_to_one_page() {
        let info = TileSetInfo::new(grid(1000, 300), 256, 4, None).unwrap();
        let sizes: Vec<_> = info
            .levels
            .iter()
            .map(|l| (l.width, l.height, l.pages_x, l.pages_y))
            .collect();
        assert_eq!(sizes, vec![(1000, 300, 4, 2), (250, 75, 1, 1)]);
        assert_eq!(info.levels[1].cell_x, 2.0);
        assert_eq!(info.levels[1].cell_y, -2.0);
        let info = TileSetInfo::new(grid(1000, 300), 16, 2, None).unwrap();
        let last = info.levels.last().unwrap();
        assert!(last.width <= 16 && last.height <= 16);
        let prev = &info.levels[info.levels.len() - 2];
        assert!(prev.width > 16 || prev.height > 16);
        // ceil at every level: 1000 → 500 → 250 → 125 → 63 → 32 → 16
        assert_eq!(
            info.levels.iter().map(|l| l.width).collect::<Vec<_>>(),
            vec![1000, 500, 250, 125, 63, 32, 16]
        );
    }

    #[test]
    fn grid_smaller_than_a_page_has_one_level() {
        let info = TileSetInfo::new(grid(3, 5), 256, 4, None).unwrap();
        assert_eq!(info.levels.len(), 1);
        assert_eq!(info.page_count(), 1);
        assert_eq!(info.page_extent(0, 0, 0), (3, 5));
    }

    #[test]
    fn explicit_level_count_and_bad_parameters() {
        let info = TileSetInfo::new(grid(100, 100), 8, 4, Some(6)).unwrap();
        assert_eq!(info.levels.len(), 6);
        assert_eq!((info.levels[5].width, info.levels[5].height), (1, 1));
        assert!(TileSetInfo::new(grid(100, 100), 8, 3, None).is_err());
        assert!(TileSetInfo::new(grid(100, 100), 0, 4, None).is_err());
        assert!(TileSetInfo::new(grid(100, 100), 8, 4, Some(0)).is_err());
        assert!(TileSetInfo::new(grid(0, 100), 8, 4, None).is_err());
        assert!(TileSetInfo::new(grid(1 << 32, 100), 256, 4, None).is_err());
        let err = TileSetInfo::new(grid(1 << 20, 1 << 20), 1, 4, None).unwrap_err();
        assert!(err.to_string().contains("use a larger --page"), "{err}");
        let mut g = grid(10, 10);
        g.transform.cell_x = f64::NAN;
        assert!(TileSetInfo::new(g, 8, 4, None).is_err());
        let mut g = grid(10, 10);
        g.transform.cell_y = 0.0;
        assert!(TileSetInfo::new(g, 8, 4, None).is_err());
    }

    #[test]
    fn index_position_is_level_base_plus_row_major() {
        let info = TileSetInfo::new(grid(1000, 300), 64, 2, None).unwrap();
        let mut pos = 0;
        for l in &info.levels {
            for ty in 0..l.pages_y {
                for tx in 0..l.pages_x {
                    assert_eq!(info.index_position(l.level, tx, ty), Some(pos));
                    assert_eq!(info.page_at(pos), Some((l.level, tx, ty)));
                    pos += 1;
                }
            }
            assert_eq!(info.index_position(l.level, l.pages_x, 0), None);
        }
        assert_eq!(pos, info.page_count());
        assert_eq!(info.page_at(pos), None);
        assert_eq!(info.index_position(info.levels.len(), 0, 0), None);
    }

    #[test]
    fn validate_rejects_tampered_levels_and_layers() {
        let info = TileSetInfo::new(grid(1000, 300), 64, 4, None).unwrap();
        info.validate().unwrap();
        let mut bad = info.clone();
        bad.levels[1].width += 1;
        assert!(bad.validate().unwrap_err().problem.contains("level 1"));
        let mut bad = info.clone();
        bad.layers.retain(|l| l.name != "state");
        assert!(bad.validate().unwrap_err().problem.contains("state"));
        let mut bad = info.clone();
        bad.layers.push(bad.layers[0].clone());
        assert!(bad.validate().unwrap_err().problem.contains("max_z twice"));
        let mut bad = info.clone();
        bad.effects = serde_json::json!([1]);
        assert!(bad.validate().is_err());
        // Extra layers are allowed: readers skip what they do not know.
        let mut grown = info;
        grown
            .layers
            .push(LayerInfo::new("temperature", "f32", 4, "NaN", "kelvin"));
        grown.validate().unwrap();
    }

    #[test]
    fn level_grid_keeps_the_corner() {
        let info = TileSetInfo::new(grid(1000, 300), 64, 4, None).unwrap();
        let g = info.level_grid(2);
        assert_eq!(
            g.transform.pixel_to_world(0.0, 0.0),
            (500_000.0, 5_000_000.0)
        );
        assert_eq!(g.cell_size(), (8.0, 8.0));
        assert_eq!((g.width, g.height), (63, 19));
    }
}
