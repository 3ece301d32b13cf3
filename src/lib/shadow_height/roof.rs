//! Does a roof look pitched? Its faces, lit by the sun at different angles, show the photo
//! areas of different brightness; a flat roof is one brightness with texture.
//!
//! Why it matters: the refinement extrudes the footprint to a *flat* roof. Over a gable or hip
//! roof whose pitch is below the sun's elevation, the far face is lit and the shadow's tip comes
//! from the eaves (POV-Ray scenes: 3 m roofs came back exactly 3 m low, at the eaves, with
//! every check agreeing); over a steeper one it comes from the ridge in places. Neither is the
//! ridge height the truth asks for, and nothing in the shadow tells them apart, so the roof's
//! appearance is the evidence: a pitched-looking roof is flagged.
//!
//! Invariant: the roof cells are the cells whose centre is inside the footprint and at least a
//! cell from its outline (no mixed edge cells). The roof looks pitched when Otsu's split of their
//! luminance gives two classes of at least [`MIN_FACE`] of the cells each, the darker mean below
//! [`MAX_FACE_RATIO`] of the brighter, and the classes are *faces*, not texture: at least
//! [`MIN_COHERENCE`] of the 4-neighbour pairs of roof cells are of the same class; and the
//! dark class lies *away from the sun* (its centroid beyond the bright one's, along the
//! shadows): a face is darker because it tilts away from the sun, while a taller neighbour's
//! shadow darkens the side of a flat roof toward the sun, where the neighbour stands.

use super::footprint::Footprint;
use crate::raster::RowBand;
use crate::shadow::detect::{index_bin, otsu_split, otsu_threshold_of};

/// Each face class must hold at least this fraction of the roof cells.
pub const MIN_FACE: f64 = 0.15;
/// The darker face's mean luminance must be below this fraction of the brighter's.
pub const MAX_FACE_RATIO: f64 = 0.85;
/// Fraction of 4-neighbour pairs of roof cells in the same class for the classes to be faces.
pub const MIN_COHERENCE: f64 = 0.85;
/// Fewest roof cells the test is made on (a smaller roof is not judged).
pub const MIN_CELLS: usize = 24;

/// Whether a roof looks pitched in `colour` (see the module doc) under a sun `toward_sun` (unit
/// vector, east and north); `inner` are its roof cells ([`inner_cells`]), as indices of
/// `colour`'s grid.
pub fn looks_pitched(colour: &RowBand<[u8; 4]>, inner: &[usize], toward_sun: (f64, f64)) -> bool {
    let grid = &colour.grid;
    let w = grid.width;
    if inner.len() < MIN_CELLS {
        return false;
    }
    let y = |i: usize| {
        let p = *colour.at(i);
        0.299 * p[0] as f64 + 0.587 * p[1] as f64 + 0.114 * p[2] as f64
    };
    let mut hist = [0u64; 256];
    for &i in inner {
        hist[index_bin(y(i))] += 1;
    }
    // Otsu's split without the shadow-specific retry: the dark class may be most of the roof.
    let Some(t) = otsu_threshold_of(&hist, 1.0)
        .or_else(|| otsu_split(&hist).map(|(split, _, _)| split as f64 + 0.5))
    else {
        return false;
    };
    let dark: Vec<bool> = inner.iter().map(|&i| y(i) < t).collect();
    let n_dark = dark.iter().filter(|&&d| d).count();
    let frac = n_dark as f64 / inner.len() as f64;
    if !(MIN_FACE..=1.0 - MIN_FACE).contains(&frac) {
        return false;
    }
    let mean = |want: bool| {
        let v: Vec<f64> = inner
            .iter()
            .zip(&dark)
            .filter(|(_, &d)| d == want)
            .map(|(&i, _)| y(i))
            .collect();
        v.iter().sum::<f64>() / v.len() as f64
    };
    if mean(true) >= MAX_FACE_RATIO * mean(false) {
        return false;
    }
    let class: std::collections::HashMap<usize, bool> =
        inner.iter().copied().zip(dark.iter().copied()).collect();
    let (mut same, mut pairs) = (0usize, 0usize);
    for (&i, &d) in &class {
        for j in [i + 1, i + w] {
            if let Some(&e) = class.get(&j) {
                pairs += 1;
                same += (d == e) as usize;
            }
        }
    }
    let faces = pairs > 0 && same as f64 >= MIN_COHERENCE * pairs as f64;
    let centroid = |want: bool| {
        let (mut x, mut y, mut n) = (0.0, 0.0, 0.0);
        for (&i, _) in inner.iter().zip(&dark).filter(|(_, &d)| d == want) {
            let p = grid.cell_centre(i % w, i / w);
            (x, y, n) = (x + p.0, y + p.1, n + 1.0);
        }
        (x / n, y / n)
    };
    let (d, b) = (centroid(true), centroid(false));
    faces && (d.0 - b.0) * toward_sun.0 + (d.1 - b.1) * toward_sun.1 < 0.0
}

