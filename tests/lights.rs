//! Lights against closed forms: a diffuse floor seen straight down, lit by
//! one light at a time, max_bounces 0 (direct light only), pure Lambert
//! (radiance = albedo x irradiance / pi). A constant dome gives albedo x L
//! (the furnace); a point light I h / r^3; a spot the same inside its cone
//! and nothing outside; a rect light or an emissive panel facing the floor
//! the closed-form form factor; a sphere light pi L (r/D)^2 below it. The
//! thin lens images a point at focus to a point and blurs one off focus by
//! its circle of confusion. The sunny HDRI's importance sampling against
//! uniform sampling: the same mean, a fraction of the variance. And lit
//! renders are bit-identical for any thread count.

mod common;

use std::f32::consts::PI;
use std::sync::Arc;

use glam::{Affine3A, Quat, Vec2, Vec3};
use throng::render::accel::BlasSet;
use throng::render::dome::DomeSampler;
use throng::render::film::{render_frame, Film};
use throng::render::RenderSettings;
use throng::scene::dome::load_dome;
use throng::scene::lights::{Dome, Light, LightKind, SceneLights};
use throng::scene::passes::LightPath;
use throng::scene::{vis, Camera, FrameScene, Instance, InstanceAgent, Library, Material, Mesh, Sky};

const ALBEDO: f32 = 0.5;
/// Camera height over the floor, and the floor's half width seen.
const HEIGHT: f32 = 4.0;
const RES: u32 = 32;
/// Vertical field of view: the image spans 2 x HEIGHT x tan(fov/2) = 4 m of floor.
fn fov() -> f32 {
    2.0 * (0.5f32).atan()
}

/// A square in the y = 0 plane, front face (counter-clockwise) up.
fn quad(size: f32) -> Mesh {
    let h = size / 2.0;
    Mesh {
        name: "quad".into(),
        positions: [(-h, -h), (h, -h), (h, h), (-h, h)].map(|(x, z)| Vec3::new(x, 0.0, z)).to_vec(),
        normals: vec![Vec3::Y; 4],
        uvs: vec![Vec2::ZERO, Vec2::X, Vec2::ONE, Vec2::Y],
        tangents: vec![],
        indices: vec![0, 2, 1, 0, 3, 2],
    }
}

fn instance(mesh: u32, material: u32, world_from_object: Affine3A, visibility: u8) -> Instance {
    Instance { mesh, material, world_from_object, agent: InstanceAgent::NONE, part: 0, visibility }
}

/// Straight down from HEIGHT over the origin; image up is -Z.
fn top_camera() -> Camera {
    Camera::pinhole(
        Affine3A::from_cols(Vec3::X.into(), (-Vec3::Z).into(), Vec3::Y.into(), (Vec3::Y * HEIGHT).into()),
        fov(),
    )
}

fn settings(spp: u32, threads: usize) -> RenderSettings {
    RenderSettings {
        width: RES,
        height: RES,
        spp,
        max_bounces: 0,
        seed: 7,
        frame: 1,
        sky_visible: false,
        threads,
        indirect_clamp: 0.0,
        diffuse_only: true,
        ..Default::default()
    }
}

/// A grey floor (and `extra` instances and materials), lit by `lights`.
fn floor_scene(lights: SceneLights, extra: Vec<(Mesh, Material, Affine3A)>) -> (Library, FrameScene) {
    let grey = Material { name: "floor".into(), base_color: Vec3::splat(ALBEDO), ..Default::default() };
    let mut lib = Library { meshes: vec![quad(200.0)], materials: vec![grey], textures: vec![] };
    let mut instances = vec![instance(0, 0, Affine3A::IDENTITY, vis::ALL)];
    for (mesh, material, m) in extra {
        lib.meshes.push(mesh);
        lib.materials.push(material);
        instances.push(instance(lib.meshes.len() as u32 - 1, lib.materials.len() as u32 - 1, m, vis::ALL));
    }
    (lib, FrameScene { instances, camera: top_camera(), lights, motion: None })
}

fn render(lib: &Library, scene: &FrameScene, spp: u32, threads: usize) -> Film {
    render_frame(&BlasSet::build(lib), lib, scene, &settings(spp, threads), None).expect("render")
}

/// The floor point under pixel (x, y)'s centre.
fn floor_point(x: u32, y: u32) -> Vec3 {
    let t = (0.5 * fov()).tan();
    let sx = (2.0 * (x as f32 + 0.5) / RES as f32 - 1.0) * t;
    let sy = (1.0 - 2.0 * (y as f32 + 0.5) / RES as f32) * t;
    Vec3::new(sx * HEIGHT, 0.0, -sy * HEIGHT)
}

/// Compares the film (red channel) with `expected` radiance at floor points,
/// over 4x4-pixel blocks (the filter blurs single pixels): each block within
/// `block_tol` (relative, of the largest expected value) and the whole within 1%.
fn assert_matches(film: &Film, expected: impl Fn(Vec3) -> f32, block_tol: f32, what: &str) {
    let (mut sum, mut want) = (0.0f64, 0.0f64);
    let peak = (0..RES * RES).map(|i| expected(floor_point(i % RES, i / RES))).fold(0.0f32, f32::max);
    assert!(peak > 0.0, "{what}: nothing expected");
    // Skip a 2-pixel border: the filter reaches past the image edge there.
    for by in (2..RES - 2).step_by(4) {
        for bx in (2..RES - 2).step_by(4) {
            let (mut got, mut exp) = (0.0f64, 0.0f64);
            for y in by..(by + 4).min(RES - 2) {
                for x in bx..(bx + 4).min(RES - 2) {
                    got += film.rgba[(y * RES + x) as usize][0] as f64;
                    exp += expected(floor_point(x, y)) as f64;
                }
            }
            let n = 16.0;
            assert!(
                ((got - exp) / n).abs() <= (block_tol * peak) as f64,
                "{what}: block ({bx}, {by}) {:.5} vs closed form {:.5} (peak {peak:.5})",
                got / n,
                exp / n
            );
            sum += got;
            want += exp;
        }
    }
    assert!(((sum - want) / want).abs() < 0.01, "{what}: mean {sum} vs closed form {want}");
}

