//! Every allocation bounded before it is made (issue 26 item 4): a layer
//! count, an image whose film cannot fit in the memory the process may use,
//! a gzip bomb past the 2 GiB text limit, and FIFOs, devices and sockets as
//! inputs are each refused with exit 2 and a message, never an abort or a
//! hang. Each case runs under an address-space cap (`ulimit -v`) and a time
//! cap (`timeout`).

mod common;

use std::io::Write;
use std::path::Path;
use std::process::Command;
use std::time::{Duration, Instant};

use common::{two_robots, DemoShot};

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 temp path")
}

/// Address-space cap of every case, KiB (about 3.8 GiB).
const CAP_KB: u64 = 4_000_000;
/// Time cap of every case, seconds.
const TIME_CAP_S: u64 = 60;

/// Runs `throng args` in `dir` under the caps: (exit code, stderr, wall time).
fn capped(dir: &Path, args: &[&str]) -> (i32, String, Duration) {
    let started = Instant::now();
    let out = Command::new("sh")
        .arg("-c")
        .arg(format!("ulimit -v {CAP_KB}; exec timeout {TIME_CAP_S} \"$0\" \"$@\""))
        .arg(common::bin())
        .args(args)
        .current_dir(dir)
        .output()
        .unwrap();
    (out.status.code().unwrap_or(-1), common::text(&out.stderr), started.elapsed())
}

/// Expects a refusal (exit 2, not a timeout's 124 or an abort's 134) saying `says`.
fn refused(dir: &Path, args: &[&str], says: &[&str]) -> Duration {
    let (code, err, took) = capped(dir, args);
    assert_eq!(code, 2, "{args:?}: want exit 2 within {TIME_CAP_S} s under {CAP_KB} KiB:\n{err}");
    assert!(!err.contains("panicked"), "{args:?}:\n{err}");
    for s in says {
        assert!(err.contains(s), "{args:?}: should say `{s}`:\n{err}");
    }
    took
}

#[test]
fn a_layer_count_of_a_hundred_million_is_refused_up_front() {
    let dir = common::tempdir().unwrap();
    let d = dir.path();
    let shot = DemoShot::default().write(d, &two_robots(1..=3));
    refused(d, &["layers", s(&shot), "--count", "100000000"], &["--count 100000000", "at most 1000"]);
    let text = std::fs::read_to_string(&shot).unwrap().replace("count = 2", "count = 100000000");
    std::fs::write(&shot, text).unwrap();
    refused(d, &["layers", s(&shot)], &["layers.count", "at most 1000"]);
    assert!(!d.join("bad.layers.json").exists());
}

#[test]
fn an_image_whose_film_cannot_fit_is_refused_with_the_figures_before_rendering() {
    let dir = common::tempdir().unwrap();
    let d = dir.path();
    let shot = DemoShot::default().write(d, &two_robots(1..=3));
    let out = d.join("o");
    // The documented maximum, 8192 x 8192: some 40 GB of film, over the cap.
    let args = ["render", s(&shot), "--layer", "full", "--frames", "1001", "--progress", "off"];
    let mut big = args.to_vec();
    big.extend(["--resolution", "8192x8192", "--out", s(&out)]);
    let took = refused(d, &big, &["8192x8192", "needs 39.59 GB for its film", "more than the"]);
    assert!(took < Duration::from_secs(20), "refused up front, not after {took:?}");
    assert!(!out.exists(), "nothing is written");
    // The shot's own resolution, the same.
    let text = std::fs::read_to_string(&shot).unwrap().replace("[48, 27]", "[8192, 8192]");
    std::fs::write(&shot, text).unwrap();
    let mut own = args.to_vec();
    own.extend(["--out", s(&out)]);
    refused(d, &own, &["8192x8192", "for its film"]);
}

