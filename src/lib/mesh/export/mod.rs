//! `dbms export mesh`: a database as a 3D Tiles 1.1 tileset of glTF 2.0 binaries.
//!
//! **Levels.** Level 0 cuts the grid into tiles of `tile_cells` × `tile_cells` cells; level `L`
//! has tiles `factor^L` times as wide, like the pyramid's levels, up to the one level whose
//! single tile covers the grid (the tileset's root). Each tile of level `L` triangulates the
//! terrain's points (cell centres) taken every `s = factor^L` cells, with the last point of the
//! grid always kept, simplified ([`super::tin`]) to `max_error_m · s` vertically. Neighbouring
//! tiles of a level share their edge points, so a level has no cracks. The orthophoto is draped
//! over each tile as an image with a texel per point: the photo's cell at level 0, its average
//! over the `s × s` cells around each point above (the pyramid's average colour).
//!
//! **What stands.** Every level holds every building (a [`super::prisms`] prism with its
//! roof's average photo colour, walls from the level's bound below the lowest terrain under
//! it) and every placed voxel object ([`super::voxels`]), in the tile holding the centre of
//! the building's box or the object's anchor.
//!
//! **Errors.** Each tile's terrain is measured against every level-0 point it owns (a tile owns
//! the points of its cells; the grid's last row and column belong to the last tiles), streamed
//! in bands of rows: largest and root-mean-square vertical difference, and the valid points no
//! triangle covers (next to nodata, and so none elsewhere). A tile's geometric error is the
//! largest of its own measured error, its points' spacing (the detail across the ground its
//! terrain and drape cannot show) and its children's geometric errors; leaves have 0.
//!
//! **Files.** `DIR/tileset.json` and `DIR/tiles/L/X_Y.glb` (X east, Y south from the grid's
//! north-west tile), written beside each other as one commit: the glTF files first, the tileset
//! last; `.glb` files an earlier export left under `DIR/tiles` that this one did not write are
//! removed after. Same database and options, same bytes.

use super::tileset::{apply, relative, tileset_json, translation, Frame, Matrix, Tile};
use crate::db::{Database, COLOUR};
use crate::error::{Error, Result};
use crate::grid::Grid;
use crate::io::atomic::{commit_all, AtomicFile, Staged};
use crate::progress::Progress;
use crate::raster::RowSource;
use rayon::prelude::*;
use serde::Serialize;
use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};

mod standing;
mod tile;
use standing::standing_meshes;
use tile::{build_tile, Built};

/// What `dbms export mesh` is asked for.
#[derive(Debug, Clone, PartialEq)]
pub struct MeshOptions {
    /// Vertical error bound of level 0's terrain, metres (level `L`'s is this times
    /// `factor^L`).
    pub max_error_m: f64,
    /// Cells along a level-0 tile's side.
    pub tile_cells: usize,
    /// How many times wider each level's tiles are than the level below's (2–8).
    pub factor: usize,
}

impl Default for MeshOptions {
    fn default() -> MeshOptions {
        MeshOptions {
            max_error_m: 0.1,
            tile_cells: 256,
            factor: 4,
        }
    }
}

/// One level of an export: its tiles, triangles, bytes and how far its terrain is from level 0.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LevelStats {
    /// 0 = finest.
    pub level: u32,
    /// Spacing of the terrain's points, metres.
    pub point_spacing_m: f64,
    /// The vertical error bound the terrain was simplified to, metres (against its own points).
    pub bound_m: f64,
    /// Tiles with content.
    pub tiles: usize,
    /// Triangles of terrain.
    pub terrain_triangles: u64,
    /// Triangles in all (terrain, buildings, objects).
    pub triangles: u64,
    /// Bytes of the level's glTF files.
    pub bytes: u64,
    /// Largest vertical difference from the level-0 grid, metres.
    pub max_error_m: f64,
    /// Root-mean-square vertical difference from the level-0 grid, metres.
    pub rms_error_m: f64,
    /// Valid level-0 points that no terrain triangle covers (next to nodata).
    pub uncovered_points: u64,
    /// Largest distance (metres) between where a tile's frame puts a corner of the tile's cells
    /// on the globe and where the CRS's exact projection puts it (`None`: not on the globe).
    pub placement_error_m: Option<f64>,
}

/// What an export wrote.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MeshSummary {
    /// The tileset written.
    pub tileset: PathBuf,
    /// Per level, finest first.
    pub levels: Vec<LevelStats>,
    /// Buildings meshed (each level holds all of them).
    pub buildings: usize,
    /// Buildings left out because no valid terrain lies under them.
    pub buildings_over_nodata: usize,
    /// Placed voxel objects meshed.
    pub objects: usize,
    /// glTF files written.
    pub files: usize,
    /// Bytes written, the tileset included.
    pub bytes: u64,
    /// Whether the tileset is placed on the WGS 84 globe (the CRS converts).
    pub on_globe: bool,
}

