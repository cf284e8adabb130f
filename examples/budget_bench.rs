//! Does a layer budget hold? Splits a shot by `--budget`, renders every layer
//! of the split, each in its own `throng render --layer L` process as a farm
//! task does (the `throng` binary beside this example; `--in-process`: all
//! layers in this process, as `throng render --layer all`, where a layer's
//! peak also holds what earlier layers left resident), and prints, per
//! layer, the manifest's estimate against the measured peak.
//!
//! ```text
//! cargo build --release --bin throng
//! cargo run --release --example budget_bench -- SHOT.toml BUDGET [--proxy-casters]
//!     [--resolution WxH] [--spp N] [--frame F] [--out DIR] [--in-process]
//! ```
//! Prints one line per layer and a last line `holds: true|false` (every
//! measured peak under the budget). Exits 1 when the budget does not hold.

use std::path::PathBuf;

use throng::casting::ShotCrowd;
use throng::layers::{build_layers, LayerOverrides};
use throng::render::job::{all_layers, run, RenderJob, Silent};

fn main() {
    match bench() {
        Ok(true) => {}
        Ok(false) => std::process::exit(1),
        Err(e) => {
            eprintln!("budget_bench: {e}");
            std::process::exit(2);
        }
    }
}

/// Removes the benchmark's shot copy however the benchmark ends.
struct RemoveOnDrop(PathBuf);

impl Drop for RemoveOnDrop {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

/// Whether the budget held.
fn bench() -> Result<bool, String> {
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
    // The shot as benchmarked (resolution, proxy casters) is a copy beside
    // the original, so relative paths still resolve and `throng render`
    // finds the manifest current.
    let text = std::fs::read_to_string(shot.as_str()).map_err(|e| format!("{shot}: {e}"))?;
    let mut doc: toml::Table = text.parse().map_err(|e| format!("{shot}: {e}"))?;
    if let Some(r) = flag("--resolution") {
        let (w, h) = r.split_once('x').ok_or("--resolution WxH")?;
        let (w, h): (i64, i64) = (w.parse().map_err(|_| "--resolution")?, h.parse().map_err(|_| "--resolution")?);
        let render = doc.entry("render").or_insert(toml::Value::Table(Default::default()));
        if let Some(t) = render.as_table_mut() {
            t.insert("resolution".into(), toml::Value::Array(vec![w.into(), h.into()]));
        }
    }
    if args.iter().any(|a| a == "--proxy-casters") {
        let layers = doc.entry("layers").or_insert(toml::Value::Table(Default::default()));
        if let Some(t) = layers.as_table_mut() {
            t.insert("proxy_shadow_casters".into(), true.into());
        }
    }
    let copy = std::path::Path::new(shot.as_str()).with_file_name(".budget_bench.shot.toml");
    std::fs::write(&copy, toml::to_string(&doc).map_err(|e| e.to_string())?).map_err(|e| e.to_string())?;
    let _remove = RemoveOnDrop(copy.clone());
    let shot = copy.to_string_lossy().into_owned();
    let crowd = ShotCrowd::load(&copy).map_err(|e| e.to_string())?;
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
    let job = RenderJob::new(all_layers(&manifest), vec![frame], spp, out.clone());
    for layer in &job.layers {
        std::fs::create_dir_all(out.join(layer)).map_err(|e| e.to_string())?;
    }
    let done = if args.iter().any(|a| a == "--in-process") {
        run(&crowd, Some(&manifest), &job, &Silent).map_err(|e| e.to_string())?.layers
    } else {
        separate(&manifest, &job, &shot)?
    };
    let [w, h] = crowd.shot().render.resolution;
    println!(
        "shot {} ({} agents, {w}x{h}, frame {frame}, {spp} spp), budget {}, proxy casters {}: {} layers",
        crowd.shot().name,
        crowd.casting().len(),
        throng::layers::format_bytes(budget_bytes),
        crowd.shot().layers.proxy_shadow_casters,
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
    Ok(holds)
}

/// Renders each layer of the job in its own `throng render` process and
/// returns what each measured (its process's peak resident memory).
fn separate(
    manifest: &throng::layers::Manifest,
    job: &RenderJob,
    shot: &str,
) -> Result<Vec<throng::render::job::RenderedLayer>, String> {
    let exe = std::env::current_exe().map_err(|e| e.to_string())?;
    let throng_bin = exe.parent().and_then(|d| d.parent()).map(|d| d.join("throng")).ok_or("no binary folder")?;
    if !throng_bin.exists() {
        return Err(format!("{} not found: cargo build --release --bin throng", throng_bin.display()));
    }
    let manifest_path = job.out.join("budget_bench.layers.json");
    throng::layers::write_manifest(&manifest_path, manifest).map_err(|e| e.to_string())?;
    let mut done = Vec::new();
    for layer in &job.layers {
        let output = std::process::Command::new(&throng_bin)
            .args(["render", shot, "--manifest"])
            .arg(&manifest_path)
            .args(["--layer", layer, "--frames", &job.frames[0].to_string(), "--spp", &job.spp.to_string()])
            .args(["--progress", "off", "--json", "--out"])
            .arg(&job.out)
            .output()
            .map_err(|e| e.to_string())?;
        if !output.status.success() {
            return Err(format!("throng render --layer {layer}: {}", String::from_utf8_lossy(&output.stderr)));
        }
        let v: serde_json::Value = serde_json::from_slice(&output.stdout).map_err(|e| e.to_string())?;
        done.push(throng::render::job::RenderedLayer {
            layer: layer.clone(),
            frame: job.frames[0],
            path: job.out.clone(),
            skipped: false,
            seconds: v["seconds"].as_f64().unwrap_or(0.0),
            instances: v["instances"].as_u64().unwrap_or(0) as usize,
            peak_rss_bytes: v["peak_rss_bytes"].as_u64(),
            tlas_build_s: 0.0,
        });
    }
    Ok(done)
}
