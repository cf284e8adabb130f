//! Issue 15: every input the 161-case matrix found accepted silently is now
//! an error naming the file (exit 2) or a documented rule with a warning;
//! runaway sizes are refused before allocating; `--resume` compares render
//! fingerprints and removes stale temporaries; CLI conventions (closed
//! stdout, `--version` on verbs, completions, man page); and the EXR header
//! (OpenEXR `worldToNDC`, `chromaticities`, `framesPerSecond`, compression).

mod common;
use exr::prelude::{ReadChannels, ReadLayers};

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use common::{heads_wardrobe, repo_path, run, throng, two_robots, wear_heads, DemoShot};

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 temp path")
}

/// The base shot in `dir` ([`DemoShot`]): cache rows `(frame, id, x, z)`,
/// shot frames `start..=end` (cache frame = shot frame - 1000),
/// `frames_extra` inside `[frames]`.
fn shot_with(dir: &Path, rows: &[(i32, u64, f32, f32)], frames: (i64, i64), frames_extra: &str) -> PathBuf {
    DemoShot { frames, frames_extra, ..DemoShot::default() }.write(dir, rows)
}

fn rows() -> Vec<(i32, u64, f32, f32)> {
    two_robots(1..=3)
}

fn shot(dir: &Path) -> PathBuf {
    shot_with(dir, &rows(), (1001, 1003), "")
}

/// Runs throng; asserts exit 2 and no panic; returns stderr.
fn fails(args: &[&str]) -> String {
    let (code, out, err) = run(args);
    assert_eq!(code, 2, "throng {} should exit 2:\n{out}{err}", args.join(" "));
    assert!(!err.contains("panicked"), "{err}");
    err
}

fn succeeds(args: &[&str]) -> (String, String) {
    let (code, out, err) = run(args);
    assert_eq!(code, 0, "throng {} failed:\n{out}{err}", args.join(" "));
    (out, err)
}

// ------------------------------------------------ item 3: stale manifests

#[test]
fn render_refuses_a_manifest_made_before_the_cache_changed() {
    let dir = common::tempdir().unwrap();
    let shot = shot(dir.path());
    let m = dir.path().join("bad.layers.json");
    succeeds(&["layers", s(&shot), "--out", s(&m)]);
    let manifest = throng::layers::read_manifest(&m).unwrap();
    let made = manifest.made_from.expect("manifest records made_from");
    assert_eq!(made.frames, [1001, 1003]);
    // The cache changes: an agent moves.
    let mut r = rows();
    r[0].2 += 1.0;
    shot_with(dir.path(), &r, (1001, 1003), "");
    let err = fails(&["render", s(&shot), "--manifest", s(&m), "--frames", "1001", "--out", s(&dir.path().join("o"))]);
    assert!(err.contains("bad.layers.json") && err.contains("stale") && err.contains("cache"), "{err}");
    assert!(err.contains("made_from"), "{err}");
}

#[test]
fn render_refuses_a_manifest_made_for_other_frames_or_casting() {
    let dir = common::tempdir().unwrap();
    let shot = shot(dir.path());
    let m = dir.path().join("bad.layers.json");
    succeeds(&["layers", s(&shot), "--out", s(&m)]);
    let text = std::fs::read_to_string(&shot).unwrap();
    std::fs::write(&shot, text.replace("end = 1003", "end = 1002").replace("seed = 5", "seed = 6")).unwrap();
    let err = fails(&["render", s(&shot), "--manifest", s(&m), "--frames", "1001", "--out", s(&dir.path().join("o"))]);
    assert!(err.contains("frames changed from 1001-1003 to 1001-1002"), "{err}");
    assert!(err.contains("casting inputs changed"), "{err}");
}

// ------------------------------------------------ item 3: frames outside the cache

