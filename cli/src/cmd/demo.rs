//! `throng demo`: every stage on the bundled demo shot, with a summary of
//! what each wrote.

use std::path::{Path, PathBuf};
use std::time::Instant;

use clap::Args;

use throng::casting::table::{cast_stats, mib};
use throng::error::{Error, Result};
use throng::layers::{build_layers, set_bounds, LayerOverrides, MapOptions};
use throng::output::FULL_LAYER;
use throng::render::colour::{self, Colourspace};
use throng::render::job::{self, RenderJob};

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
    #[arg(long, default_value_t = 16, value_parser = super::values::spp)]
    pub spp: u32,
    /// Motion blur shutter OPEN,CLOSE in frames (default: a 180-degree shutter centred on the
    /// frame), or `off` for instants.
    #[arg(long, default_value = "-0.25,0.25", value_parser = super::values::shutter, allow_hyphen_values = true)]
    pub shutter: super::values::ShutterFlag,
    /// Denoise the renders with Open Image Denoise at this preset, or `off` (default: `high` when
    /// the library is installed, else off with a line saying how to install it).
    #[arg(long, value_enum)]
    pub denoise: Option<super::render::DenoiseFlag>,
}

/// `throng demo`: every stage on the bundled demo shot.
pub fn run(args: &DemoArgs) -> Result<()> {
    let started = Instant::now();
    let shot_path = match &args.shot {
        Some(p) => p.clone(),
        None => {
            // From the repository, or the checkout the binary was built
            // from (this crate is its `cli/`: the demo is beside it).
            let here = PathBuf::from("demo/shot.toml");
            if here.exists() {
                here
            } else {
                Path::new(env!("CARGO_MANIFEST_DIR")).join("../demo/shot.toml")
            }
        }
    };
    let out = &args.out;
    std::fs::create_dir_all(out).map_err(|e| Error::io(out, e))?;
    outln!("throng demo: {}", shot_path.display());

    let t = Instant::now();
    let shutter = args.shutter.0;
    let crowd = super::cast_shot(throng::shot::Shot::load(&shot_path)?, shutter)?;
    let info = throng::cache::info(crowd.cache())?;
    outln!(
        "  cache    {} agents over cache frames {}-{}, {} rigs, {} cycles",
        info.agents,
        info.frame_first.unwrap_or(0),
        info.frame_last.unwrap_or(0),
        info.rigs.len(),
        info.cycles.len()
    );
    let stats = cast_stats(&crowd);
    outln!(
        "  cast     {} agents, {} part instances of {} unique parts and {} materials ({} shared vs {} copied)  [{:.2} s]",
        stats.agents,
        stats.part_instances,
        stats.unique_parts,
        stats.unique_materials,
        mib(stats.unique_geometry_bytes),
        mib(stats.copied_geometry_bytes),
        t.elapsed().as_secs_f64()
    );

    let t = Instant::now();
    let manifest = build_layers(&crowd, &LayerOverrides { per_frame: true, ..Default::default() })?;
    let manifest_path = out.join(format!("{}.layers.json", crowd.shot().name));
    let map = out.join("layers_map.png");
    let glb = out.join(format!("{}.{}.glb", crowd.shot().name, manifest.ref_frame));
    let f = crowd.shot().frames;
    let mut layers = job::all_layers(&manifest);
    layers.push(FULL_LAYER.to_string());
    let (denoise, without) = match args.denoise {
        Some(flag) => (flag.preset(), None),
        None => match throng::render::denoise::Denoiser::open(None, 0) {
            Ok(_) => (Some(throng::shot::Denoise::High), None),
            Err(e) => (None, Some(e)),
        },
    };
    let render = RenderJob {
        png: true,
        shutter,
        denoise,
        colourspace: crowd.shot().render.working_colourspace,
        ..RenderJob::new(layers, vec![f.start, manifest.ref_frame, f.end], args.spp, out.join("render"))
    };
    // No output over an input: `--out` beside the shot may hold it, its cache or its rigs.
    let outputs = render.outputs(&crowd.shot().name);
    throng::output::InputFiles::new(crowd.input_files()).check_all(
        [manifest_path.as_path(), map.as_path(), glb.as_path()].into_iter().chain(outputs.iter().map(PathBuf::as_path)),
    )?;
    // Under --strict the render's warnings stop the demo before its first file.
    if super::STRICT.load(std::sync::atomic::Ordering::Relaxed) {
        for w in job::warnings_before_writing(&crowd, Some(&manifest), &render)? {
            super::warn(&w)?;
        }
    }
    throng::layers::write_manifest(&manifest_path, &manifest)?;
    throng::layers::draw_map(
        &manifest,
        &MapOptions { size: (1600, 900), set_bounds: set_bounds(&crowd), ..Default::default() },
        &map,
    )?;
    outln!(
        "  layers   {} crowd layers + set, ranked at frame {}: 0 pops fixed (per-frame ranking would pop {} agents)  [{:.2} s]",
        manifest.layers.len(),
        manifest.ref_frame,
        manifest.pops.agents_changed,
        t.elapsed().as_secs_f64()
    );

    let t = Instant::now();
    let s = throng::export::export_frame(&crowd, manifest.ref_frame, None, &glb)?;
    outln!(
        "  export   {} agents, {} mesh nodes sharing {} meshes  [{:.2} s]",
        s.agents,
        s.mesh_nodes,
        s.meshes,
        t.elapsed().as_secs_f64()
    );

    let t = Instant::now();
    let (shot_name, [w, h]) = (crowd.shot().name.clone(), crowd.shot().render.resolution);
    let colourspace = render.colourspace;
    let progress = super::progress::Progress::new(super::progress::ProgressStyle::Auto);
    // The render's working colourspace converts the library's colours (the
    // glTF export above wrote them as authored, linear Rec.709).
    let report = match colourspace {
        Colourspace::Rec709 => job::run(&crowd, Some(&manifest), &render, &progress),
        Colourspace::Acescg => job::run(&colour::into_acescg(crowd), Some(&manifest), &render, &progress),
    };
    progress.finish();
    let done = report?.layers;
    if let Some(e) = &without {
        outln!("  denoise  off: {}", super::wording(e));
    }
    let blur = match shutter {
        Some([open, close]) => format!("motion blur, shutter {open}..{close} frames"),
        None => "no motion blur".to_string(),
    };
    outln!(
        "  render   {} layer-frames at {w}x{h}, {} spp, {blur}, {}  [{:.1} s]",
        done.len(),
        render.spp,
        match render.denoise {
            Some(d) => format!("denoised ({}, {:.1} s of it)", d.name(), done.iter().map(|l| l.denoise_s).sum::<f64>()),
            None => "not denoised".to_string(),
        },
        t.elapsed().as_secs_f64()
    );

    outln!("done in {:.1} s. Wrote under {}:", started.elapsed().as_secs_f64(), out.display());
    let rows = [
        (manifest_path.display().to_string(), "the layer manifest (docs/layers.md)".to_string()),
        (map.display().to_string(), "the layer map: who is in which layer".to_string()),
        (glb.display().to_string(), format!("frame {} as glTF (open in Blender)", manifest.ref_frame)),
        (
            format!("{}/<layer>/{shot_name}.<layer>.<frame>.exr", render.out.display()),
            "EXR layers (docs/render.md), PNG previews beside them".to_string(),
        ),
    ];
    let width = rows.iter().map(|(p, _)| p.len()).max().unwrap_or(0);
    for (path, what) in &rows {
        outln!("  {path:<width$}  {what}");
    }
    outln!("Look at the PNGs, or the EXRs with `exrheader FILE` (Debian: openexr) or any compositor.");
    if let Some(a) = manifest.agents.iter().find(|a| a.layer == 0 && !a.removed) {
        outln!("Ask about an agent: throng botinfo {} {} --frame {}", shot_path.display(), a.id, manifest.ref_frame);
    }
    outln!("Look and click: throng review {} --renders {}", shot_path.display(), render.out.display());
    Ok(())
}
