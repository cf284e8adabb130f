//! The comp property: the set layer and the crowd layers stacked back
//! together match a single full render within Monte Carlo noise, on a small
//! shot (tests/fixtures/stack_shot) made so that cross-layer shadows, floor
//! shadows and floor reflections all matter. Noise is estimated from two full
//! renders with different seeds. Also: the pieces are really there (a
//! negative control that drops them must fail the same test), comp's file
//! finding and errors, and botinfo by pixel. See docs/compositing.md.
//!
//! Renders land in `target/tmp/comp/` (PNGs beside the EXRs) for looking at.

mod common;

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use common::stack_stats::{blocks, diff_stats, lum, worst_block};
use throng::casting::ShotCrowd;
use throng::comp;
use throng::layers::{LayerOverrides, Manifest};
use throng::render::exr;
use throng::render::job::{self, RenderJob};
use throng::render::Film;

const SHOT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/fixtures/stack_shot/shot.toml");
const FRAME: i32 = 1001;
/// Samples per pixel; `THRONG_COMP_SPP` overrides it for the measurements
/// in docs/compositing.md (output then goes to `target/tmp/comp-<spp>/`).
const SPP: u32 = 128;

fn spp() -> u32 {
    std::env::var("THRONG_COMP_SPP").ok().and_then(|s| s.parse().ok()).unwrap_or(SPP)
}
/// Per-block bound in standard errors. 84 blocks: a 5-sigma excursion of
/// pure noise has odds of about 1 in 40 000 per run.
const K_BLOCK: f64 = 5.0;
/// Bound on the whole-image mean, in standard errors.
const K_MEAN: f64 = 4.0;

struct Renders {
    dir: PathBuf,
    manifest: Manifest,
    /// Layer files of seed A (set, crowd layers, full).
    a: PathBuf,
    /// The full render again with another seed.
    full_b: Film,
    /// The set layer rendered with every agent removed.
    set_bare: Film,
    /// crowd1 rendered with agent 1 (crowd0) removed.
    crowd1_without_1: Film,
}

fn out_dir() -> PathBuf {
    let tmp = Path::new(env!("CARGO_TARGET_TMPDIR"));
    if spp() == SPP {
        tmp.join("comp")
    } else {
        tmp.join(format!("comp-{}", spp()))
    }
}

fn layers_args() -> LayerOverrides {
    LayerOverrides::default()
}

fn render(crowd: &ShotCrowd, manifest: &Manifest, layers: &[&str], out: &Path) {
    let job = RenderJob {
        layers: layers.iter().map(|s| s.to_string()).collect(),
        frames: vec![FRAME],
        spp: spp(),
        threads: 0,
        out: out.to_path_buf(),
        resume: false,
        png: true,
        resolution: None,
        cryptomatte: job::CryptoOutput::Header,
        compression: Default::default(),
        shutter: None,
        colourspace: Default::default(),
        passes: None,
        adaptive: None,
        tracing: Default::default(),
        denoise: None,
        deep: None,
    };
    job::run(crowd, Some(manifest), &job, &job::Silent).unwrap();
}

fn read(dir: &Path, layer: &str) -> Film {
    exr::read_layer(&throng::output::layer_path(dir, "stack", layer, FRAME)).unwrap().0
}

fn renders() -> &'static Renders {
    static R: OnceLock<Renders> = OnceLock::new();
    R.get_or_init(|| {
        let dir = out_dir();
        let _ = std::fs::remove_dir_all(&dir);
        let crowd = ShotCrowd::load(Path::new(SHOT)).unwrap();
        let manifest = throng::layers::build_layers(&crowd, &layers_args()).unwrap();
        throng::layers::write_manifest(&dir.join("stack.layers.json"), &manifest).unwrap();
        let a = dir.join("a");
        render(&crowd, &manifest, &["set", "crowd2", "crowd1", "crowd0", "full"], &a);
        // Another seed: an independent sample of the same full render.
        let seed = crowd.shot().seed;
        let crowd = crowd.with_shot(|shot| shot.seed = seed + 1).unwrap();
        render(&crowd, &manifest, &["full"], &dir.join("b"));
        // Removal keeps casting and layers, so only these agents go.
        let crowd = crowd
            .with_shot(|shot| {
                shot.seed = seed;
                shot.removed = manifest.agents.iter().map(|a| a.id).collect();
            })
            .unwrap();
        render(&crowd, &manifest, &["set"], &dir.join("bare"));
        let crowd = crowd.with_shot(|shot| shot.removed = vec![1]).unwrap();
        render(&crowd, &manifest, &["crowd1"], &dir.join("without1"));
        Renders {
            full_b: read(&dir.join("b"), "full"),
            set_bare: read(&dir.join("bare"), "set"),
            crowd1_without_1: read(&dir.join("without1"), "crowd1"),
            dir,
            manifest,
            a,
        }
    })
}

