//! The material layer (`dbms materials`): one material id per database cell, a byte GeoTIFF
//! layer [`MATERIALS`] of the database, ids from its material table.
//!
//! Sources, in order of precedence (the first that says something decides a cell):
//! 1. roofs: cells under a footprint of the database's `buildings` layer whose feature has a
//!    `roof_material` property take that material;
//! 2. vector features (`--features`, [`super::features`]: polygons, then lines with a width);
//!    not under a footprint (a roof hides the ground a feature describes);
//! 3. a land-cover raster (`--landcover`, [`super::cover`]) through a legend of the table
//!    (`esa_worldcover`, `nlcd`, or the table's own); not under a footprint either;
//! 4. the orthophoto ([`super::photo`]): roof rules under a footprint, ground rules elsewhere;
//! 5. else [`UNCLASSIFIED`] (no photo there, or black).
//!
//! The table used is the shipped default, or `--table FILE`, which is copied into the database
//! as layer [`MATERIAL_TABLE`] so later stages read the same numbers.
//!
//! Invariant: the layer is a pure function of the database's colour and buildings layers, the
//! features, the land cover and the table; every id in it is [`UNCLASSIFIED`] or a material
//! of that table.

use super::table::{MaterialTable, UNCLASSIFIED};
use super::{cover, features, photo};
use crate::db::{Database, Stage};
use crate::error::{Error, Result};
use crate::grid::Grid;
use crate::raster::Raster;
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// The database layer name of the material ids.
pub const MATERIALS: &str = "materials";
/// The database layer name of a material table given with `--table`.
pub const MATERIAL_TABLE: &str = "material_table";

/// What `dbms materials` reads besides the database.
#[derive(Debug, Clone, Default)]
pub struct MaterialOptions {
    /// GeoJSON files of features naming materials, in paint order.
    pub features: Vec<PathBuf>,
    /// A land-cover class raster and the legend (a name in the table) its codes follow.
    pub landcover: Option<(PathBuf, String)>,
    /// A material table file instead of the shipped default.
    pub table: Option<PathBuf>,
    /// The materials of the cells placed voxel objects stand on, above every other source
    /// (the object is the cell's top surface): each `MATERIAL` (every placed object not named
    /// otherwise, at most one) or `NAME=MATERIAL` (the placements of the object file `NAME`,
    /// its name as placed, without directory or `.dvox`).
    pub objects: Vec<String>,
    /// A PNG of the layer to look at: each cell in its material's colour (black: unclassified).
    pub preview: Option<PathBuf>,
    /// How long to wait for the database's lock.
    pub wait: std::time::Duration,
}

/// Cells decided by each source.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct SourceCounts {
    /// Cells under placed objects (`--objects`).
    pub objects: u64,
    /// Roofs with a `roof_material`.
    pub roofs: u64,
    /// Vector features.
    pub features: u64,
    /// The land-cover raster.
    pub landcover: u64,
    /// The photo's roof rules (under a footprint without `roof_material`).
    pub photo_roofs: u64,
    /// The photo's ground rules.
    pub photo_ground: u64,
    /// No source.
    pub unclassified: u64,
}

/// `dbms materials`' result.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MaterialSummary {
    /// Cells in the layer.
    pub cells: u64,
    /// Cells each source decided.
    pub sources: SourceCounts,
    /// Cells per material name (`unclassified` included when any).
    pub materials: BTreeMap<String, u64>,
    /// `default`, or the table file given.
    pub table: String,
    /// Land-cover codes the legend does not map, with their cell counts (those cells fell
    /// through to the photo): a non-empty list often means the wrong legend.
    pub landcover_unmapped: BTreeMap<u32, u64>,
}

impl std::fmt::Display for MaterialSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let s = &self.sources;
        writeln!(
            f,
            "materials: {} cells (table {}): objects {}, roofs {}, features {}, land cover {}, photo roofs {}, photo ground {}, unclassified {}",
            self.cells, self.table, s.objects, s.roofs, s.features, s.landcover, s.photo_roofs, s.photo_ground, s.unclassified
        )?;
        for (name, n) in &self.materials {
            writeln!(
                f,
                "  {name:<16} {n:>10} cells  {:>5.1} %",
                100.0 * *n as f64 / self.cells.max(1) as f64
            )?;
        }
        if !self.landcover_unmapped.is_empty() {
            writeln!(f, "  {}", unmapped_line(&self.landcover_unmapped))?;
        }
        Ok(())
    }
}

