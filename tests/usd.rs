//! USD interchange (docs/usd.md): the demo exported over a frame range and
//! read back through openusd; the export deterministic; the layered export;
//! a USD crowd written by Pixar's usd-core (tests/fixtures/usd, made by
//! .ci/make_usd_crowd.py) read as a cache and rendered; bad USD input
//! refused with the file, prim path and frame, exit 2.

mod common;

use std::path::{Path, PathBuf};

use common::{demo_shot, fixture, repo_path, run};
use openusd::sdf;
use openusd::usd::{Stage, TimeCode};

fn export(out: &Path, frames: &str, extra: &[&str]) -> String {
    let shot = demo_shot();
    let mut args =
        vec!["export", shot.to_str().unwrap(), "--format", "usd", "--frames", frames, "--out", out.to_str().unwrap()];
    args.extend_from_slice(extra);
    let (code, stdout, stderr) = run(&args);
    assert_eq!(code, 0, "export failed: {stderr}");
    stdout
}

fn path(p: &str) -> sdf::Path {
    sdf::Path::new(p).unwrap()
}

#[test]
fn demo_exports_and_reads_back_through_openusd() {
    let dir = common::tempdir().unwrap();
    let out = dir.path().join("demo.usda");
    let line = export(&out, "1001-1003", &[]);
    assert!(line.contains("over 3 frames"), "{line}");
    let stage = Stage::open(out.to_str().unwrap()).unwrap();
    assert!(stage.composition_errors().is_empty(), "{:?}", stage.composition_errors());
    assert_eq!(stage.start_time_code(), 1001.0);
    assert_eq!(stage.end_time_code(), 1003.0);
    assert_eq!(stage.default_prim().map(|t| t.as_str().to_string()).as_deref(), Some("World"));
    assert_eq!(stage.stage_metadata("upAxis").unwrap(), Some(sdf::Value::Token("Y".into())));
    assert_eq!(stage.stage_metadata("metersPerUnit").unwrap(), Some(sdf::Value::Double(1.0)));

    // Every agent a prim named by its Cryptomatte name, with its id primvar.
    let crowd = stage.prim(path("/World/Crowd"));
    let agents = crowd.child_names().unwrap();
    assert!(agents.len() > 100, "{} agents", agents.len());
    let first = agents[0].as_str().to_string();
    let id: i32 =
        stage.attribute(path(&format!("/World/Crowd/{first}.primvars:throng:agentId"))).get().unwrap().unwrap();
    assert_eq!(first, format!("agent_{id}"));
    let name: String =
        stage.attribute(path(&format!("/World/Crowd/{first}.primvars:throng:name"))).get().unwrap().unwrap();
    assert_eq!(name, first);
    // Its transform is sampled at every frame; its parts are instances of shared prototypes.
    let sampled = agents.iter().filter(|a| {
        let xf = stage.attribute(path(&format!("/World/Crowd/{}.xformOp:transform", a.as_str())));
        xf.time_sample_times().unwrap() == vec![1001.0, 1002.0, 1003.0]
    });
    assert!(sampled.count() > agents.len() / 2, "walking agents have a transform sample per frame");
    let part = stage.prim(path(&format!("/World/Crowd/{first}"))).child_names().unwrap()[0].as_str().to_string();
    let part_prim = stage.prim(path(&format!("/World/Crowd/{first}/{part}")));
    assert!(part_prim.is_instanceable().unwrap());
    let crypto: String =
        stage.attribute(path(&format!("/World/Crowd/{first}/{part}.primvars:throng:name"))).get().unwrap().unwrap();
    assert_eq!(crypto, format!("{first}/{part}"));
    // (Pixar USD checks that the instances share prototypes: .ci/usd_check.py.)

    // Camera with film back and focal length, lights.
    let focal: f32 =
        stage.attribute(path("/World/shotcam.focalLength")).get_at(TimeCode::new(1002.0)).unwrap().unwrap();
    // Tenths of a scene unit (metres): 35 mm is 0.35, the 36 mm film back 0.36.
    assert!((focal - 0.35).abs() < 1e-6, "focal {focal}");
    let ha: f32 = stage.attribute(path("/World/shotcam.horizontalAperture")).get().unwrap().unwrap();
    assert!((ha - 0.36).abs() < 1e-6, "aperture {ha}");
    // The demo is lit by its HDRI dome and the four lamp globes.
    assert_eq!(stage.prim(path("/World/Lights/dome")).type_name().unwrap().unwrap().as_str(), "DomeLight");
    for lamp in ["lamp_1", "lamp_2", "lamp_3", "lamp_4"] {
        let prim = stage.prim(path(&format!("/World/Lights/{lamp}")));
        assert_eq!(prim.type_name().unwrap().unwrap().as_str(), "SphereLight", "{lamp}");
    }
}

