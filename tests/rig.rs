//! The animation evaluator against the Khronos InterpolationTest file (values
//! computed here by hand from its keyframes) and rigs against a hand-made
//! fixture (tests/fixtures/rig_small.gltf, written by make_rig_small.py).

mod common;

use glam::{Quat, Vec3, Vec4};
use throng::casting::rig::{Animated, Channel, Interpolation, Property, Rig};

fn fixture(name: &str) -> String {
    common::fixture(name).display().to_string()
}

fn interpolation_test() -> Animated {
    match Animated::load(fixture("InterpolationTest/InterpolationTest.gltf")) {
        Ok(a) => a,
        Err(e) => panic!("{e}"),
    }
}

/// The only channel of clip `name`.
fn channel<'a>(a: &'a Animated, name: &str) -> &'a Channel {
    let clip = a.clip(name).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!(clip.channels.len(), 1, "{name}");
    &clip.channels[0]
}

fn close3(a: Vec3, b: Vec3, what: &str) {
    assert!(a.abs_diff_eq(b, 1e-5), "{what}: got {a}, expected {b}");
}

/// Same rotation (q and -q are equal rotations).
fn same_rotation(a: Quat, b: Quat, what: &str) {
    assert!(a.dot(b).abs() > 1.0 - 1e-6, "{what}: got {a}, expected {b}");
    assert!((a.length() - 1.0).abs() < 1e-5, "{what}: not normalised: {a}");
}

/// Rotation by `deg` degrees about +Z.
fn zrot(deg: f32) -> Quat {
    let h = deg.to_radians() / 2.0;
    Quat::from_xyzw(0.0, 0.0, h.sin(), h.cos())
}

// Key times of the InterpolationTest clips (from the file's accessors).
const SCALE_T: [f32; 5] = [0.041666668, 0.41666666, 0.875, 1.25, 1.6666666];
const ROT_T: [f32; 5] = [0.0, 0.41666666, 0.875, 1.25, 1.7083334];

#[test]
fn file_has_nine_clips_and_channels_target_the_right_properties() {
    let a = interpolation_test();
    let names: Vec<&str> = a.clips.iter().map(|c| c.name.as_str()).collect();
    assert_eq!(names.len(), 9, "{names:?}");
    for (name, property, interpolation) in [
        ("Step Scale", Property::Scale, Interpolation::Step),
        ("Linear Scale", Property::Scale, Interpolation::Linear),
        ("CubicSpline Scale", Property::Scale, Interpolation::CubicSpline),
        ("Step Rotation", Property::Rotation, Interpolation::Step),
        ("Linear Rotation", Property::Rotation, Interpolation::Linear),
        ("CubicSpline Rotation", Property::Rotation, Interpolation::CubicSpline),
        ("Step Translation", Property::Translation, Interpolation::Step),
        ("Linear Translation", Property::Translation, Interpolation::Linear),
        ("CubicSpline Translation", Property::Translation, Interpolation::CubicSpline),
    ] {
        let ch = channel(&a, name);
        assert_eq!((ch.property, ch.interpolation), (property, interpolation), "{name}");
    }
    // Scale clips start at the first key (1/24 s), not at 0.
    let clip = a.clip("Linear Scale").unwrap_or_else(|e| panic!("{e}"));
    assert!((clip.start - SCALE_T[0]).abs() < 1e-6 && (clip.end - SCALE_T[4]).abs() < 1e-6);
    assert_eq!(a.hierarchy.nodes[channel(&a, "Linear Scale").node].name, "Cube.001");
}

#[test]
fn unknown_clip_lists_the_clips() {
    let a = interpolation_test();
    let err = a.clip("Jump").err().map(|e| e.to_string()).unwrap_or_default();
    assert!(err.contains("Jump") && err.contains("Linear Rotation") && err.contains("InterpolationTest.gltf"), "{err}");
}

