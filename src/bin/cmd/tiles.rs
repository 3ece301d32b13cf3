//! `dbms tiles TILES [--verify] [--index]`: describe a tile file, optionally check every page
//! and list its page index.

use super::Ctx;
use dbms::tiles::{IndexEntry, TileReader, TileSetInfo, FLAG_BRICKS, FLAG_LZ4, FLAG_SHUFFLE};
use serde::Serialize;
use std::path::PathBuf;

/// Print a tile file's header summary; with --verify, check every page's checksum.
#[derive(clap::Args)]
pub struct Args {
    /// The tile file (written by `dbms pyramid`).
    tiles: PathBuf,
    /// Read every page and check its checksum; exit non-zero naming the first bad page.
    #[arg(long)]
    verify: bool,
    /// Also list the page index: every page's (level, tx, ty), offset, lengths, CRC-32 and flags,
    /// in index order (JSON: schemas/tiles-index.schema.json).
    #[arg(long)]
    index: bool,
}

/// The names of the flags set in an index entry (docs/tile-format.md, Index).
fn flag_names(flags: u32) -> Vec<&'static str> {
    [
        (FLAG_LZ4, "lz4"),
        (FLAG_BRICKS, "bricks"),
        (FLAG_SHUFFLE, "planes"),
    ]
    .into_iter()
    .filter(|&(bit, _)| flags & bit != 0)
    .map(|(_, name)| name)
    .collect()
}

/// One page's index entry as `dbms tiles --index` lists it (schemas/tiles-index.schema.json).
#[derive(Serialize)]
struct Listed {
    level: usize,
    tx: usize,
    ty: usize,
    offset: u64,
    stored_len: u32,
    raw_len: u32,
    crc32: u32,
    flags: Vec<&'static str>,
}

impl Listed {
    fn new((level, tx, ty): (usize, usize, usize), e: &IndexEntry) -> Listed {
        Listed {
            level,
            tx,
            ty,
            offset: e.offset,
            stored_len: e.stored_len,
            raw_len: e.raw_len,
            crc32: e.crc,
            flags: flag_names(e.flags),
        }
    }
}

pub fn run(args: Args, ctx: &Ctx) -> dbms::Result<()> {
    let reader = TileReader::open(&args.tiles, 0)?;
    let verified = if args.verify {
        let progress = ctx.progress(reader.entries().len() as u64, "verifying");
        let n = reader.verify(&progress)?;
        let regions = dbms::tiles::region::verify(&args.tiles, &reader, &progress)?;
        progress.finish();
        Some((n, regions))
    } else {
        None
    };
    let info = reader.info();
    let entries = reader.entries();
    let stored: u64 = entries.iter().map(|e| e.stored_len as u64).sum();
    let raw: u64 = entries.iter().map(|e| e.raw_len as u64).sum();
    let compressed = entries.iter().filter(|e| e.flags & FLAG_LZ4 != 0).count();
    let with_bricks = entries
        .iter()
        .filter(|e| e.flags & FLAG_BRICKS != 0)
        .count();

    ctx.report(&TileFileInfo {
        path: args.tiles.clone(),
        format_version: reader.version(),
        file_bytes: reader.file_len(),
        header: info,
        pages: entries.len(),
        compressed_pages: compressed,
        pages_with_bricks: with_bricks,
        stored_bytes: stored,
        raw_bytes: raw,
        verified_pages: verified.map(|(n, _)| n),
        verified_regions: verified.map(|(_, r)| r).filter(|r| r.regions > 0),
        // With --index: each entry beside the page its index position stands for.
        index: args.index.then(|| {
            (entries.iter().enumerate())
                .map(|(pos, e)| {
                    Listed::new(info.page_at(pos).expect("an entry per index position"), e)
                })
                .collect()
        }),
    });
    Ok(())
}

/// `dbms tiles`' summary: the header and the index's totals, optionally the index.
#[derive(Serialize)]
struct TileFileInfo<'a> {
    path: PathBuf,
    format_version: u32,
    file_bytes: u64,
    header: &'a TileSetInfo,
    pages: usize,
    compressed_pages: usize,
    pages_with_bricks: usize,
    stored_bytes: u64,
    raw_bytes: u64,
    /// Pages whose checksum `--verify` checked.
    verified_pages: Option<usize>,
    /// With regions: what `--verify` checked of them.
    #[serde(skip_serializing_if = "Option::is_none")]
    verified_regions: Option<dbms::tiles::region::Verified>,
    index: Option<Vec<Listed>>,
}

impl std::fmt::Display for TileFileInfo<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let info = self.header;
        let g = &info.grid;
        let (cx, cy) = g.cell_size();
        writeln!(
            f,
            "{}: dbms tile file, format version {}, {} bytes",
            self.path.display(),
            self.format_version,
            self.file_bytes
        )?;
        writeln!(
            f,
            "grid {}×{} cells of {cx}×{cy} {} ({}), origin ({}, {})",
            g.width,
            g.height,
            g.crs.unit(),
            g.crs.name(),
            g.transform.origin_x,
            g.transform.origin_y
        )?;
        writeln!(
            f,
            "pages of {0}×{0} cells, factor {1}, {2} levels:",
            info.page_size,
            info.factor,
            info.levels.len()
        )?;
        for l in &info.levels {
            writeln!(
                f,
                "  level {}: {}×{} cells of {}×{}, {}×{} pages",
                l.level,
                l.width,
                l.height,
                l.cell_x.abs(),
                l.cell_y.abs(),
                l.pages_x,
                l.pages_y
            )?;
        }
        let layers: Vec<String> = (info.layers.iter())
            .map(|l| format!("{} ({})", l.name, l.kind))
            .collect();
        writeln!(f, "layers: {}", layers.join(", "))?;
        writeln!(
            f,
            "compression: {} ({} of {} pages compressed, {} of {} bytes stored); {} pages with bricks",
            info.compression.name(),
            self.compressed_pages,
            self.pages,
            self.stored_bytes,
            self.raw_bytes,
            self.pages_with_bricks
        )?;
        write!(f, "effects: {}", info.effects)?;
        if let Some(n) = self.verified_pages {
            write!(f, "\nverified: all {n} pages match their checksums")?;
        }
        if let Some(r) = &self.verified_regions {
            write!(
                f,
                "\nverified: {} regions, all {} of their pages; their parents' {} cells over them hold their covers",
                r.regions, r.pages, r.covered_cells
            )?;
        }
        for r in &info.regions {
            write!(
                f,
                "\nregion {}: {}× finer than {} over its cells {}, in {}",
                r.name,
                r.factor,
                r.parent.as_deref().unwrap_or("the base"),
                r.window,
                r.file
            )?;
        }
        if let Some(index) = &self.index {
            write!(
                f,
                "\nindex (level, tx, ty: offset, stored/raw bytes, crc32, flags):"
            )?;
            for e in index {
                let flags = match e.flags.join("+") {
                    names if names.is_empty() => "none".to_string(),
                    names => names,
                };
                write!(
                    f,
                    "\n  {}, {}, {}: {}, {}/{}, {:08x}, {flags}",
                    e.level, e.tx, e.ty, e.offset, e.stored_len, e.raw_len, e.crc32
                )?;
            }
        }
        Ok(())
    }
}
