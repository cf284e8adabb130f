//! Cryptomatte: ids against the specification's 432 test vectors, the
//! decoder on Psyop's sample files, and our own agent / part / material
//! mattes (ranking, coverage, manifest, determinism, EXR round trip, sidecar
//! manifests) and named set objects.

mod common;

use std::collections::BTreeSet;
use std::path::PathBuf;

use glam::{Affine3A, Vec2, Vec3};
use throng::render::accel::BlasSet;
use throng::render::cryptomatte::{
    self, agent_name, id_hex, layer_key, name_id, part_name, set_object_name, CryptoNames, Cryptomatte, NameTables,
    AGENT_MATTE, MATERIAL_MATTE, PART_MATTE, RANKS, SET_NAME,
};
use throng::render::exr::{
    camera_matrices, mattes, read_layer, read_parts, write_layer, write_layer_with, LayerMeta, ManifestMode,
    WriteOptions, ID_MAPPING,
};
use throng::render::film::{render_frame_with_cryptomatte, Film};
use throng::render::RenderSettings;
use throng::scene::{
    lights::SceneLights, vis, Camera, FrameScene, Instance, InstanceAgent, Library, Material, Mesh, Sky,
};

fn fixtures() -> PathBuf {
    common::fixture("cryptomatte")
}

/// The larger Psyop samples live in ../shared (not copied into the repo).
fn shared_sample(name: &str) -> PathBuf {
    common::shared_asset("exr/cryptomatte_psyop").join(name)
}

/// Found by the `exr_reader` fuzz target (docs/fuzzing.md): a data window
/// far larger than the file made the exr crate allocate every channel of
/// it before reading a pixel. Readers now refuse it, naming the file.
#[test]
fn a_data_window_larger_than_the_file_can_hold_is_refused() {
    let bytes = std::fs::read(fixtures().join("special_chars.exr")).unwrap();
    let key = b"dataWindow\0box2i\0\x10\0\0\0";
    let at = bytes.windows(key.len()).position(|w| w == key).unwrap() + key.len();
    let mut huge = bytes.clone();
    // xMax and yMax: 64x64 becomes 30000x30000.
    for offset in [8, 12] {
        huge[at + offset..at + offset + 4].copy_from_slice(&29_999i32.to_le_bytes());
    }
    let dir = common::tempdir().unwrap();
    let path = dir.path().join("huge.exr");
    std::fs::write(&path, &huge).unwrap();
    let errors = [read_layer(&path).err(), read_parts(&path, |_| true).err(), mattes::read(&path).err()];
    for err in errors.map(|e| e.map(|e| e.to_string()).unwrap_or_default()) {
        assert!(err.contains("huge.exr") && err.contains("more than a"), "{err}");
    }
    // The file as it was reads.
    std::fs::write(&path, &bytes).unwrap();
    assert_eq!(mattes::read(&path).unwrap().len(), 1);
}

// ------------------------------------------------------------ ids

#[test]
fn all_432_test_vectors() {
    let text = std::fs::read_to_string(fixtures().join("manifest_test_vectors.json")).unwrap();
    let vectors: Vec<serde_json::Value> = serde_json::from_str(&text).unwrap();
    assert_eq!(vectors.len(), 432);
    for v in &vectors {
        let name = v["name"].as_str().unwrap();
        assert_eq!(id_hex(name_id(name)), v["hash_hex"].as_str().unwrap(), "name `{name}`");
        let id = name_id(name);
        assert!(id.is_finite() && id != 0.0 && id.is_normal(), "`{name}` -> {id}");
        assert_eq!(layer_key(v["layer"].as_str().unwrap()), v["layer_key"].as_str().unwrap());
    }
}

// ------------------------------------------------- decoder on real files

/// Plausibility of a decoded third-party matte: every manifest name that is
/// on screen has a non-empty matte, coverage never exceeds 1 over the ranks
/// and ranks are sorted by coverage.
fn check_plausible(m: &Cryptomatte, sorted: bool) {
    assert_eq!(m.ranks, 6, "{}", m.name);
    for (i, s) in m.coverage_sum().iter().enumerate() {
        assert!(*s <= 1.0 + 1e-3, "{}: pixel {i} coverage sum {s}", m.name);
        let px = m.pixel(i);
        // (The Cornell box sample is not sorted everywhere; the others are.)
        for w in px.windows(2).filter(|_| sorted) {
            assert!(w[0][1] >= w[1][1] - 1e-6, "{}: pixel {i} ranks unsorted {px:?}", m.name);
        }
    }
    for (name, &bits) in &m.manifest {
        assert_eq!(bits, name_id(name).to_bits(), "{}: manifest `{name}`", m.name);
    }
}

