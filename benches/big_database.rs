//! Benchmark: ingest and pyramid of a large generated database, against GDAL (issue 19 item 4).
//!
//! `DBMS_BIG_DIR=/some/dir cargo bench --bench big_database` (side `DBMS_BIG_SIZE`, default
//! 16384; tile side `DBMS_BIG_TILE`, default 4096). Writes an N × N database's inputs at 1 m as
//! K × K GeoTIFF tiles — `DIR/dem/*.tif` (Float32, smooth rolling hills with blocks of
//! buildings) and `DIR/ortho/*.tif` (RGBA8, a textured colour) — one tile in memory at a time
//! (a tile is itself pushed to the writer 256 rows at a time), deterministic. Skipped when
//! `DIR/inputs-N-T.done` exists. Then, each timed (wall time and peak RSS with
//! `/usr/bin/time -f "%e %M"`) through the release binary `target/release/dbms`:
//!
//! * `dbms ingest --dem DIR/dem --ortho DIR/ortho -o DIR/db` (`--max-cells` raised above 400 M)
//! * `dbms pyramid --db DIR/db -o DIR/tiles.dbt` (defaults: no sun)
//!
//! and, when `gdalbuildvrt`, `gdalwarp` and `gdaladdo` are on PATH, the same job with GDAL:
//! `gdalbuildvrt` over the tiles, `gdalwarp` onto the database grid (same `-te`/`-tr`; bilinear
//! for the DEM, average for the photo; tiled Deflate BigTIFF) and `gdaladdo -r average` with
//! levels 4 16 64 … Prints a Markdown table (wall time, peak RSS, output bytes) for
//! docs/big-database.md. `DBMS_BIG_SKIP` (comma-separated: `dbms`, `gdal`) leaves a side out;
//! `DBMS_BIG_KEEP=0` deletes each side's outputs once measured (for disk space).

#[path = "support/blocks.rs"]
mod blocks;
use dbms::crs::Crs;
use dbms::grid::Grid;
use dbms::io::geotiff::GeoTiffWriter;
use rayon::prelude::*;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

/// Lower-left corner of the generated area (UTM 32N metres).
const X0: f64 = 500_000.0;
const Y0: f64 = 5_300_000.0;

fn env_usize(name: &str, default: usize) -> usize {
    std::env::var(name)
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(default)
}

fn main() {
    let n = env_usize("DBMS_BIG_SIZE", 16384);
    let t = env_usize("DBMS_BIG_TILE", 4096).min(n);
    let dir = PathBuf::from(std::env::var("DBMS_BIG_DIR").expect(
        "set DBMS_BIG_DIR to a directory with room for the inputs and outputs (several GB)",
    ));
    let skip = std::env::var("DBMS_BIG_SKIP").unwrap_or_default();
    let keep = std::env::var("DBMS_BIG_KEEP").map_or(true, |v| v != "0");
    std::fs::create_dir_all(&dir).expect("work dir");
    println!(
        "big database: {n}² cells at 1 m ({:.0} M), tiles of {t}², threads {}",
        (n * n) as f64 / 1e6,
        rayon::current_num_threads()
    );

    let done = dir.join(format!("inputs-{n}-{t}.done"));
    if !done.exists() {
        let s = Instant::now();
        generate(&dir, n, t);
        std::fs::write(&done, b"").expect("marker");
        println!("generated inputs in {:.1} s", s.elapsed().as_secs_f64());
    }
    let dem_bytes = dir_bytes(&dir.join("dem"));
    let ortho_bytes = dir_bytes(&dir.join("ortho"));
    println!(
        "inputs: dem {} tiles {:.2} GB, ortho {:.2} GB",
        std::fs::read_dir(dir.join("dem")).unwrap().count(),
        dem_bytes as f64 / 1e9,
        ortho_bytes as f64 / 1e9
    );

    let mut rows: Vec<Row> = Vec::new();
    if !skip.contains("dbms") {
        run_dbms(&dir, n, &mut rows);
        if !keep {
            let _ = std::fs::remove_dir_all(dir.join("db"));
            let _ = std::fs::remove_file(dir.join("tiles.dbt"));
        }
    }
    let gdal = ["gdalbuildvrt", "gdalwarp", "gdaladdo"]
        .iter()
        .all(|p| Command::new(p).arg("--version").output().is_ok());
    if !skip.contains("gdal") {
        if gdal {
            run_gdal(&dir, n, &mut rows);
            if !keep {
                let _ = std::fs::remove_dir_all(dir.join("gdal"));
            }
        } else {
            println!("GDAL tools not on PATH: GDAL side skipped");
        }
    }

    println!("\n| tool | step | wall time (s) | peak RSS (MB) | output (MB) |");
    println!("|---|---|---:|---:|---:|");
    for r in &rows {
        println!(
            "| {} | {} | {:.1} | {:.0} | {} |",
            r.tool,
            r.step,
            r.wall,
            r.rss_kb as f64 / 1024.0,
            r.bytes
                .map_or("–".to_string(), |b| format!("{:.0}", b as f64 / 1e6))
        );
    }
    for tool in ["dbms", "GDAL"] {
        let of: Vec<&Row> = rows.iter().filter(|r| r.tool == tool).collect();
        if !of.is_empty() {
            println!(
                "| {tool} | **total** | {:.1} | {:.0} (max) | |",
                of.iter().map(|r| r.wall).sum::<f64>(),
                of.iter().map(|r| r.rss_kb).max().unwrap() as f64 / 1024.0
            );
        }
    }
}

