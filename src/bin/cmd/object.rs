//! `dbms object`: synthetic voxel objects (tanks, trees, extruded buildings).

use super::Ctx;
use dbms::voxel::export::{check_exports, plan_exports, write_with_exports, Export};
use dbms::voxel::object::{parse_rgb, VoxelObject};
use dbms::voxel::synth;
use std::path::{Path, PathBuf};

/// Make a synthetic voxel object (docs/voxel-object.md).
#[derive(clap::Args)]
pub struct Args {
    #[command(subcommand)]
    kind: Kind,
}

/// Options every kind shares.
#[derive(clap::Args)]
struct Out {
    /// Voxel edge, metres.
    #[arg(long)]
    voxel: f64,
    /// The voxel object to write (.dvox).
    #[arg(short, long)]
    output: PathBuf,
    /// Also write these beside the object (same name, .ply / .vox).
    #[arg(long, value_parser = super::choice::<Export>())]
    export: Vec<Export>,
}

#[derive(clap::Subcommand)]
enum Kind {
    /// Surface of revolution about the vertical axis (storage tanks, silos, domes).
    Revolve {
        /// Profile R:Z,R:Z,... metres from bottom to top, e.g. 6:0,6:8,0:9.5 (closed via the axis).
        #[arg(long)]
        profile: String,
        /// Colour R,G,B.
        #[arg(long, default_value = "200,200,195")]
        colour: String,
        #[command(flatten)]
        out: Out,
    },
    /// A cone tree on a trunk, with seeded variation in size and shade.
    Cone {
        /// Nominal total height, metres.
        #[arg(long)]
        height: f64,
        /// Crown radius at its base, metres.
        #[arg(long)]
        radius: f64,
        /// Trunk height as a fraction of the total.
        #[arg(long, default_value_t = 0.25)]
        trunk: f64,
        /// Trunk radius, metres.
        #[arg(long, default_value_t = 0.2)]
        trunk_radius: f64,
        /// Relative variation of size and shade, in [0, 1).
        #[arg(long, default_value_t = 0.2)]
        vary: f64,
        /// Seed of the variation.
        #[arg(long, default_value_t = 1)]
        seed: u64,
        /// Crown colour R,G,B.
        #[arg(long, default_value = "40,95,40")]
        colour: String,
        /// Trunk colour R,G,B.
        #[arg(long, default_value = "90,65,40")]
        trunk_colour: String,
        #[command(flatten)]
        out: Out,
    },
    /// Flat-roofed prisms from GeoJSON footprints with heights (world x, y kept; z = 0 is the ground).
    Extrude {
        /// GeoJSON FeatureCollection of Polygon / MultiPolygon footprints.
        #[arg(long)]
        footprints: PathBuf,
        /// The property holding each footprint's height, metres.
        #[arg(long, default_value = "height")]
        height_field: String,
        /// Wall colour R,G,B.
        #[arg(long, default_value = "180,170,160")]
        colour: String,
        /// Roof colour R,G,B.
        #[arg(long, default_value = "120,110,105")]
        roof_colour: String,
        #[command(flatten)]
        out: Out,
    },
}

fn parse_profile(s: &str) -> dbms::Result<Vec<[f64; 2]>> {
    s.split(',')
        .map(|pair| {
            let (r, z) = pair.split_once(':').unwrap_or((pair, ""));
            match (r.trim().parse::<f64>(), z.trim().parse::<f64>()) {
                (Ok(r), Ok(z)) => Ok([r, z]),
                _ => Err(
                    dbms::Error::msg(format!("--profile {s}: \"{pair}\" is not R:Z"))
                        .fix("e.g. --profile 6:0,6:8,0:9.5"),
                ),
            }
        })
        .collect()
}

