//! `throng review --live` (docs/review.md, "Live preview"): the page's frame
//! rendered in memory at a preview size while the lighter edits the shot.
//!
//! A thread of its own, with a rayon pool of at most the options' threads,
//! renders the frame's `full` picture (every agent, the set and the sky, as
//! `throng render --layer full` without a manifest) progressively: pass
//! after pass, each continuing every pixel's sample sequence where the last
//! stopped (`RenderSettings::first_sample`), so the passes so far are one
//! render of their total samples. Each pass's mean is published for the
//! page at once, and denoised (Open Image Denoise, when it is found) when
//! its samples have doubled since the last denoised image, and at the end.
//!
//! It watches the shot file and every file the cast shot was read from
//! (sizes and modification times, polled) and starts again once they hold
//! still ([`DEBOUNCE`]): an edit of the shot file that leaves the cast as it
//! was (lights, camera keys, render settings, air, layers) keeps the cast
//! crowd ([`ShotCrowd::with_shot`]); any other edit casts it anew. A shot
//! that no longer reads is shown as its error (file, line and key) and the
//! preview resumes at the next edit that reads. It stops when the page asks
//! or when no page has polled for [`LiveOptions::idle`], and writes no file.

use std::path::{Path, PathBuf};
use std::sync::{Arc, Condvar, Mutex, MutexGuard};
use std::thread::JoinHandle;
use std::time::{Duration, Instant, SystemTime};

use serde_json::{json, Value};

use super::{bad, tone, Answer, Body, Refusal};
use crate::casting::motion::MotionFrame;
use crate::casting::ShotCrowd;
use crate::error::{Error, Result};
use crate::output::FULL_LAYER;
use crate::render::colour::{self, Colourspace, ConvertedDome};
use crate::render::denoise::Denoiser;
use crate::render::job::{layer_settings, motion_scene, streamed_frame_scene, RenderJob};
use crate::render::{render_frame, BlasSet, Film, RenderSettings};
use crate::scene::passes::PassSet;
use crate::scene::{Acescg, FrameScene, Space};
use crate::shot::{Denoise, Shot};

/// How long the watched files must hold still after a change before the
/// preview starts again (an editor's save can be several writes).
const DEBOUNCE: Duration = Duration::from_millis(300);
/// How often the watched files are looked at.
const WATCH_EVERY: Duration = Duration::from_millis(100);
/// The most samples one pass takes: passes double (1, 1, 2, 4, ...) up to it,
/// so the first image comes after one sample and later ones keep coming.
const PASS_CAP: u32 = 16;
/// The longest a pass should take (by the last pass's time a sample): an
/// edit is only looked at between passes.
const PASS_TIME: Duration = Duration::from_millis(250);
/// The preview's denoiser quality: OIDN's interactive preset.
const PREVIEW_DENOISE: Denoise = Denoise::Fast;

/// How `throng review` renders its live preview.
#[derive(Debug, Clone)]
pub struct LiveOptions {
    /// The preview's size; none: a quarter of the shot's resolution in each axis.
    pub resolution: Option<[u32; 2]>,
    /// Render threads (0: one per core, or the process's cap).
    pub threads: usize,
    /// The samples per pixel the preview stops at; none: the shot's
    /// (`render.spp`, or `render.adaptive`'s `max_spp`).
    pub max_spp: Option<u32>,
    /// How long without a page asking for the preview's state before it stops.
    pub idle: Duration,
    /// Denoise each pass's image when Open Image Denoise is found.
    pub denoise: bool,
}

impl Default for LiveOptions {
    fn default() -> Self {
        LiveOptions { resolution: None, threads: 0, max_spp: None, idle: Duration::from_secs(30), denoise: true }
    }
}

/// The preview size of a shot rendered at `resolution`: a quarter in each axis.
fn preview_size([w, h]: [u32; 2]) -> [u32; 2] {
    [w.div_ceil(4).max(1), h.div_ceil(4).max(1)]
}

/// Whether the preview renders: asked to stop by the page, or stopped for
/// want of a page, or running.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Run {
    Running,
    Asked,
    Idle,
}

impl Run {
    fn name(self) -> &'static str {
        match self {
            Run::Running => "running",
            Run::Asked => "stopped",
            Run::Idle => "idle",
        }
    }
}

/// A file's identity for change detection: its size and modification time.
type Stamp = Option<(u64, SystemTime)>;