fn comped(set: Option<&Film>) -> Film {
    let r = renders();
    let back = set.cloned().unwrap_or_else(|| read(&r.a, "set"));
    let layers = [back, read(&r.a, "crowd2"), read(&r.a, "crowd1"), read(&r.a, "crowd0")];
    comp::over(&layers.iter().collect::<Vec<_>>()).unwrap()
}

#[test]
fn layers_are_split_as_the_fixture_says() {
    let m = &renders().manifest;
    assert_eq!(m.comp_order, ["set", "crowd2", "crowd1", "crowd0"]);
    let layer = |id: u32| m.agent(id).unwrap().layer;
    assert_eq!([layer(1), layer(4), layer(2), layer(3), layer(5)], [0, 0, 1, 2, 2]);
}

#[test]
fn stack_matches_full_render_within_noise() {
    let r = renders();
    let full_a = read(&r.a, "full");
    let stack = comped(None);
    let noise = (&full_a, &r.full_b);
    let all: Vec<usize> = (0..full_a.rgba.len()).collect();

    let (m, se) = diff_stats(&stack, &full_a, noise, &all, lum);
    let level = all.iter().map(|&i| lum(&full_a.rgba[i])).sum::<f64>() / all.len() as f64;
    eprintln!(
        "mean lum: full {level:.4}, stack - full {m:+.5} (se {se:.5}, {:.2} sigma, {:+.3}%)",
        m / se,
        100.0 * m / level
    );
    assert!((m / se).abs() < K_MEAN, "mean differs by {:.2} sigma", m / se);
    assert!((m / level).abs() < 0.005, "mean differs by {:.3}%", 100.0 * m / level);

    // Edges: pixels partly covered by some crowd layer, where premultiplied
    // over is only an approximation of the full render (the set behind a
    // silhouette is averaged over the whole pixel, not just the uncovered
    // part; docs/compositing.md). Per block, interior pixels must match
    // within noise; blocks with edges get 2% of their level on top.
    let layers = ["crowd2", "crowd1", "crowd0"].map(|l| read(&r.a, l));
    let is_edge = |i: usize| layers.iter().any(|l| l.rgba[i][3] > 0.02 && l.rgba[i][3] < 0.98);
    let (mut worst_interior, mut worst_any) = ((0.0f64, 0usize), (0.0f64, 0usize, 0.0f64));
    for (b, px) in blocks(&full_a).iter().enumerate() {
        let interior: Vec<usize> = px.iter().copied().filter(|&i| !is_edge(i)).collect();
        if interior.len() >= 16 {
            let (m, se) = diff_stats(&stack, &full_a, noise, &interior, lum);
            if (m / se).abs() > worst_interior.0 {
                worst_interior = ((m / se).abs(), b);
            }
        }
        let (m, se) = diff_stats(&stack, &full_a, noise, px, lum);
        let block_level = px.iter().map(|&i| lum(&full_a.rgba[i])).sum::<f64>() / px.len() as f64;
        if (m / se).abs() > worst_any.0 {
            worst_any = ((m / se).abs(), b, m);
        }
        assert!(
            m.abs() < K_BLOCK * se + 0.02 * block_level,
            "block {b}: stack - full {m:+.5} (se {se:.5}, level {block_level:.4})"
        );
    }
    eprintln!("worst 8x8 block, interior pixels (luminance): #{}, {:.2} sigma", worst_interior.1, worst_interior.0);
    eprintln!(
        "worst 8x8 block, all pixels (luminance): #{}, {:.2} sigma ({:+.5})",
        worst_any.1, worst_any.0, worst_any.2
    );
    assert!(
        worst_interior.0 < K_BLOCK,
        "interior of block {} differs by {:.2} sigma",
        worst_interior.1,
        worst_interior.0
    );
    let (z, b, d) = worst_block(&stack, &full_a, noise, |p| p[3] as f64);
    eprintln!("worst 8x8 block (alpha): #{b}, {z:.2} sigma ({d:+.5})");
    assert!(z < K_BLOCK, "alpha block {b} differs by {z:.2} sigma");
    let edge: Vec<usize> = all.iter().copied().filter(|&i| is_edge(i)).collect();
    let (m, se) = diff_stats(&stack, &full_a, noise, &edge, lum);
    let edge_level = edge.iter().map(|&i| lum(&full_a.rgba[i])).sum::<f64>() / edge.len().max(1) as f64;
    eprintln!(
        "edge pixels: {} of {}, level {edge_level:.4}, stack - full {m:+.5} (se {se:.5}, {:.2} sigma, {:+.2}%)",
        edge.len(),
        all.len(),
        m / se,
        100.0 * m / edge_level
    );
    assert!(m.abs() < K_BLOCK * se + 0.02 * edge_level);
    let rgb_max = |p: &[f32; 4]| p[0].max(p[1]).max(p[2]) as f64;
    let (z, b, d) = worst_block(&stack, &full_a, noise, rgb_max);
    eprintln!("worst 8x8 block (max RGB): #{b}, {z:.2} sigma ({d:+.5})");

    // The stack's noise is comparable to a full render's (rms against the
    // other seed's full render).
    let rms = |x: &Film, y: &Film| {
        (all.iter().map(|&i| (lum(&x.rgba[i]) - lum(&y.rgba[i])).powi(2)).sum::<f64>() / all.len() as f64).sqrt()
    };
    let (rs, rf) = (rms(&stack, &r.full_b), rms(&full_a, &r.full_b));
    eprintln!("rms lum vs full(seed B): stack {rs:.5}, full(seed A) {rf:.5}");
    assert!(rs < 1.5 * rf);

    // The AOVs stack too: ids agree wherever both centre samples agree on depth.
    let same = all.iter().filter(|&&i| stack.agent_id[i] == full_a.agent_id[i]).count();
    eprintln!("agent.id agrees on {same} of {} pixels", all.len());
    assert!(same as f64 > 0.9 * all.len() as f64);
}

