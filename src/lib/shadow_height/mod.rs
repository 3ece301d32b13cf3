//! Building heights from their shadows in the orthophoto, refined over the real terrain
//! (`dbms shadow-height`; the Hughes patent's shadow-height loop).
//!
//! # Method (the invariant)
//! For each valid footprint, independently (in parallel), in two passes — the second with the
//! ground in the other buildings' shadows at their first-pass roofs unusable — and the joint
//! passes (step 5):
//! 1. **Observe.** The cells around the footprint (a window reaching [`Options::max_height_m`]
//!    worth of shadow along the sun azimuth) are classified ([`local::Class`]): own footprint,
//!    other footprints, unusable (nodata colour or elevation, or shadowed by the bare terrain
//!    itself), and open ground lit or in shadow — from a given mask, or from Otsu's threshold on
//!    the [`detect::shadow_index`] of the window's open-ground cells (a local threshold). A
//!    weak split (a low sun or a bright sky: shadow only 10–25 % darker than lit ground) counts
//!    only where its dark cells lie in the footprint's possible shadow and hardly anywhere no
//!    building's shadow can fall ([`WEAK_MAX_STRAY`], [`WEAK_MIN_PLACED`]). Under a weak split
//!    the lit specks ringed by shadow are shadow: the shaded ground's texture ([`specks`]).
//! 2. **Measure.** [`scan::scan`]: parallel lines from the sun-far edges; the median valid
//!    length `L` (metres).
//! 3. **First estimate.** `Z0 = L · tan(elevation)`: the formula, exact on flat ground.
//! 4. **Refine.** [`refine::refine`]: the footprint polygon raised over the real DEM, its
//!    shadow cast with exact rays from every open cell and compared with the observed one (the
//!    shadow attached to the footprint); every height is scored by how well the photo's
//!    brightness is a lit and a shadow level mixed in its synthetic shadow's fractions (a
//!    least-squares fit), and the best wins. A roof that looks pitched ([`roof`]) is then
//!    fitted as a gable or hip roof ([`pitched::fit`]), taken only when it explains the photo
//!    clearly better: its ridge is the height and its form, eaves and direction are reported.
//! 5. **Jointly** ([`joint`], [`Options::joint_passes`]; off by default). The footprints
//!    whose shadow met another footprint, or that got no height, are measured again with
//!    every other footprint at its measured roof: its shadow hides the ground, and its roof,
//!    where measured flat and sure, is a surface this footprint's shadow is fitted on (with
//!    that roof's own levels); the corridor is every band but those of lines that disagree,
//!    and a fit the photo cannot close from above is a lower bound, not a height. Without a
//!    known roof in its window a footprint keeps its second-pass result.
//!
//! Heights: `height_m` is the roof above the **highest** terrain cell under the footprint (cell
//! centres inside it) — the lowest wall, as `dbms sample`'s truth defines it; `roof_z` is
//! absolute. Every result is a pure function of its inputs (no randomness, ordered output).
//!
//! # Scale
//! A city's footprints cost linear time and bounded memory: the layers are read in bands of
//! rows ([`Options::band_cells`]), each holding the rows its footprints' windows reach; the
//! footprints another one's shadow may reach are found in a bucket index ([`index::BoxIndex`]),
//! and in the second pass whose shadow covers each cell is rasterised once per band
//! (`neighbour_shadows`), not tested per window cell against every neighbour. Bands change
//! no result (a test measures in one-footprint bands and in one band). Measured on a generated
//! city: `benches/shadow_height_city.rs`, figures in docs/shadow-height.md.

pub mod footprint;
pub mod index;
pub mod joint;
pub mod lean;
pub mod local;
pub mod output;
pub mod pitched;
pub mod refine;
pub mod register;
pub mod roof;
pub mod scan;
pub mod shading;
pub mod specks;
pub mod uncertainty;

pub use footprint::{read_footprints, Footprint, InputFeature};

use crate::error::{Error, Result};
use crate::grid::Grid;
use crate::raster::{rows_in, Raster, RowBand, RowSource};
use crate::shadow::{detect, ShadowBits};
use crate::sun::Sun;
use crate::walk::{Corner, Walk};
use index::{swept, Box2, BoxIndex};
use local::{Class, Local};
use rayon::prelude::*;
use std::ops::Range;

/// A weak shadow split ([`detect::weak_threshold`]) is taken only when at most this fraction
/// of the open cells where the footprint's shadow cannot fall are dark.
pub const WEAK_MAX_STRAY: f64 = 0.01;
/// … and when its dark cells where the shadow can fall outnumber those elsewhere this many
/// times.
pub const WEAK_MIN_PLACED: f64 = 10.0;

/// Sun elevations below this (degrees) are flagged `low_sun`: long shadows leave the scene and
/// cross other objects.
pub const LOW_SUN_DEG: f64 = 10.0;
/// Sun elevations above this (degrees) are flagged `high_sun`: a cell of shadow length is many
/// metres of height.
pub const HIGH_SUN_DEG: f64 = 75.0;
/// Longest shadow followed, in cells, whatever `max_height_m` says (bounds the work at a low sun).
pub const MAX_SHADOW_CELLS: f64 = 4096.0;
/// Fewest valid scan lines a height is measured from (fewer when the footprint casts fewer): a
/// median of one or two lines that slipped past a neighbour is no measurement.
pub const MIN_VALID_LINES: usize = 3;

/// Independent evidence a height must have to be reported without a flag (see
/// [`Flags::lines_disagree`], [`Flags::estimates_disagree`], [`Flags::poor_shadow_match`]):
/// the fraction of valid scan lines whose own roof estimate (tip terrain + length · tan e) is
/// within [`AGREE_CELLS`] cells of shadow length of their median.
pub const MIN_AGREEING_LINES: f64 = 0.5;
/// See [`MIN_AGREEING_LINES`]: how far (in cells of shadow length, `cell · tan e` metres each)
/// a line's roof may be from the median, and the refined roof from the lines' median roof.
pub const AGREE_CELLS: f64 = 2.0;
/// See [`MIN_AGREEING_LINES`]: the lowest IoU of the synthetic shadow at the refined height and
/// the observed one.
pub const MIN_OVERLAP: f64 = 0.6;

/// Tuning of a run.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Options {
    /// Tallest building sought, metres above ground: bounds the search window and the refinement.
    pub max_height_m: f64,
    /// Scan-line spacing across the shadow direction, in cells (> 0; default 0.5).
    pub line_spacing_cells: f64,
    /// Refinement points per cell side (1..=15; default 4: a cell's synthetic shadow in
    /// sixteenths).
    pub sub_points: usize,
    /// Cells of the layers held at once (rows × grid width; default [`BAND_CELLS`]): the
    /// footprints are measured band of rows by band of rows, each band read with the rows
    /// its footprints' windows reach. A band is never smaller than one footprint's window.
    pub band_cells: usize,
    /// Joint passes after the second (default 0: none; see docs/shadow-height.md for what one
    /// gains and costs): the footprints whose shadow ran into a neighbour, or that got no
    /// height, measured again with every other footprint at the roof the pass before
    /// measured — its shadow cast over the ground (unusable there), its flat roof a surface
    /// this footprint's shadow may lie on (`refine::corridor`) — and the whole corridor
    /// read but for the bands of scan lines that disagree.
    pub joint_passes: usize,
    /// How the photo's bytes encode light (default sRGB): the faces' shading compares light,
    /// not bytes ([`shading`]).
    pub photo_encoding: shading::PhotoEncoding,
}

/// See [`Options::band_cells`]: 32 M cells, about 18 bytes each while a band is measured
/// (terrain, colour, owners, ground bins, neighbours' shadows; a mask one more), so about
/// 0.6 GB.
pub const BAND_CELLS: usize = 1 << 25;

impl Default for Options {
    fn default() -> Options {
        Options {
            max_height_m: 150.0,
            line_spacing_cells: 0.5,
            sub_points: 4,
            band_cells: BAND_CELLS,
            joint_passes: 0,
            photo_encoding: shading::PhotoEncoding::Srgb,
        }
    }
}

/// What a run looks at: the database's terrain and colour on one grid, and optionally a given
/// shadow mask on the same grid (0 = lit, 255 = nodata, anything else = shadow), each read
/// band by band (a [`Raster`] in memory serves as well as a layer file).
#[derive(Clone, Copy)]
pub struct Inputs<'a> {
    /// Bare-earth elevation, metres, NaN = nodata.
    pub terrain: &'a dyn RowSource<f32>,
    /// Orthophoto colour, alpha 0 = nodata.
    pub colour: &'a dyn RowSource<[u8; 4]>,
    /// Observed shadow mask replacing the automatic detection.
    pub mask: Option<&'a dyn RowSource<u8>>,
    /// Per footprint, how far its roof appears moved from its base in the photo, metres (east,
    /// north): the relief displacement of a perspective photo rectified on the bare ground
    /// ([`register::with_camera`]). The cells between the base and the moved roof show roof and
    /// walls, not ground: they are [`Class::Edge`]. `None`: a true orthophoto.
    pub leans: Option<&'a [(f64, f64)]>,
}

/// The hard cases met while measuring one footprint.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Flags {
    /// No scan line found any shadow (sun too high, or no shadow contrast around the footprint),
    /// or none of it is attached to the footprint where the refinement compares.
    pub no_shadow: bool,
    /// Some scan lines were dropped: the shadow left the grid (or the search window) or ended in
    /// or next to unusable cells — nodata, shadowed by the terrain, or (second pass) in another
    /// building's shadow.
    pub shadow_cut_by_edge_or_nodata: bool,
    /// Some scan lines were dropped: the shadow reached another footprint (or ended on a lit
    /// cell against one).
    pub shadow_on_other_building: bool,
    /// Sun elevation below [`LOW_SUN_DEG`].
    pub low_sun: bool,
    /// Sun elevation above [`HIGH_SUN_DEG`].
    pub high_sun: bool,
    /// The roof looks pitched in the photo (faces of different brightness, [`roof`]) but no
    /// pitched roof explains its shadow clearly better than a flat one ([`pitched`]): the
    /// height is that of a flat roof casting the same shadow — the eaves where the far face is
    /// lit, between eaves and ridge otherwise — not the ridge. Not set when a pitch is fitted
    /// ([`Measurement::pitch`]).
    pub pitched_roof: bool,
    /// The footprint's own registration estimate is clear and more than a cell from the
    /// scene's shift that was applied: its outline does not fit its roof in the photo
    /// ([`register`]), so the shadow is measured from the wrong place.
    pub footprint_off_photo: bool,
    /// Fewer than [`MIN_AGREEING_LINES`] of the valid scan lines imply a roof within
    /// [`AGREE_CELLS`] cells of shadow of their median: the lines measured different things.
    pub lines_disagree: bool,
    /// The roof the scan lines imply over the real terrain (median of tip terrain + length ·
    /// tan e) is more than [`AGREE_CELLS`] cells of shadow from the refined roof (for a fitted
    /// pitch: outside its eaves-to-ridge range by more than that).
    pub estimates_disagree: bool,
    /// The synthetic shadow at the refined height overlaps the observed one by less than
    /// [`MIN_OVERLAP`] (IoU).
    pub poor_shadow_match: bool,
    /// Scan lines dropped where the shadow ran into something that hides its end saw it reach
    /// a roof more than [`AGREE_CELLS`] cells of shadow above the measured one
    /// ([`uncertainty::at_least`]): the valid lines ended early (a car's or a tree's lit top in
    /// the shadow, a misread cell), and the roof is probably higher.
    pub shadow_reaches_further: bool,
    /// A frame photo's lean gives a roof ([`lean`]) the shadow's height disagrees with: one of
    /// the two is wrong.
    pub lean_disagrees: bool,
    /// No shadow height: the height is the one the frame photo's lean gives ([`lean`]), the
    /// outline's (a pitched roof's eaves).
    pub height_from_lean: bool,
}

impl Flags {
    /// The names of the set flags, in a fixed order (the output's `flags` array).
    pub fn names(&self) -> Vec<&'static str> {
        [
            (self.no_shadow, "no_shadow"),
            (
                self.shadow_cut_by_edge_or_nodata,
                "shadow_cut_by_edge_or_nodata",
            ),
            (self.shadow_on_other_building, "shadow_on_other_building"),
            (self.low_sun, "low_sun"),
            (self.high_sun, "high_sun"),
            (self.pitched_roof, "pitched_roof"),
            (self.footprint_off_photo, "footprint_off_photo"),
            (self.lines_disagree, "lines_disagree"),
            (self.estimates_disagree, "estimates_disagree"),
            (self.poor_shadow_match, "poor_shadow_match"),
            (self.shadow_reaches_further, "shadow_reaches_further"),
            (self.lean_disagrees, "lean_disagrees"),
            (self.height_from_lean, "height_from_lean"),
        ]
        .into_iter()
        .filter_map(|(on, name)| on.then_some(name))
        .collect()
    }
}

/// The measurement of one footprint. Heights are `None` when no valid scan line found shadow.
#[derive(Debug, Clone, PartialEq)]
pub struct Measurement {
    /// Refined roof height above the highest ground under the footprint, metres.
    pub height_m: Option<f64>,
    /// Refined absolute roof height, metres.
    pub roof_z: Option<f64>,
    /// First estimate `L · tan(elevation)`, metres.
    pub initial_height_m: Option<f64>,
    /// IoU of the synthetic shadow at `height_m` and the observed shadow, in [0, 1].
    pub overlap: Option<f64>,
    /// One cell of shadow length in height: `cell · tan(elevation)`, metres.
    pub uncertainty_m: f64,
    /// Highest terrain under the footprint, metres.
    pub ground_z: f64,
    /// Median shadow length, metres.
    pub shadow_length_m: Option<f64>,
    /// Scan lines cast, and those that gave a length.
    pub lines_total: usize,
    /// See `lines_total`.
    pub lines_used: usize,
    /// The roofs the valid lines imply over the real terrain (terrain at the shadow's tip +
    /// its length · tan e): their lower quartile, median and upper quartile, absolute metres;
    /// `None` without a valid line. How much the lines agree.
    pub line_roofs: Option<[f64; 3]>,
    /// The detection threshold on the shadow index (`None` with a given mask or no contrast).
    pub threshold: Option<f64>,
    /// The roof's plausible range at 68 % and 95 % (absolute metres, low and high), with
    /// `roof_z`: see [`uncertainty`].
    pub roof_z_intervals: Option<[(f64, f64); 2]>,
    /// Without a height: the lowest roof the shadow is seen to imply where it runs into
    /// something that hides its end (absolute metres; [`uncertainty::at_least`]).
    pub roof_z_at_least: Option<f64>,
    /// Hard cases met.
    pub flags: Flags,
    /// The pitched roof fitted ([`pitched`]), whose ridge is `roof_z`; `None`: flat.
    pub pitch: Option<crate::roof::Pitch>,
}

impl Measurement {
    /// This measurement with no height, only `least` (absolute metres) as the lowest roof the
    /// shadow implies, as when no line gave a length; its flags kept as the reasons.
    fn at_least_only(self, least: Option<f64>) -> Measurement {
        Measurement {
            height_m: None,
            roof_z: None,
            initial_height_m: None,
            overlap: None,
            shadow_length_m: None,
            roof_z_intervals: None,
            roof_z_at_least: least,
            pitch: None,
            ..self
        }
    }
}

