//! The database as a transaction target (issue 14): one writer at a time, changes that never
//! lose each other, a kill at any step of the commit protocol leaving a database that
//! verifies, a manifest that cannot be edited or point outside its directory unnoticed, and
//! re-ingest that keeps what later stages added. See docs/database.md.

use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
#[path = "support/cli.rs"]
mod cli;
use cli::{dbms_in, dbms_in_within};

fn ok(dir: &Path, args: &[&str]) -> Output {
    let out = dbms_in(dir, args);
    assert!(
        out.status.success(),
        "dbms {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

/// `ingest` of the scene into `db`.
const INGEST: &[&str] = &[
    "-q",
    "ingest",
    "--dem",
    "s/dem.tif",
    "--ortho",
    "s/ortho.tif",
    "-o",
    "db",
];

/// `shadow-height --apply` of the scene's footprints into `db`.
const APPLY: &[&str] = &[
    "-q",
    "shadow-height",
    "--db",
    "db",
    "--footprints",
    "s/buildings.geojson",
    "--sun-elevation",
    "40",
    "--sun-azimuth",
    "135",
    "--photo-encoding",
    "linear",
    "--apply",
    "-o",
    "h.geojson",
];

fn manifest(db: &Path) -> Value {
    serde_json::from_str(&std::fs::read_to_string(db.join("manifest.json")).unwrap()).unwrap()
}

/// The names in `dir`, sorted.
fn names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

/// A small sample scene ingested into `db`, a cone object `tree.dvox`, and a place inside it.
struct Scene {
    dir: tempfile::TempDir,
    at: (f64, f64),
}

impl Scene {
    fn new() -> Scene {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        ok(d, &["-q", "sample", "--size", "160", "-o", "s"]);
        ok(d, INGEST);
        ok(
            d,
            &[
                "-q",
                "object",
                "cone",
                "--height",
                "6",
                "--radius",
                "2",
                "--voxel",
                "0.5",
                "-o",
                "tree.dvox",
            ],
        );
        let g = &manifest(&d.join("db"))["grid"];
        let t = &g["transform"];
        let at = (
            t["origin_x"].as_f64().unwrap() + 20.0,
            t["origin_y"].as_f64().unwrap() - 20.0,
        );
        Scene { dir, at }
    }

    fn path(&self) -> &Path {
        self.dir.path()
    }

    fn db(&self) -> PathBuf {
        self.path().join("db")
    }

    /// `dbms place` argv for the tree at the scene's place plus `dx` metres east.
    fn place_args(&self, dx: f64) -> Vec<String> {
        ["-q", "place", "--db", "db", "--object", "tree.dvox", "--at"]
            .iter()
            .map(|s| s.to_string())
            .chain([format!("{},{}", self.at.0 + dx, self.at.1)])
            .collect()
    }

    /// Place the tree `dx` metres east of the scene's place.
    fn place(&self, dx: f64) {
        let out = Command::new(env!("CARGO_BIN_EXE_dbms"))
            .args(self.place_args(dx))
            .current_dir(self.path())
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
    }

    fn verify(&self) {
        ok(self.path(), &["-q", "info", "db", "--verify"]);
    }
}

#[test]
fn twenty_parallel_places_keep_all_twenty() {
    let s = Scene::new();
    let children: Vec<_> = (0..20)
        .map(|k| {
            Command::new(env!("CARGO_BIN_EXE_dbms"))
                .args(s.place_args(k as f64))
                .current_dir(s.path())
                .spawn()
                .unwrap()
        })
        .collect();
    for c in children {
        let out = c.wait_with_output().unwrap();
        assert!(out.status.success());
    }
    let m = manifest(&s.db());
    let xs: Vec<f64> = m["objects"]
        .as_array()
        .unwrap()
        .iter()
        .map(|o| o["x"].as_f64().unwrap() - s.at.0)
        .collect();
    assert_eq!(xs.len(), 20, "placements lost: {xs:?}");
    s.verify();
}

#[test]
fn a_writer_waits_for_the_lock_or_says_who_holds_it() {
    let s = Scene::new();
    let lock = std::fs::OpenOptions::new()
        .write(true)
        .open(s.db().join(".dbms.lock"))
        .unwrap();
    lock.lock().unwrap();
    let args: Vec<String> = ["--wait", "0.2"]
        .iter()
        .map(|a| a.to_string())
        .chain(s.place_args(0.0))
        .collect();
    let out = Command::new(env!("CARGO_BIN_EXE_dbms"))
        .args(&args)
        .current_dir(s.path())
        .output()
        .unwrap();
    assert!(!out.status.success());
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("another dbms is changing this database") && err.contains("--wait"),
        "{err}"
    );
    assert_eq!(err.trim().lines().count(), 1, "{err}");
    lock.unlock().unwrap();
    s.place(0.0);
}

/// Issue 14, defect 11: the heights file is written in full before `--apply` changes the
/// database. When it cannot be (a full disk, injected by `DBMS_FAULT`), the run fails in one line
/// with the database unchanged — not buildings applied and no heights file.
#[test]
fn a_heights_file_that_cannot_be_written_stops_the_apply() {
    let s = Scene::new();
    let before = manifest(&s.db());
    let out = Command::new(env!("CARGO_BIN_EXE_dbms"))
        .args(APPLY)
        .current_dir(s.path())
        .env("DBMS_FAULT", "enospc:h.geojson")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.starts_with("dbms: error: h.geojson: no space left on the device")
            && err.trim_end().lines().count() == 1,
        "{err}"
    );
    assert_eq!(manifest(&s.db()), before, "the apply went ahead");
    assert!(!s.path().join("h.geojson").exists());
    s.verify();
}

