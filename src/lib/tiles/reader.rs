//! Reading a tile file: validated at open, pages checked on every read, cached, shareable.
//!
//! Invariant: after [`TileReader::open`] succeeds, the header is self-consistent and every
//! index entry points inside the file at an aligned offset with plausible lengths; a page is
//! handed out only after its CRC matched and it decoded to exactly its raw length. Reads are
//! positioned (`pread`), so one reader serves any number of threads without locking the file.

use super::cache::PageCache;
use super::info::{TileSetInfo, MAX_HEADER_LEN};
use super::layout::{align_up, IndexEntry, Preamble, ENTRY_LEN, PREAMBLE_LEN};
use super::page::{self, Cell, Layout, Page, FLAG_BRICKS, FLAG_LZ4, KNOWN_FLAGS};
use crate::error::{Error, Result};
use crate::progress::Progress;
use rayon::prelude::*;
use serde::Serialize;
use std::fs::File;
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

const REBUILD: &str = "the file is corrupt, rebuild it with dbms pyramid";

/// An open tile file. `Send + Sync`: share one behind an `Arc` (or by reference) between threads.
pub struct TileReader {
    path: PathBuf,
    file: File,
    preamble: Preamble,
    info: TileSetInfo,
    layout: Layout,
    index: Vec<IndexEntry>,
    cache: PageCache,
    /// Applied to every page as it is read, before it is cached ([`TileReader::with_filter`]).
    filter: Option<PageFilter>,
    pages_read: AtomicU64,
    bytes_read: AtomicU64,
    cache_hits: AtomicU64,
    /// The tile set's region files ([`super::region`]), opened the first time they are asked for
    /// and kept, with their caches, for as long as this reader.
    regions: std::sync::OnceLock<Vec<TileReader>>,
}

/// A change made to every page a reader hands out, e.g. a sensor view's colours
/// ([`TileReader::with_filter`]): a pure function of the page, so cached pages stay right.
pub type PageFilter = Arc<dyn Fn(&mut Page) + Send + Sync>;

/// What a reader has done so far (for `dbms render --json`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct ReaderStats {
    /// Pages read from the file (cache misses and verification reads).
    pub pages_read: u64,
    /// Stored bytes read from the file.
    pub bytes_read: u64,
    /// Page requests answered from the cache.
    pub cache_hits: u64,
}

impl TileReader {
    /// Open `path`, keeping up to `cache_pages` decoded pages in memory (0: no cache). Checks
    /// magic, version, length, header and index checksums, the header's consistency and every
    /// index entry's bounds; a failure is one line naming the file and what is wrong.
    pub fn open(path: &Path, cache_pages: usize) -> Result<TileReader> {
        let file = crate::io::open_regular(path)?;
        let pre = read_preamble(&file, path)?;
        let info = read_header(&file, path, &pre)?;
        let layout = Layout::of(&info);
        let index = read_index(&file, path, &pre, &info, &layout)?;
        Ok(TileReader {
            path: path.to_path_buf(),
            file,
            preamble: pre,
            info,
            layout,
            index,
            cache: PageCache::new(cache_pages),
            filter: None,
            pages_read: AtomicU64::new(0),
            bytes_read: AtomicU64::new(0),
            cache_hits: AtomicU64::new(0),
            regions: std::sync::OnceLock::new(),
        })
    }

    /// The tile set's region files, in the header's order, each checked to be the file the
    /// header records over the grid it derives ([`super::region::open`]) and caching as many
    /// pages as this reader: opened once, then the same readers (so a flight's frames keep
    /// their pages).
    pub fn regions(&self) -> Result<&[TileReader]> {
        if let Some(r) = self.regions.get() {
            return Ok(r);
        }
        let all = &self.info.regions;
        let opened = (all.iter())
            .map(|r| {
                super::region::open(&self.path, r, all, &self.info.grid, self.cache.capacity())
            })
            .collect::<Result<Vec<_>>>()?;
        Ok(self.regions.get_or_init(|| opened))
    }

    /// Whether a page filter recolours this reader's pages ([`TileReader::with_filter`]).
    pub fn is_filtered(&self) -> bool {
        self.filter.is_some()
    }

    /// This reader with `filter` applied to every page [`page`](Self::page) and
    /// [`cell`](Self::cell) hand out (pages already cached are dropped first).
    pub fn with_filter(mut self, filter: PageFilter) -> TileReader {
        self.cache = PageCache::new(self.cache.capacity());
        self.filter = Some(filter);
        self
    }

