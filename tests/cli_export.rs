//! `dbms export mesh` end to end: a database made with the library, the tileset and its glTF
//! files read back and checked against the grid, the buildings layer and the 3D Tiles rules.

use dbms::crs::Crs;
use dbms::db::{Database, COLOUR, ELEVATION};
use dbms::grid::Grid;
use dbms::mesh::gltf::read_glb;
use dbms::mesh::tileset::content_origins;
use dbms::mesh::{Lighting, Part};
use dbms::raster::{Colour, Elevation};
use serde_json::{json, Value};
use std::collections::BTreeMap;
use std::path::Path;
#[path = "support/cli.rs"]
mod cli;
use cli::dbms;

const W: usize = 150;
const H: usize = 110;
const CELL: f64 = 0.5;
const X0: f64 = 500_000.0;
const Y0: f64 = 5_300_000.0;

/// Terrain height at grid point (column, row): a tilted, wavy slope with a ridge along a
/// diagonal and noise a few centimetres high, so simplification has work at every bound.
fn height(c: usize, r: usize) -> f32 {
    let (x, y) = (c as f64, r as f64);
    let ridge = (6.0 - (x - y).abs() * 0.15).max(0.0);
    let noise = ((c * 7919 + r * 104_729) % 97) as f64 / 97.0 * 0.04;
    (380.0 + 0.03 * x - 0.02 * y + 1.5 * (x / 9.0).sin() * (y / 13.0).cos() + ridge + noise) as f32
}

/// The buildings: an L shape and a block with a courtyard, roof heights to the millimetre.
const ROOFS: [f64; 2] = [399.137, 405.002];

