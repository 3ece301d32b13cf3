//! Sensor views (issue 18): the same geometry drawn from the layer a sensor sees.
//!
//! Invariant: a sensor view changes only what a cell is drawn in, never what a ray hits. Every
//! page is recoloured as the tile reader reads it ([`crate::tiles::TileReader::with_filter`]),
//! so the stepping, coherence and level selection of the visual view run unchanged and the
//! frames of two sensors have the same range image. The infrared view draws each cell's
//! temperature white-hot: [`IrScale::grey`] maps `min_k` to black and `max_k` to white,
//! linearly, clamped. The night-vision view draws each cell's NIR reflectance under the moon
//! and the night sky through an image intensifier's automatic brightness control
//! ([`NightScale`]), then the light points with their halos over the frame
//! ([`NightScale::draw_lights`]). The radar view with the radar at the eye ([`EyeRadar`]) is
//! the one exception to the first rule's letter: it redraws every pixel after the frame, from
//! the range image and the `normal` and `material` layers, so its rays and ranges are still
//! the visual view's. A cell with a surface but no attribute for the sensor
//! (unclassified) is dark red in both, as in `dbms thermal`'s preview; the voxel runs of a
//! partial cell take its colour.

use super::sky::Backdrop;
use super::{Frame, Viewpoint};
use crate::backscatter::{Band, RadarModel};
use crate::choice::Choice;
use crate::error::{Error, Result};
use crate::tiles::{unpack_normal, LightPoint, Page, PageFilter, SensorLayer, TileReader};
use crate::voxel::columns::{PageColumns, Run};
use rayon::prelude::*;
use std::sync::Arc;

crate::choice! {
    /// Which sensor a view is drawn for.
    #[derive(Debug, Clone, Copy, PartialEq, Eq)]
    pub enum Sensor {
        /// Daylight colour: the orthophoto with the pyramid's shading and shadows.
        Visual = "visual",
        /// Thermal infrared, white-hot: the tile set's `temperature` layer (build it with
        /// `dbms pyramid --temperature`).
        Ir = "ir",
        /// Night vision at --time: the `material` layer's NIR reflectance under the moon and
        /// the night sky, and the header's light points (`dbms pyramid --materials --lights`).
        Nvg = "nvg",
        /// Radar backscatter, σ⁰ in dB, −30 dB black to 0 dB white: the `backscatter` layer
        /// (`dbms pyramid --backscatter`, the map from `dbms radar`), or with a band the radar
        /// at the eye ([`EyeRadar`], `dbms pyramid --normals --materials`).
        Radar = "radar",
    }
}

/// Colour of a cell that has a surface but no attribute for the sensor (an unclassified cell).
pub const NO_ATTRIBUTE: [u8; 4] = [96, 0, 0, 255];

/// What a sensor view is drawn with, besides the tile set.
#[derive(Debug, Clone, Default)]
pub struct SensorOptions {
    /// The infrared scale (default: [`IrScale::of_tiles`]).
    pub ir_range: Option<IrScale>,
    /// The night-vision view's instant, RFC 3339 (required for it).
    pub time: Option<String>,
    /// Atmospheric extinction for the moonlight, magnitudes per air mass.
    pub extinction_mag_per_airmass: f64,
    /// The radar view's band when the radar is at the eye (σ⁰ from the `normal` and
    /// `material` layers at each pixel's own incidence); `None`: the `backscatter` layer.
    pub band: Option<Band>,
}

/// How a sensor view draws a tile set.
pub struct SensorView {
    /// Recolours every page as it is read.
    pub filter: PageFilter,
    /// The sky and haze.
    pub backdrop: Backdrop,
    /// What is drawn over each rendered frame.
    pub overlay: Overlay,
}

/// What a sensor view draws over a rendered frame.
#[derive(Debug, Clone)]
pub enum Overlay {
    /// Nothing.
    None,
    /// The night-vision view's light points ([`NightScale::draw_lights`]).
    Night(NightScale),
    /// Every pixel's σ⁰ for a radar at the eye ([`EyeRadar::draw`]).
    Radar(EyeRadar),
}

