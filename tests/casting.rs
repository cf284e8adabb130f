//! Casting on the bundled demo shot: uniform heads, height jitter, stability
//! under removal and reordering, determinism, exclusions, posing, export.

mod common;

use std::collections::BTreeSet;

use throng::cache::{self, CacheReader};
use throng::casting::wardrobe::Wardrobes;
use throng::casting::{cast_agent, RigCasting};
use throng::casting::{AgentDress, Lod, ShotCrowd, ShotRig};
use throng::shot::Shot;

use common::demo_shot;

fn load_with(edit: impl FnOnce(&mut Shot, &mut cache::CrowdCache)) -> ShotCrowd {
    let mut shot = Shot::load(&demo_shot()).unwrap();
    let mut crowd = cache::read(&shot.cache.path).unwrap();
    edit(&mut shot, &mut crowd);
    let path = shot.cache.path.clone();
    ShotCrowd::new(shot, CacheReader::from_crowd(path, crowd), None).unwrap()
}

#[test]
fn heads_are_uniform_and_inside_their_box() {
    let crowd = ShotCrowd::load(&demo_shot()).unwrap();
    let mut heads = 0;
    for (id, dress) in crowd.dressing().iter() {
        let AgentDress::Slots(parts) = dress else { continue };
        let cast = crowd.cast(id).unwrap();
        let Some(ShotRig::Slots(rig)) = crowd.rigs().get(&cast.rig) else { panic!("agent {id} dressed in slots") };
        // A part may be several pieces (one per glTF material): check the
        // union of its pieces, as fitted.
        let mut by_slot: std::collections::BTreeMap<usize, (glam::Vec3, glam::Vec3, glam::Affine3A)> =
            Default::default();
        for p in parts {
            let (lo, hi) = crowd.library().meshes[p.mesh as usize].bounds();
            let fit = crowd.dressing().fit(p.fit).slot_from_part;
            // A part turned by its `forward` (whole axes) swaps corners: take both.
            let (p0, p1) = (fit.transform_point3(lo), fit.transform_point3(hi));
            let (a, b) = (p0.min(p1), p0.max(p1));
            let e = by_slot.entry(p.slot as usize).or_insert((a, b, fit));
            e.0 = e.0.min(a);
            e.1 = e.1.max(b);
        }
        for (slot_index, (a, b, fit)) in by_slot {
            let slot = &rig.slots()[slot_index];
            let uniform = cast.slots[slot_index].part.as_ref().unwrap().uniform;
            let eps = 1e-4;
            assert!(
                a.cmpge(slot.proxy_min - eps).all() && b.cmple(slot.proxy_max + eps).all(),
                "agent {id} slot {}",
                slot.name
            );
            if uniform {
                heads += 1;
                let (s, _, _) = fit.to_scale_rotation_translation();
                assert!((s.x - s.y).abs() < 1e-5 && (s.y - s.z).abs() < 1e-5, "agent {id} head scale {s}");
                assert!((a.y - slot.proxy_min.y).abs() < 1e-4, "agent {id}: head rests on the box bottom");
            } else {
                // Body parts fill their box on every axis.
                assert!(
                    (a - slot.proxy_min).abs().max_element() < 1e-4 && (b - slot.proxy_max).abs().max_element() < 1e-4
                );
            }
        }
    }
    assert!(heads > 100, "demo has heads: {heads}");
}

