//! The build graph of a scene: its steps, each an ordinary `dbms` command line, what each reads
//! and writes, and whether it is up to date.
//!
//! Invariant: a step's key is a SHA-256 over the dbms version, the step's command lines, the
//! content of every input file it reads that no step writes, and the keys of the steps it runs
//! after; so a change to any of them changes the key of the step and of every step after it.
//! A step is up to date when its stamp (`<database>.steps/<step>.done`, written only after the
//! step succeeded) holds its current key and every output it writes exists. An input's hash is
//! taken again only when its size or modification time differ from those its stamp recorded.

use super::file::{ObjectSpec, Product, Scene};
use crate::choice::Choice;
use crate::db::sha256_file;
use crate::error::{Error, Result};
use crate::io::atomic::AtomicFile;
use crate::voxel::place::Variation;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};
use std::collections::BTreeMap;
use std::io::Write;
use std::path::{Path, PathBuf};

/// One step: the `dbms` command lines it runs, in order, and what it reads and writes.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Step {
    /// `ingest` (with its insets), `heights`, `object.NAME`, `place`, `product.NAME` (`products`
    /// for several).
    pub name: String,
    /// What the step is for, in a few words.
    pub does: String,
    /// `dbms` arguments of each command line (without the program name).
    pub commands: Vec<Vec<String>>,
    /// Files the step reads that no step writes: their content is part of its key.
    pub inputs: Vec<PathBuf>,
    /// Files or directories the step writes.
    pub outputs: Vec<PathBuf>,
    /// Steps that must run before it.
    pub after: Vec<String>,
    /// The step changes the database in place (ingest, heights, place): when one of these runs,
    /// all of them run again from ingest, since placing adds to what is there.
    pub writes_database: bool,
}

/// A step with its key and status, as `dbms plan` reports it.
#[derive(Debug, Clone, Serialize)]
pub struct PlannedStep {
    /// The step.
    #[serde(flatten)]
    pub step: Step,
    /// The stamp the step leaves when it runs now (JSON: its key, hex SHA-256, see the module
    /// doc).
    #[serde(rename = "key", serialize_with = "key_only")]
    stamp: Stamp,
    /// Whether the step's stamp holds its key and its outputs exist.
    pub up_to_date: bool,
    /// Why it would run; empty when up to date.
    pub why: Vec<String>,
    /// Wall-clock seconds the step took the last time `dbms build` ran it (its estimated cost:
    /// the same step on inputs of about the same size); `None` when its last run was not by
    /// `dbms build` (the Makefile's rules do not time their steps) or it never ran.
    pub last_seconds: Option<f64>,
}

fn key_only<S: serde::Serializer>(stamp: &Stamp, s: S) -> std::result::Result<S::Ok, S::Error> {
    s.serialize_str(&stamp.key)
}

impl PlannedStep {
    /// The step's key (hex SHA-256, see the module doc).
    pub fn key(&self) -> &str {
        &self.stamp.key
    }
}

/// What a stamp records: the key, and what went into it, so a later plan can say what changed.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct Stamp {
    key: String,
    version: String,
    commands: Vec<Vec<String>>,
    inputs: BTreeMap<PathBuf, InputSum>,
    after: BTreeMap<String, String>,
    /// Wall-clock seconds the step's commands took, when `dbms build` ran them (not part of
    /// the key).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    seconds: Option<f64>,
}

/// An input file's content hash, with the size and modification time it was taken at: a later
/// plan reuses the hash while both are unchanged, so a gigabyte DEM is read once a build, not
/// once a step. The key depends on the hash alone: a file touched without a change of content
/// leaves its steps up to date.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
struct InputSum {
    sha256: String,
    size: u64,
    modified_ns: u128,
}

impl InputSum {
    /// The sum of the file at `path`, reusing `known`'s hash when its size and modification
    /// time are the file's.
    fn of(path: &Path, known: Option<&InputSum>) -> Result<InputSum> {
        let meta = std::fs::metadata(path).map_err(|e| Error::io(path, e))?;
        let modified_ns = meta
            .modified()
            .ok()
            .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
            .map_or(0, |d| d.as_nanos());
        let size = meta.len();
        let sha256 = match known {
            Some(k) if k.size == size && k.modified_ns == modified_ns && modified_ns != 0 => {
                k.sha256.clone()
            }
            _ => sha256_file(path)?,
        };
        Ok(InputSum {
            sha256,
            size,
            modified_ns,
        })
    }
}

/// The directory of a scene's stamps and intermediate files (objects, heights), beside its
/// database: `<database.dir>.steps`.
pub fn steps_dir(scene: &Scene) -> PathBuf {
    let mut dir = scene.database.dir.clone().into_os_string();
    dir.push(".steps");
    PathBuf::from(dir)
}

/// The lock a build of the scene holds while it runs, in its [`steps_dir`].
pub fn lock_path(scene: &Scene) -> PathBuf {
    steps_dir(scene).join("build.lock")
}