fn light(kind: LightKind, position: Vec3, facing: Vec3, emission: f32) -> Light {
    let world_from_light = throng::shot::look_at(position, position + facing);
    Light {
        name: "test".into(),
        kind,
        world_from_light,
        emission: Vec3::splat(emission),
        two_sided: false,
        camera_visible: false,
        light_group: None,
    }
}

fn local(lights: Vec<Light>) -> SceneLights {
    SceneLights { sun: None, sky: Sky { radiance: Vec3::ZERO }, dome: None, local: lights, groups: Default::default() }
}

/// Irradiance at a point from a parallel rectangle with one corner straight
/// above it at height d and sides a, b: pi L x the form factor
/// F = 1/(2 pi) [X/sqrt(1+X^2) atan(Y/sqrt(1+X^2)) + Y/sqrt(1+Y^2) atan(X/sqrt(1+Y^2))].
fn corner_irradiance(l: f32, a: f32, b: f32, d: f32) -> f32 {
    let (x, y) = ((a / d) as f64, (b / d) as f64);
    let f = (x / (1.0 + x * x).sqrt() * (y / (1.0 + x * x).sqrt()).atan()
        + y / (1.0 + y * y).sqrt() * (x / (1.0 + y * y).sqrt()).atan())
        / (2.0 * std::f64::consts::PI);
    (std::f64::consts::PI * l as f64 * f) as f32
}

/// A w x h rectangle centred at (cx, cz), height d, as four corner pieces
/// (signed, for points outside its footprint).
fn rect_irradiance(l: f32, p: Vec3, w: f32, h: f32, d: f32) -> f32 {
    let (x0, x1) = (-0.5 * w - p.x, 0.5 * w - p.x);
    let (z0, z1) = (-0.5 * h - p.z, 0.5 * h - p.z);
    let piece = |a: f32, b: f32| a.signum() * b.signum() * corner_irradiance(l, a.abs(), b.abs(), d);
    piece(x1, z1) - piece(x0, z1) - piece(x1, z0) + piece(x0, z0)
}

/// A 16 x 8 dome of constant `radiance`, turned by `rotate` radians.
fn constant_dome(radiance: f32, rotate: f32) -> Arc<Dome> {
    Arc::new(Dome {
        file: "constant".into(),
        width: 16,
        height: 8,
        texels: vec![Vec3::splat(radiance); 128],
        scale: Vec3::ONE,
        rotate,
        camera_visible: true,
    })
}

#[test]
fn a_constant_dome_gives_albedo_times_radiance() {
    let lights = SceneLights { dome: Some(constant_dome(2.0, 0.3)), ..local(vec![]) };
    let (lib, scene) = floor_scene(lights, vec![]);
    let film = render(&lib, &scene, 16, 2);
    assert_matches(&film, |_| ALBEDO * 2.0, 0.02, "constant dome");
}

/// Environment and local lights together (one shadow ray per vertex, to
/// the dome or the lamp, picked by what each gives the point): the dome's
/// and the lamp's irradiance add up, each as alone. 64 samples: one ray
/// where there were two leaves twice the variance per sample.
#[test]
fn a_dome_and_a_point_light_add_up() {
    let (i, h) = (30.0, 2.0);
    let p0 = Vec3::new(-0.3, h, 0.5);
    let lamp = light(LightKind::Point, p0, -Vec3::Y, i);
    let lights = SceneLights { dome: Some(constant_dome(0.5, 0.0)), ..local(vec![lamp]) };
    let (lib, scene) = floor_scene(lights, vec![]);
    let film = render(&lib, &scene, 64, 2);
    let expected = |p: Vec3| {
        let r = p0 - p;
        ALBEDO * 0.5 + ALBEDO / PI * i * h / r.length().powi(3)
    };
    assert_matches(&film, expected, 0.03, "dome + point light");
}

#[test]
fn a_point_light_falls_off_with_distance_squared_and_cosine() {
    let (i, h) = (30.0, 2.0);
    let p0 = Vec3::new(0.7, h, -0.4);
    let (lib, scene) = floor_scene(local(vec![light(LightKind::Point, p0, -Vec3::Y, i)]), vec![]);
    let film = render(&lib, &scene, 4, 2);
    let expected = |p: Vec3| {
        let r = p0 - p;
        ALBEDO / PI * i * h / r.length().powi(3)
    };
    assert_matches(&film, expected, 0.03, "point light");
}

#[test]
fn a_spot_is_a_point_inside_its_cone_and_dark_outside() {
    let (i, h) = (30.0, 2.0);
    let outer = 20f32.to_radians();
    let p0 = Vec3::new(0.0, h, 0.0);
    let spot = light(LightKind::Spot { outer, blend: 0.0 }, p0, -Vec3::Y, i);
    let (lib, scene) = floor_scene(local(vec![spot]), vec![]);
    let film = render(&lib, &scene, 4, 2);
    let (mut inside, mut outside) = (0, 0);
    for y in 0..RES {
        for x in 0..RES {
            let p = floor_point(x, y);
            let r = p0 - p;
            let angle = (r.normalize().dot(Vec3::Y)).acos();
            let got = film.rgba[(y * RES + x) as usize][0];
            // Pixels clear of the edge by more than the filter's reach.
            if angle < outer - 0.05 {
                let want = ALBEDO / PI * i * h / r.length().powi(3);
                assert!((got - want).abs() < 0.02 * want, "inside ({x}, {y}): {got} vs {want}");
                inside += 1;
            } else if angle > outer + 0.05 {
                assert_eq!(got, 0.0, "outside ({x}, {y})");
                outside += 1;
            }
        }
    }
    assert!(inside > 50 && outside > 50, "{inside} inside, {outside} outside");
}

