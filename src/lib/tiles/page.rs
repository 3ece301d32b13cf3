//! One page: the layers of `P × P` cells, and its byte encoding.
//!
//! Invariant: a page's raw bytes are its layers in header-table order, each `P² · bytes_per_cell`
//! little-endian bytes, row-major, followed by the `bricks` blob when flag [`FLAG_BRICKS`] is
//! set; decoding what [`encode`] made gives back the same page bit for bit (NaN payloads too).

use super::info::{Compression, TileSetInfo};
use super::sensor::{SensorCells, SensorLayer};
use crate::error::{Error, Result};

/// A cell's `state`: defined with the voxel columns that a partial cell points to.
pub use crate::voxel::columns::{STATE_EMPTY, STATE_OPAQUE, STATE_PARTIAL};

/// Index flag: the stored bytes are one lz4 block of the raw bytes.
pub const FLAG_LZ4: u32 = 1;
/// Index flag: the page carries a `bricks` blob after its layers.
pub const FLAG_BRICKS: u32 = 2;
/// Index flag: each multi-byte layer is stored as byte planes (byte 0 of every cell, then
/// byte 1, …), applied before lz4; the bricks blob is not shuffled.
pub const FLAG_SHUFFLE: u32 = 4;
/// Every flag format version 1 defines; a reader rejects any other bit.
pub const KNOWN_FLAGS: u32 = FLAG_LZ4 | FLAG_BRICKS | FLAG_SHUFFLE;

/// One page's layers for `P × P` cells, row-major (`row · P + col`). Cells beyond the level's
/// edge (padding of the right and bottom pages) are nodata: NaN, alpha 0, state 0.
#[derive(Debug, Clone, PartialEq)]
pub struct Page {
    /// Maximum height in each cell, metres; NaN = nodata.
    pub max_z: Vec<f32>,
    /// Average RGBA colour of each cell's visible top surface; alpha 0 = nodata.
    pub colour: Vec<[u8; 4]>,
    /// Occupancy of each cell: [`STATE_EMPTY`], [`STATE_PARTIAL`] or [`STATE_OPAQUE`].
    pub state: Vec<u8>,
    /// Sparse voxel bricks of the page's partial cells; format defined by the voxel module.
    pub bricks: Option<Vec<u8>>,
    /// The tile set's sensor layers, in its table's order (none in a visual-only tile set).
    pub sensor: Vec<(SensorLayer, SensorCells)>,
}

/// One cell of one level, as [`TileReader::cell`](super::TileReader::cell) returns it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cell {
    /// Maximum height, metres; NaN = nodata.
    pub max_z: f32,
    /// Average RGBA colour; alpha 0 = nodata.
    pub colour: [u8; 4],
    /// Occupancy state (see [`STATE_EMPTY`] and friends).
    pub state: u8,
}

/// The rounded average colour `sum / count` of `count` valid colours whose channels sum to
/// `sum` (halves round up), alpha 255; nodata when `count == 0`: a coarse cell's colour, and a
/// parent cell's over a region.
#[inline]
pub fn average_colour(sum: [u64; 3], count: u64) -> [u8; 4] {
    if count == 0 {
        return [0; 4];
    }
    let ch = |s: u64| ((2 * s + count) / (2 * count)) as u8;
    [ch(sum[0]), ch(sum[1]), ch(sum[2]), 255]
}

impl Page {
    /// A page of `page_size²` nodata cells and no bricks: the starting point for filling one.
    pub fn nodata(page_size: usize) -> Page {
        let n = page_size * page_size;
        Page {
            max_z: vec![f32::NAN; n],
            colour: vec![[0; 4]; n],
            state: vec![STATE_EMPTY; n],
            bricks: None,
            sensor: Vec::new(),
        }
    }

    /// A nodata page with the sensor `layers` (all nodata too).
    pub fn nodata_with(page_size: usize, layers: &[SensorLayer]) -> Page {
        let n = page_size * page_size;
        Page {
            sensor: layers.iter().map(|&l| (l, l.nodata(n))).collect(),
            ..Page::nodata(page_size)
        }
    }