#[test]
fn export_is_deterministic_and_round_trips_as_a_cache() {
    let dir = common::tempdir().unwrap();
    // The same name in two folders: the layer names its texture folder after itself.
    std::fs::create_dir(dir.path().join("b")).unwrap();
    let a = dir.path().join("a.usda");
    let b = dir.path().join("b/a.usda");
    export(&a, "1010-1011", &[]);
    export(&b, "1010-1011", &[]);
    assert!(std::fs::read(&a).unwrap() == std::fs::read(&b).unwrap(), "two exports differ");
    for tex in std::fs::read_dir(dir.path().join("a_textures")).unwrap() {
        let tex = tex.unwrap().path();
        let twin = dir.path().join("b/a_textures").join(tex.file_name().unwrap());
        assert!(std::fs::read(&tex).unwrap() == std::fs::read(&twin).unwrap(), "{} differs", tex.display());
    }

    // The export read back as a cache: same agents and positions as the demo cache.
    let usd = throng::cache::read(&a).unwrap();
    let demo = throng::cache::read(repo_path("demo/cache/demo.crowd")).unwrap();
    let usd_frame = usd.frames.iter().find(|b| b.frame == 1010).unwrap();
    let demo_frame = demo.frames.iter().find(|b| b.frame == 10).unwrap();
    let rendered: Vec<_> = demo_frame.agents.iter().filter(|a| !a.hidden()).collect();
    assert_eq!(usd_frame.agents.len(), rendered.len());
    for (u, d) in usd_frame.agents.iter().zip(&rendered) {
        assert_eq!(u.id, d.id);
        assert!((u.position - d.position).length() < 1e-4, "agent {}: {} vs {}", u.id, u.position, d.position);
        let dh = (u.heading - d.heading).rem_euclid(std::f32::consts::TAU);
        assert!(!(1e-3..=std::f32::consts::TAU - 1e-3).contains(&dh), "agent {} heading", u.id);
        assert_eq!(usd.rigs[u.rig as usize], demo.rigs[d.rig as usize]);
        assert_eq!(usd.cycles[u.cycle as usize], demo.cycles[d.cycle as usize]);
        assert_eq!(u.seated(), d.seated(), "agent {} seated", u.id);
    }
}

