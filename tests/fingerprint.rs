//! One fingerprint (issue 22 item 4): a layer manifest made before anything
//! that moves, times or picks agents changed is refused by `throng render`
//! (exit 2), naming the change: the cache file (a `.crowd` cache included,
//! whose CRC-32 is the same for every file), each `[cache]` import key,
//! `frames.fps` and `cache.frame_offset`.

mod common;

use std::path::{Path, PathBuf};

use common::run;

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 temp path")
}

/// A trajectory table in centimetres, z up, headings in degrees: agents 1
/// and 2 walk along x on source frames 0-60, agent 3 stands.
fn table() -> String {
    let mut t = String::from("t,agent,px,py,pz,yaw,yaw2\n");
    for f in 0..=60 {
        let x = f as f32 * 5.0;
        t.push_str(&format!("{f},1,{x},100,0,0,90\n{f},2,{x},-100,0,0,90\n{f},3,0,300,0,45,0\n"));
    }
    t
}

/// The `[cache]` table of the base shot: every import key a foreign table
/// can change without changing the file.
const CACHE_KEYS: &str = r#"delimiter = ","
header = true
units = "cm"
up = "z"
handedness = "right"
source_fps = 24.0
max_gap = 1.0
heading = "column"
heading_units = "degrees"
heading_window = 0.5
hold_speed = 0.25
rig = "bipedThinA"
cycle = "WalkA"
idle_cycle = "IdleA"
translate = [0.0, 0.0, 0.0]
rotate = 0.0
scale = 1.0
"#;

/// A shot over `cache` in `dir` with `keys` in its `[cache]` table.
fn write_shot(dir: &Path, cache: &str, keys: &str, fps: &str, frame_offset: i32) -> PathBuf {
    let demo = common::repo_path("demo");
    let wardrobe = common::repo_path("wardrobes/robots.toml");
    let text = format!(
        r#"version = 1
name = "fp"
seed = 3
wardrobes = ["{wardrobe}"]
[frames]
start = 10
end = 20
fps = {fps}
outside_cache = "empty"
[cache]
path = "{cache}"
frame_offset = {frame_offset}
{keys}
[cache.columns]
frame = "t"
id = "agent"
x = "px"
y = "py"
z = "pz"
heading = "yaw"
[rigs.bipedThinA]
file = "{demo}/rigs/bipedThinA.glb"
schemes = {{ HighEnd = 1.0 }}
[camera]
[[camera.keys]]
frame = 10
position = [0.0, 1.7, 20.0]
aim = [0.0, 1.0, 0.0]
focal_length = 35.0
[layers]
count = 2
[render]
resolution = [16, 9]
spp = 1
"#,
        wardrobe = wardrobe.display(),
        demo = demo.display()
    );
    let path = dir.join("shot.toml");
    std::fs::write(&path, text).unwrap();
    path
}

/// `throng render` of one frame of layer `crowd0` with `manifest`: (exit code, stderr).
fn render_with(shot: &Path, manifest: &Path, out: &Path) -> (i32, String) {
    let (code, _, err) = run(&[
        "render",
        s(shot),
        "--manifest",
        s(manifest),
        "--layer",
        "crowd0",
        "--frames",
        "12",
        "--progress",
        "off",
        "--out",
        s(out),
    ]);
    (code, err)
}

