//! Layering: fixed-frame membership, distance order, budget, removal
//! invariance, pins, per-frame pops, LOD, the manifest and the map.

mod common;

use glam::Vec3;
use throng::layers::{
    build_manifest, draw_map, membership, pops_in, read_manifest, render_map, summary, write_manifest, AgentInput,
    LayerInput, LayerOptions, Lod, MapOptions, Ranking,
};
use throng::scene::{vis, Camera};
use throng::shot::{look_at, LayerSettings, Pin, SplitMode};

const FRAMES: std::ops::RangeInclusive<i32> = 1001..=1024;

/// The demo camera: near (0, 1.7, 24) looking towards -Z, 35 mm on a 36 mm back, 16:9.
fn camera() -> Camera {
    let yfov = 2.0 * ((36.0 / (16.0 / 9.0)) * 0.5f32 / 35.0).atan();
    Camera::pinhole(look_at(Vec3::new(0.0, 1.7, 24.0), Vec3::new(0.0, 1.0, -2.0)), yfov)
}

fn agent(id: u32, positions: Vec<Option<Vec3>>) -> AgentInput {
    AgentInput {
        id,
        positions,
        height_m: 1.75 + (id % 5) as f32 * 0.05,
        memory_full: 40_000_000 + (id as u64 % 7) * 1_000_000,
        memory_proxy: 1_500,
        removed: false,
    }
}

/// A standing grid of `nx * nz` agents in x [-18, 18], z [-30, 12].
fn grid(nx: u32, nz: u32) -> Vec<AgentInput> {
    let n = FRAMES.count();
    let mut v = Vec::new();
    for j in 0..nz {
        for i in 0..nx {
            let x = -18.0 + 36.0 * i as f32 / (nx - 1).max(1) as f32;
            let z = -30.0 + 42.0 * j as f32 / (nz - 1).max(1) as f32;
            v.push(agent(j * nx + i, vec![Some(Vec3::new(x, 0.0, z)); n]));
        }
    }
    v
}

/// Agents walking across the frame at different depths, so their order by
/// distance changes during the shot.
fn crossing(n: u32) -> Vec<AgentInput> {
    (0..n)
        .map(|id| {
            let z = 14.0 - id as f32 * 1.5;
            let dir = if id % 2 == 0 { 1.0 } else { -1.0 };
            let positions = FRAMES
                .enumerate()
                .map(|(f, _)| Some(Vec3::new(dir * (-16.0 + (id % 4) as f32 * 4.0 + 1.4 * f as f32), 0.0, z)))
                .collect();
            agent(id, positions)
        })
        .collect()
}

fn input(agents: Vec<AgentInput>, settings: LayerSettings) -> LayerInput {
    let frames: Vec<i32> = FRAMES.collect();
    LayerInput {
        shot: "test".into(),
        source: "test/shot.toml".into(),
        cameras: vec![camera(); frames.len()],
        frames,
        image_size: (960, 540),
        agents,
        settings,
        options: LayerOptions::default(),
    }
}

fn count(n: usize) -> LayerSettings {
    LayerSettings { split: SplitMode::Count, count: n, ..Default::default() }
}

fn cutoffs(c: &[f32]) -> LayerSettings {
    LayerSettings { split: SplitMode::Cutoffs, cutoffs: c.to_vec(), ..Default::default() }
}

/// A budget split whose other layers' agents cast as proxy boxes: with
/// full casters every layer would carry the whole crowd (see
/// `budget_counts_every_other_agent_as_a_caster`).
fn budget(b: &str) -> LayerSettings {
    LayerSettings { split: SplitMode::Budget, budget: Some(b.into()), proxy_shadow_casters: true, ..Default::default() }
}

fn layers_by_id(m: &throng::layers::Manifest) -> Vec<(u32, usize)> {
    m.agents.iter().map(|a| (a.id, a.layer)).collect()
}

