//! The film (per-pixel output buffers) and the tiled, parallel frame loop.
//!
//! Buffers are row-major, top row first (the order EXR stores scanlines).
//! - `rgba`: premultiplied linear RGB and alpha, the mean of all samples
//!   (each sample already filter-weighted by its position: weight 1).
//! - `normal`, `albedo`: means over all samples, misses contributing zero,
//!   i.e. premultiplied by coverage like RGB.
//! - `z`, `agent_id`: from the single sample nearest the pixel centre (never
//!   filtered, so ids stay exact and depths are never blends of two surfaces).
//!   `z` is camera-space depth, positive forward, +inf where that sample
//!   missed or hit a holdout.
//!   `agent_id` is 0 for "no agent" (sky, set, holdout), else cache id + 1.
//! - `motion`: with a shutter only (else empty), the screen-space motion of
//!   the surface the nearest sample hit, pixels per frame, +u right and +v
//!   up (Nuke's `forward` vectors); zero where that sample missed, hit a
//!   holdout or hit something that does not move.
//! - `cryptomatte`: when rendered with [`CryptoNames`], the `CryptoAgent`,
//!   `CryptoMaterial` and `CryptoPart` mattes (sorted by type name, as a file
//!   reads back): per pixel the top [`RANKS`] (id, coverage) pairs, ranked
//!   from a fixed-size per-pixel accumulator over the samples in index order
//!   (so also independent of threading).
//! - `samples`: with adaptive sampling only (else empty), the samples each
//!   pixel took. Every pixel takes `min_spp`; from there, after every
//!   [`ADAPTIVE_STEP`] samples, it stops once its error is below the
//!   threshold: the standard error of its mean luminance over that mean
//!   (plus [`ADAPTIVE_FLOOR`], so dark pixels are held to an absolute
//!   error) or the standard error of its alpha (edges), whichever is
//!   larger, and never below 1 / n after n samples (what happens less often
//!   than once in n samples, n samples cannot see); or at `max_spp`.
//!   The decision reads the pixel's own samples alone, in index order, so
//!   the image is the same for any thread count, and a pixel's first n
//!   samples are those of a fixed n-sample render. Every other buffer is
//!   the mean over the samples the pixel took.
//! - `passes`: the light-path passes and light groups asked for (means over
//!   all samples, like RGB, from the same samples: scene::passes), the
//!   shadow pass (set surfaces' direct light the crowd's shadows took), the
//!   camera rays' transmittance through the air (a mean like RGB), then the
//!   world position `P` of the nearest sample's first hit (never filtered,
//!   like `z`; zero where it missed).

use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use glam::Vec3;
use rayon::prelude::*;

use super::accel::{BlasSet, Tlas};
use super::cryptomatte::{CryptoNames, Cryptomatte, RankAccumulator, MATTES, RANKS};
use super::deep::{DeepImage, DeepPixel, DeepSample, DeepSettings};
use super::integrator::{CameraBatch, Integrator, RayCounts, SampleResult, Tally};
use super::wide::PACKET;
use super::RenderSettings;
use crate::error::{Error, Result};
use crate::scene::passes::{LightGroups, PassSet, Split};
use crate::scene::{FrameScene, Library};

/// Tile edge in pixels: small enough to balance load, large enough to keep a
/// thread on coherent rays.
const TILE: u32 = 16;

/// Adaptive sampling checks a pixel's error every this many samples after
/// its first `min_spp`.
pub const ADAPTIVE_STEP: u32 = 4;
/// Added to a pixel's mean luminance under the square root its error is
/// divided by, so that black pixels are held to an absolute error.
pub const ADAPTIVE_FLOOR: f64 = 0.01;

/// How many samples a pixel takes: `min` to `max`, stopping at `threshold`.
#[derive(Clone, Copy, Debug)]
struct SampleCount {
    min: u32,
    max: u32,
    /// `None`: exactly `max` (no adaptive sampling).
    threshold: Option<f64>,
    /// The index of the pixel's first sample (`RenderSettings::first_sample`).
    first: u32,
}

