//! `dbms plan` on a scene file: the steps, up to date or not and why, and the Makefile that runs
//! them, whose tile file is byte for byte the one the same commands give stage by stage.

#[path = "support/cli.rs"]
mod cli;

use cli::{dbms, dbms_in};
use std::path::Path;
use std::process::Command;

const SUN: &str = "2026-09-15T08:30:00Z";

/// `dbms object` arguments of the scene's tree (its `[objects.tree]`), without the output.
const TREE: [&str; 13] = [
    "-q", "object", "cone", "--height", "10", "--radius", "2.5", "--voxel", "0.5", "--seed", "1",
    "--vary", "0.2",
];

/// A scene over the sample at `scene/` (relative to the scene file): two trees, one product.
fn scene_toml(heading: f64) -> String {
    format!(
        r#"version = 1
[database]
dir = "build/db"
[terrain]
dem = "scene/dem.tif"
ortho = "scene/ortho.tif"
photo_time = "{SUN}"
[buildings]
footprints = "scene/buildings.geojson"
photo_encoding = "linear"
[objects.tree]
kind = "cone"
height = 10
radius = 2.5
voxel = 0.5
[[placements]]
object = "tree"
at = [500030, 5300030]
heading = {heading}
[[placements]]
object = "tree"
at = [500050, 5300040]
[products.day]
sensor = "visual"
tiles = "build/day.dbt"
time = "{SUN}"
"#
    )
}

