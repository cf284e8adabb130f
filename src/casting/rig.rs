//! Slot rigs and their animation cycles, loaded from glTF (SPEC "Rig glTF").
//!
//! A [`Rig`] is an [`Animated`] file (`casting::animation`: any glTF file's
//! node hierarchy and node animations, re-exported here) with slots and a
//! `root` node, whose clips are looping [`Cycle`]s sampled by cycle frame.
//!
//! Slots are nodes whose extras carry `"slot"`. Their proxy box comes from the
//! extras' `"proxy_box"` `{min, max}` (node-local space) when present, which
//! wins over the node mesh's bounds; the mesh bounds are used only when
//! `proxy_box` is missing. A slot with neither is an error.
//!
//! Looping: a cycle spans its clip's first to last key time (over all
//! channels). Cycle frame `f` samples at `start + (f mod length) / fps`
//! seconds, with `length = duration * fps` frames and a Euclidean modulo (so
//! negative frames wrap too). The frame `length` itself wraps to 0: walk clips
//! repeat the first key as the last for a seamless loop, so both are the same
//! pose and the seam is sampled once.
//!
//! Root motion: posing zeroes the `root` node's X and Z translation (the cache
//! gives the agent's position) and keeps Y (bob). The stride is the root's Z
//! travel from the clip's first to last key.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use glam::{Affine3A, Vec3};

use crate::cache::jupedsim::{RigClip, SHOT_FPS};
pub use crate::casting::animation::{Animated, Channel, Clip, Hierarchy, Interpolation, Node, Property, Trs};
use crate::casting::kind;
use crate::error::{Error, Result};
use crate::scene::gltf::{node_label, read_mesh, GltfFile};
use crate::shot::SkinOptions;

/// A part slot of a rig: where a wardrobe part goes.
#[derive(Clone, Debug, PartialEq)]
pub struct Slot {
    /// Slot name from the node extras (`head`, `upper_arm_l`, ...).
    pub name: String,
    /// The slot's node index.
    pub node: usize,
    /// Proxy box minimum, node-local space.
    pub proxy_min: Vec3,
    /// Proxy box maximum, node-local space.
    pub proxy_max: Vec3,
}

/// What every cycle and pose of a rig shares.
#[derive(Debug)]
struct RigShape {
    hierarchy: Hierarchy,
    slots: Vec<Slot>,
    root: usize,
}

/// A rig: node hierarchy, slots, root-motion node and cycles.
#[derive(Clone, Debug)]
pub struct Rig {
    path: PathBuf,
    shape: Arc<RigShape>,
    cycles: Vec<Cycle>,
}

impl Rig {
    /// Loads a rig glTF (SPEC "Rig glTF"). Needs a node named `root` and at
    /// least one slot.
    pub fn load(path: impl AsRef<Path>) -> Result<Rig> {
        let file = GltfFile::open(path)?;
        let animated = Animated::from_file(&file)?;
        let hierarchy = animated.hierarchy;
        if kind::is_skinned(&file) && !kind::has_slots(&file) {
            return Err(kind::skinned_refusal(&file.path, "this rig"));
        }
        let root = hierarchy.find("root").ok_or_else(|| file.err("rig has no node named `root`"))?;
        let mut slots: Vec<Slot> = Vec::new();
        for node in file.doc.nodes() {
            let Some(slot) = read_slot(&file, &node)? else { continue };
            if slots.iter().any(|s| s.name == slot.name) {
                return Err(file.err(format!("slot `{}` appears on more than one node", slot.name)));
            }
            slots.push(slot);
        }
        if slots.is_empty() {
            return Err(file.err("rig has no slots (nodes with a \"slot\" in their extras)"));
        }
        let shape = Arc::new(RigShape { hierarchy, slots, root });
        let cycles = animated
            .clips
            .into_iter()
            .map(|clip| {
                let stride = clip
                    .channel(root, Property::Translation)
                    .map_or(0.0, |c| c.sample_vec3(clip.end).z - c.sample_vec3(clip.start).z);
                Cycle { shape: shape.clone(), clip, stride }
            })
            .collect();
        Ok(Rig { path: file.path, shape, cycles })
    }

    /// Slots in node order (stable).
    pub fn slots(&self) -> &[Slot] {
        &self.shape.slots
    }

    /// The node tree.
    pub fn hierarchy(&self) -> &Hierarchy {
        &self.shape.hierarchy
    }

    /// Index of the root-motion node.
    pub fn root(&self) -> usize {
        self.shape.root
    }

    /// The rig's own name: its top node, the parent of `root`, when the
    /// file names one (docs/wardrobes.md "Rig glTF").
    pub(crate) fn name_in_file(&self) -> Option<&str> {
        let h = &self.shape.hierarchy;
        let top = h.nodes.get(self.shape.root)?.parent.and_then(|p| h.nodes.get(p))?;
        // Unnamed nodes are labelled `#index`.
        (!top.name.starts_with('#')).then_some(top.name.as_str())
    }

    /// All cycles, in file order.
    pub(crate) fn cycles(&self) -> &[Cycle] {
        &self.cycles
    }