#[test]
fn a_gzip_bomb_stops_at_the_text_limit() {
    let dir = common::tempdir().unwrap();
    let d = dir.path();
    // One gzip member of 64 MiB of spaces (about 64 KiB), repeated: 33
    // members decompress to 2.06 GiB, past the 2 GiB limit.
    let mut member = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::best());
    let block = vec![b' '; 1 << 20];
    for _ in 0..64 {
        member.write_all(&block).unwrap();
    }
    let member = member.finish().unwrap();
    let mut bomb = std::fs::File::create(d.join("bomb.txt.gz")).unwrap();
    for _ in 0..33 {
        bomb.write_all(&member).unwrap();
    }
    drop(bomb);
    assert!(std::fs::metadata(d.join("bomb.txt.gz")).unwrap().len() < 8 << 20);
    refused(d, &["cache", "info", "bomb.txt.gz", "--preset", "petrack"], &["bomb.txt.gz", "decompresses to more than"]);
}

#[test]
fn fifos_devices_and_sockets_are_refused_as_inputs() {
    let dir = common::tempdir().unwrap();
    let d = dir.path();
    let shot = DemoShot::default().write(d, &two_robots(1..=3));
    let fifo = d.join("pipe");
    let made = Command::new("mkfifo").arg(&fifo).status().unwrap();
    assert!(made.success());
    let _socket = std::os::unix::net::UnixListener::bind(d.join("sock")).unwrap();
    // A shot over the FIFO as its cache, and one wearing it as its wardrobe.
    let text = std::fs::read_to_string(&shot).unwrap();
    std::fs::write(d.join("fifo_cache.toml"), text.replace("path = \"c.csv\"", "path = \"pipe\"")).unwrap();
    let wardrobe = common::repo_path("wardrobes/robots.toml").display().to_string();
    std::fs::write(d.join("fifo_wardrobe.toml"), text.replace(&wardrobe, s(&fifo))).unwrap();
    assert_eq!(common::run(&["layers", s(&shot)]).0, 0);
    let cases: &[(&[&str], &str)] = &[
        (&["layers", "pipe"], "a FIFO"),
        (&["cast", "/dev/zero"], "a device"),
        (&["layers", "sock"], "a socket"),
        (&["layers", "fifo_cache.toml"], "a FIFO"),
        (&["layers", "fifo_wardrobe.toml"], "a FIFO"),
        (&["render", "shot.toml", "--manifest", "pipe", "--frames", "1001", "--out", "o"], "a FIFO"),
        (&["cache", "info", "pipe.csv"], "a FIFO"),
        (&["sim", "pipe", "--out", "x.crowd"], "a FIFO"),
        (&["farm", "status", "pipe"], "a FIFO"),
        (&["botinfo", "shot.toml", "--exr", "pipe.exr", "--pixel", "1,1"], "a FIFO"),
    ];
    std::os::unix::fs::symlink(&fifo, d.join("pipe.csv")).unwrap();
    std::os::unix::fs::symlink(&fifo, d.join("pipe.exr")).unwrap();
    for (args, says) in cases {
        refused(d, args, &[says, "regular files only"]);
    }
}

/// A folder where a file belongs is named as a folder, not left to the
/// reader (SQLite called it a "disk I/O error").
#[test]
fn folders_are_refused_where_files_belong() {
    let dir = common::tempdir().unwrap();
    let d = dir.path();
    let shot = DemoShot::default().write(d, &two_robots(1..=3));
    for folder in ["trajectories.sqlite", "folder.crowd", "folder.csv", "folder.toml", "folder.exr", "folder.json"] {
        std::fs::create_dir(d.join(folder)).unwrap();
    }
    let text = std::fs::read_to_string(&shot).unwrap();
    std::fs::write(d.join("folder_cache.toml"), text.replace("path = \"c.csv\"", "path = \"folder.crowd\"")).unwrap();
    let cases: &[&[&str]] = &[
        &["cache", "info", "trajectories.sqlite"],
        &["cache", "info", "folder.csv"],
        &["layers", "folder.toml"],
        &["layers", "folder_cache.toml"],
        &["render", "shot.toml", "--manifest", "folder.json", "--frames", "1001", "--out", "o"],
        &["botinfo", "shot.toml", "--exr", "folder.exr", "--pixel", "1,1"],
        &["farm", "status", "folder.json"],
    ];
    for args in cases {
        refused(d, args, &["a folder, not a file"]);
    }
}
