//! Sensor layers through the hierarchy (issue 18): level 0 from the database's materials layer
//! and the maps `dbms thermal` writes, and each coarse level's reduction of them.
//!
//! Invariant (as for the colour: no average of averages): a coarse cell's material is the id
//! most valid level-0 cells of its block hold (ties to the lower id), from per-id counts carried
//! up the cascade; a coarse temperature or radiance is the f64 sum of the f32 values of its
//! block's valid level-0 cells divided by their count, rounded once to f32; a coarse normal is
//! the f64 sum of its block's valid level-0 unit normals, renormalised once as it is packed. A
//! level-0 cell is valid in a sensor layer when it is valid in `max_z` and its own value is not
//! nodata; a coarse cell with no valid level-0 cell is nodata.

use crate::db::{Database, LayerRows};
use crate::error::{Error, Result};
use crate::io::SourceRaster;
use crate::material::table::MaterialTable;
use crate::raster::RowSource;
use crate::standing::Standing;
use crate::tiles::{
    pack_normal, MaterialAttributes, SensorCells, SensorLayer, MATERIAL_NODATA, NORMAL_NODATA,
};
use rayon::prelude::*;
use std::path::Path;
use std::sync::Arc;

/// The material ids a build counts: every id its materials layer holds, and 0 (unclassified)
/// always, so there is at least one; ascending.
#[derive(Debug, Clone, PartialEq)]
pub struct Counted {
    /// The ids, ascending; never [`MATERIAL_NODATA`].
    ids: Vec<u8>,
    /// `slot[id]`: the position of `id` in `ids`, or `u8::MAX` when it is not counted.
    slot: [u8; 256],
}

impl Counted {
    /// The ids `ids` and 0 (any order, duplicates and [`MATERIAL_NODATA`] ignored).
    pub fn new(ids: impl IntoIterator<Item = u8>) -> Counted {
        let mut seen = [false; 256];
        seen[0] = true;
        ids.into_iter().for_each(|id| seen[id as usize] = true);
        seen[MATERIAL_NODATA as usize] = false;
        let ids: Vec<u8> = (0..=255u8).filter(|&i| seen[i as usize]).collect();
        let mut slot = [u8::MAX; 256];
        for (k, &id) in ids.iter().enumerate() {
            slot[id as usize] = k as u8;
        }
        Counted { ids, slot }
    }

    /// Every id `rows` holds, read band by band.
    pub fn scan(rows: &dyn RowSource<u8>) -> Result<Counted> {
        let g = rows.grid();
        let per_band = crate::raster::band_rows(g.width);
        let mut seen = [false; 256];
        for row0 in (0..g.height).step_by(per_band) {
            let band = rows.read_rows(row0, per_band.min(g.height - row0))?;
            band.iter().for_each(|&id| seen[id as usize] = true);
        }
        Ok(Counted::new((0..=255u8).filter(|&i| seen[i as usize])))
    }

    /// The majority of `counts` (one per counted id): the id with the most, the lower id on a
    /// tie; [`MATERIAL_NODATA`] when every count is 0.
    fn majority(&self, counts: &[u64]) -> u8 {
        let mut best = (0, MATERIAL_NODATA);
        for (&n, &id) in counts.iter().zip(&self.ids) {
            if n > best.0 {
                best = (n, id);
            }
        }
        best.1
    }
}

/// What the sensor views need of each material `counted` holds (0 left out), from `table`:
/// the NIR reflectance, or the solar albedo where the table has none (and `nir_from` says so),
/// and the radar's specular flag and σ⁰ models.
/// An id the table lacks gets neither: it is left out, and the view draws it as unclassified.
pub fn attributes(table: &MaterialTable, counted: &Counted) -> Vec<MaterialAttributes> {
    let known = counted.ids.iter().filter_map(|&id| table.by_id(id));
    known
        .map(|m| {
            let (nir_reflectance, nir_from) = match m.nir_reflectance {
                Some(r) => (r, "nir_reflectance"),
                None => (m.solar_albedo, "solar_albedo"),
            };
            MaterialAttributes {
                id: m.id,
                name: m.name.clone(),
                nir_reflectance,
                nir_from: nir_from.into(),
                radar_specular: m.radar.specular,
                radar: m.radar.models.clone(),
            }
        })
        .collect()
}

