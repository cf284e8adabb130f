//! One output folder, one writer (issue 26 item 2): a render claims each
//! layer folder it writes (`output::WriterLock`, recorded in
//! `.throng-writers`), so a second render of the same frames, or of the
//! same layer with other settings, is refused naming the first; a render
//! removes only the temporaries of processes that are gone; and two renders
//! started at once into one folder both end correctly or one refuses, with
//! no frame lost or mixed.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use common::{run, two_robots, DemoShot};
use throng::output::{WriterLock, WRITERS_FILE};
use throng::render::exr::read_layer;

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 temp path")
}

/// The demo shot of two robots on frames 1001-1004 at `spp`, with its manifest.
fn shot(dir: &Path, spp: u32) -> PathBuf {
    let shot = DemoShot { frames: (1001, 1004), spp, ..Default::default() }.write(dir, &two_robots(1..=4));
    let (code, out, err) = run(&["layers", s(&shot)]);
    assert_eq!(code, 0, "{out}{err}");
    shot
}

fn render_args<'a>(shot: &'a Path, out: &'a Path, frames: &'a str, spp: &'a str) -> Vec<&'a str> {
    vec!["render", s(shot), "--frames", frames, "--spp", spp, "--progress", "off", "--out", s(out)]
}

/// Every file under `dir` (relative names), recursively.
fn files(dir: &Path) -> Vec<String> {
    let mut out = Vec::new();
    let Ok(entries) = std::fs::read_dir(dir) else { return out };
    for e in entries.flatten() {
        let p = e.path();
        if p.is_dir() {
            out.extend(files(&p).into_iter().map(|f| format!("{}/{f}", e.file_name().to_string_lossy())));
        } else {
            out.push(e.file_name().to_string_lossy().into_owned());
        }
    }
    out.sort();
    out
}

#[test]
fn a_render_into_a_folder_another_process_writes_is_refused_naming_it() {
    let dir = common::tempdir().unwrap();
    let d = dir.path();
    let shot = shot(d, 1);
    let out = d.join("render");
    // This test process claims frame 1002 of crowd0, as a running render would.
    let held = WriterLock::claim(&out.join("crowd0"), &["bad.crowd0.1002.exr".into()], "").unwrap();
    let (code, o, err) = run(&render_args(&shot, &out, "1002", "1"));
    assert_eq!(code, 2, "{o}{err}");
    let pid = std::process::id().to_string();
    assert!(err.contains("is being written by throng process") && err.contains(&pid), "{err}");
    assert!(err.contains("bad.crowd0.1002.exr") && err.contains(WRITERS_FILE), "{err}");
    // Another frame of the same layer, with no settings compared: rendered.
    let (code, o, err) = run(&render_args(&shot, &out, "1003", "1"));
    assert_eq!(code, 0, "{o}{err}");
    drop(held);
    // Released: the frame renders, and no record is left behind.
    let (code, o, err) = run(&render_args(&shot, &out, "1002", "1"));
    assert_eq!(code, 0, "{o}{err}");
    assert!(!files(&out).iter().any(|f| f.ends_with(WRITERS_FILE) || f.ends_with(".tmp")), "{:?}", files(&out));

    // A claim with other settings on the layer: refused even for other frames.
    let held = WriterLock::claim(&out.join("set"), &["bad.set.1001.exr".into()], "0123456789abcdef").unwrap();
    let (code, _, err) = run(&render_args(&shot, &out, "1004", "1"));
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("with other settings") && err.contains("0123456789abcdef"), "{err}");
    drop(held);
}

#[test]
fn only_the_temporaries_of_processes_that_are_gone_are_removed() {
    let dir = common::tempdir().unwrap();
    let d = dir.path();
    let shot = shot(d, 1);
    let out = d.join("render");
    let folder = out.join("crowd0");
    std::fs::create_dir_all(&folder).unwrap();
    // A pid no process has (above the kernel's pid_max), and this live test process.
    let dead = folder.join(".bad.crowd0.1002.exr.4194305.tmp");
    let live = folder.join(format!(".bad.crowd0.1002.exr.{}.tmp", std::process::id()));
    std::fs::write(&dead, b"killed").unwrap();
    std::fs::write(&live, b"still writing").unwrap();
    // A record left by a killed writer of the same frame: it is gone, so it does not count.
    let stale = r#"{"pid":4194305,"start":1,"host":"HOST","settings":"","targets":["bad.crowd0.1002.exr"]}"#;
    let host = std::fs::read_to_string("/proc/sys/kernel/hostname").unwrap();
    std::fs::write(folder.join(WRITERS_FILE), stale.replace("HOST", host.trim()) + "\n").unwrap();
    let (code, o, err) = run(&render_args(&shot, &out, "1002", "1"));
    assert_eq!(code, 0, "{o}{err}");
    assert!(!dead.exists(), "the dead process's temporary should be removed");
    assert!(live.exists(), "a live process's temporary must be kept:\n{err}");
    assert!(err.contains("removed 1 stale temporary"), "{err}");
    assert!(!folder.join(WRITERS_FILE).exists());
}

