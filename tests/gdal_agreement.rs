//! Agreement of `dbms ingest` with GDAL on the same target grid (the foundation issue's goal):
//! elevation within 1e-3 m RMS of `gdalwarp -r bilinear` with the same nodata cells, colour
//! within 1 grey level RMS of `gdalwarp -r average`, and `gdalinfo` reading both layers with the
//! database grid's georeference. Runs only where `gdalwarp` is on PATH; elsewhere it prints why
//! it skipped, except under CI (`CI` set), whose .ci/run installs gdal-bin: there it fails.
//!
//! Where the cell ratio is an integer or the target is finer, both tools compute the same
//! weights and agree to float32 rounding. At non-integer coarsening ratios GDAL takes its kernel
//! scale from chunk sizes (e.g. 69 target over 96 source cells = 0.719 instead of 1/1.4 = 0.714),
//! we use the exact ratio; the difference is bounded and printed, see docs/ingest.md.

use dbms::crs::Crs;
use dbms::grid::Grid;
use dbms::io::{geotiff, read_raster};
use dbms::raster::Raster;
use std::path::Path;
use std::process::Command;

/// Whether GDAL's tools are on PATH to compare with; if not, says the test is skipped. Under
/// CI (`CI` set), whose .ci/run installs gdal-bin, a missing gdalwarp is a broken setup, not a
/// reason to skip: it fails.
fn gdal_tools() -> bool {
    let found = Command::new("gdalwarp")
        .arg("--version")
        .output()
        .map(|o| o.status.success())
        .unwrap_or(false);
    if !found {
        assert!(
            std::env::var_os("CI").is_none(),
            "gdalwarp not found under CI: .ci/run installs gdal-bin"
        );
        println!("skipped: GDAL's tools not found (install gdal-bin to run this comparison)");
    }
    found
}

/// Smooth but non-planar terrain with a nodata hole, at UTM coordinates.
fn terrain(g: &Grid) -> Raster<f32> {
    let data = (0..g.len())
        .map(|i| {
            let (c, r) = ((i % g.width) as f64, (i / g.width) as f64);
            if (30.0..38.0).contains(&c) && (20.0..25.0).contains(&r) {
                return f32::NAN;
            }
            (200.0 + 8.0 * (c * 0.11).sin() * (r * 0.07).cos() + 0.05 * c * r / 10.0) as f32
        })
        .collect();
    Raster::new(g.clone(), data)
}

fn photo(g: &Grid) -> Raster<[u8; 4]> {
    let data = (0..g.len())
        .map(|i| {
            let (c, r) = (i % g.width, i / g.width);
            let v = |k: usize| {
                (128.0 + 100.0 * (c as f64 * 0.09 + k as f64).sin() * (r as f64 * 0.05).cos()) as u8
            };
            if c < 6 && r < 6 {
                [0, 0, 0, 0]
            } else {
                [v(0), v(1), (c % 256) as u8, 255]
            }
        })
        .collect();
    Raster::new(g.clone(), data)
}

fn run(cmd: &mut Command) {
    let o = cmd.output().expect("spawn");
    assert!(
        o.status.success(),
        "{:?}: {}",
        cmd,
        String::from_utf8_lossy(&o.stderr)
    );
}

/// RMS difference over cells valid in both, and whether the validity masks are identical.
fn compare(ours: &[f64], theirs: &[f64]) -> (f64, usize) {
    let (mut sum, mut n, mut mismatched) = (0.0, 0usize, 0usize);
    for (a, b) in ours.iter().zip(theirs) {
        match (a.is_nan(), b.is_nan()) {
            (false, false) => {
                sum += (a - b) * (a - b);
                n += 1;
            }
            (true, true) => {}
            _ => mismatched += 1,
        }
    }
    ((sum / n.max(1) as f64).sqrt(), mismatched)
}

/// The file of `db`'s layer `name` (named by its content: docs/database.md).
fn layer(db: &Path, name: &str) -> std::path::PathBuf {
    dbms::db::Database::open(db)
        .unwrap()
        .layer_path(name)
        .unwrap()
}

