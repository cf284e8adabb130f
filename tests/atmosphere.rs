//! The atmosphere (render::atmosphere) in whole renders against closed
//! forms: a point light's single scattering in an infinite medium (the
//! integral along the camera ray, by quadrature); the closed-form haze
//! against the path tracer's own single scattering of a sun; a floor seen
//! through absorbing air, lit through it; and bit-identical renders for any
//! thread count.

use std::f32::consts::{FRAC_PI_2, PI};

use glam::{Affine3A, Vec2, Vec3};
use throng::render::accel::BlasSet;
use throng::render::atmosphere::{Atmosphere, AtmosphereMode};
use throng::render::film::{render_frame, Film};
use throng::render::RenderSettings;
use throng::scene::lights::{Light, LightKind, SceneLights};
use throng::scene::passes::{LightPath, PassSet};
use throng::scene::{vis, Camera, FrameScene, Instance, InstanceAgent, Library, Material, Mesh, Sky, Sun};

const RES: u32 = 8;

fn air(density: f32, albedo: f32, g: f32, top: f32, mode: AtmosphereMode) -> Atmosphere {
    Atmosphere { density, albedo: Vec3::splat(albedo), anisotropy: g, top, mode, ..Default::default() }
}

fn settings(spp: u32, threads: usize, atmosphere: Atmosphere) -> RenderSettings {
    RenderSettings {
        width: RES,
        height: RES,
        spp,
        max_bounces: 0,
        seed: 3,
        frame: 1,
        layer: 0,
        sky_visible: true,
        threads,
        indirect_clamp: 0.0,
        diffuse_only: true,
        atmosphere: Some(atmosphere),
        ..Default::default()
    }
}

/// Looking down -Z from `at`, with a field of view so narrow every ray is the centre ray.
fn narrow_camera(at: Vec3) -> Camera {
    Camera::pinhole(Affine3A::from_translation(at), 1e-4)
}

fn lights(sun: Option<Sun>, local: Vec<Light>) -> SceneLights {
    SceneLights { sun, sky: Sky { radiance: Vec3::ZERO }, dome: None, local, groups: Default::default() }
}

fn point_light(at: Vec3, intensity: f32) -> Light {
    Light {
        name: "lamp".into(),
        kind: LightKind::Point,
        world_from_light: Affine3A::from_translation(at),
        emission: Vec3::splat(intensity),
        two_sided: false,
        camera_visible: false,
        light_group: None,
    }
}

fn render(lib: &Library, scene: &FrameScene, s: &RenderSettings) -> Film {
    render_frame(&BlasSet::build(lib), lib, scene, s, None).expect("render")
}

fn mean_red(film: &Film) -> f64 {
    film.rgba.iter().map(|p| p[0] as f64).sum::<f64>() / film.rgba.len() as f64
}

fn hg(cos: f64, g: f64) -> f64 {
    (1.0 - g * g) / (4.0 * std::f64::consts::PI * (1.0 + g * g - 2.0 * g * cos).powf(1.5))
}

/// Single scattering along the ray t -> t (0, 0, -1) of a point light of
/// intensity `i` at (0, h, -foot), infinite medium: int_0^inf sigma_s
/// e^(-sigma_t t) p(cos) i e^(-sigma_t r) / r^2 dt, in t = foot + h tan(theta).
fn point_in_scatter(sigma_t: f64, albedo: f64, g: f64, i: f64, h: f64, foot: f64) -> f64 {
    let (lo, hi) = ((-foot / h).atan(), std::f64::consts::FRAC_PI_2);
    let n = 200_000;
    let step = (hi - lo) / n as f64;
    (0..n)
        .map(|k| {
            let theta = lo + (k as f64 + 0.5) * step;
            let t = foot + h * theta.tan();
            let r = h / theta.cos();
            // Towards the light from the point: (0, h, -(foot - t)) / r; the ray runs along -Z.
            let cos = (foot - t) / r;
            sigma_t * albedo * (-sigma_t * (t + r)).exp() * hg(cos, g) * i / h * step
        })
        .sum()
}

#[test]
fn a_point_lights_single_scattering_is_its_integral() {
    let lib = Library::default();
    for g in [0.0f32, 0.6] {
        let scene = FrameScene {
            instances: vec![],
            camera: narrow_camera(Vec3::ZERO),
            lights: lights(None, vec![point_light(Vec3::new(0.0, 0.5, -2.0), 10.0)]),
            motion: None,
        };
        let a = air(0.3, 0.8, g, f32::INFINITY, AtmosphereMode::Full);
        let got = mean_red(&render(&lib, &scene, &settings(256, 2, a)));
        let want = point_in_scatter(0.3, 0.8, g as f64, 10.0, 0.5, 2.0);
        assert!(((got - want) / want).abs() < 0.01, "g {g}: {got} vs integral {want}");
    }
}

