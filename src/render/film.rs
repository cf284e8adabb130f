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
//!   pixel took. A tile of [`ADAPTIVE_TILE`] pixels is sampled in passes:
//!   every pixel first takes `min_spp` (at least 2); after each pass, each
//!   pixel's variance on a logarithmic scale ([`ErrorEstimate::variance`]:
//!   its luminance's over its mean squared plus [`ADAPTIVE_FLOOR`], or its
//!   alpha's at edges) is pooled with its neighbours' within [`POOL_RADIUS`] (what a
//!   denoiser averages, and enough samples to know a variance from), and the
//!   pixel takes more while sqrt(pooled variance) / n is above the threshold
//!   (the samples a frame's summed squared error wants: [`SampleCount::next_total`]),
//!   up to `max_spp`. The passes read the tile's samples alone, so the
//!   image is the same for any thread count, and a pixel's n samples are
//!   those of a fixed n-sample render, summed in the same order. Every other
//!   buffer is the mean over the samples the pixel took.
//! - `passes`: the light-path passes and light groups asked for (means over
//!   all samples, like RGB, from the same samples: scene::passes), the
//!   shadow pass (set surfaces' direct light the crowd's shadows took), the
//!   camera rays' transmittance through the air (a mean like RGB), then the
//!   world position `P` of the nearest sample's first hit (never filtered,
//!   like `z`; zero where it missed).

use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::{Duration, Instant};

use glam::{Vec2, Vec3};
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

/// Adaptive sampling works a tile of this edge at a time: the tile's pixels
/// keep their sums between its passes (one tile's worth per thread, not a
/// frame's), and a pixel's variance is pooled with its neighbours in the tile.
const ADAPTIVE_TILE: u32 = 32;

/// Adaptive sampling's pass totals are multiples of this many samples
/// (below `max_spp`; the first pass takes `min_spp`, at least 2).
pub const ADAPTIVE_STEP: u32 = 4;
/// Added to a pixel's mean luminance squared, which its variance is divided
/// by (a logarithmic scale), so that black pixels are held to an absolute error.
pub const ADAPTIVE_FLOOR: f64 = 0.01;
/// A pixel's variance is pooled over the (2r + 1)^2 pixels around it (within
/// its tile): the denoiser averages about that far in its busiest places,
/// and four samples a pixel are too few to know a variance from, 100 are not.
const POOL_RADIUS: usize = 2;
/// A pass takes a pixel to at most this many times the samples it has: its
/// need is an estimate, re-made after every pass.
const ADAPTIVE_GROWTH: f64 = 4.0;

/// How many samples a pixel takes: exactly `max`, or adaptively from `min`
/// to `max` by `threshold`.
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

    /// The samples every pixel takes in the first pass: `min`, but at least
    /// 2 (one sample has no variance), and at most `max`.
    fn first_pass(&self) -> u32 {
        self.min.max(2).min(self.max)
    }

    /// The pass total of a pixel holding `n` samples whose pooled variance is
    /// `variance`, or `None` when it is done: it is done once the error of
    /// one more sample's worth, sqrt(variance) / n, is under the threshold.
    /// Stopping there, rather than once the pixel's standard error
    /// sqrt(variance / n) is, spends samples as sqrt(variance) rather than as
    /// variance: what minimises the summed squared error of a frame for its
    /// number of samples (a pixel's next sample is worth variance / n^2 to
    /// that sum), which is what a denoiser, averaging a footprint of pixels,
    /// turns into its own error.
    fn next_total(&self, threshold: f64, n: u32, variance: f64) -> Option<u32> {
        let need = variance.sqrt() / threshold;
        if n >= self.max || need <= f64::from(n) || need.is_nan() {
            return None;
        }
        let want = need.min(f64::from(n) * ADAPTIVE_GROWTH).ceil() as u32;
        Some(want.max(n + 1).next_multiple_of(ADAPTIVE_STEP).min(self.max))
    }
}

