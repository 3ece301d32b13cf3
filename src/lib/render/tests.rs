//! Analytic scenes for the renderer: flat planes, a single column, a step, rough terrain.

use super::*;
use crate::crs::Crs;
use crate::grid::Grid;
use crate::testing::tiles as synthetic;
use crate::tiles::Compression;
use crate::voxel::columns::Run;
use proptest::prelude::*;
use ray::Axis;
use std::sync::OnceLock;

const GREY: [u8; 4] = [120, 120, 120, 255];

/// A tile set over a `w × h` grid of 1 m cells with its north-west corner at `(x0, y0)`.
pub(super) fn tiles<F>(
    x0: f64,
    y0: f64,
    w: usize,
    h: usize,
    page: usize,
    factor: usize,
    f: F,
) -> (tempfile::TempDir, TileReader)
where
    F: Fn(usize, usize) -> (f32, [u8; 4]) + Sync,
{
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("t.dbt");
    let grid = Grid::north_up(x0, y0, 1.0, w, h, Crs::epsg(32614));
    synthetic::write_tiles(&path, grid, page, factor, Compression::None, f).unwrap();
    let reader = TileReader::open(&path, 64).unwrap();
    (dir, reader)
}

fn camera(eye: [f64; 3], roll: f64, pitch: f64, yaw: f64, w: usize, h: usize) -> Viewpoint {
    Viewpoint {
        eye,
        attitude: Attitude { roll, pitch, yaw },
        hfov: 60.0,
        width: w,
        height: h,
    }
}

fn no_lod(traversal: Traversal) -> ViewOptions {
    ViewOptions {
        traversal,
        lod: false,
        ..ViewOptions::default()
    }
}

fn centre(f: &Frame) -> usize {
    (f.height / 2) * f.width + f.width / 2
}

#[test]
fn looking_straight_down_on_a_plane_gives_height_over_cosine() {
    // 100 m up over the middle of 256 m: the corner rays (< 37° off vertical) stay inside.
    let (_d, r) = tiles(0.0, 256.0, 256, 256, 64, 4, |_, _| (10.0, GREY));
    let f = render_view(
        &r,
        &camera([128.25, 128.5, 110.0], 0.0, -90.0, 0.0, 9, 7),
        &ViewOptions::default(),
    )
    .unwrap();
    assert_eq!(f.range[centre(&f)], 100.0);
    let b = camera([0.0; 3], 0.0, -90.0, 0.0, 9, 7).basis();
    for (k, &range) in f.range.iter().enumerate() {
        let d = b.direction(k % 9, k / 9);
        assert!(
            (range as f64 - 100.0 / -d[2]).abs() < 1e-3,
            "pixel {k}: {range}"
        );
    }
    assert_eq!(f.stats.hits, 63);
    assert!(
        f.stats.reader.pages_read > 0 && f.stats.reader.bytes_read > 0 && f.stats.pages_touched > 0
    );
}

#[test]
fn looking_straight_up_sees_only_sky() {
    let (_d, r) = tiles(0.0, 64.0, 64, 64, 16, 4, |_, _| (10.0, GREY));
    let f = render_view(
        &r,
        &camera([32.0, 32.0, 20.0], 0.0, 90.0, 0.0, 8, 6),
        &ViewOptions::default(),
    )
    .unwrap();
    assert!(f.range.iter().all(|r| r.is_infinite()));
    assert_eq!(f.stats.hits, 0);
    assert!(f.rgb.iter().all(|&c| c[2] > c[0]), "blue overhead");
}

/// A plane at 0 with one 20 m column at cell (40, 30).
fn column(col: usize, row: usize) -> (f32, [u8; 4]) {
    if (col, row) == (40, 30) {
        (20.0, [255, 0, 0, 255])
    } else {
        (0.0, GREY)
    }
}

#[test]
fn ray_exactly_parallel_to_the_x_axis_hits_the_west_wall() {
    let (_d, r) = tiles(0.0, 64.0, 64, 64, 16, 4, column);
    // Row 30 spans y in (33, 34]; eye 10 m up at x = 10.5, looking due east: the centre ray has
    // no north component and enters cell 40 at x = 40.
    for t in [Traversal::Hierarchical, Traversal::Level0] {
        let f = render_view(
            &r,
            &camera([10.5, 33.5, 10.0], 0.0, 0.0, 90.0, 5, 5),
            &no_lod(t),
        )
        .unwrap();
        assert_eq!(f.range[centre(&f)], 29.5, "{t:?}");
        assert_eq!(
            f.rgb[centre(&f)],
            sky::Backdrop::Daylight.shade([255, 0, 0, 255], Face::WallU, 29.5, None)
        );
    }
}

#[test]
fn ray_exactly_parallel_to_the_y_axis_hits_the_north_wall() {
    let (_d, r) = tiles(0.0, 64.0, 64, 64, 16, 4, column);
    // Column 40 spans x in [40, 41); looking due south from row 5 toward row 30 (y = 34 edge).
    for t in [Traversal::Hierarchical, Traversal::Level0] {
        let f = render_view(
            &r,
            &camera([40.5, 60.25, 10.0], 0.0, 0.0, 180.0, 5, 5),
            &no_lod(t),
        )
        .unwrap();
        assert_eq!(f.range[centre(&f)], 26.25, "{t:?}");
        assert_eq!(
            f.rgb[centre(&f)],
            sky::Backdrop::Daylight.shade([255, 0, 0, 255], Face::WallV, 26.25, None)
        );
    }
}

#[test]
fn a_rising_ray_that_enters_a_column_below_its_top_hits_the_wall() {
    // (a 50 m tower elsewhere keeps the database's top above the column's)
    let (_d, r) = tiles(0.0, 64.0, 64, 64, 16, 4, |c, r| {
        if (c, r) == (5, 5) {
            (50.0, GREY)
        } else {
            column(c, r)
        }
    });
    // Half a metre west of the 20 m column, 19.2 m up, looking east 45° up: the ray meets the
    // wall at 19.7 m and would leave the cell over the top at 20.7 m.
    for t in [Traversal::Hierarchical, Traversal::Level0] {
        let f = render_view(
            &r,
            &camera([39.5, 33.5, 19.2], 0.0, 45.0, 90.0, 5, 5),
            &no_lod(t),
        )
        .unwrap();
        assert!(
            (f.range[centre(&f)] as f64 - 0.5 * 2f64.sqrt()).abs() < 1e-6,
            "{t:?}: {}",
            f.range[centre(&f)]
        );
    }
}