#[test]
fn fixed_membership_is_identical_on_every_frame() {
    let inp = input(crossing(30), count(3));
    let table = membership(&inp, Ranking::Fixed).unwrap();
    assert_eq!(table.len(), FRAMES.count());
    assert!(table.iter().all(|f| f == &table[0]));
    assert_eq!(pops_in(&table).agents_changed, 0);
    // And it is the manifest's membership.
    let m = build_manifest(&inp).unwrap();
    for (a, l) in inp.agents.iter().zip(&table[0]) {
        assert_eq!(m.agent(a.id).map(|r| r.layer), *l);
    }
    assert_eq!(m.ref_frame, 1012, "middle of 1001-1024");
    assert_eq!((m.pops.agents_changed, m.pops.changes), (0, 0));
    assert!(m.agents.iter().all(|a| a.ranked_frame == 1012));
}

#[test]
fn per_frame_finds_pops_when_agents_cross_the_camera() {
    let mut inp = input(crossing(30), count(3));
    let table = membership(&inp, Ranking::PerFrame).unwrap();
    let pops = pops_in(&table);
    assert!(pops.agents_changed > 0, "{pops:?}");
    inp.options.per_frame = true;
    let m = build_manifest(&inp).unwrap();
    assert_eq!(m.ranking, Ranking::PerFrame);
    assert_eq!(m.pops, pops);
    // Membership in the manifest is still the reference frame's.
    let fixed = build_manifest(&input(crossing(30), count(3))).unwrap();
    assert_eq!(layers_by_id(&m), layers_by_id(&fixed));
    assert!(summary(&m).contains(&format!("would pop {} agents", pops.agents_changed)));
}

#[test]
fn layers_are_ordered_by_distance() {
    for settings in [count(4), cutoffs(&[15.0, 25.0, 40.0]), budget("400MB")] {
        let m = build_manifest(&input(grid(12, 10), settings.clone())).unwrap();
        assert!(m.layers.len() >= 3, "{:?}: {} layers", settings.split, m.layers.len());
        for w in m.layers.windows(2) {
            if let (Some(near), Some(far)) = (w[0].distance_max_m, w[1].distance_min_m) {
                assert!(
                    near <= far,
                    "{:?}: {} ends at {near}, {} starts at {far}",
                    settings.split,
                    w[0].name,
                    w[1].name
                );
            }
        }
        let total: usize = m.layers.iter().map(|l| l.agents).sum();
        assert_eq!(total, 120);
        assert_eq!(m.comp_order.first().map(String::as_str), Some("set"));
        assert_eq!(m.comp_order.last().map(String::as_str), Some("crowd0"));
    }
    // Cut-offs: every agent sits in its interval.
    let cuts = [15.0, 25.0, 40.0];
    let m = build_manifest(&input(grid(12, 10), cutoffs(&cuts))).unwrap();
    for a in &m.agents {
        let lo = if a.layer == 0 { 0.0 } else { cuts[a.layer - 1] };
        let hi = cuts.get(a.layer).copied().unwrap_or(f32::INFINITY);
        assert!(a.distance_m >= lo && a.distance_m < hi, "agent {} at {} in layer {}", a.id, a.distance_m, a.layer);
    }
    // Count: equal sizes.
    let m = build_manifest(&input(grid(12, 10), count(4))).unwrap();
    assert!(m.layers.iter().all(|l| l.agents == 30));
}

#[test]
fn ties_are_broken_by_agent_id() {
    // Two agents mirrored about the camera axis are at the same distance.
    let n = FRAMES.count();
    let agents =
        vec![agent(7, vec![Some(Vec3::new(3.0, 0.0, 0.0)); n]), agent(3, vec![Some(Vec3::new(-3.0, 0.0, 0.0)); n])];
    let mut agents = agents;
    agents[0].height_m = 1.8;
    agents[1].height_m = 1.8;
    let m = build_manifest(&input(agents, count(2))).unwrap();
    assert_eq!(m.agent(3).unwrap().layer, 0);
    assert_eq!(m.agent(7).unwrap().layer, 1);
}

