//! `throng cast`: the casting table, or its instancing figures.

use std::path::PathBuf;

use clap::Args;
use serde::Serialize;

use throng::casting::table::{cast_row, cast_stats, format_stats, CastStats};
use throng::casting::ShotCrowd;
use throng::error::Result;

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
    if args.json {
        // Rows are made as they are written, not held for the whole crowd.
        struct Rows<'a>(&'a ShotCrowd);
        impl Serialize for Rows<'_> {
            fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
                s.collect_seq(self.0.casting().iter().map(|c| cast_row(self.0, c)))
            }
        }
        #[derive(Serialize)]
        struct Out<'a> {
            version: u32,
            shot: &'a str,
            seed: u64,
            agents: Rows<'a>,
            #[serde(skip_serializing_if = "Option::is_none")]
            stats: Option<CastStats>,
        }
        let out = Out {
            version: 1,
            shot: &crowd.shot().name,
            seed: crowd.shot().seed,
            agents: Rows(&crowd),
            stats: args.stats.then(|| cast_stats(&crowd)),
        };
        outln!("{}", super::to_json(&out)?);
        return Ok(());
    }
    if args.stats {
        out!("{}", format_stats(&cast_stats(&crowd)));
        return Ok(());
    }
    outln!("{:>6}  {:<12} {:<20} {:>6}  {:<16} {:<6} props", "id", "rig", "scheme", "height", "head", "parts");
    // Straight from the casting: the table row's paths and names are for --json.
    for cast in crowd.casting().iter() {
        let head = cast
            .slots
            .iter()
            .find(|s| s.part.as_ref().is_some_and(|p| p.uniform))
            .and_then(|s| s.part.as_ref())
            .map_or("-", |p| &*p.mesh);
        let filled = cast.slots.iter().filter(|s| s.part.is_some()).count();
        let props: Vec<&str> = cast.props.iter().map(|p| &*p.name).collect();
        outln!(
            "{:>6}  {:<12} {:<20} {:>6.3}  {:<16} {:<6} {}",
            cast.id,
            cast.rig,
            cast.scheme,
            cast.height_scale,
            head,
            format!("{filled}/{}", cast.slots.len()),
            if props.is_empty() { "-".to_string() } else { props.join(",") }
        );
    }
    Ok(())
}
