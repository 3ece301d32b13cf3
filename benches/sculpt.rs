//! Carving accuracy and cost: the four benchmark solids rendered to silhouettes from 3
//! orthographic, 8 and 24 pinhole views, carved at 64³, 128³ and 256³ voxels.
//!
//! Prints a Markdown table: IoU against the true solid and against the exact (pixel-free)
//! visual hull, voxel count, hierarchical and dense carve times and the speedup, and checks that
//! the hierarchical carver's output equals the dense carver's bit for bit (exits non-zero if not).
//! A second table times the colour pass (visibility by ray casting through the carved volume).
//! Run: `cargo bench --bench sculpt` (add `-- quick` for 64³ and 128³ only).

use dbms::testing::solids::{benchmark_solids, exact_hull, render, voxelize, BENCHMARK_NAMES};
use dbms::voxel::camera::Camera;
use dbms::voxel::carve::{carve, carve_dense, CarveOptions, View};
use dbms::voxel::colour::colour;
use dbms::voxel::grid::VoxelGrid;
use dbms::voxel::picture::Picture;
use std::time::Instant;

/// Image size of every view, pixels.
const IMAGE: u32 = 512;

fn ortho3() -> Vec<Camera> {
    let s = IMAGE as f64 / 2.4;
    let c = IMAGE as f64 / 2.0;
    vec![
        Camera::orthographic([0.0, 0.0, -1.0], Some([0.0, 1.0, 0.0]), s, [0.0; 3], c, c).unwrap(),
        Camera::orthographic([0.0, 1.0, 0.0], None, s, [0.0; 3], c, c).unwrap(),
        Camera::orthographic([-1.0, 0.0, 0.0], None, s, [0.0; 3], c, c).unwrap(),
    ]
}

/// Rings of 8 pinhole cameras 4 m from the centre at the given elevations (degrees).
fn rings(elevations: &[f64]) -> Vec<Camera> {
    let f = IMAGE as f64 * 1.1;
    let c = IMAGE as f64 / 2.0;
    elevations
        .iter()
        .enumerate()
        .flat_map(|(k, &e)| {
            (0..8).map(move |i| {
                let az = (i as f64 + k as f64 / 3.0) * std::f64::consts::TAU / 8.0;
                let e = e.to_radians();
                let pos = [
                    4.0 * e.cos() * az.cos(),
                    4.0 * e.cos() * az.sin(),
                    4.0 * e.sin(),
                ];
                Camera::look_at(f, f, c, c, pos, [0.0; 3], None).unwrap()
            })
        })
        .collect()
}

fn main() {
    let quick = std::env::args().any(|a| a == "quick");
    let sizes: &[u32] = if quick { &[64, 128] } else { &[64, 128, 256] };
    let setups: Vec<(&str, Vec<Camera>)> = vec![
        ("3 ortho", ortho3()),
        ("8 pinhole", rings(&[20.0])),
        ("24 pinhole", rings(&[-15.0, 20.0, 55.0])),
    ];
    let opts = CarveOptions::default();
    println!(
        "Images {IMAGE}×{IMAGE}; box [-1, 1]³ m; {} rayon threads.\n",
        rayon::current_num_threads()
    );
    println!("| solid | views | voxels³ | IoU truth | IoU exact hull | voxels kept | hierarchical ms | dense ms | speedup | equal |");
    println!("|---|---|---|---|---|---|---|---|---|---|");
    let mut all_equal = true;
    for (solid, name) in benchmark_solids().iter().zip(BENCHMARK_NAMES) {
        for (setup, cams) in &setups {
            let views: Vec<View> = cams
                .iter()
                .map(|c| View {
                    camera: c.clone(),
                    silhouette: render(solid, c, IMAGE, IMAGE),
                })
                .collect();
            let sized: Vec<(Camera, u32, u32)> =
                cams.iter().map(|c| (c.clone(), IMAGE, IMAGE)).collect();
            for &n in sizes {
                let grid = VoxelGrid::covering([-1.0; 3], [1.0; 3], 2.0 / n as f64).unwrap();
                // Best of three for the fast carver, one run of the slow one.
                let mut hier_ms = f64::INFINITY;
                let mut hier = None;
                for _ in 0..3 {
                    let t = Instant::now();
                    let h = carve(&grid, &views, &opts).unwrap();
                    hier_ms = hier_ms.min(t.elapsed().as_secs_f64() * 1e3);
                    hier = Some(h);
                }
                let hier = hier.unwrap();
                let t = Instant::now();
                let dense = carve_dense(&grid, &views, &opts).unwrap();
                let dense_ms = t.elapsed().as_secs_f64() * 1e3;
                let equal = hier == dense;
                all_equal &= equal;
                let truth = voxelize(solid, &grid);
                let hull = exact_hull(solid, &sized, &grid, &opts);
                println!(
                    "| {name} | {setup} | {n} | {:.4} | {:.4} | {} | {hier_ms:.1} | {dense_ms:.1} | {:.1}× | {} |",
                    hier.iou(&truth),
                    hier.iou(&hull),
                    hier.count(),
                    dense_ms / hier_ms,
                    if equal { "yes" } else { "NO" }
                );
            }
        }
    }
    println!("\n| solid | views | voxels³ | surface voxels | seen | unseen | colour ms |");
    println!("|---|---|---|---|---|---|---|");
    for (solid, name) in benchmark_solids()
        .iter()
        .zip(BENCHMARK_NAMES)
        .filter(|(_, n)| ["sphere", "L-block"].contains(n))
    {
        for (setup, cams) in setups.iter().skip(1) {
            let views: Vec<View> = cams
                .iter()
                .map(|c| View {
                    camera: c.clone(),
                    silhouette: render(solid, c, IMAGE, IMAGE),
                })
                .collect();
            // Each view paints the object in its own colour.
            let images: Vec<Picture> = (0..views.len())
                .map(|i| Picture {
                    width: IMAGE,
                    height: IMAGE,
                    pixels: vec![
                        [(i * 10) as u8, 255 - (i * 10) as u8, 128, 255];
                        (IMAGE * IMAGE) as usize
                    ],
                })
                .collect();
            for &n in sizes.iter().skip(1) {
                let grid = VoxelGrid::covering([-1.0; 3], [1.0; 3], 2.0 / n as f64).unwrap();
                let occ = carve(&grid, &views, &opts).unwrap();
                let t = Instant::now();
                let (_, stats) = colour(grid, occ, &views, &images, [128; 3]);
                let ms = t.elapsed().as_secs_f64() * 1e3;
                println!(
                    "| {name} | {setup} | {n} | {} | {} | {} | {ms:.0} |",
                    stats.surface, stats.seen, stats.unseen
                );
            }
        }
    }
    if !all_equal {
        eprintln!("hierarchical and dense carvers differ");
        std::process::exit(1);
    }
}
