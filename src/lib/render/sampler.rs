//! Cell lookups for one worker thread: the tile reader behind a memo of the current page per
//! level and the few pages used before it.
//!
//! Invariant: every value comes from [`TileReader::page`] (checked, LRU-cached, counted); the
//! memo only avoids asking the shared cache again for a page this sampler already holds (while
//! a ray stays inside one page, and when the next image column's walk crosses the pages this
//! one crossed: the shared cache is behind a lock both workers would wait on). Outside a
//! level's `width × height` a lookup is `None`, unless the database repeats (`wrap`), in which
//! case indices wrap modulo the level's size (only used for levels that tile the plane exactly).
//! The voxel columns of a level-0 page are decoded from its `bricks` blob the first time any ray
//! of the frame needs one, checked against the page's layers ([`PageColumns::check_layers`]),
//! and shared by the frame's samplers through a [`ColumnCache`].

use crate::error::{Error, Result};
use crate::tiles::{Cell, Page, TileReader, BRICKS_FORMAT};
use crate::voxel::columns::{PageColumns, Run};
use std::collections::{BTreeMap, BTreeSet};
use std::sync::{Arc, Mutex};

/// Pages per level a [`Sampler`] keeps besides its current one: enough for the pages an image
/// column's walk crosses at each level, which the next column's crosses again.
pub const RECENT_PAGES: usize = 16;

/// Level-0 pages whose decoded columns a [`ColumnCache`] keeps; when full it is emptied and
/// refills (decoded columns are about as large as their blob, tens of kB a page).
pub const COLUMN_PAGES: usize = 256;

/// Decoded voxel columns of level-0 pages, `(tx, ty)` → columns, shared by one frame's samplers
/// so each page's bricks are decoded about once per frame. Values are pure functions of the
/// tile file, so sharing cannot change a pixel.
#[derive(Debug, Default)]
pub struct ColumnCache {
    pages: Mutex<BTreeMap<(usize, usize), Arc<PageColumns>>>,
}

/// Per-thread cell access to a tile set.
pub struct Sampler<'a> {
    reader: &'a TileReader,
    page_size: usize,
    /// `log2(page_size)` when the page size is a power of two (shifts instead of divisions
    /// in the per-step lookup).
    page_shift: Option<u32>,
    sizes: Vec<(i64, i64)>,
    wrap: bool,
    /// Per level, the page the last lookup used, and up to [`RECENT_PAGES`] used before it,
    /// oldest first (the next image column's walk crosses the pages this one did).
    memo: Vec<Option<(usize, usize, Arc<Page>)>>,
    recent: Vec<Vec<(usize, usize, Arc<Page>)>>,
    /// The frame's decoded columns, and the level-0 page `(tx, ty)` this sampler last used.
    column_cache: &'a ColumnCache,
    columns: Option<(usize, usize, Arc<PageColumns>)>,
    /// Pages this sampler asked the reader for, `(level, tx, ty)`.
    pub touched: BTreeSet<(usize, usize, usize)>,
    /// The tile set's regions, each with its own sampler ([`super::regions`]).
    pub children: Vec<super::regions::Child<'a>>,
    /// This is a region's sampler: its edge meets its parent's surface (the seam), so a column
    /// side there with no neighbour is a step, not the database's cut edge.
    pub seam_edges: bool,
}