#[test]
fn layers_split_into_sublayers_and_collections() {
    let dir = common::tempdir().unwrap();
    let manifest = dir.path().join("m.json");
    let shot = demo_shot();
    let (code, _, err) = run(&["layers", shot.to_str().unwrap(), "--out", manifest.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    let out = dir.path().join("demo.usda");
    export(&out, "1001-1002", &["--manifest", manifest.to_str().unwrap(), "--split-layers"]);
    for layer in ["crowd0", "crowd1", "crowd2"] {
        assert!(dir.path().join(format!("demo.{layer}.usda")).exists(), "no {layer} file");
    }
    let stage = Stage::open(out.to_str().unwrap()).unwrap();
    assert_eq!(stage.layer_count(), 4, "{:?}", stage.layer_identifiers());
    let m: serde_json::Value = serde_json::from_slice(&std::fs::read(&manifest).unwrap()).unwrap();
    let agent = &m["agents"][0];
    let id = agent["id"].as_u64().unwrap();
    let layer = m["layers"][agent["layer"].as_u64().unwrap() as usize]["name"].as_str().unwrap().to_string();
    let got: String =
        stage.attribute(path(&format!("/World/Crowd/agent_{id}.primvars:throng:layer"))).get().unwrap().unwrap();
    assert_eq!(got, layer);
    let targets = stage.relationship(path(&format!("/World/Crowd.collection:{layer}:includes"))).targets().unwrap();
    assert!(targets.iter().any(|t| t.as_str() == format!("/World/Crowd/agent_{id}")));
    // The agent's prim spec lives in its layer's file.
    let text = std::fs::read_to_string(dir.path().join(format!("demo.{layer}.usda"))).unwrap();
    assert!(text.contains(&format!("\"agent_{id}\"")));
}

/// A shot like the demo's, reading `cache` with frame_offset -1000 over shot frames 1001-1005.
fn shot_on(dir: &Path, cache: &Path) -> PathBuf {
    shot_until(dir, cache, 1005)
}

/// [`shot_on`], over shot frames 1001-`end`.
fn shot_until(dir: &Path, cache: &Path, end: i32) -> PathBuf {
    let demo = repo_path("demo");
    let text = std::fs::read_to_string(demo_shot()).unwrap();
    let text = text
        .replace("\"../wardrobes/", &format!("\"{}/", repo_path("wardrobes").display()))
        .replace("\"rigs/", &format!("\"{}/rigs/", demo.display()))
        .replace("\"set/", &format!("\"{}/set/", demo.display()))
        .replace("\"hdri/", &format!("\"{}/hdri/", demo.display()))
        .replace("path = \"cache/demo.crowd\"", &format!("path = \"{}\"", cache.display()))
        .replace("end = 1048", &format!("end = {end}"));
    let p = dir.join("usd_shot.toml");
    std::fs::write(&p, text).unwrap();
    p
}

#[test]
fn a_usd_core_crowd_renders_through_throng() {
    let dir = common::tempdir().unwrap();
    let cache = fixture("usd/pointinstancer_crowd.usda");
    let c = throng::cache::read(&cache).unwrap();
    assert_eq!(c.frames.len(), 5);
    let ids: Vec<u32> = c.frames[0].agents.iter().map(|a| a.id).collect();
    assert_eq!(ids, [7, 11, 12, 40, 41, 99]);
    assert_eq!(c.rigs, ["bipedThinA", "bipedTallB"]);
    let a7 = c.frames[0].agents[0];
    assert!((a7.heading - -0.8).abs() < 2e-3, "heading {}", a7.heading);
    assert!((a7.position - glam::Vec3::new(-3.0, 0.0, -2.0)).length() < 1e-5);
    assert_eq!(c.frames[2].agents[0].cycle_frame, 2.0);

    let shot = shot_on(dir.path(), &cache);
    let out = dir.path().join("r");
    let (code, _, err) = run(&[
        "render",
        shot.to_str().unwrap(),
        "--layer",
        "full",
        "--frames",
        "1002",
        "--spp",
        "1",
        "--resolution",
        "32x18",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "render of the usd-core crowd failed: {err}");
    let exr = out.join("full/demo.full.1002.exr");
    assert!(exr.exists(), "no {}", exr.display());
    // botinfo knows the imported agents.
    let (code, stdout, err) = run(&["botinfo", shot.to_str().unwrap(), "40", "--frame", "1002", "--json"]);
    assert_eq!(code, 0, "{err}");
    assert!(stdout.contains("\"cycle\": \"IdleA\""), "{stdout}");
}

#[test]
fn shot_frames_beyond_the_usd_time_samples_name_file_prim_and_frame() {
    // The usd-core crowd holds frames 1-5; a shot over 1001-1008 (frame_offset
    // -1000) asks for 6-8.
    let dir = common::tempdir().unwrap();
    let cache = fixture("usd/pointinstancer_crowd.usda");
    let shot = shot_until(dir.path(), &cache, 1008);
    let (code, _, err) = run(&["botinfo", shot.to_str().unwrap(), "7", "--frame", "1002", "--json"]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("pointinstancer_crowd.usda"), "names the USD file: {err}");
    assert!(err.contains("</World/crowd."), "names the prim: {err}");
    assert!(err.contains("1006"), "names the first shot frame outside: {err}");
    assert!(err.contains("cover 1-5, not frame 6"), "says what the samples cover: {err}");
    assert!(!err.contains("panick"), "{err}");
}

#[test]
fn a_point_instancer_under_transformed_xforms_lands_in_world_space() {
    // tests/fixtures/usd/make_parented_crowd.py: /World/site translated
    // (time-sampled), turned 90 degrees about +Y and scaled 2x; the
    // instancer translated (1, 0, 0).
    let c = throng::cache::read(fixture("usd/parented_crowd.usda")).unwrap();
    assert_eq!(c.frames.iter().map(|b| b.frame).collect::<Vec<_>>(), [1, 2, 3]);
    for b in &c.frames {
        let f = b.frame as f32;
        let [a1, a2] = [b.agents[0], b.agents[1]];
        assert_eq!((a1.id, a2.id), (1, 2));
        let want1 = glam::Vec3::new(10.0 + f, 0.0, -6.0);
        let want2 = glam::Vec3::new(14.0 + f, 0.0, -8.0);
        assert!((a1.position - want1).length() < 1e-4, "frame {f}: agent 1 at {} not {want1}", a1.position);
        assert!((a2.position - want2).length() < 1e-3, "frame {f}: agent 2 at {} not {want2}", a2.position);
        assert!(
            (a1.heading - 90f32.to_radians()).abs() < 2e-3,
            "frame {f}: agent 1 heading {}",
            a1.heading.to_degrees()
        );
        assert!(
            (a2.heading - 120f32.to_radians()).abs() < 2e-3,
            "frame {f}: agent 2 heading {}",
            a2.heading.to_degrees()
        );
    }
}

#[test]
fn agent_prims_compose_ancestor_ops_and_every_rotate_order() {
    // Hand-written: /World/g translated, rotateXYZ (0, 90, 0), and the agent
    // under it with its own translate; a second agent under a
    // `!resetXformStack!` ignores /World/g.
    let dir = common::tempdir().unwrap();
    let text = "#usda 1.0\n(\n    startTimeCode = 1\n    endTimeCode = 2\n)\n\
        def Xform \"World\"\n{\n    def Xform \"g\"\n    {\n        \
        double3 xformOp:translate.timeSamples = { 1: (5, 0, 0), 2: (6, 0, 0) }\n        \
        float3 xformOp:rotateXYZ = (0, 90, 0)\n        \
        uniform token[] xformOpOrder = [\"xformOp:translate\", \"xformOp:rotateXYZ\"]\n        \
        def Xform \"a\"\n        {\n            int primvars:throng:agentId = 3\n            \
        double3 xformOp:translate = (1, 0, 0)\n            \
        uniform token[] xformOpOrder = [\"xformOp:translate\"]\n        }\n        \
        def Xform \"b\"\n        {\n            int primvars:throng:agentId = 4\n            \
        double3 xformOp:translate = (1, 0, 0)\n            \
        uniform token[] xformOpOrder = [\"!resetXformStack!\", \"xformOp:translate\"]\n        }\n    }\n}\n";
    let p = dir.path().join("nested.usda");
    std::fs::write(&p, text).unwrap();
    let c = throng::cache::read(&p).unwrap();
    assert_eq!(c.frames.len(), 2);
    for b in &c.frames {
        let x = 4.0 + b.frame as f32;
        let (a, r) = (b.agents[0], b.agents[1]);
        assert_eq!((a.id, r.id), (3, 4));
        assert!((a.position - glam::Vec3::new(x, 0.0, -1.0)).length() < 1e-5, "agent 3 at {}", a.position);
        assert!((a.heading - std::f32::consts::FRAC_PI_2).abs() < 1e-5, "agent 3 heading {}", a.heading);
        assert!((r.position - glam::Vec3::new(1.0, 0.0, 0.0)).length() < 1e-5, "agent 4 at {}", r.position);
        assert!(r.heading.abs() < 1e-5);
    }
}

fn bad(dir: &Path, name: &str, text: &str) -> (i32, String) {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    let (code, _, err) = run(&["cache", "info", p.to_str().unwrap()]);
    (code, err)
}

const HEAD: &str = "#usda 1.0\n(\n    startTimeCode = 1\n    endTimeCode = 4\n)\n";

#[test]
fn bad_usd_crowds_name_file_prim_and_frame() {
    let dir = common::tempdir().unwrap();
    // No crowd.
    let (code, err) = bad(
        dir.path(),
        "empty.usda",
        &format!("{HEAD}def Xform \"World\"\n{{\n    def Cube \"c\"\n    {{\n    }}\n}}\n"),
    );
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("empty.usda") && err.contains("no crowd"), "{err}");

    // Time samples that stop before the crowd's last frame.
    let short = format!(
        "{HEAD}def PointInstancer \"crowd\"\n{{\n    int64[] ids.timeSamples = {{ 1: [1, 2], 2: [1, 2] }}\n    \
         point3f[] positions.timeSamples = {{ 1: [(0, 0, 0), (1, 0, 0)], 2: [(0, 0, 0), (1, 0, 0)] }}\n}}\n"
    );
    let (code, err) = bad(dir.path(), "short.usda", &short);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("short.usda") && err.contains("/crowd.ids") && err.contains("frame 4"), "{err}");

    // A missing prototype.
    let missing = format!(
        "{HEAD}def PointInstancer \"crowd\"\n{{\n    int64[] ids = [1]\n    point3f[] positions = [(0, 0, 0)]\n    \
         rel prototypes = </nowhere>\n}}\n"
    );
    let (code, err) = bad(dir.path(), "missing.usda", &missing);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("missing.usda") && err.contains("/nowhere") && err.contains("/crowd"), "{err}");

    // No ids on the point instancer.
    let no_ids = format!("{HEAD}def PointInstancer \"crowd\"\n{{\n    point3f[] positions = [(0, 0, 0)]\n}}\n");
    let (code, err) = bad(dir.path(), "noids.usda", &no_ids);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("ids"), "{err}");

    // Lengths that disagree at one frame.
    let uneven = format!(
        "{HEAD}def PointInstancer \"crowd\"\n{{\n    int64[] ids = [1, 2]\n    \
         point3f[] positions.timeSamples = {{ 1: [(0, 0, 0), (1, 0, 0)], 3: [(0, 0, 0)], 4: [(0, 0, 0)] }}\n}}\n"
    );
    let (code, err) = bad(dir.path(), "uneven.usda", &uneven);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("uneven.usda") && err.contains("frame 3"), "{err}");

    // Not USD at all, and a missing file: errors, not panics.
    let (code, err) = bad(dir.path(), "junk.usda", "#usda 1.0\ndef def def {{{{\n");
    assert_eq!(code, 2, "{err}");
    let (code, _, err) = run(&["cache", "info", dir.path().join("nope.usd").to_str().unwrap()]);
    assert_eq!(code, 2, "{err}");
}