impl Overlay {
    /// Draw over `frame`, seen from `camera`, of the tile set `reader` reads, in air of
    /// `visibility` metres (haze, for the lights); the light points drawn for night vision.
    pub fn draw(
        &self,
        frame: &mut Frame,
        camera: &Viewpoint,
        reader: &TileReader,
        visibility: Option<f64>,
    ) -> Result<Option<usize>> {
        match self {
            Overlay::None => Ok(None),
            Overlay::Night(n) => Ok(Some(n.draw_lights(frame, camera, visibility))),
            Overlay::Radar(r) => r.draw(frame, camera, reader).map(|_| None),
        }
    }
}

/// How temperatures map to grey in the infrared view.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct IrScale {
    /// Temperature drawn black, kelvin.
    pub min_k: f64,
    /// Temperature drawn white, kelvin; above `min_k`.
    pub max_k: f64,
}

impl IrScale {
    /// The scale from `min_k` to `max_k`, checked (finite, `min_k < max_k`).
    pub fn new(min_k: f64, max_k: f64) -> Result<IrScale> {
        if !(min_k.is_finite() && max_k.is_finite() && min_k < max_k) {
            return Err(Error::msg(format!(
                "--ir-range {min_k},{max_k}: needs two finite temperatures in kelvin, the first below the second"
            ))
            .fix("e.g. --ir-range 280,320"));
        }
        Ok(IrScale { min_k, max_k })
    }

    /// The scale spanning the coldest and hottest cell of the coarsest level that has two
    /// different temperatures (block means: the level-0 extremes lie a little beyond them and
    /// are clamped); levels are read from the coarsest down, so a tile set whose top level is
    /// one cell still scales by the level under it.
    pub fn of_tiles(reader: &TileReader) -> Result<IrScale> {
        let info = reader.info();
        for (level, l) in info.levels.iter().enumerate().rev() {
            let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
            for ty in 0..l.pages_y {
                for tx in 0..l.pages_x {
                    let page = reader.page(level, tx, ty)?;
                    let values = page
                        .sensor(SensorLayer::Temperature)
                        .and_then(|c| c.values());
                    for &t in values.into_iter().flatten().filter(|t| !t.is_nan()) {
                        (lo, hi) = (lo.min(f64::from(t)), hi.max(f64::from(t)));
                    }
                }
            }
            if lo < hi {
                return IrScale::new(lo, hi);
            }
        }
        Err(Error::file(
            reader.path(),
            "has no two different temperatures to scale the infrared view by",
        )
        .fix("give the scale with --ir-range MIN,MAX (kelvin)"))
    }

    /// The white-hot grey of temperature `t` (kelvin); [`NO_ATTRIBUTE`] for NaN.
    pub fn grey(&self, t: f32) -> [u8; 4] {
        if t.is_nan() {
            return NO_ATTRIBUTE;
        }
        let x = (f64::from(t) - self.min_k) / (self.max_k - self.min_k);
        let g = super::sky::channel(255.0 * x.clamp(0.0, 1.0));
        [g, g, g, 255]
    }
}

