//! The demo's skinned character, demo/rigs/walker.glb: a procedural humanoid
//! on a 22-joint skeleton (Y up, facing +Z, feet on y = 0, 1.75 m), two body
//! meshes (`body_slim`, `body_broad`) and a `head`, each skinned on its own
//! node, and the clips `Walk` (32 frames, 1.4 m of hips travel, feet planted
//! by two-bone IK) and `Idle` (48 frames, weight shift and breathing).

use glam::{EulerRot, Mat4, Quat, Vec3};
use std::f32::consts::{PI, TAU};
use std::path::Path;
use throng::error::{Error, Result};
use throng::export::glb::{
    AnimationDesc, ChannelDesc, ChannelValues, GlbBuilder, Interpolation, MaterialDesc, MeshData, NodeDesc, NodeId,
};

use crate::rigs::FPS;

/// Walk cycle length in frames and its stride (hips Z travel per cycle, metres).
pub const WALK_FRAMES: u32 = 32;
pub const WALK_STRIDE: f32 = 1.4;
/// Idle cycle length in frames.
pub const IDLE_FRAMES: u32 = 48;

/// Joints: name, parent, rest translation relative to the parent. Rest
/// rotations are identity, so a joint's bind transform is a translation.
/// The character's left is +X (it faces +Z).
const JOINTS: [(&str, Option<usize>, [f32; 3]); 22] = [
    ("root", None, [0.0, 0.0, 0.0]),
    ("hips", Some(ROOT), [0.0, HIP_Y, 0.0]),
    ("spine", Some(HIPS), [0.0, 0.12, 0.0]),
    ("chest", Some(SPINE), [0.0, 0.2, 0.0]),
    ("neck", Some(CHEST), [0.0, 0.22, 0.0]),
    ("head", Some(NECK), [0.0, 0.08, 0.0]),
    ("shoulder_l", Some(CHEST), [0.07, 0.17, 0.0]),
    ("upper_arm_l", Some(6), [0.15, 0.0, 0.0]),
    ("forearm_l", Some(7), [0.0, -UPPER_ARM, 0.0]),
    ("hand_l", Some(8), [0.0, -FOREARM, 0.0]),
    ("shoulder_r", Some(CHEST), [-0.07, 0.17, 0.0]),
    ("upper_arm_r", Some(10), [-0.15, 0.0, 0.0]),
    ("forearm_r", Some(11), [0.0, -UPPER_ARM, 0.0]),
    ("hand_r", Some(12), [0.0, -FOREARM, 0.0]),
    ("thigh_l", Some(HIPS), [HIP_X, -0.04, 0.0]),
    ("shin_l", Some(14), [0.0, -THIGH, 0.0]),
    ("foot_l", Some(15), [0.0, -SHIN, 0.0]),
    ("toe_l", Some(16), [0.0, -0.04, 0.14]),
    ("thigh_r", Some(HIPS), [-HIP_X, -0.04, 0.0]),
    ("shin_r", Some(18), [0.0, -THIGH, 0.0]),
    ("foot_r", Some(19), [0.0, -SHIN, 0.0]),
    ("toe_r", Some(20), [0.0, -0.04, 0.14]),
];
const ROOT: usize = 0;
const HIPS: usize = 1;
const SPINE: usize = 2;
const CHEST: usize = 3;
const NECK: usize = 4;
const HEAD: usize = 5;
/// First joint of each arm (shoulder) and leg (thigh), left then right.
const ARM: [usize; 2] = [6, 10];
const LEG: [usize; 2] = [14, 18];

const HIP_Y: f32 = 0.95;
const HIP_X: f32 = 0.09;
const THIGH: f32 = 0.43;
const SHIN: f32 = 0.4;
const UPPER_ARM: f32 = 0.29;
const FOREARM: f32 = 0.26;
/// Ankle height with the foot flat (the sole is on y = 0).
const ANKLE_Y: f32 = HIP_Y - 0.04 - THIGH - SHIN;

/// Rest-pose (bind) position of every joint.
fn rest_positions() -> Vec<Vec3> {
    let mut out: Vec<Vec3> = Vec::with_capacity(JOINTS.len());
    for (_, parent, t) in JOINTS {
        let base = parent.map_or(Vec3::ZERO, |p| out[p]);
        out.push(base + Vec3::from(t));
    }
    out
}