fn ok(out: std::process::Output, what: &str) -> String {
    assert!(
        out.status.success(),
        "{what}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

/// The same pipeline, command by command, into `dir/manual`; returns the tile file's bytes.
fn stage_by_stage(dir: &Path, heading: f64) -> Vec<u8> {
    stage_by_stage_with(dir, heading, None)
}

/// [`stage_by_stage`], adding the inset `--inset` value `inset` right after ingest.
fn stage_by_stage_with(dir: &Path, heading: f64, inset: Option<&str>) -> Vec<u8> {
    let run = |args: &[&str]| ok(dbms_in(dir, args), &args.join(" "));
    let inputs = [
        "-q",
        "ingest",
        "--dem",
        "scene/dem.tif",
        "--ortho",
        "scene/ortho.tif",
        "--photo-time",
        SUN,
    ];
    run(&[&inputs[..], &["--overwrite", "-o", "manual/db"]].concat());
    if let Some(inset) = inset {
        run(&[&inputs[..], &["--inset", inset, "-o", "manual/db"]].concat());
    }
    run(&[
        "-q",
        "shadow-height",
        "--db",
        "manual/db",
        "--footprints",
        "scene/buildings.geojson",
        "--time",
        SUN,
        "--photo-encoding",
        "linear",
        "--apply",
        "-o",
        "manual/heights.geojson",
    ]);
    run(&[&TREE[..], &["-o", "manual/tree.dvox"]].concat());
    let h = heading.to_string();
    for (at, heading) in [("500030,5300030", h.as_str()), ("500050,5300040", "0")] {
        run(&[
            "-q",
            "place",
            "--db",
            "manual/db",
            "--object",
            "manual/tree.dvox",
            "--at",
            at,
            "--heading",
            heading,
        ]);
    }
    run(&[
        "-q",
        "pyramid",
        "--db",
        "manual/db",
        "--time",
        SUN,
        "-o",
        "manual/day.dbt",
    ]);
    std::fs::read(dir.join("manual/day.dbt")).unwrap()
}

fn make(dir: &Path) -> String {
    make_scene(dir, "scene.toml")
}

/// Run the Makefile `dbms plan SCENE --makefile` writes for `scene` in `dir`.
fn make_scene(dir: &Path, scene: &str) -> String {
    let makefile = ok(
        dbms_in(dir, &["plan", scene, "--makefile"]),
        "plan --makefile",
    );
    std::fs::write(dir.join("Makefile.scene"), makefile).unwrap();
    let out = Command::new("make")
        .args([
            "-f",
            "Makefile.scene",
            &format!("DBMS={}", env!("CARGO_BIN_EXE_dbms")),
        ])
        .current_dir(dir)
        .output()
        .expect("make is on PATH (the README's main job needs it too)");
    ok(out, "make -f Makefile.scene")
}

/// A temporary directory holding a small generated sample (`scene/`) and `scene.toml` over it.
fn sample_with_scene() -> tempfile::TempDir {
    let t = tempfile::tempdir().unwrap();
    let scene = t.path().join("scene");
    ok(
        dbms(&[
            "-q",
            "sample",
            "--size",
            "160",
            "-o",
            scene.to_str().unwrap(),
        ]),
        "sample",
    );
    std::fs::write(t.path().join("scene.toml"), scene_toml(30.0)).unwrap();
    t
}

#[test]
fn the_makefile_builds_what_the_stages_build_and_an_edit_reruns_what_depends_on_it() {
    let t = sample_with_scene();
    let dir = t.path();

    let plan = ok(dbms_in(dir, &["plan", "scene.toml"]), "plan");
    assert!(plan.starts_with("scene.toml: 5 steps, 5 to run"), "{plan}");
    assert!(plan.contains("never built"), "{plan}");

    make(dir);
    let built = std::fs::read(dir.join("build/day.dbt")).unwrap();
    assert!(
        built == stage_by_stage(dir, 30.0),
        "the scene's tile file differs from the stages'"
    );
    let plan = ok(dbms_in(dir, &["plan", "scene.toml"]), "plan");
    assert!(plan.contains("all up to date"), "{plan}");
    assert!(make(dir).contains("Nothing to be done"));

    // Moving one tree: the objects stay, the database steps and the product run again.
    std::fs::write(dir.join("scene.toml"), scene_toml(75.0)).unwrap();
    let json: serde_json::Value = serde_json::from_str(&ok(
        dbms_in(dir, &["--json", "plan", "scene.toml"]),
        "plan --json",
    ))
    .unwrap();
    let status: Vec<(String, bool)> = json["steps"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| {
            (
                s["name"].as_str().unwrap().to_string(),
                s["up_to_date"].as_bool().unwrap(),
            )
        })
        .collect();
    let want = [
        ("ingest", false),
        ("heights", false),
        ("object.tree", true),
        ("place", false),
        ("product.day", false),
    ];
    assert_eq!(status, want.map(|(n, u)| (n.to_string(), u)));
    assert_eq!(json["steps"][3]["why"][0], "its options changed");
    make(dir);
    let rebuilt = std::fs::read(dir.join("build/day.dbt")).unwrap();
    assert!(rebuilt != built, "the move changed the database");
    assert!(
        rebuilt == stage_by_stage(dir, 75.0),
        "an edit rebuilds to what a full build gives"
    );
}

#[test]
fn bad_scene_files_are_one_line_errors_naming_the_key() {
    let t = tempfile::tempdir().unwrap();
    let dir = t.path();
    let cases = [
        (
            "version = 1\n[database]\ndir = \"db\"\nfoo = 1\n",
            "line 4: unknown field `foo`",
        ),
        (
            "version = 1\n[database]\ndir = \"db\"\n",
            "missing field `terrain`",
        ),
    ];
    for (text, want) in cases {
        std::fs::write(dir.join("bad.toml"), text).unwrap();
        let out = dbms_in(dir, &["plan", "bad.toml"]);
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(
            !out.status.success() && err.contains(want) && err.contains("bad.toml"),
            "{err}"
        );
        assert_eq!(err.trim_end().lines().count(), 1, "one line: {err}");
    }
    std::fs::write(dir.join("s.toml"), scene_toml(0.0)).unwrap();
    let out = dbms_in(dir, &["plan", "s.toml"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("terrain.dem") && err.contains("does not exist"),
        "{err}"
    );
}

#[test]
fn build_runs_what_is_out_of_date_and_names_a_failing_step() {
    let t = sample_with_scene();
    let dir = t.path();
    let ran = |dir: &Path| -> Vec<String> {
        let out = ok(dbms_in(dir, &["--json", "build", "scene.toml"]), "build");
        let json: serde_json::Value = serde_json::from_str(&out).unwrap();
        let mut ran: Vec<String> = json["ran"]
            .as_array()
            .unwrap()
            .iter()
            .map(|s| s.as_str().unwrap().to_string())
            .collect();
        ran.sort();
        ran
    };
    assert_eq!(ran(dir).len(), 5);
    // Each step's time is recorded: the plan's estimate of what a rerun costs.
    let json: serde_json::Value =
        serde_json::from_str(&ok(dbms_in(dir, &["--json", "plan", "scene.toml"]), "plan")).unwrap();
    let times: Vec<f64> = json["steps"]
        .as_array()
        .unwrap()
        .iter()
        .map(|s| s["last_seconds"].as_f64().unwrap())
        .collect();
    assert!(
        times.len() == 5 && times.iter().all(|&t| t > 0.0),
        "{times:?}"
    );
    let built = std::fs::read(dir.join("build/day.dbt")).unwrap();
    assert!(
        built == stage_by_stage(dir, 30.0),
        "build gives the stages' tile file"
    );
    assert!(ran(dir).is_empty(), "an unchanged scene builds nothing");
    // Touched but not changed: the content decides, so still nothing to build.
    let later = std::time::SystemTime::now() + std::time::Duration::from_secs(5);
    let dem = std::fs::File::options()
        .write(true)
        .open(dir.join("scene/dem.tif"))
        .unwrap();
    dem.set_modified(later).unwrap();
    assert!(
        ran(dir).is_empty(),
        "a touched input with the same content builds nothing"
    );
    let text = ok(dbms_in(dir, &["build", "scene.toml"]), "build");
    assert!(text.contains("nothing to do"), "{text}");

    std::fs::write(dir.join("scene.toml"), scene_toml(75.0)).unwrap();
    let plan = ok(dbms_in(dir, &["plan", "scene.toml"]), "plan");
    assert!(
        plan.contains("4 to run (about") && plan.contains("s last time"),
        "{plan}"
    );
    assert_eq!(ran(dir), ["heights", "ingest", "place", "product.day"]);
    assert!(std::fs::read(dir.join("build/day.dbt")).unwrap() == stage_by_stage(dir, 75.0));

    // A step that fails stops the build with one line naming it; nothing after it runs.
    std::fs::write(dir.join("scene/buildings.geojson"), "not json").unwrap();
    let out = dbms_in(dir, &["build", "scene.toml"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    assert!(
        err.contains("step heights failed") && err.contains("buildings.geojson"),
        "{err}"
    );
    assert_eq!(err.trim_end().lines().count(), 1, "one line: {err}");
    let plan = ok(dbms_in(dir, &["plan", "scene.toml"]), "plan");
    assert!(plan.contains("product.day  runs"), "{plan}");
}

/// A placement by point layer places one object per point with the seeded variation the
/// command gives, and the point layer is an input: editing it rebuilds the placements.
#[test]
fn a_point_layer_placement_varies_by_seed_and_its_file_is_an_input() {
    let t = sample_with_scene();
    let dir = t.path();
    let points = |xs: &[f64]| {
        let features: Vec<serde_json::Value> = xs
            .iter()
            .map(|x| serde_json::json!({"type": "Feature", "geometry": {"type": "Point", "coordinates": [x, 5300030.0]}, "properties": {}}))
            .collect();
        let fc = serde_json::json!({"type": "FeatureCollection", "features": features});
        std::fs::write(dir.join("trees.geojson"), fc.to_string()).unwrap();
    };
    points(&[500030.0, 500040.0, 500050.0]);
    let text = scene_toml(0.0).replace(
        "at = [500030, 5300030]\nheading = 0\n",
        "points = \"trees.geojson\"\nrandom_heading = true\nscale_range = [0.5, 1.5]\nseed = 9\n",
    );
    assert_ne!(text, scene_toml(0.0));
    std::fs::write(dir.join("scene.toml"), &text).unwrap();
    ok(dbms_in(dir, &["-q", "build", "scene.toml"]), "build");
    let placed = |db: &str| -> Vec<(f64, f64)> {
        let m: serde_json::Value =
            serde_json::from_slice(&std::fs::read(dir.join(db).join("manifest.json")).unwrap())
                .unwrap();
        m["objects"]
            .as_array()
            .unwrap()
            .iter()
            .map(|o| {
                (
                    o["heading_deg"].as_f64().unwrap(),
                    o["scale"].as_f64().unwrap_or(1.0),
                )
            })
            .collect()
    };
    let built = placed("build/db");
    assert_eq!(built.len(), 4, "three points and one tree at a place");
    assert!(
        built[..3]
            .iter()
            .all(|&(h, k)| h != 0.0 && (0.5..=1.5).contains(&k)),
        "{built:?}"
    );
    assert_eq!(built[3], (0.0, 1.0));

    // The command on its own draws the same.
    let run = |args: &[&str]| ok(dbms_in(dir, args), &args.join(" "));
    run(&[
        "-q",
        "ingest",
        "--dem",
        "scene/dem.tif",
        "--ortho",
        "scene/ortho.tif",
        "-o",
        "manual",
    ]);
    run(&[&TREE[..], &["-o", "tree.dvox"]].concat());
    run(&[
        "-q",
        "place",
        "--db",
        "manual",
        "--object",
        "tree.dvox",
        "--points",
        "trees.geojson",
        "--random-heading",
        "--scale-range",
        "0.5,1.5",
        "--seed",
        "9",
    ]);
    assert_eq!(placed("manual"), built[..3]);

    let plan = ok(dbms_in(dir, &["plan", "scene.toml"]), "plan");
    assert!(plan.contains("all up to date"), "{plan}");
    points(&[500030.0, 500040.0]);
    let json: serde_json::Value =
        serde_json::from_str(&ok(dbms_in(dir, &["--json", "plan", "scene.toml"]), "plan")).unwrap();
    let place = json["steps"]
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["name"] == "place")
        .unwrap();
    assert_eq!(place["up_to_date"], false);
    assert!(
        place["why"][0]
            .as_str()
            .unwrap()
            .contains("trees.geojson changed"),
        "{place}"
    );
}

/// Two products under two suns are one step: what stands on the terrain is read once and the
/// cast for the photo's sun both need is made once (the second product's record in the
/// manifest says what it took from the first); each tile file is the one its own
/// `dbms pyramid` makes.
#[test]
fn two_products_share_what_they_have_in_common() {
    let t = sample_with_scene();
    let dir = t.path();
    let dusk = "2026-09-15T15:30:00Z";
    let text = scene_toml(30.0)
        + &format!(
            "[products.dusk]\nsensor = \"visual\"\ntiles = \"build/dusk.dbt\"\ntime = \"{dusk}\"\n"
        );
    std::fs::write(dir.join("scene.toml"), text).unwrap();
    let plan = ok(dbms_in(dir, &["plan", "scene.toml"]), "plan");
    assert!(plan.contains("  products "), "{plan}");
    ok(dbms_in(dir, &["-q", "build", "scene.toml"]), "build");
    let manifest: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("build/db/manifest.json")).unwrap())
            .unwrap();
    let stages = manifest["stages"].as_array().unwrap();
    let last = |tiles: &str| {
        stages
            .iter()
            .rev()
            .find(|s| {
                s["name"] == "pyramid" && s["params"]["tiles"].as_str().unwrap().ends_with(tiles)
            })
            .unwrap_or_else(|| panic!("a pyramid stage for {tiles}: {manifest}"))
            .clone()
    };
    let reused = |s: &serde_json::Value| -> Vec<String> {
        let list = s["params"]["reused"].as_array();
        list.map(|l| l.iter().map(|v| v.as_str().unwrap().to_string()).collect())
            .unwrap_or_default()
    };
    assert!(
        reused(&last("day.dbt")).is_empty(),
        "the first product makes all it needs"
    );
    let took = reused(&last("dusk.dbt"));
    assert!(
        took.iter()
            .any(|r| r.starts_with("what stands on the terrain"))
            && took
                .iter()
                .any(|r| r.contains("over terrain and buildings")),
        "{took:?}"
    );
    // The dusk product casts its own sun: that is not shared.
    assert_eq!(took.len(), 2, "{took:?}");
    ok(
        dbms_in(
            dir,
            &[
                "-q",
                "pyramid",
                "--db",
                "build/db",
                "--time",
                dusk,
                "-o",
                "alone.dbt",
            ],
        ),
        "pyramid",
    );
    assert!(
        std::fs::read(dir.join("alone.dbt")).unwrap()
            == std::fs::read(dir.join("build/dusk.dbt")).unwrap(),
        "a shared build gives each product's own tile file"
    );
}

/// Sensor products in a scene file: one `materials` step, a `thermal.NAME` and `radar.NAME`
/// step for the products that need a map, and each product's own `pyramid`; every tile file
/// carries its sensor's layers (and the night one its lights), and the ir tile file is byte for
/// byte what the same commands give by hand. A second plan has nothing to do.
#[test]
fn sensor_products_get_their_maps_and_layers() {
    let t = sample_with_scene();
    let dir = t.path();
    let lights = r#"{"type": "FeatureCollection", "features": [{"type": "Feature",
        "properties": {"intensity_cd": 1500, "height_m": 8},
        "geometry": {"type": "Point", "coordinates": [500040.5, 5300040.5]}}]}"#;
    std::fs::write(dir.join("lights.geojson"), lights).unwrap();
    let ir_time = "2026-09-15T13:00:00Z";
    let text = scene_toml(30.0)
        + "[materials]\nobjects = [\"forest\"]\n"
        + &format!(
            "[products.ir]\nsensor = \"ir\"\ntiles = \"build/ir.dbt\"\ntime = \"{ir_time}\"\n\
             [products.night]\nsensor = \"nvg\"\ntiles = \"build/night.dbt\"\nlights = \"lights.geojson\"\n\
             [products.sar]\nsensor = \"radar\"\ntiles = \"build/sar.dbt\"\nradar = {{ azimuth = 220, elevation = 20 }}\n"
        );
    std::fs::write(dir.join("scene.toml"), text).unwrap();
    let plan = ok(dbms_in(dir, &["plan", "scene.toml"]), "plan");
    for step in [
        "materials",
        "thermal.ir",
        "radar.sar",
        "product.ir",
        "product.night",
        "product.sar",
        "product.day",
    ] {
        assert!(plan.contains(&format!("  {step} ")), "{step}: {plan}");
    }
    ok(dbms_in(dir, &["-q", "build", "scene.toml"]), "build");
    let layers = |name: &str| {
        let r = dbms::tiles::TileReader::open(&dir.join("build").join(name), 1).unwrap();
        let names: Vec<&str> = r.info().sensor_layers().iter().map(|l| l.name()).collect();
        (names.join(","), r.info().lights.len())
    };
    assert_eq!(layers("day.dbt"), (String::new(), 0));
    assert_eq!(layers("ir.dbt"), ("material,temperature".into(), 0));
    assert_eq!(layers("night.dbt"), ("material".into(), 1));
    assert_eq!(layers("sar.dbt"), ("material,backscatter,normal".into(), 0));
    // The trees' cells are forest ([materials] objects, here a list of --objects values); the
    // ground beside them is not.
    let db = dbms::db::Database::open(&dir.join("build/db")).unwrap();
    let m = dbms::io::read_raster(&db.layer_path("materials").unwrap()).unwrap();
    let id_at = |x: f64, y: f64| {
        let (c, r) = m.grid.cell_at(x, y).unwrap();
        m.sample(r * m.grid.width + c, 0) as u8
    };
    let forest = dbms::material::table::MaterialTable::default_table().id_of("forest");
    assert_eq!(Some(id_at(500030.1, 5300030.1)), forest);
    assert_ne!(Some(id_at(500045.1, 5300030.1)), forest);
    // By hand, on the database the build made: the same ir tile file.
    let run = |args: &[&str]| ok(dbms_in(dir, args), &args.join(" "));
    run(&[
        "-q", "thermal", "--db", "build/db", "--time", ir_time, "-o", "t.tif",
    ]);
    run(&[
        "-q",
        "pyramid",
        "--db",
        "build/db",
        "--materials",
        "--temperature",
        "t.tif",
        "-o",
        "ir.dbt",
    ]);
    assert!(
        std::fs::read(dir.join("ir.dbt")).unwrap()
            == std::fs::read(dir.join("build/ir.dbt")).unwrap(),
        "the scene's ir product differs from the same commands by hand"
    );
    let again = ok(dbms_in(dir, &["plan", "scene.toml", "--json"]), "plan");
    let steps: serde_json::Value = serde_json::from_str(&again).unwrap();
    let pending: Vec<&str> = steps["steps"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|s| s["up_to_date"] == false)
        .map(|s| s["name"].as_str().unwrap())
        .collect();
    assert!(pending.is_empty(), "{pending:?}");
}

