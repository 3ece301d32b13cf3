//! Benchmark: `dbms shadow-height` on a real town's layout, against independent truth —
//! orthophotos rendered by POV-Ray of the 472 real building footprints of a dense 600 m × 600 m
//! window of Boulder, Colorado (tests/data/boulder/), with heights, roofs, trees and vehicles
//! drawn by tests/support/town.rs and written into the scene as truth (issue 39, item 4).
//!
//! `cargo bench --bench shadow_height_town` (every setting, ~13 min on 2 busy cores) or
//! `-- quick` (four settings, under a minute); `-- keep` keeps every scene's directory
//! (`scene.pov`, the photo, the database, `footprints.geojson`, `heights.geojson` and
//! `truth.geojson`, every building's truth; otherwise only failed ones are kept, under the
//! temporary directory printed at the start); any other word runs only the
//! settings whose label contains it (`-- keep "JPEG"`); options starting with `--` go to
//! `dbms shadow-height`. Needs `povray` on PATH (`apt-get install povray`).
//!
//! Each setting photographs two 150 m windows of the town (one in `quick`; the settings walk
//! through the 16 windows, so each sees different parts) with a 25 m margin, and scores the
//! buildings whose
//! footprint's centroid is in the window (every building of the town is in the POV-Ray scene,
//! so shadows cast into the photo from outside it are there; every footprint that shows in
//! the photo is in the footprint file, but for the `unlisted` setting). The base photo: a soft
//! sun (the 0.53° solar disc as an area light), sRGB PNG, 0.5 m cells, flat ground, a true
//! orthophoto, footprints exact; each other setting changes one or two of these: the sun
//! (12–70° elevation, azimuths on the exact diagonals, axes and off them), 0.25 m cells, a
//! 5 % or 12 % slope, a hard sun and a linear PNG, JPEG at quality 75 and 90, frame photos from
//! 500, 1500 and 3000 m, footprints shifted by up to 3 m, a tenth of the buildings unlisted.
//!
//! Per setting and in summaries (truth: the absolute roof top, the ridge of a pitched roof):
//! buildings scored; with a height (`roof_z`); with only a lower bound (`roof_z_at_least`);
//! with neither; the share of heights within 1 m; the share of buildings whose truth is
//! outside the reported 95 % and 68 % intervals (`roof_z_interval_95`, `roof_z_interval_68`;
//! a truth below a lower bound counts as outside; "–" when dbms gives none); silent gross
//! errors (no flag but `low_sun` / `high_sun`, more than 2 cells off); the share flagged or
//! without a height; for pitched roofs, the ridge (`roof_z`) and the eaves (`eave_z`) within 2
//! cells and the form right (`roof_form`); and `dbms shadow-height`'s wall clock per footprint
//! in the file (run alone). Then the flags seen and the worst cases.

#[path = "../tests/support/povray.rs"]
mod povray;
#[path = "../tests/support/shadow_truth.rs"]
mod shadow_truth;
#[path = "../tests/support/town.rs"]
mod town;

use povray::{Camera, Photo, PolygonBuilding, Roof, Scene, UTM13N_WKT};
use shadow_truth::{measure_prepared_with, prepare_scene_photo, Outcome};
use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::Instant;
use town::{window_scene, Shot, Town, TOWN_SIDE, TOWN_SW};

/// The town's seed (heights, roofs, trees, vehicles): one town for every setting.
const TOWN_SEED: u64 = 39;
/// Windows per setting in the full run (one in `quick`).
const WINDOWS: usize = 2;
/// Window side and margin, metres.
const WINDOW: f64 = 150.0;
const MARGIN: f64 = 25.0;
/// A silent gross error is an unflagged roof off by more than this many cells.
const GROSS_CELLS: f64 = 2.0;
/// Scenes rendered and ingested at once (POV-Ray runs one thread each).
const WORKERS: usize = 2;

/// How the photo is encoded.
#[derive(Debug, Clone, Copy, PartialEq)]
enum Encoding {
    LinearPng,
    SrgbPng,
    SrgbJpeg(u8),
}

/// One row of the table.
#[derive(Debug, Clone)]
struct Setting {
    az: f64,
    elev: f64,
    cell: f64,
    /// Ground grade, %, and its direction (azimuth of the rise, degrees).
    slope: (f64, f64),
    soft: bool,
    encoding: Encoding,
    /// Frame photo from this height above the ground (nadir 300 m south-west of the window's
    /// centre); `None`: a true orthophoto.
    perspective: Option<f64>,
    shift: (f64, f64),
    unlisted: f64,
}

