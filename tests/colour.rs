//! The working colourspace (docs/render.md, "Compression and colourspace"):
//! Rec.709 by default, ACEScg as an option that the renderer honours: every
//! input colour is converted to AP1 where the render loads it, the header
//! says AP1, previews convert back.

mod common;

use std::f32::consts::PI;
use std::path::{Path, PathBuf};

use exr::prelude::{ReadChannels, ReadLayers};
use glam::{Affine3A, Mat3, Quat, Vec2, Vec3};
use throng::render::colour::{self, Colourspace};
use throng::render::{render_frame, BlasSet, RenderSettings};
use throng::scene::{
    lights::SceneLights, vis, Camera, FrameScene, Instance, InstanceAgent, Library, Material, Mesh, Sky, Sun, Texture,
};

use common::run;

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 temp path")
}

// ------------------------------------------------ the matrix

/// RGB -> XYZ for primaries `p` (x, y) and white `w`, in f64.
fn rgb_to_xyz(p: [[f64; 2]; 3], w: [f64; 2]) -> glam::DMat3 {
    let xyz = |[x, y]: [f64; 2]| glam::DVec3::new(x / y, 1.0, (1.0 - x - y) / y);
    let m = glam::DMat3::from_cols(xyz(p[0]), xyz(p[1]), xyz(p[2]));
    let scale = m.inverse() * xyz(w);
    glam::DMat3::from_cols(m.x_axis * scale.x, m.y_axis * scale.y, m.z_axis * scale.z)
}

#[test]
fn the_matrix_is_rec709_to_ap1_with_a_bradford_d65_to_aces_white() {
    // The primaries and whites (x, y): ITU-R BT.709 with D65; ACES AP1 with the ACES white.
    let r709 = [[0.64, 0.33], [0.30, 0.60], [0.15, 0.06], [0.3127, 0.3290]];
    let ap1 = [[0.713, 0.293], [0.165, 0.830], [0.128, 0.044], [0.32168, 0.33767]];
    let f32s = |v: [[f64; 2]; 4]| v.map(|[x, y]| [x as f32, y as f32]);
    assert_eq!((f32s(r709), f32s(ap1)), (colour::REC709_CHROMATICITIES, colour::AP1_CHROMATICITIES));
    let bradford = glam::DMat3::from_cols_array_2d(&[
        [0.8951, 0.2664, -0.1614],
        [-0.7502, 1.7135, 0.0367],
        [0.0389, -0.0685, 1.0296],
    ])
    .transpose();
    let white = |[x, y]: [f64; 2]| glam::DVec3::new(x / y, 1.0, (1.0 - x - y) / y);
    let (src, dst) = (bradford * white(r709[3]), bradford * white(ap1[3]));
    let adapt = bradford.inverse() * glam::DMat3::from_diagonal(dst / src) * bradford;
    let m = rgb_to_xyz([ap1[0], ap1[1], ap1[2]], ap1[3]).inverse()
        * adapt
        * rgb_to_xyz([r709[0], r709[1], r709[2]], r709[3]);
    let ours = Mat3::from_cols_array_2d(&colour::REC709_TO_ACESCG).transpose().as_dmat3();
    let inverse = Mat3::from_cols_array_2d(&colour::ACESCG_TO_REC709).transpose().as_dmat3();
    for (a, b) in m.to_cols_array().iter().zip(ours.to_cols_array()) {
        assert!((a - b).abs() < 6e-8, "derived {m} vs {ours}"); // f32 rounding of the constants
    }
    for (a, b) in m.inverse().to_cols_array().iter().zip(inverse.to_cols_array()) {
        assert!((a - b).abs() < 1e-6, "derived inverse {} vs {inverse}", m.inverse());
    }
    // The published figures (ACES, OpenColorIO): first row 0.6131 0.3395 0.0474.
    assert!((ours.x_axis.x - 0.6131).abs() < 1e-4 && (ours.y_axis.x - 0.3395).abs() < 1e-4);
    // White stays white.
    let w = m * glam::DVec3::ONE;
    assert!((w - glam::DVec3::ONE).abs().max_element() < 1e-12, "{w}");
}