// ---------------------------------------------------------------------------
// Meshes
// ---------------------------------------------------------------------------

/// Influences of one vertex: up to three (joint, weight), summing to 1.
type Influence = Vec<(u16, f32)>;

fn smoothstep(x: f32) -> f32 {
    let x = x.clamp(0.0, 1.0);
    x * x * (3.0 - 2.0 * x)
}

/// Linear interpolation through `(u, value)` keys sorted by `u`.
fn table(keys: &[(f32, [f32; 2])], u: f32) -> [f32; 2] {
    let i = keys.iter().position(|k| k.0 >= u).unwrap_or(keys.len() - 1).max(1);
    let (a, b) = (keys[i - 1], keys[i]);
    let t = ((u - a.0) / (b.0 - a.0).max(1e-6)).clamp(0.0, 1.0);
    [a.1[0] + (b.1[0] - a.1[0]) * t, a.1[1] + (b.1[1] - a.1[1]) * t]
}

/// A skinned tube along a straight chain of points. Segment `k` (point k to
/// k + 1) is bound to `chain[k].1`; within `blend` metres of an inner point
/// the weight passes smoothly to the next segment's joint (half each at the
/// point), and at the start to `parent`, so bending a joint bends the skin
/// instead of tearing it. `profile(s)` gives the half widths (side, other)
/// at arc length `s`; the ends close on poles.
struct Tube<'a> {
    chain: &'a [(Vec3, usize)],
    parent: Option<usize>,
    blend: f32,
    rings: usize,
    segs: usize,
}

impl Tube<'_> {
    fn build(&self, scale: [f32; 2], profile: impl Fn(f32, f32) -> [f32; 2]) -> MeshData {
        let lengths: Vec<f32> = self.chain.windows(2).map(|w| w[0].0.distance(w[1].0)).collect();
        let total: f32 = lengths.iter().sum();
        let (first, last) = (self.chain[0].0, self.chain[self.chain.len() - 1].0);
        let axis = (last - first).normalize();
        // Ring frame: `side` as close to +X as the axis allows.
        let side = (Vec3::X - axis * axis.dot(Vec3::X)).normalize();
        let other = axis.cross(side);
        let mut mesh = MeshData::default();
        let mut influences: Vec<Influence> = Vec::new();
        let weights_at = |s: f32| -> Influence {
            let mut k = 0;
            let mut s0 = 0.0;
            while k + 1 < lengths.len() && s > s0 + lengths[k] {
                s0 += lengths[k];
                k += 1;
            }
            let (len, local) = (lengths[k], (s - s0).clamp(0.0, lengths[k]));
            let b = self.blend.min(0.45 * len);
            let own = self.chain[k].1;
            let prev = if k == 0 { self.parent } else { Some(self.chain[k - 1].1) };
            let next = Some(self.chain[k + 1].1);
            let mut out: Influence = vec![(own as u16, 1.0)];
            for (joint, d) in [(prev, local), (next, len - local)] {
                let Some(j) = joint.filter(|&j| j != own) else { continue };
                let w = 0.5 * (1.0 - smoothstep(d / b));
                if w > 0.0 {
                    out[0].1 -= w;
                    out.push((j as u16, w));
                }
            }
            out
        };
        // Rings, with the first and last replaced by poles.
        for i in 0..=self.rings {
            let s = total * i as f32 / self.rings as f32;
            let centre = first + axis * s;
            if i == 0 || i == self.rings {
                mesh.positions.push(centre.to_array());
                influences.push(weights_at(s));
                continue;
            }
            let [a, b] = profile(s, total);
            let (a, b) = (a * scale[0], b * scale[1]);
            for j in 0..self.segs {
                let th = TAU * j as f32 / self.segs as f32;
                let p = centre + side * (a * th.cos()) + other * (b * th.sin());
                mesh.positions.push(p.to_array());
                influences.push(weights_at(s));
            }
        }
        // Triangles: fans at the poles, quads between rings.
        let ring = |i: usize, j: usize| (1 + (i - 1) * self.segs + j % self.segs) as u32;
        let top = (mesh.positions.len() - 1) as u32;
        for j in 0..self.segs {
            mesh.indices.extend([0, ring(1, j + 1), ring(1, j)]);
            mesh.indices.extend([top, ring(self.rings - 1, j), ring(self.rings - 1, j + 1)]);
        }
        for i in 1..self.rings - 1 {
            for j in 0..self.segs {
                let (a, b, c, d) = (ring(i, j), ring(i, j + 1), ring(i + 1, j), ring(i + 1, j + 1));
                mesh.indices.extend([a, b, d, a, d, c]);
            }
        }
        orient_outwards(&mut mesh, first, axis);
        set_skin(&mut mesh, &influences);
        mesh
    }
}

