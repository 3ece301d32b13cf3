//! `dbms materials` end to end (a database made with the library, the layer read back), and
//! `dbms thermal` over the layer.

use dbms::crs::Crs;
use dbms::db::{Database, COLOUR, ELEVATION};
use dbms::grid::Grid;
use dbms::io::geotiff;
use dbms::material::table::MaterialTable;
use dbms::raster::{Colour, Raster};
use std::path::{Path, PathBuf};
use std::process::Output;
#[path = "support/cli.rs"]
mod cli;
use cli::dbms;

const ORIGIN: (f64, f64) = (500_000.0, 5_300_020.0);

/// A 40 × 20 database of 1 m cells: grass on the west half, a grey road colour on the east
/// half, no photo in the last column, and a building (roof_material tile) over cells 2..4 of
/// rows 2..4.
fn database(dir: &Path) {
    database_over(dir, 40, 20, |_, _| 100.0);
}

/// [`database`] on a `w × h` grid with terrain heights `z(col, row)`.
fn database_over(dir: &Path, w: usize, h: usize, z: impl Fn(usize, usize) -> f32) {
    let grid = Grid::north_up(ORIGIN.0, ORIGIN.1, 1.0, w, h, Crs::epsg(32632));
    let mut db = Database::create(dir, grid.clone(), vec![]).unwrap();
    let heights = (0..grid.len()).map(|i| z(i % w, i / w)).collect();
    geotiff::write_f32(&dir.join("e.tif"), &Raster::new(grid.clone(), heights)).unwrap();
    let colour: Colour = Raster::new(
        grid.clone(),
        (0..grid.len())
            .map(|i| match i % w {
                c if c == w - 1 => [0, 0, 0, 0],
                c if c < w / 2 => [74, 112, 48, 255],
                _ => [92, 92, 96, 255],
            })
            .collect(),
    );
    geotiff::write_rgba8(&dir.join("c.tif"), &colour).unwrap();
    db.set_layer(ELEVATION, "elevation", "e.tif", Some(0))
        .unwrap();
    db.set_layer(COLOUR, "colour", "c.tif", Some(20)).unwrap();
    let (x, y) = ORIGIN;
    let building = serde_json::json!({"type": "FeatureCollection", "features": [
        {"type": "Feature", "properties": {"roof_z": 110.0, "roof_material": "roof_tile"},
         "geometry": {"type": "Polygon", "coordinates": [[[x + 2.0, y - 2.0], [x + 4.0, y - 2.0], [x + 4.0, y - 4.0], [x + 2.0, y - 4.0], [x + 2.0, y - 2.0]]]}}]});
    std::fs::write(dir.join("b.geojson"), building.to_string()).unwrap();
    db.set_layer("buildings", "buildings", "b.geojson", None)
        .unwrap();
    db.save().unwrap();
}

/// `o`, which must be a success (else its stderr is the failure).
fn ok(o: Output) -> Output {
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    o
}

/// A GeoJSON file `dir/name` of one feature of `material`: the rectangle over columns
/// `c0..c1` and rows `r0..r1` of the 1 m grids here (corner at [`ORIGIN`]).
fn rectangle_of(dir: &Path, name: &str, material: &str, [c0, r0, c1, r1]: [f64; 4]) -> PathBuf {
    let (x, y) = ORIGIN;
    let ring = [[c0, r0], [c1, r0], [c1, r1], [c0, r1], [c0, r0]].map(|[c, r]| [x + c, y - r]);
    let doc = serde_json::json!({"type": "FeatureCollection", "features": [
        {"type": "Feature", "properties": {"material": material},
         "geometry": {"type": "Polygon", "coordinates": [ring]}}]});
    let path = dir.join(name);
    std::fs::write(&path, doc.to_string()).unwrap();
    path
}

/// `dbms thermal` of the database `d` at `time` with half-hour steps into `out`, and `report`
/// (`--json` or `-q`).
fn thermal(d: &str, time: &str, out: &Path, report: &str) -> Output {
    let out = out.to_str().unwrap();
    dbms(&[
        "thermal", "--db", d, "--time", time, "--step", "1800", "-o", out, report,
    ])
}

fn layer(dir: &Path) -> Vec<u8> {
    let db = Database::open(dir).unwrap();
    let r = dbms::io::read_raster(&db.layer_path("materials").unwrap()).unwrap();
    (0..r.grid.len()).map(|i| r.sample(i, 0) as u8).collect()
}

#[test]
fn layer_from_roofs_features_and_photo() {
    let t = tempfile::tempdir().unwrap();
    let dir = t.path().join("db");
    database(&dir);
    // A water polygon over the grass's first 10 columns, rows 10..20 (south half).
    let features = rectangle_of(t.path(), "water.geojson", "water", [0.0, 10.0, 10.0, 20.0]);
    let o = ok(dbms(&[
        "materials",
        "--db",
        dir.to_str().unwrap(),
        "--features",
        features.to_str().unwrap(),
        "--preview",
        t.path().join("m.png").to_str().unwrap(),
        "--json",
    ]));
    let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(summary["cells"], 800);
    assert_eq!(summary["sources"]["roofs"], 4);
    assert_eq!(summary["sources"]["features"], 100);
    assert_eq!(summary["sources"]["unclassified"], 20);
    assert_eq!(summary["materials"]["water"], 100);
    let ids = layer(&dir);
    let table = MaterialTable::default_table();
    let name = |c: usize, r: usize| {
        table
            .by_id(ids[r * 40 + c])
            .map_or("unclassified", |m| m.name.as_str())
    };
    assert_eq!(name(2, 2), "roof_tile");
    assert_eq!(name(3, 3), "roof_tile");
    assert_eq!(name(5, 5), "grass");
    assert_eq!(name(5, 15), "water");
    assert_eq!(name(30, 15), "asphalt");
    assert_eq!(name(39, 0), "unclassified");
    // The preview: each cell in its material's colour, black where unclassified.
    let png = image::open(t.path().join("m.png")).unwrap().to_rgb8();
    assert_eq!(png.dimensions(), (40, 20));
    assert_eq!(
        png.get_pixel(5, 15).0,
        table.by_name("water").unwrap().colour
    );
    assert_eq!(png.get_pixel(39, 0).0, [0, 0, 0]);
    // The stage is recorded with its inputs.
    let db = Database::open(&dir).unwrap();
    let stage = db.manifest.stages.last().unwrap();
    assert_eq!(stage.name, "materials");
    assert_eq!(stage.params["table"], "default");
    assert!(stage.params["inputs"][0]["sha256"].is_string());
    assert!(!db.manifest.layers.contains_key("material_table"));
}

