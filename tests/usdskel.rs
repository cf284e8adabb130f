//! UsdSkel crowds (docs/usd.md, "UsdSkel crowds"): crowds usd-core writes
//! in the shapes Houdini and Golaem document (tests/fixtures/usd, made by
//! make_skel_crowds.py) read as a cache and posed as their animations say:
//! every joint's world position against usd-core's own UsdSkel evaluation
//! (skel_expected.json); agents holding the same samples share poses; the
//! crowd renders with botinfo; bad input refused with file, prim, attribute
//! and frame, exit 2.

mod common;

use std::path::{Path, PathBuf};

use common::{fixture, run};
use glam::{Affine3A, Quat, Vec3};
use throng::casting::skin::SkinnedRig;
use throng::shot::SkinOptions;

/// usd-core's joint world positions: file -> agent prim -> frame -> joints.
fn expected(file: &str) -> serde_json::Map<String, serde_json::Value> {
    let text = std::fs::read_to_string(fixture("usd/skel_expected.json")).unwrap();
    let all: serde_json::Value = serde_json::from_str(&text).unwrap();
    all[file].as_object().unwrap().clone()
}

/// Every joint of every agent at every frame, as throng poses it (the
/// agent's place and heading from the cache, its joints from the rig at the
/// step its cycle frame names), against usd-core's.
fn joints_match_usd_core(file: &str) {
    joints_match_usd_core_with(file, &[None], 24.0);
}

/// [`joints_match_usd_core`] with the cache's rig `k` loaded with `root =
/// roots[k]`, for a shot at `fps`.
fn joints_match_usd_core_with(file: &str, roots: &[Option<&str>], fps: f32) {
    let path = fixture(&format!("usd/{file}"));
    let crowd = throng::cache::read(&path).unwrap();
    assert_eq!(crowd.rigs.len(), roots.len(), "{file}: {:?}", crowd.rigs);
    let rigs: Vec<SkinnedRig> = (roots.iter())
        .map(|r| SkinOptions { root: r.map(str::to_string), ..SkinOptions::default() })
        .map(|options| SkinnedRig::load(&path, &options, fps).unwrap())
        .collect();
    let want = expected(file);
    // Agents in prim order are agents in x order (make_skel_crowds.py: agent i at x = 1 + 2i + ...).
    let mut prims: Vec<&String> = want.keys().collect();
    prims.sort();
    assert_eq!(crowd.frames.len(), 8);
    let mut worst = 0.0f32;
    for block in &crowd.frames {
        let mut agents = block.agents.clone();
        agents.sort_by(|a, b| a.position.x.total_cmp(&b.position.x));
        assert_eq!(agents.len(), prims.len());
        for (a, prim) in agents.iter().zip(&prims) {
            let rig = &rigs[a.rig as usize];
            let cycle = rig.cycle_index(&crowd.cycles[a.cycle as usize]).unwrap();
            // Pose steps are chosen for pose_error_max, a whole number a frame
            // here: a still frame is a step, its exact pose.
            let (steps, frames) = (rig.cycles()[cycle].steps, rig.cycle_frames(cycle));
            let per_frame = steps as f32 / frames;
            assert!((per_frame - per_frame.round()).abs() < 1e-4, "{steps} steps over {frames} frames");
            let per_frame = per_frame.round();
            let joints = rig.step_joints(cycle, (a.cycle_frame * per_frame).round() as u32);
            let world_from_agent = Affine3A::from_rotation_translation(Quat::from_rotation_y(a.heading), a.position);
            let frame = &want[*prim]["frames"][block.frame.to_string()];
            for (j, w) in frame.as_array().unwrap().iter().enumerate() {
                let w: Vec<f32> = w.as_array().unwrap().iter().map(|x| x.as_f64().unwrap() as f32).collect();
                let got = (world_from_agent * joints[j]).translation;
                let d = Vec3::from(got).distance(Vec3::new(w[0], w[1], w[2]));
                assert!(d < 1e-4, "{file} {prim} frame {} joint {j}: throng {got:?}, usd-core {w:?}", block.frame);
                worst = worst.max(d);
            }
        }
    }
    assert!(worst > 0.0 || prims.is_empty(), "compared nothing");
}

#[test]
fn houdini_shaped_agents_move_as_usd_core_evaluates_them() {
    joints_match_usd_core("skel_crowd.usda");
}

