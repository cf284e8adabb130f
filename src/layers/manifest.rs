//! The layer manifest (JSON, versioned; docs/layers.md): agent -> layer and
//! LOD, distances, thresholds, the reference frame, memory per layer, and the
//! visibility each render gives every agent and the set. Rendering reads it
//! and never re-ranks. Also: byte formatting and the human summary (the
//! memory figures come from [`super::memory`]).

use std::fmt::Write as _;
use std::path::Path;

use glam::Vec3;
use serde::{Deserialize, Serialize};

use crate::error::{write_atomic, Error, IoContext, Result};
use crate::scene::{vis, Camera};

/// The manifest version this build writes and reads.
pub(crate) const MANIFEST_VERSION: u32 = 1;

/// How agents were ranked. Membership is always the reference-frame ranking;
/// `PerFrame` additionally ranked every frame to count pops, for comparison.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Ranking {
    /// Ranked once at the reference frame.
    Fixed,
    /// Also ranked on every frame to count pops.
    PerFrame,
}

/// Level of detail (shared with posing).
pub use crate::casting::Lod;

/// A ray type an object is visible to; see [`crate::scene::vis`].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub(crate) enum RayKind {
    /// Camera rays: colour and alpha.
    Camera,
    /// Shadow rays.
    Shadow,
    /// Reflection / indirect rays.
    Indirect,
    /// Occludes camera rays with alpha 0 and no colour.
    Holdout,
}

/// [`vis`] bits of a ray list.
pub(crate) fn vis_bits(rays: &[RayKind]) -> u8 {
    rays.iter().fold(0, |b, r| {
        b | match r {
            RayKind::Camera => vis::CAMERA,
            RayKind::Shadow => vis::SHADOW,
            RayKind::Indirect => vis::INDIRECT,
            RayKind::Holdout => vis::HOLDOUT,
        }
    })
}

/// What one render (a crowd layer or the set layer) sees of what.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct Visibility {
    /// This layer's own (non-removed) agents.
    pub(crate) own_agents: Vec<RayKind>,
    /// Every other non-removed agent.
    pub(crate) other_agents: Vec<RayKind>,
    /// Other agents drawn as proxy boxes (else at their own LOD).
    pub(crate) other_agents_as_proxy: bool,
    /// The set.
    pub(crate) set: Vec<RayKind>,
}

/// One crowd layer.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LayerRecord {
    /// `crowd0` (nearest), `crowd1`, ...
    pub name: String,
    /// 0 = nearest.
    pub index: usize,
    /// Agents assigned, removed ones included.
    pub agents: usize,
    /// Agents rendered (assigned and not removed).
    pub(crate) rendered: usize,
    /// Agents assigned but removed.
    pub removed: usize,
    /// Agents here by a pin (counted in `agents`).
    pub(crate) pinned: usize,
    /// Nearest agent the split put here (pinned agents excluded), metres; null when none.
    pub distance_min_m: Option<f32>,
    /// Farthest agent the split put here (pinned agents excluded), metres; null when none.
    pub distance_max_m: Option<f32>,
    /// Rendered agents at full LOD (at the reference frame).
    pub(crate) lod_full: usize,
    /// Rendered agents as proxies (at the reference frame).
    pub(crate) lod_proxy: usize,
    /// Estimated peak memory of this layer's render process
    /// ([`super::memory`]): shared bytes plus rendered agents' estimates.
    pub memory_bytes: u64,
    /// Visibility in this layer's render.
    pub(crate) visibility: Visibility,
}

impl LayerRecord {
    pub(crate) fn empty(index: usize, shared_bytes: u64, proxy_casters: bool) -> Self {
        LayerRecord {
            name: crate::output::crowd_layer_name(index),
            index,
            agents: 0,
            rendered: 0,
            removed: 0,
            pinned: 0,
            distance_min_m: None,
            distance_max_m: None,
            lod_full: 0,
            lod_proxy: 0,
            memory_bytes: shared_bytes,
            visibility: Visibility {
                own_agents: vec![RayKind::Camera, RayKind::Shadow, RayKind::Indirect],
                other_agents: vec![RayKind::Shadow, RayKind::Indirect],
                other_agents_as_proxy: proxy_casters,
                set: vec![RayKind::Holdout, RayKind::Shadow, RayKind::Indirect],
            },
        }
    }
}

