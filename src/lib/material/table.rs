//! The material table: what each material id means to every sensor — the solar albedo and
//! near-infrared reflectance the visual and night-vision images see, the 8–12 µm emissivity and
//! the layered column the thermal solver conducts heat through, and the radar backscatter model —
//! with the land-cover legends that map a class code to a material.
//!
//! The format is `schemas/materials.schema.json` (documented in `docs/materials.md`); the
//! built-in table is `default-materials.json`, embedded in the library.
//!
//! Invariant: a [`MaterialTable`] has passed [`MaterialTable::read`]'s checks — ids unique in
//! 1..=254 (0 is [`UNCLASSIFIED`], 255 is [`NODATA`]), names unique and snake_case, every number
//! finite and in its physical range, at least one layer of positive thickness, every number
//! naming an existing source, every land-cover class naming a material of the table — so code
//! that uses one never re-checks.

pub use crate::backscatter::{Band, Polarisation, RadarModel};
use crate::error::{Error, Result};
use serde::Deserialize;
use std::collections::{BTreeMap, HashSet};
use std::path::Path;
use std::sync::OnceLock;

/// The table format version this dbms reads.
pub const FORMAT_VERSION: u32 = 1;
/// The material id of a cell nothing classified (no vector, no land cover, no photo rule).
pub const UNCLASSIFIED: u8 = 0;
/// The material id of a cell outside the data (nodata in the elevation).
pub const NODATA: u8 = 255;

const DEFAULT_TEXT: &str = include_str!("default-materials.json");
const DEFAULT_PATH: &str = "<built-in default-materials.json>";

/// A material table: its sources, its materials and its land-cover legends.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MaterialTable {
    /// The format version, [`FORMAT_VERSION`].
    pub version: u32,
    /// The publications the numbers come from, each with an id the numbers name.
    pub sources: Vec<Source>,
    /// The materials, in any order.
    pub materials: Vec<Material>,
    /// Class code → material mappings of published land-cover legends.
    #[serde(default)]
    pub landcover: Vec<Legend>,
    /// Index of each id's material in `materials`, filled by the checks.
    #[serde(skip)]
    slots: Vec<Option<usize>>,
}

/// A publication numbers are taken from.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Source {
    /// Short id the `sources` maps name, e.g. `"cibse2006"`.
    pub id: String,
    /// The full citation: authors, year, title, publisher or journal, table or page.
    pub citation: String,
}

/// One material: a surface and the column of layers beneath it.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Material {
    /// The id stored in the material layer, 1..=254.
    pub id: u8,
    /// Unique snake_case name (`asphalt`, `roof_metal`).
    pub name: String,
    /// What the material stands for and which values are representative choices.
    pub description: String,
    /// Fallback sRGB colour for cells without a photo, `[r, g, b]`, 0–255.
    pub colour: [u8; 3],
    /// Broadband (0.3–3 µm) solar albedo, dimensionless, 0..=1.
    pub solar_albedo: f64,
    /// Thermal-infrared (8–12 µm) emissivity, dimensionless, (0, 1].
    pub emissivity: f64,
    /// Reflectance in the 0.6–0.9 µm band image intensifiers (NVG) and low-light TV see,
    /// dimensionless, 0..=1; absent where no published value was found.
    #[serde(default)]
    pub nir_reflectance: Option<f64>,
    /// Bulk surface resistance to evaporation, s/m (FAO-56's surface resistance): absent for
    /// a dry surface (no latent heat), 0 for open water, 70 for well-watered grass.
    #[serde(default)]
    pub surface_resistance_s_per_m: Option<f64>,
    /// The column's layers, top first.
    pub layers: Vec<Layer>,
    /// What lies below the last layer.
    pub bottom: Bottom,
    /// The radar backscatter model.
    pub radar: Radar,
    /// Source id of each number of the material itself (`colour`, `solar_albedo`,
    /// `emissivity`, `nir_reflectance`): field name → [`Source::id`].
    pub sources: BTreeMap<String, String>,
}

/// One homogeneous layer of a material's column.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Layer {
    /// Thickness, metres, > 0.
    pub thickness_m: f64,
    /// Density, kg/m³, > 0.
    pub density_kg_per_m3: f64,
    /// Specific heat capacity, J/(kg·K), > 0.
    pub specific_heat_j_per_kg_k: f64,
    /// Thermal conductivity, W/(m·K), > 0.
    pub conductivity_w_per_m_k: f64,
    /// Source id of each of the four numbers: field name → [`Source::id`].
    pub sources: BTreeMap<String, String>,
}