#[test]
fn dropping_agents_from_the_set_layer_is_caught() {
    // Negative control: the set layer without the agents' shadows and
    // reflections must fail the very test the real stack passes.
    let r = renders();
    let full_a = read(&r.a, "full");
    let broken = comped(Some(&r.set_bare));
    let (z, b, _) = worst_block(&broken, &full_a, (&full_a, &r.full_b), lum);
    eprintln!("stack without agents in the set layer: worst block #{b} at {z:.1} sigma");
    assert!(z > 2.0 * K_BLOCK);
}

#[test]
fn floor_shadows_and_reflections_are_in_the_set_layer() {
    let r = renders();
    let full_a = read(&r.a, "full");
    let set = read(&r.a, "set");
    let noise = (&full_a, &r.full_b);
    let stack = comped(None);
    let bare_stack = comped(Some(&r.set_bare));

    // Shadows: floor pixels (no agent in front) clearly darker with agents
    // (the sky lights the shadows, and thin limbs cast partial ones at this size).
    for t in [0.6, 0.7, 0.8, 0.9] {
        let n = (0..set.rgba.len())
            .filter(|&i| full_a.agent_id[i] == 0 && lum(&set.rgba[i]) < t * lum(&r.set_bare.rgba[i]))
            .count();
        eprintln!("set pixels darker than {t} x bare: {n}");
    }
    let shadow: Vec<usize> = (0..set.rgba.len())
        .filter(|&i| {
            full_a.agent_id[i] == 0 && stack.rgba[i][3] > 0.99 && lum(&set.rgba[i]) < 0.8 * lum(&r.set_bare.rgba[i])
        })
        .collect();
    let (m, se) = diff_stats(&stack, &bare_stack, noise, &shadow, lum);
    eprintln!("floor shadow pixels: {}, stack darker by {m:.4} ({:.1} sigma)", shadow.len(), -m / se);
    assert!(shadow.len() >= 20, "only {} shadow pixels", shadow.len());
    assert!(m / se < -10.0);
    let (m, se) = diff_stats(&stack, &full_a, noise, &shadow, lum);
    assert!((m / se).abs() < K_BLOCK, "shadow region: stack - full {m:+.5} = {:.2} sigma", m / se);

    // Reflections: below each agent's feet, where the floor mirrors it.
    let cam = &r.manifest.camera;
    let mut mirror = Vec::new();
    for a in &r.manifest.agents {
        let p = glam::Vec3::from(a.position);
        let (fx, fy, _) = cam.project(p).unwrap();
        let (_, hy, _) = cam.project(p - glam::Vec3::Y * 0.6 * a.height_m).unwrap();
        for y in (fy.ceil() as u32 + 1)..=(hy as u32).min(set.height - 1) {
            for x in (fx as u32).saturating_sub(1)..=(fx as u32 + 1).min(set.width - 1) {
                let i = set.index(x, y);
                if full_a.agent_id[i] == 0 && stack.rgba[i][3] > 0.99 {
                    mirror.push(i);
                }
            }
        }
    }
    mirror.sort();
    mirror.dedup();
    let (m, se) = diff_stats(&stack, &bare_stack, noise, &mirror, lum);
    eprintln!("reflection pixels: {}, stack - stack(bare set) {m:+.4} ({:.1} sigma)", mirror.len(), m / se);
    assert!(mirror.len() >= 10);
    assert!((m / se).abs() > 5.0, "no reflection of the agents in the floor");
    let (m, se) = diff_stats(&stack, &full_a, noise, &mirror, lum);
    assert!((m / se).abs() < K_BLOCK, "reflection region: stack - full {m:+.5} = {:.2} sigma", m / se);
}