#[test]
fn landcover_and_a_table_of_ones_own() {
    let t = tempfile::tempdir().unwrap();
    let dir = t.path().join("db");
    database(&dir);
    // WorldCover codes: 80 (water) on the west half, 10 (trees) on the east, 255 unmapped.
    let grid = Grid::north_up(ORIGIN.0, ORIGIN.1, 10.0, 4, 2, Crs::epsg(32632));
    let lc = t.path().join("lc.tif");
    geotiff::write_u8(
        &lc,
        &Raster::new(grid, vec![80, 80, 10, 10, 80, 80, 10, 255]),
        None,
    )
    .unwrap();
    // The default table, copied: given with --table it is stored in the database.
    let table = t.path().join("table.json");
    std::fs::write(
        &table,
        include_str!("../src/lib/material/default-materials.json"),
    )
    .unwrap();
    let o = ok(dbms(&[
        "materials",
        "--db",
        dir.to_str().unwrap(),
        "--landcover",
        lc.to_str().unwrap(),
        "--legend",
        "esa_worldcover",
        "--table",
        table.to_str().unwrap(),
        "--json",
    ]));
    let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    // 800 cells − 4 roof cells; 100 cells (the south-east 10 × 10) have the unmapped 255.
    assert_eq!(summary["sources"]["landcover"], 696);
    assert_eq!(summary["landcover_unmapped"]["255"], 100);
    let ids = layer(&dir);
    let t2 = MaterialTable::default_table();
    assert_eq!(t2.by_id(ids[15]).unwrap().name, "water");
    assert_eq!(t2.by_id(ids[25]).unwrap().name, "forest");
    assert_eq!(t2.by_id(ids[15 * 40 + 35]).unwrap().name, "asphalt"); // unmapped: the photo
    let db = Database::open(&dir).unwrap();
    assert!(db.manifest.layers.contains_key("material_table"));
    db.verify().unwrap();
}

#[test]
fn bad_input_is_a_one_line_error_and_changes_nothing() {
    let t = tempfile::tempdir().unwrap();
    let dir = t.path().join("db");
    database(&dir);
    let before = std::fs::read(dir.join("manifest.json")).unwrap();
    let lava = rectangle_of(t.path(), "lava.geojson", "lava", [0.0, 0.0, 5.0, 5.0]);
    let d = dir.to_str().unwrap();
    let cases: [(&[&str], &str); 5] = [
        (
            &["--features", lava.to_str().unwrap()],
            "material \"lava\" is not in the material table",
        ),
        (&["--landcover", "lc.tif"], "--legend"),
        (
            &["--features", "missing.geojson"],
            "missing.geojson: no such file",
        ),
        (
            &["--table", lava.to_str().unwrap()],
            "not a valid material table",
        ),
        // Fails after the layer is made, before the commit: the database is unchanged.
        (&["--preview", "/nonexistent/m.png"], "/nonexistent"),
    ];
    for (extra, expect) in cases {
        let mut args = vec!["materials", "--db", d];
        args.extend(extra);
        let o = dbms(&args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success(), "{args:?}");
        assert!(err.contains(expect), "{args:?}: {err}");
        assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    }
    assert_eq!(std::fs::read(dir.join("manifest.json")).unwrap(), before);
}

/// `dbms thermal` at 14:00 and 22:00 local solar time (the database is at 9° E: UTC + 36 min)
/// on the materials of [`database`]: asphalt hotter than grass by day; everything cooler at
/// night; the building's roof over a room; nodata where unclassified.
#[test]
fn thermal_map_by_day_and_night() {
    let t = tempfile::tempdir().unwrap();
    let dir = t.path().join("db");
    database(&dir);
    let d = dir.to_str().unwrap();
    ok(dbms(&["materials", "--db", d, "-q"]));
    let run = |time: &str, name: &str| {
        let out = t.path().join(name);
        let o = ok(thermal(d, time, &out, "--json"));
        let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        let r = dbms::io::read_raster(&out).unwrap();
        let v: Vec<f64> = (0..r.grid.len()).map(|i| r.sample(i, 0)).collect();
        (summary, v, r.nodata)
    };
    let (day, t14, nodata) = run("2026-07-01T13:24:00Z", "t14.tif");
    let (night, t22, _) = run("2026-07-01T21:24:00Z", "t22.tif");
    let mean = |s: &serde_json::Value, m: &str| s["materials"][m]["mean_k"].as_f64().unwrap();
    assert!(mean(&day, "asphalt") > mean(&day, "grass") + 1.0, "{day}");
    for m in ["asphalt", "grass", "roof_tile"] {
        assert!(mean(&night, m) < mean(&day, m) - 3.0, "{m}: {night}");
        // Between 250 K and 350 K: a physical surface on a 15 °C day.
        assert!((250.0..350.0).contains(&mean(&day, m)), "{m}: {day}");
    }
    assert_eq!(day["steps"], 48);
    assert_eq!(day["nodata_cells"], 20);
    // The unclassified last column is nodata; a grass and an asphalt cell hold their map.
    assert_eq!(Some(t14[39]), nodata);
    assert!(t14[40 * 15 + 5] < t14[40 * 15 + 30]);
    assert!(t22[40 * 15 + 30] < t14[40 * 15 + 30]);
}

