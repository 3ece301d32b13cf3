//! `dbms render`: a ray-casting preview of a paged tile set (the Hughes patent's stepping loop).
//!
//! A pinhole [`Viewpoint`] casts one ray per pixel. Each ray is moved into the database's local
//! cell space (relative to the grid origin, so UTM-sized eyes keep full precision) and
//! [marched](march::march) through the max-Z hierarchy: coarse steps through empty space,
//! descents where it may hit, exact integer-boundary stepping at level 0 — or, for a level
//! camera, with all the rays of its image column at once ([`column`](mod@column)). Range
//! thresholds `TH_k = L_k · N_pix / H_fov` (cell edge `L_k` in metres, field of view in
//! radians) stop a ray at a coarse level's average colour at long range. Rays that leave the
//! database take the [sky](sky::sky), or with `repeat` continue through copies of it (modulo
//! arithmetic).
//! [`render_top`] is the orthographic map of the whole database or of a window of it.
//!
//! Invariants: pages come only through [`TileReader`] (bounded cache, counted reads); the same
//! tile set and camera give the same pixels whatever the thread count; without range thresholds
//! the hierarchical and level-0 traversals give bit-identical frames. A partial cell (`state` 1)
//! is hit on the solid runs of its voxel column (the page's bricks), so rays pass under
//! overhangs and through holes; the range is the distance to the run's face.
//! Conventions and figures: `docs/render.md`.

pub mod camera;
pub mod column;
pub mod flight;
pub mod march;
#[cfg(feature = "testing")]
pub mod mesh;
pub mod path;
pub mod ray;
pub mod regions;
pub mod sampler;
pub mod sensor;
pub mod sky;

pub use camera::{Attitude, Viewpoint};
pub use march::{Face, Hit, Plan, Span, Traversal};

use crate::error::{Error, Result};
use crate::grid::Bounds;
use crate::io::atomic::write_bytes_atomic;
use crate::tiles::{ReaderStats, TileReader, STATE_PARTIAL};
use ray::{Ray, Rays};
use rayon::prelude::*;
use sampler::{ColumnCache, Sampler};
use serde::Serialize;
use std::collections::BTreeSet;
use std::path::Path;
use std::time::Instant;

/// Farthest an eye may be from the grid origin, in level-0 cells (keeps every cell index and
/// boundary time exact in f64 / i64; a farther eye is a CRS mistake).
pub const MAX_EYE_CELLS: f64 = (1u64 << 40) as f64;

/// With `repeat`, rays that hit nothing stop after this many database diagonals of range.
pub const REPEAT_RANGE_DIAGONALS: f64 = 8.0;

/// How to render a perspective view.
#[derive(Debug, Clone, PartialEq)]
pub struct ViewOptions {
    /// Traversal strategy.
    pub traversal: Traversal,
    /// Use range thresholds (coarse colour at long range).
    pub lod: bool,
    /// Repeat the database over the plane by modulo arithmetic.
    pub repeat: bool,
    /// Range haze: distance at which `1 − 1/e` of a colour is haze, metres (`None`: off).
    pub visibility: Option<f64>,
    /// The sky and the haze colour (daylight, or a sensor's: [`sensor::view`]).
    pub backdrop: sky::Backdrop,
    /// Stop looking beyond this range, metres (`None`: the database's edge, or
    /// [`REPEAT_RANGE_DIAGONALS`] diagonals with `repeat`).
    pub max_range: Option<f64>,
    /// Rays per pixel, a square `n²` (1, 4, 9, 16, …): one per cell of an `n × n` grid over the
    /// pixel, each at a fixed pseudo-random point of its cell; the pixel's colour is their mean.
    /// 1 casts the one ray through the pixel's centre.
    pub samples: usize,
    /// Blend two levels' colours around each range threshold instead of switching
    /// ([`march::blend_weight`]).
    pub blend: bool,
    /// March the rays of each image column with one walk (the patent's vertical scan-line
    /// coherence, [`column`](mod@column)); used only where image columns are vertical planes
    /// (zero roll and pitch). The image is the same either way.
    pub coherence: bool,
}

impl Default for ViewOptions {
    fn default() -> Self {
        ViewOptions {
            traversal: Traversal::Hierarchical,
            lod: true,
            repeat: false,
            visibility: None,
            backdrop: sky::Backdrop::Daylight,
            max_range: None,
            samples: 1,
            blend: false,
            coherence: true,
        }
    }
}

