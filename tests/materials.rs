//! Materials against closed forms: glass (KHR_materials_transmission) in
//! front of a uniform rect light transmits what a slab of two boundaries
//! with every internal reflection does, (1 - R)^2 / (1 - R^2) at normal
//! incidence (R = ((n - 1) / (n + 1))^2), as a thin wall and as a solid
//! (KHR_materials_volume), and Beer's law inside; alpha MASK and BLEND let
//! camera and shadow rays through exactly the cut-out texels of a checker;
//! a constant tilted normal map shades a flat quad like the tilted quad; and
//! the glTF loader reads what the extensions say (KHR_texture_transform,
//! TANGENT, ior, volume), refusing an ior below 1 by name.

mod common;

use std::f32::consts::PI;

use glam::{Affine3A, Vec2, Vec3, Vec4};
use throng::render::accel::BlasSet;
use throng::render::film::{render_frame, Film};
use throng::render::RenderSettings;
use throng::scene::gltf::AssetCache;
use throng::scene::lights::{Light, LightKind, SceneLights};
use throng::scene::{
    vis, AlphaMode, Camera, FrameScene, Instance, InstanceAgent, Library, Material, Mesh, Sky, Sun, Texture,
    TextureRef, UvTransform, Volume,
};

const RES: u32 = 16;

/// A `size` square in the plane z = `z`, front face (counter-clockwise)
/// towards +Z, u along +x and v along -y (glTF's v runs down the image).
fn quad_z(size: f32, z: f32) -> Mesh {
    let h = size / 2.0;
    Mesh {
        name: format!("quad_z{z}"),
        positions: [(-h, -h), (h, -h), (h, h), (-h, h)].map(|(x, y)| Vec3::new(x, y, z)).to_vec(),
        normals: vec![Vec3::Z; 4],
        uvs: vec![Vec2::new(0.0, 1.0), Vec2::new(1.0, 1.0), Vec2::new(1.0, 0.0), Vec2::new(0.0, 0.0)],
        tangents: vec![],
        indices: vec![0, 1, 2, 0, 2, 3],
    }
}

/// A closed box from z0 (back) to z1 (front), `half` wide in x and y,
/// every face counter-clockwise seen from outside.
fn slab(z0: f32, z1: f32, half: f32) -> Mesh {
    let (lo, hi) = (Vec3::new(-half, -half, z0), Vec3::new(half, half, z1));
    let corner = |i: usize| {
        Vec3::new(
            if i & 1 == 0 { lo.x } else { hi.x },
            if i & 2 == 0 { lo.y } else { hi.y },
            if i & 4 == 0 { lo.z } else { hi.z },
        )
    };
    let centre = (lo + hi) / 2.0;
    let faces = [[0, 1, 3, 2], [4, 5, 7, 6], [0, 1, 5, 4], [2, 3, 7, 6], [0, 2, 6, 4], [1, 3, 7, 5]];
    let mut indices = Vec::new();
    for f in faces {
        let [a, b, c, d] = f.map(|i| i as u32);
        let (pa, pb, pc) = (corner(f[0]), corner(f[1]), corner(f[2]));
        let outward = (pa + corner(f[3])) / 2.0 - centre;
        if (pb - pa).cross(pc - pa).dot(outward) > 0.0 {
            indices.extend([a, b, c, a, c, d]);
        } else {
            indices.extend([a, c, b, a, d, c]);
        }
    }
    Mesh { name: "slab".into(), positions: (0..8).map(corner).collect(), indices, ..Default::default() }
}

fn instance(mesh: u32, material: u32, visibility: u8) -> Instance {
    Instance { mesh, material, world_from_object: Affine3A::IDENTITY, agent: InstanceAgent::NONE, part: 0, visibility }
}

fn settings(spp: u32, threads: usize, max_bounces: u32, diffuse_only: bool) -> RenderSettings {
    RenderSettings {
        width: RES,
        height: RES,
        spp,
        max_bounces,
        seed: 11,
        frame: 1,
        sky_visible: true,
        threads,
        indirect_clamp: 0.0,
        diffuse_only,
        ..Default::default()
    }
}

