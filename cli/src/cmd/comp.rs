//! `throng comp`: stack a frame's layers into one EXR.

use std::path::PathBuf;

use clap::Args;

use throng::error::Result;
use throng::render::exr;

/// `throng comp`.
#[derive(Debug, Args)]
pub struct CompArgs {
    /// Render output directory.
    pub dir: PathBuf,
    /// Shot frame.
    #[arg(long, value_parser = super::values::frame)]
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
    /// Print a machine-readable summary instead of the line.
    #[arg(long)]
    pub json: bool,
}

/// `throng comp DIR --frame F --out FILE.exr [--png FILE.png] [--manifest FILE]`.
pub fn run(args: &CompArgs) -> Result<()> {
    let clock = std::time::Instant::now();
    super::existing_folder_of(&args.out, "--out")?;
    if let Some(png) = &args.png {
        super::existing_folder_of(png, "--png")?;
    }
    let manifest = args.manifest.as_deref().map(throng::layers::read_manifest).transpose()?;
    // No output over an input: the layer EXRs stacked and the manifest.
    let mut inputs = throng::output::InputFiles::new(
        throng::comp::layer_files(&args.dir, args.frame, manifest.as_ref())?
            .into_iter()
            .map(|(layer, path)| (format!("layer {layer} EXR"), path)),
    );
    inputs.extend(args.manifest.iter().map(|m| ("layer manifest".to_string(), m.clone())));
    inputs.check_all(std::iter::once(args.out.as_path()).chain(args.png.as_deref()))?;
    // One writer per output file: held until the files are written.
    let _claims =
        throng::output::WriterLock::claim_files(std::iter::once(args.out.as_path()).chain(args.png.as_deref()))?;
    let comped = throng::comp::comp_frame(&args.dir, args.frame, manifest.as_ref())?;
    for w in &comped.warnings {
        super::warn(w)?;
    }
    exr::write_layer(&args.out, &comped.film, &comped.meta)?;
    if let Some(png) = &args.png {
        exr::write_preview_png_from(png, &comped.film, comped.meta.colourspace)?;
    }
    if args.json {
        let files = std::iter::once(args.out.clone()).chain(args.png.clone()).collect();
        return super::Summary::new("comp", clock, comped.layers.len() as u64, files).print();
    }
    let names: Vec<&str> = comped.layers.iter().map(|l| l.0.as_str()).collect();
    outln!(
        "comp {} frame {}: {} (back to front) -> {}",
        comped.meta.shot,
        args.frame,
        names.join(", "),
        args.out.display()
    );
    Ok(())
}
