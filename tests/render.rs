//! Renderer core tests: acceleration structure vs brute force, furnace,
//! determinism across thread counts, visibility semantics, self-intersection
//! far from the origin, and the EXR round trip. Images are tiny so this runs
//! in seconds in the dev profile.

mod common;

use std::f32::consts::PI;

use glam::{Affine3A, Quat, Vec2, Vec3};
use throng::render::accel::{BlasSet, Tlas, TlasKind, WorldRay};
use throng::render::bsdf::Bsdf;
use throng::render::exr::{camera_matrices, read_layer, write_layer, write_preview_png, LayerMeta, ID_MAPPING};
use throng::render::film::{render_frame, Film};
use throng::render::RenderSettings;
use throng::scene::{
    lights::SceneLights, vis, Camera, FrameScene, Instance, InstanceAgent, Library, Material, Mesh, Sky, Sun,
};

// ---------------------------------------------------------------- fixtures

/// Tiny deterministic generator for test data.
struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f32 {
        self.0 = self.0.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (self.0 >> 40) as f32 / (1u64 << 24) as f32
    }
    fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.next()
    }
    fn vec3(&mut self, lo: f32, hi: f32) -> Vec3 {
        Vec3::new(self.range(lo, hi), self.range(lo, hi), self.range(lo, hi))
    }
}

/// A square in the y = 0 plane, `size` on a side, centred on `centre`.
fn quad(size: f32, centre: Vec3) -> Mesh {
    let h = size / 2.0;
    let positions = [(-h, -h), (h, -h), (h, h), (-h, h)].map(|(x, z)| centre + Vec3::new(x, 0.0, z)).to_vec();
    Mesh {
        name: "quad".into(),
        normals: vec![Vec3::Y; 4],
        uvs: vec![Vec2::new(0.0, 0.0), Vec2::new(1.0, 0.0), Vec2::new(1.0, 1.0), Vec2::new(0.0, 1.0)],
        tangents: vec![],
        positions,
        indices: vec![0, 2, 1, 0, 3, 2],
    }
}

fn material(name: &str, base: Vec3, metallic: f32, roughness: f32) -> Material {
    Material {
        name: name.into(),
        base_color: base,
        base_color_texture: None,
        roughness,
        metallic,
        ..Default::default()
    }
}

fn instance(mesh: u32, material: u32, world_from_object: Affine3A, agent: Option<u32>, visibility: u8) -> Instance {
    let agent = agent.map_or(InstanceAgent::NONE, InstanceAgent::some);
    Instance { mesh, material, world_from_object, agent, part: 0, visibility }
}

fn camera(eye: Vec3, target: Vec3, yfov_deg: f32) -> Camera {
    // Columns: right, up, back (the camera looks down its -Z), position.
    let forward = (target - eye).normalize();
    let right = forward.cross(Vec3::Y).normalize();
    let up = right.cross(forward);
    let world_from_camera = Affine3A::from_cols(right.into(), up.into(), (-forward).into(), eye.into());
    Camera::pinhole(world_from_camera, yfov_deg.to_radians())
}

fn settings(width: u32, height: u32, spp: u32) -> RenderSettings {
    RenderSettings {
        width,
        height,
        spp,
        max_bounces: 3,
        seed: 1234,
        frame: 1001,
        sky_visible: false,
        threads: 2,
        indirect_clamp: 10.0,
        ..Default::default()
    }
}

fn luminance(p: [f32; 4]) -> f32 {
    0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2]
}

// ------------------------------------------------------------ accel tests

/// Möller-Trumbore on world-space triangles: (t, u, v).
fn brute_triangle(o: Vec3, d: Vec3, a: Vec3, b: Vec3, c: Vec3) -> Option<(f32, f32, f32)> {
    let (e1, e2) = (b - a, c - a);
    let p = d.cross(e2);
    let det = e1.dot(p);
    if det.abs() < 1e-12 {
        return None;
    }
    let s = o - a;
    let u = s.dot(p) / det;
    let q = s.cross(e1);
    let v = d.dot(q) / det;
    let t = e2.dot(q) / det;
    (u >= 0.0 && v >= 0.0 && u + v <= 1.0 && t > 0.0).then_some((t, u, v))
}

