//! Rigid and vehicle agents (`kind = "rigid"`): meshes on a node hierarchy
//! with node animation, no skin. Khronos InterpolationTest posed as a rigid
//! rig against the glTF sampler's values (a STEP, LINEAR and CUBICSPLINE
//! channel of each property); a car built here whose wheels roll at speed /
//! radius through a shot; `forward` on a rigid rig; and bad input. The
//! Kenney alien given a walk clip, and the car, read by the reference
//! simulation's `[rigs]` and `cache convert --rig-file` as the shot reads
//! them. Pictures: target/tmp/rigid_car.png, target/tmp/rigid_alien.png.

mod common;

use std::f32::consts::{PI, TAU};
use std::path::{Path, PathBuf};

use glam::{Affine3A, Quat, Vec3};
use throng::casting::rig::{Animated, Interpolation, Property};
use throng::casting::skin::SkinnedRig;
use throng::casting::{Lod, ShotCrowd};
use throng::export::glb::{
    AnimationDesc, ChannelDesc, ChannelValues, GlbBuilder, Interpolation as Interp, MaterialDesc, MeshData, NodeDesc,
};
use throng::scene::vis;
use throng::shot::{Axis, SkinOptions};

const FPS: f32 = 24.0;

fn interpolation_test() -> PathBuf {
    common::shared_asset("gltf/InterpolationTest/InterpolationTest.gltf")
}

fn rigid(path: &Path, options: SkinOptions) -> SkinnedRig {
    let options = SkinOptions { rigid: Some(true), ..options };
    SkinnedRig::load(path, &options, FPS).unwrap_or_else(|e| panic!("{} loads: {e}", path.display()))
}

/// A node's rest transform as the file gives it, read with the gltf crate.
fn rest_trs(path: &Path, node: usize) -> (Vec3, Quat, Vec3) {
    let (doc, _, _) = gltf::import(path).unwrap();
    let (t, r, s) = doc.nodes().nth(node).unwrap().transform().decomposed();
    (Vec3::from(t), Quat::from_array(r), Vec3::from(s))
}

/// The mesh of node `node`'s first primitive, in node space.
fn node_vertices(path: &Path, node: usize) -> Vec<Vec3> {
    let (doc, buffers, _) = gltf::import(path).unwrap();
    let mesh = doc.nodes().nth(node).unwrap().mesh().unwrap();
    let prim = mesh.primitives().next().unwrap();
    let reader = prim.reader(|b| Some(&buffers[b.index()].0[..]));
    reader.read_positions().unwrap().map(Vec3::from).collect()
}

fn close(a: Affine3A, b: Affine3A, what: &str) {
    assert!(a.abs_diff_eq(b, 1e-4), "{what}: got {a:?}, want {b:?}");
}

#[test]
fn a_rigid_rig_posed_at_each_step_matches_the_samplers_node_transform() {
    let path = interpolation_test();
    // One pose a frame at 24 fps: every key of the file (at whole frames) is a step.
    let rig = rigid(&path, SkinOptions { pose_step: Some(1.0), ..Default::default() });
    assert!(rig.is_rigid());
    let animated = Animated::load(&path).unwrap();
    // The Light node (1) never moves: rig_from_node = lift * rest, so the
    // lift (feet on the ground) is read from it.
    let (lt, lr, ls) = rest_trs(&path, 1);
    let mut seen = std::collections::BTreeSet::new();
    for clip_name in [
        "Step Scale",
        "Linear Scale",
        "CubicSpline Scale",
        "Step Rotation",
        "Linear Rotation",
        "CubicSpline Rotation",
        "Step Translation",
        "Linear Translation",
        "CubicSpline Translation",
    ] {
        let clip = animated.clip(clip_name).unwrap();
        let ch = &clip.channels[0];
        seen.insert((ch.property as u8, ch.interpolation as u8));
        let cycle = rig.cycle_index(clip_name).unwrap();
        let steps = rig.cycles()[cycle].steps;
        assert_eq!(steps as f32, (clip.end - clip.start) * FPS, "{clip_name}: a step a frame");
        let (t0, r0, s0) = rest_trs(&path, ch.node);
        let rest = node_vertices(&path, ch.node);
        let mut keys_hit = 0;
        for step in 0..=steps {
            let t = clip.start + step as f32 / FPS;
            let joints = rig.step_joints(cycle, step);
            let lift = joints[1] * Affine3A::from_scale_rotation_translation(ls, lr, lt).inverse();
            assert!(lift.matrix3.abs_diff_eq(glam::Mat3A::IDENTITY, 1e-5), "the lift only translates");
            let (mut tr, mut rot, mut sc) = (t0, r0, s0);
            match ch.property {
                Property::Translation => tr = ch.sample_vec3(t),
                Property::Rotation => rot = ch.sample_quat(t),
                Property::Scale => sc = ch.sample_vec3(t),
            }
            let want = lift * Affine3A::from_scale_rotation_translation(sc, rot, tr);
            close(joints[ch.node], want, &format!("{clip_name} step {step}"));
            // At a key the node takes the key's own value.
            if let Some(k) = ch.times.iter().position(|&kt| (kt - t).abs() < 1e-4) {
                let v = match ch.interpolation {
                    Interpolation::CubicSpline => ch.values[3 * k + 1],
                    _ => ch.values[k],
                };
                let got = match ch.property {
                    Property::Rotation => Quat::from_vec4(v).normalize().dot(rot).abs() > 1.0 - 1e-5,
                    _ => v.truncate().abs_diff_eq(if ch.property == Property::Scale { sc } else { tr }, 1e-5),
                };
                assert!(got, "{clip_name} key {k}: the sampler gives the key");
                keys_hit += 1;
            }
            // The node's mesh rides it rigidly.
            let piece = (0..rig.piece_count())
                .find(|&p| {
                    rig.pose_piece(p, &joints, "x")
                        .name
                        .contains(&format!("#{}@", animated.hierarchy.nodes[ch.node].name))
                })
                .unwrap_or_else(|| panic!("{clip_name}: the node's mesh is a piece"));
            let posed = rig.pose_piece(piece, &joints, "x");
            for (p, v) in posed.positions.iter().zip(&rest) {
                assert!(p.distance(want.transform_point3(*v)) < 1e-4, "{clip_name} step {step}: {p} vs {v}");
            }
        }
        assert_eq!(keys_hit, ch.times.len(), "{clip_name}: every key is a step");
    }
    assert_eq!(seen.len(), 9, "three properties by three interpolations");
}

