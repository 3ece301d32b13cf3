//! The photo's shadows as the photo shows them: a streamed, whole-grid run of the shadow
//! detector of `dbms shadow-height` ([`crate::shadow::detect`]).
//!
//! # Method (the invariant)
//! 1. Every cell gets the shadow index of its colour ([`shadow_index`], lower = darker). Cells
//!    not judged — nodata colour, and roofs of raised buildings (`skip`: dark roofs are common,
//!    and the cast for the photo's sun knows which roofs the photo saw shadowed) — count nowhere
//!    and are never found in shadow.
//! 2. The grid is cut into blocks of [`BLOCK`] × [`BLOCK`] cells. Each block's threshold is
//!    Otsu's ([`otsu_threshold_of`]) over the index histogram of the judged cells of the blocks
//!    up to [`REACH`] blocks around it (a window of `(2·REACH + 1)·BLOCK` = 320 cells a side): a
//!    local threshold, as shadow-height's around a footprint. The shadow class must be a
//!    minority of the window ([`MAX_DARK_FRACTION`]), so light roofs over grass do not make the
//!    grass the "shadow"; a window with no clear shadow class has no threshold.
//! 3. A cell's threshold is the bilinear blend of the thresholds of the four block centres around
//!    it (blocks without one left out, weights renormalised; none → the cell is lit), so there
//!    are no seams at block edges. A judged cell is in shadow when its index is below it.
//!
//! Histograms are integer counts and every cell's threshold is a fixed sequence of `f64`
//! operations, so the mask is a pure function of the colours and `skip` (no dependence on the
//! number of threads).
//!
//! # Memory
//! Two passes over the colour layer, band by band: the first keeps the histograms (1 KiB a
//! block) of the block rows the next thresholds need and one threshold a block; the second
//! classifies each band. The result is one bit a cell.

use super::{band_rows, ShadowBits};
use crate::error::Result;
use crate::raster::RowSource;
use crate::shadow::detect::{index_bin, otsu_threshold_of, shadow_index};
use crate::standing::Raised;
use rayon::prelude::*;

/// Edge of a threshold block, cells.
pub const BLOCK: usize = 64;
/// Blocks either side of a block whose cells its threshold is computed from.
pub const REACH: usize = 2;
/// Most of a threshold window the shadow class may hold (a fraction of its judged cells): the
/// lit ground is the majority (see [`otsu_threshold_of`]).
pub const MAX_DARK_FRACTION: f64 = 0.5;

/// Index histogram of one block (bins of [`index_bin`]).
type Hist = [u32; 256];

/// The cells of grid rows `rows` of `colour` the detector finds in shadow (see the module
/// doc); cells of other rows are left unset. `skip` are raised cells never judged (and left out
/// of the thresholds): it must hold those within [`super::DETECTION_REACH`] of the rows. Only
/// the colour rows the rows' thresholds need are read.
pub fn detect(
    colour: &dyn RowSource<[u8; 4]>,
    skip: &Raised,
    rows: std::ops::Range<usize>,
) -> Result<ShadowBits> {
    let g = colour.grid();
    let (w, h) = (g.width, g.height);
    let rows = rows.start.min(h)..rows.end.min(h);
    let thresholds = Thresholds::compute(colour, skip, &rows)?;
    let mut bits = vec![0u64; (w * h).div_ceil(64)];
    let per_band = band_rows(w);
    for row0 in (rows.start..rows.end).step_by(per_band) {
        let rows = per_band.min(rows.end - row0);
        let data = colour.read_rows(row0, rows)?;
        let start = row0 * w;
        let mut dark = vec![false; data.len()];
        dark.par_chunks_mut(w)
            .zip(data.par_chunks(w))
            .enumerate()
            .for_each(|(r, (out, line))| {
                for (col, (d, c)) in out.iter_mut().zip(line).enumerate() {
                    *d = c[3] != 0
                        && thresholds
                            .at(col, row0 + r)
                            .is_some_and(|t| shadow_index(*c) < t);
                }
            });
        for c in skip.range(start, start + dark.len()) {
            dark[c.index - start] = false;
        }
        for (k, _) in dark.iter().enumerate().filter(|(_, &d)| d) {
            let i = start + k;
            bits[i / 64] |= 1 << (i % 64);
        }
    }
    Ok(ShadowBits::from_bits(bits))
}