#[test]
fn eye_exactly_on_a_cell_corner() {
    let (_d, r) = tiles(0.0, 64.0, 64, 64, 16, 4, column);
    // Straight down from the corner shared by columns 39..=40 and rows 29..=30: the corner
    // touches the 20 m column, the eye is 30 m up.
    let f = render_view(
        &r,
        &camera([40.0, 34.0, 30.0], 0.0, -90.0, 0.0, 5, 5),
        &ViewOptions::default(),
    )
    .unwrap();
    assert!(f.range.iter().all(|r| r.is_finite()));
    // The vertical centre ray has no horizontal step to look into: it is in the cell whose
    // half-open span [col, col + 1) × [row, row + 1) holds the corner, column 40 / row 30, and
    // lands on its top 10 m down; the other rays reach the 0 m ground around it.
    assert_eq!(f.range[centre(&f)], 10.0);
    assert_eq!(f.rgb[centre(&f)][1], 0, "red column top");
    let b = camera([40.0, 34.0, 30.0], 0.0, -90.0, 0.0, 5, 5).basis();
    for (k, &x) in f.range.iter().enumerate().filter(|&(k, _)| k != centre(&f)) {
        let d = b.direction(k % 5, k / 5);
        assert!((x as f64 - 30.0 / -d[2]).abs() < 1e-4, "pixel {k}: {x}");
    }
    let h = render_view(
        &r,
        &camera([40.0, 34.0, 30.0], 0.0, -50.0, 45.0, 31, 23),
        &no_lod(Traversal::Hierarchical),
    )
    .unwrap();
    let l = render_view(
        &r,
        &camera([40.0, 34.0, 30.0], 0.0, -50.0, 45.0, 31, 23),
        &no_lod(Traversal::Level0),
    )
    .unwrap();
    assert_eq!(h.rgb, l.rgb);
    assert_eq!(bits(&h.range), bits(&l.range));
}

#[test]
fn a_step_is_hit_on_its_wall_then_its_top() {
    // z = 0 west of column 32, 16 m from column 32 on; eye at x = 4.5, 8 m up, looking east.
    let (_d, r) = tiles(0.0, 64.0, 64, 64, 16, 4, |c, _| {
        (if c < 32 { 0.0 } else { 16.0 }, GREY)
    });
    let f = render_view(
        &r,
        &camera([4.5, 20.5, 8.0], 0.0, 0.0, 90.0, 5, 5),
        &ViewOptions::default(),
    )
    .unwrap();
    assert_eq!(f.range[centre(&f)], 27.5);
    // Looking down at 45°, from 24 m over x = 4.5: the ray reaches z = 16 at x = 12.5 (west
    // of the step) and would reach the ground at x = 28.5, so it hits the ground there.
    let f = render_view(
        &r,
        &camera([4.5, 20.5, 24.0], 0.0, -45.0, 90.0, 5, 5),
        &ViewOptions::default(),
    )
    .unwrap();
    assert!((f.range[centre(&f)] as f64 - 24.0 * 2f64.sqrt()).abs() < 1e-4);
}

#[test]
fn eye_below_the_terrain_is_an_error() {
    let (_d, r) = tiles(0.0, 64.0, 64, 64, 16, 4, column);
    let e = render_view(
        &r,
        &camera([40.5, 33.5, 19.0], 0.0, 0.0, 0.0, 4, 4),
        &ViewOptions::default(),
    )
    .unwrap_err();
    assert!(e.to_string().contains("below the terrain"), "{e}");
    // exactly on the edge of the column counts too
    let e = render_view(
        &r,
        &camera([41.0, 33.5, 20.0], 0.0, 0.0, 0.0, 4, 4),
        &ViewOptions::default(),
    )
    .unwrap_err();
    assert!(e.to_string().contains("--eye 41,33.5,20"), "{e}");
}

#[test]
fn an_eye_in_the_wrong_crs_is_an_error_not_a_hang() {
    let (_d, r) = tiles(0.0, 64.0, 64, 64, 16, 4, column);
    let e = render_view(
        &r,
        &camera([1e300, -4.0, 10.0], 0.0, 0.0, 270.0, 4, 4),
        &ViewOptions::default(),
    )
    .unwrap_err();
    assert!(e.to_string().contains("cells from the database"), "{e}");
}

#[test]
fn eye_outside_the_database_looking_in_hits_its_edge() {
    let (_d, r) = tiles(0.0, 64.0, 64, 64, 16, 4, |_, _| (10.0, GREY));
    // 100 m west of the west edge, 5 m up (below the 10 m plane), looking east: the wall at x = 0.
    let f = render_view(
        &r,
        &camera([-100.0, 32.5, 5.0], 0.0, 0.0, 90.0, 5, 5),
        &ViewOptions::default(),
    )
    .unwrap();
    assert_eq!(f.range[centre(&f)], 100.0);
    // From above and far away, looking down at it: the top of the plane.
    let f = render_view(
        &r,
        &camera([-50.0, 32.5, 60.0], 0.0, -45.0, 90.0, 5, 5),
        &ViewOptions::default(),
    )
    .unwrap();
    assert!((f.range[centre(&f)] as f64 - 50.0 * 2f64.sqrt()).abs() < 1e-4);
    // Looking away from it: sky and haze only.
    let f = render_view(
        &r,
        &camera([-50.0, 32.5, 60.0], 0.0, -10.0, 270.0, 5, 5),
        &ViewOptions::default(),
    )
    .unwrap();
    assert_eq!(f.stats.hits, 0);
}

/// Rough terrain with sharp columns: heights from a hash of the cell.
fn rough(c: usize, r: usize) -> (f32, [u8; 4]) {
    let h = (c as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
        ^ (r as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
    let h = h ^ (h >> 29);
    let base = 8.0 * ((c as f32 * 0.07).sin() + (r as f32 * 0.05).cos());
    let spike = if h.is_multiple_of(23) {
        (h % 17) as f32
    } else {
        0.0
    };
    let z = if h.is_multiple_of(97) {
        f32::NAN
    } else {
        base + spike + (h % 5) as f32 * 0.25
    };
    (z, [(h % 251) as u8, (h >> 8) as u8, (h >> 16) as u8, 255])
}

fn bits(r: &[f32]) -> Vec<u32> {
    r.iter().map(|x| x.to_bits()).collect()
}

fn rough_tiles() -> &'static (tempfile::TempDir, TileReader) {
    static T: OnceLock<(tempfile::TempDir, TileReader)> = OnceLock::new();
    T.get_or_init(|| tiles(0.0, 150.0, 200, 150, 16, 2, rough))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]
    #[test]
    fn hierarchy_and_level0_stepping_give_identical_frames(
        x in -40.0f64..240.0, y in -40.0f64..190.0, z in 18.0f64..60.0,
        roll in -30.0f64..30.0, pitch in -89.0f64..20.0, yaw in 0.0f64..360.0, repeat in any::<bool>()
    ) {
        let (_d, r) = rough_tiles();
        let cam = camera([x, y, z], roll, pitch, yaw, 24, 18);
        let opts = |t| ViewOptions { repeat, ..no_lod(t) };
        let h = render_view(r, &cam, &opts(Traversal::Hierarchical));
        let l = render_view(r, &cam, &opts(Traversal::Level0));
        // An eye below a terrain spike (up to 33 m here) is refused by both alike.
        prop_assert_eq!(h.is_ok(), l.is_ok());
        prop_assume!(h.is_ok());
        let (h, l) = (h.unwrap(), l.unwrap());
        prop_assert_eq!(&h.rgb, &l.rgb);
        prop_assert_eq!(bits(&h.range), bits(&l.range));
    }
}

