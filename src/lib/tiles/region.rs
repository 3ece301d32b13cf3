//! Finer regions of a tile set: a database's insets, each its own tile file beside the base's,
//! listed in the base header's `regions` (docs/tile-format.md, "Regions").
//!
//! Invariants:
//! * A region's tile file is an ordinary tile file over the inset's grid, derived from its
//!   parent's (base or another region) as the database derives it ([`crate::inset`]); the base
//!   header records its length and header and index CRCs, so a region file rebuilt or replaced
//!   without its base is refused.
//! * **The parent covers its regions**: every level-0 cell of a parent under a region's window
//!   has a `max_z` at least the highest `max_z` of the region's level-0 cells in it ([`Cover`]),
//!   so the parent's max-Z hierarchy bounds every region cell under it (hierarchical stepping
//!   stays exact). The pyramid keeps the parent's own cell where its column is already that
//!   high, and otherwise raises it to the region's top (opaque, its own colour, or the
//!   region's average where it had no data): a view that does not descend into the region sees
//!   the parent as it was, wherever the region does not rise above it.

use super::TileReader;
use crate::error::{Error, Result};
use crate::grid::Grid;
use crate::inset::{CellWindow, InsetSpec};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// One finer region of a tile set, as the base header lists it.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct Region {
    /// The inset's name, unique in the tile set.
    pub name: String,
    /// The region it refines; `null`: the base.
    pub parent: Option<String>,
    /// Parent cells per region cell along each axis (2–10).
    pub factor: usize,
    /// The parent's level-0 cells it covers, half open.
    pub window: CellWindow,
    /// Its tile file, a file name in the base file's directory.
    pub file: String,
    /// That file's length in bytes and the CRC-32 of its header and of its index.
    pub tiles: [u64; 3],
}

impl Region {
    /// The inset this region is the tile set of.
    pub fn spec(&self) -> InsetSpec {
        InsetSpec {
            name: self.name.clone(),
            parent: self.parent.clone(),
            factor: self.factor,
            window: self.window,
        }
    }

    /// The region's tile file, for the base tile file `base`.
    pub fn path(&self, base: &Path) -> PathBuf {
        base.with_file_name(&self.file)
    }
}

/// The regions' specifications, parents first.
pub fn specs(regions: &[Region]) -> Vec<InsetSpec> {
    regions.iter().map(Region::spec).collect()
}

/// Check `regions` over the base grid `base` as the database checks its insets (names, parents
/// before children, factors, windows inside their parents, siblings apart) and name plain files.
pub fn check(regions: &[Region], base: &Grid) -> Result<()> {
    let mut seen = Vec::new();
    for r in regions {
        crate::inset::check_new(&r.spec(), &seen, base)?;
        let plain = Path::new(&r.file).file_name() == Some(std::ffi::OsStr::new(&r.file));
        if !plain || r.file.is_empty() {
            return Err(Error::msg(format!(
                "region {}: its file {:?} is not a file name beside the base",
                r.name, r.file
            )));
        }
        seen.push(r.spec());
    }
    Ok(())
}

/// Open region `r` of the tile file `base` (whose regions are `all`, level-0 grid `base_grid`)
/// with a cache of `cache_pages`: its tile file, checked to be the one the base header records,
/// over the grid it derives.
pub fn open(
    base: &Path,
    r: &Region,
    all: &[Region],
    base_grid: &Grid,
    cache_pages: usize,
) -> Result<TileReader> {
    let path = r.path(base);
    let fix = "rebuild the tile set with dbms pyramid (its files are written together)";
    let reader = TileReader::open(&path, cache_pages).map_err(|e| e.fix(fix))?;
    let (h, i) = reader.checksums();
    if [reader.file_len(), h as u64, i as u64] != r.tiles {
        return Err(Error::file(
            &path,
            format!(
                "is not the region {} that {} records (length or checksums differ)",
                r.name,
                base.display()
            ),
        )
        .fix(fix));
    }
    let want = crate::inset::grid_of(&r.name, &specs(all), base_grid)?;
    if reader.info().grid != want {
        return Err(Error::file(
            &path,
            format!("its grid is not the one region {} derives", r.name),
        )
        .fix(fix));
    }
    Ok(reader)
}

/// A region's reduction onto its parent's level-0 cells (see the module doc), one entry per
/// parent cell of its window, row-major.
#[derive(Debug, Clone, PartialEq)]
pub struct Cover {
    /// The parent cells.
    pub window: CellWindow,
    /// Highest `max_z` of the region's level-0 cells in each, metres; NaN when none is valid.
    pub max_z: Vec<f32>,
    /// Rounded average colour of those cells; alpha 0 when none is valid.
    pub colour: Vec<[u8; 4]>,
}

