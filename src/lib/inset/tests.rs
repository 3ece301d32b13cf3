use super::*;
use crate::crs::Crs;

/// A 10 m base grid at UTM magnitudes: 200 x 150 cells from (500 000, 5 000 000).
fn base() -> Grid {
    Grid::north_up(500_000.0, 5_000_000.0, 10.0, 200, 150, Crs::epsg(32632))
}

fn spec(name: &str, parent: Option<&str>, factor: usize, w: [usize; 4]) -> InsetSpec {
    InsetSpec {
        name: name.into(),
        parent: parent.map(str::to_string),
        factor,
        window: CellWindow {
            col0: w[0],
            row0: w[1],
            col1: w[2],
            row1: w[3],
        },
    }
}

fn bounds(min_x: f64, min_y: f64, max_x: f64, max_y: f64) -> Bounds {
    Bounds {
        min_x,
        min_y,
        max_x,
        max_y,
    }
}

fn err<T: std::fmt::Debug>(r: Result<T>) -> String {
    let e = r.unwrap_err().to_string();
    assert!(!e.contains('\n'), "one line: {e}");
    e
}

/// 10 m → 1 m → 0.1 m at UTM magnitudes: each inset's corner is its parent's cell edge, its
/// cell the parent's / factor; every inset cell edge on a parent edge is that edge to f64
/// rounding; every inset cell centre lies in the parent cell `parent_cell` names.
#[test]
fn grids_derive_exactly_at_utm_magnitudes() {
    let b = base();
    let a = spec("a", None, 10, [123, 45, 131, 51]);
    let n = spec("n", Some("a"), 10, [17, 9, 29, 21]);
    let ga = a.grid(&b);
    assert_eq!((ga.width, ga.height), (80, 60));
    assert_eq!(
        (ga.transform.origin_x, ga.transform.origin_y),
        (501_230.0, 4_999_550.0)
    );
    assert_eq!((ga.transform.cell_x, ga.transform.cell_y), (1.0, -1.0));
    let gn = grid_of("n", &[a.clone(), n.clone()], &b).unwrap();
    assert_eq!(gn, n.grid(&ga));
    assert_eq!((gn.width, gn.height), (120, 120));
    assert_eq!(
        (gn.transform.origin_x, gn.transform.origin_y),
        (501_247.0, 4_999_541.0)
    );
    assert_eq!(gn.transform.cell_x, 0.1);
    assert_eq!(gn.crs, b.crs);
    for (child, parent, s) in [(&ga, &b, &a), (&gn, &ga, &n)] {
        for k in 0..=s.window.width() {
            let (xi, _) = child.transform.pixel_to_world((k * s.factor) as f64, 0.0);
            let (xp, _) = parent
                .transform
                .pixel_to_world((s.window.col0 + k) as f64, 0.0);
            assert!((xi - xp).abs() <= 2e-9, "{xi} vs {xp}");
        }
        for k in 0..=s.window.height() {
            let (_, yi) = child.transform.pixel_to_world(0.0, (k * s.factor) as f64);
            let (_, yp) = parent
                .transform
                .pixel_to_world(0.0, (s.window.row0 + k) as f64);
            assert!((yi - yp).abs() <= 2e-9, "{yi} vs {yp}");
        }
        for r in 0..child.height {
            for c in 0..child.width {
                let (x, y) = child.cell_centre(c, r);
                assert_eq!(parent.cell_at(x, y), Some(s.parent_cell(c, r)), "({c},{r})");
            }
        }
    }
    // 0.1 m cells 1 cm apart stay apart at y = 5e6.
    let (_, y0) = gn.cell_centre(0, 0);
    let (_, y1) = gn.cell_centre(0, 1);
    assert!(((y0 - y1) - 0.1).abs() < 1e-9);
}