impl std::fmt::Display for MeshSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "{}: {} glTF files, {} bytes; {} buildings, {} objects{}",
            self.tileset.display(),
            self.files,
            self.bytes,
            self.buildings,
            self.objects,
            match self.on_globe {
                true => "; on the WGS 84 globe, a frame per tile",
                false =>
                    "; in the root tile's frame (the CRS does not convert to latitude/longitude)",
            }
        )?;
        writeln!(
            f,
            "level  spacing_m  bound_m  tiles  terrain_tris  all_tris      bytes  max_err_m  rms_err_m  uncovered  placed_m"
        )?;
        for l in &self.levels {
            writeln!(
                f,
                "{:>5}  {:>9.3}  {:>7.3}  {:>5}  {:>12}  {:>8}  {:>9}  {:>9.3}  {:>9.4}  {:>9}  {:>8}",
                l.level,
                l.point_spacing_m,
                l.bound_m,
                l.tiles,
                l.terrain_triangles,
                l.triangles,
                l.bytes,
                l.max_error_m,
                l.rms_error_m,
                l.uncovered_points,
                l.placement_error_m
                    .map_or("-".to_string(), |e| format!("{e:.4}"))
            )?;
        }
        if self.buildings_over_nodata > 0 {
            writeln!(
                f,
                "{} buildings over nodata terrain left out",
                self.buildings_over_nodata
            )?;
        }
        Ok(())
    }
}

/// Rows of level-0 points measured at a time.
const BAND_ROWS: usize = 256;

/// Export `db` as a tileset in `dir` (created if missing).
pub fn export_mesh(
    db: &Database,
    dir: &Path,
    opts: &MeshOptions,
    progress: &Progress,
) -> Result<MeshSummary> {
    check_options(opts)?;
    let grid = db.grid().clone();
    let elevation = db.elevation_rows()?;
    // Without an orthophoto the terrain is grey.
    let colour: Box<dyn RowSource<[u8; 4]>> = match db.manifest.layers.contains_key(COLOUR) {
        true => Box::new(db.colour_rows()?),
        false => Box::new(Uniform {
            grid: grid.clone(),
            value: [128, 128, 128, 255],
        }),
    };
    let colour = colour.as_ref();
    let levels = Levels::new(&grid, opts);
    let base = origin(&grid, &elevation)?;
    let standing = standing_meshes(db, &elevation, colour)?;

    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let total: usize = (0..levels.count).map(|l| levels.tiles(l).len()).sum();
    progress.phase(total as u64, "mesh tiles");
    let mut staged: Vec<Staged> = Vec::new();
    let mut stats = Vec::new();
    let mut built: Vec<BTreeMap<(usize, usize), Built>> = Vec::new();
    for level in 0..levels.count {
        let tiles = levels.tiles(level);
        let level_dir = dir.join("tiles").join(level.to_string());
        std::fs::create_dir_all(&level_dir).map_err(|e| Error::io(&level_dir, e))?;
        let done: Vec<Result<(Built, Option<Staged>)>> = tiles
            .par_iter()
            .map(|&(tx, ty)| {
                let frame = levels.frame(&grid, level, tx, ty, base);
                let r = build_tile(
                    &levels, level, tx, ty, &elevation, colour, &standing, frame, &level_dir,
                );
                progress.inc(1);
                r
            })
            .collect();
        let mut level_built = BTreeMap::new();
        let mut s = LevelStats {
            level: level as u32,
            point_spacing_m: levels.spacing(level),
            bound_m: levels.bound(level),
            tiles: 0,
            terrain_triangles: 0,
            triangles: 0,
            bytes: 0,
            max_error_m: 0.0,
            rms_error_m: 0.0,
            uncovered_points: 0,
            placement_error_m: None,
        };
        let mut sum_sq = 0.0;
        let mut points = 0u64;
        for ((tx, ty), r) in tiles.iter().zip(done) {
            let (b, file) = r?;
            if let Some(f) = file {
                staged.push(f);
                s.tiles += 1;
            }
            s.terrain_triangles += b.terrain_triangles;
            s.triangles += b.triangles;
            s.bytes += b.bytes;
            s.max_error_m = s.max_error_m.max(b.error.max);
            sum_sq += b.error.sum_sq;
            points += b.error.points;
            s.uncovered_points += b.error.uncovered;
            if let Some(e) = b.frame.corner_error_m {
                s.placement_error_m = Some(s.placement_error_m.unwrap_or(0.0).max(e));
            }
            level_built.insert((*tx, *ty), b);
        }
        s.rms_error_m = if points > 0 {
            (sum_sq / points as f64).sqrt()
        } else {
            0.0
        };
        stats.push(s);
        built.push(level_built);
    }

    let root = tree(&levels, &built, levels.count - 1, 0, 0, None, base);
    let generator = format!("dbms {}", env!("CARGO_PKG_VERSION"));
    let json = tileset_json(&root, &grid.crs.name(), &generator);
    let text = serde_json::to_string_pretty(&json).expect("JSON values serialise") + "\n";
    let tileset = dir.join("tileset.json");
    let mut f = AtomicFile::create(&tileset)?;
    f.writer()
        .write_all(text.as_bytes())
        .map_err(|e| Error::io(&tileset, e))?;
    let files = staged.len();
    let written: Vec<PathBuf> = staged.iter().map(|s| s.path().to_path_buf()).collect();
    staged.push(f.stage()?);
    commit_all(staged)?;
    remove_stale(&dir.join("tiles"), &written)?;
    let bytes = stats.iter().map(|s| s.bytes).sum::<u64>() + text.len() as u64;
    Ok(MeshSummary {
        tileset,
        levels: stats,
        buildings: standing.buildings,
        buildings_over_nodata: standing.over_nodata,
        objects: standing.objects,
        files,
        bytes,
        // The root is on the globe exactly when its frame converts, like every tile's.
        on_globe: root.transform.is_some(),
    })
}