#[test]
fn budget_split_keeps_every_layer_under_budget() {
    let b = 300_000_000u64;
    let mut inp = input(grid(12, 10), budget("300MB"));
    inp.options.shared_bytes = 20_000_000;
    let m = build_manifest(&inp).unwrap();
    assert!(m.layers.len() > 2);
    for l in &m.layers {
        assert!(l.memory_bytes <= b, "{} needs {}", l.name, l.memory_bytes);
        assert!(l.agents > 0);
    }
    assert_eq!(m.split.budget_bytes, Some(b));
    // Near agents are full LOD (expensive), far ones proxies: near layers hold fewer agents.
    assert!(m.layers[0].agents < m.layers[m.layers.len() - 1].agents);
}

#[test]
fn budget_counts_every_other_agent_as_a_caster() {
    // Full casters: every layer render traces the whole crowd, so no split
    // can fit 120 agents of ~40 MB into 300 MB, and the error says why.
    let settings = LayerSettings { proxy_shadow_casters: false, ..budget("300MB") };
    let err = build_manifest(&input(grid(12, 10), settings)).unwrap_err().to_string();
    assert!(err.contains("shadow and reflection casters"), "{err}");
    assert!(err.contains("proxy_shadow_casters = true"), "{err}");
    assert!(err.contains("layers.budget"), "{err}");
    // Proxy casters: each layer is the shared part (floor + every agent as a
    // proxy caster) plus what its own agents cost beyond their proxies.
    let mut inp = input(grid(12, 10), budget("300MB"));
    inp.options.shared_bytes = 20_000_000;
    let m = build_manifest(&inp).unwrap();
    let casters: u64 = inp.agents.iter().map(|a| a.memory_proxy).sum();
    assert_eq!(m.split.shared_bytes, 20_000_000 + casters);
    for l in &m.layers {
        let own: u64 = m
            .agents
            .iter()
            .filter(|a| a.layer == l.index && !a.removed)
            .map(|a| a.memory_bytes - inp.agents.iter().find(|x| x.id == a.id).unwrap().memory_proxy)
            .sum();
        assert_eq!(l.memory_bytes, m.split.shared_bytes + own, "{}", l.name);
    }
}

#[test]
fn budget_split_fails_clearly_when_one_agent_exceeds_it() {
    let mut agents = grid(4, 4);
    // Agent 13 is near the camera (full LOD) and huge.
    agents[13].memory_full = 5_000_000_000;
    let err = build_manifest(&input(agents, budget("2.8GB"))).unwrap_err().to_string();
    assert!(err.contains("agent 13"), "{err}");
    assert!(err.contains("5.00 GB"), "{err}");
    assert!(err.contains("2.80 GB"), "{err}");
    assert!(err.contains("layers.budget"), "{err}");
}

#[test]
fn removing_an_agent_moves_no_other_agent() {
    for settings in [count(3), cutoffs(&[12.0, 30.0]), budget("500MB")] {
        let base = build_manifest(&input(grid(10, 8), settings.clone())).unwrap();
        for removed in [0u32, 17, 42, 79] {
            let mut agents = grid(10, 8);
            agents[removed as usize].removed = true;
            let m = build_manifest(&input(agents, settings.clone())).unwrap();
            assert_eq!(layers_by_id(&m), layers_by_id(&base), "{:?}, removing {removed}", settings.split);
            let r = m.agent(removed).unwrap();
            assert!(r.removed);
            assert_eq!(m.layers[r.layer].removed, 1);
            assert_eq!(m.agent_visibility(&m.layers[r.layer].name, removed, 1001), None, "removed is never rendered");
            assert_eq!(m.agent_visibility("set", removed, 1001), None);
        }
    }
}

#[test]
fn pins_move_only_the_pinned_agent() {
    let base = build_manifest(&input(grid(10, 8), count(3))).unwrap();
    let far = base.agents.iter().max_by(|a, b| a.distance_m.total_cmp(&b.distance_m)).unwrap().id;
    let mut settings = count(3);
    settings.pins = vec![Pin { agent: far, layer: 0 }, Pin { agent: 5, layer: 3 }];
    let m = build_manifest(&input(grid(10, 8), settings)).unwrap();
    assert_eq!(m.agent(far).unwrap().layer, 0);
    assert!(m.agent(far).unwrap().pinned);
    assert_eq!(m.agent(5).unwrap().layer, 3);
    assert_eq!(m.layers.len(), 4, "pinning to layer 3 of 3 creates crowd3");
    assert_eq!(m.layers[3].agents, 1);
    for (a, b) in m.agents.iter().zip(&base.agents) {
        if a.id != far && a.id != 5 {
            assert_eq!(a.layer, b.layer, "agent {}", a.id);
        }
    }
    // A pin for an agent not in the crowd is an error naming it.
    let mut settings = count(3);
    settings.pins = vec![Pin { agent: 9999, layer: 0 }];
    let err = build_manifest(&input(grid(3, 3), settings)).unwrap_err().to_string();
    assert!(err.contains("agent 9999") && err.contains("layers.pins"), "{err}");
}