#[test]
fn a_rigid_rig_is_detected_without_kind_and_every_mesh_node_is_a_part() {
    let path = interpolation_test();
    let detected = SkinnedRig::load(&path, &SkinOptions::default(), FPS).unwrap();
    assert!(detected.is_rigid(), "no skin and no slots: rigid");
    // Ten mesh nodes (nine cubes and the plane), each its own piece.
    assert_eq!(detected.piece_count(), 10);
    assert_eq!(detected.cycles().len(), 9);
    // The lowest rest vertex is lifted to the ground: the plane.
    let joints = detected.step_joints(0, 0);
    let lowest = (0..detected.piece_count())
        .flat_map(|p| detected.pose_piece(p, &joints, "x").positions)
        .map(|v| v.y)
        .fold(f32::INFINITY, f32::min);
    assert!(lowest.abs() < 0.05, "lowest vertex {lowest}");
}

// ------------------------------------------------------------ a car

const WHEEL_RADIUS: f32 = 0.3;
const WHEELS: [(&str, f32, f32); 4] =
    [("wheel_fl", 0.8, 1.1), ("wheel_fr", -0.8, 1.1), ("wheel_rl", 0.8, -1.1), ("wheel_rr", -0.8, -1.1)];

/// An octagonal wheel of `WHEEL_RADIUS` about the X axis, 0.2 m wide.
fn wheel_mesh() -> MeshData {
    let mut m = MeshData::default();
    for side in [-0.1f32, 0.1] {
        m.positions.push([side, 0.0, 0.0]);
        m.normals.push([side.signum(), 0.0, 0.0]);
        for i in 0..8 {
            let a = i as f32 * TAU / 8.0;
            m.positions.push([side, WHEEL_RADIUS * a.cos(), WHEEL_RADIUS * a.sin()]);
            m.normals.push([side.signum(), 0.0, 0.0]);
        }
    }
    for s in 0..2u32 {
        let c = s * 9;
        for i in 0..8 {
            let (a, b) = (c + 1 + i, c + 1 + (i + 1) % 8);
            m.indices.extend(if s == 0 { [c, b, a] } else { [c, a, b] });
        }
    }
    for i in 0..8 {
        let (a, b) = (1 + i, 1 + (i + 1) % 8);
        m.indices.extend([a, b, a + 9, b, b + 9, a + 9]);
    }
    m
}

/// A car facing +Z (or, `backwards`, modelled facing -Z) whose clip `Drive`
/// turns each wheel once about X in a second (LINEAR keys every 45 degrees,
/// forward rolling), written to `dir/name`.
fn write_car(dir: &Path, name: &str, backwards: bool) -> PathBuf {
    let flip = if backwards { -1.0 } else { 1.0 };
    let mut b = GlbBuilder::new();
    let paint = b.add_material(&MaterialDesc::new("paint", [0.8, 0.1, 0.1, 1.0]));
    let rubber = b.add_material(&MaterialDesc::new("rubber", [0.05, 0.05, 0.05, 1.0]));
    // A long bonnet: the car's front is the end further from its middle.
    let (back, front) = (Vec3::new(-0.8, 0.3, -1.6), Vec3::new(0.8, 1.1, 2.2));
    let body = if backwards {
        common::cuboid(-front * Vec3::new(1.0, -1.0, 1.0), -back * Vec3::new(1.0, -1.0, 1.0))
    } else {
        common::cuboid(back, front)
    };
    let body = b.add_mesh("body", &body, Some(paint)).unwrap();
    let tyre = b.add_mesh("tyre", &wheel_mesh(), Some(rubber)).unwrap();
    let mut children = vec![b.add_node(NodeDesc::new("body").mesh(body)).unwrap()];
    let mut channels = Vec::new();
    for (wheel, x, z) in WHEELS {
        let node = b.add_node(NodeDesc::new(wheel).mesh(tyre).translation([x * flip, WHEEL_RADIUS, z * flip])).unwrap();
        children.push(node);
        let times: Vec<f32> = (0..=8).map(|i| i as f32 / 8.0).collect();
        // Rolling forward turns +Y towards the way the car faces.
        let values = times.iter().map(|t| Quat::from_rotation_x(flip * t * TAU).to_array()).collect();
        channels.push(ChannelDesc {
            node,
            interpolation: Interp::Linear,
            times,
            values: ChannelValues::Rotation(values),
        });
    }
    let top = b.add_node(NodeDesc::new("car")).unwrap();
    for c in children {
        b.add_child(top, c).unwrap();
    }
    b.add_animation(&AnimationDesc { name: "Drive".into(), channels }).unwrap();
    let path = dir.join(name);
    b.write(&path).unwrap();
    path
}