/// One sensor layer of a band of rows of one level.
#[derive(Debug, Clone, PartialEq)]
pub struct SensorRows {
    /// Which layer.
    pub layer: SensorLayer,
    /// Its cells.
    pub data: SensorData,
}

/// The cells of a [`SensorRows`]: level 0 holds values, coarse levels what reduces exactly.
#[derive(Debug, Clone, PartialEq)]
pub enum SensorData {
    /// Level-0 material ids ([`MATERIAL_NODATA`] = nodata), and the ids a build counts.
    Ids(Vec<u8>, Arc<Counted>),
    /// Coarse material counts: for each cell, how many valid level-0 cells of its block hold
    /// each counted id (`cells × ids` row-major).
    Counts(Vec<u64>, Arc<Counted>),
    /// Level-0 values (NaN = nodata).
    Values(Vec<f32>),
    /// Coarse sums of the block's valid level-0 values, and their count.
    Sums(Vec<f64>, Vec<u64>),
    /// Normals: at level 0 each cell's unit normal, at coarse levels the sum of its block's
    /// valid level-0 normals; `[0; 3]` = nodata (a valid normal points up, so no sum of them
    /// is 0).
    Vectors(Vec<[f64; 3]>),
}

impl SensorRows {
    /// Number of cells held.
    pub fn len(&self) -> usize {
        match &self.data {
            SensorData::Ids(v, _) => v.len(),
            SensorData::Counts(v, c) => v.len() / c.ids.len(),
            SensorData::Values(v) => v.len(),
            SensorData::Sums(_, n) => n.len(),
            SensorData::Vectors(v) => v.len(),
        }
    }

    /// Whether no cell is held.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Make level-0 cell `i` nodata (its `max_z` is).
    pub fn clear(&mut self, i: usize) {
        match &mut self.data {
            SensorData::Ids(v, _) => v[i] = MATERIAL_NODATA,
            SensorData::Values(v) => v[i] = f32::NAN,
            SensorData::Vectors(v) => v[i] = [0.0; 3],
            SensorData::Counts(..) | SensorData::Sums(..) => {
                unreachable!("only level-0 cells are cleared")
            }
        }
    }

    /// Append the cells of `other` (same layer, same level) after these.
    pub fn append(&mut self, other: SensorRows) {
        match (&mut self.data, other.data) {
            (SensorData::Counts(v, _), SensorData::Counts(o, _)) => v.extend(o),
            (SensorData::Sums(s, n), SensorData::Sums(os, on)) => {
                s.extend(os);
                n.extend(on);
            }
            (SensorData::Ids(v, _), SensorData::Ids(o, _)) => v.extend(o),
            (SensorData::Values(v), SensorData::Values(o)) => v.extend(o),
            (SensorData::Vectors(v), SensorData::Vectors(o)) => v.extend(o),
            _ => unreachable!("rows of one layer and level"),
        }
    }

    /// Cells `i .. i + n` as a page stores them, into `out[o .. o + n]`.
    pub fn copy_run(&self, i: usize, n: usize, out: &mut SensorCells, o: usize) {
        match (&self.data, out) {
            (SensorData::Ids(v, _), SensorCells::Ids(out)) => {
                out[o..o + n].copy_from_slice(&v[i..i + n])
            }
            (SensorData::Counts(v, c), SensorCells::Ids(out)) => {
                let k = c.ids.len();
                for (j, cell) in out[o..o + n].iter_mut().enumerate() {
                    *cell = c.majority(&v[(i + j) * k..(i + j + 1) * k]);
                }
            }
            (SensorData::Values(v), SensorCells::Values(out)) => {
                out[o..o + n].copy_from_slice(&v[i..i + n])
            }
            (SensorData::Sums(s, c), SensorCells::Values(out)) => {
                for (j, cell) in out[o..o + n].iter_mut().enumerate() {
                    *cell = mean(s[i + j], c[i + j]);
                }
            }
            (SensorData::Vectors(v), SensorCells::Normals(out)) => {
                for (cell, sum) in out[o..o + n].iter_mut().zip(&v[i..i + n]) {
                    *cell = match *sum == [0.0; 3] {
                        true => NORMAL_NODATA,
                        false => pack_normal(*sum),
                    };
                }
            }
            _ => unreachable!("a page's cells have the layer's type"),
        }
    }

