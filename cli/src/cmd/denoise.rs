//! `throng denoise`: denoise rendered files as a step of their own (as
//! studios run RenderMan's denoise utility or Arnold's noice on the farm).

use std::path::PathBuf;

use clap::Args;

use throng::error::{Error, Result};
use throng::render::denoise::{denoise_file, Denoiser};

use super::render::DenoiseFlag;

/// `throng denoise`.
#[derive(Debug, Args)]
pub struct DenoiseArgs {
    /// Layer or comp EXRs written by `throng render` or `throng comp` (with their albedo and normal
    /// channels), not denoised yet.
    #[arg(required = true)]
    pub files: Vec<PathBuf>,
    /// Folder for the denoised files (same file names); never an input's own folder's file.
    #[arg(long)]
    pub out: PathBuf,
    /// Open Image Denoise's preset.
    #[arg(long, value_enum, default_value_t = DenoiseFlag::High)]
    pub quality: DenoiseFlag,
    /// Print a machine-readable summary instead of the lines.
    #[arg(long)]
    pub json: bool,
}

/// `throng denoise FILES... --out DIR [--quality high|balanced|fast]`.
pub fn run(args: &DenoiseArgs, threads: Option<usize>) -> Result<()> {
    let clock = std::time::Instant::now();
    let Some(preset) = args.quality.preset() else {
        return Err(Error::Usage("--quality off: nothing to do (the inputs are left as they are)".into()));
    };
    if !args.out.is_dir() {
        return Err(Error::Usage(format!("--out {}: not a folder (create it first)", args.out.display())));
    }
    let mut outputs: Vec<PathBuf> = Vec::new();
    for f in &args.files {
        let Some(name) = f.file_name() else {
            return Err(Error::Usage(format!("{}: not a file name", f.display())));
        };
        let out = args.out.join(name);
        if outputs.contains(&out) {
            return Err(Error::Usage(format!(
                "two inputs are named {}: their outputs in {} would collide",
                name.to_string_lossy(),
                args.out.display()
            )));
        }
        outputs.push(out);
    }
    // No output over any input, and one writer per output file.
    let inputs = throng::output::InputFiles::new(args.files.iter().map(|f| ("file to denoise".to_string(), f.clone())));
    inputs.check_all(outputs.iter().map(PathBuf::as_path))?;
    let _claims = throng::output::WriterLock::claim_files(outputs.iter().map(PathBuf::as_path))?;
    // Every file checked before any is written or the library is looked for.
    for f in &args.files {
        throng::render::denoise::check_input(f)?;
    }
    let denoiser = Denoiser::open(None, threads.unwrap_or(0))?;
    for (input, output) in args.files.iter().zip(&outputs) {
        let started = std::time::Instant::now();
        denoise_file(&denoiser, input, output, preset)?;
        if !args.json {
            outln!("{} -> {} ({:.2} s)", input.display(), output.display(), started.elapsed().as_secs_f64());
        }
    }
    if args.json {
        return super::Summary::new("denoise", clock, 0, outputs).print();
    }
    outln!(
        "denoised {} file(s) with Open Image Denoise {} ({}) in {:.1} s",
        args.files.len(),
        denoiser.version(),
        preset.name(),
        clock.elapsed().as_secs_f64()
    );
    Ok(())
}