#[test]
fn step_scale_holds_previous_key() {
    let a = interpolation_test();
    let ch = channel(&a, "Step Scale");
    // keys: 1, 0.5, 1, 0.5, 1 (uniform)
    for (t, s) in [
        (SCALE_T[0], 1.0),
        (SCALE_T[1], 0.5),
        ((SCALE_T[1] + SCALE_T[2]) / 2.0, 0.5),
        (SCALE_T[2] - 1e-4, 0.5),
        (SCALE_T[2], 1.0),
        (1.0, 1.0),
        (SCALE_T[3] + 0.01, 0.5),
        (0.0, 1.0),  // before the first key: first key
        (10.0, 1.0), // after the last key: last key
    ] {
        close3(ch.sample_vec3(t), Vec3::splat(s), &format!("t={t}"));
    }
}

#[test]
fn linear_scale_interpolates() {
    let a = interpolation_test();
    let ch = channel(&a, "Linear Scale");
    let lerp = |a: f32, b: f32, u: f32| a + (b - a) * u;
    for (i, (from, to)) in [(1.0, 0.5), (0.5, 1.0), (1.0, 0.5), (0.5, 1.0)].into_iter().enumerate() {
        for u in [0.0, 0.25, 0.5, 0.9] {
            let t = SCALE_T[i] + u * (SCALE_T[i + 1] - SCALE_T[i]);
            close3(ch.sample_vec3(t), Vec3::splat(lerp(from, to, u)), &format!("key {i} u={u}"));
        }
    }
    close3(ch.sample_vec3(-1.0), Vec3::ONE, "before first key");
    close3(ch.sample_vec3(SCALE_T[4]), Vec3::ONE, "last key");
}

#[test]
fn cubic_scale_follows_hermite_basis() {
    let a = interpolation_test();
    let ch = channel(&a, "CubicSpline Scale");
    // All tangents are zero, so p(u) = p0 (2u^3 - 3u^2 + 1) + p1 (-2u^3 + 3u^2).
    // At u = 1/4: h00 = 27/32, h01 = 5/32.
    let (h00, h01) = (27.0 / 32.0, 5.0 / 32.0);
    let t = SCALE_T[0] + 0.25 * (SCALE_T[1] - SCALE_T[0]);
    close3(ch.sample_vec3(t), Vec3::splat(1.0 * h00 + 0.5 * h01), "key 0 u=1/4");
    let t = SCALE_T[1] + 0.25 * (SCALE_T[2] - SCALE_T[1]);
    close3(ch.sample_vec3(t), Vec3::splat(0.5 * h00 + 1.0 * h01), "key 1 u=1/4");
    let mid = (SCALE_T[2] + SCALE_T[3]) / 2.0;
    close3(ch.sample_vec3(mid), Vec3::splat(0.75), "midpoint is the average with zero tangents");
    for (i, s) in [1.0, 0.5, 1.0, 0.5, 1.0].into_iter().enumerate() {
        close3(ch.sample_vec3(SCALE_T[i]), Vec3::splat(s), &format!("exact at key {i}"));
    }
}

#[test]
fn step_rotation_holds_previous_key() {
    let a = interpolation_test();
    let ch = channel(&a, "Step Rotation");
    // keys: 0, -45, -90, -135, -180 degrees about Z
    same_rotation(ch.sample_quat(0.2), zrot(0.0), "before key 1");
    same_rotation(ch.sample_quat(ROT_T[1]), zrot(-45.0), "at key 1");
    same_rotation(ch.sample_quat(0.6), zrot(-45.0), "between keys 1 and 2");
    same_rotation(ch.sample_quat(1.5), zrot(-135.0), "between keys 3 and 4");
    same_rotation(ch.sample_quat(3.0), zrot(-180.0), "after the last key");
}

