//! Motion blur and motion vectors (docs/render.md, "Motion blur"): an
//! analytic coverage case, a still scene identical with and without a
//! shutter, motion vectors of known translations, thread-count determinism,
//! deformation blur of skinned agents, the layer stack matching the full
//! render with blur on, sub-frame agents, and the shutter's checks. The
//! blurred golden image is in tests/golden.rs.

mod common;

use std::path::Path;

use glam::{Affine3A, Vec2, Vec3};
use throng::casting::motion::MotionFrame;
use throng::casting::ShotCrowd;
use throng::render::accel::BlasSet;
use throng::render::film::{render_frame, Film};
use throng::render::job::{self, RenderJob};
use throng::render::RenderSettings;
use throng::scene::{
    lights::SceneLights, vis, Camera, FrameScene, Instance, InstanceAgent, InstanceMotion, Library, Material, Mesh,
    SceneMotion, Sky,
};

// ---------------------------------------------------------------- fixtures

/// A square facing +Z in the z = 0 plane, 1 on a side, centred on the origin.
fn square() -> Mesh {
    let positions = vec![
        Vec3::new(-0.5, -0.5, 0.0),
        Vec3::new(0.5, -0.5, 0.0),
        Vec3::new(0.5, 0.5, 0.0),
        Vec3::new(-0.5, 0.5, 0.0),
    ];
    Mesh {
        name: "square".into(),
        normals: vec![Vec3::Z; 4],
        positions,
        indices: vec![0, 1, 2, 0, 2, 3],
        uvs: vec![],
        tangents: vec![],
    }
}

fn library() -> Library {
    Library {
        meshes: vec![square()],
        materials: vec![Material { name: "grey".into(), base_color: Vec3::splat(0.5), ..Default::default() }],
        textures: vec![],
    }
}

/// Image 64 x 32; the camera at z = 10 sees 8 x 4 units of the z = 0 plane:
/// 8 pixels per unit, world x = (px - 32) / 8, world y = (16 - py) / 8.
const W: u32 = 64;
const H: u32 = 32;
const PX_PER_UNIT: f32 = 8.0;

fn camera() -> Camera {
    Camera::pinhole(Affine3A::from_translation(Vec3::new(0.0, 0.0, 10.0)), 2.0 * 0.2f32.atan())
}

fn settings(spp: u32, threads: usize) -> RenderSettings {
    RenderSettings {
        width: W,
        height: H,
        spp,
        max_bounces: 1,
        seed: 9,
        frame: 1001,
        layer: 0,
        sky_visible: false,
        threads,
        ..Default::default()
    }
}

fn square_at(x: f32, y: f32) -> Instance {
    Instance {
        mesh: 0,
        material: 0,
        world_from_object: Affine3A::from_translation(Vec3::new(x, y, 0.0)),
        agent: InstanceAgent::some(7),
        part: 0,
        visibility: vis::ALL,
    }
}

/// One square moving from `from` at shutter open to `to` at close over a
/// shutter of `shutter` frames.
fn moving_square(from: Vec2, to: Vec2, shutter: [f32; 2]) -> FrameScene {
    let inst = square_at(from.x, from.y);
    let close = Affine3A::from_translation(to.extend(0.0));
    FrameScene {
        instances: vec![inst],
        camera: camera(),
        lights: SceneLights::sun_and_sky(None, Sky { radiance: Vec3::ONE }),
        motion: Some(SceneMotion {
            shutter,
            instances: vec![InstanceMotion { world_from_object_close: close, deform: None }],
            camera: [camera(); 2],
        }),
    }
}

fn render(scene: &FrameScene, s: &RenderSettings) -> Film {
    let lib = library();
    let blas = BlasSet::build(&lib);
    render_frame(&blas, &lib, scene, s, None).expect("renders")
}

fn world_x(px: u32) -> f32 {
    (px as f32 + 0.5 - W as f32 / 2.0) / PX_PER_UNIT
}

// ---------------------------------------------------------------- analytic