    /// The cells of sensor layer `layer`, when the page has it.
    pub fn sensor(&self, layer: SensorLayer) -> Option<&SensorCells> {
        self.sensor
            .iter()
            .find(|(l, _)| *l == layer)
            .map(|(_, c)| c)
    }

    /// The cell at `(col, row)` within the page.
    #[inline]
    pub fn cell(&self, page_size: usize, col: usize, row: usize) -> Cell {
        let i = row * page_size + col;
        Cell {
            max_z: self.max_z[i],
            colour: self.colour[i],
            state: self.state[i],
        }
    }
}

/// A page as stored: what goes in the file and in its index entry.
pub(crate) struct Encoded {
    pub stored: StoredBytes,
    pub raw_len: u32,
    pub crc: u32,
    pub flags: u32,
}

/// Memory alignment of uncompressed stored bytes: enough for `O_DIRECT` writes.
pub(crate) const MEMORY_ALIGN: usize = 4096;

/// A page's stored bytes: `buf[start..start + len]`. Uncompressed pages start at a multiple of
/// [`MEMORY_ALIGN`] in memory, so they can be written with direct I/O.
pub(crate) struct StoredBytes {
    buf: Vec<u8>,
    start: usize,
    len: usize,
}

impl StoredBytes {
    /// `len` zero bytes starting at a multiple of [`MEMORY_ALIGN`] in memory.
    pub(crate) fn aligned_zeroed(len: usize) -> StoredBytes {
        let buf = vec![0u8; len + MEMORY_ALIGN];
        // Moving the Vec never moves its heap block, so the alignment holds wherever it goes.
        let start = buf.as_ptr().align_offset(MEMORY_ALIGN);
        StoredBytes { buf, start, len }
    }

    pub(crate) fn as_mut_slice(&mut self) -> &mut [u8] {
        &mut self.buf[self.start..self.start + self.len]
    }
}

impl std::ops::Deref for StoredBytes {
    type Target = [u8];

    fn deref(&self) -> &[u8] {
        &self.buf[self.start..self.start + self.len]
    }
}

impl From<Vec<u8>> for StoredBytes {
    fn from(buf: Vec<u8>) -> StoredBytes {
        let len = buf.len();
        StoredBytes { buf, start: 0, len }
    }
}

/// Where the known layers sit in a page's raw bytes (from the header's layer table).
#[derive(Debug, Clone)]
pub(crate) struct Layout {
    cells: usize,
    max_z: usize,
    colour: usize,
    state: usize,
    /// Offset of each sensor layer of the table, in table order.
    sensor: Vec<(SensorLayer, usize)>,
    /// `(offset, bytes_per_cell)` of every layer of the table, known or not.
    layers: Vec<(usize, usize)>,
    /// Bytes of all layers together; the bricks blob starts here.
    pub fixed_len: usize,
}

impl Layout {
    /// The layout of `info`'s layer table (validated: the three known layers exist).
    pub fn of(info: &TileSetInfo) -> Layout {
        let cells = info.page_cells();
        let (mut at, mut offsets, mut layers) = (0, [0usize; 3], Vec::new());
        let mut sensor = Vec::new();
        for l in &info.layers {
            layers.push((at, l.bytes_per_cell));
            if let Some(s) = SensorLayer::named(&l.name) {
                sensor.push((s, at));
            }
            if let Some(i) = ["max_z", "colour", "state"]
                .iter()
                .position(|n| *n == l.name)
            {
                offsets[i] = at;
            }
            at += cells * l.bytes_per_cell;
        }
        Layout {
            cells,
            max_z: offsets[0],
            colour: offsets[1],
            state: offsets[2],
            sensor,
            layers,
            fixed_len: at,
        }
    }
}

