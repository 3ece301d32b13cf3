//! Sun effects on level-0 colour: cast shadows, Lambert shading, walls, photo compensation.
//!
//! # Model (the invariant)
//! The illumination of a surface with unit normal `n`, relative to flat sunlit ground, is
//! `I = F + (1 − F) · min(max(0, n·s) / s_z, G_MAX)` when lit and `I = F` in cast shadow, where `s`
//! is the unit vector to the sun, `s_z = sin(elevation)` and `F` the shadow factor (skylight
//! only, as a fraction of full sun on flat ground; the Hughes patent's `F`). Flat lit ground has
//! `I = 1`, flat shadowed ground `I = F`. A cell's colour is multiplied by `I_new / I_photo`
//! (rounded, clamped to 255): `I_new` for the requested sun over the merged surface,
//! `I_photo` for the orthophoto's own sun over what the photo saw (terrain and buildings) —
//! or 1 when the photo's sun is unknown (the photo taken as evenly lit) and for placed objects
//! (their voxel colours are unlit albedo). So one rule gives every case:
//! * no sun → no effect is prepared at all (nothing is cast or shaded);
//! * the photo's own sun → terrain and roofs keep `I_new / I_photo = 1` (the photo holds their
//!   shading and shadows; nothing is computed for them), walls and objects are shaded and
//!   objects' new shadows darken what they fall on;
//! * a different sun → the photo's shadows are brightened by `1 / F` — on the ground those
//!   detected in the photo itself (`detected`: shadows of things the database does not hold
//!   are there too, and a cast from a height slightly off is not), on raised roofs those cast
//!   over terrain + buildings for the photo's sun — the new ones darkened by `F`, slopes
//!   re-shaded.
//!
//! Normals are central differences of the heights (one-sided at edges, nodata and class
//! boundaries: terrain, building and object cells only use neighbours of their own class, so a
//! wall's jump does not tilt the roof or the ground at its foot). A **wall cell** is a building
//! or object cell with a 4-neighbour lower by at least one cell size, unless both are building
//! cells and the drop is no steeper than [`crate::roof::MAX_PITCH_DEG`]: the roof's own slope (a steep
//! roof's faces, ridge and hips, whose neighbours lie a cell or more lower, are roof, shaded
//! by their normals; its eaves and gable ends, over the terrain, are walls). The
//! renderer sees the wall as that column's side, so its colour becomes the roof's colour times
//! the mean illumination of its exposed vertical faces (face normals horizontal, toward the
//! lower neighbours).
//!
//! # Memory
//! The terrain is read through a [`RowSource`] band by band, never whole: the surfaces are the
//! terrain with the raised cells laid over it, built for a band of rows with a one-row apron
//! (normals need the rows either side), and the cast shadows are kept as one bit per cell, cast
//! with [`crate::shadow::RowSweep`] from bands read in the sun's order. Memory: 2 bits a cell for the two
//! masks (3 with the detected one), plus a few bands of [`band_rows`] rows.

mod detected;
mod record;
pub use record::{add_optional, Counts, EffectsRecord, Outcome, SunAngles};

use super::effects::{self, Situation, Skipped};
use crate::error::{Error, Result};
use crate::grid::Grid;
use crate::raster::band_rows;
use crate::raster::RowSource;
use crate::shadow::ShadowBits;
use crate::standing::Raised;
use crate::sun::Sun;
use rayon::prelude::*;
use std::collections::HashMap;
use std::ops::Range;
use std::sync::{Arc, Mutex};

/// How far (cells) a change of which cells the photo's shadow detector judges (a building's
/// roof raised, moved or removed) can change what it finds: the blocks whose threshold windows
/// hold the changed cells, the bilinear blend to the block centres next to those, and a block
/// for alignment (`detected`).
pub const DETECTION_REACH: usize = (detected::REACH + 2) * detected::BLOCK;

/// Default shadow factor `F`: a shadowed surface gets this fraction of the light of a sunlit
/// one. 0.45 is typical of aerial photos on clear days (skylight); the patent's example, 0.02,
/// would make shadows black.
pub const DEFAULT_SHADOW_FACTOR: f64 = 0.45;

/// Most a tilted surface can be brighter than flat lit ground (caps `n·s / s_z`, which grows
/// without bound for a low sun).
pub const G_MAX: f64 = 2.0;

/// Two sun directions closer than this (degrees, in elevation and azimuth) are the same sun.
pub const SAME_SUN_DEG: f64 = 0.01;

/// Cell classes for normals and walls.
const TERRAIN: u8 = 0;
const BUILDING: u8 = 1;
const OBJECT: u8 = 2;

/// The prepared effects for one sun over one database: shadow masks and what to apply, over the
/// terrain and raised cells they were prepared from.
pub struct Effects<'a> {
    sun: Sun,
    s: [f64; 3],
    photo: Option<(Sun, [f64; 3])>,
    same_sun: bool,
    factor: f64,
    /// Terrain heights, metres; NaN = nodata.
    terrain: &'a dyn RowSource<f32>,
    /// Buildings: raised in both surfaces.
    buildings: &'a Raised,
    /// Placed objects: raised in the new surface only (the photo never saw them).
    objects: &'a Raised,
    /// Both: the new surface is the terrain with these laid over it.
    all: &'a Raised,
    /// The photo's surface (terrain + buildings) differs from the new one and is shaded apart.
    photo_apart: bool,
    new_shadow: Option<Arc<ShadowBits>>,
    /// The cast for the photo's sun (over the surface the photo saw).
    photo_shadow: Option<Arc<ShadowBits>>,
    /// The photo's shadows as the photo shows them ([`detected`]): with a different sun, what
    /// is compensated on the ground instead of `photo_shadow`.
    detected: Option<Arc<ShadowBits>>,
    /// Raised cells of the prepared rows with an exposed vertical face, ascending cell index.
    walls: Vec<usize>,
    lambert: bool,
    applied: Vec<&'static str>,
    skipped: Vec<Skipped>,
    /// The grid rows prepared ([`Window`]).
    rows: std::ops::Range<usize>,
}