/// One timed command.
struct Row {
    tool: &'static str,
    step: String,
    wall: f64,
    rss_kb: u64,
    bytes: Option<u64>,
}

/// Run `cmd args` under `/usr/bin/time -f "%e %M"`; panics if it fails.
fn timed(tool: &'static str, step: &str, cmd: &str, args: &[&str], out: Option<&Path>) -> Row {
    let stats = std::env::temp_dir().join(format!("big-database-time-{}", std::process::id()));
    match args.len() > 24 {
        true => println!(
            "$ {cmd} {} … ({} arguments)",
            args[..4].join(" "),
            args.len()
        ),
        false => println!("$ {cmd} {}", args.join(" ")),
    }
    let status = Command::new("/usr/bin/time")
        .arg("-f")
        .arg("%e %M")
        .arg("-o")
        .arg(&stats)
        .arg(cmd)
        .args(args)
        .status()
        .expect("run /usr/bin/time");
    assert!(status.success(), "{cmd} failed: {status}");
    let text = std::fs::read_to_string(&stats).expect("time output");
    let _ = std::fs::remove_file(&stats);
    let last = text.lines().last().unwrap_or("");
    let mut it = last.split_whitespace();
    let wall: f64 = it.next().and_then(|s| s.parse().ok()).expect("wall time");
    let rss_kb: u64 = it.next().and_then(|s| s.parse().ok()).expect("max RSS");
    let bytes = out.map(|p| {
        if p.is_dir() {
            dir_bytes(p)
        } else {
            std::fs::metadata(p).map(|m| m.len()).unwrap_or(0)
        }
    });
    println!(
        "  {wall:.1} s, peak RSS {:.0} MB{}",
        rss_kb as f64 / 1024.0,
        bytes.map_or(String::new(), |b| format!(", {:.2} GB", b as f64 / 1e9))
    );
    Row {
        tool,
        step: step.to_string(),
        wall,
        rss_kb,
        bytes,
    }
}

fn run_dbms(dir: &Path, n: usize, rows: &mut Vec<Row>) {
    let bin = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/release/dbms");
    let bin = bin.to_str().unwrap();
    let db = dir.join("db");
    let _ = std::fs::remove_dir_all(&db);
    let tiles = dir.join("tiles.dbt");
    let _ = std::fs::remove_file(&tiles);
    let (dem, ortho) = (dir.join("dem"), dir.join("ortho"));
    let max_cells = (n * n).max(400_000_000).to_string();
    rows.push(timed(
        "dbms",
        "ingest (DEM + photo → database layers)",
        bin,
        &[
            "ingest",
            "--dem",
            dem.to_str().unwrap(),
            "--ortho",
            ortho.to_str().unwrap(),
            "-o",
            db.to_str().unwrap(),
            "--max-cells",
            &max_cells,
        ],
        Some(&db),
    ));
    rows.push(timed(
        "dbms",
        "pyramid (levels → tile file)",
        bin,
        &[
            "pyramid",
            "--db",
            db.to_str().unwrap(),
            "-o",
            tiles.to_str().unwrap(),
        ],
        Some(&tiles),
    ));
}

fn run_gdal(dir: &Path, n: usize, rows: &mut Vec<Row>) {
    let g = dir.join("gdal");
    let _ = std::fs::remove_dir_all(&g);
    std::fs::create_dir_all(&g).expect("gdal dir");
    let te = [
        X0.to_string(),
        Y0.to_string(),
        (X0 + n as f64).to_string(),
        (Y0 + n as f64).to_string(),
    ];
    let mut levels = Vec::new();
    let mut f = 4;
    while n / f >= 64 {
        levels.push(f.to_string());
        f *= 4;
    }
    for (layer, resampling, predictor) in [("dem", "bilinear", "3"), ("ortho", "average", "2")] {
        let tifs = tile_list(&dir.join(layer));
        let vrt = g.join(format!("{layer}.vrt"));
        let out = g.join(format!("{layer}.tif"));
        let mut args = vec!["-q".to_string(), vrt.to_str().unwrap().to_string()];
        args.extend(tifs);
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        rows.push(timed(
            "GDAL",
            &format!("gdalbuildvrt {layer}"),
            "gdalbuildvrt",
            &args,
            None,
        ));
        let predictor = format!("PREDICTOR={predictor}");
        let mut args = vec![
            "-q",
            "-r",
            resampling,
            "-te",
            &te[0],
            &te[1],
            &te[2],
            &te[3],
            "-tr",
            "1",
            "1",
            "-multi",
            "-wo",
            "NUM_THREADS=ALL_CPUS",
            "-co",
            "TILED=YES",
            "-co",
            "COMPRESS=DEFLATE",
            "-co",
            &predictor,
            "-co",
            "BIGTIFF=YES",
        ];
        args.push(vrt.to_str().unwrap());
        args.push(out.to_str().unwrap());
        rows.push(timed(
            "GDAL",
            &format!("gdalwarp -r {resampling} {layer}"),
            "gdalwarp",
            &args,
            Some(&out),
        ));
        let mut args = vec![
            "-q",
            "--config",
            "COMPRESS_OVERVIEW",
            "DEFLATE",
            "--config",
            "GDAL_NUM_THREADS",
            "ALL_CPUS",
            "-r",
            "average",
            out.to_str().unwrap(),
        ];
        args.extend(levels.iter().map(String::as_str));
        rows.push(timed(
            "GDAL",
            &format!("gdaladdo -r average {layer} ({})", levels.join(" ")),
            "gdaladdo",
            &args,
            Some(&out),
        ));
    }
}

