//! `throng layers`: the layer split, its manifest and map.

use std::path::PathBuf;

use clap::Args;

use super::values::budget;
use throng::error::{Error, Result};
use throng::layers::{self, build_layers, set_bounds, LayerOverrides, MapOptions};

/// `throng layers`.
#[derive(Debug, Args)]
pub struct LayersArgs {
    /// Shot file.
    pub shot: PathBuf,
    /// Split into N layers of equal agent count, nearest first.
    #[arg(long, conflicts_with_all = ["cutoffs", "budget"], value_parser = super::values::count)]
    pub count: Option<usize>,
    /// Split at these distances in metres, e.g. 10,25,60.
    #[arg(long, value_delimiter = ',', conflicts_with = "budget", value_parser = super::values::number)]
    pub cutoffs: Option<Vec<f32>>,
    /// Split so each layer's estimated render memory stays under this, e.g. 2.8GB.
    #[arg(long, value_parser = budget)]
    pub budget: Option<String>,
    /// Shot frame to rank at (default: the middle of the shot).
    #[arg(long, value_parser = super::values::frame)]
    pub ref_frame: Option<i32>,
    /// Also rank on every frame and report how many agents would change layer
    /// (membership stays the reference frame's; the count is for comparison only).
    #[arg(long)]
    pub per_frame: bool,
    /// Projected height in pixels below which an agent renders as proxy boxes
    /// (default: the shot's `lod_full_min_px`).
    #[arg(long, allow_hyphen_values = true, value_parser = super::values::number)]
    pub lod_px: Option<f32>,
    /// Choose LOD on every frame, with hysteresis, instead of once at the reference frame.
    #[arg(long)]
    pub lod_per_frame: bool,
    /// Draw the layer map to this PNG.
    #[arg(long)]
    pub map: Option<PathBuf>,
    /// Where to write the layer manifest (default: beside the shot).
    #[arg(long)]
    pub out: Option<PathBuf>,
    /// Machine-readable output.
    #[arg(long)]
    pub json: bool,
}

impl LayersArgs {
    /// The flags' own ranges, so an error names the flag (not the shot's key it overrides).
    fn check(&self, shot: &throng::shot::Shot) -> Result<()> {
        if self.count == Some(0) {
            return Err(Error::Usage("--count 0: at least one crowd layer".into()));
        }
        if let Some(n) = self.count.filter(|&n| n > layers::MAX_LAYERS) {
            return Err(Error::Usage(format!("--count {n}: at most {} crowd layers", layers::MAX_LAYERS)));
        }
        if let Some(c) = &self.cutoffs {
            if c.len() >= layers::MAX_LAYERS {
                return Err(Error::Usage(format!(
                    "--cutoffs: {} distances, at most {}",
                    c.len(),
                    layers::MAX_LAYERS - 1
                )));
            }
            if c.iter().any(|v| !(*v > 0.0 && v.is_finite())) || c.windows(2).any(|w| !(w[0] < w[1])) {
                return Err(Error::Usage(format!(
                    "--cutoffs {c:?}: distances must be positive metres and increase, e.g. 10,25,60"
                )));
            }
        }
        if let Some(px) = self.lod_px {
            if !(px >= 0.0 && px.is_finite()) {
                return Err(Error::Usage(format!("--lod-px {px}: a projected height in pixels, >= 0")));
            }
        }
        if let Some(f) = self.ref_frame {
            if !shot.frames.contains(f) {
                return Err(Error::Usage(format!(
                    "--ref-frame {f} is not a frame of shot {} ({}-{})",
                    shot.name, shot.frames.start, shot.frames.end
                )));
            }
        }
        Ok(())
    }

    /// What these flags override of the shot's `[layers]` table.
    pub fn overrides(&self) -> LayerOverrides {
        LayerOverrides {
            count: self.count,
            cutoffs: self.cutoffs.clone(),
            budget: self.budget.clone(),
            ref_frame: self.ref_frame,
            per_frame: self.per_frame,
            lod_px: self.lod_px,
            lod_per_frame: self.lod_per_frame,
        }
    }
}

/// `throng layers SHOT ...`: writes the manifest (and map) and prints the split.
pub fn run(args: &LayersArgs) -> Result<()> {
    if let Some(out) = &args.out {
        super::existing_folder_of(out, "--out")?;
    }
    if let Some(map) = &args.map {
        super::existing_folder_of(map, "--map")?;
    }
    let crowd = super::load_crowd(&args.shot)?;
    args.check(crowd.shot())?;
    for w in layers::checks::check_placement(&crowd)?.warnings() {
        super::warn(&w)?;
    }
    let out = args.out.clone().unwrap_or_else(|| layers::default_manifest_path(&crowd.shot().path, &crowd.shot().name));
    throng::output::refuse_input_overwrite(
        std::iter::once(out.as_path()).chain(args.map.as_deref()),
        crowd.input_files(),
    )?;
    let manifest = build_layers(&crowd, &args.overrides())?;
    layers::write_manifest(&out, &manifest)?;
    if let Some(map) = &args.map {
        layers::draw_map(
            &manifest,
            &MapOptions { size: (1600, 900), set_bounds: set_bounds(&crowd), ..Default::default() },
            map,
        )?;
    }
    if args.json {
        outln!("{}", super::to_json(&manifest.summary_json())?);
    } else {
        out!("{}", layers::summary(&manifest));
        outln!("manifest  {}", out.display());
        if let Some(map) = &args.map {
            outln!("map       {}", map.display());
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    #[test]
    fn command_line_flags_override_the_shot() {
        use crate::cmd::{Cli, Verb};
        use clap::Parser;
        use throng::layers::settings_with_overrides;
        use throng::shot::{LayerSettings, SplitMode};
        let count = |n: usize| LayerSettings { split: SplitMode::Count, count: n, ..Default::default() };
        let parse = |args: &[&str]| match Cli::try_parse_from(args).unwrap().verb {
            Verb::Layers(a) => a,
            _ => unreachable!(),
        };
        let shot = count(3);
        let a =
            parse(&["throng", "layers", "shot.toml", "--cutoffs", "10,25,60", "--ref-frame", "1010", "--per-frame"]);
        let (s, o) = settings_with_overrides(&shot, &a.overrides()).unwrap();
        assert_eq!(
            (s.split, s.cutoffs.clone(), s.ref_frame, o.per_frame),
            (SplitMode::Cutoffs, vec![10.0, 25.0, 60.0], Some(1010), true)
        );
        let a = parse(&["throng", "layers", "shot.toml", "--budget", "2.8GB", "--lod-px", "25", "--lod-per-frame"]);
        let (s, o) = settings_with_overrides(&shot, &a.overrides()).unwrap();
        assert_eq!(
            (s.split, s.budget.as_deref(), s.lod_full_min_px, o.lod_per_frame),
            (SplitMode::Budget, Some("2.8GB"), 25.0, true)
        );
        // A bad budget is refused at parse time, naming the flag.
        let e = Cli::try_parse_from(["throng", "layers", "shot.toml", "--budget", "lots"]).unwrap_err().to_string();
        assert!(e.contains("--budget"), "{e}");
        assert!(Cli::try_parse_from(["throng", "layers", "s.toml", "--count", "2", "--budget", "1GB"]).is_err());
    }
}