/// Check `page` fits page `(level, tx, ty)` of `info`: layer lengths, nodata padding, known
/// states. The problem text names the page.
pub(crate) fn check(
    info: &TileSetInfo,
    level: usize,
    tx: usize,
    ty: usize,
    page: &Page,
) -> Result<()> {
    let name = format!("page (level {level}, {tx}, {ty})");
    let n = info.page_cells();
    if page.max_z.len() != n || page.colour.len() != n || page.state.len() != n {
        return Err(Error::msg(format!(
            "{name} has {}/{}/{} max_z/colour/state cells, expected {n} each",
            page.max_z.len(),
            page.colour.len(),
            page.state.len()
        )));
    }
    let want: Vec<SensorLayer> = info.sensor_layers();
    let have: Vec<SensorLayer> = page.sensor.iter().map(|(l, _)| *l).collect();
    if have != want {
        return Err(Error::msg(format!(
            "{name} has the sensor layers {have:?}, the tile set {want:?}"
        )));
    }
    if let Some((l, c)) = page.sensor.iter().find(|(_, c)| c.len() != n) {
        return Err(Error::msg(format!(
            "{name} has {} {} cells, expected {n}",
            c.len(),
            l.name()
        )));
    }
    if let Some(i) = page.state.iter().position(|&s| s > STATE_OPAQUE) {
        return Err(Error::msg(format!(
            "{name}: cell {i} has state {}, expected 0, 1 or 2",
            page.state[i]
        )));
    }
    let p = info.page_size;
    let (cols, rows) = info.page_extent(level, tx, ty);
    for row in 0..p {
        for col in (if row < rows { cols } else { 0 })..p {
            let c = page.cell(p, col, row);
            let i = row * p + col;
            if let Some((l, _)) = page.sensor.iter().find(|(_, s)| !s.is_nodata(i)) {
                return Err(Error::msg(format!(
                    "{name}: padding cell ({col}, {row}) beyond the level's edge is not nodata in layer {}",
                    l.name()
                )));
            }
            if !(c.max_z.is_nan() && c.colour[3] == 0 && c.state == STATE_EMPTY) {
                return Err(Error::msg(format!(
                    "{name}: padding cell ({col}, {row}) beyond the level's edge is not nodata (NaN, alpha 0, state 0)"
                )));
            }
        }
    }
    Ok(())
}

/// Encode a checked page with the standard layer table of a writer.
pub(crate) fn encode(layout: &Layout, page: &Page, compression: Compression) -> Result<Encoded> {
    let bricks = page.bricks.as_deref().unwrap_or(&[]);
    let mut stored_raw = StoredBytes::aligned_zeroed(layout.fixed_len + bricks.len());
    let raw = stored_raw.as_mut_slice();
    let n = layout.cells;
    let max_z = raw[layout.max_z..][..4 * n].chunks_exact_mut(4);
    max_z
        .zip(&page.max_z)
        .for_each(|(b, z)| b.copy_from_slice(&z.to_bits().to_le_bytes()));
    let colour = raw[layout.colour..][..4 * n].chunks_exact_mut(4);
    colour
        .zip(&page.colour)
        .for_each(|(b, c)| b.copy_from_slice(c));
    raw[layout.state..][..layout.cells].copy_from_slice(&page.state);
    for ((_, cells), (_, at)) in page.sensor.iter().zip(&layout.sensor) {
        match cells {
            SensorCells::Ids(ids) => raw[*at..][..n].copy_from_slice(ids),
            SensorCells::Values(v) => raw[*at..][..4 * n]
                .chunks_exact_mut(4)
                .zip(v)
                .for_each(|(b, x)| b.copy_from_slice(&x.to_bits().to_le_bytes())),
            SensorCells::Normals(v) => raw[*at..][..4 * n]
                .chunks_exact_mut(4)
                .zip(v)
                .for_each(|(b, x)| b.copy_from_slice(&x.to_le_bytes())),
        }
    }
    raw[layout.fixed_len..].copy_from_slice(bricks);
    let raw_len = u32::try_from(raw.len()).map_err(|_| {
        Error::msg(format!(
            "a page of {} bytes is over the format's 4 GiB limit",
            raw.len()
        ))
    })?;
    let mut flags = if page.bricks.is_some() {
        FLAG_BRICKS
    } else {
        0
    };
    let stored = match compression {
        Compression::Lz4 => {
            let packed = lz4_flex::block::compress(&to_planes(layout, raw));
            if packed.len() < raw.len() {
                flags |= FLAG_LZ4 | FLAG_SHUFFLE;
                packed.into()
            } else {
                stored_raw
            }
        }
        Compression::None => stored_raw,
    };
    Ok(Encoded {
        crc: crc32fast::hash(&stored),
        stored,
        raw_len,
        flags,
    })
}