#[test]
fn accel_matches_brute_force() {
    let mut rng = Lcg(42);
    let mut lib = Library::default();
    // A random triangle soup, a sphere, a cube, and an empty mesh.
    let mut soup = Mesh { name: "soup".into(), ..Default::default() };
    for i in 0..60u32 {
        let c = rng.vec3(-1.0, 1.0);
        for _ in 0..3 {
            soup.positions.push(c + rng.vec3(-0.4, 0.4));
        }
        soup.indices.extend_from_slice(&[3 * i, 3 * i + 1, 3 * i + 2]);
    }
    lib.meshes = vec![soup, Mesh::uv_sphere("sphere", 1.0, 8, 12), Mesh::cube("cube"), Mesh::default()];
    lib.materials = vec![Material::default()];
    let blas = BlasSet::build(&lib);
    blas.validate();

    let mut instances = Vec::new();
    for i in 0..40u32 {
        let rot = Quat::from_axis_angle(rng.vec3(-1.0, 1.0).normalize(), rng.range(0.0, 6.0));
        let scale = Vec3::new(rng.range(0.3, 2.0), rng.range(0.3, 2.0), rng.range(0.3, 2.0));
        let m = Affine3A::from_scale_rotation_translation(scale, rot, rng.vec3(-8.0, 8.0));
        let visibility =
            [vis::ALL, vis::CAMERA, vis::SHADOW, vis::INDIRECT | vis::SHADOW, vis::HOLDOUT][i as usize % 5];
        // Three parts per agent, so agent leaves hold several instances.
        instances.push(instance(i % 4, 0, m, Some(i / 3), visibility));
    }

    // Per-part leaves (both tree kinds) and per-agent leaves (what scenes of
    // millions of parts use) must find the same hits.
    for (kind, by_agent) in [(TlasKind::Bvh2, false), (TlasKind::CwBvh, false), (TlasKind::CwBvh, true)] {
        let tlas = Tlas::build_clustered(&blas, &instances, kind, by_agent);
        tlas.validate();
        assert_eq!(tlas.len(), 30, "empty-mesh instances are skipped");
        // Agents 0..=12 keep a part with a mesh (agent 13 has only instance 39, on the empty mesh).
        assert_eq!(tlas.leaves(), if by_agent { 13 } else { 30 });
        let mut rng = Lcg(7);
        let (mut hits, mut occluded) = (0, 0);
        for r in 0..3000 {
            let origin = rng.vec3(-12.0, 12.0);
            let target = rng.vec3(-6.0, 6.0);
            let direction = (target - origin) * rng.range(0.2, 3.0); // not normalised on purpose
            let mask = [vis::CAMERA | vis::HOLDOUT, vis::SHADOW, vis::INDIRECT][r % 3];
            let tmax = if r % 4 == 0 { rng.range(0.1, 1.0) } else { f32::INFINITY };
            // Brute force over every instance and triangle in world space.
            let mut best: Option<(f32, u32, u32)> = None;
            for (ii, inst) in instances.iter().enumerate() {
                if inst.visibility & mask == 0 {
                    continue;
                }
                let mesh = &lib.meshes[inst.mesh as usize];
                for (ti, idx) in mesh.indices.chunks_exact(3).enumerate() {
                    let [a, b, c] =
                        [0, 1, 2].map(|k| inst.world_from_object.transform_point3(mesh.positions[idx[k] as usize]));
                    if let Some((t, _, _)) = brute_triangle(origin, direction, a, b, c) {
                        if t <= tmax && best.is_none_or(|(bt, _, _)| t < bt) {
                            best = Some((t, ii as u32, ti as u32));
                        }
                    }
                }
            }
            let ray = WorldRay { origin, direction, tmax, time: 0.0 };
            let got = tlas.intersect(&ray, mask);
            match (best, got) {
                (None, None) => {}
                (Some((t, ii, ti)), Some(h)) => {
                    hits += 1;
                    assert!((h.t - t).abs() <= 1e-3 * t.max(1.0), "ray {r}: t {} vs brute {t}", h.t);
                    if (h.instance, h.triangle) != (ii, ti) {
                        // Only acceptable as a near tie (shared edges, coplanar faces).
                        assert!(
                            (h.t - t).abs() <= 1e-4 * t.max(1.0),
                            "ray {r}: hit ({}, {}) vs ({ii}, {ti})",
                            h.instance,
                            h.triangle
                        );
                    }
                    // Barycentrics rebuild the hit point.
                    let inst = &instances[h.instance as usize];
                    let mesh = &lib.meshes[inst.mesh as usize];
                    let idx = &mesh.indices[h.triangle as usize * 3..][..3];
                    let [a, b, c] =
                        [0, 1, 2].map(|k| inst.world_from_object.transform_point3(mesh.positions[idx[k] as usize]));
                    let p = a * (1.0 - h.u - h.v) + b * h.u + c * h.v;
                    let q = origin + direction * h.t;
                    assert!((p - q).length() <= 1e-3 * q.length().max(1.0), "ray {r}: barycentric point {p} vs {q}");
                }
                (b, g) => {
                    // Grazing edge hits may differ between the two tests; accept only at an edge.
                    panic!("ray {r}: brute {b:?} vs accel {g:?}");
                }
            }
            let occ = tlas.occluded(&ray, mask);
            assert_eq!(occ, best.is_some(), "ray {r}: occlusion");
            occluded += occ as u32;
        }
        assert!(hits > 300 && occluded > 300, "the fixture should be hit often: {hits}");
    }
}

