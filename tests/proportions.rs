//! Body proportions (docs/wardrobes.md "Body proportions"): seeded bone
//! length and girth per joint group, drawn for a rig's bodies; the head
//! never stretched; feet on the ground; strides that follow leg length, so
//! a longer-legged or taller agent's cycle plays slower and its feet do not
//! slide.

mod common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use glam::{Affine3A, Vec3};
use throng::casting::skin::SkinnedRig;
use throng::casting::{AgentPose, ShotCrowd, ShotRig};

fn demo(rel: &str) -> String {
    common::repo_path(&format!("demo/{rel}")).display().to_string()
}

const PROPORTIONS: &str = r#"
[rigs.walker.proportions]
bodies = 4
head = ["head"]
legs = "legs"
[rigs.walker.proportions.groups.legs]
joints = ["thigh_l", "shin_l", "thigh_r", "shin_r"]
length = 0.12
girth = 0.1
[rigs.walker.proportions.groups.arms]
joints = ["upper_arm_l", "forearm_l", "upper_arm_r", "forearm_r"]
length = 0.08
girth = 0.15
[rigs.walker.proportions.groups.torso]
joints = ["spine", "chest"]
length = 0.05
girth = 0.12
"#;

/// Walking speed of the test cache, m/s.
const SPEED: f32 = 1.3;
/// Frames of the test shot.
const FRAMES: i32 = 48;

/// The demo walker's stride (m) and cycle length (frames) of `WalkA`.
fn walk_timing() -> (f32, f32) {
    let options = throng::shot::SkinOptions {
        cycles: [("WalkA".to_string(), "Walk".to_string())].into(),
        root: Some("hips".into()),
        ..Default::default()
    };
    let rig = SkinnedRig::load(Path::new(&demo("rigs/walker.glb")), &options, 24.0).unwrap();
    rig.cycle_timing("WalkA").unwrap()
}

/// A cache of `agents` walkers at `SPEED` along +Z (heading 0), 2 m apart in
/// X, frames 1..=FRAMES, their cycle frames advancing by distance over the
/// modelled stride as the simulation makes them; agent `idle` (if any)
/// stands on `IdleA`. Rows of agents in `skip` are left out.
fn cache_rows(agents: u32, idle: Option<u32>, skip: &[u32]) -> (String, BTreeMap<(i32, u32), f32>) {
    let (stride, length) = walk_timing();
    let mut csv = String::from("frame,id,x,y,z,heading,rig,cycle,cycle_frame,flags\n");
    let mut raw = BTreeMap::new();
    for f in 1..=FRAMES {
        for id in (1..=agents).filter(|id| !skip.contains(id)) {
            let x = id as f32 * 2.0;
            if Some(id) == idle {
                csv.push_str(&format!("{f},{id},{x:?},0,0,0,walker,IdleA,{:?},\n", (f % 20) as f32));
                continue;
            }
            let z = SPEED * f as f32 / 24.0;
            let cf = (z / stride * length + id as f32 * 1.7).rem_euclid(length);
            raw.insert((f, id), cf);
            csv.push_str(&format!("{f},{id},{x:?},0,{z:?},0,walker,WalkA,{cf:?},\n"));
        }
    }
    (csv, raw)
}

/// A shot of the demo walker (its own meshes) over the cache `csv`, with `extra` after `[rigs.walker]`.
fn walker_shot(dir: &Path, csv: &str, extra: &str) -> PathBuf {
    std::fs::write(dir.join("c.csv"), csv).unwrap();
    let shot = format!(
        r#"version = 1
name = "bodies"
seed = 11
no_scale_cycles = ["IdleA"]
[frames]
start = 1
end = {FRAMES}
fps = 24.0
[cache]
path = "c.csv"
[rigs.walker]
file = "{walker}"
kind = "skinned"
cycles = {{ WalkA = "Walk", IdleA = "Idle" }}
root = "hips"
height_jitter = 0.1
{extra}
[camera]
[[camera.keys]]
frame = 1
position = [0.0, 1.2, -6.0]
aim = [0.0, 0.9, 0.0]
focal_length = 35.0
[layers]
count = 1
[render]
resolution = [32, 18]
spp = 1
max_bounces = 1
"#,
        walker = demo("rigs/walker.glb"),
    );
    let path = dir.join("shot.toml");
    std::fs::write(&path, shot).unwrap();
    path
}