#[test]
fn bounds_on_the_parent_edges_give_the_window() {
    let s = InsetSpec::from_bounds(
        "town",
        None,
        4,
        &bounds(500_100.0, 4_999_000.0, 500_300.0, 4_999_250.0),
        &base(),
    )
    .unwrap();
    assert_eq!(s.window, spec("t", None, 4, [10, 75, 30, 100]).window);
    assert_eq!(
        s.grid(&base()).bounds(),
        bounds(500_100.0, 4_999_000.0, 500_300.0, 4_999_250.0)
    );
    // f64 noise in the bounds is no misalignment.
    let noisy = bounds(
        500_100.000_000_01,
        4_999_000.0,
        500_300.0,
        4_999_249.999_999_99,
    );
    assert_eq!(
        InsetSpec::from_bounds("town", None, 4, &noisy, &base())
            .unwrap()
            .window,
        s.window
    );
}

#[test]
fn misaligned_bounds_say_by_how_much_and_give_the_snapped_bounds() {
    let e = err(InsetSpec::from_bounds(
        "town",
        None,
        4,
        &bounds(500_103.2, 4_999_000.0, 500_300.0, 4_999_251.5),
        &base(),
    ));
    assert!(e.contains("inset town: bounds 500103.2,4999000,500300,4999251.5 are not on the cell edges of its parent (the base grid, 10 x 10 metre cells)"), "{e}");
    assert!(e.contains("MINX by 3.2 m, MAXY by 1.5 m off"), "{e}");
    assert!(
        e.ends_with("give the bounds snapped outward to them: 500100,4999000,500300,4999260"),
        "{e}"
    );
}

#[test]
fn bounds_outside_the_parent_give_the_part_inside() {
    let e = err(InsetSpec::from_bounds(
        "town",
        None,
        4,
        &bounds(499_900.0, 4_999_000.0, 500_300.0, 4_999_250.0),
        &base(),
    ));
    assert!(e.contains("inset town: bounds 499900,4999000,500300,4999250 reach outside its parent (the base grid, extent 500000,4998500,502000,5000000)"), "{e}");
    assert!(
        e.ends_with("e.g. the part that is: 500000,4999000,500300,4999250"),
        "{e}"
    );
    let e = err(InsetSpec::from_bounds(
        "town",
        None,
        4,
        &bounds(400_000.0, 4_999_000.0, 400_300.0, 4_999_250.0),
        &base(),
    ));
    assert!(e.ends_with("give bounds inside the parent's extent"), "{e}");
}

#[test]
fn factors_must_be_whole_numbers_from_2_to_10() {
    assert_eq!(parse_factor("t", "4").unwrap(), 4);
    assert_eq!(parse_factor("t", "10").unwrap(), 10);
    for bad in ["2.5", "1", "11", "0", "-3", "four", ""] {
        let e = err(parse_factor("t", bad));
        assert!(
            e.starts_with(&format!(
                "inset t: factor {bad} is not a whole number from 2 to 10"
            )),
            "{e}"
        );
        assert!(e.contains("nest insets for more than 10"), "{e}");
    }
    assert!(check_factor("t", 2).is_ok());
    assert!(err(check_factor("t", 12)).contains("factor 12"));
}

#[test]
fn names_are_plain() {
    for good in ["town", "T-2", "road_1"] {
        assert!(check_name(good).is_ok(), "{good}");
    }
    for bad in ["", "../x", "a/b", "-x", ".hidden", "a b", &"x".repeat(65)] {
        let e = err(check_name(bad));
        assert!(
            e.contains("is not a plain name") && e.contains("e.g. town"),
            "{e}"
        );
    }
}

#[test]
fn option_arguments_parse_and_check() {
    let (n, f, b) = parse_inset_arg("town:4:500100,4999000,500300,4999250").unwrap();
    assert_eq!((n.as_str(), f), ("town", 4));
    assert_eq!(b, bounds(500_100.0, 4_999_000.0, 500_300.0, 4_999_250.0));
    assert!(err(parse_inset_arg("town:4")).contains("expected NAME:FACTOR:MINX,MINY,MAXX,MAXY"));
    assert!(err(parse_inset_arg("town:2.5:0,0,1,1")).contains("factor 2.5"));
    assert!(err(parse_inset_arg("a/b:2:0,0,1,1")).contains("not a plain name"));
    assert!(err(parse_inset_arg("town:2:0,0,1")).contains("four numbers"));
    assert!(err(parse_inset_arg("town:2:5,0,1,1")).contains("MINX must be below MAXX"));
    let (n, f, buf) = parse_corridor_arg("road:10:30").unwrap();
    assert_eq!((n.as_str(), f, buf), ("road", 10, 30.0));
    assert!(err(parse_corridor_arg("road:10")).contains("expected NAME:FACTOR:BUFFER_M"));
    assert!(err(parse_corridor_arg("road:10:-1")).contains("not a distance above 0"));
    assert!(err(parse_corridor_arg("road:10:0")).contains("not a distance above 0"));
    assert!(err(parse_corridor_arg("road:1:5")).contains("factor 1"));
}