/// Makes every triangle face away from the tube's axis (the ring frame's
/// handedness depends on the axis), then sets smooth normals.
fn orient_outwards(mesh: &mut MeshData, origin: Vec3, axis: Vec3) {
    let p = |i: u32| Vec3::from(mesh.positions[i as usize]);
    let mut indices = std::mem::take(&mut mesh.indices);
    for tri in indices.chunks_exact_mut(3) {
        let (a, b, c) = (p(tri[0]), p(tri[1]), p(tri[2]));
        let centre = (a + b + c) / 3.0;
        let from_axis = centre - (origin + axis * axis.dot(centre - origin));
        if (b - a).cross(c - a).dot(from_axis) < 0.0 {
            tri.swap(1, 2);
        }
    }
    mesh.indices = indices;
    smooth_normals(mesh);
}

/// Area-weighted vertex normals.
fn smooth_normals(mesh: &mut MeshData) {
    let mut n = vec![Vec3::ZERO; mesh.positions.len()];
    for tri in mesh.indices.chunks_exact(3) {
        let p: Vec<Vec3> = tri.iter().map(|&i| Vec3::from(mesh.positions[i as usize])).collect();
        let face = (p[1] - p[0]).cross(p[2] - p[0]);
        for &i in tri {
            n[i as usize] += face;
        }
    }
    mesh.normals = n.iter().map(|v| v.normalize_or(Vec3::Y).to_array()).collect();
}

/// Writes JOINTS_0/WEIGHTS_0 from influences, strongest first.
fn set_skin(mesh: &mut MeshData, influences: &[Influence]) {
    for inf in influences {
        let mut inf = inf.clone();
        inf.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
        let (mut j, mut w) = ([0u16; 4], [0f32; 4]);
        for (k, &(joint, weight)) in inf.iter().take(4).enumerate() {
            j[k] = joint;
            w[k] = weight;
        }
        let sum: f32 = w.iter().sum();
        mesh.joints.push(j);
        mesh.weights.push(w.map(|x| x / sum));
    }
}

/// Rounds a tube's ends over `cap` metres.
fn capped(r: [f32; 2], s: f32, total: f32, cap: f32) -> [f32; 2] {
    let e = s.min(total - s).max(0.0);
    let k = if e < cap { (1.0 - (1.0 - e / cap).powi(2)).max(0.0).sqrt() } else { 1.0 };
    [r[0] * k, r[1] * k]
}

/// Body proportions: `width` scales the torso across, `depth` front to back,
/// `limb` every limb's radius.
#[derive(Clone, Copy)]
struct Build {
    width: f32,
    depth: f32,
    limb: f32,
}

