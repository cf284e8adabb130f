//! Body proportions (`[rigs.NAME.proportions]`, docs/wardrobes.md): a
//! character rig's bodies, each a seeded draw of bone length and girth per
//! joint group, the skinned form of the Robots head rule (the head's joints
//! and everything below them are never stretched; they scale uniformly with
//! the agent's height like the rest of it).
//!
//! A body scales each grouped joint's geometry in the joint's own frame: by
//! its group's length along the bone (towards its children) and by its
//! girth across it. A joint's children ride the stretched bone, so their
//! offsets from it are scaled the same way, and a longer thigh carries the
//! shin, foot and toes out with it without stretching them. A body is drawn
//! per (seed, rig, body index, group), never per agent: agents play one of
//! the rig's `bodies` and share its pose steps, so posed geometry grows with
//! bodies, not agents. Body 0 is the rig as modelled.

use std::collections::BTreeSet;
use std::path::Path;

use glam::{Mat3, Vec3};

use crate::casting::animation::Hierarchy;
use crate::error::{Error, Result};
use crate::seed::uniform;
use crate::shot::Proportions;

/// One body of a rig (index 1 and up; 0 is the rig as modelled).
#[derive(Debug, Clone)]
pub(crate) struct Body {
    /// Per node: its bone's scale in its own frame (identity outside the groups).
    pub(crate) bone: Vec<Mat3>,
    /// Standing height in metres (rest pose, before height jitter).
    pub(crate) height: f32,
    /// The `legs` group's length factor: the body's strides are the
    /// modelled strides times this (1 without `legs`).
    pub(crate) stride: f32,
    /// (group, length factor, girth factor) as drawn, in group name order.
    pub(crate) draws: Vec<(String, f32, f32)>,
}

/// A factor drawn from 1 +/- `spread` for (seed, body, stream).
fn factor(seed: u64, body: u16, stream: &str, spread: f32) -> f32 {
    if spread == 0.0 {
        return 1.0;
    }
    1.0 + spread * (2.0 * uniform(seed, u32::from(body), stream) as f32 - 1.0)
}

/// Scale `length` along unit `axis` and `girth` across it.
fn bone_scale(axis: Vec3, length: f32, girth: f32) -> Mat3 {
    let outer = Mat3::from_cols(axis * axis.x, axis * axis.y, axis * axis.z);
    Mat3::from_diagonal(Vec3::splat(girth)) + outer * (length - girth)
}

/// The direction of node `n`'s bone in its own frame: towards its children
/// (their rest offsets summed), or for a joint with none, on along the
/// offset from its parent; +Y when neither gives one.
fn bone_axis(h: &Hierarchy, n: usize) -> Vec3 {
    let towards: Vec3 = h.nodes.iter().filter(|c| c.parent == Some(n)).map(|c| c.rest.translation).sum();
    if let Some(a) = towards.try_normalize() {
        return a;
    }
    let rest = h.nodes[n].rest;
    let local = (Mat3::from_quat(rest.rotation) * Mat3::from_diagonal(rest.scale)).inverse() * rest.translation;
    local.try_normalize().unwrap_or(Vec3::Y)
}

/// Every body's bone scales (height 0, measured by the caller, which can
/// pose meshes), from the checked `spec` and the nodes of rig file `file`.
/// Errors name the file and the key under `proportions`: a joint the file
/// lacks, or one at or below the head.
pub(crate) fn draw(file: &Path, rig_name: &str, spec: &Proportions, seed: u64, h: &Hierarchy) -> Result<Vec<Body>> {
    let key = |k: String| format!("proportions.{k}");
    let names = || h.nodes.iter().map(|n| n.name.as_str()).collect::<Vec<_>>().join(", ");
    let mut head: BTreeSet<usize> = BTreeSet::new();
    for (i, j) in spec.head.iter().enumerate() {
        let n = h.find(j).ok_or_else(|| {
            Error::invalid(file, format!("no joint `{j}` in the rig (joints: {})", names()))
                .field(key(format!("head[{i}]")))
        })?;
        head.insert(n);
    }
    // Below the head: a node any of whose ancestors is a head joint.
    let under_head = |mut n: usize| loop {
        if head.contains(&n) {
            return true;
        }
        match h.nodes[n].parent {
            Some(p) => n = p,
            None => return false,
        }
    };
    let mut grouped: Vec<(usize, &str)> = Vec::new();
    for (g, group) in &spec.groups {
        for (i, j) in group.joints.iter().enumerate() {
            let field = key(format!("groups.{g}.joints[{i}]"));
            let n = h.find(j).ok_or_else(|| {
                Error::invalid(file, format!("no joint `{j}` in the rig (joints: {})", names())).field(field.clone())
            })?;
            if under_head(n) {
                return Err(Error::invalid(
                    file,
                    format!("joint `{j}` is the head's or below it: the head scales uniformly with the body"),
                )
                .field(field));
            }
            grouped.push((n, g));
        }
    }
    let axes: Vec<(usize, &str, Vec3)> = grouped.iter().map(|&(n, g)| (n, g, bone_axis(h, n))).collect();
    let mut bodies = Vec::with_capacity(spec.bodies as usize);
    for b in 1..=spec.bodies {
        let draws: Vec<(String, f32, f32)> = (spec.groups.iter())
            .map(|(g, group)| {
                let length = factor(seed, b, &format!("proportions/{rig_name}/{g}/length"), group.length);
                let girth = factor(seed, b, &format!("proportions/{rig_name}/{g}/girth"), group.girth);
                (g.clone(), length, girth)
            })
            .collect();
        let mut bone = vec![Mat3::IDENTITY; h.nodes.len()];
        for &(n, g, axis) in &axes {
            let Some((_, length, girth)) = draws.iter().find(|d| d.0 == g) else { continue };
            bone[n] = bone_scale(axis, *length, *girth);
        }
        let stride = (spec.legs.as_ref()).and_then(|legs| draws.iter().find(|d| &d.0 == legs)).map_or(1.0, |d| d.1);
        bodies.push(Body { bone, height: 0.0, stride, draws });
    }
    Ok(bodies)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bone_scale_stretches_along_and_across() {
        let axis = Vec3::new(0.0, 0.6, 0.8);
        let m = bone_scale(axis, 1.2, 0.9);
        assert!((m * axis - axis * 1.2).length() < 1e-6);
        let across = Vec3::new(1.0, 0.0, 0.0);
        assert!((m * across - across * 0.9).length() < 1e-6);
        let across = Vec3::new(0.0, 0.8, -0.6);
        assert!((m * across - across * 0.9).length() < 1e-6);
    }

    #[test]
    fn factors_are_keyed_and_within_the_spread() {
        let a = factor(3, 1, "proportions/r/legs/length", 0.1);
        assert_eq!(a, factor(3, 1, "proportions/r/legs/length", 0.1));
        assert_ne!(a, factor(3, 2, "proportions/r/legs/length", 0.1));
        assert_ne!(a, factor(4, 1, "proportions/r/legs/length", 0.1));
        for b in 1..200 {
            let f = factor(9, b, "x", 0.1);
            assert!((0.9..=1.1).contains(&f), "{f}");
        }
        assert_eq!(factor(9, 1, "x", 0.0), 1.0);
    }
}