#[test]
fn hierarchy_takes_fewer_steps_than_level0() {
    let (_d, r) = rough_tiles();
    let cam = camera([10.0, 10.0, 30.0], 0.0, -8.0, 120.0, 32, 24);
    let h = render_view(r, &cam, &no_lod(Traversal::Hierarchical)).unwrap();
    let l = render_view(r, &cam, &no_lod(Traversal::Level0)).unwrap();
    assert!(
        h.stats.cells_stepped * 2 < l.stats.cells_stepped,
        "{} vs {}",
        h.stats.cells_stepped,
        l.stats.cells_stepped
    );
}

#[test]
fn utm_sized_coordinates_do_not_jitter() {
    let (x0, y0) = (512_000.0, 5_210_000.0);
    let (_a, near) = tiles(0.0, 150.0, 200, 150, 16, 2, rough);
    let (_b, utm) = tiles(x0, y0 + 150.0, 200, 150, 16, 2, rough);
    let eye = [20.25, 30.5, 30.0];
    let local = render_view(
        &near,
        &camera(eye, 3.0, -12.0, 70.0, 48, 36),
        &ViewOptions::default(),
    )
    .unwrap();
    let far = render_view(
        &utm,
        &camera([x0 + eye[0], y0 + eye[1], eye[2]], 3.0, -12.0, 70.0, 48, 36),
        &ViewOptions::default(),
    )
    .unwrap();
    assert_eq!(
        local.rgb, far.rgb,
        "dyadic eye offsets subtract exactly: same frame"
    );
    assert_eq!(bits(&local.range), bits(&far.range));
    // Moving the eye 1 cm changes ranges by about 1 cm and only pixels on silhouettes.
    let moved = render_view(
        &utm,
        &camera(
            [x0 + eye[0] + 0.01, y0 + eye[1], eye[2]],
            3.0,
            -12.0,
            70.0,
            48,
            36,
        ),
        &ViewOptions::default(),
    )
    .unwrap();
    let changed = far
        .rgb
        .iter()
        .zip(&moved.rgb)
        .filter(|(a, b)| a != b)
        .count();
    assert!(
        changed * 50 < far.rgb.len(),
        "{changed} of {} pixels changed",
        far.rgb.len()
    );
    let steady = far
        .range
        .iter()
        .zip(&moved.range)
        .filter(|(a, b)| a.is_finite() && (**a - **b).abs() <= 0.05)
        .count();
    assert!(steady * 10 > far.range.iter().filter(|a| a.is_finite()).count() * 9);
}

#[test]
fn pitch_of_89_9_degrees() {
    let (_d, r) = rough_tiles();
    for pitch in [89.9, -89.9] {
        let f = render_view(
            r,
            &camera([100.0, 75.0, 40.0], 0.0, pitch, 33.0, 16, 12),
            &ViewOptions::default(),
        )
        .unwrap();
        assert!(f.range.iter().all(|x| !x.is_nan()));
        assert_eq!(
            f.stats.hits == 0,
            pitch > 0.0,
            "up sees sky, down sees ground"
        );
        // Looking down, 0.1° off the vertical: the same frame by both traversals.
        if pitch < 0.0 {
            let cam = camera([100.0, 75.0, 40.0], 0.0, pitch, 33.0, 16, 12);
            let h = render_view(r, &cam, &no_lod(Traversal::Hierarchical)).unwrap();
            let l = render_view(r, &cam, &no_lod(Traversal::Level0)).unwrap();
            assert_eq!(bits(&h.range), bits(&l.range));
            assert_eq!(h.rgb, l.rgb);
        }
    }
}

#[test]
fn repeat_carries_the_ground_to_the_horizon() {
    let (_d, r) = tiles(0.0, 64.0, 64, 64, 16, 4, |_, _| (0.0, GREY));
    let cam = camera([32.0, 32.0, 5.0], 0.0, -5.0, 0.0, 20, 20);
    let once = render_view(&r, &cam, &ViewOptions::default()).unwrap();
    let tiled = render_view(
        &r,
        &cam,
        &ViewOptions {
            repeat: true,
            ..ViewOptions::default()
        },
    )
    .unwrap();
    let below = |f: &Frame| f.range.iter().filter(|x| x.is_finite()).count();
    assert!(below(&tiled) > below(&once));
    // every ray below the horizon that reaches the ground within 8 diagonals hits it
    let b = cam.basis();
    for (k, &x) in tiled.range.iter().enumerate() {
        let d = b.direction(k % 20, k / 20);
        let ground = 5.0 / -d[2];
        if d[2] < 0.0 && ground < REPEAT_RANGE_DIAGONALS * 64.0 * 2f64.sqrt() {
            assert!(
                (x as f64 - ground).abs() < 1e-3 * ground,
                "pixel {k}: {x} vs {ground}"
            );
        }
    }
}

/// A fine black/white checkerboard of 1 m cells, 512 m square, factor 2: every coarser level
/// averages it to grey.
fn checkerboard() -> (tempfile::TempDir, TileReader) {
    tiles(0.0, 512.0, 512, 512, 64, 2, |c, r| {
        (
            0.0,
            if (c + r) % 2 == 0 {
                [0, 0, 0, 255]
            } else {
                [255, 255, 255, 255]
            },
        )
    })
}

#[test]
fn range_threshold_is_cell_size_times_pixels_over_field_of_view() {
    // TH_1 = L · N_pix / H_fov with L = 2 m (level 1), N_pix = 64, H_fov = 60°: 122.2 m. A hit
    // takes level 1's grey only beyond it, and every hit a level-1 cell (under 3 m of a grazing
    // ray) beyond it does; a threshold off by any factor near 2 fails one of the two.
    let (_d, r) = checkerboard();
    let cam = camera([256.0, 0.5, 3.0], 0.0, -1.0, 0.0, 64, 48);
    let th1 = 2.0 * 64.0 / 60f64.to_radians();
    for traversal in [Traversal::Hierarchical, Traversal::Level0] {
        let opts = ViewOptions {
            traversal,
            ..ViewOptions::default()
        };
        let f = render_view(&r, &cam, &opts).unwrap();
        let (mut near, mut far) = (0, 0);
        for (k, &t) in f.range.iter().enumerate().filter(|(_, t)| t.is_finite()) {
            let (t, v) = (t as f64, f.rgb[k][0] as i32);
            let grey = (v - 128).abs() < 10;
            if t <= th1 {
                assert!(
                    !grey,
                    "{traversal:?} pixel {k} at {t} m is grey within TH_1 {th1}"
                );
                near += 1;
            } else if t > th1 + 3.0 {
                assert!(
                    grey,
                    "{traversal:?} pixel {k} at {t} m is {v}, past TH_1 {th1}"
                );
                far += 1;
            }
        }
        assert!(near > 100 && far > 30, "{near} {far}");
    }
}

#[test]
fn range_thresholds_use_coarse_average_colour_far_away() {
    let (_d, r) = checkerboard();
    let cam = camera([256.0, 0.5, 3.0], 0.0, -1.0, 0.0, 64, 48);
    let lod = render_view(&r, &cam, &ViewOptions::default()).unwrap();
    let far_grey = |f: &Frame| {
        (0..f.rgb.len())
            .filter(|&k| {
                f.range[k] > 200.0
                    && f.range[k].is_finite()
                    && (f.rgb[k][0] as i32 - 128).abs() < 10
            })
            .count()
    };
    let sharp = render_view(&r, &cam, &no_lod(Traversal::Hierarchical)).unwrap();
    assert!(
        far_grey(&lod) > 0 && far_grey(&sharp) == 0,
        "{} {}",
        far_grey(&lod),
        far_grey(&sharp)
    );
    // level-0 stepping with thresholds recolours far hits the same way
    let l0 = render_view(
        &r,
        &cam,
        &ViewOptions {
            traversal: Traversal::Level0,
            ..ViewOptions::default()
        },
    )
    .unwrap();
    assert!(far_grey(&l0) > 0);
    assert!(lod.stats.cells_stepped < sharp.stats.cells_stepped);
}