impl Setting {
    fn base(az: f64, elev: f64) -> Setting {
        Setting {
            az,
            elev,
            cell: 0.5,
            slope: (0.0, 0.0),
            soft: true,
            encoding: Encoding::SrgbPng,
            perspective: None,
            shift: (0.0, 0.0),
            unlisted: 0.0,
        }
    }
    fn label(&self) -> String {
        let mut l = format!("az {}° · el {}° · {} m", self.az, self.elev, self.cell);
        if self.slope.0 > 0.0 {
            l += &format!(" · {} % slope", self.slope.0);
        }
        l += if self.soft {
            " · soft sun"
        } else {
            " · hard sun"
        };
        l += match self.encoding {
            Encoding::LinearPng => " · linear PNG".to_string(),
            Encoding::SrgbPng => " · sRGB PNG".to_string(),
            Encoding::SrgbJpeg(q) => format!(" · JPEG q{q}"),
        }
        .as_str();
        if let Some(h) = self.perspective {
            l += &format!(" · frame from {h} m");
        }
        if self.shift != (0.0, 0.0) {
            l += &format!(" · shift ({}, {}) m", self.shift.0, self.shift.1);
        }
        if self.unlisted > 0.0 {
            l += &format!(" · {:.0} % unlisted", 100.0 * self.unlisted);
        }
        l
    }
    fn photo(&self) -> Photo {
        Photo {
            sun_disc_deg: self.soft.then_some(0.53),
            area_samples: 9,
            srgb: self.encoding != Encoding::LinearPng,
            jpeg_quality: match self.encoding {
                Encoding::SrgbJpeg(q) => Some(q),
                _ => None,
            },
            crs_wkt: UTM13N_WKT,
        }
    }
}

/// The settings; `quick` keeps four.
fn settings(quick: bool) -> Vec<Setting> {
    let b = Setting::base;
    let mut v = vec![
        b(135.0, 40.0),
        b(180.0, 40.0),
        b(200.0, 40.0),
        b(90.0, 25.0),
        b(225.0, 12.0),
        b(160.0, 20.0),
        b(135.0, 55.0),
        b(250.0, 70.0),
        Setting {
            cell: 0.25,
            ..b(135.0, 40.0)
        },
        Setting {
            cell: 0.25,
            ..b(200.0, 30.0)
        },
        Setting {
            slope: (5.0, 100.0),
            ..b(200.0, 40.0)
        },
        Setting {
            slope: (12.0, 300.0),
            ..b(120.0, 30.0)
        },
        Setting {
            soft: false,
            encoding: Encoding::LinearPng,
            ..b(135.0, 40.0)
        },
        Setting {
            encoding: Encoding::SrgbJpeg(75),
            ..b(200.0, 40.0)
        },
        Setting {
            encoding: Encoding::SrgbJpeg(90),
            ..b(145.0, 35.0)
        },
        Setting {
            perspective: Some(500.0),
            ..b(135.0, 40.0)
        },
        Setting {
            perspective: Some(1500.0),
            ..b(200.0, 45.0)
        },
        Setting {
            perspective: Some(3000.0),
            ..b(180.0, 35.0)
        },
        Setting {
            shift: (2.1, -1.4),
            ..b(200.0, 40.0)
        },
        Setting {
            shift: (-2.8, 0.9),
            ..b(135.0, 30.0)
        },
        Setting {
            unlisted: 0.1,
            ..b(170.0, 40.0)
        },
        Setting {
            cell: 0.25,
            encoding: Encoding::SrgbJpeg(85),
            ..b(315.0, 30.0)
        },
    ];
    if quick {
        // The base, a 12° sun, a JPEG, a frame photo.
        v = [0usize, 4, 13, 15].iter().map(|&i| v[i].clone()).collect();
    }
    v
}

