//! `dbms pyramid`: the max-Z / average-colour hierarchy of a database as a paged tile file.

use super::Ctx;
use dbms::db::Database;
use dbms::pyramid::{build_pyramids, shard, Product, PyramidOptions, PyramidSummary};
use dbms::pyramid::{DEFAULT_FACTOR, DEFAULT_PAGE};
use dbms::sun::Sun;
use dbms::tiles::Compression;
use std::path::PathBuf;

/// Build the render database: every level (max Z, average colour, occupancy) in one tile file,
/// with shadows and shading for a sun when one is given.
#[derive(clap::Args)]
pub struct Args {
    /// The database directory.
    #[arg(long)]
    db: PathBuf,
    /// Ratio of cell sizes between levels: 4 (cells of 1, 4, 16, 64) or 2.
    #[arg(long, default_value_t = DEFAULT_FACTOR)]
    factor: usize,
    /// Number of levels (default: down to the first level that fits in one page).
    #[arg(long)]
    levels: Option<usize>,
    /// Page edge in cells (a multiple of the factor).
    #[arg(long, default_value_t = DEFAULT_PAGE)]
    page: usize,
    #[command(flatten)]
    sun: super::SunArgs,
    /// Fraction of full-sun brightness left in shadow (the patent's F), in (0, 1].
    #[arg(long, default_value_t = dbms::pyramid::shade::DEFAULT_SHADOW_FACTOR)]
    shadow_factor: f64,
    /// Per-page compression: none or lz4.
    #[arg(long, default_value = "none")]
    compression: String,
    /// Also write every level as GeoTIFF here (level<N>_maxz.tif, level<N>_colour.tif).
    #[arg(long)]
    export_levels: Option<PathBuf>,
    /// Keep a ledger beside the tile file (TILES.ledger.json) and make again only the pages
    /// that buildings or placements changed since the build it records touch; the rest are
    /// copied. The tile file is byte for byte a full build's; without a usable ledger (or with
    /// --export-levels) every page is made, and the summary says why.
    #[arg(long)]
    incremental: bool,
    /// Carry the database's materials layer (`dbms materials`) as the tile layer `material`:
    /// coarse cells take the id most of their level-0 cells have.
    #[arg(long)]
    materials: bool,
    /// Carry this temperature map (kelvin, on the database grid: `dbms thermal -o`) as the tile
    /// layer `temperature`: coarse cells take the mean. For `dbms render --sensor ir`.
    #[arg(long, value_name = "TIF")]
    temperature: Option<PathBuf>,
    /// Carry this 8-12 um radiance map (`dbms thermal --radiance-out`) as the tile layer
    /// `radiance`: coarse cells take the mean.
    #[arg(long, value_name = "TIF")]
    radiance: Option<PathBuf>,
    /// Carry this radar σ⁰ map (linear, `dbms radar -o`) as the tile layer `backscatter`:
    /// coarse cells take the mean power. For `dbms render --sensor radar`.
    #[arg(long, value_name = "TIF")]
    backscatter: Option<PathBuf>,
    /// Carry each cell's surface normal as the tile layer `normal` (terrain normals, level on
    /// buildings and objects; coarse cells the renormalised sum), so a radar or shading
    /// model can take its own incidence at render time.
    #[arg(long)]
    normals: bool,
    /// Light points for the night sensors, a GeoJSON of Point features with intensity_cd
    /// (candela) and optional height_m (above the terrain) and colour ([r, g, b]); carried in
    /// the tile header for `dbms render --sensor nvg`.
    #[arg(long, value_name = "GEOJSON")]
    lights: Option<PathBuf>,
    /// Output tile file.
    #[arg(short, long)]
    output: PathBuf,
    /// Another product built in the same run, TILES@SUN: its tile file and its sun, a UTC time
    /// (RFC 3339), ELEVATION/AZIMUTH in degrees, or `none`. Repeatable. What stands on the
    /// terrain is read once, and a cast (or the photo's detected shadows) one product made
    /// serves the others that need the same; each summary's `reused` says what it took.
    #[arg(long, value_name = "TILES@SUN")]
    product: Vec<String>,
    /// Build only shard I of N of the tile file: the level-0 pages of one of N windows of whole
    /// pages, written to -o as a one-level tile file of the window (its part) with a record
    /// beside it (PART.shard.json). Needs --survey; --merge assembles the parts.
    #[arg(long, value_name = "I/N", requires = "survey", conflicts_with_all = ["merge", "product"], value_parser = parse_shard)]
    shard: Option<[usize; 2]>,
    /// The survey of the database every shard reads (dbms survey).
    #[arg(long, value_name = "JSON", requires = "shard")]
    survey: Option<PathBuf>,
    /// Assemble the tile file -o from the parts of shards 1..N built with the same options
    /// (byte for byte the file one dbms pyramid makes) and record the stage.
    #[arg(long, value_name = "PART", num_args = 1.., conflicts_with = "product")]
    merge: Vec<PathBuf>,
}