/// The inset of [`an_inset_is_added_after_ingest_and_built_as_the_stages_build_it`]: the small
/// sample's middle (with the first tree) at 4× (0.0625 m cells), as the scene declares it and
/// as `--inset` takes it.
const TOWN: (&str, &str) = (
    "[insets.town]\nfactor = 4\nbounds = [500020, 5300020, 500040, 5300044]\n",
    "town:4:500020,5300020,500040,5300044",
);

/// A scene with an inset: the ingest step adds it after its `--overwrite`, the Makefile and the
/// Snakefile both build the tile set the stages build by hand (the base file and the town's
/// region file, byte for byte; verified whole), and moving a tree starts the database over
/// from ingest with the inset added again. Built in 4 shards, it is the same tile set.
#[test]
fn an_inset_is_added_after_ingest_and_built_as_the_stages_build_it() {
    let t = sample_with_scene();
    let dir = t.path();
    let scene = |heading: f64| scene_toml(heading) + TOWN.0;
    std::fs::write(dir.join("scene.toml"), scene(30.0)).unwrap();
    let json: serde_json::Value = serde_json::from_str(&ok(
        dbms_in(dir, &["--json", "plan", "scene.toml"]),
        "plan --json",
    ))
    .unwrap();
    let ingest = &json["steps"][0];
    assert_eq!(ingest["name"], "ingest");
    let lines = ingest["commands"].as_array().unwrap();
    assert_eq!(lines.len(), 2, "{ingest}");
    assert!(lines[0].to_string().contains("--overwrite"), "{ingest}");
    assert!(lines[1].to_string().contains(TOWN.1), "{ingest}");

    let region = |d: &str| {
        let base = std::fs::read(dir.join(format!("{d}/day.dbt"))).unwrap();
        (
            base,
            std::fs::read(dir.join(format!("{d}/day.town.dbt"))).unwrap(),
        )
    };
    let by_hand = |heading: f64| {
        stage_by_stage_with(dir, heading, Some(TOWN.1));
        region("manual")
    };
    make(dir);
    let want = by_hand(30.0);
    assert!(
        region("build") == want,
        "the Makefile's tile set differs from the stages'"
    );
    let verify = ok(
        dbms_in(dir, &["tiles", "build/day.dbt", "--verify"]),
        "tiles --verify",
    );
    assert!(verify.contains("town"), "{verify}");
    let plan = ok(dbms_in(dir, &["plan", "scene.toml"]), "plan");
    assert!(plan.contains("all up to date"), "{plan}");

    // Moving a tree: ingest runs again, so the inset is added again.
    std::fs::write(dir.join("scene.toml"), scene(75.0)).unwrap();
    make(dir);
    let info: serde_json::Value =
        serde_json::from_str(&ok(dbms_in(dir, &["--json", "info", "build/db"]), "info")).unwrap();
    assert!(info.to_string().contains("\"town\""), "{info}");
    let want = by_hand(75.0);
    assert!(
        region("build") == want,
        "an edit rebuilds the whole tile set"
    );

    // Cut into 4 shards, the same tile set (the shards apply the town's cover, the merge
    // writes its region file).
    std::fs::remove_dir_all(dir.join("build")).unwrap();
    ok(
        dbms_in(dir, &["-q", "build", "scene.toml", "--shards", "4"]),
        "build --shards 4",
    );
    assert!(
        region("build") == want,
        "the sharded tile set differs from the stages'"
    );

    // The same steps as a Snakefile, from nothing: the same bytes.
    if !have_snakemake() {
        return;
    }
    std::fs::remove_dir_all(dir.join("build")).unwrap();
    let snakefile = ok(
        dbms_in(dir, &["plan", "scene.toml", "--snakefile"]),
        "plan --snakefile",
    );
    snakemake(dir, &snakefile);
    assert!(
        region("build") == want,
        "the Snakefile's tile set differs from the stages'"
    );
    let plan = ok(dbms_in(dir, &["plan", "scene.toml"]), "plan");
    assert!(plan.contains("all up to date"), "{plan}");
}

