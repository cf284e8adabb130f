//! `throng botinfo`: the botInfo block of agents, by id or by pixel.

use std::path::PathBuf;

use clap::Args;

use super::values::{pixel, Pixel};
use throng::botinfo::{add_layers, bot_info, format_bot_info};
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
            if x >= film.width || y >= film.height {
                return Err(Error::Usage(format!(
                    "pixel {x},{y} is outside {} ({}x{}; 0,0 is the top-left pixel)",
                    exr_path.display(),
                    film.width,
                    film.height
                )));
            }
            if args.frame.is_some_and(|f| f != meta.frame) {
                return Err(Error::Usage(format!(
                    "--frame {} disagrees with {}, which is frame {}",
                    args.frame.unwrap_or_default(),
                    exr_path.display(),
                    meta.frame
                )));
            }
            let id = film.agent_id[film.index(x, y)];
            if id == 0 {
                outln!("no agent at pixel {x},{y} (set or sky) in {} frame {}", exr_path.display(), meta.frame);
                return Ok(());
            }
            Some((shot.clone(), id - 1, meta, exr_path.clone(), (x, y)))
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
    if !crowd.shot().frames.contains(frame) {
        return Err(Error::Usage(format!(
            "frame {frame} is outside shot {} ({}-{})",
            crowd.shot().name,
            crowd.shot().frames.start,
            crowd.shot().frames.end
        )));
    }
    let mut infos = bot_info(&crowd, &ids, frame)?;
    let manifest_path = throng::layers::default_manifest_path(&crowd.shot().path, &crowd.shot().name);
    if manifest_path.exists() {
        let manifest = throng::layers::read_manifest(&manifest_path)?;
        if manifest.shot == crowd.shot().name {
            add_layers(&mut infos, &manifest);
        }
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
    Ok(())
}
