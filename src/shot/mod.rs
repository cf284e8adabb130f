//! The shot file (TOML, `version = 1`): ties a cache, rigs, wardrobes, a
//! set, a camera, lights, layer and render settings together. Every path is
//! relative to the shot file. Unknown keys, wrong types and missing files are
//! errors naming the file, line and key. docs/shot.md documents every key.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use glam::{Affine3A, Vec3};
use serde::{Deserialize, Serialize};
use toml::Spanned;

use crate::cache::keys::CacheTable;
use crate::cache::{TabularOptions, TabularSpec};
use crate::error::{line_of, Error, IoContext, Result};
use crate::scene::atmosphere::{Atmosphere, AtmosphereMode};
use crate::scene::{Camera, Sky, Sun};

mod lights;
use lights::LightsFile;
pub use lights::{DomeSpec, Lights, SunSpec};

/// The shot file version this build reads.
pub(crate) const SHOT_VERSION: u32 = 1;

/// A parsed, validated shot with absolute paths.
#[derive(Debug, Clone)]
pub struct Shot {
    /// The shot file itself.
    pub path: PathBuf,
    /// Shot name, used in output file names.
    pub name: String,
    /// Seed for casting and rendering.
    pub seed: u64,
    /// Frame range and rate.
    pub frames: Frames,
    /// The simulation cache.
    pub cache: CacheRef,
    /// Wardrobe files.
    pub wardrobes: Vec<PathBuf>,
    /// Rigs by name, as named in the cache.
    pub rigs: BTreeMap<String, RigRef>,
    /// The environment.
    pub(crate) set: Option<SetRef>,
    /// The camera.
    pub(crate) camera: CameraSpec,
    /// Sun, sky, dome and local lights.
    pub lights: Lights,
    /// `[atmosphere]`: haze or fog (render::atmosphere); `None`: clear air.
    pub atmosphere: Option<Atmosphere>,
    /// How to split agents into layers.
    pub layers: LayerSettings,
    /// Render settings.
    pub render: RenderSettings,
    /// Agents never rendered (still ranked, so removing one moves nobody else).
    pub removed: Vec<u32>,
    /// Agents on these cycles are not rendered.
    pub culled_cycles: Vec<String>,
    /// Agents on these cycles are never height-scaled.
    pub(crate) no_scale_cycles: Vec<String>,
    /// Part mesh names never cast in this shot.
    pub exclude_parts: Vec<String>,
}

/// `[frames]`.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Frames {
    /// First shot frame.
    pub start: i32,
    /// Last shot frame (inclusive).
    pub end: i32,
    /// Frames per second.
    #[serde(default = "default_fps")]
    pub fps: f32,
    /// What a shot frame with no cache frame (a gap, or past the cache's
    /// ends) renders: an error (the default) or an empty crowd, with a warning.
    #[serde(default)]
    pub(crate) outside_cache: OutsideCache,
}

/// `frames.outside_cache`: shot frames the cache does not hold.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub(crate) enum OutsideCache {
    /// Loading the shot fails, naming the first such frame.
    #[default]
    Error,
    /// Those frames have no agents; loading warns once, listing them.
    Empty,
}

/// Most frames a shot or a `--frames` list may hold (about 70 minutes at 24 fps).
pub(crate) const MAX_FRAMES: u64 = 100_000;
/// Largest width or height of a render.
pub const MAX_RESOLUTION: u32 = 16384;
/// Most pixels of a render (8192 x 8192): the film holds about 60 bytes a pixel.
pub const MAX_PIXELS: u64 = 8192 * 8192;
/// Most samples per pixel.
pub const MAX_SPP: u32 = 65536;
/// Most bounces after the camera ray (Russian roulette ends paths long before).
pub(crate) const MAX_BOUNCES: u32 = 1024;

/// Checks a shot name: it names output files (`<shot>.<layer>.<frame>.exr`),
/// so it is one plain file-name part: 1-255 bytes, no `/` or `\`, no
/// control characters, not starting with `.`.
pub(crate) fn check_shot_name(name: &str) -> std::result::Result<(), String> {
    if name.is_empty() || name.len() > 255 {
        return Err(format!("shot name must be 1-255 bytes, got {}", name.len()));
    }
    if name.starts_with('.') || name.chars().any(|c| c == '/' || c == '\\' || c.is_control()) {
        return Err(format!(
            "shot name `{}` names output files: no `/`, `\\` or control characters, and no leading `.`",
            name.escape_debug()
        ));
    }
    Ok(())
}

/// Checks a render size: each side 1..=[`MAX_RESOLUTION`], at most [`MAX_PIXELS`].
pub fn check_resolution(w: u32, h: u32) -> std::result::Result<(), String> {
    if w == 0 || h == 0 || w > MAX_RESOLUTION || h > MAX_RESOLUTION || u64::from(w) * u64::from(h) > MAX_PIXELS {
        return Err(format!(
            "resolution {w}x{h} is out of range (1 to {MAX_RESOLUTION} a side, at most {MAX_PIXELS} pixels)"
        ));
    }
    Ok(())
}

/// Checks samples per pixel: 1..=[`MAX_SPP`].
pub fn check_spp(spp: u32) -> std::result::Result<(), String> {
    if spp == 0 || spp > MAX_SPP {
        return Err(format!("spp {spp} is out of range (1 to {MAX_SPP})"));
    }
    Ok(())
}

impl Frames {
    /// The middle frame, the default reference frame for layering.
    pub fn middle(&self) -> i32 {
        ((i64::from(self.start) + i64::from(self.end)) / 2) as i32
    }
    /// How many frames the shot has.
    pub fn len(&self) -> u64 {
        (i64::from(self.end) - i64::from(self.start) + 1).max(0) as u64
    }
    /// Whether the shot has no frames (never true for a loaded shot).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// Whether `f` is in the shot.
    pub fn contains(&self, f: i32) -> bool {
        (self.start..=self.end).contains(&f)
    }
    /// Every shot frame.
    pub fn iter(&self) -> impl Iterator<Item = i32> {
        self.start..=self.end
    }
}

/// `[cache]`.
#[derive(Debug, Clone, Serialize)]
pub struct CacheRef {
    /// The cache file.
    pub path: PathBuf,
    /// cache frame = shot frame + frame_offset.
    pub(crate) frame_offset: i32,
    /// How raw data is imported and where the crowd stands (every other
    /// `[cache]` key; docs/shot.md).
    pub import: TabularSpec,
}

impl CacheRef {
    /// The cache frame that a shot frame reads.
    /// Loading checks this fits an i32 for every shot frame; other frames saturate.
    pub fn cache_frame(&self, shot_frame: i32) -> i32 {
        shot_frame.saturating_add(self.frame_offset)
    }
    /// The shot frame a cache frame lands on (saturating).
    pub fn shot_frame(&self, cache_frame: i32) -> i32 {
        cache_frame.saturating_sub(self.frame_offset)
    }
}

/// `[rigs.NAME]`.
#[derive(Debug, Clone)]
pub struct RigRef {
    /// Rig glTF.
    pub file: PathBuf,
    /// Scheme name -> weight.
    pub schemes: BTreeMap<String, f32>,
    /// Height jitter: scale drawn uniformly from 1 +/- this.
    pub height_jitter: f32,
    /// `kind`: `None` detects it from the file (slots: a slot rig; else a
    /// skin: skinned; else rigid).
    pub(crate) kind: Option<RigKind>,
    /// Options of a skinned or rigid character (defaults for slot rigs, which ignore them).
    pub skin: SkinOptions,
    /// Per-agent body proportions of a skinned or rigid character (`None`: every agent's body as modelled).
    pub proportions: Option<Proportions>,
}

/// `[rigs.NAME.proportions]`: seeded limb length and girth per joint
/// group, drawn for a fixed number of bodies the rig's agents share
/// (docs/wardrobes.md, "Body proportions").
#[derive(Debug, Clone, PartialEq)]
pub struct Proportions {
    /// How many bodies are drawn; each agent plays one (bodies share pose steps, so memory grows with this, not with agents).
    pub bodies: u16,
    /// Joints kept uniform, with every joint below them (the head rule).
    pub head: Vec<String>,
    /// The group whose length sets the stride (`None`: strides as modelled).
    pub legs: Option<String>,
    /// Joint groups by name.
    pub groups: BTreeMap<String, JointGroup>,
}