    /// The tile set's description (the header).
    pub fn info(&self) -> &TileSetInfo {
        &self.info
    }

    /// The file's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Format version of the file.
    pub fn version(&self) -> u32 {
        self.preamble.version
    }

    /// Length of the file, bytes.
    pub fn file_len(&self) -> u64 {
        self.preamble.file_len
    }

    /// Offset of the index in the file, bytes (entry `p` is at `index_offset + 24 · p`).
    pub fn index_offset(&self) -> u64 {
        self.preamble.index_offset
    }

    /// CRC-32 of the header and of the index, as the preamble records them: together with the
    /// file's length, what tells one tile file from another without reading its pages.
    pub fn checksums(&self) -> (u32, u32) {
        (self.preamble.header_crc, self.preamble.index_crc)
    }

    /// All index entries, in index order (see [`TileSetInfo::index_position`]).
    pub fn entries(&self) -> &[IndexEntry] {
        &self.index
    }

    /// The index entry of page `(level, tx, ty)`: one array lookup. `None` if no such page.
    pub fn entry(&self, level: usize, tx: usize, ty: usize) -> Option<IndexEntry> {
        self.info
            .index_position(level, tx, ty)
            .map(|p| self.index[p])
    }

    /// Page `(level, tx, ty)`, from the cache or read and checked. Errors on a page outside the
    /// tile set, a checksum mismatch, undecodable data or a read failure, naming the page.
    pub fn page(&self, level: usize, tx: usize, ty: usize) -> Result<Arc<Page>> {
        let pos = self.info.page_position(&self.path, (level, tx, ty))?;
        if let Some(page) = self.cache.get(pos) {
            self.cache_hits.fetch_add(1, Ordering::Relaxed);
            return Ok(page);
        }
        let mut page = self.load(pos)?;
        if let Some(f) = &self.filter {
            f(&mut page);
        }
        let page = Arc::new(page);
        self.cache.insert(pos, page.clone());
        Ok(page)
    }

    /// Cell `(col, row)` of `level`, from whichever page holds it: every cell lives in exactly
    /// one page, `(col / P, row / P)`, so lookups cross page edges without seams. `Ok(None)`
    /// outside the level's `width × height`; `Err` for a level that does not exist or a bad page.
    pub fn cell(&self, level: usize, col: usize, row: usize) -> Result<Option<Cell>> {
        let Some(l) = self.info.levels.get(level) else {
            return Err(Error::file(
                &self.path,
                format!(
                    "level {level} does not exist (the file has {})",
                    self.info.levels.len()
                ),
            ));
        };
        if col >= l.width || row >= l.height {
            return Ok(None);
        }
        let p = self.info.page_size;
        let page = self.page(level, col / p, row / p)?;
        Ok(Some(page.cell(p, col % p, row % p)))
    }

    /// Read every page in file order (in parallel, bypassing the cache) and check its checksum
    /// and decoding. Returns the number of pages checked, or the error of the first bad page in
    /// file order.
    pub fn verify(&self, progress: &Progress) -> Result<usize> {
        let mut order: Vec<usize> = (0..self.index.len()).collect();
        order.sort_by_key(|&p| self.index[p].offset);
        match order.par_iter().find_map_first(|&pos| {
            let r = self.load(pos).err();
            progress.inc(1);
            r
        }) {
            Some(e) => Err(e),
            None => Ok(order.len()),
        }
    }

    /// Counters since open.
    pub fn stats(&self) -> ReaderStats {
        ReaderStats {
            pages_read: self.pages_read.load(Ordering::Relaxed),
            bytes_read: self.bytes_read.load(Ordering::Relaxed),
            cache_hits: self.cache_hits.load(Ordering::Relaxed),
        }
    }

    /// Read, check and decode the page at index position `pos`.
    /// Page `(level, tx, ty)` as stored (possibly compressed), checked against its CRC but not
    /// decoded, with its index entry: what a writer of the same tile set copies unchanged
    /// ([`super::TileWriter::write_stored`]). Not cached.
    pub fn stored(&self, level: usize, tx: usize, ty: usize) -> Result<(IndexEntry, Vec<u8>)> {
        let pos = self.info.page_position(&self.path, (level, tx, ty))?;
        Ok((self.index[pos], self.read_stored(pos)?))
    }