#[test]
fn cross_layer_shadow_falls_on_the_agent_behind() {
    // Agent 1 (crowd0) shadows agent 2 (crowd1): crowd1's render of agent 2
    // is darker with agent 1 than without, and the stack keeps it.
    let r = renders();
    let full_a = read(&r.a, "full");
    let crowd1 = read(&r.a, "crowd1");
    let stack = comped(None);
    let agent2: Vec<usize> =
        (0..crowd1.rgba.len()).filter(|&i| full_a.agent_id[i] == 3 && crowd1.agent_id[i] == 3).collect();
    let noise = (&full_a, &r.full_b);
    let (m, se) = diff_stats(&crowd1, &r.crowd1_without_1, noise, &agent2, lum);
    eprintln!("agent 2: {} pixels, darker by {:.4} ({:.1} sigma) with agent 1's shadow", agent2.len(), -m, -m / se);
    assert!(agent2.len() >= 20);
    assert!(m / se < -5.0, "agent 1 casts no shadow on agent 2 in crowd1");
    let (m, se) = diff_stats(&stack, &full_a, noise, &agent2, lum);
    assert!((m / se).abs() < K_BLOCK, "agent 2: stack - full {m:+.5} = {:.2} sigma", m / se);
}

#[test]
fn comp_finds_layers_and_writes_exr() {
    let r = renders();
    // By manifest and by scanning (the `full` directory is ignored).
    let with = comp::comp_frame(&r.a, FRAME, Some(&r.manifest)).unwrap();
    let scanned = comp::comp_frame(&r.a, FRAME, None).unwrap();
    assert_eq!(with.film, scanned.film);
    assert_eq!(with.layers.iter().map(|l| l.0.as_str()).collect::<Vec<_>>(), ["set", "crowd2", "crowd1", "crowd0"]);
    assert_eq!(with.film, comped(None));
    let out = r.dir.join("comp.1001.exr");
    exr::write_layer(&out, &with.film, &with.meta).unwrap();
    exr::write_preview_png(&out.with_extension("png"), &with.film).unwrap();
    let (back, meta) = exr::read_layer(&out).unwrap();
    assert_eq!((meta.layer.as_str(), meta.shot.as_str(), meta.frame), ("comp", "stack", FRAME));
    assert_eq!(back.agent_id, with.film.agent_id);
    assert!(meta.near > 0.0 && meta.far > meta.near);

    // A missing layer is named.
    let partial = r.dir.join("partial");
    for l in ["set", "crowd2", "crowd0"] {
        let from = throng::output::layer_path(&r.a, "stack", l, FRAME);
        let to = throng::output::layer_path(&partial, "stack", l, FRAME);
        std::fs::create_dir_all(to.parent().unwrap()).unwrap();
        std::fs::copy(from, to).unwrap();
    }
    for m in [Some(&r.manifest), None] {
        let e = comp::comp_frame(&partial, FRAME, m).unwrap_err().to_string();
        assert!(e.contains("crowd1") && e.contains("missing"), "{e}");
    }
    let e = comp::comp_frame(&r.a, 1002, None).unwrap_err().to_string();
    assert!(e.contains("1002"), "{e}");
}

