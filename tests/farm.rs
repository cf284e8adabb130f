//! `throng farm` through the binary: plan determinism and graph shape,
//! fingerprint refusals, the local engine's outputs byte-identical to a local
//! render + comp, status (done, waiting, failed with the log), re-submit of
//! only what is missing, engine errors, and the `--json` summaries and
//! `--progress plain` lines the farm logs rely on. Tiny renders only
//! (32x18, spp 1). A deep plan (`--deep`): deep files are task outputs and a
//! cut one is redone. The real Slurm run is .ci/slurm_test.sh.

mod common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use common::{demo_shot, repo_path, run};
use throng::farm::{read_plan, TaskKind};
use throng::layers::memory;

const FRAMES: &str = "1024-1025";

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 temp path")
}

fn ok(args: &[&str]) -> String {
    let (code, out, err) = run(args);
    assert_eq!(code, 0, "throng {} failed:\n{out}{err}", args.join(" "));
    out
}

/// Plans the demo's two frames at 32x18, spp 1, into `dir`; returns plan.json.
fn plan_demo(shot: &Path, dir: &Path, extra: &[&str]) -> PathBuf {
    let mut args = vec!["farm", "plan", s(shot), "--spp", "1", "--resolution", "32x18", "--out", s(dir)];
    if !extra.contains(&"--frames") {
        args.extend(["--frames", FRAMES]);
    }
    args.extend_from_slice(extra);
    ok(&args);
    dir.join("plan.json")
}

/// Every EXR under `dir`, relative, with its bytes.
fn exrs(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    fn walk(root: &Path, dir: &Path, out: &mut BTreeMap<PathBuf, Vec<u8>>) {
        for e in std::fs::read_dir(dir).expect("read dir").flatten() {
            let p = e.path();
            if p.is_dir() {
                walk(root, &p, out);
            } else if p.extension().is_some_and(|x| x == "exr") {
                out.insert(p.strip_prefix(root).expect("under root").to_path_buf(), std::fs::read(&p).expect("read"));
            }
        }
    }
    let mut out = BTreeMap::new();
    walk(dir, dir, &mut out);
    out
}

/// A copy of the demo shot (and the wardrobes it names by `../`) to edit.
fn demo_copy(root: &Path) -> PathBuf {
    fn copy(from: &Path, to: &Path) {
        std::fs::create_dir_all(to).expect("mkdir");
        for e in std::fs::read_dir(from).expect("read dir").flatten() {
            let p = e.path();
            if p.is_dir() {
                copy(&p, &to.join(e.file_name()));
            } else {
                std::fs::copy(&p, to.join(e.file_name())).expect("copy");
            }
        }
    }
    copy(&repo_path("demo"), &root.join("demo"));
    copy(&repo_path("wardrobes"), &root.join("wardrobes"));
    root.join("demo/shot.toml")
}

#[test]
fn planning_twice_gives_the_same_bytes() {
    let tmp = common::tempdir().unwrap();
    let plan = plan_demo(&demo_shot(), tmp.path(), &["--chunk", "2"]);
    let first = std::fs::read(&plan).unwrap();
    let manifest = std::fs::read(tmp.path().join("demo.layers.json")).unwrap();
    plan_demo(&demo_shot(), tmp.path(), &["--chunk", "2"]);
    assert_eq!(first, std::fs::read(&plan).unwrap(), "plan.json differs between two plannings");
    assert_eq!(manifest, std::fs::read(tmp.path().join("demo.layers.json")).unwrap());
    // --json prints the same plan.
    let (_, json, _) = run(&[
        "farm",
        "plan",
        s(&demo_shot()),
        "--frames",
        FRAMES,
        "--spp",
        "1",
        "--resolution",
        "32x18",
        "--chunk",
        "2",
        "--out",
        s(tmp.path()),
        "--json",
    ]);
    assert_eq!(json.trim_end(), String::from_utf8(first).unwrap().trim_end());
}

