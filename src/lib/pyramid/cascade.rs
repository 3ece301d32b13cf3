//! Streaming the whole hierarchy from level-0 bands, in bounded memory.
//!
//! Invariant: level 0 is requested one page-row (`P` grid rows) at a time, top to bottom; each
//! level keeps at most one page-row of its own rows pending. When a level's pending rows make a
//! whole page-row (or its last, shorter one), its pages are emitted and the rows are reduced into
//! the next level ([`super::reduce::reduce`]) and dropped. With `P` a multiple of the
//! factor `f`, a page-row of level `k` gives exactly `P / f` rows of level `k + 1`, so page-rows
//! of every level fill without carry-over. Memory at any moment: one level-0 band
//! (`P · W` cells), the pages being emitted from it, and at most `P · ceil(W / f^k)` pending
//! cells per coarse level `k` — see `docs/pyramid.md` for the byte count.

use super::reduce::{reduce, BaseRows, CoarseRows, LevelRows};
use crate::error::{Error, Result};
use crate::tiles::{Page, TileSetInfo, STATE_EMPTY};
use crate::voxel::columns::{PageColumns, Run};
use rayon::prelude::*;

/// A level-0 band: its rows and the voxel columns of its partial cells, which go into the
/// level-0 pages' `bricks` blobs (coarse levels keep only max Z, colour and state).
#[derive(Debug, Clone, PartialEq)]
pub struct Band {
    /// The cells.
    pub rows: BaseRows,
    /// `(band-local row-major index, runs)` of every partial cell, index ascending.
    pub columns: Vec<(usize, Vec<Run>)>,
}

impl From<BaseRows> for Band {
    /// A band without voxel columns (every cell a height-field column).
    fn from(rows: BaseRows) -> Band {
        Band {
            rows,
            columns: Vec::new(),
        }
    }
}

/// Build every level of `info` and hand each page to `emit(level, tx, ty, page)` (called from
/// many threads, each page exactly once, in no particular order).
///
/// `band(row0, rows)` must return level-0 rows `row0 .. row0 + rows` of the grid
/// (`info.grid.width` cells each), as a [`Band`] or plain [`BaseRows`]; it is called for
/// consecutive page-rows, top to bottom. A level-0 page with partial cells gets their columns
/// as its `bricks` blob ([`PageColumns`]); other pages get none.
pub fn build_levels<B, T, E>(info: &TileSetInfo, band: B, emit: &E) -> Result<()>
where
    B: FnMut(usize, usize) -> Result<T> + Send,
    T: Into<Band> + Send,
    E: Fn(usize, usize, usize, &Page) -> Result<()> + Sync,
{
    build_levels_by_page_row(info, band, emit, &mut |_, _| Ok(()))
}

/// [`build_levels`], and after the last page of each page-row `(level, ty)` has been emitted,
/// `page_row_done(level, ty)`, on one thread at a time, with no page of any level being emitted at
/// the same time (so it may take locks the emitter takes, and run parallel work of its own).
/// Each level's page-rows complete in order, top to bottom.
///
/// The next level-0 band is made while the current one's pages are emitted and reduced (two
/// bands in memory at a time), so reading and decoding it overlaps writing.
pub fn build_levels_by_page_row<B, T, E, D>(
    info: &TileSetInfo,
    mut band: B,
    emit: &E,
    page_row_done: &mut D,
) -> Result<()>
where
    B: FnMut(usize, usize) -> Result<T> + Send,
    T: Into<Band> + Send,
    E: Fn(usize, usize, usize, &Page) -> Result<()> + Sync,
    D: FnMut(usize, usize) -> Result<()> + Send,
{
    let (p, f) = (info.page_size, info.factor);
    if info.levels.len() > 1 && p % f != 0 {
        return Err(Error::msg(format!("--page {p}: with more than one level the page size must be a multiple of the factor {f}"))
            .fix("use a power of two such as 256"));
    }
    let mut pending: Vec<Pending> = info
        .levels
        .iter()
        .skip(1)
        .map(|l| Pending {
            rows: CoarseRows::new(l.width),
            received: 0,
            next_ty: 0,
        })
        .collect();
    let top = &info.levels[0];
    // Level-0 rows of page-row `ty`.
    let span = |ty: usize| (ty * p, p.min(top.height - ty * p));
    let mut next = match top.pages_y {
        0 => None,
        _ => Some(band(0, span(0).1)),
    };
    for ty in 0..top.pages_y {
        let (row0, rows) = span(ty);
        let Band {
            rows: base,
            columns,
        } = next.take().expect("made in the previous round")?.into();
        if base.width != top.width || base.rows() != rows {
            return Err(Error::msg(format!(
                "internal: level-0 band at row {row0} is {}×{} cells, expected {}×{rows}",
                base.width,
                base.rows(),
                top.width
            )));
        }
        let make_next = || match ty + 1 < top.pages_y {
            true => {
                let (row0, rows) = span(ty + 1);
                Some(band(row0, rows))
            }
            false => None,
        };
        let this_band = || -> Result<()> {
            emit_page_row(info, 0, ty, &base, Some(&columns), emit)?;
            page_row_done(0, ty)?;
            if info.levels.len() > 1 {
                push(info, &mut pending, 1, reduce(&base, f), emit, page_row_done)?;
            }
            Ok(())
        };
        let done;
        (next, done) = rayon::join(make_next, this_band);
        done?;
    }
    Ok(())
}