// ------------------------------------------------ pixels

fn quad(size: f32) -> Mesh {
    let h = size / 2.0;
    Mesh {
        name: "quad".into(),
        positions: [(-h, -h), (h, -h), (h, h), (-h, h)].map(|(x, z)| Vec3::new(x, 0.0, z)).to_vec(),
        normals: vec![Vec3::Y; 4],
        uvs: vec![Vec2::new(0.0, 0.0), Vec2::new(1.0, 0.0), Vec2::new(1.0, 1.0), Vec2::new(0.0, 1.0)],
        tangents: vec![],
        indices: vec![0, 2, 1, 0, 3, 2],
    }
}

/// A floor of `base` (times a 2x1 texture of `texel` when given) seen from
/// above under a sun of `sun` and a sky of `sky`.
fn floor_scene(base: Vec3, texel: Option<[f32; 4]>, sun: Vec3, sky: Vec3) -> (Library, FrameScene) {
    let material = Material {
        name: "floor".into(),
        base_color: base,
        base_color_texture: texel.map(|_| 0),
        roughness: 0.7,
        metallic: 0.0,
        ..Default::default()
    };
    let textures = texel.map(|t| Texture { name: "t".into(), width: 2, height: 1, texels: vec![t; 2] });
    let lib = Library { meshes: vec![quad(8.0)], materials: vec![material], textures: textures.into_iter().collect() };
    let scene = FrameScene {
        instances: vec![Instance {
            mesh: 0,
            material: 0,
            world_from_object: Affine3A::IDENTITY,
            agent: InstanceAgent::NONE,
            part: 0,
            visibility: vis::ALL,
        }],
        camera: Camera {
            world_from_camera: Affine3A::from_rotation_translation(
                Quat::from_rotation_x(-PI / 2.0),
                Vec3::new(0.0, 3.0, 0.0),
            ),
            yfov: 0.6,
            aperture: 0.0,
            focus_distance: 1.0,
        },
        lights: SceneLights::sun_and_sky(
            Some(Sun { direction: Vec3::new(0.3, 1.0, 0.2).normalize(), angular_diameter: 0.02, irradiance: sun }),
            Sky { radiance: sky },
        ),
        motion: None,
    };
    (lib, scene)
}

fn settings(diffuse_only: bool, max_bounces: u32) -> RenderSettings {
    RenderSettings {
        width: 24,
        height: 16,
        spp: 8,
        max_bounces,
        seed: 7,
        frame: 1001,
        sky_visible: true,
        threads: 2,
        indirect_clamp: 10.0,
        diffuse_only,
        ..Default::default()
    }
}

/// Renders the scene as given and again with the library and lights converted to `space`.
fn both(lib: &Library, scene: &FrameScene, s: &RenderSettings) -> (throng::render::Film, throng::render::Film) {
    let blas = BlasSet::build(lib);
    let rec709 = render_frame(&blas, lib, scene, s, None).unwrap();
    let (mut lib2, mut scene2) = (lib.clone(), scene.clone());
    colour::convert_library(&mut lib2.materials, &mut lib2.textures, Colourspace::Acescg);
    colour::scene_lights(&mut scene2, Colourspace::Acescg);
    let acescg = render_frame(&blas, &lib2, &scene2, s, None).unwrap();
    (rec709, acescg)
}

#[test]
fn a_grey_scene_renders_the_same_in_both_spaces() {
    // Grey material and texture, white sun, grey sky; glossy paths and bounces on.
    let (lib, scene) = floor_scene(Vec3::splat(0.6), Some([0.5, 0.5, 0.5, 1.0]), Vec3::splat(3.0), Vec3::splat(0.4));
    let (a, b) = both(&lib, &scene, &settings(false, 3));
    let mut worst = 0.0f32;
    for (p, q) in a.rgba.iter().zip(&b.rgba) {
        for c in 0..4 {
            worst = worst.max((p[c] - q[c]).abs() / p[c].abs().max(1e-3));
        }
    }
    // The matrix's rows sum to 1 to within 2 float steps: neutral stays neutral.
    assert!(worst < 2e-5, "grey differs by {worst} (relative)");
    assert!(a.rgba.iter().any(|p| p[0] > 0.1), "the floor is lit");
}