fn render(lib: &Library, scene: &FrameScene, s: &RenderSettings) -> Film {
    render_frame(&BlasSet::build(lib), lib, scene, s, None).expect("render")
}

fn mean_red(film: &Film) -> f64 {
    film.rgba.iter().map(|p| p[0] as f64).sum::<f64>() / film.rgba.len() as f64
}

// ---------------------------------------------------------------- glass

fn glass(ior: f32, volume: Option<Volume>) -> Material {
    Material {
        name: "glass".into(),
        base_color: Vec3::ONE,
        metallic: 0.0,
        roughness: 0.0,
        transmission: 1.0,
        ior,
        volume,
        ..Default::default()
    }
}

/// Looking down -Z through `glass` (z between -1 and -1.5) at a uniform
/// rect light of radiance 1 facing the camera at z = -3, with a black sky;
/// a narrow view, so every ray meets the glass at normal incidence to 1e-4.
fn through_glass(glass_mesh: Mesh, material: Material, threads: usize) -> Film {
    let lib = Library { meshes: vec![glass_mesh], materials: vec![material], textures: vec![] };
    let light = Light {
        name: "backlight".into(),
        kind: LightKind::Rect { size: Vec2::splat(20.0) },
        world_from_light: throng::shot::look_at(Vec3::new(0.0, 0.0, -3.0), Vec3::new(0.0, 0.0, 0.0)),
        emission: Vec3::ONE,
        two_sided: false,
        camera_visible: true,
        light_group: None,
    };
    let lights = SceneLights {
        sun: None,
        sky: Sky { radiance: Vec3::ZERO },
        dome: None,
        local: vec![light],
        groups: Default::default(),
    };
    let scene = FrameScene {
        instances: vec![instance(0, 0, vis::ALL)],
        camera: Camera::pinhole(Affine3A::IDENTITY, 0.02),
        lights,
        motion: None,
    };
    render(&lib, &scene, &settings(256, threads, 24, false))
}

/// Transmittance at normal incidence of a slab whose boundaries reflect R,
/// with every internal reflection, each crossing inside multiplying by `tau`.
fn slab_transmittance(n: f32, tau: f64) -> f64 {
    let r = (((n - 1.0) / (n + 1.0)) as f64).powi(2);
    (1.0 - r).powi(2) * tau / (1.0 - r * r * tau * tau)
}

/// The mean against a closed form, within 4.5 standard errors of a
/// pass-or-not estimate (each sample is 0 or 1 but for internal bounces).
fn assert_transmits(film: &Film, want: f64, what: &str) {
    let n = (RES * RES * 256) as f64;
    let sigma = (want * (1.0 - want) / n).sqrt();
    let got = mean_red(film);
    assert!((got - want).abs() < 4.5 * sigma, "{what}: {got:.5} vs closed form {want:.5} (sigma {sigma:.5})");
}

#[test]
fn thin_glass_transmits_a_two_boundary_slab() {
    for n in [1.5f32, 3.0] {
        let film = through_glass(quad_z(10.0, -1.0), glass(n, None), 0);
        let want = slab_transmittance(n, 1.0);
        assert_transmits(&film, want, &format!("thin wall, ior {n}"));
        // Not one boundary's 1 - R, nor two without internal reflection.
        let r = (((n - 1.0) / (n + 1.0)) as f64).powi(2);
        if n == 3.0 {
            assert!((mean_red(&film) - (1.0 - r)).abs() > 0.1 && (mean_red(&film) - (1.0 - r).powi(2)).abs() > 0.02);
        }
    }
}