impl Cover {
    /// The reduction of region `spec`'s tile file `tiles` (its level 0) onto its parent, read
    /// page by page. Max Z takes the first valid value and then only greater ones, in the
    /// pages' order, row-major in each; colours are integer sums.
    pub fn of(spec: &InsetSpec, tiles: &TileReader) -> Result<Cover> {
        let (w, f) = (spec.window, spec.factor);
        let info = tiles.info();
        let p = info.page_size;
        let (pw, ph) = (w.width(), w.height());
        let mut max_z = vec![f32::NAN; pw * ph];
        let mut sums = vec![[0u64; 4]; pw * ph];
        let l0 = &info.levels[0];
        for ty in 0..l0.pages_y {
            for tx in 0..l0.pages_x {
                let page = tiles.page(0, tx, ty)?;
                for r in 0..p.min(l0.height - ty * p) {
                    let row = ty * p + r;
                    for c in 0..p.min(l0.width - tx * p) {
                        let col = tx * p + c;
                        let k = (row / f) * pw + col / f;
                        let i = r * p + c;
                        let z = page.max_z[i];
                        // NaN-skipping max, the first valid value taken as it is.
                        if !z.is_nan() && (max_z[k].is_nan() || z > max_z[k]) {
                            max_z[k] = z;
                        }
                        let [red, green, blue, a] = page.colour[i];
                        if a != 0 {
                            let s = &mut sums[k];
                            s[0] += red as u64;
                            s[1] += green as u64;
                            s[2] += blue as u64;
                            s[3] += 1;
                        }
                    }
                }
            }
        }
        let colour = sums
            .iter()
            .map(|&[r, g, b, n]| super::average_colour([r, g, b], n))
            .collect();
        Ok(Cover {
            window: w,
            max_z,
            colour,
        })
    }

    /// The region's highest `max_z` and average colour over parent cell `(col, row)`; `None`
    /// outside the window or where no region cell there is valid.
    pub fn at(&self, col: usize, row: usize) -> Option<(f32, [u8; 4])> {
        let w = &self.window;
        if !(w.col0..w.col1).contains(&col) || !(w.row0..w.row1).contains(&row) {
            return None;
        }
        let k = (row - w.row0) * w.width() + col - w.col0;
        let z = self.max_z[k];
        (!z.is_nan()).then(|| (z, self.colour[k]))
    }
}

/// What [`verify`] checked.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
pub struct Verified {
    /// Regions opened and checked.
    pub regions: usize,
    /// Their pages whose checksum and decoding were checked.
    pub pages: usize,
    /// Parent cells over region data found bounding it.
    pub covered_cells: usize,
}

/// Check every region of the tile file `base` (opened as `reader`): each is the file the header
/// records over the grid it derives, every page of it reads back (checksums, decoding), and
/// every parent cell over region data has a `max_z` at least the region's highest there (the
/// bound the parent's hierarchy gives the renderer). The first failure is the error, naming the
/// region and the cell.
pub fn verify(
    base: &Path,
    reader: &TileReader,
    progress: &crate::progress::Progress,
) -> Result<Verified> {
    let regions = &reader.info().regions;
    let grid = &reader.info().grid;
    let mut opened: Vec<TileReader> = Vec::new();
    let mut done = Verified::default();
    for r in regions {
        let tiles = open(base, r, regions, grid, 64)?;
        done.pages += tiles.verify(progress)?;
        let parent = match &r.parent {
            None => reader,
            Some(p) => {
                let k = regions.iter().position(|o| &o.name == p).expect("checked");
                &opened[k]
            }
        };
        let cover = Cover::of(&r.spec(), &tiles)?;
        let w = r.window;
        for row in w.row0..w.row1 {
            for col in w.col0..w.col1 {
                let Some((z, _)) = cover.at(col, row) else {
                    continue;
                };
                let cell = parent.cell(0, col, row)?.expect("inside the parent");
                if !(cell.max_z >= z) {
                    return Err(Error::file(
                        parent.path(),
                        format!(
                            "level-0 cell ({col}, {row}) does not cover region {} under it (max Z {} where the region's highest is {z})",
                            r.name, cell.max_z
                        ),
                    )
                    .fix("rebuild the tile set with dbms pyramid"));
                }
                done.covered_cells += 1;
            }
        }
        done.regions += 1;
        opened.push(tiles);
    }
    Ok(done)
}
