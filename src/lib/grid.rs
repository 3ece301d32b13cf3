//! Georeferenced grids: the geometry every layer and stage shares.
//!
//! # Conventions (the invariant every stage relies on)
//! * A grid is north-up and unrotated: `x = origin_x + col · cell_x`, `y = origin_y + row · cell_y`
//!   at cell **corners** (GDAL's geotransform and GeoTIFF's PixelIsArea). `cell_x > 0`; `cell_y`
//!   is negative for the usual north-up raster whose first row is the northernmost.
//! * Cell `(col, row)` covers `[col, col+1) × [row, row+1)` in pixel space; its **centre** is at
//!   pixel `(col + 0.5, row + 0.5)`. Values of a raster are samples at cell centres: resampling and
//!   interpolation work on centres (this is what `gdalwarp` does).
//! * World coordinates are `f64` metres (projected CRS) or degrees (geographic CRS). Positions are
//!   computed as `origin + index · cell` with no accumulation, so UTM-sized coordinates
//!   (x ≈ 5e5, y ≈ 5e6) keep sub-millimetre precision at any index.
//! * Row-major storage: index `row · width + col`.

use crate::crs::Crs;
use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};

/// North-up affine transform from pixel space to world space (corner convention, see module docs).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct GeoTransform {
    /// World x of the west edge of column 0 (CRS units).
    pub origin_x: f64,
    /// World y of the top edge of row 0 (CRS units; the north edge when `cell_y < 0`).
    pub origin_y: f64,
    /// Cell width in CRS units, > 0.
    pub cell_x: f64,
    /// Cell height in CRS units; negative for north-up rasters.
    pub cell_y: f64,
}

/// Why a file's georeference cannot be a grid's [`GeoTransform`] (each reader words the error
/// in its own format's terms).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NotNorthUp {
    /// A rotation or shear term is not zero.
    Sheared,
    /// A value is not finite, or the cell is not wider than 0 and of non-zero height.
    BadGeometry,
}

impl GeoTransform {
    /// The north-up transform with corner `origin` and `cell` size (x, y, CRS units), from a
    /// file whose rotation or shear terms are `shear`: both must be zero, every value finite,
    /// the cell wider than 0 and of non-zero height. The one check every georeference reader
    /// (GeoTIFF tags, GDAL, world files) applies.
    pub fn north_up(
        origin: [f64; 2],
        cell: [f64; 2],
        shear: [f64; 2],
    ) -> std::result::Result<GeoTransform, NotNorthUp> {
        if shear != [0.0, 0.0] {
            return Err(NotNorthUp::Sheared);
        }
        let finite = origin.iter().chain(&cell).all(|v| v.is_finite());
        if !finite || !(cell[0] > 0.0) || cell[1] == 0.0 {
            return Err(NotNorthUp::BadGeometry);
        }
        Ok(GeoTransform {
            origin_x: origin[0],
            origin_y: origin[1],
            cell_x: cell[0],
            cell_y: cell[1],
        })
    }

    /// World position of pixel-space point `(px, py)` (fractional pixels, corner convention).
    #[inline]
    pub fn pixel_to_world(&self, px: f64, py: f64) -> (f64, f64) {
        (
            self.origin_x + px * self.cell_x,
            self.origin_y + py * self.cell_y,
        )
    }

    /// Pixel-space position of world point `(x, y)`; inverse of [`pixel_to_world`](Self::pixel_to_world).
    #[inline]
    pub fn world_to_pixel(&self, x: f64, y: f64) -> (f64, f64) {
        (
            (x - self.origin_x) / self.cell_x,
            (y - self.origin_y) / self.cell_y,
        )
    }

    /// GDAL's six-term geotransform `[origin_x, cell_x, 0, origin_y, 0, cell_y]`.
    pub fn to_gdal(&self) -> [f64; 6] {
        [
            self.origin_x,
            self.cell_x,
            0.0,
            self.origin_y,
            0.0,
            self.cell_y,
        ]
    }
}

/// An axis-aligned world rectangle (CRS units), `min < max` on both axes.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Bounds {
    /// West edge.
    pub min_x: f64,
    /// South edge.
    pub min_y: f64,
    /// East edge.
    pub max_x: f64,
    /// North edge.
    pub max_y: f64,
}

