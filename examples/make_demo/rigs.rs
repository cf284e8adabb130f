//! Demo rigs (SPEC "Rig glTF"): a rigid node hierarchy with one proxy box
//! per slot and the clips WalkA, WalkB, IdleA and SitA.

use glam::{EulerRot, Quat};
use serde_json::json;
use std::f32::consts::TAU;
use std::path::Path;
use throng::error::Result;
use throng::export::glb::{
    AnimationDesc, ChannelDesc, ChannelValues, GlbBuilder, Interpolation, MaterialDesc, NodeDesc, NodeId,
};

use crate::geometry::cuboid;

/// Shot frames per second; clip durations are frames / FPS.
pub const FPS: f32 = 24.0;
/// Hip joint height while seated (SPEC: hips at about y = 0.5).
pub const SIT_HIP_Y: f32 = 0.5;
/// Hip joint Z while seated, relative to the agent origin (SPEC: -0.25).
pub const SIT_HIP_Z: f32 = -0.25;
/// Frames between rotation keys (every other frame is plenty for rigid parts).
const KEY_STEP: u32 = 2;
/// Frames between CUBICSPLINE root keys.
const CUBIC_KEY_STEP: u32 = 4;

/// A clip's length in frames and its stride (root Z travel per cycle, metres).
#[derive(Clone, Copy, Debug)]
pub struct ClipSpec {
    pub name: &'static str,
    pub frames: u32,
    pub stride: f32,
}

/// Proportions of a biped (metres). Heights add up to the rig's height:
/// upper_leg + lower_leg + torso_offset + torso_h + neck + head_h.
#[derive(Clone, Copy, Debug)]
pub struct Dims {
    pub upper_leg: f32,
    pub lower_leg: f32,
    pub leg_r: f32,
    pub foot: f32,
    pub hip_x: f32,
    pub hips_half: [f32; 3],
    pub hips_above: f32,
    pub torso_offset: f32,
    pub torso_h: f32,
    pub torso_half: [f32; 2],
    pub neck: f32,
    pub head_h: f32,
    pub head_half: [f32; 2],
    pub shoulder: [f32; 2],
    pub upper_arm: f32,
    pub lower_arm: f32,
    pub arm_r: f32,
}

impl Dims {
    pub fn hip_height(&self) -> f32 {
        self.upper_leg + self.lower_leg
    }
    pub fn height(&self) -> f32 {
        self.hip_height() + self.torso_offset + self.torso_h + self.neck + self.head_h
    }
}

/// One rig: name, proportions and its four clips.
#[derive(Clone, Debug)]
pub struct RigSpec {
    pub name: &'static str,
    pub dims: Dims,
    pub walk_a: ClipSpec,
    pub walk_b: ClipSpec,
    pub idle: ClipSpec,
    pub sit: ClipSpec,
}

/// The two demo rigs: bipedThinA (~1.77 m, slim) and bipedTallB (~2.05 m, broad).
pub fn rig_specs() -> Vec<RigSpec> {
    vec![
        RigSpec {
            name: "bipedThinA",
            dims: Dims {
                upper_leg: 0.44,
                lower_leg: 0.46,
                leg_r: 0.055,
                foot: 0.09,
                hip_x: 0.1,
                hips_half: [0.17, 0.08, 0.11],
                hips_above: 0.1,
                torso_offset: 0.1,
                torso_h: 0.5,
                torso_half: [0.19, 0.12],
                neck: 0.02,
                head_h: 0.25,
                head_half: [0.12, 0.13],
                shoulder: [0.235, 0.46],
                upper_arm: 0.29,
                lower_arm: 0.3,
                arm_r: 0.04,
            },
            walk_a: ClipSpec { name: "WalkA", frames: 32, stride: 1.5 },
            walk_b: ClipSpec { name: "WalkB", frames: 40, stride: 1.9 },
            idle: ClipSpec { name: "IdleA", frames: 48, stride: 0.0 },
            sit: ClipSpec { name: "SitA", frames: 48, stride: 0.0 },
        },
        RigSpec {
            name: "bipedTallB",
            dims: Dims {
                upper_leg: 0.52,
                lower_leg: 0.54,
                leg_r: 0.075,
                foot: 0.11,
                hip_x: 0.13,
                hips_half: [0.22, 0.09, 0.14],
                hips_above: 0.12,
                torso_offset: 0.12,
                torso_h: 0.58,
                torso_half: [0.27, 0.16],
                neck: 0.02,
                head_h: 0.27,
                head_half: [0.15, 0.15],
                shoulder: [0.325, 0.53],
                upper_arm: 0.34,
                lower_arm: 0.35,
                arm_r: 0.055,
            },
            walk_a: ClipSpec { name: "WalkA", frames: 32, stride: 1.7 },
            walk_b: ClipSpec { name: "WalkB", frames: 40, stride: 2.1 },
            idle: ClipSpec { name: "IdleA", frames: 48, stride: 0.0 },
            sit: ClipSpec { name: "SitA", frames: 48, stride: 0.0 },
        },
    ]
}