/// One threshold (shadow index) per block, or none.
struct Thresholds {
    /// Blocks per row.
    across: usize,
    /// Blocks per column.
    down: usize,
    /// Row-major, `across × down`.
    t: Vec<Option<f64>>,
}

impl Thresholds {
    /// First pass: block histograms band by band, each block row's thresholds as soon as the
    /// rows of blocks within [`REACH`] of it are counted; only the block rows whose centres
    /// grid rows `want` blend ([`Thresholds::at`]) get thresholds (the others none), from the
    /// block rows within [`REACH`] of them.
    fn compute(
        colour: &dyn RowSource<[u8; 4]>,
        skip: &Raised,
        want: &std::ops::Range<usize>,
    ) -> Result<Thresholds> {
        let g = colour.grid();
        let (w, h) = (g.width, g.height);
        let (across, down) = (w.div_ceil(BLOCK), h.div_ceil(BLOCK));
        let per_band = (band_rows(w) / BLOCK).max(1) * BLOCK;
        // Block rows with thresholds: those around the wanted rows' blends, a block each side.
        let first = (want.start / BLOCK).saturating_sub(1);
        let last = match want.is_empty() {
            true => first,
            false => ((want.end - 1) / BLOCK + 2).min(down),
        };
        let mut t = vec![None; first * across];
        t.reserve(across * down);
        // Histograms of block rows `kept.0 ..`, dropped once no threshold needs them.
        let from = first.saturating_sub(REACH);
        let to = (last + REACH).min(down);
        let mut kept: (usize, Vec<Vec<Hist>>) = (from, Vec::new());
        for row0 in (from * BLOCK..(to * BLOCK).min(h)).step_by(per_band) {
            let rows = per_band.min((to * BLOCK).min(h) - row0);
            let data = colour.read_rows(row0, rows)?;
            let start = row0 * w;
            let mut skipped = vec![false; data.len()];
            for c in skip.range(start, start + data.len()) {
                skipped[c.index - start] = true;
            }
            let band: Vec<Vec<Hist>> = data
                .par_chunks(BLOCK * w)
                .zip(skipped.par_chunks(BLOCK * w))
                .map(|(block_row, skipped)| {
                    let mut hists = vec![[0u32; 256]; across];
                    for (k, (c, &s)) in block_row.iter().zip(skipped).enumerate() {
                        if !s && c[3] != 0 {
                            hists[(k % w) / BLOCK][index_bin(shadow_index(*c))] += 1;
                        }
                    }
                    hists
                })
                .collect();
            kept.1.extend(band);
            let counted = kept.0 + kept.1.len();
            // Block rows whose neighbourhood is complete (all of them after the last band).
            let ready = if row0 + rows >= (to * BLOCK).min(h) {
                last
            } else {
                counted.saturating_sub(REACH).min(last)
            };
            let next = t.len() / across.max(1);
            let more: Vec<Option<f64>> = (next..ready)
                .into_par_iter()
                .flat_map_iter(|kr| {
                    let kept = &kept;
                    (0..across).map(move |kc| {
                        let mut sum = [0u64; 256];
                        for r in kr.saturating_sub(REACH)..(kr + REACH + 1).min(down) {
                            let hists = &kept.1[r - kept.0];
                            for hist in
                                &hists[kc.saturating_sub(REACH)..(kc + REACH + 1).min(across)]
                            {
                                for (s, &v) in sum.iter_mut().zip(hist) {
                                    *s += v as u64;
                                }
                            }
                        }
                        otsu_threshold_of(&sum, MAX_DARK_FRACTION)
                    })
                })
                .collect();
            t.extend(more);
            // Keep the block rows the next thresholds still need.
            let keep_from = ready.saturating_sub(REACH).max(kept.0);
            kept.1.drain(..keep_from - kept.0);
            kept.0 = keep_from;
        }
        t.resize(across * down, None);
        Ok(Thresholds { across, down, t })
    }