/// Ingest at `cell` and compare with gdalwarp; returns (elevation RMS m, colour RMS grey levels).
/// GDAL opens the database's two layers with the grid's georeference, CRS and nodata.
fn gdal_sees_the_database_grid(db: &Path, g: &Grid) {
    let t = &g.transform;
    let geo = serde_json::json!([t.origin_x, t.cell_x, 0.0, t.origin_y, 0.0, t.cell_y]);
    for (file, types, interp) in [
        ("elevation", &["Float32"][..], &["Gray"][..]),
        (
            "colour",
            &["Byte"; 4][..],
            &["Red", "Green", "Blue", "Alpha"][..],
        ),
    ] {
        let out = Command::new("gdalinfo")
            .arg("-json")
            .arg(layer(db, file))
            .output()
            .expect("gdalinfo comes with gdalwarp");
        assert!(out.status.success(), "gdalinfo rejected {file}");
        let info: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
        assert_eq!(info["geoTransform"], geo, "{file}");
        assert_eq!(
            info["size"],
            serde_json::json!([g.width, g.height]),
            "{file}"
        );
        let wkt = info["coordinateSystem"]["wkt"].as_str().unwrap();
        assert!(wkt.ends_with("ID[\"EPSG\",32632]]"), "{file}: {wkt}");
        assert_eq!(info["metadata"][""]["AREA_OR_POINT"], "Area", "{file}");
        let bands = info["bands"].as_array().unwrap();
        let got: Vec<(&str, &str)> = bands
            .iter()
            .map(|b| {
                (
                    b["type"].as_str().unwrap(),
                    b["colorInterpretation"].as_str().unwrap(),
                )
            })
            .collect();
        let want: Vec<(&str, &str)> = types.iter().copied().zip(interp.iter().copied()).collect();
        assert_eq!(got, want, "{file}");
    }
}

/// A 0.5 m DEM and a 0.25 m photo of the same 48 × 32 m (`terrain`, `photo`) written into
/// `dir` as dem.tif and ortho.tif.
fn inputs(dir: &Path) -> (std::path::PathBuf, std::path::PathBuf) {
    let crs = Crs::epsg(32632);
    let dem_grid = Grid::north_up(500_000.0, 5_300_000.0, 0.5, 96, 64, crs.clone());
    let photo_grid = Grid::north_up(500_000.0, 5_300_000.0, 0.25, 192, 128, crs);
    let (dem, ortho) = (dir.join("dem.tif"), dir.join("ortho.tif"));
    geotiff::write_f32(&dem, &terrain(&dem_grid)).unwrap();
    geotiff::write_rgba8(&ortho, &photo(&photo_grid)).unwrap();
    (dem, ortho)
}

fn agreement(dir: &Path, cell: f64) -> (f64, f64) {
    let (dem, ortho) = inputs(dir);
    let db = dir.join(format!("db{cell}"));
    run(Command::new(env!("CARGO_BIN_EXE_dbms"))
        .args(["ingest", "-q", "--cell", &cell.to_string(), "-o"])
        .arg(&db)
        .arg("--dem")
        .arg(&dem)
        .arg("--ortho")
        .arg(&ortho));
    let elev = read_raster(&layer(&db, "elevation"))
        .unwrap()
        .to_elevation()
        .unwrap();
    let g = &elev.grid;
    gdal_sees_the_database_grid(&db, g);
    let b = g.bounds();
    let te = [b.min_x, b.min_y, b.max_x, b.max_y].map(|v| v.to_string());
    let (gdem, gcol) = (
        dir.join(format!("g{cell}.tif")),
        dir.join(format!("gc{cell}.tif")),
    );
    let warp = |r: &str, src: &Path, dst: &Path, extra: &[&str]| {
        run(Command::new("gdalwarp")
            .args(["-q", "-overwrite", "-r", r, "-te"])
            .args(&te)
            .args(["-tr", &cell.to_string(), &cell.to_string()])
            .args(extra)
            .arg(src)
            .arg(dst));
    };
    warp("bilinear", &dem, &gdem, &["-dstnodata", "-9999"]);
    warp("average", &ortho, &gcol, &["-dstalpha"]);

    let theirs = read_raster(&gdem).unwrap().to_elevation().unwrap();
    assert_eq!((theirs.grid.width, theirs.grid.height), (g.width, g.height));
    let f = |v: &Vec<f32>| v.iter().map(|&x| x as f64).collect::<Vec<_>>();
    let (elev_rms, mismatched) = compare(&f(&elev.data), &f(&theirs.data));
    println!("cell {cell}: elevation RMS vs gdalwarp -r bilinear = {elev_rms:.3e} m, nodata mismatches = {mismatched}");
    assert_eq!(mismatched, 0, "nodata cells differ from gdalwarp");

    let ours = read_raster(&layer(&db, "colour"))
        .unwrap()
        .to_colour()
        .unwrap();
    let theirs = read_raster(&gcol).unwrap().to_colour().unwrap();
    let grey = |c: &Raster<[u8; 4]>| {
        c.data
            .iter()
            .flat_map(|p| (0..3).map(move |k| if p[3] == 0 { f64::NAN } else { p[k] as f64 }))
            .collect::<Vec<_>>()
    };
    let (colour_rms, mismatched) = compare(&grey(&ours), &grey(&theirs));
    println!("cell {cell}: colour RMS vs gdalwarp -r average = {colour_rms:.3} grey levels, nodata mismatches = {mismatched}");
    assert_eq!(mismatched, 0, "colour nodata cells differ from gdalwarp");
    (elev_rms, colour_rms)
}