/// Most rays per pixel `--samples` takes (a 16 × 16 grid).
pub const MAX_SAMPLES: usize = 256;

/// The side `n` of the `n × n` grid of `samples` rays per pixel, or an error naming the fix.
pub fn sample_grid(samples: usize) -> Result<usize> {
    let n = (samples as f64).sqrt().round() as usize;
    if samples == 0 || samples > MAX_SAMPLES || n * n != samples {
        return Err(Error::msg(format!(
            "--samples {samples}: rays per pixel must be a square from 1 to {MAX_SAMPLES}"
        ))
        .fix("use 1, 4, 9, 16, 25, 36, 49 or 64 (an n × n grid over each pixel)"));
    }
    Ok(n)
}

/// Where in its cell of the `n × n` grid sample `s` of pixel `p` looks: a fixed pseudo-random
/// point of `[0, 1)²` (two SplitMix64 draws seeded by the pair), so frames are reproducible to
/// the byte.
fn jitter(p: usize, s: usize) -> (f64, f64) {
    let mix = |x: u64| {
        let mut z = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    };
    let unit = |bits: u64| (bits >> 11) as f64 / (1u64 << 53) as f64;
    let a = mix((p as u64) << 16 | s as u64);
    (unit(a), unit(mix(a)))
}

/// What rendering a frame did (for `--json`).
#[derive(Debug, Clone, Serialize)]
pub struct RenderStats {
    /// Rays cast: one per pixel, plus `samples` per pixel when supersampling (the centre ray
    /// then gives only the range).
    pub rays: u64,
    /// Rays that hit the database.
    pub hits: u64,
    /// Cells visited by all rays, over all levels; a column marched as one
    /// ([`column`](mod@column)) counts each cell its walk visits once, for all the column's rays.
    pub cells_stepped: u64,
    /// Distinct pages the rays asked for.
    pub pages_touched: usize,
    /// Reader counters for this frame (pages and bytes read from the file, cache hits).
    pub reader: ReaderStats,
    /// Wall-clock time of the frame, seconds.
    pub seconds: f64,
    /// Rays per second.
    pub rays_per_second: f64,
}

/// A rendered image: RGB pixels and the range of each, row-major from the top-left.
#[derive(Debug, Clone)]
pub struct Frame {
    /// Width, pixels.
    pub width: usize,
    /// Height, pixels.
    pub height: usize,
    /// Colour of each pixel.
    pub rgb: Vec<[u8; 3]>,
    /// Range of each pixel's hit, metres; `+inf` where the ray saw the sky.
    pub range: Vec<f32>,
    /// What it took.
    pub stats: RenderStats,
}

/// The database box and level geometry a frame needs, read once.
struct Scene {
    width: i64,
    height: i64,
    origin: [f64; 2],
    cell: [f64; 2],
    /// Highest `max_z` of the whole tile set, metres (NaN when it has no data).
    z_max: f64,
    scales: Vec<i64>,
}

impl Scene {
    fn of(reader: &TileReader) -> Result<Scene> {
        let info = reader.info();
        if info.grid.crs.geographic {
            return Err(Error::file(
                reader.path(),
                "the tile set's CRS is geographic (degrees); rendering needs metres on every axis",
            )
            .fix("ingest the database in a projected CRS such as UTM"));
        }
        let top = info.levels.len() - 1;
        let l = &info.levels[top];
        let mut z_max = f32::NAN;
        for ty in 0..l.pages_y {
            for tx in 0..l.pages_x {
                z_max = reader
                    .page(top, tx, ty)?
                    .max_z
                    .iter()
                    .fold(z_max, |m, &z| m.max(z));
            }
        }
        let t = &info.grid.transform;
        Ok(Scene {
            width: info.grid.width as i64,
            height: info.grid.height as i64,
            origin: [t.origin_x, t.origin_y],
            cell: [t.cell_x, t.cell_y],
            z_max: z_max as f64,
            scales: march::level_scales(info),
        })
    }

    /// The eye in local cell space.
    fn local(&self, x: f64, y: f64) -> (f64, f64) {
        (
            (x - self.origin[0]) / self.cell[0],
            (y - self.origin[1]) / self.cell[1],
        )
    }

