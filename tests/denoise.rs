//! Denoising end to end (docs/render.md, "Denoising"): the demo rendered
//! through the CLI with `--denoise` keeps its noisy beauty bit for bit and
//! comes out closer to a many-sample reference; light groups add up to the
//! denoised beauty; holes in crowd layers stay empty; the stack of denoised
//! layers is the denoised full render within the documented tolerance;
//! `throng denoise` on a noisy file gives what `render --denoise` gives; the
//! denoised channels do not depend on the thread count; bad requests are
//! refused by name.
//!
//! These need Open Image Denoise. Where it is not installed they say so and
//! pass, unless `THRONG_REQUIRE_OIDN=1` (CI installs it and sets that).

mod common;

use std::path::{Path, PathBuf};

use common::{demo_shot, oidn_available, run, tempdir};
use throng::render::exr;
use throng::render::Film;

const FRAME: &str = "1024";

fn read(path: &Path) -> (Film, exr::LayerMeta) {
    exr::read_layer(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Renders the demo's `layer` (or `all`) at frame 1024, 160x90, into `out`.
fn render(out: &Path, layer: &str, spp: &str, extra: &[&str]) {
    let shot = demo_shot();
    let mut args: Vec<String> = ["render", shot.to_str().unwrap(), "--layer", layer, "--frames", FRAME, "--spp", spp]
        .iter()
        .map(|s| s.to_string())
        .collect();
    args.extend(["--resolution", "160x90", "--progress", "off", "--out"].map(String::from));
    args.push(out.to_str().unwrap().to_string());
    args.extend(extra.iter().map(|s| s.to_string()));
    let (code, stdout, stderr) = run(&args);
    assert_eq!(code, 0, "render {args:?}: {stdout}\n{stderr}");
}

fn layer_file(out: &Path, layer: &str) -> PathBuf {
    out.join(layer).join(format!("demo.{layer}.{FRAME}.exr"))
}

fn rgb(film: &Film) -> Vec<[f32; 3]> {
    film.rgba.iter().map(|p| [p[0], p[1], p[2]]).collect()
}

fn pass<'a>(film: &'a Film, name: &str) -> &'a [[f32; 3]] {
    &film.passes.iter().find(|p| p.name == name).unwrap_or_else(|| panic!("no pass {name}")).data
}

/// Mean squared error of `a` against `b`, relative to `b`'s mean square.
fn relative_mse(a: &[[f32; 3]], b: &[[f32; 3]]) -> f64 {
    let (mut err, mut power) = (0.0f64, 0.0f64);
    for (x, y) in a.iter().zip(b) {
        for c in 0..3 {
            err += f64::from(x[c] - y[c]).powi(2);
            power += f64::from(y[c]).powi(2);
        }
    }
    err / power.max(1e-12)
}

#[test]
fn a_denoised_render_keeps_its_noisy_beauty_and_is_closer_to_the_reference() {
    if !oidn_available("a_denoised_render_keeps_its_noisy_beauty_and_is_closer_to_the_reference") {
        return;
    }
    let dir = tempdir().unwrap();
    let (noisy, denoised, reference) = (dir.path().join("noisy"), dir.path().join("denoised"), dir.path().join("ref"));
    render(&noisy, "full", "4", &[]);
    render(&denoised, "full", "4", &["--denoise"]);
    render(&reference, "full", "256", &[]);
    let (plain, _) = read(&layer_file(&noisy, "full"));
    let (clean, meta) = read(&layer_file(&denoised, "full"));
    let (truth, _) = read(&layer_file(&reference, "full"));
    assert!(meta.denoiser.starts_with("Open Image Denoise 2."), "throng/denoiser: {:?}", meta.denoiser);
    assert_eq!(
        pass(&clean, "noisy"),
        rgb(&plain).as_slice(),
        "the noisy beauty is the undenoised render's, bit for bit"
    );
    for field in [&clean.z, &plain.z] {
        assert_eq!(field.len(), 160 * 90);
    }
    assert_eq!(clean.z, plain.z, "depth is not denoised");
    assert_eq!(clean.agent_id, plain.agent_id, "ids are not denoised");
    assert_eq!(clean.albedo, plain.albedo, "the guides are written as rendered");
    let (before, after) = (relative_mse(&rgb(&plain), &rgb(&truth)), relative_mse(&rgb(&clean), &rgb(&truth)));
    assert!(after * 2.0 < before, "relative MSE against 256 spp: {before:.5} noisy, {after:.5} denoised");
}