/// Every file or directory a build of `scene` writes, each with what names it (the scene's key,
/// or the step and what the file is for): the database, each step's outputs and stamp, what
/// the pyramid derives from a product's tile file (its ledger, a region file per inset:
/// [`crate::pyramid::regions::region_file`]) and the build's lock.
pub fn written(scene: &Scene) -> Vec<(String, PathBuf)> {
    let dir = steps_dir(scene);
    let mut out = vec![("database.dir".to_string(), scene.database.dir.clone())];
    for step in steps(scene) {
        for o in step.outputs.iter().filter(|&o| *o != scene.database.dir) {
            // The product of this tile file not named yet (two may name one file).
            let key = scene
                .products
                .iter()
                .filter(|(_, p)| step.name.starts_with("product") && p.tiles == *o)
                .map(|(name, _)| format!("products.{name}.tiles"))
                .find(|key| !out.iter().any(|(k, _)| k == key));
            let Some(key) = key else {
                out.push((format!("the {} step's output", step.name), o.clone()));
                continue;
            };
            out.push((key.clone(), o.clone()));
            let ledger = crate::pyramid::incremental::ledger_path(o);
            out.push((format!("the ledger of {key}"), ledger));
            for inset in scene.insets.keys() {
                let region = crate::pyramid::regions::region_file(o, inset);
                out.push((format!("the region file of inset {inset} of {key}"), region));
            }
        }
        let stamp = stamp_path(&dir, &step.name);
        out.push((format!("the {} step's stamp", step.name), stamp));
        let begun = begun_path(&dir, &step.name);
        out.push((format!("the {} step's start record", step.name), begun));
    }
    out.push(("the build's lock".into(), lock_path(scene)));
    out
}

/// An error unless every file a build of `scene` writes ([`written`]) is its own: not another
/// output, not an input ([`Scene::inputs`]), not inside another output (the database directory)
/// and holding none. Paths are compared as absolute paths with `.` and `..` resolved lexically
/// and the part that exists resolved by the file system (symbolic links), so `db/../t.dbt` is
/// `t.dbt` also before `db` exists.
pub fn check_written(scene: &Scene) -> Result<()> {
    let inputs: Vec<(String, PathBuf, PathBuf)> = scene
        .inputs()
        .into_iter()
        .map(|(k, p)| (k, normal(&p), p))
        .collect();
    let written: Vec<(String, PathBuf, PathBuf)> = written(scene)
        .into_iter()
        .map(|(k, p)| (k, normal(&p), p))
        .collect();
    for (k, (key, out, given)) in written.iter().enumerate() {
        let others = written[..k].iter().chain(&inputs);
        let Some((other, at, _)) = others
            .clone()
            .find(|(_, p, _)| p.starts_with(out) || out.starts_with(p))
        else {
            continue;
        };
        let how = match (at == out, out.starts_with(at)) {
            (true, _) => format!("which {other} also names"),
            (false, true) => format!("inside {other}"),
            (false, false) => format!("which holds {other}"),
        };
        return Err(super::file::key_error(
            key,
            format!(
                "is {}, {how}: a step would overwrite what another reads or writes",
                given.display()
            ),
            "give each output its own path, outside the database directory",
        ));
    }
    Ok(())
}

/// `path` made absolute with `.` and `..` resolved lexically, then its longest existing
/// ancestor resolved by the file system (symbolic links) and the rest appended.
fn normal(path: &Path) -> PathBuf {
    use std::path::Component;
    let abs = std::path::absolute(path).unwrap_or_else(|_| path.to_path_buf());
    let mut lexical = PathBuf::new();
    for c in abs.components() {
        match c {
            Component::ParentDir => {
                lexical.pop();
            }
            Component::CurDir => {}
            c => lexical.push(c),
        }
    }
    let mut rest = Vec::new();
    let mut at = lexical.as_path();
    loop {
        if let Ok(real) = at.canonicalize() {
            return rest.iter().rev().fold(real, |p, c| p.join(c));
        }
        match (at.parent(), at.file_name()) {
            (Some(parent), Some(name)) => {
                rest.push(name.to_os_string());
                at = parent;
            }
            _ => return lexical,
        }
    }
}

fn s(v: impl ToString) -> String {
    v.to_string()
}

/// The steps of `scene`, in an order that runs each after the steps it needs.
pub fn steps(scene: &Scene) -> Vec<Step> {
    let mut out = vec![ingest_step(scene)];
    if let Some(heights) = heights_step(scene) {
        out.push(heights);
    }
    for (name, spec) in &scene.objects {
        out.push(object_step(name, spec, &object_file(scene, name)));
    }
    let database_steps: Vec<String> = out
        .iter()
        .filter(|s| s.writes_database)
        .map(|s| s.name.clone())
        .collect();
    let mut last = database_steps.last().expect("ingest").clone();
    if let Some(place) = place_step(scene, &last) {
        last = place.name.clone();
        out.push(place);
    }
    let (visual, sensor): (Vec<_>, Vec<_>) = scene
        .products
        .iter()
        .partition(|(_, p)| p.sensor == "visual");
    if !sensor.is_empty() {
        // The sensor products read the materials layer; the visual ones' colour fallback does
        // too, so they wait for it (the same tiles whichever step the scheduler starts first).
        out.push(materials_step(scene, &last));
        last = "materials".into();
    }
    match (visual.is_empty(), scene.shards()) {
        (true, _) => {}
        (false, 1) => out.push(product_step(scene, &visual, &last)),
        (false, n) => out.extend(sharded_steps(scene, &visual, &last, n)),
    }
    for (name, p) in sensor {
        out.extend(sensor_steps(scene, name, p, &last));
    }
    out
}