/// Unmapped land-cover codes shown by name in the summary; `--json` lists them all.
const UNMAPPED_SHOWN: usize = 5;

/// The summary's line for the land-cover codes the legend does not map (`unmapped`: code →
/// cells): how many codes and cells, and the first [`UNMAPPED_SHOWN`] codes, so a raster of
/// thousands of codes (the wrong legend, a raster of ids) stays one short line.
fn unmapped_line(unmapped: &BTreeMap<u32, u64>) -> String {
    let cells: u64 = unmapped.values().sum();
    let first: Vec<String> = (unmapped.keys().take(UNMAPPED_SHOWN))
        .map(u32::to_string)
        .collect();
    let more = match unmapped.len().saturating_sub(UNMAPPED_SHOWN) {
        0 => String::new(),
        n => format!(" and {n} more (--json lists them all)"),
    };
    format!(
        "{} land-cover codes the legend does not map ({cells} cells, from the photo): {}{more}",
        unmapped.len(),
        first.join(", ")
    )
}

/// Everything the classification reads, on one grid (row-major cells).
pub struct Inputs<'a> {
    /// The orthophoto colour (alpha 0 = no photo).
    pub colour: &'a [[u8; 4]],
    /// Cells under a building footprint.
    pub roof: &'a [bool],
    /// The cells placed objects stand on, and the material they get (`--objects`), in
    /// placement order: a later placement over an earlier one wins.
    pub objects: &'a [features::Painted],
    /// Roofs with a given material, then ground features, as painted.
    pub roofs_given: &'a [features::Painted],
    /// Ground features in paint order.
    pub features: &'a [features::Painted],
    /// Land-cover codes and the legend that maps them.
    pub landcover: Option<(&'a [Option<u32>], &'a str)>,
}

/// The material id of every cell, by the precedence of the module doc, with the summary's
/// counts (`table` names it as the summary shows).
pub fn classify(
    inputs: &Inputs,
    table: &MaterialTable,
    table_name: &str,
) -> Result<(Vec<u8>, MaterialSummary)> {
    let n = inputs.colour.len();
    let mut ids: Vec<Option<u8>> = vec![None; n];
    let mut sources = SourceCounts::default();
    let id_of = |p: &features::Painted| {
        table.id_of(&p.material).ok_or_else(|| {
            Error::msg(format!(
                "{}: material {:?} is not in the material table ({table_name})",
                p.origin, p.material
            ))
            .fix(format!(
                "use one of: {}",
                names(table.materials.iter().map(|m| &m.name))
            ))
        })
    };
    for p in inputs.objects {
        let id = id_of(p)?;
        for &c in &p.cells {
            if ids[c].is_none() {
                sources.objects += 1;
            }
            ids[c] = Some(id);
        }
    }
    let object_cells = ids.clone();
    for p in inputs.roofs_given {
        let id = id_of(p)?;
        for &c in p.cells.iter().filter(|&&c| object_cells[c].is_none()) {
            if ids[c].is_none() {
                sources.roofs += 1;
            }
            ids[c] = Some(id);
        }
    }
    for p in inputs.features {
        let id = id_of(p)?;
        let ground = |c: usize| !inputs.roof[c] && object_cells[c].is_none();
        for &c in p.cells.iter().filter(|&&c| ground(c)) {
            if ids[c].is_none() {
                sources.features += 1;
            }
            ids[c] = Some(id);
        }
    }
    let mut unmapped = BTreeMap::new();
    if let Some((codes, legend)) = inputs.landcover {
        if !table.landcover.iter().any(|l| l.legend == legend) {
            return Err(Error::msg(format!(
                "land-cover legend {legend:?} is not in the material table ({table_name})"
            ))
            .fix(format!(
                "use one of: {}",
                names(table.landcover.iter().map(|l| &l.legend))
            )));
        }
        for c in 0..n {
            if ids[c].is_some() || inputs.roof[c] {
                continue;
            }
            if let Some(code) = codes[c] {
                match table.landcover_material(legend, code) {
                    Some(id) => {
                        ids[c] = Some(id);
                        sources.landcover += 1;
                    }
                    None => *unmapped.entry(code).or_insert(0) += 1,
                }
            }
        }
    }
    // A table needs the photo's classes only where the photo decides a cell.
    let photo_ids: BTreeMap<&str, Option<u8>> =
        photo::NAMES.iter().map(|&n| (n, table.id_of(n))).collect();
    let mut missing: BTreeMap<&str, u64> = BTreeMap::new();
    let ids: Vec<u8> = ids
        .into_iter()
        .enumerate()
        .map(|(c, id)| match id {
            Some(id) => id,
            None => match photo::classify(inputs.colour[c], inputs.roof[c]) {
                Some(name) => {
                    match inputs.roof[c] {
                        true => sources.photo_roofs += 1,
                        false => sources.photo_ground += 1,
                    }
                    photo_ids[name].unwrap_or_else(|| {
                        *missing.entry(name).or_insert(0) += 1;
                        UNCLASSIFIED
                    })
                }
                None => {
                    sources.unclassified += 1;
                    UNCLASSIFIED
                }
            },
        })
        .collect();
    if !missing.is_empty() {
        let list: Vec<String> = missing
            .iter()
            .map(|(n, k)| format!("{n} ({k} cells)"))
            .collect();
        return Err(Error::msg(format!(
            "the material table ({table_name}) lacks classes the photo gives: {}",
            list.join(", ")
        ))
        .fix("add them to the table, or cover those cells with --features or --landcover (docs/materials.md)"));
    }
    let mut per_id = [0u64; 256];
    ids.iter().for_each(|&id| per_id[id as usize] += 1);
    let materials = (0..=255u8)
        .filter(|&id| per_id[id as usize] > 0)
        .map(|id| {
            let name = table.by_id(id).map_or("unclassified", |m| m.name.as_str());
            (name.to_string(), per_id[id as usize])
        })
        .collect();
    let summary = MaterialSummary {
        cells: n as u64,
        sources,
        materials,
        table: table_name.to_string(),
        landcover_unmapped: unmapped,
    };
    Ok((ids, summary))
}