#[test]
fn prim_names_prototypes_and_xform_ops_that_are_not_usd_names_are_refused() {
    // Found by the usd_crowd fuzzer (docs/fuzzing.md): openusd takes these as
    // they come, and `/a}` is its own parent there, so composing it overflowed
    // the stack (a prototype or a prim named `a}`) or never ended (an xform op
    // `a}`, whose time samples were asked for), and so did traversal (a root
    // prim named "").
    let dir = common::tempdir().unwrap();
    let crowd = |name: &str, proto: &str| {
        format!(
            "{HEAD}def Xform \"{name}\"\n{{\n    def PointInstancer \"crowd\"\n    {{\n        int64[] ids = [1]\n        \
             point3f[] positions = [(0, 0, 0)]\n        rel prototypes = <{proto}>\n    }}\n}}\n"
        )
    };
    let (code, err) = bad(dir.path(), "proto.usda", &crowd("World", "}"));
    assert_eq!(code, 2, "{err}");
    assert!(
        err.contains("proto.usda") && err.contains("/World/crowd.prototypes") && err.contains("not a prim path"),
        "{err}"
    );
    let (code, err) = bad(dir.path(), "brace.usda", &crowd("a}", "/a}/crowd"));
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("brace.usda") && err.contains("`/a}`") && err.contains("not a USD identifier"), "{err}");
    let (code, err) = bad(dir.path(), "empty_name.usda", &crowd("", "/x"));
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("empty_name.usda") && err.contains("\"\"") && err.contains("not a USD identifier"), "{err}");
    let op = crowd("World", "/World/crowd")
        .replace("def Xform \"World\"\n{\n", "def Xform \"World\"\n{\n    uniform token[] xformOpOrder = [\"a}\"]\n");
    let (code, err) = bad(dir.path(), "op.usda", &op);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("op.usda") && err.contains("/World.xformOpOrder") && err.contains("\"a}\""), "{err}");
}