/// `dbms materials` (the `[materials]` sources, roofs and the photo's rules), after the database
/// steps `last`: what every sensor product reads.
fn materials_step(scene: &Scene, last: &str) -> Step {
    let mut cmd = vec![s("materials"), s("--db"), s(scene.database.dir.display())];
    let mut inputs = vec![];
    if let Some(m) = &scene.materials {
        for spec in m.objects.iter().flat_map(|o| o.specs()) {
            cmd.extend([s("--objects"), spec.clone()]);
        }
        for f in &m.features {
            cmd.extend([s("--features"), s(f.display())]);
        }
        if let (Some(cover), Some(legend)) = (&m.landcover, &m.legend) {
            cmd.extend([
                s("--landcover"),
                s(cover.display()),
                s("--legend"),
                legend.clone(),
            ]);
        }
        if let Some(table) = &m.table {
            cmd.extend([s("--table"), s(table.display())]);
        }
        inputs = m.inputs().into_iter().map(|(_, p)| p.clone()).collect();
    }
    Step {
        name: "materials".into(),
        does: "what each cell is made of, for the sensor products".into(),
        commands: vec![cmd],
        inputs,
        outputs: vec![],
        after: vec![last.to_string()],
        writes_database: false,
    }
}

/// A sensor product's steps after `last` (the materials step): its map (`thermal.NAME` for
/// `ir`, `radar.NAME` for `radar`; none for `nvg`) and `product.NAME`, one `dbms pyramid`
/// carrying the materials and the map (and for `nvg` the light points).
fn sensor_steps(scene: &Scene, name: &str, p: &Product, last: &str) -> Vec<Step> {
    let db = s(scene.database.dir.display());
    let map = steps_dir(scene).join(format!("{name}.{}.tif", p.sensor));
    let map_step = match (p.sensor.as_str(), &p.time, &p.radar) {
        ("ir", Some(time), _) => {
            let mut command = vec![
                s("thermal"),
                s("--db"),
                db.clone(),
                s("--time"),
                time.clone(),
            ];
            for (_, option, v) in p.conditions.weather() {
                command.extend([s(option), s(v)]);
            }
            command.extend([s("-o"), s(map.display())]);
            Some((
                "thermal",
                "surface temperatures at its time",
                command,
                "--temperature",
            ))
        }
        ("radar", _, Some(r)) => Some((
            "radar",
            "radar backscatter for its look",
            vec![
                s("radar"),
                s("--db"),
                db.clone(),
                s("--azimuth"),
                s(r.azimuth),
                s("--elevation"),
                s(r.elevation),
                s("--band"),
                r.band.clone(),
                s("-o"),
                s(map.display()),
            ],
            "--backscatter",
        )),
        _ => None,
    };
    let mut out = Vec::new();
    let mut pyramid = vec![s("pyramid"), s("--db"), db, s("--materials")];
    let mut after = last.to_string();
    if let Some((kind, does, command, option)) = map_step {
        after = format!("{kind}.{name}");
        out.push(Step {
            name: after.clone(),
            does: format!("the {} product {name}'s {does}", p.sensor),
            commands: vec![command],
            inputs: vec![],
            outputs: vec![map.clone()],
            after: vec![last.to_string()],
            writes_database: false,
        });
        pyramid.extend([s(option), s(map.display())]);
    }
    if p.sensor == "radar" {
        // The normals let a radar model take its own incidence from any position later.
        pyramid.push(s("--normals"));
    }
    if let Some(lights) = &p.lights {
        pyramid.extend([s("--lights"), s(lights.display())]);
    }
    pyramid.extend([s("-o"), s(p.tiles.display())]);
    out.push(Step {
        name: format!("product.{name}"),
        does: format!("the {} tile file", p.sensor),
        commands: vec![pyramid],
        inputs: p.lights.iter().cloned().collect(),
        outputs: vec![p.tiles.clone()],
        after: vec![after],
        writes_database: false,
    });
    out
}

/// `shadow-height --apply` for the scene's buildings, after ingest; `None` without buildings.
fn heights_step(scene: &Scene) -> Option<Step> {
    let (Some(b), Some(t)) = (&scene.buildings, &scene.terrain.photo_time) else {
        return None;
    };
    let heights = steps_dir(scene).join("heights.geojson");
    let mut command = vec![
        s("shadow-height"),
        s("--db"),
        s(scene.database.dir.display()),
        s("--footprints"),
        s(b.footprints.display()),
        s("--time"),
        t.clone(),
    ];
    if let Some(e) = b.photo_encoding {
        command.extend([s("--photo-encoding"), s(e.name())]);
    }
    command.extend([s("--apply"), s("-o"), s(heights.display())]);
    Some(Step {
        name: "heights".into(),
        does: "building heights from the photo's shadows, into the database".into(),
        commands: vec![command],
        inputs: vec![b.footprints.clone()],
        outputs: vec![heights],
        after: vec!["ingest".into()],
        writes_database: true,
    })
}

/// Most `at` placements one `place` command line carries (its arguments stay far below the
/// system's limit on a command line's length, about 150 bytes each).
const AT_PER_COMMAND: usize = 1000;

