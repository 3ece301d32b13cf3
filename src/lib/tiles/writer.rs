//! Writing a tile file: pages arrive in any order, the file comes out in canonical order.
//!
//! Invariant: the output depends only on the [`TileSetInfo`] and the set of pages, never on the
//! order or thread they arrived from. Memory stays bounded: each page is encoded by the calling
//! thread and handed to the writer's one I/O thread, which writes it to a temporary file beside
//! the output (at most [`QUEUED_PAGES`] pages wait); the writer keeps only a small record per
//! page. Uncompressed pages without bricks all have the same length, so their
//! canonical offsets are known before the first page arrives: such a page goes straight to its
//! final place, and when every page did, [`TileWriter::finish`] only adds the preamble, header
//! and index in front and renames the file into place. Otherwise (lz4, bricks) pages are
//! appended as they come and `finish` copies them into canonical order through a second
//! temporary file. Either way a failed or killed run leaves no partial output: the temporary
//! files are removed on drop.

use super::info::{Compression, TileSetInfo};
use super::layout::{
    align_up, storage_order, IndexEntry, Preamble, ENTRY_LEN, PREAMBLE_LEN, VERSION,
};
use super::page::{self, Layout, Page, StoredBytes, MEMORY_ALIGN};
use crate::error::{Error, Result};
use crate::io::atomic::{AtomicFile, Staged};
use std::fs::File;
use std::io::Write;
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};
use std::sync::mpsc::{sync_channel, SyncSender};
use std::sync::{Arc, Mutex};
use std::thread::JoinHandle;

/// Pages encoded and waiting for the I/O thread, at most (each up to one page's raw bytes).
pub const QUEUED_PAGES: usize = 32;

/// Writes one tile file. `write_page` takes `&self`, so pages can be produced and written from
/// many threads (e.g. inside a rayon loop); checking, encoding and compression run on the
/// calling thread, outside any lock, and the positioned writes on the writer's own I/O thread.
/// One thread writes because concurrent writes to one file serialise on its inode lock in the
/// kernel, where waiting threads spin (measured: a tenth of the CPU of a pyramid build).
pub struct TileWriter {
    path: PathBuf,
    info: TileSetInfo,
    layout: Layout,
    header: Vec<u8>,
    /// Canonical offset of every page (by index position) if all pages are `fixed_len` bytes
    /// uncompressed without bricks; `None` with lz4, where lengths are known only once encoded.
    plan: Option<Vec<u64>>,
    target: Target,
    slots: Mutex<Slots>,
    io: Sink,
}

/// The I/O thread: takes `(bytes, offset)` and writes them into the target file, in arrival
/// order. On the first error it stops taking more and keeps the error, which the next
/// [`Sink::send`] or [`Sink::close`] returns.
///
/// Bytes aligned in memory, length and offset (uncompressed pages of the usual sizes) go through
/// a second handle opened with `O_DIRECT` when the file system allows it: straight to the disk,
/// without a copy into the page cache and without the long `fsync` of the whole file at the end
/// (the final `fsync` still makes the header, index and metadata durable). Anything else, or
/// everything once a direct write is refused, goes through the ordinary handle.
struct Sink {
    queue: Option<SyncSender<(StoredBytes, u64)>>,
    thread: Option<JoinHandle<()>>,
    failed: Arc<Mutex<Option<std::io::Error>>>,
}