/// The set layer: the far-most background, rendered by the renderer with
/// every agent as a shadow and reflection caster.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SetRecord {
    /// Always `set`.
    pub name: String,
    /// Visibility in the set render (`own_agents` is empty: it has none).
    pub(crate) visibility: Visibility,
    /// Estimated peak memory of the set layer's render ([`super::memory`]):
    /// the floor and every agent as a caster. Absent in manifests of older
    /// throngs and of [`super::build_manifest`] alone (then the split's
    /// shared bytes stand in).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub memory_bytes: Option<u64>,
}

impl SetRecord {
    pub(crate) fn new(proxy_casters: bool) -> Self {
        SetRecord {
            name: crate::output::SET_LAYER.into(),
            visibility: Visibility {
                own_agents: Vec::new(),
                // Agents' shadows and their reflections in the set belong to
                // the set layer: crowd layers hold the set out.
                other_agents: vec![RayKind::Shadow, RayKind::Indirect],
                other_agents_as_proxy: proxy_casters,
                set: vec![RayKind::Camera, RayKind::Shadow, RayKind::Indirect],
            },
            memory_bytes: None,
        }
    }
}

/// A change of LOD at a frame (per-frame LOD only).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LodChange {
    /// First shot frame with this LOD.
    pub(crate) frame: i32,
    /// The LOD from that frame on.
    pub(crate) lod: Lod,
}

/// One agent.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct LayerAgent {
    /// Cache agent id.
    pub id: u32,
    /// Layer index.
    pub layer: usize,
    /// LOD at the reference frame (the LOD for the whole shot unless `lod_changes`).
    pub lod: Lod,
    /// Camera to agent centre (half height), metres, at `ranked_frame`.
    pub distance_m: f32,
    /// Projected height in pixels at `ranked_frame` (0 when behind the camera).
    pub projected_px: f32,
    /// Behind the camera at `ranked_frame` (so LOD proxy).
    pub behind_camera: bool,
    /// Ranked like everyone else, but never rendered.
    pub removed: bool,
    /// Layer set by a pin, not by the split.
    pub pinned: bool,
    /// The reference frame, or the nearest frame the agent is present.
    pub ranked_frame: i32,
    /// Foot position at `ranked_frame`.
    pub position: [f32; 3],
    /// Standing height, metres.
    pub height_m: f32,
    /// Estimated render memory at its LOD (full if ever full), bytes.
    pub memory_bytes: u64,
    /// Per-frame LOD: the LOD from each listed frame on; empty when LOD is fixed.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub lod_changes: Vec<LodChange>,
}

impl LayerAgent {
    /// LOD at a shot frame.
    pub fn lod_at(&self, frame: i32) -> Lod {
        lod_at(&self.lod_changes, frame).unwrap_or(self.lod)
    }
}

/// The LOD at a shot frame from a list of changes (the first one holds
/// before it); `None` when there are none.
pub fn lod_at(changes: &[LodChange], frame: i32) -> Option<Lod> {
    changes.iter().rev().find(|c| c.frame <= frame).or(changes.first()).map(|c| c.lod)
}

/// The camera at the reference frame (for the map and for checking).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CameraRecord {
    /// Position.
    pub(crate) position: [f32; 3],
    /// Unit view direction.
    pub(crate) forward: [f32; 3],
    /// Unit up.
    pub(crate) up: [f32; 3],
    /// Vertical field of view, radians.
    pub(crate) yfov: f32,
    /// Image width and height, pixels.
    pub image_size: [u32; 2],
}

impl CameraRecord {
    pub(crate) fn new(cam: &Camera, image_size: (u32, u32)) -> Self {
        let m = &cam.world_from_camera;
        CameraRecord {
            position: Vec3::from(m.translation).to_array(),
            forward: m.transform_vector3(-Vec3::Z).normalize_or_zero().to_array(),
            up: m.transform_vector3(Vec3::Y).normalize_or_zero().to_array(),
            yfov: cam.yfov,
            image_size: [image_size.0, image_size.1],
        }
    }

    /// Pixel position (x right, y down) of a world point, with its depth
    /// along the view axis; `None` when behind the camera.
    pub fn project(&self, p: Vec3) -> Option<(f32, f32, f32)> {
        let fwd = Vec3::from(self.forward);
        let up = Vec3::from(self.up);
        let right = fwd.cross(up);
        let d = p - Vec3::from(self.position);
        let depth = d.dot(fwd);
        if depth <= 0.01 {
            return None;
        }
        let (w, h) = (self.image_size[0] as f32, self.image_size[1] as f32);
        let t = (0.5 * self.yfov).tan();
        let ndc_x = d.dot(right) / (depth * t * w / h);
        let ndc_y = d.dot(up) / (depth * t);
        Some(((ndc_x + 1.0) * 0.5 * w, (1.0 - ndc_y) * 0.5 * h, depth))
    }
}

