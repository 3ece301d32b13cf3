//! Nested resolution insets: a finer grid over a window of its parent's cells.
//!
//! An inset ([`InsetSpec`]) refines a rectangle of its parent's cells — the base grid's or
//! another inset's — by an integer `factor` in 2..=10 on both axes: each parent cell becomes
//! `factor × factor` inset cells (10 m → 1 m → 0.1 m). Its grid ([`InsetSpec::grid`]) starts on
//! the parent's cell edge at the window's corner, with the parent's cell divided by the factor.
//!
//! Invariant: the relation between an inset cell and its parent cell is integer arithmetic
//! ([`InsetSpec::parent_cell`]), never a world-coordinate lookup; the inset grid's f64 origin
//! and cell are the parent's `origin + col0 · cell` and `cell / factor`, computed once, so inset
//! cell edges on a parent edge agree with it to f64 rounding (below 1e-9 m at UTM magnitudes).
//! Inset names are plain directory names; siblings (insets of one parent) never overlap.
//! [`check_new`] is the one check every new inset passes. [`seam`] blends an inset's border
//! into its parent's surface. [`corridor`] covers a buffered route with a chain of sibling
//! insets.

pub mod corridor;
pub mod seam;

use crate::error::{Error, Result};
use crate::grid::{Bounds, GeoTransform, Grid};
use serde::{Deserialize, Serialize};

/// The factors an inset may refine its parent's cells by.
pub const FACTORS: std::ops::RangeInclusive<usize> = 2..=10;

/// How far (in cells) a world edge may lie from a parent cell edge and still be on it:
/// 1e-6 of a cell (0.01 mm at 10 m cells), far above f64 noise and far below any real offset.
const EDGE_TOLERANCE_CELLS: f64 = 1e-6;

/// A rectangle of a parent grid's cells, half open: columns `col0..col1`, rows `row0..row1`
/// (row 0 is the parent's first, northernmost, row).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct CellWindow {
    /// First column (parent cells).
    pub col0: usize,
    /// First row (parent cells).
    pub row0: usize,
    /// One past the last column (parent cells).
    pub col1: usize,
    /// One past the last row (parent cells).
    pub row1: usize,
}

impl CellWindow {
    /// Number of parent columns (0 when empty).
    pub fn width(&self) -> usize {
        self.col1.saturating_sub(self.col0)
    }

    /// Number of parent rows (0 when empty).
    pub fn height(&self) -> usize {
        self.row1.saturating_sub(self.row0)
    }

    /// True when the window holds no cell.
    pub fn is_empty(&self) -> bool {
        self.width() == 0 || self.height() == 0
    }

    /// The cells both windows hold, or `None` when they share none.
    pub fn overlap(&self, other: &CellWindow) -> Option<CellWindow> {
        let w = CellWindow {
            col0: self.col0.max(other.col0),
            row0: self.row0.max(other.row0),
            col1: self.col1.min(other.col1),
            row1: self.row1.min(other.row1),
        };
        (!w.is_empty()).then_some(w)
    }
}

impl std::fmt::Display for CellWindow {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "columns {}..{}, rows {}..{}",
            self.col0, self.col1, self.row0, self.row1
        )
    }
}

/// One inset: its name, its parent, its refinement and where it lies in the parent.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct InsetSpec {
    /// Unique in the database; a plain directory name ([`check_name`]): the inset lives in
    /// `DB/insets/NAME/`.
    pub name: String,
    /// The inset it refines, or `None` for the base grid.
    pub parent: Option<String>,
    /// Parent cells per inset cell along each axis, in [`FACTORS`].
    pub factor: usize,
    /// The parent cells it covers.
    pub window: CellWindow,
}

