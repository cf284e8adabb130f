//! Rigs and their animation cycles, loaded from glTF (SPEC "Rig glTF").
//!
//! Two levels:
//! - [`Animated`]: any glTF file's node hierarchy and node animations
//!   ([`Clip`]s of [`Channel`]s), sampled with the glTF rules: STEP, LINEAR
//!   (shortest-path slerp for rotations) and CUBICSPLINE (Hermite, tangents
//!   scaled by the key interval). Times before the first key clamp to the
//!   first key, after the last key to the last.
//! - [`Rig`]: an [`Animated`] file with slots and a `root` node, whose clips
//!   are looping [`Cycle`]s sampled by cycle frame.
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

use glam::{Affine3A, Quat, Vec3, Vec4};
use gltf::accessor::{DataType, Dimensions};

use crate::cache::jupedsim::{RigClip, SHOT_FPS};
use crate::error::{Error, Result};
use crate::scene::gltf::{check_accessor, node_label, out_of_range, quat_from_gltf, read_mesh, GltfFile};
use crate::shot::SkinOptions;

/// A translation, rotation and scale (glTF node transform order T * R * S).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Trs {
    /// Translation.
    pub(crate) translation: Vec3,
    /// Unit rotation.
    pub rotation: Quat,
    /// Non-uniform scale.
    pub(crate) scale: Vec3,
}

impl Default for Trs {
    fn default() -> Self {
        Trs { translation: Vec3::ZERO, rotation: Quat::IDENTITY, scale: Vec3::ONE }
    }
}

impl Trs {
    /// As an affine transform (parent_from_node).
    pub(crate) fn affine(&self) -> Affine3A {
        Affine3A::from_scale_rotation_translation(self.scale, self.rotation, self.translation)
    }
}

/// A node of the hierarchy.
#[derive(Clone, Debug)]
pub struct Node {
    /// Node name (`#index` when the file gives none).
    pub name: String,
    /// Parent node index; `None` for top-level nodes.
    pub(crate) parent: Option<usize>,
    /// Rest transform relative to the parent.
    pub(crate) rest: Trs,
}

/// The node tree of a glTF file.
#[derive(Clone, Debug)]
pub struct Hierarchy {
    /// Nodes in file order (indices match the glTF node indices).
    pub nodes: Vec<Node>,
    /// Node indices with every parent before its children.
    order: Vec<usize>,
}

impl Hierarchy {
    fn load(file: &GltfFile) -> Result<Hierarchy> {
        let parents = file.parents()?;
        let nodes: Vec<Node> = file
            .doc
            .nodes()
            .map(|n| {
                let (t, r, s) = n.transform().decomposed();
                Node {
                    name: n.name().map(str::to_string).unwrap_or_else(|| format!("#{}", n.index())),
                    parent: parents[n.index()],
                    rest: Trs { translation: Vec3::from(t), rotation: quat_from_gltf(r), scale: Vec3::from(s) },
                }
            })
            .collect();
        // Breadth-first from the top-level nodes: parents come first.
        let children: Vec<Vec<usize>> = file.doc.nodes().map(|n| n.children().map(|c| c.index()).collect()).collect();
        let mut order: Vec<usize> = (0..nodes.len()).filter(|&i| nodes[i].parent.is_none()).collect();
        let mut next = 0;
        while let Some(&at) = order.get(next) {
            order.extend(&children[at]);
            next += 1;
        }
        Ok(Hierarchy { nodes, order })
    }

    /// Index of the first node named `name`.
    pub(crate) fn find(&self, name: &str) -> Option<usize> {
        self.nodes.iter().position(|n| n.name == name)
    }

    /// Every node's rest transform.
    pub(crate) fn rest_pose(&self) -> Vec<Trs> {
        self.nodes.iter().map(|n| n.rest).collect()
    }

    /// Composes local transforms down the tree: `top_from_node` for every
    /// node (the space of the top-level nodes' parent).
    pub(crate) fn compose(&self, local: &[Trs]) -> Vec<Affine3A> {
        let mut world = vec![Affine3A::IDENTITY; self.nodes.len()];
        for &i in &self.order {
            let local = local.get(i).copied().unwrap_or(self.nodes[i].rest).affine();
            world[i] = match self.nodes[i].parent {
                Some(p) => world[p] * local,
                None => local,
            };
        }
        world
    }

