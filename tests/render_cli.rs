//! `throng render` end to end through the binary: `throng layers`, then the
//! render of one demo frame, the files and headers it writes, `--resume`
//! (skips whole files, re-renders a truncated one), errors and exit codes,
//! and byte-identical output for 1 and 2 threads.

mod common;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use throng::render::exr::{read_layer, ID_MAPPING};

const FRAME: i32 = 1024;

use common::demo_shot;

use common::{text, throng};

fn ok(args: &[&str]) -> String {
    let out = throng(args);
    assert!(
        out.status.success(),
        "throng {} failed ({}):\n{}{}",
        args.join(" "),
        out.status,
        text(&out.stdout),
        text(&out.stderr)
    );
    text(&out.stdout)
}

/// Runs a command that must fail with status 2 and returns its stderr.
fn usage_error(args: &[&str]) -> String {
    let out = throng(args);
    assert_eq!(
        out.status.code(),
        Some(2),
        "throng {} should exit 2:\n{}{}",
        args.join(" "),
        text(&out.stdout),
        text(&out.stderr)
    );
    text(&out.stderr)
}

/// Writes the demo's layer manifest into `dir` (never beside the shot, so the
/// checkout stays clean); returns its path and the layers, back to front.
fn manifest_in(dir: &Path) -> (PathBuf, Vec<String>) {
    let path = dir.join("demo.layers.json");
    let shot = demo_shot();
    ok(&["layers", s(&shot), "--out", s(&path)]);
    let m = throng::layers::read_manifest(&path).expect("manifest reads back");
    (path, m.comp_order)
}

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 temp path")
}

/// Every file under `dir`, relative, with its bytes.
fn files(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    fn walk(root: &Path, dir: &Path, out: &mut BTreeMap<PathBuf, Vec<u8>>) {
        for e in std::fs::read_dir(dir).expect("read dir").flatten() {
            let p = e.path();
            if p.is_dir() {
                walk(root, &p, out);
            } else {
                out.insert(
                    p.strip_prefix(root).expect("under root").to_path_buf(),
                    std::fs::read(&p).expect("read file"),
                );
            }
        }
    }
    let mut out = BTreeMap::new();
    walk(dir, dir, &mut out);
    out
}

// ---------------------------------------------------------------- EXR headers, read independently

/// One header attribute: name, type, raw value.
type Attr = (String, String, Vec<u8>);

/// The header attributes of a single-part scanline EXR, parsed from the
/// bytes (independent of the exr crate the writer uses).
fn exr_header(bytes: &[u8]) -> Vec<Attr> {
    exr_header_and_end(bytes).0
}

/// The header attributes and the offset just past the header.
fn exr_header_and_end(bytes: &[u8]) -> (Vec<Attr>, usize) {
    assert_eq!(bytes.get(..4), Some(&[0x76, 0x2f, 0x31, 0x01][..]), "EXR magic number");
    let mut at = 8;
    let cstr = |at: &mut usize| {
        let end = bytes[*at..].iter().position(|&b| b == 0).expect("NUL-terminated name") + *at;
        let s = text(&bytes[*at..end]);
        *at = end + 1;
        s
    };
    let mut attrs = Vec::new();
    loop {
        let name = cstr(&mut at);
        if name.is_empty() {
            return (attrs, at);
        }
        let ty = cstr(&mut at);
        let size = i32::from_le_bytes(bytes[at..at + 4].try_into().expect("4 bytes")) as usize;
        at += 4;
        attrs.push((name, ty, bytes[at..at + size].to_vec()));
        at += size;
    }
}

fn attr<'a>(attrs: &'a [Attr], name: &str) -> &'a Attr {
    attrs.iter().find(|a| a.0 == name).unwrap_or_else(|| panic!("header attribute `{name}` is missing"))
}

fn attr_text(attrs: &[Attr], name: &str) -> String {
    let a = attr(attrs, name);
    assert_eq!(a.1, "string", "`{name}` type");
    text(&a.2)
}

fn attr_int(attrs: &[Attr], name: &str) -> i32 {
    let a = attr(attrs, name);
    assert_eq!(a.1, "int", "`{name}` type");
    i32::from_le_bytes(a.2[..4].try_into().expect("4 bytes"))
}

/// Channel names of the `chlist` attribute, as stored (sorted).
fn channel_names(attrs: &[Attr]) -> Vec<String> {
    let v = &attr(attrs, "channels").2;
    let mut names = Vec::new();
    let mut at = 0;
    while at < v.len() && v[at] != 0 {
        let end = v[at..].iter().position(|&b| b == 0).expect("channel name") + at;
        names.push(text(&v[at..end]));
        at = end + 1 + 16; // pixel type, pLinear + 3 reserved, x and y sampling
    }
    names
}