impl InsetSpec {
    /// The inset's grid over `parent` (the parent's grid): `window.width() · factor` ×
    /// `window.height() · factor` cells of the parent's cell size / `factor` (CRS units), top-left
    /// corner on the parent's cell edge at `(col0, row0)`, the parent's CRS.
    pub fn grid(&self, parent: &Grid) -> Grid {
        let t = &parent.transform;
        let (x, y) = t.pixel_to_world(self.window.col0 as f64, self.window.row0 as f64);
        let f = self.factor as f64;
        Grid {
            width: self.window.width() * self.factor,
            height: self.window.height() * self.factor,
            transform: GeoTransform {
                origin_x: x,
                origin_y: y,
                cell_x: t.cell_x / f,
                cell_y: t.cell_y / f,
            },
            crs: parent.crs.clone(),
        }
    }

    /// The parent cell `(col, row)` that inset cell `(col, row)` lies in.
    pub fn parent_cell(&self, col: usize, row: usize) -> (usize, usize) {
        (
            self.window.col0 + col / self.factor,
            self.window.row0 + row / self.factor,
        )
    }

    /// The inset `name` of `parent_grid` (the grid of `parent`) over the world rectangle
    /// `bounds` (CRS units), whose edges must lie on the parent's cell edges and inside it.
    /// Errors say by how much an edge is off and give the bounds snapped outward as the fix,
    /// or give the part inside the parent.
    pub fn from_bounds(
        name: &str,
        parent: Option<&str>,
        factor: usize,
        bounds: &Bounds,
        parent_grid: &Grid,
    ) -> Result<InsetSpec> {
        let t = &parent_grid.transform;
        // Pixel-space positions of the four edges (rows grow southward when cell_y < 0).
        let px = |e| bounds_px(t, bounds, e);
        let (px0, px1) = (
            px(Edge::MinX).min(px(Edge::MaxX)),
            px(Edge::MinX).max(px(Edge::MaxX)),
        );
        let (py0, py1) = (
            px(Edge::MaxY).min(px(Edge::MinY)),
            px(Edge::MaxY).max(px(Edge::MinY)),
        );
        let shown = show_bounds(bounds);
        let (cx, cy) = parent_grid.cell_size();
        let mut off = Vec::new();
        for (label, p, cell) in [
            ("MINX", px(Edge::MinX), cx),
            ("MINY", px(Edge::MinY), cy),
            ("MAXX", px(Edge::MaxX), cx),
            ("MAXY", px(Edge::MaxY), cy),
        ] {
            let miss = p - p.round();
            if miss.abs() > EDGE_TOLERANCE_CELLS {
                off.push(format!("{label} by {} m", round_mm(miss.abs() * cell)));
            }
        }
        let snap = |p: f64, up: bool| -> f64 {
            if up {
                (p - EDGE_TOLERANCE_CELLS).ceil()
            } else {
                (p + EDGE_TOLERANCE_CELLS).floor()
            }
        };
        let (c0, r0, c1, r1) = (
            snap(px0, false),
            snap(py0, false),
            snap(px1, true),
            snap(py1, true),
        );
        let world = |c0: f64, r0: f64, c1: f64, r1: f64| {
            let (xa, ya) = t.pixel_to_world(c0, r0);
            let (xb, yb) = t.pixel_to_world(c1, r1);
            Bounds {
                min_x: xa.min(xb),
                min_y: ya.min(yb),
                max_x: xa.max(xb),
                max_y: ya.max(yb),
            }
        };
        if !off.is_empty() {
            let parent_name = parent.unwrap_or("the base grid");
            return Err(Error::msg(format!(
                "inset {name}: bounds {shown} are not on the cell edges of its parent ({parent_name}, {cx} x {cy} {} cells): {} off",
                parent_grid.crs.unit(),
                off.join(", ")
            ))
            .fix(format!(
                "give the bounds snapped outward to them: {}",
                show_bounds(&world(c0, r0, c1, r1))
            )));
        }
        let (w, h) = (parent_grid.width as f64, parent_grid.height as f64);
        if c0 < 0.0 || r0 < 0.0 || c1 > w || r1 > h {
            let parent_name = parent.unwrap_or("the base grid");
            let extent = show_bounds(&parent_grid.bounds());
            let inside = (c0.max(0.0) < c1.min(w) && r0.max(0.0) < r1.min(h))
                .then(|| show_bounds(&world(c0.max(0.0), r0.max(0.0), c1.min(w), r1.min(h))));
            return Err(Error::msg(format!(
                "inset {name}: bounds {shown} reach outside its parent ({parent_name}, extent {extent})"
            ))
            .fix(match inside {
                Some(b) => format!("give bounds inside the parent, e.g. the part that is: {b}"),
                None => "give bounds inside the parent's extent".to_string(),
            }));
        }
        Ok(InsetSpec {
            name: name.to_string(),
            parent: parent.map(str::to_string),
            factor,
            window: CellWindow {
                col0: c0 as usize,
                row0: r0 as usize,
                col1: c1 as usize,
                row1: r1 as usize,
            },
        })
    }
}