/// How footprints were registered to the photo before measuring ([`register_footprints`]).
#[derive(Debug, Clone, PartialEq)]
pub struct Registration {
    /// The shift applied to every footprint, metres (east, north), and how many buildings'
    /// clear estimates it rests on; `None`: none was clear, nothing moved.
    pub scene: Option<(f64, f64, usize)>,
    /// Each footprint's own estimate (relative to the footprint as given).
    pub buildings: Vec<Option<register::Shift>>,
    /// Each footprint's roof lean in a perspective photo, metres (east, north); zeros for an
    /// orthophoto.
    pub leans: Vec<(f64, f64)>,
    /// The perspective centre the leans are toward, with whether it was estimated
    /// ([`register::estimate_camera`]) rather than given; `None` for an orthophoto.
    pub camera: Option<(register::PerspectiveCentre, bool)>,
}

impl Registration {
    /// No registration: `n` footprints taken as given.
    pub fn none(n: usize) -> Registration {
        Registration {
            scene: None,
            buildings: vec![None; n],
            leans: vec![(0.0, 0.0); n],
            camera: None,
        }
    }

    /// The applied shift, metres (east, north); zero when none.
    pub fn applied(&self) -> (f64, f64) {
        self.scene.map_or((0.0, 0.0), |(e, n, _)| (e, n))
    }

    /// Set `footprint_off_photo` on every measurement (one per registered footprint, in order)
    /// whose footprint is [`Self::off_photo`] by more than a cell of `grid`.
    pub fn flag_off_photo(
        &self,
        measured: &mut [std::result::Result<Measurement, String>],
        grid: &Grid,
    ) {
        let (cx, cy) = grid.cell_size();
        for (k, m) in measured.iter_mut().enumerate() {
            if let Ok(m) = m {
                m.flags.footprint_off_photo = self.off_photo(k, cx.max(cy));
            }
        }
    }

    /// Whether footprint `k`'s own clear estimate is more than `cell` metres from the applied
    /// shift plus its lean.
    pub fn off_photo(&self, k: usize, cell: f64) -> bool {
        let (e, n) = self.applied();
        let (le, ln) = self.leans[k];
        self.buildings[k]
            .is_some_and(|s| s.counts() && (s.east_m - e - le).hypot(s.north_m - n - ln) > cell)
    }
}

/// Estimate every footprint's shift onto its roof in `inputs.colour` lit by `sun`, then the
/// scene's shift: the median of the clear estimates for an orthophoto (each sought within
/// ±`max_shift_m` metres), or, with the `camera` of a perspective photo, the shift that leaves
/// only radial leans ([`register::with_camera`]; each sought along its radial direction over
/// the leans of roofs up to `opts.max_height_m` above the ground under it, within
/// ±`max_shift_m`: [`register::Reach::leaning`]). Returns the registration and the footprints
/// moved by the scene's shift.
pub fn register_footprints(
    inputs: &Inputs,
    footprints: &[Footprint],
    sun: &Sun,
    max_shift_m: f64,
    camera: Option<&register::PerspectiveCentre>,
    opts: &Options,
) -> Result<(Registration, Vec<Footprint>)> {
    let colour = inputs.colour;
    let grid = colour.grid();
    let (e, n) = sun.direction();
    let (cx, cy) = grid.cell_size();
    let grounds = match camera {
        None => Vec::new(),
        Some(_) => grounds_under(inputs.terrain, footprints, opts.band_cells)?,
    };
    let reaches: Vec<register::Reach> = match camera {
        None => vec![register::Reach::square(max_shift_m); footprints.len()],
        Some(cam) => grounds
            .iter()
            .zip(footprints)
            .map(|(&g, f)| register::Reach::leaning(f, cam, g, max_shift_m, opts.max_height_m))
            .collect(),
    };
    // The search reads the photo up to the largest shift away, plus the fine search's ¾ pixel,
    // the samples' offset across the outline and the bilinear neighbour: 4 cells more.
    let margin = max_shift_m.max(0.0) / cy.abs().min(cx.abs()) + 4.0;
    let estimates = |sought: &[(usize, register::Reach)]| {
        let needs: Vec<Range<usize>> = sought
            .iter()
            .map(|(k, r)| box_rows(grid, r.leaned_box(footprints[*k].bbox()), margin))
            .collect();
        in_bands(
            &needs,
            rows_in(opts.band_cells, grid.width),
            |rows, members| {
                let band = RowBand::read(colour, rows)?;
                Ok(members
                    .par_iter()
                    .map(|&i| {
                        let (k, reach) = &sought[i];
                        register::estimate(&footprints[*k], &band, (-e, -n), reach)
                    })
                    .collect())
            },
        )
    };
    let all: Vec<(usize, register::Reach)> = reaches.iter().copied().enumerate().collect();
    let mut buildings = estimates(&all)?;
    let (scene, leans) = match camera {
        None => (
            register::scene_shift(&buildings),
            vec![(0.0, 0.0); footprints.len()],
        ),
        Some(cam) => {
            let cell = cx.max(cy);
            let (scene, _) = register::with_camera(footprints, &buildings, cam, cell);
            if let Some((ge, gn, _)) = scene {
                let again =
                    register::off_the_leans(footprints, &buildings, cam, &grounds, (ge, gn), cell);
                let sought: Vec<(usize, register::Reach)> = again
                    .iter()
                    .map(|&k| (k, reaches[k].along_from((ge, gn), cell)))
                    .collect();
                for ((k, _), s) in sought.iter().zip(estimates(&sought)?) {
                    if let Some(s) = s.filter(|s| s.counts()) {
                        buildings[*k] = Some(register::Shift {
                            along_lean: true,
                            ..s
                        });
                    }
                }
            }
            register::with_camera(footprints, &buildings, cam, cell)
        }
    };
    let reg = Registration {
        scene,
        buildings,
        leans,
        camera: camera.map(|c| (*c, false)),
    };
    let (e, n) = reg.applied();
    let moved = footprints
        .iter()
        .map(|f| register::moved(f, e, n))
        .collect();
    Ok((reg, moved))
}

/// The bare ground under each footprint's box centre, absolute metres (NaN off the grid or on
/// nodata), read band by band.
fn grounds_under(
    terrain: &dyn RowSource<f32>,
    footprints: &[Footprint],
    band_cells: usize,
) -> Result<Vec<f64>> {
    let grid = terrain.grid();
    let needs: Vec<Range<usize>> = footprints
        .iter()
        .map(|f| box_rows(grid, f.bbox(), 1.0))
        .collect();
    in_bands(&needs, rows_in(band_cells, grid.width), |rows, members| {
        let band = RowBand::read(terrain, rows)?;
        Ok(members
            .iter()
            .map(|&k| {
                let (x, y) = footprints[k].bbox_centre();
                grid.cell_at(x, y)
                    .filter(|&(_, r)| band.holds_row(r))
                    .map_or(f64::NAN, |(c, r)| f64::from(*band.get(c, r)))
            })
            .collect())
    })
}

/// The whole stage for footprints as given: register them to the photo (unless
/// `max_shift_m` is 0), measure them, and flag those off the photo. Returns the registration
/// and one result per footprint.
///
/// Without a `camera`, a photo whose buildings' own shifts disagree with the scene's (at least
/// [`register::MIN_CAMERA_BUILDINGS`] of them, and [`register::MIN_CAMERA_FRACTION`] of those
/// with a clear estimate, off it by more than a cell: no single shift puts them all on their
/// roofs) may be a perspective one. Then the footprints are measured as
/// given, a perspective centre is sought that explains the shifts by those heights
/// ([`register::estimate_camera`]), and, when one does, the footprints are registered and
/// measured again as with that camera (recorded as estimated). An orthophoto pays nothing.
pub fn register_and_measure(
    inputs: &Inputs,
    given: &[Footprint],
    sun: &Sun,
    opts: &Options,
    max_shift_m: f64,
    camera: Option<&register::PerspectiveCentre>,
) -> Result<(Registration, Vec<std::result::Result<Measurement, String>>)> {
    let grid = inputs.terrain.grid();
    let (cx, cy) = grid.cell_size();
    let cell = cx.max(cy);
    let run = |reg: Registration, moved: Vec<Footprint>| -> Result<_> {
        let leaned = Inputs {
            leans: reg.camera.is_some().then_some(&reg.leans[..]),
            ..*inputs
        };
        let mut measured = measure(&leaned, &moved, sun, opts)?;
        reg.flag_off_photo(&mut measured, grid);
        if let Some((cam, _)) = reg.camera {
            meet_leans(&reg, &cam, &moved, &mut measured, cell);
        }
        Ok((reg, measured))
    };
    if max_shift_m <= 0.0 {
        return run(Registration::none(given.len()), given.to_vec());
    }
    let (reg, moved) = register_footprints(inputs, given, sun, max_shift_m, camera, opts)?;
    if camera.is_some() || !may_be_perspective(&reg, cell) {
        return run(reg, moved);
    }
    match camera_from_heights(inputs, given, sun, opts, &reg, cell)? {
        None => run(reg, moved),
        Some(cam) => {
            let (mut reg, moved) =
                register_footprints(inputs, given, sun, max_shift_m, Some(&cam), opts)?;
            reg.camera = Some((cam, true));
            run(reg, moved)
        }
    }
}

/// Meet each measurement of `footprints` (registered as `reg` in a frame photo taken from
/// `camera`, `cell` metres) with the height its lean gives ([`lean::meet`]).
fn meet_leans(
    reg: &Registration,
    camera: &register::PerspectiveCentre,
    footprints: &[Footprint],
    measured: &mut [std::result::Result<Measurement, String>],
    cell: f64,
) {
    for (k, ((m, fp), &l)) in measured
        .iter_mut()
        .zip(footprints)
        .zip(&reg.leans)
        .enumerate()
    {
        if let Ok(m) = m {
            if let Some(h) = lean::LeanHeight::new(fp, l, camera, m.ground_z, cell) {
                let along_lean = reg.buildings[k].is_some_and(|s| s.along_lean);
                lean::meet(m, &h, pitched::highest_rise(fp), along_lean);
            }
        }
    }
}

/// Whether the photo registered as `reg` may be a perspective one: at least
/// [`register::MIN_CAMERA_BUILDINGS`] of its footprints, and [`register::MIN_CAMERA_FRACTION`]
/// of those with a clear estimate, are off the scene's shift by more than `cell` metres
/// ([`Registration::off_photo`]).
fn may_be_perspective(reg: &Registration, cell: f64) -> bool {
    let off = (0..reg.buildings.len())
        .filter(|&k| reg.off_photo(k, cell))
        .count();
    let clear = reg
        .buildings
        .iter()
        .flatten()
        .filter(|s| s.counts())
        .count();
    off >= register::MIN_CAMERA_BUILDINGS
        && (off as f64) >= register::MIN_CAMERA_FRACTION * clear as f64
}

/// The perspective centre that explains the footprints' own shifts (`reg`, for the footprints
/// `given`) by their heights measured as given ([`register::estimate_camera`], from the
/// heights no flag doubts, over the median ground under the footprints; `cell` metres); `None`
/// when none does.
fn camera_from_heights(
    inputs: &Inputs,
    given: &[Footprint],
    sun: &Sun,
    opts: &Options,
    reg: &Registration,
    cell: f64,
) -> Result<Option<register::PerspectiveCentre>> {
    let as_given = measure(inputs, given, sun, opts)?;
    let trusted = |m: &Measurement| {
        let f = &m.flags;
        !(f.no_shadow
            || f.lines_disagree
            || f.estimates_disagree
            || f.poor_shadow_match
            || f.shadow_reaches_further)
    };
    let heights: Vec<Option<f64>> = as_given
        .iter()
        .map(|m| {
            m.as_ref()
                .ok()
                .filter(|m| trusted(m))
                .and_then(|m| m.height_m)
        })
        .collect();
    let grounds: Vec<f64> = as_given
        .iter()
        .filter_map(|m| m.as_ref().ok().map(|m| m.ground_z))
        .collect();
    Ok(scan::median(&grounds).and_then(|ground_z| {
        register::estimate_camera(given, &reg.buildings, &heights, ground_z, cell)
    }))
}

/// [`register_and_measure`] for the features of a footprint file ([`read_footprints`]): their
/// valid footprints registered and measured. Returns the registration (an estimate per valid
/// footprint) and one result per feature, in order: its measurement, or why its footprint is
/// unusable or could not be measured ([`output::per_feature`]).
pub fn measure_features(
    inputs: &Inputs,
    features: &[InputFeature],
    sun: &Sun,
    opts: &Options,
    max_shift_m: f64,
    camera: Option<&register::PerspectiveCentre>,
) -> Result<(Registration, Vec<std::result::Result<Measurement, String>>)> {
    let given: Vec<Footprint> = features
        .iter()
        .filter_map(|f| f.footprint.clone().ok())
        .collect();
    let (registration, measured) =
        register_and_measure(inputs, &given, sun, opts, max_shift_m, camera)?;
    Ok((registration, output::per_feature(features, measured)))
}

/// Measure every footprint. The outer error is for the whole run (grids that differ, a grid in
/// degrees); the inner one is a one-line reason a footprint could not be measured.
///
/// The layers are read band of rows by band of rows ([`Options::band_cells`]), each band with
/// the rows its footprints' windows reach, twice (one band sweep a pass); the whole-grid state
/// is the bare terrain's cast shadow (a bit a cell) and the footprints. Results do not depend
/// on the band size: every footprint reads the same cells with the same coordinates.
pub fn measure(
    inputs: &Inputs,
    footprints: &[Footprint],
    sun: &Sun,
    opts: &Options,
) -> Result<Vec<std::result::Result<Measurement, String>>> {
    check_run(inputs, opts)?;
    // Shadows of the bare terrain: where a building's shadow cannot be told from the hill's.
    let terrain_shadow = ShadowBits::cast(inputs.terrain, sun, |_, _| ())?;
    let passes = Passes::new(*inputs, footprints, sun, opts, terrain_shadow);
    // Pass 1 sketches every building on its own; pass 2 measures them, with the ground the
    // others' shadows cover at their pass-1 roofs (plus their uncertainty) unusable: a shadow
    // merging into a taller neighbour's would otherwise be measured to the end of the
    // neighbour's.
    let no_roofs = vec![None; footprints.len()];
    let first = passes.run(&no_roofs, true, None, None)?;
    let roofs: Vec<Option<f64>> = first
        .iter()
        .map(|m| {
            m.as_ref()
                .ok()
                .and_then(|m| Some(m.roof_z? + m.uncertainty_m))
        })
        .collect();
    let thresholds: Vec<Option<f64>> = first
        .iter()
        .map(|m| m.as_ref().ok().and_then(|m| m.threshold))
        .collect();
    let mut measured = passes.run(&roofs, false, Some(&thresholds), None)?;
    // The joint passes: the footprints the others' shadows and roofs bear on, measured again
    // with the others at their roofs so far (every one from the same pass: the order of the
    // footprints changes nothing).
    let again: Vec<usize> = (0..footprints.len())
        .filter(|&k| measured[k].as_ref().is_ok_and(joint::wanted))
        .collect();
    for _ in 0..opts.joint_passes {
        if again.is_empty() {
            break;
        }
        let known = joint::Known::from(&measured, &roofs);
        let redone = passes.run(
            &known.shading,
            false,
            Some(&thresholds),
            Some((&again, &known)),
        )?;
        for (&k, m) in again.iter().zip(redone) {
            measured[k] = m;
        }
    }
    Ok(measured)
}

