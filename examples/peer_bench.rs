//! throng's renderer on the peer harness's scenes and conventions
//! (/work/shared/peers: Cycles, Mitsuba, Embree), for side-by-side figures.
//! See docs/benchmarks.md for the commands and the measured numbers.
//!
//! ```text
//! cargo run --release --example peer_bench -- SCENE.glb [--out PREFIX] [options]
//! cargo run --release --example peer_bench -- --synthetic N [--out PREFIX] [options]
//! options: --res W H (960 540)  --spp S (64)  --bounces B (5)  --threads T (2)
//!          --sky R G B (0.30 0.38 0.50)  --seed S (0)  --materials diffuse|gltf (diffuse)
//!          --camera NODE (first node with a perspective camera)  --no-rays  --no-render
//!          --hdri FILE (.hdr/.exr lat-long; replaces --sky)  --hdri-strength S (1)  --hdri-rotate DEG (0)
//!          --no-sun (drop the sun)  --sun-angle DEG (the sun's angular diameter, 0: delta)  --sun-direction X Y Z (towards the sun)  --point-lights N (N lamps 4 m over the scene, 2,000 W/sr in all)
//!          --atmosphere DENSITY ALBEDO G HEIGHT (haze below HEIGHT, mode full: render::atmosphere)
//!          --adaptive THRESHOLD MIN MAX (adaptive sampling, render.adaptive's keys; replaces --spp)
//!          --denoise (Open Image Denoise on the render, quality high: `denoise_s`; the EXR then holds
//!          the denoised beauty as R, G, B and the noisy one as noisy.R/G/B)
//! ```
//! Any .glb with a perspective camera (make_crowd.py output, `throng export`
//! output), lit by its KHR_lights_punctual lights (directional, point, spot)
//! and emissive materials. Conventions as the peers' scripts: sun irradiance
//! W/m^2 = lux / 683, point and spot W/sr = cd / 683, Blender's spot edge,
//! emission = emissiveFactor x strength, hard lights (angular diameter and
//! radius 0), uniform sky radiance or the HDRI visible to the camera, no
//! clamping, pure Lambert materials from the base colour
//! (`RenderSettings::diffuse_only`).
//!
//! Bounces: our `max_bounces` B traces up to B BSDF-sampled rays after the
//! camera ray and does sun next-event estimation at every vertex 0..=B.
//! Cycles `max_bounces = 4` / Mitsuba `max_depth = 6` trace 5 BSDF rays
//! (from vertices 0..=4; the last can only pick up the sky) and sample the
//! sun at vertices 0..=4. So the default B = 5 traces the same sky paths and
//! the same number of bounce rays, plus one sun shadow ray at vertex 5 (a
//! fifth-order sun bounce; B = 4 would instead drop the sky seen from vertex 4).
//!
//! Environment switches (A/B runs of one binary): THRONG_TRAVERSAL=wide|avx2|obvhs|scalar,
//! THRONG_PACKETS=1|0 (camera rays as packets or singly), THRONG_FLATTEN=0|1|one
//! (every instance's triangles baked into world-space meshes: one per material, or one in all).
//!
//! `--synthetic N`: N agents x 11 rigid parts sharing 8 meshes (make_crowd.py's
//! shape: ~1,060 triangles per agent, density 0.5 agents/m^2, a ground quad 4x
//! the field), built in memory, to measure memory at 100,000 and 1,000,000 agents.
//!
//! Prints one JSON line: load_s (glb import or synthetic build), blas_build_s,
//! tlas_build_s, first_sample_s (start of load to the first finished 16x16
//! tile, an upper bound on the first sample), render_s (render call: TLAS
//! build + tracing), trace_s, total_s, peak_rss_mib (VmHWM) after the render
//! and at the end, triangles (instanced), unique_triangles, and the
//! single-thread closest-hit ray rates measured like the peers' Embree script:
//! `primary` (one ray per pixel centre) and `bounce` (one cosine-weighted ray
//! from every primary hit), best wall time of 3 and per thread CPU second.
//! Primary rays go as packets (blocks of 8x4 pixels through
//! `Tlas::intersect_stream`), as the render's camera rays do, unless
//! THRONG_PACKETS=0 (which also makes the render trace camera rays one by
//! one); THRONG_TRAVERSAL=obvhs|scalar|avx2|wide picks the node test kernel.

use std::f32::consts::PI;
use std::path::PathBuf;
use std::sync::Mutex;
use std::time::Instant;

use glam::{Affine3A, Quat, Vec2, Vec3};
use throng::render::accel::{Tlas, TlasKind, WorldRay};
use throng::render::bsdf::ShadingFrame;
use throng::render::camera::CameraRays;
use throng::render::exr::{camera_matrices, write_layer, write_preview_png, LayerMeta, ID_MAPPING};
use throng::render::film::render_frame_with_stats;
use throng::render::integrator::offset_ray_origin;
use throng::render::sampling::sample_cosine_hemisphere;
use throng::render::wide::Traversal;
use throng::render::{BlasSet, RenderSettings, Tracing};
use throng::scene::dome::load_dome;
use throng::scene::gltf::{AssetCache, LUMENS_PER_WATT};
use throng::scene::lights::{Light, LightKind};
use throng::scene::{
    lights::SceneLights, vis, Camera, FrameScene, Instance, InstanceAgent, Library, Material, Mesh, Sky, Sun,
};