/// One edge of a [`Bounds`].
#[derive(Clone, Copy)]
enum Edge {
    MinX,
    MinY,
    MaxX,
    MaxY,
}

/// The pixel-space coordinate (column or row, fractional) of one edge of `b` under `t`.
fn bounds_px(t: &GeoTransform, b: &Bounds, edge: Edge) -> f64 {
    match edge {
        Edge::MinX => (b.min_x - t.origin_x) / t.cell_x,
        Edge::MaxX => (b.max_x - t.origin_x) / t.cell_x,
        Edge::MinY => (b.min_y - t.origin_y) / t.cell_y,
        Edge::MaxY => (b.max_y - t.origin_y) / t.cell_y,
    }
}

/// `v` rounded to the millimetre, for messages.
fn round_mm(v: f64) -> f64 {
    (v * 1000.0).round() / 1000.0
}

fn show_bounds(b: &Bounds) -> String {
    format!("{},{},{},{}", b.min_x, b.min_y, b.max_x, b.max_y)
}

/// An error unless `name` can name an inset: 1 to 64 ASCII letters, digits, `-` or `_`, not
/// starting with `-` (it becomes the directory `DB/insets/NAME/`).
pub fn check_name(name: &str) -> Result<()> {
    let ok = (1..=64).contains(&name.len())
        && !name.starts_with('-')
        && name
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'-' || b == b'_');
    if ok {
        return Ok(());
    }
    Err(
        Error::msg(format!("inset name {name:?} is not a plain name"))
            .fix("name it with 1 to 64 letters, digits, - or _ (not starting with -), e.g. town"),
    )
}

/// The factor of an inset as text: a whole number in [`FACTORS`].
pub fn parse_factor(name: &str, text: &str) -> Result<usize> {
    let f = text
        .trim()
        .parse::<usize>()
        .ok()
        .filter(|f| FACTORS.contains(f));
    f.ok_or_else(|| factor_error(name, text))
}

/// An error unless `factor` is in [`FACTORS`].
pub fn check_factor(name: &str, factor: usize) -> Result<()> {
    match FACTORS.contains(&factor) {
        true => Ok(()),
        false => Err(factor_error(name, &factor.to_string())),
    }
}

fn factor_error(name: &str, text: &str) -> Error {
    Error::msg(format!(
        "inset {name}: factor {text} is not a whole number from {} to {}",
        FACTORS.start(),
        FACTORS.end()
    ))
    .fix("give the parent cells per inset cell, e.g. 4 (10 m cells become 2.5 m); nest insets for more than 10")
}

/// `NAME:FACTOR:MINX,MINY,MAXX,MAXY` (the `--inset` option): the name, factor and world
/// bounds (CRS units) of an inset; the name and factor checked.
pub fn parse_inset_arg(arg: &str) -> Result<(String, usize, Bounds)> {
    let malformed = || {
        Error::msg(format!(
            "--inset {arg}: expected NAME:FACTOR:MINX,MINY,MAXX,MAXY"
        ))
        .fix("e.g. --inset town:4:500100,5000100,500300,5000300")
    };
    let mut parts = arg.splitn(3, ':');
    let (Some(name), Some(factor), Some(bounds)) = (parts.next(), parts.next(), parts.next())
    else {
        return Err(malformed());
    };
    check_name(name)?;
    let factor = parse_factor(name, factor)?;
    let bounds = Bounds::parse_option(&format!("--inset {name}:{factor}:"), bounds)?;
    Ok((name.to_string(), factor, bounds))
}