#[test]
fn comps_depend_on_their_frames_layer_tasks() {
    let tmp = common::tempdir().unwrap();
    let path = plan_demo(&demo_shot(), tmp.path(), &["--frames", "1024-1026", "--chunk", "2", "--cores", "2"]);
    let plan = read_plan(&path).unwrap();
    let manifest = throng::layers::read_manifest(&plan.manifest).unwrap();
    assert_eq!(plan.layers, manifest.comp_order);
    assert_eq!(plan.frames, vec![1024, 1025, 1026]);
    let renders: Vec<_> = plan.tasks.iter().filter(|t| t.kind == TaskKind::Render).collect();
    let comps: Vec<_> = plan.tasks.iter().filter(|t| t.kind == TaskKind::Comp).collect();
    // (layer, chunk) pairs: 2 chunks (1024-1025, 1026) per layer, one comp per frame.
    assert_eq!(renders.len(), 2 * plan.layers.len());
    assert_eq!(comps.len(), 3);
    for r in &renders {
        let layer = r.layer.as_deref().unwrap();
        assert_eq!(r.argv[..2], ["throng", "render"]);
        assert!(r.argv.windows(2).any(|w| w == ["--layer", layer]));
        assert!(r.argv.windows(2).any(|w| w == ["--threads", "2"]), "cores go to --threads");
        assert_eq!(r.cores, 2);
        assert!(r.depends_on.is_empty());
        assert_eq!(r.outputs.len(), r.frames.len());
        // The one memory model, counted once: the manifest's estimate (which
        // holds the process and the film at the shot's 960x540) with only its
        // film moved to the task's 32x18, rounded up to whole MiB. Adding
        // process or film again, as plans once did, fails this.
        let estimate = manifest.render_memory(layer).unwrap();
        let [mw, mh] = manifest.camera.image_size;
        let moved = memory::at_pixels(estimate, mw as u64 * mh as u64, 32 * 18, Default::default());
        assert_eq!(
            moved,
            estimate - memory::film_bytes(960 * 540, Default::default())
                + memory::film_bytes(32 * 18, Default::default())
        );
        assert_eq!(r.memory_bytes, moved.div_ceil(1 << 20) << 20, "{}: memory from the one model", r.id);
        assert!(r.memory_bytes < estimate, "{}: a smaller image needs less than the shot's", r.id);
        assert!(r.log.starts_with(&plan.log_dir));
    }
    for c in &comps {
        let f = c.frames[0];
        let mut want: Vec<&str> = renders.iter().filter(|r| r.frames.contains(&f)).map(|r| r.id.as_str()).collect();
        want.sort_unstable();
        let mut got: Vec<&str> = c.depends_on.iter().map(String::as_str).collect();
        got.sort_unstable();
        assert_eq!(got, want, "comp of frame {f} depends on exactly that frame's layer tasks");
        assert_eq!(c.argv[..2], ["throng", "comp"]);
    }
    // A subset of layers: render tasks only (a comp needs every layer).
    let sub = plan_demo(&demo_shot(), &tmp.path().join("sub"), &["--layers", "crowd0,set"]);
    let sub = read_plan(&sub).unwrap();
    assert_eq!(sub.layers, ["set", "crowd0"]);
    assert!(sub.tasks.iter().all(|t| t.kind == TaskKind::Render));
}

/// Runs `throng args` and asserts exit 2 with every one of `want` in stderr.
fn refused(args: &[&str], want: &[&str]) -> String {
    let (code, out, err) = run(args);
    assert_eq!(code, 2, "throng {} should exit 2:\n{out}{err}", args.join(" "));
    for w in want {
        assert!(err.contains(w), "stderr of throng {} lacks `{w}`:\n{err}", args.join(" "));
    }
    err
}