/// Rows of a coarse level waiting to fill a page-row.
struct Pending {
    rows: CoarseRows,
    /// Rows of this level received so far.
    received: usize,
    /// The page-row the pending rows belong to.
    next_ty: usize,
}

/// Add rows to level `k`; emit and reduce onward whenever a page-row is complete.
fn push<E, D>(
    info: &TileSetInfo,
    pending: &mut [Pending],
    k: usize,
    rows: CoarseRows,
    emit: &E,
    page_row_done: &mut D,
) -> Result<()>
where
    E: Fn(usize, usize, usize, &Page) -> Result<()> + Sync,
    D: FnMut(usize, usize) -> Result<()>,
{
    let level = &info.levels[k];
    let slot = &mut pending[k - 1];
    slot.received += rows.rows();
    slot.rows.append(rows);
    if slot.rows.rows() < info.page_size && slot.received < level.height {
        return Ok(());
    }
    let full = std::mem::replace(&mut slot.rows, CoarseRows::new(level.width));
    let ty = slot.next_ty;
    slot.next_ty += 1;
    emit_page_row(info, k, ty, &full, None, emit)?;
    page_row_done(k, ty)?;
    if k + 1 < info.levels.len() {
        push(
            info,
            pending,
            k + 1,
            reduce(&full, info.factor),
            emit,
            page_row_done,
        )?;
    }
    Ok(())
}

/// Cut one page-row of `level` into pages (nodata padding at the edges), each with the bricks of
/// its `columns` (band-local indices) if it has any, and emit them, in parallel.
pub(super) fn emit_page_row<R, E>(
    info: &TileSetInfo,
    level: usize,
    ty: usize,
    rows: &R,
    columns: Option<&[(usize, Vec<Run>)]>,
    emit: &E,
) -> Result<()>
where
    R: LevelRows,
    E: Fn(usize, usize, usize, &Page) -> Result<()> + Sync,
{
    let p = info.page_size;
    let w = rows.width();
    // One page buffer per worker, refilled for each page: no allocation (and no fresh-memory
    // page faults) per page.
    let layers = info.sensor_layers();
    (0..info.levels[level].pages_x)
        .into_par_iter()
        .try_for_each_init(
            || Page::nodata_with(p, &layers),
            |page, tx| {
                let cols = p.min(w - tx * p);
                for r in 0..p {
                    let o = r * p;
                    let valid = if r < rows.rows() { cols } else { 0 };
                    if valid > 0 {
                        rows.copy_run(
                            r * w + tx * p,
                            &mut page.max_z[o..o + valid],
                            &mut page.colour[o..o + valid],
                            &mut page.state[o..o + valid],
                        );
                    }
                    page.max_z[o + valid..o + p].fill(f32::NAN);
                    page.colour[o + valid..o + p].fill([0; 4]);
                    page.state[o + valid..o + p].fill(STATE_EMPTY);
                    debug_assert_eq!(rows.sensor().len(), page.sensor.len());
                    for (rows, (layer, cells)) in rows.sensor().iter().zip(&mut page.sensor) {
                        assert_eq!(rows.layer, *layer, "sensor rows in the tile set's order");
                        if valid > 0 {
                            rows.copy_run(r * w + tx * p, valid, cells, o);
                        }
                        cells.clear(o + valid..o + p);
                    }
                }
                page.bricks = page_bricks(columns.unwrap_or(&[]), w, tx * p..tx * p + cols, p)
                    .map_err(|e| {
                        Error::msg(format!(
                            "internal: page (level {level}, {tx}, {ty}) bricks: {e}"
                        ))
                    })?;
                emit(level, tx, ty, page)
            },
        )
}

