//! Fuzzes glTF loading (binary .glb or JSON .gltf) as sets, wardrobe parts
//! and glTF cameras use it: `GltfFile::open` (buffers), the set's scene walk
//! `AssetCache::load_scene_objects` (meshes, materials, textures, object
//! names), each named mesh merged and per primitive, node transforms,
//! cameras and lights. Run: `cargo +nightly fuzz run gltf_load`
//! (docs/fuzzing.md).
#![no_main]

use libfuzzer_sys::fuzz_target;
use std::path::PathBuf;
use std::sync::OnceLock;
use throng::scene::gltf::{AssetCache, GltfFile};

fn files() -> &'static [PathBuf; 2] {
    static P: OnceLock<[PathBuf; 2]> = OnceLock::new();
    P.get_or_init(|| {
        let dir = std::env::temp_dir().join(format!("throng-fuzz-gltf-{}", std::process::id()));
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
    let Ok(file) = GltfFile::open(path) else { return };
    let _ = file.world_transforms();
    let mut assets = AssetCache::new();
    let _ = assets.load_scene_objects(path);
    let meshes: Vec<String> = file.doc.meshes().filter_map(|m| m.name().map(str::to_string)).take(8).collect();
    for name in &meshes {
        let _ = assets.mesh(path, name);
        let _ = assets.mesh_primitives(path, name);
        let _ = assets.gltf_material(path, name);
    }
    let nodes: Vec<String> = file.doc.nodes().filter_map(|n| n.name().map(str::to_string)).take(8).collect();
    for name in &nodes {
        let _ = assets.find_camera(path, name);
    }
    let _ = assets.punctual_lights(path);
});
