//! Whole images judged against a reference nobody here stepped: smooth terrain must render
//! smooth.
//!
//! The reference ray-casts the *continuous* analytic surface the tile set samples (sphere
//! tracing with the surface's slope bound, no grid walk, no tile page), 4 × 4 stratified rays per
//! pixel, and colours each hit with the tile set's colour of the cell under it. A renderer that
//! darkens the stair steps of a sampled slope as if they were walls covers a smooth slope in
//! rings of dark speckle; the high-frequency energy of its image is then several times the
//! reference's.

use super::*;

/// Grid side, cells of 1 m; the grid's north-west corner is at `(0, SIDE)`.
const SIDE: usize = 512;

/// A smooth scene: height (metres) at world `(x, y)`, and a bound on its slope.
struct Relief {
    z: fn(f64, f64) -> f64,
    max_slope: f64,
}

const PLANE: Relief = Relief {
    z: |x, y| 0.3 * x + 0.12 * y,
    max_slope: 0.33,
};

const HILLS: Relief = Relief {
    z: |x, y| 12.0 * (x / 41.0).sin() * (y / 53.0).cos() + 0.05 * x,
    max_slope: 0.42,
};

/// Colour of cell `(col, row)`: slowly varying, so a correct image of it is smooth.
fn colour(col: usize, row: usize) -> [u8; 4] {
    let (x, y) = (col as f64, row as f64);
    [
        (110.0 + 40.0 * (x / 37.0).sin()) as u8,
        (140.0 + 30.0 * (y / 29.0).cos()) as u8,
        (90.0 + 20.0 * ((x + y) / 61.0).sin()) as u8,
        255,
    ]
}

fn tile_set(relief: &Relief) -> (tempfile::TempDir, TileReader) {
    let z = relief.z;
    super::tests::tiles(0.0, SIDE as f64, SIDE, SIDE, 64, 4, |c, r| {
        let (x, y) = (c as f64 + 0.5, SIDE as f64 - r as f64 - 0.5);
        (z(x, y) as f32, colour(c, r))
    })
}

/// The reference image: 4 × 4 stratified rays per pixel, each sphere-traced against the
/// continuous surface (a step never exceeds the gap over the largest rate at which the slope
/// bound lets it close), coloured by the cell under the hit, the sky where it leaves the grid.
fn reference(relief: &Relief, camera: &Viewpoint) -> Vec<[f64; 3]> {
    let basis = camera.basis();
    let [ex, ey, ez] = camera.eye;
    let side = SIDE as f64;
    let trace = |d: [f64; 3]| -> [f64; 3] {
        let horizontal = d[0].hypot(d[1]);
        let closing = relief.max_slope * horizontal - d[2];
        let mut t = 0.0;
        loop {
            let (x, y) = (ex + t * d[0], ey + t * d[1]);
            if !(0.0..side).contains(&x) || !(0.0..side).contains(&y) || closing <= 0.0 {
                return sky::sky(d[2]).map(f64::from);
            }
            let gap = ez + t * d[2] - (relief.z)(x, y);
            if gap < 1e-3 {
                let c = colour(x.floor() as usize, (side - y).floor() as usize);
                return [c[0], c[1], c[2]].map(f64::from);
            }
            t += gap / closing;
        }
    };
    let n = 4;
    (0..camera.width * camera.height)
        .into_par_iter()
        .map(|p| {
            let (i, j) = (p % camera.width, p / camera.width);
            let mut sum = [0.0; 3];
            for a in 0..n {
                for b in 0..n {
                    let d = basis.direction_at(
                        i as f64 + (a as f64 + 0.5) / n as f64,
                        j as f64 + (b as f64 + 0.5) / n as f64,
                    );
                    let c = trace(d);
                    (0..3).for_each(|k| sum[k] += c[k]);
                }
            }
            sum.map(|s| s / (n * n) as f64)
        })
        .collect()
}

/// Mean absolute Laplacian of the luma over the interior pixels: the image's high-frequency
/// energy, grey levels.
fn high_frequency(rgb: &[[f64; 3]], width: usize, height: usize) -> f64 {
    let luma: Vec<f64> = rgb
        .iter()
        .map(|c| 0.299 * c[0] + 0.587 * c[1] + 0.114 * c[2])
        .collect();
    let mut sum = 0.0;
    for j in 1..height - 1 {
        for i in 1..width - 1 {
            let k = j * width + i;
            sum += (4.0 * luma[k] - luma[k - 1] - luma[k + 1] - luma[k - width] - luma[k + width])
                .abs();
        }
    }
    sum / ((width - 2) * (height - 2)) as f64
}

#[test]
fn smooth_slopes_render_as_smoothly_as_a_supersampled_trace_of_the_continuous_surface() {
    for (name, relief) in [("plane", PLANE), ("hills", HILLS)] {
        let (_d, reader) = tile_set(&relief);
        let (x, y) = (60.0, 50.0);
        let camera = Viewpoint {
            eye: [x, y, (relief.z)(x, y) + 25.0],
            attitude: Attitude {
                roll: 0.0,
                pitch: -12.0,
                yaw: 40.0,
            },
            hfov: 60.0,
            width: 160,
            height: 100,
        };
        let frame = render_view(&reader, &camera, &ViewOptions::default()).unwrap();
        let rendered: Vec<[f64; 3]> = frame.rgb.iter().map(|c| c.map(f64::from)).collect();
        let got = high_frequency(&rendered, 160, 100);
        let want = high_frequency(&reference(&relief, &camera), 160, 100);
        eprintln!("{name}: rendered {got:.2}, reference {want:.2}");
        assert!(
            got < 1.5 * want + 1.0,
            "{name}: high-frequency energy {got:.2} grey levels, the reference's {want:.2}"
        );
    }
}