/// Running sums of one pixel's luminance and alpha for its error estimate.
#[derive(Clone, Copy, Default)]
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

    /// The variance of one sample after `n` of them: of its luminance on a
    /// logarithmic scale (over its mean squared, plus [`ADAPTIVE_FLOOR`]),
    /// or of its alpha (edges), whichever is larger; 0 for fewer than 2.
    /// Logarithmic because that is how the denoiser takes light (OIDN's HDR
    /// mode works on a log-like transfer curve) and how a relative error and
    /// the eye measure it; Cycles' square-root scale (the variance over the
    /// mean) spent more on bright pixels and paid less (docs/benchmarks.md).
    fn variance(&self, n: u32) -> f64 {
        if n < 2 {
            return 0.0;
        }
        let n = f64::from(n);
        let var = |[s, s2]: [f64; 2]| (s2 / n - (s / n) * (s / n)).max(0.0) * n / (n - 1.0);
        let mean = self.lum[0] / n;
        (var(self.lum) / (mean * mean + ADAPTIVE_FLOOR)).max(var(self.alpha))
    }
}

/// Each pixel's variance ([`ErrorEstimate::variance`]) pooled: the mean
/// over the pixels of the tile (`width` wide, row-major) within
/// [`POOL_RADIUS`] of it.
fn pooled_variance(sums: &[PixelSums], width: usize) -> Vec<f64> {
    let v: Vec<f64> = sums.iter().map(|p| p.estimate.variance(p.spp)).collect();
    let height = v.len() / width.max(1);
    let span = |c: usize, len: usize| c.saturating_sub(POOL_RADIUS)..(c + POOL_RADIUS + 1).min(len);
    let mut pooled = Vec::with_capacity(v.len());
    for y in 0..height {
        for x in 0..width {
            let (mut total, mut k) = (0.0, 0u32);
            for ny in span(y, height) {
                for value in &v[ny * width + span(x, width).start..ny * width + span(x, width).end] {
                    total += value;
                    k += 1;
                }
            }
            pooled.push(total / f64::from(k));
        }
    }
    pooled
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

/// What a frame's pixels are sampled for, beside the beauty.
#[derive(Clone, Copy)]
struct Wants<'a, 'n, 'd> {
    /// Names for the Cryptomatte mattes (`None`: none rendered).
    crypto: Option<&'a CryptoNames<'n>>,
    /// The passes written (`None`: none).
    passes: Option<&'a PassSet>,
    /// Deep samples (`None`: none gathered).
    deep: Option<&'a DeepRequest<'a, 'd>>,
    /// Whether samples feed the adaptive error estimate.
    estimate: bool,
}

/// One pixel's sums over the samples it has taken, added in sample index
/// order: the floats are the same for any threading and however the samples
/// were split into passes, so a pixel that took n samples holds what a fixed
/// n-sample render holds there.
struct PixelSums {
    spp: u32,
    rgb: Vec3,
    alpha: f32,
    normal: Vec3,
    albedo: Vec3,
    /// The sample nearest the pixel centre: squared offset and result.
    nearest: (f32, SampleResult),
    crypto: [RankAccumulator; 3],
    /// The passes' sums (`position` unused: `P` is the nearest sample's).
    light: Split,
    estimate: ErrorEstimate,
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

impl PixelSums {
    /// No samples yet, with room for `groups` light groups.
    fn new(groups: usize) -> PixelSums {
        PixelSums {
            spp: 0,
            rgb: Vec3::ZERO,
            alpha: 0.0,
            normal: Vec3::ZERO,
            albedo: Vec3::ZERO,
            nearest: (f32::INFINITY, SampleResult { z: f32::INFINITY, ..Default::default() }),
            crypto: Default::default(),
            light: Split::new(groups),
            estimate: ErrorEstimate::default(),
        }
    }

    /// Back to no samples (for the next pixel).
    fn clear(&mut self) {
        self.spp = 0;
        (self.rgb, self.alpha, self.normal, self.albedo) = (Vec3::ZERO, 0.0, Vec3::ZERO, Vec3::ZERO);
        self.nearest = (f32::INFINITY, SampleResult { z: f32::INFINITY, ..Default::default() });
        self.crypto = Default::default();
        self.light.clear();
        self.estimate = ErrorEstimate::default();
    }

    /// Adds sample `r` taken at `offset` from the pixel centre, whose passes
    /// `split` holds (when passes are written).
    fn add(&mut self, r: &SampleResult, offset: Vec2, split: Option<&Split>, wants: &Wants) {
        // A sample the beauty drops (not finite) the passes drop too.
        if let Some(p) = split.filter(|_| r.rgb.is_finite()) {
            self.light.add_sample(p);
        }
        if let Some(names) = wants.crypto {
            // Each sample has filter weight 1 (importance-sampled filter).
            let ids = r.instance.map_or([0; 3], |i| names.ids(i));
            for (a, id) in self.crypto.iter_mut().zip(ids) {
                a.add(id);
            }
        }
        self.rgb += r.rgb;
        self.alpha += r.alpha;
        self.normal += r.normal;
        self.albedo += r.albedo;
        let d2 = offset.length_squared();
        if d2 < self.nearest.0 {
            self.nearest = (d2, *r);
        }
        if wants.estimate {
            self.estimate.add(r.rgb, r.alpha);
        }
        self.spp += 1;
    }