#[test]
fn haze_by_quadrature_is_the_path_tracers_single_scattering_of_the_sun_in_thinning_air() {
    // Air thinning with height from 1 m up (scale height 3 m), no top: the
    // sun reaches into it through a finite depth. Haze only's quadrature
    // against the path tracer's exact distance sampling.
    let lib = Library::default();
    let sun =
        Sun { direction: Vec3::new(0.3, 1.0, 0.2).normalize(), angular_diameter: 0.0, irradiance: Vec3::splat(3.0) };
    for (at, tilt) in
        [(Vec3::new(0.0, 2.0, 0.0), 0.0f32), (Vec3::new(0.0, 0.5, 0.0), 0.3), (Vec3::new(0.0, 4.0, 0.0), -0.2)]
    {
        let camera = Camera::pinhole(Affine3A::from_translation(at) * Affine3A::from_rotation_x(tilt), 1e-4);
        let scene = FrameScene { instances: vec![], camera, lights: lights(Some(sun), vec![]), motion: None };
        let full = Atmosphere { falloff: 3.0, base: 1.0, ..air(0.08, 0.9, 0.4, f32::INFINITY, AtmosphereMode::Full) };
        let haze = Atmosphere { mode: AtmosphereMode::Haze, ..full };
        let traced = mean_red(&render(&lib, &scene, &settings(1024, 2, full)));
        let closed = mean_red(&render(&lib, &scene, &settings(1, 2, haze)));
        assert!(closed > 0.0);
        assert!(((traced - closed) / closed).abs() < 0.02, "tilt {tilt}: traced {traced} vs quadrature {closed}");
    }
}

#[test]
fn a_start_distance_keeps_the_camera_rays_first_metres_clear() {
    // The floor 4 m below the camera through air 10 m deep that starts 1.5 m out.
    let sun = Sun { direction: Vec3::Y, angular_diameter: 0.0, irradiance: Vec3::splat(2.0) };
    let (lib, scene) = grey_floor_from_above(sun, vec![], 1e-4);
    for mode in [AtmosphereMode::Haze, AtmosphereMode::Full] {
        let a = Atmosphere { start: 1.5, ..air(0.1, 0.0, 0.0, 10.0, mode) };
        let film = render(&lib, &scene, &RenderSettings { passes: air_passes(), ..settings(64, 2, a) });
        let t = pass_red(&film, "atmosphere_transmittance");
        assert!(t.iter().all(|&t| (t - (-0.1f64 * 2.5).exp()).abs() < 1e-5), "{mode:?}: {:?}", &t[..2]);
        // What the camera sees is dimmed by 2.5 m of air, its light by all 10 (full) or none (haze).
        let lit = if mode == AtmosphereMode::Full { (-0.1f64 * 10.0).exp() } else { 1.0 };
        let want = 0.5 / std::f64::consts::PI * 2.0 * lit * (-0.1f64 * 2.5).exp();
        let got = mean_red(&film);
        assert!(((got - want) / want).abs() < 1e-2, "{mode:?}: {got} vs {want}");
    }
}

#[test]
fn a_sphere_lamp_found_by_the_phase_functions_rays_is_weighed_three_ways() {
    // A slab of air 1 mm thick over a black floor, the camera ray inside it
    // and a big sphere lamp just above (so wide that light sampling's density
    // is near the phase function's and the phase rays carry a real share).
    // With a bounce the phase function's rays from the slab find the lamp
    // too (the third technique, weighed against NEE and equiangular
    // sampling: render::integrator), and hardly any scatter again (their
    // path in the slab is millimetres: under 1 % more), so with or without
    // the bounce the render is the single scattering integral.
    let black = Material { name: "black".into(), base_color: Vec3::ZERO, ..Default::default() };
    let lib = Library { meshes: vec![floor()], materials: vec![black], textures: vec![] };
    for g in [0.0f32, -0.3] {
        let ground = Instance {
            mesh: 0,
            material: 0,
            world_from_object: Affine3A::from_translation(Vec3::new(0.0, -0.001, 0.0)),
            agent: InstanceAgent::NONE,
            part: 0,
            visibility: vis::ALL,
        };
        let lamp = Light {
            kind: LightKind::Sphere { radius: 0.45 },
            emission: Vec3::splat(10.0),
            ..point_light(Vec3::new(0.0, 0.5, -2.0), 0.0)
        };
        let camera = narrow_camera(Vec3::ZERO);
        let scene = FrameScene { instances: vec![ground], camera, lights: lights(None, vec![lamp]), motion: None };
        let a = air(0.3, 0.8, g, 0.001, AtmosphereMode::Full);
        let want = sphere_in_scatter(0.3, 0.8, g as f64, 10.0, 0.45, 0.5, 2.0, Some(0.001));
        for bounces in [0, 1] {
            let s = RenderSettings { max_bounces: bounces, ..settings(256, 2, a) };
            let got = mean_red(&render(&lib, &scene, &s));
            assert!(((got - want) / want).abs() < 0.015, "g {g}, {bounces} bounces: {got} vs integral {want}");
        }
    }
}

