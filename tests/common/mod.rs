//! What every integration test shares: the `throng` binary runner and the
//! paths of fixtures, the demo and the shared assets. Each test crate uses
//! only part of it.
#![allow(dead_code)]

use std::ffi::OsStr;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// Runs the built `throng` binary with `args`.
pub fn throng<S: AsRef<OsStr>>(args: &[S]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_throng")).args(args).output().expect("run the throng binary")
}

/// Runs `throng` and gives (exit code, stdout, stderr); -1 when killed by a signal.
pub fn run<S: AsRef<OsStr>>(args: &[S]) -> (i32, String, String) {
    let out = throng(args);
    (out.status.code().unwrap_or(-1), text(&out.stdout), text(&out.stderr))
}

/// Output bytes as text.
pub fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// A path inside the repository.
pub fn repo_path(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(rel)
}

/// The bundled demo shot.
pub fn demo_shot() -> PathBuf {
    repo_path("demo/shot.toml")
}

/// A file under tests/fixtures.
pub fn fixture(rel: &str) -> PathBuf {
    repo_path("tests/fixtures").join(rel)
}

/// A file under the shared assets, `../shared/assets` beside the repository
/// root. Panics with what is missing, so no test passes without its input.
pub fn shared_asset(rel: &str) -> PathBuf {
    let root = repo_path("../shared");
    assert!(
        root.is_dir(),
        "the shared assets are missing: expected {} (../shared beside the repository root, as CI lays it out)",
        root.display()
    );
    let path = root.join("assets").join(rel);
    assert!(path.exists(), "shared asset {} is missing", path.display());
    path
}
