//! `dbms sculpt` end to end: views rendered from analytic solids, carved by the binary, checked
//! against the truth; plus the hard cases of issue 4.

use dbms::testing::solids::{self, Solid};
use dbms::voxel::format;
use dbms::voxel::grid::VoxelGrid;
use dbms::voxel::views::CameraSpec;
use serde_json::{json, Value};
use std::path::Path;
use std::process::Command;
#[path = "support/cli.rs"]
mod cli;
use cli::dbms;

const SIZE: u32 = 128;

/// Run dbms: success, stdout, stderr.
fn run(args: &[&str]) -> (bool, String, String) {
    let out = dbms(args);
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn sphere() -> Solid {
    solids::benchmark_solids()[0].clone()
}

/// Render `solid` for each camera JSON: a photo (red object on blue) and a mask; write the
/// views file with `silhouette` = "mask" or "key".
fn write_views(
    dir: &Path,
    solid: &Solid,
    cameras: &[Value],
    silhouette: &str,
) -> std::path::PathBuf {
    let mut views = vec![];
    for (i, cam) in cameras.iter().enumerate() {
        let spec: CameraSpec = serde_json::from_value(cam.clone()).unwrap();
        let camera = spec.build(SIZE, SIZE).unwrap();
        let sil = solids::render(solid, &camera, SIZE, SIZE);
        let mut photo = Vec::new();
        let mut mask = Vec::new();
        for r in 0..SIZE {
            for c in 0..SIZE {
                let on = sil.contains(c, r);
                photo.extend_from_slice(if on { &[220, 30, 30] } else { &[0, 0, 255] });
                mask.push(if on { 255u8 } else { 0 });
            }
        }
        let (img, msk) = (format!("view{i}.png"), format!("mask{i}.png"));
        image::save_buffer(
            dir.join(&img),
            &photo,
            SIZE,
            SIZE,
            image::ExtendedColorType::Rgb8,
        )
        .unwrap();
        image::save_buffer(
            dir.join(&msk),
            &mask,
            SIZE,
            SIZE,
            image::ExtendedColorType::L8,
        )
        .unwrap();
        let mut v = json!({ "image": img, "camera": cam });
        if silhouette == "mask" {
            v["mask"] = json!(msk);
        } else {
            v["key"] = json!({ "colour": [0, 0, 255], "tolerance": 10 });
        }
        views.push(v);
    }
    let p = dir.join("views.json");
    std::fs::write(
        &p,
        serde_json::to_string_pretty(&json!({ "views": views, "bounds": [-1, -1, -1, 1, 1, 1] }))
            .unwrap(),
    )
    .unwrap();
    p
}

fn ortho3() -> Vec<Value> {
    let s = SIZE as f64 / 2.4;
    vec![
        json!({"type": "orthographic", "direction": [0, 0, -1], "up": [0, 1, 0], "scale": s}),
        json!({"type": "orthographic", "direction": [0, 1, 0], "scale": s}),
        json!({"type": "orthographic", "direction": [-1, 0, 0], "scale": s}),
    ]
}

fn pinhole(pos: [f64; 3]) -> Value {
    json!({"type": "pinhole", "fx": SIZE as f64, "fy": SIZE as f64, "position": pos, "look_at": [0, 0, 0]})
}

fn ring8() -> Vec<Value> {
    (0..8)
        .map(|i| {
            let a = i as f64 * std::f64::consts::TAU / 8.0;
            pinhole([4.0 * a.cos(), 4.0 * a.sin(), 1.5])
        })
        .collect()
}

/// Fraction of the true solid's voxels (centres inside it) that the object keeps, and the IoU.
fn against_truth(obj_path: &Path, solid: &Solid) -> (f64, f64) {
    let (obj, _) = format::read(obj_path).unwrap();
    let truth = solids::voxelize(solid, &obj.grid);
    (
        truth.count_and(&obj.occupancy) as f64 / truth.count() as f64,
        truth.iou(&obj.occupancy),
    )
}

fn sculpt(dir: &Path, views: &Path, extra: &[&str]) -> (bool, String, String) {
    let out = dir.join("obj.dvox");
    let mut args = vec![
        "sculpt",
        "--views",
        views.to_str().unwrap(),
        "--voxel",
        "0.05",
        "-o",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    run(&args)
}

#[test]
fn three_orthographic_views_carve_a_cylinder_with_exports() {
    let dir = tempfile::tempdir().unwrap();
    let solid = solids::benchmark_solids()[1].clone();
    let views = write_views(dir.path(), &solid, &ortho3(), "mask");
    let (ok, stdout, stderr) = sculpt(dir.path(), &views, &["--export", "ply", "--export", "vox"]);
    assert!(ok, "{stderr}");
    assert!(stdout.contains("voxels in a 40x40x40 grid"), "{stdout}");
    let (kept, iou) = against_truth(&dir.path().join("obj.dvox"), &solid);
    assert!(kept > 0.98 && iou > 0.7, "kept {kept} iou {iou}");
    assert!(dir.path().join("obj.ply").exists() && dir.path().join("obj.vox").exists());
}

#[test]
fn eight_pinhole_views_carve_and_colour_a_sphere_from_a_colour_key() {
    let dir = tempfile::tempdir().unwrap();
    let views = write_views(dir.path(), &sphere(), &ring8(), "key");
    let out = dir.path().join("obj.dvox");
    let args = [
        "--json",
        "sculpt",
        "--views",
        views.to_str().unwrap(),
        "--voxel",
        "0.05",
        "-o",
        out.to_str().unwrap(),
    ];
    let (ok, stdout, stderr) = run(&args);
    assert!(ok, "{stderr}");
    let j: Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(j["views"], 8);
    assert!(j["colour"]["seen"].as_u64().unwrap() > 0);
    let (kept, iou) = against_truth(&out, &sphere());
    assert!(kept > 0.98 && iou > 0.8, "kept {kept} iou {iou}");
    // Seen surface voxels are the object's red, never the blue background.
    let (obj, _) = format::read(&out).unwrap();
    let red = obj
        .colours
        .iter()
        .filter(|c| c[0] > 150 && c[2] < 80)
        .count();
    assert!(
        red as u64 >= j["colour"]["seen"].as_u64().unwrap() * 9 / 10,
        "red {red}"
    );
    // Same inputs, same bytes.
    let first = std::fs::read(&out).unwrap();
    assert!(run(&args).0);
    assert_eq!(first, std::fs::read(&out).unwrap());
}

#[test]
fn hard_case_empty_silhouette_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    let views = write_views(dir.path(), &sphere(), &ortho3(), "mask");
    image::save_buffer(
        dir.path().join("mask1.png"),
        &vec![0u8; (SIZE * SIZE) as usize],
        SIZE,
        SIZE,
        image::ExtendedColorType::L8,
    )
    .unwrap();
    let (ok, _, stderr) = sculpt(dir.path(), &views, &[]);
    assert!(!ok);
    assert!(
        stderr.contains("mask1.png: view 1: the silhouette is empty")
            && stderr.contains("; check the mask"),
        "{stderr}"
    );
    assert_eq!(stderr.lines().count(), 1, "{stderr}");
}

#[test]
fn hard_case_silhouette_touching_the_border_warns_and_keeps_the_object() {
    let dir = tempfile::tempdir().unwrap();
    let mut cams = ortho3();
    // A close top view whose silhouette fills the image edge to edge.
    cams[0]["scale"] = json!(SIZE as f64 / 1.0);
    let views = write_views(dir.path(), &sphere(), &cams, "mask");
    let (ok, _, stderr) = sculpt(dir.path(), &views, &[]);
    assert!(ok, "{stderr}");
    assert!(
        stderr.contains("view 0: the silhouette touches the image border"),
        "{stderr}"
    );
    let (kept, _) = against_truth(&dir.path().join("obj.dvox"), &sphere());
    assert!(
        kept > 0.98,
        "the part outside the close view must survive: kept {kept}"
    );
    // With --outside carve the close view cuts the sphere to what it sees.
    let (ok, _, _) = sculpt(dir.path(), &views, &["--outside", "carve"]);
    assert!(ok);
    let (kept, _) = against_truth(&dir.path().join("obj.dvox"), &sphere());
    assert!(kept < 0.95, "kept {kept}");
}

#[test]
fn hard_case_camera_inside_the_bounding_box() {
    let dir = tempfile::tempdir().unwrap();
    let mut cams = ortho3();
    // Inside the box and inside the sphere, looking north: the cap y < -0.5 (9 % of the volume) is behind it.
    cams.push(json!({"type": "pinhole", "fx": 40, "fy": 40, "position": [0, -0.5, 0], "look_at": [0, 1, 0]}));
    let views = write_views(dir.path(), &sphere(), &cams, "mask");
    let (ok, _, stderr) = sculpt(dir.path(), &views, &[]);
    assert!(ok, "{stderr}");
    let (kept, iou) = against_truth(&dir.path().join("obj.dvox"), &sphere());
    assert!(kept > 0.98 && iou > 0.6, "kept {kept} iou {iou}");
    let (ok, _, stderr) = sculpt(dir.path(), &views, &["--behind", "carve"]);
    assert!(ok, "{stderr}");
    let (kept, _) = against_truth(&dir.path().join("obj.dvox"), &sphere());
    assert!(
        (0.88..0.93).contains(&kept),
        "carving behind the camera removes the 9 % cap y < -0.5: kept {kept}"
    );
}

#[test]
fn hard_case_two_nearly_parallel_views() {
    let dir = tempfile::tempdir().unwrap();
    // 0.01° apart: together they constrain almost nothing along the viewing direction.
    let a = 0.01f64.to_radians();
    let cams = vec![
        pinhole([0.0, -4.0, 0.0]),
        pinhole([4.0 * a.sin(), -4.0 * a.cos(), 0.0]),
    ];
    let views = write_views(dir.path(), &sphere(), &cams, "mask");
    let (ok, _, stderr) = sculpt(dir.path(), &views, &[]);
    assert!(ok, "{stderr}");
    let (kept, iou) = against_truth(&dir.path().join("obj.dvox"), &sphere());
    assert!(kept > 0.98, "kept {kept}");
    assert!(
        iou < 0.8,
        "two parallel views give an elongated hull, iou {iou}"
    );
}

#[test]
fn hard_case_view_straight_down_with_default_up() {
    let dir = tempfile::tempdir().unwrap();
    let mut cams = ring8();
    cams.push(pinhole([0.0, 0.0, 4.0])); // no "up": north-up by rule
    let views = write_views(dir.path(), &solids::benchmark_solids()[3], &cams, "mask");
    let (ok, _, stderr) = sculpt(dir.path(), &views, &[]);
    assert!(ok, "{stderr}");
    let (kept, iou) = against_truth(&dir.path().join("obj.dvox"), &solids::benchmark_solids()[3]);
    assert!(kept > 0.98 && iou > 0.6, "kept {kept} iou {iou}");
}

#[test]
fn straight_down_view_has_image_right_east_and_image_top_north() {
    // The mask is drawn by hand, not rendered through the camera code the carver shares: the
    // object fills part of the top-right quarter of a straight-down image with no "up" (north-up
    // by rule), so every voxel kept must lie north-east of the camera's foot.
    let dir = tempfile::tempdir().unwrap();
    let n = SIZE as usize;
    let mut mask = vec![0u8; n * n];
    for r in n / 8..3 * n / 8 {
        for c in 5 * n / 8..7 * n / 8 {
            mask[r * n + c] = 255;
        }
    }
    let save = |name: &str, bytes: &[u8], kind| {
        image::save_buffer(dir.path().join(name), bytes, SIZE, SIZE, kind).unwrap()
    };
    save("m.png", &mask, image::ExtendedColorType::L8);
    save(
        "p.png",
        &vec![128; n * n * 3],
        image::ExtendedColorType::Rgb8,
    );
    let views = dir.path().join("views.json");
    let spec = json!({
        "views": [{ "image": "p.png", "mask": "m.png", "camera": pinhole([0.0, 0.0, 4.0]) }],
        "bounds": [-1, -1, -1, 1, 1, 1],
    });
    std::fs::write(&views, spec.to_string()).unwrap();
    let (ok, _, stderr) = sculpt(dir.path(), &views, &[]);
    assert!(ok, "{stderr}");
    let (obj, _) = format::read(&dir.path().join("obj.dvox")).unwrap();
    let mut kept = 0;
    for ([x, y, z], _) in obj.voxels() {
        let [cx, cy, _] = obj.grid.centre(x, y, z);
        assert!(
            cx > 0.0 && cy > 0.0,
            "voxel at ({cx}, {cy}) is not north-east"
        );
        kept += 1;
    }
    assert!(kept > 1000, "{kept}");
}

#[test]
fn hard_case_voxel_larger_than_the_object() {
    let dir = tempfile::tempdir().unwrap();
    let views = write_views(dir.path(), &sphere(), &ortho3(), "mask");
    let out = dir.path().join("obj.dvox");
    let (ok, stdout, stderr) = run(&[
        "sculpt",
        "--views",
        views.to_str().unwrap(),
        "--voxel",
        "5",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(ok, "{stderr}");
    assert!(stdout.contains("1 voxels in a 1x1x1 grid"), "{stdout}");
    // A 2 m voxel (wider than the 1.6 m sphere) whose centre (-0.8, -0.8, -0.8) is in every
    // image but outside every silhouette: a clear error, not an empty file.
    let (ok, _, stderr) = run(&[
        "sculpt",
        "--views",
        views.to_str().unwrap(),
        "--voxel",
        "2",
        "--bounds",
        "-1.8,-1.8,-1.8,-1.7,-1.7,-1.7",
        "-o",
        dir.path().join("x.dvox").to_str().unwrap(),
    ]);
    assert!(
        !ok && stderr.contains("no voxel survives carving") && stderr.contains("smaller --voxel"),
        "{stderr}"
    );
    assert!(!dir.path().join("x.dvox").exists());
}

#[test]
fn hard_case_non_invertible_camera_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    let views = write_views(dir.path(), &sphere(), &ortho3(), "mask");
    let mut v: Value = serde_json::from_str(&std::fs::read_to_string(&views).unwrap()).unwrap();
    v["views"][2]["camera"] = json!({"type": "pinhole", "fx": 100, "fy": 100, "R": [[1, 0, 0], [0, 1, 0], [1, 1, 0]], "t": [0, 0, 4]});
    std::fs::write(&views, v.to_string()).unwrap();
    let (ok, _, stderr) = sculpt(dir.path(), &views, &[]);
    assert!(!ok);
    assert!(
        stderr.contains("views.json: view 2: rotation R is singular")
            && stderr.contains("not invertible"),
        "{stderr}"
    );
}

#[test]
fn vox_export_of_an_oversized_object_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let views = write_views(dir.path(), &sphere(), &ortho3(), "mask");
    let (ok, _, stderr) = run(&[
        "sculpt",
        "--views",
        views.to_str().unwrap(),
        "--voxel",
        "0.007",
        "--export",
        "vox",
        "-o",
        dir.path().join("o.dvox").to_str().unwrap(),
    ]);
    assert!(
        !ok && stderr.contains("o.vox: ")
            && stderr.contains("at most 256 per axis")
            && stderr.contains("--export ply"),
        "{stderr}"
    );
    // Refused before anything was written: no object either.
    assert!(!dir.path().join("o.dvox").exists() && !dir.path().join("o.vox").exists());
    // The grid geometry behind it: 2 m / 7 mm = 286 voxels.
    assert_eq!(
        VoxelGrid::covering([-1.0; 3], [1.0; 3], 0.007)
            .unwrap()
            .dims[0],
        286
    );
}

#[test]
fn missing_bounds_and_bad_views_files_are_one_line_errors() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("v.json");
    std::fs::write(
        &p,
        r#"{"views": [{"image": "a.png", "mask": "m.png", "camera": {"type": "fisheye"}}]}"#,
    )
    .unwrap();
    let (ok, _, stderr) = sculpt(dir.path(), &p, &[]);
    assert!(
        !ok && stderr.contains("v.json: not a valid views file") && stderr.lines().count() == 1,
        "{stderr}"
    );
    let views = write_views(dir.path(), &sphere(), &ortho3(), "mask");
    let mut v: Value = serde_json::from_str(&std::fs::read_to_string(&views).unwrap()).unwrap();
    v.as_object_mut().unwrap().remove("bounds");
    std::fs::write(&views, v.to_string()).unwrap();
    let (ok, _, stderr) = sculpt(dir.path(), &views, &[]);
    assert!(!ok && stderr.contains("no bounds to carve"), "{stderr}");
}