/// One joint group of [`Proportions`]: one draw per body for all its joints.
#[derive(Debug, Clone, PartialEq)]
pub struct JointGroup {
    /// The joints (named nodes of the rig file).
    pub joints: Vec<String>,
    /// Bone length drawn from 1 +/- this.
    pub length: f32,
    /// Thickness across the bone drawn from 1 +/- this.
    pub girth: f32,
}

impl Proportions {
    /// The largest length factor any body can draw (1 + the largest `length`).
    pub(crate) fn max_length(&self) -> f32 {
        1.0 + self.groups.values().map(|g| g.length).fold(0.0, f32::max)
    }
}

/// Bodies a rig draws unless `bodies` says otherwise.
pub const DEFAULT_BODIES: u16 = 8;
/// The most bodies a rig may draw (each is posed at every step its agents take).
pub const MAX_BODIES: u16 = 64;

/// What kind of character a rig file is.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub(crate) enum RigKind {
    /// Rigid nodes with part slots (the frankenbot).
    Slots,
    /// A skinned mesh on a skeleton.
    Skinned,
    /// Meshes on a node hierarchy with node animation, no skin (a
    /// multi-part character, a vehicle): each mesh moves with its node.
    Rigid,
}

impl RigKind {
    /// A character's `rigid` option for a declared kind (`None`: detected from the file).
    pub(crate) fn rigid(kind: Option<RigKind>) -> Option<bool> {
        match kind {
            Some(RigKind::Rigid) => Some(true),
            Some(RigKind::Skinned) => Some(false),
            _ => None,
        }
    }
}

/// A coordinate axis of a source file (it is the glTF reader's: `orientation` reads it).
pub use crate::scene::gltf::Axis;

/// Largest pose error of a skinned rig, metres, when the shot gives no
/// `pose_error_max` (docs/wardrobes.md, "Pose instancing").
pub const DEFAULT_POSE_ERROR_MAX: f32 = 0.02;

/// How a skinned or rigid character file maps onto throng's agents.
#[derive(Debug, Clone, PartialEq)]
pub struct SkinOptions {
    /// Whether the character is rigid (`kind = "rigid"`: meshes on animated
    /// nodes, no skin) or skinned; `None`: a skin in the file says skinned.
    pub rigid: Option<bool>,
    /// Cache cycle name -> clip name (or `#index` for unnamed clips).
    pub cycles: BTreeMap<String, String>,
    /// The file's up axis (default +y; a Z-up parent node in the file is respected anyway).
    pub up: Axis,
    /// The direction the character faces in the file (default +z).
    pub forward: Axis,
    /// Metres per file unit (0.01 for a file in centimetres).
    pub scale: f32,
    /// Joint whose horizontal travel is root motion (stripped; its Z travel is the stride).
    pub root: Option<String>,
    /// Metres per cycle by cache cycle name, overriding the root joint's travel.
    pub strides: BTreeMap<String, f32>,
    /// Pose instancing step in cycle frames; `None`: chosen per clip for `pose_error_max`.
    pub pose_step: Option<f32>,
    /// Largest pose error in metres on the rig's tallest agent (default
    /// [`DEFAULT_POSE_ERROR_MAX`]): the bound chosen steps hold.
    pub pose_error_max: f32,
    /// The largest height scale an agent of the rig gets (`1 + height_jitter`):
    /// pose error grows with it.
    pub max_height_scale: f32,
    /// Slot names for wardrobes (default: one per skinned mesh node of the file).
    pub slots: Option<Vec<String>>,
}

impl Default for SkinOptions {
    fn default() -> Self {
        SkinOptions {
            rigid: None,
            cycles: BTreeMap::new(),
            up: Axis::PosY,
            forward: Axis::PosZ,
            scale: 1.0,
            root: None,
            strides: BTreeMap::new(),
            pose_step: None,
            pose_error_max: DEFAULT_POSE_ERROR_MAX,
            max_height_scale: 1.0,
            slots: None,
        }
    }
}

/// `[set]`.
#[derive(Debug, Clone)]
pub(crate) struct SetRef {
    /// Environment glTF.
    pub(crate) file: PathBuf,
}

/// One camera keyframe.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct CameraKey {
    /// Shot frame.
    pub(crate) frame: f32,
    /// Camera position.
    pub(crate) position: [f32; 3],
    /// Point the camera looks at.
    pub(crate) aim: [f32; 3],
    /// Focal length in mm.
    pub(crate) focal_length: f32,
    /// Lens f-number for depth of field (with `focus_distance`); none: a pinhole.
    pub(crate) f_stop: Option<f32>,
    /// Distance in focus, scene units (metres), along the view axis.
    pub(crate) focus_distance: Option<f32>,
}

/// `[camera]`: keyframes, or a camera node in a glTF file.
#[derive(Debug, Clone)]
pub(crate) struct CameraSpec {
    /// Horizontal film back in mm.
    pub(crate) sensor_width: f32,
    /// Keyframes, sorted by frame.
    pub(crate) keys: Vec<CameraKey>,
    /// glTF file holding the camera node (instead of keys).
    pub(crate) gltf: Option<(PathBuf, String)>,
}

/// How agents are split into layers.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SplitMode {
    /// N layers of equal agent count, nearest first.
    Count,
    /// Distance cut-offs in metres.
    Cutoffs,
    /// A memory budget per layer.
    Budget,
}

/// An agent forced into a layer.
#[derive(Debug, Clone, Copy, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Pin {
    /// Agent id.
    pub agent: u32,
    /// Layer index, 0 = nearest.
    pub layer: usize,
}

/// `[layers]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LayerSettings {
    /// Split mode.
    #[serde(default = "default_split")]
    pub split: SplitMode,
    /// Layer count for `count`.
    #[serde(default = "default_layer_count")]
    pub count: usize,
    /// Cut-offs for `cutoffs`, metres, increasing.
    #[serde(default)]
    pub cutoffs: Vec<f32>,
    /// Budget for `budget`, e.g. "2.8GB".
    #[serde(default)]
    pub budget: Option<String>,
    /// Reference frame (default: the middle of the shot).
    #[serde(default)]
    pub ref_frame: Option<i32>,
    /// Pinned agents.
    #[serde(default)]
    pub pins: Vec<Pin>,
    /// Projected height in pixels below which an agent renders as proxy boxes.
    #[serde(default = "default_lod_px")]
    pub lod_full_min_px: f32,
    /// Other layers' agents appear in shadows and reflections as proxy boxes.
    #[serde(default)]
    pub proxy_shadow_casters: bool,
}

impl Default for LayerSettings {
    fn default() -> Self {
        LayerSettings {
            split: SplitMode::Count,
            count: default_layer_count(),
            cutoffs: Vec::new(),
            budget: None,
            ref_frame: None,
            pins: Vec::new(),
            lod_full_min_px: default_lod_px(),
            proxy_shadow_casters: false,
        }
    }
}

