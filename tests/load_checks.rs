//! Inputs checked when loaded, not when drawn (issue 26 item 5): every part
//! of every wardrobe scheme the shot's rigs draw from, and the textures of
//! the materials those parts may wear, are checked when the shot is cast,
//! even when no agent happens to draw them; and a name in `culled_cycles`,
//! `exclude_parts` or `removed` that names nothing is refused; and a slot
//! rig file is the rig the shot says it is.

mod common;

use std::path::Path;

use common::{run, two_robots, DemoShot};

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 temp path")
}

/// `throng cast SHOT` must fail (exit 2) saying each of `says`.
fn refused(shot: &Path, says: &[&str]) {
    let (code, out, err) = run(&["cast", s(shot)]);
    assert_eq!(code, 2, "should be refused:\n{out}{err}");
    assert!(!err.contains("panicked"), "{err}");
    for w in says {
        assert!(err.contains(w), "should say `{w}`:\n{err}");
    }
}

/// The demo shot in `dir` wearing a one-scheme wardrobe of `materials` and
/// the heads part plus `second` (another `[[schemes.Only.parts]]` body).
fn wearing(dir: &Path, materials: &str, second: &str) -> std::path::PathBuf {
    let shot = DemoShot::default().write(dir, &two_robots(1..=3));
    let heads = common::repo_path("demo/parts/heads.glb").display().to_string();
    let mut w = common::heads_wardrobe(materials, "slot = \"head\"\nweight = 1.0");
    w.push_str(&format!("[[schemes.Only.parts]]\nfile = \"{heads}\"\nslot = \"head\"\n{second}\n"));
    let path = dir.join("w.toml");
    std::fs::write(&path, w).unwrap();
    common::wear_heads(&shot, s(&path));
    shot
}

#[test]
fn a_part_no_agent_draws_is_still_checked() {
    let dir = common::tempdir().unwrap();
    let d = dir.path();
    // The second part's weight is so small that neither robot draws it.
    let shot = wearing(d, "", "mesh = \"head_gone\"\nweight = 0.000001");
    refused(&shot, &["heads.glb", "no mesh named `head_gone`", "schemes.Only.parts[1].mesh"]);
    // The same part, excluded by the shot: nothing to check.
    let text = std::fs::read_to_string(&shot).unwrap();
    std::fs::write(&shot, text.replacen("seed = 5\n", "seed = 5\nexclude_parts = [\"head_gone\"]\n", 1)).unwrap();
    let (code, out, err) = run(&["cast", s(&shot)]);
    assert_eq!(code, 0, "{out}{err}");
}

#[test]
fn a_texture_that_is_not_an_image_is_refused_when_the_shot_is_cast() {
    let dir = common::tempdir().unwrap();
    let d = dir.path();
    std::fs::write(d.join("t.png"), "not a picture").unwrap();
    let materials = "[materials.tex]\nbase_color_texture = \"t.png\"";
    let shot = wearing(d, materials, "mesh = \"head_box\"\nweight = 0.000001\nmaterials = [\"tex\"]");
    refused(&shot, &["w.toml", "materials.tex.base_color_texture", "not an image", "schemes.Only.parts[1]"]);
}

#[test]
fn list_entries_that_name_nothing_are_refused() {
    let dir = common::tempdir().unwrap();
    let d = dir.path();
    let shot = DemoShot::default().write(d, &two_robots(1..=3));
    let text = std::fs::read_to_string(&shot).unwrap();
    for (line, says) in [
        ("culled_cycles = [\"IdleA\", \"WalkZ\"]", &["culled_cycles[1]", "`WalkZ` is no cycle of the cache"][..]),
        ("exclude_parts = [\"head_gonee\"]", &["exclude_parts[0]", "`head_gonee` is no part mesh"]),
        ("removed = [2, 99]", &["removed[1]", "agent 99 is in none of the shot's frames"]),
    ] {
        std::fs::write(&shot, text.replacen("seed = 5\n", &format!("seed = 5\n{line}\n"), 1)).unwrap();
        refused(&shot, says);
    }
    // Names that name something pass.
    std::fs::write(&shot, text.replacen("seed = 5\n", "seed = 5\nremoved = [2]\nculled_cycles = [\"IdleA\"]\n", 1))
        .unwrap();
    let (code, out, err) = run(&["cast", s(&shot)]);
    assert_eq!(code, 0, "{out}{err}");
}

/// A slot rig's file names its rig (its top node). Two rigs whose files are
/// swapped cast as each other, so that is refused naming the key; a file
/// under a name that is no rig of the shot is legal, with a warning that
/// `--strict` turns into an error.
#[test]
fn a_rig_file_swapped_for_another_rigs_is_refused() {
    let dir = common::tempdir().unwrap();
    let d = dir.path();
    let shot = DemoShot::default().write(d, &two_robots(1..=3));
    let text = std::fs::read_to_string(&shot).unwrap();
    let demo = common::repo_path("demo").display().to_string();
    let tall = format!("\n[rigs.bipedTallB]\nfile = \"{demo}/rigs/bipedTallB.glb\"\nschemes = {{ HighEnd = 1.0 }}\n");
    let both = text.replacen("\n[set]", &format!("{tall}\n[set]"), 1);
    std::fs::write(&shot, &both).unwrap();
    let (code, out, err) = run(&["cast", s(&shot)]);
    assert_eq!(code, 0, "the two rigs as they are:\n{out}{err}");
    assert!(!err.contains("names its rig"), "{err}");

    let swapped =
        both.replace("rigs/bipedThinA.glb", "rigs/SWAP").replace("rigs/bipedTallB.glb", "rigs/bipedThinA.glb");
    std::fs::write(&shot, swapped.replace("rigs/SWAP", "rigs/bipedTallB.glb")).unwrap();
    refused(&shot, &["bipedThinA.glb", "rigs.bipedTallB.file", "is rig `bipedThinA`", "are the two files swapped"]);

    // One file under a name of its own: cast, with a warning.
    let renamed = both.replace("[rigs.bipedTallB]", "[rigs.tallHero]");
    std::fs::write(&shot, renamed).unwrap();
    let (code, out, err) = run(&["cast", s(&shot)]);
    assert_eq!(code, 0, "{out}{err}");
    assert!(err.contains("rigs.tallHero.file") && err.contains("names its rig `bipedTallB`"), "{err}");
    let (code, _, err) = run(&["--strict", "cast", s(&shot)]);
    assert_eq!(code, 2, "--strict refuses the warning:\n{err}");
}