#[test]
fn an_edited_shot_or_another_shot_is_refused() {
    let tmp = common::tempdir().unwrap();
    let shot = demo_copy(&tmp.path().join("copy"));
    let plan = plan_demo(&shot, &tmp.path().join("plan"), &[]);
    // The right shot: status answers (not done: exit 1).
    assert_eq!(run(&["farm", "status", s(&plan), "--shot", s(&shot)]).0, 1);
    // Another shot file.
    refused(&["farm", "status", s(&plan), "--shot", s(&demo_shot())], &["plan is for shot `demo`", "shot_file"]);
    refused(&["farm", "submit", s(&plan), "--engine", "local", "--shot", s(&demo_shot())], &["not"]);
    // The shot edited after planning.
    let mut text = std::fs::read_to_string(&shot).unwrap();
    text = text.replace("seed = 1234", "seed = 1235");
    std::fs::write(&shot, text).unwrap();
    let why = ["shot.toml changed since this plan was made", "fingerprint"];
    refused(&["farm", "submit", s(&plan), "--engine", "local"], &why);
    refused(&["farm", "status", s(&plan)], &why);
    refused(&["farm", "run-task", s(&plan), "render.set.0"], &why);
    // Planning the edited shot over the old plan would take its frames as done.
    refused(
        &["farm", "plan", s(&shot), "--frames", FRAMES, "--out", s(&tmp.path().join("plan"))],
        &["made from other inputs", "fingerprint"],
    );
    // A manifest edited after planning is refused too.
    let p2 = plan_demo(&demo_shot(), &tmp.path().join("p2"), &[]);
    let m = tmp.path().join("p2/demo.layers.json");
    let edited = std::fs::read_to_string(&m).unwrap().replacen("\"ref_frame\"", " \"ref_frame\"", 1);
    std::fs::write(&m, edited).unwrap();
    refused(&["farm", "status", s(&p2)], &["layers.json changed since this plan was made"]);
    // Not a plan at all.
    refused(&["farm", "status", s(&m)], &["not a throng farm plan", "format"]);
}

#[test]
fn the_local_engine_matches_a_local_render_and_comp_byte_for_byte() {
    let tmp = common::tempdir().unwrap();
    let plan = plan_demo(&demo_shot(), &tmp.path().join("farm"), &["--chunk", "2"]);
    let out = ok(&["farm", "submit", s(&plan), "--engine", "local", "--workers", "2"]);
    assert!(out.contains("local: comp.1025 done"), "{out}");
    // The same frames and layers rendered and comped by hand.
    let manifest = tmp.path().join("farm/demo.layers.json");
    let local = tmp.path().join("local");
    ok(&[
        "render",
        s(&demo_shot()),
        "--manifest",
        s(&manifest),
        "--frames",
        FRAMES,
        "--spp",
        "1",
        "--resolution",
        "32x18",
        "--out",
        s(&local),
    ]);
    for f in ["1024", "1025"] {
        let comp = local.join(format!("comp/demo.comp.{f}.exr"));
        std::fs::create_dir_all(comp.parent().unwrap()).unwrap();
        ok(&["comp", s(&local), "--frame", f, "--manifest", s(&manifest), "--out", s(&comp)]);
    }
    let farm = exrs(&tmp.path().join("farm/render"));
    let by_hand = exrs(&local);
    assert_eq!(farm.len(), 2 * 4 + 2, "{:?}", farm.keys().collect::<Vec<_>>());
    assert_eq!(farm.keys().collect::<Vec<_>>(), by_hand.keys().collect::<Vec<_>>());
    for (name, bytes) in &farm {
        assert!(bytes == &by_hand[name], "{} differs between the farm and a local render + comp", name.display());
    }
    assert_eq!(run(&["farm", "status", s(&plan)]).0, 0, "status exits 0 when every task is done");
}