#[test]
fn usd_export_refuses_bad_requests() {
    let dir = common::tempdir().unwrap();
    let shot = demo_shot();
    let s = shot.to_str().unwrap();
    for (args, want) in [
        (vec!["--frames", "900-1002", "--out", "x.usda"], "not within shot"),
        (vec!["--frames", "1001-1002", "--out", "x.usdc"], ".usdc"),
        (vec!["--frames", "1001,1003", "--out", "x.usda"], "contiguous"),
        (vec!["--frames", "1001-1002", "--split-layers", "--out", "x.usdz"], "usdz"),
    ] {
        let mut full = vec!["export", s, "--format", "usd"];
        let out = dir.path().join(args.last().unwrap());
        let mut args = args.clone();
        *args.last_mut().unwrap() = out.to_str().unwrap();
        full.extend(args);
        let (code, _, err) = run(&full);
        assert_eq!(code, 2, "{full:?}: {err}");
        assert!(err.contains(want), "{full:?}: {err}");
        assert!(!out.exists());
    }
}

/// `[lights]` of the lit test shot: the shared HDRI dome (turned), a sun and
/// one light of every kind, a two-sided rect among them.
fn lit_lights() -> String {
    format!(
        r#"
[lights.sun]
direction = [-0.7, 0.45, 0.35]
intensity = 3.0
color = [1.0, 0.93, 0.82]
[lights.dome]
file = "{hdri}"
intensity = 0.8
exposure = 0.5
color = [1.0, 0.95, 0.9]
rotate = 30.0
[[lights.point]]
position = [-2.0, 2.5, 1.0]
intensity = 40.0
color = [1.0, 0.8, 0.6]
[[lights.spot]]
name = "street lamp"
light_group = "street"
position = [2.0, 4.0, 0.5]
aim = [1.5, 0.0, 0.0]
intensity = 120.0
inner_angle = 20.0
outer_angle = 35.0
[[lights.rect]]
name = "window"
position = [0.0, 1.5, -3.0]
direction = [0.0, 0.0, 1.0]
size = [2.0, 1.2]
intensity = 6.0
two_sided = true
[[lights.disk]]
position = [1.0, 3.0, 2.0]
radius = 0.3
intensity = 15.0
[[lights.sphere]]
position = [-1.0, 1.0, -1.5]
radius = 0.25
intensity = 9.0
exposure = -1.0
"#,
        hdri = common::shared_asset("hdri/quarry_01_1k.hdr").display()
    )
}

/// The lit shot in `dir`: two idle robots on frames 1001-1003, [`lit_lights`],
/// and a lens keyed from f/2.8 focused at 9 m to f/4 at 6 m.
fn lit_shot(dir: &Path) -> PathBuf {
    let second_key = "[[camera.keys]]\nframe = 1003\nposition = [0.5, 1.6, 8.0]\naim = [0.0, 0.9, 0.0]\n\
                      focal_length = 50.0\nf_stop = 4.0\nfocus_distance = 6.0\n";
    let lights = lit_lights();
    let shot = common::DemoShot { name: "lit", lights: &lights, extra: second_key, ..Default::default() }
        .write(dir, &common::two_robots(1..=3));
    let text = std::fs::read_to_string(&shot).unwrap();
    let text = text.replacen("focal_length = 35.0\n", "focal_length = 35.0\nf_stop = 2.8\nfocus_distance = 9.0\n", 1);
    std::fs::write(&shot, text).unwrap();
    shot
}

