//! `dbms tiles TILES [--verify] [--index]`: describe a tile file, optionally check every page
//! and list its page index.

use super::Ctx;
use dbms::tiles::{IndexEntry, TileReader, FLAG_BRICKS, FLAG_LZ4, FLAG_SHUFFLE};
use serde_json::json;
use std::fmt::Write as _;
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

/// One page's index entry as `dbms tiles --index --json` lists it.
fn entry_json(page: (usize, usize, usize), e: &IndexEntry) -> serde_json::Value {
    json!({
        "level": page.0, "tx": page.1, "ty": page.2,
        "offset": e.offset, "stored_len": e.stored_len, "raw_len": e.raw_len,
        "crc32": e.crc, "flags": flag_names(e.flags),
    })
}

pub fn run(args: Args, ctx: &Ctx) -> dbms::Result<()> {
    let reader = TileReader::open(&args.tiles, 0)?;
    let verified = if args.verify {
        let progress = ctx.progress(reader.entries().len() as u64, "verifying");
        let n = reader.verify(&progress)?;
        progress.finish();
        Some(n)
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

    let mut human = String::new();
    let g = &info.grid;
    let (cx, cy) = g.cell_size();
    let _ = writeln!(
        human,
        "{}: dbms tile file, format version {}, {} bytes",
        args.tiles.display(),
        reader.version(),
        reader.file_len()
    );
    let _ = writeln!(
        human,
        "grid {}×{} cells of {cx}×{cy} {} ({}), origin ({}, {})",
        g.width,
        g.height,
        g.crs.unit(),
        g.crs.name(),
        g.transform.origin_x,
        g.transform.origin_y
    );
    let _ = writeln!(
        human,
        "pages of {0}×{0} cells, factor {1}, {2} levels:",
        info.page_size,
        info.factor,
        info.levels.len()
    );
    for l in &info.levels {
        let _ = writeln!(
            human,
            "  level {}: {}×{} cells of {}×{}, {}×{} pages",
            l.level,
            l.width,
            l.height,
            l.cell_x.abs(),
            l.cell_y.abs(),
            l.pages_x,
            l.pages_y
        );
    }
    let layers: Vec<String> = info
        .layers
        .iter()
        .map(|l| format!("{} ({})", l.name, l.kind))
        .collect();
    let _ = writeln!(human, "layers: {}", layers.join(", "));
    let _ = writeln!(
        human,
        "compression: {} ({compressed} of {} pages compressed, {stored} of {raw} bytes stored); {with_bricks} pages with bricks",
        info.compression.name(),
        entries.len()
    );
    let _ = write!(human, "effects: {}", info.effects);
    if let Some(n) = verified {
        let _ = write!(human, "\nverified: all {n} pages match their checksums");
    }
    // With --index: each entry beside the page its index position stands for.
    let index: Option<Vec<_>> = args.index.then(|| {
        entries
            .iter()
            .enumerate()
            .map(|(pos, e)| (info.page_at(pos).expect("an entry per index position"), e))
            .collect()
    });
    if let Some(pages) = &index {
        let _ = write!(
            human,
            "\nindex (level, tx, ty: offset, stored/raw bytes, crc32, flags):"
        );
        for &((l, tx, ty), e) in pages {
            let _ = write!(
                human,
                "\n  {l}, {tx}, {ty}: {}, {}/{}, {:08x}, {}",
                e.offset,
                e.stored_len,
                e.raw_len,
                e.crc,
                match flag_names(e.flags).join("+") {
                    f if f.is_empty() => "none".to_string(),
                    f => f,
                }
            );
        }
    }

    let index_json: Option<Vec<_>> =
        index.map(|pages| pages.into_iter().map(|(p, e)| entry_json(p, e)).collect());
    ctx.report(
        human,
        json!({
            "path": args.tiles,
            "format_version": reader.version(),
            "file_bytes": reader.file_len(),
            "header": info,
            "pages": entries.len(),
            "compressed_pages": compressed,
            "pages_with_bricks": with_bricks,
            "stored_bytes": stored,
            "raw_bytes": raw,
            "verified_pages": verified,
            "index": index_json,
        }),
    );
    Ok(())
}