/// A body mesh: torso, arms, legs and feet, about 5,500 triangles.
fn body(build: Build) -> MeshData {
    let rest = rest_positions();
    let at = |j: usize| rest[j];
    let mut parts = Vec::new();

    // Torso from the crotch to the base of the neck; half widths by height.
    let torso_keys: [(f32, [f32; 2]); 8] = [
        (0.82, [0.1, 0.08]),
        (0.86, [0.145, 0.1]),
        (0.95, [0.155, 0.105]),
        (1.05, [0.13, 0.095]),
        (1.25, [0.15, 0.11]),
        (1.4, [0.165, 0.1]),
        (1.46, [0.1, 0.07]),
        (1.51, [0.05, 0.05]),
    ];
    let torso_chain = [
        (Vec3::new(0.0, 0.82, 0.0), HIPS),
        (at(SPINE), SPINE),
        (at(CHEST), CHEST),
        (at(NECK), NECK),
        (Vec3::new(0.0, 1.51, 0.0), NECK),
    ];
    let tube = Tube { chain: &torso_chain, parent: None, blend: 0.06, rings: 36, segs: 24 };
    parts.push(tube.build([build.width, build.depth], |s, total| {
        let [a, b] = table(&torso_keys, 0.82 + s);
        // Close the crotch end; the neck end is already narrow.
        capped([a, b], s, total + 0.2, 0.04)
    }));

    for side in 0..2 {
        // Arm from the top of the shoulder to the finger tips.
        let [shoulder, upper, fore, hand] = [ARM[side], ARM[side] + 1, ARM[side] + 2, ARM[side] + 3];
        let arm_chain = [
            (at(upper) + Vec3::Y * 0.03, upper),
            (at(fore), fore),
            (at(hand), hand),
            (at(hand) - Vec3::Y * 0.17, hand),
        ];
        let arm_keys: [(f32, [f32; 2]); 6] = [
            (0.0, [0.05, 0.05]),
            (0.3, [0.04, 0.042]),
            (0.45, [0.038, 0.04]),
            (0.58, [0.028, 0.032]),
            (0.66, [0.02, 0.042]),
            (0.75, [0.016, 0.035]),
        ];
        let tube = Tube { chain: &arm_chain, parent: Some(shoulder), blend: 0.05, rings: 28, segs: 12 };
        parts.push(tube.build([build.limb, build.limb], |s, total| capped(table(&arm_keys, s), s, total, 0.035)));

        // Leg from inside the hips to the ankle.
        let [thigh, shin, foot, toe] = [LEG[side], LEG[side] + 1, LEG[side] + 2, LEG[side] + 3];
        let leg_chain = [(at(thigh) + Vec3::Y * 0.06, thigh), (at(shin), shin), (at(foot), foot)];
        let leg_keys: [(f32, [f32; 2]); 5] = [
            (0.0, [0.085, 0.09]),
            (0.25, [0.07, 0.075]),
            (0.49, [0.05, 0.055]),
            (0.65, [0.05, 0.06]),
            (0.9, [0.038, 0.04]),
        ];
        let tube = Tube { chain: &leg_chain, parent: Some(HIPS), blend: 0.06, rings: 30, segs: 16 };
        parts.push(tube.build([build.limb, build.limb], |s, total| {
            let r = table(&leg_keys, s);
            // Round the top (inside the hips); the ankle closes into the foot.
            capped(r, s, total + 0.06, 0.05)
        }));

        // Foot from heel to toe tip, sole on y = 0.
        let x = at(foot).x;
        let foot_chain = [
            (Vec3::new(x, 0.045, -0.07), foot),
            (Vec3::new(x, 0.045, at(toe).z), toe),
            (Vec3::new(x, 0.045, at(toe).z + 0.08), toe),
        ];
        let tube = Tube { chain: &foot_chain, parent: None, blend: 0.03, rings: 12, segs: 12 };
        parts.push(tube.build([build.limb, 1.0], |s, total| {
            let [a, _] = capped([0.045, 0.0], s, total, 0.05);
            // Height stays whole so the sole is flat: y from 0.0 to 0.09.
            [a, 0.045]
        }));
    }
    let mut out = MeshData::default();
    for p in &parts {
        crate::geometry::append(&mut out, p);
    }
    out
}

/// The head: neck, skull and a nose that shows which way it faces.
fn head() -> MeshData {
    let rest = rest_positions();
    let neck_chain = [(Vec3::new(0.0, 1.45, 0.0), NECK), (rest[HEAD], HEAD), (Vec3::new(0.0, 1.62, 0.0), HEAD)];
    let neck = Tube { chain: &neck_chain, parent: Some(CHEST), blend: 0.04, rings: 10, segs: 16 }
        .build([1.0, 1.0], |s, total| capped([0.048, 0.05], s, total, 0.03));
    let skull_chain = [(Vec3::new(0.0, 1.53, 0.01), HEAD), (Vec3::new(0.0, 1.75, 0.01), HEAD)];
    let skull =
        Tube { chain: &skull_chain, parent: None, blend: 0.0, rings: 22, segs: 26 }.build([1.0, 1.0], |s, total| {
            // An egg: fuller at the crown than the jaw.
            let u = (s / total) * 2.0 - 1.0;
            let k = (1.0 - u * u).max(0.0).sqrt() * (1.0 + 0.08 * u);
            [0.085 * k, 0.1 * k]
        });
    let nose_chain = [(Vec3::new(0.0, 1.625, 0.08), HEAD), (Vec3::new(0.0, 1.625, 0.135), HEAD)];
    let nose = Tube { chain: &nose_chain, parent: None, blend: 0.0, rings: 6, segs: 10 }
        .build([1.0, 1.0], |s, total| capped([0.017, 0.022], s, total, 0.03));
    let mut out = MeshData::default();
    for p in [&neck, &skull, &nose] {
        crate::geometry::append(&mut out, p);
    }
    out
}

