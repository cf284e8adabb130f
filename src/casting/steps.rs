//! The pose steps agents take: their records sampled between cache frames
//! (the rule of [`crate::casting::motion`]'s docs), a skinned agent's keys
//! at shutter open and close, and every step the shot's still frames and a
//! shutter need, which the pose library poses once at load.

use std::collections::{BTreeSet, HashMap};
use std::sync::Arc;

use crate::cache::{AgentSample, CacheReader, FrameBlock};
use crate::casting::cast::{Casting, PoseStep};
use crate::casting::rigs::ShotRigs;
use crate::casting::skin::SkinnedRig;
use crate::casting::timing::{cycle_delta, cycle_name, length_of, CycleTiming};
use crate::error::Result;
use crate::shot::Shot;

/// The cache records of an agent's neighbours.
pub(crate) struct Neighbours {
    pub(crate) prev: HashMap<u32, AgentSample>,
    pub(crate) next: HashMap<u32, AgentSample>,
}

fn block_map(block: Option<FrameBlock>) -> HashMap<u32, AgentSample> {
    block.map(|b| b.agents.into_iter().map(|a| (a.id, a)).collect()).unwrap_or_default()
}

impl Neighbours {
    pub(crate) fn read(shot: &Shot, cache: &CacheReader, timing: &CycleTiming, shot_frame: i32) -> Result<Neighbours> {
        let cf = shot.cache.cache_frame(shot_frame);
        let read = |f: Option<i32>| -> Result<Option<FrameBlock>> {
            match f {
                Some(f) if cache.frames().binary_search(&f).is_ok() => Ok(Some(timing.read(cache, f)?)),
                _ => Ok(None),
            }
        };
        Ok(Neighbours { prev: block_map(read(cf.checked_sub(1))?), next: block_map(read(cf.checked_add(1))?) })
    }
}

/// The shortest signed angle from `a` to `b`, radians in [-pi, pi].
pub(crate) fn shortest_arc(a: f32, b: f32) -> f32 {
    let tau = std::f32::consts::TAU;
    let d = (b - a).rem_euclid(tau);
    if d > std::f32::consts::PI {
        d - tau
    } else {
        d
    }
}

/// The agent record `a` (at the frame's cache frame) moved to sub-frame
/// offset `s` with the rule of the module docs. `prev` and `next` are its
/// records at the neighbouring cache frames, if there.
pub(crate) fn sample_at(
    a: &AgentSample,
    prev: Option<&AgentSample>,
    next: Option<&AgentSample>,
    s: f32,
    length: Option<f32>,
) -> AgentSample {
    if s == 0.0 {
        return *a;
    }
    // The neighbour on the side of `s` (sign +1), or the other one extrapolated (sign -1).
    let (toward, away) = if s > 0.0 { (next, prev) } else { (prev, next) };
    let (other, u) = match (toward, away) {
        (Some(o), _) => (o, s.abs()),
        (None, Some(o)) => (o, -s.abs()),
        (None, None) => return *a,
    };
    let cycle_frame = if other.cycle == a.cycle {
        a.cycle_frame + cycle_delta(a.cycle_frame, other.cycle_frame, length) * u
    } else {
        a.cycle_frame + s
    };
    let position = a.position + (other.position - a.position) * u;
    let heading = a.heading + shortest_arc(a.heading, other.heading) * u;
    let ok = position.is_finite() && heading.is_finite() && cycle_frame.is_finite();
    if !ok {
        return *a;
    }
    AgentSample { position, heading, cycle_frame, ..*a }
}

/// (rig, cycle, step at open, step at close, blend weights): see [`skin_keys`].
pub(crate) type SkinKeys = (Arc<str>, usize, u32, u32, [f32; 2]);

/// The skinned character an agent plays, with its shared rig name and its body.
pub(crate) fn skinned_of<'a>(
    casting: &'a Casting,
    rigs: &'a ShotRigs,
    id: u32,
) -> Option<(&'a Arc<str>, &'a SkinnedRig, u16)> {
    let cast = casting.get(id)?;
    Some((&cast.rig, rigs.skinned(&cast.rig)?, cast.body))
}

