//! `throng comp`: stack a frame's layers into one EXR.

use std::path::PathBuf;

use clap::Args;

use throng::error::Result;
use throng::render::exr;
use throng::render::job::deep_layer_path;

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
    /// Merge the layers' deep files (`render --deep`) by depth, as Nuke's DeepMerge does, into a
    /// deep comp beside --out (`<out stem>.deep.exr`); the flat comp's R G B A are the deep comp
    /// flattened.
    #[arg(long)]
    pub deep: bool,
}

/// `throng comp DIR --frame F --out FILE.exr [--png FILE.png] [--manifest FILE] [--deep]`.
pub fn run(args: &CompArgs) -> Result<()> {
    let clock = std::time::Instant::now();
    super::existing_folder_of(&args.out, "--out")?;
    let deep_out = args.deep.then(|| deep_layer_path(&args.out));
    let outputs = || std::iter::once(args.out.as_path()).chain(args.png.as_deref()).chain(deep_out.as_deref());
    if let Some(png) = &args.png {
        super::existing_folder_of(png, "--png")?;
    }
    let manifest = args.manifest.as_deref().map(throng::layers::read_manifest).transpose()?;
    // No output over an input: the layer EXRs stacked and the manifest.
    let layers = throng::comp::layer_files(&args.dir, args.frame, manifest.as_ref())?;
    let mut inputs = throng::output::InputFiles::new(layers.iter().flat_map(|(layer, path)| {
        let deep = args.deep.then(|| (format!("layer {layer} deep EXR"), deep_layer_path(path)));
        std::iter::once((format!("layer {layer} EXR"), path.clone())).chain(deep)
    }));
    inputs.extend(args.manifest.iter().map(|m| ("layer manifest".to_string(), m.clone())));
    inputs.check_all(outputs())?;
    // One writer per output file: held until the files are written.
    let _claims = throng::output::WriterLock::claim_files(outputs())?;
    let (comped, deep) = if args.deep {
        let d = throng::comp::deep::comp_frame_deep(&args.dir, args.frame, manifest.as_ref())?;
        (d.flat, Some(d.deep))
    } else {
        (throng::comp::comp_frame(&args.dir, args.frame, manifest.as_ref())?, None)
    };
    for w in &comped.warnings {
        super::warn(w)?;
    }
    exr::write_layer(&args.out, &comped.film, &comped.meta)?;
    if let (Some(image), Some(path)) = (&deep, &deep_out) {
        exr::deep::write_deep(path, image, &comped.film, &comped.meta, exr::deep::DeepCompression::default())?;
    }
    if let Some(png) = &args.png {
        exr::write_preview_png_from(png, &comped.film, comped.meta.colourspace)?;
    }
    if args.json {
        let files = std::iter::once(args.out.clone()).chain(args.png.clone()).chain(deep_out.clone()).collect();
        return super::Summary::new("comp", clock, comped.layers.len() as u64, files).print();
    }
    let names: Vec<&str> = comped.layers.iter().map(|l| l.0.as_str()).collect();
    let deep_note = deep_out.as_ref().map(|p| format!(" and {} (deep)", p.display())).unwrap_or_default();
    outln!(
        "comp {} frame {}: {} (back to front) -> {}{deep_note}",
        comped.meta.shot,
        args.frame,
        names.join(", "),
        args.out.display()
    );
    Ok(())
}
