//! `dbms sculpt`: carve a coloured voxel object from calibrated silhouettes.

use super::Ctx;
use dbms::voxel::carve::{CarveOptions, Unseen};
use dbms::voxel::export::{check_exports, plan_exports, write_with_exports, Export};
use dbms::voxel::sculpt::{sculpt, SculptOptions, SculptReport};
use dbms::voxel::views::ViewsFile;
use dbms::voxel::{grid::parse_box, object::parse_rgb};
use std::path::{Path, PathBuf};

/// Carve the visual hull of an object from calibrated views and colour it (docs/sculpt.md).
#[derive(clap::Args)]
pub struct Args {
    /// The views file (schemas/views.schema.json): images, silhouettes, cameras.
    #[arg(long)]
    views: PathBuf,
    /// Voxel edge, metres.
    #[arg(long)]
    voxel: f64,
    /// Box to carve, MINX,MINY,MINZ,MAXX,MAXY,MAXZ metres (default: "bounds" in the views file).
    #[arg(long, allow_hyphen_values = true)]
    bounds: Option<String>,
    /// The voxel object to write (.dvox, docs/voxel-object.md).
    #[arg(short, long)]
    output: PathBuf,
    /// Also write these beside the object (same name, .ply / .vox).
    #[arg(long, value_parser = super::choice::<Export>())]
    export: Vec<Export>,
    /// Voxels that project outside a view's image: kept (that view has no say) or carved.
    #[arg(long, value_parser = super::choice::<Unseen>(), default_value = "keep")]
    outside: Unseen,
    /// Voxels behind a pinhole camera: kept (that view has no say) or carved.
    #[arg(long, value_parser = super::choice::<Unseen>(), default_value = "keep")]
    behind: Unseen,
    /// Colour R,G,B of interior voxels and of surface voxels no view sees.
    #[arg(long, default_value = "128,128,128")]
    fill: String,
}

pub fn run(args: Args, ctx: &Ctx) -> dbms::Result<()> {
    let opts = SculptOptions {
        voxel: args.voxel,
        bounds: args.bounds.as_deref().map(parse_box).transpose()?,
        carve: CarveOptions {
            outside: args.outside,
            behind: args.behind,
        },
        fill: parse_rgb(&args.fill)?,
    };
    // Before any work: no output may be a special file, a database's, or an input.
    let inputs = ViewsFile::read(&args.views)?.files(&args.views);
    let inputs: Vec<&Path> = inputs.iter().map(PathBuf::as_path).collect();
    let planned = plan_exports(&args.output, &args.export, &inputs)?;
    let (obj, report) = sculpt(&args.views, &opts)?;
    ctx.warn_all(&report.warnings);
    check_exports(&obj, &planned)?;
    write_with_exports(
        &args.output,
        &obj,
        &format!("dbms sculpt --voxel {}", args.voxel),
        &planned,
    )?;
    ctx.report(&Sculpted {
        report,
        output: args.output,
        exports: planned.into_iter().map(|(_, p)| p).collect(),
        voxel: args.voxel,
    });
    Ok(())
}

/// `dbms sculpt`'s summary: the carving's report, the object file and its exports.
#[derive(serde::Serialize)]
struct Sculpted {
    #[serde(flatten)]
    report: SculptReport,
    output: PathBuf,
    exports: Vec<PathBuf>,
    /// Voxel edge, metres (in the report's text only).
    #[serde(skip)]
    voxel: f64,
}

impl std::fmt::Display for Sculpted {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let (r, d, c) = (&self.report, self.report.dims, self.report.colour);
        write!(
            f,
            "{}: {} voxels in a {}x{}x{} grid of {} m from {} views; {} surface voxels, {} coloured, {} seen by no view",
            self.output.display(),
            r.voxels,
            d[0],
            d[1],
            d[2],
            self.voxel,
            r.views,
            c.surface,
            c.seen,
            c.unseen
        )?;
        for p in &self.exports {
            write!(f, "\nexported {}", p.display())?;
        }
        Ok(())
    }
}
