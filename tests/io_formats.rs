//! Raster input/output against fixtures made by GDAL (tests/data/make_fixtures.sh): every format
//! and layout reads to the exact values and the georeference `gdalinfo -json` reported when the
//! fixtures were made; our writers round-trip bit-exactly and (when gdalinfo is installed) GDAL
//! reads what we write; every bad input is a one-line error naming the file.

use dbms::crs::Crs;
use dbms::grid::{GeoTransform, Grid};
use dbms::io::{geotiff, read_raster, Samples, SourceRaster};
use dbms::raster::{Colour, Raster};
use std::path::{Path, PathBuf};

const W: usize = 20;
const H: usize = 15;
/// Cells that hold nodata in the fixtures that declare one.
const NODATA_CELLS: [(usize, usize); 2] = [(3, 2), (10, 7)];

fn data(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data").join(name)
}

fn read(name: &str) -> SourceRaster {
    read_raster(&data(name)).unwrap_or_else(|e| panic!("{name}: {e}"))
}

/// The fixtures' elevation formula (see make_fixtures.sh).
fn e(c: usize, r: usize) -> i32 {
    1000 + 37 * c as i32 - 53 * r as i32
}

fn rgb(c: usize, r: usize) -> [u8; 3] {
    [(10 * c + 5) as u8, (15 * r + 3) as u8, ((7 * c + 11 * r) % 256) as u8]
}

fn alpha(c: usize, r: usize) -> u8 {
    if (c + r) % 5 == 0 { 0 } else { 255 }
}

/// The georeference gdalinfo reports for the UTM fixtures: [500000, 30, 0, 5000000, 0, -30].
const UTM: GeoTransform = GeoTransform { origin_x: 500_000.0, origin_y: 5_000_000.0, cell_x: 30.0, cell_y: -30.0 };

fn assert_utm(s: &SourceRaster) {
    assert_eq!((s.grid.width, s.grid.height), (W, H), "{}", s.path.display());
    assert_eq!(s.grid.transform, UTM, "{}", s.path.display());
    assert_eq!(s.grid.crs.epsg, Some(32614), "{}", s.path.display());
    assert!(!s.grid.crs.geographic);
}

fn cells() -> impl Iterator<Item = (usize, usize)> {
    (0..H).flat_map(|r| (0..W).map(move |c| (c, r)))
}

#[test]
fn int16_stripped_uncompressed_with_nodata_minus_32768() {
    let s = read("int16_strip_none_nodata.tif");
    assert_utm(&s);
    assert_eq!((s.format, s.bands, s.nodata, s.pixel_is_point), ("GTiff", 1, Some(-32768.0), false));
    let Samples::I16(v) = &s.samples else { panic!("expected Int16, got {}", s.samples.type_name()) };
    let el = s.to_elevation().unwrap();
    for (c, r) in cells() {
        let i = r * W + c;
        if NODATA_CELLS.contains(&(c, r)) {
            assert_eq!(v[i], -32768);
            assert!(el.data[i].is_nan());
        } else {
            assert_eq!(v[i] as i32, e(c, r));
            assert_eq!(el.data[i], e(c, r) as f32);
        }
    }
    assert_eq!(el.nodata_count(), 2);
}

#[test]
fn uint16_tiled_lzw() {
    let s = read("uint16_tiled_lzw.tif");
    assert_utm(&s);
    let Samples::U16(v) = &s.samples else { panic!("expected UInt16") };
    assert!(cells().all(|(c, r)| v[r * W + c] as i32 == e(c, r)));
    assert_eq!(s.nodata, None);
}

#[test]
fn int32_deflate_horizontal_predictor() {
    let s = read("int32_deflate_pred2.tif");
    assert_utm(&s);
    let Samples::I32(v) = &s.samples else { panic!("expected Int32") };
    assert!(cells().all(|(c, r)| v[r * W + c] == 1000 * e(c, r)));
    // 1000·e stays below 2^24, so the elevation is exact.
    assert_eq!(s.to_elevation().unwrap().data[W + 1], (1000 * e(1, 1)) as f32);
}

