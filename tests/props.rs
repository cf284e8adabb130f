//! Props (docs/wardrobes.md "Props"): parts a wardrobe scheme hangs on a
//! joint of a skinned character or a slot of a slot rig, drawn one per group
//! or none, posed with their joint or slot, named `agent_<id>/<prop>` in
//! Cryptomatte, botinfo and export.

mod common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use glam::{Affine3A, Quat, Vec3};
use throng::casting::wardrobe::Wardrobes;
use throng::casting::{cast_agent, AgentPose, Lod, RigCasting, ShotCrowd};
use throng::scene::vis;

fn demo(rel: &str) -> String {
    common::repo_path(&format!("demo/{rel}")).display().to_string()
}

/// The hand prop's offset and turn in these fixtures.
const OFFSET: [f32; 3] = [0.02, -0.12, 0.05];
const ROTATE: [f32; 3] = [0.0, 0.0, 90.0];

/// A wardrobe of scheme `Carry` for the demo walker (its own body and head)
/// with prop group `hand` (a ball on `hand_r`, weight 3, or none, weight 1)
/// and `more` (more `[[schemes.Carry.props]]` entries).
fn walker_wardrobe(more: &str) -> String {
    format!(
        r#"version = 1
name = "carry"
[materials.leather]
base_color = [0.3, 0.2, 0.1]
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
weight = 3.0
offset = {OFFSET:?}
rotate = {ROTATE:?}
materials = ["leather"]
[[schemes.Carry.props]]
group = "hand"
name = "none"
weight = 1.0
{more}
"#,
        walker = demo("rigs/walker.glb"),
        heads = demo("parts/heads.glb"),
    )
}

/// A shot of `agents` demo walkers walking at frames 1001-1003, wearing
/// `wardrobe` (written to `dir/w.toml`), and its cache.
fn walker_shot(dir: &Path, wardrobe: &str, agents: u32) -> PathBuf {
    std::fs::write(dir.join("w.toml"), wardrobe).unwrap();
    let mut csv = String::from("frame,id,x,y,z,heading,rig,cycle,cycle_frame,flags\n");
    for f in 1..=3 {
        for id in 1..=agents {
            let x = (id as f32 - 1.0) * 0.8 - 0.8;
            csv.push_str(&format!("{f},{id},{x:?},0,0,0.3,walker,WalkA,{:?},\n", (f * 5 + id as i32 * 3) as f32));
        }
    }
    std::fs::write(dir.join("c.csv"), csv).unwrap();
    let shot = format!(
        r#"version = 1
name = "props"
seed = 5
wardrobes = ["w.toml"]
[frames]
start = 1001
end = 1003
fps = 24.0
[cache]
path = "c.csv"
frame_offset = -1000
[rigs.walker]
file = "{walker}"
kind = "skinned"
cycles = {{ WalkA = "Walk" }}
root = "hips"
schemes = {{ Carry = 1.0 }}
slots = ["body", "head"]
height_jitter = 0.1
[camera]
[[camera.keys]]
frame = 1001
position = [0.0, 1.2, 5.0]
aim = [0.0, 0.9, 0.0]
focal_length = 35.0
[layers]
count = 1
[render]
resolution = [64, 36]
spp = 2
max_bounces = 1
"#,
        walker = demo("rigs/walker.glb"),
    );
    let path = dir.join("shot.toml");
    std::fs::write(&path, shot).unwrap();
    path
}

/// Positions of mesh `mesh` of a glTF file, in file order.
fn mesh_positions(file: &str, mesh: &str) -> Vec<Vec3> {
    let (doc, buffers, _) = gltf::import(file).unwrap();
    let m = doc.meshes().find(|m| m.name() == Some(mesh)).unwrap();
    let prim = m.primitives().next().unwrap();
    prim.reader(|b| Some(&buffers[b.index()])).read_positions().unwrap().map(Vec3::from).collect()
}

/// Index of node `name` of a glTF file.
fn node_index(file: &str, name: &str) -> usize {
    let (doc, _, _) = gltf::import(file).unwrap();
    doc.nodes().find(|n| n.name() == Some(name)).unwrap().index()
}

fn offset() -> Affine3A {
    let [x, y, z] = ROTATE.map(f32::to_radians);
    let turn = Quat::from_rotation_z(z) * Quat::from_rotation_y(y) * Quat::from_rotation_x(x);
    Affine3A::from_rotation_translation(turn, Vec3::from(OFFSET))
}

