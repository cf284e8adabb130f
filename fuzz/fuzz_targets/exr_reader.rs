//! Fuzzes the EXR readers: `render::exr::read_layer` (what botinfo, comp and
//! `render --resume` read back) and `render::exr::mattes::read` (every part,
//! every Cryptomatte type, as botinfo reads any EXR's mattes), and the deep
//! readers (`render::exr::deep`: whole, counts only, header only, and the
//! completeness check `render --resume` and the farm make).
//! Run: `cargo +nightly fuzz run exr_reader` (docs/fuzzing.md).
#![no_main]

use libfuzzer_sys::fuzz_target;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

fn file() -> &'static Path {
    static P: OnceLock<PathBuf> = OnceLock::new();
    P.get_or_init(|| std::env::temp_dir().join(format!("throng-fuzz-{}.exr", std::process::id())))
}

fuzz_target!(|data: &[u8]| {
    let path = file();
    if std::fs::write(path, data).is_err() {
        return;
    }
    let _ = throng::render::exr::read_layer(path);
    let _ = throng::render::exr::mattes::read(path);
    let _ = throng::render::exr::deep::read_deep(path);
    let _ = throng::render::exr::deep::read_sample_counts(path);
    let _ = throng::render::exr::deep::read_deep_header(path);
    let _ = throng::render::exr::deep::is_whole(path);
});
