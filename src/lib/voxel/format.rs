//! The `.dvox` sparse voxel object file (spec: `docs/voxel-object.md`, header schema:
//! `schemas/voxel-object.schema.json`).
//!
//! Layout: 8 magic bytes `DBMSVOX1`; a little-endian `u32` header length; the UTF-8 JSON header;
//! the body, LZ4 block-compressed with its uncompressed size prepended. The uncompressed body is
//! the run table — one 8-byte record `(x, y, z0, len)` of little-endian `u16`s per vertical run
//! of solid voxels, sorted by `(y, x, z0)` — followed by 3 bytes of RGB per solid voxel in run
//! order (the object's storage order). Same object → same bytes.

use super::grid::{try_reserve, VoxelGrid};
use super::object::VoxelObject;
use super::occupancy::Occupancy;
use crate::error::{Error, Result};
use crate::io::atomic::write_bytes_atomic;
use serde::{Deserialize, Serialize};
use std::path::Path;

const MAGIC: &[u8; 8] = b"DBMSVOX1";
/// The `format` string of the header.
pub const FORMAT_NAME: &str = "dbms-voxel-object";
/// The version this build writes and reads.
pub const VERSION: u32 = 1;

/// The JSON header of a `.dvox` file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Header {
    /// Always [`FORMAT_NAME`].
    pub format: String,
    /// Format version, [`VERSION`].
    pub version: u32,
    /// World position (metres) of the minimum corner of voxel (0, 0, 0).
    pub origin: [f64; 3],
    /// Voxel edge, metres.
    pub voxel_size: f64,
    /// Voxels along x, y, z.
    pub dims: [u32; 3],
    /// Number of solid voxels.
    pub voxels: u64,
    /// Number of runs in the run table.
    pub runs: u64,
    /// Size of the compressed body, bytes.
    pub body_bytes: u64,
    /// CRC-32 (IEEE) of the compressed body.
    pub body_crc32: u32,
    /// Free text: what made the object (command and parameters), never a timestamp.
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub source: String,
}

/// Encode `obj` as `.dvox` bytes, with `source` in the header; the body's buffers are
/// allocated fallibly (a memory limit is [`super::grid::out_of_memory`], not an abort).
pub fn encode(obj: &VoxelObject, source: &str) -> Result<Vec<u8>> {
    let g = &obj.grid;
    let nz = g.dims[2] as usize;
    let mut runs: Vec<u8> = Vec::new();
    let mut nruns = 0u64;
    let mut run: Option<(usize, usize)> = None; // (start index, length)
    let mut flush = |run: (usize, usize), runs: &mut Vec<u8>| {
        let [x, y, z] = g.coords(run.0);
        for v in [x as u16, y as u16, z as u16, run.1 as u16] {
            runs.extend_from_slice(&v.to_le_bytes());
        }
        nruns += 1;
    };
    for i in obj.occupancy.occupied() {
        run = match run {
            // Extend while contiguous and in the same column.
            Some((s, n)) if s + n == i && i % nz != 0 => Some((s, n + 1)),
            Some(r) => {
                flush(r, &mut runs);
                Some((i, 1))
            }
            None => Some((i, 1)),
        };
    }
    if let Some(r) = run {
        flush(r, &mut runs);
    }
    // One exact allocation and one copy: a city's colours are gigabytes, and growing the body
    // byte by byte took most of `object extrude`'s time.
    let mut body = runs;
    try_reserve(&mut body, 3 * obj.colours.len(), "the voxel file's body")?;
    body.extend_from_slice(obj.colours.as_flattened());
    let packed = lz4_flex::compress_prepend_size(&body);
    let header = Header {
        format: FORMAT_NAME.to_string(),
        version: VERSION,
        origin: g.origin,
        voxel_size: g.voxel_size,
        dims: g.dims,
        voxels: obj.len() as u64,
        runs: nruns,
        body_bytes: packed.len() as u64,
        body_crc32: crc32fast::hash(&packed),
        source: source.to_string(),
    };
    let json = serde_json::to_vec(&header).expect("header serialises");
    let mut out = Vec::new();
    try_reserve(&mut out, 12 + json.len() + packed.len(), "the voxel file")?;
    out.extend_from_slice(MAGIC);
    out.extend_from_slice(&(json.len() as u32).to_le_bytes());
    out.extend_from_slice(&json);
    out.extend_from_slice(&packed);
    Ok(out)
}

/// Write `obj` to `path` atomically.
pub fn write(path: &Path, obj: &VoxelObject, source: &str) -> Result<()> {
    write_bytes_atomic(path, &encode(obj, source)?)
}

/// Read a `.dvox` file.
pub fn read(path: &Path) -> Result<(VoxelObject, Header)> {
    let bytes = crate::io::read_bytes(path)?;
    decode(&bytes).map_err(|e| e.in_file(path))
}

fn bad(problem: impl Into<String>) -> Error {
    Error::msg(problem).fix("rewrite the object with `dbms sculpt` or `dbms object`")
}