#[test]
fn frames_are_deterministic_and_encode() {
    let (_d, r) = rough_tiles();
    let cam = camera([5.0, 5.0, 35.0], 2.0, -15.0, 135.0, 40, 30);
    let opts = ViewOptions {
        visibility: Some(300.0),
        ..ViewOptions::default()
    };
    let a = render_view(r, &cam, &opts).unwrap();
    let b = render_view(r, &cam, &opts).unwrap();
    assert_eq!(a.png().unwrap(), b.png().unwrap());
    let dir = tempfile::tempdir().unwrap();
    a.write_range_exr(&dir.path().join("r.exr")).unwrap();
    b.write_range_exr(&dir.path().join("r2.exr")).unwrap();
    assert!(
        std::fs::read(dir.path().join("r.exr")).unwrap()
            == std::fs::read(dir.path().join("r2.exr")).unwrap()
    );
    let img = exr::prelude::read_first_flat_layer_from_file(dir.path().join("r.exr")).unwrap();
    let exr::prelude::FlatSamples::F32(z) = &img.layer_data.channel_data.list[0].sample_data else {
        panic!("f32")
    };
    assert_eq!(bits(z), bits(&a.range));
}

#[test]
fn top_view_shows_each_cell_under_its_pixel() {
    let (_d, r) = tiles(0.0, 32.0, 32, 32, 16, 4, |c, r| {
        (c as f32, [c as u8 * 8, r as u8 * 8, 0, 255])
    });
    let f = render_top(&r, 32, 32, true, None).unwrap();
    for k in 0..32 * 32 {
        assert_eq!(f.rgb[k], [(k % 32) as u8 * 8, (k / 32) as u8 * 8, 0]);
        assert_eq!(f.range[k], 31.0 - (k % 32) as f32);
    }
    // 8 × 8 pixels over 32 × 32 cells: one level-1 cell (4 × 4) per pixel, its average colour.
    let small = render_top(&r, 8, 8, true, None).unwrap();
    assert_eq!(small.rgb[0], [12, 12, 0]);
    assert_eq!(
        render_top(&r, 8, 8, false, None).unwrap().rgb[0],
        [16, 16, 0]
    );
}

fn window(min_x: f64, min_y: f64, max_x: f64, max_y: f64) -> Bounds {
    Bounds {
        min_x,
        min_y,
        max_x,
        max_y,
    }
}

#[test]
fn a_top_window_maps_just_its_cells_and_the_world_outside_black() {
    // Grid corner (0, 32), 1 m cells: cell (c, r) spans x [c, c + 1], y [31 − r, 32 − r].
    let (_d, r) = tiles(0.0, 32.0, 32, 32, 16, 4, |c, r| {
        (c as f32, [c as u8 * 8, r as u8 * 8, 0, 255])
    });
    // x 8..16, y 20..24: columns 8..15, rows 8..11, one pixel a cell.
    let f = render_top(&r, 8, 4, true, Some(window(8.0, 20.0, 16.0, 24.0))).unwrap();
    for k in 0..8 * 4 {
        let (c, row) = (8 + k % 8, 8 + k / 8);
        assert_eq!(f.rgb[k], [c as u8 * 8, row as u8 * 8, 0], "pixel {k}");
    }
    // Two pixels a cell: each cell twice across; level 0 (a pixel is half a cell).
    let fine = render_top(&r, 16, 8, true, Some(window(8.0, 20.0, 16.0, 24.0))).unwrap();
    assert_eq!(fine.rgb[0], fine.rgb[1]);
    assert_ne!(fine.rgb[1], fine.rgb[2]);
    // Half the window off the west edge: those pixels black, the rest the cells.
    let half = render_top(&r, 8, 1, false, Some(window(-4.0, 30.0, 4.0, 31.0))).unwrap();
    assert!(half.rgb[..4].iter().all(|&p| p == [0, 0, 0]));
    assert!(half.range[..4].iter().all(|r| r.is_infinite()));
    assert_eq!(half.rgb[4], [0, 8, 0]);
    // The whole grid as a window is the default map.
    let whole = render_top(&r, 32, 32, true, Some(window(0.0, 0.0, 32.0, 32.0))).unwrap();
    assert_eq!(whole.rgb, render_top(&r, 32, 32, true, None).unwrap().rgb);
    for bad in [
        window(5.0, 0.0, 5.0, 1.0),
        window(0.0, 0.0, f64::NAN, 1.0),
        window(100.0, 0.0, 120.0, 8.0),
    ] {
        let e = render_top(&r, 8, 8, true, Some(bad))
            .unwrap_err()
            .to_string();
        assert!(e.contains("--window"), "{e}");
    }
}

#[test]
fn geographic_tile_sets_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("g.dbt");
    let grid = Grid::north_up(10.0, 50.0, 0.001, 8, 8, Crs::epsg(4326));
    synthetic::write_tiles(&path, grid, 8, 4, Compression::None, |_, _| (1.0, GREY)).unwrap();
    let r = TileReader::open(&path, 4).unwrap();
    let e = render_top(&r, 8, 8, false, None).unwrap_err();
    assert!(e.to_string().contains("geographic"), "{e}");
}

// ---- Voxel columns: holes and overhangs --------------------------------------------------

const RED: [u8; 4] = [200, 30, 30, 255];
const BLUE: [u8; 4] = [30, 30, 200, 255];

fn ground(z: f32, colour: [u8; 4]) -> Run {
    Run {
        bottom: f32::NEG_INFINITY,
        top: z,
        colour,
    }
}

/// Ground at 0 m; a 10 m back wall along row 5 (y 58..59); with `arch`, an arch over rows
/// 28..=36 (y 27..37): legs 4 m high at columns 30 and 34, a lintel 3..4 m over columns 31..=33.
fn arch_scene(arch: bool) -> (tempfile::TempDir, TileReader) {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("arch.dbt");
    let grid = Grid::north_up(0.0, 64.0, 1.0, 64, 64, Crs::epsg(32614));
    synthetic::write_columns(&path, grid, 16, 4, |c, r| match (c, r) {
        (_, 5) => vec![ground(10.0, BLUE)],
        (30 | 34, 28..=36) if arch => vec![ground(4.0, RED)],
        (31..=33, 28..=36) if arch => vec![
            ground(0.0, GREY),
            Run {
                bottom: 3.0,
                top: 4.0,
                colour: RED,
            },
        ],
        _ => vec![ground(0.0, GREY)],
    })
    .unwrap();
    let reader = TileReader::open(&path, 64).unwrap();
    (dir, reader)
}

