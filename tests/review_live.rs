//! `throng review --live` (docs/review.md, "Live preview") on a tiny shot of
//! two robots under one point light: the first image arrives and, once at
//! the samples asked, is the `full` render of the same settings; raising
//! the light's intensity in the shot file renders a brighter image (the
//! cast kept); a malformed edit is reported by file and key while the
//! server keeps answering, and the next good edit renders again; stop
//! stops, start resumes; a page that stops polling stops it; nothing is
//! written. And the renderer's side: passes that continue each pixel's
//! samples (`first_sample`) add up to one render of their total.

mod common;

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant, SystemTime};

use common::{start_review, tempdir, two_robots, DemoShot};
use serde_json::Value;
use throng::casting::ShotCrowd;
use throng::render::job::{self, RenderJob, Silent};
use throng::render::{render_frame, BlasSet, RenderSettings};
use throng::review::{LiveOptions, ReviewOptions, Stopper};

const FRAME: i32 = 1002;
const SIZE: [u32; 2] = [48, 27];

/// The shot's one light, at `intensity` W/sr.
fn lamp(intensity: &str) -> String {
    format!("[[lights.point]]\nname = \"lamp\"\nposition = [1.0, 3.0, 4.0]\nintensity = {intensity}\n")
}

/// `dir/shot.toml` (two robots, the lamp at 20 W/sr, 4 spp at 48x27) and its cache.
fn write_shot(dir: &Path) -> PathBuf {
    let lights = lamp("20.0");
    DemoShot { name: "live", lights: &lights, spp: 4, ..DemoShot::default() }.write(dir, &two_robots(1..=3))
}

/// Rewrites the lamp's intensity in `shot`, as an editor saving would.
fn set_intensity(shot: &Path, intensity: &str) {
    let text = std::fs::read_to_string(shot).unwrap();
    let line = text.lines().find(|l| l.starts_with("intensity = ")).unwrap().to_string();
    std::fs::write(shot, text.replacen(&line, &format!("intensity = {intensity}"), 1)).unwrap();
}

/// Stops the server when dropped (its live preview's thread with it).
struct Server(String, Stopper);

impl Drop for Server {
    fn drop(&mut self) {
        self.1.stop();
    }
}

/// `METHOD TARGET` with more header lines and a body, through the tests'
/// one HTTP client: status and body.
fn call(addr: &str, line: &str, headers: &str, body: &str) -> (u16, Vec<u8>) {
    let head = format!("{line} HTTP/1.1\r\nHost: {addr}\r\n{headers}Content-Length: {}", body.len());
    let reply = common::request(addr, &head, body.as_bytes());
    (reply.status, reply.body)
}

fn json(addr: &str, target: &str) -> Value {
    let (status, body) = call(addr, &format!("GET {target}"), "", "");
    assert_eq!(status, 200, "GET {target}: {}", String::from_utf8_lossy(&body));
    serde_json::from_slice(&body).unwrap()
}

fn post(addr: &str, target: &str, body: &str) -> (u16, Value) {
    let (status, body) = call(addr, &format!("POST {target}"), "Content-Type: application/json\r\n", body);
    (status, serde_json::from_slice(&body).unwrap_or(Value::Null))
}

/// The live image before denoising, as RGB8.
fn image(addr: &str) -> image::RgbImage {
    let (status, body) = call(addr, "GET /api/live.png?noisy=1", "", "");
    assert_eq!(status, 200, "{}", String::from_utf8_lossy(&body));
    image::load_from_memory(&body).expect("a PNG").to_rgb8()
}

fn mean(img: &image::RgbImage) -> f64 {
    img.pixels().map(|p| p.0.iter().map(|&c| f64::from(c)).sum::<f64>()).sum::<f64>() / img.len() as f64
}

