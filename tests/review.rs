//! `throng review` over HTTP (docs/review.md): every endpoint on a tiny
//! render of the demo (64x36, 1 spp, frame 1024), botInfo by pixel equal to
//! `throng botinfo --json` on a grid of pixels, path traversal refused
//! (`..`, `%2e%2e`, symlinks out), bad requests answered with a 4xx and
//! the server still answering after, the caches under their bound, and the
//! binary printing its URL. The client is a few lines over `TcpStream`, so
//! requests go out exactly as written (no path normalising).

mod common;

use std::collections::{BTreeMap, BTreeSet};
use std::io::{Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use std::time::Duration;

use common::{bin, demo_shot, request, run, start_review, tempdir, Reply};
use serde_json::Value;
use throng::review::{ReviewOptions, Stopper};

const FRAME: i32 = 1024;

/// The tiny render every test reads: `DIR/render/<layer>/...`, its manifest
/// `DIR/demo.layers.json` and a `render --json` summary in the renders folder.
struct Fixture {
    dir: PathBuf,
}

impl Fixture {
    fn renders(&self) -> PathBuf {
        self.dir.join("render")
    }
    fn manifest(&self) -> PathBuf {
        self.dir.join("demo.layers.json")
    }
    fn layer(&self, layer: &str) -> PathBuf {
        self.renders().join(layer).join(format!("demo.{layer}.{FRAME}.exr"))
    }
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn fixture() -> &'static Fixture {
    static F: OnceLock<Fixture> = OnceLock::new();
    F.get_or_init(|| {
        // Under the target folder, made afresh by each run (a static is never
        // dropped, so a temporary folder would be left behind).
        let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join("review");
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let f = Fixture { dir };
        let (code, _, err) = run(&["layers", s(&demo_shot()), "--out", s(&f.manifest())]);
        assert_eq!(code, 0, "{err}");
        let (code, out, err) = run(&[
            "render",
            s(&demo_shot()),
            "--manifest",
            s(&f.manifest()),
            "--layer",
            "all",
            "--frames",
            "1024",
            "--spp",
            "1",
            "--resolution",
            "64x36",
            "--progress",
            "off",
            "--json",
            "--out",
            s(&f.renders()),
        ]);
        assert_eq!(code, 0, "{err}");
        std::fs::write(f.renders().join("render.json"), out).unwrap();
        // Larger than any socket buffer: a client that never reads it must
        // not hold up the server.
        std::fs::write(f.renders().join("big.bin"), vec![7u8; 48 << 20]).unwrap();
        // Something outside both folders, and links to it from inside.
        let outside = f.dir.join("outside");
        std::fs::create_dir(&outside).unwrap();
        std::fs::write(outside.join("secret.txt"), "TOP SECRET").unwrap();
        std::fs::copy(f.layer("set"), outside.join("demo.link.1024.exr")).unwrap();
        std::os::unix::fs::symlink(outside.join("secret.txt"), f.renders().join("secret.txt")).unwrap();
        std::fs::create_dir(f.renders().join("link")).unwrap();
        std::os::unix::fs::symlink(outside.join("demo.link.1024.exr"), f.renders().join("link/demo.link.1024.exr"))
            .unwrap();
        f
    })
}

/// A review server of the fixture in this process on a free port: its
/// address and stopper.
fn start(cache_bytes: u64) -> (String, Stopper) {
    let f = fixture();
    let options = ReviewOptions {
        renders: Some(f.renders()),
        manifest: Some(f.manifest()),
        port: 0,
        cache_bytes,
        ..ReviewOptions::default()
    };
    start_review(&demo_shot(), options)
}

/// The shared server of most tests.
fn server() -> &'static str {
    static S: OnceLock<(String, Stopper)> = OnceLock::new();
    &S.get_or_init(|| start(1 << 30)).0
}

/// Sends `head` (request line and headers, without the blank line) as written.
fn raw(addr: &str, head: &str) -> Reply {
    request(addr, head, b"")
}

fn get(addr: &str, target: &str) -> Reply {
    raw(addr, &format!("GET {target} HTTP/1.1\r\nHost: {addr}"))
}

fn get_ok(addr: &str, target: &str) -> Reply {
    let r = get(addr, target);
    assert_eq!(r.status, 200, "GET {target}: {}", r.text());
    r
}

