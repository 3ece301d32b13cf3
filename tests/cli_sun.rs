//! `dbms sun` from the outside: values, JSON keys, `--db`, and one-line errors.

use dbms::crs::Crs;
use dbms::db::Database;
use dbms::grid::Grid;
#[path = "support/cli.rs"]
mod cli;
use cli::dbms;

fn json(args: &[&str]) -> serde_json::Value {
    let mut all = vec!["--json"];
    all.extend_from_slice(args);
    let out = dbms(&all);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("stdout is JSON")
}

fn f(v: &serde_json::Value, key: &str) -> f64 {
    v[key]
        .as_f64()
        .unwrap_or_else(|| panic!("no number {key} in {v}"))
}

/// An error run: fails, prints nothing on stdout and exactly one line on stderr.
fn one_line_error(args: &[&str]) -> String {
    let out = dbms(args);
    assert!(!out.status.success(), "{args:?} should fail");
    assert!(out.stdout.is_empty());
    let err = String::from_utf8_lossy(&out.stderr).to_string();
    assert_eq!(err.trim_end().lines().count(), 1, "{err}");
    assert!(err.starts_with("dbms: error: "), "{err}");
    err
}

const SPA_EXAMPLE: [&str; 16] = [
    "sun",
    "--lat",
    "39.742476",
    "--lon",
    "-105.1786",
    "--height",
    "1830.14",
    "--time",
    "2003-10-17T12:30:30-07:00",
    "--delta-t",
    "67",
    "--pressure",
    "820",
    "--temperature",
    "11",
    "--quiet",
];

/// The SPA paper's example (zenith 50.11162°, azimuth 194.34024°, printed to 5 decimals).
#[test]
fn spa_example_as_json() {
    let v = json(&SPA_EXAMPLE);
    assert!((f(&v, "zenith_deg") - 50.11162).abs() <= 5e-6, "{v}");
    assert!((f(&v, "azimuth_deg") - 194.34024).abs() <= 5e-6, "{v}");
    assert!(
        (f(&v, "elevation_deg") - (90.0 - 50.11162)).abs() <= 5e-6,
        "{v}"
    );
    // The inputs come back too, the time normalised to UTC.
    assert_eq!(v["time"], "2003-10-17T19:30:30Z");
    assert_eq!(
        (
            f(&v, "latitude_deg"),
            f(&v, "longitude_deg"),
            f(&v, "height_m")
        ),
        (39.742476, -105.1786, 1830.14)
    );
    assert_eq!(
        (
            f(&v, "pressure_mbar"),
            f(&v, "temperature_c"),
            f(&v, "delta_t_s")
        ),
        (820.0, 11.0, 67.0)
    );
    assert_eq!(v["refraction"], true);
}

#[test]
fn human_output_names_the_three_angles() {
    let out = dbms(&SPA_EXAMPLE[..SPA_EXAMPLE.len() - 1]);
    assert!(out.status.success());
    let text = String::from_utf8_lossy(&out.stdout);
    for want in [
        "elevation",
        "39.888378",
        "azimuth",
        "194.340241",
        "zenith",
        "50.111622",
        "with refraction",
    ] {
        assert!(text.contains(want), "{want} missing from {text}");
    }
    // --quiet: nothing on stdout.
    assert!(dbms(&SPA_EXAMPLE).stdout.is_empty());
}

#[test]
fn no_refraction_gives_the_geometric_sun() {
    let base = [
        "sun",
        "--lat",
        "52",
        "--lon",
        "4.9",
        "--time",
        "2026-03-20T17:55:00Z",
    ];
    let seen = json(&base);
    let mut geo_args = base.to_vec();
    geo_args.push("--no-refraction");
    let geo = json(&geo_args);
    assert_eq!(geo["refraction"], false);
    let lift = f(&seen, "elevation_deg") - f(&geo, "elevation_deg");
    // Amsterdam near sunset: the sun is within a few degrees of the horizon.
    assert!(f(&geo, "elevation_deg").abs() < 3.0, "{geo}");
    assert!(lift > 0.1 && lift < 0.6, "refraction lift {lift}");
    assert_eq!(f(&seen, "azimuth_deg"), f(&geo, "azimuth_deg"));
}

