//! The verbs on the bundled demo shot, through the library and the binary.

mod common;

use std::path::Path;

use throng::cache::CacheReader;
use throng::casting::ShotCrowd;
use throng::layers::{build_layers, LayerOverrides};
use throng::shot::Shot;

use common::demo_shot;

fn layer_args(per_frame: bool) -> LayerOverrides {
    LayerOverrides { per_frame, ..Default::default() }
}

use common::run as throng;

#[test]
fn fixed_layers_do_not_pop_and_per_frame_ranking_does() {
    let crowd = ShotCrowd::load(&demo_shot()).unwrap();
    let fixed = build_layers(&crowd, &layer_args(false)).unwrap();
    assert_eq!(fixed.pops.agents_changed, 0);
    assert_eq!(fixed.ref_frame, crowd.shot().frames.middle());
    let per_frame = build_layers(&crowd, &layer_args(true)).unwrap();
    assert!(per_frame.pops.agents_changed > 0, "the demo's walkers cross layer boundaries");
    // Layers are ordered by distance, nearest first.
    for w in fixed.layers.windows(2) {
        assert!(
            w[0].distance_max_m.unwrap() <= w[1].distance_min_m.unwrap() + 1e-3,
            "{} then {}",
            w[0].name,
            w[1].name
        );
    }
}

#[test]
fn removing_an_agent_moves_no_other_agent_between_layers() {
    let crowd = ShotCrowd::load(&demo_shot()).unwrap();
    let before = build_layers(&crowd, &layer_args(false)).unwrap();
    // Remove the agent on a layer boundary: the nearest of layer 1.
    let victim =
        before.agents.iter().filter(|a| a.layer == 1).min_by(|a, b| a.distance_m.total_cmp(&b.distance_m)).unwrap().id;
    let mut shot = Shot::load(&demo_shot()).unwrap();
    shot.removed.push(victim);
    let cache = CacheReader::open(&shot.cache.path).unwrap();
    let removed = ShotCrowd::new(shot, cache, None).unwrap();
    let after = build_layers(&removed, &layer_args(false)).unwrap();
    for a in &before.agents {
        let b = after.agent(a.id).unwrap();
        assert_eq!(a.layer, b.layer, "agent {} moved when {victim} was removed", a.id);
        assert_eq!(a.lod, b.lod);
        assert_eq!(b.removed, a.id == victim);
    }
    // The removed agent is in no render.
    for l in &after.comp_order {
        assert!(after.agent_visibility(l, victim, after.ref_frame).is_none());
    }
}

#[test]
fn botinfo_prints_the_block_and_names_nearest_ids() {
    let shot = demo_shot();
    let shot = shot.to_str().unwrap();
    let (code, out, err) = throng(&["botinfo", shot, "142", "--frame", "1010"]);
    assert_eq!(code, 0, "{err}");
    for key in ["Agent ID  142", "Rig", "Cycle", "Frame", "Scheme", "Height", "Distance", "head"] {
        assert!(out.contains(key), "missing {key} in\n{out}");
    }
    let (code, _, err) = throng(&["botinfo", shot, "99999"]);
    assert_eq!(code, 2);
    assert!(err.contains("agent 99999 is not in shot demo") && err.contains("nearest ids"), "{err}");
    let (code, out, _) = throng(&["botinfo", shot, "142", "--json"]);
    assert_eq!(code, 0);
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(v[0]["id"], 142);
    // Several ids, one unknown: every agent found is printed, the unknown
    // one is named, and the exit status says something was missing.
    let (code, out, err) = throng(&["botinfo", shot, "142", "99999", "100", "--frame", "1010"]);
    assert_eq!(code, 2, "{err}");
    assert!(out.contains("Agent ID  142") && out.contains("Agent ID  100"), "{out}");
    assert!(err.contains("agent 99999 is not in shot demo") && err.contains("1 of 3 agents not found"), "{err}");
    let (code, out, _) = throng(&["botinfo", shot, "142", "99999", "--json"]);
    assert_eq!(code, 2);
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!((v.as_array().unwrap().len(), &v[0]["id"]), (1, &serde_json::json!(142)));
}

