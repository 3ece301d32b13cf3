//! Flight paths for `dbms render --path`: waypoints read from CSV or GeoJSON, and the camera of
//! each frame along them.
//!
//! A path is a polyline of eye positions (world x, y in the tile set's CRS units, z in metres)
//! with a time at each vertex (seconds, strictly increasing), given in the file or worked out
//! from a speed along the 3-D polyline. Frame `k` is at time `t₀ + k / fps`, up to the last
//! vertex's time; the eye moves linearly between vertices. Unless the heading is fixed, the
//! yaw is the direction of travel over the second around the frame (a central difference of
//! positions ½ s either side, clamped to the path), so the view turns smoothly through a
//! vertex instead of snapping; while the eye only climbs or hovers the yaw is the last one.
//!
//! Invariant: frames are a pure function of the waypoints and the options (no clock), so the
//! same path renders the same frames.

use super::camera::{Attitude, Viewpoint};
use crate::error::{Error, Result};
use std::path::Path;

/// Most frames one path may make (an hour at 25 fps).
pub const MAX_FRAMES: usize = 90_000;

/// One vertex of a path.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Waypoint {
    /// Eye position: world x, y (CRS units) and z (metres).
    pub at: [f64; 3],
    /// Time at the vertex, seconds (`None`: from the speed).
    pub time: Option<f64>,
}

/// How the frames are taken along a path.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Flight {
    /// Frames per second of path time.
    pub fps: f64,
    /// Speed along the path, metres per second, for paths without times.
    pub speed: Option<f64>,
    /// Roll and pitch of every frame, degrees; its yaw too when `fixed_heading`.
    pub attitude: Attitude,
    /// Keep `attitude.yaw` instead of looking along the path.
    pub fixed_heading: bool,
}

/// Read a path file: `.csv` (a header naming columns `x`, `y`, `z` and optionally `t`, then
/// one vertex a line) or `.geojson` / `.json` (a LineString geometry, Feature or the first
/// feature of a FeatureCollection, `[x, y, z]` positions; optional `properties.times`, seconds,
/// one per vertex).
pub fn read(path: &Path) -> Result<Vec<Waypoint>> {
    let text = crate::io::read_text(path)?;
    let ext = path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase();
    let points = match ext.as_str() {
        "csv" => from_csv(&text),
        "geojson" | "json" => from_geojson(&text),
        _ => Err("unknown format".to_string()),
    }
    .map_err(|why| {
        Error::file(path, format!("not a usable flight path: {why}")).fix(
            "give a .csv with a header x,y,z[,t] or a .geojson LineString of [x, y, z] positions",
        )
    })?;
    check(&points).map_err(|why| Error::file(path, why))?;
    Ok(points)
}

fn from_csv(text: &str) -> std::result::Result<Vec<Waypoint>, String> {
    let mut lines = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty() && !l.trim_start().starts_with('#'));
    let (_, header) = lines.next().ok_or("the file is empty")?;
    let names: Vec<String> = header
        .split(',')
        .map(|s| s.trim().to_ascii_lowercase())
        .collect();
    let column = |n: &str| names.iter().position(|c| c == n);
    let (Some(x), Some(y), Some(z)) = (column("x"), column("y"), column("z")) else {
        return Err(format!(
            "the header `{header}` must name columns x, y and z (and t for times)"
        ));
    };
    let t = column("t");
    lines
        .map(|(k, line)| {
            let v: Vec<&str> = line.split(',').map(str::trim).collect();
            let num = |i: usize| -> std::result::Result<f64, String> {
                v.get(i)
                    .and_then(|s| s.parse::<f64>().ok())
                    .filter(|f| f.is_finite())
                    .ok_or_else(|| {
                        format!("line {}: `{line}` is not {} numbers", k + 1, names.len())
                    })
            };
            Ok(Waypoint {
                at: [num(x)?, num(y)?, num(z)?],
                time: t.map(num).transpose()?,
            })
        })
        .collect()
}