/// A unit square sweeps from x = -1 to x = +1 over the shutter across an
/// empty background. A point at x is covered while |x - c(t)| <= 0.5 with
/// c(t) = -1 + 2t, i.e. for a fraction of the shutter
/// f(x) = clamp((1.5 - |x|) / 2, 0, 0.5): each pixel's alpha (coverage) must
/// be that fraction, within noise. The pixel filter (radius 1.5 px) averages
/// f over its footprint, which is the centre value wherever f is linear
/// there, so pixels within 1.5 px of a kink of f are left out.
#[test]
fn coverage_is_the_fraction_of_the_shutter_covered() {
    let scene = moving_square(Vec2::new(-1.0, 0.0), Vec2::new(1.0, 0.0), [-0.25, 0.25]);
    let film = render(&scene, &settings(256, 0));
    let expected = |x: f32| ((1.5 - x.abs()) / 2.0).clamp(0.0, 0.5);
    let kinks = [-1.5f32, -0.5, 0.5, 1.5];
    let (mut checked, mut worst, mut sum_err) = (0, 0.0f32, 0.0f64);
    for y in 13..19 {
        // Rows within 0.4 units of y = 0: inside the square's height.
        for x in 0..W {
            let wx = world_x(x);
            if kinks.iter().any(|k| (wx - k).abs() * PX_PER_UNIT < 1.6) {
                continue;
            }
            let a = film.rgba[film.index(x, y)][3];
            let err = a - expected(wx);
            worst = worst.max(err.abs());
            sum_err += err as f64;
            checked += 1;
        }
    }
    let mean_err = sum_err / checked as f64;
    eprintln!("{checked} pixels: worst |alpha - fraction| {worst:.4}, mean error {mean_err:+.5}");
    assert!(checked > 200);
    assert!(worst < 0.04, "a pixel's coverage is off by {worst}");
    assert!(mean_err.abs() < 0.004, "coverage is biased by {mean_err}");
    // The still square at the middle of the shutter covers |x| <= 0.5 fully.
    let mut still = scene.clone();
    still.motion = None;
    still.instances[0] = square_at(0.0, 0.0);
    let film = render(&still, &settings(16, 0));
    assert_eq!(film.rgba[film.index(32, 16)][3], 1.0);
    assert_eq!(film.rgba[film.index(2, 16)][3], 0.0);
}

/// A scene where nothing moves renders the same bits with and without a
/// shutter (the ray time comes from a stream of its own), and its motion
/// vectors are zero.
#[test]
fn a_still_scene_renders_identically_with_and_without_a_shutter() {
    let blurred = moving_square(Vec2::ZERO, Vec2::ZERO, [-0.25, 0.25]);
    let mut still = blurred.clone();
    still.motion = None;
    let s = RenderSettings { max_bounces: 3, sky_visible: true, ..settings(8, 2) };
    let (a, b) = (render(&still, &s), render(&blurred, &s));
    assert!(a.motion.is_empty(), "no motion pass without a shutter");
    assert_eq!(b.motion.len(), a.rgba.len());
    assert!(b.motion.iter().all(|m| *m == [0.0, 0.0]), "zero where nothing moves");
    assert_eq!(a.rgba, b.rgba);
    assert_eq!(a.z, b.z);
    assert_eq!(a.normal, b.normal);
    assert_eq!(a.albedo, b.albedo);
    assert_eq!(a.agent_id, b.agent_id);
}

/// Motion vectors of known translations: a square moving 2 units right over
/// a half-frame shutter moves 4 units = 32 px per frame (+u); one moving up
/// has +v (Nuke's convention, y up) and one moving left -u.
#[test]
fn motion_vectors_of_a_translation_are_its_pixels_per_frame() {
    for (to, expect) in [
        (Vec2::new(2.0, 0.0), Vec2::new(32.0, 0.0)),
        (Vec2::new(-1.0, 0.0), Vec2::new(-16.0, 0.0)),
        (Vec2::new(0.0, 0.5), Vec2::new(0.0, 8.0)),
    ] {
        let scene = moving_square(Vec2::ZERO, to, [-0.25, 0.25]);
        let film = render(&scene, &settings(4, 0));
        let mut hits = 0;
        for i in 0..film.rgba.len() {
            if film.agent_id[i] == 8 {
                let m = Vec2::from(film.motion[i]);
                assert!((m - expect).length() < 1e-3, "pixel {i}: {m} not {expect}");
                hits += 1;
            } else {
                assert_eq!(film.motion[i], [0.0, 0.0], "zero where nothing was hit");
            }
        }
        assert!(hits > 20, "{hits} pixels saw the square");
    }
}

