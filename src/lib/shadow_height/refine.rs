//! Refinement over the real terrain (the Hughes patent's loop): extrude the footprint to a
//! trial height over the DEM, cast its shadow, compare with the observed shadow, and keep the
//! height whose shadow overlaps the observed one best.
//!
//! Invariant: the synthetic shadow is cast with exact rays from every usable open-ground cell
//! centre toward the sun over the real terrain, against the footprint *polygon* (not its
//! raster): a ray from a cell centre at terrain height `z` first meets the footprint's walls
//! `t` metres away, so the cell is in the shadow of a roof at `ground_z + Z` exactly when
//! `Z > z + t·tan(elevation) − ground_z`, that cell's *threshold*. (Cells the bare terrain
//! shadows are unusable, so nothing else blocks the ray.) A prism's shadow only grows with its
//! height; the *corridor* is the kept cells with a threshold up to `z_hi`. The observed shadow is
//! the corridor's shadow cells connected to the footprint (shadow beyond lit ground belongs to
//! something else). The score of `Z` is the IoU of synthetic and observed shadow over the
//! corridor; it changes only at thresholds, so every height in `[0, z_hi]` is scored by one
//! sweep over the sorted thresholds, and the answer is the middle of the best interval (the
//! unbiased choice). Exact polygons make the answer finer than a cell of shadow length, which
//! matters most where a cell of shadow is metres of height (high sun, coarse cells).

use super::footprint::Footprint;
use super::local::{Class, Local};

/// The refined height above `ground_z` (metres) and its IoU with the observed shadow.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Refined {
    /// Height above `ground_z`, metres.
    pub height_m: f64,
    /// IoU of synthetic and observed shadow at that height, in [0, 1].
    pub overlap: f64,
}

/// Search heights in `(0, z_hi]` metres above `ground_z` (absolute metres) for footprint `fp`,
/// whose cells are [`Class::Own`] in `local`. `u` is the unit shadow direction (east, north),
/// `tan_e` the tangent of the sun elevation. Only cells with `keep[i]` can be in the corridor
/// (the caller drops the bands of scan lines that met other buildings or disagreed with the
/// median length). `None` when the corridor holds no observed shadow.
pub fn refine(
    local: &Local,
    fp: &Footprint,
    keep: &[bool],
    u: (f64, f64),
    tan_e: f64,
    ground_z: f64,
    z_hi: f64,
) -> Option<Refined> {
    let w = local.grid.width;
    let toward_sun = (-u.0, -u.1);
    let threshold: Vec<f64> = (0..local.class.len())
        .map(|i| {
            if !keep[i] || !matches!(local.class[i], Class::Lit | Class::Shadow) {
                return f64::NAN;
            }
            let p = local.grid.cell_centre(i % w, i / w);
            first_wall(fp, p, toward_sun)
                .map_or(f64::NAN, |t| local.heights[i] as f64 + t * tan_e - ground_z)
        })
        .collect();
    let corridor: Vec<bool> = threshold.iter().map(|&h| h <= z_hi).collect();
    let observed = attached_shadow(local, &corridor);
    let mut cells: Vec<(f64, bool)> = (0..corridor.len())
        .filter(|&i| corridor[i])
        .map(|i| (threshold[i].max(0.0), observed[i]))
        .collect();
    cells.sort_by(|a, b| a.0.total_cmp(&b.0));
    best_interval(&cells, z_hi)
}

/// The best IoU over `Z` in `(0, z_hi]` for cells `(threshold, observed)` sorted by threshold,
/// a cell being in the synthetic shadow when `Z > threshold`: the middle of the first interval
/// reaching it.
fn best_interval(cells: &[(f64, bool)], z_hi: f64) -> Option<Refined> {
    let n_obs = cells.iter().filter(|c| c.1).count();
    if n_obs == 0 {
        return None;
    }
    let (mut inter, mut extra) = (0usize, 0usize);
    let mut best: Option<(f64, usize)> = None; // (IoU, index of the interval's first cell past it)
    for k in 0..cells.len() {
        inter += cells[k].1 as usize;
        extra += !cells[k].1 as usize;
        // Only between distinct thresholds: Z just above cells[k].0 and up to the next one.
        if k + 1 < cells.len() && cells[k + 1].0 == cells[k].0 {
            continue;
        }
        let iou = inter as f64 / (n_obs + extra) as f64;
        if best.is_none_or(|b| iou > b.0) {
            best = Some((iou, k + 1));
        }
    }
    let (overlap, next) = best?;
    let lo = cells[next - 1].0;
    let hi = cells.get(next).map_or(z_hi, |c| c.0).max(lo);
    Some(Refined {
        height_m: (lo + hi) / 2.0,
        overlap,
    })
}