#[test]
fn a_saturated_red_renders_to_the_matrix_times_its_rec709_pixel() {
    // A red base colour, white light, Lambert, direct light plus one bounce
    // to the sky: every pixel is the base colour times a grey light term,
    // linear in the colour, so the ACEScg pixel is exactly M x the Rec.709
    // pixel (same seeds, same paths: nothing samples by colour in a pure
    // Lambert render). (Two colours multiplied, such as a red base under a
    // red texture, are not linear: M(a) M(b) is not M(ab).)
    let (lib, scene) = floor_scene(Vec3::new(0.8, 0.05, 0.03), None, Vec3::ONE * 2.0, Vec3::ONE);
    let (a, b) = both(&lib, &scene, &settings(true, 1));
    check_matrix_times(&a, &b);
    // The same red from a texture under a grey base colour: the texels are converted.
    let (lib, scene) = floor_scene(Vec3::splat(0.9), Some([0.9, 0.06, 0.03, 1.0]), Vec3::ONE * 2.0, Vec3::ONE);
    let (ta, tb) = both(&lib, &scene, &settings(true, 1));
    check_matrix_times(&ta, &tb);
    assert_ne!(ta.rgba, a.rgba);
    check_red(&a, &b);
}

fn check_matrix_times(a: &throng::render::Film, b: &throng::render::Film) {
    let mut lit = 0;
    for (p, q) in a.rgba.iter().zip(&b.rgba) {
        let want = colour::rec709_to_acescg(Vec3::new(p[0], p[1], p[2]));
        let got = Vec3::new(q[0], q[1], q[2]);
        assert!((want - got).abs().max_element() <= 1e-5 * want.max_element().max(1e-2), "{got} vs M x rec709 {want}");
        assert_eq!(p[3], q[3]);
        lit += (p[0] > 0.05) as usize;
    }
    assert!(lit > 100, "the red floor fills the frame ({lit} lit pixels)");
}

fn check_red(a: &throng::render::Film, b: &throng::render::Film) {
    // And the conversion did something: AP1 red is less saturated in numbers.
    let (p, q) = (a.rgba[a.index(12, 8)], b.rgba[b.index(12, 8)]);
    assert!(q[1] > 2.0 * p[1] && q[0] < p[0], "{p:?} -> {q:?}");
    // The albedo pass is in the working space too.
    let (al, bl) = (Vec3::from(a.albedo[a.index(12, 8)]), Vec3::from(b.albedo[b.index(12, 8)]));
    assert!((colour::rec709_to_acescg(al) - bl).abs().max_element() < 1e-5, "{al} -> {bl}");
}

#[test]
fn previews_of_acescg_films_convert_back_to_rec709() {
    let (lib, scene) = floor_scene(Vec3::new(0.8, 0.05, 0.03), None, Vec3::ONE * 2.0, Vec3::ONE);
    let (a, b) = both(&lib, &scene, &settings(true, 1));
    let dir = common::tempdir().unwrap();
    let (pa, pb) = (dir.path().join("a.png"), dir.path().join("b.png"));
    throng::render::exr::write_preview_png(&pa, &a).unwrap();
    throng::render::exr::write_preview_png_from(&pb, &b, Colourspace::Acescg).unwrap();
    let (ia, ib) = (image::open(&pa).unwrap().to_rgb8(), image::open(&pb).unwrap().to_rgb8());
    let worst = ia.pixels().zip(ib.pixels()).flat_map(|(p, q)| (0..3).map(move |c| p[c].abs_diff(q[c]))).max();
    assert!(worst <= Some(1), "previews differ by {worst:?} levels");
}

// ------------------------------------------------ the command line

