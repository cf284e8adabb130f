//! Deep output (docs/render.md, "Deep output"): the deep scanline writer
//! round-trips through our reader of record, a rendered deep layer keeps
//! its invariants (samples per pixel within the cap, Z <= ZBack, sorted,
//! the truthful deepImageState, crowd layers without set samples) and
//! flattens front to back to its flat beauty, and bad `render.deep` keys
//! exit 2 naming the key. `.ci/deep_check.py` reads the same files with
//! OpenImageIO.
//!
//! Deep compositing (docs/compositing.md, "Deep comp"), on the comp
//! property test's shot (tests/fixtures/stack_shot, with the statistics of
//! tests/comp.rs): deep-merging every layer of a frame and flattening gives
//! the full render within noise, and today's flat comp; an external element
//! (an analytic sphere among the agents, its own deep image) merges into the
//! crowd per pixel with no holdout render; `throng comp --deep` writes both
//! files and refuses a deep file that is not throng's.
//!
//! Also: the completeness check (`is_whole`) judges from the header and the
//! line offset table, refusing a file cut anywhere; a frame rendered with
//! RLE and with ZIPS holds the same samples bit for bit, and `render
//! --json` reports the deep file's size and samples; `throng review` shows
//! a deep layer's samples per pixel (docs/review.md).

mod common;

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use common::stack_stats::{blocks, diff_stats, lum, worst_block};
use common::{demo_shot, text, throng};
use throng::casting::ShotCrowd;
use throng::layers::Manifest;
use throng::render::deep::{DeepImage, DeepSample};
use throng::render::exr::deep::{
    is_whole, read_deep, read_deep_header, read_sample_counts, write_deep, DeepCompression,
};
use throng::render::exr::{read_layer, LayerMeta};
use throng::render::job::deep_layer_path;
use throng::render::job::{self, RenderJob};
use throng::render::Film;

const FRAME: i32 = 1024;

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn out_dir(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join("deep").join(name);
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// The demo shot with `deep` as its `render.deep` (written beside it, so its paths resolve).
fn shot_with(tag: &str, deep: &str) -> PathBuf {
    let text = std::fs::read_to_string(demo_shot()).unwrap();
    let path = demo_shot().with_file_name(format!(".deep_{tag}_{}.toml", std::process::id()));
    std::fs::write(&path, text.replace("[render]\n", &format!("[render]\ndeep = {deep}\n"))).unwrap();
    path
}

fn meta() -> LayerMeta {
    LayerMeta {
        shot: "unit".into(),
        layer: "crowd0".into(),
        frame: 7,
        seed: 3,
        spp: 4,
        id_mapping: throng::render::exr::ID_MAPPING.into(),
        world_to_camera: [0.0; 16],
        world_to_ndc: [1.0; 16],
        near: 0.5,
        far: 90.0,
        fps: 24.0,
        render_fingerprint: "abc".into(),
        denoiser: String::new(),
        shutter: None,
        colourspace: Default::default(),
    }
}

/// A small deep image: pixel i holds i % 4 samples at varied depths.
fn synthetic(w: u32, h: u32) -> DeepImage {
    let mut img = DeepImage { width: w, height: h, ..Default::default() };
    for i in 0..w * h {
        let n = i % 4;
        img.counts.push(n);
        for k in 0..n {
            let z = 1.0 + k as f32 * 2.0 + i as f32 * 0.01;
            img.samples.push(DeepSample {
                rgba: [0.25 * k as f32, 0.5, 0.125, 0.5],
                z,
                z_back: z + if k == 1 { 0.5 } else { 0.0 },
                agent_id: f32::from_bits(0x3f80_0000 + i),
                object_id: f32::from_bits(0x4000_0000 + k),
            });
        }
    }
    img
}

#[test]
fn the_writer_round_trips_through_the_reader_of_record() {
    let dir = out_dir("unit");
    let img = synthetic(13, 5);
    let film = Film::new(13, 5);
    for (c, name) in [(DeepCompression::Zips, "zips"), (DeepCompression::Rle, "rle"), (DeepCompression::None, "none")] {
        let path = dir.join(format!("unit.{name}.deep.exr"));
        write_deep(&path, &img, &film, &meta(), c).unwrap();
        let (back, head) = read_deep(&path).unwrap();
        // The chosen values are exact in half, so the image comes back bit for bit.
        assert_eq!(back, img, "{name}");
        assert_eq!(head.compression, Some(c));
        assert_eq!(head.version, 2 | 0x800);
        assert_eq!(head.block_type, "deepscanline");
        assert_eq!(head.max_samples_per_pixel, 3);
        assert_eq!(head.channels, ["A", "B", "G", "R", "Z", "ZBack", "id.agent", "id.object"]);
        assert_eq!(head.state, 3, "sorted and non-overlapping: tidy");
        assert_eq!(head.text.get("throng/shot").map(String::as_str), Some("unit"));
        assert_eq!(head.text.get("throng/renderFingerprint").map(String::as_str), Some("abc"));
        assert_eq!(head.world_to_ndc, Some([1.0; 16]));
        assert!(head.chromaticities);
        // The same image gives the same bytes.
        let again = dir.join(format!("again.{name}.deep.exr"));
        write_deep(&again, &img, &film, &meta(), c).unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), std::fs::read(&again).unwrap());
    }
    // Overlapping samples are only "sorted".
    let mut overlapping = synthetic(13, 5);
    overlapping.samples[1].z_back = overlapping.samples[2].z + 1.0;
    let path = dir.join("overlap.deep.exr");
    write_deep(&path, &overlapping, &film, &meta(), DeepCompression::Zips).unwrap();
    assert_eq!(read_deep(&path).unwrap().1.state, 1);
    // Counts that do not match the samples are refused, and nothing is left.
    let mut bad = synthetic(13, 5);
    bad.counts[3] += 1;
    let path = dir.join("bad.deep.exr");
    assert!(write_deep(&path, &bad, &film, &meta(), DeepCompression::Zips).is_err());
    assert!(!path.exists());
    // A truncated file is an error, not a panic.
    let whole = std::fs::read(dir.join("unit.zips.deep.exr")).unwrap();
    let cut = dir.join("cut.deep.exr");
    std::fs::write(&cut, &whole[..whole.len() - 9]).unwrap();
    assert!(read_deep(&cut).is_err());
}