#[test]
fn forty_lamps_picked_by_the_light_tree_sum_to_their_integrals() {
    // Past 16 point lights equiangular sampling picks by the light tree at
    // one point of the ray part (render::lights): still unbiased, so the
    // in-scatter is the sum of each lamp's integral.
    let lib = Library::default();
    let lamps: Vec<Light> = (0..40)
        .map(|k| {
            let at = Vec3::new(0.3 * ((k % 3) as f32 - 1.0), 0.4 + 0.1 * (k % 4) as f32, -0.5 - 0.35 * k as f32);
            point_light(at, 2.0)
        })
        .collect();
    let want: f64 = lamps
        .iter()
        .map(|l| {
            let at = l.world_from_light.translation;
            point_in_scatter(0.3, 0.8, 0.3, 2.0, (at.x * at.x + at.y * at.y).sqrt() as f64, -at.z as f64)
        })
        .sum();
    let scene =
        FrameScene { instances: vec![], camera: narrow_camera(Vec3::ZERO), lights: lights(None, lamps), motion: None };
    let a = air(0.3, 0.8, 0.3, f32::INFINITY, AtmosphereMode::Full);
    let got = mean_red(&render(&lib, &scene, &settings(256, 2, a)));
    assert!(((got - want) / want).abs() < 0.02, "{got} vs the lamps' integrals {want}");
}

#[test]
fn haze_in_closed_form_is_the_path_tracers_single_scattering_of_the_sun() {
    let lib = Library::default();
    let sun =
        Sun { direction: Vec3::new(0.3, 1.0, 0.2).normalize(), angular_diameter: 0.0, irradiance: Vec3::splat(3.0) };
    // Looking level and a little down and up, in air 12 m deep over the camera.
    for (at, tilt) in [(Vec3::new(0.0, 2.0, 0.0), 0.0f32), (Vec3::new(0.0, 2.0, 0.0), 0.2), (Vec3::ZERO, -0.15)] {
        let camera = Camera::pinhole(Affine3A::from_translation(at) * Affine3A::from_rotation_x(tilt), 1e-4);
        let scene = FrameScene { instances: vec![], camera, lights: lights(Some(sun), vec![]), motion: None };
        let full = air(0.05, 0.9, 0.4, 12.0, AtmosphereMode::Full);
        let haze = Atmosphere { mode: AtmosphereMode::Haze, ..full };
        let traced = mean_red(&render(&lib, &scene, &settings(1024, 2, full)));
        let closed = mean_red(&render(&lib, &scene, &settings(1, 2, haze)));
        assert!(closed > 0.0);
        assert!(((traced - closed) / closed).abs() < 0.02, "tilt {tilt}: traced {traced} vs closed form {closed}");
    }
}

/// A square in the y = 0 plane, front face up.
fn floor() -> Mesh {
    let h = 100.0;
    Mesh {
        name: "floor".into(),
        positions: [(-h, -h), (h, -h), (h, h), (-h, h)].map(|(x, z)| Vec3::new(x, 0.0, z)).to_vec(),
        normals: vec![Vec3::Y; 4],
        uvs: vec![Vec2::ZERO, Vec2::X, Vec2::ONE, Vec2::Y],
        tangents: vec![],
        indices: vec![0, 2, 1, 0, 3, 2],
    }
}

#[test]
fn a_floor_through_absorbing_air_is_lit_and_seen_through_it() {
    // Straight down from 4 m at a floor lit by a sun overhead, under air 10 m deep that only absorbs.
    let sun = Sun { direction: Vec3::Y, angular_diameter: 0.0, irradiance: Vec3::splat(2.0) };
    let (lib, scene) = grey_floor_from_above(sun, vec![], 1e-4);
    let a = air(0.1, 0.0, 0.0, 10.0, AtmosphereMode::Full);
    let got = mean_red(&render(&lib, &scene, &settings(64, 2, a)));
    // albedo / pi x irradiance x (10 m of air down to the floor) x (4 m back up to the camera).
    let want = 0.5 / std::f64::consts::PI * 2.0 * (-0.1f64 * 10.0).exp() * (-0.1f64 * 4.0).exp();
    // The camera ray's attenuation by distance sampling: a share of paths ends, within noise.
    assert!(((got - want) / want).abs() < 1e-2, "{got} vs {want}");
    // Haze only attenuates the camera ray alone (bounce and shadow rays see no air).
    let haze = Atmosphere { mode: AtmosphereMode::Haze, ..a };
    let got = mean_red(&render(&lib, &scene, &settings(4, 2, haze)));
    let want = 0.5 / std::f64::consts::PI * 2.0 * (-0.1f64 * 4.0).exp();
    assert!(((got - want) / want).abs() < 1e-3, "haze: {got} vs {want}");
}