#[test]
fn height_scales_are_uniform_within_range() {
    let shot = Shot::load(&demo_shot()).unwrap();
    let wardrobes = Wardrobes::load(&shot.wardrobes).unwrap();
    let (name, rig) = shot.rigs.iter().next().unwrap();
    let slots: Vec<std::sync::Arc<str>> = vec!["head".into()];
    let rc =
        RigCasting { name: name.as_str().into(), slots: &slots, schemes: &rig.schemes, height_jitter: 0.1, bodies: 0 };
    let n = 10_000;
    let mut h: Vec<f64> =
        (1..=n).map(|id| cast_agent(shot.seed, id, &rc, &wardrobes, &[], false).unwrap().height_scale as f64).collect();
    assert!(h.iter().all(|&x| (0.9..=1.1).contains(&x)));
    h.sort_by(f64::total_cmp);
    // Kolmogorov-Smirnov against U(0.9, 1.1): D < 1.63 / sqrt(n) is alpha = 0.01.
    let d = h
        .iter()
        .enumerate()
        .map(|(i, &x)| {
            let f = (x - 0.9) / 0.2;
            (f - i as f64 / n as f64).abs().max(((i + 1) as f64 / n as f64 - f).abs())
        })
        .fold(0.0, f64::max);
    assert!(d < 1.63 / (n as f64).sqrt(), "KS D = {d}");
    // Never-scaled agents keep 1.0.
    assert_eq!(cast_agent(shot.seed, 5, &rc, &wardrobes, &[], true).unwrap().height_scale, 1.0);
}

#[test]
fn seated_agents_are_never_scaled() {
    let crowd = ShotCrowd::load(&demo_shot()).unwrap();
    let block = crowd.agents_at(crowd.shot().frames.start).unwrap();
    let seated: Vec<_> = block.agents.iter().filter(|a| a.seated()).collect();
    assert!(!seated.is_empty());
    for a in seated {
        assert_eq!(crowd.cast(a.id).unwrap().height_scale, 1.0, "agent {}", a.id);
    }
}

#[test]
fn removal_and_reordering_change_no_other_agent() {
    let base = ShotCrowd::load(&demo_shot()).unwrap();
    let victim = base.casting().ids().nth(7).unwrap();
    let removed = load_with(|_, c| {
        for f in &mut c.frames {
            f.agents.retain(|a| a.id != victim);
        }
    });
    let reordered = load_with(|_, c| {
        for f in &mut c.frames {
            f.agents.reverse();
        }
    });
    assert!(removed.cast(victim).is_none());
    for cast in base.casting().iter() {
        let id = cast.id;
        if id != victim {
            assert_eq!(removed.cast(id), Some(cast), "agent {id} changed when {victim} was removed");
        }
        assert_eq!(reordered.cast(id), Some(cast), "agent {id} changed on reordering");
    }
}

#[test]
fn same_seed_same_cast_other_seed_differs() {
    let a = ShotCrowd::load(&demo_shot()).unwrap();
    let b = ShotCrowd::load(&demo_shot()).unwrap();
    assert_eq!(a.casting(), b.casting());
    let c = load_with(|s, _| s.seed += 1);
    let differ = a.casting().iter().filter(|cast| c.cast(cast.id) != Some(*cast)).count();
    assert!(differ > a.casting().len() / 2, "only {differ} agents changed with another seed");
}

#[test]
fn excluded_parts_and_culled_cycles_never_appear() {
    let base = ShotCrowd::load(&demo_shot()).unwrap();
    // Exclude the most used head.
    let mut counts = std::collections::BTreeMap::new();
    for c in base.casting().iter() {
        for s in &c.slots {
            if let Some(p) = s.part.as_ref().filter(|p| p.uniform) {
                *counts.entry(p.mesh.clone()).or_insert(0) += 1;
            }
        }
    }
    let (top, _) = counts.iter().max_by_key(|(_, n)| **n).unwrap();
    let top = top.clone();
    let culled = "IdleA".to_string();
    let edited = load_with(|s, _| {
        s.exclude_parts.push(top.to_string());
        s.culled_cycles.push(culled.clone());
    });
    for c in edited.casting().iter() {
        assert!(c.slots.iter().all(|s| s.part.as_ref().is_none_or(|p| p.mesh != top)), "agent {} wears {top}", c.id);
    }
    for f in edited.shot().frames.iter() {
        let block = edited.agents_at(f).unwrap();
        let instances = edited.frame_instances(f, |_| Lod::Full).unwrap();
        let ids: BTreeSet<u32> = instances.iter().filter_map(|i| i.agent.get()).collect();
        for a in &block.agents {
            if edited.cycle_name(a) == culled {
                assert!(!ids.contains(&a.id), "agent {} on culled cycle rendered at {f}", a.id);
            }
        }
    }
}