/// The boundary below a column's last layer.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Bottom {
    /// Ground: below the last layer the temperature is the deep-ground temperature.
    Deep,
    /// A roof over a room: the last layer exchanges heat with room air.
    Interior {
        /// Room air temperature, kelvin, in 200..=350.
        temperature_k: f64,
        /// Surface heat-transfer coefficient to the room, W/(m²·K), > 0.
        h_w_per_m2_k: f64,
        /// Source id of each of the two numbers: field name → [`Source::id`].
        sources: BTreeMap<String, String>,
    },
}

/// A material's radar behaviour: backscatter fits per band, and whether it is mirror-like.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Radar {
    /// Mirror-like (calm water, flat roofs): little backscatter except near normal incidence.
    pub specular: bool,
    /// Published σ⁰ fits, at most one per band and polarisation; empty where none was found.
    #[serde(default)]
    pub models: Vec<RadarModel>,
}

impl Radar {
    /// The σ⁰ model for `band`: the table's first for it (any polarisation), if any.
    pub fn model_for(&self, band: Band) -> Option<&RadarModel> {
        crate::backscatter::model_for(&self.models, band)
    }
}

/// A published land-cover legend's classes mapped to materials.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Legend {
    /// The legend's name as callers give it (`esa_worldcover`, `nlcd`).
    pub legend: String,
    /// Source id of the legend (its product documentation).
    pub source: String,
    /// The classes.
    pub classes: Vec<LandcoverClass>,
}

/// One class of a land-cover legend.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LandcoverClass {
    /// The class code stored in the land-cover raster.
    pub code: u32,
    /// The class name as the legend gives it.
    pub label: String,
    /// The name of the material the class maps to.
    pub material: String,
}

impl MaterialTable {
    /// The built-in table (`default-materials.json`), parsed and checked once.
    pub fn default_table() -> &'static MaterialTable {
        static TABLE: OnceLock<MaterialTable> = OnceLock::new();
        TABLE.get_or_init(|| {
            // The tests check the built-in table, so this cannot fail on a built dbms.
            MaterialTable::parse(DEFAULT_TEXT, Path::new(DEFAULT_PATH))
                .unwrap_or_else(|e| panic!("the built-in material table is broken: {e}"))
        })
    }

    /// Read and check the material table at `path`.
    pub fn read(path: &Path) -> Result<MaterialTable> {
        let text = crate::io::read_settings(path)?;
        MaterialTable::parse(&text, path)
    }

    fn parse(text: &str, path: &Path) -> Result<MaterialTable> {
        let mut table: MaterialTable = serde_json::from_str(text).map_err(|e| {
            Error::file(path, format!("not a valid material table: {e}"))
                .fix("see docs/materials.md and schemas/materials.schema.json")
        })?;
        table.check(path)?;
        Ok(table)
    }

    /// The material with id `id`, if the table has one.
    pub fn by_id(&self, id: u8) -> Option<&Material> {
        self.slots[id as usize].map(|i| &self.materials[i])
    }

    /// The material named `name`, if the table has one.
    pub fn by_name(&self, name: &str) -> Option<&Material> {
        self.materials.iter().find(|m| m.name == name)
    }

    /// The id of the material named `name`, if the table has one.
    pub fn id_of(&self, name: &str) -> Option<u8> {
        self.by_name(name).map(|m| m.id)
    }

    /// The material id land-cover class `code` of legend `legend` maps to; `None` for a legend
    /// or code the table does not map.
    pub fn landcover_material(&self, legend: &str, code: u32) -> Option<u8> {
        let legend = self.landcover.iter().find(|l| l.legend == legend)?;
        let class = legend.classes.iter().find(|c| c.code == code)?;
        self.id_of(&class.material)
    }

    fn check(&mut self, path: &Path) -> Result<()> {
        let bad = |problem: String, fix: &str| Error::file(path, problem).fix(fix);
        if self.version != FORMAT_VERSION {
            return Err(bad(
                format!("version is {}, not {FORMAT_VERSION}", self.version),
                "this dbms reads version 1 tables; see docs/materials.md",
            ));
        }
        let mut source_ids = HashSet::new();
        for s in &self.sources {
            if !source_ids.insert(s.id.as_str()) {
                return Err(bad(
                    format!("source id `{}` is given twice", s.id),
                    "give each source a unique id",
                ));
            }
            if s.citation.trim().is_empty() {
                return Err(bad(
                    format!("source `{}` has an empty citation", s.id),
                    "give the full citation: authors, year, title, publisher, table or page",
                ));
            }
        }
        if self.materials.is_empty() {
            return Err(bad("has no materials".into(), "add at least one material"));
        }
        let mut slots = vec![None; 256];
        let mut names = HashSet::new();
        for (i, m) in self.materials.iter().enumerate() {
            let what = format!("material `{}` (id {})", m.name, m.id);
            if m.id == UNCLASSIFIED || m.id == NODATA {
                return Err(bad(
                    format!(
                        "{what}: id {} is reserved (0 unclassified, 255 nodata)",
                        m.id
                    ),
                    "give an id in 1..=254",
                ));
            }
            if slots[m.id as usize].replace(i).is_some() {
                return Err(bad(
                    format!("{what}: id {} is used by another material too", m.id),
                    "give each material a unique id in 1..=254",
                ));
            }
            if !is_snake_case(&m.name) {
                return Err(bad(
                    format!("{what}: name is not snake_case"),
                    "use lower-case letters, digits and `_`, starting with a letter",
                ));
            }
            if !names.insert(m.name.as_str()) {
                return Err(bad(
                    format!("{what}: name is used by another material too"),
                    "give each material a unique name",
                ));
            }
            check_material(m, &source_ids).map_err(|(problem, fix)| {
                Error::file(path, format!("{what}: {problem}")).fix(fix)
            })?;
        }
        let mut legends = HashSet::new();
        for l in &self.landcover {
            let what = format!("land-cover legend `{}`", l.legend);
            if !legends.insert(l.legend.as_str()) {
                return Err(bad(
                    format!("{what} is given twice"),
                    "merge its classes into one",
                ));
            }
            if !source_ids.contains(l.source.as_str()) {
                return Err(bad(
                    format!("{what}: source `{}` is not in `sources`", l.source),
                    "add the source or correct its id",
                ));
            }
            let mut codes = HashSet::new();
            for c in &l.classes {
                if !codes.insert(c.code) {
                    return Err(bad(
                        format!("{what}: class {} is given twice", c.code),
                        "map each class code once",
                    ));
                }
                if !names.contains(c.material.as_str()) {
                    return Err(bad(
                        format!(
                            "{what}: class {} maps to `{}`, which is not a material of the table",
                            c.code, c.material
                        ),
                        "name a material of the table's `materials`",
                    ));
                }
            }
        }
        self.slots = slots;
        Ok(())
    }
}