fn skinned(crowd: &ShotCrowd) -> &SkinnedRig {
    let Some(ShotRig::Skinned(rig)) = crowd.rigs().get("walker") else { panic!("skinned walker") };
    rig
}

fn node(_crowd: &ShotCrowd, name: &str) -> usize {
    let (doc, _, _) = gltf::import(demo("rigs/walker.glb")).unwrap();
    doc.nodes().find(|n| n.name() == Some(name)).unwrap().index()
}

/// Index of the rig piece whose mesh is `mesh` (posed once to read its name).
fn piece(rig: &SkinnedRig, mesh: &str) -> usize {
    let joints = rig.step_joints(0, 0);
    (0..rig.piece_count()).find(|&p| rig.pose_piece(p, &joints, "x").name.contains(&format!("#{mesh}@"))).unwrap()
}

/// The largest spread of |a_i - a_j| / |b_i - b_j| over vertex pairs, relative to its mean:
/// 0 when `a` is `b` scaled uniformly (and moved rigidly).
fn distance_ratio_spread(a: &[Vec3], b: &[Vec3]) -> (f32, f32) {
    let mut ratios = Vec::new();
    for i in (0..a.len()).step_by(7) {
        for j in (i + 1..a.len()).step_by(5) {
            let d = b[i].distance(b[j]);
            if d > 1e-3 {
                ratios.push(a[i].distance(a[j]) / d);
            }
        }
    }
    let mean = ratios.iter().sum::<f32>() / ratios.len() as f32;
    let spread = ratios.iter().map(|r| (r - mean).abs()).fold(0.0, f32::max) / mean;
    (mean, spread)
}

#[test]
fn heads_stay_uniform_while_limbs_vary() {
    let dir = common::tempdir().unwrap();
    let (csv, _) = cache_rows(6, None, &[]);
    let crowd = ShotCrowd::load(&walker_shot(dir.path(), &csv, PROPORTIONS)).unwrap();
    let rig = skinned(&crowd);
    assert_eq!(rig.body_count(), 4);
    let cycle = rig.cycle_index("WalkA").unwrap();
    let (head, body) = (piece(rig, "head"), piece(rig, "body_slim"));
    let (thigh, shin, upper, fore) =
        (node(&crowd, "thigh_l"), node(&crowd, "shin_l"), node(&crowd, "upper_arm_l"), node(&crowd, "forearm_l"));
    let (doc, _, _) = gltf::import(demo("rigs/walker.glb")).unwrap();
    let skin_joints: Vec<usize> = doc.skins().next().unwrap().joints().map(|j| j.index()).collect();
    let head_node = node(&crowd, "head");
    let mut leg_lengths = Vec::new();
    for step in [0, 7, 19] {
        let modelled = rig.step_joints(cycle, step);
        // The head joint's own vertices (the head mesh's neck is weighted to the neck and chest, and follows them).
        let on_head: Vec<usize> = (rig.piece(head).influences.iter().enumerate())
            .filter(|(_, inf)| inf.iter().any(|&(j, w)| skin_joints[j as usize] == head_node && w == 1.0))
            .map(|(i, _)| i)
            .collect();
        assert!(on_head.len() > 100, "{} head vertices", on_head.len());
        let only = |p: Vec<Vec3>| on_head.iter().map(|&i| p[i]).collect::<Vec<_>>();
        let modelled_head = only(rig.pose_piece(head, &modelled, "m").positions);
        let modelled_body = rig.pose_piece(body, &modelled, "m").positions;
        let bone = |j: &[Affine3A], a: usize, b: usize| j[a].translation.distance(j[b].translation);
        for b in 1..=rig.body_count() {
            let joints = rig.body_step_joints(b, cycle, step);
            // The head: every vertex distance kept (scale 1 in rig space; the
            // agent's height scale then scales it uniformly with the rest).
            let posed = only(rig.pose_body_piece(b, head, &joints, "b").positions);
            let (mean, spread) = distance_ratio_spread(&posed, &modelled_head);
            assert!(
                (mean - 1.0).abs() < 1e-4 && spread < 1e-4,
                "body {b} step {step}: head ratio {mean}, spread {spread}"
            );
            // The body mesh is stretched: its distances do not keep one ratio.
            let posed = rig.pose_body_piece(b, body, &joints, "b").positions;
            let (_, spread) = distance_ratio_spread(&posed, &modelled_body);
            assert!(spread > 0.01, "body {b} step {step}: the body mesh should change shape (spread {spread})");
            // Bones of a group scale by the group's one draw, on both sides alike.
            let legs = bone(&joints, thigh, shin) / bone(&modelled, thigh, shin);
            let arms = bone(&joints, upper, fore) / bone(&modelled, upper, fore);
            assert!((0.88 - 1e-4..=1.12 + 1e-4).contains(&legs), "legs x{legs}");
            assert!((0.92 - 1e-4..=1.08 + 1e-4).contains(&arms), "arms x{arms}");
            let (thigh_r, shin_r) = (node(&crowd, "thigh_r"), node(&crowd, "shin_r"));
            let right = bone(&joints, thigh_r, shin_r) / bone(&modelled, thigh_r, shin_r);
            assert!((legs - right).abs() < 1e-4, "left {legs} and right {right} legs differ");
            assert!(
                (rig.body_stride(b) - legs).abs() < 1e-4,
                "the stride follows the legs: {} vs {legs}",
                rig.body_stride(b)
            );
            if step == 0 {
                leg_lengths.push(legs);
            }
        }
    }
    leg_lengths.sort_by(f32::total_cmp);
    assert!(leg_lengths[3] - leg_lengths[0] > 0.02, "bodies differ: {leg_lengths:?}");
    // Every agent plays one of the bodies, and the posed geometry grows with bodies, not agents.
    let bodies: std::collections::BTreeSet<u16> = crowd.casting().iter().map(|c| c.body).collect();
    assert!(bodies.iter().all(|&b| (1..=4).contains(&b)), "{bodies:?}");
    assert!(bodies.len() >= 2, "{bodies:?}");
}

