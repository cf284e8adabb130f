//! `farm plan`: the task graph of a shot. The layer manifest is computed
//! here, once, and every render task reads it; render tasks are (layer,
//! frame chunk) pairs; each frame's comp depends on the render tasks that
//! write that frame's layers.

use std::path::{Path, PathBuf};

use super::{fingerprint, Plan, Task, TaskKind, PLAN_FILE, PLAN_FORMAT, PLAN_VERSION};
use crate::casting::ShotCrowd;
use crate::error::{Error, IoContext, Result};
use crate::layers::{build_layers, memory, render_shutter, LayerOverrides, Manifest};
use crate::output::{layer_path, COMP_LAYER};
use crate::render::job::deep_layer_path;
use crate::shot::Denoise;

/// What to plan; `Default`-like values come from [`PlanOptions::new`].
#[derive(Debug, Clone)]
pub struct PlanOptions {
    /// The shot file.
    pub shot: PathBuf,
    /// Shot frames (default: every frame of the shot).
    pub frames: Option<Vec<i32>>,
    /// Layers (default: every layer of the manifest, back to front).
    pub layers: Option<Vec<String>>,
    /// Frames per render task.
    pub chunk: usize,
    /// The plan's directory.
    pub out: PathBuf,
    /// Samples per pixel (default: the shot's).
    pub spp: Option<u32>,
    /// Image size (default: the shot's).
    pub resolution: Option<[u32; 2]>,
    /// Cores per render task.
    pub cores: u32,
    /// Extra attempts of a failed task.
    pub retries: u32,
    /// Denoising of every render task: `None` follows the shot's
    /// `render.denoise`; `Some(None)` turns it off, `Some(Some(q))` sets it.
    pub denoise: Option<Option<Denoise>>,
    /// Deep output in every render task and comp (docs/render.md, "Deep
    /// output"); a shot with a `render.deep` table has it whatever this says.
    pub deep: bool,
}

impl PlanOptions {
    /// Every frame and layer of `shot` into `out`: 1 frame per task, 1 core, 1 retry.
    pub fn new(shot: PathBuf, out: PathBuf) -> PlanOptions {
        PlanOptions {
            shot,
            frames: None,
            layers: None,
            chunk: 1,
            out,
            spp: None,
            resolution: None,
            cores: 1,
            retries: 1,
            denoise: None,
            deep: false,
        }
    }
}

/// Most tasks one plan may hold; bounds the plan before it is built.
pub(crate) const MAX_TASKS: usize = 1_000_000;
/// Most cores a task may ask for.
pub(crate) const MAX_CORES: u32 = 4096;

/// Open Image Denoise's peak while it filters a layer-frame: its weights
/// and scratch, and per pixel its images and the network's tensors
/// (docs/benchmarks.md, "Denoising": peak RSS at two image sizes).
const DENOISE_BYTES: u64 = 96 << 20;
const DENOISE_BYTES_PER_PIXEL: u64 = 1024;

/// Bytes per pixel per layer held by a comp (every layer's film at once).
const COMP_BYTES_PER_PIXEL: u64 = 256;
/// Bytes per pixel per layer per three-channel pass a comp stacks (read as
/// f32, stacked, encoded).
const COMP_BYTES_PER_PASS_PIXEL: u64 = 24;