impl<'a> Sampler<'a> {
    /// A sampler over `reader`; `wrap` makes the database repeat; voxel columns come through
    /// `column_cache`.
    pub fn new(reader: &'a TileReader, wrap: bool, column_cache: &'a ColumnCache) -> Sampler<'a> {
        let info = reader.info();
        Sampler {
            reader,
            page_size: info.page_size,
            page_shift: info
                .page_size
                .is_power_of_two()
                .then(|| info.page_size.trailing_zeros()),
            sizes: info
                .levels
                .iter()
                .map(|l| (l.width as i64, l.height as i64))
                .collect(),
            wrap,
            memo: vec![None; info.levels.len()],
            recent: vec![Vec::new(); info.levels.len()],
            column_cache,
            columns: None,
            touched: BTreeSet::new(),
            children: Vec::new(),
            seam_edges: false,
        }
    }

    /// This sampler as a region's ([`Sampler::seam_edges`]).
    pub fn region_edges(mut self) -> Sampler<'a> {
        self.seam_edges = true;
        self
    }

    /// `(width, height)` of `level`, cells.
    pub fn size(&self, level: usize) -> (i64, i64) {
        self.sizes[level]
    }

    /// The region holding level-0 cell `(c, r)`, if one does.
    #[inline]
    pub fn child_at(&self, c: i64, r: i64) -> Option<usize> {
        self.children.iter().position(|k| k.holds(c, r))
    }

    /// Cell `(col, row)` of `level`; `None` outside the level (without wrap).
    #[inline(always)]
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
        let ((tx, ty), (c, r)) = match self.page_shift {
            Some(k) => ((col >> k, row >> k), (col & (p - 1), row & (p - 1))),
            None => ((col / p, row / p), (col % p, row % p)),
        };
        let page = match &self.memo[level] {
            Some((x, y, page)) if *x == tx && *y == ty => page,
            _ => self.load(level, tx, ty)?,
        };
        Ok(Some(page.cell(p, c, r)))
    }

    /// Page `(tx, ty)` of `level`, now the level's memo (the memo before it joins the recent
    /// pages): from the recent pages if it is one, else from the reader (the lookup's slow
    /// path, kept out of line so the memo's hit stays small enough to inline).
    #[inline(never)]
    fn load(&mut self, level: usize, tx: usize, ty: usize) -> Result<&Arc<Page>> {
        let recent = &mut self.recent[level];
        let page = match recent.iter().position(|(x, y, _)| (*x, *y) == (tx, ty)) {
            Some(k) => recent.remove(k).2,
            None => {
                let page = self.reader.page(level, tx, ty)?;
                self.touched.insert((level, tx, ty));
                page
            }
        };
        if let Some(old) = self.memo[level].take() {
            let recent = &mut self.recent[level];
            if recent.len() == RECENT_PAGES {
                recent.remove(0);
            }
            recent.push(old);
        }
        Ok(&self.memo[level].insert((tx, ty, page)).2)
    }

    /// The solid runs of level-0 cell `(col, row)`, which must be a partial cell (`state` 1)
    /// inside the level: its voxel column from the page's bricks. A page whose bricks are
    /// missing, malformed or inconsistent with its layers is an error naming the page.
    pub fn column(&mut self, col: i64, row: i64) -> Result<&[Run]> {
        let (w, h) = self.sizes[0];
        let (col, row) = (col.rem_euclid(w) as usize, row.rem_euclid(h) as usize);
        let p = self.page_size;
        let (tx, ty) = (col / p, row / p);
        let cached = matches!(&self.columns, Some((x, y, _)) if (*x, *y) == (tx, ty));
        if !cached {
            let shared = self
                .column_cache
                .pages
                .lock()
                .expect("column cache lock")
                .get(&(tx, ty))
                .cloned();
            let decoded = match shared {
                Some(c) => c,
                None => {
                    // Decoded outside the lock: two workers may both decode a page, harmlessly.
                    let page = self.reader.page(0, tx, ty)?;
                    self.touched.insert((0, tx, ty));
                    let c = Arc::new(self.decode(&page, tx, ty)?);
                    let mut pages = self.column_cache.pages.lock().expect("column cache lock");
                    if pages.len() >= COLUMN_PAGES {
                        pages.clear();
                    }
                    pages.insert((tx, ty), c.clone());
                    c
                }
            };
            self.columns = Some((tx, ty, decoded));
        }
        let (.., columns) = self.columns.as_ref().expect("just decoded");
        let cell = (row % p) * p + col % p;
        columns.runs(cell).ok_or_else(|| {
            Error::file(
                self.reader.path(),
                format!("page (level 0, {tx}, {ty}): cell {cell} has no voxel column"),
            )
        })
    }

    fn decode(&self, page: &Page, tx: usize, ty: usize) -> Result<PageColumns> {
        let bad = |problem: String| {
            Error::file(self.reader.path(), format!("page (level 0, {tx}, {ty}) bricks: {problem}"))
                .fix("the tile file is corrupt or was written by another dbms; rebuild it with dbms pyramid")
        };
        let format = &self.reader.info().bricks;
        if format != BRICKS_FORMAT {
            return Err(bad(format!(
                "the header's bricks format is {format:?}, this dbms reads {BRICKS_FORMAT:?}"
            )));
        }
        let blob = page.bricks.as_deref().unwrap_or(&[0u8; 4][..]); // no blob: no columns
        let columns = PageColumns::decode(blob, self.page_size * self.page_size).map_err(&bad)?;
        columns
            .check_layers(&page.state, &page.max_z)
            .map_err(bad)?;
        Ok(columns)
    }
}