/// The lowest vertex of every piece of the file posed at `joints` on body `b`.
fn lowest(rig: &SkinnedRig, b: u16, joints: &[Affine3A]) -> f32 {
    let pieces = [piece(rig, "body_slim"), piece(rig, "head")];
    let posed = pieces.iter().flat_map(|&p| rig.pose_body_piece(b, p, joints, "x").positions);
    posed.map(|v| v.y).fold(f32::INFINITY, f32::min)
}

#[test]
fn feet_stay_on_the_ground() {
    let dir = common::tempdir().unwrap();
    let (csv, _) = cache_rows(2, None, &[]);
    let crowd = ShotCrowd::load(&walker_shot(dir.path(), &csv, PROPORTIONS)).unwrap();
    let rig = skinned(&crowd);
    let cycle = rig.cycle_index("WalkA").unwrap();
    let steps = rig.cycles()[cycle].steps;
    let mut worst: f32 = 0.0;
    for b in 1..=rig.body_count() {
        for step in 0..steps {
            let modelled = lowest(rig, 0, &rig.step_joints(cycle, step));
            let body = lowest(rig, b, &rig.body_step_joints(b, cycle, step));
            worst = worst.max((body - modelled).abs());
        }
    }
    // Every step is lifted so its lowest point is the modelled body's.
    assert!(worst < 1e-4, "the lowest point moved {worst} m from the modelled body's");
    // A body with longer legs stands taller.
    let tallest = (1..=rig.body_count()).max_by(|&a, &b| rig.body_stride(a).total_cmp(&rig.body_stride(b))).unwrap();
    assert!(rig.body_height(tallest) > rig.height(), "{} vs {}", rig.body_height(tallest), rig.height());
}

/// World position of joint `j` of agent `id` at shot frame `f`, posed at
/// the cycle frame the crowd plays (`raw: None`) or at the cache's (`Some`).
fn joint_at(crowd: &ShotCrowd, id: u32, f: i32, j: usize, raw: Option<f32>) -> Vec3 {
    let block = crowd.agents_at(f).unwrap();
    let a = block.agents.iter().find(|a| a.id == id).unwrap();
    let AgentPose::Skinned { world_from_rig, body, cycle, step } = crowd.agent_pose(a).unwrap() else { panic!() };
    let rig = skinned(crowd);
    let step = match raw {
        None => step,
        Some(cf) => {
            let (length, steps) = (rig.cycle_frames(cycle), rig.cycles()[cycle].steps);
            ((cf.rem_euclid(length) / (length / steps as f32)).round() as u32).min(steps)
        }
    };
    world_from_rig.transform_point3(rig.body_step_joints(body, cycle, step)[j].translation.into())
}