#[test]
fn a_kill_at_any_step_of_a_change_leaves_a_database_that_verifies() {
    // Each step of the protocol (docs/database.md): the new layer written, renamed to its
    // content name, just before and just after the manifest's rename.
    let s = Scene::new();
    for point in [
        "layer-written",
        "layer-renamed",
        "before-commit",
        "after-commit",
    ] {
        let before = manifest(&s.db());
        let out = Command::new(env!("CARGO_BIN_EXE_dbms"))
            .args(APPLY)
            .current_dir(s.path())
            .env("DBMS_FAULT", point)
            .output()
            .unwrap();
        assert!(!out.status.success(), "{point}: the fault did not fire");
        s.verify();
        let after = manifest(&s.db());
        if point == "after-commit" {
            assert!(after["layers"]["buildings"].is_object(), "{point}");
        } else {
            assert_eq!(
                after, before,
                "{point}: the database changed without its commit"
            );
            assert!(
                !s.path().join("h.geojson").exists(),
                "{point}: the heights file was left"
            );
        }
    }
    // The next change clears what the killed ones left: no staging file, no unnamed layer.
    s.place(0.0);
    s.verify();
    let m = manifest(&s.db());
    let named: Vec<&str> = m["layers"]
        .as_object()
        .unwrap()
        .values()
        .map(|l| l["file"].as_str().unwrap())
        .chain(["manifest.json", ".dbms.lock", "objects"])
        .collect();
    for f in names(&s.db()) {
        assert!(named.contains(&f.as_str()), "left behind: {f}");
    }
}

#[test]
fn place_killed_at_its_commit_loses_nothing_else() {
    let s = Scene::new();
    s.place(0.0);
    let before = manifest(&s.db());
    let out = Command::new(env!("CARGO_BIN_EXE_dbms"))
        .args(s.place_args(5.0))
        .current_dir(s.path())
        .env("DBMS_FAULT", "before-commit")
        .output()
        .unwrap();
    assert!(!out.status.success());
    s.verify();
    assert_eq!(manifest(&s.db()), before);
}