// ---------------------------------------------------------------------------
// Clips
// ---------------------------------------------------------------------------

/// Local rotations of every joint and the hips translation at one key.
struct Pose {
    rotation: Vec<Quat>,
    hips: Vec3,
}

impl Pose {
    fn rest() -> Pose {
        Pose { rotation: vec![Quat::IDENTITY; JOINTS.len()], hips: Vec3::new(0.0, HIP_Y, 0.0) }
    }

    /// Global (file-space) transform of every joint.
    fn globals(&self) -> Vec<(Quat, Vec3)> {
        let mut out: Vec<(Quat, Vec3)> = Vec::with_capacity(JOINTS.len());
        for (j, (_, parent, t)) in JOINTS.iter().enumerate() {
            let local_t = if j == HIPS { self.hips } else { Vec3::from(*t) };
            let (q, p) = match parent {
                None => (self.rotation[j], local_t),
                Some(p) => {
                    let (pq, pp) = out[*p];
                    (pq * self.rotation[j], pp + pq * local_t)
                }
            };
            out.push((q, p));
        }
        out
    }

    /// Places leg `side`'s ankle at `ankle` (file space) with the knee bent
    /// forwards, and turns the foot to `foot` (global) with the toe bent by
    /// `toe` radians.
    fn leg_ik(&mut self, side: usize, ankle: Vec3, foot: Quat, toe: f32) {
        let thigh = LEG[side];
        let g = self.globals();
        let (hips_q, _) = g[HIPS];
        let hip = g[thigh].1;
        let d = ankle - hip;
        let reach = (THIGH + SHIN) * 0.9999;
        let len = d.length().clamp(0.05, reach);
        let dir = d.normalize();
        // Law of cosines: the thigh's angle off the hip-ankle line.
        let cos_b = ((THIGH * THIGH + len * len - SHIN * SHIN) / (2.0 * THIGH * len)).clamp(-1.0, 1.0);
        let bend_axis = dir.cross(Vec3::Z).try_normalize().unwrap_or(Vec3::X);
        let thigh_dir = Quat::from_axis_angle(bend_axis, cos_b.acos()) * dir;
        let knee = hip + thigh_dir * THIGH;
        let shin_dir = (hip + dir * len - knee).normalize();
        // Global rotations taking the rest bone direction (-Y) onto each bone.
        let thigh_global = Quat::from_rotation_arc(Vec3::NEG_Y, thigh_dir);
        let shin_global = Quat::from_rotation_arc(thigh_dir, shin_dir) * thigh_global;
        self.rotation[thigh] = hips_q.inverse() * thigh_global;
        self.rotation[thigh + 1] = thigh_global.inverse() * shin_global;
        self.rotation[thigh + 2] = shin_global.inverse() * foot;
        self.rotation[thigh + 3] = Quat::from_rotation_x(toe);
    }

    /// Swings arm `side` forwards by `swing` radians, out by `out` radians,
    /// with the elbow bent by `elbow`.
    fn arm(&mut self, side: usize, swing: f32, out: f32, elbow: f32) {
        let sign = if side == 0 { 1.0 } else { -1.0 };
        // -Y towards +Z is a negative turn about X; out is away from the body.
        self.rotation[ARM[side] + 1] = Quat::from_euler(EulerRot::ZXY, sign * out, -swing, 0.0);
        self.rotation[ARM[side] + 2] = Quat::from_rotation_x(-elbow);
    }
}

