//! `dbms render` end to end: outputs, exactness of the two traversals, errors, determinism.

use dbms::crs::Crs;
use dbms::grid::Grid;
use dbms::testing::tiles::write_tiles;
use dbms::tiles::Compression;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;
#[path = "support/cli.rs"]
mod cli;
use cli::dbms;

/// Hills with a few tall columns, 2 m cells, UTM-sized origin; nodata in one corner.
fn hills(dir: &Path) -> PathBuf {
    let path = dir.join("hills.dbt");
    let grid = Grid::north_up(431_000.0, 4_582_000.0, 2.0, 300, 200, Crs::epsg(32633));
    write_tiles(&path, grid, 64, 4, Compression::Lz4, |c, r| {
        if c < 10 && r < 10 {
            return (f32::NAN, [0; 4]);
        }
        let z = 100.0 + 12.0 * ((c as f32 * 0.05).sin() + (r as f32 * 0.04).cos());
        let tower = c % 37 == 5 && r % 29 == 7;
        (
            if tower { z + 30.0 } else { z },
            [(c % 256) as u8, (r % 256) as u8, 90, 255],
        )
    })
    .unwrap();
    path
}

fn render(tiles: &Path, out: &Path, extra: &[&str]) -> Value {
    let mut args = vec![
        "--json",
        "render",
        "--tiles",
        tiles.to_str().unwrap(),
        "-o",
        out.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    let o = dbms(&args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    serde_json::from_slice(&o.stdout).unwrap()
}

const VIEW: [&str; 8] = [
    "--eye",
    "431020,4581620,140",
    "--attitude",
    "0,-8,60",
    "--fov",
    "70",
    "--size",
    "96x64",
];

#[test]
fn renders_a_png_and_reports_pages_bytes_and_speed() {
    let dir = tempfile::tempdir().unwrap();
    let tiles = hills(dir.path());
    let out = dir.path().join("view.png");
    let s = render(&tiles, &out, &VIEW);
    let img = image::open(&out).unwrap().to_rgb8();
    assert_eq!(img.dimensions(), (96, 64));
    let st = &s["stats"];
    assert_eq!(st["rays"], 96 * 64);
    assert!(st["hits"].as_u64().unwrap() > 1000, "{s}");
    assert!(st["pages_touched"].as_u64().unwrap() > 0);
    assert!(st["reader"]["pages_read"].as_u64().unwrap() > 0);
    assert!(st["reader"]["bytes_read"].as_u64().unwrap() > 0);
    assert!(st["rays_per_second"].as_f64().unwrap() > 0.0 && st["seconds"].as_f64().unwrap() > 0.0);
    // the sky is at the top, the ground at the bottom
    let (top, bottom) = (img.get_pixel(48, 0).0, img.get_pixel(48, 63).0);
    assert!(top[2] > top[0], "sky {top:?}");
    assert_ne!(top, bottom);
}

#[test]
fn hierarchical_and_level0_traversals_are_pixel_identical_without_lod() {
    let dir = tempfile::tempdir().unwrap();
    let tiles = hills(dir.path());
    let mut outs = Vec::new();
    for t in ["hierarchical", "level0"] {
        let (png, exr) = (
            dir.path().join(format!("{t}.png")),
            dir.path().join(format!("{t}.exr")),
        );
        let mut args = VIEW.to_vec();
        args.extend([
            "--traversal",
            t,
            "--no-lod",
            "--range-out",
            exr.to_str().unwrap(),
        ]);
        let s = render(&tiles, &png, &args);
        outs.push((
            std::fs::read(png).unwrap(),
            std::fs::read(exr).unwrap(),
            s["stats"]["cells_stepped"].as_u64().unwrap(),
        ));
    }
    assert!(outs[0].0 == outs[1].0, "PNGs differ");
    assert!(outs[0].1 == outs[1].1, "range EXRs differ");
    assert!(
        outs[0].2 < outs[1].2,
        "hierarchy steps {} vs level 0 {}",
        outs[0].2,
        outs[1].2
    );
}

#[test]
fn range_exr_holds_metres_and_inf_for_sky() {
    let dir = tempfile::tempdir().unwrap();
    let tiles = hills(dir.path());
    let (png, exr) = (dir.path().join("v.png"), dir.path().join("v.exr"));
    let mut args = VIEW.to_vec();
    args.extend(["--range-out", exr.to_str().unwrap()]);
    render(&tiles, &png, &args);
    let img = exr::prelude::read_first_flat_layer_from_file(&exr).unwrap();
    let ch = &img.layer_data.channel_data.list[0];
    assert_eq!(ch.name.to_string(), "Z");
    let exr::prelude::FlatSamples::F32(z) = &ch.sample_data else {
        panic!("f32 samples")
    };
    assert_eq!(z.len(), 96 * 64);
    assert!(z[0].is_infinite(), "top-left pixel is sky");
    let last = z[z.len() - 48];
    // the bottom centre looks 8° + half the vertical fov down from 140 m over ~100 m ground
    assert!(last > 40.0 && last < 1000.0, "{last}");
}

/// Issue 14, defect 11: the view and its range image are renamed into place together. The range
/// image failing as it is finished (a full disk, injected by `DBMS_FAULT`) fails the run in one
/// line and leaves no new view: none where there was none, the old one where there was one.
#[test]
fn a_failed_range_image_leaves_no_view() {
    let dir = tempfile::tempdir().unwrap();
    let tiles = hills(dir.path());
    let out = dir.path().join("out");
    std::fs::create_dir(&out).unwrap();
    let (png, exr) = (out.join("v.png"), out.join("v.exr"));
    let run = |fov: &str| {
        let mut args = vec!["render", "--tiles", tiles.to_str().unwrap()];
        args.extend(&VIEW[..4]);
        args.extend(["--fov", fov, "--size", "96x64"]);
        args.extend(["--range-out", exr.to_str().unwrap()]);
        args.extend(["-o", png.to_str().unwrap()]);
        Command::new(env!("CARGO_BIN_EXE_dbms"))
            .args(&args)
            .env("DBMS_FAULT", "enospc:v.exr")
            .output()
            .unwrap()
    };
    let failed = |o: std::process::Output| {
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{err}");
        assert!(
            err.starts_with("dbms: error: ")
                && err.contains("v.exr: no space left on the device")
                && err.trim_end().lines().count() == 1,
            "{err}"
        );
    };
    failed(run("70"));
    let left: Vec<_> = std::fs::read_dir(&out).unwrap().collect();
    assert!(left.is_empty(), "left: {left:?}");
    render(&tiles, &png, &VIEW);
    let before = std::fs::read(&png).unwrap();
    failed(run("40"));
    assert_eq!(
        std::fs::read(&png).unwrap(),
        before,
        "the view was replaced"
    );
    assert!(!exr.exists());
}

#[test]
fn same_command_gives_byte_identical_files() {
    let dir = tempfile::tempdir().unwrap();
    let tiles = hills(dir.path());
    let (a, b) = (dir.path().join("a.png"), dir.path().join("b.png"));
    let mut args = VIEW.to_vec();
    args.extend(["--haze", "800", "--repeat"]);
    render(&tiles, &a, &args);
    render(&tiles, &b, &args);
    assert!(std::fs::read(a).unwrap() == std::fs::read(b).unwrap());
}

#[test]
fn supersampled_blended_views_cast_the_extra_rays_and_keep_the_range_image() {
    let dir = tempfile::tempdir().unwrap();
    let tiles = hills(dir.path());
    let (plain, smooth) = (dir.path().join("a.png"), dir.path().join("b.png"));
    let with_range = |png: &Path, exr: &str, extra: &[&str]| {
        let exr = dir.path().join(exr);
        let mut args = VIEW.to_vec();
        args.extend(["--range-out", exr.to_str().unwrap()]);
        args.extend(extra);
        let json = render(&tiles, png, &args);
        (json, std::fs::read(exr).unwrap())
    };
    let (a, range_a) = with_range(&plain, "a.exr", &[]);
    let (b, range_b) = with_range(&smooth, "b.exr", &["--samples", "9"]);
    assert_eq!(a["stats"]["rays"], 96 * 64);
    assert_eq!(b["stats"]["rays"], 96 * 64 * 10);
    assert!(range_a == range_b, "the range image is the centre rays'");
    assert!(std::fs::read(&plain).unwrap() != std::fs::read(&smooth).unwrap());
    // Blending may stop rays at a finer level, so it may change ranges: only the count here.
    let (c, _) = with_range(
        &dir.path().join("c.png"),
        "c.exr",
        &["--samples", "4", "--blend"],
    );
    assert_eq!(c["stats"]["rays"], 96 * 64 * 5);
}

#[test]
fn top_view_maps_the_whole_database() {
    let dir = tempfile::tempdir().unwrap();
    let tiles = hills(dir.path());
    let out = dir.path().join("map.png");
    let s = render(&tiles, &out, &["--top"]);
    assert_eq!(
        (s["width"].as_u64(), s["height"].as_u64()),
        (Some(300), Some(200))
    );
    let img = image::open(&out).unwrap().to_rgb8();
    assert_eq!(img.get_pixel(0, 0).0, [0, 0, 0], "nodata corner is black");
    assert_eq!(
        img.get_pixel(123, 45).0,
        [123, 45, 90],
        "cell colour under the pixel"
    );
    let s = render(&tiles, &out, &["--top", "--size", "75x50"]);
    assert_eq!(s["width"], 75);
    // A window of 40 × 20 cells (2 m) from column 100, row 30: one pixel a cell by default.
    let w = "431200,4581900,431280,4581940";
    let s = render(&tiles, &out, &["--top", "--window", w]);
    assert_eq!(
        (s["width"].as_u64(), s["height"].as_u64()),
        (Some(40), Some(20))
    );
    let img = image::open(&out).unwrap().to_rgb8();
    assert_eq!(img.get_pixel(23, 15).0, [123, 45, 90]);
    let o = dbms(&[
        "render",
        "--tiles",
        tiles.to_str().unwrap(),
        "--window",
        w,
        "-o",
        "x.png",
    ]);
    assert!(String::from_utf8_lossy(&o.stderr).contains("--top"));
}

#[test]
fn eye_below_the_terrain_is_a_one_line_error() {
    let dir = tempfile::tempdir().unwrap();
    let tiles = hills(dir.path());
    let out = dir.path().join("v.png");
    let o = dbms(&[
        "render",
        "--tiles",
        tiles.to_str().unwrap(),
        "--eye",
        "431200,4581800,50",
        "-o",
        out.to_str().unwrap(),
    ]);
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("below the terrain") && err.lines().count() == 1,
        "{err}"
    );
    assert!(!out.exists());
}

/// Run dbms with `args`: it must fail, saying `expect` in an error of at most two lines.
fn refused(args: &[&str], expect: &str) {
    let o = dbms(args);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains(expect) && err.trim().lines().count() <= 2,
        "{expect}: {err}"
    );
}