fn stamp(path: &Path) -> Stamp {
    std::fs::metadata(path).ok().map(|m| (m.len(), m.modified().unwrap_or(SystemTime::UNIX_EPOCH)))
}

/// One published image: the mean of the passes so far, and the last
/// denoised image of the same start with its samples per pixel.
struct Preview {
    noisy: Arc<Film>,
    denoised: Option<(Arc<Film>, u32)>,
    space: Colourspace,
}

/// What the page is told ([`Live::poll`]).
#[derive(Debug, Clone, Default)]
struct Status {
    /// `loading`, `rendering`, `converged` (at the samples asked) or `error`.
    state: &'static str,
    /// Starts so far (each reload or new frame is one).
    generation: u64,
    /// How the current start came about: `start`, `frame`, `cast kept`, `recast`.
    reload: &'static str,
    frame: Option<i32>,
    size: [u32; 2],
    pass: u32,
    spp: u32,
    max_spp: u32,
    /// When the current start began, and when the change behind it was seen.
    started: Option<Instant>,
    changed: Option<Instant>,
    /// Seconds from `started` to the last pass published.
    elapsed_s: f64,
    /// Seconds from the change seen (or the start) to this start's first image.
    first_image_s: Option<f64>,
    /// Images published so far (the page's cache key), and of which start the last.
    images: u64,
    image_generation: u64,
    /// Whether the last image is denoised (and at how many samples); the
    /// denoiser, or why there is none.
    denoised: bool,
    denoised_spp: Option<u32>,
    denoiser: Option<String>,
    denoise_note: Option<String>,
    error: Option<Value>,
    warnings: Vec<String>,
}

/// What the page and the worker share.
struct Control {
    frame: i32,
    run: Run,
    quit: bool,
    last_poll: Instant,
    status: Status,
    preview: Option<Arc<Preview>>,
}

struct Shared {
    shot_file: PathBuf,
    options: LiveOptions,
    control: Mutex<Control>,
    wake: Condvar,
}

impl Shared {
    fn lock(&self) -> MutexGuard<'_, Control> {
        // A panic elsewhere leaves plain data behind: carry on with it.
        self.control.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    fn status(&self, edit: impl FnOnce(&mut Status)) {
        edit(&mut self.lock().status);
    }
}

/// An error as the page shows it: the message, and the file, line and key
/// it names.
fn error_json(e: &Error) -> Value {
    match e {
        Error::Invalid { at, .. } => json!({
            "message": e.to_string(),
            "file": at.path,
            "line": at.line,
            "key": at.field,
        }),
        Error::Io { path, .. } => json!({ "message": e.to_string(), "file": path, "line": null, "key": null }),
        e => json!({ "message": e.to_string(), "file": null, "line": null, "key": null }),
    }
}

/// The live preview of a review: its worker thread and what it shares.
pub(crate) struct Live {
    shared: Arc<Shared>,
    worker: Option<JoinHandle<()>>,
}

impl Live {
    /// Starts rendering `frame` of the shot at `shot_file`, reading it anew.
    pub(crate) fn start(shot_file: &Path, frame: i32, options: LiveOptions) -> Result<Live> {
        let denoise_note = (!options.denoise).then(|| "not asked".to_string());
        let shared = Arc::new(Shared {
            shot_file: shot_file.to_path_buf(),
            options,
            control: Mutex::new(Control {
                frame,
                run: Run::Running,
                quit: false,
                last_poll: Instant::now(),
                status: Status { state: "loading", denoise_note, ..Status::default() },
                preview: None,
            }),
            wake: Condvar::new(),
        });
        let worker = std::thread::Builder::new()
            .name("review-live".into())
            .spawn({
                let shared = shared.clone();
                move || work(shared)
            })
            .map_err(|e| Error::setting("live", format!("cannot start the live preview's thread: {e}")))?;
        Ok(Live { shared, worker: Some(worker) })
    }

    /// `/api/live`: the preview's state. A page asking keeps the preview
    /// going, and starts one that stopped for want of a page again.
    pub(crate) fn poll(&self) -> Value {
        let mut c = self.shared.lock();
        c.last_poll = Instant::now();
        let run = c.run;
        if run == Run::Idle {
            c.run = Run::Running;
            self.shared.wake.notify_all();
        }
        status_json(&c.status, run, c.frame)
    }

