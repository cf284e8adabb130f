//! Fuzzes the USD crowd import as the CLI runs it on a cache file
//! (`cache info`, `layers`, `render`): `CacheReader::open` on a `.usda`
//! (`.usdc` when the input starts with `PXR-USDC`, `.usdz` when it starts
//! with `PK`), `read_frame` of every frame, `cache::info`, `read_all`.
//! Run: `cargo +nightly fuzz run usd_crowd` (docs/fuzzing.md).
#![no_main]

use libfuzzer_sys::fuzz_target;
use std::path::PathBuf;
use std::sync::OnceLock;
use throng::cache::CacheReader;

fn files() -> &'static [PathBuf; 3] {
    static P: OnceLock<[PathBuf; 3]> = OnceLock::new();
    P.get_or_init(|| {
        let dir = std::env::temp_dir().join(format!("throng-fuzz-usd-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("scratch folder");
        [dir.join("fuzz.usda"), dir.join("fuzz.usdc"), dir.join("fuzz.usdz")]
    })
}

fuzz_target!(|data: &[u8]| {
    let [usda, usdc, usdz] = files();
    let path = if data.starts_with(b"PXR-USDC") {
        usdc
    } else if data.starts_with(b"PK") {
        usdz
    } else {
        usda
    };
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
});