#[test]
fn status_reports_waiting_done_and_failed_with_the_log() {
    let tmp = common::tempdir().unwrap();
    let plan = plan_demo(&demo_shot(), tmp.path(), &["--retries", "0"]);
    let (code, out, _) = run(&["farm", "status", s(&plan)]);
    assert_eq!(code, 1, "nothing rendered: not done\n{out}");
    assert!(out.contains("render.set.0") && out.contains("waiting") && out.contains("0 done"), "{out}");
    // A directory where crowd1's EXR of 1024 should go makes that task fail.
    let blocker = tmp.path().join("render/crowd1/demo.crowd1.1024.exr");
    std::fs::create_dir_all(&blocker).unwrap();
    let (code, out, err) = run(&["farm", "submit", s(&plan), "--engine", "local", "--workers", "2"]);
    assert_eq!(code, 2, "a failed task fails the submit:\n{out}{err}");
    let log = tmp.path().join("logs/render.crowd1.0.log");
    assert!(err.contains("render.crowd1.0") && err.contains(s(&log)), "{err}");
    assert!(out.contains("comp.1024 blocked"), "{out}");
    let (code, out, _) = run(&["farm", "status", s(&plan)]);
    assert_eq!(code, 3, "a failed task: exit 3, not 1 (it will not finish by itself)\n{out}");
    let line = out.lines().find(|l| l.starts_with("render.crowd1.0 ")).unwrap_or_default();
    assert!(line.contains("failed") && line.contains(s(&log)), "failed task names its log: {out}");
    assert!(out.lines().any(|l| l.starts_with("render.set.0 ") && l.contains("done")), "{out}");
    assert!(out.lines().any(|l| l.starts_with("comp.1024 ") && l.contains("waiting")), "{out}");
    // JSON status has the same states.
    let (code, json, _) = run(&["farm", "status", s(&plan), "--json"]);
    assert_eq!(code, 3);
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert_eq!(v["done"], false);
    let t = v["tasks"].as_array().unwrap().iter().find(|t| t["id"] == "render.crowd1.0").unwrap();
    assert_eq!(t["state"], "failed");
    assert_eq!(t["log"], s(&log));
    // Fixed, re-submitted: only what was not done runs, and then all is done.
    std::fs::remove_dir(&blocker).unwrap();
    let (code, json, err) = run(&["farm", "submit", s(&plan), "--engine", "local", "--json"]);
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    let mut ran: Vec<&str> = v["ran"].as_array().unwrap().iter().filter_map(|r| r.as_str()).collect();
    ran.sort_unstable();
    assert_eq!(ran, ["comp.1024", "render.crowd1.0"]);
    assert_eq!(run(&["farm", "status", s(&plan)]).0, 0);
}

#[test]
fn a_resubmit_runs_only_what_is_missing() {
    let tmp = common::tempdir().unwrap();
    let plan = plan_demo(&demo_shot(), tmp.path(), &[]);
    ok(&["farm", "submit", s(&plan), "--engine", "local", "--workers", "2"]);
    let untouched = tmp.path().join("render/set/demo.set.1024.exr");
    let before = std::fs::metadata(&untouched).unwrap().modified().unwrap();
    // A truncated EXR is not done; nor is a missing one.
    let cut = tmp.path().join("render/crowd0/demo.crowd0.1025.exr");
    let bytes = std::fs::read(&cut).unwrap();
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    std::fs::remove_file(tmp.path().join("render/comp/demo.comp.1024.exr")).unwrap();
    let (code, json, err) = run(&["farm", "submit", s(&plan), "--engine", "local", "--json"]);
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    let mut ran: Vec<&str> = v["ran"].as_array().unwrap().iter().filter_map(|r| r.as_str()).collect();
    ran.sort_unstable();
    assert_eq!(ran, ["comp.1024", "comp.1025", "render.crowd0.1"]);
    assert_eq!(v["skipped"], 7);
    assert_eq!(std::fs::metadata(&untouched).unwrap().modified().unwrap(), before, "a done task ran again");
    assert_eq!(std::fs::read(&cut).unwrap().len(), bytes.len());
    // Nothing left: nothing runs.
    let (_, json, _) = run(&["farm", "submit", s(&plan), "--engine", "local", "--json"]);
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert_eq!(v["ran"].as_array().unwrap().len(), 0);
}

