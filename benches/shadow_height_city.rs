//! Benchmark: `dbms shadow-height` on a city — 100,000 footprints over a 20000² orthophoto at
//! 0.5 m (issue 14's goal: under 2 minutes on 2 cores, under 2 GB resident).
//!
//! `cargo bench --bench shadow_height_city` (full size), `-- quick` (a 5000² corner of the same
//! density: 6,250 buildings). Work directory from `DBMS_BENCH_DIR` (default
//! `target/bench-city`); the generated scene is kept there and reused by the next run.
//! `DBMS_BENCH_EVERY=100,10` runs only those subsets.
//!
//! The scene (generated with the library's rasterisers and cast, not timed):
//! * terrain: rolling hills, ±12 m over kilometres and ±1.5 m over a hundred metres;
//! * buildings: one per lot of a square grid of lots (pitch = extent / √count, 31.6 m at full
//!   size): a rectangle with sides 10 m to min(25 m, pitch − 6 m), its centre jittered within
//!   the lot, turned ±6° off the street grid (one in five at any angle), 10–40 m high, a flat
//!   roof at that height above the highest ground under it;
//! * photo: ground texture and a roof colour per building, the cast shadows of terrain and
//!   buildings for a sun at 35° from azimuth 150° (grid) darkened to 45 %, one sample a cell.
//!
//! Timed: the release `dbms shadow-height` on every 100th, every 10th and every footprint
//! (all buildings stand in the photo each time), under `/usr/bin/time` for peak resident
//! memory. Also reported: how the heights compare with the truth (median absolute error of
//! the unflagged ones and how many are off by more than 2 m without a flag) — a check that
//! the scale path measures what the small scenes do, not an accuracy benchmark (the POV-Ray
//! benches are that).

use dbms::crs::Crs;
use dbms::db::{Database, Stage};
use dbms::grid::Grid;
use dbms::io::geotiff::GeoTiffWriter;
use dbms::shadow::{cast_shadows_slice, SHADOW};
use dbms::standing::{rasterise_prisms, Prism};
use dbms::sun::Sun;
use rayon::prelude::*;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

const CELL_M: f64 = 0.5;
const SUN_ELEVATION: f64 = 35.0;
const SUN_AZIMUTH: f64 = 150.0;
const SHADOW_FACTOR: f32 = 0.45;
const MIN_X: f64 = 500_000.0;
const MAX_Y: f64 = 5_310_000.0;

/// One generated building: its footprint ring (world metres) and its height over the highest
/// ground under it.
struct Building {
    ring: Vec<(f64, f64)>,
    height_m: f64,
    roof: [u8; 3],
}

fn main() {
    let quick = std::env::args().any(|a| a == "quick");
    let (size, count) = if quick {
        (5_000, 6_250)
    } else {
        (20_000, 100_000)
    };
    let work = std::env::var_os("DBMS_BENCH_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|| PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("target/bench-city"))
        .join(format!("{size}-{count}"));
    let db = work.join("db");
    if !work.join("ready").exists() {
        let t = Instant::now();
        generate(&work, size, count);
        std::fs::write(work.join("ready"), "").expect("mark ready");
        eprintln!("generated in {:.0} s", t.elapsed().as_secs_f64());
    }
    let truth: Vec<Option<f64>> = serde_json::from_str(
        &std::fs::read_to_string(work.join("truth.json")).expect("truth.json"),
    )
    .expect("truth is a list of heights");
    println!(
        "| footprints | seconds | peak resident MB | s per 1,000 | measured | unflagged: median |err| m | unflagged off > 2 m |"
    );
    println!("|---:|---:|---:|---:|---:|---:|---:|");
    // Which subsets: every 100th, 10th and every footprint, or those `DBMS_BENCH_EVERY` lists
    // (e.g. "100,10" to leave out the longest run).
    let subsets: Vec<usize> = std::env::var("DBMS_BENCH_EVERY")
        .ok()
        .map(|v| v.split(',').filter_map(|x| x.trim().parse().ok()).collect())
        .unwrap_or_else(|| vec![100, 10, 1]);
    for every in subsets {
        let fp = work.join(format!("footprints-every-{every}.geojson"));
        if !fp.exists() {
            write_footprints(&work, &fp, every);
        }
        let out = work.join(format!("heights-every-{every}.geojson"));
        let mut cmd = Command::new(env!("CARGO_BIN_EXE_dbms"));
        cmd.args(["--quiet", "shadow-height", "--db"])
            .arg(&db)
            .arg("--footprints")
            .arg(&fp)
            .args([
                "--sun-elevation",
                &SUN_ELEVATION.to_string(),
                "--sun-azimuth",
                &SUN_AZIMUTH.to_string(),
                "-o",
            ])
            .arg(&out);
        let (secs, kb) = timed(&mut cmd);
        let n = count.div_ceil(every);
        let (measured, median, gross) = score(&out, &truth);
        println!(
            "| {n} | {secs:.1} | {:.0} | {:.2} | {measured} | {median:.2} | {gross} |",
            kb as f64 / 1024.0,
            secs / n as f64 * 1000.0,
        );
    }
}

/// Heights measured, the median absolute error of the unflagged ones (metres) and how many
/// unflagged ones are off by more than 2 m.
fn score(out: &Path, truth: &[Option<f64>]) -> (usize, f64, usize) {
    let v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out).expect("heights")).expect("json");
    let mut errors = Vec::new();
    let mut measured = 0;
    for f in v["features"].as_array().expect("features") {
        let p = &f["properties"];
        let Some(h) = p["height_m"].as_f64() else {
            continue;
        };
        measured += 1;
        let flagged = p["flags"].as_array().is_some_and(|a| !a.is_empty());
        if !flagged {
            let id = p["id"].as_u64().expect("id") as usize;
            if let Some(t) = truth[id - 1] {
                errors.push((h - t).abs());
            }
        }
    }
    errors.sort_by(f64::total_cmp);
    let median = errors.get(errors.len() / 2).copied().unwrap_or(f64::NAN);
    (
        measured,
        median,
        errors.iter().filter(|e| **e > 2.0).count(),
    )
}