fn schema(name: &str) -> jsonschema::Validator {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("schemas")
        .join(name);
    let v: Value = serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    jsonschema::validator_for(&v).unwrap()
}

/// The JSON header of a .dvox file.
fn dvox_header(path: &Path) -> Value {
    let b = std::fs::read(path).unwrap();
    let n = u32::from_le_bytes(b[8..12].try_into().unwrap()) as usize;
    serde_json::from_slice(&b[12..12 + n]).unwrap()
}

#[test]
fn views_files_and_object_headers_match_their_schemas() {
    let dir = tempfile::tempdir().unwrap();
    let mut cams = ring8();
    cams.push(json!({"type": "pinhole", "fx": 100, "fy": 100, "R": [[1, 0, 0], [0, 0, -1], [0, 1, 0]], "t": [0, 0, 4]}));
    let views = write_views(dir.path(), &sphere(), &cams, "key");
    let views_schema = schema("views.schema.json");
    let doc: Value = serde_json::from_str(&std::fs::read_to_string(&views).unwrap()).unwrap();
    assert!(
        views_schema.is_valid(&doc),
        "{:?}",
        views_schema
            .iter_errors(&doc)
            .map(|e| e.to_string())
            .collect::<Vec<_>>()
    );
    assert!(
        views_schema.is_valid(&doc["views"]),
        "a bare list of views is valid too"
    );
    let mut with_schema = doc.clone();
    with_schema["$schema"] = json!("https://dbms.invalid/schemas/views.schema.json");
    assert!(views_schema.is_valid(&with_schema));
    std::fs::write(&views, with_schema.to_string()).unwrap();
    let mut bad = doc.clone();
    bad["views"][0]["mask"] = json!("m.png"); // mask and key together
    assert!(!views_schema.is_valid(&bad));
    let (ok, _, stderr) = sculpt(dir.path(), &views, &[]);
    assert!(ok, "{stderr}");
    let header = dvox_header(&dir.path().join("obj.dvox"));
    let obj_schema = schema("voxel-object.schema.json");
    assert!(obj_schema.is_valid(&header), "{header}");
    let mut bad = header.clone();
    bad["dims"] = json!([0, 1, 1]);
    assert!(!obj_schema.is_valid(&bad));
}

