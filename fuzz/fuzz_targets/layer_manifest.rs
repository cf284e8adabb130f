//! Fuzzes the layer manifest reader `layers::read_manifest` and what
//! render, comp, botinfo and export ask of a manifest they read.
//! Run: `cargo +nightly fuzz run layer_manifest` (docs/fuzzing.md).
#![no_main]

use libfuzzer_sys::fuzz_target;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

fn file() -> &'static Path {
    static P: OnceLock<PathBuf> = OnceLock::new();
    P.get_or_init(|| std::env::temp_dir().join(format!("throng-fuzz-{}.layers.json", std::process::id())))
}

fuzz_target!(|data: &[u8]| {
    let path = file();
    if std::fs::write(path, data).is_err() {
        return;
    }
    let Ok(m) = throng::layers::read_manifest(path) else { return };
    let layers = throng::render::job::all_layers(&m);
    for layer in m.comp_order.iter().chain(&layers).take(64) {
        let _ = m.set_visibility(layer);
        let _ = m.layer_agents(layer);
        for a in m.agents.iter().take(64) {
            for frame in [m.ref_frame, m.frame_range[0], m.frame_range[1]] {
                let _ = m.agent_visibility(layer, a.id, frame);
            }
        }
    }
    for l in &m.layers {
        let _ = throng::layers::manifest::distance_range(l);
    }
    for a in m.agents.iter().take(64) {
        let _ = m.agent(a.id);
        let _ = m.camera.project(glam::Vec3::from(a.position));
    }
    let _ = throng::layers::summary(&m);
    // comp's layer lookup, in a folder that holds no layers.
    let _ = throng::comp::layer_files(&std::env::temp_dir(), m.ref_frame, Some(&m));
});