/// Slopes facing the sun are warmer: a 41 × 41 pyramid of 45° faces, all asphalt, at 47.9° N.
/// At local noon (11:24 UTC at 9° E) in July the south face is the warmest and the north the
/// coolest; at 07:24 local the east face is warmer than the west. Fails if the normal's north
/// or east component has the wrong sign.
#[test]
fn thermal_map_sees_the_slopes() {
    let t = tempfile::tempdir().unwrap();
    let dir = t.path().join("db");
    let n = 41;
    let peak = |c: usize, r: usize| {
        let d = (c as i64 - 20).abs().max((r as i64 - 20).abs());
        120.0 - d as f32
    };
    database_over(&dir, n, n, peak);
    let features = rectangle_of(t.path(), "all.geojson", "asphalt", [0.0, 0.0, 41.0, 41.0]);
    let d = dir.to_str().unwrap();
    ok(dbms(&[
        "materials",
        "--db",
        d,
        "--features",
        features.to_str().unwrap(),
        "-q",
    ]));
    // Mean temperature of each face's inner cells: north (rows above the peak), east, south, west.
    let faces = |time: &str| -> [f64; 4] {
        let out = t.path().join("t.tif");
        ok(dbms(&[
            "thermal",
            "--db",
            d,
            "--time",
            time,
            "-o",
            out.to_str().unwrap(),
            "-q",
        ]));
        let r = dbms::io::read_raster(&out).unwrap();
        let mut sum = [(0.0, 0); 4];
        for row in 3..n - 3 {
            for col in 3..n - 3 {
                let (dc, dr) = (col as i64 - 20, row as i64 - 20);
                let face = match () {
                    _ if dr < 0 && dr.abs() > dc.abs() + 1 => 0,
                    _ if dc > 0 && dc.abs() > dr.abs() + 1 => 1,
                    _ if dr > 0 && dr.abs() > dc.abs() + 1 => 2,
                    _ if dc < 0 && dc.abs() > dr.abs() + 1 => 3,
                    _ => continue,
                };
                sum[face].0 += r.sample(row * n + col, 0);
                sum[face].1 += 1;
            }
        }
        sum.map(|(s, k)| s / k as f64)
    };
    let [north, east, south, west] = faces("2026-07-01T11:24:00Z");
    assert!(
        south > east.max(west) + 2.0 && north < east.min(west) - 2.0,
        "{north} {east} {south} {west}"
    );
    let [_, east, _, west] = faces("2026-07-01T06:24:00Z");
    assert!(east > west + 2.0, "morning: east {east} west {west}");
    // Bad weather and clashing outputs are one-line errors naming the option; nothing is left.
    let out = t.path().join("x.tif");
    for (extra, expect) in [
        (vec!["--air-temp", "nan"], "--air-temp NaN"),
        (vec!["--humidity", "0"], "--humidity 0"),
        (vec!["--step", "86400"], "--step 86400"),
        (vec!["--radiance-out", out.to_str().unwrap()], "two outputs"),
        (vec!["--radiance-out", "/nonexistent/r.tif"], "/nonexistent"),
    ] {
        let mut args = vec!["thermal", "--db", d, "--time", "2026-07-01T11:24:00Z"];
        args.extend(["-o", out.to_str().unwrap()]);
        args.extend(extra);
        let o = dbms(&args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(
            !o.status.success() && err.contains(expect),
            "{args:?}: {err}"
        );
        assert_eq!(err.trim_end().lines().count(), 1, "{err}");
        assert!(!out.exists(), "{args:?} left {}", out.display());
    }
}

/// A cell without a photo takes its material's colour in the pyramid: the last column of
/// [`database`] has no photo; painted water, its level-0 cells are the table's water colour,
/// opaque; without the materials layer they are nodata.
#[test]
fn pyramid_colours_cells_without_a_photo_by_their_material() {
    let t = tempfile::tempdir().unwrap();
    let dir = t.path().join("db");
    database(&dir);
    let d = dir.to_str().unwrap();
    let tiles = |name: &str| {
        let out = t.path().join(name);
        ok(dbms(&[
            "pyramid",
            "--db",
            d,
            "-o",
            out.to_str().unwrap(),
            "-q",
        ]));
        dbms::tiles::TileReader::open(&out, 16).unwrap()
    };
    let before = tiles("before.dbt");
    let cell = before.cell(0, 39, 5).unwrap().unwrap();
    assert_eq!(cell.colour[3], 0, "{cell:?}");
    let features = rectangle_of(t.path(), "w.geojson", "water", [39.0, 0.0, 40.0, 20.0]);
    ok(dbms(&[
        "materials",
        "--db",
        d,
        "--features",
        features.to_str().unwrap(),
        "-q",
    ]));
    let after = tiles("after.dbt");
    let [r, g, b] = MaterialTable::default_table()
        .by_name("water")
        .unwrap()
        .colour;
    assert_eq!(
        after.cell(0, 39, 5).unwrap().unwrap().colour,
        [r, g, b, 255]
    );
    // Cells with a photo keep it.
    assert_eq!(
        after.cell(0, 5, 5).unwrap().unwrap().colour,
        before.cell(0, 5, 5).unwrap().unwrap().colour
    );
}

/// The sensor layers through the pyramid and the infrared view: `dbms pyramid --materials
/// --temperature` carries the materials layer and `dbms thermal`'s map beside the geometry.
/// Level 0 holds them bit for bit (nodata where the cell has no surface), every coarse cell the
/// majority and the mean over its level-0 block, counted here from the GeoTIFFs; the visual
/// view is byte-identical to that of a tile set without them; `--sensor ir` draws asphalt
/// brighter than grass at 14:00, and asks for a temperature layer where there is none.
#[test]
fn sensor_layers_reduce_exactly_and_draw_the_infrared_view() {
    use dbms::tiles::{SensorCells, SensorLayer, MATERIAL_NODATA};
    let t = tempfile::tempdir().unwrap();
    let dir = t.path().join("db");
    database(&dir);
    let (d, p) = (dir.to_str().unwrap(), |n: &str| t.path().join(n));
    let s = |p: &Path| p.to_str().unwrap().to_string();
    ok(dbms(&["materials", "--db", d, "-q"]));
    let temp = p("t14.tif");
    let time = "2026-07-01T13:24:00Z";
    ok(thermal(d, time, &temp, "-q"));
    let pyramid = |out: &Path, extra: &[&str]| {
        let mut args = vec![
            "pyramid", "--db", d, "--page", "8", "--factor", "2", "-q", "-o",
        ];
        let out = s(out);
        args.push(&out);
        args.extend(extra);
        ok(dbms(&args));
    };
    let temp_arg = s(&temp);
    pyramid(&p("ir.dbt"), &["--materials", "--temperature", &temp_arg]);
    pyramid(&p("visual.dbt"), &[]);

    let material = layer(&dir);
    let r = dbms::io::read_raster(&temp).unwrap();
    let kelvin: Vec<f32> = (0..r.grid.len()).map(|i| r.sample(i, 0) as f32).collect();
    let reader = dbms::tiles::TileReader::open(&p("ir.dbt"), 64).unwrap();
    let info = reader.info().clone();
    assert_eq!(
        info.sensor_layers(),
        [SensorLayer::Material, SensorLayer::Temperature]
    );
    // The effects record says which sensor layers were made, and that a visual product made none.
    let applied = |i: &dbms::tiles::TileSetInfo| i.effects["applied"].to_string();
    assert_eq!(applied(&info), r#"["material_layer","temperature_layer"]"#);
    let visual = dbms::tiles::TileReader::open(&p("visual.dbt"), 1).unwrap();
    assert_eq!(applied(visual.info()), "[]");
    let skipped = visual.info().effects["skipped"].to_string();
    let not_asked = r#""effect":"material_layer","why":"not asked for (--materials)""#;
    assert!(skipped.contains(not_asked), "{skipped}");
    let (w, h) = (40usize, 20usize);
    let level0_valid = |c: usize, r: usize| !reader.cell(0, c, r).unwrap().unwrap().max_z.is_nan();
    for (level, l) in info.levels.iter().enumerate() {
        let s = 1usize << level;
        for row in 0..l.height {
            for col in 0..l.width {
                let (mut counts, mut sum, mut n) = ([0u64; 256], 0.0f64, 0u64);
                for r0 in row * s..((row + 1) * s).min(h) {
                    for c0 in col * s..((col + 1) * s).min(w) {
                        if !level0_valid(c0, r0) {
                            continue;
                        }
                        counts[material[r0 * w + c0] as usize] += 1;
                        let k = kelvin[r0 * w + c0];
                        if !k.is_nan() && Some(f64::from(k)) != r.nodata {
                            sum += f64::from(k);
                            n += 1;
                        }
                    }
                }
                let best = (0..255)
                    .max_by_key(|&i| (counts[i], std::cmp::Reverse(i)))
                    .unwrap();
                let want_m = if counts[best] == 0 {
                    MATERIAL_NODATA
                } else {
                    best as u8
                };
                let want_t = if n == 0 {
                    f32::NAN
                } else {
                    (sum / n as f64) as f32
                };
                let (tx, ty, p) = (col / 8, row / 8, info.page_size);
                let page = reader.page(level, tx, ty).unwrap();
                let i = (row % p) * p + col % p;
                let Some(SensorCells::Ids(m)) = page.sensor(SensorLayer::Material) else {
                    panic!("no material layer")
                };
                let got_t = page
                    .sensor(SensorLayer::Temperature)
                    .unwrap()
                    .values()
                    .unwrap()[i];
                assert_eq!(m[i], want_m, "level {level} cell ({col}, {row})");
                assert!(
                    got_t.to_bits() == want_t.to_bits() || (got_t.is_nan() && want_t.is_nan()),
                    "level {level} cell ({col}, {row}): {got_t} against {want_t}"
                );
            }
        }
    }

    let render = |tiles: &str, out: &str, extra: &[&str]| {
        let (tiles, out) = (s(&p(tiles)), s(&p(out)));
        let mut args = vec!["render", "--tiles", &tiles, "--top", "-q", "-o", &out];
        args.extend(extra);
        let o = dbms(&args);
        (o, std::fs::read(&out).unwrap_or_default())
    };
    assert_eq!(
        render("ir.dbt", "a.png", &[]).1,
        render("visual.dbt", "b.png", &[]).1
    );
    let (o, png) = render(
        "ir.dbt",
        "ir.png",
        &["--sensor", "ir", "--ir-range", "280,330"],
    );
    ok(o);
    let img = image::load_from_memory(&png).unwrap().to_rgb8();
    let (grass, asphalt) = (img.get_pixel(5, 15)[0], img.get_pixel(30, 15)[0]);
    assert!(asphalt > grass + 5, "asphalt {asphalt}, grass {grass}");
    let (o, _) = render("visual.dbt", "none.png", &["--sensor", "ir"]);
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && e.contains("no temperature layer") && e.contains("--temperature"),
        "{e}"
    );
    let (o, _) = render("ir.dbt", "x.png", &["--ir-range", "280,330"]);
    assert!(String::from_utf8_lossy(&o.stderr).contains("--sensor ir"));

    // A map off the database grid (one column narrower, or shifted) is refused with the fix.
    let off = |name: &str, w: usize, x0: f64| {
        let grid = Grid::north_up(x0, ORIGIN.1, 1.0, w, 20, Crs::epsg(32632));
        let path = p(name);
        geotiff::write_f32(&path, &Raster::new(grid, vec![300.0; w * 20])).unwrap();
        let path = s(&path);
        let out = s(&p("off.dbt"));
        dbms(&["pyramid", "--db", d, "--temperature", &path, "-o", &out])
    };
    for o in [
        off("narrow.tif", 39, ORIGIN.0),
        off("shifted.tif", 40, ORIGIN.0 + 0.5),
    ] {
        let e = String::from_utf8_lossy(&o.stderr);
        assert!(
            !o.status.success() && e.contains("not on the database grid") && e.contains("gdalwarp"),
            "{e}"
        );
    }
}

/// Night vision end to end: `dbms pyramid --materials --lights` writes the materials' NIR
/// reflectances (or their albedo, marked) and the lights, stood on the terrain, into the tile
/// header (a directional lamp with its beam, outside the view below); `dbms render --sensor nvg`
/// at full moon draws grass (NIR-bright) brighter than the road and shows the lamp in view; it needs --time and a material layer, and says so.
#[test]
fn night_vision_view_with_lights() {
    let t = tempfile::tempdir().unwrap();
    let dir = t.path().join("db");
    database(&dir);
    let d = dir.to_str().unwrap();
    let s = |p: &Path| p.to_str().unwrap().to_string();
    ok(dbms(&["materials", "--db", d, "-q"]));
    let lights = t.path().join("lights.geojson");
    let (x, y) = ORIGIN;
    let doc = serde_json::json!({"type": "FeatureCollection", "features": [
        {"type": "Feature", "properties": {"intensity_cd": 1500, "height_m": 6},
         "geometry": {"type": "Point", "coordinates": [x + 30.5, y - 10.5]}},
        {"type": "Feature", "properties": {"intensity_cd": 20000, "height_m": 0.3,
          "beam": {"azimuth_deg": 270, "elevation_deg": 3, "spread_deg": [12, 8]}},
         "geometry": {"type": "Point", "coordinates": [x + 0.5, y - 0.5]}}]});
    std::fs::write(&lights, doc.to_string()).unwrap();
    let (nvg, visual) = (t.path().join("nvg.dbt"), t.path().join("visual.dbt"));
    let (nvg_s, lights_s) = (s(&nvg), s(&lights));
    ok(dbms(&[
        "pyramid",
        "--db",
        d,
        "--materials",
        "--lights",
        &lights_s,
        "-q",
        "-o",
        &nvg_s,
    ]));
    ok(dbms(&["pyramid", "--db", d, "-q", "-o", &s(&visual)]));
    let info = dbms::tiles::TileReader::open(&nvg, 1)
        .unwrap()
        .info()
        .clone();
    assert_eq!(info.lights.len(), 2);
    assert_eq!(info.lights[0].z, 106.0, "100 m terrain + 6 m");
    let beam = dbms::tiles::Beam {
        azimuth_deg: 270.0,
        elevation_deg: 3.0,
        spread_deg: [12.0, 8.0],
    };
    assert_eq!(
        (info.lights[0].beam, info.lights[1].beam),
        (None, Some(beam))
    );
    let grass = info.materials.iter().find(|m| m.name == "grass").unwrap();
    assert_eq!(
        (grass.nir_from.as_str(), grass.nir_reflectance),
        ("nir_reflectance", 0.31)
    );
    assert!(info.effects["applied"].to_string().contains("light_points"));
    let schema = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/schemas/tiles-header.schema.json"
    );
    let schema: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(schema).unwrap()).unwrap();
    let header = serde_json::to_value(&info).unwrap();
    let errors: Vec<String> = jsonschema::validator_for(&schema)
        .unwrap()
        .iter_errors(&header)
        .map(|e| e.to_string())
        .collect();
    assert!(errors.is_empty(), "{errors:?}");

    // Looking east along row 10 from 5 m west of the grid, 30 m up, 45° down, at full moon
    // (0.14 lux: above the knee, so a top's green is 255 · ρ / 0.6): the bottom row sees grass
    // 10 m in, the centre row the east half's material 25 m in, and the lamp is in view.
    let eye = format!("{},{},130", x - 5.0, y - 10.5);
    let render = |tiles: &str, extra: &[&str]| {
        let out = s(&t.path().join("v.png"));
        let mut args = vec![
            "render",
            "--tiles",
            tiles,
            "--eye",
            &eye,
            "--attitude",
            "0,-45,90",
        ];
        args.extend(["--size", "160x100", "--json", "-o", &out]);
        args.extend(extra);
        let o = dbms(&args);
        (o, std::fs::read(&out).unwrap_or_default())
    };
    let full_moon = ["--sensor", "nvg", "--time", "2026-09-26T21:00:00Z"];
    let (o, png) = render(&nvg_s, &full_moon);
    let o = ok(o);
    let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(summary["lights_drawn"], 1, "{summary}");
    let img = image::load_from_memory(&png).unwrap().to_rgb8();
    let green = |r: f64| (255.0 * (r / 0.6).min(1.0)).round() as u8;
    let east = layer(&dir)[10 * 40 + 25];
    let east = info.materials.iter().find(|m| m.id == east).unwrap();
    assert_eq!(img.get_pixel(80, 99)[1], green(0.31), "grass");
    assert_eq!(
        img.get_pixel(80, 50)[1],
        green(east.nir_reflectance),
        "{}",
        east.name
    );
    let (o, _) = render(&nvg_s, &["--sensor", "nvg"]);
    assert!(String::from_utf8_lossy(&o.stderr).contains("needs --time"));
    let (o, _) = render(&s(&visual), &full_moon);
    let e = String::from_utf8_lossy(&o.stderr).to_string();
    assert!(
        e.contains("no material layer") && e.contains("--materials"),
        "{e}"
    );
}