#[test]
fn shot_frames_past_the_cache_or_in_a_gap_are_an_error() {
    let dir = common::tempdir().unwrap();
    // Past the end: the cache holds 1-3, the shot asks for 1001-1005.
    let shot = shot_with(dir.path(), &rows(), (1001, 1005), "");
    let err = fails(&["layers", s(&shot), "--out", s(&dir.path().join("m.json"))]);
    assert!(err.contains("shot.toml") && err.contains("frame 1004") && err.contains("outside_cache"), "{err}");
    // A gap: cache frame 2 missing.
    let gap: Vec<_> = rows().into_iter().filter(|r| r.0 != 2).collect();
    let shot = shot_with(dir.path(), &gap, (1001, 1003), "");
    let err = fails(&["cast", s(&shot)]);
    assert!(err.contains("frame 1002") && err.contains("c.csv"), "{err}");
}

#[test]
fn frames_outside_the_cache_render_empty_when_the_shot_asks_with_a_warning() {
    let dir = common::tempdir().unwrap();
    let shot = shot_with(dir.path(), &rows(), (1001, 1004), "outside_cache = \"empty\"");
    let (_, err) = succeeds(&["layers", s(&shot), "--out", s(&dir.path().join("bad.layers.json"))]);
    assert!(err.contains("warning") && err.contains("1004") && err.contains("no agents"), "{err}");
    // A pipeline's --strict makes the warning an error, and no manifest is written.
    let strict = dir.path().join("strict.layers.json");
    let err = fails(&["layers", s(&shot), "--strict", "--out", s(&strict)]);
    assert!(err.contains("error") && err.contains("1004") && err.contains("--strict"), "{err}");
    assert!(!strict.exists());
}

// ------------------------------------------------ item 3: ids, pins, wardrobes

#[test]
fn an_agent_id_that_agent_id_channels_cannot_hold_is_refused_at_load() {
    let dir = common::tempdir().unwrap();
    let mut r = rows();
    r.insert(2, (1, u32::MAX as u64, 0.0, 0.0));
    let shot = shot_with(dir.path(), &r, (1001, 1003), "");
    let err = fails(&["cast", s(&shot)]);
    assert!(err.contains("c.csv") && err.contains("agent 4294967295") && err.contains("field `id`"), "{err}");
}

#[test]
fn a_pin_to_layer_7_of_2_is_refused() {
    let dir = common::tempdir().unwrap();
    let shot = shot_with(dir.path(), &rows(), (1001, 1003), "");
    let text =
        std::fs::read_to_string(&shot).unwrap().replace("count = 2", "count = 2\npins = [{ agent = 1, layer = 7 }]");
    std::fs::write(&shot, text).unwrap();
    let err = fails(&["layers", s(&shot), "--out", s(&dir.path().join("m.json"))]);
    assert!(err.contains("agent 1") && err.contains("layers.pins"), "{err}");
}

fn wardrobe_shot(dir: &Path, part: &str) -> PathBuf {
    let w = dir.join("w.toml");
    let materials =
        "[materials.red]\nbase_color = [0.6, 0.05, 0.04]\n[materials.blue]\nbase_color = [0.05, 0.15, 0.55]";
    std::fs::write(&w, heads_wardrobe(materials, part)).unwrap();
    let shot = shot(dir);
    wear_heads(&shot, &w.display().to_string());
    shot
}

#[test]
fn all_zero_material_weights_are_refused() {
    let dir = common::tempdir().unwrap();
    let shot =
        wardrobe_shot(dir.path(), "slot = \"head\"\nmaterials = [\"red\", \"blue\"]\nmaterial_weights = [0.0, 0.0]");
    let err = fails(&["cast", s(&shot)]);
    assert!(err.contains("w.toml") && err.contains("schemes.Only.parts[0].material_weights"), "{err}");
}

#[test]
fn a_part_for_a_slot_the_rig_lacks_is_refused() {
    let dir = common::tempdir().unwrap();
    let shot = wardrobe_shot(dir.path(), "slot = \"tail\"\nmaterials = [\"red\"]");
    let err = fails(&["cast", s(&shot)]);
    assert!(err.contains("w.toml") && err.contains("slot `tail`") && err.contains("bipedThinA"), "{err}");
    assert!(err.contains("schemes.Only.parts[0].slot"), "{err}");
}

// ------------------------------------------------ item 3: flags and runaway sizes