    /// Coarsest level usable: every level, or with `repeat` those whose cells tile the plane.
    fn top(&self, repeat: bool) -> usize {
        let n = self.scales.len() - 1;
        match repeat {
            false => n,
            true => (0..=n)
                .take_while(|&k| {
                    self.width % self.scales[k] == 0 && self.height % self.scales[k] == 0
                })
                .last()
                .unwrap_or(0),
        }
    }

    fn diagonal_m(&self) -> f64 {
        (self.width as f64 * self.cell[0]).hypot(self.height as f64 * self.cell[1])
    }

    /// The times `τ` a ray with `ray`'s horizontal motion is over the database's footprint
    /// (all of them with `repeat`).
    fn footprint(&self, ray: &Ray, repeat: bool) -> (f64, f64) {
        if repeat {
            return (f64::NEG_INFINITY, f64::INFINITY);
        }
        let (a, b) = ray.u.slab(self.width);
        let (c, d) = ray.v.slab(self.height);
        (a.max(c), b.min(d))
    }

    /// The part of `ray` worth stepping: inside the box (unless repeating), below `z_max`,
    /// within `max_range` metres.
    fn span(&self, ray: &Ray, repeat: bool, max_range: f64) -> Option<Span> {
        self.span_within(ray, self.footprint(ray, repeat), max_range)
    }

    /// [`Scene::span`] for a ray over the footprint during `footprint` ([`Scene::footprint`]).
    fn span_within(&self, ray: &Ray, footprint: (f64, f64), max_range: f64) -> Option<Span> {
        let far = match max_range.is_finite() {
            true => max_range / ray.norm,
            false => f64::INFINITY,
        };
        let (mut t0, mut t1) = (footprint.0.max(0.0), far.min(footprint.1));
        if self.z_max.is_nan() {
            return None;
        }
        if ray.z0 > self.z_max {
            t0 = t0.max(ray.time_at_height(self.z_max).filter(|_| ray.dz < 0.0)?);
        } else if ray.dz > 0.0 {
            t1 = t1.min(ray.time_at_height(self.z_max).expect("rising"));
        }
        (t0 < t1).then_some(Span { t0, t1 })
    }
}

/// Render the perspective view of `camera` over the tile set behind `reader`.
pub fn render_view(reader: &TileReader, camera: &Viewpoint, opts: &ViewOptions) -> Result<Frame> {
    camera.validate()?;
    if let Some(v) = opts.visibility.filter(|v| !(*v > 0.0 && v.is_finite())) {
        return Err(Error::msg(format!(
            "--haze {v}: visibility must be a positive number of metres"
        ))
        .fix("e.g. --haze 5000"));
    }
    if let Some(r) = opts.max_range.filter(|r| r.is_nan() || *r <= 0.0) {
        return Err(Error::msg(format!(
            "--max-range {r}: must be a positive number of metres"
        )));
    }
    let n = sample_grid(opts.samples)?;
    let start = Instant::now();
    let before = reader.stats();
    let view = View::new(reader, camera, opts, n)?;
    let (w, h) = (camera.width, camera.height);
    // One sampler for each run of lines a worker takes: its page memo stays warm from line to
    // line (a sampler is a cache of pure lookups, so which lines share one changes no pixel).
    let sampler = || {
        let base = Sampler::new(reader, opts.repeat, &view.column_cache);
        view.regions.attach(base)
    };
    let (lines, order) = if view.coherent {
        // Each column bottom-up (the order of the patent's vertical scan lines).
        let columns = (0..w)
            .into_par_iter()
            .map_init(sampler, |s, i| {
                view.trace(&(0..h).rev().map(|j| (i, j)).collect::<Vec<_>>(), s)
            })
            .collect::<Result<_>>()?;
        (columns, Order::ColumnsUp)
    } else {
        let rows = (0..h)
            .into_par_iter()
            .map_init(sampler, |s, j| {
                view.trace(&(0..w).map(|i| (i, j)).collect::<Vec<_>>(), s)
            })
            .collect::<Result<_>>()?;
        (rows, Order::Rows)
    };
    Ok(assemble(w, h, lines, order, reader, before, start))
}