impl Sink {
    fn start(file: File, mut direct: Option<File>) -> std::io::Result<Sink> {
        let (queue, pages) = sync_channel::<(StoredBytes, u64)>(QUEUED_PAGES);
        let failed = Arc::new(Mutex::new(None));
        let keep = Arc::clone(&failed);
        let thread = std::thread::Builder::new()
            .name("dbms-tile-io".into())
            .spawn(move || {
                for (bytes, at) in pages {
                    let bytes = &bytes[..];
                    let mut written = false;
                    if let Some(d) = direct.as_ref().filter(|_| direct_ok(bytes, at)) {
                        match d.write_all_at(bytes, at) {
                            Ok(()) => written = true,
                            // Refused (EINVAL: the file system or device wants other
                            // alignment): write this and all later pages the ordinary way.
                            Err(_) => direct = None,
                        }
                    }
                    if written {
                        continue;
                    }
                    if let Err(e) = file.write_all_at(bytes, at) {
                        *keep.lock().unwrap_or_else(|p| p.into_inner()) = Some(e);
                        return;
                    }
                }
            })?;
        Ok(Sink {
            queue: Some(queue),
            thread: Some(thread),
            failed,
        })
    }

    /// Queue `bytes` for offset `at`, or the error the I/O thread stopped on.
    fn send(&self, bytes: StoredBytes, at: u64) -> std::io::Result<()> {
        let queue = self.queue.as_ref().expect("open until closed");
        match queue.send((bytes, at)) {
            Ok(()) => Ok(()),
            Err(_) => Err(self.error()),
        }
    }

    /// Wait for every queued write; the error the I/O thread stopped on, if any.
    fn close(&mut self) -> std::io::Result<()> {
        self.queue = None;
        let Some(thread) = self.thread.take() else {
            return Ok(());
        };
        if thread.join().is_err() {
            return Err(std::io::Error::other(
                "the tile writer's I/O thread panicked",
            ));
        }
        match self.failed.lock().unwrap_or_else(|p| p.into_inner()).take() {
            Some(e) => Err(e),
            None => Ok(()),
        }
    }

    /// The error the I/O thread stopped on (taken once; later callers get a generic one).
    fn error(&self) -> std::io::Error {
        let kept = self.failed.lock().unwrap_or_else(|p| p.into_inner()).take();
        kept.unwrap_or_else(|| std::io::Error::other("an earlier write of the tile file failed"))
    }
}

/// Whether `bytes` at file offset `at` meet `O_DIRECT`'s alignment (memory, length, offset).
fn direct_ok(bytes: &[u8], at: u64) -> bool {
    let a = MEMORY_ALIGN;
    (bytes.as_ptr() as usize).is_multiple_of(a)
        && bytes.len().is_multiple_of(a)
        && at.is_multiple_of(a as u64)
}

/// A second, write-only handle of `path` with `O_DIRECT`, if the file system supports it.
#[cfg(target_os = "linux")]
fn open_direct(path: &Path) -> Option<File> {
    use std::os::unix::fs::OpenOptionsExt;
    std::fs::OpenOptions::new()
        .write(true)
        .custom_flags(libc::O_DIRECT)
        .open(path)
        .ok()
}

#[cfg(not(target_os = "linux"))]
fn open_direct(_path: &Path) -> Option<File> {
    None
}

impl Drop for Sink {
    fn drop(&mut self) {
        let _ = self.close();
    }
}

/// Where pages are written (the I/O thread holds a second handle of the same file).
enum Target {
    /// The output's temporary file (planned layout): renamed into place by `finish`.
    Direct(tempfile::NamedTempFile),
    /// An unnamed spool file (lz4): nothing to clean up even if the process is killed.
    Spool(File),
}

impl Target {
    fn file(&self) -> &File {
        match self {
            Target::Direct(t) => t.as_file(),
            Target::Spool(f) => f,
        }
    }
}

struct Slots {
    /// Append cursor: pages that are not at their planned place go here, past the plan's end.
    len: u64,
    /// One slot per index position: where the page's stored bytes sit in the target file.
    pages: Vec<Option<Stored>>,
}

#[derive(Clone, Copy)]
struct Stored {
    at: u64,
    stored_len: u32,
    raw_len: u32,
    crc: u32,
    flags: u32,
}

impl Stored {
    /// What [`place`] needs: the stored length and whether the page has bricks.
    fn slot(&self) -> (u64, bool) {
        (self.stored_len as u64, self.flags & page::FLAG_BRICKS != 0)
    }

