//! Fuzzes the sim scene file as `throng sim` reads it: `SimScene::parse`
//! (as `SimScene::load` calls it), then, for scenes small enough to step
//! quickly (at most 20,000 agent-frames), `sim::run` and the cache write's
//! validation. The scene is placed in `demo/sim/` (by path only, nothing is
//! written there), so the rig files real scenes name exist.
//! Run: `cargo +nightly fuzz run sim_scene` (docs/fuzzing.md).
#![no_main]

use libfuzzer_sys::fuzz_target;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use throng::sim::SimScene;

const SCENE: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../demo/sim/fuzz.toml");
/// Largest agents x simulated frames stepped per input.
const MAX_STEPS: u64 = 20_000;

fn out() -> &'static Path {
    static P: OnceLock<PathBuf> = OnceLock::new();
    P.get_or_init(|| std::env::temp_dir().join(format!("throng-fuzz-sim-{}.crowd", std::process::id())))
}

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else { return };
    let Ok(scene) = SimScene::parse(text, SCENE) else { return };
    let frames = (i64::from(scene.end) - i64::from(scene.first_frame()) + 1).max(0) as u64;
    if (scene.agents.len() as u64).saturating_mul(frames) > MAX_STEPS {
        return;
    }
    let crowd = throng::sim::run(&scene);
    let _ = throng::cache::write(out(), &crowd);
});
