//! The paged tile file format end to end: writer → file bytes → reader, and `dbms tiles`.

use dbms::crs::Crs;
use dbms::grid::Grid;
use dbms::tiles::{
    morton, Cell, Compression, IndexEntry, Page, TileReader, TileSetInfo, TileWriter, ENTRY_LEN,
    PAGE_ALIGN,
};
use proptest::prelude::*;
use std::path::{Path, PathBuf};

/// SplitMix64: deterministic pseudo-random values for test content.
fn mix(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// A tile set with known content: every cell of every level, row-major, and each page's bricks.
struct Fixture {
    info: TileSetInfo,
    cells: Vec<Vec<Cell>>,
    seed: u64,
}

impl Fixture {
    fn new(
        width: usize,
        height: usize,
        page: usize,
        factor: usize,
        compression: Compression,
        seed: u64,
    ) -> Fixture {
        let grid = Grid::north_up(500_000.0, 5_000_000.0, 0.5, width, height, Crs::epsg(32614));
        let mut info = TileSetInfo::new(grid, page, factor, None).unwrap();
        info.compression = compression;
        info.effects = serde_json::json!({"shadows": false, "note": "test"});
        Fixture::with_info(info, seed)
    }

    /// Random content for every cell of `info`'s levels.
    fn with_info(info: TileSetInfo, seed: u64) -> Fixture {
        let cells = info
            .levels
            .iter()
            .map(|l| {
                (0..l.width * l.height)
                    .map(|i| {
                        let r = mix(seed ^ mix(l.level as u64) ^ (i as u64) << 8);
                        if r.is_multiple_of(8) {
                            Cell {
                                max_z: f32::NAN,
                                colour: [0; 4],
                                state: 0,
                            }
                        } else {
                            // Any bit pattern: NaN payloads and infinities must survive too.
                            let max_z = if r % 8 == 1 {
                                f32::from_bits((r >> 32) as u32)
                            } else {
                                (r % 100_000) as f32 * 0.01
                            };
                            Cell {
                                max_z,
                                colour: [(r >> 8) as u8, (r >> 16) as u8, (r >> 24) as u8, 255],
                                state: 1 + (r % 2) as u8,
                            }
                        }
                    })
                    .collect()
            })
            .collect();
        Fixture { info, cells, seed }
    }

    fn page(&self, level: usize, tx: usize, ty: usize) -> Page {
        let p = self.info.page_size;
        let l = &self.info.levels[level];
        let mut page = Page::nodata(p);
        for row in 0..p.min(l.height - ty * p) {
            for col in 0..p.min(l.width - tx * p) {
                let c = self.cells[level][(ty * p + row) * l.width + tx * p + col];
                let i = row * p + col;
                (page.max_z[i], page.colour[i], page.state[i]) = (c.max_z, c.colour, c.state);
            }
        }
        let r = mix(self.seed ^ ((level * 1000 + ty * 31 + tx) as u64));
        if r.is_multiple_of(3) {
            page.bricks = Some(
                (0..(r % 50) as usize)
                    .map(|i| (r >> (i % 56)) as u8)
                    .collect(),
            );
        }
        page
    }

    /// Every page `(level, tx, ty)` in index order.
    fn pages(&self) -> Vec<(usize, usize, usize)> {
        self.info
            .levels
            .iter()
            .flat_map(|l| {
                (0..l.pages_y).flat_map(move |ty| (0..l.pages_x).map(move |tx| (l.level, tx, ty)))
            })
            .collect()
    }

    fn write(&self, path: &Path, order: &[(usize, usize, usize)]) {
        let w = TileWriter::create(path, self.info.clone()).unwrap();
        for &(level, tx, ty) in order {
            w.write_page(level, tx, ty, &self.page(level, tx, ty))
                .unwrap();
        }
        w.finish().unwrap();
    }
}

fn same_bits(a: f32, b: f32) -> bool {
    a.to_bits() == b.to_bits()
}

/// Check every cell of every level reads back bit for bit, across page edges, and that cells
/// beyond each level's edge are absent.
fn assert_reads_back(fx: &Fixture, reader: &TileReader) {
    assert_eq!(reader.info(), &fx.info);
    for l in &fx.info.levels {
        for row in 0..l.height {
            for col in 0..l.width {
                let want = fx.cells[l.level][row * l.width + col];
                let got = reader.cell(l.level, col, row).unwrap().unwrap();
                assert!(
                    same_bits(got.max_z, want.max_z)
                        && got.colour == want.colour
                        && got.state == want.state,
                    "level {} cell ({col}, {row}): {got:?} != {want:?}",
                    l.level
                );
            }
        }
        assert_eq!(reader.cell(l.level, l.width, 0).unwrap(), None);
        assert_eq!(reader.cell(l.level, 0, l.height).unwrap(), None);
    }
    for (level, tx, ty) in fx.pages() {
        assert_eq!(
            reader.page(level, tx, ty).unwrap().bricks,
            fx.page(level, tx, ty).bricks
        );
    }
}

fn shuffled(mut v: Vec<(usize, usize, usize)>, seed: u64) -> Vec<(usize, usize, usize)> {
    for i in (1..v.len()).rev() {
        v.swap(i, (mix(seed + i as u64) % (i as u64 + 1)) as usize);
    }
    v
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 40, ..ProptestConfig::default() })]

    /// Round trip is bit-exact, and the file bytes do not depend on the order pages came in.
    #[test]
    fn round_trip_is_bit_exact_and_order_free(
        width in 1usize..70, height in 1usize..70, page in 1usize..20,
        factor in prop::sample::select(vec![2usize, 4]), lz4 in any::<bool>(), seed in any::<u64>(),
    ) {
        let dir = tempfile::tempdir().unwrap();
        let compression = if lz4 { Compression::Lz4 } else { Compression::None };
        let fx = Fixture::new(width, height, page, factor, compression, seed);
        let (a, b) = (dir.path().join("a.dbt"), dir.path().join("b.dbt"));
        fx.write(&a, &fx.pages());
        fx.write(&b, &shuffled(fx.pages(), seed));
        prop_assert!(std::fs::read(&a).unwrap() == std::fs::read(&b).unwrap(), "page order changed the file");
        let reader = TileReader::open(&a, 3).unwrap();
        assert_reads_back(&fx, &reader);
    }
}