fn from_geojson(text: &str) -> std::result::Result<Vec<Waypoint>, String> {
    let v: serde_json::Value = serde_json::from_str(text).map_err(|e| e.to_string())?;
    let feature = match v["type"].as_str() {
        Some("FeatureCollection") => v["features"].get(0).cloned().ok_or("no features")?,
        _ => v,
    };
    let (geometry, properties) = match feature["type"].as_str() {
        Some("Feature") => (&feature["geometry"], &feature["properties"]),
        _ => (&feature, &serde_json::Value::Null),
    };
    if geometry["type"] != "LineString" {
        return Err(format!(
            "the geometry is {}, not a LineString",
            geometry["type"]
        ));
    }
    let coords = geometry["coordinates"].as_array().ok_or("no coordinates")?;
    let times = match &properties["times"] {
        serde_json::Value::Null => None,
        t => Some(t.as_array().ok_or("properties.times is not an array")?),
    };
    if times.is_some_and(|t| t.len() != coords.len()) {
        return Err(format!(
            "properties.times has {} entries for {} positions",
            times.map_or(0, |t| t.len()),
            coords.len()
        ));
    }
    coords
        .iter()
        .enumerate()
        .map(|(k, c)| {
            // Every element a number: a stray string is an error, never a dropped value.
            let p: Vec<f64> = c
                .as_array()
                .and_then(|a| a.iter().map(serde_json::Value::as_f64).collect())
                .unwrap_or_default();
            if p.len() != 3 {
                return Err(format!("position {k} is {c}, not [x, y, z] (z: metres)"));
            }
            let time = match times {
                Some(t) => Some(t[k].as_f64().ok_or(format!("times[{k}] is not a number"))?),
                None => None,
            };
            Ok(Waypoint {
                at: [p[0], p[1], p[2]],
                time,
            })
        })
        .collect()
}

/// At least two vertices; times on all or none, finite and strictly increasing.
fn check(points: &[Waypoint]) -> std::result::Result<(), String> {
    if points.len() < 2 {
        return Err(format!(
            "a flight path needs at least two positions, this one has {}",
            points.len()
        ));
    }
    if points.iter().any(|p| p.at.iter().any(|c| !c.is_finite())) {
        return Err("a position is not finite".into());
    }
    let timed = points.iter().filter(|p| p.time.is_some()).count();
    if timed != 0 && timed != points.len() {
        return Err("times are given for some positions only: give all or none".into());
    }
    for (k, w) in points.windows(2).enumerate() {
        if let (Some(a), Some(b)) = (w[0].time, w[1].time) {
            if !(b > a) {
                return Err(format!(
                    "times must increase: position {} at {a} s, the next at {b} s",
                    k
                ));
            }
        }
    }
    Ok(())
}

/// The time of each of the checked `points`, seconds: their own, or at `speed` (metres per
/// second) along the path from 0 at the first.
fn waypoint_times(points: &[Waypoint], speed: Option<f64>) -> Result<Vec<f64>> {
    let times = match (points[0].time, speed) {
        (Some(_), _) => points.iter().map(|p| p.time.expect("checked")).collect(),
        (None, Some(v)) if v > 0.0 && v.is_finite() => {
            let mut t = vec![0.0];
            for w in points.windows(2) {
                let d = (0..3)
                    .map(|k| (w[1].at[k] - w[0].at[k]).powi(2))
                    .sum::<f64>();
                t.push(t.last().expect("one") + d.sqrt() / v);
            }
            if t.windows(2).any(|w| !(w[1] > w[0])) {
                return Err(Error::msg(
                    "the flight path repeats a position: with --speed every leg must have a length",
                ));
            }
            t
        }
        (None, Some(v)) => {
            return Err(Error::msg(format!(
                "--speed {v}: must be a positive number of metres per second"
            )))
        }
        (None, None) => {
            return Err(Error::msg("the flight path has no times")
                .fix("give --speed METRES_PER_SECOND, or a time t at every position"))
        }
    };
    Ok(times)
}