/// `dbms radar` on [`database`]'s grass, road and 10 m building (cols 2..4, rows 2..4), X band,
/// the radar to the west: level grass returns Nathanson's γ = −20 dB times cos(incidence) =
/// sin(elevation); the ground east of the building is in radar shadow for 10 m / tan(elevation);
/// the ground at the foot of its west wall is a dihedral; the road and the tile roof have no
/// X-band model (NaN, listed); a ramp steeper than the radar's incidence lays over, a gentler
/// one does not; bad requests are one-line errors.
#[test]
fn radar_backscatter_shadow_dihedral_and_layover() {
    let t = tempfile::tempdir().unwrap();
    let run = |dir: &Path, az: &str, el: &str| -> (Vec<f64>, Vec<u8>, serde_json::Value) {
        let d = dir.to_str().unwrap();
        let (s0, class) = (dir.join("s0.tif"), dir.join("class.tif"));
        let o = ok(dbms(&[
            "radar",
            "--db",
            d,
            "--azimuth",
            az,
            "--elevation",
            el,
            "--band",
            "X",
            "--class-out",
            class.to_str().unwrap(),
            "-o",
            s0.to_str().unwrap(),
            "--json",
        ]));
        let s0 = dbms::io::read_raster(&s0).unwrap();
        let c = dbms::io::read_raster(&class).unwrap();
        let summary = serde_json::from_slice(&o.stdout).unwrap();
        let value = |i| Some(s0.sample(i, 0)).filter(|v| Some(*v) != s0.nodata);
        (
            (0..s0.grid.len())
                .map(|i| value(i).unwrap_or(f64::NAN))
                .collect(),
            (0..c.grid.len()).map(|i| c.sample(i, 0) as u8).collect(),
            summary,
        )
    };
    let dir = t.path().join("db");
    database(&dir);
    ok(dbms(&["materials", "--db", dir.to_str().unwrap(), "-q"]));
    let (s0, class, summary) = run(&dir, "270", "45");
    let at = |c: usize, r: usize| r * 40 + c;
    let want = 0.01 * 45f64.to_radians().sin();
    assert!((s0[at(10, 15)] - want).abs() < 1e-9, "{}", s0[at(10, 15)]);
    assert_eq!(class[at(10, 15)], 1, "lit");
    // Shadow: east of the 10 m building for 10 m (cols 4..14 of rows 2..4), not beyond.
    assert!(
        (4..13).all(|c| class[at(c, 3)] == 2),
        "{:?}",
        &class[at(0, 3)..at(20, 3)]
    );
    assert_eq!(class[at(15, 3)], 1);
    assert_eq!(s0[at(6, 3)], 0.0);
    // The foot of the west wall (col 1) is a dihedral; the roof (tile) has no model.
    assert_eq!((class[at(1, 2)], class[at(1, 3)]), (4, 4));
    assert_eq!(class[at(2, 2)], 6);
    assert!(s0[at(2, 2)].is_nan());
    let no_model = summary["no_model"].to_string();
    assert!(no_model.contains("roof_tile"), "{summary}");

    // A ramp rising 3 m per 1 m cell to the east (71.6°) faces a radar in the west: beyond a
    // 60° incidence (elevation 30°) it lays over; within an 80° one (elevation 10°) it does not.
    let ramp = t.path().join("ramp");
    database_over(&ramp, 40, 20, |c, _| 100.0 + 3.0 * c as f32);
    ok(dbms(&["materials", "--db", ramp.to_str().unwrap(), "-q"]));
    let (_, steep, _) = run(&ramp, "270", "30");
    assert_eq!(steep[at(10, 15)], 3, "layover");
    let (_, gentle, _) = run(&ramp, "270", "10");
    assert_eq!(gentle[at(10, 15)], 1, "lit");

    // Hard angles: an ulp either side of the west axis and the diagonals light level grass
    // alike (γ·sin E does not depend on the azimuth), and a radar a hair north or south of
    // west still puts the ground east of the building in shadow.
    let west_ulps = [
        f64::from_bits(270f64.to_bits() - 1),
        f64::from_bits(270f64.to_bits() + 1),
    ];
    for az in west_ulps.into_iter().chain([225.0, 315.0, 135.0, 45.0]) {
        let (s0, class, _) = run(&dir, &az.to_string(), "45");
        assert!(
            (s0[at(10, 15)] - want).abs() < 1e-9,
            "azimuth {az}: {}",
            s0[at(10, 15)]
        );
        if (az - 270.0).abs() < 1e-6 {
            assert!((4..13).all(|c| class[at(c, 3)] == 2), "azimuth {az}");
        }
    }

    let d = dir.to_str().unwrap();
    for (args, want) in [
        (
            vec!["--azimuth", "90", "--elevation", "0"],
            "the elevation must be",
        ),
        (
            vec!["--azimuth", "90", "--elevation", "NaN"],
            "the elevation must be",
        ),
        // Issue 40: a NaN azimuth was reported as an elevation error.
        (
            vec!["--azimuth", "NaN", "--elevation", "30"],
            "the azimuth must be a finite",
        ),
        (
            vec!["--azimuth", "inf", "--elevation", "30"],
            "the azimuth must be a finite",
        ),
        (
            vec!["--azimuth", "90", "--elevation", "30", "--band", "Q"],
            "--band Q",
        ),
    ] {
        let mut all = vec!["radar", "--db", d, "-o", "x.tif"];
        all.extend(args);
        let o = dbms(&all);
        let e = String::from_utf8_lossy(&o.stderr);
        assert!(
            !o.status.success() && e.contains(want) && e.lines().count() == 1,
            "{e}"
        );
    }
}