/// Run the Snakefile `snakefile` in `dir` with Snakemake, two jobs at a time, this test's dbms.
fn snakemake(dir: &Path, snakefile: &str) {
    std::fs::write(dir.join("Snakefile"), snakefile).unwrap();
    let out = Command::new("snakemake")
        .args(["-s", "Snakefile", "-j", "2", "--quiet", "--config"])
        .arg(format!("dbms={}", env!("CARGO_BIN_EXE_dbms")))
        .current_dir(dir)
        .output()
        .unwrap();
    ok(out, "snakemake");
}

/// Whether Snakemake is on PATH (under CI it must be: `.ci/run` installs it).
fn have_snakemake() -> bool {
    let ok = Command::new("snakemake").arg("--version").output().is_ok();
    if !ok {
        assert!(
            std::env::var_os("CI").is_none(),
            "snakemake is not on PATH under CI: .ci/run must install it"
        );
        eprintln!("skipped: snakemake not on PATH (apt-get install snakemake)");
    }
    ok
}

/// The scene cut into 4 shards (2 × 2 windows of the 320² grid's pages) from the command line,
/// handed to Snakemake as a Snakefile and run here with two jobs: the tile file is byte for byte
/// the stage-by-stage build's, and the stamps the rules leave are the plan's (nothing to do).
/// `dbms build --shards 4` runs the same shards itself and gives the same bytes.
#[test]
fn a_sharded_scene_through_snakemake_gives_the_same_bytes() {
    if !have_snakemake() {
        return;
    }
    let t = sample_with_scene();
    let dir = t.path();
    let want = stage_by_stage(dir, 30.0);
    let plan = ok(
        dbms_in(dir, &["plan", "scene.toml", "--shards", "4"]),
        "plan",
    );
    for step in ["survey", "shard.day.1", "shard.day.4", "product.day"] {
        assert!(plan.contains(&format!("\n  {step} ")), "{step}: {plan}");
    }
    let snakefile = ok(
        dbms_in(dir, &["plan", "scene.toml", "--shards", "4", "--snakefile"]),
        "plan --snakefile",
    );
    assert_eq!(
        snakefile.matches("\nrule shard_day_").count(),
        4,
        "{snakefile}"
    );
    snakemake(dir, &snakefile);
    assert!(
        std::fs::read(dir.join("build/day.dbt")).unwrap() == want,
        "the tile file merged from 4 shards by Snakemake is not the single build's"
    );
    let plan = ok(
        dbms_in(dir, &["plan", "scene.toml", "--shards", "4"]),
        "plan",
    );
    assert!(plan.contains("all up to date"), "{plan}");

    std::fs::remove_dir_all(dir.join("build")).unwrap();
    ok(
        dbms_in(dir, &["-q", "build", "scene.toml", "--shards", "4"]),
        "build --shards 4",
    );
    assert!(std::fs::read(dir.join("build/day.dbt")).unwrap() == want);
}

