//! Does the memory model hold? Renders every layer of a shot, each in its
//! own `throng render --layer L` process as a farm task does (the `throng`
//! binary beside this example; `--in-process`: all layers in this process,
//! as `throng render --layer all`, where a layer's peak also holds what
//! earlier layers left resident), and prints, per layer, the model's
//! estimate (`layers::memory`, the manifest's and the farm plan's figure)
//! against the process's measured peak RSS, and their ratio.
//!
//! ```text
//! cargo build --bin throng --example budget_bench
//! target/debug/examples/budget_bench SHOT.toml [BUDGET] [--shutter OPEN,CLOSE] [--proxy-casters]
//!     [--resolution WxH] [--spp N] [--frame F] [--out DIR] [--in-process]
//! ```
//! Without BUDGET the shot is rendered unsplit (one crowd layer and the
//! set), then split again with a budget of 1.5x the crowd layer's measured
//! peak: the line `unsplit at 1.5x measured: N layer(s)` says whether that
//! budget keeps it in one layer. With BUDGET the shot is split by it and
//! every measured peak is checked against it. `--shutter` renders (and
//! estimates) with motion blur. The last line is `holds: true|false`: every
//! estimate at or above its measurement, and every measurement under the
//! budget (or the one-layer check). Exits 1 when it does not hold.

use std::path::PathBuf;

use throng::casting::ShotCrowd;
use throng::layers::{build_layers, format_bytes, render_shutter, LayerOverrides, Manifest, RenderFloor};
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

fn mib(b: u64) -> String {
    format!("{:.1}", b as f64 / 1048576.0)
}

