//! Benchmark: `dbms shadow-height` against independent truth — orthophotos rendered by POV-Ray
//! (tests/support/povray.rs) of isolated flat-roofed buildings whose roof heights are known.
//!
//! POV-Ray shares no code with dbms: it ray-traces the scene's geometry (a ground plane, prisms,
//! a parallel sun), with its own anti-aliasing and shading. dbms sees only the PNG with its world
//! file, an ASCII DEM and GeoJSON footprints, through the `dbms ingest` and `dbms shadow-height`
//! commands (the release binary). The truth is the roof height written into the scene.
//!
//! `cargo bench --bench shadow_height_povray` (all rows, ~13 min on 2 cores) or `-- quick`
//! (a subset, ~2.5 min); `-- keep` keeps every scene's directory (otherwise only those with a
//! silent gross error are kept, under the temporary directory printed at the start); any other
//! word runs only the settings whose label contains it (`-- quick keep "el 8° ·"`), and options
//! starting with `--` go to `dbms shadow-height` (`-- "el 80°" --max-shift=0`).
//! Needs `povray` on PATH (`apt-get install povray`).
//!
//! The scenes. Each holds four buildings on a 2 × 2 lattice of square slots; a building and the
//! longest shadow it can cast fit in its slot with at least [`MARGIN`] metres of lit ground to
//! the slot's edge, so shadows never meet another building or shadow. Sides 8–25 m; roof 6–25 m
//! above the highest ground under the footprint, lowered at low suns so that a shadow is at
//! most [`MAX_SHADOW_M`] long (never below 6 m); flat roofs coloured grey, red or dark (each
//! with a little jitter). Ground: flat, or a plane of 15–20 % grade in a random direction —
//! redrawn while it would make shadows more than twice their flat length (at low suns a slope
//! falling away from the sun as steeply as the sun is high shadows the ground itself: no
//! building's shadow can be seen there). Footprints axis-aligned (rotation 0) or rotated at
//! random (0–90°); buildings' centres continuous, so every sub-cell phase occurs. Footprints
//! exactly on the roofs (no misregistration), true orthophotos, 3 × 3 anti-aliasing samples per
//! pixel (9 × 9 from a 60° sun up: [`povray::antialias_for`]). Each setting has [`LAYOUTS`] random layouts ([`LAYOUTS_FINE`] at 0.25 m cells, one in
//! `quick`), drawn from a seed made of the setting's label, so `quick`'s rows are the same
//! scenes as the full run's first layouts.
//!
//! The settings are two sweeps, not their full product (too slow):
//! * **azimuth**: 0–345° in 15° steps (so every exact axis and diagonal) and eight directions
//!   two ulps off 45°, 90°, 135°, 180°, 270°, 315°, at elevation 40° with 0.5 m cells, flat and
//!   sloped, axis-aligned and rotated;
//! * **elevation**: 8, 15, 30, 45, 60, 80° × cells 0.25, 0.5, 1 m × azimuths 135° (an exact
//!   diagonal), 270° (an exact axis) and 200° (neither), flat and sloped, axis-aligned and
//!   rotated.
//!
//! `quick` keeps the azimuth sweep's exact axes and diagonals and 45° ± 2 ulp, and the
//! elevation sweep's 8, 30 and 80° at 135°.
//!
//! Per row: buildings, measured (a roof height), unflagged (measured, and no flag but
//! `low_sun` / `high_sun`: [`Outcome::flagged`]), the RMSE of the unflagged roofs' errors in
//! metres and cells, the worst unflagged error in cells, the silent gross errors (unflagged,
//! off by more than 2 cells), the buildings flagged or without a height, and the wall clock of
//! `dbms shadow-height` per building (run alone: scenes are rendered and ingested two at a
//! time, then measured one after the other). Then summaries by group (with how many scenes
//! dbms moved the footprints by more than a cell: `footprint_shift_m`, where the truth is no
//! shift), the flags seen, and every silent gross error with its properties.

#[path = "../tests/support/povray.rs"]
mod povray;
#[path = "../tests/support/shadow_truth.rs"]
mod shadow_truth;

