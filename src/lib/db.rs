//! The database directory: `manifest.json` plus layer files.
//!
//! A database is a directory `DB/` that `dbms ingest` creates and later stages extend:
//! * `manifest.json` — the one source of truth ([`Manifest`], schema `schemas/manifest.schema.json`):
//!   grid, CRS, units, the grid centre's latitude/longitude, each layer's file and SHA-256,
//!   placed objects, provenance (inputs and their SHA-256, command line, dbms version) and the
//!   stages that have run, in order.
//! * `elevation.tif` (float32 GeoTIFF, nodata −9999) and `colour.tif` (RGBA8 GeoTIFF, alpha = mask).
//!
//! Invariant: every file the manifest names exists with the recorded SHA-256, and the manifest
//! names only files inside the directory and carries the SHA-256 of its own content. A change
//! ([`Change`], from [`Database::begin`]) holds the database's write lock, reads the manifest
//! under it, writes every new layer under a new content-derived name, and commits by renaming
//! the new manifest into place — the one commit point — before removing the files it replaced.
//! So a change killed at any instant leaves either the old database or the new one, and two
//! changes never lose each other's updates. See docs/database.md.

use crate::error::{Error, Result};
use crate::grid::Grid;
use crate::inset::InsetSpec;
use crate::io::atomic::write_database_file;
use crate::io::SourceRaster;
use crate::manifest::hex;
pub use crate::manifest::{
    InputFile, InsetRecord, LatLon, Layer, Manifest, PlacedObject, Provenance, Stage, Units,
    FORMAT_NAME, FORMAT_VERSION, INSETS_DIR, LOCK_FILE, MANIFEST_FILE,
};
use crate::raster::{Colour, Elevation, Raster, RowSource};
use sha2::{Digest, Sha256};
use std::borrow::Cow;
use std::collections::BTreeMap;
use std::io::Read;
use std::path::{Path, PathBuf};

/// The layer name of the terrain elevation.
pub const ELEVATION: &str = "elevation";
/// The layer name of the orthophoto colour.
pub const COLOUR: &str = "colour";
/// The layer name of the raised buildings (GeoJSON prisms with `roof_z`, from
/// `dbms shadow-height --apply`).
pub const BUILDINGS: &str = "buildings";

/// An open database directory.
#[derive(Debug, Clone)]
pub struct Database {
    /// The database directory.
    pub dir: PathBuf,
    /// Its manifest as last read or saved.
    pub manifest: Manifest,
}

impl Database {
    /// Start a new database in `dir` (created if missing) for `grid`; nothing is written until
    /// [`save`](Self::save). An existing database there is replaced layer by layer.
    pub fn create(dir: &Path, grid: Grid, inputs: Vec<InputFile>) -> Result<Database> {
        std::fs::create_dir_all(dir)
            .map_err(|e| Error::io(dir, e).fix("choose a writable output directory"))?;
        let (cx, cy) = grid.centre();
        let centre = grid
            .crs
            .to_lat_lon(cx, cy)
            .map(|(latitude_deg, longitude_deg)| LatLon {
                latitude_deg,
                longitude_deg,
            });
        let manifest = Manifest {
            format: FORMAT_NAME.to_string(),
            format_version: FORMAT_VERSION,
            units: Units {
                horizontal: grid.crs.unit().to_string(),
                vertical: "metre".to_string(),
            },
            grid,
            centre,
            layers: BTreeMap::new(),
            objects: Vec::new(),
            last_placement_id: 0,
            insets: Vec::new(),
            provenance: Provenance {
                inputs,
                dbms_version: env!("CARGO_PKG_VERSION").to_string(),
            },
            stages: Vec::new(),
            checksum: None,
        };
        Ok(Database {
            dir: dir.to_path_buf(),
            manifest,
        })
    }

    /// Open an existing database, checking its manifest's format and version.
    pub fn open(dir: &Path) -> Result<Database> {
        Ok(Database {
            dir: dir.to_path_buf(),
            manifest: Manifest::read(dir)?,
        })
    }

    /// The database grid.
    pub fn grid(&self) -> &Grid {
        &self.manifest.grid
    }

    /// Latitude/longitude of the grid centre in degrees, when known.
    pub fn centre_lat_lon(&self) -> Option<(f64, f64)> {
        self.manifest
            .centre
            .map(|c| (c.latitude_deg, c.longitude_deg))
    }