#[test]
fn bad_options_name_the_option() {
    let dir = tempfile::tempdir().unwrap();
    let tiles = hills(dir.path());
    let t = tiles.to_str().unwrap();
    for (args, expect) in [
        (vec!["--eye", "1,2"], "--eye 1,2: expected three"),
        (
            vec!["--eye", "431020,4581620,140", "--size", "640"],
            "--size 640",
        ),
        (
            vec!["--eye", "431020,4581620,140", "--attitude", "0,100,0"],
            "pitch must be in [-90, 90]",
        ),
        (vec!["--eye", "431020,4581620,140", "--fov", "0"], "--fov 0"),
        (
            vec!["--eye", "431020,4581620,140", "--haze", "-5"],
            "--haze -5",
        ),
        (
            vec!["--eye", "431020,4581620,140", "--samples", "3"],
            "--samples 3: rays per pixel must be a square",
        ),
        (
            vec!["--eye", "431020,4581620,140", "--blend", "--no-lod"],
            "cannot be used with",
        ),
    ] {
        let mut a = vec!["render", "--tiles", t, "-o", "/nonexistent/x.png"];
        a.extend(args);
        refused(&a, expect);
    }
    let o = dbms(&[
        "render",
        "--tiles",
        "/nonexistent.dbt",
        "--top",
        "-o",
        "x.png",
    ]);
    assert!(String::from_utf8_lossy(&o.stderr).contains("/nonexistent.dbt"));
}