/// How far a planted foot slides, metres a frame on average: over frames
/// where the lower toe is within 5 mm of its lowest at both ends, its world travel.
fn slide(crowd: &ShotCrowd, id: u32, raw: Option<&BTreeMap<(i32, u32), f32>>) -> f32 {
    let toes = [node(crowd, "toe_l"), node(crowd, "toe_r")];
    let at = |f: i32, j: usize| joint_at(crowd, id, f, j, raw.map(|r| r[&(f, id)]));
    let ground = (1..=FRAMES).flat_map(|f| toes.map(|t| at(f, t).y)).fold(f32::INFINITY, f32::min);
    let (mut total, mut n) = (0.0, 0);
    for f in 1..FRAMES {
        let low = *toes.iter().min_by(|&&a, &&b| at(f, a).y.total_cmp(&at(f, b).y)).unwrap();
        let (p, q) = (at(f, low), at(f + 1, low));
        if p.y.max(q.y) < ground + 0.005 {
            total += Vec3::new(q.x - p.x, 0.0, q.z - p.z).length();
            n += 1;
        }
    }
    assert!(n > 5, "agent {id}: planted frames {n}");
    total / n as f32
}

#[test]
fn strides_follow_leg_length_so_feet_do_not_slide() {
    let dir = common::tempdir().unwrap();
    let (csv, raw) = cache_rows(8, None, &[]);
    // Fine pose steps, so what is measured is the timing, not the snapping to steps.
    let extra = format!("pose_step = 0.1\n{PROPORTIONS}");
    let crowd = ShotCrowd::load(&walker_shot(dir.path(), &csv, &extra)).unwrap();
    let rig = skinned(&crowd);
    let pace = |id: u32| {
        let c = crowd.cast(id).unwrap();
        c.height_scale * rig.body_stride(c.body)
    };
    // The agent whose pace is farthest from 1, and the played advance per
    // frame against the cache's: slower by the pace.
    let id = (1..=8).max_by(|&a, &b| (pace(a) - 1.0).abs().total_cmp(&(pace(b) - 1.0).abs())).unwrap();
    let k = pace(id);
    assert!((k - 1.0).abs() > 0.05, "an agent with a pace away from 1: {k}");
    let length = rig.cycle_frames(rig.cycle_index("WalkA").unwrap());
    let played = |f: i32| crowd.agents_at(f).unwrap().agents.iter().find(|a| a.id == id).unwrap().cycle_frame;
    let advance = |a: f32, b: f32| (b - a).rem_euclid(length);
    for f in [2, 17, 30] {
        let cache = advance(raw[&(f, id)], raw[&(f + 1, id)]);
        let got = advance(played(f), played(f + 1));
        assert!((got - cache / k).abs() < 1e-3, "frame {f}: played advance {got}, cache {cache} / pace {k}");
    }
    // The planted foot slides far less than it would at the cache's cycle
    // frames. (What is left is the walk's own: its toes roll and slip a few
    // millimetres a frame at pace 1 too.)
    let timed = slide(&crowd, id, None);
    let untimed = slide(&crowd, id, Some(&raw));
    eprintln!("agent {id} pace {k:.3}: slide {timed:.4} m/frame retimed, {untimed:.4} at the cache's cycle frames");
    assert!(timed < 0.6 * untimed, "retimed {timed} vs {untimed}");
}