use povray::{Building, Camera, Rng, Roof, Scene};
use shadow_truth::{measure_prepared_with, prepare_scene, Outcome};
use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;
use std::time::Instant;

/// Random layouts per setting in the full run (one in `quick`).
const LAYOUTS: usize = 2;
/// Random layouts per setting with cells finer than 0.5 m in the full run: their renders cost
/// 4 × as much (one layout keeps the full run within ~15 minutes on 2 cores).
const LAYOUTS_FINE: usize = 1;
/// Buildings per scene: a 2 × 2 lattice of slots.
const SLOTS: usize = 2;
/// Lit ground kept between a building or its shadow and the edge of its slot, metres.
const MARGIN: f64 = 10.0;
/// Longest shadow a building's height is chosen to cast (horizontal), metres.
const MAX_SHADOW_M: f64 = 60.0;
/// A silent gross error is an unflagged roof off by more than this many cells.
const GROSS_CELLS: f64 = 2.0;
/// Scenes rendered and ingested at once (POV-Ray runs one thread each).
const WORKERS: usize = 2;

/// FNV-1a of a label: the seed of a setting's layouts.
fn seed(label: &str, layout: usize) -> u64 {
    let mut h: u64 = 0xcbf29ce484222325;
    for b in label.bytes().chain(std::iter::once(layout as u8)) {
        h = (h ^ b as u64).wrapping_mul(0x100000001b3);
    }
    h
}

/// `x` moved by `ulps` units in the last place (positive `x`).
fn ulps(x: f64, ulps: i64) -> f64 {
    f64::from_bits((x.to_bits() as i64 + ulps) as u64)
}

/// One row of the table.
#[derive(Debug, Clone)]
struct Setting {
    sweep: &'static str,
    /// Sun azimuth, degrees, and how it is written (`45° + 2 ulp`).
    az: f64,
    az_label: String,
    elev: f64,
    cell: f64,
    slope: bool,
    rotated: bool,
}

impl Setting {
    fn ground(&self) -> &'static str {
        if self.slope {
            "15–20 % slope"
        } else {
            "flat"
        }
    }
    fn footprints(&self) -> &'static str {
        if self.rotated {
            "rotated"
        } else {
            "axis-aligned"
        }
    }
    fn label(&self) -> String {
        format!(
            "{} · az {} · el {}° · {} m · {} · {}",
            self.sweep,
            self.az_label,
            self.elev,
            self.cell,
            self.ground(),
            self.footprints()
        )
    }
    /// An exact grid diagonal (45°, 135°, …).
    fn diagonal(&self) -> bool {
        self.az % 90.0 == 45.0
    }
    /// An exact grid axis.
    fn axis(&self) -> bool {
        self.az % 90.0 == 0.0
    }
    /// A few ulps off an axis or a diagonal.
    fn near_ulps(&self) -> bool {
        !self.diagonal() && !self.axis() && ((self.az / 45.0).round() * 45.0 - self.az).abs() < 1e-9
    }
}

fn az_label(az: f64) -> String {
    let near = (az / 45.0).round() * 45.0;
    if az == near || (az - near).abs() > 1e-9 {
        format!("{az}°")
    } else {
        let d = az.to_bits() as i64 - near.to_bits() as i64;
        format!("{near}° {} {} ulp", if d > 0 { "+" } else { "−" }, d.abs())
    }
}

