//! Seams: an inset's border blended into its parent's surface, so that the terrain has no crack
//! or step where the finer cells meet the coarser ones.
//!
//! The parent's surface is the bilinear interpolation of its elevation samples (one per cell
//! centre, the convention of [`crate::grid`]), evaluated at an inset cell's centre
//! ([`ParentSurface::at`]). Over a ring of [`ring_cells`]`(factor)` inset cells (one parent
//! cell) along each side of the inset that borders parent cells, the inset's elevation goes
//! linearly from that surface to its own: cell `d` cells in from the outer edge (0 = outermost)
//! becomes `p + (d / B) · (z − p)`, so the outermost cells lie on the parent's surface and cells
//! `B` or more in keep their own heights. A side on the parent's own edge has no neighbour to
//! meet and is not blended.
//!
//! Invariant: across the border the height changes by no more than the parent's own bilinear
//! surface does between the two cell centres. Nodata stays nodata: an inset cell without data
//! is not filled, and where every parent sample around an inset cell is nodata the inset keeps
//! its own height.

use super::InsetSpec;
use crate::grid::Grid;
use std::ops::Range;

/// Width of the blended ring, in inset cells, of an inset refining its parent by `factor`: one
/// parent cell, so the blend spans the same ground at every factor.
pub fn ring_cells(factor: usize) -> usize {
    factor
}

/// The parent's elevation around one inset: its window and one parent cell beyond it on each
/// side (clipped to the parent), enough for the bilinear surface at every inset cell centre.
#[derive(Debug, Clone)]
pub struct ParentSurface {
    spec: InsetSpec,
    /// Parent size in cells.
    parent_size: (usize, usize),
    /// Parent columns and rows held.
    cols: Range<usize>,
    rows: Range<usize>,
    /// Heights of those cells, metres, row-major over `cols`; NaN = nodata.
    z: Vec<f32>,
}

impl ParentSurface {
    /// The parent columns and rows the surface of `spec` over `parent` (its parent's grid)
    /// needs: the window and one cell around it, clipped to the parent.
    pub fn needs(spec: &InsetSpec, parent: &Grid) -> (Range<usize>, Range<usize>) {
        let w = &spec.window;
        (
            w.col0.saturating_sub(1)..(w.col1 + 1).min(parent.width),
            w.row0.saturating_sub(1)..(w.row1 + 1).min(parent.height),
        )
    }

    /// The surface from `rows`, the parent's elevation (metres, NaN = nodata) over the rows
    /// [`needs`](Self::needs) names, whole parent rows, row-major.
    pub fn new(spec: &InsetSpec, parent: &Grid, rows: &[f32]) -> ParentSurface {
        let (cols, rs) = Self::needs(spec, parent);
        assert_eq!(
            rows.len(),
            rs.len() * parent.width,
            "parent rows of the window"
        );
        let z = rows
            .chunks_exact(parent.width)
            .flat_map(|row| &row[cols.clone()])
            .copied()
            .collect();
        ParentSurface {
            spec: spec.clone(),
            parent_size: (parent.width, parent.height),
            cols,
            rows: rs,
            z,
        }
    }

    /// The parent's bilinear surface (metres) at the centre of inset cell `(col, row)`; nodata
    /// samples get no weight (the rest are renormalised); `None` when none has data.
    pub fn at(&self, col: usize, row: usize) -> Option<f64> {
        let f = self.spec.factor as f64;
        let w = &self.spec.window;
        // Parent centre space: 0.0 is the centre of parent cell 0.
        let u = w.col0 as f64 + (col as f64 + 0.5) / f - 0.5;
        let v = w.row0 as f64 + (row as f64 + 0.5) / f - 0.5;
        let taps = |p: f64, n: usize| {
            let i = p.floor();
            let t = p - i;
            let clamp = |k: f64| k.clamp(0.0, (n - 1) as f64) as usize;
            [(clamp(i), 1.0 - t), (clamp(i + 1.0), t)]
        };
        let (mut sum, mut weight) = (0.0, 0.0);
        for (r, wy) in taps(v, self.parent_size.1) {
            for (c, wx) in taps(u, self.parent_size.0) {
                let k = (r - self.rows.start) * self.cols.len() + (c - self.cols.start);
                let z = self.z[k];
                if !z.is_nan() && wx * wy > 0.0 {
                    sum += wx * wy * z as f64;
                    weight += wx * wy;
                }
            }
        }
        (weight > 0.0).then(|| sum / weight)
    }