struct Args {
    scene: Option<PathBuf>,
    synthetic: Option<usize>,
    out: Option<PathBuf>,
    res: (u32, u32),
    spp: u32,
    bounces: u32,
    threads: usize,
    sky: Vec3,
    seed: u64,
    diffuse: bool,
    camera: Option<String>,
    hdri: Option<PathBuf>,
    hdri_strength: f32,
    hdri_rotate: f32,
    no_sun: bool,
    sun_angle: Option<f32>,
    sun_direction: Option<Vec3>,
    point_lights: usize,
    atmosphere: Option<throng::render::atmosphere::Atmosphere>,
    adaptive: Option<throng::shot::Adaptive>,
    rays: bool,
    denoise: bool,
    render: bool,
}

fn parse_args() -> Result<Args, String> {
    let mut a = Args {
        scene: None,
        synthetic: None,
        out: None,
        res: (960, 540),
        spp: 64,
        bounces: 5,
        threads: 2,
        sky: Vec3::new(0.30, 0.38, 0.50),
        seed: 0,
        diffuse: true,
        camera: None,
        hdri: None,
        hdri_strength: 1.0,
        hdri_rotate: 0.0,
        no_sun: false,
        sun_angle: None,
        sun_direction: None,
        point_lights: 0,
        atmosphere: None,
        adaptive: None,
        rays: true,
        denoise: false,
        render: true,
    };
    let mut it = std::env::args().skip(1);
    fn num<T: std::str::FromStr>(it: &mut impl Iterator<Item = String>, flag: &str) -> Result<T, String> {
        let v = it.next().ok_or(format!("{flag} needs a value"))?;
        v.parse().map_err(|_| format!("{flag}: cannot parse `{v}`"))
    }
    while let Some(arg) = it.next() {
        match arg.as_str() {
            "--synthetic" => a.synthetic = Some(num(&mut it, &arg)?),
            "--out" => a.out = Some(PathBuf::from(it.next().ok_or("--out needs a value")?)),
            "--res" => a.res = (num(&mut it, &arg)?, num(&mut it, &arg)?),
            "--spp" => a.spp = num(&mut it, &arg)?,
            "--bounces" => a.bounces = num(&mut it, &arg)?,
            "--threads" => a.threads = num(&mut it, &arg)?,
            "--sky" => a.sky = Vec3::new(num(&mut it, &arg)?, num(&mut it, &arg)?, num(&mut it, &arg)?),
            "--seed" => a.seed = num(&mut it, &arg)?,
            "--materials" => {
                a.diffuse = match it.next().as_deref() {
                    Some("diffuse") => true,
                    Some("gltf") => false,
                    other => return Err(format!("--materials diffuse|gltf, not {other:?}")),
                }
            }
            "--camera" => a.camera = Some(it.next().ok_or("--camera needs a node name")?),
            "--hdri" => a.hdri = Some(PathBuf::from(it.next().ok_or("--hdri needs a file")?)),
            "--hdri-strength" => a.hdri_strength = num(&mut it, &arg)?,
            "--hdri-rotate" => a.hdri_rotate = num(&mut it, &arg)?,
            "--no-sun" => a.no_sun = true,
            "--sun-angle" => a.sun_angle = Some(num(&mut it, &arg)?),
            "--sun-direction" => {
                let d = Vec3::new(num(&mut it, &arg)?, num(&mut it, &arg)?, num(&mut it, &arg)?);
                a.sun_direction = Some(d.try_normalize().ok_or("--sun-direction: a zero vector")?);
            }
            "--point-lights" => a.point_lights = num(&mut it, &arg)?,
            "--atmosphere" => {
                let air = throng::render::atmosphere::Atmosphere {
                    density: num(&mut it, &arg)?,
                    albedo: Vec3::splat(num(&mut it, &arg)?),
                    anisotropy: num(&mut it, &arg)?,
                    top: num(&mut it, &arg)?,
                    ..Default::default()
                };
                air.check().map_err(|(key, m)| format!("--atmosphere ({key}): {m}"))?;
                a.atmosphere = Some(air);
            }
            "--adaptive" => {
                let adaptive = throng::shot::Adaptive {
                    threshold: num(&mut it, &arg)?,
                    min_spp: num(&mut it, &arg)?,
                    max_spp: num(&mut it, &arg)?,
                };
                adaptive.check().map_err(|(key, m)| format!("--adaptive ({key}): {m}"))?;
                a.adaptive = Some(adaptive);
            }
            "--no-rays" => a.rays = false,
            "--denoise" => a.denoise = true,
            "--no-render" => a.render = false,
            s if s.starts_with("--") => return Err(format!("unknown flag {s}")),
            s => a.scene = Some(PathBuf::from(s)),
        }
    }
    if a.scene.is_none() == a.synthetic.is_none() {
        return Err("give either SCENE.glb or --synthetic N".into());
    }
    Ok(a)
}