    /// [`Hierarchy::compose`] with every node's offset from its parent
    /// scaled by the parent's `bone` (a body's proportions,
    /// `casting::body`): a lengthened bone carries its children out with it
    /// without stretching them.
    pub(crate) fn compose_scaled(&self, local: &[Trs], bone: &[glam::Mat3]) -> Vec<Affine3A> {
        let mut world = vec![Affine3A::IDENTITY; self.nodes.len()];
        for &i in &self.order {
            let mut trs = local.get(i).copied().unwrap_or(self.nodes[i].rest);
            let parent = self.nodes[i].parent;
            if let Some(b) = parent.and_then(|p| bone.get(p)) {
                trs.translation = *b * trs.translation;
            }
            world[i] = match parent {
                Some(p) => world[p] * trs.affine(),
                None => trs.affine(),
            };
        }
        world
    }
}

/// Which node property a channel drives.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Property {
    /// Translation (xyz in a [`Vec4`], w = 0).
    Translation,
    /// Rotation quaternion (xyzw).
    Rotation,
    /// Scale (xyz, w = 0).
    Scale,
}

/// glTF sampler interpolation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Interpolation {
    /// Hold the previous key.
    Step,
    /// Linear (slerp for rotations).
    Linear,
    /// Cubic Hermite spline with in/out tangents per key.
    CubicSpline,
}

/// One animated property of one node.
#[derive(Clone, Debug)]
pub struct Channel {
    /// Target node index.
    pub node: usize,
    /// Animated property.
    pub property: Property,
    /// Interpolation between keys.
    pub interpolation: Interpolation,
    /// Key times in seconds, strictly increasing.
    pub times: Vec<f32>,
    /// Key values: one per key, or for [`Interpolation::CubicSpline`] three
    /// per key (in-tangent, value, out-tangent), as glTF stores them.
    pub values: Vec<Vec4>,
}

impl Channel {
    fn key(&self, i: usize) -> Vec4 {
        match self.interpolation {
            Interpolation::CubicSpline => self.values[3 * i + 1],
            _ => self.values[i],
        }
    }

    /// The value at `t` seconds (clamped to the first and last keys).
    /// Rotations come back normalised.
    pub(crate) fn sample(&self, t: f32) -> Vec4 {
        let v = self.sample_raw(t);
        if self.property == Property::Rotation {
            v.try_normalize().unwrap_or(Vec4::W)
        } else {
            v
        }
    }

    fn sample_raw(&self, t: f32) -> Vec4 {
        let n = self.times.len();
        if n == 1 || t.is_nan() || t <= self.times[0] {
            return self.key(0);
        }
        if t >= self.times[n - 1] {
            return self.key(n - 1);
        }
        // times[i] <= t < times[i + 1]; i >= 0 because t > times[0].
        let i = self.times.partition_point(|&k| k <= t) - 1;
        let dt = self.times[i + 1] - self.times[i];
        let u = (t - self.times[i]) / dt;
        match self.interpolation {
            Interpolation::Step => self.key(i),
            Interpolation::Linear if self.property == Property::Rotation => slerp(self.key(i), self.key(i + 1), u),
            Interpolation::Linear => self.key(i).lerp(self.key(i + 1), u),
            Interpolation::CubicSpline => {
                let p0 = self.values[3 * i + 1];
                let m0 = self.values[3 * i + 2] * dt; // out-tangent of key i
                let p1 = self.values[3 * (i + 1) + 1];
                let m1 = self.values[3 * (i + 1)] * dt; // in-tangent of key i + 1
                let (u2, u3) = (u * u, u * u * u);
                p0 * (2.0 * u3 - 3.0 * u2 + 1.0)
                    + m0 * (u3 - 2.0 * u2 + u)
                    + p1 * (-2.0 * u3 + 3.0 * u2)
                    + m1 * (u3 - u2)
            }
        }
    }

    /// [`Channel::sample`] as a quaternion (for rotation channels).
    pub fn sample_quat(&self, t: f32) -> Quat {
        Quat::from_vec4(self.sample(t))
    }