#[test]
fn a_shot_at_another_fps_than_the_stage_still_plays_each_time_code_at_its_frame() {
    // The fixtures' timeCodesPerSecond is 24: a 25 or 30 fps shot's frame f is still time code f.
    for fps in [25.0, 30.0] {
        joints_match_usd_core_with("skel_crowd.usda", &[None], fps);
    }
}

#[test]
fn instanced_prototypes_with_subset_animations_move_as_usd_core_evaluates_them() {
    joints_match_usd_core("skel_instanced.usda");
}

#[test]
fn a_skel_crowd_is_a_cache_with_documented_ids_and_one_cycle_per_distinct_animation() {
    let crowd = throng::cache::read(fixture("usd/skel_crowd.usda")).unwrap();
    assert_eq!(crowd.rigs, ["bipedThinA"], "the import's rig when the SkelRoot names none");
    assert_eq!(crowd.cycles, ["/Crowd/agent_0/Skel/Anim", "/Crowd/agent_1/Skel/Anim", "/Crowd/agent_2/Skel/Anim"]);
    let ids: Vec<u32> = crowd.frames[0].agents.iter().map(|a| a.id).collect();
    assert!(ids.contains(&7), "agent_1 carries primvars:throng:agentId = 7: {ids:?}");
    // The others' ids come from their prim paths: the same on every read.
    let again = throng::cache::read(fixture("usd/skel_crowd.usda")).unwrap();
    assert_eq!(again, crowd);
    // Cycle frame 1 at the animation's first sample (the clip holds it a frame early).
    assert_eq!(crowd.frames[0].frame, 1001);
    assert!(crowd.frames[0].agents.iter().all(|a| a.cycle_frame == 1.0));

    let inst = throng::cache::read(fixture("usd/skel_instanced.usda")).unwrap();
    // anim_2 holds anim_0's samples: one cycle, named by the first.
    assert_eq!(inst.cycles, ["/Crowd/Anims/anim_0", "/Crowd/Anims/anim_1"]);
}

/// A copy of `shot.toml` and its crowd in `dir`, the crowd's text edited by `edit`.
fn edited_shot(dir: &Path, crowd: &str, edit: impl Fn(&str) -> String) -> (PathBuf, PathBuf) {
    let text = std::fs::read_to_string(fixture(&format!("usd/{crowd}"))).unwrap();
    let usd = dir.join("skel_crowd.usda");
    std::fs::write(&usd, edit(&text)).unwrap();
    let shot = dir.join("shot.toml");
    std::fs::copy(fixture("usd/skel_shot.toml"), &shot).unwrap();
    (shot, usd)
}