/// A scene ready to render, with what loading it cost.
struct Loaded {
    lib: Library,
    scene: FrameScene,
    /// When loading started (the reference for `first_sample_s`).
    started: Instant,
    load_s: f64,
}

/// The first node with a perspective camera (the peers' scripts use the first camera).
fn first_camera_node(path: &PathBuf) -> Result<String, String> {
    let doc = gltf::Gltf::open(path).map_err(|e| format!("{}: {e}", path.display()))?;
    let node = doc
        .nodes()
        .find(|n| n.camera().is_some_and(|c| matches!(c.projection(), gltf::camera::Projection::Perspective(_))))
        .ok_or(format!("{}: no node with a perspective camera", path.display()))?;
    node.name()
        .map(str::to_string)
        .ok_or(format!("{}: the camera node has no name (needed by find_camera)", path.display()))
}

fn load_glb(path: &PathBuf, args: &Args) -> Result<Loaded, String> {
    let camera_node = match &args.camera {
        Some(c) => c.clone(),
        None => first_camera_node(path)?,
    };
    let start = Instant::now();
    let mut cache = AssetCache::new();
    let placed = cache.load_scene_instances(path).map_err(|e| e.to_string())?;
    let camera = cache.find_camera(path, &camera_node).map_err(|e| e.to_string())?;
    let local = cache.punctual_lights(path).map_err(|e| e.to_string())?;
    let lib = cache.into_library();
    let instances = placed
        .into_iter()
        .map(|(mesh, material, world_from_object)| Instance {
            mesh,
            material,
            world_from_object,
            agent: InstanceAgent::NONE,
            part: 0,
            visibility: vis::ALL,
        })
        .collect();
    let load_s = start.elapsed().as_secs_f64();
    let dome = match &args.hdri {
        Some(file) => Some(std::sync::Arc::new(
            load_dome(file, Vec3::splat(args.hdri_strength), args.hdri_rotate.to_radians(), true)
                .map_err(|e| e.to_string())?,
        )),
        None => None,
    };
    let lights = SceneLights { sun: None, sky: Sky { radiance: args.sky }, dome, local, groups: Default::default() };
    Ok(Loaded { lib, scene: FrameScene { instances, camera, lights, motion: None }, started: start, load_s })
}

// ------------------------------------------------------------ synthetic crowd

struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f32 {
        self.0 = self.0.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (self.0 >> 40) as f32 / (1u64 << 24) as f32
    }
}

/// `n` point lights on a square grid 4 m over the middle half of the
/// scene's footprint, 2,000 W/sr shared between them (the same total light
/// whatever `n`, for timing many lights against one).
fn lamps(lib: &Library, scene: &FrameScene, n: usize) -> Vec<Light> {
    if n == 0 {
        return Vec::new();
    }
    let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for inst in scene.instances.iter().skip(1) {
        if let Some(m) = lib.meshes.get(inst.mesh as usize) {
            let (a, b) = m.bounds();
            lo = lo.min(inst.world_from_object.transform_point3(a));
            hi = hi.max(inst.world_from_object.transform_point3(b));
        }
    }
    let (centre, half) = (0.5 * (lo + hi), 0.25 * (hi - lo));
    let side = (n as f32).sqrt().ceil() as usize;
    (0..n)
        .map(|k| {
            let (i, j) = ((k % side) as f32 + 0.5, (k / side) as f32 + 0.5);
            let p = Vec3::new(
                centre.x - half.x + 2.0 * half.x * i / side as f32,
                4.0,
                centre.z - half.z + 2.0 * half.z * j / side as f32,
            );
            Light {
                name: format!("lamp{k}"),
                kind: LightKind::Point,
                world_from_light: Affine3A::from_translation(p),
                emission: Vec3::new(1.0, 0.8, 0.6) * (2000.0 / n as f32),
                two_sided: false,
                camera_visible: false,
                light_group: None,
            }
        })
        .collect()
}

fn quad(half: f32) -> Mesh {
    Mesh {
        name: "ground".into(),
        positions: vec![
            Vec3::new(-half, 0.0, -half),
            Vec3::new(half, 0.0, -half),
            Vec3::new(half, 0.0, half),
            Vec3::new(-half, 0.0, half),
        ],
        normals: vec![Vec3::Y; 4],
        uvs: vec![],
        tangents: vec![],
        indices: vec![0, 2, 1, 0, 3, 2],
    }
}