fn value(stage: &Stage, p: &str) -> sdf::Value {
    stage.attribute(path(p)).get::<sdf::Value>().unwrap().unwrap_or_else(|| panic!("no value at {p}"))
}

fn float(stage: &Stage, p: &str) -> f32 {
    stage.attribute(path(p)).get::<f32>().unwrap().unwrap_or_else(|| panic!("no float at {p}"))
}

fn flag(stage: &Stage, p: &str) -> bool {
    matches!(stage.attribute(path(p)).get::<sdf::Value>().unwrap(), Some(sdf::Value::Bool(true)))
}

/// UsdLux's luminance L = intensity x 2^exposure x color (exposure unauthored: 0).
fn luminance(stage: &Stage, prim: &str) -> glam::Vec3 {
    let sdf::Value::Vec3f(c) = value(stage, &format!("{prim}.inputs:color")) else { panic!("{prim}: color") };
    let exposure = stage.attribute(path(&format!("{prim}.inputs:exposure"))).get::<f32>().unwrap().unwrap_or(0.0);
    glam::Vec3::new(c.x, c.y, c.z) * float(stage, &format!("{prim}.inputs:intensity")) * exposure.exp2()
}

fn light_matrix(stage: &Stage, prim: &str) -> glam::Mat4 {
    let sdf::Value::Matrix4d(m) = value(stage, &format!("{prim}.xformOp:transform")) else { panic!("{prim}: xform") };
    glam::Mat4::from_cols_array(&m.0.map(|x| x as f32))
}

fn near(a: glam::Vec3, b: glam::Vec3) -> bool {
    (a - b).abs().max_element() <= 1e-5 * b.abs().max_element().max(1.0)
}

