//! A render job: the frames and layers of a shot, each traced from the cast
//! crowd and the layer manifest into `OUT/<layer>/<shot>.<layer>.<frame:04>.exr`.
//!
//! The manifest decides every instance's visibility; this module never
//! re-ranks. BLASes are built once per run and shared by every frame and
//! layer; only the TLAS is rebuilt per (frame, layer).

use std::borrow::Cow;
use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::cache::AgentSample;
use crate::casting::motion::MotionFrame;
use crate::casting::{AgentPose, Lod, ShotCrowd};
use crate::error::{Error, Result};
use crate::fingerprint::Fingerprinter;
use crate::layers::Manifest;
use crate::output::{layer_path, WriterLock, FULL_LAYER};
use crate::render::colour::{self, Colourspace};
use crate::render::cryptomatte::{CryptoNames, NameTables};
use crate::render::deep::{DeepImage, DeepSettings};
use crate::render::denoise::Denoiser;
use crate::render::film::{render_frame_deep, DeepRequest};
use crate::render::{exr, BlasSet, Film, RenderSettings, Tracing};
use crate::scene::passes::PassSet;
use crate::scene::{vis, Camera, Deform, FrameScene, Instance, InstanceMotion, SceneMotion, Space};

/// What to render.
#[derive(Debug, Clone)]
pub struct RenderJob {
    /// Layer names in render order (`set`, crowd layers, or `full`).
    pub layers: Vec<String>,
    /// Shot frames.
    pub frames: Vec<i32>,
    /// Samples per pixel.
    pub spp: u32,
    /// Threads (0 = all cores).
    pub threads: usize,
    /// Output directory.
    pub out: PathBuf,
    /// Skip frames whose EXR exists and reads back whole.
    pub resume: bool,
    /// Also write a PNG preview beside each EXR.
    pub png: bool,
    /// Image size override (width, height); the shot's when `None`.
    pub resolution: Option<[u32; 2]>,
    /// Cryptomatte output (`CryptoAgent`, `CryptoPart`, `CryptoMaterial`).
    pub cryptomatte: CryptoOutput,
    /// EXR compression (lossless ZIP by default).
    pub compression: exr::LayerCompression,
    /// Motion blur: shutter `[open, close]` in frames relative to each frame
    /// (`None`: no blur, no motion-vector pass). Skinned agents blur through
    /// their shutter's pose steps, so the crowd must be built for this
    /// shutter ([`ShotCrowd::open`]); [`run`] refuses one that is not.
    pub shutter: Option<[f32; 2]>,
    /// The working colourspace (`render.working_colourspace`): the crowd's
    /// library must be in it (for ACEScg, [`crate::render::colour::into_acescg`]);
    /// [`run`] refuses one that is not. The job converts each frame's lights itself.
    pub colourspace: Colourspace,
    /// Light-path passes, light groups and position to write (`None`: the
    /// shot's `render.passes`).
    pub passes: Option<PassSet>,
    /// Adaptive sampling (`spp` is then not used); `None`: `spp` samples
    /// in every pixel. `throng render` takes the shot's `render.adaptive`
    /// unless given `--spp`.
    pub adaptive: Option<crate::shot::Adaptive>,
    /// How rays are traced: the product's default; benchmarks and tests
    /// compare other choices (the same pixels on every one).
    pub tracing: Tracing,
    /// Denoise every layer-frame with Open Image Denoise at this preset
    /// (render::denoise); `None`: not denoised. `throng render` takes the
    /// shot's `render.denoise` unless told otherwise.
    pub denoise: Option<crate::shot::Denoise>,
    /// Also write every layer-frame as a deep OpenEXR beside the flat one
    /// (`deep_layer_path`; render::deep); `None`: flat files only.
    /// `throng render` takes the shot's `render.deep` unless told otherwise.
    pub deep: Option<crate::shot::Deep>,
}

impl RenderJob {
    /// The passes the job writes: its own, else the shot's `render.passes`
    /// (checked when the shot was read).
    /// In clear air without the air's passes ([`PassSet::in_air`]).
    pub fn passes_of(&self, shot: &crate::shot::Shot) -> Result<PassSet> {
        let set = match &self.passes {
            Some(p) => p.clone(),
            None => PassSet::parse(&shot.render.passes, "render.passes")?,
        };
        Ok(set.in_air(shot.hazy()))
    }

    /// A job for `layers` x `frames` at `spp` into `out`, with the defaults
    /// of `throng render`: all cores, the shot's resolution, Cryptomatte in
    /// the header, no resume, no PNG previews.
    pub fn new(layers: Vec<String>, frames: Vec<i32>, spp: u32, out: PathBuf) -> RenderJob {
        RenderJob {
            layers,
            frames,
            spp,
            threads: 0,
            out,
            resume: false,
            png: false,
            resolution: None,
            cryptomatte: CryptoOutput::Header,
            compression: exr::LayerCompression::Zip,
            shutter: None,
            colourspace: Colourspace::Rec709,
            passes: None,
            adaptive: None,
            tracing: Tracing::default(),
            denoise: None,
            deep: None,
        }
    }
}

impl RenderJob {
    /// Every file the job may write for shot `shot`: each layer-frame's
    /// EXR, and its PNG preview and Cryptomatte sidecars when asked for.
    pub fn outputs(&self, shot: &str) -> Vec<PathBuf> {
        let mut out = Vec::new();
        for layer in &self.layers {
            for &frame in &self.frames {
                let exr_path = layer_path(&self.out, shot, layer, frame);
                if self.png {
                    out.push(exr_path.with_extension("png"));
                }
                if self.deep.is_some() {
                    out.push(deep_layer_path(&exr_path));
                }
                if self.cryptomatte == CryptoOutput::Sidecar {
                    let dir = exr_path.parent().map(std::path::Path::to_path_buf).unwrap_or_default();
                    out.extend(
                        crate::render::cryptomatte::MATTES.iter().map(|t| dir.join(exr::sidecar_name(&exr_path, t))),
                    );
                }
                out.push(exr_path);
            }
        }
        out
    }
}