#[test]
fn check_new_accepts_nesting_and_refuses_each_bad_definition() {
    let b = base();
    let a = spec("a", None, 10, [10, 10, 20, 20]);
    let have = vec![a.clone()];
    // Nested inside a, and a sibling of a beside it: fine.
    let g = check_new(&spec("n", Some("a"), 4, [0, 0, 100, 100]), &have, &b).unwrap();
    assert_eq!(g.transform.cell_x, 0.25);
    assert!(check_new(&spec("s", None, 2, [20, 10, 30, 20]), &have, &b).is_ok());
    let cases: [(InsetSpec, &str); 7] = [
        (spec("a", None, 2, [50, 50, 60, 60]), "inset a already exists in this database; give the new inset another name"),
        (spec("x", Some("zz"), 2, [0, 0, 1, 1]), "inset parent zz is not an inset of this database (it has a); give --inset-parent one of its insets"),
        (spec("x", None, 11, [50, 50, 60, 60]), "inset x: factor 11 is not a whole number from 2 to 10"),
        (spec("x", None, 2, [50, 50, 50, 60]), "inset x: its window (columns 50..50, rows 50..60) holds no parent cell"),
        (spec("x", None, 2, [190, 50, 201, 60]), "inset x: its window (columns 190..201, rows 50..60) reaches outside its parent (the base grid, 200 x 150 cells)"),
        (spec("x", Some("a"), 2, [90, 0, 101, 5]), "reaches outside its parent (a, 100 x 100 cells)"),
        (spec("x", None, 2, [15, 19, 25, 30]), "inset x overlaps inset a (both refine the base grid) over 500150,4999800,500200,4999810; move or shrink it off a, or nest it inside a with --inset-parent a"),
    ];
    for (s, want) in cases {
        let e = err(check_new(&s, &have, &b));
        assert!(e.contains(want), "want {want:?} in {e}");
    }
    let e = err(check_new(&spec("x", Some("a"), 2, [0, 0, 1, 1]), &[], &b));
    assert!(e.contains("(it has none)"), "{e}");
    // Siblings inside a parent inset are checked against each other, not against the base's.
    let two = vec![a.clone(), spec("n", Some("a"), 2, [0, 0, 10, 10])];
    assert!(err(check_new(
        &spec("m", Some("a"), 2, [5, 5, 12, 12]),
        &two,
        &b
    ))
    .contains("overlaps inset n"));
    assert!(check_new(&spec("m", Some("a"), 2, [10, 0, 20, 10]), &two, &b).is_ok());
}

#[test]
fn corridor_is_the_buffered_routes_cell_window_clipped_to_the_parent() {
    let b = base();
    let route = vec![vec![(500_105.0, 4_999_505.0), (500_255.0, 4_999_405.0)]];
    let w = corridor_window("road", &route, 20.0, &b).unwrap();
    // x 500085..500275 → columns 8..28; y 4999385..4999525 → rows 47..62.
    assert_eq!(w, spec("r", None, 2, [8, 47, 28, 62]).window);
    // Reaching past the parent's west edge: clipped.
    let west = vec![vec![(499_990.0, 4_999_505.0), (500_055.0, 4_999_505.0)]];
    let w = corridor_window("road", &west, 0.0, &b).unwrap();
    assert_eq!((w.col0, w.col1, w.row0, w.row1), (0, 6, 49, 50));
    let far = vec![vec![(9.0, 47.0), (9.1, 47.1)]];
    let e = err(corridor_window("road", &far, 5.0, &b));
    assert!(
        e.contains("corridor road: the route buffered by 5 m")
            && e.contains("misses its parent's extent 500000,4998500,502000,5000000"),
        "{e}"
    );
}