#[test]
fn a_prop_on_a_joint_moves_with_that_joint() {
    let dir = common::tempdir().unwrap();
    let shot = walker_shot(dir.path(), &walker_wardrobe(""), 4);
    let crowd = ShotCrowd::load(&shot).unwrap();
    let ball = mesh_positions(&demo("parts/heads.glb"), "head_sphere");
    let hand = node_index(&demo("rigs/walker.glb"), "hand_r");
    let Some(throng::casting::ShotRig::Skinned(rig)) = crowd.rigs().get("walker") else { panic!("skinned") };
    let carrier = crowd.casting().iter().find(|c| c.props.iter().any(|p| &*p.name == "ball")).expect("a carrier");
    let mut hands = Vec::new();
    for frame in [1001, 1003] {
        let block = crowd.agents_at(frame).unwrap();
        let a = block.agents.iter().find(|a| a.id == carrier.id).unwrap();
        let AgentPose::Skinned { world_from_rig, cycle, step, .. } = crowd.agent_pose(a).unwrap() else { panic!() };
        let mut insts = Vec::new();
        crowd.agent_instances(a, Lod::Full, vis::ALL, &mut insts).unwrap();
        // Parts are the slots (0, 1); the prop is part 2.
        let prop: Vec<_> = insts.iter().filter(|i| i.part == 2).collect();
        assert_eq!(prop.len(), 1, "one ball instance at frame {frame}");
        let mesh = &crowd.library().meshes[prop[0].mesh as usize];
        let joint = rig.step_joints(cycle, step)[hand];
        let want = world_from_rig * joint * offset();
        assert_eq!(mesh.positions.len(), ball.len());
        for (i, (p, v)) in mesh.positions.iter().zip(&ball).enumerate() {
            let got = prop[0].world_from_object.transform_point3(*p);
            let w = want.transform_point3(*v);
            assert!(got.distance(w) < 1e-4, "frame {frame} vertex {i}: {got} want {w}");
        }
        hands.push(world_from_rig.transform_point3(joint.translation.into()));
        // Proxy LOD: the ball's box hangs on the same joint.
        let mut proxies = Vec::new();
        crowd.agent_instances(a, Lod::Proxy, vis::ALL, &mut proxies).unwrap();
        let boxes: Vec<_> = proxies.iter().filter(|i| i.part == 2).collect();
        assert_eq!(boxes.len(), 1, "one proxy box for the ball");
        let centre = boxes[0].world_from_object.transform_point3(Vec3::splat(0.5));
        let ball_centre = ball.iter().fold(Vec3::ZERO, |s, v| s + *v) / ball.len() as f32;
        assert!(centre.distance(want.transform_point3(ball_centre)) < 0.05, "proxy box at the ball");
    }
    assert!(hands[0].distance(hands[1]) > 0.02, "the hand moved between the two poses: {hands:?}");
}

#[test]
fn a_prop_on_a_slot_moves_with_that_slot() {
    let dir = common::tempdir().unwrap();
    let shot = common::DemoShot::default().write(dir.path(), &common::two_robots(1..=3));
    let wardrobe = format!(
        "{}\n[[schemes.Only.props]]\nname = \"drink\"\nslot = \"lower_arm_r\"\nfile = \"{}\"\nmesh = \"head_can\"\noffset = {OFFSET:?}\nrotate = {ROTATE:?}\n",
        common::heads_wardrobe("", "slot = \"head\""),
        demo("parts/heads.glb")
    );
    std::fs::write(dir.path().join("w.toml"), wardrobe).unwrap();
    common::wear_heads(&shot, &dir.path().join("w.toml").display().to_string());
    // The robots idle: move agent 1 along its cycle to see the slot move.
    let csv = std::fs::read_to_string(dir.path().join("c.csv")).unwrap();
    let csv: String = csv
        .lines()
        .map(|l| if l.starts_with("3,1,") { l.replace(",IdleA,3,", ",IdleA,20,") } else { l.to_string() })
        .collect::<Vec<_>>()
        .join("\n");
    std::fs::write(dir.path().join("c.csv"), csv + "\n").unwrap();
    let crowd = ShotCrowd::load(&shot).unwrap();
    let cast = crowd.cast(1).unwrap();
    assert_eq!(cast.props.len(), 1, "a lone prop is always drawn");
    let mut wrists = Vec::new();
    for frame in [1001, 1003] {
        let block = crowd.agents_at(frame).unwrap();
        let a = block.agents.iter().find(|a| a.id == 1).unwrap();
        let AgentPose::Slots(slots) = crowd.agent_pose(a).unwrap() else { panic!("slot rig") };
        let Some(throng::casting::ShotRig::Slots(rig)) = crowd.rigs().get("bipedThinA") else { panic!() };
        let arm = rig.slots().iter().position(|s| s.name == "lower_arm_r").unwrap();
        let mut insts = Vec::new();
        crowd.agent_instances(a, Lod::Full, vis::ALL, &mut insts).unwrap();
        let part = cast.slots.len() as u16;
        let prop: Vec<_> = insts.iter().filter(|i| i.part == part).collect();
        assert_eq!(prop.len(), 1, "one drink instance at frame {frame}");
        let want = slots[arm] * offset();
        assert!(prop[0].world_from_object.abs_diff_eq(want, 1e-5), "frame {frame}: the drink hangs on the slot");
        wrists.push(slots[arm].translation);
    }
    assert!(wrists[0].distance(wrists[1]) > 1e-3, "the slot moved: {wrists:?}");
}