    /// These rows (`width` cells a row) reduced by `factor` in both directions: coarse cell
    /// `(c, r)` gathers fine rows `r·f .. r·f + f` and columns `c·f .. c·f + f` (fewer at the
    /// right and bottom edges). Parallel over coarse rows.
    pub fn reduce(&self, width: usize, factor: usize) -> SensorRows {
        let rows = self.len() / width.max(1);
        let (cw, ch) = (width.div_ceil(factor), rows.div_ceil(factor));
        let fine_rows = |r: usize| (r * factor)..((r + 1) * factor).min(rows);
        let data = match &self.data {
            SensorData::Ids(_, c) | SensorData::Counts(_, c) => {
                let k = c.ids.len();
                let mut counts = vec![0u64; cw * ch * k];
                if cw > 0 {
                    counts
                        .par_chunks_mut(cw * k)
                        .enumerate()
                        .for_each(|(r, out)| {
                            for fr in fine_rows(r) {
                                for fc in 0..width {
                                    let at = (fc / factor) * k;
                                    self.count_into(fr * width + fc, &mut out[at..at + k]);
                                }
                            }
                        });
                }
                SensorData::Counts(counts, c.clone())
            }
            SensorData::Values(_) | SensorData::Sums(..) => {
                let (mut sum, mut count) = (vec![0.0; cw * ch], vec![0u64; cw * ch]);
                if cw > 0 {
                    sum.par_chunks_mut(cw)
                        .zip(count.par_chunks_mut(cw))
                        .enumerate()
                        .for_each(|(r, (sum, count))| {
                            for fr in fine_rows(r) {
                                for fc in 0..width {
                                    let (s, n) = self.sum_of(fr * width + fc);
                                    sum[fc / factor] += s;
                                    count[fc / factor] += n;
                                }
                            }
                        });
                }
                SensorData::Sums(sum, count)
            }
            SensorData::Vectors(v) => {
                let mut sum = vec![[0.0; 3]; cw * ch];
                if cw > 0 {
                    sum.par_chunks_mut(cw).enumerate().for_each(|(r, sum)| {
                        for fr in fine_rows(r) {
                            for fc in 0..width {
                                let (s, n) = (&mut sum[fc / factor], v[fr * width + fc]);
                                (0..3).for_each(|k| s[k] += n[k]);
                            }
                        }
                    });
                }
                SensorData::Vectors(sum)
            }
        };
        SensorRows {
            layer: self.layer,
            data,
        }
    }

    /// Add cell `i`'s material counts to `out` (one per counted id).
    #[inline]
    fn count_into(&self, i: usize, out: &mut [u64]) {
        match &self.data {
            SensorData::Ids(v, c) => {
                let slot = c.slot[v[i] as usize];
                if slot != u8::MAX {
                    out[slot as usize] += 1;
                }
            }
            SensorData::Counts(v, c) => {
                let k = c.ids.len();
                out.iter_mut()
                    .zip(&v[i * k..(i + 1) * k])
                    .for_each(|(o, n)| *o += n);
            }
            _ => unreachable!("material rows"),
        }
    }

    /// Cell `i`'s sum of valid level-0 values and their count.
    #[inline]
    fn sum_of(&self, i: usize) -> (f64, u64) {
        match &self.data {
            SensorData::Values(v) if v[i].is_nan() => (0.0, 0),
            SensorData::Values(v) => (f64::from(v[i]), 1),
            SensorData::Sums(s, n) => (s[i], n[i]),
            _ => unreachable!("value rows"),
        }
    }
}

