//! `throng cache info` and `throng cache convert`.

use std::collections::HashSet;
use std::path::PathBuf;

use clap::{Args, Subcommand};

use crate::cache::{info, read_with, write, CacheReader, Format, ImportInfo, ImportOptions};
use crate::casting::rig::import_clip;
use crate::error::{Error, Result};

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

impl ImportArgs {
    /// The import options these flags ask for (reads `--rig-file`).
    fn options(&self) -> Result<ImportOptions> {
        // The flags are checked before the rig file is read.
        ImportOptions::new(&self.rig, &self.cycle, self.stride, self.cycle_length, None)?;
        let clip = self.rig_file.as_deref().map(|f| import_clip(f, &self.rig, &self.cycle)).transpose()?;
        ImportOptions::new(&self.rig, &self.cycle, self.stride, self.cycle_length, clip)
    }
}

/// Runs a `throng cache` verb.
pub fn run(verb: &CacheVerb) -> Result<()> {
    match verb {
        CacheVerb::Info(args) => run_info(args),
        CacheVerb::Convert(args) => run_convert(args),
    }
}

/// `throng cache info FILE [--json]`: prints to stdout.
fn run_info(args: &CacheInfoArgs) -> Result<()> {
    let format = Format::of(&args.file)?;
    let opts = match format {
        Format::JuPedSim => args.import.options()?,
        _ => ImportOptions::default(),
    };
    let reader = CacheReader::open_with(&args.file, &opts)?;
    let mut info = info(&reader)?;
    if format == Format::JuPedSim {
        info.import = Some(ImportInfo {
            rig: opts.rig.clone(),
            cycle: opts.cycle.clone(),
            stride: opts.stride(),
            cycle_length: opts.cycle_length(),
            rig_file: opts.rig_clip.as_ref().map(|c| c.file.display().to_string()),
        });
    }
    if args.json {
        outln!("{}", super::to_json(&info)?);
    } else {
        out!("{}", info.to_text());
        if format == Format::JuPedSim {
            outln!("{:<8} {}", "import", opts.describe());
        }
    }
    Ok(())
}

/// `throng cache convert IN OUT`: reads IN whole, writes OUT atomically.
fn run_convert(args: &CacheConvertArgs) -> Result<()> {
    let (from, to) = (Format::of(&args.input)?, Format::of(&args.output)?);
    if to == Format::JuPedSim {
        return Err(Error::Usage(format!(
            "{}: JuPedSim files are read only; convert to .crowd or .csv",
            args.output.display()
        )));
    }
    let opts = match from {
        Format::JuPedSim => args.import.options()?,
        _ => ImportOptions::default(),
    };
    let crowd = read_with(&args.input, &opts)?;
    write(&args.output, &crowd)?;
    let agents: HashSet<u32> = crowd.frames.iter().flat_map(|b| b.agents.iter().map(|a| a.id)).collect();
    outln!(
        "wrote {} ({}): {} frames, {} agents, from {} ({})",
        args.output.display(),
        to.name(),
        crowd.frames.len(),
        agents.len(),
        args.input.display(),
        from.name()
    );
    if from == Format::JuPedSim {
        outln!("import: {}", opts.describe());
    }
    Ok(())
}
