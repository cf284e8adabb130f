//! Fuzzes a farm plan.json as every engine and `farm status` read it:
//! `farm::read_plan` (format, version, task graph), `farm::open_plan`
//! (the inputs' fingerprint), then, for a plan that opens, `plan_status`
//! and `task` of every task id.
//! Run: `cargo +nightly fuzz run farm_plan` (docs/fuzzing.md).
#![no_main]

use libfuzzer_sys::fuzz_target;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

fn file() -> &'static Path {
    static P: OnceLock<PathBuf> = OnceLock::new();
    P.get_or_init(|| {
        let dir = std::env::temp_dir().join(format!("throng-fuzz-farm-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("scratch folder");
        dir.join("plan.json")
    })
}

fuzz_target!(|data: &[u8]| {
    let path = file();
    if std::fs::write(path, data).is_err() {
        return;
    }
    if throng::farm::read_plan(path).is_err() {
        return;
    }
    let Ok(plan) = throng::farm::open_plan(path, None) else { return };
    for t in &plan.tasks {
        assert!(plan.task(&t.id).is_some(), "task {} not found by its id", t.id);
    }
    let _ = throng::farm::plan_status(&plan);
});