/// Does a sun need effects at all? `sun: None` → nothing (no work).
/// `photo_sun` is the orthophoto's own sun when the database records it; `colour` is the
/// orthophoto on the terrain's grid, read (twice, band by band) only when the two suns differ,
/// to detect the photo's shadows. Prepared for every row of the grid. With `shared`, a cast or
/// detection another product of the same run already made (same sun, same surface) is taken
/// from it instead of made again, and noted as reused.
#[allow(clippy::too_many_arguments)]
pub fn prepare<'a>(
    sun: Option<Sun>,
    photo_sun: Option<Sun>,
    shadow_factor: f64,
    terrain: &'a dyn RowSource<f32>,
    colour: &dyn RowSource<[u8; 4]>,
    [buildings, objects, all]: [&'a Raised; 3],
    shared: Option<&Shared>,
) -> Result<Option<Effects<'a>>> {
    let window = Window {
        rows: 0..terrain.grid().height,
        top: f64::INFINITY,
        raised_anywhere: None,
    };
    let raised = [buildings, objects, all];
    prepare_rows(
        (sun, photo_sun, shadow_factor),
        terrain,
        colour,
        raised,
        window,
        shared,
    )
}

/// What products of one run share: the casts made so far, by sun and surface, and the photo's
/// detected shadows (they depend only on the photo and the buildings), each made once however
/// many products need it; and what each product took from another. Only for effects prepared
/// for the whole grid, over the same terrain and raised cells.
#[derive(Default)]
pub struct Shared {
    casts: Mutex<HashMap<CastKey, Arc<ShadowBits>>>,
    /// The rows the detection was made for, and the detection.
    detected: Mutex<Option<(std::ops::Range<usize>, Arc<ShadowBits>)>>,
    reused: Mutex<Vec<String>>,
}

/// A cast's sun (bits of its angles), surface ("all" or "buildings"), rows and height bound.
type CastKey = (u64, u64, &'static str, usize, usize, u64);

impl Shared {
    /// The cast for `sun` over `surface` ("all" or "buildings") for the rows of `window`, made
    /// by `make` the first time.
    fn cast(
        &self,
        sun: &Sun,
        surface: &'static str,
        window: &Window,
        make: impl FnOnce() -> Result<ShadowBits>,
    ) -> Result<Arc<ShadowBits>> {
        let key = (
            sun.elevation_deg.to_bits(),
            sun.azimuth_deg.to_bits(),
            surface,
            window.rows.start,
            window.rows.end,
            window.top.to_bits(),
        );
        if let Some(bits) = lock(&self.casts).get(&key) {
            lock(&self.reused).push(format!(
                "the cast for the sun at {:.2}° elevation, {:.2}° azimuth over {}",
                sun.elevation_deg,
                sun.azimuth_deg,
                match surface {
                    "all" => "terrain, buildings and objects",
                    _ => "terrain and buildings",
                }
            ));
            return Ok(bits.clone());
        }
        let bits = Arc::new(make()?);
        lock(&self.casts).insert(key, bits.clone());
        Ok(bits)
    }

    /// The photo's detected shadows on `rows`, made by `make` the first time these rows are
    /// asked for (a detection is only good on the rows it was made for, and with what stands
    /// near them).
    fn detected(
        &self,
        rows: &std::ops::Range<usize>,
        make: impl FnOnce() -> Result<ShadowBits>,
    ) -> Result<Arc<ShadowBits>> {
        if let Some((made, bits)) = lock(&self.detected).as_ref() {
            if made == rows {
                lock(&self.reused).push("the photo's detected shadows".into());
                return Ok(bits.clone());
            }
        }
        let bits = Arc::new(make()?);
        *lock(&self.detected) = Some((rows.clone(), bits.clone()));
        Ok(bits)
    }

    /// What was taken from earlier products since the last call, in words.
    pub fn take_reused(&self) -> Vec<String> {
        std::mem::take(&mut *lock(&self.reused))
    }
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

/// The grid rows effects are prepared for, and a bound on every surface height anywhere
/// (terrain or raised, metres): the casts sweep only from where a shadow can reach the rows
/// ([`ShadowBits::cast_rows`]); `+inf` sweeps from the grid's edge.
#[derive(Debug, Clone, PartialEq)]
pub struct Window {
    /// The rows.
    pub rows: std::ops::Range<usize>,
    /// No surface is higher, metres.
    pub top: f64,
    /// Whether buildings and placed objects stand anywhere on the grid, `[buildings, objects]`,
    /// when the raised sets given hold only those near the window (the effects that run depend
    /// on the whole grid); `None`: the raised sets are the whole grid's.
    pub raised_anywhere: Option<[bool; 2]>,
}

/// [`prepare`] for the rows of `window` only: [`Effects::shade_band`] gives there, bit for bit,
/// what the whole grid's effects give, and may be asked only for bands within them; the
/// record's counts are the window's. `[buildings, objects, all]` must hold everything raised
/// on the rows the casts sweep (the window, and toward the sun as far as a shadow reaches).
#[allow(clippy::too_many_arguments)]
pub fn prepare_window<'a>(
    sun: Option<Sun>,
    photo_sun: Option<Sun>,
    shadow_factor: f64,
    terrain: &'a dyn RowSource<f32>,
    colour: &dyn RowSource<[u8; 4]>,
    raised: [&'a Raised; 3],
    window: Window,
    shared: Option<&Shared>,
) -> Result<Option<Effects<'a>>> {
    let suns = (sun, photo_sun, shadow_factor);
    prepare_rows(suns, terrain, colour, raised, window, shared)
}

/// What the effects cast for a requested sun over what the registry decided on, `seen`: the
/// one rule [`prepare_window`] follows and an incremental build reckons shadows' reach by.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Casts {
    /// The photo's sun is cast too (its sun differs, or objects' new shadows must be told
    /// apart from the photo's).
    pub photo: Option<Sun>,
    /// The photo's sun is cast over terrain and buildings only (objects stand: the photo never
    /// saw them), not over everything.
    pub photo_over_buildings: bool,
    /// The photo's shadows are detected in the photo (its sun differs from the requested one).
    pub detect: bool,
}

/// What the effects of a build for `sun` (and the photo's, `photo_sun`) do over a grid where
/// buildings and objects raise cells as `raised` says, `[buildings, objects]`: the situation the
/// registry decides on, and the casts made (`None` without a sun, or when nothing runs). For
/// builds that make pages apart from the whole grid (incremental, sharded), which know `raised`
/// without reading what stands.
pub fn casts_for(
    sun: Option<Sun>,
    photo_sun: Option<Sun>,
    raised: [bool; 2],
) -> (Situation, Option<Casts>) {
    let seen = situation_of(sun, photo_sun, raised);
    let casts = sun.and_then(|_| Casts::of(&seen, photo_sun));
    (seen, casts)
}

