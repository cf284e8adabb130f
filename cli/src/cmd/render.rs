//! `throng render`: path-traced EXR layers.

use std::path::PathBuf;

use clap::{Args, ValueEnum};

use super::progress::{Progress, ProgressStyle};
use super::values::{frame_list, resolution, shutter, spp, FrameList, Resolution, ShutterFlag};
use throng::error::{Error, Result};
use throng::output::FULL_LAYER;
use throng::render::colour::{self, Colourspace};
use throng::render::exr;
use throng::render::job::{self, CryptoOutput, RenderJob};
use throng::scene::passes::PassSet;

/// `--cryptomatte`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum CryptoFlag {
    /// Manifest in the EXR header.
    Header,
    /// Manifest in a JSON beside the EXR.
    Sidecar,
    /// No Cryptomatte channels.
    Off,
}

impl From<CryptoFlag> for CryptoOutput {
    fn from(f: CryptoFlag) -> CryptoOutput {
        match f {
            CryptoFlag::Header => CryptoOutput::Header,
            CryptoFlag::Sidecar => CryptoOutput::Sidecar,
            CryptoFlag::Off => CryptoOutput::Off,
        }
    }
}

/// `--compression`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum CompressionFlag {
    /// ZIP, 16-line blocks: lossless (the default).
    Zip,
    /// ZIP per scanline: lossless.
    Zips,
    /// PIZ wavelet: lossless, often smaller on noisy renders.
    Piz,
    /// B44: lossy on half channels (beauty, N, albedo), for previews; Z, agent.id and Cryptomatte stay exact.
    B44,
    /// Uncompressed.
    None,
}

impl From<CompressionFlag> for exr::LayerCompression {
    fn from(f: CompressionFlag) -> exr::LayerCompression {
        match f {
            CompressionFlag::Zip => exr::LayerCompression::Zip,
            CompressionFlag::Zips => exr::LayerCompression::Zips,
            CompressionFlag::Piz => exr::LayerCompression::Piz,
            CompressionFlag::B44 => exr::LayerCompression::B44,
            CompressionFlag::None => exr::LayerCompression::None,
        }
    }
}

/// `--colourspace`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ColourspaceFlag {
    /// Linear Rec.709 / sRGB primaries, D65 white.
    Rec709,
    /// ACEScg (AP1 primaries, ACES white): every input colour converted from linear Rec.709.
    Acescg,
}

/// `--denoise`: Open Image Denoise's preset, or `off`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum DenoiseFlag {
    /// Best quality, for finals.
    High,
    /// Faster, a little softer (dailies).
    Balanced,
    /// Fastest (previews).
    Fast,
    /// Not denoised, whatever the shot says.
    Off,
}

impl DenoiseFlag {
    /// The library's preset (`None`: off).
    pub fn preset(self) -> Option<throng::shot::Denoise> {
        match self {
            DenoiseFlag::High => Some(throng::shot::Denoise::High),
            DenoiseFlag::Balanced => Some(throng::shot::Denoise::Balanced),
            DenoiseFlag::Fast => Some(throng::shot::Denoise::Fast),
            DenoiseFlag::Off => None,
        }
    }
}

impl From<ColourspaceFlag> for throng::shot::Colourspace {
    fn from(f: ColourspaceFlag) -> throng::shot::Colourspace {
        match f {
            ColourspaceFlag::Rec709 => throng::shot::Colourspace::Rec709,
            ColourspaceFlag::Acescg => throng::shot::Colourspace::Acescg,
        }
    }
}

/// `--progress`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, ValueEnum)]
pub enum ProgressFlag {
    /// A bar on a terminal, plain lines otherwise.
    Auto,
    /// One line redrawn in place.
    Bar,
    /// One flushed line per finished frame or block of tiles, with percent and ETA (farm logs).
    Plain,
    /// No progress.
    Off,
}