/// Parent cells of `g` within `buffer` of the route `lines`, found independently of the cover:
/// points every 0.25 m along the route, each marking the cells whose area it comes within
/// `buffer` of (a sampled distance is never below the true one, so every cell marked is truly
/// within the buffer).
fn cells_near(lines: &[Vec<(f64, f64)>], buffer: f64, g: &Grid) -> Vec<bool> {
    let mut near = vec![false; g.width * g.height];
    let (cx, cy) = g.cell_size();
    let reach = (buffer / cx.min(cy)).ceil() as i64 + 1;
    for line in lines {
        for p in line.windows(2) {
            let ((xa, ya), (xb, yb)) = (p[0], p[1]);
            let n = (((xb - xa).hypot(yb - ya)) / 0.25).ceil().max(1.0) as usize;
            for k in 0..=n {
                let t = k as f64 / n as f64;
                let (x, y) = (xa + t * (xb - xa), ya + t * (yb - ya));
                let (u, v) = (
                    ((x - g.transform.origin_x) / g.transform.cell_x).floor() as i64,
                    ((y - g.transform.origin_y) / g.transform.cell_y).floor() as i64,
                );
                for r in (v - reach).max(0)..(v + reach + 1).min(g.height as i64) {
                    for c in (u - reach).max(0)..(u + reach + 1).min(g.width as i64) {
                        let (x0, y1) = g.transform.pixel_to_world(c as f64, r as f64);
                        let (x1, y0) = g.transform.pixel_to_world(c as f64 + 1.0, r as f64 + 1.0);
                        let dx = (x0 - x).max(x - x1).max(0.0);
                        let dy = (y0 - y).max(y - y1).max(0.0);
                        if dx.hypot(dy) <= buffer {
                            near[r as usize * g.width + c as usize] = true;
                        }
                    }
                }
            }
        }
    }
    near
}

/// The cover's windows lie in the parent, never overlap, come north to south then west to east,
/// and hold every cell within the buffer of the route. Returns how many cells that is.
fn check_cover(cover: &corridor::CorridorCover, lines: &[Vec<(f64, f64)>], buffer: f64) -> usize {
    let g = base();
    let mut owner = vec![usize::MAX; g.width * g.height];
    for (k, w) in cover.windows.iter().enumerate() {
        assert!(
            !w.is_empty() && w.col1 <= g.width && w.row1 <= g.height,
            "{w}"
        );
        for r in w.row0..w.row1 {
            for c in w.col0..w.col1 {
                let o = &mut owner[r * g.width + c];
                assert_eq!(
                    *o,
                    usize::MAX,
                    "windows {} and {k} overlap at ({c},{r})",
                    *o
                );
                *o = k;
            }
        }
    }
    let order: Vec<(usize, usize)> = cover.windows.iter().map(|w| (w.row0, w.col0)).collect();
    let mut sorted = order.clone();
    sorted.sort();
    assert_eq!(order, sorted, "north to south, west to east");
    let near = cells_near(lines, buffer, &g);
    for (i, _) in near.iter().enumerate().filter(|(_, n)| **n) {
        assert_ne!(
            owner[i],
            usize::MAX,
            "cell ({},{}) within the buffer is not covered",
            i % g.width,
            i / g.width
        );
    }
    near.iter().filter(|n| **n).count()
}

#[test]
fn corridor_blocks_are_powers_of_two_about_the_buffer() {
    use corridor::block_cells;
    assert_eq!(block_cells(20.0, 10.0), 8);
    assert_eq!(block_cells(100.0, 1.0), 128);
    assert_eq!(block_cells(128.0, 1.0), 128);
    assert_eq!(block_cells(0.5, 1.0), 8);
    assert_eq!(block_cells(1000.0, 1.0), 1024);
}

