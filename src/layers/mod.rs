//! Layering: rank agents by distance to camera at ONE reference frame, split
//! them into render layers (by count, distance cut-offs or a memory budget),
//! choose each agent's level of detail, and write the layer manifest that
//! rendering reads (it never re-ranks). docs/layers.md documents the rules and
//! the manifest.
//!
//! Why one frame: on Robots, ranking on every frame made agents pop between
//! layers and took their shadows with them. Ranking once keeps membership
//! fixed for the whole shot; `--per-frame` ranks on every frame only to count
//! the pops for comparison.
//!
//! The ranking itself is pure: it works from a [`LayerInput`] (positions,
//! heights, memory estimates, cameras), independent of cache and casting
//! types; [`input`] builds that input from a cast shot.

pub mod checks;
mod font;
pub(crate) mod input;
pub(crate) mod made_from;
pub mod manifest;
pub(crate) mod map;
pub mod memory;

use std::collections::HashMap;
use std::path::PathBuf;

use glam::Vec3;

use crate::error::{Error, Result};
use crate::scene::Camera;
use crate::shot::{parse_bytes, LayerSettings, SplitMode};

pub use input::{build_layers, render_shutter, set_bounds, settings_with_overrides, LayerOverrides};
pub use made_from::{check_current, MadeFrom};
pub use manifest::{format_bytes, read_manifest, summary, write_manifest, Lod, Manifest, Ranking};
pub(crate) use manifest::{
    lod_at, CameraRecord, LayerAgent, LayerRecord, LodChange, Pops, SetRecord, SplitRecord, MANIFEST_VERSION,
};
pub use map::{draw_map, render_map, MapOptions};
pub use memory::RenderFloor;

/// One agent as layering sees it.
#[derive(Debug, Clone)]
pub struct AgentInput {
    /// Cache agent id.
    pub id: u32,
    /// Foot position at each frame of [`LayerInput::frames`]; `None` where absent.
    pub positions: Vec<Option<Vec3>>,
    /// Standing height in metres, casting's height scale included.
    pub height_m: f32,
    /// Estimated render memory with full parts, bytes (see [`memory::instance_bytes`]).
    pub memory_full: u64,
    /// Estimated render memory as proxy boxes, bytes (see [`memory::instance_bytes`]).
    pub memory_proxy: u64,
    /// Ranked like everyone else, then left out of every render.
    pub removed: bool,
}

/// Switches that are not part of the shot's `[layers]` table.
#[derive(Debug, Clone, Copy)]
pub struct LayerOptions {
    /// Rank on every frame as well and report pops (membership stays fixed).
    pub per_frame: bool,
    /// Choose LOD on every frame, with hysteresis, instead of once.
    pub lod_per_frame: bool,
    /// Hysteresis band for per-frame LOD, as a fraction of `lod_full_min_px`:
    /// an agent turns full above `min * (1 + h)` and proxy below `min * (1 - h)`.
    pub lod_hysteresis: f32,
    /// Memory every layer render carries whatever its agents (the render
    /// floor, [`memory::RenderFloor::bytes`]), counted once per layer against
    /// the budget; the split adds the other layers' agents as casters.
    pub shared_bytes: u64,
}

impl Default for LayerOptions {
    fn default() -> Self {
        LayerOptions { per_frame: false, lod_per_frame: false, lod_hysteresis: 0.15, shared_bytes: 0 }
    }
}

/// Everything layering needs, independent of cache and casting types.
#[derive(Debug, Clone)]
pub struct LayerInput {
    /// Shot name, written into the manifest.
    pub shot: String,
    /// The shot file, named in error messages.
    pub source: PathBuf,
    /// Shot frames, in order.
    pub frames: Vec<i32>,
    /// The camera at each of `frames`.
    pub cameras: Vec<Camera>,
    /// Rendered image width and height in pixels.
    pub image_size: (u32, u32),
    /// The crowd.
    pub agents: Vec<AgentInput>,
    /// The shot's `[layers]` table, command-line overrides applied.
    pub settings: LayerSettings,
    /// Extra switches.
    pub options: LayerOptions,
}

