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
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(name)
}

fn read(name: &str) -> SourceRaster {
    read_raster(&data(name)).unwrap_or_else(|e| panic!("{name}: {e}"))
}

/// The fixtures' elevation formula (see make_fixtures.sh).
fn e(c: usize, r: usize) -> i32 {
    1000 + 37 * c as i32 - 53 * r as i32
}

fn rgb(c: usize, r: usize) -> [u8; 3] {
    [
        (10 * c + 5) as u8,
        (15 * r + 3) as u8,
        ((7 * c + 11 * r) % 256) as u8,
    ]
}

fn alpha(c: usize, r: usize) -> u8 {
    if (c + r).is_multiple_of(5) {
        0
    } else {
        255
    }
}

/// The georeference gdalinfo reports for the UTM fixtures: [500000, 30, 0, 5000000, 0, -30].
const UTM: GeoTransform = GeoTransform {
    origin_x: 500_000.0,
    origin_y: 5_000_000.0,
    cell_x: 30.0,
    cell_y: -30.0,
};

fn assert_utm(s: &SourceRaster) {
    assert_eq!(
        (s.grid.width, s.grid.height),
        (W, H),
        "{}",
        s.path.display()
    );
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
    assert_eq!(
        (s.format, s.bands, s.nodata, s.pixel_is_point),
        ("GTiff", 1, Some(-32768.0), false)
    );
    let Samples::I16(v) = &s.samples else {
        panic!("expected Int16, got {}", s.samples.type_name())
    };
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
    let Samples::U16(v) = &s.samples else {
        panic!("expected UInt16")
    };
    assert!(cells().all(|(c, r)| v[r * W + c] as i32 == e(c, r)));
    assert_eq!(s.nodata, None);
}

/// GDAL's sparse files (`SPARSE_OK=TRUE`): a tile or strip of offset 0 and byte count 0 holds
/// no data and reads as the nodata value, or 0 without one, as `gdallocationinfo` reads it
/// (issue 14, defect 15). Read whole and by rows (the band-by-band path ingest uses).
#[test]
fn sparse_chunks_read_as_nodata_or_zero_like_gdal() {
    let tiled = read("sparse_tiled_nodata.tif");
    assert_utm(&tiled);
    assert_eq!(tiled.nodata, Some(-32768.0));
    let strips = read("sparse_strips_zero.tif");
    assert_utm(&strips);
    assert_eq!(strips.nodata, None);
    for (c, r) in cells() {
        let want_tiled = if c >= 16 { -32768 } else { e(c, r) };
        let want_strips = if r >= 8 { 0 } else { e(c, r) };
        assert_eq!(tiled.sample(r * W + c, 0) as i32, want_tiled, "({c}, {r})");
        assert_eq!(
            strips.sample(r * W + c, 0) as i32,
            want_strips,
            "({c}, {r})"
        );
    }
    let el = tiled.to_elevation().unwrap();
    assert_eq!(el.nodata_count(), 4 * H);
    let rows = dbms::io::geotiff::read_rows(&data("sparse_strips_zero.tif"), 6..13).unwrap();
    assert_eq!(rows.samples, strips.samples.slice(6 * W..13 * W));
}

#[test]
fn int32_deflate_horizontal_predictor() {
    let s = read("int32_deflate_pred2.tif");
    assert_utm(&s);
    let Samples::I32(v) = &s.samples else {
        panic!("expected Int32")
    };
    assert!(cells().all(|(c, r)| v[r * W + c] == 1000 * e(c, r)));
    // 1000·e stays below 2^24, so the elevation is exact.
    assert_eq!(
        s.to_elevation().unwrap().data[W + 1],
        (1000 * e(1, 1)) as f32
    );
}

