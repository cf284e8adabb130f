//! Motion over the shutter: agents sampled between cache frames, posed at
//! shutter open and close (motion blur and motion vectors).
//!
//! An agent at shot frame `f` and sub-frame offset `s` (frames, the shutter
//! lies within -1..=1) is interpolated between its records at cache frame
//! `cf = f + frame_offset` and the neighbour on the side of `s` (`cf + 1` for
//! `s > 0`, `cf - 1` for `s < 0`), with weight `|s|`:
//!
//! - position: linearly;
//! - heading: by the shortest arc (a turn from 350 to 10 degrees goes through
//!   0, not back through 180);
//! - cycle frame: advances continuously by the difference to the neighbour
//!   taken modulo the cycle length (the one nearest zero), so a cycle that
//!   wraps from its last frame to its first inside the shutter keeps moving
//!   forward and wraps where posing samples it (`rem_euclid`). When the
//!   neighbour plays another cycle, the cycle frame advances at one frame per
//!   frame instead.
//!
//! **Agents entering or leaving.** An agent is in a frame's render exactly
//! when it is in that frame's cache record, as without blur (layers, ids and
//! Cryptomatte see the same agents). Over the shutter it exists for the whole
//! interval: where the neighbour on the side of `s` lacks it (it enters or
//! leaves there), its motion is extrapolated at constant velocity from the
//! other neighbour; with neither neighbour, it holds still. It never pops in
//! or out mid-shutter.
//!
//! Rigid parts (slot rigs) are posed from their clips at the exact cycle
//! frame of each key. Skinned agents use the shared pose steps: when the
//! shutter stays within one step, the keys are the steps just below and
//! above it and the mesh blends between those two posed meshes with a weight
//! that runs linearly over the shutter (exact piecewise-linear pose
//! interpolation); when it spans more (steps shorter than the shutter, as
//! `pose_error_max` chooses for fast clips), the keys are the steps nearest
//! open and close, each within the pose error bound of its exact pose, with
//! the blend running from one to the other (a shutter shorter than a step
//! that straddles one still blends the two steps around it). Agents at the same keys share the
//! same posed meshes, as pose instancing does for still frames. A crowd
//! built for a shutter ([`ShotCrowd::open`] with it) has every step that
//! shutter needs posed, once, in its pose library
//! ([`crate::casting::steps::shutter_steps`]).

use crate::cache::AgentSample;
use crate::casting::crowd::{AgentPose, ShotCrowd};
use crate::casting::steps::{sample_at, skin_keys, skinned_of, Neighbours};
use crate::casting::timing::length_of;
use crate::error::Result;
use crate::scene::Camera;

/// An agent posed at shutter open and at close.
#[derive(Debug, Clone)]
pub struct AgentMotion {
    /// The pose at shutter open.
    pub(crate) open: AgentPose,
    /// The pose at shutter close.
    pub(crate) close: AgentPose,
    /// Skinned agents: the blend weight of the close pose's meshes at open
    /// and at close (vertices blend from the open pose's meshes); `None` for
    /// rigid motion only.
    pub deform: Option<[f32; 2]>,
}

/// Every rendered agent of a frame posed at shutter open and close, and the
/// camera at both: computed once per frame and shared by every layer.
pub struct MotionFrame {
    /// Shot frame.
    pub(crate) frame: i32,
    /// Shutter `[open, close]`, frames relative to the frame.
    pub(crate) shutter: [f32; 2],
    /// (agent id, its motion), in cache order.
    pub agents: Vec<(u32, AgentMotion)>,
    /// The camera at shutter open and close.
    pub(crate) camera: [Camera; 2],
}

/// Length in frames of the cycle an agent record plays (`None` if unknown).
pub(crate) fn cycle_length<C>(crowd: &ShotCrowd<C>, a: &AgentSample) -> Option<f32> {
    length_of(crowd.shot(), crowd.cache(), crowd.casting(), crowd.rigs(), a)
}

/// The camera at a fractional shot frame (keys interpolated; a glTF camera does not move).
pub(crate) fn camera_at<C>(crowd: &ShotCrowd<C>, shot_frame: i32, offset: f32) -> Result<Camera> {
    match crowd.shot().keyed_camera(shot_frame as f32 + offset) {
        Some(c) => Ok(c),
        None => crowd.camera(shot_frame),
    }
}

impl MotionFrame {
    /// Reads the frame and its neighbouring cache frames once and poses
    /// every rendered agent at shutter open and close.
    pub fn new<C>(crowd: &ShotCrowd<C>, frame: i32, shutter: [f32; 2]) -> Result<MotionFrame> {
        let block = crowd.agents_at(frame)?;
        let near = Neighbours::read(crowd.shot(), crowd.cache(), crowd.timing(), frame)?;
        let mut agents = Vec::with_capacity(block.agents.len());
        for a in block.agents.iter().filter(|a| crowd.renders(a)) {
            let length = cycle_length(crowd, a);
            let (prev, next) = (near.prev.get(&a.id), near.next.get(&a.id));
            let [s0, s1] = shutter.map(|s| sample_at(a, prev, next, s, length));
            let skinned = skinned_of(crowd.casting(), crowd.rigs(), a.id);
            let keys = skinned.and_then(|(name, rig, body)| {
                Some((body, skin_keys((name, rig), crowd.cycle_name(a), s0.cycle_frame, s1.cycle_frame)?))
            });
            let motion = match keys {
                Some((body, (_, cycle, k0, k1, weight))) => AgentMotion {
                    open: AgentPose::Skinned { world_from_rig: crowd.world_from_agent(&s0), body, cycle, step: k0 },
                    close: AgentPose::Skinned { world_from_rig: crowd.world_from_agent(&s1), body, cycle, step: k1 },
                    deform: (k0 != k1).then_some(weight),
                },
                None => AgentMotion { open: crowd.agent_pose(&s0)?, close: crowd.agent_pose(&s1)?, deform: None },
            };
            agents.push((a.id, motion));
        }
        let camera = [camera_at(crowd, frame, shutter[0])?, camera_at(crowd, frame, shutter[1])?];
        Ok(MotionFrame { frame, shutter, agents, camera })
    }
}

/// Whether a shot's agents move at all over a shutter (tests and benchmarks).
pub fn moves(m: &MotionFrame) -> bool {
    let eq = |a: &AgentPose, b: &AgentPose| match (a, b) {
        (AgentPose::Slots(x), AgentPose::Slots(y)) => x == y,
        (
            AgentPose::Skinned { world_from_rig: x, body: b, cycle: c, step: s },
            AgentPose::Skinned { world_from_rig: y, body: e, cycle: d, step: t },
        ) => x == y && b == e && c == d && s == t,
        _ => false,
    };
    m.agents.iter().any(|(_, a)| !eq(&a.open, &a.close))
        || m.camera[0].world_from_camera != m.camera[1].world_from_camera
}