#[test]
fn hazy_renders_are_bit_identical_for_any_thread_count() {
    let lib = Library::default();
    let sphere = Light {
        kind: LightKind::Sphere { radius: 0.1 },
        emission: Vec3::splat(40.0),
        camera_visible: true,
        ..point_light(Vec3::new(-0.5, 1.2, -2.0), 0.0)
    };
    let sun =
        Sun { direction: Vec3::new(0.3, 1.0, 0.2).normalize(), angular_diameter: 0.02, irradiance: Vec3::splat(3.0) };
    let scene = FrameScene {
        instances: vec![],
        camera: Camera::pinhole(Affine3A::from_translation(Vec3::Y), 1.0),
        lights: lights(Some(sun), vec![point_light(Vec3::new(0.5, 1.5, -3.0), 5.0), sphere]),
        motion: None,
    };
    let a = air(0.2, 0.8, 0.3, 6.0, AtmosphereMode::Full);
    let s = |threads| RenderSettings { max_bounces: 3, ..settings(8, threads, a) };
    let one = render(&lib, &scene, &s(1));
    let four = render(&lib, &scene, &s(4));
    assert!(one.rgba.iter().any(|p| p[0] > 0.0));
    assert!(one.rgba.iter().zip(&four.rgba).all(|(a, b)| a.map(f32::to_bits) == b.map(f32::to_bits)));
}

/// A grey floor seen straight down from 4 m (a pinhole of field `fov`) under `sun` and `local` lights.
fn grey_floor_from_above(sun: Sun, local: Vec<Light>, fov: f32) -> (Library, FrameScene) {
    let grey = Material { name: "floor".into(), base_color: Vec3::splat(0.5), ..Default::default() };
    let lib = Library { meshes: vec![floor()], materials: vec![grey], textures: vec![] };
    let instance = Instance {
        mesh: 0,
        material: 0,
        world_from_object: Affine3A::IDENTITY,
        agent: InstanceAgent::NONE,
        part: 0,
        visibility: vis::ALL,
    };
    let down = Affine3A::from_cols(Vec3::X.into(), (-Vec3::Z).into(), Vec3::Y.into(), (Vec3::Y * 4.0).into());
    let scene = FrameScene {
        instances: vec![instance],
        camera: Camera::pinhole(down, fov),
        lights: lights(Some(sun), local),
        motion: None,
    };
    (lib, scene)
}

/// The floor of [`a_floor_through_absorbing_air_is_lit_and_seen_through_it`],
/// wide, with a point light in group `key` and a sun.
fn hazy_floor() -> (Library, FrameScene) {
    let sun =
        Sun { direction: Vec3::new(0.2, 1.0, 0.1).normalize(), angular_diameter: 0.02, irradiance: Vec3::splat(2.0) };
    let mut lamp = point_light(Vec3::new(0.3, 1.5, -0.2), 8.0);
    lamp.light_group = Some("key".into());
    grey_floor_from_above(sun, vec![lamp], 1.0)
}

#[test]
fn passes_and_light_groups_add_up_to_the_beauty_in_haze() {
    let (lib, scene) = hazy_floor();
    for mode in [AtmosphereMode::Full, AtmosphereMode::Haze] {
        let a = air(0.15, 0.8, 0.3, 6.0, mode);
        let s = RenderSettings {
            width: 16,
            height: 16,
            max_bounces: 2,
            indirect_clamp: 10.0,
            passes: throng::scene::passes::PassSet::all(),
            ..settings(8, 2, a)
        };
        let film = render(&lib, &scene, &s);
        let is_path = |n: &str| throng::scene::passes::LightPath::ALL.iter().any(|l| l.name() == n);
        let paths: Vec<_> = film.passes.iter().filter(|p| is_path(&p.name)).collect();
        let groups: Vec<_> = film.passes.iter().filter(|p| p.name.starts_with("lg_")).collect();
        assert!(groups.iter().any(|p| p.name == "lg_key") && groups.iter().any(|p| p.name == "lg_sun"));
        for i in 0..film.rgba.len() {
            let beauty = Vec3::from_slice(&film.rgba[i][..3]);
            for family in [&paths, &groups] {
                let sum: Vec3 = family.iter().map(|p| Vec3::from(p.data[i])).sum();
                let size: f32 = family.iter().map(|p| Vec3::from(p.data[i]).abs().max_element()).sum();
                assert!(
                    (sum - beauty).abs().max_element() <= 1e-5 * size + 1e-6,
                    "{mode:?} pixel {i}: {sum} vs {beauty}"
                );
            }
        }
        let total =
            |n: &str| film.passes.iter().find(|p| p.name == n).unwrap().data.iter().map(|v| v[0] as f64).sum::<f64>();
        assert!(total("atmosphere") > 0.0, "{mode:?}: no light in the atmosphere pass");
        assert!(total("diffuse_direct") > 0.0);
    }
}

