//! No output ever replaces an input (issue 26 item 1): every verb refuses,
//! with exit 2 and naming both files, an output that is the same file as one
//! it reads (the shot, the cache, a wardrobe texture, the manifest, a layer
//! EXR), also when the output is a symlink or a hard link to it; and the
//! input is left as it was.

mod common;

use std::path::Path;

use common::{run, two_robots, DemoShot};

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 temp path")
}

/// Runs `args`, expects the refusal naming `output` and `input`, and
/// `input`'s bytes unchanged.
fn refused(args: &[&str], output: &Path, input: &Path) {
    let before = std::fs::read(input).unwrap();
    let (code, out, err) = run(args);
    assert_eq!(code, 2, "{args:?} should be refused:\n{out}{err}");
    assert!(err.contains("refusing to write") && err.contains("which this command reads"), "{args:?}:\n{err}");
    assert!(err.contains(s(output)) && err.contains(s(input)), "{args:?}: should name both files:\n{err}");
    assert!(!err.contains("panicked"), "{err}");
    assert_eq!(std::fs::read(input).unwrap(), before, "{args:?}: {} changed", input.display());
}

#[test]
fn layers_refuses_a_manifest_over_the_shot_and_a_map_over_a_texture() {
    let dir = common::tempdir().unwrap();
    let d = dir.path();
    let shot = DemoShot::default().write(d, &two_robots(1..=3));
    refused(&["layers", s(&shot), "--out", s(&shot)], &shot, &shot);
    // The same file by another spelling of its folder.
    let dotted = d.join(".").join("shot.toml");
    refused(&["layers", s(&shot), "--out", s(&dotted)], &dotted, &shot);

    // A wardrobe whose material is textured by t.png: the map may not be t.png.
    std::fs::copy(common::repo_path("wardrobes/textures/hazard.png"), d.join("t.png")).unwrap();
    let part = "slot = \"head\"\nmaterials = [\"tex\"]";
    let w = d.join("w.toml");
    std::fs::write(&w, common::heads_wardrobe("[materials.tex]\nbase_color_texture = \"t.png\"", part)).unwrap();
    common::wear_heads(&shot, s(&w));
    let manifest = d.join("bad.layers.json");
    let (code, out, err) = run(&["layers", s(&shot), "--out", s(&manifest), "--map", s(&d.join("map.png"))]);
    assert_eq!(code, 0, "{out}{err}");
    refused(
        &["layers", s(&shot), "--out", s(&manifest), "--map", s(&d.join("t.png"))],
        &d.join("t.png"),
        &d.join("t.png"),
    );
    // A symlink to the wardrobe.
    std::os::unix::fs::symlink(&w, d.join("w.link")).unwrap();
    refused(&["layers", s(&shot), "--out", s(&d.join("w.link"))], &d.join("w.link"), &w);
}

#[test]
fn export_render_and_cache_convert_refuse_to_write_over_the_cache_the_shot_or_the_manifest() {
    let dir = common::tempdir().unwrap();
    let d = dir.path();
    let shot = DemoShot::default().write(d, &two_robots(1..=3));
    let cache = d.join("c.csv");
    // A symlink to the cache as the glTF export.
    let link = d.join("scene.glb");
    std::os::unix::fs::symlink(&cache, &link).unwrap();
    refused(&["export", s(&shot), "--frame", "1002", "--out", s(&link)], &link, &cache);
    // A hard link to the shot as the USD export.
    let hard = d.join("scene.usda");
    std::fs::hard_link(&shot, &hard).unwrap();
    refused(&["export", s(&shot), "--format", "usd", "--out", s(&hard)], &hard, &shot);
    // The manifest beside the shot, as the export.
    let manifest = d.join("bad.layers.json");
    assert_eq!(run(&["layers", s(&shot)]).0, 0);
    refused(&["export", s(&shot), "--frame", "1002", "--out", s(&manifest)], &manifest, &manifest);

    // A render whose layer file would be a symlink to the manifest.
    let out = d.join("render");
    let target = out.join("crowd0").join("bad.crowd0.1002.exr");
    std::fs::create_dir_all(target.parent().unwrap()).unwrap();
    std::os::unix::fs::symlink(&manifest, &target).unwrap();
    let args = ["render", s(&shot), "--layer", "crowd0", "--frames", "1002", "--progress", "off", "--out", s(&out)];
    refused(&args, &target, &manifest);

    // cache convert over its own input, by a hard link.
    let copy = d.join("copy.csv");
    std::fs::hard_link(&cache, &copy).unwrap();
    refused(&["cache", "convert", s(&cache), s(&copy)], &copy, &cache);
}

#[test]
fn comp_refuses_to_write_over_a_layer_it_stacks() {
    let dir = common::tempdir().unwrap();
    let d = dir.path();
    let shot = DemoShot::default().write(d, &two_robots(1..=3));
    assert_eq!(run(&["layers", s(&shot)]).0, 0);
    let out = d.join("render");
    let (code, o, err) = run(&["render", s(&shot), "--frames", "1002", "--progress", "off", "--out", s(&out)]);
    assert_eq!(code, 0, "{o}{err}");
    let set = out.join("set").join("bad.set.1002.exr");
    let crowd0 = out.join("crowd0").join("bad.crowd0.1002.exr");
    refused(&["comp", s(&out), "--frame", "1002", "--out", s(&set)], &set, &set);
    // Through a hard link and a symlink.
    let hard = d.join("comp.exr");
    std::fs::hard_link(&crowd0, &hard).unwrap();
    refused(&["comp", s(&out), "--frame", "1002", "--out", s(&hard)], &hard, &crowd0);
    let link = d.join("comp.png");
    std::os::unix::fs::symlink(&set, &link).unwrap();
    let ok = d.join("ok.exr");
    refused(&["comp", s(&out), "--frame", "1002", "--out", s(&ok), "--png", s(&link)], &link, &set);
    // An output elsewhere is written.
    let (code, o, err) = run(&["comp", s(&out), "--frame", "1002", "--out", s(&ok)]);
    assert_eq!(code, 0, "{o}{err}");
    assert!(ok.is_file());
}