#[test]
fn the_crowd_renders_with_its_own_character_and_botinfo() {
    let dir = common::tempdir().unwrap();
    let (shot, _) = edited_shot(dir.path(), "skel_crowd.usda", str::to_string);
    let out = dir.path().join("r");
    // Motion-blurred with the shutter centred on the crowd's first and last
    // frames: the clip's held ends keep both in the animation.
    let args = ["render", shot.to_str().unwrap(), "--layer", "full", "--frames", "1001,1008", "--spp", "1"];
    let more = ["--shutter", "-0.25,0.25", "--resolution", "96x54", "--out", out.to_str().unwrap()];
    let (code, _, err) = run(&[&args[..], &more[..]].concat());
    assert_eq!(code, 0, "render of the UsdSkel crowd failed: {err}");
    let crowd = throng::cache::read(fixture("usd/skel_crowd.usda")).unwrap();
    for f in [1001, 1008] {
        let (film, _) = throng::render::exr::read_layer(&out.join(format!("full/skel.full.{f}.exr"))).unwrap();
        let mut seen: Vec<u32> = film.agent_id.iter().filter_map(|&i| i.checked_sub(1)).collect();
        seen.sort_unstable();
        seen.dedup();
        let ids: Vec<u32> = crowd.frames[0].agents.iter().map(|a| a.id).collect();
        assert_eq!(seen, ids, "frame {f}: every agent is in the picture");
        let moving = (film.agent_id.iter().zip(&film.motion)).filter(|(&i, m)| i > 0 && (m[0] != 0.0 || m[1] != 0.0));
        assert!(moving.count() > 0, "frame {f}: the agents' pixels carry motion");
    }
    // The Cryptomatte manifest names every agent (`agent_<id>`, docs/render.md).
    let mattes = throng::render::exr::mattes::read(&out.join("full/skel.full.1008.exr")).unwrap();
    let agents = mattes.iter().find(|m| m.name == throng::render::cryptomatte::AGENT_MATTE).expect("an agent matte");
    for a in &crowd.frames[0].agents {
        let name = throng::render::cryptomatte::agent_name(a.id);
        assert!(agents.manifest.contains_key(&name), "the manifest names {name}: {:?}", agents.manifest.keys());
    }
    // botinfo of every agent: its id, SkelRoot, Skeleton, animation and time code.
    let ids: Vec<String> = crowd.frames[0].agents.iter().map(|a| a.id.to_string()).collect();
    let mut args = vec!["botinfo", shot.to_str().unwrap()];
    args.extend(ids.iter().map(String::as_str));
    args.extend(["--frame", "1008", "--json"]);
    let (code, stdout, err) = run(&args);
    assert_eq!(code, 0, "{err}");
    let json: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    let rows = json.as_array().or_else(|| json["agents"].as_array()).expect("one row per agent");
    assert_eq!(rows.len(), 3, "{stdout}");
    for row in rows {
        let id = row["id"].as_u64().unwrap();
        let usd = &row["usd"];
        let prim = usd["prim"].as_str().unwrap();
        // make_skel_crowds.py: agent_1 carries primvars:throng:agentId 7; the others' ids hash their paths.
        assert_eq!(id == 7, prim == "/Crowd/agent_1", "{row}");
        assert_eq!(usd["skeleton"], format!("{prim}/Skel").as_str(), "{row}");
        assert_eq!(usd["animation"], format!("{prim}/Skel/Anim").as_str(), "{row}");
        assert_eq!(usd["time_code"], 1008, "{row}");
        assert_eq!(row["shot_frame"], 1008, "{row}");
    }
}

#[test]
fn a_farm_plan_of_a_skel_shot_renders_its_tasks() {
    let dir = common::tempdir().unwrap();
    let (shot, _) = edited_shot(dir.path(), "skel_crowd.usda", str::to_string);
    let farm = dir.path().join("farm");
    let args = ["farm", "plan", shot.to_str().unwrap(), "--frames", "1001-1002", "--spp", "1"];
    let more = ["--resolution", "48x27", "--out", farm.to_str().unwrap()];
    let (code, out, err) = run(&[&args[..], &more[..]].concat());
    assert_eq!(code, 0, "farm plan of the UsdSkel shot failed: {out}{err}");
    let plan = farm.join("plan.json");
    let (code, out, err) = run(&["farm", "submit", plan.to_str().unwrap(), "--engine", "local", "--workers", "1"]);
    assert_eq!(code, 0, "the plan's tasks failed: {out}{err}");
    let crowd = throng::cache::read(fixture("usd/skel_crowd.usda")).unwrap();
    let mut ids: Vec<u32> = crowd.frames[0].agents.iter().map(|a| a.id).collect();
    ids.sort_unstable();
    let mut seen = std::collections::BTreeSet::new();
    let mut exrs = 0;
    for layer in std::fs::read_dir(farm.join("render")).unwrap() {
        for file in std::fs::read_dir(layer.unwrap().path()).unwrap() {
            let path = file.unwrap().path();
            if path.extension().is_some_and(|e| e == "exr") && !path.to_string_lossy().contains(".comp.") {
                let (film, _) = throng::render::exr::read_layer(&path).unwrap();
                seen.extend(film.agent_id.iter().filter_map(|&i| i.checked_sub(1)));
                exrs += 1;
            }
        }
    }
    assert!(exrs >= 2, "a layer file per frame at least: {exrs}");
    assert_eq!(seen.into_iter().collect::<Vec<_>>(), ids, "the farm's layers hold every agent");
    assert_eq!(run(&["farm", "status", plan.to_str().unwrap()]).0, 0, "every task done");
}

