//! Shadow length along the sun azimuth, over parallel scan lines.
//!
//! Invariant: scan lines run along the shadow direction `u` (away from the sun), spaced
//! `spacing` apart across the footprint (half a cell by default), keeping one cell clear of
//! its two extreme tangents (where the raster edge is ragged). Each line starts where it last
//! leaves the polygon (its sun-far edge) and walks the cells it crosses ([`crate::walk`],
//! through corners diagonally); cells its own roof covers in part ([`Class::Edge`]) do not end
//! it; it ends, valid, at the first lit cell. A line is dropped ("cut") when it leaves the
//! window or its shadow ends in or within a cell of unusable cells (passing through them, e.g.
//! under another building's shadow, it goes on), and dropped as meeting another footprint when
//! it enters one or its shadow ends on a lit cell touching one (or with one within a cell
//! further along): that cell may read lit only because the other building's sunlit roof covers
//! part of it. Another footprint's roof read shaded ([`Class::Crossed`], only in a crossing scan)
//! is walked through like the shadow on the ground: the shadow lies on it. For a prism on flat ground every valid line's length is exactly
//! `H / tan(elevation)`, whatever the footprint's shape, so the median over lines is a robust
//! length.

use super::footprint::Footprint;
use super::local::{Class, Local};
use crate::grid::Grid;
use crate::walk::{Corner, Walk};

/// What the scan lines of one footprint found.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Scan {
    /// Lines cast across the footprint.
    pub lines: usize,
    /// Shadow length of each valid line, metres (0 when the line met lit ground at once).
    pub lengths: Vec<f64>,
    /// Per valid line, the roof height the line implies over the real terrain: terrain at the
    /// shadow's tip + length · tan(elevation), metres (NaN where the tip has no terrain height).
    pub tip_roofs: Vec<f64>,
    /// Per valid line, its offset across the shadow direction from [`Scan::origin`], metres
    /// (along `n = (−u.north, u.east)`).
    pub line_t: Vec<f64>,
    /// The point the offsets are measured from (world, metres): the footprint's bounding-box centre.
    pub origin: (f64, f64),
    /// Valid lines that crossed at least one shadow cell.
    pub with_shadow: usize,
    /// Lines, valid or dropped, that crossed another footprint's shaded roof
    /// ([`Class::Crossed`]): the shadow lay on another building.
    pub crossed: usize,
    /// Lines dropped: shadow left the window or ended in or next to unusable cells.
    pub cut: usize,
    /// Lines dropped: shadow reached another footprint or ended on a lit cell against one.
    pub on_other: usize,
    /// Per dropped line that crossed this footprint's shadow before it was dropped (before any
    /// unusable cell), the lowest roof that shadow implies over the real terrain: terrain at
    /// the last shadow cell it crossed + the distance to where it entered that cell · tan(e),
    /// metres. The shadow reached at least that far, so the roof is at least that high.
    pub reached_roofs: Vec<f64>,
    /// Whether a line read a cell on the window's border or went past it: in a larger window
    /// the lines could read differently (the caller classified a part of the window it may need).
    pub at_window_edge: bool,
}

/// Scan the footprint's shadow in `local`. `u` is the unit shadow direction (east, north),
/// `cell` the cell size, `spacing` the distance between lines and `max_len` the longest shadow
/// sought, metres; `tan_e` = tan(elevation).
pub fn scan(
    fp: &Footprint,
    local: &Local,
    u: (f64, f64),
    cell: f64,
    spacing: f64,
    max_len: f64,
    tan_e: f64,
) -> Scan {
    let frame = Frame::new(fp, u);
    let ts = frame.line_offsets(fp, cell, spacing);
    let mut out = Scan {
        lines: ts.len(),
        origin: frame.o,
        ..Scan::default()
    };
    let lines = ShadowWalk {
        local,
        u,
        cell,
        max_len,
        tan_e,
    };
    for t in ts {
        let exit = frame.last_exit(fp, t);
        if !exit.is_finite() {
            out.lines -= 1;
            continue;
        }
        let mut crossed = false;
        let end = lines.follow(frame.point(exit, t), &mut out.at_window_edge, &mut crossed);
        out.crossed += crossed as usize;
        match end {
            LineEnd::Cut { reached } => {
                out.cut += 1;
                out.reached_roofs.extend(reached);
            }
            LineEnd::OnOther { reached } => {
                out.on_other += 1;
                out.reached_roofs.extend(reached);
            }
            LineEnd::Valid {
                length,
                tip_roof,
                seen_shadow,
            } => {
                out.lengths.push(length);
                out.line_t.push(t);
                out.tip_roofs.push(tip_roof);
                out.with_shadow += seen_shadow as usize;
            }
        }
    }
    out
}