/// Builds the plan and writes it, with its manifest, into `opts.out`.
/// Refuses a directory that already holds a plan of other inputs, whose
/// outputs would otherwise be taken as done.
pub fn write_new_plan(opts: &PlanOptions) -> Result<(PathBuf, Plan)> {
    std::fs::create_dir_all(&opts.out).at(&opts.out)?;
    let out = std::fs::canonicalize(&opts.out).at(&opts.out)?;
    let plan_path = out.join(PLAN_FILE);
    let crowd = ShotCrowd::load(&opts.shot)?;
    let manifest = build_layers(&crowd, &LayerOverrides::default())?;
    let manifest_path = out.join(format!("{}.layers.json", crowd.shot().name));
    crate::output::refuse_input_overwrite([plan_path.as_path(), manifest_path.as_path()], crowd.input_files())?;
    let plan = build_plan(&crowd, &manifest, &manifest_path, &out, opts, &|inputs| {
        // The manifest is fingerprinted as written, so write it first; a
        // directory of another plan must not be overwritten, so check first.
        if plan_path.exists() {
            if let Ok(old) = super::read_plan(&plan_path) {
                if old.shot != crowd.shot().name {
                    return Err(Error::invalid(
                        &plan_path,
                        format!(
                            "{} holds the plan of shot `{}`, not `{}`: plan into another folder",
                            out.display(),
                            old.shot,
                            crowd.shot().name
                        ),
                    )
                    .field("shot"));
                }
                let now = fingerprint(&inputs[..inputs.len() - 1])?;
                let old_inputs = &old.fingerprint.inputs[..old.fingerprint.inputs.len().saturating_sub(1)];
                if now.inputs != old_inputs {
                    return Err(Error::invalid(
                        &plan_path,
                        format!(
                            "{} holds a plan of shot `{}` made from other inputs; its rendered frames would count as done: plan the edited shot into another folder (or remove it)",
                            out.display(),
                            old.shot
                        ),
                    )
                    .field("fingerprint"));
                }
            }
        }
        crate::layers::write_manifest(&manifest_path, &manifest)?;
        fingerprint(inputs)
    })?;
    // The plan owns its tree: the comps' folder is made here, since a verb
    // writing one file (`comp --out`) needs its folder to exist.
    for dir in
        plan.tasks.iter().filter(|t| t.kind == TaskKind::Comp).flat_map(|t| &t.outputs).filter_map(|o| o.parent())
    {
        std::fs::create_dir_all(dir).at(dir)?;
    }
    super::write_plan(&plan_path, &plan)?;
    Ok((plan_path, plan))
}

/// The shot's input files, in a fixed order, with the manifest last.
fn inputs(crowd: &ShotCrowd, manifest_path: &Path) -> Result<Vec<(String, PathBuf)>> {
    let shot = crowd.shot();
    let abs = |p: &Path| std::fs::canonicalize(p).at(p);
    let mut v = vec![("shot".to_string(), abs(&shot.path)?), ("cache".to_string(), abs(&shot.cache.path)?)];
    for rig in shot.rigs.values() {
        v.push(("rig".into(), abs(&rig.file)?));
    }
    for w in &shot.wardrobes {
        v.push(("wardrobe".into(), abs(w)?));
    }
    if let Some(set) = &shot.set {
        v.push(("set".into(), abs(&set.file)?));
    }
    v.push(("manifest".into(), manifest_path.to_path_buf()));
    Ok(v)
}

/// Estimated peak memory of a render task of `layer`: the manifest's
/// estimate from the one model ([`crate::layers::memory`], which holds the
/// process and the film already), its film moved to the task's image size.
pub(crate) fn render_memory(
    manifest: &Manifest,
    layer: &str,
    [w, h]: [u32; 2],
    channels: memory::FilmChannels,
) -> Result<u64> {
    let bytes =
        manifest.render_memory(layer).ok_or_else(|| Error::Usage(format!("no layer `{layer}` in the manifest")))?;
    let [mw, mh] = manifest.camera.image_size;
    Ok(round_mib(memory::at_pixels(bytes, mw as u64 * mh as u64, w as u64 * h as u64, channels)))
}

/// Rounds up to whole MiB (schedulers ask in MB).
fn round_mib(b: u64) -> u64 {
    b.div_ceil(1 << 20) << 20
}

fn s(p: &Path) -> String {
    p.display().to_string()
}

/// Writes the manifest and fingerprints the (role, file) inputs it is given.
pub(crate) type FingerprintInputs<'a> = dyn Fn(&[(String, PathBuf)]) -> Result<super::Fingerprint> + 'a;