#[test]
fn linear_rotation_slerps() {
    let a = interpolation_test();
    let ch = channel(&a, "Linear Rotation");
    // Slerp between rotations about one axis interpolates the angle.
    for (i, u) in [(0, 0.5), (1, 0.25), (2, 0.5), (3, 0.5), (3, 0.8)] {
        let t = ROT_T[i] + u * (ROT_T[i + 1] - ROT_T[i]);
        let deg = -45.0 * (i as f32 + u);
        same_rotation(ch.sample_quat(t), zrot(deg), &format!("key {i} u={u}"));
    }
    for (i, &t) in ROT_T.iter().enumerate() {
        same_rotation(ch.sample_quat(t), zrot(-45.0 * i as f32), &format!("exact at key {i}"));
    }
}

#[test]
fn linear_rotation_takes_the_short_way() {
    // The second key is stored as -q: the same rotation as -90 degrees about Z.
    // Naive interpolation would swing 270 degrees; the midpoint must be -45.
    let q = zrot(-90.0);
    let ch = Channel {
        node: 0,
        property: Property::Rotation,
        interpolation: Interpolation::Linear,
        times: vec![0.0, 1.0],
        values: vec![Vec4::W, -Vec4::from(q)],
    };
    same_rotation(ch.sample_quat(0.5), zrot(-45.0), "midpoint");
    same_rotation(ch.sample_quat(0.25), zrot(-22.5), "quarter");
}

#[test]
fn cubic_rotation_uses_scaled_tangents_and_normalises() {
    let a = interpolation_test();
    let ch = channel(&a, "CubicSpline Rotation");
    // Keys (in, value, out), xyzw, straight from the file: key 1 and key 2.
    let v1 = Vec4::new(0.0, 0.0, -0.38268346, 0.92387956);
    let out1 = Vec4::new(0.0, 0.0, -0.0478909, 0.99885267);
    let in2 = Vec4::new(0.0, 0.0, -0.035464317, 0.999371);
    let s = std::f32::consts::FRAC_1_SQRT_2;
    let v2 = Vec4::new(0.0, 0.0, -s, s);
    let dt = ROT_T[2] - ROT_T[1];
    let u: f32 = 0.25;
    let (u2, u3) = (u * u, u * u * u);
    let raw = v1 * (2.0 * u3 - 3.0 * u2 + 1.0)
        + out1 * dt * (u3 - 2.0 * u2 + u)
        + v2 * (-2.0 * u3 + 3.0 * u2)
        + in2 * dt * (u3 - u2);
    let expected = Quat::from_vec4(raw.normalize());
    same_rotation(ch.sample_quat(ROT_T[1] + u * dt), expected, "key 1 u=1/4");
    // The tangents matter: the result is not the plain slerp.
    assert!(ch.sample_quat(ROT_T[1] + u * dt).dot(zrot(-45.0 - 45.0 * u)).abs() < 1.0 - 1e-6);
    same_rotation(ch.sample_quat(ROT_T[2]), zrot(-90.0), "exact at key 2");
    same_rotation(ch.sample_quat(-1.0), zrot(0.0), "before the first key");
}

#[test]
fn step_translation_holds_previous_key() {
    let a = interpolation_test();
    let ch = channel(&a, "Step Translation");
    let t = [0.0, 0.45833334, 0.8333333, 1.2916666, 1.7083334];
    let y = [6.665_226, 10.0, 6.0, 10.0, 6.0];
    for i in 0..4 {
        let mid = (t[i] + t[i + 1]) / 2.0;
        close3(ch.sample_vec3(mid), Vec3::new(0.0, y[i], 0.0), &format!("between keys {i} and {}", i + 1));
        close3(ch.sample_vec3(t[i]), Vec3::new(0.0, y[i], 0.0), &format!("at key {i}"));
    }
    close3(ch.sample_vec3(5.0), Vec3::new(0.0, 6.0, 0.0), "after the last key");
}