/// Byte planes: within each layer of `w`-byte cells, byte 0 of every cell, then byte 1 of every
/// cell, and so on; the bricks blob is left as it is. Slowly varying heights and colours then
/// form long runs in their high bytes, which lz4 finds (on the sample scene's pages: 49 % of
/// the raw size instead of 72 %). [`words`] reads planes back.
fn to_planes(layout: &Layout, raw: &[u8]) -> Vec<u8> {
    let (n, mut out) = (layout.cells, raw.to_vec());
    for &(at, w) in layout.layers.iter().filter(|(_, w)| *w > 1) {
        let (src, dst) = (&raw[at..at + n * w], &mut out[at..at + n * w]);
        for (k, plane) in dst.chunks_exact_mut(n).enumerate() {
            plane
                .iter_mut()
                .zip(src.chunks_exact(w))
                .for_each(|(b, cell)| *b = cell[k]);
        }
    }
    out
}

/// The first `n` 4-byte cells of `layer`, stored cell after cell or as four byte planes, each
/// turned into a value by `f`.
fn words<T>(layer: &[u8], n: usize, planar: bool, f: impl Fn([u8; 4]) -> T) -> Vec<T> {
    let layer = &layer[..4 * n];
    if planar {
        let (p0, rest) = layer.split_at(n);
        let (p1, rest) = rest.split_at(n);
        let (p2, p3) = rest.split_at(n);
        let quads = p0.iter().zip(p1).zip(p2).zip(p3);
        quads.map(|(((a, b), c), d)| f([*a, *b, *c, *d])).collect()
    } else {
        layer
            .chunks_exact(4)
            .map(|c| f([c[0], c[1], c[2], c[3]]))
            .collect()
    }
}

