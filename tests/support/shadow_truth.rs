//! Run `dbms ingest` and `dbms shadow-height` on a POV-Ray scene and pair each building's
//! result with its truth. Shared by the POV-Ray test slice and bench: [`measure_scene`] does it
//! all; the bench calls its two halves, [`prepare_scene`] (render and ingest, run in parallel)
//! and [`measure_prepared`] (timed, run alone).

#![allow(dead_code)]

use super::povray::{Photo, Scene, Structure, Written};
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

/// One building's result beside its truth.
#[derive(Debug, Clone, PartialEq)]
pub struct Outcome {
    /// The building's index in the scene's `buildings` (its footprint's `id`).
    pub building: usize,
    /// True roof top (flat roof, or ridge), absolute metres.
    pub truth_z: f64,
    /// Measured absolute roof, metres (`None`: no height).
    pub roof_z: Option<f64>,
    /// Flags dbms set.
    pub flags: Vec<String>,
    /// The feature's `error`, if any.
    pub error: Option<String>,
    /// The whole output feature's properties.
    pub properties: serde_json::Value,
}

impl Outcome {
    /// Whether dbms said anything that warns against trusting the height: a flag other than
    /// the sun's (`low_sun`, `high_sun` describe the setting, not this building).
    pub fn flagged(&self) -> bool {
        self.flags.iter().any(|f| f != "low_sun" && f != "high_sun")
    }

    /// Measured minus true, metres.
    pub fn error_m(&self) -> Option<f64> {
        self.roof_z.map(|z| z - self.truth_z)
    }

    /// A number property, if present and a number.
    pub fn number(&self, key: &str) -> Option<f64> {
        self.properties.get(key)?.as_f64()
    }

    /// A two-number property (`[lo, hi]`), if present and well formed.
    pub fn pair(&self, key: &str) -> Option<(f64, f64)> {
        let a = self.properties.get(key)?.as_array()?;
        Some((a.first()?.as_f64()?, a.get(1)?.as_f64()?))
    }

    /// The lower bound dbms gave instead of a height (`roof_z_at_least`, absolute metres),
    /// when there is no `roof_z`.
    pub fn at_least(&self) -> Option<f64> {
        if self.roof_z.is_some() {
            return None;
        }
        self.number("roof_z_at_least")
    }
}

#[path = "cli.rs"]
mod cli;
use cli::command as dbms;

fn run(mut c: Command, what: &str) -> Result<(), String> {
    let out = c.output().map_err(|e| format!("{what}: {e}"))?;
    if !out.status.success() {
        return Err(format!(
            "{what} failed: {}",
            String::from_utf8_lossy(&out.stderr)
        ));
    }
    Ok(())
}

/// A scene rendered and ingested into a database, ready for `dbms shadow-height`.
pub struct Prepared {
    /// The scene's files (photo, DEM, footprints).
    pub written: Written,
    /// The database `dbms ingest` wrote.
    pub db: PathBuf,
    /// Wall clock of POV-Ray's render (with the DEM and footprints written), seconds.
    pub render_secs: f64,
    /// Wall clock of `dbms ingest`, seconds.
    pub ingest_secs: f64,
    /// Whether the photo's bytes are sRGB (else linear): `dbms shadow-height` is told, as a user
    /// who knows their photo would tell it.
    pub srgb: bool,
}

/// Render `scene` into `dir` and ingest it (`dir/db`).
pub fn prepare_scene<B: Structure>(scene: &Scene<B>, dir: &Path) -> Result<Prepared, String> {
    prepare_scene_photo(scene, dir, &Photo::default())
}