impl LayerInput {
    /// The reference frame: `settings.ref_frame`, else the middle shot frame.
    pub(crate) fn ref_frame(&self) -> i32 {
        match self.settings.ref_frame {
            Some(f) => f,
            None => self.frames.get((self.frames.len().saturating_sub(1)) / 2).copied().unwrap_or(0),
        }
    }
}

/// The split rule, validated.
#[derive(Debug, Clone, PartialEq)]
enum Plan {
    Count(usize),
    Cutoffs(Vec<f32>),
    Budget(u64),
}

/// Most crowd layers a split may make (each is a render of every frame):
/// checked before any per-layer list is allocated.
pub const MAX_LAYERS: usize = 1000;

/// Agents closer than this along the view axis count as behind the camera.
const NEAR_M: f32 = 0.01;
/// Pins may create layers, but not absurdly many by a typo.
const MAX_PIN_LAYER: usize = 999;

/// Where and how big an agent is at the frame it is ranked at.
#[derive(Debug, Clone, Copy)]
struct Sample {
    frame_idx: usize,
    pos: Vec3,
    distance: f32,
    px: f32,
    behind: bool,
}

/// Nearest frame index (earlier first on ties) at which the agent is present.
fn nearest_present(positions: &[Option<Vec3>], fi: usize) -> Option<usize> {
    if positions.get(fi).is_some_and(|p| p.is_some()) {
        return Some(fi);
    }
    (1..positions.len()).find_map(|d| {
        let before = fi.checked_sub(d).filter(|&i| positions.get(i).is_some_and(|p| p.is_some()));
        before.or_else(|| Some(fi + d).filter(|&i| positions.get(i).is_some_and(|p| p.is_some())))
    })
}

/// Distance and projected height (pixels) of an agent of `height` metres
/// standing at `pos` seen by `cam`, and whether it is behind the camera.
/// Distance is Euclidean from the camera to the agent's centre (half height),
/// projected height uses the depth along the view axis. botinfo uses this
/// too, so both report the same distance.
pub(crate) fn measure(cam: &Camera, image_h: u32, pos: Vec3, height: f32) -> (f32, f32, bool) {
    let eye = Vec3::from(cam.world_from_camera.translation);
    let forward = cam.world_from_camera.transform_vector3(-Vec3::Z).normalize_or_zero();
    let to = pos + Vec3::Y * (0.5 * height) - eye;
    let depth = to.dot(forward);
    let behind = depth <= NEAR_M;
    let px = if behind { 0.0 } else { height / (2.0 * depth * (0.5 * cam.yfov).tan()) * image_h as f32 };
    (to.length(), px, behind)
}

fn sample(input: &LayerInput, agent: &AgentInput, fi: usize) -> Option<Sample> {
    let at = nearest_present(&agent.positions, fi)?;
    let pos = agent.positions[at]?;
    let (distance, px, behind) = measure(&input.cameras[at], input.image_size.1, pos, agent.height_m);
    Some(Sample { frame_idx: at, pos, distance, px, behind })
}

/// Checked input, the split plan and the pins by agent index.
struct Prepared {
    plan: Plan,
    ref_idx: usize,
    pins: HashMap<usize, usize>,
    /// Agent indices in id order.
    by_id: Vec<u32>,
}

