//! The command line: one file per verb, each owning its clap arguments and
//! its human and `--json` printing. Typed flag values are parsed here, at
//! parse time, so a bad value fails with clap's message before any work.
//! Nothing outside `cmd` imports clap or this module; stages take plain
//! option structs.

use clap::{Parser, Subcommand};

use crate::error::Result;

pub mod botinfo;
pub mod cache;
pub mod cast;
pub mod comp;
pub mod demo;
pub mod export;
pub mod layers;
pub mod render;
pub mod sim;
mod values;

/// throng: crowd renderer and level-of-detail layering tool for lighters.
#[derive(Debug, Parser)]
#[command(name = "throng", version, about, long_about = None)]
pub struct Cli {
    /// The verb.
    #[command(subcommand)]
    pub verb: Verb,
}

/// The verbs of DESIGN.md.
#[derive(Debug, Subcommand)]
pub enum Verb {
    /// Build the bundled demo shot and run every stage on it.
    Demo(demo::DemoArgs),
    /// Inspect and convert simulation caches.
    #[command(subcommand)]
    Cache(cache::CacheVerb),
    /// Reference steering simulation that writes a cache.
    Sim(sim::SimArgs),
    /// The casting table: scheme, parts, materials and height of every agent.
    Cast(cast::CastArgs),
    /// Who is agent N? Rig, cycle, frame, scheme, parts, height, layer.
    Botinfo(botinfo::BotinfoArgs),
    /// Split agents into render layers by distance to camera at one frame.
    Layers(layers::LayersArgs),
    /// Path-trace layers into multi-channel OpenEXR files.
    Render(render::RenderArgs),
    /// Stack a frame's layers back into one image.
    Comp(comp::CompArgs),
    /// Write one frame of the shot as glTF (.glb).
    Export(export::ExportArgs),
}

/// Runs one parsed command line.
pub fn run(cli: Cli) -> Result<()> {
    match cli.verb {
        Verb::Demo(args) => demo::run(&args),
        Verb::Cache(verb) => cache::run(&verb),
        Verb::Sim(args) => sim::run(&args),
        Verb::Cast(args) => cast::run(&args),
        Verb::Botinfo(args) => botinfo::run(&args),
        Verb::Layers(args) => layers::run(&args),
        Verb::Render(args) => render::run(&args),
        Verb::Comp(args) => comp::run(&args),
        Verb::Export(args) => export::run(&args),
    }
}

/// Loads and casts a shot, printing what loading noticed but accepted
/// (renormalised weights, ignored morph targets) to stderr, once.
fn load_crowd(shot: &std::path::Path) -> Result<crate::casting::ShotCrowd> {
    let crowd = crate::casting::ShotCrowd::load(shot)?;
    for w in &crowd.warnings {
        eprintln!("throng: warning: {w}");
    }
    Ok(crowd)
}

/// Pretty JSON of a summary, for `--json` outputs.
fn to_json(value: &impl serde::Serialize) -> Result<String> {
    serde_json::to_string_pretty(value).map_err(|e| crate::error::Error::Usage(format!("cannot print JSON: {e}")))
}
