//! Footprints registered to the orthophoto: the shift that puts each outline on its roof's
//! edges, and one robust shift for the scene.
//!
//! Footprints from OpenStreetMap or a cadastre sit 0.5–3 m off an orthophoto. A footprint off
//! its roof puts lit roof where the scan lines expect shadow (or shadow under the "roof"), and
//! the height is wrong or refused.
//!
//! Invariant: a footprint's outline fits the photo where the brightness changes most across
//! it, *in the sense the sun allows*. The *contrast* of a shift `(dx, dy)` is the mean, over
//! points every half cell along every edge of the moved outline, of the step from outside to
//! inside, `Y(p − n·c)` against `Y(p + n·c)` (Rec. 601 luminance, bilinear; `n` the edge's
//! outward normal, `c` = ¾ cell, `ACROSS`):
//! - on an edge facing away from the sun (`n·u > 0`, `u` the shadow direction) the outside is
//!   the building's own shadow, so only a roof *brighter* inside counts: `max(0, Y_in − Y_out)`.
//!   The shadow's own outer boundary is a copy of these edges moved along `u`, with shadow
//!   inside and lit ground outside — the strongest edge in the scene, and the wrong one. Read
//!   unsigned, a thin shadow (a high sun) pulled outlines onto it by the shadow's width;
//!   signed, it scores nothing;
//! - on the other edges, roof against lit ground, either may be the brighter: `|Y_in − Y_out|`.
//!
//! The shift is searched on a grid of whole cells within ±`max_shift_m` (reading every other
//! sample, a sample a cell), then on the half cells around the best, then refined to an eighth
//! of a cell around that. In a frame photo with a known camera the whole cells run on along
//! the building's radial direction over the leans of every height sought ([`Reach`]); a lean
//! beyond the square is taken only when it beats the square's best by [`LEAN_MARGIN`], and
//! the background stays the square's. An orthophoto's search is the square alone. A building's estimate counts only when its best contrast
//! stands clear of its search's typical one ([`MIN_PEAK_RATIO`]); the scene's shift is the
//! component-wise median over the buildings that count, so a few wrong estimates (a roof the
//! colour of its ground, a neighbour's edge) do not move it.

use super::footprint::Footprint;
use crate::num::floor_i64;
use crate::raster::RowBand;

/// A building's best contrast must be at least this many times the median contrast over its
/// search for its estimate to count.
pub const MIN_PEAK_RATIO: f64 = 1.5;

/// A roof's best contrast leaning beyond ±`max_shift_m` must be at least this many times the
/// best within it to be taken ([`Reach`]).
pub const LEAN_MARGIN: f64 = 1.2;

/// How far either side of the outline (pixels) the contrast is read. A sharp edge between two
/// pixels is a one-pixel ramp in the bilinear luminance, so its contrast read at ±¾ is the full
/// step on a plateau ½ pixel wide around the edge: [`estimate`] takes the plateau's centre.
/// (At ±½ the plateau is a point, but one pixel of noise or blur moves it: in the POV-Ray
/// sweep's 80° slice that gave 13 silent gross errors instead of 3.)
const ACROSS: f64 = 0.75;

/// A scene's shift, metres east and north, with the number of buildings it rests on.
pub type SceneShift = (f64, f64, usize);

/// One footprint's estimated shift onto the photo.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Shift {
    /// Metres east and north to move the footprint by.
    pub east_m: f64,
    /// See `east_m`.
    pub north_m: f64,
    /// Best contrast over the median contrast of the search (≥ 1): how clearly it stands out.
    pub peak_ratio: f64,
    /// Whether it was sought again along the lean from the scene's misregistration alone
    /// ([`Reach::along_from`], [`off_the_leans`]), the broad search's best being off it: a
    /// narrower search always finds a best, so its lean may confirm or doubt a shadow's
    /// height but not stand for one ([`super::lean::meet`]).
    pub along_lean: bool,
}

impl Shift {
    /// Whether the estimate is clear enough to count ([`MIN_PEAK_RATIO`]).
    pub fn counts(&self) -> bool {
        self.peak_ratio >= MIN_PEAK_RATIO
    }
}

/// Rec. 601 luminance of the photo over a window of its pixels, computed once for a
/// footprint's search (which reads each pixel hundreds of times). NaN marks nodata.
///
/// Invariant: the window is the pixels asked for clipped to the grid and to the band's rows,
/// so [`Luma::at`] answers exactly as reading the band itself would.
struct Luma {
    /// The window's first column and row in the whole grid.
    col0: i64,
    row0: i64,
    width: i64,
    height: i64,
    /// Row-major luminance, 0–255, NaN where the photo's alpha is 0.
    values: Vec<f64>,
}

impl Luma {
    /// The luminance of `colour`'s pixels in columns `cols` and rows `rows` (whole-grid
    /// indices, clipped to the grid and the band).
    fn new(colour: &RowBand<[u8; 4]>, cols: (i64, i64), rows: (i64, i64)) -> Luma {
        let band = colour.rows();
        let col0 = cols.0.max(0);
        let col1 = cols.1.min(colour.grid.width as i64).max(col0);
        let row0 = rows.0.max(band.start as i64);
        let row1 = rows.1.min(band.end as i64).max(row0);
        let mut values = Vec::with_capacity(((col1 - col0) * (row1 - row0)) as usize);
        for r in row0..row1 {
            for c in col0..col1 {
                let p = colour.get(c as usize, r as usize);
                values.push(if p[3] != 0 {
                    0.299 * p[0] as f64 + 0.587 * p[1] as f64 + 0.114 * p[2] as f64
                } else {
                    f64::NAN
                });
            }
        }
        Luma {
            col0,
            row0,
            width: col1 - col0,
            height: row1 - row0,
            values,
        }
    }

    /// The cell centre before pixel coordinate `px` of the whole grid along the columns
    /// (a column of the window, maybe off it) and the point's fraction from it.
    fn column_before(&self, px: f64) -> (i64, f64) {
        let x = px - 0.5;
        let c = floor_i64(x);
        (c - self.col0, x - c as f64)
    }

    /// [`Self::column_before`] along the rows.
    fn row_before(&self, py: f64) -> (i64, f64) {
        let y = py - 0.5;
        let r = floor_i64(y);
        (r - self.row0, y - r as f64)
    }

    /// The luminance `(fx, fy)` from the centre of window cell `(c, r)` toward the next
    /// column and row, bilinear; `None` when one of the four is off the window or nodata.
    fn blend(&self, c: i64, r: i64, fx: f64, fy: f64) -> Option<f64> {
        // The window starts at column and row 0 or later: off it is off the grid too.
        if c < 0 || r < 0 || c + 1 >= self.width || r + 1 >= self.height {
            return None;
        }
        let i = (r * self.width + c) as usize;
        let w = self.width as usize;
        let (a, b, cc, d) = (
            self.values[i],
            self.values[i + 1],
            self.values[i + w],
            self.values[i + w + 1],
        );
        let v = (1.0 - fy) * ((1.0 - fx) * a + fx * b) + fy * ((1.0 - fx) * cc + fx * d);
        // A NaN corner (nodata) makes the whole blend NaN.
        (!v.is_nan()).then_some(v)
    }
}

/// One point on a footprint's outline, in pixel coordinates of the photo's grid.
#[derive(Debug, Clone, Copy)]
struct Sample {
    /// The point.
    at: (f64, f64),
    /// Unit outward normal.
    out: (f64, f64),
    /// Whether the edge faces away from the sun, so that its outside is the building's shadow.
    faces_shadow: bool,
}