fn prepare(input: &LayerInput) -> Result<Prepared> {
    let bad = |field: &str, msg: String| Error::invalid(&input.source, msg).field(field);
    let s = &input.settings;
    if input.frames.is_empty() {
        return Err(bad("frames", "the shot has no frames".into()));
    }
    if input.cameras.len() != input.frames.len() {
        return Err(bad(
            "camera",
            format!("{} cameras for {} frames (one camera per frame)", input.cameras.len(), input.frames.len()),
        ));
    }
    if input.image_size.0 == 0 || input.image_size.1 == 0 {
        return Err(bad("render.resolution", "image size must be > 0".into()));
    }
    let ref_frame = input.ref_frame();
    let ref_idx = input.frames.iter().position(|&f| f == ref_frame).ok_or_else(|| {
        bad(
            "layers.ref_frame",
            format!(
                "reference frame {ref_frame} is not a shot frame ({}-{})",
                input.frames[0],
                input.frames[input.frames.len() - 1]
            ),
        )
    })?;
    for a in &input.agents {
        if a.positions.len() != input.frames.len() {
            return Err(Error::invalid(
                &input.source,
                format!("{} positions for {} frames", a.positions.len(), input.frames.len()),
            )
            .agent(a.id));
        }
        if !(a.height_m > 0.0 && a.height_m.is_finite()) {
            return Err(Error::invalid(&input.source, format!("height must be > 0, got {}", a.height_m)).agent(a.id));
        }
        if let Some(p) = a.positions.iter().flatten().find(|p| !p.is_finite()) {
            return Err(Error::invalid(&input.source, format!("position is not finite: {p}")).agent(a.id));
        }
    }
    // Agents by id: finds duplicates and pinned agents, and orders the
    // manifest, without a hash map (1M inserts cost more than the sort).
    let mut by_id: Vec<u64> =
        input.agents.iter().enumerate().map(|(i, a)| (u64::from(a.id) << 32) | i as u64).collect();
    by_id.sort_unstable();
    if let Some(w) = by_id.windows(2).find(|w| w[0] >> 32 == w[1] >> 32) {
        return Err(Error::invalid(&input.source, "agent id appears twice").agent((w[0] >> 32) as u32));
    }
    let by_id: Vec<u32> = by_id.into_iter().map(|k| k as u32).collect();
    let index_of =
        |id: u32| by_id.binary_search_by_key(&id, |&i| input.agents[i as usize].id).ok().map(|k| by_id[k] as usize);
    let plan = match s.split {
        SplitMode::Count => {
            if s.count == 0 {
                return Err(bad("layers.count", "must be at least 1".into()));
            }
            if s.count > MAX_LAYERS {
                return Err(bad("layers.count", format!("{} layers: at most {MAX_LAYERS}", s.count)));
            }
            Plan::Count(s.count)
        }
        SplitMode::Cutoffs => {
            if s.cutoffs.is_empty() {
                return Err(bad("layers.cutoffs", "a cut-off split needs at least one distance, e.g. 10,25,60".into()));
            }
            if s.cutoffs.iter().any(|c| !(*c > 0.0 && c.is_finite())) || s.cutoffs.windows(2).any(|w| !(w[0] < w[1])) {
                return Err(bad(
                    "layers.cutoffs",
                    format!("cut-offs must be positive and increase, got {:?}", s.cutoffs),
                ));
            }
            if s.cutoffs.len() >= MAX_LAYERS {
                return Err(bad(
                    "layers.cutoffs",
                    format!("{} cut-offs make {} layers: at most {MAX_LAYERS}", s.cutoffs.len(), s.cutoffs.len() + 1),
                ));
            }
            Plan::Cutoffs(s.cutoffs.clone())
        }
        SplitMode::Budget => {
            let text = s
                .budget
                .as_deref()
                .ok_or_else(|| bad("layers.budget", "a budget split needs a budget, e.g. 2.8GB".into()))?;
            let bytes = parse_bytes(text).map_err(|m| bad("layers.budget", m))?;
            if bytes == 0 {
                return Err(bad("layers.budget", "budget must be > 0".into()));
            }
            Plan::Budget(bytes)
        }
    };
    if !(s.lod_full_min_px >= 0.0 && s.lod_full_min_px.is_finite()) {
        return Err(bad("layers.lod_full_min_px", format!("must be >= 0, got {}", s.lod_full_min_px)));
    }
    let h = input.options.lod_hysteresis;
    if !(0.0..1.0).contains(&h) {
        return Err(bad("layers.lod_hysteresis", format!("must be in [0, 1), got {h}")));
    }
    let mut pins = HashMap::new();
    for pin in &s.pins {
        let i = index_of(pin.agent).ok_or_else(|| {
            Error::invalid(&input.source, "pinned agent is not in the crowd").agent(pin.agent).field("layers.pins")
        })?;
        if pin.layer > MAX_PIN_LAYER {
            return Err(Error::invalid(&input.source, format!("pin to layer {} (at most {MAX_PIN_LAYER})", pin.layer))
                .agent(pin.agent)
                .field("layers.pins"));
        }
        if pins.insert(i, pin.layer).is_some_and(|l| l != pin.layer) {
            return Err(Error::invalid(&input.source, "agent pinned to two different layers")
                .agent(pin.agent)
                .field("layers.pins"));
        }
    }
    Ok(Prepared { plan, ref_idx, pins, by_id })
}