/// Where a running job is: the layer-frame at hand and how many of the
/// job's layer-frames are finished.
#[derive(Debug, Clone, Copy)]
pub struct RenderProgress<'a> {
    /// Shot frame.
    pub frame: i32,
    /// Layer name.
    pub layer: &'a str,
    /// Layer-frames finished before this one.
    pub done: usize,
    /// Layer-frames in the job.
    pub total: usize,
}

/// What a render reports while it runs. The stage never prints: the
/// command line implements this to draw a bar or write log lines, tests use
/// [`Silent`]. Every method has a silent default; calls may come from
/// render threads.
pub trait RenderObserver: Sync {
    /// Whether to report pixels done within a layer-frame (costs a callback per tile).
    fn wants_pixels(&self) -> bool {
        false
    }
    /// A layer-frame starts rendering.
    fn layer_started(&self, _at: RenderProgress<'_>) {}
    /// `fraction` (0-1) of the current layer-frame's pixels are done.
    fn pixels(&self, _at: RenderProgress<'_>, _fraction: f64) {}
    /// A layer-frame is finished: written, or `skipped` as already complete (resume).
    fn layer_finished(&self, _at: RenderProgress<'_>, _skipped: bool) {}
    /// Something legal but worth telling the lighter (also kept in
    /// [`RenderReport::warnings`]). An error ends the job there, before it
    /// writes anything more: a pipeline that treats warnings as errors.
    fn warning(&self, _text: &str) -> Result<()> {
        Ok(())
    }
}

/// An observer that reports nothing.
#[derive(Debug, Clone, Copy, Default)]
pub struct Silent;

impl RenderObserver for Silent {}

/// What a finished job gives back.
#[derive(Debug, Clone, Default)]
pub struct RenderReport {
    /// Every layer-frame, in the order rendered.
    pub layers: Vec<RenderedLayer>,
    /// Warnings given on the way, in order.
    pub warnings: Vec<String>,
}

/// Whether and how a job writes Cryptomatte mattes.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub enum CryptoOutput {
    /// No Cryptomatte channels.
    Off,
    /// Mattes with their manifests in the EXR header (the default).
    #[default]
    Header,
    /// Mattes with sidecar manifests `<exr stem>.<type>.json` (`manif_file`).
    Sidecar,
}

/// The Cryptomatte names of a frame scene's instances: slot and prop names
/// from each agent's cast, set objects from the set file's nodes
/// ([`ShotCrowd::set_names`]), materials from the library.
pub(crate) fn crypto_names<'a, C>(crowd: &'a ShotCrowd<C>, scene: &'a FrameScene) -> CryptoNames<'a> {
    let tables = NameTables { materials: &crowd.library().materials, set_objects: crowd.set_names() };
    CryptoNames::new(&scene.instances, &tables, |agent| {
        let cast = crowd.cast(agent)?;
        Some(move |part: u16| cast.part_name(part))
    })
}

/// One file the job wrote or skipped.
#[derive(Debug, Clone)]
pub struct RenderedLayer {
    /// Layer name.
    pub layer: String,
    /// Shot frame.
    pub frame: i32,
    /// The EXR.
    pub path: PathBuf,
    /// Whether `--resume` found it complete and skipped it.
    pub skipped: bool,
    /// Seconds spent (0 when skipped).
    pub seconds: f64,
    /// Instances traced.
    pub instances: usize,
    /// Peak resident memory of the process while this layer-frame rendered,
    /// bytes (from its posing to its file written; `None` when skipped or
    /// where /proc cannot say). The figure a layer budget must hold.
    pub peak_rss_bytes: Option<u64>,
    /// Seconds building the top-level tree (0 when skipped).
    pub tlas_build_s: f64,
    /// Each pass written (light paths, light groups, shadow, P) with its
    /// channels' bytes before compression (empty when skipped or none).
    pub pass_bytes: Vec<(String, u64)>,
    /// Bytes of the EXR written (0 when skipped).
    pub file_bytes: u64,
    /// Seconds denoising, included in `seconds` (0 when not denoised or skipped).
    pub denoise_s: f64,
    /// The deep file written (`None`: no deep output, or skipped), its bytes
    /// and its deep samples.
    pub deep: Option<DeepWritten>,
}

/// What a layer-frame's deep file holds.
#[derive(Debug, Clone)]
pub struct DeepWritten {
    /// The deep EXR.
    pub path: PathBuf,
    /// Its bytes.
    pub file_bytes: u64,
    /// Deep samples in it.
    pub samples: u64,
    /// The most samples one pixel holds.
    pub max_samples_per_pixel: u32,
    /// Pixels of the image.
    pub pixels: u64,
}

/// The deep file beside the flat layer file `flat`
/// (`<shot>.<layer>.<frame:04>.deep.exr`).
pub fn deep_layer_path(flat: &Path) -> PathBuf {
    flat.with_extension("deep.exr")
}

impl RenderedLayer {
    /// Layer `layer` of frame `frame` at `path`, left as a resumed job found it.
    fn skipped(layer: &str, frame: i32, path: PathBuf) -> RenderedLayer {
        RenderedLayer {
            layer: layer.to_string(),
            frame,
            path,
            skipped: true,
            seconds: 0.0,
            instances: 0,
            peak_rss_bytes: None,
            tlas_build_s: 0.0,
            pass_bytes: Vec::new(),
            file_bytes: 0,
            denoise_s: 0.0,
            deep: None,
        }
    }
}

/// Every rendered agent of a frame with its posed slots (world_from_slot):
/// posed once per frame and shared by every layer's scene.
pub struct PosedFrame {
    /// Shot frame.
    pub(crate) frame: i32,
    /// (agent id, its pose).
    pub(crate) agents: Vec<(u32, AgentPose)>,
}

impl PosedFrame {
    /// Reads the frame from the cache once and poses every rendered agent.
    pub fn new<C>(crowd: &ShotCrowd<C>, frame: i32) -> Result<PosedFrame> {
        use rayon::prelude::*;
        let block = crowd.agents_at(frame)?;
        // Pure per agent: posed in parallel, kept in order (and the first
        // error in order is the one reported, for any thread count).
        let posed: Vec<Result<(u32, AgentPose)>> =
            (block.agents.par_iter()).filter(|a| crowd.renders(a)).map(|a| Ok((a.id, crowd.agent_pose(a)?))).collect();
        let agents = posed.into_iter().collect::<Result<_>>()?;
        Ok(PosedFrame { frame, agents })
    }
}

/// The set's visibility bits in `layer` (`None`: not in it).
fn set_bits(manifest: Option<&Manifest>, layer: &str) -> Result<Option<u8>> {
    if layer == FULL_LAYER {
        return Ok(Some(vis::ALL));
    }
    let m = manifest.ok_or_else(|| Error::Usage(format!("layer `{layer}` needs a layer manifest")))?;
    Ok(m.set_visibility(layer).filter(|&b| b != 0))
}

/// How agent `id` appears in `layer` at `frame`: its visibility bits (never
/// 0) and LOD, or `None` when it is not traced there. `full` shows every
/// agent at the LOD the manifest gives it (full without one).
fn agent_bits(manifest: Option<&Manifest>, layer: &str, id: u32, frame: i32) -> Option<(u8, Lod)> {
    let how = match manifest {
        _ if layer == FULL_LAYER => {
            Some((vis::ALL, manifest.and_then(|m| m.agent(id)).map_or(Lod::Full, |r| r.lod_at(frame))))
        }
        Some(m) => m.agent_visibility(layer, id, frame),
        None => None,
    };
    how.filter(|&(bits, _)| bits != 0)
}

/// The instances of one (frame, layer) render, from the frame's shared poses.
pub fn frame_scene<C>(
    crowd: &ShotCrowd<C>,
    manifest: Option<&Manifest>,
    layer: &str,
    posed: &PosedFrame,
) -> Result<FrameScene> {
    scene_from_poses(
        crowd,
        manifest,
        layer,
        posed.frame,
        &posed.agents,
        |(id, _)| *id,
        |(_, pose)| Ok(Cow::Borrowed(pose)),
    )
}

/// The same scene as [`frame_scene`], posing each agent as it is placed:
/// for a frame's last layer, so a million agents' slot poses are never
/// held beside their instances.
pub fn streamed_frame_scene<C>(
    crowd: &ShotCrowd<C>,
    manifest: Option<&Manifest>,
    layer: &str,
    frame: i32,
) -> Result<FrameScene> {
    let block = crowd.agents_at(frame)?;
    let rendered: Vec<&AgentSample> = block.agents.iter().filter(|a| crowd.renders(a)).collect();
    scene_from_poses(crowd, manifest, layer, frame, &rendered, |a| a.id, |a| crowd.agent_pose(a).map(Cow::Owned))
}

/// Agents placed per parallel task, and tasks per wave: a wave's instances
/// are appended in agent order before the next starts, so placing in
/// parallel holds only a wave's worth of extra instances.
const PLACING_CHUNK: usize = 1024;
const PLACING_WAVE: usize = 16;

/// A frame scene from its agents (`id` and `pose` of each). Posing and
/// placing are pure per agent: done in parallel, appended in agent order,
/// so the scene is the same for any thread count.
fn scene_from_poses<'p, T: Sync, C>(
    crowd: &ShotCrowd<C>,
    manifest: Option<&Manifest>,
    layer: &str,
    frame: i32,
    agents: &'p [T],
    id: impl Fn(&T) -> u32 + Sync,
    pose: impl Fn(&'p T) -> Result<Cow<'p, AgentPose>> + Sync,
) -> Result<FrameScene> {
    use rayon::prelude::*;
    let set_bits = set_bits(manifest, layer)?;
    // Sized once: at a million agents the doublings of a growing list cost a gigabyte.
    let bound = instance_bound(crowd, manifest, layer, frame, agents.iter().map(&id), set_bits);
    let mut instances: Vec<Instance> = Vec::with_capacity(bound);
    for wave in agents.chunks(PLACING_CHUNK * PLACING_WAVE) {
        let placed: Vec<Result<Vec<Instance>>> = wave
            .par_chunks(PLACING_CHUNK)
            .map(|chunk| {
                let mut out = Vec::new();
                for a in chunk {
                    let id = id(a);
                    if let Some((bits, lod)) = agent_bits(manifest, layer, id, frame) {
                        let pose = pose(a)?;
                        crowd.posed_instances(id, &pose, lod, bits, &mut out);
                    }
                }
                Ok(out)
            })
            .collect();
        for chunk in placed {
            instances.extend(chunk?);
        }
    }
    if let Some(bits) = set_bits {
        instances.extend(crowd.set().iter().map(|i| Instance { visibility: bits, ..*i }));
    }
    Ok(FrameScene { instances, camera: crowd.camera(frame)?, lights: crowd.lights(), motion: None })
}

/// At most how many instances a (frame, layer) scene of agents `ids` holds
/// (the set's too when it is in the layer), so its list is allocated once.
fn instance_bound<C>(
    crowd: &ShotCrowd<C>,
    manifest: Option<&Manifest>,
    layer: &str,
    frame: i32,
    ids: impl Iterator<Item = u32>,
    set_bits: Option<u8>,
) -> usize {
    ids.filter_map(|id| Some(crowd.instance_count(id, agent_bits(manifest, layer, id, frame)?.1))).sum::<usize>()
        + set_bits.map_or(0, |_| crowd.set().len())
}

/// The instances of one (frame, layer) render moving over the shutter: each
/// agent's instances at shutter open, and in the scene's motion their close
/// keys (the set stands still). An agent whose open and close instances do
/// not pair up (a pose missing at one key) is rendered still at open.
pub fn motion_scene<C>(
    crowd: &ShotCrowd<C>,
    manifest: Option<&Manifest>,
    layer: &str,
    motion: &MotionFrame,
) -> Result<FrameScene> {
    let frame = motion.frame;
    let set_bits = set_bits(manifest, layer)?;
    let bound = instance_bound(crowd, manifest, layer, frame, motion.agents.iter().map(|(id, _)| *id), set_bits);
    let mut instances: Vec<Instance> = Vec::with_capacity(bound);
    let mut keys: Vec<InstanceMotion> = Vec::with_capacity(bound);
    let mut close: Vec<Instance> = Vec::new();
    for (id, m) in &motion.agents {
        let Some((bits, lod)) = agent_bits(manifest, layer, *id, frame) else { continue };
        let start = instances.len();
        crowd.posed_instances(*id, &m.open, lod, bits, &mut instances);
        close.clear();
        crowd.posed_instances(*id, &m.close, lod, bits, &mut close);
        let opened = &instances[start..];
        if close.len() == opened.len() {
            keys.extend(opened.iter().zip(&close).map(|(o, c)| InstanceMotion {
                world_from_object_close: c.world_from_object,
                deform: m.deform.filter(|_| c.mesh != o.mesh).map(|weight| Deform { mesh: c.mesh, weight }),
            }));
        } else {
            keys.extend(opened.iter().map(InstanceMotion::still));
        }
    }
    if let Some(bits) = set_bits {
        let from = instances.len();
        instances.extend(crowd.set().iter().map(|i| Instance { visibility: bits, ..*i }));
        keys.extend(instances[from..].iter().map(InstanceMotion::still));
    }
    Ok(FrameScene {
        instances,
        camera: crowd.camera(frame)?,
        lights: crowd.lights(),
        motion: Some(SceneMotion { shutter: motion.shutter, instances: keys, camera: motion.camera }),
    })
}

/// Every layer a manifest renders, back to front (`set`, then crowd layers far to near).
pub fn all_layers(manifest: &Manifest) -> Vec<String> {
    manifest.comp_order.clone()
}

/// The render fingerprint of one layer (`throng/renderFingerprint`, 16 hex
/// digits, [`crate::fingerprint`]): everything that changes the pixels or
/// channels of a layer file: samples per pixel, resolution, seed, bounces,
/// the camera and lights of the shot, the shutter, the working colourspace,
/// Cryptomatte (with its matte types and set object naming) and compression
/// choices, the atmosphere, the layer name, the manifest (whose `made_from` covers the
/// cache, its import keys and the casting) and the throng version.
/// `--resume` skips a file only when its fingerprint matches.
pub fn render_fingerprint<C>(
    crowd: &ShotCrowd<C>,
    manifest: Option<&Manifest>,
    job: &RenderJob,
    layer: &str,
) -> String {
    let shot = crowd.shot();
    let lights = crowd.lights();
    // The dome's texels are hashed below; its path is not what the render
    // used (a farm task names the shot by another path than a local run).
    let mut lights_without_paths = shot.lights.clone();
    if let Some(d) = &mut lights_without_paths.dome {
        d.file = std::path::PathBuf::new();
    }
    let mut f = Fingerprinter::new();
    f.value("spp", &job.spp)
        .value("resolution", &job.resolution.unwrap_or(shot.render.resolution))
        .value("seed", &shot.seed)
        .value("max_bounces", &shot.render.max_bounces)
        .value("indirect_clamp", &shot.render.indirect_clamp)
        .debug("passes", &job.passes_of(shot).unwrap_or_default())
        .debug("adaptive", &job.adaptive)
        .value("sensor_width", &shot.camera.sensor_width)
        .debug("camera keys", &shot.camera.keys)
        .debug("camera node", &shot.camera.gltf.as_ref().map(|(_, node)| node))
        .debug("lights", &lights_without_paths)
        .debug("set lights", &lights.local)
        .floats("dome", lights.dome.iter().flat_map(|d| d.texels.iter().flat_map(|t| t.to_array())))
        .value("shutter", &job.shutter)
        .text("colourspace", colour::header_name(job.colourspace))
        .debug("cryptomatte", &job.cryptomatte)
        .value("mattes", &crate::render::cryptomatte::MATTES)
        .debug("compression", &job.compression)
        .text("layer", layer);
    // Only a denoised render names it, so an undenoised file keeps the
    // fingerprint it had before denoising existed.
    if let Some(d) = job.denoise {
        f.text("denoise", d.name());
    }
    if let Some(d) = &job.deep {
        f.debug("deep", d);
    }
    // Likewise only hazy shots name their air (air of density 0 renders
    // nothing, as clear air does).
    if let Some(a) = shot.atmosphere.filter(|a| a.is_active()) {
        f.debug("atmosphere", &a);
    }
    f.value("manifest", &manifest).text("throng", env!("CARGO_PKG_VERSION"));
    f.hex()
}

/// Claims each layer folder of the job for this process
/// ([`WriterLock`]: its files and its layer's render fingerprint), so a
/// second render of the same frames, or of the same layer with other
/// settings, into the same folder is refused naming this one.
fn claim_layer_folders(
    shot: &str,
    job: &RenderJob,
    fingerprints: &std::collections::HashMap<&str, String>,
) -> Result<Vec<(String, WriterLock)>> {
    let outputs = job.outputs(shot);
    let mut claims = Vec::new();
    for layer in &job.layers {
        let dir = job.out.join(layer);
        let names: Vec<String> = (outputs.iter())
            .filter(|p| p.parent() == Some(dir.as_path()))
            .filter_map(|p| Some(p.file_name()?.to_string_lossy().into_owned()))
            .collect();
        let settings = fingerprints.get(layer.as_str()).map_or("", String::as_str);
        claims.push((layer.clone(), WriterLock::claim(&dir, &names, settings)?));
    }
    Ok(claims)
}

/// Refuses, before anything is allocated or written, an image whose film
/// (the memory model's bytes a pixel: film, AOVs, Cryptomatte, the EXR
/// being encoded, [`crate::layers::memory::film_bytes`]) needs more than
/// this process may still allocate ([`crate::bench::memory_headroom`]),
/// naming both figures.
fn check_film_fits(w: u32, h: u32, channels: crate::layers::memory::FilmChannels) -> Result<()> {
    let need = crate::layers::memory::film_bytes(u64::from(w) * u64::from(h), channels);
    match crate::bench::memory_headroom() {
        Some(free) if need > free => Err(Error::Usage(format!(
            "a {w}x{h} image needs {} for its film alone ({} bytes a pixel: the film, its AOVs, passes, Cryptomatte \
             and the EXR being written), more than the {} this process may still use (its address-space limit, \
             its control group's memory limit or the memory available): render a smaller image",
            crate::layers::format_bytes(need),
            need / (u64::from(w) * u64::from(h)).max(1),
            crate::layers::format_bytes(free)
        ))),
        _ => Ok(()),
    }
}

/// Frames of other runs whose headers [`other_settings`] reads per layer.
const OTHER_SETTINGS_SAMPLE: usize = 8;

/// Per layer of the job, the frames already in its folder that the job
/// does not render and whose `throng/renderFingerprint` is not this run's
/// (read from their headers only, of the [`OTHER_SETTINGS_SAMPLE`] such
/// frames nearest the job's first).
fn other_settings(
    shot: &str,
    job: &RenderJob,
    fingerprints: &std::collections::HashMap<&str, String>,
) -> Vec<(String, Vec<i32>)> {
    let rendered: std::collections::HashSet<i32> = job.frames.iter().copied().collect();
    let mut out = Vec::new();
    for layer in &job.layers {
        let Ok(entries) = std::fs::read_dir(job.out.join(layer)) else { continue };
        let prefix = format!("{shot}.{layer}.");
        let Some(now) = fingerprints.get(layer.as_str()) else { continue };
        let mut others: Vec<(i32, PathBuf)> = entries
            .flatten()
            .filter_map(|e| {
                let name = e.file_name().to_string_lossy().into_owned();
                let frame: i32 = name.strip_prefix(&prefix)?.strip_suffix(".exr")?.parse().ok()?;
                (!rendered.contains(&frame)).then(|| (frame, e.path()))
            })
            .collect();
        // Headers may hold large Cryptomatte manifests, and a farm task of
        // one frame must not read a thousand: the nearest few tell.
        let first = job.frames.iter().copied().min().unwrap_or(0);
        others.sort_unstable_by_key(|(f, _)| ((i64::from(*f) - i64::from(first)).abs(), *f));
        others.truncate(OTHER_SETTINGS_SAMPLE);
        let mut frames: Vec<i32> = others
            .into_iter()
            .filter(|(_, path)| exr::read_render_fingerprint(path).is_ok_and(|f| f != *now))
            .map(|(f, _)| f)
            .collect();
        frames.sort_unstable();
        if !frames.is_empty() {
            out.push((layer.clone(), frames));
        }
    }
    out
}

/// The warning for each layer folder holding frames of other settings
/// ([`other_settings`]).
fn mixing_warnings(shot: &str, job: &RenderJob, fingerprints: &std::collections::HashMap<&str, String>) -> Vec<String> {
    other_settings(shot, job, fingerprints)
        .into_iter()
        .map(|(layer, others)| {
            format!(
                "{} holds frames of layer {layer} rendered with other settings ({} of the nearest, first {}): the \
                 folder will mix two renders; render every frame again, or into another folder, to keep it whole",
                job.out.join(&layer).display(),
                others.len(),
                others[0]
            )
        })
        .collect()
}

/// The layer-frames of the job already rendered as it would render them
/// (a resumed job skips them), each other one found telling `warn` it is
/// rendered again; nothing when the job does not resume. Asked of every
/// layer-frame before the first is written, so a warning that stops the
/// job (a pipeline's strict mode) stops it with nothing written.
fn rendered_already(
    shot: &str,
    job: &RenderJob,
    fingerprints: &std::collections::HashMap<&str, String>,
    warn: &mut dyn FnMut(String) -> Result<()>,
) -> Result<std::collections::HashSet<(i32, String)>> {
    let mut complete = std::collections::HashSet::new();
    if !job.resume {
        return Ok(complete);
    }
    for &frame in &job.frames {
        for layer in &job.layers {
            let fingerprint = fingerprints.get(layer.as_str()).map_or("", String::as_str);
            if is_rendered(&layer_path(&job.out, shot, layer, frame), fingerprint, warn)? {
                complete.insert((frame, layer.clone()));
            }
        }
    }
    Ok(complete)
}

/// What [`run`] would warn of before it writes its first file: layer
/// folders holding frames of other settings and, resuming, layer-frames
/// rendered again. Read only (no claim taken, no temporary removed), for a
/// caller that writes files of its own before the render and must not
/// write them when a warning is an error (`run` warns of these itself).
pub fn warnings_before_writing<C: Space>(
    crowd: &ShotCrowd<C>,
    manifest: Option<&Manifest>,
    job: &RenderJob,
) -> Result<Vec<String>> {
    // Any library colourspace: the job's choices are checked when it runs.
    let fingerprints: std::collections::HashMap<&str, String> =
        job.layers.iter().map(|l| (l.as_str(), render_fingerprint(crowd, manifest, job, l))).collect();
    let shot = &crowd.shot().name;
    let mut warnings = mixing_warnings(shot, job, &fingerprints);
    rendered_already(shot, job, &fingerprints, &mut |w| {
        warnings.push(w);
        Ok(())
    })?;
    Ok(warnings)
}

/// Removes the temporaries that a killed run left beside this job's targets
/// (`.<file>.<pid>.tmp`, as `write_atomic` names them, for a frame of the
/// job in a layer of the job) whose process is gone: not this one, not
/// alive, not another writer holding a claim on the folder (`claims`, one
/// per layer, taken first). Returns them.
pub(crate) fn remove_stale_temporaries(
    shot: &str,
    job: &RenderJob,
    claims: &[(String, WriterLock)],
) -> Result<Vec<PathBuf>> {
    let frames: std::collections::HashSet<i32> = job.frames.iter().copied().collect();
    let mut removed = Vec::new();
    for (layer, claim) in claims {
        let dir = job.out.join(layer);
        let Ok(entries) = std::fs::read_dir(&dir) else { continue };
        let prefix = format!("{shot}.{layer}.");
        for e in entries.flatten() {
            let name = e.file_name().to_string_lossy().into_owned();
            let Some(inner) = name.strip_prefix('.').and_then(|n| n.strip_suffix(".tmp")) else { continue };
            let Some((target, pid)) = inner.rsplit_once('.') else { continue };
            if pid.parse::<u32>().map_or(true, |p| claim.may_be_writing(p)) {
                continue;
            }
            let frame = target.strip_prefix(&prefix).and_then(|r| r.split('.').next()).and_then(|f| f.parse().ok());
            if frame.is_some_and(|f| frames.contains(&f)) {
                let path = e.path();
                std::fs::remove_file(&path).map_err(|err| Error::io(&path, err))?;
                removed.push(path);
            }
        }
    }
    Ok(removed)
}

/// Claims the job's layer folders (one writer per file and per layer's
/// settings), warning through `warn` of folders holding frames rendered
/// otherwise, and removes temporaries a killed render left behind. The
/// claims hold until they are dropped.
fn claim_and_clean<C: Space>(
    crowd: &ShotCrowd<C>,
    job: &RenderJob,
    fingerprints: &std::collections::HashMap<&str, String>,
    warn: &mut dyn FnMut(String) -> Result<()>,
) -> Result<Vec<(String, WriterLock)>> {
    let claims = claim_layer_folders(&crowd.shot().name, job, fingerprints)?;
    for w in mixing_warnings(&crowd.shot().name, job, fingerprints) {
        warn(w)?;
    }
    let stale = remove_stale_temporaries(&crowd.shot().name, job, &claims)?;
    if !stale.is_empty() {
        warn(format!(
            "removed {} stale temporary file(s) a killed render left behind (first: {})",
            stale.len(),
            stale[0].display()
        ))?;
    }
    Ok(claims)
}

/// The job's choices against the crowd and manifest it renders: its
/// colourspace and shutter are the crowd's, its layers and frames exist.
fn check_job<C: Space>(crowd: &ShotCrowd<C>, manifest: Option<&Manifest>, job: &RenderJob) -> Result<()> {
    if C::COLOURSPACE != job.colourspace {
        return Err(Error::Usage(format!(
            "the job renders in {} but the crowd's library is in {}: convert the crowd (render::colour::into_acescg)",
            colour::header_name(job.colourspace),
            colour::header_name(C::COLOURSPACE)
        )));
    }
    if job.shutter.is_some() && crowd.poses().shutter() != job.shutter {
        return Err(Error::Usage(format!(
            "the job blurs over shutter {:?} but the crowd is posed for {:?}: build it for that shutter (ShotCrowd::open)",
            job.shutter,
            crowd.poses().shutter()
        )));
    }
    for layer in &job.layers {
        let known = layer == FULL_LAYER || manifest.is_some_and(|m| m.comp_order.contains(layer));
        if !known {
            let names = manifest.map(|m| m.comp_order.join(", ")).unwrap_or_default();
            return Err(Error::Usage(format!("no layer `{layer}` in the manifest (layers: {names}, or `full`)")));
        }
    }
    for &f in &job.frames {
        if !crowd.shot().frames.contains(f) {
            return Err(Error::Usage(format!(
                "frame {f} is outside shot {} ({}-{})",
                crowd.shot().name,
                crowd.shot().frames.start,
                crowd.shot().frames.end
            )));
        }
    }
    Ok(())
}

/// A deep render is complete only with its deep file beside the flat one,
/// readable.
fn deep_complete(job: &RenderJob, path: &Path) -> bool {
    job.deep.is_none() || exr::deep::is_whole(&deep_layer_path(path))
}

/// Whether `path` holds the layer-frame rendered as `fingerprint` says (a
/// resumed job skips it); a file rendered otherwise is told of through `warn`.
fn is_rendered(path: &Path, fingerprint: &str, warn: &mut dyn FnMut(String) -> Result<()>) -> Result<bool> {
    Ok(match exr::read_layer(path) {
        Ok((_, meta)) if meta.render_fingerprint == fingerprint => true,
        Ok((_, meta)) => {
            warn(format!(
                    "resume: re-rendering {}: it was rendered with other settings \
                     (renderFingerprint {}, now {fingerprint}: spp, resolution, seed, camera, lights, shutter, colourspace, Cryptomatte, compression or manifest differ)",
                    path.display(),
                    if meta.render_fingerprint.is_empty() { "none" } else { &meta.render_fingerprint },
                ))?;
            false
        }
        Err(_) => false,
    })
}

/// The settings of layer `layer` of frame `frame`.
pub(crate) fn layer_settings<C: Space>(
    crowd: &ShotCrowd<C>,
    manifest: Option<&Manifest>,
    job: &RenderJob,
    layer: &str,
    frame: i32,
    passes: &PassSet,
) -> RenderSettings {
    let [width, height] = job.resolution.unwrap_or(crowd.shot().render.resolution);
    // The layer index keys the random streams, so layers are
    // independent samples; `full` and `set` get fixed indices.
    let index = manifest.and_then(|m| m.comp_order.iter().position(|l| l == layer)).unwrap_or(u32::MAX as usize) as u32;
    RenderSettings {
        width,
        height,
        spp: job.spp,
        max_bounces: crowd.shot().render.max_bounces,
        indirect_clamp: crowd.shot().render.indirect_clamp,
        seed: crowd.shot().seed,
        frame: frame as i64,
        layer: index,
        sky_visible: layer == FULL_LAYER || manifest.is_some_and(|m| *layer == m.set.name),
        threads: job.threads,
        passes: passes.clone(),
        adaptive: job.adaptive,
        tracing: job.tracing,
        atmosphere: crowd.shot().atmosphere.filter(|a| a.is_active()).map(|a| colour::atmosphere(a, job.colourspace)),
        ..RenderSettings::default()
    }
}

/// Drops what earlier frames built and `scene` does not trace (its later
/// layers add to it): one frame's BLASes at a time, what the memory model
/// (`layers::memory`) counts.
fn keep_frame_blases(blas: &mut BlasSet, scene: &FrameScene) {
    let meshes: std::collections::HashSet<u32> = scene.instances.iter().map(|i| i.mesh).collect();
    let pairs: std::collections::HashSet<(u32, u32)> = scene.motion.as_ref().map_or_else(Default::default, |m| {
        scene.instances.iter().zip(&m.instances).filter_map(|(i, k)| k.deform.map(|d| (i.mesh, d.mesh))).collect()
    });
    blas.retain(|m| meshes.contains(&m), |p| pairs.contains(&p));
}

/// The EXR header of layer `layer` of frame `frame`, rendered as
/// `fingerprint` into `film` through `camera`.
fn layer_meta<C: Space>(
    crowd: &ShotCrowd<C>,
    job: &RenderJob,
    layer: &str,
    frame: i32,
    fingerprint: String,
    film: &Film,
    camera: &Camera,
) -> exr::LayerMeta {
    let [w, h] = job.resolution.unwrap_or(crowd.shot().render.resolution);
    let (near, far) = film.depth_range().unwrap_or((0.1, 1000.0));
    let (world_to_camera, world_to_ndc) = exr::camera_matrices(camera, w, h, near, far);
    exr::LayerMeta {
        shot: crowd.shot().name.clone(),
        layer: layer.to_string(),
        frame,
        seed: crowd.shot().seed,
        spp: job.adaptive.map_or(job.spp, |a| a.max_spp),
        id_mapping: exr::ID_MAPPING.to_string(),
        world_to_camera,
        world_to_ndc,
        near,
        far,
        fps: crowd.shot().frames.fps,
        render_fingerprint: fingerprint,
        denoiser: String::new(),
        shutter: job.shutter,
        colourspace: job.colourspace,
    }
}

/// Which layer-frame file is being written, under which fingerprint.
struct LayerFile<'a> {
    layer: &'a str,
    frame: i32,
    path: &'a Path,
    fingerprint: String,
}

/// What writing a layer-frame's file gave.
struct Written {
    pass_bytes: Vec<(String, u64)>,
    file_bytes: u64,
    denoise_s: f64,
    deep: Option<DeepWritten>,
}

/// Denoises `film` when the job asks (render::denoise), then writes its
/// EXR, its deep EXR when given `deep` (never denoised: its samples are
/// the camera's) and, when asked, its PNG preview.
fn write_layer_file<C: Space>(
    crowd: &ShotCrowd<C>,
    job: &RenderJob,
    denoiser: Option<&Denoiser>,
    at: LayerFile<'_>,
    (mut film, deep): (Film, Option<DeepImage>),
    camera: &Camera,
) -> Result<Written> {
    let started = Instant::now();
    let mut stamp = String::new();
    if let (Some(denoiser), Some(preset)) = (denoiser, job.denoise) {
        denoiser.denoise(&mut film, preset)?;
        stamp = crate::render::denoise::stamp(denoiser, preset);
    }
    let denoise_s = if stamp.is_empty() { 0.0 } else { started.elapsed().as_secs_f64() };
    let mut meta = layer_meta(crowd, job, at.layer, at.frame, at.fingerprint, &film, camera);
    meta.denoiser = stamp;
    let manifest = match job.cryptomatte {
        CryptoOutput::Sidecar => exr::ManifestMode::Sidecar,
        _ => exr::ManifestMode::Header,
    };
    let deep = match (deep, &job.deep) {
        (Some(image), Some(how)) => {
            let path = deep_layer_path(at.path);
            let mut deep_meta = meta.clone();
            deep_meta.denoiser = String::new();
            exr::deep::write_deep(&path, &image, &film, &deep_meta, exr::deep::DeepCompression::of(how))?;
            let file_bytes = std::fs::metadata(&path).map_or(0, |m| m.len());
            let (samples, max_samples_per_pixel) = (image.samples.len() as u64, image.max_samples());
            let pixels = u64::from(image.width) * u64::from(image.height);
            Some(DeepWritten { path, file_bytes, samples, max_samples_per_pixel, pixels })
        }
        _ => None,
    };
    exr::write_layer_with(at.path, &film, &meta, &exr::WriteOptions { manifest, compression: job.compression })?;
    if job.png {
        exr::write_preview_png_from(&at.path.with_extension("png"), &film, job.colourspace)?;
    }
    let file_bytes = std::fs::metadata(at.path).map_or(0, |m| m.len());
    Ok(Written { pass_bytes: exr::pass_bytes(&film), file_bytes, denoise_s, deep })
}

/// Renders every (frame, layer) of the job, reporting to `observer`. The
/// crowd's library is in the job's colourspace and posed for its shutter.
pub fn run<C: Space>(
    crowd: &ShotCrowd<C>,
    manifest: Option<&Manifest>,
    job: &RenderJob,
    observer: &dyn RenderObserver,
) -> Result<RenderReport> {
    check_job(crowd, manifest, job)?;
    let mut warnings = Vec::new();
    let mut warn = |text: String| -> Result<()> {
        let told = observer.warning(&text);
        warnings.push(text);
        told
    };
    let [w, h] = job.resolution.unwrap_or(crowd.shot().render.resolution);
    let passes = job.passes_of(crowd.shot())?;
    let channels = crate::layers::memory::FilmChannels {
        blurred: job.shutter.is_some(),
        passes: crate::layers::memory::pass_count_of(crowd, &passes)?,
        deep: job.deep.is_some(),
    };
    check_film_fits(w, h, channels)?;
    // Opened before anything is written: a missing library stops the job here.
    let denoiser = job.denoise.map(|_| Denoiser::open(None, job.threads)).transpose()?;
    let fingerprints: std::collections::HashMap<&str, String> =
        job.layers.iter().map(|l| (l.as_str(), render_fingerprint(crowd, manifest, job, l))).collect();
    // Held until the job returns: one writer per file and per layer's settings.
    let _claims = claim_and_clean(crowd, job, &fingerprints, &mut warn)?;
    // Every warning before the first write: a resume's files are judged now.
    let complete = rendered_already(&crowd.shot().name, job, &fingerprints, &mut warn)?;
    // BLASes are built as layer-frames need them (and kept for later frames).
    let mut blas = BlasSet::lazy(crowd.library());
    // The dome in the working colourspace, converted once for the job.
    let mut dome = colour::ConvertedDome::default();
    let total = job.frames.len() * job.layers.len();
    let mut out = Vec::new();
    for &frame in &job.frames {
        // Read and pose lazily: a fully resumed frame needs neither.
        let mut posed: Option<PosedFrame> = None;
        let mut moving: Option<MotionFrame> = None;
        let mut first_of_frame = true;
        for layer in &job.layers {
            let path = layer_path(&job.out, &crowd.shot().name, layer, frame);
            let fingerprint = fingerprints.get(layer.as_str()).cloned().unwrap_or_default();
            if complete.contains(&(frame, layer.clone())) && deep_complete(job, &path) {
                out.push(RenderedLayer::skipped(layer, frame, path));
                observer.layer_finished(RenderProgress { frame, layer, done: out.len() - 1, total }, true);
                continue;
            }
            let started = Instant::now();
            // Measure this layer-frame's own peak, not the run's so far.
            let measured = crate::bench::reset_peak_rss();
            let at = RenderProgress { frame, layer, done: out.len(), total };
            observer.layer_started(at);
            let mut scene = match job.shutter {
                Some(shutter) => {
                    if moving.is_none() {
                        moving = Some(MotionFrame::new(crowd, frame, shutter)?);
                    }
                    let Some(moving) = moving.as_ref() else { continue };
                    motion_scene(crowd, manifest, layer, moving)?
                }
                // A frame's only (or last unposed) layer poses as it goes.
                None if posed.is_none() && job.layers.last() == Some(layer) => {
                    streamed_frame_scene(crowd, manifest, layer, frame)?
                }
                None => {
                    if posed.is_none() {
                        posed = Some(PosedFrame::new(crowd, frame)?);
                    }
                    let Some(posed) = posed.as_ref() else { continue };
                    frame_scene(crowd, manifest, layer, posed)?
                }
            };
            colour::scene_lights_once(&mut scene, job.colourspace, &mut dome);
            if job.layers.last() == Some(layer) {
                // The frame's last layer has its instances: free the poses
                // before its trees are built (a million agents' slots).
                (posed, moving) = (None, None);
            }
            let settings = layer_settings(crowd, manifest, job, layer, frame, &passes);
            let pixels = (w as usize * h as usize).max(1);
            let report = |p: usize| observer.pixels(at, p as f64 / pixels as f64);
            if first_of_frame {
                keep_frame_blases(&mut blas, &scene);
                first_of_frame = false;
            }
            blas.prepare(crowd.library(), scene.instances.iter().map(|i| i.mesh));
            let names =
                (job.cryptomatte != CryptoOutput::Off || job.deep.is_some()).then(|| crypto_names(crowd, &scene));
            let deep = job.deep.as_ref().map(|d| DeepRequest { settings: DeepSettings::of(d), names: names.as_ref() });
            let (film, deep, stats) = render_frame_deep(
                &blas,
                crowd.library(),
                &scene,
                &settings,
                names.as_ref().filter(|_| job.cryptomatte != CryptoOutput::Off),
                deep.as_ref(),
                if observer.wants_pixels() { Some(&report) } else { None },
            )?;
            let at_file = LayerFile { layer, frame, path: &path, fingerprint };
            let written = write_layer_file(crowd, job, denoiser.as_ref(), at_file, (film, deep), &scene.camera)?;
            out.push(RenderedLayer {
                layer: layer.clone(),
                frame,
                path,
                skipped: false,
                seconds: started.elapsed().as_secs_f64(),
                instances: scene.instances.len(),
                peak_rss_bytes: measured.then(crate::bench::peak_rss_bytes).flatten(),
                tlas_build_s: stats.tlas_build.as_secs_f64(),
                pass_bytes: written.pass_bytes,
                file_bytes: written.file_bytes,
                denoise_s: written.denoise_s,
                deep: written.deep,
            });
            observer.layer_finished(at, false);
        }
    }
    Ok(RenderReport { layers: out, warnings })
}
