//! Benchmark: `dbms pyramid --incremental` after one tree moved, against a full build (issue 17:
//! "one tree moved in a database of 10 000 placed trees on the 8192² grid — rebuild time against
//! a full build (goal: ≥ 50× faster)").
//!
//! `cargo bench --bench incremental` (size from `DBMS_BENCH_SIZE`, default 8192; work directory
//! from `DBMS_BENCH_DIR`, default a temporary one; moves per case from `DBMS_BENCH_MOVES`,
//! default 3). Steps:
//! 1. generate a W×W database of 1 m cells (as `benches/pyramid.rs`: rolling terrain with a
//!    nodata hole, a textured colour layer) — not timed;
//! 2. one cone tree (`dbms object cone --height 8 --radius 2.5 --voxel 0.25`) placed 10 000 times
//!    in one `dbms place --points` call, at points uniform at random (seeded) over the grid, off
//!    the hole and away from the edges, with random headings and scales 0.8–1.25 — not timed;
//! 3. for each case (no sun; a sun at elevation 35°, azimuth 135°): a full build with
//!    `--incremental` (no ledger yet: it makes every page and writes the ledger), then
//!    `DBMS_BENCH_MOVES` times: one tree moved a few tens of metres (`dbms place --move`), the
//!    `--incremental` build again, a plain full build (no `--incremental`) to another file, and
//!    the two tile files compared byte for byte (`cmp`; a difference fails the bench).
//!
//! Every `dbms` run is the release binary under `/usr/bin/time` for its peak memory, its
//! `--json` summary giving the pages made and the steps' seconds. Prints Markdown tables.

#[path = "support/rolling_db.rs"]
mod rolling_db;

#[path = "support/files.rs"]
mod files;
use dbms::voxel::place::uniform;
use files::{loadavg, remove, same_bytes};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

/// Placed trees.
const TREES: usize = 10_000;
/// Seed of the points and of `place`'s headings and scales.
const SEED: u64 = 7;
/// Grid origin (top-left corner), as `make_database` makes it; cells of 1 m.
const X0: f64 = 500_000.0;
const Y0: f64 = 5_300_000.0;

/// The two cases: name and the sun options.
const CASES: [(&str, &[&str]); 2] = [
    ("no sun", &[]),
    (
        "sun 35° elevation, 135° azimuth",
        &["--sun-elevation", "35", "--sun-azimuth", "135"],
    ),
];