#[test]
fn a_manifest_edited_by_hand_or_naming_files_outside_is_refused() {
    let s = Scene::new();
    let path = s.db().join("manifest.json");
    let text = std::fs::read_to_string(&path).unwrap();
    // One character of the origin: the next pyramid would put the tile set 100 km off.
    let edited = text.replacen("\"origin_x\": 5", "\"origin_x\": 6", 1);
    assert_ne!(edited, text);
    std::fs::write(&path, &edited).unwrap();
    let out = dbms_in(s.path(), &["info", "db", "--verify"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("checksum"), "{err}");
    // A layer path leading out of the directory, with the checksum made to match.
    let mut m: Value = serde_json::from_str(&text).unwrap();
    m["layers"]["colour"]["file"] = "../../etc/passwd".into();
    m.as_object_mut().unwrap().remove("checksum");
    std::fs::write(&path, serde_json::to_string_pretty(&m).unwrap() + "\n").unwrap();
    let out = dbms_in(s.path(), &["info", "db", "--verify"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("outside the database directory"),
        "{err}"
    );
}

#[test]
fn re_ingest_keeps_placements_and_buildings_on_the_same_grid() {
    let s = Scene::new();
    s.place(0.0);
    ok(s.path(), APPLY);
    let before = manifest(&s.db());
    let ingest = INGEST;
    ok(s.path(), ingest);
    let after = manifest(&s.db());
    assert_eq!(after["objects"], before["objects"]);
    assert_eq!(after["layers"]["buildings"], before["layers"]["buildings"]);
    s.verify();
    // On another grid (a 2 m cell) it would drop them: refused, unless --overwrite.
    let coarse = [ingest, &["--cell", "2"]].concat();
    let out = dbms_in(s.path(), &coarse);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("--overwrite"),
        "{err}"
    );
    assert_eq!(manifest(&s.db()), after);
    ok(s.path(), &[&coarse[..], &["--overwrite"]].concat());
    let m = manifest(&s.db());
    assert!(m["objects"].as_array().unwrap().is_empty() && m["layers"]["buildings"].is_null());
    s.verify();
    // Their files went with them.
    let buildings = before["layers"]["buildings"]["file"].as_str().unwrap();
    assert!(!s.db().join(buildings).exists());
}

/// `--overwrite` starts over on the same grid too: the sample Makefile re-ingests that way when
/// dbms is rebuilt, so the stages after it (which place objects again) do not add duplicates.
#[test]
fn re_ingest_with_overwrite_on_the_same_grid_starts_over() {
    let s = Scene::new();
    s.place(0.0);
    ok(s.path(), APPLY);
    let before = manifest(&s.db());
    assert_eq!(before["objects"].as_array().unwrap().len(), 1);
    ok(s.path(), &[INGEST, &["--overwrite"]].concat());
    let m = manifest(&s.db());
    assert!(m["objects"].as_array().unwrap().is_empty() && m["layers"]["buildings"].is_null());
    s.verify();
    s.place(0.0);
    assert_eq!(manifest(&s.db())["objects"].as_array().unwrap().len(), 1);
}

/// Outputs never alias inputs or special files (issue 14, defect 4): each refused in one line,
/// with what was there left as it was.
#[test]
fn outputs_that_would_destroy_something_are_refused() {
    let s = Scene::new();
    let d = s.path();
    ok(d, &["-q", "pyramid", "--db", "db", "-o", "t.dbt"]);
    let tiles = std::fs::read(d.join("t.dbt")).unwrap();
    let m = manifest(&s.db());
    let elevation = format!("db/{}", m["layers"]["elevation"]["file"].as_str().unwrap());
    std::fs::write(d.join("real.png"), b"keep").unwrap();
    std::os::unix::fs::symlink("real.png", d.join("link.png")).unwrap();
    assert!(Command::new("mkfifo")
        .arg(d.join("fifo.png"))
        .status()
        .unwrap()
        .success());
    let render = [
        "-q", "render", "--tiles", "t.dbt", "--top", "--size", "32x32",
    ];
    for (args, says) in [
        (vec!["-o", "t.dbt"], "also an input"),
        (vec!["-o", "v.png", "--range-out", "v.png"], "two outputs"),
        (vec!["-o", "link.png"], "symbolic link"),
        (vec!["-o", "fifo.png"], "device, FIFO"),
        (vec!["-o", "db/manifest.json"], "file of the database"),
    ] {
        let out = dbms_in(d, &[&render[..], &args[..]].concat());
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            !out.status.success() && err.contains(says),
            "{args:?}: {err}"
        );
        assert_eq!(err.trim().lines().count(), 1, "{err}");
    }
    for args in [
        vec!["pyramid", "--db", "db", "-o", "db/manifest.json"],
        vec![
            "shadows",
            "--db",
            "db",
            "--sun-elevation",
            "30",
            "--sun-azimuth",
            "200",
            "-o",
            &elevation,
        ],
    ] {
        let out = dbms_in(d, &args);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            !out.status.success() && err.contains("file of the database"),
            "{args:?}: {err}"
        );
    }
    s.verify();
    assert_eq!(manifest(&s.db()), m);
    assert_eq!(std::fs::read(d.join("t.dbt")).unwrap(), tiles);
    assert_eq!(std::fs::read(d.join("link.png")).unwrap(), b"keep");
    assert!(std::fs::symlink_metadata(d.join("link.png"))
        .unwrap()
        .file_type()
        .is_symlink());
    assert!(!d.join("v.png").exists());
}

