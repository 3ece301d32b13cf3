//! Parallel decoding of a TIFF image's strips or tiles ("chunks").
//!
//! Invariant: for every layout [`layout`] accepts, [`decode`] returns exactly the samples the
//! `tiff` crate's serial `read_image_to_buffer` returns (same variant, same values, same plane
//! order), except in sparse chunks and 1-bit samples (below); layouts it does not accept (other
//! compressions, float16, other sub-byte samples, mixed sample formats) return `None` from
//! [`layout`] and are left to the `tiff` crate. Each chunk's
//! compressed bytes are read by offset and byte count (positioned reads, no shared cursor),
//! inflated (Deflate by libdeflate, adler-32 checked; LZW by `weezl`) and un-predicted on a
//! rayon thread, then copied into the image.
//!
//! One-bit samples (one a pixel, unsigned, no predictor: a transparency mask as GDAL writes it)
//! decode to one byte each, 0 or 1, as GDAL reads such a band; the `tiff` crate keeps them packed.
//!
//! Sparse files: a chunk of byte count 0 (GDAL's `SPARSE_OK=TRUE` writes offset 0 and byte count 0
//! for a block that is all nodata, or all zero without nodata) holds no data and reads as the fill
//! value ([`ChunkLayout::with_fill`]): the file's nodata value, else 0, as GDAL reads it.

use crate::error::{Error, Result};
use rayon::prelude::*;
use std::fs::File;
use std::io::{Read, Seek};
use std::ops::Range;
use std::os::unix::fs::FileExt;
use std::path::Path;
use tiff::decoder::{Decoder, DecodingResult};
use tiff::tags::{ByteOrder, Tag};
use tiff::TiffResult;

/// How the chunks of an image are stored, as far as [`decode`] needs it.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct ChunkLayout {
    width: usize,
    height: usize,
    /// Samples per pixel.
    samples: usize,
    /// Bytes per decoded sample: 1, 2, 4 or 8.
    bytes: usize,
    /// 1-bit samples, eight to a stored byte, most significant bit first (each stored row
    /// starts on a byte); decoded to one byte each.
    packed: bool,
    /// SampleFormat: 1 unsigned, 2 signed, 3 IEEE float.
    format: u16,
    /// PlanarConfiguration 2: one set of chunks per sample.
    planar: bool,
    big_endian: bool,
    codec: Codec,
    /// Predictor: 1 none, 2 horizontal, 3 floating point.
    predictor: u16,
    /// Chunk width and height, pixels (a strip is as wide as the image).
    chunk_w: usize,
    chunk_h: usize,
    offsets: Vec<u64>,
    counts: Vec<u64>,
    /// The bits of the sample a sparse chunk (byte count 0) reads as, in the sample's type.
    fill: u64,
}

#[derive(Debug, Clone, Copy, PartialEq)]
enum Codec {
    None,
    Lzw,
    Deflate,
}

/// The chunk plan of the decoder's current image, or `None` for a layout [`decode`] leaves to the
/// `tiff` crate.
pub(crate) fn layout<R: Read + Seek>(dec: &mut Decoder<R>) -> TiffResult<Option<ChunkLayout>> {
    let (width, height) = dec.dimensions()?;
    let (width, height) = (width as usize, height as usize);
    let samples: usize = dec.find_tag_unsigned(Tag::SamplesPerPixel)?.unwrap_or(1);
    let bits: Vec<u16> = dec
        .find_tag_unsigned_vec(Tag::BitsPerSample)?
        .unwrap_or_else(|| vec![1]);
    let formats: Vec<u16> = dec
        .find_tag_unsigned_vec(Tag::SampleFormat)?
        .unwrap_or_else(|| vec![1]);
    let codec = match dec.find_tag_unsigned::<u16>(Tag::Compression)?.unwrap_or(1) {
        1 => Codec::None,
        5 => Codec::Lzw,
        8 | 32946 => Codec::Deflate,
        _ => return Ok(None),
    };
    let predictor: u16 = dec.find_tag_unsigned(Tag::Predictor)?.unwrap_or(1);
    let planar = dec
        .find_tag_unsigned::<u16>(Tag::PlanarConfiguration)?
        .unwrap_or(1)
        == 2;
    let (Some(&b), Some(&format)) = (bits.first(), formats.first()) else {
        return Ok(None);
    };
    let packed = b == 1;
    let bytes = (b as usize / 8).max(1);
    let supported = supported(samples, &bits, &formats, predictor, planar);
    if !supported || width == 0 || height == 0 {
        return Ok(None);
    }
    let Some(Chunks {
        size: (chunk_w, chunk_h),
        offsets,
        counts,
    }) = chunks(dec, width, height)?
    else {
        return Ok(None);
    };
    Ok(Some(ChunkLayout {
        width,
        height,
        samples,
        bytes,
        packed,
        format,
        planar,
        big_endian: dec.byte_order() == ByteOrder::BigEndian,
        codec,
        predictor,
        chunk_w,
        chunk_h,
        offsets,
        counts,
        fill: 0,
    }))
}

