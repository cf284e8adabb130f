//! Skinned characters: exact skinning against hand-worked values on Khronos'
//! SimpleSkin, RiggedFigure (a skeleton under a Z-up parent node) standing
//! upright, pose instancing, invariants, determinism, and bad input.

mod common;

use std::path::{Path, PathBuf};

use glam::{Quat, Vec3};
use throng::casting::skin::SkinnedRig;
use throng::casting::{AgentPose, Lod, ShotCrowd};
use throng::scene::vis;
use throng::shot::SkinOptions;

const FPS: f32 = 24.0;

fn simple_skin(name: &str) -> PathBuf {
    common::shared_asset("gltf/SimpleSkin").join(name)
}

fn load(path: &Path, options: SkinOptions) -> SkinnedRig {
    SkinnedRig::load(path, &options, FPS).unwrap_or_else(|e| panic!("{} loads: {e}", path.display()))
}

/// SimpleSkin's posed vertices worked out by hand. Joint 0 sits at (0, 1, 0)
/// and does not move; joint 1 (its child, at the same place) rotates about Z.
/// Both inverse bind matrices are a translation by (0, -1, 0), so joint 1's
/// skin matrix is a rotation about the pivot (0, 1, 0), and a vertex with
/// weights (w0, w1) lands at `w0 * v + w1 * (p + R(v - p))`.
fn hand_posed(v: Vec3, w1: f32, angle: f32) -> Vec3 {
    let p = Vec3::new(0.0, 1.0, 0.0);
    let r = Quat::from_rotation_z(angle);
    (1.0 - w1) * v + w1 * (p + r * (v - p))
}

/// The file's ten vertices (x = +-0.5 at y = 0, 0.5, .., 2) and the weight of
/// joint 1 at each height (0, 0.25, 0.5, 0.75, 1).
fn simple_skin_vertices() -> Vec<(Vec3, f32)> {
    (0..10)
        .map(|i| (Vec3::new(if i % 2 == 0 { -0.5 } else { 0.5 }, (i / 2) as f32 * 0.5, 0.0), (i / 2) as f32 * 0.25))
        .collect()
}

fn assert_close(got: Vec3, want: Vec3, what: &str) {
    assert!(got.distance(want) < 2e-4, "{what}: got {got}, want {want}");
}

#[test]
fn simple_skin_matches_positions_worked_by_hand() {
    // Pose step 6 frames = 0.25 s at 24 fps: steps land on the keys (every
    // 0.5 s) and halfway between them.
    let rig = load(&simple_skin("SimpleSkin.gltf"), SkinOptions { pose_step: Some(6.0), ..Default::default() });
    assert!((rig.height() - 2.0).abs() < 1e-5, "rest height {}", rig.height());
    let cycle = rig.cycle_index("#0").expect("the unnamed clip is cycle #0");
    assert_eq!(rig.cycles()[cycle].steps, 22, "5.5 s clip in 0.25 s steps");
    // Key 1 (t = 0.5 s) is the quaternion (0, 0, 0.383, 0.924): 45.03 degrees.
    let key1 = 2.0 * 0.383f32.atan2(0.924);
    // (step, angle): t = 0 rest; 0.25 s halfway to key 1 (slerp: half the
    // angle); 0.5 s key 1; 1.0 s key 2 (0, 0, .707, .707) = 90 degrees;
    // 4.0 s key 8 = -90 degrees.
    for (step, angle) in
        [(0, 0.0), (1, key1 / 2.0), (2, key1), (4, std::f32::consts::FRAC_PI_2), (16, -std::f32::consts::FRAC_PI_2)]
    {
        let joints = rig.step_joints(cycle, step);
        let posed = rig.pose_piece(0, &joints, "test");
        assert_eq!(posed.positions.len(), 10);
        for (i, (v, w1)) in simple_skin_vertices().into_iter().enumerate() {
            assert_close(posed.positions[i], hand_posed(v, w1, angle), &format!("step {step} vertex {i}"));
        }
    }
    // Spot values written out: at 90 degrees the tip (-0.5, 2) swings to (-1, 0.5).
    let tip = rig.pose_piece(0, &rig.step_joints(cycle, 4), "t").positions[8];
    assert_close(tip, Vec3::new(-1.0, 0.5, 0.0), "tip at 90 degrees");
    // The middle vertex (-0.5, 1), half on each joint: (-0.25, 0.75).
    let mid = rig.pose_piece(0, &rig.step_joints(cycle, 4), "t").positions[4];
    assert_close(mid, Vec3::new(-0.25, 0.75, 0.0), "middle at 90 degrees");
}

