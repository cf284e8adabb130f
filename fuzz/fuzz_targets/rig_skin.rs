//! Fuzzes glTF as the rig loaders read it (`.glb` when the input starts
//! with `glTF`, else `.gltf`): a slot rig (`Rig::load`, its rest pose, slot
//! and node transforms, the `WalkA` cycle sampled at whole and half frames),
//! `Animated::load`, the cache import's `import_clip` (`cache convert
//! --rig-file`), and a skinned character (`SkinnedRig::load` with the
//! shot's default skin options at 24 fps, each cycle's joints at its first
//! steps).
//! Run: `cargo +nightly fuzz run rig_skin` (docs/fuzzing.md).
#![no_main]

use libfuzzer_sys::fuzz_target;
use std::path::PathBuf;
use std::sync::OnceLock;
use throng::casting::rig::{import_clip, Animated, Rig};
use throng::casting::skin::SkinnedRig;
use throng::shot::SkinOptions;

fn files() -> &'static [PathBuf; 2] {
    static P: OnceLock<[PathBuf; 2]> = OnceLock::new();
    P.get_or_init(|| {
        let dir = std::env::temp_dir().join(format!("throng-fuzz-rig-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("scratch folder");
        [dir.join("fuzz.glb"), dir.join("fuzz.gltf")]
    })
}

fuzz_target!(|data: &[u8]| {
    let [glb, gltf] = files();
    let path = if data.starts_with(b"glTF") { glb } else { gltf };
    if std::fs::write(path, data).is_err() {
        return;
    }
    if let Ok(rig) = Rig::load(path) {
        let _ = rig.rest_pose().slot_transforms();
        let _ = rig.rest_pose().node_transforms();
        let _ = rig.slots().len() + rig.root();
        if let Ok(cycle) = rig.cycle("WalkA") {
            let n = cycle.frames(24.0);
            let _ = cycle.stride();
            for f in [0.0, 0.5, 1.0, n * 0.5, n, n + 1.0, -1.0] {
                let _ = cycle.sample(f, 24.0).slot_transforms();
            }
        }
    }
    if let Ok(a) = Animated::load(path) {
        let _ = a.clip("WalkA");
    }
    let _ = import_clip(path, "bipedThinA", "WalkA", None, None);
    if let Ok(skin) = SkinnedRig::load(path, &SkinOptions::default(), 24.0) {
        let _ = skin.height();
        let _ = skin.warnings();
        for (i, c) in skin.cycles().iter().enumerate().take(4) {
            let _ = skin.cycle_frames(i);
            let _ = skin.cycle_index(&c.name);
            for step in 0..c.steps.min(3) {
                let _ = skin.step_joints(i, step);
            }
        }
    }
});