// ---------------------------------------------------------- render tests

/// Expected radiance of a surface under a uniform white sky: the directional
/// albedo of the BSDF, integrated with a uniform hemisphere grid (independent
/// of the BSDF's own importance sampling).
fn directional_albedo(bsdf: &Bsdf, cos_o: f32) -> f32 {
    let wo = Vec3::new((1.0 - cos_o * cos_o).max(0.0).sqrt(), 0.0, cos_o);
    let n = 64;
    let mut sum = 0.0;
    for i in 0..n {
        for j in 0..n {
            let z = (i as f32 + 0.5) / n as f32;
            let phi = 2.0 * PI * (j as f32 + 0.5) / n as f32;
            let r = (1.0 - z * z).sqrt();
            let wi = Vec3::new(r * phi.cos(), r * phi.sin(), z);
            sum += bsdf.eval(wo, wi).x * z * 2.0 * PI;
        }
    }
    sum / (n * n) as f32
}

#[test]
fn furnace_convex_sphere_under_uniform_sky() {
    let albedo = 0.5;
    let lib = Library {
        meshes: vec![Mesh::uv_sphere("sphere", 1.0, 48, 96)],
        materials: vec![material("grey", Vec3::splat(albedo), 0.0, 1.0)],
        textures: vec![],
    };
    let blas = BlasSet::build(&lib);
    let eye = Vec3::new(0.0, 0.0, 4.0);
    let scene = FrameScene {
        instances: vec![instance(0, 0, Affine3A::IDENTITY, None, vis::ALL)],
        camera: camera(eye, Vec3::ZERO, 40.0),
        lights: SceneLights::sun_and_sky(None, Sky { radiance: Vec3::ONE }),
        motion: None,
    };
    let s = RenderSettings { sky_visible: true, ..settings(48, 36, 64) };
    let film = render_frame(&blas, &lib, &scene, &s, None).unwrap();
    let bsdf = Bsdf::new(Vec3::splat(albedo), 0.0, 1.0);
    let (mut sum, mut expected, mut count) = (0.0f64, 0.0f64, 0);
    for i in 0..film.rgba.len() {
        if film.albedo[i] == [0.0; 3] {
            // Every sample missed: pure sky, exactly 1 with alpha 1.
            assert_eq!(film.rgba[i], [1.0; 4], "sky pixel {i}");
        } else if film.albedo[i] == [albedo; 3] {
            // Every sample hit the sphere: radiance = directional albedo.
            let (x, y) = ((i % 48) as f32 + 0.5, (i / 48) as f32 + 0.5);
            let t = (20f32).to_radians().tan();
            let d = Vec3::new((2.0 * x / 48.0 - 1.0) * t * 48.0 / 36.0, (1.0 - 2.0 * y / 36.0) * t, -1.0).normalize();
            let cos_o = Vec3::from(film.normal[i]).normalize().dot(-d).clamp(0.0, 1.0);
            sum += film.rgba[i][0] as f64;
            expected += directional_albedo(&bsdf, cos_o) as f64;
            count += 1;
            assert_eq!(film.rgba[i][3], 1.0);
        }
    }
    assert!(count > 200, "sphere covers too few pixels: {count}");
    let (mean, expected) = (sum / count as f64, expected / count as f64);
    assert!((mean - expected).abs() < 0.01, "furnace: mean {mean} vs expected {expected}");
    // And the BSDF is close to the diffuse albedo (Fresnel moves energy around a little).
    assert!((mean - albedo as f64).abs() < 0.08, "furnace: mean {mean} vs albedo {albedo}");
}

/// Floor, a few boxes, a sphere and a sun: the common fixture.
fn small_set() -> (Library, FrameScene) {
    let lib = Library {
        meshes: vec![quad(20.0, Vec3::ZERO), Mesh::cube("cube"), Mesh::uv_sphere("sphere", 1.0, 16, 24)],
        materials: vec![
            material("floor", Vec3::splat(0.6), 0.0, 0.6),
            material("red", Vec3::new(0.8, 0.1, 0.1), 0.0, 0.4),
            material("chrome", Vec3::splat(0.9), 1.0, 0.2),
        ],
        textures: vec![],
    };
    let mut instances = vec![instance(0, 0, Affine3A::IDENTITY, None, vis::ALL)];
    for k in 0..5 {
        let m = Affine3A::from_scale_rotation_translation(
            Vec3::new(0.6, 1.8, 0.4),
            Quat::from_rotation_y(k as f32),
            Vec3::new(-3.0 + 1.5 * k as f32, 0.9, -1.0 - 0.5 * k as f32),
        );
        instances.push(instance(1 + (k % 2), 1 + (k % 2), m, Some(10 + k), vis::ALL));
    }
    let scene = FrameScene {
        instances,
        camera: camera(Vec3::new(0.0, 2.0, 6.0), Vec3::new(0.0, 0.5, -1.0), 50.0),
        lights: SceneLights::sun_and_sky(
            Some(Sun {
                direction: Vec3::new(-0.4, 0.6, 0.5).normalize(),
                angular_diameter: 0.0093,
                irradiance: Vec3::splat(3.0),
            }),
            Sky { radiance: Vec3::new(0.3, 0.38, 0.5) },
        ),
        motion: None,
    };
    (lib, scene)
}