/// The centre pixel's range and colour for both traversals (asserting they agree).
fn centre_hit(r: &TileReader, cam: &Viewpoint) -> (f32, [u8; 3]) {
    let h = render_view(r, cam, &no_lod(Traversal::Hierarchical)).unwrap();
    let l = render_view(r, cam, &no_lod(Traversal::Level0)).unwrap();
    assert_eq!((h.rgb.clone(), bits(&h.range)), (l.rgb, bits(&l.range)));
    (h.range[centre(&h)], h.rgb[centre(&h)])
}

#[test]
fn a_ray_through_an_arch_opening_hits_what_is_behind_it() {
    let (_a, with) = arch_scene(true);
    let (_b, without) = arch_scene(false);
    // Looking north 1.5 m up along x = 32.5: under the lintel (3 m), on to the wall at y = 58.
    let cam = camera([32.5, 10.25, 1.5], 0.0, 0.0, 0.0, 5, 5);
    let (range, rgb) = centre_hit(&with, &cam);
    assert_eq!(range, 47.75);
    assert_eq!(
        rgb,
        sky::Backdrop::Daylight.shade(BLUE, Face::WallV, 47.75, None)
    );
    assert_eq!(
        range.to_bits(),
        centre_hit(&without, &cam).0.to_bits(),
        "the same range as with no arch"
    );
    // 3.5 m up: the lintel's south face at y = 27.
    let (range, rgb) = centre_hit(&with, &camera([32.5, 10.25, 3.5], 0.0, 0.0, 0.0, 5, 5));
    assert_eq!(
        (range, rgb),
        (
            16.75,
            sky::Backdrop::Daylight.shade(RED, Face::WallV, 16.75, None)
        )
    );
    // 4.5 m up: over the arch, on to the wall again.
    assert_eq!(
        centre_hit(&with, &camera([32.5, 10.25, 4.5], 0.0, 0.0, 0.0, 5, 5)).0,
        47.75
    );
    // Through the leg's column (x = 30.5) nothing passes.
    assert_eq!(
        centre_hit(&with, &camera([30.5, 10.25, 1.5], 0.0, 0.0, 0.0, 5, 5)).0,
        16.75
    );
}

#[test]
fn a_ray_under_an_overhang_hits_the_ground_below_it() {
    let (_a, with) = arch_scene(true);
    let (_b, without) = arch_scene(false);
    // From 2 m up at y = 10.25, down toward the ground at y = 31 (under the lintel, y 27..37):
    // at the lintel's face (y = 27) the ray is 0.39 m up, below its bottom.
    let pitch = -(2.0f64 / 20.75).atan().to_degrees();
    let cam = camera([32.5, 10.25, 2.0], 0.0, pitch, 0.0, 5, 5);
    let (range, rgb) = centre_hit(&with, &cam);
    assert!((range as f64 - 20.75f64.hypot(2.0)).abs() < 1e-4, "{range}");
    assert_eq!(
        rgb,
        sky::Backdrop::Daylight.shade(GREY, Face::Top, range as f64, None)
    );
    assert_eq!(range.to_bits(), centre_hit(&without, &cam).0.to_bits());
}

#[test]
fn a_rising_ray_under_an_overhang_hits_its_underside_and_the_eye_may_stand_there() {
    let (_a, with) = arch_scene(true);
    // Under the lintel, 1 m up, looking north 45° up: the lintel's bottom (3 m) 2 m ahead.
    let (range, rgb) = centre_hit(&with, &camera([32.5, 31.5, 1.0], 0.0, 45.0, 0.0, 5, 5));
    assert!((range as f64 - 2.0 * 2f64.sqrt()).abs() < 1e-5, "{range}");
    assert_eq!(
        rgb,
        sky::Backdrop::Daylight.shade(RED, Face::Bottom, range as f64, None)
    );
    // Inside the lintel is inside solid matter.
    let e = render_view(
        &with,
        &camera([32.5, 31.5, 3.5], 0.0, 0.0, 0.0, 4, 4),
        &ViewOptions::default(),
    )
    .unwrap_err();
    assert!(
        e.to_string()
            .contains("inside a voxel column, solid there from 3.00 m to 4.00 m"),
        "{e}"
    );
}

#[test]
fn a_page_with_partial_cells_but_no_bricks_is_an_error_naming_the_page() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("t.dbt");
    let grid = Grid::north_up(0.0, 16.0, 1.0, 16, 16, Crs::epsg(32614));
    let info = crate::tiles::TileSetInfo::new(grid, 16, 4, None).unwrap();
    let writer = crate::tiles::TileWriter::create(&path, info).unwrap();
    let mut page = crate::tiles::Page::nodata(16);
    page.max_z.fill(1.0);
    page.colour.fill(GREY);
    page.state.fill(crate::tiles::STATE_OPAQUE);
    page.state[8 * 16 + 8] = crate::tiles::STATE_PARTIAL;
    writer.write_page(0, 0, 0, &page).unwrap();
    writer.finish().unwrap();
    let r = TileReader::open(&path, 4).unwrap();
    let e = render_view(
        &r,
        &camera([8.5, 7.5, 5.0], 0.0, -90.0, 0.0, 3, 3),
        &ViewOptions::default(),
    )
    .unwrap_err();
    assert!(
        e.to_string()
            .contains("page (level 0, 0, 0) bricks: cell 136 has state 1 (partial) but no column"),
        "{e}"
    );
}

/// [`rough`] with floating runs over some cells (arches, overhangs) and a second one over a few.
fn rough_columns(c: usize, r: usize) -> Vec<Run> {
    let (z, colour) = rough(c, r);
    if z.is_nan() {
        return Vec::new();
    }
    let h = (c as u64 * 31 + r as u64 * 17) % 11;
    let mut runs = vec![ground(z, colour)];
    if h < 3 {
        runs.push(Run {
            bottom: z + 1.5 + h as f32,
            top: z + 3.0 + h as f32,
            colour: RED,
        });
    }
    if h == 0 {
        runs.push(Run {
            bottom: z + 5.0,
            top: z + 5.5,
            colour: BLUE,
        });
    }
    runs
}

fn rough_column_tiles() -> &'static (tempfile::TempDir, TileReader) {
    static T: OnceLock<(tempfile::TempDir, TileReader)> = OnceLock::new();
    T.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("c.dbt");
        synthetic::write_columns(
            &path,
            Grid::north_up(0.0, 150.0, 1.0, 200, 150, Crs::epsg(32614)),
            16,
            2,
            rough_columns,
        )
        .unwrap();
        let reader = TileReader::open(&path, 64).unwrap();
        (dir, reader)
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]
    /// With voxel columns in a quarter of the cells, low eyes (some between the runs) and
    /// rising rays, the two traversals still agree bit for bit.
    #[test]
    fn hierarchy_and_level0_agree_through_holes_and_overhangs(
        x in -20.0f64..220.0, y in -20.0f64..170.0, z in 2.0f64..50.0,
        roll in -30.0f64..30.0, pitch in -60.0f64..30.0, yaw in 0.0f64..360.0, repeat in any::<bool>()
    ) {
        let (_d, r) = rough_column_tiles();
        let cam = camera([x, y, z], roll, pitch, yaw, 24, 18);
        let opts = |t| ViewOptions { repeat, ..no_lod(t) };
        let h = render_view(r, &cam, &opts(Traversal::Hierarchical));
        prop_assume!(h.is_ok(), "eye inside solid matter");
        let (h, l) = (h.unwrap(), render_view(r, &cam, &opts(Traversal::Level0)).unwrap());
        prop_assert_eq!(&h.rgb, &l.rgb);
        prop_assert_eq!(bits(&h.range), bits(&l.range));
    }
}