#[test]
fn special_chars_sample() {
    let path = fixtures().join("special_chars.exr");
    let mattes = mattes::read(&path).unwrap();
    assert_eq!(mattes.len(), 1);
    let m = &mattes[0];
    assert_eq!(m.name, "special_chars");
    assert_eq!((m.width, m.height), (64, 64));
    check_plausible(m, true);
    let names: BTreeSet<&str> = m.manifest.keys().map(String::as_str).collect();
    assert!(names.contains("равнина") && names.contains("name, with, comma"), "{names:?}");
    for name in m.manifest.keys() {
        let matte = m.matte(name);
        let area: f32 = matte.iter().sum();
        assert!(area > 1.0, "`{name}` matte is empty");
    }
    // The four objects cover most of the frame and their mattes sum to ~1 there.
    let full = m.coverage_sum().iter().filter(|&&s| (s - 1.0).abs() < 1e-3).count();
    assert!(full > 64 * 64 / 2, "{full} fully covered pixels");
}

#[test]
fn sidecar_manifest_sample() {
    let path = fixtures().join("sidecar_manifest.exr");
    let mattes = mattes::read(&path).unwrap();
    assert_eq!(mattes.len(), 1);
    let m = &mattes[0];
    assert_eq!(m.name, "crypto_asset");
    assert_eq!(m.manifest.len(), 8, "manifest read from the sidecar");
    check_plausible(m, true);
    let on_screen: Vec<&String> = m.manifest.keys().filter(|n| m.matte(n).iter().any(|&c| c > 0.0)).collect();
    assert!(on_screen.len() >= 2, "{on_screen:?}");
    assert!(m.matte("default").iter().sum::<f32>() > 1.0);
}

#[test]
fn multichannel_and_cornell_samples() {
    let path = shared_sample("multichannel.exr");
    let mattes = mattes::read(&path).unwrap();
    let names: Vec<&str> = mattes.iter().map(|m| m.name.as_str()).collect();
    assert_eq!(names.len(), 3, "{names:?}");
    for m in &mattes {
        check_plausible(m, true);
        assert!(!m.manifest.is_empty());
        // At least one named object is visible with full coverage somewhere.
        let best = m.manifest.keys().map(|n| m.matte(n).iter().cloned().fold(0.0, f32::max)).fold(0.0, f32::max);
        assert!(best > 0.99, "{}: best matte peak {best}", m.name);
    }
    let object = mattes.iter().find(|m| m.name == "crypto_object").unwrap();
    assert_eq!(object.manifest.len(), 407);
    let asset = mattes.iter().find(|m| m.name == "crypto_asset").unwrap();
    // Two assets: their mattes are non-empty and disjoint-ish (sum <= 1 per pixel).
    let (a, b) = (asset.matte("ball_asset"), asset.matte("toroidal_asset"));
    assert!(a.iter().sum::<f32>() > 10.0 && b.iter().sum::<f32>() > 10.0);
    assert!(a.iter().zip(&b).all(|(x, y)| x + y <= 1.0 + 1e-3));

    let path = shared_sample("cornellBox_CryptoWildcard.0001.exr");
    let mattes = mattes::read(&path).unwrap();
    assert_eq!(mattes.len(), 1);
    let m = &mattes[0];
    assert_eq!(m.name, "uCryptoWildcard");
    check_plausible(m, false);
    let area = m.matte("rect_[_top").iter().sum::<f32>();
    assert!(area > 100.0, "rect_[_top covers {area} pixels");
}

// -------------------------------------------------------- our own mattes