#[test]
fn light_groups_add_up_to_the_denoised_beauty_and_holes_stay_empty() {
    if !oidn_available("light_groups_add_up_to_the_denoised_beauty_and_holes_stay_empty") {
        return;
    }
    let dir = tempdir().unwrap();
    let out = dir.path().join("r");
    let layers = dir.path().join("demo.layers.json");
    let shot = demo_shot();
    let (code, _, stderr) = run(&["layers", shot.to_str().unwrap(), "--out", layers.to_str().unwrap()]);
    assert_eq!(code, 0, "{stderr}");
    render(&out, "crowd0", "4", &["--denoise", "--passes", "light_groups", "--manifest", layers.to_str().unwrap()]);
    let (film, _) = read(&layer_file(&out, "crowd0"));
    let groups: Vec<&[[f32; 3]]> =
        film.passes.iter().filter(|p| p.name.starts_with("lg_")).map(|p| p.data.as_slice()).collect();
    assert!(groups.len() >= 2, "light groups: {}", groups.len());
    let (mut holes, mut lit) = (0, 0);
    for (i, px) in film.rgba.iter().enumerate() {
        let sum: [f32; 3] = std::array::from_fn(|c| groups.iter().map(|g| g[i][c]).sum());
        for c in 0..3 {
            // Each value was rounded to half once in the file.
            let tol = (sum[c] + px[c]) * 2f32.powi(-11) + 1e-6;
            assert!((sum[c] - px[c]).abs() <= tol, "pixel {i}: groups sum to {sum:?}, beauty {px:?}");
        }
        if px[3] == 0.0 {
            holes += 1;
            assert_eq!([px[0], px[1], px[2]], [0.0; 3], "pixel {i}: colour in a hole");
            assert!(groups.iter().all(|g| g[i] == [0.0; 3]), "pixel {i}: a group has light in a hole");
        } else {
            lit += 1;
        }
    }
    assert!(holes > 100 && lit > 100, "{holes} empty and {lit} covered pixels");
}