#[test]
fn solid_glass_slab_transmits_the_closed_form_and_absorbs_by_beer() {
    let clear = Volume { attenuation_color: Vec3::ONE, attenuation_distance: f32::INFINITY };
    let film = through_glass(slab(-1.5, -1.0, 10.0), glass(3.0, Some(clear)), 0);
    assert_transmits(&film, slab_transmittance(3.0, 1.0), "solid slab, ior 3");
    // Half the light left after the slab's thickness: tau = 0.5 per crossing.
    let murky = Volume { attenuation_color: Vec3::splat(0.5), attenuation_distance: 0.5 };
    let film = through_glass(slab(-1.5, -1.0, 10.0), glass(3.0, Some(murky)), 0);
    assert_transmits(&film, slab_transmittance(3.0, 0.5), "absorbing slab, ior 3");
}

#[test]
fn glass_renders_bit_identically_for_any_thread_count() {
    let clear = Volume { attenuation_color: Vec3::splat(0.8), attenuation_distance: 1.0 };
    let a = through_glass(slab(-1.5, -1.0, 10.0), glass(1.5, Some(clear)), 1);
    let b = through_glass(slab(-1.5, -1.0, 10.0), glass(1.5, Some(clear)), 2);
    assert!(a.rgba.iter().zip(&b.rgba).all(|(p, q)| p.map(f32::to_bits) == q.map(f32::to_bits)));
}

// ---------------------------------------------------------------- alpha

/// Checker images: 32 pixels, 4 x 4 cells of 8.
const CHECKER_RES: u32 = 32;

/// A black 4 x 4 checker of alpha 1 (even cells) and 0 (odd), each cell 4 x
/// 4 texels: bilinear lookups between the texel centres of one cell are
/// exactly its alpha.
fn checker() -> Texture {
    let texels = (0..256)
        .map(|i| if ((i % 16) / 4 + (i / 16) / 4) % 2 == 0 { [0.0, 0.0, 0.0, 1.0] } else { [0.0; 4] })
        .collect();
    Texture { name: "checker".into(), width: 16, height: 16, texels }
}

/// Whether the checker's cell under pixel (x, y) is solid (the quad fills
/// the image exactly, rows top to bottom).
fn solid_cell(x: u32, y: u32) -> bool {
    let per = CHECKER_RES / 4;
    (x / per + y / per).is_multiple_of(2)
}

fn checker_settings(spp: u32, threads: usize) -> RenderSettings {
    RenderSettings { width: CHECKER_RES, height: CHECKER_RES, ..settings(spp, threads, 0, true) }
}

/// A camera far up +Z looking down -Z (nearly orthographic, so the
/// floor behind lines up with the checker to 2 mm); the 4 m checker quad at
/// z = 0 spans the image; a grey floor at z = -1 behind it, seen by camera
/// rays only; a white sky and a sun straight down -Z.
fn checker_scene(mode: AlphaMode, checker_visibility: u8) -> (Library, FrameScene) {
    let holes = Material {
        name: "leaves".into(),
        base_color: Vec3::ONE,
        base_color_texture: Some(0),
        alpha_mode: mode,
        ..Default::default()
    };
    let floor = Material { name: "floor".into(), base_color: Vec3::splat(0.5), ..Default::default() };
    let lib = Library {
        meshes: vec![quad_z(4.0, 0.0), quad_z(100.0, -1.0)],
        materials: vec![holes, floor],
        textures: vec![checker()],
    };
    let sun = Sun { direction: Vec3::Z, angular_diameter: 0.0, irradiance: Vec3::splat(PI) };
    let lights = SceneLights::sun_and_sky(Some(sun), Sky { radiance: Vec3::ONE });
    let scene = FrameScene {
        instances: vec![instance(0, 0, checker_visibility), instance(1, 1, vis::CAMERA)],
        camera: Camera::pinhole(
            Affine3A::from_translation(Vec3::new(0.0, 0.0, 1000.0)),
            2.0 * (2.0f32 / 1000.0).atan(),
        ),
        lights,
        motion: None,
    };
    (lib, scene)
}