/// `sum / count` rounded to f32; NaN when `count` is 0.
fn mean(sum: f64, count: u64) -> f32 {
    match count {
        0 => f32::NAN,
        n => (sum / n as f64) as f32,
    }
}

/// What a value map carried as a sensor layer holds: one band of floating-point values in a
/// plausible range (inclusive; NaN and the declared nodata aside).
///
/// * Temperature, kelvin: 150 to 400 K. Earth's land surface lies between about 180 K (the
///   coldest skin temperature measured from orbit, on the East Antarctic plateau) and about
///   345 K (the hottest, in the Lut desert); the margin holds a sun-heated metal roof. A map in
///   °C (−90 to 70) or a σ⁰ map (0 to a few) falls below it.
/// * Radiance, 8–12 µm, W·m⁻²·sr⁻¹: 0 to a black body's at 400 K (emissivity ≤ 1), 134 rounded up.
/// * Backscatter σ⁰, linear power ratio (docs/sensors.md: `dbms radar` writes it linear): 0 (radar
///   shadow, specular surfaces) to 100 (+20 dB). The published models of distributed surfaces
///   (Ulaby & Dobson's handbook; the default table's γ of −21 to −15 dB) stay well below
///   +20 dB, and a temperature map in kelvin (≥ 150) cannot pass as σ⁰; a map in dB is
///   negative almost everywhere.
struct Holds {
    /// The map, in words: "a temperature map".
    what: &'static str,
    /// Its band, in words: "kelvin".
    band: &'static str,
    /// The plausible range of its values.
    range: (f64, f64),
    /// The range in words, with its unit: "150 to 400 K".
    range_words: String,
    /// The command that writes such a map.
    maker: &'static str,
}

/// What the value map carried as `layer` holds, or `None` for a layer no map carries
/// (materials and normals come from the database).
fn holds(layer: SensorLayer) -> Option<Holds> {
    let holds = |what, band, range: (f64, f64), unit, maker| Holds {
        what,
        band,
        range,
        range_words: format!("{} to {}{unit}", range.0, range.1),
        maker,
    };
    match layer {
        SensorLayer::Temperature => Some(holds(
            "a temperature map",
            "kelvin",
            (150.0, 400.0),
            " K",
            "dbms thermal -o",
        )),
        SensorLayer::Radiance => {
            let band = crate::thermal::planck::BAND_8_12_UM;
            let hottest = crate::thermal::planck::band_radiance(400.0, band).ok()?;
            Some(holds(
                "an 8–12 µm radiance map",
                "W·m⁻²·sr⁻¹",
                (0.0, hottest.ceil()),
                " W·m⁻²·sr⁻¹",
                "dbms thermal --radiance-out",
            ))
        }
        SensorLayer::Backscatter => Some(holds(
            "a linear σ⁰ map",
            "linear power ratios (m²/m²)",
            (0.0, 100.0),
            " (+20 dB)",
            "dbms radar -o",
        )),
        SensorLayer::Material | SensorLayer::Normal => None,
    }
}

/// The map at `path` opened as the level-0 source of `layer` (temperature, radiance or
/// backscatter), checked to be such a map before anything is built from it: one band of
/// floating-point samples (a photo, a class layer refused), on the database grid
/// ([`Database::values_on_grid`]), every value in the layer's plausible range (`Holds`: a σ⁰
/// map given as the temperature, a temperature map as the σ⁰, °C or dB refused). Checking the
/// range reads the map once, band by band.
pub fn open_values(db: &Database, path: &Path, layer: SensorLayer) -> Result<LayerRows<f32>> {
    let Some(holds) = holds(layer) else {
        return Err(Error::file(
            path,
            format!("no map carries the {layer:?} layer"),
        ));
    };
    let head = crate::io::geotiff::read_rows(path, 0..1)?;
    check_samples(&head, &holds)?;
    let rows = db.values_on_grid(path)?;
    let Some((lo, hi)) = value_range(&rows)? else {
        return Ok(rows);
    };
    if f64::from(lo) < holds.range.0 || f64::from(hi) > holds.range.1 {
        return Err(Error::file(
            path,
            format!(
                "holds values from {lo} to {hi}, outside the {} {} holds",
                holds.range_words, holds.what
            ),
        )
        .fix(range_fix(layer, &holds, lo.into(), hi.into())));
    }
    Ok(rows)
}