/// The settings of both sweeps; `quick` keeps a subset.
fn settings(quick: bool) -> Vec<Setting> {
    let mut v = Vec::new();
    let mut azimuths: Vec<f64> = (0..24).map(|k| 15.0 * k as f64).collect();
    for (a, d) in [
        (45.0, 2),
        (45.0, -2),
        (90.0, 2),
        (90.0, -2),
        (135.0, 2),
        (180.0, -2),
        (270.0, 2),
        (315.0, -2),
    ] {
        azimuths.push(ulps(a, d));
    }
    azimuths.sort_by(f64::total_cmp);
    for &az in &azimuths {
        if quick && (az / 45.0).round() * 45.0 != az && !(az > 44.0 && az < 46.0) {
            // quick: the exact axes and diagonals, and 45° ± 2 ulp.
            continue;
        }
        for slope in [false, true] {
            for rotated in [false, true] {
                v.push(Setting {
                    sweep: "azimuth",
                    az,
                    az_label: az_label(az),
                    elev: 40.0,
                    cell: 0.5,
                    slope,
                    rotated,
                });
            }
        }
    }
    let (elevs, cells, azs): (&[f64], &[f64], &[f64]) = if quick {
        (&[8.0, 30.0, 80.0], &[0.25, 0.5, 1.0], &[135.0])
    } else {
        (
            &[8.0, 15.0, 30.0, 45.0, 60.0, 80.0],
            &[0.25, 0.5, 1.0],
            &[135.0, 270.0, 200.0],
        )
    };
    for &elev in elevs {
        for &cell in cells {
            for &az in azs {
                for slope in [false, true] {
                    for rotated in [false, true] {
                        v.push(Setting {
                            sweep: "elevation",
                            az,
                            az_label: az_label(az),
                            elev,
                            cell,
                            slope,
                            rotated,
                        });
                    }
                }
            }
        }
    }
    v
}

/// Layout `k` of setting `s`.
fn scene(s: &Setting, k: usize) -> Scene {
    let mut rng = Rng(seed(&s.label(), k));
    let tan_e = s.elev.to_radians().tan();
    let (sa, ca) = s.az.to_radians().sin_cos();
    let u = (-sa, -ca); // shadow direction (east, north)
                        // Ground gradient (rise per metre east, north) and its rise along the shadow.
    let (grad, grade) = if s.slope {
        loop {
            let g = rng.range(0.15, 0.20);
            let phi = rng.range(0.0, std::f64::consts::TAU);
            let grad = (g * phi.cos(), g * phi.sin());
            if tan_e + grad.0 * u.0 + grad.1 * u.1 >= 0.5 * tan_e {
                break (grad, g);
            }
        }
    } else {
        ((0.0, 0.0), 0.0)
    };
    let per_m = 1.0 / (tan_e + grad.0 * u.0 + grad.1 * u.1); // shadow metres per metre of wall
    let h_max = (MAX_SHADOW_M / per_m).clamp(6.0, 25.0);
    // Buildings relative to their own centres: sides, rotation, height, colour; and the box
    // (min, max) around the footprint and its longest possible shadow.
    struct Draft {
        size: (f64, f64),
        rot: f64,
        h: f64,
        colour: [f64; 3],
        lo: (f64, f64),
        hi: (f64, f64),
    }
    let drafts: Vec<Draft> = (0..SLOTS * SLOTS)
        .map(|_| {
            let size = (rng.range(8.0, 25.0), rng.range(8.0, 25.0));
            let rot = if s.rotated { rng.range(0.0, 90.0) } else { 0.0 };
            let h = rng.range(6.0, h_max);
            let base = match (rng.next() * 3.0) as usize {
                0 => [0.45, 0.45, 0.43], // grey
                1 => [0.50, 0.17, 0.11], // red tiles
                _ => [0.10, 0.10, 0.11], // dark (tar, slate)
            };
            let j = rng.range(-0.04, 0.04);
            let colour = base.map(|c: f64| (c + j).max(0.02));
            // The wall stands at most h + grade · diagonal above the ground at its foot; the
            // box holds the footprint's corners and their shadows at that reach.
            let reach = (h + grade * size.0.hypot(size.1)) * per_m;
            let at_origin = Building {
                centre: (0.0, 0.0),
                size,
                rotation_deg: rot,
                roof: Roof::Flat { z: h },
                colour,
            };
            let (mut lo, mut hi) = (
                (f64::INFINITY, f64::INFINITY),
                (f64::NEG_INFINITY, f64::NEG_INFINITY),
            );
            for (x, y) in at_origin.corners() {
                for (px, py) in [(x, y), (x + u.0 * reach, y + u.1 * reach)] {
                    lo = (lo.0.min(px), lo.1.min(py));
                    hi = (hi.0.max(px), hi.1.max(py));
                }
            }
            Draft {
                size,
                rot,
                h,
                colour,
                lo,
                hi,
            }
        })
        .collect();
    let slot = drafts
        .iter()
        .map(|d| (d.hi.0 - d.lo.0).max(d.hi.1 - d.lo.1))
        .fold(0.0, f64::max)
        + 2.0 * MARGIN;
    let extent = slot * SLOTS as f64;
    let size = (extent / s.cell).ceil() as usize;
    let origin = (500_000.0, 5_300_000.0 + size as f64 * s.cell);
    let z0 = 250.0;
    let ground = |p: (f64, f64)| z0 + grad.0 * (p.0 - origin.0) + grad.1 * (p.1 - origin.1);
    let buildings = drafts
        .iter()
        .enumerate()
        .map(|(i, d)| {
            // Slot (column, row) from the north-west corner; the box anywhere inside it with
            // MARGIN to spare.
            let (col, row) = ((i % SLOTS) as f64, (i / SLOTS) as f64);
            let (w, h) = (d.hi.0 - d.lo.0, d.hi.1 - d.lo.1);
            let x0 = origin.0 + col * slot + MARGIN + rng.next() * (slot - 2.0 * MARGIN - w);
            let y1 = origin.1 - row * slot - MARGIN - rng.next() * (slot - 2.0 * MARGIN - h);
            let centre = (x0 - d.lo.0, y1 - d.hi.1);
            let mut b = Building {
                centre,
                size: d.size,
                rotation_deg: d.rot,
                roof: Roof::Flat { z: 0.0 },
                colour: d.colour,
            };
            let top = b
                .corners()
                .iter()
                .map(|&p| ground(p))
                .fold(f64::NEG_INFINITY, f64::max);
            b.roof = Roof::Flat { z: top + d.h };
            b
        })
        .collect();
    Scene {
        origin,
        cell: s.cell,
        size: (size, size),
        ground: (z0, grad.0, grad.1),
        sun_azimuth_deg: s.az,
        sun_elevation_deg: s.elev,
        buildings,
        clutter: vec![],
        footprint_shift: (0.0, 0.0),
        camera: Camera::Ortho,
        antialias: povray::antialias_for(s.elev),
    }
}