#[test]
fn float32_tiled_deflate_floating_point_predictor_with_nan_cells() {
    let s = read("float32_tiled_deflate_pred3_nan.tif");
    assert_utm(&s);
    assert!(
        s.nodata.is_some_and(f64::is_nan),
        "GDAL_NODATA 'nan' reads as NaN"
    );
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
    let Samples::F64(v) = &s.samples else {
        panic!("expected Float64")
    };
    assert!(cells().all(|(c, r)| v[r * W + c] == e(c, r) as f64 / 3.0));
    assert_eq!(
        s.to_elevation().unwrap().data[5],
        (e(5, 0) as f64 / 3.0) as f32
    );
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
    assert_eq!(
        s.grid.transform,
        GeoTransform {
            origin_x: 500_000.0,
            origin_y: 4_999_550.0,
            cell_x: 30.0,
            cell_y: 30.0
        }
    );
    let Samples::I16(v) = &s.samples else {
        panic!()
    };
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
    assert!(
        (t.cell_x - 0.001).abs() < 1e-15 && (t.cell_y + 0.001).abs() < 1e-15,
        "{t:?}"
    );
    assert_eq!(s.nodata, Some(-32768.0));
    assert_eq!(s.to_elevation().unwrap().nodata_count(), 2);
}

#[test]
fn user_defined_crs_has_no_epsg_but_a_name() {
    let s = read("user_defined_crs.tif");
    assert_eq!(s.grid.crs.epsg, None);
    assert!(
        !s.grid.crs.is_unknown(),
        "a user-defined CRS must not match every other CRS"
    );
    assert!(!s.grid.crs.same_as(&Crs::epsg(32614)));
    assert!(!s.grid.crs.geographic);
}

#[test]
fn bigtiff() {
    let s = read("bigtiff.tif");
    assert_utm(&s);
    let Samples::I16(v) = &s.samples else {
        panic!()
    };
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
            let want = if with_alpha && alpha(c, r) == 0 {
                [0, 0, 0, 0]
            } else {
                [red, g, b, 255]
            };
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
    let Samples::U16(v) = &s.samples else {
        panic!("expected UInt16")
    };
    assert_eq!(
        v[0],
        5 * 257,
        "gdal_translate -scale 0 255 0 65535 maps v to 257·v"
    );
    expect(&s, false);
    let grey = read("grey8.tif").to_colour().unwrap();
    let [red, ..] = rgb(4, 2);
    assert_eq!(grey.data[2 * W + 4], [red, red, red, 255]);
}

#[test]
fn jpeg_compressed_ycbcr_tiff_is_rgb_like_gdal() {
    // The decoder keeps JPEG's YCbCr; we convert. GDAL's libjpeg upsamples chroma differently,
    // so levels may differ by a few (5 at most on this image, mean under 0.5).
    let s = read("rgb8_jpeg_ycbcr.tif");
    assert_utm(&s);
    let col = s.to_colour().unwrap();
    let gdal = std::fs::read(data("rgb8_jpeg_ycbcr.gdal.rgb")).unwrap();
    let mut total = 0usize;
    for (i, px) in col.data.iter().enumerate() {
        for k in 0..3 {
            let d = (px[k] as i32 - gdal[3 * i + k] as i32).abs();
            assert!(
                d <= 6,
                "pixel {i} band {k}: {} vs GDAL {}",
                px[k],
                gdal[3 * i + k]
            );
            total += d as usize;
        }
    }
    assert!(
        total < col.data.len() * 3,
        "mean difference from GDAL must stay below one level: {total}"
    );
}

#[test]
fn ascii_grid_with_prj() {
    let s = read("grid.asc");
    assert_utm(&s);
    assert_eq!(s.format, "AAIGrid");
    assert!(s
        .grid
        .crs
        .wkt
        .as_deref()
        .is_some_and(|w| w.starts_with("PROJCS[\"WGS 84 / UTM zone 14N\"")));
    assert_eq!(
        s.samples,
        Samples::I32(cells().map(|(c, r)| e(c, r)).collect())
    );
}

