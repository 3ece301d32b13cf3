//! `manifest.json`, a database directory's one source of truth ([`Manifest`], schema
//! `schemas/manifest.schema.json`): its format, reading and checking, and which files of the
//! directory it owns. Below `io` and `db`: `io::atomic` asks it whether an output would clobber a
//! database's file, and [`crate::db`] builds the directory and its commit protocol on it.
//!
//! Invariant: a [`Manifest`] from [`Manifest::read`] has this build's format name, a version it
//! reads, a checksum that matches its content (when it has one), and names only files inside
//! its directory.

use crate::error::{Error, Result};
use crate::grid::Grid;
use crate::inset::InsetSpec;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use std::collections::BTreeMap;
use std::path::Path;

/// The manifest's file name inside a database directory.
pub const MANIFEST_FILE: &str = "manifest.json";
/// Format name recorded in every manifest.
pub const FORMAT_NAME: &str = "dbms-database";
/// Version of the manifest format this build writes and reads.
pub const FORMAT_VERSION: u32 = 1;

/// The contents of `manifest.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    /// Always [`FORMAT_NAME`].
    pub format: String,
    /// [`FORMAT_VERSION`] of the writer.
    pub format_version: u32,
    /// The database grid every layer shares.
    pub grid: Grid,
    /// Units of coordinates and values.
    pub units: Units,
    /// Latitude/longitude of the grid centre (degrees), when the CRS allows it (see
    /// [`crate::crs::Crs::to_lat_lon`]); the sun model uses it.
    pub centre: Option<LatLon>,
    /// Layers by name ([`crate::db::ELEVATION`], [`crate::db::COLOUR`], and what later stages
    /// add).
    pub layers: BTreeMap<String, Layer>,
    /// Voxel objects placed in the scene, in placement order.
    #[serde(default)]
    pub objects: Vec<PlacedObject>,
    /// The largest placement id ever given (removed placements included), so ids are never
    /// reused; 0 before the first.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub last_placement_id: u64,
    /// Every inset of the database, nested ones too, parents before their children; each is a
    /// database of its own in `insets/NAME/` ([`crate::db::Database::open_inset`]). Absent
    /// (and not written) when there are none, so manifests without insets read and write as
    /// before.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub insets: Vec<InsetRecord>,
    /// Where the database came from.
    pub provenance: Provenance,
    /// Stages that have run, in order (ingest first).
    pub stages: Vec<Stage>,
    /// Lower-case hex SHA-256 of this manifest written without this member
    /// ([`Manifest::content_sha256`]); absent in manifests of dbms before 0.x's transactions.
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub checksum: Option<String>,
}

fn is_zero(v: &u64) -> bool {
    *v == 0
}

/// The text dbms saves a JSON document as: pretty JSON with a final newline.
fn pretty_text<T: Serialize>(doc: &T) -> String {
    let mut text = serde_json::to_string_pretty(doc).expect("a dbms document serialises");
    text.push('\n');
    text
}

/// The checksum a document dbms writes carries of its own content (the manifest's, a pyramid
/// ledger's): the lower-case hex SHA-256 of `bare`, the document without its `checksum`
/// member, saved as `pretty_text`. A reader computes it again and compares.
pub fn content_checksum<T: Serialize>(bare: &T) -> String {
    hex(&Sha256::digest(pretty_text(bare).as_bytes()))
}

impl Manifest {
    /// The manifest's text as saved: pretty JSON with a final newline.
    pub(crate) fn text(&self) -> String {
        pretty_text(self)
    }

    /// SHA-256 of the manifest's text without its `checksum` member ([`content_checksum`]).
    pub fn content_sha256(&self) -> String {
        content_checksum(&Manifest {
            checksum: None,
            ..self.clone()
        })
    }

    /// Every file the manifest names (layers, then objects), relative to the directory.
    pub(crate) fn files(&self) -> impl Iterator<Item = (&String, &String)> {
        let layers = self.layers.values().map(|l| (&l.file, &l.sha256));
        layers.chain(self.objects.iter().map(|o| (&o.file, &o.sha256)))
    }
}

