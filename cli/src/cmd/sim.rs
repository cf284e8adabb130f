//! `throng sim`: the reference steering simulation.

use std::path::PathBuf;
use std::time::Instant;

use clap::Args;

use throng::error::Result;
use throng::sim::SimScene;

/// `throng sim`.
#[derive(Debug, Args)]
pub struct SimArgs {
    /// Simulation scene (TOML).
    pub scene: PathBuf,
    /// Cache to write (.crowd or .csv).
    #[arg(long)]
    pub out: PathBuf,
    /// Print a machine-readable summary instead of the line.
    #[arg(long)]
    pub json: bool,
}

/// Simulates the scene and writes its cache.
pub fn run(args: &SimArgs) -> Result<()> {
    let clock = Instant::now();
    super::existing_folder_of(&args.out, "--out")?;
    throng::output::refuse_input_overwrite([args.out.as_path()], [("sim scene".to_string(), args.scene.clone())])?;
    let scene = SimScene::load(&args.scene)?;
    // The rig files the scene reads, too.
    let rigs = scene.rigs.iter().zip(&scene.rig_files);
    let rig_files = rigs.filter_map(|(name, f)| Some((format!("rigs.{name}"), f.clone()?)));
    throng::output::refuse_input_overwrite([args.out.as_path()], rig_files)?;
    let crowd = throng::sim::run(&scene);
    throng::cache::write(&args.out, &crowd)?;
    if args.json {
        return super::Summary::new("sim", clock, scene.agents.len() as u64, vec![args.out.clone()]).print();
    }
    outln!(
        "throng sim: {} agents, frames {}-{} (simulated from {}), {:.2} s -> {}",
        scene.agents.len(),
        scene.start,
        scene.end,
        scene.first_frame(),
        clock.elapsed().as_secs_f64(),
        args.out.display()
    );
    Ok(())
}