/// [`prepare_scene`] with `photo`'s sun and encoding ([`Scene::write_photo`]).
pub fn prepare_scene_photo<B: Structure>(
    scene: &Scene<B>,
    dir: &Path,
    photo: &Photo,
) -> Result<Prepared, String> {
    let t = Instant::now();
    let w = scene.write_photo(dir, photo)?;
    let render_secs = t.elapsed().as_secs_f64();
    let db = dir.join("db");
    let mut ingest = dbms();
    ingest
        .args(["--quiet", "ingest", "--dem"])
        .arg(&w.dem)
        .arg("--ortho")
        .arg(&w.ortho)
        .arg("-o")
        .arg(&db);
    let t = Instant::now();
    run(ingest, "dbms ingest")?;
    Ok(Prepared {
        written: w,
        db,
        render_secs,
        ingest_secs: t.elapsed().as_secs_f64(),
        srgb: photo.srgb,
    })
}

/// Run `dbms shadow-height` on a prepared scene (the scene's sun, its camera for a perspective
/// photo, the photo's encoding, default options otherwise; output
/// `heights.geojson` beside the photo): one outcome per listed building in scene order, and the
/// command's wall clock in seconds (process start, reading the database and footprints,
/// measuring, writing).
pub fn measure_prepared<B: Structure>(
    scene: &Scene<B>,
    p: &Prepared,
) -> Result<(Vec<Outcome>, f64), String> {
    measure_prepared_with(scene, p, &[])
}

/// [`measure_prepared`] with `extra` options for `dbms shadow-height` (e.g. `--sub-points=8`).
pub fn measure_prepared_with<B: Structure>(
    scene: &Scene<B>,
    p: &Prepared,
    extra: &[String],
) -> Result<(Vec<Outcome>, f64), String> {
    let heights = p.written.dir.join("heights.geojson");
    let mut sh = dbms();
    sh.args(["--quiet", "shadow-height", "--db"])
        .arg(&p.db)
        .arg("--footprints")
        .arg(&p.written.footprints)
        .arg(format!("--sun-elevation={}", scene.sun_elevation_deg))
        .arg(format!("--sun-azimuth={}", scene.sun_azimuth_deg))
        .arg("-o")
        .arg(&heights);
    if !p.srgb {
        sh.arg("--photo-encoding=linear");
    }
    if let super::povray::Camera::Perspective { nadir, height_m } = scene.camera {
        // A frame photo: dbms is told where it was taken from.
        sh.arg(format!(
            "--camera={},{},{}",
            nadir.0,
            nadir.1,
            scene.ground_z(nadir) + height_m
        ));
    }
    sh.args(extra);
    let t = Instant::now();
    run(sh, "dbms shadow-height")?;
    let secs = t.elapsed().as_secs_f64();
    let text = std::fs::read_to_string(&heights).map_err(|e| e.to_string())?;
    let v: serde_json::Value = serde_json::from_str(&text).map_err(|e| e.to_string())?;
    let features = v["features"].as_array().ok_or("no features")?;
    let listed: Vec<usize> = (0..scene.buildings.len())
        .filter(|&k| scene.buildings[k].listed())
        .collect();
    if features.len() != listed.len() {
        return Err(format!(
            "{}: {} features for {} listed buildings",
            heights.display(),
            features.len(),
            listed.len()
        ));
    }
    let outcomes = features
        .iter()
        .zip(&listed)
        .map(|(f, &k)| {
            let p = &f["properties"];
            Outcome {
                building: k,
                truth_z: scene.buildings[k].roof().top_z(),
                roof_z: p["roof_z"].as_f64(),
                flags: p["flags"]
                    .as_array()
                    .map(|a| {
                        a.iter()
                            .filter_map(|x| x.as_str().map(String::from))
                            .collect()
                    })
                    .unwrap_or_default(),
                error: p["error"].as_str().map(String::from),
                properties: p.clone(),
            }
        })
        .collect();
    Ok((outcomes, secs))
}

/// Render `scene` into `dir`, ingest it, measure every building; one outcome per building in
/// scene order.
pub fn measure_scene<B: Structure>(scene: &Scene<B>, dir: &Path) -> Result<Vec<Outcome>, String> {
    let p = prepare_scene(scene, dir)?;
    Ok(measure_prepared(scene, &p)?.0)
}