/// The placements in the manifest of the database at `db`.
fn placements(db: &Path) -> usize {
    let m: serde_json::Value =
        serde_json::from_slice(&std::fs::read(db.join("manifest.json")).unwrap()).unwrap();
    m["objects"].as_array().unwrap().len()
}

/// Two `dbms build`s of one scene started at once give the database one build gives: the
/// second waits for the first's lock and finds its steps up to date (each placement once).
#[test]
fn two_builds_at_once_give_the_database_one_build_gives() {
    let t = sample_with_scene();
    let dir = t.path();
    let start = || {
        cli::command()
            .args(["-q", "build", "scene.toml"])
            .current_dir(dir)
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap()
    };
    let (a, b) = (start(), start());
    for build in [a, b] {
        ok(build.wait_with_output().unwrap(), "build");
    }
    assert_eq!(placements(&dir.join("build/db")), 2);
    let plan = ok(dbms_in(dir, &["plan", "scene.toml"]), "plan");
    assert!(plan.contains("all up to date"), "{plan}");
    assert!(std::fs::read(dir.join("build/day.dbt")).unwrap() == stage_by_stage(dir, 30.0));
}

/// The ids of the running processes (other than `but`) whose command line names `marker`.
#[cfg(target_os = "linux")]
fn processes_naming(marker: &str, but: u32) -> Vec<(u32, String)> {
    let mut found = Vec::new();
    for e in std::fs::read_dir("/proc").unwrap().flatten() {
        let Some(pid) = e.file_name().to_str().and_then(|p| p.parse::<u32>().ok()) else {
            continue;
        };
        let Ok(cmdline) = std::fs::read(e.path().join("cmdline")) else {
            continue;
        };
        let cmdline = String::from_utf8_lossy(&cmdline).replace('\0', " ");
        if pid != but && cmdline.contains(marker) {
            found.push((pid, cmdline));
        }
    }
    found
}

