//! The bundled sample scene as benchmark input (`benches/render.rs`, `benches/mesh.rs`): made
//! once per work directory by the binary, as a modeller makes it.

use std::path::{Path, PathBuf};
use std::process::Command;

/// The sample's tile set `WORK/sample.dbt`, made untimed unless it exists: `dbms sample` into
/// `WORK/scene`, `dbms ingest` of its DEM and orthophoto into the database `WORK/db`, `dbms
/// pyramid` from it.
pub fn sample_tiles(work: &Path) -> PathBuf {
    let out = work.join("sample.dbt");
    if out.exists() {
        return out;
    }
    let bin = env!("CARGO_BIN_EXE_dbms");
    let (scene, db) = (work.join("scene"), work.join("db"));
    let dem = scene.join("dem.tif");
    let ortho = scene.join("ortho.tif");
    for args in [
        vec!["-q", "sample", "-o", scene.to_str().unwrap()],
        vec![
            "-q",
            "ingest",
            "--dem",
            dem.to_str().unwrap(),
            "--ortho",
            ortho.to_str().unwrap(),
            "-o",
            db.to_str().unwrap(),
        ],
        vec![
            "-q",
            "pyramid",
            "--db",
            db.to_str().unwrap(),
            "-o",
            out.to_str().unwrap(),
        ],
    ] {
        let o = Command::new(bin).args(&args).output().expect("run dbms");
        assert!(
            o.status.success(),
            "dbms {args:?}: {}",
            String::from_utf8_lossy(&o.stderr)
        );
    }
    out
}
