//! Asset loading: the Kenney alien (6 part meshes, 5 materials, a node
//! hierarchy) and a hand-made set (tests/fixtures/set_small.gltf, written by
//! make_set_small.py) with a texture, a camera and a sun.

mod common;

use glam::{Affine3A, Quat, Vec3};
use throng::error::Error;
use throng::scene::gltf::{srgb_to_linear, AssetCache, GltfFile, LUMENS_PER_WATT};
use throng::scene::lights::LightKind;
use throng::scene::Material;

fn fixture(name: &str) -> String {
    common::fixture(name).display().to_string()
}

fn alien() -> String {
    fixture("KenneyAlien/alien.glb")
}

fn ok<T>(r: throng::error::Result<T>) -> T {
    r.unwrap_or_else(|e| panic!("{e}"))
}

fn close3(a: Vec3, b: Vec3, what: &str) {
    assert!(a.abs_diff_eq(b, 1e-5), "{what}: got {a}, expected {b}");
}

// The file names its meshes "Mesh <node>".
const PARTS: [&str; 6] = ["Mesh armLeft", "Mesh armRight", "Mesh body", "Mesh head", "Mesh legLeft", "Mesh legRight"];

#[test]
fn loads_each_alien_part_once() {
    let mut cache = AssetCache::new();
    let ids: Vec<u32> = PARTS.iter().map(|p| ok(cache.mesh(alien(), p))).collect();
    // Loading again, or through another spelling of the path, shares the mesh.
    for (p, &id) in PARTS.iter().zip(&ids) {
        assert_eq!(ok(cache.mesh(alien(), p)), id, "{p}");
    }
    let other = fixture("KenneyAlien/../KenneyAlien/alien.glb");
    assert_eq!(ok(cache.mesh(&other, "Mesh head")), ids[3]);
    let lib = cache.library();
    assert_eq!(lib.meshes.len(), 6);

    // armLeft: three primitives merged (36 + 12 + 28 vertices, 42 + 12 + 30 indices).
    let arm = &lib.meshes[ids[0] as usize];
    assert_eq!(arm.name, format!("{}#Mesh armLeft", alien()));
    assert_eq!(arm.positions.len(), 76);
    assert_eq!(arm.triangle_count(), 28);
    assert_eq!(arm.normals.len(), 76);
    assert_eq!(arm.uvs.len(), 76);
    assert!(arm.indices.iter().all(|&i| (i as usize) < arm.positions.len()));
    let (lo, hi) = arm.bounds();
    close3(lo, Vec3::new(-0.13, -0.3917962, -0.11753921), "armLeft min");
    close3(hi, Vec3::new(0.0, 0.0, 0.065), "armLeft max");

    let head = &lib.meshes[ids[3] as usize];
    assert_eq!((head.positions.len(), head.triangle_count()), (176 + 4 + 8, (282 + 6 + 12) / 3));
    for m in &lib.meshes {
        assert!(m.normals.iter().all(|n| (n.length() - 1.0).abs() < 1e-3), "{} normals", m.name);
    }
}

#[test]
fn alien_materials_are_shared_and_named() {
    let mut cache = AssetCache::new();
    // The material of the primitive with the most triangles.
    let expect = [
        ("Mesh armLeft", "crystal"),
        ("Mesh armRight", "crystal"),
        ("Mesh body", "metalDark"),
        ("Mesh head", "crystal"),
        ("Mesh legLeft", "dark"),
        ("Mesh legRight", "dark"),
    ];
    let ids: Vec<u32> = expect.iter().map(|(p, _)| ok(cache.gltf_material(alien(), p))).collect();
    let lib = cache.library();
    for ((part, name), &id) in expect.iter().zip(&ids) {
        assert_eq!(lib.materials[id as usize].name, format!("{}#{name}", alien()), "{part}");
    }
    assert_eq!(ids[0], ids[1]);
    assert_eq!(ids[0], ids[3]);
    assert_eq!(ids[4], ids[5]);
    assert_eq!(lib.materials.len(), 3, "crystal, metalDark, dark");

    let crystal = &lib.materials[ids[0] as usize];
    close3(crystal.base_color, Vec3::new(0.18623178, 0.8773585, 0.59343624), "crystal colour");
    // The file gives no metallic/roughness factors: glTF defaults are 1.
    assert_eq!((crystal.metallic, crystal.roughness), (1.0, 1.0));
    assert_eq!(crystal.base_color_texture, None);

    // Per primitive: armLeft is crystal, metal, metalRed.
    let prims = ok(cache.mesh_primitives(alien(), "Mesh armLeft"));
    let names: Vec<String> = prims
        .iter()
        .map(|&(_, m)| cache.library().materials[m as usize].name.rsplit('#').next().unwrap_or("").to_string())
        .collect();
    assert_eq!(names, ["crystal", "metal", "metalRed"]);
    assert_eq!(prims[0].1, ids[0], "shared with gltf_material");
    let red = &cache.library().materials[prims[2].1 as usize];
    close3(red.base_color, Vec3::new(1.0, 0.62852424, 0.2028302), "metalRed colour");
}