/// A build ended by SIGTERM (what `timeout` sends) while a step runs leaves no step running:
/// each child is sent SIGTERM when the build dies. (The test holds the database's lock, so the
/// ingest step waits for it: it would outlive the build by a minute.)
#[cfg(target_os = "linux")]
#[test]
fn a_build_ended_by_sigterm_leaves_no_step_running() {
    let t = sample_with_scene();
    let dir = t.path();
    std::fs::create_dir_all(dir.join("build/db")).unwrap();
    let lock = std::fs::File::create(dir.join("build/db/.dbms.lock")).unwrap();
    lock.lock().unwrap();
    // Absolute paths in every command line: a step is a process naming the temporary directory.
    let scene = dir.join("scene.toml");
    let marker = dir.to_str().unwrap();
    let mut build = cli::command()
        .args(["-q", "build", scene.to_str().unwrap()])
        .stderr(std::process::Stdio::null())
        .spawn()
        .unwrap();
    let start = std::time::Instant::now();
    while !processes_naming(marker, build.id())
        .iter()
        .any(|(_, c)| c.contains(" ingest "))
    {
        assert!(
            start.elapsed().as_secs() < 60,
            "the ingest step never started"
        );
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    let kill = Command::new("kill")
        .args(["-TERM", &build.id().to_string()])
        .status()
        .unwrap();
    assert!(kill.success());
    build.wait().unwrap();
    std::thread::sleep(std::time::Duration::from_millis(500));
    let left = processes_naming(marker, build.id());
    for (pid, _) in &left {
        let _ = Command::new("kill")
            .args(["-KILL", &pid.to_string()])
            .status();
    }
    assert!(left.is_empty(), "steps left running: {left:?}");
}

/// A step given a build's owner (DBMS_BUILD_OWNER, TOKEN:LOCK) commits its output only while
/// that build holds its lock with that token: not once it was killed (nobody holds the lock),
/// nor once a later build took it over (another token).
#[test]
fn a_step_whose_build_has_ended_commits_nothing() {
    let t = tempfile::tempdir().unwrap();
    let dir = t.path();
    let lock = dir.join("build.lock");
    std::fs::write(&lock, "41-7").unwrap();
    let run = |token: &str| {
        cli::command()
            .env("DBMS_BUILD_OWNER", format!("{token}:{}", lock.display()))
            .args([&TREE[..], &["-o", "tree.dvox"]].concat())
            .current_dir(dir)
            .output()
            .unwrap()
    };
    let refused = |out: std::process::Output| {
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success() && err.contains("has ended"), "{err}");
        assert_eq!(err.trim_end().lines().count(), 1, "one line: {err}");
        assert!(!dir.join("tree.dvox").exists());
    };
    refused(run("41-7"));
    let held = std::fs::File::open(&lock).unwrap();
    held.lock().unwrap();
    refused(run("40-1"));
    ok(run("41-7"), "object while its build runs");
    assert!(dir.join("tree.dvox").exists());
}

