//! Fuzzes the shot parser: any text must give a `Shot` or an error, never a
//! panic. Run: `cargo +nightly fuzz run shot_toml` (from the repository root).
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(text) = std::str::from_utf8(data) {
        if let Ok(shot) = throng::shot::Shot::parse(text, std::path::Path::new("/nonexistent/shot.toml")) {
            // What later stages compute from a loaded shot must not overflow.
            let _ = shot.frames.middle();
            let _ = shot.frames.len();
            let _ = shot.cache.cache_frame(shot.frames.end);
            let _ = shot.keyed_camera(shot.frames.start as f32);
        }
    }
    if let Ok(text) = std::str::from_utf8(data) {
        let _ = throng::shot::parse_frame_list(text);
        let _ = throng::shot::parse_bytes(text);
    }
});