#[test]
fn every_endpoint_answers() {
    let (f, a) = (fixture(), server());
    let page = get_ok(a, "/").text();
    assert!(page.contains("botinfo") && page.contains("/page.js") && !page.contains("http"), "the page: {page}");
    assert!(get_ok(a, "/page.js").text().contains("/api/pick"));
    assert!(get_ok(a, "/page.css").text().contains("#stage"));

    let shot = get_ok(a, "/api/shot").json();
    assert_eq!(shot["shot"], "demo");
    assert_eq!(shot["rendered_frames"], serde_json::json!([FRAME]));
    assert_eq!(shot["start_frame"], FRAME);
    assert_eq!(get_ok(a, "/api/frames").json()["frames"], serde_json::json!([FRAME]));

    let layers = get_ok(a, &format!("/api/layers?frame={FRAME}")).json();
    assert_eq!(layers["comp"]["layers"], serde_json::json!(["set", "crowd2", "crowd1", "crowd0"]));
    let names: Vec<&str> = layers["layers"].as_array().unwrap().iter().map(|l| l["name"].as_str().unwrap()).collect();
    // The symlinked layer outside the renders folder is not listed.
    assert_eq!(names, ["set", "crowd2", "crowd1", "crowd0"]);
    for l in layers["layers"].as_array().unwrap() {
        assert_eq!((l["width"].as_u64(), l["height"].as_u64()), (Some(64), Some(36)));
        assert_eq!(l["cryptomatte"], true);
    }

    // Images: every view of a layer and of the comp, the comp's toggles,
    // and exposure brightening the beauty.
    let views: Vec<String> =
        layers["layers"][3]["views"].as_array().unwrap().iter().map(|v| v.as_str().unwrap().to_string()).collect();
    assert!(views.len() >= 6 && views[0] == "beauty" && views.contains(&"id".to_string()), "{views:?}");
    for layer in ["crowd0", "comp"] {
        for view in ["beauty", "alpha", "depth", "normal", "albedo", "id"] {
            let img = get(a, &format!("/api/image.png?frame={FRAME}&layer={layer}&view={view}")).png();
            assert_eq!((img.width(), img.height()), (64, 36), "{layer} {view}");
            assert!(img.to_rgb8().pixels().any(|p| p.0 != [0, 0, 0]), "{layer} {view} is black");
        }
    }
    let mean = |target: &str| {
        let img = get(a, target).png().to_rgb8();
        img.pixels().map(|p| p.0.iter().map(|&c| c as f64).sum::<f64>()).sum::<f64>() / img.len() as f64
    };
    let base = mean(&format!("/api/image.png?frame={FRAME}&layer=comp"));
    assert!(mean(&format!("/api/image.png?frame={FRAME}&layer=comp&exposure=2")) > base + 10.0);
    let rgb = |target: &str| get(a, target).png().to_rgb8().into_raw();
    let set_only = rgb(&format!("/api/image.png?frame={FRAME}&layer=comp&layers=set"));
    assert_eq!(set_only, rgb(&format!("/api/image.png?frame={FRAME}&layer=set")), "a comp of the set alone is the set");
    let all = rgb(&format!("/api/image.png?frame={FRAME}&layer=comp"));
    let changed = set_only.chunks(3).zip(all.chunks(3)).filter(|(p, q)| p != q).count();
    assert!(changed > 64 * 36 / 10, "the crowd layers change {changed} pixels of the comp");

    // Agents in an image, their matte, search by id.
    let agents = get_ok(a, &format!("/api/agents?frame={FRAME}&layer=crowd0")).json();
    let list = agents["agents"].as_array().unwrap();
    assert!(!list.is_empty(), "crowd0 shows agents");
    let (film, _) = throng::render::exr::read_layer(&f.layer("crowd0")).unwrap();
    let top = &list[0];
    let id = top["id"].as_u64().unwrap() as u32;
    let count = film.agent_id.iter().filter(|&&v| v == id + 1).count();
    assert_eq!(top["pixels"].as_u64(), Some(count as u64));
    let [x, y] = [0, 1].map(|i| top["pixel"][i].as_u64().unwrap() as u32);
    assert_eq!(film.agent_id[film.index(x, y)], id + 1, "the spot named is the agent's pixel");
    let matte = get(a, &format!("/api/matte.png?frame={FRAME}&layer=crowd0&id={id}")).png().to_rgba8();
    assert!(matte.get_pixel(x, y).0[3] > 0, "the matte covers the agent's pixel");
    let covered = matte.pixels().filter(|p| p.0[3] > 0).count();
    assert!(covered >= count / 2 && covered < 64 * 36 / 2, "matte covers {covered} px, agent.id {count}");
    let found = get_ok(a, &format!("/api/agent?frame={FRAME}&layer=crowd0&id={id}")).json();
    assert_eq!((found["pixel"][0].as_u64(), found["pixel"][1].as_u64()), (Some(x as u64), Some(y as u64)));
    assert_eq!(found["botinfo"][0]["id"].as_u64(), Some(id as u64));
    assert_eq!(found["botinfo"][0]["layer"], "crowd0");

    // The map, plain and with the agent ringed.
    let plain = get(a, "/api/map.png").png();
    assert_eq!((plain.width(), plain.height()), (1600, 900));
    let ringed = get(a, &format!("/api/map.png?agent={id}")).png();
    assert_ne!(plain.to_rgba8().as_raw(), ringed.to_rgba8().as_raw(), "the highlight shows on the map");
    // Drawn at the width the page shows it, so its text is not shrunk to 3 px.
    let shown = get(a, "/api/map.png?w=480").png();
    assert_eq!((shown.width(), shown.height()), (480, 270));
    assert_eq!(get(a, "/api/map.png?w=9").png().width(), 320, "clamped to a legible width");

    // Figures: casting, per-layer agents and memory (estimated, measured), pops.
    let fig = get_ok(a, "/api/figures").json();
    assert_eq!(fig["cast"]["agents"], 302);
    let manifest = throng::layers::read_manifest(&f.manifest()).unwrap();
    for (row, l) in fig["layers"].as_array().unwrap().iter().zip(&manifest.layers) {
        assert_eq!(row["name"], l.name.as_str());
        assert_eq!(row["agents"].as_u64(), Some(l.agents as u64));
        assert_eq!(row["estimated_bytes"].as_u64(), Some(l.memory_bytes));
        assert!(row["measured"]["peak_rss_bytes"].as_u64().unwrap() > 1 << 20, "{row}");
    }
    assert_eq!(fig["layers"].as_array().unwrap().len(), manifest.layers.len() + 1, "the set row too");
    // Each row's figures are that layer's own: its estimate from the model
    // (the set layer's too, not the split's shared bytes) and its measured
    // peak from the `render --json` summary's layer-frame.
    let summary: Value = serde_json::from_slice(&std::fs::read(f.renders().join("render.json")).unwrap()).unwrap();
    for row in fig["layers"].as_array().unwrap() {
        let name = row["name"].as_str().unwrap();
        assert_eq!(row["estimated_bytes"].as_u64(), manifest.render_memory(name), "{row}");
        let peak = summary["layer_frames"].as_array().unwrap().iter().find(|lf| lf["layer"] == name).unwrap();
        assert_eq!(row["measured"]["peak_rss_bytes"], peak["peak_rss_bytes"], "{row}");
    }
    assert_eq!(manifest.render_memory("set"), manifest.set.memory_bytes, "the set layer has an estimate of its own");
    assert!(fig["pops_avoided"].is_object());
    assert_eq!(fig["summaries"].as_array().unwrap().len(), 1);

    // Files, as they are on disk.
    let toml = get_ok(a, "/files/shot/shot.toml");
    assert_eq!(toml.body, std::fs::read(demo_shot()).unwrap());
    let exr = get_ok(a, "/files/renders/crowd0/demo.crowd0.1024.exr");
    assert_eq!(exr.body, std::fs::read(f.layer("crowd0")).unwrap());

    // HEAD answers without a body.
    let head = raw(a, &format!("HEAD /api/shot HTTP/1.1\r\nHost: {a}"));
    assert_eq!(head.status, 200);
    let cache = get_ok(a, "/api/cache").json();
    assert!(cache["films"]["entries"].as_u64().unwrap() >= 5, "{cache}");
}