/// An inset as the database's manifest records it: where it lies and which inset manifest
/// it is.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InsetRecord {
    /// Name, parent, factor and window of parent cells.
    #[serde(flatten)]
    pub spec: InsetSpec,
    /// Lower-case hex SHA-256 of the inset's `manifest.json` file as committed with this one.
    pub manifest_sha256: String,
}

/// Units of a database.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Units {
    /// `metre` or `degree`: the CRS's horizontal unit.
    pub horizontal: String,
    /// Always `metre`.
    pub vertical: String,
}

/// A geographic position in degrees.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LatLon {
    /// Latitude, degrees north.
    pub latitude_deg: f64,
    /// Longitude, degrees east.
    pub longitude_deg: f64,
}

/// One layer file of the database.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Layer {
    /// File name relative to the database directory.
    pub file: String,
    /// What it holds: `elevation` (float32 m), `colour` (RGBA8), `buildings` (GeoJSON), ...
    pub kind: String,
    /// Lower-case hex SHA-256 of the file.
    pub sha256: String,
    /// Number of nodata cells (raster layers).
    #[serde(skip_serializing_if = "Option::is_none", default)]
    pub nodata_cells: Option<u64>,
}

/// A voxel object placed in the scene (by `dbms place`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PlacedObject {
    /// The placement's id: unique in the database, never reused, kept when it moves
    /// (`dbms place --move ID`). Manifests written before ids get them in placement order.
    #[serde(default)]
    pub id: u64,
    /// Object file relative to the database directory.
    pub file: String,
    /// SHA-256 of the object file.
    pub sha256: String,
    /// World position of the object's anchor, the centre of the bottom face of its voxel grid
    /// (`VoxelObject::anchor`): CRS units; z in metres, absolute.
    pub x: f64,
    /// See `x`.
    pub y: f64,
    /// See `x`.
    pub z: f64,
    /// Rotation about the vertical axis, degrees clockwise from north (0 = object's +y points north).
    pub heading_deg: f64,
    /// Size factor about the anchor (> 0): voxel edge and every voxel's offset from the anchor
    /// times this. 1 (the default) is left out of the manifest.
    #[serde(default = "unit_scale", skip_serializing_if = "is_unit_scale")]
    pub scale: f64,
}

impl PlacedObject {
    /// ` scale K` when the scale is not 1, else nothing: for one-line summaries.
    pub fn scale_note(&self) -> String {
        match self.scale {
            1.0 => String::new(),
            k => format!(" scale {k}"),
        }
    }
}

fn unit_scale() -> f64 {
    1.0
}

fn is_unit_scale(v: &f64) -> bool {
    *v == 1.0
}

/// Inputs and tool that made the database.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Provenance {
    /// Input files with their role and SHA-256.
    pub inputs: Vec<InputFile>,
    /// Version of dbms that created the database.
    pub dbms_version: String,
}

/// An input file of a stage.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct InputFile {
    /// What the file was used as (`dem`, `ortho`, `footprints`, ...).
    pub role: String,
    /// The path as given on the command line.
    pub path: String,
    /// Lower-case hex SHA-256 of the file's bytes.
    pub sha256: String,
}

/// A stage that has run on the database.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Stage {
    /// Subcommand name (`ingest`, `shadow-height`, `place`, `pyramid`, ...).
    pub name: String,
    /// The command line, as argv.
    pub command_line: Vec<String>,
    /// dbms version that ran it.
    pub dbms_version: String,
    /// Stage-specific parameters and results.
    pub params: serde_json::Value,
}

impl Stage {
    /// A stage record for the running dbms with the process's own command line.
    pub fn now(name: &str, params: serde_json::Value) -> Stage {
        Stage {
            name: name.to_string(),
            command_line: std::env::args().collect(),
            dbms_version: env!("CARGO_PKG_VERSION").to_string(),
            params,
        }
    }
}

/// The directory of a database's insets: inset `NAME` is the database `insets/NAME/`.
pub const INSETS_DIR: &str = "insets";

/// The lock file in a database directory. A [`crate::db::Change`] holds an exclusive advisory
/// lock (`flock`) on it; it is never removed (removing it would let two writers lock two files).
pub const LOCK_FILE: &str = ".dbms.lock";