/// Builds the plan of `crowd` with its `manifest` (to be at
/// `manifest_path`) in `out`; `fingerprint_inputs` writes the manifest and
/// fingerprints the inputs it is given.
pub(crate) fn build_plan(
    crowd: &ShotCrowd,
    manifest: &Manifest,
    manifest_path: &Path,
    out: &Path,
    opts: &PlanOptions,
    fingerprint_inputs: &FingerprintInputs<'_>,
) -> Result<Plan> {
    let shot = crowd.shot();
    if opts.chunk == 0 {
        return Err(Error::setting("chunk", "must be at least 1 frame"));
    }
    if opts.cores == 0 || opts.cores > MAX_CORES {
        return Err(Error::setting("cores", format!("must be 1 to {MAX_CORES}")));
    }
    let frames = match &opts.frames {
        Some(f) => f.clone(),
        None => shot.frames.iter().collect(),
    };
    if frames.is_empty() {
        return Err(Error::Usage("no frames to plan".into()));
    }
    if let Some(f) = frames.iter().find(|&&f| !shot.frames.contains(f)) {
        return Err(Error::Usage(format!(
            "frame {f} is outside shot {} ({}-{})",
            shot.name, shot.frames.start, shot.frames.end
        )));
    }
    let mut seen = std::collections::BTreeSet::new();
    if let Some(f) = frames.iter().find(|&&f| !seen.insert(f)) {
        return Err(Error::Usage(format!("frame {f} is listed twice")));
    }
    let all = manifest.comp_order.clone();
    let layers = match &opts.layers {
        None => all.clone(),
        Some(asked) => {
            if let Some(l) = asked.iter().find(|l| !all.contains(l)) {
                return Err(Error::Usage(format!("no layer `{l}` in the manifest (layers: {})", all.join(", "))));
            }
            // Back to front, whatever order they were asked in.
            all.iter().filter(|l| asked.contains(l)).cloned().collect()
        }
    };
    let chunks = frames.len().div_ceil(opts.chunk);
    let comps = if layers == all { frames.len() } else { 0 };
    let total = chunks.saturating_mul(layers.len()).saturating_add(comps);
    if total > MAX_TASKS {
        return Err(Error::setting(
            "chunk",
            format!("{total} tasks is more than a plan holds ({MAX_TASKS}): raise it"),
        ));
    }
    let spp = opts.spp.unwrap_or(shot.render.spp).max(1);
    let resolution = opts.resolution.unwrap_or(shot.render.resolution);
    // Every task says how it denoises, so the plan reads the same whatever
    // the shot's key; the OIDN filter's memory comes on top of the render's.
    let denoise = opts.denoise.unwrap_or(shot.render.denoise);
    let denoise_args: Vec<&str> = match denoise {
        Some(q) => vec!["--denoise", q.name()],
        None if shot.render.denoise.is_some() => vec!["--denoise", "off"],
        None => Vec::new(),
    };
    let denoise_bytes = match denoise {
        Some(_) => DENOISE_BYTES + DENOISE_BYTES_PER_PIXEL * resolution[0] as u64 * resolution[1] as u64,
        None => 0,
    };
    // Tasks pass no --shutter: they blur as the shot says, as the manifest's estimate assumed.
    let blurred = render_shutter(crowd).is_some();
    // The manifest's estimates hold a deep image when the shot asks for one.
    let channels =
        memory::FilmChannels { blurred, passes: memory::pass_count(crowd)?, deep: shot.render.deep.is_some() };
    let deep = opts.deep || channels.deep;
    let pixels = resolution[0] as u64 * resolution[1] as u64;
    let deep_only_here = if deep && !channels.deep { pixels * memory::DEEP_PIXEL_BYTES } else { 0 };
    let deep_flag: &[&str] = if deep { &["--deep"] } else { &[] };
    let shot_file = std::fs::canonicalize(&shot.path).at(&shot.path)?;
    let render_dir = out.join("render");
    let log_dir = out.join("logs");
    let mut tasks = Vec::with_capacity(total);
    // Which render task writes (layer, frame): the comps' dependencies.
    let mut writer: std::collections::BTreeMap<(&str, i32), String> = std::collections::BTreeMap::new();
    for layer in &layers {
        for (chunk, frames) in frames.chunks(opts.chunk).enumerate() {
            let id = format!("render.{layer}.{chunk}");
            let list = frames.iter().map(|f| f.to_string()).collect::<Vec<_>>().join(",");
            let spp_text = spp.to_string();
            // A fixed sample count, unless the shot samples adaptively and
            // the plan was given none (a task's --spp turns adaptive off).
            let fixed: &[&str] =
                if opts.spp.is_some() || shot.render.adaptive.is_none() { &["--spp", &spp_text] } else { &[] };
            let size = format!("{}x{}", resolution[0], resolution[1]);
            let cores = opts.cores.to_string();
            let (shot_arg, manifest_arg, out_arg) = (s(&shot_file), s(manifest_path), s(&render_dir));
            let head =
                ["throng", "render", &shot_arg, "--manifest", &manifest_arg, "--layer", layer, "--frames", &list];
            let tail =
                ["--resolution", &size, "--threads", &cores, "--resume", "--progress", "plain", "--out", &out_arg];
            let argv: Vec<String> = head
                .iter()
                .chain(fixed)
                .chain(deep_flag)
                .chain(&denoise_args)
                .chain(&tail)
                .map(|a| a.to_string())
                .collect();
            for &f in frames {
                writer.insert((layer.as_str(), f), id.clone());
            }
            tasks.push(Task {
                log: log_dir.join(format!("{id}.log")),
                id,
                kind: TaskKind::Render,
                layer: Some(layer.clone()),
                chunk: Some(chunk),
                frames: frames.to_vec(),
                argv,
                outputs: frames
                    .iter()
                    .map(|&f| layer_path(&render_dir, &shot.name, layer, f))
                    .flat_map(|p| [Some(deep_layer_path(&p)).filter(|_| deep), Some(p)].into_iter().flatten())
                    .collect(),
                cores: opts.cores,
                memory_bytes: round_mib(render_memory(manifest, layer, resolution, channels)? + deep_only_here)
                    + round_mib(denoise_bytes),
                depends_on: Vec::new(),
            });
        }
    }
    if comps > 0 {
        for &f in &frames {
            let id = format!("comp.{f}");
            let out_path = layer_path(&render_dir, &shot.name, COMP_LAYER, f);
            let mut argv = [
                "throng",
                "comp",
                &s(&render_dir),
                "--frame",
                &f.to_string(),
                "--manifest",
                &s(manifest_path),
                "--out",
                &s(&out_path),
            ]
            .map(String::from)
            .to_vec();
            argv.extend(deep_flag.iter().map(|a| a.to_string()));
            let mut deps: Vec<String> = layers.iter().filter_map(|l| writer.get(&(l.as_str(), f)).cloned()).collect();
            deps.dedup();
            tasks.push(Task {
                log: log_dir.join(format!("{id}.log")),
                id,
                kind: TaskKind::Comp,
                layer: None,
                chunk: None,
                frames: vec![f],
                argv,
                outputs: [Some(deep_layer_path(&out_path)).filter(|_| deep), Some(out_path)]
                    .into_iter()
                    .flatten()
                    .collect(),
                cores: 1,
                // Deep: every layer's deep image and the merge, a render's deep image each.
                memory_bytes: round_mib(
                    pixels
                        * (COMP_BYTES_PER_PIXEL
                            + channels.passes * COMP_BYTES_PER_PASS_PIXEL
                            + if deep { memory::DEEP_PIXEL_BYTES } else { 0 })
                        * (layers.len() as u64 + 1)
                        + memory::PROCESS_BYTES,
                ),
                depends_on: deps,
            });
        }
    }
    let fingerprint = fingerprint_inputs(&inputs(crowd, manifest_path)?)?;
    Ok(Plan {
        format: PLAN_FORMAT.into(),
        version: PLAN_VERSION,
        shot: shot.name.clone(),
        shot_file,
        fingerprint,
        manifest: manifest_path.to_path_buf(),
        out: out.to_path_buf(),
        render_dir,
        log_dir,
        frames,
        layers,
        chunk: opts.chunk,
        spp,
        resolution,
        retries: opts.retries,
        tasks,
    })
}