#[test]
fn bad_atmosphere_keys_are_refused_by_name() {
    let path = std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/stack_shot/shot.toml"));
    let base = std::fs::read_to_string(path).unwrap();
    let parse = |table: &str| throng::shot::Shot::parse(&format!("{base}\n[atmosphere]\n{table}\n"), path);
    let good =
        parse("density = 0.05\ncolor = [0.9, 0.8, 0.7]\nanisotropy = 0.3\nheight = 10.0\nmode = \"haze\"").unwrap();
    let air = good.atmosphere.expect("the table is read");
    assert_eq!((air.density, air.top, air.mode), (0.05, 10.0, AtmosphereMode::Haze));
    assert_eq!((air.falloff, air.base, air.start), (f32::INFINITY, 0.0, 0.0));
    let thin = parse("density = 0.05\nfalloff = 6.0\nbase = -1.0\nstart = 3.5").unwrap().atmosphere.unwrap();
    assert_eq!((thin.falloff, thin.base, thin.start), (6.0, -1.0, 3.5));
    assert_eq!(air.albedo, Vec3::new(0.9, 0.8, 0.7));
    for (table, key) in [
        ("density = -0.1", "atmosphere.density"),
        ("density = nan", "atmosphere.density"),
        ("density = inf", "atmosphere.density"),
        ("density = 0.1\nanisotropy = 1.0", "atmosphere.anisotropy"),
        ("density = 0.1\nanisotropy = -1.5", "atmosphere.anisotropy"),
        ("density = 0.1\ncolor = [0.5, 1.2, 0.5]", "atmosphere.color"),
        ("density = 0.1\ncolor = [-0.1, 0.5, 0.5]", "atmosphere.color"),
        ("density = 0.1\nheight = nan", "atmosphere.height"),
        ("density = 0.1\nfalloff = 0.0", "atmosphere.falloff"),
        ("density = 0.1\nfalloff = -3.0", "atmosphere.falloff"),
        ("density = 0.1\nfalloff = 5.0\nbase = inf", "atmosphere.base"),
        ("density = 0.1\nstart = -1.0", "atmosphere.start"),
        ("density = 0.1\nstart = nan", "atmosphere.start"),
    ] {
        let err = parse(table).expect_err(table).to_string();
        assert!(err.contains(key) && err.contains("shot.toml"), "{table}: {err}");
    }
    // An unknown key names itself too.
    assert!(parse("density = 0.1\nfog = 1").unwrap_err().to_string().contains("fog"));
}

/// The light and transmittance passes of `film`: `name`'s red channel per pixel.
fn pass_red(film: &Film, name: &str) -> Vec<f64> {
    let pass = film.passes.iter().find(|p| p.name == name).unwrap_or_else(|| panic!("no pass {name}"));
    pass.data.iter().map(|v| v[0] as f64).collect()
}

/// The air's two passes (docs/compositing.md, "Removing and regrading the air").
fn air_passes() -> PassSet {
    PassSet { light_paths: vec![LightPath::Atmosphere], transmittance: true, ..Default::default() }
}

