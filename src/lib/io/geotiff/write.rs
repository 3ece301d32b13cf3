//! GeoTIFF writing: our three layer kinds (Float32 heights, RGBA8 or RGB8 with an internal
//! mask for colour, 8-bit masks), tiled, Deflate, pushed band by band.
//!
//! Invariant: identical rasters give byte-identical files (no timestamps; the IFDs, GeoKeys and
//! tiles depend only on the cells and the [`Grid`]), and pushing the rows in any bands writes
//! the same bytes as pushing them whole.

use super::geokeys;
use crate::error::{Error, Result};
use crate::grid::Grid;
use crate::io::atomic::{AtomicFile, Staged};
use crate::raster::{Colour, Raster};
use rayon::prelude::*;
use std::io::{Seek, Write};
use std::marker::PhantomData;
use std::path::Path;
use tiff::encoder::compression::{CompressionAlgorithm, Deflate, DeflateLevel};
use tiff::tags::ExtraSamples;

/// The nodata value [`write_f32`] writes for NaN cells.
pub const F32_NODATA: f32 = -9999.0;

/// Write a Float32 GeoTIFF (elevation, metres): NaN is written as [`F32_NODATA`] (-9999) with the
/// GDAL_NODATA tag "-9999". Tiled 256 × 256, Deflate with the floating-point predictor (3).
/// A valid cell that equals -9999 exactly would read back as nodata, so it is an error.
pub fn write_f32(path: &Path, r: &Raster<f32>) -> Result<()> {
    let mut w = GeoTiffWriter::create_f32(path, &r.grid)?;
    w.push_rows(&r.data)?;
    w.finish()
}

/// Write an RGBA8 GeoTIFF (ExtraSamples = unassociated alpha, so GDAL/QGIS treat band 4 as the
/// mask); same georeference as [`write_f32`]. Tiled, Deflate with horizontal predictor.
pub fn write_rgba8(path: &Path, r: &Colour) -> Result<()> {
    let mut w = GeoTiffWriter::create_rgba8(path, &r.grid)?;
    w.push_rows(&r.data)?;
    w.finish()
}

/// Write a single-band 8-bit GeoTIFF with an optional nodata value (used for masks: 1 = shadow,
/// 0 = lit, 255 nodata). Tiled, Deflate with horizontal predictor.
pub fn write_u8(path: &Path, r: &Raster<u8>, nodata: Option<u8>) -> Result<()> {
    let mut w = GeoTiffWriter::create_u8(path, &r.grid, nodata)?;
    w.push_rows(&r.data)?;
    w.finish()
}

/// A sample type our GeoTIFFs hold: how a row of cells becomes little-endian bytes.
pub trait TiffSample: Copy + Send + Sync {
    /// Write `cells` into `out` (exactly `size_of::<Self>()` bytes a cell); `Err(k)` when
    /// `cells[k]` cannot be written (it would read back as nodata).
    fn encode(cells: &[Self], out: &mut [u8]) -> std::result::Result<(), usize>;
}

impl TiffSample for f32 {
    /// NaN becomes [`F32_NODATA`]; a valid cell equal to it is refused.
    fn encode(cells: &[f32], out: &mut [u8]) -> std::result::Result<(), usize> {
        for (k, (&v, o)) in cells.iter().zip(out.chunks_exact_mut(4)).enumerate() {
            if v == F32_NODATA {
                return Err(k);
            }
            o.copy_from_slice(&if v.is_nan() { F32_NODATA } else { v }.to_le_bytes());
        }
        Ok(())
    }
}

impl TiffSample for u8 {
    fn encode(cells: &[u8], out: &mut [u8]) -> std::result::Result<(), usize> {
        out.copy_from_slice(cells);
        Ok(())
    }
}

impl TiffSample for [u8; 4] {
    fn encode(cells: &[[u8; 4]], out: &mut [u8]) -> std::result::Result<(), usize> {
        out.copy_from_slice(cells.as_flattened());
        Ok(())
    }
}