/// (x, y, red) of the pixels whose filter footprint (1.5 pixels) stays
/// between the texel centres of one cell (1 pixel in from its edges).
fn cell_centres(film: &Film) -> Vec<(u32, u32, f32)> {
    let per = CHECKER_RES / 4;
    let inner = |i: u32| (2..per - 2).contains(&(i % per));
    let mut out = Vec::new();
    for y in (0..CHECKER_RES).filter(|&y| inner(y)) {
        for x in (0..CHECKER_RES).filter(|&x| inner(x)) {
            out.push((x, y, film.rgba[(y * CHECKER_RES + x) as usize][0]));
        }
    }
    out
}

#[test]
fn cut_out_texels_let_camera_rays_through() {
    for mode in [AlphaMode::Mask { cutoff: 0.5 }, AlphaMode::Blend] {
        // The checker casts no shadow here; max_bounces 0: black where solid, the lit floor where not.
        let (lib, scene) = checker_scene(mode, vis::CAMERA);
        let film = render(&lib, &scene, &checker_settings(16, 0));
        let centres = cell_centres(&film);
        assert!(centres.len() >= 16, "{}", centres.len());
        for (x, y, r) in centres {
            // Through a hole: the floor (albedo 0.5 under irradiance pi: 0.5), where the sun is not blocked.
            let want = if solid_cell(x, y) { 0.0 } else { 0.5 };
            assert!((r - want).abs() < 1e-4, "{mode:?}: pixel ({x}, {y}) {r} vs {want}");
        }
    }
}

#[test]
fn cut_out_texels_let_shadow_rays_through() {
    for mode in [AlphaMode::Mask { cutoff: 0.5 }, AlphaMode::Blend] {
        // The checker only casts shadows: the camera sees the floor, lit through the holes.
        let (lib, scene) = checker_scene(mode, vis::SHADOW);
        let film = render(&lib, &scene, &checker_settings(16, 0));
        for (x, y, r) in cell_centres(&film) {
            let want = if solid_cell(x, y) { 0.0 } else { 0.5 };
            assert!((r - want).abs() < 1e-4, "{mode:?}: pixel ({x}, {y}) {r} vs {want}");
        }
    }
}

#[test]
fn blend_alpha_passes_its_share_and_stays_deterministic() {
    // Constant alpha 0.3 with BLEND: 70 % of the rays reach the floor, camera and shadow alike.
    let (mut lib, scene) = checker_scene(AlphaMode::Blend, vis::ALL);
    lib.materials[0].base_color_texture = None;
    lib.materials[0].alpha = 0.3;
    lib.materials[0].base_color = Vec3::ZERO;
    let s = checker_settings(16, 1);
    let film = render(&lib, &scene, &s);
    // Seen through (0.7) and lit through (0.7): 0.5 x 0.7 x 0.7.
    let want = 0.5 * 0.7 * 0.7;
    // Away from the border, where the pixel filter reaches past the checker.
    let n = CHECKER_RES;
    let inner: Vec<f64> = (2..n - 2)
        .flat_map(|y| (2..n - 2).map(move |x| (x, y)))
        .map(|(x, y)| film.rgba[(y * n + x) as usize][0] as f64)
        .collect();
    let got = inner.iter().sum::<f64>() / inner.len() as f64;
    assert!((got - want).abs() < 0.01, "{got} vs {want}");
    let again = render(&lib, &scene, &RenderSettings { threads: 2, ..s });
    assert!(film.rgba.iter().zip(&again.rgba).all(|(p, q)| p.map(f32::to_bits) == q.map(f32::to_bits)));
}

// ---------------------------------------------------------------- normal maps

/// A 1x1 normal map holding tangent-space normal `n` (linear data).
fn normal_texture(n: Vec3) -> Texture {
    let c = (n.normalize() + Vec3::ONE) * 0.5;
    Texture { name: "normal".into(), width: 1, height: 1, texels: vec![[c.x, c.y, c.z, 1.0]] }
}

