//! Accuracy and cost of `dbms shadow-height` on generated scenes with known heights.
//!
//! Scenes (`dbms::testing::shadow_scene`): flat ground and 20 % slopes facing the sun (shadows
//! fall uphill) and facing away (downhill); sun elevation 15°..75°; cells 0.25..2 m. Layouts:
//! * `isolated`: one building;
//! * `adjacent`: the same building with a 10 m × 10 m neighbour beside it, across the shadow
//!   direction, at least 0.9 m apart (its shadow runs parallel to the building's and never
//!   meets it);
//! * `down-sun`: the same building (A) with a neighbour (B) in its shadow path: B stands on the
//!   shadow side along the sun azimuth, the gap between the two footprints' extents along the
//!   shadow direction uniform in [`GAP_MIN`, `GAP_MAX`] × A's nominal shadow length
//!   (`h / (tan e + grade)`, grade +0.2 facing the sun, −0.2 facing away), so A's shadow always
//!   reaches B's footprint; B's centre is offset across the shadow direction by up to
//!   ± [`LATERAL_MAX`] × A's width across it, and B has its own size (10–20 m sides), rotation
//!   and height. Where B is lower than A's shadow there, A's shadow runs over B's roof and on
//!   behind B, merged with B's own shadow. A and B are scored in separate rows (`down-sun A`,
//!   `down-sun B`); [`TRIALS_DOWN_SUN`] scenes per case, with [`MARGIN_DOWN_SUN`] of lit ground.
//!
//! Buildings are rotated rectangles, 10–20 m sides, 6–25 m high (lower on the downhill slope at
//! a low sun, where the shadow would run for hundreds of metres), random azimuth; the photo
//! (exact prism shadows on the ground; roofs are never darkened) is rendered 2 × 2 finer and
//! averaged. Seeded: `down-sun` trial k's first building (A) is `isolated` trial k's (and so is
//! `adjacent`'s in the first trial).
//! Prints one table row per case: RMSE and worst error of the first estimate (`L·tan e`) and of
//! the refined height, in metres and in cells, how many heights are null and how many measured
//! ones carry a neighbour or cut flag, and the time per building; then every null height and
//! every refined error over one cell, with its flags.
//!
//! `cargo bench --bench shadow_height` (all cases) or `-- quick` (0.5 m cells only).

use dbms::shadow_height::{measure, Inputs, Measurement, Options};
use dbms::sun::Sun;
use dbms::testing::shadow_scene::{synth_scene, SynthBuilding, SynthSpec};
use std::time::Instant;

const TRIALS: usize = 4;
/// Trials per down-sun case (two buildings each; fewer, to bound the run time: its scenes
/// are larger).
const TRIALS_DOWN_SUN: usize = 3;
/// Down-sun: lit ground kept beyond the shadows (and before the first building), metres.
const MARGIN_DOWN_SUN: f64 = 20.0;
/// Down-sun gap, as a fraction of the first building's nominal shadow length: lower bound.
const GAP_MIN: f64 = 0.2;
/// See [`GAP_MIN`]: upper bound (< 1, so the shadow reaches the neighbour).
const GAP_MAX: f64 = 0.9;
/// Down-sun lateral offset of the neighbour's centre, as a fraction of A's width across the
/// shadow direction (either side).
const LATERAL_MAX: f64 = 0.25;

/// A deterministic stream of numbers in [0, 1).
struct Rng(u64);
impl Rng {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
    fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next()
    }
}

#[derive(Default)]
struct Stats {
    n: usize,
    sq0: f64,
    max0: f64,
    sq: f64,
    max: f64,
    /// Null heights.
    missing: usize,
    /// Measured heights carrying `shadow_on_other_building`, `shadow_cut_by_edge_or_nodata` or
    /// `no_shadow`.
    flagged: usize,
    /// Squared refined errors in cells, summed (for totals over rows): measured with a flag,
    /// without.
    sq_cells: (f64, f64),
    /// Measured with a refined error over one cell: (all, without a flag).
    over_cell: (usize, usize),
}

