//! `dbms survey`: what every shard of a sharded pyramid must know about the whole database.

use super::Ctx;
use dbms::db::Database;
use dbms::pyramid::shard;
use std::path::PathBuf;

/// Survey a database for a sharded `dbms pyramid`: the terrain's height range, the highest
/// surface, and whether buildings and objects raise any cell (docs/pyramid.md, "Sharded builds").
#[derive(clap::Args)]
pub struct Args {
    /// The database directory.
    #[arg(long)]
    db: PathBuf,
    /// The survey to write (JSON, schemas/pyramid-survey.schema.json).
    #[arg(short, long)]
    output: PathBuf,
}

/// `dbms survey`'s summary: the survey and where it went.
#[derive(serde::Serialize)]
struct Surveyed {
    output: PathBuf,
    #[serde(flatten)]
    survey: shard::Survey,
}

impl std::fmt::Display for Surveyed {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let s = &self.survey;
        write!(
            f,
            "{}: terrain {:.2} to {:.2} m, highest surface {:.2} m, buildings {}, objects {}",
            self.output.display(),
            s.terrain[0],
            s.terrain[1],
            s.top,
            if s.raised[0] { "raise cells" } else { "none" },
            if s.raised[1] { "raise cells" } else { "none" },
        )
    }
}

pub fn run(args: Args, ctx: &Ctx) -> dbms::Result<()> {
    let db = Database::open(&args.db)?;
    dbms::io::atomic::check_output(&args.output)?;
    let survey = shard::survey(&db)?;
    shard::write_json(&args.output, &survey)?;
    ctx.report(&Surveyed {
        output: args.output,
        survey,
    });
    Ok(())
}
