//! Fuzzes the wardrobe loader `Wardrobes::load` (it reads files, so each
//! input is written to a file first). The file sits in a scratch
//! `wardrobes/` folder beside links to the repository's `demo/` and
//! `wardrobes/textures/`, as the real wardrobes do, so the part files and
//! textures they name exist and loading goes on past "not found".
//! Run: `cargo +nightly fuzz run wardrobe_toml` (docs/fuzzing.md).
#![no_main]

use libfuzzer_sys::fuzz_target;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use throng::casting::wardrobe::Wardrobes;

fn file() -> &'static Path {
    static P: OnceLock<PathBuf> = OnceLock::new();
    P.get_or_init(|| {
        let repo = Path::new(env!("CARGO_MANIFEST_DIR")).join("..").canonicalize().expect("repository");
        let root = std::env::temp_dir().join(format!("throng-fuzz-wardrobe-{}", std::process::id()));
        let dir = root.join("wardrobes");
        std::fs::create_dir_all(&dir).expect("scratch folder");
        let link = |target: PathBuf, at: PathBuf| {
            if !at.exists() {
                std::os::unix::fs::symlink(target, at).expect("symlink");
            }
        };
        link(repo.join("demo"), root.join("demo"));
        link(repo.join("wardrobes/textures"), dir.join("textures"));
        dir.join("fuzz.toml")
    })
}

fuzz_target!(|data: &[u8]| {
    let path = file();
    if std::fs::write(path, data).is_err() {
        return;
    }
    if let Ok(w) = Wardrobes::load(&[path.to_path_buf()]) {
        // What casting asks of a loaded wardrobe.
        let slots: Vec<&str> = w.slots().into_iter().collect();
        let schemes = w.schemes.keys().map(|k| (k.clone(), 1.0)).collect();
        let _ = w.check_slots("fuzz", &schemes, &slots);
        let _ = w.check_slots("fuzz", &schemes, &slots[..slots.len() / 2]);
    }
});