/// The file with its header attributes in name order. The exr crate writes
/// custom (`throng/...`) attributes from a `HashMap`, so their order changes
/// from run to run although every byte of every attribute and every pixel
/// chunk is the same; the header keeps its length, so chunk offsets hold.
fn canonical_exr(bytes: &[u8]) -> Vec<u8> {
    let (mut attrs, end) = exr_header_and_end(bytes);
    attrs.sort();
    let mut out = bytes[..8].to_vec();
    for (name, ty, value) in attrs {
        out.extend_from_slice(name.as_bytes());
        out.push(0);
        out.extend_from_slice(ty.as_bytes());
        out.push(0);
        out.extend_from_slice(&(value.len() as i32).to_le_bytes());
        out.extend_from_slice(&value);
    }
    out.push(0);
    assert_eq!(out.len(), end, "canonical header length");
    out.extend_from_slice(&bytes[end..]);
    out
}

/// [`files`] with every EXR canonicalised by [`canonical_exr`].
fn canonical_files(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    files(dir)
        .into_iter()
        .map(|(p, b)| {
            let b = if p.extension().is_some_and(|e| e == "exr") { canonical_exr(&b) } else { b };
            (p, b)
        })
        .collect()
}

// ---------------------------------------------------------------- tests

#[test]
fn layers_render_resume_and_errors() {
    let tmp = common::tempdir().expect("temp dir");
    let (manifest, layers) = manifest_in(tmp.path());
    assert_eq!(layers, ["set", "crowd2", "crowd1", "crowd0"], "the demo's layers, back to front");
    let out = tmp.path().join("out");
    let shot = demo_shot();
    let frame = FRAME.to_string();
    let render = |extra: &[&str]| {
        let mut args = vec![
            "render",
            s(&shot),
            "--manifest",
            s(&manifest),
            "--frames",
            &frame,
            "--spp",
            "2",
            "--resolution",
            "64x36",
        ];
        args.extend_from_slice(&["--png", "--out", s(&out)]);
        args.extend_from_slice(extra);
        ok(&args)
    };
    let said = render(&[]);
    assert!(said.contains("rendered 4 layer-frames (0 skipped as complete)"), "render said:\n{said}");

    // Every layer file, whole, with its channels and header.
    let written = files(&out);
    let mut expected = Vec::new();
    for layer in &layers {
        let exr = PathBuf::from(layer).join(format!("demo.{layer}.{FRAME}.exr"));
        expected.push(exr.clone());
        expected.push(exr.with_extension("png"));
        let path = out.join(&exr);
        let (film, meta) = read_layer(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
        assert_eq!((film.width, film.height), (64, 36), "{layer} size");
        assert_eq!(
            (meta.shot.as_str(), meta.layer.as_str(), meta.frame, meta.seed, meta.spp),
            ("demo", layer.as_str(), FRAME, 1234, 2),
            "{layer} metadata"
        );
        assert_eq!(meta.id_mapping, ID_MAPPING);
        assert!(meta.near > 0.0 && meta.far >= meta.near, "{layer} near/far {} {}", meta.near, meta.far);

        let attrs = exr_header(&written[&exr]);
        let mut names = channel_names(&attrs);
        names.sort();
        let mut want = ["R", "G", "B", "A", "Z", "N.X", "N.Y", "N.Z", "albedo.R", "albedo.G", "albedo.B", "agent.id"];
        want.sort();
        for c in want {
            assert!(names.iter().any(|n| n == c), "{layer}: channel {c} missing from {names:?}");
        }
        assert_eq!(attr_text(&attrs, "throng/shot"), "demo");
        assert_eq!(attr_text(&attrs, "throng/layer"), *layer);
        assert_eq!(attr_int(&attrs, "throng/frame"), FRAME);
        assert_eq!(attr_text(&attrs, "throng/seed"), "1234");
        assert_eq!(attr_int(&attrs, "throng/spp"), 2);
        assert_eq!(attr_text(&attrs, "throng/zConvention"), "cameraDepth");
        assert_eq!(attr_text(&attrs, "throng/idMapping"), ID_MAPPING);
    }
    // Nothing else: no temporary files left behind.
    let mut got: Vec<PathBuf> = written.keys().cloned().collect();
    got.sort();
    expected.sort();
    assert_eq!(got, expected, "files in the output directory");

    // --resume: whole files are skipped, a truncated one is rendered again.
    let victim = out.join(format!("crowd1/demo.crowd1.{FRAME}.exr"));
    let whole = written[&PathBuf::from(format!("crowd1/demo.crowd1.{FRAME}.exr"))].clone();
    std::fs::write(&victim, &whole[..whole.len() / 2]).expect("truncate");
    assert!(read_layer(&victim).is_err(), "a truncated EXR must not read back");
    let said = render(&["--resume"]);
    assert!(said.contains("rendered 1 layer-frames (3 skipped as complete)"), "resume said:\n{said}");
    let after = files(&out);
    assert_eq!(after.keys().collect::<Vec<_>>(), written.keys().collect::<Vec<_>>(), "files after --resume");
    for (name, bytes) in &written {
        let now = &after[name];
        if *name == victim.strip_prefix(&out).expect("under out") {
            assert!(
                canonical_exr(now) == canonical_exr(bytes),
                "--resume must render the truncated {} again, identical to the first render",
                name.display()
            );
        } else {
            assert!(now == bytes, "--resume must leave the complete {} alone", name.display());
        }
    }

    // Errors: clear, exit status 2.
    let bad = usage_error(&["render", s(&shot), "--manifest", s(&manifest), "--frames", "1001-abc", "--out", s(&out)]);
    assert!(bad.contains("bad frame range `1001-abc`"), "bad --frames said:\n{bad}");
    let outside = usage_error(&["render", s(&shot), "--manifest", s(&manifest), "--frames", "2000", "--out", s(&out)]);
    assert!(outside.contains("frame 2000 is outside shot demo (1001-1048)"), "outside frame said:\n{outside}");
    let missing = tmp.path().join("nowhere.layers.json");
    let none = usage_error(&["render", s(&shot), "--manifest", s(&missing), "--frames", &frame, "--out", s(&out)]);
    assert!(none.contains("no layer manifest at") && none.contains("run `throng layers"), "no manifest said:\n{none}");
    let unknown = usage_error(&["render", s(&shot), "--manifest", s(&manifest), "--layer", "crowd9", "--out", s(&out)]);
    assert!(unknown.contains("no layer `crowd9`"), "unknown layer said:\n{unknown}");
    assert!(files(&out) == after, "failed renders must not touch the output");
}

#[test]
fn output_is_byte_identical_for_1_and_2_threads() {
    let tmp = common::tempdir().expect("temp dir");
    let (manifest, layers) = manifest_in(tmp.path());
    let shot = demo_shot();
    let frame = FRAME.to_string();
    let mut outs = Vec::new();
    for threads in ["1", "2"] {
        let out = tmp.path().join(format!("threads{threads}"));
        for layer in ["all", "full"] {
            ok(&[
                "render",
                s(&shot),
                "--manifest",
                s(&manifest),
                "--layer",
                layer,
                "--frames",
                &frame,
                "--spp",
                "4",
                "--resolution",
                "96x54",
                "--threads",
                threads,
                "--out",
                s(&out),
            ]);
        }
        outs.push(canonical_files(&out));
    }
    assert_eq!(outs[0].len(), layers.len() + 1, "one EXR per layer and full: {:?}", outs[0].keys());
    for (name, bytes) in &outs[0] {
        assert!(
            outs[1].get(name) == Some(bytes),
            "{} differs between --threads 1 and --threads 2 (header attribute order aside)",
            name.display()
        );
    }
    assert_eq!(outs[0].keys().collect::<Vec<_>>(), outs[1].keys().collect::<Vec<_>>());
}

/// Strict byte identity of two runs, header attribute order included
/// (src/render/exr.rs sorts the header attributes the exr crate keeps in a
/// `HashMap`).
#[test]
fn output_is_byte_identical_including_header_order() {
    let tmp = common::tempdir().expect("temp dir");
    let (manifest, _) = manifest_in(tmp.path());
    let shot = demo_shot();
    let frame = FRAME.to_string();
    let mut outs = Vec::new();
    for threads in ["1", "2"] {
        let out = tmp.path().join(format!("threads{threads}"));
        ok(&[
            "render",
            s(&shot),
            "--manifest",
            s(&manifest),
            "--layer",
            "crowd0",
            "--frames",
            &frame,
            "--spp",
            "2",
            "--resolution",
            "64x36",
            "--threads",
            threads,
            "--out",
            s(&out),
        ]);
        outs.push(files(&out));
    }
    assert!(outs[0] == outs[1], "the EXRs of --threads 1 and --threads 2 differ byte for byte");
}

/// `render.adaptive` from the shot: the file gets a `samples` channel (each
/// pixel's count, within min and max) and says max_spp as its spp; `--spp`
/// renders that fixed count instead, with no samples channel; bad keys exit
/// 2 naming the key, writing nothing.
#[test]
fn adaptive_sampling_from_the_shot_and_its_bad_keys() {
    let dir = common::tempdir().unwrap();
    let shot_text = std::fs::read_to_string(demo_shot()).unwrap();
    let edited = |tag: &str, adaptive: &str| {
        let path = demo_shot().with_file_name(format!(".adaptive_{tag}_{}.toml", std::process::id()));
        std::fs::write(&path, shot_text.replace("[render]\n", &format!("[render]\nadaptive = {adaptive}\n"))).unwrap();
        path
    };
    let shot = edited("ok", "{ threshold = 0.05, min_spp = 2, max_spp = 16 }");
    let out = dir.path().join("r");
    let run = |extra: &[&str]| {
        let mut args = vec!["render", s(&shot), "--layer", "full", "--frames", "1024", "--resolution", "32x18"];
        args.extend_from_slice(extra);
        args.extend_from_slice(&["--progress", "off", "--out", s(&out)]);
        let out = throng(&args);
        (out.status.code(), text(&out.stderr))
    };
    let (code, err) = run(&[]);
    let exr = throng::output::layer_path(&out, "demo", "full", FRAME);
    let (film, meta) = read_layer(&exr).unwrap();
    let (fixed_code, fixed_err) = run(&["--spp", "3"]);
    let (fixed, fixed_meta) = read_layer(&exr).unwrap();
    let bad: Vec<(i32, String)> = [
        ("nan", "{ threshold = nan, min_spp = 2, max_spp = 16 }", "render.adaptive.threshold"),
        ("zero", "{ threshold = 0.0, min_spp = 2, max_spp = 16 }", "render.adaptive.threshold"),
        ("order", "{ threshold = 0.1, min_spp = 32, max_spp = 16 }", "render.adaptive.min_spp"),
        ("max", "{ threshold = 0.1, min_spp = 1, max_spp = 0 }", "render.adaptive.max_spp"),
        ("key", "{ threshold = 0.1, min_spp = 1, max_spp = 4, step = 2 }", "step"),
    ]
    .iter()
    .map(|(tag, adaptive, key)| {
        let path = edited(tag, adaptive);
        let o = throng(&["render", s(&path), "--layer", "full", "--out", s(&dir.path().join(tag))]);
        let _ = std::fs::remove_file(&path);
        let e = text(&o.stderr);
        assert!(e.contains(key), "{tag}: {e}");
        assert!(!dir.path().join(tag).exists(), "{tag}: wrote output");
        (o.status.code().unwrap_or(-1), e)
    })
    .collect();
    let _ = std::fs::remove_file(&shot);
    assert_eq!(code, Some(0), "{err}");
    assert_eq!(meta.spp, 16);
    assert_eq!(film.samples.len(), 32 * 18);
    assert!(film.samples.iter().all(|&n| (2..=16).contains(&n)), "{:?}", film.samples);
    assert_eq!(fixed_code, Some(0), "{fixed_err}");
    assert!(fixed.samples.is_empty() && fixed_meta.spp == 3);
    for (code, e) in bad {
        assert_eq!(code, 2, "{e}");
    }
}

/// Interfaces say what they do: `render --json` gives `layer_frames: []`
/// when every frame was skipped as complete (not no key at all), and
/// `export --help` describes USD too and offers no `.usdc` it would refuse.
#[test]
fn json_and_help_say_what_the_verbs_do() {
    let dir = common::tempdir().unwrap();
    let out = dir.path().join("r");
    let shot = demo_shot();
    let args = [
        "render",
        s(&shot),
        "--layer",
        "full",
        "--frames",
        "1024",
        "--spp",
        "1",
        "--resolution",
        "16x9",
        "--resume",
        "--progress",
        "off",
        "--json",
        "--out",
        s(&out),
    ];
    let first: serde_json::Value = serde_json::from_str(&ok(&args)).unwrap();
    assert_eq!(first["layer_frames"].as_array().map(Vec::len), Some(1), "{first}");
    let again: serde_json::Value = serde_json::from_str(&ok(&args)).unwrap();
    assert_eq!(again["layer_frames"], serde_json::json!([]), "{again}");
    assert_eq!(again["files_skipped"].as_array().map(Vec::len), Some(1), "{again}");
    let help = ok(&["export", "--help"]);
    assert!(help.contains("USD") && help.contains("glTF"), "{help}");
    assert!(!help.contains(".usdc /") && help.contains(".usdc is refused"), "{help}");
}

/// A Unicode shot name (the docs allow one) renders, names its files, is
/// written to the EXR header as UTF-8 (what OpenEXR's tools and Cryptomatte
/// read), reads back the same, and `--resume` and botinfo recognise it.
#[test]
fn a_unicode_shot_name_round_trips_through_the_exr_header() {
    let tmp = common::tempdir().expect("temp dir");
    let shot = common::figure_shot(tmp.path(), &common::five_walkers(), "");
    let name = "plaza_ünïcødé_✓";
    let toml = std::fs::read_to_string(&shot).unwrap().replacen("name = \"figure\"", &format!("name = \"{name}\""), 1);
    std::fs::write(&shot, toml).unwrap();
    let out = tmp.path().join("out");
    let args = [
        "render",
        s(&shot),
        "--layer",
        "full",
        "--frames",
        "1020",
        "--spp",
        "1",
        "--resolution",
        "16x9",
        "--out",
        s(&out),
    ];
    ok(&args);
    let exr = out.join("full").join(format!("{name}.full.1020.exr"));
    let bytes = std::fs::read(&exr).unwrap_or_else(|e| panic!("{}: {e}", exr.display()));
    let header = exr_header(&bytes);
    assert_eq!(attr(&header, "throng/shot").2, name.as_bytes(), "throng/shot holds the name's UTF-8 bytes");
    let (_, meta) = read_layer(&exr).expect("reads back");
    assert_eq!(meta.shot, name);
    let again = ok(&[&args[..], &["--resume"]].concat());
    assert!(again.contains("(1 skipped as complete)"), "--resume knows its own frame:\n{again}");
    let said = ok(&["botinfo", s(&shot), "--exr", s(&exr), "--pixel", "8,4"]);
    assert!(!said.contains("is from shot"), "botinfo takes the EXR as this shot's:\n{said}");
}

/// `botinfo --exr --pixel`: `--json` answers in JSON whether or not an
/// agent is at the pixel, and a file of another shot is refused (exit 2,
/// naming the file and the shot it belongs to) whether or not an agent is
/// at the pixel (issue 49: an agentless pixel of another shot's file was
/// "no agent", exit 0, and a text line under --json).
#[test]
fn botinfo_by_pixel_answers_in_json_and_refuses_another_shots_file() {
    let tmp = common::tempdir().expect("temp dir");
    let shot = common::figure_shot(tmp.path(), &common::five_walkers(), "");
    let out = tmp.path().join("out");
    let args = ["render", s(&shot), "--layer", "full", "--frames", "1020", "--spp", "1"];
    ok(&[&args[..], &["--resolution", "16x9", "--progress", "off", "--out", s(&out)]].concat());
    let exr = out.join("full/figure.full.1020.exr");
    let (film, _) = read_layer(&exr).expect("reads back");
    let at = |want_agent: bool| {
        let i = film.agent_id.iter().position(|&id| (id != 0) == want_agent).expect("such a pixel");
        format!("{},{}", i as u32 % film.width, i as u32 / film.width)
    };
    let (sky, agent) = (at(false), at(true));
    let json = |pixel: &str| -> serde_json::Value {
        let said = ok(&["botinfo", s(&shot), "--exr", s(&exr), "--pixel", pixel, "--json"]);
        serde_json::from_str(&said).unwrap_or_else(|e| panic!("not JSON ({e}):\n{said}"))
    };
    let none = json(&sky);
    let (x, y) = sky.split_once(',').unwrap();
    assert_eq!(none["agent"], serde_json::Value::Null, "{none}");
    assert_eq!(none["pixel"], serde_json::json!([x.parse::<u32>().unwrap(), y.parse::<u32>().unwrap()]), "{none}");
    assert_eq!(none["frame"], 1020, "{none}");
    let hit = json(&agent);
    assert!(hit.as_array().is_some_and(|a| a.len() == 1 && a[0]["id"].is_u64()), "{hit}");
    // The same file against another shot: refused, at the set as at an agent, with or without --json.
    let other = tmp.path().join("other.toml");
    let toml = std::fs::read_to_string(&shot).unwrap().replacen("name = \"figure\"", "name = \"other\"", 1);
    std::fs::write(&other, toml).unwrap();
    for pixel in [&sky, &agent] {
        for json in [&[][..], &["--json"]] {
            let err = usage_error(&[&["botinfo", s(&other), "--exr", s(&exr), "--pixel", pixel][..], json].concat());
            assert!(err.contains("figure.full.1020.exr") && err.contains("`figure`"), "{err}");
            assert!(err.contains("other.toml") && !err.contains("panicked"), "{err}");
        }
    }
}
