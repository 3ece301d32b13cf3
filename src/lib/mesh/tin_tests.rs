use super::*;
use crate::num::SplitMix;
use proptest::prelude::*;

/// A window of `w` × `h` points with heights `f(column, row)`.
fn window(w: usize, h: usize, mut f: impl FnMut(usize, usize) -> f32) -> Vec<f32> {
    (0..w * h).map(|i| f(i % w, i / w)).collect()
}

/// Uniform in [-1, 1) from a seed, an octave and a lattice point.
fn noise(seed: u64, octave: u64, i: i64, j: i64) -> f64 {
    SplitMix(seed ^ (octave << 56) ^ ((i as u64) << 28) ^ j as u64).signed()
}

/// Rough terrain: `base` plus value noise over octaves of 64 down to 1 point, each octave's
/// amplitude `relief * size / 64` metres (the finest is white noise).
fn rough(w: usize, h: usize, seed: u64, base: f32, relief: f64) -> Vec<f32> {
    window(w, h, |c, r| {
        let mut z = 0.0;
        for octave in 0..=6u64 {
            let size = 1i64 << octave;
            let (i, j) = (c as i64 / size, r as i64 / size);
            let (fx, fy) = (
                (c as i64 % size) as f64 / size as f64,
                (r as i64 % size) as f64 / size as f64,
            );
            let n = |di, dj| noise(seed, octave, i + di, j + dj);
            let top = n(0, 0) * (1.0 - fx) + n(1, 0) * fx;
            let bottom = n(0, 1) * (1.0 - fx) + n(1, 1) * fx;
            z += relief * size as f64 / 64.0 * (top * (1.0 - fy) + bottom * fy);
        }
        base + z as f32
    })
}

/// `z` with the points where `hole(column, row)` set to nodata.
fn holes(w: usize, mut z: Vec<f32>, hole: impl Fn(usize, usize) -> bool) -> Vec<f32> {
    for (i, v) in z.iter_mut().enumerate() {
        if hole(i % w, i / w) {
            *v = f32::NAN;
        }
    }
    z
}

fn corner(tin: &Tin, i: u32) -> [i64; 2] {
    let [c, r] = tin.vertices[i as usize];
    [c as i64, r as i64]
}

/// The TIN's shape: vertices valid and sorted, triangles clockwise in (column, row) with a
/// nonzero area and sorted, no nodata point in any triangle, each triangle edge along the
/// border joining consecutive `edge_points`, and the areas summing to the window's when there
/// is no nodata.
fn check_shape(h: &Heights, tin: &Tin, max_error: f64) {
    let at = |q: [i64; 2]| h.z[q[1] as usize * h.width + q[0] as usize];
    assert!(tin
        .vertices
        .windows(2)
        .all(|v| (v[0][1], v[0][0]) < (v[1][1], v[1][0])));
    assert!(tin.triangles.windows(2).all(|t| t[0] < t[1]));
    let edges = [
        edge_points(&h.z[..h.width], max_error),
        edge_points(&h.z[(h.height - 1) * h.width..], max_error),
        edge_points(&window(1, h.height, |_, r| h.z[r * h.width]), max_error),
        edge_points(
            &window(1, h.height, |_, r| h.z[r * h.width + h.width - 1]),
            max_error,
        ),
    ];
    let (last_c, last_r) = (h.width as i64 - 1, h.height as i64 - 1);
    let mut area2 = 0;
    for t in &tin.triangles {
        assert!(
            t[0] < t[1] && t[0] < t[2],
            "{t:?} does not start at its lowest index"
        );
        let p = t.map(|i| corner(tin, i));
        let o = orient(p[0], p[1], p[2]);
        assert!(
            o < 0,
            "{p:?} is degenerate or counter-clockwise in (column, row)"
        );
        area2 -= o;
        let facet = Facet::new(p, h);
        assert!(
            facet.points().all(|q| !at(q).is_nan()),
            "{p:?} holds nodata"
        );
        for k in 0..3 {
            let (a, b) = (p[k], p[(k + 1) % 3]);
            let (lo, hi) = if (a[1], a[0]) < (b[1], b[0]) {
                (a, b)
            } else {
                (b, a)
            };
            let along = if lo[1] == hi[1] && (lo[1] == 0 || lo[1] == last_r) {
                Some((
                    &edges[usize::from(lo[1] != 0)],
                    lo[0] as usize,
                    hi[0] as usize,
                ))
            } else if lo[0] == hi[0] && (lo[0] == 0 || lo[0] == last_c) {
                Some((
                    &edges[2 + usize::from(lo[0] != 0)],
                    lo[1] as usize,
                    hi[1] as usize,
                ))
            } else {
                None
            };
            if let Some((kept, i, j)) = along {
                let at_i = kept
                    .binary_search(&i)
                    .expect("border vertex is an edge point");
                assert_eq!(
                    kept[at_i + 1],
                    j,
                    "border edge {lo:?}-{hi:?} skips an edge point"
                );
            }
        }
    }
    if !h.z.iter().any(|z| z.is_nan()) {
        assert_eq!(area2, 2 * (h.width as i64 - 1) * (h.height as i64 - 1));
    }
}

