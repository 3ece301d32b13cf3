//! `dbms materials`: the per-cell material layer of a database (issue 18, docs/materials.md).

use super::Ctx;
use dbms::material::layer::{build, MaterialOptions};
use std::path::PathBuf;

/// Classify every cell of a database into a material of the material table: from building
/// roofs with a `roof_material`, vector features, a land-cover raster, then the orthophoto.
#[derive(clap::Args)]
pub struct Args {
    /// The database directory.
    #[arg(long)]
    db: PathBuf,
    /// GeoJSON features naming a `material` (polygons; lines with a `width_m`), in the
    /// database's CRS. Repeatable; later features paint over earlier ones, lines over polygons.
    #[arg(long = "features", value_name = "GEOJSON")]
    features: Vec<PathBuf>,
    /// A land-cover class raster (GeoTIFF in the database's CRS, or lon/lat), needs --legend.
    #[arg(long, value_name = "TIF", requires = "legend")]
    landcover: Option<PathBuf>,
    /// The legend the land-cover codes follow: a legend of the table (`esa_worldcover`, `nlcd`
    /// in the default table).
    #[arg(long, requires = "landcover")]
    legend: Option<String>,
    /// A material table (JSON, schemas/materials.schema.json) instead of the shipped default;
    /// it is copied into the database for later stages.
    #[arg(long, value_name = "JSON")]
    table: Option<PathBuf>,
    /// The material of the cells placed voxel objects stand on, above every other source:
    /// MATERIAL for every placed object (e.g. forest for trees), NAME=MATERIAL for the
    /// placements of the object file NAME (as placed, without .dvox: tank=roof_metal).
    /// Repeatable; a name wins over the bare MATERIAL.
    #[arg(long, value_name = "[NAME=]MATERIAL")]
    objects: Vec<String>,
    /// Also write the layer as a PNG to look at: each cell in its material's colour from the
    /// table (black: unclassified).
    #[arg(long, value_name = "PNG")]
    preview: Option<PathBuf>,
}

pub fn run(args: Args, ctx: &Ctx) -> dbms::Result<()> {
    let progress = ctx.progress(0, "materials");
    let summary = build(
        &args.db,
        &MaterialOptions {
            features: args.features,
            landcover: args.landcover.zip(args.legend),
            table: args.table,
            objects: args.objects,
            preview: args.preview,
            wait: ctx.wait,
        },
    )?;
    progress.finish();
    ctx.report(&summary);
    Ok(())
}