#[test]
fn engine_errors_are_one_message_and_exit_2() {
    let tmp = common::tempdir().unwrap();
    let plan = plan_demo(&demo_shot(), tmp.path(), &[]);
    refused(&["farm", "submit", s(&plan), "--engine", "tractor"], &["invalid value 'tractor'", "slurm", "local"]);
    // No sbatch on PATH.
    let empty = tmp.path().join("empty-path");
    std::fs::create_dir_all(&empty).unwrap();
    let out = Command::new(common::bin())
        .args(["farm", "submit", s(&plan), "--engine", "slurm"])
        .env("PATH", &empty)
        .output()
        .unwrap();
    let err = common::text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(err.contains("`sbatch` is not on PATH") && err.lines().count() == 1, "{err}");
    // A scheduler that rejects the job: an sbatch that refuses.
    let fake = tmp.path().join("fake-slurm");
    std::fs::create_dir_all(&fake).unwrap();
    let sbatch = fake.join("sbatch");
    std::fs::write(&sbatch, "#!/bin/sh\necho 'sbatch: error: Batch job submission failed: Requested node configuration is not available' >&2\nexit 1\n").unwrap();
    std::fs::set_permissions(&sbatch, std::os::unix::fs::PermissionsExt::from_mode(0o755)).unwrap();
    let out = Command::new(common::bin())
        .args(["farm", "submit", s(&plan), "--engine", "slurm"])
        .env("PATH", &fake)
        .output()
        .unwrap();
    let err = common::text(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("submitting render.set") && err.contains("Requested node configuration is not available"),
        "{err}"
    );
    refused(&["farm", "submit", s(&plan), "--engine", "local", "--workers", "0"], &["--workers: must be 1 to"]);
    refused(&["farm", "plan", s(&demo_shot()), "--chunk", "0", "--out", s(&tmp.path().join("x"))], &["--chunk"]);
    refused(
        &["farm", "plan", s(&demo_shot()), "--frames", "1-5", "--out", s(&tmp.path().join("y"))],
        &["frame 1 is outside shot demo"],
    );
    refused(
        &["farm", "plan", s(&demo_shot()), "--layers", "crowd9", "--out", s(&tmp.path().join("z"))],
        &["no layer `crowd9`"],
    );
}