/// The demo's small shot ([`common::DemoShot`]) "col" on frames 1001-1002
/// at 2 spp, `extra_render` added to `[render]`.
fn small_shot(dir: &Path, extra_render: &str) -> PathBuf {
    let shot =
        common::DemoShot { name: "col", frames: (1001, 1002), spp: 2, extra: extra_render, ..Default::default() };
    shot.write(dir, &common::two_robots(1..=2))
}

fn render(shot: &Path, out: &Path, extra: &[&str]) -> (i32, String) {
    let mut args = vec!["render", s(shot), "--layer", "full", "--frames", "1001", "--progress", "off", "--out", s(out)];
    args.extend_from_slice(extra);
    let (code, o, e) = run(&args);
    (code, format!("{o}{e}"))
}

fn header(path: &Path) -> (exr::meta::attribute::Chromaticities, String) {
    let image = exr::prelude::read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_file(path)
        .unwrap();
    let name = exr::prelude::Text::from("throng/colorspace");
    let cs = match image.layer_data.attributes.other.get(&name) {
        Some(exr::prelude::AttributeValue::Text(t)) => t.to_string(),
        other => panic!("throng/colorspace is {other:?}"),
    };
    (image.attributes.chromaticities.expect("chromaticities"), cs)
}

#[test]
fn acescg_headers_state_ap1_and_the_aces_white_and_rec709_stays_the_default() {
    let dir = common::tempdir().unwrap();
    let exr = |o: &str| dir.path().join(o).join("full/col.full.1001.exr");
    // The default: Rec.709.
    let shot = small_shot(dir.path(), "");
    assert_eq!(render(&shot, &dir.path().join("d"), &[]).0, 0);
    let (c, name) = header(&exr("d"));
    assert_eq!((c.red.0, c.red.1, c.white.0, c.white.1, name.as_str()), (0.64, 0.33, 0.3127, 0.3290, "lin_rec709"));
    // The flag.
    let (code, out) = render(&shot, &dir.path().join("f"), &["--colourspace", "acescg", "--png"]);
    assert_eq!(code, 0, "{out}");
    let (c, name) = header(&exr("f"));
    let got = [c.red, c.green, c.blue, c.white].map(|v| [v.0, v.1]);
    assert_eq!(got, colour::AP1_CHROMATICITIES);
    assert_eq!(got, [[0.713, 0.293], [0.165, 0.830], [0.128, 0.044], [0.32168, 0.33767]]);
    assert_eq!(name, "ACEScg");
    assert!(exr("f").with_extension("png").exists());
    let (film_d, meta_d) = throng::render::exr::read_layer(&exr("d")).unwrap();
    let (film_f, meta_f) = throng::render::exr::read_layer(&exr("f")).unwrap();
    assert_eq!((meta_d.colourspace, meta_f.colourspace), (Colourspace::Rec709, Colourspace::Acescg));
    assert_ne!(film_d.rgba, film_f.rgba, "acescg converts the inputs");
    assert_eq!(film_d.agent_id, film_f.agent_id);
    // The shot setting gives the same file as the flag.
    let shot = small_shot(dir.path(), "working_colourspace = \"acescg\"");
    assert_eq!(render(&shot, &dir.path().join("s"), &[]).0, 0);
    assert_eq!(std::fs::read(exr("s")).unwrap(), std::fs::read(exr("f")).unwrap());
    // The flag wins over the shot.
    assert_eq!(render(&shot, &dir.path().join("r"), &["--colourspace", "rec709"]).0, 0);
    assert_eq!(std::fs::read(exr("r")).unwrap(), std::fs::read(exr("d")).unwrap());
}

#[test]
fn resume_rerenders_a_frame_made_in_the_other_colourspace() {
    let dir = common::tempdir().unwrap();
    let shot = small_shot(dir.path(), "");
    let out = dir.path().join("o");
    assert_eq!(render(&shot, &out, &[]).0, 0);
    let (code, text) = render(&shot, &out, &["--resume"]);
    assert!(code == 0 && text.contains("1 skipped"), "{text}");
    let (code, text) = render(&shot, &out, &["--resume", "--colourspace", "acescg"]);
    assert!(code == 0 && text.contains("other settings") && text.contains("0 skipped"), "{text}");
    let (_, meta) = throng::render::exr::read_layer(&out.join("full/col.full.1001.exr")).unwrap();
    assert_eq!(meta.colourspace, Colourspace::Acescg);
}

