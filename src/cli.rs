//! The command line: verb definitions (clap) and dispatch to the stage
//! modules. Nothing here reads files beyond what the verb's module does.

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand};

use crate::error::Result;

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
    Demo(DemoArgs),
    /// Inspect and convert simulation caches.
    #[command(subcommand)]
    Cache(CacheVerb),
    /// Reference steering simulation that writes a cache.
    Sim(SimArgs),
    /// The casting table: scheme, parts, materials and height of every agent.
    Cast(CastArgs),
    /// Who is agent N? Rig, cycle, frame, scheme, parts, height, layer.
    Botinfo(BotinfoArgs),
    /// Split agents into render layers by distance to camera at one frame.
    Layers(LayersArgs),
    /// Path-trace layers into multi-channel OpenEXR files.
    Render(RenderArgs),
    /// Stack a frame's layers back into one image.
    Comp(CompArgs),
    /// Write one frame of the shot as glTF (.glb).
    Export(ExportArgs),
}

/// `throng demo`.
#[derive(Debug, Args)]
pub struct DemoArgs {
    /// Where to write the demo's outputs.
    #[arg(long, default_value = "out/demo")]
    pub out: PathBuf,
    /// The shot (default: the bundled demo/shot.toml).
    #[arg(long)]
    pub shot: Option<PathBuf>,
    /// Samples per pixel for the demo renders.
    #[arg(long, default_value_t = 16)]
    pub spp: u32,
}

/// `throng cache ...`.
#[derive(Debug, Subcommand)]
pub enum CacheVerb {
    /// Frame range, agent counts, rigs, cycles and bounds of a cache.
    Info(CacheInfoArgs),
    /// Convert between formats, chosen by extension (.crowd, .csv, .sqlite).
    Convert(CacheConvertArgs),
}

/// `throng cache info`.
#[derive(Debug, Args)]
pub struct CacheInfoArgs {
    /// Cache file (.crowd, .csv, or a JuPedSim .sqlite).
    pub file: PathBuf,
    /// Machine-readable output.
    #[arg(long)]
    pub json: bool,
    /// Options for simulator imports.
    #[command(flatten)]
    pub import: ImportArgs,
}

/// `throng cache convert`.
#[derive(Debug, Args)]
pub struct CacheConvertArgs {
    /// Input cache.
    pub input: PathBuf,
    /// Output cache; the format comes from the extension.
    pub output: PathBuf,
    /// Options for simulator imports.
    #[command(flatten)]
    pub import: ImportArgs,
}

/// How to turn a foreign simulator's trajectories into agents.
#[derive(Debug, Args, Clone)]
pub struct ImportArgs {
    /// Rig given to every imported agent.
    #[arg(long, default_value = "bipedThinA")]
    pub rig: String,
    /// Walk cycle given to every imported agent.
    #[arg(long, default_value = "WalkA")]
    pub cycle: String,
    /// Cycle length in frames (the walk cycle loops at this length).
    #[arg(long)]
    pub cycle_length: Option<f32>,
    /// Metres walked per cycle; the cycle frame advances by distance / stride.
    #[arg(long)]
    pub stride: Option<f32>,
    /// Rig glTF to read the cycle's length (frames at 24 fps) and stride (root
    /// travel) from; its rig name must match --rig. --stride and --cycle-length override it.
    #[arg(long)]
    pub rig_file: Option<PathBuf>,
}

/// `throng sim`.
#[derive(Debug, Args)]
pub struct SimArgs {
    /// Simulation scene (TOML).
    pub scene: PathBuf,
    /// Cache to write (.crowd or .csv).
    #[arg(long)]
    pub out: PathBuf,
}

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

/// `throng botinfo`.
#[derive(Debug, Args)]
pub struct BotinfoArgs {
    /// Shot file (optional with --exr, which names its shot in the header).
    pub shot: Option<PathBuf>,
    /// Agent ids.
    pub ids: Vec<u32>,
    /// Shot frame (default: the shot's first frame).
    #[arg(long)]
    pub frame: Option<i32>,
    /// Machine-readable output.
    #[arg(long)]
    pub json: bool,
    /// Pick the agent at this pixel of --exr: X,Y.
    #[arg(long, requires = "exr")]
    pub pixel: Option<String>,
    /// Rendered layer to pick from.
    #[arg(long)]
    pub exr: Option<PathBuf>,
}