#[test]
fn a_pin_that_would_leave_empty_layers_is_refused() {
    // Regression (issue 15): a pin to layer 7 of 3 made crowd3-crowd6 empty, silently.
    let mut settings = count(3);
    settings.pins = vec![Pin { agent: 5, layer: 7 }];
    let err = build_manifest(&input(grid(10, 8), settings)).unwrap_err().to_string();
    assert!(err.contains("agent 5") && err.contains("layers.pins") && err.contains("layer 3 empty"), "{err}");
}

#[test]
fn absent_agents_are_ranked_at_their_nearest_frame() {
    let n = FRAMES.count();
    let mut agents = grid(3, 3);
    // Present only from frame 1020 on, walking away.
    let late: Vec<Option<Vec3>> =
        (0..n).map(|f| (f >= 19).then(|| Vec3::new(0.0, 0.0, 10.0 - (f - 19) as f32))).collect();
    agents.push(agent(100, late));
    agents.push(agent(101, vec![None; n]));
    let m = build_manifest(&input(agents, count(2))).unwrap();
    let a = m.agent(100).unwrap();
    assert_eq!(a.ranked_frame, 1020);
    assert_eq!(a.position, [0.0, 0.0, 10.0]);
    assert!(m.agent(101).is_none());
    assert_eq!(m.absent, vec![101]);
}

#[test]
fn lod_from_projected_height() {
    let n = FRAMES.count();
    let agents = vec![
        agent(1, vec![Some(Vec3::new(0.0, 0.0, 18.0)); n]),  // 6 m away: big
        agent(2, vec![Some(Vec3::new(0.0, 0.0, -30.0)); n]), // 54 m away: small
        agent(3, vec![Some(Vec3::new(0.0, 0.0, 30.0)); n]),  // behind the camera
    ];
    let m = build_manifest(&input(agents, count(1))).unwrap();
    let (near, far, behind) = (m.agent(1).unwrap(), m.agent(2).unwrap(), m.agent(3).unwrap());
    assert_eq!(near.lod, Lod::Full);
    assert_eq!(far.lod, Lod::Proxy);
    assert!(near.projected_px > 100.0 && far.projected_px < 40.0, "{} {}", near.projected_px, far.projected_px);
    assert!(behind.behind_camera && behind.lod == Lod::Proxy && behind.projected_px == 0.0);
    // Projected height: 1.8 m at depth d fills 1.8 / (2 d tan(yfov/2)) of 540 px.
    let cam = camera();
    let eye = Vec3::new(0.0, 1.7, 24.0);
    let fwd = cam.world_from_camera.transform_vector3(-Vec3::Z);
    let depth = (Vec3::new(0.0, 0.9, 18.0) - eye).dot(fwd);
    let want = 1.8 / (2.0 * depth * (0.5 * cam.yfov).tan()) * 540.0;
    assert!((m.agent(1).unwrap().projected_px - want).abs() < 0.5, "{} vs {want}", near.projected_px);
}

#[test]
fn per_frame_lod_uses_hysteresis() {
    let n = FRAMES.count();
    // Walks towards the camera, then jitters around the threshold distance.
    let positions: Vec<Option<Vec3>> = (0..n)
        .map(|f| {
            let z = if f < 12 { -40.0 + 4.0 * f as f32 } else { -6.0 + if f % 2 == 0 { 0.3 } else { -0.3 } };
            Some(Vec3::new(0.0, 0.0, z))
        })
        .collect();
    let mut inp = input(vec![agent(1, positions)], LayerSettings { lod_full_min_px: 50.0, ..count(1) });
    inp.options.lod_per_frame = true;
    let m = build_manifest(&inp).unwrap();
    let a = m.agent(1).unwrap();
    assert!(!a.lod_changes.is_empty());
    assert_eq!(a.lod_at(1001), Lod::Proxy);
    assert!(a.lod_changes.len() <= 2, "hysteresis stops flicker: {:?}", a.lod_changes);
    assert_eq!(a.memory_bytes, inp.agents[0].memory_full, "charged full memory when ever full");
}