/// The object `kind` asks for, with its options, the source line its file records, and what
/// the summary adds for its kind.
fn make(kind: Kind) -> dbms::Result<(VoxelObject, Out, String, Extra)> {
    Ok(match kind {
        Kind::Revolve {
            profile,
            colour,
            out,
        } => {
            let obj = synth::revolve(&parse_profile(&profile)?, out.voxel, parse_rgb(&colour)?)?;
            (
                obj,
                out,
                format!("dbms object revolve --profile {profile}"),
                Extra::default(),
            )
        }
        Kind::Cone {
            height,
            radius,
            trunk,
            trunk_radius,
            vary,
            seed,
            colour,
            trunk_colour,
            out,
        } => {
            let p = synth::TreeParams {
                height,
                radius,
                trunk_fraction: trunk,
                trunk_radius,
                vary,
                crown: parse_rgb(&colour)?,
                trunk: parse_rgb(&trunk_colour)?,
                seed,
            };
            let (obj, h) = synth::cone_tree(&p, out.voxel)?;
            (
                obj,
                out,
                format!("dbms object cone --height {height} --radius {radius} --vary {vary} --seed {seed}"),
                Extra {
                    tree_height_m: Some(h),
                    ..Extra::default()
                },
            )
        }
        Kind::Extrude {
            footprints,
            height_field,
            colour,
            roof_colour,
            out,
        } => {
            let fp = synth::read_extrusions(&footprints, &height_field)?;
            let obj = synth::extrude(
                &fp,
                out.voxel,
                parse_rgb(&colour)?,
                parse_rgb(&roof_colour)?,
            )
            .map_err(|e| e.in_file(&footprints))?;
            let n = fp.len();
            (
                obj,
                out,
                format!("dbms object extrude ({n} footprints)"),
                Extra {
                    footprints: Some(n),
                    ..Extra::default()
                },
            )
        }
    })
}

pub fn run(args: Args, ctx: &Ctx) -> dbms::Result<()> {
    // Before any work: no output may be a special file, a database's, or an input.
    let (out, inputs): (&Out, Vec<&Path>) = match &args.kind {
        Kind::Revolve { out, .. } | Kind::Cone { out, .. } => (out, vec![]),
        Kind::Extrude {
            out, footprints, ..
        } => (out, vec![footprints]),
    };
    let planned = plan_exports(&out.output, &out.export, &inputs)?;
    let (obj, out, source, extra) = make(args.kind)?;
    check_exports(&obj, &planned)?;
    write_with_exports(&out.output, &obj, &source, &planned)?;
    ctx.report(&Made {
        voxels: obj.len(),
        dims: obj.grid.dims,
        anchor: obj.anchor(),
        output: out.output,
        exports: planned.into_iter().map(|(_, p)| p).collect(),
        extra,
        voxel: out.voxel,
    });
    Ok(())
}

/// `dbms object`'s summary.
#[derive(serde::Serialize)]
struct Made {
    output: PathBuf,
    exports: Vec<PathBuf>,
    voxels: usize,
    dims: [u32; 3],
    /// Bottom centre of the voxel grid, metres in the object's frame.
    anchor: [f64; 3],
    #[serde(flatten)]
    extra: Extra,
    /// Voxel edge, metres (in the text only).
    #[serde(skip)]
    voxel: f64,
}

/// What a kind of object adds to its summary.
#[derive(Default, serde::Serialize)]
struct Extra {
    /// A cone tree's height after `--vary`, metres.
    #[serde(skip_serializing_if = "Option::is_none")]
    tree_height_m: Option<f64>,
    /// Footprints extruded.
    #[serde(skip_serializing_if = "Option::is_none")]
    footprints: Option<usize>,
}

impl std::fmt::Display for Made {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let (d, a) = (self.dims, self.anchor);
        write!(
            f,
            "{}: {} voxels in a {}x{}x{} grid of {} m; anchor (bottom centre) at ({}, {}, {})",
            self.output.display(),
            self.voxels,
            d[0],
            d[1],
            d[2],
            self.voxel,
            a[0],
            a[1],
            a[2]
        )
    }
}