/// Whether [`decode`] reads samples of these `bits` and SampleFormat `formats` (one value per
/// sample, all equal), `samples` per pixel, with this predictor and planar configuration.
fn supported(samples: usize, bits: &[u16], formats: &[u16], predictor: u16, planar: bool) -> bool {
    let (b, format) = (bits[0], formats[0]);
    let packed = b == 1;
    samples >= 1
        && (matches!(b, 8 | 16 | 32 | 64) || packed && samples == 1 && predictor == 1)
        && bits.iter().all(|&x| x == b)
        && formats.iter().all(|&f| f == format)
        && match format {
            1 | 2 => matches!(predictor, 1 | 2),
            // The floating-point predictor's rows are summed with a pixel's samples as lanes
            // (see float_row): up to 4 in a chunk; more are left to the tiff crate.
            3 => {
                b >= 32
                    && (1..=3).contains(&predictor)
                    && (predictor != 3 || planar || samples <= FLOAT_LANES)
            }
            _ => false,
        }
}

/// Where an image's chunks (tiles or strips) are.
struct Chunks {
    /// Chunk width and height, pixels.
    size: (usize, usize),
    /// Each chunk's file offset, bytes.
    offsets: Vec<u64>,
    /// Each chunk's stored length, bytes (0: sparse).
    counts: Vec<u64>,
}

/// The chunks of an image of `width` × `height` pixels, from the tile tags or else the strip
/// tags; `None` when a tag is missing or a chunk would be empty.
fn chunks<R: Read + Seek>(
    dec: &mut Decoder<R>,
    width: usize,
    height: usize,
) -> TiffResult<Option<Chunks>> {
    let tiled = dec.find_tag(Tag::TileWidth)?.is_some();
    let (chunk_w, chunk_h, offsets, counts) = if tiled {
        let tw: usize = dec.find_tag_unsigned(Tag::TileWidth)?.unwrap_or(0);
        let th: usize = dec.find_tag_unsigned(Tag::TileLength)?.unwrap_or(0);
        let offsets = dec.find_tag_unsigned_vec(Tag::TileOffsets)?;
        let counts = dec.find_tag_unsigned_vec(Tag::TileByteCounts)?;
        (tw, th, offsets, counts)
    } else {
        let rows: u64 = dec
            .find_tag_unsigned(Tag::RowsPerStrip)?
            .unwrap_or(u32::MAX as u64);
        let offsets = dec.find_tag_unsigned_vec(Tag::StripOffsets)?;
        let counts = dec.find_tag_unsigned_vec(Tag::StripByteCounts)?;
        (width, rows.min(height as u64) as usize, offsets, counts)
    };
    let (Some(offsets), Some(counts)) = (offsets, counts) else {
        return Ok(None);
    };
    if chunk_w == 0 || chunk_h == 0 {
        return Ok(None);
    }
    Ok(Some(Chunks {
        size: (chunk_w, chunk_h),
        offsets,
        counts,
    }))
}

impl ChunkLayout {
    /// This plan with sparse chunks (byte count 0) read as `nodata` (the file's declared value,
    /// in the sample's type as GDAL converts it), or as 0 when the file declares none.
    pub(crate) fn with_fill(self, nodata: Option<f64>) -> ChunkLayout {
        let v = nodata.unwrap_or(0.0);
        let fill = match (self.format, self.bytes) {
            (3, 4) => (v as f32).to_bits() as u64,
            (3, _) => v.to_bits(),
            // Two's complement: the word's low bytes are the signed value's.
            (2, _) => v as i64 as u64,
            _ => v as u64,
        };
        ChunkLayout { fill, ..self }
    }

    /// Planes of chunks: one per sample if planar, else one.
    pub(crate) fn planes(&self) -> usize {
        if self.planar {
            self.samples
        } else {
            1
        }
    }

    /// Bytes of the decoded image.
    pub(crate) fn decoded_bytes(&self) -> u64 {
        (self.width * self.height) as u64 * (self.samples * self.bytes) as u64
    }

    /// Samples of a pixel within one chunk.
    fn chunk_samples(&self) -> usize {
        if self.planar {
            1
        } else {
            self.samples
        }
    }

    /// Bytes of one stored (inflated) row of a chunk, of samples `word` bytes wide once decoded.
    fn stored_row_bytes(&self, word: usize) -> usize {
        if self.packed {
            self.chunk_w.div_ceil(8)
        } else {
            self.chunk_w * self.chunk_samples() * word
        }
    }