/// SimpleSkin with a rigid mesh (its own vertices, no weights) on a node
/// one metre up joint 1 (the rotating one), and the same mesh on a
/// top-level node outside the skeleton.
fn simple_skin_with_a_rigid_limb(dir: &Path) -> PathBuf {
    let mut doc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(simple_skin("SimpleSkin.gltf")).unwrap()).unwrap();
    doc["meshes"].as_array_mut().unwrap().push(serde_json::json!({
        "name": "limb", "primitives": [{ "attributes": { "POSITION": 1 }, "indices": 0 }]
    }));
    let nodes = doc["nodes"].as_array_mut().unwrap();
    nodes.push(serde_json::json!({ "name": "limb", "mesh": 1, "translation": [0.0, 1.0, 0.0] }));
    nodes.push(serde_json::json!({ "name": "floor", "mesh": 1 }));
    doc["nodes"][2]["children"] = serde_json::json!([3]);
    doc["scenes"][0]["nodes"] = serde_json::json!([0, 1, 4]);
    // Buffers are data URIs, so the copy stands alone.
    let file = dir.join("limb.gltf");
    std::fs::write(&file, serde_json::to_string(&doc).unwrap()).unwrap();
    file
}

#[test]
fn a_mesh_parented_to_a_joint_follows_it_rigidly() {
    let dir = common::tempdir().unwrap();
    let path = simple_skin_with_a_rigid_limb(dir.path());
    let rig = load(&path, SkinOptions { pose_step: Some(6.0), ..Default::default() });
    // The limb stands on joint 1: up to 1 + 1 + 2 m in the rest pose.
    assert!((rig.height() - 4.0).abs() < 1e-5, "rest height {}", rig.height());
    assert!(rig.warnings().iter().any(|w| w.contains("`floor`") && w.contains("left out")), "{:?}", rig.warnings());
    let cycle = rig.cycle_index("#0").unwrap();
    let key1 = 2.0 * 0.383f32.atan2(0.924);
    for (step, angle) in
        [(0, 0.0), (1, key1 / 2.0), (2, key1), (4, std::f32::consts::FRAC_PI_2), (16, -std::f32::consts::FRAC_PI_2)]
    {
        let joints = rig.step_joints(cycle, step);
        // Piece 0 is the skin, piece 1 the limb: joint 1's transform,
        // (0, 1, 0) then the rotation, applied to (0, 1, 0) + v.
        let skin = rig.pose_piece(0, &joints, "t");
        let limb = rig.pose_piece(1, &joints, "t");
        let r = Quat::from_rotation_z(angle);
        for (i, (v, w1)) in simple_skin_vertices().into_iter().enumerate() {
            assert_close(skin.positions[i], hand_posed(v, w1, angle), &format!("skin, step {step} vertex {i}"));
            let want = Vec3::new(0.0, 1.0, 0.0) + r * (Vec3::new(0.0, 1.0, 0.0) + v);
            assert_close(limb.positions[i], want, &format!("limb, step {step} vertex {i}"));
        }
    }
}

#[test]
fn a_shot_casts_the_joint_parented_mesh_with_the_skin() {
    let dir = common::tempdir().unwrap();
    let file = simple_skin_with_a_rigid_limb(dir.path());
    let shot = common::figure_shot(dir.path(), &common::five_walkers(), "");
    let text = std::fs::read_to_string(&shot).unwrap();
    let figure = common::shared_asset("gltf/RiggedFigure/RiggedFigure.gltf");
    std::fs::write(&shot, text.replace(&figure.display().to_string(), &file.display().to_string())).unwrap();
    let (code, out, err) = common::run(&["cast".as_ref(), shot.as_os_str(), "--json".as_ref()]);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("`floor`") && err.contains("left out"), "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let text = v.to_string();
    assert!(text.contains("limb"), "the limb is cast: {text}");
}