    /// Latitude, longitude and meridian convergence at the grid centre, degrees, when the CRS
    /// allows them ([`crate::crs::Crs::grid_convergence_deg`]): where a sun model stands, and
    /// how far its true azimuths turn to lie along the grid.
    pub fn centre_on_globe(&self) -> Option<(f64, f64, f64)> {
        let (lat, lon) = self.centre_lat_lon()?;
        let (cx, cy) = self.grid().centre();
        Some((lat, lon, self.grid().crs.grid_convergence_deg(cx, cy)?))
    }

    /// The insets' specifications, parents before their children (empty: no insets).
    pub fn insets(&self) -> Vec<InsetSpec> {
        self.manifest.inset_specs()
    }

    /// The directory of inset `name`: `DB/insets/NAME/`, a database of its own.
    pub fn inset_dir(&self, name: &str) -> PathBuf {
        self.dir.join(INSETS_DIR).join(name)
    }

    /// The grid of inset `name`, derived from the base grid through its parents
    /// ([`crate::inset::grid_of`]).
    pub fn inset_grid(&self, name: &str) -> Result<Grid> {
        crate::inset::grid_of(name, &self.insets(), self.grid()).map_err(|e| e.in_file(&self.dir))
    }

    /// Open inset `name` as a database, checked against this one: its manifest is the one
    /// recorded (SHA-256) and its grid the derived one.
    pub fn open_inset(&self, name: &str) -> Result<Database> {
        let grid = self.inset_grid(name)?;
        let dir = self.inset_dir(name);
        let record = self.manifest.insets.iter().find(|r| r.spec.name == name);
        let want = &record.expect("inset_grid found it").manifest_sha256;
        let file = dir.join(MANIFEST_FILE);
        if !file.exists() || sha256_file(&file)? != *want {
            return Err(Error::file(
                &file,
                format!("is not the manifest of inset {name} that the database recorded (missing, changed or corrupt)"),
            )
            .fix("re-create the database and its insets with `dbms ingest`"));
        }
        let inset = Database::open(&dir)?;
        if *inset.grid() != grid {
            return Err(Error::file(
                &file,
                format!("its grid is not inset {name}'s grid in its parent"),
            )
            .fix("re-create the database and its insets with `dbms ingest`"));
        }
        Ok(inset)
    }

    /// Path of a layer's file, or an error naming the stage that makes it.
    pub fn layer_path(&self, name: &str) -> Result<PathBuf> {
        match self.manifest.layers.get(name) {
            Some(l) => Ok(self.dir.join(&l.file)),
            None => Err(
                Error::file(&self.dir, format!("database has no {name} layer")).fix(match name {
                    ELEVATION | COLOUR => "re-create it with `dbms ingest`",
                    BUILDINGS => "run `dbms shadow-height --apply` first",
                    _ => "run the stage that makes it first",
                }),
            ),
        }
    }

    /// Read the terrain elevation layer (metres, NaN = nodata), checked against the grid.
    pub fn read_elevation(&self) -> Result<Elevation> {
        self.read_layer(ELEVATION, |s| s.to_elevation())
    }

    /// Read the colour layer (RGBA8, alpha 0 = nodata), checked against the grid.
    pub fn read_colour(&self) -> Result<Colour> {
        self.read_layer(COLOUR, SourceRaster::into_colour)
    }

    /// Read a raster layer and check it lies on the database grid.
    fn read_layer<T>(
        &self,
        name: &str,
        convert: impl FnOnce(SourceRaster) -> Result<Raster<T>>,
    ) -> Result<Raster<T>> {
        let path = self.layer_path(name)?;
        let layer = convert(crate::io::read_raster(&path)?).map_err(|e| e.in_file(&path))?;
        let (g, want) = (&layer.grid, self.grid());
        if (g.width, g.height) != (want.width, want.height) {
            return Err(Error::file(
                &path,
                format!(
                    "is {}x{} cells but the database grid is {}x{}",
                    g.width, g.height, want.width, want.height
                ),
            )
            .fix("re-create the database with `dbms ingest`"));
        }
        Ok(layer)
    }

    /// The elevation layer read band by band ([`LayerRows`]): for streaming a grid larger than
    /// memory. Checked against the grid now; each band converts as [`read_elevation`](Self::read_elevation) does,
    /// except that a band may be all nodata.
    pub fn elevation_rows(&self) -> Result<LayerRows<f32>> {
        self.layer_rows(ELEVATION, SourceRaster::into_elevation_band)
    }

    /// The colour layer read band by band ([`LayerRows`]), as [`read_colour`](Self::read_colour) converts it.
    pub fn colour_rows(&self) -> Result<LayerRows<[u8; 4]>> {
        self.layer_rows(COLOUR, SourceRaster::into_colour)
    }