/// Refuse options that cannot make a tileset, in words.
fn check_options(opts: &MeshOptions) -> Result<()> {
    if !(opts.max_error_m.is_finite() && opts.max_error_m >= 0.0) {
        return Err(Error::msg(format!(
            "--max-error {} is not a height difference",
            opts.max_error_m
        ))
        .fix("give a vertical error bound in metres, 0 or more (e.g. --max-error 0.1)"));
    }
    if !(2..=4096).contains(&opts.tile_cells) {
        return Err(
            Error::msg(format!("--tile-cells {} is out of range", opts.tile_cells))
                .fix("give 2 to 4096 cells along a level-0 tile's side (e.g. 256)"),
        );
    }
    if !(2..=8).contains(&opts.factor) {
        return Err(
            Error::msg(format!("--factor {} is out of range", opts.factor))
                .fix("give 2 to 8 (each level's tiles that many times wider)"),
        );
    }
    Ok(())
}

/// The tile layout of every level.
struct Levels {
    width: usize,
    height: usize,
    tile: usize,
    factor: usize,
    max_error_m: f64,
    /// Cell size, metres.
    cell: f64,
    /// Levels, the last one a single tile.
    count: usize,
}

impl Levels {
    fn new(grid: &Grid, opts: &MeshOptions) -> Levels {
        let mut l = Levels {
            width: grid.width,
            height: grid.height,
            tile: opts.tile_cells,
            factor: opts.factor,
            max_error_m: opts.max_error_m,
            cell: grid.transform.cell_x.abs(),
            count: 1,
        };
        while l.across(l.count - 1) != (1, 1) {
            l.count += 1;
        }
        l
    }

    /// Cells between a level's points.
    fn stride(&self, level: usize) -> usize {
        self.factor.pow(level as u32)
    }

    /// Metres between a level's points: the detail across the ground that it cannot show.
    fn spacing(&self, level: usize) -> f64 {
        self.cell * self.stride(level) as f64
    }

    /// Cells along a level's tile side.
    fn span(&self, level: usize) -> usize {
        self.tile * self.stride(level)
    }

    /// The level's vertical bound, metres.
    fn bound(&self, level: usize) -> f64 {
        self.max_error_m * self.stride(level) as f64
    }

    /// Tiles across and down: enough to cover the points' intervals (at least one).
    fn across(&self, level: usize) -> (usize, usize) {
        let n = |points: usize| (points.saturating_sub(1)).div_ceil(self.span(level)).max(1);
        (n(self.width), n(self.height))
    }

    /// The level's tiles, row by row.
    fn tiles(&self, level: usize) -> Vec<(usize, usize)> {
        let (nx, ny) = self.across(level);
        (0..ny).flat_map(|y| (0..nx).map(move |x| (x, y))).collect()
    }

    /// The grid indices of a tile's points along one axis of `n` points: every stride from the
    /// tile's start to the next tile's, the axis's last point always kept.
    fn points(&self, level: usize, t: usize, n: usize) -> Vec<usize> {
        let (s, start) = (self.stride(level), t * self.span(level));
        let end = (start + self.span(level)).min(n - 1);
        let mut v: Vec<usize> = (start..end).step_by(s).collect();
        v.push(end);
        v
    }