    fn load(&self, pos: usize) -> Result<Page> {
        let e = self.index[pos];
        let stored = self.read_stored(pos)?;
        let (level, tx, ty) = self.info.page_at(pos).expect("position within the index");
        let name = format!("page (level {level}, {tx}, {ty})");
        page::decode(&self.layout, &stored, e.raw_len, e.flags)
            .map_err(|problem| Error::file(&self.path, format!("{name} {problem}")).fix(REBUILD))
    }

    /// The stored bytes of the page at index position `pos`, their CRC checked.
    fn read_stored(&self, pos: usize) -> Result<Vec<u8>> {
        let e = self.index[pos];
        let (level, tx, ty) = self.info.page_at(pos).expect("position within the index");
        let name = format!("page (level {level}, {tx}, {ty})");
        let mut stored = vec![0u8; e.stored_len as usize];
        self.file
            .read_exact_at(&mut stored, e.offset)
            .map_err(|err| {
                Error::file(
                    &self.path,
                    format!("{name}: {}", Error::io(&self.path, err).problem),
                )
                .fix(REBUILD)
            })?;
        self.pages_read.fetch_add(1, Ordering::Relaxed);
        self.bytes_read
            .fetch_add(stored.len() as u64, Ordering::Relaxed);
        if crc32fast::hash(&stored) != e.crc {
            return Err(Error::file(&self.path, format!("{name} checksum mismatch")).fix(REBUILD));
        }
        Ok(stored)
    }
}

/// The error for a tile file `path` that is damaged in the way `problem` says.
fn corrupt(path: &Path, problem: String) -> Error {
    Error::file(path, problem).fix(REBUILD)
}

/// The preamble of the tile file `file` (at `path`), checked against the file's length: the
/// file is neither truncated nor extended, and the header and index it points to lie inside
/// the file, in that order, after the preamble.
fn read_preamble(file: &File, path: &Path) -> Result<Preamble> {
    let actual_len = file.metadata().map_err(|e| Error::io(path, e))?.len();
    let mut head = vec![0u8; PREAMBLE_LEN.min(actual_len as usize)];
    file.read_exact_at(&mut head, 0)
        .map_err(|e| Error::io(path, e))?;
    let pre =
        Preamble::decode(&head).map_err(|(problem, fix)| Error::file(path, problem).fix(fix))?;
    if actual_len < pre.file_len {
        return Err(Error::file(
            path,
            format!("file is truncated ({actual_len} of {} bytes)", pre.file_len),
        )
        .fix("rebuild it with dbms pyramid"));
    }
    if actual_len > pre.file_len {
        return Err(corrupt(
            path,
            format!("file has {} bytes after its end", actual_len - pre.file_len),
        ));
    }
    match (header_end(&pre), index_end(&pre)) {
        (Some(h), Some(i))
            if pre.header_offset >= PREAMBLE_LEN as u64
                && pre.header_len <= MAX_HEADER_LEN
                && h <= pre.index_offset
                && i <= pre.file_len =>
        {
            Ok(pre)
        }
        _ => Err(corrupt(
            path,
            "preamble's header or index lies outside the file".into(),
        )),
    }
}

/// The byte offset just past the header, `None` if it overflows.
fn header_end(pre: &Preamble) -> Option<u64> {
    pre.header_offset.checked_add(pre.header_len)
}

/// The byte offset just past the index, `None` if it overflows.
fn index_end(pre: &Preamble) -> Option<u64> {
    let index_len = pre.page_count.checked_mul(ENTRY_LEN as u64);
    index_len.and_then(|n| n.checked_add(pre.index_offset))
}

/// The JSON header the checked preamble `pre` points to: its checksum matches, it describes a
/// valid tile set, and its levels have as many pages as the index.
fn read_header(file: &File, path: &Path, pre: &Preamble) -> Result<TileSetInfo> {
    let mut header = vec![0u8; pre.header_len as usize];
    file.read_exact_at(&mut header, pre.header_offset)
        .map_err(|e| Error::io(path, e))?;
    if crc32fast::hash(&header) != pre.header_crc {
        return Err(corrupt(path, "header checksum mismatch".into()));
    }
    let info: TileSetInfo = serde_json::from_slice(&header).map_err(|e| {
        corrupt(
            path,
            format!("header is not a valid tile set description ({e})"),
        )
    })?;
    info.validate().map_err(|e| e.in_file(path).fix(REBUILD))?;
    if pre.page_count != info.page_count() as u64 {
        return Err(corrupt(
            path,
            format!(
                "index has {} pages, the header's levels have {}",
                pre.page_count,
                info.page_count()
            ),
        ));
    }
    Ok(info)
}