#[test]
fn cast_stats_show_instancing() {
    let (code, out, err) = throng(&["cast", demo_shot().to_str().unwrap(), "--stats", "--json"]);
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(&out).unwrap();
    let s = &v["stats"];
    assert!(s["copied_geometry_bytes"].as_u64().unwrap() > 10 * s["unique_geometry_bytes"].as_u64().unwrap());
    assert_eq!(v["agents"].as_array().unwrap().len(), s["agents"].as_u64().unwrap() as usize);
}

#[test]
fn verbs_report_bad_input_with_exit_code_2() {
    let (code, _, err) = throng(&["cast", "no/such/shot.toml"]);
    assert_eq!(code, 2);
    assert!(err.contains("no/such/shot.toml"), "{err}");
    let (code, _, err) = throng(&["export", demo_shot().to_str().unwrap(), "--frame", "5", "--out", "/tmp/x.glb"]);
    assert_eq!(code, 2);
    assert!(err.contains("outside shot demo"), "{err}");
}

#[test]
fn a_cycle_the_rig_lacks_is_named_with_frame_and_agent() {
    let shot = Shot::load(&demo_shot()).unwrap();
    let mut crowd = throng::cache::read(&shot.cache.path).unwrap();
    crowd.cycles.push("Moonwalk".into());
    let last = (crowd.cycles.len() - 1) as u16;
    let victim = crowd.frames[3].agents[5].id;
    crowd.frames[3].agents[5].cycle = last;
    let err = match ShotCrowd::new(shot.clone(), CacheReader::from_crowd(shot.cache.path.clone(), crowd), None) {
        Ok(_) => panic!("an unknown cycle was accepted"),
        Err(e) => e.to_string(),
    };
    assert!(err.contains("Moonwalk") && err.contains(&format!("agent {victim}")), "{err}");
    assert!(err.contains("frame 1004"), "names the shot frame: {err}");
}

#[test]
fn botinfo_distance_is_the_manifests_distance_at_the_reference_frame() {
    let crowd = ShotCrowd::load(&demo_shot()).unwrap();
    let manifest = build_layers(&crowd, &layer_args(false)).unwrap();
    let present: Vec<u32> = crowd.agents_at(manifest.ref_frame).unwrap().agents.iter().map(|a| a.id).take(20).collect();
    let infos = throng::botinfo::bot_info(&crowd, &present, manifest.ref_frame).unwrap();
    for b in infos {
        let m = manifest.agent(b.id).unwrap();
        assert!(
            (b.distance - m.distance_m).abs() < 1e-4,
            "agent {}: botinfo {} vs manifest {}",
            b.id,
            b.distance,
            m.distance_m
        );
    }
}

#[test]
fn an_unknown_scheme_names_file_agent_and_key_once() {
    let mut shot = Shot::load(&demo_shot()).unwrap();
    shot.rigs.get_mut("bipedTallB").unwrap().schemes = [("NoSuchScheme".to_string(), 1.0)].into();
    let cache = CacheReader::open(&shot.cache.path).unwrap();
    let err = match ShotCrowd::new(shot, cache, None) {
        Ok(_) => panic!("an unknown scheme was accepted"),
        Err(e) => e.to_string(),
    };
    assert!(
        err.contains("shot.toml") && err.contains("rigs.bipedTallB.schemes") && err.contains("NoSuchScheme"),
        "{err}"
    );
    assert_eq!(err.matches("agent ").count(), 1, "the agent is named once: {err}");
}

#[test]
fn a_wardrobe_type_error_names_file_line_and_key() {
    let text = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("wardrobes/robots.toml")).unwrap();
    let (before, after) = text.split_once("roughness = ").unwrap();
    let line = before.lines().count() + 1; // `before` ends at the start of that line
    let broken = format!("{before}roughness = \"shiny\"{}", &after[after.find('\n').unwrap()..]);
    let dir = common::tempdir().unwrap();
    let path = dir.path().join("robots.toml");
    std::fs::write(&path, broken).unwrap();
    let err = throng::casting::wardrobe::Wardrobes::load(&[path]).unwrap_err().to_string();
    assert!(err.contains(&format!("robots.toml:{line}")) && err.contains("`materials.chrome.roughness`"), "{err}");
}
