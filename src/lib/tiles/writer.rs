//! Writing a tile file: pages arrive in any order, the file comes out in canonical order.
//!
//! Invariant: the output depends only on the [`TileSetInfo`] and the set of pages, never on the
//! order or thread they arrived from. Memory stays bounded: each page is encoded by the calling
//! thread and appended to a spool file beside the output at once; the writer keeps only a
//! 24-byte record per page. [`TileWriter::finish`] streams the spool into the final layout
//! through a temporary file renamed into place, so a failed run never leaves a partial file.

use super::info::TileSetInfo;
use super::layout::{
    align_up, storage_order, IndexEntry, Preamble, ENTRY_LEN, PREAMBLE_LEN, VERSION,
};
use super::page::{self, Layout, Page};
use crate::error::{Error, Result};
use crate::io::atomic::write_atomic;
use std::io::Write;
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// Writes one tile file. `write_page` takes `&self`, so pages can be produced and written from
/// many threads (e.g. inside a rayon loop); encoding and compression run on the calling thread.
pub struct TileWriter {
    path: PathBuf,
    info: TileSetInfo,
    layout: Layout,
    spool: Mutex<Spool>,
}

struct Spool {
    file: tempfile::NamedTempFile,
    len: u64,
    /// One slot per index position: where the page's stored bytes sit in the spool.
    pages: Vec<Option<Spooled>>,
}

#[derive(Clone, Copy)]
struct Spooled {
    at: u64,
    stored_len: u32,
    raw_len: u32,
    crc: u32,
    flags: u32,
}

impl TileWriter {
    /// Start writing the tile set `info` to `path`. Nothing appears at `path` until
    /// [`finish`](Self::finish); the spool is a hidden temporary file in the same directory.
    pub fn create(path: &Path, info: TileSetInfo) -> Result<TileWriter> {
        info.validate().map_err(|e| e.in_file(path))?;
        if info.layers != super::info::standard_layers() {
            return Err(Error::file(
                path,
                "this dbms writes only the standard layers max_z, colour, state",
            ));
        }
        let dir = match path.parent() {
            Some(p) if !p.as_os_str().is_empty() => p,
            _ => Path::new("."),
        };
        let file = tempfile::Builder::new()
            .prefix(".dbms-spool-")
            .suffix(".tmp")
            .tempfile_in(dir)
            .map_err(|e| {
                Error::io(dir, e).fix("check that the output directory exists and is writable")
            })?;
        let pages = vec![None; info.page_count()];
        Ok(TileWriter {
            path: path.to_path_buf(),
            layout: Layout::of(&info),
            info,
            spool: Mutex::new(Spool {
                file,
                len: 0,
                pages,
            }),
        })
    }

    /// The tile set being written.
    pub fn info(&self) -> &TileSetInfo {
        &self.info
    }

    /// Write page `(level, tx, ty)`. Pages may come in any order, from any thread; each page
    /// exactly once. Errors on a page outside the tile set, a page written twice, layers of the
    /// wrong length, padding cells that are not nodata, or an unknown state value.
    pub fn write_page(&self, level: usize, tx: usize, ty: usize, page: &Page) -> Result<()> {
        let pos = self.info.index_position(level, tx, ty).ok_or_else(|| {
            Error::file(
                &self.path,
                format!("page (level {level}, {tx}, {ty}) is outside the tile set"),
            )
        })?;
        page::check(&self.info, level, tx, ty, page).map_err(|e| e.in_file(&self.path))?;
        let enc = page::encode(&self.layout, page, self.info.compression)
            .map_err(|e| e.in_file(&self.path))?;
        let mut spool = self.spool.lock().unwrap_or_else(|p| p.into_inner());
        if spool.pages[pos].is_some() {
            return Err(Error::file(
                &self.path,
                format!("page (level {level}, {tx}, {ty}) was written twice"),
            ));
        }
        let at = spool.len;
        spool
            .file
            .as_file()
            .write_all_at(&enc.stored, at)
            .map_err(|e| Error::io(spool.file.path(), e))?;
        spool.len += enc.stored.len() as u64;
        let stored_len = enc.stored.len() as u32; // ≤ raw_len (lz4 kept only when smaller)
        spool.pages[pos] = Some(Spooled {
            at,
            stored_len,
            raw_len: enc.raw_len,
            crc: enc.crc,
            flags: enc.flags,
        });
        Ok(())
    }

    /// Check every page was written, then write the file in canonical order and rename it
    /// into place. Errors name the first missing page.
    pub fn finish(self) -> Result<()> {
        let spool = self.spool.into_inner().unwrap_or_else(|p| p.into_inner());
        let missing = spool.pages.iter().filter(|p| p.is_none()).count();
        if let Some(first) = spool.pages.iter().position(Option::is_none) {
            let (level, tx, ty) = self.info.page_at(first).expect("position within the index");
            return Err(Error::file(
                &self.path,
                format!("{missing} page(s) were never written, the first is (level {level}, {tx}, {ty})"),
            )
            .fix("write every page of every level before finishing"));
        }
        let pages: Vec<Spooled> = spool
            .pages
            .into_iter()
            .map(|p| p.expect("checked above"))
            .collect();

        let header = serde_json::to_vec_pretty(&self.info).expect("header serialises");
        let header_offset = PREAMBLE_LEN as u64;
        let index_offset = align_up(header_offset + header.len() as u64, 8);
        let index_end = index_offset + (pages.len() * ENTRY_LEN) as u64;
        let align = self.info.alignment;
        let order = storage_order(&self.info);
        let mut entries = vec![
            IndexEntry {
                offset: 0,
                stored_len: 0,
                raw_len: 0,
                crc: 0,
                flags: 0
            };
            pages.len()
        ];
        let mut end = index_end;
        for &pos in &order {
            let p = pages[pos];
            let offset = align_up(end, align);
            entries[pos] = IndexEntry {
                offset,
                stored_len: p.stored_len,
                raw_len: p.raw_len,
                crc: p.crc,
                flags: p.flags,
            };
            end = offset + p.stored_len as u64;
        }
        let index: Vec<u8> = entries.iter().flat_map(|e| e.encode()).collect();
        let preamble = Preamble {
            version: VERSION,
            header_offset,
            header_len: header.len() as u64,
            index_offset,
            page_count: pages.len() as u64,
            file_len: end,
            header_crc: crc32fast::hash(&header),
            index_crc: crc32fast::hash(&index),
        };

        let path = &self.path;
        let spool_path = spool.file.path().to_path_buf();
        write_atomic(path, |w| {
            let io = |e| Error::io(path, e);
            let mut at = 0u64;
            let put = |w: &mut dyn Write, bytes: &[u8], at: &mut u64| -> Result<()> {
                w.write_all(bytes).map_err(io)?;
                *at += bytes.len() as u64;
                Ok(())
            };
            let zeros = vec![0u8; align as usize];
            put(w, &preamble.encode(), &mut at)?;
            put(w, &header, &mut at)?;
            put(w, &zeros[..(index_offset - at) as usize], &mut at)?;
            put(w, &index, &mut at)?;
            let mut buf = Vec::new();
            for &pos in &order {
                let (e, p) = (entries[pos], pages[pos]);
                put(w, &zeros[..(e.offset - at) as usize], &mut at)?;
                buf.resize(p.stored_len as usize, 0);
                spool
                    .file
                    .as_file()
                    .read_exact_at(&mut buf, p.at)
                    .map_err(|e| Error::io(&spool_path, e))?;
                put(w, &buf, &mut at)?;
            }
            debug_assert_eq!(at, end);
            Ok(())
        })
    }
}