/// A tiled, Deflate-compressed, predicted GeoTIFF written top to bottom, a band of rows at a
/// time, so a raster never has to be whole in memory: the writer holds at most one tile row
/// (256 grid rows) of raw samples and that tile row's compressed tiles, whatever the height.
/// [`write_f32`], [`write_rgba8`] and [`write_u8`] are this writer fed a whole raster, so a file
/// written band by band is byte-identical to one written whole.
///
/// Invariant: rows `0..rows_done` have been pushed; those of complete tile rows are in the file
/// (tiles compressed in parallel, written in order), the rest are in `buf`. The output is
/// atomic: nothing appears at the path until [`finish`](GeoTiffWriter::finish) succeeds.
pub struct GeoTiffWriter<T> {
    out: AtomicFile,
    grid: Grid,
    spec: Spec,
    big: bool,
    /// Raw sample bytes of the pushed rows not yet in the file (fewer than a tile row).
    buf: Vec<u8>,
    rows_done: usize,
    /// File offset and length of every tile written, in tile order.
    offsets: Vec<u64>,
    counts: Vec<u64>,
    /// The same for the tiles of the internal mask (empty unless `spec.mask`).
    mask_offsets: Vec<u64>,
    mask_counts: Vec<u64>,
    /// Bytes in the file so far.
    pos: u64,
    sample: PhantomData<T>,
}

impl GeoTiffWriter<f32> {
    /// A Float32 GeoTIFF on `grid` (see [`write_f32`]).
    pub fn create_f32(path: &Path, grid: &Grid) -> Result<Self> {
        Self::create(path, grid, Spec::float32())
    }
}

impl GeoTiffWriter<[u8; 4]> {
    /// An RGBA8 GeoTIFF on `grid` (see [`write_rgba8`]).
    pub fn create_rgba8(path: &Path, grid: &Grid) -> Result<Self> {
        Self::create(path, grid, Spec::rgba8())
    }

    /// An RGB8 GeoTIFF on `grid` (PhotometricInterpretation RGB, 3 bands, tiled, Deflate with
    /// horizontal predictor) fed RGBA cells: the alpha is not stored as a band but as a TIFF
    /// internal mask, as GDAL writes one with `GDAL_TIFF_INTERNAL_MASK=YES` — a second IFD after
    /// the image's (NewSubfileType 4, PhotometricInterpretation 4 = transparency mask, 1 bit a
    /// cell, same size and 256 × 256 tiles, Deflate), bit 1 where alpha ≠ 0. GDAL reports it as
    /// "Mask Flags: PER_DATASET" (masked cells are nodata to every GDAL tool) and [`super::read`] returns
    /// it as a 4th (alpha) band, so no colour value has to be given up as nodata.
    pub fn create_rgb8_masked(path: &Path, grid: &Grid) -> Result<Self> {
        Self::create(path, grid, Spec::rgb8_masked())
    }
}

impl GeoTiffWriter<u8> {
    /// A single-band byte GeoTIFF on `grid` (see [`write_u8`]).
    pub fn create_u8(path: &Path, grid: &Grid, nodata: Option<u8>) -> Result<Self> {
        Self::create(path, grid, Spec::byte(nodata))
    }
}

impl<T: TiffSample> GeoTiffWriter<T> {
    /// Classic TIFF, or BigTIFF when the padded samples would pass [`BIGTIFF_ABOVE`] bytes.
    fn create(path: &Path, grid: &Grid, spec: Spec) -> Result<Self> {
        let tiles = grid.width.div_ceil(TILE) as u64 * grid.height.div_ceil(TILE) as u64;
        let mask = if spec.mask { TILE * TILE / 8 } else { 0 };
        let big = tiles * (TILE * TILE * spec.pixel_bytes() + mask) as u64 > BIGTIFF_ABOVE;
        Self::create_layout(path, grid, spec, big)
    }

    /// [`create`](Self::create) with the TIFF flavour chosen by the caller.
    fn create_layout(path: &Path, grid: &Grid, spec: Spec, big: bool) -> Result<Self> {
        debug_assert_eq!(spec.cell_bytes(), std::mem::size_of::<T>());
        let (w, h) = (grid.width, grid.height);
        if w == 0 || h == 0 {
            return Err(Error::file(path, "cannot write an empty raster"));
        }
        if u32::try_from(w).is_err() || u32::try_from(h).is_err() {
            return Err(Error::file(
                path,
                format!("{w} × {h} cells is too large for a TIFF"),
            ));
        }
        let mut out = AtomicFile::create(path)?;
        // The first IFD's offset is patched in by `finish`.
        let header: &[u8] = if big {
            b"II\x2b\x00\x08\x00\x00\x00\0\0\0\0\0\0\0\0"
        } else {
            b"II\x2a\x00\0\0\0\0"
        };
        out.writer()
            .write_all(header)
            .map_err(|e| Error::io(path, e))?;
        let tiles = w.div_ceil(TILE) * h.div_ceil(TILE);
        Ok(GeoTiffWriter {
            out,
            grid: grid.clone(),
            spec,
            big,
            buf: Vec::new(),
            rows_done: 0,
            offsets: Vec::with_capacity(tiles),
            counts: Vec::with_capacity(tiles),
            mask_offsets: Vec::new(),
            mask_counts: Vec::new(),
            pos: header.len() as u64,
            sample: PhantomData,
        })
    }