/// A flat white Lambert quad facing +Z (tangent +x, bitangent +y), seen
/// from +Z, lit by a sun from `sun` only: its radiance is irradiance x
/// cos(shading normal, sun) / pi.
fn lit_quad(mesh: Mesh, normal_map: Option<(Texture, f32)>, sun: Vec3) -> f64 {
    let mut material = Material { name: "bumpy".into(), base_color: Vec3::ONE, ..Default::default() };
    let mut textures = Vec::new();
    if let Some((t, scale)) = normal_map {
        textures.push(t);
        material.normal_texture = Some(TextureRef::plain(0));
        material.normal_scale = scale;
    }
    let lib = Library { meshes: vec![mesh], materials: vec![material], textures };
    let sun = Sun { direction: sun.normalize(), angular_diameter: 0.0, irradiance: Vec3::splat(PI) };
    let scene = FrameScene {
        instances: vec![instance(0, 0, vis::ALL)],
        camera: Camera::pinhole(Affine3A::from_translation(Vec3::new(0.0, 0.0, 5.0)), 0.2),
        lights: SceneLights::sun_and_sky(Some(sun), Sky { radiance: Vec3::ZERO }),
        motion: None,
    };
    mean_red(&render(&lib, &scene, &settings(4, 0, 0, true)))
}

#[test]
fn a_tilted_normal_map_shades_like_a_tilted_quad() {
    let theta = 0.5f32;
    let sun = Vec3::new(0.6, 0.3, 0.8);
    for (tilt, what) in [
        (Vec3::new(theta.sin(), 0.0, theta.cos()), "towards the tangent (+u)"),
        (Vec3::new(0.0, theta.sin(), theta.cos()), "towards the bitangent (up the image, -v)"),
        (Vec3::new(-theta.sin(), 0.0, theta.cos()), "away from the tangent"),
    ] {
        // The map's tangent space is the quad's world frame here: x = +u, y = up the image.
        let want = tilt.dot(sun.normalize()).max(0.0) as f64;
        let got = lit_quad(quad_z(4.0, 0.0), Some((normal_texture(tilt), 1.0)), sun);
        assert!((got - want).abs() < 1e-4, "{what}: {got} vs {want}");
        // The same from glTF TANGENT (+x, w = 1) instead of the UVs.
        let mut with_tangents = quad_z(4.0, 0.0);
        with_tangents.tangents = vec![Vec4::new(1.0, 0.0, 0.0, 1.0); 4];
        let got = lit_quad(with_tangents, Some((normal_texture(tilt), 1.0)), sun);
        assert!((got - want).abs() < 1e-4, "{what}, TANGENT: {got} vs {want}");
        // And the tilted quad itself, flat shaded.
        let mut tilted = quad_z(4.0, 0.0);
        let r = glam::Quat::from_rotation_arc(Vec3::Z, tilt);
        tilted.positions.iter_mut().for_each(|p| *p = r * *p);
        tilted.normals = vec![tilt; 4];
        let geometric = lit_quad(tilted, None, sun);
        assert!((geometric - want).abs() < 1e-4, "{what}, tilted geometry: {geometric} vs {want}");
    }
    // TANGENT's w = -1 mirrors the bitangent: a +Y tilt leans down the image.
    let up = Vec3::new(0.0, theta.sin(), theta.cos());
    let mut mirrored = quad_z(4.0, 0.0);
    mirrored.tangents = vec![Vec4::new(1.0, 0.0, 0.0, -1.0); 4];
    let want = Vec3::new(0.0, -theta.sin(), theta.cos()).dot(sun.normalize()) as f64;
    let got = lit_quad(mirrored, Some((normal_texture(up), 1.0)), sun);
    assert!((got - want).abs() < 1e-4, "w = -1: {got} vs {want}");
    // normalTexture.scale scales X and Y of the map.
    let scaled = Vec3::new(0.5 * theta.sin(), 0.0, theta.cos()).normalize();
    let got = lit_quad(quad_z(4.0, 0.0), Some((normal_texture(Vec3::new(theta.sin(), 0.0, theta.cos())), 0.5)), sun);
    let want = scaled.dot(sun.normalize()) as f64;
    assert!((got - want).abs() < 1e-3, "scale 0.5: {got} vs {want}");
}