#[test]
fn removing_the_air_with_its_passes_gives_the_clear_render() {
    // Looking straight up from the floor at a grey ceiling 4 m up, lit by a
    // lamp 1 m under it; the air fills the lowest 2 m: the camera ray crosses
    // it, the lamp lights it from above, and the ceiling's own light (lamp to
    // ceiling, no bounce) never enters it. So beauty = T x ceiling + atmosphere,
    // and (beauty - atmosphere) / T is the clear render, within the noise of
    // distance sampling.
    let grey = Material { name: "ceiling".into(), base_color: Vec3::splat(0.5), ..Default::default() };
    let lib = Library { meshes: vec![floor()], materials: vec![grey], textures: vec![] };
    let ceiling = Instance {
        mesh: 0,
        material: 0,
        world_from_object: Affine3A::from_translation(Vec3::Y * 4.0) * Affine3A::from_rotation_x(PI),
        agent: InstanceAgent::NONE,
        part: 0,
        visibility: vis::ALL,
    };
    let up = Camera::pinhole(Affine3A::from_rotation_x(FRAC_PI_2), 1e-4);
    let lamp = point_light(Vec3::new(0.5, 3.0, 0.0), 5.0);
    let scene = FrameScene { instances: vec![ceiling], camera: up, lights: lights(None, vec![lamp]), motion: None };
    let a = air(0.2, 0.8, 0.3, 2.0, AtmosphereMode::Full);
    let hazy = render(&lib, &scene, &RenderSettings { passes: air_passes(), ..settings(256, 2, a) });
    let clear = render(&lib, &scene, &RenderSettings { atmosphere: None, ..settings(4, 2, a) });
    let t = pass_red(&hazy, "atmosphere_transmittance");
    let glow = pass_red(&hazy, "atmosphere");
    let want_t = (-0.2f64 * 2.0).exp();
    assert!(t.iter().all(|&t| (t - want_t).abs() < 1e-4), "transmittance {:?} vs {want_t}", &t[..4]);
    let n = t.len() as f64;
    let removed: f64 = hazy.rgba.iter().zip(&glow).zip(&t).map(|((p, g), t)| (p[0] as f64 - g) / t).sum::<f64>() / n;
    let (beauty, glow_mean) = (mean_red(&hazy), glow.iter().sum::<f64>() / n);
    let clear = mean_red(&clear);
    assert!(glow_mean > 0.05 * beauty, "the air glows: {glow_mean} of {beauty}");
    assert!(((removed - clear) / clear).abs() < 0.03, "haze removed {removed} vs clear air {clear}");
    // And the beauty is not the clear render: the air is there.
    assert!(((beauty - clear) / clear).abs() > 0.1, "{beauty} vs {clear}");
}

#[test]
fn haze_only_removed_with_its_passes_is_the_clear_render_exactly() {
    // Haze only attenuates the camera ray alone and adds a closed-form glow:
    // beauty = T x surface + atmosphere sample by sample, with nothing random in the air.
    let sun = Sun { direction: Vec3::new(0.3, 1.0, 0.1).normalize(), angular_diameter: 0.0, irradiance: Vec3::ONE };
    let (lib, scene) = grey_floor_from_above(sun, vec![], 1e-4);
    let a = air(0.1, 0.8, 0.3, 10.0, AtmosphereMode::Haze);
    let hazy = render(&lib, &scene, &RenderSettings { passes: air_passes(), ..settings(4, 2, a) });
    let clear = render(&lib, &scene, &RenderSettings { atmosphere: None, ..settings(4, 2, a) });
    let (t, glow) = (pass_red(&hazy, "atmosphere_transmittance"), pass_red(&hazy, "atmosphere"));
    for i in 0..t.len() {
        let (beauty, want) = (hazy.rgba[i][0] as f64, clear.rgba[i][0] as f64);
        assert!(glow[i] > 0.0 && (t[i] - (-0.4f64).exp()).abs() < 1e-5, "pixel {i}: T {} glow {}", t[i], glow[i]);
        let removed = (beauty - glow[i]) / t[i];
        assert!((removed - want).abs() <= 1e-5 * want, "pixel {i}: {removed} vs {want}");
    }
}

#[test]
fn clear_air_writes_no_air_passes_and_hazy_air_both() {
    use throng::render::job::RenderJob;
    let path = std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/stack_shot/shot.toml"));
    let base = std::fs::read_to_string(path).unwrap();
    let clear = throng::shot::Shot::parse(&base, path).unwrap();
    let hazy = throng::shot::Shot::parse(&format!("{base}\n[atmosphere]\ndensity = 0.05\n"), path).unwrap();
    let none = throng::shot::Shot::parse(&format!("{base}\n[atmosphere]\ndensity = 0.0\n"), path).unwrap();
    for names in [vec!["all"], vec!["atmosphere", "atmosphere_transmittance", "diffuse_direct"]] {
        let job = RenderJob {
            passes: Some(PassSet::parse(&names, "--passes").unwrap()),
            ..RenderJob::new(vec![], vec![], 1, Default::default())
        };
        let air = job.passes_of(&hazy).unwrap();
        assert!(air.transmittance && air.light_paths.contains(&LightPath::Atmosphere), "{names:?}");
        for shot in [&clear, &none] {
            let set = job.passes_of(shot).unwrap();
            assert!(!set.transmittance && !set.light_paths.contains(&LightPath::Atmosphere), "{names:?}");
            assert!(set.light_paths.contains(&LightPath::DiffuseDirect));
        }
    }
}