#[test]
fn still_agents_and_order_keep_their_bodies() {
    let dir = common::tempdir().unwrap();
    // Agent 3 stands on a no-scale cycle: the modelled body, height 1, cache timing.
    let (csv, _) = cache_rows(9, Some(3), &[]);
    let crowd = ShotCrowd::load(&walker_shot(dir.path(), &csv, PROPORTIONS)).unwrap();
    let idle = crowd.cast(3).unwrap();
    assert_eq!((idle.body, idle.height_scale), (0, 1.0));
    for f in [1, 20] {
        let block = crowd.agents_at(f).unwrap();
        let a = block.agents.iter().find(|a| a.id == 3).unwrap();
        assert_eq!(a.cycle_frame, (f % 20) as f32, "a no-scale cycle plays as cached");
    }
    // Removing agent 7 changes no other agent's body or played cycle frames.
    let other = common::tempdir().unwrap();
    let (csv, _) = cache_rows(9, Some(3), &[7]);
    let without = ShotCrowd::load(&walker_shot(other.path(), &csv, PROPORTIONS)).unwrap();
    for id in (1..=9).filter(|&id| id != 7) {
        assert_eq!(crowd.cast(id).unwrap().body, without.cast(id).unwrap().body, "agent {id}");
        for f in [1, 25, FRAMES] {
            let find = |c: &ShotCrowd| c.agents_at(f).unwrap().agents.iter().find(|a| a.id == id).copied().unwrap();
            assert_eq!(find(&crowd), find(&without), "agent {id} frame {f}");
        }
    }
    // The bodies and their poses: posed geometry grows with the rig's bodies, not its agents.
    let plain_dir = common::tempdir().unwrap();
    let plain = ShotCrowd::load(&walker_shot(plain_dir.path(), &csv, "")).unwrap();
    let (posed, modelled) = (crowd.poses().skins().mesh_count(), plain.poses().skins().mesh_count());
    assert!(posed <= 5 * modelled, "{posed} posed meshes with 4 bodies, {modelled} without");
}

#[test]
fn a_carried_prop_keeps_its_size() {
    let dir = common::tempdir().unwrap();
    let walker = demo("rigs/walker.glb");
    std::fs::write(
        dir.path().join("w.toml"),
        format!(
            r#"version = 1
name = "carry"
[schemes.Carry]
[[schemes.Carry.parts]]
slot = "body"
file = "{walker}"
mesh = "body_slim"
[[schemes.Carry.parts]]
slot = "head"
file = "{walker}"
mesh = "head"
[[schemes.Carry.props]]
group = "hand"
name = "ball"
joint = "hand_r"
file = "{heads}"
mesh = "head_sphere"
"#,
            heads = demo("parts/heads.glb")
        ),
    )
    .unwrap();
    let (csv, _) = cache_rows(3, None, &[]);
    let extra = format!("schemes = {{ Carry = 1.0 }}\nslots = [\"body\", \"head\"]\n{PROPORTIONS}");
    let shot = walker_shot(dir.path(), &csv, &extra);
    let text =
        std::fs::read_to_string(&shot).unwrap().replacen("seed = 11\n", "seed = 11\nwardrobes = [\"w.toml\"]\n", 1);
    std::fs::write(&shot, text).unwrap();
    let crowd = ShotCrowd::load(&shot).unwrap();
    let a = crowd.agents_at(5).unwrap().agents[0];
    assert_ne!(crowd.cast(a.id).unwrap().body, 0);
    let mut insts = Vec::new();
    crowd.agent_instances(&a, throng::casting::Lod::Full, throng::scene::vis::ALL, &mut insts).unwrap();
    let ball = insts.iter().find(|i| i.part == 2).expect("the ball");
    let mesh = &crowd.library().meshes[ball.mesh as usize];
    let (doc, buffers, _) = gltf::import(demo("parts/heads.glb")).unwrap();
    let m = doc.meshes().find(|m| m.name() == Some("head_sphere")).unwrap();
    let prim = m.primitives().next().unwrap();
    let file: Vec<Vec3> =
        prim.reader(|b| Some(&buffers[b.index()])).read_positions().unwrap().map(Vec3::from).collect();
    let world: Vec<Vec3> = mesh.positions.iter().map(|p| ball.world_from_object.transform_point3(*p)).collect();
    let (mean, spread) = distance_ratio_spread(&world, &file);
    let h = crowd.cast(a.id).unwrap().height_scale;
    assert!(
        (mean - h).abs() < 1e-3 && spread < 1e-3,
        "the ball scales by the height {h} only: x{mean}, spread {spread}"
    );
}