/// Outcomes of one row, pooled over its layouts.
#[derive(Default, Clone)]
struct Stats {
    buildings: usize,
    measured: usize,
    unflagged: usize,
    /// Σ error² of unflagged roofs, metres² and cells².
    sq_m: f64,
    sq_cells: f64,
    /// Worst unflagged |error|, cells.
    worst_cells: f64,
    gross: usize,
    flagged_or_null: usize,
    /// Flagged, measured and within one cell: right heights a flag warns against.
    flagged_right: usize,
    /// Flagged (or null) and measured more than 2 cells off: wrong heights the flag caught.
    flagged_wrong: usize,
    /// Measured buildings with a reported 95 % interval, and those whose truth lies outside
    /// the 68 % and the 95 % interval.
    with_interval: usize,
    outside_68: usize,
    outside_95: usize,
    /// Scenes whose render or dbms run failed (their buildings count as null).
    failed_scenes: usize,
    /// `dbms shadow-height` wall clock, seconds.
    secs: f64,
    /// Scenes, and POV-Ray's wall clock over them (render, DEM and footprints), seconds.
    scenes: usize,
    render_secs: f64,
    /// Scenes where dbms reported the footprint shift it applied (`footprint_shift_m`; the
    /// truth is none), those where it is over one cell, and the largest, cells.
    shift_scenes: usize,
    shift_off: usize,
    worst_shift_cells: f64,
}

impl Stats {
    fn add(&mut self, o: &Stats) {
        self.buildings += o.buildings;
        self.measured += o.measured;
        self.unflagged += o.unflagged;
        self.sq_m += o.sq_m;
        self.sq_cells += o.sq_cells;
        self.worst_cells = self.worst_cells.max(o.worst_cells);
        self.gross += o.gross;
        self.flagged_or_null += o.flagged_or_null;
        self.flagged_right += o.flagged_right;
        self.flagged_wrong += o.flagged_wrong;
        self.with_interval += o.with_interval;
        self.outside_68 += o.outside_68;
        self.outside_95 += o.outside_95;
        self.failed_scenes += o.failed_scenes;
        self.secs += o.secs;
        self.scenes += o.scenes;
        self.render_secs += o.render_secs;
        self.shift_scenes += o.shift_scenes;
        self.shift_off += o.shift_off;
        self.worst_shift_cells = self.worst_shift_cells.max(o.worst_shift_cells);
    }
    fn rmse_m(&self) -> String {
        rms(self.sq_m, self.unflagged)
    }
    fn rmse_cells(&self) -> String {
        rms(self.sq_cells, self.unflagged)
    }
    /// Truth outside the 68 % and the 95 % intervals, % of the measured buildings with one.
    fn outside(&self) -> (String, String) {
        let pc = |k: usize| match self.with_interval {
            0 => "–".to_string(),
            n => format!("{:.1}", 100.0 * k as f64 / n as f64),
        };
        (pc(self.outside_68), pc(self.outside_95))
    }
}