/// The botInfo endpoint is `throng botinfo --json`: on a grid of pixels of
/// every layer, each pick names the agent the file's agent.id holds and the
/// same JSON the CLI prints for that id and frame; a few pixels go through
/// the CLI's own `--exr --pixel` too, and the comp against `throng comp`'s.
#[test]
fn botinfo_endpoint_agrees_with_the_cli_on_a_grid() {
    let (f, a) = (fixture(), server());
    let mut picks: Vec<(String, u32, u32, Value)> = Vec::new();
    for layer in ["set", "crowd2", "crowd1", "crowd0"] {
        let (film, _) = throng::render::exr::read_layer(&f.layer(layer)).unwrap();
        for y in (1..36).step_by(5) {
            for x in (2..64).step_by(6) {
                let r = get_ok(a, &format!("/api/pick?frame={FRAME}&layer={layer}&x={x}&y={y}")).json();
                let want = film.agent_id[film.index(x, y)].checked_sub(1);
                assert_eq!(r["agent"].as_u64(), want.map(u64::from), "{layer} {x},{y}");
                if want.is_none() {
                    assert!(r["botinfo"].is_null());
                }
                picks.push((layer.to_string(), x, y, r));
            }
        }
    }
    let ids: BTreeSet<u64> = picks.iter().filter_map(|p| p.3["agent"].as_u64()).collect();
    assert!(ids.len() >= 10, "the grid hits {} agents", ids.len());
    let mut args: Vec<String> = vec!["botinfo".into(), s(&demo_shot()).into()];
    args.extend(ids.iter().map(u64::to_string));
    args.extend(["--frame", "1024", "--manifest", s(&f.manifest()), "--json"].map(String::from));
    let (code, out, err) = run(&args);
    assert_eq!(code, 0, "{err}");
    let cli: Value = serde_json::from_str(&out).unwrap();
    let by_id: BTreeMap<u64, &Value> = cli.as_array().unwrap().iter().map(|b| (b["id"].as_u64().unwrap(), b)).collect();
    for (layer, x, y, r) in &picks {
        if let Some(id) = r["agent"].as_u64() {
            assert_eq!(&r["botinfo"][0], by_id[&id], "{layer} {x},{y}");
            assert_eq!(r["botinfo"].as_array().unwrap().len(), 1);
            assert!(by_id[&id]["layer"].is_string(), "the manifest's layer is in the botInfo");
        }
    }
    // The CLI itself by pixel, with the command the endpoint names.
    let with_agent = picks.iter().filter(|p| p.3["agent"].is_u64());
    let samples: Vec<&(String, u32, u32, Value)> =
        with_agent.step_by(7).take(3).chain(picks.iter().filter(|p| p.3["agent"].is_null()).take(1)).collect();
    for (layer, x, y, r) in samples {
        let file = f.layer(layer);
        let pixel = format!("{x},{y}");
        let (code, out, err) = run(&[
            "botinfo",
            s(&demo_shot()),
            "--exr",
            s(&file),
            "--pixel",
            &pixel,
            "--manifest",
            s(&f.manifest()),
            "--json",
        ]);
        assert_eq!(code, 0, "{err}");
        match r["agent"].as_u64() {
            Some(_) => {
                assert_eq!(serde_json::from_str::<Value>(&out).unwrap(), r["botinfo"], "{layer} {pixel}");
                assert_eq!(r["file"].as_str().map(PathBuf::from), Some(file.canonicalize().unwrap()));
            }
            // Under --json an agentless pixel is a JSON answer too (docs/farm.md).
            None => {
                let answer: Value = serde_json::from_str(&out).unwrap_or_else(|e| panic!("{e}: {out}"));
                assert!(answer["agent"].is_null(), "{out}");
                assert_eq!(answer["pixel"], serde_json::json!([x, y]), "{out}");
            }
        }
    }
    // The comp: the endpoint's stack against `throng comp`'s file.
    let comp = f.dir.join("comp.1024.exr");
    let (code, _, err) =
        run(&["comp", s(&f.renders()), "--frame", "1024", "--manifest", s(&f.manifest()), "--out", s(&comp)]);
    assert_eq!(code, 0, "{err}");
    let (film, _) = throng::render::exr::read_layer(&comp).unwrap();
    let i = film.agent_id.iter().position(|&v| v > 0).unwrap() as u32;
    let (x, y) = (i % film.width, i / film.width);
    let r = get_ok(a, &format!("/api/pick?frame={FRAME}&layer=comp&x={x}&y={y}")).json();
    let pixel = format!("{x},{y}");
    let (code, out, err) = run(&[
        "botinfo",
        s(&demo_shot()),
        "--exr",
        s(&comp),
        "--pixel",
        &pixel,
        "--manifest",
        s(&f.manifest()),
        "--json",
    ]);
    assert_eq!(code, 0, "{err}");
    assert_eq!(serde_json::from_str::<Value>(&out).unwrap(), r["botinfo"], "comp {pixel}");
}