#[test]
fn throngs_usd_export_of_a_skel_shot_reads_back_as_the_same_crowd() {
    let dir = common::tempdir().unwrap();
    let (shot, usd) = edited_shot(dir.path(), "skel_crowd.usda", str::to_string);
    let out = dir.path().join("export.usda");
    let args = ["export", shot.to_str().unwrap(), "--format", "usd", "--frames", "1001-1008"];
    let (code, _, err) = run(&[&args[..], &["--out", out.to_str().unwrap()][..]].concat());
    assert_eq!(code, 0, "export of the UsdSkel shot failed: {err}");
    let back = throng::cache::read(&out).unwrap();
    let crowd = throng::cache::read(&usd).unwrap();
    assert_eq!(back.frames.len(), crowd.frames.len());
    for (b, c) in back.frames.iter().zip(&crowd.frames) {
        assert_eq!(b.frame, c.frame);
        let ids = |f: &throng::cache::FrameBlock| f.agents.iter().map(|a| a.id).collect::<Vec<_>>();
        assert_eq!(ids(b), ids(c), "frame {}: the same agents", b.frame);
        for (x, y) in b.agents.iter().zip(&c.agents) {
            assert!(x.position.distance(y.position) < 1e-4, "frame {} agent {}: {x:?} vs {y:?}", b.frame, x.id);
            let turn = (x.heading - y.heading).rem_euclid(std::f32::consts::TAU);
            assert!(turn.min(std::f32::consts::TAU - turn) < 1e-4, "frame {} agent {}: heading", b.frame, x.id);
        }
    }
}

#[test]
fn agents_on_the_same_samples_share_posed_meshes() {
    for (file, distinct) in [("skel_crowd.usda", 3), ("skel_instanced.usda", 2)] {
        let dir = common::tempdir().unwrap();
        let (shot, _) = edited_shot(dir.path(), file, str::to_string);
        let crowd = throng::casting::ShotCrowd::load(&shot).unwrap();
        // One mesh, 8 frames, one step a frame; the clip's held end poses are posed only if played.
        assert_eq!(crowd.poses().skins().mesh_count(), distinct * 8, "{file}");
    }
}

/// `throng cast` on the shot over an edited crowd: exit 2, naming what `needles` say.
fn refused(edit: impl Fn(&str) -> String, needles: &[&str]) {
    let dir = common::tempdir().unwrap();
    let (shot, _) = edited_shot(dir.path(), "skel_crowd.usda", edit);
    let (code, _, err) = run(&["cast", shot.to_str().unwrap()]);
    assert_eq!(code, 2, "not refused: {err}");
    assert!(err.contains("skel_crowd.usda"), "names the file: {err}");
    for n in needles {
        assert!(err.contains(n), "names {n}: {err}");
    }
    assert!(!err.contains("panicked"), "{err}");
}

const ANIM_JOINTS: &str =
    "uniform token[] joints = [\"Hips\", \"Hips/Spine\", \"Hips/Spine/Head\", \"Hips/Leg\"]\n                quatf[]";

#[test]
fn an_animation_of_joints_the_skeleton_lacks_is_refused() {
    refused(
        |t| t.replacen(ANIM_JOINTS, &ANIM_JOINTS.replace("Hips/Leg", "Hips/Tail"), 1),
        &["/Crowd/agent_0/Skel/Anim.joints", "Hips/Tail"],
    );
}

#[test]
fn a_skeleton_without_bind_transforms_is_refused() {
    refused(
        |t| {
            let at = t.find("uniform matrix4d[] bindTransforms").unwrap();
            let end = at + t[at..].find('\n').unwrap();
            format!("{}{}", &t[..at], &t[end..])
        },
        &["/Crowd/agent_0/Skel.bindTransforms"],
    );
}

#[test]
fn joint_indices_out_of_range_are_refused() {
    refused(
        |t| t.replacen("primvars:skel:jointIndices = [3, 3,", "primvars:skel:jointIndices = [9, 3,", 1),
        &["/Crowd/agent_0/Body.primvars:skel:jointIndices", "joint 9"],
    );
}

#[test]
fn a_non_finite_joint_transform_is_refused_naming_the_frame() {
    refused(
        |t| t.replacen("1001: [(0, 0.9, 0), (0, 0.4, 0)", "1001: [(0, 1e39, 0), (0, 0.4, 0)", 1),
        &["/Crowd/agent_0/Skel/Anim", "frame 1001"],
    );
}