#[test]
fn png_with_world_file_and_prj() {
    let s = read("ortho.png");
    assert_eq!(s.format, "PNG");
    assert_utm(&s);
    let col = s.to_colour().unwrap();
    for (c, r) in cells() {
        let [red, g, b] = rgb(c, r);
        let want = if alpha(c, r) == 0 {
            [0, 0, 0, 0]
        } else {
            [red, g, b, 255]
        };
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
    for (c, r, want) in [
        (0, 0, [0u8, 5, 0]),
        (7, 4, [73, 64, 91]),
        (19, 14, [195, 218, 26]),
    ] {
        let got = col.data[r * W + c];
        for k in 0..3 {
            assert!(
                (got[k] as i32 - want[k] as i32).abs() <= 2,
                "({c}, {r}): {got:?} vs GDAL {want:?}"
            );
        }
        assert_eq!(got[3], 255);
    }
}

/// Each bad input: one line, naming the file, saying what is wrong.
fn bad(name: &str, problem: &str) {
    let err = read_raster(&data(name)).expect_err(name).to_string();
    assert!(!err.contains('\n'), "{err}");
    assert!(err.starts_with(&data(name).display().to_string()), "{err}");
    assert!(
        err.contains(problem),
        "{name}: expected '{problem}' in: {err}"
    );
}

#[test]
fn bad_inputs_are_one_line_errors_naming_the_file() {
    bad("truncated.tif", "corrupt or truncated TIFF");
    if cfg!(feature = "gdal") {
        bad(
            "not_a_raster.tif",
            "not a TIFF, ASCII grid, PNG or JPEG file, nor a raster GDAL can open; check",
        );
        bad("empty.tif", "nor a raster GDAL can open");
    } else {
        bad(
            "not_a_raster.tif",
            "not a TIFF, ASCII grid, PNG or JPEG file",
        );
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
    let el = Raster::new(
        grid.clone(),
        (0..grid.len())
            .map(|i| {
                if i % 11 == 0 {
                    f32::NAN
                } else {
                    (i as f32).sin() * 1e3
                }
            })
            .collect(),
    );
    let p = dir.path().join("el.tif");
    geotiff::write_f32(&p, &el).unwrap();
    let back = read_raster(&p).unwrap().to_elevation().unwrap();
    assert_eq!(back.grid, grid);
    assert!(back
        .data
        .iter()
        .zip(&el.data)
        .all(|(a, b)| a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan())));

    let col: Colour = Raster::new(
        grid.clone(),
        (0..grid.len())
            .map(|i| {
                if i % 7 == 0 {
                    [0; 4]
                } else {
                    [i as u8, (i / 3) as u8, 200, 255]
                }
            })
            .collect(),
    );
    let p = dir.path().join("col.tif");
    geotiff::write_rgba8(&p, &col).unwrap();
    assert_eq!(read_raster(&p).unwrap().to_colour().unwrap(), col);

    let mask = Raster::new(
        grid.clone(),
        (0..grid.len()).map(|i| [0u8, 1, 255][i % 3]).collect(),
    );
    let p = dir.path().join("mask.tif");
    geotiff::write_u8(&p, &mask, Some(255)).unwrap();
    let s = read_raster(&p).unwrap();
    assert_eq!(
        (s.samples, s.nodata),
        (Samples::U8(mask.data.clone()), Some(255.0))
    );
}

/// GDAL's view of a file we wrote, or `None` (with a message) when gdalinfo is not installed.
fn gdalinfo(path: &Path) -> Option<serde_json::Value> {
    let out = match std::process::Command::new("gdalinfo")
        .arg("-json")
        .arg("-stats")
        .arg(path)
        .output()
    {
        Ok(o) => o,
        Err(_) => {
            println!("skipped: gdalinfo not found");
            return None;
        }
    };
    assert!(
        out.status.success(),
        "gdalinfo rejected {}: {}",
        path.display(),
        String::from_utf8_lossy(&out.stderr)
    );
    Some(serde_json::from_slice(&out.stdout).unwrap())
}

#[test]
fn gdal_reads_our_geotiffs() {
    let dir = tempfile::tempdir().unwrap();
    let grid = Grid::north_up(500_000.0, 5_000_000.0, 2.0, 8, 6, Crs::epsg(32614));
    let el = Raster::new(
        grid.clone(),
        (0..grid.len())
            .map(|i| if i == 5 { f32::NAN } else { i as f32 + 0.5 })
            .collect(),
    );
    let p = dir.path().join("el.tif");
    geotiff::write_f32(&p, &el).unwrap();
    let Some(info) = gdalinfo(&p) else { return };
    assert_eq!(
        info["geoTransform"],
        serde_json::json!([500000.0, 2.0, 0.0, 5000000.0, 0.0, -2.0])
    );
    assert!(info["coordinateSystem"]["wkt"]
        .as_str()
        .unwrap()
        .ends_with("ID[\"EPSG\",32614]]"));
    let band = &info["bands"][0];
    assert_eq!(band["type"], "Float32");
    assert_eq!(band["noDataValue"], -9999.0);
    assert_eq!(band["minimum"], 0.5);
    assert_eq!(band["maximum"], 47.5);
    assert_eq!(info["metadata"][""]["AREA_OR_POINT"], "Area");

    let geo = Grid::north_up(-97.5, 33.0, 0.25, 4, 4, Crs::epsg(4326));
    let col: Colour = Raster::new(
        geo,
        (0..16u8)
            .map(|i| {
                if i == 0 {
                    [0; 4]
                } else {
                    [i, 2 * i, 3 * i, 255]
                }
            })
            .collect(),
    );
    let p = dir.path().join("col.tif");
    geotiff::write_rgba8(&p, &col).unwrap();
    let info = gdalinfo(&p).unwrap();
    let interp: Vec<_> = info["bands"]
        .as_array()
        .unwrap()
        .iter()
        .map(|b| b["colorInterpretation"].as_str().unwrap().to_string())
        .collect();
    assert_eq!(interp, ["Red", "Green", "Blue", "Alpha"]);
    assert!(info["coordinateSystem"]["wkt"]
        .as_str()
        .unwrap()
        .ends_with("ID[\"EPSG\",4326]]"));
    assert_eq!(
        info["geoTransform"],
        serde_json::json!([-97.5, 0.25, 0.0, 33.0, 0.0, -0.25])
    );

    let mask = Raster::new(grid, (0..48u8).map(|i| i % 2).collect());
    let p = dir.path().join("mask.tif");
    geotiff::write_u8(&p, &mask, Some(255)).unwrap();
    let info = gdalinfo(&p).unwrap();
    assert_eq!(info["bands"][0]["type"], "Byte");
    assert_eq!(info["bands"][0]["noDataValue"], 255.0);
}

/// Feature `gdal`: formats only GDAL reads, and reprojection onto a target grid.
#[cfg(feature = "gdal")]
mod with_gdal {
    use super::*;
    use ::gdal::spatial_ref::{AxisMappingStrategy, CoordTransform, SpatialRef};
    use dbms::io::gdal;

    #[test]
    fn dted_reads_through_gdal() {
        let s = read("n32_w098.dt0");
        assert_eq!(s.format, "GDAL:DTED");
        assert_eq!(
            (s.grid.width, s.grid.height, s.grid.crs.epsg),
            (121, 121, Some(4326))
        );
        assert!(s.grid.crs.geographic && s.pixel_is_point);
        // gdalinfo -json: [-98.0041666666666629, 0.0083333333333333, 0, 33.00416666666667, 0, -0.0083333333333333].
        let t = s.grid.transform;
        assert!(
            (t.origin_x + 98.004_166_666_666_66).abs() < 1e-12
                && (t.origin_y - 33.00416666666667).abs() < 1e-12,
            "{t:?}"
        );
        assert!(
            (t.cell_x - 1.0 / 120.0).abs() < 1e-12 && (t.cell_y + 1.0 / 120.0).abs() < 1e-12,
            "{t:?}"
        );
        let Samples::I16(v) = &s.samples else {
            panic!("expected Int16")
        };
        // gdallocationinfo n32_w098.dt0 5 7 → 101 = 100 + 3·5 − 2·7.
        assert_eq!(v[7 * 121 + 5], 101);
        assert!((0..121usize)
            .all(|r| (0..121usize)
                .all(|c| v[r * 121 + c] as i32 == 100 + 3 * c as i32 - 2 * r as i32)));
    }

    #[test]
    fn vrt_reads_through_gdal_like_the_tiff_it_wraps() {
        let vrt = read("int16.vrt");
        let tif = read("int16_strip_none_nodata.tif");
        assert_eq!(vrt.format, "GDAL:VRT");
        assert_eq!(
            (vrt.grid.transform, vrt.grid.crs.epsg),
            (tif.grid.transform, Some(32614))
        );
        assert_eq!((vrt.samples, vrt.nodata), (tif.samples, tif.nodata));
    }

    #[test]
    fn gdal_read_agrees_with_our_geotiff_reader() {
        for name in [
            "float32_tiled_deflate_pred3_nan.tif",
            "rgba8.tif",
            "geographic_4326.tif",
            "pixel_is_point.tif",
        ] {
            let ours = read(name);
            let theirs = gdal::read(&data(name)).unwrap();
            assert_eq!(theirs.grid.transform, ours.grid.transform, "{name}");
            assert_eq!(theirs.grid.crs.epsg, ours.grid.crs.epsg, "{name}");
            assert_eq!(
                (theirs.bands, theirs.alpha_band, theirs.pixel_is_point),
                (ours.bands, ours.alpha_band, ours.pixel_is_point),
                "{name}"
            );
            assert_eq!(
                format!("{:?}", theirs.samples),
                format!("{:?}", ours.samples),
                "{name}"
            ); // NaN-safe
        }
    }

    #[test]
    fn warp_onto_the_same_grid_is_identity() {
        let src = read("int16_strip_none_nodata.tif");
        let w =
            gdal::warp_to_grid(&data("int16_strip_none_nodata.tif"), &src.grid, "nearest").unwrap();
        let (a, b) = (w.to_elevation().unwrap(), src.to_elevation().unwrap());
        assert_eq!(a.grid, b.grid);
        assert_eq!(
            format!("{:?}", a.data),
            format!("{:?}", b.data),
            "values and nodata cells must match"
        );
        let rgba = read("rgba8.tif");
        let w = gdal::warp_to_grid(&data("rgba8.tif"), &rgba.grid, "nearest").unwrap();
        assert_eq!((w.bands, w.alpha_band), (4, Some(3)));
        assert_eq!(w.to_colour().unwrap(), rgba.to_colour().unwrap());
    }

    #[test]
    fn bilinear_half_cell_shift_interpolates_and_outside_is_nodata() {
        // e is linear in (c, r), so bilinear resampling at a half-cell offset is exact: e(c + ½, r + ½).
        let src = read("uint16_tiled_lzw.tif");
        let mut g = src.grid.clone();
        g.transform.origin_x += 15.0;
        g.transform.origin_y -= 15.0;
        let w = gdal::warp_to_grid(&data("float64_lzw.tif"), &g, "bilinear").unwrap();
        let el = w.to_elevation().unwrap();
        for r in 0..H - 1 {
            for c in 0..W - 1 {
                let want = (1000.0 + 37.0 * (c as f64 + 0.5) - 53.0 * (r as f64 + 0.5)) / 3.0;
                assert!(
                    (el.data[r * W + c] as f64 - want).abs() < 1e-3,
                    "({c}, {r}): {} vs {want}",
                    el.data[r * W + c]
                );
            }
        }
        // The last column's centre lies half a cell past the source's last centre, inside its edge cell:
        // GDAL extrapolates there; one more cell east would be outside.
        g.transform.origin_x += 30.0 * W as f64;
        let outside = gdal::warp_to_grid(&data("float64_lzw.tif"), &g, "bilinear").unwrap();
        assert!(
            outside.to_elevation().is_err(),
            "a grid wholly outside the source has no valid cell"
        );
    }

    #[test]
    fn warp_utm_to_geographic_samples_the_right_cells() {
        // A geographic grid inside the UTM fixture; nearest resampling must pick, for each cell
        // centre, the UTM cell that contains it (checked with GDAL's own coordinate transform).
        let grid = Grid::north_up(-98.9995, 45.1530, 2.0e-4, 20, 12, Crs::epsg(4326));
        let w = gdal::warp_to_grid(&data("uint16_tiled_lzw.tif"), &grid, "nearest").unwrap();
        let el = w.to_elevation().unwrap();
        let mut wgs = SpatialRef::from_epsg(4326).unwrap();
        wgs.set_axis_mapping_strategy(AxisMappingStrategy::TraditionalGisOrder);
        let mut utm = SpatialRef::from_epsg(32614).unwrap();
        utm.set_axis_mapping_strategy(AxisMappingStrategy::TraditionalGisOrder);
        let to_utm = CoordTransform::new(&wgs, &utm).unwrap();
        let mut checked = 0;
        for r in 0..grid.height {
            for c in 0..grid.width {
                let (lon, lat) = grid.cell_centre(c, r);
                let (mut x, mut y, mut z) = ([lon], [lat], [0.0]);
                to_utm.transform_coords(&mut x, &mut y, &mut z).unwrap();
                let (px, py) = UTM.world_to_pixel(x[0], y[0]);
                let v = el.data[r * grid.width + c];
                let (fx, fy) = (px.fract(), py.fract());
                if px < 0.0 || py < 0.0 || px >= W as f64 || py >= H as f64 {
                    continue;
                }
                if !(0.01..0.99).contains(&fx) || !(0.01..0.99).contains(&fy) {
                    continue; // too close to a cell edge to be sure which cell "nearest" picks
                }
                assert_eq!(
                    v,
                    e(px as usize, py as usize) as f32,
                    "cell ({c}, {r}) at UTM pixel ({px:.3}, {py:.3})"
                );
                checked += 1;
            }
        }
        assert!(checked > 100, "only {checked} cells fell inside the source");
    }
}

/// Invariants over random rasters: writers and readers are exact inverses.
mod properties {
    use super::*;
    use proptest::prelude::*;

    /// Deterministic pseudo-random values from a seed (splitmix64).
    fn stream(seed: u64) -> impl Iterator<Item = u64> {
        let mut s = seed;
        std::iter::repeat_with(move || {
            s = s.wrapping_add(0x9E37_79B9_7F4A_7C15);
            let mut z = s;
            z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
            z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
            z ^ (z >> 31)
        })
    }

    fn crs(k: u8) -> Crs {
        [Crs::epsg(32614), Crs::epsg(4326), Crs::unknown()][k as usize % 3].clone()
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 24, ..ProptestConfig::default() })]

        /// Any f32 bit pattern (NaN written as -9999, infinities kept) on any grid, across tile edges.
        #[test]
        fn f32_geotiff_round_trips_any_bits(w in 1usize..300, h in 1usize..300, seed: u64, x0 in -1e7f64..1e7, y0 in -1e7f64..1e7, cell in 0.01f64..1000.0, k: u8) {
            let grid = Grid::north_up(x0, y0, cell, w, h, crs(k));
            let data: Vec<f32> = stream(seed).take(w * h).map(|b| f32::from_bits(b as u32)).map(|v| if v == geotiff::F32_NODATA { 0.0 } else { v }).collect();
            let dir = tempfile::tempdir().unwrap();
            let p = dir.path().join("p.tif");
            geotiff::write_f32(&p, &Raster::new(grid.clone(), data.clone())).unwrap();
            let s = read_raster(&p).unwrap();
            prop_assert_eq!(&s.grid, &grid);
            let Samples::F32(back) = &s.samples else { panic!("expected Float32") };
            for (a, b) in back.iter().zip(&data) {
                let want = if b.is_nan() { geotiff::F32_NODATA } else { *b };
                prop_assert_eq!(a.to_bits(), want.to_bits());
            }
        }

        #[test]
        fn rgba_geotiff_round_trips(w in 1usize..300, h in 1usize..300, seed: u64) {
            let grid = Grid::north_up(0.0, 0.0, 1.0, w, h, Crs::epsg(32614));
            let data: Colour = Raster::new(grid, stream(seed).take(w * h).map(|b| {
                let [r, g, bl, a, ..] = b.to_le_bytes();
                if a < 64 { [0, 0, 0, 0] } else { [r, g, bl, 255] }
            }).collect());
            let dir = tempfile::tempdir().unwrap();
            let p = dir.path().join("c.tif");
            geotiff::write_rgba8(&p, &data).unwrap();
            prop_assert_eq!(read_raster(&p).unwrap().to_colour().unwrap(), data);
        }

        /// Values written as Rust prints them (shortest round-trip decimal), wrapped anyhow, any header case.
        #[test]
        fn ascii_grid_reads_exactly_what_is_written(w in 1usize..40, h in 1usize..40, seed: u64, wrap in 1usize..50, integers: bool, upper: bool, centre: bool) {
            let values: Vec<f64> = stream(seed).take(w * h).map(|b| if integers { (b as i32 / 1000) as f64 } else { (b as i64 as f64) * 1e-15 }).collect();
            let key = |k: &str| if upper { k.to_uppercase() } else { k.to_string() };
            let (xk, yk) = if centre { ("xllcenter", "yllcenter") } else { ("xllcorner", "yllcorner") };
            let mut text = format!("{} {w}\n{} {h}\n{} 500000.5\n{} 4999000.25\n{} 0.5\n", key("ncols"), key("nrows"), key(xk), key(yk), key("cellsize"));
            for chunk in values.chunks(wrap) {
                let line: Vec<String> = chunk.iter().map(|v| if integers { format!("{}", *v as i32) } else { format!("{v:?}") }).collect();
                text.push_str(&line.join(" "));
                text.push('\n');
            }
            let dir = tempfile::tempdir().unwrap();
            let p = dir.path().join("g.asc");
            std::fs::write(&p, text).unwrap();
            let s = read_raster(&p).unwrap();
            let half = if centre { 0.25 } else { 0.0 };
            prop_assert_eq!(s.grid.transform, GeoTransform { origin_x: 500000.5 - half, origin_y: 4999000.25 - half + 0.5 * h as f64, cell_x: 0.5, cell_y: -0.5 });
            let got: Vec<f64> = (0..w * h).map(|i| s.sample(i, 0)).collect();
            prop_assert_eq!(got, values);
        }
    }
}

