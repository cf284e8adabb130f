//! `throng review`: a local web page where a lighter looks at a shot's
//! rendered layers and clicks an agent to read its botInfo (docs/review.md).
//!
//! A small HTTP server (tiny_http), read-only, answering one request at a
//! time (each answer written on its own thread): the page
//! (`page.html`, `page.js`, `page.css`, built into the binary), JSON about
//! the shot, its frames and layers, PNGs tone-mapped on the server from the
//! layer EXRs (or their comp, stacked by `comp::over`), the layer map
//! (`layers::render_map`), and botInfo by pixel or id through the same
//! `botinfo::bot_info_with_layers` call `throng botinfo` makes. It reads
//! only files under the shot's folder and the renders folder ([`safe`]),
//! answers a bad request with a 4xx and a message and carries on, and keeps
//! decoded films and their PNGs in byte-bounded caches ([`lru`]).

mod deep_view;
mod figures;
mod live;
mod lru;
mod mixer;
mod safe;
mod tone;

use std::collections::BTreeMap;
use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

use glam::Vec3;
use serde_json::{json, Value};

use crate::botinfo::{agent_at_pixel, bot_info_with_layers, shot_manifest};
use crate::casting::ShotCrowd;
use crate::error::{Error, Result};
use crate::layers::{Manifest, MapOptions};
use crate::output::{layer_file_frame, layer_path};
use crate::render::exr::{read_channel_names, read_layer_channels, LayerMeta};
use crate::render::Film;
use lru::Lru;
use safe::{percent_decode, Root};

pub use live::LiveOptions;

const PAGE_HTML: &str = include_str!("page.html");
const PAGE_JS: &str = include_str!("page.js");
const PAGE_CSS: &str = include_str!("page.css");

/// The name the page and the API give the stack of a frame's layers.
pub const COMP_VIEW: &str = "comp";

/// How `throng review` serves a shot.
#[derive(Debug, Clone)]
pub struct ReviewOptions {
    /// The render output folder (`<layer>/<shot>.<layer>.<frame>.exr`); none:
    /// figures and map only.
    pub renders: Option<PathBuf>,
    /// The layer manifest; none: the shot's `<shot dir>/<shot>.layers.json`
    /// (as botinfo reads it), else `<shot>.layers.json` beside or in the
    /// renders folder (where `throng demo` writes it).
    pub manifest: Option<PathBuf>,
    /// The frame the page opens on (default: the first rendered).
    pub frame: Option<i32>,
    /// The address to listen on (127.0.0.1 unless asked).
    pub bind: IpAddr,
    /// The port (0: any free port).
    pub port: u16,
    /// Bytes of decoded films and PNGs kept between requests.
    pub cache_bytes: u64,
    /// A live preview of the page's frame that follows edits of the shot
    /// (`live`); none: the renders only.
    pub live: Option<LiveOptions>,
}

impl Default for ReviewOptions {
    fn default() -> Self {
        ReviewOptions {
            renders: None,
            manifest: None,
            frame: None,
            bind: IpAddr::V4(Ipv4Addr::LOCALHOST),
            port: 8028,
            cache_bytes: 1 << 30,
            live: None,
        }
    }
}

/// A decoded layer file, or a stack of them.
#[derive(Debug)]
struct Decoded {
    film: Film,
    meta: LayerMeta,
    /// The file (a layer), or none (a comp).
    file: Option<PathBuf>,
    /// Counts this decoded layer among those held (none: a comp).
    _held: Option<Held>,
}

/// How many decoded layers the review holds (in its cache or for the
/// request at hand), and the most it has held at once: what bounds a
/// request's memory (docs/review.md, "Memory bound"), shown by `/api/cache`.
#[derive(Debug, Default)]
struct LayerCount {
    now: AtomicUsize,
    peak: AtomicUsize,
}

/// One decoded layer, counted while it lives.
#[derive(Debug)]
struct Held(Arc<LayerCount>);

impl Held {
    fn new(count: &Arc<LayerCount>) -> Held {
        let now = count.now.fetch_add(1, Ordering::SeqCst) + 1;
        count.peak.fetch_max(now, Ordering::SeqCst);
        Held(count.clone())
    }
}

impl Drop for Held {
    fn drop(&mut self) {
        self.0.now.fetch_sub(1, Ordering::SeqCst);
    }
}

/// The channels one request decodes: only what its answer reads, so a
/// beauty view never holds normals, mattes or passes.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
struct Plan {
    /// `R G B A` (the beauty, and the over of everything stacked by it).
    colour: bool,
    normal: bool,
    albedo: bool,
    /// `Z` (the depth view, and which layer's id and `P` the comp takes).
    depth: bool,
    /// `agent.id`.
    id: bool,
    /// The `CryptoAgent` rank channels (the matte the page lays over).
    mattes: bool,
    /// One light pass (or `P`).
    pass: Option<String>,
    /// Every light-group pass (`lg_*`: the mixer).
    groups: bool,
}

impl Plan {
    /// What `endpoint` (`image`, `pick`, `agents`, `agent`, `matte`) needs
    /// for `view`, of a layer or of the comp (which stacks by alpha and Z).
    fn of(endpoint: &str, view: &str, comp: bool) -> Plan {
        let mut p = Plan::default();
        match endpoint {
            "image" => match view {
                "beauty" | "alpha" => p.colour = true,
                // The normal view shades by alpha.
                "normal" => (p.normal, p.colour) = (true, true),
                "albedo" => (p.albedo, p.colour) = (true, comp),
                "depth" => p.depth = true,
                "id" => (p.id, p.depth) = (true, comp),
                pass => {
                    p.pass = Some(pass.to_string());
                    p.colour = comp && pass != crate::scene::passes::POSITION;
                    p.depth = comp && pass == crate::scene::passes::POSITION;
                }
            },
            "matte" => (p.mattes, p.colour) = (true, comp),
            "mix" => (p.groups, p.colour) = (true, comp),
            _ => (p.id, p.depth) = (true, comp),
        }
        p
    }

