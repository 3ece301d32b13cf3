//! The `dbms shadows` stage: a database's cast-shadow mask for one sun, as a byte GeoTIFF.
//!
//! Invariant: the mask is on the database grid, 1 ([`SHADOW`]) where a cell is in cast shadow,
//! 0 ([`LIT`]) where lit and 255 ([`NODATA`]) exactly where the elevation is nodata; the terrain
//! casts with what stands on it (buildings, placed voxel objects, raised as the pyramid raises
//! them, [`crate::standing`]) unless `terrain_only`. The geometric rule streams the terrain band
//! by band (memory: one bit a cell plus a band); GRASS's rule holds the elevation in memory.
//! The file is written atomically. See `docs/shadows.md`.

use crate::db::{self, Database};
use crate::error::Result;
use crate::io::geotiff::GeoTiffWriter;
use crate::progress::Progress;
use crate::raster::{band_rows, RowSource};
use crate::shadow::{cast_shadows_sunmask_slice, ShadowBits, LIT, NODATA, SHADOW};
use crate::standing::{Raised, Standing};
use crate::sun::Sun;
use std::path::Path;

/// Which cells a ray tests, and at what distance (`docs/shadows.md`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Rule {
    /// Each crossed cell at the distance of the ray's point nearest its centre (streamed; the
    /// pyramid's rule).
    Geometric,
    /// GRASS `r.sunmask`'s rule: the cell containing each step point, at the step's distance.
    Sunmask,
}

impl Rule {
    /// The rule's name as `--rule` takes it and the summary reports it.
    pub fn name(self) -> &'static str {
        match self {
            Rule::Geometric => "geometric",
            Rule::Sunmask => "sunmask",
        }
    }
}

/// What [`write_shadow_mask`] found, in cells of the database grid.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct MaskCounts {
    /// Cells in cast shadow.
    pub shadow: usize,
    /// Valid cells lit.
    pub lit: usize,
    /// Cells without elevation.
    pub nodata: usize,
    /// Cells raised by buildings (0 with `terrain_only`).
    pub building_cells: usize,
    /// Cells raised by placed objects (0 with `terrain_only`).
    pub object_cells: usize,
}

/// A cast mask: one bit a cell (the streamed geometric cast) or one byte (the sunmask rule).
enum Cast {
    Bits(ShadowBits),
    Mask(Vec<u8>),
}

impl Cast {
    fn shadowed(&self, i: usize) -> bool {
        match self {
            Cast::Bits(b) => b.get(i),
            Cast::Mask(m) => m[i] == SHADOW,
        }
    }

    fn count(&self) -> usize {
        match self {
            Cast::Bits(b) => b.count(),
            Cast::Mask(m) => m.iter().filter(|&&v| v == SHADOW).count(),
        }
    }
}

/// Cast the shadows of `db`'s terrain (and, unless `terrain_only`, what stands on it) for `sun`
/// under `rule` and write the mask to `output`; `progress` gets one phase ("shadows").
pub fn write_shadow_mask(
    db: &Database,
    sun: &Sun,
    rule: Rule,
    terrain_only: bool,
    output: &Path,
    progress: &Progress,
) -> Result<MaskCounts> {
    let elevation_path = db.layer_path(db::ELEVATION)?;
    let terrain = db.elevation_rows()?;
    let grid = terrain.grid().clone();
    let band = band_rows(grid.width);
    let standing = match terrain_only {
        true => None,
        false => Some(Standing::read(db, &terrain, band)?),
    };
    let empty = Raised::default();
    let raised = standing.as_ref().map_or(&empty, |s| &s.all);
    progress.phase(1 + grid.height.div_ceil(band) as u64, "shadows");
    let cast = match rule {
        Rule::Geometric => Cast::Bits(
            ShadowBits::cast(&terrain, sun, |s, row| raised.lay_over(s, row))
                .map_err(|e| e.in_file(&elevation_path))?,
        ),
        Rule::Sunmask => {
            let mut heights = terrain.read_rows(0, grid.height)?.into_owned();
            for c in raised.cells() {
                heights[c.index] = c.top_z;
            }
            Cast::Mask(
                cast_shadows_sunmask_slice(&heights, &grid, sun)
                    .map_err(|e| e.in_file(&elevation_path))?,
            )
        }
    };
    progress.inc(1);

    let mut out = GeoTiffWriter::create_u8(output, &grid, Some(NODATA))?;
    let (mut nodata, mut mask) = (0, Vec::new());
    for row0 in (0..grid.height).step_by(band) {
        let rows = band.min(grid.height - row0);
        let heights = terrain.read_rows(row0, rows)?;
        let first = row0 * grid.width;
        mask.clear();
        mask.extend(heights.iter().enumerate().map(|(k, z)| match () {
            _ if z.is_nan() => NODATA,
            _ if cast.shadowed(first + k) => SHADOW,
            _ => LIT,
        }));
        nodata += heights.iter().filter(|z| z.is_nan()).count();
        out.push_rows(&mask)?;
        progress.inc(1);
    }
    out.finish()?;
    let shadow = cast.count();
    let (building_cells, object_cells) = standing
        .as_ref()
        .map_or((0, 0), |s| (s.buildings.len(), s.objects.len()));
    Ok(MaskCounts {
        shadow,
        lit: grid.len() - shadow - nodata,
        nodata,
        building_cells,
        object_cells,
    })
}