/// Sample points of `fp`'s outline: every half cell along every edge. `away` is the shadow
/// direction (world east, north; any length).
fn outline_samples(fp: &Footprint, colour: &RowBand<[u8; 4]>, away: (f64, f64)) -> Vec<Sample> {
    let t = &colour.grid.transform;
    let mut out = Vec::new();
    for (a, b) in fp.edges() {
        let (pa, pb) = (t.world_to_pixel(a.0, a.1), t.world_to_pixel(b.0, b.1));
        let (dx, dy) = (pb.0 - pa.0, pb.1 - pa.1);
        let len = dx.hypot(dy);
        if len == 0.0 {
            continue;
        }
        // World outward normal: the side of the edge's midpoint that is outside.
        let (ex, ey) = (b.0 - a.0, b.1 - a.1);
        let (mx, my) = ((a.0 + b.0) / 2.0, (a.1 + b.1) / 2.0);
        let eps = 1e-6;
        let mut world = (ey, -ex);
        if fp.contains(mx + eps * world.0, my + eps * world.1) {
            world = (-world.0, -world.1);
        }
        // The pixel normal on the same side (the grid's transform may flip orientation).
        let (qx, qy) = t.world_to_pixel(mx + eps * world.0, my + eps * world.1);
        let (mpx, mpy) = ((pa.0 + pb.0) / 2.0, (pa.1 + pb.1) / 2.0);
        let mut n = (-dy / len, dx / len);
        if n.0 * (qx - mpx) + n.1 * (qy - mpy) < 0.0 {
            n = (-n.0, -n.1);
        }
        let faces_shadow = world.0 * away.0 + world.1 * away.1 > 0.0;
        let k = (len * 2.0).ceil().max(1.0) as usize;
        for i in 0..k {
            let s = (i as f64 + 0.5) / k as f64;
            out.push(Sample {
                at: (pa.0 + s * dx, pa.1 + s * dy),
                out: n,
                faces_shadow,
            });
        }
    }
    out
}

/// One sample's contrast, from the luminance `outside` to `inside` (the module's invariant).
fn step(outside: f64, inside: f64, faces_shadow: bool) -> f64 {
    if faces_shadow {
        (inside - outside).max(0.0)
    } else {
        (inside - outside).abs()
    }
}

/// The mean of `len` samples' contrasts (`None`: unread); `None` when under half are read.
fn mean_step(len: usize, steps: impl Iterator<Item = Option<f64>>) -> Option<f64> {
    let (mut sum, mut n) = (0.0, 0usize);
    for v in steps.flatten() {
        sum += v;
        n += 1;
    }
    (n * 2 >= len && n > 0).then(|| sum / n as f64)
}

/// The outline's contrast ([`step`]) for the shifts on a square grid: `2k + 1` columns and
/// rows `pitch` pixels apart around a centre. Where each read point falls between cell
/// centres depends on the shift's column along one axis and its row along the other, so it is
/// worked out once per column and per row for all the grid's shifts (on a grid of whole
/// pixels, once: the fractions stay, the cells move by whole pixels).
///
/// Invariant: [`Shifts::contrast`]`(i, j)` is the mean contrast across the outline moved by
/// column `i` and row `j` of the grid, read at `p ± n·ACROSS` around each moved sample `p`
/// (bilinear); `None` when under half the samples can be read (off the window, or next to
/// nodata).
struct Shifts<'a> {
    luma: &'a Luma,
    faces_shadow: Vec<bool>,
    /// Per column of the grid, per read (each sample's outside, then its inside): the window
    /// column of the centre before it and the fraction from there.
    cols: Vec<(i64, f64)>,
    /// Per row of the grid, per read: as `cols`, along the rows.
    rows: Vec<(i64, f64)>,
}

impl<'a> Shifts<'a> {
    /// The grid around `centre` (pixels, column and row): `2k + 1` shifts `pitch` pixels apart
    /// on each axis.
    fn new(
        luma: &'a Luma,
        samples: &[Sample],
        centre: (f64, f64),
        pitch: f64,
        k: usize,
    ) -> Shifts<'a> {
        let first = (centre.0 - k as f64 * pitch, centre.1 - k as f64 * pitch);
        // Per read, where it falls on the axis (column or row) with the first shift.
        let reads = |axis: fn(&Luma, f64) -> (i64, f64), at: &dyn Fn(&Sample) -> (f64, f64)| {
            let mut out = Vec::with_capacity(2 * samples.len());
            for s in samples {
                let (p, n) = at(s);
                out.push(axis(luma, p + n * ACROSS));
                out.push(axis(luma, p - n * ACROSS));
            }
            out
        };
        let x0 = reads(Luma::column_before, &|s| (s.at.0 + first.0, s.out.0));
        let y0 = reads(Luma::row_before, &|s| (s.at.1 + first.1, s.out.1));
        // The other shifts move each read by whole cells plus a part of one.
        let along = |start: &[(i64, f64)]| {
            let mut out = Vec::with_capacity(start.len() * (2 * k + 1));
            for i in 0..=2 * k {
                let moved = i as f64 * pitch;
                out.extend(start.iter().map(|&(c, f)| {
                    if pitch == 1.0 {
                        (c + i as i64, f)
                    } else {
                        let v = f + moved;
                        let whole = floor_i64(v);
                        (c + whole, v - whole as f64)
                    }
                }));
            }
            out
        };
        Shifts {
            luma,
            faces_shadow: samples.iter().map(|s| s.faces_shadow).collect(),
            cols: along(&x0),
            rows: along(&y0),
        }
    }

    /// The mean contrast for the shift by column `i` and row `j` of the grid.
    fn contrast(&self, i: usize, j: usize) -> Option<f64> {
        let n = self.faces_shadow.len();
        let cols = &self.cols[2 * n * i..2 * n * (i + 1)];
        let rows = &self.rows[2 * n * j..2 * n * (j + 1)];
        let read = |k: usize| {
            let ((c, fx), (r, fy)) = (cols[k], rows[k]);
            self.luma.blend(c, r, fx, fy)
        };
        mean_step(
            n,
            self.faces_shadow
                .iter()
                .enumerate()
                .map(|(k, &f)| Some(step(read(2 * k)?, read(2 * k + 1)?, f))),
        )
    }
}

/// Where a footprint's shift onto its roof is sought: every shift within `across_m` on each
/// axis of a point of the segment from `from_m` to `from_m + lean_m`. An orthophoto's is the
/// square ±`across_m` around no shift (`lean_m` zero); a frame photo's runs along the
/// building's radial direction from the nadir over the leans of every height it may have
/// ([`Reach::leaning`]), with the footprint's misregistration either side; once the scene's
/// misregistration is known, a footprint's roof is sought again along that line alone
/// ([`Reach::along_from`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reach {
    /// The largest misregistration sought on each axis, metres.
    pub across_m: f64,
    /// The lean of the tallest roof sought, metres (east, north).
    pub lean_m: (f64, f64),
    /// Where the segment starts: the shift of a roof on the ground, metres (east, north).
    pub from_m: (f64, f64),
}

impl Reach {
    /// Within ±`max_shift_m` metres on each axis of no shift (an orthophoto).
    pub fn square(max_shift_m: f64) -> Reach {
        Reach {
            across_m: max_shift_m.max(0.0),
            lean_m: (0.0, 0.0),
            from_m: (0.0, 0.0),
        }
    }

    /// For `fp` in a frame photo taken from `camera` over ground at `ground_z` (absolute
    /// metres): its roof, `h` above the ground, is seen `r·h / (Z − h)` from its base, radially
    /// away from the nadir (`r` from the nadir to the footprint's box centre, `Z` the camera
    /// above the ground); sought for `h` from 0 to `max_height_m` — no more than half of `Z`,
    /// whose leans would exceed `r` — within ±`max_shift_m`. The square when the ground is
    /// unknown (NaN), at or above the camera, or the footprint under the nadir.
    pub fn leaning(
        fp: &Footprint,
        camera: &PerspectiveCentre,
        ground_z: f64,
        max_shift_m: f64,
        max_height_m: f64,
    ) -> Reach {
        let (x, y) = fp.bbox_centre();
        let (dx, dy) = (x - camera.east, y - camera.north);
        let r = dx.hypot(dy);
        let z = camera.z - ground_z;
        if !(z > 0.0 && r > 0.0) {
            return Reach::square(max_shift_m);
        }
        let h = max_height_m.clamp(0.0, z / 2.0);
        let lean = h / (z - h); // metres of lean per metre from the nadir
        Reach {
            lean_m: (lean * dx, lean * dy),
            ..Reach::square(max_shift_m)
        }
    }