/// Brute force, independent of `measure`: every valid point's height lies within `max_error`
/// of plain barycentric interpolation over each triangle holding it (found by testing every
/// triangle); a point inside one triangle lies in no other; every valid interior point with no
/// nodata point among its 8 neighbours is covered (on the border, see
/// `a_border_segment_beside_a_nodata_corner_can_stay_uncovered`).
fn check_brute(h: &Heights, tin: &Tin, max_error: f64) {
    let tris: Vec<[[i64; 2]; 3]> = tin
        .triangles
        .iter()
        .map(|t| t.map(|i| corner(tin, i)))
        .collect();
    let nodata = |c: i64, r: i64| {
        c >= 0
            && r >= 0
            && (c as usize) < h.width
            && (r as usize) < h.height
            && h.z[r as usize * h.width + c as usize].is_nan()
    };
    for r in 0..h.height as i64 {
        for c in 0..h.width as i64 {
            let z = h.z[r as usize * h.width + c as usize];
            if z.is_nan() {
                continue;
            }
            let (mut holding, mut inside) = (0, 0);
            for p in &tris {
                let area = orient(p[0], p[1], p[2]) as f64;
                let l = [
                    orient([c, r], p[1], p[2]) as f64 / area,
                    orient(p[0], [c, r], p[2]) as f64 / area,
                    orient(p[0], p[1], [c, r]) as f64 / area,
                ];
                if l.iter().any(|&x| x < 0.0) {
                    continue;
                }
                holding += 1;
                inside += usize::from(l.iter().all(|&x| x > 0.0));
                let zi: f64 = (0..3)
                    .map(|k| l[k] * h.z[p[k][1] as usize * h.width + p[k][0] as usize] as f64)
                    .sum();
                let e = (z as f64 - zi).abs();
                assert!(e <= max_error + 1e-9, "({c}, {r}) is {e} m off in {p:?}");
            }
            assert!(inside == 0 || holding == 1, "({c}, {r}) overlapped");
            let near_hole = (-1..=1).any(|dr| (-1..=1).any(|dc| nodata(c + dc, r + dr)));
            let border = c == 0 || r == 0 || c == h.width as i64 - 1 || r == h.height as i64 - 1;
            assert!(near_hole || border || holding > 0, "({c}, {r}) uncovered");
        }
    }
}

/// Simplify, then check shape, brute-force bound and coverage, and `measure`'s bound.
fn simplify_checked(h: &Heights, max_error: f64) -> Tin {
    let tin = simplify(h, max_error);
    check_shape(h, &tin, max_error);
    check_brute(h, &tin, max_error);
    let m = measure(h, &tin);
    assert!(m.max <= max_error, "measured {} > {max_error}", m.max);
    tin
}

/// A tilted plane (exactly linear, dyadic slopes) is two triangles and no error.
#[test]
fn a_tilted_plane_is_two_triangles_with_no_error() {
    let z = window(17, 9, |c, r| 100.0 + 0.5 * c as f32 - 0.25 * r as f32);
    let h = Heights {
        width: 17,
        height: 9,
        z: &z,
    };
    let tin = simplify_checked(&h, 0.0);
    assert_eq!(tin.vertices, [[0, 0], [16, 0], [0, 8], [16, 8]]);
    assert_eq!(tin.triangles.len(), 2);
    let m = measure(&h, &tin);
    assert_eq!((m.max, m.rms, m.points), (0.0, 0.0, 17 * 9));
}