/// What every ray of one perspective frame shares, fixed before the first is cast.
struct View<'a> {
    camera: &'a Viewpoint,
    opts: &'a ViewOptions,
    scene: Scene,
    /// The eye in local cell space (`u`, `v`) and its height, metres.
    eye: [f64; 3],
    plan: Plan,
    basis: camera::Basis,
    /// Range beyond which rays stop looking, metres.
    max_range: f64,
    /// A pixel centre's place on the image plane, per image column and per row.
    x_terms: Vec<f64>,
    y_terms: Vec<f64>,
    /// Rays per pixel along each axis (`samples = n²`).
    n: usize,
    /// Image columns are marched as one ([`column`](mod@column)).
    coherent: bool,
    column_cache: ColumnCache,
    /// The tile set's regions, which rays descend into ([`regions`]).
    regions: regions::RegionFrames<'a>,
}

impl<'a> View<'a> {
    /// The frame's geometry: scene, eye (checked to be near the database and in open air),
    /// range thresholds and the image plane's terms.
    fn new(
        reader: &'a TileReader,
        camera: &'a Viewpoint,
        opts: &'a ViewOptions,
        n: usize,
    ) -> Result<View<'a>> {
        let scene = Scene::of(reader)?;
        let [ex, ey, ez] = camera.eye;
        let (u0, v0) = scene.local(ex, ey);
        if u0.abs().max(v0.abs()) > MAX_EYE_CELLS {
            return Err(Error::msg(format!(
                "--eye {ex},{ey},{ez}: the eye is over {MAX_EYE_CELLS:e} cells from the database"
            ))
            .fix("give X,Y in the tile set's CRS (see `dbms tiles`)"));
        }
        check_eye_above_terrain(reader, opts.repeat, u0, v0, camera)?;
        let per_pixel = camera.hfov.to_radians() / camera.width as f64;
        let plan = Plan::of_levels(
            reader.info(),
            scene.top(opts.repeat),
            opts.traversal,
            opts.lod,
            opts.blend,
            per_pixel,
        );
        let max_range = opts.max_range.unwrap_or(if opts.repeat {
            REPEAT_RANGE_DIAGONALS * scene.diagonal_m()
        } else {
            f64::INFINITY
        });
        let basis = camera.basis();
        let x_terms = (0..camera.width)
            .map(|i| basis.x_term(i as f64 + 0.5))
            .collect();
        let y_terms = (0..camera.height)
            .map(|j| basis.y_term(j as f64 + 0.5))
            .collect();
        let regions = regions::RegionFrames::open(reader, &plan, per_pixel, opts.repeat)?;
        // Image columns are vertical half-planes through the eye only without roll and pitch;
        // regions are marched ray by ray.
        let coherent = opts.coherence
            && camera.attitude.roll == 0.0
            && camera.attitude.pitch == 0.0
            && regions.is_empty();
        Ok(View {
            camera,
            opts,
            scene,
            eye: [u0, v0, ez],
            plan,
            basis,
            max_range,
            x_terms,
            y_terms,
            n,
            coherent,
            column_cache: ColumnCache::default(),
            regions,
        })
    }

    /// Trace one line of `pixels` (`(column, row)`, an image row or an image column bottom-up)
    /// with `sampler` (its pages newly asked for become the line's `touched`).
    fn trace(&self, pixels: &[(usize, usize)], sampler: &mut Sampler) -> Result<Line> {
        let (scene, opts) = (&self.scene, self.opts);
        let mut line = Line::new(pixels.len());
        // The centre rays: the range is always theirs, so the range image does not depend on
        // the sampling; they are the rays that share a column's path. Rays sharing a
        // horizontal direction share their axes and footprint times.
        let mut centre_rays = Rays::new(self.eye, scene.cell);
        let mut footprint = (0.0, 0.0);
        let (rays, spans): (Vec<Ray>, Vec<Option<Span>>) = pixels
            .iter()
            .map(|&(i, j)| {
                let through = self.basis.through_terms(self.x_terms[i], self.y_terms[j]);
                let (ray, same) = centre_rays.ray(through);
                if !same {
                    footprint = scene.footprint(&ray, opts.repeat);
                }
                (ray, scene.span_within(&ray, footprint, self.max_range))
            })
            .unzip();
        let hits = if self.coherent && column::shares_path(&rays) {
            let (hits, steps) = column::march_column(&rays, &spans, sampler, &self.plan)?;
            line.steps += steps;
            hits
        } else {
            let mut hits = Vec::with_capacity(rays.len());
            for (ray, span) in rays.iter().zip(&spans) {
                hits.push(line.march(ray, *span, sampler, &self.plan)?);
            }
            hits
        };
        for ((&(i, j), ray), hit) in pixels.iter().zip(&rays).zip(hits) {
            line.rays += 1;
            line.hits += u64::from(hit.is_some());
            let rgb = match self.n {
                1 => colour(hit, ray, opts),
                _ => self.supersample(i, j, &mut line, sampler)?,
            };
            line.rgb.push(rgb);
            line.range.push(hit.map_or(f32::INFINITY, |h| h.t as f32));
        }
        line.touched = std::mem::take(&mut sampler.touched);
        Ok(line)
    }

    /// Pixel `(i, j)`'s colour as the mean of its `n²` jittered rays.
    fn supersample(
        &self,
        i: usize,
        j: usize,
        line: &mut Line,
        sampler: &mut Sampler,
    ) -> Result<[u8; 3]> {
        let n = self.n;
        let [u0, v0, ez] = self.eye;
        let mut sum = [0u32; 3];
        for s in 0..n * n {
            let (a, b) = jitter(j * self.camera.width + i, s);
            let x = i as f64 + ((s % n) as f64 + a) / n as f64;
            let y = j as f64 + ((s / n) as f64 + b) / n as f64;
            let ray = Ray::new(u0, v0, ez, self.basis.through(x, y), self.scene.cell);
            let span = self.scene.span(&ray, self.opts.repeat, self.max_range);
            let hit = line.march(&ray, span, sampler, &self.plan)?;
            line.rays += 1;
            line.hits += u64::from(hit.is_some());
            let c = colour(hit, &ray, self.opts);
            (0..3).for_each(|k| sum[k] += u32::from(c[k]));
        }
        let m = (n * n) as u32;
        Ok(sum.map(|v| ((v + m / 2) / m) as u8))
    }
}