    /// Append whole rows (`cells.len()` a multiple of the width, row-major) below those pushed
    /// before. Every complete tile row is compressed and written at once.
    pub fn push_rows(&mut self, mut cells: &[T]) -> Result<()> {
        let (w, h) = (self.grid.width, self.grid.height);
        let n = cells.len() / w;
        if !cells.len().is_multiple_of(w) || self.rows_done + n > h {
            return Err(Error::file(
                self.out.path(),
                format!(
                    "internal: {} cells pushed after row {} of a {w} × {h} raster",
                    cells.len(),
                    self.rows_done
                ),
            ));
        }
        let row_len = w * self.spec.cell_bytes();
        while !cells.is_empty() {
            let room = TILE - self.buf.len() / row_len;
            let (now, rest) = cells.split_at(room.min(cells.len() / w) * w);
            let start = self.buf.len();
            self.buf.resize(start + now.len() / w * row_len, 0);
            let bad = self.buf[start..]
                .par_chunks_mut(row_len)
                .zip(now.par_chunks(w))
                .enumerate()
                .find_map_first(|(r, (out, row))| T::encode(row, out).err().map(|c| (c, r)));
            if let Some((col, r)) = bad {
                return Err(Error::file(
                    self.out.path(),
                    format!(
                        "cell ({col}, {}) holds {}, the nodata value of our GeoTIFFs",
                        self.rows_done + r,
                        self.spec.nodata.as_deref().unwrap_or("?")
                    ),
                )
                .fix("offset the heights or mark that cell as nodata"));
            }
            self.rows_done += now.len() / w;
            if self.buf.len() == TILE * row_len {
                self.flush_tile_row()?;
            }
            cells = rest;
        }
        Ok(())
    }

    /// Compress the buffered rows (one tile row, or the last, shorter one) as tiles in parallel,
    /// padded with zeros beyond the grid, and append them in order (then the tiles of the
    /// internal mask of those rows, if the spec has one).
    fn flush_tile_row(&mut self) -> Result<()> {
        let (w, spec) = (self.grid.width, &self.spec);
        let (pixel, cell) = (spec.pixel_bytes(), spec.cell_bytes());
        let (row_len, tile_row_len) = (w * cell, TILE * pixel);
        let (buf, rows) = (&self.buf, self.buf.len() / row_len);
        let tiles: Vec<(Vec<u8>, Option<Vec<u8>>)> = (0..w.div_ceil(TILE))
            .into_par_iter()
            .map(|tx| {
                let (mut raw, mut scratch) = (
                    Vec::with_capacity(TILE * tile_row_len),
                    Vec::with_capacity(tile_row_len),
                );
                let cols = tx * TILE * cell..((tx + 1) * TILE).min(w) * cell;
                let src = |r: usize| &buf[r * row_len..][cols.clone()];
                for r in 0..TILE {
                    let start = raw.len();
                    if r < rows && spec.mask {
                        raw.extend(src(r).chunks_exact(cell).flat_map(|c| &c[..pixel]));
                    } else if r < rows {
                        raw.extend_from_slice(src(r));
                    }
                    raw.resize(start + tile_row_len, 0);
                    spec.predict(&mut raw[start..], &mut scratch);
                }
                let mask = spec.mask.then(|| {
                    // 1 bit a cell, most significant first; 0 (nodata) beyond the grid.
                    let mut bits = vec![0u8; TILE * TILE / 8];
                    for r in 0..rows {
                        for (i, c) in src(r).chunks_exact(cell).enumerate() {
                            if c[pixel] != 0 {
                                bits[r * TILE / 8 + i / 8] |= 0x80 >> (i % 8);
                            }
                        }
                    }
                    deflate(&bits)
                });
                (deflate(&raw), mask)
            })
            .collect();
        let path = self.out.path().to_path_buf();
        let (image, masks): (Vec<_>, Vec<_>) = tiles.into_iter().unzip();
        for (t, mask) in image
            .iter()
            .map(|t| (t, false))
            .chain(masks.iter().flatten().map(|t| (t, true)))
        {
            let (offsets, counts) = if mask {
                (&mut self.mask_offsets, &mut self.mask_counts)
            } else {
                (&mut self.offsets, &mut self.counts)
            };
            offsets.push(self.pos);
            counts.push(t.len() as u64);
            self.out
                .writer()
                .write_all(t)
                .map_err(|e| Error::io(&path, e))?;
            self.pos += t.len() as u64;
        }
        self.buf.clear();
        Ok(())
    }

