//! The one-line error contract across commands (issue 14, defect 13): argument errors, I/O
//! errors, a file given as a database, GeoJSON with a byte order mark or in lon/lat, and
//! warnings summarised rather than one line per skipped feature; inputs that are not regular
//! files or are too large to be what they claim (issue 40, defect 4).

use dbms::crs::Crs;
use dbms::grid::Grid;
use dbms::io::geotiff;
use dbms::raster::Raster;
use serde_json::json;
use std::path::Path;
use std::process::Output;
#[path = "support/cli.rs"]
mod cli;
use cli::{dbms_in, dbms_in_within};
use std::time::Duration;

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Failed with `status`, one `dbms: error:` line on stderr containing `needle`, nothing on stdout.
fn assert_one_line(o: &Output, status: i32, needle: &str) {
    let err = stderr(o);
    assert_eq!(o.status.code(), Some(status), "{err}");
    assert_eq!(err.lines().count(), 1, "want one line: {err}");
    assert!(err.starts_with("dbms: error: "), "{err}");
    assert!(err.contains(needle), "want {needle:?} in: {err}");
    assert!(!err.contains("os error"), "{err}");
    assert!(o.stdout.is_empty());
}

/// A flat 40 × 40 m database of 0.5 m cells at UTM 32N (500 000, 5 300 000).
fn database(dir: &Path) {
    let g = Grid::north_up(500_000.0, 5_300_040.0, 0.5, 80, 80, Crs::epsg(32632));
    geotiff::write_f32(&dir.join("dem.tif"), &Raster::filled(g.clone(), 100.0f32)).unwrap();
    geotiff::write_rgba8(
        &dir.join("ortho.tif"),
        &Raster::filled(g, [90, 90, 90, 255]),
    )
    .unwrap();
    let o = dbms_in(
        dir,
        &[
            "ingest",
            "-q",
            "--dem",
            "dem.tif",
            "--ortho",
            "ortho.tif",
            "-o",
            "db",
        ],
    );
    assert!(o.status.success(), "{}", stderr(&o));
}

fn square(x: f64, y: f64, side: f64) -> serde_json::Value {
    let ring = [
        [x, y],
        [x + side, y],
        [x + side, y + side],
        [x, y + side],
        [x, y],
    ];
    json!({"type": "Feature", "properties": {}, "geometry": {"type": "Polygon", "coordinates": [ring]}})
}

#[test]
fn argument_errors_are_one_line_with_exit_status_2() {
    let t = tempfile::tempdir().unwrap();
    for (args, needle) in [
        (&[][..], "no command given; see `dbms --help`"),
        (&["object"][..], "see `dbms object --help`"),
        (&["ingest"][..], "--dem <DEM>, --ortho <ORTHO>"),
        (
            &["ingest", "--dem", "a", "--bogus"][..],
            "unexpected argument '--bogus'",
        ),
        (
            &["object", "cone", "--height", "x"][..],
            "see `dbms object cone --help`",
        ),
        (&["ingset"][..], "a similar subcommand exists: 'ingest'"),
        (
            &["--quiet", "--verbose", "info", "db"][..],
            "cannot be used with",
        ),
    ] {
        let o = dbms_in(t.path(), args);
        assert_one_line(&o, 2, needle);
        assert!(!stderr(&o).contains("Usage:"), "{args:?}");
    }
    // Help and version are not errors.
    for args in [
        &["--help"][..],
        &["ingest", "--help"][..],
        &["--version"][..],
    ] {
        let o = dbms_in(t.path(), args);
        assert_eq!(o.status.code(), Some(0), "{args:?}");
        assert!(!o.stdout.is_empty() && o.stderr.is_empty(), "{args:?}");
    }
}