/// Walk pose at cycle frame `f` (0..32): the hips travel `WALK_STRIDE` per
/// cycle; each foot is planted for half the cycle, moving back under the body
/// exactly as fast as the body moves forward, so in the world it stands still.
fn walk_pose(f: u32) -> Pose {
    let travel = WALK_STRIDE * f as f32 / WALK_FRAMES as f32;
    let f = f % WALK_FRAMES; // the last key repeats the first, moved on by the stride
    let p = f as f32 / WALK_FRAMES as f32;
    let phi = TAU * p;
    let mut pose = Pose::rest();
    // Lowest at double support (p = 0, 0.5), highest over the planted foot.
    pose.hips = Vec3::new(0.0, 0.875 - 0.02 * (2.0 * phi).cos(), travel);
    pose.rotation[HIPS] = Quat::from_euler(EulerRot::YXZ, 0.06 * phi.cos(), 0.0, 0.03 * (phi).sin());
    pose.rotation[SPINE] = Quat::from_euler(EulerRot::YXZ, -0.04 * phi.cos(), 0.05, -0.02 * phi.sin());
    pose.rotation[CHEST] = Quat::from_euler(EulerRot::YXZ, -0.05 * phi.cos(), 0.0, 0.0);
    pose.rotation[NECK] = Quat::from_euler(EulerRot::YXZ, 0.03 * phi.cos(), -0.04, 0.0);
    let half_span = WALK_STRIDE / 4.0;
    for side in 0..2 {
        let q = (p + 0.5 * side as f32).fract();
        let x = if side == 0 { HIP_X } else { -HIP_X };
        let (z, lift, pitch, toe) = if q < 0.5 {
            // Stance: back at the body's speed, foot flat.
            (half_span - WALK_STRIDE * q, 0.0, 0.0, 0.0)
        } else {
            // Swing: forward, lifted, toe pointing down then up.
            let u = (q - 0.5) / 0.5;
            let s = 0.5 - 0.5 * (PI * u).cos();
            (-half_span + 2.0 * half_span * s, 0.1 * (PI * u).sin(), 0.35 * (TAU * u).sin(), 0.3 * (PI * u).sin())
        };
        let ankle = Vec3::new(x, ANKLE_Y + lift, travel + z);
        pose.leg_ik(side, ankle, Quat::from_rotation_x(pitch), toe);
        // Arms swing against the leg on their side.
        let swing = -0.35 * (TAU * q).cos();
        pose.arm(side, swing, 0.1, 0.25 + 0.15 * (0.5 + 0.5 * swing / 0.35));
    }
    pose
}

/// Idle pose at cycle frame `f` (0..48): hips sway from one leg to the other
/// by rolling (no travel, the feet stay put), and the chest breathes.
fn idle_pose(f: u32) -> Pose {
    let phi = TAU * (f % IDLE_FRAMES) as f32 / IDLE_FRAMES as f32;
    let mut pose = Pose::rest();
    pose.hips = Vec3::new(0.0, 0.935 - 0.008 * (2.0 * phi).cos(), 0.0);
    pose.rotation[HIPS] = Quat::from_euler(EulerRot::YXZ, 0.03 * phi.sin(), 0.0, 0.05 * phi.sin());
    pose.rotation[SPINE] = Quat::from_euler(EulerRot::YXZ, 0.0, 0.02 + 0.02 * (2.0 * phi).sin(), -0.04 * phi.sin());
    pose.rotation[CHEST] = Quat::from_euler(EulerRot::YXZ, 0.0, -0.03 * (2.0 * phi).sin(), -0.02 * phi.sin());
    pose.rotation[NECK] = Quat::from_euler(EulerRot::YXZ, 0.15 * (phi + 0.7).sin(), 0.0, 0.0);
    for side in 0..2 {
        let x = if side == 0 { 0.11 } else { -0.11 };
        pose.leg_ik(side, Vec3::new(x, ANKLE_Y, 0.0), Quat::IDENTITY, 0.0);
        let sway = 0.04 * (phi + side as f32 * PI).sin();
        pose.arm(side, sway, 0.12, 0.2 + 0.05 * (2.0 * phi).sin());
    }
    pose
}