/// The `place` step after the database step `last` and every object: one `dbms place` for
/// each run of `at` placements (up to [`AT_PER_COMMAND`]: one change of the database, not one
/// each, which rewrote the manifest once a placement) and one per point layer, in the scene's
/// order; `None` without placements.
fn place_step(scene: &Scene, last: &str) -> Option<Step> {
    if scene.placements.is_empty() {
        return None;
    }
    let db = s(scene.database.dir.display());
    let mut commands: Vec<Vec<String>> = Vec::new();
    let mut run: Vec<String> = Vec::new();
    let at_count = |c: &[String]| c.iter().filter(|a| *a == "--at").count();
    for p in &scene.placements {
        let object = s(object_file(scene, &p.object).display());
        match (&p.at, &p.points) {
            (Some(at), _) => {
                if run.is_empty() || at_count(&run) == AT_PER_COMMAND {
                    commands.extend((!run.is_empty()).then(|| std::mem::take(&mut run)));
                    run = vec![s("place"), s("--db"), db.clone()];
                }
                let at: Vec<String> = at.iter().map(s).collect();
                let heading = p.heading.unwrap_or(0.0);
                run.extend([s("--object"), object, s("--at"), at.join(",")]);
                run.extend([
                    s("--heading"),
                    s(heading),
                    s("--scale"),
                    s(p.scale.unwrap_or(1.0)),
                ]);
            }
            (None, Some(points)) => {
                commands.extend((!run.is_empty()).then(|| std::mem::take(&mut run)));
                let mut c = vec![s("place"), s("--db"), db.clone(), s("--object"), object];
                c.extend([s("--points"), s(points.display())]);
                if p.random_heading == Some(true) {
                    c.push(s("--random-heading"));
                }
                if let Some([lo, hi]) = p.scale_range {
                    c.extend([s("--scale-range"), format!("{lo},{hi}")]);
                }
                if let Some(seed) = p.seed.filter(|&n| n != 0) {
                    c.extend([s("--seed"), s(seed)]);
                }
                commands.push(c);
            }
            (None, None) => unreachable!("Scene::check requires at or points"),
        }
    }
    commands.extend((!run.is_empty()).then_some(run));
    // A point layer and the object files its features name themselves (read here; one that
    // cannot be read is the place step's error when it runs).
    let mut inputs: Vec<PathBuf> = Vec::new();
    for p in &scene.placements {
        if let Some(points) = &p.points {
            inputs.push(points.clone());
            let own =
                crate::voxel::place::read_points(points, Some(Path::new("")), &Variation::NONE);
            for placed in own.iter().flatten() {
                if placed.object != Path::new("") && !inputs.contains(&placed.object) {
                    inputs.push(placed.object.clone());
                }
            }
        }
    }
    let mut after = vec![last.to_string()];
    after.extend(scene.objects.keys().map(|n| format!("object.{n}")));
    Some(Step {
        name: "place".into(),
        does: format!("{} placements on the terrain", scene.placements.len()),
        commands,
        inputs,
        outputs: vec![],
        after,
        writes_database: true,
    })
}

/// The sun options of `dbms pyramid` for product `p`: `--time T`, the angles, or none.
fn sun_options(p: &Product) -> Vec<String> {
    match (&p.time, &p.sun) {
        (Some(t), _) => vec![s("--time"), t.clone()],
        (None, Some(sun)) => vec![
            s("--sun-elevation"),
            s(sun.elevation),
            s("--sun-azimuth"),
            s(sun.azimuth),
        ],
        (None, None) => vec![],
    }
}

/// The visual products built as `n` shards each, after the last database step `last`:
/// `survey` (`dbms survey`, what every shard needs of the whole database), for each product
/// `shard.NAME.I` (`dbms pyramid --shard I/N`, its part and record in the steps directory)
/// and `product.NAME` (`dbms pyramid --merge` of its parts). Shards of every product are
/// independent of each other: a scheduler runs them side by side, on one machine or many.
fn sharded_steps(scene: &Scene, visual: &[(&String, &Product)], last: &str, n: usize) -> Vec<Step> {
    let db = s(scene.database.dir.display());
    let survey = steps_dir(scene).join("survey.json");
    let mut out = vec![Step {
        name: "survey".into(),
        does: "what every shard must know of the whole database".into(),
        commands: vec![vec![
            s("survey"),
            s("--db"),
            db.clone(),
            s("-o"),
            s(survey.display()),
        ]],
        inputs: vec![],
        outputs: vec![survey.clone()],
        after: vec![last.to_string()],
        writes_database: false,
    }];
    for (name, p) in visual {
        let pyramid = || {
            let mut c = vec![s("pyramid"), s("--db"), db.clone()];
            c.extend(sun_options(p));
            c
        };
        let parts: Vec<PathBuf> = (1..=n)
            .map(|i| steps_dir(scene).join(format!("{name}.part-{i}-of-{n}.dbt")))
            .collect();
        for (i, part) in (1..=n).zip(&parts) {
            let mut c = pyramid();
            c.extend([
                s("--shard"),
                format!("{i}/{n}"),
                s("--survey"),
                s(survey.display()),
            ]);
            c.extend([s("-o"), s(part.display())]);
            out.push(Step {
                name: format!("shard.{name}.{i}"),
                does: format!("shard {i} of {n} of the visual tile file {name}"),
                commands: vec![c],
                inputs: vec![],
                outputs: vec![part.clone(), crate::pyramid::shard::record_path(part)],
                after: vec!["survey".into()],
                writes_database: false,
            });
        }
        let mut c = pyramid();
        c.push(s("--merge"));
        c.extend(parts.iter().map(|p| s(p.display())));
        c.extend([s("-o"), s(p.tiles.display())]);
        out.push(Step {
            name: format!("product.{name}"),
            does: format!("the visual tile file, merged from its {n} shards"),
            commands: vec![c],
            inputs: vec![],
            outputs: vec![p.tiles.clone()],
            after: (1..=n).map(|i| format!("shard.{name}.{i}")).collect(),
            writes_database: false,
        });
    }
    out
}