#[test]
fn io_errors_and_a_file_as_database_say_what_and_how_to_fix() {
    let t = tempfile::tempdir().unwrap();
    let dir = t.path();
    // An input that is a directory (outputs that are directories are refused before writing).
    std::fs::create_dir(dir.join("fp")).unwrap();
    let extrude = [
        "object",
        "extrude",
        "--footprints",
        "fp",
        "--voxel",
        "1",
        "-o",
        "x.dvox",
    ];
    assert_one_line(
        &dbms_in(dir, &extrude),
        1,
        "fp: is a directory, not a file; give the path of a file",
    );
    std::fs::write(dir.join("file"), "x").unwrap();
    assert_one_line(
        &dbms_in(dir, &["info", "file"]),
        1,
        "file: is a file, not a database directory",
    );
    assert_one_line(
        &dbms_in(dir, &["ingest", "--dem", "a", "--ortho", "b", "-o", "file"]),
        1,
        "file: is a file, not a database directory",
    );
}

#[test]
fn footprints_with_a_bom_in_lon_lat_and_many_bad_features() {
    let t = tempfile::tempdir().unwrap();
    let dir = t.path();
    database(dir);
    let run = |file: &str, extra: &[&str]| {
        let mut a = vec![
            "shadow-height",
            "--db",
            "db",
            "--footprints",
            file,
            "--sun-elevation",
            "40",
            "--sun-azimuth",
            "135",
            "-o",
            "h.geojson",
        ];
        a.extend_from_slice(extra);
        dbms_in(dir, &a)
    };
    // Lon/lat footprints on the UTM database: one CRS error, not one failure per feature.
    let lon_lat: Vec<_> = (0..3)
        .map(|k| square(9.0 + k as f64 * 1e-4, 47.85, 5e-5))
        .collect();
    let doc = json!({"type": "FeatureCollection", "features": lon_lat}).to_string();
    std::fs::write(dir.join("lonlat.geojson"), &doc).unwrap();
    assert_one_line(
        &run("lonlat.geojson", &[]),
        1,
        "lonlat.geojson: coordinates look like longitude/latitude degrees",
    );
    // One good footprint and twelve outside the grid, in a file that starts with a UTF-8 BOM.
    let mut features = vec![square(500_010.0, 5_300_010.0, 8.0)];
    features.extend((0..12).map(|k| square(600_000.0 + 20.0 * k as f64, 5_300_010.0, 8.0)));
    let doc = json!({"type": "FeatureCollection", "features": features}).to_string();
    std::fs::write(dir.join("bom.geojson"), format!("\u{feff}{doc}")).unwrap();
    let o = run("bom.geojson", &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    let warnings: Vec<String> = stderr(&o)
        .lines()
        .filter(|l| l.starts_with("dbms: warning: "))
        .map(str::to_string)
        .collect();
    assert_eq!(warnings.len(), 6, "five and a count: {warnings:#?}");
    assert!(warnings[0].contains("bom.geojson: feature 1: covers no cell centre"));
    assert_eq!(
        warnings[5],
        "dbms: warning: 7 more like these (--verbose lists them all)"
    );
    let verbose = run("bom.geojson", &["--verbose"]);
    let all = stderr(&verbose)
        .lines()
        .filter(|l| l.contains("skipped"))
        .count();
    assert_eq!(all, 12);
    assert!(run("bom.geojson", &["-q"]).stderr.is_empty());
}

/// A FIFO at `path` (no writer ever opens it: a read of it would block for ever).
fn fifo(path: &Path) {
    let c = std::ffi::CString::new(path.as_os_str().as_encoded_bytes()).unwrap();
    assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o644) }, 0, "mkfifo");
}

/// [`assert_one_line`] for a run that must end within 20 s (killed and failed otherwise).
fn refused_promptly(dir: &Path, args: &[&str], needle: &str) {
    let o = dbms_in_within(dir, args, Duration::from_secs(20));
    assert_one_line(&o, 1, needle);
}