    fn across(&self) -> usize {
        self.width.div_ceil(self.chunk_w)
    }

    fn down(&self) -> usize {
        self.height.div_ceil(self.chunk_h)
    }
}

/// Decode image rows `rows` (within `0..height`) from `file`, reading only the chunks they
/// overlap, in parallel: the samples in the `tiff` crate's layout (pixel-interleaved, or plane
/// after plane when planar). `0..height` gives the whole image.
pub(crate) fn decode(
    path: &Path,
    file: &File,
    plan: &ChunkLayout,
    rows: Range<usize>,
) -> Result<DecodingResult> {
    let chunks = plan.planes() * plan.across() * plan.down();
    if plan.offsets.len() < chunks || plan.counts.len() < chunks {
        return Err(Error::file(
            path,
            format!(
                "corrupt or truncated TIFF: {} chunk offsets and {} byte counts for {chunks} chunks",
                plan.offsets.len(),
                plan.counts.len()
            ),
        )
        .fix("re-create the file, or check it with gdalinfo"));
    }
    Ok(match (plan.format, plan.bytes) {
        (1, 1) => DecodingResult::U8(words::<u8>(path, file, plan, rows.clone())?),
        (2, 1) => DecodingResult::I8(
            words::<u8>(path, file, plan, rows.clone())?
                .into_iter()
                .map(|w| w as i8)
                .collect(),
        ),
        (1, 2) => DecodingResult::U16(words::<u16>(path, file, plan, rows.clone())?),
        (2, 2) => DecodingResult::I16(
            words::<u16>(path, file, plan, rows.clone())?
                .into_iter()
                .map(|w| w as i16)
                .collect(),
        ),
        (1, 4) => DecodingResult::U32(words::<u32>(path, file, plan, rows.clone())?),
        (2, 4) => DecodingResult::I32(
            words::<u32>(path, file, plan, rows.clone())?
                .into_iter()
                .map(|w| w as i32)
                .collect(),
        ),
        (3, 4) => DecodingResult::F32(
            words::<u32>(path, file, plan, rows.clone())?
                .into_iter()
                .map(f32::from_bits)
                .collect(),
        ),
        (1, 8) => DecodingResult::U64(words::<u64>(path, file, plan, rows.clone())?),
        (2, 8) => DecodingResult::I64(
            words::<u64>(path, file, plan, rows.clone())?
                .into_iter()
                .map(|w| w as i64)
                .collect(),
        ),
        (3, 8) => DecodingResult::F64(
            words::<u64>(path, file, plan, rows.clone())?
                .into_iter()
                .map(f64::from_bits)
                .collect(),
        ),
        _ => unreachable!("layout() accepts only these sample types"),
    })
}

/// An unsigned sample word: samples are decoded as their bits, then reinterpreted (in place).
trait Word: bytemuck::Pod + Default + Send + Sync {
    const BYTES: usize;
    /// The word whose bytes, most significant first, are `b` (`BYTES` long).
    fn from_be_bytes(b: &[u8]) -> Self;
    /// The word with its bytes reversed.
    fn swap_bytes(self) -> Self;
    fn wrapping_add(self, other: Self) -> Self;
}

/// The most lanes (samples of a pixel in a chunk) [`float_row`] sums side by side.
const FLOAT_LANES: usize = 4;

/// Words of one stored row under the floating-point predictor (TIFF Technical Note 3). `bytes`
/// holds the row's byte planes, most significant first (`out[i]`'s bytes are `bytes[i]`,
/// `bytes[n + i]`, … for `n = out.len()`), differenced as one stream with stride `spp` (a
/// pixel's samples, at most [`FLOAT_LANES`]). A plane's running sums start where the previous
/// plane's end, so those starting sums are found first (plain byte sums), then the planes are
/// summed side by side straight into words: no pass that un-differences the bytes in place.
fn float_row<W: Word>(bytes: &[u8], spp: usize, out: &mut [W]) {
    fn lanes<W: Word, const N: usize>(bytes: &[u8], out: &mut [W]) {
        let n = out.len();
        let mut planes: [&[u8]; 8] = [&[]; 8];
        for (k, plane) in bytes.chunks_exact(n).take(W::BYTES).enumerate() {
            planes[k] = plane;
        }
        // acc[k][j]: the running sum of plane k, lane j.
        let mut acc = [[0u8; N]; 8];
        for k in 1..W::BYTES {
            acc[k] = acc[k - 1];
            for px in planes[k - 1].chunks_exact(N) {
                for j in 0..N {
                    acc[k][j] = acc[k][j].wrapping_add(px[j]);
                }
            }
        }
        for (p, words) in out.chunks_exact_mut(N).enumerate() {
            for (j, word) in words.iter_mut().enumerate() {
                let mut be = [0u8; 8];
                for k in 0..W::BYTES {
                    acc[k][j] = acc[k][j].wrapping_add(planes[k][p * N + j]);
                    be[k] = acc[k][j];
                }
                *word = W::from_be_bytes(&be[..W::BYTES]);
            }
        }
    }
    debug_assert_eq!(bytes.len(), out.len() * W::BYTES);
    match spp {
        1 => lanes::<W, 1>(bytes, out),
        2 => lanes::<W, 2>(bytes, out),
        3 => lanes::<W, 3>(bytes, out),
        4 => lanes::<W, 4>(bytes, out),
        _ => unreachable!("layout() leaves more than {FLOAT_LANES} lanes to the tiff crate"),
    }
}