impl Manifest {
    /// Read and check the manifest of database directory `dir`: its format and version, its
    /// checksum, and that it names only files inside the directory.
    pub fn read(dir: &Path) -> Result<Manifest> {
        let path = dir.join(MANIFEST_FILE);
        if dir.exists() && !dir.is_dir() {
            return Err(Error::file(dir, "is a file, not a database directory")
                .fix("give the directory `dbms ingest -o DIR` made"));
        }
        if !dir.is_dir() {
            return Err(Error::file(dir, "no such database directory")
                .fix("create it with `dbms ingest ... -o DIR`"));
        }
        if std::fs::symlink_metadata(&path).is_err() {
            return Err(Error::file(dir, "not a dbms database (no manifest.json)")
                .fix("create it with `dbms ingest ... -o DIR`"));
        }
        // Placements make it grow: a data file's cap, and never a FIFO or a device.
        let text = crate::reading::read_text(&path)?;
        let mut manifest: Manifest = serde_json::from_str(&text).map_err(|e| {
            Error::file(&path, format!("not a valid dbms manifest: {e}"))
                .fix("re-create the database with `dbms ingest`")
        })?;
        if manifest.format != FORMAT_NAME {
            return Err(Error::file(
                &path,
                format!("format is {:?}, not {FORMAT_NAME:?}", manifest.format),
            ));
        }
        if manifest.format_version > FORMAT_VERSION {
            return Err(Error::file(
                &path,
                format!(
                    "format version {} is newer than this dbms reads ({FORMAT_VERSION})",
                    manifest.format_version
                ),
            )
            .fix("upgrade dbms"));
        }
        if let Some(sum) = &manifest.checksum {
            if *sum != manifest.content_sha256() {
                return Err(Error::file(
                    &path,
                    "was changed outside dbms or is corrupt: its checksum does not match its content",
                )
                .fix("undo the edit, or re-create the database with `dbms ingest`"));
            }
        }
        manifest.number_placements();
        manifest.check_insets().map_err(|e| {
            Error::file(&path, format!("names a bad inset: {}", e.problem))
                .fix("re-create the database with `dbms ingest`")
        })?;
        if let Some((file, _)) = manifest.files().find(|(f, _)| !inside(f)) {
            return Err(Error::file(
                &path,
                format!("names {file:?}, a file outside the database directory"),
            )
            .fix("re-create the database with `dbms ingest`"));
        }
        Ok(manifest)
    }

    /// The insets' specifications, in the manifest's order (parents first).
    pub fn inset_specs(&self) -> Vec<InsetSpec> {
        self.insets.iter().map(|r| r.spec.clone()).collect()
    }

    /// An error unless every inset has a plain name, its own, and a grid: its parents are
    /// earlier insets, its window inside its parent ([`crate::inset::check_new`] against the
    /// insets before it).
    fn check_insets(&self) -> Result<()> {
        let specs = self.inset_specs();
        for (k, spec) in specs.iter().enumerate() {
            crate::inset::check_new(spec, &specs[..k], &self.grid)?;
        }
        Ok(())
    }

    /// Give every placement without an id (from a dbms before ids) a new one, in placement
    /// order.
    fn number_placements(&mut self) {
        let largest = self.objects.iter().map(|o| o.id).max().unwrap_or(0);
        self.last_placement_id = self.last_placement_id.max(largest);
        for k in 0..self.objects.len() {
            if self.objects[k].id == 0 {
                self.objects[k].id = self.new_placement_id();
            }
        }
    }

    /// A placement id never given before in this database (ids start at 1).
    pub fn new_placement_id(&mut self) -> u64 {
        self.last_placement_id += 1;
        self.last_placement_id
    }

    /// Whether the database owns file `name` of its directory: the manifest, the lock, or a
    /// file the manifest names.
    pub fn owns(&self, name: &str) -> bool {
        name == MANIFEST_FILE
            || name == LOCK_FILE
            || (name == INSETS_DIR && !self.insets.is_empty())
            || self.files().any(|(f, _)| f == name)
    }
}

/// Lower-case hex of `bytes`.
pub(crate) fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// Whether `file` (as a manifest names it) is a relative path of plain names: inside the
/// database directory.
fn inside(file: &str) -> bool {
    let p = Path::new(file);
    !file.is_empty()
        && p.components()
            .all(|c| matches!(c, std::path::Component::Normal(_)))
}