fn parse_shard(s: &str) -> Result<[usize; 2], String> {
    let bad = || format!("{s}: give I/N, shard I of N counted from 1 (e.g. 3/8)");
    let (i, n) = s.split_once('/').ok_or_else(bad)?;
    let (i, n) = (i.parse().map_err(|_| bad())?, n.parse().map_err(|_| bad())?);
    match 1 <= i && i <= n {
        true => Ok([i, n]),
        false => Err(bad()),
    }
}

/// The product `TILES@SUN` of `--product` over `db`.
fn product(text: &str, db: &Database) -> dbms::Result<Product> {
    let bad = |problem: &str| {
        dbms::Error::msg(format!("--product {text}: {problem}"))
            .fix("give TILES@TIME (RFC 3339 UTC), TILES@ELEVATION/AZIMUTH (degrees) or TILES@none")
    };
    let (tiles, sun) = text
        .rsplit_once('@')
        .ok_or_else(|| bad("no @ before the sun"))?;
    if tiles.is_empty() {
        return Err(bad("no tile file before the @"));
    }
    let sun = match sun.split_once('/') {
        _ if sun == "none" => None,
        Some((e, a)) => {
            let angle = |v: &str| {
                v.trim()
                    .parse::<f64>()
                    .map_err(|_| bad("the angles are not numbers"))
            };
            Some(Sun::new(angle(e)?, angle(a)?)?)
        }
        None => Some(dbms::sun::at_database_centre(db, sun)?),
    };
    Ok(Product {
        tiles: PathBuf::from(tiles),
        sun,
    })
}

/// The summaries of a run: one product's as before, several as a list.
struct Built(Vec<PyramidSummary>);

impl serde::Serialize for Built {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self.0.as_slice() {
            [one] => one.serialize(s),
            all => all.serialize(s),
        }
    }
}

impl std::fmt::Display for Built {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        for (k, summary) in self.0.iter().enumerate() {
            if k > 0 {
                writeln!(f)?;
            }
            write!(f, "{summary}")?;
        }
        Ok(())
    }
}

pub fn run(args: Args, ctx: &Ctx) -> dbms::Result<()> {
    let db = Database::open(&args.db)?;
    // No sun given: no shadow or shading work at all.
    let sun = args.sun.resolve(&db)?;
    let opts = PyramidOptions {
        factor: args.factor,
        levels: args.levels,
        page_size: args.page,
        sun,
        shadow_factor: args.shadow_factor,
        compression: Compression::parse(&args.compression)?,
        export_levels: args.export_levels,
        incremental: args.incremental,
        sensor: dbms::pyramid::SensorInputs {
            material: args.materials,
            temperature: args.temperature,
            radiance: args.radiance,
            backscatter: args.backscatter,
            normals: args.normals,
            lights: args.lights,
        },
    };
    let progress = ctx.progress(0, "pyramid");
    if let (Some(shard), Some(survey)) = (args.shard, &args.survey) {
        let survey = dbms::pyramid::shard::read_survey(survey, &db)?;
        let made = shard::build_shard(&db, &opts, &survey, shard, &args.output, &progress)?;
        ctx.report(&made);
        return Ok(());
    }
    if !args.merge.is_empty() {
        let merged = shard::merge(&db, ctx.wait, &opts, &args.merge, &args.output, &progress)?;
        ctx.report(&merged);
        return Ok(());
    }
    let mut products = vec![Product {
        tiles: args.output.clone(),
        sun,
    }];
    for text in &args.product {
        products.push(product(text, &db)?);
    }
    let built = build_pyramids(&db, ctx.wait, &products, &opts, &progress)?;
    let warnings: Vec<String> = built.iter().flat_map(|s| s.warnings.clone()).collect();
    ctx.warn_all(&warnings);
    ctx.report(&Built(built));
    Ok(())
}