#[test]
fn a_rect_light_gives_the_form_factor() {
    let (l, d, w, h) = (3.0, 1.5, 1.2, 0.8);
    let rect = light(LightKind::Rect { size: Vec2::new(w, h) }, Vec3::new(0.0, d, 0.0), -Vec3::Y, l);
    // look_at puts the light's local X along world X and its local Y along world -Z or +Z: the
    // rectangle's w runs along X and h along Z either way.
    let (lib, scene) = floor_scene(local(vec![rect]), vec![]);
    let film = render(&lib, &scene, 64, 2);
    assert_matches(&film, |p| ALBEDO / PI * rect_irradiance(l, p, w, h, d), 0.03, "rect light");
}

#[test]
fn an_emissive_panel_lights_like_a_rect_light_and_only_from_its_front() {
    let (l, d, size) = (3.0, 1.5, 1.0);
    let glow = Material { name: "glow".into(), base_color: Vec3::ZERO, emission: Vec3::splat(l), ..Default::default() };
    // Turned over (front face down), at height d.
    let down = Affine3A::from_rotation_translation(Quat::from_rotation_x(PI), Vec3::new(0.0, d, 0.0));
    let (lib, scene) = floor_scene(local(vec![]), vec![(quad(size), glow.clone(), down)]);
    let film = render(&lib, &scene, 64, 2);
    // The camera above sees the panel's dark back over its shadow on the
    // image (its footprint grown by HEIGHT / (HEIGHT - d)): compare around it.
    let hidden = 0.5 * size * HEIGHT / (HEIGHT - d) + 0.15;
    let outside = |p: Vec3| p.x.abs() > hidden || p.z.abs() > hidden;
    let (mut got, mut want, mut n) = (0.0f64, 0.0f64, 0);
    for y in 2..RES - 2 {
        for x in 2..RES - 2 {
            let p = floor_point(x, y);
            if outside(p) {
                got += film.rgba[(y * RES + x) as usize][0] as f64;
                want += (ALBEDO / PI * rect_irradiance(l, p, size, size, d)) as f64;
                n += 1;
            }
        }
    }
    assert!(n > 300, "{n} pixels");
    assert!(((got - want) / want).abs() < 0.02, "emissive panel: {got} vs closed form {want}");
    // Its back over the footprint is black: base colour 0, and it emits only forwards.
    let centre = film.rgba[(RES / 2 * RES + RES / 2) as usize];
    assert_eq!(centre[0], 0.0, "the panel's back");
    // Face up, it lights nothing below.
    let up = Affine3A::from_translation(Vec3::new(0.0, d, 0.0));
    let (lib, scene) = floor_scene(local(vec![]), vec![(quad(size), glow, up)]);
    let film = render(&lib, &scene, 16, 2);
    for y in 0..RES {
        for x in 0..RES {
            if outside(floor_point(x, y)) {
                assert_eq!(film.rgba[(y * RES + x) as usize][0], 0.0, "a face-up panel lights nothing below it");
            }
        }
    }
}

#[test]
fn a_sphere_light_gives_pi_l_r2_over_d2_below_it() {
    let (l, r, centre_height) = (5.0, 0.3, 2.0);
    let sphere = light(LightKind::Sphere { radius: r }, Vec3::new(0.0, centre_height, 0.0), -Vec3::Y, l);
    let (lib, scene) = floor_scene(local(vec![sphere]), vec![]);
    let film = render(&lib, &scene, 16, 2);
    // A sphere seen from p: pi L sin^2(half angle) x cos of its direction.
    let expected = |p: Vec3| {
        let d = Vec3::new(0.0, centre_height, 0.0) - p;
        ALBEDO / PI * PI * l * (r * r / d.length_squared()) * (d.normalize().y)
    };
    assert_matches(&film, expected, 0.03, "sphere light");
}

/// A small camera-visible emitter at distance `z` in front of a lens camera
/// focused at `focus`: the radius (pixels) holding its image.
fn image_radius(z: f32, focus: f32, aperture: f32) -> f32 {
    let glow = Material { name: "glow".into(), emission: Vec3::ONE, ..Default::default() };
    let size = 0.02 * z;
    // Facing the camera (front towards +Z).
    let m = Affine3A::from_rotation_translation(Quat::from_rotation_x(PI / 2.0), Vec3::new(0.0, 0.0, -z));
    let lib = Library { meshes: vec![quad(size)], materials: vec![glow], textures: vec![] };
    let mut camera = Camera::pinhole(Affine3A::IDENTITY, 20f32.to_radians());
    camera.aperture = aperture;
    camera.focus_distance = focus;
    let scene =
        FrameScene { instances: vec![instance(0, 0, m, vis::ALL)], camera, lights: local(vec![]), motion: None };
    let s = RenderSettings { width: 64, height: 64, ..settings(64, 2) };
    let film = render_frame(&BlasSet::build(&lib), &lib, &scene, &s, None).expect("render");
    let total: f32 = film.rgba.iter().map(|p| p[0]).sum();
    assert!(total > 0.0);
    // The radius holding 95% of the light, from the image centre.
    let mut by_radius: Vec<(f32, f32)> = (0..64 * 64)
        .map(|i| {
            let (x, y) = ((i % 64) as f32 + 0.5 - 32.0, (i / 64) as f32 + 0.5 - 32.0);
            ((x * x + y * y).sqrt(), film.rgba[i][0])
        })
        .collect();
    by_radius.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut acc = 0.0;
    for (r, v) in by_radius {
        acc += v;
        if acc >= 0.95 * total {
            return r;
        }
    }
    64.0
}

#[test]
fn the_thin_lens_focuses_at_its_distance_and_blurs_by_the_circle_of_confusion() {
    let (focus, aperture) = (5.0, 0.05);
    let sharp = image_radius(focus, focus, aperture);
    let pinhole = image_radius(focus, focus, 0.0);
    assert!((sharp - pinhole).abs() <= 1.0, "in focus: {sharp} px vs pinhole {pinhole} px");
    // At 2.5 m the circle of confusion at the focus plane is 2 a |z - s| / z = 0.05 m across,
    // which is 0.05 / (2 s tan(10 deg)) x 64 px = 1.81 px; at 10 m likewise 0.05 m -> 1.81 px...
    // so take 1.25 m: 2 x 0.05 x 3.75 / 1.25 = 0.3 m -> 10.9 px across, 5.4 px radius.
    let near = image_radius(1.25, focus, aperture);
    let coc_radius = 0.5 * (2.0 * aperture * (focus - 1.25) / 1.25) / (2.0 * focus * (10f32).to_radians().tan()) * 64.0;
    assert!((near - coc_radius).abs() < 1.5, "off focus: {near} px vs circle of confusion {coc_radius} px");
    assert!(near > sharp + 3.0, "blur grows off focus: {near} vs {sharp}");
}