    /// A single-band byte layer (e.g. `materials`) read band by band ([`LayerRows`]).
    pub fn byte_rows(&self, name: &str) -> Result<LayerRows<u8>> {
        self.layer_rows(name, SourceRaster::into_bytes)
    }

    /// A one-band `f32` GeoTIFF outside the database but on its grid (same size and corner
    /// transform), e.g. the temperature map `dbms thermal` writes, read band by band; the
    /// declared nodata becomes NaN.
    pub fn values_on_grid(&self, path: &Path) -> Result<LayerRows<f32>> {
        let grid = self.grid();
        let probe = crate::io::geotiff::read_rows(path, 0..1.min(grid.height))?;
        let (want, have) = (&grid.transform, &probe.grid.transform);
        let (w, h) = (grid.width, grid.height);
        if crate::io::geotiff::size(path)? != (w, h) || want != have {
            return Err(Error::file(
                path,
                format!(
                    "is not on the database grid ({w}x{h} cells of {} m from {:.3}, {:.3})",
                    want.cell_x, want.origin_x, want.origin_y
                ),
            )
            .fix("make it from this database (dbms thermal, dbms radar), or warp it onto the grid with gdalwarp"));
        }
        // Size and transform are the grid's: the width check of `rows_of` has nothing to add.
        Ok(LayerRows {
            path: path.to_path_buf(),
            grid: grid.clone(),
            convert: SourceRaster::into_elevation_band,
        })
    }

    fn layer_rows<T>(
        &self,
        name: &str,
        convert: fn(SourceRaster) -> Result<Raster<T>>,
    ) -> Result<LayerRows<T>> {
        self.rows_of(self.layer_path(name)?, convert)
    }

    fn rows_of<T>(
        &self,
        path: PathBuf,
        convert: fn(SourceRaster) -> Result<Raster<T>>,
    ) -> Result<LayerRows<T>> {
        let rows = LayerRows {
            path,
            grid: self.grid().clone(),
            convert,
        };
        // The first row says whether the file is readable and as wide as the grid; the height
        // is checked by every band that reaches the end.
        let probe = crate::io::geotiff::read_rows(&rows.path, 0..1.min(rows.grid.height))?;
        if probe.grid.width != rows.grid.width {
            return Err(Error::file(
                &rows.path,
                format!(
                    "is {} cells wide but the database grid is {}",
                    probe.grid.width, rows.grid.width
                ),
            )
            .fix("re-create the database with `dbms ingest`"));
        }
        Ok(rows)
    }

    /// Record a layer file that is already written inside the directory (hashes it now).
    pub fn set_layer(
        &mut self,
        name: &str,
        kind: &str,
        file: &str,
        nodata_cells: Option<u64>,
    ) -> Result<()> {
        let sha256 = sha256_file(&self.dir.join(file))?;
        self.manifest.layers.insert(
            name.to_string(),
            Layer {
                file: file.to_string(),
                kind: kind.to_string(),
                sha256,
                nodata_cells,
            },
        );
        Ok(())
    }

    /// Append a stage record (saved with the next [`save`](Self::save)).
    pub fn record_stage(&mut self, stage: Stage) {
        self.manifest.stages.push(stage);
    }

    /// Names of the stages that have run, in order.
    pub fn stages_run(&self) -> Vec<&str> {
        self.manifest
            .stages
            .iter()
            .map(|s| s.name.as_str())
            .collect()
    }

    /// Write `manifest.json` atomically, with its checksum. Stages change a database through a
    /// [`Change`] ([`Database::begin`]), which locks it and calls this as its commit; a
    /// database built by hand (tests) may call it directly.
    pub fn save(&mut self) -> Result<()> {
        self.manifest.checksum = Some(self.manifest.content_sha256());
        write_database_file(
            &self.dir.join(MANIFEST_FILE),
            self.manifest.text().as_bytes(),
        )
    }

    /// Whether `name` (a file name in the database directory) is one of the database's own
    /// files: its manifest, its lock, or a file the manifest names.
    pub fn owns(&self, name: &str) -> bool {
        self.manifest.owns(name)
    }

    /// Check every layer and object file against its recorded SHA-256, and every inset as a
    /// database of its own ([`open_inset`](Self::open_inset), then its files); the first
    /// mismatch is an error. (The manifest's own checksum and file names were checked by
    /// [`Database::open`].)
    pub fn verify(&self) -> Result<()> {
        for spec in self.insets() {
            self.open_inset(&spec.name)?.verify()?;
        }
        for (file, sha) in self.manifest.files() {
            let path = self.dir.join(file);
            if &sha256_file(&path)? != sha {
                return Err(Error::file(
                    &path,
                    "checksum does not match the manifest (file changed or corrupt)",
                )
                .fix("re-run the stage that wrote it"));
            }
        }
        Ok(())
    }
}

