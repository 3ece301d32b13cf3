//! Benchmark: what accuracy costs in `dbms export mesh` — triangles, bytes and time against the
//! vertical error bound, and how far a render of the mesh is from a render of the voxel tiles.
//!
//! `cargo bench --bench mesh` (work directory from `DBMS_BENCH_DIR`, default a temporary one;
//! with `DBMS_BENCH_PNG=DIR`, every render is also written there as a PNG). One run:
//! 1. the sample's database and tile set (`support/sample.rs`, untimed);
//! 2. two fixed low-altitude views of the tile set rendered with [`render_view`] without range
//!    thresholds, so every pixel comes from level 0;
//! 3. for each error bound: the export (timed, the 1-minute load average beside it), its
//!    triangles and bytes, level 0's measured vertical error; then every `tiles/0/*.glb` read
//!    back with [`read_glb`] (what was written, not what was meant) into one mesh, rendered
//!    through the same two views with [`render_mesh`] (the tile renderer's rays), and compared
//!    pixel by pixel: RMS range difference where both hit, and the same with each difference
//!    times the sine of the ray's depression (about the vertical difference on level ground, to
//!    set beside the bound), the share of pixels one hits and the other misses, RMS colour
//!    difference (0–255, over channels) where both hit.
//!
//! Prints a Markdown table for docs/mesh.md.

#[allow(dead_code)] // this bench needs only the load average
#[path = "support/files.rs"]
mod files;
#[path = "support/sample.rs"]
mod sample;

use dbms::db::Database;
use dbms::mesh::export::{export_mesh, MeshOptions};
use dbms::mesh::gltf::read_glb;
use dbms::mesh::tileset::content_origins;
use dbms::mesh::Part;
use dbms::progress::Progress;
use dbms::render::mesh::{render_mesh, MeshFrame, MeshScene};
use dbms::render::{render_view, Attitude, Frame, ViewOptions, Viewpoint};
use dbms::tiles::TileReader;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Vertical error bounds of level 0, metres (0: every cell centre kept).
const BOUNDS: [f64; 8] = [0.0, 0.02, 0.05, 0.1, 0.25, 0.5, 1.0, 2.0];

fn main() {
    let tmp = tempfile::tempdir().expect("temp dir");
    let work = std::env::var("DBMS_BENCH_DIR")
        .map(PathBuf::from)
        .unwrap_or_else(|_| tmp.path().to_path_buf());
    std::fs::create_dir_all(&work).expect("work dir");
    let png_dir = std::env::var("DBMS_BENCH_PNG").ok().map(PathBuf::from);
    println!("threads: {}", rayon::current_num_threads());

    let tiles = sample::sample_tiles(&work);
    let db = Database::open(&work.join("db")).expect("open the sample database");
    let reader = TileReader::open(&tiles, 1024).expect("open tiles");
    let views = views(&reader);
    let opts = ViewOptions {
        lod: false,
        ..ViewOptions::default()
    };
    let voxel: Vec<Frame> = views
        .iter()
        .map(|v| render_view(&reader, v, &opts).expect("render the tiles"))
        .collect();
    for (k, f) in voxel.iter().enumerate() {
        save(
            &png_dir,
            &format!("tiles-view{k}.png"),
            f.png().expect("png"),
        );
    }

    println!("\n| bound (m) | level-0 triangles | all triangles | bytes | export (s) | load | level-0 max error (m) | level-0 RMS error (m) | RMS range difference (m) | same, × sin depression (m) | hit in one only | RMS colour difference |");
    println!("|---|---|---|---|---|---|---|---|---|---|---|---|");
    for bound in BOUNDS {
        let out = work.join(format!("mesh-{bound}"));
        if out.exists() {
            std::fs::remove_dir_all(&out).expect("remove an old export");
        }
        let options = MeshOptions {
            max_error_m: bound,
            ..MeshOptions::default()
        };
        let load = files::loadavg();
        let t = Instant::now();
        let summary = export_mesh(&db, &out, &options, &Progress::hidden()).expect("export");
        let seconds = t.elapsed().as_secs_f64();
        let level0 = &summary.levels[0];
        let all: u64 = summary.levels.iter().map(|l| l.triangles).sum();

        let finest = MeshScene::of_parts(&finest_level(&out));
        let mut diff = Difference::default();
        for (k, (view, tiles)) in views.iter().zip(&voxel).enumerate() {
            let mesh = render_mesh(&finest, view).expect("render the mesh");
            save(
                &png_dir,
                &format!("mesh-{bound}-view{k}.png"),
                mesh.png().expect("png"),
            );
            diff.add(view, tiles, &mesh);
        }
        println!(
            "| {bound} | {} | {all} | {} | {seconds:.1} | {load:.1} | {:.3} | {:.4} | {:.3} | {:.4} | {:.2} % | {:.1} |",
            level0.triangles,
            summary.bytes,
            level0.max_error_m,
            level0.rms_error_m,
            diff.rms_range(),
            diff.rms_vertical(),
            100.0 * diff.one_only as f64 / diff.pixels as f64,
            diff.rms_colour(),
        );
    }
}