/// The centre pixel's range from a 5 × 5 render's range EXR (the centre ray is exactly on the
/// view axis).
fn centre_range(tiles: &Path, dir: &Path, eye: &str, attitude: &str, traversal: &str) -> f32 {
    let (png, exr) = (dir.join("c.png"), dir.join("c.exr"));
    let args = [
        "--eye",
        eye,
        "--attitude",
        attitude,
        "--size",
        "5x5",
        "--no-lod",
        "--traversal",
        traversal,
        "--range-out",
        exr.to_str().unwrap(),
    ];
    render(tiles, &png, &args);
    let img = exr::prelude::read_first_flat_layer_from_file(&exr).unwrap();
    let exr::prelude::FlatSamples::F32(z) = &img.layer_data.channel_data.list[0].sample_data else {
        panic!("f32 samples")
    };
    z[12]
}

#[test]
fn rays_pass_through_an_arch_and_its_range_is_on_the_face_hit() {
    use dbms::testing::tiles::write_columns;
    use dbms::voxel::columns::Run;
    let dir = tempfile::tempdir().unwrap();
    // Ground at 50 m, UTM-sized origin, 1 m cells; a 10 m wall along row 4; an arch over rows
    // 20..=24 (y 4 582 075..4 582 080): legs to 56 m at columns 20 and 24, a lintel 54..56 m
    // over columns 21..=23.
    let ground = |z: f32| Run {
        bottom: f32::NEG_INFINITY,
        top: z,
        colour: [90, 140, 60, 255],
    };
    let tiles = dir.path().join("arch.dbt");
    let grid = Grid::north_up(431_000.0, 4_582_100.0, 1.0, 48, 48, Crs::epsg(32633));
    write_columns(&tiles, grid, 16, 4, |c, r| match (c, r) {
        (_, 4) => vec![ground(60.0)],
        (20 | 24, 20..=24) => vec![ground(56.0)],
        (21..=23, 20..=24) => vec![
            ground(50.0),
            Run {
                bottom: 54.0,
                top: 56.0,
                colour: [180, 40, 40, 255],
            },
        ],
        _ => vec![ground(50.0)],
    })
    .unwrap();
    for t in ["hierarchical", "level0"] {
        // Looking north from y = 4 582 060.25: through the opening (52 m) to the wall's south
        // face at y = 4 582 095; on the lintel's south face at y = 4 582 075 (55 m); on the leg.
        assert_eq!(
            centre_range(&tiles, dir.path(), "431022.5,4582060.25,52", "0,0,0", t),
            34.75,
            "{t}"
        );
        assert_eq!(
            centre_range(&tiles, dir.path(), "431022.5,4582060.25,55", "0,0,0", t),
            14.75,
            "{t}"
        );
        assert_eq!(
            centre_range(&tiles, dir.path(), "431020.5,4582060.25,52", "0,0,0", t),
            14.75,
            "{t}"
        );
        // Standing under the lintel and looking straight up: its underside 4 m above.
        assert_eq!(
            centre_range(&tiles, dir.path(), "431022.5,4582077.5,50.5", "0,90,0", t),
            3.5,
            "{t}"
        );
    }
    // An eye inside the lintel is a one-line error.
    let out = dir.path().join("v.png");
    let o = dbms(&[
        "render",
        "--tiles",
        tiles.to_str().unwrap(),
        "--eye",
        "431022.5,4582077.5,55",
        "-o",
        out.to_str().unwrap(),
    ]);
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        !o.status.success() && err.contains("inside a voxel column") && err.lines().count() == 1,
        "{err}"
    );
}