/// An L-shaped route (east 1.4 km, then south 1.3 km, 25 m buffer, blocks of 8 cells = 80 m):
/// two arms, each a few rectangles, covering every cell within the buffer.
#[test]
fn an_l_shaped_corridor_is_a_few_windows_along_its_arms() {
    let b = base();
    let route = vec![vec![
        (500_105.0, 4_999_905.0),
        (501_505.0, 4_999_905.0),
        (501_505.0, 4_998_605.0),
    ]];
    let cover = corridor::corridor_cover("road", &route, 25.0, &b).unwrap();
    assert_eq!(cover.block_cells, 8);
    let near = check_cover(&cover, &route, 25.0);
    assert!(near > 0);
    // The east arm's buffer spans rows 7..12 (block rows 0 and 1), the south arm's columns
    // 148..153 (block columns 18 and 19): two rows of blocks, then two columns.
    assert_eq!(
        cover.windows,
        [[8, 0, 160, 8], [0, 8, 160, 16], [144, 16, 160, 144]]
            .map(|w| spec("w", None, 2, w).window)
    );
    assert!(cover.area_ratio() < 0.3, "{}", cover.area_ratio());
    let specs = cover.specs("road", None, 4).unwrap();
    let names: Vec<&str> = specs.iter().map(|s| s.name.as_str()).collect();
    let want: Vec<String> = (1..=specs.len()).map(|k| format!("road-{k}")).collect();
    assert_eq!(names, want);
    // Each joins the database beside the ones before it.
    let mut have: Vec<InsetSpec> = Vec::new();
    for s in specs {
        check_new(&s, &have, &b).unwrap();
        have.push(s);
    }
}

/// A diagonal across the whole parent (2 km x 1.5 km, 20 m buffer): its bounding rectangle is
/// the whole parent, its cover a staircase of one window per block row or so, far smaller.
#[test]
fn a_diagonal_corridor_covers_far_less_than_its_bounding_rectangle() {
    let b = base();
    let route = vec![vec![(500_000.0, 5_000_000.0), (502_000.0, 4_998_500.0)]];
    let cover = corridor::corridor_cover("diag", &route, 20.0, &b).unwrap();
    assert_eq!(cover.bounding, spec("d", None, 2, [0, 0, 200, 150]).window);
    let near = check_cover(&cover, &route, 20.0);
    assert!(cover.windows.len() >= 10, "{:?}", cover.windows);
    assert!(cover.area_ratio() < 0.25, "{}", cover.area_ratio());
    // Within a few blocks of what the buffer itself needs.
    assert!(
        cover.cells() < 3 * near as u64,
        "{} vs {near}",
        cover.cells()
    );
    // A MultiLineString's parts are covered alike, the windows still disjoint.
    let two = vec![
        route[0].clone(),
        vec![(500_000.0, 4_998_500.0), (502_000.0, 5_000_000.0)],
    ];
    let cover = corridor::corridor_cover("x", &two, 20.0, &b).unwrap();
    check_cover(&cover, &two, 20.0);
}

#[test]
fn a_corridor_outside_its_parent_or_without_a_buffer_is_a_one_line_error() {
    let b = base();
    let far = vec![vec![(9.0, 47.0), (9.1, 47.1)]];
    let e = err(corridor::corridor_cover("road", &far, 5.0, &b));
    assert!(
        e.contains("corridor road: the route buffered by 5 m")
            && e.contains("misses its parent's extent 500000,4998500,502000,5000000"),
        "{e}"
    );
    let route = vec![vec![(500_105.0, 4_999_505.0), (500_255.0, 4_999_405.0)]];
    for bad in [0.0, -3.0, f64::NAN] {
        let e = err(corridor::corridor_cover("road", &route, bad, &b));
        assert!(
            e.contains("corridor road: buffer") && e.contains("is not a distance above 0"),
            "{e}"
        );
    }
    // Past the parent's corner diagonally: the bounding rectangle reaches in, no block does.
    // (28 m from the corner at 500000,4998500, its buffered bounding box 60 m into the parent).
    let corner = vec![vec![(499_920.0, 4_998_540.0), (500_040.0, 4_998_420.0)]];
    assert!(corridor_window("road", &corner, 20.0, &b).is_ok());
    let e = err(corridor::corridor_cover("road", &corner, 20.0, &b));
    assert!(e.contains("misses its parent's extent"), "{e}");
    // A name too long for its members' names.
    let cover = corridor::corridor_cover("road", &route, 20.0, &b).unwrap();
    assert!(err(cover.specs(&"r".repeat(63), None, 2)).contains("is not a plain name"));
}