/// The viewpoint of every frame along `points` (each `width × height`, `hfov` degrees).
pub fn viewpoints(
    points: &[Waypoint],
    flight: &Flight,
    hfov: f64,
    width: usize,
    height: usize,
) -> Result<Vec<Viewpoint>> {
    check(points).map_err(Error::msg)?;
    if !(flight.fps > 0.0 && flight.fps <= 1000.0) {
        return Err(Error::msg(format!(
            "--fps {}: frames per second must be in (0, 1000]",
            flight.fps
        )));
    }
    let times = waypoint_times(points, flight.speed)?;
    let (t0, t1) = (times[0], *times.last().expect("two"));
    let count = ((t1 - t0) * flight.fps + 1e-9).floor() as usize + 1;
    if count > MAX_FRAMES {
        return Err(Error::msg(format!(
            "the flight takes {:.0} s: {count} frames at {} fps, over the {MAX_FRAMES} allowed",
            t1 - t0,
            flight.fps
        ))
        .fix("lower --fps or raise --speed"));
    }
    let at = |t: f64| -> [f64; 3] {
        let t = t.clamp(t0, t1);
        let k = times.partition_point(|&s| s <= t).clamp(1, times.len() - 1);
        let f = (t - times[k - 1]) / (times[k] - times[k - 1]);
        std::array::from_fn(|i| points[k - 1].at[i] + f * (points[k].at[i] - points[k - 1].at[i]))
    };
    let mut yaw = flight.attitude.yaw;
    Ok((0..count)
        .map(|k| {
            let t = t0 + k as f64 / flight.fps;
            if !flight.fixed_heading {
                let (a, b) = (at(t - 0.5), at(t + 0.5));
                let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
                if dx != 0.0 || dy != 0.0 {
                    yaw = dx.atan2(dy).to_degrees().rem_euclid(360.0);
                }
            }
            Viewpoint {
                eye: at(t),
                attitude: Attitude {
                    yaw,
                    ..flight.attitude
                },
                hfov,
                width,
                height,
            }
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flight(fps: f64, speed: Option<f64>) -> Flight {
        Flight {
            fps,
            speed,
            attitude: Attitude {
                roll: 0.0,
                pitch: -5.0,
                yaw: 17.0,
            },
            fixed_heading: false,
        }
    }

    fn wp(x: f64, y: f64, z: f64, t: Option<f64>) -> Waypoint {
        Waypoint {
            at: [x, y, z],
            time: t,
        }
    }

    #[test]
    fn frames_follow_the_speed_and_look_along_the_path() {
        // 100 m east then 100 m north at 20 m/s, 2 fps: 10 s, 21 frames.
        let pts = [
            wp(0.0, 0.0, 50.0, None),
            wp(100.0, 0.0, 50.0, None),
            wp(100.0, 100.0, 50.0, None),
        ];
        let cams = viewpoints(&pts, &flight(2.0, Some(20.0)), 60.0, 8, 6).unwrap();
        assert_eq!(cams.len(), 21);
        assert_eq!(cams[0].eye, [0.0, 0.0, 50.0]);
        assert_eq!(cams[4].eye, [40.0, 0.0, 50.0]);
        assert_eq!(cams[20].eye, [100.0, 100.0, 50.0]);
        assert_eq!(cams[4].attitude.yaw, 90.0);
        assert_eq!(cams[16].attitude.yaw, 0.0);
        // through the corner the view turns, half way at the vertex
        assert!(
            (cams[10].attitude.yaw - 45.0).abs() < 1e-9,
            "{}",
            cams[10].attitude.yaw
        );
        assert!(cams.iter().all(|c| c.attitude.pitch == -5.0));
    }

    #[test]
    fn given_times_set_the_pace_and_a_fixed_heading_is_kept() {
        let pts = [
            wp(0.0, 0.0, 50.0, Some(10.0)),
            wp(0.0, -30.0, 50.0, Some(13.0)),
        ];
        let mut f = flight(1.0, Some(999.0));
        f.fixed_heading = true;
        let cams = viewpoints(&pts, &f, 60.0, 8, 6).unwrap();
        assert_eq!(cams.len(), 4);
        assert_eq!(cams[1].eye, [0.0, -10.0, 50.0]);
        assert!(cams.iter().all(|c| c.attitude.yaw == 17.0));
        f.fixed_heading = false;
        assert_eq!(
            viewpoints(&pts, &f, 60.0, 8, 6).unwrap()[1].attitude.yaw,
            180.0
        );
    }

    #[test]
    fn a_vertical_climb_keeps_the_last_heading() {
        let pts = [
            wp(0.0, 0.0, 50.0, None),
            wp(0.0, 10.0, 50.0, None),
            wp(0.0, 10.0, 90.0, None),
        ];
        let cams = viewpoints(&pts, &flight(4.0, Some(10.0)), 60.0, 8, 6).unwrap();
        assert!(cams.iter().all(|c| c.attitude.yaw == 0.0));
    }

    #[test]
    fn bad_paths_and_options_are_errors_that_say_what_to_do() {
        let two = [wp(0.0, 0.0, 50.0, None), wp(10.0, 0.0, 50.0, None)];
        let e = |r: Result<Vec<Viewpoint>>| r.unwrap_err().to_string();
        assert!(e(viewpoints(&two, &flight(25.0, None), 60.0, 8, 6)).contains("--speed"));
        assert!(e(viewpoints(&two, &flight(0.0, Some(1.0)), 60.0, 8, 6)).contains("--fps 0"));
        assert!(e(viewpoints(&two, &flight(25.0, Some(-1.0)), 60.0, 8, 6)).contains("--speed -1"));
        assert!(e(viewpoints(&two, &flight(1000.0, Some(1e-4)), 60.0, 8, 6)).contains("allowed"));
        assert!(
            e(viewpoints(&two[..1], &flight(1.0, Some(1.0)), 60.0, 8, 6)).contains("at least two")
        );
        let back = [wp(0.0, 0.0, 50.0, Some(2.0)), wp(1.0, 0.0, 50.0, Some(2.0))];
        assert!(e(viewpoints(&back, &flight(1.0, None), 60.0, 8, 6)).contains("must increase"));
        let same = [wp(0.0, 0.0, 50.0, None), wp(0.0, 0.0, 50.0, None)];
        assert!(e(viewpoints(&same, &flight(1.0, Some(1.0)), 60.0, 8, 6)).contains("repeats"));
    }

    #[test]
    fn csv_and_geojson_read_the_same_path() {
        let dir = tempfile::tempdir().unwrap();
        let csv = dir.path().join("p.csv");
        std::fs::write(
            &csv,
            "# a flight\nt, X ,y,z\n0,500000.5,5300000,430\n\n4,500010,5300020.25,431\n",
        )
        .unwrap();
        let gj = dir.path().join("p.geojson");
        std::fs::write(
            &gj,
            r#"{"type":"FeatureCollection","features":[{"type":"Feature","properties":{"times":[0,4]},
               "geometry":{"type":"LineString","coordinates":[[500000.5,5300000,430],[500010,5300020.25,431]]}}]}"#,
        )
        .unwrap();
        let a = read(&csv).unwrap();
        assert_eq!(a, read(&gj).unwrap());
        assert_eq!(a[1], wp(500010.0, 5300020.25, 431.0, Some(4.0)));
        // A spreadsheet's byte order mark before the header is not part of it.
        let bom = dir.path().join("bom.csv");
        let text = std::fs::read_to_string(&csv).unwrap();
        std::fs::write(&bom, format!("\u{feff}{text}")).unwrap();
        assert_eq!(read(&bom).unwrap(), a);
        for (name, text, expect) in [
            ("a.csv", "x,y\n1,2\n3,4\n", "must name columns x, y and z"),
            ("b.csv", "x,y,z\n1,2,3\n4,five,6\n", "line 3"),
            (
                "c.geojson",
                r#"{"type":"Point","coordinates":[1,2,3]}"#,
                "not a LineString",
            ),
            (
                "d.geojson",
                r#"{"type":"LineString","coordinates":[[1,2],[3,4]]}"#,
                "not [x, y, z]",
            ),
            ("e.txt", "x,y,z\n", "unknown format"),
            (
                "g.geojson",
                r#"{"type":"LineString","coordinates":[[1,2,3],[1,"a",2,3]]}"#,
                "not [x, y, z]",
            ),
            ("f.csv", "x,y,z,t\n1,2,3,0\n4,5,6,\n", "line 3"),
        ] {
            let p = dir.path().join(name);
            std::fs::write(&p, text).unwrap();
            let err = read(&p).unwrap_err().to_string();
            assert!(err.contains(name) && err.contains(expect), "{name}: {err}");
        }
    }
}