#[test]
fn object_revolve_cone_and_extrude() {
    let dir = tempfile::tempdir().unwrap();
    let d = |f: &str| dir.path().join(f).to_str().unwrap().to_string();
    let (ok, out, err) = run(&[
        "object",
        "revolve",
        "--profile",
        "5:0,5:8,0:9",
        "--voxel",
        "0.5",
        "-o",
        &d("tank.dvox"),
        "--export",
        "vox",
    ]);
    assert!(ok, "{err}");
    assert!(out.contains("anchor (bottom centre) at (0, 0, 0)"), "{out}");
    let (tank, _) = format::read(&dir.path().join("tank.dvox")).unwrap();
    assert_eq!(tank.grid.dims, [21, 21, 18]);
    assert!(dir.path().join("tank.vox").exists());
    let tree = |seed: &str, name: &str| {
        run(&[
            "object",
            "cone",
            "--height",
            "10",
            "--radius",
            "2.5",
            "--seed",
            seed,
            "--voxel",
            "0.25",
            "-o",
            &d(name),
        ])
    };
    assert!(tree("1", "a.dvox").0 && tree("1", "b.dvox").0 && tree("2", "c.dvox").0);
    let bytes = |n: &str| std::fs::read(dir.path().join(n)).unwrap();
    assert_eq!(bytes("a.dvox"), bytes("b.dvox"), "same seed, same bytes");
    assert_ne!(bytes("a.dvox"), bytes("c.dvox"));
    std::fs::write(
        dir.path().join("f.geojson"),
        r#"{"type":"FeatureCollection","features":[{"type":"Feature","properties":{"h":7.5},"geometry":{"type":"Polygon","coordinates":[[[10,20],[18,20],[18,26],[10,26],[10,20]]]}}]}"#,
    )
    .unwrap();
    let (ok, _, err) = run(&[
        "object",
        "extrude",
        "--footprints",
        &d("f.geojson"),
        "--height-field",
        "h",
        "--voxel",
        "0.5",
        "-o",
        &d("b.dvox"),
    ]);
    assert!(ok, "{err}");
    let (b, _) = format::read(&dir.path().join("b.dvox")).unwrap();
    assert_eq!(b.len(), 16 * 12 * 15);
    let (ok, _, err) = run(&[
        "object",
        "extrude",
        "--footprints",
        &d("f.geojson"),
        "--voxel",
        "0.5",
        "-o",
        &d("x.dvox"),
    ]);
    assert!(
        !ok && err.contains("feature 0: no positive number in property \"height\""),
        "{err}"
    );
    let (ok, _, err) = run(&[
        "object",
        "revolve",
        "--profile",
        "5;0",
        "--voxel",
        "0.5",
        "-o",
        &d("x.dvox"),
    ]);
    assert!(!ok && err.contains("is not R:Z"), "{err}");
}