/// The database's material table: its own (`dbms materials --table`) or the default.
pub fn table_of(db: &Database) -> Result<MaterialTable> {
    match db.manifest.layers.contains_key(MATERIAL_TABLE) {
        true => MaterialTable::read(&db.layer_path(MATERIAL_TABLE)?),
        false => Ok(MaterialTable::default_table().clone()),
    }
}

/// The colour the stages draw: the photo, and where it has no colour (alpha 0) the colour of
/// the cell's material from the table, opaque, when the database has a materials layer and the
/// cell a material. Read band by band like the layers under it.
pub struct ColourRows {
    photo: crate::db::LayerRows<[u8; 4]>,
    /// The materials layer and each id's colour (`None`: unclassified or not in the table).
    materials: Option<(crate::db::LayerRows<u8>, Palette)>,
}

/// Each material id's opaque colour (`None`: unclassified or not in the table).
type Palette = Box<[Option<[u8; 4]>; 256]>;

/// The database's [`ColourRows`].
pub fn colour_rows(db: &Database) -> Result<ColourRows> {
    let materials = match db.manifest.layers.contains_key(MATERIALS) {
        false => None,
        true => {
            let table = table_of(db)?;
            let mut palette = Box::new([None; 256]);
            for m in &table.materials {
                let [r, g, b] = m.colour;
                palette[m.id as usize] = Some([r, g, b, 255]);
            }
            Some((db.byte_rows(MATERIALS)?, palette))
        }
    };
    Ok(ColourRows {
        photo: db.colour_rows()?,
        materials,
    })
}

impl crate::raster::RowSource<[u8; 4]> for ColourRows {
    fn grid(&self) -> &Grid {
        self.photo.grid()
    }