    /// Whether channel `name` is decoded.
    fn keeps(&self, name: &str) -> bool {
        let pass = self.pass.as_deref().and_then(|p| name.strip_prefix(p)?.strip_prefix('.'));
        (self.colour && matches!(name, "R" | "G" | "B" | "A"))
            || (self.normal && matches!(name, "N.X" | "N.Y" | "N.Z"))
            || (self.albedo && matches!(name, "albedo.R" | "albedo.G" | "albedo.B"))
            || (self.depth && name == "Z")
            || (self.id && name == "agent.id")
            || (self.mattes && name.starts_with(crate::render::cryptomatte::AGENT_MATTE))
            || matches!(pass, Some("R" | "G" | "B" | "X" | "Y" | "Z"))
            || (self.groups
                && name
                    .strip_prefix(mixer::GROUP_PREFIX)
                    .is_some_and(|n| n.ends_with(".R") || n.ends_with(".G") || n.ends_with(".B")))
    }
}

/// The paths answered to `POST`: the mixer's save and the live preview's controls.
const POSTS: [&str; 3] = ["/api/save-shot", "/api/live/start", "/api/live/stop"];

/// A request answered with an error: the status and a message for the page.
#[derive(Debug)]
struct Refusal(u16, String);

type Answer<T> = std::result::Result<T, Refusal>;

/// A frame's layer files by name, in display order.
type LayerFiles = Vec<(String, PathBuf)>;

fn bad(msg: impl Into<String>) -> Refusal {
    Refusal(400, msg.into())
}

fn not_found(msg: impl Into<String>) -> Refusal {
    Refusal(404, msg.into())
}

/// A library error as the HTTP answer: what the request asked for is
/// wrong (400), or a file on disk is (500).
fn refusal(e: Error) -> Refusal {
    match e {
        Error::Usage(_) | Error::Setting { .. } => Refusal(400, e.to_string()),
        e => Refusal(500, e.to_string()),
    }
}

/// What a request gets back.
enum Body {
    Bytes(&'static str, Vec<u8>),
    File(&'static str, std::fs::File),
}

/// A running review server. [`Review::serve`] answers requests until a
/// [`Stopper`] stops it.
pub struct Review {
    server: Arc<tiny_http::Server>,
    stop: Arc<AtomicBool>,
    addr: SocketAddr,
    state: State,
}

/// Stops a [`Review`] from another thread.
#[derive(Clone)]
pub struct Stopper {
    server: Arc<tiny_http::Server>,
    stop: Arc<AtomicBool>,
}

impl Stopper {
    /// Makes [`Review::serve`] return after the request it is answering.
    pub fn stop(&self) {
        self.stop.store(true, Ordering::SeqCst);
        self.server.unblock();
    }
}

struct State {
    crowd: ShotCrowd,
    shot_file: PathBuf,
    shot_root: Root,
    /// The renders folder as given, and canonical.
    renders: Option<(PathBuf, Root)>,
    manifest: Option<(Manifest, PathBuf)>,
    start_frame: Option<i32>,
    set_bounds: Option<(Vec3, Vec3)>,
    /// `Host` header values accepted (none: any, when bound beyond loopback).
    hosts: Option<Vec<String>>,
    films: Mutex<Lru<Decoded>>,
    pngs: Mutex<Lru<Vec<u8>>>,
    layers_held: Arc<LayerCount>,
    live: Option<live::Live>,
}

impl Review {
    /// Opens the review of `crowd` (loaded from `shot_file`): finds its
    /// manifest, checks the renders folder holds this shot's layers, and
    /// listens on `options.bind:options.port`.
    pub fn open(crowd: ShotCrowd, shot_file: &Path, options: &ReviewOptions) -> Result<Review> {
        let name = crowd.shot().name.clone();
        let shot_dir = crowd.shot().path.parent().map(Path::to_path_buf).unwrap_or_else(|| PathBuf::from("."));
        let shot_dir = if shot_dir.as_os_str().is_empty() { PathBuf::from(".") } else { shot_dir };
        let shot_root = Root::new(&shot_dir).map_err(|e| Error::io(&shot_dir, e))?;
        let renders = match &options.renders {
            Some(dir) => {
                if !dir.is_dir() {
                    return Err(Error::setting("renders", format!("{} is not a folder", dir.display())));
                }
                Some((dir.clone(), Root::new(dir).map_err(|e| Error::io(dir, e))?))
            }
            None => None,
        };
        let manifest = find_manifest(&crowd, options, renders.as_ref().map(|r| r.0.as_path()))?;
        let mut state = State {
            set_bounds: crate::layers::set_bounds(&crowd),
            crowd,
            shot_file: shot_file.to_path_buf(),
            shot_root,
            renders,
            manifest,
            start_frame: None,
            hosts: None,
            films: Mutex::new(Lru::new(options.cache_bytes - options.cache_bytes / 8)),
            pngs: Mutex::new(Lru::new(options.cache_bytes / 8)),
            layers_held: Arc::default(),
            live: None,
        };
        if let Some((dir, _)) = &state.renders {
            let frames = state.scan();
            if frames.is_empty() {
                return Err(Error::setting(
                    "renders",
                    format!(
                        "{} holds no layer files of shot `{name}` (expected <layer>/{name}.<layer>.<frame>.exr)",
                        dir.display()
                    ),
                ));
            }
            state.start_frame = match options.frame {
                Some(f) if frames.contains_key(&f) => Some(f),
                Some(f) => {
                    let have: Vec<String> = frames.keys().map(i32::to_string).collect();
                    return Err(Error::setting(
                        "frame",
                        format!("frame {f} is not rendered in {}; rendered: {}", dir.display(), have.join(", ")),
                    ));
                }
                None => frames.keys().next().copied(),
            };
        }
        let server = tiny_http::Server::http(SocketAddr::new(options.bind, options.port))
            .map_err(|e| Error::setting("port", format!("cannot listen on {}:{}: {e}", options.bind, options.port)))?;
        let addr = server
            .server_addr()
            .to_ip()
            .ok_or_else(|| Error::setting("bind", "the server is not listening on an IP address"))?;
        if let Some(live) = &options.live {
            let shot = state.crowd.shot();
            let frame = options.frame.or(state.start_frame).unwrap_or(shot.frames.start);
            if !shot.frames.contains(frame) {
                let (a, b) = (shot.frames.start, shot.frames.end);
                return Err(Error::setting("frame", format!("frame {frame} is outside shot `{name}` ({a}-{b})")));
            }
            state.live = Some(live::Live::start(shot_file, frame, live.clone())?);
        }
        if addr.ip().is_loopback() {
            let port = addr.port();
            state.hosts = Some(vec![
                format!("127.0.0.1:{port}"),
                format!("localhost:{port}"),
                format!("[::1]:{port}"),
                addr.to_string(),
            ]);
        }
        Ok(Review { server: Arc::new(server), stop: Arc::new(AtomicBool::new(false)), addr, state })
    }

    /// The address it listens on.
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// The page's URL.
    pub fn url(&self) -> String {
        match self.addr.ip() {
            IpAddr::V4(Ipv4Addr::UNSPECIFIED) => format!("http://127.0.0.1:{}/", self.addr.port()),
            IpAddr::V6(a) if a.is_unspecified() => format!("http://[::1]:{}/", self.addr.port()),
            _ => format!("http://{}/", self.addr),
        }
    }

    /// The manifest it reads, if any.
    pub fn manifest_path(&self) -> Option<&Path> {
        self.state.manifest.as_ref().map(|(_, p)| p.as_path())
    }

    /// A handle that stops [`Review::serve`].
    pub fn stopper(&self) -> Stopper {
        Stopper { server: self.server.clone(), stop: self.stop.clone() }
    }

    /// Answers requests until stopped: each worked out one at a time, its
    /// answer written on a thread of its own. A request that fails is
    /// answered with its status and message; the server carries on.
    pub fn serve(&self) {
        while !self.stop.load(Ordering::SeqCst) {
            let Ok(mut request) = self.server.recv() else {
                if self.stop.load(Ordering::SeqCst) {
                    break;
                }
                // An accept error: go on listening, without spinning.
                std::thread::sleep(std::time::Duration::from_millis(20));
                continue;
            };
            let answer = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| self.state.answer(&mut request)))
                .unwrap_or_else(|_| Err(Refusal(500, "internal error while answering this request".into())));
            // Written on a thread of its own, so a client that reads slowly
            // (or never) holds up only itself; one that went away is no
            // concern of the server's.
            let writer = std::thread::Builder::new().name("review-respond".into());
            let _ = writer.spawn(move || {
                let _ = respond(request, answer);
            });
        }
    }
}