    /// Tile `(tx, ty)`'s frame: its origin at the centre of its cells (at `base`'s height),
    /// placed on the globe through the grid's CRS; its departure measured at its cells'
    /// corners.
    fn frame(&self, grid: &Grid, level: usize, tx: usize, ty: usize, base: [f64; 3]) -> Frame {
        let (nx, ny) = self.across(level);
        let cols = self.owned(level, tx, grid.width, nx);
        let rows = self.owned(level, ty, grid.height, ny);
        let t = &grid.transform;
        let (x0, y0) = t.pixel_to_world(cols.start as f64, rows.start as f64);
        let (x1, y1) = t.pixel_to_world(cols.end as f64, rows.end as f64);
        let origin = [(x0 + x1) / 2.0, (y0 + y1) / 2.0, base[2]];
        let area = [x0.min(x1), y0.min(y1), x0.max(x1), y0.max(y1)];
        Frame::new(&grid.crs, origin, area)
    }

    /// The grid indices of the level-0 points a tile owns along an axis of `n` points.
    fn owned(&self, level: usize, t: usize, n: usize, tiles: usize) -> std::ops::Range<usize> {
        let start = t * self.span(level);
        let end = if t + 1 == tiles {
            n
        } else {
            start + self.span(level)
        };
        start..end
    }
}

/// The local frame's origin: the grid's centre, at the mean valid height of the grid's middle
/// row (0 when it has none).
fn origin(grid: &Grid, elevation: &dyn RowSource<f32>) -> Result<[f64; 3]> {
    let (cx, cy) = grid.centre();
    let row = elevation.read_rows(grid.height / 2, 1)?;
    let valid: Vec<f64> = row
        .iter()
        .filter(|z| z.is_finite())
        .map(|&z| z as f64)
        .collect();
    let z = match valid.len() {
        0 => 0.0,
        n => valid.iter().sum::<f64>() / n as f64,
    };
    // Whole centimetres: a round origin, the same on every machine.
    Ok([cx, cy, (z * 100.0).round() / 100.0])
}

/// The mean of the opaque ones among `pixels` (sRGB, rounded half up), grey when none is.
fn mean_opaque<'a>(pixels: impl IntoIterator<Item = &'a [u8; 4]>) -> [u8; 3] {
    let (mut sum, mut n) = ([0u64; 3], 0u64);
    for p in pixels.into_iter().filter(|p| p[3] > 0) {
        (0..3).for_each(|k| sum[k] += p[k] as u64);
        n += 1;
    }
    match n {
        0 => [128; 3],
        _ => sum.map(|s| ((s + n / 2) / n) as u8),
    }
}

fn min3(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|k| a[k].min(b[k]))
}

fn max3(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|k| a[k].max(b[k]))
}

/// The tile `(level, tx, ty)` and the tiles under it, with boxes grown to hold their children
/// (carried into the tile's frame) and errors no smaller than their children's. `parent` is the
/// parent's frame as a matrix (`None` at the root); `base` the root frame's origin, which the
/// frames of a tileset off the globe are translations from.
fn tree(
    levels: &Levels,
    built: &[BTreeMap<(usize, usize), Built>],
    level: usize,
    tx: usize,
    ty: usize,
    parent: Option<&Matrix>,
    base: [f64; 3],
) -> Tile {
    let b = &built[level][&(tx, ty)];
    let own = b
        .frame
        .to_ecef
        .unwrap_or_else(|| translation(std::array::from_fn(|k| b.frame.origin[k] - base[k])));
    let mut children = Vec::new();
    if level > 0 {
        let f = levels.factor;
        let (nx, ny) = levels.across(level - 1);
        for cy in ty * f..((ty + 1) * f).min(ny) {
            for cx in tx * f..((tx + 1) * f).min(nx) {
                let child = tree(levels, built, level - 1, cx, cy, Some(&own), base);
                if child.uri.is_some() || !child.children.is_empty() {
                    children.push(child);
                }
            }
        }
    }
    let bounds = children
        .iter()
        .map(|c| {
            carried(
                &c.bounds,
                c.transform.as_ref().expect("a child has a transform"),
            )
        })
        .chain(b.bounds)
        .reduce(|a, c| (min3(a.0, c.0), max3(a.1, c.1)))
        .unwrap_or(([0.0; 3], [0.0; 3]));
    // Shown instead of its children, a coarse tile is off by its terrain's height error and,
    // across the ground, by its points' spacing (its drape's texels): the larger counts.
    let geometric_error = match level {
        0 => 0.0,
        _ => children
            .iter()
            .map(|c| c.geometric_error)
            .fold(b.error.max.max(levels.spacing(level)), f64::max),
    };
    let transform = match parent {
        Some(p) => Some(relative(p, &own)),
        None => b.frame.to_ecef,
    };
    Tile {
        uri: b.uri.clone(),
        origin: b.frame.origin,
        transform,
        bounds,
        geometric_error,
        children,
    }
}

