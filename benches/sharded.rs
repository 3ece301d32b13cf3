//! Benchmark: a sharded pyramid build against one `dbms pyramid` (issue 19 item 5: "estimated
//! hours on N machines from the measured per-shard throughput").
//!
//! `cargo bench --bench sharded` (side `DBMS_SHARD_SIZE`, default 8192; shard counts
//! `DBMS_SHARDS`, comma-separated, default 4; cases `DBMS_SHARD_CASES`, comma-separated, default
//! `photo,sun,none`, also `bare` and `lz4`; work directory `DBMS_BENCH_DIR`, default a temporary one).
//! Steps:
//! 1. an N × N database of 1 m cells (`support/rolling_db.rs`, as `benches/pyramid.rs`:
//!    rolling terrain with a nodata hole, a textured colour layer), reused when
//!    `DIR/db-N.done` exists — not timed;
//! 2. a `buildings` layer of flat-roofed buildings (GeoJSON footprints with `roof_z`, recorded
//!    as `dbms shadow-height --apply` records it): towns in about 30 % of the 1024 m blocks,
//!    one building on a 50 m lattice cell of a town, 8–25 m sides, 5–30 m above the highest
//!    ground under it — not timed;
//! 3. for each case — `photo`: a sun (`--sun-elevation 30 --sun-azimuth 135`) and the photo's
//!    time recorded (`PHOTO_TIME`, a low morning sun from the east: the photo's shadows are
//!    detected and removed, the new ones cast); `sun`: the same sun, no photo time (one cast);
//!    `none`: no sun; `bare`: no sun and no buildings layer (terrain only); `lz4`: `photo`
//!    with `--compression lz4` — the release binary, each process timed with
//!    `/usr/bin/time -f "%e %M"` (wall, peak RSS):
//!    * `dbms pyramid` (one build), `dbms survey`,
//!    * for each shard count K: the K shards one after another (`--shard I/K`), then the merge
//!      (`--merge`), and the merged file compared with the single one byte for byte (`cmp`; a
//!      difference fails the bench).
//!
//! Prints a Markdown table per case and the derived figures: level-0 cells per second per
//! shard, merge MB/s (tile file written), survey cells/s, the shards' sum against the single
//! build, and the load average before and after. Results and the 200 km plan made from them:
//! docs/big-database.md, "Sharded builds: measured, and a 200 km area planned".

#[path = "support/rolling_db.rs"]
mod rolling_db;

#[path = "support/files.rs"]
mod files;
use dbms::db::{Database, Stage};
use files::{loadavg, remove, same_bytes};
use std::path::{Path, PathBuf};
use std::process::Command;

/// Grid origin (top-left corner), as `make_database` makes it; cells of 1 m.
const X0: f64 = 500_000.0;
const Y0: f64 = 5_300_000.0;
/// The photo's time in the `photo` case: at 47.8° N, 9° E the sun is about 30° up in the
/// east (azimuth about 90°), far from the requested 135°, so the photo's shadows are detected.
const PHOTO_TIME: &str = "2026-06-21T07:00:00Z";
/// The requested sun.
const SUN: [&str; 4] = ["--sun-elevation", "30", "--sun-azimuth", "135"];
/// Page edge (the default).
const PAGE: usize = 256;

fn env_list(name: &str, default: &str) -> Vec<String> {
    std::env::var(name)
        .unwrap_or_else(|_| default.to_string())
        .split(',')
        .map(|s| s.trim().to_string())
        .filter(|s| !s.is_empty())
        .collect()
}