#[test]
fn bit_identical_for_any_thread_count() {
    let (lib, scene) = small_set();
    let blas = BlasSet::build(&lib);
    let s1 = RenderSettings { threads: 1, ..settings(40, 30, 4) };
    let s2 = RenderSettings { threads: 2, ..s1.clone() };
    let s3 = RenderSettings { threads: 3, ..s1.clone() };
    let a = render_frame(&blas, &lib, &scene, &s1, None).unwrap();
    let b = render_frame(&blas, &lib, &scene, &s2, None).unwrap();
    let c = render_frame(&blas, &lib, &scene, &s3, None).unwrap();
    let bits = |f: &Film| f.rgba.iter().flatten().map(|v| v.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&a), bits(&b));
    assert_eq!(bits(&a), bits(&c));
    assert_eq!(a, b);
    // And the seed / frame matter.
    let d = render_frame(&blas, &lib, &scene, &RenderSettings { frame: 1002, ..s1.clone() }, None).unwrap();
    assert_ne!(bits(&a), bits(&d));
    // Agent ids appear exactly (id + 1), never blended.
    assert!(a.agent_id.iter().all(|&id| id == 0 || (11..=15).contains(&id)));
    assert!(a.agent_id.iter().any(|&id| id != 0));
}

#[test]
fn holdout_gives_alpha_zero() {
    let (lib, mut scene) = small_set();
    let blas = BlasSet::build(&lib);
    // The floor becomes a holdout; box 0 stays an agent.
    scene.instances[0].visibility = vis::HOLDOUT | vis::SHADOW | vis::INDIRECT;
    let film = render_frame(&blas, &lib, &scene, &settings(40, 30, 4), None).unwrap();
    let (mut holdout, mut agent) = (0, 0);
    for i in 0..film.rgba.len() {
        if film.agent_id[i] == 0 {
            // Floor (holdout) or background: nothing, in colour or alpha, wherever all samples agree.
            if film.normal[i] == [0.0; 3] {
                assert_eq!(film.rgba[i], [0.0; 4], "pixel {i}");
                holdout += 1;
            }
        } else if Vec3::from(film.normal[i]).length() > 0.999 {
            assert_eq!(film.rgba[i][3], 1.0);
            agent += 1;
        }
    }
    assert!(holdout > 500 && agent > 10, "{holdout} {agent}");
    // A holdout in front of an agent hides it.
    let mut wall = scene.clone();
    wall.instances.push(instance(
        0,
        0,
        Affine3A::from_rotation_translation(Quat::from_rotation_x(PI / 2.0), Vec3::new(0.0, 0.0, 3.0)),
        None,
        vis::HOLDOUT,
    ));
    let film = render_frame(&blas, &lib, &wall, &settings(40, 30, 2), None).unwrap();
    assert!(film.rgba.iter().all(|p| p[3] == 0.0) && film.agent_id.iter().all(|&id| id == 0));
}

#[test]
fn shadow_only_instance_is_invisible_but_casts_a_shadow() {
    let lib = Library {
        meshes: vec![quad(20.0, Vec3::ZERO), Mesh::cube("cube")],
        materials: vec![material("floor", Vec3::splat(0.6), 0.0, 0.8), material("box", Vec3::splat(0.6), 0.0, 0.8)],
        textures: vec![],
    };
    let blas = BlasSet::build(&lib);
    let floor = instance(0, 0, Affine3A::IDENTITY, None, vis::ALL);
    let blocker = instance(
        1,
        1,
        Affine3A::from_scale_rotation_translation(Vec3::splat(1.5), Quat::IDENTITY, Vec3::new(0.0, 1.5, 0.0)),
        Some(5),
        vis::SHADOW,
    );
    let scene = |instances| FrameScene {
        instances,
        camera: camera(Vec3::new(0.0, 6.0, 6.0), Vec3::ZERO, 50.0),
        lights: SceneLights::sun_and_sky(
            Some(Sun { direction: Vec3::Y, angular_diameter: 0.0093, irradiance: Vec3::splat(3.0) }),
            Sky { radiance: Vec3::splat(0.1) },
        ),
        motion: None,
    };
    let s = settings(40, 30, 4);
    let with = render_frame(&blas, &lib, &scene(vec![floor, blocker]), &s, None).unwrap();
    let without = render_frame(&blas, &lib, &scene(vec![floor]), &s, None).unwrap();
    // Never seen by the camera: no id, and every pixel still shows the floor.
    assert!(with.agent_id.iter().all(|&id| id == 0));
    assert_eq!(with.z, without.z);
    // The centre of the image looks at the floor under the box: in shadow.
    let centre = with.index(20, 15);
    assert!(
        luminance(with.rgba[centre]) < 0.3 * luminance(without.rgba[centre]),
        "{:?} vs {:?}",
        with.rgba[centre],
        without.rgba[centre]
    );
    // Far from the box nothing changes much (sky occlusion only).
    let corner = with.index(2, 28);
    assert!(luminance(with.rgba[corner]) > 0.9 * luminance(without.rgba[corner]));
}