/// Single scattering along the ray t -> t (0, 0, -1) of a sphere light of
/// radiance `l`, radius `r`, centre (0, h, -foot), infinite medium: int_0^inf
/// sigma_s e^(-sigma_t t) int_cone p(cos) l e^(-sigma_t s) dw dt, s the distance
/// to the sphere along w, or only what lies below `slab` (the top of the air,
/// the ray at height 0); t = foot + h tan(psi) outside, the cone by (cos, phi) inside.
#[allow(clippy::too_many_arguments, reason = "the integral's parameters, named as the formula has them")]
fn sphere_in_scatter(sigma_t: f64, albedo: f64, g: f64, l: f64, r: f64, h: f64, foot: f64, slab: Option<f64>) -> f64 {
    use std::f64::consts::{FRAC_PI_2, PI};
    let (lo, hi) = ((-foot / h).atan(), FRAC_PI_2);
    let (n, m) = (4000, 48);
    let step = (hi - lo) / n as f64;
    let centre = glam::DVec3::new(0.0, h, -foot);
    let dir = glam::DVec3::new(0.0, 0.0, -1.0);
    (0..n)
        .map(|k| {
            let psi = lo + (k as f64 + 0.5) * step;
            let t = foot + h * psi.tan();
            let x = dir * t;
            let to = centre - x;
            let dc = to.length();
            let axis = to / dc;
            let cos_max = (1.0 - (r / dc).powi(2)).max(0.0).sqrt();
            let e1 = axis.cross(glam::DVec3::X).normalize();
            let e2 = axis.cross(e1);
            let mut cone = 0.0;
            for i in 0..m {
                let c = cos_max + (1.0 - cos_max) * (i as f64 + 0.5) / m as f64;
                let sin = (1.0 - c * c).max(0.0).sqrt();
                let s = dc * c - (r * r - dc * dc * sin * sin).max(0.0).sqrt();
                for j in 0..m {
                    let phi = 2.0 * PI * (j as f64 + 0.5) / m as f64;
                    let w = axis * c + (e1 * phi.cos() + e2 * phi.sin()) * sin;
                    let s = slab.map_or(s, |top| if w.y > 0.0 { s.min(top / w.y) } else { s });
                    cone += hg(w.dot(dir), g) * (-sigma_t * s).exp();
                }
            }
            let cone = cone * l * (1.0 - cos_max) * 2.0 * PI / (m * m) as f64;
            // dt = h / cos^2(psi) dpsi.
            sigma_t * albedo * (-sigma_t * t).exp() * cone * h / psi.cos().powi(2) * step
        })
        .sum()
}

#[test]
fn a_sphere_lights_single_scattering_is_its_integral() {
    // Equiangular sampling towards its centre, a point on it by solid angle,
    // weighed against distance sampling with NEE (render::atmosphere).
    let lib = Library::default();
    for g in [0.0f32, 0.6] {
        let lamp = Light {
            kind: LightKind::Sphere { radius: 0.2 },
            emission: Vec3::splat(10.0),
            ..point_light(Vec3::new(0.0, 0.5, -2.0), 0.0)
        };
        let scene = FrameScene {
            instances: vec![],
            camera: narrow_camera(Vec3::ZERO),
            lights: lights(None, vec![lamp]),
            motion: None,
        };
        let a = air(0.3, 0.8, g, f32::INFINITY, AtmosphereMode::Full);
        let got = mean_red(&render(&lib, &scene, &settings(256, 2, a)));
        let want = sphere_in_scatter(0.3, 0.8, g as f64, 10.0, 0.2, 0.5, 2.0, None);
        assert!(((got - want) / want).abs() < 0.015, "g {g}: {got} vs integral {want}");
    }
}

mod common;

fn s(p: &std::path::Path) -> &str {
    p.to_str().expect("utf-8 temp path")
}

/// A small demo-asset shot under a grey sun and sky, with `extra` after its `[render]` keys.
fn small_shot(dir: &std::path::Path, extra: &str) -> std::path::PathBuf {
    let lights = "[lights.sun]\ndirection = [-0.4, 0.6, 0.5]\nintensity = 3.0\n[lights.sky]\ncolor = [0.4, 0.4, 0.4]\n";
    let shot = common::DemoShot { name: "air", frames: (1001, 1001), lights, spp: 4, extra, ..Default::default() };
    shot.write(dir, &common::two_robots(1..=1))
}

fn render_cli(shot: &std::path::Path, out: &std::path::Path, extra: &[&str]) -> (i32, String) {
    let mut args = vec!["render", s(shot), "--layer", "full", "--frames", "1001", "--progress", "off", "--out", s(out)];
    args.extend_from_slice(extra);
    let (code, o, e) = common::run(&args);
    (code, format!("{o}{e}"))
}