/// A database of W × H cells at 0.5 m in UTM 32N: terrain, photo, a nodata hole, two buildings
/// and one placed cone tree.
fn make_db(dir: &Path) -> std::path::PathBuf {
    let grid = Grid::north_up(X0, Y0 + H as f64 * CELL, CELL, W, H, Crs::epsg(32632));
    let z: Vec<f32> = (0..W * H)
        .map(|i| {
            let (c, r) = (i % W, i / W);
            if (100..106).contains(&c) && (20..24).contains(&r) {
                f32::NAN
            } else {
                height(c, r)
            }
        })
        .collect();
    let photo: Vec<[u8; 4]> = (0..W * H)
        .map(|i| [(i % W * 255 / W) as u8, (i / W * 255 / H) as u8, 90, 255])
        .collect();
    let db_dir = dir.join("db");
    let mut db = Database::create(&db_dir, grid.clone(), vec![]).unwrap();
    dbms::io::geotiff::write_f32(&db_dir.join("e.tif"), &Elevation::new(grid.clone(), z)).unwrap();
    dbms::io::geotiff::write_rgba8(&db_dir.join("c.tif"), &Colour::new(grid, photo)).unwrap();
    db.set_layer(ELEVATION, "elevation", "e.tif", None).unwrap();
    db.set_layer(COLOUR, "colour", "c.tif", None).unwrap();
    let l_shape = json!([
        [500010.0, 5300010.0],
        [500025.0, 5300010.0],
        [500025.0, 5300016.5],
        [500016.25, 5300016.5],
        [500016.25, 5300030.25],
        [500010.0, 5300030.25],
        [500010.0, 5300010.0]
    ]);
    let outer = json!([
        [500040.0, 5300030.0],
        [500060.0, 5300030.0],
        [500060.0, 5300050.0],
        [500040.0, 5300050.0],
        [500040.0, 5300030.0]
    ]);
    let court = json!([
        [500045.0, 5300035.0],
        [500045.0, 5300045.0],
        [500055.0, 5300045.0],
        [500055.0, 5300035.0],
        [500045.0, 5300035.0]
    ]);
    let doc = json!({"type": "FeatureCollection", "features": [
        {"type": "Feature", "properties": {"roof_z": ROOFS[0]}, "geometry": {"type": "Polygon", "coordinates": [l_shape]}},
        {"type": "Feature", "properties": {"roof_z": ROOFS[1]}, "geometry": {"type": "Polygon", "coordinates": [outer, court]}}]});
    std::fs::write(db_dir.join("b.geojson"), doc.to_string()).unwrap();
    db.set_layer("buildings", "buildings", "b.geojson", None)
        .unwrap();
    db.save().unwrap();
    let tree = dir.join("tree.dvox");
    let out = dbms(&[
        "object",
        "cone",
        "--height",
        "6",
        "--radius",
        "2",
        "--voxel",
        "0.25",
        "--seed",
        "1",
        "-o",
        tree.to_str().unwrap(),
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let out = dbms(&[
        "place",
        "--db",
        db_dir.to_str().unwrap(),
        "--object",
        tree.to_str().unwrap(),
        "--at",
        "500030,5300040",
        "--heading",
        "30",
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    db_dir
}

/// The command line `export mesh --db DB -o OUT ARGS`.
fn export_args<'a>(db: &'a Path, out: &'a Path, args: &[&'a str]) -> Vec<&'a str> {
    let mut all = vec![
        "export",
        "mesh",
        "--db",
        db.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ];
    all.extend_from_slice(args);
    all
}

/// `dbms --json export mesh --db DB -o OUT ARGS`, which must succeed: its summary.
fn export(db: &Path, out: &Path, args: &[&str]) -> Value {
    let all = [vec!["--json"], export_args(db, out, args)].concat();
    let o = dbms(&all);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    serde_json::from_slice(&o.stdout).unwrap()
}

/// Every tile of the tileset with its level (from its content's path) and parent's index.
struct Tiles {
    tiles: Vec<(Value, Option<usize>)>,
}

impl Tiles {
    fn of(tileset: &Value) -> Tiles {
        fn walk(t: &Value, parent: Option<usize>, out: &mut Vec<(Value, Option<usize>)>) {
            let me = out.len();
            out.push((t.clone(), parent));
            for c in t["children"].as_array().into_iter().flatten() {
                walk(c, Some(me), out);
            }
        }
        let mut tiles = Vec::new();
        walk(&tileset["root"], None, &mut tiles);
        Tiles { tiles }
    }
}

fn boxes(t: &Value) -> ([f64; 3], [f64; 3]) {
    let b: Vec<f64> = t["boundingVolume"]["box"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    let h = [b[3], b[7], b[11]];
    (
        [b[0] - h[0], b[1] - h[1], b[2] - h[2]],
        [b[0] + h[0], b[1] + h[1], b[2] + h[2]],
    )
}

/// The decoded parts of every content (world coordinates: its tile's origin added back), by
/// its uri.
fn contents(out: &Path, tileset: &Value) -> BTreeMap<String, Vec<Part>> {
    content_origins(tileset)
        .into_iter()
        .map(|(uri, origin)| {
            let bytes = std::fs::read(out.join(&uri)).unwrap();
            let parts = read_glb(&bytes, origin).unwrap();
            (uri, parts)
        })
        .collect()
}

/// A tile's origin (world) from its extras.
fn origin_of(t: &Value) -> [f64; 3] {
    let o = t["extras"]["origin"].as_array().unwrap();
    [0, 1, 2].map(|k| o[k].as_f64().unwrap())
}

/// The transform of a tile (column-major 4 × 4) applied to `p`.
fn carry(t: &Value, p: [f64; 3]) -> [f64; 3] {
    let m: Vec<f64> = t["transform"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_f64().unwrap())
        .collect();
    std::array::from_fn(|r| m[r] * p[0] + m[4 + r] * p[1] + m[8 + r] * p[2] + m[12 + r])
}

/// The sample-sized scene exported: the tileset matches the 3D Tiles schema; boxes hold their
/// content and children; errors fall from root to leaves; the finest terrain is within the
/// bound of every valid grid point (checked by a brute-force search over the decoded
/// triangles, independently of the exporter's own measure); every roof is at the buildings
/// layer's roof_z to the centimetre at every level; the run is byte-for-byte repeatable.
#[test]
fn export_matches_grid_buildings_and_3d_tiles() {
    let dir = tempfile::tempdir().unwrap();
    let db = make_db(dir.path());
    let out = dir.path().join("mesh");
    let bound = 0.05;
    let summary = export(
        &db,
        &out,
        &["--max-error", "0.05", "--tile-cells", "32", "--factor", "2"],
    );
    let levels = summary["levels"].as_array().unwrap();
    assert_eq!(levels.len(), 4, "{summary}");
    assert!(
        levels[0]["max_error_m"].as_f64().unwrap() <= bound + 1e-9,
        "{summary}"
    );
    assert_eq!(summary["buildings"], 2);
    assert_eq!(summary["objects"], 1);
    assert_eq!(summary["on_globe"], true);

    let text = std::fs::read_to_string(out.join("tileset.json")).unwrap();
    let tileset: Value = serde_json::from_str(&text).unwrap();
    let schema_text = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("schemas/3dtiles-tileset.schema.json"),
    )
    .unwrap();
    let schema = jsonschema::validator_for(&serde_json::from_str(&schema_text).unwrap()).unwrap();
    let errors: Vec<String> = schema
        .iter_errors(&tileset)
        .map(|e| format!("{e} at {}", e.instance_path()))
        .collect();
    assert!(errors.is_empty(), "{}", errors.join("\n"));

    let tiles = Tiles::of(&tileset);
    let decoded = contents(&out, &tileset);
    for (t, parent) in &tiles.tiles {
        let (lo, hi) = boxes(t);
        let ge = t["geometricError"].as_f64().unwrap();
        if let Some(p) = parent {
            // The child's box, carried into the parent's frame by the child's transform.
            let (plo, phi) = boxes(&tiles.tiles[*p].0);
            for c in 0..8 {
                let corner = std::array::from_fn(|k| if c >> k & 1 == 0 { lo[k] } else { hi[k] });
                let q = carry(t, corner);
                for k in 0..3 {
                    assert!(
                        plo[k] - 1e-6 <= q[k] && q[k] <= phi[k] + 1e-6,
                        "a child's box leaves its parent's"
                    );
                }
            }
            assert!(tiles.tiles[*p].0["geometricError"].as_f64().unwrap() >= ge);
        } else {
            assert_eq!(
                t["transform"].as_array().unwrap().len(),
                16,
                "the root is on the globe"
            );
        }
        let origin = origin_of(t);
        if t.get("children").is_none() {
            assert_eq!(ge, 0.0, "leaves are exact");
        }
        if let Some(uri) = t["content"]["uri"].as_str() {
            for part in &decoded[uri] {
                for p in &part.mesh.positions {
                    for k in 0..3 {
                        let l = p[k] - origin[k];
                        assert!(
                            lo[k] - 1e-6 <= l && l <= hi[k] + 1e-6,
                            "{uri}: a vertex outside its box"
                        );
                    }
                }
            }
        }
    }

    // The finest terrain against every valid grid point, by brute force.
    let mut tris: Vec<[[f64; 3]; 3]> = Vec::new();
    for (uri, parts) in &decoded {
        if uri.starts_with("tiles/0/") {
            for p in parts.iter().filter(|p| p.lighting == Lighting::Unlit) {
                tris.extend(
                    p.mesh
                        .triangles
                        .iter()
                        .map(|t| t.map(|i| p.mesh.positions[i as usize])),
                );
            }
        }
    }
    let (mut worst, mut uncovered) = (0.0f64, 0);
    for r in 0..H {
        for c in 0..W {
            if (99..107).contains(&c) && (19..25).contains(&r) {
                continue; // the hole and the ring of points beside it
            }
            let (x, y) = (
                X0 + (c as f64 + 0.5) * CELL,
                Y0 + H as f64 * CELL - (r as f64 + 0.5) * CELL,
            );
            let hit = tris.iter().find_map(|t| interpolate(t, x, y));
            match hit {
                Some(z) => worst = worst.max((z - height(c, r) as f64).abs()),
                None => uncovered += 1,
            }
        }
    }
    assert_eq!(uncovered, 0, "grid points with no terrain over them");
    // The bound, plus the 16-bit positions' rounding (at most 1 mm).
    assert!(
        worst <= bound + 0.001 + 1e-6,
        "worst vertical error {worst}"
    );

    // Roofs: at every level, each building's corners carry its roof_z to the centimetre.
    let corners = [
        (500016.25, 5300030.25, ROOFS[0]),
        (500025.0, 5300010.0, ROOFS[0]),
        (500045.0, 5300045.0, ROOFS[1]),
    ];
    for level in 0..levels.len() {
        for &(x, y, roof) in &corners {
            let tops: Vec<f64> = decoded
                .iter()
                .filter(|(uri, _)| uri.starts_with(&format!("tiles/{level}/")))
                .flat_map(|(_, parts)| parts.iter().filter(|p| p.lighting == Lighting::Lit))
                .flat_map(|p| p.mesh.positions.iter())
                .filter(|p| (p[0] - x).abs() < 0.01 && (p[1] - y).abs() < 0.01)
                .map(|p| p[2])
                .collect();
            let top = tops.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
            assert!(
                (top - roof).abs() <= 0.01,
                "level {level}: roof at ({x}, {y}) is {top}, layer says {roof}"
            );
        }
    }

    // Same database, same options: the same bytes.
    let again = dir.path().join("again");
    export(
        &db,
        &again,
        &["--max-error", "0.05", "--tile-cells", "32", "--factor", "2"],
    );
    assert_eq!(
        std::fs::read(out.join("tileset.json")).unwrap(),
        std::fs::read(again.join("tileset.json")).unwrap()
    );
    for uri in decoded.keys() {
        assert_eq!(
            std::fs::read(out.join(uri)).unwrap(),
            std::fs::read(again.join(uri)).unwrap(),
            "{uri}"
        );
    }
}

/// The height of triangle `t` (world) at `(x, y)`, when it covers the point (edges included).
fn interpolate(t: &[[f64; 3]; 3], x: f64, y: f64) -> Option<f64> {
    let [a, b, c] = t;
    let d = (b[0] - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (b[1] - a[1]);
    let wb = ((x - a[0]) * (c[1] - a[1]) - (c[0] - a[0]) * (y - a[1])) / d;
    let wc = ((b[0] - a[0]) * (y - a[1]) - (x - a[0]) * (b[1] - a[1])) / d;
    let wa = 1.0 - wb - wc;
    let eps = -1e-9;
    (wa >= eps && wb >= eps && wc >= eps).then(|| wa * a[2] + wb * b[2] + wc * c[2])
}

/// The finest level's terrain has no cracks: every triangle edge is shared by two triangles
/// (across tiles too) except on the grid's border and around the nodata hole.
#[test]
fn finest_terrain_has_no_cracks_between_tiles() {
    let dir = tempfile::tempdir().unwrap();
    let db = make_db(dir.path());
    let out = dir.path().join("mesh");
    export(&db, &out, &["--max-error", "0.2", "--tile-cells", "32"]);
    let tileset: Value =
        serde_json::from_slice(&std::fs::read(out.join("tileset.json")).unwrap()).unwrap();
    let decoded = contents(&out, &tileset);
    // A vertex's grid point (column, row): the same point in two tiles is one key, whatever
    // the two files' rounding.
    let key = |p: [f64; 3]| {
        (
            ((p[0] - X0) / CELL - 0.5).round() as i64,
            ((Y0 + H as f64 * CELL - p[1]) / CELL - 0.5).round() as i64,
        )
    };
    // Edge (lower point, higher point) → +1 per use one way, −1 the other.
    type Edge = ((i64, i64), (i64, i64));
    let mut edges: BTreeMap<Edge, i32> = BTreeMap::new();
    for (uri, parts) in &decoded {
        if !uri.starts_with("tiles/0/") {
            continue;
        }
        for p in parts.iter().filter(|p| p.lighting == Lighting::Unlit) {
            for t in &p.mesh.triangles {
                for k in 0..3 {
                    let (a, b) = (
                        key(p.mesh.positions[t[k] as usize]),
                        key(p.mesh.positions[t[(k + 1) % 3] as usize]),
                    );
                    // +1 one way, −1 the other: a shared edge sums to 0.
                    if a < b {
                        *edges.entry((a, b)).or_default() += 1;
                    } else {
                        *edges.entry((b, a)).or_default() -= 1;
                    }
                }
            }
        }
    }
    let open: Vec<_> = edges
        .iter()
        .filter(|(_, n)| **n != 0)
        .map(|(e, _)| *e)
        .collect();
    assert!(!open.is_empty(), "the border is open");
    for (pa, pb) in open {
        let on_border =
            |p: (i64, i64)| p.0 == 0 || p.1 == 0 || p.0 == W as i64 - 1 || p.1 == H as i64 - 1;
        let by_hole = |p: (i64, i64)| (99..107).contains(&p.0) && (19..25).contains(&p.1);
        assert!(
            (on_border(pa) && on_border(pb)) || by_hole(pa) || by_hole(pb),
            "an open edge inside the grid: {pa:?}–{pb:?}"
        );
    }
}

/// Bad options and a missing database: one-line errors, a non-zero exit, nothing written.
#[test]
fn bad_input_is_a_one_line_error() {
    let dir = tempfile::tempdir().unwrap();
    let db = make_db(dir.path());
    let out = dir.path().join("mesh");
    for (args, says) in [
        (vec!["--max-error=-1"], "--max-error -1"),
        (vec!["--max-error", "NaN"], "--max-error NaN"),
        (vec!["--factor", "1"], "--factor 1"),
        (vec!["--tile-cells", "1"], "--tile-cells 1"),
    ] {
        let o = dbms(&export_args(&db, &out, &args));
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(!o.status.success());
        assert_eq!(err.trim().lines().count(), 1, "{err}");
        assert!(err.contains(says), "{err}");
        assert!(!out.exists(), "nothing is written");
    }
    let o = dbms(&[
        "export",
        "mesh",
        "--db",
        dir.path().join("nope").to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    assert_eq!(String::from_utf8_lossy(&o.stderr).trim().lines().count(), 1);
}

/// A second export with larger tiles leaves none of the first one's glTF files behind.
#[test]
fn a_new_export_removes_the_old_tiles() {
    let dir = tempfile::tempdir().unwrap();
    let db = make_db(dir.path());
    let out = dir.path().join("mesh");
    export(&db, &out, &["--tile-cells", "16"]);
    assert!(out.join("tiles/0/8_6.glb").exists());
    export(&db, &out, &["--tile-cells", "64"]);
    assert!(!out.join("tiles/0/8_6.glb").exists());
    let tileset = std::fs::read_to_string(out.join("tileset.json")).unwrap();
    for level in std::fs::read_dir(out.join("tiles")).unwrap() {
        for f in std::fs::read_dir(level.unwrap().path()).unwrap() {
            let p = f.unwrap().path();
            let rel = p.strip_prefix(&out).unwrap().to_str().unwrap().to_string();
            assert!(tileset.contains(&rel), "{rel} is not in the tileset");
        }
    }
}

/// On the globe, checked against GDAL: each content's vertices, carried down the tree's
/// transforms from the root to their tile (3D Tiles composes them so), land in Earth-centred
/// coordinates where `gdaltransform` (EPSG:32632 → EPSG:4978, heights ellipsoidal) puts the
/// same world points, to a millimetre. Runs where gdaltransform is on PATH (always under CI).
#[test]
fn tiles_sit_on_the_globe_where_gdal_puts_them() {
    let found = std::process::Command::new("gdaltransform")
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success());
    if !found {
        assert!(
            std::env::var_os("CI").is_none(),
            "gdaltransform not found under CI: .ci/run installs gdal-bin"
        );
        println!("skipped: gdaltransform not found (install gdal-bin to run this comparison)");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let db = make_db(dir.path());
    let out = dir.path().join("mesh");
    export(&db, &out, &["--tile-cells", "32", "--factor", "2"]);
    let tileset: Value =
        serde_json::from_slice(&std::fs::read(out.join("tileset.json")).unwrap()).unwrap();
    // (world point, our ECEF) for every 50th vertex of every content.
    let mut ours: Vec<([f64; 3], [f64; 3])> = Vec::new();
    fn walk(t: &Value, chain: &[&Value], out: &Path, ours: &mut Vec<([f64; 3], [f64; 3])>) {
        let mut chain = chain.to_vec();
        chain.push(t);
        if let Some(uri) = t["content"]["uri"].as_str() {
            let origin = origin_of(t);
            let parts = read_glb(&std::fs::read(out.join(uri)).unwrap(), origin).unwrap();
            for p in parts
                .iter()
                .flat_map(|p| p.mesh.positions.iter())
                .step_by(50)
            {
                let mut q = [0, 1, 2].map(|k| p[k] - origin[k]);
                for tile in chain.iter().rev() {
                    q = carry(tile, q);
                }
                ours.push((*p, q));
            }
        }
        for c in t["children"].as_array().into_iter().flatten() {
            walk(c, &chain, out, ours);
        }
    }
    walk(&tileset["root"], &[], &out, &mut ours);
    assert!(ours.len() > 100, "{} points", ours.len());
    let input: String = ours
        .iter()
        .map(|(p, _)| format!("{:.4} {:.4} {:.4}\n", p[0], p[1], p[2]))
        .collect();
    let mut child = std::process::Command::new("gdaltransform")
        .args(["-s_srs", "EPSG:32632", "-t_srs", "EPSG:4978"])
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    use std::io::Write;
    child
        .stdin
        .take()
        .unwrap()
        .write_all(input.as_bytes())
        .unwrap();
    let o = child.wait_with_output().unwrap();
    let text = String::from_utf8(o.stdout).unwrap();
    let mut worst = 0.0f64;
    for ((p, q), line) in ours.iter().zip(text.lines()) {
        let g: Vec<f64> = line
            .split_whitespace()
            .map(|v| v.parse().unwrap())
            .collect();
        let d = (0..3).map(|k| (q[k] - g[k]).powi(2)).sum::<f64>().sqrt();
        assert!(d < 0.001, "{p:?}: {d} m from GDAL's");
        worst = worst.max(d);
    }
    assert_eq!(text.lines().count(), ours.len());
    println!("{} points, worst {worst:.6} m from GDAL", ours.len());
}

/// Databases at the edges: no photo (grey terrain), no buildings, and grids of 2 × 2, 1 × 5
/// and 1 × 1 cells, and one all nodata: each exports a tileset the schema accepts, its glTF
/// files readable, its terrain where there is terrain to triangulate.
#[test]
fn tiny_and_bare_databases_export() {
    let schema_text = std::fs::read_to_string(
        Path::new(env!("CARGO_MANIFEST_DIR")).join("schemas/3dtiles-tileset.schema.json"),
    )
    .unwrap();
    let schema = jsonschema::validator_for(&serde_json::from_str(&schema_text).unwrap()).unwrap();
    for (w, h, nodata, triangles) in [
        (2, 2, false, 2),
        (5, 1, false, 0),
        (1, 1, false, 0),
        (4, 3, true, 0),
    ] {
        let dir = tempfile::tempdir().unwrap();
        let grid = Grid::north_up(X0, Y0, CELL, w, h, Crs::epsg(32632));
        let z: Vec<f32> = (0..w * h)
            .map(|i| {
                if nodata {
                    f32::NAN
                } else {
                    100.0 + i as f32 * 0.3
                }
            })
            .collect();
        let db_dir = dir.path().join("db");
        let mut db = Database::create(&db_dir, grid.clone(), vec![]).unwrap();
        dbms::io::geotiff::write_f32(&db_dir.join("e.tif"), &Elevation::new(grid, z)).unwrap();
        db.set_layer(ELEVATION, "elevation", "e.tif", None).unwrap();
        db.save().unwrap();
        let out = dir.path().join("mesh");
        let summary = export(&db_dir, &out, &[]);
        let what = format!("{w} × {h}{}", if nodata { ", all nodata" } else { "" });
        assert_eq!(
            summary["levels"][0]["terrain_triangles"], triangles,
            "{what}: {summary}"
        );
        let tileset: Value =
            serde_json::from_slice(&std::fs::read(out.join("tileset.json")).unwrap()).unwrap();
        assert!(schema.is_valid(&tileset), "{what}: {tileset}");
        for (_, parts) in contents(&out, &tileset) {
            assert!(parts.iter().all(|p| !p.mesh.triangles.is_empty()), "{what}");
            // Grey where there is no photo.
            assert!(
                parts[0].mesh.colours.iter().all(|c| *c == [128; 3]),
                "{what}"
            );
        }
    }
}