    /// Write the last tiles and the directory, then move the file into place. Every row of the
    /// grid must have been pushed.
    pub fn finish(self) -> Result<()> {
        self.stage()?.commit()
    }

    /// [`finish`](Self::finish) but leave the file under its temporary name, for a run that
    /// renames all its outputs together ([`crate::io::atomic::commit_all`]).
    pub fn stage(mut self) -> Result<Staged> {
        let (w, h) = (self.grid.width, self.grid.height);
        if self.rows_done != h {
            return Err(Error::file(
                self.out.path(),
                format!(
                    "internal: {} of the {h} rows of a {w} × {h} raster were written",
                    self.rows_done
                ),
            ));
        }
        if !self.buf.is_empty() {
            self.flush_tile_row()?;
        }
        let path = self.out.path().to_path_buf();
        let io = |e| Error::io(&path, e);
        let (big, mut pos) = (self.big, self.pos);
        let out = self.out.writer();
        if pos % 2 == 1 {
            out.write_all(&[0]).map_err(io)?;
            pos += 1;
        }
        let entries = ifd_entries(&self.grid, &self.spec, self.offsets, self.counts, big);
        let mut ifd = ifd_bytes(&entries, pos, big, 0);
        if self.spec.mask {
            // GDAL finds the mask by scanning the IFDs after the image's: chain it second.
            let at = pos + ifd.len() as u64;
            let mask = mask_ifd_entries(&self.grid, self.mask_offsets, self.mask_counts, big);
            ifd = ifd_bytes(&entries, pos, big, at);
            ifd.extend(ifd_bytes(&mask, at, big, 0));
        }
        if !big && pos + ifd.len() as u64 > u32::MAX as u64 {
            return Err(
                Error::file(&path, "compressed data exceeds the 4 GiB of a classic TIFF")
                    .fix("write a smaller raster (tile it)"),
            );
        }
        out.write_all(&ifd).map_err(io)?;
        out.seek(std::io::SeekFrom::Start(if big { 8 } else { 4 }))
            .map_err(io)?;
        if big {
            out.write_all(&pos.to_le_bytes()).map_err(io)?;
        } else {
            out.write_all(&(pos as u32).to_le_bytes()).map_err(io)?;
        }
        self.out.stage()
    }
}

/// Tile edge of the GeoTIFFs we write, cells (GDAL's and Cloud-Optimised GeoTIFF's default).
const TILE: usize = 256;

/// The sample layout of an image we write.
struct Spec {
    /// Samples per pixel.
    samples: u16,
    /// Bytes per sample.
    bytes: u16,
    /// IEEE float samples (predictor 3) rather than unsigned integers (predictor 2).
    float: bool,
    /// Photometric RGB rather than MinIsBlack.
    rgb: bool,
    /// The last sample is unassociated alpha.
    alpha: bool,
    /// Each cell arrives with one more byte after its samples (RGBA's alpha) that is written
    /// not as a sample but as the TIFF internal mask (bit 1 where the byte is not 0).
    mask: bool,
    /// GDAL_NODATA text.
    nodata: Option<String>,
}

impl Spec {
    /// Float32 elevation, nodata -9999.
    fn float32() -> Spec {
        Spec {
            samples: 1,
            bytes: 4,
            float: true,
            rgb: false,
            alpha: false,
            mask: false,
            nodata: Some(F32_NODATA.to_string()),
        }
    }

    /// RGB with an unassociated alpha band as the mask.
    fn rgba8() -> Spec {
        Spec {
            samples: 4,
            bytes: 1,
            float: false,
            rgb: true,
            alpha: true,
            mask: false,
            nodata: None,
        }
    }

    /// RGB, the cells' alpha written as the internal mask.
    fn rgb8_masked() -> Spec {
        Spec {
            samples: 3,
            bytes: 1,
            float: false,
            rgb: true,
            alpha: false,
            mask: true,
            nodata: None,
        }
    }