/// The rig's slot nodes, by name.
struct Nodes {
    root: NodeId,
    hips: NodeId,
    torso: NodeId,
    head: NodeId,
    upper_arm: [NodeId; 2],
    lower_arm: [NodeId; 2],
    upper_leg: [NodeId; 2],
    lower_leg: [NodeId; 2],
}

/// Slot node with its proxy box in extras and a matching box mesh.
fn slot_node(
    glb: &mut GlbBuilder,
    rig: &str,
    slot: &str,
    translation: [f32; 3],
    min: [f32; 3],
    max: [f32; 3],
    material: throng::export::glb::MaterialId,
) -> Result<NodeId> {
    let mesh = glb.add_mesh(&format!("{rig}_{slot}_proxy"), &cuboid(min, max), Some(material))?;
    glb.add_node(
        NodeDesc::new(slot)
            .translation(translation)
            .mesh(mesh)
            .extras(json!({"slot": slot, "proxy_box": {"min": min, "max": max}})),
    )
}

fn build_nodes(glb: &mut GlbBuilder, spec: &RigSpec) -> Result<Nodes> {
    let d = &spec.dims;
    let rig = spec.name;
    let body = glb.add_material(&MaterialDesc::new("proxy_body", [0.55, 0.55, 0.58, 1.0]).pbr(0.0, 0.6));
    let limb = glb.add_material(&MaterialDesc::new("proxy_limb", [0.35, 0.36, 0.4, 1.0]).pbr(0.0, 0.6));
    let head_mat = glb.add_material(&MaterialDesc::new("proxy_head", [0.8, 0.75, 0.6, 1.0]).pbr(0.0, 0.5));

    // Children are attached after creation, so build top-down.
    let top = glb.add_node(NodeDesc::new(rig))?;
    let root = glb.add_node(NodeDesc::new("root"))?;
    glb.add_child(top, root)?;
    let [hx, hy, hz] = d.hips_half;
    let hips = slot_node(glb, rig, "hips", [0.0, d.hip_height(), 0.0], [-hx, -hy, -hz], [hx, d.hips_above, hz], body)?;
    glb.add_child(root, hips)?;
    let [tx, tz] = d.torso_half;
    let torso = slot_node(glb, rig, "torso", [0.0, d.torso_offset, 0.0], [-tx, 0.0, -tz], [tx, d.torso_h, tz], body)?;
    glb.add_child(hips, torso)?;
    let [ex, ez] = d.head_half;
    let head =
        slot_node(glb, rig, "head", [0.0, d.torso_h, 0.0], [-ex, d.neck, -ez], [ex, d.neck + d.head_h, ez], head_mat)?;
    glb.add_child(torso, head)?;

    let mut upper_arm = Vec::new();
    let mut lower_arm = Vec::new();
    let mut upper_leg = Vec::new();
    let mut lower_leg = Vec::new();
    // The character's left is +X (it faces +Z).
    for (side, sx) in [("l", 1.0f32), ("r", -1.0)] {
        let a = d.arm_r;
        let ua = slot_node(
            glb,
            rig,
            &format!("upper_arm_{side}"),
            [sx * d.shoulder[0], d.shoulder[1], 0.0],
            [-a, -d.upper_arm, -a],
            [a, 0.0, a],
            limb,
        )?;
        glb.add_child(torso, ua)?;
        let la = slot_node(
            glb,
            rig,
            &format!("lower_arm_{side}"),
            [0.0, -d.upper_arm, 0.0],
            [-0.9 * a, -d.lower_arm, -0.9 * a],
            [0.9 * a, 0.0, 0.9 * a],
            limb,
        )?;
        glb.add_child(ua, la)?;
        let l = d.leg_r;
        let ul = slot_node(
            glb,
            rig,
            &format!("upper_leg_{side}"),
            [sx * d.hip_x, 0.0, 0.0],
            [-l, -d.upper_leg, -l],
            [l, 0.0, l],
            limb,
        )?;
        glb.add_child(hips, ul)?;
        // The lower leg box includes the foot, reaching forward (+Z) and down to y = 0.
        let ll = slot_node(
            glb,
            rig,
            &format!("lower_leg_{side}"),
            [0.0, -d.upper_leg, 0.0],
            [-0.9 * l, -d.lower_leg, -l],
            [0.9 * l, 0.0, l + d.foot],
            limb,
        )?;
        glb.add_child(ul, ll)?;
        upper_arm.push(ua);
        lower_arm.push(la);
        upper_leg.push(ul);
        lower_leg.push(ll);
    }
    let pair = |v: Vec<NodeId>| [v[0], v[1]];
    Ok(Nodes {
        root,
        hips,
        torso,
        head,
        upper_arm: pair(upper_arm),
        lower_arm: pair(lower_arm),
        upper_leg: pair(upper_leg),
        lower_leg: pair(lower_leg),
    })
}

