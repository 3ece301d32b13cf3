//! Benchmark: `shadow::cast_shadows` — throughput, ratio to the exact reference march, thread
//! scaling, and agreement of both rules (geometric, r.sunmask's) with GRASS GIS `r.sunmask` on a
//! real DEM.
//!
//! `cargo bench --bench shadows`. Environment:
//! * `DBMS_BENCH_SIZE`: side of the generated grid (default 4096, 1 m cells: rolling hills
//!   ±20 m with 3–25 m boxes, a few nodata holes);
//! * `DBMS_SUNMASK_DEM`: a projected float DEM for the GRASS comparison (skipped, with a
//!   message, when unset or when `grass` is not on PATH); `DBMS_SUNMASK_WINDOW=col,row,size`
//!   picks the crop (default the centre, 256 × 256: r.sunmask needs ~1 ms per cell off the axes).
//!
//! Prints Markdown tables for docs/shadows.md. All ratios are measured in the same run.

use dbms::crs::Crs;
use dbms::grid::{Grid, Window};
use dbms::raster::{Elevation, Raster};
use dbms::shadow::{cast_shadows, cast_shadows_reference, cast_shadows_sunmask, NODATA, SHADOW};
use dbms::sun::Sun;
use rayon::prelude::*;
use std::path::Path;
use std::process::Command;
use std::time::Instant;

fn main() {
    let size: usize = std::env::var("DBMS_BENCH_SIZE")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(4096);
    let terrain = synthetic(size);
    println!(
        "## cast_shadows on a generated {size} × {size} grid ({} threads)\n",
        rayon::current_num_threads()
    );
    println!("| sun elevation, azimuth | best of 3 | ns per cell | Mcells/s | cells in shadow | sunmask rule: best of 3, ns per cell, in shadow |");
    println!("|---|---|---|---|---|---|");
    for (el, az) in [
        (30.0, 0.0),
        (30.0, 45.0),
        (30.0, 127.0),
        (10.0, 200.0),
        (5.0, 300.0),
    ] {
        let (secs, mask) = best_of(3, || cast_shadows(&terrain, el, az).unwrap());
        let sun = Sun::new(el, az).unwrap();
        let (rule_s, rule) = best_of(3, || cast_shadows_sunmask(&terrain, &sun).unwrap());
        let n = terrain.data.len() as f64;
        let shade =
            |m: &Raster<u8>| 100.0 * m.data.iter().filter(|&&v| v == SHADOW).count() as f64 / n;
        println!(
            "| {el}°, {az}° | {:.1} ms | {:.2} | {:.0} | {:.1} % | {:.1} ms, {:.2}, {:.1} % |",
            secs * 1e3,
            secs * 1e9 / n,
            n / secs / 1e6,
            shade(&mask),
            rule_s * 1e3,
            rule_s * 1e9 / n,
            shade(&rule)
        );
    }

    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let (t1, _) = one.install(|| best_of(3, || cast_shadows(&terrain, 30.0, 127.0).unwrap()));
    let (tn, _) = best_of(3, || cast_shadows(&terrain, 30.0, 127.0).unwrap());
    println!(
        "\nThreads (30°, 127°): 1 thread {:.1} ms, {} threads {:.1} ms: {:.2}× faster.\n",
        t1 * 1e3,
        rayon::current_num_threads(),
        tn * 1e3,
        t1 / tn
    );

    let crop = window(
        &terrain,
        &Window {
            col: 0,
            row: 0,
            width: size.min(1024),
            height: size.min(1024),
        },
    );
    println!(
        "## Sweep against the exact reference march ({0} × {0} crop)\n",
        crop.width()
    );
    println!("| sun | sweep | reference | reference / sweep | agreement |");
    println!("|---|---|---|---|---|");
    for (el, az) in [(30.0, 0.0), (30.0, 45.0), (30.0, 127.0), (10.0, 200.0)] {
        let sun = Sun::new(el, az).unwrap();
        let (fast_s, fast) = best_of(3, || cast_shadows(&crop, el, az).unwrap());
        let (ref_s, exact) = best_of(1, || cast_shadows_reference(&crop, &sun).unwrap());
        println!(
            "| {el}°, {az}° | {:.2} ms | {:.1} ms | {:.0}× | {:.3} % |",
            fast_s * 1e3,
            ref_s * 1e3,
            ref_s / fast_s,
            agreement(&fast, &exact)
        );
    }
    sunmask_comparison();
}