    /// The cycle named `name`; the error lists the rig's cycles.
    pub fn cycle(&self, name: &str) -> Result<&Cycle> {
        self.cycles.iter().find(|c| c.clip.name == name).ok_or_else(|| {
            let names: Vec<&str> = self.cycles.iter().map(|c| c.clip.name.as_str()).collect();
            Error::invalid(&self.path, format!("rig has no cycle `{name}`; cycles: {}", names.join(", ")))
        })
    }

    /// The rest pose (root X/Z stripped like any pose).
    pub fn rest_pose(&self) -> Pose {
        Pose::new(self.shape.clone(), self.shape.hierarchy.rest_pose())
    }

    /// Standing height in metres: the top of the proxy boxes in the rest
    /// pose (the feet are on y = 0).
    pub(crate) fn height(&self) -> f32 {
        let pose = self.rest_pose();
        pose.slot_transforms()
            .into_iter()
            .flat_map(|(i, m)| {
                let s = &self.slots()[i];
                crate::scene::box_corners(s.proxy_min, s.proxy_max).map(|p| m.transform_point3(p).y)
            })
            .fold(0.0f32, f32::max)
    }
}

impl Rig {
    /// Slots whose proxy box, posed at rest, is more than
    /// [`OVERSIZED_PROXY`] times the median slot's largest side (rigs of
    /// three or more slots): legal, but no body part is that much larger
    /// than the rest (a box in the wrong units, or a typo). Each with its
    /// side and the median, in metres.
    pub fn oversized_slots(&self) -> Vec<(&Slot, f32, f32)> {
        let sides: Vec<(usize, f32)> = self
            .rest_pose()
            .slot_transforms()
            .into_iter()
            .map(|(i, m)| {
                let s = &self.slots()[i];
                let corners = crate::scene::box_corners(s.proxy_min, s.proxy_max).map(|p| m.transform_point3(p));
                let lo = corners.iter().copied().fold(Vec3::INFINITY, Vec3::min);
                let hi = corners.iter().copied().fold(Vec3::NEG_INFINITY, Vec3::max);
                (i, (hi - lo).max_element())
            })
            .collect();
        if sides.len() < 3 {
            return Vec::new();
        }
        let mut sorted: Vec<f32> = sides.iter().map(|&(_, side)| side).collect();
        sorted.sort_by(f32::total_cmp);
        let median = sorted[sorted.len() / 2];
        sides
            .into_iter()
            .filter(|&(_, side)| side > OVERSIZED_PROXY * median)
            .map(|(i, side)| (&self.slots()[i], side, median))
            .collect()
    }
}

/// How many times the median slot's side a proxy box may be before loading
/// warns of it.
pub const OVERSIZED_PROXY: f32 = 10.0;

/// Largest coordinate, and side, of a slot's `proxy_box`, in the rig file's
/// units (a millimetre rig stands some 1800 units tall).
pub(crate) const MAX_PROXY_EXTENT: f32 = 1.0e6;

/// Reads a node's slot extras; `None` when the node is not a slot.
fn read_slot(file: &GltfFile, node: &gltf::Node) -> Result<Option<Slot>> {
    let Some(raw) = node.extras() else { return Ok(None) };
    let ctx = |msg: String| file.err(format!("node {}: {msg}", node_label(node)));
    let extras: serde_json::Value =
        serde_json::from_str(raw.get()).map_err(|e| ctx(format!("extras are not JSON: {e}")))?;
    let Some(slot) = extras.get("slot") else { return Ok(None) };
    let name = slot.as_str().ok_or_else(|| ctx("extras `slot` must be a string".into()))?;
    let (proxy_min, proxy_max) = match extras.get("proxy_box") {
        Some(b) => {
            let corner = |k: &str| -> Result<Vec3> {
                let v = b
                    .get(k)
                    .and_then(|v| v.as_array())
                    .ok_or_else(|| ctx(format!("proxy_box needs `{k}`: [x, y, z]")))?;
                let xyz: Vec<f32> = v.iter().filter_map(|x| x.as_f64()).map(|x| x as f32).collect();
                if xyz.len() != 3 || v.len() != 3 || xyz.iter().any(|x| !x.is_finite()) {
                    return Err(ctx(format!("proxy_box `{k}` must be three numbers")));
                }
                Ok(Vec3::new(xyz[0], xyz[1], xyz[2]))
            };
            let (lo, hi) = (corner("min")?, corner("max")?);
            if lo.cmpgt(hi).any() {
                return Err(ctx(format!("proxy_box min {lo} exceeds max {hi}")));
            }
            // A box this large is no body part (a typo or a corrupt file):
            // its extent would overflow and it would vanish from the trace.
            if (hi - lo).max_element() > MAX_PROXY_EXTENT || lo.abs().max(hi.abs()).max_element() > MAX_PROXY_EXTENT {
                return Err(ctx(format!(
                    "proxy_box from {lo} to {hi} reaches past {MAX_PROXY_EXTENT} file units: no part of an agent is \
                     that large (a mistyped or corrupt box)"
                )));
            }
            (lo, hi)
        }
        None => {
            let mesh = node.mesh().ok_or_else(|| ctx(format!("slot `{name}` has neither a proxy_box nor a mesh")))?;
            read_mesh(file, &mesh, String::new())?.bounds()
        }
    };
    Ok(Some(Slot { name: name.to_string(), node: node.index(), proxy_min, proxy_max }))
}