#[test]
fn linear_translation_interpolates() {
    let a = interpolation_test();
    let ch = channel(&a, "Linear Translation");
    let t = [0.0, 0.41666666, 0.8333333, 1.25, 1.6666666];
    let y = [6.621_015, 10.0, 6.0, 10.0, 6.0];
    let x = -3.2975807;
    for i in 0..4 {
        for u in [0.5, 0.25] {
            let at = t[i] + u * (t[i + 1] - t[i]);
            let expect = y[i] + (y[i + 1] - y[i]) * u;
            close3(ch.sample_vec3(at), Vec3::new(x, expect, 0.0), &format!("key {i} u={u}"));
        }
    }
}

#[test]
fn cubic_translation_follows_hermite_basis() {
    let a = interpolation_test();
    let ch = channel(&a, "CubicSpline Translation");
    let t = [0.0, 0.41666666, 0.8333333, 1.25, 1.6666666];
    let y = [6.640_117, 10.0, 6.0, 10.0, 6.0];
    let x = 3.3051798;
    let (h00, h01) = (27.0 / 32.0, 5.0 / 32.0); // zero tangents, u = 1/4
    for i in 0..4 {
        let at = t[i] + 0.25 * (t[i + 1] - t[i]);
        close3(ch.sample_vec3(at), Vec3::new(x, y[i] * h00 + y[i + 1] * h01, 0.0), &format!("key {i} u=1/4"));
    }
}

// ---- rigs ----

fn small_rig() -> Rig {
    Rig::load(fixture("rig_small.gltf")).unwrap_or_else(|e| panic!("{e}"))
}

#[test]
fn slots_in_node_order_with_proxy_boxes() {
    let rig = small_rig();
    let names: Vec<&str> = rig.slots().iter().map(|s| s.name.as_str()).collect();
    assert_eq!(names, ["hips", "torso", "head"]);
    let [hips, torso, head] = [&rig.slots()[0], &rig.slots()[1], &rig.slots()[2]];
    // proxy_box wins over the mesh bounds (the hips mesh is a smaller box).
    close3(hips.proxy_min, Vec3::new(-0.25, -0.15, -0.12), "hips min");
    close3(hips.proxy_max, Vec3::new(0.25, 0.1, 0.12), "hips max");
    // No proxy_box: the mesh's bounds.
    close3(torso.proxy_min, Vec3::new(-0.2, 0.0, -0.1), "torso min");
    close3(torso.proxy_max, Vec3::new(0.2, 0.5, 0.1), "torso max");
    close3(head.proxy_max, Vec3::new(0.1, 0.25, 0.1), "head max");
    assert_eq!(rig.hierarchy().nodes[head.node].name, "head");
    assert_eq!(rig.hierarchy().nodes[rig.root()].name, "root");
}

#[test]
fn cycle_lengths_and_strides() {
    let rig = small_rig();
    let walk = rig.cycle("WalkA").unwrap_or_else(|e| panic!("{e}"));
    assert!((walk.frames(24.0) - 24.0).abs() < 1e-5);
    assert!((walk.stride() - 1.4).abs() < 1e-6, "stride {}", walk.stride());
    let idle = rig.cycle("IdleA").unwrap_or_else(|e| panic!("{e}"));
    assert!((idle.frames(24.0) - 48.0).abs() < 1e-5);
    assert!((idle.frames(30.0) - 60.0).abs() < 1e-5);
    assert_eq!(idle.stride(), 0.0, "no root channel, no stride");
    let err = rig.cycle("RunA").err().map(|e| e.to_string()).unwrap_or_default();
    assert!(err.contains("RunA") && err.contains("WalkA, IdleA") && err.contains("rig_small.gltf"), "{err}");
}