// ---------------------------------------------------------------- KHR_texture_transform

#[test]
fn texture_transform_follows_the_extensions_example() {
    // KHR_texture_transform's example: the lower-left quadrant, rotated 90 degrees.
    let t = UvTransform {
        offset: Vec2::new(0.0, 1.0),
        rotation: std::f32::consts::FRAC_PI_2,
        scale: Vec2::splat(0.5),
        tex_coord: 0,
    };
    for (uv, want) in
        [((0.0, 0.0), (0.0, 1.0)), ((1.0, 0.0), (0.0, 0.5)), ((0.0, 1.0), (0.5, 1.0)), ((1.0, 1.0), (0.5, 0.5))]
    {
        let got = t.apply(Vec2::new(uv.0, uv.1));
        assert!((got - Vec2::new(want.0, want.1)).length() < 1e-6, "{uv:?} -> {got} (want {want:?})");
    }
    // The identity is exact.
    let uv = Vec2::new(0.123_456_7, 9.876_543);
    assert_eq!(UvTransform::IDENTITY.apply(uv), uv);
}

// ---------------------------------------------------------------- the glTF loader

/// One triangle with normals, UVs and tangents, and `material` (JSON), in a
/// .gltf beside its .bin and a 2x2 PNG, in `dir`.
fn write_gltf(dir: &std::path::Path, name: &str, material: &str) -> std::path::PathBuf {
    let mut bin = Vec::new();
    for v in [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]] {
        v.iter().for_each(|f| bin.extend(f.to_le_bytes()));
    }
    for _ in 0..3 {
        [0.0f32, 0.0, 1.0].iter().for_each(|f| bin.extend(f.to_le_bytes()));
    }
    for uv in [[0.0f32, 1.0], [1.0, 1.0], [0.0, 0.0]] {
        uv.iter().for_each(|f| bin.extend(f.to_le_bytes()));
    }
    for _ in 0..3 {
        [1.0f32, 0.0, 0.0, -1.0].iter().for_each(|f| bin.extend(f.to_le_bytes()));
    }
    std::fs::write(dir.join(format!("{name}.bin")), &bin).unwrap_or_else(|e| panic!("{e}"));
    let png = image::RgbaImage::from_fn(2, 2, |x, _| image::Rgba([128, 128, if x == 0 { 255 } else { 0 }, 255]));
    png.save(dir.join("map.png")).unwrap_or_else(|e| panic!("{e}"));
    let json = format!(
        r#"{{"asset":{{"version":"2.0"}},
        "extensionsUsed":["KHR_materials_transmission","KHR_materials_ior","KHR_materials_volume","KHR_texture_transform"],
        "buffers":[{{"uri":"{name}.bin","byteLength":{len}}}],
        "bufferViews":[{{"buffer":0,"byteOffset":0,"byteLength":36}},{{"buffer":0,"byteOffset":36,"byteLength":36}},
                       {{"buffer":0,"byteOffset":72,"byteLength":24}},{{"buffer":0,"byteOffset":96,"byteLength":48}}],
        "accessors":[{{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}},
                     {{"bufferView":1,"componentType":5126,"count":3,"type":"VEC3"}},
                     {{"bufferView":2,"componentType":5126,"count":3,"type":"VEC2"}},
                     {{"bufferView":3,"componentType":5126,"count":3,"type":"VEC4"}}],
        "images":[{{"uri":"map.png"}}],
        "textures":[{{"source":0}}],
        "materials":[{material}],
        "meshes":[{{"name":"tri","primitives":[{{"attributes":{{"POSITION":0,"NORMAL":1,"TEXCOORD_0":2,"TANGENT":3}},"material":0}}]}}],
        "nodes":[{{"name":"tri","mesh":0}}],
        "scenes":[{{"nodes":[0]}}],"scene":0}}"#,
        len = bin.len()
    );
    let path = dir.join(format!("{name}.gltf"));
    std::fs::write(&path, json).unwrap_or_else(|e| panic!("{e}"));
    path
}