/// Whether [`measure`] can run: the colour, elevation and any mask on one grid, and the
/// options in range; the error says what is not.
fn check_run(inputs: &Inputs, opts: &Options) -> Result<()> {
    let grid = inputs.terrain.grid();
    if inputs.colour.grid() != grid {
        return Err(
            Error::msg("the colour and elevation layers are on different grids")
                .fix("re-run `dbms ingest`"),
        );
    }
    if inputs.mask.is_some_and(|m| m.grid() != grid) {
        return Err(Error::msg("the shadow mask is not on the database grid")
            .fix("make it on the database grid (same size, origin and cell size as the database layers)"));
    }
    if !(opts.line_spacing_cells.is_finite() && opts.line_spacing_cells > 0.0) {
        return Err(Error::msg(format!(
            "--line-spacing {} is not a positive number of cells",
            opts.line_spacing_cells
        )));
    }
    if !(1..=15).contains(&opts.sub_points) {
        return Err(Error::msg(format!(
            "--sub-points {} is not from 1 to 15",
            opts.sub_points
        )));
    }
    if !(opts.max_height_m.is_finite() && opts.max_height_m > 0.0) {
        return Err(Error::msg(format!(
            "--max-height {} is not a positive number of metres",
            opts.max_height_m
        )));
    }
    Ok(())
}

/// What both passes of [`measure`] share: the inputs, the footprints and where each one's
/// outline and shadow may lie, and the rows each one's measurement reads.
struct Passes<'a> {
    inputs: Inputs<'a>,
    footprints: &'a [Footprint],
    sun: &'a Sun,
    opts: &'a Options,
    /// The longest shadow sought, metres ([`reach`]).
    reach: f64,
    /// The bare terrain's cast shadow over the whole grid.
    terrain_shadow: ShadowBits,
    /// Every footprint's box swept over [`Self::reach`] away from the sun.
    shadows: BoxIndex,
    /// Every footprint's box.
    outlines: BoxIndex,
    /// Per footprint, the rows its measurement reads ([`rows_read`]).
    needs: Vec<Range<usize>>,
}

impl<'a> Passes<'a> {
    /// The passes over `footprints` in `inputs` lit by `sun`, whose bare terrain casts
    /// `terrain_shadow`.
    fn new(
        inputs: Inputs<'a>,
        footprints: &'a [Footprint],
        sun: &'a Sun,
        opts: &'a Options,
        terrain_shadow: ShadowBits,
    ) -> Passes<'a> {
        let grid = inputs.terrain.grid();
        let reach = reach(grid, sun, opts);
        let (dx, dy) = sun.direction();
        let away = (-dx * reach, -dy * reach);
        let extent = grid_box(grid, 0..grid.height);
        let (cx, cy) = grid.cell_size();
        let bucket = (reach / 2.0).max(32.0 * cx.max(cy));
        let boxes: Vec<Box2> = footprints.iter().map(|f| f.bbox()).collect();
        let shadows = BoxIndex::new(
            boxes.iter().map(|&b| swept(b, away)).collect(),
            swept(extent, away),
            bucket,
        );
        let outlines = BoxIndex::new(boxes, extent, 32.0 * cx.max(cy));
        let needs = rows_read(grid, footprints, inputs.leans, (-dx, -dy), reach);
        Passes {
            inputs,
            footprints,
            sun,
            opts,
            reach,
            terrain_shadow,
            shadows,
            outlines,
            needs,
        }
    }

    /// One pass over every footprint — or, in a joint pass, over those listed with what is
    /// [`joint::Known`] of the others — band by band, with the others' `roofs` (whose shadows
    /// make ground unusable), `sketch` and the first pass's `thresholds` as [`PassInputs`]
    /// takes them; one result per footprint measured, in order.
    fn run(
        &self,
        roofs: &[Option<f64>],
        sketch: bool,
        thresholds: Option<&[Option<f64>]>,
        joint: Option<(&[usize], &joint::Known)>,
    ) -> Result<Vec<std::result::Result<Measurement, String>>> {
        let grid = self.inputs.terrain.grid();
        let footprints = self.footprints;
        let max_rows = rows_in(self.opts.band_cells, grid.width);
        let every: Vec<usize>;
        let which = match joint {
            Some((listed, _)) => listed,
            None => {
                every = (0..footprints.len()).collect();
                &every
            }
        };
        let needs: Vec<Range<usize>> = which.iter().map(|&k| self.needs[k].clone()).collect();
        in_bands(&needs, max_rows, |rows, members| {
            let band = BandLayers::read(
                &self.inputs,
                rows,
                footprints,
                &self.outlines,
                &self.terrain_shadow,
            )?;
            let shaders = roofs.iter().any(Option::is_some).then(|| {
                let (sun, reach) = (self.sun, self.reach);
                neighbour_shadows(&band.terrain, footprints, roofs, &self.shadows, sun, reach)
            });
            let pass_inputs = PassInputs {
                grid,
                band: &band,
                shaders: shaders.as_ref(),
                leans: self.inputs.leans,
                sun: self.sun,
                opts: self.opts,
                reach: self.reach,
                footprints,
                roofs,
                sketch,
                thresholds,
                shadows: &self.shadows,
                known: joint.map(|j| j.1),
            };
            Ok(members
                .par_iter()
                .map(|&m| {
                    let k = which[m];
                    pass_inputs.measure_footprint(k as u32 + 1, &footprints[k], band.cells_of(k))
                })
                .collect())
        })
    }
}

/// Per footprint, the rows of `grid` its measurement reads: those of its window reaching
/// `reach` metres along `u` (the way shadows fall, unit east, north) and those of its outline
/// moved by its lean (`leans`, metres; none for an orthophoto) with a row either side, where
/// the photo shows its roof.
fn rows_read(
    grid: &Grid,
    footprints: &[Footprint],
    leans: Option<&[(f64, f64)]>,
    u: (f64, f64),
    reach: f64,
) -> Vec<Range<usize>> {
    footprints
        .iter()
        .enumerate()
        .map(|(k, f)| {
            let win = local::window_for(grid, f.bbox(), u, reach, 3);
            let lean = leans.map_or((0.0, 0.0), |l| l[k]);
            let seen = box_rows(grid, register::moved(f, lean.0, lean.1).bbox(), 1.0);
            let classified = win.row..win.row + win.height;
            match (classified.is_empty(), seen.is_empty()) {
                (true, _) => seen,
                (_, true) => classified,
                _ => classified.start.min(seen.start)..classified.end.max(seen.end),
            }
        })
        .collect()
}

/// The longest shadow sought, metres: that of a `max_height_m` building, at most
/// [`MAX_SHADOW_CELLS`] cells.
fn reach(grid: &Grid, sun: &Sun, opts: &Options) -> f64 {
    let tan_e = sun.elevation_deg.to_radians().tan();
    let (cx, cy) = grid.cell_size();
    (opts.max_height_m / tan_e).min(MAX_SHADOW_CELLS * cx.max(cy))
}

/// The rows of `grid` the world box `b` covers, `margin` rows more each side, clipped to the
/// grid (empty for a box off it).
fn box_rows(grid: &Grid, b: Box2, margin: f64) -> Range<usize> {
    let t = &grid.transform;
    let (_, ya) = t.world_to_pixel(b.0, b.1);
    let (_, yb) = t.world_to_pixel(b.2, b.3);
    let h = grid.height as f64;
    let lo = (ya.min(yb) - margin).floor().clamp(0.0, h) as usize;
    let hi = (ya.max(yb) + margin).ceil().clamp(0.0, h) as usize;
    lo..hi.max(lo)
}

/// The world box of rows `rows` of `grid` (its whole width).
fn grid_box(grid: &Grid, rows: Range<usize>) -> Box2 {
    let whole_rows = crate::grid::Window {
        col: 0,
        row: rows.start,
        width: grid.width,
        height: rows.len(),
    };
    window_box(grid, &whole_rows)
}

/// The world box of window `win` of `grid`.
fn window_box(grid: &Grid, win: &crate::grid::Window) -> Box2 {
    let t = &grid.transform;
    let (ax, ay) = t.pixel_to_world(win.col as f64, win.row as f64);
    let (bx, by) = t.pixel_to_world((win.col + win.width) as f64, (win.row + win.height) as f64);
    (ax.min(bx), ay.min(by), ax.max(bx), ay.max(by))
}

/// Run `run(rows, members)` over bands of at most `max_rows` grid rows (more when one item's
/// own rows are more): items in order of the first row they need (`needs[k]`), a band holding
/// the rows every member needs. Returns one result per item, in item order.
fn in_bands<T>(
    needs: &[Range<usize>],
    max_rows: usize,
    mut run: impl FnMut(Range<usize>, &[usize]) -> Result<Vec<T>>,
) -> Result<Vec<T>> {
    let mut order: Vec<usize> = (0..needs.len()).collect();
    order.sort_by_key(|&k| (needs[k].start, k));
    let mut out: Vec<Option<T>> = (0..needs.len()).map(|_| None).collect();
    let mut i = 0;
    while i < order.len() {
        let start = needs[order[i]].start;
        let mut end = needs[order[i]].end;
        let mut j = i + 1;
        while let Some(&k) = order.get(j) {
            let e = end.max(needs[k].end);
            if e - start > max_rows {
                break;
            }
            end = e;
            j += 1;
        }
        let members = &order[i..j];
        for (&k, v) in members.iter().zip(run(start..end, members)?) {
            out[k] = Some(v);
        }
        i = j;
    }
    Ok(out
        .into_iter()
        .map(|v| v.expect("every item is in a band"))
        .collect())
}

/// The layers' rows of one band, and which footprint owns each of its cells.
struct BandLayers<'a> {
    terrain: RowBand<'a, f32>,
    colour: RowBand<'a, [u8; 4]>,
    mask: Option<RowBand<'a, u8>>,
    /// Per cell, the footprint (id = index + 1) whose polygon holds its centre (the last one
    /// when several do), 0 for none.
    owner: RowBand<'a, u32>,
    /// The footprints with a cell in the band, ascending, and their cells (whole-grid indices).
    cells: Vec<(usize, Vec<usize>)>,
    /// Per cell, what it is as open ground, whoever's window it is in: [`NOT_OPEN`] under a
    /// footprint or where the reading cannot be trusted (nodata colour or elevation, shadowed
    /// by the bare terrain, nodata in the mask), else the histogram bin of its shadow index
    /// ([`detect::index_bin`]; from a mask 0 for shadow, 255 for lit).
    ground: RowBand<'a, u16>,
}

/// See [`BandLayers::ground`]: a cell that is not open ground.
const NOT_OPEN: u16 = u16::MAX;

/// The shadow index a given mask's cell stands for: 0 where it says shadow (or nodata), 255
/// where lit (its ground bin too, so a threshold between them splits as the mask does).
fn mask_index(mask: u8) -> u8 {
    if mask != 0 {
        0
    } else {
        255
    }
}

impl<'a> BandLayers<'a> {
    fn read(
        inputs: &Inputs<'a>,
        rows: Range<usize>,
        footprints: &[Footprint],
        outlines: &BoxIndex,
        terrain_shadow: &ShadowBits,
    ) -> Result<BandLayers<'a>> {
        let terrain = RowBand::read(inputs.terrain, rows.clone())?;
        let colour = RowBand::read(inputs.colour, rows.clone())?;
        let mask = inputs
            .mask
            .map(|m| RowBand::read(m, rows.clone()))
            .transpose()?;
        let grid = terrain.grid;
        let near = outlines.meeting(grid_box(grid, rows.clone()));
        let cells: Vec<(usize, Vec<usize>)> = near
            .into_par_iter()
            .map(|k| (k, footprints[k].cells(grid)))
            .collect();
        let (w, first) = (grid.width, rows.start * grid.width);
        let mut owner = vec![0u32; rows.len() * w];
        for (k, cs) in &cells {
            for &i in cs {
                if rows.contains(&(i / w)) {
                    owner[i - first] = *k as u32 + 1;
                }
            }
        }
        let first_cell = rows.start * w;
        let ground: Vec<u16> = (0..rows.len() * w)
            .into_par_iter()
            .map(|k| {
                let i = first_cell + k;
                let c = colour.at(i);
                let in_mask = mask.as_ref().map(|m| *m.at(i));
                if owner[k] != 0
                    || c[3] == 0
                    || terrain.at(i).is_nan()
                    || terrain_shadow.get(i)
                    || in_mask == Some(255)
                {
                    return NOT_OPEN;
                }
                match in_mask {
                    Some(m) => mask_index(m) as u16,
                    None => detect::index_bin(detect::shadow_index(*c)) as u16,
                }
            })
            .collect();
        Ok(BandLayers {
            owner: RowBand::new(grid, rows.clone(), owner),
            ground: RowBand::new(grid, rows, ground),
            terrain,
            colour,
            mask,
            cells,
        })
    }

    /// The cells of footprint `k`, a member of the band (whose rows hold all its cells):
    /// none when it is off the grid.
    fn cells_of(&self, k: usize) -> &[usize] {
        self.cells
            .binary_search_by_key(&k, |c| c.0)
            .map_or(&[], |at| &self.cells[at].1)
    }
}

/// A footprint whose shadow can reach a band ([`neighbour_shadows`]).
struct Caster {
    /// The footprint's id (index + 1).
    id: u32,
    /// Its roof, absolute metres.
    roof: f64,
    /// Its walls, for rays toward the sun.
    walls: refine::Walls,
    /// Its outline swept as far as the roof's shadow reaches over the band's lowest ground.
    hull: Vec<(f64, f64)>,
    /// The band's rows the swept outline covers.
    rows: Range<usize>,
}

impl Caster {
    /// Mark the cells of grid rows `rows` that this footprint's shadow covers (by `rays`, over
    /// `terrain`, the band holding them) in `chunk`, those rows' cells of the band's marks
    /// ([`neighbour_shadows`]).
    fn mark(
        &self,
        chunk: &mut [u32],
        rows: Range<usize>,
        terrain: &RowBand<f32>,
        rays: &ShadowRays,
    ) {
        let grid = terrain.grid;
        let w = grid.width;
        for r in self.rows.start.max(rows.start)..self.rows.end.min(rows.end) {
            let Some(columns) = hull_columns(grid, &self.hull, r) else {
                continue;
            };
            for c in columns {
                let z = *terrain.at(r * w + c) as f64;
                if rays.shade(&self.walls, self.roof, grid.cell_centre(c, r), z) {
                    let v = &mut chunk[(r - rows.start) * w + c];
                    *v = match *v {
                        0 => self.id,
                        v if v == self.id => v,
                        _ => MANY_SHADOWS,
                    };
                }
            }
        }
    }
}