impl SampleCount {
    fn of(settings: &RenderSettings) -> SampleCount {
        match settings.adaptive {
            Some(a) => {
                SampleCount { min: a.min_spp, max: a.max_spp, threshold: Some(f64::from(a.threshold)), first: 0 }
            }
            None => SampleCount { min: settings.spp, max: settings.spp, threshold: None, first: settings.first_sample },
        }
    }

    /// Whether a pixel may stop after its first `spp` samples (as `render_pixel` decides).
    fn may_stop_after(&self, spp: u32) -> bool {
        self.threshold.is_some() && spp >= self.min.max(2) && (spp - self.min).is_multiple_of(ADAPTIVE_STEP)
    }

    /// The end of the run of samples from `s` (an index in the pixel's
    /// sequence, from `first`) whose camera rays are traced together: at
    /// most a packet's worth, and never past a sample after which the pixel
    /// may stop (no camera ray is traced for nothing).
    fn batch_end(&self, s: u32) -> u32 {
        let cap = s.saturating_add(PACKET as u32).min(self.first + self.max);
        let mut end = s + 1;
        while end < cap && !self.may_stop_after(end - self.first) {
            end += 1;
        }
        end
    }
}

/// Running sums of one pixel's luminance and alpha for its error estimate.
#[derive(Default)]
struct ErrorEstimate {
    lum: [f64; 2],
    alpha: [f64; 2],
}

impl ErrorEstimate {
    fn add(&mut self, rgb: Vec3, alpha: f32) {
        let l = f64::from(rgb.dot(Vec3::new(0.2126, 0.7152, 0.0722)));
        let l = if l.is_finite() { l } else { 0.0 };
        let a = f64::from(alpha);
        self.lum[0] += l;
        self.lum[1] += l * l;
        self.alpha[0] += a;
        self.alpha[1] += a * a;
    }

    /// The larger of the standard error of the mean luminance on a
    /// tone-mapped scale and the standard error of the mean alpha, after
    /// `n` (> 1) samples, and at least 1 / `n`. The tone-mapped scale is
    /// Cycles' (the error over the square root of the mean, as a display
    /// transform compresses light): a denoiser smooths away the grain of
    /// dark pixels that a relative error would spend samples on, while
    /// what shows after it is the noise of bright ones.
    fn error(&self, n: u32) -> f64 {
        let n = f64::from(n);
        let se = |[s, s2]: [f64; 2]| {
            let mean = s / n;
            ((s2 / n - mean * mean).max(0.0) / (n - 1.0)).sqrt()
        };
        let mean = self.lum[0] / n;
        let relative = se(self.lum) / (mean.abs() + ADAPTIVE_FLOOR).sqrt();
        // n samples cannot see what happens less often than once in n (a
        // shadow, a lamp through a gap): their variance says nothing of it,
        // so no pixel claims an error below 1 / n.
        relative.max(se(self.alpha)).hypot(1.0 / n)
    }
}

/// Timings and ray counts of one frame.
#[derive(Clone, Copy, Debug, Default)]
pub struct RenderStats {
    /// TLAS build time.
    pub tlas_build: Duration,
    /// Time spent tracing (all threads, wall clock).
    pub trace: Duration,
    /// Rays traced.
    pub rays: RayCounts,
}

/// The rendered image and its AOVs. See the module docs for conventions.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Film {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Premultiplied RGBA.
    pub rgba: Vec<[f32; 4]>,
    /// Camera-space depth (positive forward), +inf for no hit.
    pub z: Vec<f32>,
    /// World shading normal (coverage-weighted mean).
    pub normal: Vec<[f32; 3]>,
    /// Albedo (coverage-weighted mean).
    pub albedo: Vec<[f32; 3]>,
    /// 0 = no agent, else cache agent id + 1.
    pub agent_id: Vec<u32>,
    /// Cryptomatte types (`CryptoAgent`, `CryptoMaterial`, `CryptoPart`),
    /// sorted by type name; empty when not rendered.
    pub cryptomatte: Vec<Cryptomatte>,
    /// Motion vectors (u right, v up), pixels per frame; empty when rendered without a shutter.
    pub motion: Vec<[f32; 2]>,
    /// Light-path passes, light groups and position, in file order; empty
    /// when none were asked for.
    pub passes: Vec<Pass>,
    /// Samples each pixel took; empty unless rendered with adaptive sampling.
    pub samples: Vec<u32>,
}