/// A flat window is two triangles.
#[test]
fn a_flat_window_is_two_triangles() {
    let z = vec![7.5f32; 30 * 20];
    let h = Heights {
        width: 30,
        height: 20,
        z: &z,
    };
    let tin = simplify_checked(&h, 0.0);
    assert_eq!(tin.triangles.len(), 2);
    assert_eq!(measure(&h, &tin).max, 0.0);
}

/// A single spike in the middle of a flat window is inserted and the bound holds.
#[test]
fn a_spike_is_inserted() {
    let z = window(9, 9, |c, r| if (c, r) == (4, 4) { 2.0 } else { 0.0 });
    let h = Heights {
        width: 9,
        height: 9,
        z: &z,
    };
    let tin = simplify_checked(&h, 0.5);
    assert!(tin.vertices.contains(&[4, 4]));
    assert!(measure(&h, &tin).max <= 0.5);
    // With a bound the spike's slopes keep, it is the only inner vertex.
    let tin = simplify_checked(&h, 1.5);
    assert_eq!(tin.vertices, [[0, 0], [8, 0], [4, 4], [0, 8], [8, 8]]);
    assert_eq!(tin.triangles.len(), 4);
}

/// A bound exactly equal to a point's deviation keeps it out (`<=`); one ulp below takes it
/// in; a few ulps above keeps it out — on the border (1-D) and inside.
#[test]
fn a_bound_equal_to_a_deviation_keeps_the_point_out() {
    let below = f64::from_bits(1.0f64.to_bits() - 1);
    let above = f64::from_bits(1.0f64.to_bits() + 4);
    let edge = [0.0f32, 0.0, 1.0, 0.0, 0.0];
    assert_eq!(edge_points(&edge, 1.0), [0, 4]);
    assert_eq!(edge_points(&edge, above), [0, 4]);
    assert_eq!(edge_points(&edge, below), [0, 2, 4]);
    let z = window(5, 5, |c, r| if (c, r) == (2, 2) { 1.0 } else { 0.0 });
    let h = Heights {
        width: 5,
        height: 5,
        z: &z,
    };
    for bound in [1.0, above] {
        let tin = simplify_checked(&h, bound);
        assert_eq!(tin.triangles.len(), 2);
        assert_eq!(measure(&h, &tin).max, 1.0);
    }
    let tin = simplify_checked(&h, below);
    assert!(tin.vertices.contains(&[2, 2]));
    assert_eq!(measure(&h, &tin).max, 0.5);
}

/// UTM-sized absolute heights (4000 m) with relief of a quarter metre: the spike is judged on
/// its relief, and rough terrain at that height keeps the bound.
#[test]
fn utm_sized_heights_keep_their_small_relief() {
    let z = window(9, 9, |c, r| {
        4000.0 + if (c, r) == (3, 5) { 0.25 } else { 0.0 }
    });
    let h = Heights {
        width: 9,
        height: 9,
        z: &z,
    };
    assert_eq!(simplify_checked(&h, 0.25).triangles.len(), 2);
    assert!(simplify_checked(&h, 0.2).vertices.contains(&[3, 5]));
    let z = rough(33, 33, 11, 4000.0, 0.5);
    let h = Heights {
        width: 33,
        height: 33,
        z: &z,
    };
    for bound in [0.0, 0.01, 0.05] {
        simplify_checked(&h, bound);
    }
}

/// Windows less than 2 points wide or high give no triangle; short edges keep their ends; a
/// 2×2 window is at most two triangles, one when a corner is nodata.
#[test]
fn tiny_windows_and_edges() {
    assert_eq!(edge_points(&[], 0.0), Vec::<usize>::new());
    assert_eq!(edge_points(&[1.0], 0.0), [0]);
    assert_eq!(edge_points(&[1.0, 5.0], 0.0), [0, 1]);
    assert_eq!(edge_points(&[f32::NAN], 0.0), [0]);
    for (w, h) in [(1, 1), (1, 5), (5, 1), (0, 0)] {
        let z = vec![1.0f32; w * h];
        let heights = Heights {
            width: w,
            height: h,
            z: &z,
        };
        assert_eq!(simplify(&heights, 0.1), Tin::default());
    }
    let z = [1.0f32, 2.0, 4.0, 3.0];
    let h = Heights {
        width: 2,
        height: 2,
        z: &z,
    };
    let tin = simplify_checked(&h, 0.0);
    assert_eq!(tin.triangles.len(), 2);
    for hole in 0..4 {
        let mut z = [1.0f32, 2.0, 4.0, 3.0];
        z[hole] = f32::NAN;
        let h = Heights {
            width: 2,
            height: 2,
            z: &z,
        };
        let tin = simplify_checked(&h, 0.0);
        assert!(tin.triangles.len() <= 1);
        assert!(tin.vertices.len() <= 3);
    }
}