#[test]
fn a_cars_stride_is_the_distance_its_wheels_roll_in_one_turn() {
    let dir = common::tempdir().unwrap();
    let car = rigid(&write_car(dir.path(), "car.glb", false), SkinOptions::default());
    let drive = &car.cycles()[car.cycle_index("Drive").unwrap()];
    assert!((drive.stride - TAU * WHEEL_RADIUS).abs() < 1e-4, "stride {}", drive.stride);
    assert!(car.warnings().is_empty(), "{:?}", car.warnings());
    // A stride given in the shot wins over the wheels.
    let strides = [("Drive".to_string(), 5.0)].into_iter().collect();
    let given = rigid(&write_car(dir.path(), "car2.glb", false), SkinOptions { strides, ..Default::default() });
    assert_eq!(given.cycles()[given.cycle_index("Drive").unwrap()].stride, 5.0);
}

#[test]
fn forward_turns_a_rigid_rig_modelled_facing_minus_z() {
    let dir = common::tempdir().unwrap();
    let plus = rigid(&write_car(dir.path(), "plus.glb", false), SkinOptions::default());
    let minus_path = write_car(dir.path(), "minus.glb", true);
    let minus = rigid(&minus_path, SkinOptions { forward: Axis::NegZ, ..Default::default() });
    let unturned = rigid(&minus_path, SkinOptions::default());
    let c = plus.cycle_index("Drive").unwrap();
    assert_eq!(plus.cycles()[c].stride, minus.cycles()[c].stride);
    for step in [0, 3, 10] {
        let (a, b, u) = (plus.step_joints(c, step), minus.step_joints(c, step), unturned.step_joints(c, step));
        let mut moved = false;
        for p in 0..plus.piece_count() {
            let (pa, pb, pu) =
                (plus.pose_piece(p, &a, "x"), minus.pose_piece(p, &b, "x"), unturned.pose_piece(p, &u, "x"));
            // Mirrored models list their vertices in another order: compare bounds.
            let (ba, bb, bu) = (pa.bounds(), pb.bounds(), pu.bounds());
            assert!(
                ba.0.distance(bb.0) < 1e-4 && ba.1.distance(bb.1) < 1e-4,
                "piece {p} step {step}: {ba:?} vs {bb:?}"
            );
            moved |= ba.0.distance(bu.0) > 0.1;
        }
        assert!(moved, "without `forward` the car faces backwards");
    }
}

/// The angle of a wheel's posed first rim vertex about its axle (rig space),
/// from +Y towards +Z.
fn wheel_angle(crowd: &ShotCrowd, frame: i32, wheel: &str) -> f32 {
    let block = crowd.agents_at(frame).unwrap();
    let mut out = Vec::new();
    crowd.agent_instances(&block.agents[0], Lod::Full, vis::ALL, &mut out).unwrap();
    assert_eq!(out.len(), 5, "body and four wheels, each its own instance");
    let lib = crowd.library();
    let mesh = out
        .iter()
        .map(|i| &lib.meshes[i.mesh as usize])
        .find(|m| m.name.contains(&format!("#{wheel}@")))
        .unwrap_or_else(|| panic!("{wheel} at frame {frame}"));
    // Vertex 0 is the hub, vertex 1 the rim at angle 0 (+Y).
    let d = mesh.positions[1] - mesh.positions[0];
    d.z.atan2(d.y)
}

/// A shot of one car driving at `speed` m/s (a trajectory table with no
/// cycle column: the cycle frame follows distance / stride).
fn car_shot(dir: &Path, speed: f32, extra_rig: &str) -> PathBuf {
    let car = write_car(dir, "car.glb", false);
    let mut csv = String::from("frame,id,x,y\n");
    for f in 1..=25 {
        csv.push_str(&format!("{f},1,0.0,{:?}\n", speed * (f - 1) as f32 / FPS));
    }
    std::fs::write(dir.join("cars.csv"), csv).unwrap();
    let shot = format!(
        r#"version = 1
name = "cars"
seed = 3
wardrobes = []
[frames]
start = 1
end = 25
fps = 24.0
[cache]
path = "cars.csv"
columns = {{ frame = "frame", id = "id", x = "x", y = "y" }}
source_fps = 24.0
rig = "car"
cycle = "Drive"
[rigs.car]
file = "{}"
kind = "rigid"
pose_step = 0.125
{extra_rig}
[camera]
sensor_width = 36.0
[[camera.keys]]
frame = 1
position = [5.0, 2.5, 1.5]
aim = [0.0, 0.5, -1.4]
focal_length = 35.0
[render]
resolution = [96, 54]
spp = 2
"#,
        car.display()
    );
    let path = dir.join("cars.toml");
    std::fs::write(&path, shot).unwrap();
    path
}

#[test]
fn a_cars_wheels_spin_at_speed_over_radius() {
    let dir = common::tempdir().unwrap();
    let speed = 2.0;
    let crowd = ShotCrowd::load(&car_shot(dir.path(), speed, "")).unwrap();
    // Frames 13 to 16 (well inside the track, where the speed is steady):
    // the wheel turns speed / radius / fps a frame, up to the pose step
    // (1/8 frame of a 24-frame loop: 1.9 degrees) at each end.
    let per_frame = speed / WHEEL_RADIUS / FPS;
    for wheel in ["wheel_fl", "wheel_rr"] {
        let (a, b) = (wheel_angle(&crowd, 13, wheel), wheel_angle(&crowd, 16, wheel));
        let turned = (b - a).rem_euclid(TAU);
        let want = 3.0 * per_frame;
        assert!(want < PI, "measurable without ambiguity");
        assert!((turned - want).abs() < 0.07, "{wheel}: turned {turned} rad in 3 frames, want {want}");
    }
    // Twice the speed, twice the spin.
    let dir2 = common::tempdir().unwrap();
    let fast = ShotCrowd::load(&car_shot(dir2.path(), 2.0 * speed, "")).unwrap();
    let turned = (wheel_angle(&fast, 14, "wheel_fl") - wheel_angle(&fast, 13, "wheel_fl")).rem_euclid(TAU);
    assert!((turned - 2.0 * per_frame).abs() < 0.07, "turned {turned}, want {}", 2.0 * per_frame);
    // The body does not turn with the wheels.
    assert!(crowd.warnings().iter().all(|w| !w.contains("slides")), "{:?}", crowd.warnings());
    // `cast --stats` counts the cars as rigid, not skinned.
    let stats = throng::casting::table::cast_stats(&crowd);
    let posed = stats.skinned.as_ref().expect("the cars are posed from their node animation");
    assert!(posed.agents > 0 && posed.rigid_agents == posed.agents, "{posed:?}");
    let text = throng::casting::table::format_stats(&stats);
    assert!(text.contains(&format!("rigid agents         {}", posed.agents)), "{text}");
    assert!(text.contains("skinned agents       0"), "{text}");
}