/// The columns of row `r` of `grid` that the convex `hull` (world metres) may cover: its span
/// along the row's centre line, a column more each side, clipped to the grid; `None` when the
/// centre line misses it.
fn hull_columns(grid: &Grid, hull: &[(f64, f64)], r: usize) -> Option<Range<usize>> {
    let t = &grid.transform;
    let (_, y) = grid.cell_centre(0, r);
    let (x0, x1) = footprint::hull_span(hull, y)?;
    let (c0, _) = t.world_to_pixel(x0, y);
    let (c1, _) = t.world_to_pixel(x1, y);
    let wf = grid.width as f64;
    let (c0, c1) = (c0.min(c1), c0.max(c1));
    let c0 = (c0 - 1.0).floor().clamp(0.0, wf) as usize;
    let c1 = (c1 + 1.0).ceil().clamp(0.0, wf) as usize;
    Some(c0..c1)
}

/// How a footprint's shadow is decided for a ground point: by the ray from it toward the sun,
/// followed at most `reach` metres, rising `tan_e` (the tangent of the sun's elevation)
/// metres a metre.
struct ShadowRays {
    tan_e: f64,
    reach: f64,
}

impl ShadowRays {
    /// Whether ground point `p` (world metres) at terrain height `z` (metres) is in the shadow
    /// of a footprint with `walls` (toward the sun) and roof `roof` (absolute metres): its ray
    /// toward the sun meets the walls `t` metres away, within `reach`, below the roof
    /// (`z + t · tan e < roof`, [`refine::Walls::first`]).
    fn shade(&self, walls: &refine::Walls, roof: f64, p: (f64, f64), z: f64) -> bool {
        walls
            .first(p)
            .is_some_and(|t| t <= self.reach && z + t * self.tan_e < roof)
    }
}

/// Per cell of `terrain`'s band: which footprint's shadow at its roof (`roofs`, absolute
/// metres) covers the ground there — the footprint's id (index + 1), [`MANY_SHADOWS`] for
/// more than one, 0 for none. A footprint shades ground point `p` at terrain height `z` when
/// the ray from `p` toward the sun meets its walls within [`reach`] metres (`t`) below its roof:
/// `z + t · tan e < roof` ([`ShadowRays::shade`]). Each footprint is tried on the cells of its
/// outline swept toward the shadow as far as its roof's shadow can reach over the band's
/// lowest ground ([`band_casters`]): the work is the shadows' area, not footprints × window.
fn neighbour_shadows<'a>(
    terrain: &RowBand<'a, f32>,
    footprints: &[Footprint],
    roofs: &[Option<f64>],
    shadows: &BoxIndex,
    sun: &Sun,
    reach: f64,
) -> RowBand<'a, u32> {
    let grid = terrain.grid;
    let rows = terrain.rows();
    let w = grid.width;
    let rays = ShadowRays {
        tan_e: sun.elevation_deg.to_radians().tan(),
        reach,
    };
    let casters = band_casters(terrain, footprints, roofs, shadows, sun, reach);
    // Marked in chunks of rows, in parallel: a cell's mark does not depend on the order its
    // shadows are cast in.
    const CHUNK_ROWS: usize = 32;
    let mut by = vec![0u32; rows.len() * w];
    by.par_chunks_mut(CHUNK_ROWS * w)
        .enumerate()
        .for_each(|(n, chunk)| {
            let start = rows.start + n * CHUNK_ROWS;
            let end = start + chunk.len() / w;
            for caster in &casters {
                caster.mark(chunk, start..end, terrain, &rays);
            }
        });
    RowBand::new(grid, rows, by)
}

/// The footprints whose shadow at their roof (`roofs`, absolute metres; none for the
/// unmeasured) can reach `terrain`'s band: among those whose box swept over `reach` metres
/// away from the sun (`shadows`) meets it, those whose roof's shadow over the band's lowest
/// ground has a length (at most `reach` metres), each with its outline swept that far.
fn band_casters(
    terrain: &RowBand<f32>,
    footprints: &[Footprint],
    roofs: &[Option<f64>],
    shadows: &BoxIndex,
    sun: &Sun,
    reach: f64,
) -> Vec<Caster> {
    let grid = terrain.grid;
    let rows = terrain.rows();
    let z_min = terrain
        .values()
        .iter()
        .copied()
        .filter(|z| z.is_finite())
        .fold(f32::INFINITY, f32::min) as f64;
    let tan_e = sun.elevation_deg.to_radians().tan();
    let toward = sun.direction();
    let band_box = grid_box(grid, rows.clone());
    shadows
        .meeting(band_box)
        .into_par_iter()
        .filter_map(|k| {
            let roof = roofs[k]?;
            let len = ((roof - z_min) / tan_e).min(reach);
            // NaN (no valid ground in the band) or nothing to reach: no shadow here.
            if len.is_nan() || len <= 0.0 {
                return None;
            }
            let f = &footprints[k];
            let along = (-toward.0 * len, -toward.1 * len);
            let lo = box_rows(grid, swept(f.bbox(), along), 1.0);
            let span = lo.start.max(rows.start)..lo.end.min(rows.end);
            Some(Caster {
                id: k as u32 + 1,
                roof,
                walls: refine::Walls::new(f, toward),
                hull: f.swept_hull(along),
                rows: span,
            })
        })
        .collect()
}

/// See [`neighbour_shadows`]: a cell more than one footprint's shadow covers.
const MANY_SHADOWS: u32 = u32::MAX;

/// Read a shadow mask: a one-band 8-bit raster on exactly `grid` (same size and geotransform),
/// 0 = lit, 255 or the declared nodata = nodata, anything else = shadow (`dbms shadows` writes
/// such masks). The result is on `grid`.
pub fn read_mask(path: &std::path::Path, grid: &Grid) -> Result<Raster<u8>> {
    let src = crate::io::read_raster(path)?;
    let crate::io::Samples::U8(v) = &src.samples else {
        return Err(Error::file(path, "a shadow mask must be 8-bit")
            .fix("write it as Byte (gdal_translate -ot Byte)"));
    };
    if src.bands != 1 {
        return Err(Error::file(
            path,
            format!("a shadow mask has one band, this has {}", src.bands),
        )
        .fix("keep only the mask band (gdal_translate -b 1)"));
    }
    if src.grid.width != grid.width
        || src.grid.height != grid.height
        || src.grid.transform != grid.transform
    {
        return Err(Error::file(path, format!("the mask's grid ({} × {}) is not the database grid ({} × {})", src.grid.width, src.grid.height, grid.width, grid.height))
            .fix("make it on the database grid, e.g. with `dbms shadows` or gdalwarp -te/-tr of the database"));
    }
    let nodata = src
        .nodata
        .filter(|n| (0.0..=255.0).contains(n) && n.fract() == 0.0)
        .map(|n| n as u8);
    Ok(Raster::new(
        grid.clone(),
        v.iter()
            .map(|&m| if Some(m) == nodata { 255 } else { m })
            .collect(),
    ))
}

/// Which open or unusable cells of `local` lie in the band (half a cell either side) of an
/// *inlier* scan line (every other cell is false: the refinement reads the bands only there):
/// a valid line whose length is within [`LINE_TOLERANCE`] of the median `len`. Lines that
/// met other buildings, left the grid, or ran on into a neighbour's shadow do not lead the
/// refinement.
fn inlier_bands(local: &Local, s: &scan::Scan, len: f64, n: (f64, f64), cell: f64) -> Vec<bool> {
    line_bands(local, s, n, cell, agreeing(len, cell))
}

/// Which open or unusable cells of `local` lie in the band of a valid scan line whose length
/// is *not* within [`LINE_TOLERANCE`] of the median `len`: where something else's shadow, or
/// a lit car or tree top in this one's, made the line disagree (the joint pass reads every
/// other band).
fn disagreeing_bands(
    local: &Local,
    s: &scan::Scan,
    len: f64,
    n: (f64, f64),
    cell: f64,
) -> Vec<bool> {
    let agrees = agreeing(len, cell);
    line_bands(local, s, n, cell, |l| !agrees(l))
}

/// How far a valid line's length may be from the median and still agree: this share of the
/// median plus this many cells.
const LINE_TOLERANCE: (f64, f64) = (0.3, 2.0);

/// Whether a line's length (metres) agrees with the median `len`: within [`LINE_TOLERANCE`],
/// with `cell` the cell edge (metres).
fn agreeing(len: f64, cell: f64) -> impl Fn(f64) -> bool {
    let tol = LINE_TOLERANCE.0 * len + LINE_TOLERANCE.1 * cell;
    move |l| (l - len).abs() <= tol
}

/// Which open or unusable cells of `local` lie in the band (half a cell either side, across
/// the lines: `n`, unit) of a valid line of `s` whose length (metres) is `chosen`.
fn line_bands(
    local: &Local,
    s: &scan::Scan,
    n: (f64, f64),
    cell: f64,
    chosen: impl Fn(f64) -> bool,
) -> Vec<bool> {
    let mut ts: Vec<f64> = s
        .line_t
        .iter()
        .zip(&s.lengths)
        .filter(|(_, &l)| chosen(l))
        .map(|(&t, _)| t)
        .collect();
    ts.sort_by(f64::total_cmp);
    let w = local.grid.width;
    // `k` is `ts.partition_point(|&v| v < t)`, followed from cell to cell along a row (where
    // `t` moves steadily) rather than searched for.
    let mut k = 0;
    (0..local.class.len())
        .map(|i| {
            // Only open and unusable cells are read through the bands (the refinement's).
            if !matches!(local.class[i], Class::Lit | Class::Shadow | Class::Unusable) {
                return false;
            }
            let (x, y) = local.grid.cell_centre(i % w, i / w);
            let t = (x - s.origin.0) * n.0 + (y - s.origin.1) * n.1;
            while k < ts.len() && ts[k] < t {
                k += 1;
            }
            while k > 0 && ts[k - 1] >= t {
                k -= 1;
            }
            let near = |j: usize| ts.get(j).is_some_and(|&v| (v - t).abs() <= cell / 2.0);
            near(k) || (k > 0 && near(k - 1))
        })
        .collect()
}

/// `base` (one optional class per cell of `grid`, a window) with the cells that an edge of
/// `fp` crosses — every cell the closed edge touches ([`Corner::Touching`]) — and that are
/// still open ground, [`Class::Edge`]; with a `lean` (metres), also every open cell that the
/// footprint covers anywhere on its way from its base to its leaning roof (outlines every half
/// cell along the lean: their edges, and the cells whose centre they hold).
fn own_edge(
    mut base: Vec<Option<Class>>,
    fp: &Footprint,
    lean: (f64, f64),
    grid: &Grid,
) -> Vec<Option<Class>> {
    let t = &grid.transform;
    let (w, h) = (grid.width as i64, grid.height as i64);
    let (cx, cy) = grid.cell_size();
    let steps = (lean.0.hypot(lean.1) / (0.5 * cx.min(cy))).ceil() as usize;
    let mut mark = |c: i64, r: i64| {
        if c >= 0 && r >= 0 && c < w && r < h {
            let k = (r * w + c) as usize;
            if base[k].is_none() {
                base[k] = Some(Class::Edge);
            }
        }
    };
    for s in 0..=steps {
        let f = if steps == 0 {
            0.0
        } else {
            s as f64 / steps as f64
        };
        let moved = register::moved(fp, f * lean.0, f * lean.1);
        for (a, b) in moved.edges() {
            let (pa, pb) = (t.world_to_pixel(a.0, a.1), t.world_to_pixel(b.0, b.1));
            let d = [pb.0 - pa.0, pb.1 - pa.1];
            for v in Walk::new([pa.0, pa.1], d, Corner::Touching).take_while(|v| v.t_in <= 1.0) {
                mark(v.cell[0], v.cell[1]);
            }
        }
        if s > 0 {
            for i in moved.cells(grid) {
                mark((i % grid.width) as i64, (i / grid.width) as i64);
            }
        }
    }
    base
}

/// The shadow length the scan lines measured, metres: their median, unless too few lines were
/// valid, none saw shadow, or the few left are the lines along the footprint's own edge.
fn shadow_length(s: &scan::Scan, cell: f64) -> Option<f64> {
    if s.lengths.len() < MIN_VALID_LINES.min(s.lines) {
        return None;
    }
    let (Some(len), true) = (scan::median(&s.lengths), s.with_shadow > 0) else {
        return None;
    };
    // Most lines met another footprint and the few left say "no shadow": those are the
    // lines along the footprint's edge, whose first cell its own lit roof covers in part,
    // not a measurement (a 20 % downhill slope at 15° gave 0 m for 8 m).
    (!(len < cell && s.on_other > s.lengths.len())).then_some(len)
}

/// Where one footprint's shadow is sought: away from the sun in a window reaching the longest
/// shadow (`reach`). The cells are classified in a part of it reaching `classified_len`, grown
/// while the scan lines reach its border (a building's shadow is mostly far shorter than the
/// tallest sought); the threshold is always the whole window's. A leaning roof's cells may lie
/// anywhere along its lean: classified whole.
struct Sought<'p, 'a, 'h> {
    pass: &'p PassInputs<'a>,
    id: u32,
    fp: &'p Footprint,
    /// The way shadows fall, `(east, north)`.
    u: (f64, f64),
    /// The roof's offset from its footprint in the photo, metres (`(0, 0)`: none).
    lean: (f64, f64),
    /// The whole window, reaching `reach` along `u`.
    full: crate::grid::Window,
    source: Threshold<'h>,
    /// How far along `u` the cells classified so far reach, metres.
    classified_len: f64,
    /// Cell edge (the larger), metres.
    cell: f64,
    tan_e: f64,
    /// The roof cells the photo shows ([`PassInputs::roof_cells`]; none in a sketch): read
    /// for the pitched look and the faces' shading.
    roof: Vec<usize>,
    /// Whether the others' roofs read shaded are [`Class::Crossed`] ([`PassInputs::crossing`]).
    crossing: bool,
}

impl<'p, 'a, 'h> Sought<'p, 'a, 'h> {
    fn new(
        pass: &'p PassInputs<'a>,
        id: u32,
        fp: &'p Footprint,
        u: (f64, f64),
        full: crate::grid::Window,
        source: Threshold<'h>,
    ) -> Self {
        let (cx, cy) = pass.grid.cell_size();
        let lean = pass.leans.map_or((0.0, 0.0), |l| l[id as usize - 1]);
        Sought {
            pass,
            id,
            fp,
            u,
            lean,
            full,
            source,
            classified_len: match lean == (0.0, 0.0) {
                true => pass.reach / 4.0,
                false => pass.reach,
            },
            cell: cx.max(cy),
            tan_e: pass.sun.elevation_deg.to_radians().tan(),
            roof: Vec::new(),
            crossing: false,
        }
    }

    /// The cells of the window's part reaching `len` (at most `reach`) classified, and the
    /// detection threshold used.
    fn classified(&self, len: f64) -> (Local, Option<f64>) {
        let p = self.pass;
        let win = local::window_for(p.grid, self.fp.bbox(), self.u, len.min(p.reach), 3);
        let (mut local, threshold) =
            p.classify(self.id, self.fp, self.lean, win, self.full, self.source);
        if self.crossing {
            p.mark_crossed_roofs(&mut local);
        }
        (local, threshold)
    }

