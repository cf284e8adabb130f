//! The shot file: strict parsing, errors that name file, line and key.

mod common;

use std::path::Path;

use throng::shot::Shot;

const GOOD: &str = r#"
version = 1
name = "t"
seed = 5
removed = [7]
[frames]
start = 1001
end = 1011
fps = 24.0
[cache]
path = "c.csv"
frame_offset = -911
[rigs.bipedThinA]
file = "r.glb"
schemes = { A = 1.0 }
[camera]
sensor_width = 36.0
[[camera.keys]]
frame = 1001
position = [0.0, 1.0, 10.0]
aim = [0.0, 1.0, 0.0]
focal_length = 35.0
[[camera.keys]]
frame = 1011
position = [10.0, 1.0, 10.0]
aim = [0.0, 1.0, 0.0]
focal_length = 70.0
[lights.sun]
direction = [0.0, 2.0, 0.0]
"#;

fn dir_with_files() -> common::TempDir {
    let d = common::tempdir().unwrap();
    std::fs::write(d.path().join("c.csv"), "").unwrap();
    std::fs::write(d.path().join("r.glb"), "").unwrap();
    d
}

fn parse(dir: &Path, text: &str) -> Result<Shot, String> {
    let p = dir.join("shot.toml");
    std::fs::write(&p, text).unwrap();
    Shot::load(&p).map_err(|e| e.to_string())
}

#[test]
fn good_shot_parses_and_resolves_paths() {
    let d = dir_with_files();
    let shot = parse(d.path(), GOOD).unwrap();
    assert_eq!(shot.name, "t");
    assert_eq!(shot.cache.cache_frame(1001), 90, "shot 1001 reads cache frame 90");
    assert_eq!(shot.cache.path, d.path().join("c.csv"));
    assert_eq!(shot.rigs["bipedThinA"].height_jitter, 0.1);
    assert_eq!(shot.frames.middle(), 1006);
    assert_eq!(shot.removed, vec![7]);
    assert!((shot.sun().unwrap().direction.length() - 1.0).abs() < 1e-6);
}

#[test]
fn camera_interpolates_between_keys_and_holds_outside() {
    let d = dir_with_files();
    let shot = parse(d.path(), GOOD).unwrap();
    let pos = |f: f32| shot.keyed_camera(f).unwrap().world_from_camera.translation;
    assert!((pos(1006.0).x - 5.0).abs() < 1e-5);
    assert_eq!(pos(900.0).x, 0.0);
    assert_eq!(pos(2000.0).x, 10.0);
    // Longer lens, narrower view.
    assert!(shot.keyed_camera(1011.0).unwrap().yfov < shot.keyed_camera(1001.0).unwrap().yfov);
}

#[test]
fn unknown_key_names_key_line_and_file() {
    let d = dir_with_files();
    let text = GOOD.replace("fps = 24.0", "fps = 24.0\nfsp = 2");
    let err = parse(d.path(), &text).unwrap_err();
    assert!(err.contains("shot.toml:10"), "{err}");
    assert!(err.contains("fsp"), "{err}");
}

#[test]
fn wrong_type_names_key_and_line() {
    let d = dir_with_files();
    let text = GOOD.replace("seed = 5", "seed = \"five\"");
    let err = parse(d.path(), &text).unwrap_err();
    assert!(err.contains("shot.toml:4"), "{err}");
    assert!(err.contains("`seed`"), "{err}");
}

#[test]
fn missing_file_names_key() {
    let d = dir_with_files();
    let text = GOOD.replace("r.glb", "nope.glb");
    let err = parse(d.path(), &text).unwrap_err();
    assert!(err.contains("rigs.bipedThinA.file"), "{err}");
    assert!(err.contains("nope.glb"), "{err}");
    assert!(err.contains("shot.toml:14"), "{err}");
}

#[test]
fn other_versions_are_refused() {
    let d = dir_with_files();
    let err = parse(d.path(), &GOOD.replace("version = 1", "version = 2")).unwrap_err();
    assert!(err.contains("unsupported shot version 2"), "{err}");
}

#[test]
fn bad_values_are_refused() {
    let d = dir_with_files();
    let err = parse(d.path(), &GOOD.replace("end = 1011", "end = 1000")).unwrap_err();
    assert!(err.contains("before start"), "{err}");
    let err = parse(d.path(), &format!("{GOOD}\n[layers]\nbudget = \"3 parsecs\"\n")).unwrap_err();
    assert!(err.contains("layers.budget"), "{err}");
}

/// Found writing the `shot_toml` fuzz target and confirmed through it
/// (docs/fuzzing.md), and fixed on main meanwhile: a lone camera key at
/// frame `nan` made `keyed_camera` index past the end of the keys.
#[test]
fn non_finite_camera_keys_are_refused() {
    let d = dir_with_files();
    let one_key = |from: &str, to: &str| {
        let start = GOOD.find("[[camera.keys]]\nframe = 1011").unwrap();
        let end = GOOD.find("[lights.sun]").unwrap();
        format!("{}{}", &GOOD[..start], &GOOD[end..]).replace(from, to)
    };
    // Each names the key, and the component of a vector.
    for (from, to, says) in [
        ("frame = 1001", "frame = nan", "field `camera.keys[0].frame`: camera key 1 (frame NaN): frame is NaN"),
        ("frame = 1001", "frame = -inf", "field `camera.keys[0].frame`"),
        ("position = [0.0, 1.0, 10.0]", "position = [0.0, inf, 10.0]", "field `camera.keys[0].position[1]`"),
        (
            "aim = [0.0, 1.0, 0.0]",
            "aim = [nan, 1.0, 0.0]",
            "field `camera.keys[0].aim[0]`: camera key 1 (frame 1001): aim x is NaN",
        ),
        (
            "focal_length = 35.0",
            "focal_length = inf",
            "field `camera.keys`: camera key at frame 1001: focal length must be > 0",
        ),
    ] {
        let err = parse(d.path(), &one_key(from, to)).unwrap_err();
        assert!(err.contains("shot.toml") && err.contains(says), "{to}: {err}");
    }
    parse(d.path(), &one_key("", "")).unwrap().keyed_camera(1001.5).unwrap();
}