    /// `POST /api/live/start` `{"frame": F}` (frame optional): renders that
    /// frame (from where it was, if it is the one rendered).
    pub(crate) fn start_frame(&self, body: &Value) -> Answer<Body> {
        let frame = match &body["frame"] {
            Value::Null => None,
            v => Some(
                v.as_i64()
                    .and_then(|f| i32::try_from(f).ok())
                    .ok_or_else(|| bad(format!("`frame` {v} is not a frame number")))?,
            ),
        };
        let mut c = self.shared.lock();
        if let Some(f) = frame {
            c.frame = f;
        }
        c.run = Run::Running;
        c.last_poll = Instant::now();
        self.shared.wake.notify_all();
        Ok(super::json_body(&status_json(&c.status, c.run, c.frame)))
    }

    /// `POST /api/live/stop`: no more passes until started again.
    pub(crate) fn stop(&self) -> Answer<Body> {
        let mut c = self.shared.lock();
        c.run = Run::Asked;
        self.shared.wake.notify_all();
        Ok(super::json_body(&status_json(&c.status, c.run, c.frame)))
    }

    /// `/api/live.png`: the last image, exposed by `exposure` stops;
    /// `noisy=1`: before denoising.
    pub(crate) fn png(&self, exposure: f32, noisy: bool) -> Answer<Body> {
        let preview = self.shared.lock().preview.clone();
        let Some(p) = preview else {
            return Err(Refusal(404, "no live image yet".into()));
        };
        let film = match &p.denoised {
            Some((film, _)) if !noisy => film,
            _ => &p.noisy,
        };
        let px = tone::view_pixels(film, p.space, "beauty", exposure).map_err(|m| Refusal(500, m))?;
        let png = tone::png(film.width, film.height, 3, px).map_err(|m| Refusal(500, m))?;
        Ok(Body::Bytes("image/png", png))
    }

    /// What `/api/shot` says of the preview.
    pub(crate) fn describe(&self) -> Value {
        let o = &self.shared.options;
        json!({ "resolution": o.resolution, "max_spp": o.max_spp, "idle_s": o.idle.as_secs_f64() })
    }
}

impl Drop for Live {
    fn drop(&mut self) {
        self.shared.lock().quit = true;
        self.shared.wake.notify_all();
        if let Some(w) = self.worker.take() {
            let _ = w.join();
        }
    }
}

fn status_json(s: &Status, run: Run, frame: i32) -> Value {
    json!({
        "run": run.name(),
        "state": s.state,
        "frame": s.frame,
        "asked_frame": frame,
        "width": s.size[0],
        "height": s.size[1],
        "generation": s.generation,
        "reload": s.reload,
        "pass": s.pass,
        "spp": s.spp,
        "max_spp": s.max_spp,
        "elapsed_s": s.elapsed_s,
        "first_image_s": s.first_image_s,
        "image": s.images,
        "image_generation": s.image_generation,
        "denoised": s.denoised,
        "denoised_spp": s.denoised_spp,
        "denoiser": s.denoiser,
        "denoise_note": s.denoise_note,
        "error": s.error,
        "warnings": s.warnings,
    })
}

/// The worker thread: the pool, then the loop.
fn work(shared: Arc<Shared>) {
    let threads = shared.options.threads;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .thread_name(|i| format!("review-live-{i}"))
        .build()
        .map_err(|e| Error::setting("threads", format!("cannot start {threads} render threads: {e}")));
    match pool {
        Ok(pool) => pool.install(|| Worker::new(shared).run()),
        Err(e) => shared.status(|s| (s.state, s.error) = ("error", Some(error_json(&e)))),
    }
}

/// The cast shot in its working colourspace, with the BLASes built for it so far.
enum Crowd {
    Rec709(ShotCrowd, BlasSet),
    Acescg(ShotCrowd<Acescg>, BlasSet),
}

impl Crowd {
    fn input_files(&self) -> Vec<(String, PathBuf)> {
        match self {
            Crowd::Rec709(c, _) => c.input_files(),
            Crowd::Acescg(c, _) => c.input_files(),
        }
    }

    fn warnings(&self) -> &[String] {
        match self {
            Crowd::Rec709(c, _) => c.warnings(),
            Crowd::Acescg(c, _) => c.warnings(),
        }
    }
}