/// Euler (pitch about X, yaw about Y, roll about Z) to a quaternion array.
/// Positive pitch tips a limb hanging down towards -Z (backwards).
fn q(pitch: f32, yaw: f32, roll: f32) -> [f32; 4] {
    Quat::from_euler(EulerRot::YXZ, yaw, pitch, roll).to_array()
}

/// Key times (seconds) every `step` frames from 0 to `frames` inclusive, and
/// the matching cycle phases 0..=1.
fn keys(frames: u32, step: u32) -> (Vec<f32>, Vec<f32>) {
    (0..=frames / step)
        .map(|k| {
            let f = (k * step) as f32;
            (f / FPS, f / frames as f32)
        })
        .unzip()
}

/// A LINEAR rotation channel sampled from `f(phase)`.
fn rotation(node: NodeId, frames: u32, f: impl Fn(f32) -> [f32; 4]) -> ChannelDesc {
    let (times, phases) = keys(frames, KEY_STEP);
    ChannelDesc {
        node,
        interpolation: Interpolation::Linear,
        times,
        values: ChannelValues::Rotation(phases.into_iter().map(f).collect()),
    }
}

/// A constant LINEAR channel (two keys) holding a pose over the whole clip.
fn hold_rotation(node: NodeId, frames: u32, value: [f32; 4]) -> ChannelDesc {
    ChannelDesc {
        node,
        interpolation: Interpolation::Linear,
        times: vec![0.0, frames as f32 / FPS],
        values: ChannelValues::Rotation(vec![value; 2]),
    }
}

fn hold_translation(node: NodeId, frames: u32, value: [f32; 3]) -> ChannelDesc {
    ChannelDesc {
        node,
        interpolation: Interpolation::Linear,
        times: vec![0.0, frames as f32 / FPS],
        values: ChannelValues::Translation(vec![value; 2]),
    }
}

/// How a walk looks: joint amplitudes (radians) and root bob (metres).
struct WalkStyle {
    thigh: f32,
    knee: f32,
    knee_rest: f32,
    arm: f32,
    elbow: f32,
    bob: f32,
    sway: f32,
    /// Root translation as CUBICSPLINE (with analytic tangents) instead of LINEAR.
    cubic_root: bool,
}

