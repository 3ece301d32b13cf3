//! Level 0: the database cells with raised things merged in and the sun effects applied.
//!
//! Invariant: a level-0 cell is valid exactly when its elevation is valid **and** its colour is
//! (a surface with no colour, or a colour with no surface, cannot be drawn); otherwise it is
//! nodata in all three layers (NaN, alpha 0, state empty). A valid cell is an opaque column
//! (state 2) from the ground to its terrain height, or to its [`RaisedCell`](crate::standing::RaisedCell)
//! top with that cell's state and colour. A partial cell (state 1) also gets its voxel column
//! ([`crate::voxel::columns`]): its runs, a run with no colour of its own (terrain, roof) taking
//! the photo's. Effects then multiply the colour by the cell's factor (see [`super::shade`]), and
//! every run of the cell's column by the same factor, so the top run's colour is the layer's.

use super::cascade::Band;
use super::reduce::BaseRows;
use super::sensor::SensorSource;
use super::shade::{lit, Effects};
use crate::error::Result;
use crate::raster::RowSource;
use crate::standing::Raised;
use crate::tiles::{STATE_EMPTY, STATE_OPAQUE, STATE_PARTIAL};
use crate::voxel::columns::Run;
use rayon::prelude::*;
use std::sync::atomic::{AtomicUsize, Ordering};

/// Everything level 0 is made of. Bands are cut from it on demand, the layers read band by band.
pub struct Level0<'a> {
    /// Terrain heights, metres; NaN = nodata.
    terrain: &'a dyn RowSource<f32>,
    /// Orthophoto colour; alpha 0 = nodata.
    colour: &'a dyn RowSource<[u8; 4]>,
    /// Buildings and objects standing on the terrain.
    raised: &'a Raised,
    /// Sun effects, when a sun was given and the scene calls for any.
    effects: Option<&'a Effects<'a>>,
    /// Page edge, cells: half-valid cells are counted per page.
    page: usize,
    /// Cells of the bands cut so far where only one of elevation and colour is valid, per
    /// page (row-major over the level's pages).
    half_valid: Vec<AtomicUsize>,
    /// The columns effects are applied in (all but for [`only_columns`](Self::only_columns)).
    shaded: std::ops::Range<usize>,
    /// Where the sensor layers come from, in the tile set's order.
    sensor: Vec<SensorSource<'a>>,
}