#[test]
fn a_car_renders_exports_and_blurs() {
    let dir = common::tempdir().unwrap();
    let shot = car_shot(dir.path(), 3.0, "");
    // Over a shutter the wheels turn: their posed meshes blend (as skinned ones do).
    let crowd = ShotCrowd::open(throng::shot::Shot::load(&shot).unwrap(), Some([-0.25, 0.25])).unwrap();
    let m = throng::casting::motion::MotionFrame::new(&crowd, 12, [-0.25, 0.25]).unwrap();
    assert!(throng::casting::motion::moves(&m));
    assert!(m.agents.iter().all(|(_, a)| a.deform.is_some()), "the wheels turn over the shutter");
    let (code, out, err) = common::run(&[
        "render".as_ref(),
        shot.as_os_str(),
        "--layer".as_ref(),
        "full".as_ref(),
        "--frames".as_ref(),
        "12".as_ref(),
        "--shutter".as_ref(),
        "-0.25,0.25".as_ref(),
        "--png".as_ref(),
        "--resolution".as_ref(),
        "320x180".as_ref(),
        "--spp".as_ref(),
        "16".as_ref(),
        "--out".as_ref(),
        dir.path().join("renders").as_os_str(),
    ]);
    assert_eq!(code, 0, "{out}\n{err}");
    // Kept for looking at: target/tmp/rigid_car.png (the car blurred at 3 m/s).
    let png = dir.path().join("renders/full/cars.full.0012.png");
    let png = if png.exists() { png } else { dir.path().join("renders/full/cars.full.12.png") };
    std::fs::copy(&png, Path::new(env!("CARGO_TARGET_TMPDIR")).join("rigid_car.png")).unwrap();
    let (code, out, err) = common::run(&[
        "export".as_ref(),
        shot.as_os_str(),
        "--frame".as_ref(),
        "12".as_ref(),
        "--out".as_ref(),
        dir.path().join("car_out.glb").as_os_str(),
    ]);
    assert_eq!(code, 0, "{out}\n{err}");
    let (doc, _, _) = gltf::import(dir.path().join("car_out.glb")).unwrap();
    assert!(doc.meshes().count() >= 5, "the body and the wheels' posed meshes");
}

#[test]
fn bad_rigid_rigs_are_refused_naming_file_rig_and_field() {
    let dir = common::tempdir().unwrap();
    let skinned = common::shared_asset("gltf/SimpleSkin/SimpleSkin.gltf");
    let still = dir.path().join("still.glb");
    {
        let mut b = GlbBuilder::new();
        let m = b.add_mesh("box", &common::cuboid(Vec3::ZERO, Vec3::ONE), None).unwrap();
        b.add_node(NodeDesc::new("box").mesh(m)).unwrap();
        b.write(&still).unwrap();
    }
    let cases: [(&str, String, &[&str]); 4] = [
        (
            "skin",
            format!("file = \"{}\"\nkind = \"rigid\"", skinned.display()),
            &["SimpleSkin.gltf", "rigs.car.kind", "has a skin"],
        ),
        (
            "no animation",
            format!("file = \"{}\"\nkind = \"rigid\"", still.display()),
            &["still.glb", "rigs.car", "no animation"],
        ),
        ("unknown clip", "cycles = { Drive = \"Fly\" }".into(), &["car.glb", "rigs.car.cycles.Drive", "Fly"]),
        ("forward along up", "forward = \"+y\"".into(), &["car.glb", "rigs.car.forward", "along up"]),
    ];
    for (what, rig, want) in cases {
        let d = common::tempdir().unwrap();
        let shot = car_shot(d.path(), 2.0, "");
        let text = std::fs::read_to_string(&shot).unwrap();
        let text = match rig.starts_with("file") {
            true => {
                let start = text.find("file = ").unwrap();
                let end = start + text[start..].find('\n').unwrap();
                let text = format!("{}{}{}", &text[..start], rig, &text[end..]);
                text.replacen("kind = \"rigid\"\nkind = \"rigid\"", "kind = \"rigid\"", 1)
            }
            false => text.replace("pose_step = 0.125", &format!("pose_step = 0.125\n{rig}")),
        };
        std::fs::write(&shot, text).unwrap();
        let (code, out, err) = common::run(&["cast".as_ref(), shot.as_os_str()]);
        assert_eq!(code, 2, "{what}: {out}\n{err}");
        for w in want {
            assert!(err.contains(w), "{what}: `{w}` missing from: {err}");
        }
        assert!(!err.contains("panicked"), "{what}: {err}");
    }
}