#[test]
fn visibility_per_layer() {
    let mut settings = count(2);
    settings.proxy_shadow_casters = true;
    let m = build_manifest(&input(grid(4, 4), settings)).unwrap();
    let a = m.agents.iter().find(|a| a.layer == 0 && a.lod == Lod::Full).unwrap();
    assert_eq!(m.agent_visibility("crowd0", a.id, 1001), Some((vis::ALL, Lod::Full)));
    assert_eq!(m.agent_visibility("crowd1", a.id, 1001), Some((vis::SHADOW | vis::INDIRECT, Lod::Proxy)));
    assert_eq!(m.agent_visibility("set", a.id, 1001), Some((vis::SHADOW | vis::INDIRECT, Lod::Proxy)));
    assert_eq!(m.set_visibility("crowd0"), Some(vis::HOLDOUT | vis::SHADOW | vis::INDIRECT));
    assert_eq!(m.set_visibility("set"), Some(vis::ALL));
    assert_eq!(m.agent_visibility("crowd9", a.id, 1001), None);
}

#[test]
fn manifest_round_trips_and_checks_its_version() {
    let dir = common::tempdir().unwrap();
    let path = dir.path().join("layers.json");
    let m = build_manifest(&input(grid(5, 5), count(3))).unwrap();
    write_manifest(&path, &m).unwrap();
    assert_eq!(read_manifest(&path).unwrap(), m);
    let text = std::fs::read_to_string(&path).unwrap().replacen("\"version\": 1", "\"version\": 7", 1);
    std::fs::write(&path, text).unwrap();
    let err = read_manifest(&path).unwrap_err().to_string();
    assert!(err.contains("version 7") && err.contains("layers.json"), "{err}");
}

#[test]
fn bad_settings_are_clear_errors() {
    let err = build_manifest(&input(grid(2, 2), cutoffs(&[20.0, 10.0]))).unwrap_err().to_string();
    assert!(err.contains("layers.cutoffs"), "{err}");
    let err = build_manifest(&input(grid(2, 2), LayerSettings { split: SplitMode::Budget, ..Default::default() }))
        .unwrap_err()
        .to_string();
    assert!(err.contains("layers.budget"), "{err}");
    let err =
        build_manifest(&input(grid(2, 2), LayerSettings { ref_frame: Some(900), ..count(2) })).unwrap_err().to_string();
    assert!(err.contains("900") && err.contains("ref_frame"), "{err}");
    let mut agents = grid(2, 2);
    agents[1].id = agents[0].id;
    assert!(build_manifest(&input(agents, count(2))).unwrap_err().to_string().contains("twice"));
}

#[test]
fn summary_has_one_aligned_line_per_layer() {
    let mut agents = grid(8, 6);
    agents[3].removed = true;
    let m = build_manifest(&input(agents, count(3))).unwrap();
    let s = summary(&m);
    let lines: Vec<&str> = s.lines().filter(|l| l.starts_with("crowd")).collect();
    assert_eq!(lines.len(), 3, "{s}");
    // Aligned: the memory column ends at the same place on every line.
    assert!(lines.iter().all(|l| l.len() == lines[0].len()), "{s}");
    assert!(s.contains("comp order, back to front: set, crowd2, crowd1, crowd0"), "{s}");
    assert!(s.contains("0 pops"), "{s}");
    let json = m.summary_json();
    assert!(json.get("agents").is_none() && json["layers"].as_array().unwrap().len() == 3);
}