#[test]
fn every_light_and_the_lens_export_in_usd_units_and_the_lit_export_reads_back() {
    use throng::scene::lights::LightKind;
    let dir = common::tempdir().unwrap();
    let shot = lit_shot(dir.path());
    let out = dir.path().join("lit.usda");
    let (code, _, err) = run(&["export", shot.to_str().unwrap(), "--format", "usd", "--out", out.to_str().unwrap()]);
    assert_eq!(code, 0, "export failed: {err}");
    let crowd = throng::casting::ShotCrowd::load(&shot).unwrap();
    let lights = crowd.lights();
    let stage = Stage::open(out.to_str().unwrap()).unwrap();
    assert!(stage.composition_errors().is_empty(), "{:?}", stage.composition_errors());

    // The sun: normalize on makes UsdLux's intensity x color the irradiance.
    let sun = lights.sun.unwrap();
    assert!(flag(&stage, "/World/Lights/sun.inputs:normalize"));
    assert!(near(luminance(&stage, "/World/Lights/sun"), sun.irradiance));
    assert!((float(&stage, "/World/Lights/sun.inputs:angle") - sun.angular_diameter.to_degrees()).abs() < 1e-5);
    let towards = light_matrix(&stage, "/World/Lights/sun").transform_vector3(glam::Vec3::NEG_Z);
    assert!(near(towards, -sun.direction), "the sun shines along {towards}");

    // Every local light by its name: type, placement and implied quantity.
    let names: Vec<String> =
        stage.prim(path("/World/Lights")).child_names().unwrap().iter().map(|t| t.as_str().to_string()).collect();
    let mut prims: std::collections::BTreeMap<String, Vec<String>> = Default::default();
    for n in &names {
        let p = format!("/World/Lights/{n}");
        if let Ok(Some(name)) = stage.attribute(path(&format!("{p}.throng:name"))).get::<String>() {
            prims.entry(name).or_default().push(p);
        }
    }
    assert_eq!(lights.local.len(), 5);
    for light in &lights.local {
        let found = &prims[&light.name];
        assert_eq!(found.len(), if light.two_sided { 2 } else { 1 }, "{}: {found:?}", light.name);
        let p = &found[0];
        // Each prim names its light group (its pass lg_<name>): its own, or
        // the light's name made a channel name.
        let group = light.light_group.clone().unwrap_or_else(|| throng::scene::passes::default_group(&light.name));
        assert_eq!(light.name == "street lamp", group == "street", "{}: group {group}", light.name);
        for q in found {
            let got = stage.attribute(path(&format!("{q}.throng:lightGroup"))).get::<String>().unwrap();
            assert_eq!(got.as_deref(), Some(group.as_str()), "{q}");
        }
        let ty = stage.prim(path(p)).type_name().unwrap().unwrap().as_str().to_string();
        let m = light_matrix(&stage, p);
        assert!(m.abs_diff_eq(glam::Mat4::from(light.world_from_light), 1e-6), "{}: {m}", light.name);
        let l = luminance(&stage, p);
        match light.kind {
            LightKind::Point | LightKind::Spot { .. } => {
                // A treatAsPoint SphereLight, normalize on: its radiant
                // intensity is L / (4 pi r^2) x pi r^2 = L / 4 at any radius.
                assert_eq!(ty, "SphereLight");
                assert!(flag(&stage, &format!("{p}.treatAsPoint")) && flag(&stage, &format!("{p}.inputs:normalize")));
                assert_eq!(float(&stage, &format!("{p}.inputs:radius")), 0.0);
                assert!(near(l / 4.0, light.emission), "{}: {l} / 4 vs {} W/sr", light.name, light.emission);
                if let LightKind::Spot { outer, blend } = light.kind {
                    let cone = float(&stage, &format!("{p}.inputs:shaping:cone:angle"));
                    assert!((cone - 35.0).abs() < 1e-5 && (cone.to_radians() - outer).abs() < 1e-6, "cone {cone}");
                    let soft = float(&stage, &format!("{p}.inputs:shaping:cone:softness"));
                    assert!((soft - blend).abs() < 1e-6 && (soft - (1.0 - 20.0 / 35.0)).abs() < 1e-6);
                }
            }
            LightKind::Rect { size } => {
                assert_eq!(ty, "RectLight");
                assert!(near(l, light.emission), "{}: radiance {l}", light.name);
                assert_eq!(float(&stage, &format!("{p}.inputs:width")), size.x);
                assert_eq!(float(&stage, &format!("{p}.inputs:height")), size.y);
                // Its back face: a twin facing the other way from the same place.
                let back = light_matrix(&stage, &found[1]);
                assert!(near(back.transform_vector3(glam::Vec3::NEG_Z), -light.facing()));
                assert!(near(back.w_axis.truncate(), light.position()));
            }
            LightKind::Disk { radius } | LightKind::Sphere { radius } => {
                let want = if matches!(light.kind, LightKind::Disk { .. }) { "DiskLight" } else { "SphereLight" };
                assert_eq!(ty, want);
                assert!(!flag(&stage, &format!("{p}.inputs:normalize")));
                assert!(near(l, light.emission), "{}: radiance {l}", light.name);
                assert_eq!(float(&stage, &format!("{p}.inputs:radius")), radius);
            }
            LightKind::Distant { .. } => panic!("the shot has no distant light"),
        }
    }

    // The dome: its map copied beside the layer, lat-long, a quarter turn
    // more than throng's rotate (the image centre at +Z, not +X).
    let dome = lights.dome.as_ref().unwrap();
    assert!(names.contains(&"dome".to_string()) && !names.contains(&"sky".to_string()), "a dome replaces the sky");
    assert!(near(luminance(&stage, "/World/Lights/dome"), dome.scale));
    for (prim, group) in [("sun", "sun"), ("dome", "dome")] {
        let got = stage.attribute(path(&format!("/World/Lights/{prim}.throng:lightGroup"))).get::<String>().unwrap();
        assert_eq!(got.as_deref(), Some(group), "{prim}");
    }
    assert!((float(&stage, "/World/Lights/dome.xformOp:rotateY") - 120.0).abs() < 1e-4);
    assert_eq!(value(&stage, "/World/Lights/dome.inputs:texture:format"), sdf::Value::Token("latlong".into()));
    let sdf::Value::AssetPath(asset) = value(&stage, "/World/Lights/dome.inputs:texture:file") else { panic!() };
    assert_eq!(asset.authored_path, "./lit_textures/quarry_01_1k.hdr");
    let copied = std::fs::read(dir.path().join("lit_textures/quarry_01_1k.hdr")).unwrap();
    assert!(copied == std::fs::read(&dome.file).unwrap(), "the dome map is not the shot's file");

    // The lens: fStop and focusDistance per frame, the f-number that gives
    // the renderer's aperture radius focal / (2 fStop).
    let cam = stage.attribute(path("/World/shotcam.fStop"));
    assert_eq!(cam.time_sample_times().unwrap(), vec![1001.0, 1002.0, 1003.0]);
    for f in 1001..=1003 {
        let t = TimeCode::new(f64::from(f));
        // (openusd 0.6 reads a float time sample of a text layer as a double.)
        let at = |a: &str| match stage.attribute(path(a)).get_at::<sdf::Value>(t).unwrap() {
            Some(sdf::Value::Float(x)) => x,
            Some(sdf::Value::Double(x)) => x as f32,
            v => panic!("{a} at {f}: {v:?}"),
        };
        let c = crowd.camera(f).unwrap();
        let focal_m = at("/World/shotcam.focalLength") * 0.1;
        let n = at("/World/shotcam.fStop");
        assert!((focal_m / (2.0 * n) - c.aperture).abs() < 1e-7, "frame {f}: f/{n} vs aperture {}", c.aperture);
        assert!((at("/World/shotcam.focusDistance") - c.focus_distance).abs() < 1e-5, "frame {f}");
        let (want_n, want_d) = [(2.8, 9.0), (3.4, 7.5), (4.0, 6.0)][(f - 1001) as usize];
        assert!((n - want_n).abs() < 1e-5 && (at("/World/shotcam.focusDistance") - want_d).abs() < 1e-5);
    }

    // The lit export, and its package, read back as a crowd: the cache's agents.
    let usdz = dir.path().join("lit.usdz");
    let (code, _, err) = run(&["export", shot.to_str().unwrap(), "--format", "usd", "--out", usdz.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    for file in [&out, &usdz] {
        let c = throng::cache::read(file).unwrap();
        assert_eq!(c.frames.iter().map(|b| b.frame).collect::<Vec<_>>(), [1001, 1002, 1003], "{}", file.display());
        for b in &c.frames {
            let at: Vec<(u32, glam::Vec3)> = b.agents.iter().map(|a| (a.id, a.position)).collect();
            assert_eq!(at.len(), 2, "{}", file.display());
            assert!(at[0].0 == 1 && at[0].1.abs_diff_eq(glam::Vec3::new(-0.8, 0.0, 1.0), 1e-5), "{at:?}");
            assert!(at[1].0 == 2 && at[1].1.abs_diff_eq(glam::Vec3::new(0.9, 0.0, -1.0), 1e-5), "{at:?}");
        }
    }
    // ... and renders as the cache of a shot lit the same way.
    let text = std::fs::read_to_string(&shot).unwrap();
    let again = dir.path().join("again.toml");
    let text =
        text.replace("path = \"c.csv\"", "path = \"lit.usdz\"").replace("frame_offset = -1000", "frame_offset = 0");
    std::fs::write(&again, text).unwrap();
    let r = dir.path().join("r");
    let (code, _, err) =
        run(&["render", again.to_str().unwrap(), "--layer", "full", "--frames", "1002", "--out", r.to_str().unwrap()]);
    assert_eq!(code, 0, "render of the lit USD crowd failed: {err}");
    assert!(r.join("full/lit.full.1002.exr").exists());
}

/// Every emissive material, the set's and the crowd's, carries the radiance
/// the renderer emits (emissiveFactor x strength, a wardrobe's emission) as
/// its UsdPreviewSurface `emissiveColor`; the others have none.
#[test]
fn emissive_materials_export_the_radiance_the_renderer_emits() {
    let dir = common::tempdir().unwrap();
    let d = dir.path();
    let shot = common::DemoShot { name: "glow", ..Default::default() }.write(d, &common::two_robots(1..=3));
    let glow = "[materials.glow]\nbase_color = [0.1, 0.1, 0.1]\nemission = [2.0, 1.0, 0.5]\n";
    std::fs::write(d.join("w.toml"), common::heads_wardrobe(glow, "slot = \"head\"\nmaterials = [\"glow\"]")).unwrap();
    common::wear_heads(&shot, "w.toml");
    let out = d.join("glow.usda");
    let (code, _, err) = run(&[
        "export",
        shot.to_str().unwrap(),
        "--format",
        "usd",
        "--frames",
        "1001-1002",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    let crowd = throng::casting::ShotCrowd::load(&shot).unwrap();
    let stage = Stage::open(out.to_str().unwrap()).unwrap();
    let mut emissive = Vec::new();
    for look in stage.prim(path("/World/Looks")).child_names().unwrap() {
        let attr =
            stage.attribute(path(&format!("/World/Looks/{}/PreviewSurface.inputs:emissiveColor", look.as_str())));
        if let Some(sdf::Value::Vec3f(c)) = attr.get::<sdf::Value>().unwrap() {
            emissive.push((look.as_str().to_string(), glam::Vec3::new(c.x, c.y, c.z)));
        }
    }
    let want: Vec<glam::Vec3> =
        (crowd.library().materials.iter()).filter(|m| m.emission.max_element() > 0.0).map(|m| m.emission).collect();
    assert_eq!(emissive.len(), want.len(), "{emissive:?} vs {want:?}");
    for w in &want {
        assert!(emissive.iter().any(|(_, c)| (*c - *w).abs().max_element() < 1e-6), "{w} not in {emissive:?}");
    }
    // The set's shop windows (emissiveFactor x KHR_materials_emissive_strength 1.1) and the crowd's glow.
    let by_name = |n: &str| emissive.iter().find(|(l, _)| l.ends_with(n)).map(|x| x.1);
    assert_eq!(by_name("glow"), Some(glam::Vec3::new(2.0, 1.0, 0.5)));
    let window = by_name("set_shop_window").expect("the shop windows emit");
    assert!((window - glam::Vec3::new(1.0, 0.72727275, 0.4363636) * 1.1).abs().max_element() < 1e-6, "{window}");
}