/// Decode `.dvox` bytes, checking every structural rule of the format.
pub fn decode(bytes: &[u8]) -> Result<(VoxelObject, Header)> {
    if bytes.len() < 12 || &bytes[..8] != MAGIC {
        return Err(Error::msg("not a dbms voxel object (bad magic bytes)")
            .fix("give a .dvox file written by dbms"));
    }
    let hlen = u32::from_le_bytes(bytes[8..12].try_into().expect("4 bytes")) as usize;
    let json = bytes
        .get(12..12 + hlen)
        .ok_or_else(|| bad("file ends inside the header (truncated?)"))?;
    let header: Header =
        serde_json::from_slice(json).map_err(|e| bad(format!("bad header: {e}")))?;
    if header.format != FORMAT_NAME || header.version != VERSION {
        return Err(Error::msg(format!(
            "header says {} version {}; this dbms reads {FORMAT_NAME} version {VERSION}",
            header.format, header.version
        ))
        .fix("use the dbms version that wrote it"));
    }
    let grid = VoxelGrid::new(header.origin, header.voxel_size, header.dims)?;
    let packed = &bytes[12 + hlen..];
    if packed.len() as u64 != header.body_bytes {
        return Err(bad(format!(
            "body is {} bytes, header says {} (truncated?)",
            packed.len(),
            header.body_bytes
        )));
    }
    if crc32fast::hash(packed) != header.body_crc32 {
        return Err(bad("body checksum mismatch (corrupt file)"));
    }
    let body = lz4_flex::decompress_size_prepended(packed)
        .map_err(|e| bad(format!("body does not decompress: {e}")))?;
    let (nruns, nvox) = (header.runs as usize, header.voxels as usize);
    if (body.len() as u64) != header.runs * 8 + header.voxels * 3 {
        return Err(bad(format!(
            "body holds {} bytes, expected {} runs and {} voxels",
            body.len(),
            nruns,
            nvox
        )));
    }
    let mut occ = Occupancy::empty(&grid);
    let mut total = 0usize;
    let mut prev_end: Option<usize> = None;
    for rec in body[..nruns * 8].chunks_exact(8) {
        let f = |k: usize| u16::from_le_bytes([rec[2 * k], rec[2 * k + 1]]) as u32;
        let (x, y, z0, len) = (f(0), f(1), f(2), f(3));
        if len == 0 || x >= grid.dims[0] || y >= grid.dims[1] || z0 + len > grid.dims[2] {
            return Err(bad(format!(
                "run ({x}, {y}, {z0}, {len}) lies outside the {:?} grid",
                grid.dims
            )));
        }
        let start = grid.index(x, y, z0);
        if prev_end.is_some_and(|e| start < e) {
            return Err(bad(format!(
                "run ({x}, {y}, {z0}) is out of order or overlaps the previous one"
            )));
        }
        for i in start..start + len as usize {
            occ.set_index(i, true);
        }
        prev_end = Some(start + len as usize);
        total += len as usize;
    }
    if total != nvox {
        return Err(bad(format!("runs hold {total} voxels, header says {nvox}")));
    }
    let colours = body[nruns * 8..]
        .chunks_exact(3)
        .map(|c| [c[0], c[1], c[2]])
        .collect();
    Ok((VoxelObject::new(grid, occ, colours), header))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]
        #[test]
        fn round_trip_is_exact_and_deterministic(nx in 1u32..9, ny in 1u32..9, nz in 1u32..70, seed in any::<u64>()) {
            let g = VoxelGrid::new([500_000.25, 5_000_000.5, 101.0], 0.25, [nx, ny, nz]).unwrap();
            let o = VoxelObject::from_fn(g, |_, i| {
                let h = (i as u64 ^ seed).wrapping_mul(0x9E37_79B9_7F4A_7C15);
                (h >> 60 < 9).then_some([(h >> 8) as u8, (h >> 16) as u8, (h >> 24) as u8])
            });
            let bytes = encode(&o, "test").unwrap();
            prop_assert_eq!(&bytes, &encode(&o, "test").unwrap());
            let (back, h) = decode(&bytes).unwrap();
            prop_assert_eq!(&back, &o);
            prop_assert_eq!(h.source, "test");
        }
    }

    #[test]
    fn corrupt_and_foreign_files_are_clear_errors() {
        let g = VoxelGrid::new([0.0; 3], 1.0, [2, 2, 2]).unwrap();
        let o = VoxelObject::from_fn(g, |p, _| (p[2] < 1.0).then_some([1, 2, 3]));
        let mut bytes = encode(&o, "").unwrap();
        assert!(decode(b"PK\x03\x04 zip file")
            .unwrap_err()
            .to_string()
            .contains("bad magic"));
        assert!(decode(&bytes[..bytes.len() - 1])
            .unwrap_err()
            .to_string()
            .contains("truncated"));
        let last = bytes.len() - 1;
        bytes[last] ^= 0xff;
        assert!(decode(&bytes).unwrap_err().to_string().contains("checksum"));
    }
}