/// The first open cell each scan line of `fp` reads past its sun-far edge, as [`scan`] casts
/// the lines (`u`, `cell`, `spacing`) over the cells of `grid` (a window's) whose classes are
/// `base` (row-major; `None`: open ground, lit or shadow not decided yet): where the line
/// leaves the footprint and the cells it covers in part ([`Class::Own`], [`Class::Edge`]).
/// Lines that read anything else first, or leave the window, give none. Window indices.
///
/// Any building casts a shadow from its walls: at the elevations shadows are measured at,
/// these cells are in it, whatever else is.
pub fn first_open_cells(
    fp: &Footprint,
    grid: &Grid,
    base: &[Option<Class>],
    u: (f64, f64),
    cell: f64,
    spacing: f64,
) -> Vec<usize> {
    let frame = Frame::new(fp, u);
    frame
        .line_offsets(fp, cell, spacing)
        .into_iter()
        .filter_map(|t| {
            let exit = frame.last_exit(fp, t);
            if !exit.is_finite() {
                return None;
            }
            cells_along(grid, frame.point(exit, t), u)
                .map(|(_, _, at)| at.map(|(c, r)| (r * grid.width + c, base[r * grid.width + c])))
                .find(|at| !matches!(at, Some((_, Some(Class::Own | Class::Edge)))))?
                .and_then(|(i, class)| class.is_none().then_some(i))
        })
        .collect()
}

/// Where the scan lines run: positions as metres along the shadow direction `u` and across it
/// (along `n = (−u.north, u.east)`), from the footprint's bounding-box centre `o`.
struct Frame {
    /// The origin, world metres ([`Scan::origin`]).
    o: (f64, f64),
    /// The unit shadow direction (east, north).
    u: (f64, f64),
    /// The unit direction across the shadow, `(−u.north, u.east)`.
    n: (f64, f64),
}

impl Frame {
    /// The frame of footprint `fp`'s lines along the unit shadow direction `u`.
    fn new(fp: &Footprint, u: (f64, f64)) -> Frame {
        Frame {
            o: fp.bbox_centre(),
            u,
            n: (-u.1, u.0),
        }
    }

    /// World point `p` (metres) as metres along `u` and across (along `n`) from the origin.
    fn proj(&self, p: (f64, f64)) -> (f64, f64) {
        let (o, u, n) = (self.o, self.u, self.n);
        let d = (p.0 - o.0, p.1 - o.1);
        (d.0 * u.0 + d.1 * u.1, d.0 * n.0 + d.1 * n.1)
    }

    /// The world point `s` metres along `u` and `t` across from the origin.
    fn point(&self, s: f64, t: f64) -> (f64, f64) {
        let (o, u, n) = (self.o, self.u, self.n);
        (o.0 + s * u.0 + t * n.0, o.1 + s * u.1 + t * n.1)
    }

    /// The lines' offsets across the shadow (along `n`), metres: every `spacing` from one
    /// `cell` inside `fp`'s lower extreme tangent while a `cell` or more inside the upper; the
    /// middle line alone when `fp` is too narrow for that.
    fn line_offsets(&self, fp: &Footprint, cell: f64, spacing: f64) -> Vec<f64> {
        let (t_min, t_max) =
            fp.rings
                .iter()
                .flatten()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, z), &p| {
                    let t = self.proj(p).1;
                    (a.min(t), z.max(t))
                });
        if t_max - t_min > 2.0 * cell + spacing {
            let k = ((t_max - t_min - 2.0 * cell) / spacing).floor() as usize;
            (0..=k).map(|i| t_min + cell + i as f64 * spacing).collect()
        } else {
            vec![(t_min + t_max) / 2.0]
        }
    }

    /// Where the line `t` metres across leaves `fp` last, metres along `u`: the largest of its
    /// edge crossings (−∞ when it crosses none).
    fn last_exit(&self, fp: &Footprint, t: f64) -> f64 {
        fp.edges()
            .filter_map(|(a, b)| {
                let ((sa, ta), (sb, tb)) = (self.proj(a), self.proj(b));
                ((ta <= t) != (tb <= t)).then(|| sa + (t - ta) / (tb - ta) * (sb - sa))
            })
            .fold(f64::NEG_INFINITY, f64::max)
    }
}

