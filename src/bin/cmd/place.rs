//! `dbms place`: put a voxel object into a database.

use super::Ctx;
use dbms::voxel::place::place;
use std::path::PathBuf;

/// Place a voxel object in a database, recorded in the manifest for the pyramid stage.
#[derive(clap::Args)]
pub struct Args {
    /// The database directory.
    #[arg(long)]
    db: PathBuf,
    /// The voxel object (.dvox from `dbms sculpt` or `dbms object`).
    #[arg(long)]
    object: PathBuf,
    /// X,Y[,Z]: world position of the object's anchor (bottom centre); Z absolute metres, default the ground.
    #[arg(long, allow_hyphen_values = true)]
    at: String,
    /// Rotation about the vertical, degrees clockwise from north.
    #[arg(long, default_value_t = 0.0, allow_hyphen_values = true)]
    heading: f64,
}

pub fn run(args: Args, ctx: &Ctx) -> dbms::Result<()> {
    let v: Vec<f64> = args
        .at
        .split(',')
        .map(|t| t.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .ok()
        .filter(|v: &Vec<f64>| v.len() == 2 || v.len() == 3)
        .ok_or_else(|| {
            dbms::Error::msg(format!("--at {}: expected X,Y or X,Y,Z", args.at))
                .fix("e.g. --at 500120.5,5000340,0")
        })?;
    let p = place(
        &args.db,
        ctx.wait,
        &args.object,
        v[0],
        v[1],
        v.get(2).copied(),
        args.heading,
    )?;
    ctx.report(&Placed {
        object: p,
        db: args.db,
    });
    Ok(())
}

/// `dbms place`'s summary: the manifest's record of the placed object.
#[derive(serde::Serialize)]
struct Placed {
    #[serde(flatten)]
    object: dbms::manifest::PlacedObject,
    #[serde(skip)]
    db: PathBuf,
}

impl std::fmt::Display for Placed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let p = &self.object;
        write!(
            f,
            "placed {} at ({}, {}, {}) heading {} deg in {}",
            p.file,
            p.x,
            p.y,
            p.z,
            p.heading_deg,
            self.db.display()
        )
    }
}
