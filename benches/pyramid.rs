//! Benchmark: `dbms pyramid` against GDAL making the same levels, on one generated grid.
//!
//! `cargo bench --bench pyramid` (size from `DBMS_BENCH_SIZE`, default 8192; work directory from
//! `DBMS_BENCH_DIR`, default a temporary one). Steps:
//! 1. generate a W×W database (rolling terrain with nodata holes, a textured colour layer) with
//!    the library's GeoTIFF writers — not timed;
//! 2. ours: `dbms pyramid` (the release binary, as a modeller runs it: factor 4, pages of 256, no
//!    sun) from the database's GeoTIFFs to the tile file, under `/usr/bin/time` for its peak
//!    memory, its `--json` summary giving the time of each step;
//! 3. GDAL, when `gdalwarp` is on PATH: the same max-Z levels with `gdalwarp -r max -tr`, each
//!    level from the previous, and the average-colour levels with `gdaladdo -r average 4 16 64`
//!    (both multi-threaded), each run under `/usr/bin/time` for its peak memory;
//! 4. every max-Z level of ours compared cell by cell with GDAL's (must be identical).
//!
//! Prints a Markdown table for docs/pyramid.md.

#[path = "support/rolling_db.rs"]
mod rolling_db;

use dbms::tiles::TileReader;
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
    let db_dir = work.join("db");
    let t = Instant::now();
    rolling_db::make_database(&db_dir, size);
    eprintln!(
        "generated {size}×{size} database in {:.1} s",
        t.elapsed().as_secs_f64()
    );

    let tiles = work.join("bench.dbt");
    // Like GDAL's outputs below, ours starts from nothing: replacing a previous 645 MB file
    // would add the file system's freeing of it to our time.
    let _ = std::fs::remove_file(&tiles);
    let (ours_s, ours_kb, steps) = run_ours(&db_dir, &tiles);
    let mut rows = vec![(
        "dbms pyramid (all levels: max Z, colour, state; tile file)".to_string(),
        ours_s,
        Some(ours_kb),
    )];
    let names = [
        "open the two layers (decoded band by band inside levels)",
        "prepare (no sun: nothing)",
        "levels: layers decoded band by band, reductions, pages written in place",
        "tile writer's finish (index, fsync, rename)",
    ];
    for (name, s) in names.iter().zip(&steps) {
        rows.push((format!("  of which: {name}"), *s, None));
    }

    if which("gdalwarp") && which("gdaladdo") {
        let cell = [1.0f64, 4.0, 16.0, 64.0];
        let mut prev = db_dir.join("elevation.tif");
        let mut gdal_total = 0.0;
        let mut gdal_peak = 0u64;
        for (k, c) in cell.iter().enumerate().skip(1) {
            let out = work.join(format!("gdal_level{k}_maxz.tif"));
            let _ = std::fs::remove_file(&out);
            let (s, kb, _) = timed(
                Command::new("gdalwarp")
                    .args([
                        "-q",
                        "-multi",
                        "-wo",
                        "NUM_THREADS=ALL_CPUS",
                        "-r",
                        "max",
                        "-tr",
                    ])
                    .arg(c.to_string())
                    .arg(c.to_string())
                    .arg(&prev)
                    .arg(&out),
            );
            rows.push((
                format!(
                    "gdalwarp -r max -tr {c} {c} (level {k} from level {})",
                    k - 1
                ),
                s,
                kb,
            ));
            gdal_total += s;
            gdal_peak = gdal_peak.max(kb.unwrap_or(0));
            prev = out;
        }
        let colour = work.join("gdal_colour.tif");
        std::fs::copy(db_dir.join("colour.tif"), &colour).expect("copy colour");
        let (s, kb, _) = timed(
            Command::new("gdaladdo")
                .args([
                    "-q",
                    "-r",
                    "average",
                    "--config",
                    "GDAL_NUM_THREADS",
                    "ALL_CPUS",
                ])
                .arg(&colour)
                .args(["4", "16", "64"]),
        );
        rows.push(("gdaladdo -r average 4 16 64 (colour)".to_string(), s, kb));
        gdal_total += s;
        gdal_peak = gdal_peak.max(kb.unwrap_or(0));
        rows.push((
            "GDAL total (max-Z levels + colour overviews)".to_string(),
            gdal_total,
            Some(gdal_peak),
        ));
        let identical = compare_max_z(&tiles, &work);
        print_table(size, &rows);
        println!(
            "\nours / GDAL speed-up: {:.2}×; max-Z identical to GDAL's on levels 1–3: {identical}",
            gdal_total / ours_s
        );
    } else {
        print_table(size, &rows);
        println!("\nskipped GDAL comparison: gdalwarp / gdaladdo not found on PATH");
    }
}