/// A skinned agent's shutter keys: (cycle, step at open, step at close, the
/// close step's blend weight at open and close), for cycle frames `c0` at
/// open and `c1` at close of cycle `cycle_name`.
pub(crate) fn skin_keys(skinned: (&Arc<str>, &SkinnedRig), cycle_name: &str, c0: f32, c1: f32) -> Option<SkinKeys> {
    let (rig_name, rig) = skinned;
    let cycle = rig.cycle_index(cycle_name).ok()?;
    let length = rig.cycle_frames(cycle);
    let steps = rig.cycle_steps(cycle);
    // A cycle that does not advance over the shutter keeps the still frame's
    // nearest step, so an agent that stands still renders as without blur.
    if c0 == c1 || !(length > 0.0 && length.is_finite() && steps > 0 && c0.is_finite() && c1.is_finite()) {
        let step = rig.step_of(cycle, c0);
        return Some((rig_name.clone(), cycle, step, step, [0.0; 2]));
    }
    let step_len = length / steps as f32;
    // In steps, the open key wrapped into the cycle and the close key unwrapped from it.
    let x0 = c0.rem_euclid(length) / step_len;
    let x1 = x0 + (c1 - c0) / step_len;
    let (lo, hi) = (x0.min(x1).floor(), x0.max(x1).ceil());
    if lo == hi {
        // Both keys exactly on one step.
        let step = (lo.rem_euclid(steps as f32) as u32).min(steps);
        return Some((rig_name.clone(), cycle, step, step, [0.0; 2]));
    }
    let wrap = |k: f32| -> u32 {
        // Poses 0..=steps exist; past the end the cycle starts again.
        let k = k as i64;
        let n = steps as i64;
        if (0..=n).contains(&k) {
            k as u32
        } else {
            k.rem_euclid(n) as u32
        }
    };
    let (n0, n1) = (x0.round(), x1.round());
    if hi - lo > 1.0 && n0 != n1 {
        // The shutter spans more than one step and its ends are nearest
        // different steps: blending the steps around it would put open and
        // close on a chord longer than the shutter, which a joint reversing
        // within it leaves far behind. Key the steps nearest open and close
        // instead, so each is its still-frame pose (within pose_error_max of
        // the exact pose) and the blend runs between. (A shutter shorter
        // than a step that straddles one blends the two steps around it.)
        return Some((rig_name.clone(), cycle, wrap(n0), wrap(n1), [0.0, 1.0]));
    }
    let w = |x: f32| ((x - lo) / (hi - lo)).clamp(0.0, 1.0);
    Some((rig_name.clone(), cycle, wrap(lo), wrap(hi), [w(x0), w(x1)]))
}

/// Every pose step a visible skinned agent takes on the shot's still
/// frames, at the cycle frames it plays: bounded by the rigs' bodies, cycles
/// and steps, whatever the agent count.
pub(crate) fn still_steps(
    shot: &Shot,
    cache: &CacheReader,
    casting: &Casting,
    rigs: &ShotRigs,
    timing: &CycleTiming,
) -> Result<BTreeSet<PoseStep>> {
    let mut steps: BTreeSet<PoseStep> = BTreeSet::new();
    if !rigs.any_skinned() {
        return Ok(steps);
    }
    for f in shot.frames.iter() {
        let cf = shot.cache.cache_frame(f);
        if cache.frames().binary_search(&cf).is_err() {
            continue;
        }
        for a in timing.read(cache, cf)?.agents.iter().filter(|a| !a.hidden()) {
            let Some((name, rig, body)) = skinned_of(casting, rigs, a.id) else { continue };
            if let Ok(cycle) = rig.cycle_index(cycle_name(cache, a)) {
                steps.insert((name.clone(), body, cycle, rig.step_of(cycle, a.cycle_frame)));
            }
        }
    }
    Ok(steps)
}

/// Every skinned pose step that `shutter` needs over the shot's frames
/// (its open and close keys for every visible skinned agent): what a crowd
/// built for that shutter poses beside the still steps.
pub(crate) fn shutter_steps(
    shot: &Shot,
    cache: &CacheReader,
    casting: &Casting,
    rigs: &ShotRigs,
    timing: &CycleTiming,
    shutter: [f32; 2],
) -> Result<BTreeSet<PoseStep>> {
    let mut needed: BTreeSet<PoseStep> = BTreeSet::new();
    for f in shot.frames.iter() {
        for (_, open, close) in shutter_keys_at(shot, cache, casting, rigs, timing, f, shutter)? {
            needed.insert(open);
            needed.insert(close);
        }
    }
    Ok(needed)
}