    fn scan(&self, local: &Local) -> scan::Scan {
        let spacing = self.pass.opts.line_spacing_cells * self.cell;
        scan::scan(
            self.fp,
            local,
            self.u,
            self.cell,
            spacing,
            self.pass.reach,
            self.tan_e,
        )
    }

    /// Scan `local`, doubling the part classified while the lines reach its edge.
    fn scan_growing(&mut self, local: &mut Local) -> scan::Scan {
        let mut s = self.scan(local);
        while s.at_window_edge && self.classified_len < self.pass.reach {
            self.classified_len *= 2.0;
            *local = self.classified(self.classified_len).0;
            s = self.scan(local);
        }
        s
    }
}

/// Where [`PassInputs::classify`] takes a footprint's detection threshold from.
#[derive(Clone, Copy)]
enum Threshold<'h> {
    /// Found already (in the first pass).
    Known(Option<f64>),
    /// To be found: the histogram of the whole window's open cells.
    Open(&'h [u64; 256]),
}

/// What every footprint's measurement in one pass reads.
struct PassInputs<'a> {
    grid: &'a Grid,
    /// The rows of the layers the footprints measured now read.
    band: &'a BandLayers<'a>,
    /// Second pass: whose shadow covers each cell of the band ([`neighbour_shadows`]).
    shaders: Option<&'a RowBand<'a, u32>>,
    /// See [`Inputs::leans`].
    leans: Option<&'a [(f64, f64)]>,
    sun: &'a Sun,
    opts: &'a Options,
    /// The longest shadow sought, metres ([`reach`]).
    reach: f64,
    /// Every footprint's box swept over [`Self::reach`] away from the sun.
    shadows: &'a BoxIndex,
    /// Every footprint, by id − 1.
    footprints: &'a [Footprint],
    /// Per footprint, the roof (absolute metres) whose shadow makes ground unusable for the
    /// others; `None` in the first pass and for unmeasured footprints.
    roofs: &'a [Option<f64>],
    /// Second pass: each footprint's detection threshold from the first (`None` in the first).
    thresholds: Option<&'a [Option<f64>]>,
    /// A joint pass: the others' roofs as measured so far.
    known: Option<&'a joint::Known<'a>>,
    /// The first pass: only the roofs are wanted, to within their uncertainty (one cell of
    /// shadow), which is added to them. The roof is the one the scan lines imply over the
    /// real terrain (the median of their tips' terrain + length · tan e), not refined, and it
    /// is not checked for a pitch.
    sketch: bool,
}