/// The pyramids of the scene's products, after the last database step `last`: one
/// `dbms pyramid` for all of them (`--product` for each after the first), so they share what
/// stands on the terrain and every cast or detection more than one needs is made once. Named
/// `product.NAME`, or `products` for several.
fn product_step(scene: &Scene, visual: &[(&String, &Product)], last: &str) -> Step {
    let mut cmd = vec![s("pyramid"), s("--db"), s(scene.database.dir.display())];
    // After an edit of buildings or placements only the pages it touches are made again.
    cmd.push(s("--incremental"));
    let mut products = visual.iter().copied();
    let (_, first) = products.next().expect("a scene with visual products");
    cmd.extend(sun_options(first));
    cmd.extend([s("-o"), s(first.tiles.display())]);
    for (_, p) in products {
        let sun = match (&p.time, &p.sun) {
            (Some(t), _) => t.clone(),
            (None, Some(sun)) => format!("{}/{}", sun.elevation, sun.azimuth),
            (None, None) => s("none"),
        };
        cmd.extend([s("--product"), format!("{}@{sun}", p.tiles.display())]);
    }
    let names: Vec<&str> = visual.iter().map(|(n, _)| n.as_str()).collect();
    Step {
        name: match names.as_slice() {
            [one] => format!("product.{one}"),
            _ => "products".into(),
        },
        does: match names.len() {
            1 => "the visual tile file".into(),
            n => format!(
                "the {n} visual tile files {}, sharing what they have in common",
                names.join(", ")
            ),
        },
        commands: vec![cmd],
        inputs: vec![],
        outputs: visual.iter().map(|(_, p)| p.tiles.clone()).collect(),
        after: vec![last.to_string()],
        writes_database: false,
    }
}

/// Where the build writes object `name`.
fn object_file(scene: &Scene, name: &str) -> PathBuf {
    steps_dir(scene)
        .join("objects")
        .join(format!("{name}.dvox"))
}

fn ingest_step(scene: &Scene) -> Step {
    let t = &scene.terrain;
    let mut cmd = vec![
        s("ingest"),
        s("--dem"),
        s(t.dem.display()),
        s("--ortho"),
        s(t.ortho.display()),
    ];
    if let Some(time) = &t.photo_time {
        cmd.extend([s("--photo-time"), time.clone()]);
    }
    if let Some(cell) = scene.database.cell {
        cmd.extend([s("--cell"), s(cell)]);
    }
    if let Some([a, b, c, d]) = scene.database.bounds {
        cmd.extend([s("--bounds"), format!("{a},{b},{c},{d}")]);
    }
    // The database is built over from its inputs: later steps add to it (placements append).
    cmd.extend([s("--overwrite"), s("-o"), s(scene.database.dir.display())]);
    let mut commands = vec![cmd];
    let mut inputs = vec![t.dem.clone(), t.ortho.clone()];
    // --overwrite drops the insets, so they are added again after it, in the same step: when
    // any database step runs, the database starts over from ingest and gets them back.
    let order = scene.inset_order().expect("Scene::check orders the insets");
    for name in &order {
        let (c, files) = inset_command(scene, name);
        commands.push(c);
        for f in files {
            if !inputs.contains(&f) {
                inputs.push(f);
            }
        }
    }
    Step {
        name: "ingest".into(),
        does: match order.len() {
            0 => "DEM and orthophoto onto the database grid".into(),
            n => format!(
                "DEM and orthophoto onto the database grid, then its {n} inset{} (parents first)",
                if n == 1 { "" } else { "s" }
            ),
        },
        commands,
        inputs,
        outputs: vec![scene.database.dir.clone()],
        after: vec![],
        writes_database: true,
    }
}

/// The `dbms ingest --inset` (or `--corridor`) command line that adds inset `name` to the
/// scene's database, and the files it reads.
fn inset_command(scene: &Scene, name: &str) -> (Vec<String>, Vec<PathBuf>) {
    let inset = &scene.insets[name];
    let (dem, ortho, time) = inset.inputs(&scene.terrain);
    let mut cmd = vec![
        s("ingest"),
        s("--dem"),
        s(dem.display()),
        s("--ortho"),
        s(ortho.display()),
    ];
    if let Some(time) = time {
        cmd.extend([s("--photo-time"), s(time)]);
    }
    let mut files = vec![dem.to_path_buf(), ortho.to_path_buf()];
    let f = inset.factor();
    match (&inset.bounds, &inset.corridor) {
        (Some([a, b, c, d]), _) => {
            cmd.extend([s("--inset"), format!("{name}:{f}:{a},{b},{c},{d}")]);
        }
        (None, Some(corridor)) => {
            cmd.extend([
                s("--corridor"),
                format!("{name}:{f}:{}", corridor.buffer),
                s("--route"),
                s(corridor.route.display()),
            ]);
            files.push(corridor.route.clone());
        }
        (None, None) => unreachable!("Scene::check requires bounds or corridor"),
    }
    if let Some(parent) = &inset.parent {
        cmd.extend([s("--inset-parent"), parent.clone()]);
    }
    cmd.extend([s("-o"), s(scene.database.dir.display())]);
    (cmd, files)
}