#[test]
fn a_wardrobe_repaints_a_car_and_its_parts_ride_their_slots_nodes() {
    let dir = common::tempdir().unwrap();
    let shot = car_shot(dir.path(), 2.0, "schemes = { Cars = 1.0 }");
    let car = dir.path().join("car.glb");
    let mut wardrobe = String::from(
        "version = 1\nname = \"w\"\n[materials.red]\nbase_color = [0.9, 0.1, 0.1]\n[materials.blue]\nbase_color = [0.1, 0.2, 0.9]\n\
         [schemes.Cars]\n",
    );
    wardrobe.push_str(&format!(
        "[[schemes.Cars.parts]]\nslot = \"body\"\nfile = \"{}\"\nmesh = \"body\"\nmaterials = [\"red\", \"blue\"]\n",
        car.display()
    ));
    for (wheel, _, _) in WHEELS {
        wardrobe.push_str(&format!(
            "[[schemes.Cars.parts]]\nslot = \"{wheel}\"\nfile = \"{}\"\nmesh = \"tyre\"\n",
            car.display()
        ));
    }
    std::fs::write(dir.path().join("w.toml"), wardrobe).unwrap();
    let text = std::fs::read_to_string(&shot).unwrap().replace("wardrobes = []", "wardrobes = [\"w.toml\"]");
    std::fs::write(&shot, text).unwrap();
    let dressed = ShotCrowd::load(&shot).unwrap();
    let plain = ShotCrowd::load(&car_shot(common::tempdir().unwrap().path(), 2.0, "")).unwrap();
    let instances = |c: &ShotCrowd| {
        let block = c.agents_at(12).unwrap();
        let mut out = Vec::new();
        c.agent_instances(&block.agents[0], Lod::Full, vis::ALL, &mut out).unwrap();
        out.iter()
            .map(|i| {
                let m = &c.library().meshes[i.mesh as usize];
                (m.positions.clone(), c.library().materials[i.material as usize].name.clone())
            })
            .collect::<Vec<_>>()
    };
    let (a, b) = (instances(&dressed), instances(&plain));
    assert_eq!(a.len(), 5);
    // Same geometry where it was (the wardrobe's parts ride the same nodes)...
    for ((pa, _), (pb, _)) in a.iter().zip(&b) {
        assert_eq!(pa.len(), pb.len());
        assert!(pa.iter().zip(pb).all(|(x, y)| x.distance(*y) < 1e-5));
    }
    // ... in the wardrobe's paint.
    assert!(a[0].1 == "w/red" || a[0].1 == "w/blue", "body wears {}", a[0].1);
    assert!(b[0].1.ends_with("#paint"), "{}", b[0].1);
}

#[test]
fn a_part_turned_by_forward_on_a_rigid_rig_is_refused_not_ignored() {
    let dir = common::tempdir().unwrap();
    let shot = car_shot(dir.path(), 2.0, "schemes = { Cars = 1.0 }");
    let car = dir.path().join("car.glb");
    let wardrobe = format!(
        "version = 1\nname = \"w\"\n[schemes.Cars]\n[[schemes.Cars.parts]]\nslot = \"body\"\nfile = \"{}\"\nmesh = \"body\"\nforward = \"-z\"\n",
        car.display()
    );
    std::fs::write(dir.path().join("w.toml"), wardrobe).unwrap();
    let text = std::fs::read_to_string(&shot).unwrap().replace("wardrobes = []", "wardrobes = [\"w.toml\"]");
    std::fs::write(&shot, text).unwrap();
    let err = ShotCrowd::load(&shot).err().expect("refused").to_string();
    for want in ["w.toml", "schemes.Cars.parts[0].forward", "rig `car`", "the shot"] {
        assert!(err.contains(want), "`{want}` missing from: {err}");
    }
}

#[test]
fn a_skinned_mesh_worn_on_a_rigid_rig_is_refused_not_drawn_in_its_bind_pose() {
    let dir = common::tempdir().unwrap();
    let shot = car_shot(dir.path(), 2.0, "schemes = { Cars = 1.0 }");
    let walker = common::repo_path("demo/rigs/walker.glb");
    let wardrobe = format!(
        "version = 1\nname = \"w\"\n[schemes.Cars]\n[[schemes.Cars.parts]]\nslot = \"body\"\nfile = \"{}\"\nmesh = \"#0\"\n",
        walker.display()
    );
    std::fs::write(dir.path().join("w.toml"), wardrobe).unwrap();
    let text = std::fs::read_to_string(&shot).unwrap().replace("wardrobes = []", "wardrobes = [\"w.toml\"]");
    std::fs::write(&shot, text).unwrap();
    let err = ShotCrowd::load(&shot).err().expect("refused").to_string();
    for want in ["walker.glb", "mesh `#0` is skinned", "mesh"] {
        assert!(err.contains(want), "`{want}` missing from: {err}");
    }
}

// ------------------------------------------------------------ an alien that walks

/// Metres the walking alien's `alien` node travels in its one-second `Walk`.
const ALIEN_STRIDE: f32 = 0.8;