/// (success, stdout, stderr) of a `throng` run.
fn throng(args: &[&str]) -> (bool, String, String) {
    let (code, stdout, stderr) = common::run(args);
    (code == 0, stdout, stderr)
}

#[test]
fn comp_and_botinfo_on_the_command_line() {
    let r = renders();
    let dir = r.a.to_str().unwrap();
    let out = r.dir.join("cli.comp.exr");
    let png = r.dir.join("cli.comp.png");
    let manifest = r.dir.join("stack.layers.json");
    let (ok, stdout, stderr) = throng(&[
        "comp",
        dir,
        "--frame",
        "1001",
        "--out",
        out.to_str().unwrap(),
        "--png",
        png.to_str().unwrap(),
        "--manifest",
        manifest.to_str().unwrap(),
    ]);
    assert!(ok, "{stderr}");
    assert!(stdout.contains("set, crowd2, crowd1, crowd0"), "{stdout}");
    assert!(png.is_file());

    // The pixel of agent 2 (id channel 3) in the comp.
    let (film, _) = exr::read_layer(&out).unwrap();
    let i = film.agent_id.iter().position(|&id| id == 3).unwrap();
    let pixel = format!("{},{}", i as u32 % film.width, i as u32 / film.width);
    let (ok, stdout, stderr) = throng(&["botinfo", SHOT, "--exr", out.to_str().unwrap(), "--pixel", &pixel]);
    assert!(ok, "{stderr}");
    assert!(stdout.contains("Agent ID  2") && stdout.contains("Rig       bipedTallB"), "{stdout}");
    assert!(stdout.contains("Cycle     IdleA"), "{stdout}");

    // Sky (top-left corner): no agent.
    let (ok, stdout, _) = throng(&["botinfo", SHOT, "--exr", out.to_str().unwrap(), "--pixel", "0,0"]);
    assert!(ok && stdout.contains("no agent at pixel 0,0 (set or sky)"), "{stdout}");
    // Outside the image, no shot, bad pixel: clear errors.
    let (ok, _, stderr) = throng(&["botinfo", SHOT, "--exr", out.to_str().unwrap(), "--pixel", "500,3"]);
    assert!(!ok && stderr.contains("outside"), "{stderr}");
    let (ok, _, stderr) = throng(&["botinfo", "--exr", out.to_str().unwrap(), "--pixel", "1,1"]);
    assert!(!ok && stderr.contains("shot `stack`"), "{stderr}");
    let (ok, _, stderr) = throng(&["botinfo", SHOT, "--exr", out.to_str().unwrap(), "--pixel", "1;1"]);
    assert!(!ok && stderr.contains("--pixel"), "{stderr}");
}