/// `[min_x, min_y, max_x, max_y]`, as errors quote an extent.
impl std::fmt::Display for Bounds {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let Bounds {
            min_x,
            min_y,
            max_x,
            max_y,
        } = self;
        write!(f, "[{min_x}, {min_y}, {max_x}, {max_y}]")
    }
}

impl Bounds {
    /// The overlap of two rectangles, or `None` when they do not overlap with positive area.
    pub fn intersection(&self, other: &Bounds) -> Option<Bounds> {
        let b = Bounds {
            min_x: self.min_x.max(other.min_x),
            min_y: self.min_y.max(other.min_y),
            max_x: self.max_x.min(other.max_x),
            max_y: self.max_y.min(other.max_y),
        };
        (b.min_x < b.max_x && b.min_y < b.max_y).then_some(b)
    }

    /// Width (east–west extent), CRS units.
    pub fn width(&self) -> f64 {
        self.max_x - self.min_x
    }

    /// Height (north–south extent), CRS units.
    pub fn height(&self) -> f64 {
        self.max_y - self.min_y
    }

    /// Parse `MINX,MINY,MAXX,MAXY` (the `--bounds` option).
    pub fn parse(s: &str) -> Result<Bounds> {
        Bounds::parse_option("--bounds", s)
    }

    /// Parse `MINX,MINY,MAXX,MAXY` given to option `option` (named in the errors).
    pub fn parse_option(option: &str, s: &str) -> Result<Bounds> {
        let malformed = || {
            Error::msg(format!(
                "{option} {s}: expected four numbers MINX,MINY,MAXX,MAXY"
            ))
            .fix(format!("e.g. {option} 500000,5000000,501000,5001000"))
        };
        let v: Vec<f64> = s
            .split(',')
            .map(|t| t.trim().parse::<f64>())
            .collect::<std::result::Result<_, _>>()
            .map_err(|_| malformed())?;
        if v.iter().any(|x| !x.is_finite()) {
            return Err(malformed());
        }
        let [min_x, min_y, max_x, max_y] = <[f64; 4]>::try_from(v).map_err(|_| malformed())?;
        Bounds {
            min_x,
            min_y,
            max_x,
            max_y,
        }
        .check(option, s)
    }

    /// `self` if its edges are finite and `min < max` on both axes, else an error naming
    /// `option` and `shown` (the rectangle as given).
    pub fn check(self, option: &str, shown: &str) -> Result<Bounds> {
        let edges = [self.min_x, self.min_y, self.max_x, self.max_y];
        if !edges.iter().all(|c| c.is_finite()) {
            return Err(Error::msg(format!(
                "{option} {shown}: every edge must be a finite number"
            )));
        }
        if !(self.min_x < self.max_x && self.min_y < self.max_y) {
            return Err(Error::msg(format!(
                "{option} {shown}: MINX must be below MAXX and MINY below MAXY"
            )));
        }
        Ok(self)
    }
}

/// A georeferenced grid: size, transform and CRS. Holds no data; see [`crate::raster::Raster`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Grid {
    /// Number of columns.
    pub width: usize,
    /// Number of rows.
    pub height: usize,
    /// Pixel → world transform.
    pub transform: GeoTransform,
    /// The CRS of the world coordinates.
    pub crs: Crs,
}

impl Grid {
    /// A north-up grid whose top-left corner is `(min_x, max_y)` with square cells of `cell` units.
    pub fn north_up(
        min_x: f64,
        max_y: f64,
        cell: f64,
        width: usize,
        height: usize,
        crs: Crs,
    ) -> Grid {
        Grid {
            width,
            height,
            transform: GeoTransform {
                origin_x: min_x,
                origin_y: max_y,
                cell_x: cell,
                cell_y: -cell,
            },
            crs,
        }
    }

    /// The grid of square `cell`-sized cells that covers `bounds`, snapped outward so every
    /// point of `bounds` lies in a cell; the top-left corner stays at `(min_x, max_y)`.
    /// Errors on a cell size that is not finite and positive.
    pub fn covering(bounds: &Bounds, cell: f64, crs: Crs) -> Result<Grid> {
        if !(cell.is_finite() && cell > 0.0) {
            return Err(
                Error::msg(format!("cell size {cell} is not a positive number"))
                    .fix("give --cell a value > 0"),
            );
        }
        // Tolerate floating noise: 1000.0000000001 / 0.5 should be 2000 cells, not 2001.
        let n = |extent: f64| ((extent / cell) - 1e-9).ceil().max(1.0) as usize;
        Ok(Grid::north_up(
            bounds.min_x,
            bounds.max_y,
            cell,
            n(bounds.width()),
            n(bounds.height()),
            crs,
        ))
    }