/// A camera panning over a still square gives the square (and the shutter
/// length) the camera's motion.
#[test]
fn camera_motion_gives_motion_vectors() {
    let mut scene = moving_square(Vec2::ZERO, Vec2::ZERO, [0.0, 0.5]);
    let mut moved = camera();
    moved.world_from_camera.translation.x += 1.0; // the camera moves right: the image moves left
    if let Some(m) = &mut scene.motion {
        m.camera = [camera(), moved];
    }
    let film = render(&scene, &settings(4, 0));
    let i = film.index(32, 16);
    let m = Vec2::from(film.motion[i]);
    assert!((m - Vec2::new(-16.0, 0.0)).length() < 1e-2, "{m}");
}

#[test]
fn blurred_renders_are_bit_identical_for_any_thread_count() {
    let scene = moving_square(Vec2::new(-1.0, 0.3), Vec2::new(1.0, -0.2), [-0.25, 0.25]);
    let a = render(&scene, &settings(8, 1));
    let b = render(&scene, &settings(8, 3));
    assert_eq!(a, b);
}

// ---------------------------------------------------------------- casting

/// The demo cast and posed for `shutter`.
fn demo(shutter: [f32; 2]) -> ShotCrowd {
    let shot = throng::shot::Shot::load(&common::demo_shot()).expect("demo loads");
    ShotCrowd::open(shot, Some(shutter)).expect("demo casts")
}

/// The demo's agents move over the shutter; those walking keep their feet:
/// the frame-centre sample of a sub-frame sampled agent is its cache record.
#[test]
fn demo_agents_move_over_the_shutter() {
    let crowd = demo([-0.25, 0.25]);
    let m = MotionFrame::new(&crowd, 1024, [-0.25, 0.25]).expect("motion frame");
    assert!(throng::casting::motion::moves(&m));
    let skinned_deforming = m.agents.iter().filter(|(_, a)| a.deform.is_some()).count();
    eprintln!("{} agents, {skinned_deforming} skinned agents deform over the shutter", m.agents.len());
    assert!(skinned_deforming > 0, "skinned agents deformation-blur");
    // Every pose a shutter sample needs was posed: no agent loses a piece.
    let manifest = throng::layers::build_layers(&crowd, &Default::default()).unwrap();
    let scene = job::motion_scene(&crowd, Some(&manifest), "full", &m).unwrap();
    let still =
        job::frame_scene(&crowd, Some(&manifest), "full", &job::PosedFrame::new(&crowd, 1024).unwrap()).unwrap();
    assert_eq!(scene.instances.len(), still.instances.len());
    let motion = scene.motion.as_ref().unwrap();
    let deforming = motion.instances.iter().filter(|i| i.deform.is_some()).count();
    assert!(deforming > 0);
    // Agents hold their ids and parts; the set does not move.
    for (a, b) in scene.instances.iter().zip(&still.instances) {
        assert_eq!((a.agent, a.part, a.material, a.visibility), (b.agent, b.part, b.material, b.visibility));
    }
    for (inst, k) in scene.instances.iter().zip(&motion.instances).filter(|(i, _)| i.agent.get().is_none()) {
        assert_eq!(inst.world_from_object, k.world_from_object_close);
    }
}

/// Skinned characters (RiggedFigure) blur: deforming meshes render, and the
/// blurred render differs from the still one while staying bit-identical
/// across thread counts.
#[test]
fn skinned_agents_deformation_blur() {
    let dir = common::tempdir().unwrap();
    let shot = common::figure_shot(dir.path(), &common::five_walkers(), "pose_step = 1.0");
    let crowd = ShotCrowd::open(throng::shot::Shot::load(&shot).unwrap(), Some([-0.25, 0.25])).unwrap();
    let manifest = throng::layers::build_layers(&crowd, &Default::default()).unwrap();
    let m = MotionFrame::new(&crowd, 1023, [-0.25, 0.25]).unwrap();
    assert!(m.agents.iter().any(|(_, a)| a.deform.is_some()));
    let run = |threads: usize, shutter: Option<[f32; 2]>, out: &Path| {
        let job =
            RenderJob { threads, shutter, ..RenderJob::new(vec!["full".into()], vec![1023], 8, out.to_path_buf()) };
        let done = job::run(&crowd, Some(&manifest), &job, &job::Silent).unwrap().layers;
        throng::render::exr::read_layer(&done[0].path).unwrap().0
    };
    let a = run(1, Some([-0.25, 0.25]), &dir.path().join("a"));
    let b = run(2, Some([-0.25, 0.25]), &dir.path().join("b"));
    let still = run(2, None, &dir.path().join("s"));
    assert_eq!(a, b);
    assert_ne!(a.rgba, still.rgba);
    let moving = a.motion.iter().filter(|m| m[0] != 0.0 || m[1] != 0.0).count();
    assert!(moving > 20, "{moving} pixels have motion vectors");
}