/// How to draw `reader`'s tile set for `sensor`; `None` for the visual view (the pages as
/// stored). Errors when the tile set lacks what the sensor needs, naming the pyramid option.
pub fn view(
    sensor: Sensor,
    reader: &TileReader,
    opts: &SensorOptions,
) -> Result<Option<SensorView>> {
    let info = reader.info();
    let needs = |layer: SensorLayer, option: &str| -> Result<()> {
        match info.sensor_layers().contains(&layer) {
            true => Ok(()),
            false => Err(Error::file(
                reader.path(),
                format!(
                    "has no {} layer for --sensor {}",
                    layer.name(),
                    sensor.name()
                ),
            )
            .fix(format!("build the tile set with dbms pyramid {option}"))),
        }
    };
    match sensor {
        Sensor::Visual => Ok(None),
        Sensor::Ir => {
            needs(
                SensorLayer::Temperature,
                "--temperature TEMP.tif (TEMP.tif from dbms thermal)",
            )?;
            let scale = match opts.ir_range {
                Some(s) => s,
                None => IrScale::of_tiles(reader)?,
            };
            Ok(Some(SensorView {
                filter: values_filter(SensorLayer::Temperature, move |t| scale.grey(t)),
                backdrop: Backdrop::infrared(&scale),
                overlay: Overlay::None,
            }))
        }
        Sensor::Radar => {
            let black = Backdrop::Flat {
                sky: [0, 0, 0],
                haze: [0.0; 3],
            };
            if let Some(band) = opts.band {
                needs(SensorLayer::Normal, "--normals --materials")?;
                needs(SensorLayer::Material, "--materials --normals")?;
                return Ok(Some(SensorView {
                    filter: Arc::new(|_: &mut Page| {}),
                    backdrop: black,
                    overlay: Overlay::Radar(EyeRadar::new(reader, band)),
                }));
            }
            needs(
                SensorLayer::Backscatter,
                "--backscatter S0.tif (S0.tif from dbms radar), or give --band for a radar at the eye (pyramid --normals --materials)",
            )?;
            Ok(Some(SensorView {
                filter: values_filter(SensorLayer::Backscatter, |s| match s.is_nan() {
                    true => NO_ATTRIBUTE,
                    false => {
                        let g = crate::backscatter::grey_db(s);
                        [g, g, g, 255]
                    }
                }),
                backdrop: black,
                overlay: Overlay::None,
            }))
        }
        Sensor::Nvg => {
            needs(SensorLayer::Material, "--materials")?;
            let time = opts.time.as_deref().ok_or_else(|| {
                Error::msg("--sensor nvg needs --time: the moon's light depends on it")
                    .fix("give the instant, e.g. --time 2026-09-26T21:00:00Z")
            })?;
            let night = NightScale::at(reader, time, opts.extinction_mag_per_airmass)?;
            let mut reflectance = [f64::NAN; 256];
            for m in &info.materials {
                reflectance[m.id as usize] = m.nir_reflectance;
            }
            let scale = night.clone();
            Ok(Some(SensorView {
                filter: Arc::new(move |page: &mut Page| {
                    let Some(ids) = page.sensor(SensorLayer::Material).and_then(|c| c.ids()) else {
                        return;
                    };
                    let colours: Vec<[u8; 4]> = ids
                        .iter()
                        .map(|&id| scale.cell(reflectance[id as usize]))
                        .collect();
                    recolour(page, &colours);
                }),
                backdrop: night.backdrop(),
                overlay: Overlay::Night(night),
            }))
        }
    }
}

/// The radar view with the radar at the eye (`--sensor radar --band B`): each pixel is drawn in
/// the σ⁰ of the surface its centre ray hits, from the hit cell's material model for the band
/// at the incidence between the ray and the surface's normal, on the scale of `dbms radar`'s
/// preview (`backscatter::grey_db`). What the eye does not see, the radar does not light: its
/// shadows are the view's occlusion.
///
/// The hit is the range image's point on the pixel's centre ray, its cell the level-0 cell just
/// beyond it along the ray. A point on the cell's top takes the `normal` layer's normal (the
/// terrain's, level on what stands on it); a point more than 1 % of a cell below the top is on
/// the cell's side, which faces the ray horizontally (`−sign` of the ray along the axis of the
/// nearer cell edge) when the cell rises a cell width or more above the neighbour the ray came
/// from, as the renderer draws walls; a smaller rise is a stair step of sampled terrain and
/// takes the cell's normal. Partial (voxel) cells take the cell's normal. Specular materials
/// return nothing; a material without a model for the band, or no material, is drawn
/// [`NO_ATTRIBUTE`].
#[derive(Debug, Clone)]
pub struct EyeRadar {
    /// For each material id of the header: whether it is specular, and its model for the band.
    models: Vec<Option<(bool, Option<RadarModel>)>>,
}