/// The shot `j` of setting `s`, which is row `i` of the full list (its window: `i + 8 j` mod
/// 16, so a setting's two windows are in different halves of the town).
fn shot(s: &Setting, i: usize, j: usize) -> Shot {
    let per_side = (TOWN_SIDE / WINDOW) as usize;
    let w = (i + 8 * j) % (per_side * per_side);
    let sw = (
        TOWN_SW.0 + WINDOW * (w % per_side) as f64,
        TOWN_SW.1 + WINDOW * (w / per_side) as f64,
    );
    let (g, dir) = (s.slope.0 / 100.0, s.slope.1.to_radians());
    let camera = match s.perspective {
        None => Camera::Ortho,
        Some(h) => Camera::Perspective {
            nadir: (sw.0 + WINDOW / 2.0 - 212.0, sw.1 + WINDOW / 2.0 - 212.0),
            height_m: h,
        },
    };
    Shot {
        sw,
        side: WINDOW,
        margin: MARGIN,
        cell: s.cell,
        sun_azimuth_deg: s.az,
        sun_elevation_deg: s.elev,
        gradient: (g * dir.sin(), g * dir.cos()),
        camera,
        footprint_shift: s.shift,
        unlisted: s.unlisted,
        antialias: povray::antialias_for(s.elev),
        seed: 1000 + 10 * i as u64 + j as u64,
    }
}

/// Counts over a set of scored buildings.
#[derive(Default, Clone)]
struct Stats {
    buildings: usize,
    measured: usize,
    bound_only: usize,
    neither: usize,
    within_1m: usize,
    /// Buildings with a 95 % interval (or a lower bound) and those whose truth is outside it;
    /// the same for 68 %.
    with95: usize,
    out95: usize,
    with68: usize,
    out68: usize,
    gross: usize,
    flagged_or_null: usize,
    pitched: usize,
    ridge_ok: usize,
    with_eave: usize,
    eave_ok: usize,
    with_form: usize,
    form_ok: usize,
    /// Footprints in the files dbms was given, and its wall clock over them, seconds.
    footprints: usize,
    secs: f64,
    failed_scenes: usize,
}

impl Stats {
    fn add(&mut self, o: &Stats) {
        self.buildings += o.buildings;
        self.measured += o.measured;
        self.bound_only += o.bound_only;
        self.neither += o.neither;
        self.within_1m += o.within_1m;
        self.with95 += o.with95;
        self.out95 += o.out95;
        self.with68 += o.with68;
        self.out68 += o.out68;
        self.gross += o.gross;
        self.flagged_or_null += o.flagged_or_null;
        self.pitched += o.pitched;
        self.ridge_ok += o.ridge_ok;
        self.with_eave += o.with_eave;
        self.eave_ok += o.eave_ok;
        self.with_form += o.with_form;
        self.form_ok += o.form_ok;
        self.footprints += o.footprints;
        self.secs += o.secs;
        self.failed_scenes += o.failed_scenes;
    }

    /// Score one building.
    fn score(&mut self, o: &Outcome, b: &PolygonBuilding, cell: f64) {
        self.buildings += 1;
        let truth = b.roof.top_z();
        match (o.roof_z, o.at_least()) {
            (Some(_), _) => self.measured += 1,
            (None, Some(_)) => self.bound_only += 1,
            (None, None) => self.neither += 1,
        }
        let flagged = o.flagged() || o.roof_z.is_none();
        self.flagged_or_null += flagged as usize;
        if let Some(e) = o.error_m() {
            self.within_1m += (e.abs() <= 1.0) as usize;
            if !o.flagged() && e.abs() > GROSS_CELLS * cell {
                self.gross += 1;
            }
        }
        for (key, with, out) in [
            ("roof_z_interval_95", &mut self.with95, &mut self.out95),
            ("roof_z_interval_68", &mut self.with68, &mut self.out68),
        ] {
            if o.roof_z.is_some() {
                if let Some((lo, hi)) = o.pair(key) {
                    *with += 1;
                    *out += (truth < lo || truth > hi) as usize;
                }
            } else if let Some(lo) = o.at_least() {
                *with += 1;
                *out += (truth < lo) as usize;
            }
        }
        if !matches!(b.roof, Roof::Flat { .. }) {
            self.pitched += 1;
            if let Some(e) = o.error_m() {
                self.ridge_ok += (e.abs() <= GROSS_CELLS * cell) as usize;
            }
            if let Some(eave) = o.number("eave_z") {
                self.with_eave += 1;
                self.eave_ok += ((eave - b.roof.eave_z()).abs() <= GROSS_CELLS * cell) as usize;
            }
            if let Some(form) = o.properties.get("roof_form").and_then(|f| f.as_str()) {
                self.with_form += 1;
                self.form_ok += (form == b.roof.form()) as usize;
            }
        }
    }
}

/// `n` of `of` as a percentage, or "–" when `of` is 0.
fn pct(n: usize, of: usize) -> String {
    if of == 0 {
        "–".into()
    } else {
        format!("{:.1}", 100.0 * n as f64 / of as f64)
    }
}