fn main() {
    let size: usize = std::env::var("DBMS_BENCH_SIZE")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(8192);
    let moves: usize = std::env::var("DBMS_BENCH_MOVES")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(3)
        .max(1);
    let tmp = tempfile::tempdir().expect("temp dir");
    let work = std::env::var("DBMS_BENCH_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|_| tmp.path().to_path_buf());
    std::fs::create_dir_all(&work).expect("work dir");
    let load_at_start = loadavg();
    let db_dir = work.join("db");
    if db_dir.exists() {
        std::fs::remove_dir_all(&db_dir).expect("remove the earlier database");
    }
    let t = Instant::now();
    rolling_db::make_database(&db_dir, size);
    eprintln!(
        "generated {size}×{size} database in {:.1} s",
        t.elapsed().as_secs_f64()
    );

    // The trees: one object, 10 000 placements in one change.
    let t = Instant::now();
    let tree = work.join("tree.dvox");
    dbms(&[
        "object", "cone", "--height", "8", "--radius", "2.5", "--voxel", "0.25", "--seed", "1",
        "-o",
    ])
    .arg(&tree)
    .run();
    let points = tree_points(size);
    let layer = work.join("trees.geojson");
    write_points(&layer, &points);
    let placed = dbms(&["--json", "place", "--db"])
        .arg(&db_dir)
        .arg("--object")
        .arg(&tree)
        .arg("--points")
        .arg(&layer)
        .args(["--random-heading", "--scale-range", "0.8,1.25", "--seed"])
        .arg(SEED.to_string())
        .run();
    let placed: serde_json::Value = serde_json::from_str(&placed.stdout).expect("place summary");
    let placed: Vec<(u64, f64, f64)> = placed["placements"]
        .as_array()
        .expect("placements")
        .iter()
        .map(|p| {
            (
                p["id"].as_u64().expect("id"),
                p["x"].as_f64().expect("x"),
                p["y"].as_f64().expect("y"),
            )
        })
        .collect();
    assert_eq!(placed.len(), TREES, "every point placed");
    eprintln!(
        "placed {} trees in {:.1} s",
        placed.len(),
        t.elapsed().as_secs_f64()
    );

    let mut results = Vec::new();
    let mut trees = placed.clone();
    for (case, (name, sun)) in CASES.iter().enumerate() {
        let tiles = work.join(format!("case{case}.dbt"));
        let reference = work.join(format!("case{case}_full.dbt"));
        let ledger = ledger_path(&tiles);
        // No ledger, no earlier file: the first --incremental build makes every page.
        remove(&tiles);
        remove(&ledger);
        let first = pyramid(&db_dir, &tiles, sun, true);
        assert!(
            first.full_build.is_some(),
            "{name}: the first --incremental build should be a full one"
        );
        eprintln!(
            "{name}: full build with --incremental {:.2} s ({})",
            first.secs,
            first.full_build.as_deref().unwrap_or("")
        );
        let mut runs = Vec::new();
        for m in 0..moves {
            // A different tree each time, moved 30 m east or west and 20 m north or south,
            // toward the grid's centre (never off the grid; never onto the hole, see below).
            let target = |(_, x, y): (u64, f64, f64)| {
                let c = size as f64 / 2.0;
                (
                    x + if x - X0 < c { 30.0 } else { -30.0 },
                    y + if Y0 - y < c { -20.0 } else { 20.0 },
                )
            };
            let k = (((case * moves + m) * 997)..)
                .map(|k| k % trees.len())
                .find(|&k| !near_hole(target(trees[k]), size))
                .expect("a tree to move");
            let (id, x, y) = trees[k];
            let to = target(trees[k]);
            dbms(&["place", "--db"])
                .arg(&db_dir)
                .args(["--move", &id.to_string(), "--at"])
                .arg(format!("{},{}", to.0, to.1))
                .run();
            trees[k] = (id, to.0, to.1);
            let load = loadavg();
            let inc = pyramid(&db_dir, &tiles, sun, true);
            assert!(
                inc.full_build.is_none(),
                "{name}: move {m}: incremental build made every page: {:?}",
                inc.full_build
            );
            remove(&reference);
            let full = pyramid(&db_dir, &reference, sun, false);
            let identical = same_bytes(&tiles, &reference);
            eprintln!(
                "{name}: moved tree {id} ({x:.1}, {y:.1}) → ({:.1}, {:.1}); incremental {:.2} s, {} of {} pages; full {:.2} s; identical: {identical}",
                to.0, to.1, inc.secs, inc.pages_rebuilt, inc.pages, full.secs
            );
            runs.push(Run {
                tree: id,
                load,
                inc,
                full,
                identical,
            });
        }
        results.push((name.to_string(), first, runs));
        remove(&reference);
    }

    print_tables(size, &results);
    println!(
        "\nload average (1 min): {load_at_start:.2} before the bench, {:.2} after it",
        loadavg()
    );
    let bad: Vec<String> = results
        .iter()
        .flat_map(|(name, _, runs)| {
            runs.iter()
                .enumerate()
                .filter(|(_, r)| !r.identical)
                .map(move |(m, r)| format!("{name}, move {m} (tree {})", r.tree))
        })
        .collect();
    if !bad.is_empty() && std::env::var("DBMS_BENCH_DIR").is_err() {
        // Keep the files for whoever reproduces it.
        let kept = tmp.keep();
        eprintln!("kept the work directory {}", kept.display());
    }
    assert!(
        bad.is_empty(),
        "incremental tile file differs from the full build's: {}",
        bad.join("; ")
    );
}

/// One move: the incremental build, the full build it is checked against.
struct Run {
    tree: u64,
    load: f64,
    inc: Build,
    full: Build,
    identical: bool,
}

/// A `dbms pyramid` run: wall seconds, peak resident kB, and its summary's figures.
#[derive(Clone)]
struct Build {
    secs: f64,
    kb: Option<u64>,
    pages: u64,
    pages_rebuilt: u64,
    full_build: Option<String>,
    /// read, prepare, levels, finish.
    steps: [f64; 4],
}

/// `dbms --quiet --json pyramid --db DB -o TILES [sun] [--incremental]`, timed.
fn pyramid(db: &Path, tiles: &Path, sun: &[&str], incremental: bool) -> Build {
    let mut cmd = dbms(&["--quiet", "--json", "pyramid", "--db"])
        .arg(db)
        .arg("-o")
        .arg(tiles)
        .args(sun);
    if incremental {
        cmd = cmd.arg("--incremental");
    }
    let out = cmd.run();
    let s: serde_json::Value = serde_json::from_str(&out.stdout).expect("pyramid --json summary");
    let step = |k: &str| s["seconds"][k].as_f64().expect("step seconds");
    Build {
        secs: out.secs,
        kb: out.kb,
        pages: s["pages"].as_u64().expect("pages"),
        pages_rebuilt: s["pages_rebuilt"].as_u64().expect("pages_rebuilt"),
        full_build: s["full_build"].as_str().map(str::to_string),
        steps: [
            step("read"),
            step("prepare"),
            step("levels"),
            step("finish"),
        ],
    }
}

/// A `dbms` command (the release binary cargo built for this bench).
fn dbms(args: &[&str]) -> Timed {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_dbms"));
    cmd.args(args);
    Timed(cmd)
}

struct Timed(Command);

struct Output {
    secs: f64,
    kb: Option<u64>,
    stdout: String,
}

impl Timed {
    fn arg(mut self, a: impl AsRef<std::ffi::OsStr>) -> Self {
        self.0.arg(a);
        self
    }

    fn args<I: IntoIterator<Item = S>, S: AsRef<std::ffi::OsStr>>(mut self, a: I) -> Self {
        self.0.args(a);
        self
    }

    /// Run it (under `/usr/bin/time` when there is one, for the peak resident memory); it must
    /// succeed.
    fn run(self) -> Output {
        let cmd = self.0;
        let have_time = Path::new("/usr/bin/time").exists();
        let t = Instant::now();
        let o = if have_time {
            Command::new("/usr/bin/time")
                .args(["-f", "%M"])
                .arg(cmd.get_program())
                .args(cmd.get_args())
                .output()
        } else {
            Command::new(cmd.get_program())
                .args(cmd.get_args())
                .output()
        }
        .expect("run dbms");
        let secs = t.elapsed().as_secs_f64();
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert!(o.status.success(), "{cmd:?} failed: {stderr}");
        let kb = have_time
            .then(|| stderr.lines().last().and_then(|l| l.trim().parse().ok()))
            .flatten();
        Output {
            secs,
            kb,
            stdout: String::from_utf8_lossy(&o.stdout).into_owned(),
        }
    }
}

/// The ledger `--incremental` keeps beside `tiles`.
fn ledger_path(tiles: &Path) -> PathBuf {
    let mut name = tiles.file_name().expect("file name").to_os_string();
    name.push(".ledger.json");
    tiles.with_file_name(name)
}

/// Whether `(x, y)` is within 15 m of `make_database`'s nodata hole (a circle of radius W/40
/// about column 0.3 W, row 0.6 W): `place` refuses an anchor on nodata.
fn near_hole((x, y): (f64, f64), n: usize) -> bool {
    let n = n as f64;
    let (col, row) = (x - X0, Y0 - y);
    ((col - 0.3 * n).powi(2) + (row - 0.6 * n).powi(2)).sqrt() < n / 40.0 + 15.0
}

/// `TREES` points uniform at random over the grid (seeded), 50 m from its edges (a move of
/// tens of metres stays on it) and off the hole.
fn tree_points(n: usize) -> Vec<(f64, f64)> {
    let margin = 50.0;
    let span = n as f64 - 2.0 * margin;
    let mut points = Vec::with_capacity(TREES);
    let mut i = 0u64;
    while points.len() < TREES {
        let p = (
            X0 + margin + span * uniform(SEED, i, 0),
            Y0 - margin - span * uniform(SEED, i, 1),
        );
        i += 1;
        if !near_hole(p, n) {
            // Centimetres: the GeoJSON stays small and the manifest's numbers short.
            points.push(((p.0 * 100.0).round() / 100.0, (p.1 * 100.0).round() / 100.0));
        }
    }
    points
}

fn write_points(path: &Path, points: &[(f64, f64)]) {
    let features: Vec<serde_json::Value> = points
        .iter()
        .map(|&(x, y)| {
            serde_json::json!({
                "type": "Feature",
                "properties": {},
                "geometry": {"type": "Point", "coordinates": [x, y]},
            })
        })
        .collect();
    let doc = serde_json::json!({"type": "FeatureCollection", "features": features});
    std::fs::write(path, serde_json::to_string(&doc).expect("json")).expect("write points");
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    match n % 2 {
        1 => v[n / 2],
        _ => (v[n / 2 - 1] + v[n / 2]) / 2.0,
    }
}

fn mb(kb: Option<u64>) -> String {
    kb.map(|k| format!("{:.0}", k as f64 / 1024.0))
        .unwrap_or_else(|| "n/a".to_string())
}

fn print_tables(size: usize, results: &[(String, Build, Vec<Run>)]) {
    println!(
        "\n{size}×{size} cells of 1 m, {TREES} placed trees, one moved per run; {} threads\n",
        std::thread::available_parallelism().map_or(0, |n| n.get())
    );
    println!(
        "| case | full build (s) | incremental (s, median) | speed-up | pages made / pages | identical | read | prepare | levels | finish | peak MB full / incr. |"
    );
    println!("|---|---:|---:|---:|---:|---|---:|---:|---:|---:|---:|");
    for (name, _, runs) in results {
        let full = median(runs.iter().map(|r| r.full.secs).collect());
        let inc = median(runs.iter().map(|r| r.inc.secs).collect());
        // The steps of the run whose time is the median (the middle one of an odd count).
        let mut order: Vec<&Run> = runs.iter().collect();
        order.sort_by(|a, b| a.inc.secs.total_cmp(&b.inc.secs));
        let mid = order[(order.len() - 1) / 2];
        let made = median(runs.iter().map(|r| r.inc.pages_rebuilt as f64).collect());
        let identical = match runs.iter().all(|r| r.identical) {
            true => "yes".to_string(),
            false => format!(
                "**NO** ({} of {})",
                runs.iter().filter(|r| !r.identical).count(),
                runs.len()
            ),
        };
        let kb_full = runs.iter().filter_map(|r| r.full.kb).max();
        let kb_inc = runs.iter().filter_map(|r| r.inc.kb).max();
        let [read, prepare, levels, finish] = mid.inc.steps;
        println!(
            "| {name} | {full:.2} | {inc:.3} | {:.1}× | {made} / {} | {identical} | {read:.3} | {prepare:.3} | {levels:.3} | {finish:.3} | {} / {} |",
            full / inc,
            mid.inc.pages,
            mb(kb_full),
            mb(kb_inc)
        );
    }

    println!("\nEvery run:\n");
    println!(
        "| case | run | tree moved | load avg | wall (s) | pages made | read | prepare | levels | finish | peak MB | identical |"
    );
    println!("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|");
    for (name, first, runs) in results {
        let row = |what: &str, tree: String, load: String, b: &Build, same: &str| {
            let [read, prepare, levels, finish] = b.steps;
            println!(
                "| {name} | {what} | {tree} | {load} | {:.3} | {} / {} | {read:.3} | {prepare:.3} | {levels:.3} | {finish:.3} | {} | {same} |",
                b.secs,
                b.pages_rebuilt,
                b.pages,
                mb(b.kb)
            );
        };
        row(
            "full, --incremental (writes the ledger)",
            "".into(),
            "".into(),
            first,
            "",
        );
        for (m, r) in runs.iter().enumerate() {
            let same = if r.identical { "yes" } else { "**NO**" };
            row(
                &format!("move {}: incremental", m + 1),
                r.tree.to_string(),
                format!("{:.2}", r.load),
                &r.inc,
                same,
            );
            row(
                &format!("move {}: full", m + 1),
                r.tree.to_string(),
                "".into(),
                &r.full,
                "",
            );
        }
    }
}