/// Undo horizontal differencing in place: each value plus the one `stride` before it, running
/// along the row (one independent running sum per sample of a pixel).
fn undifference<W: Word>(row: &mut [W], stride: usize) {
    /// The running sums of a pixel of `N` samples, with `N` known to the compiler.
    fn lanes<W: Word, const N: usize>(row: &mut [W]) {
        let mut acc = [W::default(); N];
        for px in row.chunks_exact_mut(N) {
            for k in 0..N {
                acc[k] = acc[k].wrapping_add(px[k]);
                px[k] = acc[k];
            }
        }
    }
    match stride {
        1 => lanes::<W, 1>(row),
        2 => lanes::<W, 2>(row),
        3 => lanes::<W, 3>(row),
        4 => lanes::<W, 4>(row),
        _ => {
            for i in stride..row.len() {
                row[i] = row[i].wrapping_add(row[i - stride]);
            }
        }
    }
}

macro_rules! word {
    ($t:ty) => {
        impl Word for $t {
            const BYTES: usize = std::mem::size_of::<$t>();
            #[inline]
            fn from_be_bytes(b: &[u8]) -> $t {
                <$t>::from_be_bytes(b.try_into().expect("word-sized slice"))
            }
            #[inline]
            fn wrapping_add(self, other: $t) -> $t {
                <$t>::wrapping_add(self, other)
            }
            #[inline]
            fn swap_bytes(self) -> $t {
                <$t>::swap_bytes(self)
            }
        }
    };
}
word!(u8);
word!(u16);
word!(u32);
word!(u64);

/// Samples of image rows `rows` as words, in the `tiff` crate's layout (pixel-interleaved, or
/// plane after plane). Only the chunk rows that overlap `rows` are read. One task per chunk row
/// (and plane), the chunks of a row decoded in parallel too, so a single-strip image still
/// spreads; each chunk's bytes are then turned into words straight in the output rows, rows in
/// parallel.
fn words<W: Word>(
    path: &Path,
    file: &File,
    plan: &ChunkLayout,
    rows: Range<usize>,
) -> Result<Vec<W>> {
    let spp = plan.chunk_samples();
    let row_len = plan.width * spp;
    let mut out = vec![W::default(); rows.len() * row_len * plan.planes()];
    let (across, down, ch) = (plan.across(), plan.down(), plan.chunk_h);
    // (plane, chunk row, first row within the chunk, output rows) for every overlapping chunk row.
    let mut parts = Vec::new();
    if !rows.is_empty() {
        for (plane, mut buf) in out.chunks_mut(rows.len() * row_len).enumerate() {
            for cy in rows.start / ch..=(rows.end - 1) / ch {
                let (lo, hi) = (rows.start.max(cy * ch), rows.end.min((cy + 1) * ch));
                let (part, rest) = buf.split_at_mut((hi - lo) * row_len);
                parts.push((plane, cy, lo - cy * ch, part));
                buf = rest;
            }
        }
    }
    let chunk_row_bytes = plan.stored_row_bytes(W::BYTES);
    let fill = W::from_be_bytes(&plan.fill.to_be_bytes()[8 - W::BYTES..]);
    parts
        .into_par_iter()
        .try_for_each(|(plane, cy, skip, part)| {
            let n_rows = part.len() / row_len;
            let decoded: Vec<Option<Vec<u8>>> = (0..across)
                .into_par_iter()
                .map(|cx| {
                    let index = (plane * down + cy) * across + cx;
                    chunk_bytes(path, file, plan, index, skip + n_rows, W::BYTES)
                })
                .collect::<Result<_>>()?;
            // Rows in parallel: a band one chunk row tall is a single part, and converting it
            // on one thread would leave the other cores idle.
            part.par_chunks_mut(row_len).enumerate().for_each_init(
                Vec::new,
                |scratch, (r, row)| {
                    for (cx, c) in decoded.iter().enumerate() {
                        let x0 = cx * plan.chunk_w;
                        let n = (plan.chunk_w.min(plan.width - x0)) * spp;
                        let out = &mut row[x0 * spp..][..n];
                        match c {
                            Some(c) => {
                                let bytes = &c[(skip + r) * chunk_row_bytes..][..chunk_row_bytes];
                                chunk_row(plan, bytes, out, scratch);
                            }
                            None => out.fill(fill),
                        }
                    }
                },
            );
            Ok(())
        })?;
    Ok(out)
}

