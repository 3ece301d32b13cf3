//! Corridors: a chain of sibling insets that covers a buffered route tightly.
//!
//! The parent grid is cut into square blocks of [`block_cells`] parent cells a side, counted
//! from the parent's corner (the last column and row of blocks clipped to the parent). A block
//! is *marked* when the route comes within `buffer` of it: the exact distance between each
//! route segment and the block's rectangle (CRS units), with a slack of 1e-6 cell for f64 noise.
//! Every parent cell whose area comes within `buffer` of the route lies in a marked block, so
//! the marked blocks cover the buffered route. They are merged into rectangles: the marked
//! blocks of each block row into runs of consecutive blocks, and runs with the same columns in
//! consecutive block rows into one rectangle. Each block lies in exactly one rectangle, so the
//! rectangles never overlap; ordered north to south (by first row), then west to east, they
//! become the windows of the insets `NAME-1`, `NAME-2`, ….
//!
//! The bounding rectangle of the buffered route ([`super::corridor_window`]) is kept for
//! comparison: a diagonal route's chain covers a small part of it.

use super::{corridor_window, show_bounds, CellWindow, InsetSpec, EDGE_TOLERANCE_CELLS};
use crate::error::{Error, Result};
use crate::grid::Grid;
use serde::Serialize;
use std::collections::{BTreeMap, BTreeSet};

/// The smallest block side, in parent cells.
pub const MIN_BLOCK_CELLS: usize = 8;

/// The block side (parent cells) for a corridor buffered by `buffer` CRS units over a parent of
/// `cell` CRS units (the smaller side of a non-square cell): the smallest power of two at least
/// `buffer / cell`, and at least [`MIN_BLOCK_CELLS`]. A block about as wide as the buffer makes
/// the corridor 2–4 blocks across, so the cover reaches at most about one block beyond the
/// buffer on either side; smaller blocks would cover a little less ground with many more, smaller
/// insets (each a database of its own, with a seam along every side).
pub fn block_cells(buffer: f64, cell: f64) -> usize {
    let cells = (buffer / cell).ceil();
    if !(cells.is_finite() && cells >= 1.0) {
        return MIN_BLOCK_CELLS;
    }
    let cells = cells.min((1u64 << 40) as f64) as usize;
    cells.next_power_of_two().max(MIN_BLOCK_CELLS)
}

/// The windows of a corridor's chain of insets in its parent, and what they cover.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct CorridorCover {
    /// Block side in parent cells ([`block_cells`]).
    pub block_cells: usize,
    /// The insets' windows, north to south then west to east; no two overlap.
    pub windows: Vec<CellWindow>,
    /// The buffered route's bounding rectangle of parent cells, clipped to the parent
    /// ([`super::corridor_window`]): what a single rectangular corridor would cover.
    pub bounding: CellWindow,
}

impl CorridorCover {
    /// Parent cells the windows cover.
    pub fn cells(&self) -> u64 {
        self.windows.iter().map(area).sum()
    }

    /// Parent cells of the bounding rectangle.
    pub fn bounding_cells(&self) -> u64 {
        area(&self.bounding)
    }

    /// [`cells`](Self::cells) over [`bounding_cells`](Self::bounding_cells).
    pub fn area_ratio(&self) -> f64 {
        self.cells() as f64 / self.bounding_cells() as f64
    }

    /// The chain's insets: `NAME-1`, `NAME-2`, … over the windows in order, refining `parent`
    /// by `factor`. An error when the names are not plain ([`super::check_name`]).
    pub fn specs(&self, name: &str, parent: Option<&str>, factor: usize) -> Result<Vec<InsetSpec>> {
        self.windows
            .iter()
            .enumerate()
            .map(|(k, w)| {
                let name = member_name(name, k);
                super::check_name(&name)?;
                Ok(InsetSpec {
                    name,
                    parent: parent.map(str::to_string),
                    factor,
                    window: *w,
                })
            })
            .collect()
    }
}

/// The name of the `k`-th (from 0) inset of corridor `name`: `NAME-{k+1}`.
pub fn member_name(name: &str, k: usize) -> String {
    format!("{name}-{}", k + 1)
}

fn area(w: &CellWindow) -> u64 {
    w.width() as u64 * w.height() as u64
}

