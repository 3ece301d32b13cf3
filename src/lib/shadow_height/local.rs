//! The cells around one footprint, classified once: what the scan lines and the refinement see.
//!
//! Invariant: a [`Local`] covers a window of the database grid (never outside it); every cell
//! holds exactly one [`Class`], with the footprint's own cells taking precedence over other
//! footprints', those over the cells the footprint covers in part ([`Class::Edge`]), and those
//! over the photo's lit / shadow reading. Cells whose reading cannot be trusted — nodata colour
//! or elevation, or cells the bare terrain shadows itself — are [`Class::Unusable`]: a
//! building's shadow reaching them has an unknown end.

use crate::grid::{Grid, Window};

/// What one cell is, for measuring this footprint's shadow.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Class {
    /// Open ground, lit in the photo.
    Lit,
    /// Open ground, in shadow in the photo.
    Shadow,
    /// Under this footprint (its centre is inside the polygon).
    Own,
    /// Open ground that this footprint's polygon covers in part (an edge of the polygon crosses
    /// the cell, its centre is outside): the photo shows a mix of the lit roof and the ground
    /// beside it, so its reading says nothing about the shadow. Scan lines walk through it like
    /// [`Class::Own`]; the refinement leaves it out of the comparison. (Read as ground, a cell
    /// crossed by a footprint edge at 0.6–0.8 of its width reads lit beside the shadow, and
    /// every line leaving through that edge measures 0 m.)
    Edge,
    /// Under another footprint.
    Other,
    /// Under another footprint whose roof reads shaded there: this footprint's shadow may lie
    /// on it and run on beyond ([`crate::shadow_height`]'s crossing scan, only for a footprint
    /// whose every line met another). Scan lines walk through it; the refinement does not
    /// compare it, but the shadow attached to the footprint connects through it.
    Crossed,
    /// Nodata, or shadowed by the terrain alone.
    Unusable,
}

/// A window of classified cells with their terrain heights (metres, NaN = nodata).
#[derive(Debug, Clone)]
pub struct Local {
    /// The window in the database grid.
    pub win: Window,
    /// The window's own grid (same cells, origin at the window's corner).
    pub grid: Grid,
    /// One class per window cell, row-major.
    pub class: Vec<Class>,
    /// Terrain heights per window cell, metres.
    pub heights: Vec<f32>,
    /// Shadow index per window cell ([`crate::shadow::detect::shadow_index`], lower = darker; from a
    /// given mask 0 where it says shadow and 255 where lit): how much of a cell is shadow.
    /// Empty in a window classified for the scan lines, which read only the classes; the
    /// refinement's crop has it for its open cells (NaN elsewhere: never read).
    pub index: Vec<f32>,
    /// Per cell, the known roof of the neighbour under it: in the joint pass, the
    /// [`Class::Other`] cells of neighbours whose roof was measured flat, where no third
    /// building's shadow falls on it. Empty when no neighbour's roof is known.
    pub roofs: Vec<Option<RoofCell>>,
}

/// A cell of a neighbour's roof whose height is known.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RoofCell {
    /// The neighbour's id (index + 1 in the footprints).
    pub owner: u32,
    /// The roof's height there, absolute metres.
    pub z: f32,
}

impl Local {
    /// The known neighbour's roof at cell `i`, if any ([`Local::roofs`]).
    pub fn roof(&self, i: usize) -> Option<RoofCell> {
        self.roofs.get(i).copied().flatten()
    }