#[test]
fn the_stack_of_denoised_layers_is_the_denoised_full_render() {
    if !oidn_available("the_stack_of_denoised_layers_is_the_denoised_full_render") {
        return;
    }
    let dir = tempdir().unwrap();
    let out = dir.path().join("r");
    let layers = dir.path().join("demo.layers.json");
    let shot = demo_shot();
    let (code, _, stderr) = run(&["layers", shot.to_str().unwrap(), "--out", layers.to_str().unwrap()]);
    assert_eq!(code, 0, "{stderr}");
    let manifest = ["--manifest", layers.to_str().unwrap()];
    render(&out, "all", "8", &[&["--denoise"][..], &manifest[..]].concat());
    render(&out, "full", "8", &[&["--denoise"][..], &manifest[..]].concat());
    let comp = dir.path().join("comp.exr");
    let (code, _, stderr) = run(&[
        "comp",
        out.to_str().unwrap(),
        "--frame",
        FRAME,
        "--manifest",
        layers.to_str().unwrap(),
        "--out",
        comp.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{stderr}");
    let (stacked, _) = read(&comp);
    let (full, _) = read(&layer_file(&out, "full"));
    // docs/render.md, "Denoising": each layer is rendered with its own
    // holdouts and denoised on its own, so the two differ by their sample
    // noise left after denoising and by what the denoiser does where layers
    // meet. Measured on the display scale (clipped to 0..1, as a viewer and
    // FLIP see it) and against the noisy stack's own difference, which the
    // denoised stack must cut to well under a half.
    let clip = |v: Vec<[f32; 3]>| v.into_iter().map(|p| p.map(|c| c.clamp(0.0, 1.0))).collect::<Vec<_>>();
    let shown = relative_mse(&clip(rgb(&stacked)), &clip(rgb(&full)));
    assert!(shown < 0.05, "relative MSE of the denoised stack against the denoised full render, 0..1: {shown:.5}");
    let denoised = relative_mse(&rgb(&stacked), &rgb(&full));
    let noisy = relative_mse(pass(&stacked, "noisy"), pass(&full, "noisy"));
    assert!(denoised * 3.0 < noisy, "relative MSE stack against full: {denoised:.5} denoised, {noisy:.5} noisy");
}

#[test]
fn throng_denoise_gives_what_render_denoise_gives_for_any_thread_count() {
    if !oidn_available("throng_denoise_gives_what_render_denoise_gives_for_any_thread_count") {
        return;
    }
    let dir = tempdir().unwrap();
    let (noisy, one, two) = (dir.path().join("noisy"), dir.path().join("t1"), dir.path().join("t2"));
    render(&noisy, "full", "4", &[]);
    render(&one, "full", "4", &["--denoise", "--threads", "1"]);
    render(&two, "full", "4", &["--denoise", "--threads", "2"]);
    let (a, _) = read(&layer_file(&one, "full"));
    let (b, _) = read(&layer_file(&two, "full"));
    assert_eq!(a.rgba, b.rgba, "denoised beauty with 1 and 2 threads");
    let later = dir.path().join("later");
    std::fs::create_dir_all(&later).unwrap();
    let input = layer_file(&noisy, "full");
    let (code, stdout, stderr) =
        run(&["denoise", input.to_str().unwrap(), "--out", later.to_str().unwrap(), "--threads", "2"]);
    assert_eq!(code, 0, "{stdout}\n{stderr}");
    let (c, meta) = read(&later.join("demo.full.1024.exr"));
    assert!(!meta.denoiser.is_empty());
    // The separate step reads the guides back from half floats, the render
    // denoises from its float film: they agree to that rounding.
    let rel = relative_mse(&rgb(&c), &rgb(&b));
    assert!(rel < 1e-3, "throng denoise against render --denoise: relative MSE {rel:.6}");
    // Denoising it again is refused by name; so is writing over the input.
    let again = dir.path().join("again");
    std::fs::create_dir_all(&again).unwrap();
    let done = later.join("demo.full.1024.exr");
    let (code, _, stderr) = run(&["denoise", done.to_str().unwrap(), "--out", again.to_str().unwrap()]);
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("already denoised"), "{stderr}");
    let (code, _, stderr) =
        run(&["denoise", input.to_str().unwrap(), "--out", input.parent().unwrap().to_str().unwrap()]);
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("same file"), "{stderr}");
}

#[test]
fn without_the_library_denoising_exits_2_saying_how_to_install_it() {
    let dir = tempdir().unwrap();
    let shot = demo_shot();
    let out = dir.path().join("r");
    let output = std::process::Command::new(common::bin())
        .args(["render", shot.to_str().unwrap(), "--layer", "full", "--frames", FRAME, "--spp", "1"])
        .args(["--resolution", "32x18", "--progress", "off", "--denoise", "--out", out.to_str().unwrap()])
        .env("THRONG_OIDN", dir.path().join("no-such-oidn"))
        .output()
        .unwrap();
    let stderr = common::text(&output.stderr);
    assert_eq!(output.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("pip install") && stderr.contains("pyoidn"), "{stderr}");
    assert!(stderr.contains("THRONG_OIDN"), "{stderr}");
    assert!(!layer_file(&out, "full").exists(), "nothing written before the denoiser was found");
}

#[test]
fn a_file_without_guides_is_refused_naming_the_channel() {
    let dir = tempdir().unwrap();
    // An EXR with a beauty and nothing else, as another renderer may write.
    let path = dir.path().join("plain.exr");
    let img = ::exr::prelude::Image::from_channels(
        (4, 4),
        ::exr::prelude::SpecificChannels::rgba(|_| (0.5f32, 0.5f32, 0.5f32, 1.0f32)),
    );
    ::exr::prelude::WritableImage::write(&img).to_file(&path).unwrap();
    let out = dir.path().join("out");
    std::fs::create_dir_all(&out).unwrap();
    let output = std::process::Command::new(common::bin())
        .args(["denoise", path.to_str().unwrap(), "--out", out.to_str().unwrap()])
        .output()
        .unwrap();
    let stderr = common::text(&output.stderr);
    assert_eq!(output.status.code(), Some(2), "{stderr}");
    // Checked before the library is looked for: the same answer anywhere.
    assert!(stderr.contains("albedo.R"), "{stderr}");
    assert!(!out.join("plain.exr").exists());
}