#[test]
fn alien_scene_places_every_primitive() {
    let mut cache = AssetCache::new();
    let placed = ok(cache.load_scene_instances(alien()));
    assert_eq!(placed.len(), 18, "6 meshes, 18 primitives");
    // Loading again shares every mesh and material.
    let again = ok(cache.load_scene_instances(alien()));
    assert!(placed.iter().zip(&again).all(|(a, b)| a.0 == b.0 && a.1 == b.1));
    assert_eq!(cache.library().meshes.len(), 18);
    assert_eq!(cache.library().materials.len(), 5);

    // Nodes in file order under tmpParent -> alien (no transforms): armLeft first.
    let lib = cache.library();
    assert!(lib.meshes[placed[0].0 as usize].name.ends_with("#Mesh armLeft/0"));
    let arm_left =
        Affine3A::from_scale_rotation_translation(Vec3::splat(0.8584), Quat::IDENTITY, Vec3::new(-0.13, 0.473184, 0.0));
    assert!(placed[0].2.abs_diff_eq(arm_left, 1e-5), "{:?}", placed[0].2);
    // The head is the 4th node: primitives 9..12, scaled 0.26.
    let head = placed.iter().find(|p| lib.meshes[p.0 as usize].name.ends_with("#Mesh head/0")).map(|p| p.2);
    let expect =
        Affine3A::from_scale_rotation_translation(Vec3::splat(0.26), Quat::IDENTITY, Vec3::new(0.0, 0.483184, 0.0));
    assert!(head.is_some_and(|h| h.abs_diff_eq(expect, 1e-5)), "{head:?}");
    // Each primitive keeps its own material.
    let body_mats: Vec<&str> = placed
        .iter()
        .filter(|p| lib.meshes[p.0 as usize].name.contains("#Mesh body/"))
        .map(|p| lib.materials[p.1 as usize].name.rsplit('#').next().unwrap_or(""))
        .collect();
    assert_eq!(body_mats, ["metalDark", "metal", "metalRed"]);
}

#[test]
fn unknown_mesh_lists_the_meshes() {
    let mut cache = AssetCache::new();
    let err = cache.mesh(alien(), "tail").err().map(|e| e.to_string()).unwrap_or_default();
    assert!(err.contains("alien.glb") && err.contains("`tail`"), "{err}");
    for p in PARTS {
        assert!(err.contains(p), "{err}");
    }
    let err = cache.gltf_material(alien(), "tail").err().map(|e| e.to_string()).unwrap_or_default();
    assert!(err.contains("armLeft"), "{err}");
}

#[test]
fn missing_file_is_an_io_error_naming_it() {
    let mut cache = AssetCache::new();
    match cache.mesh(fixture("nope/parts.glb"), "head") {
        Err(Error::Io { path, .. }) => assert!(path.ends_with("nope/parts.glb")),
        other => panic!("expected an I/O error, got {other:?}"),
    }
}

#[test]
fn garbage_file_is_invalid_not_a_panic() {
    let dir = common::tempdir().unwrap_or_else(|e| panic!("{e}"));
    let path = dir.path().join("broken.glb");
    std::fs::write(&path, b"glTF\x02\0\0\0garbage").unwrap_or_else(|e| panic!("{e}"));
    let err = AssetCache::new().mesh(&path, "x").err().map(|e| e.to_string()).unwrap_or_default();
    assert!(err.contains("broken.glb"), "{err}");
    // A .gltf whose buffer file is missing names the buffer.
    let path = dir.path().join("nobin.gltf");
    let gltf = std::fs::read_to_string(fixture("InterpolationTest/InterpolationTest.gltf")).unwrap_or_default();
    std::fs::write(&path, gltf).unwrap_or_else(|e| panic!("{e}"));
    let err = AssetCache::new().mesh(&path, "Cube").err().map(|e| e.to_string()).unwrap_or_default();
    assert!(err.contains("nobin.gltf") && err.contains("interpolation.bin"), "{err}");
}