/// Byte ranges a reader checks: preamble, header, index and every page's stored bytes. What lies
/// outside them is zero padding.
fn covered(bytes: &[u8], reader: &TileReader) -> Vec<std::ops::Range<usize>> {
    let header_len = u64::from_le_bytes(bytes[24..32].try_into().unwrap()) as usize;
    let index_offset = reader.index_offset() as usize;
    let mut ranges = vec![
        0..64 + header_len,
        index_offset..index_offset + ENTRY_LEN * reader.entries().len(),
    ];
    ranges.extend(
        reader
            .entries()
            .iter()
            .map(|e| e.offset as usize..(e.offset + e.stored_len as u64) as usize),
    );
    ranges
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 300, ..ProptestConfig::default() })]

    /// Any flipped byte is caught at open or when its page is read, unless it is padding; no panic.
    #[test]
    fn any_flipped_byte_is_detected_or_harmless(at in 0.0f64..1.0, mask in 1u8..=255, lz4 in any::<bool>()) {
        let dir = tempfile::tempdir().unwrap();
        let fx = Fixture::new(30, 20, 8, 2, if lz4 { Compression::Lz4 } else { Compression::None }, 5);
        let path = dir.path().join("t.dbt");
        fx.write(&path, &fx.pages());
        let mut bytes = std::fs::read(&path).unwrap();
        let ranges = covered(&bytes, &TileReader::open(&path, 0).unwrap());
        let at = ((bytes.len() as f64 * at) as usize).min(bytes.len() - 1);
        bytes[at] ^= mask;
        std::fs::write(&path, &bytes).unwrap();
        let detected = match TileReader::open(&path, 0) {
            Err(_) => true,
            Ok(r) => fx.pages().iter().any(|&(l, x, y)| r.page(l, x, y).is_err()),
        };
        let is_padding = !ranges.iter().any(|r| r.contains(&at));
        prop_assert!(detected != is_padding, "byte {at} (padding: {is_padding}) detected: {detected}");
    }

    /// A file cut anywhere does not open.
    #[test]
    fn a_file_cut_anywhere_does_not_open(at in 0.0f64..1.0) {
        let dir = tempfile::tempdir().unwrap();
        let fx = Fixture::new(30, 20, 8, 4, Compression::Lz4, 9);
        let path = dir.path().join("t.dbt");
        fx.write(&path, &fx.pages());
        let bytes = std::fs::read(&path).unwrap();
        let len = (bytes.len() as f64 * at) as usize;
        std::fs::write(&path, &bytes[..len]).unwrap();
        let err = TileReader::open(&path, 0).err().expect("a cut file must not open").to_string();
        prop_assert!(err.contains("truncated"), "{len} bytes: {err}");
    }
}