/// `NAME:FACTOR:BUFFER_M` (the `--corridor` option): the name, factor and buffer (metres, CRS
/// units, > 0) of a corridor; checked.
pub fn parse_corridor_arg(arg: &str) -> Result<(String, usize, f64)> {
    let malformed = || {
        Error::msg(format!("--corridor {arg}: expected NAME:FACTOR:BUFFER_M"))
            .fix("e.g. --corridor road:10:30 --route road.geojson")
    };
    let parts: Vec<&str> = arg.split(':').collect();
    let [name, factor, buffer] = parts[..] else {
        return Err(malformed());
    };
    check_name(name)?;
    let factor = parse_factor(name, factor)?;
    let buffer = buffer
        .trim()
        .parse::<f64>()
        .ok()
        .filter(|b| b.is_finite() && *b > 0.0)
        .ok_or_else(|| {
            Error::msg(format!(
                "--corridor {arg}: buffer {buffer} is not a distance above 0 in metres"
            ))
            .fix("e.g. --corridor road:10:30 for 30 m either side of the route")
        })?;
    Ok((name.to_string(), factor, buffer))
}

/// The window of `parent_grid` cells (the grid of inset `parent`, or the base) that covers the
/// route `lines` (vertices in CRS units) buffered by `buffer` CRS units on every side: the
/// buffered lines' bounding rectangle snapped outward to the parent's cells and clipped to the
/// parent. A diagonal route's bounding rectangle is mostly far from the route: corridors are
/// covered by [`corridor::corridor_cover`], which keeps this rectangle for comparison. An error
/// when the buffered route misses the parent.
pub fn corridor_window(
    name: &str,
    lines: &[Vec<(f64, f64)>],
    buffer: f64,
    parent_grid: &Grid,
) -> Result<CellWindow> {
    let points = || lines.iter().flatten();
    let (mut min_x, mut min_y) = (f64::INFINITY, f64::INFINITY);
    let (mut max_x, mut max_y) = (f64::NEG_INFINITY, f64::NEG_INFINITY);
    for &(x, y) in points() {
        (min_x, max_x) = (min_x.min(x), max_x.max(x));
        (min_y, max_y) = (min_y.min(y), max_y.max(y));
    }
    let t = &parent_grid.transform;
    let b = Bounds {
        min_x: min_x - buffer,
        min_y: min_y - buffer,
        max_x: max_x + buffer,
        max_y: max_y + buffer,
    };
    let (w, h) = (parent_grid.width as f64, parent_grid.height as f64);
    let (xa, xb) = (bounds_px(t, &b, Edge::MinX), bounds_px(t, &b, Edge::MaxX));
    let (ya, yb) = (bounds_px(t, &b, Edge::MaxY), bounds_px(t, &b, Edge::MinY));
    let c0 = (xa.min(xb) + EDGE_TOLERANCE_CELLS).floor().max(0.0);
    let c1 = (xa.max(xb) - EDGE_TOLERANCE_CELLS).ceil().min(w);
    let r0 = (ya.min(yb) + EDGE_TOLERANCE_CELLS).floor().max(0.0);
    let r1 = (ya.max(yb) - EDGE_TOLERANCE_CELLS).ceil().min(h);
    if !(c0 < c1 && r0 < r1) || points().next().is_none() {
        return Err(Error::msg(format!(
            "corridor {name}: the route buffered by {buffer} m, {}, misses its parent's extent {}",
            show_bounds(&b),
            show_bounds(&parent_grid.bounds())
        ))
        .fix("check that the route is in the database's CRS and crosses its area"));
    }
    Ok(CellWindow {
        col0: c0 as usize,
        row0: r0 as usize,
        col1: c1 as usize,
        row1: r1 as usize,
    })
}