/// An error unless `head` (a map's first row) is one band of floating-point samples.
fn check_samples(head: &SourceRaster, holds: &Holds) -> Result<()> {
    let fix = format!("give the map `{}` writes", holds.maker);
    let kind = head.samples.type_name();
    if head.bands != 1 {
        return Err(Error::file(
            &head.path,
            format!(
                "has {} bands of {kind} samples (an image?), but {} has one band of {}",
                head.bands, holds.what, holds.band
            ),
        )
        .fix(fix));
    }
    if !matches!(kind, "Float32" | "Float64") {
        return Err(Error::file(
            &head.path,
            format!(
                "has {kind} samples, but {} holds {} as floating point",
                holds.what, holds.band
            ),
        )
        .fix(format!("{fix} (Float32)")));
    }
    Ok(())
}

/// The smallest and largest value of `rows` (NaN, nodata, skipped), read band by band; `None`
/// when there is none.
fn value_range(rows: &LayerRows<f32>) -> Result<Option<(f32, f32)>> {
    let grid = rows.grid();
    let band = crate::raster::band_rows(grid.width);
    let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
    for row0 in (0..grid.height).step_by(band) {
        let values = rows.read_rows(row0, band.min(grid.height - row0))?;
        let (l, h) = (values.par_iter().copied())
            .filter(|v| !v.is_nan())
            .fold(
                || (f32::INFINITY, f32::NEG_INFINITY),
                |(l, h), v| (l.min(v), h.max(v)),
            )
            .reduce(
                || (f32::INFINITY, f32::NEG_INFINITY),
                |a, b| (a.0.min(b.0), a.1.max(b.1)),
            );
        (lo, hi) = (lo.min(l), hi.max(h));
    }
    Ok((lo <= hi).then_some((lo, hi)))
}

/// The fix for a map of `layer` whose values `lo..hi` are out of its range: what it likely
/// is (°C for a temperature, dB for a σ⁰) and the conversion, else the command that makes one.
fn range_fix(layer: SensorLayer, holds: &Holds, lo: f64, hi: f64) -> String {
    let calc = |expr: &str| format!("gdal_calc.py -A IN.tif --calc=\"{expr}\" --outfile=OUT.tif");
    match layer {
        SensorLayer::Temperature if lo >= -100.0 && hi <= 100.0 && hi > 1.0 => {
            format!("in °C? add 273.15: {}", calc("A+273.15"))
        }
        SensorLayer::Backscatter if lo < 0.0 && hi <= 40.0 => {
            format!("in dB? convert to linear power: {}", calc("10**(A/10)"))
        }
        _ => format!("give the map `{}` writes", holds.maker),
    }
}