/// The comp carries the stacked Cryptomatte: every agent's matte in the comp
/// covers what it covers in the full render (within noise), the set's too,
/// and mattes written to the comp EXR read back with their merged manifests.
#[test]
fn comp_mattes_match_the_full_render() {
    let r = renders();
    let comp = comp::comp_frame(&r.a, FRAME, Some(&r.manifest)).unwrap().film;
    let full = read(&r.a, "full");
    let names: Vec<&str> = comp.cryptomatte.iter().map(|m| m.name.as_str()).collect();
    assert_eq!(names, ["CryptoAgent", "CryptoMaterial", "CryptoPart"]);
    // Named set objects and materials survive the stack: the floor, a
    // building, the floor's glTF material and the robots' wardrobe ones.
    let comp_type = |name: &str| comp.cryptomatte.iter().find(|m| m.name == name).unwrap();
    for type_name in ["CryptoAgent", "CryptoPart"] {
        let m = comp_type(type_name);
        assert!(m.manifest.contains_key("set/floor"), "{type_name}: {:?}", m.manifest.keys());
        assert!(m.manifest.keys().any(|n| n.starts_with("set/building_")), "{type_name}");
        assert!(!m.manifest.contains_key("set"), "{type_name}: unnamed set geometry");
        assert!(m.matte("set/floor").iter().sum::<f32>() > 100.0);
    }
    let materials = comp_type("CryptoMaterial");
    assert!(materials.manifest.contains_key("floor_polished"), "{:?}", materials.manifest.keys());
    assert!(materials.manifest.keys().any(|n| n.starts_with("robots/")), "{:?}", materials.manifest.keys());
    // Where a layer covers the pixel, its materials' coverage adds up to the
    // comp's alpha (no material gets lost in the stack).
    let cover = materials.coverage_sum();
    for (i, px) in comp.rgba.iter().enumerate() {
        assert!(cover[i] <= px[3] + 1e-3, "pixel {i}: material coverage {} over alpha {}", cover[i], px[3]);
    }
    let full_cover: f32 = cover.iter().sum();
    let alpha: f32 = comp.rgba.iter().map(|p| p[3]).sum();
    assert!(full_cover > 0.97 * alpha, "material coverage {full_cover} of alpha {alpha}");
    for m in &comp.cryptomatte {
        let f = full.cryptomatte.iter().find(|f| f.name == m.name).expect("full render has the same matte type");
        // Every name the full render shows is in the comp's manifest.
        for (name, _) in f.manifest.iter().filter(|(n, _)| f.matte(n).iter().sum::<f32>() > 0.0) {
            assert!(m.manifest.contains_key(name), "{}: comp manifest lacks {name}", m.name);
        }
        let mut checked = 0;
        for name in f.manifest.keys() {
            let (a, b): (f32, f32) = (m.matte(name).iter().sum(), f.matte(name).iter().sum());
            if b < 4.0 {
                continue; // a few pixels: too noisy to compare
            }
            assert!(
                (a - b).abs() / b < 0.2,
                "{} `{name}`: {a:.1} pixels in the comp, {b:.1} in the full render",
                m.name
            );
            checked += 1;
        }
        assert!(checked >= 3, "{}: compared {checked} objects", m.name);
        // Ranks are sorted by coverage, highest first.
        for px in m.pairs.chunks_exact(m.ranks) {
            assert!(px.windows(2).all(|w| w[0][1] >= w[1][1]), "{px:?}");
        }
    }
    let out = r.dir.join("comp.mattes.exr");
    let comped = comp::comp_frame(&r.a, FRAME, Some(&r.manifest)).unwrap();
    exr::write_layer(&out, &comped.film, &comped.meta).unwrap();
    let back = throng::render::exr::mattes::read(&out).unwrap();
    assert_eq!(back.len(), 3);
    assert_eq!(back.len(), comped.film.cryptomatte.len());
    for (a, b) in back.iter().zip(&comped.film.cryptomatte) {
        assert_eq!((&a.name, &a.manifest), (&b.name, &b.manifest));
    }
}