/// SplitMix64's finaliser: a well-mixed 64-bit value of `x`.
fn mix(mut x: u64) -> u64 {
    x = x.wrapping_add(0x9E37_79B9_7F4A_7C15);
    x = (x ^ (x >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    x = (x ^ (x >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    x ^ (x >> 31)
}

/// A seeded sequence of uniform numbers.
struct Rng(u64);

impl Rng {
    fn new(seed: u64) -> Rng {
        Rng(seed)
    }

    /// Uniform in [lo, hi).
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        self.0 = self.0.wrapping_add(1);
        lo + (hi - lo) * (mix(self.0) >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Ground height, metres, at world point (x, y).
fn ground(x: f64, y: f64) -> f64 {
    let (u, v) = (x - MIN_X, MAX_Y - y);
    300.0 + 12.0 * (u / 1900.0).sin() * (v / 2300.0).cos() + 1.5 * (u / 97.0 + v / 131.0).sin()
}

fn buildings(size: usize, count: usize) -> Vec<Building> {
    let extent = size as f64 * CELL_M;
    let side = (count as f64).sqrt().ceil() as usize;
    let pitch = extent / side as f64;
    let max_side = (pitch - 6.0).min(25.0);
    let mut rng = Rng::new(mix(0xc17e));
    (0..count)
        .map(|k| {
            let (i, j) = (k % side, k / side);
            let (w, d) = (rng.range(10.0, max_side), rng.range(10.0, max_side));
            let turn = if rng.range(0.0, 1.0) < 0.2 {
                rng.range(0.0, 180.0)
            } else {
                rng.range(-6.0, 6.0)
            }
            .to_radians();
            // Half the rotated box's extent, so the jitter keeps it inside its lot.
            let (c, s) = (turn.cos().abs(), turn.sin().abs());
            let (hx, hy) = ((w * c + d * s) / 2.0, (w * s + d * c) / 2.0);
            let slack_x = (pitch / 2.0 - hx - 3.0).max(0.0);
            let slack_y = (pitch / 2.0 - hy - 3.0).max(0.0);
            let cx = MIN_X + (i as f64 + 0.5) * pitch + rng.range(-slack_x, slack_x);
            let cy = MAX_Y - (j as f64 + 0.5) * pitch + rng.range(-slack_y, slack_y);
            let ring = [(-w, -d), (w, -d), (w, d), (-w, d)]
                .iter()
                .map(|&(a, b)| {
                    let (a, b) = (a / 2.0, b / 2.0);
                    (
                        cx + a * turn.cos() - b * turn.sin(),
                        cy + a * turn.sin() + b * turn.cos(),
                    )
                })
                .collect();
            let grey = rng.range(70.0, 200.0) as u8;
            let roof = if rng.range(0.0, 1.0) < 0.3 {
                [grey.saturating_add(40), grey / 2 + 30, grey / 3 + 20]
            } else {
                [grey, grey, grey.saturating_add(8)]
            };
            Building {
                ring,
                height_m: rng.range(10.0, 40.0),
                roof,
            }
        })
        .collect()
}

/// Generate the database, the truth and the building list into `work`.
fn generate(work: &Path, size: usize, count: usize) {
    std::fs::create_dir_all(work).expect("work dir");
    let grid = Grid::north_up(MIN_X, MAX_Y, CELL_M, size, size, Crs::epsg(32632));
    let n = size * size;
    let t = Instant::now();
    let terrain: Vec<f32> = (0..n)
        .into_par_iter()
        .map(|i| {
            let (x, y) = grid.cell_centre(i % size, i / size);
            ground(x, y) as f32
        })
        .collect();
    let plans = buildings(size, count);
    // Each building's cells: its roof stands over the highest ground under it.
    let cells: Vec<Vec<usize>> = plans
        .par_iter()
        .map(|b| {
            let prism = Prism {
                rings: vec![b.ring.clone()],
                roof: dbms::roof::RoofShape::flat(0.0),
            };
            rasterise_prisms(&grid, std::slice::from_ref(&prism))
                .into_iter()
                .map(|c| c.index)
                .collect()
        })
        .collect();
    let mut surface = terrain.clone();
    let mut roof_of = vec![0u32; n];
    let mut truth = Vec::with_capacity(count);
    for (k, (b, cells)) in plans.iter().zip(&cells).enumerate() {
        let base = cells
            .iter()
            .map(|&i| terrain[i])
            .fold(f32::NEG_INFINITY, f32::max);
        let roof = base + b.height_m as f32;
        for &i in cells {
            surface[i] = roof;
            roof_of[i] = k as u32 + 1;
        }
        truth.push((!cells.is_empty()).then_some(b.height_m));
    }
    drop(cells);
    let sun = Sun::new(SUN_ELEVATION, SUN_AZIMUTH).expect("sun");
    let shadow = cast_shadows_slice(&surface, &grid, &sun).expect("cast");
    drop(surface);
    eprintln!("scene cast in {:.0} s", t.elapsed().as_secs_f64());
    let colour: Vec<[u8; 4]> = (0..n)
        .into_par_iter()
        .map(|i| {
            let base = match roof_of[i] {
                0 => {
                    let v = (mix(i as u64) >> 40) as f32 / (1u64 << 24) as f32;
                    let (x, y) = (i % size, i / size);
                    let patch = ((x / 37 + y / 53) % 3) as f32 * 12.0;
                    [
                        118.0 + 30.0 * v + patch,
                        122.0 + 28.0 * v,
                        96.0 + 20.0 * v - patch / 2.0,
                    ]
                }
                k => plans[k as usize - 1].roof.map(|c| c as f32),
            };
            let f = if shadow[i] == SHADOW {
                SHADOW_FACTOR
            } else {
                1.0
            };
            let [r, g, b] = base.map(|c| (c * f).round().clamp(0.0, 255.0) as u8);
            [r, g, b, 255]
        })
        .collect();
    drop(shadow);
    drop(roof_of);
    let dir = work.join("db");
    let _ = std::fs::remove_dir_all(&dir);
    let mut db = Database::create(&dir, grid.clone(), vec![]).expect("create database");
    let mut w = GeoTiffWriter::create_f32(&dir.join("elevation.tif"), &grid).expect("elevation");
    w.push_rows(&terrain).expect("write elevation");
    w.finish().expect("finish elevation");
    drop(terrain);
    let mut w = GeoTiffWriter::create_rgba8(&dir.join("colour.tif"), &grid).expect("colour");
    w.push_rows(&colour).expect("write colour");
    w.finish().expect("finish colour");
    db.set_layer("elevation", "elevation", "elevation.tif", None)
        .expect("layer");
    db.set_layer("colour", "colour", "colour.tif", None)
        .expect("layer");
    db.record_stage(Stage::now("ingest", serde_json::json!({})));
    db.save().expect("save");
    let rings: Vec<Vec<[f64; 2]>> = plans
        .iter()
        .map(|b| {
            let mut r: Vec<[f64; 2]> = b.ring.iter().map(|&(x, y)| [x, y]).collect();
            r.push(r[0]);
            r
        })
        .collect();
    std::fs::write(
        work.join("rings.json"),
        serde_json::to_string(&rings).expect("rings"),
    )
    .expect("write rings");
    std::fs::write(
        work.join("truth.json"),
        serde_json::to_string(&truth).expect("truth"),
    )
    .expect("write truth");
}

/// Every `every`-th building's footprint (id = its index + 1) as GeoJSON in EPSG:32632.
fn write_footprints(work: &Path, path: &Path, every: usize) {
    let rings: Vec<Vec<[f64; 2]>> =
        serde_json::from_str(&std::fs::read_to_string(work.join("rings.json")).expect("rings"))
            .expect("rings json");
    let features: Vec<serde_json::Value> = rings
        .iter()
        .enumerate()
        .step_by(every)
        .map(|(k, r)| {
            serde_json::json!({
                "type": "Feature",
                "properties": { "id": k + 1 },
                "geometry": { "type": "Polygon", "coordinates": [r] },
            })
        })
        .collect();
    let doc = serde_json::json!({
        "type": "FeatureCollection",
        "crs": { "type": "name", "properties": { "name": "urn:ogc:def:crs:EPSG::32632" } },
        "features": features,
    });
    std::fs::write(path, serde_json::to_string(&doc).expect("geojson")).expect("write footprints");
}

/// Run a command under `/usr/bin/time`: wall seconds and peak resident kB.
fn timed(cmd: &mut Command) -> (f64, u64) {
    let t = Instant::now();
    let o = Command::new("/usr/bin/time")
        .args(["-f", "%M"])
        .arg(cmd.get_program())
        .args(cmd.get_args())
        .output()
        .expect("run /usr/bin/time (apt-get install time)");
    let secs = t.elapsed().as_secs_f64();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(o.status.success(), "{cmd:?}: {stderr}");
    let kb = stderr
        .lines()
        .last()
        .and_then(|l| l.trim().parse().ok())
        .expect("peak kB from /usr/bin/time");
    (secs, kb)
}
