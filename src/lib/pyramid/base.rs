//! Level 0: the database cells with raised things merged in and the sun effects applied.
//!
//! Invariant: a level-0 cell is valid exactly when its elevation is valid **and** its colour is
//! (a surface with no colour, or a colour with no surface, cannot be drawn); otherwise it is
//! nodata in all three layers (NaN, alpha 0, state empty). A valid cell is an opaque column
//! (state 2) from the ground to its terrain height, or to its [`RaisedCell`](super::raised::RaisedCell)
//! top with that cell's state and colour. Effects then multiply the colour (see [`super::shade`]).

use super::raised::Raised;
use super::reduce::BaseRows;
use super::shade::Effects;
use crate::raster::{Colour, Elevation};
use crate::tiles::{STATE_OPAQUE, STATE_PARTIAL};
use rayon::prelude::*;

/// Everything level 0 is made of. Bands are cut from it on demand.
pub struct Level0<'a> {
    /// Terrain heights, metres; NaN = nodata.
    pub terrain: &'a Elevation,
    /// Orthophoto colour; alpha 0 = nodata.
    pub colour: &'a Colour,
    /// Buildings and objects standing on the terrain.
    pub raised: &'a Raised,
    /// Sun effects, when a sun was given and the scene calls for any.
    pub effects: Option<&'a Effects>,
}

impl Level0<'_> {
    /// Level-0 rows `row0 .. row0 + rows`.
    pub fn band(&self, row0: usize, rows: usize) -> BaseRows {
        let w = self.terrain.grid.width;
        let mut out = BaseRows::nodata(w, rows);
        out.max_z
            .par_chunks_mut(w)
            .zip(out.colour.par_chunks_mut(w))
            .zip(out.state.par_chunks_mut(w))
            .enumerate()
            .for_each(|(r, ((zs, cs), ss))| {
                let start = (row0 + r) * w;
                let mut raised = self.raised.range(start, start + w).iter().peekable();
                for col in 0..w {
                    let i = start + col;
                    let (z, c) = (self.terrain.data[i], self.colour.data[i]);
                    let lifted = raised.next_if(|rc| rc.index == i);
                    if z.is_nan() || c[3] == 0 {
                        continue;
                    }
                    match lifted {
                        Some(rc) => {
                            zs[col] = rc.top_z;
                            cs[col] = rc.colour.unwrap_or(c);
                            ss[col] = if rc.partial {
                                STATE_PARTIAL
                            } else {
                                STATE_OPAQUE
                            };
                        }
                        None => {
                            zs[col] = z;
                            cs[col] = c;
                            ss[col] = STATE_OPAQUE;
                        }
                    }
                }
            });
        if let Some(fx) = self.effects {
            fx.shade_band(row0, &mut out.colour);
        }
        out
    }

    /// Cells dropped because only one of elevation and colour is valid there.
    pub fn half_valid_cells(&self) -> usize {
        self.terrain
            .data
            .par_iter()
            .zip(&self.colour.data)
            .filter(|(z, c)| z.is_nan() != (c[3] == 0))
            .count()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::crs::Crs;
    use crate::grid::Grid;
    use crate::pyramid::raised::RaisedCell;
    use crate::tiles::STATE_EMPTY;

    #[test]
    fn cells_valid_only_where_height_and_colour_both_are() {
        let g = Grid::north_up(0.0, 2.0, 1.0, 3, 2, Crs::unknown());
        let t = Elevation::new(g.clone(), vec![1.0, f32::NAN, 3.0, 4.0, 5.0, 6.0]);
        let c = Colour::new(
            g,
            vec![
                [9, 9, 9, 255],
                [9, 9, 9, 255],
                [0, 0, 0, 0],
                [1, 2, 3, 255],
                [1, 2, 3, 255],
                [1, 2, 3, 255],
            ],
        );
        let raised = Raised::new(
            vec![
                RaisedCell {
                    index: 4,
                    top_z: 15.0,
                    colour: None,
                    partial: false,
                },
                RaisedCell {
                    index: 5,
                    top_z: 16.0,
                    colour: Some([7, 7, 7, 255]),
                    partial: true,
                },
            ],
            &t,
        );
        let l0 = Level0 {
            terrain: &t,
            colour: &c,
            raised: &raised,
            effects: None,
        };
        assert_eq!(l0.half_valid_cells(), 2);
        let b = l0.band(0, 2);
        assert_eq!(
            b.state,
            vec![
                STATE_OPAQUE,
                STATE_EMPTY,
                STATE_EMPTY,
                STATE_OPAQUE,
                STATE_OPAQUE,
                STATE_PARTIAL
            ]
        );
        assert!(b.max_z[1].is_nan() && b.max_z[2].is_nan());
        assert_eq!(b.colour[2], [0; 4]);
        assert_eq!(&b.max_z[3..], &[4.0, 15.0, 16.0]);
        assert_eq!(
            b.colour[4],
            [1, 2, 3, 255],
            "a building keeps the photo's roof colour"
        );
        assert_eq!(
            b.colour[5],
            [7, 7, 7, 255],
            "an object brings its own colour"
        );
        let second = l0.band(1, 1);
        assert_eq!(second.max_z, vec![4.0, 15.0, 16.0]);
    }
}