#[test]
fn the_sunny_hdri_samples_to_the_same_mean_with_less_variance() {
    let hdri = common::shared_asset("hdri/quarry_01_1k.hdr");
    let dome = Arc::new(load_dome(&hdri, Vec3::ONE, 0.0, true).expect("the shared HDRI"));
    let sampler = DomeSampler::new(dome.clone());
    // Irradiance on an upward-facing plane: E = integral of L cos over the upper hemisphere.
    let lum = |c: Vec3| (0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z) as f64;
    // The closed form for the map as stored: every texel's radiance x cos x solid angle.
    let (w, h) = (dome.width as usize, dome.height as usize);
    let mut exact = 0.0f64;
    for y in 0..h {
        let (t0, t1) = (PI * y as f32 / h as f32, PI * (y + 1) as f32 / h as f32);
        for x in 0..w {
            let d = sampler.direction(Vec2::new((x as f32 + 0.5) / w as f32, (y as f32 + 0.5) / h as f32));
            if d.y > 0.0 {
                let solid_angle = 2.0 * PI / w as f32 * (t0.cos() - t1.cos());
                exact += lum(dome.texels[y * w + x]) * d.y as f64 * solid_angle as f64;
            }
        }
    }
    let n = 1 << 14;
    let (mut imp, mut imp2, mut uni, mut uni2) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    for k in 0..n {
        // A (0,2) sequence: Hammersley points.
        let u = Vec2::new((k as f32 + 0.5) / n as f32, (k as u32).reverse_bits() as f32 / 4294967296.0);
        let e =
            sampler.sample(u).map_or(0.0, |(d, l, pdf)| if d.y > 0.0 { lum(l) * d.y as f64 / pdf as f64 } else { 0.0 });
        imp += e;
        imp2 += e * e;
        // Uniform over the sphere.
        let z = 1.0 - 2.0 * u.x;
        let r = (1.0 - z * z).max(0.0).sqrt();
        let d = Vec3::new(r * (2.0 * PI * u.y).cos(), z, r * (2.0 * PI * u.y).sin());
        let e = if d.y > 0.0 { lum(sampler.radiance(d)) * d.y as f64 * 4.0 * std::f64::consts::PI } else { 0.0 };
        uni += e;
        uni2 += e * e;
    }
    let nf = n as f64;
    let (mi, mu) = (imp / nf, uni / nf);
    let (vi, vu) = (imp2 / nf - mi * mi, uni2 / nf - mu * mu);
    // The sun is 0.5 degrees across: uniform directions all but never find
    // it (so their mean falls short and their variance, measured, is a
    // floor); the importance-sampled mean is the closed form.
    assert!(((mi - exact) / exact).abs() < 0.01, "importance {mi} vs closed form {exact}");
    assert!(mu < exact, "uniform {mu} vs closed form {exact}");
    assert!(vi < 0.1 * vu, "variance: importance {vi} vs uniform {vu}");
}

/// A point, a spot, a rect light and an emissive panel together: the local
/// group's pick then weighs each light by what it gives the shading point
/// (render::lights), and with a bounce the BSDF rays that find the rect
/// and the panel are weighed by multiple importance sampling against that
/// pick, taken at the point they leave. The floor is their four closed
/// forms added, and 1 and 2 threads give the same image.
#[test]
fn a_point_a_spot_a_rect_and_a_panel_add_up_with_mis() {
    let (ip, hp) = (4.0, 2.0);
    let p_point = Vec3::new(-1.0, hp, -1.0);
    let (is, outer, blend) = (30.0, 0.35, 0.3);
    let p_spot = Vec3::new(1.0, 3.0, 1.0);
    let (lr, dr, wr) = (4.0, 1.2, 0.8);
    let c_rect = Vec3::new(-1.0, dr, 1.0);
    // The panel, face down, out of the camera's view (it sees 1.25 m either side at its height).
    let (lp, dp) = (6.0, 1.5);
    let c_panel = Vec3::new(2.0, dp, 0.0);
    let lights = local(vec![
        light(LightKind::Point, p_point, -Vec3::Y, ip),
        light(LightKind::Spot { outer, blend }, p_spot, -Vec3::Y, is),
        light(LightKind::Rect { size: Vec2::splat(wr) }, c_rect, -Vec3::Y, lr),
    ]);
    let glow =
        Material { name: "glow".into(), base_color: Vec3::ZERO, emission: Vec3::splat(lp), ..Default::default() };
    let down = Affine3A::from_rotation_translation(Quat::from_rotation_x(PI), c_panel);
    let (lib, scene) = floor_scene(lights, vec![(quad(1.0), glow, down)]);
    let s = |threads| RenderSettings { max_bounces: 1, ..settings(64, threads) };
    let blas = BlasSet::build(&lib);
    let film = render_frame(&blas, &lib, &scene, &s(2), None).unwrap();
    let expected = |p: Vec3| {
        let r = p_point - p;
        let point = ip * hp / r.length().powi(3);
        let r = p_spot - p;
        // Blender's edge: smoothstep over the outer `blend` of the cone, in cosines.
        let (cos, cos_outer) = (r.normalize().dot(Vec3::Y), outer.cos());
        let t = ((cos - cos_outer) / ((1.0 - cos_outer) * blend)).clamp(0.0, 1.0);
        let cone = t * t * (3.0 - 2.0 * t);
        let spot = is * cone * r.y / r.length().powi(3);
        let offset = |c: Vec3| Vec3::new(p.x - c.x, 0.0, p.z - c.z);
        let rect = rect_irradiance(lr, offset(c_rect), wr, wr, dr);
        let panel = rect_irradiance(lp, offset(c_panel), 1.0, 1.0, dp);
        ALBEDO / PI * (point + spot + rect + panel)
    };
    assert_matches(&film, expected, 0.03, "point + spot + rect + panel");
    let one = render_frame(&blas, &lib, &scene, &s(1), None).unwrap();
    assert_eq!(one.rgba, film.rgba, "1 and 2 threads");
}