/// `pyramid --normals` on a quadratic terrain, whose centred differences are its exact
/// derivatives: every level-0 normal is the analytic one (the one-sided difference at the
/// grid's edge: the derivative half a cell in), straight up on the building, nodata where the
/// photo is missing; every coarse normal the renormalised sum of its block's analytic normals.
/// Both to the packing's 0.004°.
#[test]
fn normals_are_the_terrain_s_analytic_normals_at_every_level() {
    use dbms::tiles::{unpack_normal, SensorLayer};
    let t = tempfile::tempdir().unwrap();
    let dir = t.path().join("db");
    let (w, h) = (40usize, 20usize);
    // z = 100 + a·(c − 13.3)² + b·(r − 7)² + e·c·r over columns c and rows r of 1 m cells.
    let (a, b, e) = (0.02, -0.015, 0.01);
    let z = |c: f64, r: f64| 100.0 + a * (c - 13.3).powi(2) + b * (r - 7.0).powi(2) + e * c * r;
    database_over(&dir, w, h, |c, r| z(c as f64, r as f64) as f32);
    let tiles = t.path().join("n.dbt");
    let d = dir.to_str().unwrap();
    let args = [
        "pyramid",
        "--db",
        d,
        "--page",
        "8",
        "--factor",
        "2",
        "--normals",
        "-q",
    ];
    ok(dbms(
        &[&args[..], &["-o", tiles.to_str().unwrap()]].concat(),
    ));

    // dz/dc and dz/dr as the grid takes them: centred inside, one-sided at the edges.
    let d_dc = |c: f64, r: f64| match c {
        0.0 => z(1.0, r) - z(0.0, r),
        c if c == (w - 1) as f64 => z(c, r) - z(c - 1.0, r),
        c => 2.0 * a * (c - 13.3) + e * r,
    };
    let d_dr = |c: f64, r: f64| match r {
        0.0 => z(c, 1.0) - z(c, 0.0),
        r if r == (h - 1) as f64 => z(c, r) - z(c, r - 1.0),
        r => 2.0 * b * (r - 7.0) + e * c,
    };
    let truth = |c: usize, r: usize| -> Option<[f64; 3]> {
        if c == w - 1 {
            return None; // no photo: no surface
        }
        if (2..4).contains(&c) && (2..4).contains(&r) {
            return Some([0.0, 0.0, 1.0]); // the building's level roof
        }
        // World y grows northward, against the rows.
        let (zx, zy) = (d_dc(c as f64, r as f64), -d_dr(c as f64, r as f64));
        let n = (zx * zx + zy * zy + 1.0).sqrt();
        Some([-zx / n, -zy / n, 1.0 / n])
    };
    let reader = dbms::tiles::TileReader::open(&tiles, 64).unwrap();
    let info = reader.info().clone();
    assert_eq!(info.sensor_layers(), [SensorLayer::Normal]);
    assert_eq!(info.effects["applied"].to_string(), r#"["normal_layer"]"#);
    let angle = |u: [f64; 3], v: [f64; 3]| {
        let dot: f64 = (0..3).map(|k| u[k] * v[k]).sum();
        let len = |x: [f64; 3]| (0..3).map(|k| x[k] * x[k]).sum::<f64>().sqrt();
        (dot / len(u) / len(v)).clamp(-1.0, 1.0).acos().to_degrees()
    };
    let (mut checked, mut tilted) = (0, 0);
    for (level, l) in info.levels.iter().enumerate() {
        let s = 1usize << level;
        for row in 0..l.height {
            for col in 0..l.width {
                let mut sum = [0.0f64; 3];
                let mut any = false;
                for r0 in row * s..((row + 1) * s).min(h) {
                    for c0 in col * s..((col + 1) * s).min(w) {
                        if let Some(n) = truth(c0, r0) {
                            (0..3).for_each(|k| sum[k] += n[k]);
                            any = true;
                        }
                    }
                }
                let p = info.page_size;
                let page = reader.page(level, col / p, row / p).unwrap();
                let cells = page.sensor(SensorLayer::Normal).unwrap().normals().unwrap();
                let got = unpack_normal(cells[(row % p) * p + col % p]);
                let at = format!("level {level} cell ({col}, {row})");
                match (got, any) {
                    (None, false) => {}
                    (Some(g), true) => {
                        assert!(angle(g, sum) < 0.004, "{at}: {g:?} against {sum:?}");
                        tilted += usize::from(angle(sum, [0.0, 0.0, 1.0]) > 1.0);
                        checked += 1;
                    }
                    _ => panic!("{at}: {got:?}, expected data {any}"),
                }
            }
        }
    }
    assert!(
        checked > 1000 && tilted > 500,
        "{checked} cells, {tilted} tilted"
    );
}

/// `materials --objects`: a bare material for every placed object, `NAME=MATERIAL` for the
/// placements of one object file (winning over the bare one); objects not named keep what the
/// other sources say; an unknown name or a material given twice is a one-line error.
#[test]
fn each_placed_object_gets_its_own_material() {
    let t = tempfile::tempdir().unwrap();
    let dir = t.path().join("db");
    database(&dir);
    let (d, p) = (dir.to_str().unwrap(), |n: &str| t.path().join(n));
    let s = |p: &Path| p.to_str().unwrap().to_string();
    for (name, height) in [("tree", "6"), ("tank", "4")] {
        let out = s(&p(&format!("{name}.dvox")));
        let args = ["object", "cone", "--height", height, "--radius", "1.5"];
        ok(dbms(
            &[&args[..], &["--voxel", "0.5", "-q", "-o", &out]].concat(),
        ));
    }
    // Trees at columns 10 and 20 of row 10, the tank at column 30 (nowhere near the building).
    let (x, y) = ORIGIN;
    for (name, col) in [("tree", 10.5), ("tree", 20.5), ("tank", 30.5)] {
        let object = s(&p(&format!("{name}.dvox")));
        let at = format!("{},{}", x + col, y - 10.5);
        let args = ["place", "--db", d, "--object", &object, "--at", &at, "-q"];
        ok(dbms(&args));
    }
    let table = MaterialTable::default_table();
    let name_at = |ids: &[u8], col: usize| table.by_id(ids[10 * 40 + col]).unwrap().name.clone();
    let run = |objects: &[&str]| {
        let mut args = vec!["materials", "--db", d, "-q"];
        objects.iter().for_each(|o| args.extend(["--objects", o]));
        dbms(&args)
    };
    ok(run(&["forest", "tank=roof_metal"]));
    let ids = layer(&dir);
    let got: Vec<String> = [10, 20, 30].iter().map(|&c| name_at(&ids, c)).collect();
    assert_eq!(got, ["forest", "forest", "roof_metal"]);
    // Only the tank named: the trees' cells are what the photo says (grass on the west half,
    // the road's grey from column 20).
    ok(run(&["tank=roof_metal"]));
    let ids = layer(&dir);
    let got: Vec<String> = [10, 20, 30].iter().map(|&c| name_at(&ids, c)).collect();
    assert_eq!(got, ["grass", "asphalt", "roof_metal"]);
    for (objects, want) in [
        (
            &["tonk=roof_metal"][..],
            "no placed object is named \"tonk\"",
        ),
        (&["forest", "grass"][..], "given twice"),
        (&["tank=water", "tank=grass"][..], "given twice"),
        (&["tank=tin"][..], "\"tin\" is not in the material table"),
    ] {
        let o = run(objects);
        let e = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success() && e.contains(want), "{objects:?}: {e}");
        assert_eq!(e.trim().lines().count(), 1, "{e}");
    }
    let o = run(&["tonk=roof_metal"]);
    assert!(String::from_utf8_lossy(&o.stderr).contains("tank, tree"));
}

