//! Doubts about where a shot's crowd stands, printed by `throng layers`:
//! bounds that look like the wrong units, and agents standing inside closed
//! set geometry (a building), which usually means the crowd needs the
//! `[cache]` placement keys (docs/shot.md).

use std::collections::{BTreeSet, HashSet};

use glam::Vec3;

use crate::cache::{bounds_warning, Bounds};
use crate::casting::ShotCrowd;
use crate::error::Result;

/// Shot frames sampled for the checks (evenly spread), so a long shot
/// against a large set stays quick.
pub(crate) const CHECK_FRAMES: usize = 48;
/// Height above the feet that is tested for being inside geometry: the
/// torso, clear of floors, kerbs and ground planes.
pub(crate) const TORSO_HEIGHT: f32 = 1.0;
/// Agent ids a warning lists.
pub(crate) const LISTED_IDS: usize = 5;

/// What the checks found.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PlacementReport {
    /// The bounds warning, if the units look wrong.
    pub(crate) bounds: Option<String>,
    /// Agents inside set geometry at some checked frame, in id order.
    pub(crate) inside_set: Vec<u32>,
}

impl PlacementReport {
    /// Lines to print, each one warning.
    pub fn warnings(&self) -> Vec<String> {
        let mut out: Vec<String> = self.bounds.iter().cloned().collect();
        if !self.inside_set.is_empty() {
            let ids: Vec<String> = self.inside_set.iter().take(LISTED_IDS).map(u32::to_string).collect();
            let more = if self.inside_set.len() > LISTED_IDS { ", ..." } else { "" };
            out.push(format!(
                "{} agents stand inside set geometry (ids {}{more}); place the crowd with the [cache] keys translate, rotate and scale",
                self.inside_set.len(),
                ids.join(", ")
            ));
        }
        out
    }
}

/// One closed piece of the set in world space.
struct Solid {
    lo: Vec3,
    hi: Vec3,
    triangles: Vec<[Vec3; 3]>,
}

/// Ray along a direction no set is likely aligned with, from `p`: whether
/// it crosses the triangle (Moller-Trumbore).
fn crosses(p: Vec3, dir: Vec3, [a, b, c]: [Vec3; 3]) -> bool {
    let (e1, e2) = (b - a, c - a);
    let h = dir.cross(e2);
    let det = e1.dot(h);
    if det.abs() < 1e-12 {
        return false;
    }
    let s = p - a;
    let u = s.dot(h) / det;
    if !(0.0..=1.0).contains(&u) {
        return false;
    }
    let q = s.cross(e1);
    let v = dir.dot(q) / det;
    if v < 0.0 || u + v > 1.0 {
        return false;
    }
    e2.dot(q) / det > 0.0
}

/// Checks the shot's crowd at up to [`CHECK_FRAMES`] frames.
pub fn check_placement(crowd: &ShotCrowd) -> Result<PlacementReport> {
    let lib = crowd.library();
    let solids: Vec<Solid> = crowd
        .set()
        .iter()
        .filter_map(|inst| {
            let mesh = lib.meshes.get(inst.mesh as usize)?;
            let world: Vec<Vec3> = mesh.positions.iter().map(|&p| inst.world_from_object.transform_point3(p)).collect();
            let triangles: Vec<[Vec3; 3]> = mesh
                .indices
                .chunks_exact(3)
                .filter_map(|t| {
                    Some([*world.get(t[0] as usize)?, *world.get(t[1] as usize)?, *world.get(t[2] as usize)?])
                })
                .collect();
            let lo = world.iter().copied().reduce(Vec3::min)?;
            let hi = world.iter().copied().reduce(Vec3::max)?;
            Some(Solid { lo, hi, triangles })
        })
        .collect();
    let frames: Vec<i32> = crowd.shot().frames.iter().collect();
    let step = frames.len().div_ceil(CHECK_FRAMES).max(1);
    let dir = Vec3::new(1.0, 0.001_37, 0.000_71).normalize();
    let mut inside = BTreeSet::new();
    let mut ids = HashSet::new();
    let mut bounds: Option<Bounds> = None;
    for &f in frames.iter().step_by(step) {
        for a in crowd.agents_at(f)?.agents.iter().filter(|a| !a.hidden()) {
            ids.insert(a.id);
            let p = a.position.to_array();
            let b = bounds.get_or_insert(Bounds { min: p, max: p });
            b.min = Vec3::from(b.min).min(a.position).to_array();
            b.max = Vec3::from(b.max).max(a.position).to_array();
            if inside.contains(&a.id) {
                continue;
            }
            let torso = a.position + Vec3::Y * TORSO_HEIGHT;
            // Inside a solid's box and an odd number of its faces ahead: inside
            // it. Open pieces (a ground plane, a lone wall) have thin boxes.
            let hit = solids.iter().any(|s| {
                torso.cmpge(s.lo).all()
                    && torso.cmple(s.hi).all()
                    && s.triangles.iter().filter(|&&t| crosses(torso, dir, t)).count() % 2 == 1
            });
            if hit {
                inside.insert(a.id);
            }
        }
    }
    Ok(PlacementReport {
        bounds: bounds.and_then(|b| bounds_warning(&b, ids.len())),
        inside_set: inside.into_iter().collect(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ray_parity_in_a_cube() {
        // Unit cube faces as triangles.
        let c = |x: f32, y: f32, z: f32| Vec3::new(x, y, z);
        let quads = [
            [c(0., 0., 0.), c(1., 0., 0.), c(1., 1., 0.), c(0., 1., 0.)],
            [c(0., 0., 1.), c(1., 0., 1.), c(1., 1., 1.), c(0., 1., 1.)],
            [c(0., 0., 0.), c(0., 1., 0.), c(0., 1., 1.), c(0., 0., 1.)],
            [c(1., 0., 0.), c(1., 1., 0.), c(1., 1., 1.), c(1., 0., 1.)],
            [c(0., 0., 0.), c(1., 0., 0.), c(1., 0., 1.), c(0., 0., 1.)],
            [c(0., 1., 0.), c(1., 1., 0.), c(1., 1., 1.), c(0., 1., 1.)],
        ];
        let tris: Vec<[Vec3; 3]> = quads.iter().flat_map(|q| [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]).collect();
        let dir = Vec3::new(1.0, 0.001_37, 0.000_71).normalize();
        let count = |p: Vec3| tris.iter().filter(|&&t| crosses(p, dir, t)).count();
        assert_eq!(count(c(0.5, 0.5, 0.5)) % 2, 1);
        assert_eq!(count(c(-0.5, 0.5, 0.5)) % 2, 0);
    }
}
