//! `--threads N` caps every stage of a process (docs/render.md, "Threads"):
//! each verb run under `--threads 1` uses no more CPU time than wall time
//! (a second busy thread anywhere, in casting, posing, BVH builds, the
//! render or EXR compression, would push CPU time past wall time). Timed by
//! bash's `time`, which reports the finished child's own user and system
//! seconds.

mod common;

use std::path::Path;
use std::process::Command;

/// (CPU seconds, wall seconds) of `throng --threads 1 ARGS`, which must succeed.
fn cpu_and_wall(args: &[&str]) -> (f64, f64) {
    let out = Command::new("bash")
        .arg("-c")
        .arg("TIMEFORMAT='%3U %3S %3R'; time \"$@\" >/dev/null 2>&1")
        .arg("bash")
        .arg(common::bin())
        .arg("--threads")
        .arg("1")
        .args(args)
        .output()
        .expect("bash runs");
    assert!(out.status.success(), "throng {}: {}", args.join(" "), common::text(&out.stderr));
    let times = common::text(&out.stderr);
    let v: Vec<f64> = times.split_whitespace().filter_map(|t| t.parse().ok()).collect();
    assert_eq!(v.len(), 3, "bash's time printed {times:?}");
    (v[0] + v[1], v[2])
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

#[test]
fn one_thread_means_one_busy_thread_in_every_verb() {
    let dir = common::tempdir().unwrap();
    let d = dir.path();
    let shot = common::demo_shot();
    let shot = s(&shot);
    let manifest = d.join("demo.layers.json");
    let renders = d.join("r");
    let runs: Vec<Vec<String>> = [
        vec!["layers", shot, "--out", s(&manifest)],
        vec!["cast", shot],
        vec![
            "render",
            shot,
            "--manifest",
            s(&manifest),
            "--layer",
            "all",
            "--frames",
            "1024",
            "--spp",
            "4",
            "--resolution",
            "160x90",
            "--shutter",
            "-0.25,0.25",
            "--progress",
            "off",
            "--out",
            s(&renders),
        ],
        vec!["comp", s(&renders), "--frame", "1024", "--manifest", s(&manifest), "--out", s(&d.join("comp.exr"))],
        vec!["export", shot, "--frame", "1024", "--out", s(&d.join("frame.glb"))],
        vec!["export", shot, "--format", "usd", "--frames", "1020-1024", "--out", s(&d.join("shot.usda"))],
        vec!["botinfo", shot, "7", "--frame", "1024"],
    ]
    .into_iter()
    .map(|v| v.into_iter().map(String::from).collect())
    .collect();
    for args in &runs {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        let (cpu, wall) = cpu_and_wall(&args);
        // A little slack for the kernel's accounting granularity.
        assert!(cpu <= wall * 1.05 + 0.05, "throng --threads 1 {}: {cpu:.2} s of CPU in {wall:.2} s", args[0]);
    }
}