/// The frame count and loop of an animated PNG, from its `acTL` chunk.
fn apng_frames(bytes: &[u8]) -> Option<(u32, u32)> {
    let mut i = 8;
    while i + 8 <= bytes.len() {
        let n = u32::from_be_bytes(bytes[i..i + 4].try_into().unwrap()) as usize;
        if &bytes[i + 4..i + 8] == b"acTL" {
            let word = |k: usize| u32::from_be_bytes(bytes[k..k + 4].try_into().unwrap());
            return Some((word(i + 8), word(i + 12)));
        }
        i += 12 + n;
    }
    None
}

#[test]
fn a_flight_renders_every_frame_and_an_animation_the_same_on_every_run() {
    let dir = tempfile::tempdir().unwrap();
    let tiles = hills(dir.path());
    let path = dir.path().join("flight.csv");
    // 515 m at 100 m/s: frames at 0, 0.25, …, 5 s.
    std::fs::write(&path, "x,y,z\n431050,4581650,200\n431500,4581900,200\n").unwrap();
    let (frames, anim) = (dir.path().join("frames"), dir.path().join("flight.png"));
    let fly = |fps: &str| {
        render(
            &tiles,
            &frames,
            &[
                "--path",
                path.to_str().unwrap(),
                "--speed",
                "100",
                "--fps",
                fps,
                "--size",
                "48x32",
                "--attitude",
                "0,-10,0",
                "--animation",
                anim.to_str().unwrap(),
            ],
        )
    };
    let json = fly("4");
    assert_eq!(json["stats"]["frames"], 21);
    assert!(json["stats"]["frames_per_second"].as_f64().unwrap() > 0.0);
    assert!(json["stats"]["pages_read_max"].as_u64().unwrap() > 0);
    let read = |k: usize| std::fs::read(frames.join(format!("frame-{k:05}.png"))).unwrap();
    let (first, last) = (read(0), read(20));
    assert_ne!(first, last, "the eye moved");
    let animation = std::fs::read(&anim).unwrap();
    assert_eq!(apng_frames(&animation), Some((21, 0)));
    // Same bytes again; a shorter flight into the same directory leaves no stale frames.
    fly("4");
    assert!(read(0) == first && read(20) == last && std::fs::read(&anim).unwrap() == animation);
    fly("2");
    let left = std::fs::read_dir(&frames)
        .unwrap()
        .filter(|e| e.as_ref().unwrap().file_name() != "frames.json")
        .count();
    assert_eq!(left, 11);
    assert_eq!(apng_frames(&std::fs::read(&anim).unwrap()), Some((11, 0)));
}

