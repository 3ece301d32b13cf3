//! Byte layout of a tile file: the fixed preamble, index entries, and where pages go.
//!
//! Invariant: all integers are little-endian; the preamble is [`PREAMBLE_LEN`] bytes at offset
//! 0; the index holds one [`ENTRY_LEN`]-byte entry per page at `index_offset + 24 · position`;
//! page data follows in [`storage_order`], every page at a multiple of the header's alignment.
//! `docs/tile-format.md` is the normative description.

use super::info::TileSetInfo;

/// The file's first 8 bytes.
pub const MAGIC: [u8; 8] = *b"DBMSTILE";
/// The format version this code writes and the newest it reads.
pub const VERSION: u32 = 1;
/// Bytes of the fixed preamble.
pub const PREAMBLE_LEN: usize = 64;
/// Bytes of one index entry.
pub const ENTRY_LEN: usize = 24;

/// The fixed preamble at offset 0.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Preamble {
    /// Format version ([`VERSION`]).
    pub version: u32,
    /// Offset of the JSON header, bytes (64 in version 1).
    pub header_offset: u64,
    /// Length of the JSON header, bytes.
    pub header_len: u64,
    /// Offset of the index, bytes (8-aligned, after the header).
    pub index_offset: u64,
    /// Number of index entries (pages).
    pub page_count: u64,
    /// Length of the whole file, bytes: a shorter file is truncated.
    pub file_len: u64,
    /// CRC-32 (IEEE) of the header bytes.
    pub header_crc: u32,
    /// CRC-32 (IEEE) of the index bytes.
    pub index_crc: u32,
}

impl Preamble {
    /// The 64 bytes on disk.
    pub fn encode(&self) -> [u8; PREAMBLE_LEN] {
        let mut b = [0u8; PREAMBLE_LEN];
        b[0..8].copy_from_slice(&MAGIC);
        b[8..12].copy_from_slice(&self.version.to_le_bytes());
        b[12..16].copy_from_slice(&(PREAMBLE_LEN as u32).to_le_bytes());
        b[16..24].copy_from_slice(&self.header_offset.to_le_bytes());
        b[24..32].copy_from_slice(&self.header_len.to_le_bytes());
        b[32..40].copy_from_slice(&self.index_offset.to_le_bytes());
        b[40..48].copy_from_slice(&self.page_count.to_le_bytes());
        b[48..56].copy_from_slice(&self.file_len.to_le_bytes());
        b[56..60].copy_from_slice(&self.header_crc.to_le_bytes());
        b[60..64].copy_from_slice(&self.index_crc.to_le_bytes());
        b
    }

    /// Parse the preamble; `Err` is the problem with its fix, for the caller to put a path on.
    pub fn decode(b: &[u8]) -> Result<Preamble, (String, &'static str)> {
        const REBUILD: &str = "rebuild it with dbms pyramid";
        let n = b.len().min(MAGIC.len());
        if b[..n] != MAGIC[..n] {
            return Err((
                "not a dbms tile file (bad magic bytes)".into(),
                "give a file written by dbms pyramid",
            ));
        }
        if b.len() < 12 {
            return Err(("file ends inside its preamble (truncated?)".into(), REBUILD));
        }
        let u32_at = |at: usize| u32::from_le_bytes(b[at..at + 4].try_into().expect("4 bytes"));
        let u64_at = |at: usize| u64::from_le_bytes(b[at..at + 8].try_into().expect("8 bytes"));
        let version = u32_at(8);
        if version > VERSION {
            return Err((
                format!("tile format version {version} is newer than this dbms reads (version {VERSION})"),
                "upgrade dbms, or rebuild the file with this dbms pyramid",
            ));
        }
        if version == 0 {
            return Err(("tile format version 0 does not exist".into(), REBUILD));
        }
        if b.len() < PREAMBLE_LEN || u32_at(12) as usize != PREAMBLE_LEN {
            return Err(("file ends inside its preamble (truncated?)".into(), REBUILD));
        }
        Ok(Preamble {
            version,
            header_offset: u64_at(16),
            header_len: u64_at(24),
            index_offset: u64_at(32),
            page_count: u64_at(40),
            file_len: u64_at(48),
            header_crc: u32_at(56),
            index_crc: u32_at(60),
        })
    }
}

/// One page's index entry.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct IndexEntry {
    /// Offset of the stored bytes in the file (a multiple of the alignment).
    pub offset: u64,
    /// Stored (possibly compressed) length, bytes.
    pub stored_len: u32,
    /// Raw (decompressed) length, bytes: the layers, plus the bricks blob if flagged.
    pub raw_len: u32,
    /// CRC-32 (IEEE) of the stored bytes.
    pub crc: u32,
    /// [`FLAG_LZ4`](super::FLAG_LZ4) | [`FLAG_BRICKS`](super::FLAG_BRICKS).
    pub flags: u32,
}

impl IndexEntry {
    /// The 24 bytes on disk.
    pub fn encode(&self) -> [u8; ENTRY_LEN] {
        let mut b = [0u8; ENTRY_LEN];
        b[0..8].copy_from_slice(&self.offset.to_le_bytes());
        b[8..12].copy_from_slice(&self.stored_len.to_le_bytes());
        b[12..16].copy_from_slice(&self.raw_len.to_le_bytes());
        b[16..20].copy_from_slice(&self.crc.to_le_bytes());
        b[20..24].copy_from_slice(&self.flags.to_le_bytes());
        b
    }