fn floor() -> Mesh {
    let positions =
        [(-20.0, -20.0), (20.0, -20.0), (20.0, 20.0), (-20.0, 20.0)].map(|(x, z)| Vec3::new(x, 0.0, z)).to_vec();
    Mesh {
        name: "floor".into(),
        normals: vec![Vec3::Y; 4],
        uvs: vec![Vec2::ZERO; 4],
        tangents: vec![],
        positions,
        indices: vec![0, 2, 1, 0, 3, 2],
    }
}

fn camera(eye: Vec3, target: Vec3, yfov_deg: f32) -> Camera {
    let forward = (target - eye).normalize();
    let right = forward.cross(Vec3::Y).normalize();
    let up = right.cross(forward);
    Camera {
        world_from_camera: Affine3A::from_cols(right.into(), up.into(), (-forward).into(), eye.into()),
        yfov: yfov_deg.to_radians(),
        aperture: 0.0,
        focus_distance: 1.0,
    }
}

const SLOTS: [&str; 2] = ["torso", "head"];

fn material(name: &str, grey: f32) -> Material {
    Material {
        name: name.into(),
        base_color: Vec3::splat(grey),
        base_color_texture: None,
        roughness: 0.5,
        metallic: 0.0,
        ..Default::default()
    }
}

/// The library's materials: a glTF set material (library name
/// `<file>#<name>`) and two wardrobe materials.
const MATERIALS: [&str; 3] = ["../shared/sets/floor.glb#tiles", "robots/red", "robots/blue"];

/// A floor (set, material `tiles`), agents 3, 78 and 1000 as two stacked
/// boxes (torso, head; agent 3 in `robots/red`, the others in
/// `robots/blue`), agent 5 (red) far off screen, and a holdout box over part
/// of agent 1000.
fn crowd_scene() -> (Library, FrameScene) {
    let lib = Library {
        meshes: vec![floor(), Mesh::cube("cube")],
        materials: MATERIALS.iter().zip([0.5, 0.6, 0.4]).map(|(n, g)| material(n, g)).collect(),
        textures: vec![],
    };
    let inst = |mesh, m: Affine3A, agent: Option<u32>, part, visibility| Instance {
        mesh,
        material: match agent {
            None => 0,
            Some(3 | 5) => 1,
            Some(_) => 2,
        },
        world_from_object: m,
        agent: agent.map_or(InstanceAgent::NONE, InstanceAgent::some),
        part,
        visibility,
    };
    let mut instances = vec![inst(0, Affine3A::IDENTITY, None, 0, vis::ALL)];
    for (agent, x) in [(3u32, -1.2f32), (78, 0.0), (1000, 1.3), (5, 60.0)] {
        let torso = Affine3A::from_scale_rotation_translation(
            Vec3::new(0.8, 1.0, 0.5),
            Default::default(),
            Vec3::new(x, 0.5, 0.0),
        );
        let head =
            Affine3A::from_scale_rotation_translation(Vec3::splat(0.4), Default::default(), Vec3::new(x, 1.2, 0.0));
        instances.push(inst(1, torso, Some(agent), 0, vis::ALL));
        instances.push(inst(1, head, Some(agent), 1, vis::ALL));
    }
    let holdout =
        Affine3A::from_scale_rotation_translation(Vec3::splat(0.3), Default::default(), Vec3::new(1.5, 0.4, 0.6));
    instances.push(inst(1, holdout, None, 0, vis::HOLDOUT | vis::SHADOW));
    let scene = FrameScene {
        instances,
        camera: camera(Vec3::new(0.0, 1.0, 4.5), Vec3::new(0.0, 0.7, 0.0), 40.0),
        lights: SceneLights::sun_and_sky(None, Sky { radiance: Vec3::splat(0.5) }),
        motion: None,
    };
    (lib, scene)
}

fn names<'a>(lib: &'a Library, scene: &'a FrameScene, set_objects: &'a [String]) -> CryptoNames<'a> {
    let tables = NameTables { materials: &lib.materials, set_objects };
    CryptoNames::new(&scene.instances, &tables, |_| Some(|part: u16| SLOTS.get(part as usize).copied()))
}

/// The film's matte of type `name`.
fn matte<'a>(film: &'a Film, name: &str) -> &'a Cryptomatte {
    film.cryptomatte.iter().find(|m| m.name == name).unwrap_or_else(|| panic!("no {name} matte"))
}