/// Every file a build writes, derived ones included, is checked against the others and the
/// inputs before anything runs, with paths normalised (`db/../t.dbt` is `t.dbt` even when
/// `db` does not exist yet), and nothing goes inside the database directory.
#[test]
fn outputs_that_collide_are_refused_before_anything_runs() {
    let t = sample_with_scene();
    let dir = t.path();
    let product = |name: &str, tiles: &str| {
        format!("[products.{name}]\nsensor = \"visual\"\ntiles = \"{tiles}\"\n")
    };
    let cases = [
        // Another product's region file for the inset.
        (
            scene_toml(0.0) + TOWN.0 + &product("night", "build/day.town.dbt"),
            "day.town.dbt, which the region file of inset town of products.day.tiles also names",
        ),
        // The heights step's own file, and another product's ledger.
        (
            scene_toml(0.0) + &product("x", "build/db.steps/heights.geojson"),
            "which the heights step's output also names",
        ),
        (
            scene_toml(0.0) + &product("x", "build/day.dbt.ledger.json"),
            "the ledger of products.day.tiles also names",
        ),
        (
            scene_toml(0.0) + &product("x", "build/db.steps/place.done"),
            "which the place step's stamp also names",
        ),
        // Through a directory that does not exist yet.
        (
            scene_toml(0.0) + &product("x", "build/db/../day.dbt"),
            "which products.day.tiles also names",
        ),
        (
            scene_toml(0.0) + &product("x", "build/db/x.dbt"),
            "inside database.dir",
        ),
        (
            scene_toml(0.0) + &product("x", "scene/dem.tif"),
            "which terrain.dem also names",
        ),
    ];
    for (text, want) in cases {
        std::fs::write(dir.join("scene.toml"), &text).unwrap();
        for command in ["plan", "build"] {
            let out = dbms_in(dir, &[command, "scene.toml"]);
            let err = String::from_utf8_lossy(&out.stderr);
            assert!(!out.status.success() && err.contains(want), "{want}: {err}");
            assert_eq!(err.trim_end().lines().count(), 1, "one line: {err}");
        }
        assert!(!dir.join("build").exists(), "nothing ran: {want}");
    }
}

/// A scene's `at = [x, y, z]` stands the object at height z, as `dbms place --at X,Y,Z`
/// does; four numbers are refused in one line naming the file and the placement.
#[test]
fn a_scene_placement_at_a_height_keeps_it_and_four_numbers_are_refused() {
    let t = sample_with_scene();
    let dir = t.path();
    let text = scene_toml(0.0).replace("at = [500050, 5300040]", "at = [500050, 5300040, 7.5]");
    std::fs::write(dir.join("scene.toml"), &text).unwrap();
    let json: serde_json::Value =
        serde_json::from_str(&ok(dbms_in(dir, &["--json", "plan", "scene.toml"]), "plan")).unwrap();
    let place = json["steps"]
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["name"] == "place")
        .unwrap();
    assert!(
        place["commands"]
            .to_string()
            .contains("\"500050,5300040,7.5\""),
        "{place}"
    );
    let text = scene_toml(0.0).replace("at = [500050, 5300040]", "at = [500050, 5300040, 7, 1]");
    std::fs::write(dir.join("scene.toml"), &text).unwrap();
    let out = dbms_in(dir, &["plan", "scene.toml"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success()
            && err.contains("scene.toml")
            && err.contains("placements[1].at has 4 numbers"),
        "{err}"
    );
    assert_eq!(err.trim_end().lines().count(), 1, "one line: {err}");
}

/// `plan --begin STEP` (what the Makefile's rules run before a step) hashes the inputs when
/// the step starts: an input changed while it runs is not recorded as built by its
/// `--stamp STEP`, and the next plan runs the step again.
#[test]
fn an_input_changed_while_its_step_runs_is_not_recorded_as_built() {
    let t = sample_with_scene();
    let dir = t.path();
    ok(
        dbms_in(dir, &["plan", "scene.toml", "--begin", "heights"]),
        "--begin",
    );
    let footprints = dir.join("scene/buildings.geojson");
    let mut text = std::fs::read_to_string(&footprints).unwrap();
    text.push('\n');
    std::fs::write(&footprints, text).unwrap();
    ok(
        dbms_in(dir, &["plan", "scene.toml", "--stamp", "heights"]),
        "--stamp",
    );
    let json: serde_json::Value =
        serde_json::from_str(&ok(dbms_in(dir, &["--json", "plan", "scene.toml"]), "plan")).unwrap();
    let heights = &json["steps"][1];
    assert_eq!(heights["name"], "heights");
    assert!(
        heights["why"][0]
            .as_str()
            .unwrap()
            .ends_with("buildings.geojson changed"),
        "{heights}"
    );
    let makefile = ok(
        dbms_in(dir, &["plan", "scene.toml", "--makefile"]),
        "makefile",
    );
    let begin = makefile.find("--begin heights").unwrap();
    let shadow = makefile.find("shadow-height").unwrap();
    assert!(begin < shadow, "{makefile}");
}