fn respond(request: tiny_http::Request, answer: Answer<Body>) -> std::io::Result<()> {
    let header = |k: &str, v: &str| tiny_http::Header::from_bytes(k.as_bytes(), v.as_bytes()).ok();
    let common = [header("X-Content-Type-Options", "nosniff"), header("Cache-Control", "no-store")];
    let head = request.method() == &tiny_http::Method::Head;
    match answer {
        Ok(Body::Bytes(kind, bytes)) => {
            let mut r = tiny_http::Response::from_data(if head { Vec::new() } else { bytes });
            for h in common.into_iter().chain([header("Content-Type", kind)]).flatten() {
                r.add_header(h);
            }
            request.respond(r)
        }
        Ok(Body::File(kind, file)) => {
            let mut r = tiny_http::Response::from_file(file);
            for h in common.into_iter().chain([header("Content-Type", kind)]).flatten() {
                r.add_header(h);
            }
            request.respond(r)
        }
        Err(Refusal(status, msg)) => {
            let body = serde_json::to_vec(&json!({ "status": status, "error": msg })).unwrap_or_default();
            let mut r = tiny_http::Response::from_data(body).with_status_code(status);
            for h in common.into_iter().chain([header("Content-Type", "application/json")]).flatten() {
                r.add_header(h);
            }
            request.respond(r)
        }
    }
}

/// The manifest the review reads, with its path.
fn find_manifest(
    crowd: &ShotCrowd,
    options: &ReviewOptions,
    renders: Option<&Path>,
) -> Result<Option<(Manifest, PathBuf)>> {
    let name = &crowd.shot().name;
    if let Some(path) = &options.manifest {
        let m = crate::layers::read_manifest(path)?;
        if &m.shot != name {
            return Err(Error::setting(
                "manifest",
                format!("{} is the manifest of shot `{}`, not of `{name}`", path.display(), m.shot),
            ));
        }
        return Ok(Some((m, path.clone())));
    }
    if let Some(m) = shot_manifest(crowd)? {
        return Ok(Some((m, crate::layers::default_manifest_path(&crowd.shot().path, name))));
    }
    let file = format!("{name}.layers.json");
    let beside = renders.into_iter().flat_map(|r| [r.parent().map(|p| p.join(&file)), Some(r.join(&file))]);
    for path in beside.flatten() {
        if path.is_file() {
            let m = crate::layers::read_manifest(&path)?;
            if &m.shot == name {
                return Ok(Some((m, path)));
            }
        }
    }
    Ok(None)
}

/// The query parameters of a URL, percent-decoded.
fn query(url: &str) -> Answer<BTreeMap<String, String>> {
    let mut out = BTreeMap::new();
    let Some((_, q)) = url.split_once('?') else { return Ok(out) };
    for pair in q.split('&').filter(|p| !p.is_empty()) {
        let (k, v) = pair.split_once('=').unwrap_or((pair, ""));
        let k = percent_decode(k, true).ok_or_else(|| bad(format!("bad escape in query `{pair}`")))?;
        let v = percent_decode(v, true).ok_or_else(|| bad(format!("bad escape in query `{pair}`")))?;
        out.insert(k, v);
    }
    Ok(out)
}

/// Parameter `key` of query `q`, parsed.
fn param<T: std::str::FromStr>(q: &BTreeMap<String, String>, key: &str) -> Answer<Option<T>> {
    match q.get(key) {
        None => Ok(None),
        Some(v) => v.trim().parse().map(Some).map_err(|_| bad(format!("`{key}={v}` is not a valid {key}"))),
    }
}

/// The `exposure` parameter, stops (default 0), within -20..20.
fn exposure(q: &BTreeMap<String, String>) -> Answer<f32> {
    let exposure: f32 = param(q, "exposure")?.unwrap_or(0.0);
    if !(exposure.abs() <= 20.0) {
        return Err(bad(format!("exposure {exposure} is outside -20..20 stops")));
    }
    Ok(exposure)
}

fn need<T: std::str::FromStr>(q: &BTreeMap<String, String>, key: &str) -> Answer<T> {
    param(q, key)?.ok_or_else(|| bad(format!("missing parameter `{key}`")))
}

fn json_body(v: &Value) -> Body {
    Body::Bytes("application/json", serde_json::to_vec(v).unwrap_or_default())
}