    /// Number of cells.
    pub fn len(&self) -> usize {
        self.width * self.height
    }

    /// True when the grid has no cells.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Row-major index of cell `(col, row)`.
    #[inline]
    pub fn index(&self, col: usize, row: usize) -> usize {
        row * self.width + col
    }

    /// Cell size as `(|cell_x|, |cell_y|)`, CRS units.
    pub fn cell_size(&self) -> (f64, f64) {
        (self.transform.cell_x.abs(), self.transform.cell_y.abs())
    }

    /// World coordinates of the centre of cell `(col, row)`.
    #[inline]
    pub fn cell_centre(&self, col: usize, row: usize) -> (f64, f64) {
        self.transform
            .pixel_to_world(col as f64 + 0.5, row as f64 + 0.5)
    }

    /// The cell containing world point `(x, y)`, or `None` outside the grid.
    pub fn cell_at(&self, x: f64, y: f64) -> Option<(usize, usize)> {
        let (px, py) = self.transform.world_to_pixel(x, y);
        if px >= 0.0 && py >= 0.0 && px < self.width as f64 && py < self.height as f64 {
            Some((px as usize, py as usize))
        } else {
            None
        }
    }

    /// Continuous cell-centre coordinates of world point `(x, y)`: `(0.0, 0.0)` is the centre of
    /// cell (0, 0). This is the space in which bilinear and cubic interpolation work.
    #[inline]
    pub fn world_to_centre_space(&self, x: f64, y: f64) -> (f64, f64) {
        let (px, py) = self.transform.world_to_pixel(x, y);
        (px - 0.5, py - 0.5)
    }

    /// The world rectangle the grid covers (cell edges).
    pub fn bounds(&self) -> Bounds {
        let (x0, y0) = self.transform.pixel_to_world(0.0, 0.0);
        let (x1, y1) = self
            .transform
            .pixel_to_world(self.width as f64, self.height as f64);
        Bounds {
            min_x: x0.min(x1),
            min_y: y0.min(y1),
            max_x: x0.max(x1),
            max_y: y0.max(y1),
        }
    }

    /// World coordinates of the grid's centre point.
    pub fn centre(&self) -> (f64, f64) {
        self.transform
            .pixel_to_world(self.width as f64 / 2.0, self.height as f64 / 2.0)
    }

    /// The sub-grid of a window: same cell size and CRS, origin moved to the window's corner.
    pub fn window_grid(&self, w: &Window) -> Grid {
        let (x, y) = self.transform.pixel_to_world(w.col as f64, w.row as f64);
        Grid {
            width: w.width,
            height: w.height,
            transform: GeoTransform {
                origin_x: x,
                origin_y: y,
                ..self.transform
            },
            crs: self.crs.clone(),
        }
    }

    /// Windows of at most `tile × tile` cells covering the grid, row by row: the unit of
    /// streaming and parallel work. Edge windows are smaller when the size is not a multiple.
    pub fn windows(&self, tile: usize) -> impl Iterator<Item = Window> + '_ {
        let tile = tile.max(1);
        let (w, h) = (self.width, self.height);
        (0..h.div_ceil(tile)).flat_map(move |ty| {
            (0..w.div_ceil(tile)).map(move |tx| {
                let (col, row) = (tx * tile, ty * tile);
                Window {
                    col,
                    row,
                    width: tile.min(w - col),
                    height: tile.min(h - row),
                }
            })
        })
    }
}