fn settings(spp: u32, threads: usize) -> RenderSettings {
    RenderSettings {
        width: 48,
        height: 36,
        spp,
        max_bounces: 1,
        seed: 7,
        frame: 1001,
        sky_visible: false,
        threads,
        indirect_clamp: 10.0,
        ..Default::default()
    }
}

fn render(spp: u32, threads: usize) -> (FrameScene, Film) {
    let (lib, scene) = crowd_scene();
    let blas = BlasSet::build(&lib);
    let crypto = names(&lib, &scene, &[]);
    let (film, _) =
        render_frame_with_cryptomatte(&blas, &lib, &scene, &settings(spp, threads), Some(&crypto), None).unwrap();
    drop(crypto);
    (scene, film)
}

fn meta(film: &Film, scene: &FrameScene) -> LayerMeta {
    let (world_to_camera, world_to_ndc) = camera_matrices(&scene.camera, film.width, film.height, 0.1, 100.0);
    LayerMeta {
        shot: "demo".into(),
        layer: "crowd_0".into(),
        frame: 1001,
        seed: 7,
        spp: 16,
        id_mapping: ID_MAPPING.into(),
        world_to_camera,
        world_to_ndc,
        near: 0.1,
        far: 100.0,
        fps: 24.0,
        render_fingerprint: String::new(),
        denoiser: String::new(),
        shutter: None,
        colourspace: Default::default(),
    }
}

#[test]
fn agent_and_part_mattes_match_the_render() {
    let (_, film) = render(16, 2);
    // Sorted by type name, as the file reads back.
    let types: Vec<&str> = film.cryptomatte.iter().map(|m| m.name.as_str()).collect();
    assert_eq!(types, [AGENT_MATTE, MATERIAL_MATTE, PART_MATTE]);
    let (agents, parts) = (matte(&film, AGENT_MATTE), matte(&film, PART_MATTE));
    assert_eq!(agents.ranks, RANKS);

    // Manifests: only what is on screen (agent 5 is off to the side, the holdout is nameless).
    let expect: Vec<String> = [agent_name(1000), agent_name(3), agent_name(78), SET_NAME.to_string()].to_vec();
    assert_eq!(agents.manifest.keys().cloned().collect::<Vec<_>>(), expect);
    assert_eq!(parts.manifest.len(), 7, "{:?}", parts.manifest);
    assert!(parts.manifest.contains_key(&part_name(78, "head")) && parts.manifest.contains_key(SET_NAME));
    for (name, &bits) in agents.manifest.iter().chain(&parts.manifest) {
        assert_eq!(bits, name_id(name).to_bits());
    }

    // With at most 6 objects under a pixel the ranks hold every sample:
    // coverage over the ranks is exactly the alpha (sky and holdout are id 0).
    let (agent_cov, part_cov) = (agents.coverage_sum(), parts.coverage_sum());
    for (i, px) in film.rgba.iter().enumerate() {
        assert!((agent_cov[i] - px[3]).abs() < 1e-5, "pixel {i}: coverage {} alpha {}", agent_cov[i], px[3]);
        assert!((part_cov[i] - px[3]).abs() < 1e-5);
    }

    for agent in [3u32, 78, 1000] {
        let matte = agents.matte(&agent_name(agent));
        let head = parts.matte(&part_name(agent, "head"));
        let torso = parts.matte(&part_name(agent, "torso"));
        let mut pixels_with_id = 0;
        for i in 0..matte.len() {
            // The agent matte is the sum of its parts' mattes.
            assert!((matte[i] - head[i] - torso[i]).abs() < 1e-5);
            // agent.id comes from the sample nearest the pixel centre: where it
            // names this agent, the matte has that sample at least.
            if film.agent_id[i] == agent + 1 {
                pixels_with_id += 1;
                assert!(matte[i] >= 1.0 / 16.0, "agent {agent} pixel {i}: matte {}", matte[i]);
            }
            // Full coverage means every sample, so also the nearest one, hit it.
            if matte[i] == 1.0 {
                assert_eq!(film.agent_id[i], agent + 1);
            }
        }
        // Area agrees with the id AOV within the filter's edge blur.
        let area: f32 = matte.iter().sum();
        assert!(pixels_with_id > 20, "agent {agent} barely visible");
        let rel = (area - pixels_with_id as f32).abs() / pixels_with_id as f32;
        assert!(rel < 0.15, "agent {agent}: matte area {area} vs {pixels_with_id} id pixels");
        // Partial coverage only along edges, and a solid interior.
        assert!(matte.iter().filter(|&&c| c == 1.0).count() > pixels_with_id / 3);
    }
    assert!(agents.matte(&agent_name(5)).iter().all(|&c| c == 0.0));
}