#[test]
fn a_manifest_is_refused_after_any_change_that_moves_times_or_picks_agents() {
    let dir = common::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("walk.csv"), table()).unwrap();
    let base = || write_shot(d, "walk.csv", CACHE_KEYS, "24.0", 0);
    let shot = base();
    let manifest = d.join("fp.layers.json");
    let (code, out, err) = run(&["layers", s(&shot), "--out", s(&manifest)]);
    assert_eq!(code, 0, "{out}{err}");
    let out = d.join("render");
    // The unchanged shot renders with its manifest.
    let (code, err) = render_with(&shot, &manifest, &out);
    assert_eq!(code, 0, "{err}");

    // (the [cache] line as written, its replacement, what the refusal names)
    let key_changes: &[(&str, &str, &str)] = &[
        ("units = \"cm\"", "units = \"mm\"", "`units`"),
        ("up = \"z\"", "up = \"y\"", "`up`"),
        ("handedness = \"right\"", "handedness = \"left\"", "`handedness`"),
        ("source_fps = 24.0", "source_fps = 25.0", "`source_fps`"),
        ("max_gap = 1.0", "max_gap = 0.5", "`max_gap`"),
        ("heading = \"column\"", "heading = \"motion\"", "`heading`"),
        ("heading_units = \"degrees\"", "heading_units = \"radians\"", "`heading_units`"),
        ("heading_window = 0.5", "heading_window = 1.5", "`heading_window`"),
        ("hold_speed = 0.25", "hold_speed = 2.0", "`hold_speed`"),
        ("cycle = \"WalkA\"", "cycle = \"WalkB\"", "`cycle`"),
        ("idle_cycle = \"IdleA\"", "idle_cycle = \"SitA\"", "`idle_cycle`"),
        ("translate = [0.0, 0.0, 0.0]", "translate = [1.0, 0.0, 0.0]", "`translate`"),
        ("rotate = 0.0", "rotate = 90.0", "`rotate`"),
        ("scale = 1.0", "scale = 2.0", "`scale`"),
        // A key written out with its default, then left out: the value is the same.
        ("delimiter = \",\"", "", "`delimiter`"),
        ("header = true", "", "`header`"),
        // A key the base shot leaves out.
        ("rig = \"bipedThinA\"", "rig = \"bipedThinA\"\ncomment = \"#\"", "`comment`"),
    ];
    let mut refusals = Vec::new();
    for (from, to, names) in key_changes {
        assert!(CACHE_KEYS.contains(from), "{from}");
        let shot = write_shot(d, "walk.csv", &CACHE_KEYS.replacen(from, to, 1), "24.0", 0);
        refusals.push((format!("[cache] {from} -> {to}"), render_with(&shot, &manifest, &out), *names));
    }
    // A column chosen differently.
    let text = std::fs::read_to_string(base()).unwrap().replace("heading = \"yaw\"", "heading = \"yaw2\"");
    std::fs::write(&shot, text).unwrap();
    refusals.push(("[cache.columns] heading".into(), render_with(&shot, &manifest, &out), "`columns`"));
    // The shot's frame rate, and the frame offset.
    let shot = write_shot(d, "walk.csv", CACHE_KEYS, "25.0", 0);
    refusals.push(("frames.fps".into(), render_with(&shot, &manifest, &out), "frames.fps changed from 24 to 25"));
    let shot = write_shot(d, "walk.csv", CACHE_KEYS, "24.0", 2);
    refusals.push(("frame_offset".into(), render_with(&shot, &manifest, &out), "cache.frame_offset changed"));
    // The cache file itself: one sample moves.
    let moved = table().replacen("\n3,1,15,100,0,0,90\n", "\n3,1,16,100,0,0,90\n", 1);
    assert_ne!(moved, table());
    std::fs::write(d.join("walk.csv"), moved).unwrap();
    let shot = base();
    refusals.push(("the cache file".into(), render_with(&shot, &manifest, &out), "the cache"));
    std::fs::write(d.join("walk.csv"), table()).unwrap();

    for (change, (code, err), names) in &refusals {
        assert_eq!(code, &2, "{change}: the old manifest should be refused:\n{err}");
        assert!(err.contains("stale layer manifest") && err.contains(names), "{change}: should name {names}:\n{err}");
        assert!(err.contains("fp.layers.json") && !err.contains("panicked"), "{change}:\n{err}");
    }
    // Back as it was: current again.
    let (code, err) = render_with(&base(), &manifest, &out);
    assert_eq!(code, 0, "{err}");
}

/// Rows of throng's own CSV: agents walking along x, `dx` added to agent 1's x.
fn crowd_csv(dx: f32) -> String {
    let mut t = String::from("frame,id,x,y,z,heading,rig,cycle,cycle_frame,flags\n");
    for f in 0..=30 {
        for id in 1..=2u32 {
            let x = f as f32 * 0.05 + if id == 1 { dx } else { 0.0 };
            t.push_str(&format!("{f},{id},{x:?},0,{:?},0,bipedThinA,WalkA,{f},\n", id as f32 * 2.0 - 3.0));
        }
    }
    t
}