fn object_step(name: &str, spec: &ObjectSpec, file: &Path) -> Step {
    let mut cmd = vec![s("object")];
    match spec {
        ObjectSpec::Cone {
            height,
            radius,
            voxel,
            seed,
            vary,
        } => cmd.extend([
            s("cone"),
            s("--height"),
            s(height),
            s("--radius"),
            s(radius),
            s("--voxel"),
            s(voxel),
            s("--seed"),
            s(seed),
            s("--vary"),
            s(vary),
        ]),
        ObjectSpec::Revolve { profile, voxel } => {
            let profile: Vec<String> = profile.iter().map(|[r, z]| format!("{r}:{z}")).collect();
            cmd.extend([
                s("revolve"),
                s("--profile"),
                profile.join(","),
                s("--voxel"),
                s(voxel),
            ])
        }
    }
    cmd.extend([s("-o"), s(file.display())]);
    Step {
        name: format!("object.{name}"),
        does: "a synthetic voxel object".into(),
        commands: vec![cmd],
        inputs: vec![],
        outputs: vec![file.to_path_buf()],
        after: vec![],
        writes_database: false,
    }
}

/// Where the stamp of step `name` is, in a scene's [`steps_dir`] `dir`.
pub fn stamp_path(dir: &Path, name: &str) -> PathBuf {
    dir.join(format!("{name}.done"))
}

/// Each step of `scene` up to and including `until` (all of them when `None`), with the stamp
/// it leaves when it runs now and the stamp it left last time.
fn stamps(scene: &Scene, until: Option<&str>) -> Result<Vec<(Step, Stamp, Option<Stamp>)>> {
    let dir = steps_dir(scene);
    let mut keys: BTreeMap<String, Stamp> = BTreeMap::new();
    let mut out = Vec::new();
    for step in steps(scene) {
        let old = read_stamp(&stamp_path(&dir, &step.name));
        let stamp = stamp_of(&step, &keys, old.as_ref())?;
        keys.insert(step.name.clone(), stamp.clone());
        let last = until == Some(step.name.as_str());
        out.push((step, stamp, old));
        if last {
            break;
        }
    }
    Ok(out)
}

/// The steps of `scene` with their keys and whether each is up to date (stamps read from
/// [`steps_dir`]).
pub fn plan(scene: &Scene) -> Result<Vec<PlannedStep>> {
    let mut planned: Vec<PlannedStep> = Vec::new();
    for (step, stamp, old) in stamps(scene, None)? {
        let mut why = reasons(&stamp, old.as_ref());
        if why.is_empty() {
            if let Some(o) = step.outputs.iter().find(|o| !o.exists()) {
                why.push(format!("{} is missing", o.display()));
            }
        }
        planned.push(PlannedStep {
            up_to_date: false,
            last_seconds: old.and_then(|o| o.seconds),
            stamp,
            step,
            why,
        });
    }
    // Placing adds to the database: any of its steps running means all of them, from ingest.
    let rebuild = planned
        .iter()
        .any(|p| p.step.writes_database && !p.why.is_empty());
    for k in 0..planned.len() {
        if planned[k].why.is_empty() {
            let before: Vec<String> = planned[..k]
                .iter()
                .filter(|p| planned[k].step.after.contains(&p.step.name) && !p.up_to_date)
                .map(|p| p.step.name.clone())
                .collect();
            let p = &mut planned[k];
            if rebuild && p.step.writes_database {
                p.why
                    .push("the database is built again from ingest (placing adds to it)".into());
            } else if !before.is_empty() {
                p.why.push(format!("runs after {}", before.join(", ")));
            }
        }
        planned[k].up_to_date = planned[k].why.is_empty();
    }
    Ok(planned)
}

/// The stamp `step` would leave now, with the keys of the steps before it; `old`, the stamp it
/// left last time, lends the hashes of inputs that have not changed size or time since.
fn stamp_of(step: &Step, before: &BTreeMap<String, Stamp>, old: Option<&Stamp>) -> Result<Stamp> {
    let inputs: BTreeMap<PathBuf, InputSum> = step
        .inputs
        .iter()
        .map(|p| {
            let known = old.and_then(|o| o.inputs.get(p));
            Ok((p.clone(), InputSum::of(p, known)?))
        })
        .collect::<Result<_>>()?;
    let after: BTreeMap<String, String> = step
        .after
        .iter()
        .map(|n| (n.clone(), before[n].key.clone()))
        .collect();
    let version = env!("CARGO_PKG_VERSION").to_string();
    let mut h = Sha256::new();
    h.update(version.as_bytes());
    for c in &step.commands {
        h.update([1]);
        for a in c {
            h.update(a.as_bytes());
            h.update([0]);
        }
    }
    for (p, sum) in inputs.iter() {
        h.update(p.to_string_lossy().as_bytes());
        h.update(sum.sha256.as_bytes());
    }
    for (n, k) in after.iter() {
        h.update(n.as_bytes());
        h.update(k.as_bytes());
    }
    let key = crate::manifest::hex(&h.finalize());
    Ok(Stamp {
        key,
        version,
        commands: step.commands.clone(),
        inputs,
        after,
        seconds: None,
    })
}