impl EyeRadar {
    /// The radar at the eye for `band`, with `reader`'s header's material models.
    pub fn new(reader: &TileReader, band: Band) -> EyeRadar {
        let mut models = vec![None; 256];
        for m in &reader.info().materials {
            let model = crate::backscatter::model_for(&m.radar, band).cloned();
            models[m.id as usize] = Some((m.radar_specular, model));
        }
        EyeRadar { models }
    }

    /// Draw every pixel of `frame` (rendered from `camera` over `reader`) in its σ⁰.
    pub fn draw(&self, frame: &mut Frame, camera: &Viewpoint, reader: &TileReader) -> Result<()> {
        let basis = camera.basis();
        let w = frame.width;
        let rows = frame.rgb.par_chunks_mut(w).zip(frame.range.par_chunks(w));
        rows.enumerate().try_for_each(|(j, (rgb, range))| {
            for (i, (px, &r)) in rgb.iter_mut().zip(range).enumerate() {
                if !r.is_finite() {
                    *px = [0; 3];
                    continue;
                }
                let d = basis.through(i as f64 + 0.5, j as f64 + 0.5);
                let len = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
                let d = d.map(|c| c / len);
                let hit = [0, 1, 2].map(|k| camera.eye[k] + d[k] * f64::from(r));
                *px = match self.sigma0(reader, hit, d)? {
                    Some(s) => [crate::backscatter::grey_db(s); 3],
                    None => [NO_ATTRIBUTE[0], NO_ATTRIBUTE[1], NO_ATTRIBUTE[2]],
                };
            }
            Ok(())
        })
    }

    /// σ⁰ (linear) of the surface a ray along unit `d` meets at `hit`; `None` where there is
    /// no material, no normal, or no model for the band.
    pub fn sigma0(&self, reader: &TileReader, hit: [f64; 3], d: [f64; 3]) -> Result<Option<f32>> {
        let info = reader.info();
        let (g, p) = (&info.grid, info.page_size);
        let t = &g.transform;
        let width = t.cell_x.abs().min(t.cell_y.abs());
        let ahead = 1e-3 * width;
        let Some((c, r)) = g.cell_at(hit[0] + d[0] * ahead, hit[1] + d[1] * ahead) else {
            return Ok(None);
        };
        let at = |c: usize, r: usize| -> Result<(Arc<Page>, usize)> {
            Ok((reader.page(0, c / p, r / p)?, (r % p) * p + c % p))
        };
        let (page, i) = at(c, r)?;
        let (Some(ids), Some(normals)) = (
            page.sensor(SensorLayer::Material).and_then(|l| l.ids()),
            page.sensor(SensorLayer::Normal).and_then(|l| l.normals()),
        ) else {
            return Ok(None);
        };
        let (Some(mut n), top) = (unpack_normal(normals[i]), f64::from(page.max_z[i])) else {
            return Ok(None);
        };
        let below_top = hit[2] < top - 0.01 * width;
        if below_top && page.state[i] != crate::tiles::STATE_PARTIAL {
            // Which edge the hit is on: the nearer, in cells.
            let (px, py) = t.world_to_pixel(hit[0], hit[1]);
            let (fx, fy) = (px - c as f64, py - r as f64);
            let along_x = fx.min(1.0 - fx) <= fy.min(1.0 - fy);
            // The neighbour the ray came from, across that edge.
            let (dc, dr) = match along_x {
                true => (if d[0] / t.cell_x > 0.0 { -1 } else { 1 }, 0),
                false => (0, if d[1] / t.cell_y > 0.0 { -1 } else { 1 }),
            };
            let (c2, r2) = (c as i64 + dc, r as i64 + dr);
            let inside = (0..g.width as i64).contains(&c2) && (0..g.height as i64).contains(&r2);
            let below = match inside {
                true => {
                    let (q, k) = at(c2 as usize, r2 as usize)?;
                    f64::from(q.max_z[k])
                }
                false => f64::NAN,
            };
            if !(top - below < width) {
                n = match along_x {
                    true => [-d[0].signum(), 0.0, 0.0],
                    false => [0.0, -d[1].signum(), 0.0],
                };
            }
        }
        let Some((specular, model)) = &self.models[ids[i] as usize] else {
            return Ok(None);
        };
        let cos_inc = -(n[0] * d[0] + n[1] * d[1] + n[2] * d[2]);
        if *specular || cos_inc <= 0.0 {
            return Ok(Some(0.0));
        }
        let Some(model) = model else {
            return Ok(None);
        };
        Ok(Some(model.sigma0(cos_inc)))
    }
}