    /// This reach's leans from the scene's misregistration `g` (metres east, north) alone,
    /// within `across_m` on each axis: the line every roof of the footprint lies on once `g`
    /// is known. A roof the broad search found off that line (on a neighbour's edges beside
    /// its lean, on another building far along it) is sought there again.
    pub fn along_from(&self, g: (f64, f64), across_m: f64) -> Reach {
        Reach {
            across_m,
            lean_m: self.lean_m,
            from_m: g,
        }
    }

    /// The footprint's box `b` (world metres: west, south, east, north) grown to hold it moved
    /// by any shift sought but the misregistration across (the caller's margin).
    pub fn leaned_box(&self, b: (f64, f64, f64, f64)) -> (f64, f64, f64, f64) {
        let (le, ln) = self.lean_m;
        let (fe, fn_) = self.from_m;
        (
            b.0 + fe + le.min(0.0),
            b.1 + fn_ + ln.min(0.0),
            b.2 + fe + le.max(0.0),
            b.3 + fn_ + ln.max(0.0),
        )
    }

    /// The reach in pixels of a grid with cells `cx` by `cy` metres (`cy` < 0 north-up): the
    /// misregistration over the larger cell side, as always.
    fn in_pixels(&self, cx: f64, cy: f64) -> PixelReach {
        PixelReach {
            across: self.across_m / cx.abs().max(cy.abs()),
            lean: (self.lean_m.0 / cx, self.lean_m.1 / cy),
            from: (self.from_m.0 / cx, self.from_m.1 / cy),
        }
    }
}

/// A [`Reach`] in pixels (columns, rows).
///
/// Invariant: with no lean and from no shift, [`PixelReach::contains`] is exactly `|x|, |y| ≤
/// across`, the square searched before frame photos had their own reach: an orthophoto's
/// search is unchanged.
#[derive(Debug, Clone, Copy)]
struct PixelReach {
    across: f64,
    lean: (f64, f64),
    from: (f64, f64),
}

impl PixelReach {
    /// Whether the shift `(x, y)` pixels is within `across` on both axes of `from + λ·lean`
    /// for some `λ` in [0, 1]: the intervals of `λ` each axis allows meet.
    fn contains(&self, x: f64, y: f64) -> bool {
        let (mut lo, mut hi) = (0.0f64, 1.0f64);
        let (x, y) = (x - self.from.0, y - self.from.1);
        for (s, l) in [(x, self.lean.0), (y, self.lean.1)] {
            if l == 0.0 {
                if s.abs() > self.across {
                    return false;
                }
            } else {
                let (a, b) = ((s - self.across) / l, (s + self.across) / l);
                lo = lo.max(a.min(b));
                hi = hi.min(a.max(b));
            }
        }
        lo <= hi
    }

    /// The smallest and largest shifts sought on each axis: (x0, y0, x1, y1) pixels.
    fn bounds(&self) -> (f64, f64, f64, f64) {
        let (lx, ly) = self.lean;
        let (fx, fy) = self.from;
        (
            fx + lx.min(0.0) - self.across,
            fy + ly.min(0.0) - self.across,
            fx + lx.max(0.0) + self.across,
            fy + ly.max(0.0) + self.across,
        )
    }
}

/// The shift (within `reach`) that best fits `fp` to its roof in `colour` with shadows cast
/// along `away` (world east, north, away from the sun); `None` when the outline is mostly off
/// the grid or on nodata.
///
/// Whole pixels first (their scores are the search's background, whose median the peak is
/// judged against), then the half pixels around the best: a quarter of the evaluations of a
/// half-pixel grid, and the contrast (read `ACROSS` = ¾ pixel each side of the outline) is
/// more than a pixel wide, so the whole-pixel best lies beside the peak. Then the eighths
/// around that, whose top plateau's centre is the estimate (`plateau_centre`).
pub fn estimate(
    fp: &Footprint,
    colour: &RowBand<[u8; 4]>,
    away: (f64, f64),
    reach: &Reach,
) -> Option<Shift> {
    let samples = outline_samples(fp, colour, away);
    let t = &colour.grid.transform;
    let (cx, cy) = (t.cell_x, t.cell_y); // metres per pixel (cy < 0 for north-up)
    let reach = reach.in_pixels(cx, cy);
    let luma = search_luma(colour, &samples, &reach);
    let (scores, whole, reach) = whole_pixel_search(&luma, &samples, &reach);
    let half = half_pixel_search(&luma, &samples, whole?, &reach)?;
    let median = super::scan::median(&scores)?;
    let top = plateau_centre(&luma, &samples, half, median);
    Some(Shift {
        east_m: top.x * cx,
        north_m: top.y * cy,
        peak_ratio: if median > 0.0 {
            top.score / median
        } else {
            1.0
        },
        along_lean: false,
    })
}

/// A shift the search scored: its contrast ([`Shifts::contrast`]) and the shift, pixels
/// (along the columns and the rows).
#[derive(Clone, Copy)]
struct Candidate {
    score: f64,
    x: f64,
    y: f64,
}

/// Keep in `best` the better of it and `c`: the higher score, or on a tie the smaller shift.
fn keep_best(best: &mut Option<Candidate>, c: Candidate) {
    if best.is_none_or(|b| {
        c.score > b.score || (c.score == b.score && c.x.hypot(c.y) < b.x.hypot(b.y))
    }) {
        *best = Some(c);
    }
}

/// The luminance of every pixel the search of `samples` can read: the samples moved by any
/// shift within `reach` and the fine search's ¾ pixel, read ¾ pixel across, with the bilinear
/// neighbour.
fn search_luma(colour: &RowBand<[u8; 4]>, samples: &[Sample], reach: &PixelReach) -> Luma {
    let (x0, y0, x1, y1) = samples.iter().fold(
        (
            f64::INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
        ),
        |b, s| {
            (
                b.0.min(s.at.0),
                b.1.min(s.at.1),
                b.2.max(s.at.0),
                b.3.max(s.at.1),
            )
        },
    );
    let (r0, s0, r1, s1) = reach.bounds();
    Luma::new(
        colour,
        (
            (x0 + r0 - 4.0).floor() as i64,
            (x1 + r1 + 4.0).ceil() as i64,
        ),
        (
            (y0 + s0 - 4.0).floor() as i64,
            (y1 + s1 + 4.0).ceil() as i64,
        ),
    )
}