/// Whether `new` casts as `old` does: they differ at most in what a cast
/// crowd takes anew ([`ShotCrowd::with_shot`]): lights (the dome's file
/// read again), camera keys, render settings but the shutter (the poses
/// are the shutter's), air and layer settings.
fn cast_unchanged(old: &Shot, new: &Shot) -> bool {
    let mut probe = new.clone();
    probe.lights = old.lights.clone();
    probe.atmosphere = old.atmosphere;
    probe.layers = old.layers.clone();
    // The shutter and the working colourspace change what the cast holds
    // (motion samples; input colours converted as the crowd loads).
    probe.render = crate::shot::RenderSettings {
        shutter: new.render.shutter,
        working_colourspace: new.render.working_colourspace,
        ..old.render.clone()
    };
    probe.camera = crate::shot::CameraSpec { gltf: new.camera.gltf.clone(), ..old.camera.clone() };
    // Debug prints every field (maps are ordered): equal text, equal shots.
    format!("{probe:?}") == format!("{old:?}")
}

/// The frame being rendered: its scene, the render's settings, and the sums
/// of the passes so far.
struct Progressive {
    scene: FrameScene,
    settings: RenderSettings,
    max_spp: u32,
    done: u32,
    passes: u32,
    rgba: Vec<[f32; 4]>,
    normal: Vec<[f32; 3]>,
    albedo: Vec<[f32; 3]>,
    /// Depth and ids of the first pass (its nearest sample's).
    first: Option<(Vec<f32>, Vec<u32>)>,
    /// What one sample a pixel took in the last pass.
    per_sample: Option<Duration>,
    /// The samples of the last image denoised.
    denoised_spp: u32,
}

impl Progressive {
    /// `frame` of `crowd` at the preview size, with the settings
    /// `throng render --layer full` takes (no manifest: every agent at full
    /// detail), the BLASes it needs built.
    fn new<C: Space>(crowd: &ShotCrowd<C>, blas: &mut BlasSet, frame: i32, options: &LiveOptions) -> Result<Self> {
        let shot = crowd.shot();
        if !shot.frames.contains(frame) {
            return Err(Error::Usage(format!(
                "frame {frame} is outside shot {} ({}-{})",
                shot.name, shot.frames.start, shot.frames.end
            )));
        }
        let [w, h] = options.resolution.unwrap_or_else(|| preview_size(shot.render.resolution));
        let max_spp = options.max_spp.unwrap_or(shot.render.adaptive.map_or(shot.render.spp, |a| a.max_spp)).max(1);
        let job = RenderJob {
            resolution: Some([w, h]),
            threads: options.threads,
            colourspace: C::COLOURSPACE,
            shutter: shot.render.shutter,
            ..RenderJob::new(vec![FULL_LAYER.to_string()], vec![frame], 1, PathBuf::new())
        };
        let mut scene = match shot.render.shutter {
            Some(shutter) => motion_scene(crowd, None, FULL_LAYER, &MotionFrame::new(crowd, frame, shutter)?)?,
            None => streamed_frame_scene(crowd, None, FULL_LAYER, frame)?,
        };
        colour::scene_lights_once(&mut scene, C::COLOURSPACE, &mut ConvertedDome::default());
        blas.prepare(crowd.library(), scene.instances.iter().map(|i| i.mesh));
        let settings = layer_settings(crowd, None, &job, FULL_LAYER, frame, &PassSet::default());
        let n = w as usize * h as usize;
        Ok(Progressive {
            scene,
            settings,
            max_spp,
            done: 0,
            passes: 0,
            rgba: vec![[0.0; 4]; n],
            normal: vec![[0.0; 3]; n],
            albedo: vec![[0.0; 3]; n],
            first: None,
            per_sample: None,
            denoised_spp: 0,
        })
    }

    fn converged(&self) -> bool {
        self.done >= self.max_spp
    }