#[test]
fn two_crowd_caches_fingerprint_differently_and_a_changed_one_is_refused() {
    let dir = common::tempdir().unwrap();
    let d = dir.path();
    let (a, b) = (d.join("a.crowd"), d.join("b.crowd"));
    for (dx, crowd) in [(0.0, &a), (0.5, &b)] {
        let csv = d.join("in.csv");
        std::fs::write(&csv, crowd_csv(dx)).unwrap();
        let (code, out, err) = run(&["cache", "convert", s(&csv), s(crowd)]);
        assert_eq!(code, 0, "{out}{err}");
    }
    let (bytes_a, bytes_b) = (std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
    assert_ne!(bytes_a, bytes_b);
    // A .crowd file ends with the CRC-32 of its own bytes, so the CRC-32 of
    // every .crowd file is one constant: it cannot tell two caches apart.
    assert_eq!(crc32fast::hash(&bytes_a), crc32fast::hash(&bytes_b));
    let (fa, fb) = (throng::fingerprint::hash_file(&a).unwrap(), throng::fingerprint::hash_file(&b).unwrap());
    assert_ne!(fa.hash, fb.hash);
    assert_eq!(fa.bytes, bytes_a.len() as u64);

    // A shot over a.crowd; the manifest is made; a.crowd is replaced by b's bytes.
    let shot = write_shot(d, "c.crowd", "", "24.0", 0).to_path_buf();
    let text = std::fs::read_to_string(&shot).unwrap();
    let columns = text.find("[cache.columns]").unwrap();
    let rigs = text.find("[rigs.bipedThinA]").unwrap();
    std::fs::write(&shot, format!("{}{}", &text[..columns], &text[rigs..])).unwrap();
    std::fs::copy(&a, d.join("c.crowd")).unwrap();
    let manifest = d.join("fp.layers.json");
    let (code, out, err) = run(&["layers", s(&shot), "--out", s(&manifest)]);
    assert_eq!(code, 0, "{out}{err}");
    let out = d.join("render");
    assert_eq!(render_with(&shot, &manifest, &out).0, 0);
    std::fs::copy(&b, d.join("c.crowd")).unwrap();
    let (code, err) = render_with(&shot, &manifest, &out);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("stale layer manifest") && err.contains("c.crowd changed (made_from.cache)"), "{err}");
}

#[test]
fn a_manifest_fingerprinted_by_an_older_throng_is_refused_naming_the_algorithm() {
    let dir = common::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("walk.csv"), table()).unwrap();
    let shot = write_shot(d, "walk.csv", CACHE_KEYS, "24.0", 0);
    let manifest = d.join("fp.layers.json");
    assert_eq!(run(&["layers", s(&shot), "--out", s(&manifest)]).0, 0);
    let text = std::fs::read_to_string(&manifest).unwrap();
    assert!(text.contains("\"algorithm\": \"fnv1a64\""), "{text}");
    std::fs::write(&manifest, text.replace("\"algorithm\": \"fnv1a64\"", "\"algorithm\": \"crc32\"")).unwrap();
    let (code, err) = render_with(&shot, &manifest, &d.join("render"));
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("`crc32`") && err.contains("made_from.algorithm"), "{err}");
}

/// A shot over `cache` (a file read by its own format, no columns) with
/// `keys` in its `[cache]` table.
fn plain_shot(dir: &Path, cache: &str, keys: &str, fps: &str, frame_offset: i32) -> PathBuf {
    let shot = write_shot(dir, cache, keys, fps, frame_offset);
    let text = std::fs::read_to_string(&shot).unwrap();
    let (columns, rigs) = (text.find("[cache.columns]").unwrap(), text.find("[rigs.bipedThinA]").unwrap());
    // The USD crowd's agents also wear the demo's tall rig.
    let tall = format!(
        "[rigs.bipedTallB]\nfile = \"{}\"\nschemes = {{ HighEnd = 1.0 }}\n",
        common::repo_path("demo/rigs/bipedTallB.glb").display()
    );
    std::fs::write(&shot, format!("{}{tall}{}", &text[..columns], &text[rigs..])).unwrap();
    shot
}