fn main() {
    let n: usize = std::env::var("DBMS_SHARD_SIZE")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(8192);
    let counts: Vec<usize> = env_list("DBMS_SHARDS", "4")
        .iter()
        .map(|s| s.parse().expect("DBMS_SHARDS: shard counts, e.g. 4,16"))
        .collect();
    let cases = env_list("DBMS_SHARD_CASES", "photo,sun,none");
    let tmp = tempfile::tempdir().expect("temp dir");
    let work = std::env::var("DBMS_BENCH_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|_| tmp.path().to_path_buf());
    std::fs::create_dir_all(&work).expect("work dir");
    let load_at_start = loadavg();

    let db_dir = work.join(format!("db-{n}"));
    let done = work.join(format!("db-{n}.done"));
    if !done.exists() {
        if db_dir.exists() {
            std::fs::remove_dir_all(&db_dir).expect("remove the earlier database");
        }
        let t = std::time::Instant::now();
        rolling_db::make_database(&db_dir, n);
        std::fs::write(&done, b"").expect("marker");
        eprintln!(
            "generated {n}×{n} database in {:.1} s",
            t.elapsed().as_secs_f64()
        );
    }
    let (buildings, raised) = add_buildings(&db_dir, n);
    eprintln!("buildings layer: {buildings} buildings, {raised} cells under their footprints");

    let mut results: Vec<Case> = Vec::new();
    for case in &cases {
        let mut opts: Vec<&str> = Vec::new();
        let photo = match case.as_str() {
            "photo" => {
                opts.extend(SUN);
                true
            }
            "sun" => {
                opts.extend(SUN);
                false
            }
            "none" | "bare" => false,
            "lz4" => {
                opts.extend(SUN);
                opts.extend(["--compression", "lz4"]);
                true
            }
            other => panic!("DBMS_SHARD_CASES: no case {other:?} (photo, sun, none, bare, lz4)"),
        };
        set_buildings(&db_dir, case != "bare");
        set_photo_time(&db_dir, photo.then_some(PHOTO_TIME));
        let load = loadavg();
        let single = work.join("single.dbt");
        remove(&single);
        let one = timed(
            "pyramid (one build)",
            &[
                &["pyramid", "--db", path(&db_dir)][..],
                &opts[..],
                &["-o", path(&single)],
            ]
            .concat(),
            Some(&single),
        );
        let effects = one.json["effects"]["applied"].to_string();
        let survey_file = work.join("survey.json");
        remove(&survey_file);
        let survey = timed(
            "survey",
            &["survey", "--db", path(&db_dir), "-o", path(&survey_file)],
            Some(&survey_file),
        );
        let mut runs = Vec::new();
        for &k in &counts {
            let parts: Vec<PathBuf> = (1..=k)
                .map(|i| work.join(format!("part-{i}.dbt")))
                .collect();
            let mut shards = Vec::new();
            for (i, part) in parts.iter().enumerate() {
                remove(part);
                let shard = format!("{}/{k}", i + 1);
                let r = timed(
                    &format!("shard {shard}"),
                    &[
                        &["pyramid", "--db", path(&db_dir)][..],
                        &opts[..],
                        &[
                            "--shard",
                            &shard,
                            "--survey",
                            path(&survey_file),
                            "-o",
                            path(part),
                        ],
                    ]
                    .concat(),
                    Some(part),
                );
                shards.push(r);
            }
            let merged = work.join("merged.dbt");
            remove(&merged);
            let mut args: Vec<&str> = vec!["pyramid", "--db", path(&db_dir)];
            args.extend(&opts);
            args.extend(["-o", path(&merged), "--merge"]);
            args.extend(parts.iter().map(|p| path(p)));
            let merge = timed("merge", &args, Some(&merged));
            let identical = same_bytes(&single, &merged);
            eprintln!("{case}, {k} shards: merged file identical to the single one: {identical}");
            runs.push(Sharded {
                k,
                shards,
                merge,
                identical,
            });
            for p in &parts {
                remove(p);
                remove(&p.with_file_name(format!(
                    "{}.shard.json",
                    p.file_name().unwrap().to_str().unwrap()
                )));
            }
            remove(&merged);
        }
        remove(&single);
        results.push(Case {
            name: case.clone(),
            opts: opts.join(" "),
            photo,
            effects,
            load: [load, loadavg()],
            single: one,
            survey,
            runs,
        });
    }

    print_tables(n, buildings, raised, &results);
    println!(
        "\nload average (1 min): {load_at_start:.2} before the bench, {:.2} after it ({} threads)",
        loadavg(),
        std::thread::available_parallelism().map_or(0, |n| n.get())
    );
    let bad: Vec<String> = results
        .iter()
        .flat_map(|c| {
            c.runs
                .iter()
                .filter(|r| !r.identical)
                .map(move |r| format!("{}, {} shards", c.name, r.k))
        })
        .collect();
    assert!(
        bad.is_empty(),
        "merged tile file differs from the single build's: {}",
        bad.join("; ")
    );
}

fn path(p: &Path) -> &str {
    p.to_str().expect("UTF-8 path")
}

/// One case: its single build, survey and sharded builds.
struct Case {
    name: String,
    opts: String,
    photo: bool,
    effects: String,
    load: [f64; 2],
    single: Run,
    survey: Run,
    runs: Vec<Sharded>,
}

/// The shards of one count and their merge.
struct Sharded {
    k: usize,
    shards: Vec<Run>,
    merge: Run,
    identical: bool,
}

/// One timed `dbms` process.
struct Run {
    wall: f64,
    rss_kb: u64,
    bytes: u64,
    json: serde_json::Value,
}

/// `dbms --quiet --json ARGS` under `/usr/bin/time -f "%e %M"`; it must succeed.
fn timed(what: &str, args: &[&str], out: Option<&Path>) -> Run {
    let stats = std::env::temp_dir().join(format!("sharded-bench-time-{}", std::process::id()));
    let o = Command::new("/usr/bin/time")
        .args(["-f", "%e %M", "-o"])
        .arg(&stats)
        .arg(env!("CARGO_BIN_EXE_dbms"))
        .args(["--quiet", "--json"])
        .args(args)
        .output()
        .expect("run /usr/bin/time dbms");
    assert!(
        o.status.success(),
        "dbms {} failed: {}",
        args.join(" "),
        String::from_utf8_lossy(&o.stderr)
    );
    let text = std::fs::read_to_string(&stats).expect("time output");
    let _ = std::fs::remove_file(&stats);
    let mut it = text.lines().last().unwrap_or("").split_whitespace();
    let wall: f64 = it.next().and_then(|s| s.parse().ok()).expect("wall time");
    let rss_kb: u64 = it.next().and_then(|s| s.parse().ok()).expect("max RSS");
    let bytes = out.map_or(0, |p| std::fs::metadata(p).map(|m| m.len()).unwrap_or(0));
    let json = serde_json::from_slice(&o.stdout).unwrap_or(serde_json::Value::Null);
    eprintln!(
        "{what}: {wall:.1} s, peak RSS {:.0} MB, {:.1} MB written (load {:.2})",
        rss_kb as f64 / 1024.0,
        bytes as f64 / 1e6,
        loadavg()
    );
    Run {
        wall,
        rss_kb,
        bytes,
        json,
    }
}

/// Record (or drop) the photo's time: the last `ingest` stage's `photo_time` is what the
/// pyramid reads (`sun::photo_sun`).
fn set_photo_time(db_dir: &Path, time: Option<&str>) {
    let mut db = Database::open(db_dir).expect("open database");
    db.record_stage(Stage::now(
        "ingest",
        serde_json::json!({ "photo_time": time }),
    ));
    db.save().expect("save database");
}

/// Record the `buildings` layer (`buildings.geojson`, written by [`add_buildings`]) or drop it
/// from the manifest (the `bare` case: terrain only).
fn set_buildings(db_dir: &Path, on: bool) {
    let mut db = Database::open(db_dir).expect("open database");
    match on {
        true => db
            .set_layer("buildings", "buildings", "buildings.geojson", None)
            .expect("buildings layer"),
        false => {
            db.manifest.layers.remove("buildings");
        }
    }
    db.save().expect("save database");
}

/// `make_database`'s ground height at (column, row) without its per-cell noise (≤ 0.5 m).
fn ground(c: f64, r: f64) -> f64 {
    300.0 + 40.0 * (c / 700.0).sin() * (r / 900.0).cos() + 8.0 * (c / 97.0 + r / 131.0).sin()
}

/// A value in [0, 1) from two integers and a salt (deterministic).
fn hash2(a: usize, b: usize, salt: u64) -> f64 {
    let mut x = (a as u64)
        .wrapping_mul(0x9E37_79B9_7F4A_7C15)
        .wrapping_add((b as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F))
        ^ salt.wrapping_mul(0x1656_67B1_9E37_79F9);
    x ^= x >> 31;
    x = x.wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x ^= x >> 29;
    (x >> 11) as f64 / (1u64 << 53) as f64
}

/// Write `buildings.geojson` in the database and record it as the `buildings` layer (as
/// `dbms shadow-height --apply` does). Towns in about 30 % of the 1024 m blocks; in a town,
/// one building per 50 m lattice cell, sides 8–25 m, roof 5–30 m above the highest ground under
/// it; none within 30 m of the nodata hole or of the grid's edge. Returns the buildings and
/// the cells under their footprints.
fn add_buildings(db_dir: &Path, n: usize) -> (usize, usize) {
    let (hole_c, hole_r, hole_radius) = (0.3 * n as f64, 0.6 * n as f64, n as f64 / 40.0);
    let mut features = Vec::new();
    let mut cells = 0usize;
    let lattice = 50usize;
    for lr in 0..n / lattice {
        for lc in 0..n / lattice {
            let (bc, br) = (lc * lattice / 1024, lr * lattice / 1024);
            if hash2(bc, br, 1) >= 0.3 {
                continue;
            }
            let w = 8 + (hash2(lc, lr, 2) * 18.0) as usize;
            let h = 8 + (hash2(lc, lr, 3) * 18.0) as usize;
            let c0 = lc * lattice + (hash2(lc, lr, 4) * (lattice - w) as f64) as usize;
            let r0 = lr * lattice + (hash2(lc, lr, 5) * (lattice - h) as f64) as usize;
            let (cm, rm) = (c0 as f64 + w as f64 / 2.0, r0 as f64 + h as f64 / 2.0);
            let edge = 30.0;
            if c0 as f64 <= edge
                || r0 as f64 <= edge
                || (c0 + w) as f64 >= n as f64 - edge
                || (r0 + h) as f64 >= n as f64 - edge
                || ((cm - hole_c).powi(2) + (rm - hole_r).powi(2)).sqrt()
                    < hole_radius + 30.0 + w.max(h) as f64
            {
                continue;
            }
            let mut top = f64::MIN;
            for r in (r0..=r0 + h).step_by(2) {
                for c in (c0..=c0 + w).step_by(2) {
                    top = top.max(ground(c as f64, r as f64));
                }
            }
            let roof = top + 1.5 + 5.0 + (hash2(lc, lr, 6) * 25.0).round();
            let (x0, y0) = (X0 + c0 as f64, Y0 - (r0 + h) as f64);
            let (x1, y1) = (x0 + w as f64, y0 + h as f64);
            let ring = serde_json::json!([[x0, y0], [x1, y0], [x1, y1], [x0, y1], [x0, y0]]);
            features.push(serde_json::json!({
                "type": "Feature",
                "properties": {"id": features.len() + 1, "roof_z": roof},
                "geometry": {"type": "Polygon", "coordinates": [ring]},
            }));
            cells += w * h;
        }
    }
    let count = features.len();
    let doc = serde_json::json!({"type": "FeatureCollection", "features": features});
    let file = "buildings.geojson";
    std::fs::write(
        db_dir.join(file),
        serde_json::to_string(&doc).expect("json"),
    )
    .expect("write buildings");
    let mut db = Database::open(db_dir).expect("open database");
    db.set_layer("buildings", "buildings", file, None)
        .expect("buildings layer");
    db.save().expect("save database");
    (count, cells)
}

fn mb(kb: u64) -> f64 {
    kb as f64 / 1024.0
}

/// Level-0 cells of a shard's window (`pages`: `[tx0, ty0, tx1, ty1]` in pages of `PAGE`).
fn window_cells(run: &Run, n: usize) -> usize {
    let p = &run.json["pages"];
    let at = |k: usize| p[k].as_u64().expect("shard window") as usize;
    let span = |a: usize, b: usize| (b * PAGE).min(n) - a * PAGE;
    span(at(0), at(2)) * span(at(1), at(3))
}

fn print_tables(n: usize, buildings: usize, raised: usize, cases: &[Case]) {
    let cells = (n * n) as f64;
    println!(
        "\n{n}×{n} cells of 1 m ({:.0} M), {buildings} flat-roofed buildings over {raised} cells ({:.1} %), page {PAGE}, factor 4; {} threads\n",
        cells / 1e6,
        100.0 * raised as f64 / cells,
        std::thread::available_parallelism().map_or(0, |n| n.get())
    );
    for c in cases {
        println!(
            "### {} — `{}`{}; effects applied: {}; load average {:.2} → {:.2}\n",
            c.name,
            if c.opts.is_empty() {
                "(no sun)"
            } else {
                &c.opts
            },
            if c.photo {
                format!(", photo time {PHOTO_TIME}")
            } else {
                String::new()
            },
            c.effects,
            c.load[0],
            c.load[1]
        );
        println!("| step | wall (s) | peak RSS (MB) | output (MB) | level-0 cells | M cells/s |");
        println!("|---|---:|---:|---:|---:|---:|");
        let row = |what: &str, r: &Run, cells: Option<f64>| {
            println!(
                "| {what} | {:.1} | {:.0} | {} | {} | {} |",
                r.wall,
                mb(r.rss_kb),
                if r.bytes > 0 {
                    format!("{:.1}", r.bytes as f64 / 1e6)
                } else {
                    "–".into()
                },
                cells.map_or("–".into(), |c| format!("{:.1} M", c / 1e6)),
                cells.map_or("–".into(), |c| format!(
                    "{:.2}",
                    c / 1e6 / r.wall.max(1e-3)
                ))
            );
        };
        row("`dbms pyramid` (one build)", &c.single, Some(cells));
        row("`dbms survey`", &c.survey, Some(cells));
        for s in &c.runs {
            for (i, r) in s.shards.iter().enumerate() {
                row(
                    &format!("shard {}/{}", i + 1, s.k),
                    r,
                    Some(window_cells(r, n) as f64),
                );
            }
            row(&format!("merge of {} parts", s.k), &s.merge, None);
        }
        println!();
        for s in &c.runs {
            let sum: f64 = s.shards.iter().map(|r| r.wall).sum();
            let max = s.shards.iter().map(|r| r.wall).fold(0.0, f64::max);
            let min = s.shards.iter().map(|r| r.wall).fold(f64::MAX, f64::min);
            let rates: Vec<f64> = s
                .shards
                .iter()
                .map(|r| window_cells(r, n) as f64 / 1e6 / r.wall.max(1e-3))
                .collect();
            let rate_lo = rates.iter().copied().fold(f64::MAX, f64::min);
            let rate_hi = rates.iter().copied().fold(0.0, f64::max);
            let part_bytes: u64 = s.shards.iter().map(|r| r.bytes).sum();
            let rss = s.shards.iter().map(|r| r.rss_kb).max().unwrap_or(0);
            println!(
                "* {} shards: per shard {:.2}–{:.2} M level-0 cells/s ({:.1}–{:.1} s, peak RSS up to {:.0} MB); shards' sum {sum:.1} s = {:.2}× the one build; survey + slowest shard + merge = {:.1} s ({:.2}× the one build); parts {:.1} MB = {:.2} B a level-0 cell; merge {:.0} MB/s written ({:.0} MB/s of parts read), merged file {:.2} B a level-0 cell; identical to the one build: {}",
                s.k,
                rate_lo,
                rate_hi,
                min,
                max,
                mb(rss),
                sum / c.single.wall,
                c.survey.wall + max + s.merge.wall,
                (c.survey.wall + max + s.merge.wall) / c.single.wall,
                part_bytes as f64 / 1e6,
                part_bytes as f64 / cells,
                s.merge.bytes as f64 / 1e6 / s.merge.wall.max(1e-3),
                part_bytes as f64 / 1e6 / s.merge.wall.max(1e-3),
                s.merge.bytes as f64 / cells,
                if s.identical { "yes" } else { "**NO**" }
            );
        }
        println!(
            "* survey {:.1} M cells/s; one build {:.1} M cells/s, {:.2} B a level-0 cell",
            cells / 1e6 / c.survey.wall.max(1e-3),
            cells / 1e6 / c.single.wall.max(1e-3),
            c.single.bytes as f64 / cells
        );
        if let Some(s) = c.single.json.get("seconds") {
            println!("* one build's steps (s): {s}");
        }
        println!();
    }
}