#[test]
fn gltf_materials_read_transmission_ior_volume_alpha_normal_maps_and_transforms() {
    let dir = common::tempdir().unwrap_or_else(|e| panic!("{e}"));
    let material = r#"{"name":"pane",
        "pbrMetallicRoughness":{"baseColorFactor":[0.9,0.8,0.7,0.6],"roughnessFactor":0.25,
            "baseColorTexture":{"index":0,"extensions":{"KHR_texture_transform":{"offset":[0.5,0.25],"rotation":0.5,"scale":[2,3]}}},
            "metallicRoughnessTexture":{"index":0,"texCoord":1}},
        "normalTexture":{"index":0,"scale":0.5,"extensions":{"KHR_texture_transform":{"offset":[0.1,0.2]}}},
        "alphaMode":"MASK","alphaCutoff":0.3,"doubleSided":true,
        "extensions":{"KHR_materials_transmission":{"transmissionFactor":0.75,"transmissionTexture":{"index":0}},
                      "KHR_materials_ior":{"ior":1.33},
                      "KHR_materials_volume":{"thicknessFactor":0.1,"attenuationColor":[0.5,0.6,0.7],"attenuationDistance":2}}}"#;
    let path = write_gltf(dir.path(), "pane", material);
    let mut cache = AssetCache::new();
    let mesh = cache.mesh(&path, "tri").unwrap_or_else(|e| panic!("{e}"));
    let id = cache.gltf_material(&path, "tri").unwrap_or_else(|e| panic!("{e}"));
    let lib = cache.library();
    let m = &lib.materials[id as usize];
    assert_eq!(lib.meshes[mesh as usize].tangents, vec![Vec4::new(1.0, 0.0, 0.0, -1.0); 3]);
    assert_eq!(m.alpha, 0.6);
    assert_eq!(m.alpha_mode, AlphaMode::Mask { cutoff: 0.3 });
    assert!(m.double_sided);
    assert_eq!(m.base_color_uv.offset, Vec2::new(0.5, 0.25));
    assert_eq!((m.base_color_uv.rotation, m.base_color_uv.scale), (0.5, Vec2::new(2.0, 3.0)));
    // On TEXCOORD_1, which throng does not load: left out.
    assert_eq!(m.metallic_roughness_texture, None);
    let normal = m.normal_texture.unwrap_or_else(|| panic!("normal map"));
    assert_eq!((normal.uv.offset, m.normal_scale), (Vec2::new(0.1, 0.2), 0.5));
    assert_eq!((m.transmission, m.ior), (0.75, 1.33));
    let v = m.volume.unwrap_or_else(|| panic!("volume"));
    assert_eq!((v.attenuation_color, v.attenuation_distance), (Vec3::new(0.5, 0.6, 0.7), 2.0));
    // The same image as colour (sRGB-decoded) and as data (linear): two textures.
    let colour = &lib.textures[m.base_color_texture.unwrap_or(u32::MAX) as usize];
    let data = &lib.textures[normal.texture as usize];
    assert!((data.texels[0][0] - 128.0 / 255.0).abs() < 1e-6, "{:?}", data.texels[0]);
    assert!((colour.texels[0][0] - throng::scene::gltf::srgb_to_linear(128.0 / 255.0)).abs() < 1e-6);
    assert_eq!(m.transmission_texture.map(|t| t.texture), Some(normal.texture), "data textures are shared");
}