/// A manifest is made over `cache` in `d`; then each change in turn (a
/// function making it, undone after) must get the manifest refused naming
/// it. `edit_cache` changes the cache file's decoded content.
fn refused_after_each_change(d: &Path, cache: &str, frame_offset: i32, edit_cache: &dyn Fn(&Path)) {
    let shot = plain_shot(d, cache, "", "24.0", frame_offset);
    let manifest = d.join("fp.layers.json");
    let (code, out, err) = run(&["layers", s(&shot), "--out", s(&manifest)]);
    assert_eq!(code, 0, "{cache}: {out}{err}");
    let out = d.join("render");
    let (code, err) = render_with(&shot, &manifest, &out);
    assert_eq!(code, 0, "{cache}: the unchanged shot renders:\n{err}");
    let mut refusals = Vec::new();
    for (keys, names) in
        [("translate = [0.5, 0.0, 0.0]", "`translate`"), ("rotate = 10.0", "`rotate`"), ("scale = 1.5", "`scale`")]
    {
        let shot = plain_shot(d, cache, keys, "24.0", frame_offset);
        refusals.push((keys.to_string(), render_with(&shot, &manifest, &out), names));
    }
    let shot = plain_shot(d, cache, "", "25.0", frame_offset);
    refusals.push(("frames.fps".into(), render_with(&shot, &manifest, &out), "frames.fps changed"));
    // The cache's content.
    let path = d.join(cache);
    let before = std::fs::read(&path).unwrap();
    edit_cache(&path);
    assert_ne!(std::fs::read(&path).unwrap(), before, "{cache}: the edit changes the file");
    let shot = plain_shot(d, cache, "", "24.0", frame_offset);
    refusals.push(("the cache's content".into(), render_with(&shot, &manifest, &out), "changed (made_from.cache)"));
    std::fs::write(&path, &before).unwrap();
    // The manifest itself, edited by hand: an agent deleted from `agents`.
    let text = std::fs::read_to_string(&manifest).unwrap();
    let mut m: serde_json::Value = serde_json::from_str(&text).unwrap();
    let agents = m["agents"].as_array_mut().unwrap();
    assert!(agents.len() > 1, "{cache}: the manifest ranks agents");
    agents.remove(0);
    std::fs::write(&manifest, serde_json::to_string_pretty(&m).unwrap()).unwrap();
    refusals.push(("an agent deleted".into(), render_with(&shot, &manifest, &out), "made_from.content"));
    std::fs::write(&manifest, &text).unwrap();

    for (change, (code, err), names) in &refusals {
        assert_eq!(code, &2, "{cache}: {change}: the old manifest should be refused:\n{err}");
        assert!(
            err.contains("stale layer manifest") && err.contains(names),
            "{cache}: {change}: names {names}:\n{err}"
        );
    }
    // Everything back as it was: current again.
    let (code, err) = render_with(&shot, &manifest, &out);
    assert_eq!(code, 0, "{cache}: {err}");
}

#[test]
fn every_cache_format_is_fingerprinted_by_content_keys_and_rate() {
    // .crowd (made from throng's own CSV), .csv, JuPedSim .sqlite, USD.
    let dir = common::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("crowd.csv"), crowd_csv(0.0)).unwrap();
    let (code, out, err) = run(&["cache", "convert", s(&d.join("crowd.csv")), s(&d.join("c.crowd"))]);
    assert_eq!(code, 0, "{out}{err}");
    refused_after_each_change(d, "c.crowd", 0, &|p| {
        let csv = d.join("moved.csv");
        std::fs::write(&csv, crowd_csv(0.25)).unwrap();
        assert_eq!(run(&["cache", "convert", s(&csv), s(p)]).0, 0);
    });
    refused_after_each_change(d, "crowd.csv", 0, &|p| std::fs::write(p, crowd_csv(0.25)).unwrap());

    std::fs::copy(common::fixture("jupedsim_small.sqlite"), d.join("j.sqlite")).unwrap();
    refused_after_each_change(d, "j.sqlite", 0, &|p| {
        let db = rusqlite::Connection::open(p).unwrap();
        let n = db.execute("UPDATE trajectory_data SET pos_x = pos_x + 0.5 WHERE frame = 12", []).unwrap();
        assert!(n > 0);
    });

    // The USD crowd holds frames 1-5: shot frame 15 (the reference) is its frame 2.
    let usd = std::fs::read_to_string(common::fixture("usd/pointinstancer_crowd.usda")).unwrap();
    std::fs::write(d.join("u.usda"), &usd).unwrap();
    refused_after_each_change(d, "u.usda", -13, &|p| {
        let text = std::fs::read_to_string(p).unwrap();
        let moved = text.replacen("1: [(-3, 0, -2)", "1: [(-3.5, 0, -2)", 1);
        assert_ne!(moved, text);
        std::fs::write(p, moved).unwrap();
    });
}