fn tmp_file(dir: &tempfile::TempDir, name: &str) -> PathBuf {
    dir.path().join(name)
}

/// A multi-level fixture: 70×45 cells, pages of 8, factor 2 → levels of 9×6, 5×3, 3×2, 2×1, 1×1 pages.
fn standard(dir: &tempfile::TempDir, compression: Compression) -> (Fixture, PathBuf) {
    let fx = Fixture::new(70, 45, 8, 2, compression, 7);
    let path = tmp_file(dir, "tiles.dbt");
    fx.write(&path, &fx.pages());
    (fx, path)
}

#[test]
fn single_cell_grid_with_more_levels_than_needed() {
    let dir = tempfile::tempdir().unwrap();
    let grid = Grid::north_up(0.0, 1.0, 1.0, 1, 1, Crs::unknown());
    let info = TileSetInfo::new(grid, 1, 2, Some(4)).unwrap();
    assert_eq!(
        info.levels
            .iter()
            .map(|l| (l.width, l.pages()))
            .collect::<Vec<_>>(),
        vec![(1, 1); 4]
    );
    assert_eq!(info.levels[3].cell_x, 8.0);
    let fx = Fixture::with_info(info, 2);
    let path = tmp_file(&dir, "one.dbt");
    fx.write(&path, &fx.pages());
    assert_reads_back(&fx, &TileReader::open(&path, 1).unwrap());
}

#[test]
fn georeference_round_trips_exactly_at_utm_magnitudes() {
    let dir = tempfile::tempdir().unwrap();
    let mut grid = Grid::north_up(
        512_345.123_456_789,
        5_301_234.987_654_321,
        0.1,
        300,
        200,
        Crs::epsg(32632),
    );
    grid.transform.cell_y = -0.123_456_789_012_345;
    grid.crs.wkt = Some("PROJCRS[\"WGS 84 / UTM zone 32N\", \"quoted\" ünïcode]".into());
    let mut info = TileSetInfo::new(grid.clone(), 64, 4, None).unwrap();
    info.effects = serde_json::json!({"sun": {"azimuth_deg": 0.1 + 0.2, "elevation_deg": 1e-300}});
    let fx = Fixture::with_info(info.clone(), 4);
    let path = tmp_file(&dir, "geo.dbt");
    fx.write(&path, &fx.pages());
    let reader = TileReader::open(&path, 0).unwrap();
    assert_eq!(reader.info().grid, grid);
    assert_eq!(reader.info().effects, info.effects);
    let (x, y) = reader.info().level_grid(1).cell_centre(10, 20);
    assert_eq!(
        (x, y),
        (
            512_345.123_456_789 + 10.5 * 0.4,
            5_301_234.987_654_321 + 20.5 * (4.0 * -0.123_456_789_012_345)
        )
    );
}

#[test]
fn index_entry_is_found_by_arithmetic_in_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let (fx, path) = standard(&dir, Compression::Lz4);
    let bytes = std::fs::read(&path).unwrap();
    let index_offset = u64::from_le_bytes(bytes[32..40].try_into().unwrap()) as usize;
    let reader = TileReader::open(&path, 0).unwrap();
    assert_eq!(reader.index_offset() as usize, index_offset);
    let mut level_base = 0;
    for l in &fx.info.levels {
        for ty in 0..l.pages_y {
            for tx in 0..l.pages_x {
                let at = index_offset + ENTRY_LEN * (level_base + ty * l.pages_x + tx);
                let e = IndexEntry::decode(bytes[at..at + ENTRY_LEN].try_into().unwrap());
                assert_eq!(Some(e), reader.entry(l.level, tx, ty));
                let stored = &bytes[e.offset as usize..][..e.stored_len as usize];
                assert_eq!(crc32fast::hash(stored), e.crc);
            }
        }
        level_base += l.pages();
    }
    assert_eq!(level_base, reader.entries().len());
}

