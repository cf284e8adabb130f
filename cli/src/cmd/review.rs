//! `throng review`: the shot's rendered layers, map and figures on a local
//! web page; click an agent to read its botInfo (docs/review.md).

use std::net::IpAddr;
use std::path::PathBuf;

use clap::Args;

use throng::error::{Error, Result};
use throng::review::{LiveOptions, Review, ReviewOptions};

use super::values::{resolution, Resolution};

/// `throng review`.
#[derive(Debug, Args)]
pub struct ReviewArgs {
    /// Shot file.
    pub shot: PathBuf,
    /// Render output folder (`<layer>/<shot>.<layer>.<frame>.exr`), as `render --out` wrote it.
    #[arg(long)]
    pub renders: Option<PathBuf>,
    /// Layer manifest (default: <shot dir>/<shot>.layers.json, else <shot>.layers.json beside or in --renders).
    #[arg(long)]
    pub manifest: Option<PathBuf>,
    /// The frame the page opens on (default: the first rendered).
    #[arg(long, value_parser = super::values::frame)]
    pub frame: Option<i32>,
    /// Port to listen on (0: any free port).
    #[arg(long, default_value_t = 8028, value_parser = super::values::port)]
    pub port: u16,
    /// Address to listen on; anything but loopback lets other machines read the shot.
    #[arg(long, default_value = "127.0.0.1", value_parser = super::values::ip)]
    pub bind: IpAddr,
    /// Memory kept for decoded EXRs and images between requests (e.g. 512MB, 2GB).
    #[arg(long, default_value = "1GiB", value_parser = super::values::bytes)]
    pub cache: u64,
    /// Open the page in the desktop's browser.
    #[arg(long)]
    pub open: bool,
    /// Also render the page's frame live, in memory, and render it again whenever the shot file
    /// or a file it reads changes (docs/review.md, "Live preview"); uses at most --threads cores.
    #[arg(long)]
    pub live: bool,
    /// The live preview's size, e.g. 480x270 (default: a quarter of the shot's resolution).
    #[arg(long, value_parser = resolution, requires = "live")]
    pub live_resolution: Option<Resolution>,
}

/// `throng review`: serves until interrupted. `threads`: the process's
/// `--threads` cap, if any (the live preview's pool).
pub fn run(args: &ReviewArgs, threads: Option<usize>) -> Result<()> {
    let crowd = super::load_crowd(&args.shot)?;
    let options = ReviewOptions {
        renders: args.renders.clone(),
        manifest: args.manifest.clone(),
        frame: args.frame,
        bind: args.bind,
        port: args.port,
        cache_bytes: args.cache,
        live: args.live.then(|| LiveOptions {
            resolution: args.live_resolution.map(|Resolution(r)| r),
            threads: threads.unwrap_or(0),
            ..LiveOptions::default()
        }),
    };
    let review = Review::open(crowd, &args.shot, &options)?;
    match review.manifest_path() {
        Some(m) => eprintln!("throng review: layer manifest {}", m.display()),
        None => eprintln!("throng review: no layer manifest (no map, layers or LOD); run `throng layers` to make one"),
    }
    if args.renders.is_none() {
        let what = if args.live { "the live preview, figures and map" } else { "figures and map only" };
        eprintln!("throng review: no --renders folder: {what}");
    }
    if !args.bind.is_loopback() {
        eprintln!("throng review: warning: listening on {}: other machines can read the shot's files", args.bind);
    }
    let url = review.url();
    let live = if args.live { "; live: renders the page's frame as the shot changes" } else { "" };
    outln!("throng review: {url}  (read-only{live}; Ctrl-C to stop)");
    if args.open {
        let opener = if cfg!(target_os = "macos") { "open" } else { "xdg-open" };
        if let Err(e) = std::process::Command::new(opener).arg(&url).spawn() {
            eprintln!("throng review: warning: --open: cannot run {opener}: {e}; open {url} by hand");
        }
    }
    review.serve();
    Err(Error::Usage("the review server stopped".into()))
}