    /// [`Channel::sample`] as a vector (for translation and scale channels).
    pub fn sample_vec3(&self, t: f32) -> Vec3 {
        self.sample(t).truncate()
    }
}

/// Spherical interpolation of unit quaternions (xyzw in a [`Vec4`]) along
/// the shorter arc.
fn slerp(a: Vec4, b: Vec4, u: f32) -> Vec4 {
    let mut dot = a.dot(b);
    // q and -q are the same rotation; flip one so we take the short way round.
    let b = if dot < 0.0 {
        dot = -dot;
        -b
    } else {
        b
    };
    if dot > 0.9995 {
        // Nearly parallel: sin(theta) ~ 0, a normalised lerp is exact enough.
        return a.lerp(b, u).normalize_or(Vec4::W);
    }
    let theta = dot.min(1.0).acos();
    let s = theta.sin();
    (a * ((1.0 - u) * theta).sin() / s + b * (u * theta).sin() / s).normalize_or(Vec4::W)
}

/// A named glTF animation: channels over node properties.
#[derive(Clone, Debug)]
pub struct Clip {
    /// Animation name (`#index` when unnamed).
    pub name: String,
    /// Node property channels (morph-weight channels are skipped).
    pub channels: Vec<Channel>,
    /// Earliest key time over all channels, seconds.
    pub start: f32,
    /// Latest key time over all channels, seconds.
    pub end: f32,
}

impl Clip {
    /// `end - start`, seconds.
    pub(crate) fn duration(&self) -> f32 {
        self.end - self.start
    }

    /// Overwrites the animated properties of `pose` (local TRS per node) with
    /// their values at `t` seconds; other properties keep their values.
    pub(crate) fn apply(&self, t: f32, pose: &mut [Trs]) {
        for ch in &self.channels {
            let Some(trs) = pose.get_mut(ch.node) else { continue };
            match ch.property {
                Property::Translation => trs.translation = ch.sample_vec3(t),
                Property::Rotation => trs.rotation = ch.sample_quat(t),
                Property::Scale => trs.scale = ch.sample_vec3(t),
            }
        }
    }

    /// The channel driving `property` of node `node`, if any.
    pub(crate) fn channel(&self, node: usize, property: Property) -> Option<&Channel> {
        self.channels.iter().find(|c| c.node == node && c.property == property)
    }