#[test]
fn coarse_levels_come_first_in_z_order_at_aligned_offsets() {
    let dir = tempfile::tempdir().unwrap();
    let (fx, path) = standard(&dir, Compression::None);
    assert_eq!(fx.info.levels.len(), 5);
    let reader = TileReader::open(&path, 0).unwrap();
    let file_len = std::fs::metadata(&path).unwrap().len();
    assert_eq!(reader.file_len(), file_len);
    let mut previous_level_end = 0;
    for l in fx.info.levels.iter().rev() {
        let mut pages: Vec<(u64, IndexEntry)> = (0..l.pages_y)
            .flat_map(|ty| (0..l.pages_x).map(move |tx| (tx, ty)))
            .map(|(tx, ty)| {
                (
                    morton(tx as u32, ty as u32),
                    reader.entry(l.level, tx, ty).unwrap(),
                )
            })
            .collect();
        pages.sort_by_key(|p| p.0);
        for (_, e) in &pages {
            assert_eq!(
                e.offset % PAGE_ALIGN,
                0,
                "unaligned page offset {}",
                e.offset
            );
            assert!(
                e.offset > previous_level_end,
                "level {} is not after the coarser levels / out of Z-order",
                l.level
            );
            previous_level_end = e.offset;
        }
    }
    // The whole coarse part (levels ≥ 1) sits before any level-0 page.
    let first_level0 = (0..fx.info.levels[0].pages())
        .map(|p| reader.entries()[p].offset)
        .min()
        .unwrap();
    let last_coarse = reader.entries()[fx.info.levels[0].pages()..]
        .iter()
        .map(|e| e.offset)
        .max()
        .unwrap();
    assert!(last_coarse < first_level0);
}

#[test]
fn flipped_byte_in_a_page_is_a_checksum_error_naming_the_page() {
    let dir = tempfile::tempdir().unwrap();
    let (fx, path) = standard(&dir, Compression::None);
    let e = TileReader::open(&path, 0).unwrap().entry(1, 2, 1).unwrap();
    let mut bytes = std::fs::read(&path).unwrap();
    bytes[e.offset as usize + 77] ^= 0x10;
    std::fs::write(&path, &bytes).unwrap();
    let reader = TileReader::open(&path, 4).unwrap(); // the index is intact: open succeeds
    let err = reader.page(1, 2, 1).unwrap_err().to_string();
    assert_eq!(
        err,
        format!(
            "{}: page (level 1, 2, 1) checksum mismatch; the file is corrupt, rebuild it with dbms pyramid",
            path.display()
        )
    );
    // The cell lookup reports it too; other pages are unaffected.
    assert!(reader
        .cell(1, 2 * 8 + 3, 8)
        .unwrap_err()
        .to_string()
        .contains("page (level 1, 2, 1)"));
    assert_eq!(reader.page(1, 1, 1).unwrap().max_z.len(), 64);
    assert!(reader
        .verify(&dbms::progress::Progress::hidden())
        .unwrap_err()
        .to_string()
        .contains("page (level 1, 2, 1)"));
    drop(fx);
}

#[test]
fn flipped_byte_in_an_lz4_page_is_a_checksum_error_too() {
    let dir = tempfile::tempdir().unwrap();
    let (_, path) = standard(&dir, Compression::Lz4);
    let e = TileReader::open(&path, 0).unwrap().entry(0, 8, 5).unwrap();
    let mut bytes = std::fs::read(&path).unwrap();
    bytes[e.offset as usize + e.stored_len as usize - 1] ^= 1;
    std::fs::write(&path, &bytes).unwrap();
    let err = TileReader::open(&path, 0)
        .unwrap()
        .page(0, 8, 5)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("page (level 0, 8, 5) checksum mismatch"),
        "{err}"
    );
}

#[test]
fn truncated_file_is_a_clear_error_at_open_for_every_length() {
    let dir = tempfile::tempdir().unwrap();
    let (_, path) = standard(&dir, Compression::Lz4);
    let bytes = std::fs::read(&path).unwrap();
    let cut = tmp_file(&dir, "cut.dbt");
    for len in [
        0,
        4,
        8,
        12,
        40,
        63,
        64,
        100,
        4096,
        bytes.len() / 2,
        bytes.len() - 1,
    ] {
        std::fs::write(&cut, &bytes[..len]).unwrap();
        let err = TileReader::open(&cut, 0)
            .err()
            .unwrap_or_else(|| panic!("{len} bytes opened"))
            .to_string();
        assert!(err.starts_with(&format!("{}: ", cut.display())), "{err}");
        assert!(
            err.contains("truncated") || err.contains("bad magic"),
            "{len} bytes: {err}"
        );
        assert!(!err.contains('\n'));
    }
    std::fs::write(&cut, &bytes[..bytes.len() - 1]).unwrap();
    let err = TileReader::open(&cut, 0).err().unwrap().to_string();
    assert!(
        err.contains(&format!(
            "file is truncated ({} of {} bytes)",
            bytes.len() - 1,
            bytes.len()
        )),
        "{err}"
    );
}