thread_local! {
    /// libdeflate's decompressor, one per thread (it keeps its tables between calls).
    static INFLATER: std::cell::RefCell<libdeflater::Decompressor> =
        std::cell::RefCell::new(libdeflater::Decompressor::new());
}

/// Inflate a zlib stream (TIFF's Deflate, adler-32 checked) of at most `limit` bytes; `Err`
/// says what is wrong with the data (a longer stream is refused as corrupt).
fn inflate_zlib(stored: &[u8], limit: usize) -> std::result::Result<Vec<u8>, String> {
    let mut raw = vec![0u8; limit];
    let n = INFLATER.with(|d| d.borrow_mut().zlib_decompress(stored, &mut raw));
    let n = n.map_err(|e| format!("Deflate data: {e}"))?;
    raw.truncate(n);
    Ok(raw)
}

/// One stored row of a chunk (`chunk_w` pixels, inflated) as words into `out`, its first
/// `out.len()` samples (fewer than the chunk's when the chunk overhangs the image's right edge;
/// `scratch` holds the whole row then).
fn chunk_row<W: Word>(plan: &ChunkLayout, bytes: &[u8], out: &mut [W], scratch: &mut Vec<W>) {
    let spp = plan.chunk_samples();
    if plan.packed {
        for (c, w) in out.iter_mut().enumerate() {
            *w = W::from_be_bytes(&[bytes[c / 8] >> (7 - c % 8) & 1]);
        }
        return;
    }
    match plan.predictor {
        // Byte planes, most significant first, whatever the file's byte order.
        3 if out.len() * W::BYTES == bytes.len() => float_row(bytes, spp, out),
        3 => {
            scratch.resize(bytes.len() / W::BYTES, W::default());
            float_row(bytes, spp, scratch);
            out.copy_from_slice(&scratch[..out.len()]);
        }
        p => {
            // The words' bytes as stored, then turned round if the file's order is not ours.
            let n = out.len();
            bytemuck::cast_slice_mut(out).copy_from_slice(&bytes[..n * W::BYTES]);
            if W::BYTES > 1 && plan.big_endian != cfg!(target_endian = "big") {
                out.iter_mut().for_each(|w| *w = w.swap_bytes());
            }
            // Running sums from the row's left edge: the overhang is at the right, so the
            // image's samples do not depend on it.
            if p == 2 {
                undifference(out, spp);
            }
        }
    }
}

/// The first `rows` rows of chunk `index` as stored bytes, inflated (rows of samples of `word`
/// bytes); `None` for a sparse chunk (byte count 0), which holds no bytes.
fn chunk_bytes(
    path: &Path,
    file: &File,
    plan: &ChunkLayout,
    index: usize,
    rows: usize,
    word: usize,
) -> Result<Option<Vec<u8>>> {
    let corrupt = |what: String| {
        Error::file(
            path,
            format!("corrupt or truncated TIFF: chunk {index}: {what}"),
        )
        .fix("re-create the file, or check it with gdalinfo")
    };
    let row_bytes = plan.stored_row_bytes(word);
    // Tiles are stored whole and the last strip may be too: only the first `rows` rows matter.
    let want = rows * row_bytes;
    let whole = plan.chunk_h * row_bytes;
    let count =
        usize::try_from(plan.counts[index]).map_err(|_| corrupt("byte count too large".into()))?;
    if count == 0 {
        return Ok(None);
    }
    let mut stored = vec![0u8; count];
    file.read_exact_at(&mut stored, plan.offsets[index])
        .map_err(|e| match e.kind() {
            std::io::ErrorKind::UnexpectedEof => {
                Error::file(path, "corrupt or truncated TIFF: file ends early")
                    .fix("re-create or re-download the file")
            }
            _ => Error::io(path, e),
        })?;
    let mut raw = match plan.codec {
        Codec::None => stored,
        // A stream may hold more than the rows wanted (a whole tile), never more than the
        // whole chunk: anything longer is corrupt.
        Codec::Deflate => inflate_zlib(&stored, whole).map_err(corrupt)?,
        Codec::Lzw => weezl::decode::Decoder::with_tiff_size_switch(weezl::BitOrder::Msb, 8)
            .decode(&stored)
            .map_err(|e| corrupt(format!("LZW data: {e}")))?,
    };
    if raw.len() < want {
        return Err(corrupt(format!(
            "{} bytes decoded, expected {want}",
            raw.len()
        )));
    }
    raw.truncate(want);
    Ok(Some(raw))
}