impl<'a> Level0<'a> {
    /// Level 0 of `terrain` and `colour` (on the same grid) with `raised` merged in and
    /// `effects` applied, cut into pages of `page` cells for its counts.
    pub fn new(
        terrain: &'a dyn RowSource<f32>,
        colour: &'a dyn RowSource<[u8; 4]>,
        raised: &'a Raised,
        effects: Option<&'a Effects<'a>>,
        page: usize,
    ) -> Level0<'a> {
        let g = terrain.grid();
        let pages = g.width.div_ceil(page) * g.height.div_ceil(page);
        Level0 {
            terrain,
            colour,
            raised,
            effects,
            page,
            half_valid: (0..pages).map(|_| AtomicUsize::new(0)).collect(),
            shaded: 0..g.width,
            sensor: Vec::new(),
        }
    }

    /// This level 0 with sensor layers from `sources` (in the tile set's order): each band
    /// carries their values, nodata wherever the cell has no surface.
    pub fn with_sensor(mut self, sources: Vec<SensorSource<'a>>) -> Level0<'a> {
        self.sensor = sources;
        self
    }

    /// This level 0 with the effects applied in columns `cols` only: for a caller that keeps
    /// only cells there (an incremental build's pages), the rest is not worth shading.
    pub fn only_columns(mut self, cols: std::ops::Range<usize>) -> Level0<'a> {
        self.shaded = cols;
        self
    }

    /// Level-0 rows `row0 .. row0 + rows` and the columns of their partial cells.
    ///
    /// The decoded layers become the band's `max_z` and `colour` in place (no copy): nodata
    /// cells are cleared, raised cells lifted, and the photo's colour under raised cells kept
    /// aside for their voxel columns.
    pub fn band(&self, row0: usize, rows: usize) -> Result<Band> {
        let w = self.terrain.grid().width;
        let (terrain, colour) = rayon::join(
            || self.terrain.read_rows(row0, rows),
            || self.colour.read_rows(row0, rows),
        );
        let sensor = self.sensor.par_iter().map(|s| s.read(row0, rows));
        let mut out = BaseRows {
            width: w,
            max_z: terrain?.into_owned(),
            colour: colour?.into_owned(),
            state: vec![STATE_EMPTY; w * rows],
            sensor: sensor.collect::<Result<_>>()?,
        };
        let start = row0 * w;
        let raised = self.raised.range(start, start + w * rows);
        let photo: Vec<[u8; 4]> = raised
            .iter()
            .map(|rc| out.colour[rc.index - start])
            .collect();
        let pages_x = w.div_ceil(self.page);
        out.max_z
            .par_chunks_mut(w)
            .zip(out.colour.par_chunks_mut(w))
            .zip(out.state.par_chunks_mut(w))
            .enumerate()
            .for_each(|(r, ((zs, cs), ss))| {
                let start = (row0 + r) * w;
                let mut raised = self.raised.range(start, start + w).iter().peekable();
                let mut half_valid = vec![0; pages_x];
                for col in 0..w {
                    let lifted = raised.next_if(|rc| rc.index == start + col);
                    if zs[col].is_nan() || cs[col][3] == 0 {
                        half_valid[col / self.page] +=
                            usize::from(zs[col].is_nan() != (cs[col][3] == 0));
                        zs[col] = f32::NAN;
                        cs[col] = [0; 4];
                        continue;
                    }
                    match lifted {
                        Some(rc) => {
                            zs[col] = rc.top_z;
                            cs[col] = rc.colour.unwrap_or(cs[col]);
                            ss[col] = if rc.partial {
                                STATE_PARTIAL
                            } else {
                                STATE_OPAQUE
                            };
                        }
                        None => ss[col] = STATE_OPAQUE,
                    }
                }
                let first = (row0 + r) / self.page * pages_x;
                for (n, counter) in half_valid.iter().zip(&self.half_valid[first..]) {
                    counter.fetch_add(*n, Ordering::Relaxed);
                }
            });
        for s in &mut out.sensor {
            let nodata = out.max_z.iter().enumerate().filter(|(_, z)| z.is_nan());
            nodata.for_each(|(i, _)| s.clear(i));
        }
        let factors = match self.effects {
            Some(fx) => Some(fx.shade_band(row0, &mut out.colour, self.shaded.clone())?),
            None => None,
        };
        let columns = self.columns(row0, &out, &photo, factors.as_deref());
        Ok(Band { rows: out, columns })
    }

    /// The voxel columns of the partial cells of band `rows` (starting at grid row `row0`), lit
    /// by the band's effect `factors` when there are any; `photo` holds the orthophoto's colour
    /// of each of the band's raised cells, in [`Raised::range`] order.
    fn columns(
        &self,
        row0: usize,
        rows: &BaseRows,
        photo: &[[u8; 4]],
        factors: Option<&[f64]>,
    ) -> Vec<(usize, Vec<Run>)> {
        let start = row0 * rows.width;
        let cells = self.raised.range(start, start + rows.state.len());
        cells
            .par_iter()
            .zip(photo)
            .filter(|(rc, _)| rows.state[rc.index - start] == STATE_PARTIAL)
            .map(|(rc, &photo)| {
                let k = rc.index - start;
                let factor = factors.map_or(1.0, |f| f[k]);
                let runs = self
                    .raised
                    .runs(rc.index)
                    .expect("a partial raised cell has runs");
                let runs = runs
                    .iter()
                    .map(|r| {
                        let [red, green, blue, _] = r.colour.unwrap_or(photo);
                        Run {
                            bottom: r.bottom,
                            top: r.top,
                            colour: lit([red, green, blue, 255], factor),
                        }
                    })
                    .collect();
                (k, runs)
            })
            .collect()
    }

    /// Cells dropped, in the bands cut so far, because only one of elevation and colour is
    /// valid there.
    pub fn half_valid_cells(&self) -> usize {
        self.half_valid
            .iter()
            .map(|n| n.load(Ordering::Relaxed))
            .sum()
    }

    /// [`half_valid_cells`](Self::half_valid_cells) of level-0 page `(tx, ty)`.
    pub fn half_valid_in_page(&self, tx: usize, ty: usize) -> usize {
        let pages_x = self.terrain.grid().width.div_ceil(self.page);
        self.half_valid[ty * pages_x + tx].load(Ordering::Relaxed)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::crs::Crs;
    use crate::grid::Grid;
    use crate::raster::{Colour, Elevation};
    use crate::standing::{PlacedVoxels, RaisedCell};
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
        let building = Raised::new(
            vec![RaisedCell {
                index: 4,
                top_z: 15.0,
                colour: None,
                partial: false,
            }],
            &t,
        );
        // A voxel floating 15..16 m over cell 5 (centre (2.5, 0.5), terrain 6 m).
        let lintel = PlacedVoxels {
            origin: [2.5, 0.5, 0.0],
            heading_deg: 0.0,
            voxel_size: 1.0,
            voxels: vec![([0.0, 0.0, 15.5], [7, 7, 7])].into(),
            scale: 1.0,
        };
        let raised = building.union(&Raised::objects(&t.grid, &[lintel], &t), &t);
        let l0 = Level0::new(&t, &c, &raised, None, 2);
        let band = l0.band(0, 2).unwrap();
        assert_eq!(l0.half_valid_cells(), 2);
        let b = &band.rows;
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
        // The partial cell's column: the ground with the photo's colour, the voxel with its own.
        let ground = Run {
            bottom: f32::NEG_INFINITY,
            top: 6.0,
            colour: [1, 2, 3, 255],
        };
        let voxel = Run {
            bottom: 15.0,
            top: 16.0,
            colour: [7, 7, 7, 255],
        };
        assert_eq!(band.columns, vec![(5, vec![ground, voxel])]);
        let second = l0.band(1, 1).unwrap();
        assert_eq!(second.rows.max_z, vec![4.0, 15.0, 16.0]);
        assert_eq!(
            second.columns,
            vec![(2, vec![ground, voxel])],
            "band-local index"
        );
    }

    #[test]
    fn sun_effects_light_every_run_like_the_colour_layer() {
        // A 12 × 12 grid; a lintel floating 4..5 m over cells (3..=8, 6), a 6 m building block
        // east of it; a low sun from the east puts parts of the lintel in shadow.
        let g = Grid::north_up(0.0, 12.0, 1.0, 12, 12, Crs::unknown());
        let t = Elevation::filled(g.clone(), 0.0);
        let c = Colour::filled(g, [100, 150, 200, 255]);
        let lintel = PlacedVoxels {
            origin: [3.5, 5.5, 0.0],
            heading_deg: 0.0,
            voxel_size: 1.0,
            voxels: (0..6)
                .map(|u| ([u as f64, 0.0, 4.5], [80, 40, 20]))
                .collect(),
            scale: 1.0,
        };
        let objects = Raised::objects(&t.grid, &[lintel], &t);
        let block = Raised::new(
            (0..12)
                .map(|r| RaisedCell {
                    index: t.grid.index(10, r),
                    top_z: 6.0,
                    colour: None,
                    partial: false,
                })
                .collect(),
            &t,
        );
        let all = block.union(&objects, &t);
        let sun = crate::sun::Sun::new(20.0, 90.0).unwrap();
        let fx = crate::pyramid::shade::prepare(
            Some(sun),
            None,
            0.5,
            &t,
            &c,
            [&block, &objects, &all],
            None,
        )
        .unwrap()
        .unwrap();
        let l0 = Level0::new(&t, &c, &all, Some(&fx), 4);
        let band = l0.band(0, 12).unwrap();
        assert_eq!(band.columns.len(), 6);
        let mut lit_differently = 0;
        for (i, runs) in &band.columns {
            let k = fx.factor_at(i % 12, i / 12).unwrap();
            assert_eq!(
                runs.last().unwrap().colour,
                band.rows.colour[*i],
                "cell {i}: the top run is the layer's colour"
            );
            assert_eq!(
                runs[0].colour,
                lit([100, 150, 200, 255], k),
                "cell {i}: the ground under the gap, the photo's colour lit"
            );
            lit_differently += (k != 1.0) as usize;
        }
        assert!(
            lit_differently > 0,
            "the test must see a factor other than 1"
        );
    }
}