/// The Kenney alien (shared assets, CC0 1.0, Kenney "Space Kit"): its six
/// part meshes on their nodes as the file has them (armLeft ... legRight
/// under `alien`), in its materials, with a clip `Walk` (one second, LINEAR
/// keys every quarter) swinging each leg and the opposite arm 30 degrees
/// about X from the hip or shoulder, and, with `travel`, the `alien` node
/// walking `ALIEN_STRIDE` along -Z, the way the model faces. No skin and no
/// slots: a rigid rig, detected.
fn write_alien(dir: &Path, name: &str, travel: bool) -> PathBuf {
    let (doc, buffers, _) = gltf::import(common::shared_asset("gltf/KenneyAlien/alien.glb")).unwrap();
    let mut b = GlbBuilder::new();
    let materials: Vec<_> = doc
        .materials()
        .map(|m| b.add_material(&MaterialDesc::new(m.name().unwrap(), m.pbr_metallic_roughness().base_color_factor())))
        .collect();
    let top = b.add_node(NodeDesc::new("alien")).unwrap();
    let times: Vec<f32> = (0..=4).map(|i| i as f32 / 4.0).collect();
    let mut channels = Vec::new();
    for node in doc.nodes() {
        let Some(mesh) = node.mesh() else { continue };
        let mut id = None;
        for prim in mesh.primitives() {
            let r = prim.reader(|buf| Some(&buffers[buf.index()].0[..]));
            let data = MeshData {
                positions: r.read_positions().unwrap().collect(),
                normals: r.read_normals().unwrap().collect(),
                indices: r.read_indices().unwrap().into_u32().collect(),
                ..Default::default()
            };
            let material = prim.material().index().map(|i| materials[i]);
            match id {
                None => id = Some(b.add_mesh(mesh.name().unwrap(), &data, material).unwrap()),
                Some(m) => b.add_primitive(m, &data, material).unwrap(),
            }
        }
        let (t, r, s) = node.transform().decomposed();
        let name = node.name().unwrap();
        let n = b.add_node(NodeDesc::new(name).mesh(id.unwrap()).translation(t).rotation(r).scale(s)).unwrap();
        b.add_child(top, n).unwrap();
        // Left leg with right arm, then the other pair half a cycle later.
        let swing = match name {
            "legLeft" | "armRight" => 1.0,
            "legRight" | "armLeft" => -1.0,
            _ => continue,
        };
        let values = times
            .iter()
            .map(|t| {
                (Quat::from_array(r) * Quat::from_rotation_x(swing * 30f32.to_radians() * (t * TAU).sin())).to_array()
            })
            .collect();
        channels.push(ChannelDesc {
            node: n,
            interpolation: Interp::Linear,
            times: times.clone(),
            values: ChannelValues::Rotation(values),
        });
    }
    if travel {
        channels.push(ChannelDesc {
            node: top,
            interpolation: Interp::Linear,
            times: vec![0.0, 1.0],
            values: ChannelValues::Translation(vec![[0.0, 0.0, 0.0], [0.0, 0.0, -ALIEN_STRIDE]]),
        });
    }
    b.add_animation(&AnimationDesc { name: "Walk".into(), channels }).unwrap();
    let path = dir.join(name);
    b.write(&path).unwrap();
    path
}

/// Every agent-frame's cycle advance is its distance over the stride: feet
/// (and wheels) do not slide. `agents` is how many must move.
fn assert_planted(crowd: &throng::cache::CrowdCache, stride: f32, length: f32, agents: usize) {
    let mut moving = 0;
    for w in crowd.frames.windows(2) {
        for (a, b) in w[0].agents.iter().zip(&w[1].agents) {
            assert_eq!(a.id, b.id);
            let dist = (b.position - a.position).length();
            let got = (b.cycle_frame - a.cycle_frame).rem_euclid(length);
            let want = (dist / stride * length).rem_euclid(length);
            assert!((got - want).abs() < 1e-3, "agent {} frame {}: {got} vs {want}", b.id, w[1].frame);
            moving += (dist > 0.0) as usize;
        }
    }
    assert!(moving >= agents, "{moving} moving agent-frames");
}

#[test]
fn a_rigid_alien_walks_at_its_root_nodes_travel_and_is_detected() {
    let dir = common::tempdir().unwrap();
    let alien = rigid(
        &write_alien(dir.path(), "alien.glb", true),
        SkinOptions { root: Some("alien".into()), forward: Axis::NegZ, ..Default::default() },
    );
    let walk = &alien.cycles()[alien.cycle_index("Walk").unwrap()];
    assert!((walk.stride - ALIEN_STRIDE).abs() < 1e-4, "stride {}", walk.stride);
    // Six part meshes of three primitives each, each primitive a piece.
    assert_eq!(alien.piece_count(), 18);
    let detected = SkinnedRig::load(&dir.path().join("alien.glb"), &SkinOptions::default(), FPS).unwrap();
    assert!(detected.is_rigid());

    // Five aliens walking at the camera, simulated (the sim's `[rigs]` reads
    // the alien as the shot does) and rendered: target/tmp/rigid_alien.png.
    let mut sim = String::from(
        "version = 1\nseed = 11\n[frames]\nstart = 1\nend = 30\n[rigs]\n\
         alien = { file = \"alien.glb\", root = \"alien\", forward = \"-z\" }\n[cycles.Walk]\n",
    );
    for id in 1..=5u32 {
        let x = (id as f32 - 3.0) * 0.8;
        sim.push_str(&format!(
            "[[agents]]\nid = {id}\nposition = [{x:?}, {:?}]\nrig = \"alien\"\ncycle = \"Walk\"\n",
            -((id % 2) as f32) * 0.6
        ));
    }
    std::fs::write(dir.path().join("aliens_sim.toml"), sim).unwrap();
    let crowd_file = dir.path().join("aliens.crowd");
    let (code, out, err) = common::run(&[
        "sim".as_ref(),
        dir.path().join("aliens_sim.toml").as_os_str(),
        "--out".as_ref(),
        crowd_file.as_os_str(),
    ]);
    assert_eq!(code, 0, "{out}\n{err}");
    let shot = dir.path().join("aliens.toml");
    std::fs::write(
        &shot,
        r#"version = 1
name = "aliens"
seed = 3
wardrobes = []
[frames]
start = 1
end = 30
fps = 24.0
[cache]
path = "aliens.crowd"
[rigs.alien]
file = "alien.glb"
root = "alien"
forward = "-z"
[camera]
sensor_width = 36.0
[[camera.keys]]
frame = 1
position = [2.0, 0.9, 3.8]
aim = [0.3, 0.35, 0.6]
focal_length = 30.0
[render]
resolution = [480, 270]
spp = 16
"#,
    )
    .unwrap();
    let crowd = ShotCrowd::load(&shot).unwrap();
    // A leg swings from frame to frame; the body rides along unturned.
    let part = |frame: i32, id: u32, name: &str| {
        let block = crowd.agents_at(frame).unwrap();
        let a = block.agents.iter().find(|a| a.id == id).unwrap();
        let mut out = Vec::new();
        crowd.agent_instances(a, Lod::Full, vis::ALL, &mut out).unwrap();
        assert_eq!(out.len(), 18, "every primitive of the six parts, each its own instance");
        let lib = crowd.library();
        let m = out.iter().map(|i| &lib.meshes[i.mesh as usize]).find(|m| m.name.contains(&format!("#{name}/0@")));
        m.unwrap_or_else(|| panic!("{name} at frame {frame}")).positions.clone()
    };
    let moved = |a: &[Vec3], b: &[Vec3]| a.iter().zip(b).map(|(x, y)| x.distance(*y)).fold(0.0f32, f32::max);
    assert!(moved(&part(10, 1, "legLeft"), &part(16, 1, "legLeft")) > 0.03, "the left leg swings");
    assert!(moved(&part(10, 1, "body"), &part(16, 1, "body")) < 1e-3, "the body does not");
    let renders = dir.path().join("renders");
    let (code, out, err) = common::run(&[
        "render".as_ref(),
        shot.as_os_str(),
        "--layer".as_ref(),
        "full".as_ref(),
        "--frames".as_ref(),
        "24".as_ref(),
        "--png".as_ref(),
        "--out".as_ref(),
        renders.as_os_str(),
    ]);
    assert_eq!(code, 0, "{out}\n{err}");
    let png = first_png(&renders.join("full"));
    let (film, _) = throng::render::exr::read_layer(&png.with_extension("exr")).unwrap();
    let seen: std::collections::BTreeSet<u32> = film.agent_id.iter().copied().filter(|&id| id != 0).collect();
    assert_eq!(seen.len(), 5, "all five aliens in frame: {seen:?}");
    let covered = film.agent_id.iter().filter(|&&id| id != 0).count() as f32 / film.agent_id.len() as f32;
    assert!(covered > 0.05, "the aliens cover {covered} of the frame");
    std::fs::copy(&png, Path::new(env!("CARGO_TARGET_TMPDIR")).join("rigid_alien.png")).unwrap();
}