#[test]
fn spp_and_threads_zero_are_refused_not_replaced() {
    let dir = common::tempdir().unwrap();
    let shot = shot(dir.path());
    let out = dir.path().join("o");
    for flag in [["--spp", "0"], ["--threads", "0"], ["--spp", "1000000"]] {
        let err =
            fails(&["render", s(&shot), "--layer", "full", "--frames", "1001", "--out", s(&out), flag[0], flag[1]]);
        assert!(err.contains(flag[0]), "{err}");
    }
    assert!(!out.exists());
}

/// One rule for every verb that writes a file: its folder must exist.
#[test]
fn output_files_need_an_existing_folder_in_every_verb() {
    let dir = common::tempdir().unwrap();
    let shot = shot(dir.path());
    let out = |name: &str| dir.path().join("no/such/folder").join(name).to_str().unwrap().to_string();
    let cache = common::fixture("jupedsim_small.sqlite");
    let render = dir.path().join("r");
    let cases: Vec<Vec<String>> = vec![
        vec!["export".into(), s(&shot).into(), "--frame".into(), "1001".into(), "--out".into(), out("x.glb")],
        vec!["layers".into(), s(&shot).into(), "--out".into(), out("x.layers.json")],
        vec!["cache".into(), "convert".into(), s(&cache).into(), out("x.crowd")],
        vec!["sim".into(), s(&common::repo_path("demo/sim/demo.toml")).into(), "--out".into(), out("x.crowd")],
        vec!["comp".into(), s(&render).into(), "--frame".into(), "1001".into(), "--out".into(), out("x.exr")],
    ];
    for args in &cases {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let err = fails(&args);
        assert!(err.contains("does not exist") && err.contains("no/such/folder"), "throng {}: {err}", args.join(" "));
    }
    assert!(!dir.path().join("no").exists());
}

#[test]
fn a_huge_shot_resolution_is_refused_before_any_allocation() {
    let dir = common::tempdir().unwrap();
    let shot = shot(dir.path());
    let text = std::fs::read_to_string(&shot).unwrap().replace("[48, 27]", "[100000, 100000]");
    std::fs::write(&shot, text).unwrap();
    let err = fails(&["render", s(&shot), "--layer", "full", "--frames", "1001", "--out", s(&dir.path().join("o"))]);
    assert!(err.contains("shot.toml") && err.contains("render.resolution"), "{err}");
    // 16384 x 16384 a side is in range but too many pixels.
    let err = fails(&["render", s(&shot), "--resolution", "16384x16384", "--out", s(&dir.path().join("o"))]);
    assert!(err.contains("resolution"), "{err}");
}

#[test]
fn a_four_billion_frame_list_is_refused_before_allocating() {
    let dir = common::tempdir().unwrap();
    let shot = shot(dir.path());
    let err = fails(&["render", s(&shot), "--frames=-2147483648-2147483647", "--out", s(&dir.path().join("o"))]);
    assert!(err.contains("more than 100000 frames"), "{err}");
    // And a shot that long.
    let shot = shot_with(dir.path(), &rows(), (-2147483648, 2147483647), "");
    let err = fails(&["cast", s(&shot)]);
    assert!(err.contains("frames") && err.contains("more than a shot may hold"), "{err}");
}

#[test]
fn frame_plus_frame_offset_overflow_is_an_error() {
    let dir = common::tempdir().unwrap();
    let shot = shot_with(dir.path(), &rows(), (1001, 1003), "");
    let text = std::fs::read_to_string(&shot).unwrap().replace("frame_offset = -1000", "frame_offset = -2147483000");
    std::fs::write(&shot, text.replace("start = 1001", "start = -1001")).unwrap();
    let err = fails(&["cast", s(&shot)]);
    assert!(err.contains("cache.frame_offset") && err.contains("not a representable"), "{err}");
}

// ------------------------------------------------ item 4: resume

