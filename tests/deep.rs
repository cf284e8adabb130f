//! Deep output (docs/render.md, "Deep output"): the deep scanline writer
//! round-trips through our reader of record, a rendered deep layer keeps
//! its invariants (samples per pixel within the cap, Z <= ZBack, sorted,
//! the truthful deepImageState, crowd layers without set samples) and
//! flattens front to back to its flat beauty, and bad `render.deep` keys
//! exit 2 naming the key. `.ci/deep_check.py` reads the same files with
//! OpenImageIO.

mod common;

use std::path::{Path, PathBuf};

use common::{demo_shot, text, throng};
use throng::render::deep::{DeepImage, DeepSample};
use throng::render::exr::deep::{read_deep, write_deep, DeepCompression};
use throng::render::exr::{read_layer, LayerMeta};
use throng::render::job::deep_layer_path;
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
    for (c, name) in [(DeepCompression::Zips, "zips"), (DeepCompression::None, "none")] {
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
            assert!(err.contains("zips, none"), "the allowed ones are named: {err}");
        }
    }
}