#[test]
fn resume_rerenders_a_frame_made_in_other_air() {
    let dir = common::tempdir().unwrap();
    let out = dir.path().join("o");
    let clear = small_shot(dir.path(), "");
    let (code, text) = render_cli(&clear, &out, &[]);
    assert_eq!(code, 0, "{text}");
    let (code, text) = render_cli(&clear, &out, &["--resume"]);
    assert!(code == 0 && text.contains("1 skipped"), "{text}");
    // Air added, then the air changed, then the same air again.
    for (atmosphere, skipped) in [
        ("[atmosphere]\ndensity = 0.05\nheight = 5.0\n", "0 skipped"),
        ("[atmosphere]\ndensity = 0.08\nheight = 5.0\n", "0 skipped"),
        ("[atmosphere]\ndensity = 0.08\nheight = 5.0\nmode = \"haze\"\n", "0 skipped"),
        ("[atmosphere]\ndensity = 0.08\nheight = 5.0\nmode = \"haze\"\n", "1 skipped"),
    ] {
        let shot = small_shot(dir.path(), atmosphere);
        let (code, text) = render_cli(&shot, &out, &["--resume"]);
        assert!(code == 0 && text.contains(skipped), "{atmosphere}: {text}");
        if skipped == "0 skipped" {
            assert!(text.contains("other settings"), "{atmosphere}: {text}");
        }
    }
}

#[test]
fn acescg_renders_convert_the_airs_albedo() {
    // Grey lights, no bounce: the atmosphere pass is the albedo times a
    // grey value, sample by sample, so in ACEScg it is the Rec.709 one
    // through the matrix (the same samples: only colours differ).
    let dir = common::tempdir().unwrap();
    let extra = "max_bounces = 0\npasses = [\"atmosphere\"]\n[atmosphere]\ndensity = 0.08\ncolor = [0.9, 0.5, 0.2]\nheight = 5.0\n";
    let shot = small_shot(dir.path(), extra);
    // Without the set: its shop windows would light the air in colour.
    let text = std::fs::read_to_string(&shot).unwrap();
    let set = text.find("[set]").unwrap();
    let end = set + text[set..].find("\n\n").unwrap();
    std::fs::write(&shot, format!("{}{}", &text[..set], &text[end..])).unwrap();
    let mean_atmosphere = |cs: &str| -> Vec3 {
        let out = dir.path().join(cs);
        let (code, text) = render_cli(&shot, &out, &["--colourspace", cs]);
        assert_eq!(code, 0, "{text}");
        let (film, _) = throng::render::exr::read_layer(&out.join("full/air.full.1001.exr")).unwrap();
        let pass = film.passes.iter().find(|p| p.name == "atmosphere").expect("the atmosphere pass");
        pass.data.iter().map(|&v| Vec3::from(v)).sum::<Vec3>() / pass.data.len() as f32
    };
    let (rec, aces) = (mean_atmosphere("rec709"), mean_atmosphere("acescg"));
    let want = throng::render::colour::rec709_to_acescg(rec);
    assert!(rec.min_element() > 0.0);
    assert!((aces - want).abs().max_element() < 2e-3 * want.max_element(), "{aces} vs M x {rec} = {want}");
    // Unconverted it would differ by far more.
    assert!((rec - want).abs().max_element() > 0.05 * want.max_element());
}

#[test]
fn usd_export_writes_the_air_with_its_falloff_and_start() {
    let dir = common::tempdir().unwrap();
    let export = |extra: &str, name: &str| -> String {
        let shot = small_shot(dir.path(), extra);
        let out = dir.path().join(name);
        let (code, o, e) =
            common::run(&["export", s(&shot), "--format", "usd", "--frames", "1001-1001", "--out", s(&out)]);
        assert_eq!(code, 0, "{o}{e}");
        std::fs::read_to_string(&out).unwrap()
    };
    let thin = export("[atmosphere]\ndensity = 0.05\nfalloff = 6.0\nbase = 1.5\nstart = 2.0\n", "thin.usda");
    for attr in ["density = 0.05", "falloff = 6", "base = 1.5", "start = 2", "mode = \"full\""] {
        let line = thin.lines().find(|l| l.contains(&format!("throng:atmosphere:{}", attr.split(' ').next().unwrap())));
        assert!(line.is_some_and(|l| l.contains(attr)), "{attr}: {line:?}");
    }
    // Homogeneous air from the camera on writes neither; clear air no scope at all.
    let flat = export("[atmosphere]\ndensity = 0.05\n", "flat.usda");
    assert!(flat.contains("throng:atmosphere:density") && !flat.contains("falloff") && !flat.contains(":start"));
    assert!(!export("", "clear.usda").contains("Atmosphere"));
}