/// A scene in a directory with a space, `#` and `$` in its name: make runs the Makefile's
/// rules (escaped targets, quoted recipes); a `:` in a path is refused in one line. A `{` in
/// a path is refused for the Snakefile (Snakemake would read a wildcard), a `{` in a recipe
/// kept.
#[test]
fn the_makefile_escapes_what_make_can_and_refuses_the_rest() {
    let t = sample_with_scene();
    let root = t.path();
    let odd = root.join("my scene #1 $x");
    std::fs::create_dir(&odd).unwrap();
    std::fs::rename(root.join("scene"), odd.join("scene")).unwrap();
    std::fs::write(odd.join("scene.toml"), scene_toml(30.0)).unwrap();
    // The scene's paths are then absolute, each with the directory's name.
    let scene = odd.join("scene.toml");
    let scene = scene.to_str().unwrap();
    assert!(ok(dbms_in(&odd, &["plan", scene, "--makefile"]), "plan")
        .contains("my\\ scene\\ \\#1\\ $$x/build/db.steps/place.done"));
    make_scene(&odd, scene);
    assert!(std::fs::read(odd.join("build/day.dbt")).unwrap() == stage_by_stage(&odd, 30.0));
    let plan = ok(dbms_in(&odd, &["plan", scene]), "plan");
    assert!(plan.contains("all up to date"), "{plan}");
    let text = scene_toml(30.0).replace("build/db", "build/d:b");
    std::fs::write(odd.join("scene.toml"), text).unwrap();
    let out = dbms_in(&odd, &["plan", "scene.toml", "--makefile"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("a Makefile rule cannot name"),
        "{err}"
    );
    let text = scene_toml(30.0).replace("build/db", "build/{db}");
    std::fs::write(odd.join("scene.toml"), text).unwrap();
    let out = dbms_in(&odd, &["plan", "scene.toml", "--snakefile"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("a Snakefile rule cannot name"),
        "{err}"
    );
    assert_eq!(err.trim_end().lines().count(), 1, "one line: {err}");
}

/// The scene's `at` placements are one `dbms place` (a change of the database each would
/// rewrite its manifest: a build in quadratic time), in the scene's order, giving the
/// database placement by placement gives.
#[test]
fn at_placements_are_placed_by_one_command() {
    let t = sample_with_scene();
    let dir = t.path();
    let json: serde_json::Value =
        serde_json::from_str(&ok(dbms_in(dir, &["--json", "plan", "scene.toml"]), "plan")).unwrap();
    let place = json["steps"]
        .as_array()
        .unwrap()
        .iter()
        .find(|s| s["name"] == "place")
        .unwrap();
    let commands = place["commands"].as_array().unwrap();
    assert_eq!(commands.len(), 1, "{place}");
    let line = commands[0].to_string();
    let first = line.find("500030,5300030").unwrap();
    assert!(first < line.find("500050,5300040").unwrap(), "{line}");
    ok(dbms_in(dir, &["-q", "build", "scene.toml"]), "build");
    assert!(std::fs::read(dir.join("build/day.dbt")).unwrap() == stage_by_stage(dir, 30.0));
}

/// A scale the database cannot hold (the object wider than its extent, or taller than
/// `Z_MARGIN_M`) is refused in one line, by `dbms place` and so by a scene's build.
#[test]
fn a_scale_the_grid_cannot_hold_is_refused() {
    let t = sample_with_scene();
    let dir = t.path();
    let text = scene_toml(30.0).replace("heading = 30\n", "heading = 30\nscale = 150\n");
    std::fs::write(dir.join("scene.toml"), text).unwrap();
    let out = dbms_in(dir, &["build", "scene.toml"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("step place failed") && err.contains("--scale 150"),
        "{err}"
    );
    assert_eq!(err.trim_end().lines().count(), 1, "one line: {err}");
    // Moved to a scale it cannot hold: refused, the placement unchanged.
    std::fs::write(dir.join("scene.toml"), scene_toml(30.0)).unwrap();
    ok(dbms_in(dir, &["-q", "build", "scene.toml"]), "build");
    let out = dbms_in(
        dir,
        &[
            "place",
            "--db",
            "build/db",
            "--move",
            "1",
            "--at",
            "500030,5300030",
            "--scale",
            "100",
        ],
    );
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        !out.status.success() && err.contains("--scale 100"),
        "{err}"
    );
    assert_eq!(err.trim_end().lines().count(), 1, "one line: {err}");
    let plan = ok(dbms_in(dir, &["plan", "scene.toml"]), "plan");
    assert!(plan.contains("all up to date"), "{plan}");
}
