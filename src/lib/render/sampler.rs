//! Cell lookups for one worker thread: the tile reader behind a memo of the current page per level.
//!
//! Invariant: every value comes from [`TileReader::page`] (checked, LRU-cached, counted); the
//! memo only avoids asking the shared cache again while a ray stays inside one page. Outside a
//! level's `width × height` a lookup is `None`, unless the database repeats (`wrap`), in which
//! case indices wrap modulo the level's size (only used for levels that tile the plane exactly).

use crate::error::Result;
use crate::tiles::{Cell, Page, TileReader};
use std::collections::BTreeSet;
use std::sync::Arc;

/// Per-thread cell access to a tile set.
pub struct Sampler<'a> {
    reader: &'a TileReader,
    page_size: usize,
    sizes: Vec<(i64, i64)>,
    wrap: bool,
    memo: Vec<Option<(usize, usize, Arc<Page>)>>,
    /// Pages this sampler asked the reader for, `(level, tx, ty)`.
    pub touched: BTreeSet<(usize, usize, usize)>,
}

impl<'a> Sampler<'a> {
    /// A sampler over `reader`; `wrap` makes the database repeat.
    pub fn new(reader: &'a TileReader, wrap: bool) -> Sampler<'a> {
        let info = reader.info();
        Sampler {
            reader,
            page_size: info.page_size,
            sizes: info.levels.iter().map(|l| (l.width as i64, l.height as i64)).collect(),
            wrap,
            memo: vec![None; info.levels.len()],
            touched: BTreeSet::new(),
        }
    }

    /// Cell `(col, row)` of `level`; `None` outside the level (without wrap).
    #[inline]
    pub fn cell(&mut self, level: usize, col: i64, row: i64) -> Result<Option<Cell>> {
        let (w, h) = self.sizes[level];
        let (col, row) = if self.wrap {
            (col.rem_euclid(w), row.rem_euclid(h))
        } else if col < 0 || row < 0 || col >= w || row >= h {
            return Ok(None);
        } else {
            (col, row)
        };
        let p = self.page_size;
        let (col, row) = (col as usize, row as usize);
        let (tx, ty) = (col / p, row / p);
        let page = match &self.memo[level] {
            Some((x, y, page)) if *x == tx && *y == ty => page,
            _ => {
                let page = self.reader.page(level, tx, ty)?;
                self.touched.insert((level, tx, ty));
                &self.memo[level].insert((tx, ty, page)).2
            }
        };
        Ok(Some(page.cell(p, col % p, row % p)))
    }
}