/// Polls `/api/live` until `test` holds (60 s at most); the last status.
fn until(addr: &str, what: &str, test: impl Fn(&Value) -> bool) -> Value {
    let end = Instant::now() + Duration::from_secs(60);
    loop {
        let s = json(addr, "/api/live");
        if test(&s) {
            return s;
        }
        assert!(Instant::now() < end, "timed out waiting for {what}: {s}");
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Every file under `dir` with its size and modification time.
fn listing(dir: &Path) -> Vec<(PathBuf, u64, SystemTime)> {
    let mut out = Vec::new();
    for e in std::fs::read_dir(dir).unwrap().flatten() {
        let m = e.metadata().unwrap();
        if m.is_dir() {
            out.extend(listing(&e.path()));
        } else {
            out.push((e.path(), m.len(), m.modified().unwrap()));
        }
    }
    out.sort();
    out
}

fn live_options() -> LiveOptions {
    LiveOptions { resolution: Some(SIZE), threads: 2, ..LiveOptions::default() }
}

#[test]
fn the_live_preview_follows_edits_of_the_shot_and_writes_nothing() {
    let dir = tempdir().unwrap();
    let shot = write_shot(dir.path());
    // The renders folder the page reviews: the `full` layer at the preview's
    // size and samples, with its PNG (what the preview must equal).
    let renders = dir.path().join("renders");
    let job = RenderJob {
        png: true,
        resolution: Some(SIZE),
        ..RenderJob::new(vec!["full".into()], vec![FRAME], 4, renders.clone())
    };
    job::run(&ShotCrowd::load(&shot).unwrap(), None, &job, &Silent).unwrap();
    let before = listing(dir.path());

    let started = Instant::now();
    let options = ReviewOptions {
        renders: Some(renders.clone()),
        frame: Some(FRAME),
        port: 0,
        live: Some(live_options()),
        ..ReviewOptions::default()
    };
    let (addr, stopper) = start_review(&shot, options);
    let server = Server(addr, stopper);
    let a = server.0.as_str();
    assert!(json(a, "/api/shot")["live"].is_object());

    let first = until(a, "a first image", |s| s["image"].as_u64() > Some(0));
    eprintln!("first image {:.2} s after the server was started", started.elapsed().as_secs_f64());
    assert_eq!((first["frame"].as_i64(), first["width"].as_u64()), (Some(FRAME as i64), Some(48)));
    let s0 = until(a, "4 spp", |s| s["state"] == "converged" && s["image"] != first["image"]);
    assert_eq!((s0["spp"].as_u64(), s0["max_spp"].as_u64()), (Some(4), Some(4)), "{s0}");
    // The page says whether the last image is denoised (at the end, all of
    // its samples), and else why not.
    let denoised = s0["denoised"] == true && s0["denoised_spp"] == 4;
    assert!(denoised || s0["denoise_note"].is_string(), "{s0}");
    // Its passes are the render of their total samples: the job's PNG, within a code.
    let shown = image(a);
    let rendered = image::open(renders.join(format!("full/live.full.{FRAME:04}.png"))).unwrap().to_rgb8();
    assert_eq!(shown.dimensions(), rendered.dimensions());
    let off = shown.pixels().zip(rendered.pixels()).flat_map(|(p, q)| (0..3).map(move |c| p[c].abs_diff(q[c]))).max();
    assert!(off <= Some(1), "the preview is off the render by {off:?} codes");
    let dark = mean(&shown);

    // Four times the light: a brighter image, the cast kept.
    let edited = Instant::now();
    set_intensity(&shot, "80.0");
    let s1 = until(a, "the brighter render", |s| {
        s["generation"].as_u64() > s0["generation"].as_u64() && s["state"] == "converged"
    });
    eprintln!("edit to converged image {:.2} s ({s1})", edited.elapsed().as_secs_f64());
    assert_eq!(s1["reload"], "cast kept", "{s1}");
    let bright = mean(&image(a));
    assert!(bright > dark * 1.1, "four times the lamp: mean code {dark:.1} -> {bright:.1}");

    // A malformed edit: the error names the file and key; the server answers on.
    set_intensity(&shot, "\"bright\"");
    let broken = until(a, "the error", |s| !s["error"].is_null());
    let e = &broken["error"];
    assert_eq!(e["key"], "intensity", "{e}");
    assert!(e["file"].as_str().is_some_and(|f| f.ends_with("shot.toml")), "{e}");
    assert!(e["message"].as_str().unwrap().contains("intensity"), "{e}");
    assert_eq!(json(a, "/api/shot")["shot"], "live");
    assert_eq!(image(a).dimensions(), (48, 27), "the last image stays");
    // The next good edit renders again.
    set_intensity(&shot, "40.0");
    let s2 = until(a, "the render after the fix", |s| {
        s["error"].is_null() && s["generation"].as_u64() > s1["generation"].as_u64() && s["state"] == "converged"
    });
    let middle = mean(&image(a));
    assert!(dark < middle && middle < bright, "{dark:.1} < {middle:.1} < {bright:.1}");

    // Stopped, an edit waits; started, it is rendered.
    let (status, stopped) = post(a, "/api/live/stop", "{}");
    assert_eq!((status, stopped["run"].as_str()), (200, Some("stopped")), "{stopped}");
    set_intensity(&shot, "60.0");
    std::thread::sleep(Duration::from_millis(1200));
    let idle = json(a, "/api/live");
    assert_eq!((idle["run"].as_str(), &idle["generation"]), (Some("stopped"), &s2["generation"]), "{idle}");
    assert_eq!(post(a, "/api/live/start", "{}").0, 200);
    let s3 = until(a, "the render after start", |s| s["generation"].as_u64() > s2["generation"].as_u64());
    // An edit that changes the cast (the seed), and a new write of a file
    // the shot reads (its cache): cast anew.
    let text = std::fs::read_to_string(&shot).unwrap();
    std::fs::write(&shot, text.replacen("seed = 5", "seed = 6", 1)).unwrap();
    let s4 = until(a, "the recast", |s| s["generation"].as_u64() > s3["generation"].as_u64());
    assert_eq!(s4["reload"], "recast", "{s4}");
    let cache = dir.path().join("c.csv");
    std::fs::write(&cache, std::fs::read(&cache).unwrap()).unwrap();
    let s5 = until(a, "the cache read again", |s| s["generation"].as_u64() > s4["generation"].as_u64());
    assert_eq!(s5["reload"], "recast", "{s5}");
    // A frame of the shot, asked for; one outside it, an error.
    post(a, "/api/live/start", "{\"frame\": 1003}");
    until(a, "frame 1003", |s| s["frame"] == 1003 && s["state"] == "converged");
    post(a, "/api/live/start", "{\"frame\": 999}");
    let outside = until(a, "frame 999 refused", |s| !s["error"].is_null());
    assert!(outside["error"]["message"].as_str().unwrap().contains("999"), "{outside}");
    // Bad requests: 4xx, and the server answers on.
    assert_eq!(call(a, "POST /api/live/stop", "", "{}").0, 415);
    assert_eq!(post(a, "/api/live/start", "{\"frame\": \"x\"}").0, 400);
    assert_eq!(call(a, "GET /api/live.png?exposure=99", "", "").0, 400);
    assert_eq!(json(a, "/api/shot")["shot"], "live");
    drop(server);

    // Nothing written: the folder is as it was but for the test's own edits.
    let after = listing(dir.path());
    let mine = [shot.clone(), cache];
    let others =
        |l: &[(PathBuf, u64, SystemTime)]| l.iter().filter(|f| !mine.contains(&f.0)).cloned().collect::<Vec<_>>();
    assert_eq!(others(&after), others(&before));
    assert_eq!(after.len(), before.len(), "files were added: {after:?}");
}

#[test]
fn a_page_that_stops_polling_stops_the_preview() {
    let dir = tempdir().unwrap();
    let shot = write_shot(dir.path());
    let live = LiveOptions { idle: Duration::from_secs(1), max_spp: Some(1 << 16), ..live_options() };
    let (addr, stopper) = start_review(&shot, ReviewOptions { port: 0, live: Some(live), ..ReviewOptions::default() });
    let server = Server(addr, stopper);
    let a = server.0.as_str();
    let s0 = until(a, "a few passes", |s| s["pass"].as_u64() >= Some(3));
    let polled = Instant::now();
    std::thread::sleep(Duration::from_millis(2500));
    let s1 = json(a, "/api/live");
    let waited = polled.elapsed().as_secs_f64();
    assert_eq!(s1["run"], "idle", "{s1}");
    // No pass ended after the idle second (and the one pass then running).
    let rendered = s1["elapsed_s"].as_f64().unwrap() - s0["elapsed_s"].as_f64().unwrap();
    assert!(rendered < waited - 0.8, "passes went on for {rendered:.2} s of the {waited:.2} s nobody polled");
    // Polled again, it goes on.
    let s2 = until(a, "the render resumed", |s| s["run"] == "running" && s["spp"].as_u64() > s1["spp"].as_u64());
    assert!(s2["spp"].as_u64() < Some(1 << 16));
    // A review that is not live has no live preview.
    let (addr2, stopper2) = start_review(&shot, ReviewOptions { port: 0, ..ReviewOptions::default() });
    let other = Server(addr2, stopper2);
    assert_eq!(call(&other.0, "GET /api/live", "", "").0, 404);
    assert!(json(&other.0, "/api/shot")["live"].is_null());
}

/// Passes that continue each pixel's samples are one render of their total
/// (within float rounding); passes that each start at sample 0 are not.
#[test]
fn progressive_passes_add_up_to_one_render() {
    let dir = tempdir().unwrap();
    let crowd = ShotCrowd::load(&write_shot(dir.path())).unwrap();
    let scene = job::streamed_frame_scene(&crowd, None, "full", FRAME).unwrap();
    let blas = BlasSet::build(crowd.library());
    let base = RenderSettings {
        width: 32,
        height: 18,
        seed: 5,
        frame: i64::from(FRAME),
        sky_visible: true,
        threads: 2,
        ..RenderSettings::default()
    };
    let render = |spp, first_sample| {
        render_frame(&blas, crowd.library(), &scene, &RenderSettings { spp, first_sample, ..base.clone() }, None)
            .unwrap()
    };
    let whole = render(8, 0);
    let mean_of = |passes: &[(u32, u32)]| {
        let mut sum = vec![[0f32; 4]; whole.rgba.len()];
        for &(spp, first) in passes {
            for (s, p) in sum.iter_mut().zip(&render(spp, first).rgba) {
                *s = std::array::from_fn(|c| s[c] + p[c] * spp as f32);
            }
        }
        sum.into_iter().map(|p| p.map(|c| c / 8.0)).collect::<Vec<_>>()
    };
    let worst = |image: &[[f32; 4]]| {
        image
            .iter()
            .zip(&whole.rgba)
            .flat_map(|(a, b)| (0..4).map(move |c| (a[c] - b[c]).abs() / (1.0 + b[c])))
            .fold(0.0, f32::max)
    };
    let continued = worst(&mean_of(&[(1, 0), (1, 1), (2, 2), (4, 4)]));
    assert!(continued < 1e-5, "continued passes are off the whole render by {continued}");
    let restarted = worst(&mean_of(&[(1, 0), (1, 0), (2, 0), (4, 0)]));
    assert!(restarted > 1e-3, "passes from sample 0 repeat samples: off by only {restarted}");
    // Adaptive sampling starts every pixel at 0: a later first sample is refused.
    let adaptive = throng::shot::Adaptive { threshold: 0.05, min_spp: 4, max_spp: 16 };
    let adaptive = RenderSettings { first_sample: 4, adaptive: Some(adaptive), ..base };
    assert!(render_frame(&blas, crowd.library(), &scene, &adaptive, None).is_err());
}