/// The grid of the parent `parent` (`None`: the base grid `base`) among the database's
/// insets `all`; an error naming the insets there are when there is no such inset.
pub fn parent_grid(parent: Option<&str>, all: &[InsetSpec], base: &Grid) -> Result<Grid> {
    let Some(name) = parent else {
        return Ok(base.clone());
    };
    grid_of(name, all, base).map_err(|_| {
        let names: Vec<&str> = all.iter().map(|s| s.name.as_str()).collect();
        let have = match names.is_empty() {
            true => "it has none".to_string(),
            false => format!("it has {}", names.join(", ")),
        };
        Error::msg(format!(
            "inset parent {name} is not an inset of this database ({have})"
        ))
        .fix("give --inset-parent one of its insets, or leave it out to refine the base grid")
    })
}

/// The grid of inset `name` among `all` over the base grid `base`, through its chain of
/// parents. An error when `name`, or a parent on its chain, is not in `all` (or the chain loops).
pub fn grid_of(name: &str, all: &[InsetSpec], base: &Grid) -> Result<Grid> {
    let mut chain = Vec::new();
    let mut at = Some(name);
    while let Some(n) = at {
        let spec = all.iter().find(|s| s.name == n).ok_or_else(|| {
            Error::msg(format!("inset {n} is not an inset of this database"))
                .fix("re-create the database's insets with `dbms ingest --inset`")
        })?;
        if chain.len() > all.len() {
            return Err(Error::msg(format!("inset {name}: its parents form a loop"))
                .fix("re-create the database's insets with `dbms ingest --inset`"));
        }
        chain.push(spec);
        at = spec.parent.as_deref();
    }
    Ok(chain.iter().rev().fold(base.clone(), |g, s| s.grid(&g)))
}

/// Check that `spec` can join a database over the base grid `base` whose insets are
/// `existing`: a new name, a known parent, a factor in [`FACTORS`], a non-empty window inside
/// the parent, no overlap with a sibling. Returns the inset's grid.
pub fn check_new(spec: &InsetSpec, existing: &[InsetSpec], base: &Grid) -> Result<Grid> {
    let name = &spec.name;
    check_name(name)?;
    if existing.iter().any(|s| s.name == *name) {
        return Err(
            Error::msg(format!("inset {name} already exists in this database")).fix(
                "give the new inset another name (re-ingest the base with --overwrite to start all over)",
            ),
        );
    }
    check_factor(name, spec.factor)?;
    let parent = parent_grid(spec.parent.as_deref(), existing, base)?;
    let parent_name = spec.parent.as_deref().unwrap_or("the base grid");
    let w = &spec.window;
    if w.is_empty() {
        return Err(Error::msg(format!(
            "inset {name}: its window ({w}) holds no parent cell"
        ))
        .fix("give bounds at least one parent cell wide and high"));
    }
    if w.col1 > parent.width || w.row1 > parent.height {
        return Err(Error::msg(format!(
            "inset {name}: its window ({w}) reaches outside its parent ({parent_name}, {} x {} cells)",
            parent.width, parent.height
        ))
        .fix("give a window inside the parent"));
    }
    for sib in existing.iter().filter(|s| s.parent == spec.parent) {
        if let Some(o) = w.overlap(&sib.window) {
            let b = show_bounds(&spec_world(&parent, &o));
            return Err(Error::msg(format!(
                "inset {name} overlaps inset {} (both refine {parent_name}) over {b}",
                sib.name
            ))
            .fix(format!(
                "move or shrink it off {0}, or nest it inside {0} with --inset-parent {0}",
                sib.name
            )));
        }
    }
    Ok(spec.grid(&parent))
}

/// The world rectangle of window `w` of `grid`.
fn spec_world(grid: &Grid, w: &CellWindow) -> Bounds {
    grid.window_grid(&crate::grid::Window {
        col: w.col0,
        row: w.row0,
        width: w.width(),
        height: w.height(),
    })
    .bounds()
}

#[cfg(test)]
mod tests;