/// `render --sensor radar --band X` puts the radar at the eye: each pixel is γ·cos θ of the
/// grass it sees (Nathanson's γ = −20 dB, θ the incidence of the pixel's own ray, worked out
/// here from the pinhole camera: the ray through pixel `(i, j)` is forward + x′·right + y′·up on
/// an image plane one unit ahead). Looking straight down on level grass θ is the ray's angle
/// off the vertical; looking east at a 5 m grass cliff the face is a wall facing west, so θ is
/// the ray's angle off west, not the slope of the cell's stored normal. The road (asphalt: no
/// model published) is drawn as unclassified; --band needs the normal layer and --top has no
/// eye, and both say so.
#[test]
fn radar_at_the_eye_lights_each_pixel_at_its_own_incidence() {
    let t = tempfile::tempdir().unwrap();
    let dir = t.path().join("db");
    // Level at 100 m, a 5 m cliff up at column 10 (grass to column 19, the road beyond).
    database_over(&dir, 40, 20, |c, _| if c < 10 { 100.0 } else { 105.0 });
    let (d, s) = (dir.to_str().unwrap(), |p: &Path| {
        p.to_str().unwrap().to_string()
    });
    ok(dbms(&["materials", "--db", d, "-q"]));
    let (tiles, plain) = (t.path().join("r.dbt"), t.path().join("p.dbt"));
    let pyramid = ["pyramid", "--db", d, "--page", "8", "--factor", "2", "-q"];
    let with = ["--materials", "--normals", "-o", &s(&tiles)];
    ok(dbms(&[&pyramid[..], &with].concat()));
    ok(dbms(
        &[&pyramid[..], &["--materials", "-o", &s(&plain)]].concat(),
    ));
    let (x, y) = ORIGIN;
    let (w, h, fov) = (64usize, 48usize, 60.0f64);
    let render = |tiles: &Path, eye: String, attitude: &str, extra: &[&str]| {
        let out = s(&t.path().join("radar.png"));
        let (size, tiles) = (format!("{w}x{h}"), s(tiles));
        let mut args = vec!["render", "--tiles", &tiles, "--eye", &eye];
        args.extend(["--attitude", attitude, "--size", &size, "-q", "-o", &out]);
        args.extend(["--sensor", "radar"]);
        args.extend(extra);
        let o = dbms(&args);
        (o, std::fs::read(&out).unwrap_or_default())
    };
    // The unit ray through pixel (i, j) in the camera's own axes: forward, right, up.
    let ray = |i: usize, j: usize| {
        let half_w = (fov.to_radians() / 2.0).tan();
        let half_h = half_w * h as f64 / w as f64;
        let xp = (2.0 * (i as f64 + 0.5) / w as f64 - 1.0) * half_w;
        let yp = (1.0 - 2.0 * (j as f64 + 0.5) / h as f64) * half_h;
        let n = (1.0 + xp * xp + yp * yp).sqrt();
        (1.0 / n, xp / n, yp / n)
    };
    let gamma = 10f64.powf(-20.0 / 10.0);
    let grey = |cos_inc: f64| dbms::backscatter::grey_db((gamma * cos_inc) as f32);
    let close = |got: u8, want: u8, at: &str| {
        assert!(got.abs_diff(want) <= 1, "{at}: {got} against {want}");
    };

    // Straight down from 50 m over column 5 (pitch −90: forward is down): cos θ = forward.
    let (o, png) = render(
        &tiles,
        format!("{},{},150", x + 5.0, y - 10.0),
        "0,-90,0",
        &["--band", "X"],
    );
    ok(o);
    let img = image::load_from_memory(&png).unwrap().to_rgb8();
    // The ground seen spans ±29 m across and ±21 m along; these pixels see level grass (west of
    // column 9, whose centred difference takes in the cliff, and inside the grid).
    for (i, j) in [(32, 24), (31, 23), (28, 20), (34, 30), (29, 33)] {
        let (f, _, _) = ray(i, j);
        close(
            img.get_pixel(i as u32, j as u32)[0],
            grey(f),
            &format!("down ({i}, {j})"),
        );
    }

    // Looking east from 2 m west of the grid at 102 m: the centre rays meet the cliff face at
    // x = 10 m (12 m ahead), a wall facing west: cos θ = the ray's eastward part, forward.
    let (o, png) = render(
        &tiles,
        format!("{},{},102", x - 2.0, y - 10.0),
        "0,0,90",
        &["--band", "X"],
    );
    ok(o);
    let img = image::load_from_memory(&png).unwrap().to_rgb8();
    let mut walls = 0;
    for j in 20..28 {
        for i in 26..38 {
            // Below the cliff's top at 12 m ahead (the ray climbs yp·12 / forward metres).
            let (f, _, up) = ray(i, j);
            if 102.0 + up / f * 12.0 < 104.8 && 102.0 + up / f * 12.0 > 100.2 {
                close(
                    img.get_pixel(i as u32, j as u32)[0],
                    grey(f),
                    &format!("wall ({i}, {j})"),
                );
                walls += 1;
            }
        }
    }
    assert!(walls > 40, "{walls} wall pixels checked");
    // Red where the road (no model at X band) is seen: beyond the grass, far up the frame.
    let (o, png) = render(
        &tiles,
        format!("{},{},130", x + 30.0, y - 10.0),
        "0,-90,0",
        &["--band", "X"],
    );
    ok(o);
    let img = image::load_from_memory(&png).unwrap().to_rgb8();
    assert_eq!(img.get_pixel(32, 24).0, [96, 0, 0], "asphalt: no model");

    let (o, _) = render(
        &plain,
        format!("{},{},150", x + 5.0, y - 10.0),
        "0,-90,0",
        &["--band", "X"],
    );
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && e.contains("no normal layer") && e.contains("--normals"),
        "{e}"
    );
    let (o, _) = render(
        &tiles,
        format!("{},{},150", x + 5.0, y - 10.0),
        "0,-90,0",
        &["--band", "X", "--top"],
    );
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && e.contains("--top"), "{e}");
}