/// One clip from `frames + 1` poses (first and last keys in place), keyed
/// every frame: hips translation and every joint's rotation, linear.
fn clip(glb: &mut GlbBuilder, name: &str, nodes: &[NodeId], poses: &[Pose]) -> Result<()> {
    let times: Vec<f32> = (0..poses.len()).map(|i| i as f32 / FPS).collect();
    let mut channels = vec![ChannelDesc {
        node: nodes[HIPS],
        interpolation: Interpolation::Linear,
        times: times.clone(),
        values: ChannelValues::Translation(poses.iter().map(|p| p.hips.to_array()).collect()),
    }];
    for (j, &node) in nodes.iter().enumerate() {
        let rotations: Vec<[f32; 4]> = poses.iter().map(|p| p.rotation[j].normalize().to_array()).collect();
        if rotations.iter().all(|r| *r == [0.0, 0.0, 0.0, 1.0]) {
            continue;
        }
        channels.push(ChannelDesc {
            node,
            interpolation: Interpolation::Linear,
            times: times.clone(),
            values: ChannelValues::Rotation(rotations),
        });
    }
    glb.add_animation(&AnimationDesc { name: name.into(), channels })
}

/// Largest distance a planted walk foot moves in the world between frames
/// (0 for feet that do not slide). The generator checks it stays tiny.
fn walk_foot_slide() -> f32 {
    let mut worst = 0.0f32;
    for f in 0..WALK_FRAMES {
        let (a, b) = (walk_pose(f).globals(), walk_pose(f + 1).globals());
        for (side, thigh) in LEG.iter().enumerate() {
            let q = (f as f32 / WALK_FRAMES as f32 + 0.5 * side as f32).fract();
            let q1 = q + 1.0 / WALK_FRAMES as f32;
            if q1 <= 0.5 + 1e-6 {
                let foot = thigh + 2;
                worst = worst.max(a[foot].1.distance(b[foot].1));
            }
        }
    }
    worst
}

/// The walker's triangle and joint counts, for the generator's summary.
pub struct Summary {
    pub joints: usize,
    pub triangles: Vec<(&'static str, usize)>,
    pub foot_slide: f32,
}

/// Writes demo/rigs/walker.glb.
pub fn write_walker(path: &Path) -> Result<Summary> {
    let mut glb = GlbBuilder::new();
    glb.set_generator("throng examples/make_demo (walker.glb)");

    // Skeleton, top down (children are attached after creation).
    let mut nodes: Vec<NodeId> = Vec::new();
    for (name, parent, t) in JOINTS {
        let n = glb.add_node(NodeDesc::new(name).translation(t))?;
        if let Some(p) = parent {
            glb.add_child(nodes[p], n)?;
        }
        nodes.push(n);
    }
    let inverse_bind: Vec<[f32; 16]> =
        rest_positions().iter().map(|p| Mat4::from_translation(-*p).to_cols_array()).collect();
    let skin = glb.add_skin(&nodes, &inverse_bind)?;

    let cloth = glb.add_material(&MaterialDesc::new("walker_cloth", [0.35, 0.38, 0.45, 1.0]).pbr(0.0, 0.8));
    let skin_tone = glb.add_material(&MaterialDesc::new("walker_skin", [0.62, 0.42, 0.32, 1.0]).pbr(0.0, 0.55));
    let meshes = [
        ("body_slim", body(Build { width: 1.0, depth: 1.0, limb: 1.0 }), cloth),
        ("body_broad", body(Build { width: 1.12, depth: 1.2, limb: 1.22 }), cloth),
        ("head", head(), skin_tone),
    ];
    let mut triangles = Vec::new();
    for (name, data, material) in &meshes {
        let mesh = glb.add_mesh(name, data, Some(*material))?;
        // glTF ignores a skinned mesh node's transform: leave it at identity.
        // `_mesh` keeps node names apart from the joints (there is a `head` joint).
        glb.add_node(NodeDesc::new(format!("{name}_mesh")).mesh(mesh).skin(skin))?;
        triangles.push((*name, data.triangle_count()));
    }

    let walk: Vec<Pose> = (0..=WALK_FRAMES).map(walk_pose).collect();
    clip(&mut glb, "Walk", &nodes, &walk)?;
    let idle: Vec<Pose> = (0..=IDLE_FRAMES).map(idle_pose).collect();
    clip(&mut glb, "Idle", &nodes, &idle)?;

    let foot_slide = walk_foot_slide();
    if foot_slide > 1e-3 {
        return Err(Error::invalid(path, format!("walk feet slide {foot_slide} m a frame; the IK is off")));
    }
    glb.write(path)?;
    Ok(Summary { joints: JOINTS.len(), triangles, foot_slide })
}