#[test]
fn map_decodes_as_png_of_the_requested_size() {
    let mut agents = grid(12, 10);
    agents[30].removed = true;
    let mut settings = count(3);
    settings.pins = vec![Pin { agent: 5, layer: 0 }];
    let m = build_manifest(&input(agents, settings)).unwrap();
    let opts = MapOptions {
        size: (1200, 700),
        set_bounds: Some((Vec3::new(-40.0, 0.0, -40.0), Vec3::new(40.0, 20.0, 40.0))),
        ..Default::default()
    };
    let png = render_map(&m, &opts).unwrap();
    let img = image::load_from_memory_with_format(&png, image::ImageFormat::Png).unwrap();
    assert_eq!((img.width(), img.height()), (1200, 700));
    let dir = common::tempdir().unwrap();
    let path = dir.path().join("map.png");
    draw_map(&m, &MapOptions { size: (400, 240), set_bounds: None, ..Default::default() }, &path).unwrap();
    let img = image::open(&path).unwrap();
    assert_eq!((img.width(), img.height()), (400, 240));
    assert!(render_map(&m, &MapOptions { size: (0, 10), set_bounds: None, ..Default::default() }).is_err());
}

#[test]
fn input_from_a_shot_and_crowd() {
    use throng::cache::{AgentSample as Rec, CrowdCache, FrameBlock};
    use throng::layers::shot_input;
    let dir = common::tempdir().unwrap();
    std::fs::write(dir.path().join("c.crowd"), b"").unwrap();
    let text = r#"
version = 1
name = "tiny"
removed = [2]
[frames]
start = 1001
end = 1005
[cache]
path = "c.crowd"
frame_offset = -1000
[camera]
[[camera.keys]]
frame = 1001
position = [0.0, 1.7, 24.0]
aim = [0.0, 1.0, -2.0]
focal_length = 35.0
[layers]
count = 2
"#;
    let shot = throng::shot::Shot::parse(text, &dir.path().join("shot.toml")).unwrap();
    let rec = |id: u32, z: f32| Rec {
        id,
        position: Vec3::new(0.0, 0.0, z),
        heading: 0.0,
        rig: 0,
        cycle: 0,
        cycle_frame: 0.0,
        flags: 0,
    };
    // Cache frames 1..=5; agent 3 only appears from cache frame 4.
    let frames = (1..=5)
        .map(|f| FrameBlock {
            frame: f,
            agents: [rec(1, 10.0), rec(2, 0.0)].into_iter().chain((f >= 4).then(|| rec(3, -10.0))).collect(),
        })
        .collect();
    let crowd = CrowdCache { rigs: vec!["r".into()], cycles: vec!["c".into()], frames };
    let input =
        shot_input(&shot, &crowd, None, shot.layers.clone(), LayerOptions::default(), |_| (1.8, 1_000_000, 1_000))
            .unwrap();
    assert_eq!(input.frames, vec![1001, 1002, 1003, 1004, 1005]);
    let m = build_manifest(&input).unwrap();
    assert_eq!(m.ref_frame, 1003);
    assert_eq!(m.agents.iter().map(|a| (a.id, a.layer)).collect::<Vec<_>>(), vec![(1, 0), (2, 0), (3, 1)]);
    assert!(m.agent(2).unwrap().removed);
    assert_eq!(m.agent(3).unwrap().ranked_frame, 1004);
}