/// Issue 40, defect 10: a flight killed while rendering into a directory that holds an earlier
/// flight once left frames of both, as many as a complete run. The earlier flight now stays
/// whole with its record (`frames.json`, every frame's SHA-256) until the new one is rendered;
/// a run killed while renaming its frames into place leaves no record.
#[test]
fn a_killed_flight_leaves_the_earlier_one_whole_or_no_record() {
    let dir = tempfile::tempdir().unwrap();
    let tiles = hills(dir.path());
    let frames = dir.path().join("frames");
    let fly = |path: &str, fault: Option<&str>| {
        let csv = dir.path().join("flight.csv");
        std::fs::write(&csv, path).unwrap();
        let mut c = std::process::Command::new(env!("CARGO_BIN_EXE_dbms"));
        c.args(["-q", "render", "--tiles", tiles.to_str().unwrap(), "-o"])
            .arg(&frames)
            .args([
                "--path",
                csv.to_str().unwrap(),
                "--speed",
                "100",
                "--fps",
                "4",
            ])
            .args(["--size", "48x32", "--attitude", "0,-10,0"]);
        if let Some(f) = fault {
            c.env("DBMS_FAULT", f);
        }
        c.output().unwrap().status.success()
    };
    let record = || -> Value {
        serde_json::from_slice(&std::fs::read(frames.join("frames.json")).unwrap()).unwrap()
    };
    let holds = |r: &Value| {
        r["files"].as_array().unwrap().iter().all(|f| {
            let bytes = std::fs::read(frames.join(f["file"].as_str().unwrap())).unwrap();
            let sha: String = sha256_hex(&bytes);
            f["sha256"] == sha.as_str()
        })
    };
    let (a, b) = (
        "x,y,z\n431050,4581650,200\n431500,4581900,200\n",
        "x,y,z\n431500,4581900,150\n431050,4581650,150\n",
    );
    assert!(fly(a, None));
    let first = record();
    let schema = Path::new(env!("CARGO_MANIFEST_DIR")).join("schemas/flight-frames.schema.json");
    let schema: Value = serde_json::from_slice(&std::fs::read(schema).unwrap()).unwrap();
    assert!(jsonschema::is_valid(&schema, &first), "{first}");
    assert_eq!(first["frames"], 21);
    assert!(holds(&first));
    assert!(
        !fly(b, Some("flight-frame-staged")),
        "the fault did not fire"
    );
    assert_eq!(record(), first, "the record changed");
    assert!(
        holds(&first),
        "a frame of the killed flight replaced one of the earlier"
    );
    assert!(
        !fly(b, Some("flight-frames-renamed")),
        "the fault did not fire"
    );
    assert!(
        !frames.join("frames.json").exists(),
        "a record of a mixed set"
    );
    assert!(fly(b, None));
    let second = record();
    assert!(holds(&second) && second != first);
}