/// Every time in `(0, span.t1)` at which `ray` crosses a column (axis 0) or row (axis 1)
/// boundary of a `w` × `h` grid or the one just outside it, as (time, axis), sorted by time.
fn boundary_crossings(ray: &Ray, span: Span, w: i64, h: i64) -> Vec<(f64, usize)> {
    let mut crossings: Vec<(f64, usize)> = Vec::new();
    for (a, axis, n) in [(0, ray.u, w), (1, ray.v, h)] {
        for b in -1..=n + 1 {
            let t = axis.cross(b);
            if t > 0.0 && t < span.t1 {
                crossings.push((t, a));
            }
        }
    }
    crossings.sort_by(|x, y| x.0.total_cmp(&y.0));
    crossings
}

/// The level-0 hit of `ray` over `span` by brute force, sharing no code with the walk: every
/// column and row boundary crossing in `(0, t1)` sorted (equal times are one corner, crossed
/// together), the cell from the eye's cell moved one cell per crossing passed, and each cell's
/// column (from `height`, not the tile set) tested over the times the ray is in it.
fn brute_force_hit<F>(
    ray: &Ray,
    span: Span,
    w: i64,
    h: i64,
    height: F,
) -> Option<(f64, [u8; 4], Face)>
where
    F: Fn(usize, usize) -> (f32, [u8; 4]),
{
    let crossings = boundary_crossings(ray, span, w, h);
    let start = |a: Axis| {
        if a.d < 0.0 {
            a.o.ceil() as i64 - 1
        } else {
            a.o.floor() as i64
        }
    };
    let step = |a: Axis| if a.d > 0.0 { 1 } else { -1 };
    let mut cell = [start(ray.u), start(ray.v)];
    // (time entered, axes crossed to enter) of the current cell
    let (mut ta, mut by) = (0.0, [false, false]);
    let mut k = 0;
    loop {
        // the crossings at the next time: the cell's exit
        let tb = crossings.get(k).map_or(span.t1, |c| c.0);
        let mut next = cell;
        let mut next_by = [false, false];
        while k < crossings.len() && crossings[k].0 == tb {
            let a = crossings[k].1;
            next[a] += step([ray.u, ray.v][a]);
            next_by[a] = true;
            k += 1;
        }
        let tb = tb.min(span.t1);
        if tb > span.t0 && (0..w).contains(&cell[0]) && (0..h).contains(&cell[1]) {
            let (max_z, colour) = height(cell[0] as usize, cell[1] as usize);
            let (t_in, face) = if ta >= span.t0 {
                (ta, if by[0] { Face::WallU } else { Face::WallV })
            } else {
                (span.t0, Face::Top)
            };
            let mz = max_z as f64;
            if !max_z.is_nan() && ray.z(t_in).min(ray.z(tb)) <= mz {
                // A side less than a cell (1 m) above the cell behind it is a slope's step.
                let behind = match face {
                    Face::WallU => Some([cell[0] - step(ray.u), cell[1]]),
                    Face::WallV => Some([cell[0], cell[1] - step(ray.v)]),
                    _ => None,
                };
                let rise = behind
                    .filter(|&[c, r]| (0..w).contains(&c) && (0..h).contains(&r))
                    .map(|[c, r]| mz - height(c as usize, r as usize).0 as f64);
                let face = if rise.is_some_and(|rise| rise < 1.0) {
                    Face::Step
                } else {
                    face
                };
                return Some(if ray.z(t_in) <= mz {
                    (t_in, colour, face)
                } else {
                    let t = ray.time_at_height(mz).unwrap().max(t_in).min(tb);
                    (t, colour, Face::Top)
                });
            }
        }
        if tb >= span.t1 {
            return None;
        }
        (cell, ta, by) = (next, tb, next_by);
    }
}

/// The plan of `scene` without range thresholds (every level, no repeat): marching finds the
/// exact level-0 hit.
fn exact_plan(scene: &Scene, traversal: Traversal) -> Plan {
    Plan {
        traversal,
        top: scene.top(false),
        scales: scene.scales.clone(),
        thresholds: None,
        blend: false,
        cell_m: scene.cell.map(f64::abs),
    }
}

#[test]
fn hard_case_axes_diagonals_and_two_ulps_off_them_from_utm_eyes_hit_what_brute_force_hits() {
    // Rough terrain (spikes, nodata holes) on a UTM grid; every level of a factor-2 hierarchy.
    let (x0, y0) = (500_000.0, 5_300_150.0);
    let (_d, r) = tiles(x0, y0, 200, 150, 16, 2, rough);
    let scene = Scene::of(&r).unwrap();
    let plan = |traversal| exact_plan(&scene, traversal);
    let cache = ColumnCache::default();
    let mut sampler = Sampler::new(&r, false, &cache);
    let nudge = |x: f64, ulps: i64| {
        if x == 0.0 {
            // 2 ulps off zero: the smallest subnormals, either side
            ulps.signum() as f64 * f64::from_bits(ulps.unsigned_abs())
        } else {
            f64::from_bits((x.to_bits() as i64 + ulps) as u64)
        }
    };
    let s = std::f64::consts::FRAC_1_SQRT_2;
    let (mut rays, mut spans, mut hits, mut corners) = (0, 0, 0, 0);
    let (mut walls, mut steps) = (0, 0);
    // On a cell corner, at a cell centre, anywhere; UTM-sized world coordinates.
    for (ex, ey) in [(37.0, 41.0), (120.5, 99.5), (63.318_77, 12.904_41)] {
        let (u0, v0) = scene.local(x0 + ex, y0 - ey);
        for (du, dv) in [
            (1.0, 0.0),
            (0.0, 1.0),
            (-1.0, 0.0),
            (0.0, -1.0),
            (s, s),
            (-s, s),
            (s, -s),
            (-s, -s),
        ] {
            for (nu, nv) in [(0, 0), (2, 0), (-2, 0), (0, 2), (0, -2), (2, -2), (-2, 2)] {
                for (z0, dz) in [(40.0, -0.3), (45.0, -0.15), (36.0, -0.6)] {
                    let ray = Ray {
                        u: Axis::new(u0, nudge(du, nu)),
                        v: Axis::new(v0, nudge(dv, nv)),
                        z0,
                        dz,
                        norm: 1.0,
                    };
                    rays += 1;
                    let Some(span) = scene.span(&ray, false, f64::INFINITY) else {
                        continue; // passes over the box above its highest column
                    };
                    let want = brute_force_hit(&ray, span, 200, 150, rough);
                    for traversal in [Traversal::Hierarchical, Traversal::Level0] {
                        let (got, _) =
                            march::march(&ray, span, &mut sampler, &plan(traversal)).unwrap();
                        let got = got.map(|h| (h.t, h.colour, h.face));
                        assert_eq!(
                            got.map(|g| (g.0.to_bits(), g.1, g.2)),
                            want.map(|g| (g.0.to_bits(), g.1, g.2)),
                            "{traversal:?}: eye ({ex}, {ey}, {z0}), direction ({}, {}, {dz}): got {got:?}, brute force {want:?}",
                            ray.u.d,
                            ray.v.d
                        );
                    }
                    spans += 1;
                    hits += want.is_some() as u32;
                    let face = want.map(|w| w.2);
                    walls += matches!(face, Some(Face::WallU | Face::WallV)) as u32;
                    steps += (face == Some(Face::Step)) as u32;
                    // rays through cell corners: both crossings of some time the same f64
                    corners += ((ray.u.d.abs() == ray.v.d.abs()) && ex == 37.0) as u32;
                }
            }
        }
    }
    // Most rays meet the box and hit (the brute force is not vacuous); some pass over the box
    // or run off its edge.
    assert_eq!(rays, 3 * 8 * 7 * 3);
    assert!(spans > rays * 2 / 3, "{spans} of {rays}");
    assert!(hits > spans / 2, "{hits} of {spans}");
    assert!(corners > 0);
    assert!(walls > 0 && steps > 0, "{walls} walls, {steps} steps");
}