/// The split at one frame.
struct Assigned {
    /// Per agent (input order): where it was ranked; `None` if absent from every frame.
    samples: Vec<Option<Sample>>,
    /// Per agent: layer after pins; `u32::MAX` when absent.
    layer: Vec<u32>,
    /// Layers made by the split plus any created by pins.
    n_layers: usize,
    /// Distance where each layer after the first begins (before pins).
    boundaries: Vec<Option<f32>>,
}

/// Ranks every agent at frame index `fi` and splits. `full_lod(i, sample)`
/// says whether agent `i` is charged its full-parts memory.
fn assign(
    input: &LayerInput,
    prep: &Prepared,
    fi: usize,
    full_lod: &dyn Fn(usize, &Sample) -> bool,
) -> Result<Assigned> {
    let samples: Vec<Option<Sample>> = input.agents.iter().map(|a| sample(input, a, fi)).collect();
    // Rank on (distance, id): deterministic, ties broken by agent id. The
    // key packs both in a u64 (a non-negative f32's bits sort like the
    // float), so the sort compares integers.
    let mut keyed: Vec<(u64, u32)> = samples
        .iter()
        .enumerate()
        .filter_map(|(i, s)| {
            s.map(|s| ((u64::from(s.distance.to_bits()) << 32) | u64::from(input.agents[i].id), i as u32))
        })
        .collect();
    keyed.sort_unstable_by_key(|k| k.0);
    let order: Vec<(f32, u32)> = keyed.into_iter().map(|(k, i)| (f32::from_bits((k >> 32) as u32), i)).collect();

    let mut layer = vec![u32::MAX; input.agents.len()];
    let n = order.len();
    let mut n_layers = match &prep.plan {
        Plan::Count(c) => {
            // Equal counts by rank over ALL agents, removed included, so removing one moves nobody.
            for (rank, &(_, i)) in order.iter().enumerate() {
                layer[i as usize] = (rank * c / n.max(1)) as u32;
            }
            *c
        }
        Plan::Cutoffs(cuts) => {
            for &(d, i) in &order {
                layer[i as usize] = cuts.partition_point(|&c| c <= d) as u32;
            }
            cuts.len() + 1
        }
        Plan::Budget(budget) => {
            // Greedy nearest-first fill. Removed agents are charged too, so
            // removing one never moves another.
            let (shared, charge) = budget_charges(input, &samples, full_lod);
            if shared > *budget {
                return Err(Error::invalid(
                    &input.source,
                    format!(
                        "every layer render carries {} whatever its agents ({} for the loaded shot, library, BVHs, \
                         set and film, plus {} for the other agents as shadow and reflection casters), over the \
                         layer budget of {}; raise the budget{}",
                        format_bytes(shared),
                        format_bytes(input.options.shared_bytes),
                        format_bytes(shared - input.options.shared_bytes),
                        format_bytes(*budget),
                        if input.settings.proxy_shadow_casters {
                            ""
                        } else {
                            ", or set [layers] proxy_shadow_casters = true so other layers' agents cast as proxy boxes"
                        }
                    ),
                )
                .field("layers.budget"));
            }
            let mut current = 0u32;
            let mut used = shared;
            let mut count = 0usize;
            for &(_, i) in &order {
                let i = i as usize;
                let m = charge[i];
                if shared.saturating_add(m) > *budget {
                    return Err(Error::invalid(
                        &input.source,
                        format!(
                            "agent alone needs {} ({} per-layer shared + {} agent), over the layer budget of {}; \
                             raise the budget or remove the agent",
                            format_bytes(shared + m),
                            format_bytes(shared),
                            format_bytes(m),
                            format_bytes(*budget)
                        ),
                    )
                    .agent(input.agents[i].id)
                    .field("layers.budget"));
                }
                if count > 0 && used + m > *budget {
                    current += 1;
                    used = shared;
                    count = 0;
                }
                used += m;
                count += 1;
                layer[i] = current;
            }
            let n = current as usize + 1;
            if n > MAX_LAYERS {
                return Err(Error::invalid(
                    &input.source,
                    format!(
                        "a budget of {} makes {n} layers, more than {MAX_LAYERS}: raise the budget",
                        format_bytes(*budget)
                    ),
                )
                .field("layers.budget"));
            }
            n
        }
    };
    // Where each layer begins: the first-ranked agent of that layer.
    let mut boundaries = vec![None; n_layers.saturating_sub(1)];
    for &(d, i) in order.iter().rev() {
        let l = layer[i as usize] as usize;
        if l > 0 && l - 1 < boundaries.len() {
            boundaries[l - 1] = Some(d);
        }
    }
    if let Plan::Cutoffs(cuts) = &prep.plan {
        boundaries = cuts.iter().map(|&c| Some(c)).collect();
    }
    // Pins override the split for the pinned agent only. A pin may add
    // layers after the split's, but never leave one of them empty.
    let split_layers = n_layers;
    for (&i, &l) in &prep.pins {
        if layer[i] != u32::MAX {
            layer[i] = l as u32;
            n_layers = n_layers.max(l + 1);
        }
    }
    if n_layers > split_layers {
        let mut used = vec![false; n_layers - split_layers];
        for &l in &layer {
            if l != u32::MAX && l as usize >= split_layers {
                used[l as usize - split_layers] = true;
            }
        }
        if let Some(empty) = used.iter().position(|u| !u).map(|e| e + split_layers) {
            let (&i, &l) = prep
                .pins
                .iter()
                .filter(|(&i, &l)| l > empty && layer[i] != u32::MAX)
                .min_by_key(|(&i, _)| input.agents[i].id)
                .unwrap_or((&0, &empty));
            return Err(Error::invalid(
                &input.source,
                format!(
                    "pin to layer {l} leaves layer {empty} empty: the split makes {split_layers} layer(s) (0-{}), \
                     so pin to at most layer {split_layers}, or raise the layer count",
                    split_layers - 1
                ),
            )
            .agent(input.agents.get(i).map_or(0, |a| a.id))
            .field("layers.pins"));
        }
    }
    Ok(Assigned { samples, layer, n_layers, boundaries })
}