impl Stats {
    fn add(&mut self, o: &Stats) {
        self.n += o.n;
        self.sq0 += o.sq0;
        self.max0 = self.max0.max(o.max0);
        self.sq += o.sq;
        self.max = self.max.max(o.max);
        self.missing += o.missing;
        self.flagged += o.flagged;
        self.sq_cells.0 += o.sq_cells.0;
        self.sq_cells.1 += o.sq_cells.1;
        self.over_cell.0 += o.over_cell.0;
        self.over_cell.1 += o.over_cell.1;
    }
}

/// One building worth listing: null, or refined error over one cell.
struct Note {
    row: String,
    truth: f64,
    first: Option<f64>,
    refined: Option<f64>,
    cell: f64,
    lines: (usize, usize),
    shadow_m: Option<f64>,
    flags: Vec<&'static str>,
    gap_m: Option<f64>,
}

/// One case: the stats per scored role (row label), the time in `measure` and the number of
/// buildings measured.
struct Case {
    roles: Vec<(&'static str, Stats)>,
    secs: f64,
    buildings: usize,
}

fn main() {
    let quick = std::env::args().any(|a| a == "quick");
    let cells: &[f64] = if quick {
        &[0.5]
    } else {
        &[0.25, 0.5, 1.0, 2.0]
    };
    println!("| layout | ground | sun elev | cell m | n | first RMSE m | first worst m | refined RMSE m | refined worst m | refined RMSE / cell | no height | flagged, measured | ms / building |");
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|---|");
    let mut worst_isolated: f64 = 0.0;
    let mut notes = Vec::new();
    let mut totals: Vec<(&'static str, Stats)> = Vec::new();
    let started = Instant::now();
    let mut layout_secs = Vec::new();
    for layout in ["isolated", "adjacent", "down-sun"] {
        let layout_start = Instant::now();
        for ground in ["flat", "20% facing sun", "20% facing away"] {
            for elev in [15.0, 30.0, 45.0, 60.0, 75.0] {
                for &cell in cells {
                    let c = case(layout, ground, elev, cell, &mut notes);
                    for (role, s) in &c.roles {
                        let n = s.n.max(1) as f64;
                        let rmse = (s.sq / n).sqrt();
                        if *role == "isolated" {
                            worst_isolated = worst_isolated.max(rmse / cell);
                        }
                        println!(
                            "| {role} | {ground} | {elev:.0}° | {cell} | {} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {} | {} | {:.1} |",
                            s.n,
                            (s.sq0 / n).sqrt(),
                            s.max0,
                            rmse,
                            s.max,
                            rmse / cell,
                            s.missing,
                            s.flagged,
                            1000.0 * c.secs / c.buildings.max(1) as f64
                        );
                        match totals.iter_mut().find(|(r, _)| r == role) {
                            Some((_, t)) => t.add(s),
                            None => {
                                let mut t = Stats::default();
                                t.add(s);
                                totals.push((role, t));
                            }
                        }
                    }
                }
            }
        }
        layout_secs.push(format!(
            "{layout} {:.1} s",
            layout_start.elapsed().as_secs_f64()
        ));
    }
    let wall = started.elapsed().as_secs_f64();
    println!("\nworst refined RMSE on isolated buildings: {worst_isolated:.2} cells (goal ≤ 1)");
    println!("\nTotals over all rows (errors in cells of each row):\n");
    println!("| layout | buildings | null | measured | flagged, measured | refined RMSE / cell, measured | … flagged | … unflagged | over one cell | over one cell, unflagged |");
    println!("|---|---|---|---|---|---|---|---|---|---|");
    for (role, t) in &totals {
        let rms = |sq: f64, n: usize| {
            if n == 0 {
                "–".to_string()
            } else {
                format!("{:.2}", (sq / n as f64).sqrt())
            }
        };
        println!(
            "| {role} | {} | {} | {} | {} | {} | {} | {} | {} | {} |",
            t.n + t.missing,
            t.missing,
            t.n,
            t.flagged,
            rms(t.sq_cells.0 + t.sq_cells.1, t.n),
            rms(t.sq_cells.0, t.flagged),
            rms(t.sq_cells.1, t.n - t.flagged),
            t.over_cell.0,
            t.over_cell.1
        );
    }
    println!("\nNull heights and refined errors over one cell (L: measured shadow length; gap: down-sun, between the footprints' extents along the shadow; m):\n");
    println!("| case | truth m | first m | refined m | error m | error / cell | lines used / cast | L m | gap m | flags |");
    println!("|---|---|---|---|---|---|---|---|---|---|");
    let f = |v: Option<f64>| v.map_or("null".to_string(), |v| format!("{v:.2}"));
    for n in &notes {
        let err = n.refined.map(|z| z - n.truth);
        println!(
            "| {} | {:.2} | {} | {} | {} | {} | {} / {} | {} | {} | {} |",
            n.row,
            n.truth,
            f(n.first),
            f(n.refined),
            err.map_or("–".to_string(), |e| format!("{e:+.2}")),
            err.map_or("–".to_string(), |e| format!("{:+.2}", e / n.cell)),
            n.lines.0,
            n.lines.1,
            f(n.shadow_m),
            n.gap_m.map_or("–".to_string(), |g| format!("{g:.1}")),
            if n.flags.is_empty() {
                "**none**".to_string()
            } else {
                n.flags.join(", ")
            }
        );
    }
    println!(
        "\nwall clock, all cases: {wall:.1} s ({})",
        layout_secs.join(", ")
    );
}

/// Half the extent of a `size` rectangle rotated by `rot_deg` along the unit vector `v`.
fn half_extent(size: (f64, f64), rot_deg: f64, v: (f64, f64)) -> f64 {
    let (s, c) = rot_deg.to_radians().sin_cos();
    size.0 / 2.0 * (v.0 * c + v.1 * s).abs() + size.1 / 2.0 * (-v.0 * s + v.1 * c).abs()
}

fn case(layout: &str, ground: &str, elev: f64, cell: f64, notes: &mut Vec<Note>) -> Case {
    // Same seed for every layout ("isolated", "adjacent" and "down-sun" all have 8 letters);
    // the down-sun neighbours draw from a stream of their own, so down-sun trial k's first
    // building is isolated trial k's.
    let seed = ((elev * 1000.0) as u64)
        ^ ((cell * 100.0) as u64) << 20
        ^ (ground.len() as u64) << 40
        ^ layout.len() as u64;
    let mut rng = Rng(seed);
    let mut rng_b = Rng(seed ^ 0x5EED_0000_0000_D05E);
    let tan_e = elev.to_radians().tan();
    let roles: &[&'static str] = match layout {
        "isolated" => &["isolated"],
        "adjacent" => &["adjacent"],
        _ => &["down-sun A", "down-sun B"],
    };
    let mut stats: Vec<Stats> = roles.iter().map(|_| Stats::default()).collect();
    let (mut secs, mut measured) = (0.0, 0);
    let trials = if layout == "down-sun" {
        TRIALS_DOWN_SUN
    } else {
        TRIALS
    };
    for _ in 0..trials {
        let az = rng.range(0.0, 360.0);
        let sun = Sun::new(elev, az).unwrap();
        let (dx, dy) = sun.direction();
        let u = (-dx, -dy); // shadow direction
        let grade = match ground {
            "flat" => 0.0,
            "20% facing sun" => 0.2,
            _ => -0.2,
        };
        // Horizontal shadow length per metre of height on this slope; keep shadows ≤ 120 m.
        let per_m = 1.0 / (tan_e + grade);
        let h = rng.range(6.0, 25.0).min(120.0 / per_m);
        let (a, b) = (rng.range(10.0, 20.0), rng.range(10.0, 20.0));
        let mut extent = 2.0 * (h * per_m + 40.0);
        // Offset of the first building's centre from the scene centre, along the shadow.
        let mut back = h * per_m / 2.0;
        let rot = rng.range(0.0, 90.0);
        let mut rel = vec![((0.0, 0.0), (a, b), rot, h)];
        let mut gap_m = None;
        if layout == "adjacent" {
            // Beside it, across the shadow direction: its centre 8 m beyond the circle around the
            // first one, so at least 0.9 m apart.
            let n = (-u.1, u.0);
            let off = a.hypot(b) / 2.0 + 2.0 + 6.0;
            let h2 = rng.range(6.0, 25.0).min(120.0 / per_m);
            rel.push(((n.0 * off, n.1 * off), (10.0, 10.0), rot, h2));
        } else if layout == "down-sun" {
            // In the shadow path: the footprints' extents along u are `gap` apart.
            let n = (-u.1, u.0);
            let (a2, b2) = (rng_b.range(10.0, 20.0), rng_b.range(10.0, 20.0));
            let rot2 = rng_b.range(0.0, 90.0);
            let h2 = rng_b.range(6.0, 25.0).min(120.0 / per_m);
            let gap = rng_b.range(GAP_MIN, GAP_MAX) * h * per_m;
            let lat = rng_b.range(-LATERAL_MAX, LATERAL_MAX) * 2.0 * half_extent((a, b), rot, n);
            let (ea, eb) = (half_extent((a, b), rot, u), half_extent((a2, b2), rot2, u));
            let along = ea + gap + eb;
            rel.push((
                (u.0 * along + n.0 * lat, u.1 * along + n.1 * lat),
                (a2, b2),
                rot2,
                h2,
            ));
            // From A's sun side to the end of the longer of A's shadow and B's. On the downhill
            // slope the wall on the shadow side stands higher than the height above the highest
            // ground by the drop across the footprint.
            let far = |h: f64, e: f64| (h + (-grade).max(0.0) * 2.0 * e) * per_m;
            let chain = ea + (ea + far(h, ea)).max(along + eb + far(h2, eb));
            extent = chain + 2.0 * MARGIN_DOWN_SUN;
            back = chain / 2.0 - ea;
            gap_m = Some(gap);
        }
        let size = (extent / cell).ceil() as usize;
        let c = extent / 2.0;
        // Centre the first building on the sun side so the shadows fit.
        let centre = (c - u.0 * back, c - u.1 * back);
        let buildings: Vec<SynthBuilding> = rel
            .iter()
            .map(|&(o, size, rotation_deg, height_m)| SynthBuilding {
                centre: (centre.0 + o.0, centre.1 + o.1),
                size,
                rotation_deg,
                height_m,
            })
            .collect();
        let spec = SynthSpec {
            cell,
            size: (size, size),
            slope: (grade * u.0, grade * u.1),
            sun,
            buildings,
            supersample: 2,
        };
        let scene = synth_scene(&spec);
        let inputs = Inputs {
            terrain: &scene.terrain,
            colour: &scene.colour,
            mask: None,
            leans: None,
        };
        let t = Instant::now();
        let out = measure(&inputs, &scene.footprints, &sun, &Options::default()).unwrap();
        secs += t.elapsed().as_secs_f64();
        measured += out.len();
        for (k, (m, truth)) in out.iter().zip(&scene.height_m).enumerate() {
            let m: &Measurement = m.as_ref().expect("generated footprints are valid");
            // Isolated and adjacent rows pool every building; down-sun scores A and B apart.
            let role = k.min(stats.len() - 1);
            let st = &mut stats[role];
            let flags = m.flags.names();
            let flagged = m.flags.shadow_on_other_building
                || m.flags.shadow_cut_by_edge_or_nodata
                || m.flags.no_shadow;
            let note = |refined| Note {
                row: format!("{} · {ground} · {elev:.0}° · {cell} m", roles[role]),
                truth: *truth,
                first: m.initial_height_m,
                refined,
                cell,
                lines: (m.lines_used, m.lines_total),
                shadow_m: m.shadow_length_m,
                flags: flags.clone(),
                gap_m,
            };
            match (m.initial_height_m, m.height_m) {
                (Some(z0), Some(z)) => {
                    let e = (z - truth).abs();
                    st.n += 1;
                    st.sq0 += (z0 - truth).powi(2);
                    st.max0 = st.max0.max((z0 - truth).abs());
                    st.sq += e.powi(2);
                    st.max = st.max.max(e);
                    if flagged {
                        st.sq_cells.0 += (e / cell).powi(2);
                    } else {
                        st.sq_cells.1 += (e / cell).powi(2);
                    }
                    st.flagged += flagged as usize;
                    if e > cell {
                        st.over_cell.0 += 1;
                        st.over_cell.1 += !flagged as usize;
                        notes.push(note(Some(z)));
                    }
                }
                _ => {
                    st.missing += 1;
                    notes.push(note(None));
                }
            }
        }
    }
    Case {
        roles: roles.iter().copied().zip(stats).collect(),
        secs,
        buildings: measured,
    }
}