/// Largest difference between a deep file flattened and its flat beauty,
/// measured in half-float steps of the larger value (both files store half).
fn flatten_error(deep: &DeepImage, flat: &Film) -> f32 {
    let mut worst = 0.0f32;
    for (d, f) in deep.flatten().iter().zip(&flat.rgba) {
        for c in 0..4 {
            let tol = 2e-3 * d[c].abs().max(f[c].abs()) + 1e-3;
            worst = worst.max((d[c] - f[c]).abs() / tol);
        }
    }
    worst
}

#[test]
fn rendered_deep_layers_keep_their_invariants_and_flatten_to_the_beauty() {
    let dir = out_dir("demo");
    let manifest = dir.join("demo.layers.json");
    let shot = shot_with("cap", "{ max_samples = 3 }");
    let o = throng(&["layers", s(&shot), "--out", s(&manifest)]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let out = dir.join("out");
    let f = FRAME.to_string();
    for layer in ["all", "full"] {
        let args = ["render", s(&shot), "--manifest", s(&manifest), "--layer", layer, "--frames", &f];
        let rest = ["--spp", "4", "--resolution", "96x54", "--progress", "off", "--out", s(&out)];
        let o = throng(&[&args[..], &rest[..]].concat());
        assert!(o.status.success(), "{}", text(&o.stderr));
    }
    let _ = std::fs::remove_file(&shot);
    let mut layers = 0;
    for layer in ["set", "crowd0", "crowd1", "crowd2", "full"] {
        let flat_path = throng::output::layer_path(&out, "demo", layer, FRAME);
        let (deep, head) = read_deep(&deep_layer_path(&flat_path)).unwrap();
        let (flat, _) = read_layer(&flat_path).unwrap();
        layers += 1;
        assert_eq!((deep.width, deep.height), (96, 54));
        assert!(deep.max_samples() <= 3, "{layer}: the cap holds");
        assert_eq!(head.max_samples_per_pixel, deep.max_samples() as usize);
        assert_eq!(head.state == 3, deep.is_tidy(), "{layer}: deepImageState is truthful");
        assert!(!deep.samples.is_empty(), "{layer}: has samples");
        for p in deep.pixels() {
            for s in p {
                assert!(s.z <= s.z_back, "{layer}: Z <= ZBack");
                assert!((0.0..=1.0).contains(&s.rgba[3]) && s.rgba[3] > 0.0, "{layer}: alpha in (0, 1]");
                if layer.starts_with("crowd") {
                    assert!(s.agent_id != 0.0 && s.z.is_finite(), "{layer}: a crowd layer holds agents only");
                }
            }
            assert!(p.windows(2).all(|w| w[0].z <= w[1].z), "{layer}: sorted by Z");
        }
        let err = flatten_error(&deep, &flat);
        assert!(err <= 1.0, "{layer}: flattened deep differs from the flat beauty ({err} of the tolerance)");
    }
    assert_eq!(layers, 5);
}

#[test]
fn bad_deep_keys_exit_2_naming_the_key() {
    let out = out_dir("bad");
    for (tag, value, key) in [
        ("zero", "{ max_samples = 0 }", "render.deep.max_samples"),
        ("huge", "{ max_samples = 100000 }", "render.deep.max_samples"),
        ("tol", "{ tolerance = -1.0 }", "render.deep.tolerance"),
        ("zip", "{ compression = \"zip\" }", "render.deep.compression"),
        ("key", "{ depth = 3 }", "depth"),
    ] {
        let shot = shot_with(tag, value);
        let o = throng(&["render", s(&shot), "--layer", "full", "--frames", "1024", "--out", s(&out)]);
        let _ = std::fs::remove_file(&shot);
        let err = text(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{tag}: {err}");
        assert!(err.contains(key), "{tag}: the error names {key}: {err}");
        if tag == "zip" {
            assert!(err.contains("zips, rle, none"), "the allowed ones are named: {err}");
        }
    }
}

const STACK_SHOT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/stack_shot/shot.toml");
const STACK_FRAME: i32 = 1001;
/// The comp property test's sample count and bounds (tests/comp.rs).
const STACK_SPP: u32 = 128;
const K_BLOCK: f64 = 5.0;
const K_MEAN: f64 = 4.0;
const STACK_LAYERS: [&str; 4] = ["set", "crowd2", "crowd1", "crowd0"];

/// The stack shot's layers and full render with deep output (seed A), and
/// the full render again with another seed (the noise estimate).
struct Stack {
    a: PathBuf,
    manifest: Manifest,
    full_b: Film,
}

fn stack_render(crowd: &ShotCrowd, manifest: &Manifest, layers: &[&str], out: &Path, deep: bool) {
    let job = RenderJob {
        cryptomatte: job::CryptoOutput::Header,
        deep: deep.then(throng::shot::Deep::default),
        ..RenderJob::new(layers.iter().map(|s| s.to_string()).collect(), vec![STACK_FRAME], STACK_SPP, out.into())
    };
    job::run(crowd, Some(manifest), &job, &job::Silent).unwrap();
}

fn stack() -> &'static Stack {
    static S: OnceLock<Stack> = OnceLock::new();
    S.get_or_init(|| {
        let dir = out_dir("stack");
        let crowd = ShotCrowd::load(Path::new(STACK_SHOT)).unwrap();
        let manifest = throng::layers::build_layers(&crowd, &Default::default()).unwrap();
        let a = dir.join("a");
        stack_render(&crowd, &manifest, &[&STACK_LAYERS[..], &["full"]].concat(), &a, true);
        let seed = crowd.shot().seed;
        let crowd = crowd.with_shot(|shot| shot.seed = seed + 1).unwrap();
        let b = dir.join("b");
        stack_render(&crowd, &manifest, &["full"], &b, false);
        let full_b = stack_flat(&b, "full");
        Stack { a, manifest, full_b }
    })
}

fn stack_flat(dir: &Path, layer: &str) -> Film {
    read_layer(&throng::output::layer_path(dir, "stack", layer, STACK_FRAME)).unwrap().0
}

fn stack_deep(layer: &str) -> DeepImage {
    let flat = throng::output::layer_path(&stack().a, "stack", layer, STACK_FRAME);
    read_deep(&deep_layer_path(&flat)).unwrap().0
}

#[test]
fn deep_merging_every_layer_flattens_to_the_full_render() {
    let st = stack();
    let comped = throng::comp::deep::comp_frame_deep(&st.a, STACK_FRAME, Some(&st.manifest)).unwrap();
    assert_eq!(comped.deep_files.len(), 4);
    let deep = &comped.deep;
    for p in deep.pixels() {
        assert!(
            p.windows(2).all(|w| (w[0].z, w[0].z_back) < (w[1].z, w[1].z_back)),
            "sorted, coincident ones combined"
        );
    }
    let merged_samples = deep.samples.len();
    let layer_samples: usize = STACK_LAYERS.iter().map(|l| stack_deep(l).samples.len()).sum();
    assert!(merged_samples > 0 && merged_samples <= layer_samples, "combining only removes samples");
    let stacked = &comped.flat.film;
    let full_a = stack_flat(&st.a, "full");
    let noise = (&full_a, &st.full_b);
    let all: Vec<usize> = (0..full_a.rgba.len()).collect();
    let level = all.iter().map(|&i| lum(&full_a.rgba[i])).sum::<f64>() / all.len() as f64;
    let (m, se) = diff_stats(stacked, &full_a, noise, &all, lum);
    eprintln!("deep comp - full: {m:+.5} (se {se:.5}, {:.2} sigma, {:+.3}%)", m / se, 100.0 * m / level);
    assert!((m / se).abs() < K_MEAN && (m / level).abs() < 0.005, "mean: {m:+.5}, se {se:.5}");
    // Every block within noise, and a margin of 2% of its level for the
    // edges (as the flat stack: docs/compositing.md).
    for (b, px) in blocks(&full_a).iter().enumerate() {
        let (m, se) = diff_stats(stacked, &full_a, noise, px, lum);
        let block_level = px.iter().map(|&i| lum(&full_a.rgba[i])).sum::<f64>() / px.len() as f64;
        assert!(m.abs() < K_BLOCK * se + 0.02 * block_level, "block {b}: deep comp - full {m:+.5} (se {se:.5})");
    }
    let (z, b, d) = worst_block(stacked, &full_a, noise, |p| p[3] as f64);
    assert!(z < K_BLOCK, "alpha block {b} differs by {z:.2} sigma ({d:+.5})");
    // Equal to today's flat comp within noise: the same layers' samples.
    let flat = throng::comp::comp_frame(&st.a, STACK_FRAME, Some(&st.manifest)).unwrap().film;
    let (m, se) = diff_stats(stacked, &flat, noise, &all, lum);
    eprintln!("deep comp - flat comp: {m:+.5} (se {se:.5}, {:.2} sigma)", m / se);
    assert!((m / se).abs() < K_MEAN, "deep comp differs from the flat comp by {:.2} sigma", m / se);
    let (z, b, d) = worst_block(stacked, &flat, noise, lum);
    assert!(z < K_BLOCK, "block {b}: deep comp - flat comp {d:+.5} ({z:.2} sigma)");
    // Negative control: the merge without the set layer is far off.
    let crowd: Vec<DeepImage> = STACK_LAYERS[1..].iter().map(|l| stack_deep(l)).collect();
    let no_set = throng::comp::deep::merge(&crowd.iter().collect::<Vec<_>>()).unwrap();
    let mut no_set_film = stacked.clone();
    no_set_film.rgba = no_set.flatten();
    let (z, _, _) = worst_block(&no_set_film, &full_a, noise, lum);
    assert!(z > 4.0 * K_BLOCK, "dropping the set must fail the block test ({z:.1} sigma)");
}

/// A sphere of radius `radius` centred at `centre` (OpenEXR camera space:
/// +z forward, y up) rendered analytically as its own deep image with the
/// camera of `meta`: 4 x 4 rays a pixel, each intersected with the sphere
/// exactly; a pixel's hits make one deep sample of flat colour `rgb`,
/// alpha the share of rays that hit, `Z`/`ZBack` their nearest and
/// farthest depth.
fn sphere_deep(meta: &LayerMeta, w: u32, h: u32, centre: glam::Vec3, radius: f32, rgb: [f32; 3]) -> DeepImage {
    use glam::{Mat4, Vec3};
    // NDC = P * camera (docs/render.md, "Header"): ndc.x = m00 x / z + 0.5, ndc.y = m11 y / z + 0.5.
    let p = Mat4::from_cols_array(&meta.world_to_ndc) * Mat4::from_cols_array(&meta.world_to_camera).inverse();
    let (m00, m11) = (p.x_axis.x, p.y_axis.y);
    const RAYS: u32 = 4;
    let mut img = DeepImage { width: w, height: h, ..Default::default() };
    for y in 0..h {
        for x in 0..w {
            let (mut hits, mut near, mut far) = (0u32, f32::INFINITY, 0.0f32);
            for k in 0..RAYS * RAYS {
                let u = (x as f32 + ((k % RAYS) as f32 + 0.5) / RAYS as f32) / w as f32;
                let v = (y as f32 + ((k / RAYS) as f32 + 0.5) / RAYS as f32) / h as f32;
                let d = Vec3::new((u - 0.5) / m00, (v - 0.5) / m11, 1.0);
                // |t d - c|^2 = r^2, nearest root; depth = t (d.z = 1).
                let (a, b, c) = (d.length_squared(), d.dot(centre), centre.length_squared() - radius * radius);
                let disc = b * b - a * c;
                if disc >= 0.0 {
                    let t = (b - disc.sqrt()) / a;
                    hits += 1;
                    near = near.min(t);
                    far = far.max(t);
                }
            }
            let n = if hits > 0 { 1 } else { 0 };
            img.counts.push(n);
            if hits > 0 {
                let alpha = hits as f32 / (RAYS * RAYS) as f32;
                img.samples.push(DeepSample {
                    rgba: [rgb[0] * alpha, rgb[1] * alpha, rgb[2] * alpha, alpha],
                    z: near,
                    z_back: far,
                    agent_id: 0.0,
                    object_id: f32::from_bits(0x4f00_0001),
                });
            }
        }
    }
    img
}

#[test]
fn an_external_sphere_merges_among_the_agents_per_pixel() {
    use glam::Vec3;
    let st = stack();
    let layers: Vec<DeepImage> = STACK_LAYERS.iter().map(|l| stack_deep(l)).collect();
    let set_path = throng::output::layer_path(&st.a, "stack", "set", STACK_FRAME);
    let (set_flat, meta) = read_layer(&set_path).unwrap();
    let (w, h) = (set_flat.width, set_flat.height);
    // The sphere stands at crowd1's depth (agent 2's median) between the
    // left crowd0 agent (nearer, x 15-24 at 96x54) and the left crowd2 agent
    // (farther, x 26-31), overlapping both in the image: centre pixel
    // (23, 22), a radius of 6 pixels.
    let crowd1_depths = {
        let mut z: Vec<f32> = layers[2].pixels().filter_map(|p| p.first().map(|s| s.z)).collect();
        z.sort_by(f32::total_cmp);
        z
    };
    assert!(crowd1_depths.len() > 50, "agent 2 is in crowd1's deep layer");
    let zc = crowd1_depths[crowd1_depths.len() / 2];
    let p =
        glam::Mat4::from_cols_array(&meta.world_to_ndc) * glam::Mat4::from_cols_array(&meta.world_to_camera).inverse();
    assert_eq!((w, h), (96, 54), "the fixture's image size");
    let (cx, cy, r_px) = (23.5f32, 22.5f32, 6.0f32);
    let centre = Vec3::new((cx / w as f32 - 0.5) / p.x_axis.x * zc, (cy / h as f32 - 0.5) / p.y_axis.y * zc, zc);
    let radius = r_px / (w as f32 * p.x_axis.x) * zc;
    const MAGENTA: [f32; 3] = [1.0, 0.0, 1.0];
    let sphere = sphere_deep(&meta, w, h, centre, radius, MAGENTA);
    // Through the file, as an element from another renderer would come.
    let path = out_dir("sphere").join("sphere.deep.exr");
    write_deep(&path, &sphere, &set_flat, &LayerMeta { layer: "sphere".into(), ..meta.clone() }, DeepCompression::Zips)
        .unwrap();
    let sphere = read_deep(&path).unwrap().0;
    // Layer order does not matter in a deep merge: the sphere goes last.
    let mut with: Vec<&DeepImage> = layers.iter().collect();
    let without = throng::comp::deep::merge(&with).unwrap().flatten();
    with.push(&sphere);
    let merged = throng::comp::deep::merge(&with).unwrap();
    let flat = merged.flatten();
    let crowd_pixels: Vec<Vec<&[DeepSample]>> = {
        let mut it: Vec<_> = layers[1..].iter().map(|l| l.pixels()).collect();
        (0..w * h).map(|_| it.iter_mut().map(|p| p.next().unwrap()).collect()).collect()
    };
    let (mut covered_by_agents, mut covering_agents) = (0, 0);
    for ((i, s), m) in sphere.pixels().enumerate().zip(merged.pixels()) {
        let [s] = s else { continue };
        if s.rgba[3] < 1.0 {
            continue; // the sphere's silhouette: partly covered pixels
        }
        let agents: Vec<&DeepSample> = crowd_pixels[i].iter().flat_map(|p| p.iter()).collect();
        // Agents' coverage entirely in front of the sphere, by over.
        let front = agents.iter().filter(|a| a.z_back < s.z).fold(0.0f32, |t, a| t + (1.0 - t) * a.rgba[3]);
        let close =
            |x: [f32; 4], y: [f32; 4]| (0..4).all(|c| (x[c] - y[c]).abs() <= 2e-3 * x[c].abs().max(y[c].abs()) + 1e-4);
        if front >= 0.999 {
            // Agents in front cover it: the sphere adds nothing.
            covered_by_agents += 1;
            assert!(close(flat[i], without[i]), "pixel {i}: agents in front, yet {:?} vs {:?}", flat[i], without[i]);
            assert!(m[0].agent_id != 0.0, "pixel {i}: the front sample is an agent's");
        } else if !agents.is_empty() && agents.iter().all(|a| a.z > s.z_back) {
            // Agents behind are covered: only the sphere shows.
            covering_agents += 1;
            let want = [MAGENTA[0], MAGENTA[1], MAGENTA[2], 1.0];
            assert!(close(flat[i], want), "pixel {i}: agents behind, yet {:?}", flat[i]);
            assert!(!close(without[i], want), "pixel {i}: the agent showed before");
            assert_eq!(m[0].object_id.to_bits(), 0x4f00_0001, "pixel {i}: the front sample is the sphere's");
        }
    }
    eprintln!(
        "sphere pixels covered by agents in front: {covered_by_agents}; covering agents behind: {covering_agents}"
    );
    assert!(
        covered_by_agents >= 10 && covering_agents >= 10,
        "both cases happen ({covered_by_agents}, {covering_agents})"
    );
}

#[test]
fn comp_deep_writes_both_files_and_refuses_a_deep_file_not_throngs() {
    let st = stack();
    let dir = out_dir("comp_cli");
    let out = dir.join("comp.1001.exr");
    let a = s(&st.a);
    let o = throng(&["comp", a, "--frame", "1001", "--out", s(&out), "--deep", "--json"]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let (deep, head) = read_deep(&deep_layer_path(&out)).unwrap();
    assert_eq!(head.state == 3, deep.is_tidy(), "deepImageState is truthful");
    assert_eq!(head.text.get("throng/layer").map(String::as_str), Some("comp"));
    let (flat, _) = read_layer(&out).unwrap();
    assert!(flatten_error(&deep, &flat) <= 1.0, "the flat comp is the deep comp flattened");
    assert!(text(&o.stdout).contains("comp.1001.deep.exr"), "{}", text(&o.stdout));
    // Layers copied, then crowd1's deep file replaced by ones that are not throng's.
    let copy = dir.join("layers");
    for layer in STACK_LAYERS {
        let flat = throng::output::layer_path(&st.a, "stack", layer, STACK_FRAME);
        let to = throng::output::layer_path(&copy, "stack", layer, STACK_FRAME);
        std::fs::create_dir_all(to.parent().unwrap()).unwrap();
        std::fs::copy(&flat, &to).unwrap();
        std::fs::copy(deep_layer_path(&flat), deep_layer_path(&to)).unwrap();
    }
    let victim = deep_layer_path(&throng::output::layer_path(&copy, "stack", "crowd1", STACK_FRAME));
    let crowd0 = deep_layer_path(&throng::output::layer_path(&copy, "stack", "crowd0", STACK_FRAME));
    let flat_crowd1 = throng::output::layer_path(&copy, "stack", "crowd1", STACK_FRAME);
    let out2 = dir.join("bad.exr");
    for (what, bytes) in [
        ("another layer's deep file", std::fs::read(&crowd0).unwrap()),
        ("a flat EXR", std::fs::read(&flat_crowd1).unwrap()),
        ("not an EXR", b"P6 not an image".to_vec()),
    ] {
        std::fs::write(&victim, bytes).unwrap();
        let o = throng(&["comp", s(&copy), "--frame", "1001", "--out", s(&out2), "--deep"]);
        let err = text(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{what}: {err}");
        assert!(err.contains("stack.crowd1.1001.deep.exr"), "{what}: the error names the file: {err}");
        assert!(!out2.exists() && !deep_layer_path(&out2).exists(), "{what}: nothing written");
    }
    std::fs::remove_file(&victim).unwrap();
    let o = throng(&["comp", s(&copy), "--frame", "1001", "--out", s(&out2), "--deep"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(text(&o.stderr).contains("no deep file"), "{}", text(&o.stderr));
}

#[test]
fn is_whole_judges_from_the_header_and_offsets_and_refuses_any_cut() {
    let dir = out_dir("whole");
    // Taller than one chunk per compression's run, with empty lines between.
    let img = synthetic(21, 9);
    let film = Film::new(21, 9);
    for (c, name) in [(DeepCompression::Zips, "zips"), (DeepCompression::Rle, "rle"), (DeepCompression::None, "none")] {
        let path = dir.join(format!("w.{name}.deep.exr"));
        write_deep(&path, &img, &film, &meta(), c).unwrap();
        assert!(is_whole(&path), "{name}: a whole file");
        // The counts alone and the header alone say what the whole read says.
        let (full, head) = read_deep(&path).unwrap();
        let (counts, counts_head) = read_sample_counts(&path).unwrap();
        assert_eq!((counts.width, counts.height, &counts.counts), (full.width, full.height, &full.counts));
        assert!(counts.samples.is_empty());
        assert_eq!(counts_head, head);
        assert_eq!(read_deep_header(&path).unwrap(), head, "{name}");
        // Cut anywhere, from the last byte to the magic number: not whole
        // (one copy cut shorter and shorter).
        let whole = std::fs::read(&path).unwrap();
        let cut = dir.join(format!("cut.{name}.deep.exr"));
        std::fs::write(&cut, &whole).unwrap();
        let shortened = std::fs::OpenOptions::new().write(true).open(&cut).unwrap();
        for len in (0..whole.len()).rev() {
            shortened.set_len(len as u64).unwrap();
            assert!(!is_whole(&cut), "{name}: cut to {len} of {} bytes counted whole", whole.len());
            // The readers refuse it (the counts alone may still be whole), never panic.
            assert!(read_deep(&cut).is_err());
            if let Ok((counts, _)) = read_sample_counts(&cut) {
                assert_eq!(counts.counts, img.counts, "{name}: cut to {len}");
            }
        }
        drop(shortened);
        let chunks_at = first_chunk(&whole, 9);
        // An offset table not yet filled in (zeros), or one offset pointing
        // past the end: not whole.
        let mut zeroed = whole.clone();
        zeroed[chunks_at - 72..chunks_at].fill(0);
        std::fs::write(&cut, &zeroed).unwrap();
        assert!(!is_whole(&cut), "{name}: a zeroed offset table");
        let mut far = whole.clone();
        far[chunks_at - 8..chunks_at].copy_from_slice(&(whole.len() as u64).to_le_bytes());
        std::fs::write(&cut, &far).unwrap();
        assert!(!is_whole(&cut), "{name}: an offset past the end");
        // Judged without reading every chunk: a first chunk that says it is
        // another line passes the check and fails the whole read.
        let mut relabelled = whole.clone();
        relabelled[chunks_at..chunks_at + 4].copy_from_slice(&5i32.to_le_bytes());
        std::fs::write(&cut, &relabelled).unwrap();
        assert!(is_whole(&cut) && read_deep(&cut).is_err(), "{name}: judged from the header and offsets");
    }
    // Bytes flipped anywhere (a fixed xorshift sequence): every reader
    // answers, none panics, and a file the whole read accepts is whole.
    let whole = std::fs::read(dir.join("w.rle.deep.exr")).unwrap();
    let flipped = dir.join("flipped.deep.exr");
    let mut x = 0x9e37_79b9_7f4a_7c15u64;
    for _ in 0..300 {
        let mut bytes = whole.clone();
        for _ in 0..3 {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            let at = (x % bytes.len() as u64) as usize;
            bytes[at] ^= (x >> 32) as u8 | 1;
        }
        std::fs::write(&flipped, &bytes).unwrap();
        let read = read_deep(&flipped);
        let _ = (read_sample_counts(&flipped), read_deep_header(&flipped));
        assert!(read.is_err() || is_whole(&flipped));
    }
    // A header longer than the first read (64 KiB): read on until it ends.
    let long = LayerMeta { shot: "x".repeat(300_000), ..meta() };
    let path = dir.join("long.deep.exr");
    write_deep(&path, &img, &film, &long, DeepCompression::Zips).unwrap();
    assert!(is_whole(&path));
    assert_eq!(read_deep_header(&path).unwrap(), read_deep(&path).unwrap().1);
    let whole = std::fs::read(&path).unwrap();
    let cut = dir.join("cut.long.deep.exr");
    for len in [70_000, 299_000, whole.len() - 1] {
        std::fs::write(&cut, &whole[..len]).unwrap();
        assert!(!is_whole(&cut), "a long header cut to {len} of {} bytes", whole.len());
    }
    // Not a deep file at all.
    let flat = dir.join("flat.exr");
    std::fs::write(&flat, b"P6 not an image").unwrap();
    assert!(!is_whole(&flat) && !is_whole(&dir.join("missing.deep.exr")));
}

/// Where a deep file's first chunk starts (the line offset table of
/// `height` entries ends there): the first place whose u64 is its own
/// position plus the table's length.
fn first_chunk(file: &[u8], height: usize) -> usize {
    (8..file.len() - 8)
        .find(|&at| u64::from_le_bytes(file[at..at + 8].try_into().unwrap()) as usize == at + 8 * height)
        .expect("a line offset table")
        + 8 * height
}

/// `render --json` of `shot` (demo `full`, frame 1024, 160x90 at 4 spp, as
/// `.ci/run` renders it) into `out`: the summary.
fn render_full_json(shot: &Path, manifest: &Path, out: &Path) -> serde_json::Value {
    let f = FRAME.to_string();
    let args = ["render", s(shot), "--manifest", s(manifest), "--layer", "full", "--frames", &f];
    let rest = ["--spp", "4", "--resolution", "160x90", "--progress", "off", "--json", "--out", s(out)];
    let o = throng(&[&args[..], &rest[..]].concat());
    assert!(o.status.success(), "{}", text(&o.stderr));
    serde_json::from_slice(&o.stdout).unwrap()
}

#[test]
fn rle_and_zips_renders_of_a_frame_hold_the_same_samples() {
    let dir = out_dir("rle_zips");
    let manifest = dir.join("demo.layers.json");
    let o = throng(&["layers", s(&demo_shot()), "--out", s(&manifest)]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let mut images = Vec::new();
    for name in ["rle", "zips"] {
        let shot = shot_with(name, &format!("{{ compression = \"{name}\" }}"));
        let out = dir.join(name);
        let v = render_full_json(&shot, &manifest, &out);
        let _ = std::fs::remove_file(&shot);
        let path = deep_layer_path(&throng::output::layer_path(&out, "demo", "full", FRAME));
        let (image, head) = read_deep(&path).unwrap();
        assert_eq!(head.compression, Some(if name == "rle" { DeepCompression::Rle } else { DeepCompression::Zips }));
        // render --json: the deep file's size per megapixel and samples, and the peak memory.
        let row = &v["layer_frames"][0];
        let d = &row["deep"];
        let bytes = std::fs::metadata(&path).unwrap().len();
        assert_eq!(d["file_bytes"].as_u64(), Some(bytes), "{name}: {d}");
        assert_eq!(d["bytes_per_megapixel"].as_u64(), Some((bytes as f64 * 1e6 / (160.0 * 90.0)).round() as u64));
        assert_eq!(d["samples"].as_u64(), Some(image.samples.len() as u64), "{name}: {d}");
        assert_eq!(d["max_samples_per_pixel"].as_u64(), Some(image.max_samples() as u64));
        assert!(row["peak_rss_bytes"].as_u64().is_some_and(|b| b > 1 << 20), "{row}");
        images.push(image);
    }
    let (rle, zips) = (&images[0], &images[1]);
    assert!(rle.samples.len() > 1000, "{} samples", rle.samples.len());
    assert_eq!(rle.counts, zips.counts, "per-pixel sample counts");
    // Bit for bit (NaN-free: compared as bits so -0 and 0 differ too).
    let bits = |i: &DeepImage| -> Vec<[u32; 8]> {
        i.samples
            .iter()
            .map(|s| {
                let [r, g, b, a] = s.rgba.map(f32::to_bits);
                [r, g, b, a, s.z.to_bits(), s.z_back.to_bits(), s.agent_id.to_bits(), s.object_id.to_bits()]
            })
            .collect()
    };
    assert!(bits(rle) == bits(zips), "every sample's values");
}

/// A GET of `target` from the review server at `addr`: status and body.
fn http_get(addr: &str, target: &str) -> (u16, Vec<u8>) {
    use std::io::{Read, Write};
    let mut stream = std::net::TcpStream::connect(addr).unwrap();
    stream.set_read_timeout(Some(std::time::Duration::from_secs(120))).unwrap();
    // HTTP/1.0: the body ends with the connection, never chunked.
    stream.write_all(format!("GET {target} HTTP/1.0\r\nHost: {addr}\r\n\r\n").as_bytes()).unwrap();
    let mut bytes = Vec::new();
    stream.read_to_end(&mut bytes).unwrap();
    let split = bytes.windows(4).position(|w| w == b"\r\n\r\n").expect("a complete HTTP answer");
    let head = String::from_utf8_lossy(&bytes[..split]).into_owned();
    let status = head.split(' ').nth(1).unwrap().parse().unwrap();
    (status, bytes[split + 4..].to_vec())
}

#[test]
fn review_shows_a_deep_layers_samples_per_pixel() {
    let dir = out_dir("review");
    let manifest = dir.join("demo.layers.json");
    let o = throng(&["layers", s(&demo_shot()), "--out", s(&manifest)]);
    assert!(o.status.success(), "{}", text(&o.stderr));
    let renders = dir.join("render");
    let (f, shot) = (FRAME.to_string(), demo_shot());
    let args = ["render", s(&shot), "--manifest", s(&manifest), "--layer", "all", "--frames", &f];
    let rest = ["--spp", "2", "--resolution", "64x36", "--deep", "--progress", "off", "--out", s(&renders)];
    let o = throng(&[&args[..], &rest[..]].concat());
    assert!(o.status.success(), "{}", text(&o.stderr));
    // crowd2 without its deep file: no samples view.
    std::fs::remove_file(deep_layer_path(&throng::output::layer_path(&renders, "demo", "crowd2", FRAME))).unwrap();
    let (tx, rx) = std::sync::mpsc::channel();
    let options = throng::review::ReviewOptions {
        renders: Some(renders.clone()),
        manifest: Some(manifest.clone()),
        port: 0,
        ..Default::default()
    };
    std::thread::spawn(move || {
        let shot = demo_shot();
        let review = throng::review::Review::open(ShotCrowd::load(&shot).unwrap(), &shot, &options).unwrap();
        tx.send((review.addr().to_string(), review.stopper())).unwrap();
        review.serve();
    });
    let (addr, stopper) = rx.recv_timeout(std::time::Duration::from_secs(120)).expect("the review server started");
    let (status, body) = http_get(&addr, &format!("/api/layers?frame={FRAME}"));
    assert_eq!(status, 200, "{}", text(&body));
    let v: serde_json::Value = serde_json::from_slice(&body).unwrap();
    let mut shown = 0;
    for l in v["layers"].as_array().unwrap() {
        let layer = l["name"].as_str().unwrap();
        let q = format!("/api/deep.png?frame={FRAME}&layer={layer}");
        if layer == "crowd2" {
            assert!(l["deep"].is_null(), "{l}");
            assert_eq!(http_get(&addr, &q).0, 404, "crowd2 has no deep file");
            continue;
        }
        let flat = throng::output::layer_path(&renders, "demo", layer, FRAME);
        let (deep, _) = read_deep(&deep_layer_path(&flat)).unwrap();
        let max = deep.max_samples();
        assert_eq!(l["deep"]["view"], "samples", "{l}");
        assert_eq!(l["deep"]["max"].as_u64(), Some(max as u64), "{layer}: the legend's max");
        let ramp: Vec<&str> = l["deep"]["ramp"].as_array().unwrap().iter().map(|c| c.as_str().unwrap()).collect();
        let (status, png) = http_get(&addr, &q);
        assert_eq!(status, 200, "{layer}: {}", text(&png));
        let img = image::load_from_memory(&png).unwrap().to_rgb8();
        assert_eq!(img.dimensions(), (64, 36));
        let hex = |p: &image::Rgb<u8>| format!("#{:02x}{:02x}{:02x}", p[0], p[1], p[2]);
        // Black where a pixel holds no sample, the ramp's foot at 1 and its
        // top at the layer's most.
        let mut by_count: std::collections::BTreeMap<u32, String> = Default::default();
        for (p, &n) in img.pixels().zip(&deep.counts) {
            assert_eq!(n == 0, hex(p) == "#000000", "{layer}: {n} samples drawn {}", hex(p));
            let seen = by_count.entry(n).or_insert_with(|| hex(p));
            assert_eq!(*seen, hex(p), "{layer}: one colour per count");
        }
        assert_eq!(by_count.get(&max).map(String::as_str), Some(*ramp.last().unwrap()), "{layer}");
        if max > 1 {
            assert_eq!(by_count.get(&1).map(String::as_str), Some(ramp[0]), "{layer}");
        }
        shown += 1;
    }
    assert_eq!(shown, 3, "set, crowd1 and crowd0 have deep files");
    assert_eq!(http_get(&addr, &format!("/api/deep.png?frame={FRAME}&layer=comp")).0, 404);
    let (_, js) = http_get(&addr, "/page.js");
    assert!(text(&js).contains("/api/deep.png"), "the page offers the view");
    stopper.stop();
}