/// How one scan line ended (the module's invariant). A dropped line carries the lowest roof
/// the shadow it crossed implies ([`Scan::reached_roofs`]), if it crossed any.
enum LineEnd {
    /// Dropped: the shadow left the window or the longest shadow sought, or ended in or within
    /// a cell of unusable cells.
    Cut { reached: Option<f64> },
    /// Dropped: the shadow reached another footprint or ended on a lit cell against one.
    OnOther { reached: Option<f64> },
    /// Valid: the shadow's length and the roof it implies over the real terrain (terrain at
    /// the tip + length · tan e; NaN where the tip has no terrain height), metres, and whether
    /// the line crossed a shadow cell.
    Valid {
        length: f64,
        tip_roof: f64,
        seen_shadow: bool,
    },
}

/// What every scan line of one footprint walks: the cells of `local` along the unit shadow
/// direction `u` (east, north), with the cell size and the longest shadow sought (metres) and
/// tan(elevation).
struct ShadowWalk<'a> {
    local: &'a Local,
    u: (f64, f64),
    cell: f64,
    max_len: f64,
    tan_e: f64,
}

impl ShadowWalk<'_> {
    /// Walk the line from `start` (world metres, where it leaves the footprint) to its end.
    /// Sets `at_window_edge` when it reads a cell on the window's border or past it
    /// ([`Scan::at_window_edge`]), and `crossed` when it walks over another footprint's shaded
    /// roof ([`Scan::crossed`]).
    fn follow(&self, start: (f64, f64), at_window_edge: &mut bool, crossed: &mut bool) -> LineEnd {
        let (local, cell) = (self.local, self.cell);
        let mut seen_shadow = false;
        // Where the line last left unusable cells (metres along it): a shadow ending within a
        // cell of them has an unknown end; one merely passing through them goes on.
        let mut unusable_until = f64::NEG_INFINITY;
        // Where the line last left its own footprint's cells or edge cells, metres.
        let mut roof_until = 0.0f64;
        // The lowest roof the shadow crossed so far implies (before any unusable cell).
        let mut reached: Option<f64> = None;
        let mut walk = cells_along(&local.grid, start, self.u);
        loop {
            let (x, x_out, cell_at) = walk.next().expect("a walk along a unit vector never ends");
            // Past the longest shadow sought beyond the footprint and its edge cells (a line
            // grazing an oblique edge may cross several).
            if x > roof_until + self.max_len + cell {
                return LineEnd::Cut { reached };
            }
            *at_window_edge |= on_border(local, cell_at);
            let class = cell_at.map(|(c, r)| {
                let i = r * local.grid.width + c;
                (i, local.class[i])
            });
            match class {
                None => return LineEnd::Cut { reached },
                Some((_, Class::Unusable)) => unusable_until = x_out,
                Some((_, Class::Other)) => return LineEnd::OnOther { reached },
                // The own roof, or a cell it covers in part: not yet the shadow's end.
                Some((_, Class::Own | Class::Edge)) => roof_until = x_out,
                // Shadow on the ground, or on a roof it crosses (the ray is above the roof, so
                // above the ground under it: a lower bound still).
                Some((i, class @ (Class::Shadow | Class::Crossed))) => {
                    seen_shadow = true;
                    *crossed |= class == Class::Crossed;
                    if unusable_until == f64::NEG_INFINITY {
                        reached = Some(local.heights[i] as f64 + x * self.tan_e)
                            .filter(|z| z.is_finite());
                    }
                }
                Some((i, Class::Lit)) => {
                    return if x - unusable_until < cell {
                        LineEnd::Cut { reached }
                    } else if meets_other(
                        local,
                        cell_at.unwrap(),
                        &mut walk,
                        x + cell,
                        at_window_edge,
                    ) {
                        LineEnd::OnOther { reached }
                    } else {
                        LineEnd::Valid {
                            length: x,
                            tip_roof: local.heights[i] as f64 + x * self.tan_e,
                            seen_shadow,
                        }
                    };
                }
            }
        }
    }
}

