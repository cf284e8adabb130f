//! Does a layer budget hold? Splits a shot by `--budget`, renders every layer
//! of the split (as `throng render --layer all` does) and prints, per layer,
//! the manifest's estimate against the peak memory measured while that layer
//! rendered.
//!
//! ```text
//! cargo run --release --example budget_bench -- SHOT.toml BUDGET [--proxy-casters]
//!     [--resolution WxH] [--spp N] [--frame F] [--out DIR]
//! ```
//! Prints one line per layer and a last line `holds: true|false` (every
//! measured peak under the budget). Exits 1 when the budget does not hold.

use std::path::PathBuf;

use throng::casting::ShotCrowd;
use throng::layers::{build_layers, LayerOverrides};
use throng::render::job::{all_layers, run, ProgressStyle, RenderJob};

fn main() {
    if let Err(e) = bench() {
        eprintln!("budget_bench: {e}");
        std::process::exit(2);
    }
}

fn bench() -> Result<(), String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let flag = |name: &str| args.iter().position(|a| a == name).and_then(|i| args.get(i + 1)).cloned();
    let takes_value = ["--resolution", "--spp", "--frame", "--out"];
    let positional: Vec<&String> = args
        .iter()
        .enumerate()
        .filter(|(i, a)| !a.starts_with("--") && (*i == 0 || !takes_value.contains(&args[i - 1].as_str())))
        .map(|(_, a)| a)
        .collect();
    let (Some(shot), Some(budget)) = (positional.first(), positional.get(1)) else {
        return Err("usage: budget_bench SHOT.toml BUDGET [--proxy-casters] [--resolution WxH] [--spp N] [--frame F] [--out DIR]".into());
    };
    let mut crowd = ShotCrowd::load(std::path::Path::new(shot.as_str())).map_err(|e| e.to_string())?;
    if args.iter().any(|a| a == "--proxy-casters") {
        crowd.shot.layers.proxy_shadow_casters = true;
    }
    if let Some(r) = flag("--resolution") {
        let (w, h) = r.split_once('x').ok_or("--resolution WxH")?;
        crowd.shot.render.resolution = [w.parse().map_err(|_| "--resolution")?, h.parse().map_err(|_| "--resolution")?];
    }
    let overrides = LayerOverrides { budget: Some(budget.to_string()), ..Default::default() };
    let manifest = build_layers(&crowd, &overrides).map_err(|e| e.to_string())?;
    let frame = match flag("--frame") {
        Some(f) => f.parse().map_err(|_| "--frame")?,
        None => manifest.ref_frame,
    };
    let spp = flag("--spp").map_or(Ok(1), |s| s.parse().map_err(|_| "--spp"))?;
    let out = PathBuf::from(flag("--out").unwrap_or_else(|| "/tmp/budget_bench".into()));
    std::fs::create_dir_all(&out).map_err(|e| e.to_string())?;
    let budget_bytes = manifest.split.budget_bytes.unwrap_or(u64::MAX);
    let job = RenderJob {
        progress: ProgressStyle::Off,
        ..RenderJob::new(all_layers(&manifest), vec![frame], spp, out.clone())
    };
    for layer in &job.layers {
        std::fs::create_dir_all(out.join(layer)).map_err(|e| e.to_string())?;
    }
    let done = run(&crowd, Some(&manifest), &job).map_err(|e| e.to_string())?;
    let [w, h] = crowd.shot.render.resolution;
    println!(
        "shot {} ({} agents, {w}x{h}, frame {frame}, {spp} spp), budget {}, proxy casters {}: {} layers",
        crowd.shot.name,
        crowd.casting.len(),
        throng::layers::format_bytes(budget_bytes),
        crowd.shot.layers.proxy_shadow_casters,
        manifest.layers.len()
    );
    println!(
        "{:<10} {:>8} {:>14} {:>14} {:>7}  under budget",
        "layer", "agents", "estimate MiB", "measured MiB", "ratio"
    );
    let mut holds = true;
    for d in &done {
        // The set layer carries the shared part: the floor and every agent as a caster.
        let estimate = match manifest.layers.iter().find(|l| l.name == d.layer) {
            Some(l) => Some(l.memory_bytes),
            None => Some(manifest.split.shared_bytes),
        };
        let measured = d.peak_rss_bytes;
        let agents = manifest.layers.iter().find(|l| l.name == d.layer).map_or(0, |l| l.agents);
        let under = measured.is_some_and(|m| m <= budget_bytes);
        holds &= under;
        let mib = |b: Option<u64>| b.map_or("-".to_string(), |b| format!("{:.1}", b as f64 / 1048576.0));
        let ratio = match (estimate, measured) {
            (Some(e), Some(m)) if m > 0 => format!("{:.2}", e as f64 / m as f64),
            _ => "-".into(),
        };
        println!("{:<10} {:>8} {:>14} {:>14} {:>7}  {under}", d.layer, agents, mib(estimate), mib(measured), ratio);
    }
    println!("holds: {holds}");
    if !holds {
        std::process::exit(1);
    }
    Ok(())
}