#[test]
fn file_truncated_after_open_names_the_page() {
    let dir = tempfile::tempdir().unwrap();
    let (_, path) = standard(&dir, Compression::None);
    let reader = TileReader::open(&path, 0).unwrap();
    let last = *reader.entries().iter().max_by_key(|e| e.offset).unwrap();
    let pos = reader.entries().iter().position(|e| *e == last).unwrap();
    std::fs::OpenOptions::new()
        .write(true)
        .open(&path)
        .unwrap()
        .set_len(last.offset + 10)
        .unwrap();
    let (level, tx, ty) = reader.info().page_at(pos).unwrap();
    let err = reader.page(level, tx, ty).unwrap_err().to_string();
    assert!(
        err.contains(&format!("page (level {level}, {tx}, {ty})")) && err.contains("truncated"),
        "{err}"
    );
}

#[test]
fn bad_magic_future_version_and_corrupt_header_are_clear_errors() {
    let dir = tempfile::tempdir().unwrap();
    let (_, path) = standard(&dir, Compression::None);
    let bytes = std::fs::read(&path).unwrap();
    let bad = tmp_file(&dir, "bad.dbt");
    let open_err = |b: &[u8]| {
        std::fs::write(&bad, b).unwrap();
        TileReader::open(&bad, 0)
            .err()
            .expect("must not open")
            .to_string()
    };

    let mut b = bytes.clone();
    b[..8].copy_from_slice(b"GIF89a\0\0");
    assert_eq!(
        open_err(&b),
        format!(
            "{}: not a dbms tile file (bad magic bytes); give a file written by dbms pyramid",
            bad.display()
        )
    );
    let mut b = bytes.clone();
    b[8..12].copy_from_slice(&2u32.to_le_bytes());
    assert!(open_err(&b)
        .contains("tile format version 2 is newer than this dbms reads (version 1); upgrade dbms"));
    let mut b = bytes.clone();
    b[70] ^= 1; // inside the JSON header
    assert!(open_err(&b).contains("header checksum mismatch"));
    let index_offset = u64::from_le_bytes(bytes[32..40].try_into().unwrap()) as usize;
    let mut b = bytes.clone();
    b[index_offset + 3] ^= 1;
    assert!(open_err(&b).contains("index checksum mismatch"));
    let mut b = bytes.clone();
    b.extend_from_slice(b"junk");
    assert!(open_err(&b).contains("4 bytes after its end"));
}

#[test]
fn partial_edge_pages_are_padded_with_nodata() {
    let dir = tempfile::tempdir().unwrap();
    // 10×7 cells, pages of 4: level 0 has 3×2 pages, the right ones 2 columns wide, the bottom 3 rows.
    let fx = Fixture::new(10, 7, 4, 4, Compression::None, 3);
    let path = tmp_file(&dir, "edge.dbt");
    fx.write(&path, &fx.pages());
    let reader = TileReader::open(&path, 0).unwrap();
    let page = reader.page(0, 2, 1).unwrap();
    assert_eq!(page.max_z.len(), 16);
    for row in 0..4 {
        for col in 0..4 {
            let c = page.cell(4, col, row);
            if col < 2 && row < 3 {
                let want = fx.cells[0][(4 + row) * 10 + 8 + col];
                assert!(same_bits(c.max_z, want.max_z) && c.colour == want.colour);
            } else {
                assert!(
                    c.max_z.is_nan() && c.colour[3] == 0 && c.state == 0,
                    "padding ({col}, {row}) is {c:?}"
                );
            }
        }
    }
    assert_eq!(reader.cell(0, 10, 6).unwrap(), None);
    assert!(reader.cell(0, 9, 6).unwrap().is_some());
    assert!(reader.cell(2, 0, 0).is_err(), "level 2 does not exist");

    // The writer refuses data in the padding instead of storing it silently.
    let w = TileWriter::create(&tmp_file(&dir, "x.dbt"), fx.info.clone()).unwrap();
    let mut page = fx.page(0, 2, 1);
    page.max_z[3] = 5.0; // (3, 0): beyond the 2 valid columns
    let err = w.write_page(0, 2, 1, &page).unwrap_err().to_string();
    assert!(
        err.contains("page (level 0, 2, 1): padding cell (3, 0)"),
        "{err}"
    );
}