/// Where a level-0 sensor layer comes from.
pub enum SensorSource<'a> {
    /// The database's materials layer, and the ids it holds.
    Material(&'a dyn RowSource<u8>, Arc<Counted>),
    /// A map of values on the database grid (temperature or radiance), NaN = nodata.
    Values(SensorLayer, &'a dyn RowSource<f32>),
    /// The normals of the terrain's heights (NaN = nodata) by [`crate::raster::surface_normal`],
    /// a roof's face on a building ([`crate::standing::Raised::top_normal`]) and straight up on a placed
    /// object's top: the surface `dbms thermal` and `dbms radar` take
    /// ([`crate::material::surface`]).
    Normals(&'a dyn RowSource<f32>, &'a Standing),
}

impl SensorSource<'_> {
    /// The layer it fills.
    pub fn layer(&self) -> SensorLayer {
        match self {
            SensorSource::Material(..) => SensorLayer::Material,
            SensorSource::Values(l, _) => *l,
            SensorSource::Normals(..) => SensorLayer::Normal,
        }
    }

    /// Level-0 rows `row0 .. row0 + rows`, before the cells without a surface are cleared.
    pub fn read(&self, row0: usize, rows: usize) -> Result<SensorRows> {
        let data = match self {
            SensorSource::Material(src, counted) => {
                SensorData::Ids(src.read_rows(row0, rows)?.into_owned(), counted.clone())
            }
            SensorSource::Values(_, src) => {
                SensorData::Values(src.read_rows(row0, rows)?.into_owned())
            }
            SensorSource::Normals(terrain, standing) => {
                SensorData::Vectors(normals(*terrain, standing, row0, rows)?)
            }
        };
        Ok(SensorRows {
            layer: self.layer(),
            data,
        })
    }
}

