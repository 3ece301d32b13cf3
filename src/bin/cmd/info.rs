//! `dbms info`: what a database holds.

use super::Ctx;
use dbms::db::Database;
use std::path::PathBuf;

/// Print what a database holds: grid, CRS, layers with checksums, objects, stages run.
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
    let m = &db.manifest;
    let g = &m.grid;
    let (cx, cy) = g.cell_size();
    let b = g.bounds();
    let mut h = format!(
        "database {} (format {} v{})\n",
        args.db.display(),
        m.format,
        m.format_version
    );
    h += &format!(
        "grid: {} x {} cells of {} x {} {}, {}\n",
        g.width,
        g.height,
        cx,
        cy,
        m.units.horizontal,
        g.crs.name()
    );
    h += &format!(
        "extent: [{}, {}, {}, {}]\n",
        b.min_x, b.min_y, b.max_x, b.max_y
    );
    if let Some(c) = m.centre {
        let ns = if c.latitude_deg < 0.0 { 'S' } else { 'N' };
        let ew = if c.longitude_deg < 0.0 { 'W' } else { 'E' };
        h += &format!(
            "centre: {:.6} {ns}, {:.6} {ew}\n",
            c.latitude_deg.abs(),
            c.longitude_deg.abs()
        );
    }
    h += "layers:\n";
    for (name, l) in &m.layers {
        let nodata = l
            .nodata_cells
            .map(|n| format!(", {n} nodata cells"))
            .unwrap_or_default();
        h += &format!(
            "  {name}: {} ({}{nodata}) sha256 {}\n",
            l.file, l.kind, l.sha256
        );
    }
    if !m.objects.is_empty() {
        h += "objects:\n";
        for o in &m.objects {
            h += &format!(
                "  {} at ({}, {}, {}) heading {} deg\n",
                o.file, o.x, o.y, o.z, o.heading_deg
            );
        }
    }
    h += &format!("stages: {}", db.stages_run().join(", "));
    if args.verify {
        h += "\nverified: every file matches its checksum";
    }
    let mut json = serde_json::to_value(m).expect("manifest serialises");
    if args.verify {
        json["verified"] = serde_json::Value::Bool(true);
    }
    ctx.report(h, json);
    Ok(())
}
