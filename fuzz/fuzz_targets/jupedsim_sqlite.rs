//! Fuzzes the JuPedSim SQLite import as the CLI runs it on a cache file
//! (`cache info`, `cache convert`, `layers`): `CacheReader::open` on a
//! `.sqlite`, `read_frame` of every frame, `cache::info`, `read_all`, and
//! `cache::read_with` under explicit import options (stride and cycle
//! length given, as `--stride` and `--cycle-length` set them).
//! Run: `cargo +nightly fuzz run jupedsim_sqlite` (docs/fuzzing.md).
#![no_main]

use libfuzzer_sys::fuzz_target;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use throng::cache::{CacheReader, ImportOptions};

fn file() -> &'static Path {
    static P: OnceLock<PathBuf> = OnceLock::new();
    P.get_or_init(|| std::env::temp_dir().join(format!("throng-fuzz-{}.sqlite", std::process::id())))
}

fuzz_target!(|data: &[u8]| {
    let path = file();
    if std::fs::write(path, data).is_err() {
        return;
    }
    let _ = CacheReader::open(path).and_then(|r| {
        for &f in r.frames() {
            r.read_frame(f)?;
        }
        throng::cache::info(&r)?;
        r.read_all()
    });
    let opts = ImportOptions::new("bipedTallB", "RunZ", Some(1.7), Some(20.0), None).expect("valid options");
    let _ = throng::cache::read_with(path, &opts);
});