#[test]
fn float32_tiled_deflate_floating_point_predictor_with_nan_cells() {
    let s = read("float32_tiled_deflate_pred3_nan.tif");
    assert_utm(&s);
    assert!(s.nodata.is_some_and(f64::is_nan), "GDAL_NODATA 'nan' reads as NaN");
    let el = s.to_elevation().unwrap();
    for (c, r) in cells() {
        let v = el.data[r * W + c];
        if NODATA_CELLS.contains(&(c, r)) {
            assert!(v.is_nan());
        } else {
            assert_eq!(v, e(c, r) as f32 / 4.0, "({c}, {r})");
        }
    }
}

#[test]
fn float64_lzw_keeps_full_precision() {
    let s = read("float64_lzw.tif");
    assert_utm(&s);
    let Samples::F64(v) = &s.samples else { panic!("expected Float64") };
    assert!(cells().all(|(c, r)| v[r * W + c] == e(c, r) as f64 / 3.0));
    assert_eq!(s.to_elevation().unwrap().data[5], (e(5, 0) as f64 / 3.0) as f32);
}

#[test]
fn pixel_is_point_is_shifted_to_corner_like_gdal() {
    // GDAL stored the tiepoint at the centre of pixel (0,0): 500015, 4999985. gdalinfo reports the
    // corner 500000, 5000000, and so must we.
    let s = read("pixel_is_point.tif");
    assert!(s.pixel_is_point);
    assert_utm(&s);
}

#[test]
fn model_transformation_south_up() {
    // gdalinfo: [500000, 30, 0, 4999550, 0, 30]: GDAL writes a ModelTransformation for south-up grids.
    let s = read("model_transformation.tif");
    assert_eq!(s.grid.transform, GeoTransform { origin_x: 500_000.0, origin_y: 4_999_550.0, cell_x: 30.0, cell_y: 30.0 });
    let Samples::I16(v) = &s.samples else { panic!() };
    assert_eq!(v[0] as i32, e(0, 0));
}

#[test]
fn geographic_epsg_4326() {
    let s = read("geographic_4326.tif");
    assert_eq!(s.grid.crs.epsg, Some(4326));
    assert!(s.grid.crs.geographic);
    // gdalinfo -json: [-97.5, 0.001, 0.0, 33.0, 0.0, -0.001] (0.001 to its printed precision).
    let t = s.grid.transform;
    assert_eq!((t.origin_x, t.origin_y), (-97.5, 33.0));
    assert!((t.cell_x - 0.001).abs() < 1e-15 && (t.cell_y + 0.001).abs() < 1e-15, "{t:?}");
    assert_eq!(s.nodata, Some(-32768.0));
    assert_eq!(s.to_elevation().unwrap().nodata_count(), 2);
}

#[test]
fn user_defined_crs_has_no_epsg_but_a_name() {
    let s = read("user_defined_crs.tif");
    assert_eq!(s.grid.crs.epsg, None);
    assert!(!s.grid.crs.is_unknown(), "a user-defined CRS must not match every other CRS");
    assert!(!s.grid.crs.same_as(&Crs::epsg(32614)));
    assert!(!s.grid.crs.geographic);
}

#[test]
fn bigtiff() {
    let s = read("bigtiff.tif");
    assert_utm(&s);
    let Samples::I16(v) = &s.samples else { panic!() };
    assert_eq!(v[W * H - 1] as i32, e(W - 1, H - 1));
}

#[test]
fn plain_tiff_with_tfw_world_file() {
    let s = read("world_file.tif");
    assert_eq!(s.grid.transform, UTM);
    assert!(s.grid.crs.is_unknown());
}