/// make_crowd.py's shape in memory: ground, N agents of 11 parts (a ~500
/// triangle head from 4 variants, box torso and pelvis, 8 capsule-ish limbs
/// from 2 variants), 6 materials; camera auto-framed (yfov 40 deg, 28 deg
/// elevation), sun at 50 deg elevation, 3 W/m^2.
fn synthetic(n: usize, args: &Args) -> Loaded {
    let start = Instant::now();
    let density = 0.5f32;
    let depth = (n.max(1) as f32 / density / 1.6).sqrt();
    let width = depth * 1.6;
    let ground_half = (2.0 * width).max(100.0);
    let mut meshes = vec![quad(ground_half), Mesh::cube("cube")];
    for (k, (rings, segs)) in [(16u32, 16u32), (15, 17), (14, 18), (16, 15)].iter().enumerate() {
        meshes.push(Mesh::uv_sphere(&format!("head{k}"), 0.5, *rings, *segs));
    }
    meshes.push(Mesh::uv_sphere("limb0", 0.5, 6, 6));
    meshes.push(Mesh::uv_sphere("limb1", 0.5, 5, 7));
    let m = |name: &str, c: [f32; 3]| Material {
        name: name.into(),
        base_color: Vec3::from(c),
        base_color_texture: None,
        roughness: 1.0,
        metallic: 0.0,
        ..Default::default()
    };
    let materials = vec![
        m("ground", [0.5, 0.5, 0.5]),
        m("skin", [0.6, 0.45, 0.35]),
        m("shirt_red", [0.6, 0.1, 0.08]),
        m("shirt_blue", [0.1, 0.2, 0.6]),
        m("shirt_yellow", [0.7, 0.6, 0.1]),
        m("trousers", [0.25, 0.22, 0.2]),
    ];
    // (mesh: 0 head, 1 box, 2 limb; centre; size; material: 0 skin, 1 shirt, 2 trousers)
    let slots: [(u8, [f32; 3], [f32; 3], u8); 11] = [
        (0, [0.0, 1.6, 0.0], [0.24, 0.27, 0.24], 0),
        (1, [0.0, 1.2, 0.0], [0.4, 0.5, 0.22], 1),
        (1, [0.0, 0.9, 0.0], [0.35, 0.15, 0.2], 2),
        (2, [-0.27, 1.25, 0.0], [0.1, 0.3, 0.1], 1),
        (2, [-0.27, 0.95, 0.0], [0.09, 0.3, 0.09], 0),
        (2, [0.27, 1.25, 0.0], [0.1, 0.3, 0.1], 1),
        (2, [0.27, 0.95, 0.0], [0.09, 0.3, 0.09], 0),
        (2, [-0.1, 0.62, 0.0], [0.13, 0.4, 0.13], 2),
        (2, [-0.1, 0.22, 0.0], [0.11, 0.42, 0.11], 2),
        (2, [0.1, 0.62, 0.0], [0.13, 0.4, 0.13], 2),
        (2, [0.1, 0.22, 0.0], [0.11, 0.42, 0.11], 2),
    ];
    let mut rng = Lcg(n as u64 ^ 0x5eed);
    let mut instances = Vec::with_capacity(1 + 11 * n);
    instances.push(Instance {
        mesh: 0,
        material: 0,
        world_from_object: Affine3A::IDENTITY,
        agent: InstanceAgent::NONE,
        part: 0,
        visibility: vis::ALL,
    });
    // Jittered grid, `cols` x `rows` cells over the field.
    let cols = ((n as f32 * 1.6).sqrt().ceil() as usize).max(1);
    let rows = n.div_ceil(cols).max(1);
    let (cw, ch) = (width / cols as f32, depth / rows as f32);
    for a in 0..n {
        let (c, r) = (a % cols, a / cols);
        let x = -0.5 * width + (c as f32 + 0.2 + 0.6 * rng.next()) * cw;
        let z = -0.5 * depth + (r as f32 + 0.2 + 0.6 * rng.next()) * ch;
        let scale = 0.9 + 0.2 * rng.next();
        let agent = Affine3A::from_scale_rotation_translation(
            Vec3::splat(scale),
            Quat::from_rotation_y(rng.next() * 2.0 * PI),
            Vec3::new(x, 0.0, z),
        );
        let head = 2 + (rng.next() * 4.0) as u32 % 4;
        let limb = 6 + (rng.next() * 2.0) as u32 % 2;
        let shirt = 2 + (rng.next() * 3.0) as u32 % 3;
        for (k, (kind, centre, size, mat)) in slots.iter().enumerate() {
            let swing = if k >= 3 { (rng.next() - 0.5) * 0.6 } else { 0.0 };
            let local = Affine3A::from_scale_rotation_translation(
                Vec3::from(*size),
                Quat::from_rotation_x(swing),
                Vec3::from(*centre),
            );
            instances.push(Instance {
                mesh: [head, 1, limb][*kind as usize],
                material: [1, shirt, 5][*mat as usize],
                world_from_object: agent * local,
                agent: InstanceAgent::some(a as u32),
                part: k as u16,
                visibility: vis::ALL,
            });
        }
    }
    // Camera: 28 deg elevation, yfov 40 deg, far enough back to see the whole field.
    let yfov = 40f32.to_radians();
    let elevation = 28f32.to_radians();
    let aspect = args.res.0 as f32 / args.res.1 as f32;
    let distance =
        (0.5 * width / ((0.5 * yfov).tan() * aspect)).max(0.5 * depth / (0.5 * yfov).tan()) * 1.15 + 0.5 * depth;
    let eye = Vec3::new(0.0, distance * elevation.sin(), distance * elevation.cos());
    let forward = (Vec3::new(0.0, 0.8, 0.0) - eye).normalize();
    let right = forward.cross(Vec3::Y).normalize();
    let up = right.cross(forward);
    let camera = Camera::pinhole(Affine3A::from_cols(right.into(), up.into(), (-forward).into(), eye.into()), yfov);
    let sun_elevation = 50f32.to_radians();
    let sun_direction =
        Vec3::new(-0.5 * sun_elevation.cos(), sun_elevation.sin(), 0.87 * sun_elevation.cos()).normalize();
    let sun = Some(Sun {
        direction: sun_direction,
        angular_diameter: 0.0,
        irradiance: Vec3::splat(2049.0 / LUMENS_PER_WATT),
    });
    let lib = Library { meshes, materials, textures: vec![] };
    let load_s = start.elapsed().as_secs_f64();
    Loaded {
        lib,
        scene: FrameScene {
            instances,
            camera,
            lights: SceneLights::sun_and_sky(sun, Sky { radiance: args.sky }),
            motion: None,
        },
        started: start,
        load_s,
    }
}