#[test]
fn resume_rerenders_frames_made_with_other_settings_and_removes_stale_temporaries() {
    let dir = common::tempdir().unwrap();
    let shot = shot(dir.path());
    let out = dir.path().join("o");
    let base = ["render", s(&shot), "--layer", "full", "--frames", "1001-1002", "--progress", "off", "--json"];
    let with = |extra: &[&str]| {
        let mut a: Vec<&str> = base.to_vec();
        a.extend_from_slice(&["--out", s(&out)]);
        a.extend_from_slice(extra);
        let (o, e) = succeeds(&a);
        (serde_json::from_str::<serde_json::Value>(&o).unwrap(), e)
    };
    with(&["--spp", "1"]);
    let exr = out.join("full/bad.full.1001.exr");
    let fp1 = throng::render::exr::read_layer(&exr).unwrap().1.render_fingerprint;
    assert_eq!(fp1.len(), 16);
    // Same settings: both skipped.
    let (j, _) = with(&["--spp", "1", "--resume"]);
    assert_eq!(j["files_skipped"].as_array().unwrap().len(), 2, "{j}");
    // A kill left a temporary behind (another pid).
    let tmp = out.join("full/.bad.full.1002.exr.999999999.tmp");
    std::fs::write(&tmp, b"partial").unwrap();
    // Other spp: re-rendered, with a warning naming the file.
    let (j, err) = with(&["--spp", "2", "--resume"]);
    assert_eq!(j["files_written"].as_array().unwrap().len(), 2, "{j}");
    assert!(err.contains("bad.full.1001.exr") && err.contains("other settings"), "{err}");
    assert!(err.contains("stale temporary"), "{err}");
    assert!(!tmp.exists(), "the stale temporary is removed");
    let fp2 = throng::render::exr::read_layer(&exr).unwrap().1.render_fingerprint;
    assert_ne!(fp1, fp2);
    // Other resolution: re-rendered too.
    let (j, _) = with(&["--spp", "2", "--resolution", "32x18", "--resume"]);
    assert_eq!(j["files_written"].as_array().unwrap().len(), 2, "{j}");
}

// ------------------------------------------------ item 5: CLI conventions

#[test]
fn a_closed_stdout_ends_quietly_with_status_0() {
    let bin = common::bin();
    let shot = repo_path("demo/shot.toml");
    // More than a pipe buffer (64 KiB) of JSON: the demo's 12 agents, 30 times.
    let ids: Vec<String> = (0..360).map(|i| (i % 12 + 1).to_string()).collect();
    let mut child = Command::new(bin)
        .args(["botinfo", s(&shot)])
        .args(&ids)
        .arg("--json")
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take()); // `| head` that already quit
    let out = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{err}");
    assert!(!err.contains("panicked") && !err.contains("Broken pipe"), "{err}");
}

#[test]
fn every_verb_takes_version() {
    for verb in ["render", "comp", "layers", "botinfo", "cast", "export", "demo", "sim", "review", "completions", "man"]
    {
        let (code, out, err) = run(&[verb, "--version"]);
        assert_eq!(code, 0, "{verb} --version: {err}");
        assert!(out.contains(env!("CARGO_PKG_VERSION")), "{verb}: {out}");
    }
    let (code, out, _) = run(&["farm", "plan", "--version"]);
    assert_eq!(code, 0);
    assert!(out.contains(env!("CARGO_PKG_VERSION")));
}

#[test]
fn completions_and_man_pages() {
    for shell in ["bash", "zsh", "fish"] {
        let (out, _) = succeeds(&["completions", shell]);
        assert!(out.contains("throng") && out.contains("render"), "{shell}");
        // Only what a user types: not the engines' hidden `farm run-task`;
        // the global flags are offered.
        assert!(!out.contains("run-task") && out.contains("strict") && out.contains("threads"), "{shell}");
    }
    fails(&["completions", "tcsh"]);
    // So does the farm's help.
    let (help, _) = succeeds(&["farm", "--help"]);
    assert!(!help.contains("run-task") && help.contains("submit"), "{help}");
    let (man, _) = succeeds(&["man"]);
    assert!(man.contains(".TH") && man.contains("throng"), "{man}");
    let dir = common::tempdir().unwrap();
    succeeds(&["man", "--out", s(dir.path())]);
    assert!(dir.path().join("throng.1").exists() && dir.path().join("throng-render.1").exists());
    fails(&["man", "--out", s(&dir.path().join("missing"))]);
}

// ------------------------------------------------ item 1: the EXR header