#[test]
fn bad_colourspaces_are_refused_naming_the_key_or_flag() {
    let dir = common::tempdir().unwrap();
    let shot = small_shot(dir.path(), "working_colourspace = \"p3\"");
    let (code, text) = render(&shot, &dir.path().join("o"), &[]);
    assert_eq!(code, 2, "{text}");
    assert!(text.contains("shot.toml") && text.contains("working_colourspace") && !text.contains("panicked"), "{text}");
    assert!(text.contains("rec709") && text.contains("acescg"), "says what is allowed: {text}");
    let shot = small_shot(dir.path(), "");
    let (code, text) = render(&shot, &dir.path().join("o"), &["--colourspace", "ACES2065-1"]);
    assert_eq!(code, 2, "{text}");
    assert!(text.contains("--colourspace"), "{text}");
    assert!(!dir.path().join("o").exists());
}

#[test]
fn the_comp_refuses_layers_of_two_colourspaces() {
    let dir = common::tempdir().unwrap();
    let shot = small_shot(dir.path(), "");
    let (code, _, err) = run(&["layers", s(&shot)]);
    assert_eq!(code, 0, "{err}");
    let out = dir.path().join("o");
    for (layer, cs) in [("set", "rec709"), ("crowd0", "acescg"), ("crowd1", "rec709")] {
        let (code, o, e) = run(&[
            "render",
            s(&shot),
            "--layer",
            layer,
            "--frames",
            "1001",
            "--progress",
            "off",
            "--colourspace",
            cs,
            "--out",
            s(&out),
        ]);
        assert_eq!(code, 0, "{o}{e}");
    }
    let (code, _, err) = run(&["comp", s(&out), "--frame", "1001", "--out", s(&dir.path().join("c.exr"))]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("throng/colorspace") && err.contains("ACEScg") && err.contains("crowd"), "{err}");
    assert!(!dir.path().join("c.exr").exists());
}

/// The crowd's colours are converted by type: `into_acescg` takes the
/// Rec.709 crowd and gives an ACEScg one (converting twice, or exporting
/// the converted crowd, does not compile: the doctests of `into_acescg`),
/// and a render refuses a crowd whose colourspace is not its job's.
#[test]
fn the_render_takes_a_crowd_in_its_colourspace() {
    let crowd = throng::casting::ShotCrowd::load(&common::demo_shot()).unwrap();
    assert_eq!(crowd.poses().colourspace(), Colourspace::Rec709);
    let authored = crowd.library().materials.clone();
    let dir = common::tempdir().unwrap();
    let frame = crowd.shot().frames.start;
    let job = throng::render::job::RenderJob {
        colourspace: Colourspace::Acescg,
        resolution: Some([16, 9]),
        ..throng::render::job::RenderJob::new(vec!["full".into()], vec![frame], 1, dir.path().to_path_buf())
    };
    let err = throng::render::job::run(&crowd, None, &job, &throng::render::job::Silent).unwrap_err().to_string();
    assert!(err.contains("ACEScg") && err.contains("lin_rec709"), "{err}");
    assert!(!dir.path().join("full").exists(), "a refused job writes nothing");
    let converted = colour::into_acescg(crowd);
    assert_eq!(converted.poses().colourspace(), Colourspace::Acescg);
    assert_eq!(converted.library().materials.len(), authored.len());
    for (a, b) in authored.iter().zip(&converted.library().materials) {
        assert!((colour::rec709_to_acescg(a.base_color) - b.base_color).abs().max_element() < 1e-6, "{}", a.name);
    }
    let done = throng::render::job::run(&converted, None, &job, &throng::render::job::Silent).unwrap();
    assert_eq!(done.layers.len(), 1);
}