/// A robot built as RobotExpressive is: a skeleton (hips, torso, head,
/// arms, hands, legs) whose body parts are separate meshes on nodes
/// parented to its joints, not skinned, and only the hands a skinned mesh
/// (the two hands, bound wholly to their hand joints). Its one clip swings
/// the legs and arms 25 degrees about X over a second. `parts` false leaves
/// the joint-parented meshes out: the hands alone, what throng drew of
/// RobotExpressive before joint-parented meshes were read.
fn write_robot(dir: &Path, name: &str, parts: bool) -> PathBuf {
    use throng::export::glb::{
        AnimationDesc, ChannelDesc, ChannelValues, GlbBuilder, Interpolation, MaterialDesc, MaterialId, MeshData,
        NodeDesc,
    };
    let v = Vec3::new;
    let mut b = GlbBuilder::new();
    let paint = b.add_material(&MaterialDesc::new("paint", [0.85, 0.55, 0.1, 1.0]));
    let dark = b.add_material(&MaterialDesc::new("dark", [0.08, 0.08, 0.1, 1.0]));
    let steel = b.add_material(&MaterialDesc::new("steel", [0.6, 0.62, 0.66, 1.0]));
    // (joint, parent, offset from the parent, its mesh's box in joint space, material)
    type Joint = (&'static str, Option<usize>, Vec3, Option<(Vec3, Vec3)>, MaterialId);
    let joints: [Joint; 9] = [
        ("hips", None, v(0.0, 0.9, 0.0), Some((v(-0.17, -0.1, -0.11), v(0.17, 0.1, 0.11))), steel),
        ("torso", Some(0), v(0.0, 0.1, 0.0), Some((v(-0.21, 0.0, -0.13), v(0.21, 0.5, 0.13))), paint),
        ("head", Some(1), v(0.0, 0.55, 0.0), Some((v(-0.16, 0.0, -0.15), v(0.16, 0.3, 0.15))), paint),
        ("leg_l", Some(0), v(0.1, -0.05, 0.0), Some((v(-0.06, -0.85, -0.07), v(0.06, 0.0, 0.07))), steel),
        ("leg_r", Some(0), v(-0.1, -0.05, 0.0), Some((v(-0.06, -0.85, -0.07), v(0.06, 0.0, 0.07))), steel),
        ("arm_l", Some(1), v(0.27, 0.47, 0.0), Some((v(-0.05, -0.45, -0.05), v(0.05, 0.03, 0.05))), steel),
        ("arm_r", Some(1), v(-0.27, 0.47, 0.0), Some((v(-0.05, -0.45, -0.05), v(0.05, 0.03, 0.05))), steel),
        ("hand_l", Some(5), v(0.0, -0.45, 0.0), None, dark),
        ("hand_r", Some(6), v(0.0, -0.45, 0.0), None, dark),
    ];
    let mut nodes = Vec::new();
    let mut world = Vec::new();
    for (name, parent, offset, mesh, material) in joints {
        let n = b.add_node(NodeDesc::new(name).translation(offset.to_array())).unwrap();
        let at = parent.map_or(Vec3::ZERO, |p: usize| world[p]) + offset;
        if let Some(p) = parent {
            b.add_child(nodes[p], n).unwrap();
        }
        if let (true, Some((lo, hi))) = (parts, mesh) {
            let m = b.add_mesh(&format!("{name}_part"), &common::cuboid(lo, hi), Some(material)).unwrap();
            let child = b.add_node(NodeDesc::new(format!("{name}_part")).mesh(m)).unwrap();
            b.add_child(n, child).unwrap();
        }
        nodes.push(n);
        world.push(at);
    }
    // A visor on the head's front (+Z): the way the robot faces.
    if parts {
        let m = b.add_mesh("visor", &common::cuboid(v(-0.12, 0.12, 0.14), v(0.12, 0.22, 0.17)), Some(dark)).unwrap();
        let child = b.add_node(NodeDesc::new("visor").mesh(m)).unwrap();
        b.add_child(nodes[2], child).unwrap();
    }
    // The skinned hands, in the bind (rest) pose, each wholly on its joint.
    let mut hands = MeshData::default();
    for joint in [7, 8] {
        let c = world[joint] + v(0.0, -0.06, 0.0);
        let mut cube = common::cuboid(c - v(0.06, 0.07, 0.06), c + v(0.06, 0.07, 0.06));
        let base = hands.positions.len() as u32;
        hands.positions.append(&mut cube.positions);
        hands.normals.append(&mut cube.normals);
        hands.indices.extend(cube.indices.iter().map(|i| i + base));
    }
    let count = hands.positions.len();
    hands.joints = (0..count).map(|i| [if i < count / 2 { 7 } else { 8 }, 0, 0, 0]).collect();
    hands.weights = vec![[1.0, 0.0, 0.0, 0.0]; count];
    let inverse_bind: Vec<[f32; 16]> =
        world.iter().map(|w| glam::Mat4::from_translation(-*w).to_cols_array()).collect();
    let skin = b.add_skin(&nodes, &inverse_bind).unwrap();
    let mesh = b.add_mesh("hands", &hands, Some(dark)).unwrap();
    b.add_node(NodeDesc::new("hands").mesh(mesh).skin(skin)).unwrap();
    // Walk: legs and the opposite arms swing about X.
    let times: Vec<f32> = (0..=4).map(|i| i as f32 / 4.0).collect();
    let channels = [(3, 1.0), (4, -1.0), (5, -1.0), (6, 1.0)]
        .map(|(joint, swing): (usize, f32)| ChannelDesc {
            node: nodes[joint],
            interpolation: Interpolation::Linear,
            times: times.clone(),
            values: ChannelValues::Rotation(
                times
                    .iter()
                    .map(|t| {
                        Quat::from_rotation_x(swing * 25f32.to_radians() * (t * std::f32::consts::TAU).sin()).to_array()
                    })
                    .collect(),
            ),
        })
        .to_vec();
    b.add_animation(&AnimationDesc { name: "Walk".into(), channels }).unwrap();
    let path = dir.join(name);
    b.write(&path).unwrap();
    path
}

/// Five RobotExpressive-like robots rendered whole: their joint-parented
/// parts cover many times the pixels of their skinned hands (all that was
/// drawn before), and follow their joints. Kept for looking at:
/// target/tmp/joint_parented_robots.png.
#[test]
fn robots_with_joint_parented_parts_render_whole() {
    let render = |parts: bool| {
        let dir = common::tempdir().unwrap();
        let robot = write_robot(dir.path(), "robot.glb", parts);
        let shot = common::figure_shot(dir.path(), &common::five_walkers(), "");
        let figure = common::shared_asset("gltf/RiggedFigure/RiggedFigure.gltf");
        let text = std::fs::read_to_string(&shot)
            .unwrap()
            .replace(&figure.display().to_string(), &robot.display().to_string())
            .replace("resolution = [160, 90]", "resolution = [480, 270]")
            .replace("position = [0.0, 1.1, 5.5]", "position = [0.0, 1.2, 6.5]")
            .replace("aim = [0.0, 0.75, 0.0]", "aim = [0.0, 0.8, -1.2]");
        std::fs::write(&shot, text).unwrap();
        let crowd = ShotCrowd::load(&shot).unwrap();
        let block = crowd.agents_at(1023).unwrap();
        let mut out = Vec::new();
        crowd.agent_instances(&block.agents[0], Lod::Full, vis::ALL, &mut out).unwrap();
        // Eight parts and the visor on their joints, and the skinned hands.
        assert_eq!(out.len(), if parts { 9 } else { 1 }, "instances of one robot");
        let renders = dir.path().join("renders");
        let args = ["render", shot.to_str().unwrap(), "--layer", "full", "--frames", "1023", "--png", "--spp", "8"];
        let (code, stdout, err) = common::run(&[&args[..], &["--out", renders.to_str().unwrap()]].concat());
        assert_eq!(code, 0, "{stdout}\n{err}");
        let png = std::fs::read_dir(renders.join("full"))
            .unwrap()
            .flatten()
            .map(|e| e.path())
            .find(|p| p.extension().is_some_and(|e| e == "png"))
            .expect("a PNG preview");
        let (film, _) = throng::render::exr::read_layer(&png.with_extension("exr")).unwrap();
        let covered = film.agent_id.iter().filter(|&&id| id != 0).count();
        let seen: std::collections::BTreeSet<u32> = film.agent_id.iter().copied().filter(|&i| i != 0).collect();
        if parts {
            std::fs::copy(&png, Path::new(env!("CARGO_TARGET_TMPDIR")).join("joint_parented_robots.png")).unwrap();
        }
        (covered, seen.len())
    };
    let (whole, seen) = render(true);
    let (hands, _) = render(false);
    assert_eq!(seen, 5, "five robots in frame");
    assert!(hands > 0, "the hands render");
    assert!(whole > 10 * hands, "the robots cover {whole} pixels, their hands alone {hands}");
}

#[test]
fn second_joint_set_counts_and_unnormalised_weights_warn_once() {
    // The multi-joint-set file repeats JOINTS_0/WEIGHTS_0 as JOINTS_1/WEIGHTS_1:
    // every vertex's weights sum to 2, so all ten are renormalised, and the
    // result is SimpleSkin's.
    let path = simple_skin("SimpleSkin-multi-joint-set.gltf");
    // Steps on the clip's keys, whose coarse pose error (22 cm) is not what this counts.
    let rig = load(&path, SkinOptions { pose_step: Some(6.0), pose_error_max: 1.0, ..Default::default() });
    assert_eq!(rig.warnings().len(), 1, "{:?}", rig.warnings());
    let w = &rig.warnings()[0];
    assert!(
        w.contains("SimpleSkin-multi-joint-set.gltf") && w.contains("#0") && w.contains("10 of 10 vertices"),
        "{w}"
    );
    let single = load(&simple_skin("SimpleSkin.gltf"), SkinOptions { pose_step: Some(6.0), ..Default::default() });
    let (a, b) = (rig.cycle_index("#0").unwrap(), single.cycle_index("#0").unwrap());
    let pa = rig.pose_piece(0, &rig.step_joints(a, 4), "t");
    let pb = single.pose_piece(0, &single.step_joints(b, 4), "t");
    for (x, y) in pa.positions.iter().zip(&pb.positions) {
        assert_close(*x, *y, "two joint sets vs one");
    }
    assert!(rig.piece(0).influences.iter().all(|inf| (inf.iter().map(|i| i.1).sum::<f32>() - 1.0).abs() < 1e-6));
}

#[test]
fn rigged_figure_under_a_z_up_node_stands_upright_on_the_ground() {
    let path = common::shared_asset("gltf/RiggedFigure/RiggedFigure.gltf");
    let rig = load(&path, SkinOptions::default());
    // The file's mesh is 1.45 units tall along its Z axis; its Z_UP parent
    // node turns that into Y.
    assert!((1.3..1.6).contains(&rig.height()), "height {}", rig.height());
    let cycle = rig.cycle_index("#0").unwrap();
    for step in [0, 7, 15] {
        let posed = rig.pose_piece(0, &rig.step_joints(cycle, step), "t");
        let (lo, hi) = posed.bounds();
        let size = hi - lo;
        assert!(size.y > 2.0 * size.x.max(size.z) * 0.6 && size.y > 1.2, "step {step}: not upright: {size}");
        assert!(lo.y.abs() < 0.08, "step {step}: feet at y {}", lo.y);
    }
    // The skinned mesh ignores its own node's transform: the posed rest mesh
    // sits where the joints are, centred on the agent.
    let rest = rig.pose_piece(0, &rig.step_joints(cycle, 0), "t");
    let (lo, hi) = rest.bounds();
    assert!(((lo.x + hi.x) / 2.0).abs() < 0.2 && ((lo.z + hi.z) / 2.0).abs() < 0.3, "{lo} {hi}");
}

// ------------------------------------------------------------ through a shot

fn mesh_of(crowd: &ShotCrowd, frame: i32, id: u32) -> u32 {
    let block = crowd.agents_at(frame).unwrap();
    let a = block.agents.iter().find(|a| a.id == id).unwrap();
    let mut out = Vec::new();
    crowd.agent_instances(a, Lod::Full, vis::ALL, &mut out).unwrap();
    assert_eq!(out.len(), 1, "one skinned mesh");
    out[0].mesh
}

#[test]
fn agents_on_one_quantised_pose_share_one_mesh_and_others_do_not() {
    let dir = common::tempdir().unwrap();
    // Agents 1 and 2 play the same cycle frame (up to less than half a step);
    // agent 3 is 6 frames further on.
    let rows = [
        (1020, 1, 0.0, 0.0, 0.0, 4.0),
        (1020, 2, 1.0, 0.0, 1.0, 4.2),
        (1020, 3, -1.0, 0.0, 0.0, 10.0),
        (1021, 1, 0.0, 0.1, 0.0, 5.0),
    ];
    let crowd = ShotCrowd::load(&common::figure_shot(dir.path(), &rows, "")).unwrap();
    assert_eq!(mesh_of(&crowd, 1020, 1), mesh_of(&crowd, 1020, 2), "same pose, same mesh (and BLAS)");
    assert_ne!(mesh_of(&crowd, 1020, 1), mesh_of(&crowd, 1020, 3), "another pose");
    assert_ne!(mesh_of(&crowd, 1020, 1), mesh_of(&crowd, 1021, 1), "the next frame is another pose");
    // Three poses in all (frames 4, 5, 10 of the walk): posed once each.
    assert_eq!(crowd.poses().skins().mesh_count(), 3);
    let stats = throng::casting::table::cast_stats(&crowd);
    let skin = stats.skinned.expect("skinned figures");
    assert_eq!((skin.agents, skin.unique_poses, skin.posed_meshes), (3, 3, 3));
    assert!(skin.worst_quantisation_error_m > 0.0 && skin.worst_quantisation_error_m < 0.02, "{skin:?}");
}

#[test]
fn removing_an_agent_changes_no_other_agents_cast_or_pose() {
    let dir = common::tempdir().unwrap();
    let all = common::five_walkers();
    let without: Vec<_> = all.iter().copied().filter(|r| r.1 != 3).collect();
    let a = ShotCrowd::load(&common::figure_shot(dir.path(), &all, "")).unwrap();
    let dir2 = common::tempdir().unwrap();
    let b = ShotCrowd::load(&common::figure_shot(dir2.path(), &without, "")).unwrap();
    for id in [1u32, 2, 4, 5] {
        assert_eq!(a.cast(id).unwrap(), b.cast(id).unwrap(), "agent {id}'s casting");
        for f in [1020, 1023, 1026] {
            let pose = |c: &ShotCrowd| {
                let block = c.agents_at(f).unwrap();
                let s = *block.agents.iter().find(|s| s.id == id).unwrap();
                match c.agent_pose(&s).unwrap() {
                    AgentPose::Skinned { world_from_rig, cycle, step, .. } => (world_from_rig, cycle, step),
                    AgentPose::Slots(_) => panic!("a skinned agent"),
                }
            };
            assert_eq!(pose(&a), pose(&b), "agent {id} frame {f}");
            let pos = |c: &ShotCrowd| {
                let m = mesh_of(c, f, id);
                c.library().meshes[m as usize].positions.clone()
            };
            assert_eq!(pos(&a), pos(&b), "agent {id} frame {f}: posed vertices");
        }
    }
}

fn render_layers(shot: &Path, out: &Path, threads: usize, layers: &[&str]) -> Vec<PathBuf> {
    let crowd = ShotCrowd::load(shot).unwrap();
    let manifest = throng::layers::build_layers(&crowd, &Default::default()).unwrap();
    let job = throng::render::job::RenderJob {
        threads,
        ..throng::render::job::RenderJob::new(
            layers.iter().map(|l| l.to_string()).collect(),
            vec![1023],
            8,
            out.to_path_buf(),
        )
    };
    throng::render::job::run(&crowd, Some(&manifest), &job, &throng::render::job::Silent)
        .unwrap()
        .layers
        .into_iter()
        .map(|r| r.path)
        .collect()
}

#[test]
fn skinned_renders_are_bit_identical_for_one_and_two_threads() {
    let dir = common::tempdir().unwrap();
    let shot = common::figure_shot(dir.path(), &common::five_walkers(), "");
    let one = render_layers(&shot, &dir.path().join("t1"), 1, &["crowd0", "full"]);
    let two = render_layers(&shot, &dir.path().join("t2"), 2, &["crowd0", "full"]);
    for (a, b) in one.iter().zip(&two) {
        assert_eq!(std::fs::read(a).unwrap(), std::fs::read(b).unwrap(), "{} differs by thread count", a.display());
    }
}

#[test]
fn the_layer_stack_matches_the_full_render_with_skinned_agents() {
    let dir = common::tempdir().unwrap();
    let shot = common::figure_shot(dir.path(), &common::five_walkers(), "");
    let out = dir.path().join("r");
    let files = render_layers(&shot, &out, 0, &["set", "crowd1", "crowd0", "full"]);
    let comped = throng::comp::comp_frame(&out, 1023, None).unwrap();
    let (full, _) = throng::render::exr::read_layer(&files[3]).unwrap();
    let n = full.rgba.len() as f64;
    let mut diff = [0.0f64; 4];
    let mut coverage = 0.0f64;
    for (a, b) in comped.film.rgba.iter().zip(&full.rgba) {
        for c in 0..4 {
            diff[c] += (a[c] - b[c]) as f64 / n;
        }
        coverage += b[3] as f64 / n;
    }
    // The figures cover part of the frame (no set: the rest is empty).
    assert!(coverage > 0.05, "figures cover {coverage:.3} of the frame");
    for (c, d) in diff.iter().enumerate() {
        assert!(d.abs() < 0.01, "channel {c}: comp - full mean {d:.4} (more than noise)");
    }
}

// ------------------------------------------------------------ bad input

/// Runs `throng cast` on a figure shot with `extra` in its rig table; the
/// error text on failure.
fn cast_error(extra_rig: &str, rows: &[(i32, u32, f32, f32, f32, f32)]) -> String {
    let dir = common::tempdir().unwrap();
    let shot = common::figure_shot(dir.path(), rows, extra_rig);
    let (code, _, err) = common::run(&["cast".as_ref(), shot.as_os_str()]);
    assert_eq!(code, 2, "should be refused: {err}");
    err
}

#[test]
fn a_skinned_file_as_a_slot_rig_is_refused_naming_skinning() {
    let dir = common::tempdir().unwrap();
    let shot = common::figure_shot(dir.path(), &common::five_walkers(), "kind = \"slots\"");
    let text = std::fs::read_to_string(&shot).unwrap().replace("cycles = { Walk = \"#0\" }\n", "");
    std::fs::write(&shot, text).unwrap();
    let (code, _, err) = common::run(&["cast".as_ref(), shot.as_os_str()]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("skinned") && err.contains("kind = \"skinned\"") && err.contains("RiggedFigure"), "{err}");
}

#[test]
fn a_skinned_mesh_as_a_rigid_part_is_refused_naming_skinning() {
    let dir = common::tempdir().unwrap();
    let figure = common::shared_asset("gltf/RiggedFigure/RiggedFigure.gltf");
    let wardrobe = dir.path().join("w.toml");
    std::fs::write(
        &wardrobe,
        format!(
            "version = 1\nname = \"w\"\n[schemes.Figures]\n[[schemes.Figures.parts]]\nslot = \"torso\"\nfile = \"{}\"\nmesh = \"Proxy\"\n",
            figure.display()
        ),
    )
    .unwrap();
    // One slot-rig robot whose torso would be the skinned figure.
    std::fs::write(
        dir.path().join("c.csv"),
        "frame,id,x,y,z,heading,rig,cycle,cycle_frame,flags\n1,1,0,0,0,0,bipedThinA,WalkA,0,\n",
    )
    .unwrap();
    let text = format!(
        "version = 1\nname = \"r\"\nseed = 1\nwardrobes = [\"{}\"]\n[frames]\nstart = 1\nend = 1\n[cache]\npath = \"c.csv\"\n\
         [rigs.bipedThinA]\nfile = \"{}\"\nschemes = {{ Figures = 1.0 }}\n[camera]\n[[camera.keys]]\nframe = 1\n\
         position = [0.0, 1.0, 5.0]\naim = [0.0, 1.0, 0.0]\nfocal_length = 35.0\n",
        wardrobe.display(),
        common::repo_path("demo/rigs/bipedThinA.glb").display()
    );
    let shot = dir.path().join("shot.toml");
    std::fs::write(&shot, text).unwrap();
    let (code, _, err) = common::run(&["cast".as_ref(), shot.as_os_str()]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("skinned") && err.contains("kind = \"skinned\"") && err.contains("Proxy"), "{err}");
}

#[test]
fn a_clip_mapping_to_a_missing_clip_lists_the_clips() {
    let dir = common::tempdir().unwrap();
    let shot = common::figure_shot(dir.path(), &common::five_walkers(), "");
    let text =
        std::fs::read_to_string(&shot).unwrap().replace("cycles = { Walk = \"#0\" }", "cycles = { Walk = \"Run\" }");
    std::fs::write(&shot, text).unwrap();
    let (code, _, err) = common::run(&["cast".as_ref(), shot.as_os_str()]);
    assert_eq!(code, 2);
    assert!(err.contains("Run") && err.contains("clips: #0 (#0)") && err.contains("rigs.figure.cycles.Walk"), "{err}");
}

/// SimpleSkin's JSON with `edit` applied, written beside a shot that uses it;
/// the `throng cast` error.
fn broken_simple_skin(edit: impl Fn(&mut serde_json::Value)) -> String {
    let dir = common::tempdir().unwrap();
    let mut doc: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(simple_skin("SimpleSkin.gltf")).unwrap()).unwrap();
    edit(&mut doc);
    let file = dir.path().join("broken.gltf");
    std::fs::write(&file, serde_json::to_string(&doc).unwrap()).unwrap();
    let shot = common::figure_shot(dir.path(), &common::five_walkers(), "");
    let text = std::fs::read_to_string(&shot).unwrap();
    let figure = common::shared_asset("gltf/RiggedFigure/RiggedFigure.gltf");
    let text = text.replace(&figure.display().to_string(), &file.display().to_string());
    std::fs::write(&shot, text).unwrap();
    let (code, _, err) = common::run(&["cast".as_ref(), shot.as_os_str()]);
    assert_eq!(code, 2, "should be refused: {err}");
    err
}