// ---------------------------------------------------------------- comp

fn lum(p: &[f32; 4]) -> f64 {
    (0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2]) as f64
}

/// With blur on, the demo's set and crowd layers stacked back together
/// match a single blurred full render within noise (noise estimated from a
/// second full render with another seed), like tests/comp.rs without blur;
/// motion vectors and ids carry through the comp.
#[test]
fn blurred_stack_matches_blurred_full_render() {
    let dir = common::tempdir().unwrap();
    let shutter = [-0.25, 0.25];
    let crowd = demo(shutter);
    let manifest = throng::layers::build_layers(&crowd, &Default::default()).unwrap();
    let frame = 1024;
    let render = |crowd: &ShotCrowd, layers: Vec<String>, out: &Path| {
        let job = RenderJob {
            shutter: Some(shutter),
            resolution: Some([160, 90]),
            ..RenderJob::new(layers, vec![frame], 32, out.to_path_buf())
        };
        job::run(crowd, Some(&manifest), &job, &job::Silent).unwrap();
    };
    let mut layers = job::all_layers(&manifest);
    layers.push("full".into());
    render(&crowd, layers, &dir.path().join("a"));
    let crowd = crowd.with_shot(|shot| shot.seed += 1).unwrap();
    render(&crowd, vec!["full".into()], &dir.path().join("b"));
    let read = |d: &str, l: &str| {
        throng::render::exr::read_layer(&throng::output::layer_path(&dir.path().join(d), "demo", l, frame)).unwrap().0
    };
    let films: Vec<Film> = job::all_layers(&manifest).iter().map(|l| read("a", l)).collect();
    let stack = throng::comp::over(&films.iter().collect::<Vec<_>>()).unwrap();
    let (full_a, full_b) = (read("a", "full"), read("b", "full"));
    assert_eq!(stack.motion.len(), stack.rgba.len(), "the comp carries the motion vectors");
    let n = stack.rgba.len();
    // Per 16x16 block and overall: stack - full within noise (+2% of the level at edges, as tests/comp.rs).
    let stats = |px: &[usize]| {
        let k = px.len() as f64;
        let mean = px.iter().map(|&i| lum(&stack.rgba[i]) - lum(&full_a.rgba[i])).sum::<f64>() / k;
        let var: f64 = px.iter().map(|&i| (lum(&full_a.rgba[i]) - lum(&full_b.rgba[i])).powi(2) / 2.0).sum();
        let level = px.iter().map(|&i| lum(&full_a.rgba[i])).sum::<f64>() / k;
        (mean, (2.0 * var).sqrt() / k + 1e-4, level)
    };
    let all: Vec<usize> = (0..n).collect();
    let (m, se, level) = stats(&all);
    eprintln!("whole image: stack - full {m:+.5} (se {se:.5}, {:.2} sigma, level {level:.4})", m / se);
    // Within noise, and any bias under 1 % of the level beyond two standard
    // errors (one light sample per vertex leaves about 1 % noise here).
    assert!((m / se).abs() < 4.0 && (m.abs() - 2.0 * se) / level < 0.01);
    let mut worst = 0.0f64;
    for by in (0..90).step_by(16) {
        for bx in (0..160).step_by(16) {
            let px: Vec<usize> =
                (by..(by + 16).min(90)).flat_map(|y| (bx..(bx + 16).min(160)).map(move |x| y * 160 + x)).collect();
            let (m, se, level) = stats(&px);
            worst = worst.max((m.abs() - 0.02 * level).max(0.0) / se);
            assert!(m.abs() < 5.0 * se + 0.02 * level, "block ({bx},{by}): {m:+.5} se {se:.5} level {level:.4}");
        }
    }
    eprintln!("worst block beyond the edge allowance: {worst:.2} sigma");
    let same = (0..n).filter(|&i| stack.agent_id[i] == full_a.agent_id[i]).count();
    assert!(same as f64 > 0.9 * n as f64, "agent ids agree on {same} of {n} pixels");
    let moving = (0..n).filter(|&i| stack.motion[i] != [0.0, 0.0]).count();
    assert!(moving > n / 2, "the moving camera gives vectors nearly everywhere ({moving} of {n})");
}