/// Distance (metres) from `p` along the unit vector `d` to the first edge of the footprint,
/// `None` when the ray misses it.
fn first_wall(fp: &Footprint, p: (f64, f64), d: (f64, f64)) -> Option<f64> {
    let cross = |a: (f64, f64), b: (f64, f64)| a.0 * b.1 - a.1 * b.0;
    fp.edges()
        .filter_map(|(a, b)| {
            let e = (b.0 - a.0, b.1 - a.1);
            let den = cross(d, e);
            if den == 0.0 {
                return None;
            }
            let ap = (a.0 - p.0, a.1 - p.1);
            let (t, s) = (cross(ap, e) / den, cross(ap, d) / den);
            (t >= 0.0 && (0.0..=1.0).contains(&s)).then_some(t)
        })
        .min_by(f64::total_cmp)
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::crs::Crs;
    use crate::grid::{Grid, Window};
    use crate::raster::Raster;
    use crate::shadow::{cast_shadows_reference, Sun, SHADOW};

    /// 40 × 40 m of 1 m cells on flat ground at 100 m with a 6 × 6 m footprint at x, y 10..16,
    /// its shadow observed as a photo would show it for a roof at `roof_z` and `sun`: cast by the
    /// shared caster on a grid 8 × 8 finer, a cell in shadow when most of it is.
    fn scene(sun: &Sun, roof_z: f32) -> (Local, Footprint) {
        let g = Grid::north_up(0.0, 40.0, 1.0, 40, 40, Crs::epsg(32632));
        let w = Window {
            col: 0,
            row: 0,
            width: 40,
            height: 40,
        };
        let fp = Footprint::new(vec![vec![vec![
            (10.0, 10.0),
            (16.0, 10.0),
            (16.0, 16.0),
            (10.0, 16.0),
        ]]])
        .unwrap();
        let inside = |(x, y): (f64, f64)| (10.0..16.0).contains(&x) && (10.0..16.0).contains(&y);
        let fine = Grid::north_up(0.0, 40.0, 0.125, 320, 320, Crs::epsg(32632));
        let raised: Vec<f32> = (0..fine.len())
            .map(|i| match inside(fine.cell_centre(i % 320, i / 320)) {
                true => roof_z,
                false => 100.0,
            })
            .collect();
        let cast = cast_shadows_reference(&Raster::new(fine, raised), sun).unwrap();
        let class = (0..1600)
            .map(|i| {
                let (c, r) = (i % 40, i / 40);
                let dark = (0..64)
                    .filter(|k| cast.data[(r * 8 + k / 8) * 320 + c * 8 + k % 8] == SHADOW)
                    .count();
                match (inside(g.cell_centre(c, r)), dark > 32) {
                    (true, _) => Class::Own,
                    (false, true) => Class::Shadow,
                    (false, false) => Class::Lit,
                }
            })
            .collect();
        let local = Local {
            win: w,
            grid: g.window_grid(&w),
            class,
            heights: vec![100.0; 1600],
        };
        (local, fp)
    }

    #[test]
    fn recovers_the_height_whose_shadow_the_shared_caster_cast() {
        // Sun from the south at 45°: a 6.5 m roof's shadow covers most of the 6 cells north of
        // the wall; every height in (5.5, 6.5] shadows those cell centres: the answer is 6 ± 0.5.
        let sun = Sun::new(45.0, 180.0).unwrap();
        let (l, fp) = scene(&sun, 106.5);
        let r = refine(&l, &fp, &[true; 1600], (0.0, 1.0), 1.0, 100.0, 20.0).unwrap();
        assert!((r.height_m - 6.0).abs() <= 0.5, "{r:?}");
        assert_eq!(r.overlap, 1.0);
    }

    #[test]
    fn hard_case_oblique_sun_resolves_less_than_a_cell_of_shadow() {
        // Sun from the south-south-east at 60°: cells along the wall see it at many distances,
        // so the best interval is much narrower than one cell of shadow (1.73 m of height).
        let sun = Sun::new(60.0, 160.0).unwrap();
        let (dx, dy) = sun.direction();
        let tan_e = 60f64.to_radians().tan();
        let (l, fp) = scene(&sun, 109.0);
        let r = refine(&l, &fp, &[true; 1600], (-dx, -dy), tan_e, 100.0, 30.0).unwrap();
        assert!((r.height_m - 9.0).abs() <= 0.5, "{r:?}");
    }

    #[test]
    fn no_observed_shadow_is_no_refinement() {
        let sun = Sun::new(45.0, 180.0).unwrap();
        let (mut l, fp) = scene(&sun, 106.5);
        l.class
            .iter_mut()
            .filter(|c| **c == Class::Shadow)
            .for_each(|c| *c = Class::Lit);
        assert_eq!(
            refine(&l, &fp, &[true; 1600], (0.0, 1.0), 1.0, 100.0, 20.0),
            None
        );
    }

    #[test]
    fn best_interval_takes_the_middle_of_the_first_best_and_ignores_ties_inside_it() {
        // Thresholds 1 (observed), 2 (observed), 2 (not), 3 (not): IoU 0.5 above 1, 2/3 above 2
        // (both cells at 2 at once), 0.5 above 3.
        let c = [(1.0, true), (2.0, true), (2.0, false), (3.0, false)];
        let r = best_interval(&c, 10.0).unwrap();
        assert_eq!((r.height_m, r.overlap), (2.5, 2.0 / 3.0));
        // The best interval running to the top ends at z_hi.
        assert_eq!(best_interval(&[(1.0, true)], 3.0).unwrap().height_m, 2.0);
    }

    #[test]
    fn first_wall_is_the_nearest_edge_along_the_ray() {
        let fp = Footprint::new(vec![vec![vec![
            (0.0, 0.0),
            (4.0, 0.0),
            (4.0, 4.0),
            (0.0, 4.0),
        ]]])
        .unwrap();
        assert_eq!(first_wall(&fp, (2.0, 7.0), (0.0, -1.0)), Some(3.0));
        assert_eq!(first_wall(&fp, (9.0, 7.0), (0.0, -1.0)), None);
    }
}