#[test]
fn glossy_floor_reflects_indirect_only_object() {
    let lib = Library {
        meshes: vec![quad(40.0, Vec3::ZERO), Mesh::cube("cube")],
        materials: vec![
            material("mirror", Vec3::splat(0.9), 1.0, 0.05),
            material("red", Vec3::new(0.9, 0.02, 0.02), 0.0, 0.8),
        ],
        textures: vec![],
    };
    let blas = BlasSet::build(&lib);
    let floor = instance(0, 0, Affine3A::IDENTITY, None, vis::ALL);
    let red = instance(
        1,
        1,
        Affine3A::from_scale_rotation_translation(Vec3::splat(2.0), Quat::IDENTITY, Vec3::new(0.0, 1.0, -4.0)),
        Some(3),
        vis::INDIRECT,
    );
    let scene = |instances| FrameScene {
        instances,
        camera: camera(Vec3::new(0.0, 1.0, 6.0), Vec3::new(0.0, -0.5, -4.0), 50.0),
        lights: SceneLights::sun_and_sky(
            Some(Sun {
                direction: Vec3::new(0.0, 0.7, 0.7).normalize(),
                angular_diameter: 0.0093,
                irradiance: Vec3::splat(3.0),
            }),
            Sky { radiance: Vec3::splat(0.2) },
        ),
        motion: None,
    };
    let s = settings(40, 30, 8);
    let with = render_frame(&blas, &lib, &scene(vec![floor, red]), &s, None).unwrap();
    let without = render_frame(&blas, &lib, &scene(vec![floor]), &s, None).unwrap();
    let reddish = |f: &Film| f.rgba.iter().filter(|p| p[0] > 2.0 * p[1] + 0.05).count();
    assert_eq!(reddish(&without), 0);
    assert!(reddish(&with) > 10, "reflection of the red box: {} reddish pixels", reddish(&with));
    // Not seen directly: no id, and above the horizon there is no coverage.
    assert!(with.agent_id.iter().all(|&id| id == 0));
    assert_eq!(with.z, without.z);
}

#[test]
fn no_shadow_acne_far_from_origin() {
    // The same slightly tilted floor twice (tilted so rounding is not trivially exact):
    // baked at 500 m, and built at the origin and moved 500 m by its instance.
    let far = Vec3::new(500.0, 0.0, -500.0);
    let tilt = Quat::from_axis_angle(Vec3::new(1.0, 0.0, 1.0).normalize(), 0.1);
    let mut baked = quad(30.0, Vec3::ZERO);
    baked.positions.iter_mut().for_each(|p| *p = far + tilt * *p);
    let lib = Library {
        meshes: vec![baked, quad(30.0, Vec3::ZERO)],
        materials: vec![material("floor", Vec3::splat(0.5), 0.0, 1.0)],
        textures: vec![],
    };
    let blas = BlasSet::build(&lib);
    let moved = Affine3A::from_rotation_translation(tilt, far);
    for inst in [instance(0, 0, Affine3A::IDENTITY, None, vis::ALL), instance(1, 0, moved, None, vis::ALL)] {
        let scene = FrameScene {
            instances: vec![inst],
            camera: camera(far + Vec3::new(0.0, 4.0, 8.0), far, 40.0),
            lights: SceneLights::sun_and_sky(
                Some(Sun {
                    direction: Vec3::new(0.3, 0.5, 0.2).normalize(),
                    angular_diameter: 0.0093,
                    irradiance: Vec3::splat(3.0),
                }),
                Sky { radiance: Vec3::ZERO },
            ),
            motion: None,
        };
        let film = render_frame(&blas, &lib, &scene, &settings(48, 32, 4), None).unwrap();
        let lum: Vec<f32> = film.rgba.iter().filter(|p| p[3] == 1.0).map(|&p| luminance(p)).collect();
        assert!(lum.len() > 1000);
        let (lo, hi) = lum.iter().fold((f32::MAX, 0.0f32), |(lo, hi), &l| (lo.min(l), hi.max(l)));
        assert!(lo > 0.85 * hi, "acne: floor luminance ranges {lo}..{hi}");
    }
}