#[test]
fn devices_and_fifos_as_inputs_are_refused_without_reading() {
    let t = tempfile::tempdir().unwrap();
    let dir = t.path();
    database(dir);
    let inset = [
        "ingest",
        "-q",
        "--dem",
        "dem.tif",
        "--ortho",
        "ortho.tif",
        "-o",
        "db",
    ];
    let o = dbms_in(
        dir,
        &[
            &inset[..],
            &["--inset", "town:2:500010,5300010,500020,5300020"],
        ]
        .concat(),
    );
    assert!(o.status.success(), "{}", stderr(&o));
    let o = dbms_in(dir, &["pyramid", "-q", "--db", "db", "-o", "t.dbt"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let cone = [
        "object", "cone", "-q", "--height", "2", "--radius", "1", "--voxel", "0.5",
    ];
    let o = dbms_in(dir, &[&cone[..], &["-o", "c.dvox"]].concat());
    assert!(o.status.success(), "{}", stderr(&o));
    fifo(&dir.join("fifo"));
    let zero = "/dev/zero: is a character device, not a regular file";
    let pipe = "fifo: is a FIFO (named pipe), not a regular file";
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (
            vec![
                "render",
                "--tiles",
                "t.dbt",
                "--path",
                "/dev/zero",
                "--speed",
                "3",
                "-o",
                "out",
            ],
            zero,
        ),
        (
            vec![
                "render", "--tiles", "t.dbt", "--path", "fifo", "--speed", "3", "-o", "out",
            ],
            pipe,
        ),
        (
            vec!["render", "--tiles", "fifo", "--top", "-o", "v.png"],
            pipe,
        ),
        (vec!["tiles", "fifo"], pipe),
        (vec!["build", "/dev/zero"], zero),
        (vec!["plan", "fifo"], pipe),
        (
            vec![
                "object",
                "extrude",
                "--footprints",
                "/dev/zero",
                "--voxel",
                "1",
                "-o",
                "x.dvox",
            ],
            zero,
        ),
        (
            vec![
                "object",
                "extrude",
                "--footprints",
                "fifo",
                "--voxel",
                "1",
                "-o",
                "x.dvox",
            ],
            pipe,
        ),
        (
            vec![
                "shadow-height",
                "--db",
                "db",
                "--footprints",
                "fifo",
                "--sun-elevation",
                "40",
                "--sun-azimuth",
                "135",
                "-o",
                "h.geojson",
            ],
            pipe,
        ),
        (
            vec![
                "place", "--db", "db", "--object", "c.dvox", "--points", "fifo",
            ],
            pipe,
        ),
        (
            vec![
                "ingest",
                "--dem",
                "fifo",
                "--ortho",
                "ortho.tif",
                "-o",
                "db2",
            ],
            pipe,
        ),
        (
            vec![
                "ingest",
                "--dem",
                "dem.tif",
                "--ortho",
                "/dev/zero",
                "-o",
                "db2",
            ],
            zero,
        ),
        (vec!["materials", "--db", "db", "--table", "fifo"], pipe),
        (
            vec!["materials", "--db", "db", "--features", "/dev/zero"],
            zero,
        ),
        (
            vec!["pyramid", "--db", "db", "--lights", "fifo", "-o", "x.dbt"],
            pipe,
        ),
    ];
    for (args, needle) in cases {
        refused_promptly(dir, &args, needle);
    }
    // A region file replaced by a FIFO: refused when the tile set opens its regions.
    std::fs::remove_file(dir.join("t.town.dbt")).unwrap();
    fifo(&dir.join("t.town.dbt"));
    refused_promptly(
        dir,
        &["tiles", "t.dbt", "--verify"],
        "t.town.dbt: is a FIFO (named pipe), not a regular file",
    );
}

#[test]
fn text_inputs_larger_than_their_limit_are_refused_before_reading() {
    let t = tempfile::tempdir().unwrap();
    let dir = t.path();
    // Sparse files: their length is what is refused, nothing is read.
    let sparse = |name: &str, len: u64| {
        let f = std::fs::File::create(dir.join(name)).unwrap();
        f.set_len(len).unwrap();
    };
    sparse("big.geojson", (1 << 30) + 1);
    sparse("big.toml", (64 << 20) + 1);
    refused_promptly(
        dir,
        &[
            "object",
            "extrude",
            "--footprints",
            "big.geojson",
            "--voxel",
            "1",
            "-o",
            "x.dvox",
        ],
        "big.geojson: is 1073741825 bytes, over the 1 GiB dbms reads of a data file",
    );
    refused_promptly(
        dir,
        &["plan", "big.toml"],
        "big.toml: is 67108865 bytes, over the 64 MiB dbms reads of a settings file",
    );
}