/// Rolling hills (±20 m over ~100 m), boxes of 3–25 m on a 40 m lattice, nodata holes; 1 m cells.
fn synthetic(size: usize) -> Elevation {
    let grid = Grid::north_up(500_000.0, 5_300_000.0, 1.0, size, size, Crs::epsg(32632));
    let data = (0..size * size)
        .map(|i| {
            let (c, r) = ((i % size) as f64, (i / size) as f64);
            let hills =
                20.0 * (c * 0.061).sin() * (r * 0.047).cos() + 8.0 * (c * 0.013 + r * 0.021).sin();
            let (bx, by) = ((c / 40.0) as u64, (r / 40.0) as u64);
            let h = (bx * 7919 + by * 104_729) % 23;
            let in_box = (c % 40.0) < 12.0 && (r % 40.0) < 9.0 && h % 3 == 0;
            if (bx + by) % 97 == 5 && (c % 40.0) > 30.0 {
                f32::NAN
            } else {
                (300.0 + hills + if in_box { 3.0 + h as f64 } else { 0.0 }) as f32
            }
        })
        .collect();
    Elevation::new(grid, data)
}

fn best_of<T>(n: usize, mut f: impl FnMut() -> T) -> (f64, T) {
    let mut best = f64::INFINITY;
    let mut out = None;
    for _ in 0..n {
        let t = Instant::now();
        let v = f();
        best = best.min(t.elapsed().as_secs_f64());
        out = Some(v);
    }
    (best, out.unwrap())
}

fn window(e: &Elevation, w: &Window) -> Elevation {
    let data = (w.row..w.row + w.height)
        .flat_map(|r| (w.col..w.col + w.width).map(move |c| (c, r)))
        .map(|(c, r)| *e.get(c, r))
        .collect();
    Elevation::new(e.grid.window_grid(w), data)
}

/// Percentage of cells valid in both masks that agree.
fn agreement(a: &Raster<u8>, b: &Raster<u8>) -> f64 {
    let both: Vec<(u8, u8)> = a
        .data
        .iter()
        .zip(&b.data)
        .filter(|(x, y)| **x != NODATA && **y != NODATA)
        .map(|(x, y)| (*x, *y))
        .collect();
    100.0 * both.iter().filter(|(x, y)| x == y).count() as f64 / both.len().max(1) as f64
}

/// Our mask against GRASS `r.sunmask` on a crop of a real DEM, for several suns.
fn sunmask_comparison() {
    let Ok(dem_path) = std::env::var("DBMS_SUNMASK_DEM") else {
        println!("\n(r.sunmask comparison skipped: set DBMS_SUNMASK_DEM to a projected DEM)");
        return;
    };
    if Command::new("grass").arg("--version").output().is_err() {
        println!(
            "\n(r.sunmask comparison skipped: `grass` is not on PATH; apt-get install grass-core)"
        );
        return;
    }
    let dem = dbms::io::read_raster(Path::new(&dem_path))
        .unwrap()
        .to_elevation()
        .unwrap();
    let w: Vec<usize> = std::env::var("DBMS_SUNMASK_WINDOW")
        .map(|s| s.split(',').map(|v| v.trim().parse().unwrap()).collect())
        .unwrap_or_else(|_| {
            vec![
                dem.width().saturating_sub(256) / 2,
                dem.height().saturating_sub(256) / 2,
                256,
            ]
        });
    let win = Window {
        col: w[0],
        row: w[1],
        width: w[2].min(dem.width() - w[0]),
        height: w[2].min(dem.height() - w[1]),
    };
    let crop = window(&dem, &win);
    let tmp = tempfile::tempdir().unwrap();
    let crop_path = tmp.path().join("crop.tif");
    dbms::io::geotiff::write_f32(&crop_path, &crop).unwrap();
    let (cx, _) = crop.grid.cell_size();
    println!(
        "\n## Against GRASS r.sunmask: {dem_path}, window {win:?} ({} m cells, {} nodata)\n",
        cx,
        crop.nodata_count()
    );
    println!("| sun | r.sunmask shadow | geometric shadow | agreement (geometric sweep) | agreement (exact reference) | sunmask rule: shadow, agreement | bilinear-surface march: shadow, vs geometric, vs r.sunmask | r.sunmask time | µs per cell (GRASS) | ms per Mcell: geometric, sunmask rule |");
    println!("|---|---|---|---|---|---|---|---|---|---|");
    for (el, az) in [
        (2.0, 270.0),
        (3.0, 0.0),
        (3.0, 135.0),
        (4.0, 45.0),
        (5.0, 200.0),
        (3.0, 300.0),
        (6.0, 160.0),
    ] {
        let out = tmp.path().join(format!("sunmask_{el}_{az}.tif"));
        let script = format!(
            "r.in.gdal --quiet input={} output=dem && g.region raster=dem && r.sunmask --quiet -z elevation=dem output=sh altitude={el} azimuth={az} && r.out.gdal --quiet -c input=sh output={} type=Byte nodata=255",
            crop_path.display(),
            out.display()
        );
        let t = Instant::now();
        let status = Command::new("grass")
            .arg("--tmp-location")
            .arg(&crop_path)
            .arg("--exec")
            .arg("sh")
            .arg("-c")
            .arg(&script)
            .output()
            .unwrap();
        let grass_s = t.elapsed().as_secs_f64();
        if !status.status.success() {
            println!(
                "| {el}°, {az}° | r.sunmask failed: {} |",
                String::from_utf8_lossy(&status.stderr)
                    .lines()
                    .last()
                    .unwrap_or("")
            );
            continue;
        }
        // r.sunmask writes 1 in shadow and null elsewhere: null over valid height is lit.
        let src = dbms::io::read_raster(&out).unwrap();
        let theirs: Vec<u8> = (0..crop.data.len())
            .map(|i| match (crop.data[i].is_nan(), src.sample(i, 0)) {
                (true, _) => NODATA,
                (false, 1.0) => SHADOW,
                _ => 0,
            })
            .collect();
        let theirs = Raster::new(crop.grid.clone(), theirs);
        let sun = Sun::new(el, az).unwrap();
        let (ours_s, ours) = best_of(3, || cast_shadows(&crop, el, az).unwrap());
        let (rule_s, rule) = best_of(3, || cast_shadows_sunmask(&crop, &sun).unwrap());
        let exact = cast_shadows_reference(&crop, &sun).unwrap();
        let count = |m: &Raster<u8>| m.data.iter().filter(|&&v| v == SHADOW).count();
        let surface = bilinear_surface_march(&crop, el, az);
        let per_mcell = |s: f64| s * 1e9 / crop.data.len() as f64;
        println!(
            "| {el}°, {az}° | {} | {} | {:.2} % | {:.2} % | {}, {:.2} % | {}, {:.2} %, {:.2} % | {:.1} s | {:.0} | {:.1}, {:.1} |",
            count(&theirs),
            count(&ours),
            agreement(&ours, &theirs),
            agreement(&exact, &theirs),
            count(&rule),
            agreement(&rule, &theirs),
            count(&surface),
            agreement(&surface, &ours),
            agreement(&surface, &theirs),
            grass_s,
            grass_s * 1e6 / crop.data.len() as f64,
            per_mcell(ours_s),
            per_mcell(rule_s),
        );
    }
}