/// The bricks blob of the page holding band columns `cols` (band `w` cells wide, pages `p`
/// cells): its cells' columns re-indexed within the page; `None` when it has none.
fn page_bricks(
    columns: &[(usize, Vec<Run>)],
    w: usize,
    cols: std::ops::Range<usize>,
    p: usize,
) -> std::result::Result<Option<Vec<u8>>, String> {
    let mut page = PageColumns::default();
    // Band order (row-major) restricted to the page's columns is the page's row-major order.
    for (i, runs) in columns.iter().filter(|(i, _)| cols.contains(&(i % w))) {
        page.push((i / w) * p + i % w - cols.start, runs)?;
    }
    Ok((!page.is_empty()).then(|| page.encode()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::crs::Crs;
    use crate::grid::Grid;
    use crate::raster::Raster;
    use std::sync::Mutex;

    /// Every page of a 10×7 grid with pages of 4 and factor 2 arrives exactly once.
    #[test]
    fn every_page_is_emitted_once() {
        let grid = Grid::north_up(0.0, 7.0, 1.0, 10, 7, Crs::unknown());
        let info = TileSetInfo::new(grid, 4, 2, None).unwrap();
        let seen = Mutex::new(Vec::new());
        build_levels(
            &info,
            |_, rows| Ok(BaseRows::nodata(10, rows)),
            &|l, tx, ty, _| {
                seen.lock().unwrap().push((l, tx, ty));
                Ok(())
            },
        )
        .unwrap();
        let mut seen = seen.into_inner().unwrap();
        seen.sort();
        let want: Vec<_> = (0..info.page_count())
            .map(|i| info.page_at(i).unwrap())
            .collect();
        let mut want = want;
        want.sort();
        assert_eq!(seen, want);
    }

    /// Level 0 from whole arrays, as `build_pyramid` cuts it.
    fn cut(base: &BaseRows, row0: usize, rows: usize) -> BaseRows {
        let w = base.width;
        let r = row0 * w..(row0 + rows) * w;
        BaseRows {
            width: w,
            max_z: base.max_z[r.clone()].to_vec(),
            colour: base.colour[r.clone()].to_vec(),
            state: base.state[r].to_vec(),
            sensor: Vec::new(),
        }
    }

    /// One level as whole rasters, gathered from its pages.
    struct Level {
        max_z: Raster<f32>,
        colour: Raster<[u8; 4]>,
        state: Raster<u8>,
    }

    fn build(
        base: &BaseRows,
        height: usize,
        page: usize,
        factor: usize,
    ) -> (TileSetInfo, Vec<Level>) {
        let grid = Grid::north_up(
            500_000.0,
            5_000_000.0,
            0.5,
            base.width,
            height,
            Crs::epsg(32632),
        );
        let info = TileSetInfo::new(grid, page, factor, None).unwrap();
        let levels: Vec<Mutex<Level>> = (0..info.levels.len())
            .map(|k| {
                let g = info.level_grid(k);
                Mutex::new(Level {
                    max_z: Raster::filled(g.clone(), f32::NAN),
                    colour: Raster::filled(g.clone(), [0; 4]),
                    state: Raster::filled(g, 0),
                })
            })
            .collect();
        build_levels(
            &info,
            |row0, rows| Ok(cut(base, row0, rows)),
            &|k, tx, ty, page| {
                let (cols, rows) = info.page_extent(k, tx, ty);
                let mut l = levels[k].lock().unwrap();
                for r in 0..rows {
                    for c in 0..cols {
                        let p = info.page_size;
                        let (col, row, i) = (tx * p + c, ty * p + r, r * p + c);
                        *l.max_z.get_mut(col, row) = page.max_z[i];
                        *l.colour.get_mut(col, row) = page.colour[i];
                        *l.state.get_mut(col, row) = page.state[i];
                    }
                }
                Ok(())
            },
        )
        .unwrap();
        let levels = levels
            .into_iter()
            .map(|l| l.into_inner().unwrap())
            .collect();
        (info, levels)
    }

    proptest::proptest! {
        #![proptest_config(proptest::prelude::ProptestConfig::with_cases(64))]
        /// Every coarse cell against its whole level-0 block: the max exactly (NaN only when the
        /// block has no valid cell), the colour the rounded mean of the valid cells (so within ½
        /// of the true mean), the state by the block rule. Sizes are not multiples of anything.
        #[test]
        fn coarse_cells_are_exact_over_their_level0_block(
            w in 1usize..70, h in 1usize..70, page_pow in 2u32..5, f4 in proptest::bool::ANY,
            seed in 0u64..u64::MAX, nodata_pct in 0u64..101,
        ) {
            let (page, factor) = (1usize << page_pow, if f4 { 4 } else { 2 });
            let mut s = seed | 1;
            let mut next = || { s ^= s << 13; s ^= s >> 7; s ^= s << 17; s };
            let mut base = BaseRows::nodata(w, h);
            for i in 0..w * h {
                let v = next();
                if v % 100 >= nodata_pct {
                    base.max_z[i] = ((v >> 8) % 100_000) as f32 * 0.01 - 300.0;
                    base.colour[i] = [(v >> 20) as u8, (v >> 28) as u8, (v >> 36) as u8, 255];
                    base.state[i] = if (v >> 44) % 7 == 0 { 1 } else { 2 };
                }
            }
            let (info, levels) = build(&base, h, page, factor);
            proptest::prop_assert_eq!(levels.len(), info.levels.len());
            proptest::prop_assert!(levels[0].max_z.data.iter().zip(&base.max_z).all(|(a, b)| a.to_bits() == b.to_bits()));
            proptest::prop_assert_eq!(&levels[0].colour.data, &base.colour);
            for (k, l) in levels.iter().enumerate().skip(1) {
                let span = factor.pow(k as u32);
                for row in 0..l.max_z.grid.height {
                    for col in 0..l.max_z.grid.width {
                        let (mut z, mut sum, mut n, mut filled, mut opaque) = (f32::NAN, [0u64; 3], 0u64, false, true);
                        for r in row * span..((row + 1) * span).min(h) {
                            for c in col * span..((col + 1) * span).min(w) {
                                let i = r * w + c;
                                if !base.max_z[i].is_nan() && (z.is_nan() || base.max_z[i] > z) {
                                    z = base.max_z[i];
                                }
                                if base.colour[i][3] != 0 {
                                    for (s, &v) in sum.iter_mut().zip(&base.colour[i][..3]) { *s += v as u64; }
                                    n += 1;
                                }
                                filled |= base.state[i] != 0;
                                opaque &= base.state[i] == 2;
                            }
                        }
                        let got = *l.max_z.get(col, row);
                        proptest::prop_assert!(got.to_bits() == z.to_bits() || (got.is_nan() && z.is_nan()), "level {} ({}, {}): {} vs {}", k, col, row, got, z);
                        let c = *l.colour.get(col, row);
                        proptest::prop_assert_eq!(c[3] == 0, n == 0, "nodata colour exactly where no valid cell");
                        for ch in 0..3 {
                            if n > 0 {
                                let mean = sum[ch] as f64 / n as f64;
                                proptest::prop_assert!((c[ch] as f64 - mean).abs() <= 0.5, "level {} colour {} vs mean {}", k, c[ch], mean);
                            }
                        }
                        let want = if !filled { 0 } else if opaque { 2 } else { 1 };
                        proptest::prop_assert_eq!(*l.state.get(col, row), want);
                    }
                }
            }
        }
    }

    #[test]
    fn page_size_not_a_multiple_of_the_factor_is_an_error() {
        let grid = Grid::north_up(0.0, 7.0, 1.0, 10, 7, Crs::unknown());
        let info = TileSetInfo::new(grid, 6, 4, None).unwrap();
        let e = build_levels(
            &info,
            |_, rows| Ok(BaseRows::nodata(10, rows)),
            &|_, _, _, _| Ok(()),
        )
        .unwrap_err();
        assert!(e.to_string().contains("multiple of the factor"), "{e}");
    }
}