#[test]
fn mattes_are_identical_for_any_thread_count() {
    let (_, a) = render(8, 1);
    let (_, b) = render(8, 3);
    assert!(a.cryptomatte == b.cryptomatte, "mattes differ between 1 and 3 threads");
    assert!(a == b, "films differ between 1 and 3 threads");
}

#[test]
fn exr_round_trip_and_header() {
    let (scene, film) = render(4, 2);
    let dir = common::tempdir().unwrap();
    let path = dir.path().join("demo.crowd_0.1001.exr");
    write_layer(&path, &film, &meta(&film, &scene)).unwrap();
    let (back, _) = read_layer(&path).unwrap();
    assert!(back.cryptomatte == film.cryptomatte, "read_layer round trip differs");

    let parts = read_parts(&path, |_| true).unwrap();
    assert_eq!(parts.len(), 1);
    let p = &parts[0];
    for (i, m) in film.cryptomatte.iter().enumerate() {
        let key = layer_key(&m.name);
        assert_eq!(key, m.key());
        assert_eq!(p.attributes[&format!("cryptomatte/{key}/name")], m.name);
        assert_eq!(p.attributes[&format!("cryptomatte/{key}/hash")], "MurmurHash3_32");
        assert_eq!(p.attributes[&format!("cryptomatte/{key}/conversion")], "uint32_to_float32");
        let manifest = mattes::parse_manifest(&p.attributes[&format!("cryptomatte/{key}/manifest")], &path).unwrap();
        assert_eq!(manifest, m.manifest);
        for level in ["00", "01", "02"] {
            for c in ["R", "G", "B", "A"] {
                assert!(p.channels.contains_key(&format!("{}{level}.{c}", m.name)), "{}{level}.{c}", m.name);
            }
        }
        assert!(!p.channels.contains_key(&format!("{}03.R", m.name)));
        // R = id rank 0, G = its coverage.
        let r0: Vec<f32> = m.pairs.chunks(RANKS).map(|px| px[0][0]).collect();
        assert!(p.channels[&format!("{}00.R", m.name)] == r0, "matte {i}: R is not rank 0's id");
    }
    let decoded = mattes::read(&path).unwrap();
    assert!(decoded == film.cryptomatte, "decoder round trip differs");
}

#[test]
fn sidecar_manifest_option() {
    let (scene, film) = render(4, 2);
    let dir = common::tempdir().unwrap();
    let path = dir.path().join("demo.crowd_0.1001.exr");
    write_layer_with(
        &path,
        &film,
        &meta(&film, &scene),
        &WriteOptions { manifest: ManifestMode::Sidecar, ..Default::default() },
    )
    .unwrap();
    let side = dir.path().join("demo.crowd_0.1001.CryptoAgent.json");
    assert!(side.exists() && dir.path().join("demo.crowd_0.1001.CryptoPart.json").exists());
    assert!(dir.path().join("demo.crowd_0.1001.CryptoMaterial.json").exists());
    let p = &read_parts(&path, |_| false).unwrap()[0];
    let key = layer_key(AGENT_MATTE);
    assert_eq!(p.attributes[&format!("cryptomatte/{key}/manif_file")], "demo.crowd_0.1001.CryptoAgent.json");
    assert!(!p.attributes.contains_key(&format!("cryptomatte/{key}/manifest")));
    assert!(mattes::read(&path).unwrap() == film.cryptomatte, "sidecar round trip differs");
    // A missing sidecar is an error naming it.
    std::fs::remove_file(&side).unwrap();
    let err = mattes::read(&path).unwrap_err().to_string();
    assert!(err.contains("CryptoAgent.json"), "{err}");
}