/// `geotiff::read_rows` gives the rows of `read`, with the rows' sub-grid, for parallel-decoded
/// layouts (stripped, tiled, planar, LZW, Deflate) and the `tiff` crate's (JPEG) alike.
#[test]
fn read_rows_is_the_window_of_read() {
    use dbms::grid::Window;
    use dbms::io::geotiff::read_rows;
    for name in [
        "int16_strip_none_nodata.tif",
        "uint16_tiled_lzw.tif",
        "int32_deflate_pred2.tif",
        "float32_tiled_deflate_pred3_nan.tif",
        "float64_lzw.tif",
        "rgb8_planar.tif",
        "rgba8.tif",
        "rgb8_jpeg_ycbcr.tif",
    ] {
        let whole = read(name);
        let (w, h, bands) = (whole.grid.width, whole.grid.height, whole.bands);
        for rows in [0..h, 1..h - 1, h / 2..h / 2 + 1, h - 1..h] {
            let part = read_rows(&data(name), rows.clone()).unwrap();
            let window = Window {
                col: 0,
                row: rows.start,
                width: w,
                height: rows.len(),
            };
            assert_eq!(
                part.grid,
                whole.grid.window_grid(&window),
                "{name} {rows:?}"
            );
            let want = match &whole.samples {
                Samples::U8(v) => {
                    Samples::U8(v[rows.start * w * bands..rows.end * w * bands].to_vec())
                }
                Samples::U16(v) => {
                    Samples::U16(v[rows.start * w * bands..rows.end * w * bands].to_vec())
                }
                Samples::I16(v) => {
                    Samples::I16(v[rows.start * w * bands..rows.end * w * bands].to_vec())
                }
                Samples::I32(v) => {
                    Samples::I32(v[rows.start * w * bands..rows.end * w * bands].to_vec())
                }
                Samples::U32(v) => {
                    Samples::U32(v[rows.start * w * bands..rows.end * w * bands].to_vec())
                }
                Samples::F32(v) => {
                    Samples::F32(v[rows.start * w * bands..rows.end * w * bands].to_vec())
                }
                Samples::F64(v) => {
                    Samples::F64(v[rows.start * w * bands..rows.end * w * bands].to_vec())
                }
            };
            // NaN cells compare by bits.
            assert_eq!(
                format!("{:?}", part.samples),
                format!("{want:?}"),
                "{name} {rows:?}"
            );
            let meta = |s: &SourceRaster| format!("{:?}", (s.bands, s.nodata, s.alpha_band));
            assert_eq!(meta(&part), meta(&whole), "{name} {rows:?}");
        }
        let err = read_rows(&data(name), h..h + 1).unwrap_err().to_string();
        assert!(err.contains("outside the image"), "{err}");
    }
}