fn content_type(path: &Path) -> &'static str {
    match path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).as_deref() {
        Some("png") => "image/png",
        Some("json") => "application/json",
        Some("toml" | "txt" | "md" | "csv") => "text/plain; charset=utf-8",
        Some("exr") => "image/x-exr",
        Some("glb") => "model/gltf-binary",
        Some("hdr") => "image/vnd.radiance",
        _ => "application/octet-stream",
    }
}

/// A film's size in memory, bytes, for the cache bound: the channels it
/// holds (a request decodes only some).
fn film_bytes(f: &Film) -> u64 {
    let crypto: u64 = f.cryptomatte.iter().map(|m| m.pairs.len() as u64 * 8 + m.manifest.len() as u64 * 64).sum();
    let passes: u64 = f.passes.iter().map(|p| p.data.len() as u64 * 12).sum();
    let len = |n: usize, size: u64| n as u64 * size;
    len(f.rgba.len(), 16)
        + len(f.z.len(), 4)
        + len(f.normal.len(), 12)
        + len(f.albedo.len(), 12)
        + len(f.agent_id.len(), 4)
        + len(f.motion.len(), 8)
        + len(f.samples.len(), 4)
        + crypto
        + passes
}

/// Whether a request names the comp (the default) rather than a layer.
fn is_comp(q: &BTreeMap<String, String>) -> bool {
    q.get("layer").is_none_or(|l| l == COMP_VIEW)
}

/// Widest and narrowest layer map drawn, pixels.
const MAP_WIDTH: (u32, u32) = (320, 1600);

/// The size the layer map is drawn at for a page showing it `w` pixels wide
/// (16:9; 1600x900 when not asked): drawn at the size it is shown, its text
/// is the map font's own 7 pixels or more, where a 1600-pixel map shrunk to
/// a 500-pixel panel made it 3.
fn map_size(w: Option<u32>) -> (u32, u32) {
    let w = w.unwrap_or(MAP_WIDTH.1).clamp(MAP_WIDTH.0, MAP_WIDTH.1);
    (w, w * 9 / 16)
}

/// A file's identity for cache keys: path, length and modification time,
/// so a layer rendered again is decoded again.
fn file_key(path: &Path) -> String {
    let (len, modified) = std::fs::metadata(path)
        .map(|m| (m.len(), m.modified().ok().and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())))
        .unwrap_or((0, None));
    format!("{}|{len}|{:?}", path.display(), modified.map(|d| d.as_nanos()))
}

/// The pixel of `id` (cache id) nearest the centroid of its pixels in the
/// `agent.id` channel, and how many pixels it has.
fn agent_spot(film: &Film, id: u32) -> (Option<[u32; 2]>, usize) {
    let w = film.width as usize;
    let pixels: Vec<usize> = (0..film.agent_id.len()).filter(|&i| film.agent_id[i] == id + 1).collect();
    if pixels.is_empty() {
        return (None, 0);
    }
    let n = pixels.len() as f64;
    let cx = pixels.iter().map(|&i| (i % w) as f64).sum::<f64>() / n;
    let cy = pixels.iter().map(|&i| (i / w) as f64).sum::<f64>() / n;
    let d = |i: usize| ((i % w) as f64 - cx).powi(2) + ((i / w) as f64 - cy).powi(2);
    let best = pixels.iter().copied().min_by(|&a, &b| d(a).total_cmp(&d(b)).then(a.cmp(&b))).unwrap_or(pixels[0]);
    (Some([(best % w) as u32, (best / w) as u32]), pixels.len())
}

impl State {
    fn name(&self) -> &str {
        &self.crowd.shot().name
    }

    fn manifest(&self) -> Option<&Manifest> {
        self.manifest.as_ref().map(|(m, _)| m)
    }

    /// The rendered frames and, for each, its layer files, from the renders
    /// folder as it is now (renders that land while the page is open show).
    fn scan(&self) -> BTreeMap<i32, BTreeMap<String, PathBuf>> {
        let mut out: BTreeMap<i32, BTreeMap<String, PathBuf>> = BTreeMap::new();
        let Some((dir, root)) = &self.renders else { return out };
        let Ok(entries) = std::fs::read_dir(dir) else { return out };
        for sub in entries.filter_map(|e| e.ok()).filter(|e| e.path().is_dir()) {
            let Ok(layer) = sub.file_name().into_string() else { continue };
            let Ok(files) = std::fs::read_dir(sub.path()) else { continue };
            for f in files.filter_map(|e| e.ok()) {
                let Ok(file) = f.file_name().into_string() else { continue };
                // Only files that resolve inside the renders folder (no symlink out).
                let Some(frame) = layer_file_frame(&file, self.name(), &layer) else { continue };
                if let Ok(real) = root.confine(&f.path()) {
                    out.entry(frame).or_default().insert(layer.clone(), real);
                }
            }
        }
        out
    }

    /// Layer names of `frame`: the comp order (back to front) first, then
    /// any other (the `full` reference).
    fn ordered_layers(&self, frame: i32) -> Answer<(LayerFiles, Answer<Vec<String>>)> {
        let scan = self.scan();
        let Some(files) = scan.get(&frame) else {
            let have: Vec<String> = scan.keys().map(i32::to_string).collect();
            return Err(not_found(format!("frame {frame} is not rendered; rendered frames: {}", have.join(", "))));
        };
        let comp = match &self.renders {
            Some((dir, _)) => crate::comp::layer_files(dir, frame, self.manifest())
                .map(|l| l.into_iter().map(|(name, _)| name).collect())
                .map_err(|e| Refusal(404, format!("no comp of frame {frame}: {e}"))),
            None => Err(not_found("no renders folder")),
        };
        let mut names: Vec<String> = comp.as_ref().map(|c: &Vec<String>| c.clone()).unwrap_or_default();
        names.retain(|n| files.contains_key(n));
        let mut rest: Vec<String> = files.keys().filter(|k| !names.contains(k)).cloned().collect();
        rest.sort();
        names.extend(rest);
        Ok((names.into_iter().map(|n| (n.clone(), files[&n].clone())).collect(), comp))
    }

    /// The file of `layer` at `frame`, confined to the renders folder.
    fn layer_file(&self, frame: i32, layer: &str) -> Answer<PathBuf> {
        let Some((dir, root)) = &self.renders else { return Err(not_found("no renders folder")) };
        let scan = self.scan();
        let files = scan.get(&frame).ok_or_else(|| not_found(format!("frame {frame} is not rendered")))?;
        if !files.contains_key(layer) {
            let have: Vec<&str> = files.keys().map(String::as_str).collect();
            return Err(not_found(format!("no layer `{layer}` at frame {frame}; it has {}", have.join(", "))));
        }
        // The name the scan found, checked again as it is read.
        root.confine(&layer_path(dir, self.name(), layer, frame)).map_err(|(status, m)| Refusal(status, m))
    }