#[test]
fn colour_tiffs_rgb_rgba_grey_planar_and_16_bit() {
    let expect = |s: &SourceRaster, with_alpha: bool| {
        let col = s.to_colour().unwrap();
        for (c, r) in cells() {
            let [red, g, b] = rgb(c, r);
            let want = if with_alpha && alpha(c, r) == 0 { [0, 0, 0, 0] } else { [red, g, b, 255] };
            assert_eq!(col.data[r * W + c], want, "{} ({c}, {r})", s.path.display());
        }
    };
    let s = read("rgb8.tif");
    assert_utm(&s);
    assert_eq!((s.bands, s.alpha_band), (3, None));
    expect(&s, false);
    let s = read("rgba8.tif");
    assert_eq!((s.bands, s.alpha_band), (4, Some(3)));
    expect(&s, true);
    expect(&read("rgb8_planar.tif"), false);
    let s = read("rgb16.tif");
    let Samples::U16(v) = &s.samples else { panic!("expected UInt16") };
    assert_eq!(v[0], 5 * 257, "gdal_translate -scale 0 255 0 65535 maps v to 257·v");
    expect(&s, false);
    let grey = read("grey8.tif").to_colour().unwrap();
    let [red, ..] = rgb(4, 2);
    assert_eq!(grey.data[2 * W + 4], [red, red, red, 255]);
}

#[test]
fn ascii_grid_with_prj() {
    let s = read("grid.asc");
    assert_utm(&s);
    assert_eq!(s.format, "AAIGrid");
    assert!(s.grid.crs.wkt.as_deref().is_some_and(|w| w.starts_with("PROJCS[\"WGS 84 / UTM zone 14N\"")));
    assert_eq!(s.samples, Samples::I32(cells().map(|(c, r)| e(c, r)).collect()));
}

#[test]
fn png_with_world_file_and_prj() {
    let s = read("ortho.png");
    assert_eq!(s.format, "PNG");
    assert_utm(&s);
    let col = s.to_colour().unwrap();
    for (c, r) in cells() {
        let [red, g, b] = rgb(c, r);
        let want = if alpha(c, r) == 0 { [0, 0, 0, 0] } else { [red, g, b, 255] };
        assert_eq!(col.data[r * W + c], want);
    }
}

#[test]
fn jpeg_with_world_file_matches_gdal_within_jpeg_tolerance() {
    let s = read("ortho.jpg");
    assert_eq!(s.format, "JPEG");
    assert_utm(&s); // ortho.prj is shared by stem with ortho.png
    let col = s.to_colour().unwrap();
    // gdallocationinfo on the same file (ortho_jpg_values.txt); decoders' IDCTs may differ slightly.
    for (c, r, want) in [(0, 0, [0u8, 5, 0]), (7, 4, [73, 64, 91]), (19, 14, [195, 218, 26])] {
        let got = col.data[r * W + c];
        for k in 0..3 {
            assert!((got[k] as i32 - want[k] as i32).abs() <= 2, "({c}, {r}): {got:?} vs GDAL {want:?}");
        }
        assert_eq!(got[3], 255);
    }
}

/// Each bad input: one line, naming the file, saying what is wrong.
fn bad(name: &str, problem: &str) {
    let err = read_raster(&data(name)).expect_err(name).to_string();
    assert!(!err.contains('\n'), "{err}");
    assert!(err.starts_with(&data(name).display().to_string()), "{err}");
    assert!(err.contains(problem), "{name}: expected '{problem}' in: {err}");
}

#[test]
fn bad_inputs_are_one_line_errors_naming_the_file() {
    bad("truncated.tif", "corrupt or truncated TIFF");
    if cfg!(not(feature = "gdal")) {
        bad("not_a_raster.tif", "not a TIFF, ASCII grid, PNG or JPEG file");
        bad("empty.tif", "empty file");
    }
    bad("rotated.tif", "rotated");
    bad("gcps.tif", "ground control points");
    bad("no_georef.tif", "no georeference");
    bad("does_not_exist.tif", "no such file");
}