#[test]
fn world_to_ndc_projects_an_agent_onto_its_pixels() {
    let dir = common::tempdir().unwrap();
    let shot = shot(dir.path());
    let out = dir.path().join("o");
    succeeds(&[
        "render",
        s(&shot),
        "--layer",
        "full",
        "--frames",
        "1001",
        "--resolution",
        "160x90",
        "--spp",
        "1",
        "--progress",
        "off",
        "--out",
        s(&out),
    ]);
    let (film, meta) = throng::render::exr::read_layer(&out.join("full/bad.full.1001.exr")).unwrap();
    let m = glam::Mat4::from_cols_array(&meta.world_to_ndc);
    // Agent 1 stands at (-0.8, 0, 1.0) at cache frame 1, agent 2 at (0.9, 0, -1.0): their chests.
    for (id, x, z) in [(1u32, -0.8f32, 1.0f32), (2, 0.9, -1.0)] {
        let ndc = m.project_point3(glam::Vec3::new(x, 1.1, z));
        assert!((0.0..1.0).contains(&ndc.x) && (0.0..1.0).contains(&ndc.y), "{ndc}");
        assert!(ndc.z > 0.0 && ndc.z < 1.0, "{ndc}");
        let (px, py) = ((ndc.x * film.width as f32) as u32, (ndc.y * film.height as f32) as u32);
        assert_eq!(film.agent_id[film.index(px, py)], id + 1, "agent {id} at pixel {px},{py} (ndc {ndc})");
    }
    assert_eq!(meta.fps, 24.0);
    // chromaticities and framesPerSecond as OpenEXR attributes.
    let image = exr::prelude::read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_file(out.join("full/bad.full.1001.exr"))
        .unwrap();
    let c = image.attributes.chromaticities.expect("chromaticities");
    assert_eq!((c.red.0, c.green.1, c.white.0), (0.64, 0.60, 0.3127));
    assert_eq!(image.layer_data.attributes.frames_per_second, Some((24, 1)));
}

#[test]
fn compression_is_chosen_and_lossless_by_default() {
    use exr::prelude::Compression;
    let dir = common::tempdir().unwrap();
    let shot = shot(dir.path());
    let read = |out: &Path| {
        let image = exr::prelude::read()
            .no_deep_data()
            .largest_resolution_level()
            .all_channels()
            .first_valid_layer()
            .all_attributes()
            .from_file(out.join("full/bad.full.1001.exr"))
            .unwrap();
        image.layer_data.encoding.compression
    };
    let mut films = Vec::new();
    for (flag, want) in [(None, Compression::ZIP16), (Some("piz"), Compression::PIZ), (Some("b44"), Compression::B44)] {
        let out = dir.path().join(flag.unwrap_or("default"));
        let mut args = vec!["render", s(&shot), "--layer", "full", "--frames", "1001", "--progress", "off"];
        if let Some(f) = flag {
            args.extend_from_slice(&["--compression", f]);
        }
        args.extend_from_slice(&["--out", s(&out)]);
        succeeds(&args);
        assert_eq!(read(&out), want);
        films.push(throng::render::exr::read_layer(&out.join("full/bad.full.1001.exr")).unwrap().0);
    }
    // PIZ is lossless; B44 keeps agent.id and Cryptomatte exact.
    assert_eq!(films[0].rgba, films[1].rgba);
    assert_eq!(films[0].agent_id, films[2].agent_id);
    assert_eq!(films[0].cryptomatte, films[2].cryptomatte);
    let _ = throng(&["--version"]);
}

#[test]
fn a_layer_map_into_a_missing_folder_is_refused_like_every_other_output() {
    let dir = common::tempdir().unwrap();
    let shot = shot_with(dir.path(), &rows(), (1001, 1003), "");
    let (m, missing) = (dir.path().join("m.layers.json"), dir.path().join("nope").join("map.png"));
    let err = fails(&["layers", s(&shot), "--out", s(&m), "--map", s(&missing)]);
    assert!(err.contains("--map") && err.contains("nope"), "{err}");
    assert!(!dir.path().join("nope").exists() && !m.exists());
}