/// The cover of `parent_grid` (the grid of the corridor's parent) for corridor `name`: the route
/// `lines` (vertices in CRS units) buffered by `buffer` CRS units (module docs). An error when
/// the buffer is not above 0 or the buffered route misses the parent.
pub fn corridor_cover(
    name: &str,
    lines: &[Vec<(f64, f64)>],
    buffer: f64,
    parent_grid: &Grid,
) -> Result<CorridorCover> {
    if !(buffer.is_finite() && buffer > 0.0) {
        return Err(Error::msg(format!(
            "corridor {name}: buffer {buffer} m is not a distance above 0"
        ))
        .fix("give the metres either side of the route, e.g. --corridor road:10:30"));
    }
    let bounding = corridor_window(name, lines, buffer, parent_grid)?;
    let t = &parent_grid.transform;
    let (cx, cy) = (t.cell_x.abs(), t.cell_y.abs());
    let block = block_cells(buffer, cx.min(cy));
    // Metres east and south of the parent's corner (rows grow southward when cell_y < 0).
    let local = |&(x, y): &(f64, f64)| {
        (
            (x - t.origin_x) * t.cell_x.signum(),
            (y - t.origin_y) * t.cell_y.signum(),
        )
    };
    let (w, h) = (parent_grid.width, parent_grid.height);
    let (size_x, size_y) = (w as f64 * cx, h as f64 * cy);
    let (bw, bh) = (block as f64 * cx, block as f64 * cy);
    let (blocks_x, blocks_y) = (w.div_ceil(block), h.div_ceil(block));
    let slack = EDGE_TOLERANCE_CELLS * cx.min(cy);
    let reach = buffer + slack;
    let rect = |bc: usize, br: usize| Rect {
        x0: bc as f64 * bw,
        y0: br as f64 * bh,
        x1: ((bc + 1) as f64 * bw).min(size_x),
        y1: ((br + 1) as f64 * bh).min(size_y),
    };
    // The blocks of `range` (CRS units along an axis of block side `side`), clipped to `n`.
    let blocks = |lo: f64, hi: f64, side: f64, n: usize| {
        let first = (lo / side).floor().max(0.0);
        let last = (hi / side).floor().min(n as f64 - 1.0);
        (first as usize)..(last as usize + 1).max(first as usize)
    };
    let mut marked: BTreeMap<usize, BTreeSet<usize>> = BTreeMap::new();
    for line in lines {
        let pts: Vec<(f64, f64)> = line.iter().map(local).collect();
        let segments: Vec<((f64, f64), (f64, f64))> = match pts.len() {
            0 => Vec::new(),
            1 => vec![(pts[0], pts[0])],
            _ => pts.windows(2).map(|p| (p[0], p[1])).collect(),
        };
        for (a, b) in segments {
            let (ylo, yhi) = (a.1.min(b.1), a.1.max(b.1));
            if yhi + reach < 0.0 || ylo - reach > size_y {
                continue;
            }
            for br in blocks(ylo - reach, yhi + reach, bh, blocks_y) {
                let band = rect(0, br);
                // The part of the segment within `reach` of the block row, and its x extent.
                let Some((xa, xb)) = x_extent_in_band(a, b, band.y0 - reach, band.y1 + reach)
                else {
                    continue;
                };
                if xb + reach < 0.0 || xa - reach > size_x {
                    continue;
                }
                for bc in blocks(xa - reach, xb + reach, bw, blocks_x) {
                    if rect(bc, br).distance_to_segment(a, b) <= reach {
                        marked.entry(br).or_default().insert(bc);
                    }
                }
            }
        }
    }
    if marked.is_empty() {
        // The bounding rectangle reached the parent but no block is within the buffer (a route
        // passing a corner of the parent diagonally): as corridor_window's error.
        return Err(Error::msg(format!(
            "corridor {name}: the route buffered by {buffer} m misses its parent's extent {}",
            show_bounds(&parent_grid.bounds())
        ))
        .fix("check that the route is in the database's CRS and crosses its area"));
    }
    let windows = merge(&marked)
        .into_iter()
        .map(|[c0, r0, c1, r1]| CellWindow {
            col0: c0 * block,
            row0: r0 * block,
            col1: (c1 * block).min(w),
            row1: (r1 * block).min(h),
        })
        .collect();
    Ok(CorridorCover {
        block_cells: block,
        windows,
        bounding,
    })
}