/// The shifts by whole pixels within `reach`, read on every other sample (a sample a cell):
/// they only seed the finer searches and give the background, and are most of the
/// evaluations. Returns the background (the contrasts read within ±`across` of no shift, the
/// old square; all of them when none is), the best shift, if any, and the part of the reach
/// the finer searches stay in.
///
/// A lean beyond ±`across` is taken only when its best beats the square's by
/// [`LEAN_MARGIN`]: a roof whose lean the square holds (most from 1500 m up) keeps the
/// square's estimate, and the longer search adds no chance of a neighbour's edges winning.
fn whole_pixel_search(
    luma: &Luma,
    samples: &[Sample],
    reach: &PixelReach,
) -> (Vec<f64>, Option<Candidate>, PixelReach) {
    // The square grid around the reach's middle (whole pixels) that holds it.
    let (x0, y0, x1, y1) = reach.bounds();
    let (mx, my) = (((x0 + x1) / 2.0).round(), ((y0 + y1) / 2.0).round());
    let whole = (x1 - mx).max(mx - x0).max(y1 - my).max(my - y0).floor() as i64;
    let square = PixelReach {
        lean: (0.0, 0.0),
        ..*reach
    };
    let (mut near_scores, mut far_scores) = (Vec::new(), Vec::new());
    let (mut near, mut far) = (None, None);
    let sparse: Vec<Sample> = samples.iter().step_by(2).copied().collect();
    let pixels = Shifts::new(luma, &sparse, (mx, my), 1.0, whole as usize);
    for j in -whole..=whole {
        for i in -whole..=whole {
            let (x, y) = (mx + i as f64, my + j as f64);
            if !reach.contains(x, y) {
                continue;
            }
            let at = ((i + whole) as usize, (j + whole) as usize);
            if let Some(s) = pixels.contrast(at.0, at.1) {
                let c = Candidate { score: s, x, y };
                if square.contains(x, y) {
                    near_scores.push(s);
                    keep_best(&mut near, c);
                } else {
                    far_scores.push(s);
                    keep_best(&mut far, c);
                }
            }
        }
    }
    let leaning = match (near, far) {
        (Some(n), Some(f)) => f.score >= LEAN_MARGIN * n.score,
        (n, f) => n.is_none() && f.is_some(),
    };
    let background = if near_scores.is_empty() {
        far_scores
    } else {
        near_scores
    };
    if leaning {
        (background, far, *reach)
    } else {
        (background, near, square)
    }
}

/// The best of the half-pixel shifts around the whole-pixel best `whole`, all read on every
/// sample (`whole` itself scored again first); none outside `reach`. `None` when none can be
/// read.
fn half_pixel_search(
    luma: &Luma,
    samples: &[Sample],
    whole: Candidate,
    reach: &PixelReach,
) -> Option<Candidate> {
    let (wx, wy) = (whole.x, whole.y);
    let halves = Shifts::new(luma, samples, (wx, wy), 0.5, 1);
    let mut best = halves.contrast(1, 1).map(|s| Candidate {
        score: s,
        x: wx,
        y: wy,
    });
    for j in -1..=1 {
        for i in -1..=1 {
            let (sx, sy) = (wx + i as f64 / 2.0, wy + j as f64 / 2.0);
            if (i, j) == (0, 0) || !reach.contains(sx, sy) {
                continue;
            }
            if let Some(s) = halves.contrast((i + 1) as usize, (j + 1) as usize) {
                keep_best(
                    &mut best,
                    Candidate {
                        score: s,
                        x: sx,
                        y: sy,
                    },
                );
            }
        }
    }
    best
}

/// The centre of the top around the half-pixel best `half`, refined to an eighth of a pixel
/// within ¾ pixel of it: the mean shift (pixels) of every shift scoring within `PLATEAU` of
/// the peak (over the search's `median`), with the peak's score. A sharp edge's contrast is
/// flat for ±¼ pixel around it ([`ACROSS`]); the first maximum found there sat at the
/// plateau's west or north end, ¼ pixel off. The eighths are scored ring by ring out from the
/// centre, and no further once a whole ring is below the top: the plateau around the best has
/// ended (most are ±¼ pixel, three rings of six).
fn plateau_centre(luma: &Luma, samples: &[Sample], half: Candidate, median: f64) -> Candidate {
    const PLATEAU: f64 = 0.02;
    let (gx, gy) = (half.x, half.y);
    let floor_of = |s0: f64| s0 - PLATEAU * (s0 - median).max(0.0);
    // The grid of eighths is made for the usual three rings first, for all six when needed.
    const RINGS: i64 = 6;
    let eighths = |k: i64| (k, Shifts::new(luma, samples, (gx, gy), 0.125, k as usize));
    let mut grid = eighths(3);
    // ((row, column) on the eighths' grid, the shift scored).
    let mut fine: Vec<((i64, i64), Candidate)> = Vec::new();
    let mut s0 = f64::NEG_INFINITY;
    for ring in 0..=RINGS {
        if ring > grid.0 {
            grid = eighths(RINGS);
        }
        let mut ring_best = f64::NEG_INFINITY;
        for j in -ring..=ring {
            for i in -ring..=ring {
                if i.abs().max(j.abs()) != ring {
                    continue;
                }
                let (sx, sy) = (gx + i as f64 / 8.0, gy + j as f64 / 8.0);
                let (col, row) = ((i + grid.0) as usize, (j + grid.0) as usize);
                if let Some(s) = grid.1.contrast(col, row) {
                    ring_best = ring_best.max(s);
                    let c = Candidate {
                        score: s,
                        x: sx,
                        y: sy,
                    };
                    fine.push(((j, i), c));
                }
            }
        }
        s0 = s0.max(ring_best);
        if ring > 0 && ring_best < floor_of(s0) {
            break;
        }
    }
    // The coarse best is the fine grid's centre, so the top holds at least it. Summed in
    // raster order, as the whole grid was.
    fine.sort_by_key(|f| f.0);
    let floor = floor_of(s0);
    let top: Vec<&Candidate> = fine
        .iter()
        .map(|f| &f.1)
        .filter(|f| f.score >= floor)
        .collect();
    let k = top.len() as f64;
    Candidate {
        score: s0,
        x: top.iter().map(|f| f.x).sum::<f64>() / k,
        y: top.iter().map(|f| f.y).sum::<f64>() / k,
    }
}

/// The scene's shift: the component-wise median of the estimates that count; `None` when none
/// does.
pub fn scene_shift(shifts: &[Option<Shift>]) -> Option<SceneShift> {
    let good: Vec<&Shift> = shifts.iter().flatten().filter(|s| s.counts()).collect();
    let e: Vec<f64> = good.iter().map(|s| s.east_m).collect();
    let n: Vec<f64> = good.iter().map(|s| s.north_m).collect();
    Some((
        super::scan::median(&e)?,
        super::scan::median(&n)?,
        good.len(),
    ))
}

/// The perspective centre of a frame photo: world metres east and north, and its absolute
/// height, metres.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PerspectiveCentre {
    /// Metres east.
    pub east: f64,
    /// Metres north.
    pub north: f64,
    /// Absolute height, metres.
    pub z: f64,
}