/// Prefix of the files a [`Change`] is still writing: what a killed change leaves behind, and
/// the next change removes.
const STAGING_PREFIX: &str = ".dbms-stage-";

/// A change to a database under its write lock: read the manifest, write layers, commit.
///
/// Invariant: until [`Change::commit`] the database on disk is the one the change began from:
/// new layers go to new files, named by their content (`buildings-1a2b3c4d5e6f.geojson`); the
/// commit renames the new manifest into place and only then removes the files it no longer
/// names. Dropped without a commit (an error), it removes what it wrote.
pub struct Change {
    /// The database as read under the lock, changed by the caller and saved by the commit.
    pub db: Database,
    /// The files the manifest named when the change began.
    before: Vec<String>,
    /// The insets the manifest named when the change began.
    before_insets: Vec<String>,
    /// Files this change created (removed if it is dropped uncommitted).
    written: Vec<PathBuf>,
    /// Inset directories this change created (removed if it is dropped uncommitted).
    written_dirs: Vec<PathBuf>,
    /// What the change may remove of the files it did not write.
    leftovers: Leftovers,
    committed: bool,
    _lock: std::fs::File,
}

impl Database {
    /// Begin a change to the database in `dir`: wait up to `wait` for its write lock, clear
    /// what killed changes left (never one of the run's `inputs`, which a user may keep in
    /// the database's directory), and read the manifest as it is now.
    pub fn begin(dir: &Path, wait: std::time::Duration, inputs: &[&Path]) -> Result<Change> {
        if !dir.is_dir() {
            Database::open(dir)?; // the one-line error for a missing directory or a file
        }
        let lock = lock(dir, wait)?;
        Change::new(Database::open(dir)?, lock, Leftovers::clear(inputs))
    }

    /// Begin a change that creates the database in `dir` (made if missing) for `grid`, or
    /// replaces the one there: the change's `db` is the database there when there is one, else
    /// a new one with no layers. The caller decides what to keep.
    pub fn begin_create(
        dir: &Path,
        grid: Grid,
        inputs: Vec<InputFile>,
        wait: std::time::Duration,
    ) -> Result<(Change, Option<Manifest>)> {
        std::fs::create_dir_all(dir)
            .map_err(|e| Error::io(dir, e).fix("choose a writable output directory"))?;
        // A directory no dbms change has written before (no manifest, no lock file) holds
        // nothing of ours to clear: a file there named like a layer is the user's.
        let ours = dir.join(MANIFEST_FILE).exists() || dir.join(LOCK_FILE).exists();
        let inputs_read: Vec<PathBuf> = inputs.iter().map(|i| PathBuf::from(&i.path)).collect();
        let leftovers = match ours {
            true => Leftovers::clear(&inputs_read),
            false => Leftovers::Keep,
        };
        let lock = lock(dir, wait)?;
        let old = dir
            .join(MANIFEST_FILE)
            .exists()
            .then(|| Database::open(dir))
            .transpose()?;
        let db = Database::create(dir, grid, inputs)?;
        if let Some(old) = &old {
            // The files of the database being replaced are removed by the commit unless kept.
            let mut change = Change::new(old.clone(), lock, leftovers)?;
            change.db = db;
            return Ok((change, Some(old.manifest.clone())));
        }
        Ok((Change::new(db, lock, leftovers)?, None))
    }
}

/// What a [`Change`] may remove of what it finds in the database directory.
enum Leftovers {
    /// Nothing: the directory was no database (a first ingest into a user's directory).
    Keep,
    /// What killed changes left and what the commit drops, except these files (canonical
    /// paths): the run's own inputs, which may lie in the directory under a layer's name.
    Clear(Vec<PathBuf>),
}

impl Leftovers {
    /// Clear, sparing `inputs` (paths as given; those that do not exist spare nothing).
    fn clear(inputs: &[impl AsRef<Path>]) -> Leftovers {
        Leftovers::Clear(
            inputs
                .iter()
                .filter_map(|p| p.as_ref().canonicalize().ok())
                .collect(),
        )
    }

