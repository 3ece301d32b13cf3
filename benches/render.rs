//! Benchmark: `dbms render` frames along a low-altitude flight path.
//!
//! `cargo bench --bench render` (work directory from `DBMS_BENCH_DIR`, default a temporary
//! one; the 8192² side from `DBMS_BENCH_SIZE`). Two tile sets, made untimed:
//! 1. the sample scene (`dbms sample`, `dbms ingest`, `dbms pyramid` run through the binary);
//! 2. a generated `N × N` grid of 1 m cells (rolling hills, blocks of buildings, a textured
//!    colour) written with `testing::tiles::write_tiles` (lz4 pages of 256, factor 4).
//!
//! On each, 640 × 480 frames (60° field of view) along a straight path 25 m above the ground,
//! pitched 4° down, rendered three ways: hierarchical without range thresholds, level-0 stepping
//! without them (fewer frames: it is slow), and hierarchical with them. Prints a Markdown table
//! (rays per second, time per frame, cells stepped per ray, hierarchy speed-up) and what the
//! range thresholds change in the image against the time they save, for docs/render.md.
//!
//! Then anti-aliasing (`cargo bench --bench render -- aa` for this table alone): one flight frame
//! of each tile set rendered with 1, 4 and 16 rays per pixel, level blending off and on, against
//! a 64-ray blended reference: mean absolute error and time per frame.
//!
//! Then column coherence (`cargo bench --bench render -- coherence` alone): 24 frames of the
//! same path flown level (zero pitch, where it applies), with and without it: frames per second
//! and cells stepped per ray; the bench fails if a pixel differs.
//!
//! `cargo bench --bench render -- insets` alone: the sample with and without a 4× inset under
//! the flight, frames per second ([`insets`]).

#[path = "support/blocks.rs"]
mod blocks;
#[path = "support/sample.rs"]
mod sample;
use dbms::crs::Crs;
use dbms::grid::Grid;
use dbms::render::{render_view, Attitude, Frame, Traversal, ViewOptions, Viewpoint};
use dbms::testing::tiles as synthetic;
use dbms::tiles::{Compression, TileReader};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