/// The first PNG in `dir`.
fn first_png(dir: &Path) -> PathBuf {
    let found =
        std::fs::read_dir(dir).unwrap().flatten().map(|e| e.path()).find(|p| p.extension().is_some_and(|e| e == "png"));
    found.unwrap_or_else(|| panic!("no PNG in {}", dir.display()))
}

/// A sim scene of a car on `Drive` and an alien on `Walk`, with `[rigs]`
/// entries `car` and `alien` as given, walking straight for 48 frames.
fn rigid_scene(dir: &Path, car: &str, alien: &str) -> String {
    format!(
        "version = 1\nseed = 4\n[frames]\nstart = 1\nend = 48\n[rigs]\ncar = {car}\nalien = {alien}\n\
         [cycles.Drive]\n[cycles.Walk]\n\
         [[agents]]\nid = 1\nposition = [0.0, 0.0]\nrig = \"car\"\ncycle = \"Drive\"\ncycle_frame = 0.0\n\
         [[agents]]\nid = 2\nposition = [4.0, 0.0]\nrig = \"alien\"\ncycle = \"Walk\"\ncycle_frame = 0.0\n"
    )
    .replace("DIR", &dir.display().to_string())
}

/// The reference simulation's `[rigs]` reads a car and a walking alien as
/// the shot does, kind detected: the car's stride is its wheels' roll, the
/// alien's its root node's travel, each cycle one clip long.
#[test]
fn the_sims_rigs_table_times_a_car_and_an_alien_without_kind() {
    use throng::sim::{CycleTiming, SimScene};
    let dir = common::tempdir().unwrap();
    write_car(dir.path(), "car.glb", false);
    write_alien(dir.path(), "alien.glb", true);
    write_alien(dir.path(), "still_alien.glb", false);
    let parse = |car: &str, alien: &str| SimScene::parse(&rigid_scene(dir.path(), car, alien), "rigid.toml");
    let alien = "{ file = \"DIR/alien.glb\", root = \"alien\", forward = \"-z\" }";
    let scene = parse("\"DIR/car.glb\"", alien).unwrap_or_else(|e| panic!("{e}"));
    let r = |n: &str| scene.rigs.iter().position(|x| x == n).unwrap() as u16;
    let c = |n: &str| scene.cycles.iter().position(|x| x.name == n).unwrap() as u16;
    let (car, walk) = (scene.timing(r("car"), c("Drive")), scene.timing(r("alien"), c("Walk")));
    assert!((car.stride - TAU * WHEEL_RADIUS).abs() < 1e-4 && (car.length - 24.0).abs() < 1e-3, "{car:?}");
    assert!((walk.stride - ALIEN_STRIDE).abs() < 1e-4 && (walk.length - 24.0).abs() < 1e-3, "{walk:?}");
    // What the shot plays: the same rig loaded as a shot loads it, kind detected.
    let shot_car = SkinnedRig::load(&dir.path().join("car.glb"), &SkinOptions::default(), FPS).unwrap();
    assert!(shot_car.is_rigid());
    let (stride, length) = shot_car.cycle_timing("Drive").unwrap();
    assert_eq!(car, CycleTiming { length, stride });
    // Declared `kind = "rigid"`, the same timing.
    let declared = parse("{ file = \"DIR/car.glb\", kind = \"rigid\" }", alien).unwrap();
    assert_eq!(declared.timing(r("car"), c("Drive")), car);
    // Each agent's cycle advances by its distance over its rig's stride.
    let crowd = throng::sim::run(&scene);
    for (k, t) in [(0, car), (1, walk)] {
        let mut walked = 0.0;
        for f in 1..crowd.frames.len() {
            let (a, b) = (&crowd.frames[f - 1].agents[k], &crowd.frames[f].agents[k]);
            let adv = (b.cycle_frame - a.cycle_frame).rem_euclid(t.length);
            let dist = (b.position - a.position).length();
            assert!((adv * t.stride / t.length - dist).abs() < 1e-4, "agent {k} frame {f}: {adv} frames for {dist} m");
            walked += dist;
        }
        assert!(walked > 40.0 * 0.9 * t.stride / t.length, "agent {k} moves: {walked} m");
    }
    // An alien with no root node and no wheels has no stride: refused, naming
    // the scene, the rig entry and the two keys that would give one...
    let bare = "{ file = \"DIR/still_alien.glb\", forward = \"-z\" }";
    let Err(e) = parse("\"DIR/car.glb\"", bare) else { panic!("an alien with no stride is refused") };
    let e = e.to_string();
    for want in [
        "rigid.toml",
        "field `rigs.alien`",
        "rigid rig `alien`",
        "still_alien.glb",
        "turns no wheel",
        "rigs.alien.strides.Walk",
    ] {
        assert!(e.contains(want), "`{want}` missing from: {e}");
    }
    // ... and given `strides` it walks at that.
    let given = "{ file = \"DIR/still_alien.glb\", forward = \"-z\", strides = { Walk = 0.7 } }";
    let scene = parse("\"DIR/car.glb\"", given).unwrap();
    assert_eq!(scene.timing(r("alien"), c("Walk")).stride, 0.7);
}