    /// Whether `path` may be removed: not a run's input, nor a directory holding one.
    fn may_remove(&self, path: &Path) -> bool {
        let Leftovers::Clear(inputs) = self else {
            return false;
        };
        let Ok(path) = path.canonicalize() else {
            return true; // gone already, or a dangling name: nothing of the inputs
        };
        !inputs.iter().any(|i| i.starts_with(&path))
    }
}

/// Take `dir`'s write lock, retrying every 50 ms for up to `wait`.
fn lock(dir: &Path, wait: std::time::Duration) -> Result<std::fs::File> {
    let busy = "another dbms is changing this database";
    crate::io::lock::wait_for_lock(&dir.join(LOCK_FILE), wait, dir, busy)
}

impl Change {
    fn new(db: Database, lock: std::fs::File, leftovers: Leftovers) -> Result<Change> {
        let before: Vec<String> = db.manifest.files().map(|(f, _)| f.clone()).collect();
        let before_insets: Vec<String> = db.insets().into_iter().map(|s| s.name).collect();
        clear_leftovers(&db.dir, &before, &leftovers)?;
        clear_inset_leftovers(&db.dir, &before_insets, &leftovers)?;
        Ok(Change {
            leftovers,
            db,
            before,
            before_insets,
            written: Vec::new(),
            written_dirs: Vec::new(),
            committed: false,
            _lock: lock,
        })
    }

    /// Write layer `name` (`kind` as [`Layer::kind`]) with `fill`, which writes the whole file
    /// at the path it is given and returns its nodata cells (raster layers), and record it
    /// under a name made of `name`, its content's SHA-256 and `ext` (e.g.
    /// `elevation-1a2b3c4d5e6f.tif`).
    pub fn write_layer(
        &mut self,
        name: &str,
        kind: &str,
        ext: &str,
        fill: impl FnOnce(&Path) -> Result<Option<u64>>,
    ) -> Result<()> {
        let dir = self.db.dir.clone();
        let staging = dir.join(format!(
            "{STAGING_PREFIX}{}-{name}.{ext}",
            std::process::id()
        ));
        self.written.push(staging.clone());
        let nodata_cells = fill(&staging)?;
        fault_point("layer-written");
        let sha256 = sha256_file(&staging)?;
        let file = format!("{name}-{}.{ext}", &sha256[..12]);
        let dest = dir.join(&file);
        std::fs::rename(&staging, &dest).map_err(|e| Error::io(&dest, e))?;
        if !self.before.contains(&file) {
            self.written.push(dest);
        }
        fault_point("layer-renamed");
        self.db.manifest.layers.insert(
            name.to_string(),
            Layer {
                file,
                kind: kind.to_string(),
                sha256,
                nodata_cells,
            },
        );
        Ok(())
    }

    /// Note a file this change created in the directory (relative to it) by other means, so
    /// that an uncommitted change removes it.
    pub fn wrote(&mut self, file: &str) {
        if !self.before.iter().any(|f| f == file) {
            self.written.push(self.db.dir.join(file));
        }
    }

    /// Note that this change is creating inset `name`'s directory ([`Database::inset_dir`]),
    /// so that an uncommitted change removes it; an error when it is an inset the database
    /// already has.
    pub fn wrote_inset(&mut self, name: &str) -> Result<()> {
        if self.before_insets.iter().any(|n| n == name) {
            return Err(
                Error::file(&self.db.dir, format!("already has an inset {name}"))
                    .fix("give the new inset another name"),
            );
        }
        self.written_dirs.push(self.db.inset_dir(name));
        Ok(())
    }

    /// Commit: save the manifest (the rename that switches the database to the new state),
    /// then remove the files the old state named and the new one does not.
    pub fn commit(mut self) -> Result<()> {
        fault_point("before-commit");
        self.db.save()?;
        self.committed = true;
        fault_point("after-commit");
        let now: Vec<&String> = self.db.manifest.files().map(|(f, _)| f).collect();
        for f in self.before.iter().filter(|f| !now.contains(f)) {
            let path = self.db.dir.join(f);
            if self.leftovers.may_remove(&path) {
                let _ = std::fs::remove_file(path);
            }
        }
        let insets = self.db.insets();
        for name in &self.before_insets {
            let dir = self.db.inset_dir(name);
            if !insets.iter().any(|s| s.name == *name) && self.leftovers.may_remove(&dir) {
                let _ = std::fs::remove_dir_all(dir);
            }
        }
        Ok(())
    }
}

impl Drop for Change {
    fn drop(&mut self) {
        if !self.committed {
            for f in &self.written {
                let _ = std::fs::remove_file(f);
            }
            for d in &self.written_dirs {
                let _ = std::fs::remove_dir_all(d);
            }
        }
    }
}