impl PassInputs<'_> {
    /// Footprint `id` (`fp`, whose cell centres in the band are `cells`) measured, or why it
    /// cannot be. Scan lines across the shadow give its length, hence a first height; outside
    /// the first pass the refinement then casts synthetic shadows over the real terrain and
    /// keeps the height whose shadow matches the photo's, flagged unless every estimate agrees.
    fn measure_footprint(
        &self,
        id: u32,
        fp: &Footprint,
        cells: &[usize],
    ) -> std::result::Result<Measurement, String> {
        let ground_z = self.ground_under(cells)?;
        // The threshold depends only on the window's cells: the second pass has the first's.
        let u = self.away_from_sun();
        let full = local::window_for(self.grid, fp.bbox(), u, self.reach, 3);
        let open;
        let source = match self.thresholds {
            Some(known) => Threshold::Known(known[id as usize - 1]),
            None => {
                open = self.open_histogram(&full);
                Threshold::Open(&open)
            }
        };
        let mut sought = Sought::new(self, id, fp, u, full, source);
        if !self.sketch {
            sought.roof = self.roof_cells(id, fp, cells, sought.lean);
        }
        let (mut local, threshold) = sought.classified(sought.classified_len);
        let e = self.sun.elevation_deg;
        let mut m = Measurement {
            height_m: None,
            roof_z: None,
            initial_height_m: None,
            overlap: None,
            uncertainty_m: sought.cell * sought.tan_e,
            ground_z,
            shadow_length_m: None,
            lines_total: 0,
            lines_used: 0,
            line_roofs: None,
            threshold,
            roof_z_intervals: None,
            roof_z_at_least: None,
            flags: Flags {
                low_sun: e < LOW_SUN_DEG,
                high_sun: e > HIGH_SUN_DEG,
                pitched_roof: roof::looks_pitched(
                    &self.band.colour,
                    &sought.roof,
                    self.sun.direction(),
                ),
                ..Flags::default()
            },
            pitch: None,
        };
        let s = self.crossing(&mut sought, &mut local, ground_z);
        m.lines_total = s.lines;
        m.lines_used = s.lengths.len();
        let q = |at| scan::quantile(&s.tip_roofs, at);
        m.line_roofs = q(0.25)
            .zip(q(0.5))
            .zip(q(0.75))
            .map(|((a, b), c)| [a, b, c]);
        m.flags.shadow_cut_by_edge_or_nodata = s.cut > 0;
        m.flags.shadow_on_other_building = s.on_other > 0 || s.crossed > 0;
        m.flags.no_shadow = s.with_shadow == 0 && !s.lengths.is_empty();
        let Some(len) = shadow_length(&s, sought.cell) else {
            m.roof_z_at_least = uncertainty::at_least(&s, ground_z);
            if self.known.is_some() {
                // No length, but the others' roofs known: the whole corridor may tell.
                return self.refine_height(m, &sought, local, &s, None);
            }
            return Ok(m);
        };
        let z0 = len * sought.tan_e;
        let z_ray = scan::median(&s.tip_roofs).map_or(z0, |r| r - ground_z);
        m.shadow_length_m = Some(len);
        m.initial_height_m = Some(z0);
        if self.sketch {
            m.height_m = Some(z_ray);
            m.roof_z = Some(ground_z + z_ray);
            return Ok(m);
        }
        let m = self.refine_height(m, &sought, local, &s, Some([len, z0, z_ray]))?;
        if sought.crossing && m.flags.estimates_disagree {
            // The length ran over the others' roofs, and the shadow cast on the ground alone
            // does not agree with it: neither is a height, the lines' reach is a lower bound.
            return Ok(m.at_least_only(uncertainty::at_least(&s, ground_z)));
        }
        Ok(m)
    }

    /// The scan of `sought` over `local`, grown as needed ([`Sought::scan_growing`]). When it
    /// gives no length and lines met other footprints, in an orthophoto (where the roofs are
    /// where their footprints are) and outside a joint pass (which fits the shadow on the
    /// others' known roofs instead), the footprint is scanned again with the others' roofs
    /// that read shaded walked through ([`Self::mark_crossed_roofs`]) — a tower's shadow over
    /// a lower neighbour runs on to the ground beyond it — and that scan is kept (with
    /// `sought` and `local` crossing) when it gives a length, or a higher lower bound over
    /// `ground_z` ([`uncertainty::at_least`]; the shadow seen on a roof is as far as it
    /// reached at least).
    fn crossing(&self, sought: &mut Sought, local: &mut Local, ground_z: f64) -> scan::Scan {
        let s = sought.scan_growing(local);
        let blocked = shadow_length(&s, sought.cell).is_none() && s.on_other > 0;
        if !blocked || sought.lean != (0.0, 0.0) || self.known.is_some() {
            return s;
        }
        sought.crossing = true;
        let mut crossed = sought.classified(sought.classified_len).0;
        let c = sought.scan_growing(&mut crossed);
        let higher = uncertainty::at_least(&c, ground_z) > uncertainty::at_least(&s, ground_z);
        if shadow_length(&c, sought.cell).is_none() && !higher {
            sought.crossing = false;
            return s;
        }
        *local = crossed;
        c
    }

    /// Mark as [`Class::Crossed`] the cells of `local` under other footprints whose roof reads
    /// shaded there: a shadow index under [`detect::MAX_DARK_RATIO`] × that roof's lit level
    /// ([`Self::lit_roof_level`]), as far apart as a clear split of shadow from lit ground. A
    /// roof of one colour all over (lit, or dark tiles) is never crossed.
    fn mark_crossed_roofs(&self, local: &mut Local) {
        let (w, win) = (self.grid.width, local.win);
        let mut levels: Vec<(u32, Option<f64>)> = Vec::new();
        for k in 0..local.class.len() {
            if local.class[k] != Class::Other {
                continue;
            }
            let i = grid_index(&win, w, k);
            let owner = *self.band.owner.at(i);
            let level = match levels.iter().find(|(o, _)| *o == owner) {
                Some(&(_, level)) => level,
                None => {
                    let level = self.lit_roof_level(owner as usize - 1);
                    levels.push((owner, level));
                    level
                }
            };
            if level.is_some_and(|l| self.index_at(i) < detect::MAX_DARK_RATIO * l) {
                local.class[k] = Class::Crossed;
            }
        }
    }

    /// The lit level of footprint `k`'s roof: the upper decile of its cells' shadow index in
    /// the band ([`Self::index_at`]); `None` with fewer than [`roof::MIN_CELLS`] cells there.
    fn lit_roof_level(&self, k: usize) -> Option<f64> {
        let rows = self.band.terrain.rows();
        let w = self.grid.width;
        let mut index: Vec<f64> = self
            .band
            .cells_of(k)
            .iter()
            .filter(|&&i| rows.contains(&(i / w)))
            .map(|&i| self.index_at(i))
            .collect();
        if index.len() < roof::MIN_CELLS {
            return None;
        }
        index.sort_by(f64::total_cmp);
        Some(index[index.len() * 9 / 10])
    }

    /// The shadow index of the band's cell `i` (whole-grid index): [`detect::shadow_index`] of
    /// the photo, or from a given mask 0 where it says shadow and 255 where lit.
    fn index_at(&self, i: usize) -> f64 {
        match self.band.mask.as_ref() {
            Some(mask) => mask_index(*mask.at(i)) as f64,
            None => detect::shadow_index(*self.band.colour.at(i)),
        }
    }

    /// The highest valid terrain under a footprint's cells, metres.
    fn ground_under(&self, cells: &[usize]) -> std::result::Result<f64, String> {
        if cells.is_empty() {
            return Err(
                "covers no cell centre of the database grid (outside it, or smaller than a cell)"
                    .into(),
            );
        }
        let ground_z = cells
            .iter()
            .map(|&i| *self.band.terrain.at(i) as f64)
            .filter(|z| z.is_finite())
            .fold(f64::NAN, f64::max);
        match ground_z.is_nan() {
            true => Err("stands on nodata elevation only".into()),
            false => Ok(ground_z),
        }
    }

    /// The horizontal unit vector away from the sun, `(east, north)`: the way shadows fall.
    fn away_from_sun(&self) -> (f64, f64) {
        let (dx, dy) = self.sun.direction();
        (-dx, -dy)
    }

    /// The refinement of `m` (scanned: `s`, with shadow length, first height and the scan
    /// lines' roof above the ground `[len, z0, z_ray]`, if the lines measured a length) over
    /// the cells `local` classified: its height, overlap and agreement flags. No height when
    /// none of the shadow the lines saw is attached to the footprint (nothing to refine
    /// against: no height is better than an unchecked one).
    ///
    /// Heights are sought up to twice the lines' (or, without a length, up to
    /// [`Options::max_height_m`]), over the bands of the scan lines that agree
    /// ([`inlier_bands`]) — in a joint pass, over every band but those of valid lines that
    /// disagree, with the neighbours' known roofs ([`Self::neighbour_roofs`]).
    fn refine_height(
        &self,
        mut m: Measurement,
        sought: &Sought,
        mut local: Local,
        s: &scan::Scan,
        lines: Option<[f64; 3]>,
    ) -> std::result::Result<Measurement, String> {
        let (fp, u, cell, tan_e) = (sought.fp, sought.u, sought.cell, sought.tan_e);
        let z_hi = match lines {
            Some([_, z0, z_ray]) => (2.0 * z0)
                .max(1.5 * z_ray)
                .max(z0 + 4.0 * cell * tan_e)
                .min(self.opts.max_height_m.max(z0 + cell * tan_e)),
            None => self.opts.max_height_m,
        };
        let sub_len = z_hi / tan_e + cell;
        if sub_len > sought.classified_len && sought.classified_len < self.reach {
            local = sought.classified(sub_len).0;
        }
        let mut sub = local.crop(
            local::window_for(self.grid, fp.bbox(), u, sub_len, 3),
            self.grid,
        );
        if let Some(known) = self.known {
            sub.roofs = self.neighbour_roofs(sought.id, &sub, known);
            let previous = known.previous[sought.id as usize - 1].as_ref().ok();
            if let (true, Some(m)) = (sub.roofs.iter().all(Option::is_none), previous) {
                return Ok(m.clone());
            }
        }
        sub.index = self.shade(&sub);
        let n = (-u.1, u.0);
        let keep = match (self.known, lines) {
            (None, Some([len, ..])) => inlier_bands(&sub, s, len, n, cell),
            (Some(_), Some([len, ..])) => disagreeing_bands(&sub, s, len, n, cell)
                .into_iter()
                .map(|b| !b)
                .collect(),
            (_, None) => vec![true; sub.class.len()],
        };
        let ground_z = m.ground_z;
        let Some(r) = refine::refine(
            &sub,
            fp,
            &keep,
            u,
            tan_e,
            ground_z,
            z_hi,
            self.opts.sub_points,
        ) else {
            m.flags.no_shadow |= lines.is_some();
            m.roof_z_at_least = uncertainty::at_least(s, ground_z);
            return Ok(m);
        };
        if lines.is_none() && r.plausible[1].1 >= z_hi - 1e-6 {
            // Censored: the shadow may reach as far as any height sought. What the fit rules
            // out is a lower bound, no height.
            let fitted = ground_z + r.plausible[1].0;
            m.roof_z_at_least = Some(m.roof_z_at_least.map_or(fitted, |z| z.max(fitted)));
            return Ok(m);
        }
        // A pitched-looking roof whose shape fits clearly better: the ridge is its height,
        // the eaves the lowest the scan lines may see; otherwise the flat roof, still flagged.
        // Faces whose shading tells a pitch make a pitched-looking roof too.
        let shaded_by = self
            .shading(sought, &sub)
            .map_or_else(Vec::new, |(r, l)| pitched::shaded_roofs(fp, &r, &l));
        m.flags.pitched_roof |= pitched::shading_tells(&shaded_by);
        let fitted = m.flags.pitched_roof.then(|| {
            let sub_points = self.opts.sub_points;
            pitched::fit(
                &shaded_by, &sub, fp, &keep, u, tan_e, ground_z, z_hi, sub_points, cell,
            )
        });
        let (top_m, eave_m, overlap, plausible) = match fitted.flatten() {
            Some(p) => {
                m.pitch = Some(p.pitch);
                m.flags.pitched_roof = false;
                let eave_m = p.pitch.eave_z - ground_z;
                (p.top_m, eave_m, p.overlap, Some(p.top_plausible_m))
            }
            None => (r.height_m, r.height_m, r.overlap, None),
        };
        m.height_m = Some(top_m);
        m.roof_z = Some(ground_z + top_m);
        m.overlap = Some(overlap);
        // Never a silent wrong height: unflagged only when the lines agree with each other, the
        // refinement agrees with them, and its shadow matches the photo's.
        let tol = AGREE_CELLS * m.uncertainty_m;
        let line_roofs: Vec<f64> = s
            .tip_roofs
            .iter()
            .copied()
            .filter(|z| z.is_finite())
            .collect();
        match scan::median(&line_roofs) {
            Some(ray_roof) => {
                let agreeing = line_roofs
                    .iter()
                    .filter(|z| (*z - ray_roof).abs() <= tol)
                    .count();
                m.flags.lines_disagree =
                    (agreeing as f64) < MIN_AGREEING_LINES * line_roofs.len() as f64;
                let (eave, top) = (ground_z + eave_m, ground_z + top_m);
                m.flags.estimates_disagree = ray_roof < eave - tol || ray_roof > top + tol;
            }
            // No valid line: nothing to disagree with when none was needed (a joint pass).
            None => m.flags.estimates_disagree = lines.is_some(),
        }
        m.flags.poor_shadow_match = overlap < MIN_OVERLAP;
        let least = uncertainty::at_least(s, ground_z);
        m.flags.shadow_reaches_further = least.is_some_and(|z| z > ground_z + top_m + tol);
        // A fitted pitched roof's ridge: its interval is what chose the rise (a point when the
        // shadow did, the pitch's range when the faces' shading did), widened by the walls'
        // place and the lines' spread.
        let fit = match plausible {
            Some(plausible) => refine::Refined {
                height_m: top_m,
                overlap,
                plausible,
            },
            None => r,
        };
        m.roof_z_intervals = Some(uncertainty::intervals(
            &m,
            &fit,
            least,
            // A roof left pitched-looking may rise above the search, up to the steepest pitch.
            [
                z_hi.max(top_m + pitched::highest_rise(fp)),
                self.opts.max_height_m,
            ],
        ));
        Ok(m)
    }

    /// The roof cells of `fp` (own cells `cells`) to read where the photo shows it
    /// ([`roof::inner_cells`]): of the footprint moved by its `lean` (metres) in a perspective
    /// photo. Without a lean, roof cells in a taller neighbour's shadow (second pass: at this
    /// building's first-pass roof) are left out: a roof half in a neighbour's shadow is two
    /// brightnesses with a straight boundary too (`dbms sample`'s adjacent pairs). A leaning
    /// roof is read whole.
    fn roof_cells(&self, id: u32, fp: &Footprint, cells: &[usize], lean: (f64, f64)) -> Vec<usize> {
        let colour = &self.band.colour;
        if lean != (0.0, 0.0) {
            let seen = register::moved(fp, lean.0, lean.1);
            return roof::inner_cells(&seen, colour, &seen.cells(self.grid));
        }
        let inner = roof::inner_cells(fp, colour, cells);
        let Some(own) = self.roofs[id as usize - 1] else {
            return inner;
        };
        let w = self.grid.width;
        let taller = self.shading_neighbours(id, fp, own);
        let tan_e = self.sun.elevation_deg.to_radians().tan();
        inner
            .into_iter()
            .filter(|&i| {
                let p = self.grid.cell_centre(i % w, i / w);
                !self.in_shadow_of(&taller, p, own, tan_e)
            })
            .collect()
    }

    /// What the faces' shading of `sought`'s roof needs ([`shading`]): its roof cells
    /// ([`Sought::roof`]), moved back onto the footprint by the lean, and the light read off the
    /// open ground of `sub` (lit and shadow cells). `None` for a roof of fewer than
    /// [`roof::MIN_CELLS`] cells or of one colour, or when the ground does not tell the light.
    fn shading(&self, sought: &Sought, sub: &Local) -> Option<(shading::Roof, shading::Light)> {
        let colour = &self.band.colour;
        let w = self.grid.width;
        if sought.roof.len() < roof::MIN_CELLS {
            return None;
        }
        let (le, ln) = sought.lean;
        let samples = sought.roof.iter().map(|&i| {
            let (x, y) = self.grid.cell_centre(i % w, i / w);
            ((x - le, y - ln), *colour.at(i))
        });
        let roof = shading::Roof::new(samples, sought.cell, self.opts.photo_encoding);
        if !roof.varies() {
            return None;
        }
        let ground = |want: Class| -> Vec<[u8; 4]> {
            (0..sub.class.len())
                .filter(|&k| sub.class[k] == want)
                .map(|k| *colour.at(grid_index(&sub.win, w, k)))
                .filter(|c| c[3] != 0)
                .collect()
        };
        let light = shading::Light::from_ground(
            self.sun.direction(),
            self.sun.elevation_deg.to_radians(),
            &ground(Class::Lit),
            &ground(Class::Shadow),
            self.opts.photo_encoding,
        )?;
        Some((roof, light))
    }

    /// A [`detect::weak_threshold`] for footprint `fp`'s open ground (`open`: window offset and
    /// shadow index of each open cell; `centre`: a window offset's world centre), taken only
    /// when its dark cells lie where `fp`'s shadow can fall (a ray toward the sun meets `fp`
    /// within [`Self::reach`]) and hardly anywhere else: at most [`WEAK_MAX_STRAY`] of the open
    /// cells that no building's shadow can reach (`others`: the other footprints near) dark,
    /// and [`WEAK_MIN_PLACED`] times as many dark cells where the shadow can be as there.
    fn placed_weak_threshold(
        &self,
        fp: &Footprint,
        others: &[&Footprint],
        open: &[(usize, f64)],
        centre: impl Fn(usize) -> (f64, f64),
    ) -> Option<f64> {
        let t = detect::weak_threshold(open.iter().map(|o| o.1))?;
        let (toward, reach) = (self.sun.direction(), self.reach);
        let reached_by = |f: &refine::Walls, p| f.first(p).is_some_and(|d| d <= reach);
        let own = refine::Walls::new(fp, toward);
        let others: Vec<refine::Walls> = others
            .iter()
            .map(|f| refine::Walls::new(f, toward))
            .collect();
        let (mut dark_in, mut dark_out, mut out) = (0usize, 0usize, 0usize);
        for &(k, v) in open {
            let p = centre(k);
            let dark = v < t;
            if reached_by(&own, p) {
                dark_in += dark as usize;
            } else if !others.iter().any(|f| reached_by(f, p)) {
                out += 1;
                dark_out += dark as usize;
            }
        }
        let stray_ok = dark_out as f64 <= WEAK_MAX_STRAY * out as f64;
        (stray_ok && dark_in > 0 && dark_in as f64 >= WEAK_MIN_PLACED * dark_out as f64)
            .then_some(t)
    }

    /// The walls (toward the sun) and roofs of the other footprints whose shadow can reach
    /// footprint `fp` (id `id`) and whose roof is above `z` metres (only those can shade a
    /// point of it at that height): their box swept toward the shadow over the longest shadow
    /// sought meets `fp`'s.
    fn shading_neighbours(&self, id: u32, fp: &Footprint, z: f64) -> Vec<(refine::Walls, f64)> {
        let toward_sun = self.sun.direction();
        self.reaching(id, fp.bbox())
            .filter_map(|j| {
                let roof = self.roofs[j].filter(|&r| r > z)?;
                Some((refine::Walls::new(&self.footprints[j], toward_sun), roof))
            })
            .collect()
    }

    /// The indices of the other footprints (than `id`) whose shadow could reach the world box
    /// `b` at any height up to `max_height_m`: their box swept toward the shadow over
    /// [`Self::reach`] meets `b`.
    fn reaching(&self, id: u32, b: Box2) -> impl Iterator<Item = usize> + '_ {
        self.shadows
            .meeting(b)
            .into_iter()
            .filter(move |&j| j as u32 + 1 != id)
    }

    /// Whether ground point `p` at terrain height `z` (metres) is in the shadow of one of the
    /// `neighbours` (walls toward the sun, roof): its ray toward the sun meets the walls below
    /// the roof within [`Self::reach`] ([`ShadowRays::shade`], as [`neighbour_shadows`] decides
    /// it for the ground); `tan_e` is the tangent of the sun's elevation.
    fn in_shadow_of(
        &self,
        neighbours: &[(refine::Walls, f64)],
        p: (f64, f64),
        z: f64,
        tan_e: f64,
    ) -> bool {
        let rays = ShadowRays {
            tan_e,
            reach: self.reach,
        };
        neighbours
            .iter()
            .any(|(walls, roof)| rays.shade(walls, *roof, p, z))
    }

    /// The histogram of ground bins ([`BandLayers::ground`]) over the open cells of window `win`:
    /// usable ground under no footprint.
    fn open_histogram(&self, win: &crate::grid::Window) -> [u64; 256] {
        let w = self.grid.width;
        // Counted without a branch: every cell that is not open lands in bin 256, dropped.
        let mut counts = [0u32; 257];
        for r in win.row..win.row + win.height {
            let i = r * w + win.col;
            for &g in self.band.ground.span(i, win.width) {
                counts[(g as usize).min(256)] += 1;
            }
        }
        std::array::from_fn(|k| counts[k] as u64)
    }

    /// Classify the cells of window `win` for footprint `id` (its roof seen `lean` metres from
    /// its base), with the detection threshold of the larger window `full` that holds it
    /// (known, or from `full`'s [`Self::open_histogram`]); the threshold, if any. `win` must hold
    /// every cell an edge of the footprint touches (any window of [`local::window_for`] with
    /// its margin does, and with a lean `full` itself).
    fn classify(
        &self,
        id: u32,
        fp: &Footprint,
        lean: (f64, f64),
        win: crate::grid::Window,
        full: crate::grid::Window,
        source: Threshold,
    ) -> (Local, Option<f64>) {
        let cells = self.window_cells(id, &win);
        let base = own_edge(cells.base, fp, lean, &self.grid.window_grid(&win));
        // Open ground: from the mask, or below the local threshold of the shadow index. Either
        // way a cell is shadow when its ground bin is below `cut` (a mask's shadow is bin 0, its
        // lit ground 255; a threshold is a bin boundary, `split + ½`, so comparing bins is
        // comparing indices).
        let (cut, threshold) = match (self.band.mask.as_ref(), source) {
            (Some(_), _) => (0.5, None),
            (None, Threshold::Known(t)) => (t.unwrap_or(f64::NEG_INFINITY), t),
            (None, Threshold::Open(open)) => {
                let edges = edge_cells(&base, &win, self.grid.width);
                let (cx, cy) = self.grid.cell_size();
                let cell = cx.max(cy);
                let behind: Vec<u16> = scan::first_open_cells(
                    fp,
                    &self.grid.window_grid(&win),
                    &base,
                    self.away_from_sun(),
                    cell,
                    self.opts.line_spacing_cells * cell,
                )
                .into_iter()
                .map(|k| cells.ground[k])
                .collect();
                let threshold = self.window_threshold(id, fp, open, &edges, &behind, &full);
                (threshold.unwrap_or(f64::NEG_INFINITY), threshold)
            }
        };
        let mut class = self.classes(id, &win, &base, &cells.ground, cut);
        if threshold.is_some() && specks::weak_split(&class, &cells.ground) {
            let (cx, cy) = self.grid.cell_size();
            let max_cells = (specks::MAX_SPECK_M2 / (cx * cy)).round() as usize;
            specks::fill_lit_specks(&mut class, win.width, max_cells);
        }
        (
            Local {
                win,
                grid: self.grid.window_grid(&win),
                class,
                heights: cells.heights,
                index: Vec::new(),
                roofs: Vec::new(),
            },
            threshold,
        )
    }

    /// The band's cells of footprint `id`'s window `win`, row-major: see [`WindowCells`].
    fn window_cells(&self, id: u32, win: &crate::grid::Window) -> WindowCells {
        let w = self.grid.width;
        let band = self.band;
        let n = win.width * win.height;
        let (mut heights, mut ground, mut base) = (
            Vec::with_capacity(n),
            Vec::with_capacity(n),
            Vec::with_capacity(n),
        );
        for r in win.row..win.row + win.height {
            let i = r * w + win.col;
            heights.extend_from_slice(band.terrain.span(i, win.width));
            let grounds = band.ground.span(i, win.width);
            ground.extend_from_slice(grounds);
            base.extend(band.owner.span(i, win.width).iter().zip(grounds).map(
                |(&o, &g)| match o {
                    o if o == id => Some(Class::Own),
                    0 => (g == NOT_OPEN).then_some(Class::Unusable),
                    _ => Some(Class::Other),
                },
            ));
        }
        WindowCells {
            heights,
            ground,
            base,
        }
    }

    /// The detection threshold (on the shadow index) of footprint `id`'s (`fp`'s) window
    /// `full`, from `open`, its open cells' histogram ([`Self::open_histogram`]), less the
    /// footprint's `edges` (whole-grid indices, ascending): Otsu's ([`behind_the_walls`]: or a
    /// weak split above it that its `behind` cells say is the shadow), or else a weak split
    /// where the footprint's shadow can fall ([`Self::placed_weak_threshold`]); `None` for
    /// neither. `behind`: the ground bins of the first open cell past the footprint's sun-far
    /// edge on each scan line ([`scan::first_open_cells`]).
    fn window_threshold(
        &self,
        id: u32,
        fp: &Footprint,
        open: &[u64; 256],
        edges: &[usize],
        behind: &[u16],
        full: &crate::grid::Window,
    ) -> Option<f64> {
        let mut hist = *open;
        for &i in edges {
            hist[*self.band.ground.at(i) as usize] -= 1;
        }
        match detect::otsu_threshold_of(&hist, 1.0) {
            Some(t) => Some(behind_the_walls(&hist, t, behind)),
            None => self.weak_window_threshold(id, fp, edges, full),
        }
    }

    /// [`Self::placed_weak_threshold`] for footprint `id` (`fp`) over the open cells of window
    /// `full` but its `edges` (whole-grid indices, ascending), against the other footprints
    /// whose shadow may reach the window.
    fn weak_window_threshold(
        &self,
        id: u32,
        fp: &Footprint,
        edges: &[usize],
        full: &crate::grid::Window,
    ) -> Option<f64> {
        let w = self.grid.width;
        let band = self.band;
        let open: Vec<(usize, f64)> = (0..full.width * full.height)
            .filter(|&k| {
                let i = grid_index(full, w, k);
                *band.ground.at(i) != NOT_OPEN && edges.binary_search(&i).is_err()
            })
            .map(|k| {
                (
                    k,
                    detect::shadow_index(*band.colour.at(grid_index(full, w, k))),
                )
            })
            .collect();
        let others: Vec<&Footprint> = self
            .reaching(id, window_box(self.grid, full))
            .map(|j| &self.footprints[j])
            .collect();
        self.placed_weak_threshold(fp, &others, &open, |k| {
            let i = grid_index(full, w, k);
            self.grid.cell_centre(i % w, i / w)
        })
    }

    /// The class of each cell of footprint `id`'s window `win`: its `base` class where it has
    /// one; else, on open ground, unusable where a neighbour's shadow covers it (second pass:
    /// it still counted for the threshold, where it is shadow like any other), shadow where its
    /// `ground` bin is below `cut`, lit otherwise.
    fn classes(
        &self,
        id: u32,
        win: &crate::grid::Window,
        base: &[Option<Class>],
        ground: &[u16],
        cut: f64,
    ) -> Vec<Class> {
        let w = self.grid.width;
        let shaders: Vec<u32> = match self.shaders {
            Some(s) => (win.row..win.row + win.height)
                .flat_map(|r| s.span(r * w + win.col, win.width).iter().copied())
                .collect(),
            None => Vec::new(),
        };
        let shaded = |k: usize| shaders.get(k).is_some_and(|&v| v != 0 && v != id);
        (0..win.width * win.height)
            .map(|k| {
                base[k].unwrap_or_else(|| {
                    if shaded(k) {
                        Class::Unusable
                    } else if (ground[k] as f64) < cut {
                        Class::Shadow
                    } else {
                        Class::Lit
                    }
                })
            })
            .collect()
    }

    /// The shadow index of `local`'s open cells ([`Class::Lit`], [`Class::Shadow`]) and known
    /// neighbours' roofs ([`Local::roofs`]: the only ones the refinement reads it of),
    /// row-major, NaN for the others: [`detect::shadow_index`] of the photo, or from a given
    /// mask 0 where it says shadow and 255 where lit.
    fn shade(&self, local: &Local) -> Vec<f32> {
        let (w, win) = (self.grid.width, &local.win);
        let cells = (win.row..win.row + win.height)
            .flat_map(|r| r * w + win.col..r * w + win.col + win.width);
        cells
            .zip(&local.class)
            .enumerate()
            .map(|(k, (i, class))| {
                let read = matches!(class, Class::Lit | Class::Shadow) || local.roof(k).is_some();
                if read {
                    self.index_at(i) as f32
                } else {
                    f32::NAN
                }
            })
            .collect()
    }

    /// The known roofs ([`Local::roofs`]) under `local`'s cells for footprint `id`: the
    /// [`Class::Other`] cells of footprints whose roof is a surface in `known`, where no third
    /// footprint's shadow falls at that roof's height ([`ShadowRays::shade`], the others at
    /// their `known` shading roofs).
    fn neighbour_roofs(
        &self,
        id: u32,
        local: &Local,
        known: &joint::Known,
    ) -> Vec<Option<local::RoofCell>> {
        let (w, win) = (self.grid.width, &local.win);
        let toward_sun = self.sun.direction();
        let rays = ShadowRays {
            tan_e: self.sun.elevation_deg.to_radians().tan(),
            reach: self.reach,
        };
        // Each shading footprint's id, walls toward the sun and shading roof.
        let shaders: Vec<(u32, refine::Walls, f64)> = self
            .reaching(id, window_box(self.grid, win))
            .filter_map(|j| {
                let roof = known.shading[j]?;
                let walls = refine::Walls::new(&self.footprints[j], toward_sun);
                Some((j as u32 + 1, walls, roof))
            })
            .collect();
        (0..local.class.len())
            .map(|k| {
                if local.class[k] != Class::Other {
                    return None;
                }
                let (c, r) = (win.col + k % win.width, win.row + k / win.width);
                let owner = *self.band.owner.at(r * w + c);
                let z = known.surfaces[(owner as usize).checked_sub(1)?]?;
                let p = self.grid.cell_centre(c, r);
                let shaded = shaders
                    .iter()
                    .any(|(j, walls, roof)| *j != owner && rays.shade(walls, *roof, p, z));
                (!shaded).then_some(local::RoofCell { owner, z: z as f32 })
            })
            .collect()
    }
}