/// A rectangle of cells within a grid.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct Window {
    /// First column.
    pub col: usize,
    /// First row.
    pub row: usize,
    /// Number of columns.
    pub width: usize,
    /// Number of rows.
    pub height: usize,
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn north_up_takes_a_grid_and_says_why_not_otherwise() {
        let t = GeoTransform::north_up([500_000.0, 5e6], [2.0, -2.0], [0.0, -0.0]).unwrap();
        assert_eq!(
            (t.origin_x, t.origin_y, t.cell_x, t.cell_y),
            (500_000.0, 5e6, 2.0, -2.0)
        );
        let why = |o: [f64; 2], c: [f64; 2], s: [f64; 2]| GeoTransform::north_up(o, c, s).err();
        assert_eq!(
            why([0.0; 2], [1.0, -1.0], [1e-12, 0.0]),
            Some(NotNorthUp::Sheared)
        );
        assert_eq!(
            why([0.0; 2], [1.0, -1.0], [0.0, f64::NAN]),
            Some(NotNorthUp::Sheared)
        );
        for (o, c) in [
            ([0.0, 0.0], [0.0, -1.0]),
            ([0.0, 0.0], [-1.0, -1.0]),
            ([0.0, 0.0], [1.0, 0.0]),
            ([0.0, 0.0], [f64::NAN, -1.0]),
            ([f64::INFINITY, 0.0], [1.0, -1.0]),
            ([0.0, f64::NAN], [1.0, -1.0]),
        ] {
            assert_eq!(
                why(o, c, [0.0; 2]),
                Some(NotNorthUp::BadGeometry),
                "{o:?} {c:?}"
            );
        }
    }

    fn utm_grid() -> Grid {
        Grid::north_up(
            500_000.0,
            5_000_000.0,
            0.5,
            40_000,
            40_000,
            Crs::epsg(32614),
        )
    }

    #[test]
    fn utm_sized_coordinates_keep_centimetres() {
        // Every conversion at UTM magnitudes must be exact to far better than a centimetre.
        let g = utm_grid();
        for &(c, r) in &[(0usize, 0usize), (1, 1), (12_345, 39_999), (39_999, 7)] {
            let (x, y) = g.cell_centre(c, r);
            assert!((x - (500_000.0 + (c as f64 + 0.5) * 0.5)).abs() < 1e-6);
            assert!((y - (5_000_000.0 - (r as f64 + 0.5) * 0.5)).abs() < 1e-6);
            assert_eq!(g.cell_at(x, y), Some((c, r)));
            let (cx, cy) = g.world_to_centre_space(x, y);
            assert!((cx - c as f64).abs() < 1e-9 && (cy - r as f64).abs() < 1e-9);
        }
        // One centimetre east of a centre moves 0.02 cells: visible in f64 at 5e6.
        let (x, y) = g.cell_centre(100, 100);
        let (cx, _) = g.world_to_centre_space(x + 0.01, y);
        assert!((cx - 100.02).abs() < 1e-9);
    }

    #[test]
    fn bounds_and_covering_grid() {
        let g = Grid::north_up(10.0, 20.0, 2.0, 5, 3, Crs::unknown());
        assert_eq!(
            g.bounds(),
            Bounds {
                min_x: 10.0,
                min_y: 14.0,
                max_x: 20.0,
                max_y: 20.0
            }
        );
        let c = Grid::covering(&g.bounds(), 0.5, Crs::unknown()).unwrap();
        assert_eq!((c.width, c.height), (20, 12));
        let c = Grid::covering(
            &Bounds {
                min_x: 0.0,
                min_y: 0.0,
                max_x: 1.1,
                max_y: 1.0,
            },
            0.5,
            Crs::unknown(),
        )
        .unwrap();
        assert_eq!((c.width, c.height), (3, 2));
        assert!(Grid::covering(&g.bounds(), 0.0, Crs::unknown()).is_err());
        assert!(Grid::covering(&g.bounds(), -1.0, Crs::unknown()).is_err());
    }

    #[test]
    fn windows_cover_every_cell_once() {
        let g = Grid::north_up(0.0, 0.0, 1.0, 7, 5, Crs::unknown());
        let mut seen = vec![0u8; g.len()];
        for w in g.windows(3) {
            for r in w.row..w.row + w.height {
                for c in w.col..w.col + w.width {
                    seen[g.index(c, r)] += 1;
                }
            }
        }
        assert!(seen.iter().all(|&n| n == 1));
        let w = Window {
            col: 3,
            row: 3,
            width: 3,
            height: 2,
        };
        let sub = g.window_grid(&w);
        assert_eq!(sub.cell_centre(0, 0), g.cell_centre(3, 3));
    }

    #[test]
    fn bounds_parse_rejects_bad_input() {
        assert!(Bounds::parse("0,0,10,10").is_ok());
        assert!(Bounds::parse("0,0,10").is_err());
        assert!(Bounds::parse("10,0,0,10").is_err());
        assert!(Bounds::parse("a,b,c,d").is_err());
        assert!(Bounds::parse("0,0,inf,10").is_err());
    }
}