/// The axis-aligned box holding box `(lo, hi)`'s corners carried by `m`.
fn carried((lo, hi): &([f64; 3], [f64; 3]), m: &Matrix) -> ([f64; 3], [f64; 3]) {
    (0..8)
        .map(|c| {
            let corner = std::array::from_fn(|k| if c >> k & 1 == 0 { lo[k] } else { hi[k] });
            apply(m, corner)
        })
        .fold(([f64::INFINITY; 3], [f64::NEG_INFINITY; 3]), |(a, b), p| {
            (min3(a, p), max3(b, p))
        })
}

/// Remove `.glb` files under `tiles` (in its level directories) that are not in `written`.
fn remove_stale(tiles: &Path, written: &[PathBuf]) -> Result<()> {
    let Ok(levels) = std::fs::read_dir(tiles) else {
        return Ok(());
    };
    for level in levels.flatten() {
        let Ok(files) = std::fs::read_dir(level.path()) else {
            continue;
        };
        for f in files.flatten() {
            let p = f.path();
            if p.extension().is_some_and(|e| e == "glb") && !written.contains(&p) {
                std::fs::remove_file(&p).map_err(|e| Error::io(&p, e))?;
            }
        }
    }
    Ok(())
}

/// One value everywhere: the photo of a database without one.
struct Uniform {
    grid: Grid,
    value: [u8; 4],
}

impl RowSource<[u8; 4]> for Uniform {
    fn grid(&self) -> &Grid {
        &self.grid
    }

    fn read_rows(&self, _row0: usize, rows: usize) -> Result<std::borrow::Cow<'_, [[u8; 4]]>> {
        Ok(vec![self.value; rows * self.grid.width].into())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::crs::Crs;
    use proptest::prelude::*;

    fn levels(width: usize, height: usize, tile: usize, factor: usize) -> Levels {
        let grid = Grid::north_up(500_000.0, 5_300_000.0, 0.5, width, height, Crs::epsg(32632));
        let opts = MeshOptions {
            max_error_m: 0.1,
            tile_cells: tile,
            factor,
        };
        Levels::new(&grid, &opts)
    }

    proptest! {
        /// At every level: the tiles' owned points cover the axis once, in order; each tile's
        /// points start at its first owned point, rise, stay on the grid, reach the next
        /// tile's first point (or the axis's last), so neighbours share their border; the
        /// last level is one tile.
        #[test]
        fn tiles_cover_every_point_once_and_share_borders(
            n in 1usize..700, tile in 2usize..40, factor in 2usize..6,
        ) {
            let l = levels(n, 3, tile, factor);
            prop_assert_eq!(l.across(l.count - 1), (1, 1));
            for level in 0..l.count {
                let (nx, _) = l.across(level);
                let mut next = 0;
                for t in 0..nx {
                    let own = l.owned(level, t, n, nx);
                    prop_assert_eq!(own.start, next);
                    next = own.end;
                    let pts = l.points(level, t, n);
                    prop_assert_eq!(pts[0], own.start.min(n - 1));
                    prop_assert!(pts.windows(2).all(|p| p[0] < p[1]));
                    prop_assert!(*pts.last().unwrap() < n);
                    let want_end = if t + 1 == nx { n - 1 } else { own.end };
                    prop_assert_eq!(*pts.last().unwrap(), want_end);
                }
                prop_assert_eq!(next, n);
            }
        }
    }

    /// The hard sizes: a grid whose last point falls exactly on a tile border (257 = 256 + 1)
    /// has no one-point tile; a one-point grid is one tile of one point.
    #[test]
    fn border_sizes_make_no_empty_tile() {
        let l = levels(257, 257, 256, 4);
        assert_eq!(l.across(0), (1, 1));
        assert_eq!(l.points(0, 0, 257).len(), 257);
        let l = levels(258, 1, 256, 4);
        assert_eq!(l.across(0), (2, 1));
        assert_eq!(l.points(0, 1, 258), vec![256, 257]);
        let l = levels(1, 1, 256, 4);
        assert_eq!((l.count, l.points(0, 0, 1)), (1, vec![0]));
    }
}