#[test]
fn bad_proportions_are_refused_naming_the_key() {
    let cases: &[(&str, &str, &str)] = &[
        (
            "joints = [\"thigh_l\", \"shin_l\", \"thigh_r\", \"shin_r\"]",
            "joints = [\"thigh_x\"]",
            "rigs.walker.proportions.groups.legs.joints[0]",
        ),
        (
            "joints = [\"spine\", \"chest\"]",
            "joints = [\"spine\", \"head\"]",
            "rigs.walker.proportions.groups.torso.joints[1]",
        ),
        ("head = [\"head\"]", "head = [\"chest\"]", "rigs.walker.proportions.groups.arms.joints[0]"),
        (
            "joints = [\"spine\", \"chest\"]",
            "joints = [\"spine\", \"shin_l\"]",
            "rigs.walker.proportions.groups.torso.joints[1]",
        ),
        ("length = 0.12", "length = 0.5", "rigs.walker.proportions.groups.legs.length"),
        ("girth = 0.1\n", "girth = -0.1\n", "rigs.walker.proportions.groups.legs.girth"),
        ("bodies = 4", "bodies = 0", "rigs.walker.proportions.bodies"),
        ("bodies = 4", "bodies = 65", "rigs.walker.proportions.bodies"),
        ("legs = \"legs\"", "legs = \"leg\"", "rigs.walker.proportions.legs"),
        ("head = [\"head\"]\n", "", "rigs.walker.proportions.head"),
        ("head = [\"head\"]", "head = [\"hed\"]", "rigs.walker.proportions.head[0]"),
    ];
    let (csv, _) = cache_rows(2, None, &[]);
    for (from, to, field) in cases {
        let dir = common::tempdir().unwrap();
        assert!(PROPORTIONS.contains(from), "{from}");
        let shot = walker_shot(dir.path(), &csv, &PROPORTIONS.replacen(from, to, 1));
        let (code, _, err) = common::run(&["cast", shot.to_str().unwrap(), "--stats"]);
        assert_eq!(code, 2, "{to}: {err}");
        assert!(err.contains(field), "{to}: the error names {field}: {err}");
        assert!(!err.contains("panicked"), "{err}");
    }
}

#[test]
fn a_lineup_of_bodies_renders() {
    // Seven walkers side by side facing the camera, each on its own body:
    // kept for looking at in target/tmp/proportions_lineup.png.
    let dir = common::tempdir().unwrap();
    let mut csv = String::from("frame,id,x,y,z,heading,rig,cycle,cycle_frame,flags\n");
    for f in 1..=FRAMES {
        for id in 1..=7u32 {
            let x = (id as f32 - 4.0) * 0.75;
            csv.push_str(&format!("{f},{id},{x:?},0,0,0,walker,WalkA,{:?},\n", (f as f32 * 0.5 + id as f32 * 4.0)));
        }
    }
    let spread = PROPORTIONS
        .replace("bodies = 4", "bodies = 64")
        .replace("length = 0.12", "length = 0.2")
        .replace("girth = 0.15", "girth = 0.3")
        .replace("girth = 0.12", "girth = 0.3");
    let shot = walker_shot(dir.path(), &csv, &spread);
    let text = std::fs::read_to_string(&shot)
        .unwrap()
        .replace("position = [0.0, 1.2, -6.0]", "position = [0.0, 1.1, 6.5]")
        .replace("resolution = [32, 18]", "resolution = [480, 200]");
    std::fs::write(&shot, text).unwrap();
    let crowd = ShotCrowd::load(&shot).unwrap();
    let bodies: std::collections::BTreeSet<u16> = (1..=7).map(|id| crowd.cast(id).unwrap().body).collect();
    assert!(bodies.len() >= 5, "most of the seven on bodies of their own: {bodies:?}");
    let out = dir.path().join("renders");
    let args = ["render", shot.to_str().unwrap(), "--layer", "full", "--frames", "10", "--png", "--spp", "8"];
    let (code, stdout, err) = common::run(&[&args[..], &["--out", out.to_str().unwrap()]].concat());
    assert_eq!(code, 0, "{stdout}\n{err}");
    let png = std::fs::read_dir(out.join("full"))
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .find(|p| p.extension().is_some_and(|e| e == "png"));
    let png = png.expect("a PNG preview");
    let img = image::open(&png).unwrap().to_rgb8();
    // The walkers cover a good part of the frame.
    let exr = png.with_extension("exr");
    let (film, _) = throng::render::exr::read_layer(&exr).unwrap();
    let ids = &film.agent_id;
    let covered = ids.iter().filter(|&&id| id != 0).count() as f32 / ids.len() as f32;
    assert!(covered > 0.1, "walkers cover {covered} of the frame");
    assert_eq!((img.width(), img.height()), (480, 200));
    std::fs::copy(&png, Path::new(env!("CARGO_TARGET_TMPDIR")).join("proportions_lineup.png")).unwrap();
}