#[cfg(test)]
mod tests {
    use super::*;
    use tiff::encoder::compression::{CompressionAlgorithm, Deflate, DeflateLevel};
    use tiff::encoder::{colortype, Compression, Predictor, TiffEncoder};

    /// The parallel path's samples and the `tiff` crate's serial ones, for the file at `path`;
    /// `None` when the parallel path leaves the layout to the `tiff` crate.
    fn both(path: &Path) -> Option<(DecodingResult, DecodingResult)> {
        let file = File::open(path).unwrap();
        let mut dec = Decoder::new(std::io::BufReader::new(file.try_clone().unwrap())).unwrap();
        let plan = layout(&mut dec).unwrap()?;
        let parallel = decode(path, &file, &plan, 0..plan.height).unwrap();
        assert_windows_match(path, &file, &plan, &parallel);
        let mut serial = DecodingResult::U8(Vec::new());
        dec.read_image_to_buffer(&mut serial).unwrap();
        Some((parallel, serial))
    }

    /// Windows of rows (chunk-aligned or not, one row, all but the edges) decode to the same
    /// samples as the matching rows of the whole image, plane by plane.
    fn assert_windows_match(path: &Path, file: &File, plan: &ChunkLayout, whole: &DecodingResult) {
        let h = plan.height;
        let row_len = plan.width * plan.chunk_samples();
        let all = bits(whole);
        for rows in [
            0..h,
            1..h.saturating_sub(1).max(1),
            h / 2..h / 2 + 1,
            h - 1..h,
            0..0,
        ] {
            let got = bits(&decode(path, file, plan, rows.clone()).unwrap());
            let want: Vec<u64> = (0..plan.planes())
                .flat_map(|p| &all[(p * h + rows.start) * row_len..(p * h + rows.end) * row_len])
                .copied()
                .collect();
            assert_eq!(got, want, "{}: rows {rows:?}", path.display());
        }
    }

    /// Every sample's bits, widened.
    fn bits(r: &DecodingResult) -> Vec<u64> {
        match r {
            DecodingResult::U8(v) => v.iter().map(|&x| x as u64).collect(),
            DecodingResult::I8(v) => v.iter().map(|&x| x as u8 as u64).collect(),
            DecodingResult::U16(v) => v.iter().map(|&x| x as u64).collect(),
            DecodingResult::I16(v) => v.iter().map(|&x| x as u16 as u64).collect(),
            DecodingResult::U32(v) => v.iter().map(|&x| x as u64).collect(),
            DecodingResult::I32(v) => v.iter().map(|&x| x as u32 as u64).collect(),
            DecodingResult::F32(v) => v.iter().map(|x| x.to_bits() as u64).collect(),
            DecodingResult::U64(v) => v.clone(),
            DecodingResult::I64(v) => v.iter().map(|&x| x as u64).collect(),
            DecodingResult::F64(v) => v.iter().map(|x| x.to_bits()).collect(),
            DecodingResult::F16(v) => v.iter().map(|x| x.to_bits() as u64).collect(),
        }
    }

    /// Same variant and the same bits (NaN payloads included).
    fn assert_same(name: &str, a: &DecodingResult, b: &DecodingResult) {
        assert_eq!(
            std::mem::discriminant(a),
            std::mem::discriminant(b),
            "{name}: sample type"
        );
        let (a, b) = (bits(a), bits(b));
        assert_eq!(a.len(), b.len(), "{name}: sample count");
        if let Some(i) = (0..a.len()).find(|&i| a[i] != b[i]) {
            panic!("{name}: sample {i} is {:#x}, serial {:#x}", a[i], b[i]);
        }
    }

    #[test]
    fn undifference_is_the_running_sum_per_sample_for_every_stride() {
        for stride in 1..=7 {
            let row: Vec<u16> = (0..7 * 12).map(|i| (i * 40_503 % 65_521) as u16).collect();
            let mut want = row.clone();
            for i in stride..want.len() {
                want[i] = want[i].wrapping_add(want[i - stride]);
            }
            let mut got = row;
            undifference(&mut got, stride);
            assert_eq!(got, want, "stride {stride}");
        }
    }