    /// Parse 24 bytes.
    pub fn decode(b: &[u8; ENTRY_LEN]) -> IndexEntry {
        let u32_at = |at: usize| u32::from_le_bytes(b[at..at + 4].try_into().expect("4 bytes"));
        IndexEntry {
            offset: u64::from_le_bytes(b[0..8].try_into().expect("8 bytes")),
            stored_len: u32_at(8),
            raw_len: u32_at(12),
            crc: u32_at(16),
            flags: u32_at(20),
        }
    }
}

/// Z-order (Morton) code of `(x, y)`: x's bits at even positions, y's at odd ones.
pub fn morton(x: u32, y: u32) -> u64 {
    fn spread(v: u32) -> u64 {
        let mut v = v as u64;
        v = (v | (v << 16)) & 0x0000_ffff_0000_ffff;
        v = (v | (v << 8)) & 0x00ff_00ff_00ff_00ff;
        v = (v | (v << 4)) & 0x0f0f_0f0f_0f0f_0f0f;
        v = (v | (v << 2)) & 0x3333_3333_3333_3333;
        v = (v | (v << 1)) & 0x5555_5555_5555_5555;
        v
    }
    spread(x) | (spread(y) << 1)
}

/// Index positions in the order their data is stored: coarsest level first, down to level 0;
/// within a level ascending Morton code of `(tx, ty)`.
pub fn storage_order(info: &TileSetInfo) -> Vec<usize> {
    let mut order = Vec::with_capacity(info.page_count());
    for l in info.levels.iter().rev() {
        let base = info.level_base(l.level);
        let mut level: Vec<(u64, usize)> = (0..l.pages_y)
            .flat_map(|ty| {
                (0..l.pages_x)
                    .map(move |tx| (morton(tx as u32, ty as u32), base + ty * l.pages_x + tx))
            })
            .collect();
        level.sort_unstable();
        order.extend(level.into_iter().map(|(_, pos)| pos));
    }
    order
}

/// `x` rounded up to a multiple of `align` (a power of two).
pub fn align_up(x: u64, align: u64) -> u64 {
    (x + align - 1) & !(align - 1)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::crs::Crs;
    use crate::grid::Grid;

    #[test]
    fn morton_interleaves_bits() {
        assert_eq!(morton(0, 0), 0);
        assert_eq!(morton(1, 0), 1);
        assert_eq!(morton(0, 1), 2);
        assert_eq!(morton(1, 1), 3);
        assert_eq!(morton(2, 0), 4);
        assert_eq!(morton(3, 5), 0b100111);
        assert_eq!(morton(u32::MAX, 0), 0x5555_5555_5555_5555);
    }

    #[test]
    fn storage_order_is_coarse_first_then_z_order() {
        let info = TileSetInfo::new(
            Grid::north_up(0.0, 0.0, 1.0, 40, 24, Crs::unknown()),
            8,
            2,
            None,
        )
        .unwrap();
        // levels: 40×24 (5×3 pages), 20×12 (3×2), 10×6 (2×1), 5×3 (1×1)
        let order = storage_order(&info);
        let pages: Vec<_> = order.iter().map(|&p| info.page_at(p).unwrap()).collect();
        assert_eq!(&pages[..4], &[(3, 0, 0), (2, 0, 0), (2, 1, 0), (1, 0, 0)]);
        assert_eq!(
            &pages[4..9],
            &[(1, 1, 0), (1, 0, 1), (1, 1, 1), (1, 2, 0), (1, 2, 1)]
        );
        assert_eq!(pages[9], (0, 0, 0));
        let mut sorted = order.clone();
        sorted.sort_unstable();
        assert_eq!(sorted, (0..info.page_count()).collect::<Vec<_>>());
    }

    #[test]
    fn preamble_round_trips_and_rejects_bad_magic_and_versions() {
        let p = Preamble {
            version: VERSION,
            header_offset: 64,
            header_len: 1234,
            index_offset: 1304,
            page_count: 7,
            file_len: 99_999,
            header_crc: 0xdead_beef,
            index_crc: 42,
        };
        assert_eq!(Preamble::decode(&p.encode()).unwrap(), p);
        let mut b = p.encode();
        b[0] = b'X';
        assert!(Preamble::decode(&b).unwrap_err().0.contains("bad magic"));
        let mut b = p.encode();
        b[8..12].copy_from_slice(&9u32.to_le_bytes());
        assert!(Preamble::decode(&b)
            .unwrap_err()
            .0
            .contains("version 9 is newer"));
        assert!(Preamble::decode(&p.encode()[..40])
            .unwrap_err()
            .0
            .contains("truncated"));
        assert!(Preamble::decode(b"DBMS")
            .unwrap_err()
            .0
            .contains("truncated"));
        assert!(Preamble::decode(b"").unwrap_err().0.contains("truncated"));
        assert!(Preamble::decode(b"II*")
            .unwrap_err()
            .0
            .contains("bad magic"));
    }

    #[test]
    fn entry_round_trips_and_align_up() {
        let e = IndexEntry {
            offset: 1 << 40,
            stored_len: 3,
            raw_len: 4,
            crc: 5,
            flags: 2,
        };
        assert_eq!(IndexEntry::decode(&e.encode()), e);
        assert_eq!(align_up(0, 4096), 0);
        assert_eq!(align_up(1, 4096), 4096);
        assert_eq!(align_up(4096, 4096), 4096);
        assert_eq!(align_up(13, 8), 16);
    }
}