    /// One byte band with an optional nodata value.
    fn byte(nodata: Option<u8>) -> Spec {
        Spec {
            samples: 1,
            bytes: 1,
            float: false,
            rgb: false,
            alpha: false,
            mask: false,
            nodata: nodata.map(|v| v.to_string()),
        }
    }

    /// Bytes of a stored pixel.
    fn pixel_bytes(&self) -> usize {
        self.samples as usize * self.bytes as usize
    }

    /// Bytes of a cell as pushed: the stored pixel and the mask byte, if any.
    fn cell_bytes(&self) -> usize {
        self.pixel_bytes() + self.mask as usize
    }

    /// Apply the predictor to one row of a tile, in place (TIFF 6 section 14 and Adobe's
    /// floating-point predictor technical note 3, as libtiff writes them).
    fn predict(&self, row: &mut [u8], scratch: &mut Vec<u8>) {
        let stride = self.samples as usize;
        if self.float {
            // Byte planes, most significant first, then byte differences along the whole row.
            let bps = self.bytes as usize;
            let n = row.len() / bps;
            scratch.clear();
            scratch.extend_from_slice(row);
            for i in 0..n {
                for b in 0..bps {
                    row[(bps - 1 - b) * n + i] = scratch[i * bps + b];
                }
            }
        }
        // Horizontal differencing of bytes (8-bit samples, or the float byte planes).
        for i in (stride..row.len()).rev() {
            row[i] = row[i].wrapping_sub(row[i - stride]);
        }
    }
}

/// Classic TIFF offsets are 32-bit: beyond this many bytes of (padded) samples we write BigTIFF.
const BIGTIFF_ABOVE: u64 = 0xF000_0000;

/// A TIFF field value.
enum Field {
    Short(Vec<u16>),
    Long(Vec<u32>),
    Long8(Vec<u64>),
    Double(Vec<f64>),
    Ascii(String),
}

impl Field {
    /// TIFF type code, count and little-endian bytes.
    fn encode(&self) -> (u16, u64, Vec<u8>) {
        match self {
            Field::Short(v) => (
                3,
                v.len() as u64,
                v.iter().flat_map(|x| x.to_le_bytes()).collect(),
            ),
            Field::Long(v) => (
                4,
                v.len() as u64,
                v.iter().flat_map(|x| x.to_le_bytes()).collect(),
            ),
            Field::Long8(v) => (
                16,
                v.len() as u64,
                v.iter().flat_map(|x| x.to_le_bytes()).collect(),
            ),
            Field::Double(v) => (
                12,
                v.len() as u64,
                v.iter().flat_map(|x| x.to_le_bytes()).collect(),
            ),
            Field::Ascii(s) => {
                let mut b = s.as_bytes().to_vec();
                b.push(0);
                (2, b.len() as u64, b)
            }
        }
    }
}

/// The tags of an image we write, sorted by tag number as TIFF requires.
fn ifd_entries(
    grid: &Grid,
    spec: &Spec,
    offsets: Vec<u64>,
    counts: Vec<u64>,
    big: bool,
) -> Vec<(u16, Field)> {
    let n = spec.samples as usize;
    let long = |v: u64| Field::Long(vec![v as u32]);
    let chunks = |v| chunk_field(v, big);
    let t = &grid.transform;
    let mut e = vec![
        (256, long(grid.width as u64)),
        (257, long(grid.height as u64)),
        (258, Field::Short(vec![spec.bytes * 8; n])),
        (259, Field::Short(vec![8])), // Deflate
        (262, Field::Short(vec![if spec.rgb { 2 } else { 1 }])),
        (277, Field::Short(vec![spec.samples])),
        (284, Field::Short(vec![1])), // chunky
        (317, Field::Short(vec![if spec.float { 3 } else { 2 }])),
        (322, long(TILE as u64)),
        (323, long(TILE as u64)),
        (324, chunks(offsets)),
        (325, chunks(counts)),
        (339, Field::Short(vec![if spec.float { 3 } else { 1 }; n])),
    ];
    if spec.alpha {
        e.push((
            338,
            Field::Short(vec![ExtraSamples::UnassociatedAlpha.to_u16()]),
        ));
    }
    if t.cell_y < 0.0 {
        e.push((33550, Field::Double(vec![t.cell_x, -t.cell_y, 0.0])));
        e.push((
            33922,
            Field::Double(vec![0.0, 0.0, 0.0, t.origin_x, t.origin_y, 0.0]),
        ));
    } else {
        let m = vec![
            t.cell_x, 0.0, 0.0, t.origin_x, 0.0, t.cell_y, 0.0, t.origin_y, 0.0, 0.0, 0.0, 0.0,
            0.0, 0.0, 0.0, 1.0,
        ];
        e.push((34264, Field::Double(m)));
    }
    let (keys, ascii) = geokeys::directory(&grid.crs);
    e.push((34735, Field::Short(keys)));
    if let Some(a) = ascii {
        e.push((34737, Field::Ascii(a)));
    }
    if let Some(nd) = &spec.nodata {
        e.push((42113, Field::Ascii(nd.clone())));
    }
    e.sort_by_key(|(tag, _)| *tag);
    e
}