    fn read_rows(&self, row0: usize, rows: usize) -> Result<std::borrow::Cow<'_, [[u8; 4]]>> {
        let photo = self.photo.read_rows(row0, rows)?;
        let Some((materials, palette)) = &self.materials else {
            return Ok(photo);
        };
        if photo.iter().all(|c| c[3] != 0) {
            return Ok(photo);
        }
        let ids = materials.read_rows(row0, rows)?;
        let mut colour = photo.into_owned();
        for (c, &id) in colour.iter_mut().zip(ids.iter()) {
            if c[3] == 0 {
                if let Some(fallback) = palette[id as usize] {
                    *c = fallback;
                }
            }
        }
        Ok(std::borrow::Cow::Owned(colour))
    }
}

/// `names` as a list for an error's fix.
fn names<'a>(names: impl Iterator<Item = &'a String>) -> String {
    names.map(String::as_str).collect::<Vec<_>>().join(", ")
}

/// The cells under the footprints of the database's buildings layer (if it has one), and
/// those of footprints with a `roof_material`, as painted features.
/// The cells each placement of `db` stands on, with its material from `specs` (see
/// [`MaterialOptions::objects`]), in placement order; placements no spec names are left out.
/// A name no placement has, two bare materials or a name given twice is an error.
fn object_materials(db: &Database, specs: &[String]) -> Result<Vec<features::Painted>> {
    if specs.is_empty() {
        return Ok(Vec::new());
    }
    let (mut every, mut named) = (None, BTreeMap::new());
    for spec in specs {
        let twice = |what: String| {
            Error::msg(format!("--objects {spec}: {what} is given twice"))
                .fix("give each object name once, and at most one MATERIAL for the rest")
        };
        match spec.split_once('=') {
            Some((name, material)) => {
                if named.insert(name, material).is_some() {
                    return Err(twice(format!("object {name:?}")));
                }
            }
            None if every.is_some() => return Err(twice("a material for every object".into())),
            None => every = Some(spec.as_str()),
        }
    }
    let terrain = db.elevation_rows()?;
    let grid = crate::raster::RowSource::grid(&terrain).clone();
    let band = crate::raster::band_rows(grid.width);
    let (standing, placed) =
        crate::standing::Standing::read_placed(db, &terrain, band, 0..grid.height, 0..grid.width)?;
    let raised = standing.objects;
    let name_of = |file: &str| crate::voxel::place::placed_name(file).to_string();
    if let Some(name) = named
        .keys()
        .find(|n| !placed.iter().any(|(p, _)| name_of(&p.file) == **n))
    {
        let mut names: Vec<String> = placed.iter().map(|(p, _)| name_of(&p.file)).collect();
        names.sort();
        names.dedup();
        return Err(Error::msg(format!(
            "--objects {name}=...: no placed object is named {name:?}"
        ))
        .fix(format!(
            "name one of the placed objects: {}",
            names.join(", ")
        )));
    }
    let mut painted = Vec::new();
    for (p, marked) in placed {
        let name = name_of(&p.file);
        let Some(material) = named.get(name.as_str()).copied().or(every) else {
            continue;
        };
        let cells = marked.into_iter().filter(|&c| raised.contains(c)).collect();
        painted.push(features::Painted {
            material: material.to_string(),
            origin: format!("--objects (placement {} of {name})", p.id),
            cells,
        });
    }
    Ok(painted)
}

fn roofs(db: &Database) -> Result<(Vec<bool>, Vec<features::Painted>)> {
    let grid = db.grid();
    let mut roof = vec![false; grid.len()];
    let mut given = Vec::new();
    if !db.manifest.layers.contains_key(crate::db::BUILDINGS) {
        return Ok((roof, given));
    }
    let path = db.layer_path(crate::db::BUILDINGS)?;
    let fix = "re-run `dbms shadow-height --apply`";
    for (i, f) in crate::geojson::read_features(&path, fix)?
        .iter()
        .enumerate()
    {
        let bad = |what: String| Error::file(&path, format!("feature {i}: {what}")).fix(fix);
        let geometry = f.get("geometry").ok_or_else(|| bad("no geometry".into()))?;
        let cells: Vec<usize> = crate::geojson::polygons(geometry)
            .map_err(bad)?
            .iter()
            .flat_map(|rings| crate::standing::polygon_cells(grid, rings))
            .collect();
        cells.iter().for_each(|&c| roof[c] = true);
        match f.pointer("/properties/roof_material") {
            None | Some(serde_json::Value::Null) => {}
            Some(serde_json::Value::String(m)) => given.push(features::Painted {
                material: m.clone(),
                origin: format!("{}: feature {i}", path.display()),
                cells,
            }),
            Some(_) => return Err(bad("roof_material is not a string".into())),
        }
    }
    Ok((roof, given))
}