/// Registration of a perspective photo rectified on the bare ground. A building's roof outline
/// is seen moved by the scene's misregistration `g` plus its *lean*, the relief displacement
/// `λ·ρ`: radially away from the nadir (`ρ`, unit), by `λ = r·h / (Z − h)` ≥ 0 for a roof `h`
/// above the ground, `r` from the nadir. So the part of a building's estimate `s` across its
/// radial direction (`n ⟂ ρ`) is `g`'s alone: `s·n = g·n`. Each clear estimate is a line in
/// the plane (buildings in different directions from the nadir fix both components); `g` is
/// the least-squares point of the lines that pass within [`CONSENSUS_CELLS`] of the point
/// most of them pass near (`consensus`), solved again over the estimates within `cell` of
/// it, and each clear building's lean is `max(0, (s − g)·ρ)·ρ`
/// (0 for unclear estimates). Returns `g` (metres east, north) with the number of buildings
/// it rests on (`None` with fewer than two), and the leans.
pub fn with_camera(
    footprints: &[Footprint],
    shifts: &[Option<Shift>],
    camera: &PerspectiveCentre,
    cell: f64,
) -> (Option<SceneShift>, Vec<(f64, f64)>) {
    let radial: Vec<(f64, f64)> = footprints.iter().map(|f| radial(f, camera)).collect();
    let clear: Vec<usize> = (0..shifts.len())
        .filter(|&k| shifts[k].is_some_and(|s| s.counts()) && radial[k] != (0.0, 0.0))
        .collect();
    let solve = |use_: &[usize]| -> Option<(f64, f64)> {
        let (mut a, mut b, mut c, mut u, mut v) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for &k in use_ {
            let s = shifts[k].unwrap();
            let n = (-radial[k].1, radial[k].0);
            let d = s.east_m * n.0 + s.north_m * n.1;
            a += n.0 * n.0;
            b += n.0 * n.1;
            c += n.1 * n.1;
            u += d * n.0;
            v += d * n.1;
        }
        // A little pull toward no shift keeps the solution defined when every building lies
        // in one direction from the nadir (then g along that direction is not observable).
        let eps = 1e-3 * use_.len() as f64;
        let (a, c) = (a + eps, c + eps);
        let det = a * c - b * b;
        (use_.len() >= 2 && det > 0.0).then(|| ((c * u - b * v) / det, (a * v - b * u) / det))
    };
    let across = |k: usize, g: (f64, f64)| {
        let s = shifts[k].unwrap();
        let n = (-radial[k].1, radial[k].0);
        ((s.east_m - g.0) * n.0 + (s.north_m - g.1) * n.1).abs()
    };
    // Each clear estimate's line `g·n = s·n`.
    let lines: Vec<((f64, f64), f64)> = clear
        .iter()
        .map(|&k| {
            let (s, n) = (shifts[k].unwrap(), (-radial[k].1, radial[k].0));
            (n, s.east_m * n.0 + s.north_m * n.1)
        })
        .collect();
    let agreeing = |g: (f64, f64)| -> Vec<usize> {
        clear
            .iter()
            .copied()
            .filter(|&k| across(k, g) <= CONSENSUS_CELLS * cell)
            .collect()
    };
    let Some(first) = consensus(&lines, cell).and_then(|g| solve(&agreeing(g))) else {
        return (None, vec![(0.0, 0.0); footprints.len()]);
    };
    let kept: Vec<usize> = clear
        .iter()
        .copied()
        .filter(|&k| across(k, first) <= cell)
        .collect();
    let g = solve(&kept).unwrap_or(first);
    let leans = (0..footprints.len())
        .map(|k| match shifts[k] {
            Some(s) if clear.contains(&k) => {
                let l = ((s.east_m - g.0) * radial[k].0 + (s.north_m - g.1) * radial[k].1).max(0.0);
                (l * radial[k].0, l * radial[k].1)
            }
            _ => (0.0, 0.0),
        })
        .collect();
    (Some((g.0, g.1, kept.len())), leans)
}

/// The unit vector (east, north) from the nadir of `camera` to `fp`'s box centre, along which
/// its roof leans; zero under the nadir.
fn radial(fp: &Footprint, camera: &PerspectiveCentre) -> (f64, f64) {
    let (x, y) = fp.bbox_centre();
    let (dx, dy) = (x - camera.east, y - camera.north);
    let r = dx.hypot(dy);
    if r > 0.0 {
        (dx / r, dy / r)
    } else {
        (0.0, 0.0)
    }
}

/// The footprints (indices) whose roofs are to be sought again along their leans from the
/// scene's misregistration `g` ([`Reach::along_from`]): those whose estimate is unclear, or
/// more than `cell` metres from `g` plus its lean (the outward part of `s − g` along the
/// radial direction from `camera`'s nadir), as `footprint_off_photo` would flag them; not
/// those without one (their outline off the photo), nor those whose lean would not be
/// precise over their ground `grounds[k]` (absolute metres; [`super::lean::precise`]: from
/// 1500 m up the broad search is the square, and a lean found along a line would only be
/// a guess).
pub fn off_the_leans(
    footprints: &[Footprint],
    shifts: &[Option<Shift>],
    camera: &PerspectiveCentre,
    grounds: &[f64],
    g: (f64, f64),
    cell: f64,
) -> Vec<usize> {
    (0..footprints.len())
        .filter(|&k| {
            let (x, y) = footprints[k].bbox_centre();
            let r = (x - camera.east).hypot(y - camera.north);
            super::lean::precise(camera.z - grounds[k], r, 0.0, cell)
        })
        .filter(|&k| {
            let rho = radial(&footprints[k], camera);
            shifts[k].is_some_and(|s| {
                let d = (s.east_m - g.0, s.north_m - g.1);
                let l = (d.0 * rho.0 + d.1 * rho.1).max(0.0);
                !s.counts() || (d.0 - l * rho.0).hypot(d.1 - l * rho.1) > cell
            })
        })
        .collect()
}

/// How far across its radial direction (cells) a clear estimate may be from the scene's
/// misregistration and still vote for it in [`with_camera`]'s consensus.
pub const CONSENSUS_CELLS: f64 = 0.5;

/// The misregistration `g` (metres east, north) that the most lines `g·n = d` (`lines`: unit
/// normal `n`, offset `d` metres) pass within [`CONSENSUS_CELLS`] of, sought every quarter
/// `cell` within the largest `|d|` on each axis; on a tie the smallest `g`. `None` without a
/// line.
///
/// Why not least squares: the lines of a window seen from one side of the nadir are nearly
/// parallel, so `g` along the radial direction rests on their small spread, and a few clear
/// estimates on a neighbour's edges (2–4 m across) tilted the least-squares point by 2 m
/// along it — every lean 2 m short (the town bench, 500 m, window 15-0: the scene's shift
/// came out (1.6, 1.0) m for exact footprints). The consensus ignores them; the least
/// squares then runs on the lines that agree.
fn consensus(lines: &[((f64, f64), f64)], cell: f64) -> Option<(f64, f64)> {
    let reach = lines.iter().map(|l| l.1.abs()).fold(f64::NAN, f64::max);
    if reach.is_nan() || cell <= 0.0 {
        return None;
    }
    let step = (cell / 4.0).max(reach / 64.0);
    let n = (reach / step).ceil() as i64;
    let tol = CONSENSUS_CELLS * cell;
    let mut best: Option<(usize, f64, (f64, f64))> = None;
    for i in -n..=n {
        for j in -n..=n {
            let g = (i as f64 * step, j as f64 * step);
            let votes = lines
                .iter()
                .filter(|(m, d)| (g.0 * m.0 + g.1 * m.1 - d).abs() <= tol)
                .count();
            let size = g.0.hypot(g.1);
            if best.is_none_or(|(v, s, _)| votes > v || (votes == v && size < s)) {
                best = Some((votes, size, g));
            }
        }
    }
    best.map(|b| b.2)
}

/// The perspective centre of a frame photo, estimated from the buildings themselves: their own
/// shift estimates `shifts` and their heights above the ground `heights` (metres, measured with
/// the footprints as given: a photo rectified on the ground has the bases, and so the shadows'
/// tips, in place). A roof `h` above the ground at `p` is seen moved by the scene's
/// misregistration `g` plus its lean `h·(p − N)/(Z − h)`, which for `h ≪ Z` is linear in the
/// unknowns: `s = g + a·h·p − h·m`, `a = 1/Z`, `m = N/Z` (positions from the buildings' mean,
/// for conditioning). Least squares over the buildings with a clear estimate and a height,
/// solved again without those more than `cell` off the first solution.
///
/// The photo is taken for a perspective one only when the leans explain the estimates: at
/// least [`MIN_CAMERA_BUILDINGS`] buildings kept (and two thirds of those tried), a camera
/// above twice the tallest roof, the leans' model leaving at most a quarter of the estimates'
/// scatter about their mean, and some lean over a cell (smaller leans change no height).
/// `None` otherwise. `ground_z` (absolute metres) turns `Z` into the returned camera's height.
pub fn estimate_camera(
    footprints: &[Footprint],
    shifts: &[Option<Shift>],
    heights: &[Option<f64>],
    ground_z: f64,
    cell: f64,
) -> Option<PerspectiveCentre> {
    let tried: Vec<(usize, f64)> = (0..footprints.len())
        .filter_map(|k| match (shifts[k], heights[k]) {
            (Some(s), Some(h)) if s.counts() && h > 0.0 => Some((k, h)),
            _ => None,
        })
        .collect();
    if tried.len() < MIN_CAMERA_BUILDINGS {
        return None;
    }
    let fit = LeanFit::new(footprints, shifts, &tried);
    let first = fit.solve(&tried)?;
    let kept: Vec<(usize, f64)> = tried
        .iter()
        .copied()
        .filter(|&(k, h)| fit.residual(&first, k, h) <= cell)
        .collect();
    if kept.len() < MIN_CAMERA_BUILDINGS || 3 * kept.len() < 2 * tried.len() {
        return None;
    }
    let x = fit.solve(&kept)?;
    let (a, m) = (x[2], (x[3], x[4]));
    let tallest = kept.iter().map(|&(_, h)| h).fold(0.0, f64::max);
    if a.is_nan() || a <= 0.0 || 1.0 / a <= 2.0 * tallest {
        return None;
    }
    fit.explains(&x, &kept, cell).then(|| PerspectiveCentre {
        east: fit.origin.0 + m.0 / a,
        north: fit.origin.1 + m.1 / a,
        z: ground_z + 1.0 / a,
    })
}