/// The page filter that draws each cell of value layer `layer` in `colour(value)`; a page
/// without the layer is left as it is.
fn values_filter(
    layer: SensorLayer,
    colour: impl Fn(f32) -> [u8; 4] + Send + Sync + 'static,
) -> PageFilter {
    Arc::new(move |page: &mut Page| {
        let Some(values) = page.sensor(layer).and_then(|c| c.values()) else {
            return;
        };
        let colours: Vec<[u8; 4]> = values.iter().map(|&v| colour(v)).collect();
        recolour(page, &colours);
    })
}

/// Draw `page`'s cells in `colours` (one per cell) and its voxel runs in their cell's; cells
/// without a surface (alpha 0) stay nodata.
fn recolour(page: &mut Page, colours: &[[u8; 4]]) {
    for (c, g) in page.colour.iter_mut().zip(colours) {
        if c[3] != 0 {
            *c = *g;
        }
    }
    // A blob that does not decode is left for the sampler to report.
    let cells = page.max_z.len();
    let decoded = page
        .bricks
        .as_deref()
        .and_then(|b| PageColumns::decode(b, cells).ok());
    if let Some(columns) = decoded {
        let mut out = PageColumns::default();
        for (cell, runs) in columns.iter() {
            let runs: Vec<Run> = runs
                .iter()
                .map(|r| Run {
                    colour: colours[cell],
                    ..*r
                })
                .collect();
            out.push(cell, &runs)
                .expect("the same cells and runs, recoloured");
        }
        page.bricks = Some(out.encode());
    }
}

/// The reflectance an intensifier's automatic brightness control draws white, at or above
/// [`KNEE_LUX`]: a display choice, not a measurement.
pub const WHITE_REFLECTANCE: f64 = 0.6;
/// Scene illuminance, lux, below which the automatic brightness control has no gain left and
/// the picture darkens in proportion (a display choice: image intensifiers hold their output
/// down to about a clear starlit night).
pub const KNEE_LUX: f64 = 1e-3;
/// The green of the intensifier's phosphor, as fractions of a grey level (a display choice).
pub const PHOSPHOR: [f64; 3] = [0.45, 1.0, 0.45];
/// Largest halo radius around a light, as a fraction of the image width (a display choice).
pub const HALO_MAX_FRACTION: f64 = 0.02;

/// The night-vision view's light and display: the illuminance on the ground at the time, and
/// how a reflectance under it is drawn.
#[derive(Debug, Clone)]
pub struct NightScale {
    /// Moonlight on a horizontal surface, lux ([`crate::moon`]); 0 with the moon down.
    pub moon_lux: f64,
    /// The moonless night sky's illuminance, lux ([`crate::moon::night_sky_lux`]).
    pub sky_lux: f64,
    /// The tile set's light points.
    pub lights: Vec<LightPoint>,
}

