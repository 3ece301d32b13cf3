//! `dbms sculpt`: carve a coloured voxel object from calibrated silhouettes.

use super::Ctx;
use dbms::voxel::carve::{CarveOptions, Unseen};
use dbms::voxel::export::{check_exports, plan_exports, write_with_exports, Export};
use dbms::voxel::sculpt::{sculpt, SculptOptions};
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
    let exports: Vec<&PathBuf> = planned.iter().map(|(_, p)| p).collect();
    let d = report.dims;
    let c = report.colour;
    let mut human = format!(
        "{}: {} voxels in a {}x{}x{} grid of {} m from {} views; {} surface voxels, {} coloured, {} seen by no view",
        args.output.display(),
        report.voxels,
        d[0],
        d[1],
        d[2],
        args.voxel,
        report.views,
        c.surface,
        c.seen,
        c.unseen
    );
    for p in &exports {
        human += &format!("\nexported {}", p.display());
    }
    let mut json = serde_json::to_value(&report).expect("report serialises");
    json["output"] = serde_json::json!(args.output);
    json["exports"] = serde_json::json!(exports);
    ctx.report(human, json);
    Ok(())
}
