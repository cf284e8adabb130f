//! Fuzzes the shot parser `Shot::parse`, as `Shot::load` calls it for every
//! verb: any text must give a `Shot` or an error, never a panic. The shot
//! is placed (by path only; nothing is written there) in the repository's
//! `demo/` and `tests/fixtures/stack_shot/`, so the files that real shots
//! name exist and parsing goes on past the "file not found" checks.
//! Run: `cargo +nightly fuzz run shot_toml` (docs/fuzzing.md).
#![no_main]

use libfuzzer_sys::fuzz_target;
use std::path::Path;
use throng::shot::Shot;

const ANCHORS: [&str; 2] = [
    concat!(env!("CARGO_MANIFEST_DIR"), "/../demo/fuzz.shot.toml"),
    concat!(env!("CARGO_MANIFEST_DIR"), "/../tests/fixtures/stack_shot/fuzz.shot.toml"),
];

/// What later stages compute from a loaded shot; none of it may panic.
fn use_shot(shot: &Shot) {
    let f = shot.frames;
    let _ = (f.middle(), f.len(), f.contains(f.end));
    for frame in [f.start, f.middle(), f.end] {
        let _ = shot.cache.cache_frame(frame);
        let _ = shot.cache.shot_frame(shot.cache.cache_frame(frame));
        let _ = shot.keyed_camera(frame as f32);
        let _ = shot.keyed_camera(frame as f32 + 0.5);
    }
    let _ = (shot.aspect(), shot.sun(), shot.sky());
    if let Some(b) = &shot.layers.budget {
        let _ = throng::shot::parse_bytes(b);
    }
}

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    for anchor in ANCHORS {
        if let Ok(shot) = Shot::parse(text, Path::new(anchor)) {
            use_shot(&shot);
        }
    }
    // The --frames and --budget flag values.
    let _ = throng::shot::parse_frame_list(text);
    let _ = throng::shot::parse_bytes(text);
});