/// Remove what killed changes left in `dir` (under its lock, so nobody is writing them): the
/// staging files of layers, and layer files the committed manifest does not name (`named`,
/// the files it does) — written and renamed by a change killed before its commit — except
/// what `leftovers` spares.
fn clear_leftovers(dir: &Path, named: &[String], leftovers: &Leftovers) -> Result<()> {
    let entries = std::fs::read_dir(dir).map_err(|e| Error::io(dir, e))?;
    for e in entries.flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        if (name.starts_with(STAGING_PREFIX) || (content_named(&name) && !named.contains(&name)))
            && leftovers.may_remove(&e.path())
        {
            let _ = std::fs::remove_file(e.path());
        }
    }
    Ok(())
}

/// Remove the inset directories of `dir` (under its lock) that its committed manifest does
/// not name (`named`): made by a change killed before its commit, or left by one that dropped
/// them.
fn clear_inset_leftovers(dir: &Path, named: &[String], leftovers: &Leftovers) -> Result<()> {
    let insets = dir.join(INSETS_DIR);
    let Ok(entries) = std::fs::read_dir(&insets) else {
        return Ok(()); // no insets directory: nothing to clear
    };
    for e in entries.flatten() {
        let name = e.file_name().to_string_lossy().into_owned();
        if !named.contains(&name) && leftovers.may_remove(&e.path()) {
            let path = e.path();
            let _ = match path.is_dir() {
                true => std::fs::remove_dir_all(&path),
                false => std::fs::remove_file(&path),
            };
        }
    }
    Ok(())
}

/// Whether `file` has the form of a layer file a [`Change`] writes: `name-<12 hex>.ext`.
fn content_named(file: &str) -> bool {
    let Some((stem, _ext)) = file.rsplit_once('.') else {
        return false;
    };
    stem.rsplit_once('-').is_some_and(|(name, sha)| {
        !name.is_empty()
            && sha.len() == 12
            && sha
                .bytes()
                .all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b))
    })
}

/// Abort the process here when `DBMS_FAULT` names this point: how the tests kill a change at
/// each step of its protocol (no effect otherwise).
pub fn fault_point(name: &str) {
    if std::env::var_os("DBMS_FAULT").is_some_and(|v| v == name) {
        std::process::abort();
    }
}

/// A database layer (a GeoTIFF written by `dbms ingest`) read band by band: each
/// [`read_rows`](RowSource::read_rows) decodes only the strips or tiles of its rows
/// ([`crate::io::geotiff::read_rows`]) and converts them as reading the whole layer would.
pub struct LayerRows<T> {
    path: PathBuf,
    grid: Grid,
    convert: fn(SourceRaster) -> Result<Raster<T>>,
}

impl<T: Clone + Send + Sync> RowSource<T> for LayerRows<T> {
    fn grid(&self) -> &Grid {
        &self.grid
    }

    fn read_rows(&self, row0: usize, rows: usize) -> Result<Cow<'_, [T]>> {
        assert!(
            row0 + rows <= self.grid.height,
            "rows {row0}..{} outside the grid",
            row0 + rows
        );
        let band = (self.convert)(crate::io::geotiff::read_rows(
            &self.path,
            row0..row0 + rows,
        )?)
        .map_err(|e| e.in_file(&self.path))?;
        if (band.grid.width, band.grid.height) != (self.grid.width, rows) {
            return Err(Error::file(
                &self.path,
                format!(
                    "rows {row0}..{} are {}x{} cells, not {}x{rows}",
                    row0 + rows,
                    band.grid.width,
                    band.grid.height,
                    self.grid.width
                ),
            )
            .fix("re-create the database with `dbms ingest`"));
        }
        Ok(Cow::Owned(band.data))
    }
}