/// Two fixed low-altitude views of the sample, 640 × 480 with a 60° field of view: across the
/// scene 25 m over the ground, pitched 4° down (as `benches/render.rs` flies), and down a slope
/// 40 m over it, pitched 25° down.
fn views(reader: &TileReader) -> Vec<Viewpoint> {
    let g = &reader.info().grid;
    let view = |fx: f64, fy: f64, above: f64, pitch: f64, yaw: f64| {
        let (col, row) = (
            (g.width as f64 * fx) as usize,
            (g.height as f64 * fy) as usize,
        );
        let ground = reader
            .cell(0, col, row)
            .expect("read")
            .map(|c| c.max_z)
            .filter(|z| !z.is_nan())
            .expect("ground under the eye");
        let (x, y) = g
            .transform
            .pixel_to_world(col as f64 + 0.5, row as f64 + 0.5);
        Viewpoint {
            eye: [x, y, ground as f64 + above],
            attitude: Attitude {
                roll: 0.0,
                pitch,
                yaw,
            },
            hfov: 60.0,
            width: 640,
            height: 480,
        }
    };
    vec![
        view(0.1, 0.77, 25.0, -4.0, 30.0),
        view(0.6, 0.3, 40.0, -25.0, 200.0),
    ]
}

/// Every level-0 tile of the export in `dir`, read back: the parts of all of them (world
/// coordinates: each tile's origin added back).
fn finest_level(dir: &Path) -> Vec<Part> {
    let tileset: serde_json::Value = serde_json::from_slice(
        &std::fs::read(dir.join("tileset.json")).expect("read tileset.json"),
    )
    .expect("tileset.json is JSON");
    let mut parts = Vec::new();
    for (uri, origin) in content_origins(&tileset) {
        if uri.starts_with("tiles/0/") {
            let bytes = std::fs::read(dir.join(&uri)).expect("read a tile");
            parts.extend(read_glb(&bytes, origin).expect("a glTF binary"));
        }
    }
    parts
}

/// Pixel differences between tile and mesh renders, summed over views.
#[derive(Default)]
struct Difference {
    pixels: u64,
    /// Pixels both renders hit, the sum of their squared range differences (m²) and of their
    /// squared colour differences over the three channels.
    both: u64,
    range_sq: f64,
    /// Squared range differences times the squared sine of the ray's depression, m².
    vertical_sq: f64,
    colour_sq: f64,
    /// Pixels one render hits and the other misses.
    one_only: u64,
}

impl Difference {
    fn add(&mut self, view: &Viewpoint, tiles: &Frame, mesh: &MeshFrame) {
        let basis = view.basis();
        for k in 0..tiles.range.len() {
            self.pixels += 1;
            let (a, b) = (tiles.range[k], mesh.range[k]);
            match (a.is_finite(), b.is_finite()) {
                (true, true) => {
                    self.both += 1;
                    let d =
                        basis.through((k % view.width) as f64 + 0.5, (k / view.width) as f64 + 0.5);
                    let sin_sq = d[2] * d[2] / (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
                    let range_sq = (a as f64 - b as f64).powi(2);
                    self.range_sq += range_sq;
                    self.vertical_sq += range_sq * sin_sq;
                    self.colour_sq += (0..3)
                        .map(|c| (tiles.rgb[k][c] as f64 - mesh.rgb[k][c] as f64).powi(2))
                        .sum::<f64>();
                }
                (false, false) => {}
                _ => self.one_only += 1,
            }
        }
    }

    fn rms_range(&self) -> f64 {
        (self.range_sq / self.both as f64).sqrt()
    }

    fn rms_vertical(&self) -> f64 {
        (self.vertical_sq / self.both as f64).sqrt()
    }

    fn rms_colour(&self) -> f64 {
        (self.colour_sq / (3 * self.both) as f64).sqrt()
    }
}

/// Write `bytes` as `name` under `dir`, when one is given.
fn save(dir: &Option<PathBuf>, name: &str, bytes: Vec<u8>) {
    if let Some(dir) = dir {
        std::fs::create_dir_all(dir).expect("PNG directory");
        std::fs::write(dir.join(name), bytes).expect("write a PNG");
    }
}