/// Ours as a modeller runs it: the `dbms pyramid` command (release build) on the database,
/// under `/usr/bin/time` for its peak memory; its `--json` summary gives the steps' seconds.
fn run_ours(db_dir: &Path, tiles: &Path) -> (f64, u64, Vec<f64>) {
    let mut cmd = Command::new(env!("CARGO_BIN_EXE_dbms"));
    cmd.arg("--quiet")
        .arg("--json")
        .arg("pyramid")
        .arg("--db")
        .arg(db_dir)
        .arg("-o")
        .arg(tiles);
    let (secs, kb, stdout) = timed(&mut cmd);
    let summary: serde_json::Value = serde_json::from_str(&stdout).expect("dbms --json summary");
    let steps = ["read", "prepare", "levels", "finish"]
        .iter()
        .map(|k| summary["seconds"][k].as_f64().expect("step seconds"))
        .collect();
    (secs, kb.unwrap_or(0), steps)
}

/// Run a command, returning wall seconds, (under /usr/bin/time) peak resident kB, and stdout.
fn timed(cmd: &mut Command) -> (f64, Option<u64>, String) {
    let have_time = Path::new("/usr/bin/time").exists();
    let t = Instant::now();
    let o = if have_time {
        let mut wrapped = Command::new("/usr/bin/time");
        wrapped
            .args(["-f", "%M"])
            .arg(cmd.get_program())
            .args(cmd.get_args());
        wrapped.output()
    } else {
        cmd.output()
    }
    .expect("run command");
    let secs = t.elapsed().as_secs_f64();
    assert!(
        o.status.success(),
        "{:?}: {}",
        cmd,
        String::from_utf8_lossy(&o.stderr)
    );
    let kb = have_time
        .then(|| {
            String::from_utf8_lossy(&o.stderr)
                .lines()
                .last()
                .and_then(|l| l.trim().parse().ok())
        })
        .flatten();
    (secs, kb, String::from_utf8_lossy(&o.stdout).into_owned())
}

fn which(tool: &str) -> bool {
    Command::new(tool)
        .arg("--version")
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false)
}

/// Every cell of our levels 1..3 against GDAL's max-Z GeoTIFFs: bit-identical or both nodata.
fn compare_max_z(tiles: &Path, work: &Path) -> bool {
    let r = TileReader::open(tiles, 4096).expect("open tiles");
    let mut all = true;
    for k in 1..r.info().levels.len().min(4) {
        let g = dbms::io::read_raster(&work.join(format!("gdal_level{k}_maxz.tif")))
            .expect("read GDAL level")
            .to_elevation()
            .expect("as elevation");
        let l = &r.info().levels[k];
        if (g.grid.width, g.grid.height) != (l.width, l.height) {
            println!(
                "level {k}: GDAL made {}×{}, we made {}×{}",
                g.grid.width, g.grid.height, l.width, l.height
            );
            all = false;
            continue;
        }
        let differ = (0..l.width * l.height)
            .filter(|&i| {
                let ours = r
                    .cell(k, i % l.width, i / l.width)
                    .expect("cell")
                    .expect("in range")
                    .max_z;
                let theirs = g.data[i];
                !(ours.to_bits() == theirs.to_bits() || (ours.is_nan() && theirs.is_nan()))
            })
            .count();
        println!(
            "level {k}: {differ} of {} max-Z cells differ from GDAL",
            l.width * l.height
        );
        all &= differ == 0;
    }
    all
}

fn print_table(size: usize, rows: &[(String, f64, Option<u64>)]) {
    println!(
        "\n{size}×{size} cells, {} threads\n",
        rayon::current_num_threads()
    );
    println!("| step | wall time (s) | peak memory (MB) |");
    println!("|---|---:|---:|");
    for (what, s, kb) in rows {
        let mb = kb
            .map(|k| format!("{:.0}", k as f64 / 1024.0))
            .unwrap_or_else(|| "n/a".to_string());
        println!("| {what} | {s:.2} | {mb} |");
    }
}