    fn of(e: &IndexEntry) -> Stored {
        Stored {
            at: e.offset,
            stored_len: e.stored_len,
            raw_len: e.raw_len,
            crc: e.crc,
            flags: e.flags,
        }
    }
}

/// Where the index starts and ends for a header of `header_len` bytes and `pages` pages.
fn index_span(header_len: usize, pages: usize) -> (u64, u64) {
    let index_offset = align_up(PREAMBLE_LEN as u64 + header_len as u64, 8);
    (index_offset, index_offset + (pages * ENTRY_LEN) as u64)
}

/// After a page with a bricks blob the next page starts at the page's offset plus its length
/// rounded up to a multiple of this many bytes: room for the blob to grow or shrink when an
/// edit moves voxels, so that the pages after it keep their offsets and an incremental build
/// can change just this page in place ([`InPlace`]). A sixteenth of a page without bricks, as
/// a power of two, and at least the alignment: 64 KiB for pages of 256 (whose 589 824 bytes
/// are 9 × 64 KiB), 4 KiB for 64 and below. Pages without bricks need none.
pub fn bricks_slot(info: &TileSetInfo) -> u64 {
    let fixed = Layout::of(info).fixed_len as u64;
    (fixed / 16).next_power_of_two().max(info.alignment)
}

/// Canonical offsets (by index position) of pages of the given stored lengths and bricks flags,
/// and the file's end (the end of the last page's bytes: no trailing padding).
fn place(
    info: &TileSetInfo,
    index_end: u64,
    stored: impl Fn(usize) -> (u64, bool),
) -> (Vec<u64>, u64) {
    let mut offsets = vec![0; info.page_count()];
    let slot = bricks_slot(info);
    let (mut next, mut end) = (index_end, index_end);
    for pos in storage_order(info) {
        let offset = align_up(next, info.alignment);
        let (len, bricks) = stored(pos);
        offsets[pos] = offset;
        end = offset + len;
        next = match bricks {
            true => offset + align_up(len, slot),
            false => end,
        };
    }
    (offsets, end)
}

