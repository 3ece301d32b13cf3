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
    /// of points without an `object` property. With several --at: once for all, or once each.
    #[arg(long)]
    object: Vec<PathBuf>,
    /// X,Y[,Z]: world position of the object's anchor (bottom centre); Z absolute metres, default the ground.
    /// Repeat to place several objects in one change (one manifest write).
    #[arg(long, allow_hyphen_values = true)]
    at: Vec<String>,
    /// Rotation about the vertical, degrees clockwise from north. With several --at: once for
    /// all, or once each.
    #[arg(long, allow_hyphen_values = true)]
    heading: Vec<f64>,
    /// Size factor about the anchor (2: twice as large); with --move, the new one. With several
    /// --at: once for all, or once each. At most what the database holds (docs/voxel-object.md).
    #[arg(long)]
    scale: Vec<f64>,
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

/// The value of option `name` for the `k`-th of `n` placements: given `values` once for all,
/// once for each, or not at all (`None`).
fn nth<T: Clone>(values: &[T], k: usize, n: usize, name: &str) -> dbms::Result<Option<T>> {
    match values.len() {
        0 => Ok(None),
        1 => Ok(Some(values[0].clone())),
        m if m == n => Ok(Some(values[k].clone())),
        m => Err(dbms::Error::msg(format!(
            "--{name} is given {m} times for {n} --at: give it once for all, or once for each"
        ))
        .fix("e.g. --object tree.dvox --at 1,2 --at 3,4 --heading 10 --heading 20")),
    }
}

/// The placements `--object`, `--at`, `--heading` and `--scale` give, in order.
fn placements(args: &Args) -> dbms::Result<Vec<Placement>> {
    let n = args.at.len();
    if args.object.is_empty() || n == 0 {
        return Err(dbms::Error::msg(
            "nothing to place: give --object FILE --at X,Y, or --points, --remove or --move",
        )
        .fix("see dbms place --help"));
    }
    (0..n)
        .map(|k| {
            let (x, y, z) = parse_at(&args.at[k])?;
            Ok(Placement {
                object: nth(&args.object, k, n, "object")?.expect("given"),
                x,
                y,
                z,
                heading_deg: nth(&args.heading, k, n, "heading")?.unwrap_or(0.0),
                scale: nth(&args.scale, k, n, "scale")?.unwrap_or(1.0),
            })
        })
        .collect()
}

pub fn run(args: Args, ctx: &Ctx) -> dbms::Result<()> {
    let (objects, action) = if let Some(id) = args.remove {
        (vec![remove(&args.db, ctx.wait, id)?], "removed")
    } else if let Some(id) = args.move_id {
        let at = match args.at.as_slice() {
            [at] => parse_at(at)?,
            _ => {
                return Err(
                    dbms::Error::msg("--move takes one --at").fix("move one placement at a time")
                )
            }
        };
        (
            vec![move_to(
                &args.db,
                ctx.wait,
                id,
                at,
                nth(&args.heading, 0, 1, "heading")?,
                nth(&args.scale, 0, 1, "scale")?,
            )?],
            "moved",
        )
    } else if let Some(points) = &args.points {
        let vary = Variation {
            seed: args.seed,
            random_heading: args.random_heading,
            scale_range: args.scale_range.as_deref().map(parse_range).transpose()?,
        };
        let object = nth(&args.object, 0, 1, "object")?;
        let placements = read_points(points, object.as_deref(), &vary)?;
        let progress = ctx.progress(placements.len() as u64, "placements");
        let placed = place_all(&args.db, ctx.wait, &placements)?;
        progress.inc(placed.len() as u64);
        progress.finish();
        (placed, "placed")
    } else {
        (
            place_all(&args.db, ctx.wait, &placements(&args)?)?,
            "placed",
        )
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