#[test]
fn malformed_skins_are_errors_naming_file_mesh_and_accessor() {
    // No inverse bind matrices.
    let err = broken_simple_skin(|d| {
        d["skins"][0].as_object_mut().unwrap().remove("inverseBindMatrices");
    });
    assert!(err.contains("broken.gltf") && err.contains("mesh") && err.contains("inverseBindMatrices"), "{err}");
    // A skin of one joint: the vertices weighted to joint 1 point past it.
    let err = broken_simple_skin(|d| {
        d["skins"][0]["joints"] = serde_json::json!([1]);
        d["accessors"][4]["count"] = serde_json::json!(1);
    });
    assert!(
        err.contains("broken.gltf") && err.contains("joint 1 is out of range") && err.contains("accessor 2"),
        "{err}"
    );
    // A third joint set: more than 8 influences.
    let err = broken_simple_skin(|d| {
        let attrs = &mut d["meshes"][0]["primitives"][0]["attributes"];
        attrs["JOINTS_2"] = serde_json::json!(2);
        attrs["WEIGHTS_2"] = serde_json::json!(3);
    });
    assert!(err.contains("broken.gltf") && err.contains("more than 8 influences"), "{err}");
    // Weights pointed at the inverse bind matrices: a MAT4 accessor.
    let err = broken_simple_skin(|d| d["meshes"][0]["primitives"][0]["attributes"]["WEIGHTS_0"] = serde_json::json!(4));
    assert!(err.contains("broken.gltf") && err.contains("WEIGHTS_0"), "{err}");
}