/// Build the material layer of the database in `dir` and commit it (with the table, when one
/// is given, and a `materials` stage) as one change.
pub fn build(dir: &Path, opts: &MaterialOptions) -> Result<MaterialSummary> {
    let db = Database::open(dir)?;
    let grid: Grid = db.grid().clone();
    let (table, table_name) = match &opts.table {
        Some(path) => (MaterialTable::read(path)?, path.display().to_string()),
        None => (
            MaterialTable::default_table().clone(),
            "default".to_string(),
        ),
    };
    let colour = db.read_colour()?;
    let (roof, roofs_given) = roofs(&db)?;
    let painted = features::read(&opts.features, &grid)?;
    let objects = object_materials(&db, &opts.objects)?;
    let codes = match &opts.landcover {
        Some((path, _)) => Some(cover::sample_codes(path, &grid)?),
        None => None,
    };
    let inputs = Inputs {
        colour: &colour.data,
        roof: &roof,
        objects: &objects,
        roofs_given: &roofs_given,
        features: &painted,
        landcover: codes
            .as_deref()
            .zip(opts.landcover.as_ref().map(|(_, l)| l.as_str())),
    };
    let (ids, summary) = classify(&inputs, &table, &table_name)?;
    let read = opts
        .features
        .iter()
        .chain(&opts.table)
        .chain(opts.landcover.iter().map(|l| &l.0));
    let read: Vec<&Path> = read.map(PathBuf::as_path).collect();
    let mut change = Database::begin(dir, opts.wait, &read)?;
    if change.db.manifest.layers.get(crate::db::COLOUR) != db.manifest.layers.get(crate::db::COLOUR)
    {
        return Err(Error::file(
            dir,
            "its colour layer was replaced while materials were classified",
        )
        .fix("run dbms materials again"));
    }
    let layer = Raster::new(grid, ids);

    change.write_layer(MATERIALS, "materials", "tif", |path| {
        crate::io::geotiff::write_u8(path, &layer, None)?;
        Ok(None)
    })?;
    let mut inputs_record = Vec::new();
    if let Some(path) = &opts.table {
        let bytes = crate::io::read_settings(path)?.into_bytes();
        change.write_layer(MATERIAL_TABLE, "material-table", "json", |dest| {
            crate::io::atomic::write_bytes_atomic(dest, &bytes)?;
            Ok(None)
        })?;
    } else {
        change.db.manifest.layers.remove(MATERIAL_TABLE);
    }
    for path in opts
        .features
        .iter()
        .chain(opts.landcover.as_ref().map(|(p, _)| p))
        .chain(&opts.table)
    {
        inputs_record.push(serde_json::json!({
            "path": path.display().to_string(),
            "sha256": crate::db::sha256_file(path)?,
        }));
    }
    change.db.record_stage(Stage::now(
        "materials",
        serde_json::json!({
            "inputs": inputs_record,
            "legend": opts.landcover.as_ref().map(|(_, l)| l),
            "objects": opts.objects,
            "table": summary.table,
            "sources": summary.sources,
        }),
    ));
    // The picture is written and staged before the commit, renamed into place after it: a
    // preview that cannot be written fails the run with the database unchanged.
    let preview = match &opts.preview {
        Some(png) => {
            let rgb: Vec<u8> = layer
                .data
                .iter()
                .flat_map(|&id| table.by_id(id).map_or([0; 3], |m| m.colour))
                .collect();
            let (w, h) = (layer.grid.width, layer.grid.height);
            Some(crate::io::png::stage_rgb(png, w, h, &rgb)?)
        }
        None => None,
    };
    change.commit()?;
    if let Some(staged) = preview {
        staged.commit()?;
    }
    Ok(summary)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Thousands of unmapped codes (the wrong legend for a float raster of ids, say): the
    /// summary says how many and shows the first five, not one line of every code.
    #[test]
    fn many_unmapped_codes_are_a_count_and_the_first_five() {
        let summary = |codes: std::ops::Range<u32>| MaterialSummary {
            cells: 10,
            sources: SourceCounts::default(),
            materials: BTreeMap::new(),
            table: "default".into(),
            landcover_unmapped: codes.map(|c| (c, 2)).collect(),
        };
        let text = summary(100..50_100).to_string();
        let line = text.lines().last().unwrap();
        assert_eq!(
            line,
            "  50000 land-cover codes the legend does not map (100000 cells, from the photo): 100, 101, 102, 103, 104 and 49995 more (--json lists them all)"
        );
        let few = summary(7..9).to_string();
        let line = few.lines().last().unwrap();
        assert_eq!(
            line,
            "  2 land-cover codes the legend does not map (4 cells, from the photo): 7, 8"
        );
    }

    fn painted(material: &str, cells: Vec<usize>) -> features::Painted {
        features::Painted {
            material: material.into(),
            origin: "f.geojson: feature 0".into(),
            cells,
        }
    }

    /// Eight cells, each decided by another source, in the order of precedence.
    #[test]
    fn sources_take_precedence_in_order() {
        let table = MaterialTable::default_table();
        let grass = [74, 112, 48, 255];
        let colour = [grass; 8];
        // Cells 0–2 are under a footprint; 0 has a given roof material.
        let roof = [true, true, true, false, false, false, false, false];
        let roofs_given = [painted("roof_metal", vec![0])];
        // A feature over cells 1 (a roof: ignored), 3 and 4, a later one over 4.
        let features = [painted("water", vec![1, 3, 4]), painted("asphalt", vec![4])];
        // Land cover: built-up (50) everywhere but cell 6 (no code) and cell 7 (unmapped 7).
        let codes = [
            Some(50),
            Some(50),
            Some(50),
            Some(50),
            Some(50),
            Some(50),
            None,
            Some(7),
        ];
        let inputs = Inputs {
            colour: &colour,
            roof: &roof,
            objects: &[],
            roofs_given: &roofs_given,
            features: &features,
            landcover: Some((&codes, "esa_worldcover")),
        };
        let (ids, summary) = classify(&inputs, table, "default").unwrap();
        let name = |c: usize| table.by_id(ids[c]).unwrap().name.as_str();
        let got: Vec<&str> = (0..8).map(name).collect();
        // The photo's grass colour under a roof is a roof class (green-painted sheet metal).
        assert_eq!(
            got,
            [
                "roof_metal",
                "roof_metal",
                "roof_metal",
                "water",
                "asphalt",
                "concrete",
                "grass",
                "grass"
            ]
        );
        let s = &summary.sources;
        assert_eq!(
            (
                s.roofs,
                s.features,
                s.landcover,
                s.photo_roofs,
                s.photo_ground,
                s.unclassified
            ),
            (1, 2, 1, 2, 2, 0)
        );
        assert_eq!(summary.landcover_unmapped, BTreeMap::from([(7, 1)]));
        assert_eq!(summary.materials["roof_metal"], 3);

        // Placed objects over cells 0 (a roof with a material), 4 (features) and 5 (land
        // cover) are their material there, above every other source; the rest is as before.
        let trees = painted("forest", vec![0, 4, 5]);
        let with_trees = Inputs {
            objects: std::slice::from_ref(&trees),
            ..inputs
        };
        let (ids, summary) = classify(&with_trees, table, "default").unwrap();
        let got: Vec<&str> = (0..8)
            .map(|c| table.by_id(ids[c]).unwrap().name.as_str())
            .collect();
        assert_eq!(
            got,
            [
                "forest",
                "roof_metal",
                "roof_metal",
                "water",
                "forest",
                "forest",
                "grass",
                "grass"
            ]
        );
        let s = &summary.sources;
        assert_eq!(
            (
                s.objects,
                s.roofs,
                s.features,
                s.landcover,
                s.photo_roofs,
                s.photo_ground
            ),
            (3, 0, 1, 0, 2, 2)
        );
    }

    #[test]
    fn unknown_names_are_errors_naming_the_feature() {
        let table = MaterialTable::default_table();
        let colour = [[0, 0, 0, 0]; 2];
        let features = [painted("lava", vec![0])];
        let inputs = Inputs {
            colour: &colour,
            roof: &[false, false],
            objects: &[],
            roofs_given: &[],
            features: &features,
            landcover: None,
        };
        let e = classify(&inputs, table, "default").unwrap_err().to_string();
        assert!(
            e.contains("f.geojson: feature 0: material \"lava\"")
                && e.contains("asphalt, concrete"),
            "{e}"
        );
        let codes = [None, None];
        let inputs = Inputs {
            features: &[],
            landcover: Some((&codes, "corine")),
            ..inputs
        };
        let e = classify(&inputs, table, "default").unwrap_err().to_string();
        assert!(
            e.contains("legend \"corine\"") && e.contains("esa_worldcover, nlcd"),
            "{e}"
        );
        // No photo: unclassified.
        let inputs = Inputs {
            landcover: None,
            ..inputs
        };
        let (ids, summary) = classify(&inputs, table, "default").unwrap();
        assert_eq!(ids, [UNCLASSIFIED; 2]);
        assert_eq!(summary.materials["unclassified"], 2);
    }

    /// The photo rules scored against what the sample generator painted (its own labels, not
    /// the rules'): overall accuracy and each class's recall, printed as the confusion matrix
    /// docs/materials.md shows (`cargo test --lib confusion -- --nocapture`).
    #[test]
    fn photo_rules_on_the_labelled_sample() {
        use crate::sample_scene::{generate, SampleOptions, TRUTH_MATERIALS};
        let scene = generate(SampleOptions {
            seed: 1,
            size: 1024,
        })
        .unwrap();
        let grid = &scene.ortho.grid;
        let mut roof = vec![false; grid.len()];
        for b in &scene.buildings {
            let ring: Vec<(f64, f64)> = b.footprint.iter().map(|p| (p[0], p[1])).collect();
            for c in crate::standing::polygon_cells(grid, &[ring]) {
                roof[c] = true;
            }
        }
        let table = MaterialTable::default_table();
        let inputs = Inputs {
            colour: &scene.ortho.data,
            roof: &roof,
            objects: &[],
            roofs_given: &[],
            features: &[],
            landcover: None,
        };
        let (ids, _) = classify(&inputs, table, "default").unwrap();
        let mut classes: Vec<&str> = TRUTH_MATERIALS.to_vec();
        classes.dedup();
        classes.sort();
        classes.dedup();
        let mut names: Vec<&str> = ids
            .iter()
            .map(|&id| table.by_id(id).map_or("unclassified", |m| m.name.as_str()))
            .collect::<std::collections::BTreeSet<_>>()
            .into_iter()
            .collect();
        names.retain(|n| !classes.contains(n));
        let columns: Vec<&str> = classes.iter().chain(&names).copied().collect();
        let mut matrix = BTreeMap::<(&str, &str), u64>::new();
        for (c, &id) in ids.iter().enumerate() {
            let truth = TRUTH_MATERIALS[scene.truth_materials.data[c] as usize];
            let got = table.by_id(id).map_or("unclassified", |m| m.name.as_str());
            *matrix.entry((truth, got)).or_insert(0) += 1;
        }
        println!("| truth \\ classified | {} | recall |", columns.join(" | "));
        println!("|---{}|---|", "|---".repeat(columns.len()));
        let mut correct = 0;
        for truth in &classes {
            let row: Vec<u64> = columns
                .iter()
                .map(|got| *matrix.get(&(*truth, *got)).unwrap_or(&0))
                .collect();
            let total: u64 = row.iter().sum();
            let hit = *matrix.get(&(*truth, *truth)).unwrap_or(&0);
            correct += hit;
            let recall = hit as f64 / total.max(1) as f64;
            println!(
                "| {truth} | {} | {:.3} |",
                row.iter()
                    .map(u64::to_string)
                    .collect::<Vec<_>>()
                    .join(" | "),
                recall
            );
            // Every class the generator paints is found at least three times in four, except
            // the slate roofs, which are grey: the roof rules make grey concrete or bitumen.
            if *truth != "roof_tile" {
                assert!(recall >= 0.75, "{truth}: recall {recall:.3}");
            }
        }
        let accuracy = correct as f64 / ids.len() as f64;
        println!("overall accuracy {accuracy:.4} over {} cells", ids.len());
        assert!(accuracy >= 0.85, "accuracy {accuracy:.4}");
    }
}