/// An all-nodata window gives an empty TIN.
#[test]
fn an_all_nodata_window_is_empty() {
    let z = vec![f32::NAN; 12 * 9];
    let h = Heights {
        width: 12,
        height: 9,
        z: &z,
    };
    assert_eq!(simplify_checked(&h, 0.1), Tin::default());
    assert_eq!(measure(&h, &Tin::default()).points, 0);
}

/// Holes inside, at the corners, along an edge and a whole nodata edge: no triangle holds
/// nodata, every valid point away from the holes is covered, the bound holds.
#[test]
fn holes_inside_at_corners_along_edges() {
    let (w, ht) = (24, 19);
    let base = rough(w, ht, 3, 50.0, 8.0);
    type Hole = Box<dyn Fn(usize, usize) -> bool>;
    let cases: [(&str, Hole); 6] = [
        (
            "inside",
            Box::new(|c, r| (8..12).contains(&c) && (5..9).contains(&r)),
        ),
        ("single", Box::new(|c, r| (c, r) == (10, 1))),
        (
            "corners",
            Box::new(move |c, r| (c < 2 && r < 2) || (c == w - 1 && r == ht - 1)),
        ),
        (
            "along an edge",
            Box::new(|c, r| r <= 1 && (5..15).contains(&c)),
        ),
        ("a whole edge", Box::new(|c, _| c == 0)),
        ("diagonal band", Box::new(|c, r| c.abs_diff(r) <= 1)),
    ];
    for (name, hole) in cases {
        let z = holes(w, base.clone(), hole);
        let h = Heights {
            width: w,
            height: ht,
            z: &z,
        };
        for bound in [0.0, 0.3, 2.0, 100.0] {
            let tin = simplify_checked(&h, bound);
            assert!(!tin.triangles.is_empty(), "{name}");
        }
    }
}

/// Nodata along a flat border edge with a hole next to it: the long border segment is still
/// covered (nodata points are never made vertices, which would pull the hull edge's triangle
/// onto the hole).
#[test]
fn a_hole_next_to_a_flat_border_segment_leaves_it_covered() {
    let z = holes(11, vec![0.0f32; 11 * 6], |c, r| (c, r) == (5, 1));
    let h = Heights {
        width: 11,
        height: 6,
        z: &z,
    };
    let tin = simplify_checked(&h, 0.1);
    let m = measure(&h, &tin);
    assert_eq!(m.points, 11 * 6 - 1);
}

/// Same input, same TIN: vertices, triangles and their order.
#[test]
fn simplify_is_deterministic() {
    let z = holes(65, rough(65, 40, 5, 300.0, 10.0), |c, r| {
        (c * 7 + r * 3) % 41 == 0
    });
    let h = Heights {
        width: 65,
        height: 40,
        z: &z,
    };
    let a = simplify(&h, 0.2);
    let copy = z.clone();
    let b = simplify(
        &Heights {
            width: 65,
            height: 40,
            z: &copy,
        },
        0.2,
    );
    assert_eq!(a, b);
    assert!(a.triangles.len() > 100);
}

/// The height a TIN gives point `q` of its window, from the triangle holding it.
fn height_at(h: &Heights, tin: &Tin, q: [i64; 2]) -> f64 {
    tin.triangles
        .iter()
        .map(|t| Facet::new(t.map(|i| corner(tin, i)), h))
        .find_map(|f| {
            let w = f.weights(q);
            w.iter().all(|&x| x >= 0).then(|| f.interpolate(w))
        })
        .expect("the point is covered")
}

