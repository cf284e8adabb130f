//! `throng export`: one frame of the shot as glTF, or a frame range as USD.

use std::path::PathBuf;

use clap::Args;

use super::values::{frame_list, FrameList};
use throng::error::{Error, Result};

/// `--format`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum ExportFormat {
    /// One frame as binary glTF (`--frame`).
    Glb,
    /// A frame range as USD (`--frames`; .usda, .usd (text) or .usdz by the --out extension; .usdc is refused).
    Usd,
}

/// `--usd-instancing`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum UsdInstancing {
    /// Agents as prims, parts as instanceable prims (default).
    Prims,
    /// One PointInstancer per part slot, ids = agent ids.
    PointInstancer,
}

/// `throng export`.
#[derive(Debug, Args)]
pub struct ExportArgs {
    /// Shot file.
    pub shot: PathBuf,
    /// Shot frame (glTF).
    #[arg(long, value_parser = super::values::frame)]
    pub frame: Option<i32>,
    /// Output format.
    #[arg(long, value_enum, default_value = "glb")]
    pub format: ExportFormat,
    /// Shot frame range A-B (USD; default: the shot's).
    #[arg(long, value_parser = frame_list)]
    pub frames: Option<FrameList>,
    /// USD: the layer manifest (default: `<shot dir>/<shot>.layers.json` when it exists).
    #[arg(long)]
    pub manifest: Option<PathBuf>,
    /// USD: one file per render layer beside --out, sublayered by it.
    #[arg(long)]
    pub split_layers: bool,
    /// USD: how agents are instanced (docs/usd.md).
    #[arg(long, value_enum, default_value = "prims")]
    pub usd_instancing: UsdInstancing,
    /// Only this layer's agents.
    #[arg(long)]
    pub layer: Option<String>,
    /// Output .glb, or .usda / .usd / .usdz.
    #[arg(long)]
    pub out: PathBuf,
    /// Print a machine-readable summary instead of the line.
    #[arg(long)]
    pub json: bool,
}

/// `throng export SHOT --frame F [--layer L] --out scene.glb`.
pub fn run(args: &ExportArgs) -> Result<()> {
    let clock = std::time::Instant::now();
    super::existing_folder_of(&args.out, "--out")?;
    if args.format == ExportFormat::Usd {
        return run_usd(args, clock);
    }
    let Some(frame) = args.frame else {
        return Err(Error::Usage("a glTF export needs --frame F (or --format usd --frames A-B)".into()));
    };
    let crowd = super::load_crowd(&args.shot)?;
    if !crowd.shot().frames.contains(frame) {
        return Err(Error::Usage(format!(
            "frame {} is outside shot {} ({}-{})",
            frame,
            crowd.shot().name,
            crowd.shot().frames.start,
            crowd.shot().frames.end
        )));
    }
    refuse_input_overwrite(args, &crowd)?;
    let _claim = claim_out(args)?;
    // --layer: only that crowd layer's agents, from the manifest beside the shot.
    let only = layer_agents(args, &crowd)?;
    let s = throng::export::export_frame(&crowd, frame, only.as_ref(), &args.out)?;
    if args.json {
        return super::Summary::new("export", clock, s.mesh_nodes as u64, vec![args.out.clone()]).print();
    }
    outln!(
        "wrote {}: {} agents, {} mesh nodes sharing {} meshes, {} instanced triangles",
        args.out.display(),
        s.agents,
        s.mesh_nodes,
        s.meshes,
        s.instanced_triangles
    );
    Ok(())
}

/// Refuses an `--out` that is one of the files the export reads: the
/// shot's, and the manifest (given, or the one beside the shot).
fn refuse_input_overwrite(args: &ExportArgs, crowd: &throng::casting::ShotCrowd) -> Result<()> {
    let mut inputs = crowd.input_files();
    let manifest = (args.manifest.clone())
        .unwrap_or_else(|| throng::layers::default_manifest_path(&crowd.shot().path, &crowd.shot().name));
    if manifest.exists() {
        inputs.push(("layer manifest".into(), manifest));
    }
    throng::output::refuse_input_overwrite([args.out.as_path()], inputs)
}

/// Claims `--out` for this process until the export returns (one writer per file).
fn claim_out(args: &ExportArgs) -> Result<Vec<throng::output::WriterLock>> {
    throng::output::WriterLock::claim_files([args.out.as_path()])
}

/// `--format usd`.
fn run_usd(args: &ExportArgs, clock: std::time::Instant) -> Result<()> {
    use throng::export::usd::{export_usd, Instancing, UsdExportOptions};
    if args.frame.is_some() {
        return Err(Error::Usage("a USD export takes --frames A-B, not --frame".into()));
    }
    let crowd = super::load_crowd(&args.shot)?;
    let frames = match &args.frames {
        None => (crowd.shot().frames.start, crowd.shot().frames.end),
        Some(FrameList(list)) => {
            let (a, b) = (list.iter().min().copied().unwrap_or(0), list.iter().max().copied().unwrap_or(0));
            if list.len() != (b - a + 1) as usize {
                return Err(Error::Usage("a USD export takes a contiguous --frames A-B range".into()));
            }
            (a, b)
        }
    };
    refuse_input_overwrite(args, &crowd)?;
    let _claim = claim_out(args)?;
    let only = layer_agents(args, &crowd)?;
    let manifest = match &args.manifest {
        Some(p) => Some(super::read_current_manifest(p, crowd.shot())?),
        None => super::beside_manifest(&crowd)?,
    };
    let opts = UsdExportOptions {
        only: only.as_ref(),
        manifest: manifest.as_ref(),
        split_layers: args.split_layers,
        instancing: match args.usd_instancing {
            UsdInstancing::Prims => Instancing::Prims,
            UsdInstancing::PointInstancer => Instancing::PointInstancer,
        },
        ..UsdExportOptions::new(frames)
    };
    let s = export_usd(&crowd, &opts, &args.out)?;
    if args.json {
        return super::Summary::new("export", clock, s.instances as u64, s.files.clone()).print();
    }
    println!(
        "wrote {}: {} agents over {} frames, {} instances of {} shared prototypes, {} materials, {} prims, {} bytes in {} file(s)",
        args.out.display(),
        s.agents,
        s.frames,
        s.instances,
        s.prototypes,
        s.materials,
        s.prims,
        s.bytes,
        s.files.len()
    );
    Ok(())
}

/// `--layer`: only that crowd layer's agents, from the manifest beside the shot.
fn layer_agents(
    args: &ExportArgs,
    crowd: &throng::casting::ShotCrowd,
) -> Result<Option<std::collections::BTreeSet<u32>>> {
    Ok(match &args.layer {
        None => None,
        Some(layer) => {
            let path = (args.manifest.clone())
                .unwrap_or_else(|| throng::layers::default_manifest_path(&crowd.shot().path, &crowd.shot().name));
            if !path.exists() {
                return Err(Error::Usage(format!(
                    "--layer needs the layer manifest {}: run `throng layers {}` first",
                    path.display(),
                    args.shot.display()
                )));
            }
            let m = super::read_current_manifest(&path, crowd.shot())?;
            Some(m.layer_agents(layer).map_err(|names| {
                Error::Usage(format!("no crowd layer `{layer}` in {} (layers: {})", path.display(), names.join(", ")))
            })?)
        }
    })
}