/// A material's own checks, as (problem, fix) for the caller to put the file and name on.
fn check_material(m: &Material, source_ids: &HashSet<&str>) -> Result<(), (String, String)> {
    let fix = |s: &str| s.to_string();
    if m.description.trim().is_empty() {
        return Err((
            "description is empty".into(),
            fix("say what the material stands for"),
        ));
    }
    in_range("solar_albedo", m.solar_albedo, 0.0, 1.0, false, "")?;
    in_range("emissivity", m.emissivity, 0.0, 1.0, true, "")?;
    if let Some(r) = m.nir_reflectance {
        in_range("nir_reflectance", r, 0.0, 1.0, false, "")?;
    }
    if let Some(r) = m.surface_resistance_s_per_m {
        in_range("surface_resistance_s_per_m", r, 0.0, 1e5, false, " s/m")?;
    }
    let mut own = vec!["colour", "solar_albedo", "emissivity"];
    if m.nir_reflectance.is_some() {
        own.push("nir_reflectance");
    }
    if m.surface_resistance_s_per_m.is_some() {
        own.push("surface_resistance_s_per_m");
    }
    check_sources("", &m.sources, &own, source_ids)?;
    if m.layers.is_empty() {
        return Err((
            "has no layers".into(),
            fix("give at least one layer (top first)"),
        ));
    }
    for (i, l) in m.layers.iter().enumerate() {
        let at = format!("layers[{i}].");
        positive(&at, "thickness_m", l.thickness_m, "metres")?;
        positive(&at, "density_kg_per_m3", l.density_kg_per_m3, "kg/m³")?;
        positive(
            &at,
            "specific_heat_j_per_kg_k",
            l.specific_heat_j_per_kg_k,
            "J/(kg·K)",
        )?;
        positive(
            &at,
            "conductivity_w_per_m_k",
            l.conductivity_w_per_m_k,
            "W/(m·K)",
        )?;
        check_sources(&at, &l.sources, &LAYER_NUMBERS, source_ids)?;
    }
    if let Bottom::Interior {
        temperature_k,
        h_w_per_m2_k,
        sources,
    } = &m.bottom
    {
        in_range(
            "bottom.temperature_k",
            *temperature_k,
            200.0,
            350.0,
            false,
            " K",
        )?;
        positive("bottom.", "h_w_per_m2_k", *h_w_per_m2_k, "W/(m²·K)")?;
        check_sources(
            "bottom.",
            sources,
            &["temperature_k", "h_w_per_m2_k"],
            source_ids,
        )?;
    }
    let mut seen = HashSet::new();
    for (i, model) in m.radar.models.iter().enumerate() {
        let at = format!("radar.models[{i}]");
        if !seen.insert((model.band(), model.polarisation())) {
            return Err((
                format!("{at}: a second model for the same band and polarisation"),
                fix("give one model per band and polarisation"),
            ));
        }
        match model {
            RadarModel::UlabyDobson {
                p, incidence_deg, ..
            } => {
                if p.iter().any(|v| !v.is_finite()) {
                    return Err((
                        format!("{at}.p has a number that is not finite"),
                        fix("give P1..P6 as published"),
                    ));
                }
                let [lo, hi] = *incidence_deg;
                if !(0.0..=90.0).contains(&lo) || !(0.0..=90.0).contains(&hi) || lo >= hi {
                    return Err((
                        format!("{at}.incidence_deg is [{lo}, {hi}], not [min, max] within 0..=90"),
                        fix("give the fit's incidence range in degrees, min below max"),
                    ));
                }
            }
            RadarModel::ConstantGamma { gamma_db, .. } => {
                if !gamma_db.is_finite() {
                    return Err((
                        format!("{at}.gamma_db is not a finite number"),
                        fix("give γ in dB as published"),
                    ));
                }
            }
        }
        if !source_ids.contains(model.source()) {
            return Err((
                format!("{at}.source `{}` is not in `sources`", model.source()),
                fix("add the source or correct its id"),
            ));
        }
    }
    Ok(())
}

