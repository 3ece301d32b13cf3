//! `dbms shadow-height` on a real photo against a real truth (issue 39): IGN's Montpellier
//! block, source "IGN — LiDAR HD and BD ORTHO" (Licence Ouverte / Etalab 2.0), in
//! `tests/data/ign_montpellier` (its README says what each file is and how it was made).
//!
//! `dbms ingest` puts IGN's terrain model (0.5 m) and the 0.2 m orthophoto on a 0.5 m grid (the
//! terrain's cell, and the cell the real-town harness uses); `dbms shadow-height`
//! measures the footprints traced from the LiDAR's building points under the sun estimated
//! from the photo's shadows (`sun.json`), and its roofs are compared with the LiDAR's.
//! The photo is not a true orthophoto and the sun runs almost along the block's ridge, so
//! dbms flags every building today (docs/shadow-height.md, "Real data: IGN Montpellier").

#[path = "support/cli.rs"]
mod cli;
#[path = "support/real_truth.rs"]
mod real_truth;

use real_truth::{compare, data_dir, read_sun, read_truth, table, write_bare_footprints, Row};
use serde_json::Value;
use std::sync::OnceLock;

/// The database grid's cell, metres: the unit of the "off by more than 2 cells".
const CELL_M: f64 = 0.5;

/// Flags that say why a shadow could not be followed to a height.
const REASONS: [&str; 6] = [
    "no_shadow",
    "shadow_cut_by_edge_or_nodata",
    "shadow_on_other_building",
    "footprint_off_photo",
    "low_sun",
    "high_sun",
];

fn run(args: &[&str], dir: &std::path::Path) {
    let out = cli::dbms_in(dir, args);
    assert!(
        out.status.success(),
        "dbms {args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// Ingest + shadow-height once for every test of this file; the rows in the truth's order.
fn rows() -> &'static [Row] {
    static ROWS: OnceLock<Vec<Row>> = OnceLock::new();
    ROWS.get_or_init(|| {
        let data = data_dir();
        let t = tempfile::tempdir().unwrap();
        write_bare_footprints(
            &data.join("footprints.geojson"),
            &t.path().join("fp.geojson"),
        );
        let (az, el) = read_sun(&data.join("sun.json"));
        let (dem, ortho) = (data.join("dtm_0p50m.tif"), data.join("ortho_rgb_0p20m.tif"));
        let cell = CELL_M.to_string();
        run(
            &[
                "ingest",
                "--dem",
                dem.to_str().unwrap(),
                "--ortho",
                ortho.to_str().unwrap(),
                "--cell",
                &cell,
                "-o",
                "db",
            ],
            t.path(),
        );
        let (az, el) = (az.to_string(), el.to_string());
        run(
            &[
                "shadow-height",
                "--db",
                "db",
                "--footprints",
                "fp.geojson",
                "--sun-azimuth",
                &az,
                "--sun-elevation",
                &el,
                "-o",
                "h.geojson",
            ],
            t.path(),
        );
        let text = std::fs::read_to_string(t.path().join("h.geojson")).unwrap();
        let heights: Value = serde_json::from_str(&text).unwrap();
        compare(&read_truth(&data.join("footprints.geojson")), &heights)
    })
}

#[test]
fn every_real_building_gets_a_height_a_lower_bound_or_a_reason() {
    let rows = rows();
    assert_eq!(rows.len(), 10, "the parts make_truth.py outlined");
    for r in rows {
        let reason = r.flags.iter().any(|f| REASONS.contains(&f.as_str()));
        assert!(
            r.roof_z.is_some() || r.at_least.is_some() || reason,
            "{} has no height, no lower bound and no reason:\n{}",
            r.truth.name,
            table(rows, CELL_M)
        );
    }
}

/// 2 cells (1 m) is the bound. What limits a right answer here: the LiDAR's roofs are
/// good to ~0.1 m (faces' RMS 2-9 cm), the sun's elevation to ±2.2°, which moves a height
/// from a shadow by ±7.9 %: ±1.2 cells on the 7.3 m block.
#[test]
fn no_unflagged_real_height_is_off_the_lidar_by_more_than_two_cells() {
    let rows = rows();
    for r in rows {
        if let (Some(e), true) = (r.error_cells(CELL_M), r.flags.is_empty()) {
            assert!(
                e.abs() <= 2.0,
                "{}: unflagged roof {e:+.1} cells off the LiDAR:\n{}",
                r.truth.name,
                table(rows, CELL_M)
            );
        }
    }
}

/// The "within 1 m of truth (the ridge, for pitched roofs) for ≥ 90 % of buildings",
/// flagged or not; 1 m is 2 cells here. Measured on 2376fe8 (sun 135°/54°): 0 of 10 (two
/// heights, b2 4.3 and b10 13.5 cells low, both flagged).
#[test]
#[ignore = "dbms measures 0 of the 10 real roofs within 2 cells (2 heights, 4.3 and 13.5 cells low, flagged), issue 39"]
fn real_roofs_within_two_cells_for_nine_in_ten() {
    let rows = rows();
    let close = rows
        .iter()
        .filter(|r| r.error_cells(CELL_M).is_some_and(|e| e.abs() <= 2.0))
        .count();
    assert!(
        close as f64 >= 0.9 * rows.len() as f64,
        "{close} of {} within 2 cells:\n{}",
        rows.len(),
        table(rows, CELL_M)
    );
}

/// The "truth outside the reported 95 % interval for ≤ 5 %" over the measured roofs.
#[test]
#[ignore = "b10's 95 % interval [21.32, 22.52] m misses its 28.50 m ridge (1 of 2 measured), issue 39"]
fn real_roofs_lie_inside_their_95_percent_interval() {
    let rows = rows();
    let measured: Vec<&Row> = rows.iter().filter(|r| r.interval_95.is_some()).collect();
    let outside = measured
        .iter()
        .filter(|r| {
            let (lo, hi) = r.interval_95.unwrap();
            r.truth.roof_z < lo || r.truth.roof_z > hi
        })
        .count();
    assert!(
        outside as f64 <= 0.05 * measured.len() as f64,
        "{outside} of {} measured roofs outside their 95 % interval:\n{}",
        measured.len(),
        table(rows, CELL_M)
    );
}