/// [`estimate_camera`]'s linear model of the buildings' shifts, `s = g + a·h·p − h·m` in the
/// unknowns `x = [gx, gy, a, mx, my]`, with the positions `p` from `origin`. Buildings are
/// given as (index, height above the ground in metres).
struct LeanFit<'a> {
    footprints: &'a [Footprint],
    shifts: &'a [Option<Shift>],
    /// The mean of the bounding-box centres of the buildings tried, world metres.
    origin: (f64, f64),
}

impl<'a> LeanFit<'a> {
    /// The model of the buildings `tried` (each with a clear shift), positions from their mean
    /// centre.
    fn new(
        footprints: &'a [Footprint],
        shifts: &'a [Option<Shift>],
        tried: &[(usize, f64)],
    ) -> LeanFit<'a> {
        let n = tried.len() as f64;
        let origin = tried.iter().fold((0.0, 0.0), |o, &(k, _)| {
            let c = footprints[k].bbox_centre();
            (o.0 + c.0 / n, o.1 + c.1 / n)
        });
        LeanFit {
            footprints,
            shifts,
            origin,
        }
    }

    /// Building `k`'s position from the origin, metres (east, north).
    fn position(&self, k: usize) -> (f64, f64) {
        let (cx, cy) = self.footprints[k].bbox_centre();
        (cx - self.origin.0, cy - self.origin.1)
    }

    /// The two rows of building `k` (`h` metres high): the coefficients of
    /// `[gx, gy, a, mx, my]` and the observed shift, metres, east then north.
    fn rows(&self, k: usize, h: f64) -> [([f64; 5], f64); 2] {
        let (px, py) = self.position(k);
        let s = self.shifts[k].unwrap();
        [
            ([1.0, 0.0, h * px, -h, 0.0], s.east_m),
            ([0.0, 1.0, h * py, 0.0, -h], s.north_m),
        ]
    }

    /// The least-squares `x` over the buildings `used` (normal equations); `None` when they
    /// do not determine it.
    fn solve(&self, used: &[(usize, f64)]) -> Option<[f64; 5]> {
        let mut ata = [[0.0; 5]; 5];
        let mut atb = [0.0; 5];
        for &(k, h) in used {
            for (a, b) in self.rows(k, h) {
                for i in 0..5 {
                    atb[i] += a[i] * b;
                    for j in 0..5 {
                        ata[i][j] += a[i] * a[j];
                    }
                }
            }
        }
        solve5(ata, atb)
    }

    /// How far building `k`'s (`h` metres high) observed shift is from the one `x` gives,
    /// metres.
    fn residual(&self, x: &[f64; 5], k: usize, h: f64) -> f64 {
        let r = self
            .rows(k, h)
            .map(|(a, b)| (0..5).map(|i| a[i] * x[i]).sum::<f64>() - b);
        r[0].hypot(r[1])
    }

    /// Whether `x` explains the shifts of the buildings `kept`: the sum of their squared
    /// residuals at most a quarter of the shifts' scatter about their mean, and some lean
    /// (`a·h·p − h·m`) over `cell` metres.
    fn explains(&self, x: &[f64; 5], kept: &[(usize, f64)], cell: f64) -> bool {
        let (a, m) = (x[2], (x[3], x[4]));
        let mean = kept.iter().fold((0.0, 0.0), |o, &(k, _)| {
            let s = self.shifts[k].unwrap();
            let n = kept.len() as f64;
            (o.0 + s.east_m / n, o.1 + s.north_m / n)
        });
        let scatter: f64 = kept
            .iter()
            .map(|&(k, _)| {
                let s = self.shifts[k].unwrap();
                (s.east_m - mean.0).powi(2) + (s.north_m - mean.1).powi(2)
            })
            .sum();
        let unexplained: f64 = kept
            .iter()
            .map(|&(k, h)| self.residual(x, k, h).powi(2))
            .sum();
        let largest_lean = kept
            .iter()
            .map(|&(k, h)| {
                let (px, py) = self.position(k);
                (a * h * px - h * m.0).hypot(a * h * py - h * m.1)
            })
            .fold(0.0, f64::max);
        unexplained <= 0.25 * scatter && largest_lean > cell
    }
}

/// The centre of `f`'s bounding box, world metres (east, north).
/// Fewest buildings [`estimate_camera`] rests a perspective centre on (five unknowns, two
/// equations a building, and one more building than the bare minimum to show a misfit).
pub const MIN_CAMERA_BUILDINGS: usize = 4;

/// Least fraction of the buildings with a clear estimate that must be off the scene's shift by
/// more than a cell (and at least [`MIN_CAMERA_BUILDINGS`]) before a perspective centre is
/// sought. A frame photo's leans grow with height and distance from the nadir, so many roofs
/// lean at once; a few off among thousands (a city's footprints beside neighbours whose edges
/// fool the search: 26 of 6,250 in the city bench) are flagged `footprint_off_photo`, and the
/// search for a camera, which measures every footprint a second time, would find none.
pub const MIN_CAMERA_FRACTION: f64 = 0.1;

/// The solution of the 5 × 5 system `a·x = b` by Gaussian elimination with partial pivoting;
/// `None` when `a` is singular (relative pivot below 1e-12).
fn solve5(mut a: [[f64; 5]; 5], mut b: [f64; 5]) -> Option<[f64; 5]> {
    let scale = a.iter().flatten().fold(0.0f64, |m, v| m.max(v.abs()));
    for col in 0..5 {
        let piv = (col..5).max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))?;
        if a[piv][col].is_nan() || a[piv][col].abs() <= 1e-12 * scale {
            return None;
        }
        a.swap(col, piv);
        b.swap(col, piv);
        for r in col + 1..5 {
            let f = a[r][col] / a[col][col];
            let pivot = a[col];
            for (x, p) in a[r][col..].iter_mut().zip(&pivot[col..]) {
                *x -= f * p;
            }
            b[r] -= f * b[col];
        }
    }
    let mut x = [0.0; 5];
    for r in (0..5).rev() {
        let s: f64 = (r + 1..5).map(|c| a[r][c] * x[c]).sum();
        x[r] = (b[r] - s) / a[r][r];
    }
    Some(x)
}