/// `[render]`.
#[derive(Debug, Clone, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RenderSettings {
    /// Width, height in pixels.
    #[serde(default = "default_resolution")]
    pub resolution: [u32; 2],
    /// Samples per pixel.
    #[serde(default = "default_spp")]
    pub spp: u32,
    /// Maximum path depth after the camera ray.
    #[serde(default = "default_bounces")]
    pub max_bounces: u32,
    /// Largest RGB component one indirect contribution may add to a sample
    /// (0: no clamp), like Cycles' and Arnold's indirect clamp: caustics of
    /// a small bright sun through glossy floors otherwise speckle.
    #[serde(default = "default_indirect_clamp")]
    pub indirect_clamp: f32,
    /// Shutter `[open, close]` in frames relative to the rendered frame
    /// (`[-0.25, 0.25]`: a 180-degree shutter centred on the frame). `None`
    /// (the default): no motion blur, every frame an instant.
    #[serde(default)]
    pub shutter: Option<[f32; 2]>,
    /// The colourspace the renderer works in (`rec709`, the default, or
    /// `acescg`); inputs are always read as linear Rec.709 (docs/render.md).
    #[serde(default)]
    pub working_colourspace: Colourspace,
    /// Passes beyond the beauty and data passes: light-path names,
    /// `light_groups`, `P` or `all` (scene::passes, docs/render.md).
    #[serde(default)]
    pub passes: Vec<String>,
    /// Adaptive sampling: each pixel between `min_spp` and `max_spp`
    /// samples, stopping once its error is below `threshold` (`spp` is then
    /// not used; docs/render.md, "Adaptive sampling").
    #[serde(default)]
    pub adaptive: Option<Adaptive>,
    /// Denoise every layer and pass with Open Image Denoise at this quality
    /// (`"high"`, `"balanced"`, `"fast"`); `None` (the default): not denoised
    /// (docs/render.md, "Denoising").
    #[serde(default)]
    pub denoise: Option<Denoise>,
    /// Deep output: with a `[render.deep]` table, every layer also as a deep
    /// scanline OpenEXR (docs/render.md, "Deep output"); `None` (the
    /// default): flat files only.
    #[serde(default)]
    pub deep: Option<Deep>,
}

/// `[render.deep]`: how deep samples are gathered and stored
/// (`render::deep`, `render::exr::deep`).
#[derive(Debug, Clone, PartialEq, Deserialize, serde::Serialize)]
#[serde(deny_unknown_fields)]
pub struct Deep {
    /// At most this many deep samples per pixel (1..=256).
    #[serde(default = "default_deep_max_samples")]
    pub max_samples: u32,
    /// Relative depth within which one object's camera samples merge.
    #[serde(default = "default_deep_tolerance")]
    pub tolerance: f32,
    /// `zips` (the default), `rle` or `none`: what OpenEXR allows for deep data.
    #[serde(default = "default_deep_compression")]
    pub compression: String,
}

fn default_deep_max_samples() -> u32 {
    Deep::DEFAULT_MAX_SAMPLES
}

fn default_deep_tolerance() -> f32 {
    Deep::DEFAULT_TOLERANCE
}

fn default_deep_compression() -> String {
    Deep::COMPRESSIONS[0].to_string()
}

impl Default for Deep {
    fn default() -> Self {
        Deep {
            max_samples: default_deep_max_samples(),
            tolerance: default_deep_tolerance(),
            compression: default_deep_compression(),
        }
    }
}

impl Deep {
    /// The largest per-pixel cap a shot may ask for: bounds the memory a
    /// deep image may take.
    pub const MAX_SAMPLES_LIMIT: u32 = 256;
    /// The default per-pixel cap: a 16-spp render seldom sees more distinct
    /// (object, depth) pairs in one pixel.
    pub const DEFAULT_MAX_SAMPLES: u32 = 16;
    /// The default depth tolerance (relative): one object's camera samples
    /// within 1 % of each other's depth are one deep sample.
    pub const DEFAULT_TOLERANCE: f32 = 0.01;
    /// The compressions deep files may have (OpenEXR allows NONE, RLE and
    /// ZIPS for deep data), the default first.
    pub const COMPRESSIONS: [&'static str; 3] = ["zips", "rle", "none"];

    /// Checks the keys, naming the one that is wrong (`render.deep.<key>`).
    pub fn check(&self) -> std::result::Result<(), (&'static str, String)> {
        const MAX_SAMPLES_LIMIT: u32 = Deep::MAX_SAMPLES_LIMIT;
        if !(1..=MAX_SAMPLES_LIMIT).contains(&self.max_samples) {
            return Err((
                "render.deep.max_samples",
                format!("must be 1..={MAX_SAMPLES_LIMIT}, got {}", self.max_samples),
            ));
        }
        if !(self.tolerance.is_finite() && (0.0..=1.0).contains(&self.tolerance)) {
            return Err((
                "render.deep.tolerance",
                format!("must be a number in 0..=1 (relative depth), got {}", self.tolerance),
            ));
        }
        if !Deep::COMPRESSIONS.contains(&self.compression.as_str()) {
            return Err((
                "render.deep.compression",
                format!(
                    "`{}` is not a compression deep files allow here; use one of: {}",
                    self.compression,
                    Deep::COMPRESSIONS.join(", ")
                ),
            ));
        }
        Ok(())
    }
}

/// `render.denoise`: Open Image Denoise's quality preset: `high` for
/// finals, `balanced` (faster, a little softer) for dailies, `fast` for
/// previews.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Denoise {
    /// OIDN's best (its default).
    #[default]
    High,
    /// Faster, a little softer.
    Balanced,
    /// Fastest.
    Fast,
}

impl Denoise {
    /// Every preset's name, as the shot and the command line spell it.
    pub const NAMES: [&'static str; 3] = ["high", "balanced", "fast"];

    /// The preset named `name`.
    pub fn parse(name: &str) -> Option<Denoise> {
        match name {
            "high" => Some(Denoise::High),
            "balanced" => Some(Denoise::Balanced),
            "fast" => Some(Denoise::Fast),
            _ => None,
        }
    }

    /// Its name.
    pub fn name(self) -> &'static str {
        match self {
            Denoise::High => "high",
            Denoise::Balanced => "balanced",
            Denoise::Fast => "fast",
        }
    }
}

/// `render.adaptive`: a pixel stops sampling once its estimated error
/// (`render::film`'s estimator) is below `threshold`, after at least
/// `min_spp` and at most `max_spp` samples.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Adaptive {
    /// Relative error at which a pixel stops (e.g. 0.01).
    pub threshold: f32,
    /// Samples every pixel takes.
    pub min_spp: u32,
    /// Samples no pixel exceeds.
    pub max_spp: u32,
}

impl Adaptive {
    /// Checks the keys, naming the one that is wrong (`render.adaptive.<key>`).
    pub fn check(&self) -> std::result::Result<(), (&'static str, String)> {
        if !(self.threshold.is_finite() && self.threshold > 0.0) {
            return Err(("render.adaptive.threshold", format!("must be a finite number > 0, got {}", self.threshold)));
        }
        check_spp(self.min_spp).map_err(|m| ("render.adaptive.min_spp", m))?;
        check_spp(self.max_spp).map_err(|m| ("render.adaptive.max_spp", m))?;
        if self.min_spp > self.max_spp {
            return Err((
                "render.adaptive.min_spp",
                format!("min_spp {} is above max_spp {}", self.min_spp, self.max_spp),
            ));
        }
        Ok(())
    }
}

impl Default for RenderSettings {
    fn default() -> Self {
        RenderSettings {
            resolution: default_resolution(),
            spp: default_spp(),
            max_bounces: default_bounces(),
            indirect_clamp: default_indirect_clamp(),
            shutter: None,
            working_colourspace: Colourspace::Rec709,
            passes: Vec::new(),
            adaptive: None,
            denoise: None,
            deep: None,
        }
    }
}

pub use crate::scene::Colourspace;

/// Checks a shutter `[open, close]` (frames relative to the frame): both
/// finite, within one frame of it (`-1..=1`), open before close, and at most
/// one frame long (a 360-degree shutter).
pub fn check_shutter(shutter: [f32; 2]) -> std::result::Result<(), String> {
    let [open, close] = shutter;
    if !(open.is_finite() && close.is_finite()) {
        return Err(format!("shutter [{open}, {close}] is not finite"));
    }
    if !(-1.0..=1.0).contains(&open) || !(-1.0..=1.0).contains(&close) {
        return Err(format!("shutter [{open}, {close}] must lie within one frame of the frame (-1 to 1)"));
    }
    if open >= close {
        return Err(format!("shutter open {open} must be before close {close} (frames relative to the frame)"));
    }
    if close - open > 1.0 {
        return Err(format!("shutter [{open}, {close}] is longer than one frame (360 degrees)"));
    }
    Ok(())
}