/// A third opinion, independent of both rules: the terrain as the continuous bilinear surface
/// through the cell centres, and each valid cell's ray toward the sun marched in steps of 1/20
/// of a cell; a cell is shadowed when the ray passes below the surface anywhere in the grid.
/// Slow (O(n · shadow length · 20)); a benchmark check, not a production model.
fn bilinear_surface_march(e: &Elevation, el: f64, az: f64) -> Raster<u8> {
    let (w, h) = (e.width(), e.height());
    let (cx, cy) = e.grid.cell_size();
    let (tan_e, a) = (el.to_radians().tan(), az.to_radians());
    let (dc, dr) = (a.sin() / cx, -a.cos() / cy); // cells per metre toward the sun
    let (lo, top) = e.min_max().unwrap();
    let at = |c: usize, r: usize| *e.get(c.min(w - 1), r.min(h - 1)) as f64;
    let surface = |x: f64, y: f64| -> f64 {
        // (x, y) in cells from the grid corner; centres at +0.5. Clamped at the edges.
        let (x, y) = (
            (x - 0.5).clamp(0.0, (w - 1) as f64),
            (y - 0.5).clamp(0.0, (h - 1) as f64),
        );
        let (c, r) = (x.floor() as usize, y.floor() as usize);
        let (fx, fy) = (x - c as f64, y - r as f64);
        let row = |r| at(c, r) * (1.0 - fx) + at(c + 1, r) * fx;
        row(r) * (1.0 - fy) + row(r + 1) * fy
    };
    let step_m = 0.05 * cx.min(cy);
    let reach_m = (top - lo) as f64 / tan_e + cx.max(cy);
    let data = (0..w * h)
        .into_par_iter()
        .map(|i| {
            let z = e.data[i] as f64;
            if z.is_nan() {
                return NODATA;
            }
            let (x0, y0) = ((i % w) as f64 + 0.5, (i / w) as f64 + 0.5);
            let mut d = step_m;
            while d < reach_m {
                let (x, y) = (x0 + d * dc, y0 + d * dr);
                if x < 0.0 || y < 0.0 || x > w as f64 || y > h as f64 {
                    break;
                }
                if surface(x, y) > z + d * tan_e {
                    return SHADOW;
                }
                d += step_m;
            }
            0
        })
        .collect();
    Raster::new(e.grid.clone(), data)
}