fn walk(n: &Nodes, clip: ClipSpec, s: &WalkStyle) -> AnimationDesc {
    let frames = clip.frames;
    let period = frames as f32 / FPS;
    let mut channels = Vec::new();
    // Root: forward along +Z by one stride per cycle, dipping twice per cycle
    // (at double support, phase 1/4 and 3/4).
    let root_y = |p: f32| -0.5 * s.bob * (1.0 - (2.0 * TAU * p).cos());
    let root_dy = |p: f32| -0.5 * s.bob * (2.0 * TAU / period) * (2.0 * TAU * p).sin();
    if s.cubic_root {
        let (times, phases) = keys(frames, CUBIC_KEY_STEP);
        let mut values = Vec::new();
        for p in phases {
            let tangent = [0.0, root_dy(p), clip.stride / period];
            values.extend([tangent, [0.0, root_y(p), clip.stride * p], tangent]);
        }
        channels.push(ChannelDesc {
            node: n.root,
            interpolation: Interpolation::CubicSpline,
            times,
            values: ChannelValues::Translation(values),
        });
    } else {
        let (times, phases) = keys(frames, 1);
        channels.push(ChannelDesc {
            node: n.root,
            interpolation: Interpolation::Linear,
            times,
            values: ChannelValues::Translation(phases.iter().map(|&p| [0.0, root_y(p), clip.stride * p]).collect()),
        });
    }
    let sin = |p: f32| (TAU * p).sin();
    let cos = |p: f32| (TAU * p).cos();
    // Side 0 = left, 1 = right (half a cycle later).
    for side in 0..2 {
        let sign = if side == 0 { 1.0 } else { -1.0 };
        let thigh = move |p: f32| -sign * s.thigh * sin(p);
        // The knee bends while the leg swings forward (thigh angle falling).
        let knee = move |p: f32| s.knee_rest + s.knee * (sign * cos(p)).max(0.0).powi(2);
        let arm = move |p: f32| sign * s.arm * sin(p);
        let elbow = move |p: f32| -(0.2 + s.elbow * (-sign * sin(p)).max(0.0));
        channels.push(rotation(n.upper_leg[side], frames, move |p| q(thigh(p), 0.0, 0.0)));
        channels.push(rotation(n.lower_leg[side], frames, move |p| q(knee(p), 0.0, 0.0)));
        channels.push(rotation(n.upper_arm[side], frames, move |p| q(arm(p), 0.0, sign * 0.05)));
        channels.push(rotation(n.lower_arm[side], frames, move |p| q(elbow(p), 0.0, 0.0)));
    }
    // Hips turn with the forward leg; the torso counter-rotates.
    channels.push(rotation(n.hips, frames, move |p| q(0.0, -s.sway * sin(p), 0.0)));
    channels.push(rotation(n.torso, frames, move |p| q(0.05, 0.8 * s.sway * sin(p), 0.0)));
    AnimationDesc { name: clip.name.to_string(), channels }
}

fn idle(n: &Nodes, clip: ClipSpec) -> AnimationDesc {
    let frames = clip.frames;
    let sin = |p: f32| (TAU * p).sin();
    let mut channels = vec![hold_translation(n.root, frames, [0.0; 3])];
    // Breathing: the chest swells a little (a scale channel).
    let (times, phases) = keys(frames, 4);
    channels.push(ChannelDesc {
        node: n.torso,
        interpolation: Interpolation::Linear,
        times,
        values: ChannelValues::Scale(
            phases.iter().map(|&p| [1.0, 1.0 + 0.012 * sin(p), 1.0 + 0.025 * sin(p)]).collect(),
        ),
    });
    channels.push(rotation(n.torso, frames, move |p| q(0.0, 0.0, 0.025 * sin(p))));
    channels.push(rotation(n.hips, frames, move |p| q(0.0, 0.0, -0.015 * sin(p))));
    // Robots glance around in jerks: a STEP channel.
    let t = |f: f32| f / FPS;
    channels.push(ChannelDesc {
        node: n.head,
        interpolation: Interpolation::Step,
        times: vec![t(0.0), t(12.0), t(24.0), t(36.0), t(frames as f32)],
        values: ChannelValues::Rotation(vec![
            q(0.0, 0.0, 0.0),
            q(0.0, 0.35, 0.0),
            q(0.08, -0.25, 0.0),
            q(0.0, 0.0, 0.0),
            q(0.0, 0.0, 0.0),
        ]),
    });
    for side in 0..2 {
        let sign = if side == 0 { 1.0 } else { -1.0 };
        channels.push(rotation(n.upper_arm[side], frames, move |p| q(0.04 * sin(p + 0.25 * sign), 0.0, sign * 0.07)));
        channels.push(hold_rotation(n.lower_arm[side], frames, q(-0.2, 0.0, 0.0)));
        channels.push(hold_rotation(n.upper_leg[side], frames, q(0.0, 0.0, sign * 0.03)));
        channels.push(hold_rotation(n.lower_leg[side], frames, q(0.0, 0.0, -sign * 0.03)));
    }
    AnimationDesc { name: clip.name.to_string(), channels }
}