/// Error if the eye is inside the solid part of any level-0 column whose closed cell contains
/// it: at or below the top of a height-field column, or within a run of a voxel column (the
/// gap under an arch is open air).
fn check_eye_above_terrain(
    reader: &TileReader,
    repeat: bool,
    u: f64,
    v: f64,
    camera: &Viewpoint,
) -> Result<()> {
    let near = |x: f64| {
        let k = x.floor() as i64;
        if x == x.floor() {
            vec![k - 1, k]
        } else {
            vec![k]
        }
    };
    let column_cache = ColumnCache::default();
    let mut sampler = Sampler::new(reader, repeat, &column_cache);
    for c in near(u) {
        for r in near(v) {
            let Some(cell) = sampler.cell(0, c, r)? else {
                continue;
            };
            let [x, y, z] = camera.eye;
            if cell.state == STATE_PARTIAL {
                if let Some(run) = sampler
                    .column(c, r)?
                    .iter()
                    .find(|run| z >= run.bottom as f64 && z <= run.top as f64)
                {
                    return Err(Error::msg(format!(
                        "--eye {x},{y},{z}: the eye is inside a voxel column, solid there from {:.2} m to {:.2} m",
                        run.bottom, run.top
                    ))
                    .fix("move the eye into the open air (above, or in a gap under an overhang)"));
                }
            } else if !cell.max_z.is_nan() && z <= cell.max_z as f64 {
                return Err(Error::msg(format!(
                    "--eye {x},{y},{z}: the eye is at or below the terrain, whose top there is {:.2} m",
                    cell.max_z
                ))
                .fix("raise Z above the ground or move the eye"));
            }
        }
    }
    Ok(())
}

/// How the [`Line`]s a frame was traced in lie in the image.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Order {
    /// Each line is an image row, left to right, rows top to bottom.
    Rows,
    /// Each line is an image column, bottom to top, columns left to right.
    ColumnsUp,
}

/// One line of pixels (a row, or a column) as a worker renders it.
struct Line {
    rgb: Vec<[u8; 3]>,
    range: Vec<f32>,
    rays: u64,
    steps: u64,
    hits: u64,
    touched: BTreeSet<(usize, usize, usize)>,
}

impl Line {
    /// March one ray (no hit without a span), counting its steps.
    fn march(
        &mut self,
        ray: &Ray,
        span: Option<Span>,
        sampler: &mut Sampler,
        plan: &Plan,
    ) -> Result<Option<Hit>> {
        let Some(span) = span else {
            return Ok(None);
        };
        let (hit, steps) = march::march(ray, span, sampler, plan)?;
        self.steps += steps;
        Ok(hit)
    }

    fn new(len: usize) -> Line {
        Line {
            rgb: Vec::with_capacity(len),
            range: Vec::with_capacity(len),
            rays: 0,
            steps: 0,
            hits: 0,
            touched: BTreeSet::new(),
        }
    }
}

