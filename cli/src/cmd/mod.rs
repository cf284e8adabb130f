//! The command line: one file per verb, each owning its clap arguments and
//! its human and `--json` printing. Typed flag values are parsed here, at
//! parse time, so a bad value fails with clap's message before any work.
//! Nothing outside `cmd` imports clap or this module; stages take plain
//! option structs.

use clap::{Parser, Subcommand};

use throng::error::Result;

/// `print!` to stdout that prints nothing more, quietly, once stdout is
/// closed (`throng botinfo ... --json | head`); the verb's exit status stands.
macro_rules! out {
    ($($t:tt)*) => { $crate::cmd::emit(&format!($($t)*)) };
}

/// `println!` with [`out!`]'s closed-stdout rule.
macro_rules! outln {
    () => { $crate::cmd::emit("\n") };
    ($($t:tt)*) => { $crate::cmd::emit(&format!("{}\n", format_args!($($t)*))) };
}

pub mod botinfo;
pub mod cache;
pub mod cast;
pub mod comp;
pub mod demo;
pub mod denoise;
pub mod export;
pub mod farm;
pub mod layers;
mod progress;
pub mod render;
pub mod review;
pub mod shell;
pub mod sim;
mod values;

/// throng: crowd renderer and level-of-detail layering tool for lighters.
#[derive(Debug, Parser)]
#[command(name = "throng", version, propagate_version = true, about, long_about = None)]
// clap's own `help` verb takes no `--help` (`throng help --help` was a
// usage error); [`Verb::Help`] and the farm's and cache's are ours.
#[command(disable_help_subcommand = true)]
pub struct Cli {
    /// The verb.
    #[command(subcommand)]
    pub verb: Verb,
    /// Threads for every stage of this process, 1-4096: casting, posing, BVH builds, rendering and
    /// EXR compression share one cap (default: every core). Output does not depend on it.
    #[arg(long, global = true, value_parser = values::threads)]
    pub threads: Option<usize>,
    /// Treat every warning as an error, for pipelines: the command stops at the first one with exit
    /// status 2; every verb gives its warnings before it writes its first output, so it writes none.
    #[arg(long, global = true)]
    pub strict: bool,
}

/// Whether warnings are errors (`--strict`), set once before the verb runs.
static STRICT: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Tells the user something legal but surprising on stderr; under
/// `--strict` it is an error instead, which the caller returns at once.
pub(crate) fn warn(text: &dyn std::fmt::Display) -> Result<()> {
    if STRICT.load(std::sync::atomic::Ordering::Relaxed) {
        return Err(throng::error::Error::Usage(format!("{text} (a warning, an error under --strict)")));
    }
    eprintln!("throng: warning: {text}");
    Ok(())
}

/// Reads the layer manifest at `path`; one of `shot` is refused when it is
/// stale (`layers::check_current`; one an older throng made passes with a
/// warning). One of another shot is left to the caller to refuse.
pub(crate) fn read_current_manifest(
    path: &std::path::Path,
    shot: &throng::shot::Shot,
) -> Result<throng::layers::Manifest> {
    let mut m = throng::layers::read_manifest(path)?;
    if m.shot == shot.name {
        if let Some(warning) = throng::layers::check_current(path, &mut m, shot)? {
            warn(&warning)?;
        }
    }
    Ok(m)
}

/// The manifest beside the shot when `throng layers` wrote one for it
/// (checked by [`read_current_manifest`]).
pub(crate) fn beside_manifest(crowd: &throng::casting::ShotCrowd) -> Result<Option<throng::layers::Manifest>> {
    let path = throng::layers::default_manifest_path(&crowd.shot().path, &crowd.shot().name);
    if !path.exists() {
        return Ok(None);
    }
    let m = read_current_manifest(&path, crowd.shot())?;
    Ok((m.shot == crowd.shot().name).then_some(m))
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
    /// Denoise rendered layer or comp files (Open Image Denoise) into another folder.
    Denoise(denoise::DenoiseArgs),
    /// Write one frame of the shot as glTF (.glb), or a frame range as USD (.usda, .usd, .usdz).
    Export(export::ExportArgs),
    /// A local web page of the shot's layers: click an agent to read its botInfo.
    Review(review::ReviewArgs),
    /// Plan, submit and follow a shot on a render farm (Slurm) or local workers.
    #[command(subcommand)]
    Farm(farm::FarmVerb),
    /// Print a shell completion script (bash, zsh, fish, elvish, powershell).
    Completions(shell::CompletionsArgs),
    /// Print the man page, or write one per verb with --out DIR.
    Man(shell::ManArgs),
    /// Print this message or the help of the given verb(s).
    Help(shell::HelpArgs),
}