/// Found by the `gltf_load` fuzz target (docs/fuzzing.md): gltf's own
/// validation indexed the accessors with a primitive's POSITION unchecked.
#[test]
fn a_position_accessor_past_the_end_is_invalid_not_a_panic() {
    let dir = common::tempdir().unwrap_or_else(|e| panic!("{e}"));
    let path = dir.path().join("bad_position.gltf");
    let gltf = r#"{"asset":{"version":"2.0"},"meshes":[{"name":"m","primitives":[{"attributes":{"POSITION":1}}]}]}"#;
    std::fs::write(&path, gltf).unwrap_or_else(|e| panic!("{e}"));
    let err = GltfFile::open(&path).err().map(|e| e.to_string()).unwrap_or_default();
    assert!(err.contains("bad_position.gltf"), "{err}");
    assert!(err.contains("mesh `m` primitive 0: POSITION is accessor 1, but the file has 0"), "{err}");
    let err = AssetCache::new().load_scene_objects(&path).err().map(|e| e.to_string()).unwrap_or_default();
    assert!(err.contains("POSITION is accessor 1"), "{err}");
}

/// Found by the `gltf_load` fuzz target (docs/fuzzing.md): gltf's
/// `Image::source` unwraps the uri of an image without a bufferView, and
/// the mimeType of one with a bufferView.
#[test]
fn an_image_without_uri_or_mime_type_is_invalid_not_a_panic() {
    let dir = common::tempdir().unwrap_or_else(|e| panic!("{e}"));
    let text = std::fs::read_to_string(set()).unwrap_or_else(|e| panic!("{e}"));
    let uri = text.find("\"uri\": \"data:image/png").unwrap_or_else(|| panic!("set_small.gltf has no image uri"));
    let end = uri + text[uri..].find('\n').unwrap_or(0);
    for (name, image, msg) in [
        ("no_uri.gltf", "\"extras\": {}", "has neither a uri nor a bufferView"),
        ("no_mime.gltf", "\"bufferView\": 0", "an image in a bufferView needs a mimeType"),
    ] {
        let path = dir.path().join(name);
        std::fs::write(&path, format!("{}{image}{}", &text[..uri], &text[end..])).unwrap_or_else(|e| panic!("{e}"));
        let err = AssetCache::new().load_scene_objects(&path).err().map(|e| e.to_string()).unwrap_or_default();
        assert!(err.contains(name) && err.contains(&format!("image `tiles.png`: {msg}")), "{err}");
    }
}

#[test]
fn add_material_dedups_by_name() {
    let mut cache = AssetCache::new();
    let chrome = Material { name: "robots/chrome".into(), metallic: 1.0, roughness: 0.25, ..Material::default() };
    let a = cache.add_material(chrome.clone());
    let b = cache.add_material(Material { roughness: 0.9, ..chrome });
    let c = cache.add_material(Material { name: "robots/rust".into(), ..Material::default() });
    assert_eq!(a, b);
    assert_ne!(a, c);
    let lib = cache.into_library();
    assert_eq!(lib.materials.len(), 2);
    assert_eq!(lib.materials[a as usize].roughness, 0.25, "first one wins");
}

fn set() -> String {
    fixture("set_small.gltf")
}

#[test]
fn texture_is_decoded_to_linear() {
    let mut cache = AssetCache::new();
    let id = ok(cache.gltf_material(set(), "floor"));
    let lib = cache.library();
    let m = &lib.materials[id as usize];
    assert_eq!(m.name, format!("{}#tiles", set()));
    close3(m.base_color, Vec3::new(0.5, 1.0, 1.0), "factor");
    assert_eq!((m.metallic, m.roughness), (0.0, 0.2));
    let tex = &lib.textures[m.base_color_texture.unwrap_or(u32::MAX) as usize];
    assert_eq!((tex.width, tex.height), (2, 1));
    assert_eq!(tex.texels[0], [1.0, 0.0, 0.0, 1.0]);
    let g = srgb_to_linear(128.0 / 255.0);
    assert!((g - 0.21586).abs() < 1e-4, "{g}");
    let [r, gg, b, a] = tex.texels[1];
    assert!((r - g).abs() < 1e-6 && (gg - g).abs() < 1e-6 && (b - g).abs() < 1e-6, "{:?}", tex.texels[1]);
    assert!((a - 64.0 / 255.0).abs() < 1e-6, "alpha stays linear");
}

