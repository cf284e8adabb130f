//! Renderer benchmark on a synthetic crowd: N agents x 11 parts (boxes and
//! spheres sharing a few meshes) over a ground plane, N = 100, 1000, 10000.
//! Reports BLAS build, TLAS build (Bvh2 vs CwBvh), single-thread incoherent
//! bounce and shadow ray rates, a small multi-threaded frame, and peak RSS.
//!
//! Run: `cargo run --example render_bench [-- --out DIR]` (DIR gets PNG previews).

use std::f32::consts::PI;

use glam::{Affine3A, Quat, Vec3};
use throng::render::accel::{BlasSet, Tlas, TlasKind, WorldRay};
use throng::render::exr::write_preview_png;
use throng::render::film::render_frame_with_stats;
use throng::render::RenderSettings;
use throng::scene::{
    lights::SceneLights, vis, Camera, FrameScene, Instance, InstanceAgent, Library, Material, Mesh, Sky, Sun,
};

struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f32 {
        self.0 = self.0.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (self.0 >> 40) as f32 / (1u64 << 24) as f32
    }
}

fn ground(size: f32) -> Mesh {
    let h = size / 2.0;
    Mesh {
        name: "ground".into(),
        positions: vec![Vec3::new(-h, 0.0, -h), Vec3::new(h, 0.0, -h), Vec3::new(h, 0.0, h), Vec3::new(-h, 0.0, h)],
        normals: vec![Vec3::Y; 4],
        uvs: vec![],
        tangents: vec![],
        indices: vec![0, 2, 1, 0, 3, 2],
    }
}

fn library() -> Library {
    let m = |name: &str, c: [f32; 3], metallic, roughness| Material {
        name: name.into(),
        base_color: Vec3::from(c),
        base_color_texture: None,
        roughness,
        metallic,
        ..Default::default()
    };
    Library {
        // Ground, a box part, a 2k-triangle head sphere, a 500-triangle limb sphere.
        meshes: vec![
            ground(200.0),
            Mesh::cube("cube"),
            Mesh::uv_sphere(&format!("sphere{}", 32), 0.5, 32, 32),
            Mesh::uv_sphere(&format!("sphere{}", 16), 0.5, 16, 16),
        ],
        materials: vec![
            m("ground", [0.5, 0.5, 0.5], 0.0, 0.2),
            m("chrome", [0.8, 0.8, 0.85], 1.0, 0.25),
            m("rust", [0.5, 0.2, 0.1], 0.3, 0.7),
            m("paint", [0.1, 0.3, 0.7], 0.0, 0.4),
        ],
        textures: vec![],
    }
}

/// N agents x 11 parts in a square around the demo crowd area.
fn crowd(n: usize) -> Vec<Instance> {
    let mut rng = Lcg(n as u64);
    let mut out = vec![Instance {
        mesh: 0,
        material: 0,
        world_from_object: Affine3A::IDENTITY,
        agent: InstanceAgent::NONE,
        part: 0,
        visibility: vis::ALL,
    }];
    // Density like the demo: ~1 agent per 2 m^2.
    let side = (n as f32 * 2.0).sqrt();
    // (mesh, centre, size) of each slot in the agent's space.
    let slots: [(u32, [f32; 3], [f32; 3]); 11] = [
        (2, [0.0, 1.6, 0.0], [0.25, 0.28, 0.25]),
        (1, [0.0, 1.2, 0.0], [0.4, 0.5, 0.22]),
        (1, [0.0, 0.9, 0.0], [0.35, 0.15, 0.2]),
        (3, [-0.27, 1.25, 0.0], [0.1, 0.3, 0.1]),
        (3, [-0.27, 0.95, 0.0], [0.09, 0.3, 0.09]),
        (3, [0.27, 1.25, 0.0], [0.1, 0.3, 0.1]),
        (3, [0.27, 0.95, 0.0], [0.09, 0.3, 0.09]),
        (1, [-0.1, 0.62, 0.0], [0.13, 0.4, 0.13]),
        (1, [-0.1, 0.22, 0.0], [0.11, 0.42, 0.11]),
        (1, [0.1, 0.62, 0.0], [0.13, 0.4, 0.13]),
        (1, [0.1, 0.22, 0.0], [0.11, 0.42, 0.11]),
    ];
    for a in 0..n {
        let pos = Vec3::new((rng.next() - 0.5) * side, 0.0, -(rng.next()) * side + 12.0);
        let agent_from_world = Affine3A::from_rotation_translation(Quat::from_rotation_y(rng.next() * 2.0 * PI), pos);
        for (k, (mesh, c, s)) in slots.iter().enumerate() {
            out.push(Instance {
                mesh: *mesh,
                material: 1 + ((a + k) % 3) as u32,
                world_from_object: agent_from_world
                    * Affine3A::from_scale_rotation_translation(Vec3::from(*s), Quat::IDENTITY, Vec3::from(*c)),
                agent: InstanceAgent::some(a as u32),
                part: k as u16,
                visibility: vis::ALL,
            });
        }
    }
    out
}