    /// The part of this local view inside `w` (a window of the database grid), clipped to
    /// `self.win`: a crop never reaches outside what was classified.
    pub fn crop(&self, w: Window, db_grid: &Grid) -> Local {
        let (c0, r0) = (w.col.max(self.win.col), w.row.max(self.win.row));
        let c1 = (w.col + w.width).min(self.win.col + self.win.width).max(c0);
        let r1 = (w.row + w.height)
            .min(self.win.row + self.win.height)
            .max(r0);
        let w = Window {
            col: c0,
            row: r0,
            width: c1 - c0,
            height: r1 - r0,
        };
        let (dc, dr) = (w.col - self.win.col, w.row - self.win.row);
        let mut class = Vec::with_capacity(w.width * w.height);
        let mut heights = Vec::with_capacity(w.width * w.height);
        let mut index = Vec::with_capacity(w.width * w.height);
        let mut roofs = Vec::new();
        for r in 0..w.height {
            let start = (r + dr) * self.win.width + dc;
            class.extend_from_slice(&self.class[start..start + w.width]);
            heights.extend_from_slice(&self.heights[start..start + w.width]);
            if !self.index.is_empty() {
                index.extend_from_slice(&self.index[start..start + w.width]);
            }
            if !self.roofs.is_empty() {
                roofs.extend_from_slice(&self.roofs[start..start + w.width]);
            }
        }
        Local {
            win: w,
            grid: db_grid.window_grid(&w),
            class,
            heights,
            index,
            roofs,
        }
    }
}

/// The window of `grid` covering the world box `bbox` (min x, min y, max x, max y), the same box
/// moved `len_m` metres along the unit vector `u` (east, north), and `margin` cells around.
pub fn window_for(
    grid: &Grid,
    bbox: (f64, f64, f64, f64),
    u: (f64, f64),
    len_m: f64,
    margin: usize,
) -> Window {
    let t = &grid.transform;
    let (ax, ay) = t.world_to_pixel(bbox.0, bbox.1);
    let (bx, by) = t.world_to_pixel(bbox.2, bbox.3);
    let (sx, sy) = (u.0 * len_m / t.cell_x, u.1 * len_m / t.cell_y);
    let (x0, x1) = (ax.min(bx), ax.max(bx));
    let (y0, y1) = (ay.min(by), ay.max(by));
    let m = margin as f64;
    let lo_x = (x0.min(x0 + sx) - m).floor().clamp(0.0, grid.width as f64) as usize;
    let hi_x = (x1.max(x1 + sx) + m).ceil().clamp(0.0, grid.width as f64) as usize;
    let lo_y = (y0.min(y0 + sy) - m).floor().clamp(0.0, grid.height as f64) as usize;
    let hi_y = (y1.max(y1 + sy) + m).ceil().clamp(0.0, grid.height as f64) as usize;
    Window {
        col: lo_x,
        row: lo_y,
        width: hi_x.max(lo_x) - lo_x,
        height: hi_y.max(lo_y) - lo_y,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::crs::Crs;

    #[test]
    fn window_reaches_along_the_shadow_and_stays_in_the_grid() {
        let g = Grid::north_up(0.0, 100.0, 1.0, 100, 100, Crs::epsg(32632));
        // A 10 m box at x 40..50, y 40..50, shadow 20 m to the north.
        let w = window_for(&g, (40.0, 40.0, 50.0, 50.0), (0.0, 1.0), 20.0, 2);
        assert_eq!(
            w,
            Window {
                col: 38,
                row: 28,
                width: 14,
                height: 34
            }
        );
        let far = window_for(&g, (40.0, 40.0, 50.0, 50.0), (1.0, 0.0), 1e6, 2);
        assert_eq!((far.col, far.col + far.width), (38, 100));
        let l = Local {
            win: w,
            grid: g.window_grid(&w),
            class: vec![Class::Lit; 14 * 34],
            heights: vec![0.0; 14 * 34],
            index: (0..14 * 34).map(|i| i as f32).collect(),
            roofs: Vec::new(),
        };
        let c = l.crop(
            Window {
                col: 40,
                row: 30,
                width: 3,
                height: 2,
            },
            &g,
        );
        assert_eq!(c.class.len(), 6);
        assert_eq!(c.index[..2], [(2 * 14 + 2) as f32, (2 * 14 + 3) as f32]);
        assert_eq!(c.grid.transform.origin_x, 40.0);
        // A crop asked beyond the classified window is clipped to it (a short --max-height
        // made the refinement's window outrun the scan's: a panic before).
        let big = l.crop(
            Window {
                col: 30,
                row: 20,
                width: 100,
                height: 100,
            },
            &g,
        );
        assert_eq!(
            (big.win.col, big.win.row, big.win.width, big.win.height),
            (38, 28, 14, 34)
        );
        assert_eq!(big.class.len(), 14 * 34);
    }
}