    /// Renders the next pass and adds it to the sums.
    fn pass(&mut self, blas: &BlasSet, lib: &crate::scene::Library) -> Result<()> {
        let mut k = self.done.clamp(1, PASS_CAP).min(self.max_spp - self.done);
        if let Some(t) = self.per_sample.filter(|t| !t.is_zero()) {
            k = k.min((PASS_TIME.as_secs_f64() / t.as_secs_f64()) as u32).max(1);
        }
        let settings = RenderSettings { spp: k, first_sample: self.done, ..self.settings.clone() };
        let started = Instant::now();
        let film = render_frame(blas, lib, &self.scene, &settings, None)?;
        self.per_sample = Some(started.elapsed() / k);
        let w = k as f32;
        for (sum, p) in self.rgba.iter_mut().zip(&film.rgba) {
            *sum = std::array::from_fn(|c| sum[c] + p[c] * w);
        }
        for (sums, px) in [(&mut self.normal, &film.normal), (&mut self.albedo, &film.albedo)] {
            for (sum, p) in sums.iter_mut().zip(px) {
                *sum = std::array::from_fn(|c| sum[c] + p[c] * w);
            }
        }
        self.first.get_or_insert_with(|| (film.z.clone(), film.agent_id.clone()));
        self.done += k;
        self.passes += 1;
        Ok(())
    }

    /// The mean of the passes so far.
    fn mean(&self) -> Film {
        let mut film = Film::new(self.settings.width, self.settings.height);
        let inv = 1.0 / self.done.max(1) as f32;
        film.rgba = self.rgba.iter().map(|p| p.map(|c| c * inv)).collect();
        film.normal = self.normal.iter().map(|p| p.map(|c| c * inv)).collect();
        film.albedo = self.albedo.iter().map(|p| p.map(|c| c * inv)).collect();
        if let Some((z, ids)) = &self.first {
            (film.z, film.agent_id) = (z.clone(), ids.clone());
        }
        film
    }
}

/// The worker's own state.
struct Worker {
    shared: Arc<Shared>,
    crowd: Option<Crowd>,
    /// The files the shot was read from (the shot file first), and their
    /// stamps when it was last read.
    watched: Vec<PathBuf>,
    seen: Vec<Stamp>,
    /// A change seen (the stamps then, and when first seen), waiting for
    /// the files to hold still.
    pending: Option<(Vec<Stamp>, Instant, Instant)>,
    last_watch: Instant,
    /// Whether the shot has been read at all, and whether the last read failed
    /// (no passes until the next change reads).
    read_once: bool,
    broken: bool,
    /// The frame rendered, and how.
    frame: Option<i32>,
    progressive: Option<Progressive>,
    denoiser: Option<std::result::Result<Denoiser, String>>,
    /// Why the next start happens, and when the change behind it was seen.
    reason: &'static str,
    changed: Option<Instant>,
}

impl Worker {
    fn new(shared: Arc<Shared>) -> Worker {
        let watched = vec![shared.shot_file.clone()];
        Worker {
            shared,
            crowd: None,
            seen: vec![None],
            watched,
            pending: None,
            last_watch: Instant::now(),
            read_once: false,
            broken: false,
            frame: None,
            progressive: None,
            denoiser: None,
            reason: "start",
            changed: None,
        }
    }

    /// Sleeps until woken or `timeout`.
    fn wait(&self, timeout: Duration) {
        let c = self.shared.lock();
        if !c.quit {
            let _ = self.shared.wake.wait_timeout(c, timeout);
        }
    }

    fn run(mut self) {
        loop {
            let (frame, running) = {
                let mut c = self.shared.lock();
                if c.quit {
                    return;
                }
                if c.run == Run::Running && c.last_poll.elapsed() > self.shared.options.idle {
                    c.run = Run::Idle;
                }
                (c.frame, c.run == Run::Running)
            };
            if !running {
                self.wait(WATCH_EVERY);
                continue;
            }
            if !self.read_once {
                self.reload(Some(Instant::now()));
                continue;
            }
            if let Some(changed) = self.watch() {
                self.reload(Some(changed));
                continue;
            }
            if self.pending.is_some() {
                self.wait(WATCH_EVERY / 2);
                continue;
            }
            if self.broken {
                self.wait(WATCH_EVERY);
                continue;
            }
            if self.crowd.is_some() && self.frame != Some(frame) {
                self.begin(frame);
                continue;
            }
            if self.progressive.as_ref().is_some_and(|p| !p.converged()) {
                self.pass();
                continue;
            }
            self.wait(WATCH_EVERY);
        }
    }

    fn stamps(&self) -> Vec<Stamp> {
        self.watched.iter().map(|p| stamp(p)).collect()
    }