#[test]
fn bad_scene_is_an_error_not_a_panic() {
    let (lib, mut scene) = small_set();
    let blas = BlasSet::build(&lib);
    scene.instances[2].mesh = 99;
    let err = render_frame(&blas, &lib, &scene, &settings(8, 8, 1), None).unwrap_err().to_string();
    assert!(err.contains("mesh 99") && err.contains("agent 11"), "{err}");
    let (_, scene) = small_set();
    assert!(render_frame(&blas, &lib, &scene, &settings(0, 8, 1), None).is_err());
}

// ----------------------------------------------------------------- EXR

#[test]
fn exr_round_trip() {
    let (lib, scene) = small_set();
    let blas = BlasSet::build(&lib);
    let s = settings(24, 16, 2);
    let film = render_frame(&blas, &lib, &scene, &s, None).unwrap();
    let (world_to_camera, world_to_ndc) = camera_matrices(&scene.camera, s.width, s.height, 0.1, 1000.0);
    let meta = LayerMeta {
        shot: "demo".into(),
        layer: "crowd_0".into(),
        frame: 1001,
        seed: 1234,
        spp: 2,
        id_mapping: ID_MAPPING.into(),
        world_to_camera,
        world_to_ndc,
        near: 0.1,
        far: 1000.0,
        fps: 24.0,
        render_fingerprint: String::new(),
        denoiser: String::new(),
        shutter: None,
        colourspace: Default::default(),
    };
    let dir = common::tempdir().unwrap();
    let path = dir.path().join("demo.crowd_0.1001.exr");
    write_layer(&path, &film, &meta).unwrap();
    // No temporary file left behind.
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1);

    let (back, meta_back) = read_layer(&path).unwrap();
    assert_eq!(meta_back, meta);
    assert_eq!((back.width, back.height), (24, 16));
    assert_eq!(back.z, film.z, "Z is f32: lossless");
    assert_eq!(back.agent_id, film.agent_id, "agent.id is u32: lossless");
    let half = |a: f32, b: f32| (a - b).abs() <= 1e-3 * a.abs().max(1e-2);
    for i in 0..film.rgba.len() {
        for c in 0..4 {
            assert!(half(film.rgba[i][c], back.rgba[i][c]));
        }
        for c in 0..3 {
            assert!(half(film.normal[i][c], back.normal[i][c]) && half(film.albedo[i][c], back.albedo[i][c]));
        }
    }

    // The raw file: sorted channel names and types, standard attributes.
    use exr::prelude::*;
    let image = read_first_flat_layer_from_file(&path).unwrap();
    let names: Vec<String> = image.layer_data.channel_data.list.iter().map(|c| c.name.to_string()).collect();
    assert_eq!(names, ["A", "B", "G", "N.X", "N.Y", "N.Z", "R", "Z", "agent.id", "albedo.B", "albedo.G", "albedo.R"]);
    let types: Vec<&str> = image
        .layer_data
        .channel_data
        .list
        .iter()
        .map(|c| match c.sample_data {
            FlatSamples::F16(_) => "half",
            FlatSamples::F32(_) => "float",
            FlatSamples::U32(_) => "uint",
        })
        .collect();
    assert_eq!(
        types,
        ["half", "half", "half", "half", "half", "half", "half", "float", "uint", "half", "half", "half"]
    );
    let attrs = &image.layer_data.attributes;
    assert!(attrs.software_name.as_ref().unwrap().to_string().starts_with("throng "));
    assert_eq!(image.layer_data.encoding.compression, Compression::ZIP16);

    // The worldToCamera matrix puts a point in front of the camera at +z (Imath row vectors).
    let target = Vec3::new(0.0, 0.5, -1.0);
    let m = glam::Mat4::from_cols_array(&world_to_camera);
    let pc = m.transform_point3(target);
    assert!(pc.z > 0.0 && pc.x.abs() < 1e-4, "{pc}");
    // And worldToNDC (OpenEXR's NDC: 0..1 from the top-left) maps the image centre's point to (0.5, 0.5).
    let ndc = glam::Mat4::from_cols_array(&world_to_ndc).project_point3(target);
    assert!((ndc.x - 0.5).abs() < 1e-4 && (ndc.y - 0.5).abs() < 1e-4 && ndc.z > 0.0 && ndc.z < 1.0, "{ndc}");

    let png = dir.path().join("preview.png");
    write_preview_png(&png, &film).unwrap();
    assert!(std::fs::metadata(&png).unwrap().len() > 50);
}