/// rig_from_slot of slot `name` at a cycle frame.
fn slot_at(rig: &Rig, cycle: &str, frame: f32, slot: &str) -> glam::Affine3A {
    let cycle = rig.cycle(cycle).unwrap_or_else(|e| panic!("{e}"));
    let index = rig.slots().iter().position(|s| s.name == slot).unwrap_or_else(|| panic!("no slot {slot}"));
    let transforms = cycle.sample(frame, 24.0).slot_transforms();
    assert_eq!(transforms.len(), rig.slots().len());
    assert_eq!(transforms[index].0, index);
    transforms[index].1
}

#[test]
fn root_motion_strips_x_and_z_and_keeps_bob() {
    let rig = small_rig();
    // Frame 12 = 0.5 s: root at (0.05, 0.04, 0.7) in the clip.
    let hips = slot_at(&rig, "WalkA", 12.0, "hips");
    close3(hips.translation.into(), Vec3::new(0.0, 0.9 + 0.04, 0.0), "hips at frame 12");
    // Frame 6 = 0.25 s: halfway to the bob.
    let hips = slot_at(&rig, "WalkA", 6.0, "hips");
    close3(hips.translation.into(), Vec3::new(0.0, 0.9 + 0.02, 0.0), "hips at frame 6");
    // The rest pose is stripped too (root rest is at the origin here anyway).
    let rest = rig.rest_pose().slot_transforms();
    close3(rest[2].1.translation.into(), Vec3::new(0.0, 0.9 + 0.1 + 0.55, 0.0), "head at rest");
}

#[test]
fn hierarchy_composes_rotations() {
    let rig = small_rig();
    // STEP: hips turn 30 degrees about Y from 0.5 s to 1.0 s; the head (on the
    // torso, on the hips) turns with them. The head's own CUBICSPLINE
    // rotation is identity at both keys.
    let head = slot_at(&rig, "WalkA", 12.0, "head");
    let (_, rot, pos) = head.to_scale_rotation_translation();
    close3(pos, Vec3::new(0.0, 0.9 + 0.04 + 0.65, 0.0), "head position (Y axis turn keeps it on axis)");
    let head_local =
        rig.cycle("WalkA").map(|c| c.sample(12.0, 24.0).local()[4].rotation).unwrap_or_else(|e| panic!("{e}"));
    same_rotation(rot, Quat::from_rotation_y(30f32.to_radians()) * head_local, "head rotation");
    // The tail hangs 0.2 m behind the hips: after a 30 degree turn it swings in X.
    let pose = rig.cycle("WalkA").map(|c| c.sample(12.0, 24.0)).unwrap_or_else(|e| panic!("{e}"));
    let tail = pose.node_transforms()[5].translation;
    let expect = Quat::from_rotation_y(30f32.to_radians()) * Vec3::new(0.0, 0.0, -0.2) + Vec3::new(0.0, 0.94, 0.0);
    close3(tail.into(), expect, "tail");
}

#[test]
fn cubic_channel_in_rig_matches_hermite() {
    let rig = small_rig();
    // Head: identity at t=0 and t=1, out-tangent (0, 0.5, 0, 0) at key 0, dt = 1.
    // At u = 0.25: h00 + h01 = 1 for w, h10 = u^3 - 2u^2 + u = 9/64 for y.
    let pose = rig.cycle("WalkA").map(|c| c.sample(6.0, 24.0)).unwrap_or_else(|e| panic!("{e}"));
    let expected = Quat::from_xyzw(0.0, 0.5 * 9.0 / 64.0, 0.0, 1.0).normalize();
    same_rotation(pose.local()[4].rotation, expected, "head at frame 6");
}