fn main() {
    let size: usize = std::env::var("DBMS_BENCH_SIZE")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(8192);
    let tmp = tempfile::tempdir().expect("temp dir");
    let work = std::env::var("DBMS_BENCH_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|_| tmp.path().to_path_buf());
    std::fs::create_dir_all(&work).expect("work dir");
    println!("threads: {}", rayon::current_num_threads());

    let sample = sample::sample_tiles(&work);
    let generated = work.join(format!("generated-{size}.dbt"));
    if !generated.exists() {
        let t = Instant::now();
        let grid = Grid::north_up(
            600_000.0,
            5_200_000.0 + size as f64,
            1.0,
            size,
            size,
            Crs::epsg(32633),
        );
        synthetic::write_tiles(&generated, grid, 256, 4, Compression::Lz4, terrain)
            .expect("generate tiles");
        println!(
            "generated {size}² tile set in {:.1} s",
            t.elapsed().as_secs_f64()
        );
    }

    let sets = [("sample", &sample), ("generated", &generated)];
    if std::env::args().any(|a| a == "aa") {
        anti_aliasing(&sets);
        return;
    }
    if std::env::args().any(|a| a == "coherence") {
        coherence(&sets);
        return;
    }
    if std::env::args().any(|a| a == "insets") {
        insets(&work);
        return;
    }

    println!("\n| tile set | traversal | range thresholds | frames | time per frame (s) | rays/s | cells stepped per ray | pages touched per frame | speed-up vs level 0 |");
    println!("|---|---|---|---|---|---|---|---|---|");
    let mut lod_rows = Vec::new();
    for (kind, path) in sets {
        let reader = TileReader::open(path, 1024).expect("open tiles");
        let g = &reader.info().grid;
        let name = format!(
            "{kind} ({}×{}, {} m cells)",
            g.width, g.height, g.transform.cell_x
        );
        let path = flight(&reader, 6, -4.0);
        let run = |traversal, lod, frames: usize| {
            let opts = ViewOptions {
                traversal,
                lod,
                ..ViewOptions::default()
            };
            let mut out = Vec::new();
            let t = Instant::now();
            for cam in path.iter().take(frames) {
                out.push(render_view(&reader, cam, &opts).expect("render"));
            }
            (t.elapsed().as_secs_f64() / frames as f64, out)
        };
        run(Traversal::Hierarchical, false, 6); // warm the page cache: every timed run starts equal
        let hier = run(Traversal::Hierarchical, false, 6);
        let level0 = run(Traversal::Level0, false, 2);
        let lod = run(Traversal::Hierarchical, true, 6);
        // the two traversals must agree exactly on the frames both rendered
        for (a, b) in hier.1.iter().zip(&level0.1) {
            assert!(a.rgb == b.rgb, "hierarchical and level-0 frames differ");
        }
        for (label, lodf, (secs, frames)) in [
            ("hierarchical", "off", &hier),
            ("level 0", "off", &level0),
            ("hierarchical", "on", &lod),
        ] {
            let rays: u64 = frames.iter().map(|f| f.stats.rays).sum();
            let steps: u64 = frames.iter().map(|f| f.stats.cells_stepped).sum();
            let pages: usize = frames.iter().map(|f| f.stats.pages_touched).sum();
            let speedup = level0.0 / secs;
            println!(
                "| {name} | {label} | {lodf} | {} | {secs:.3} | {:.2e} | {:.1} | {:.0} | {speedup:.1}× |",
                frames.len(),
                rays as f64 / frames.len() as f64 / secs,
                steps as f64 / rays as f64,
                pages as f64 / frames.len() as f64
            );
        }
        let (diff, changed) = image_difference(&hier.1, &lod.1);
        lod_rows.push(format!(
            "| {name} | {:.1} % | {diff:.2} | {changed:.1} % |",
            100.0 * (1.0 - lod.0 / hier.0)
        ));
    }
    println!("\n| tile set | time saved by range thresholds | mean absolute difference (0–255, per channel) | pixels changed |");
    println!("|---|---|---|---|");
    for r in lod_rows {
        println!("{r}");
    }
    anti_aliasing(&sets);
    coherence(&sets);
}

/// The column-coherence table: a level flight (zero roll and pitch, where image columns are
/// vertical planes) rendered with and without coherence, range thresholds on: frames per
/// second, cells stepped per ray; the frames must be identical.
fn coherence(sets: &[(&str, &PathBuf)]) {
    println!("\n| tile set | column coherence | frames | frames per second | time per frame (s) | cells stepped per ray | speed-up |");
    println!("|---|---|---|---|---|---|---|");
    for (kind, path) in sets {
        let reader = TileReader::open(path, 1024).expect("open tiles");
        let path = flight(&reader, 24, 0.0);
        let run = |coherence| {
            let opts = ViewOptions {
                coherence,
                ..ViewOptions::default()
            };
            let t = Instant::now();
            let frames: Vec<Frame> = path
                .iter()
                .map(|cam| render_view(&reader, cam, &opts).expect("render"))
                .collect();
            (t.elapsed().as_secs_f64() / frames.len() as f64, frames)
        };
        run(true); // warm the page cache
        let (off, on) = (run(false), run(true));
        for (a, b) in off.1.iter().zip(&on.1) {
            assert!(
                a.rgb == b.rgb && a.range == b.range,
                "coherent frames differ"
            );
        }
        for (label, (secs, frames)) in [("off", &off), ("on", &on)] {
            let rays: u64 = frames.iter().map(|f| f.stats.rays).sum();
            let steps: u64 = frames.iter().map(|f| f.stats.cells_stepped).sum();
            println!(
                "| {kind} | {label} | {} | {:.1} | {secs:.4} | {:.1} | {:.2}× |",
                frames.len(),
                1.0 / secs,
                steps as f64 / rays as f64,
                off.0 / secs
            );
        }
    }
}

/// The insets table (`cargo bench --bench render -- insets`): the sample's database built
/// without and with a 4× finer inset over the middle of the flight (180 m square), the same
/// 24 level frames rendered on both (each frame's rays descend into the inset where a parent
/// cell is wider than a pixel), range thresholds on and off: frames per second, cells stepped
/// per ray. Without the inset the frames march with column coherence (the default), with it ray
/// by ray; a row without coherence shows which part of the cost is which.
fn insets(work: &Path) {
    let plain = sample::sample_tiles(work);
    let bin = env!("CARGO_BIN_EXE_dbms");
    let db = work.join("db");
    let with = work.join("sample-inset.dbt");
    if !with.exists() {
        let scene = work.join("scene");
        let t = Instant::now();
        for args in [
            vec![
                "-q".to_string(),
                "ingest".into(),
                "--dem".into(),
                scene.join("dem.tif").display().to_string(),
                "--ortho".into(),
                scene.join("ortho.tif").display().to_string(),
                "-o".into(),
                db.display().to_string(),
                "--inset".into(),
                "middle:4:500150,5300150,500330,5300330".into(),
            ],
            vec![
                "-q".into(),
                "pyramid".into(),
                "--db".into(),
                db.display().to_string(),
                "-o".into(),
                with.display().to_string(),
            ],
        ] {
            let o = Command::new(bin).args(&args).output().expect("run dbms");
            assert!(
                o.status.success(),
                "dbms {args:?}: {}",
                String::from_utf8_lossy(&o.stderr)
            );
        }
        println!(
            "inset added and tile set built in {:.1} s",
            t.elapsed().as_secs_f64()
        );
    }
    println!("\n| tile set | range thresholds | column coherence | frames | frames per second | time per frame (s) | cells stepped per ray |");
    println!("|---|---|---|---|---|---|---|");
    for (label, path) in [("sample", &plain), ("sample + 4× inset", &with)] {
        let reader = TileReader::open(path, 1024).expect("open tiles");
        let cams = flight(&reader, 24, 0.0);
        for (lod, coherence) in [(true, true), (true, false), (false, false)] {
            let opts = ViewOptions {
                lod,
                coherence,
                ..ViewOptions::default()
            };
            let run = || {
                let t = Instant::now();
                let frames: Vec<Frame> = cams
                    .iter()
                    .map(|cam| render_view(&reader, cam, &opts).expect("render"))
                    .collect();
                (t.elapsed().as_secs_f64() / frames.len() as f64, frames)
            };
            run(); // warm the page cache
            let (secs, frames) = run();
            let rays: u64 = frames.iter().map(|f| f.stats.rays).sum();
            let steps: u64 = frames.iter().map(|f| f.stats.cells_stepped).sum();
            println!(
                "| {label} | {} | {} | {} | {:.1} | {secs:.4} | {:.1} |",
                if lod { "on" } else { "off" },
                if coherence { "on" } else { "off" },
                frames.len(),
                1.0 / secs,
                steps as f64 / rays as f64
            );
        }
    }
}

/// The anti-aliasing table: error against a 64-ray blended frame and time per frame for 1, 4
/// and 16 rays per pixel, blending off and on (range thresholds on throughout).
fn anti_aliasing(sets: &[(&str, &PathBuf)]) {
    println!("\n| tile set | rays per pixel | blend | mean absolute error vs 64 rays, blended (0–255, per channel) | time per frame (s) | × the 1-ray frame |");
    println!("|---|---|---|---|---|---|");
    for &(kind, path) in sets {
        let reader = TileReader::open(path, 1024).expect("open tiles");
        let cam = &flight(&reader, 6, -4.0)[0];
        let render = |samples, blend| {
            let opts = ViewOptions {
                samples,
                blend,
                ..ViewOptions::default()
            };
            // best of two: the first also warms the page cache
            let mut best: Option<(f64, Frame)> = None;
            for _ in 0..2 {
                let t = Instant::now();
                let f = render_view(&reader, cam, &opts).expect("render");
                let secs = t.elapsed().as_secs_f64();
                if best.as_ref().is_none_or(|b| secs < b.0) {
                    best = Some((secs, f));
                }
            }
            best.expect("rendered")
        };
        let reference = render(64, true).1;
        let mut one_ray = None;
        for samples in [1, 4, 16] {
            for blend in [false, true] {
                let (secs, frame) = render(samples, blend);
                let base = *one_ray.get_or_insert(secs);
                let (error, _) = image_difference(&[frame], std::slice::from_ref(&reference));
                println!(
                    "| {kind} | {samples} | {} | {error:.2} | {secs:.3} | {:.1} |",
                    if blend { "on" } else { "off" },
                    secs / base
                );
            }
        }
    }
}

/// Rolling hills, a few sharp ridges and city blocks of 8–40 m buildings every 200 m.
fn terrain(c: usize, r: usize) -> (f32, [u8; 4]) {
    let (x, y) = (c as f32, r as f32);
    let ground = 40.0 * (x * 0.0021).sin() * (y * 0.0017).cos()
        + 12.0 * (x * 0.011 + y * 0.007).sin()
        + 3.0 * (x * 0.05).sin() * (y * 0.043).sin();
    let roof = blocks::roof(c, r, ground);
    let (building, z) = (roof.is_some(), roof.unwrap_or(ground));
    let shade = (128.0 + ground * 2.0) as u8;
    let colour = if building {
        [170, 160, 150, 255]
    } else {
        [shade / 2, shade, shade / 3, 255]
    };
    (
        z,
        [
            colour[0] ^ ((c * 31 + r * 17) % 16) as u8,
            colour[1],
            colour[2],
            255,
        ],
    )
}

/// The sample scene's tile set, made with the dbms binary if not already in `work`.
/// `n` cameras along the database's diagonal band, 25 m over the ground, pitched `pitch`
/// degrees (up positive), heading along the path.
fn flight(reader: &TileReader, n: usize, pitch: f64) -> Vec<Viewpoint> {
    let g = &reader.info().grid;
    let t = &g.transform;
    (0..n)
        .map(|k| {
            let f = 0.1 + 0.5 * k as f64 / n as f64;
            let (col, row) = (
                (g.width as f64 * f) as usize,
                (g.height as f64 * (0.8 - 0.3 * f)) as usize,
            );
            let ground = reader
                .cell(0, col, row)
                .expect("read")
                .map(|c| c.max_z)
                .filter(|z| !z.is_nan())
                .unwrap_or(0.0);
            let (x, y) = t.pixel_to_world(col as f64 + 0.5, row as f64 + 0.5);
            Viewpoint {
                eye: [x, y, ground as f64 + 25.0],
                attitude: Attitude {
                    roll: 0.0,
                    pitch,
                    yaw: 30.0,
                },
                hfov: 60.0,
                width: 640,
                height: 480,
            }
        })
        .collect()
}

/// Mean absolute difference per channel and the percentage of pixels that differ.
fn image_difference(a: &[Frame], b: &[Frame]) -> (f64, f64) {
    let (mut sum, mut changed, mut n) = (0u64, 0u64, 0u64);
    for (fa, fb) in a.iter().zip(b) {
        for (pa, pb) in fa.rgb.iter().zip(&fb.rgb) {
            let d: u64 = (0..3)
                .map(|k| (pa[k] as i64 - pb[k] as i64).unsigned_abs())
                .sum();
            sum += d;
            changed += (d > 0) as u64;
            n += 1;
        }
    }
    (
        sum as f64 / (3 * n) as f64,
        100.0 * changed as f64 / n as f64,
    )
}