/// The shutter keys of every visible skinned agent at shot frame `f`: (agent
/// id, its step at shutter open, its step at close), in cache order; empty
/// when the cache has no record of that frame. The steps a shutter poses
/// ([`shutter_steps`]) and what a blurred render of the frame traces (its
/// open meshes, and a deforming BLAS where the two steps differ).
pub(crate) fn shutter_keys_at(
    shot: &Shot,
    cache: &CacheReader,
    casting: &Casting,
    rigs: &ShotRigs,
    timing: &CycleTiming,
    f: i32,
    shutter: [f32; 2],
) -> Result<Vec<(u32, PoseStep, PoseStep)>> {
    let cf = shot.cache.cache_frame(f);
    if cache.frames().binary_search(&cf).is_err() {
        return Ok(Vec::new());
    }
    let block = timing.read(cache, cf)?;
    let near = Neighbours::read(shot, cache, timing, f)?;
    let mut keys = Vec::new();
    for a in block.agents.iter().filter(|a| !a.hidden()) {
        let Some((name, rig, body)) = skinned_of(casting, rigs, a.id) else { continue };
        let length = length_of(shot, cache, casting, rigs, a);
        let (prev, next) = (near.prev.get(&a.id), near.next.get(&a.id));
        let [s0, s1] = shutter.map(|s| sample_at(a, prev, next, s, length));
        let keys_of = skin_keys((name, rig), cycle_name(cache, a), s0.cycle_frame, s1.cycle_frame);
        if let Some((rig, cycle, k0, k1, _)) = keys_of {
            keys.push((a.id, (rig.clone(), body, cycle, k0), (rig, body, cycle, k1)));
        }
    }
    Ok(keys)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::Vec3;
    use std::f32::consts::PI;

    fn agent(x: f32, heading: f32, cycle_frame: f32) -> AgentSample {
        AgentSample { id: 1, position: Vec3::new(x, 0.0, 0.0), heading, rig: 0, cycle: 0, cycle_frame, flags: 0 }
    }

    #[test]
    fn heading_takes_the_shortest_arc() {
        let a = agent(0.0, 350f32.to_radians(), 0.0);
        let b = agent(0.0, 10f32.to_radians(), 0.0);
        let s = sample_at(&a, None, Some(&b), 0.5, None);
        assert!((s.heading - 2.0 * PI).abs() < 1e-4, "{}", s.heading.to_degrees());
        assert!((shortest_arc(0.1, -0.1) + 0.2).abs() < 1e-6);
    }

    #[test]
    fn cycle_frames_advance_through_the_wrap() {
        let a = agent(0.0, 0.0, 23.0);
        let b = agent(0.0, 0.0, 1.0); // 24-frame cycle: advanced 2 frames
        let s = sample_at(&a, None, Some(&b), 0.25, Some(24.0));
        assert!((s.cycle_frame - 23.5).abs() < 1e-5);
        let s = sample_at(&a, None, Some(&b), 0.75, Some(24.0));
        assert!((s.cycle_frame - 24.5).abs() < 1e-5, "{}", s.cycle_frame);
    }

    #[test]
    fn entering_agents_extrapolate_and_lone_agents_hold() {
        let prev = agent(-1.0, 0.0, 4.0);
        let a = agent(0.0, 0.0, 5.0);
        // No next record (the agent leaves): constant velocity from the previous one.
        let s = sample_at(&a, Some(&prev), None, 0.25, Some(24.0));
        assert!((s.position.x - 0.25).abs() < 1e-6 && (s.cycle_frame - 5.25).abs() < 1e-6);
        let s = sample_at(&a, Some(&prev), None, -0.25, Some(24.0));
        assert!((s.position.x + 0.25).abs() < 1e-6);
        let s = sample_at(&a, None, None, 0.25, Some(24.0));
        assert_eq!(s, a);
    }

    /// Keys of a shutter over RiggedFigure's walk cut into `pose_step`-frame steps.
    fn figure_keys(pose_step: f32, c0: f32, c1: f32) -> (u32, u32, [f32; 2]) {
        let file = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
            .join("../shared/assets/gltf/RiggedFigure/RiggedFigure.gltf");
        let options = crate::shot::SkinOptions { pose_step: Some(pose_step), ..Default::default() };
        let rig = SkinnedRig::load(&file, &options, 24.0).expect("RiggedFigure loads");
        let name: Arc<str> = "figure".into();
        let (_, _, k0, k1, w) = skin_keys((&name, &rig), "#0", c0, c1).expect("keys");
        (k0, k1, w)
    }

    #[test]
    fn a_shutter_within_one_step_blends_the_steps_around_it() {
        // Steps of 1 frame: 4.25..4.75 lies within step 4..5.
        assert_eq!(figure_keys(1.0, 4.25, 4.75), (4, 5, [0.25, 0.75]));
        // Straddling step 5 with a shutter shorter than a step: 4..6, as before.
        assert_eq!(figure_keys(1.0, 4.75, 5.25), (4, 6, [0.375, 0.625]));
    }

    #[test]
    fn a_shutter_over_several_steps_keys_the_steps_nearest_open_and_close() {
        // Steps of 0.25 frames: open at step 16.8, close at 18.8 (of 120).
        assert_eq!(figure_keys(0.25, 4.2, 4.7), (17, 19, [0.0, 1.0]));
        // Across the cycle's end (30 frames): from step 119.6 to 121.6, nearest
        // 120 (the end pose) and 122, step 2 of the next cycle.
        assert_eq!(figure_keys(0.25, 29.9, 30.4), (120, 2, [0.0, 1.0]));
    }
}