#[test]
fn path_traversal_is_refused() {
    let a = server();
    let secret = "TOP SECRET";
    for target in [
        "/files/shot/../Cargo.toml",
        "/files/shot/../../../../../../etc/passwd",
        "/files/shot/%2e%2e/Cargo.toml",
        "/files/shot/%2E%2E%2FCargo.toml",
        "/files/shot/cache/%2e%2e/%2e%2e/Cargo.toml",
        "/files/renders/..%2f..%2fetc%2fpasswd",
        "/files/renders/..%5c..%5cetc%5cpasswd",
        "/files/shot//etc/passwd",
        "/files/shot/%2fetc%2fpasswd",
        "/files/shot/./shot.toml",
        "/files/shot/shot.toml%00.png",
        "/files/renders/secret.txt",
        "/files/renders/link/demo.link.1024.exr",
        "/files/renders/../outside/secret.txt",
        "/files/etc/passwd",
        "/files/",
        "/../../etc/passwd",
    ] {
        let r = get(a, target);
        assert!((400..500).contains(&r.status), "GET {target} answered {}: {}", r.status, r.text());
        assert!(!r.text().contains(secret) && !r.text().contains("root:"), "GET {target} leaked: {}", r.text());
        assert!(r.json()["error"].is_string(), "GET {target}: the refusal says why");
    }
    // A symlink out of the renders folder is refused as outside (403).
    let r = get(a, "/files/renders/secret.txt");
    assert_eq!(r.status, 403, "{}", r.text());
    assert!(r.text().contains("outside"), "{}", r.text());
    // Layers are named, never pathed: a layer name with `..` is no layer,
    // and the linked-out layer is not one.
    for layer in ["..%2f..%2foutside", "link", "..", "set%2f..%2fset"] {
        let r = get(a, &format!("/api/image.png?frame={FRAME}&layer={layer}"));
        assert_eq!(r.status, 404, "{layer}: {}", r.text());
    }
    // Another site's page cannot read the server through a rebound name.
    let r = raw(a, "GET /api/shot HTTP/1.1\r\nHost: evil.example:80");
    assert_eq!(r.status, 403, "{}", r.text());
    // And it still serves.
    assert_eq!(get(a, "/files/shot/shot.toml").status, 200);
}

#[test]
fn bad_requests_get_4xx_and_the_server_carries_on() {
    let a = server();
    let cases: [(&str, u16, &str); 17] = [
        ("/api/layers", 400, "frame"),
        ("/api/layers?frame=abc", 400, "frame"),
        ("/api/layers?frame=99999", 404, "not rendered"),
        ("/api/image.png?frame=1024&layer=nope", 404, "no layer `nope`"),
        ("/api/image.png?frame=1024&layer=crowd0&view=nope", 404, "no view `nope`"),
        ("/api/image.png?frame=1024&layer=crowd0&exposure=NaN", 400, "exposure"),
        ("/api/image.png?frame=1024&layer=crowd0&exposure=100", 400, "exposure"),
        ("/api/image.png?frame=1024&layer=comp&layers=set,bogus", 400, "bogus"),
        ("/api/image.png?frame=1024&layer=comp&layers=", 400, "no layers"),
        ("/api/pick?frame=1024&layer=crowd0&x=64&y=0", 400, "outside"),
        ("/api/pick?frame=1024&layer=crowd0&x=-1&y=0", 400, "x"),
        ("/api/pick?frame=1024&layer=crowd0&y=0", 400, "missing parameter `x`"),
        ("/api/agent?frame=1024&id=99999", 404, "nearest ids"),
        ("/api/agent?frame=5&id=1", 404, "outside shot"),
        ("/api/matte.png?frame=1024&layer=crowd0", 400, "id"),
        ("/api/pick?frame=%zz", 400, "escape"),
        ("/nope", 404, "no page"),
    ];
    for (target, status, says) in cases {
        let r = get(a, target);
        assert_eq!(r.status, status, "GET {target}: {}", r.text());
        let msg = r.json()["error"].as_str().unwrap().to_string();
        assert!(msg.contains(says), "GET {target}: {msg}");
    }
    let r = raw(a, &format!("POST /api/shot HTTP/1.1\r\nHost: {a}\r\nContent-Length: 0"));
    assert_eq!(r.status, 405, "{}", r.text());
    // Garbage, a client that hangs up at once, and one that never finishes.
    let mut junk = TcpStream::connect(a).unwrap();
    junk.write_all(b"HELLO WORLD\r\n\r\n").unwrap();
    drop(TcpStream::connect(a).unwrap());
    let mut slow = TcpStream::connect(a).unwrap();
    slow.write_all(b"GET /api/shot HTTP/1.1\r\n").unwrap();
    // The server still answers.
    assert_eq!(get_ok(a, "/api/shot").json()["shot"], "demo");
    drop((junk, slow));
}