/// Otsu's threshold `clear` on the histogram `hist`, unless it leaves most of the cells just
/// `behind` a footprint's sun-far walls (their ground bins, [`scan::first_open_cells`]) lit:
/// then the lowest weak split of what it calls lit ([`detect::weak_splits_above`]) that makes
/// most of them shadow, if any. A building's shadow starts at its walls; a split leaving them
/// lit went below the shadow — a low sun's shadow is a weak split in an sRGB photo, and the
/// tree crowns and dark cars in it a clear one below (the POV-Ray town at 12°: lit grass 97,
/// shadow 80, crowns 55–68; every line ended at once). The lowest: over two-tone ground the
/// higher split is the texture. With no cell behind the walls to tell, `clear`.
fn behind_the_walls(hist: &[u64; 256], clear: f64, behind: &[u16]) -> f64 {
    let mostly_shadow =
        |t: f64| 2 * behind.iter().filter(|&&g| (g as f64) < t).count() > behind.len();
    if behind.is_empty() || mostly_shadow(clear) {
        return clear;
    }
    detect::weak_splits_above(hist, clear)
        .into_iter()
        .rfind(|&t| mostly_shadow(t))
        .unwrap_or(clear)
}

/// A window's cells as [`PassInputs::classify`] reads them from the band for one footprint,
/// row-major.
struct WindowCells {
    /// Terrain heights, metres (NaN = nodata).
    heights: Vec<f32>,
    /// Ground bins ([`BandLayers::ground`]).
    ground: Vec<u16>,
    /// What the footprints make of each cell: [`Class::Own`] under this footprint,
    /// [`Class::Other`] under another, [`Class::Unusable`] where the ground is not open, `None`
    /// on open ground.
    base: Vec<Option<Class>>,
}

/// The whole-grid index of offset `k` (row-major) in window `win` of a grid `w` cells wide.
fn grid_index(win: &crate::grid::Window, w: usize, k: usize) -> usize {
    (win.row + k / win.width) * w + win.col + k % win.width
}