// ------------------------------------------------------------ ray rates

/// Geometric normal of a hit, world space, unnormalised.
fn hit_normal(lib: &Library, inst: &Instance, triangle: u32) -> Option<Vec3> {
    let mesh = lib.meshes.get(inst.mesh as usize)?;
    let i = triangle as usize * 3;
    let idx = mesh.indices.get(i..i + 3)?;
    let p = |k: u32| mesh.positions.get(k as usize).map(|&v| inst.world_from_object.transform_point3(v));
    let (a, b, c) = (p(idx[0])?, p(idx[1])?, p(idx[2])?);
    Some((b - a).cross(c - a))
}

/// Rays per second (best wall time of 3, and rays per thread-CPU second of
/// the best run) tracing `rays` closest-hit on the calling thread; and the
/// hit fraction. With `stream`, `rays` go to `Tlas::intersect_stream` in
/// runs of that many (packets where their octants agree), else one by one.
fn rate(tlas: &Tlas, rays: &[WorldRay], mask: u8, stream: Option<usize>) -> (f64, f64, f64) {
    let (mut best_wall, mut best_cpu, mut hits) = (f64::INFINITY, f64::INFINITY, 0usize);
    let mut found = vec![None; stream.unwrap_or(0)];
    for _ in 0..3 {
        let (t, c) = (Instant::now(), throng::bench::thread_cpu_s());
        hits = match stream {
            None => rays.iter().filter(|r| tlas.intersect(r, mask).is_some()).count(),
            Some(n) => rays
                .chunks(n)
                .map(|run| {
                    let found = &mut found[..run.len()];
                    tlas.intersect_stream(run, mask, found);
                    found.iter().filter(|h| h.is_some()).count()
                })
                .sum(),
        };
        best_cpu = best_cpu.min(throng::bench::thread_cpu_s() - c);
        best_wall = best_wall.min(t.elapsed().as_secs_f64());
    }
    let n = rays.len() as f64;
    (n / best_wall, n / best_cpu, hits as f64 / n)
}

