//! CLI tests of `dbms ingest` and `dbms info`: the happy path, determinism, output modes, and
//! every kind of bad input the foundation issue lists (each must fail with one line naming the
//! file and a fix, a non-zero exit, no panic and no partial output).

use dbms::crs::Crs;
use dbms::grid::Grid;
use dbms::io::geotiff;
use dbms::raster::Raster;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
#[path = "support/cli.rs"]
mod cli;
use cli::dbms;

const X0: f64 = 500_000.0;
const Y0: f64 = 5_300_000.0;

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

/// A 40 x 30 DEM at 1 m (a tilted plane) and a 80 x 60 photo at 0.5 m over the same area.
fn write_inputs(dir: &Path, dem_crs: Crs, photo_crs: Crs) -> (PathBuf, PathBuf) {
    let g = Grid::north_up(X0, Y0, 1.0, 40, 30, dem_crs);
    let dem = Raster::new(
        g.clone(),
        (0..g.len())
            .map(|i| 100.0 + (i % 40) as f32 * 0.5 - (i / 40) as f32 * 0.25)
            .collect(),
    );
    let pg = Grid::north_up(X0, Y0, 0.5, 80, 60, photo_crs);
    let photo = Raster::new(
        pg.clone(),
        (0..pg.len())
            .map(|i| [(i % 256) as u8, (i / 80 % 256) as u8, 77, 255])
            .collect(),
    );
    let (d, o) = (dir.join("dem.tif"), dir.join("ortho.tif"));
    geotiff::write_f32(&d, &dem).unwrap();
    geotiff::write_rgba8(&o, &photo).unwrap();
    (d, o)
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// The command failed cleanly: non-zero exit, one line on stderr containing `needle`, no panic.
fn assert_clean_failure(o: &Output, needle: &str) {
    let err = stderr(o);
    assert!(!o.status.success(), "expected failure, got success: {err}");
    assert_eq!(o.status.code(), Some(1), "exit code: {err}");
    assert!(!err.contains("panicked"), "panic: {err}");
    assert_eq!(err.trim_end().lines().count(), 1, "want one line: {err}");
    assert!(err.starts_with("dbms: error: "), "{err}");
    assert!(err.contains(needle), "want {needle:?} in: {err}");
}

#[test]
fn ingest_builds_a_database_and_info_describes_it() {
    let t = tempfile::tempdir().unwrap();
    let (d, o) = write_inputs(t.path(), Crs::epsg(32632), Crs::epsg(32632));
    let db = t.path().join("db");
    let out = dbms(&[
        "ingest",
        "--dem",
        s(&d),
        "--ortho",
        s(&o),
        "-o",
        s(&db),
        "--json",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["grid"]["width"], 80);
    assert_eq!(v["grid"]["height"], 60);
    assert_eq!(v["elevation"]["nodata_cells"], 0);
    // Layers are named by their content (docs/database.md): a change never overwrites a file
    // the committed manifest names.
    let manifest: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(db.join("manifest.json")).unwrap()).unwrap();
    for (layer, ext) in [("elevation", "tif"), ("colour", "tif")] {
        let l = &manifest["layers"][layer];
        let sha = l["sha256"].as_str().unwrap();
        assert_eq!(l["file"], format!("{layer}-{}.{ext}", &sha[..12]));
        assert!(db.join(l["file"].as_str().unwrap()).is_file(), "{l}");
    }
    // The photo is copied 1:1 at its own resolution.
    let colour = dbms::db::Database::open(&db)
        .unwrap()
        .read_colour()
        .unwrap();
    assert_eq!(*colour.get(3, 2), [(2 * 80 + 3) as u8, 2, 77, 255]);
    // The DEM plane is reproduced exactly by bilinear interpolation (inside its centre hull).
    let elev = dbms::db::Database::open(&db)
        .unwrap()
        .read_elevation()
        .unwrap();
    let (x, y) = elev.grid.cell_centre(20, 20);
    let expect = 100.0 + (x - X0 - 0.5) * 0.5 - (Y0 - y - 0.5) * 0.25;
    assert!((*elev.get(20, 20) as f64 - expect).abs() < 1e-4);

    let info = dbms(&["info", s(&db), "--verify"]);
    let text = String::from_utf8_lossy(&info.stdout);
    assert!(
        info.status.success()
            && text.contains("EPSG:32632")
            && text.contains("stages: ingest")
            && text.contains("verified"),
        "{text}"
    );
    let info_json: serde_json::Value =
        serde_json::from_slice(&dbms(&["info", s(&db), "--json"]).stdout).unwrap();
    assert_eq!(info_json["provenance"]["inputs"][0]["role"], "dem");
    assert_eq!(
        info_json["layers"]["elevation"]["file"],
        manifest["layers"]["elevation"]["file"]
    );
    assert!(info_json["centre"]["latitude_deg"].as_f64().unwrap() > 47.0);
}

#[test]
fn same_inputs_give_byte_identical_databases() {
    let t = tempfile::tempdir().unwrap();
    write_inputs(t.path(), Crs::epsg(32632), Crs::epsg(32632)); // as dem.tif and ortho.tif, used by relative name
    let (a, b) = (t.path().join("a"), t.path().join("b"));
    // Relative output names so the recorded command lines are identical too.
    for db in [&a, &b] {
        let out = Command::new(env!("CARGO_BIN_EXE_dbms"))
            .current_dir(db.parent().unwrap())
            .args([
                "ingest",
                "--dem",
                "dem.tif",
                "--ortho",
                "ortho.tif",
                "-o",
                "out",
                "-q",
            ])
            .output()
            .unwrap();
        assert!(out.status.success(), "{}", stderr(&out));
        std::fs::rename(t.path().join("out"), db).unwrap();
    }
    let files = |d: &std::path::Path| {
        let mut v: Vec<_> = std::fs::read_dir(d)
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        v.sort();
        v
    };
    assert_eq!(files(&a), files(&b));
    assert_eq!(files(&a).len(), 4, "{:?}", files(&a)); // manifest, 2 layers, the lock file
    for f in files(&a) {
        assert_eq!(
            std::fs::read(a.join(&f)).unwrap(),
            std::fs::read(b.join(&f)).unwrap(),
            "{f:?} differs"
        );
    }
}

#[test]
fn quiet_prints_nothing_and_human_output_goes_to_stdout() {
    let t = tempfile::tempdir().unwrap();
    let (d, o) = write_inputs(t.path(), Crs::epsg(32632), Crs::epsg(32632));
    let q = dbms(&[
        "ingest",
        "--dem",
        s(&d),
        "--ortho",
        s(&o),
        "-o",
        s(&t.path().join("q")),
        "--quiet",
    ]);
    assert!(q.status.success() && q.stdout.is_empty() && q.stderr.is_empty());
    let h = dbms(&[
        "ingest",
        "--dem",
        s(&d),
        "--ortho",
        s(&o),
        "-o",
        s(&t.path().join("h")),
    ]);
    let text = String::from_utf8_lossy(&h.stdout);
    assert!(
        text.contains("80 x 60 cells") && text.contains("nodata"),
        "{text}"
    );
}

#[test]
fn utm_coordinates_survive_to_the_centimetre() {
    let t = tempfile::tempdir().unwrap();
    let (d, o) = write_inputs(t.path(), Crs::epsg(32632), Crs::epsg(32632));
    let db = t.path().join("db");
    let bounds = format!("{},{},{},{}", X0 + 0.01, Y0 - 20.01, X0 + 10.01, Y0 - 0.01);
    let out = dbms(&[
        "ingest",
        "--dem",
        s(&d),
        "--ortho",
        s(&o),
        "--cell",
        "0.25",
        "--bounds",
        &bounds,
        "-o",
        s(&db),
        "-q",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let g = dbms::db::Database::open(&db)
        .unwrap()
        .read_elevation()
        .unwrap()
        .grid;
    // The grid corner written to and read back from GeoTIFF keeps the 1 cm offsets exactly.
    assert!(
        (g.transform.origin_x - (X0 + 0.01)).abs() < 1e-6,
        "{}",
        g.transform.origin_x
    );
    assert!(
        (g.transform.origin_y - (Y0 - 0.01)).abs() < 1e-6,
        "{}",
        g.transform.origin_y
    );
    assert_eq!((g.width, g.height), (40, 80));
}

#[test]
fn fill_voids_fills_an_interior_hole() {
    let t = tempfile::tempdir().unwrap();
    let (_, o) = write_inputs(t.path(), Crs::epsg(32632), Crs::epsg(32632));
    let g = Grid::north_up(X0, Y0, 1.0, 40, 30, Crs::epsg(32632));
    let mut dem = Raster::filled(g, 50.0f32);
    for r in 10..14 {
        for c in 10..16 {
            *dem.get_mut(c, r) = f32::NAN;
        }
    }
    let d = t.path().join("holes.tif");
    geotiff::write_f32(&d, &dem).unwrap();
    let plain: serde_json::Value = serde_json::from_slice(
        &dbms(&[
            "ingest",
            "--dem",
            s(&d),
            "--ortho",
            s(&o),
            "-o",
            s(&t.path().join("a")),
            "--json",
        ])
        .stdout,
    )
    .unwrap();
    assert!(plain["elevation"]["nodata_cells"].as_u64().unwrap() > 0);
    let filled: serde_json::Value = serde_json::from_slice(
        &dbms(&[
            "ingest",
            "--dem",
            s(&d),
            "--ortho",
            s(&o),
            "-o",
            s(&t.path().join("b")),
            "--fill-voids",
            "--json",
        ])
        .stdout,
    )
    .unwrap();
    assert_eq!(filled["elevation"]["nodata_cells"], 0);
    assert_eq!(
        filled["elevation"]["range_m"],
        serde_json::json!([50.0, 50.0])
    );
}

#[test]
fn bad_inputs_fail_cleanly_with_one_line() {
    let t = tempfile::tempdir().unwrap();
    let dir = t.path();
    let (d, o) = write_inputs(dir, Crs::epsg(32632), Crs::epsg(32632));
    let db = dir.join("db");
    let ingest = |dem: &Path, ortho: &Path, extra: &[&str]| {
        let mut a = vec!["ingest", "--dem", s(dem), "--ortho", s(ortho), "-o", s(&db)];
        a.extend_from_slice(extra);
        dbms(&a)
    };

    // Missing file.
    assert_clean_failure(
        &ingest(&dir.join("nope.tif"), &o, &[]),
        "nope.tif: no such file",
    );
    // Not a TIFF.
    let junk = dir.join("junk.tif");
    std::fs::write(&junk, "this is not a raster\n").unwrap();
    assert_clean_failure(&ingest(&junk, &o, &[]), "junk.tif: not a TIFF");
    // Truncated TIFF.
    let trunc = dir.join("trunc.tif");
    let bytes = std::fs::read(&d).unwrap();
    std::fs::write(&trunc, &bytes[..bytes.len() / 2]).unwrap();
    assert_clean_failure(
        &ingest(&trunc, &o, &[]),
        "trunc.tif: corrupt or truncated TIFF",
    );
    // Corrupt Deflate data inside a tile: the decoder's own (multi-line) message is quoted on
    // one line.
    let bad = dir.join("bad_deflate.tif");
    let mut bytes = std::fs::read(&d).unwrap();
    let (at, len) = {
        let mut dec = tiff::decoder::Decoder::new(std::fs::File::open(&d).unwrap()).unwrap();
        let mut tag = |t| dec.get_tag_u64_vec(t).unwrap()[0] as usize;
        (
            tag(tiff::tags::Tag::TileOffsets),
            tag(tiff::tags::Tag::TileByteCounts),
        )
    };
    for b in &mut bytes[at + len / 4..at + len / 2] {
        *b ^= 0x5a;
    }
    std::fs::write(&bad, &bytes).unwrap();
    assert_clean_failure(&ingest(&bad, &o, &[]), "bad_deflate.tif");
    // All-nodata DEM.
    let g = Grid::north_up(X0, Y0, 1.0, 40, 30, Crs::epsg(32632));
    let nod = dir.join("nodata.tif");
    geotiff::write_f32(&nod, &Raster::filled(g.clone(), f32::NAN)).unwrap();
    assert_clean_failure(&ingest(&nod, &o, &[]), "nodata.tif");
    // No overlap.
    let far = dir.join("far.tif");
    geotiff::write_f32(
        &far,
        &Raster::filled(
            Grid::north_up(X0 + 1e4, Y0, 1.0, 40, 30, Crs::epsg(32632)),
            1.0f32,
        ),
    )
    .unwrap();
    assert_clean_failure(&ingest(&far, &o, &[]), "does not overlap");
    // Mismatched CRS names both and says how to reproject (a GDAL build reprojects instead).
    #[cfg(not(feature = "gdal"))]
    {
        let sub = dir.join("crs");
        std::fs::create_dir(&sub).unwrap();
        let (d33, o32) = write_inputs(&sub, Crs::epsg(32633), Crs::epsg(32632));
        let e = ingest(&d33, &o32, &[]);
        assert_clean_failure(&e, "EPSG:32632");
        assert!(stderr(&e).contains("EPSG:32633") && stderr(&e).contains("gdalwarp"));
    }
    // Zero and negative cell sizes.
    assert_clean_failure(&ingest(&d, &o, &["--cell", "0"]), "--cell");
    assert_clean_failure(&ingest(&d, &o, &["--cell=-1"]), "--cell");
    // A grid larger than --max-cells.
    assert_clean_failure(&ingest(&d, &o, &["--cell", "0.001"]), "--max-cells");
    // A geographic DEM with a metric --cell.
    let geo = dir.join("geo");
    std::fs::create_dir(&geo).unwrap();
    let gd = geo.join("dem.tif");
    geotiff::write_f32(
        &gd,
        &Raster::filled(
            Grid::north_up(9.0, 48.0, 0.001, 20, 20, Crs::epsg(4326)),
            1.0f32,
        ),
    )
    .unwrap();
    let go = geo.join("ortho.tif");
    geotiff::write_rgba8(
        &go,
        &Raster::filled(
            Grid::north_up(9.0, 48.0, 0.001, 20, 20, Crs::epsg(4326)),
            [1, 2, 3, 255],
        ),
    )
    .unwrap();
    assert_clean_failure(&ingest(&gd, &go, &["--cell", "1"]), "geographic");
    // Bad --photo-time.
    assert_clean_failure(&ingest(&d, &o, &["--photo-time", "yesterday"]), "RFC 3339");
    // None of the failures left a database behind, nor a temporary file.
    assert!(!db.exists(), "a failed ingest left {}", db.display());
    let left: Vec<_> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with(".dbms-") || n.ends_with(".tmp"))
        .collect();
    assert!(left.is_empty(), "temporary files left: {left:?}");
}

/// A photo given as the DEM would make the terrain its red band; a DEM without a CRS would
/// silently take the photo's (and a photo without one the DEM's). All three are refused, each
/// naming the file and the fix (issue 14, defect 7).
#[test]
fn a_photo_as_dem_and_an_input_without_crs_are_refused() {
    let t = tempfile::tempdir().unwrap();
    let dir = t.path();
    let (_, o) = write_inputs(dir, Crs::epsg(32632), Crs::epsg(32632));
    let db = dir.join("db");
    let ingest = |dem: &Path, ortho: &Path| {
        dbms(&["ingest", "--dem", s(dem), "--ortho", s(ortho), "-o", s(&db)])
    };
    let e = ingest(&o, &o);
    assert_clean_failure(&e, "ortho.tif: has 4 bands of Byte samples");
    assert!(stderr(&e).contains("gdal_translate -b 1"), "{}", stderr(&e));

    for (dem_crs, photo_crs, unnamed, named) in [
        (Crs::unknown(), Crs::epsg(32632), "dem.tif", "orthophoto"),
        (Crs::epsg(32632), Crs::unknown(), "ortho.tif", "DEM"),
    ] {
        let sub = tempfile::tempdir_in(dir).unwrap();
        let (d, o) = write_inputs(sub.path(), dem_crs, photo_crs);
        let e = ingest(&d, &o);
        assert_clean_failure(&e, &format!("{unnamed}: has no CRS"));
        let msg = stderr(&e);
        assert!(
            msg.contains(&format!("the {named} is in EPSG:32632")),
            "{msg}"
        );
        assert!(msg.contains("gdalsrsinfo -o wkt1 EPSG:32632 >"), "{msg}");
    }
    // Both without a CRS: nothing is assumed, the database has none either.
    let sub = dir.join("none");
    std::fs::create_dir(&sub).unwrap();
    let (d0, o0) = write_inputs(&sub, Crs::unknown(), Crs::unknown());
    let ok = ingest(&d0, &o0);
    assert!(ok.status.success(), "{}", stderr(&ok));
}

#[test]
fn nan_cells_in_a_dem_are_nodata() {
    let t = tempfile::tempdir().unwrap();
    let (_, o) = write_inputs(t.path(), Crs::epsg(32632), Crs::epsg(32632));
    let g = Grid::north_up(X0, Y0, 1.0, 40, 30, Crs::epsg(32632));
    let mut dem = Raster::filled(g, 10.0f32);
    *dem.get_mut(5, 5) = f32::NAN;
    let d = t.path().join("nan.tif");
    geotiff::write_f32(&d, &dem).unwrap();
    let v: serde_json::Value = serde_json::from_slice(
        &dbms(&[
            "ingest",
            "--dem",
            s(&d),
            "--ortho",
            s(&o),
            "-o",
            s(&t.path().join("db")),
            "--json",
        ])
        .stdout,
    )
    .unwrap();
    // One 1 m DEM cell covers 2 x 2 photo-resolution database cells.
    assert_eq!(v["elevation"]["nodata_cells"], 4);
}

#[test]
fn opening_a_missing_database_explains_itself() {
    let t = tempfile::tempdir().unwrap();
    assert_clean_failure(&dbms(&["info", s(t.path())]), "not a dbms database");
}

#[cfg(not(feature = "gdal"))]
#[test]
fn t_srs_without_gdal_says_how_to_get_it() {
    let t = tempfile::tempdir().unwrap();
    let (d, o) = write_inputs(t.path(), Crs::epsg(32632), Crs::epsg(32632));
    let out = dbms(&[
        "ingest",
        "--dem",
        s(&d),
        "--ortho",
        s(&o),
        "--t-srs",
        "EPSG:32633",
        "-o",
        s(&t.path().join("db")),
    ]);
    assert_clean_failure(&out, "--features gdal");
}

/// With GDAL, inputs in different CRSs are reprojected onto the database CRS.
#[cfg(feature = "gdal")]
#[test]
fn gdal_build_reprojects_a_geographic_dem_onto_a_utm_photo() {
    let t = tempfile::tempdir().unwrap();
    // A photo in UTM 32N around 500 000 / 5 300 000 (about 47.85 N, 9 E) and a geographic DEM covering it.
    let pg = Grid::north_up(X0, Y0, 1.0, 100, 100, Crs::epsg(32632));
    let o = t.path().join("ortho.tif");
    geotiff::write_rgba8(&o, &Raster::filled(pg, [10, 20, 30, 255])).unwrap();
    let dg = Grid::north_up(8.99, 47.86, 0.0001, 300, 300, Crs::epsg(4326));
    let d = t.path().join("dem.tif");
    geotiff::write_f32(&d, &Raster::filled(dg, 321.0f32)).unwrap();
    let db = t.path().join("db");
    let out = dbms(&[
        "ingest",
        "--dem",
        s(&d),
        "--ortho",
        s(&o),
        "--t-srs",
        "EPSG:32632",
        "--cell",
        "2",
        "-o",
        s(&db),
        "--json",
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let v: serde_json::Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(v["grid"]["crs"]["epsg"], 32632);
    assert_eq!(v["elevation"]["nodata_cells"], 0);
    assert_eq!(v["elevation"]["range_m"], serde_json::json!([321.0, 321.0]));
    let colour = dbms::db::Database::open(&db)
        .unwrap()
        .read_colour()
        .unwrap();
    assert_eq!(*colour.get(10, 10), [10, 20, 30, 255]);
}

/// With GDAL, a photo in another CRS follows the same rule as a native one: refined bilinearly
/// (a 1 m stripe pattern onto 0.25 m cells gets intermediate shades), not by `average`, which
/// would copy the nearest photo cell.
#[cfg(feature = "gdal")]
#[test]
fn gdal_build_refines_a_reprojected_photo_bilinearly() {
    let t = tempfile::tempdir().unwrap();
    let dem = t.path().join("dem.tif");
    geotiff::write_f32(
        &dem,
        &Raster::filled(
            Grid::north_up(X0, Y0, 1.0, 40, 40, Crs::epsg(32632)),
            50.0f32,
        ),
    )
    .unwrap();
    // ETRS89 / UTM 32N: the same lattice to well under a millimetre, but another CRS.
    let pg = Grid::north_up(X0, Y0, 1.0, 40, 40, Crs::epsg(25832));
    let photo = Raster::new(
        pg.clone(),
        (0..pg.len())
            .map(|i| {
                if i % 2 == 0 {
                    [0, 0, 0, 255]
                } else {
                    [200, 200, 200, 255]
                }
            })
            .collect(),
    );
    let o = t.path().join("ortho.tif");
    geotiff::write_rgba8(&o, &photo).unwrap();
    let db = t.path().join("db");
    let bounds = format!("{},{},{},{}", X0 + 5.0, Y0 - 35.0, X0 + 35.0, Y0 - 5.0);
    let out = dbms(&[
        "--quiet",
        "ingest",
        "--dem",
        s(&dem),
        "--ortho",
        s(&o),
        "--cell",
        "0.25",
        "--bounds",
        &bounds,
        "-o",
        s(&db),
    ]);
    assert!(out.status.success(), "{}", stderr(&out));
    let colour = dbms::db::Database::open(&db)
        .unwrap()
        .read_colour()
        .unwrap();
    let between = colour
        .data
        .iter()
        .filter(|p| p[3] != 0 && p[0] > 30 && p[0] < 170)
        .count();
    assert!(
        between * 4 > colour.data.len(),
        "{between} of {} cells between the stripes' shades",
        colour.data.len()
    );
}

/// A DEM whose CRS is in US survey feet (an Esri .prj, as ArcGIS writes for State Plane) is
/// refused with the unit named and how to reproject: read as metres, every height and distance
/// would be wrong by 3.28×, silently.
#[test]
fn a_dem_in_feet_is_refused_with_the_unit_named() {
    let t = tempfile::tempdir().unwrap();
    let dem = t.path().join("dem.asc");
    let mut text = String::from(
        "ncols 4\nnrows 4\nxllcorner 2000000\nyllcorner 7000000\ncellsize 10\nNODATA_value -9999\n",
    );
    for _ in 0..4 {
        text.push_str("500 501 502 503\n");
    }
    std::fs::write(&dem, text).unwrap();
    std::fs::write(
        t.path().join("dem.prj"),
        r#"PROJCS["NAD_1983_StatePlane_Texas_Central_FIPS_4203_Feet",GEOGCS["GCS_North_American_1983",DATUM["D_North_American_1983",SPHEROID["GRS_1980",6378137.0,298.257222101]],PRIMEM["Greenwich",0.0],UNIT["Degree",0.0174532925199433]],PROJECTION["Lambert_Conformal_Conic"],PARAMETER["False_Easting",2296583.333333333],PARAMETER["Central_Meridian",-100.3333333333333],UNIT["Foot_US",0.3048006096012192]]"#,
    )
    .unwrap();
    let photo = t.path().join("ortho.tif");
    geotiff::write_rgba8(
        &photo,
        &Raster::filled(
            Grid::north_up(2_000_000.0, 7_000_040.0, 5.0, 8, 8, Crs::unknown()),
            [1, 2, 3, 255],
        ),
    )
    .unwrap();
    std::fs::copy(t.path().join("dem.prj"), t.path().join("ortho.prj")).unwrap();
    let out = dbms(&[
        "ingest",
        "--dem",
        s(&dem),
        "--ortho",
        s(&photo),
        "-o",
        s(&t.path().join("db")),
    ]);
    assert_clean_failure(&out, "Foot_US");
    let e = stderr(&out);
    assert!(
        e.contains("dem.asc") && e.contains("gdalwarp -t_srs"),
        "{e}"
    );
}