#[test]
fn two_renders_at_once_into_one_folder_end_correctly_or_one_refuses() {
    let dir = common::tempdir().unwrap();
    let d = dir.path();
    let shot = shot(d, 1);
    for (round, spps) in [["24", "24"], ["24", "48"]].iter().enumerate() {
        let out = d.join(format!("render{round}"));
        let start = |spp: &str| {
            Command::new(common::bin())
                .args(render_args(&shot, &out, "1001-1004", spp))
                .stdout(Stdio::piped())
                .stderr(Stdio::piped())
                .spawn()
                .unwrap()
        };
        let (a, b) = (start(spps[0]), start(spps[1]));
        let ends: Vec<(i32, String)> = [a, b]
            .into_iter()
            .map(|c| {
                let o = c.wait_with_output().unwrap();
                (o.status.code().unwrap_or(-1), common::text(&o.stderr))
            })
            .collect();
        for (code, err) in &ends {
            assert!(!err.contains("panicked"), "{err}");
            assert!(
                *code == 0 || (*code == 2 && err.contains("is being written by throng process")),
                "round {round}: each render ends correctly or refuses naming the other: exit {code}\n{err}"
            );
        }
        assert!(ends.iter().any(|(c, _)| *c == 0), "round {round}: one render must end: {ends:?}");
        // No frame lost: every layer-frame is there and reads back whole.
        let names = files(&out);
        for layer in ["set", "crowd0", "crowd1"] {
            let mut spp = Vec::new();
            for f in 1001..=1004 {
                let path = out.join(layer).join(format!("bad.{layer}.{f}.exr"));
                let (_, meta) = read_layer(&path).unwrap_or_else(|e| panic!("round {round}: {}: {e}", path.display()));
                spp.push(meta.spp);
            }
            // Not mixed: every frame of a layer is one run's, or the later run said the folder mixes.
            let mixed = spp.iter().any(|&x| x != spp[0]);
            let warned = ends.iter().any(|(_, e)| e.contains("rendered with other settings"));
            assert!(!mixed || warned, "round {round}: {layer} mixes spp {spp:?} without a word: {ends:?}");
        }
        assert!(!names.iter().any(|f| f.ends_with(".tmp") || f.ends_with(WRITERS_FILE)), "round {round}: {names:?}");
    }
}

#[test]
fn a_run_beside_frames_of_other_settings_says_the_folder_will_mix() {
    let dir = common::tempdir().unwrap();
    let d = dir.path();
    let shot = shot(d, 1);
    let out = d.join("render");
    let (code, o, err) = run(&render_args(&shot, &out, "1001-1002", "1"));
    assert_eq!(code, 0, "{o}{err}");
    // The same settings: no word.
    let (code, _, err) = run(&render_args(&shot, &out, "1003", "1"));
    assert_eq!(code, 0, "{err}");
    assert!(!err.contains("other settings"), "{err}");
    // Other settings: rendered, with the warning naming the folder.
    let (code, _, err) = run(&render_args(&shot, &out, "1004", "2"));
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("rendered with other settings") && err.contains("will mix two renders"), "{err}");
    assert!(err.contains(s(&out.join("crowd0"))), "{err}");
}

#[test]
fn strict_turns_the_mixing_warning_into_an_error_before_anything_is_written() {
    let dir = common::tempdir().unwrap();
    let d = dir.path();
    let shot = shot(d, 1);
    let out = d.join("render");
    // Nothing to warn about: --strict changes nothing.
    let mut args = render_args(&shot, &out, "1001-1002", "1");
    args.push("--strict");
    let (code, o, err) = run(&args);
    assert_eq!(code, 0, "{o}{err}");
    let before = files(&out);
    assert!(!before.is_empty());
    // Other settings beside them: an error naming the folder, exit 2, no new frame.
    let mut args = render_args(&shot, &out, "1004", "2");
    args.insert(0, "--strict");
    let (code, _, err) = run(&args);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("error") && err.contains("will mix two renders") && err.contains("--strict"), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    assert_eq!(files(&out), before, "a strict run that refused left files behind");
}