impl Casts {
    /// The suns these casts cast for the requested `sun`: it, and the photo's when cast too.
    pub fn suns(&self, sun: Sun) -> Vec<Sun> {
        std::iter::once(sun).chain(self.photo).collect()
    }

    /// The casts for `seen` (a sun requested) and the photo's own sun when known; `None` when
    /// nothing runs: the photo's own sun with nothing raised (the photo holds it all).
    pub fn of(seen: &Situation, photo_sun: Option<Sun>) -> Option<Casts> {
        if seen.same_sun && !seen.buildings && !seen.objects {
            return None;
        }
        let photo_over_buildings = seen.objects && photo_sun.is_some();
        Some(Casts {
            photo: photo_sun.filter(|_| !seen.same_sun || photo_over_buildings),
            photo_over_buildings,
            detect: photo_sun.is_some() && !seen.same_sun,
        })
    }
}

/// [`prepare_window`], taking casts and detections from `shared` when given.
fn prepare_rows<'a>(
    (sun, photo_sun, shadow_factor): (Option<Sun>, Option<Sun>, f64),
    terrain: &'a dyn RowSource<f32>,
    colour: &dyn RowSource<[u8; 4]>,
    [buildings, objects, all]: [&'a Raised; 3],
    window: Window,
    shared: Option<&Shared>,
) -> Result<Option<Effects<'a>>> {
    let Some(sun) = sun else { return Ok(None) };
    same_size(terrain.grid(), colour.grid())?;
    let mut seen = situation(Some(sun), photo_sun, buildings, objects);
    if let Some([b, o]) = window.raised_anywhere {
        (seen.buildings, seen.objects) = (b, o);
    }
    let same_sun = seen.same_sun;
    let Some(casts) = Casts::of(&seen, photo_sun) else {
        return Ok(None);
    };
    let (photo_apart, photo_cast) = (casts.photo_over_buildings, casts.photo);
    let cast = |sun: &Sun, surface: &'static str| {
        let laid = if surface == "all" { all } else { buildings };
        let make = || {
            let overlay = |start, row: &mut [f32]| laid.lay_over(start, row);
            ShadowBits::cast_rows(terrain, sun, overlay, window.rows.clone(), window.top)
        };
        match shared {
            Some(s) => s.cast(sun, surface, &window, make),
            None => make().map(Arc::new),
        }
    };
    let (new_shadow, photo_shadow) = rayon::join(
        || cast(&sun, "all"),
        || {
            photo_cast
                .map(|p| cast(&p, if photo_apart { "buildings" } else { "all" }))
                .transpose()
        },
    );
    let (new_shadow, photo_shadow) = (Some(new_shadow?), photo_shadow?);
    // A different sun: the photo's shadows on the ground are found in the photo itself.
    let detect = || detected::detect(colour, buildings, window.rows.clone());
    let detected = match (casts.detect, shared) {
        (false, _) => None,
        (true, Some(s)) => Some(s.detected(&window.rows, detect)?),
        (true, None) => Some(Arc::new(detect()?)),
    };
    let (applied, skipped) = effects::decide(&seen);
    let mut fx = Effects {
        s: sun.direction_enu(),
        sun,
        photo: photo_sun.map(|p| (p, p.direction_enu())),
        same_sun,
        factor: shadow_factor,
        terrain,
        buildings,
        objects,
        all,
        photo_apart,
        new_shadow,
        photo_shadow,
        detected,
        walls: Vec::new(),
        lambert: !same_sun,
        applied,
        skipped,
        rows: window.rows,
    };
    fx.walls = fx.find_walls()?;
    Ok(Some(fx))
}

/// An error unless the colour layer's grid `gc` has as many cells as the elevation's `g`.
fn same_size(g: &Grid, gc: &Grid) -> Result<()> {
    if (gc.width, gc.height) != (g.width, g.height) {
        return Err(Error::msg(format!(
            "the colour layer is {} × {} cells, the elevation {} × {}",
            gc.width, gc.height, g.width, g.height
        ))
        .fix("both layers must be on the database grid: run dbms ingest again"));
    }
    Ok(())
}

/// What the effects registry decides on for a requested `sun`, the photo's own `photo_sun`
/// (when known) and what stands on the terrain.
pub fn situation(
    sun: Option<Sun>,
    photo_sun: Option<Sun>,
    buildings: &Raised,
    objects: &Raised,
) -> Situation {
    situation_of(sun, photo_sun, [!buildings.is_empty(), !objects.is_empty()])
}

/// [`situation`] when whether buildings and objects raise any cell is known,
/// `[buildings, objects]`.
pub fn situation_of(sun: Option<Sun>, photo_sun: Option<Sun>, [b, o]: [bool; 2]) -> Situation {
    Situation {
        sun: sun.is_some(),
        photo_sun: photo_sun.is_some(),
        same_sun: matches!((sun, photo_sun), (Some(s), Some(p)) if same(&p, &s)),
        buildings: b,
        objects: o,
    }
}

/// `colour` lit by an effects factor: channels × `factor`, rounded, at most 255; alpha kept.
pub fn lit(mut colour: [u8; 4], factor: f64) -> [u8; 4] {
    if factor != 1.0 {
        for ch in &mut colour[..3] {
            *ch = (*ch as f64 * factor).round().min(255.0) as u8;
        }
    }
    colour
}

fn same(a: &Sun, b: &Sun) -> bool {
    let daz = (a.azimuth_deg - b.azimuth_deg).rem_euclid(360.0);
    (a.elevation_deg - b.elevation_deg).abs() < SAME_SUN_DEG && daz.min(360.0 - daz) < SAME_SUN_DEG
}

/// The surfaces over a band of rows `first..first + n` (the rows shaded plus a one-row apron
/// each side, clipped to the grid): heights of the new surface and of the surface the photo saw
/// (metres, NaN = nodata), and each cell's class.
struct Surfaces {
    first: usize,
    width: usize,
    new: Vec<f32>,
    /// `None` when the photo saw the new surface.
    photo: Option<Vec<f32>>,
    class: Vec<u8>,
}

impl Surfaces {
    fn at(&self, col: usize, row: usize) -> usize {
        (row - self.first) * self.width + col
    }

    fn new_height(&self, col: usize, row: usize) -> f32 {
        self.new[self.at(col, row)]
    }