/// What `ray` shows: its hit, shaded and hazed, or the sky.
fn colour(hit: Option<Hit>, ray: &Ray, opts: &ViewOptions) -> [u8; 3] {
    match hit {
        Some(h) => opts.backdrop.shade(h.colour, h.face, h.t, opts.visibility),
        None => opts.backdrop.sky(ray.sin_elevation()),
    }
}

/// The frame of `lines` (traced in `order`) with the frame's counts; the pixels are placed by
/// image row in parallel (each row takes its pixel from every line), so no core waits while one
/// copies the whole frame.
fn assemble(
    width: usize,
    height: usize,
    lines: Vec<Line>,
    order: Order,
    reader: &TileReader,
    before: ReaderStats,
    start: Instant,
) -> Frame {
    let mut frame_rgb = vec![[0u8; 3]; width * height];
    let mut frame_range = vec![0f32; width * height];
    frame_rgb
        .par_chunks_mut(width)
        .zip(frame_range.par_chunks_mut(width))
        .enumerate()
        .for_each(|(j, (rgb, range))| match order {
            Order::Rows => {
                rgb.copy_from_slice(&lines[j].rgb);
                range.copy_from_slice(&lines[j].range);
            }
            Order::ColumnsUp => {
                let m = height - 1 - j;
                for ((pixel, r), line) in rgb.iter_mut().zip(range.iter_mut()).zip(&lines) {
                    (*pixel, *r) = (line.rgb[m], line.range[m]);
                }
            }
        });
    let (mut rays, mut steps, mut hits, mut touched) = (0, 0, 0, BTreeSet::new());
    for line in lines {
        rays += line.rays;
        steps += line.steps;
        hits += line.hits;
        touched.extend(line.touched);
    }
    let after = reader.stats();
    let seconds = start.elapsed().as_secs_f64();
    Frame {
        width,
        height,
        rgb: frame_rgb,
        range: frame_range,
        stats: RenderStats {
            rays,
            hits,
            cells_stepped: steps,
            pages_touched: touched.len(),
            reader: ReaderStats {
                pages_read: after.pages_read - before.pages_read,
                bytes_read: after.bytes_read - before.bytes_read,
                cache_hits: after.cache_hits - before.cache_hits,
            },
            seconds,
            rays_per_second: rays as f64 / seconds.max(1e-9),
        },
    }
}

/// Render the orthographic map of `window` (`None`: the whole database), `width × height`
/// pixels, looking straight down: the patent's god's-eye view. Each pixel shows the cell under
/// its centre; with `lod`, from the coarsest level whose cells are no wider than a pixel's
/// footprint. Range is the depth below the database's highest point, metres (`+inf` over
/// nodata and outside the database, drawn black).
pub fn render_top(
    reader: &TileReader,
    width: usize,
    height: usize,
    lod: bool,
    window: Option<Bounds>,
) -> Result<Frame> {
    camera::check_size(width, height)?;
    let start = Instant::now();
    let before = reader.stats();
    let scene = Scene::of(reader)?;
    let (u0, v0, sx, sy) = top_window(&scene, reader, window, width, height)?;
    let level = match lod {
        true => scene
            .scales
            .iter()
            .rposition(|&s| s as f64 <= sx.min(sy))
            .unwrap_or(0),
        false => 0,
    };
    let s = scene.scales[level];
    let rows: Vec<Line> = (0..height)
        .into_par_iter()
        .map(|j| {
            let no_columns = ColumnCache::default(); // the top view never looks inside a column
            let mut sampler = Sampler::new(reader, false, &no_columns);
            let mut row = Line::new(width);
            let r = ((v0 + (j as f64 + 0.5) * sy).floor() as i64).div_euclid(s);
            for i in 0..width {
                let c = ((u0 + (i as f64 + 0.5) * sx).floor() as i64).div_euclid(s);
                row.rays += 1;
                row.steps += 1;
                match sampler.cell(level, c, r)? {
                    Some(cell) if !cell.max_z.is_nan() => {
                        row.hits += 1;
                        row.rgb
                            .push([cell.colour[0], cell.colour[1], cell.colour[2]]);
                        row.range.push((scene.z_max - cell.max_z as f64) as f32);
                    }
                    _ => {
                        row.rgb.push([0, 0, 0]);
                        row.range.push(f32::INFINITY);
                    }
                }
            }
            row.touched = sampler.touched;
            Ok(row)
        })
        .collect::<Result<_>>()?;
    Ok(assemble(
        width,
        height,
        rows,
        Order::Rows,
        reader,
        before,
        start,
    ))
}