/// Runs one parsed command line.
pub fn run(cli: Cli) -> Result<()> {
    start_threads(cli.threads)?;
    STRICT.store(cli.strict, std::sync::atomic::Ordering::Relaxed);
    match cli.verb {
        Verb::Demo(args) => demo::run(&args),
        Verb::Cache(verb) => cache::run(&verb),
        Verb::Sim(args) => sim::run(&args),
        Verb::Cast(args) => cast::run(&args),
        Verb::Botinfo(args) => botinfo::run(&args),
        Verb::Layers(args) => layers::run(&args),
        Verb::Render(args) => render::run(&args, cli.threads),
        Verb::Comp(args) => comp::run(&args),
        Verb::Denoise(args) => denoise::run(&args, cli.threads),
        Verb::Export(args) => export::run(&args),
        Verb::Review(args) => review::run(&args, cli.threads),
        Verb::Farm(verb) => farm::run(&verb),
        Verb::Completions(args) => shell::completions(&args),
        Verb::Man(args) => shell::man(&args),
        Verb::Help(args) => shell::help(&[], &args),
    }
}

/// Starts the process's global thread pool, `n` threads (`--threads`) or
/// one per core, and caps every other pool at `n`. Each stage runs on
/// rayon: the global pool (casting, posing, BVH builds), the render pool
/// and the exr crate's compression pool; rayon sizes every pool built
/// without an explicit size by `RAYON_NUM_THREADS`, set here before any
/// pool or thread exists (so no other thread can read the environment
/// meanwhile); the render pool gets `n` explicitly as well.
///
/// The global pool is built here, fallibly: left to rayon, it is built on
/// first use and a pool that cannot start (too little address space for
/// the threads' stacks, a process limit) panics inside rayon. Here it is
/// exit 2 naming `--threads` and the cause.
fn start_threads(n: Option<usize>) -> Result<()> {
    if let Some(n) = n {
        std::env::set_var("RAYON_NUM_THREADS", n.to_string());
    }
    // Refused before any thread starts when their stacks cannot fit: a pool
    // that starts some threads and then fails can leave a started one
    // panicking for want of its signal stack.
    let threads = n.unwrap_or_else(|| std::thread::available_parallelism().map_or(1, usize::from));
    if let Some(left) = address_space_left() {
        let need = threads as u64 * THREAD_ADDRESS_SPACE;
        // The stage's own pool (the render's) takes as many again, and the data needs room.
        if need * 2 + DATA_ROOM > left {
            let cause = format!(
                "their stacks need {:.1} GiB of address space twice over (the global and the render pool), with \
                 1 GiB for data, and the process may map {:.1} GiB more (ulimit -v)",
                need as f64 / GIB,
                left as f64 / GIB
            );
            return Err(threads_error(n, &cause));
        }
    }
    let mut pool = rayon::ThreadPoolBuilder::new();
    if let Some(n) = n {
        pool = pool.num_threads(n);
    }
    pool.build_global().map_err(|e| threads_error(n, &e))
}

const GIB: f64 = (1u64 << 30) as f64;

/// Address space kept for a stage's data when sizing pools.
const DATA_ROOM: u64 = 1 << 30;

/// Address space one pool thread maps: its stack (Rust's and rayon's
/// default 2 MiB) and the guard and signal-stack pages std adds.
const THREAD_ADDRESS_SPACE: u64 = (2 << 20) + (64 << 10);