/// The roof cells of `fp` among its own `cells` (indices of `colour`'s grid): opaque in the
/// photo and at least a cell from the outline (module docs).
pub fn inner_cells(fp: &Footprint, colour: &RowBand<[u8; 4]>, cells: &[usize]) -> Vec<usize> {
    let grid = &colour.grid;
    let (cx, cy) = grid.cell_size();
    let cell = cx.max(cy);
    let w = grid.width;
    cells
        .iter()
        .copied()
        .filter(|&i| {
            let p = grid.cell_centre(i % w, i / w);
            colour.at(i)[3] != 0 && distance2_to_outline(fp, p) >= cell * cell
        })
        .collect()
}

/// Squared distance (square metres) from `p` to the nearest edge of `fp`.
fn distance2_to_outline(fp: &Footprint, p: (f64, f64)) -> f64 {
    fp.edges()
        .map(|(a, b)| {
            let (ex, ey) = (b.0 - a.0, b.1 - a.1);
            let l2 = ex * ex + ey * ey;
            let s = if l2 == 0.0 {
                0.0
            } else {
                (((p.0 - a.0) * ex + (p.1 - a.1) * ey) / l2).clamp(0.0, 1.0)
            };
            let (dx, dy) = (p.0 - a.0 - s * ex, p.1 - a.1 - s * ey);
            dx * dx + dy * dy
        })
        .fold(f64::INFINITY, f64::min)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::crs::Crs;
    use crate::grid::Grid;
    use crate::raster::Colour;
    use crate::raster::Raster;

    /// A 12 × 8 m roof at x 10..22, y 10..18 on 0.5 m cells; `value(x, y)` its brightness.
    fn roof(value: impl Fn(f64, f64, usize) -> u8) -> (Footprint, Colour, Vec<usize>) {
        let g = Grid::north_up(0.0, 30.0, 0.5, 60, 60, Crs::epsg(32632));
        let fp = Footprint::new(vec![vec![vec![
            (10.0, 10.0),
            (22.0, 10.0),
            (22.0, 18.0),
            (10.0, 18.0),
        ]]])
        .unwrap();
        let mut cells = Vec::new();
        let data = (0..g.len())
            .map(|i| {
                let (x, y) = g.cell_centre(i % 60, i / 60);
                let inside = (10.0..22.0).contains(&x) && (10.0..18.0).contains(&y);
                if inside {
                    cells.push(i);
                }
                let v = if inside { value(x, y, i) } else { 90 };
                [v, v, v, 255]
            })
            .collect();
        (fp, Raster::new(g, data), cells)
    }

    #[test]
    fn a_gable_looks_pitched_a_flat_textured_roof_does_not() {
        let noise = |i: usize| ((i * 7919) % 17) as u8;
        let (fp, c, cells) = roof(|_, y, i| if y < 14.0 { 170 } else { 120 } + noise(i));
        assert!(looks(&fp, &c, &cells, SOUTH));
        let (fp, c, cells) = roof(|_, _, i| 130 + 3 * noise(i));
        assert!(
            !looks(&fp, &c, &cells, SOUTH),
            "speckled texture is not faces"
        );
        let (fp, c, cells) = roof(|_, _, i| 150 + noise(i) / 2);
        assert!(!looks(&fp, &c, &cells, SOUTH));
    }

    /// [`looks_pitched`] over the inner cells of `fp` (own cells `cells`) in `c`.
    fn looks(fp: &Footprint, c: &Colour, cells: &[usize], toward_sun: (f64, f64)) -> bool {
        let band = RowBand::whole(c);
        looks_pitched(&band, &inner_cells(fp, &band, cells), toward_sun)
    }

    /// Toward a sun in the south.
    const SOUTH: (f64, f64) = (0.0, -1.0);

    #[test]
    fn a_neighbours_shadow_on_a_flat_roofs_sunny_side_is_not_a_face() {
        // The southern third dark under a sun from the south: a taller neighbour south of it
        // shades it there. Under a sun from the north the same picture is a face turned away.
        let noise = |i: usize| ((i * 7919) % 17) as u8;
        let (fp, c, cells) = roof(|_, y, i| if y < 13.0 { 100 } else { 170 } + noise(i));
        assert!(!looks(&fp, &c, &cells, SOUTH));
        assert!(looks(&fp, &c, &cells, (0.0, 1.0)));
    }

    #[test]
    fn a_hip_roof_with_the_sun_along_its_ridge_looks_pitched() {
        // The two long faces alike; the sun-facing hip end bright, the far one dark.
        let (fp, c, cells) = roof(|x, _, _| {
            if x < 14.0 {
                190
            } else if x > 18.0 {
                90
            } else {
                140
            }
        });
        assert!(looks(&fp, &c, &cells, (-1.0, 0.0)));
    }
}