/// The numbers of a layer, each of which needs a source.
const LAYER_NUMBERS: [&str; 4] = [
    "thickness_m",
    "density_kg_per_m3",
    "specific_heat_j_per_kg_k",
    "conductivity_w_per_m_k",
];

/// `sources` names a known source for exactly the fields `numbers` (prefixed `at` in messages).
fn check_sources(
    at: &str,
    sources: &BTreeMap<String, String>,
    numbers: &[&str],
    source_ids: &HashSet<&str>,
) -> Result<(), (String, String)> {
    for n in numbers {
        match sources.get(*n) {
            None => {
                return Err((
                    format!("{at}{n} has no source"),
                    format!("add `\"{n}\": \"SOURCE_ID\"` to {at}sources"),
                ))
            }
            Some(id) if !source_ids.contains(id.as_str()) => {
                return Err((
                    format!("{at}sources.{n} names `{id}`, which is not in `sources`"),
                    "add the source or correct its id".into(),
                ))
            }
            Some(_) => {}
        }
    }
    if let Some(extra) = sources.keys().find(|k| !numbers.contains(&k.as_str())) {
        return Err((
            format!("{at}sources names `{extra}`, which is not a number here"),
            format!("name only {}", numbers.join(", ")),
        ));
    }
    Ok(())
}

fn in_range(
    field: &str,
    v: f64,
    lo: f64,
    hi: f64,
    lo_open: bool,
    unit: &str,
) -> Result<(), (String, String)> {
    let ok = v.is_finite() && (if lo_open { v > lo } else { v >= lo }) && v <= hi;
    if ok {
        return Ok(());
    }
    let range = if lo_open {
        format!("({lo}, {hi}]")
    } else {
        format!("[{lo}, {hi}]")
    };
    Err((
        format!("{field} is {v}{unit}, outside {range}"),
        format!("give {field} within {range}{unit}"),
    ))
}

fn positive(at: &str, field: &str, v: f64, unit: &str) -> Result<(), (String, String)> {
    if v.is_finite() && v > 0.0 {
        return Ok(());
    }
    Err((
        format!("{at}{field} is {v}, not a positive number"),
        format!("give {field} in {unit}, greater than 0"),
    ))
}

fn is_snake_case(s: &str) -> bool {
    let mut chars = s.chars();
    chars.next().is_some_and(|c| c.is_ascii_lowercase())
        && chars.all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_')
        && !s.ends_with('_')
        && !s.contains("__")
}

#[cfg(test)]
#[path = "table_tests.rs"]
mod tests;