/// A 20 × 10 cell database at 1 m with flat ground at 3 m, made by `dbms ingest`.
/// A 20 × 10 m database of 1 m cells on a plane rising 0.5 m a metre east and 0.25 m a metre
/// south: 3 m at the centre of the north-west cell.
fn database(dir: &Path) -> std::path::PathBuf {
    use dbms::crs::Crs;
    use dbms::grid::Grid;
    use dbms::raster::Raster;
    let g = Grid::north_up(500_000.0, 5_300_000.0, 1.0, 20, 10, Crs::epsg(32632));
    let (dem, ortho) = (dir.join("dem.tif"), dir.join("ortho.tif"));
    let plane = (0..g.len())
        .map(|i| 3.0 + 0.5 * (i % 20) as f32 + 0.25 * (i / 20) as f32)
        .collect();
    dbms::io::geotiff::write_f32(&dem, &Raster::new(g.clone(), plane)).unwrap();
    dbms::io::geotiff::write_rgba8(&ortho, &Raster::filled(g, [1, 2, 3, 255])).unwrap();
    let db = dir.join("db");
    let (ok, _, err) = run(&[
        "ingest",
        "-q",
        "--photo-time",
        "2026-06-21T10:00:00Z",
        "--dem",
        dem.to_str().unwrap(),
        "--ortho",
        ortho.to_str().unwrap(),
        "-o",
        db.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    db
}

#[test]
fn place_records_objects_in_the_manifest() {
    let dir = tempfile::tempdir().unwrap();
    let db = database(dir.path());
    let tree = dir.path().join("tree.dvox");
    assert!(
        run(&[
            "object",
            "cone",
            "--height",
            "6",
            "--radius",
            "2",
            "--voxel",
            "0.5",
            "-o",
            tree.to_str().unwrap()
        ])
        .0
    );
    let (dbs, ts) = (db.to_str().unwrap(), tree.to_str().unwrap());
    let (ok, out, err) = run(&[
        "--json",
        "place",
        "--db",
        dbs,
        "--object",
        ts,
        "--at",
        "500005.5,5299995",
    ]);
    assert!(ok, "{err}");
    let p: Value = serde_json::from_str(&out).unwrap();
    // Between cell centres (5, 4) and (5, 5): the ground is interpolated, 3 + 2.5 + 1.125 m.
    assert_eq!(p["z"], 6.625, "z from the ground");
    let (ok, _, err) = run(&[
        "place",
        "--db",
        dbs,
        "--object",
        ts,
        "--at",
        "500010,5299995,12.5",
        "--heading",
        "-90",
    ]);
    assert!(ok, "{err}");
    let m: Value =
        serde_json::from_slice(&std::fs::read(db.join("manifest.json")).unwrap()).unwrap();
    let objs = m["objects"].as_array().unwrap();
    assert_eq!(objs.len(), 2);
    assert_eq!(
        (objs[1]["z"].as_f64(), objs[1]["heading_deg"].as_f64()),
        (Some(12.5), Some(270.0))
    );
    assert_eq!(
        objs[0]["file"], objs[1]["file"],
        "one stored copy of the same object"
    );
    assert_eq!(
        std::fs::read(db.join(objs[0]["file"].as_str().unwrap())).unwrap(),
        std::fs::read(&tree).unwrap()
    );
    assert!(
        m["stages"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|s| s["name"] == "place")
            .count()
            == 2
    );
    let (ok, _, err) = run(&["info", "--verify", dbs]);
    assert!(ok, "{err}");
    // Outside the database, and not an object: clear errors, manifest untouched.
    let (ok, _, err) = run(&[
        "place",
        "--db",
        dbs,
        "--object",
        ts,
        "--at",
        "400000,5299995",
    ]);
    assert!(!ok && err.contains("outside the database extent"), "{err}");
    let (ok, _, err) = run(&[
        "place",
        "--db",
        dbs,
        "--object",
        db.join("manifest.json").to_str().unwrap(),
        "--at",
        "500005,5299995",
    ]);
    assert!(!ok && err.contains("not a dbms voxel object"), "{err}");
    let m2: Value =
        serde_json::from_slice(&std::fs::read(db.join("manifest.json")).unwrap()).unwrap();
    assert_eq!(m2["objects"].as_array().unwrap().len(), 2);
}

/// A placement far from the terrain (a unit slip, `1e8`) or not a number is refused before
/// anything is written: it would otherwise make every later pyramid fail (issue 14, defect 9).
#[test]
fn place_refuses_a_height_far_from_the_terrain_before_writing() {
    let dir = tempfile::tempdir().unwrap();
    let db = database(dir.path());
    let tree = dir.path().join("tree.dvox");
    let t = tree.to_str().unwrap();
    let cone = ["object", "cone", "--height", "6", "--radius", "2"];
    assert!(run(&[&cone[..], &["--voxel", "0.5", "-o", t]].concat()).0);
    let manifest = std::fs::read(db.join("manifest.json")).unwrap();
    let place = |at: &str| {
        run(&[
            "place",
            "--db",
            db.to_str().unwrap(),
            "--object",
            t,
            "--at",
            at,
        ])
    };
    for at in [
        "500005,5299995,1e8",
        "500005,5299995,-5000",
        "500005,5299995,NaN",
    ] {
        let (ok, _, err) = place(at);
        assert!(!ok, "--at {at} was accepted");
        assert_eq!(err.trim_end().lines().count(), 1, "{err}");
        assert!(err.starts_with("dbms: error: --at"), "{err}");
    }
    let (_, _, err) = place("500005,5299995,1e8");
    assert!(
        err.contains("more than 1000 m outside the terrain's range"),
        "{err}"
    );
    assert_eq!(std::fs::read(db.join("manifest.json")).unwrap(), manifest);
    assert!(!db.join("objects").exists(), "the object was copied in");
    // Within a kilometre of the terrain is a placement (an object on a tall roof).
    let (ok, _, err) = place("500005,5299995,900");
    assert!(ok, "{err}");
}

/// `dbms ARGS` with `DBMS_FAULT` set to `fault`: its exit status and stderr.
fn dbms_fault(fault: &str, args: &[&str]) -> (Option<i32>, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_dbms"))
        .args(args)
        .env("DBMS_FAULT", fault)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    (out.status.code(), err)
}

/// The names in `dir`, sorted (temporary files included).
fn names(dir: &Path) -> Vec<String> {
    let mut n: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    n.sort();
    n
}

/// Issue 14, defect 11: an object and its exports are renamed into place together at the end.
/// One that fails (a full disk as it is finished, injected by `DBMS_FAULT`) fails the run in one
/// line and leaves no `.dvox` — the make target — nor any export, and an earlier run's files
/// stay as they were.
#[test]
fn a_failed_export_leaves_no_object_and_no_other_export() {
    let dir = tempfile::tempdir().unwrap();
    let objects = dir.path().join("objects");
    std::fs::create_dir(&objects).unwrap();
    let t = objects.join("tree.dvox");
    let t = t.to_str().unwrap();
    let cone = |seed| {
        let exports = ["--export", "ply", "--export", "vox"];
        let args = ["object", "cone", "--height", "6", "--radius", "2"];
        [
            &args[..],
            &["--voxel", "0.5", "--seed", seed, "-o", t],
            &exports,
        ]
        .concat()
    };
    let failed = |(code, err): (Option<i32>, String), file: &str| {
        assert_eq!(code, Some(1), "{err}");
        assert!(
            err.starts_with("dbms: error: ")
                && err.contains(&format!("{file}: no space left on the device"))
                && err.trim_end().lines().count() == 1,
            "{err}"
        );
    };
    for file in ["tree.vox", "tree.ply", "tree.dvox"] {
        failed(dbms_fault(&format!("enospc:{file}"), &cone("1")), file);
        assert!(names(&objects).is_empty(), "{file}: {:?}", names(&objects));
    }
    let (ok, _, err) = run(&cone("1"));
    assert!(ok, "{err}");
    let read = |n: &str| std::fs::read(objects.join(n)).unwrap();
    let before = ["tree.dvox", "tree.ply", "tree.vox"].map(read);
    failed(dbms_fault("enospc:tree.vox", &cone("2")), "tree.vox");
    assert_eq!(names(&objects), ["tree.dvox", "tree.ply", "tree.vox"]);
    assert_eq!(["tree.dvox", "tree.ply", "tree.vox"].map(read), before);

    // sculpt commits the same way.
    let views = write_views(dir.path(), &sphere(), &ortho3(), "mask");
    let obj = objects.join("obj.dvox");
    let args = [
        "sculpt",
        "--views",
        views.to_str().unwrap(),
        "--voxel",
        "0.1",
        "--export",
        "ply",
        "-o",
        obj.to_str().unwrap(),
    ];
    failed(dbms_fault("enospc:obj.ply", &args), "obj.ply");
    assert!(!obj.exists() && !objects.join("obj.ply").exists());
    assert_eq!(names(&objects), ["tree.dvox", "tree.ply", "tree.vox"]);
}

/// Issue 14, defect 4 for `object` and `sculpt`: an output that would destroy something — an
/// export that is a directory or a FIFO, an object or export that is one of the run's inputs
/// (the footprints, the views file, a view's image) — is refused in one line before anything is
/// written; the same export asked twice is one file.
#[test]
fn object_and_sculpt_outputs_that_would_destroy_something_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = |f: &str| dir.path().join(f).to_str().unwrap().to_string();
    let refused = |args: &[&str], says: &str| {
        let (ok, _, err) = run(args);
        assert!(!ok && err.contains(says), "{args:?}: {err}");
        assert!(err.starts_with("dbms: error: "), "{err}");
        assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    };
    std::fs::create_dir(d("tree.ply")).unwrap();
    assert!(Command::new("mkfifo")
        .arg(d("tree.vox"))
        .status()
        .unwrap()
        .success());
    let cone = [
        "object", "cone", "--height", "6", "--radius", "2", "--voxel", "0.5",
    ];
    let tree = d("tree.dvox");
    refused(
        &[&cone[..], &["-o", &tree, "--export", "ply"]].concat(),
        "tree.ply: the output is a directory",
    );
    refused(
        &[&cone[..], &["-o", &tree, "--export", "vox"]].concat(),
        "tree.vox: the output is a device, FIFO",
    );
    assert!(!dir.path().join("tree.dvox").exists());

    // Footprints that happen to be named like the export, or given as the object.
    let footprints = r#"{"type":"FeatureCollection","features":[{"type":"Feature","properties":{"height":7.5},"geometry":{"type":"Polygon","coordinates":[[[10,20],[18,20],[18,26],[10,26],[10,20]]]}}]}"#;
    std::fs::write(d("b.ply"), footprints).unwrap();
    let extrude = [
        "object",
        "extrude",
        "--footprints",
        &d("b.ply"),
        "--voxel",
        "0.5",
    ];
    refused(
        &[&extrude[..], &["-o", &d("b.dvox"), "--export", "ply"]].concat(),
        "b.ply: the output is also an input",
    );
    refused(
        &[&extrude[..], &["-o", &d("b.ply")]].concat(),
        "the output is also an input",
    );
    assert_eq!(std::fs::read_to_string(d("b.ply")).unwrap(), footprints);
    assert!(!dir.path().join("b.dvox").exists());

    // The views file, or one of its images, as the object.
    let views = write_views(dir.path(), &sphere(), &ortho3(), "mask");
    let view0 = std::fs::read(d("view0.png")).unwrap();
    let sculpt = [
        "sculpt",
        "--views",
        views.to_str().unwrap(),
        "--voxel",
        "0.1",
    ];
    for o in ["views.json", "view0.png", "mask2.png"] {
        refused(
            &[&sculpt[..], &["-o", &d(o)]].concat(),
            &format!("{o}: the output is also an input"),
        );
    }
    assert_eq!(std::fs::read(d("view0.png")).unwrap(), view0);
    assert!(
        serde_json::from_slice::<Value>(&std::fs::read(&views).unwrap()).is_ok(),
        "the views file was overwritten"
    );

    // The same export twice is one export, not two outputs of one path.
    let (ok, _, err) = run(&[
        &sculpt[..],
        &["-o", &d("s.dvox"), "--export", "ply", "--export", "ply"],
    ]
    .concat());
    assert!(ok, "{err}");
    assert!(dir.path().join("s.ply").exists());
}

/// `place --points` places one object per point in one change; ids are stable, never reused,
/// and `--remove` / `--move` address them; the pyramid of the bulk placements is the pyramid of
/// the same placements made one by one.
#[test]
fn placements_in_bulk_have_stable_ids_and_can_be_moved_or_removed() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    std::fs::create_dir_all(&a).unwrap();
    std::fs::create_dir_all(&b).unwrap();
    let (one, bulk) = (database(&a), database(&b));
    let tree = dir.path().join("tree.dvox");
    let t = tree.to_str().unwrap();
    let cone = [
        "object", "cone", "--height", "6", "--radius", "2", "--voxel", "0.5",
    ];
    assert!(run(&[&cone[..], &["--seed", "3", "-o", t]].concat()).0);
    let points = [
        (500003.5, 5299997.0, 0.0),
        (500010.0, 5299995.5, 90.0),
        (500016.0, 5299992.0, 200.0),
    ];
    let features: Vec<Value> = points
        .iter()
        .map(|&(x, y, h)| serde_json::json!({"type": "Feature", "geometry": {"type": "Point", "coordinates": [x, y]}, "properties": {"heading": h}}))
        .collect();
    let geojson = dir.path().join("trees.geojson");
    let fc = serde_json::json!({"type": "FeatureCollection", "features": features});
    std::fs::write(&geojson, fc.to_string()).unwrap();

    let b = bulk.to_str().unwrap();
    let (ok, out, err) = run(&[
        "--json",
        "place",
        "--db",
        b,
        "--object",
        t,
        "--points",
        geojson.to_str().unwrap(),
    ]);
    assert!(ok, "{err}");
    let placed: Value = serde_json::from_str(&out).unwrap();
    let ids: Vec<u64> = placed["placements"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["id"].as_u64().unwrap())
        .collect();
    assert_eq!(ids, [1, 2, 3]);
    for &(x, y, h) in &points {
        let (ok, _, err) = run(&[
            "place",
            "--db",
            one.to_str().unwrap(),
            "--object",
            t,
            "--at",
            &format!("{x},{y}"),
            "--heading",
            &h.to_string(),
        ]);
        assert!(ok, "{err}");
    }
    let pyramid = |db: &Path| {
        let out = db.with_extension("dbt");
        let (ok, _, err) = run(&[
            "pyramid",
            "-q",
            "--db",
            db.to_str().unwrap(),
            "--sun-elevation",
            "40",
            "--sun-azimuth",
            "135",
            "-o",
            out.to_str().unwrap(),
        ]);
        assert!(ok, "{err}");
        std::fs::read(out).unwrap()
    };
    assert!(
        pyramid(&one) == pyramid(&bulk),
        "bulk placing builds what one-by-one placing builds"
    );
    let manifest = |db: &Path| -> Value {
        serde_json::from_slice(&std::fs::read(db.join("manifest.json")).unwrap()).unwrap()
    };
    let places = |m: &Value| {
        m["stages"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|s| s["name"] == "place")
            .count()
    };
    assert_eq!(places(&manifest(&bulk)), 1, "one change for the whole file");

    // Remove 2, move 3, place another: ids 1, 3, 4 — 2 is never given again.
    assert!(run(&["place", "--db", b, "--remove", "2"]).0);
    let (ok, out, err) = run(&[
        "--json",
        "place",
        "--db",
        b,
        "--move",
        "3",
        "--at",
        "500012,5299994,20",
    ]);
    assert!(ok, "{err}");
    let moved: Value = serde_json::from_str(&out).unwrap();
    assert_eq!(
        (
            moved["id"].as_u64(),
            moved["x"].as_f64(),
            moved["z"].as_f64(),
            moved["heading_deg"].as_f64()
        ),
        (Some(3), Some(500012.0), Some(20.0), Some(200.0))
    );
    assert!(run(&["place", "--db", b, "--object", t, "--at", "500004,5299996"]).0);
    let m = manifest(&bulk);
    let ids: Vec<u64> = m["objects"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p["id"].as_u64().unwrap())
        .collect();
    assert_eq!(ids, [1, 3, 4]);
    let (ok, _, err) = run(&["info", "--verify", b]);
    assert!(ok, "{err}");

    // An id that is not there, and a point without an object: one-line errors, nothing written.
    let before = std::fs::read(bulk.join("manifest.json")).unwrap();
    let (ok, _, err) = run(&["place", "--db", b, "--remove", "2"]);
    assert!(
        !ok && err.contains("has no placement 2") && err.trim_end().lines().count() == 1,
        "{err}"
    );
    let (ok, _, err) = run(&["place", "--db", b, "--points", geojson.to_str().unwrap()]);
    assert!(
        !ok && err.contains("feature 0") && err.contains("no --object"),
        "{err}"
    );
    assert_eq!(std::fs::read(bulk.join("manifest.json")).unwrap(), before);
}

