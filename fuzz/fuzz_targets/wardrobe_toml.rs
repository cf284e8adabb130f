//! Fuzzes the wardrobe loader (it reads files, so each input is written to a
//! temporary file first). Run: `cargo +nightly fuzz run wardrobe_toml`.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let path = std::env::temp_dir().join(format!("throng-fuzz-wardrobe-{}.toml", std::process::id()));
    if std::fs::write(&path, data).is_ok() {
        let _ = throng::casting::wardrobe::Wardrobes::load(&[path.clone()]);
    }
});
