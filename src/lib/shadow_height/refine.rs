//! Refinement over the real terrain (the Hughes patent's loop): extrude the footprint to a
//! trial height over the DEM, cast its shadow with the shared caster, compare with the observed
//! shadow, and keep the height whose shadow overlaps the observed one best.
//!
//! Invariant: the observed shadow is the corridor's shadow cells connected to the footprint
//! (shadow beyond lit ground belongs to something else); the score of a trial height is the
//! IoU of synthetic and that observed shadow over the
//! usable open-ground cells (class [`Class::Lit`] / [`Class::Shadow`]) of the *corridor*, the
//! synthetic shadow at the highest trial height (a prism's shadow only grows with its height, so
//! the corridor holds every trial's shadow). The search is a coarse grid over `[0, z_hi]`, then a
//! fine grid around the coarse best; the answer is the middle of the run of fine heights that
//! share the best score (the score is piecewise constant: the middle of the plateau is the
//! unbiased choice).

use super::local::{Class, Local};
use crate::error::Result;
use crate::raster::Raster;
use crate::shadow::{cast_shadows_reference, cast_shadows_slice, Sun, SHADOW};
use rayon::prelude::*;

/// Coarse samples over `[0, z_hi]`.
const COARSE: usize = 24;
/// At most this many fine samples.
const MAX_FINE: usize = 96;
/// Shadows up to this many cells long (at the highest trial) are cast with exact rays.
const EXACT_MAX_CELLS: f64 = 64.0;

/// The refined height above `ground_z` (metres) and its IoU with the observed shadow.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Refined {
    /// Height above `ground_z`, metres.
    pub height_m: f64,
    /// IoU of synthetic and observed shadow at that height, in [0, 1].
    pub overlap: f64,
}

/// Search heights in `[0, z_hi]` metres above `ground_z` (absolute metres) for the footprint's
/// [`Class::Own`] cells in `local`. `fine_step` is the smallest height step worth resolving,
/// metres (a quarter of a cell's worth of shadow length is a good choice). Only cells with
/// `keep[i]` can be in the corridor (the caller drops the bands of scan lines that met other
/// buildings or disagreed with the median length).
pub fn refine(
    local: &Local,
    keep: &[bool],
    sun: &Sun,
    ground_z: f64,
    z_hi: f64,
    fine_step: f64,
) -> Result<Refined> {
    // Short shadows (few cells: a high sun) are cast with exact rays: there one cell of the
    // sweep's digital-line approximation is metres of height. Long ones use the O(n) sweep.
    let (cx, cy) = local.grid.cell_size();
    let exact = z_hi / (sun.elevation_deg.to_radians().tan() * cx.max(cy)) <= EXACT_MAX_CELLS;
    let cast_at = |roof_z: f64| cast_at(local, sun, roof_z, exact);
    let corridor: Vec<bool> = cast_at(ground_z + z_hi)?
        .iter()
        .zip(&local.class)
        .zip(keep)
        .map(|((&m, &c), &k)| k && m == SHADOW && matches!(c, Class::Lit | Class::Shadow))
        .collect();
    let observed = attached_shadow(local, &corridor);
    let score = |z: f64| -> Result<f64> {
        let mask = cast_at(ground_z + z)?;
        let (mut inter, mut union) = (0usize, 0usize);
        for i in 0..mask.len() {
            if corridor[i] {
                let (s, o) = (mask[i] == SHADOW, observed[i]);
                inter += (s && o) as usize;
                union += (s || o) as usize;
            }
        }
        Ok(if union == 0 {
            0.0
        } else {
            inter as f64 / union as f64
        })
    };
    let coarse: Vec<f64> = (0..=COARSE)
        .map(|i| z_hi * i as f64 / COARSE as f64)
        .collect();
    let scores = coarse
        .par_iter()
        .map(|&z| score(z))
        .collect::<Result<Vec<f64>>>()?;
    let best = first_max(&scores);
    // The fine grid spans the whole coarse plateau of the best score, one sample beyond each end.
    let mut last = best;
    while last < COARSE && scores[last + 1] >= scores[best] {
        last += 1;
    }
    let (lo, hi) = (
        coarse[best.saturating_sub(1)],
        coarse[(last + 1).min(COARSE)],
    );
    let step = fine_step.max((hi - lo) / MAX_FINE as f64);
    let n = ((hi - lo) / step).ceil() as usize;
    let fine: Vec<f64> = (0..=n).map(|i| (lo + i as f64 * step).min(hi)).collect();
    let fine_scores = fine
        .par_iter()
        .map(|&z| score(z))
        .collect::<Result<Vec<f64>>>()?;
    let b = first_max(&fine_scores);
    let top = fine_scores[b];
    let mut e = b;
    while e + 1 < fine.len() && fine_scores[e + 1] >= top {
        e += 1;
    }
    Ok(Refined {
        height_m: (fine[b] + fine[e]) / 2.0,
        overlap: top,
    })
}