/// LOD of each agent over the shot with hysteresis: per agent, the changes
/// (first entry at the first frame). Absent frames hold the nearest position.
fn lod_spans(input: &LayerInput) -> Vec<Vec<LodChange>> {
    let min = input.settings.lod_full_min_px;
    let h = input.options.lod_hysteresis;
    input
        .agents
        .iter()
        .map(|a| {
            let mut spans: Vec<LodChange> = Vec::new();
            let mut state: Option<Lod> = None;
            for (fi, &frame) in input.frames.iter().enumerate() {
                let Some(s) = sample(input, a, fi) else { break };
                let next = match state {
                    None if s.px >= min => Lod::Full,
                    None => Lod::Proxy,
                    Some(Lod::Full) if s.px < min * (1.0 - h) => Lod::Proxy,
                    Some(Lod::Proxy) if s.px >= min * (1.0 + h) => Lod::Full,
                    Some(l) => l,
                };
                if state != Some(next) {
                    spans.push(LodChange { frame, lod: next });
                    state = Some(next);
                }
            }
            spans
        })
        .collect()
}

/// Whether agent `i` is charged its full-parts memory: full LOD at the
/// ranked frame, or with per-frame LOD, full at any frame.
fn charged_full(spans: &Option<Vec<Vec<LodChange>>>, min_px: f32, i: usize, s: &Sample) -> bool {
    match spans {
        Some(sp) => sp[i].iter().any(|c| c.lod == Lod::Full),
        None => !s.behind && s.px >= min_px,
    }
}