#[test]
fn supersampling_converges_on_the_many_sample_image_and_leaves_the_range_alone() {
    // The checkerboard without range thresholds aliases badly in the distance: 1 ray per pixel
    // picks black or white at random, 64 average them.
    let (_d, r) = checkerboard();
    let cam = camera([256.0, 0.5, 3.0], 0.0, -1.0, 0.0, 64, 48);
    let frame = |samples| {
        let opts = ViewOptions {
            samples,
            ..no_lod(Traversal::Hierarchical)
        };
        render_view(&r, &cam, &opts).unwrap()
    };
    let reference = frame(64);
    let error = |f: &Frame| {
        f.rgb
            .iter()
            .zip(&reference.rgb)
            .map(|(a, b)| {
                (0..3)
                    .map(|k| (a[k] as f64 - b[k] as f64).abs())
                    .sum::<f64>()
                    / 3.0
            })
            .sum::<f64>()
            / f.rgb.len() as f64
    };
    let frames: Vec<Frame> = [1, 4, 16].into_iter().map(frame).collect();
    let errors: Vec<f64> = frames.iter().map(error).collect();
    assert!(
        errors[0] > 1.5 * errors[1] && errors[1] > 1.5 * errors[2] && errors[0] > 20.0,
        "mean error against 64 rays per pixel for 1, 4, 16: {errors:?}"
    );
    for (f, n) in frames.iter().zip([1u64, 4, 16]) {
        assert_eq!(bits(&f.range), bits(&reference.range), "{n} samples");
        let extra = if n > 1 { n } else { 0 };
        assert_eq!(f.stats.rays, 64 * 48 * (1 + extra));
    }
    assert_eq!(frame(16).rgb, frames[2].rgb, "reproducible");
}

#[test]
fn samples_must_be_a_square_in_range() {
    for n in [1, 4, 9, 64, 256] {
        assert_eq!(sample_grid(n).unwrap().pow(2), n);
    }
    for n in [0, 2, 3, 8, 63, 289] {
        let e = sample_grid(n).unwrap_err().to_string();
        assert!(
            e.contains(&format!("--samples {n}")) && e.contains("square"),
            "{e}"
        );
    }
}

#[test]
fn blend_weight_switches_without_blending_and_ramps_in_log_range_with_it() {
    assert_eq!(march::blend_weight(99.9, 100.0, false), 0.0);
    assert_eq!(march::blend_weight(100.0, 100.0, false), 0.0);
    assert_eq!(march::blend_weight(100.1, 100.0, false), 1.0);
    let b = march::BLEND_BAND;
    assert_eq!(march::blend_weight(100.0 / b / 1.001, 100.0, true), 0.0);
    assert!((march::blend_weight(100.0 / b, 100.0, true)).abs() < 1e-12);
    assert!((march::blend_weight(100.0, 100.0, true) - 0.5).abs() < 1e-12);
    assert!((march::blend_weight(100.0 * b, 100.0, true) - 1.0).abs() < 1e-12);
    assert_eq!(march::blend_weight(100.0 * b * 1.001, 100.0, true), 1.0);
    let (w1, w2) = (
        march::blend_weight(90.0, 100.0, true),
        march::blend_weight(110.0, 100.0, true),
    );
    assert!(0.0 < w1 && w1 < 0.5 && 0.5 < w2 && w2 < 1.0);
}

#[test]
fn blending_mixes_level_0_and_level_1_by_range_across_the_threshold_band() {
    // Level 0 is black or white, level 1 grey: inside [TH_1 / √2, TH_1 · √2] a hit shows
    // lerp(its cell's black or white, grey, w(range)), outside it the one level's colour.
    let (_d, r) = checkerboard();
    let cam = camera([256.0, 0.5, 3.0], 0.0, -1.0, 0.0, 64, 48);
    let th1 = 2.0 * 64.0 / 60f64.to_radians();
    let b = march::BLEND_BAND;
    let grey = {
        let cache = ColumnCache::default();
        Sampler::new(&r, false, &cache)
            .cell(1, 0, 0)
            .unwrap()
            .unwrap()
            .colour[0] as f64
    };
    for traversal in [Traversal::Hierarchical, Traversal::Level0] {
        let opts = ViewOptions {
            traversal,
            blend: true,
            ..ViewOptions::default()
        };
        let f = render_view(&r, &cam, &opts).unwrap();
        let mut inside = 0;
        for (k, &t) in f.range.iter().enumerate().filter(|(_, t)| t.is_finite()) {
            let (t, v) = (t as f64, f.rgb[k][0] as f64);
            let w = march::blend_weight(t, th1, true);
            let fits = [0.0, 255.0]
                .iter()
                .any(|&c| (v - (c + (grey - c) * w)).abs() <= 1.0);
            assert!(fits, "{traversal:?} pixel {k} at {t} m: {v}, weight {w}");
            inside += (t > th1 / b * 1.01 && t < th1 * b * 0.99) as u32;
        }
        assert!(inside > 30, "{inside} hits inside the band");
    }
}

/// A yaw on an axis or diagonal, or a few ulps off one, or any.
fn hard_yaw() -> impl Strategy<Value = f64> {
    prop_oneof![
        (0..8, -3i64..=3).prop_map(|(k, ulps)| {
            let y = k as f64 * 45.0;
            f64::from_bits((y.to_bits() as i64 + ulps).max(0) as u64)
        }),
        0.0f64..360.0,
    ]
}