/// `cache convert --rig-file` reads a car and a walking alien as the shot
/// does, kind detected: stride and length in the import report, and the
/// written cycle frames advance by distance over that stride.
#[test]
fn cache_convert_reads_a_car_and_an_alien_as_rig_files() {
    let dir = common::tempdir().unwrap();
    let car = write_car(dir.path(), "car.glb", false);
    let alien = write_alien(dir.path(), "alien.glb", true);
    let still = write_alien(dir.path(), "still_alien.glb", false);
    let input = common::fixture("jupedsim_small.sqlite");
    let info = |args: &[&str]| {
        let mut all = vec!["cache", "info", input.to_str().unwrap(), "--json"];
        all.extend_from_slice(args);
        let (code, out, err) = common::run(&all);
        assert_eq!(code, 0, "{args:?}: {err}");
        let v: serde_json::Value = serde_json::from_str(&out).unwrap();
        (v["import"]["stride"].as_f64().unwrap() as f32, v["import"]["cycle_length"].as_f64().unwrap() as f32)
    };
    let (c, a, s) = (car.to_str().unwrap(), alien.to_str().unwrap(), still.to_str().unwrap());
    let car_args = ["--rig", "car", "--cycle", "Drive", "--rig-file", c];
    let (stride, length) = info(&car_args);
    assert!((stride - TAU * WHEEL_RADIUS).abs() < 1e-4 && (length - 24.0).abs() < 1e-3, "car: {stride} m, {length}");
    let alien_args =
        ["--rig", "alien", "--cycle", "Walk", "--rig-file", a, "--rig-root", "alien", "--rig-forward", "-z"];
    let (stride, length) = info(&alien_args);
    assert!((stride - ALIEN_STRIDE).abs() < 1e-4 && (length - 24.0).abs() < 1e-3, "alien: {stride} m, {length}");
    // Converted: the cycle frames follow distance / stride.
    for (args, stride) in [(&car_args[..], TAU * WHEEL_RADIUS), (&alien_args[..], ALIEN_STRIDE)] {
        let out = dir.path().join(format!("{}.crowd", args[1]));
        let mut all = vec!["cache", "convert", input.to_str().unwrap(), out.to_str().unwrap()];
        all.extend_from_slice(args);
        let (code, stdout, err) = common::run(&all);
        assert_eq!(code, 0, "{err}");
        assert!(stdout.contains(&format!("stride {stride}")) || stdout.contains("stride"), "{stdout}");
        assert_planted(&throng::cache::read(&out).unwrap(), stride, 24.0, 100);
    }
    // A trajectory table takes the car's stride too.
    let table = common::fixture("tabular/eth_obsmat.txt");
    let (code, out, err) = common::run(&[
        "cache",
        "info",
        table.to_str().unwrap(),
        "--preset",
        "eth-ucy",
        "--rig",
        "car",
        "--cycle",
        "Drive",
        "--rig-file",
        c,
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(out.contains("rig car, cycle Drive, stride 1.88495"), "{out}");
    // No root node and no wheels: exit 2 naming the file and the field, nothing written.
    let none = dir.path().join("none.crowd");
    let (code, _, err) = common::run(&[
        "cache",
        "convert",
        input.to_str().unwrap(),
        none.to_str().unwrap(),
        "--rig",
        "alien",
        "--cycle",
        "Walk",
        "--rig-file",
        s,
        "--rig-forward",
        "-z",
    ]);
    assert_eq!(code, 2, "{err}");
    for want in ["still_alien.glb", "field `cycle`", "cycle `Walk` walks 0 m", "turns no wheel", "root node"] {
        assert!(err.contains(want), "`{want}` missing from: {err}");
    }
    assert!(!none.exists());
    // `--stride` gives the walk its stride, as the message says (the shot's `strides`).
    let given = dir.path().join("given.crowd");
    let (code, _, err) = common::run(&[
        "cache",
        "convert",
        input.to_str().unwrap(),
        given.to_str().unwrap(),
        "--rig",
        "alien",
        "--cycle",
        "Walk",
        "--rig-file",
        s,
        "--stride",
        "0.7",
    ]);
    assert_eq!(code, 0, "{err}");
    assert_planted(&throng::cache::read(&given).unwrap(), 0.7, 24.0, 100);
}