/// The demo walker's rig as casting sees it, with the schemes of `wardrobe`.
fn cast_all(wardrobes: &Wardrobes, n: u32) -> Vec<throng::casting::AgentCast> {
    let slots: Vec<std::sync::Arc<str>> = vec!["body".into(), "head".into()];
    let schemes = BTreeMap::from([("Carry".to_string(), 1.0f32)]);
    let rig = RigCasting { name: "walker".into(), slots: &slots, schemes: &schemes, height_jitter: 0.1, bodies: 0 };
    (1..=n).map(|id| cast_agent(9, id, &rig, wardrobes, &[], false).unwrap()).collect()
}

fn load(dir: &Path, name: &str, text: &str) -> Wardrobes {
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    Wardrobes::load(&[path]).unwrap()
}

#[test]
fn prop_weights_are_honoured_and_none_is_drawn() {
    let dir = common::tempdir().unwrap();
    let w = load(dir.path(), "w.toml", &walker_wardrobe(""));
    let casts = cast_all(&w, 4000);
    let balls = casts.iter().filter(|c| c.props.iter().any(|p| &*p.name == "ball")).count();
    let none = casts.iter().filter(|c| c.props.is_empty()).count();
    assert_eq!(balls + none, 4000);
    let frac = balls as f64 / 4000.0;
    assert!((frac - 0.75).abs() < 0.025, "ball drawn {frac} of the time, weight 3 against none 1");
}

#[test]
fn adding_a_prop_group_changes_no_other_draw() {
    let dir = common::tempdir().unwrap();
    let heads = demo("parts/heads.glb");
    let before = cast_all(&load(dir.path(), "a.toml", &walker_wardrobe("")), 500);
    let more = format!(
        "[[schemes.Carry.props]]\ngroup = \"back\"\nname = \"pack\"\njoint = \"chest\"\nfile = \"{heads}\"\nmesh = \"head_box\"\nweight = 1.0\n\
         [[schemes.Carry.props]]\ngroup = \"back\"\nname = \"none\"\nweight = 1.0\n"
    );
    let after = cast_all(&load(dir.path(), "b.toml", &walker_wardrobe(&more)), 500);
    let mut packs = 0;
    for (a, b) in before.iter().zip(&after) {
        assert_eq!((a.id, &a.scheme, a.height_scale, &a.slots), (b.id, &b.scheme, b.height_scale, &b.slots));
        let hand = |c: &throng::casting::AgentCast| c.props.iter().find(|p| &*p.name == "ball").map(|p| p.mesh.clone());
        assert_eq!(hand(a), hand(b), "agent {}: the hand draw is unchanged", a.id);
        packs += b.props.iter().filter(|p| &*p.name == "pack").count();
    }
    assert!(packs > 150 && packs < 350, "the new group draws too: {packs} of 500");
    // And without any prop, the parts are the same draws.
    let plain = walker_wardrobe("").split("[[schemes.Carry.props]]").next().unwrap().to_string();
    let bare = cast_all(&load(dir.path(), "c.toml", &plain), 500);
    for (a, b) in before.iter().zip(&bare) {
        assert_eq!((a.height_scale, &a.slots), (b.height_scale, &b.slots));
        assert!(b.props.is_empty());
    }
}

