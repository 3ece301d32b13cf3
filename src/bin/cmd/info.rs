//! `dbms info`: what a database holds.

use super::Ctx;
use dbms::db::Database;
use dbms::manifest::Manifest;
use std::path::{Path, PathBuf};

/// Print what a database holds: grid, CRS, layers with checksums, objects, insets, stages run.
#[derive(clap::Args)]
pub struct Args {
    /// The database directory.
    db: PathBuf,
    /// Also check every file against its recorded SHA-256.
    #[arg(long)]
    verify: bool,
}

pub fn run(args: Args, ctx: &Ctx) -> dbms::Result<()> {
    let db = Database::open(&args.db)?;
    if args.verify {
        db.verify()?;
    }
    ctx.report(&DatabaseInfo {
        manifest: &db.manifest,
        verified: args.verify,
        dir: &args.db,
        stages: db.stages_run(),
    });
    Ok(())
}

/// `dbms info`'s summary: the manifest (JSON: as stored, plus `verified` after `--verify`).
#[derive(serde::Serialize)]
struct DatabaseInfo<'a> {
    #[serde(flatten)]
    manifest: &'a Manifest,
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    verified: bool,
    #[serde(skip)]
    dir: &'a Path,
    #[serde(skip)]
    stages: Vec<&'a str>,
}

impl std::fmt::Display for DatabaseInfo<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let m = self.manifest;
        let g = &m.grid;
        let (cx, cy) = g.cell_size();
        let b = g.bounds();
        writeln!(
            f,
            "database {} (format {} v{})",
            self.dir.display(),
            m.format,
            m.format_version
        )?;
        writeln!(
            f,
            "grid: {} x {} cells of {} x {} {}, {}",
            g.width,
            g.height,
            cx,
            cy,
            m.units.horizontal,
            g.crs.name()
        )?;
        writeln!(
            f,
            "extent: [{}, {}, {}, {}]",
            b.min_x, b.min_y, b.max_x, b.max_y
        )?;
        if let Some(c) = m.centre {
            let ns = if c.latitude_deg < 0.0 { 'S' } else { 'N' };
            let ew = if c.longitude_deg < 0.0 { 'W' } else { 'E' };
            writeln!(
                f,
                "centre: {:.6} {ns}, {:.6} {ew}",
                c.latitude_deg.abs(),
                c.longitude_deg.abs()
            )?;
        }
        writeln!(f, "layers:")?;
        for (name, l) in &m.layers {
            let nodata = l
                .nodata_cells
                .map(|n| format!(", {n} nodata cells"))
                .unwrap_or_default();
            writeln!(
                f,
                "  {name}: {} ({}{nodata}) sha256 {}",
                l.file, l.kind, l.sha256
            )?;
        }
        if !m.objects.is_empty() {
            writeln!(f, "objects:")?;
            for o in &m.objects {
                writeln!(
                    f,
                    "  {}: {} at ({}, {}, {}) heading {} deg{}",
                    o.id,
                    o.file,
                    o.x,
                    o.y,
                    o.z,
                    o.heading_deg,
                    o.scale_note()
                )?;
            }
        }
        if !m.insets.is_empty() {
            writeln!(f, "insets:")?;
            for i in &m.insets {
                let s = &i.spec;
                writeln!(
                    f,
                    "  {}: factor {} of {}, parent {} (insets/{}/)",
                    s.name,
                    s.factor,
                    s.parent.as_deref().unwrap_or("the base grid"),
                    s.window,
                    s.name
                )?;
            }
        }
        write!(f, "stages: {}", self.stages.join(", "))?;
        if self.verified {
            write!(f, "\nverified: every file matches its checksum")?;
        }
        Ok(())
    }
}
