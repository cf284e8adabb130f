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
    /// Agent ids: the agents' ids in the cache, as `throng cast` lists them.
    #[arg(value_name = "ID", value_parser = super::values::agent_id)]
    pub ids: Vec<u32>,
    /// Shot frame (default: the shot's first frame).
    #[arg(long, value_parser = super::values::frame)]
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
        (Some(exr_path), Some(pixel)) => Some(pick(args, exr_path, pixel)?),
        _ => None,
    };
    let Some(shot) = &args.shot else {
        return Err(Error::Usage("botinfo needs a shot file".into()));
    };
    if picked.is_none() && args.ids.is_empty() {
        if !shot.exists() {
            // `throng botinfo 17`: the first argument is the shot file.
            return Err(Error::Usage(format!(
                "`{}` is not a shot file (no such file): botinfo takes the shot file first, then agent ids (throng botinfo SHOT ID...)",
                shot.display()
            )));
        }
        return Err(Error::Usage(format!(
            "name at least one agent id after the shot file (throng botinfo {} ID..., or --exr FILE --pixel X,Y)",
            shot.display()
        )));
    }
    let (crowd, ids, frame) = match picked {
        Some(Picked { agent: None, meta, exr, pixel: Pixel { x, y }, .. }) => {
            // The set or sky: said in the form asked for, and not an error.
            if args.json {
                let v = serde_json::json!({
                    "file": exr,
                    "layer": meta.layer,
                    "frame": meta.frame,
                    "pixel": [x, y],
                    "agent": null,
                });
                outln!("{}", super::to_json(&v)?);
            } else {
                outln!("no agent at pixel {x},{y} (set or sky) in {} frame {}", exr.display(), meta.frame);
            }
            return Ok(());
        }
        Some(Picked { shot, agent: Some(id), meta, exr, pixel: Pixel { x, y } }) => {
            if !args.json {
                outln!("pixel {x},{y} of {} (layer {}, frame {})", exr.display(), meta.layer, meta.frame);
            }
            (super::cast_shot(shot, None)?, vec![id], meta.frame)
        }
        None => {
            let crowd = super::load_crowd(shot)?;
            let frame = args.frame.unwrap_or(crowd.shot().frames.start);
            (crowd, args.ids.clone(), frame)
        }
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

/// What `--exr FILE --pixel X,Y` picked: the shot (loaded, checked to be
/// the file's), and the agent at the pixel (`None`: set or sky).
struct Picked {
    shot: throng::shot::Shot,
    agent: Option<u32>,
    meta: throng::render::exr::LayerMeta,
    exr: PathBuf,
    pixel: Pixel,
}

/// Reads the pixel of `--exr`, after checking the file is a throng layer
/// (or comp) of the shot given and of the frame asked: a file of another
/// shot is refused whether or not an agent is at the pixel.
fn pick(args: &BotinfoArgs, exr: &std::path::Path, pixel: Pixel) -> Result<Picked> {
    if !args.ids.is_empty() {
        return Err(Error::Usage("give agent ids or --pixel, not both".into()));
    }
    let (film, meta) = throng::render::exr::read_layer(exr).map_err(|e| not_a_layer(exr, e))?;
    let Some(shot_path) = &args.shot else {
        return Err(Error::Usage(format!(
            "botinfo --exr needs the shot file too: {} is from shot `{}` (throng botinfo SHOT --exr FILE --pixel X,Y)",
            exr.display(),
            meta.shot
        )));
    };
    if args.frame.is_some_and(|f| f != meta.frame) {
        return Err(Error::Usage(format!(
            "--frame {} disagrees with {}, which is frame {}",
            args.frame.unwrap_or_default(),
            exr.display(),
            meta.frame
        )));
    }
    let shot = throng::shot::Shot::load(shot_path)?;
    if meta.shot != shot.name {
        return Err(Error::invalid(
            exr,
            format!(
                "EXR is a render of shot `{}`, not of {} (shot `{}`): give that shot's file",
                meta.shot,
                shot_path.display(),
                shot.name
            ),
        )
        .field("throng/shot"));
    }
    let agent = agent_at_pixel(&film.agent_id, film.width, film.height, pixel.x, pixel.y, exr)?;
    Ok(Picked { shot, agent, meta, exr: exr.to_path_buf(), pixel })
}

/// A file without throng's header attributes (`throng/shot`, ...) is said
/// to be no throng layer, with what it lacks.
fn not_a_layer(exr: &std::path::Path, e: Error) -> Error {
    match e {
        Error::Invalid { msg, .. } if msg.contains("header attribute `throng/") => {
            let key = msg.split('`').nth(1).unwrap_or("throng/shot").to_string();
            Error::invalid(exr, format!("not a throng layer or comp (throng render and comp write one): {msg}"))
                .field(key)
        }
        e => e,
    }
}
