//! The committed demo assets (made by `cargo run --example make_demo`) open
//! and agree with SPEC and with each other.

mod common;

use std::collections::{BTreeMap, BTreeSet};

const SLOTS: [&str; 11] = [
    "head",
    "torso",
    "hips",
    "upper_arm_l",
    "lower_arm_l",
    "upper_arm_r",
    "lower_arm_r",
    "upper_leg_l",
    "lower_leg_l",
    "upper_leg_r",
    "lower_leg_r",
];
/// Slots of the skinned walker (demo/shot.toml `[rigs.walker] slots`).
const WALKER_SLOTS: [&str; 2] = ["body", "head"];
const CLIPS: [&str; 4] = ["WalkA", "WalkB", "IdleA", "SitA"];
const FPS: f32 = 24.0;

use common::repo_path as crate_path;

fn import(rel: &str) -> (gltf::Document, Vec<gltf::buffer::Data>, Vec<gltf::image::Data>) {
    gltf::import(crate_path(rel)).unwrap_or_else(|e| panic!("{rel}: {e}"))
}

fn extras(node: &gltf::Node) -> Option<serde_json::Value> {
    node.extras().as_ref().map(|r| serde_json::from_str(r.get()).unwrap())
}

#[test]
fn every_demo_glb_imports() {
    let mut count = 0;
    for dir in ["demo/parts", "demo/rigs", "demo/set"] {
        for entry in std::fs::read_dir(crate_path(dir)).unwrap() {
            let path = entry.unwrap().path();
            if path.extension().is_some_and(|e| e == "glb") {
                gltf::import(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
                count += 1;
            }
        }
    }
    assert!(count >= 8, "only {count} glb files");
}

fn mesh_tris(mesh: &gltf::Mesh) -> usize {
    mesh.primitives().map(|p| p.indices().map_or(0, |a| a.count()) / 3).sum()
}

#[test]
fn parts_are_named_meshes_with_normals_and_uvs() {
    let (heads, _, _) = import("demo/parts/heads.glb");
    assert!(heads.meshes().count() >= 8);
    for m in heads.meshes() {
        let tris = mesh_tris(&m);
        assert!((100..=600).contains(&tris), "{:?}: {tris} triangles", m.name());
    }
    let (torsos, _, _) = import("demo/parts/torsos.glb");
    assert_eq!(torsos.meshes().count(), 3);
    let (limbs, _, _) = import("demo/parts/limbs.glb");
    let names: Vec<String> = limbs.meshes().filter_map(|m| m.name().map(str::to_string)).collect();
    for prefix in ["upper_arm_", "lower_arm_", "upper_leg_", "lower_leg_", "hips_"] {
        assert!(names.iter().filter(|n| n.starts_with(prefix)).count() >= 2, "{prefix}");
    }
    for doc in [&heads, &torsos, &limbs] {
        let mut seen = BTreeSet::new();
        for m in doc.meshes() {
            let name = m.name().expect("named mesh").to_string();
            assert!(seen.insert(name.clone()), "duplicate {name}");
            for p in m.primitives() {
                assert!(p.get(&gltf::Semantic::Normals).is_some(), "{name} normals");
                assert!(p.get(&gltf::Semantic::TexCoords(0)).is_some(), "{name} uvs");
            }
        }
    }
}

#[derive(Debug)]
struct Clip {
    frames: f32,
    stride: f32,
}

/// Per rig: clip name -> length in frames and root Z travel.
fn rig_clips(rel: &str) -> BTreeMap<String, Clip> {
    let (doc, buffers, _) = import(rel);
    let root = doc.nodes().find(|n| n.name() == Some("root")).expect("root node");
    let mut out = BTreeMap::new();
    for anim in doc.animations() {
        let mut end = 0.0f32;
        let mut stride = 0.0;
        for ch in anim.channels() {
            let r = ch.reader(|b| Some(&buffers[b.index()]));
            let times: Vec<f32> = r.read_inputs().unwrap().collect();
            end = end.max(*times.last().unwrap());
            if ch.target().node().index() == root.index()
                && ch.target().property() == gltf::animation::Property::Translation
            {
                let v: Vec<[f32; 3]> = match r.read_outputs().unwrap() {
                    gltf::animation::util::ReadOutputs::Translations(t) => t.collect(),
                    _ => unreachable!(),
                };
                // CUBICSPLINE stores (in-tangent, value, out-tangent) per key.
                let cubic = ch.sampler().interpolation() == gltf::animation::Interpolation::CubicSpline;
                let (first, last) = if cubic { (v[1], v[v.len() - 2]) } else { (v[0], v[v.len() - 1]) };
                stride = last[2] - first[2];
            }
        }
        out.insert(anim.name().unwrap().to_string(), Clip { frames: (end * FPS).round(), stride });
    }
    out
}

/// The skinned walker's cycles as the shot plays them (cache cycle ->
/// length in frames and stride), read by throng's own skinning code.
fn walker_cycles() -> (throng::casting::skin::SkinnedRig, BTreeMap<String, Clip>) {
    let shot = throng::shot::Shot::load(&common::demo_shot()).unwrap();
    let r = &shot.rigs["walker"];
    let rig = throng::casting::skin::SkinnedRig::load(&r.file, &r.skin, shot.frames.fps).unwrap();
    let clips = (0..rig.cycles().len())
        .map(|i| (rig.cycles()[i].name.clone(), Clip { frames: rig.cycle_frames(i), stride: rig.cycles()[i].stride }))
        .collect();
    (rig, clips)
}

#[test]
fn walker_is_a_skinned_humanoid() {
    let (doc, buffers, _) = import("demo/rigs/walker.glb");
    let skin = doc.skins().next().expect("a skin");
    let joints: Vec<String> = skin.joints().map(|j| j.name().unwrap().to_string()).collect();
    assert!(joints.len() >= 20, "{joints:?}");
    for name in ["root", "hips", "spine", "chest", "neck", "head"].into_iter().map(str::to_string).chain(
        ["shoulder", "upper_arm", "forearm", "hand", "thigh", "shin", "foot", "toe"]
            .iter()
            .flat_map(|j| [format!("{j}_l"), format!("{j}_r")]),
    ) {
        assert!(joints.contains(&name), "no joint {name}: {joints:?}");
    }
    let ibm = skin.reader(|b| Some(&buffers[b.index()])).read_inverse_bind_matrices().unwrap().count();
    assert_eq!(ibm, joints.len());
    // Each mesh skinned on its own node, weights summing to 1, with normals and a material.
    let mut tris = 0;
    for name in ["body_slim", "body_broad", "head"] {
        let node = doc
            .nodes()
            .find(|n| n.mesh().is_some_and(|m| m.name() == Some(name)))
            .unwrap_or_else(|| panic!("no node draws mesh {name}"));
        assert!(node.skin().is_some(), "{name}");
        let mesh = node.mesh().unwrap();
        assert_eq!(mesh.name(), Some(name));
        for prim in mesh.primitives() {
            assert!(prim.get(&gltf::Semantic::Normals).is_some() && prim.material().index().is_some(), "{name}");
            let r = prim.reader(|b| Some(&buffers[b.index()]));
            for w in r.read_weights(0).unwrap().into_f32() {
                assert!((w.iter().sum::<f32>() - 1.0).abs() < 1e-4, "{name}: weights {w:?}");
            }
        }
        tris += mesh_tris(&mesh);
    }
    assert!(tris >= 5000, "{tris} triangles");

    // As throng plays it: 1.75 m tall, Walk 32 frames over 1.4 m (WalkA and
    // WalkB both play it), Idle 48 frames standing still.
    let (rig, cycles) = walker_cycles();
    assert!((rig.height() - 1.75).abs() < 0.02, "height {}", rig.height());
    assert!(rig.warnings().is_empty(), "{:?}", rig.warnings());
    for (cycle, frames, stride) in [("WalkA", 32.0, 1.4), ("WalkB", 32.0, 1.4), ("IdleA", 48.0, 0.0)] {
        let c = &cycles[cycle];
        assert!((c.frames - frames).abs() < 1e-3 && (c.stride - stride).abs() < 1e-4, "{cycle}: {c:?}");
    }

    // The sim walks the walker at its Walk clip's speed, so feet do not slide.
    let scene = throng::sim::SimScene::load(crate_path("demo/sim/demo.toml")).unwrap();
    let r = scene.rigs.iter().position(|n| n == "walker").unwrap() as u16;
    assert!(scene.rig_files[r as usize].is_none(), "the sim has no file for the skinned walker");
    for (c, cycle) in scene.cycles.iter().enumerate() {
        if let Some(clip) = cycles.get(&cycle.name).filter(|_| cycle.name != "SitA") {
            let t = scene.timing(r, c as u16);
            assert_eq!((t.length, t.stride), (clip.frames, clip.stride), "{}", cycle.name);
        }
    }
}

#[test]
fn rigs_follow_spec() {
    for (rig, height) in [("bipedThinA", 1.75), ("bipedTallB", 2.05)] {
        let rel = format!("demo/rigs/{rig}.glb");
        let (doc, _, _) = import(&rel);
        let top = doc.default_scene().unwrap().nodes().next().unwrap();
        assert_eq!(top.name(), Some(rig));
        assert_eq!(top.transform().matrix(), glam::Mat4::IDENTITY.to_cols_array_2d());
        assert_eq!(top.children().next().unwrap().name(), Some("root"));

        // World-space rest pose: feet on the floor, height about right.
        let mut world = vec![glam::Mat4::IDENTITY; doc.nodes().count()];
        fn walk(n: gltf::Node, parent: glam::Mat4, world: &mut [glam::Mat4]) {
            let m = parent * glam::Mat4::from_cols_array_2d(&n.transform().matrix());
            world[n.index()] = m;
            for c in n.children() {
                walk(c, m, world);
            }
        }
        walk(top.clone(), glam::Mat4::IDENTITY, &mut world);
        let (mut lo, mut hi) = (f32::MAX, f32::MIN);
        let mut slots = BTreeSet::new();
        for node in doc.nodes() {
            let Some(ex) = extras(&node) else { continue };
            let slot = ex["slot"].as_str().unwrap().to_string();
            assert_eq!(node.name(), Some(slot.as_str()));
            let bmin: Vec<f32> =
                ex["proxy_box"]["min"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap() as f32).collect();
            let bmax: Vec<f32> =
                ex["proxy_box"]["max"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap() as f32).collect();
            assert!((0..3).all(|k| bmin[k] < bmax[k]), "{rig} {slot} box");
            let bb = node.mesh().expect("slot mesh").primitives().next().unwrap().bounding_box();
            assert_eq!(
                (bb.min.to_vec(), bb.max.to_vec()),
                (bmin.clone(), bmax.clone()),
                "{rig} {slot} mesh matches proxy_box"
            );
            for corner in [glam::Vec3::from_slice(&bmin), glam::Vec3::from_slice(&bmax)] {
                let y = world[node.index()].transform_point3(corner).y;
                lo = lo.min(y);
                hi = hi.max(y);
            }
            slots.insert(slot);
        }
        assert_eq!(slots, SLOTS.iter().map(|s| s.to_string()).collect());
        assert!(lo.abs() < 1e-4, "{rig}: feet at {lo}");
        assert!((hi - height).abs() < 0.05, "{rig}: height {hi}");

        let clips = rig_clips(&rel);
        assert_eq!(clips.keys().cloned().collect::<BTreeSet<_>>(), CLIPS.iter().map(|s| s.to_string()).collect());
        assert!(clips["WalkA"].stride > 1.0 && clips["WalkB"].stride > clips["WalkA"].stride);
        assert_eq!(clips["IdleA"].stride, 0.0);
        assert_eq!(clips["SitA"].stride, 0.0);
        let modes: BTreeSet<String> = doc
            .animations()
            .flat_map(|a| a.samplers().map(|s| format!("{:?}", s.interpolation())).collect::<Vec<_>>())
            .collect();
        for m in ["Step", "Linear", "CubicSpline"] {
            assert!(modes.contains(m), "{rig}: no {m} sampler");
        }
    }
}

#[test]
fn set_has_benches_camera_lamps_and_shop_windows() {
    let (doc, _, _) = import("demo/set/set.glb");
    let mut benches: Vec<[f32; 3]> = doc
        .nodes()
        .filter(|n| n.name().is_some_and(|s| s.starts_with("bench_")))
        .map(|n| n.transform().decomposed().0)
        .collect();
    benches.sort_by(|a, b| a[0].total_cmp(&b[0]));
    assert_eq!(benches, [[-9.0, 0.0, -4.0], [-3.0, 0.0, -4.0], [3.0, 0.0, -4.0], [9.0, 0.0, -4.0]]);
    let bench = doc.meshes().find(|m| m.name() == Some("bench")).unwrap();
    let bb = bench.primitives().next().unwrap().bounding_box();
    assert_eq!(bb.min, [-1.5, 0.0, -0.25]);
    assert_eq!(bb.max, [1.5, 0.9, 0.25]);
    let cam = doc.nodes().find(|n| n.name() == Some("shotcam")).unwrap();
    assert!(cam.camera().is_some());
    let shot = toml_file("demo/shot.toml");
    let key = &shot["camera"]["keys"][0]["position"];
    let first_key: Vec<f32> = key.as_array().unwrap().iter().map(|v| v.as_float().unwrap() as f32).collect();
    assert_eq!(cam.transform().decomposed().0.to_vec(), first_key, "shotcam sits at the first camera key");
    // The sun is the dome's: a set sun would light the shot twice.
    assert!(doc.nodes().all(|n| n.light().is_none()), "the set carries no lights of its own");
    // Street lamps, each under one of the shot's camera-visible sphere lights.
    let lamps: Vec<[f32; 3]> = doc
        .nodes()
        .filter(|n| n.name().is_some_and(|s| s.starts_with("lamp_")))
        .map(|n| n.transform().decomposed().0)
        .collect();
    let globes = shot["lights"]["sphere"].as_array().expect("[[lights.sphere]] globes");
    assert_eq!(lamps.len(), 4);
    assert_eq!(globes.len(), lamps.len());
    for (lamp, globe) in lamps.iter().zip(globes) {
        let p: Vec<f64> = globe["position"].as_array().unwrap().iter().map(|v| v.as_float().unwrap()).collect();
        assert!((p[0] - lamp[0] as f64).abs() < 1e-6 && p[1] > 3.0 && (p[2] - lamp[2] as f64).abs() < 1.0, "{p:?}");
        assert_eq!(globe["camera_visible"].as_bool(), Some(true));
    }
    // Lit shop windows: emissive, so next-event estimation finds them.
    let shops = doc.meshes().filter(|m| m.name().is_some_and(|s| s.ends_with("_shops"))).collect::<Vec<_>>();
    assert_eq!(shops.len(), 3);
    for m in &shops {
        let e = m.primitives().next().unwrap().material().emissive_factor();
        assert!(e.iter().all(|&c| c > 0.0), "{:?}: emissive {e:?}", m.name());
    }
    let floor = doc.meshes().find(|m| m.name() == Some("floor")).unwrap();
    let mat = floor.primitives().next().unwrap().material();
    assert!((mat.pbr_metallic_roughness().roughness_factor() - 0.2).abs() < 0.05);
    assert_eq!(mat.pbr_metallic_roughness().metallic_factor(), 0.0);
    let bb = floor.primitives().next().unwrap().bounding_box();
    assert_eq!((bb.min, bb.max), ([-40.0, 0.0, -40.0], [40.0, 0.0, 40.0]));
    assert!(doc.meshes().filter(|m| m.name().is_some_and(|s| s.starts_with("building"))).count() >= 6);
}

#[test]
fn cache_crowd_is_a_plausible_crowd() {
    // demo/cache/demo.crowd is the reference simulation's output
    // (demo/sim/demo.toml; tests/sim.rs checks it is up to date).
    let crowd = throng::cache::read(crate_path("demo/cache/demo.crowd")).unwrap();
    let frames: Vec<i32> = crowd.frames.iter().map(|f| f.frame).collect();
    assert_eq!(frames, (1..=48).collect::<Vec<_>>());
    let ids: BTreeSet<u32> = crowd.frames[0].agents.iter().map(|a| a.id).collect();
    assert!((280..=320).contains(&ids.len()), "{} agents", ids.len());
    for f in &crowd.frames {
        assert_eq!(
            f.agents.iter().map(|a| a.id).collect::<BTreeSet<_>>(),
            ids,
            "frame {}: every agent in every frame",
            f.frame
        );
    }
    let mut rigs = crowd.rigs.clone();
    rigs.sort();
    assert_eq!(rigs, ["bipedTallB", "bipedThinA", "walker"]);
    let mut cycles = crowd.cycles.clone();
    cycles.sort();
    assert_eq!(cycles, ["IdleA", "SitA", "WalkA", "WalkB"]);

    // Twelve seated agents on the benches (SPEC "Demo set layout"), still.
    let seated: Vec<_> = crowd.frames[0].agents.iter().filter(|a| a.seated()).collect();
    assert_eq!(seated.len(), 12);
    let mut seats = BTreeSet::new();
    for f in &crowd.frames {
        for a in f.agents.iter().filter(|a| a.seated()) {
            assert_eq!(crowd.cycles[a.cycle as usize], "SitA", "agent {}", a.id);
            assert_eq!((a.position.z, a.position.y, a.heading), (-3.55, 0.0, 0.0), "agent {}", a.id);
            let x = a.position.x;
            assert!([-9.0f32, -3.0, 3.0, 9.0].iter().any(|b| [-1.0f32, 0.0, 1.0].contains(&(x - b))), "seat x {x}");
            seats.insert((x * 10.0) as i32);
        }
    }
    assert_eq!(seats.len(), 12, "one agent per seat");

    // Feet do not slide: a walker's distance per cycle frame is its own rig's
    // stride / cycle length; standers stand and play their cycle at 1 frame per frame.
    let mut clips: BTreeMap<String, BTreeMap<String, Clip>> = ["bipedThinA", "bipedTallB"]
        .iter()
        .map(|r| (r.to_string(), rig_clips(&format!("demo/rigs/{r}.glb"))))
        .collect();
    clips.insert("walker".into(), walker_cycles().1);
    let (mut walked, mut stood) = (BTreeMap::<(String, String), usize>::new(), 0);
    let mut idle = BTreeSet::new();
    for w in crowd.frames.windows(2) {
        for (a, b) in w[0].agents.iter().zip(&w[1].agents) {
            assert_eq!(a.id, b.id);
            assert!((-18.0..=18.0).contains(&b.position.x) && (-30.0..=12.0).contains(&b.position.z), "{b:?}");
            let (rig, cycle) = (&crowd.rigs[b.rig as usize], &crowd.cycles[b.cycle as usize]);
            if cycle == "IdleA" {
                idle.insert(b.id);
            }
            if a.cycle != b.cycle || b.cycle_frame < a.cycle_frame {
                continue; // a cycle ended this frame
            }
            let clip = &clips[rig][cycle];
            let adv = b.cycle_frame - a.cycle_frame;
            let step = (b.position - a.position).length();
            if clip.stride == 0.0 {
                assert_eq!(step, 0.0, "agent {} on {cycle} moved", b.id);
                assert!((adv - 1.0).abs() < 1e-4, "agent {}: {adv}", b.id);
                stood += 1;
            } else {
                assert!((0.89..=1.0001).contains(&adv), "agent {} frame {}: advance {adv}", b.id, w[1].frame);
                let expect = clip.stride / clip.frames;
                assert!(
                    (step / adv - expect).abs() < 1e-4,
                    "agent {} ({rig} {cycle}) frame {}: {step} m per {adv} frames, stride says {expect}",
                    b.id,
                    w[1].frame
                );
                *walked.entry((rig.clone(), cycle.clone())).or_default() += 1;
            }
        }
    }
    assert_eq!(walked.len(), 6, "all three rigs walk both walks: {walked:?}");
    assert!(walked.values().all(|&n| n > 200), "{walked:?}");
    // A quarter of the spawned agents are skinned walkers.
    let walker = crowd.rigs.iter().position(|r| r == "walker").unwrap() as u16;
    let walkers = crowd.frames[0].agents.iter().filter(|a| a.rig == walker).count();
    assert!((50..=100).contains(&walkers), "{walkers} walkers");
    assert!(stood > 1000 && idle.len() >= 10, "{stood} standing agent-frames, {} idlers", idle.len());

    // Nobody overlaps badly (agent radius 0.3: centres 0.6 m apart touch).
    for f in &crowd.frames {
        let a = &f.agents;
        for i in 0..a.len() {
            for j in i + 1..a.len() {
                let d = (a[i].position - a[j].position).length();
                assert!(d >= 0.45, "frame {}: agents {} and {} are {d} m apart", f.frame, a[i].id, a[j].id);
            }
        }
    }
}

fn toml_file(rel: &str) -> toml::Value {
    toml::from_str(&std::fs::read_to_string(crate_path(rel)).unwrap()).unwrap_or_else(|e| panic!("{rel}: {e}"))
}

/// scheme name -> wardrobe; checks every part's file, mesh, slot and materials.
fn check_wardrobe(rel: &str, slots: &[&str], schemes: &mut BTreeMap<String, String>) {
    let w = toml_file(rel);
    assert_eq!(w["version"].as_integer(), Some(1));
    let dir = crate_path(rel).parent().unwrap().to_path_buf();
    let materials: BTreeSet<String> =
        w.get("materials").and_then(|m| m.as_table()).map(|t| t.keys().cloned().collect()).unwrap_or_default();
    for m in w.get("materials").and_then(|m| m.as_table()).into_iter().flatten() {
        if let Some(tex) = m.1.get("base_color_texture").and_then(|t| t.as_str()) {
            assert!(dir.join(tex).is_file(), "{rel}: texture {tex}");
        }
    }
    for (name, scheme) in w["schemes"].as_table().unwrap() {
        schemes.insert(name.clone(), rel.to_string());
        for part in scheme["parts"].as_array().unwrap() {
            let slot = part["slot"].as_str().unwrap();
            assert!(slots.contains(&slot), "{rel} {name}: slot {slot}");
            let file = dir.join(part["file"].as_str().unwrap());
            let (doc, _, _) = gltf::import(&file).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
            let mesh = part["mesh"].as_str().unwrap();
            assert!(doc.meshes().any(|m| m.name() == Some(mesh)), "{rel} {name}: no mesh {mesh}");
            let mats = part["materials"].as_array().unwrap();
            for m in mats {
                let m = m.as_str().unwrap();
                assert!(m == "gltf" || materials.contains(m), "{rel} {name}: material {m}");
            }
            if let Some(w) = part.get("material_weights") {
                assert_eq!(w.as_array().unwrap().len(), mats.len());
            }
        }
    }
}

#[test]
fn wardrobes_and_shot_agree() {
    let mut schemes = BTreeMap::new();
    check_wardrobe("wardrobes/robots.toml", &SLOTS, &mut schemes);
    check_wardrobe("wardrobes/kenney_alien.toml", &SLOTS, &mut schemes);
    check_wardrobe("wardrobes/walkers.toml", &WALKER_SLOTS, &mut schemes);
    let robots = toml_file("wardrobes/robots.toml");
    assert!(robots["materials"].as_table().unwrap().len() >= 8);
    let heads_in = |scheme: &str| -> BTreeSet<String> {
        let s = &robots["schemes"][scheme];
        let excluded: BTreeSet<&str> = s["exclude"].as_array().unwrap().iter().filter_map(|v| v.as_str()).collect();
        s["parts"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|p| p["slot"].as_str() == Some("head"))
            .filter_map(|p| p["mesh"].as_str())
            .filter(|m| !excluded.contains(m))
            .map(str::to_string)
            .collect()
    };
    assert!(heads_in("LowEnd_good_heads").len() < heads_in("HighEnd").len());
    assert!(heads_in("HighEnd").len() >= 8);

    let shot = toml_file("demo/shot.toml");
    assert_eq!(shot["frames"]["start"].as_integer(), Some(1001));
    assert_eq!(shot["frames"]["end"].as_integer(), Some(1048));
    assert_eq!(shot["cache"]["frame_offset"].as_integer(), Some(-1000));
    assert_eq!(shot["cache"]["path"].as_str(), Some("cache/demo.crowd"));
    assert!(crate_path("demo").join(shot["cache"]["path"].as_str().unwrap()).is_file());
    assert!(crate_path("demo").join(shot["set"]["file"].as_str().unwrap()).is_file());
    for w in shot["wardrobes"].as_array().unwrap() {
        assert!(crate_path("demo").join(w.as_str().unwrap()).is_file());
    }
    for (rig, spec) in shot["rigs"].as_table().unwrap() {
        assert!(crate_path("demo").join(spec["file"].as_str().unwrap()).is_file(), "{rig}");
        if rig == "walker" {
            assert_eq!(spec["kind"].as_str(), Some("skinned"));
            let slots: Vec<&str> = spec["slots"].as_array().unwrap().iter().filter_map(|s| s.as_str()).collect();
            assert_eq!(slots, WALKER_SLOTS);
        }
        for scheme in spec["schemes"].as_table().unwrap().keys() {
            assert!(schemes.contains_key(scheme), "{rig}: unknown scheme {scheme}");
        }
    }
    assert_eq!(shot["layers"]["count"].as_integer(), Some(3));
    // Lit by the shared HDRI, copied in with its licence.
    let dome = crate_path("demo").join(shot["lights"]["dome"]["file"].as_str().unwrap());
    let shared = common::shared_asset("hdri/quarry_01_1k.hdr");
    assert_eq!(std::fs::read(&dome).unwrap(), std::fs::read(&shared).unwrap(), "{}", dome.display());
    let source = std::fs::read_to_string(dome.with_file_name("SOURCE.md")).unwrap();
    assert!(source.contains("CC0"), "the HDRI's licence is recorded beside it");
}

/// Nobody walks through a lamp post: the posts stand clear of every agent
/// of every frame of the cache.
#[test]
fn lamp_posts_stand_clear_of_the_crowd() {
    let (doc, _, _) = import("demo/set/set.glb");
    let posts: Vec<[f32; 3]> = doc
        .nodes()
        .filter(|n| n.name().is_some_and(|s| s.starts_with("lamp_")))
        .map(|n| n.transform().decomposed().0)
        .collect();
    assert!(!posts.is_empty());
    let crowd = throng::cache::read(crate_path("demo/cache/demo.crowd")).unwrap();
    let mut nearest = f32::INFINITY;
    for f in &crowd.frames {
        for a in &f.agents {
            for p in &posts {
                nearest = nearest.min(((a.position.x - p[0]).powi(2) + (a.position.z - p[2]).powi(2)).sqrt());
            }
        }
    }
    // Agent radius 0.3 (demo/sim/demo.toml) plus the post's half-width and room.
    assert!(nearest > 1.0, "an agent comes within {nearest} m of a lamp post");
}