    /// The blended threshold at cell `(col, row)`: bilinear over the four block centres around
    /// it, blocks without a threshold left out; `None` when none of them has one (or only ones
    /// of weight 0).
    fn at(&self, col: usize, row: usize) -> Option<f64> {
        let axis = |v: usize, n: usize| {
            let f = (v as f64 + 0.5) / BLOCK as f64 - 0.5;
            let k0 = (f.floor().max(0.0) as usize).min(n - 1);
            let k1 = (k0 + 1).min(n - 1);
            let u = (f - k0 as f64).clamp(0.0, 1.0);
            [(k0, 1.0 - u), (k1, u)]
        };
        let (xs, ys) = (axis(col, self.across), axis(row, self.down));
        let (mut sum, mut weight) = (0.0, 0.0);
        for (kr, wy) in ys {
            for (kc, wx) in xs {
                if let Some(t) = self.t[kr * self.across + kc] {
                    sum += wx * wy * t;
                    weight += wx * wy;
                }
            }
        }
        (weight > 0.0).then(|| sum / weight)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::crs::Crs;
    use crate::grid::Grid;
    use crate::ingest::resample::{resample_elevation, Resampling};
    use crate::raster::{Colour, Elevation};
    use crate::sample_scene::{generate, Building, SampleOptions};
    use crate::standing::{rasterise_prisms, Prism, RaisedCell};

    /// Grey of index `v` (a grey's shadow index is its value).
    fn grey(v: usize) -> [u8; 4] {
        [v as u8, v as u8, v as u8, 255]
    }

    #[test]
    fn shadow_is_found_under_light_roofs_and_nodata_and_raised_cells_never_are() {
        // 200 × 200: textured grass (85–95), a light unraised roof (165–175) over 30 % of the
        // grid, a shadow (38–42) of 20 × 20 cells, a raised dark roof and a nodata strip.
        let g = Grid::north_up(0.0, 200.0, 1.0, 200, 200, Crs::unknown());
        let shadow = |c: usize, r: usize| (20..40).contains(&c) && (20..40).contains(&r);
        let raised_roof = |c: usize, r: usize| (150..160).contains(&c) && (150..160).contains(&r);
        let data = (0..g.len())
            .map(|i| {
                let (c, r) = (i % 200, i / 200);
                match () {
                    _ if r >= 196 => [0, 0, 0, 0],
                    _ if shadow(c, r) => grey(38 + i % 5),
                    _ if raised_roof(c, r) => grey(30),
                    _ if c >= 140 => grey(165 + i % 11),
                    _ => grey(85 + i % 11),
                }
            })
            .collect();
        let colour = Colour::new(g.clone(), data);
        let roof = Raised::new(
            (0..g.len())
                .filter(|&i| raised_roof(i % 200, i / 200))
                .map(|index| RaisedCell {
                    index,
                    top_z: 9.0,
                    colour: None,
                    partial: false,
                })
                .collect(),
            &Elevation::filled(g.clone(), 0.0),
        );
        let found = detect(&colour, &roof, 0..usize::MAX).unwrap();
        for i in 0..g.len() {
            assert_eq!(found.get(i), shadow(i % 200, i / 200), "cell {i}");
        }
        // Nothing dark: nothing found.
        let lit = Colour::new(g.clone(), (0..g.len()).map(|i| grey(85 + i % 11)).collect());
        assert_eq!(
            detect(&lit, &Raised::default(), 0..usize::MAX)
                .unwrap()
                .count(),
            0
        );
    }

    /// Detected on some rows only (what a window of pages needs), the cells of those rows are
    /// the whole grid's detection, bit for bit, and no other cell is set: windows at the top,
    /// across block edges, one row, at the bottom.
    #[test]
    fn detection_on_rows_is_the_whole_detection_there() {
        let scene = generate(SampleOptions { seed: 2, size: 256 }).unwrap();
        let grid = scene.ortho.grid.clone();
        let t = resample_elevation(&scene.dem, &grid, Resampling::Bilinear);
        let prisms: Vec<Prism> = (scene.buildings.iter())
            .map(|b| Prism {
                rings: vec![b.footprint.iter().map(|p| (p[0], p[1])).collect()],
                roof: crate::roof::RoofShape::flat(b.roof_z),
            })
            .collect();
        let raised = Raised::new(rasterise_prisms(&grid, &prisms), &t);
        let whole = detect(&scene.ortho, &raised, 0..usize::MAX).unwrap();
        assert!(whole.count() > 1000, "the sample's photo has shadows");
        let w = grid.width;
        for rows in [0..64, 100..300, 200..201, 63..65, 450..grid.height] {
            let part = detect(&scene.ortho, &raised, rows.clone()).unwrap();
            for i in 0..grid.len() {
                let want = rows.contains(&(i / w)) && whole.get(i);
                assert_eq!(part.get(i), want, "rows {rows:?}, cell {i}");
            }
        }
    }

    /// On `dbms sample` scenes (seeds 1–3, 2048² cells of 0.25 m, the photo's shadows known
    /// exactly), the cells a different sun would compensate, against the photo's true shadows,
    /// with a database that lacks some buildings and has the others' heights off. Prints the
    /// table of docs/pyramid.md ("Which shadows are compensated"):
    /// `cargo test --release --lib compensation_on_the_sample -- --ignored --nocapture`.
    #[test]
    #[ignore]
    fn compensation_on_the_sample() {
        for seed in [1u64, 2, 3] {
            let scene = generate(SampleOptions { seed, size: 1024 }).unwrap();
            let grid = scene.ortho.grid.clone();
            let t = resample_elevation(&scene.dem, &grid, Resampling::Bilinear);
            let prism = |b: &Building, dz: f64| Prism {
                rings: vec![b.footprint.iter().map(|p| (p[0], p[1])).collect()],
                roof: crate::roof::RoofShape::flat(b.roof_z + dz),
            };
            let every: Vec<Prism> = scene.buildings.iter().map(|b| prism(b, 0.0)).collect();
            let roofs = Raised::new(rasterise_prisms(&grid, &every), &t);
            let truth = ShadowBits::cast(&t, &scene.sun, |s, row| roofs.lay_over(s, row)).unwrap();
            for (drop_every, dz) in [(0usize, 0.0), (4, 0.5), (3, 0.5), (2, 1.0)] {
                // Every `drop_every`-th building missing, the others `dz` metres too high or
                // too low, alternately.
                let db: Vec<Prism> = scene
                    .buildings
                    .iter()
                    .enumerate()
                    .filter(|(k, _)| drop_every == 0 || k % drop_every != 0)
                    .map(|(k, b)| prism(b, if k % 2 == 0 { dz } else { -dz }))
                    .collect();
                let raised = Raised::new(rasterise_prisms(&grid, &db), &t);
                let cast =
                    ShadowBits::cast(&t, &scene.sun, |s, row| raised.lay_over(s, row)).unwrap();
                let found = detect(&scene.ortho, &raised, 0..usize::MAX).unwrap();
                let th = Thresholds::compute(&scene.ortho, &raised, &(0..grid.height)).unwrap();
                let darkish = |i: usize| {
                    th.at(i % grid.width, i / grid.width)
                        .is_some_and(|t| shadow_index(scene.ortho.data[i]) < 1.5 * t)
                };
                let rules: [(&str, &dyn Fn(usize) -> bool); 3] = [
                    ("cast", &|i| cast.get(i)),
                    ("detected", &|i| found.get(i)),
                    ("detected or (cast and < 1.5 t)", &|i| {
                        found.get(i) || (cast.get(i) && darkish(i))
                    }),
                ];
                for (name, rule) in rules {
                    // Ground cells of the database (its raised roofs take the cast either way).
                    // Missed and wrongly compensated cells, and of those on missing roofs.
                    let (mut missed, mut wrong) = ([0, 0], [0, 0]);
                    for i in (0..grid.len()).filter(|&i| raised.get(i).is_none()) {
                        let on_roof = roofs.get(i).is_some() as usize;
                        match (truth.get(i), rule(i)) {
                            (true, false) => missed[on_roof] += 1,
                            (false, true) => wrong[on_roof] += 1,
                            _ => {}
                        }
                    }
                    println!(
                        "seed {seed} | {} of {} missing, ±{dz} m | {} | {name} | {} ({}) | {} ({})",
                        scene.buildings.len() - db.len(),
                        scene.buildings.len(),
                        truth.count(),
                        missed[0] + missed[1],
                        missed[1],
                        wrong[0] + wrong[1],
                        wrong[1],
                    );
                }
            }
        }
    }
}