/// Whether the lit cell `at` ending a line's shadow is within a cell of another footprint: one
/// of its 8 neighbours is [`Class::Other`] or [`Class::Crossed`], or the line enters such a
/// cell before `until` metres. That cell may read lit only because the other building's
/// sunlit roof covers part of it; the shadow met the building there rather than ending (and
/// one ending right past a roof it crossed may have ended on the roof's far edge). Sets `at_edge` when a cell
/// read is on the window's border or past it ([`Scan::at_window_edge`]).
fn meets_other(
    local: &Local,
    at: (usize, usize),
    walk: &mut impl Iterator<Item = (f64, f64, Option<(usize, usize)>)>,
    until: f64,
    at_edge: &mut bool,
) -> bool {
    let (w, h) = (local.grid.width, local.grid.height);
    let (c, r) = at;
    let near = (r.saturating_sub(1)..=(r + 1).min(h - 1))
        .flat_map(|rr| (c.saturating_sub(1)..=(c + 1).min(w - 1)).map(move |cc| rr * w + cc))
        .any(|i| other(local.class[i]));
    near || walk.take_while(|&(x, _, _)| x <= until).any(|(_, _, a)| {
        *at_edge |= on_border(local, a);
        a.is_some_and(|(c, r)| other(local.class[r * w + c]))
    })
}

/// Whether a cell is under another footprint.
fn other(class: Class) -> bool {
    matches!(class, Class::Other | Class::Crossed)
}

/// Whether a cell a line reads (`None`: outside the window) is on the border of `local`'s
/// window or outside it, where a larger window would show more.
fn on_border(local: &Local, at: Option<(usize, usize)>) -> bool {
    let (w, h) = (local.grid.width, local.grid.height);
    at.is_none_or(|(c, r)| c == 0 || r == 0 || c + 1 == w || r + 1 == h)
}

/// The cells of `grid` (a window's) a scan line from `start` (world metres) along the unit vector `u` crosses
/// ([`Corner::Diagonal`]: a line through a cell corner steps into the diagonal cell, the side
/// cells touch it at a point only): the metres at which it enters and leaves each, and the
/// cell (`None` once outside the window).
fn cells_along(
    grid: &Grid,
    start: (f64, f64),
    u: (f64, f64),
) -> impl Iterator<Item = (f64, f64, Option<(usize, usize)>)> {
    let tr = &grid.transform;
    let p = tr.world_to_pixel(start.0, start.1);
    let (w, h) = (grid.width as i64, grid.height as i64);
    Walk::new(
        [p.0, p.1],
        [u.0 / tr.cell_x, u.1 / tr.cell_y],
        Corner::Diagonal,
    )
    .map(move |v| {
        let [c, r] = v.cell;
        let inside = c >= 0 && r >= 0 && c < w && r < h;
        (v.t_in, v.t_out, inside.then_some((c as usize, r as usize)))
    })
}

/// The finite values, in ascending order.
fn sorted_finite(values: &[f64]) -> Vec<f64> {
    let mut v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
    v.sort_by(f64::total_cmp);
    v
}

/// The `q`-quantile (0 ≤ q < 1) of the finite values: the value at sorted index
/// `⌊q · n⌋`; `None` when there is none.
pub fn quantile(values: &[f64], q: f64) -> Option<f64> {
    let v = sorted_finite(values);
    let k = ((q * v.len() as f64) as usize).min(v.len().checked_sub(1)?);
    Some(v[k])
}

