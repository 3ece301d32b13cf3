//! Real data with an independent truth: IGN's Montpellier block (`tests/data/ign_montpellier`,
//! source "IGN — LiDAR HD and BD ORTHO", Licence Ouverte / Etalab 2.0).
//!
//! The footprints and their roofs come from the LiDAR's building points
//! (`tests/data/ign_montpellier/make_truth.py`), the photo's sun from its shadows against the
//! LiDAR's surface (`estimate_sun.py`); nothing there uses dbms. This module reads them,
//! hands dbms the footprints *without* the truth, and lines dbms's output up with the truth.
//!
//! Invariant: the footprints dbms reads carry only their `name`; the truth's roof properties
//! (`roof_z`, `eave_z`, `roof_form`, ...) never reach it, since `dbms shadow-height` keeps
//! input properties in its output and a buildings layer reads them as roofs.

#![allow(dead_code)]

use serde_json::{json, Value};
use std::path::{Path, PathBuf};

/// `tests/data/ign_montpellier`.
pub fn data_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/ign_montpellier")
}

/// One building part's roof as the LiDAR has it (absolute metres, IGN69; degrees).
#[derive(Debug, Clone)]
pub struct TruthRoof {
    /// `b1`, `b2`, ... in the file's order.
    pub name: String,
    /// 99th percentile of the class-6 points on the fitted roof (the ridge of a pitched roof).
    pub roof_z: f64,
    /// The eaves (2nd percentile of the pitched faces' points; `roof_z` for a flat roof).
    pub eave_z: f64,
    /// `flat`, `gable`, `hip` or `shed`.
    pub roof_form: String,
    /// The fitted planes' slope, degrees.
    pub pitch_deg: f64,
    /// Share of the part's area inside the photo's tile, 0 to 1.
    pub in_tile: f64,
}

fn read_json(path: &Path) -> Value {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    serde_json::from_str(&text).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

fn number(p: &Value, key: &str) -> f64 {
    p[key]
        .as_f64()
        .unwrap_or_else(|| panic!("truth property {key} missing: {p}"))
}

/// The truth of `footprints.geojson`, in its order.
pub fn read_truth(path: &Path) -> Vec<TruthRoof> {
    read_json(path)["features"]
        .as_array()
        .expect("a FeatureCollection")
        .iter()
        .map(|f| {
            let p = &f["properties"];
            TruthRoof {
                name: p["name"].as_str().expect("name").to_string(),
                roof_z: number(p, "roof_z"),
                eave_z: number(p, "eave_z"),
                roof_form: p["roof_form"].as_str().expect("roof_form").to_string(),
                pitch_deg: number(p, "pitch_deg"),
                in_tile: number(p, "in_tile"),
            }
        })
        .collect()
}

/// Write `src`'s footprints to `dst` with only their `name` (see the module's invariant).
pub fn write_bare_footprints(src: &Path, dst: &Path) {
    let mut doc = read_json(src);
    for f in doc["features"].as_array_mut().expect("a FeatureCollection") {
        let name = f["properties"]["name"].clone();
        f["properties"] = json!({ "name": name });
    }
    std::fs::write(dst, serde_json::to_string(&doc).unwrap()).unwrap();
}

/// The photo's estimated sun from `sun.json`: (azimuth, elevation), degrees.
pub fn read_sun(path: &Path) -> (f64, f64) {
    let s = read_json(path);
    (
        number(&s, "sun_azimuth_deg"),
        number(&s, "sun_elevation_deg"),
    )
}

/// One building: the truth and what dbms said.
#[derive(Debug, Clone)]
pub struct Row {
    /// The truth.
    pub truth: TruthRoof,
    /// dbms's `roof_z` (absolute m), if measured.
    pub roof_z: Option<f64>,
    /// dbms's `roof_z_interval_95`, if measured.
    pub interval_95: Option<(f64, f64)>,
    /// dbms's `roof_z_at_least`, if given.
    pub at_least: Option<f64>,
    /// dbms's `roof_form` (`flat` when absent).
    pub roof_form: String,
    /// dbms's flags.
    pub flags: Vec<String>,
}

impl Row {
    /// dbms's roof minus the truth's, in cells of `cell_m` metres.
    pub fn error_cells(&self, cell_m: f64) -> Option<f64> {
        self.roof_z.map(|z| (z - self.truth.roof_z) / cell_m)
    }
}

/// dbms's heights file lined up with the truth, feature by feature (same order, same names).
pub fn compare(truth: &[TruthRoof], heights: &Value) -> Vec<Row> {
    let fs = heights["features"].as_array().expect("a FeatureCollection");
    assert_eq!(fs.len(), truth.len(), "one output feature per footprint");
    truth
        .iter()
        .zip(fs)
        .map(|(t, f)| {
            let p = &f["properties"];
            assert_eq!(p["name"].as_str(), Some(t.name.as_str()), "order kept: {p}");
            let pair = |v: &Value| Some((v.get(0)?.as_f64()?, v.get(1)?.as_f64()?));
            Row {
                truth: t.clone(),
                roof_z: p["roof_z"].as_f64(),
                interval_95: pair(&p["roof_z_interval_95"]),
                at_least: p["roof_z_at_least"].as_f64(),
                roof_form: p["roof_form"].as_str().unwrap_or("flat").to_string(),
                flags: p["flags"]
                    .as_array()
                    .map(|a| {
                        a.iter()
                            .filter_map(|s| s.as_str().map(String::from))
                            .collect()
                    })
                    .unwrap_or_default(),
            }
        })
        .collect()
}

/// The rows as a Markdown table (for failure messages and docs/shadow-height.md).
pub fn table(rows: &[Row], cell_m: f64) -> String {
    let opt = |v: Option<f64>| v.map_or("—".to_string(), |z| format!("{z:.2}"));
    let mut s = String::from(
        "| part | truth form, pitch | truth roof_z / eave_z | dbms roof_z [95 %] | at least | \
         dbms form | error (cells) | flags |\n|---|---|---|---|---|---|---|---|\n",
    );
    for r in rows {
        let t = &r.truth;
        let iv = r
            .interval_95
            .map_or(String::new(), |(a, b)| format!(" [{a:.2}, {b:.2}]"));
        s += &format!(
            "| {} | {}, {:.1}° | {:.2} / {:.2} | {}{iv} | {} | {} | {} | {} |\n",
            t.name,
            t.roof_form,
            t.pitch_deg,
            t.roof_z,
            t.eave_z,
            opt(r.roof_z),
            opt(r.at_least),
            r.roof_form,
            r.error_cells(cell_m)
                .map_or("—".to_string(), |e| format!("{e:+.1}")),
            r.flags.join(", ")
        );
    }
    s
}