/// The memory model on the demo (rigid robots and skinned walkers over 48
/// frames, a set): what the manifest charges is the one model's floor plus
/// the agents, each part counted once; a frame's BLASes, not the whole
/// library's; and with a shutter, its deforming BLASes, whether or not the
/// crowd was posed for it.
#[test]
fn the_memory_model_counts_each_part_once() {
    use throng::casting::ShotCrowd;
    use throng::layers::{build_layers, memory, LayerOverrides, RenderFloor};
    let shot = common::demo_shot();
    let crowd = ShotCrowd::load(&shot).unwrap();
    let [w, h] = crowd.shot().render.resolution;
    let px = w as u64 * h as u64;
    let unsplit = LayerOverrides { count: Some(1), ..Default::default() };
    let m = build_layers(&crowd, &unsplit).unwrap();
    assert!(m.absent.is_empty() && m.agents.iter().all(|a| !a.removed));
    let full = |id: u32, f: i32| m.agent(id).is_some_and(|a| a.lod_at(f) == Lod::Full);
    let floor = RenderFloor::of(&crowd, None, px, full).unwrap();
    let poses = |c: &ShotCrowd, shutter| {
        let t = memory::AgentTraces::of(c, shutter, 1, |id, f| if full(id, f) { vec![0] } else { Vec::new() });
        t.unwrap().per_render[0]
    };
    let (pose_tris, _) = poses(&crowd, None);
    // Shared: the floor, every full agent's poses (casters keep their LOD,
    // so every render traces them) and every agent as a caster; the one
    // crowd layer adds nothing on top (its agents are those casters).
    let agents: u64 = m.agents.iter().map(|a| a.memory_bytes).sum();
    assert_eq!(m.split.shared_bytes, floor.bytes() + memory::blas_bytes(pose_tris, 0) + agents);
    assert_eq!(m.render_memory("crowd0"), Some(m.split.shared_bytes));
    assert_eq!(m.render_memory("set"), Some(m.split.shared_bytes));
    // The film (and the process) once.
    assert_eq!(floor.bytes() - RenderFloor { pixels: 0, ..floor }.bytes(), memory::film_bytes(px, floor.film()));
    assert_eq!(memory::at_pixels(floor.bytes(), px, 0, floor.film()), RenderFloor { pixels: 0, ..floor }.bytes());
    // Passes: three more channels per pixel each, in the film once.
    let with_passes = ShotCrowd::load(&shot).unwrap().with_shot(|s| s.render.passes = vec!["all".into()]).unwrap();
    let passes = memory::pass_count(&with_passes).unwrap();
    assert!(passes >= 10, "7 light paths, groups, shadow, P: {passes}");
    let floor_passes = RenderFloor::of(&with_passes, None, px, full).unwrap();
    assert_eq!(floor_passes.bytes() - floor.bytes(), px * passes * memory::PASS_PIXEL_BYTES);
    assert!(build_layers(&with_passes, &unsplit).unwrap().split.shared_bytes > m.split.shared_bytes);
    // One frame's poses, not the 48 frames' the library holds; only full agents trace theirs.
    let library: u64 = crowd.library().meshes.iter().map(|m| m.triangle_count() as u64).sum();
    assert!(floor.triangles + pose_tris < library / 2, "{} + {pose_tris} of {library} triangles", floor.triangles);
    assert!(pose_tris > 0 && floor.deform_triangles == 0);
    let none = memory::AgentTraces::of(&crowd, None, 1, |_, _| Vec::new()).unwrap();
    assert_eq!(none.per_render[0], (0, 0));
    // Blurred: deforming BLASes, motion records and the motion AOV.
    let shutter = [-0.25f32, 0.25];
    let blurred = RenderFloor::of(&crowd, Some(shutter), px, full).unwrap();
    let (_, deform) = poses(&crowd, Some(shutter));
    assert!(blurred.blurred && deform > 0);
    assert!(blurred.bytes() > floor.bytes());
    let shot_blurred = crowd.with_shot(|s| s.render.shutter = Some(shutter)).unwrap();
    let mb = build_layers(&shot_blurred, &unsplit).unwrap();
    assert!(mb.split.shared_bytes > m.split.shared_bytes);
    // A crowd posed for the shutter (as `throng render` poses it) gets the same estimate.
    let mut posed_shot = throng::shot::Shot::load(&shot).unwrap();
    posed_shot.render.shutter = Some(shutter);
    let posed = ShotCrowd::open(posed_shot, Some(shutter)).unwrap();
    assert!(posed.library().meshes.len() >= shot_blurred.library().meshes.len());
    assert_eq!(build_layers(&posed, &unsplit).unwrap().split.shared_bytes, mb.split.shared_bytes);
}