/// The process id `farm submit` records in the plan's state folder while it
/// holds the plan (`None` once `child` has ended without one).
fn submit_holder(plan_out: &Path, child: &mut std::process::Child) -> Option<u64> {
    let writers = plan_out.join("farm/state/.throng-writers");
    let clock = std::time::Instant::now();
    loop {
        let text = std::fs::read_to_string(&writers).unwrap_or_default();
        let pid = text
            .lines()
            .filter_map(|l| serde_json::from_str::<serde_json::Value>(l).ok())
            .find(|w| w["targets"].as_array().is_some_and(|t| t.iter().any(|t| t == "submit")))
            .and_then(|w| w["pid"].as_u64());
        if pid.is_some() || child.try_wait().unwrap().is_some() || clock.elapsed().as_secs() > 30 {
            return pid;
        }
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
}

#[test]
fn a_second_slurm_submit_while_the_first_submits_is_refused_naming_it() {
    let tmp = common::tempdir().unwrap();
    let plan = plan_demo(&demo_shot(), &tmp.path().join("farm"), &[]);
    // A slow sbatch (and no squeue: nothing queued yet), so the first submit is still submitting.
    let fake = tmp.path().join("fake-slurm");
    std::fs::create_dir_all(&fake).unwrap();
    let sbatch = fake.join("sbatch");
    std::fs::write(&sbatch, "#!/bin/sh\n/bin/sleep 0.3\necho 4242\n").unwrap();
    std::fs::set_permissions(&sbatch, std::os::unix::fs::PermissionsExt::from_mode(0o755)).unwrap();
    let submit = |piped: bool| {
        let mut c = Command::new(common::bin());
        c.args(["farm", "submit", s(&plan), "--engine", "slurm"]).env("PATH", &fake);
        if piped {
            c.stdout(std::process::Stdio::piped()).stderr(std::process::Stdio::piped());
        }
        c
    };
    let mut first = submit(true).spawn().unwrap();
    let holder = submit_holder(&tmp.path().join("farm"), &mut first).expect("the first submit claims the plan");
    let second = submit(false).output().unwrap();
    let err = common::text(&second.stderr);
    assert_eq!(second.status.code(), Some(2), "{err}");
    assert!(
        err.contains("is being submitted by another throng")
            && err.contains(&format!("is being written by throng process {holder} on "))
            && err.lines().count() == 1,
        "{err}"
    );
    let first = first.wait_with_output().unwrap();
    let out = common::text(&first.stdout);
    assert_eq!(first.status.code(), Some(0), "{out}{}", common::text(&first.stderr));
    assert!(out.contains("submitted render.set array") && out.contains("slurm job 4242"), "{out}");
    // Once the first has ended, a submit runs again (no squeue to ask here,
    // so what is not done is submitted again).
    let again = submit(false).output().unwrap();
    assert_eq!(again.status.code(), Some(0), "{}", common::text(&again.stderr));
}

#[test]
fn json_summaries_and_plain_progress() {
    let tmp = common::tempdir().unwrap();
    let plan = plan_demo(&demo_shot(), tmp.path(), &[]);
    let manifest = tmp.path().join("demo.layers.json");
    let out = tmp.path().join("r");
    let (code, json, err) = run(&[
        "render",
        s(&demo_shot()),
        "--manifest",
        s(&manifest),
        "--frames",
        "1024",
        "--layer",
        "crowd0",
        "--spp",
        "1",
        "--resolution",
        "32x18",
        "--progress",
        "plain",
        "--json",
        "--out",
        s(&out),
    ]);
    assert_eq!(code, 0, "{err}");
    assert!(
        err.lines().any(|l| l.starts_with("render: frame 1024 layer crowd0 done [1/1] 100.0%") && l.contains("ETA")),
        "{err}"
    );
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    for key in ["verb", "files_written", "files_skipped", "seconds", "instances", "peak_rss_bytes"] {
        assert!(v.get(key).is_some(), "render --json lacks `{key}`: {json}");
    }
    assert_eq!(v["verb"], "render");
    assert_eq!(v["files_written"][0], s(&out.join("crowd0/demo.crowd0.1024.exr")));
    assert!(v["instances"].as_u64().unwrap() > 0 && v["peak_rss_bytes"].as_u64().unwrap() > 0);
    // --progress off: nothing on stderr.
    let (_, _, err) = run(&[
        "render",
        s(&demo_shot()),
        "--manifest",
        s(&manifest),
        "--frames",
        "1024",
        "--layer",
        "crowd0",
        "--spp",
        "1",
        "--resolution",
        "32x18",
        "--progress",
        "off",
        "--resume",
        "--out",
        s(&out),
    ]);
    assert!(err.is_empty(), "{err}");
    let _ = plan;
    for layer in ["set", "crowd1", "crowd2"] {
        ok(&[
            "render",
            s(&demo_shot()),
            "--manifest",
            s(&manifest),
            "--frames",
            "1024",
            "--layer",
            layer,
            "--spp",
            "1",
            "--resolution",
            "32x18",
            "--progress",
            "off",
            "--out",
            s(&out),
        ]);
    }
    let comp = tmp.path().join("comp.exr");
    let json = ok(&["comp", s(&out), "--frame", "1024", "--manifest", s(&manifest), "--out", s(&comp), "--json"]);
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert_eq!(v["verb"], "comp");
    assert_eq!(v["files_written"][0], s(&comp));
    assert_eq!(v["instances"], 4, "comp counts the layers it stacked");
    let glb = tmp.path().join("f.glb");
    let json = ok(&["export", s(&demo_shot()), "--frame", "1024", "--out", s(&glb), "--json"]);
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert_eq!(v["verb"], "export");
    assert!(v["instances"].as_u64().unwrap() > 0);
    let cache = tmp.path().join("sim.crowd");
    let json = ok(&["sim", s(&repo_path("demo/sim/demo.toml")), "--out", s(&cache), "--json"]);
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    assert_eq!(v["verb"], "sim");
    assert_eq!(v["files_written"][0], s(&cache));
}

/// `farm status PLAN | head`: the exit status is the plan's, whatever reads
/// stdout and whenever it stops (a closed stdout once made it 0).
#[test]
fn status_exits_the_same_into_a_closed_pipe() {
    use std::process::Stdio;
    let tmp = common::tempdir().unwrap();
    let plan = plan_demo(&demo_shot(), tmp.path(), &[]);
    for json in [&[][..], &["--json"]] {
        let mut child = Command::new(common::bin())
            .args(["farm", "status", s(&plan)])
            .args(json)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        drop(child.stdout.take()); // `| true`, or a `| head` that already quit
        let out = child.wait_with_output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "an unfinished plan is 1 into a closed pipe too: {err}");
        assert!(!err.contains("panicked") && !err.contains("Broken pipe"), "{err}");
    }
}

/// Memory of each render task of a plan, by task id.
fn task_memory(plan: &throng::farm::Plan) -> BTreeMap<String, u64> {
    plan.tasks.iter().filter(|t| t.kind == TaskKind::Render).map(|t| (t.id.clone(), t.memory_bytes)).collect()
}