/// The `.tif` files of a directory, by name.
fn tile_list(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .expect("tile dir")
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "tif"))
        .map(|p| p.to_str().unwrap().to_string())
        .collect();
    v.sort();
    v
}

/// Total bytes of the files under `p` (recursively).
fn dir_bytes(p: &Path) -> u64 {
    let Ok(rd) = std::fs::read_dir(p) else {
        return 0;
    };
    rd.map(|e| {
        let e = e.unwrap();
        let m = e.metadata().unwrap();
        if m.is_dir() {
            dir_bytes(&e.path())
        } else {
            m.len()
        }
    })
    .sum()
}

/// Write the K × K DEM and photo tiles of the N × N grid, one tile (and 256 rows of it) in
/// memory at a time.
fn generate(dir: &Path, n: usize, t: usize) {
    for layer in ["dem", "ortho"] {
        let _ = std::fs::remove_dir_all(dir.join(layer));
        std::fs::create_dir_all(dir.join(layer)).expect("tile dir");
    }
    let k = n.div_ceil(t);
    for tr in 0..k {
        for tc in 0..k {
            let (c0, r0) = (tc * t, tr * t);
            let (w, h) = (t.min(n - c0), t.min(n - r0));
            let grid = Grid::north_up(
                X0 + c0 as f64,
                Y0 + (n - r0) as f64,
                1.0,
                w,
                h,
                Crs::epsg(32632),
            );
            let name = format!("r{tr:02}_c{tc:02}.tif");
            let mut dem = GeoTiffWriter::create_f32(&dir.join("dem").join(&name), &grid)
                .expect("create dem tile");
            let mut ortho = GeoTiffWriter::create_rgba8(&dir.join("ortho").join(&name), &grid)
                .expect("create ortho tile");
            for b0 in (0..h).step_by(256) {
                let bh = 256.min(h - b0);
                let cells: Vec<(f32, [u8; 4])> = (0..w * bh)
                    .into_par_iter()
                    .map(|i| terrain(c0 + i % w, r0 + b0 + i / w))
                    .collect();
                let z: Vec<f32> = cells.iter().map(|c| c.0).collect();
                let rgba: Vec<[u8; 4]> = cells.iter().map(|c| c.1).collect();
                dem.push_rows(&z).expect("dem rows");
                ortho.push_rows(&rgba).expect("ortho rows");
            }
            dem.finish().expect("finish dem tile");
            ortho.finish().expect("finish ortho tile");
            print!(".");
            use std::io::Write;
            let _ = std::io::stdout().flush();
        }
    }
    println!();
}

/// Ground height (m) and colour of cell (column `c`, row `r` from the north edge): rolling
/// hills at several scales, a ridge line, blocks of flat-roofed buildings every 200 m, and a
/// colour shaded by height with field stripes and per-cell texture.
fn terrain(c: usize, r: usize) -> (f32, [u8; 4]) {
    let (x, y) = (c as f32, r as f32);
    let ground = 200.0
        + 60.0 * (x * 0.0007).sin() * (y * 0.0009).cos()
        + 40.0 * (x * 0.0021).sin() * (y * 0.0017).cos()
        + 12.0 * (x * 0.011 + y * 0.007).sin()
        + 3.0 * (x * 0.05).sin() * (y * 0.043).sin()
        + 25.0 * (-((x - y * 0.6).rem_euclid(5000.0) - 2500.0).abs() / 400.0).exp();
    let roof = blocks::roof(c, r, ground);
    let (building, z) = (roof.is_some(), roof.unwrap_or(ground));
    let shade = (ground - 60.0).clamp(0.0, 255.0) as u8;
    let stripe = if (c / 37 + r / 53).is_multiple_of(5) {
        30
    } else {
        0
    };
    let noise = ((c.wrapping_mul(31) ^ r.wrapping_mul(17)).wrapping_mul(2654435761) >> 7) % 24;
    let colour = if building {
        [170, 160, 150, 255]
    } else {
        [
            (shade / 2).saturating_add(stripe),
            shade,
            (shade / 3).saturating_add(stripe / 2),
            255,
        ]
    };
    (
        z,
        [
            colour[0].saturating_add(noise as u8),
            colour[1].saturating_add((noise / 2) as u8),
            colour[2],
            255,
        ],
    )
}