#[test]
fn gltf_defaults_are_opaque_thin_and_ior_one_and_a_half() {
    let dir = common::tempdir().unwrap_or_else(|e| panic!("{e}"));
    let thin = r#"{"name":"thin","extensions":{"KHR_materials_transmission":{"transmissionFactor":1},
        "KHR_materials_volume":{"thicknessFactor":0}}}"#;
    let path = write_gltf(dir.path(), "thin", thin);
    let mut cache = AssetCache::new();
    let id = cache.gltf_material(&path, "tri").unwrap_or_else(|e| panic!("{e}"));
    let m = &cache.library().materials[id as usize];
    // glTF: thickness 0 is a thin wall; no KHR_materials_ior is 1.5; alpha OPAQUE; single-sided.
    assert_eq!(
        (m.transmission, m.ior, m.volume, m.alpha_mode, m.double_sided),
        (1.0, 1.5, None, AlphaMode::Opaque, false)
    );
}

#[test]
fn gltf_bad_material_values_are_refused_by_name() {
    let dir = common::tempdir().unwrap_or_else(|e| panic!("{e}"));
    for (name, material, field) in [
        ("low_ior", r#"{"name":"water","extensions":{"KHR_materials_ior":{"ior":0.9}}}"#, "KHR_materials_ior.ior"),
        (
            "much",
            r#"{"name":"much","extensions":{"KHR_materials_transmission":{"transmissionFactor":1.5}}}"#,
            "transmissionFactor",
        ),
        ("cutoff", r#"{"name":"cut","alphaMode":"MASK","alphaCutoff":-1}"#, "alphaCutoff"),
    ] {
        let path = write_gltf(dir.path(), name, material);
        let err = AssetCache::new().gltf_material(&path, "tri").err().map(|e| e.to_string()).unwrap_or_default();
        assert!(err.contains(&format!("{name}.gltf")) && err.contains(field), "{err}");
    }
}

// ---------------------------------------------------------------- cut-out emitters

/// The floor's mean radiance under an emissive panel 2 m above it facing
/// down (seen by bounce rays only, so NEE and BSDF rays both find it), with
/// alpha `alpha` in `mode`.
fn under_panel(mode: AlphaMode, alpha: f32, spp: u32) -> f64 {
    let mut panel = quad_z(1.0, 2.0);
    panel.indices = vec![0, 2, 1, 0, 3, 2]; // front face down, towards the floor
    let glow = Material {
        name: "sign".into(),
        base_color: Vec3::ZERO,
        emission: Vec3::splat(4.0),
        alpha,
        alpha_mode: mode,
        ..Default::default()
    };
    let floor = Material { name: "floor".into(), base_color: Vec3::splat(0.5), ..Default::default() };
    let lib = Library { meshes: vec![panel, quad_z(100.0, 0.0)], materials: vec![glow, floor], textures: vec![] };
    let scene = FrameScene {
        instances: vec![instance(0, 0, vis::INDIRECT | vis::SHADOW), instance(1, 1, vis::ALL)],
        camera: Camera::pinhole(Affine3A::from_translation(Vec3::new(0.0, 0.0, 10.0)), 0.1),
        lights: SceneLights::sun_and_sky(None, Sky { radiance: Vec3::ZERO }),
        motion: None,
    };
    mean_red(&render(&lib, &scene, &settings(spp, 0, 1, true)))
}

#[test]
fn cut_out_emitters_light_by_their_coverage() {
    let full = under_panel(AlphaMode::Opaque, 1.0, 64);
    assert!(full > 0.05, "{full}");
    // Below the cutoff the panel is not there: no light, by NEE or by bounce rays.
    assert_eq!(under_panel(AlphaMode::Mask { cutoff: 0.5 }, 0.2, 16), 0.0);
    assert_eq!(under_panel(AlphaMode::Mask { cutoff: 0.5 }, 0.8, 64), full, "solid where alpha >= cutoff");
    // BLEND at alpha 0.4 emits 40 % on average: NEE by the coverage, bounce rays by the coin.
    let blend = under_panel(AlphaMode::Blend, 0.4, 64);
    assert!((blend / full - 0.4).abs() < 0.02, "{blend} vs 0.4 x {full}");
}
