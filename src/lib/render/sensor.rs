//! Sensor views (issue 18): the same geometry drawn from the layer a sensor sees.
//!
//! Invariant: a sensor view changes only what a cell is drawn in, never what a ray hits. Every
//! page is recoloured as the tile reader reads it ([`crate::tiles::TileReader::with_filter`]),
//! so the stepping, coherence and level selection of the visual view run unchanged and the
//! frames of two sensors have the same range image. The infrared view draws each cell's
//! temperature white-hot: [`IrScale::grey`] maps `min_k` to black and `max_k` to white,
//! linearly, clamped; a cell with a surface but no temperature (unclassified) is dark red, as in
//! `dbms thermal`'s preview; the voxel runs of a partial cell take its grey.

use super::sky::Backdrop;
use crate::error::{Error, Result};
use crate::tiles::{Page, PageFilter, SensorLayer, TileReader};
use crate::voxel::columns::{PageColumns, Run};
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
    }
}

/// Colour of a cell that has a surface but no temperature (an unclassified cell).
pub const NO_TEMPERATURE: [u8; 4] = [96, 0, 0, 255];

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

    /// The scale spanning the coldest and hottest cell of the tile set's coarsest level (block
    /// means: the level-0 extremes lie a little beyond them and are clamped).
    pub fn of_tiles(reader: &TileReader) -> Result<IrScale> {
        let info = reader.info();
        let top = info.levels.len() - 1;
        let l = &info.levels[top];
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for ty in 0..l.pages_y {
            for tx in 0..l.pages_x {
                let page = reader.page(top, tx, ty)?;
                let values = page
                    .sensor(SensorLayer::Temperature)
                    .and_then(|c| c.values());
                for &t in values.into_iter().flatten().filter(|t| !t.is_nan()) {
                    (lo, hi) = (lo.min(f64::from(t)), hi.max(f64::from(t)));
                }
            }
        }
        if !(lo < hi) {
            return Err(Error::file(
                reader.path(),
                "has no two different temperatures to scale the infrared view by",
            )
            .fix("give the scale with --ir-range MIN,MAX (kelvin)"));
        }
        IrScale::new(lo, hi)
    }

    /// The white-hot grey of temperature `t` (kelvin); [`NO_TEMPERATURE`] for NaN.
    pub fn grey(&self, t: f32) -> [u8; 4] {
        if t.is_nan() {
            return NO_TEMPERATURE;
        }
        let x = (f64::from(t) - self.min_k) / (self.max_k - self.min_k);
        let g = super::sky::channel(255.0 * x.clamp(0.0, 1.0));
        [g, g, g, 255]
    }
}

/// The page filter and backdrop that draw `reader`'s tile set for `sensor`; `None` for the
/// visual view (the pages as stored). `ir_range` fixes the infrared scale (else
/// [`IrScale::of_tiles`]). Errors when the tile set lacks the layer the sensor needs.
pub fn view(
    sensor: Sensor,
    reader: &TileReader,
    ir_range: Option<IrScale>,
) -> Result<Option<(PageFilter, Backdrop)>> {
    match sensor {
        Sensor::Visual => Ok(None),
        Sensor::Ir => {
            if !reader
                .info()
                .sensor_layers()
                .contains(&SensorLayer::Temperature)
            {
                return Err(Error::file(reader.path(), "has no temperature layer for --sensor ir")
                    .fix("build the tile set with dbms pyramid --temperature TEMP.tif (TEMP.tif from dbms thermal)"));
            }
            let scale = match ir_range {
                Some(s) => s,
                None => IrScale::of_tiles(reader)?,
            };
            let filter: PageFilter = Arc::new(move |page: &mut Page| recolour_ir(page, &scale));
            Ok(Some((filter, Backdrop::infrared(&scale))))
        }
    }
}

/// Draw `page`'s cells (and its voxel runs) in their temperature's grey; cells without a
/// surface (alpha 0) stay nodata.
fn recolour_ir(page: &mut Page, scale: &IrScale) {
    let Some(t) = page
        .sensor(SensorLayer::Temperature)
        .and_then(|c| c.values())
    else {
        return;
    };
    let grey: Vec<[u8; 4]> = t.iter().map(|&t| scale.grey(t)).collect();
    for (c, g) in page.colour.iter_mut().zip(&grey) {
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
                    colour: grey[cell],
                    ..*r
                })
                .collect();
            out.push(cell, &runs)
                .expect("the same cells and runs, recoloured");
        }
        page.bricks = Some(out.encode());
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn grey_is_linear_clamped_and_marks_missing_temperatures() {
        let s = IrScale::new(280.0, 320.0).unwrap();
        assert_eq!(s.grey(280.0), [0, 0, 0, 255]);
        assert_eq!(s.grey(320.0), [255, 255, 255, 255]);
        assert_eq!(s.grey(300.0), [128, 128, 128, 255]); // 127.5 rounds half away from zero
        assert_eq!(s.grey(200.0), [0, 0, 0, 255]);
        assert_eq!(s.grey(400.0), [255, 255, 255, 255]);
        assert_eq!(s.grey(f32::NAN), NO_TEMPERATURE);
        for (a, b) in [(300.0, 300.0), (310.0, 290.0), (f64::NAN, 300.0)] {
            let e = IrScale::new(a, b).unwrap_err().to_string();
            assert!(e.contains("--ir-range"), "{e}");
        }
    }
}