#[test]
fn writers_round_trip_bit_exactly_through_read() {
    let dir = tempfile::tempdir().unwrap();
    let grid = Grid::north_up(500_000.0, 5_000_000.0, 0.5, 37, 23, Crs::epsg(32614));
    let el = Raster::new(grid.clone(), (0..grid.len()).map(|i| if i % 11 == 0 { f32::NAN } else { (i as f32).sin() * 1e3 }).collect());
    let p = dir.path().join("el.tif");
    geotiff::write_f32(&p, &el).unwrap();
    let back = read_raster(&p).unwrap().to_elevation().unwrap();
    assert_eq!(back.grid, grid);
    assert!(back.data.iter().zip(&el.data).all(|(a, b)| a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())));

    let col: Colour = Raster::new(grid.clone(), (0..grid.len()).map(|i| if i % 7 == 0 { [0; 4] } else { [i as u8, (i / 3) as u8, 200, 255] }).collect());
    let p = dir.path().join("col.tif");
    geotiff::write_rgba8(&p, &col).unwrap();
    assert_eq!(read_raster(&p).unwrap().to_colour().unwrap(), col);

    let mask = Raster::new(grid.clone(), (0..grid.len()).map(|i| [0u8, 1, 255][i % 3]).collect());
    let p = dir.path().join("mask.tif");
    geotiff::write_u8(&p, &mask, Some(255)).unwrap();
    let s = read_raster(&p).unwrap();
    assert_eq!((s.samples, s.nodata), (Samples::U8(mask.data.clone()), Some(255.0)));
}

/// GDAL's view of a file we wrote, or `None` (with a message) when gdalinfo is not installed.
fn gdalinfo(path: &Path) -> Option<serde_json::Value> {
    let out = match std::process::Command::new("gdalinfo").arg("-json").arg("-stats").arg(path).output() {
        Ok(o) => o,
        Err(_) => {
            println!("skipped: gdalinfo not found");
            return None;
        }
    };
    assert!(out.status.success(), "gdalinfo rejected {}: {}", path.display(), String::from_utf8_lossy(&out.stderr));
    Some(serde_json::from_slice(&out.stdout).unwrap())
}

#[test]
fn gdal_reads_our_geotiffs() {
    let dir = tempfile::tempdir().unwrap();
    let grid = Grid::north_up(500_000.0, 5_000_000.0, 2.0, 8, 6, Crs::epsg(32614));
    let el = Raster::new(grid.clone(), (0..grid.len()).map(|i| if i == 5 { f32::NAN } else { i as f32 + 0.5 }).collect());
    let p = dir.path().join("el.tif");
    geotiff::write_f32(&p, &el).unwrap();
    let Some(info) = gdalinfo(&p) else { return };
    assert_eq!(info["geoTransform"], serde_json::json!([500000.0, 2.0, 0.0, 5000000.0, 0.0, -2.0]));
    assert!(info["coordinateSystem"]["wkt"].as_str().unwrap().ends_with("ID[\"EPSG\",32614]]"));
    let band = &info["bands"][0];
    assert_eq!(band["type"], "Float32");
    assert_eq!(band["noDataValue"], -9999.0);
    assert_eq!(band["minimum"], 0.5);
    assert_eq!(band["maximum"], 47.5);
    assert_eq!(info["metadata"][""]["AREA_OR_POINT"], "Area");

    let geo = Grid::north_up(-97.5, 33.0, 0.25, 4, 4, Crs::epsg(4326));
    let col: Colour = Raster::new(geo, (0..16u8).map(|i| if i == 0 { [0; 4] } else { [i, 2 * i, 3 * i, 255] }).collect());
    let p = dir.path().join("col.tif");
    geotiff::write_rgba8(&p, &col).unwrap();
    let info = gdalinfo(&p).unwrap();
    let interp: Vec<_> = info["bands"].as_array().unwrap().iter().map(|b| b["colorInterpretation"].as_str().unwrap().to_string()).collect();
    assert_eq!(interp, ["Red", "Green", "Blue", "Alpha"]);
    assert!(info["coordinateSystem"]["wkt"].as_str().unwrap().ends_with("ID[\"EPSG\",4326]]"));
    assert_eq!(info["geoTransform"], serde_json::json!([-97.5, 0.25, 0.0, 33.0, 0.0, -0.25]));

    let mask = Raster::new(grid, (0..48u8).map(|i| i % 2).collect());
    let p = dir.path().join("mask.tif");
    geotiff::write_u8(&p, &mask, Some(255)).unwrap();
    let info = gdalinfo(&p).unwrap();
    assert_eq!(info["bands"][0]["type"], "Byte");
    assert_eq!(info["bands"][0]["noDataValue"], 255.0);
}