/// The split actually used.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SplitRecord {
    /// `count`, `cutoffs` or `budget`.
    pub(crate) mode: String,
    /// Layer count (count split).
    pub(crate) count: Option<usize>,
    /// Cut-offs in metres (cut-off split).
    #[serde(default)]
    pub(crate) cutoffs_m: Vec<f32>,
    /// Budget per layer in bytes (budget split).
    pub budget_bytes: Option<u64>,
    /// Memory every layer carries, counted once per layer.
    pub shared_bytes: u64,
    /// Distance where each layer after crowd0 begins, before pins (null for
    /// an empty layer): the cut-offs, or the nearest agent of that layer.
    pub(crate) boundaries_m: Vec<Option<f32>>,
}

/// Agents that change layer during the shot.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Pops {
    /// Agents that change layer at least once.
    pub agents_changed: u64,
    /// Layer changes between consecutive frames, all agents.
    pub changes: u64,
}

/// The layer manifest.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    /// [`MANIFEST_VERSION`].
    pub(crate) version: u32,
    /// Shot name.
    pub shot: String,
    /// The frame agents were ranked at.
    pub ref_frame: i32,
    /// First and last shot frame.
    pub frame_range: [i32; 2],
    /// Fixed, or also ranked per frame for comparison.
    pub ranking: Ranking,
    /// The split.
    pub split: SplitRecord,
    /// Projected height in pixels at or above which an agent is full LOD.
    pub(crate) lod_full_min_px: f32,
    /// LOD chosen per frame (see agents' `lod_changes`).
    pub(crate) lod_per_frame: bool,
    /// Hysteresis band of per-frame LOD, fraction of `lod_full_min_px`.
    pub(crate) lod_hysteresis: f32,
    /// Other layers' agents cast shadows and reflections as proxy boxes.
    pub(crate) proxy_shadow_casters: bool,
    /// The camera at the reference frame.
    pub camera: CameraRecord,
    /// Pops: 0 in fixed ranking; measured with per-frame ranking.
    pub pops: Pops,
    /// Layer names, back to front: `set`, then crowd layers far to near.
    pub comp_order: Vec<String>,
    /// The background set layer.
    pub set: SetRecord,
    /// Crowd layers, nearest first.
    pub layers: Vec<LayerRecord>,
    /// Every ranked agent, sorted by id.
    pub agents: Vec<LayerAgent>,
    /// Agents absent from every shot frame (in no layer).
    #[serde(default)]
    pub absent: Vec<u32>,
    /// What the manifest was made from; `render` refuses it when stale
    /// ([`super::made_from`]). Absent in manifests of older throngs.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub made_from: Option<super::made_from::MadeFrom>,
}

impl Manifest {
    /// An agent by id.
    pub fn agent(&self, id: u32) -> Option<&LayerAgent> {
        self.agents.binary_search_by_key(&id, |a| a.id).ok().map(|i| &self.agents[i])
    }

    /// The ids of a crowd layer's agents (removed agents left out), or the
    /// crowd layer names when there is no such layer.
    pub fn layer_agents(&self, name: &str) -> std::result::Result<std::collections::BTreeSet<u32>, Vec<String>> {
        let index = self
            .layers
            .iter()
            .position(|l| l.name == name)
            .ok_or_else(|| self.layers.iter().map(|l| l.name.clone()).collect::<Vec<_>>())?;
        Ok(self.agents.iter().filter(|a| a.layer == index && !a.removed).map(|a| a.id).collect())
    }

    /// A crowd layer by name.
    pub fn layer(&self, name: &str) -> Option<&LayerRecord> {
        self.layers.iter().find(|l| l.name == name)
    }

    /// Estimated peak memory of the render of `layer` at the manifest's
    /// image size ([`super::memory`]): a crowd layer's `memory_bytes`, or
    /// the set layer's (the floor with every agent as a caster, which is all
    /// it traces; the split's shared bytes in older manifests). `None` for
    /// an unknown layer.
    pub fn render_memory(&self, layer: &str) -> Option<u64> {
        if layer == self.set.name {
            return Some(self.set.memory_bytes.unwrap_or(self.split.shared_bytes));
        }
        self.layer(layer).map(|l| l.memory_bytes)
    }

    fn visibility_of(&self, layer: &str) -> Option<&Visibility> {
        if layer == self.set.name {
            Some(&self.set.visibility)
        } else {
            self.layer(layer).map(|l| &l.visibility)
        }
    }