    /// A row encoded as TIFF Technical Note 3 says (words' big-endian bytes as planes, then the
    /// byte stream differenced with stride `spp`) comes back word for word.
    #[test]
    fn float_row_undoes_the_floating_point_predictor_for_every_lane_count() {
        /// Encode `words` as the predictor does, then decode them with float_row.
        fn round_trip<W: Word>(words: &[W], spp: usize, be: impl Fn(W) -> Vec<u8>) -> Vec<W> {
            let n = words.len();
            let mut bytes = vec![0u8; n * W::BYTES];
            for (i, &w) in words.iter().enumerate() {
                for (k, b) in be(w).into_iter().enumerate() {
                    bytes[k * n + i] = b;
                }
            }
            for i in (spp..bytes.len()).rev() {
                bytes[i] = bytes[i].wrapping_sub(bytes[i - spp]);
            }
            let mut got = vec![W::default(); n];
            float_row(&bytes, spp, &mut got);
            got
        }
        for spp in 1..=FLOAT_LANES {
            let words: Vec<u32> = (0..12 * spp as u32)
                .map(|i| (i as f32 * 0.7 - 3.0).sin().to_bits() ^ i.wrapping_mul(0x9E37_79B9))
                .collect();
            let got = round_trip(&words, spp, |w| w.to_be_bytes().to_vec());
            assert_eq!(got, words, "u32, {spp} lanes");
            let words: Vec<u64> = words.iter().map(|&w| (w as u64) << 29 ^ w as u64).collect();
            let got = round_trip(&words, spp, |w| w.to_be_bytes().to_vec());
            assert_eq!(got, words, "u64, {spp} lanes");
        }
    }