#[test]
fn no_cryptomatte_without_names() {
    let (lib, scene) = crowd_scene();
    let blas = BlasSet::build(&lib);
    let (film, _) = render_frame_with_cryptomatte(&blas, &lib, &scene, &settings(2, 1), None, None).unwrap();
    assert!(film.cryptomatte.is_empty());
}

#[test]
fn material_matte_covers_the_agents_wearing_it() {
    let (_, film) = render(16, 2);
    let (agents, materials) = (matte(&film, AGENT_MATTE), matte(&film, MATERIAL_MATTE));
    // Names: a glTF material keeps its own name, wardrobe ones `wardrobe/name`.
    let names: Vec<&str> = materials.manifest.keys().map(String::as_str).collect();
    assert_eq!(names, ["robots/blue", "robots/red", "tiles"]);
    for (name, &bits) in &materials.manifest {
        assert_eq!(bits, name_id(name).to_bits(), "{name}");
    }
    assert_eq!(cryptomatte::layer_key(MATERIAL_MATTE), "be359d6");

    let sum = |names: &[String]| -> Vec<f32> {
        let mattes: Vec<Vec<f32>> = names.iter().map(|n| agents.matte(n)).collect();
        (0..film.rgba.len()).map(|i| mattes.iter().map(|m| m[i]).sum()).collect()
    };
    let red = materials.matte("robots/red");
    let blue = materials.matte("robots/blue");
    let tiles = materials.matte("tiles");
    let want_red = sum(&[agent_name(3)]);
    let want_blue = sum(&[agent_name(78), agent_name(1000)]);
    let want_tiles = agents.matte(SET_NAME);
    for i in 0..film.rgba.len() {
        assert!((red[i] - want_red[i]).abs() < 1e-6, "pixel {i}: red {} vs agent 3 {}", red[i], want_red[i]);
        assert!(
            (blue[i] - want_blue[i]).abs() < 1e-6,
            "pixel {i}: blue {} vs agents 78 + 1000 {}",
            blue[i],
            want_blue[i]
        );
        assert!((tiles[i] - want_tiles[i]).abs() < 1e-6, "pixel {i}: tiles {} vs set {}", tiles[i], want_tiles[i]);
        // The holdout and the sky have no material: coverage adds up to alpha.
        assert!((red[i] + blue[i] + tiles[i] - film.rgba[i][3]).abs() < 1e-5);
    }
    assert!(red.iter().sum::<f32>() > 20.0 && blue.iter().sum::<f32>() > 40.0);
}

/// A floor and two set boxes, one of them (`box_b`) two primitives with
/// their own materials placed by one node: objects 0, 1, 2 of the set.
fn set_scene() -> (Library, FrameScene, Vec<String>) {
    let lib = Library {
        meshes: vec![floor(), Mesh::cube("cube")],
        materials: ["set.glb#tiles", "set.glb#brick", "set.glb#glass"].iter().map(|n| material(n, 0.5)).collect(),
        textures: vec![],
    };
    let boxed = |x: f32, y: f32, size: f32| {
        Affine3A::from_scale_rotation_translation(Vec3::splat(size), Default::default(), Vec3::new(x, y, 0.0))
    };
    let inst = |mesh, world_from_object, material, part| Instance {
        mesh,
        material,
        world_from_object,
        agent: InstanceAgent::NONE,
        part,
        visibility: vis::ALL,
    };
    let instances = vec![
        inst(0, Affine3A::IDENTITY, 0, 0),
        inst(1, boxed(-1.0, 0.5, 1.0), 1, 1),
        inst(1, boxed(1.0, 0.4, 0.8), 1, 2),
        inst(1, boxed(1.0, 1.0, 0.4), 2, 2),
    ];
    let scene = FrameScene {
        instances,
        camera: camera(Vec3::new(0.0, 1.0, 4.5), Vec3::new(0.0, 0.5, 0.0), 40.0),
        lights: SceneLights::sun_and_sky(None, Sky { radiance: Vec3::splat(0.5) }),
        motion: None,
    };
    (lib, scene, ["floor", "box_a", "box_b"].map(String::from).to_vec())
}

