//! Streaming the whole hierarchy from level-0 bands, in bounded memory.
//!
//! Invariant: level 0 is requested one page-row (`P` grid rows) at a time, top to bottom; each
//! level keeps at most one page-row of its own rows pending. When a level's pending rows make a
//! whole page-row (or its last, shorter one), its pages are emitted and the rows are reduced into
//! the next level ([`reduce`](super::reduce::reduce)) and dropped. With `P` a multiple of the
//! factor `f`, a page-row of level `k` gives exactly `P / f` rows of level `k + 1`, so page-rows
//! of every level fill without carry-over. Memory at any moment: one level-0 band
//! (`P · W` cells), the pages being emitted from it, and at most `P · ceil(W / f^k)` pending
//! cells per coarse level `k` — see `docs/pyramid.md` for the byte count.

use super::reduce::{reduce, BaseRows, CoarseRows, LevelRows};
use crate::error::{Error, Result};
use crate::tiles::{Page, TileSetInfo};
use rayon::prelude::*;

/// Build every level of `info` and hand each page to `emit(level, tx, ty, page)` (called from
/// many threads, each page exactly once, in no particular order).
///
/// `band(row0, rows)` must return level-0 rows `row0 .. row0 + rows` of the grid
/// (`info.grid.width` cells each); it is called for consecutive page-rows, top to bottom.
pub fn build_levels<B, E>(info: &TileSetInfo, mut band: B, emit: &E) -> Result<()>
where
    B: FnMut(usize, usize) -> Result<BaseRows>,
    E: Fn(usize, usize, usize, Page) -> Result<()> + Sync,
{
    let (p, f) = (info.page_size, info.factor);
    if info.levels.len() > 1 && p % f != 0 {
        return Err(Error::msg(format!("--page {p}: with more than one level the page size must be a multiple of the factor {f}"))
            .fix("use a power of two such as 256"));
    }
    let mut pending: Vec<Pending> =
        info.levels.iter().skip(1).map(|l| Pending { rows: CoarseRows::new(l.width), received: 0, next_ty: 0 }).collect();
    let top = &info.levels[0];
    for ty in 0..top.pages_y {
        let row0 = ty * p;
        let rows = p.min(top.height - row0);
        let base = band(row0, rows)?;
        if base.width != top.width || base.rows() != rows {
            return Err(Error::msg(format!(
                "internal: level-0 band at row {row0} is {}×{} cells, expected {}×{rows}",
                base.width,
                base.rows(),
                top.width
            )));
        }
        emit_page_row(info, 0, ty, &base, emit)?;
        if info.levels.len() > 1 {
            push(info, &mut pending, 1, reduce(&base, f), emit)?;
        }
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
fn push<E>(info: &TileSetInfo, pending: &mut [Pending], k: usize, rows: CoarseRows, emit: &E) -> Result<()>
where
    E: Fn(usize, usize, usize, Page) -> Result<()> + Sync,
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
    emit_page_row(info, k, ty, &full, emit)?;
    if k + 1 < info.levels.len() {
        push(info, pending, k + 1, reduce(&full, info.factor), emit)?;
    }
    Ok(())
}

/// Cut one page-row of `level` into pages (nodata padding at the edges) and emit them, in parallel.
fn emit_page_row<R, E>(info: &TileSetInfo, level: usize, ty: usize, rows: &R, emit: &E) -> Result<()>
where
    R: LevelRows,
    E: Fn(usize, usize, usize, Page) -> Result<()> + Sync,
{
    let p = info.page_size;
    let w = rows.width();
    (0..info.levels[level].pages_x).into_par_iter().try_for_each(|tx| {
        let mut page = Page::nodata(p);
        let cols = p.min(w - tx * p);
        for r in 0..rows.rows() {
            for c in 0..cols {
                let (i, o) = (r * w + tx * p + c, r * p + c);
                page.max_z[o] = rows.max_z(i);
                page.colour[o] = rows.colour(i);
                page.state[o] = rows.state(i);
            }
        }
        emit(level, tx, ty, page)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::crs::Crs;
    use crate::grid::Grid;
    use std::sync::Mutex;

    /// Every page of a 10×7 grid with pages of 4 and factor 2 arrives exactly once.
    #[test]
    fn every_page_is_emitted_once() {
        let grid = Grid::north_up(0.0, 7.0, 1.0, 10, 7, Crs::unknown());
        let info = TileSetInfo::new(grid, 4, 2, None).unwrap();
        let seen = Mutex::new(Vec::new());
        build_levels(&info, |_, rows| Ok(BaseRows::nodata(10, rows)), &|l, tx, ty, _| {
            seen.lock().unwrap().push((l, tx, ty));
            Ok(())
        })
        .unwrap();
        let mut seen = seen.into_inner().unwrap();
        seen.sort();
        let want: Vec<_> = (0..info.page_count()).map(|i| info.page_at(i).unwrap()).collect();
        let mut want = want;
        want.sort();
        assert_eq!(seen, want);
    }

    #[test]
    fn page_size_not_a_multiple_of_the_factor_is_an_error() {
        let grid = Grid::north_up(0.0, 7.0, 1.0, 10, 7, Crs::unknown());
        let info = TileSetInfo::new(grid, 6, 4, None).unwrap();
        let e = build_levels(&info, |_, rows| Ok(BaseRows::nodata(10, rows)), &|_, _, _, _| Ok(())).unwrap_err();
        assert!(e.to_string().contains("multiple of the factor"), "{e}");
    }
}