fn default_fps() -> f32 {
    24.0
}
fn default_split() -> SplitMode {
    SplitMode::Count
}
fn default_layer_count() -> usize {
    3
}
fn default_lod_px() -> f32 {
    40.0
}
fn default_resolution() -> [u32; 2] {
    [960, 540]
}
fn default_spp() -> u32 {
    16
}
fn default_indirect_clamp() -> f32 {
    10.0
}

fn default_bounces() -> u32 {
    4
}
fn default_jitter() -> f32 {
    0.1
}
fn default_sensor() -> f32 {
    36.0
}

// ---- the file as written (paths still relative, with spans for errors) ----

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ShotFile {
    version: Spanned<u32>,
    name: String,
    #[serde(default)]
    seed: u64,
    #[serde(default)]
    wardrobes: Vec<Spanned<PathBuf>>,
    #[serde(default)]
    removed: Vec<u32>,
    #[serde(default)]
    culled_cycles: Vec<String>,
    #[serde(default)]
    no_scale_cycles: Vec<String>,
    #[serde(default)]
    exclude_parts: Vec<String>,
    pose_error_max: Option<Spanned<f32>>,
    frames: Spanned<Frames>,
    cache: CacheTable,
    #[serde(default)]
    rigs: BTreeMap<String, RigFile>,
    set: Option<SetFile>,
    camera: CameraFile,
    #[serde(default)]
    lights: LightsFile,
    atmosphere: Option<AtmosphereFile>,
    #[serde(default)]
    layers: LayerSettings,
    #[serde(default)]
    render: RenderSettings,
}

/// `[atmosphere]` as written (docs/shot.md, "Atmosphere").
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct AtmosphereFile {
    density: f32,
    #[serde(default = "white")]
    color: [f32; 3],
    #[serde(default)]
    anisotropy: f32,
    height: Option<f32>,
    #[serde(default)]
    mode: AtmosphereMode,
    falloff: Option<f32>,
    #[serde(default)]
    base: f32,
    #[serde(default)]
    start: f32,
}

fn white() -> [f32; 3] {
    [1.0; 3]
}