#[test]
fn default_delta_t_is_reported() {
    let v = json(&[
        "sun",
        "--lat",
        "0",
        "--lon",
        "0",
        "--time",
        "2024-01-01T00:00:00Z",
    ]);
    let dt = f(&v, "delta_t_s");
    assert!(dt > 63.0 && dt < 76.0, "{v}");
    assert!(v["delta_t_source"].as_str().unwrap().contains("Espenak"));
}

/// `--db` takes the observer from the database's centre: same answer as giving that centre.
#[test]
fn db_centre_is_the_observer() {
    let dir = tempfile::tempdir().unwrap();
    // 10 km square in UTM 13N around Golden, Colorado.
    let grid = Grid::north_up(470_000.0, 4_405_000.0, 10.0, 1000, 1000, Crs::epsg(32613));
    Database::create(dir.path(), grid, Vec::new())
        .unwrap()
        .save()
        .unwrap();
    let db = dir.path().to_str().unwrap();
    let time = "2026-06-21T18:00:00Z";
    let v = json(&["sun", "--db", db, "--time", time]);
    let (lat, lon) = (f(&v, "latitude_deg"), f(&v, "longitude_deg"));
    assert!(
        (lat - 39.75).abs() < 0.1 && (lon + 105.35).abs() < 0.1,
        "centre {lat}, {lon}"
    );
    assert_eq!(v["db"], db);
    let direct = json(&[
        "sun",
        "--lat",
        &lat.to_string(),
        "--lon",
        &lon.to_string(),
        "--time",
        time,
    ]);
    for key in ["elevation_deg", "azimuth_deg", "zenith_deg"] {
        assert_eq!(f(&v, key), f(&direct, key), "{key}");
    }
}

#[test]
fn db_reports_the_azimuth_from_grid_north() {
    // Near the east edge of UTM 13N at 39.7° N grid north is about 1.9° east of true north, so
    // a shadow cast along the true azimuth would be off by that much.
    let dir = tempfile::tempdir().unwrap();
    let grid = Grid::north_up(750_000.0, 4_405_000.0, 10.0, 100, 100, Crs::epsg(32613));
    Database::create(dir.path(), grid, Vec::new())
        .unwrap()
        .save()
        .unwrap();
    let db = dir.path().to_str().unwrap();
    let v = json(&["sun", "--db", db, "--time", "2026-06-21T18:00:00Z"]);
    let gamma = f(&v, "grid_convergence_deg");
    assert!((1.7..2.1).contains(&gamma), "{v}");
    let expect = (f(&v, "azimuth_deg") - gamma).rem_euclid(360.0);
    assert!((f(&v, "grid_azimuth_deg") - expect).abs() < 1e-12, "{v}");
    // The stages take the same sun for the same time.
    let lib =
        dbms::sun::at_database_centre(&Database::open(dir.path()).unwrap(), "2026-06-21T18:00:00Z");
    assert!((lib.unwrap().azimuth_deg - expect).abs() < 1e-9);
    // Without a database there is no grid: no grid azimuth.
    let direct = json(&[
        "sun",
        "--lat",
        "39.7",
        "--lon",
        "-102",
        "--time",
        "2026-06-21T18:00:00Z",
    ]);
    assert!(direct["grid_azimuth_deg"].is_null() && direct["grid_convergence_deg"].is_null());
}

#[test]
fn db_without_geographic_centre_is_a_clear_error() {
    let dir = tempfile::tempdir().unwrap();
    // A CRS the default build cannot convert to latitude/longitude (Web Mercator).
    let grid = Grid::north_up(0.0, 1000.0, 10.0, 10, 10, Crs::epsg(3857));
    Database::create(dir.path(), grid, Vec::new())
        .unwrap()
        .save()
        .unwrap();
    let err = one_line_error(&[
        "sun",
        "--db",
        dir.path().to_str().unwrap(),
        "--time",
        "2026-06-21T18:00:00Z",
    ]);
    assert!(
        err.contains("latitude/longitude") && err.contains("--lat"),
        "{err}"
    );
    let err = one_line_error(&[
        "sun",
        "--db",
        dir.path().join("nope").to_str().unwrap(),
        "--time",
        "2026-06-21T18:00:00Z",
    ]);
    assert!(
        err.contains("nope") && err.contains("no such database"),
        "{err}"
    );
}

