//! Fuzzes the EXR reader botinfo, comp and `--resume` use (`read_layer`) and
//! the Cryptomatte part reader. Run: `cargo +nightly fuzz run exr_reader`.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let path = std::env::temp_dir().join(format!("throng-fuzz-{}.exr", std::process::id()));
    if std::fs::write(&path, data).is_ok() {
        let _ = throng::render::exr::read_layer(&path);
        let _ = throng::render::exr::read_parts(&path, |n| n.starts_with("Crypto"));
    }
});