impl TileWriter {
    /// Start writing the tile set `info` to `path`. Nothing appears at `path` until
    /// [`finish`](Self::finish); pages go to a hidden temporary file in the same directory.
    pub fn create(path: &Path, info: TileSetInfo) -> Result<TileWriter> {
        info.validate().map_err(|e| e.in_file(path))?;
        if !info.writable_layers() {
            return Err(Error::file(
                path,
                "this dbms writes only the standard layers max_z, colour, state, then any of the sensor layers material, temperature, radiance in that order",
            ));
        }
        crate::io::atomic::check_output(path)?;
        let dir = crate::io::atomic::output_dir(path);
        let cannot =
            |e| Error::io(dir, e).fix("check that the output directory exists and is writable");
        let layout = Layout::of(&info);
        let header = serde_json::to_vec_pretty(&info).expect("header serialises");
        if header.len() as u64 > super::info::MAX_HEADER_LEN {
            return Err(Error::file(
                path,
                format!(
                    "the tile header would be {} bytes, over the format's {} ({} light points)",
                    header.len(),
                    super::info::MAX_HEADER_LEN,
                    info.lights.len()
                ),
            )
            .fix("give fewer light points (about 150 000 fit), or split the area into several databases"));
        }
        let (_, index_end) = index_span(header.len(), info.page_count());
        let (plan, target, len) = match info.compression {
            Compression::None => {
                let fixed = layout.fixed_len as u64;
                let (plan, end) = place(&info, index_end, |_| (fixed, false));
                let tmp = crate::io::atomic::temp_beside(path)?;
                (Some(plan), Target::Direct(tmp), end)
            }
            Compression::Lz4 => (
                None,
                Target::Spool(tempfile::tempfile_in(dir).map_err(cannot)?),
                0,
            ),
        };
        let pages = vec![None; info.page_count()];
        let direct = match &target {
            Target::Direct(tmp) => open_direct(tmp.path()),
            Target::Spool(_) => None,
        };
        let io = target
            .file()
            .try_clone()
            .and_then(|f| Sink::start(f, direct))
            .map_err(cannot)?;
        Ok(TileWriter {
            path: path.to_path_buf(),
            layout,
            header,
            plan,
            target,
            info,
            slots: Mutex::new(Slots { len, pages }),
            io,
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
        let pos = self.info.page_position(&self.path, (level, tx, ty))?;
        page::check(&self.info, level, tx, ty, page).map_err(|e| e.in_file(&self.path))?;
        let enc = page::encode(&self.layout, page, self.info.compression)
            .map_err(|e| e.in_file(&self.path))?;
        let record = Stored {
            at: 0,
            stored_len: enc.stored.len() as u32, // ≤ raw_len (lz4 kept only when smaller)
            raw_len: enc.raw_len,
            crc: enc.crc,
            flags: enc.flags,
        };
        self.put(pos, (level, tx, ty), record, enc.stored)
    }

    /// Write page `(level, tx, ty)` as `stored` bytes with the index `entry` they were read with
    /// ([`super::TileReader::stored`]) from a tile file of the same description: the page copied
    /// unchanged, without decoding or encoding it. The same checks on the position and on
    /// writing twice as [`write_page`](Self::write_page); the bytes must match the entry's
    /// length and CRC.
    pub fn write_stored(
        &self,
        level: usize,
        tx: usize,
        ty: usize,
        entry: IndexEntry,
        stored: Vec<u8>,
    ) -> Result<()> {
        let pos = self.info.page_position(&self.path, (level, tx, ty))?;
        if stored.len() != entry.stored_len as usize || crc32fast::hash(&stored) != entry.crc {
            return Err(Error::file(
                &self.path,
                format!(
                    "internal: page (level {level}, {tx}, {ty}) copied with a wrong length or CRC"
                ),
            ));
        }
        let record = Stored {
            at: 0,
            stored_len: entry.stored_len,
            raw_len: entry.raw_len,
            crc: entry.crc,
            flags: entry.flags,
        };
        self.put(pos, (level, tx, ty), record, stored.into())
    }

    /// Place page `pos` (`record` without its offset yet) and queue its bytes for the I/O thread.
    fn put(
        &self,
        pos: usize,
        (level, tx, ty): (usize, usize, usize),
        mut record: Stored,
        stored: StoredBytes,
    ) -> Result<()> {
        let stored_len = record.stored_len;
        let at = {
            let mut slots = self.slots.lock().unwrap_or_else(|p| p.into_inner());
            if slots.pages[pos].is_some() {
                return Err(Error::file(
                    &self.path,
                    format!("page (level {level}, {tx}, {ty}) was written twice"),
                ));
            }
            let at = match &self.plan {
                Some(plan) if stored_len as usize == self.layout.fixed_len => plan[pos],
                _ => {
                    let at = slots.len;
                    slots.len += stored_len as u64;
                    at
                }
            };
            record.at = at;
            slots.pages[pos] = Some(record);
            at
        };
        self.io.send(stored, at).map_err(|e| {
            Error::io(&self.path, e).fix("check the free space in the output's directory")
        })
    }

    /// Check every page was written, then finish the file in canonical order and rename it
    /// into place. Errors name the first missing page.
    pub fn finish(self) -> Result<()> {
        self.stage()?.commit()
    }

    /// [`finish`](Self::finish) but leave the file under its temporary name, for a run that
    /// renames all its outputs together ([`crate::io::atomic::commit_all`]).
    pub fn stage(mut self) -> Result<Staged> {
        self.io.close().map_err(|e| {
            Error::io(&self.path, e).fix("check the free space in the output's directory")
        })?;
        let slots = self.slots.into_inner().unwrap_or_else(|p| p.into_inner());
        let pages = every_page(slots, &self.info, &self.path)?;
        let (index_offset, index_end) = index_span(self.header.len(), pages.len());
        let (offsets, end) = place(&self.info, index_end, |pos| pages[pos].slot());
        let front = front_matter(&self.header, &pages, &offsets, index_offset, end);
        let path = &self.path;
        let in_place = pages.iter().zip(&offsets).all(|(p, &o)| p.at == o);
        match self.target {
            Target::Direct(tmp) if in_place => add_front(tmp, &front, end, path),
            target => {
                let mut out = AtomicFile::create(path)?;
                let w = out.writer();
                w.write_all(&front).map_err(|e| Error::io(path, e))?;
                let order = storage_order(&self.info);
                let at = copy_pages(target.file(), w, &pages, &offsets, &order, index_end)
                    .map_err(|e| Error::io(path, e))?;
                debug_assert_eq!(at, end);
                out.stage()
            }
        }
    }
}

/// A change of the tile file `path` in place: `pages` replaced, every other page kept as
/// stored, planned by [`InPlace::plan`] only when that leaves every kept page at its offset,
/// so the result is byte for byte what a [`TileWriter`] of the same description and pages
/// writes. Nothing is touched until [`apply`](Self::apply).
pub struct InPlace {
    path: PathBuf,
    /// `(index position, encoded page, stored length of the page it replaces)`.
    pages: Vec<(usize, u64, page::Encoded, usize)>,
    /// Preamble, header and index, zero-padded to the first page.
    front: Vec<u8>,
    end: u64,
    checksums: (u32, u32),
}

impl InPlace {
    /// The change of `path` (open in `earlier`) to describe `info` with `pages` replaced, or
    /// `None` when a page would move (the caller writes the file anew).
    pub fn plan(
        path: &Path,
        info: &TileSetInfo,
        earlier: &super::TileReader,
        pages: &[((usize, usize, usize), &Page)],
    ) -> Result<Option<InPlace>> {
        if earlier.info().compression != info.compression
            || earlier.info().page_count() != info.page_count()
        {
            return Ok(None);
        }
        let layout = Layout::of(info);
        let mut records: Vec<Stored> = earlier.entries().iter().map(Stored::of).collect();
        let mut encoded = Vec::with_capacity(pages.len());
        for &((level, tx, ty), page) in pages {
            let pos = info
                .index_position(level, tx, ty)
                .expect("a page of the tile set");
            page::check(info, level, tx, ty, page).map_err(|e| e.in_file(path))?;
            let enc = page::encode(&layout, page, info.compression).map_err(|e| e.in_file(path))?;
            let old = records[pos];
            records[pos] = Stored {
                at: old.at,
                stored_len: enc.stored.len() as u32,
                raw_len: enc.raw_len,
                crc: enc.crc,
                flags: enc.flags,
            };
            encoded.push((pos, old.at, enc, old.stored_len as usize));
        }
        let header = serde_json::to_vec_pretty(info).expect("header serialises");
        let (index_offset, index_end) = index_span(header.len(), records.len());
        let (offsets, end) = place(info, index_end, |pos| records[pos].slot());
        if records.iter().zip(&offsets).any(|(r, &o)| r.at != o) {
            return Ok(None);
        }
        let mut front = front_matter(&header, &records, &offsets, index_offset, end);
        let index = &front[index_offset as usize..];
        let checksums = (crc32fast::hash(&header), crc32fast::hash(index));
        let first = offsets.iter().copied().min().unwrap_or(end);
        front.resize(front.len().max(first as usize), 0);
        Ok(Some(InPlace {
            path: path.to_path_buf(),
            pages: encoded,
            front,
            end,
            checksums,
        }))
    }

    /// `[file length, header CRC, index CRC]` of the file once changed.
    pub fn stamp(&self) -> [u64; 3] {
        [self.end, self.checksums.0 as u64, self.checksums.1 as u64]
    }

    /// Change the file: rename it to a temporary name in its directory, write the replaced
    /// pages (each zero-filled to the end of what its slot held before), the front and the
    /// length, sync it, and stage it for renaming back. While it is changed it is not at
    /// `path`: no reader that opens `path` meets it half-written, and a run that fails or is
    /// killed meanwhile leaves no `path` at all (a `make` target missing, not stale). A reader
    /// that already had it open reads the replaced pages through the old index and reports
    /// them as damaged; another hard link to the file changes with it.
    pub fn apply(self) -> Result<Staged> {
        let path = &self.path;
        let io = |e| Error::io(path, e);
        let tmp = crate::io::atomic::temp_beside(path)?.into_temp_path();
        std::fs::rename(path, &tmp).map_err(io)?;
        let f = std::fs::OpenOptions::new()
            .write(true)
            .open(&tmp)
            .map_err(io)?;
        for (_, at, enc, old_len) in &self.pages {
            let mut bytes = enc.stored.to_vec();
            bytes.resize(bytes.len().max(*old_len), 0);
            f.write_all_at(&bytes, *at).map_err(io)?;
        }
        crate::db::fault_point("tiles-in-place");
        f.write_all_at(&self.front, 0).map_err(io)?;
        f.set_len(self.end).map_err(io)?;
        f.sync_all().map_err(io)?;
        Staged::new(path, tmp)
    }
}

/// Every page's record, by index position; an error naming the first page never written.
fn every_page(slots: Slots, info: &TileSetInfo, path: &Path) -> Result<Vec<Stored>> {
    let missing = slots.pages.iter().filter(|p| p.is_none()).count();
    if let Some(first) = slots.pages.iter().position(Option::is_none) {
        let (level, tx, ty) = info.page_at(first).expect("position within the index");
        return Err(Error::file(
            path,
            format!(
                "{missing} page(s) were never written, the first is (level {level}, {tx}, {ty})"
            ),
        )
        .fix("write every page of every level before finishing"));
    }
    Ok(slots
        .pages
        .into_iter()
        .map(|p| p.expect("checked above"))
        .collect())
}

/// The bytes before the first page: preamble, `header`, zero padding up to `index_offset`, and
/// the index of `pages` at their canonical `offsets`, in a file `end` bytes long.
fn front_matter(
    header: &[u8],
    pages: &[Stored],
    offsets: &[u64],
    index_offset: u64,
    end: u64,
) -> Vec<u8> {
    let index: Vec<u8> = pages
        .iter()
        .zip(offsets)
        .flat_map(|(p, &offset)| {
            IndexEntry {
                offset,
                stored_len: p.stored_len,
                raw_len: p.raw_len,
                crc: p.crc,
                flags: p.flags,
            }
            .encode()
        })
        .collect();
    let preamble = Preamble {
        version: VERSION,
        header_offset: PREAMBLE_LEN as u64,
        header_len: header.len() as u64,
        index_offset,
        page_count: pages.len() as u64,
        file_len: end,
        header_crc: crc32fast::hash(header),
        index_crc: crc32fast::hash(&index),
    };
    let mut front = preamble.encode().to_vec();
    front.extend_from_slice(header);
    front.resize(index_offset as usize, 0);
    front.extend_from_slice(&index);
    front
}

/// Finish a temporary file whose every page already sits at its canonical offset: write
/// `front` at its start, cut it to `end` bytes, make it readable like any output, sync it, and
/// stage it for renaming to `path`.
fn add_front(tmp: tempfile::NamedTempFile, front: &[u8], end: u64, path: &Path) -> Result<Staged> {
    let io = |e| Error::io(path, e);
    let f = tmp.as_file();
    f.write_all_at(front, 0).map_err(io)?;
    f.set_len(end).map_err(io)?;
    // tempfile creates 0600; outputs are ordinary files other users and tools may read.
    use std::os::unix::fs::PermissionsExt;
    f.set_permissions(std::fs::Permissions::from_mode(0o644))
        .map_err(io)?;
    f.sync_all().map_err(io)?;
    Staged::new(path, tmp.into_temp_path())
}

/// Copy `pages` from `from` to `to` in storage `order`, each zero-padded up to its canonical
/// offset, starting at `index_end` (where `to` stands); returns the offset reached.
fn copy_pages(
    from: &File,
    to: &mut impl Write,
    pages: &[Stored],
    offsets: &[u64],
    order: &[usize],
    index_end: u64,
) -> std::io::Result<u64> {
    let (mut at, mut buf) = (index_end, Vec::new());
    for &pos in order {
        let p = pages[pos];
        let pad = offsets[pos] - at;
        buf.clear();
        buf.resize(pad as usize + p.stored_len as usize, 0);
        from.read_exact_at(&mut buf[pad as usize..], p.at)?;
        to.write_all(&buf)?;
        at = offsets[pos] + p.stored_len as u64;
    }
    Ok(at)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A direct handle that refuses writes (here: opened read-only) hands the page, and every
    /// later one, to the ordinary handle; unaligned bytes never try it.
    #[test]
    fn sink_falls_back_to_the_ordinary_handle() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t");
        let file = File::create(&path).unwrap();
        let refusing = File::open(&path).unwrap();
        let mut sink = Sink::start(file, Some(refusing)).unwrap();
        let page = |fill: u8| {
            let mut b = StoredBytes::aligned_zeroed(2 * MEMORY_ALIGN);
            b.as_mut_slice().fill(fill);
            b
        };
        assert!(direct_ok(&page(0), 4096));
        sink.send(page(1), 4096).unwrap();
        sink.send(page(2), 3 * 4096).unwrap();
        sink.send(vec![3u8; 5].into(), 1).unwrap();
        sink.close().unwrap();
        let bytes = std::fs::read(&path).unwrap();
        assert_eq!(bytes.len(), 5 * 4096);
        assert_eq!(&bytes[1..6], &[3; 5]);
        assert!(bytes[4096..3 * 4096].iter().all(|&b| b == 1));
        assert!(bytes[3 * 4096..].iter().all(|&b| b == 2));
    }

    /// A header no reader would accept (too many light points) is refused before anything is
    /// written, with the light count and the fix.
    #[test]
    fn a_header_over_the_readers_limit_is_refused() {
        let t = tempfile::tempdir().unwrap();
        let grid = crate::grid::Grid::north_up(0.0, 100.0, 1.0, 8, 8, crate::crs::Crs::unknown());
        let mut info = TileSetInfo::new(grid, 8, 4, None).unwrap();
        let lamp = crate::tiles::LightPoint {
            x: 1.123456789,
            y: 2.123456789,
            z: 3.123456789,
            intensity_cd: 1500.5,
            colour: [255, 200, 130],
            beam: None,
        };
        info.lights = vec![lamp; 200_000];
        let path = t.path().join("l.dbt");
        let e = TileWriter::create(&path, info).err().unwrap().to_string();
        assert!(
            e.contains("200000 light points") && e.contains("fewer"),
            "{e}"
        );
        assert!(!path.exists());
    }

    /// A write error on the I/O thread comes back from `send` or `close`, not lost.
    #[test]
    fn sink_reports_a_write_error() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("t");
        std::fs::write(&path, b"x").unwrap();
        let read_only = File::open(&path).unwrap();
        let mut sink = Sink::start(read_only, None).unwrap();
        let first = sink.send(vec![1u8; 10].into(), 0);
        let err = first.and_then(|_| sink.close()).unwrap_err();
        assert_eq!(err.raw_os_error(), Some(9), "EBADF: {err}");
    }
}