#[test]
fn lit_renders_are_bit_identical_for_any_thread_count() {
    let dome = Dome {
        file: "two".into(),
        width: 8,
        height: 4,
        texels: (0..32).map(|i| Vec3::splat(0.1 + (i % 5) as f32)).collect(),
        scale: Vec3::splat(0.2),
        rotate: 0.0,
        camera_visible: true,
    };
    let lights = SceneLights {
        dome: Some(Arc::new(dome)),
        ..local(vec![
            light(LightKind::Point, Vec3::new(0.5, 1.0, 0.0), -Vec3::Y, 2.0),
            light(LightKind::Rect { size: Vec2::ONE }, Vec3::new(-0.5, 1.5, 0.0), -Vec3::Y, 1.0),
            light(LightKind::Sphere { radius: 0.2 }, Vec3::new(0.0, 1.0, 1.0), -Vec3::Y, 4.0),
        ])
    };
    let glow = Material { name: "glow".into(), emission: Vec3::new(2.0, 1.0, 0.5), ..Default::default() };
    let down = Affine3A::from_rotation_translation(Quat::from_rotation_x(PI), Vec3::new(1.0, 1.0, -1.0));
    let (lib, scene) = floor_scene(lights, vec![(quad(0.5), glow, down)]);
    let s = |threads| RenderSettings { max_bounces: 3, diffuse_only: false, ..settings(8, threads) };
    let blas = BlasSet::build(&lib);
    let a = render_frame(&blas, &lib, &scene, &s(1), None).unwrap();
    let b = render_frame(&blas, &lib, &scene, &s(2), None).unwrap();
    assert!(a.rgba.iter().any(|p| p[0] > 0.0));
    assert_eq!(a.rgba, b.rgba);
}

// ------------------------------------------------------- the shot's lights, through the CLI

mod cli {
    use std::path::Path;

    use super::common::{run, two_robots, DemoShot};

    const LOCAL: &str = r#"
[[lights.point]]
position = [1.0, 2.5, 1.0]
intensity = 6.0
color = [1.0, 0.8, 0.6]
[[lights.spot]]
name = "follow"
position = [0.0, 5.0, 3.0]
aim = [0.0, 0.0, 0.0]
intensity = 40.0
outer_angle = 20.0
inner_angle = 10.0
[[lights.rect]]
position = [-2.0, 2.0, 0.0]
direction = [1.0, -0.3, 0.0]
size = [1.0, 2.0]
intensity = 2.0
[[lights.disk]]
position = [2.0, 2.0, -1.0]
direction = [-1.0, -0.5, 0.0]
radius = 0.4
intensity = 3.0
[[lights.sphere]]
position = [0.0, 2.2, -2.0]
radius = 0.2
intensity = 5.0
camera_visible = true
"#;

    fn render(dir: &Path, lights: &str, extra: &str, colourspace: &str) -> (i32, String) {
        let shot = DemoShot { lights, extra, ..DemoShot::default() }.write(dir, &two_robots(1..=3));
        let out = dir.join("out");
        let (code, stdout, stderr) = run(&[
            "render",
            shot.to_str().unwrap(),
            "--layer",
            "full",
            "--frames",
            "1001",
            "--colourspace",
            colourspace,
            "--progress",
            "off",
            "--out",
            out.to_str().unwrap(),
        ]);
        assert!(!stderr.contains("panicked"), "{stderr}");
        (code, format!("{stdout}{stderr}"))
    }

    fn exr_files(dir: &Path) -> usize {
        walk(&dir.join("out"))
    }

    fn walk(dir: &Path) -> usize {
        let Ok(entries) = std::fs::read_dir(dir) else { return 0 };
        entries
            .flatten()
            .map(|e| {
                if e.path().is_dir() {
                    walk(&e.path())
                } else {
                    usize::from(e.path().extension().is_some_and(|x| x == "exr"))
                }
            })
            .sum()
    }

    #[test]
    fn a_shot_lit_by_the_hdri_and_every_local_light_renders() {
        for space in ["rec709", "acescg"] {
            let dir = super::common::tempdir().unwrap();
            let hdri = super::common::shared_asset("hdri/quarry_01_1k.hdr");
            let lights = format!("[lights.dome]\nfile = \"{}\"\nrotate = 30.0\n{LOCAL}", hdri.display());
            let (code, log) = render(dir.path(), &lights, "", space);
            assert_eq!(code, 0, "{log}");
            assert_eq!(exr_files(dir.path()), 1, "{log}");
        }
    }

    #[test]
    fn depth_of_field_from_the_shot_renders() {
        let dir = super::common::tempdir().unwrap();
        let extra = "[[camera.keys]]\nframe = 1003\nposition = [0.0, 1.6, 9.0]\naim = [0.0, 0.9, 0.0]\nfocal_length = 35.0\nf_stop = 2.0\nfocus_distance = 9.0";
        // The template's own key has no depth of field: every key or none.
        let (code, log) = render(dir.path(), "", extra, "rec709");
        assert_eq!(code, 2, "{log}");
        assert!(log.contains("camera.keys.f_stop") && log.contains("every key"), "{log}");
    }

    /// Writes a tiny Radiance or OpenEXR map of `w` x `h` texels of `value`.
    fn write_map(path: &Path, w: usize, h: usize, value: f32) {
        if path.extension().is_some_and(|e| e == "exr") {
            exr::prelude::write_rgb_file(path, w, h, |_, _| (value, value, value)).unwrap();
        } else {
            let file = std::fs::File::create(path).unwrap();
            let px = vec![image::Rgb([value; 3]); w * h];
            image::codecs::hdr::HdrEncoder::new(file).encode(&px, w, h).unwrap();
        }
    }

