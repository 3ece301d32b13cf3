//! What accuracy costs in time, knob by knob, for `dbms shadow-height` on POV-Ray orthophotos
//! (independent truth: tests/support/povray.rs).
//!
//! The scenes are rendered once; each knob setting then runs `dbms shadow-height` on all of
//! them, the other knobs at their defaults. Per setting: buildings, how many are flagged or
//! refused, RMSE and worst error of the unflagged roofs (metres and cells), silent gross errors
//! (unflagged, over two cells) and the wall clock per building (the whole command, ms).
//! Knobs: `--line-spacing` (scan-line spacing, cells), `--sub-points` (refinement points per
//! cell side), `--max-shift` (registration search, metres; on scenes whose footprints are
//! 2 m off), `--max-height` (search window and refinement range, metres).
//!
//! `cargo bench --bench shadow_height_knobs` (needs `povray` on PATH).

#[path = "../tests/support/povray.rs"]
mod povray;
#[path = "../tests/support/shadow_truth.rs"]
mod shadow_truth;

use povray::{isolated_layout, Camera, Scene};
use shadow_truth::{measure_prepared_with, prepare_scene, Prepared};

/// 16 isolated buildings on a 4 × 4 layout 60 m apart, 0.5 m cells, flat or sloped ground.
/// One scene: seed, sun azimuth and elevation (degrees), ground plane `(z0, gx, gy)` and the
/// footprints' shift (metres), the arguments of [`scene`].
type Spec = (u64, f64, f64, (f64, f64, f64), (f64, f64));

fn scene(seed: u64, az: f64, el: f64, ground: (f64, f64, f64), shift: (f64, f64)) -> Scene {
    let origin = (500_000.0, 5_300_260.0);
    Scene {
        origin,
        cell: 0.5,
        size: (520, 520),
        ground,
        sun_azimuth_deg: az,
        sun_elevation_deg: el,
        buildings: isolated_layout(seed, 4, 14.0, true, ground, origin),
        clutter: vec![],
        footprint_shift: shift,
        camera: Camera::Ortho,
        antialias: povray::antialias_for(el),
    }
}

fn main() {
    if std::process::Command::new("povray")
        .arg("--version")
        .output()
        .is_err()
    {
        eprintln!("povray is not on PATH (apt-get install povray)");
        return;
    }
    let root = tempfile::tempdir().unwrap();
    let specs = [
        (1, 135.0, 40.0, (250.0, 0.0, 0.0), (0.0, 0.0)),
        (2, 200.0, 25.0, (250.0, 0.08, -0.15), (0.0, 0.0)),
        (3, 100.0, 60.0, (250.0, 0.0, 0.0), (0.0, 0.0)),
    ];
    let shifted = [(4, 160.0, 40.0, (250.0, 0.0, 0.0), (1.6, -1.2))];
    let prep = |list: &[Spec]| -> Vec<(Scene, Prepared)> {
        list.iter()
            .map(|&(seed, az, el, g, sh)| {
                let s = scene(seed, az, el, g, sh);
                let p = prepare_scene(&s, &root.path().join(format!("s{seed}"))).unwrap();
                (s, p)
            })
            .collect()
    };
    let plain = prep(&specs);
    let off = prep(&shifted);
    println!("| knob | setting | scenes | buildings | flagged or null | unflagged RMSE m (cells) | worst unflagged, cells | silent > 2 cells | ms / building |");
    println!("|---|---|---|---|---|---|---|---|---|");
    let knobs = [
        ("--line-spacing", vec!["2", "1", "0.5", "0.25"], &plain[..]),
        ("--sub-points", vec!["1", "2", "4", "8"], &plain[..]),
        ("--max-height", vec!["40", "150", "400"], &plain[..]),
        ("--max-shift", vec!["0", "1", "3", "6"], &off[..]),
    ];
    for (knob, values, scenes) in knobs {
        for v in values {
            let (mut n, mut flagged, mut silent, mut sq, mut k, mut worst, mut secs) =
                (0, 0, 0, 0.0, 0, 0.0f64, 0.0);
            for (s, p) in scenes {
                let (out, t) = measure_prepared_with(s, p, &[format!("{knob}={v}")]).unwrap();
                secs += t;
                for o in &out {
                    n += 1;
                    if o.flagged() || o.roof_z.is_none() {
                        flagged += 1;
                        continue;
                    }
                    let e = o.error_m().unwrap();
                    silent += (e.abs() > 2.0 * s.cell) as usize;
                    worst = worst.max(e.abs() / s.cell);
                    sq += e * e;
                    k += 1;
                }
            }
            let rmse = (sq / k.max(1) as f64).sqrt();
            println!(
                "| `{knob}` | {v} | {} | {n} | {flagged} | {rmse:.3} ({:.2}) | {worst:.2} | {silent} | {:.0} |",
                scenes.len(),
                rmse / 0.5,
                1000.0 * secs / n as f64
            );
        }
    }
}