/// Decode stored bytes whose CRC has been checked. `Err` carries the problem without the page's
/// name (the caller adds it).
pub(crate) fn decode(
    layout: &Layout,
    stored: &[u8],
    raw_len: u32,
    flags: u32,
) -> std::result::Result<Page, String> {
    let unpacked;
    let raw = if flags & FLAG_LZ4 != 0 {
        unpacked = lz4_flex::block::decompress(stored, raw_len as usize)
            .map_err(|e| format!("lz4 data is invalid ({e})"))?;
        &unpacked[..]
    } else {
        stored
    };
    if raw.len() != raw_len as usize || raw.len() < layout.fixed_len {
        return Err(format!("holds {} bytes, expected {raw_len}", raw.len()));
    }
    let (n, planar) = (layout.cells, flags & FLAG_SHUFFLE != 0);
    Ok(Page {
        max_z: words(&raw[layout.max_z..], n, planar, |w| {
            f32::from_bits(u32::from_le_bytes(w))
        }),
        colour: words(&raw[layout.colour..], n, planar, |w| w),
        state: raw[layout.state..layout.state + n].to_vec(),
        bricks: (flags & FLAG_BRICKS != 0).then(|| raw[layout.fixed_len..].to_vec()),
        sensor: layout
            .sensor
            .iter()
            .map(|&(l, at)| {
                let cells = match l {
                    SensorLayer::Material => SensorCells::Ids(raw[at..at + n].to_vec()),
                    SensorLayer::Temperature | SensorLayer::Radiance | SensorLayer::Backscatter => {
                        SensorCells::Values(words(&raw[at..], n, planar, |w| {
                            f32::from_bits(u32::from_le_bytes(w))
                        }))
                    }
                    SensorLayer::Normal => {
                        SensorCells::Normals(words(&raw[at..], n, planar, u32::from_le_bytes))
                    }
                };
                (l, cells)
            })
            .collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::crs::Crs;
    use crate::grid::Grid;
    use crate::tiles::info::LayerInfo;

    fn info(w: usize, h: usize, p: usize) -> TileSetInfo {
        TileSetInfo::new(
            Grid::north_up(0.0, 0.0, 1.0, w, h, Crs::unknown()),
            p,
            4,
            None,
        )
        .unwrap()
    }

    fn sample(p: usize) -> Page {
        let mut page = Page::nodata(p);
        for i in 0..p * p {
            page.max_z[i] = i as f32 * 0.25 - 3.0;
            page.colour[i] = [i as u8, 2, 3, 255];
            page.state[i] = (i % 3) as u8;
        }
        page.max_z[1] = f32::from_bits(0x7fc0_1234); // a NaN with a payload
        page.bricks = Some(vec![9, 8, 7]);
        page
    }

    #[test]
    fn encode_decode_is_bit_exact_with_and_without_lz4() {
        let info = info(16, 16, 8);
        let layout = Layout::of(&info);
        let page = sample(8);
        for c in [Compression::None, Compression::Lz4] {
            let e = encode(&layout, &page, c).unwrap();
            assert_eq!(e.raw_len as usize, 8 * 8 * 9 + 3);
            assert_eq!(e.crc, crc32fast::hash(&e.stored));
            let back = decode(&layout, &e.stored, e.raw_len, e.flags).unwrap();
            assert_eq!(back.max_z[1].to_bits(), 0x7fc0_1234);
            assert_eq!(back.colour, page.colour);
            assert_eq!(back.state, page.state);
            assert_eq!(back.bricks, page.bricks);
            assert!(back
                .max_z
                .iter()
                .zip(&page.max_z)
                .all(|(a, b)| a.to_bits() == b.to_bits()));
        }
        // A nodata page compresses; lz4 keeps it only when smaller.
        let e = encode(&layout, &Page::nodata(8), Compression::Lz4).unwrap();
        assert_eq!(e.flags, FLAG_LZ4 | FLAG_SHUFFLE);
        assert!(e.stored.len() < e.raw_len as usize);
    }

    #[test]
    fn sensor_layers_round_trip_bit_exactly_and_padding_must_be_nodata() {
        let layers = [
            SensorLayer::Material,
            SensorLayer::Temperature,
            SensorLayer::Normal,
        ];
        let info = info(10, 6, 8).with_sensor_layers(&layers);
        let layout = Layout::of(&info);
        let mut page = Page::nodata_with(8, &layers);
        page.max_z[0] = 1.0;
        page.sensor[0].1 = SensorCells::Ids((0..64).map(|i| (i % 7) as u8).collect());
        let mut t: Vec<f32> = (0..64).map(|i| 273.15 + i as f32 / 3.0).collect();
        t[5] = f32::from_bits(0x7fc0_0042);
        page.sensor[1].1 = SensorCells::Values(t);
        let normals = (0..64u32).map(|i| i.wrapping_mul(0x9e37_79b9));
        page.sensor[2].1 = SensorCells::Normals(normals.collect());
        for c in [Compression::None, Compression::Lz4] {
            let e = encode(&layout, &page, c).unwrap();
            assert_eq!(e.raw_len as usize, 8 * 8 * (9 + 1 + 4 + 4));
            let back = decode(&layout, &e.stored, e.raw_len, e.flags).unwrap();
            assert_eq!(back.sensor[0], page.sensor[0]);
            assert_eq!(back.sensor[2], page.sensor[2]);
            let bits = |p: &Page| -> Vec<u32> {
                let v = p
                    .sensor(SensorLayer::Temperature)
                    .unwrap()
                    .values()
                    .unwrap();
                v.iter().map(|x| x.to_bits()).collect()
            };
            assert_eq!(bits(&back), bits(&page));
        }
        // Page (0, 1, 0) has 2 valid columns: cell (2, 0) is padding.
        let mut edge = Page::nodata_with(8, &layers);
        check(&info, 0, 1, 0, &edge).unwrap();
        edge.sensor[1].1 = SensorCells::Values({
            let mut v = vec![f32::NAN; 64];
            v[2] = 300.0;
            v
        });
        let e = check(&info, 0, 1, 0, &edge).unwrap_err().to_string();
        assert!(e.contains("(2, 0)") && e.contains("temperature"), "{e}");
        // A page without the tile set's sensor layers is refused.
        let e = check(&info, 0, 0, 0, &Page::nodata(8))
            .unwrap_err()
            .to_string();
        assert!(e.contains("sensor layers"), "{e}");
    }

    #[test]
    fn empty_bricks_differ_from_no_bricks() {
        let info = info(8, 8, 8);
        let layout = Layout::of(&info);
        let mut page = Page::nodata(8);
        page.bricks = Some(vec![]);
        let e = encode(&layout, &page, Compression::None).unwrap();
        assert_eq!(e.flags, FLAG_BRICKS);
        assert_eq!(
            decode(&layout, &e.stored, e.raw_len, e.flags)
                .unwrap()
                .bricks,
            Some(vec![])
        );
    }

    #[test]
    fn decode_skips_unknown_layers() {
        let mut grown = info(8, 8, 4);
        grown.layers.insert(
            1,
            LayerInfo {
                name: "temperature".into(),
                kind: "f32".into(),
                bytes_per_cell: 4,
                nodata: "NaN".into(),
                description: "kelvin".into(),
            },
        );
        let layout = Layout::of(&grown);
        assert_eq!(layout.fixed_len, 16 * 13);
        let mut raw = vec![0u8; layout.fixed_len];
        raw[16 * 4..16 * 8].fill(0xee); // the unknown layer
        raw[16 * 8..16 * 12].copy_from_slice(&[1, 2, 3, 4].repeat(16)); // colour
        let page = decode(&layout, &raw, raw.len() as u32, 0).unwrap();
        assert!(page.colour.iter().all(|c| *c == [1, 2, 3, 4]));
        assert!(page.max_z.iter().all(|z| *z == 0.0));
    }

    #[test]
    fn check_names_the_page_and_the_bad_cell() {
        let info = info(10, 6, 8); // page (0, 1, 0) has 2 valid columns, 6 valid rows
        let mut page = Page::nodata(8);
        page.max_z[0] = 1.0;
        check(&info, 0, 1, 0, &page).unwrap();
        page.max_z[8 * 6] = 1.0; // (0, 6): below the edge
        let e = check(&info, 0, 1, 0, &page).unwrap_err().to_string();
        assert!(
            e.contains("page (level 0, 1, 0)") && e.contains("(0, 6)"),
            "{e}"
        );
        let mut page = Page::nodata(8);
        page.state[3] = 7;
        assert!(check(&info, 0, 0, 0, &page)
            .unwrap_err()
            .to_string()
            .contains("state 7"));
        let page = Page::nodata(4);
        assert!(check(&info, 0, 0, 0, &page)
            .unwrap_err()
            .to_string()
            .contains("expected 64"));
    }

    #[test]
    fn byte_planes_of_any_layer_width_decode_to_the_same_page() {
        let mut grown = info(8, 8, 3);
        grown.layers.push(LayerInfo {
            name: "emissivity".into(),
            kind: "u24".into(),
            bytes_per_cell: 3,
            nodata: "0".into(),
            description: "test".into(),
        });
        let layout = Layout::of(&grown);
        let raw: Vec<u8> = (0..layout.fixed_len + 5)
            .map(|i| (i * 7 % 251) as u8)
            .collect();
        let planes = to_planes(&layout, &raw);
        assert_eq!(
            &planes[layout.fixed_len..],
            &raw[layout.fixed_len..],
            "bricks stay as they are"
        );
        assert_eq!(
            &planes[72..81],
            &raw[72..81],
            "the one-byte state layer is its own plane"
        );
        // Plane 1 of max_z starts with cell 0's byte 1; plane 2 of the 3-byte layer (at 81)
        // holds cell 4's byte 2 at position 4.
        assert_eq!(planes[9], raw[1]);
        assert_eq!(planes[81 + 2 * 9 + 4], raw[81 + 4 * 3 + 2]);
        // A reader also accepts planes stored without compression.
        let page = decode(
            &layout,
            &planes,
            planes.len() as u32,
            FLAG_SHUFFLE | FLAG_BRICKS,
        )
        .unwrap();
        assert_eq!(
            page,
            decode(&layout, &raw, raw.len() as u32, FLAG_BRICKS).unwrap()
        );
    }

    #[test]
    fn decode_rejects_wrong_lengths() {
        let info = info(8, 8, 4);
        let layout = Layout::of(&info);
        assert!(decode(&layout, &[0u8; 10], 10, 0).is_err());
        assert!(decode(&layout, &[0xff; 20], 144, FLAG_LZ4).is_err());
    }
}