#[test]
fn degenerate_crowd_at_one_point_traces_correctly() {
    // Uninitialised cache rows put many agents at exactly the same spot: the
    // trees must stay within obvhs' fixed traversal stack (validate checks depth).
    let lib = Library { meshes: vec![Mesh::cube("cube")], materials: vec![Material::default()], textures: vec![] };
    let blas = BlasSet::build(&lib);
    let instances: Vec<Instance> = (0..20_000)
        .map(|i| instance(0, 0, Affine3A::from_translation(Vec3::new(0.0, 0.5, 0.0)), Some(i), vis::ALL))
        .collect();
    for kind in [TlasKind::Bvh2, TlasKind::CwBvh] {
        let tlas = Tlas::build_with(&blas, &instances, kind);
        tlas.validate();
        let ray = WorldRay { origin: Vec3::new(0.0, 0.5, 5.0), direction: -Vec3::Z, tmax: f32::INFINITY, time: 0.0 };
        let hit = tlas.intersect(&ray, vis::CAMERA).expect("hits the stack of cubes");
        assert!((hit.t - 4.5).abs() < 1e-4);
        assert!(tlas.occluded(&ray, vis::SHADOW));
    }
}

#[test]
fn degenerate_mesh_triangles_are_dropped() {
    // 5000 copies of one triangle, 5000 collapsed triangles, one bad index.
    let mut m = Mesh { name: "junk".into(), positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y], ..Default::default() };
    for _ in 0..5000 {
        m.indices.extend_from_slice(&[0, 1, 2, 1, 1, 1]);
    }
    m.indices.extend_from_slice(&[0, 1, 7]);
    let lib = Library { meshes: vec![m], materials: vec![Material::default()], textures: vec![] };
    let blas = BlasSet::build(&lib);
    blas.validate();
    assert_eq!(blas.get(0).unwrap().triangle_count(), 1);
    let one = [instance(0, 0, Affine3A::IDENTITY, None, vis::ALL)];
    let tlas = Tlas::build(&blas, &one);
    let hit = tlas
        .intersect(
            &WorldRay { origin: Vec3::new(0.2, 0.2, 1.0), direction: -Vec3::Z, tmax: f32::INFINITY, time: 0.0 },
            vis::ALL,
        )
        .unwrap();
    assert_eq!(hit.triangle, 0);
}

#[test]
fn axis_aligned_rays_hit_shared_edges_and_signed_zeros() {
    // Regressions: obvhs' triangle test rejects barycentrics of -0.0 (a ray
    // exactly on a face diagonal went through the box), and a -0.0 direction
    // component made traversal miss.
    let tri = Mesh {
        name: "t".into(),
        positions: vec![Vec3::ZERO, Vec3::X, Vec3::Y],
        indices: vec![0, 1, 2],
        ..Default::default()
    };
    let lib = Library { meshes: vec![tri, Mesh::cube("cube")], materials: vec![Material::default()], textures: vec![] };
    let blas = BlasSet::build(&lib);
    let turned = Affine3A::from_rotation_y(PI); // object-space directions pick up -0.0 too
    for kind in [TlasKind::Bvh2, TlasKind::CwBvh] {
        for (mesh, m, expected_t) in [(0, Affine3A::IDENTITY, 1.0), (1, Affine3A::IDENTITY, 0.5), (1, turned, 0.5)] {
            let one = [instance(mesh, 0, m, None, vis::ALL)];
            let tlas = Tlas::build_with(&blas, &one, kind);
            for d in [-Vec3::Z, Vec3::new(0.0, 0.0, -1.0)] {
                let ray = WorldRay { origin: Vec3::new(0.2, 0.2, 1.0), direction: d, tmax: f32::INFINITY, time: 0.0 };
                let hit = tlas.intersect(&ray, vis::ALL);
                let t = hit.map(|h| h.t);
                assert_eq!(t, Some(expected_t), "{kind:?} mesh {mesh} dir {d:?}");
            }
        }
    }
}

