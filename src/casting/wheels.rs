//! A vehicle's wheels: a rigid rig's animated nodes that roll.
//!
//! A wheel of a clip is a node whose rotation channel turns it about one
//! axle, within [`MAX_AXLE_TILT`] of the agent's side axis (rig X), a whole
//! number of turns over the clip (the clip loops), with a mesh on the node
//! or below it. Its radius is its meshes' farthest vertex from the axle at
//! the clip's start. A cycle then rolls `turns * 2 pi * radius` metres: that
//! is its stride when the shot gives none and no root node travels, and
//! since the cache advances a cycle by distance walked / stride, the wheel
//! spins at speed / radius radians a second. The first wheel in node order
//! sets the stride; one that would roll another distance slides, and
//! loading warns of it.

use glam::{Affine3A, Quat, Vec3};

use crate::casting::animation::{Channel, Clip, Hierarchy, Property};

/// How far a wheel's axle may lean off the agent's side axis (rig X).
pub(crate) const MAX_AXLE_TILT_DEG: f32 = 25.0;
const MAX_AXLE_TILT: f32 = MAX_AXLE_TILT_DEG * std::f32::consts::PI / 180.0;
/// How far from a whole number of turns a looping wheel may end.
const TURN_TOLERANCE: f32 = 0.02;
/// Two wheels' strides may differ by this fraction before one is said to slide.
const SLIDE_TOLERANCE: f32 = 0.02;

/// One wheel of a clip.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Wheel {
    /// The wheel's node.
    pub(crate) node: usize,
    /// Whole turns over the clip (either way round).
    pub(crate) turns: u32,
    /// Metres from the axle to the wheel's rim, in rig space.
    pub(crate) radius: f32,
}

impl Wheel {
    /// Metres the wheel rolls over one cycle.
    pub(crate) fn roll(&self) -> f32 {
        self.turns as f32 * std::f32::consts::TAU * self.radius
    }
}

/// The wheels of `clip`: `joints` are `rig_from_node` at the clip's start,
/// `meshes` each rigid mesh's node and its rig-space vertices there.
pub(crate) fn wheels(
    clip: &Clip,
    hierarchy: &Hierarchy,
    joints: &[Affine3A],
    meshes: &[(usize, Vec<Vec3>)],
) -> Vec<Wheel> {
    let mut found: Vec<Wheel> = Vec::new();
    for ch in clip.channels.iter().filter(|c| c.property == Property::Rotation) {
        let Some((turns, local_axis)) = whole_turns(ch, clip.start, clip.end) else { continue };
        let Some(&rig_from_node) = joints.get(ch.node) else { continue };
        let Some(axle) = rig_from_node.transform_vector3(local_axis).try_normalize() else { continue };
        if axle.x.abs() < MAX_AXLE_TILT.cos() {
            continue;
        }
        let origin = Vec3::from(rig_from_node.translation);
        let radius = meshes
            .iter()
            .filter(|(node, _)| under(hierarchy, *node, ch.node))
            .flat_map(|(_, vertices)| vertices.iter())
            .map(|v| {
                let d = *v - origin;
                (d - d.dot(axle) * axle).length()
            })
            .fold(0.0f32, f32::max);
        if radius > 0.0 && radius.is_finite() && !found.iter().any(|w| w.node == ch.node) {
            found.push(Wheel { node: ch.node, turns, radius });
        }
    }
    found.sort_by_key(|w| w.node);
    found
}

/// The stride the wheels give (the first wheel's roll), and the wheels that
/// would roll another distance (they slide).
pub(crate) fn stride(wheels: &[Wheel]) -> Option<(f32, Vec<&Wheel>)> {
    let first = wheels.first()?.roll();
    let sliding = wheels.iter().filter(|w| (w.roll() - first).abs() > SLIDE_TOLERANCE * first).collect();
    Some((first, sliding))
}

/// Whether node `node` is `top` or below it.
fn under(hierarchy: &Hierarchy, node: usize, top: usize) -> bool {
    let mut at = Some(node);
    while let Some(n) = at {
        if n == top {
            return true;
        }
        at = hierarchy.nodes.get(n).and_then(|h| h.parent);
    }
    false
}

/// The whole turns a rotation channel makes over `[start, end]` about one
/// axis (in the node's own frame), `None` unless it turns about a single
/// axis a whole number of times (at least one). Sampled four times a key
/// interval (at least 64 times), each sample's turn from the last taken the
/// short way round, as the sampler interpolates.
fn whole_turns(ch: &Channel, start: f32, end: f32) -> Option<(u32, Vec3)> {
    let samples = (ch.times.len() * 4).clamp(64, 4096);
    let mut previous: Quat = ch.sample_quat(start);
    let (mut axis, mut angle) = (None::<Vec3>, 0.0f32);
    for i in 1..=samples {
        let q = ch.sample_quat(start + (end - start) * i as f32 / samples as f32);
        let mut d = previous.inverse() * q;
        previous = q;
        if d.w < 0.0 {
            d = -d;
        }
        let (a, turn) = d.to_axis_angle();
        if turn < 1e-6 {
            continue;
        }
        let along = *axis.get_or_insert(a);
        let cos = a.dot(along);
        if cos.abs() < 0.999 {
            return None;
        }
        angle += turn * cos.signum();
    }
    let turns = angle.abs() / std::f32::consts::TAU;
    let whole = turns.round();
    (whole >= 1.0 && (turns - whole).abs() <= TURN_TOLERANCE).then(|| (whole as u32, axis.unwrap_or(Vec3::X)))
}
