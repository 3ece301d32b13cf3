//! Every level as GeoTIFF (`--export-levels DIR`), streamed while the pyramid is built.
//!
//! Invariant: `level<N>_maxz.tif` and `level<N>_colour.tif` hold exactly the cells of level N's
//! pages (padding dropped; the colour's alpha, 0 or 255, as the RGB file's internal mask), on
//! the level's own grid — the database's corner, cell size `c · f^N` — so they line up with the
//! database in any GIS. Pages are copied into their level's current page-row; when the cascade
//! reports the page-row complete, its rows go to the GeoTIFF writers and the buffer is reused.
//! Memory per level of width `Wk`: one page-row (`P · Wk` cells) plus the writers' tile row
//! (256 rows), 8 bytes a cell each — about `8 · (P + 256) · W · f / (f − 1)` bytes in all
//! (22 MB for W = 8192, P = 256, f = 4), whatever the grid's height.

use crate::error::{Error, Result};
use crate::io::atomic::Staged;
use crate::io::geotiff::GeoTiffWriter;
use crate::tiles::{Page, TileSetInfo};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// Writes every level of a pyramid as GeoTIFFs while its pages are emitted.
pub struct LevelExporter {
    info: TileSetInfo,
    levels: Vec<Mutex<LevelOut>>,
}

/// One level being written.
struct LevelOut {
    /// The current page-row's cells, row-major over the level's width (empty between page-rows).
    max_z: Vec<f32>,
    colour: Vec<[u8; 4]>,
    /// Pages of the current page-row received so far.
    pages: usize,
    z_file: GeoTiffWriter<f32>,
    colour_file: GeoTiffWriter<[u8; 4]>,
}

impl LevelExporter {
    /// Start `level<N>_maxz.tif` (float32, nodata −9999) and `level<N>_colour.tif` (RGB8 with a
    /// TIFF internal mask from the alpha: 0 = nodata) for every level of `info` in `dir` (created if missing). Nothing appears
    /// in `dir` until the files [`stage`](Self::stage) returns are committed.
    pub fn create(info: &TileSetInfo, dir: &Path) -> Result<LevelExporter> {
        std::fs::create_dir_all(dir)
            .map_err(|e| Error::io(dir, e).fix("choose a writable --export-levels directory"))?;
        let levels = (0..info.levels.len())
            .map(|k| {
                let (z, c) = Self::files(dir, k);
                let g = info.level_grid(k);
                Ok(Mutex::new(LevelOut {
                    max_z: Vec::new(),
                    colour: Vec::new(),
                    pages: 0,
                    z_file: GeoTiffWriter::create_f32(&z, &g)?,
                    colour_file: GeoTiffWriter::create_rgb8_masked(&c, &g)?,
                }))
            })
            .collect::<Result<_>>()?;
        Ok(LevelExporter {
            info: info.clone(),
            levels,
        })
    }

    /// Every file [`create`](Self::create) would write for `info` in `dir`, finest level
    /// first: what the run's other outputs must not be.
    pub fn paths(info: &TileSetInfo, dir: &Path) -> Vec<PathBuf> {
        (0..info.levels.len())
            .flat_map(|k| {
                let (z, c) = Self::files(dir, k);
                [z, c]
            })
            .collect()
    }

    /// The two files of level `k` in `dir`.
    fn files(dir: &Path, k: usize) -> (PathBuf, PathBuf) {
        (
            dir.join(format!("level{k}_maxz.tif")),
            dir.join(format!("level{k}_colour.tif")),
        )
    }

    /// Copy page `(level, tx, ty)` into its level's current page-row (from any thread).
    pub fn put(&self, level: usize, tx: usize, ty: usize, page: &Page) {
        let p = self.info.page_size;
        let (cols, rows) = self.info.page_extent(level, tx, ty);
        let w = self.info.levels[level].width;
        let mut l = self.levels[level]
            .lock()
            .expect("no panics while holding the lock");
        if l.max_z.is_empty() {
            l.max_z.resize(rows * w, f32::NAN);
            l.colour.resize(rows * w, [0; 4]);
        }
        for r in 0..rows {
            let (src, dst) = (r * p, r * w + tx * p);
            l.max_z[dst..dst + cols].copy_from_slice(&page.max_z[src..src + cols]);
            l.colour[dst..dst + cols].copy_from_slice(&page.colour[src..src + cols]);
        }
        l.pages += 1;
    }