fn denoise_args(plan: &throng::farm::Plan) -> Vec<Option<String>> {
    plan.tasks
        .iter()
        .filter(|t| t.kind == TaskKind::Render)
        .map(|t| t.argv.windows(2).find(|w| w[0] == "--denoise").map(|w| w[1].clone()))
        .collect()
}

#[test]
fn denoising_reaches_every_render_task_from_the_flag_or_the_shot_key() {
    let tmp = common::tempdir().unwrap();
    let plain = read_plan(&plan_demo(&demo_shot(), &tmp.path().join("plain"), &[])).unwrap();
    assert!(denoise_args(&plain).iter().all(Option::is_none), "the demo shot does not denoise");
    let flagged = read_plan(&plan_demo(&demo_shot(), &tmp.path().join("flag"), &["--denoise", "balanced"])).unwrap();
    let bare = read_plan(&plan_demo(&demo_shot(), &tmp.path().join("bare"), &["--denoise"])).unwrap();
    assert!(denoise_args(&flagged).iter().all(|a| a.as_deref() == Some("balanced")));
    assert!(denoise_args(&bare).iter().all(|a| a.as_deref() == Some("high")), "--denoise alone is high");
    assert!(flagged
        .tasks
        .iter()
        .filter(|t| t.kind == TaskKind::Comp)
        .all(|t| !t.argv.iter().any(|a| a == "--denoise")));
    // The denoiser's memory comes on top of the render's: 96 MiB and 1 KiB a
    // pixel of the task's 32x18, in whole MiB.
    let extra = (96u64 << 20) + 1024 * 32 * 18;
    let (before, after) = (task_memory(&plain), task_memory(&flagged));
    assert_eq!(before.len(), after.len());
    for (id, m) in &before {
        assert_eq!(after[id], m + (extra.div_ceil(1 << 20) << 20), "{id}");
    }
    // The shot's key reaches the tasks; the flag overrides it, `off` included.
    let root = tmp.path().join("copy");
    let shot = demo_copy(&root);
    let text = std::fs::read_to_string(&shot).unwrap();
    assert!(text.contains("\n[render]\n"));
    std::fs::write(&shot, text.replacen("\n[render]\n", "\n[render]\ndenoise = \"fast\"\n", 1)).unwrap();
    let keyed = read_plan(&plan_demo(&shot, &tmp.path().join("keyed"), &[])).unwrap();
    assert!(denoise_args(&keyed).iter().all(|a| a.as_deref() == Some("fast")));
    assert_eq!(task_memory(&keyed), after, "memory follows denoising, not its preset");
    let off = read_plan(&plan_demo(&shot, &tmp.path().join("off"), &["--denoise", "off"])).unwrap();
    assert!(denoise_args(&off).iter().all(|a| a.as_deref() == Some("off")));
    assert_eq!(task_memory(&off), before);
    // A planned task runs and denoises as it says, where the library is here.
    match throng_oidn::Library::find(None) {
        Ok(_) => {
            let task = keyed.tasks.iter().find(|t| t.kind == TaskKind::Render).unwrap();
            ok(&["farm", "run-task", s(&tmp.path().join("keyed/plan.json")), &task.id]);
            let (_, meta) = throng::render::exr::read_layer(&task.outputs[0]).unwrap();
            assert!(
                meta.denoiser.starts_with("Open Image Denoise 2.") && meta.denoiser.ends_with("quality fast"),
                "{}",
                meta.denoiser
            );
        }
        Err(e) if std::env::var("THRONG_REQUIRE_OIDN").as_deref() == Ok("1") => panic!("THRONG_REQUIRE_OIDN=1 but {e}"),
        Err(e) => {
            use std::io::Write;
            let _ = writeln!(std::io::stderr(), "SKIPPED running a denoised farm task: {e}");
        }
    }
}