    /// Looks at the watched files (every [`WATCH_EVERY`]); once a change
    /// has held still for [`DEBOUNCE`], when it was first seen.
    fn watch(&mut self) -> Option<Instant> {
        if self.pending.is_none() && self.last_watch.elapsed() < WATCH_EVERY {
            return None;
        }
        self.last_watch = Instant::now();
        let now = self.stamps();
        if now == self.seen {
            self.pending = None;
            return None;
        }
        match self.pending.take() {
            Some((stamps, first, still)) if stamps == now => {
                if still.elapsed() >= DEBOUNCE {
                    return Some(first);
                }
                self.pending = Some((stamps, first, still));
            }
            // Changed again: wait until it holds still from now.
            Some((_, first, _)) => self.pending = Some((now, first, Instant::now())),
            None => self.pending = Some((now, Instant::now(), Instant::now())),
        }
        None
    }

    /// Reads the shot again (and, unless only the shot file changed in a
    /// way that keeps the cast, everything it names), and starts again.
    fn reload(&mut self, changed: Option<Instant>) {
        let first = !self.read_once;
        self.read_once = true;
        let before = self.stamps();
        // Only the shot file (first) changed: the cast may be kept.
        let only_shot = !first && before.iter().zip(&self.seen).skip(1).all(|(a, b)| a == b);
        self.shared.status(|s| s.state = "loading");
        let read = Shot::load(&self.shared.shot_file).and_then(|shot| self.take(shot, only_shot));
        // Either way the frame's passes so far are of another shot.
        self.progressive = None;
        self.broken = read.is_err();
        match read {
            Ok(how) => {
                self.frame = None;
                let old: Vec<(PathBuf, Stamp)> = self.watched.drain(..).zip(before).collect();
                let mut files = vec![self.shared.shot_file.clone()];
                for (_, p) in self.crowd.as_ref().map(Crowd::input_files).unwrap_or_default() {
                    if !files.contains(&p) {
                        files.push(p);
                    }
                }
                // A file watched before keeps the stamp it had before the
                // read, so a change while reading is seen next time.
                self.seen = files
                    .iter()
                    .map(|p| old.iter().find(|(o, _)| o == p).map_or_else(|| stamp(p), |(_, s)| *s))
                    .collect();
                self.watched = files;
                self.reason = if first { "start" } else { how };
                self.changed = changed;
                let warnings = self.crowd.as_ref().map(|c| c.warnings().to_vec()).unwrap_or_default();
                self.shared.status(|s| (s.error, s.warnings) = (None, warnings));
            }
            Err(e) => {
                self.seen = before;
                self.shared.status(|s| (s.state, s.error) = ("error", Some(error_json(&e))));
            }
        }
    }