/// A `[low, high]` property of an outcome (a roof interval), if present.
fn interval(o: &Outcome, key: &str) -> Option<(f64, f64)> {
    let v = o.properties.get(key)?.as_array()?;
    Some((v.first()?.as_f64()?, v.get(1)?.as_f64()?))
}

fn rms(sq: f64, n: usize) -> String {
    if n == 0 {
        "–".into()
    } else {
        format!("{:.2}", (sq / n as f64).sqrt())
    }
}

/// A silent gross error, for the list.
struct Gross {
    setting: String,
    layout: usize,
    building: usize,
    truth: f64,
    measured: f64,
    cell: f64,
    flags: Vec<String>,
    properties: String,
    dir: PathBuf,
}

/// What one scene gave.
struct SceneResult {
    setting: usize,
    layout: usize,
    outcomes: Result<Vec<Outcome>, String>,
    secs: f64,
    render_secs: f64,
    dir: PathBuf,
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let quick = args.iter().any(|a| a == "quick");
    let keep = args.iter().any(|a| a == "keep");
    // Any other argument (cargo passes `--bench`) not starting with `-`: only the settings
    // whose label contains it, e.g. `"el 8° ·"` or `"az 135° · el 80°"`.
    let filters: Vec<&String> = args
        .iter()
        .filter(|a| !a.starts_with('-') && *a != "quick" && *a != "keep")
        .collect();
    // Options for `dbms shadow-height` (`--max-shift=0`): every argument starting with `--` but
    // cargo's `--bench`.
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
    let settings: Vec<Setting> = settings(quick)
        .into_iter()
        .filter(|s| filters.iter().all(|f| s.label().contains(f.as_str())))
        .collect();
    let layouts = |s: &Setting| match (quick, s.cell < 0.5) {
        (true, _) => 1,
        (false, true) => LAYOUTS_FINE,
        (false, false) => LAYOUTS,
    };
    let jobs: Vec<(usize, usize)> = settings
        .iter()
        .enumerate()
        .flat_map(|(i, s)| (0..layouts(s)).map(move |k| (i, k)))
        .collect();
    let root =
        std::env::temp_dir().join(format!("dbms-shadow-height-povray-{}", std::process::id()));
    eprintln!(
        "{} settings, {} scenes, {} buildings; scenes under {}",
        settings.len(),
        jobs.len(),
        jobs.len() * SLOTS * SLOTS,
        root.display()
    );
    // What is measured: the commit, and whether the tree differs from it where the binary
    // comes from (read at run time: rebuild and run without editing in between).
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
    // Batches: render and ingest WORKERS × 2 scenes on WORKERS threads, then time
    // `dbms shadow-height` on each alone.
    for (b, batch) in jobs.chunks(WORKERS * 2).enumerate() {
        let next = AtomicUsize::new(0);
        let prepared = Mutex::new(Vec::new());
        std::thread::scope(|sc| {
            for _ in 0..WORKERS {
                sc.spawn(|| loop {
                    let i = next.fetch_add(1, Ordering::Relaxed);
                    let Some(&(s, k)) = batch.get(i) else { break };
                    let sc = scene(&settings[s], k);
                    let dir = root.join(format!("{s:03}-{k}"));
                    let p = prepare_scene(&sc, &dir);
                    prepared.lock().unwrap().push((i, sc, dir, p));
                });
            }
        });
        let mut prepared = prepared.into_inner().unwrap();
        prepared.sort_by_key(|p| p.0);
        for (i, sc, dir, p) in prepared {
            let (s, k) = batch[i];
            let (outcomes, secs, render_secs) = match p {
                Ok(p) => match measure_prepared_with(&sc, &p, &extra) {
                    Ok((o, t)) => (Ok(o), t, p.render_secs),
                    Err(e) => (Err(e), 0.0, p.render_secs),
                },
                Err(e) => (Err(e), 0.0, 0.0),
            };
            results.push(SceneResult {
                setting: s,
                layout: k,
                outcomes,
                secs,
                render_secs,
                dir,
            });
        }
        if b % 10 == 9 {
            eprintln!(
                "{} / {} scenes, {:.0} s",
                results.len(),
                jobs.len(),
                started.elapsed().as_secs_f64()
            );
        }
    }
    let wall = started.elapsed().as_secs_f64();