/// What a layer render carries whatever its agents, and what each agent adds
/// to the layer it is in. Every layer render traces every other agent as a
/// shadow and reflection caster (as proxy boxes with `proxy_shadow_casters`,
/// else at its own LOD), so the shared part is the floor
/// (`LayerOptions::shared_bytes`: the loaded shot, library, BVHs, set and
/// film) plus every agent as a caster, and an agent in the layer adds only
/// what its own LOD costs beyond its caster form.
fn budget_charges(
    input: &LayerInput,
    samples: &[Option<Sample>],
    full_lod: impl Fn(usize, &Sample) -> bool,
) -> (u64, Vec<u64>) {
    let proxy_casters = input.settings.proxy_shadow_casters;
    let mut casters = 0u64;
    // Charges in input order: the fill then reads 8 bytes per agent in rank order.
    let charge = input
        .agents
        .iter()
        .zip(samples)
        .enumerate()
        .map(|(i, (a, s))| {
            let own = if s.as_ref().is_some_and(|s| full_lod(i, s)) { a.memory_full } else { a.memory_proxy };
            let caster = if proxy_casters { a.memory_proxy } else { own };
            casters = casters.saturating_add(caster);
            own.saturating_sub(caster)
        })
        .collect();
    (input.options.shared_bytes.saturating_add(casters), charge)
}

/// Each agent's LOD over the shot (input order), as the manifest will
/// record it: the changes from its first frame (one entry when LOD is
/// fixed), or `None` for an agent absent from every frame. What the memory
/// model needs before the split ([`memory::RenderFloor::of`]).
pub fn agent_lods(input: &LayerInput) -> Result<Vec<Option<Vec<LodChange>>>> {
    let prep = prepare(input)?;
    let min_px = input.settings.lod_full_min_px;
    let spans = if input.options.lod_per_frame { Some(lod_spans(input)) } else { None };
    let first = input.frames[0];
    Ok(input
        .agents
        .iter()
        .enumerate()
        .map(|(i, a)| {
            let s = sample(input, a, prep.ref_idx)?;
            Some(match &spans {
                Some(sp) => sp[i].clone(),
                None => {
                    let lod = if charged_full(&spans, min_px, i, &s) { Lod::Full } else { Lod::Proxy };
                    vec![LodChange { frame: first, lod }]
                }
            })
        })
        .collect())
}