/// Tile offsets or byte counts: LONG in a classic TIFF, LONG8 in a BigTIFF.
fn chunk_field(v: Vec<u64>, big: bool) -> Field {
    if big {
        Field::Long8(v)
    } else {
        Field::Long(v.into_iter().map(|x| x as u32).collect())
    }
}

/// The tags of the internal mask's IFD, as GDAL writes them for `GDAL_TIFF_INTERNAL_MASK=YES`:
/// a transparency mask (NewSubfileType 4; PhotometricInterpretation 4),
/// 1 bit a cell, tiled like the image, Deflate without predictor, no georeference of its own.
fn mask_ifd_entries(
    grid: &Grid,
    offsets: Vec<u64>,
    counts: Vec<u64>,
    big: bool,
) -> Vec<(u16, Field)> {
    let long = |v: u64| Field::Long(vec![v as u32]);
    vec![
        (254, long(4)), // NewSubfileType: transparency mask
        (256, long(grid.width as u64)),
        (257, long(grid.height as u64)),
        (258, Field::Short(vec![1])),
        (259, Field::Short(vec![8])), // Deflate
        (262, Field::Short(vec![4])), // transparency mask
        (277, Field::Short(vec![1])),
        (284, Field::Short(vec![1])),
        (322, long(TILE as u64)),
        (323, long(TILE as u64)),
        (324, chunk_field(offsets, big)),
        (325, chunk_field(counts, big)),
    ]
}

/// Deflate (zlib) of one tile's bytes.
fn deflate(raw: &[u8]) -> Vec<u8> {
    let mut packed = Vec::with_capacity(raw.len() / 2);
    // Writing into a Vec cannot fail.
    let _ = Deflate::with_level(DeflateLevel::Balanced).write_to(&mut packed, raw);
    packed
}

