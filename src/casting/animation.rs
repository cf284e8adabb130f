//! Any glTF file's node hierarchy and node animations ([`Animated`]:
//! [`Clip`]s of [`Channel`]s), sampled with the glTF rules: STEP, LINEAR
//! (shortest-path slerp for rotations) and CUBICSPLINE (Hermite, tangents
//! scaled by the key interval). Times before the first key clamp to the
//! first key, after the last key to the last. Slot rigs (`casting::rig`)
//! and characters (`casting::skin`) are both posed from it.

use std::path::{Path, PathBuf};

use glam::{Affine3A, Quat, Vec3, Vec4};
use gltf::accessor::{DataType, Dimensions};

use crate::error::{Error, Result};
use crate::scene::gltf::{check_accessor, node_label, out_of_range, quat_from_gltf, GltfFile};

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
        Ok(Self::ordered(nodes, &children))
    }

    /// A hierarchy of `nodes` whose parents are given (a UsdSkel skeleton's
    /// joints): each node's children in index order.
    pub(crate) fn new(nodes: Vec<Node>) -> Hierarchy {
        let mut children = vec![Vec::new(); nodes.len()];
        for (i, n) in nodes.iter().enumerate() {
            if let Some(c) = n.parent.and_then(|p| children.get_mut(p)) {
                c.push(i);
            }
        }
        Self::ordered(nodes, &children)
    }

    /// `nodes` with every parent ordered before its children, breadth-first.
    fn ordered(nodes: Vec<Node>, children: &[Vec<usize>]) -> Hierarchy {
        let mut order: Vec<usize> = (0..nodes.len()).filter(|&i| nodes[i].parent.is_none()).collect();
        let mut next = 0;
        while let Some(&at) = order.get(next) {
            order.extend(&children[at]);
            next += 1;
        }
        Hierarchy { nodes, order }
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