/// `--scale` sizes an object about its anchor: twice the scale stands twice as tall over four
/// times the cells; `--move --scale` changes it, and the manifest keeps it.
#[test]
fn a_placement_scales_its_object_about_the_anchor() {
    let dir = tempfile::tempdir().unwrap();
    let db = database(dir.path());
    let b = db.to_str().unwrap();
    let tree = dir.path().join("tree.dvox");
    let t = tree.to_str().unwrap();
    let cone = [
        "object", "cone", "--height", "6", "--radius", "2", "--voxel", "0.5",
    ];
    assert!(run(&[&cone[..], &["--seed", "3", "-o", t]].concat()).0);
    // Height over the ground and raised cells of the database's one placement.
    let measure = || -> (f64, u64) {
        let out = dir.path().join("t.dbt");
        let (ok, summary, err) =
            run(&["--json", "pyramid", "--db", b, "-o", out.to_str().unwrap()]);
        assert!(ok, "{err}");
        let summary: Value = serde_json::from_str(&summary).unwrap();
        let r = dbms::tiles::TileReader::open(&out, 8).unwrap();
        // The tip stands over the anchor, the corner of cells 9 and 10 of rows 4 and 5.
        let mut max = f64::MIN;
        for (col, row) in [(9, 4), (10, 4), (9, 5), (10, 5)] {
            max = max.max(r.cell(0, col, row).unwrap().unwrap().max_z as f64);
        }
        let m: Value =
            serde_json::from_slice(&std::fs::read(db.join("manifest.json")).unwrap()).unwrap();
        let z = m["objects"][0]["z"].as_f64().unwrap();
        (max - z, summary["object_cells"].as_u64().unwrap())
    };
    let (ok, out, err) = run(&[
        "--json",
        "place",
        "--db",
        b,
        "--object",
        t,
        "--at",
        "500010,5299995",
    ]);
    assert!(ok, "{err}");
    let id = serde_json::from_str::<Value>(&out).unwrap()["id"]
        .as_u64()
        .unwrap()
        .to_string();
    let (height, cells) = measure();
    assert!(height > 4.0 && height <= 6.0 + 1e-3, "{height}");
    let (ok, out, err) = run(&[
        "--json",
        "place",
        "--db",
        b,
        "--move",
        &id,
        "--at",
        "500010,5299995",
        "--scale",
        "2",
    ]);
    assert!(ok, "{err}");
    assert_eq!(serde_json::from_str::<Value>(&out).unwrap()["scale"], 2.0);
    let (height2, cells2) = measure();
    assert!(
        (height2 - 2.0 * height).abs() < 1e-3,
        "{height} → {height2}"
    );
    let ratio = cells2 as f64 / cells as f64;
    assert!((3.5..4.5).contains(&ratio), "{cells} → {cells2} cells");
    let (ok, _, err) = run(&["info", "--verify", b]);
    assert!(ok, "{err}");

    let (ok, _, err) = run(&[
        "place",
        "--db",
        b,
        "--object",
        t,
        "--at",
        "500010,5299995",
        "--scale",
        "0",
    ]);
    assert!(
        !ok && err.contains("scale 0") && err.trim_end().lines().count() == 1,
        "{err}"
    );
}

/// An object too large for memory is refused up front in one line naming the fix (it needed
/// 5.4 GB and aborted under a memory limit); under the budget, an allocation that fails (a
/// memory limit, `ulimit -v`) is the same one-line error, not an abort.
#[test]
fn an_object_too_large_for_memory_is_a_one_line_error() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("big.dvox");
    let o = out.to_str().unwrap();
    let (ok, _, err) = run(&[
        "object", "cone", "--height", "100", "--radius", "80", "--voxel", "0.1", "-o", o,
    ]);
    assert!(!ok);
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(
        err.contains("budget") && err.contains("use a larger --voxel"),
        "{err}"
    );
    assert!(!out.exists());
    // Under the budget (about 1 GB), under a 300 MB limit of address space.
    let limited = Command::new("sh")
        .arg("-c")
        .arg(format!(
            "ulimit -v 300000 && exec \"$0\" object cone --height 60 --radius 40 --voxel 0.1 -o {o}"
        ))
        .arg(env!("CARGO_BIN_EXE_dbms"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&limited.stderr);
    assert_eq!(limited.status.code(), Some(1), "{err}");
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(
        err.contains("out of memory") && err.contains("--voxel"),
        "{err}"
    );
    assert!(!out.exists());
}