    fn load(file: &GltfFile, anim: &gltf::Animation) -> Result<Clip> {
        let name = anim.name().map(str::to_string).unwrap_or_else(|| format!("#{}", anim.index()));
        let mut channels = Vec::new();
        for ch in anim.channels() {
            let target = ch.target().node();
            let ctx = |msg: String| {
                file.err(format!("animation `{name}` channel {} (node {}): {msg}", ch.index(), node_label(&target)))
            };
            let property = match ch.target().property() {
                gltf::animation::Property::Translation => Property::Translation,
                gltf::animation::Property::Rotation => Property::Rotation,
                gltf::animation::Property::Scale => Property::Scale,
                // Rigs are rigid; morph weights do not move nodes.
                gltf::animation::Property::MorphTargetWeights => continue,
            };
            let sampler = ch.sampler();
            let interpolation = match sampler.interpolation() {
                gltf::animation::Interpolation::Step => Interpolation::Step,
                gltf::animation::Interpolation::Linear => Interpolation::Linear,
                gltf::animation::Interpolation::CubicSpline => Interpolation::CubicSpline,
            };
            let reader = ch.reader(|b| file.buffer_data(b));
            let input = sampler.input();
            check_accessor(&input, Dimensions::Scalar, &[DataType::F32]).map_err(ctx)?;
            let times: Vec<f32> = reader.read_inputs().ok_or_else(|| ctx(out_of_range(&input)))?.collect();
            if times.iter().any(|t| !t.is_finite()) {
                return Err(ctx("key time is not a finite number".into()));
            }
            if let Some(w) = times.windows(2).find(|w| w[1] <= w[0]) {
                return Err(ctx(format!("key times must increase ({} then {})", w[0], w[1])));
            }
            let output = sampler.output();
            let values: Vec<Vec4> = match property {
                Property::Rotation => {
                    let types = [DataType::F32, DataType::I8, DataType::U8, DataType::I16, DataType::U16];
                    check_accessor(&output, Dimensions::Vec4, &types).map_err(ctx)?;
                    match reader.read_outputs() {
                        Some(gltf::animation::util::ReadOutputs::Rotations(r)) => {
                            r.into_f32().map(Vec4::from).collect()
                        }
                        _ => return Err(ctx(out_of_range(&output))),
                    }
                }
                Property::Translation | Property::Scale => {
                    check_accessor(&output, Dimensions::Vec3, &[DataType::F32]).map_err(ctx)?;
                    match reader.read_outputs() {
                        Some(gltf::animation::util::ReadOutputs::Translations(v))
                        | Some(gltf::animation::util::ReadOutputs::Scales(v)) => {
                            v.map(|v| Vec3::from(v).extend(0.0)).collect()
                        }
                        _ => return Err(ctx(out_of_range(&output))),
                    }
                }
            };
            let per_key = if interpolation == Interpolation::CubicSpline { 3 } else { 1 };
            if values.len() != times.len() * per_key {
                return Err(ctx(format!(
                    "{} output values for {} keys ({interpolation:?} needs {per_key} per key)",
                    values.len(),
                    times.len()
                )));
            }
            if values.iter().any(|v| !v.is_finite()) {
                return Err(ctx("output value is not a finite number".into()));
            }
            channels.push(Channel { node: target.index(), property, interpolation, times, values });
        }
        // check_accessor guarantees at least one key per channel.
        let start = channels.iter().map(|c| c.times[0]).fold(f32::INFINITY, f32::min);
        let end = channels.iter().map(|c| c.times[c.times.len() - 1]).fold(f32::NEG_INFINITY, f32::max);
        let (start, end) = if channels.is_empty() { (0.0, 0.0) } else { (start, end) };
        Ok(Clip { name, channels, start, end })
    }
}

/// Any glTF file's node hierarchy and node animations.
#[derive(Clone, Debug)]
pub struct Animated {
    /// The file.
    pub(crate) path: PathBuf,
    /// Its nodes.
    pub hierarchy: Hierarchy,
    /// Its animations, in file order.
    pub clips: Vec<Clip>,
}

impl Animated {
    /// Loads the nodes and animations of `path` (no images are decoded).
    pub fn load(path: impl AsRef<Path>) -> Result<Animated> {
        let file = GltfFile::open(path)?;
        Self::from_file(&file)
    }

    /// The nodes and animations of an already opened file.
    pub(crate) fn from_file(file: &GltfFile) -> Result<Animated> {
        let hierarchy = Hierarchy::load(file)?;
        let clips = file.doc.animations().map(|a| Clip::load(file, &a)).collect::<Result<Vec<_>>>()?;
        Ok(Animated { path: file.path.clone(), hierarchy, clips })
    }

    /// The clip named `name`; the error lists the clips in the file.
    pub fn clip(&self, name: &str) -> Result<&Clip> {
        self.clips.iter().find(|c| c.name == name).ok_or_else(|| {
            let names: Vec<&str> = self.clips.iter().map(|c| c.name.as_str()).collect();
            Error::invalid(&self.path, format!("no animation `{name}`; animations in this file: {}", names.join(", ")))
        })
    }
}

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
        if crate::casting::skin::is_skinned(&file) && !has_slots(&file) {
            return Err(crate::casting::skin::skinned_refusal(&file.path, "this rig"));
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

/// Whether any node of the file is a slot (extras with a `"slot"` key):
/// what tells a slot rig from a skinned character when both have a skin.
pub(crate) fn has_slots(file: &GltfFile) -> bool {
    file.doc.nodes().any(|n| {
        n.extras()
            .as_ref()
            .is_some_and(|e| serde_json::from_str::<serde_json::Value>(e.get()).is_ok_and(|v| v.get("slot").is_some()))
    })
}

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
    if crate::casting::shot_cache::is_character_file(file, skin)? {
        let g = crate::casting::shot_cache::skinned_file_gait(file, skin, cycle, None, stride)?;
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