/// A pitched-roof share "n / of" or "–" when dbms reported nothing to judge.
fn share(n: usize, of: usize) -> String {
    if of == 0 {
        "–".into()
    } else {
        format!("{n} / {of}")
    }
}

fn table_header() {
    println!(
        "| setting | buildings | height | lower bound only | neither | within 1 m % | truth outside 95 % | outside 68 % | silent gross | flagged or null % | pitched: ridge ±2 cells | eaves ±2 cells | form right | ms / footprint |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
}

fn table_row(name: &str, t: &Stats) {
    println!(
        "| {name} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {:.0} |",
        t.buildings,
        t.measured,
        t.bound_only,
        t.neither,
        pct(t.within_1m, t.measured),
        pct(t.out95, t.with95),
        pct(t.out68, t.with68),
        if t.gross > 0 {
            format!("**{}**", t.gross)
        } else {
            "0".into()
        },
        pct(t.flagged_or_null, t.buildings),
        share(t.ridge_ok, t.pitched),
        share(t.eave_ok, t.with_eave),
        share(t.form_ok, t.with_form),
        1000.0 * t.secs / t.footprints.max(1) as f64
    );
}

/// One building worth showing.
struct Case {
    setting: String,
    building: usize,
    form: &'static str,
    truth: f64,
    measured: Option<f64>,
    at_least: Option<f64>,
    flags: Vec<String>,
    cell: f64,
}

/// What one scene gave.
struct SceneResult {
    setting: usize,
    outcomes: Result<Vec<Outcome>, String>,
    scene: Scene<PolygonBuilding>,
    core: Vec<usize>,
    secs: f64,
    render_secs: f64,
    dir: PathBuf,
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let quick = args.iter().any(|a| a == "quick");
    let keep = args.iter().any(|a| a == "keep");
    let filters: Vec<&String> = args
        .iter()
        .filter(|a| !a.starts_with('-') && *a != "quick" && *a != "keep")
        .collect();
    let extra: Vec<String> = args
        .iter()
        .filter(|a| a.starts_with("--") && *a != "--bench")
        .cloned()
        .collect();
    if std::process::Command::new("povray")
        .arg("--version")
        .output()
        .is_err()
    {
        eprintln!("povray is not on PATH (apt-get install povray)");
        std::process::exit(1);
    }
    let root_dir = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let town = Town::load(&root_dir, TOWN_SEED).unwrap_or_else(|e| panic!("the town: {e}"));
    // Rows keep their index in the full list (it picks the window).
    let full = settings(false);
    let chosen: Vec<Setting> = settings(quick);
    let rows: Vec<(usize, Setting)> = chosen
        .into_iter()
        .map(|s| {
            let i = full
                .iter()
                .position(|f| f.label() == s.label())
                .expect("a quick setting is a full one");
            (i, s)
        })
        .filter(|(_, s)| filters.iter().all(|f| s.label().contains(f.as_str())))
        .collect();
    let root = std::env::temp_dir().join(format!("dbms-shadow-height-town-{}", std::process::id()));
    let forms = |f: &str| town.buildings.iter().filter(|b| b.form == f).count();
    eprintln!(
        "town: {} buildings ({} flat of which {} towers, {} gable, {} hip), {} trees, {} vehicles; {} settings; scenes under {}",
        town.buildings.len(),
        forms("flat"),
        town.buildings.iter().filter(|b| b.tower).count(),
        forms("gable"),
        forms("hip"),
        town.clutter.iter().filter(|c| matches!(c, povray::Clutter::Tree { .. })).count(),
        town.clutter.iter().filter(|c| matches!(c, povray::Clutter::Vehicle { .. })).count(),
        rows.len(),
        root.display()
    );
    let git = |args: &[&str]| {
        std::process::Command::new("git")
            .args(args)
            .output()
            .ok()
            .map(|o| String::from_utf8_lossy(&o.stdout).trim_end().to_string())
            .unwrap_or_default()
    };
    let commit = git(&["rev-parse", "--short=12", "HEAD"]);
    let dirty = git(&[
        "status",
        "--porcelain",
        "--",
        "src",
        "Cargo.toml",
        "Cargo.lock",
    ]);
    let threads = std::thread::available_parallelism().map_or(0, |n| n.get());
    let started = Instant::now();
    let mut results: Vec<SceneResult> = Vec::new();
    let windows = if quick { 1 } else { WINDOWS };
    let jobs: Vec<(usize, Setting, usize)> = rows
        .iter()
        .flat_map(|(i, s)| (0..windows).map(move |j| (*i, s.clone(), j)))
        .collect();
    for batch in jobs.chunks(WORKERS * 2) {
        let next = AtomicUsize::new(0);
        let prepared = Mutex::new(Vec::new());
        std::thread::scope(|sc| {
            for _ in 0..WORKERS {
                sc.spawn(|| loop {
                    let j = next.fetch_add(1, Ordering::Relaxed);
                    let Some((i, s, w)) = batch.get(j) else { break };
                    let ws = window_scene(&town, &shot(s, *i, *w));
                    let dir = root.join(format!("{i:02}-{w}"));
                    let p = prepare_scene_photo(&ws.scene, &dir, &s.photo());
                    // The truth beside the scene, for whoever keeps it (`keep`).
                    let _ = std::fs::write(
                        dir.join("truth.geojson"),
                        town::truth_geojson(&town, &ws.scene),
                    );
                    prepared.lock().unwrap().push((j, ws, dir, p));
                });
            }
        });
        let mut prepared = prepared.into_inner().unwrap();
        prepared.sort_by_key(|p| p.0);
        for (j, ws, dir, p) in prepared {
            let (i, s, _) = &batch[j];
            let (outcomes, secs, render_secs) = match p {
                Ok(p) => match measure_prepared_with(&ws.scene, &p, &extra) {
                    Ok((o, t)) => (Ok(o), t, p.render_secs),
                    Err(e) => (Err(e), 0.0, p.render_secs),
                },
                Err(e) => (Err(e), 0.0, 0.0),
            };
            eprintln!(
                "{}: rendered in {render_secs:.0} s, measured in {secs:.1} s{}",
                s.label(),
                if outcomes.is_err() { " (failed)" } else { "" }
            );
            results.push(SceneResult {
                setting: *i,
                outcomes,
                scene: ws.scene,
                core: ws.core,
                secs,
                render_secs,
                dir,
            });
        }
    }
    let wall = started.elapsed().as_secs_f64();

    let mut per_row: Vec<(usize, Stats)> = Vec::new();
    let mut failures = Vec::new();
    let mut flag_counts: Vec<(String, usize)> = Vec::new();
    let mut cases: Vec<Case> = Vec::new();
    // By roof form (flat, tower, gable, hip).
    let mut by_form: Vec<(&str, Stats)> = ["flat", "tower", "gable", "hip"]
        .iter()
        .map(|f| (*f, Stats::default()))
        .collect();
    let mut render_secs = 0.0;
    for r in &results {
        let set = &full[r.setting];
        render_secs += r.render_secs;
        let mut st = Stats {
            secs: r.secs,
            ..Stats::default()
        };
        let mut keep_dir = keep;
        match &r.outcomes {
            Err(e) => {
                st.failed_scenes += 1;
                st.buildings += r.core.len();
                st.neither += r.core.len();
                st.flagged_or_null += r.core.len();
                failures.push(format!("{}: {e}", set.label()));
                keep_dir = true;
            }
            Ok(out) => {
                st.footprints = out.len();
                for o in out {
                    if !r.core.contains(&o.building) {
                        continue;
                    }
                    let b = &r.scene.buildings[o.building];
                    st.score(o, b, set.cell);
                    let tb = &town.buildings[o.building];
                    let form = if tb.tower { "tower" } else { tb.form };
                    let mut one = Stats::default();
                    one.score(o, b, set.cell);
                    by_form
                        .iter_mut()
                        .find(|(f, _)| *f == form)
                        .unwrap()
                        .1
                        .add(&one);
                    for f in &o.flags {
                        match flag_counts.iter_mut().find(|(k, _)| k == f) {
                            Some((_, c)) => *c += 1,
                            None => flag_counts.push((f.clone(), 1)),
                        }
                    }
                    cases.push(Case {
                        setting: set.label(),
                        building: o.building,
                        form,
                        truth: o.truth_z,
                        measured: o.roof_z,
                        at_least: o.at_least(),
                        flags: o.flags.clone(),
                        cell: set.cell,
                    });
                }
            }
        }
        if !keep_dir {
            let _ = std::fs::remove_dir_all(&r.dir);
        }
        match per_row.iter_mut().find(|(i, _)| *i == r.setting) {
            Some((_, t)) => t.add(&st),
            None => per_row.push((r.setting, st)),
        }
    }
    per_row.sort_by_key(|r| r.0);

    println!(
        "\nPer setting ({windows} × 150 m window{} each; the buildings whose centroid is in one):\n",
        if windows > 1 { "s" } else { "" }
    );
    table_header();
    let mut all = Stats::default();
    for (i, st) in &per_row {
        table_row(&full[*i].label(), st);
        all.add(st);
    }
    table_row("**all**", &all);

    // Summaries by group.
    type Pick = Box<dyn Fn(&Setting) -> bool>;
    let groups: Vec<(&str, Pick)> = vec![
        ("sun below 25°", Box::new(|s| s.elev < 25.0)),
        ("sun 25–45°", Box::new(|s| s.elev >= 25.0 && s.elev <= 45.0)),
        ("sun above 45°", Box::new(|s| s.elev > 45.0)),
        ("0.25 m cells", Box::new(|s| s.cell == 0.25)),
        ("sloped ground", Box::new(|s| s.slope.0 > 0.0)),
        (
            "JPEG",
            Box::new(|s| matches!(s.encoding, Encoding::SrgbJpeg(_))),
        ),
        ("frame photos", Box::new(|s| s.perspective.is_some())),
        ("footprints shifted", Box::new(|s| s.shift != (0.0, 0.0))),
        ("hard sun, linear PNG", Box::new(|s| !s.soft)),
    ];
    println!("\nSummary by group of settings, and by roof form over all settings:\n");
    table_header();
    table_row("all settings", &all);
    for (name, pick) in &groups {
        let mut t = Stats::default();
        for (i, st) in &per_row {
            if pick(&full[*i]) {
                t.add(st);
            }
        }
        if t.buildings > 0 {
            table_row(name, &t);
        }
    }
    for (f, st) in &by_form {
        table_row(&format!("roof: {f}"), st);
    }

    flag_counts.sort_by(|a, b| b.1.cmp(&a.1).then(a.0.cmp(&b.0)));
    println!(
        "\nFlags seen (scored buildings carrying each, of {}): {}",
        all.buildings,
        flag_counts
            .iter()
            .map(|(f, c)| format!("{f} {c}"))
            .collect::<Vec<_>>()
            .join(", ")
    );

    // Worst cases: the silent gross errors first, then the largest errors among flagged ones.
    let err = |c: &Case| c.measured.map_or(0.0, |m| (m - c.truth).abs());
    let silent = |c: &Case| {
        c.flags.iter().all(|f| f == "low_sun" || f == "high_sun")
            && c.measured.is_some()
            && err(c) > GROSS_CELLS * c.cell
    };
    cases.sort_by(|a, b| {
        silent(b)
            .cmp(&silent(a))
            .then(err(b).partial_cmp(&err(a)).unwrap())
    });
    println!("\nWorst cases (silent gross first, then by |error|; building = index in the town, tests/support/town.rs):\n");
    println!(
        "| setting | building | roof | truth m | measured m | error m | lower bound m | flags |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    for c in cases.iter().take(20) {
        println!(
            "| {} | {} | {} | {:.2} | {} | {} | {} | {} |",
            c.setting,
            c.building,
            c.form,
            c.truth,
            c.measured.map_or("–".into(), |m| format!("{m:.2}")),
            c.measured
                .map_or("–".into(), |m| format!("{:+.2}", m - c.truth)),
            c.at_least.map_or("–".into(), |m| format!("{m:.2}")),
            if c.flags.is_empty() {
                "none".into()
            } else {
                c.flags.join(", ")
            }
        );
    }
    if !failures.is_empty() {
        println!("\nFailed scenes ({}):\n", failures.len());
        for f in &failures {
            println!("* {f}");
        }
    }
    let measure_secs: f64 = per_row.iter().map(|r| r.1.secs).sum();
    println!(
        "\n{} scenes, {} buildings scored; wall clock {wall:.0} s ({WORKERS} scenes rendered at a time: POV-Ray {render_secs:.0} s summed over scenes; `dbms shadow-height` {measure_secs:.0} s, run alone)",
        results.len(),
        all.buildings
    );
    println!(
        "commit {commit}{}; {threads} hardware threads; {}",
        if dirty.is_empty() {
            String::new()
        } else {
            format!(" with uncommitted changes to {}", dirty.lines().count())
        },
        if quick { "quick" } else { "full run" }
    );
    if !extra.is_empty() {
        println!("dbms shadow-height options: {}", extra.join(" "));
    }
    if !keep && failures.is_empty() {
        let _ = std::fs::remove_dir_all(&root);
    } else {
        println!("scenes kept under {}", root.display());
    }
}