    // Rows.
    let mut rows: Vec<Stats> = vec![Stats::default(); settings.len()];
    let mut gross = Vec::new();
    let mut failures = Vec::new();
    // Buildings carrying each flag, per sun elevation (the flags that matter depend on it).
    let mut flag_counts: Vec<((u32, String), usize)> = Vec::new();
    let mut render_secs = 0.0;
    let mut tsv: Vec<String> = Vec::new();
    for r in &results {
        let st = &mut rows[r.setting];
        let set = &settings[r.setting];
        st.secs += r.secs;
        st.scenes += 1;
        st.render_secs += r.render_secs;
        render_secs += r.render_secs;
        let mut keep_dir = keep;
        match &r.outcomes {
            Err(e) => {
                st.failed_scenes += 1;
                st.buildings += SLOTS * SLOTS;
                st.flagged_or_null += SLOTS * SLOTS;
                failures.push(format!("{} · layout {}: {e}", set.label(), r.layout));
                keep_dir = true;
            }
            Ok(out) => {
                let shift = out.iter().find_map(|o| {
                    let v = o.properties.get("footprint_shift_m")?.as_array()?;
                    Some(v.first()?.as_f64()?.hypot(v.get(1)?.as_f64()?))
                });
                if let Some(d) = shift {
                    st.shift_scenes += 1;
                    st.shift_off += (d > set.cell) as usize;
                    st.worst_shift_cells = st.worst_shift_cells.max(d / set.cell);
                }
                for (j, o) in out.iter().enumerate() {
                    st.buildings += 1;
                    for f in &o.flags {
                        let key = (set.elev as u32, f.clone());
                        match flag_counts.iter_mut().find(|(k, _)| *k == key) {
                            Some((_, c)) => *c += 1,
                            None => flag_counts.push((key, 1)),
                        }
                    }
                    let flagged = o.flagged() || o.roof_z.is_none();
                    st.flagged_or_null += flagged as usize;
                    let Some(e) = o.error_m() else { continue };
                    st.measured += 1;
                    let (i68, i95) = (
                        interval(o, "roof_z_interval_68"),
                        interval(o, "roof_z_interval_95"),
                    );
                    if let (Some(a), Some(b)) = (i68, i95) {
                        let out = |(lo, hi): (f64, f64)| o.truth_z < lo || o.truth_z > hi;
                        st.with_interval += 1;
                        st.outside_68 += out(a) as usize;
                        st.outside_95 += out(b) as usize;
                        // One line a building for calibrating the intervals (docs/shadow-height.md,
                        // "Heights with their uncertainty").
                        tsv.push(format!(
                            "{}\t{}\t{}\t{}\t{:.4}\t{:.4}\t{:.4}\t{:.4}\t{:.4}\t{:.4}\t{}",
                            set.label(),
                            set.cell,
                            set.elev,
                            j,
                            o.truth_z,
                            o.roof_z.unwrap(),
                            a.0,
                            a.1,
                            b.0,
                            b.1,
                            o.flags.join(",")
                        ));
                    }
                    let ec = e.abs() / set.cell;
                    if flagged {
                        st.flagged_right += (ec <= 1.0) as usize;
                        st.flagged_wrong += (ec > GROSS_CELLS) as usize;
                        continue;
                    }
                    st.unflagged += 1;
                    st.sq_m += e * e;
                    st.sq_cells += ec * ec;
                    st.worst_cells = st.worst_cells.max(ec);
                    if ec > GROSS_CELLS {
                        st.gross += 1;
                        keep_dir = true;
                        gross.push(Gross {
                            setting: set.label(),
                            layout: r.layout,
                            building: j,
                            truth: o.truth_z,
                            measured: o.roof_z.unwrap(),
                            cell: set.cell,
                            flags: o.flags.clone(),
                            properties: o.properties.to_string(),
                            dir: r.dir.clone(),
                        });
                    }
                }
            }
        }
        if !keep_dir {
            let _ = std::fs::remove_dir_all(&r.dir);
        }
    }