#[test]
fn nan_weights_are_an_error_naming_the_accessor() {
    // A weights accessor of 10 VEC4 floats, all NaN, in a buffer of its own.
    let err = broken_simple_skin(|d| {
        let nan = f32::NAN.to_le_bytes();
        let bytes: Vec<u8> = (0..40).flat_map(|_| nan).collect();
        let uri = format!("data:application/octet-stream;base64,{}", base64(&bytes));
        d["buffers"].as_array_mut().unwrap().push(serde_json::json!({ "uri": uri, "byteLength": bytes.len() }));
        let buffer = d["buffers"].as_array().unwrap().len() - 1;
        d["bufferViews"]
            .as_array_mut()
            .unwrap()
            .push(serde_json::json!({ "buffer": buffer, "byteLength": bytes.len() }));
        let view = d["bufferViews"].as_array().unwrap().len() - 1;
        d["accessors"]
            .as_array_mut()
            .unwrap()
            .push(serde_json::json!({ "bufferView": view, "componentType": 5126, "count": 10, "type": "VEC4" }));
        let acc = d["accessors"].as_array().unwrap().len() - 1;
        d["meshes"][0]["primitives"][0]["attributes"]["WEIGHTS_0"] = serde_json::json!(acc);
    });
    assert!(err.contains("broken.gltf") && err.contains("WEIGHTS_0 (accessor 7)") && err.contains("NaN"), "{err}");
}