#[test]
fn base_color_texture_reaches_the_albedo_aov() {
    // Left half of the texture red, right half green, on a floor seen from above.
    let texture = throng::scene::Texture {
        name: "split".into(),
        width: 2,
        height: 1,
        texels: vec![[1.0, 0.0, 0.0, 1.0], [0.0, 1.0, 0.0, 1.0]],
    };
    let mut tiles = material("tiles", Vec3::ONE, 0.0, 0.8);
    tiles.base_color_texture = Some(0);
    let lib = Library { meshes: vec![quad(4.0, Vec3::ZERO)], materials: vec![tiles], textures: vec![texture] };
    let blas = BlasSet::build(&lib);
    let scene = FrameScene {
        instances: vec![instance(0, 0, Affine3A::IDENTITY, None, vis::ALL)],
        camera: Camera {
            world_from_camera: Affine3A::from_rotation_translation(
                Quat::from_rotation_x(-PI / 2.0),
                Vec3::new(0.0, 3.0, 0.0),
            ),
            yfov: 0.5,
            aperture: 0.0,
            focus_distance: 1.0,
        },
        lights: SceneLights::sun_and_sky(None, Sky { radiance: Vec3::ONE }),
        motion: None,
    };
    let film = render_frame(&blas, &lib, &scene, &settings(32, 16, 4), None).unwrap();
    // The camera looks down with +Y up on screen = -Z in the world; u runs along +X (image left to right).
    let (left, right) = (film.albedo[film.index(5, 8)], film.albedo[film.index(26, 8)]); // near texel centres
    assert!(left[0] > 0.85 && left[1] < 0.15, "{left:?}");
    assert!(right[1] > 0.85 && right[0] < 0.15, "{right:?}");
}

#[test]
fn empty_scene_renders_sky_and_reports_progress() {
    let lib = Library::default();
    let blas = BlasSet::build(&lib);
    let scene = FrameScene {
        instances: vec![],
        camera: camera(Vec3::ZERO, -Vec3::Z, 40.0),
        lights: SceneLights::sun_and_sky(None, Sky { radiance: Vec3::new(0.25, 0.5, 1.0) }),
        motion: None,
    };
    let done = std::sync::atomic::AtomicUsize::new(0);
    let report = |n: usize| {
        done.fetch_max(n, std::sync::atomic::Ordering::Relaxed);
    };
    let set_layer = RenderSettings { sky_visible: true, ..settings(20, 10, 1) };
    let film = render_frame(&blas, &lib, &scene, &set_layer, Some(&report)).unwrap();
    assert!(film.rgba.iter().all(|p| *p == [0.25, 0.5, 1.0, 1.0]));
    assert_eq!(done.into_inner(), 200);
    // A crowd layer sees no sky: black, alpha 0.
    let film = render_frame(&blas, &lib, &scene, &settings(20, 10, 1), None).unwrap();
    assert!(film.rgba.iter().all(|p| *p == [0.0; 4]) && film.z.iter().all(|z| z.is_infinite()));
}

/// `diffuse_only`: even a glossy material shades as Lambert with its base
/// colour, so a convex sphere under a white sky returns exactly its albedo.
#[test]
fn diffuse_only_is_lambert_furnace() {
    let albedo = 0.5;
    let lib = Library {
        meshes: vec![Mesh::uv_sphere("sphere", 1.0, 48, 96)],
        materials: vec![material("gloss", Vec3::splat(albedo), 0.0, 0.05)],
        textures: vec![],
    };
    let blas = BlasSet::build(&lib);
    let scene = FrameScene {
        instances: vec![instance(0, 0, Affine3A::IDENTITY, None, vis::ALL)],
        camera: camera(Vec3::new(0.0, 0.0, 4.0), Vec3::ZERO, 40.0),
        lights: SceneLights::sun_and_sky(None, Sky { radiance: Vec3::ONE }),
        motion: None,
    };
    let s = RenderSettings { sky_visible: true, diffuse_only: true, ..settings(48, 36, 16) };
    let film = render_frame(&blas, &lib, &scene, &s, None).unwrap();
    let (mut count, mut exact, mut sum) = (0, 0, 0.0f32);
    for i in 0..film.rgba.len() {
        if film.albedo[i] == [albedo; 3] {
            // Bounce rays off a convex sphere escape: weight = base colour exactly, except
            // near the silhouette, where a sample whose bounce dips below the geometric
            // normal (smooth vs flat normal) ends the path.
            exact += (0..3).all(|c| (film.rgba[i][c] - albedo).abs() < 1e-4) as usize;
            sum += film.rgba[i][0];
            count += 1;
        }
    }
    assert!(exact * 10 >= count * 9, "only {exact} of {count} pixels are exactly the albedo");
    assert!((sum / count as f32 - albedo).abs() < 0.005, "mean {}", sum / count as f32);
    assert!(count > 200, "sphere covers too few pixels: {count}");
    // Without the flag the glossy sphere is not Lambert (Fresnel reflection adds energy).
    let film = render_frame(&blas, &lib, &scene, &RenderSettings { diffuse_only: false, ..s }, None).unwrap();
    let gloss = film.rgba.iter().zip(&film.albedo).filter(|(_, a)| **a == [albedo; 3]).map(|(p, _)| p[0]).sum::<f32>()
        / count as f32;
    assert!((gloss - albedo).abs() > 0.01, "gloss {gloss}");
}