/// Lower-case hex SHA-256 of a file's bytes, streamed.
pub fn sha256_file(path: &Path) -> Result<String> {
    let mut f = crate::io::open_regular(path)?;
    let mut hasher = Sha256::new();
    let mut buf = vec![0u8; 1 << 20];
    loop {
        let n = f.read(&mut buf).map_err(|e| Error::io(path, e))?;
        if n == 0 {
            break;
        }
        hasher.update(&buf[..n]);
    }
    Ok(hex(&hasher.finalize()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::crs::Crs;

    #[test]
    fn manifest_round_trips_and_checks_files() {
        let dir = tempfile::tempdir().unwrap();
        let grid = Grid::north_up(500_000.0, 3_620_000.0, 0.5, 4, 3, Crs::epsg(32614));
        let mut db = Database::create(dir.path(), grid.clone(), vec![]).unwrap();
        let c = db.manifest.centre.unwrap();
        assert!(
            (c.latitude_deg - 32.7177).abs() < 1e-3 && (c.longitude_deg + 98.99998).abs() < 1e-4
        );
        std::fs::write(dir.path().join("a.bin"), b"abc").unwrap();
        db.set_layer("a", "test", "a.bin", None).unwrap();
        assert_eq!(
            db.manifest.layers["a"].sha256,
            "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad"
        );
        db.record_stage(Stage::now("ingest", serde_json::json!({})));
        db.save().unwrap();
        let back = Database::open(dir.path()).unwrap();
        assert_eq!(back.manifest, db.manifest);
        assert_eq!(back.stages_run(), vec!["ingest"]);
        back.verify().unwrap();
        std::fs::write(dir.path().join("a.bin"), b"abd").unwrap();
        assert!(back.verify().unwrap_err().to_string().contains("checksum"));
    }

    /// Layers read band by band give exactly the rows of the whole layer, across tile rows and
    /// at the grid's end; a layer narrower than the grid is refused up front.
    #[test]
    fn layer_rows_are_the_rows_of_the_whole_layer() {
        let dir = tempfile::tempdir().unwrap();
        let grid = Grid::north_up(500_000.0, 3_620_000.0, 0.5, 300, 600, Crs::epsg(32614));
        let mut db = Database::create(dir.path(), grid.clone(), vec![]).unwrap();
        let z: Vec<f32> = (0..grid.len())
            .map(|i| {
                if i % 101 == 0 {
                    f32::NAN
                } else {
                    (i % 977) as f32 * 0.25
                }
            })
            .collect();
        let c: Vec<[u8; 4]> = (0..grid.len())
            .map(|i| {
                if i % 89 == 0 {
                    [0; 4]
                } else {
                    [i as u8, (i / 7) as u8, 3, 255]
                }
            })
            .collect();
        crate::io::geotiff::write_f32(
            &dir.path().join("elevation.tif"),
            &Raster::new(grid.clone(), z),
        )
        .unwrap();
        crate::io::geotiff::write_rgba8(
            &dir.path().join("colour.tif"),
            &Raster::new(grid.clone(), c),
        )
        .unwrap();
        db.set_layer(ELEVATION, "elevation", "elevation.tif", None)
            .unwrap();
        db.set_layer(COLOUR, "colour", "colour.tif", None).unwrap();
        let (whole_z, whole_c) = (db.read_elevation().unwrap(), db.read_colour().unwrap());
        let (rows_z, rows_c) = (db.elevation_rows().unwrap(), db.colour_rows().unwrap());
        for (row0, n) in [(0, 1), (0, 256), (200, 100), (255, 2), (590, 10), (599, 1)] {
            let want = |w: usize| row0 * w..(row0 + n) * w;
            let got_z = rows_z.read_rows(row0, n).unwrap();
            assert!(
                got_z
                    .iter()
                    .zip(&whole_z.data[want(300)])
                    .all(|(a, b)| a.to_bits() == b.to_bits()),
                "rows {row0}+{n}"
            );
            assert_eq!(
                &*rows_c.read_rows(row0, n).unwrap(),
                &whole_c.data[want(300)],
                "rows {row0}+{n}"
            );
        }
        let narrow = Grid::north_up(500_000.0, 3_620_000.0, 0.5, 299, 600, Crs::epsg(32614));
        crate::io::geotiff::write_f32(
            &dir.path().join("elevation.tif"),
            &Raster::filled(narrow, 1.0),
        )
        .unwrap();
        let e = db.elevation_rows().err().unwrap().to_string();
        assert!(
            e.contains("299 cells wide") && e.contains("dbms ingest"),
            "{e}"
        );
    }

    /// A database with inset `a` over base cells 1..3 x 1..3 at factor 2, both with one layer
    /// file: the inset's directory and record written as a change does.
    fn with_inset(dir: &Path) -> Database {
        let grid = Grid::north_up(500_000.0, 5_000_000.0, 10.0, 4, 4, Crs::epsg(32632));
        let mut db = Database::create(dir, grid.clone(), vec![]).unwrap();
        let spec = InsetSpec {
            name: "a".into(),
            parent: None,
            factor: 2,
            window: crate::inset::CellWindow {
                col0: 1,
                row0: 1,
                col1: 3,
                row1: 3,
            },
        };
        let mut inset = Database::create(&db.inset_dir("a"), spec.grid(&grid), vec![]).unwrap();
        std::fs::write(inset.dir.join("x.bin"), b"abc").unwrap();
        inset.set_layer("x", "test", "x.bin", None).unwrap();
        inset.save().unwrap();
        let manifest_sha256 = sha256_file(&inset.dir.join(MANIFEST_FILE)).unwrap();
        db.manifest.insets.push(InsetRecord {
            spec,
            manifest_sha256,
        });
        db.save().unwrap();
        db
    }

    /// Insets are databases in `insets/NAME/`, opened and verified through the base, which
    /// refuses one whose manifest is not the recorded one; a manifest without insets writes
    /// no `insets` member.
    #[test]
    fn insets_open_and_verify_through_the_base() {
        let dir = tempfile::tempdir().unwrap();
        let db = Database::open(with_inset(dir.path()).dir.as_path()).unwrap();
        assert_eq!(db.insets().len(), 1);
        let a = db.open_inset("a").unwrap();
        assert_eq!(a.grid(), &db.inset_grid("a").unwrap());
        assert_eq!((a.grid().width, a.grid().transform.cell_x), (4, 5.0));
        assert!(db.owns(INSETS_DIR));
        db.verify().unwrap();
        std::fs::write(a.dir.join("x.bin"), b"abd").unwrap();
        assert!(db
            .verify()
            .unwrap_err()
            .to_string()
            .contains("x.bin: checksum"));
        let mut a = a;
        a.save().unwrap(); // same content: same manifest
        let mut changed = Database::open(&a.dir).unwrap();
        changed.set_layer("x", "test", "x.bin", None).unwrap();
        changed.save().unwrap();
        let e = db.open_inset("a").unwrap_err().to_string();
        assert!(
            e.contains("is not the manifest of inset a that the database recorded"),
            "{e}"
        );
        assert!(db.open_inset("b").is_err());
        let plain = Database::create(dir.path(), db.grid().clone(), vec![]).unwrap();
        assert!(!plain.manifest.text().contains("insets"));
        assert!(!plain.owns(INSETS_DIR));
    }

    /// A manifest naming an inset outside `insets/` (or on no grid) is refused when opened.
    #[test]
    fn a_manifest_with_a_bad_inset_is_refused() {
        let dir = tempfile::tempdir().unwrap();
        let mut db = with_inset(dir.path());
        db.manifest.insets[0].spec.name = "../a".into();
        db.save().unwrap();
        let e = Database::open(dir.path()).unwrap_err().to_string();
        assert!(
            e.contains("names a bad inset: inset name \"../a\" is not a plain name"),
            "{e}"
        );
        db.manifest.insets[0].spec.name = "a".into();
        db.manifest.insets[0].spec.window.col1 = 9;
        db.save().unwrap();
        let e = Database::open(dir.path()).unwrap_err().to_string();
        assert!(e.contains("names a bad inset: inset a: its window"), "{e}");
    }

    /// A change that drops an inset removes its directory when it commits; one that made an
    /// inset directory and did not commit removes it; the next change removes inset
    /// directories the manifest does not name (a killed change's).
    #[test]
    fn changes_keep_inset_directories_in_step_with_the_manifest() {
        let dir = tempfile::tempdir().unwrap();
        let db = with_inset(dir.path());
        let wait = std::time::Duration::from_secs(1);
        {
            let mut change = Database::begin(dir.path(), wait, &[]).unwrap();
            assert!(change.wrote_inset("a").is_err());
            change.wrote_inset("b").unwrap();
            std::fs::create_dir_all(db.inset_dir("b")).unwrap();
        }
        assert!(!db.inset_dir("b").exists() && db.inset_dir("a").exists());
        std::fs::create_dir_all(db.inset_dir("killed")).unwrap();
        let mut change = Database::begin(dir.path(), wait, &[]).unwrap();
        assert!(!db.inset_dir("killed").exists());
        change.db.manifest.insets.clear();
        change.commit().unwrap();
        assert!(!db.inset_dir("a").exists());
        assert!(Database::open(dir.path()).unwrap().insets().is_empty());
    }

    #[test]
    fn opening_a_non_database_says_how_to_make_one() {
        let dir = tempfile::tempdir().unwrap();
        let e = Database::open(dir.path()).unwrap_err().to_string();
        assert!(
            e.contains("not a dbms database") && e.contains("dbms ingest"),
            "{e}"
        );
        std::fs::write(dir.path().join(MANIFEST_FILE), "{").unwrap();
        assert!(Database::open(dir.path())
            .unwrap_err()
            .to_string()
            .contains("not a valid dbms manifest"));
    }
}