#[test]
fn time_samples_short_of_the_crowd_are_refused_naming_the_frame() {
    refused(|t| t.replacen("endTimeCode = 1008", "endTimeCode = 1010", 1), &["/Crowd/agent_0.xformOp:", "1010"]);
}

#[test]
fn weights_that_do_not_sum_to_one_are_renormalised_with_a_warning() {
    let dir = common::tempdir().unwrap();
    let (_, usd) = edited_shot(dir.path(), "skel_crowd.usda", |t| {
        t.replacen("primvars:skel:jointWeights = [1, 0,", "primvars:skel:jointWeights = [0.5, 0,", 1)
    });
    let rig = SkinnedRig::load(&usd, &SkinOptions::default(), 24.0).unwrap();
    let w = rig.warnings().join("\n");
    assert!(w.contains("/Crowd/agent_0/Body.primvars:skel:jointWeights") && w.contains("renormalised"), "{w}");
    let piece = rig.piece(0);
    assert!(piece.influences.iter().all(|inf| (inf.iter().map(|i| i.1).sum::<f32>() - 1.0).abs() < 1e-6));
}

#[test]
fn two_agent_types_in_one_file_are_two_characters_each_moving_as_usd_core_says() {
    let path = fixture("usd/skel_two_types.usda");
    let crowd = throng::cache::read(&path).unwrap();
    // The first character is the import's rig, the second that name with _2.
    assert_eq!(crowd.rigs, ["bipedThinA", "bipedThinA_2"]);
    let rig_of = |x: f32| crowd.frames[0].agents.iter().find(|a| (a.position.x - x).abs() < 0.5).unwrap().rig;
    // make_skel_crowds.py: agent i at x = 1 + 2i; even agents walkers, odd ones soldiers.
    assert_eq!([1.0, 3.0, 5.0, 7.0].map(rig_of), [0, 1, 0, 1]);
    // Each rig is its own character, chosen by `root`: its skeleton, mesh and material.
    joints_match_usd_core_with("skel_two_types.usda", &[None, Some("/Crowd/agent_1")], 24.0);
    let soldier = SkinOptions { root: Some("/Crowd/agent_3".into()), ..SkinOptions::default() };
    for (options, joints) in [(SkinOptions::default(), 4), (soldier, 5)] {
        let rig = SkinnedRig::load(&path, &options, 24.0).unwrap();
        // The soldier's top ring rides its arm, joint 4, which the walker lacks.
        let top = (rig.piece(0).influences.iter().flatten()).filter(|i| i.1 > 0.0).map(|i| i.0).max().unwrap();
        assert_eq!(usize::from(top) + 1, joints, "{:?}: highest joint a vertex rides", options.root);
    }
    let bad = SkinOptions { root: Some("/Crowd/Anims".into()), ..SkinOptions::default() };
    let err = SkinnedRig::load(&path, &bad, 24.0).unwrap_err().to_string();
    assert!(err.contains("root") && err.contains("/Crowd/agent_0, /Crowd/agent_1"), "{err}");
}

#[test]
fn a_shot_over_two_agent_types_renders_every_agent() {
    let dir = common::tempdir().unwrap();
    let (shot, _) = edited_shot(dir.path(), "skel_two_types.usda", str::to_string);
    let text = std::fs::read_to_string(&shot).unwrap();
    let more = "\n[rigs.crowd_2]\nfile = \"skel_crowd.usda\"\nroot = \"/Crowd/agent_1\"\n";
    std::fs::write(&shot, text.replace("[camera]", &format!("{more}\n[camera]"))).unwrap();
    let out = dir.path().join("r");
    let args = ["render", shot.to_str().unwrap(), "--layer", "full", "--frames", "1001", "--spp", "1"];
    let (code, _, err) = run(&[&args[..], &["--resolution", "96x54", "--out", out.to_str().unwrap()][..]].concat());
    assert_eq!(code, 0, "render of two agent types failed: {err}");
    let crowd = throng::cache::read(fixture("usd/skel_two_types.usda")).unwrap();
    let (film, _) = throng::render::exr::read_layer(&out.join("full/skel.full.1001.exr")).unwrap();
    let mut seen: Vec<u32> = film.agent_id.iter().filter_map(|&i| i.checked_sub(1)).collect();
    seen.sort_unstable();
    seen.dedup();
    let mut ids: Vec<u32> = crowd.frames[0].agents.iter().map(|a| a.id).collect();
    ids.sort_unstable();
    assert_eq!(seen, ids, "every agent of both types is in the picture");
}

