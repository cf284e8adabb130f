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

#[test]
fn help_and_man_open_with_what_throng_does() {
    let (code, out, _) = throng(&["--help"]);
    assert_eq!(code, 0);
    let first = out.lines().next().unwrap_or_default();
    assert!(first.contains("crowd renderer") && first.contains("lighters"), "{first}");
    assert!(!out.contains("clap"), "{out}");
    let (code, man, _) = throng(&["man"]);
    assert_eq!(code, 0);
    assert!(man.contains("crowd renderer") && !man.contains("clap, printing"), "{man}");
}

#[test]
fn help_takes_help_at_every_level() {
    for args in [
        &["help", "--help"][..],
        &["help"],
        &["help", "render"],
        &["help", "farm", "plan"],
        &["farm", "help", "--help"],
        &["farm", "help", "status"],
        &["cache", "help", "convert"],
    ] {
        let (code, out, err) = throng(args);
        assert_eq!(code, 0, "throng {}: {err}", args.join(" "));
        assert!(out.contains("Usage: throng"), "throng {}: {out}", args.join(" "));
    }
    let (_, out, _) = throng(&["help", "farm", "plan"]);
    let (_, direct, _) = throng(&["farm", "plan", "--help"]);
    assert_eq!(out, direct);
    let (code, _, err) = throng(&["help", "rendr"]);
    assert_eq!(code, 2);
    assert!(err.contains("rendr") && err.contains("render"), "{err}");
}

#[test]
fn every_man_page_has_examples_and_exit_status() {
    let dir = std::env::temp_dir().join(format!("throng-cli-man-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let (code, _, err) = throng(&["man", "--out", dir.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    let pages: Vec<_> = std::fs::read_dir(&dir).unwrap().flatten().map(|e| e.path()).collect();
    assert!(pages.len() > 10, "{pages:?}");
    for page in &pages {
        let text = std::fs::read_to_string(page).unwrap();
        assert!(text.contains(".SH EXAMPLES") && text.contains(".SH \"EXIT STATUS\""), "{}", page.display());
    }
    let status = std::fs::read_to_string(dir.join("throng-farm-status.1")).unwrap();
    assert!(status.contains(".TP\n3\n"), "{status}");
    let (_, top, _) = throng(&["man"]);
    assert!(top.contains(".SH EXAMPLES") && top.contains(".SH \"EXIT STATUS\""));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_bad_number_names_its_argument_and_what_it_takes() {
    for (args, want) in [
        (&["botinfo", "shot.toml", "abc"][..], "agent id"),
        (&["botinfo", "shot.toml", "1", "--frame", "x"], "frame"),
        (&["layers", "shot.toml", "--count", "three"], "count"),
        (&["farm", "submit", "p.json", "--engine", "local", "--workers", "two"], "whole number"),
        (&["review", "shot.toml", "--port", "http"], "port"),
        (&["render", "shot.toml", "--out", "o", "--passes", "difuse_direct"], "unknown pass"),
    ] {
        let (code, _, err) = throng(args);
        assert_eq!(code, 2, "{err}");
        assert!(err.contains(want) && !err.contains("invalid digit"), "throng {}: {err}", args.join(" "));
    }
}

/// `--threads` builds the global pool at once: a pool that cannot start is
/// exit 2 naming `--threads` and why, never a panic inside rayon.
#[test]
fn threads_that_cannot_start_are_a_usage_error_not_a_panic() {
    for n in ["4096", "2048"] {
        let out = Command::new("sh")
            .args(["-c", "ulimit -v 4000000; exec \"$0\" \"$@\"", env!("CARGO_BIN_EXE_throng")])
            .args(["render", "no-such-shot.toml", "--out", "o", "--threads", n])
            .output()
            .expect("run sh");
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{err}");
        assert!(err.contains("--threads") && err.contains("cannot start") && !err.contains("panicked"), "{err}");
    }
}
