//! Paged tile files: the render database on disk, addressed by `(level, tx, ty)`.
//!
//! A tile set is a hierarchy of levels over the database grid (level 0; level `k` has cells
//! `factor^k` times larger), each cut into square pages of `P × P` cells holding the per-cell
//! layers `max_z` (f32 metres, NaN = nodata), `colour` (RGBA8, alpha 0 = nodata) and `state`
//! (u8 occupancy), plus an optional per-page `bricks` blob for voxel content.
//!
//! Invariants (the full byte layout is in `docs/tile-format.md`):
//! * Every cell of a level lives in exactly one page, `(col / P, row / P)`; pages at the right
//!   and bottom edges are stored full size with nodata padding. There is no apron: a lookup
//!   across a page edge reads the neighbouring page ([`TileReader::cell`] does it).
//! * Page `(level, tx, ty)`'s index entry is at position `level_base[level] + ty · pages_x + tx`.
//! * Page data is stored coarsest level first, each level in Z-order, at 4096-aligned offsets,
//!   each page with a CRC-32 of its stored bytes.
//! * The same tile set description and pages give a byte-identical file, whatever the order
//!   pages were written in.
//!
//! Writing: [`TileWriter::create`], [`TileWriter::write_page`] (any order, any thread),
//! [`TileWriter::finish`]. Reading: [`TileReader::open`], [`TileReader::page`],
//! [`TileReader::cell`].

mod cache;
mod info;
mod layout;
mod page;
mod reader;
pub mod region;
mod sensor;
mod writer;

pub use info::{
    standard_layers, Compression, LayerInfo, LevelInfo, PageOrder, TileSetInfo, BRICKS_FORMAT,
    MAX_LEVELS, MAX_PAGE_SIZE, PAGE_ALIGN,
};
pub use layout::{morton, IndexEntry, ENTRY_LEN, MAGIC, PREAMBLE_LEN, VERSION};
pub use page::{
    average_colour, Cell, Page, FLAG_BRICKS, FLAG_LZ4, FLAG_SHUFFLE, STATE_EMPTY, STATE_OPAQUE,
    STATE_PARTIAL,
};
pub use reader::{PageFilter, ReaderStats, TileReader};
pub use sensor::{
    pack_normal, unpack_normal, Beam, LightPoint, MaterialAttributes, SensorCells, SensorLayer,
    MATERIAL_NODATA, NORMAL_NODATA,
};
pub use writer::{bricks_slot, InPlace, TileWriter};