#[test]
fn posed_agents_stand_on_the_floor() {
    let crowd = ShotCrowd::load(&demo_shot()).unwrap();
    let f = crowd.shot().frames.start;
    let block = crowd.agents_at(f).unwrap();
    for a in block.agents.iter().filter(|a| !a.seated()) {
        let mut insts = Vec::new();
        crowd.agent_instances(a, Lod::Proxy, throng::scene::vis::ALL, &mut insts).unwrap();
        let lowest = insts
            .iter()
            .flat_map(|i| {
                (0..8).map(move |c| {
                    let p = glam::Vec3::new((c & 1) as f32, ((c >> 1) & 1) as f32, ((c >> 2) & 1) as f32);
                    i.world_from_object.transform_point3(p).y
                })
            })
            .fold(f32::INFINITY, f32::min);
        assert!(lowest > -0.1 && lowest < 0.25, "agent {}: lowest proxy corner at y = {lowest}", a.id);
    }
}

#[test]
fn export_reopens_with_shared_meshes() {
    let crowd = ShotCrowd::load(&demo_shot()).unwrap();
    let dir = common::tempdir().unwrap();
    let out = dir.path().join("frame.glb");
    let frame = crowd.shot().frames.middle();
    let s = throng::export::export_frame(&crowd, frame, None, &out).unwrap();
    let (doc, _, _) = gltf::import(&out).unwrap();
    let rendered = crowd.agents_at(frame).unwrap().agents.iter().filter(|a| crowd.renders(a)).count();
    assert_eq!(s.agents, rendered);
    let agent_nodes =
        doc.nodes().filter(|n| n.name().is_some_and(|x| x.starts_with("agent_") && !x.contains('/'))).count();
    assert_eq!(agent_nodes, rendered);
    let mesh_nodes = doc.nodes().filter(|n| n.mesh().is_some()).count();
    assert_eq!(mesh_nodes, s.mesh_nodes);
    // Instanced: far fewer meshes than nodes that draw them.
    assert_eq!(doc.meshes().count(), s.meshes);
    assert!(doc.meshes().count() * 5 < mesh_nodes, "{} meshes for {mesh_nodes} nodes", doc.meshes().count());
    assert_eq!(doc.cameras().count(), 1);
    // The demo's four lamp globes (sphere lights) as points; its dome has no glTF form.
    let lights: Vec<_> = doc.lights().expect("KHR_lights_punctual").collect();
    assert_eq!(lights.len(), 4);
    for l in &lights {
        assert!(matches!(l.kind(), gltf::khr_lights_punctual::Kind::Point), "{:?}", l.name());
        // pi r^2 L x 683 cd per W/sr: radius 0.16, radiance 30.
        let want = std::f32::consts::PI * 0.16 * 0.16 * 30.0 * 683.0;
        assert!((l.intensity() - want).abs() < 1e-3 * want, "{} cd", l.intensity());
    }
}

/// Casting runs in parallel: one worker or several, every agent's casting
/// (scheme, parts, materials, height) is the same, byte for byte.
#[test]
fn casting_is_the_same_for_any_thread_count() {
    let cast = |threads: &str| {
        let out = std::process::Command::new(common::bin())
            .args(["cast", demo_shot().to_str().unwrap(), "--json"])
            .env("RAYON_NUM_THREADS", threads)
            .output()
            .unwrap();
        assert!(out.status.success(), "{}", common::text(&out.stderr));
        out.stdout
    };
    let one = cast("1");
    assert!(one.len() > 10_000, "a cast of the whole demo crowd");
    assert!(one == cast("3"), "casting differs between 1 and 3 threads");
}