    /// The channels of a layer file `plan` names, decoded (cached).
    fn decode_layer(&self, frame: i32, layer: &str, plan: &Plan) -> Answer<Arc<Decoded>> {
        let path = self.layer_file(frame, layer)?;
        let key = format!("{}|{plan:?}", file_key(&path));
        if let Some(d) = self.films.lock().map_err(|_| Refusal(500, "cache poisoned".into()))?.get(&key) {
            return Ok(d);
        }
        let held = Held::new(&self.layers_held);
        let (film, meta) = read_layer_channels(&path, &|c| plan.keeps(c)).map_err(refusal)?;
        if meta.shot != self.name() || meta.frame != frame {
            return Err(Refusal(
                500,
                format!(
                    "{} says it is shot `{}` frame {}, its name says `{}` frame {frame}",
                    path.display(),
                    meta.shot,
                    meta.frame,
                    self.name()
                ),
            ));
        }
        let bytes = film_bytes(&film);
        let d = Decoded { film, meta, file: Some(path), _held: Some(held) };
        Ok(self.films.lock().map_err(|_| Refusal(500, "cache poisoned".into()))?.insert(key, d, bytes))
    }

    /// The image a request names, with the channels `plan` names: a layer,
    /// or the comp of the layers it lists (`layers=a,b`, default all),
    /// stacked by `comp`'s folds one layer at a time (colour back to front,
    /// mattes front to back), so a request holds one decoded layer besides
    /// the stack (and what the cache keeps).
    fn decode(&self, q: &BTreeMap<String, String>, plan: &Plan) -> Answer<Arc<Decoded>> {
        let frame: i32 = need(q, "frame")?;
        let layer = q.get("layer").map(String::as_str).unwrap_or(COMP_VIEW);
        if layer != COMP_VIEW {
            return self.decode_layer(frame, layer, plan);
        }
        let (files, comp) = self.ordered_layers(frame)?;
        let order = comp?;
        let chosen: Vec<String> = match q.get("layers") {
            None => order.clone(),
            Some(list) => {
                let asked: Vec<&str> = list.split(',').map(str::trim).filter(|s| !s.is_empty()).collect();
                if let Some(unknown) = asked.iter().find(|a| !order.iter().any(|o| o == *a)) {
                    return Err(bad(format!("`{unknown}` is not a layer of the comp ({})", order.join(", "))));
                }
                order.iter().filter(|o| asked.contains(&o.as_str())).cloned().collect()
            }
        };
        if chosen.is_empty() {
            return Err(bad("no layers chosen for the comp"));
        }
        let keys: Vec<String> = (chosen.iter())
            .map(|l| files.iter().find(|(n, _)| n == l).map(|(_, p)| file_key(p)).unwrap_or_default())
            .collect();
        let key = format!("comp|{frame}|{plan:?}|{}", keys.join("|"));
        if let Some(d) = self.films.lock().map_err(|_| Refusal(500, "cache poisoned".into()))?.get(&key) {
            return Ok(d);
        }
        let mut meta = None;
        let film = if plan.mattes {
            // Front to back: what is in front hides what is behind.
            let mut film = Film::new(0, 0);
            let mut stack: Option<crate::comp::MatteStack> = None;
            for l in chosen.iter().rev() {
                let d = self.decode_layer(frame, l, plan)?;
                (film.width, film.height) = (d.film.width, d.film.height);
                let s = stack.get_or_insert_with(|| crate::comp::MatteStack::new(d.film.width, d.film.height));
                s.push(&d.film).map_err(refusal)?;
                // The back layer's header, as the colour stack takes.
                meta = Some(d.meta.clone());
            }
            film.cryptomatte = stack.map(crate::comp::MatteStack::finish).unwrap_or_default();
            film
        } else {
            let mut stack: Option<crate::comp::Stack> = None;
            for l in &chosen {
                let d = self.decode_layer(frame, l, plan)?;
                let s = stack.get_or_insert_with(|| crate::comp::Stack::new(&d.film));
                s.push(&d.film).map_err(refusal)?;
                meta.get_or_insert_with(|| d.meta.clone());
            }
            stack.map(crate::comp::Stack::finish).unwrap_or_else(|| Film::new(0, 0))
        };
        let Some(meta) = meta else { return Err(bad("no layers chosen for the comp")) };
        let meta = LayerMeta { layer: COMP_VIEW.to_string(), ..meta };
        let bytes = film_bytes(&film);
        let d = Decoded { film, meta, file: None, _held: None };
        Ok(self.films.lock().map_err(|_| Refusal(500, "cache poisoned".into()))?.insert(key, d, bytes))
    }

    fn cached_png(&self, key: String, make: impl FnOnce() -> Answer<Vec<u8>>) -> Answer<Body> {
        if let Some(p) = self.pngs.lock().map_err(|_| Refusal(500, "cache poisoned".into()))?.get(&key) {
            return Ok(Body::Bytes("image/png", p.as_ref().clone()));
        }
        let png = make()?;
        let bytes = png.len() as u64;
        let p = self.pngs.lock().map_err(|_| Refusal(500, "cache poisoned".into()))?.insert(key, png, bytes);
        Ok(Body::Bytes("image/png", p.as_ref().clone()))
    }

    fn key_of(d: &Decoded, q: &BTreeMap<String, String>) -> String {
        format!(
            "{}|{}|{}",
            d.file.as_deref().map(file_key).unwrap_or_else(|| format!("comp {:?}", q.get("layers"))),
            q.get("frame").map(String::as_str).unwrap_or(""),
            d.meta.layer
        )
    }