impl AtmosphereFile {
    /// The checked medium; a bad value names its key (`atmosphere.<key>`).
    fn check(&self, path: &Path) -> Result<Atmosphere> {
        let a = Atmosphere {
            density: self.density,
            albedo: Vec3::from(self.color),
            anisotropy: self.anisotropy,
            top: self.height.unwrap_or(f32::INFINITY),
            mode: self.mode,
            falloff: self.falloff.unwrap_or(f32::INFINITY),
            base: self.base,
            start: self.start,
        };
        a.check().map_err(|(key, m)| Error::invalid(path, m).field(format!("atmosphere.{key}")))?;
        Ok(a)
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RigFile {
    file: Spanned<PathBuf>,
    #[serde(default)]
    schemes: BTreeMap<String, f32>,
    height_jitter: Option<Spanned<f32>>,
    kind: Option<RigKind>,
    #[serde(default)]
    cycles: BTreeMap<String, String>,
    up: Option<Axis>,
    forward: Option<Axis>,
    scale: Option<Spanned<f32>>,
    root: Option<String>,
    #[serde(default)]
    strides: BTreeMap<String, f32>,
    pose_step: Option<Spanned<f32>>,
    pose_error_max: Option<Spanned<f32>>,
    slots: Option<Vec<String>>,
    proportions: Option<Spanned<ProportionsFile>>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ProportionsFile {
    bodies: Option<i64>,
    head: Option<Vec<String>>,
    legs: Option<String>,
    #[serde(default)]
    groups: BTreeMap<String, JointGroupFile>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct JointGroupFile {
    joints: Vec<String>,
    #[serde(default)]
    length: f32,
    #[serde(default)]
    girth: f32,
}

impl ProportionsFile {
    /// `[rigs.NAME.proportions]` -> checked proportions (joint names are checked against the file when the rig loads).
    fn check(&self, name: &str, span: std::ops::Range<usize>, cx: &Context) -> Result<Proportions> {
        let key = |k: &str| format!("rigs.{name}.proportions.{k}");
        let bodies = self.bodies.unwrap_or(DEFAULT_BODIES as i64);
        if !(1..=MAX_BODIES as i64).contains(&bodies) {
            return Err(cx.at(span, &key("bodies"), format!("must be 1 to {MAX_BODIES}, got {bodies}")));
        }
        let Some(head) = self.head.clone() else {
            return Err(cx.at(
                span,
                &key("head"),
                "give the head's joints, which proportions never stretch (`head = []` for a character without one)"
                    .into(),
            ));
        };
        if self.groups.is_empty() {
            return Err(cx.at(span, &key("groups"), "give at least one joint group".into()));
        }
        let mut groups = BTreeMap::new();
        let mut seen: BTreeMap<&str, &str> = BTreeMap::new();
        for (g, group) in &self.groups {
            if group.joints.is_empty() {
                return Err(cx.at(span.clone(), &key(&format!("groups.{g}.joints")), "give at least one joint".into()));
            }
            for (f, v) in [("length", group.length), ("girth", group.girth)] {
                if !(0.0..0.5).contains(&v) {
                    return Err(cx.at(
                        span.clone(),
                        &key(&format!("groups.{g}.{f}")),
                        format!("must be a fraction in [0, 0.5), got {v}"),
                    ));
                }
            }
            for (i, j) in group.joints.iter().enumerate() {
                if let Some(other) = seen.insert(j, g) {
                    return Err(cx.at(
                        span.clone(),
                        &key(&format!("groups.{g}.joints[{i}]")),
                        format!("joint `{j}` is already in group `{other}`: a joint takes one group's proportions"),
                    ));
                }
            }
            groups.insert(
                g.clone(),
                JointGroup { joints: group.joints.clone(), length: group.length, girth: group.girth },
            );
        }
        if let Some(legs) = &self.legs {
            if !groups.contains_key(legs) {
                return Err(cx.at(
                    span,
                    &key("legs"),
                    format!("names no group (groups: {})", groups.keys().cloned().collect::<Vec<_>>().join(", ")),
                ));
            }
        }
        Ok(Proportions { bodies: bodies as u16, head, legs: self.legs.clone(), groups })
    }
}

impl RigFile {
    /// Whether any skinned-character key is set.
    fn has_skin_keys(&self) -> bool {
        !self.cycles.is_empty()
            || self.up.is_some()
            || self.forward.is_some()
            || self.scale.is_some()
            || self.root.is_some()
            || !self.strides.is_empty()
            || self.pose_step.is_some()
            || self.pose_error_max.is_some()
            || self.slots.is_some()
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SetFile {
    file: Spanned<PathBuf>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CameraFile {
    #[serde(default = "default_sensor")]
    sensor_width: f32,
    #[serde(default)]
    keys: Vec<CameraKey>,
    gltf: Option<Spanned<PathBuf>>,
    node: Option<String>,
}

// ---- the file as written -> checked, one section at a time ----

/// What every section's check needs: the file (for messages and lines) and
/// the folder relative paths start from.
struct Context<'a> {
    path: &'a Path,
    text: &'a str,
    base: PathBuf,
}

impl Context<'_> {
    /// An error at a span of the text, naming its key.
    fn at(&self, span: std::ops::Range<usize>, key: &str, msg: String) -> Error {
        Error::invalid(self.path, msg).line(line_of(self.text, span.start)).field(key)
    }

    /// A referenced file: a path that does not exist is an error naming its key.
    fn existing(&self, p: &Spanned<PathBuf>, key: &str) -> Result<PathBuf> {
        let full = self.base.join(p.get_ref());
        if full.exists() {
            crate::error::check_readable_file(&full).map_err(|e| e.field(key))?;
            Ok(full)
        } else {
            Err(self.at(p.span(), key, format!("file not found: {}", full.display())))
        }
    }
}

/// `[frames]`: a forward range of at most [`MAX_FRAMES`] at a positive rate.
fn check_frames(raw: &Spanned<Frames>, cx: &Context) -> Result<Frames> {
    let frames = *raw.get_ref();
    if frames.end < frames.start {
        return Err(cx.at(raw.span(), "frames", format!("end {} is before start {}", frames.end, frames.start)));
    }
    if !(frames.fps > 0.0 && frames.fps.is_finite()) {
        return Err(cx.at(raw.span(), "frames.fps", format!("fps must be positive, got {}", frames.fps)));
    }
    if frames.len() > MAX_FRAMES {
        return Err(cx.at(
            raw.span(),
            "frames",
            format!("{} frames is more than a shot may hold ({MAX_FRAMES})", frames.len()),
        ));
    }
    Ok(frames)
}

/// `[cache]`: the offset fits every shot frame; a layout's keys and the
/// placement are checked here, so a bad key names its line in the shot
/// (gaits come when the cache is opened, in casting).
fn check_cache(raw: &CacheTable, frames: &Frames, cx: &Context) -> Result<CacheRef> {
    let path = cx.path;
    let offset = raw.frame_offset;
    for f in [frames.start, frames.end] {
        if f.checked_add(offset).is_none() {
            return Err(Error::invalid(
                path,
                format!("shot frame {f} + frame_offset {offset} is not a representable frame number (32-bit)"),
            )
            .field("cache.frame_offset"));
        }
    }
    let import = raw.keys();
    let key_err = |(k, m): (String, String)| Error::invalid(path, m).field(format!("cache.{k}"));
    if import.describes_layout() {
        TabularOptions::resolve(&import, frames.fps).map_err(key_err)?;
    }
    import.placement().check_key().map_err(key_err)?;
    Ok(CacheRef { path: cx.existing(&raw.path, "cache.path")?, frame_offset: offset, import })
}

/// A `pose_error_max` (metres): finite and > 0, else an error naming `key`.
fn check_pose_error_max(raw: &Spanned<f32>, key: &str, cx: &Context) -> Result<f32> {
    let m = *raw.get_ref();
    if m > 0.0 && m.is_finite() {
        Ok(m)
    } else {
        Err(cx.at(raw.span(), key, format!("must be a positive number of metres, got {m}")))
    }
}

/// The first bad value among a skinned rig's `scale` and `strides`, as
/// `[rigs.NAME]` and a sim scene's `[rigs]` table both take them: (the key
/// under the rig, the message).
pub(crate) fn skin_value_problem(scale: f32, strides: &BTreeMap<String, f32>) -> Option<(String, String)> {
    if !(scale > 0.0 && scale.is_finite()) {
        return Some(("scale".into(), format!("must be a positive number, got {scale}")));
    }
    let (cycle, s) = strides.iter().find(|(_, s)| !(**s >= 0.0 && s.is_finite()))?;
    Some((format!("strides.{cycle}"), format!("stride must be >= 0 metres, got {s}")))
}

impl RigFile {
    /// `[rigs.NAME]` -> a checked rig; `pose_error_max` is the shot's (checked).
    fn check(&self, name: &str, cx: &Context, pose_error_max: f32) -> Result<RigRef> {
        let rig = self;
        // A UsdSkel crowd's scale is the crowd department's: no jitter unless asked (docs/wardrobes.md).
        let usd = crate::cache::Format::of(rig.file.get_ref()).ok() == Some(crate::cache::Format::Usd);
        let jitter = rig.height_jitter.as_ref().map_or(if usd { 0.0 } else { default_jitter() }, |j| *j.get_ref());
        if !(0.0..1.0).contains(&jitter) {
            return Err(cx.at(
                rig.height_jitter.as_ref().map_or(rig.file.span(), |j| j.span()),
                &format!("rigs.{name}.height_jitter"),
                format!("must be in [0, 1), got {jitter}"),
            ));
        }
        for (scheme, w) in &rig.schemes {
            if !(*w >= 0.0 && w.is_finite()) {
                return Err(cx.at(
                    rig.file.span(),
                    &format!("rigs.{name}.schemes.{scheme}"),
                    format!("scheme weight must be >= 0, got {w}"),
                ));
            }
        }
        if rig.kind == Some(RigKind::Slots) && rig.has_skin_keys() {
            return Err(cx.at(
                rig.file.span(),
                &format!("rigs.{name}.kind"),
                "cycles, up, forward, scale, root, strides, pose_step, pose_error_max and slots are for `kind = \"skinned\"` \
                 and `kind = \"rigid\"` rigs"
                    .into(),
            ));
        }
        let defaults = SkinOptions::default();
        let scale = rig.scale.as_ref().map_or(defaults.scale, |s| *s.get_ref());
        if let Some((key, msg)) = skin_value_problem(scale, &rig.strides) {
            let span = match (key.as_str(), &rig.scale) {
                ("scale", Some(s)) => s.span(),
                _ => rig.file.span(),
            };
            return Err(cx.at(span, &format!("rigs.{name}.{key}"), msg));
        }
        let pose_step = rig.pose_step.as_ref().map(|s| *s.get_ref());
        if let (Some(s), Some(spanned)) = (pose_step, &rig.pose_step) {
            if !(s > 0.0 && s.is_finite()) {
                return Err(cx.at(
                    spanned.span(),
                    &format!("rigs.{name}.pose_step"),
                    format!("must be a positive number of frames, got {s}"),
                ));
            }
        }
        let pose_error_max = match &rig.pose_error_max {
            Some(spanned) => check_pose_error_max(spanned, &format!("rigs.{name}.pose_error_max"), cx)?,
            None => pose_error_max,
        };
        if rig.slots.as_ref().is_some_and(|s| s.is_empty()) {
            return Err(cx.at(rig.file.span(), &format!("rigs.{name}.slots"), "give at least one slot".into()));
        }
        let proportions = match &rig.proportions {
            Some(p) if rig.kind == Some(RigKind::Slots) => {
                return Err(cx.at(
                    p.span(),
                    &format!("rigs.{name}.proportions"),
                    "proportions are for skinned and rigid characters; a slot rig's parts are fitted to its slots"
                        .into(),
                ))
            }
            Some(p) => Some(p.get_ref().check(name, p.span(), cx)?),
            None => None,
        };
        Ok(RigRef {
            file: cx.existing(&rig.file, &format!("rigs.{name}.file"))?,
            schemes: rig.schemes.clone(),
            height_jitter: jitter,
            kind: rig.kind,
            skin: SkinOptions {
                rigid: RigKind::rigid(rig.kind),
                cycles: rig.cycles.clone(),
                up: rig.up.unwrap_or(defaults.up),
                forward: rig.forward.unwrap_or(defaults.forward),
                scale,
                root: rig.root.clone(),
                strides: rig.strides.clone(),
                pose_step,
                pose_error_max,
                // The tallest agent: the largest height scale on the longest body.
                max_height_scale: (1.0 + jitter) * proportions.as_ref().map_or(1.0, Proportions::max_length),
                slots: rig.slots.clone(),
            },
            proportions,
        })
    }
}

impl CameraFile {
    /// `[camera]` -> keys sorted by frame (each finite, one per frame), or a glTF node.
    fn check(&self, cx: &Context) -> Result<CameraSpec> {
        let path = cx.path;
        // Checked in file order so the error names the key as written.
        for (i, k) in self.keys.iter().enumerate() {
            let named = [("frame", &[k.frame][..]), ("position", &k.position[..]), ("aim", &k.aim[..])];
            for (key, values) in named {
                if let Some((c, v)) = values.iter().enumerate().find(|(_, v)| !v.is_finite()) {
                    let (field, what) = match values.len() {
                        1 => (format!("camera.keys[{i}].{key}"), key.to_string()),
                        _ => (format!("camera.keys[{i}].{key}[{c}]"), format!("{key} {}", ["x", "y", "z"][c])),
                    };
                    let msg = format!(
                        "camera key {} (frame {}): {what} is {v}; every value must be a finite number",
                        i + 1,
                        k.frame
                    );
                    return Err(Error::invalid(path, msg).field(field));
                }
            }
        }
        let mut keys = self.keys.clone();
        keys.sort_by(|a, b| a.frame.total_cmp(&b.frame));
        let gltf = match (&self.gltf, &self.node) {
            (Some(g), Some(node)) => Some((cx.existing(g, "camera.gltf")?, node.clone())),
            (Some(g), None) => return Err(cx.at(g.span(), "camera.node", "`camera.gltf` needs `camera.node`".into())),
            (None, Some(_)) => {
                return Err(Error::invalid(path, "`camera.node` needs `camera.gltf`").field("camera.node"))
            }
            (None, None) => None,
        };
        if keys.is_empty() && gltf.is_none() {
            return Err(Error::invalid(path, "the camera needs `keys` or `gltf` + `node`").field("camera"));
        }
        if let Some(w) = keys.windows(2).find(|w| w[0].frame == w[1].frame) {
            return Err(Error::invalid(path, format!("two camera keys at frame {}", w[0].frame)).field("camera.keys"));
        }
        for k in &keys {
            if !(k.focal_length > 0.0 && k.focal_length.is_finite()) || Vec3::from(k.position) == Vec3::from(k.aim) {
                return Err(Error::invalid(
                    path,
                    format!(
                        "camera key at frame {}: focal length must be > 0 and aim must differ from position",
                        k.frame
                    ),
                )
                .field("camera.keys"));
            }
        }
        // Depth of field is keyed like the rest: every key has both, or none does.
        let lens = keys.iter().filter(|k| k.f_stop.is_some() || k.focus_distance.is_some()).count();
        for k in &keys {
            let at = |m: String| Error::invalid(path, format!("camera key at frame {}: {m}", k.frame));
            if let Some(n) = k.f_stop.filter(|n| !(*n > 0.0 && n.is_finite())) {
                return Err(at(format!("f_stop must be finite and > 0, got {n}")).field("camera.keys.f_stop"));
            }
            if let Some(d) = k.focus_distance.filter(|d| !(*d > 0.0 && d.is_finite())) {
                return Err(
                    at(format!("focus_distance must be finite and > 0, got {d}")).field("camera.keys.focus_distance")
                );
            }
        }
        if let Some(k) = keys.iter().find(|k| lens > 0 && (k.f_stop.is_none() || k.focus_distance.is_none())) {
            let msg = "depth of field needs `f_stop` and `focus_distance` on every key, or on none";
            return Err(
                Error::invalid(path, format!("camera key at frame {}: {msg}", k.frame)).field("camera.keys.f_stop")
            );
        }
        if !(self.sensor_width > 0.0) {
            return Err(Error::invalid(path, "must be > 0").field("camera.sensor_width"));
        }
        Ok(CameraSpec { sensor_width: self.sensor_width, keys, gltf })
    }
}

/// `[layers]`: a count of at least 1, increasing cut-offs, a readable budget.
fn check_layers(layers: &LayerSettings, path: &Path) -> Result<()> {
    if layers.split == SplitMode::Count && layers.count == 0 {
        return Err(Error::invalid(path, "must be at least 1").field("layers.count"));
    }
    if layers.cutoffs.windows(2).any(|w| !(w[0] < w[1])) {
        return Err(Error::invalid(path, "cut-offs must increase").field("layers.cutoffs"));
    }
    if let Some(b) = &layers.budget {
        parse_bytes(b).map_err(|m| Error::invalid(path, m).field("layers.budget"))?;
    }
    if !(layers.lod_full_min_px >= 0.0 && layers.lod_full_min_px.is_finite()) {
        return Err(Error::invalid(
            path,
            format!("must be a finite number of pixels >= 0, got {}", layers.lod_full_min_px),
        )
        .field("layers.lod_full_min_px"));
    }
    Ok(())
}

/// `[render]`: bounces, resolution, samples and shutter in range.
fn check_render(render: &RenderSettings, path: &Path) -> Result<()> {
    if render.max_bounces > MAX_BOUNCES {
        return Err(Error::invalid(path, format!("at most {MAX_BOUNCES} bounces, got {}", render.max_bounces))
            .field("render.max_bounces"));
    }
    check_resolution(render.resolution[0], render.resolution[1])
        .map_err(|m| Error::invalid(path, m).field("render.resolution"))?;
    check_spp(render.spp).map_err(|m| Error::invalid(path, m).field("render.spp"))?;
    if !(render.indirect_clamp.is_finite() && render.indirect_clamp >= 0.0) {
        return Err(Error::invalid(
            path,
            format!("must be a finite number >= 0 (0: no clamp), got {}", render.indirect_clamp),
        )
        .field("render.indirect_clamp"));
    }
    if let Some(shutter) = render.shutter {
        check_shutter(shutter).map_err(|m| Error::invalid(path, m).field("render.shutter"))?;
    }
    crate::scene::passes::PassSet::parse(&render.passes, "render.passes")
        .map_err(|e| Error::invalid(path, e.to_string()).field("render.passes"))?;
    if let Some(a) = &render.adaptive {
        a.check().map_err(|(key, m)| Error::invalid(path, m).field(key))?;
    }
    if let Some(d) = &render.deep {
        d.check().map_err(|(key, m)| Error::invalid(path, m).field(key))?;
    }
    Ok(())
}

impl Shot {
    /// Whether the shot has air that changes anything (`[atmosphere]` with
    /// a density above zero): what its render traces and its air passes.
    pub fn hazy(&self) -> bool {
        self.atmosphere.is_some_and(|a| a.is_active())
    }

    /// Reads and validates a shot file.
    pub fn load(path: &Path) -> Result<Shot> {
        crate::error::check_readable_file(path)?;
        let text = std::fs::read_to_string(path).at(path)?;
        Shot::parse(&text, path)
    }

    /// Every file the shot itself names, as its key names it: the shot,
    /// the cache, each rig, each wardrobe, the set, the camera's glTF and
    /// the dome (parts and textures come from the wardrobes:
    /// `ShotCrowd::input_files`). What an output must never be.
    pub fn input_files(&self) -> Vec<(String, PathBuf)> {
        let mut out = vec![("shot".to_string(), self.path.clone()), ("cache.path".into(), self.cache.path.clone())];
        out.extend(self.rigs.iter().map(|(name, r)| (format!("rigs.{name}.file"), r.file.clone())));
        out.extend(self.wardrobes.iter().map(|w| ("wardrobe".to_string(), w.clone())));
        if let Some(s) = &self.set {
            out.push(("set.file".into(), s.file.clone()));
        }
        if let Some((file, _)) = &self.camera.gltf {
            out.push(("camera.gltf".into(), file.clone()));
        }
        if let Some(d) = &self.lights.dome {
            out.push(("lights.dome.file".into(), d.file.clone()));
        }
        out
    }

    /// Parses shot text; `path` names the file in errors and anchors relative paths.
    pub fn parse(text: &str, path: &Path) -> Result<Shot> {
        let file: ShotFile = toml::from_str(text).map_err(|e| Error::toml(path, text, e))?;
        let cx = Context { path, text, base: path.parent().unwrap_or(Path::new("")).to_path_buf() };
        check_shot_name(&file.name).map_err(|m| Error::invalid(path, m).field("name"))?;
        if *file.version.get_ref() != SHOT_VERSION {
            return Err(cx.at(
                file.version.span(),
                "version",
                format!(
                    "unsupported shot version {} (this throng reads version {SHOT_VERSION})",
                    file.version.get_ref()
                ),
            ));
        }
        let frames = check_frames(&file.frames, &cx)?;
        let cache = check_cache(&file.cache, &frames, &cx)?;
        let wardrobes = file.wardrobes.iter().map(|w| cx.existing(w, "wardrobes")).collect::<Result<Vec<_>>>()?;
        let pose_error_max = match &file.pose_error_max {
            Some(raw) => check_pose_error_max(raw, "pose_error_max", &cx)?,
            None => DEFAULT_POSE_ERROR_MAX,
        };
        let mut rigs = BTreeMap::new();
        for (name, rig) in &file.rigs {
            rigs.insert(name.clone(), rig.check(name, &cx, pose_error_max)?);
        }
        let set = match &file.set {
            Some(s) => Some(SetRef { file: cx.existing(&s.file, "set.file")? }),
            None => None,
        };
        let camera = file.camera.check(&cx)?;
        let lights = file.lights.check(&cx)?;
        let atmosphere = file.atmosphere.as_ref().map(|a| a.check(path)).transpose()?;
        check_layers(&file.layers, path)?;
        check_render(&file.render, path)?;
        Ok(Shot {
            path: path.to_path_buf(),
            name: file.name,
            seed: file.seed,
            frames,
            cache,
            wardrobes,
            rigs,
            set,
            camera,
            lights,
            atmosphere,
            layers: file.layers,
            render: file.render,
            removed: file.removed,
            culled_cycles: file.culled_cycles,
            no_scale_cycles: file.no_scale_cycles,
            exclude_parts: file.exclude_parts,
        })
    }

    /// Image aspect ratio (width / height).
    pub fn aspect(&self) -> f32 {
        self.render.resolution[0] as f32 / self.render.resolution[1] as f32
    }

    /// The keyframed camera at a (fractional) shot frame: position, aim and
    /// focal length interpolated linearly, held before the first and after
    /// the last key. `None` when the camera comes from a glTF node.
    pub fn keyed_camera(&self, frame: f32) -> Option<Camera> {
        let keys = &self.camera.keys;
        let first = keys.first()?;
        let last = keys.last()?;
        // f-stop and focus (0 without depth of field), interpolated like the rest.
        let lens = |k: &CameraKey| (k.f_stop.unwrap_or(0.0), k.focus_distance.unwrap_or(0.0));
        let (pos, aim, focal, (f_stop, focus)) = if frame <= first.frame {
            (Vec3::from(first.position), Vec3::from(first.aim), first.focal_length, lens(first))
        } else if frame >= last.frame {
            (Vec3::from(last.position), Vec3::from(last.aim), last.focal_length, lens(last))
        } else {
            let i = keys.windows(2).position(|w| frame >= w[0].frame && frame <= w[1].frame).unwrap_or(0);
            let (a, b) = (&keys[i], &keys[i + 1]);
            let t = if b.frame > a.frame { (frame - a.frame) / (b.frame - a.frame) } else { 0.0 };
            let ((na, da), (nb, db)) = (lens(a), lens(b));
            (
                Vec3::from(a.position).lerp(Vec3::from(b.position), t),
                Vec3::from(a.aim).lerp(Vec3::from(b.aim), t),
                a.focal_length + (b.focal_length - a.focal_length) * t,
                (na + (nb - na) * t, da + (db - da) * t),
            )
        };
        let sensor_height = self.camera.sensor_width / self.aspect();
        let yfov = 2.0 * (sensor_height * 0.5 / focal).atan();
        let mut camera = Camera::pinhole(look_at(pos, aim), yfov);
        if f_stop > 0.0 {
            // Aperture radius: focal length (mm -> m) over twice the f-number.
            camera.aperture = focal * 1e-3 / (2.0 * f_stop);
            camera.focus_distance = focus;
        }
        Some(camera)
    }

    /// The sun, in scene units.
    pub fn sun(&self) -> Option<Sun> {
        self.lights.sun()
    }

    /// The uniform sky.
    pub fn sky(&self) -> Sky {
        self.lights.sky()
    }

    /// Whether an agent on `cycle` is never height-scaled.
    pub(crate) fn is_no_scale_cycle(&self, cycle: &str) -> bool {
        self.no_scale_cycles.iter().any(|c| c == cycle)
    }
}

/// Camera to world for a camera at `eye` looking at `aim`, +Y up; the camera
/// looks down its local -Z (glTF convention).
pub fn look_at(eye: Vec3, aim: Vec3) -> Affine3A {
    let forward = (aim - eye).normalize();
    let up = if forward.y.abs() > 0.999 { Vec3::Z } else { Vec3::Y };
    let right = forward.cross(up).normalize();
    let true_up = right.cross(forward);
    Affine3A::from_cols(right.into(), true_up.into(), (-forward).into(), eye.into())
}

/// Parses a byte size such as `2.8GB`, `512MiB`, `1e9` (decimal units are
/// powers of 1000, binary units powers of 1024).
pub fn parse_bytes(s: &str) -> std::result::Result<u64, String> {
    let t = s.trim();
    let split = t.find(|c: char| c.is_ascii_alphabetic()).unwrap_or(t.len());
    let (num, unit) = t.split_at(split);
    let n: f64 = num.trim().parse().map_err(|_| format!("not a size: `{s}` (use e.g. 2.8GB or 512MiB)"))?;
    let mult = match unit.trim().to_ascii_lowercase().as_str() {
        "" | "b" => 1.0,
        "kb" | "k" => 1e3,
        "mb" | "m" => 1e6,
        "gb" | "g" => 1e9,
        "tb" | "t" => 1e12,
        "kib" => 1024.0,
        "mib" => 1024.0 * 1024.0,
        "gib" => 1024.0 * 1024.0 * 1024.0,
        other => return Err(format!("unknown size unit `{other}` in `{s}` (B, KB, MB, GB, KiB, MiB, GiB)")),
    };
    if !(n >= 0.0 && n.is_finite()) {
        return Err(format!("size must be positive: `{s}`"));
    }
    Ok((n * mult).round() as u64)
}

/// Parses an OpenCue-style frame list: `1001-1010`, `1001-1100x2`, `1001,1005`,
/// or any comma-separated mix. Returns sorted, de-duplicated frames.
pub fn parse_frame_list(s: &str) -> std::result::Result<Vec<i32>, String> {
    let mut frames = Vec::new();
    for item in s.split(',').map(str::trim).filter(|i| !i.is_empty()) {
        let bad = || format!("bad frame range `{item}` (use 1001-1010, 1001-1100x2 or 1001,1005)");
        let (range, step) = match item.split_once('x') {
            Some((r, st)) => (r, st.parse::<i32>().map_err(|_| bad())?),
            None => (item, 1),
        };
        if step <= 0 {
            return Err(bad());
        }
        // A leading '-' is a negative frame, not a range separator.
        let dash = range.char_indices().skip(1).find(|&(_, c)| c == '-').map(|(i, _)| i);
        let (a, b) = match dash {
            Some(i) => {
                (range[..i].parse::<i32>().map_err(|_| bad())?, range[i + 1..].parse::<i32>().map_err(|_| bad())?)
            }
            None => {
                let f = range.parse::<i32>().map_err(|_| bad())?;
                (f, f)
            }
        };
        if b < a {
            return Err(bad());
        }
        // Counted before any allocation: a list may hold at most MAX_FRAMES frames.
        let count = (i64::from(b) - i64::from(a)) as u64 / step as u64 + 1;
        if frames.len() as u64 + count > MAX_FRAMES {
            return Err(format!("frame list `{s}` holds more than {MAX_FRAMES} frames"));
        }
        frames.extend((a..=b).step_by(step as usize));
    }
    if frames.is_empty() {
        return Err(format!("no frames in `{s}`"));
    }
    frames.sort_unstable();
    frames.dedup();
    Ok(frames)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cache::tabular::Preset;

    #[test]
    fn frame_lists() {
        assert_eq!(parse_frame_list("1001-1003").unwrap(), vec![1001, 1002, 1003]);
        assert_eq!(parse_frame_list("1001-1007x3,1002").unwrap(), vec![1001, 1002, 1004, 1007]);
        assert_eq!(parse_frame_list("-2-1").unwrap(), vec![-2, -1, 0, 1]);
        assert!(parse_frame_list("10-5").is_err());
        assert!(parse_frame_list("abc").is_err());
        // Runaway lists are refused before allocating.
        assert!(parse_frame_list("-2147483648-2147483647").is_err());
        assert!(parse_frame_list("1-100000").is_ok());
        assert!(parse_frame_list("1-100000,200000").is_err());
    }

    #[test]
    fn byte_sizes() {
        assert_eq!(parse_bytes("2.8GB").unwrap(), 2_800_000_000);
        assert_eq!(parse_bytes("1MiB").unwrap(), 1 << 20);
        assert!(parse_bytes("3 parsecs").is_err());
    }

    fn cx(text: &str) -> Context<'_> {
        Context { path: Path::new("s.toml"), text, base: PathBuf::from(env!("CARGO_MANIFEST_DIR")) }
    }

    fn err<T: std::fmt::Debug>(r: Result<T>) -> String {
        r.unwrap_err().to_string()
    }

    #[derive(Deserialize)]
    struct FramesOnly {
        frames: Spanned<Frames>,
    }

    #[test]
    fn frames_section_is_a_forward_range_at_a_positive_rate() {
        let text = "[frames]\nstart = 5\nend = 1\n";
        let f: FramesOnly = toml::from_str(text).unwrap();
        assert!(err(check_frames(&f.frames, &cx(text))).contains("end 1 is before start 5"));
        let text = "[frames]\nstart = 1\nend = 5\nfps = 0.0\n";
        let f: FramesOnly = toml::from_str(text).unwrap();
        assert!(err(check_frames(&f.frames, &cx(text))).contains("frames.fps"));
        let text = "[frames]\nstart = 1\nend = 5\n";
        let f: FramesOnly = toml::from_str(text).unwrap();
        assert_eq!(check_frames(&f.frames, &cx(text)).unwrap().len(), 5);
    }

    #[test]
    fn cache_section_checks_offset_layout_and_placement() {
        let frames = Frames { start: 1, end: 10, fps: 24.0, outside_cache: OutsideCache::Error };
        let check = |text: &str| {
            let raw: CacheTable = toml::from_str(text).unwrap();
            check_cache(&raw, &frames, &cx(text))
        };
        assert!(err(check("path = \"Cargo.toml\"\nframe_offset = 2147483647")).contains("cache.frame_offset"));
        let e = err(check("path = \"Cargo.toml\"\nunits = \"cm\""));
        assert!(e.contains("cache.columns") && e.contains("no `id` column"), "{e}");
        assert!(err(check("path = \"Cargo.toml\"\nscale = 0.0")).contains("cache.scale"));
        assert!(err(check("path = \"nope.crowd\"")).contains("file not found"));
        let ok = check("path = \"Cargo.toml\"\nframe_offset = -1\npreset = \"eth\"\nrotate = 90.0").unwrap();
        assert_eq!((ok.cache_frame(1), ok.import.preset), (0, Some(Preset::Eth)));
        assert_eq!(ok.import.placement().rotate, 90.0);
    }

    #[test]
    fn rig_section_checks_jitter_kind_and_skin_keys() {
        let check = |text: &str| toml::from_str::<RigFile>(text).unwrap().check("r", &cx(text), DEFAULT_POSE_ERROR_MAX);
        let e = err(check("file = \"Cargo.toml\"\nheight_jitter = 1.5"));
        assert!(e.contains("s.toml:2") && e.contains("rigs.r.height_jitter"), "{e}");
        assert!(err(check("file = \"Cargo.toml\"\nkind = \"slots\"\nroot = \"hips\"")).contains("rigs.r.kind"));
        assert!(err(check("file = \"Cargo.toml\"\nslots = []")).contains("at least one slot"));
        let rig = check("file = \"Cargo.toml\"\nscale = 0.01").unwrap();
        assert_eq!((rig.height_jitter, rig.skin.scale), (0.1, 0.01));
        // The pose error bound: the shot's unless the rig gives its own; the tallest agent is 1 + jitter.
        assert_eq!((rig.skin.pose_error_max, rig.skin.max_height_scale), (DEFAULT_POSE_ERROR_MAX, 1.1));
        let rig = check("file = \"Cargo.toml\"\npose_error_max = 0.005\nheight_jitter = 0.0").unwrap();
        assert_eq!((rig.skin.pose_error_max, rig.skin.max_height_scale), (0.005, 1.0));
        let e = err(check("file = \"Cargo.toml\"\npose_error_max = -1.0"));
        assert!(e.contains("s.toml:2") && e.contains("rigs.r.pose_error_max"), "{e}");
    }

    #[test]
    fn camera_section_needs_distinct_finite_keys_or_a_node() {
        let check = |text: &str| toml::from_str::<CameraFile>(text).unwrap().check(&cx(text));
        let key = |f: f32| {
            format!("{{ frame = {f:?}, position = [0.0, 1.0, 5.0], aim = [0.0, 1.0, 0.0], focal_length = 35.0 }}")
        };
        assert!(err(check("")).contains("needs `keys` or `gltf`"));
        assert!(err(check("node = \"cam\"")).contains("`camera.node` needs `camera.gltf`"));
        assert!(err(check(&format!("keys = [{}, {}]", key(2.0), key(2.0)))).contains("two camera keys at frame 2"));
        let cam = check(&format!("keys = [{}, {}]", key(9.0), key(1.0))).unwrap();
        assert_eq!(cam.keys.iter().map(|k| k.frame).collect::<Vec<_>>(), [1.0, 9.0], "sorted by frame");
        // Depth of field: values > 0, on every key or none.
        let lens = |f: f32, n: f32, d: f32| {
            format!(
                "{{ frame = {f:?}, position = [0.0, 1.0, 5.0], aim = [0.0, 1.0, 0.0], focal_length = 35.0, f_stop = {n:?}, focus_distance = {d:?} }}"
            )
        };
        let e = err(check(&format!("keys = [{}, {}]", key(1.0), lens(3.0, 0.0, 4.0))));
        assert!(e.contains("camera.keys.f_stop") && e.contains("> 0"), "{e}");
        let e = err(check(&format!("keys = [{}, {}]", key(1.0), lens(3.0, 2.0, -4.0))));
        assert!(e.contains("camera.keys.focus_distance"), "{e}");
        let e = err(check(&format!("keys = [{}, {}]", key(1.0), lens(3.0, 2.0, 4.0))));
        assert!(e.contains("every key"), "{e}");
        assert!(check(&format!("keys = [{}, {}]", lens(1.0, 2.8, 4.0), lens(3.0, 2.0, 6.0))).is_ok());
    }

    #[test]
    fn lights_layers_and_render_sections_are_range_checked() {
        let cx = Context { path: Path::new("s.toml"), text: "", base: PathBuf::new() };
        let lights: LightsFile = toml::from_str("sun = { direction = [0.0, 0.0, 0.0] }").unwrap();
        assert!(err(lights.check(&cx)).contains("lights.sun.direction"));
        let lights: LightsFile = toml::from_str("sky = { intensity = -1.0 }").unwrap();
        assert!(err(lights.check(&cx)).contains("lights.sky.intensity"));
        let layers: LayerSettings = toml::from_str("count = 0").unwrap();
        assert!(err(check_layers(&layers, Path::new("s.toml"))).contains("layers.count"));
        let layers: LayerSettings = toml::from_str("cutoffs = [9.0, 3.0]").unwrap();
        assert!(err(check_layers(&layers, Path::new("s.toml"))).contains("cut-offs must increase"));
        let render: RenderSettings = toml::from_str("spp = 0").unwrap();
        assert!(err(check_render(&render, Path::new("s.toml"))).contains("render.spp"));
        for bad in [-1.0, f32::NAN, f32::INFINITY] {
            let render = RenderSettings { indirect_clamp: bad, ..RenderSettings::default() };
            assert!(err(check_render(&render, Path::new("s.toml"))).contains("render.indirect_clamp"));
        }
        let off = RenderSettings { indirect_clamp: 0.0, ..RenderSettings::default() };
        assert!(check_render(&off, Path::new("s.toml")).is_ok());
        let render: RenderSettings = toml::from_str("shutter = [0.5, -0.5]").unwrap();
        assert!(err(check_render(&render, Path::new("s.toml"))).contains("render.shutter"));
        assert!(check_render(&RenderSettings::default(), Path::new("s.toml")).is_ok());
    }

    #[test]
    fn look_at_faces_aim() {
        let m = look_at(Vec3::new(0.0, 1.0, 10.0), Vec3::new(0.0, 1.0, 0.0));
        let fwd = m.transform_vector3(-Vec3::Z);
        assert!((fwd - -Vec3::Z).length() < 1e-6);
        assert!((m.transform_vector3(Vec3::Y) - Vec3::Y).length() < 1e-6);
    }
}