#[test]
fn bad_values_are_one_line_errors() {
    let t = "2026-06-21T10:00:00Z";
    let cases: [(&[&str], &str); 7] = [
        (
            &[
                "sun",
                "--lat",
                "0",
                "--lon",
                "0",
                "--time",
                "2026-06-21 10:00",
            ],
            "RFC 3339",
        ),
        (
            &[
                "sun",
                "--lat",
                "0",
                "--lon",
                "0",
                "--time",
                "2026-06-21T10:00:00",
            ],
            "offset is required",
        ),
        (
            &["sun", "--lat", "95", "--lon", "0", "--time", t],
            "latitude 95",
        ),
        (
            &["sun", "--lat", "0", "--lon", "-190", "--time", t],
            "longitude -190",
        ),
        (
            &[
                "sun",
                "--lat",
                "0",
                "--lon",
                "0",
                "--time",
                t,
                "--pressure",
                "-5",
            ],
            "pressure",
        ),
        (
            &[
                "sun",
                "--lat",
                "0",
                "--lon",
                "0",
                "--time",
                t,
                "--delta-t",
                "99999",
            ],
            "delta T",
        ),
        (
            &[
                "sun",
                "--lat",
                "0",
                "--lon",
                "0",
                "--time",
                "9999-01-01T00:00:00Z",
            ],
            "year 9999",
        ),
    ];
    for (args, want) in cases {
        let err = one_line_error(args);
        assert!(err.contains(want) && err.contains("; "), "{args:?}: {err}");
    }
}

/// Usage mistakes are clap's (exit code 2, one line): both places, or half of one.
#[test]
fn place_is_lat_lon_or_db() {
    let t = "2026-06-21T10:00:00Z";
    for args in [
        &["sun", "--lat", "1", "--lon", "2", "--db", "x", "--time", t][..],
        &["sun", "--lat", "1", "--time", t][..],
        &["sun", "--time", t][..],
    ] {
        let out = dbms(args);
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        assert!(out.stdout.is_empty());
    }
}

/// `--moon` against PyEphem 4.2.1 (a case of `moon::tests::PYEPHEM`: 70° N, the moon 6° up,
/// PyEphem's ΔT, no refraction): elevation and azimuth within 0.01°, the lit fraction within
/// 0.001, and light on the ground; without `--moon` no `moon` key.
#[test]
fn moon_agrees_with_pyephem() {
    let args = [
        "sun",
        "--lat",
        "67.8697",
        "--lon",
        "-137.52",
        "--height",
        "2088.4",
        "--time",
        "2011-05-15T08:12:16Z",
        "--delta-t",
        "66.4191351505828",
        "--no-refraction",
    ];
    let mut with = args.to_vec();
    with.push("--moon");
    let v = json(&with);
    let m = &v["moon"];
    assert!(
        (f(m, "elevation_deg") - 6.448635593068798).abs() < 0.01,
        "{m}"
    );
    assert!((f(m, "azimuth_deg") - 196.57224325632).abs() < 0.01, "{m}");
    assert!(
        (f(m, "illuminated_fraction") - 0.9348629760742188).abs() < 0.001,
        "{m}"
    );
    assert!(f(&m["light"], "horizontal_lux") > 0.0, "{m}");
    assert!(f(m, "night_sky_lux") > 0.0);
    assert!(json(&args).get("moon").is_none());
    let text = String::from_utf8(dbms(&with).stdout).unwrap();
    assert!(
        text.contains("moon:") && text.contains("lux on the ground"),
        "{text}"
    );
}
