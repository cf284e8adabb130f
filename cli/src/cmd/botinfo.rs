//! `throng botinfo`: the botInfo block of agents, by id or by pixel.

use std::path::PathBuf;

use clap::Args;

use super::values::{pixel, Pixel};
use throng::botinfo::{agent_at_pixel, bot_info_with_layers_each, format_bot_info};
use throng::error::{Error, Result};

/// `throng botinfo`.
#[derive(Debug, Args)]
pub struct BotinfoArgs {
    /// Shot file (required; without it, --exr says which shot the EXR's header names).
    pub shot: Option<PathBuf>,
    /// Agent ids.
    pub ids: Vec<u32>,
    /// Shot frame (default: the shot's first frame).
    #[arg(long)]
    pub frame: Option<i32>,
    /// Machine-readable output.
    #[arg(long)]
    pub json: bool,
    /// Pick the agent at this pixel of --exr: X,Y.
    #[arg(long, requires = "exr", value_name = "X,Y", value_parser = pixel)]
    pub pixel: Option<Pixel>,
    /// Rendered layer to pick from.
    #[arg(long)]
    pub exr: Option<PathBuf>,
    /// Layer manifest for each agent's layer and LOD (default: <shot dir>/<shot>.layers.json when it exists).
    #[arg(long)]
    pub manifest: Option<PathBuf>,
}

/// `throng botinfo`: by ids, or by `--exr FILE --pixel X,Y` (the agent at
/// that pixel of a rendered layer or comp, at the file's frame).
pub fn run(args: &BotinfoArgs) -> Result<()> {
    if args.exr.is_some() && args.pixel.is_none() {
        return Err(Error::Usage("--exr needs --pixel X,Y".into()));
    }
    let picked = match (&args.exr, args.pixel) {
        (Some(exr_path), Some(Pixel { x, y })) => {
            if !args.ids.is_empty() {
                return Err(Error::Usage("give agent ids or --pixel, not both".into()));
            }
            let (film, meta) = throng::render::exr::read_layer(exr_path)?;
            let Some(shot) = &args.shot else {
                return Err(Error::Usage(format!(
                    "botinfo --exr needs the shot file too: {} is from shot `{}` (throng botinfo SHOT --exr FILE --pixel X,Y)",
                    exr_path.display(),
                    meta.shot
                )));
            };
            if args.frame.is_some_and(|f| f != meta.frame) {
                return Err(Error::Usage(format!(
                    "--frame {} disagrees with {}, which is frame {}",
                    args.frame.unwrap_or_default(),
                    exr_path.display(),
                    meta.frame
                )));
            }
            let Some(id) = agent_at_pixel(&film.agent_id, film.width, film.height, x, y, exr_path)? else {
                outln!("no agent at pixel {x},{y} (set or sky) in {} frame {}", exr_path.display(), meta.frame);
                return Ok(());
            };
            Some((shot.clone(), id, meta, exr_path.clone(), (x, y)))
        }
        _ => None,
    };
    let Some(shot) = &args.shot else {
        return Err(Error::Usage("botinfo needs a shot file".into()));
    };
    if picked.is_none() && args.ids.is_empty() {
        return Err(Error::Usage("name at least one agent id (or --exr FILE --pixel X,Y)".into()));
    }
    let crowd = super::load_crowd(shot)?;
    let (ids, frame) = match &picked {
        Some((_, id, meta, exr_path, _)) => {
            if meta.shot != crowd.shot().name {
                return Err(Error::invalid(
                    exr_path,
                    format!("EXR is from shot `{}` but {} is shot `{}`", meta.shot, shot.display(), crowd.shot().name),
                )
                .field("throng/shot"));
            }
            (vec![*id], meta.frame)
        }
        None => (args.ids.clone(), args.frame.unwrap_or(crowd.shot().frames.start)),
    };
    let manifest = match &args.manifest {
        Some(path) => {
            let m = super::read_current_manifest(path, crowd.shot())?;
            if m.shot != crowd.shot().name {
                return Err(Error::Usage(format!(
                    "--manifest {} is for shot `{}`, not {} (shot `{}`)",
                    path.display(),
                    m.shot,
                    shot.display(),
                    crowd.shot().name
                )));
            }
            Some(m)
        }
        None => super::beside_manifest(&crowd)?,
    };
    // Every agent found is printed; each one that is not is named after them.
    let (infos, mut missing) = bot_info_with_layers_each(&crowd, &ids, frame, manifest.as_ref())?;
    if infos.is_empty() && !missing.is_empty() {
        return Err(missing.remove(0));
    }
    if args.json {
        outln!("{}", super::to_json(&infos)?);
    } else {
        if let Some((_, _, meta, exr_path, (x, y))) = &picked {
            outln!("pixel {x},{y} of {} (layer {}, frame {})", exr_path.display(), meta.layer, meta.frame);
        }
        let blocks: Vec<String> = infos.iter().map(format_bot_info).collect();
        out!("{}", blocks.join("\n"));
    }
    if !missing.is_empty() {
        for e in &missing {
            eprintln!("throng: error: {}", super::wording(e));
        }
        return Err(Error::Usage(format!("{} of {} agents not found (named above)", missing.len(), ids.len())));
    }
    Ok(())
}