    /// Takes the shot read: into the cast crowd when only the shot file
    /// changed and the cast stays as it was, else cast anew.
    fn take(&mut self, shot: Shot, only_shot: bool) -> Result<&'static str> {
        let keep = only_shot && matches!(&self.crowd, Some(Crowd::Rec709(c, _)) if cast_unchanged(c.shot(), &shot));
        if keep {
            if let Some(Crowd::Rec709(c, blas)) = self.crowd.take() {
                // The meshes are the same: their BLASes stay.
                self.crowd = Some(Crowd::Rec709(c.with_shot(move |s| *s = shot)?, blas));
                return Ok("cast kept");
            }
        }
        // The old crowd goes before the new one is read: never two in memory.
        self.crowd = None;
        let (space, shutter) = (shot.render.working_colourspace, shot.render.shutter);
        let crowd = ShotCrowd::open(shot, shutter)?;
        self.crowd = Some(match space {
            Colourspace::Rec709 => {
                let blas = BlasSet::lazy(crowd.library());
                Crowd::Rec709(crowd, blas)
            }
            Colourspace::Acescg => {
                let crowd = colour::into_acescg(crowd);
                let blas = BlasSet::lazy(crowd.library());
                Crowd::Acescg(crowd, blas)
            }
        });
        Ok("recast")
    }

    /// Starts rendering `frame` from its first sample.
    fn begin(&mut self, frame: i32) {
        self.frame = Some(frame);
        let started = Instant::now();
        let made = match &mut self.crowd {
            Some(Crowd::Rec709(c, blas)) => Progressive::new(c, blas, frame, &self.shared.options),
            Some(Crowd::Acescg(c, blas)) => Progressive::new(c, blas, frame, &self.shared.options),
            None => return,
        };
        let (reason, changed) = (self.reason, self.changed.take());
        self.reason = "frame";
        match made {
            Ok(p) => {
                self.shared.status(|s| {
                    s.generation += 1;
                    s.state = "rendering";
                    s.reload = reason;
                    s.frame = Some(frame);
                    s.size = [p.settings.width, p.settings.height];
                    (s.pass, s.spp, s.max_spp) = (0, 0, p.max_spp);
                    (s.started, s.changed) = (Some(started), changed);
                    (s.elapsed_s, s.first_image_s) = (0.0, None);
                    s.error = None;
                });
                self.progressive = Some(p);
            }
            Err(e) => {
                self.progressive = None;
                self.shared.status(|s| (s.state, s.error) = ("error", Some(error_json(&e))));
            }
        }
    }

    /// Renders one pass and publishes the image so far: at once, and
    /// denoised each time its samples have doubled since the last denoised
    /// image, and at the end (a denoise costs as much as a few passes).
    fn pass(&mut self) {
        let (Some(p), Some(crowd)) = (&mut self.progressive, &self.crowd) else { return };
        let (done, space) = match crowd {
            Crowd::Rec709(c, blas) => (p.pass(blas, c.library()), Colourspace::Rec709),
            Crowd::Acescg(c, blas) => (p.pass(blas, c.library()), Colourspace::Acescg),
        };
        if let Err(e) = done {
            self.progressive = None;
            self.shared.status(|s| (s.state, s.error) = ("error", Some(error_json(&e))));
            return;
        }
        let noisy = Arc::new(p.mean());
        let (pass, spp, converged) = (p.passes, p.done, p.converged());
        let due = self.shared.options.denoise && (converged || spp >= 2 * p.denoised_spp);
        // The last pass is published once, denoised: `converged` is the end.
        if !(due && converged) {
            self.publish(pass, spp, converged, Preview { noisy: noisy.clone(), denoised: None, space });
        }
        if !due {
            return;
        }
        match self.denoise(&noisy) {
            Some(film) => {
                if let Some(p) = &mut self.progressive {
                    p.denoised_spp = spp;
                }
                self.publish(pass, spp, converged, Preview { noisy, denoised: Some((Arc::new(film), spp)), space });
            }
            None if converged => self.publish(pass, spp, converged, Preview { noisy, denoised: None, space }),
            None => {}
        }
    }

    /// Makes `preview` (of pass `pass`, at `spp`) the image the page gets;
    /// a later pass of the same start keeps the start's denoised image.
    fn publish(&self, pass: u32, spp: u32, converged: bool, mut preview: Preview) {
        let mut c = self.shared.lock();
        if preview.denoised.is_none() && pass > 1 {
            preview.denoised = c.preview.as_ref().and_then(|p| p.denoised.clone());
        }
        let s = &mut c.status;
        let now = Instant::now();
        (s.pass, s.spp) = (pass, spp);
        s.state = if converged { "converged" } else { "rendering" };
        s.elapsed_s = s.started.map_or(0.0, |t| (now - t).as_secs_f64());
        if s.first_image_s.is_none() {
            s.first_image_s = s.changed.or(s.started).map(|t| (now - t).as_secs_f64());
        }
        s.images += 1;
        s.image_generation = s.generation;
        (s.denoised, s.denoised_spp) = (preview.denoised.is_some(), preview.denoised.as_ref().map(|d| d.1));
        c.preview = Some(Arc::new(preview));
    }

    /// `film` denoised, when asked and the denoiser is found (opened once;
    /// the status says which, or why not).
    fn denoise(&mut self, film: &Film) -> Option<Film> {
        let threads = self.shared.options.threads;
        let denoiser = self.denoiser.get_or_insert_with(|| Denoiser::open(None, threads).map_err(|e| e.to_string()));
        let out = match denoiser {
            Ok(d) => {
                let mut out = film.clone();
                match d.denoise(&mut out, PREVIEW_DENOISE) {
                    Ok(()) => Ok((out, crate::render::denoise::stamp(d, PREVIEW_DENOISE))),
                    Err(e) => Err(e.to_string()),
                }
            }
            Err(why) => Err(why.clone()),
        };
        match out {
            Ok((film, stamp)) => {
                self.shared.status(|s| (s.denoiser, s.denoise_note) = (Some(stamp), None));
                Some(film)
            }
            Err(why) => {
                self.shared.status(|s| (s.denoiser, s.denoise_note) = (None, Some(why)));
                None
            }
        }
    }
}