#[test]
fn cycles_loop() {
    let rig = small_rig();
    let walk = rig.cycle("WalkA").unwrap_or_else(|e| panic!("{e}"));
    let at = |f: f32| walk.sample(f, 24.0).slot_transforms();
    for (a, b) in [(5.5, 29.5), (5.5, -18.5), (0.0, 24.0), (0.0, 48.0), (23.0, -1.0)] {
        for ((_, x), (_, y)) in at(a).into_iter().zip(at(b)) {
            assert!(x.abs_diff_eq(y, 1e-5), "frame {a} vs {b}: {x:?} vs {y:?}");
        }
    }
    assert!((walk.time(30.0, 24.0) - 0.25).abs() < 1e-6);
    assert!((walk.time(-6.0, 24.0) - 0.75).abs() < 1e-6);
    // Fractional frames interpolate: halfway between frames 6 and 7.
    let mid = at(6.5)[0].1.translation.y;
    let (lo, hi) = (at(6.0)[0].1.translation.y, at(7.0)[0].1.translation.y);
    assert!((mid - (lo + hi) / 2.0).abs() < 1e-6);
}

#[test]
fn non_rig_files_are_rejected_with_a_reason() {
    let err =
        Rig::load(fixture("InterpolationTest/InterpolationTest.gltf")).err().map(|e| e.to_string()).unwrap_or_default();
    assert!(err.contains("root"), "{err}");
    let err = Rig::load(fixture("missing.glb")).err().map(|e| e.to_string()).unwrap_or_default();
    assert!(err.contains("missing.glb"), "{err}");
}

// ---- malformed rigs: errors that name the file and the thing, never panics ----

/// rig_small.gltf with `edit` applied to its JSON, written to a temp dir.
fn broken_rig(edit: impl FnOnce(&mut serde_json::Value)) -> String {
    let text = std::fs::read_to_string(fixture("rig_small.gltf")).unwrap_or_else(|e| panic!("{e}"));
    let mut json: serde_json::Value = serde_json::from_str(&text).unwrap_or_else(|e| panic!("{e}"));
    edit(&mut json);
    let dir = common::tempdir().unwrap_or_else(|e| panic!("{e}"));
    let path = dir.path().join("broken_rig.gltf");
    std::fs::write(&path, json.to_string()).unwrap_or_else(|e| panic!("{e}"));
    let err = match Rig::load(&path) {
        Ok(_) => String::from("loaded"),
        Err(e) => e.to_string(),
    };
    assert!(err.contains("broken_rig.gltf"), "names the file: {err}");
    err
}

#[test]
fn malformed_animation_data_is_an_error() {
    // Sampler input pointing at a VEC3 accessor.
    let err = broken_rig(|j| {
        j["animations"][0]["samplers"][0]["input"] = j["animations"][0]["samplers"][0]["output"].clone()
    });
    assert!(err.contains("WalkA") && err.contains("root") && err.contains("Scalar"), "{err}");
    // Output count that no longer matches the keys (and runs past its view).
    let err = broken_rig(|j| {
        let out = j["animations"][0]["samplers"][1]["output"].as_u64().unwrap_or(0) as usize;
        j["accessors"][out]["count"] = 1000.into();
    });
    assert!(err.contains("WalkA") && err.contains("hips") && err.contains("do not fit"), "{err}");
    // A huge count must not overflow.
    let err = broken_rig(|j| {
        let out = j["animations"][0]["samplers"][0]["output"].as_u64().unwrap_or(0) as usize;
        j["accessors"][out]["count"] = (u64::MAX / 2).into();
    });
    assert!(err.contains("WalkA"), "{err}");
    // Fewer outputs than keys.
    let err = broken_rig(|j| {
        let out = j["animations"][0]["samplers"][0]["output"].as_u64().unwrap_or(0) as usize;
        j["accessors"][out]["count"] = 2.into();
    });
    assert!(err.contains("2 output values for 3 keys"), "{err}");
    // A byte stride smaller than the element.
    let err = broken_rig(|j| {
        let out = j["animations"][0]["samplers"][0]["output"].as_u64().unwrap_or(0) as usize;
        let view = j["accessors"][out]["bufferView"].as_u64().unwrap_or(0) as usize;
        j["bufferViews"][view]["byteStride"] = 4.into();
    });
    assert!(err.contains("stride"), "{err}");
    // A channel targeting a node past the end, or no known property: gltf's
    // validation leaves channel targets unchecked and its accessors unwrap
    // them (found by the rig_skin fuzzer, docs/fuzzing.md).
    let err = broken_rig(|j| j["animations"][0]["channels"][0]["target"]["node"] = 999.into());
    assert!(err.contains("animation `WalkA` channel 0 targets node 999, but the file has"), "{err}");
    let err = broken_rig(|j| j["animations"][0]["channels"][1]["target"]["path"] = "rotatio".into());
    assert!(err.contains("animation `WalkA` channel 1 targets no known property"), "{err}");
}