/// `fp` moved by `(east_m, north_m)`.
pub fn moved(fp: &Footprint, east_m: f64, north_m: f64) -> Footprint {
    Footprint {
        rings: fp
            .rings
            .iter()
            .map(|r| r.iter().map(|&(x, y)| (x + east_m, y + north_m)).collect())
            .collect(),
        area: fp.area,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::crs::Crs;
    use crate::grid::Grid;
    use crate::raster::Colour;
    use crate::raster::Raster;

    /// Shadows fall to the north.
    const NORTH: (f64, f64) = (0.0, 1.0);

    /// 60 × 60 m of 0.5 m cells: grass 90–102, a 10 × 8 m roof 170 at x 20..30, y 30..38 with
    /// its shadow (35) 4 m to the north.
    fn photo() -> Colour {
        photo_with(170, 4.0)
    }

    /// [`photo`] with a roof of grey `roof` and a shadow `shadow_m` metres long.
    fn photo_with(roof: u8, shadow_m: f64) -> Colour {
        let g = Grid::north_up(0.0, 60.0, 0.5, 120, 120, Crs::epsg(32632));
        let data = (0..g.len())
            .map(|i| {
                let (x, y) = g.cell_centre(i % 120, i / 120);
                let v = if (20.0..30.0).contains(&x) && (30.0..38.0).contains(&y) {
                    roof
                } else if (20.0..30.0).contains(&x) && (38.0..38.0 + shadow_m).contains(&y) {
                    35
                } else {
                    90 + ((i * 7919) % 13) as u8
                };
                [v, v, v, 255]
            })
            .collect();
        Raster::new(g, data)
    }

    fn square(x0: f64, y0: f64) -> Footprint {
        Footprint::new(vec![vec![vec![
            (x0, y0),
            (x0 + 10.0, y0),
            (x0 + 10.0, y0 + 8.0),
            (x0, y0 + 8.0),
        ]]])
        .unwrap()
    }

    #[test]
    fn a_footprint_two_metres_off_is_moved_onto_its_roof() {
        let p = photo();
        for (dx, dy) in [(0.0, 0.0), (2.0, -1.5), (-2.7, 2.2), (1.25, 0.0)] {
            let s = estimate(
                &square(20.0 + dx, 30.0 + dy),
                &RowBand::whole(&p),
                NORTH,
                &Reach::square(3.0),
            )
            .unwrap();
            assert!(
                (s.east_m + dx).abs() <= 0.25 && (s.north_m + dy).abs() <= 0.25,
                "off by ({dx}, {dy}): {s:?}"
            );
            assert!(s.counts(), "{s:?}");
        }
    }

    #[test]
    fn a_reach_without_lean_is_the_square_and_with_one_follows_it() {
        let square = Reach::square(3.0).in_pixels(0.5, -0.5);
        for (x, y) in [(6.0, -6.0), (0.0, 6.0), (-5.5, 2.5)] {
            assert!(square.contains(x, y), "{x} {y}");
        }
        for (x, y) in [(6.5, 0.0), (0.0, -6.125), (7.0, 7.0)] {
            assert!(!square.contains(x, y), "{x} {y}");
        }
        // Leaning 12 m east and 9 m north (24 and -18 pixels), ±3 m (6 pixels) either side.
        let leaning = Reach {
            across_m: 3.0,
            lean_m: (12.0, 9.0),
            from_m: (0.0, 0.0),
        }
        .in_pixels(0.5, -0.5);
        for (x, y) in [
            (0.0, 0.0),
            (12.0, -9.0),
            (24.0, -18.0),
            (30.0, -24.0),
            (6.0, 0.0),
        ] {
            assert!(leaning.contains(x, y), "{x} {y}");
        }
        for (x, y) in [(-7.0, 0.0), (31.0, -18.0), (12.0, 6.0), (0.0, -13.0)] {
            assert!(!leaning.contains(x, y), "{x} {y}");
        }
        assert_eq!(leaning.bounds(), (-6.0, -24.0, 30.0, 6.0));
    }

    #[test]
    fn a_roof_leaning_beyond_max_shift_is_found_along_its_lean() {
        // The roof seen 7 m east and 5 m north of its footprint: beyond ±3 m, within the lean
        // of the heights sought from a camera 400 m up whose nadir is 280 m west and 200 m south.
        let p = photo();
        let fp = square(20.0 - 7.0, 30.0 - 5.0);
        let (x, y) = fp.bbox_centre();
        let camera = PerspectiveCentre {
            east: x - 280.0,
            north: y - 200.0,
            z: 400.0,
        };
        let band = RowBand::whole(&p);
        let near = estimate(&fp, &band, NORTH, &Reach::square(3.0)).unwrap();
        assert!((near.east_m - 7.0).abs() > 2.0, "{near:?}");
        let reach = Reach::leaning(&fp, &camera, 0.0, 3.0, 30.0);
        let s = estimate(&fp, &band, NORTH, &reach).unwrap();
        assert!(
            (s.east_m - 7.0).abs() <= 0.25 && (s.north_m - 5.0).abs() <= 0.25,
            "{reach:?}: {s:?}"
        );
        assert!(s.counts(), "{s:?}");
    }

    /// The mean contrast across `samples` moved by `(sx, sy)` pixels, read from the photo's
    /// pixels in columns `cols` and rows `rows` directly (bilinear between centres).
    fn contrast_by_hand(
        p: &Colour,
        cols: std::ops::Range<i64>,
        rows: std::ops::Range<i64>,
        samples: &[Sample],
        (sx, sy): (f64, f64),
    ) -> Option<f64> {
        let y = |c: i64, r: i64| {
            let v = p.data[(r * p.grid.width as i64 + c) as usize];
            (v[3] != 0).then(|| 0.299 * v[0] as f64 + 0.587 * v[1] as f64 + 0.114 * v[2] as f64)
        };
        let at = |x: f64, yy: f64| {
            let (c, r) = ((x - 0.5).floor() as i64, (yy - 0.5).floor() as i64);
            if !(cols.contains(&c) && cols.contains(&(c + 1))) {
                return None;
            }
            if !(rows.contains(&r) && rows.contains(&(r + 1))) {
                return None;
            }
            let (fx, fy) = (x - 0.5 - c as f64, yy - 0.5 - r as f64);
            Some(
                (1.0 - fy) * ((1.0 - fx) * y(c, r)? + fx * y(c + 1, r)?)
                    + fy * ((1.0 - fx) * y(c, r + 1)? + fx * y(c + 1, r + 1)?),
            )
        };
        let read: Vec<f64> = samples
            .iter()
            .filter_map(|s| {
                let (x, yy) = (s.at.0 + sx, s.at.1 + sy);
                let (o, i) = (
                    at(x + s.out.0 * ACROSS, yy + s.out.1 * ACROSS)?,
                    at(x - s.out.0 * ACROSS, yy - s.out.1 * ACROSS)?,
                );
                Some(if s.faces_shadow {
                    (i - o).max(0.0)
                } else {
                    (i - o).abs()
                })
            })
            .collect();
        (read.len() * 2 >= samples.len() && !read.is_empty())
            .then(|| read.iter().sum::<f64>() / read.len() as f64)
    }

    #[test]
    fn shifts_on_a_grid_read_what_the_moved_outline_reads() {
        // A rotated outline whose samples fall between centres, on a photo with nodata, shifted
        // by whole pixels up to the window's border and off it, and by eighths.
        let mut p = photo();
        for i in (0..p.data.len()).step_by(37) {
            p.data[i][3] = 0;
        }
        let band = RowBand::whole(&p);
        let fp = Footprint::new(vec![vec![vec![
            (21.3, 30.2),
            (29.1, 31.9),
            (27.6, 38.7),
            (19.9, 36.4),
        ]]])
        .unwrap();
        let samples = outline_samples(&fp, &band, NORTH);
        let luma = Luma::new(&band, (30, 90), (40, 100));
        let mut read = 0;
        for (centre, pitch, k) in [((0.0, 0.0), 1.0, 15), ((1.5, -0.5), 0.125, 6)] {
            let shifts = Shifts::new(&luma, &samples, centre, pitch, k);
            let at = |i: usize, c: f64| c + (i as f64 - k as f64) * pitch;
            for j in 0..=2 * k {
                for i in 0..=2 * k {
                    let (sx, sy) = (at(i, centre.0), at(j, centre.1));
                    let want = contrast_by_hand(&p, 30..90, 40..100, &samples, (sx, sy));
                    match (shifts.contrast(i, j), want) {
                        (Some(a), Some(b)) => {
                            read += 1;
                            assert!((a - b).abs() < 1e-9, "{sx} {sy}: {a} {b}")
                        }
                        (a, b) => assert_eq!(a, b, "{sx} {sy}"),
                    }
                }
            }
        }
        assert!(read > 100 && read < 31 * 31 + 13 * 13, "{read}");
    }

    /// A high sun's thin shadow has the strongest edge in the scene on its far side, a copy of
    /// the roof's north edge; a roof the tone of the grass around it gives its own outline
    /// little contrast. The outline stays on the roof, not on the shadow's far edge.
    #[test]
    fn a_thin_shadow_does_not_pull_the_outline_onto_its_far_edge() {
        for roof in [96, 80, 120] {
            let p = photo_with(roof, 1.5);
            for (dx, dy) in [(0.0, 0.0), (0.0, -1.0), (1.0, 1.0)] {
                let s = estimate(
                    &square(20.0 + dx, 30.0 + dy),
                    &RowBand::whole(&p),
                    NORTH,
                    &Reach::square(3.0),
                )
                .unwrap();
                assert!(
                    (s.east_m + dx).abs() <= 0.25 && (s.north_m + dy).abs() <= 0.25,
                    "roof {roof}, off by ({dx}, {dy}): {s:?}"
                );
            }
        }
    }

    /// Nine buildings on a 3 × 3 lattice 60 m apart around (1000, 2000), heights 6–22 m, seen
    /// from `camera` with the whole scene misregistered by `g`: each one's shift is `g` plus
    /// its exact lean `h·(p − N)/(Z − h)` (the estimate models `h ≪ Z`), plus `noise(k)`.
    fn leaning(
        camera: PerspectiveCentre,
        g: (f64, f64),
        noise: impl Fn(usize) -> (f64, f64),
    ) -> (Vec<Footprint>, Vec<Option<Shift>>, Vec<Option<f64>>) {
        let mut fps = Vec::new();
        let mut shifts = Vec::new();
        let mut heights = Vec::new();
        for k in 0..9 {
            let (x0, y0) = (
                940.0 + 60.0 * (k % 3) as f64,
                1940.0 + 60.0 * (k / 3) as f64,
            );
            let fp = square(x0, y0);
            let (cx, cy) = (x0 + 5.0, y0 + 4.0);
            let h = 6.0 + 2.0 * k as f64;
            let l = h / (camera.z - 100.0 - h);
            let (ne, nn) = noise(k);
            shifts.push(Some(Shift {
                east_m: g.0 + l * (cx - camera.east) + ne,
                north_m: g.1 + l * (cy - camera.north) + nn,
                peak_ratio: 10.0,
                along_lean: false,
            }));
            fps.push(fp);
            heights.push(Some(h));
        }
        (fps, shifts, heights)
    }

    #[test]
    fn a_perspective_centre_is_found_from_leans_and_heights() {
        // From 1500 m over ground at 100 m, nadir 300 m south-west of the buildings, the scene
        // 0.8 m off: leans of 1–4 m, all nearly one way — a shift alone cannot explain them,
        // their growth with height does.
        let truth = PerspectiveCentre {
            east: 780.0,
            north: 1790.0,
            z: 1600.0,
        };
        let (fps, shifts, heights) = leaning(truth, (0.8, -0.3), |_| (0.0, 0.0));
        let c = estimate_camera(&fps, &shifts, &heights, 100.0, 0.5).unwrap();
        assert!(
            (c.east - truth.east).hypot(c.north - truth.north) < 20.0,
            "{c:?}"
        );
        assert!((c.z - truth.z).abs() < 40.0, "{c:?}");
        // Estimates a quarter metre off at random still find it, less exactly.
        let jitter = |k: usize| {
            let r = |s: usize| ((k * 7919 + s * 104729) % 1000) as f64 / 1000.0 - 0.5;
            (0.5 * r(1), 0.5 * r(2))
        };
        let (fps, shifts, heights) = leaning(truth, (0.8, -0.3), jitter);
        let c = estimate_camera(&fps, &shifts, &heights, 100.0, 0.5).unwrap();
        assert!(
            (c.east - truth.east).hypot(c.north - truth.north) < 150.0,
            "{c:?}"
        );
        assert!((c.z - truth.z).abs() < 300.0, "{c:?}");
    }

    #[test]
    fn a_few_estimates_on_a_neighbours_edges_do_not_move_the_scene_along_the_leans() {
        use std::f64::consts::FRAC_1_SQRT_2;
        // From 500 m over ground at 100 m, the nadir 300 m south-west of the buildings: their
        // radial directions are within ±15° of north-east, so the shift along it rests on that
        // spread. Exact footprints (no shift); four of nine clear estimates found a
        // neighbour's edge 2.5 m across their lean (the town bench, 500 m, window 15-0).
        let camera = PerspectiveCentre {
            east: 780.0,
            north: 1790.0,
            z: 600.0,
        };
        let (fps, shifts, _) = leaning(camera, (0.0, 0.0), |k| {
            let across = if k % 2 == 1 { -2.5 } else { 0.0 };
            (-across * FRAC_1_SQRT_2, across * FRAC_1_SQRT_2)
        });
        let (g, leans) = with_camera(&fps, &shifts, &camera, 0.5);
        let (ge, gn, _) = g.unwrap();
        assert!(ge.hypot(gn) < 0.25, "scene shift ({ge:.2}, {gn:.2}) m");
        for k in (0..9).step_by(2) {
            let s = shifts[k].unwrap();
            let off = (s.east_m - leans[k].0).hypot(s.north_m - leans[k].1);
            assert!(
                off < 0.25,
                "building {k}: lean {:?}, {off:.2} m off",
                leans[k]
            );
        }
    }

    #[test]
    fn an_orthophoto_has_no_perspective_centre() {
        // Every building off by the same shift and a little noise: nothing leans.
        let far = PerspectiveCentre {
            east: 0.0,
            north: 0.0,
            z: 1e9,
        };
        let jitter = |k: usize| (0.1 * ((k % 3) as f64 - 1.0), 0.1 * ((k / 3) as f64 - 1.0));
        let (fps, shifts, heights) = leaning(far, (1.5, 0.7), jitter);
        assert_eq!(estimate_camera(&fps, &shifts, &heights, 100.0, 0.5), None);
        // Leans under a cell change no height: not worth a camera either (from 30 km up).
        let high = PerspectiveCentre {
            east: 780.0,
            north: 1790.0,
            z: 30_000.0,
        };
        let (fps, shifts, heights) = leaning(high, (0.0, 0.0), |_| (0.0, 0.0));
        assert_eq!(estimate_camera(&fps, &shifts, &heights, 100.0, 0.5), None);
        // Too few buildings with a height to tell.
        let (fps, shifts, mut heights) = leaning(
            PerspectiveCentre {
                east: 780.0,
                north: 1790.0,
                z: 1600.0,
            },
            (0.0, 0.0),
            |_| (0.0, 0.0),
        );
        heights
            .iter_mut()
            .skip(MIN_CAMERA_BUILDINGS - 1)
            .for_each(|h| *h = None);
        assert_eq!(estimate_camera(&fps, &shifts, &heights, 100.0, 0.5), None);
    }

    #[test]
    fn scene_shift_is_the_median_of_the_clear_estimates() {
        let s = |e, n, r| {
            Some(Shift {
                east_m: e,
                north_m: n,
                peak_ratio: r,
                along_lean: false,
            })
        };
        let all = [
            s(1.0, -2.0, 3.0),
            s(1.2, -2.1, 2.0),
            s(9.0, 9.0, 1.1),
            None,
            s(0.9, -1.8, 4.0),
        ];
        assert_eq!(scene_shift(&all), Some((1.0, -2.0, 3)));
        assert_eq!(scene_shift(&[s(1.0, 1.0, 1.0)]), None);
    }
}