#[test]
fn set_object_mattes_cover_exactly_their_object() {
    let (lib, scene, objects) = set_scene();
    let blas = BlasSet::build(&lib);
    let s = settings(16, 2);
    let crypto = names(&lib, &scene, &objects);
    let (film, _) = render_frame_with_cryptomatte(&blas, &lib, &scene, &s, Some(&crypto), None).unwrap();
    for type_name in [AGENT_MATTE, PART_MATTE] {
        let m = matte(&film, type_name);
        let names: Vec<&str> = m.manifest.keys().map(String::as_str).collect();
        assert_eq!(names, ["set/box_a", "set/box_b", "set/floor"], "{type_name}");
        assert_eq!(set_object_name("box_a"), "set/box_a");
    }
    let agents = matte(&film, AGENT_MATTE);
    assert!(agents.manifest.values().all(|&b| b != name_id(SET_NAME).to_bits()), "no plain `set` left");
    // Each object alone in the scene: its alpha is exactly the coverage of
    // the camera samples that hit it first (the same samples: the boxes do
    // not overlap on screen and the floor is behind them), so it must equal
    // the object's matte in the whole scene, pixel by pixel.
    for (object, name) in objects.iter().enumerate() {
        let alone = FrameScene {
            instances: scene.instances.iter().filter(|i| i.part as usize == object).copied().collect(),
            ..scene.clone()
        };
        let (only, _) = render_frame_with_cryptomatte(&blas, &lib, &alone, &s, None, None).unwrap();
        let want: Vec<f32> = only.rgba.iter().map(|p| p[3]).collect();
        if name != "floor" {
            let got = agents.matte(&set_object_name(name));
            assert!(got.iter().sum::<f32>() > 30.0, "{name} barely visible");
            for i in 0..got.len() {
                assert!((got[i] - want[i]).abs() < 1e-6, "{name} pixel {i}: matte {} alpha alone {}", got[i], want[i]);
            }
            assert_eq!(matte(&film, PART_MATTE).matte(&set_object_name(name)), got);
        }
    }
    // The floor is hidden behind the boxes in places: its matte is alpha
    // minus the boxes'.
    let floor = agents.matte("set/floor");
    let (a, b) = (agents.matte("set/box_a"), agents.matte("set/box_b"));
    for i in 0..floor.len() {
        assert!((floor[i] + a[i] + b[i] - film.rgba[i][3]).abs() < 1e-5, "pixel {i}");
    }
    // The material matte names the materials, box_b's two among them.
    let materials = matte(&film, MATERIAL_MATTE);
    let names: Vec<&str> = materials.manifest.keys().map(String::as_str).collect();
    assert_eq!(names, ["brick", "glass", "tiles"]);
    let brick = materials.matte("brick");
    let glass = materials.matte("glass");
    for i in 0..brick.len() {
        assert!((brick[i] + glass[i] - a[i] - b[i]).abs() < 1e-5, "pixel {i}");
    }
    assert!(glass.iter().sum::<f32>() > 5.0);
}

#[test]
fn set_objects_are_named_from_the_glb_nodes() {
    // The demo set: every node with a mesh is an object named after it
    // (the four benches share one mesh and keep their own names, as do the
    // four lamps): floor, 7 buildings, 3 shop fronts, 4 lamps, 4 benches.
    let mut assets = throng::scene::gltf::AssetCache::new();
    let set = concat!(env!("CARGO_MANIFEST_DIR"), "/demo/set/set.glb");
    let (placed, names) = assets.load_scene_objects(set).unwrap();
    assert_eq!(names.len(), 19, "{names:?}");
    assert_eq!(names[0], "floor");
    assert!(names.contains(&"bench_3".to_string()) && names.contains(&"building_back_mid".to_string()), "{names:?}");
    assert!(placed.iter().all(|p| (p.3 as usize) < names.len()));
    let benches: BTreeSet<u32> =
        placed.iter().filter(|p| names[p.3 as usize].starts_with("bench_")).map(|p| p.3).collect();
    assert_eq!(benches.len(), 4);
    let lamps: BTreeSet<u32> =
        placed.iter().filter(|p| names[p.3 as usize].starts_with("lamp_")).map(|p| p.3).collect();
    assert_eq!(lamps.len(), 4);
    // The placed primitives are the ones load_scene_instances gives.
    let plain = assets.load_scene_instances(set).unwrap();
    assert_eq!(plain.len(), placed.len());
}
