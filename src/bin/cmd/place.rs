//! `dbms place`: put a voxel object into a database.

use super::Ctx;
use dbms::voxel::place::{move_to, place_all, read_points, remove, Placement, Variation};
use std::path::PathBuf;

/// Place a voxel object in a database, recorded in the manifest for the pyramid stage.
#[derive(clap::Args)]
pub struct Args {
    /// The database directory.
    #[arg(long)]
    db: PathBuf,
    /// The voxel object (.dvox from `dbms sculpt` or `dbms object`); with --points, the object
    /// of points without an `object` property.
    #[arg(long)]
    object: Option<PathBuf>,
    /// X,Y[,Z]: world position of the object's anchor (bottom centre); Z absolute metres, default the ground.
    #[arg(long, allow_hyphen_values = true)]
    at: Option<String>,
    /// Rotation about the vertical, degrees clockwise from north.
    #[arg(long, allow_hyphen_values = true)]
    heading: Option<f64>,
    /// Size factor about the anchor (2: twice as large); with --move, the new one.
    #[arg(long)]
    scale: Option<f64>,
    /// Place one object per Point of this GeoJSON FeatureCollection (properties: `object`, a
    /// path relative to the file; `heading`, degrees; `scale`), all in one change.
    #[arg(long, value_name = "FILE.geojson", conflicts_with_all = ["at", "heading", "scale", "remove", "move_id"])]
    points: Option<PathBuf>,
    /// With --points: points without a `heading` get a random one (seeded by --seed).
    #[arg(long, requires = "points")]
    random_heading: bool,
    /// With --points: points without a `scale` get one uniform in MIN..MAX (seeded by --seed).
    #[arg(long, value_name = "MIN,MAX", requires = "points")]
    scale_range: Option<String>,
    /// Seed of --random-heading and --scale-range: same seed and points, same placements.
    #[arg(long, default_value_t = 0, requires = "points")]
    seed: u64,
    /// Remove placement ID (ids: `dbms info DB --json`).
    #[arg(long, value_name = "ID", conflicts_with_all = ["object", "at", "heading", "scale", "move_id"])]
    remove: Option<u64>,
    /// Move placement ID to --at (and turn it to --heading when given).
    #[arg(
        long = "move",
        value_name = "ID",
        requires = "at",
        conflicts_with = "object"
    )]
    move_id: Option<u64>,
}

/// `--scale-range MIN,MAX` as numbers.
fn parse_range(range: &str) -> dbms::Result<(f64, f64)> {
    match range
        .split(',')
        .map(|t| t.trim().parse::<f64>())
        .collect::<Result<Vec<f64>, _>>()
        .as_deref()
    {
        Ok(&[lo, hi]) => Ok((lo, hi)),
        _ => Err(
            dbms::Error::msg(format!("--scale-range {range}: expected MIN,MAX"))
                .fix("e.g. --scale-range 0.8,1.25"),
        ),
    }
}

/// `--at X,Y[,Z]` as numbers.
fn parse_at(at: &str) -> dbms::Result<(f64, f64, Option<f64>)> {
    let v: Vec<f64> = at
        .split(',')
        .map(|t| t.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .ok()
        .filter(|v: &Vec<f64>| v.len() == 2 || v.len() == 3)
        .ok_or_else(|| {
            dbms::Error::msg(format!("--at {at}: expected X,Y or X,Y,Z"))
                .fix("e.g. --at 500120.5,5000340,0")
        })?;
    Ok((v[0], v[1], v.get(2).copied()))
}

pub fn run(args: Args, ctx: &Ctx) -> dbms::Result<()> {
    let (objects, action) = if let Some(id) = args.remove {
        (vec![remove(&args.db, ctx.wait, id)?], "removed")
    } else if let Some(id) = args.move_id {
        let at = parse_at(args.at.as_deref().expect("clap requires --at"))?;
        (
            vec![move_to(
                &args.db,
                ctx.wait,
                id,
                at,
                args.heading,
                args.scale,
            )?],
            "moved",
        )
    } else if let Some(points) = &args.points {
        let vary = Variation {
            seed: args.seed,
            random_heading: args.random_heading,
            scale_range: args.scale_range.as_deref().map(parse_range).transpose()?,
        };
        let placements = read_points(points, args.object.as_deref(), &vary)?;
        let progress = ctx.progress(placements.len() as u64, "placements");
        let placed = place_all(&args.db, ctx.wait, &placements)?;
        progress.inc(placed.len() as u64);
        progress.finish();
        (placed, "placed")
    } else {
        let (Some(object), Some(at)) = (&args.object, &args.at) else {
            return Err(dbms::Error::msg(
                "nothing to place: give --object FILE --at X,Y, or --points, --remove or --move",
            )
            .fix("see dbms place --help"));
        };
        let (x, y, z) = parse_at(at)?;
        let one = Placement {
            object: object.clone(),
            x,
            y,
            z,
            heading_deg: args.heading.unwrap_or(0.0),
            scale: args.scale.unwrap_or(1.0),
        };
        (place_all(&args.db, ctx.wait, &[one])?, "placed")
    };
    ctx.report(&Placed {
        objects,
        action,
        db: args.db,
    });
    Ok(())
}

/// `dbms place`'s summary: the manifest's record of each placement it made, moved or removed
/// (JSON: that record for one, `{"placements": [...]}` for several).
#[derive(serde::Serialize)]
#[serde(untagged)]
enum Records<'a> {
    One(&'a dbms::manifest::PlacedObject),
    Many {
        placements: &'a [dbms::manifest::PlacedObject],
    },
}

struct Placed {
    objects: Vec<dbms::manifest::PlacedObject>,
    action: &'static str,
    db: PathBuf,
}

impl serde::Serialize for Placed {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self.objects.as_slice() {
            [one] => Records::One(one).serialize(s),
            many => Records::Many { placements: many }.serialize(s),
        }
    }
}

impl std::fmt::Display for Placed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self.objects.as_slice() {
            [p] => write!(
                f,
                "{} {} (placement {}) at ({}, {}, {}) heading {} deg{} in {}",
                self.action,
                p.file,
                p.id,
                p.x,
                p.y,
                p.z,
                p.heading_deg,
                p.scale_note(),
                self.db.display()
            ),
            many => write!(
                f,
                "{} {} objects (placements {} to {}) in {}",
                self.action,
                many.len(),
                many.first().map_or(0, |p| p.id),
                many.last().map_or(0, |p| p.id),
                self.db.display()
            ),
        }
    }
}