/// Renders `cam` with and without column coherence under `opts`; both frames, or `None` when the
/// eye is inside solid matter (refused alike).
fn with_and_without_coherence(
    r: &TileReader,
    cam: &Viewpoint,
    opts: ViewOptions,
) -> Option<(Frame, Frame)> {
    let with = render_view(
        r,
        cam,
        &ViewOptions {
            coherence: true,
            ..opts.clone()
        },
    );
    let without = render_view(
        r,
        cam,
        &ViewOptions {
            coherence: false,
            ..opts
        },
    );
    assert_eq!(with.is_ok(), without.is_ok());
    Some((with.ok()?, without.unwrap()))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]
    /// The column march changes no pixel and no range: over rough terrain with nodata holes and
    /// over voxel columns with floating runs, with and without range thresholds and blending,
    /// repeating or not, with a range limit or not, from eyes below and above the highest
    /// column, on cell boundaries and corners, looking along the axes and diagonals and a few
    /// ulps off them.
    #[test]
    fn column_march_gives_the_frames_of_rays_from_the_eye(
        x in prop_oneof![-20.0f64..220.0, (-20i32..220).prop_map(f64::from)],
        y in prop_oneof![-20.0f64..170.0, (-20i32..170).prop_map(f64::from)],
        z in 2.0f64..50.0, yaw in hard_yaw(), voxels in any::<bool>(),
        lod in any::<bool>(), blend in any::<bool>(), repeat in any::<bool>(),
        level0 in any::<bool>(), max_range in prop::option::of(5.0f64..150.0),
    ) {
        let (_d, r) = if voxels { rough_column_tiles() } else { rough_tiles() };
        let cam = camera([x, y, z], 0.0, 0.0, yaw, 20, 48);
        let opts = ViewOptions {
            traversal: if level0 { Traversal::Level0 } else { Traversal::Hierarchical },
            lod,
            blend: lod && blend,
            repeat,
            max_range,
            ..ViewOptions::default()
        };
        let Some((c, n)) = with_and_without_coherence(r, &cam, opts) else {
            return Ok(());
        };
        prop_assert_eq!(&c.rgb, &n.rgb);
        prop_assert_eq!(bits(&c.range), bits(&n.range));
        prop_assert!(c.stats.cells_stepped <= n.stats.cells_stepped);
    }
}

#[test]
fn column_march_skips_most_steps_of_a_level_view_and_only_there() {
    let (_d, r) = rough_tiles();
    let steps = |pitch: f64, coherence: bool| {
        let cam = camera([10.0, 10.0, 30.0], 0.0, pitch, 50.0, 64, 48);
        let opts = ViewOptions {
            coherence,
            ..ViewOptions::default()
        };
        render_view(r, &cam, &opts).unwrap().stats.cells_stepped
    };
    let (with, without) = (steps(0.0, true), steps(0.0, false));
    assert!(with * 3 < without, "{with} vs {without} cells stepped");
    // A pitched view's image columns are not vertical planes: every ray starts at the eye.
    assert_eq!(steps(-5.0, true), steps(-5.0, false));
}

/// The rays of one column share a path that runs exactly through a cell corner beside two tall
/// columns and touches neither; the lower ray passes under the corner's height, the upper over
/// a floating run, and each must find what a ray from the eye finds: the column march gives
/// every ray its own `march` hit, at axis and diagonal headings and one ulp off them.
#[test]
fn hard_case_a_column_through_a_cell_corner_gives_each_ray_its_own_hit() {
    let tall = |c: usize, r: usize| {
        let z = if (c, r) == (6, 7) || (c, r) == (7, 6) {
            100.0
        } else {
            f32::from(u8::try_from((c * 7 + r * 3) % 5).unwrap())
        };
        (z, [(c * 20) as u8, (r * 20) as u8, 0, 255])
    };
    let (_d, r) = tiles(0.0, 64.0, 64, 64, 16, 2, tall);
    let scene = Scene::of(&r).unwrap();
    let cache = ColumnCache::default();
    let mut sampler = Sampler::new(&r, false, &cache);
    let ulp = |x: f64, n: i64| f64::from_bits((x.to_bits() as i64 + n) as u64);
    let c = 0.5;
    for traversal in [Traversal::Hierarchical, Traversal::Level0] {
        let plan = exact_plan(&scene, traversal);
        for (du, dv) in [(c, c), (ulp(c, 1), c), (c, ulp(c, -1)), (c, 0.0), (0.0, c)] {
            let rays: Vec<Ray> = (0..40)
                .map(|k| Ray {
                    u: Axis::new(5.0, du),
                    v: Axis::new(5.0, dv),
                    z0: 10.0,
                    dz: -0.4 + 0.0125 * k as f64,
                    norm: 1.0 + 0.01 * k as f64,
                })
                .collect();
            let spans: Vec<Option<Span>> = rays
                .iter()
                .map(|ray| scene.span(ray, false, f64::INFINITY))
                .collect();
            let (hits, steps) = column::march_column(&rays, &spans, &mut sampler, &plan).unwrap();
            let mut alone = 0;
            for ((ray, span), hit) in rays.iter().zip(&spans).zip(&hits) {
                let want = match span {
                    Some(span) => {
                        let (hit, n) = march::march(ray, *span, &mut sampler, &plan).unwrap();
                        alone += n;
                        hit
                    }
                    None => None,
                };
                assert_eq!(*hit, want, "{traversal:?}, ({du}, {dv}), dz {}", ray.dz);
            }
            let n_hit = hits.iter().filter(|h| h.is_some()).count();
            assert!(n_hit > 20, "{n_hit} hits, ({du}, {dv}), {traversal:?}");
            assert!(
                steps < alone,
                "{steps} column visits, {alone} steps of single rays"
            );
        }
    }
}

/// In one column, the lower ray's span ends (its range limit) part-way over a cell it passes
/// above; the ray above it, spanning the whole cell, comes down onto that cell's top later in
/// it. Only a ray that spans a whole visit vouches for the rays above it.
#[test]
fn hard_case_a_ray_whose_range_ends_over_a_cell_does_not_vouch_for_the_ray_above() {
    // Ground 0.2 m high; one tall column far off the rays' path keeps the eye below the top.
    let ground = |c, r| match (c, r) {
        (60, 60) => (50.0, GREY),
        _ => (0.2, GREY),
    };
    let (_d, r) = tiles(0.0, 64.0, 64, 64, 16, 2, ground);
    let scene = Scene::of(&r).unwrap();
    let cache = ColumnCache::default();
    let mut sampler = Sampler::new(&r, false, &cache);
    let ray = |dz: f64| Ray {
        u: Axis::new(5.0, 1.0),
        v: Axis::new(5.5, 0.0),
        z0: 10.0,
        dz,
        norm: 1.0,
    };
    let (low, high) = (ray(-1.0), ray(-0.99));
    let whole = scene.span(&high, false, f64::INFINITY).unwrap();
    assert_eq!(whole.t0, 0.0);
    // The low ray would meet the ground at τ ≈ 9.8, in cell 14; it stops looking at 9.5.
    let spans = [Some(Span { t1: 9.5, ..whole }), Some(whole)];
    for traversal in [Traversal::Hierarchical, Traversal::Level0] {
        let plan = exact_plan(&scene, traversal);
        let (hits, _) = column::march_column(&[low, high], &spans, &mut sampler, &plan).unwrap();
        assert_eq!(hits[0], None);
        let (alone, _) = march::march(&high, whole, &mut sampler, &plan).unwrap();
        let alone = alone.expect("the high ray comes down on cell 14's top");
        assert_eq!(alone.face, Face::Top);
        assert!((9.0..10.0).contains(&alone.t), "{alone:?}");
        assert_eq!(hits[1], Some(alone), "{traversal:?}");
    }
}