#[test]
fn malformed_slots_are_errors() {
    let err = broken_rig(|j| j["nodes"][4]["extras"]["proxy_box"]["min"] = serde_json::json!([0, 0]));
    assert!(err.contains("`head`") && err.contains("proxy_box"), "{err}");
    let err = broken_rig(|j| j["nodes"][4]["extras"]["proxy_box"]["min"] = serde_json::json!([1, 1, 1]));
    assert!(err.contains("exceeds"), "{err}");
    let err = broken_rig(|j| j["nodes"][4]["extras"]["slot"] = "torso".into());
    assert!(err.contains("`torso`") && err.contains("more than one"), "{err}");
    let err = broken_rig(|j| j["nodes"][4]["extras"] = serde_json::json!({"slot": 3}));
    assert!(err.contains("must be a string"), "{err}");
    let err = broken_rig(|j| j["nodes"][5]["extras"] = serde_json::json!({"slot": "tail"}));
    assert!(err.contains("tail") && err.contains("neither"), "{err}");
    let err = broken_rig(|j| j["nodes"][1]["name"] = "base".into());
    assert!(err.contains("`root`"), "{err}");
    // A cycle in the hierarchy (head -> rigSmall).
    let err = broken_rig(|j| j["nodes"][4]["children"] = serde_json::json!([0]));
    assert!(err.contains("cycle") || err.contains("ancestor") || err.contains("parent"), "{err}");
}

#[test]
fn a_proxy_box_too_large_for_any_part_is_refused_naming_the_node() {
    let dir = common::tempdir().unwrap();
    let text = std::fs::read_to_string(fixture("rig_small.gltf")).unwrap();
    let huge = text.replacen("0.25,\n      0.1,\n      0.12", "1e38,\n      0.1,\n      0.12", 1);
    assert_ne!(huge, text, "the fixture's hips proxy_box max");
    let path = dir.path().join("huge.gltf");
    std::fs::write(&path, huge).unwrap();
    let err = Rig::load(&path).map(|_| ()).unwrap_err().to_string();
    assert!(err.contains("huge.gltf") && err.contains("proxy_box") && err.contains("file units"), "{err}");
}

#[test]
fn a_proxy_box_far_larger_than_the_rest_of_its_rig_is_named() {
    let rig = Rig::load(fixture("rig_small.gltf")).unwrap();
    assert!(rig.oversized_slots().is_empty(), "the fixture's boxes are of a size");
    // The hips box 30 m wide: legal (it is under the refusal bound), surprising.
    let dir = common::tempdir().unwrap();
    let text = std::fs::read_to_string(fixture("rig_small.gltf")).unwrap();
    let wide = text.replacen("0.25,\n      0.1,\n      0.12", "30.0,\n      0.1,\n      0.12", 1);
    let path = dir.path().join("wide.gltf");
    std::fs::write(&path, wide).unwrap();
    let rig = Rig::load(&path).unwrap();
    let found: Vec<(&str, f32)> = rig.oversized_slots().iter().map(|(s, side, _)| (s.name.as_str(), *side)).collect();
    assert_eq!(found.len(), 1, "{found:?}");
    assert_eq!(found[0].0, "hips");
    assert!((found[0].1 - 30.25).abs() < 1e-3, "side {}", found[0].1);
}