/// Ranks, splits and chooses LOD: the layer manifest for this input.
pub fn build_manifest(input: &LayerInput) -> Result<Manifest> {
    let prep = prepare(input)?;
    let min_px = input.settings.lod_full_min_px;
    let spans = if input.options.lod_per_frame { Some(lod_spans(input)) } else { None };
    let full_lod = |i: usize, s: &Sample| charged_full(&spans, min_px, i, s);
    let asg = assign(input, &prep, prep.ref_idx, &full_lod)?;
    let ref_frame = input.frames[prep.ref_idx];

    let (shared, charge) = budget_charges(input, &asg.samples, full_lod);
    let mut layers: Vec<LayerRecord> =
        (0..asg.n_layers).map(|l| LayerRecord::empty(l, shared, input.settings.proxy_shadow_casters)).collect();
    let mut agents = Vec::with_capacity(input.agents.len());
    let mut absent = Vec::new();
    for &i in &prep.by_id {
        let i = i as usize;
        let a = &input.agents[i];
        let Some(s) = asg.samples[i] else {
            absent.push(a.id);
            continue;
        };
        let l = asg.layer[i] as usize;
        let full = full_lod(i, &s);
        let lod = match &spans {
            // The LOD at the reference frame, for the summary.
            Some(sp) => {
                sp[i].iter().rev().find(|c| c.frame <= ref_frame).or(sp[i].first()).map_or(Lod::Proxy, |c| c.lod)
            }
            None if full => Lod::Full,
            None => Lod::Proxy,
        };
        let memory = if full { a.memory_full } else { a.memory_proxy };
        let rec = &mut layers[l];
        rec.agents += 1;
        if a.removed {
            rec.removed += 1;
        } else {
            rec.rendered += 1;
            rec.memory_bytes += charge[i];
            match lod {
                Lod::Full => rec.lod_full += 1,
                Lod::Proxy => rec.lod_proxy += 1,
            }
        }
        let pinned = prep.pins.contains_key(&i);
        if pinned {
            rec.pinned += 1;
        } else {
            // The range shows the split; a pinned agent would stretch it.
            rec.distance_min_m = Some(rec.distance_min_m.map_or(s.distance, |d: f32| d.min(s.distance)));
            rec.distance_max_m = Some(rec.distance_max_m.map_or(s.distance, |d: f32| d.max(s.distance)));
        }
        agents.push(LayerAgent {
            id: a.id,
            layer: l,
            lod,
            distance_m: s.distance,
            projected_px: s.px,
            behind_camera: s.behind,
            removed: a.removed,
            pinned,
            ranked_frame: input.frames[s.frame_idx],
            position: s.pos.to_array(),
            height_m: a.height_m,
            memory_bytes: memory,
            lod_changes: spans.as_ref().map(|sp| sp[i].clone()).unwrap_or_default(),
        });
    }

    if let Plan::Budget(budget) = prep.plan {
        // Only pins can push a layer over: name them.
        if let Some(over) = layers.iter().find(|l| l.memory_bytes > budget) {
            let pinned: Vec<String> =
                agents.iter().filter(|a| a.pinned && a.layer == over.index).map(|a| a.id.to_string()).collect();
            return Err(Error::invalid(
                &input.source,
                format!(
                    "layer {} needs {} with pinned agents {}, over the budget of {}; unpin them or raise the budget",
                    over.name,
                    format_bytes(over.memory_bytes),
                    pinned.join(", "),
                    format_bytes(budget)
                ),
            )
            .field("layers.pins"));
        }
    }

    let pops = if input.options.per_frame { count_pops(input, &prep, &full_lod)? } else { Pops::default() };
    let cam = &input.cameras[prep.ref_idx];
    Ok(Manifest {
        version: MANIFEST_VERSION,
        shot: input.shot.clone(),
        ref_frame,
        frame_range: [input.frames[0], input.frames[input.frames.len() - 1]],
        ranking: if input.options.per_frame { Ranking::PerFrame } else { Ranking::Fixed },
        split: SplitRecord {
            mode: match prep.plan {
                Plan::Count(_) => "count",
                Plan::Cutoffs(_) => "cutoffs",
                Plan::Budget(_) => "budget",
            }
            .into(),
            count: if let Plan::Count(c) = prep.plan { Some(c) } else { None },
            cutoffs_m: if let Plan::Cutoffs(c) = &prep.plan { c.clone() } else { Vec::new() },
            budget_bytes: if let Plan::Budget(b) = prep.plan { Some(b) } else { None },
            shared_bytes: shared,
            boundaries_m: asg.boundaries,
        },
        lod_full_min_px: min_px,
        lod_per_frame: input.options.lod_per_frame,
        lod_hysteresis: input.options.lod_hysteresis,
        proxy_shadow_casters: input.settings.proxy_shadow_casters,
        camera: CameraRecord::new(cam, input.image_size),
        pops,
        comp_order: std::iter::once(crate::output::SET_LAYER.to_string())
            .chain(layers.iter().rev().map(|l| l.name.clone()))
            .collect(),
        set: SetRecord::new(input.settings.proxy_shadow_casters),
        layers,
        agents,
        absent,
        made_from: None,
    })
}

/// The layer of every agent (input order; `None` if absent from the whole
/// shot) at each shot frame. `Fixed` ranks once at the reference frame and
/// holds that membership; `PerFrame` ranks at every frame.
pub fn membership(input: &LayerInput, ranking: Ranking) -> Result<Vec<Vec<Option<usize>>>> {
    let prep = prepare(input)?;
    let min_px = input.settings.lod_full_min_px;
    let spans = if input.options.lod_per_frame { Some(lod_spans(input)) } else { None };
    let full_lod = |i: usize, s: &Sample| charged_full(&spans, min_px, i, s);
    let to_vec = |a: &Assigned| a.layer.iter().map(|&l| (l != u32::MAX).then_some(l as usize)).collect::<Vec<_>>();
    match ranking {
        Ranking::Fixed => {
            let once = to_vec(&assign(input, &prep, prep.ref_idx, &full_lod)?);
            Ok(vec![once; input.frames.len()])
        }
        Ranking::PerFrame => {
            (0..input.frames.len()).map(|fi| assign(input, &prep, fi, &full_lod).map(|a| to_vec(&a))).collect()
        }
    }
}