/// `throng layers`.
#[derive(Debug, Args)]
pub struct LayersArgs {
    /// Shot file.
    pub shot: PathBuf,
    /// Split into N layers of equal agent count, nearest first.
    #[arg(long, conflicts_with_all = ["cutoffs", "budget"])]
    pub count: Option<usize>,
    /// Split at these distances in metres, e.g. 10,25,60.
    #[arg(long, value_delimiter = ',', conflicts_with = "budget")]
    pub cutoffs: Option<Vec<f32>>,
    /// Split so each layer's estimated render memory stays under this, e.g. 2.8GB.
    #[arg(long)]
    pub budget: Option<String>,
    /// Shot frame to rank at (default: the middle of the shot).
    #[arg(long)]
    pub ref_frame: Option<i32>,
    /// Rank on every frame instead, and report agents that change layer.
    #[arg(long)]
    pub per_frame: bool,
    /// Projected height in pixels below which an agent renders as proxy boxes
    /// (default: the shot's `lod_full_min_px`).
    #[arg(long)]
    pub lod_px: Option<f32>,
    /// Choose LOD on every frame, with hysteresis, instead of once at the reference frame.
    #[arg(long)]
    pub lod_per_frame: bool,
    /// Draw the layer map to this PNG.
    #[arg(long)]
    pub map: Option<PathBuf>,
    /// Where to write the layer manifest (default: beside the shot).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Machine-readable output.
    #[arg(long)]
    pub json: bool,
}

impl LayersArgs {
    /// The shot's own `[layers]` settings, no overrides: what `throng layers SHOT` does.
    pub fn for_shot(shot: PathBuf) -> LayersArgs {
        LayersArgs {
            shot,
            count: None,
            cutoffs: None,
            budget: None,
            ref_frame: None,
            per_frame: false,
            map: None,
            out: None,
            json: false,
            lod_px: None,
            lod_per_frame: false,
        }
    }
}

/// `throng render`.
#[derive(Debug, Args)]
pub struct RenderArgs {
    /// Shot file.
    pub shot: PathBuf,
    /// Layer name, `all`, or `full` (every agent in one pass).
    #[arg(long, default_value = "all")]
    pub layer: String,
    /// Shot frames, e.g. 1001-1010 or 1001,1005.
    #[arg(long)]
    pub frames: Option<String>,
    /// Samples per pixel (default: the shot's).
    #[arg(long)]
    pub spp: Option<u32>,
    /// Render threads (default: all cores). Output does not depend on it.
    #[arg(long)]
    pub threads: Option<usize>,
    /// Output directory.
    #[arg(long)]
    pub out: PathBuf,
    /// Skip frames whose EXR already exists and reads back whole.
    #[arg(long)]
    pub resume: bool,
    /// Layer manifest (default: `<shot dir>/<shot name>.layers.json`, from `throng layers`).
    #[arg(long)]
    pub manifest: Option<PathBuf>,
    /// Also write a tone-mapped PNG preview beside each EXR.
    #[arg(long)]
    pub png: bool,
    /// Image size override, e.g. 480x270 (default: the shot's).
    #[arg(long)]
    pub resolution: Option<String>,
    /// Cryptomatte mattes (CryptoAgent, CryptoPart): `header` (manifest in
    /// the EXR header), `sidecar` (manifest in a JSON beside the EXR) or `off`.
    #[arg(long, default_value = "header")]
    pub cryptomatte: String,
}

/// `throng comp`.
#[derive(Debug, Args)]
pub struct CompArgs {
    /// Render output directory.
    pub dir: PathBuf,
    /// Shot frame.
    #[arg(long)]
    pub frame: i32,
    /// Composited EXR.
    #[arg(long)]
    pub out: PathBuf,
    /// Also write a PNG preview.
    #[arg(long)]
    pub png: Option<PathBuf>,
    /// Layer manifest giving the comp order and the layers that must be there
    /// (default: scan DIR: `set`, then `crowdN` from the highest N down).
    #[arg(long)]
    pub manifest: Option<PathBuf>,
}

/// `throng export`.
#[derive(Debug, Args)]
pub struct ExportArgs {
    /// Shot file.
    pub shot: PathBuf,
    /// Shot frame.
    #[arg(long)]
    pub frame: i32,
    /// Only this layer's agents.
    #[arg(long)]
    pub layer: Option<String>,
    /// Output .glb.
    #[arg(long)]
    pub out: PathBuf,
}

/// Runs one parsed command line.
pub fn run(cli: Cli) -> Result<()> {
    match cli.verb {
        Verb::Demo(args) => crate::commands::cmd_demo(&args),

        Verb::Cache(CacheVerb::Info(args)) => crate::cache::cmd_info(&args),

        Verb::Cache(CacheVerb::Convert(args)) => crate::cache::cmd_convert(&args),

        Verb::Sim(args) => {
            let clock = std::time::Instant::now();
            let scene = crate::sim::Scene::load(&args.scene)?;
            let crowd = crate::sim::run(&scene);
            crate::cache::write(&args.out, &crowd)?;
            println!(
                "throng sim: {} agents, frames {}-{} (simulated from {}), {:.2} s -> {}",
                scene.agents.len(),
                scene.start,
                scene.end,
                scene.first_frame(),
                clock.elapsed().as_secs_f64(),
                args.out.display()
            );
            Ok(())
        }

        Verb::Cast(args) => crate::commands::cmd_cast(&args),

        Verb::Botinfo(args) => crate::commands::cmd_botinfo(&args),

        Verb::Layers(args) => crate::commands::cmd_layers(&args),

        Verb::Render(args) => crate::commands::cmd_render(&args),

        Verb::Comp(args) => crate::comp::cmd_comp(&args),

        Verb::Export(args) => crate::commands::cmd_export(&args),
    }
}