/// `window` (`None`: the whole database) in level-0 cells for a `width × height` map: left
/// column `u0`, top row `v0`, and cells per pixel `sx`, `sy`. A window that is malformed or
/// misses the database is an error.
fn top_window(
    scene: &Scene,
    reader: &TileReader,
    window: Option<Bounds>,
    width: usize,
    height: usize,
) -> Result<(f64, f64, f64, f64)> {
    let Some(w) = window else {
        return Ok((
            0.0,
            0.0,
            scene.width as f64 / width as f64,
            scene.height as f64 / height as f64,
        ));
    };
    let shown = format!("{},{},{},{}", w.min_x, w.min_y, w.max_x, w.max_y);
    let w = w.check("--window", &shown)?;
    if w.intersection(&reader.info().grid.bounds()).is_none() {
        return Err(Error::msg(format!(
            "--window {shown}: the window does not overlap the database"
        ))
        .fix("give it in the tile set's CRS (see `dbms tiles` for the extent)"));
    }
    let (a, b) = (scene.local(w.min_x, w.max_y), scene.local(w.max_x, w.min_y));
    let (umin, umax) = (a.0.min(b.0), a.0.max(b.0));
    let (vmin, vmax) = (a.1.min(b.1), a.1.max(b.1));
    Ok((
        umin,
        vmin,
        (umax - umin) / width as f64,
        (vmax - vmin) / height as f64,
    ))
}

impl Frame {
    /// The pixels as bytes, `r, g, b` row-major from the top-left.
    pub fn rgb_bytes(&self) -> &[u8] {
        self.rgb.as_flattened()
    }

    /// The frame as PNG bytes (8-bit RGB; deterministic).
    pub fn png(&self) -> Result<Vec<u8>> {
        crate::io::png::encode_rgb(self.width, self.height, self.rgb_bytes())
    }

    /// Write the frame as a PNG file at `png` and, when `range` is given, its range image as
    /// [`Frame::write_range_exr`] does: both encoded, written and synced first, then renamed
    /// into place together, the PNG last — a run that fails leaves neither (nor replaces either).
    pub fn write(&self, png: &Path, range: Option<&Path>) -> Result<()> {
        let mut files = Vec::new();
        if let Some(r) = range {
            files.push((r, self.range_exr(r)?));
        }
        files.push((png, self.png()?));
        let mut staged = Vec::new();
        for (path, bytes) in files {
            let mut f = crate::io::atomic::AtomicFile::create(path)?;
            std::io::Write::write_all(f.writer(), &bytes).map_err(|e| crate::Error::io(path, e))?;
            staged.push(f.stage()?);
        }
        crate::io::atomic::commit_all(staged)
    }

    /// Write the range image as a one-channel (`Z`) f32 OpenEXR file (ZIP-compressed scan
    /// lines, increasing order), atomically: metres per pixel, `+inf` where the ray saw the sky.
    pub fn write_range_exr(&self, path: &Path) -> Result<()> {
        write_bytes_atomic(path, &self.range_exr(path)?)
    }

    /// The range image encoded as [`Frame::write_range_exr`] writes it (`path` for errors).
    fn range_exr(&self, path: &Path) -> Result<Vec<u8>> {
        use exr::prelude::*;
        let channel = AnyChannel::new("Z", FlatSamples::F32(self.range.clone()));
        // Scan lines in increasing order, compressed on one thread: blocks land in a fixed order,
        // so the file is byte-identical run to run (the default tiles go in completion order).
        let channels = AnyChannels::sort(SmallVec::from_vec(vec![channel]));
        let layer = Layer::new(
            (self.width, self.height),
            LayerAttributes::default(),
            Encoding::SMALL_LOSSLESS,
            channels,
        );
        let mut buf = std::io::Cursor::new(Vec::new());
        Image::from_layer(layer)
            .write()
            .non_parallel()
            .to_buffered(&mut buf)
            .map_err(|e| crate::Error::file(path, format!("encoding the EXR failed: {e}")))?;
        Ok(buf.into_inner())
    }
}

#[cfg(test)]
mod image_tests;
#[cfg(test)]
mod tests;