/// Bytes of address space this process may still map under its soft
/// `RLIMIT_AS` (`ulimit -v`), from /proc; `None` when unlimited or unknown.
fn address_space_left() -> Option<u64> {
    let limits = std::fs::read_to_string("/proc/self/limits").ok()?;
    let soft = limits.lines().find(|l| l.starts_with("Max address space"))?.split_whitespace().nth(3)?;
    let limit: u64 = soft.parse().ok()?; // "unlimited" -> None
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let kib: u64 = status.lines().find(|l| l.starts_with("VmSize:"))?.split_whitespace().nth(1)?.parse().ok()?;
    Some(limit.saturating_sub(kib * 1024))
}

/// Why the global pool did not start, naming `--threads`.
fn threads_error(n: Option<usize>, cause: &dyn std::fmt::Display) -> throng::error::Error {
    let msg = match n {
        Some(n) => format!("cannot start {n} threads ({cause}); give fewer, or leave --threads out for one per core"),
        None => format!(
            "cannot start one thread per core ({} threads: {cause}); give fewer with --threads N",
            std::thread::available_parallelism().map_or(0, usize::from)
        ),
    };
    throng::error::Error::Setting { option: "threads", msg }
}

/// An error as the command line says it: a stage's option (`Error::Setting`)
/// is named by its flag (`workers` -> `--workers`); the rest as the stage says.
pub fn wording(e: &throng::error::Error) -> String {
    match e {
        throng::error::Error::Setting { option, msg } => format!("--{}: {msg}", option.replace('_', "-")),
        e => e.to_string(),
    }
}

/// Whether stdout was found closed: nothing more is written to it.
static STDOUT_CLOSED: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(false);

/// Writes `text` to stdout and flushes. A closed pipe (EPIPE) stops the
/// printing, quietly (the reader has what it wanted), not the verb: its exit
/// status is its own, whatever reads stdout (`farm status PLAN | head` is 1
/// on an unfinished plan, as without the pipe). Any other write error ends
/// the process with status 2 and the reason.
pub(crate) fn emit(text: &str) {
    use std::io::Write;
    use std::sync::atomic::Ordering;
    if STDOUT_CLOSED.load(Ordering::Relaxed) {
        return;
    }
    let mut out = std::io::stdout().lock();
    if let Err(e) = out.write_all(text.as_bytes()).and_then(|()| out.flush()) {
        if e.kind() == std::io::ErrorKind::BrokenPipe {
            STDOUT_CLOSED.store(true, Ordering::Relaxed);
            return;
        }
        eprintln!("throng: error: cannot write to stdout: {e}");
        std::process::exit(2);
    }
}

/// One rule for every verb: an output file goes into a folder that exists
/// (like a shell redirect, so a typo in a path never grows a tree
/// somewhere unexpected); an output folder (`render --out`, `farm plan
/// --out`, `demo --out`) is created.
fn existing_folder_of(out: &std::path::Path, flag: &str) -> Result<()> {
    match out.parent().filter(|d| !d.as_os_str().is_empty() && !d.is_dir()) {
        Some(dir) => Err(throng::error::Error::Usage(format!(
            "{flag} {}: the folder {} does not exist (create it first)",
            out.display(),
            dir.display()
        ))),
        None => Ok(()),
    }
}

/// Loads and casts a shot for still frames, printing what loading noticed
/// but accepted (renormalised weights, ignored morph targets) to stderr, once.
fn load_crowd(shot: &std::path::Path) -> Result<throng::casting::ShotCrowd> {
    cast_shot(throng::shot::Shot::load(shot)?, None)
}

/// Casts a loaded shot, posed for still frames and `shutter`, printing what
/// loading noticed but accepted to stderr, once.
fn cast_shot(shot: throng::shot::Shot, shutter: Option<[f32; 2]>) -> Result<throng::casting::ShotCrowd> {
    let crowd = throng::casting::ShotCrowd::open(shot, shutter)?;
    for w in crowd.warnings() {
        warn(w)?;
    }
    Ok(crowd)
}