/// Median of finite values, `None` when there are none.
pub fn median(values: &[f64]) -> Option<f64> {
    let v = sorted_finite(values);
    if v.is_empty() {
        return None;
    }
    let m = v.len() / 2;
    Some(if v.len() % 2 == 1 {
        v[m]
    } else {
        (v[m - 1] + v[m]) / 2.0
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::crs::Crs;
    use crate::grid::{Grid, Window};

    /// A 40 × 40 window of 1 m cells: footprint x 10..20, y 10..20 (world), shadow `len` cells
    /// long to the north, and `class` at the cells just past the shadow.
    fn local(len: usize, past: Class) -> (Local, Footprint) {
        let g = Grid::north_up(0.0, 40.0, 1.0, 40, 40, Crs::epsg(32632));
        let w = Window {
            col: 0,
            row: 0,
            width: 40,
            height: 40,
        };
        let mut class = vec![Class::Lit; 1600];
        for r in 0..40usize {
            for c in 0..40usize {
                let (x, y) = g.cell_centre(c, r);
                if (10.0..20.0).contains(&x) {
                    if (10.0..20.0).contains(&y) {
                        class[r * 40 + c] = Class::Own;
                    } else if y >= 20.0 && y < 20.0 + len as f64 {
                        class[r * 40 + c] = Class::Shadow;
                    } else if y >= 20.0 + len as f64 && y < 21.0 + len as f64 {
                        class[r * 40 + c] = past;
                    }
                }
            }
        }
        let fp = Footprint::new(vec![vec![vec![
            (10.0, 10.0),
            (20.0, 10.0),
            (20.0, 20.0),
            (10.0, 20.0),
        ]]])
        .unwrap();
        (
            Local {
                win: w,
                grid: g.window_grid(&w),
                class,
                heights: vec![5.0; 1600],
                index: vec![100.0; 1600],
                roofs: Vec::new(),
            },
            fp,
        )
    }

    #[test]
    fn every_line_measures_the_shadow_to_the_first_lit_cell() {
        let (l, fp) = local(6, Class::Lit);
        let s = scan(&fp, &l, (0.0, 1.0), 1.0, 0.5, 30.0, 1.0);
        assert_eq!(s.lines, 17); // 10 m wide, 1 m clear each side, every 0.5 m.
        assert_eq!(s.lengths.len(), 17);
        assert!(s.lengths.iter().all(|&x| x == 6.0), "{:?}", s.lengths);
        assert_eq!(median(&s.lengths), Some(6.0));
        assert_eq!(s.tip_roofs[0], 11.0);
        assert_eq!(s.with_shadow, 17);
    }

    #[test]
    fn lines_meeting_other_footprints_or_unusable_cells_are_dropped() {
        let (l, fp) = local(6, Class::Other);
        let s = scan(&fp, &l, (0.0, 1.0), 1.0, 0.5, 30.0, 1.0);
        assert_eq!((s.on_other, s.lengths.len()), (17, 0));
        let (l, fp) = local(6, Class::Unusable);
        assert_eq!(scan(&fp, &l, (0.0, 1.0), 1.0, 0.5, 30.0, 1.0).cut, 17);
        // A shadow longer than the window: cut at the window's edge.
        let (l, fp) = local(25, Class::Lit);
        assert_eq!(scan(&fp, &l, (0.0, 1.0), 1.0, 0.5, 100.0, 1.0).cut, 17);
    }

    #[test]
    fn a_shadow_ending_on_a_lit_cell_against_another_footprint_met_it() {
        // Shadow 5 cells, then a cell reading lit (the neighbour's sunlit roof covers part of
        // it), then the neighbour: the shadow met the neighbour, it did not end (before: 17
        // valid lines of 5 m, the distance to the neighbour).
        let (mut l, fp) = local(5, Class::Lit);
        for c in 10..20 {
            l.class[(39 - 26) * 40 + c] = Class::Other;
        }
        let s = scan(&fp, &l, (0.0, 1.0), 1.0, 0.5, 30.0, 1.0);
        assert_eq!((s.on_other, s.lengths.len()), (17, 0), "{s:?}");
    }

    #[test]
    fn a_shadow_starting_under_unusable_cells_is_measured_past_them() {
        // Another building's shadow (unusable) over the first 3 cells of a 6-cell shadow: the
        // shadow's end is seen, the line is valid.
        let (mut l, fp) = local(6, Class::Lit);
        for r in 20..23usize {
            for c in 10..20 {
                l.class[(39 - r) * 40 + c] = Class::Unusable;
            }
        }
        let s = scan(&fp, &l, (0.0, 1.0), 1.0, 0.5, 30.0, 1.0);
        assert_eq!((s.cut, s.lengths.len()), (0, 17), "{s:?}");
        assert!(s.lengths.iter().all(|&x| x == 6.0), "{:?}", s.lengths);
    }

    /// Mark the cells of `l` at world y `ys` (metres north, 1 m rows) and x 5..25 (wider than
    /// the footprint) as `class`: another footprint's roof across the shadow.
    fn roof_across(l: &mut Local, ys: std::ops::Range<usize>, class: Class) {
        for y in ys {
            for c in 5..25 {
                l.class[(39 - y) * 40 + c] = class;
            }
        }
    }

    #[test]
    fn a_shadow_crossing_a_shaded_roof_is_measured_to_the_lit_ground_beyond() {
        // Shadow y 20..30 (10 m), with another roof read shaded over y 23..26 in it, then lit
        // ground: the shadow lies on the roof and runs on; every line is the full 10 m, and
        // counts as crossed (before Crossed was walked through: 17 lines on the other).
        let (mut l, fp) = local(10, Class::Lit);
        roof_across(&mut l, 23..26, Class::Crossed);
        let s = scan(&fp, &l, (0.0, 1.0), 1.0, 0.5, 30.0, 1.0);
        assert_eq!((s.on_other, s.cut, s.lengths.len()), (0, 0, 17), "{s:?}");
        assert!(s.lengths.iter().all(|&x| x == 10.0), "{:?}", s.lengths);
        assert!(s.tip_roofs.iter().all(|&z| z == 15.0), "{:?}", s.tip_roofs);
        assert_eq!((s.crossed, s.with_shadow), (17, 17));
    }

    #[test]
    fn a_shadow_running_from_a_shaded_roof_into_its_lit_part_met_the_roof() {
        // Shadow on the ground y 20..23, on the other roof's shaded part y 23..25, then the
        // roof's lit part (Other) y 25..28: dropped as meeting the other footprint, but the
        // lower bound runs through the shaded roof: terrain 5 + 4 m (the last crossed cell,
        // y 24, entered 4 m out) · tan e 1 = 9 m, not 7 m (the last ground shadow cell).
        let (mut l, fp) = local(10, Class::Lit);
        roof_across(&mut l, 23..25, Class::Crossed);
        roof_across(&mut l, 25..28, Class::Other);
        let s = scan(&fp, &l, (0.0, 1.0), 1.0, 0.5, 30.0, 1.0);
        assert_eq!(
            (s.on_other, s.lengths.len(), s.crossed),
            (17, 0, 17),
            "{s:?}"
        );
        assert_eq!(s.reached_roofs, vec![9.0; 17]);
    }

    #[test]
    fn a_shadow_ending_on_a_lit_cell_against_a_crossed_roof_met_it() {
        // Shadow y 20..23, the shaded roof y 23..26, then a lit cell at y 26: that cell may
        // read lit only because the roof's lit far edge covers part of it, so the line is
        // dropped (counting Crossed as not another footprint there: 17 valid lines of 6 m),
        // with the lower bound from the roof's last cell: 5 + 5 = 10 m.
        let (mut l, fp) = local(3, Class::Lit);
        roof_across(&mut l, 23..26, Class::Crossed);
        let s = scan(&fp, &l, (0.0, 1.0), 1.0, 0.5, 30.0, 1.0);
        assert_eq!(
            (s.on_other, s.lengths.len(), s.crossed),
            (17, 0, 17),
            "{s:?}"
        );
        assert_eq!(s.reached_roofs, vec![10.0; 17]);
    }

    #[test]
    fn a_shadow_crossing_a_roof_cut_by_the_window_keeps_its_lower_bound() {
        // The shaded roof from y 23 to the window's northern edge (y 40), then (second case)
        // a roof y 23..26 with ground shadow on to the edge: the lines are cut, each with the
        // lower bound of the last cell it crossed, y 39 entered 19 m out: 5 + 19 = 24 m
        // (before: on the other at y 23, 7 m).
        for roof in [23..40, 23..26] {
            let (mut l, fp) = local(20, Class::Lit);
            roof_across(&mut l, roof.clone(), Class::Crossed);
            let s = scan(&fp, &l, (0.0, 1.0), 1.0, 0.5, 100.0, 1.0);
            assert_eq!(
                (s.cut, s.on_other, s.crossed),
                (17, 0, 17),
                "{roof:?}: {s:?}"
            );
            assert!(s.at_window_edge && s.lengths.is_empty(), "{roof:?}: {s:?}");
            assert_eq!(s.reached_roofs, vec![24.0; 17], "{roof:?}");
        }
    }

    #[test]
    fn median_ignores_nan_and_averages_the_middle_pair() {
        assert_eq!(median(&[3.0, f64::NAN, 1.0, 2.0, 10.0]), Some(2.5));
        assert_eq!(median(&[f64::NAN]), None);
    }

    #[test]
    fn quantile_is_the_value_at_its_sorted_index() {
        let v = [5.0, 1.0, f64::NAN, 4.0, 2.0, 3.0, 8.0, 7.0, 6.0];
        assert_eq!(quantile(&v, 0.25), Some(3.0)); // 8 finite: index 2
        assert_eq!(quantile(&v, 0.0), Some(1.0));
        assert_eq!(quantile(&v, 0.999), Some(8.0));
        assert_eq!(quantile(&[f64::NAN], 0.25), None);
    }
}