/// The last layer of a frame poses its agents as it places them: the same
/// scene, instance for instance, as from the frame's shared poses.
#[test]
fn streamed_scene_equals_the_shared_poses_scene() {
    use throng::render::job;
    let crowd = ShotCrowd::load(&demo_shot()).unwrap();
    let manifest = throng::layers::build_layers(&crowd, &Default::default()).unwrap();
    let posed = job::PosedFrame::new(&crowd, 1024).unwrap();
    for layer in ["full", &manifest.comp_order[1]] {
        let shared = job::frame_scene(&crowd, Some(&manifest), layer, &posed).unwrap();
        let streamed = job::streamed_frame_scene(&crowd, Some(&manifest), layer, 1024).unwrap();
        assert!(shared.instances.len() > 100, "layer {layer} has agents");
        assert_eq!(shared.instances.len(), streamed.instances.len(), "layer {layer}");
        for (a, b) in shared.instances.iter().zip(&streamed.instances) {
            assert_eq!(
                (a.mesh, a.material, a.agent, a.part, a.visibility),
                (b.mesh, b.material, b.agent, b.part, b.visibility)
            );
            assert_eq!(a.world_from_object, b.world_from_object);
        }
    }
}

/// `instance_count` (what layer budgets and the render's instance lists are
/// sized by) is what posing places, for every agent of the demo (slot rigs
/// and skinned characters) at both LODs, and each agent is dressed in the
/// kind of its rig.
#[test]
fn instance_counts_are_what_posing_places() {
    let crowd = ShotCrowd::load(&demo_shot()).unwrap();
    let frame = crowd.shot().frames.middle();
    let (mut slots, mut skinned) = (0, 0);
    for a in crowd.agents_at(frame).unwrap().agents.iter().filter(|a| crowd.renders(a)) {
        match (crowd.dressing().get(a.id), crowd.rigs().get(&crowd.cast(a.id).unwrap().rig)) {
            (Some(AgentDress::Slots(_)), Some(ShotRig::Slots(_))) => slots += 1,
            (Some(AgentDress::Skinned(_)), Some(ShotRig::Skinned(_))) => skinned += 1,
            (dress, _) => panic!("agent {} is dressed as {dress:?} for its rig", a.id),
        }
        for lod in [Lod::Full, Lod::Proxy] {
            let mut insts = Vec::new();
            crowd.agent_instances(a, lod, throng::scene::vis::ALL, &mut insts).unwrap();
            assert_eq!(insts.len(), crowd.instance_count(a.id, lod), "agent {} at {lod:?}", a.id);
            assert!(!insts.is_empty(), "agent {} places nothing at {lod:?}", a.id);
        }
    }
    assert!(slots > 0 && skinned > 0, "{slots} slot-rig and {skinned} skinned agents");
}

/// For every walking Kenney alien at the first frame: its face decal's
/// centre minus its head's centre, dotted with its direction of travel
/// (positive: the face looks where it walks).
fn alien_faces(crowd: &ShotCrowd) -> Vec<f32> {
    let f = crowd.shot().frames.start;
    let (now, next) = (crowd.agents_at(f).unwrap(), crowd.agents_at(f + 1).unwrap());
    let lib = crowd.library();
    let centre = |i: &throng::scene::Instance| {
        let (lo, hi) = lib.meshes[i.mesh as usize].bounds();
        i.world_from_object.transform_point3((lo + hi) / 2.0)
    };
    let mut out = Vec::new();
    for a in &now.agents {
        let Some(b) = next.agents.iter().find(|b| b.id == a.id) else { continue };
        let travel = (b.position - a.position) * glam::Vec3::new(1.0, 0.0, 1.0);
        if travel.length() < 0.01 {
            continue;
        }
        let mut insts = Vec::new();
        crowd.agent_instances(a, Lod::Full, throng::scene::vis::ALL, &mut insts).unwrap();
        let named = |suffix: &str| insts.iter().find(|i| lib.meshes[i.mesh as usize].name.ends_with(suffix));
        let (Some(head), Some(eyes)) = (named("#Mesh head/0"), named("#Mesh head/2")) else { continue };
        out.push((centre(eyes) - centre(head)).dot(travel.normalize()));
    }
    out
}