/// A `size` square in the plane z = `z`, facing +Z.
fn quad_z(size: f32, z: f32) -> throng::scene::Mesh {
    let h = size / 2.0;
    throng::scene::Mesh {
        name: format!("quad_z{z}"),
        positions: [(-h, -h), (h, -h), (h, h), (-h, h)].map(|(x, y)| glam::Vec3::new(x, y, z)).to_vec(),
        normals: vec![glam::Vec3::Z; 4],
        indices: vec![0, 1, 2, 0, 2, 3],
        ..Default::default()
    }
}

#[test]
fn the_albedo_guide_sees_through_glass_and_in_its_mirror() {
    use glam::{Affine3A, Vec3};
    use throng::scene::{
        lights::SceneLights, vis, Camera, FrameScene, Instance, InstanceAgent, Library, Material, Sky,
    };
    // Looking down -Z, at normal incidence, through a thin glass wall (z = -1)
    // at a red wall (z = -3); a green wall behind the camera (z = +1) is what
    // the glass reflects. OIDN's albedo of a delta surface is that of the
    // first non-delta hit behind it: the red wall for the share the glass
    // transmits, the green one for the share it reflects.
    let ior = 1.5f32;
    let (red, green) = (Vec3::new(0.8, 0.2, 0.1), Vec3::new(0.1, 0.7, 0.2));
    let matte = |name: &str, c: Vec3| Material { name: name.into(), base_color: c, ..Default::default() };
    let glass = Material {
        name: "glass".into(),
        base_color: Vec3::ONE,
        roughness: 0.0,
        transmission: 1.0,
        ior,
        ..Default::default()
    };
    let lib = Library {
        meshes: vec![quad_z(10.0, -1.0), quad_z(40.0, -3.0), quad_z(40.0, 1.0)],
        materials: vec![glass, matte("red", red), matte("green", green)],
        textures: vec![],
    };
    let instance = |mesh: u32| Instance {
        mesh,
        material: mesh,
        world_from_object: Affine3A::IDENTITY,
        agent: InstanceAgent::NONE,
        part: 0,
        visibility: vis::ALL,
    };
    let lights = SceneLights {
        sun: None,
        sky: Sky { radiance: Vec3::splat(0.5) },
        dome: None,
        local: vec![],
        groups: Default::default(),
    };
    let scene = FrameScene {
        instances: (0..3).map(instance).collect(),
        camera: Camera::pinhole(Affine3A::IDENTITY, 0.02),
        lights,
        motion: None,
    };
    let (res, spp) = (16u32, 64u32);
    let settings = throng::render::RenderSettings {
        width: res,
        height: res,
        spp,
        max_bounces: 8,
        seed: 5,
        frame: 1,
        sky_visible: true,
        indirect_clamp: 0.0,
        ..Default::default()
    };
    let film =
        throng::render::film::render_frame(&throng::render::accel::BlasSet::build(&lib), &lib, &scene, &settings, None)
            .expect("render");
    // A thin wall transmits (1 - R)^2 / (1 - R^2) with every internal
    // reflection, R = ((n - 1) / (n + 1))^2, and reflects the rest.
    let r = (((ior - 1.0) / (ior + 1.0)) as f64).powi(2);
    let t = (1.0 - r).powi(2) / (1.0 - r * r);
    let n = f64::from(res * res * spp);
    for c in 0..3 {
        let got = film.albedo.iter().map(|p| f64::from(p[c])).sum::<f64>() / film.albedo.len() as f64;
        let want = t * f64::from(red[c]) + (1.0 - t) * f64::from(green[c]);
        // Each sample's albedo is red or green: a Bernoulli mix.
        let sigma = f64::from((red[c] - green[c]).abs()) * (t * (1.0 - t) / n).sqrt();
        assert!((got - want).abs() < 5.0 * sigma + 1e-3, "albedo[{c}]: {got:.4}, want {want:.4} (sigma {sigma:.4})");
        assert!((got - 1.0).abs() > 0.2, "albedo[{c}] {got:.4} is not the glass's own base colour");
    }
}