#[test]
fn missing_normals_are_computed_and_default_material_used() {
    let mut cache = AssetCache::new();
    let floor = ok(cache.mesh(set(), "floor"));
    let tri = ok(cache.mesh(set(), "tri"));
    let lib = cache.library();
    assert!(lib.meshes[floor as usize].normals.iter().all(|&n| n.abs_diff_eq(Vec3::Y, 1e-6)));
    let tri = &lib.meshes[tri as usize];
    assert_eq!(tri.indices, [0, 1, 2], "no index accessor: vertices in order");
    assert!(tri.normals.iter().all(|&n| n.abs_diff_eq(Vec3::Z, 1e-6)));
    assert!(tri.uvs.is_empty());
    let m = ok(cache.gltf_material(set(), "tri"));
    assert_eq!(cache.library().materials[m as usize].name, format!("{}#default", set()));
}

#[test]
fn non_triangle_mesh_is_refused_by_name() {
    let err = AssetCache::new().mesh(set(), "dots").err().map(|e| e.to_string()).unwrap_or_default();
    assert!(err.contains("set_small.gltf") && err.contains("`dots`") && err.contains("Points"), "{err}");
}

#[test]
fn scene_composes_parent_transforms() {
    let mut cache = AssetCache::new();
    // Scene roots: group (-> floor, tri), camrig, sun. `dots` is outside the scene.
    let placed = ok(cache.load_scene_instances(set()));
    let lib = cache.library();
    let names: Vec<&str> =
        placed.iter().map(|p| lib.meshes[p.0 as usize].name.rsplit('#').next().unwrap_or("")).collect();
    assert_eq!(names, ["floor", "tri"]);
    close3(placed[0].2.translation.into(), Vec3::new(1.0, 0.0, 2.0), "floor: group then node");
    close3(placed[1].2.translation.into(), Vec3::new(1.0, 0.0, 0.0), "tri");
    assert_eq!(lib.materials[placed[0].1 as usize].name, format!("{}#tiles", set()));
    // One-primitive meshes are the same mesh whether loaded by name or by scene.
    assert_eq!(ok(cache.mesh(set(), "floor")), placed[0].0);
}

#[test]
fn camera_and_sun() {
    let mut cache = AssetCache::new();
    let cam = ok(cache.find_camera(set(), "shotcam"));
    assert!((cam.yfov - 0.6).abs() < 1e-6);
    // camrig: translate (0,1,0), scale 2; shotcam at (0,0.35,12) inside it. Scale is dropped.
    close3(cam.world_from_camera.translation.into(), Vec3::new(0.0, 1.7, 24.0), "camera position");
    close3(cam.world_from_camera.transform_vector3(Vec3::X), Vec3::X, "no scale");
    let err = cache.find_camera(set(), "floor").err().map(|e| e.to_string()).unwrap_or_default();
    assert!(err.contains("no camera"), "{err}");
    let err = cache.find_camera(set(), "cam").err().map(|e| e.to_string()).unwrap_or_default();
    assert!(err.contains("shotcam"), "lists the nodes: {err}");

    let suns = ok(cache.punctual_lights(set()));
    assert_eq!(suns.len(), 1);
    assert_eq!(suns[0].name, "sun");
    assert_eq!(suns[0].kind, LightKind::Distant { angular_diameter: 0.0 });
    let s = std::f32::consts::FRAC_1_SQRT_2;
    close3(-suns[0].facing(), Vec3::new(0.0, s, s), "towards the sun");
    // lux -> W/m^2, as Blender's importer and the peers convert.
    close3(suns[0].emission, Vec3::new(1.0, 0.9, 0.8) * (3.0 / LUMENS_PER_WATT), "irradiance");
    assert!(ok(cache.punctual_lights(alien())).is_empty());
}

#[test]
fn interpolation_test_meshes_load_without_their_image() {
    // The file's only image (l.jpg) is not in the fixtures; meshes and
    // untextured materials must not need it.
    let mut cache = AssetCache::new();
    let path = fixture("InterpolationTest/InterpolationTest.gltf");
    let cube = ok(cache.mesh(&path, "Cube"));
    assert_eq!(cache.library().meshes[cube as usize].triangle_count(), 12);
    ok(cache.gltf_material(&path, "Cube"));
    // The textured plane names the missing image.
    let err = cache.gltf_material(&path, "Plane.001").err().map(|e| e.to_string()).unwrap_or_default();
    assert!(err.contains("l.jpg"), "{err}");
}