#[test]
fn a_part_modelled_facing_minus_z_is_turned_by_its_forward_key() {
    // The demo wears the original Kenney alien, which faces -Z, with
    // `forward = "-z"`: every walking alien looks where it walks.
    let stock = common::repo_path("wardrobes/kenney_alien.toml");
    let text = std::fs::read_to_string(&stock).unwrap();
    assert!(text.contains("kenney_alien.glb\"") && text.contains("forward = \"-z\""), "{text}");
    let demo = ShotCrowd::load(&demo_shot()).unwrap();
    let faces = alien_faces(&demo);
    assert!(!faces.is_empty(), "the demo has walking aliens");
    assert!(faces.iter().all(|&d| d > 0.05), "faces ahead: {faces:?}");
    // Without the key the original walks backwards.
    let dir = common::tempdir().unwrap();
    let plain = dir.path().join("plain.toml");
    let original = common::repo_path("demo/parts/kenney_alien.glb").display().to_string();
    let unkeyed = text.replace("forward = \"-z\"\n", "").replace("../demo/parts/kenney_alien.glb", &original);
    std::fs::write(&plain, unkeyed).unwrap();
    let without = load_with(|shot, _| {
        for w in &mut shot.wardrobes {
            if w.ends_with("kenney_alien.toml") {
                *w = plain.clone();
            }
        }
    });
    let backwards = alien_faces(&without);
    assert_eq!(backwards.len(), faces.len());
    assert!(backwards.iter().all(|&d| d < -0.05), "faces behind: {backwards:?}");
    // Along up is refused, naming the part.
    let bad =
        text.replacen("forward = \"-z\"", "forward = \"+y\"", 1).replace("../demo/parts/kenney_alien.glb", &original);
    let bad_path = dir.path().join("bad.toml");
    std::fs::write(&bad_path, bad).unwrap();
    let err = Wardrobes::load(&[bad_path]).unwrap_err().to_string();
    assert!(err.contains("bad.toml") && err.contains("parts[0].forward") && err.contains("along up"), "{err}");
}

#[test]
fn face_decals_are_lifted_off_the_head_they_lie_on() {
    // The alien's eyes and mouth (primitives 1 and 2 of `Mesh head`) lie in
    // the head's front plane, z = -0.5; loading lifts them 1/1000 of the
    // head's size (1.46 m across) out of it, towards -Z; the head itself
    // and every other vertex stay as the file gives them.
    let path = common::repo_path("demo/parts/kenney_alien.glb");
    let (doc, buffers, _) = gltf::import(&path).unwrap();
    let head = doc.meshes().find(|m| m.name() == Some("Mesh head")).unwrap();
    let mut assets = throng::scene::gltf::AssetCache::new();
    let loaded = assets.mesh_primitives(&path, "Mesh head").unwrap();
    let lib = assets.library();
    let size = 2.0 * 0.730_769_2;
    for (prim, (mesh, _)) in head.primitives().zip(&loaded) {
        let raw: Vec<glam::Vec3> =
            prim.reader(|b| Some(&buffers[b.index()].0[..])).read_positions().unwrap().map(glam::Vec3::from).collect();
        let lift = if prim.index() == 0 { 0.0 } else { -size * 1e-3 };
        for (got, want) in lib.meshes[*mesh as usize].positions.iter().zip(&raw) {
            let d = *got - *want;
            assert!(
                d.x.abs() < 1e-7 && d.y.abs() < 1e-7 && (d.z - lift).abs() < 1e-6,
                "primitive {}: {d}",
                prim.index()
            );
        }
    }
}
