//! `throng cast`: the casting table, or its instancing figures.

use std::path::PathBuf;

use clap::Args;
use serde::Serialize;

use crate::casting::table::{cast_rows, cast_stats, format_stats, CastRow, CastStats};
use crate::error::Result;

/// `throng cast`.
#[derive(Debug, Args)]
pub struct CastArgs {
    /// Shot file.
    pub shot: PathBuf,
    /// Machine-readable output.
    #[arg(long)]
    pub json: bool,
    /// Instancing figures: unique parts and materials, bytes shared vs copied.
    #[arg(long)]
    pub stats: bool,
}

/// `throng cast SHOT [--json] [--stats]`.
pub fn run(args: &CastArgs) -> Result<()> {
    let crowd = super::load_crowd(&args.shot)?;
    let rows = cast_rows(&crowd);
    if args.json {
        #[derive(Serialize)]
        struct Out<'a> {
            version: u32,
            shot: &'a str,
            seed: u64,
            agents: &'a [CastRow],
            #[serde(skip_serializing_if = "Option::is_none")]
            stats: Option<CastStats>,
        }
        let out = Out {
            version: 1,
            shot: &crowd.shot.name,
            seed: crowd.shot.seed,
            agents: &rows,
            stats: args.stats.then(|| cast_stats(&crowd)),
        };
        outln!("{}", super::to_json(&out)?);
        return Ok(());
    }
    if args.stats {
        out!("{}", format_stats(&cast_stats(&crowd)));
        return Ok(());
    }
    outln!("{:>6}  {:<12} {:<20} {:>6}  {:<16} parts", "id", "rig", "scheme", "height", "head");
    for r in &rows {
        let head = crowd.casting[&r.id]
            .slots
            .iter()
            .find(|s| s.part.as_ref().is_some_and(|p| p.uniform))
            .and_then(|s| s.part.as_ref())
            .map_or("-", |p| p.mesh.as_str());
        let filled = r.parts.iter().filter(|p| p.mesh.is_some()).count();
        outln!(
            "{:>6}  {:<12} {:<20} {:>6.3}  {:<16} {}/{}",
            r.id,
            r.rig,
            r.scheme,
            r.height_scale,
            head,
            filled,
            r.parts.len()
        );
    }
    Ok(())
}