/// Pops in a membership table from [`membership`]: agents that change layer
/// at least once, and all layer changes between consecutive frames.
pub fn pops_in(table: &[Vec<Option<usize>>]) -> Pops {
    let mut changed = vec![false; table.first().map_or(0, |f| f.len())];
    let mut changes = 0u64;
    for w in table.windows(2) {
        for (i, (a, b)) in w[0].iter().zip(&w[1]).enumerate() {
            if a != b {
                changes += 1;
                changed[i] = true;
            }
        }
    }
    Pops { agents_changed: changed.iter().filter(|&&c| c).count() as u64, changes }
}

/// Per-frame ranking, streamed frame by frame so memory stays one frame deep.
fn count_pops(input: &LayerInput, prep: &Prepared, full_lod: &dyn Fn(usize, &Sample) -> bool) -> Result<Pops> {
    let mut changed = vec![false; input.agents.len()];
    let mut changes = 0u64;
    let mut prev: Option<Vec<u32>> = None;
    for fi in 0..input.frames.len() {
        let layer = assign(input, prep, fi, full_lod)?.layer;
        if let Some(p) = &prev {
            for (i, (a, b)) in p.iter().zip(&layer).enumerate() {
                if a != b {
                    changes += 1;
                    changed[i] = true;
                }
            }
        }
        prev = Some(layer);
    }
    Ok(Pops { agents_changed: changed.iter().filter(|&&c| c).count() as u64, changes })
}

/// Every agent's foot position at each shot frame (`None` where the cache
/// has no record for it), sorted by id: the positions half of a
/// [`LayerInput`]. Hidden agents count as present (they are still simulated).
pub(crate) fn shot_positions(
    shot: &crate::shot::Shot,
    crowd: &crate::cache::CrowdCache,
) -> Vec<(u32, Vec<Option<Vec3>>)> {
    let frames: Vec<i32> = shot.frames.iter().collect();
    let mut by_id: std::collections::BTreeMap<u32, Vec<Option<Vec3>>> = Default::default();
    for (fi, &f) in frames.iter().enumerate() {
        let cache_frame = shot.cache.cache_frame(f);
        let Ok(b) = crowd.frames.binary_search_by_key(&cache_frame, |b| b.frame) else { continue };
        for a in &crowd.frames[b].agents {
            by_id.entry(a.id).or_insert_with(|| vec![None; frames.len()])[fi] = Some(a.position);
        }
    }
    by_id.into_iter().collect()
}

/// A [`LayerInput`] for a shot: positions from the crowd, cameras from the
/// shot's keys (pass `cameras` for a glTF camera), removals from the shot,
/// and `info(id) -> (height_m, memory_full, memory_proxy)` from casting.
pub fn shot_input(
    shot: &crate::shot::Shot,
    crowd: &crate::cache::CrowdCache,
    cameras: Option<Vec<Camera>>,
    settings: LayerSettings,
    options: LayerOptions,
    info: impl Fn(u32) -> (f32, u64, u64),
) -> Result<LayerInput> {
    let frames: Vec<i32> = shot.frames.iter().collect();
    let cameras = match cameras {
        Some(c) => c,
        None => frames.iter().map(|&f| shot.keyed_camera(f as f32)).collect::<Option<Vec<_>>>().ok_or_else(|| {
            Error::invalid(&shot.path, "the camera has no keys; pass the glTF camera").field("camera")
        })?,
    };
    let agents = shot_positions(shot, crowd)
        .into_iter()
        .map(|(id, positions)| {
            let (height_m, memory_full, memory_proxy) = info(id);
            AgentInput { id, positions, height_m, memory_full, memory_proxy, removed: shot.removed.contains(&id) }
        })
        .collect();
    Ok(LayerInput {
        shot: shot.name.clone(),
        source: shot.path.clone(),
        frames,
        cameras,
        image_size: (shot.render.resolution[0], shot.render.resolution[1]),
        agents,
        settings,
        options,
    })
}

/// Where `throng layers` writes the manifest unless `--out` says otherwise:
/// `<shot dir>/<shot name>.layers.json`.
pub fn default_manifest_path(shot_path: &std::path::Path, shot_name: &str) -> PathBuf {
    shot_path.parent().unwrap_or(std::path::Path::new("")).join(format!("{shot_name}.layers.json"))
}