    /// How the render of `layer` (`set` or a crowd layer) shows agent `id`
    /// at `frame`: [`vis`] bits and LOD, or `None` when the agent is not in
    /// that render at all (removed, absent or unknown layer).
    pub fn agent_visibility(&self, layer: &str, id: u32, frame: i32) -> Option<(u8, Lod)> {
        let v = self.visibility_of(layer)?;
        let a = self.agent(id)?;
        if a.removed {
            return None;
        }
        let own = layer != self.set.name && self.layers.get(a.layer).is_some_and(|l| l.name == layer);
        let lod = a.lod_at(frame);
        if own {
            Some((vis_bits(&v.own_agents), lod))
        } else {
            Some((vis_bits(&v.other_agents), if v.other_agents_as_proxy { Lod::Proxy } else { lod }))
        }
    }

    /// [`vis`] bits of the set in the render of `layer`.
    pub fn set_visibility(&self, layer: &str) -> Option<u8> {
        self.visibility_of(layer).map(|v| vis_bits(&v.set))
    }

    /// The manifest without the per-agent list: what `--json` prints.
    pub fn summary_json(&self) -> serde_json::Value {
        let mut v = serde_json::to_value(self).unwrap_or(serde_json::Value::Null);
        if let Some(o) = v.as_object_mut() {
            o.remove("agents");
        }
        v
    }
}

/// Writes the manifest atomically (pretty JSON).
pub fn write_manifest(path: &Path, m: &Manifest) -> Result<()> {
    write_atomic(path, |w| serde_json::to_writer_pretty(&mut *w, m).map_err(|e| Error::io(path, e.into())))
}

/// Reads a manifest, checking its version.
pub fn read_manifest(path: &Path) -> Result<Manifest> {
    #[derive(Deserialize)]
    struct Version {
        version: u32,
    }
    crate::error::check_readable_file(path)?;
    let text = std::fs::read_to_string(path).at(path)?;
    let json_err = |e: serde_json::Error| Error::invalid(path, e.to_string()).line(e.line());
    if !text.trim_start().starts_with('{') {
        return Err(Error::invalid(path, "not a layer manifest: expected a JSON object (`throng layers` writes one)"));
    }
    let v: Version = serde_json::from_str(&text).map_err(json_err)?;
    if v.version != MANIFEST_VERSION {
        return Err(Error::invalid(
            path,
            format!("unsupported layer manifest version {} (this throng reads {MANIFEST_VERSION})", v.version),
        )
        .field("version"));
    }
    let m: Manifest = serde_json::from_str(&text).map_err(json_err)?;
    check_consistent(path, &m)?;
    Ok(m)
}

/// A manifest edited by hand (or by another tool) must still describe one
/// split: `comp_order` is the set layer then every crowd layer once, each
/// layer's `index` is its place in `layers`, and every agent's `layer` is one
/// of them. Otherwise a render would trace layers nobody is in.
fn check_consistent(path: &Path, m: &Manifest) -> Result<()> {
    let bad = |field: &str, msg: String| Err(Error::invalid(path, msg).field(field.to_string()));
    for (i, l) in m.layers.iter().enumerate() {
        if l.index != i {
            return bad(
                &format!("layers[{i}].index"),
                format!("layer `{}` has index {}, expected {i}", l.name, l.index),
            );
        }
    }
    let mut order: Vec<&str> = m.comp_order.iter().map(String::as_str).collect();
    if order.first() != Some(&m.set.name.as_str()) {
        return bad(
            "comp_order",
            format!("comp_order {:?} does not start with the set layer `{}`", m.comp_order, m.set.name),
        );
    }
    order.remove(0);
    order.sort_unstable();
    let mut names: Vec<&str> = m.layers.iter().map(|l| l.name.as_str()).collect();
    names.sort_unstable();
    if order != names {
        return bad(
            "comp_order",
            format!(
                "comp_order {:?} does not list the set and each of the layers [{}] exactly once",
                m.comp_order,
                m.layers.iter().map(|l| l.name.as_str()).collect::<Vec<_>>().join(", ")
            ),
        );
    }
    if let Some(a) = m.agents.iter().find(|a| a.layer >= m.layers.len()) {
        return Err(Error::invalid(
            path,
            format!("agent {} is in layer {}, but the manifest has {} layers", a.id, a.layer, m.layers.len()),
        )
        .agent(a.id)
        .field("agents.layer"));
    }
    Ok(())
}