/// Seated pose (SPEC bench geometry): hips at y = SIT_HIP_Y, z = SIT_HIP_Z,
/// thighs forward, shins down to the floor.
fn sit(n: &Nodes, clip: ClipSpec, d: &Dims) -> AnimationDesc {
    let frames = clip.frames;
    let sin = |p: f32| (TAU * p).sin();
    // Thigh angle below horizontal (beta from vertical) and shin tilt forward
    // (gamma from vertical) so that the feet reach y = 0.
    let (beta, gamma) = if d.lower_leg >= SIT_HIP_Y {
        (std::f32::consts::FRAC_PI_2, (SIT_HIP_Y / d.lower_leg).acos())
    } else {
        (((SIT_HIP_Y - d.lower_leg) / d.upper_leg).acos(), 0.0)
    };
    let mut channels = vec![hold_translation(n.root, frames, [0.0; 3])];
    // Hips: root X/Z translation is ignored by posing, so the seat offset is on the hips.
    channels.push(hold_translation(n.hips, frames, [0.0, SIT_HIP_Y, SIT_HIP_Z]));
    channels.push(rotation(n.torso, frames, move |p| q(-0.12 + 0.015 * sin(p), 0.0, 0.0)));
    channels.push(rotation(n.head, frames, move |p| q(0.1, 0.25 * sin(p), 0.0)));
    for side in 0..2 {
        let sign = if side == 0 { 1.0 } else { -1.0 };
        // Knees apart a little.
        channels.push(hold_rotation(n.upper_leg[side], frames, q(-beta, sign * 0.08, 0.0)));
        channels.push(hold_rotation(n.lower_leg[side], frames, q(beta - gamma, 0.0, 0.0)));
        channels.push(rotation(n.upper_arm[side], frames, move |p| q(-0.4 + 0.02 * sin(p), 0.0, sign * 0.1)));
        channels.push(hold_rotation(n.lower_arm[side], frames, q(-0.9, 0.0, 0.0)));
    }
    AnimationDesc { name: clip.name.to_string(), channels }
}

/// Builds the rig's .glb in memory.
pub fn build_rig(spec: &RigSpec) -> Result<Vec<u8>> {
    let mut glb = GlbBuilder::new();
    glb.set_generator("throng examples/make_demo.rs");
    let nodes = build_nodes(&mut glb, spec)?;
    // Bob is about leg * (1 - cos thigh): the hips drop when the legs are spread.
    let walk_a = WalkStyle {
        thigh: 0.38,
        knee: 0.9,
        knee_rest: 0.08,
        arm: 0.35,
        elbow: 0.4,
        bob: 0.05,
        sway: 0.08,
        cubic_root: false,
    };
    // WalkB: a longer, slower, bouncier stride.
    let walk_b = WalkStyle {
        thigh: 0.5,
        knee: 1.1,
        knee_rest: 0.1,
        arm: 0.5,
        elbow: 0.6,
        bob: 0.09,
        sway: 0.12,
        cubic_root: true,
    };
    glb.add_animation(&walk(&nodes, spec.walk_a, &walk_a))?;
    glb.add_animation(&walk(&nodes, spec.walk_b, &walk_b))?;
    glb.add_animation(&idle(&nodes, spec.idle))?;
    glb.add_animation(&sit(&nodes, spec.sit, &spec.dims))?;
    glb.finish()
}

/// Writes demo/rigs/<rig>.glb.
pub fn write_rig(path: &Path, spec: &RigSpec) -> Result<()> {
    let bytes = build_rig(spec)?;
    throng::error::write_atomic(path, |w| {
        use std::io::Write;
        use throng::error::IoContext;
        w.write_all(&bytes).at(path)
    })
}