#[test]
fn copies_of_one_animation_within_the_pose_grid_share_a_cycle_and_posed_meshes() {
    // anim_2 holds anim_0's samples; nudge one rotation of anim_2 below the
    // grid (2e-6), then above it (1e-3).
    fn nudged(to: &'static str) -> impl Fn(&str) -> String {
        move |t: &str| {
            let at = t.find("def SkelAnimation \"anim_2\"").unwrap();
            let (head, tail) = t.split_at(at);
            format!(
                "{head}{}",
                tail.replacen("1003: [(0.97751504, 0.21086581,", &format!("1003: [(0.97751504, {to},"), 1)
            )
        }
    }
    for (to, cycles) in [("0.2108660", 2), ("0.2118658", 3)] {
        let dir = common::tempdir().unwrap();
        let (shot, usd) = edited_shot(dir.path(), "skel_instanced.usda", nudged(to));
        assert!(std::fs::read_to_string(&usd).unwrap().contains(to), "the edit took");
        let crowd = throng::cache::read(&usd).unwrap();
        assert_eq!(crowd.cycles.len(), cycles, "{to}: {:?}", crowd.cycles);
        let cast = throng::casting::ShotCrowd::load(&shot).unwrap();
        assert_eq!(cast.poses().skins().mesh_count(), cycles * 8, "{to}");
    }
}

#[test]
fn an_ancestors_unit_scale_scales_the_agents_joints_as_usd_core_evaluates_them() {
    // skel_scaled.usda: skel_crowd.usda's agents under a /Crowd scaled by 1.5.
    joints_match_usd_core("skel_scaled.usda");
}

const AGENT_OPS: &str = "uniform token[] xformOpOrder = [\"xformOp:translate\", \"xformOp:rotateY\"]";

#[test]
fn a_tilted_skel_root_is_refused_naming_its_prim_and_frame() {
    refused(
        |t| {
            let tilted = "float xformOp:rotateX = 10\n        uniform token[] xformOpOrder = [\"xformOp:translate\", \
                          \"xformOp:rotateY\", \"xformOp:rotateX\"]";
            t.replacen(AGENT_OPS, tilted, 1)
        },
        &["/Crowd/agent_0", "tilts the agent 10.00 degrees", "frame 1001"],
    );
}