#[test]
fn ingest_agrees_with_gdalwarp() {
    if !gdal_tools() {
        return;
    }
    let t = tempfile::tempdir().unwrap();
    // The photo's cell, the DEM's, and integer coarsening: the same weights, float32 rounding apart.
    for cell in [0.25, 0.5, 1.0, 2.0] {
        let (e, c) = agreement(t.path(), cell);
        assert!(e < 1e-5, "cell {cell}: elevation RMS {e} m");
        assert!(c < 0.5, "cell {cell}: colour RMS {c}");
    }
    // Non-integer coarsening: GDAL's chunk-derived kernel scale differs slightly from the exact one.
    for cell in [0.6, 0.7, 1.3] {
        let (e, c) = agreement(t.path(), cell);
        assert!(e < 5e-3, "cell {cell}: elevation RMS {e} m");
        assert!(c < 1.0, "cell {cell}: colour RMS {c}");
    }
}

/// Internal masks as GDAL writes them (`GDAL_TIFF_INTERNAL_MASK=YES`: 1 bit a cell) read as
/// GDAL reads them: our alpha band is `gdal_translate -b mask`'s, cell for cell, whole and by
/// rows across chunk rows, for tiled Deflate, stripped LZW and uncompressed layouts, and for a
/// sparse file whose fully masked blocks GDAL leaves out.
#[test]
fn internal_masks_read_as_gdal_reads_them() {
    if !gdal_tools() {
        return;
    }
    let t = tempfile::tempdir().unwrap();
    let g = Grid::north_up(500_000.0, 5_300_000.0, 0.5, 75, 41, Crs::epsg(32632));
    // Alpha off in a ragged pattern, and in one whole 32 × 16 block (black there, so a sparse
    // writer can leave out both the block and its mask).
    let data = (0..g.len())
        .map(|i| {
            let (c, r) = (i % g.width, i / g.width);
            if (32..64).contains(&c) && (16..32).contains(&r) {
                [0, 0, 0, 0]
            } else {
                let a = if (c * 7 + r * 3) % 11 < 4 { 0 } else { 255 };
                [(c * 3) as u8, (r * 5) as u8, (c ^ r) as u8, a]
            }
        })
        .collect();
    let rgba = t.path().join("rgba.tif");
    geotiff::write_rgba8(&rgba, &Raster::new(g.clone(), data)).unwrap();
    // Creation options by name; "tiled" and "sparse" differ only in SPARSE_OK.
    let tiled = [
        "-co",
        "TILED=YES",
        "-co",
        "BLOCKXSIZE=32",
        "-co",
        "BLOCKYSIZE=16",
    ];
    let with = |extra: &[&'static str]| [&tiled[..], extra].concat();
    let layouts: [(&str, Vec<&str>); 5] = [
        ("deflate", with(&["-co", "COMPRESS=DEFLATE"])),
        (
            "lzw-strips",
            vec!["-co", "BLOCKYSIZE=7", "-co", "COMPRESS=LZW"],
        ),
        ("strips", vec!["-co", "BLOCKYSIZE=5"]),
        ("sparse", with(&["-co", "SPARSE_OK=TRUE"])),
        ("tiled", tiled.to_vec()),
    ];
    let masked = |name: &str| t.path().join(format!("masked-{name}.tif"));
    for (name, options) in &layouts {
        let file = masked(name);
        let gdal_mask = t.path().join(format!("mask-{name}.tif"));
        run(Command::new("gdal_translate")
            .args(["-q", "-b", "1", "-b", "2", "-b", "3", "-mask", "4"])
            .args(["--config", "GDAL_TIFF_INTERNAL_MASK", "YES"])
            .args(options)
            .arg(&rgba)
            .arg(&file));
        run(Command::new("gdal_translate")
            .args(["-q", "-b", "mask"])
            .arg(&file)
            .arg(&gdal_mask));
        let theirs = match read_raster(&gdal_mask).unwrap().samples {
            dbms::io::Samples::U8(v) => v,
            other => panic!("{name}: GDAL's mask is {other:?}"),
        };
        let alpha = |rows: std::ops::Range<usize>| -> Vec<u8> {
            let s = geotiff::read_rows(&file, rows.clone()).unwrap();
            assert_eq!((s.bands, s.alpha_band), (4, Some(3)), "{name}");
            match s.samples {
                dbms::io::Samples::U8(v) => v.chunks(4).map(|px| px[3]).collect(),
                other => panic!("{name}: {other:?}"),
            }
        };
        for rows in [0..41, 13..30, 15..17, 40..41] {
            let want = &theirs[rows.start * 75..rows.end * 75];
            assert!(alpha(rows.clone()) == want, "{name}: rows {rows:?}");
        }
    }
    // The tiled layout without SPARSE_OK stores the black block and its mask.
    let size = |name| std::fs::metadata(masked(name)).unwrap().len();
    assert!(
        size("sparse") + 32 * 16 * 3 <= size("tiled"),
        "SPARSE_OK left no block out"
    );
}

/// `dbms ingest` from tiles GDAL cut (`gdal_translate -srcwin`, uneven sizes, tiled Deflate and
/// striped LZW) gives the same layers, byte for byte, as from the whole files: from a directory,
/// a list file and `gdalbuildvrt`'s mosaic (issue 19, inputs larger than memory).
#[test]
fn ingest_from_gdal_cut_tiles_equals_the_whole() {
    if !gdal_tools() {
        return;
    }
    let t = tempfile::tempdir().unwrap();
    let dir = t.path();
    let (dem, ortho) = inputs(dir);
    let cut = |src: &Path, to: &str, windows: &[[usize; 4]], opts: &[&str]| {
        std::fs::create_dir_all(dir.join(to)).unwrap();
        for [c, r, w, h] in windows {
            let out = dir.join(to).join(format!("t_{c}_{r}.tif"));
            let win = [c, r, w, h].map(|v| v.to_string());
            run(Command::new("gdal_translate")
                .args(["-q", "-srcwin", &win[0], &win[1], &win[2], &win[3]])
                .args(opts)
                .arg(src)
                .arg(&out));
        }
    };
    let tiled = ["-co", "TILED=YES", "-co", "COMPRESS=DEFLATE"];
    cut(
        &dem,
        "dem",
        &[
            [0, 0, 50, 30],
            [50, 0, 46, 30],
            [0, 30, 50, 34],
            [50, 30, 46, 34],
        ],
        &tiled,
    );
    cut(
        &ortho,
        "ortho",
        &[[0, 0, 120, 128], [120, 0, 72, 128]],
        &["-co", "COMPRESS=LZW"],
    );
    let list = "# the DEM's tiles, one a line\nt_0_0.tif\nt_50_0.tif\n\nt_0_30.tif\nt_50_30.tif\n";
    std::fs::write(dir.join("dem/tiles.txt"), list).unwrap();
    let ingest = |db: &str, dem: &Path, ortho: &Path| {
        run(Command::new(env!("CARGO_BIN_EXE_dbms"))
            .args(["ingest", "-q", "--cell", "0.5", "-o"])
            .arg(dir.join(db))
            .arg("--dem")
            .arg(dem)
            .arg("--ortho")
            .arg(ortho));
    };
    // gdalbuildvrt's mosaics of the same tiles.
    for (vrt, tiles) in [("dem.vrt", "dem"), ("ortho.vrt", "ortho")] {
        let mut tifs: Vec<_> = std::fs::read_dir(dir.join(tiles))
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|e| e == "tif"))
            .collect();
        tifs.sort();
        run(Command::new("gdalbuildvrt")
            .arg("-q")
            .arg(dir.join(vrt))
            .args(&tifs));
    }
    ingest("whole", &dem, &ortho);
    ingest("dir", &dir.join("dem"), &dir.join("ortho"));
    ingest("list", &dir.join("dem/tiles.txt"), &dir.join("ortho"));
    ingest("vrt", &dir.join("dem.vrt"), &dir.join("ortho.vrt"));
    for db in ["dir", "list", "vrt"] {
        for name in ["elevation", "colour"] {
            let (a, b) = (layer(&dir.join("whole"), name), layer(&dir.join(db), name));
            assert_eq!(
                std::fs::read(&a).unwrap(),
                std::fs::read(&b).unwrap(),
                "{db} {name}"
            );
        }
    }
    // The manifest names every tile read.
    let manifest = std::fs::read_to_string(dir.join("list/manifest.json")).unwrap();
    assert!(manifest.contains("t_50_30.tif") && manifest.contains("t_120_0.tif"));
}