#[test]
fn a_deep_plan_writes_deep_outputs_and_redoes_a_cut_deep_file() {
    use throng::render::exr::deep::{is_whole, read_deep};
    use throng::render::job::deep_layer_path;
    let tmp = common::tempdir().unwrap();
    let plan_path = plan_demo(&demo_shot(), tmp.path(), &["--deep", "--frames", "1024"]);
    let plan = read_plan(&plan_path).unwrap();
    // Every task is told --deep, and its deep files are outputs beside its flat ones.
    let (mut renders, mut comps) = (0, 0);
    for t in &plan.tasks {
        assert!(t.argv.iter().any(|a| a == "--deep"), "{}: {:?}", t.id, t.argv);
        let (deep, flat): (Vec<&PathBuf>, Vec<&PathBuf>) =
            t.outputs.iter().partition(|p| p.to_string_lossy().ends_with(".deep.exr"));
        assert!(!flat.is_empty(), "{}", t.id);
        let beside: Vec<PathBuf> = flat.iter().map(|p| deep_layer_path(p)).collect();
        assert_eq!(deep.into_iter().cloned().collect::<Vec<_>>(), beside, "{}: a deep file per flat one", t.id);
        match t.kind {
            TaskKind::Render => renders += 1,
            TaskKind::Comp => comps += 1,
        }
    }
    assert_eq!((renders, comps), (4, 1));
    ok(&["farm", "submit", s(&plan_path), "--engine", "local", "--workers", "2"]);
    for t in &plan.tasks {
        for p in t.outputs.iter().filter(|p| p.to_string_lossy().ends_with(".deep.exr")) {
            let (deep, head) = read_deep(p).unwrap_or_else(|e| panic!("{}: {e}", t.id));
            assert_eq!((deep.width, deep.height), (32, 18), "{}", p.display());
            let layer = if t.kind == TaskKind::Comp { "comp" } else { t.layer.as_deref().unwrap() };
            assert_eq!(head.text.get("throng/layer").map(String::as_str), Some(layer));
        }
    }
    // The comp task's deep comp flattens to its flat comp.
    let comp = plan.tasks.iter().find(|t| t.kind == TaskKind::Comp).unwrap();
    let flat_comp = comp.outputs.iter().find(|p| !p.to_string_lossy().ends_with(".deep.exr")).unwrap();
    let (deep, _) = read_deep(&deep_layer_path(flat_comp)).unwrap();
    let (flat, _) = throng::render::exr::read_layer(flat_comp).unwrap();
    for (d, f) in deep.flatten().iter().zip(&flat.rgba) {
        for c in 0..4 {
            assert!((d[c] - f[c]).abs() <= 2e-3 * d[c].abs().max(f[c].abs()) + 1e-3, "{d:?} vs {f:?}");
        }
    }
    assert_eq!(run(&["farm", "status", s(&plan_path)]).0, 0);
    // crowd0's deep file one byte short: its task is not done, and a
    // re-submit runs it and the comp over it, and nothing else.
    let victim = plan.tasks.iter().find(|t| t.layer.as_deref() == Some("crowd0")).unwrap();
    let cut = victim.outputs.iter().find(|p| p.to_string_lossy().ends_with(".deep.exr")).unwrap();
    let bytes = std::fs::read(cut).unwrap();
    std::fs::write(cut, &bytes[..bytes.len() - 1]).unwrap();
    assert!(!is_whole(cut));
    let (code, out, _) = run(&["farm", "status", s(&plan_path)]);
    // It ran and its outputs are not whole: failed (exit 3), not done.
    assert_eq!(code, 3, "a cut deep file: not done\n{out}");
    let line = out.lines().find(|l| l.starts_with(&format!("{} ", victim.id))).unwrap_or_default();
    assert!(line.contains("failed") && !line.contains("done"), "{out}");
    let (code, json, err) = run(&["farm", "submit", s(&plan_path), "--engine", "local", "--json"]);
    assert_eq!(code, 0, "{err}");
    let v: serde_json::Value = serde_json::from_str(&json).unwrap();
    let mut ran: Vec<&str> = v["ran"].as_array().unwrap().iter().filter_map(|r| r.as_str()).collect();
    ran.sort_unstable();
    assert_eq!(ran, [comp.id.as_str(), victim.id.as_str()]);
    assert_eq!(std::fs::read(cut).unwrap(), bytes, "re-rendered whole, the same bytes");
    assert_eq!(run(&["farm", "status", s(&plan_path)]).0, 0);
}
