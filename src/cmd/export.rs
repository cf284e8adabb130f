//! `throng export`: one frame of the shot as glTF.

use std::path::PathBuf;

use clap::Args;

use crate::error::{Error, Result};

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
    /// Print a machine-readable summary instead of the line.
    #[arg(long)]
    pub json: bool,
}

/// `throng export SHOT --frame F [--layer L] --out scene.glb`.
pub fn run(args: &ExportArgs) -> Result<()> {
    let clock = std::time::Instant::now();
    // Like a shell redirect, export writes into an existing folder only: a
    // typo in --out must not create a tree somewhere unexpected.
    if let Some(dir) = args.out.parent().filter(|d| !d.as_os_str().is_empty() && !d.is_dir()) {
        return Err(Error::Usage(format!(
            "--out {}: the folder {} does not exist (create it first)",
            args.out.display(),
            dir.display()
        )));
    }
    let crowd = super::load_crowd(&args.shot)?;
    if !crowd.shot.frames.contains(args.frame) {
        return Err(Error::Usage(format!(
            "frame {} is outside shot {} ({}-{})",
            args.frame, crowd.shot.name, crowd.shot.frames.start, crowd.shot.frames.end
        )));
    }
    // --layer: only that crowd layer's agents, from the manifest beside the shot.
    let only = match &args.layer {
        None => None,
        Some(layer) => {
            let path = crate::layers::default_manifest_path(&crowd.shot.path, &crowd.shot.name);
            if !path.exists() {
                return Err(Error::Usage(format!(
                    "--layer needs the layer manifest {}: run `throng layers {}` first",
                    path.display(),
                    args.shot.display()
                )));
            }
            let m = crate::layers::read_manifest(&path)?;
            Some(m.layer_agents(layer).map_err(|names| {
                Error::Usage(format!("no crowd layer `{layer}` in {} (layers: {})", path.display(), names.join(", ")))
            })?)
        }
    };
    let s = crate::export::export_frame(&crowd, args.frame, only.as_ref(), &args.out)?;
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