/// Standard base64 with padding (for data URIs in the broken files above).
fn base64(bytes: &[u8]) -> String {
    const T: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::new();
    for chunk in bytes.chunks(3) {
        let b = [chunk[0], *chunk.get(1).unwrap_or(&0), *chunk.get(2).unwrap_or(&0)];
        let n = (b[0] as u32) << 16 | (b[1] as u32) << 8 | b[2] as u32;
        for i in 0..4 {
            if i <= chunk.len() {
                out.push(T[(n >> (18 - 6 * i) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

#[test]
fn cycles_and_strides_options_are_checked_in_the_shot() {
    let err = cast_error("scale = -1.0", &common::five_walkers());
    assert!(err.contains("rigs.figure.scale"), "{err}");
    let err = cast_error("pose_step = 0.0", &common::five_walkers());
    assert!(err.contains("rigs.figure.pose_step"), "{err}");
    let err = cast_error("root = \"tail\"", &common::five_walkers());
    assert!(err.contains("tail") && err.contains("torso_joint_1"), "{err}");
    let err = cast_error("forward = \"+y\"\nup = \"+y\"", &common::five_walkers());
    assert!(err.contains("forward") && err.contains("up"), "{err}");
}

#[test]
fn mattes_name_skinned_agents_and_their_meshes() {
    let dir = common::tempdir().unwrap();
    let shot = common::figure_shot(dir.path(), &common::five_walkers(), "");
    let files = render_layers(&shot, &dir.path().join("r"), 0, &["full"]);
    let mattes = throng::render::exr::mattes::read(&files[0]).unwrap();
    let names: Vec<&str> = mattes.iter().map(|m| m.name.as_str()).collect();
    let agent = mattes.iter().find(|m| m.name == "CryptoAgent").unwrap_or_else(|| panic!("{names:?}"));
    let part = mattes.iter().find(|m| m.name == "CryptoPart").unwrap_or_else(|| panic!("{names:?}"));
    for id in 1..=5 {
        assert!(agent.manifest.contains_key(&format!("agent_{id}")), "{:?}", agent.manifest.keys());
        // The figure's one skinned mesh sits on its node `Proxy`: the slot.
        assert!(part.manifest.contains_key(&format!("agent_{id}/Proxy")), "{:?}", part.manifest.keys());
    }
}

#[test]
fn export_shares_posed_meshes_between_agents_on_one_pose() {
    let dir = common::tempdir().unwrap();
    // Agents 1 and 2 on one pose, 3 on another.
    let rows = [(1020, 1, 0.0, 0.0, 0.0, 4.0), (1020, 2, 1.0, 0.0, 1.0, 4.1), (1020, 3, -1.0, 0.0, 0.0, 12.0)];
    let shot = common::figure_shot(dir.path(), &rows, "");
    let glb = dir.path().join("f.glb");
    let (code, out, err) = common::run(&[
        "export".as_ref(),
        shot.as_os_str(),
        "--frame".as_ref(),
        "1020".as_ref(),
        "--out".as_ref(),
        glb.as_os_str(),
    ]);
    assert_eq!(code, 0, "{out}{err}");
    let doc = gltf::Gltf::open(&glb).unwrap();
    let mesh_of = |agent: &str| {
        let parent = doc.nodes().find(|n| n.name() == Some(agent)).unwrap();
        parent.children().find_map(|c| c.mesh()).unwrap().index()
    };
    assert_eq!(mesh_of("agent_1"), mesh_of("agent_2"), "one posed mesh for one pose");
    assert_ne!(mesh_of("agent_1"), mesh_of("agent_3"));
    assert_eq!(doc.meshes().len(), 2, "two poses, two meshes");
}

/// Issue 49 item C: a pose-error warning is given only for a clip the
/// shot's cycles play. RiggedFigure with its clip copied as `Dance` (never
/// played), a pose_step too coarse for either: only the played clip warns.
/// One rig file under two rig names warns, naming both keys (docs/wardrobes.md).
/// `cast --stats` counts the posed meshes as the skinned shot's geometry.
#[test]
fn casting_warns_of_played_clips_and_shared_rig_files_and_counts_posed_geometry() {
    let dir = common::tempdir().unwrap();
    let figure = common::shared_asset("gltf/RiggedFigure/RiggedFigure.gltf");
    let mut gltf: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&figure).unwrap()).unwrap();
    let mut dance = gltf["animations"][0].clone();
    dance["name"] = "Dance".into();
    gltf["animations"].as_array_mut().unwrap().push(dance);
    let folder = figure.parent().unwrap();
    for b in gltf["buffers"].as_array_mut().unwrap() {
        let uri = folder.join(b["uri"].as_str().unwrap());
        b["uri"] = uri.display().to_string().into();
    }
    let dancing = dir.path().join("dancing.gltf");
    std::fs::write(&dancing, gltf.to_string()).unwrap();
    let shot = common::figure_shot(dir.path(), &common::five_walkers(), "pose_step = 8.0\npose_error_max = 0.0001");
    let text =
        std::fs::read_to_string(&shot).unwrap().replace(&figure.display().to_string(), &dancing.display().to_string());
    std::fs::write(&shot, &text).unwrap();
    let (code, out, err) = common::run(&["cast".as_ref(), shot.as_os_str(), "--stats".as_ref()]);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("pose_step 8 gives a pose error") && err.contains("cycle `Walk`"), "{err}");
    assert!(!err.contains("Dance"), "a clip no cycle plays is not warned of: {err}");
    // A skinned shot has no slot parts: the figure says what it covers and
    // gives no "(0x more)"; its posed geometry is counted on its own line.
    let line = out.lines().find(|l| l.starts_with("unique geometry")).unwrap();
    assert!(line.contains("(slot parts; posed geometry below)") && !out.contains("(0x"), "{out}");
    let posed = out.lines().find(|l| l.starts_with("posed geometry")).unwrap();
    assert!(!posed.contains(" 0.00 MiB"), "{out}");

    // One file under two rig names.
    let twin = format!("{text}\n").replacen(
        "[camera]",
        &format!("[rigs.twin]\nfile = \"{}\"\n\n[camera]", dancing.display()),
        1,
    );
    std::fs::write(&shot, twin).unwrap();
    let (code, _, err) = common::run(&["cast".as_ref(), shot.as_os_str()]);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("rigs.twin.file") && err.contains("the same file as `rigs.figure.file`"), "{err}");
    let (code, _, err) = common::run(&["--strict".as_ref(), "cast".as_ref(), shot.as_os_str()]);
    assert_eq!(code, 2, "--strict refuses the warning:\n{err}");
}