/// Two windows cut from one array, overlapping by one column (and separately by one row),
/// keep the same points on the shared edge and interpolate it bit for bit the same.
#[test]
fn adjacent_windows_share_their_edge() {
    let (w, ht) = (41, 33);
    let big = rough(w, ht, 9, 120.0, 12.0);
    let cut = |c0: usize, c1: usize, r0: usize, r1: usize| {
        window(c1 - c0 + 1, r1 - r0 + 1, |c, r| big[(r0 + r) * w + c0 + c])
    };
    for bound in [0.0, 0.1, 0.7] {
        // Overlap of one column: column 20 is the west window's east edge, the east's west.
        let (west, east) = (cut(0, 20, 0, 32), cut(20, 40, 0, 32));
        let hw = Heights {
            width: 21,
            height: 33,
            z: &west,
        };
        let he = Heights {
            width: 21,
            height: 33,
            z: &east,
        };
        let (tw, te) = (simplify_checked(&hw, bound), simplify_checked(&he, bound));
        let on = |tin: &Tin, c: u32| -> Vec<u32> {
            tin.vertices
                .iter()
                .filter(|v| v[0] == c)
                .map(|v| v[1])
                .collect()
        };
        assert_eq!(on(&tw, 20), on(&te, 0));
        for r in 0..33 {
            let (a, b) = (height_at(&hw, &tw, [20, r]), height_at(&he, &te, [0, r]));
            assert_eq!(a.to_bits(), b.to_bits(), "row {r}");
        }
        // Overlap of one row: row 16 is the north window's south edge, the south's north.
        let (north, south) = (cut(0, 40, 0, 16), cut(0, 40, 16, 32));
        let hn = Heights {
            width: 41,
            height: 17,
            z: &north,
        };
        let hs = Heights {
            width: 41,
            height: 17,
            z: &south,
        };
        let (tn, ts) = (simplify_checked(&hn, bound), simplify_checked(&hs, bound));
        let on = |tin: &Tin, r: u32| -> Vec<u32> {
            tin.vertices
                .iter()
                .filter(|v| v[1] == r)
                .map(|v| v[0])
                .collect()
        };
        assert_eq!(on(&tn, 16), on(&ts, 0));
        for c in 0..41 {
            let (a, b) = (height_at(&hn, &tn, [c, 16]), height_at(&hs, &ts, [c, 0]));
            assert_eq!(a.to_bits(), b.to_bits(), "column {c}");
        }
    }
}

/// `max_error = 0` on integer heights gives a TIN that reproduces every point exactly.
#[test]
fn a_zero_bound_on_integer_heights_is_exact() {
    for seed in 0..8 {
        let mut rng = SplitMix(seed);
        let (w, ht) = (
            2 + (rng.next_u64() % 20) as usize,
            2 + (rng.next_u64() % 20) as usize,
        );
        let z = window(w, ht, |_, _| (rng.next_u64() % 9) as f32 - 4.0);
        let h = Heights {
            width: w,
            height: ht,
            z: &z,
        };
        let tin = simplify_checked(&h, 0.0);
        let m = measure(&h, &tin);
        assert_eq!((m.max, m.points), (0.0, w * ht));
    }
}

/// `measure` counts each covered valid point once and reports the rms.
#[test]
fn measure_counts_each_point_once() {
    let z = window(3, 3, |c, r| if (c, r) == (1, 1) { 3.0 } else { 0.0 });
    let h = Heights {
        width: 3,
        height: 3,
        z: &z,
    };
    let tin = Tin {
        vertices: vec![[0, 0], [2, 0], [0, 2], [2, 2]],
        triangles: vec![[0, 1, 3], [0, 3, 2]],
    };
    let m = measure(&h, &tin);
    assert_eq!((m.max, m.points), (3.0, 9));
    assert!((m.rms - 1.0).abs() < 1e-12);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// Random rough windows, with and without holes, at bounds from 0: the brute-force bound,
    /// coverage and shape checks hold.
    #[test]
    fn random_windows_keep_the_bound_and_tile(
        w in 2usize..=18,
        ht in 2usize..=18,
        seed in any::<u64>(),
        hole_share in prop::sample::select(vec![0.0, 0.1, 0.35]),
        bound in prop::sample::select(vec![0.0, 0.05, 0.5, 3.0]),
        base in prop::sample::select(vec![0.0f32, 4000.0]),
    ) {
        let z = holes(w, rough(w, ht, seed, base, 6.0), |c, r| {
            (noise(seed, 99, c as i64, r as i64) + 1.0) / 2.0 < hole_share
        });
        let h = Heights { width: w, height: ht, z: &z };
        simplify_checked(&h, bound);
    }
}