#[test]
fn an_agent_scaled_apart_from_its_character_is_drawn_at_the_characters_scale_with_a_warning() {
    let dir = common::tempdir().unwrap();
    let (shot, _) = edited_shot(dir.path(), "skel_crowd.usda", |t| {
        let scaled = "float3 xformOp:scale = (1.1, 1.1, 1.1)\n        uniform token[] xformOpOrder = \
                      [\"xformOp:translate\", \"xformOp:rotateY\", \"xformOp:scale\"]";
        // The second agent's ops (the first's scale would be the character's).
        let at = t.find(AGENT_OPS).unwrap() + AGENT_OPS.len();
        format!("{}{}", &t[..at], t[at..].replacen(AGENT_OPS, scaled, 1))
    });
    let (code, _, err) = run(&["cast", shot.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("1 agent(s) of the character of Skeleton </Crowd/agent_0/Skel> are scaled 1.1000"), "{err}");
}

#[test]
fn golaems_entity_id_is_an_agents_id_after_throngs_own() {
    let dir = common::tempdir().unwrap();
    // Golaem's USD Skeleton bake writes `int64 entityId` on each entity's prim (docs/usd.md).
    let (_, usd) = edited_shot(dir.path(), "skel_crowd.usda", |t| {
        let with = |t: &str, agent: &str, id: i64| {
            let at = format!("def SkelRoot \"{agent}\"\n    {{\n");
            t.replacen(&at, &format!("{at}        int64 entityId = {id}\n"), 1)
        };
        with(&with(&with(t, "agent_0", -1), "agent_1", 43), "agent_2", 42)
    });
    let crowd = throng::cache::read(&usd).unwrap();
    let ids: Vec<u32> = crowd.frames[0].agents.iter().map(|a| a.id).collect();
    let plain = throng::cache::read(fixture("usd/skel_crowd.usda")).unwrap();
    let hashed = plain.frames[0].agents.iter().find(|a| a.id != 7 && a.position.x < 2.0).unwrap().id;
    assert!(ids.contains(&42), "agent_2's entityId: {ids:?}");
    assert!(ids.contains(&7) && !ids.contains(&43), "agent_1's primvars:throng:agentId wins: {ids:?}");
    assert!(ids.contains(&hashed), "agent_0's entityId -1 is no id: its path's hash stays: {ids:?}");
}

#[test]
fn face_varying_uvs_and_a_diffuse_texture_reach_the_skinned_meshes() {
    let dir = common::tempdir().unwrap();
    let (shot, _) = edited_shot(dir.path(), "skel_textured.usda", str::to_string);
    // The texture sits beside the crowd, as its `inputs:file` says (make_skel_crowds.py).
    std::fs::copy(fixture("usd/skel_texture.png"), dir.path().join("skel_texture.png")).unwrap();
    let crowd = throng::casting::ShotCrowd::load(&shot).unwrap();
    let lib = crowd.library();
    // 2 x 1 texels, red then blue (linear).
    let texture = lib.textures.iter().position(|t| (t.width, t.height) == (2, 1)).expect("the texture is loaded");
    let t = &lib.textures[texture].texels;
    assert!(t[0][0] > 0.99 && t[0][2] < 0.01 && t[1][2] > 0.99 && t[1][0] < 0.01, "{t:?}");
    let textured: Vec<&throng::scene::Material> =
        lib.materials.iter().filter(|m| m.base_color_texture == Some(texture as u32)).collect();
    // One character, wearing its first agent's material (docs/usd.md).
    assert_eq!(textured.len(), 1, "the character's Skin material reads it");
    assert!(textured[0].name.ends_with("#/Crowd/agent_0/Looks/Skin"), "{}", textured[0].name);
    assert!(textured.iter().all(|m| m.base_color == glam::Vec3::ONE), "a connected diffuseColor is the texture's");
    // Ring heights 0, 0.5, 1, 1.5, 1.8 of 1.8 m, v pointing down.
    let rings = [0.0f32, 0.5, 1.0, 1.5, 1.8].map(|y| 1.0 - y / 1.8);
    let bodies: Vec<&throng::scene::Mesh> = lib.meshes.iter().filter(|m| m.name.contains("/Body")).collect();
    assert!(!bodies.is_empty());
    for m in bodies {
        assert_eq!(m.uvs.len(), m.positions.len(), "{}", m.name);
        // 20 points; faces alternate u, so points where they meet are split.
        assert!(m.positions.len() > 20, "{}: {} vertices", m.name, m.positions.len());
        for tri in m.indices.chunks(3) {
            let u: Vec<f32> = tri.iter().map(|&i| m.uvs[i as usize].x).collect();
            assert!(
                u.iter().all(|&x| x == u[0]) && (u[0] == 0.25 || u[0] == 0.75),
                "{}: a face's corners: {u:?}",
                m.name
            );
        }
        for uv in &m.uvs {
            assert!(rings.iter().any(|v| (uv.y - v).abs() < 1e-5), "{}: v {} is no ring's", m.name, uv.y);
        }
    }
    // Rendered, the agents' albedo is the texture's: red faces and blue faces.
    let out = dir.path().join("r");
    let args = ["render", shot.to_str().unwrap(), "--layer", "full", "--frames", "1001", "--spp", "1"];
    let (code, _, err) = run(&[&args[..], &["--resolution", "96x54", "--out", out.to_str().unwrap()][..]].concat());
    assert_eq!(code, 0, "render of the textured crowd failed: {err}");
    let (film, _) = throng::render::exr::read_layer(&out.join("full/skel.full.1001.exr")).unwrap();
    let agent = |i: usize| film.agent_id[i] > 0;
    let red =
        (0..film.albedo.len()).filter(|&i| agent(i) && film.albedo[i][0] > 0.9 && film.albedo[i][2] < 0.1).count();
    let blue =
        (0..film.albedo.len()).filter(|&i| agent(i) && film.albedo[i][2] > 0.9 && film.albedo[i][0] < 0.1).count();
    assert!(red > 0 && blue > 0, "red {red} and blue {blue} agent pixels");
}