fn sha256_hex(bytes: &[u8]) -> String {
    use sha2::Digest;
    sha2::Sha256::digest(bytes)
        .iter()
        .map(|b| format!("{b:02x}"))
        .collect()
}

#[test]
fn a_flight_without_times_or_speed_or_with_a_bad_path_is_a_one_line_error() {
    let dir = tempfile::tempdir().unwrap();
    let tiles = hills(dir.path());
    let t = tiles.to_str().unwrap();
    let path = dir.path().join("p.csv");
    std::fs::write(&path, "x,y,z\n431050,4581650,200\n431500,4581900,200\n").unwrap();
    let bad = dir.path().join("bad.csv");
    std::fs::write(&bad, "x,y,z\n431050,4581650\n").unwrap();
    let file = dir.path().join("a-file");
    std::fs::write(&file, "").unwrap();
    let p = path.to_str().unwrap();
    for (args, expect) in [
        (vec!["--path", p], "give --speed"),
        (
            vec!["--path", bad.to_str().unwrap(), "--speed", "5"],
            "bad.csv",
        ),
        (vec!["--path", p, "--speed", "5", "--fps", "0"], "--fps 0"),
        (
            vec!["--path", p, "--speed", "50", "-o", file.to_str().unwrap()],
            "not a directory",
        ),
        (
            vec!["--path", p, "--speed", "50", "--top"],
            "cannot be used with",
        ),
        (
            vec!["--path", p, "--speed", "50", "--range-out", "r.exr"],
            "cannot be used with",
        ),
    ] {
        let mut a = vec!["render", "--tiles", t];
        if !args.contains(&"-o") {
            a.extend(["-o", "/tmp/never-written-frames"]);
        }
        a.extend(args);
        refused(&a, expect);
    }
}