    #[test]
    fn every_fixture_decodes_to_the_serial_bytes() {
        let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data");
        let mut names: Vec<_> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|e| e == "tif"))
            .collect();
        names.sort();
        let mut compared = Vec::new();
        for p in &names {
            // Fixtures that are meant to fail (truncated, empty, not a TIFF) fail in both paths.
            let Ok(Ok(mut dec)) = File::open(p).map(|f| Decoder::new(std::io::BufReader::new(f)))
            else {
                continue;
            };
            // Sparse chunks (byte count 0): the tiff crate reads bytes at offset 0, the file's
            // header; we read GDAL's fill (tests/io_formats.rs checks those files' values).
            if matches!(layout(&mut dec), Ok(Some(p)) if p.counts.contains(&0)) {
                continue;
            }
            let mut serial = DecodingResult::U8(Vec::new());
            if dec.read_image_to_buffer(&mut serial).is_err() {
                continue;
            }
            if let Some((a, b)) = both(p) {
                assert_same(&p.display().to_string(), &a, &b);
                compared.push(p.file_name().unwrap().to_string_lossy().into_owned());
            }
        }
        for must in [
            "float32_tiled_deflate_pred3_nan.tif",
            "float64_lzw.tif",
            "int16_strip_none_nodata.tif",
            "int32_deflate_pred2.tif",
            "uint16_tiled_lzw.tif",
            "rgb8_planar.tif",
            "rgba8.tif",
            "bigtiff.tif",
        ] {
            assert!(
                compared.iter().any(|c| c == must),
                "{must} not compared: {compared:?}"
            );
        }
    }

    /// Strips written by the `tiff` crate: several strips, the last one short, each
    /// compression and predictor it writes.
    #[test]
    fn stripped_images_with_predictors_match_the_serial_path() {
        let dir = tempfile::tempdir().unwrap();
        let (w, h) = (37u32, 29u32);
        let n = (w * h) as usize;
        let f32s: Vec<f32> = (0..n)
            .map(|i| (i as f32 * 0.37).sin() * 1e3 - 5.0)
            .collect();
        let i16s: Vec<i16> = (0..n)
            .map(|i| (i as i32 * 733 % 65_536 - 32_768) as i16)
            .collect();
        let rgb: Vec<u8> = (0..3 * n).map(|i| (i * 31 % 251) as u8).collect();
        let comps = || {
            [
                Compression::Uncompressed,
                Compression::Lzw,
                Compression::Deflate(DeflateLevel::Fast),
            ]
        };
        let mut k = 0;
        let mut check = |predictor: Predictor,
                         comp: Compression,
                         what: &str,
                         write: &dyn Fn(&mut TiffEncoder<File>)| {
            let p = dir.path().join(format!("s{k}.tif"));
            k += 1;
            let mut enc = TiffEncoder::new(File::create(&p).unwrap())
                .unwrap()
                .with_predictor(predictor)
                .with_compression(comp);
            write(&mut enc);
            drop(enc);
            let (a, b) = both(&p).expect("the parallel path takes it");
            assert_same(&format!("{what} {predictor:?} {k}"), &a, &b);
        };
        // (The tiff crate writes no floating-point predictor: tests/data and our tiled writer
        // cover it.)
        for predictor in [Predictor::None, Predictor::Horizontal] {
            for comp in comps() {
                if predictor == Predictor::None {
                    check(predictor, comp, "f32", &|enc| {
                        let mut img = enc.new_image::<colortype::Gray32Float>(w, h).unwrap();
                        img.rows_per_strip(4).unwrap();
                        img.write_data(&f32s).unwrap();
                    });
                }
                check(predictor, comp, "i16", &|enc| {
                    let mut img = enc.new_image::<colortype::GrayI16>(w, h).unwrap();
                    img.rows_per_strip(4).unwrap();
                    img.write_data(&i16s).unwrap();
                });
                check(predictor, comp, "rgb8", &|enc| {
                    let mut img = enc.new_image::<colortype::RGB8>(w, h).unwrap();
                    img.rows_per_strip(3).unwrap();
                    img.write_data(&rgb).unwrap();
                });
            }
        }
    }

    /// A big-endian file (the `tiff` crate writes only little-endian): 16-bit samples,
    /// horizontal predictor, Deflate, three strips, the last one short.
    #[test]
    fn big_endian_strips_with_horizontal_predictor_match_the_serial_path() {
        let (w, h, rps) = (5u32, 7u32, 3u32);
        let values: Vec<u16> = (0..w * h).map(|i| (i * 4099 % 65_521) as u16).collect();
        let mut strips = Vec::new();
        for rows in values.chunks((w * rps) as usize) {
            let mut bytes = Vec::new();
            for row in rows.chunks(w as usize) {
                let mut prev = 0u16;
                for &v in row {
                    bytes.extend_from_slice(&v.wrapping_sub(prev).to_be_bytes());
                    prev = v;
                }
            }
            let mut packed = Vec::new();
            Deflate::default().write_to(&mut packed, &bytes).unwrap();
            strips.push(packed);
        }
        // Header, then the strips, then the IFD and its out-of-line arrays.
        let mut file = b"MM\0\x2a\0\0\0\0".to_vec();
        let (mut offsets, mut counts) = (Vec::new(), Vec::new());
        for s in &strips {
            offsets.push(file.len() as u32);
            counts.push(s.len() as u32);
            file.extend_from_slice(s);
        }
        let ifd_at = file.len() as u32;
        file[4..8].copy_from_slice(&ifd_at.to_be_bytes());
        let entries: [(u16, u16, u32, u32); 11] = [
            (256, 4, 1, w),
            (257, 4, 1, h),
            (258, 3, 1, 16 << 16),
            (259, 3, 1, 8 << 16),
            (262, 3, 1, 1 << 16),
            (273, 4, 3, ifd_at + 2 + 11 * 12 + 4),
            (277, 3, 1, 1 << 16),
            (278, 4, 1, rps),
            (279, 4, 3, ifd_at + 2 + 11 * 12 + 4 + 12),
            (317, 3, 1, 2 << 16),
            (339, 3, 1, 1 << 16),
        ];
        file.extend_from_slice(&(entries.len() as u16).to_be_bytes());
        for (tag, ty, count, value) in entries {
            file.extend_from_slice(&tag.to_be_bytes());
            file.extend_from_slice(&ty.to_be_bytes());
            file.extend_from_slice(&count.to_be_bytes());
            file.extend_from_slice(&value.to_be_bytes());
        }
        file.extend_from_slice(&[0; 4]);
        for v in offsets.iter().chain(&counts) {
            file.extend_from_slice(&v.to_be_bytes());
        }
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("be.tif");
        std::fs::write(&p, &file).unwrap();
        let (a, b) = both(&p).expect("parallel path");
        assert_same("big-endian", &a, &b);
        assert!(
            matches!(&a, DecodingResult::U16(v) if *v == values),
            "values as written"
        );
    }

    /// Our own tiled writer with partial edge tiles (both predictors), several tile rows.
    #[test]
    fn tiled_images_with_partial_edge_tiles_match_the_serial_path() {
        use crate::crs::Crs;
        use crate::grid::Grid;
        use crate::raster::Raster;
        let dir = tempfile::tempdir().unwrap();
        let g = Grid::north_up(0.0, 0.0, 1.0, 300, 530, Crs::epsg(32614));
        let z: Vec<f32> = (0..g.len())
            .map(|i| {
                if i % 97 == 0 {
                    f32::NAN
                } else {
                    (i as f32).sqrt()
                }
            })
            .collect();
        let p = dir.path().join("z.tif");
        super::super::geotiff::write_f32(&p, &Raster::new(g.clone(), z)).unwrap();
        let (a, b) = both(&p).expect("parallel path");
        assert_same("f32 tiles", &a, &b);
        let c: Vec<[u8; 4]> = (0..g.len())
            .map(|i| [(i % 251) as u8, (i / 7) as u8, 9, 255])
            .collect();
        let p = dir.path().join("c.tif");
        super::super::geotiff::write_rgba8(&p, &Raster::new(g, c)).unwrap();
        let (a, b) = both(&p).expect("parallel path");
        assert_same("rgba tiles", &a, &b);
    }
}