    println!(
        "| sweep | sun azimuth | sun elevation | cell m | ground | footprints | buildings | measured | unflagged | RMSE m | RMSE cells | worst cells | silent gross | flagged or null | ms / building |"
    );
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    for (s, st) in settings.iter().zip(&rows) {
        println!(
            "| {} | {} | {}° | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {} | {:.0} |",
            s.sweep,
            s.az_label,
            s.elev,
            s.cell,
            s.ground(),
            s.footprints(),
            st.buildings,
            st.measured,
            st.unflagged,
            st.rmse_m(),
            st.rmse_cells(),
            if st.unflagged == 0 {
                "–".into()
            } else {
                format!("{:.2}", st.worst_cells)
            },
            if st.gross > 0 {
                format!("**{}**", st.gross)
            } else {
                "0".into()
            },
            st.flagged_or_null,
            1000.0 * st.secs / st.buildings.max(1) as f64
        );
    }

    // Summaries by group.
    type Pick = Box<dyn Fn(&Setting) -> bool>;
    let mut groups: Vec<(String, Pick)> = vec![
        ("all rows".into(), Box::new(|_| true)),
        ("azimuth sweep".into(), Box::new(|s| s.sweep == "azimuth")),
        (
            "elevation sweep".into(),
            Box::new(|s| s.sweep == "elevation"),
        ),
        (
            "exact diagonals (45°, 135°, …)".into(),
            Box::new(|s| s.diagonal()),
        ),
        ("exact axes (0°, 90°, …)".into(), Box::new(|s| s.axis())),
        (
            "2 ulps off an axis or diagonal".into(),
            Box::new(|s| s.near_ulps()),
        ),
        (
            "other azimuths".into(),
            Box::new(|s| !s.diagonal() && !s.axis() && !s.near_ulps()),
        ),
        ("flat ground".into(), Box::new(|s| !s.slope)),
        ("15–20 % slope".into(), Box::new(|s| s.slope)),
        ("axis-aligned footprints".into(), Box::new(|s| !s.rotated)),
        ("rotated footprints".into(), Box::new(|s| s.rotated)),
    ];
    for e in [8.0, 15.0, 30.0, 40.0, 45.0, 60.0, 80.0] {
        groups.push((
            format!("sun elevation {e}°"),
            Box::new(move |s: &Setting| s.elev == e),
        ));
    }
    for c in [0.25, 0.5, 1.0] {
        groups.push((
            format!("cell {c} m"),
            Box::new(move |s: &Setting| s.cell == c),
        ));
    }
    println!("\nSummary by group (errors in cells of each row; RMSE over unflagged roofs):\n");
    println!("| group | rows | buildings | silent gross | unflagged RMSE cells | worst row RMSE cells | worst unflagged cells | flagged or null | flagged or null % | flagged, within 1 cell | flagged, > 2 cells off | truth outside 68 % / 95 % interval, % | scenes shifted > 1 cell | ms / building | POV-Ray s / scene |");
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    for (name, pick) in &groups {
        let mut t = Stats::default();
        let (mut n, mut worst_row) = (0, 0.0f64);
        for (s, st) in settings.iter().zip(&rows) {
            if pick(s) {
                n += 1;
                t.add(st);
                if st.unflagged > 0 {
                    worst_row = worst_row.max((st.sq_cells / st.unflagged as f64).sqrt());
                }
            }
        }
        if n == 0 {
            continue;
        }
        let (o68, o95) = t.outside();
        println!(
            "| {name} | {n} | {} | {} | {} | {worst_row:.2} | {:.2} | {} | {:.1} | {} | {} | {o68} / {o95} | {} | {:.0} | {:.1} |",
            t.buildings,
            t.gross,
            t.rmse_cells(),
            t.worst_cells,
            t.flagged_or_null,
            100.0 * t.flagged_or_null as f64 / t.buildings.max(1) as f64,
            t.flagged_right,
            t.flagged_wrong,
            if t.shift_scenes == 0 {
                "–".to_string()
            } else {
                format!(
                    "{} / {} (worst {:.1})",
                    t.shift_off, t.shift_scenes, t.worst_shift_cells
                )
            },
            1000.0 * t.secs / t.buildings.max(1) as f64,
            t.render_secs / t.scenes.max(1) as f64
        );
    }