/// An IFD placed at file offset `at`, followed by its out-of-line values (word-aligned), that
/// chains to the IFD at offset `next` (0: none).
fn ifd_bytes(entries: &[(u16, Field)], at: u64, big: bool, next: u64) -> Vec<u8> {
    let (entry_len, inline) = if big { (20u64, 8usize) } else { (12, 4) };
    let head = if big { 8 } else { 2 };
    let mut data_pos = at + head + entries.len() as u64 * entry_len + inline as u64;
    let (mut ifd, mut data) = (Vec::new(), Vec::new());
    if big {
        ifd.extend_from_slice(&(entries.len() as u64).to_le_bytes());
    } else {
        ifd.extend_from_slice(&(entries.len() as u16).to_le_bytes());
    }
    for (tag, field) in entries {
        let (ty, count, mut bytes) = field.encode();
        ifd.extend_from_slice(&tag.to_le_bytes());
        ifd.extend_from_slice(&ty.to_le_bytes());
        if big {
            ifd.extend_from_slice(&count.to_le_bytes());
        } else {
            ifd.extend_from_slice(&(count as u32).to_le_bytes());
        }
        if bytes.len() <= inline {
            bytes.resize(inline, 0);
            ifd.extend_from_slice(&bytes);
        } else {
            if big {
                ifd.extend_from_slice(&data_pos.to_le_bytes());
            } else {
                ifd.extend_from_slice(&(data_pos as u32).to_le_bytes());
            }
            if bytes.len() % 2 == 1 {
                bytes.push(0);
            }
            data_pos += bytes.len() as u64;
            data.extend_from_slice(&bytes);
        }
    }
    if big {
        ifd.extend_from_slice(&next.to_le_bytes());
    } else {
        ifd.extend_from_slice(&(next as u32).to_le_bytes());
    }
    ifd.extend_from_slice(&data);
    ifd
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::crs::Crs;
    use crate::io::geotiff::{read, read_rows};
    use crate::io::Samples;
    use crate::raster::NODATA_COLOUR;
    use tiff::decoder::Decoder;
    use tiff::tags::Tag;

    fn grid(crs: Crs) -> Grid {
        Grid::north_up(500_000.25, 5_000_000.75, 0.5, 5, 3, crs)
    }

    #[test]
    fn f32_round_trip_is_bit_exact_with_nan_as_nodata() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("e.tif");
        let data = vec![
            1.0,
            f32::NAN,
            -3.5,
            1e-7,
            8848.86,
            0.0,
            -0.0,
            f32::MIN_POSITIVE,
            12.0,
            1e30,
            2.0,
            3.0,
            4.0,
            5.0,
            f32::NAN,
        ];
        let r = Raster::new(grid(Crs::epsg(32614)), data.clone());
        write_f32(&p, &r).unwrap();
        let s = read(&p).unwrap();
        assert_eq!(s.grid, r.grid);
        assert_eq!(s.nodata, Some(-9999.0));
        let e = s.to_elevation().unwrap();
        for (a, b) in e.data.iter().zip(&data) {
            assert!(
                a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan()),
                "{a} vs {b}"
            );
        }
        let again = dir.path().join("e2.tif");
        write_f32(&again, &r).unwrap();
        assert_eq!(
            std::fs::read(&p).unwrap(),
            std::fs::read(&again).unwrap(),
            "output must be deterministic"
        );
    }

    #[test]
    fn bigtiff_layout_reads_back() {
        // Real BigTIFFs need > 3.75 GiB of samples; the layout is the same for a small image.
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("big.tif");
        let g = Grid::north_up(0.0, 600.0, 1.0, 300, 270, Crs::epsg(32614));
        let data: Vec<u8> = (0..g.len()).map(|i| (i * 7 % 251) as u8).collect();
        let mut w =
            GeoTiffWriter::<u8>::create_layout(&p, &g, Spec::byte(Some(255)), true).unwrap();
        w.push_rows(&data).unwrap();
        w.finish().unwrap();
        assert_eq!(&std::fs::read(&p).unwrap()[..4], b"II\x2b\x00");
        let s = read(&p).unwrap();
        assert_eq!(
            (s.grid, s.samples, s.nodata),
            (g, Samples::U8(data), Some(255.0))
        );
    }

    /// A raster pushed in uneven bands (crossing tile rows mid-band) is the same file, byte for
    /// byte, as the raster written whole; an unfinished writer leaves nothing behind.
    #[test]
    fn banded_writes_equal_whole_writes() {
        let dir = tempfile::tempdir().unwrap();
        let g = Grid::north_up(500_000.0, 5_000_000.0, 0.5, 300, 600, Crs::epsg(32614));
        let z: Vec<f32> = (0..g.len())
            .map(|i| {
                if i % 97 == 0 {
                    f32::NAN
                } else {
                    (i % 1013) as f32 * 0.25
                }
            })
            .collect();
        let whole = dir.path().join("whole.tif");
        write_f32(&whole, &Raster::new(g.clone(), z.clone())).unwrap();
        let banded = dir.path().join("banded.tif");
        let mut w = GeoTiffWriter::create_f32(&banded, &g).unwrap();
        let mut row = 0;
        for n in [7, 113, 1, 255, 224].into_iter().cycle() {
            let n = n.min(600 - row);
            w.push_rows(&z[row * 300..(row + n) * 300]).unwrap();
            row += n;
            if row == 600 {
                break;
            }
        }
        w.finish().unwrap();
        assert_eq!(
            std::fs::read(&whole).unwrap(),
            std::fs::read(&banded).unwrap()
        );

        let short = dir.path().join("short.tif");
        let mut w = GeoTiffWriter::create_f32(&short, &g).unwrap();
        w.push_rows(&z[..300 * 599]).unwrap();
        let e = w.finish().unwrap_err().to_string();
        assert!(e.contains("599 of the 600 rows"), "{e}");
        assert!(w_dir_names(dir.path())
            .iter()
            .all(|n| n == "whole.tif" || n == "banded.tif"));
        assert!(GeoTiffWriter::create_f32(&short, &g)
            .unwrap()
            .push_rows(&z[..301])
            .is_err());
    }

    fn w_dir_names(dir: &Path) -> Vec<String> {
        std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect()
    }

    #[test]
    fn f32_refuses_a_valid_nodata_value() {
        let dir = tempfile::tempdir().unwrap();
        let r = Raster::new(grid(Crs::unknown()), vec![F32_NODATA; 15]);
        assert!(write_f32(&dir.path().join("x.tif"), &r).is_err());
    }

    #[test]
    fn rgba_and_u8_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let g = grid(Crs::epsg(4326));
        let c = Raster::new(
            g.clone(),
            (0..15u8)
                .map(|i| {
                    if i == 3 {
                        NODATA_COLOUR
                    } else {
                        [i, 2 * i, 255 - i, 255]
                    }
                })
                .collect(),
        );
        let p = dir.path().join("c.tif");
        write_rgba8(&p, &c).unwrap();
        let s = read(&p).unwrap();
        assert_eq!((s.bands, s.alpha_band), (4, Some(3)));
        assert_eq!(s.grid, g);
        assert!(s.grid.crs.geographic);
        assert_eq!(s.to_colour().unwrap(), c);

        let m = Raster::new(g.clone(), (0..15u8).map(|i| i % 3).collect());
        let p = dir.path().join("m.tif");
        write_u8(&p, &m, Some(255)).unwrap();
        let s = read(&p).unwrap();
        assert_eq!(s.samples, Samples::U8(m.data.clone()));
        assert_eq!(s.nodata, Some(255.0));
    }

    /// RGB8 with the alpha as internal mask: masked cells read back as nodata whatever their
    /// RGB (black stays a valid colour), whole or by rows across a tile row, and the mask is the
    /// second IFD as GDAL expects (NewSubfileType 4, transparency mask, 1 bit).
    #[test]
    fn rgb8_masked_round_trips_mask_as_nodata() {
        let dir = tempfile::tempdir().unwrap();
        let g = Grid::north_up(500_000.0, 5_000_000.0, 0.5, 300, 270, Crs::epsg(32614));
        let cells: Vec<[u8; 4]> = (0..g.len())
            .map(|i| match i % 7 {
                0 => [(i % 251) as u8, 9, 9, 0],
                1 => [0, 0, 0, 255],
                _ => [(i % 251) as u8, (i % 13) as u8, 7, 255],
            })
            .collect();
        let p = dir.path().join("c.tif");
        let mut w = GeoTiffWriter::create_rgb8_masked(&p, &g).unwrap();
        for band in cells.chunks(300 * 100) {
            w.push_rows(band).unwrap();
        }
        w.finish().unwrap();
        let want: Vec<[u8; 4]> = cells
            .iter()
            .map(|&[r, g, b, a]| {
                if a == 0 {
                    NODATA_COLOUR
                } else {
                    [r, g, b, 255]
                }
            })
            .collect();
        let s = read(&p).unwrap();
        assert_eq!((s.bands, s.alpha_band, &s.grid), (4, Some(3), &g));
        assert_eq!(s.to_colour().unwrap().data, want);
        let rows = read_rows(&p, 250..262).unwrap();
        assert_eq!(rows.to_colour().unwrap().data, want[250 * 300..262 * 300]);

        let again = dir.path().join("again.tif");
        let mut w = GeoTiffWriter::create_rgb8_masked(&again, &g).unwrap();
        w.push_rows(&cells).unwrap();
        w.finish().unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), std::fs::read(&again).unwrap());

        let mut dec = Decoder::new(std::fs::File::open(&p).unwrap()).unwrap();
        let tag = |dec: &mut Decoder<_>, t| dec.find_tag_unsigned::<u32>(t).unwrap();
        assert_eq!(tag(&mut dec, Tag::SamplesPerPixel), Some(3));
        assert_eq!(tag(&mut dec, Tag::PhotometricInterpretation), Some(2));
        dec.next_image().unwrap();
        assert_eq!(tag(&mut dec, Tag::NewSubfileType), Some(4));
        assert_eq!(tag(&mut dec, Tag::PhotometricInterpretation), Some(4));
        assert_eq!(tag(&mut dec, Tag::BitsPerSample), Some(1));
        assert!(!dec.more_images());
    }

    #[test]
    fn wkt_only_crs_round_trips_through_citation() {
        let dir = tempfile::tempdir().unwrap();
        let wkt =
            r#"PROJCS["Local_Grid",GEOGCS["GCS_WGS_1984",DATUM["D_WGS_1984"]],UNIT["Meter",1.0]]"#;
        let crs = Crs {
            epsg: None,
            wkt: Some(wkt.to_string()),
            geographic: false,
            ..Crs::default()
        };
        let r = Raster::new(grid(crs.clone()), vec![1.0; 15]);
        let p = dir.path().join("w.tif");
        write_f32(&p, &r).unwrap();
        assert_eq!(read(&p).unwrap().grid.crs, crs);
    }
}