    #[test]
    fn bad_lights_exit_2_naming_file_light_and_field_and_write_nothing() {
        let cases: Vec<(String, &str)> = vec![
            ("[lights.dome]\nfile = \"missing.hdr\"".into(), "lights.dome.file"),
            ("[lights.dome]\nfile = \"tall.hdr\"".into(), "twice as wide"),
            ("[lights.dome]\nfile = \"negative.exr\"".into(), "lights.dome.file"),
            ("[lights.dome]\nfile = \"flat.hdr\"\nintensity = 0.0".into(), "lights.dome.intensity"),
            (
                "[[lights.rect]]\nposition = [0.0, 2.0, 0.0]\nsize = [1.0, 0.0]\nintensity = 1.0".into(),
                "lights.rect[0].size",
            ),
            (
                "[[lights.sphere]]\nposition = [0.0, 2.0, 0.0]\nradius = -0.5\nintensity = 1.0".into(),
                "lights.sphere[0].radius",
            ),
            ("[[lights.point]]\nposition = [0.0, 2.0, 0.0]\nintensity = -3.0".into(), "lights.point[0].intensity"),
            (
                "[[lights.spot]]\nposition = [0.0, 2.0, 0.0]\nintensity = 1.0\ninner_angle = 30.0\nouter_angle = 20.0"
                    .into(),
                "out of order",
            ),
        ];
        for (lights, field) in cases {
            let dir = super::common::tempdir().unwrap();
            write_map(&dir.path().join("tall.hdr"), 4, 4, 1.0);
            write_map(&dir.path().join("flat.hdr"), 8, 4, 1.0);
            write_map(&dir.path().join("negative.exr"), 8, 4, -1.0);
            let (code, log) = render(dir.path(), &lights, "", "rec709");
            assert_eq!(code, 2, "{lights}\n{log}");
            assert!(log.contains(field), "{lights}\n -> {log}");
            assert_eq!(exr_files(dir.path()), 0, "{lights}: nothing written");
        }
        // An f-stop of 0 on a key.
        let dir = super::common::tempdir().unwrap();
        let extra = "[[camera.keys]]\nframe = 1003\nposition = [0.0, 1.6, 9.0]\naim = [0.0, 0.9, 0.0]\nfocal_length = 35.0\nf_stop = 0.0\nfocus_distance = 9.0";
        let (code, log) = render(dir.path(), "", extra, "rec709");
        assert_eq!(code, 2, "{log}");
        assert!(log.contains("camera.keys.f_stop") && log.contains("> 0"), "{log}");
        assert_eq!(exr_files(dir.path()), 0);
    }
}

/// A farm task names the shot by another path than a local render (absolute
/// against relative): the dome's texels are fingerprinted, not its path, so
/// `--resume` and the farm's byte-identity hold for a dome-lit shot.
#[test]
fn the_render_fingerprint_does_not_depend_on_how_the_shot_is_named() {
    use throng::casting::ShotCrowd;
    use throng::render::job::{render_fingerprint, RenderJob};
    let root = common::repo_path("demo/shot.toml");
    let detour = common::repo_path("demo/../demo/shot.toml");
    let fingerprint = |shot: &std::path::Path| {
        let crowd = ShotCrowd::load(shot).expect("the demo loads");
        assert!(crowd.shot().lights.dome.is_some(), "the demo is lit by a dome");
        let job = RenderJob::new(vec!["full".into()], vec![1024], 1, std::env::temp_dir());
        render_fingerprint(&crowd, None, &job, "full")
    };
    assert_eq!(fingerprint(&root), fingerprint(&detour));
}

/// Passes: the light-path passes and the light groups each add up to the
/// beauty on every pixel (to f32 rounding: 1e-5 of the pixel's light plus
/// 1e-6), with bounces, glossy floors, a dome and two lamps in groups of
/// their own; and a group holds its own light only.
#[test]
fn passes_and_light_groups_add_up_to_the_beauty() {
    let mut a = light(LightKind::Point, Vec3::new(-0.3, 2.0, 0.5), -Vec3::Y, 30.0);
    a.name = "lamp a".into();
    let mut b = light(LightKind::Point, Vec3::new(0.6, 1.5, -0.2), -Vec3::Y, 20.0);
    b.light_group = Some("key".into());
    let lights = SceneLights { dome: Some(constant_dome(0.5, 0.0)), ..local(vec![a, b]) };
    let (lib, scene) = floor_scene(lights, vec![]);
    let mut s = settings(8, 2);
    (s.max_bounces, s.diffuse_only, s.sky_visible, s.indirect_clamp) = (3, false, true, 10.0);
    s.passes = throng::scene::passes::PassSet::all();
    let film = render_frame(&BlasSet::build(&lib), &lib, &scene, &s, None).expect("render");
    let names: Vec<&str> = film.passes.iter().map(|p| p.name.as_str()).collect();
    assert!(names.contains(&"diffuse_direct") && names.contains(&"environment") && names.contains(&"P"), "{names:?}");
    assert!(names.contains(&"lg_dome") && names.contains(&"lg_lamp_a") && names.contains(&"lg_key"), "{names:?}");
    let paths: Vec<_> = film.passes.iter().filter(|p| LightPath::ALL.iter().any(|l| l.name() == p.name)).collect();
    let groups: Vec<_> = film.passes.iter().filter(|p| p.name.starts_with("lg_")).collect();
    assert_eq!(paths.len(), LightPath::ALL.len());
    for i in 0..film.rgba.len() {
        let beauty = Vec3::from_slice(&film.rgba[i][..3]);
        for family in [&paths, &groups] {
            let sum: Vec3 = family.iter().map(|p| Vec3::from(p.data[i])).sum();
            let size: f32 = family.iter().map(|p| Vec3::from(p.data[i]).abs().max_element()).sum();
            assert!((sum - beauty).abs().max_element() <= 1e-5 * size + 1e-6, "pixel {i}: {sum} vs {beauty}");
        }
    }
    let pass = |n: &str| film.passes.iter().find(|p| p.name == n).unwrap();
    let total = |n: &str| pass(n).data.iter().map(|v| Vec3::from(*v).x as f64).sum::<f64>();
    // Every pass that should hold light does; the floor has no glass.
    for n in ["diffuse_direct", "specular_direct", "lg_dome", "lg_lamp_a", "lg_key"] {
        assert!(total(n) > 0.0, "{n} is empty");
    }
    // A lone plane sees no other surface: no light comes back to it by a bounce.
    for n in ["diffuse_indirect", "specular_indirect", "transmission"] {
        assert_eq!(total(n), 0.0, "{n}");
    }
    // The camera looks down at the floor only: no environment seen, P on the floor.
    assert_eq!(total("environment"), 0.0);
    assert!(pass("P").data.iter().all(|p| p[1].abs() < 1e-4));
    // Beauty is the same with passes off.
    s.passes = Default::default();
    let plain = render_frame(&BlasSet::build(&lib), &lib, &scene, &s, None).expect("render");
    assert_eq!(plain.rgba, film.rgba);
    assert!(plain.passes.is_empty());
}