/// Whether the model held.
fn bench() -> Result<bool, String> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let flag = |name: &str| args.iter().position(|a| a == name).and_then(|i| args.get(i + 1)).cloned();
    let takes_value = ["--resolution", "--spp", "--frame", "--out", "--shutter"];
    let positional: Vec<&String> = args
        .iter()
        .enumerate()
        .filter(|(i, a)| !a.starts_with("--") && (*i == 0 || !takes_value.contains(&args[i - 1].as_str())))
        .map(|(_, a)| a)
        .collect();
    let Some(shot) = positional.first() else {
        return Err("usage: budget_bench SHOT.toml [BUDGET] [--shutter O,C] [--proxy-casters] [--resolution WxH] [--spp N] [--frame F] [--out DIR] [--in-process]".into());
    };
    let budget = positional.get(1).map(|b| b.to_string());
    // The shot as benchmarked (resolution, shutter, proxy casters) is a copy
    // beside the original, so relative paths still resolve and `throng
    // render` finds the manifest current; its renders blur as its
    // `render.shutter` says, as a farm task's do.
    let text = std::fs::read_to_string(shot.as_str()).map_err(|e| format!("{shot}: {e}"))?;
    let mut doc: toml::Table = text.parse().map_err(|e| format!("{shot}: {e}"))?;
    let table = |doc: &mut toml::Table, name: &str| -> Result<toml::Table, String> {
        Ok(doc.remove(name).unwrap_or(toml::Value::Table(Default::default())).as_table().cloned().unwrap_or_default())
    };
    let mut render = table(&mut doc, "render")?;
    if let Some(r) = flag("--resolution") {
        let (w, h) = r.split_once('x').ok_or("--resolution WxH")?;
        let (w, h): (i64, i64) = (w.parse().map_err(|_| "--resolution")?, h.parse().map_err(|_| "--resolution")?);
        render.insert("resolution".into(), toml::Value::Array(vec![w.into(), h.into()]));
    }
    if let Some(s) = flag("--shutter") {
        let (o, c) = s.split_once(',').ok_or("--shutter OPEN,CLOSE")?;
        let (o, c): (f64, f64) = (o.parse().map_err(|_| "--shutter")?, c.parse().map_err(|_| "--shutter")?);
        render.insert("shutter".into(), toml::Value::Array(vec![o.into(), c.into()]));
    }
    doc.insert("render".into(), render.into());
    if args.iter().any(|a| a == "--proxy-casters") {
        let mut layers = table(&mut doc, "layers")?;
        layers.insert("proxy_shadow_casters".into(), true.into());
        doc.insert("layers".into(), layers.into());
    }
    let copy = std::path::Path::new(shot.as_str()).with_file_name(".budget_bench.shot.toml");
    std::fs::write(&copy, toml::to_string(&doc).map_err(|e| e.to_string())?).map_err(|e| e.to_string())?;
    let _remove = RemoveOnDrop(copy.clone());
    let shot = copy.to_string_lossy().into_owned();
    let crowd = ShotCrowd::load(&copy).map_err(|e| e.to_string())?;
    let overrides = match &budget {
        Some(b) => LayerOverrides { budget: Some(b.clone()), ..Default::default() },
        None => LayerOverrides { count: Some(1), ..Default::default() },
    };
    let manifest = build_layers(&crowd, &overrides).map_err(|e| e.to_string())?;
    let frame = match flag("--frame") {
        Some(f) => f.parse().map_err(|_| "--frame")?,
        None => manifest.ref_frame,
    };
    let spp = flag("--spp").map_or(Ok(1), |s| s.parse().map_err(|_| "--spp"))?;
    let out = PathBuf::from(flag("--out").unwrap_or_else(|| "/tmp/budget_bench".into()));
    std::fs::create_dir_all(&out).map_err(|e| e.to_string())?;
    let shutter = render_shutter(&crowd);
    let mut job = RenderJob::new(all_layers(&manifest), vec![frame], spp, out.clone());
    job.shutter = shutter;
    for layer in &job.layers {
        std::fs::create_dir_all(out.join(layer)).map_err(|e| e.to_string())?;
    }
    let done = if args.iter().any(|a| a == "--in-process") {
        let crowd = if shutter.is_some() {
            ShotCrowd::open(crowd.shot().clone(), shutter).map_err(|e| e.to_string())?
        } else {
            crowd
        };
        run(&crowd, Some(&manifest), &job, &Silent).map_err(|e| e.to_string())?.layers
    } else {
        separate(&manifest, &job, &shot)?
    };
    let crowd = ShotCrowd::load(&copy).map_err(|e| e.to_string())?;
    let [w, h] = crowd.shot().render.resolution;
    let full = |id: u32, f: i32| manifest.agent(id).is_some_and(|a| a.lod_at(f) == throng::layers::Lod::Full);
    let floor = RenderFloor::of(&crowd, shutter, w as u64 * h as u64, full).map_err(|e| e.to_string())?;
    println!(
        "shot {} ({} agents, {w}x{h}, frame {frame}, {spp} spp, shutter {}), {}, proxy casters {}: {} layers",
        crowd.shot().name,
        crowd.casting().len(),
        shutter.map_or("off".to_string(), |[o, c]| format!("{o},{c}")),
        budget.as_ref().map_or("unsplit".to_string(), |b| format!("budget {b}")),
        crowd.shot().layers.proxy_shadow_casters,
        manifest.layers.len()
    );
    println!(
        "floor {} MiB: {} parts, meshes {} MiB, textures {} MiB, {} BLAS + {} deforming triangles, {} set instances",
        mib(floor.bytes()),
        floor.agent_parts,
        mib(floor.mesh_bytes),
        mib(floor.texture_bytes),
        floor.triangles,
        floor.deform_triangles,
        floor.set_instances
    );
    println!(
        "{:<10} {:>8} {:>10} {:>14} {:>14} {:>7}",
        "layer", "agents", "instances", "estimate MiB", "measured MiB", "ratio"
    );
    let mut holds = true;
    let mut crowd0_peak = None;
    for d in &done {
        let estimate = manifest.render_memory(&d.layer).unwrap_or(0);
        let agents = manifest.layer(&d.layer).map_or(0, |l| l.agents);
        let Some(measured) = d.peak_rss_bytes else {
            println!("{:<10} {agents:>8} {:>10} {:>14} {:>14} {:>7}", d.layer, d.instances, mib(estimate), "-", "-");
            holds = false;
            continue;
        };
        if d.layer == "crowd0" {
            crowd0_peak = Some(measured);
        }
        let ratio = estimate as f64 / measured as f64;
        holds &= ratio >= 1.0;
        if let Some(b) = manifest.split.budget_bytes {
            holds &= measured <= b;
        }
        println!(
            "{:<10} {agents:>8} {:>10} {:>14} {:>14} {ratio:>7.2}",
            d.layer,
            d.instances,
            mib(estimate),
            mib(measured)
        );
    }
    if budget.is_none() {
        // A budget of 1.5x the crowd's measured unsplit peak keeps it in one layer.
        if let Some(peak) = crowd0_peak {
            let b = peak + peak / 2;
            let split = build_layers(&crowd, &LayerOverrides { budget: Some(b.to_string()), ..Default::default() });
            let layers = match &split {
                Ok(m) => m.layers.len().to_string(),
                Err(e) => format!("refused ({e})"),
            };
            println!("unsplit at 1.5x measured ({}): {layers} layer(s)", format_bytes(b));
            holds &= split.as_ref().is_ok_and(|m: &Manifest| m.layers.len() == 1);
        }
    }
    println!("holds: {holds}");
    Ok(holds)
}

/// Renders each layer of the job in its own `throng render` process and
/// returns what each measured (its process's peak resident memory).
fn separate(
    manifest: &Manifest,
    job: &RenderJob,
    shot: &str,
) -> Result<Vec<throng::render::job::RenderedLayer>, String> {
    let exe = std::env::current_exe().map_err(|e| e.to_string())?;
    let throng_bin = exe.parent().and_then(|d| d.parent()).map(|d| d.join("throng")).ok_or("no binary folder")?;
    if !throng_bin.exists() {
        return Err(format!("{} not found: cargo build --bin throng", throng_bin.display()));
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
            pass_bytes: Vec::new(),
            file_bytes: 0,
            denoise_s: 0.0,
            deep: None,
        });
    }
    Ok(done)
}