/// A looping animation cycle of a rig.
#[derive(Clone, Debug)]
pub struct Cycle {
    shape: Arc<RigShape>,
    clip: Clip,
    stride: f32,
}

impl Cycle {
    /// Cycle name (the glTF animation name).
    pub(crate) fn name(&self) -> &str {
        &self.clip.name
    }

    /// Length in frames at `fps` (`duration * fps`).
    pub fn frames(&self, fps: f32) -> f32 {
        self.clip.duration() * fps
    }

    /// Metres the root travels along +Z over one cycle (0 without root translation).
    pub fn stride(&self) -> f32 {
        self.stride
    }

    /// Clip time in seconds for a cycle frame (wrapped, see the module docs).
    pub fn time(&self, frame: f32, fps: f32) -> f32 {
        let length = self.frames(fps);
        if !(length > 0.0 && frame.is_finite()) {
            return self.clip.start;
        }
        self.clip.start + frame.rem_euclid(length) / fps
    }

    /// The pose at cycle frame `frame` (fractional, wraps) at `fps`.
    pub fn sample(&self, frame: f32, fps: f32) -> Pose {
        let mut local = self.shape.hierarchy.rest_pose();
        self.clip.apply(self.time(frame, fps), &mut local);
        Pose::new(self.shape.clone(), local)
    }
}

/// Local transforms of every rig node at one instant, root motion stripped.
#[derive(Clone, Debug)]
pub struct Pose {
    shape: Arc<RigShape>,
    local: Vec<Trs>,
}

impl Pose {
    fn new(shape: Arc<RigShape>, mut local: Vec<Trs>) -> Pose {
        // The cache places the agent; keep only the root's vertical bob.
        if let Some(root) = local.get_mut(shape.root) {
            root.translation.x = 0.0;
            root.translation.z = 0.0;
        }
        Pose { shape, local }
    }

    /// Local (parent_from_node) transforms, by node index.
    pub fn local(&self) -> &[Trs] {
        &self.local
    }

    /// `rig_from_node` for every node.
    pub fn node_transforms(&self) -> Vec<Affine3A> {
        self.shape.hierarchy.compose(&self.local)
    }

    /// `(slot index, rig_from_slot)` for every slot, in [`Rig::slots`] order.
    pub fn slot_transforms(&self) -> Vec<(usize, Affine3A)> {
        let world = self.node_transforms();
        self.shape.slots.iter().enumerate().map(|(i, s)| (i, world[s.node])).collect()
    }
}

/// The walk cycle a trajectory import takes its stride and cycle length from.
/// Reads cycle `cycle` of the rig in `file`. A slot rig's name (its top
/// node, the parent of `root`) must be `rig` when the file gives one, so
/// the cache does not name one rig and walk at another's stride. A skinned
/// or rigid character (`skin` given, or detected: no slots) walks as a
/// shot's skinned rig with those options does (`shot_cache::file_gait`):
/// stride from its root joint's travel, a rigid rig's wheels or `strides`,
/// length from the clip. A `stride` given (the import's own, as a shot's
/// `strides` entry for the cycle) stands in for the file's, so a cycle whose
/// travel the file does not give is not refused then.
pub fn import_clip(
    file: &Path,
    rig: &str,
    cycle: &str,
    skin: Option<&SkinOptions>,
    stride: Option<f32>,
) -> Result<RigClip> {
    if kind::is_character_import(file, skin)? {
        let g = crate::casting::gait::skinned_file_gait(file, skin, cycle, None, stride)?;
        return Ok(RigClip { file: file.to_path_buf(), stride: g.stride, cycle_length: g.cycle_length });
    }
    let r = Rig::load(file)?;
    if let Some(top) = r.name_in_file().filter(|&top| top != rig) {
        return Err(Error::invalid(
            file,
            format!("this is rig `{top}` but the import names rig `{rig}`; import it as rig `{top}`"),
        )
        .field("rig"));
    }
    let c = r.cycle(cycle).map_err(|e| e.field("cycle"))?;
    let (stride, cycle_length) = (stride.unwrap_or(c.stride()), c.frames(SHOT_FPS));
    if !(stride.is_finite() && stride > 0.0) {
        return Err(Error::invalid(
            file,
            format!("cycle `{cycle}` has stride {stride} m (its root does not walk forward); pick a walk cycle or give the stride"),
        )
        .field("cycle"));
    }
    if !(cycle_length.is_finite() && cycle_length > 0.0) {
        return Err(Error::invalid(file, format!("cycle `{cycle}` is {cycle_length} frames long")).field("cycle"));
    }
    Ok(RigClip { file: file.to_path_buf(), stride, cycle_length })
}