/// Bytes in decimal units, as `--budget` takes them: `1.21 GB`, `512 MB`.
pub fn format_bytes(b: u64) -> String {
    let x = b as f64;
    if x >= 1e9 {
        format!("{:.2} GB", x / 1e9)
    } else if x >= 1e6 {
        format!("{:.1} MB", x / 1e6)
    } else if x >= 1e3 {
        format!("{:.1} KB", x / 1e3)
    } else {
        format!("{b} B")
    }
}

/// A layer's distance range, `4.2-12.8 m`, or `-` when empty.
pub fn distance_range(l: &LayerRecord) -> String {
    match (l.distance_min_m, l.distance_max_m) {
        (Some(a), Some(b)) => format!("{a:.1}-{b:.1} m"),
        _ => "-".into(),
    }
}

/// The human summary: a header, one aligned line per layer, then notes.
pub fn summary(m: &Manifest) -> String {
    let mut s = String::new();
    let split = match m.split.mode.as_str() {
        "count" => format!("count {}", m.split.count.unwrap_or(0)),
        "cutoffs" => {
            format!("cut-offs {} m", m.split.cutoffs_m.iter().map(|c| format!("{c}")).collect::<Vec<_>>().join(", "))
        }
        "budget" => format!("budget {} per layer", format_bytes(m.split.budget_bytes.unwrap_or(0))),
        other => other.to_string(),
    };
    let _ = writeln!(
        s,
        "{}: {} agents, ranked at frame {} (shot {}-{}), split by {split}, full LOD from {} px",
        m.shot,
        m.agents.len(),
        m.ref_frame,
        m.frame_range[0],
        m.frame_range[1],
        m.lod_full_min_px
    );
    let rows: Vec<[String; 8]> = m
        .layers
        .iter()
        .map(|l| {
            [
                l.name.clone(),
                l.rendered.to_string(),
                l.removed.to_string(),
                l.pinned.to_string(),
                distance_range(l),
                l.lod_full.to_string(),
                l.lod_proxy.to_string(),
                format_bytes(l.memory_bytes),
            ]
        })
        .collect();
    let head = ["layer", "agents", "removed", "pinned", "distance", "full", "proxy", "memory"];
    let mut width = head.map(str::len);
    for r in &rows {
        for (w, c) in width.iter_mut().zip(r) {
            *w = (*w).max(c.len());
        }
    }
    let line = |s: &mut String, r: [&str; 8]| {
        let mut out = format!("{:<w$}", r[0], w = width[0]);
        for (c, w) in r.iter().zip(width).skip(1) {
            out += &format!("  {c:>w$}");
        }
        let _ = writeln!(s, "{}", out.trim_end());
    };
    line(&mut s, head);
    for r in &rows {
        line(&mut s, [&r[0], &r[1], &r[2], &r[3], &r[4], &r[5], &r[6], &r[7]]);
    }
    let _ = writeln!(
        s,
        "{:<w$}  background: the set, every agent as a shadow and reflection caster",
        m.set.name,
        w = width[0]
    );
    let _ = writeln!(s, "comp order, back to front: {}", m.comp_order.join(", "));
    match m.ranking {
        Ranking::Fixed => {
            let _ = writeln!(s, "fixed-frame ranking: membership holds for every frame, 0 pops");
        }
        Ranking::PerFrame => {
            let _ = writeln!(
                s,
                "per-frame ranking would pop {} agents ({} layer changes); the manifest keeps frame {}'s layers",
                m.pops.agents_changed, m.pops.changes, m.ref_frame
            );
        }
    }
    let pins: Vec<String> =
        m.agents.iter().filter(|a| a.pinned).map(|a| format!("{} -> crowd{}", a.id, a.layer)).collect();
    if !pins.is_empty() {
        let _ = writeln!(s, "pinned: {}", pins.join(", "));
    }
    let removed = m.agents.iter().filter(|a| a.removed).count();
    if removed > 0 {
        let _ = writeln!(s, "removed: {removed} agents ranked but not rendered");
    }
    let behind = m.agents.iter().filter(|a| a.behind_camera).count();
    if behind > 0 {
        let _ = writeln!(s, "behind the camera: {behind} agents (proxy LOD)");
    }
    let elsewhere = m.agents.iter().filter(|a| a.ranked_frame != m.ref_frame).count();
    if elsewhere > 0 {
        let _ = writeln!(s, "absent at frame {}: {elsewhere} agents ranked at their nearest frame", m.ref_frame);
    }
    if !m.absent.is_empty() {
        let _ = writeln!(s, "absent from every frame: {} agents (in no layer)", m.absent.len());
    }
    s
}