/// Issue 49: the page's own rules. `hidden` wins over `.controls`'s flex
/// (the comp's layer checkboxes stayed visible on one layer), pictures are
/// shrunk smoothly (nearest-neighbour sampling sparkled), and the page asks
/// for the map at the width it shows it.
#[test]
fn the_page_hides_what_it_hides_and_shrinks_pictures_smoothly() {
    let a = server();
    let css = get_ok(a, "/page.css").text();
    let rules: String = css.lines().filter(|l| !l.trim_start().starts_with("/*")).collect::<Vec<_>>().join("\n");
    assert!(rules.contains("[hidden] { display: none !important; }"), "{css}");
    assert!(!rules.contains("pixelated") && !rules.contains("crisp-edges"), "{css}");
    assert!(get_ok(a, "/").text().contains(r#"id="toggles" class="controls" hidden"#));
    assert!(get_ok(a, "/page.js").text().contains("/api/map.png?w="));
}

#[test]
fn the_caches_stay_under_their_bound() {
    // 128 KiB: 7/8 for films (a 64x36 layer's beauty is 36 KiB, so the
    // comp's four layers and the comp cannot all stay), 1/8 for PNGs.
    let (a, stop) = start(128 << 10);
    let bound = |c: &Value, k: &str| (c[k]["bytes"].as_u64().unwrap(), c[k]["bound"].as_u64().unwrap());
    for layer in ["set", "crowd2", "crowd1", "crowd0", "comp"] {
        for exposure in [0, 1, 2] {
            get_ok(&a, &format!("/api/image.png?frame={FRAME}&layer={layer}&exposure={exposure}"));
        }
        let c = get_ok(&a, "/api/cache").json();
        for k in ["films", "pngs"] {
            let (used, max) = bound(&c, k);
            assert!(used <= max && used > 0, "{k}: {used} of {max}");
        }
    }
    let c = get_ok(&a, "/api/cache").json();
    assert!(c["films"]["entries"].as_u64().unwrap() < 5, "least recently used films were dropped: {c}");
    // The same request again is answered from the cache with the same bytes.
    let target = format!("/api/image.png?frame={FRAME}&layer=comp&exposure=1");
    assert_eq!(get_ok(&a, &target).body, get_ok(&a, &target).body);
    stop.stop();
    drop(stop);
    // Stopped: nothing answers on the port any more.
    std::thread::sleep(Duration::from_millis(200));
    let gone = TcpStream::connect(&a).and_then(|mut s| {
        s.set_read_timeout(Some(Duration::from_secs(2)))?;
        s.write_all(b"GET /api/shot HTTP/1.1\r\nConnection: close\r\n\r\n")?;
        let mut b = Vec::new();
        s.read_to_end(&mut b).map(|_| b)
    });
    assert!(gone.map_or(true, |b| !b.starts_with(b"HTTP/1.1 200")), "a stopped server answered");
}

/// A request decodes only the channels its answer reads, and a comp is
/// stacked one layer at a time: with a cache too small to keep a layer, the
/// review never holds two decoded layers at once, whatever the view.
#[test]
fn a_request_decodes_what_it_reads_one_layer_at_a_time() {
    let (a, stop) = start(4 << 10);
    let comp = format!("frame={FRAME}&layer=comp");
    for target in [
        format!("/api/image.png?{comp}"),
        format!("/api/image.png?{comp}&view=normal"),
        format!("/api/image.png?{comp}&view=depth"),
        format!("/api/pick?{comp}&x=32&y=30"),
        format!("/api/agents?{comp}"),
        format!("/api/matte.png?{comp}&id=3"),
    ] {
        get_ok(&a, &target);
        let held = &get_ok(&a, "/api/cache").json()["layers_held"];
        assert_eq!(held["now"], 0, "{target}: {held}");
        assert_eq!(held["peak"], 1, "{target}: at most one decoded layer at once: {held}");
    }
    stop.stop();
    // The cache holds what was decoded: the beauty is R G B A alone (16
    // bytes a pixel), a pick adds `agent.id` alone (4).
    let (a, stop) = start(1 << 30);
    let films = |a: &str| get_ok(a, "/api/cache").json()["films"]["bytes"].as_u64().unwrap();
    get_ok(&a, &format!("/api/image.png?frame={FRAME}&layer=set"));
    assert_eq!(films(&a), 64 * 36 * 16);
    get_ok(&a, &format!("/api/pick?frame={FRAME}&layer=set&x=1&y=1"));
    assert_eq!(films(&a), 64 * 36 * (16 + 4));
    stop.stop();
}

#[test]
fn the_binary_prints_its_url_and_serves_until_killed() {
    let f = fixture();
    let mut child = std::process::Command::new(bin())
        .args(["review", s(&demo_shot()), "--renders", s(&f.renders()), "--port", "0", "--frame", "1024"])
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let mut out = std::io::BufReader::new(child.stdout.take().unwrap());
    let mut line = String::new();
    std::io::BufRead::read_line(&mut out, &mut line).unwrap();
    let url = line.split_whitespace().find(|w| w.starts_with("http://127.0.0.1:")).unwrap_or_else(|| panic!("{line}"));
    let addr = url.trim_start_matches("http://").trim_end_matches('/').to_string();
    let shot = get_ok(&addr, "/api/shot").json();
    // Found beside the renders folder, as `throng demo` lays it out.
    assert_eq!(shot["manifest"].as_str().map(PathBuf::from), Some(f.manifest()));
    assert_eq!(get(&addr, "/api/pick?frame=1024&layer=crowd0&x=1&y=1").status, 200);
    child.kill().unwrap();
    child.wait().unwrap();

    // Refused before serving: a frame not rendered, a folder with no layers.
    let (code, _, err) =
        run(&["review", s(&demo_shot()), "--renders", s(&f.renders()), "--port", "0", "--frame", "1030"]);
    assert_eq!(code, 2);
    assert!(err.contains("--frame") && err.contains("1030") && err.contains("rendered: 1024"), "{err}");
    let empty = tempdir().unwrap();
    let (code, _, err) = run(&["review", s(&demo_shot()), "--renders", s(empty.path()), "--port", "0"]);
    assert_eq!(code, 2);
    assert!(err.contains("--renders") && err.contains("no layer files"), "{err}");
}

/// Light passes are views of the layers that have them; without a manifest
/// and with only the `full` layer, there is no comp and no map, and the
/// server says so.
#[test]
fn light_passes_are_views_and_a_shot_without_manifest_has_no_comp() {
    let dir = tempdir().unwrap();
    let shot =
        common::DemoShot { name: "pass", frames: (1001, 1002), extra: "passes = [\"all\"]", ..Default::default() }
            .write(dir.path(), &common::two_robots(1..=2));
    let renders = dir.path().join("r");
    let (code, _, err) =
        run(&["render", s(&shot), "--layer", "full", "--frames", "1001", "--progress", "off", "--out", s(&renders)]);
    assert_eq!(code, 0, "{err}");
    let (a, stop) =
        start_review(&shot, ReviewOptions { renders: Some(renders.clone()), port: 0, ..ReviewOptions::default() });
    let layers = get_ok(&a, "/api/layers?frame=1001").json();
    assert!(layers["comp"]["error"].as_str().unwrap().contains("no comp"), "{layers}");
    let full = &layers["layers"][0];
    assert_eq!(full["name"], "full");
    let views: Vec<&str> = full["views"].as_array().unwrap().iter().map(|v| v.as_str().unwrap()).collect();
    let (film, _) = throng::render::exr::read_layer(&renders.join("full/pass.full.1001.exr")).unwrap();
    let passes: Vec<&str> = film.passes.iter().map(|p| p.name.as_str()).collect();
    assert!(passes.contains(&"diffuse_direct") && passes.contains(&"P"), "{passes:?}");
    assert_eq!(&views[6..], &passes[..], "every pass of the file is a view, in file order");
    let beauty = get(&a, "/api/image.png?frame=1001&layer=full").png().to_rgb8().into_raw();
    for pass in &passes {
        let img = get(&a, &format!("/api/image.png?frame=1001&layer=full&view={pass}")).png();
        assert_eq!((img.width(), img.height()), (48, 27), "{pass}");
        assert_ne!(img.to_rgb8().into_raw(), beauty, "{pass} is not the beauty");
    }
    // A pass is per layer: the comp (none here) and the map (no manifest) say why not.
    let r = get(&a, "/api/image.png?frame=1001&layer=comp");
    assert_eq!(r.status, 404, "{}", r.text());
    let r = get(&a, "/api/map.png");
    assert!(r.status == 404 && r.text().contains("manifest"), "{}", r.text());
    let fig = get_ok(&a, "/api/figures").json();
    assert!(fig["layers"].is_null() && fig["cast"]["agents"] == 2, "{fig}");
    // botInfo without a manifest: no layer, as `throng botinfo` says.
    let i = film.agent_id.iter().position(|&v| v > 0).unwrap() as u32;
    let (x, y) = (i % film.width, i / film.width);
    let r = get_ok(&a, &format!("/api/pick?frame=1001&layer=full&x={x}&y={y}")).json();
    assert!(r["botinfo"][0]["layer"].is_null(), "{r}");
    stop.stop();
}

#[test]
fn a_client_that_never_reads_holds_up_only_itself() {
    let a = server();
    let mut stuck = TcpStream::connect(a).unwrap();
    stuck.write_all(format!("GET /files/renders/big.bin HTTP/1.1\r\nHost: {a}\r\n\r\n").as_bytes()).unwrap();
    std::thread::sleep(Duration::from_millis(300));
    let started = std::time::Instant::now();
    assert_eq!(get_ok(a, "/api/shot").json()["shot"], "demo");
    assert_eq!(get(a, "/api/frames").status, 200);
    assert!(started.elapsed() < Duration::from_secs(10), "answered in {:?}", started.elapsed());
    drop(stuck);
}

/// The comp offers the light passes its layers share, stacked by `comp::over`.
#[test]
fn the_comp_offers_the_passes_its_layers_share() {
    let dir = tempdir().unwrap();
    let shot =
        common::DemoShot { name: "cpass", frames: (1001, 1002), extra: "passes = [\"all\"]", ..Default::default() }
            .write(dir.path(), &common::two_robots(1..=2));
    // The manifest beside the shot, where botinfo and review find it.
    let (code, _, err) = run(&["layers", s(&shot)]);
    assert_eq!(code, 0, "{err}");
    let renders = dir.path().join("r");
    let (code, _, err) =
        run(&["render", s(&shot), "--layer", "all", "--frames", "1001", "--progress", "off", "--out", s(&renders)]);
    assert_eq!(code, 0, "{err}");
    let (a, stop) =
        start_review(&shot, ReviewOptions { renders: Some(renders.clone()), port: 0, ..ReviewOptions::default() });
    let layers = get_ok(&a, "/api/layers?frame=1001").json();
    let views: Vec<&str> = layers["comp"]["views"].as_array().unwrap().iter().map(|v| v.as_str().unwrap()).collect();
    assert!(views.contains(&"beauty") && views.contains(&"diffuse_direct"), "{layers}");
    for l in layers["layers"].as_array().unwrap() {
        for v in &views {
            assert!(l["views"].as_array().unwrap().iter().any(|x| x == v), "{} lacks {v}", l["name"]);
        }
    }
    let comp = throng::comp::comp_frame(&renders, 1001, None).unwrap();
    let pass = comp.film.passes.iter().find(|p| p.name == "diffuse_direct").expect("the comp stacks diffuse_direct");
    assert!(pass.data.iter().any(|p| p.iter().any(|&c| c > 0.0)));
    for view in &views {
        let img = get(&a, &format!("/api/image.png?frame=1001&layer=comp&view={view}")).png();
        assert_eq!((img.width(), img.height()), (48, 27), "{view}");
    }
    stop.stop();
}

/// Sends `method target` with `headers` (each a full `Name: value` line)
/// and `body`, as written.
fn send(addr: &str, method: &str, target: &str, headers: &[&str], body: &[u8]) -> Reply {
    let mut head = format!("{method} {target} HTTP/1.1\r\nHost: {addr}\r\nContent-Length: {}", body.len());
    for h in headers {
        head.push_str("\r\n");
        head.push_str(h);
    }
    request(addr, &head, body)
}

/// Issue 50, the mixer's two endpoints: `/api/mix.png` is the light groups
/// regraded and summed (a doubled gain on every group is one stop of
/// exposure, byte for byte; a muted group leaves the others, as each
/// group's own view shows them), bad mixes are 4xx with the server still
/// answering, and `POST /api/save-shot` writes a new shot beside the
/// original, never over a file, that renders what the mix showed.
#[test]
fn the_mixer_regrades_the_groups_and_saves_a_shot_that_renders_the_mix() {
    let dir = tempdir().unwrap();
    let shot = common::DemoShot {
        name: "mix",
        frames: (1001, 1002),
        spp: 16,
        extra: "passes = [\"light_groups\"]\nindirect_clamp = 0",
        ..Default::default()
    }
    .write(dir.path(), &common::two_robots(1..=2));
    let original = std::fs::read(&shot).unwrap();
    let renders = dir.path().join("r");
    let render = |shot: &Path, out: &Path| {
        let (code, _, err) =
            run(&["render", s(shot), "--layer", "full", "--frames", "1001", "--progress", "off", "--out", s(out)]);
        assert_eq!(code, 0, "{err}");
    };
    render(&shot, &renders);
    let (film, _) = throng::render::exr::read_layer(&renders.join("full/mix.full.1001.exr")).unwrap();
    let groups: Vec<&str> = film.passes.iter().filter_map(|p| p.name.strip_prefix("lg_")).collect();
    assert!(groups.len() >= 2, "{groups:?}");
    // The set's shop windows are grouped by their own material name, not by the set file's path.
    assert!(groups.iter().all(|g| !g.contains("set_glb")), "{groups:?}");
    let (a, stop) =
        start_review(&shot, ReviewOptions { renders: Some(renders.clone()), port: 0, ..ReviewOptions::default() });
    let base = "/api/mix.png?frame=1001&layer=full";
    let mix = |q: &str| get(&a, &format!("{base}&{q}")).png().to_rgb8().into_raw();

    let all_doubled: Vec<String> = groups.iter().map(|g| format!("{g}:2:1:1:1")).collect();
    assert_eq!(mix(&format!("mix={}", all_doubled.join(","))), mix("mix=&exposure=1"));
    assert_ne!(mix("mix="), mix("mix=&exposure=1"));
    let (kept, muted) = (groups[0], &groups[1..]);
    let mutes: Vec<String> = muted.iter().map(|g| format!("{g}:0:1:1:1")).collect();
    let alone = get(&a, &format!("/api/image.png?frame=1001&layer=full&view=lg_{kept}")).png().to_rgb8().into_raw();
    assert_eq!(mix(&format!("mix={}", mutes.join(","))), alone, "muting all but `{kept}` shows `{kept}`");

    for (q, status) in
        [("mix=a:1", 400), ("mix=nope:1:1:1:1", 404), ("mix=&exposure=NaN", 400), ("mix=x:-1:1:1:1", 400)]
    {
        let r = get(&a, &format!("{base}&{q}"));
        assert_eq!(r.status, status, "{q}: {}", r.text());
    }

    let json = "Content-Type: application/json";
    let save = |name: &str, headers: &[&str]| {
        let body = serde_json::json!({ "name": name, "mix": format!("{kept}:2:1:0.5:0.25") }).to_string();
        send(&a, "POST", "/api/save-shot", headers, body.as_bytes())
    };
    let r = save("warm look", &[json]);
    assert_eq!(r.status, 200, "{}", r.text());
    let saved = PathBuf::from(r.json()["file"].as_str().unwrap());
    assert_eq!(saved, dir.path().join("warm look.toml"));
    for (name, headers, status) in [
        ("warm look", &[json][..], 409),
        ("../escape", &[json][..], 400),
        ("plain", &[][..], 415),
        ("plain", &[json, "Origin: http://evil.example"][..], 403),
    ] {
        let r = save(name, headers);
        assert_eq!(r.status, status, "{name} {headers:?}: {}", r.text());
    }
    assert!(!dir.path().join("plain.toml").exists() && !dir.path().join("escape.toml").exists());
    assert_eq!(std::fs::read(&shot).unwrap(), original, "the original shot is untouched");
    // Gains edited on disk since the review read the shot: the page's mix is
    // of the old ones, so saving is refused rather than folding in either.
    let edited = format!("{}\n[lights.gains]\n{kept} = {{ gain = 3.0 }}\n", String::from_utf8_lossy(&original));
    std::fs::write(&shot, edited).unwrap();
    let r = save("after an edit", &[json]);
    assert!(r.status == 409 && r.text().contains("changed since"), "{}: {}", r.status, r.text());
    assert!(!dir.path().join("after an edit.toml").exists());
    std::fs::write(&shot, &original).unwrap();
    assert_eq!(get(&a, "/api/shot").status, 200, "the server still answers");
    stop.stop();

    // The saved shot bakes the mix: its beauty is gain x tint x the group's
    // pass plus the other groups, within noise (light selection weighs by power).
    let baked = dir.path().join("baked");
    render(&saved, &baked);
    let (look, _) = throng::render::exr::read_layer(&baked.join("full/mix.full.1001.exr")).unwrap();
    let mut want = [0.0f64; 3];
    for p in film.passes.iter().filter(|p| p.name.starts_with("lg_")) {
        let k: [f64; 3] = if p.name == format!("lg_{kept}") { [2.0, 1.0, 0.5] } else { [1.0; 3] };
        for px in &p.data {
            (0..3).for_each(|c| want[c] += k[c] * px[c] as f64);
        }
    }
    let mut got = [0.0f64; 3];
    for px in &look.rgba {
        (0..3).for_each(|c| got[c] += px[c] as f64);
    }
    for c in 0..3 {
        assert!((got[c] / want[c] - 1.0).abs() < 0.03, "channel {c}: baked {} against the mix {}", got[c], want[c]);
    }
}

/// Issue 52's review item: a denoised render offers its noisy beauty as a
/// view (the page's "noisy" toggle asks for it), and picking still reads
/// the agent under the pixel.
#[test]
fn a_denoised_render_shows_noisy_and_denoised_and_still_picks() {
    if !common::oidn_available("a_denoised_render_shows_noisy_and_denoised_and_still_picks") {
        return;
    }
    let dir = tempdir().unwrap();
    let renders = dir.path().join("r");
    let (code, _, err) = run(&[
        "render",
        s(&demo_shot()),
        "--layer",
        "full",
        "--frames",
        "1024",
        "--spp",
        "2",
        "--resolution",
        "64x36",
        "--denoise",
        "fast",
        "--progress",
        "off",
        "--out",
        s(&renders),
    ]);
    assert_eq!(code, 0, "{err}");
    let (a, stop) = start_review(
        &demo_shot(),
        ReviewOptions { renders: Some(renders.clone()), port: 0, ..ReviewOptions::default() },
    );
    let layers = get_ok(&a, "/api/layers?frame=1024").json();
    let full = layers["layers"].as_array().unwrap().iter().find(|l| l["name"] == "full").unwrap();
    assert!(full["views"].as_array().unwrap().iter().any(|v| v == "noisy"), "{full}");
    let image = |view: &str| get(&a, &format!("/api/image.png?frame=1024&layer=full&view={view}")).png().to_rgb8();
    let (denoised, noisy) = (image("beauty"), image("noisy"));
    let differ = denoised.pixels().zip(noisy.pixels()).filter(|(d, n)| d != n).count();
    assert!(differ > 64 * 36 / 4, "only {differ} pixels differ between denoised and noisy");
    let (film, _) = throng::render::exr::read_layer(&renders.join("full/demo.full.1024.exr")).unwrap();
    let i = film.agent_id.iter().position(|&v| v > 0).unwrap() as u32;
    let (x, y) = (i % film.width, i / film.width);
    let r = get_ok(&a, &format!("/api/pick?frame=1024&layer=full&x={x}&y={y}")).json();
    assert_eq!(r["botinfo"][0]["id"], film.agent_id[i as usize] - 1, "{r}");
    stop.stop();
}