impl NightScale {
    /// The light at the centre of `reader`'s grid at `time`.
    pub fn at(reader: &TileReader, time: &str, extinction: f64) -> Result<NightScale> {
        let g = &reader.info().grid;
        let (cx, cy) = g.centre();
        let (latitude_deg, longitude_deg) = g.crs.to_lat_lon(cx, cy).ok_or_else(|| {
            Error::file(
                reader.path(),
                format!(
                    "cannot place the grid centre on the globe ({})",
                    g.crs.name()
                ),
            )
            .fix("build the tile set from a database in a CRS dbms knows (UTM)")
        })?;
        let observer = crate::sun::Observer {
            latitude_deg,
            longitude_deg,
            height_m: 0.0,
        };
        let utc = crate::sun::parse_time(time)?;
        let moon = crate::moon::moon_position(&observer, utc, &Default::default())?;
        Ok(NightScale {
            moon_lux: moon.light(extinction)?.horizontal_lux,
            sky_lux: crate::moon::night_sky_lux(),
            lights: reader.info().lights.clone(),
        })
    }

    /// Illuminance on a horizontal surface, lux.
    pub fn illuminance_lux(&self) -> f64 {
        self.moon_lux + self.sky_lux
    }

    /// The brightness (0 black, 1 white) of a Lambertian surface of reflectance `r` under
    /// this light: `r·E / (WHITE_REFLECTANCE · max(E, KNEE_LUX))`, clamped.
    pub fn brightness(&self, r: f64) -> f64 {
        let e = self.illuminance_lux();
        (r * e / (WHITE_REFLECTANCE * e.max(KNEE_LUX))).clamp(0.0, 1.0)
    }

    /// A cell of NIR reflectance `r` in the phosphor's green; [`NO_ATTRIBUTE`] for NaN.
    fn cell(&self, r: f64) -> [u8; 4] {
        if r.is_nan() {
            return NO_ATTRIBUTE;
        }
        let [red, green, blue] = phosphor(self.brightness(r));
        [red, green, blue, 255]
    }

    /// The night sky (its own luminance, the natural sky's zenith, compared with a white
    /// surface's: a moonless sky is brighter than the ground under it) and haze toward it.
    fn backdrop(&self) -> Backdrop {
        let sky = phosphor(self.brightness(self.sky_lux / self.illuminance_lux()));
        Backdrop::Flat {
            sky,
            haze: sky.map(f64::from),
        }
    }

    /// Draw the light points `camera` sees in `frame`: each one whose pixel's range reaches it
    /// (within 2 m or 5 % of its distance) adds a halo around its image point. The light's
    /// irradiance at the eye, `I / d²` (thinned by `exp(−d / visibility)` with haze), is
    /// compared with a white surface's through one pixel, `WHITE_REFLECTANCE · max(E,
    /// KNEE_LUX) / π · Ω_pixel`: that ratio `q` gives the halo's brightness at `r` pixels,
    /// `min(1, q / (1 + r)²)`, out to the radius `R` where it falls to one grey level or to
    /// [`HALO_MAX_FRACTION`] of the width, whichever is less, faded by `(1 − (r / R)²)²` so
    /// the halo has no hard rim. Returns how many lights were drawn.
    pub fn draw_lights(
        &self,
        frame: &mut Frame,
        camera: &Viewpoint,
        visibility: Option<f64>,
    ) -> usize {
        let basis = camera.basis();
        let (w, h) = (frame.width as f64, frame.height as f64);
        let pixel_sr = (2.0 * (camera.hfov.to_radians() / 2.0).tan() / w).powi(2);
        let white = WHITE_REFLECTANCE * self.illuminance_lux().max(KNEE_LUX) / std::f64::consts::PI
            * pixel_sr;
        let halo_max = (HALO_MAX_FRACTION * w).max(1.0);
        let mut drawn = 0;
        for l in &self.lights {
            let d = [
                l.x - camera.eye[0],
                l.y - camera.eye[1],
                l.z - camera.eye[2],
            ];
            let Some((x, y)) = basis.project(d) else {
                continue;
            };
            if !(0.0..w).contains(&x) || !(0.0..h).contains(&y) {
                continue;
            }
            let dist = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
            let at = y as usize * frame.width + x as usize;
            if f64::from(frame.range[at]) < dist - (0.05 * dist).max(2.0) {
                continue; // behind something
            }
            let haze = visibility.map_or(1.0, |v| (-dist / v).exp());
            let toward_eye = [-d[0], -d[1], -d[2]];
            let q = l.intensity_toward(toward_eye) / (dist * dist) * haze / white;
            let radius = ((255.0 * q).sqrt() - 1.0).clamp(0.0, halo_max);
            drawn += 1;
            let (i0, i1) = (
                (x - radius).floor().max(0.0),
                (x + radius).ceil().min(w - 1.0),
            );
            let (j0, j1) = (
                (y - radius).floor().max(0.0),
                (y + radius).ceil().min(h - 1.0),
            );
            for j in j0 as usize..=j1 as usize {
                for i in i0 as usize..=i1 as usize {
                    let r = ((i as f64 + 0.5 - x).powi(2) + (j as f64 + 0.5 - y).powi(2)).sqrt();
                    if r > radius + 0.5 {
                        continue;
                    }
                    let fade = (1.0 - (r / (radius + 0.5)).powi(2)).powi(2);
                    let add = (q / (1.0 + r).powi(2)).min(1.0) * fade;
                    let px = &mut frame.rgb[j * frame.width + i];
                    for (c, t) in px.iter_mut().zip([0.8, 1.0, 0.8]) {
                        *c = super::sky::channel(f64::from(*c) + 255.0 * add * t);
                    }
                }
            }
        }
        drawn
    }
}