fn read_stamp(path: &Path) -> Option<Stamp> {
    let text = crate::io::read_settings(path).ok()?;
    serde_json::from_str(&text).ok()
}

/// Why a step whose stamp would be `now` runs, given the stamp it left last time.
fn reasons(now: &Stamp, old: Option<&Stamp>) -> Vec<String> {
    let Some(old) = old else {
        return vec!["never built".into()];
    };
    if old.key == now.key {
        return vec![];
    }
    let mut why = Vec::new();
    if old.version != now.version {
        why.push(format!(
            "dbms {} built it, this is {}",
            old.version, now.version
        ));
    }
    if old.commands != now.commands {
        why.push("its options changed".into());
    }
    for (p, sum) in &now.inputs {
        if old.inputs.get(p).map(|o| &o.sha256) != Some(&sum.sha256) {
            why.push(format!("{} changed", p.display()));
        }
    }
    for (n, k) in &now.after {
        if old.after.get(n) != Some(k) {
            why.push(format!("{n} changed"));
        }
    }
    if why.is_empty() {
        why.push("its stamp is from another plan".into());
    }
    why
}

/// Record that step `name` of `scene` starts now (what the Makefile's rules call before the
/// step's commands): the stamp it will leave, its inputs hashed now, in
/// `<step>.begun` ([`begun_path`]) for [`stamp`] to write once the commands succeeded. An
/// input changed while the step runs is then recorded as it was when the step read it, and
/// the next plan runs the step again.
pub fn begin(scene: &Scene, name: &str) -> Result<()> {
    let (step, stamp) = stamp_now(scene, name)?;
    write_json(&begun_path(&steps_dir(scene), &step.name), &stamp)
}

/// Record that step `name` of `scene` has just run: its stamp, written atomically (what the
/// Makefile's rules call after a step; [`super::build`] writes the planned step's own). The
/// stamp is the one [`begin`] recorded when the step started, or else one taken now.
pub fn stamp(scene: &Scene, name: &str) -> Result<()> {
    let dir = steps_dir(scene);
    let (step, now) = stamp_now(scene, name)?;
    let begun = begun_path(&dir, &step.name);
    let stamp = read_stamp(&begun).unwrap_or(now);
    write_stamp(scene, &step.name, &stamp)?;
    match std::fs::remove_file(&begun) {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(Error::io(&begun, e)),
        _ => Ok(()),
    }
}

/// Step `name` of `scene` with the stamp it would leave now.
fn stamp_now(scene: &Scene, name: &str) -> Result<(Step, Stamp)> {
    let mut stamps = stamps(scene, Some(name))?;
    match stamps.pop() {
        Some((step, stamp, _)) if step.name == name => Ok((step, stamp)),
        _ => Err(Error::msg(format!("the scene has no step {name:?}"))
            .fix("dbms plan SCENE lists its steps")),
    }
}

/// Where [`begin`] records the stamp of step `name` as it started, in a scene's
/// [`steps_dir`] `dir`.
pub fn begun_path(dir: &Path, name: &str) -> PathBuf {
    dir.join(format!("{name}.begun"))
}

/// Record that the planned step `p` of `scene` has just run, taking `seconds` of wall-clock
/// time.
pub fn stamp_planned(scene: &Scene, p: &PlannedStep, seconds: f64) -> Result<()> {
    let stamp = Stamp {
        seconds: Some(seconds),
        ..p.stamp.clone()
    };
    write_stamp(scene, &p.step.name, &stamp)
}

fn write_stamp(scene: &Scene, name: &str, stamp: &Stamp) -> Result<()> {
    write_json(&stamp_path(&steps_dir(scene), name), stamp)
}