/// Timings (run with `--ignored --nocapture`): rough windows of 257² and 1025² points at
/// several bounds, triangles and milliseconds.
#[test]
#[ignore]
fn timings() {
    for (n, relief) in [(257, 8.0), (257, 20.0), (1025, 8.0)] {
        let z = rough(n, n, 1, 500.0, relief);
        let h = Heights {
            width: n,
            height: n,
            z: &z,
        };
        for bound in [0.05, 0.1, 0.25, 1.0] {
            let t0 = std::time::Instant::now();
            let tin = simplify(&h, bound);
            let ms = t0.elapsed().as_secs_f64() * 1e3;
            let m = measure(&h, &tin);
            println!(
                "{n}² relief {relief} at {bound} m: {} vertices, {} triangles, {ms:.1} ms (max {:.3}, rms {:.3})",
                tin.vertices.len(),
                tin.triangles.len(),
                m.max,
                m.rms
            );
        }
    }
}

proptest! {
    /// A triangle's row spans hold exactly the grid points whose weights are all >= 0, in
    /// (row, column) order, whatever the corners' order and orientation.
    #[test]
    fn spans_are_the_points_inside_or_on_the_triangle(
        p in prop::array::uniform3(prop::array::uniform2(0i64..12)),
    ) {
        let z = vec![0.0f32; 144];
        let h = Heights { width: 12, height: 12, z: &z };
        let f = Facet::new(p, &h);
        prop_assume!(f.area2 != 0);
        let brute: Vec<[i64; 2]> = (0..12)
            .flat_map(|y| (0..12).map(move |x| [x, y]))
            .filter(|&q| f.weights(q).iter().all(|&w| w >= 0))
            .collect();
        prop_assert_eq!(f.points().collect::<Vec<_>>(), brute);
    }

    /// The plane `worst` ranks by is the exact interpolation up to rounding, at UTM heights.
    #[test]
    fn the_gradient_is_the_interpolation(
        p in prop::array::uniform3(prop::array::uniform2(0i64..12)),
        z in prop::array::uniform3(3990.0f32..4010.0),
    ) {
        let mut grid = vec![0.0f32; 144];
        for k in 0..3 {
            grid[p[k][1] as usize * 12 + p[k][0] as usize] = z[k];
        }
        let h = Heights { width: 12, height: 12, z: &grid };
        let f = Facet::new(p, &h);
        prop_assume!(f.area2 != 0);
        let (gx, gy) = f.gradient();
        for q in f.points() {
            let plane = f.z[0] + gx * (q[0] - f.p[0][0]) as f64 + gy * (q[1] - f.p[0][1]) as f64;
            prop_assert!((plane - f.interpolate(f.weights(q))).abs() < 1e-9);
        }
    }
}

/// The known gap: in a window two points high every point is on the border, so nothing can
/// be inserted; when the Delaunay triangle over the north edge's only segment takes a nodata
/// point of the south edge as its apex (spade's pick of two co-circular ones), that whole
/// segment stays uncovered though most of its points are not next to the hole.
#[test]
fn a_border_segment_opposite_a_nodata_apex_can_stay_uncovered() {
    let covered_north = |hole: usize| {
        let z = holes(10, vec![0.0f32; 20], |c, r| (c, r) == (hole, 1));
        let h = Heights {
            width: 10,
            height: 2,
            z: &z,
        };
        let tin = simplify_checked(&h, 0.1);
        (0..10i64)
            .filter(|&c| {
                tin.triangles.iter().any(|t| {
                    let f = Facet::new(t.map(|i| corner(&tin, i)), &h);
                    f.weights([c, 0]).iter().all(|&w| w >= 0)
                })
            })
            .collect::<Vec<_>>()
    };
    assert_eq!(covered_north(4), [0, 9]);
    assert_eq!(covered_north(5), (0..10).collect::<Vec<_>>());
}