    /// How many inset cells cell `(col, row)` lies in from the nearest side that borders parent
    /// cells (0 = outermost); `None` when no side does (the inset covers its whole parent).
    fn depth(&self, col: usize, row: usize) -> Option<usize> {
        let w = &self.spec.window;
        let f = self.spec.factor;
        let (pw, ph) = self.parent_size;
        let (iw, ih) = (w.width() * f, w.height() * f);
        [
            (w.col0 > 0).then_some(col),
            (w.row0 > 0).then_some(row),
            (w.col1 < pw).then(|| iw - 1 - col),
            (w.row1 < ph).then(|| ih - 1 - row),
        ]
        .into_iter()
        .flatten()
        .min()
    }

    /// Blend rows `rows` of the inset's elevation into the parent's surface: `z` holds those
    /// rows (metres, NaN = nodata, row-major, the inset's width). See the module docs.
    pub fn blend_rows(&self, rows: Range<usize>, z: &mut [f32]) {
        let width = self.spec.window.width() * self.spec.factor;
        let ring = ring_cells(self.spec.factor);
        assert_eq!(z.len(), rows.len() * width, "inset rows");
        for (row, cells) in rows.zip(z.chunks_exact_mut(width)) {
            for (col, cell) in cells.iter_mut().enumerate() {
                let Some(d) = self.depth(col, row).filter(|&d| d < ring) else {
                    continue;
                };
                if cell.is_nan() {
                    continue;
                }
                if let Some(p) = self.at(col, row) {
                    let w = d as f64 / ring as f64;
                    *cell = (p + w * (*cell as f64 - p)) as f32;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::crs::Crs;
    use crate::inset::CellWindow;

    const PW: usize = 24;
    const PH: usize = 20;

    /// A 10 m parent at UTM magnitudes: a tilted plane with a hill, and a few nodata cells.
    fn parent() -> (Grid, Vec<f32>) {
        let g = Grid::north_up(500_000.0, 5_000_000.0, 10.0, PW, PH, Crs::epsg(32632));
        let z = (0..PW * PH)
            .map(|i| {
                let (c, r) = ((i % PW) as f32, (i / PW) as f32);
                let hill = 30.0 * (-((c - 12.0).powi(2) + (r - 9.0).powi(2)) / 20.0).exp();
                200.0 + 0.8 * c - 1.3 * r + hill
            })
            .collect();
        (g, z)
    }

    fn spec(factor: usize) -> InsetSpec {
        InsetSpec {
            name: "town".into(),
            parent: None,
            factor,
            window: CellWindow {
                col0: 6,
                row0: 5,
                col1: 15,
                row1: 13,
            },
        }
    }

    /// The inset as ingested: the parent's surface raised 20 m with 1 m of ripple — what a finer
    /// DEM of another survey looks like against the coarse one.
    fn unblended(s: &InsetSpec, surf: &ParentSurface) -> Vec<f32> {
        let (w, h) = (s.window.width() * s.factor, s.window.height() * s.factor);
        (0..w * h)
            .map(|i| {
                let (c, r) = (i % w, i / w);
                (surf.at(c, r).unwrap() + 20.0 + ((c * 7 + r * 3) % 5) as f64 * 0.25) as f32
            })
            .collect()
    }

    /// The largest step between neighbouring parent samples along x and along y, per metre:
    /// the steepest the parent's bilinear surface gets along each axis.
    fn parent_slopes(z: &[f32]) -> (f64, f64) {
        let (mut sx, mut sy) = (0.0f64, 0.0f64);
        for r in 0..PH {
            for c in 0..PW {
                let here = z[r * PW + c] as f64;
                if c + 1 < PW {
                    sx = sx.max((z[r * PW + c + 1] as f64 - here).abs() / 10.0);
                }
                if r + 1 < PH {
                    sy = sy.max((z[(r + 1) * PW + c] as f64 - here).abs() / 10.0);
                }
            }
        }
        (sx, sy)
    }

    /// Every outermost inset cell next to a parent cell outside the window, with that parent
    /// cell: `(inset col, row, parent col, row)`.
    fn border_pairs(s: &InsetSpec) -> Vec<(usize, usize, usize, usize)> {
        let (w, h) = (s.window.width() * s.factor, s.window.height() * s.factor);
        let mut out = Vec::new();
        for r in 0..h {
            for c in 0..w {
                let (pc, pr) = s.parent_cell(c, r);
                if c == 0 {
                    out.push((c, r, pc - 1, pr));
                }
                if c == w - 1 {
                    out.push((c, r, pc + 1, pr));
                }
                if r == 0 {
                    out.push((c, r, pc, pr - 1));
                }
                if r == h - 1 {
                    out.push((c, r, pc, pr + 1));
                }
            }
        }
        out
    }

    /// The seam test of issue 19: the outermost inset cells lie on the parent's bilinear
    /// surface (< 1 mm), and the step from an outermost inset cell to the parent cell beyond
    /// it is no larger than the parent's own slope implies over that distance. The raw inset
    /// (5 m above) fails both, so the test can fail.
    #[test]
    fn the_border_meets_the_parent_without_a_step() {
        let (pg, pz) = parent();
        let (sx, sy) = parent_slopes(&pz);
        for factor in [2, 4, 10] {
            let s = spec(factor);
            let (cols, rows) = ParentSurface::needs(&s, &pg);
            assert_eq!((cols, rows.clone()), (5..16, 4..14));
            let surf = ParentSurface::new(&s, &pg, &pz[rows.start * PW..rows.end * PW]);
            let raw = unblended(&s, &surf);
            let mut z = raw.clone();
            let ig = s.grid(&pg);
            surf.blend_rows(0..ig.height, &mut z);
            let step_ok = |z: &[f32], (c, r, pc, pr): (usize, usize, usize, usize)| {
                let (ix, iy) = ig.cell_centre(c, r);
                let (px, py) = pg.cell_centre(pc, pr);
                let bound = (ix - px).abs() * sx + (iy - py).abs() * sy + 1e-3;
                (z[r * ig.width + c] as f64 - pz[pr * PW + pc] as f64).abs() <= bound
            };
            for &(c, r, pc, pr) in &border_pairs(&s) {
                let outer = z[r * ig.width + c] as f64;
                let p = surf.at(c, r).unwrap();
                assert!(
                    (outer - p).abs() < 1e-3,
                    "f{factor} ({c},{r}): {outer} vs {p}"
                );
                assert!(step_ok(&z, (c, r, pc, pr)), "f{factor} step at ({c},{r})");
                assert!(!step_ok(&raw, (c, r, pc, pr)), "raw inset has no step?");
            }
            // Beyond the ring the inset keeps its own heights; inside it, they go monotonically
            // from the parent to its own along a row.
            let ring = ring_cells(factor);
            let mid = ig.height / 2;
            for c in 0..ig.width {
                let (i, d) = (mid * ig.width + c, c.min(ig.width - 1 - c));
                if d >= ring {
                    assert_eq!(z[i], raw[i]);
                } else {
                    let want = surf.at(c, mid).unwrap()
                        + d as f64 / ring as f64 * (raw[i] as f64 - surf.at(c, mid).unwrap());
                    assert!((z[i] as f64 - want).abs() < 1e-3);
                }
            }
        }
    }

    /// The parent surface reproduces the parent's samples at their centres, and a plane
    /// exactly; blending by bands gives the same as blending whole.
    #[test]
    fn surface_is_the_parents_bilinear_and_bands_agree() {
        let g = Grid::north_up(500_000.0, 5_000_000.0, 10.0, PW, PH, Crs::epsg(32632));
        let plane: Vec<f32> = (0..PW * PH)
            .map(|i| 100.0 + 0.5 * (i % PW) as f32 - 0.25 * (i / PW) as f32)
            .collect();
        let s = spec(5);
        let (_, rows) = ParentSurface::needs(&s, &g);
        let surf = ParentSurface::new(&s, &g, &plane[rows.start * PW..rows.end * PW]);
        let ig = s.grid(&g);
        for (c, r) in [(0, 0), (2, 2), (17, 33), (ig.width - 1, ig.height - 1)] {
            let (x, y) = ig.cell_centre(c, r);
            let (u, v) = g.world_to_centre_space(x, y);
            let want = 100.0 + 0.5 * u - 0.25 * v;
            assert!((surf.at(c, r).unwrap() - want).abs() < 1e-9, "({c},{r})");
        }
        // Inset cell (2, 2) of factor 5 is the centre of parent cell (6, 5).
        assert!((surf.at(2, 2).unwrap() - plane[5 * PW + 6] as f64).abs() < 1e-9);
        let raw: Vec<f32> = (0..ig.len()).map(|i| (i % 97) as f32).collect();
        let mut whole = raw.clone();
        surf.blend_rows(0..ig.height, &mut whole);
        let mut banded = raw.clone();
        for band in (0..ig.height).step_by(7) {
            let rows = band..(band + 7).min(ig.height);
            surf.blend_rows(
                rows.clone(),
                &mut banded[rows.start * ig.width..rows.end * ig.width],
            );
        }
        assert_eq!(whole, banded);
    }

    /// Nodata: an inset cell without data stays without; parent nodata gets no weight; a side
    /// on the parent's own edge is not blended; an inset over its whole parent not at all.
    #[test]
    fn nodata_and_parent_edges() {
        let (pg, mut pz) = parent();
        let s = InsetSpec {
            window: CellWindow {
                col0: 0,
                row0: 0,
                col1: 4,
                row1: 3,
            },
            ..spec(2)
        };
        // Parent cell (4, 1), beside the window's east side, has no data.
        pz[PW + 4] = f32::NAN;
        let (_, rows) = ParentSurface::needs(&s, &pg);
        let surf = ParentSurface::new(&s, &pg, &pz[rows.start * PW..rows.end * PW]);
        let ig = s.grid(&pg);
        let mut z = vec![500.0f32; ig.len()];
        z[3 * ig.width + ig.width - 1] = f32::NAN;
        surf.blend_rows(0..ig.height, &mut z);
        assert!(z[3 * ig.width + ig.width - 1].is_nan());
        // West and north sides are the parent's edges: kept; east and south are blended.
        assert_eq!(z[2 * ig.width], 500.0);
        assert_eq!(z[2], 500.0);
        let east = z[2 * ig.width + ig.width - 1] as f64;
        assert!((east - surf.at(ig.width - 1, 2).unwrap()).abs() < 1e-3);
        assert!(surf.at(ig.width - 1, 2).unwrap().is_finite());
        let all = InsetSpec {
            window: CellWindow {
                col0: 0,
                row0: 0,
                col1: PW,
                row1: PH,
            },
            ..spec(2)
        };
        let surf = ParentSurface::new(&all, &pg, &pz);
        let mut z = vec![500.0f32; all.grid(&pg).len()];
        surf.blend_rows(0..PH * 2, &mut z);
        assert!(z.iter().all(|&v| v == 500.0));
    }
}