/// Issue 40, defect 8: the leftover clean-up once removed the DEM being ingested when its name
/// had the form of a layer file (`elevation-<12 hex>.tif`, a copy of a database's layer). It
/// now clears only a directory a dbms change has written before, and never a run's input.
#[test]
fn ingest_never_removes_its_own_input_or_files_of_a_directory_that_is_no_database() {
    let s = Scene::new();
    let d = s.path();
    let layer = names(&s.db())
        .into_iter()
        .find(|f| f.starts_with("elevation-"))
        .unwrap();
    // Into a directory that is no database yet, from a layer-named copy inside it.
    std::fs::create_dir(d.join("x")).unwrap();
    std::fs::copy(s.db().join(&layer), d.join("x/elevation-0123456789ab.tif")).unwrap();
    std::fs::copy(s.db().join(&layer), d.join("x/notes-0123456789ab.txt")).unwrap();
    let ingest = |dem: &str, out: &str| {
        let args = [
            "-q",
            "ingest",
            "--dem",
            dem,
            "--ortho",
            "s/ortho.tif",
            "-o",
            out,
        ];
        ok(d, &args);
    };
    ingest("x/elevation-0123456789ab.tif", "x");
    assert!(
        d.join("x/elevation-0123456789ab.tif").exists(),
        "the input went"
    );
    assert!(
        d.join("x/notes-0123456789ab.txt").exists(),
        "a user's file went"
    );
    // Into an existing database, from a copy the manifest does not name.
    std::fs::copy(
        s.db().join(&layer),
        s.db().join("elevation-ba9876543210.tif"),
    )
    .unwrap();
    ingest("db/elevation-ba9876543210.tif", "db");
    assert!(
        s.db().join("elevation-ba9876543210.tif").exists(),
        "the input went"
    );
    s.verify();
}

/// Issue 40, defect 4 (no input makes a command block or read without bound), for the one file
/// every database command reads first: a `manifest.json` that is a FIFO or leads to
/// `/dev/zero` is refused in one line at once.
#[test]
fn a_manifest_that_is_a_fifo_or_a_device_is_refused_without_blocking() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    for (db, make) in [
        ("fifo", "mkfifo fifo/manifest.json"),
        ("zero", "ln -s /dev/zero zero/manifest.json"),
    ] {
        std::fs::create_dir(d.join(db)).unwrap();
        let made = Command::new("sh")
            .args(["-c", make])
            .current_dir(d)
            .status()
            .unwrap();
        assert!(made.success(), "{make}");
        let out = dbms_in_within(d, &["info", db], std::time::Duration::from_secs(20));
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            !out.status.success() && err.contains("not a regular file") && err.lines().count() == 1,
            "{db}: {err}"
        );
    }
}