    /// Page-row `ty` of `level` is complete (every page of it was [`put`](Self::put)): write its
    /// rows. Page-rows of a level must complete in order.
    pub fn page_row_done(&self, level: usize, ty: usize) -> Result<()> {
        let mut l = self.levels[level]
            .lock()
            .expect("no panics while holding the lock");
        let l = &mut *l;
        if l.pages != self.info.levels[level].pages_x {
            return Err(Error::msg(format!(
                "internal: level {level} page-row {ty} exported incomplete"
            )));
        }
        l.z_file.push_rows(&l.max_z)?;
        l.colour_file.push_rows(&l.colour)?;
        l.max_z.clear();
        l.colour.clear();
        l.pages = 0;
        Ok(())
    }

    /// Finish every file, still under its temporary name: the caller renames them into place
    /// with the run's other outputs ([`commit_all`](crate::io::atomic::commit_all)). Returns
    /// them finest level first.
    pub fn stage(self) -> Result<Vec<Staged>> {
        let mut files = Vec::new();
        for l in self.levels {
            let l = l.into_inner().expect("no panics while holding the lock");
            files.push(l.z_file.stage()?);
            files.push(l.colour_file.stage()?);
        }
        Ok(files)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::crs::Crs;
    use crate::grid::Grid;
    use crate::io::geotiff;
    use crate::io::Samples;
    use crate::pyramid::cascade::build_levels_by_page_row;
    use crate::pyramid::reduce::BaseRows;
    use std::collections::HashMap;

    /// Exported levels hold exactly the pages' cells, on the level grids: a 37 × 23 grid (not a
    /// multiple of the page or the factor) with pages of 8 and factor 2, so some levels have
    /// several page-rows and edge pages are cut.
    #[test]
    fn exported_levels_equal_the_pages() {
        let grid = Grid::north_up(500_000.0, 5_000_000.0, 0.5, 37, 23, Crs::epsg(32614));
        let info = TileSetInfo::new(grid, 8, 2, None).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("levels");
        let exporter = LevelExporter::create(&info, &out).unwrap();
        let pages = Mutex::new(HashMap::new());
        build_levels_by_page_row(
            &info,
            |row0, rows| {
                let mut b = BaseRows::nodata(37, rows);
                for i in 0..37 * rows {
                    let g = row0 * 37 + i;
                    if g % 11 != 0 {
                        b.max_z[i] = 100.0 + (g % 29) as f32 * 0.5;
                        b.colour[i] = [(g % 251) as u8, (g % 13) as u8, 7, 255];
                        b.state[i] = 2;
                    }
                }
                Ok(b)
            },
            &|l, tx, ty, p| {
                exporter.put(l, tx, ty, p);
                pages.lock().unwrap().insert((l, tx, ty), p.clone());
                Ok(())
            },
            &mut |l, ty| exporter.page_row_done(l, ty),
        )
        .unwrap();
        let staged = exporter.stage().unwrap();
        let files: Vec<PathBuf> = staged.iter().map(|s| s.path().to_path_buf()).collect();
        assert_eq!(files, LevelExporter::paths(&info, &out));
        assert!(
            !files.iter().any(|f| f.exists()),
            "staged, not yet in place"
        );
        crate::io::atomic::commit_all(staged).unwrap();
        let pages = pages.into_inner().unwrap();
        let p = info.page_size;
        for k in 0..info.levels.len() {
            let z = geotiff::read(&out.join(format!("level{k}_maxz.tif"))).unwrap();
            let c = geotiff::read(&out.join(format!("level{k}_colour.tif"))).unwrap();
            let g = info.level_grid(k);
            assert_eq!((&z.grid, &c.grid), (&g, &g), "level {k} grid");
            assert_eq!(
                (c.bands, c.alpha_band),
                (4, Some(3)),
                "level {k}: the mask is alpha"
            );
            let (Samples::F32(z), Samples::U8(c)) = (z.samples, c.samples) else {
                panic!("level {k}: unexpected sample types");
            };
            for row in 0..g.height {
                for col in 0..g.width {
                    let page = &pages[&(k, col / p, row / p)];
                    let i = (row % p) * p + col % p;
                    let want = page.max_z[i];
                    let got = z[row * g.width + col];
                    assert!(
                        got.to_bits() == want.to_bits() || (got == -9999.0 && want.is_nan()),
                        "level {k} ({col}, {row}): {got} vs {want}"
                    );
                    let at = 4 * (row * g.width + col);
                    assert_eq!(&c[at..at + 4], &page.colour[i], "level {k} ({col}, {row})");
                }
            }
        }
    }
}