    /// The pixel's values: means over its samples; its passes into `values`
    /// (one triple per pass of the set) and its deep samples, from `deep`,
    /// onto `samples`.
    fn finish(
        &self,
        wants: &Wants,
        values: &mut [[f32; 3]],
        deep: Option<&mut DeepPixel>,
        samples: &mut Vec<DeepSample>,
    ) -> Pixel {
        let spp = self.spp;
        let inv = 1.0 / spp as f32;
        if let Some(set) = wants.passes {
            write_passes(set, &self.light, inv, self.nearest.1.position, values);
        }
        let mut ranked = [[[0.0f32; 2]; RANKS]; 3];
        if wants.crypto.is_some() {
            for (a, out) in self.crypto.iter().zip(&mut ranked) {
                a.write_ranked(spp, out);
            }
        }
        let deep = match (wants.deep, deep) {
            (Some(request), Some(pixel)) => pixel.finish(spp, request.names, samples),
            _ => 0,
        };
        let nearest = &self.nearest.1;
        Pixel {
            rgba: (self.rgb * inv).extend(self.alpha * inv).to_array(),
            z: nearest.z,
            normal: (self.normal * inv).to_array(),
            albedo: (self.albedo * inv).to_array(),
            agent: nearest.agent,
            motion: nearest.motion.to_array(),
            samples: spp,
            crypto: ranked,
            deep,
        }
    }
}

/// What a tile's pixels reuse: ray counts, the camera batch, one sample's passes.
struct Scratch {
    counts: RayCounts,
    batch: CameraBatch,
    split: Split,
}

/// Takes pixel (x, y)'s samples from the ones it has up to `to` (index
/// order, sample indices from `first`: a progressive pass continues the
/// sequence where the one before it stopped), into `sums` and `deep`.
/// Camera rays go in packets of at most [`PACKET`], never past `to`.
#[allow(clippy::too_many_arguments, reason = "each output buffer is the caller's, reused from pixel to pixel")]
fn take_samples(
    integrator: &Integrator,
    (x, y): (u32, u32),
    (first, to): (u32, u32),
    wants: &Wants,
    sums: &mut PixelSums,
    mut deep: Option<&mut DeepPixel>,
    scratch: &mut Scratch,
) {
    scratch.batch.clear();
    let packets = integrator.camera_packets();
    let last = first + to;
    for s in first + sums.spp..last {
        let split = wants.passes.map(|_| {
            scratch.split.clear();
            &mut scratch.split
        });
        let tally = Tally { counts: &mut scratch.counts, split };
        let (r, offset) = if packets {
            let end = || s.saturating_add(PACKET as u32).min(last);
            integrator.sample_pixel_batched(x, y, s, end, &mut scratch.batch, tally)
        } else {
            integrator.sample_pixel(x, y, s, tally)
        };
        if let (Some(d), Some(request)) = (deep.as_deref_mut(), wants.deep) {
            d.add(&request.settings, r.rgb, r.alpha, r.z, r.instance);
        }
        sums.add(&r, offset, wants.passes.map(|_| &scratch.split), wants);
    }
}

/// Renders the pixels `x0..x1` x `y0..y1`, row-major: each its fixed
/// count, or, adaptively, in passes: every pixel first takes
/// [`SampleCount::first_pass`] samples; then each pixel's variance is pooled
/// with its neighbours' ([`pooled_variance`]) and [`SampleCount::next_total`]
/// says how many it takes next, until no pixel takes more. Every pass
/// depends on the tile's samples alone, so the image is the same for any
/// thread count.
fn render_tile(
    integrator: &Integrator,
    [x0, y0, x1, y1]: [u32; 4],
    count: SampleCount,
    wants: &Wants,
    (groups, triples): (usize, usize),
) -> TileResult {
    let (tw, th) = ((x1 - x0) as usize, (y1 - y0) as usize);
    let n = tw * th;
    let at = |i: usize| (x0 + (i % tw) as u32, y0 + (i / tw) as u32);
    let mut scratch =
        Scratch { counts: RayCounts::default(), batch: CameraBatch::default(), split: Split::new(groups) };
    let mut values = vec![[0f32; 3]; n * triples];
    let mut deep_samples = Vec::new();
    let mut pixels = Vec::with_capacity(n);
    let gathers_deep = wants.deep.is_some();
    match count.threshold {
        None => {
            let mut sums = PixelSums::new(groups);
            let mut deep = DeepPixel::default();
            for i in 0..n {
                sums.clear();
                deep.clear();
                take_samples(
                    integrator,
                    at(i),
                    (count.first, count.max),
                    wants,
                    &mut sums,
                    gathers_deep.then_some(&mut deep),
                    &mut scratch,
                );
                let out = &mut values[i * triples..(i + 1) * triples];
                pixels.push(sums.finish(wants, out, gathers_deep.then_some(&mut deep), &mut deep_samples));
            }
        }
        Some(threshold) => {
            let mut sums: Vec<PixelSums> = (0..n).map(|_| PixelSums::new(groups)).collect();
            let mut deep: Vec<DeepPixel> =
                (0..if gathers_deep { n } else { 0 }).map(|_| DeepPixel::default()).collect();
            let mut target = vec![count.first_pass(); n];
            loop {
                for (i, (s, &to)) in sums.iter_mut().zip(&target).enumerate() {
                    if s.spp < to {
                        take_samples(integrator, at(i), (0, to), wants, s, deep.get_mut(i), &mut scratch);
                    }
                }
                let pooled = pooled_variance(&sums, tw);
                let mut more = false;
                for ((s, v), to) in sums.iter().zip(pooled).zip(&mut target) {
                    if let Some(next) = count.next_total(threshold, s.spp, v) {
                        *to = next;
                        more = true;
                    }
                }
                if !more {
                    break;
                }
            }
            for (i, s) in sums.iter().enumerate() {
                let out = &mut values[i * triples..(i + 1) * triples];
                pixels.push(s.finish(wants, out, deep.get_mut(i), &mut deep_samples));
            }
        }
    }
    (pixels, values, scratch.counts, deep_samples)
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
        let edge = if count.threshold.is_some() { ADAPTIVE_TILE } else { TILE };
        let tiles: Vec<(u32, u32)> =
            (0..h.div_ceil(edge)).flat_map(|ty| (0..w.div_ceil(edge)).map(move |tx| (tx * edge, ty * edge))).collect();
        let wants = Wants {
            crypto,
            passes: (triples > 0).then_some(&settings.passes),
            deep,
            estimate: count.threshold.is_some(),
        };
        let split_groups = if settings.passes.light_groups { group_count } else { 0 };
        let done = AtomicUsize::new(0);
        let start = Instant::now();
        let rendered: Vec<TileResult> = tiles
            .par_iter()
            .map(|&(x0, y0)| {
                let rect = [x0, y0, (x0 + edge).min(w), (y0 + edge).min(h)];
                let tile = render_tile(&integrator, rect, count, &wants, (split_groups, triples));
                if let Some(report) = progress {
                    report(done.fetch_add(tile.0.len(), Ordering::Relaxed) + tile.0.len());
                }
                tile
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
            let tw = (x0 + edge).min(w) - x0;
            for (k, px) in values.chunks(triples.max(1)).enumerate().filter(|_| triples > 0) {
                let i = film.index(x0 + k as u32 % tw, y0 + k as u32 / tw);
                for (pass, v) in film.passes.iter_mut().zip(px) {
                    pass.data[i] = *v;
                }
            }
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
        let deep = deep.map(|_| deep_image(w, h, edge, &tiles, &rendered));
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

/// The deep image of a frame from its tiles' (of edge `edge`) pixels and
/// samples (tile order) in row-major order.
fn deep_image(w: u32, h: u32, edge: u32, tiles: &[(u32, u32)], rendered: &[TileResult]) -> DeepImage {
    let mut counts = vec![0u32; w as usize * h as usize];
    for (&(x0, y0), (pixels, ..)) in tiles.iter().zip(rendered) {
        let tw = (x0 + edge).min(w) - x0;
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
        let tw = (x0 + edge).min(w) - x0;
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

    fn sums_of(samples: &[f32]) -> PixelSums {
        let mut p = PixelSums::new(0);
        for &l in samples {
            p.estimate.add(Vec3::splat(l), 1.0);
            p.spp += 1;
        }
        p
    }

    /// The variance is of one sample, on a logarithmic scale: the
    /// luminance's over its mean squared plus the floor; samples that agree
    /// have none.
    #[test]
    fn variance_is_of_one_sample_over_the_mean() {
        assert_eq!(sums_of(&[0.5; 8]).estimate.variance(8), 0.0);
        assert_eq!(sums_of(&[3.0]).estimate.variance(1), 0.0, "one sample has no variance");
        // Luminance 0 and 4: mean 2, unbiased variance 8.
        let v = sums_of(&[0.0, 4.0]).estimate.variance(2);
        assert!((v - 8.0 / (4.0 + ADAPTIVE_FLOOR)).abs() < 1e-12, "{v}");
        // Alpha at an edge counts when it is the larger.
        let mut edge = PixelSums::new(0);
        for a in [0.0, 1.0, 0.0, 1.0] {
            edge.estimate.add(Vec3::ZERO, a);
        }
        assert!((edge.estimate.variance(4) - 1.0 / 3.0).abs() < 1e-12);
    }

    /// A pixel spends samples as the square root of its variance: four
    /// times the variance, twice the samples; a pass at most multiplies its
    /// samples by the growth, lands on a multiple of the step and never
    /// passes max; a pixel whose need is met is done.
    #[test]
    fn samples_follow_the_square_root_of_the_variance() {
        let count = SampleCount { min: 4, max: 256, threshold: Some(0.1), first: 0 };
        let t = 0.1;
        assert_eq!(count.next_total(t, 16, 1.0), None, "needs 10, has 16");
        assert_eq!(count.next_total(t, 8, 1.0), Some(12), "needs 10: the next multiple of 4");
        assert_eq!(count.next_total(t, 8, 4.0), Some(20), "four times the variance: needs 20");
        assert_eq!(count.next_total(t, 4, 100.0), Some(16), "needs 100: at most 4x a pass");
        assert_eq!(count.next_total(t, 128, 1e6), Some(256), "never past max");
        assert_eq!(count.next_total(t, 256, 1e6), None, "done at max");
        assert_eq!(count.next_total(t, 4, f64::NAN), None);
        let odd = SampleCount { min: 3, max: 10, threshold: Some(0.1), first: 0 };
        assert_eq!(odd.first_pass(), 3);
        assert_eq!(odd.next_total(t, 9, 1.0), Some(10));
        assert_eq!(SampleCount { min: 1, max: 1, threshold: Some(0.1), first: 0 }.first_pass(), 1);
        assert_eq!(SampleCount { min: 1, max: 8, threshold: Some(0.1), first: 0 }.first_pass(), 2);
    }

    /// A pixel's variance is pooled with its neighbours' within the radius,
    /// no farther: a lamp one pixel's first samples saw keeps the pixels
    /// around it sampling too (their own first samples, which missed it,
    /// agree and claim no error), and leaves the rest of the tile alone.
    #[test]
    fn variance_is_pooled_over_the_neighbourhood() {
        let width = 9;
        let mut sums: Vec<PixelSums> = (0..width * width).map(|_| sums_of(&[0.5; 4])).collect();
        sums[4 * width + 4] = sums_of(&[0.5, 0.5, 0.5, 10.0]);
        let alone = sums[4 * width + 4].estimate.variance(4);
        let pooled = pooled_variance(&sums, width);
        let r = POOL_RADIUS;
        for y in 0..width {
            for x in 0..width {
                let v = pooled[y * width + x];
                if x.abs_diff(4) <= r && y.abs_diff(4) <= r {
                    let k = ((2 * r + 1) * (2 * r + 1)) as f64;
                    assert!((v - alone / k).abs() < 1e-12, "({x}, {y}): {v}");
                } else {
                    assert_eq!(v, 0.0, "({x}, {y}) is beyond the radius");
                }
            }
        }
        // At the tile's edge the mean is over the pixels there are.
        let mut corner: Vec<PixelSums> = (0..width * width).map(|_| sums_of(&[0.5; 4])).collect();
        corner[0] = sums_of(&[0.5, 0.5, 0.5, 10.0]);
        let v = pooled_variance(&corner, width)[0];
        let k = ((r + 1) * (r + 1)) as f64;
        assert!((v - alone / k).abs() < 1e-12, "{v}");
    }
}