impl From<ProgressFlag> for ProgressStyle {
    fn from(f: ProgressFlag) -> ProgressStyle {
        match f {
            ProgressFlag::Auto => ProgressStyle::Auto,
            ProgressFlag::Bar => ProgressStyle::Bar,
            ProgressFlag::Plain => ProgressStyle::Plain,
            ProgressFlag::Off => ProgressStyle::Off,
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
    #[arg(long, value_parser = frame_list)]
    pub frames: Option<FrameList>,
    /// Samples per pixel, 1-65536 (default: the shot's); in every pixel, overriding the shot's
    /// `render.adaptive`.
    #[arg(long, value_parser = spp)]
    pub spp: Option<u32>,
    /// Output directory.
    #[arg(long)]
    pub out: PathBuf,
    /// Skip frames whose EXR already exists, reads back whole and records the same render settings
    /// (`throng/renderFingerprint`: spp, resolution, seed, camera, lights, manifest); re-render the rest.
    #[arg(long)]
    pub resume: bool,
    /// Layer manifest (default: `<shot dir>/<shot name>.layers.json`, from `throng layers`).
    #[arg(long)]
    pub manifest: Option<PathBuf>,
    /// Also write an 8-bit sRGB PNG preview beside each EXR (premultiplied RGB over black, clamped to 0-1; no tone mapping).
    #[arg(long)]
    pub png: bool,
    /// Image size override, e.g. 480x270 (default: the shot's).
    #[arg(long, value_parser = resolution)]
    pub resolution: Option<Resolution>,
    /// Cryptomatte mattes (CryptoAgent, CryptoPart).
    #[arg(long, value_enum, default_value_t = CryptoFlag::Header)]
    pub cryptomatte: CryptoFlag,
    /// EXR compression.
    #[arg(long, value_enum, default_value_t = CompressionFlag::Zip)]
    pub compression: CompressionFlag,
    /// Progress on stderr.
    #[arg(long, value_enum, default_value_t = ProgressFlag::Auto)]
    pub progress: ProgressFlag,
    /// Print a machine-readable summary (files, seconds, instances, peak memory) instead of the line.
    #[arg(long)]
    pub json: bool,
    /// Motion blur: shutter OPEN,CLOSE in frames relative to each frame (e.g. -0.25,0.25 for a
    /// 180-degree shutter centred on the frame), or `off` (default: the shot's `render.shutter`).
    /// Also writes the motion-vector pass (forward.u, forward.v).
    #[arg(long, value_parser = shutter, allow_hyphen_values = true)]
    pub shutter: Option<ShutterFlag>,
    /// Working colourspace (default: the shot's `render.working_colourspace`, else rec709). Input
    /// colours are linear Rec.709; acescg converts them and writes AP1 `chromaticities`.
    #[arg(long, value_enum)]
    pub colourspace: Option<ColourspaceFlag>,
    /// Passes beyond beauty and the data passes, comma-separated: diffuse_direct, diffuse_indirect,
    /// specular_direct, specular_indirect, transmission, emission, environment, atmosphere,
    /// light_groups (one lg_<name> per light group), P (world position), shadow (the set layer's
    /// crowd shadows), atmosphere_transmittance, or all (default: the shot's `render.passes`; the
    /// air's two only for a shot with air).
    #[arg(long, value_delimiter = ',', value_name = "NAME,...", value_parser = super::values::pass_name)]
    pub passes: Option<Vec<String>>,
    /// Denoise every layer and light pass with Intel Open Image Denoise (albedo and normal guides,
    /// prefiltered); the noisy beauty stays as noisy.R/G/B. `--denoise` alone is `high` (default:
    /// the shot's `render.denoise`, else off). Needs the library: `python3 -m pip install --no-deps
    /// --target .oidn pyoidn==2.5.1.0` in the checkout, or THRONG_OIDN=<its lib folder>.
    #[arg(long, value_enum, num_args = 0..=1, default_missing_value = "high", value_name = "QUALITY")]
    pub denoise: Option<DenoiseFlag>,
    /// Also write every layer-frame as a deep scanline OpenEXR beside the flat one,
    /// `<shot>.<layer>.<frame>.deep.exr` (deep samples per object and depth; default: the shot's
    /// `[render.deep]`, whose keys set the per-pixel cap, depth tolerance and compression).
    #[arg(long)]
    pub deep: bool,
}

/// `throng render SHOT ...`: renders the asked layers and frames.
/// `threads`: the process's `--threads` cap, if any.
pub fn run(args: &RenderArgs, threads: Option<usize>) -> Result<()> {
    let clock = std::time::Instant::now();
    let shot = throng::shot::Shot::load(&args.shot)?;
    // The crowd is posed for the shutter it renders with.
    let shutter = args.shutter.map_or(shot.render.shutter, |ShutterFlag(s)| s);
    let colourspace = args.colourspace.map_or(shot.render.working_colourspace, Into::into);
    let crowd = super::cast_shot(shot, shutter)?;
    let manifest_path = args
        .manifest
        .clone()
        .unwrap_or_else(|| throng::layers::default_manifest_path(&crowd.shot().path, &crowd.shot().name));
    let manifest = if manifest_path.exists() {
        Some(super::read_current_manifest(&manifest_path, crowd.shot())?)
    } else if args.layer == FULL_LAYER {
        None
    } else {
        return Err(Error::Usage(format!(
            "no layer manifest at {}: run `throng layers {}` first (or render --layer full)",
            manifest_path.display(),
            args.shot.display()
        )));
    };
    if let Some(m) = &manifest {
        if m.shot != crowd.shot().name {
            return Err(Error::invalid(
                &manifest_path,
                format!("manifest is for shot `{}`, not `{}`", m.shot, crowd.shot().name),
            ));
        }
    }
    let layers = match (args.layer.as_str(), &manifest) {
        ("all", Some(m)) => job::all_layers(m),
        (l, _) => vec![l.to_string()],
    };
    let frames = match &args.frames {
        Some(FrameList(f)) => f.clone(),
        None => crowd.shot().frames.iter().collect(),
    };
    let spp = args.spp.unwrap_or(crowd.shot().render.spp);
    let passes = args.passes.as_ref().map(|names| PassSet::parse(names, "--passes")).transpose()?;
    let job = RenderJob {
        passes,
        // --spp asks for a fixed count: it overrides the shot's render.adaptive.
        adaptive: if args.spp.is_some() { None } else { crowd.shot().render.adaptive },
        threads: threads.unwrap_or(0),
        resume: args.resume,
        png: args.png,
        resolution: args.resolution.map(|Resolution(r)| r),
        cryptomatte: args.cryptomatte.into(),
        compression: args.compression.into(),
        shutter,
        colourspace,
        denoise: args.denoise.map_or(crowd.shot().render.denoise, DenoiseFlag::preset),
        deep: match (args.deep, &crowd.shot().render.deep) {
            (_, Some(d)) => Some(d.clone()),
            (true, None) => Some(throng::shot::Deep::default()),
            (false, None) => None,
        },
        ..RenderJob::new(layers, frames, spp, args.out.clone())
    };
    // No output over an input: the shot's files and the manifest.
    let mut inputs = throng::output::InputFiles::new(crowd.input_files());
    if manifest.is_some() {
        inputs.extend([("layer manifest".to_string(), manifest_path.clone())]);
    }
    inputs.check_all(job.outputs(&crowd.shot().name).iter().map(PathBuf::as_path))?;
    let progress = Progress::new(args.progress.into());
    let report = match colourspace {
        Colourspace::Rec709 => job::run(&crowd, manifest.as_ref(), &job, &progress),
        Colourspace::Acescg => job::run(&colour::into_acescg(crowd), manifest.as_ref(), &job, &progress),
    };
    progress.finish();
    let done = report?.layers;
    if args.json {
        let written = (done.iter().filter(|d| !d.skipped))
            .flat_map(|d| std::iter::once(d.path.clone()).chain(d.deep.as_ref().map(|w| w.path.clone())))
            .collect();
        let instances = done.iter().map(|d| d.instances as u64).sum();
        let mut summary = super::Summary::new("render", clock, instances, written);
        summary.files_skipped = done.iter().filter(|d| d.skipped).map(|d| d.path.clone()).collect();
        summary.layer_frames = Some(
            done.iter()
                .filter(|d| !d.skipped)
                .map(|d| super::LayerFrameSummary {
                    layer: d.layer.clone(),
                    frame: d.frame,
                    seconds: d.seconds,
                    instances: d.instances as u64,
                    peak_rss_bytes: d.peak_rss_bytes,
                    tlas_build_s: d.tlas_build_s,
                    denoise_s: d.denoise_s,
                    file_bytes: d.file_bytes,
                    deep: d.deep.as_ref().map(super::DeepSummary::of),
                    passes: d
                        .pass_bytes
                        .iter()
                        .map(|(name, bytes)| super::PassSummary { name: name.clone(), bytes: *bytes })
                        .collect(),
                })
                .collect(),
        );
        // The per-layer resets lower VmHWM: the process peak is the largest of them.
        summary.peak_rss_bytes = done.iter().filter_map(|d| d.peak_rss_bytes).chain(summary.peak_rss_bytes).max();
        return summary.print();
    }
    let rendered = done.iter().filter(|d| !d.skipped).count();
    let secs: f64 = done.iter().map(|d| d.seconds).sum();
    outln!(
        "rendered {rendered} layer-frames ({} skipped as complete) in {secs:.1} s into {}",
        done.len() - rendered,
        args.out.display()
    );
    // Each layer's measured peak memory (the largest over its frames): what a budget must hold.
    let mut peaks: Vec<(&str, u64)> = Vec::new();
    for d in done.iter().filter(|d| !d.skipped) {
        let Some(b) = d.peak_rss_bytes else { continue };
        match peaks.iter_mut().find(|(l, _)| *l == d.layer) {
            Some(p) => p.1 = p.1.max(b),
            None => peaks.push((&d.layer, b)),
        }
    }
    if !peaks.is_empty() {
        let list: Vec<String> = peaks.iter().map(|(l, b)| format!("{l} {:.1} MiB", *b as f64 / 1048576.0)).collect();
        outln!("peak memory per layer: {}", list.join(", "));
    }
    Ok(())
}