/// The stack property in haze (docs/compositing.md, "Atmosphere"): the same
/// shot under air 3 m deep, scattering the low sun and the sky between and
/// behind the agents; the set and crowd layers stacked match the full
/// render within noise, in the mean and per block.
#[test]
fn hazy_stack_matches_full_render_within_noise() {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("comp-haze");
    let _ = std::fs::remove_dir_all(&dir);
    let air = throng::render::atmosphere::Atmosphere {
        density: 0.08,
        albedo: glam::Vec3::splat(0.9),
        anisotropy: 0.3,
        top: 3.0,
        ..Default::default()
    };
    let crowd = ShotCrowd::load(Path::new(SHOT))
        .unwrap()
        .with_shot(|shot| {
            shot.atmosphere = Some(air);
            shot.render.passes = vec!["atmosphere".into(), "atmosphere_transmittance".into()];
        })
        .unwrap();
    let manifest = throng::layers::build_layers(&crowd, &layers_args()).unwrap();
    render(&crowd, &manifest, &["set", "crowd2", "crowd1", "crowd0", "full"], &dir.join("a"));
    let seed = crowd.shot().seed;
    let other = crowd.with_shot(|shot| shot.seed = seed + 1).unwrap();
    render(&other, &manifest, &["full"], &dir.join("b"));
    let full_a = read(&dir.join("a"), "full");
    let full_b = read(&dir.join("b"), "full");
    let layers = ["set", "crowd2", "crowd1", "crowd0"].map(|l| read(&dir.join("a"), l));
    let stack = comp::over(&layers.iter().collect::<Vec<_>>()).unwrap();
    let noise = (&full_a, &full_b);
    let all: Vec<usize> = (0..full_a.rgba.len()).collect();
    let (m, se) = diff_stats(&stack, &full_a, noise, &all, lum);
    let level = all.iter().map(|&i| lum(&full_a.rgba[i])).sum::<f64>() / all.len() as f64;
    eprintln!("haze: mean lum full {level:.4}, stack - full {m:+.5} (se {se:.5}, {:.2} sigma)", m / se);
    assert!((m / se).abs() < K_MEAN, "mean differs by {:.2} sigma", m / se);
    assert!((m / level).abs() < 0.005, "mean differs by {:.3}%", 100.0 * m / level);
    let crowd_layers = &layers[1..];
    let is_edge = |i: usize| crowd_layers.iter().any(|l| l.rgba[i][3] > 0.02 && l.rgba[i][3] < 0.98);
    for (b, px) in blocks(&full_a).iter().enumerate() {
        let interior: Vec<usize> = px.iter().copied().filter(|&i| !is_edge(i)).collect();
        if interior.len() >= 16 {
            let (m, se) = diff_stats(&stack, &full_a, noise, &interior, lum);
            assert!((m / se).abs() < K_BLOCK, "haze: interior of block {b} differs by {:.2} sigma", m / se);
        }
    }
    // The air's passes stack too (docs/compositing.md, "Removing and
    // regrading the air"): the comp's transmittance and glow are the full
    // render's, in the mean, and so is what removing the air leaves.
    let mean_pass = |f: &Film, name: &str| {
        let p = f.passes.iter().find(|p| p.name == name).unwrap_or_else(|| panic!("no {name}"));
        p.data.iter().map(|v| v[0] as f64).sum::<f64>() / p.data.len() as f64
    };
    let removed = |f: &Film| {
        let [t, glow] =
            ["atmosphere_transmittance", "atmosphere"].map(|n| &f.passes.iter().find(|p| p.name == n).unwrap().data);
        let behind = f.rgba.iter().zip(glow).zip(t).map(|((p, g), t)| (p[0] - g[0]) as f64 / (t[0] as f64).max(1e-3));
        behind.sum::<f64>() / f.rgba.len() as f64
    };
    for name in ["atmosphere_transmittance", "atmosphere"] {
        let (s, f, b) = (mean_pass(&stack, name), mean_pass(&full_a, name), mean_pass(&full_b, name));
        assert!(
            s > 0.0 && (s - f).abs() < 0.01 * f + 3.0 * (f - b).abs(),
            "{name}: stack {s}, full {f} (other seed {b})"
        );
    }
    let (s, f, b) = (removed(&stack), removed(&full_a), removed(&full_b));
    assert!((s - f).abs() < 0.01 * f + 3.0 * (f - b).abs(), "haze removed: stack {s}, full {f} (other seed {b})");
    // The air is really there: the hazy full render is not the clear one.
    let clear = read(&renders().a, "full");
    let clear_level = all.iter().map(|&i| lum(&clear.rgba[i])).sum::<f64>() / all.len() as f64;
    assert!((level - clear_level).abs() > 0.02 * clear_level, "haze {level} vs clear {clear_level}");
}