    fn photo_height(&self, col: usize, row: usize) -> f32 {
        self.photo.as_ref().unwrap_or(&self.new)[self.at(col, row)]
    }

    fn class(&self, col: usize, row: usize) -> u8 {
        self.class[self.at(col, row)]
    }
}

impl Effects<'_> {
    /// What was applied, for the tile header and the manifest (the counts: of the rows
    /// prepared).
    pub fn record(&self) -> EffectsRecord {
        EffectsRecord {
            sun: Some(self.sun.into()),
            photo_sun: self.photo.map(|p| p.0.into()),
            shadow_factor: self.factor,
            applied: self.applied.clone(),
            skipped: self.skipped.clone(),
            outcome: Outcome::Prepared(Counts {
                shadow_cells: self.new_shadow.as_deref().map(ShadowBits::count),
                photo_shadow_cells: self.photo_shadow.as_deref().map(ShadowBits::count),
                detected_photo_shadow_cells: self.detected.as_deref().map(ShadowBits::count),
                wall_cells: self.walls.len(),
            }),
        }
    }

    /// The record's counts over the cells of columns `cols` and rows `rows` only (rows within
    /// the rows prepared): what a part of the grid adds to the whole record's.
    pub fn counts_in(&self, cols: Range<usize>, rows: Range<usize>) -> Counts {
        let w = self.terrain.grid().width;
        let mask = |m: &Option<Arc<ShadowBits>>| {
            m.as_ref().map(|m| {
                rows.clone()
                    .map(|r| cols.clone().filter(|&c| m.get(r * w + c)).count())
                    .sum()
            })
        };
        let walls = rows
            .clone()
            .map(|r| {
                let (a, b) = (r * w + cols.start, r * w + cols.end);
                let lo = self.walls.partition_point(|&i| i < a);
                self.walls.partition_point(|&i| i < b) - lo
            })
            .sum();
        Counts {
            shadow_cells: mask(&self.new_shadow),
            photo_shadow_cells: mask(&self.photo_shadow),
            detected_photo_shadow_cells: mask(&self.detected),
            wall_cells: walls,
        }
    }

    /// Raised cells of the prepared rows with at least one exposed vertical face, ascending,
    /// found band by band.
    fn find_walls(&self) -> Result<Vec<usize>> {
        let g = self.terrain.grid();
        let (w, per_band) = (g.width, band_rows(g.width));
        let end = self.rows.end;
        let bands: Vec<usize> = self.rows.clone().step_by(per_band).collect();
        bands
            .into_par_iter()
            .map(|row0| {
                let rows = per_band.min(end - row0);
                let cells = self.all.range(row0 * w, (row0 + rows) * w);
                if cells.is_empty() {
                    return Ok(Vec::new());
                }
                let band = self.band(row0, rows)?;
                Ok(cells
                    .iter()
                    .filter(|c| !self.faces(&band, c.index % w, c.index / w).is_empty())
                    .map(|c| c.index)
                    .collect::<Vec<usize>>())
            })
            .collect::<Result<Vec<Vec<usize>>>>()
            .map(|bands| bands.concat())
    }

    /// Multiply the colours of level-0 rows `row0..` (a band of `colour.len() / width` rows) by
    /// each cell's `I_new / I_photo` (see [`lit`]), in the columns `cols` only; nodata cells
    /// and other columns are left alone. Returns the factors, row-major over the band (1
    /// outside `cols`), for whatever else the band colours (voxel runs).
    ///
    /// # Panics
    /// When the band reaches outside the rows prepared ([`prepare_window`]).
    pub fn shade_band(
        &self,
        row0: usize,
        colour: &mut [[u8; 4]],
        cols: Range<usize>,
    ) -> Result<Vec<f64>> {
        let w = self.terrain.grid().width;
        let rows = colour.len() / w;
        assert!(
            self.rows.start <= row0 && row0 + rows <= self.rows.end,
            "shade_band: rows {row0}.. outside the prepared {:?}",
            self.rows
        );
        let band = self.band(row0, rows)?;
        let mut factors = vec![1.0; colour.len()];
        colour
            .par_chunks_mut(w)
            .zip(factors.par_chunks_mut(w))
            .enumerate()
            .for_each(|(r, (line, ks))| {
                let (line, ks) = (&mut line[cols.clone()], &mut ks[cols.clone()]);
                for (col, (c, k)) in (cols.start..).zip(line.iter_mut().zip(ks)) {
                    if c[3] != 0 {
                        *k = self.factor(&band, col, row0 + r);
                        *c = lit(*c, *k);
                    }
                }
            });
        Ok(factors)
    }

    /// `I_new / I_photo` of one cell (reads its three rows: for tests and single cells).
    ///
    /// # Panics
    /// When the row is outside the rows prepared ([`prepare_window`]).
    pub fn factor_at(&self, col: usize, row: usize) -> Result<f64> {
        assert!(
            self.rows.contains(&row),
            "factor_at: row {row} not prepared"
        );
        Ok(self.factor(&self.band(row, 1)?, col, row))
    }

    /// The surfaces over rows `row0 .. row0 + rows` and a one-row apron.
    fn band(&self, row0: usize, rows: usize) -> Result<Surfaces> {
        let g = self.terrain.grid();
        let (w, first) = (g.width, row0.saturating_sub(1));
        let end = (row0 + rows + 1).min(g.height);
        let terrain = self.terrain.read_rows(first, end - first)?;
        let (start, stop) = (first * w, end * w);
        let lay = |raised: &Raised| {
            let mut h = terrain.to_vec();
            for c in raised.range(start, stop) {
                h[c.index - start] = c.top_z;
            }
            h
        };
        let mut class = vec![TERRAIN; stop - start];
        for (set, value) in [(self.buildings, BUILDING), (self.objects, OBJECT)] {
            for c in set.range(start, stop) {
                class[c.index - start] = value;
            }
        }
        Ok(Surfaces {
            first,
            width: w,
            new: lay(self.all),
            photo: self.photo_apart.then(|| lay(self.buildings)),
            class,
        })
    }

    /// `I_new / I_photo` of cell `(col, row)` over `surface`, a band holding its row.
    fn factor(&self, surface: &Surfaces, col: usize, row: usize) -> f64 {
        let i = self.terrain.grid().index(col, row);
        let class = surface.class(col, row);
        let shadow_new = self.new_shadow.as_ref().is_some_and(|m| m.get(i));
        // The photo's shadow: on the ground as detected in the photo when the sun differs; on
        // roofs (never judged by the detector) and for the same sun, the cast for its sun.
        let shadow_photo = match (&self.detected, &self.photo_shadow) {
            (Some(d), _) if class != BUILDING => d.get(i),
            (_, Some(m)) => m.get(i),
            (_, None) => self.same_sun && shadow_new,
        };
        let faces = if class == TERRAIN {
            Vec::new()
        } else {
            self.faces(surface, col, row)
        };
        let i_new = if !faces.is_empty() {
            faces
                .iter()
                .map(|n| self.illum(n, &self.s, shadow_new))
                .sum::<f64>()
                / faces.len() as f64
        } else if self.lambert || class == OBJECT {
            self.illum(&self.normal(surface, false, col, row), &self.s, shadow_new)
        } else {
            self.illum(&[0.0, 0.0, 1.0], &self.s, shadow_new)
        };
        let i_photo = match self.photo {
            Some((_, sp)) if class != OBJECT => {
                // The photo saw roofs from above: for a wall cell its roof's normal, up.
                let n = if !faces.is_empty() || !self.lambert {
                    [0.0, 0.0, 1.0]
                } else {
                    self.normal(surface, true, col, row)
                };
                self.illum(&n, &sp, shadow_photo)
            }
            _ => 1.0,
        };
        i_new / i_photo
    }

    /// Illumination relative to flat sunlit ground (see the module doc).
    fn illum(&self, n: &[f64; 3], s: &[f64; 3], shadowed: bool) -> f64 {
        if shadowed {
            return self.factor;
        }
        let ns = n[0] * s[0] + n[1] * s[1] + n[2] * s[2];
        self.factor + (1.0 - self.factor) * (ns.max(0.0) / s[2]).min(G_MAX)
    }

    /// Height at `(col, row)` of the new (or, with `photo`, the photo's) surface when it is a
    /// usable neighbour of a cell of class `class`.
    fn neighbour(
        &self,
        surface: &Surfaces,
        photo: bool,
        class: u8,
        col: isize,
        row: isize,
    ) -> Option<f64> {
        let g = self.terrain.grid();
        if col < 0 || row < 0 || col >= g.width as isize || row >= g.height as isize {
            return None;
        }
        let (c, r) = (col as usize, row as usize);
        let z = if photo {
            surface.photo_height(c, r)
        } else {
            surface.new_height(c, r)
        };
        (!z.is_nan() && surface.class(c, r) == class).then_some(z as f64)
    }

    /// Unit normal (east, north, up) of the new (or the photo's) surface by central differences
    /// within the cell's class.
    fn normal(&self, surface: &Surfaces, photo: bool, col: usize, row: usize) -> [f64; 3] {
        let g = self.terrain.grid();
        let z = if photo {
            surface.photo_height(col, row)
        } else {
            surface.new_height(col, row)
        } as f64;
        let class = surface.class(col, row);
        let (c, r) = (col as isize, row as isize);
        let (dx, dy) = g.cell_size();
        let slope = |a: Option<f64>, b: Option<f64>, d: f64| match (a, b) {
            (Some(a), Some(b)) => (b - a) / (2.0 * d),
            (Some(a), None) => (z - a) / d,
            (None, Some(b)) => (b - z) / d,
            (None, None) => 0.0,
        };
        let at = |dc: isize, dr: isize| self.neighbour(surface, photo, class, c + dc, r + dr);
        let dzdx = slope(at(-1, 0), at(1, 0), dx);
        // Rows run southward: north of the cell is row − 1.
        let dzdy = slope(at(0, 1), at(0, -1), dy);
        let len = (dzdx * dzdx + dzdy * dzdy + 1.0).sqrt();
        [-dzdx / len, -dzdy / len, 1.0 / len]
    }

    /// Horizontal normals of the exposed vertical faces of a raised cell: toward each
    /// 4-neighbour of the new surface lower by at least one cell size (valid neighbours only),
    /// unless the cell and that neighbour are both building cells and the drop is within
    /// [`crate::roof::MAX_PITCH_DEG`] over a cell: then it is the roof's own slope (a steep roof's
    /// faces, ridge and hips), shaded by its normal. A building's outline (a drop to the
    /// terrain or an object: its eaves and gable ends) and a steeper drop between two roofs
    /// are walls; a smaller step between two roofs reads as a steep slope.
    fn faces(&self, surface: &Surfaces, col: usize, row: usize) -> Vec<[f64; 3]> {
        let g = self.terrain.grid();
        let z = surface.new_height(col, row) as f64;
        let step = g.cell_size().0.min(g.cell_size().1);
        let steepest = crate::roof::MAX_PITCH_DEG.to_radians().tan() * step;
        let on_roof = surface.class(col, row) == BUILDING;
        let (c, r) = (col as isize, row as isize);
        [
            (1, 0, [1.0, 0.0, 0.0]),
            (-1, 0, [-1.0, 0.0, 0.0]),
            (0, -1, [0.0, 1.0, 0.0]),
            (0, 1, [0.0, -1.0, 0.0]),
        ]
        .into_iter()
        .filter(|&(dc, dr, _)| {
            let (nc, nr) = (c + dc, r + dr);
            if nc < 0 || nr < 0 || nc >= g.width as isize || nr >= g.height as isize {
                return false;
            }
            let (nc, nr) = (nc as usize, nr as usize);
            let nz = surface.new_height(nc, nr);
            let drop = z - nz as f64;
            let roof_slope = on_roof && surface.class(nc, nr) == BUILDING && drop <= steepest;
            !nz.is_nan() && drop >= step && !roof_slope
        })
        .map(|(_, _, n)| n)
        .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::crs::Crs;
    use crate::grid::Grid;
    use crate::raster::{Colour, Elevation};
    use crate::standing::{rasterise_prisms, Prism, RaisedCell};
    use serde_json::json;

    /// The record as the tile header and the manifest hold it.
    fn json(r: &EffectsRecord) -> serde_json::Value {
        serde_json::to_value(r).unwrap()
    }

    fn terrain(w: usize, h: usize, f: impl Fn(usize, usize) -> f32) -> Elevation {
        let g = Grid::north_up(0.0, h as f64, 1.0, w, h, Crs::unknown());
        let data = (0..w * h).map(|i| f(i % w, i / w)).collect();
        Elevation::new(g, data)
    }

    /// An evenly lit orthophoto on the terrain's grid.
    fn plain(t: &Elevation) -> Colour {
        Colour::filled(t.grid.clone(), [120, 120, 120, 255])
    }

    fn sun(e: f64, a: f64) -> Sun {
        Sun::new(e, a).unwrap()
    }

    /// Nothing raised (effects borrow what they are prepared from, so it must outlive them).
    fn none() -> &'static Raised {
        static NONE: std::sync::OnceLock<Raised> = std::sync::OnceLock::new();
        NONE.get_or_init(Raised::default)
    }

    /// The effects over bare terrain `t` (nothing raised) in a plain grey photo.
    fn bare(
        sun: Option<Sun>,
        photo_sun: Option<Sun>,
        factor: f64,
        t: &Elevation,
    ) -> Option<Effects<'_>> {
        prepare(
            sun,
            photo_sun,
            factor,
            t,
            &plain(t),
            [none(), none(), none()],
            None,
        )
        .unwrap()
    }

    /// The effects of buildings `b` over terrain `t` in a plain grey photo taken under the
    /// sun `s`, shaded for that same sun.
    fn under_the_photos_sun<'a>(s: Sun, t: &'a Elevation, b: &'a Raised) -> Effects<'a> {
        prepare(Some(s), Some(s), 0.5, t, &plain(t), [b, none(), b], None)
            .unwrap()
            .unwrap()
    }

    #[test]
    fn no_sun_prepares_nothing() {
        let t = terrain(8, 8, |c, _| c as f32);
        assert!(bare(None, None, 0.5, &t).is_none());
        let r = json(&EffectsRecord::none(None, None, 0.5, none(), none()));
        assert_eq!(r["applied"], json!([]));
        assert!(r["sun"].is_null());
        assert_eq!(
            r["skipped"].as_array().unwrap().len(),
            effects::EFFECTS.len()
        );
        assert_eq!(
            r["skipped"][0],
            json!({"effect": "cast_shadows", "why": "no sun given"})
        );
    }

    #[test]
    fn a_colour_layer_on_another_grid_is_an_error() {
        let t = terrain(8, 8, |_, _| 0.0);
        let c = plain(&terrain(8, 7, |_, _| 0.0));
        let s = Some(sun(30.0, 90.0));
        let e = prepare(s, s, 0.5, &t, &c, [none(), none(), none()], None)
            .err()
            .unwrap();
        assert!(e.to_string().contains("8 × 7"), "{e}");
    }

    #[test]
    fn flat_ground_without_photo_sun_is_unchanged() {
        let t = terrain(8, 8, |_, _| 10.0);
        let fx = bare(Some(sun(30.0, 135.0)), None, 0.5, &t).unwrap();
        let mut c = vec![[100, 150, 200, 255]; 64];
        fx.shade_band(0, &mut c, 0..t.grid().width).unwrap();
        assert!(c.iter().all(|p| *p == [100, 150, 200, 255]));
        assert_eq!(json(&fx.record())["shadow_cells"], json!(0));
    }

    #[test]
    fn slopes_facing_the_sun_brighten_and_facing_away_darken() {
        // Ridge along north-south at column 5: west side rises eastward, east side falls.
        let t = terrain(11, 5, |c, _| 10.0 - (c as f32 - 5.0).abs() * 0.3);
        let fx = bare(Some(sun(40.0, 90.0)), None, 0.4, &t).unwrap();
        assert!(
            fx.factor_at(8, 2).unwrap() > 1.0,
            "east slope faces the eastern sun"
        );
        assert!(fx.factor_at(2, 2).unwrap() < 1.0, "west slope faces away");
        // n·s on the east slope: normal (0.3, 0, 1)/|.|, s = (cos40, 0, sin40).
        let n = [0.3 / 1.09f64.sqrt(), 0.0, 1.0 / 1.09f64.sqrt()];
        let s = 40f64.to_radians();
        let want = 0.4 + 0.6 * (n[0] * s.cos() + n[2] * s.sin()) / s.sin();
        assert!(
            (fx.factor_at(8, 2).unwrap() - want).abs() < 1e-6,
            "heights are f32"
        );
    }

    #[test]
    fn cliff_shadow_darkens_by_the_shadow_factor() {
        // A 10 m cliff face at column 3 (west high), sun in the west at 45°: 10 cells of shadow.
        let t = terrain(30, 3, |c, _| if c <= 3 { 10.0 } else { 0.0 });
        let fx = bare(Some(sun(45.0, 270.0)), None, 0.5, &t).unwrap();
        let mut c = vec![[200, 100, 50, 255]; 90];
        fx.shade_band(0, &mut c, 0..t.grid().width).unwrap();
        assert_eq!(c[31 + 5], [100, 50, 25, 255], "in the cliff's shadow");
        assert_eq!(c[30 + 25], [200, 100, 50, 255], "beyond the shadow");
    }

    /// A solid object `top_z` metres high on `cells` (column, row) of `t`, and it with the
    /// buildings `b`: `(objects, all)`.
    fn with_object(
        t: &Elevation,
        b: &Raised,
        cells: [(usize, usize); 4],
        top_z: f32,
    ) -> (Raised, Raised) {
        let cells = cells.map(|(c, r)| RaisedCell {
            index: t.grid.index(c, r),
            top_z,
            colour: Some([50, 60, 70, 255]),
            partial: false,
        });
        let o = Raised::new(cells.to_vec(), t);
        let mut both = b.cells().to_vec();
        both.extend(o.cells());
        let all = Raised::new(both, t);
        (o, all)
    }

    fn building_scene() -> (Elevation, Raised) {
        let t = terrain(20, 20, |_, _| 0.0);
        let p = Prism {
            rings: vec![vec![(8.0, 8.0), (12.0, 8.0), (12.0, 12.0), (8.0, 12.0)]],
            roof: crate::roof::RoofShape::flat(6.0),
        };
        let b = Raised::new(rasterise_prisms(&t.grid, &[p]), &t);
        (t, b)
    }

    #[test]
    fn photo_sun_equal_to_the_sun_shades_only_walls() {
        let (t, b) = building_scene();
        let s = sun(35.0, 90.0);
        // Nothing raised: nothing at all to do.
        assert!(bare(Some(s), Some(s), 0.5, &t).is_none());
        let fx = under_the_photos_sun(s, &t, &b);
        assert_eq!(json(&fx.record())["applied"], json!(["wall_shading"]));
        // Ground in the building's shadow (west of it) and plain ground: unchanged.
        assert_eq!(fx.factor_at(6, 10).unwrap(), 1.0);
        assert_eq!(fx.factor_at(2, 2).unwrap(), 1.0);
        // Roof interior unchanged; the east wall is brighter than the west wall.
        assert_eq!(fx.factor_at(10, 10).unwrap(), 1.0);
        let (east, west) = (fx.factor_at(11, 10).unwrap(), fx.factor_at(8, 10).unwrap());
        assert!(east > 1.0 && west < 1.0, "east {east} west {west}");
        assert_eq!(json(&fx.record())["wall_cells"], json!(12));
    }

    /// A 50° gable house on flat ground at the sample's cell size (0.25 m): 10 m × 8 m, the
    /// ridge east–west, eaves at 6 m, so each face drops 0.30 m (1.19 cells) a cell.
    fn steep_gable() -> (Elevation, Raised, Prism) {
        let g = Grid::north_up(0.0, 15.0, 0.25, 60, 60, Crs::unknown());
        let t = Elevation::new(g, vec![0.0; 3600]);
        let rings = vec![vec![(2.5, 3.5), (12.5, 3.5), (12.5, 11.5), (2.5, 11.5)]];
        let pitch = crate::roof::Pitch {
            form: crate::roof::RoofForm::Gable,
            eave_z: 6.0,
            azimuth_deg: 90.0,
        };
        let ridge = 6.0 + 4.0 * 50f64.to_radians().tan();
        let roof = crate::roof::RoofShape::new(&rings, ridge, Some(pitch));
        let p = Prism { rings, roof };
        let b = Raised::new(rasterise_prisms(&t.grid, std::slice::from_ref(&p)), &t);
        (t, b, p)
    }

    #[test]
    fn a_steep_roof_is_shaded_as_a_sloped_roof_not_as_walls() {
        let (t, b, p) = steep_gable();
        let inside = |c: isize, r: isize| {
            c >= 0 && r >= 0 && b.get(t.grid.index(c as usize, r as usize)).is_some()
        };
        // The outline's cells (a 4-neighbour outside the footprint): the eaves and gable ends.
        let outline = b
            .cells()
            .iter()
            .filter(|cell| {
                let (c, r) = ((cell.index % 60) as isize, (cell.index / 60) as isize);
                [(1, 0), (-1, 0), (0, 1), (0, -1)]
                    .iter()
                    .any(|&(dc, dr)| !inside(c + dc, r + dr))
            })
            .count();
        assert_eq!((b.cells().len(), outline), (1280, 140));
        // The photo's own sun: the photo holds the faces' shading; only the outline is walls.
        let s = sun(35.0, 160.0);
        let fx = under_the_photos_sun(s, &t, &b);
        assert_eq!(json(&fx.record())["wall_cells"], json!(outline));
        for (c, r) in [(30, 20), (30, 30), (30, 35), (30, 40), (20, 25)] {
            assert_eq!(fx.factor_at(c, r).unwrap(), 1.0, "roof cell ({c}, {r})");
        }
        // A photo without a sun, shaded for one: the south face at a 50° plane's Lambert
        // factor (heights are f32), the north face darker, not a wall's horizontal normal.
        let fx = prepare(Some(s), None, 0.5, &t, &plain(&t), [&b, none(), &b], None)
            .unwrap()
            .unwrap();
        let (c, r) = (30, 40);
        let (x, y) = t.grid.cell_centre(c, r);
        assert!(
            y < 7.5
                && (p.roof.z_at((x, y)) - 6.0 - (y - 3.5) * 50f64.to_radians().tan()).abs() < 1e-9
        );
        let (a, e) = (160f64.to_radians(), 35f64.to_radians());
        let sv = [e.cos() * a.sin(), e.cos() * a.cos(), e.sin()];
        let n = [0.0, -(50f64.to_radians().sin()), 50f64.to_radians().cos()];
        let ns = n[0] * sv[0] + n[1] * sv[1] + n[2] * sv[2];
        let want = 0.5 + 0.5 * (ns / sv[2]).min(G_MAX);
        let got = fx.factor_at(c, r).unwrap();
        assert!(
            (got - want).abs() < 1e-4,
            "south face {got}, a 50° plane {want}"
        );
        assert!(
            fx.factor_at(30, 20).unwrap() < 0.6,
            "the north face faces away"
        );
    }

    #[test]
    fn photo_sun_with_a_placed_object_darkens_only_the_objects_new_shadow() {
        let (t, b) = building_scene();
        // A 2 × 2 cell, 8 m object south-west of the building, not seen by the photo.
        let (o, all) = with_object(&t, &b, [(3, 15), (4, 15), (3, 16), (4, 16)], 8.0);
        let s = sun(45.0, 90.0);
        let fx = prepare(Some(s), Some(s), 0.5, &t, &plain(&t), [&b, &o, &all], None)
            .unwrap()
            .unwrap();
        assert_eq!(
            json(&fx.record())["applied"],
            json!(["object_shadows", "wall_shading", "object_shading"])
        );
        // West of the object: its new shadow (8 m at 45°) → × F. West of the building: the
        // photo's own shadow, unchanged. Open ground: unchanged.
        assert!((fx.factor_at(1, 15).unwrap() - 0.5).abs() < 1e-12);
        assert_eq!(fx.factor_at(6, 10).unwrap(), 1.0);
        assert_eq!(fx.factor_at(15, 3).unwrap(), 1.0);
        // The object's cells are shaded as walls (I_photo = 1). (4, 15) shows an east face
        // (n·s / s_z = cot 45° = 1 → I = 1) and a north face (n·s = 0 → I = F): mean 0.75;
        // (3, 15) shows west and north faces, both turned away: F.
        assert!(
            (fx.factor_at(4, 15).unwrap() - 0.75).abs() < 1e-9,
            "{}",
            fx.factor_at(4, 15).unwrap()
        );
        assert!((fx.factor_at(3, 15).unwrap() - 0.5).abs() < 1e-9);
    }

    /// An orthophoto of textured ground (index 90–130) taken under `photo_sun`: the cells in the
    /// cast shadow of the terrain with `seen` laid over it are darkened by `f`.
    fn photo_of(t: &Elevation, seen: &Raised, photo_sun: &Sun, f: f64) -> Colour {
        let shadow = ShadowBits::cast(t, photo_sun, |s, row| seen.lay_over(s, row)).unwrap();
        let data = (0..t.grid.len())
            .map(|i| {
                let v = 90.0 + ((i * 7919) % 41) as f64;
                let k = if shadow.get(i) { f } else { 1.0 };
                let c = (v * k).round() as u8;
                [c, c, c, 255]
            })
            .collect();
        Colour::new(t.grid.clone(), data)
    }

    #[test]
    fn a_different_sun_compensates_the_photos_shadows_and_casts_new_ones() {
        let (t, b) = building_scene();
        let (photo, now) = (sun(35.0, 90.0), sun(35.0, 270.0));
        let ortho = photo_of(&t, &b, &photo, 0.5);
        let fx = prepare(
            Some(now),
            Some(photo),
            0.5,
            &t,
            &ortho,
            [&b, none(), &b],
            None,
        )
        .unwrap()
        .unwrap();
        let applied = json(&fx.record())["applied"].clone();
        assert!(
            applied
                .as_array()
                .unwrap()
                .contains(&json!("photo_shadow_compensation")),
            "{applied}"
        );
        // West of the building: shadowed in the photo (eastern sun), lit now → × 1/F.
        assert!((fx.factor_at(6, 10).unwrap() - 2.0).abs() < 1e-12);
        // East of it: lit in the photo, shadowed now → × F.
        assert!((fx.factor_at(13, 10).unwrap() - 0.5).abs() < 1e-12);
        assert_eq!(fx.factor_at(2, 2).unwrap(), 1.0);
    }

    #[test]
    fn a_different_sun_compensates_the_shadows_detected_in_the_photo_not_the_cast() {
        // Flat ground, 96 × 96 cells of 1 m; photo sun in the east at 35°, new sun in the west.
        let t = terrain(96, 96, |_, _| 0.0);
        let (photo, now) = (sun(35.0, 90.0), sun(35.0, 270.0));
        let prism = |x0: f64, y0: f64, roof_z: f64| Prism {
            rings: vec![vec![
                (x0, y0),
                (x0 + 6.0, y0),
                (x0 + 6.0, y0 + 6.0),
                (x0, y0 + 6.0),
            ]],
            roof: crate::roof::RoofShape::flat(roof_z),
        };
        // The photo saw two 5 m blocks: one the database does not hold (unmeasured, a tree…),
        // one it holds 12 m tall (a height measured wrong), so its cast reaches too far west.
        let (missing, wrong) = (prism(60.0, 60.0, 5.0), prism(60.0, 20.0, 5.0));
        let seen = Raised::new(rasterise_prisms(&t.grid, &[missing, wrong.clone()]), &t);
        let ortho = photo_of(&t, &seen, &photo, 0.5);
        let db = Raised::new(
            rasterise_prisms(
                &t.grid,
                &[Prism {
                    roof: crate::roof::RoofShape::flat(12.0),
                    ..wrong
                }],
            ),
            &t,
        );
        let fx = prepare(
            Some(now),
            Some(photo),
            0.5,
            &t,
            &ortho,
            [&db, none(), &db],
            None,
        )
        .unwrap()
        .unwrap();
        let r = json(&fx.record());
        assert!(r["applied"]
            .as_array()
            .unwrap()
            .contains(&json!("photo_shadow_detection")));
        // The photo's shadows, 7 cells west of each block (5 m at 35°) on 6 rows, are found.
        assert_eq!(r["detected_photo_shadow_cells"], json!(84), "{r}");
        // West of the block the database lacks: dark in the photo, lit now → × 1/F.
        assert!((fx.factor_at(57, 33).unwrap() - 2.0).abs() < 1e-12);
        // 12 m cast west of the wrong block: 17 cells; beyond the photo's 7 the ground was lit
        // and stays lit → unchanged (a cast-only compensation brightened it × 1/F).
        assert_eq!(fx.factor_at(45, 73).unwrap(), 1.0);
        // Within the photo's shadow of that block: compensated.
        assert!((fx.factor_at(57, 73).unwrap() - 2.0).abs() < 1e-12);
    }

    /// Effects prepared for a window of rows shade it as the whole grid's effects do, on hills
    /// with a building and a placed object: the photo's own sun (objects' shadows apart), another
    /// sun (the photo's shadows detected and cast), and a sun with no photo sun known.
    #[test]
    fn effects_for_a_window_of_rows_shade_it_as_the_whole_grids_do() {
        let n = 40;
        let t = terrain(n, n, |c, r| (c as f32 * 0.3).sin() * 2.0 + r as f32 * 0.1);
        let p = Prism {
            rings: vec![vec![(8.0, 8.0), (13.0, 8.0), (13.0, 14.0), (8.0, 14.0)]],
            roof: crate::roof::RoofShape::flat(12.0),
        };
        let b = Raised::new(rasterise_prisms(&t.grid, &[p]), &t);
        let (o, all) = with_object(&t, &b, [(25, 20), (26, 20), (25, 21), (26, 21)], 9.0);
        let top = 12.0 + 0.1 * n as f64 + 2.0;
        let cases = [
            (sun(30.0, 200.0), Some(sun(30.0, 200.0))),
            (sun(25.0, 300.0), Some(sun(35.0, 90.0))),
            (sun(60.0, 45.0), None),
        ];
        for (now, photo) in cases {
            let ortho = photo_of(&t, &b, &photo.unwrap_or(now), 0.5);
            let raised = [&b, &o, &all];
            let full = prepare(Some(now), photo, 0.5, &t, &ortho, [&b, &o, &all], None)
                .unwrap()
                .unwrap();
            for rows in [0..n, 10..17, 33..n, 0..5, 21..22] {
                let window = Window {
                    rows: rows.clone(),
                    top,
                    raised_anywhere: None,
                };
                let part = prepare_window(Some(now), photo, 0.5, &t, &ortho, raised, window, None)
                    .unwrap()
                    .unwrap();
                let band = |fx: &Effects, row0: usize, k: usize| {
                    let mut c = ortho.data[row0 * n..(row0 + k) * n].to_vec();
                    let factors = fx.shade_band(row0, &mut c, 0..t.grid().width).unwrap();
                    (c, factors)
                };
                let k = rows.len();
                assert!(
                    band(&part, rows.start, k) == band(&full, rows.start, k),
                    "rows {rows:?}, sun {now:?}, photo {photo:?}"
                );
            }
        }
    }
}
