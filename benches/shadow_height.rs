//! Accuracy and cost of `dbms shadow-height` on generated scenes with known heights.
//!
//! Scenes (`dbms::shadow_height::synth`): flat ground and 20 % slopes facing the sun (shadows
//! fall uphill) and facing away (downhill); sun elevation 15°..75°; cells 0.25..2 m; one
//! isolated building, or one with a neighbour 2 m beside it. Buildings are rotated rectangles,
//! 10–20 m sides, 6–25 m high (lower on the downhill slope at a low sun, where the shadow would
//! run for hundreds of metres), random azimuth; the photo (exact prism shadows) is rendered
//! 2 × 2 finer and averaged.
//! Prints one table row per case: RMSE and worst error of the first estimate (`L·tan e`) and
//! of the refined height, in metres and in cells, and the time per building.
//!
//! `cargo bench --bench shadow_height` (all cases) or `-- quick` (0.5 m cells only).

use dbms::shadow::Sun;
use dbms::shadow_height::synth::{synth_scene, SynthBuilding, SynthSpec};
use dbms::shadow_height::{measure, Inputs, Options};
use std::time::Instant;

const TRIALS: usize = 4;

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
    missing: usize,
    secs: f64,
}

fn main() {
    let quick = std::env::args().any(|a| a == "quick");
    let cells: &[f64] = if quick {
        &[0.5]
    } else {
        &[0.25, 0.5, 1.0, 2.0]
    };
    println!("| layout | ground | sun elev | cell m | n | first RMSE m | first worst m | refined RMSE m | refined worst m | refined RMSE / cell | no height | ms / building |");
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|");
    let mut worst_isolated: f64 = 0.0;
    for layout in ["isolated", "adjacent"] {
        for ground in ["flat", "20% facing sun", "20% facing away"] {
            for elev in [15.0, 30.0, 45.0, 60.0, 75.0] {
                for &cell in cells {
                    let s = case(layout, ground, elev, cell);
                    let n = s.n.max(1) as f64;
                    let rmse = (s.sq / n).sqrt();
                    if layout == "isolated" {
                        worst_isolated = worst_isolated.max(rmse / cell);
                    }
                    println!(
                        "| {layout} | {ground} | {elev:.0}° | {cell} | {} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {} | {:.1} |",
                        s.n,
                        (s.sq0 / n).sqrt(),
                        s.max0,
                        rmse,
                        s.max,
                        rmse / cell,
                        s.missing,
                        1000.0 * s.secs / (s.n + s.missing).max(1) as f64
                    );
                }
            }
        }
    }
    println!("\nworst refined RMSE on isolated buildings: {worst_isolated:.2} cells (goal ≤ 1)");
}

fn case(layout: &str, ground: &str, elev: f64, cell: f64) -> Stats {
    let mut rng = Rng(((elev * 1000.0) as u64)
        ^ ((cell * 100.0) as u64) << 20
        ^ (ground.len() as u64) << 40
        ^ layout.len() as u64);
    let tan_e = elev.to_radians().tan();
    let mut st = Stats::default();
    for _ in 0..TRIALS {
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
        let extent = 2.0 * (h * per_m + 40.0);
        let size = (extent / cell).ceil() as usize;
        let c = extent / 2.0;
        // Centre the building on the sun side so its shadow fits.
        let centre = (c - u.0 * h * per_m / 2.0, c - u.1 * h * per_m / 2.0);
        let rot = rng.range(0.0, 90.0);
        let mut buildings = vec![SynthBuilding {
            centre,
            size: (a, b),
            rotation_deg: rot,
            height_m: h,
        }];
        if layout == "adjacent" {
            // Beside it, across the shadow direction, 2 m apart.
            let n = (-u.1, u.0);
            let off = a.hypot(b) / 2.0 + 2.0 + 6.0;
            buildings.push(SynthBuilding {
                centre: (centre.0 + n.0 * off, centre.1 + n.1 * off),
                size: (10.0, 10.0),
                rotation_deg: rot,
                height_m: rng.range(6.0, 25.0).min(120.0 / per_m),
            });
        }
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
        };
        let t = Instant::now();
        let out = measure(&inputs, &scene.footprints, &sun, &Options::default()).unwrap();
        st.secs += t.elapsed().as_secs_f64();
        for (m, truth) in out.iter().zip(&scene.height_m) {
            match m
                .as_ref()
                .ok()
                .and_then(|m| Some((m.initial_height_m?, m.height_m?)))
            {
                Some((z0, z)) => {
                    st.n += 1;
                    st.sq0 += (z0 - truth).powi(2);
                    st.max0 = st.max0.max((z0 - truth).abs());
                    st.sq += (z - truth).powi(2);
                    st.max = st.max.max((z - truth).abs());
                }
                None => st.missing += 1,
            }
        }
    }
    st
}