/// `o` failed with one `dbms: error:` line containing each of `needles`.
fn refused(o: &Output, needles: &[&str]) {
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert_eq!(err.lines().count(), 1, "one line: {err}");
    assert!(err.starts_with("dbms: error: "), "{err}");
    for n in needles {
        assert!(err.contains(n), "want {n:?} in: {err}");
    }
}

/// A photo, a σ⁰ map, a map in °C given as the temperature; a temperature map or σ⁰ in dB
/// given as the backscatter; a temperature map as the radiance: each is refused, naming what
/// it holds and what the layer holds, before any tile is made (issue 40, defect 5).
#[test]
fn a_map_of_another_kind_is_refused_as_a_sensor_layer() {
    let t = tempfile::tempdir().unwrap();
    let dir = t.path().join("db");
    database(&dir);
    let (d, p) = (dir.to_str().unwrap(), |n: &str| t.path().join(n));
    let s = |n: &str| p(n).to_str().unwrap().to_string();
    ok(dbms(&["materials", "--db", d, "-q"]));
    ok(thermal(d, "2026-07-01T13:24:00Z", &p("k.tif"), "-q"));
    let radar = ["radar", "--db", d, "--azimuth", "135", "--elevation", "40"];
    ok(dbms(
        &[&radar[..], &["--band", "X", "-q", "-o", &s("s0.tif")]].concat(),
    ));
    let grid = Grid::north_up(ORIGIN.0, ORIGIN.1, 1.0, 40, 20, Crs::epsg(32632));
    let filled = |name: &str, v: f32| {
        geotiff::write_f32(&p(name), &Raster::filled(grid.clone(), v)).unwrap();
        s(name)
    };
    let (celsius, db) = (filled("c.tif", 21.5), filled("db.tif", -14.0));
    let photo = dir.join("c.tif").to_str().unwrap().to_string();
    let ids = Database::open(&dir)
        .unwrap()
        .layer_path("materials")
        .unwrap();
    let ids = ids.to_str().unwrap().to_string();
    let cases: [(&str, &str, &[&str]); 7] = [
        ("--temperature", &photo, &["has 4 bands of Byte samples (an image?), but a temperature map has one band of kelvin"]),
        ("--temperature", &ids, &["has Byte samples, but a temperature map holds kelvin as floating point"]),
        ("--temperature", &s("s0.tif"), &["holds values from 0 to", "outside the 150 to 400 K a temperature map holds"]),
        ("--temperature", &celsius, &["holds values from 21.5 to 21.5", "in °C? add 273.15"]),
        ("--backscatter", &s("k.tif"), &["outside the 0 to 100 (+20 dB) a linear σ⁰ map holds"]),
        ("--backscatter", &db, &["holds values from -14 to -14", "in dB? convert"]),
        ("--radiance", &s("k.tif"), &["outside the 0 to"]),
    ];
    for (option, map, needles) in cases {
        let out = p("x.dbt");
        let o = dbms(&[
            "pyramid",
            "--db",
            d,
            "--materials",
            option,
            map,
            "-o",
            out.to_str().unwrap(),
        ]);
        refused(&o, needles);
        assert!(
            String::from_utf8_lossy(&o.stderr).contains(map),
            "names the file"
        );
        assert!(!out.exists(), "{option} {map}: no tile file");
    }
}