/// Brightness `b` (0–1) in the phosphor's green.
fn phosphor(b: f64) -> [u8; 3] {
    PHOSPHOR.map(|t| super::sky::channel(255.0 * b * t))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::{Attitude, RenderStats};
    use crate::tiles::ReaderStats;

    /// A 64 × 48 frame looking north from the origin, everything at `range` metres.
    fn frame(range: f32) -> (Frame, Viewpoint) {
        let camera = Viewpoint {
            eye: [0.0; 3],
            attitude: Attitude {
                roll: 0.0,
                pitch: 0.0,
                yaw: 0.0,
            },
            hfov: 60.0,
            width: 64,
            height: 48,
        };
        let stats = RenderStats {
            rays: 0,
            hits: 0,
            cells_stepped: 0,
            pages_touched: 0,
            reader: ReaderStats {
                pages_read: 0,
                bytes_read: 0,
                cache_hits: 0,
            },
            seconds: 0.0,
            rays_per_second: 0.0,
        };
        let n = 64 * 48;
        let frame = Frame {
            width: 64,
            height: 48,
            rgb: vec![[0; 3]; n],
            range: vec![range; n],
            stats,
        };
        (frame, camera)
    }

    fn night(lights: Vec<LightPoint>) -> NightScale {
        NightScale {
            moon_lux: 0.1,
            sky_lux: crate::moon::night_sky_lux(),
            lights,
        }
    }

    fn lamp(x: f64, y: f64) -> LightPoint {
        LightPoint {
            x,
            y,
            z: 0.0,
            intensity_cd: 1500.0,
            colour: [255, 255, 255],
            beam: None,
        }
    }

    #[test]
    fn a_light_shows_where_nothing_nearer_hides_it_with_a_halo_brightest_at_its_centre() {
        // 100 m ahead, on the view's axis: the centre of the frame.
        let n = night(vec![lamp(0.0, 100.0)]);
        let (mut open, camera) = frame(f32::INFINITY);
        assert_eq!(n.draw_lights(&mut open, &camera, None), 1);
        let at = |f: &Frame, i: usize, j: usize| f.rgb[j * 64 + i][1];
        // The halo's radius is 2 % of the 64-pixel width: the four pixels at the lamp's image
        // point (a pixel corner) are lit, fading outward; nothing farther.
        assert!(at(&open, 32, 24) > 100 && at(&open, 31, 23) == at(&open, 32, 24));
        assert!(at(&open, 33, 24) < at(&open, 32, 24));
        assert_eq!(
            at(&open, 35, 24),
            0,
            "the halo stays within 2 % of the width"
        );
        // A wall 50 m ahead hides it; the ground just behind the lamp does not.
        let (mut walled, _) = frame(50.0);
        assert_eq!(n.draw_lights(&mut walled, &camera, None), 0);
        assert!(walled.rgb.iter().all(|p| *p == [0; 3]));
        let (mut ground, _) = frame(99.0);
        assert_eq!(n.draw_lights(&mut ground, &camera, None), 1);
        // A directional lamp aimed at the eye (south, level) shows as the round one does; aimed
        // 12° to the side with a 12° spread it sends 2^−4 of its light to the eye, so a dim
        // one's halo holds less (a bright one's saturates: the bloom's choice); aimed north it
        // sends nothing.
        let light = |f: &Frame| f.rgb.iter().map(|p| u64::from(p[1])).sum::<u64>();
        let aimed = |intensity_cd: f64, azimuth_deg: f64| {
            let beam = crate::tiles::Beam {
                azimuth_deg,
                elevation_deg: 0.0,
                spread_deg: [12.0, 12.0],
            };
            let n = night(vec![LightPoint {
                intensity_cd,
                beam: Some(beam),
                ..lamp(0.0, 100.0)
            }]);
            let (mut f, _) = frame(f32::INFINITY);
            n.draw_lights(&mut f, &camera, None);
            light(&f)
        };
        assert_eq!(aimed(1500.0, 180.0), light(&open));
        assert_eq!(aimed(1500.0, 0.0), 0);
        let dim = aimed(0.02, 180.0);
        assert!(
            aimed(0.02, 168.0) < dim / 4 && aimed(0.02, 168.0) > 0,
            "{dim}"
        );
        // Behind the eye, or outside the field: not drawn.
        let away = night(vec![lamp(0.0, -100.0), lamp(100.0, 10.0)]);
        let (mut f, _) = frame(f32::INFINITY);
        assert_eq!(away.draw_lights(&mut f, &camera, None), 0);
    }

    #[test]
    fn brightness_follows_reflectance_and_darkens_only_below_the_knee() {
        let full = night(vec![]);
        assert!((full.brightness(0.3) - 0.5).abs() < 1e-12);
        assert_eq!(full.brightness(0.9), 1.0);
        let dark = NightScale {
            moon_lux: 0.0,
            sky_lux: KNEE_LUX / 4.0,
            lights: vec![],
        };
        assert!((dark.brightness(0.3) - 0.125).abs() < 1e-12);
        // A moonless sky outshines the ground under it; a moonlit one does not.
        let sky = |n: &NightScale| n.brightness(n.sky_lux / n.illuminance_lux());
        assert!(sky(&dark) > dark.brightness(0.6) - 1e-12);
        assert!(sky(&full) < full.brightness(0.05));
    }

    #[test]
    fn grey_is_linear_clamped_and_marks_missing_temperatures() {
        let s = IrScale::new(280.0, 320.0).unwrap();
        assert_eq!(s.grey(280.0), [0, 0, 0, 255]);
        assert_eq!(s.grey(320.0), [255, 255, 255, 255]);
        assert_eq!(s.grey(300.0), [128, 128, 128, 255]); // 127.5 rounds half away from zero
        assert_eq!(s.grey(200.0), [0, 0, 0, 255]);
        assert_eq!(s.grey(400.0), [255, 255, 255, 255]);
        assert_eq!(s.grey(f32::NAN), NO_ATTRIBUTE);
        for (a, b) in [(300.0, 300.0), (310.0, 290.0), (f64::NAN, 300.0)] {
            let e = IrScale::new(a, b).unwrap_err().to_string();
            assert!(e.contains("--ir-range"), "{e}");
        }
    }
}