#[test]
fn missing_or_duplicate_pages_are_errors_and_leave_no_file() {
    let dir = tempfile::tempdir().unwrap();
    let fx = Fixture::new(20, 20, 8, 4, Compression::None, 1);
    let path = tmp_file(&dir, "t.dbt");
    let w = TileWriter::create(&path, fx.info.clone()).unwrap();
    let pages = fx.pages();
    for &(l, x, y) in &pages[..4] {
        w.write_page(l, x, y, &fx.page(l, x, y)).unwrap();
    }
    let err = w
        .write_page(0, 0, 0, &fx.page(0, 0, 0))
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("page (level 0, 0, 0) was written twice"),
        "{err}"
    );
    assert!(w
        .write_page(0, 3, 0, &Page::nodata(8))
        .unwrap_err()
        .to_string()
        .contains("outside the tile set"));
    let err = w.finish().unwrap_err().to_string();
    // 20×20 / 8 → 3×3 pages at level 0 (positions 0..9), then level 1 (5×5 cells, 1 page).
    assert!(
        err.contains("6 page(s) were never written, the first is (level 0, 1, 1)"),
        "{err}"
    );
    let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
    assert!(left.is_empty(), "spool or output left behind: {left:?}");
}

#[test]
fn pages_written_from_many_threads_give_the_same_file() {
    use rayon::prelude::*;
    let dir = tempfile::tempdir().unwrap();
    let fx = Fixture::new(130, 70, 16, 2, Compression::Lz4, 11);
    let (a, b) = (tmp_file(&dir, "a.dbt"), tmp_file(&dir, "b.dbt"));
    fx.write(&a, &fx.pages());
    let w = TileWriter::create(&b, fx.info.clone()).unwrap();
    fx.pages()
        .par_iter()
        .for_each(|&(l, x, y)| w.write_page(l, x, y, &fx.page(l, x, y)).unwrap());
    w.finish().unwrap();
    assert!(std::fs::read(&a).unwrap() == std::fs::read(&b).unwrap());
}

#[test]
fn one_reader_serves_many_threads_and_counts_its_reads() {
    fn shareable<T: Send + Sync>() {}
    shareable::<TileReader>();
    let dir = tempfile::tempdir().unwrap();
    let (fx, path) = standard(&dir, Compression::Lz4);
    let reader = TileReader::open(&path, 2).unwrap();
    std::thread::scope(|s| {
        for t in 0..4 {
            let (reader, fx) = (&reader, &fx);
            s.spawn(move || {
                let l = &fx.info.levels[t % 2];
                for row in (t..l.height).step_by(3) {
                    for col in 0..l.width {
                        let want = fx.cells[l.level][row * l.width + col];
                        let got = reader.cell(l.level, col, row).unwrap().unwrap();
                        assert!(same_bits(got.max_z, want.max_z) && got.colour == want.colour);
                    }
                }
            });
        }
    });
    let before = reader.stats();
    assert!(before.pages_read > 0 && before.bytes_read > 0 && before.cache_hits > 0);
    reader.page(4, 0, 0).unwrap();
    reader.page(4, 0, 0).unwrap();
    let after = reader.stats();
    let e = reader.entry(4, 0, 0).unwrap();
    assert_eq!(after.pages_read, before.pages_read + 1);
    assert_eq!(after.bytes_read, before.bytes_read + e.stored_len as u64);
    assert_eq!(after.cache_hits, before.cache_hits + 1);
}

#[test]
fn header_has_the_schema_s_fields() {
    let dir = tempfile::tempdir().unwrap();
    let (_, path) = standard(&dir, Compression::None);
    let bytes = std::fs::read(&path).unwrap();
    let len = u64::from_le_bytes(bytes[24..32].try_into().unwrap()) as usize;
    let header: serde_json::Value = serde_json::from_slice(&bytes[64..64 + len]).unwrap();
    let schema_path =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("schemas/tiles-header.schema.json");
    let schema: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(schema_path).unwrap()).unwrap();
    let props = schema["properties"].as_object().unwrap();
    let header = header.as_object().unwrap();
    for key in header.keys() {
        assert!(
            props.contains_key(key),
            "header field {key} is not in the schema"
        );
    }
    for key in schema["required"].as_array().unwrap() {
        assert!(
            header.contains_key(key.as_str().unwrap()),
            "schema requires {key}, header lacks it"
        );
    }
    let level_props = schema["$defs"]["level"]["properties"].as_object().unwrap();
    for key in header["levels"][0].as_object().unwrap().keys() {
        assert!(
            level_props.contains_key(key),
            "level field {key} is not in the schema"
        );
    }
}

#[path = "support/cli.rs"]
mod cli;
use cli::dbms;