/// One three-channel pass of a film.
#[derive(Clone, Debug, PartialEq)]
pub struct Pass {
    /// Its layer name in the file (`diffuse_direct`, `lg_sun`, `P`).
    pub name: String,
    /// Its channels' suffixes (`R`, `G`, `B` or `X`, `Y`, `Z`).
    pub channels: [&'static str; 3],
    /// Row-major values.
    pub data: Vec<[f32; 3]>,
}

impl Pass {
    /// The layer names of the passes `set` writes with light groups `groups`, in file order.
    pub fn names(set: &PassSet, groups: &[String]) -> Vec<(String, [&'static str; 3])> {
        const RGB: [&str; 3] = ["R", "G", "B"];
        let mut names: Vec<(String, [&'static str; 3])> =
            set.light_paths.iter().map(|p| (p.name().to_string(), RGB)).collect();
        if set.light_groups {
            names.extend(groups.iter().map(|g| (format!("lg_{g}"), RGB)));
        }
        if set.shadow {
            names.push((crate::scene::passes::SHADOW.into(), RGB));
        }
        if set.transmittance {
            names.push((crate::scene::passes::TRANSMITTANCE.into(), RGB));
        }
        if set.position {
            names.push(("P".into(), ["X", "Y", "Z"]));
        }
        names
    }
}

impl Film {
    /// A black, empty film.
    pub fn new(width: u32, height: u32) -> Film {
        let n = width as usize * height as usize;
        Film {
            width,
            height,
            rgba: vec![[0.0; 4]; n],
            z: vec![f32::INFINITY; n],
            normal: vec![[0.0; 3]; n],
            albedo: vec![[0.0; 3]; n],
            agent_id: vec![0; n],
            cryptomatte: Vec::new(),
            motion: Vec::new(),
            passes: Vec::new(),
            samples: Vec::new(),
        }
    }

    /// Nearest and farthest finite depth (for the EXR `near`/`far`), if any.
    pub fn depth_range(&self) -> Option<(f32, f32)> {
        self.z.iter().filter(|z| z.is_finite()).fold(None, |acc, &z| match acc {
            None => Some((z, z)),
            Some((lo, hi)) => Some((z.min(lo), z.max(hi))),
        })
    }

    /// Index of pixel (x, y).
    pub fn index(&self, x: u32, y: u32) -> usize {
        y as usize * self.width as usize + x as usize
    }
}

/// One pixel's finished values.
#[derive(Clone, Copy)]
struct Pixel {
    rgba: [f32; 4],
    z: f32,
    normal: [f32; 3],
    albedo: [f32; 3],
    agent: u32,
    motion: [f32; 2],
    /// Samples taken.
    samples: u32,
    /// Ranked (id, coverage) of the agent, part and material mattes (when
    /// enabled), in [`MATTES`] order.
    crypto: [[[f32; 2]; RANKS]; 3],
    /// Deep samples written (render::deep; 0 without deep output).
    deep: u32,
}

/// One tile's pixels, pass values, ray counts and deep samples.
type TileResult = (Vec<Pixel>, Vec<[f32; 3]>, RayCounts, Vec<DeepSample>);

/// What a render gathers deep samples with: the settings, and the names
/// whose Cryptomatte ids the samples carry.
#[derive(Clone, Copy)]
pub struct DeepRequest<'a, 'n> {
    /// Cap and depth tolerance.
    pub settings: DeepSettings,
    /// Names of the scene's instances (`None`: ids 0).
    pub names: Option<&'a CryptoNames<'n>>,
}

/// Where a pixel's deep samples go: the pixel being gathered and its tile's samples.
struct DeepOut<'p, 'a, 'n> {
    request: &'p DeepRequest<'a, 'n>,
    pixel: &'p mut DeepPixel,
    samples: &'p mut Vec<DeepSample>,
}

/// Where a pixel's passes go: the scratch split of one sample and the
/// pixel's pass values (one triple per pass of `set`).
struct PassOut<'p> {
    set: &'p PassSet,
    split: &'p mut Split,
    values: &'p mut [[f32; 3]],
}

/// A pixel's passes of `set` into `values` (one triple each, in file
/// order): the means of its samples' `sums` (`inv` = 1 / samples), and the
/// nearest sample's `position`.
fn write_passes(set: &PassSet, sums: &Split, inv: f32, position: Vec3, values: &mut [[f32; 3]]) {
    let mut out = values.iter_mut();
    let mut put = |v: [f32; 3]| {
        if let Some(slot) = out.next() {
            *slot = v;
        }
    };
    for path in &set.light_paths {
        put((sums.paths[*path as usize] * inv).to_array());
    }
    if set.light_groups {
        sums.groups.iter().for_each(|g| put((*g * inv).to_array()));
    }
    if set.shadow {
        put((sums.shadow * inv).to_array());
    }
    if set.transmittance {
        put([sums.transmittance * inv; 3]);
    }
    if set.position {
        put(position.to_array());
    }
}

#[allow(clippy::too_many_arguments, reason = "each output buffer is the caller's, reused from pixel to pixel")]
fn render_pixel(
    integrator: &Integrator,
    (x, y): (u32, u32),
    count: SampleCount,
    crypto: Option<&CryptoNames>,
    counts: &mut RayCounts,
    batch: &mut CameraBatch,
    mut passes: Option<PassOut>,
    mut deep: Option<DeepOut<'_, '_, '_>>,
) -> Pixel {
    batch.clear();
    if let Some(d) = &mut deep {
        d.pixel.clear();
    }
    let packets = integrator.camera_packets();
    let (mut rgb, mut alpha, mut normal, mut albedo) = (Vec3::ZERO, 0.0f32, Vec3::ZERO, Vec3::ZERO);
    let mut nearest = (f32::INFINITY, SampleResult { z: f32::INFINITY, ..Default::default() });
    let mut acc: [RankAccumulator; 3] = Default::default();
    // Samples summed in index order: the float result is independent of threading.
    let mut sums = Split::new(passes.as_ref().map_or(0, |p| p.split.groups.len()));
    let mut estimate = ErrorEstimate::default();
    let mut spp = 0;
    // `s` indexes the pixel's sample sequence: a progressive pass continues
    // where the one before it stopped.
    for s in count.first..count.first + count.max {
        spp = s - count.first + 1;
        let split = passes.as_mut().map(|p| {
            p.split.clear();
            &mut *p.split
        });
        let (r, offset) = if packets {
            integrator.sample_pixel_batched(x, y, s, || count.batch_end(s), batch, Tally { counts, split })
        } else {
            integrator.sample_pixel(x, y, s, Tally { counts, split })
        };
        if let Some(p) = &passes {
            // A sample the beauty drops (not finite) the passes drop too.
            if r.rgb.is_finite() {
                sums.add_sample(p.split);
            }
        }
        if let Some(names) = crypto {
            // Each sample has filter weight 1 (importance-sampled filter).
            let ids = r.instance.map_or([0; 3], |i| names.ids(i));
            for (a, id) in acc.iter_mut().zip(ids) {
                a.add(id);
            }
        }
        if let Some(d) = &mut deep {
            d.pixel.add(&d.request.settings, r.rgb, r.alpha, r.z, r.instance);
        }
        rgb += r.rgb;
        alpha += r.alpha;
        normal += r.normal;
        albedo += r.albedo;
        let d2 = offset.length_squared();
        if d2 < nearest.0 {
            nearest = (d2, r);
        }
        if let Some(threshold) = count.threshold {
            estimate.add(r.rgb, r.alpha);
            if count.may_stop_after(spp) && estimate.error(spp) < threshold {
                break;
            }
        }
    }
    let inv = 1.0 / spp as f32;
    if let Some(p) = passes {
        write_passes(p.set, &sums, inv, nearest.1.position, p.values);
    }
    let mut ranked = [[[0.0f32; 2]; RANKS]; 3];
    if crypto.is_some() {
        for (a, out) in acc.iter().zip(&mut ranked) {
            a.write_ranked(spp, out);
        }
    }
    Pixel {
        rgba: (rgb * inv).extend(alpha * inv).to_array(),
        z: nearest.1.z,
        normal: (normal * inv).to_array(),
        albedo: (albedo * inv).to_array(),
        agent: nearest.1.agent,
        motion: nearest.1.motion.to_array(),
        samples: spp,
        crypto: ranked,
        deep: deep.map_or(0, |d| d.pixel.finish(spp, d.request.names, d.samples)),
    }
}

/// The render's thread pool could not start: a bad `threads` setting (or
/// a machine out of threads), named by its option with the cause.
fn pool_error(threads: usize, e: rayon::ThreadPoolBuildError) -> Error {
    Error::setting("threads", format!("cannot start {threads} render threads: {e}"))
}

/// Renders one frame of one layer. `blas` must be built from `lib`.
/// `progress`, if given, is called with the number of pixels finished so far
/// (from render threads, in no particular order).
pub fn render_frame(
    blas: &BlasSet,
    lib: &Library,
    scene: &FrameScene,
    settings: &RenderSettings,
    progress: Option<&(dyn Fn(usize) + Sync)>,
) -> Result<Film> {
    Ok(render_frame_with_stats(blas, lib, scene, settings, progress)?.0)
}

/// As [`render_frame`], also returning timings and ray counts.
pub fn render_frame_with_stats(
    blas: &BlasSet,
    lib: &Library,
    scene: &FrameScene,
    settings: &RenderSettings,
    progress: Option<&(dyn Fn(usize) + Sync)>,
) -> Result<(Film, RenderStats)> {
    render_frame_with_cryptomatte(blas, lib, scene, settings, None, progress)
}

/// As [`render_frame_with_stats`], also rendering the `CryptoAgent`,
/// `CryptoPart` and `CryptoMaterial` mattes when `crypto` (built from
/// `scene.instances`) is given. Their manifests list only the names present
/// in this image; the film holds them sorted by type name.
pub fn render_frame_with_cryptomatte(
    blas: &BlasSet,
    lib: &Library,
    scene: &FrameScene,
    settings: &RenderSettings,
    crypto: Option<&CryptoNames>,
    progress: Option<&(dyn Fn(usize) + Sync)>,
) -> Result<(Film, RenderStats)> {
    render_frame_deep(blas, lib, scene, settings, crypto, None, progress).map(|(film, _, stats)| (film, stats))
}

/// As [`render_frame_with_cryptomatte`], also gathering the deep image
/// (render::deep) when `deep` asks for it.
pub fn render_frame_deep(
    blas: &BlasSet,
    lib: &Library,
    scene: &FrameScene,
    settings: &RenderSettings,
    crypto: Option<&CryptoNames>,
    deep: Option<&DeepRequest<'_, '_>>,
    progress: Option<&(dyn Fn(usize) + Sync)>,
) -> Result<(Film, Option<DeepImage>, RenderStats)> {
    check(blas, lib, scene, settings)?;
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(settings.threads)
        .build()
        .map_err(|e| pool_error(settings.threads, e))?;
    pool.install(|| {
        let tracing = &settings.tracing;
        let tlas = Tlas::build_scene(blas, lib, &scene.instances, scene.motion.as_ref(), tracing.tlas)
            .with_traversal(tracing.traversal);
        let mut stats = RenderStats { tlas_build: tlas.build_time, ..Default::default() };
        let groups = if settings.passes.light_groups { Some(LightGroups::new(&scene.lights, lib)?) } else { None };
        let group_count = groups.as_ref().map_or(0, |g| g.names.len());
        let triples = if settings.passes.any() { settings.passes.triples(group_count) } else { 0 };
        let integrator = Integrator::new(lib, scene, &tlas, settings, groups.as_ref());
        let count = SampleCount::of(settings);
        let (w, h) = (settings.width, settings.height);
        let tiles: Vec<(u32, u32)> =
            (0..h.div_ceil(TILE)).flat_map(|ty| (0..w.div_ceil(TILE)).map(move |tx| (tx * TILE, ty * TILE))).collect();
        let done = AtomicUsize::new(0);
        let start = Instant::now();
        let rendered: Vec<TileResult> = tiles
            .par_iter()
            .map(|&(x0, y0)| {
                let mut counts = RayCounts::default();
                let (x1, y1) = ((x0 + TILE).min(w), (y0 + TILE).min(h));
                let n = ((x1 - x0) * (y1 - y0)) as usize;
                let mut pixels = Vec::with_capacity(n);
                let mut values = vec![[0f32; 3]; n * triples];
                let mut split = Split::new(if settings.passes.light_groups { group_count } else { 0 });
                let mut chunks = values.chunks_mut(triples.max(1));
                let mut batch = CameraBatch::default();
                let (mut deep_pixel, mut deep_samples) = (DeepPixel::default(), Vec::new());
                for y in y0..y1 {
                    for x in x0..x1 {
                        let out = chunks.next().filter(|_| triples > 0).map(|values| PassOut {
                            set: &settings.passes,
                            split: &mut split,
                            values,
                        });
                        let d =
                            deep.map(|request| DeepOut { request, pixel: &mut deep_pixel, samples: &mut deep_samples });
                        pixels.push(render_pixel(&integrator, (x, y), count, crypto, &mut counts, &mut batch, out, d));
                    }
                }
                if let Some(report) = progress {
                    report(done.fetch_add(pixels.len(), Ordering::Relaxed) + pixels.len());
                }
                (pixels, values, counts, deep_samples)
            })
            .collect();
        stats.trace = start.elapsed();

        let mut film = empty_film(w, h, scene.motion.is_some(), count.threshold.is_some());
        let mut mattes = match crypto {
            Some(_) => MATTES.iter().map(|name| Cryptomatte::new(name, w, h, RANKS)).collect(),
            None => Vec::new(),
        };
        let group_names = groups.map(|g| g.names).unwrap_or_default();
        film.passes = Pass::names(&settings.passes, &group_names)
            .into_iter()
            .map(|(name, channels)| Pass { name, channels, data: vec![[0.0; 3]; film.rgba.len()] })
            .collect();
        for (&(x0, y0), (pixels, values, counts, _)) in tiles.iter().zip(&rendered) {
            stats.rays += *counts;
            let tw = (x0 + TILE).min(w) - x0;
            for (k, px) in values.chunks(triples.max(1)).enumerate().filter(|_| triples > 0) {
                let i = film.index(x0 + k as u32 % tw, y0 + k as u32 / tw);
                for (pass, v) in film.passes.iter_mut().zip(px) {
                    pass.data[i] = *v;
                }
            }
            let tw = (x0 + TILE).min(w) - x0;
            for (k, px) in pixels.iter().enumerate() {
                let i = film.index(x0 + k as u32 % tw, y0 + k as u32 / tw);
                film.rgba[i] = px.rgba;
                film.z[i] = px.z;
                film.normal[i] = px.normal;
                film.albedo[i] = px.albedo;
                film.agent_id[i] = px.agent;
                if let Some(m) = film.motion.get_mut(i) {
                    *m = px.motion;
                }
                if let Some(n) = film.samples.get_mut(i) {
                    *n = px.samples;
                }
                for (m, ranked) in mattes.iter_mut().zip(&px.crypto) {
                    m.pairs[i * RANKS..(i + 1) * RANKS].copy_from_slice(ranked);
                }
            }
        }
        if let Some(names) = crypto {
            for (k, m) in mattes.iter_mut().enumerate() {
                m.manifest = names.manifest(k, &m.ids_present());
            }
        }
        mattes.sort_by(|a, b| a.name.cmp(&b.name));
        film.cryptomatte = mattes;
        let deep = deep.map(|_| deep_image(w, h, &tiles, &rendered));
        Ok((film, deep, stats))
    })
}

/// A black film with the buffers a render fills: motion vectors when
/// `blurred`, sample counts when `adaptive`.
fn empty_film(w: u32, h: u32, blurred: bool, adaptive: bool) -> Film {
    let mut film = Film::new(w, h);
    if blurred {
        film.motion = vec![[0.0; 2]; film.rgba.len()];
    }
    if adaptive {
        film.samples = vec![0; film.rgba.len()];
    }
    film
}

/// The deep image of a frame from its tiles' pixels and samples (tile
/// order) in row-major order.
fn deep_image(w: u32, h: u32, tiles: &[(u32, u32)], rendered: &[TileResult]) -> DeepImage {
    let mut counts = vec![0u32; w as usize * h as usize];
    for (&(x0, y0), (pixels, ..)) in tiles.iter().zip(rendered) {
        let tw = (x0 + TILE).min(w) - x0;
        for (k, px) in pixels.iter().enumerate() {
            counts[(y0 + k as u32 / tw) as usize * w as usize + (x0 + k as u32 % tw) as usize] = px.deep;
        }
    }
    let mut starts = Vec::with_capacity(counts.len());
    let mut total = 0usize;
    for &n in &counts {
        starts.push(total);
        total += n as usize;
    }
    let mut samples = vec![DeepSample::default(); total];
    for (&(x0, y0), (pixels, _, _, tile_samples)) in tiles.iter().zip(rendered) {
        let tw = (x0 + TILE).min(w) - x0;
        let mut at = 0;
        for (k, px) in pixels.iter().enumerate() {
            let i = (y0 + k as u32 / tw) as usize * w as usize + (x0 + k as u32 % tw) as usize;
            let n = px.deep as usize;
            samples[starts[i]..starts[i] + n].copy_from_slice(&tile_samples[at..at + n]);
            at += n;
        }
    }
    DeepImage { width: w, height: h, counts, samples }
}

/// Rejects settings and scenes the renderer cannot trace, naming the culprit.
fn check(blas: &BlasSet, lib: &Library, scene: &FrameScene, s: &RenderSettings) -> Result<()> {
    let here = "frame scene";
    if s.width == 0 || s.height == 0 {
        return Err(Error::Usage(format!("render resolution {}x{} is empty", s.width, s.height)));
    }
    if let Some(a) = &s.adaptive {
        a.check().map_err(|(key, m)| Error::Usage(format!("{key}: {m}")))?;
        if s.first_sample != 0 {
            return Err(Error::Usage("adaptive sampling renders a pixel's samples from the first".into()));
        }
    } else if s.spp == 0 {
        return Err(Error::Usage("render spp must be at least 1".into()));
    } else if s.first_sample.checked_add(s.spp).is_none() {
        return Err(Error::Usage(format!(
            "{} samples from sample {} run past the last sample index",
            s.spp, s.first_sample
        )));
    }
    if blas.len() != lib.meshes.len() {
        return Err(Error::invalid(
            here,
            format!(
                "BLAS set has {} meshes but the library has {} (built from another library?)",
                blas.len(),
                lib.meshes.len()
            ),
        ));
    }
    let camera = &scene.camera;
    let fov_ok = camera.yfov > 0.0 && camera.yfov < std::f32::consts::PI; // false for NaN too
    let det = camera.world_from_camera.matrix3.determinant();
    if !fov_ok || !camera.world_from_camera.is_finite() || det.abs() < 1e-12 {
        return Err(
            Error::invalid(here, format!("camera is degenerate (yfov {} rad)", scene.camera.yfov)).field("camera")
        );
    }
    for (i, inst) in scene.instances.iter().enumerate() {
        let err = |msg: String| {
            let e = Error::invalid(here, format!("instance {i}: {msg}")).field("instances");
            match inst.agent.get() {
                Some(a) => e.agent(a),
                None => e,
            }
        };
        if inst.mesh as usize >= lib.meshes.len() {
            return Err(err(format!("mesh {} does not exist ({} meshes)", inst.mesh, lib.meshes.len())));
        }
        if inst.material as usize >= lib.materials.len() {
            return Err(err(format!("material {} does not exist ({} materials)", inst.material, lib.materials.len())));
        }
        if !inst.world_from_object.is_finite() {
            return Err(err("transform is not finite".into()));
        }
    }
    if let Some(m) = &scene.motion {
        if m.instances.len() != scene.instances.len() {
            return Err(Error::invalid(
                here,
                format!("motion has {} instances but the scene {}", m.instances.len(), scene.instances.len()),
            )
            .field("motion"));
        }
        if crate::shot::check_shutter(m.shutter).is_err() && m.shutter[0] != m.shutter[1] {
            return Err(Error::invalid(here, format!("shutter {:?} is not valid", m.shutter)).field("motion.shutter"));
        }
        for (i, im) in m.instances.iter().enumerate() {
            let bad_weight = im.deform.is_some_and(|d| !d.weight.iter().all(|w| (0.0..=1.0).contains(w)));
            let bad_mesh = im.deform.is_some_and(|d| d.mesh as usize >= lib.meshes.len());
            if !im.world_from_object_close.is_finite() || bad_weight || bad_mesh {
                return Err(Error::invalid(here, format!("instance {i}: its shutter-close key is not valid"))
                    .field("motion.instances"));
            }
        }
        for c in &m.camera {
            if !(c.world_from_camera.is_finite() && c.yfov > 0.0 && c.yfov < std::f32::consts::PI) {
                return Err(Error::invalid(here, "camera over the shutter is degenerate").field("motion.camera"));
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A pool that cannot start names the `threads` setting and the cause
    /// (issue 49: it was a bare usage error naming no option).
    #[test]
    fn a_pool_that_cannot_start_names_the_threads_setting() {
        let e = rayon::ThreadPoolBuilder::new()
            .num_threads(3)
            .spawn_handler(|_| Err(std::io::Error::other("no threads left")))
            .build()
            .unwrap_err();
        match pool_error(3, e) {
            Error::Setting { option, msg } => {
                assert_eq!(option, "threads");
                assert!(msg.contains("cannot start 3 render threads") && msg.contains("no threads left"), "{msg}");
            }
            other => panic!("{other:?}"),
        }
    }

    /// Samples that all agree do not prove a pixel converged: a light seen
    /// once in 20 samples is missed by 8 of them nine times in ten, so the
    /// error of n agreeing samples is 1 / n, not 0, and a pixel whose rare
    /// light its first samples missed samples on until it is found.
    #[test]
    fn agreeing_samples_claim_no_less_than_one_over_n() {
        for n in [2u32, 8, 33, 256] {
            let mut e = ErrorEstimate::default();
            for _ in 0..n {
                e.add(Vec3::splat(0.5), 1.0);
            }
            assert_eq!(e.error(n), 1.0 / f64::from(n));
        }
        // One sample in 20 sees a lamp 20 times brighter than the rest.
        let sample = |i: u32| if i % 20 == 19 { Vec3::splat(10.0) } else { Vec3::splat(0.5) };
        let mut e = ErrorEstimate::default();
        let stop = (1..=400u32).find(|&n| {
            e.add(sample(n - 1), 1.0);
            n >= 8 && n % 4 == 0 && e.error(n) < 0.05
        });
        assert!(stop.is_none_or(|n| n >= 20), "stopped at {stop:?}, before the lamp's first sample");
        assert!(stop.is_none(), "once seen, the lamp keeps the pixel sampling: stopped at {stop:?}");
    }
}
