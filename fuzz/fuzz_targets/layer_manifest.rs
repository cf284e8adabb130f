//! Fuzzes the layer manifest reader and what render asks of a manifest.
//! Run: `cargo +nightly fuzz run layer_manifest`.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let path = std::env::temp_dir().join(format!("throng-fuzz-{}.layers.json", std::process::id()));
    if std::fs::write(&path, data).is_ok() {
        if let Ok(m) = throng::layers::read_manifest(&path) {
            for layer in &m.comp_order {
                let _ = m.set_visibility(layer);
                for a in m.agents.iter().take(64) {
                    let _ = m.agent_visibility(layer, a.id, m.ref_frame);
                }
            }
            let _ = throng::layers::summary(&m);
        }
    }
});