/// The page index the checked preamble `pre` points to: its checksum matches and every entry
/// lies inside the file with plausible lengths for `layout`.
fn read_index(
    file: &File,
    path: &Path,
    pre: &Preamble,
    info: &TileSetInfo,
    layout: &Layout,
) -> Result<Vec<IndexEntry>> {
    let index_end = index_end(pre).expect("read_preamble checked it");
    let mut raw_index = vec![0u8; (index_end - pre.index_offset) as usize];
    file.read_exact_at(&mut raw_index, pre.index_offset)
        .map_err(|e| Error::io(path, e))?;
    if crc32fast::hash(&raw_index) != pre.index_crc {
        return Err(corrupt(path, "index checksum mismatch".into()));
    }
    let index: Vec<IndexEntry> = raw_index
        .chunks_exact(ENTRY_LEN)
        .map(|b| IndexEntry::decode(b.try_into().expect("24 bytes")))
        .collect();
    for (pos, e) in index.iter().enumerate() {
        if let Some(problem) = entry_problem(e, layout, info.alignment, index_end, pre.file_len) {
            let (level, tx, ty) = info.page_at(pos).expect("index matches the levels");
            return Err(corrupt(
                path,
                format!("page (level {level}, {tx}, {ty}) {problem}"),
            ));
        }
    }
    Ok(index)
}

/// What is wrong with an index entry, if anything.
fn entry_problem(
    e: &IndexEntry,
    layout: &Layout,
    align: u64,
    data_start: u64,
    file_len: u64,
) -> Option<String> {
    if e.flags & !KNOWN_FLAGS != 0 {
        return Some(format!("has unknown flags {:#x}", e.flags));
    }
    if !e.offset.is_multiple_of(align) || e.offset < align_up(data_start, align) {
        return Some(format!("has a misplaced offset {}", e.offset));
    }
    if e.offset
        .checked_add(e.stored_len as u64)
        .is_none_or(|end| end > file_len)
    {
        return Some("extends past the end of the file".into());
    }
    let fixed = layout.fixed_len as u64;
    let raw = e.raw_len as u64;
    if (e.flags & FLAG_BRICKS == 0 && raw != fixed) || raw < fixed {
        return Some(format!("has a raw length of {raw} bytes, expected {fixed}"));
    }
    if e.flags & FLAG_LZ4 == 0 && e.stored_len != e.raw_len {
        return Some(format!(
            "stores {} bytes uncompressed, expected {raw}",
            e.stored_len
        ));
    }
    // LZ4 expands at most 255:1; a larger claim is corruption (and would be a huge allocation).
    if e.flags & FLAG_LZ4 != 0 && raw > 255 * e.stored_len as u64 + 16 {
        return Some(format!(
            "claims {raw} raw bytes from {} compressed ones",
            e.stored_len
        ));
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::crs::Crs;
    use crate::grid::Grid;

    #[test]
    fn lz4_ratio_bound_admits_the_most_compressible_pages() {
        // A page of one cell (9 bytes of layers) whose bricks blob makes up the rest.
        let info = TileSetInfo::new(
            Grid::north_up(0.0, 0.0, 1.0, 1, 1, Crs::unknown()),
            1,
            4,
            None,
        )
        .unwrap();
        let layout = Layout::of(&info);
        let entry = |stored_len: usize, raw_len: usize| IndexEntry {
            offset: 4096,
            stored_len: stored_len as u32,
            raw_len: raw_len as u32,
            crc: 0,
            flags: FLAG_LZ4 | FLAG_BRICKS,
        };
        // All-equal bytes are lz4's best case: every real page must pass the open-time check.
        for len in [9usize, 16 * 9, 256 * 256 * 9, 1024 * 1024 * 9] {
            let stored = lz4_flex::block::compress(&vec![0u8; len]).len();
            assert_eq!(
                entry_problem(&entry(stored, len), &layout, 4096, 0, u64::MAX),
                None,
                "{len} → {stored} bytes"
            );
        }
        let problem = entry_problem(&entry(10, 100_000), &layout, 4096, 0, u64::MAX).unwrap();
        assert!(
            problem.contains("claims 100000 raw bytes from 10"),
            "{problem}"
        );
    }
}