#[test]
fn malformed_meshes_are_errors_naming_the_mesh() {
    let text = std::fs::read_to_string(set()).unwrap_or_else(|e| panic!("{e}"));
    let dir = common::tempdir().unwrap_or_else(|e| panic!("{e}"));
    let load = |edit: &dyn Fn(&mut serde_json::Value)| {
        let mut json: serde_json::Value = serde_json::from_str(&text).unwrap_or_else(|e| panic!("{e}"));
        edit(&mut json);
        let path = dir.path().join("bad_set.gltf");
        std::fs::write(&path, json.to_string()).unwrap_or_else(|e| panic!("{e}"));
        let err = AssetCache::new().mesh(&path, "floor").err().map(|e| e.to_string()).unwrap_or_default();
        assert!(err.contains("bad_set.gltf") && err.contains("`floor`"), "{err}");
        err
    };
    // Floor positions swapped for the 3-vertex triangle's: index 3 is out of range.
    let err = load(&|j| {
        let tri_positions = j["meshes"][1]["primitives"][0]["attributes"]["POSITION"].clone();
        let prim = &mut j["meshes"][0]["primitives"][0];
        prim["attributes"]["POSITION"] = tri_positions;
        if let Some(a) = prim["attributes"].as_object_mut() {
            a.remove("TEXCOORD_0");
        }
    });
    assert!(err.contains("index 3 is out of range (3 vertices)"), "{err}");
    // Indices pointing at a VEC3 accessor.
    let err = load(&|j| {
        j["meshes"][0]["primitives"][0]["indices"] = j["meshes"][0]["primitives"][0]["attributes"]["POSITION"].clone()
    });
    assert!(err.contains("expected Scalar"), "{err}");
    // A zero-count accessor.
    let err = load(&|j| {
        let acc = j["meshes"][0]["primitives"][0]["indices"].as_u64().unwrap_or(0) as usize;
        j["accessors"][acc]["count"] = 0.into();
    });
    assert!(err.contains("empty"), "{err}");
    // Triangle strips are refused.
    let err = load(&|j| j["meshes"][0]["primitives"][0]["mode"] = 5.into());
    assert!(err.contains("TriangleStrip"), "{err}");
}

/// A buffer URI naming a device or a FIFO would be read forever (and
/// grow without bound): only regular files are read.
#[test]
fn a_buffer_that_is_not_a_regular_file_is_refused() {
    let dir = common::tempdir().unwrap_or_else(|e| panic!("{e}"));
    let path = dir.path().join("device.gltf");
    let gltf = r#"{"asset":{"version":"2.0"},"buffers":[{"uri":"/dev/zero","byteLength":12}]}"#;
    std::fs::write(&path, gltf).unwrap_or_else(|e| panic!("{e}"));
    let err = GltfFile::open(&path).err().map(|e| e.to_string()).unwrap_or_default();
    assert!(err.contains("device.gltf") && err.contains("/dev/zero is not a regular file"), "{err}");
    // A texture image the same way.
    let path = dir.path().join("device_image.gltf");
    let gltf = r#"{"asset":{"version":"2.0"},"buffers":[{"uri":"data:application/octet-stream;base64,AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAAAAAAAAAAAAAAAIA/AAAAAAAAAAAAAIA/","byteLength":60}],"bufferViews":[{"buffer":0,"byteOffset":0,"byteLength":36},{"buffer":0,"byteOffset":36,"byteLength":24}],"accessors":[{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]},{"bufferView":1,"componentType":5126,"count":3,"type":"VEC2"}],"images":[{"uri":"/dev/zero"}],"textures":[{"source":0}],"materials":[{"name":"m","pbrMetallicRoughness":{"baseColorTexture":{"index":0}}}],"meshes":[{"name":"q","primitives":[{"attributes":{"POSITION":0,"TEXCOORD_0":1},"material":0}]}],"nodes":[{"mesh":0}],"scenes":[{"nodes":[0]}],"scene":0}"#;
    std::fs::write(&path, gltf).unwrap_or_else(|e| panic!("{e}"));
    let err = AssetCache::new().load_scene_objects(&path).err().map(|e| e.to_string()).unwrap_or_default();
    assert!(err.contains("device_image.gltf") && err.contains("/dev/zero is not a regular file"), "{err}");
}