/// Issue 49, item 1: a layer is charged what is fixed (process, loaded
/// shot, library, set, film) once and what its own agents cost: with other
/// layers' agents as proxy-box casters, a far layer of proxies does not pay
/// for the near layer's skinned poses, and the set layer has its own figure.
#[test]
fn each_layer_is_charged_its_own_agents() {
    use throng::casting::ShotCrowd;
    use throng::layers::{build_layers, memory, LayerOverrides, RenderFloor};
    let crowd =
        ShotCrowd::load(&common::demo_shot()).unwrap().with_shot(|s| s.layers.proxy_shadow_casters = true).unwrap();
    let [w, h] = crowd.shot().render.resolution;
    let m = build_layers(&crowd, &LayerOverrides { count: Some(3), ..Default::default() }).unwrap();
    let floor = RenderFloor::of(&crowd, None, w as u64 * h as u64, |_, _| false).unwrap().bytes();
    let proxy = |id: u32| memory::instance_bytes(crowd.instance_count(id, Lod::Proxy) as u64, false);
    let casters: u64 = m.agents.iter().map(|a| proxy(a.id)).sum();
    let traces = memory::AgentTraces::of(&crowd, None, m.layers.len(), |id, f| {
        m.agent(id).filter(|a| a.lod_at(f) == Lod::Full).map(|a| vec![a.layer]).unwrap_or_default()
    })
    .unwrap();
    for (i, l) in m.layers.iter().enumerate() {
        let own: u64 = m.agents.iter().filter(|a| a.layer == i).map(|a| a.memory_bytes).sum::<u64>();
        let own_instances: u64 = m
            .agents
            .iter()
            .filter(|a| a.layer == i)
            .map(|a| memory::instance_bytes(crowd.instance_count(a.id, a.lod) as u64, false))
            .sum();
        let others: u64 = m.agents.iter().filter(|a| a.layer != i).map(|a| proxy(a.id)).sum();
        let (t, d) = traces.per_render[i];
        assert_eq!(l.memory_bytes, floor + memory::blas_bytes(t, d) + own_instances + others, "{}", l.name);
        assert!(own >= own_instances);
    }
    assert_eq!(m.render_memory("set"), Some(floor + casters), "the set traces only casters");
    assert!(m.render_memory("set") < m.render_memory("crowd0"));
    // Each layer pays for its own poses only: less than one render of every
    // full agent's, and not one figure for all.
    let every = memory::AgentTraces::of(&crowd, None, 1, |id, f| {
        m.agent(id).filter(|a| a.lod_at(f) == Lod::Full).map(|_| vec![0]).unwrap_or_default()
    })
    .unwrap();
    for (i, l) in m.layers.iter().enumerate() {
        assert!(traces.per_render[i].0 < every.per_render[0].0, "{}", l.name);
    }
    assert!(m.layers.windows(2).any(|w| w[0].memory_bytes != w[1].memory_bytes));
}

/// Issue 49, item 1: the estimate is never under the measured peak and at
/// most 1.25x over it, crowd and set layers. Checked against peaks recorded
/// (not measured here: a 960x540 render per layer is too slow for CI) with
/// `throng render demo/shot.toml --layer L --frames 1024 --spp 1 --json`
/// (when and on what: docs/benchmarks.md, issue 49).
#[test]
fn estimates_hold_within_a_quarter_of_recorded_peaks() {
    use throng::casting::ShotCrowd;
    use throng::layers::{build_layers, LayerOverrides};
    const MIB: f64 = 1048576.0;
    // (proxy casters, layer, measured peak MiB)
    let recorded: [(bool, &str, f64); 6] = [
        (false, "set", 528.44),
        (false, "crowd0", 529.04),
        (false, "crowd2", 512.32),
        (true, "set", 455.73),
        (true, "crowd0", 487.22),
        (true, "crowd2", 471.30),
    ];
    for proxy in [false, true] {
        let crowd = ShotCrowd::load(&common::demo_shot())
            .unwrap()
            .with_shot(|s| s.layers.proxy_shadow_casters = proxy)
            .unwrap();
        let m = build_layers(&crowd, &LayerOverrides::default()).unwrap();
        for &(_, layer, peak) in recorded.iter().filter(|r| r.0 == proxy) {
            let ratio = m.render_memory(layer).unwrap() as f64 / MIB / peak;
            assert!((1.0..=1.25).contains(&ratio), "proxy casters {proxy}, {layer}: {ratio:.3}");
        }
    }
}