/// Rays per second of incoherent "bounce" rays (closest hit) and shadow rays
/// (any hit) on one thread: origins inside the crowd's box, random directions.
fn ray_rates(tlas: &Tlas, n_rays: usize) -> (f64, f64, f64) {
    let (lo, hi) = tlas.bounds().unwrap_or((Vec3::ZERO, Vec3::ONE));
    let (lo, hi) = (lo.max(Vec3::new(-60.0, 0.0, -200.0)), hi.min(Vec3::new(60.0, 2.0, 200.0)));
    let mut rng = Lcg(99);
    let rays: Vec<WorldRay> = (0..n_rays)
        .map(|_| {
            let origin = lo + (hi - lo) * Vec3::new(rng.next(), rng.next(), rng.next());
            let z = rng.next() * 2.0 - 1.0;
            let phi = 2.0 * PI * rng.next();
            let r = (1.0 - z * z).sqrt();
            WorldRay { origin, direction: Vec3::new(r * phi.cos(), z, r * phi.sin()), tmax: f32::INFINITY, time: 0.0 }
        })
        .collect();
    let start = throng::bench::thread_cpu_s();
    let mut hits = 0usize;
    for r in &rays {
        hits += tlas.intersect(r, vis::INDIRECT).is_some() as usize;
    }
    let bounce = n_rays as f64 / (throng::bench::thread_cpu_s() - start);
    let sun = Vec3::new(-0.4, 0.6, 0.5).normalize();
    let start = throng::bench::thread_cpu_s();
    let mut blocked = 0usize;
    for r in &rays {
        blocked += tlas.occluded(&WorldRay { direction: sun, ..*r }, vis::SHADOW) as usize;
    }
    let shadow = n_rays as f64 / (throng::bench::thread_cpu_s() - start);
    let _ = blocked;
    (bounce, shadow, hits as f64 / n_rays as f64)
}

fn main() {
    let out_dir = std::env::args().skip_while(|a| a != "--out").nth(1).map(std::path::PathBuf::from);
    let lib = library();
    // Build the BLASes once, as a render run does (on a 1-thread pool to report single-core cost too).
    let one = rayon::ThreadPoolBuilder::new().num_threads(1).build().expect("thread pool");
    let blas = one.install(|| BlasSet::build(&lib));
    let tris: usize = lib.meshes.iter().map(Mesh::triangle_count).sum();
    println!(
        "BLAS: {} meshes, {} triangles, {:.1} ms build (1 thread, wall), {:.1} KiB",
        blas.len(),
        tris,
        blas.build_time.as_secs_f64() * 1e3,
        blas.bytes() as f64 / 1024.0
    );
    println!(
        "{:>6} {:>8} | {:>9} {:>9} | {:>12} {:>12} {:>12} {:>12} | {:>10} {:>8} {:>9}",
        "agents",
        "insts",
        "Bvh2 ms",
        "CwBvh ms",
        "Bvh2 bnc/s",
        "CwBvh bnc/s",
        "Bvh2 shd/s",
        "CwBvh shd/s",
        "frame ms",
        "Mray/cpu-s",
        "RSS MB"
    );
    for n in [100usize, 1000, 10000] {
        let instances = crowd(n);
        // TLAS builds (single-threaded builder): best wall time of 3, to dodge other load.
        let build = |kind| {
            one.install(|| {
                let mut best = (f64::INFINITY, None);
                for _ in 0..3 {
                    let t = Tlas::build_with(&blas, &instances, kind);
                    best = (best.0.min(t.build_time.as_secs_f64()), Some(t));
                }
                (best.1.expect("built"), best.0)
            })
        };
        let ((tlas2, t2), (tlas8, t8)) = (build(TlasKind::Bvh2), build(TlasKind::CwBvh));
        let rays = if n >= 10000 { 300_000 } else { 1_000_000 };
        let (b2, s2, _) = one.install(|| ray_rates(&tlas2, rays));
        let (b8, s8, _) = one.install(|| ray_rates(&tlas8, rays));

        // A small frame on all cores through the public entry point.
        let scene = FrameScene {
            instances: instances.clone(),
            camera: Camera {
                world_from_camera: Affine3A::from_rotation_translation(
                    Quat::from_rotation_x(-0.05),
                    Vec3::new(0.0, 1.7, 24.0),
                ),
                yfov: 0.6,
                aperture: 0.0,
                focus_distance: 1.0,
            },
            lights: SceneLights::sun_and_sky(
                Some(Sun {
                    direction: Vec3::new(-0.4, 0.6, 0.5).normalize(),
                    angular_diameter: 0.0093,
                    irradiance: Vec3::new(3.0, 2.85, 2.64),
                }),
                Sky { radiance: Vec3::new(0.3, 0.38, 0.5) },
            ),
            motion: None,
        };
        let settings = RenderSettings {
            width: 320,
            height: 180,
            spp: 4,
            max_bounces: 4,
            seed: 1,
            frame: 1001,
            sky_visible: true,
            indirect_clamp: 10.0,
            ..Default::default()
        };
        let cpu = throng::bench::process_cpu_s();
        let (film, stats) = render_frame_with_stats(&blas, &lib, &scene, &settings, None).expect("render");
        let cpu = throng::bench::process_cpu_s() - cpu;
        let total_rays = stats.rays.camera + stats.rays.bounce + stats.rays.shadow;
        println!(
            "{:>6} {:>8} | {:>9.2} {:>9.2} | {:>12.3e} {:>12.3e} {:>12.3e} {:>12.3e} | {:>10.1} {:>8.2} {:>9.1}",
            n,
            tlas2.len(),
            t2 * 1e3,
            t8 * 1e3,
            b2,
            b8,
            s2,
            s8,
            stats.trace.as_secs_f64() * 1e3,
            total_rays as f64 / cpu / 1e6,
            throng::bench::peak_rss_mib()
        );
        if let Some(dir) = &out_dir {
            let path = dir.join(format!("render_bench_{n}.png"));
            if let Err(e) = write_preview_png(&path, &film) {
                eprintln!("{e}");
            }
        }
    }
    println!("(TLAS ms: build, best wall time of 3; bnc/s, shd/s: single-thread incoherent closest-hit and shadow rays per CPU second;\n frame: 320x180, 4 spp, all cores, wall time; Mray/cpu-s: all ray types (camera, bounce, shadow) with shading, per process CPU second)");
}