    /// Routes one request.
    fn answer(&self, request: &mut tiny_http::Request) -> Answer<Body> {
        let post = request.method() == &tiny_http::Method::Post;
        let path = request.url().split('?').next().unwrap_or("");
        let posted = POSTS.iter().copied().find(|p| *p == path).filter(|_| post);
        if posted.is_none() && !matches!(request.method(), tiny_http::Method::Get | tiny_http::Method::Head) {
            return Err(Refusal(
                405,
                format!(
                    "{} is not served: the review reads (GET) but for POST {}",
                    request.method(),
                    POSTS.join(", POST ")
                ),
            ));
        }
        if let Some(hosts) = &self.hosts {
            let host = request.headers().iter().find(|h| h.field.equiv("Host")).map(|h| h.value.as_str().to_string());
            if let Some(host) = host.filter(|h| !hosts.contains(h)) {
                return Err(Refusal(403, format!("Host `{host}` is not this server's address")));
            }
        }
        match posted {
            Some("/api/save-shot") => return self.save_shot(request),
            Some(p) => {
                let body = self.posted_json(request)?;
                let live = self.live()?;
                return if p == "/api/live/stop" { live.stop() } else { live.start_frame(&body) };
            }
            None => {}
        }
        let url = request.url();
        let path = url.split('?').next().unwrap_or("");
        let q = query(url)?;
        match path {
            "/" | "/index.html" => Ok(Body::Bytes("text/html; charset=utf-8", PAGE_HTML.as_bytes().to_vec())),
            "/page.js" => Ok(Body::Bytes("text/javascript; charset=utf-8", PAGE_JS.as_bytes().to_vec())),
            "/page.css" => Ok(Body::Bytes("text/css; charset=utf-8", PAGE_CSS.as_bytes().to_vec())),
            "/api/shot" => Ok(json_body(&self.shot())),
            "/api/frames" => Ok(json_body(&json!({ "frames": self.scan().keys().collect::<Vec<_>>() }))),
            "/api/layers" => self.layers(&q),
            "/api/image.png" => self.image(&q),
            "/api/pick" => self.pick(&q),
            "/api/agent" => self.agent(&q),
            "/api/agents" => self.agents(&q),
            "/api/matte.png" => self.matte(&q),
            "/api/mix.png" => self.mix(&q),
            "/api/deep.png" => self.deep_png(&q),
            "/api/map.png" => self.map(&q),
            "/api/live" => Ok(json_body(&self.live()?.poll())),
            "/api/live.png" => self.live()?.png(exposure(&q)?, q.get("noisy").is_some_and(|v| v == "1")),
            "/api/cache" => Ok(json_body(&self.cache_figures()?)),
            "/api/figures" => Ok(json_body(&figures::figures(
                &self.crowd,
                self.manifest.as_ref().map(|(m, p)| (m, p.as_path())),
                self.renders.as_ref().map(|r| r.0.as_path()),
                &self.shot_file,
            ))),
            p => match p.strip_prefix("/files/") {
                Some(rest) => self.file(rest),
                None => Err(not_found(format!("no page `{p}`"))),
            },
        }
    }

    /// The live preview, when the review has one.
    fn live(&self) -> Answer<&live::Live> {
        self.live.as_ref().ok_or_else(|| not_found("no live preview: the review was not started live"))
    }

    /// What the caches hold: entries, bytes and bound of each.
    fn cache_figures(&self) -> Answer<Value> {
        let poisoned = || Refusal(500, "cache poisoned".into());
        let films = self.films.lock().map_err(|_| poisoned())?;
        let pngs = self.pngs.lock().map_err(|_| poisoned())?;
        Ok(json!({
            "films": { "entries": films.len(), "bytes": films.used(), "bound": films.bound() },
            "pngs": { "entries": pngs.len(), "bytes": pngs.used(), "bound": pngs.bound() },
            "layers_held": {
                "now": self.layers_held.now.load(Ordering::SeqCst),
                "peak": self.layers_held.peak.load(Ordering::SeqCst),
            },
        }))
    }

    fn shot(&self) -> Value {
        let s = self.crowd.shot();
        json!({
            "shot": s.name,
            "shot_file": self.shot_file,
            "frames": [s.frames.start, s.frames.end],
            "resolution": s.render.resolution,
            "renders": self.renders.as_ref().map(|r| &r.0),
            "manifest": self.manifest.as_ref().map(|(_, p)| p),
            "rendered_frames": self.scan().keys().collect::<Vec<_>>(),
            "start_frame": self.start_frame,
            "comp_view": COMP_VIEW,
            "views": tone::BASIC_VIEWS,
            "gains": s.lights.gains,
            "live": self.live.as_ref().map(live::Live::describe),
        })
    }

    fn layers(&self, q: &BTreeMap<String, String>) -> Answer<Body> {
        let frame: i32 = need(q, "frame")?;
        let (files, comp) = self.ordered_layers(frame)?;
        let renders = self.renders.as_ref().map(|r| r.1.dir.clone()).unwrap_or_default();
        let mut layers = Vec::new();
        for (name, path) in &files {
            let (w, h, channels) = read_channel_names(path).map_err(refusal)?;
            let passes = crate::render::exr::pass_layout(&channels).into_iter().map(|(n, _)| n);
            layers.push(json!({
                "name": name,
                "file": path.strip_prefix(&renders).unwrap_or(path),
                "width": w,
                "height": h,
                "views": tone::views(passes),
                "cryptomatte": channels.iter().any(|c| c.starts_with(crate::render::cryptomatte::AGENT_MATTE)),
                "in_comp": comp.as_ref().is_ok_and(|c| c.contains(name)),
                "deep": self.deep_legend(path),
            }));
        }
        let comp = match comp {
            Ok(order) => {
                // The comp stacks the passes every one of its layers has.
                let of = |name: &String| layers.iter().find(|l| &l["name"] == name).map(|l| &l["views"]);
                let mut views: Vec<Value> = of(&order[0]).and_then(Value::as_array).cloned().unwrap_or_default();
                for name in &order[1..] {
                    let here = of(name).and_then(Value::as_array);
                    views.retain(|v| here.is_some_and(|h| h.contains(v)));
                }
                json!({ "layers": order, "views": views })
            }
            Err(Refusal(_, msg)) => json!({ "error": msg }),
        };
        Ok(json_body(&json!({ "frame": frame, "layers": layers, "comp": comp })))
    }

    fn image(&self, q: &BTreeMap<String, String>) -> Answer<Body> {
        let view = q.get("view").map(String::as_str).unwrap_or("beauty");
        let exposure = exposure(q)?;
        let d = self.decode(q, &Plan::of("image", view, is_comp(q)))?;
        let key = format!("image|{}|{view}|{:08x}", Self::key_of(&d, q), exposure.to_bits());
        self.cached_png(key, || {
            let px = tone::view_pixels(&d.film, d.meta.colourspace, view, exposure).map_err(not_found)?;
            tone::png(d.film.width, d.film.height, 3, px).map_err(|m| Refusal(500, m))
        })
    }