    flag_counts.sort();
    println!("\nFlags seen, by sun elevation (buildings carrying each):\n");
    println!("| sun elevation | buildings | flags |");
    println!("|---|---|---|");
    let mut elevs: Vec<u32> = settings.iter().map(|s| s.elev as u32).collect();
    elevs.sort();
    elevs.dedup();
    for e in elevs {
        let n: usize = settings
            .iter()
            .zip(&rows)
            .filter(|(s, _)| s.elev as u32 == e)
            .map(|(_, st)| st.buildings)
            .sum();
        let seen: Vec<String> = flag_counts
            .iter()
            .filter(|((el, _), _)| *el == e)
            .map(|((_, f), c)| format!("{f} {c}"))
            .collect();
        println!(
            "| {e}° | {n} | {} |",
            if seen.is_empty() {
                "none".to_string()
            } else {
                seen.join(", ")
            }
        );
    }

    println!(
        "\nSilent gross errors (unflagged, |error| > {GROSS_CELLS} cells): {}\n",
        gross.len()
    );
    if !gross.is_empty() {
        println!("| setting | layout | building | truth roof m | measured m | error m | error cells | flags | scene | properties |");
        println!("|---|---|---|---|---|---|---|---|---|---|");
        for g in &gross {
            let e = g.measured - g.truth;
            println!(
                "| {} | {} | {} | {:.2} | {:.2} | {:+.2} | {:+.2} | {} | {} | `{}` |",
                g.setting,
                g.layout,
                g.building,
                g.truth,
                g.measured,
                e,
                e / g.cell,
                if g.flags.is_empty() {
                    "none".into()
                } else {
                    g.flags.join(", ")
                },
                g.dir.display(),
                g.properties
            );
        }
    }
    if !failures.is_empty() {
        println!("\nFailed scenes ({}):\n", failures.len());
        for f in &failures {
            println!("* {f}");
        }
    }
    let tsv_path = root.with_extension("tsv");
    tsv.insert(
        0,
        "setting\tcell\televation\tbuilding\ttruth\troof_z\tlo68\thi68\tlo95\thi95\tflags".into(),
    );
    match std::fs::write(&tsv_path, tsv.join("\n") + "\n") {
        Ok(()) => println!(
            "\nEvery measured building's interval: {}",
            tsv_path.display()
        ),
        Err(e) => eprintln!("{}: {e}", tsv_path.display()),
    }
    let measure_secs: f64 = rows.iter().map(|r| r.secs).sum();
    println!(
        "\n{} scenes, {} buildings; wall clock {wall:.0} s ({WORKERS} scenes rendered at a time: POV-Ray {render_secs:.0} s summed over scenes; `dbms shadow-height` {measure_secs:.0} s, run alone)",
        results.len(),
        results.len() * SLOTS * SLOTS
    );
    println!(
        "commit {commit}{}; {threads} hardware threads; {}",
        if dirty.is_empty() {
            String::new()
        } else {
            format!(
                " with uncommitted changes to {}",
                dirty
                    .lines()
                    .map(|l| l.get(3..).unwrap_or(l))
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        },
        if quick { "quick" } else { "full run" }
    );
    if !extra.is_empty() {
        println!("dbms shadow-height options: {}", extra.join(" "));
    }
    if !keep && gross.is_empty() && failures.is_empty() {
        let _ = std::fs::remove_dir_all(&root);
    } else {
        println!("scenes kept under {}", root.display());
    }
}