/// The normals of rows `row0 .. row0 + rows` of `terrain`, read with a row of neighbours above
/// and below (where the grid has them) so each is the whole grid's
/// [`crate::raster::surface_normal`]; a roof's face where `standing` has a building, up on a
/// placed object; `[0; 3]` where the height is nodata.
fn normals(
    terrain: &dyn RowSource<f32>,
    standing: &Standing,
    row0: usize,
    rows: usize,
) -> Result<Vec<[f64; 3]>> {
    let g = terrain.grid();
    let (top, bottom) = (row0.saturating_sub(1), (row0 + rows + 1).min(g.height));
    let heights = terrain.read_rows(top, bottom - top)?;
    let halo = crate::grid::Grid {
        height: bottom - top,
        ..g.clone()
    };
    let skip = (row0 - top) * g.width;
    let mut out: Vec<[f64; 3]> = (skip..skip + rows * g.width)
        .into_par_iter()
        .map(|i| match heights[i].is_nan() {
            true => [0.0; 3],
            false => crate::raster::surface_normal(&heights, &halo, i),
        })
        .collect();
    let start = row0 * g.width;
    let (buildings, objects) = (&standing.buildings, &standing.objects);
    for rc in buildings.range(start, start + out.len()) {
        out[rc.index - start] = buildings.top_normal(g, rc.index);
    }
    for rc in objects.range(start, start + out.len()) {
        out[rc.index - start] = [0.0, 0.0, 1.0];
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn page_cells(rows: &SensorRows) -> SensorCells {
        let mut out = rows.layer.nodata(rows.len());
        rows.copy_run(0, rows.len(), &mut out, 0);
        out
    }

    /// The majority of the level-0 cells under coarse cell `(c, r)` of level `level`, counted
    /// directly (the brute-force reference).
    fn brute_majority(ids: &[u8], w: usize, f: usize, level: u32, c: usize, r: usize) -> u8 {
        let (s, h) = (f.pow(level), ids.len() / w);
        let mut n = [0u64; 256];
        for row in r * s..((r + 1) * s).min(h) {
            for col in c * s..((c + 1) * s).min(w) {
                n[ids[row * w + col] as usize] += 1;
            }
        }
        n[MATERIAL_NODATA as usize] = 0;
        let best = (0..255)
            .max_by_key(|&i| (n[i], std::cmp::Reverse(i)))
            .unwrap();
        if n[best] == 0 {
            MATERIAL_NODATA
        } else {
            best as u8
        }
    }

    fn brute_mean(v: &[f32], w: usize, f: usize, level: u32, c: usize, r: usize) -> f32 {
        let (s, h) = (f.pow(level), v.len() / w);
        let (mut sum, mut n) = (0.0f64, 0u64);
        for row in r * s..((r + 1) * s).min(h) {
            for col in c * s..((c + 1) * s).min(w) {
                if !v[row * w + col].is_nan() {
                    sum += f64::from(v[row * w + col]);
                    n += 1;
                }
            }
        }
        mean(sum, n)
    }

    fn brute_sum(v: &[[f64; 3]], w: usize, f: usize, level: u32, c: usize, r: usize) -> [f64; 3] {
        let (s, h) = (f.pow(level), v.len() / w);
        let mut sum = [0.0; 3];
        for row in r * s..((r + 1) * s).min(h) {
            for col in c * s..((c + 1) * s).min(w) {
                (0..3).for_each(|k| sum[k] += v[row * w + col][k]);
            }
        }
        sum
    }

    /// Bands of any height give the whole grid's normals (the halo rows make them so), with
    /// a pitched roof's cells along its face (a taller neighbour's wall not tilting them), an
    /// object's top up and nodata cells `[0; 3]`.
    #[test]
    fn banded_normals_equal_the_whole_grid_s() {
        use crate::grid::Grid;
        use crate::raster::Raster;
        use crate::standing::{Raised, RaisedCell};
        let (w, h) = (7, 11);
        let grid = Grid::north_up(0.0, 0.0, 0.5, w, h, crate::crs::Crs::unknown());
        let mut z: Vec<f32> = (0..w * h)
            .map(|i| ((i % w) as f32 * 0.7).sin() * 3.0 + (i / w) as f32 * 0.4)
            .collect();
        z[3 * w + 4] = f32::NAN;
        let terrain = Raster::new(grid.clone(), z.clone());
        let cell = |index: usize, top_z: f32| RaisedCell {
            index,
            top_z,
            colour: None,
            partial: false,
        };
        // A roof rising 0.25 m a cell eastward (a 26.6° face) over columns 1–4 of rows 7–9,
        // and a tower beside it at column 5 of row 8.
        let mut roof: Vec<RaisedCell> = (7..10)
            .flat_map(|r| (1..5).map(move |c| (r, c)))
            .map(|(r, c)| cell(r * w + c, 30.0 + 0.25 * c as f32))
            .collect();
        roof.push(cell(8 * w + 5, 45.0));
        roof.sort_by_key(|c| c.index);
        let buildings = Raised::new(roof, &terrain);
        let objects = Raised::new(vec![cell(5 * w + 2, 20.0)], &terrain);
        let all = buildings.union(&objects, &terrain);
        let standing = Standing {
            buildings,
            objects,
            all,
        };
        let face = {
            let s = 0.25 / 0.5;
            let n = (s * s + 1.0f64).sqrt();
            [-s / n, 0.0, 1.0 / n]
        };
        let nothing = Standing {
            buildings: Raised::new(vec![], &terrain),
            objects: Raised::new(vec![], &terrain),
            all: Raised::new(vec![], &terrain),
        };
        let whole = normals(&terrain, &nothing, 0, h).unwrap();
        for rows in 1..=h {
            let mut banded = Vec::new();
            for row0 in (0..h).step_by(rows) {
                banded.extend(normals(&terrain, &standing, row0, rows.min(h - row0)).unwrap());
            }
            for i in 0..w * h {
                let (col, row) = (i % w, i / w);
                let want = match i {
                    _ if i == 5 * w + 2 || i == 8 * w + 5 => [0.0, 0.0, 1.0],
                    _ if (7..10).contains(&row) && (1..5).contains(&col) => face,
                    _ if z[i].is_nan() => [0.0; 3],
                    _ => crate::raster::surface_normal(&z, &grid, i),
                };
                assert_eq!(banded[i], want, "bands of {rows}, cell {i}");
                assert_eq!(whole[i] == [0.0; 3], z[i].is_nan());
            }
        }
    }

    #[test]
    fn majority_ties_go_to_the_lower_id_and_nodata_never_wins() {
        let counted = Arc::new(Counted::new([0, 3, 7]));
        let ids = vec![
            7,
            3,
            3,
            7,
            MATERIAL_NODATA,
            MATERIAL_NODATA,
            0,
            MATERIAL_NODATA,
        ];
        let rows = SensorRows {
            layer: SensorLayer::Material,
            data: SensorData::Ids(ids, counted),
        };
        // 4 × 2 cells reduced by 2: blocks {7, 3, nodata, nodata} and {3, 7, 0, nodata}.
        let coarse = rows.reduce(4, 2);
        assert_eq!(page_cells(&coarse), SensorCells::Ids(vec![3, 0]));
        let all_nodata = SensorRows {
            layer: SensorLayer::Material,
            data: SensorData::Ids(vec![MATERIAL_NODATA; 4], Arc::new(Counted::new([]))),
        };
        assert_eq!(
            page_cells(&all_nodata.reduce(2, 2)),
            SensorCells::Ids(vec![MATERIAL_NODATA])
        );
    }

    proptest! {
        /// Every coarse level's majority, mean and normal sum equal the brute-force ones over
        /// the cell's whole level-0 block (exact, not a majority of majorities or a mean of
        /// means).
        #[test]
        fn cascaded_reductions_equal_the_level0_block_reductions(
            w in 1usize..20, h in 1usize..20, f in 2usize..5,
            seed in any::<u64>(),
        ) {
            let mut rng = crate::num::SplitMix(seed);
            let ids: Vec<u8> = (0..w * h)
                .map(|_| [0, 1, 2, 9, MATERIAL_NODATA][(rng.next_u64() % 5) as usize])
                .collect();
            let vals: Vec<f32> = (0..w * h)
                .map(|_| match rng.next_u64() % 4 {
                    0 => f32::NAN,
                    k => 250.0 + k as f32 * 17.3 + (rng.next_u64() % 1000) as f32 / 7.0,
                })
                .collect();
            let normals: Vec<[f64; 3]> = (0..w * h)
                .map(|_| match rng.next_u64() % 5 {
                    0 => [0.0; 3],
                    _ => {
                        let mut r = || (rng.next_u64() % 2001) as f64 / 1000.0 - 1.0;
                        let (x, y) = (r(), r());
                        let l = (x * x + y * y + 1.0).sqrt();
                        [x / l, y / l, 1.0 / l]
                    }
                })
                .collect();
            let mut n = SensorRows { layer: SensorLayer::Normal, data: SensorData::Vectors(normals.clone()) };
            let counted = Arc::new(Counted::new(ids.iter().copied()));
            let mut m = SensorRows { layer: SensorLayer::Material, data: SensorData::Ids(ids.clone(), counted) };
            let mut t = SensorRows { layer: SensorLayer::Temperature, data: SensorData::Values(vals.clone()) };
            let mut width = w;
            for level in 1..4u32 {
                m = m.reduce(width, f);
                t = t.reduce(width, f);
                n = n.reduce(width, f);
                width = width.div_ceil(f);
                let SensorData::Vectors(sums) = &n.data else { unreachable!() };
                let SensorCells::Normals(packed) = page_cells(&n) else { unreachable!() };
                for (i, (sum, &p)) in sums.iter().zip(&packed).enumerate() {
                    let want = brute_sum(&normals, w, f, level, i % width, i / width);
                    prop_assert!((0..3).all(|k| (sum[k] - want[k]).abs() <= 1e-12 * (1.0 + want[k].abs())));
                    prop_assert_eq!(p == NORMAL_NODATA, want == [0.0; 3]);
                }
                let (SensorCells::Ids(mc), SensorCells::Values(tc)) = (page_cells(&m), page_cells(&t)) else {
                    unreachable!()
                };
                for i in 0..mc.len() {
                    let (c, r) = (i % width, i / width);
                    prop_assert_eq!(mc[i], brute_majority(&ids, w, f, level, c, r));
                    let want = brute_mean(&vals, w, f, level, c, r);
                    prop_assert!(
                        (tc[i].is_nan() && want.is_nan()) || (tc[i] - want).abs() <= 1e-4,
                        "level {} cell {}: {} against {}", level, i, tc[i], want
                    );
                }
            }
        }
    }
}