/// Pretty JSON of a summary, for `--json` outputs.
fn to_json(value: &impl serde::Serialize) -> Result<String> {
    serde_json::to_string_pretty(value).map_err(|e| throng::error::Error::Usage(format!("cannot print JSON: {e}")))
}

/// The `--json` summary of `render`, `comp`, `export` and `sim`
/// (docs/farm.md, "Machine-readable summaries").
#[derive(Debug, serde::Serialize)]
struct Summary {
    /// The verb.
    verb: &'static str,
    /// Files written, in the order written.
    files_written: Vec<std::path::PathBuf>,
    /// Files found complete and skipped (`render --resume`).
    files_skipped: Vec<std::path::PathBuf>,
    /// Wall-clock seconds of the verb.
    seconds: f64,
    /// Instances traced (render), mesh nodes written (export), agents simulated (sim), layers stacked (comp).
    instances: u64,
    /// Peak resident memory of the process, bytes (null where /proc is missing).
    peak_rss_bytes: Option<u64>,
    /// `render`: each layer-frame rendered, with its own measured peak
    /// memory (`[]` when every one was skipped as complete); absent for other verbs.
    #[serde(skip_serializing_if = "Option::is_none")]
    layer_frames: Option<Vec<LayerFrameSummary>>,
}

/// One rendered layer-frame in the `render --json` summary.
#[derive(Debug, serde::Serialize)]
struct LayerFrameSummary {
    layer: String,
    frame: i32,
    seconds: f64,
    instances: u64,
    /// Peak resident memory while this layer-frame rendered, bytes.
    peak_rss_bytes: Option<u64>,
    /// Seconds building the top-level tree.
    tlas_build_s: f64,
    /// Seconds denoising (part of `seconds`; 0 when not denoised).
    denoise_s: f64,
    /// Bytes of the EXR written.
    file_bytes: u64,
    /// The deep EXR written beside it (`--deep`).
    #[serde(skip_serializing_if = "Option::is_none")]
    deep: Option<DeepSummary>,
    /// Each pass written and its channels' bytes before compression.
    passes: Vec<PassSummary>,
}

/// A layer-frame's deep file in `render --json`.
#[derive(Debug, serde::Serialize)]
struct DeepSummary {
    path: std::path::PathBuf,
    file_bytes: u64,
    /// File bytes per million pixels of the image.
    bytes_per_megapixel: u64,
    /// Deep samples in the file, and per pixel on average.
    samples: u64,
    samples_per_pixel: f64,
    max_samples_per_pixel: u32,
}

impl DeepSummary {
    fn of(w: &throng::render::job::DeepWritten) -> DeepSummary {
        let pixels = w.pixels.max(1);
        DeepSummary {
            path: w.path.clone(),
            file_bytes: w.file_bytes,
            bytes_per_megapixel: (w.file_bytes as f64 * 1e6 / pixels as f64).round() as u64,
            samples: w.samples,
            samples_per_pixel: w.samples as f64 / pixels as f64,
            max_samples_per_pixel: w.max_samples_per_pixel,
        }
    }
}

/// One pass of a layer file in `render --json`.
#[derive(Debug, serde::Serialize)]
struct PassSummary {
    name: String,
    /// Its channels' bytes in the file before compression (compression
    /// works on blocks of every channel at once, so a pass has no compressed size of its own).
    bytes: u64,
}

impl Summary {
    fn new(
        verb: &'static str,
        clock: std::time::Instant,
        instances: u64,
        files_written: Vec<std::path::PathBuf>,
    ) -> Self {
        Summary {
            verb,
            files_written,
            files_skipped: Vec::new(),
            seconds: clock.elapsed().as_secs_f64(),
            instances,
            peak_rss_bytes: throng::bench::peak_rss_bytes(),
            layer_frames: None,
        }
    }
    fn print(&self) -> Result<()> {
        outln!("{}", to_json(self)?);
        Ok(())
    }
}