/// The shadow pass: a set surface's direct light that only the crowd
/// blocks. With one bounce off (light sampling alone, no MIS), each sample's
/// lost light is what the same sample gets once the agent is gone, so the
/// beauty plus the shadow pass is the render without the agent, pixel by
/// pixel (to f32 rounding); where the set itself shadows, nothing is lost
/// to the crowd; and the beauty is the same with the pass on.
#[test]
fn the_shadow_pass_is_the_light_the_crowd_took_from_the_set() {
    let point = light(LightKind::Point, Vec3::new(0.0, 3.0, 0.0), -Vec3::Y, 40.0);
    let rect = light(LightKind::Rect { size: Vec2::new(1.0, 0.5) }, Vec3::new(0.8, 2.5, 0.4), -Vec3::Y, 15.0);
    let grey = || Material { name: "blocker".into(), base_color: Vec3::splat(0.3), ..Default::default() };
    // An agent's part (a shadow caster only, as in the set layer) and a
    // piece of set overlapping its shadow.
    let agent = (quad(0.8), grey(), Affine3A::from_translation(Vec3::new(-0.2, 1.0, 0.0)));
    let set_piece = (quad(0.5), grey(), Affine3A::from_translation(Vec3::new(0.3, 1.5, 0.3)));
    let (lib, mut with) = floor_scene(local(vec![point, rect]), vec![agent, set_piece]);
    with.instances[1].agent = InstanceAgent::some(7);
    with.instances[1].visibility = vis::SHADOW;
    with.instances[2].visibility = vis::SHADOW;
    let mut without = with.clone();
    without.instances[1].visibility = 0;
    let mut s = settings(4, 2);
    s.passes = throng::scene::passes::PassSet::parse(&["shadow"], "render.passes").unwrap();
    let blas = BlasSet::build(&lib);
    let film = render_frame(&blas, &lib, &with, &s, None).expect("render");
    let shadow = &film.passes.iter().find(|p| p.name == "shadow").expect("a shadow pass").data;
    let clear = render_frame(&blas, &lib, &without, &s, None).expect("render");
    let (mut lost, mut pixels_in_shadow) = (0.0f64, 0);
    for (i, (px, lost_here)) in film.rgba.iter().zip(shadow).enumerate() {
        let beauty = Vec3::from_slice(&px[..3]);
        let unshadowed = Vec3::from_slice(&clear.rgba[i][..3]);
        let s = Vec3::from(*lost_here);
        assert!(s.min_element() >= 0.0, "pixel {i}: negative shadow {s}");
        assert!(
            (beauty + s - unshadowed).abs().max_element() <= 1e-5 * unshadowed.max_element() + 1e-6,
            "pixel {i}: beauty {beauty} + shadow {s} vs without the agent {unshadowed}"
        );
        lost += s.x as f64;
        pixels_in_shadow += (s.x > 0.0) as usize;
    }
    assert!(lost > 0.0 && pixels_in_shadow > 20, "the agent's shadow is in the pass ({pixels_in_shadow} pixels)");
    // The set piece's own shadow stays in the beauty: with the agent gone
    // too, the pass is empty and the beauty still darker under the piece.
    let empty = render_frame(&blas, &lib, &without, &s, None).expect("render");
    assert!(empty.passes[0].data.iter().all(|v| *v == [0.0; 3]), "no crowd, no crowd shadow");
    s.passes = Default::default();
    assert_eq!(render_frame(&blas, &lib, &with, &s, None).expect("render").rgba, film.rgba);
}