#[test]
fn cli_prints_the_summary_and_verifies() {
    let dir = tempfile::tempdir().unwrap();
    let (_, path) = standard(&dir, Compression::Lz4);
    let p = path.to_str().unwrap();
    let out = dbms(&["tiles", p]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = String::from_utf8(out.stdout).unwrap();
    assert!(
        text.contains("pages of 8×8 cells, factor 2, 5 levels"),
        "{text}"
    );
    assert!(
        text.contains("level 0: 70×45 cells of 0.5×0.5, 9×6 pages"),
        "{text}"
    );
    assert!(
        text.contains("layers: max_z (f32), colour (rgba8), state (u8)"),
        "{text}"
    );
    assert!(!text.contains("verified"));

    let out = dbms(&["tiles", p, "--verify", "--json"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(j["pages"], 54 + 15 + 6 + 2 + 1);
    assert_eq!(j["verified_pages"], 78);
    assert_eq!(j["header"]["factor"], 2);
    assert_eq!(j["header"]["compression"], "lz4");
    assert_eq!(j["header"]["effects"]["note"], "test");
}

#[test]
fn cli_lists_the_page_index_as_its_schema_says() {
    let dir = tempfile::tempdir().unwrap();
    let (_, path) = standard(&dir, Compression::Lz4);
    let p = path.to_str().unwrap();
    let out = dbms(&["tiles", p, "--index", "--json"]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    let schema = |name: &str| {
        let path = Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("schemas")
            .join(name);
        let v: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
        jsonschema::validator_for(&v).unwrap()
    };
    for (doc, name) in [
        (&j, "tiles-index.schema.json"),
        (&j["header"], "tiles-header.schema.json"),
    ] {
        let errors: Vec<String> = schema(name)
            .iter_errors(doc)
            .map(|e| e.to_string())
            .collect();
        assert!(errors.is_empty(), "{name}: {errors:?}");
    }
    // Entry by entry what the reader holds, at the page the index position stands for.
    let reader = TileReader::open(&path, 0).unwrap();
    let index = j["index"].as_array().unwrap();
    assert_eq!(index.len(), reader.entries().len());
    for (pos, (listed, e)) in index.iter().zip(reader.entries()).enumerate() {
        let (l, tx, ty) = reader.info().page_at(pos).unwrap();
        assert_eq!(
            (
                listed["level"].as_u64(),
                listed["tx"].as_u64(),
                listed["ty"].as_u64()
            ),
            (Some(l as u64), Some(tx as u64), Some(ty as u64))
        );
        assert_eq!(listed["offset"], e.offset);
        assert_eq!(listed["stored_len"], e.stored_len);
        assert_eq!(listed["raw_len"], e.raw_len);
        assert_eq!(listed["crc32"], e.crc);
        assert_eq!(
            listed["offset"].as_u64().unwrap() % reader.info().alignment,
            0
        );
        let lz4 = listed["flags"].as_array().unwrap().contains(&"lz4".into());
        assert_eq!(lz4, e.stored_len < e.raw_len, "page {pos}");
    }
    // Without --index there is no index; the human listing has one line a page.
    let out = dbms(&["tiles", p, "--json"]);
    let j: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(j["index"].is_null());
    let text = String::from_utf8(dbms(&["tiles", p, "--index"]).stdout).unwrap();
    assert_eq!(
        text.lines().filter(|l| l.starts_with("  0, ")).count(),
        9 * 6
    );
}

#[test]
fn cli_verify_fails_naming_the_first_bad_page() {
    let dir = tempfile::tempdir().unwrap();
    let (_, path) = standard(&dir, Compression::None);
    let reader = TileReader::open(&path, 0).unwrap();
    let mut bytes = std::fs::read(&path).unwrap();
    // Corrupt two level-0 pages; the first in file order is reported.
    let (a, b) = (
        reader.entry(0, 1, 1).unwrap(),
        reader.entry(0, 8, 5).unwrap(),
    );
    assert!(a.offset < b.offset);
    bytes[a.offset as usize] ^= 0xff;
    bytes[b.offset as usize] ^= 0xff;
    std::fs::write(&path, &bytes).unwrap();
    let p = path.to_str().unwrap();
    let out = dbms(&["tiles", p]);
    assert!(
        out.status.success(),
        "without --verify only the header is read"
    );
    let out = dbms(&["tiles", p, "--verify"]);
    assert!(!out.status.success());
    let err = String::from_utf8(out.stderr).unwrap();
    assert_eq!(
        err.trim_end(),
        format!("dbms: error: {p}: page (level 0, 1, 1) checksum mismatch; the file is corrupt, rebuild it with dbms pyramid")
    );
}

#[test]
fn cli_rejects_a_file_that_is_not_a_tile_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = tmp_file(&dir, "dem.tif");
    std::fs::write(
        &path,
        b"II*\0 not tiles at all, but long enough to hold a preamble of sixty-four bytes",
    )
    .unwrap();
    let out = dbms(&["tiles", path.to_str().unwrap()]);
    assert!(!out.status.success());
    assert!(String::from_utf8(out.stderr)
        .unwrap()
        .contains("not a dbms tile file (bad magic bytes)"));
}

#[test]
fn unwritable_output_and_missing_input_are_one_line_errors() {
    let dir = tempfile::tempdir().unwrap();
    let fx = Fixture::new(5, 5, 4, 4, Compression::None, 1);
    let err = TileWriter::create(&dir.path().join("no/such/dir/t.dbt"), fx.info.clone())
        .err()
        .expect("no directory to spool in")
        .to_string();
    assert!(
        err.contains("no/such/dir") && err.contains("check that the output directory exists"),
        "{err}"
    );
    let missing = tmp_file(&dir, "missing.dbt");
    let out = dbms(&["tiles", missing.to_str().unwrap()]);
    assert!(!out.status.success());
    assert_eq!(
        String::from_utf8(out.stderr).unwrap().trim_end(),
        format!(
            "dbms: error: {}: no such file or directory; check the path",
            missing.display()
        )
    );
}

#[test]
fn uncompressed_pages_without_bricks_go_straight_to_their_place_in_any_order() {
    // Pages of 16 cells (576 bytes: written through the page cache) and of 256 (144 × 4096
    // bytes: written with O_DIRECT where the file system allows it).
    straight_to_place(70, 45, 16);
    straight_to_place(700, 300, 256);
}

fn straight_to_place(width: usize, height: usize, p: usize) {
    use rayon::prelude::*;
    let dir = tempfile::tempdir().unwrap();
    let fx = Fixture::new(width, height, p, 2, Compression::None, 5);
    let plain = |l, x, y| Page {
        bricks: None,
        ..fx.page(l, x, y)
    };
    let (a, b) = (tmp_file(&dir, "a.dbt"), tmp_file(&dir, "b.dbt"));
    let w = TileWriter::create(&a, fx.info.clone()).unwrap();
    for &(l, x, y) in &fx.pages() {
        w.write_page(l, x, y, &plain(l, x, y)).unwrap();
    }
    w.finish().unwrap();
    let w = TileWriter::create(&b, fx.info.clone()).unwrap();
    let mut order = fx.pages();
    order.reverse();
    order
        .par_iter()
        .for_each(|&(l, x, y)| w.write_page(l, x, y, &plain(l, x, y)).unwrap());
    w.finish().unwrap();
    let bytes = std::fs::read(&a).unwrap();
    assert_eq!(
        bytes,
        std::fs::read(&b).unwrap(),
        "order or threads changed the bytes"
    );
    let r = TileReader::open(&a, 4).unwrap();
    for &(l, x, y) in &fx.pages() {
        let (got, want) = (r.page(l, x, y).unwrap(), plain(l, x, y));
        let bits = |p: &Page| p.max_z.iter().map(|z| z.to_bits()).collect::<Vec<_>>();
        assert_eq!(bits(&got), bits(&want), "max_z of page ({l}, {x}, {y})");
        assert_eq!(
            (&got.colour, &got.state, &got.bricks),
            (&want.colour, &want.state, &None)
        );
    }
    // Pages are consecutive in storage order, each at the next aligned offset, and the file
    // ends where the last one does: nothing of the writer's scratch is left in the file.
    let raw = 9 * (p * p) as u64;
    let mut entries: Vec<IndexEntry> = r.entries().to_vec();
    entries.sort_by_key(|e| e.offset);
    for pair in entries.windows(2) {
        assert_eq!(
            pair[1].offset,
            (pair[0].offset + raw).next_multiple_of(PAGE_ALIGN)
        );
    }
    assert_eq!(entries.last().unwrap().offset + raw, bytes.len() as u64);
    let names: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names.len(), 2, "temporary files left behind: {names:?}");
}

#[test]
fn an_unfinished_writer_leaves_nothing_behind() {
    let dir = tempfile::tempdir().unwrap();
    for compression in [Compression::None, Compression::Lz4] {
        let fx = Fixture::new(20, 20, 8, 4, compression, 3);
        let path = tmp_file(&dir, "t.dbt");
        let w = TileWriter::create(&path, fx.info.clone()).unwrap();
        for &(l, x, y) in &fx.pages()[..3] {
            w.write_page(l, x, y, &fx.page(l, x, y)).unwrap();
        }
        drop(w);
        let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
        assert!(left.is_empty(), "{compression:?}: left behind: {left:?}");
    }
}