#[test]
fn props_are_named_in_cryptomatte_botinfo_and_export() {
    let dir = common::tempdir().unwrap();
    let shot = walker_shot(dir.path(), &walker_wardrobe(""), 4);
    let crowd = ShotCrowd::load(&shot).unwrap();
    let carrier = crowd.casting().iter().find(|c| !c.props.is_empty()).expect("a carrier").id;
    let name = format!("agent_{carrier}/ball");
    let s = |p: &Path| p.display().to_string();

    // botinfo lists it, with the joint it hangs on.
    let (code, out, err) = common::run(&["botinfo", &s(&shot), &carrier.to_string(), "--frame", "1001"]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("Props") && out.contains("ball") && out.contains("joint hand_r"), "{out}");
    let (code, out, err) = common::run(&["botinfo", &s(&shot), &carrier.to_string(), "--frame", "1001", "--json"]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("\"props\"") && out.contains("\"ball\""), "{out}");

    // A rendered layer's part matte names it.
    let out_dir = dir.path().join("o");
    let (code, _, err) =
        common::run(&["render", &s(&shot), "--layer", "full", "--frames", "1001", "--out", &s(&out_dir)]);
    assert_eq!(code, 0, "{err}");
    let exr = out_dir.join("full").join("props.full.1001.exr");
    let mattes = throng::render::exr::mattes::read(&exr).unwrap();
    let names: Vec<&String> = mattes.iter().flat_map(|m| m.manifest.keys()).collect();
    assert!(names.contains(&&name), "{name} in the mattes: {names:?}");
    assert!(names.contains(&&format!("agent_{carrier}/body")), "{names:?}");

    // glTF and USD exports write it.
    let glb = dir.path().join("x.glb");
    let (code, _, err) = common::run(&["export", &s(&shot), "--frame", "1001", "--out", &s(&glb)]);
    assert_eq!(code, 0, "{err}");
    let (doc, _, _) = gltf::import(&glb).unwrap();
    assert!(doc.nodes().any(|n| n.name() == Some(name.as_str())), "{name} is a node of the glb");
    let usd = dir.path().join("x.usda");
    let (code, _, err) =
        common::run(&["export", &s(&shot), "--format", "usd", "--frames", "1001-1002", "--out", &s(&usd)]);
    assert_eq!(code, 0, "{err}");
    let text = std::fs::read_to_string(&usd).unwrap();
    assert!(text.contains(&format!("\"{name}\"")), "{name} in the usda");
}

#[test]
fn a_prop_on_a_joint_the_character_lacks_is_refused_naming_it() {
    let dir = common::tempdir().unwrap();
    let shot = walker_shot(dir.path(), &walker_wardrobe("").replace("joint = \"hand_r\"", "joint = \"claw\""), 2);
    let (code, out, err) = common::run(&["cast".as_ref(), shot.as_os_str()]);
    assert_eq!(code, 2, "{out}{err}");
    for want in ["w.toml", "schemes.Carry.props[0].joint", "prop `ball`", "claw", "hand_r"] {
        assert!(err.contains(want), "`{want}` in: {err}");
    }
    // On a skinned character a prop hangs on a joint, not a slot.
    let wardrobe = walker_wardrobe("").replace("joint = \"hand_r\"", "slot = \"body\"");
    std::fs::write(dir.path().join("w.toml"), wardrobe).unwrap();
    let (code, _, err) = common::run(&["cast".as_ref(), shot.as_os_str()]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("schemes.Carry.props[0]") && err.contains("joint"), "{err}");
}

#[test]
fn the_demo_walkers_carry_bags_and_cups() {
    let w = Wardrobes::load(&[common::repo_path("wardrobes/walkers.toml")]).unwrap();
    let slots: Vec<std::sync::Arc<str>> = vec!["body".into(), "head".into()];
    let schemes = BTreeMap::from([("Walkers".to_string(), 1.0f32)]);
    let rig = RigCasting { name: "walker".into(), slots: &slots, schemes: &schemes, height_jitter: 0.1, bodies: 0 };
    let casts: Vec<_> = (1..=1200).map(|id| cast_agent(1234, id, &rig, &w, &[], false).unwrap()).collect();
    let count = |name: &str| casts.iter().filter(|c| c.props.iter().any(|p| &*p.name == name)).count() as f64 / 1200.0;
    assert!((count("bag") - 1.0 / 3.0).abs() < 0.05, "bags {}", count("bag"));
    assert!((count("cup") - 0.25).abs() < 0.05, "cups {}", count("cup"));
    assert!(casts.iter().any(|c| c.props.is_empty()), "some carry nothing");
}