/// Write `stamp` to `path` atomically, its directory made if missing.
fn write_json(path: &Path, stamp: &Stamp) -> Result<()> {
    let dir = crate::io::atomic::output_dir(path);
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    let mut f = AtomicFile::create(path)?;
    let text = serde_json::to_string_pretty(stamp).expect("a stamp serialises");
    writeln!(f.writer(), "{text}").map_err(|e| Error::io(path, e))?;
    f.commit()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_input_is_hashed_again_only_when_its_size_or_time_changed() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("dem.tif");
        std::fs::write(&path, b"first").unwrap();
        let first = InputSum::of(&path, None).unwrap();
        assert_eq!(first.sha256, sha256_file(&path).unwrap());
        // Same size, same time, other bytes: the recorded hash is reused (no read).
        let time = std::fs::metadata(&path).unwrap().modified().unwrap();
        std::fs::write(&path, b"fir5t").unwrap();
        std::fs::File::options()
            .write(true)
            .open(&path)
            .unwrap()
            .set_modified(time)
            .unwrap();
        assert_eq!(InputSum::of(&path, Some(&first)).unwrap(), first);
        // A new time: hashed again.
        let later = time + std::time::Duration::from_secs(1);
        let f = std::fs::File::options().write(true).open(&path).unwrap();
        f.set_modified(later).unwrap();
        let again = InputSum::of(&path, Some(&first)).unwrap();
        assert_eq!(again.sha256, sha256_file(&path).unwrap());
        assert_ne!(again.sha256, first.sha256);
    }

    /// The object files a point layer's features name are inputs of the place step, so
    /// editing one places again.
    #[test]
    fn a_point_layers_own_objects_are_inputs_of_the_place_step() {
        let dir = tempfile::tempdir().unwrap();
        let points = dir.path().join("trees.geojson");
        let fc = r#"{"type": "FeatureCollection", "features": [
            {"type": "Feature", "geometry": {"type": "Point", "coordinates": [1, 2]}, "properties": {"object": "oak.dvox"}},
            {"type": "Feature", "geometry": {"type": "Point", "coordinates": [3, 4]}, "properties": {}}]}"#;
        std::fs::write(&points, fc).unwrap();
        let text = format!(
            "version = 1\n[database]\ndir = \"db\"\n[terrain]\ndem = \"d.tif\"\northo = \"o.tif\"\n\
             [objects.tree]\nkind = \"cone\"\nheight = 5\nradius = 1\nvoxel = 0.5\n\
             [[placements]]\nobject = \"tree\"\npoints = {:?}\n\
             [products.day]\nsensor = \"visual\"\ntiles = \"day.dbt\"\n",
            points.to_str().unwrap()
        );
        let scene = Scene::parse(&text).unwrap();
        let place = steps(&scene)
            .into_iter()
            .find(|s| s.name == "place")
            .unwrap();
        assert_eq!(place.inputs, [points.clone(), dir.path().join("oak.dvox")]);
    }

    /// Insets are command lines of the ingest step after its `--overwrite` (which drops them),
    /// parents first, with the terrain's inputs and photo time unless their own; their files
    /// are the step's inputs.
    #[test]
    fn insets_are_added_in_the_ingest_step_parents_first() {
        let text = "version = 1\n[database]\ndir = \"db\"\n[terrain]\ndem = \"d.tif\"\northo = \"o.tif\"\n\
             photo_time = \"2026-09-15T08:30:00Z\"\n\
             [insets.b-town]\nfactor = 4\nbounds = [0, 0, 40, 40]\n\
             [insets.a-yard]\nfactor = 2\nbounds = [10, 10, 20, 20]\nparent = \"b-town\"\northo = \"fine.tif\"\n\
             [insets.road]\nfactor = 10\ncorridor = { route = \"r.geojson\", buffer = 12.5 }\nphoto_time = \"2026-09-16T10:00:00Z\"\n\
             [products.day]\nsensor = \"visual\"\ntiles = \"day.dbt\"\n";
        let scene = Scene::parse(text).unwrap();
        let all = steps(&scene);
        let ingest = &all[0];
        assert!(ingest.writes_database && ingest.does.ends_with("its 3 insets (parents first)"));
        let lines: Vec<String> = ingest.commands.iter().map(|c| c.join(" ")).collect();
        let t = "--photo-time 2026-09-15T08:30:00Z";
        assert_eq!(
            lines,
            [
                format!("ingest --dem d.tif --ortho o.tif {t} --overwrite -o db"),
                format!("ingest --dem d.tif --ortho o.tif {t} --inset b-town:4:0,0,40,40 -o db"),
                format!("ingest --dem d.tif --ortho fine.tif {t} --inset a-yard:2:10,10,20,20 --inset-parent b-town -o db"),
                "ingest --dem d.tif --ortho o.tif --photo-time 2026-09-16T10:00:00Z --corridor road:10:12.5 --route r.geojson -o db".into(),
            ]
        );
        assert_eq!(
            ingest.inputs,
            [
                PathBuf::from("d.tif"),
                "o.tif".into(),
                "fine.tif".into(),
                "r.geojson".into()
            ]
        );
    }

    /// The materials step passes the `[materials]` sources and reads them as inputs; an ir
    /// product's thermal step passes the weather given, and only that.
    #[test]
    fn sensor_steps_carry_the_scene_s_sources_and_weather() {
        let text = "version = 1\n[database]\ndir = \"db\"\n[terrain]\ndem = \"d.tif\"\northo = \"o.tif\"\n\
             [materials]\nobjects = \"forest\"\nfeatures = [\"roads.geojson\"]\nlandcover = \"wc.tif\"\nlegend = \"esa_worldcover\"\n\
             [products.ir]\nsensor = \"ir\"\ntiles = \"ir.dbt\"\ntime = \"2026-09-15T13:00:00Z\"\n\
             conditions = { wind_m_s = 5, air_temp_c = -3.5 }\n";
        let scene = Scene::parse(text).unwrap();
        let all = steps(&scene);
        let step = |name: &str| all.iter().find(|s| s.name == name).unwrap();
        let materials = step("materials");
        assert_eq!(
            materials.commands[0][3..],
            [
                "--objects",
                "forest",
                "--features",
                "roads.geojson",
                "--landcover",
                "wc.tif",
                "--legend",
                "esa_worldcover"
            ]
        );
        assert_eq!(
            materials.inputs,
            [PathBuf::from("roads.geojson"), "wc.tif".into()]
        );
        let thermal = &step("thermal.ir").commands[0];
        let at = thermal.iter().position(|a| a == "--air-temp").unwrap();
        assert_eq!(thermal[at..at + 4], ["--air-temp", "-3.5", "--wind", "5"]);
        assert!(!thermal
            .iter()
            .any(|a| a == "--humidity" || a == "--air-range"));
    }
}
