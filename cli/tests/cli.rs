//! The binary as a user meets it: every verb is listed in `--help`, the
//! version is the workspace's, and a wrong flag is a usage error (exit 2)
//! that names it. (Having an integration test also makes `cargo test` build
//! the binary that the library's integration tests at the root run.)

use std::process::Command;

fn throng(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_throng")).args(args).output().expect("run throng");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn help_lists_every_verb() {
    let (code, out, _) = throng(&["--help"]);
    assert_eq!(code, 0);
    for verb in
        ["demo", "cache", "sim", "cast", "botinfo", "layers", "render", "comp", "export", "farm", "completions", "man"]
    {
        assert!(out.lines().any(|l| l.trim_start().starts_with(verb)), "--help lists no `{verb}`:\n{out}");
    }
}

#[test]
fn version_is_the_workspace_version() {
    let (code, out, _) = throng(&["--version"]);
    assert_eq!((code, out.trim()), (0, format!("throng {}", env!("CARGO_PKG_VERSION")).as_str()));
}

#[test]
fn an_unknown_flag_is_a_usage_error_naming_it() {
    let (code, _, err) = throng(&["render", "--no-such-flag"]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("--no-such-flag"), "{err}");
}

#[test]
fn completions_offer_no_hidden_verb() {
    for shell in ["bash", "zsh", "fish"] {
        let (code, out, err) = throng(&["completions", shell]);
        assert_eq!(code, 0, "{err}");
        assert!(out.contains("botinfo") && out.contains("plan"), "{shell}: no verbs in the script");
        assert!(!out.contains("run-task"), "{shell} completions offer the hidden `farm run-task`");
    }
}

#[test]
fn man_pages_are_written_whole_with_no_temporary_left() {
    let dir = std::env::temp_dir().join(format!("throng-man-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (code, out, err) = throng(&["man", "--out", dir.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    let mut names: Vec<String> =
        std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    names.sort();
    std::fs::remove_dir_all(&dir).unwrap();
    assert!(out.contains(&format!("wrote {} man pages", names.len())), "{out}");
    for page in ["throng.1", "throng-render.1", "throng-farm.1", "throng-farm-plan.1", "throng-cache-convert.1"] {
        assert!(names.iter().any(|n| n == page), "no {page} in {names:?}");
    }
    assert!(names.iter().all(|n| n.ends_with(".1") && !n.starts_with('.')), "a temporary is left: {names:?}");
    assert!(!names.iter().any(|n| n.contains("run-task")), "the hidden verb has a page: {names:?}");
}