#[test]
fn a_prop_blurs_with_its_joint() {
    use throng::render::job::{self, RenderJob};
    let dir = common::tempdir().unwrap();
    let shot = walker_shot(dir.path(), &walker_wardrobe(""), 4);
    let shutter = [-0.5, 0.5];
    let crowd = ShotCrowd::open(throng::shot::Shot::load(&shot).unwrap(), Some(shutter)).unwrap();
    let carrier = crowd.casting().iter().find(|c| !c.props.is_empty()).expect("a carrier").id;
    let manifest = throng::layers::build_layers(&crowd, &Default::default()).unwrap();
    let run = |threads: usize, shutter: Option<[f32; 2]>, out: &Path| {
        let job =
            RenderJob { threads, shutter, ..RenderJob::new(vec!["full".into()], vec![1002], 4, out.to_path_buf()) };
        let done = job::run(&crowd, Some(&manifest), &job, &job::Silent).unwrap().layers;
        let mattes = throng::render::exr::mattes::read(&done[0].path).unwrap();
        let name = format!("agent_{carrier}/ball");
        let m = mattes.iter().find(|m| m.manifest.contains_key(&name)).expect("the ball's matte");
        m.matte(&name)
    };
    let a = run(1, Some(shutter), &dir.path().join("a"));
    let b = run(2, Some(shutter), &dir.path().join("b"));
    let still = run(2, None, &dir.path().join("s"));
    assert_eq!(a, b, "the blurred ball is the same on any thread count");
    assert!(a.iter().any(|&c| c > 0.0), "the ball is on screen blurred");
    assert_ne!(a, still, "the ball's matte smears under motion blur");
}

/// Eight demo walkers in the demo's own wardrobe (wardrobes/walkers.toml:
/// a bag in the right hand for a third of them, a cup in the left for a
/// quarter), rendered: every prop drawn is on screen in its hand. Kept for
/// looking at: target/tmp/props_bags_and_cups.png.
#[test]
fn the_demo_walkers_render_with_their_bags_and_cups() {
    let dir = common::tempdir().unwrap();
    let shot = walker_shot(dir.path(), &walker_wardrobe(""), 8);
    let walkers = common::repo_path("wardrobes/walkers.toml");
    let text = std::fs::read_to_string(&shot)
        .unwrap()
        .replace("wardrobes = [\"w.toml\"]", &format!("wardrobes = [{:?}]", walkers.display().to_string()))
        .replace("schemes = { Carry = 1.0 }", "schemes = { Walkers = 1.0 }")
        .replace("position = [0.0, 1.2, 5.0]", "position = [2.0, 1.4, 6.2]")
        .replace("aim = [0.0, 0.9, 0.0]", "aim = [2.0, 0.85, 0.0]")
        .replace("resolution = [64, 36]", "resolution = [640, 270]")
        .replace("spp = 2", "spp = 16");
    std::fs::write(&shot, text).unwrap();
    let crowd = ShotCrowd::load(&shot).unwrap();
    let carried: Vec<(u32, String)> =
        crowd.casting().iter().flat_map(|c| c.props.iter().map(move |p| (c.id, p.name.to_string()))).collect();
    for prop in ["bag", "cup"] {
        assert!(carried.iter().any(|(_, p)| p == prop), "someone carries a {prop}: {carried:?}");
    }
    let out = dir.path().join("o");
    let s = |p: &Path| p.display().to_string();
    let (code, _, err) =
        common::run(&["render", &s(&shot), "--layer", "full", "--frames", "1002", "--png", "--out", &s(&out)]);
    assert_eq!(code, 0, "{err}");
    let exr = out.join("full").join("props.full.1002.exr");
    let mattes = throng::render::exr::mattes::read(&exr).unwrap();
    for (id, prop) in &carried {
        let name = format!("agent_{id}/{prop}");
        let m = mattes.iter().find(|m| m.manifest.contains_key(&name)).unwrap_or_else(|| panic!("{name}'s matte"));
        let pixels = m.matte(&name).iter().filter(|&&c| c > 0.5).count();
        assert!(pixels >= 20, "{name} covers {pixels} pixels");
    }
    std::fs::copy(exr.with_extension("png"), Path::new(env!("CARGO_TARGET_TMPDIR")).join("props_bags_and_cups.png"))
        .unwrap();
}
