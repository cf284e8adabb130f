//! Fuzzes glTF loading (binary .glb or JSON .gltf) into meshes and set
//! instances. Run: `cargo +nightly fuzz run gltf_load`.
#![no_main]

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let ext = if data.starts_with(b"glTF") { "glb" } else { "gltf" };
    let path = std::env::temp_dir().join(format!("throng-fuzz-{}.{ext}", std::process::id()));
    if std::fs::write(&path, data).is_ok() {
        let _ = throng::scene::gltf::GltfFile::open(&path);
        let mut assets = throng::scene::gltf::AssetCache::new();
        let _ = assets.load_scene_instances(&path);
    }
});