/// The whole-grid indices (ascending) of window `win`'s cells that `base` (one optional class
/// per window cell, row-major) makes [`Class::Edge`]; `w` is the grid's width.
fn edge_cells(base: &[Option<Class>], win: &crate::grid::Window, w: usize) -> Vec<usize> {
    (0..base.len())
        .filter(|&k| base[k] == Some(Class::Edge))
        .map(|k| grid_index(win, w, k))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::shadow::cast_shadows;
    use crate::testing::shadow_scene::{self as synth, synth_scene, SynthBuilding, SynthSpec};

    fn building(x: f64, y: f64, h: f64) -> SynthBuilding {
        SynthBuilding {
            centre: (x, y),
            size: (12.0, 9.0),
            rotation_deg: 17.0,
            height_m: h,
        }
    }

    fn spec(e: f64, az: f64, slope: (f64, f64), buildings: Vec<SynthBuilding>) -> SynthSpec {
        SynthSpec {
            cell: 0.5,
            size: (200, 200),
            slope,
            sun: Sun::new(e, az).unwrap(),
            buildings,
            supersample: 3,
        }
    }

    /// Measure a generated scene; per building the measurement (or its error) and the truth.
    fn run(s: &SynthSpec) -> Vec<(std::result::Result<Measurement, String>, f64)> {
        run_with(s, &Options::default())
    }

    /// [`run`] with options `opts`.
    fn run_with(
        s: &SynthSpec,
        opts: &Options,
    ) -> Vec<(std::result::Result<Measurement, String>, f64)> {
        let scene = synth_scene(s);
        let inputs = Inputs {
            terrain: &scene.terrain,
            colour: &scene.colour,
            mask: None,
            leans: None,
        };
        let out = measure(&inputs, &scene.footprints, &s.sun, opts).unwrap();
        out.into_iter().zip(scene.height_m).collect()
    }

    fn assert_within(s: &SynthSpec, tol: f64) -> Vec<Measurement> {
        run(s)
            .into_iter()
            .map(|(m, truth)| {
                let m = m.unwrap();
                let h = m.height_m.unwrap_or_else(|| panic!("no height: {m:?}"));
                assert!(
                    (h - truth).abs() <= tol,
                    "height {h:.3} vs truth {truth} (±{tol}): {m:?}"
                );
                m
            })
            .collect()
    }

    /// Measure `s` with its photo under a bright sky: every channel `v → v/4 + 60`, so shadow
    /// (0.45 of the light) keeps about 0.8 of the lit ground's index, a weak split. `patch`
    /// darkens cells to the shadow's tone where no shadow can fall.
    fn run_hazy(
        s: &SynthSpec,
        patch: impl Fn(f64, f64) -> bool,
    ) -> Vec<std::result::Result<Measurement, String>> {
        measure_synth(&hazy_scene(s, patch), &s.sun)
    }

    /// The scene of `s` with the photo of [`run_hazy`].
    fn hazy_scene(s: &SynthSpec, patch: impl Fn(f64, f64) -> bool) -> synth::SynthScene {
        let mut scene = synth_scene(s);
        let g = scene.colour.grid.clone();
        for (i, p) in scene.colour.data.iter_mut().enumerate() {
            let (x, y) = g.cell_centre(i % g.width, i / g.width);
            let f = if patch(x, y) {
                synth::SHADOW_FACTOR
            } else {
                1.0
            };
            for c in &mut p[..3] {
                *c = (*c as f64 * f / 4.0 + 60.0).round() as u8;
            }
        }
        scene
    }

    /// Every footprint of `scene` measured under `sun`, default options.
    fn measure_synth(
        scene: &synth::SynthScene,
        sun: &Sun,
    ) -> Vec<std::result::Result<Measurement, String>> {
        let inputs = Inputs {
            terrain: &scene.terrain,
            colour: &scene.colour,
            mask: None,
            leans: None,
        };
        measure(&inputs, &scene.footprints, sun, &Options::default()).unwrap()
    }

    /// A low sun in an sRGB photo leaves the shadow a weak split ([`run_hazy`]'s photo), and
    /// what is darker inside it — tree crowns' shaded sides, dark cars: discs of index 45, 0.6
    /// of the shadow's, 3 % of the ground — a clear one below it, which Otsu takes. The cells
    /// behind the walls say the weak split is the shadow (the POV-Ray town at 12°: every line
    /// ended at once, `no_shadow` on 61 of 70 buildings).
    #[test]
    fn hard_case_a_low_suns_faint_shadow_with_darker_clutter_in_it_is_measured() {
        let s = spec(12.0, 225.0, (0.0, 0.0), vec![building(30.0, 30.0, 5.0)]);
        let mut scene = hazy_scene(&s, |_, _| false);
        let g = scene.colour.grid.clone();
        let (ox, oy) = (synth::ORIGIN_X, synth::ORIGIN_Y);
        for (i, p) in scene.colour.data.iter_mut().enumerate() {
            let (x, y) = g.cell_centre(i % g.width, i / g.width);
            // Discs of 1.5 m every 10 m, clear of the footprint (24–36 m each way).
            let (dx, dy) = (
                (x - ox).rem_euclid(10.0) - 5.0,
                (y - oy).rem_euclid(10.0) - 5.0,
            );
            let on_roof = (x - ox - 30.0).abs() < 8.0 && (y - oy - 30.0).abs() < 8.0;
            if dx.hypot(dy) < 1.0 && !on_roof {
                *p = [45, 45, 45, 255];
            }
        }
        let m = measure_synth(&scene, &s.sun).remove(0).unwrap();
        let h = m.height_m.unwrap_or_else(|| panic!("no height: {m:?}"));
        assert!((h - 5.0).abs() <= 0.5, "{m:?}");
        assert!(!m.flags.no_shadow, "{m:?}");
    }

    #[test]
    fn behind_the_walls_a_weak_split_above_otsus_is_the_shadow_when_only_it_darkens_them() {
        // Lit 93–101, shadow 76–84, crowns 50–63 (as detect's test): Otsu's split is the
        // crowns' and leaves the cells behind the walls (the shadow) lit.
        let mut hist = [0u64; 256];
        for i in 0..10_000usize {
            hist[match i % 100 {
                0..=3 => 50 + (i / 100) % 14,
                4..=29 => 93 + (i / 100) % 9,
                _ => 76 + (i / 100) % 9,
            }] += 1;
        }
        let clear = detect::otsu_threshold_of(&hist, 1.0).unwrap();
        let behind = [78, 80, 84, 81, 79, 95];
        let t = behind_the_walls(&hist, clear, &behind);
        assert!(t > 84.0 && t < 93.0, "{clear} {t}");
        // Dark under Otsu's already, nothing to tell by, or lit under every split: Otsu's.
        assert_eq!(behind_the_walls(&hist, clear, &[50, 51, 60]), clear);
        assert_eq!(behind_the_walls(&hist, clear, &[]), clear);
        assert_eq!(behind_the_walls(&hist, clear, &[97, 99, 80]), clear);
    }

    /// A weak split is shadow when its dark cells lie where the building's shadow can fall,
    /// and refused when as dark a texture lies where no shadow can.
    #[test]
    fn hard_case_weak_shadow_contrast_is_measured_only_where_a_shadow_can_fall() {
        let s = spec(30.0, 135.0, (0.0, 0.0), vec![building(40.0, 60.0, 12.0)]);
        let hazy = run_hazy(&s, |_, _| false);
        let m = hazy[0].as_ref().unwrap();
        assert!(
            (m.height_m.expect("measured") - 12.0).abs() <= 0.5 && m.flags.names().is_empty(),
            "{m:?}"
        );
        // A dark field beside the shadow's path (north-east of it, inside the window searched):
        // the building's shadow, cast north-west, reaches (x + y)/√2 ≤ 7.4 m from its centre.
        let (cx, cy) = (synth::ORIGIN_X + 40.0, synth::ORIGIN_Y + 60.0);
        let with_field = run_hazy(&s, |x, y| (x - cx) + (y - cy) > 13.0);
        let m = with_field[0].as_ref().unwrap();
        assert!(m.height_m.is_none() && m.flags.no_shadow, "{m:?}");
    }

    #[test]
    fn isolated_building_on_flat_ground_within_a_cell() {
        let m = assert_within(
            &spec(40.0, 135.0, (0.0, 0.0), vec![building(40.0, 60.0, 12.0)]),
            0.5,
        );
        assert!(m[0].overlap.unwrap() > 0.8, "{m:?}");
        assert!(m[0].flags.names().is_empty(), "{m:?}");
        assert!((m[0].initial_height_m.unwrap() - 12.0).abs() < 1.0);
    }

    #[test]
    fn hard_case_sun_at_89_9_degrees_finds_no_shadow() {
        let r = run(&spec(
            89.9,
            180.0,
            (0.0, 0.0),
            vec![building(50.0, 50.0, 12.0)],
        ));
        let m = r[0].0.as_ref().unwrap();
        assert_eq!(m.flags.names(), ["no_shadow", "high_sun"]);
        assert_eq!((m.height_m, m.roof_z, m.overlap), (None, None, None));
        assert!(
            m.uncertainty_m > 100.0,
            "one cell of shadow is {} m of height",
            m.uncertainty_m
        );
    }

    #[test]
    fn hard_case_sun_at_0_5_degrees_runs_off_the_grid() {
        let r = run(&spec(
            0.5,
            180.0,
            (0.0, 0.0),
            vec![building(50.0, 20.0, 12.0)],
        ));
        let m = r[0].0.as_ref().unwrap();
        assert_eq!(m.flags.names(), ["shadow_cut_by_edge_or_nodata", "low_sun"]);
        assert_eq!(m.height_m, None);
        assert_eq!(m.lines_used, 0);
    }

    #[test]
    fn hard_case_azimuth_along_a_grid_axis_and_at_45_degrees() {
        for az in [0.0, 90.0, 180.0, 270.0, 45.0, 225.0] {
            let b = SynthBuilding {
                rotation_deg: 0.0,
                ..building(50.0, 50.0, 10.0)
            };
            assert_within(&spec(35.0, az, (0.0, 0.0), vec![b]), 0.5);
        }
    }

    #[test]
    fn hard_case_twenty_percent_slope_facing_the_sun_and_facing_away() {
        // Sun in the south. Ground rising to the north: the shadow climbs and is short; falling
        // to the north: it runs downhill and is long. The formula is far off; the refinement is not.
        for (slope, formula_low) in [(0.2, true), (-0.2, false)] {
            let m = assert_within(
                &spec(30.0, 180.0, (0.0, slope), vec![building(50.0, 40.0, 12.0)]),
                0.5,
            );
            let z0 = m[0].initial_height_m.unwrap();
            assert_eq!(z0 < 12.0, formula_low, "formula {z0}");
            assert!(
                (z0 - 12.0).abs() > 2.0,
                "formula {z0} should be off by more than 2 m on a 20 % slope"
            );
        }
    }

    #[test]
    fn hard_case_shadow_falling_on_a_neighbour() {
        // The neighbour stands in the north-west half of the first building's shadow.
        let a = SynthBuilding {
            centre: (40.0, 30.0),
            size: (12.0, 8.0),
            rotation_deg: 0.0,
            height_m: 10.0,
        };
        let b = SynthBuilding {
            centre: (34.0, 44.0),
            size: (10.0, 8.0),
            rotation_deg: 0.0,
            height_m: 6.0,
        };
        let r = run(&spec(40.0, 180.0, (0.0, 0.0), vec![a, b]));
        let m = r[0].0.as_ref().unwrap();
        assert!(m.flags.shadow_on_other_building, "{m:?}");
        assert!(m.lines_used > 0 && m.lines_used < m.lines_total, "{m:?}");
        let h = m.height_m.unwrap();
        assert!((h - 10.0).abs() <= 0.5, "{h} vs 10: {m:?}");
        let m2 = r[1].0.as_ref().unwrap();
        assert!((m2.height_m.unwrap() - 6.0).abs() <= 0.5, "{m2:?}");
    }

    #[test]
    fn hard_case_shadow_running_into_a_lower_neighbours_wall() {
        // The `down-sun` bench's worst case (20 % slope facing away, sun 45°, 0.25 m cells):
        // the first building's shadow runs 5.2 m into the lower neighbour's footprint. Lines
        // ending on a cell against the neighbour's wall that reads lit (its sunlit roof covers
        // part of it) measured the distance to the neighbour: 4.35 m for 18.80 m before. Such
        // lines met the neighbour; the lines beside it measure the building, or none do (null,
        // flagged) — never a wrong height.
        let sun = Sun::new(45.0, 58.29953654945278).unwrap();
        let (dx, dy) = sun.direction();
        let a = SynthBuilding {
            centre: (75.4674677710385, 67.11561379747288),
            size: (15.04534444897039, 13.568530958841706),
            rotation_deg: 27.921860212287445,
            height_m: 18.802532866456055,
        };
        let b = SynthBuilding {
            centre: (54.2542282638537, 53.99919308813154),
            size: (19.264366601472453, 14.953203301026203),
            rotation_deg: 8.672225871233923,
            height_m: 13.338221113402732,
        };
        let s = SynthSpec {
            cell: 0.25,
            size: (430, 430),
            slope: (0.2 * dx, 0.2 * dy), // −0.2 along the shadow direction
            sun,
            buildings: vec![a, b],
            supersample: 2,
        };
        let r = run(&s);
        for (m, truth) in &r {
            let m = m.as_ref().unwrap();
            if let Some(h) = m.height_m {
                assert!((h - truth).abs() <= 0.25, "{h} vs {truth}: {m:?}");
            }
        }
        let m = r[0].0.as_ref().unwrap();
        assert!(m.flags.shadow_on_other_building, "{m:?}");
        assert!(r[1].0.as_ref().unwrap().height_m.is_some(), "{:?}", r[1]);
    }

    #[test]
    fn hard_case_shadow_almost_all_on_a_neighbour_is_measured_jointly_and_flagged() {
        // The neighbour covers the north side of the first building's shadow but for its
        // easternmost scan line: too few to measure from (an adjacent pair of `dbms sample`,
        // seed 3, gave 0.9 m for an 18.5 m building from one such line). The joint pass
        // measures the neighbour's roof, fits the shadow lying on it and the ground beside,
        // and gets the height; flagged, as the shadow met the neighbour.
        let a = SynthBuilding {
            centre: (40.1, 30.0),
            size: (12.0, 8.0),
            rotation_deg: 0.0,
            height_m: 10.0,
        };
        let b = SynthBuilding {
            centre: (37.65, 40.0),
            size: (15.3, 8.0),
            rotation_deg: 0.0,
            height_m: 6.0,
        };
        let joint = Options {
            joint_passes: 1,
            ..Options::default()
        };
        let r = run_with(&spec(40.0, 180.0, (0.0, 0.0), vec![a, b]), &joint);
        let m = r[0].0.as_ref().unwrap();
        assert!(m.lines_used > 0 && m.lines_used < MIN_VALID_LINES, "{m:?}");
        assert!(m.flags.shadow_on_other_building, "{m:?}");
        assert_eq!(m.initial_height_m, None, "{m:?}");
        let h = m.height_m.unwrap_or_else(|| panic!("no height: {m:?}"));
        assert!((h - r[0].1).abs() <= 0.5, "{h} vs {}: {m:?}", r[0].1);
        let [_, (lo, hi)] = m.roof_z_intervals.unwrap();
        assert!(lo <= 410.0 && 410.0 <= hi, "{m:?}");
        let m = &run(&spec(40.0, 180.0, (0.0, 0.0), vec![a, b]))[0].0;
        assert_eq!(m.as_ref().unwrap().height_m, None, "{m:?}");
    }

    #[test]
    fn hard_case_shadow_merging_into_a_taller_neighbours_shadow() {
        // An adjacent pair, sun in the south-east: the taller east half's shadow runs north-west
        // over and past the lower west half, whose own shadow merges into it (`dbms sample`
        // seed 2: +4.1 m before the second pass). The lower one's lines into the taller one's
        // shadow are cut in the second pass; the rest measure it.
        let tall = SynthBuilding {
            centre: (60.0, 40.0),
            size: (10.0, 12.0),
            rotation_deg: 0.0,
            height_m: 18.0,
        };
        let low = SynthBuilding {
            centre: (50.0, 40.0),
            size: (10.0, 12.0),
            rotation_deg: 0.0,
            height_m: 7.5,
        };
        let r = run(&spec(35.0, 120.0, (0.0, 0.0), vec![tall, low]));
        for (m, truth) in &r {
            let m = m.as_ref().unwrap();
            let h = m.height_m.unwrap_or_else(|| panic!("no height: {m:?}"));
            assert!((h - truth).abs() <= 0.5, "{h} vs {truth}: {m:?}");
        }
        assert!(r[1].0.as_ref().unwrap().flags.shadow_cut_by_edge_or_nodata);
    }

    #[test]
    fn hard_case_footprint_touching_the_grid_edge() {
        // South edge of the footprint on the grid's south edge; the sun in the south.
        let b = SynthBuilding {
            centre: (50.0, 5.0),
            size: (12.0, 10.0),
            rotation_deg: 0.0,
            height_m: 9.0,
        };
        let m = assert_within(&spec(40.0, 180.0, (0.0, 0.0), vec![b]), 0.5);
        assert!(m[0].flags.names().is_empty(), "{m:?}");
        // Its shadow leaving the grid on the north edge is flagged and not measured.
        let n = SynthBuilding {
            centre: (50.0, 95.0),
            ..b
        };
        let r = run(&spec(40.0, 180.0, (0.0, 0.0), vec![n]));
        let m = r[0].0.as_ref().unwrap();
        assert!(
            m.flags.shadow_cut_by_edge_or_nodata && m.height_m.is_none(),
            "{m:?}"
        );
    }

    /// Bands of rows change nothing: a scene of nine buildings, shadows falling on neighbours,
    /// footprints off their roofs (registration searched), measured in the smallest bands (one
    /// footprint's rows each) equals the scene measured in one band, to the last bit.
    #[test]
    fn measuring_in_bands_of_rows_is_measuring_the_whole() {
        let mut buildings = Vec::new();
        for (k, (i, j)) in (0..3).flat_map(|i| (0..3).map(move |j| (i, j))).enumerate() {
            let mut b = building(35.0 + 40.0 * i as f64, 35.0 + 40.0 * j as f64, 0.0);
            b.height_m = 12.0 + 4.0 * k as f64;
            b.rotation_deg = 10.0 * k as f64;
            buildings.push(b);
        }
        let mut s = spec(30.0, 150.0, (0.05, -0.1), buildings);
        s.size = (300, 300);
        let scene = synth_scene(&s);
        let off: Vec<Footprint> = scene
            .footprints
            .iter()
            .map(|f| register::moved(f, 1.0, -0.5))
            .collect();
        let inputs = Inputs {
            terrain: &scene.terrain,
            colour: &scene.colour,
            mask: None,
            leans: None,
        };
        let whole = Options::default();
        let thin = Options {
            band_cells: 300,
            ..whole
        };
        let a = register_and_measure(&inputs, &off, &s.sun, &whole, 3.0, None).unwrap();
        let b = register_and_measure(&inputs, &off, &s.sun, &thin, 3.0, None).unwrap();
        assert!(a.0.scene.is_some(), "the shift was searched");
        assert!(
            a.1.iter()
                .filter(|m| m.as_ref().is_ok_and(|m| m.flags.shadow_on_other_building))
                .count()
                > 0,
            "shadows reach neighbours"
        );
        assert_eq!(a, b);
    }

    /// The neighbours' shadow raster is the brute-force rule cell by cell: for every cell,
    /// the footprints whose walls a ray toward the sun meets within the reach below their
    /// roof (none, one id, or more than one), at the axes, a diagonal and a few ulps off it.
    #[test]
    fn neighbour_shadows_are_the_rule_cell_by_cell() {
        for az in [0.0, 90.0, 135.0, 135.0 + 1e-12, 150.0, 270.0] {
            let mut s = spec(35.0, az, (0.05, -0.1), Vec::new());
            s.size = (160, 140);
            let scene = synth_scene(&s);
            let grid = &scene.terrain.grid;
            let origin = (grid.bounds().min_x, grid.bounds().min_y);
            let fps: Vec<Footprint> = (0..6)
                .map(|k| {
                    let (x, y) = (
                        origin.0 + 12.0 + 11.0 * k as f64,
                        origin.1 + 20.0 + 7.0 * (k % 3) as f64,
                    );
                    let ring = vec![
                        (x, y),
                        (x + 8.0, y + 1.0),
                        (x + 7.0, y + 9.0),
                        (x - 1.0, y + 7.0),
                    ];
                    Footprint::new(vec![vec![ring]]).unwrap()
                })
                .collect();
            let roofs: Vec<Option<f64>> = (0..6)
                .map(|k| (k != 2).then_some(400.0 + 4.0 * k as f64))
                .collect();
            let reach = 60.0;
            let away = {
                let (e, n) = s.sun.direction();
                (-e * reach, -n * reach)
            };
            let index = BoxIndex::new(
                fps.iter().map(|f| swept(f.bbox(), away)).collect(),
                swept(grid_box(grid, 0..grid.height), away),
                16.0,
            );
            let terrain = RowBand::whole(&scene.terrain);
            let raster = neighbour_shadows(&terrain, &fps, &roofs, &index, &s.sun, reach);
            let tan_e = s.sun.elevation_deg.to_radians().tan();
            let mut shaded = 0;
            for i in 0..grid.len() {
                let p = grid.cell_centre(i % grid.width, i / grid.width);
                let z = scene.terrain.data[i] as f64;
                let by: Vec<u32> = (0..fps.len())
                    .filter(|&k| {
                        roofs[k].is_some_and(|roof| {
                            refine::Walls::new(&fps[k], s.sun.direction())
                                .first(p)
                                .is_some_and(|t| t <= reach && z + t * tan_e < roof)
                        })
                    })
                    .map(|k| k as u32 + 1)
                    .collect();
                let want = match by[..] {
                    [] => 0,
                    [id] => id,
                    _ => MANY_SHADOWS,
                };
                shaded += (want != 0) as usize;
                assert_eq!(*raster.at(i), want, "cell {i} at {az}°");
            }
            assert!(shaded > 500, "{shaded} cells shaded at {az}°");
        }
    }

    #[test]
    fn footprint_outside_the_grid_fails_alone() {
        let s = spec(40.0, 180.0, (0.0, 0.0), vec![building(50.0, 50.0, 8.0)]);
        let scene = synth_scene(&s);
        let far = Footprint::new(vec![vec![vec![(0.0, 0.0), (10.0, 0.0), (10.0, 10.0)]]]).unwrap();
        let fps = vec![scene.footprints[0].clone(), far];
        let inputs = Inputs {
            terrain: &scene.terrain,
            colour: &scene.colour,
            mask: None,
            leans: None,
        };
        let out = measure(&inputs, &fps, &s.sun, &Options::default()).unwrap();
        assert!((out[0].as_ref().unwrap().height_m.unwrap() - 8.0).abs() <= 0.5);
        assert!(out[1]
            .as_ref()
            .unwrap_err()
            .contains("covers no cell centre"));
    }

    #[test]
    fn a_given_mask_replaces_detection() {
        let s = spec(40.0, 150.0, (0.0, 0.0), vec![building(50.0, 50.0, 8.0)]);
        let scene = synth_scene(&s);
        // A blank photo: detection finds nothing; the mask (the caster's shadow) is what counts.
        let blank = Raster::filled(scene.terrain.grid.clone(), [120u8, 120, 120, 255]);
        let mut raised = scene.terrain.clone();
        for i in scene.footprints[0].cells(&raised.grid) {
            raised.data[i] = scene.roof_z[0] as f32;
        }
        let mask = cast_shadows(&raised, 40.0, 150.0).unwrap();
        let with = Inputs {
            terrain: &scene.terrain,
            colour: &blank,
            mask: Some(&mask),
            leans: None,
        };
        let m = measure(&with, &scene.footprints, &s.sun, &Options::default())
            .unwrap()
            .remove(0)
            .unwrap();
        assert!(
            (m.height_m.unwrap() - 8.0).abs() <= 0.5 && m.threshold.is_none(),
            "{m:?}"
        );
        let without = Inputs {
            terrain: &scene.terrain,
            colour: &blank,
            mask: None,
            leans: None,
        };
        let m = measure(&without, &scene.footprints, &s.sun, &Options::default())
            .unwrap()
            .remove(0)
            .unwrap();
        assert!(m.flags.no_shadow && m.height_m.is_none(), "{m:?}");
    }

    #[test]
    fn mismatched_grids_are_an_error_for_the_run() {
        let s = spec(40.0, 180.0, (0.0, 0.0), vec![building(50.0, 50.0, 8.0)]);
        let scene = synth_scene(&s);
        let other = Raster::filled(
            Grid::north_up(0.0, 10.0, 1.0, 10, 10, scene.terrain.grid.crs.clone()),
            0u8,
        );
        let inputs = Inputs {
            terrain: &scene.terrain,
            colour: &scene.colour,
            mask: Some(&other),
            leans: None,
        };
        let e = measure(&inputs, &scene.footprints, &s.sun, &Options::default()).unwrap_err();
        assert!(e.to_string().contains("not on the database grid"), "{e}");
    }
}