    /// `/api/mix.png`: the image's light groups regraded by `mix`
    /// (`group:gain:r:g:b,...`, linear), exposed by `exposure` stops.
    fn mix(&self, q: &BTreeMap<String, String>) -> Answer<Body> {
        let exposure = exposure(q)?;
        let mix_text = q.get("mix").map(String::as_str).unwrap_or("");
        let gains = mixer::parse(mix_text).map_err(bad)?;
        let d = self.decode(q, &Plan::of("mix", "", is_comp(q)))?;
        let key = format!("mix|{}|{mix_text}|{:08x}", Self::key_of(&d, q), exposure.to_bits());
        self.cached_png(key, || {
            let light = mixer::mix(&d.film, d.meta.colourspace, &gains).map_err(not_found)?;
            let px = tone::light_pixels(d.meta.colourspace, light.into_iter(), exposure);
            tone::png(d.film.width, d.film.height, 3, px).map_err(|m| Refusal(500, m))
        })
    }

    /// The JSON body of a `POST`, refused unless it is JSON (415), from this
    /// server's page when an `Origin` is sent (403), at most 64 KiB (413).
    fn posted_json(&self, request: &mut tiny_http::Request) -> Answer<Value> {
        // A page elsewhere cannot send JSON here without asking first (CORS
        // preflight, which gets 405); its own origin must be this server.
        let header = |name: &'static str| {
            request.headers().iter().find(|h| h.field.equiv(name)).map(|h| h.value.as_str().to_string())
        };
        if !header("Content-Type").is_some_and(|c| c.starts_with("application/json")) {
            return Err(Refusal(415, format!("{} takes application/json", request.url())));
        }
        if let (Some(origin), Some(hosts)) = (header("Origin"), &self.hosts) {
            if !hosts.iter().any(|h| origin == format!("http://{h}")) {
                return Err(Refusal(403, format!("Origin `{origin}` is not this server")));
            }
        }
        let mut body = Vec::new();
        std::io::Read::read_to_end(&mut std::io::Read::take(request.as_reader(), 64 * 1024 + 1), &mut body)
            .map_err(|e| bad(format!("cannot read the request: {e}")))?;
        if body.len() > 64 * 1024 {
            return Err(Refusal(413, "the request is over 64 KiB".into()));
        }
        serde_json::from_slice(&body).map_err(|e| bad(format!("not JSON: {e}")))
    }

    /// `POST /api/save-shot` `{"name": FILE, "mix": "group:gain:r:g:b,..."}`:
    /// the shot with the mix folded into its `[lights.gains]`, written as a
    /// new file beside it (never over one), and the command that renders it.
    fn save_shot(&self, request: &mut tiny_http::Request) -> Answer<Body> {
        let v = self.posted_json(request)?;
        let name = v["name"].as_str().ok_or_else(|| bad("missing `name` (the new shot's file name)"))?;
        let name = mixer::shot_file_name(name).map_err(bad)?;
        let gains = mixer::parse(v["mix"].as_str().unwrap_or("")).map_err(bad)?;
        let shot = self.crowd.shot();
        let groups = self.crowd.light_groups().map_err(refusal)?;
        if let Some(g) = gains.keys().find(|g| !groups.names.contains(g)) {
            return Err(not_found(format!("`{g}` is no light group of the shot ({})", groups.names.join(", "))));
        }
        let shown = shot.path.display();
        let text = std::fs::read_to_string(&shot.path)
            .map_err(|e| Refusal(500, format!("cannot read the shot {shown}: {e}")))?;
        // The mix regrades renders of the shot as this review read it; gains
        // edited on disk since would be silently replaced or multiplied.
        let on_disk = crate::shot::Shot::parse(&text, &shot.path)
            .map_err(|e| Refusal(409, format!("the shot on disk no longer reads ({e}); fix it, then save")))?;
        if on_disk.lights.gains != shot.lights.gains {
            return Err(Refusal(
                409,
                format!(
                    "{shown}'s [lights.gains] changed since this review read it: restart the review to mix from them"
                ),
            ));
        }
        let text = mixer::with_gains(&text, &shot.lights.gains, &gains).map_err(|m| Refusal(409, m))?;
        let dir = &self.shot_root.dir;
        // Saved only if it reads back carrying exactly the page's gains.
        let reread = crate::shot::Shot::parse(&text, &dir.join(&name));
        if !reread.is_ok_and(|s| s.lights.gains == mixer::merged(&shot.lights.gains, &gains)) {
            return Err(Refusal(
                409,
                format!("{shown} spells its gains in a way the mixer cannot rewrite: edit them by hand"),
            ));
        }
        let path = mixer::write_new(dir, &name, &text).map_err(|(status, m)| Refusal(status, m))?;
        let stem = path.file_stem().and_then(|s| s.to_str()).unwrap_or("look").replace(' ', "_");
        let out = match &self.renders {
            Some((r, _)) => {
                r.with_file_name(format!("{}_{stem}", r.file_name().and_then(|n| n.to_str()).unwrap_or("render")))
            }
            None => dir.join(format!("render_{stem}")),
        };
        // The page words the render command (the library never names a flag).
        Ok(json_body(&json!({ "file": path, "out": out, "gains": gains })))
    }

    /// botInfo of `ids` at `frame`: exactly `throng botinfo --json`'s array.
    fn bot_info(&self, ids: &[u32], frame: i32) -> Answer<Value> {
        let infos = bot_info_with_layers(&self.crowd, ids, frame, self.manifest()).map_err(|e| match e {
            e @ (Error::Usage(_) | Error::Setting { .. }) => not_found(e.to_string()),
            e => refusal(e),
        })?;
        // Through text, as `--json` prints it: f32 fields keep their shortest
        // spelling (22.77457), which a direct `to_value` would widen to f64.
        let text = serde_json::to_string(&infos).map_err(|e| Refusal(500, format!("cannot write JSON: {e}")))?;
        serde_json::from_str(&text).map_err(|e| Refusal(500, format!("cannot write JSON: {e}")))
    }

    fn pick(&self, q: &BTreeMap<String, String>) -> Answer<Body> {
        let (x, y): (u32, u32) = (need(q, "x")?, need(q, "y")?);
        let d = self.decode(q, &Plan::of("pick", "", is_comp(q)))?;
        let what = d.file.clone().unwrap_or_else(|| PathBuf::from(COMP_VIEW));
        let id = agent_at_pixel(&d.film.agent_id, d.film.width, d.film.height, x, y, &what).map_err(refusal)?;
        let botinfo = match id {
            Some(id) => self.bot_info(&[id], d.meta.frame)?,
            None => Value::Null,
        };
        Ok(json_body(&json!({
            "frame": d.meta.frame,
            "layer": d.meta.layer,
            "x": x,
            "y": y,
            "agent": id,
            "botinfo": botinfo,
            "file": d.file,
        })))
    }

    fn agent(&self, q: &BTreeMap<String, String>) -> Answer<Body> {
        let (id, frame): (u32, i32) = (need(q, "id")?, need(q, "frame")?);
        let botinfo = self.bot_info(&[id], frame)?;
        let (pixel, pixels) = match q.get("layer") {
            Some(_) => agent_spot(&self.decode(q, &Plan::of("agent", "", is_comp(q)))?.film, id),
            None => (None, 0),
        };
        Ok(json_body(&json!({ "id": id, "frame": frame, "botinfo": botinfo, "pixel": pixel, "pixels": pixels })))
    }

    fn agents(&self, q: &BTreeMap<String, String>) -> Answer<Body> {
        let d = self.decode(q, &Plan::of("agents", "", is_comp(q)))?;
        let mut counts: BTreeMap<u32, usize> = BTreeMap::new();
        for &a in d.film.agent_id.iter().filter(|&&a| a > 0) {
            *counts.entry(a - 1).or_default() += 1;
        }
        let mut rows: Vec<(u32, usize)> = counts.into_iter().collect();
        rows.sort_by_key(|&(id, n)| (std::cmp::Reverse(n), id));
        let list: Vec<Value> =
            rows.iter().map(|&(id, n)| json!({ "id": id, "pixels": n, "pixel": agent_spot(&d.film, id).0 })).collect();
        Ok(json_body(&json!({ "frame": d.meta.frame, "layer": d.meta.layer, "agents": list })))
    }

    fn matte(&self, q: &BTreeMap<String, String>) -> Answer<Body> {
        let id: u32 = need(q, "id")?;
        let mut d = self.decode(q, &Plan::of("matte", "", is_comp(q)))?;
        if !d.film.cryptomatte.iter().any(|m| m.name == crate::render::cryptomatte::AGENT_MATTE) {
            // No `CryptoAgent`: the matte is `agent.id`'s.
            d = self.decode(q, &Plan::of("pick", "", is_comp(q)))?;
        }
        let key = format!("matte|{}|{id}", Self::key_of(&d, q));
        self.cached_png(key, || {
            let (coverage, _) = tone::agent_coverage(&d.film, id);
            tone::png(d.film.width, d.film.height, 4, tone::matte_pixels(&coverage)).map_err(|m| Refusal(500, m))
        })
    }

    fn map(&self, q: &BTreeMap<String, String>) -> Answer<Body> {
        let Some(m) = self.manifest() else {
            return Err(not_found("no layer manifest: run `throng layers` on the shot (or name the manifest)"));
        };
        let agent: Option<u32> = param(q, "agent")?;
        let size = map_size(param(q, "w")?);
        self.cached_png(format!("map|{agent:?}|{size:?}"), || {
            let opts = MapOptions { size, set_bounds: self.set_bounds, highlight: agent };
            crate::layers::render_map(m, &opts).map_err(|e| Refusal(500, e.to_string()))
        })
    }

    /// `/files/shot/REL` and `/files/renders/REL`: a file as it is on disk.
    fn file(&self, rest: &str) -> Answer<Body> {
        let (root, rel) = match rest.split_once('/') {
            Some(("shot", rel)) => (&self.shot_root, rel),
            Some(("renders", rel)) => match &self.renders {
                Some((_, root)) => (root, rel),
                None => return Err(not_found("no renders folder")),
            },
            _ => return Err(not_found("files are under /files/shot/ and /files/renders/")),
        };
        let rel = percent_decode(rel, false).ok_or_else(|| bad("bad escape in the path"))?;
        let path = root.file(&rel).map_err(|(status, m)| Refusal(status, m))?;
        let file = std::fs::File::open(&path).map_err(|e| Refusal(404, format!("cannot open {rel}: {e}")))?;
        Ok(Body::File(content_type(&path), file))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Which channels each request decodes (docs/review.md, "Memory bound").
    #[test]
    fn a_request_decodes_only_the_channels_it_reads() {
        let channels = [
            "A",
            "B",
            "G",
            "R",
            "N.X",
            "Z",
            "agent.id",
            "albedo.R",
            "CryptoAgent00.R",
            "CryptoPart00.R",
            "diffuse_direct.R",
            "P.X",
            "forward.u",
            "samples",
        ];
        let kept = |p: Plan| channels.iter().filter(|c| p.keeps(c)).copied().collect::<Vec<_>>();
        for comp in [false, true] {
            assert_eq!(kept(Plan::of("image", "beauty", comp)), ["A", "B", "G", "R"]);
            assert_eq!(kept(Plan::of("image", "depth", comp)), ["Z"]);
            assert_eq!(kept(Plan::of("image", "normal", comp)), ["A", "B", "G", "R", "N.X"]);
        }
        // A layer's pick reads the ids; the comp's also the depth that picks the layer.
        assert_eq!(kept(Plan::of("pick", "", false)), ["agent.id"]);
        assert_eq!(kept(Plan::of("pick", "", true)), ["Z", "agent.id"]);
        assert_eq!(kept(Plan::of("agents", "", true)), ["Z", "agent.id"]);
        assert_eq!(kept(Plan::of("matte", "", false)), ["CryptoAgent00.R"]);
        assert_eq!(kept(Plan::of("matte", "", true)), ["A", "B", "G", "R", "CryptoAgent00.R"]);
        // A pass view reads that pass (stacked over by alpha in the comp), not its namesakes.
        assert_eq!(kept(Plan::of("image", "diffuse_direct", false)), ["diffuse_direct.R"]);
        assert_eq!(kept(Plan::of("image", "diffuse_direct", true)), ["A", "B", "G", "R", "diffuse_direct.R"]);
        assert_eq!(kept(Plan::of("image", "P", true)), ["Z", "P.X"]);
        assert!(!Plan::of("image", "diffuse", false).keeps("diffuse_direct.R"));
    }
}