/// Adaptive sampling (docs/render.md, "Adaptive sampling"): every pixel
/// takes between min_spp and max_spp samples, in passes whose totals are
/// multiples of 4, the soft shadow's penumbra more than the flat floor; the
/// passes read the tile's own samples, so the image is bit-identical for any
/// thread count, and a pixel that took n samples equals the fixed n-sample
/// render's pixel, bit for bit.
#[test]
fn adaptive_sampling_spends_samples_where_the_pooled_variance_is() {
    let rect = light(LightKind::Rect { size: Vec2::new(1.5, 1.5) }, Vec3::new(0.0, 2.0, 0.0), -Vec3::Y, 8.0);
    let grey = Material { name: "blocker".into(), base_color: Vec3::splat(0.3), ..Default::default() };
    let blocker = (quad(1.0), grey, Affine3A::from_translation(Vec3::new(0.4, 1.0, 0.0)));
    let (lib, scene) = floor_scene(local(vec![rect]), vec![blocker]);
    let blas = BlasSet::build(&lib);
    let (min, max) = (4, 64);
    let mut s = settings(1, 1);
    // The threshold bounds sqrt(pooled variance) / n (docs/render.md).
    const THRESHOLD: f32 = 0.02;
    s.adaptive = Some(throng::shot::Adaptive { threshold: THRESHOLD, min_spp: min, max_spp: max });
    let one = render_frame(&blas, &lib, &scene, &s, None).expect("render");
    s.threads = 2;
    let two = render_frame(&blas, &lib, &scene, &s, None).expect("render");
    assert_eq!((&one.rgba, &one.samples), (&two.rgba, &two.samples), "thread count changed the image");
    let n = &one.samples;
    assert_eq!(n.len(), one.rgba.len());
    assert!(n.iter().all(|&k| (min..=max).contains(&k) && (k == min || k % 4 == 0)), "{n:?}");
    let fewest = *n.iter().min().unwrap();
    let most = *n.iter().max().unwrap();
    assert!(most > 4 * fewest, "noisy pixels sample longer: {fewest} to {most}");
    let mut sorted = n.clone();
    sorted.sort();
    assert!(sorted[sorted.len() / 2] <= max / 2, "most pixels stop early: median {}", sorted[sorted.len() / 2]);
    for k in [fewest, most] {
        let fixed = render_frame(&blas, &lib, &scene, &RenderSettings { spp: k, adaptive: None, ..s.clone() }, None)
            .expect("render");
        assert!(fixed.samples.is_empty());
        let matched = (0..n.len()).filter(|&i| n[i] == k).inspect(|&i| assert_eq!(one.rgba[i], fixed.rgba[i])).count();
        assert!(matched > 0);
    }
    // With every pass and deep samples gathered, the same counts, and a
    // pixel's passes and deep samples are the fixed render's of its count
    // (each kept between the passes of its tile).
    use throng::render::film::{render_frame_deep, DeepRequest};
    s.passes = throng::scene::passes::PassSet::all();
    let request = DeepRequest { settings: Default::default(), names: None };
    let deep_render = |s: &RenderSettings| {
        let (film, deep, _) = render_frame_deep(&blas, &lib, &scene, s, None, Some(&request), None).expect("render");
        (film, deep.expect("a deep image"))
    };
    let (all, deep) = deep_render(&s);
    assert_eq!((&all.rgba, &all.samples), (&one.rgba, &one.samples), "passes changed the beauty or the counts");
    let (fixed, fixed_deep) = deep_render(&RenderSettings { spp: most, adaptive: None, ..s.clone() });
    let (ours, theirs): (Vec<_>, Vec<_>) = (deep.pixels().collect(), fixed_deep.pixels().collect());
    assert!(ours.iter().all(|p| !p.is_empty()), "every pixel sees the floor");
    for i in (0..n.len()).filter(|&i| n[i] == most) {
        for (p, q) in all.passes.iter().zip(&fixed.passes) {
            assert_eq!(p.data[i], q.data[i], "pixel {i}, pass {}", p.name);
        }
        assert_eq!(ours[i], theirs[i], "pixel {i}: deep samples");
    }
    s.passes = Default::default();
    // Bad keys are refused by name.
    s.adaptive = Some(throng::shot::Adaptive { threshold: f32::NAN, min_spp: 4, max_spp: 8 });
    let e = render_frame(&blas, &lib, &scene, &s, None).unwrap_err().to_string();
    assert!(e.contains("render.adaptive.threshold"), "{e}");
    s.adaptive = Some(throng::shot::Adaptive { threshold: 0.1, min_spp: 16, max_spp: 8 });
    let e = render_frame(&blas, &lib, &scene, &s, None).unwrap_err().to_string();
    assert!(e.contains("render.adaptive.min_spp") && e.contains("above max_spp"), "{e}");
}

/// A light of huge but finite strength (each of the sun, a point, a rect, an
/// emissive panel and the dome at `strength`) renders an all-finite image
/// brighter than the same scene without it: no light's power overflows the
/// pick's sums nor its samples (issue 49).
fn huge_light_renders_finite_and_brighter(strength: f32) {
    let dim = || SceneLights { sky: Sky { radiance: Vec3::splat(0.2) }, ..local(vec![]) };
    let mean = |film: &Film| {
        assert!(film.rgba.iter().all(|p| p.iter().all(|c| c.is_finite())), "{strength}: a pixel is not finite");
        film.rgba.iter().map(|p| p[0] as f64).sum::<f64>() / film.rgba.len() as f64
    };
    let (lib, scene) = floor_scene(dim(), vec![]);
    let without = mean(&render(&lib, &scene, 4, 2));
    let sun = throng::scene::Sun { direction: Vec3::Y, angular_diameter: 0.0093, irradiance: Vec3::splat(strength) };
    let glow =
        Material { name: "glow".into(), base_color: Vec3::ZERO, emission: Vec3::splat(strength), ..Default::default() };
    let down = Affine3A::from_rotation_translation(Quat::from_rotation_x(PI), Vec3::new(3.0, 1.0, 0.0));
    let dome = Arc::new(Dome { scale: Vec3::splat(strength), ..(*constant_dome(1.0, 0.0)).clone() });
    type Case = (&'static str, SceneLights, Vec<(Mesh, Material, Affine3A)>);
    let cases: Vec<Case> = vec![
        ("sun", SceneLights { sun: Some(sun), ..dim() }, vec![]),
        (
            "point",
            SceneLights { local: vec![light(LightKind::Point, Vec3::new(0.3, 2.0, 0.0), -Vec3::Y, strength)], ..dim() },
            vec![],
        ),
        (
            "rect",
            SceneLights {
                local: vec![light(
                    LightKind::Rect { size: Vec2::splat(0.5) },
                    Vec3::new(0.0, 2.0, 0.0),
                    -Vec3::Y,
                    strength,
                )],
                ..dim()
            },
            vec![],
        ),
        ("emissive panel", dim(), vec![(quad(0.5), glow, down)]),
        ("dome", SceneLights { dome: Some(dome), ..dim() }, vec![]),
    ];
    for (what, lights, extra) in cases {
        let (lib, scene) = floor_scene(lights, extra);
        let with = mean(&render(&lib, &scene, 4, 2));
        assert!(with > without, "{what} of {strength}: mean {with} is not brighter than {without} without it");
    }
}

#[test]
fn a_light_of_huge_but_finite_strength_renders_finite_and_brighter() {
    huge_light_renders_finite_and_brighter(1e30);
}