/// The peers' `embree_rays.py` primary and bounce sets, traced on one thread.
fn ray_rates(
    blas: &BlasSet,
    lib: &Library,
    scene: &FrameScene,
    (w, h): (u32, u32),
    tracing: &Tracing,
) -> serde_json::Value {
    let tlas = Tlas::build_with(blas, &scene.instances, tracing.tlas).with_traversal(tracing.traversal);
    let cam = CameraRays::new(&scene.camera, w, h);
    let primary: Vec<WorldRay> = (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .map(|(x, y)| {
            let (origin, direction) = cam.ray(x as f32 + 0.5, y as f32 + 0.5);
            WorldRay { origin, direction, tmax: f32::INFINITY, time: 0.0 }
        })
        .collect();
    let mut rng = Lcg(7);
    let bounce: Vec<WorldRay> = primary
        .iter()
        .filter_map(|r| {
            let hit = tlas.intersect(r, vis::CAMERA)?;
            let inst = scene.instances.get(hit.instance as usize)?;
            let mut n = hit_normal(lib, inst, hit.triangle)?.try_normalize()?;
            if n.dot(r.direction) > 0.0 {
                n = -n; // face the camera
            }
            let p = r.origin + r.direction * hit.t;
            let d = ShadingFrame::from_normal(n).to_world(sample_cosine_hemisphere(Vec2::new(rng.next(), rng.next())));
            Some(WorldRay { origin: offset_ray_origin(p, n), direction: d, tmax: f32::INFINITY, time: 0.0 })
        })
        .collect();
    // As packets: the rays in blocks of 8x4 pixels, each block one stream.
    let stream = tracing.camera_packets.then_some(32);
    let blocks: Vec<WorldRay> = match stream {
        None => primary.clone(),
        Some(_) => (0..h.div_ceil(4))
            .flat_map(|by| (0..w.div_ceil(8)).map(move |bx| (bx, by)))
            .flat_map(|(bx, by)| {
                let p = &primary;
                (by * 4..(by * 4 + 4).min(h))
                    .flat_map(move |y| (bx * 8..(bx * 8 + 8).min(w)).map(move |x| p[(y * w + x) as usize]))
            })
            .collect(),
    };
    let (pw, pc, ph) = rate(&tlas, &blocks, vis::CAMERA, stream);
    // The same rays in the same block order one by one: what the packets alone change.
    let (_, sc, _) = if stream.is_some() { rate(&tlas, &blocks, vis::CAMERA, None) } else { (0.0, pc, 0.0) };
    let (bw, bc, bh) = rate(&tlas, &bounce, vis::INDIRECT, None);
    // The same bounce rays through the other TLAS kind.
    let other = match tracing.tlas {
        TlasKind::Bvh2 => TlasKind::CwBvh,
        TlasKind::CwBvh => TlasKind::Bvh2,
    };
    let (_, oc, _) = rate(
        &Tlas::build_with(blas, &scene.instances, other).with_traversal(tracing.traversal),
        &bounce,
        vis::INDIRECT,
        None,
    );
    let m = |x: f64| (x / 1e4).round() / 100.0;
    serde_json::json!({
        "primary": {"rays": primary.len(), "packets": stream.is_some(), "single_same_order_mrays_per_cpu_s_1t": m(sc), "mrays_s_1t": m(pw), "mrays_per_cpu_s_1t": m(pc), "hit_fraction": (ph * 1e4).round() / 1e4},
        "bounce": {"rays": bounce.len(), "mrays_s_1t": m(bw), "mrays_per_cpu_s_1t": m(bc), "hit_fraction": (bh * 1e4).round() / 1e4,
                   "tlas": format!("{:?}", tracing.tlas), "other_tlas_mrays_per_cpu_s_1t": m(oc)},
    })
}

/// `THRONG_FLATTEN=1` (issue 25 item 3, measured): every instance's
/// triangles in world space, one mesh per material and visibility, so the
/// TLAS has a handful of entries and each ray walks one big tree, as
/// Mitsuba's `--geometry merged` does; `THRONG_FLATTEN=one` bakes them all
/// into one mesh (one BVH, as Embree's soup; the image then has one
/// material: for ray rates only). Drops UVs and tangents (the harness's
/// diffuse materials have no textures).
fn flatten(lib: &mut Library, scene: &mut FrameScene, one: bool) {
    let mut groups: std::collections::BTreeMap<(u32, u8), Mesh> = Default::default();
    for inst in &scene.instances {
        let src = &lib.meshes[inst.mesh as usize];
        let material = if one { 0 } else { inst.material };
        let m = groups.entry((material, inst.visibility)).or_insert_with(|| Mesh {
            name: format!("flat_{material}_{}", inst.visibility),
            positions: vec![],
            normals: vec![],
            uvs: vec![],
            tangents: vec![],
            indices: vec![],
        });
        let base = m.positions.len() as u32;
        let nm = glam::Mat3::from(inst.world_from_object.matrix3).inverse().transpose();
        m.positions.extend(src.positions.iter().map(|&p| inst.world_from_object.transform_point3(p)));
        if !src.normals.is_empty() {
            m.normals.extend(src.normals.iter().map(|&n| (nm * n).normalize_or_zero()));
        } else {
            m.normals.extend(std::iter::repeat_n(Vec3::ZERO, src.positions.len()));
        }
        m.indices.extend(src.indices.iter().map(|&i| i + base));
    }
    let first = scene.instances.first().copied();
    scene.instances.clear();
    for ((material, visibility), mut m) in groups {
        if m.normals.iter().all(|n| *n == Vec3::ZERO) {
            m.normals.clear();
        }
        let mesh = lib.meshes.len() as u32;
        lib.meshes.push(m);
        let mut inst = first.expect("a scene with instances");
        inst.mesh = mesh as _;
        inst.material = material;
        inst.visibility = visibility;
        inst.world_from_object = glam::Affine3A::IDENTITY;
        scene.instances.push(inst);
    }
    eprintln!("peer_bench: flattened into {} meshes", scene.instances.len());
}

fn main() {
    let args = match parse_args() {
        Ok(a) => a,
        Err(e) => {
            eprintln!("peer_bench: {e}");
            std::process::exit(2);
        }
    };
    // A/B switch for the BVH traversal in one binary (benchmarks only):
    // THRONG_TRAVERSAL=obvhs|scalar|avx2|wide (default wide: the CPU's widest).
    let traversal = match std::env::var("THRONG_TRAVERSAL").as_deref() {
        Ok("obvhs") => Traversal::Obvhs,
        Ok("scalar") => Traversal::Scalar,
        Ok("avx2") => Traversal::Avx2,
        Ok("wide") | Err(_) => Traversal::Wide,
        Ok(other) => {
            eprintln!("peer_bench: THRONG_TRAVERSAL={other}: expected obvhs, scalar, avx2 or wide");
            std::process::exit(2);
        }
    };
    // THRONG_PACKETS=0|1 (default 1): camera rays as packets or one by one,
    // in the render and in the primary ray rate.
    let packets = match std::env::var("THRONG_PACKETS").as_deref() {
        Ok("1") | Err(_) => true,
        Ok("0") => false,
        Ok(other) => {
            eprintln!("peer_bench: THRONG_PACKETS={other}: expected 0 or 1");
            std::process::exit(2);
        }
    };
    // Both choices go to the render through its settings, and to the ray rates.
    let tracing = Tracing { traversal, camera_packets: packets, ..Tracing::default() };
    let t_all = Instant::now();
    let cpu0 = throng::bench::process_cpu_s();
    let loaded = match (&args.scene, args.synthetic) {
        (Some(path), _) => match load_glb(path, &args) {
            Ok(l) => l,
            Err(e) => {
                eprintln!("peer_bench: {e}");
                std::process::exit(1);
            }
        },
        (None, Some(n)) => synthetic(n, &args),
        (None, None) => unreachable!("checked by parse_args"),
    };
    let Loaded { mut lib, mut scene, started: t0, load_s } = loaded;
    match std::env::var("THRONG_FLATTEN").as_deref() {
        Ok("1") => flatten(&mut lib, &mut scene, false),
        Ok("one") => flatten(&mut lib, &mut scene, true),
        Ok("0") | Err(_) => {}
        Ok(other) => {
            eprintln!("peer_bench: THRONG_FLATTEN={other}: expected 0, 1 or one");
            std::process::exit(2);
        }
    }
    if args.no_sun {
        scene.lights.sun = None;
        scene.lights.local.retain(|l| !matches!(l.kind, LightKind::Distant { .. }));
    }
    if let Some(direction) = args.sun_direction {
        // The scene's sun moved (a glTF directional light becomes the shot sun).
        let first = scene.lights.local.iter().find(|l| matches!(l.kind, LightKind::Distant { .. }));
        let irradiance = scene.lights.sun.as_ref().map(|s| s.irradiance).or(first.map(|l| l.emission));
        scene.lights.local.retain(|l| !matches!(l.kind, LightKind::Distant { .. }));
        scene.lights.sun = irradiance.map(|irradiance| Sun { direction, angular_diameter: 0.0, irradiance });
    }
    if let Some(degrees) = args.sun_angle {
        // A sun of a given size, to weigh a dome's soft sun against a lamp of its size.
        if let Some(sun) = &mut scene.lights.sun {
            sun.angular_diameter = degrees.to_radians();
        }
        for light in &mut scene.lights.local {
            if let LightKind::Distant { angular_diameter } = &mut light.kind {
                *angular_diameter = degrees.to_radians();
            }
        }
    }
    scene.lights.local.extend(lamps(&lib, &scene, args.point_lights));
    let load_cpu_s = throng::bench::process_cpu_s() - cpu0;
    let rss_load = throng::bench::peak_rss_mib();
    let threads = args.threads;
    let pool = match rayon::ThreadPoolBuilder::new().num_threads(threads).build() {
        Ok(p) => p,
        Err(e) => {
            eprintln!("peer_bench: cannot start {threads} threads: {e}");
            std::process::exit(1);
        }
    };
    let cpu = throng::bench::process_cpu_s();
    let blas = pool.install(|| BlasSet::build(&lib));
    let blas_cpu_s = throng::bench::process_cpu_s() - cpu;
    let blas_build_s = blas.build_time.as_secs_f64();
    let unique: usize = lib.meshes.iter().map(Mesh::triangle_count).sum();
    let instanced: usize =
        scene.instances.iter().filter_map(|i| lib.meshes.get(i.mesh as usize)).map(Mesh::triangle_count).sum();

    let settings = RenderSettings {
        width: args.res.0,
        height: args.res.1,
        spp: args.spp,
        max_bounces: args.bounces,
        seed: args.seed,
        sky_visible: true,
        threads,
        indirect_clamp: 0.0,
        diffuse_only: args.diffuse,
        adaptive: args.adaptive,
        tracing,
        atmosphere: args.atmosphere,
        ..Default::default()
    };
    let mut out = serde_json::json!({
        "tool": "throng peer_bench",
        "traversal": throng::render::wide::kernel_name(traversal),
        "scene": args.scene.as_ref().map(|p| p.display().to_string()),
        "synthetic_agents": args.synthetic,
        "res": [args.res.0, args.res.1], "spp": args.spp, "max_bounces": args.bounces, "threads": threads,
        "materials": if args.diffuse { "diffuse" } else { "gltf" },
        "instances": scene.instances.len(),
        "triangles": instanced,
        "unique_triangles": unique,
        "unique_meshes": lib.meshes.len(),
        "load_s": load_s,
        "load_cpu_s": load_cpu_s,
        "blas_build_s": blas_build_s,
        "blas_cpu_s": blas_cpu_s,
        "blas_mib": blas.bytes() as f64 / (1 << 20) as f64,
        "peak_rss_after_load_mib": rss_load,
    });
    if args.render {
        let first_tile = Mutex::new(None::<(f64, f64)>);
        let progress = |_: usize| {
            if let Ok(mut f) = first_tile.lock() {
                f.get_or_insert_with(|| (t0.elapsed().as_secs_f64(), throng::bench::process_cpu_s() - cpu0));
            }
        };
        let (t, cpu) = (Instant::now(), throng::bench::process_cpu_s());
        let (mut film, stats) = match render_frame_with_stats(&blas, &lib, &scene, &settings, Some(&progress)) {
            Ok(r) => r,
            Err(e) => {
                eprintln!("peer_bench: {e}");
                std::process::exit(1);
            }
        };
        let render_s = t.elapsed().as_secs_f64();
        out["render_cpu_s"] = (throng::bench::process_cpu_s() - cpu).into();
        let rss_render = throng::bench::peak_rss_mib();
        let rays = stats.rays;
        out["tlas_build_s"] = stats.tlas_build.as_secs_f64().into();
        let first = first_tile.lock().ok().and_then(|f| *f);
        out["first_sample_s"] = first.map(|f| f.0).into();
        out["first_sample_cpu_s"] = first.map(|f| f.1).into();
        out["render_s"] = render_s.into();
        if args.denoise {
            let t = Instant::now();
            let denoised = throng::render::denoise::Denoiser::open(None, args.threads)
                .and_then(|d| d.denoise(&mut film, throng::shot::Denoise::High));
            if let Err(e) = denoised {
                eprintln!("peer_bench: {e}");
                std::process::exit(1);
            }
            out["denoise_s"] = t.elapsed().as_secs_f64().into();
        }
        out["trace_s"] = stats.trace.as_secs_f64().into();
        out["rays"] = serde_json::json!({"camera": rays.camera, "bounce": rays.bounce, "shadow": rays.shadow});
        out["mrays_s_all_types"] =
            ((rays.camera + rays.bounce + rays.shadow) as f64 / stats.trace.as_secs_f64() / 1e6).into();
        out["peak_rss_mib"] = rss_render.into();
        let lum: f64 = film.rgba.iter().map(|p| (0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2]) as f64).sum::<f64>()
            / film.rgba.len() as f64;
        out["mean_luminance"] = lum.into();
        if !film.samples.is_empty() {
            let taken: u64 = film.samples.iter().map(|&n| u64::from(n)).sum();
            out["mean_spp"] = (taken as f64 / film.samples.len() as f64).into();
        }
        if let Some(prefix) = &args.out {
            let (near, far) = film.depth_range().unwrap_or((0.1, 1000.0));
            let (world_to_camera, world_to_ndc) =
                camera_matrices(&scene.camera, settings.width, settings.height, near, far);
            let meta = LayerMeta {
                shot: "peer_bench".into(),
                layer: "full".into(),
                frame: 0,
                seed: settings.seed,
                spp: settings.spp,
                id_mapping: ID_MAPPING.into(),
                world_to_camera,
                world_to_ndc,
                near,
                far,
                fps: 24.0,
                render_fingerprint: String::new(),
                denoiser: String::new(),
                shutter: None,
                colourspace: Default::default(),
            };
            let exr = prefix.with_extension("exr");
            let png = prefix.with_extension("png");
            for r in [write_layer(&exr, &film, &meta), write_preview_png(&png, &film)] {
                if let Err(e) = r {
                    eprintln!("peer_bench: {e}");
                    std::process::exit(1);
                }
            }
            out["exr"] = exr.display().to_string().into();
        }
    } else {
        // Memory-only run: build the TLAS as a render would, then drop it.
        let cpu = throng::bench::process_cpu_s();
        let tlas = pool.install(|| Tlas::build_with(&blas, &scene.instances, tracing.tlas));
        out["tlas_cpu_s"] = (throng::bench::process_cpu_s() - cpu).into();
        out["tlas_build_s"] = tlas.build_time.as_secs_f64().into();
        // Everything a render does before its first sample (plus the integrator's per-instance normal matrices, not built here).
        out["first_sample_s"] = t0.elapsed().as_secs_f64().into();
        out["first_sample_cpu_s"] = (throng::bench::process_cpu_s() - cpu0).into();
        out["peak_rss_mib"] = throng::bench::peak_rss_mib().into();
        drop(tlas);
    }
    if args.rays {
        out["rays_1t"] = ray_rates(&blas, &lib, &scene, args.res, &tracing);
    }
    out["total_s"] = t_all.elapsed().as_secs_f64().into();
    out["total_cpu_s"] = (throng::bench::process_cpu_s() - cpu0).into();
    out["loadavg_end"] = std::fs::read_to_string("/proc/loadavg").unwrap_or_default().trim().into();
    out["peak_rss_end_mib"] = throng::bench::peak_rss_mib().into();
    println!("{out}");
}