/// The rectangles `[col0, row0, col1, row1]` (blocks, half open) the marked blocks merge into
/// (module docs), ordered by first row, then first column.
fn merge(marked: &BTreeMap<usize, BTreeSet<usize>>) -> Vec<[usize; 4]> {
    let mut done = Vec::new();
    let mut open: Vec<[usize; 4]> = Vec::new();
    for (&br, cols) in marked {
        let mut runs: Vec<(usize, usize)> = Vec::new();
        for &c in cols {
            match runs.last_mut() {
                Some(run) if run.1 == c => run.1 = c + 1,
                _ => runs.push((c, c + 1)),
            }
        }
        let mut next = Vec::with_capacity(runs.len());
        for (c0, c1) in runs {
            let same = open
                .iter()
                .position(|o| o[0] == c0 && o[2] == c1 && o[3] == br);
            match same {
                Some(i) => {
                    let mut o = open.swap_remove(i);
                    o[3] = br + 1;
                    next.push(o);
                }
                None => next.push([c0, br, c1, br + 1]),
            }
        }
        done.append(&mut open);
        open = next;
    }
    done.append(&mut open);
    done.sort_by_key(|r| (r[1], r[0]));
    done
}

/// The x extent of the part of segment `a`–`b` with y in `y0..=y1`, or `None` when there is none.
fn x_extent_in_band(a: (f64, f64), b: (f64, f64), y0: f64, y1: f64) -> Option<(f64, f64)> {
    let (t0, t1) = clip_axis(a.1, b.1 - a.1, y0, y1, 0.0, 1.0)?;
    let (xa, xb) = (a.0 + t0 * (b.0 - a.0), a.0 + t1 * (b.0 - a.0));
    Some((xa.min(xb), xa.max(xb)))
}

/// Liang–Barsky along one axis: the parameters `t` in `t0..=t1` where `p + t·d` lies in
/// `lo..=hi`, or `None` when none does.
fn clip_axis(p: f64, d: f64, lo: f64, hi: f64, t0: f64, t1: f64) -> Option<(f64, f64)> {
    if d == 0.0 {
        return (lo <= p && p <= hi).then_some((t0, t1));
    }
    let (ta, tb) = ((lo - p) / d, (hi - p) / d);
    let (t0, t1) = (t0.max(ta.min(tb)), t1.min(ta.max(tb)));
    (t0 <= t1).then_some((t0, t1))
}

/// An axis-aligned rectangle, `x0 ≤ x1`, `y0 ≤ y1`.
#[derive(Debug, Clone, Copy)]
struct Rect {
    x0: f64,
    y0: f64,
    x1: f64,
    y1: f64,
}

impl Rect {
    /// Distance from `p` to the rectangle (0 inside).
    fn distance_to_point(&self, p: (f64, f64)) -> f64 {
        let dx = (self.x0 - p.0).max(p.0 - self.x1).max(0.0);
        let dy = (self.y0 - p.1).max(p.1 - self.y1).max(0.0);
        dx.hypot(dy)
    }

    /// Distance from segment `a`–`b` to the rectangle: 0 when they meet, else the least of the
    /// endpoints' distances to the rectangle and the corners' distances to the segment (two
    /// disjoint convex polygons are closest at a vertex of one of them).
    fn distance_to_segment(&self, a: (f64, f64), b: (f64, f64)) -> f64 {
        let (dx, dy) = (b.0 - a.0, b.1 - a.1);
        let meets = clip_axis(a.0, dx, self.x0, self.x1, 0.0, 1.0)
            .and_then(|(t0, t1)| clip_axis(a.1, dy, self.y0, self.y1, t0, t1))
            .is_some();
        if meets {
            return 0.0;
        }
        let corners = [
            (self.x0, self.y0),
            (self.x1, self.y0),
            (self.x0, self.y1),
            (self.x1, self.y1),
        ];
        corners
            .iter()
            .map(|&c| point_segment_distance(c, a, b))
            .chain([self.distance_to_point(a), self.distance_to_point(b)])
            .fold(f64::INFINITY, f64::min)
    }
}

/// Distance from `p` to segment `a`–`b`.
pub(crate) fn point_segment_distance(p: (f64, f64), a: (f64, f64), b: (f64, f64)) -> f64 {
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    let len2 = dx * dx + dy * dy;
    let t = match len2 > 0.0 {
        true => (((p.0 - a.0) * dx + (p.1 - a.1) * dy) / len2).clamp(0.0, 1.0),
        false => 0.0,
    };
    (p.0 - (a.0 + t * dx)).hypot(p.1 - (a.1 + t * dy))
}