/// The observed shadow this footprint casts: the corridor's [`Class::Shadow`] cells connected
/// (8-neighbours, through corridor shadow cells) to the footprint's own cells. Shadow further
/// along the corridor beyond lit ground is someone else's (a neighbour's, a tree's) and would
/// pull the search toward a height whose shadow reaches it.
fn attached_shadow(local: &Local, corridor: &[bool]) -> Vec<bool> {
    let (w, h) = (local.grid.width, local.grid.height);
    let neighbours = |i: usize| {
        let (c, r) = ((i % w) as i64, (i / w) as i64);
        (-1i64..=1)
            .flat_map(move |dr| (-1i64..=1).map(move |dc| (c + dc, r + dr)))
            .filter(move |&(x, y)| x >= 0 && y >= 0 && x < w as i64 && y < h as i64)
            .map(move |(x, y)| y as usize * w + x as usize)
    };
    let open = |i: usize| corridor[i] && local.class[i] == Class::Shadow;
    let mut seen = vec![false; corridor.len()];
    let mut stack: Vec<usize> = (0..corridor.len())
        .filter(|&i| open(i) && neighbours(i).any(|j| local.class[j] == Class::Own))
        .collect();
    for &i in &stack {
        seen[i] = true;
    }
    while let Some(i) = stack.pop() {
        for j in neighbours(i) {
            if !seen[j] && open(j) {
                seen[j] = true;
                stack.push(j);
            }
        }
    }
    seen
}

/// The caster's mask of `local`'s terrain with the footprint's own cells raised to `roof_z`:
/// the exact ray-marching reference or the sweep.
fn cast_at(local: &Local, sun: &Sun, roof_z: f64, exact: bool) -> Result<Vec<u8>> {
    let heights: Vec<f32> = local
        .heights
        .iter()
        .zip(&local.class)
        .map(|(&h, &c)| if c == Class::Own { roof_z as f32 } else { h })
        .collect();
    if exact {
        Ok(cast_shadows_reference(&Raster::new(local.grid.clone(), heights), sun)?.data)
    } else {
        cast_shadows_slice(&heights, &local.grid, sun)
    }
}

fn first_max(v: &[f64]) -> usize {
    (0..v.len()).fold(0, |b, i| if v[i] > v[b] { i } else { b })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::crs::Crs;
    use crate::grid::{Grid, Window};

    #[test]
    fn recovers_the_height_whose_shadow_was_observed() {
        // Flat ground at 100 m, 1 m cells, a 6 × 6 m roof; sun from the south at 45°: a 6.5 m
        // building (the middle of the heights that shadow the same 6 cells) casts 6 cells of shadow.
        let g = Grid::north_up(0.0, 40.0, 1.0, 40, 40, Crs::epsg(32632));
        let w = Window {
            col: 0,
            row: 0,
            width: 40,
            height: 40,
        };
        let sun = Sun::new(45.0, 180.0).unwrap();
        let mut class = vec![Class::Lit; 1600];
        for r in 0..40usize {
            for c in 0..40usize {
                let (x, y) = g.cell_centre(c, r);
                if (10.0..16.0).contains(&x) && (10.0..16.0).contains(&y) {
                    class[r * 40 + c] = Class::Own;
                }
            }
        }
        let mut l = Local {
            win: w,
            grid: g.window_grid(&w),
            class,
            heights: vec![100.0; 1600],
        };
        let observed = cast_at(&l, &sun, 106.5, true).unwrap();
        for (c, m) in l.class.iter_mut().zip(&observed) {
            if *c == Class::Lit && *m == SHADOW {
                *c = Class::Shadow;
            }
        }
        let r = refine(&l, &[true; 1600], &sun, 100.0, 20.0, 0.25).unwrap();
        assert!((r.height_m - 6.5).abs() <= 0.1, "{r:?}");
        assert_eq!(r.overlap, 1.0);
    }

    #[test]
    fn first_max_takes_the_earliest_of_equal_maxima() {
        assert_eq!(first_max(&[0.1, 0.5, 0.5, 0.2]), 1);
        assert_eq!(first_max(&[0.0]), 0);
    }
}