// ---------------------------------------------------------------- input

/// The pose library is built for its shutter: the shutter's steps are posed
/// after every still mesh (which keeps its id and geometry), and a render
/// refuses to blur a crowd posed for no shutter or another one.
#[test]
fn the_render_takes_a_crowd_posed_for_its_shutter() {
    let still = ShotCrowd::load(&common::demo_shot()).expect("demo loads");
    let shutter = [-0.25, 0.25];
    let blurred = demo(shutter);
    assert_eq!((still.poses().shutter(), blurred.poses().shutter()), (None, Some(shutter)));
    let (s, b) = (still.library(), blurred.library());
    // (The demo's still frames already take most steps its shutter keys need.)
    assert!(b.meshes.len() >= s.meshes.len());
    for (x, y) in s.meshes.iter().zip(&b.meshes) {
        assert_eq!((&x.name, &x.positions, &x.indices), (&y.name, &y.positions, &y.indices));
    }
    assert!(blurred.poses().skins().step_count() >= still.poses().skins().step_count());
    let dir = common::tempdir().unwrap();
    let job = RenderJob {
        shutter: Some(shutter),
        resolution: Some([16, 9]),
        ..RenderJob::new(vec!["full".into()], vec![1024], 1, dir.path().to_path_buf())
    };
    let err = job::run(&still, None, &job, &job::Silent).unwrap_err().to_string();
    assert!(err.contains("shutter"), "{err}");
    let other = RenderJob { shutter: Some([0.0, 0.5]), ..job.clone() };
    assert!(job::run(&blurred, None, &other, &job::Silent).is_err());
    assert!(!dir.path().join("full").exists(), "a refused job writes nothing");
    // A still job renders from either crowd.
    let still_job = RenderJob { shutter: None, ..job };
    assert_eq!(job::run(&blurred, None, &still_job, &job::Silent).unwrap().layers.len(), 1);
}

/// `--resume` re-renders when the shutter changes, or when blur is turned on.
#[test]
fn the_shutter_is_in_the_render_fingerprint() {
    let crowd = ShotCrowd::load(&common::demo_shot()).expect("demo loads");
    let still = RenderJob::new(vec!["full".into()], vec![1024], 4, "/tmp/x".into());
    let blur = RenderJob { shutter: Some([-0.25, 0.25]), ..still.clone() };
    let other = RenderJob { shutter: Some([0.0, 0.5]), ..still.clone() };
    let f = |j: &RenderJob| job::render_fingerprint(&crowd, None, j, "full");
    assert_ne!(f(&still), f(&blur));
    assert_ne!(f(&blur), f(&other));
    assert_eq!(f(&blur), f(&blur.clone()));
}

#[test]
fn bad_shutters_are_refused_naming_the_field() {
    let dir = common::tempdir().unwrap();
    let text = std::fs::read_to_string(common::demo_shot()).unwrap();
    let demo_dir = common::demo_shot().parent().unwrap().to_path_buf();
    for (shutter, says) in
        [("[0.25, -0.25]", "before close"), ("[0.0, nan]", "not finite"), ("[-2.0, 0.0]", "within one frame")]
    {
        let bad = text.replace("max_bounces = 4", &format!("max_bounces = 4\nshutter = {shutter}"));
        let path = demo_dir.join(format!(".bad_shutter_{}.toml", std::process::id()));
        std::fs::write(&path, bad).unwrap();
        let (code, _, err) = common::run(&["render", path.to_str().unwrap(), "--out", dir.path().to_str().unwrap()]);
        let _ = std::fs::remove_file(&path);
        assert_eq!(code, 2, "{err}");
        assert!(err.contains("render.shutter") && err.contains(says), "{err}");
    }
    let shot = common::demo_shot();
    let (code, _, err) =
        common::run(&["render", shot.to_str().unwrap(), "--shutter", "0.5,0.1", "--out", dir.path().to_str().unwrap()]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("--shutter"), "{err}");
}