/// A land-cover raster without a CRS over a database with one, and one wholly outside the
/// grid: each refused in one line (issue 40, defect 5).
#[test]
fn land_cover_without_a_crs_or_off_the_grid_is_refused() {
    let t = tempfile::tempdir().unwrap();
    let dir = t.path().join("db");
    database(&dir);
    let d = dir.to_str().unwrap();
    let before = std::fs::read(dir.join("manifest.json")).unwrap();
    let landcover = |name: &str, x: f64, crs: Crs| {
        let g = Grid::north_up(x, ORIGIN.1, 10.0, 4, 2, crs);
        let path = t.path().join(name);
        geotiff::write_u8(
            &path,
            &Raster::new(g, vec![80, 80, 10, 10, 80, 80, 10, 10]),
            None,
        )
        .unwrap();
        path.to_str().unwrap().to_string()
    };
    let materials = |lc: &str| {
        dbms(&[
            "materials",
            "--db",
            d,
            "--landcover",
            lc,
            "--legend",
            "esa_worldcover",
        ])
    };
    let no_crs = landcover("nocrs.tif", ORIGIN.0, Crs::unknown());
    refused(
        &materials(&no_crs),
        &["nocrs.tif: has no CRS (no GeoKeys, no .prj beside it) while the database is in EPSG:32632", "gdalsrsinfo -o wkt1 EPSG:32632 >"],
    );
    let far = landcover("far.tif", ORIGIN.0 + 10_000.0, Crs::epsg(32632));
    refused(
        &materials(&far),
        &["far.tif: covers [510000, 5300000, 510040, 5300020] (EPSG:32632), no cell of the database's [500000, 5300000, 500040, 5300020]"],
    );
    assert_eq!(std::fs::read(dir.join("manifest.json")).unwrap(), before);
}
