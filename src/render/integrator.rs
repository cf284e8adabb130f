//! Unidirectional path tracer (pbrt's "path" integrator, simplified): next-event
//! estimation to one light per shading point, drawn from one distribution
//! over the suns, the dome, local lights and emissive triangles ([`super::lights`]), with
//! MIS against BSDF sampling; the uniform sky picked up by BSDF-sampled rays;
//! Russian roulette after a few bounces; a thin-lens camera for depth of field.
//!
//! Visibility per ray type (scene::vis): camera rays see CAMERA | HOLDOUT
//! instances (a holdout hit ends the path with no colour and alpha 0), shadow
//! rays are blocked by SHADOW instances, bounce rays see INDIRECT instances.

use std::ops::ControlFlow;

use glam::{Vec2, Vec3};

use super::accel::{Hit, Tlas, WorldRay};
use super::atmosphere::{phase_hg, sample_hg, Atmosphere, AtmosphereMode, Equiangular};
use super::bsdf::{Bsdf, Dielectric, ShadingFrame};
use super::camera::{CameraSample, FilmCamera};
use super::dome::Lookup;
use super::lights::{AreaHit, LightSample, LightSampler};
use super::sampler::Sampler;
use super::sampling::power_heuristic;
use super::surface::{SurfaceHit, Surfaces, TrianglePoint};
use super::RenderSettings;
use crate::scene::passes::{LightGroups, LightPath, Split};
use crate::scene::{vis, FrameScene, Library, Material};

/// Bounces before Russian roulette may end a path.
const RR_START: u32 = 3;
/// Sampler dimensions used per bounce (light point 2, lobe 1, direction 2,
/// roulette 1, light pick 1, glass-or-not pick 1).
const DIMS_PER_BOUNCE: u32 = 8;

/// Where the air's sampler dimensions start (render::atmosphere), far past
/// the surfaces', so a shot without air draws the numbers it always did:
/// per vertex, distance 1, equiangular light pick 1, distance 1 and a
/// point on a sphere light 2.
const AIR_BASE: u32 = 1 << 20;
/// Sampler dimensions the air uses per vertex.
const AIR_DIMS: u32 = 5;

/// What camera rays see: camera-visible instances and holdouts.
const CAMERA_MASK: u8 = vis::CAMERA | vis::HOLDOUT;

/// A run of one pixel's camera samples with their camera hits, traced
/// ahead of their paths ([`Integrator::sample_pixel_batched`]); reused from
/// pixel to pixel so it allocates once per tile.
#[derive(Default)]
pub(crate) struct CameraBatch {
    /// Sample index of `samples[0]`.
    first: u32,
    samples: Vec<CameraSample>,
    rays: Vec<WorldRay>,
    hits: Vec<Option<Hit>>,
}

impl CameraBatch {
    /// Forgets the samples held (for a new pixel).
    pub(crate) fn clear(&mut self) {
        self.samples.clear();
        self.first = 0;
    }
}

/// What one camera sample returns.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct SampleResult {
    /// Radiance (already zero where alpha is zero, i.e. premultiplied).
    pub(crate) rgb: Vec3,
    /// Coverage 0 or 1.
    pub(crate) alpha: f32,
    /// Camera-space depth (positive forward) of the first hit; +inf for none.
    pub(crate) z: f32,
    /// World shading normal at the first hit (zero for none).
    pub(crate) normal: Vec3,
    /// Albedo (textured base colour) at the first hit (zero for none).
    pub(crate) albedo: Vec3,
    /// 0 = no agent, else cache agent id + 1.
    pub(crate) agent: u32,
    /// Index in `scene.instances` of the first hit; `None` for a miss or a holdout.
    pub(crate) instance: Option<u32>,
    /// Screen-space motion of the first hit in pixels per frame, Nuke's
    /// convention (+u right, +v up); zero without motion or for no hit.
    pub(crate) motion: Vec2,
    /// World position of the first hit (zero for none).
    pub(crate) position: Vec3,
}

/// How the first surface sent the path on, which decides the light-path
/// pass of everything the path brings back (scene::passes).
#[derive(Clone, Copy, Debug)]
enum FirstBounce {
    /// Still at the camera vertex.
    Camera,
    /// An opaque lobe pair: the shares of the BSDF value in the bounce's
    /// direction that are diffuse and specular, per channel.
    Lobes { diffuse: Vec3, specular: Vec3 },
    /// Through glass.
    Transmission,
    /// A mirror reflection off glass.
    Mirror,
    /// Scattered by the air before the first surface (render::atmosphere).
    Air,
}

/// Adds contribution `c` of light group `group` to `split`'s passes, as
/// `first` and whether the light came straight from a light (`direct`) say.
#[inline]
fn deposit(split: &mut Split, c: Vec3, first: FirstBounce, direct: bool, group: u16) {
    let (diffuse, specular) = if direct {
        (LightPath::DiffuseDirect, LightPath::SpecularDirect)
    } else {
        (LightPath::DiffuseIndirect, LightPath::SpecularIndirect)
    };
    match first {
        // Only camera-ray light is deposited here before a bounce (emission, environment).
        FirstBounce::Camera => split.add(c, LightPath::Emission, group),
        FirstBounce::Lobes { diffuse: d, specular: sp } => {
            split.paths[diffuse as usize] += c * d;
            split.paths[specular as usize] += c * sp;
            if let Some(g) = split.groups.get_mut(group as usize) {
                *g += c;
            }
        }
        FirstBounce::Transmission => split.add(c, LightPath::Transmission, group),
        FirstBounce::Mirror => split.add(c, specular, group),
        FirstBounce::Air => split.add(c, LightPath::Atmosphere, group),
    }
}

/// Ray counts, summed per tile (integers, so any thread count gives the same totals).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct RayCounts {
    /// Primary rays.
    pub camera: u64,
    /// BSDF-sampled bounce rays.
    pub bounce: u64,
    /// Shadow rays towards lights.
    pub shadow: u64,
}

impl std::ops::AddAssign for RayCounts {
    fn add_assign(&mut self, o: RayCounts) {
        self.camera += o.camera;
        self.bounce += o.bounce;
        self.shadow += o.shadow;
    }
}

/// Beer's law over distance `t` for absorption `sigma` (per channel), with
/// no light left at infinity where sigma > 0.
#[inline]
fn transmittance(sigma: Vec3, t: f32) -> Vec3 {
    let one = |s: f32| if s > 0.0 { (-s * t).exp() } else { 1.0 };
    Vec3::new(one(sigma.x), one(sigma.y), one(sigma.z))
}

/// Offsets a surface point along the geometric normal `n` (pointing to the
/// side the new ray leaves from) by a few hundred ULPs of each coordinate, so
/// the offset grows with |p| and works hundreds of metres from the origin
/// (Waechter and Binder, "A Fast and Robust Method for Avoiding
/// Self-Intersection", Ray Tracing Gems, 2019).
pub fn offset_ray_origin(p: Vec3, n: Vec3) -> Vec3 {
    const ORIGIN: f32 = 1.0 / 32.0;
    const FLOAT_SCALE: f32 = 1.0 / 65536.0;
    const INT_SCALE: f32 = 256.0;
    let one = |p: f32, n: f32| {
        if p.abs() < ORIGIN {
            return p + FLOAT_SCALE * n;
        }
        let of = (INT_SCALE * n) as i32;
        let of = if p < 0.0 { -of } else { of };
        f32::from_bits((p.to_bits() as i32).wrapping_add(of) as u32)
    };
    Vec3::new(one(p.x, n.x), one(p.y, n.y), one(p.z, n.z))
}

/// Where a camera sample's rays are counted and, with `split`, its light
/// split into passes.
pub(crate) struct Tally<'s> {
    pub(crate) counts: &'s mut RayCounts,
    pub(crate) split: Option<&'s mut Split>,
}

/// Why a path stopped.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Stop {
    /// The path is done: its radiance and first-hit values stand.
    End,
    /// The camera ray met a holdout or a held-out lamp: an empty sample
    /// (no colour, alpha 0).
    Holdout,
}

/// What a step of the path says: go on, or stop.
type Step = ControlFlow<Stop>;

/// What the last vertex left for weighing, by MIS, the light the next ray
/// finds against next-event estimation's chance of sampling it there.
#[derive(Clone, Copy, Debug)]
struct PrevVertex {
    /// The pdf of the BSDF sample that sent the ray.
    bsdf_pdf: f32,
    /// The vertex's shading point and geometric normal, where its NEE
    /// picked its light (render::lights: the pick depends on them).
    at: (Vec3, Vec3),
    /// The bounce was a delta lobe (glass): what the ray finds has MIS weight 1.
    delta: bool,
    /// How the dome is looked up for what the ray finds (render::dome::Lookup):
    /// as the vertex's next-event estimation looked it up, so MIS weighs
    /// one radiance; sharply from the camera and after a delta lobe.
    lookup: Lookup,
}

impl PrevVertex {
    /// Before the camera ray.
    const CAMERA: PrevVertex =
        PrevVertex { bsdf_pdf: 0.0, at: (Vec3::ZERO, Vec3::ZERO), delta: false, lookup: Lookup::Bilinear };

    /// The MIS weight of light a BSDF-sampled ray found, against NEE's pdf
    /// `light_pdf` for it: 1 after a delta bounce (glass, a mirror-smooth
    /// transmission), which NEE cannot sample.
    #[inline]
    fn weight(&self, light_pdf: f32) -> f32 {
        if self.delta {
            1.0
        } else {
            power_heuristic(self.bsdf_pdf, light_pdf)
        }
    }
}

/// A path between its vertices: the ray it follows next, what it carries
/// and has gathered, and where its samples, rays and passes go.
struct PathState<'s> {
    origin: Vec3,
    dir: Vec3,
    /// Shutter fraction of every ray of the path.
    time: f32,
    /// The vertex the ray leads to (0: the camera ray's).
    depth: u32,
    throughput: Vec3,
    radiance: Vec3,
    /// The first hit's coverage and AOVs (its `rgb` is `radiance` at the end).
    out: SampleResult,
    /// How the first surface sent the path on (the light-path pass).
    first_bounce: FirstBounce,
    prev: PrevVertex,
    /// Absorption per metre of the volume the ray travels in (zero: none).
    medium: Vec3,
    /// Product of the (n_t / n_i)^2 refraction divided the throughput by (Russian roulette undoes it).
    eta_scale: f32,
    /// While the camera ray has met only delta surfaces (glass, its mirror
    /// reflection): their tint so far. OIDN's albedo guide is that of the
    /// first non-delta hit seen through them, times this.
    albedo_tint: Option<Vec3>,
    /// The camera ray's transmittance through the air up to what it shows
    /// (the transmittance pass; 1 in clear air).
    camera_transmittance: f32,
    sampler: &'s mut Sampler,
    counts: &'s mut RayCounts,
    split: Option<&'s mut Split>,
}

impl<'s> PathState<'s> {
    fn new(ray: WorldRay, sampler: &'s mut Sampler, tally: Tally<'s>) -> Self {
        PathState {
            origin: ray.origin,
            dir: ray.direction,
            time: ray.time,
            depth: 0,
            throughput: Vec3::ONE,
            radiance: Vec3::ZERO,
            out: SampleResult { z: f32::INFINITY, ..Default::default() },
            first_bounce: FirstBounce::Camera,
            prev: PrevVertex::CAMERA,
            medium: Vec3::ZERO,
            eta_scale: 1.0,
            albedo_tint: None,
            camera_transmittance: 1.0,
            sampler,
            counts: tally.counts,
            split: tally.split,
        }
    }

    /// Deposits light `c` of group `group`, as it is added to `radiance`,
    /// into the passes (when there are any).
    #[inline]
    fn pass(&mut self, c: Vec3, direct: bool, group: u16) {
        if let Some(split) = self.split.as_deref_mut() {
            deposit(split, c, self.first_bounce, direct, group);
        }
    }

    /// Russian roulette (from the sampler's current dimension), then the
    /// next ray from surface point `p` along `dir`, offset to the side of
    /// `side`.
    fn continue_from(&mut self, p: Vec3, side: Vec3, dir: Vec3) -> Step {
        if !survives_roulette(&mut self.throughput, self.eta_scale, self.depth, self.sampler) {
            return ControlFlow::Break(Stop::End);
        }
        self.counts.bounce += 1;
        self.origin = offset_ray_origin(p, side);
        self.dir = dir;
        ControlFlow::Continue(())
    }
}

/// A surface vertex of the path: the hit, its surface and material, its
/// shading frame with the way back along the ray, and where its sampler
/// dimensions start.
struct Vertex<'m> {
    hit: Hit,
    surface: SurfaceHit,
    material: &'m Material,
    frame: ShadingFrame,
    wo: Vec3,
    base: u32,
}

/// How the dome is looked up for light found at a vertex with `bsdf`:
/// sharply behind a sharp lobe, by blocks behind a broad one.
#[inline]
fn dome_lookup(bsdf: &Bsdf) -> Lookup {
    if bsdf.is_sharp() {
        Lookup::Bilinear
    } else {
        Lookup::Blocks
    }
}

/// Everything a render thread reads: immutable, shared by reference.
pub(crate) struct Integrator<'a> {
    lib: &'a Library,
    scene: &'a FrameScene,
    tlas: &'a Tlas<'a>,
    camera: FilmCamera,
    surfaces: Surfaces<'a>,
    lights: LightSampler<'a>,
    settings: &'a RenderSettings,
    /// The mean radiance of the dome or sky, for haze only's in-scatter.
    haze_environment: Vec3,
}

impl<'a> Integrator<'a> {
    /// Prepares per-frame data. `tlas` must be built from `scene.instances`.
    pub(crate) fn new(
        lib: &'a Library,
        scene: &'a FrameScene,
        tlas: &'a Tlas<'a>,
        settings: &'a RenderSettings,
        groups: Option<&'a LightGroups>,
    ) -> Self {
        Integrator {
            lib,
            scene,
            tlas,
            camera: FilmCamera::new(scene, settings),
            surfaces: Surfaces::new(lib, scene),
            lights: LightSampler::new(lib, scene, tlas.bounds(), groups),
            settings,
            haze_environment: match settings.atmosphere {
                Some(a) if a.mode == AtmosphereMode::Haze => match &scene.lights.dome {
                    Some(dome) => super::atmosphere::mean_radiance(dome),
                    None => scene.lights.sky.radiance,
                },
                _ => Vec3::ZERO,
            },
        }
    }

    /// Traces camera sample `sample` of pixel (x, y). Returns the sample
    /// result and its film offset from the pixel centre (for nearest-sample AOVs).
    /// With `split`, the sample's light is also split into passes there.
    pub(crate) fn sample_pixel(&self, x: u32, y: u32, sample: u32, tally: Tally<'_>) -> (SampleResult, Vec2) {
        self.trace_sample(self.camera.sample(self.settings, x, y, sample), None, tally)
    }

    /// Whether camera rays are traced as packets ([`Integrator::camera_hits`]):
    /// the settings' `tracing.camera_packets`.
    pub(crate) fn camera_packets(&self) -> bool {
        self.settings.tracing.camera_packets
    }

    /// The camera hits of `samples` (`hits[i]` of `samples[i]`), traced
    /// together as packets ([`Tlas::intersect_stream`]): each the hit
    /// [`Integrator::sample_pixel`]'s own camera ray finds, bit for bit.
    pub(crate) fn camera_hits(&self, samples: &[CameraSample], rays: &mut Vec<WorldRay>, hits: &mut [Option<Hit>]) {
        rays.clear();
        rays.extend(samples.iter().map(|c| c.ray));
        self.tlas.intersect_stream(rays, CAMERA_MASK, hits);
    }

    /// As [`Integrator::sample_pixel`] (the same bits), with the camera rays
    /// of a run of the pixel's samples traced together ahead of their paths:
    /// where `batch` does not hold sample `sample`, it is filled with the
    /// samples `sample..end()` of pixel (x, y) and their camera hits.
    /// `batch` must be cleared ([`CameraBatch::clear`]) for each new pixel.
    pub(crate) fn sample_pixel_batched(
        &self,
        x: u32,
        y: u32,
        sample: u32,
        end: impl FnOnce() -> u32,
        batch: &mut CameraBatch,
        tally: Tally<'_>,
    ) -> (SampleResult, Vec2) {
        let held = sample.checked_sub(batch.first).map(|k| k as usize).filter(|&k| k < batch.samples.len());
        let k = match held {
            Some(k) => k,
            None => {
                let end = end().max(sample + 1);
                batch.first = sample;
                batch.samples.clear();
                batch.samples.extend((sample..end).map(|s| self.camera.sample(self.settings, x, y, s)));
                batch.hits.clear();
                batch.hits.resize(batch.samples.len(), None);
                self.camera_hits(&batch.samples, &mut batch.rays, &mut batch.hits);
                0
            }
        };
        self.trace_sample(batch.samples[k].clone(), Some(batch.hits[k]), tally)
    }

    /// Traces camera sample `cs` as [`Integrator::sample_pixel`] does; with
    /// `hit`, its camera ray's hit as [`Integrator::camera_hits`] found it.
    pub(crate) fn trace_sample(
        &self,
        cs: CameraSample,
        hit: Option<Option<Hit>>,
        tally: Tally<'_>,
    ) -> (SampleResult, Vec2) {
        let CameraSample { mut sampler, offset, ray } = cs;
        let mut result = self.trace_path(ray, hit, &mut sampler, tally);
        if !(result.rgb.is_finite()) {
            result.rgb = Vec3::ZERO; // one bad sample must not poison the pixel
        }
        (result, offset)
    }

    /// Scales an indirect contribution down to `settings.indirect_clamp`
    /// (largest component), keeping its hue: trades a little energy for no
    /// fireflies from the sun seen through glossy paths.
    #[inline]
    fn clamp_indirect(&self, c: Vec3) -> Vec3 {
        let limit = self.settings.indirect_clamp;
        let m = c.max_element();
        if limit > 0.0 && m > limit {
            c * (limit / m)
        } else {
            c
        }
    }

    /// The path of a camera ray; `camera_hit`, where given, is what the
    /// ray meets (traced already, [`Integrator::camera_hits`]). Each
    /// vertex: intersect, add what the ray found (a sized light, the
    /// environment, a surface's emission), sample the lights, sample the
    /// BSDF, roulette ([`Integrator::vertex`]).
    fn trace_path(
        &self,
        ray: WorldRay,
        mut camera_hit: Option<Option<Hit>>,
        sampler: &mut Sampler,
        tally: Tally<'_>,
    ) -> SampleResult {
        let mut st = PathState::new(ray, sampler, tally);
        st.counts.camera += 1;
        let stop = loop {
            if let ControlFlow::Break(stop) = self.vertex(&mut st, camera_hit.take()) {
                break stop;
            }
            st.depth += 1;
        };
        match stop {
            Stop::Holdout => SampleResult { z: f32::INFINITY, ..Default::default() },
            Stop::End => {
                if let Some(split) = st.split.as_deref_mut() {
                    // Premultiplied: nothing shown, nothing seen through the air.
                    split.transmittance = st.camera_transmittance * st.out.alpha;
                }
                SampleResult { rgb: st.radiance, ..st.out }
            }
        }
    }

    /// One vertex of the path: what the ray meets, then, at a surface, the
    /// light sampled there and the bounce that moves `st` on to the next ray.
    fn vertex(&self, st: &mut PathState<'_>, camera_hit: Option<Option<Hit>>) -> Step {
        let camera = st.depth == 0;
        let mask = if camera { CAMERA_MASK } else { vis::INDIRECT };
        let hit = match camera_hit {
            Some(hit) => hit,
            None => self.tlas.intersect(
                &WorldRay { origin: st.origin, direction: st.dir, tmax: f32::INFINITY, time: st.time },
                mask,
            ),
        };
        // A sized light (rect, disk, sphere) in front of whatever the ray hits ends the path there.
        let tmax = hit.as_ref().map_or(f32::INFINITY, |h| h.t);
        let lamp = self.lights.hit_sized(st.origin, st.dir, tmax, camera, st.prev.at);
        if camera && self.settings.passes.transmittance {
            st.camera_transmittance = self.camera_transmittance(st, lamp.as_ref().map_or(tmax, |l| l.t));
        }
        if let Some(air) = self.air_on(st, hit.as_ref(), lamp.is_some()) {
            let end = lamp.as_ref().map_or(tmax, |l| l.t);
            let seg =
                if camera { air.camera_segment(st.origin, st.dir, end) } else { air.segment(st.origin, st.dir, end) };
            if let Some(seg) = seg {
                self.add_equiangular(st, air, seg);
                st.sampler.set_dimension(AIR_BASE + st.depth * AIR_DIMS);
                if let Some(t) = air.sample_distance(st.origin, st.dir, seg, st.sampler.next_1d()) {
                    if camera {
                        self.cover_behind_air(st, hit.as_ref().filter(|_| lamp.is_none()));
                    }
                    return self.scatter_in_air(st, air, seg, t);
                }
            }
        }
        if camera && self.camera_sees(hit.as_ref(), lamp.is_some()) {
            self.add_haze(st, lamp.as_ref().map_or(tmax, |l| l.t));
        }
        if let Some(light) = lamp {
            return ControlFlow::Break(self.add_sized_light(st, &light));
        }
        if st.medium != Vec3::ZERO {
            st.throughput *= transmittance(st.medium, tmax);
        }
        let Some(hit) = hit else {
            self.add_escaped(st);
            return ControlFlow::Break(Stop::End);
        };
        let point = TrianglePoint { instance: hit.instance, triangle: hit.triangle, u: hit.u, v: hit.v };
        let Some(surface) = self.surfaces.evaluate(&point, st.dir, st.time) else {
            return ControlFlow::Break(Stop::End);
        };
        if camera {
            self.record_first_hit(st, &hit, &surface)?;
        }
        if surface.emission != Vec3::ZERO {
            self.add_emitted(st, &hit, &surface);
        }
        let material = self.surfaces.material(surface.material);
        let frame = ShadingFrame::from_normal(surface.ns);
        let wo = frame.to_local(-st.dir);
        let v = Vertex { hit, surface, material, frame, wo, base: 2 + st.depth * DIMS_PER_BOUNCE };
        // Transmission replaces part of the dielectric base (glTF):
        // f = (1 - w) f_opaque + w f_glass with w = (1 - metallic)
        // transmission, f_opaque the material with metallic m / (1 - w).
        // One of the two is picked per vertex, with probability its weight,
        // from a dimension of its own (drawn only when both are possible).
        let glass_weight = if self.settings.diffuse_only {
            0.0
        } else {
            (1.0 - v.surface.metallic.clamp(0.0, 1.0)) * v.surface.transmission.clamp(0.0, 1.0)
        };
        let glass = if glass_weight <= 0.0 {
            false
        } else if glass_weight >= 1.0 {
            true
        } else {
            st.sampler.set_dimension(v.base + 7);
            st.sampler.next_1d() < glass_weight
        };
        if glass {
            return self.bounce_glass(st, &v);
        }
        if let Some(tint) = st.albedo_tint.take() {
            st.out.albedo = tint * v.surface.base_color;
        }
        let bsdf = if self.settings.diffuse_only {
            Bsdf::lambert(v.surface.base_color)
        } else {
            let metallic =
                if glass_weight > 0.0 { v.surface.metallic / (1.0 - glass_weight) } else { v.surface.metallic };
            Bsdf::with_ior(v.surface.base_color, metallic, v.surface.roughness, v.material.ior)
        };
        self.sample_lights(st, &v, &bsdf);
        self.bounce_bsdf(st, &v, &bsdf)
    }

    /// A sized light the ray meets before anything else: seen from the
    /// camera, or found by a bounce and weighed against NEE's choice of it.
    fn add_sized_light(&self, st: &mut PathState<'_>, light: &AreaHit) -> Stop {
        if st.depth == 0 {
            // A visible lamp is the set's: crowd layers hold it out
            // (empty, alpha 0, like set geometry), so the stack shows it once.
            if !self.settings.sky_visible {
                return Stop::Holdout;
            }
            // The throughput is 1 here but behind haze (x 1.0: the same bits).
            let c = st.throughput * light.radiance;
            st.radiance += c;
            st.pass(c, true, light.group);
            st.out.alpha = 1.0;
        } else {
            if st.medium != Vec3::ZERO {
                st.throughput *= transmittance(st.medium, light.t);
            }
            let weight = st.prev.weight(light.pdf);
            let c = self.clamp_indirect(st.throughput * light.radiance * weight);
            st.radiance += c;
            st.pass(c, st.depth == 1, light.group);
        }
        Stop::End
    }

    /// The dome, sky and sun a ray that escaped the scene sees.
    fn add_escaped(&self, st: &mut PathState<'_>) {
        let dir = st.dir;
        if st.depth == 0 {
            // A dome hidden from camera leaves the background empty (alpha 0) for a plate.
            if self.settings.sky_visible && (self.scene.lights.dome.is_none() || self.lights.dome_camera_visible()) {
                let environment = match self.lights.dome(dir, Lookup::Bilinear, st.prev.at) {
                    Some((l, _)) => l,
                    None => self.scene.lights.sky.radiance,
                };
                // The throughput is 1 here but behind haze (x 1.0: the same bits).
                let environment = st.throughput * environment;
                st.radiance += environment;
                if let Some(split) = st.split.as_deref_mut() {
                    split.add(environment, LightPath::Environment, self.lights.environment_group());
                }
                if let Some(sun) = self.lights.sun().filter(|s| s.contains(dir)) {
                    let c = st.throughput * sun.radiance();
                    st.radiance += c;
                    if let Some(split) = st.split.as_deref_mut() {
                        split.add(c, LightPath::Environment, self.lights.sun_group());
                    }
                }
                st.out.alpha = 1.0;
            }
            return;
        }
        let environment = match self.lights.dome(dir, st.prev.lookup, st.prev.at) {
            Some((l, pdf)) => l * st.prev.weight(pdf),
            None => self.scene.lights.sky.radiance,
        };
        let mut escaped = environment;
        let mut sun_light = Vec3::ZERO;
        if let Some(sun) = self.lights.sun().filter(|s| s.contains(dir)) {
            let pdf = sun.pdf() * self.lights.sun_pick(st.prev.at);
            sun_light = sun.radiance() * st.prev.weight(pdf);
            escaped += sun_light;
        }
        let c = self.clamp_indirect(st.throughput * escaped);
        st.radiance += c;
        if st.split.is_some() {
            // The clamp scales both parts alike.
            let throughput = st.throughput;
            let scale = if escaped.max_element() > 0.0 { c / (throughput * escaped) } else { Vec3::ZERO };
            let scale = Vec3::select(scale.is_finite_mask(), scale, Vec3::ZERO);
            let direct = st.depth == 1;
            if sun_light == Vec3::ZERO {
                st.pass(c, direct, self.lights.environment_group());
            } else {
                st.pass(throughput * environment * scale, direct, self.lights.environment_group());
                st.pass(throughput * sun_light * scale, direct, self.lights.sun_group());
            }
        }
    }

    /// The camera ray's surface: the sample's coverage and AOVs, or an empty
    /// sample at a holdout.
    fn record_first_hit(&self, st: &mut PathState<'_>, hit: &Hit, surface: &SurfaceHit) -> Step {
        let inst = &self.scene.instances[hit.instance as usize];
        if inst.visibility & vis::HOLDOUT != 0 {
            return ControlFlow::Break(Stop::Holdout);
        }
        let out = &mut st.out;
        out.alpha = 1.0;
        out.z = self.camera.depth(surface.p);
        out.normal = surface.ns;
        out.albedo = surface.base_color;
        out.agent = inst.agent.get().map_or(0, |a| a.wrapping_add(1));
        out.instance = Some(hit.instance);
        out.position = surface.p;
        if self.camera.has_shutter() {
            out.motion = self.camera.motion_vector(self.lib, self.scene, hit);
        }
        ControlFlow::Continue(())
    }

    /// An emitting surface's light: seen from the camera, or found by a
    /// bounce and weighed against NEE's choice of this point (weight 1
    /// where NEE never samples it).
    fn add_emitted(&self, st: &mut PathState<'_>, hit: &Hit, surface: &SurfaceHit) {
        let group = self.lights.material_group(surface.material as u32);
        if st.depth == 0 {
            st.radiance += surface.emission;
            st.pass(surface.emission, true, group);
        } else {
            let pdf = self.lights.triangle_pdf(hit.instance, hit.triangle, hit.t, surface.cos_front, st.prev.at);
            let weight = if pdf > 0.0 { st.prev.weight(pdf) } else { 1.0 };
            let c = self.clamp_indirect(st.throughput * surface.emission * weight);
            st.radiance += c;
            st.pass(c, st.depth == 1, group);
        }
    }

    /// The bounce off or through glass: delta lobes, which NEE finds nothing
    /// through (f = 0), so no shadow ray.
    fn bounce_glass(&self, st: &mut PathState<'_>, v: &Vertex<'_>) -> Step {
        if st.depth >= self.settings.max_bounces {
            return ControlFlow::Break(Stop::End);
        }
        let (surface, material) = (&v.surface, v.material);
        let thin = material.volume.is_none();
        let dielectric = Dielectric::new(material.ior, surface.cos_front > 0.0, thin, surface.base_color);
        st.sampler.set_dimension(v.base + 2);
        let Some(ds) = dielectric.sample(v.wo, st.sampler.next_1d()) else { return ControlFlow::Break(Stop::End) };
        // A thin wall passes the ray on unbent: the same direction, bit for bit.
        let wi = if ds.transmitted && thin { st.dir } else { v.frame.to_world(ds.wi).normalize() };
        let side = if ds.transmitted { -surface.ng } else { surface.ng };
        if wi.dot(side) <= 0.0 {
            return ControlFlow::Break(Stop::End); // the shading normal sent it to the wrong side of the true surface
        }
        st.throughput *= ds.weight;
        st.eta_scale *= ds.eta_scale;
        if st.depth == 0 {
            st.first_bounce = if ds.transmitted { FirstBounce::Transmission } else { FirstBounce::Mirror };
            // The glass's own colour is no guide: what it shows is (a path
            // that ends among delta surfaces guides as a miss does: zero).
            st.out.albedo = Vec3::ZERO;
            st.albedo_tint = Some(Vec3::ONE);
        }
        if let Some(tint) = &mut st.albedo_tint {
            // The tint without the refraction's radiance scaling.
            *tint *= ds.weight * ds.eta_scale;
        }
        if ds.transmitted && !thin {
            st.medium = match (surface.cos_front > 0.0, material.volume) {
                (true, Some(v)) => v.absorption(),
                _ => Vec3::ZERO,
            };
        }
        st.prev = PrevVertex { delta: true, lookup: Lookup::Bilinear, bsdf_pdf: 0.0, ..st.prev };
        st.sampler.set_dimension(v.base + 5);
        st.continue_from(surface.p, side, wi)
    }

    /// Next-event estimation: one shadow ray, to one light drawn from one
    /// distribution over every light of the scene (render::lights), its
    /// pick from this bounce's dimension 6 and its point from 0 and 1.
    fn sample_lights(&self, st: &mut PathState<'_>, v: &Vertex<'_>, bsdf: &Bsdf) {
        st.sampler.set_dimension(v.base + 6);
        let u_pick = st.sampler.next_1d();
        st.sampler.set_dimension(v.base);
        let u_light = st.sampler.next_2d();
        let lookup = dome_lookup(bsdf);
        if let Some(ls) = self.lights.sample_one(v.surface.p, v.surface.ng, u_pick, u_light, lookup) {
            self.add_light_sample(st, v, bsdf, &ls);
        }
        st.sampler.set_dimension(v.base + 2);
    }

    /// The light `ls` brings to vertex `v` through its shadow ray, weighed
    /// against the BSDF's chance of finding it.
    fn add_light_sample(&self, st: &mut PathState<'_>, v: &Vertex<'_>, bsdf: &Bsdf, ls: &LightSample) {
        let (camera, surface, wo) = (st.depth == 0, &v.surface, v.wo);
        if ls.wi.dot(surface.ng) <= 0.0 {
            return;
        }
        let wi_local = v.frame.to_local(ls.wi);
        let f = bsdf.eval(wo, wi_local);
        if f == Vec3::ZERO {
            return;
        }
        st.counts.shadow += 1;
        // Stop short of a light at a distance: an emissive triangle must not shadow itself.
        let tmax = if ls.distance.is_finite() { ls.distance * (1.0 - 1e-4) } else { f32::INFINITY };
        let shadow =
            WorldRay { origin: offset_ray_origin(surface.p, surface.ng), direction: ls.wi, tmax, time: st.time };
        if self.tlas.occluded(&shadow, vis::SHADOW) {
            // The shadow pass: direct light at a set surface that only
            // the crowd blocks (beauty + shadow = the set unshadowed).
            if let Some(split) = st.split.as_deref_mut().filter(|_| camera && self.settings.passes.shadow) {
                let set = |i: u32| self.scene.instances.get(i as usize).is_some_and(|x| x.agent.get().is_none());
                if self.scene.instances[v.hit.instance as usize].agent.get().is_none()
                    && !self.tlas.occluded_by(&shadow, vis::SHADOW, set)
                {
                    st.counts.shadow += 1;
                    // Light sampling alone (no MIS): the bounce ray
                    // that would find this light is blocked as well.
                    let air = self.air().map_or(1.0, |a| a.transmittance(surface.p, ls.wi, ls.distance));
                    split.shadow += st.throughput * f * wi_local.z * ls.radiance * (air / ls.pdf);
                }
            }
            return;
        }
        // At the last vertex no BSDF ray follows to find the light: NEE alone, weight 1.
        let contribution = if ls.delta || st.depth >= self.settings.max_bounces {
            f * wi_local.z * ls.radiance / ls.pdf
        } else {
            let weight = power_heuristic(ls.pdf, bsdf.pdf(wo, wi_local));
            f * wi_local.z * ls.radiance * (weight / ls.pdf)
        };
        let mut contribution = st.throughput * contribution;
        if let Some(air) = self.air() {
            contribution *= air.transmittance(surface.p, ls.wi, ls.distance);
        }
        // Clamped before the group pick's 1 / chance, so the clamp takes
        // what it would with a ray to every group.
        let c = if camera { contribution } else { self.clamp_indirect(contribution * ls.chance) / ls.chance };
        st.radiance += c;
        if let Some(split) = st.split.as_deref_mut() {
            if camera {
                // Direct light at the first surface, lobe by lobe.
                let share = lobe_share(bsdf.eval_lobes(wo, wi_local).0, f);
                let lobes = FirstBounce::Lobes { diffuse: share, specular: Vec3::ONE - share };
                deposit(split, c, lobes, true, ls.group);
            } else {
                deposit(split, c, st.first_bounce, false, ls.group);
            }
        }
    }

    /// The bounce by BSDF sampling off an opaque vertex.
    fn bounce_bsdf(&self, st: &mut PathState<'_>, v: &Vertex<'_>, bsdf: &Bsdf) -> Step {
        if st.depth >= self.settings.max_bounces {
            return ControlFlow::Break(Stop::End);
        }
        let u_lobe = st.sampler.next_1d();
        let u_dir = st.sampler.next_2d();
        let Some(bs) = bsdf.sample(v.wo, u_lobe, u_dir) else { return ControlFlow::Break(Stop::End) };
        let surface = &v.surface;
        let wi = v.frame.to_world(bs.wi);
        if wi.dot(surface.ng) <= 0.0 {
            return ControlFlow::Break(Stop::End); // below the true surface: would leak through
        }
        if st.depth == 0 && st.split.is_some() {
            let (diffuse, specular) = bsdf.eval_lobes(v.wo, bs.wi);
            let share = lobe_share(diffuse, diffuse + specular);
            st.first_bounce = FirstBounce::Lobes { diffuse: share, specular: Vec3::ONE - share };
        }
        st.throughput *= bs.weight;
        st.prev = PrevVertex { bsdf_pdf: bs.pdf, at: (surface.p, surface.ng), delta: false, lookup: dome_lookup(bsdf) };
        st.continue_from(surface.p, surface.ng, wi.normalize())
    }
}

impl Integrator<'_> {
    /// The air every ray scatters in (mode full); `None` for clear air or haze only.
    fn air(&self) -> Option<&Atmosphere> {
        self.settings.atmosphere.as_ref().filter(|a| a.mode == AtmosphereMode::Full && a.is_active())
    }

    /// The air this ray is traced through: after a bounce, all of it; on
    /// a camera ray, only in front of what the layer's camera sees (its own
    /// surfaces, or the sky and lamps where it shows them), so each pixel's
    /// air is in exactly one layer of a stack (docs/compositing.md).
    fn air_on(&self, st: &PathState<'_>, hit: Option<&Hit>, lamp: bool) -> Option<&Atmosphere> {
        let air = self.air()?;
        (st.depth > 0 || self.camera_sees(hit, lamp)).then_some(air)
    }

    /// Whether a camera ray that meets `hit` (or a lamp in front of it)
    /// shows something in this layer: its own surface, or the sky and
    /// lamps where the layer shows them; not a holdout, not an empty background.
    fn camera_sees(&self, hit: Option<&Hit>, lamp: bool) -> bool {
        match hit {
            _ if lamp => self.settings.sky_visible,
            Some(h) => self.scene.instances[h.instance as usize].visibility & vis::HOLDOUT == 0,
            None => {
                self.settings.sky_visible && (self.scene.lights.dome.is_none() || self.lights.dome_camera_visible())
            }
        }
    }

    /// The camera ray's transmittance through the air (full or haze only)
    /// up to `end`, where what it shows is: what the beauty holds of that
    /// surface, sky or lamp is this times its radiance (docs/compositing.md).
    fn camera_transmittance(&self, st: &PathState<'_>, end: f32) -> f32 {
        let air = self.settings.atmosphere.as_ref().filter(|a| a.is_active());
        air.map_or(1.0, |a| a.camera_transmittance(st.origin, st.dir, end))
    }

    /// Haze only (render::atmosphere::AtmosphereMode::Haze), on the camera
    /// ray up to `end`: the sun's and the environment's in-scatter in closed
    /// form, and the throughput of everything behind cut by the transmittance.
    fn add_haze(&self, st: &mut PathState<'_>, end: f32) {
        let Some(air) = self.settings.atmosphere.as_ref().filter(|a| a.mode == AtmosphereMode::Haze) else { return };
        let Some(seg) = air.camera_segment(st.origin, st.dir, end) else { return };
        let sun = self.scene.lights.sun.as_ref().map(|s| (s.direction.normalize_or_zero(), s.irradiance));
        let (sun, environment) = air.haze_in_scatter(st.origin, st.dir, seg, sun, self.haze_environment);
        st.radiance += sun + environment;
        if let Some(split) = st.split.as_deref_mut() {
            split.add(sun, LightPath::Atmosphere, self.lights.sun_group());
            split.add(environment, LightPath::Atmosphere, self.lights.environment_group());
        }
        st.throughput *= air.transmittance_over(st.origin, st.dir, seg);
    }

    /// A camera ray that scatters in the air covers its pixel as what is
    /// behind the air would: its coverage and AOVs are that surface's
    /// (`hit`), or the sky's or lamp's.
    fn cover_behind_air(&self, st: &mut PathState<'_>, hit: Option<&Hit>) {
        st.out.alpha = 1.0;
        let Some(hit) = hit else { return };
        let point = TrianglePoint { instance: hit.instance, triangle: hit.triangle, u: hit.u, v: hit.v };
        if let Some(surface) = self.surfaces.evaluate(&point, st.dir, st.time) {
            // Not a holdout: the air is traced only in front of what the camera sees.
            let _ = self.record_first_hit(st, hit, &surface);
        }
    }

    /// The path scatters at distance `t` along its ray, in the part `seg`
    /// of it in the air: the light sampled there, then a new direction by
    /// the phase function. Grey extinction: the event weighs the
    /// throughput by the albedo alone.
    fn scatter_in_air(&self, st: &mut PathState<'_>, air: &Atmosphere, seg: (f32, f32), t: f32) -> Step {
        let p = st.origin + st.dir * t;
        st.throughput *= air.albedo;
        if st.depth == 0 {
            st.first_bounce = FirstBounce::Air;
        }
        let base = 2 + st.depth * DIMS_PER_BOUNCE;
        self.light_in_air(st, air, seg, t, base);
        if st.depth >= self.settings.max_bounces || st.throughput == Vec3::ZERO {
            return ControlFlow::Break(Stop::End);
        }
        st.sampler.set_dimension(base + 3);
        let (wi, pdf) = sample_hg(st.dir, air.anisotropy, st.sampler.next_2d());
        st.prev = PrevVertex { bsdf_pdf: pdf, at: (p, Vec3::ZERO), delta: false, lookup: Lookup::Blocks };
        st.sampler.set_dimension(base + 5);
        // A point in the air has no surface to leave: no offset (a zero normal).
        st.continue_from(p, Vec3::ZERO, wi)
    }

    /// Next-event estimation at the air point `t` along the ray: one light
    /// from the distribution every shading point draws from (render::lights,
    /// with no normal: lit from every side), weighed against the phase
    /// function's chance of finding it and, for a point, spot or sphere
    /// light, against equiangular sampling's chance of this point
    /// ([`Integrator::add_equiangular`]).
    fn light_in_air(&self, st: &mut PathState<'_>, air: &Atmosphere, seg: (f32, f32), t: f32, base: u32) {
        let p = st.origin + st.dir * t;
        st.sampler.set_dimension(base + 6);
        let u_pick = st.sampler.next_1d();
        st.sampler.set_dimension(base);
        let u_light = st.sampler.next_2d();
        let Some(ls) = self.lights.sample_one(p, Vec3::ZERO, u_pick, u_light, Lookup::Blocks) else { return };
        let phase = phase_hg(st.dir.dot(ls.wi), air.anisotropy);
        // Against the phase function's rays (which find sized lights only,
        // and only where a bounce follows).
        let by_light =
            if ls.delta || st.depth >= self.settings.max_bounces { 1.0 } else { power_heuristic(ls.pdf, phase) };
        // Equiangular sampling's density of this point, for the light it would pick.
        let other = self.equiangular_pdf(air, st.origin, st.dir, seg, ls.source, t);
        let weight = if other > 0.0 {
            // Distance sampling's density of the point times NEE's pick of the light.
            let pick = if ls.delta { ls.pdf } else { self.lights.pick_at(ls.source as usize, (p, Vec3::ZERO)) };
            by_light * power_heuristic(air.distance_pdf(st.origin, st.dir, seg, t) * pick, other)
        } else {
            by_light
        };
        let light = phase * weight / ls.pdf;
        self.add_air_light(st, air, p, &ls, st.throughput * light);
    }

    /// Light `ls` at air point `p`, scaled by `scale`, when its shadow ray
    /// gets through: attenuated by the air on the way, added to the sample
    /// and its passes.
    fn add_air_light(&self, st: &mut PathState<'_>, air: &Atmosphere, p: Vec3, ls: &LightSample, scale: Vec3) {
        st.counts.shadow += 1;
        let tmax = if ls.distance.is_finite() { ls.distance * (1.0 - 1e-4) } else { f32::INFINITY };
        let shadow = WorldRay { origin: p, direction: ls.wi, tmax, time: st.time };
        if self.tlas.occluded(&shadow, vis::SHADOW) {
            return;
        }
        let tr = air.transmittance(p, ls.wi, ls.distance);
        let contribution = scale * ls.radiance * tr;
        let camera = st.depth == 0;
        let c = if camera { contribution } else { self.clamp_indirect(contribution * ls.chance) / ls.chance };
        if !c.is_finite() || c == Vec3::ZERO {
            return;
        }
        st.radiance += c;
        if !camera {
            st.pass(c, false, ls.group);
        } else if let Some(split) = st.split.as_deref_mut() {
            split.add(c, LightPath::Atmosphere, ls.group);
        }
    }

    /// Equiangular sampling of the ray's part `seg` in the air (before
    /// distance sampling moves the path on): a point, spot or sphere light
    /// picked by what it can give the segment, a point on the segment with
    /// density falling as 1 / distance^2 to its centre, the light's
    /// in-scatter there (a sphere's by a point on it, sampled by solid
    /// angle), weighed by MIS against distance sampling's chance of the same
    /// point and light (Kulla and Fajardo 2012). What converges a lamp's cone.
    ///
    /// A sphere light is also found by the phase function's rays from a
    /// distance-sampled point, weighed there against NEE alone
    /// ([`PrevVertex::weight`]). So, per point `t` and direction, the three
    /// weights are: this one `(1 - w(t)) v`, NEE's `w(t) v` and the phase
    /// ray's `1 - v`, with `w` the distance/equiangular weight and `v` the
    /// light/phase weight NEE uses; they sum to 1 (and `v` is 1 where no
    /// bounce follows).
    fn add_equiangular(&self, st: &mut PathState<'_>, air: &Atmosphere, seg: (f32, f32)) {
        if !self.lights.has_point_lights() {
            return;
        }
        st.sampler.set_dimension(AIR_BASE + st.depth * AIR_DIMS + 1);
        let u_pick = st.sampler.next_1d();
        let u_t = st.sampler.next_1d();
        let u_light = st.sampler.next_2d();
        let focus = air.focus(st.origin, st.dir, seg);
        let Some((source, pick, centre)) = self.lights.pick_point_light(st.origin, st.dir, seg, focus, u_pick) else {
            return;
        };
        let Some(eq) = Equiangular::new(st.origin, st.dir, centre, seg) else { return };
        let t = eq.sample(u_t);
        let pdf = eq.pdf(t) * pick;
        let p = st.origin + st.dir * t;
        let Some(ls) = self.lights.point_light(source, p, u_light) else { return };
        // Distance sampling's density of this point, times the pick NEE makes there.
        let nee_pick = self.lights.pick_at(source as usize, (p, Vec3::ZERO));
        let weight = power_heuristic(pdf, air.distance_pdf(st.origin, st.dir, seg, t) * nee_pick);
        let phase = phase_hg(st.dir.dot(ls.wi), air.anisotropy);
        let weight = if ls.delta || st.depth >= self.settings.max_bounces {
            weight
        } else {
            weight * power_heuristic(nee_pick * ls.pdf, phase)
        };
        let along = air.transmittance_over(st.origin, st.dir, (seg.0, t));
        // ls.pdf: 1 for a point or spot, the solid-angle density of a sphere's point.
        let scale = st.throughput * air.scattering_at(p) * (along * phase * weight / (pdf * ls.pdf));
        let ls = LightSample { chance: 1.0, ..ls };
        self.add_air_light(st, air, p, &ls, scale);
    }

    /// The density with which [`Integrator::add_equiangular`] on the ray
    /// (`origin`, `dir`, part `seg` in the air) picks light `source` and
    /// distance `t`; 0 for a light it never picks.
    fn equiangular_pdf(&self, air: &Atmosphere, origin: Vec3, dir: Vec3, seg: (f32, f32), source: u32, t: f32) -> f32 {
        let focus = air.focus(origin, dir, seg);
        let Some((pick, centre)) = self.lights.point_light_pick(origin, dir, seg, focus, source) else { return 0.0 };
        Equiangular::new(origin, dir, centre, seg).map_or(0.0, |eq| eq.pdf(t) * pick)
    }
}

/// The diffuse share of a BSDF value `f` whose diffuse part is `diffuse`,
/// per channel (all diffuse where `f` is zero).
#[inline]
fn lobe_share(diffuse: Vec3, f: Vec3) -> Vec3 {
    let share = diffuse / f;
    Vec3::select(share.is_finite_mask(), share.clamp(Vec3::ZERO, Vec3::ONE), Vec3::ONE)
}

/// Russian roulette after the bounce from vertex `depth` (from the sampler's
/// current dimension): whether the path goes on, its throughput divided by
/// the chance it did. `eta_scale` undoes refraction's (n_t / n_i)^2 in the
/// throughput (1 outside glass: the same bits as without it). A path whose
/// throughput is zero ends either way.
fn survives_roulette(throughput: &mut Vec3, eta_scale: f32, depth: u32, sampler: &mut Sampler) -> bool {
    if depth + 1 >= RR_START {
        // The square root of the throughput, not the throughput: paths end
        // later, so fewer survivors carry a 1 / survive weight, which buys
        // less variance than it costs in rays (docs/benchmarks.md, "equal
        // quality"), as Cycles' rule does.
        let survive = (*throughput * eta_scale).max_element().sqrt().min(0.95);
        if sampler.next_1d() >= survive {
            return false;
        }
        *throughput /= survive;
    }
    *throughput != Vec3::ZERO
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn offset_moves_off_the_surface_far_from_origin() {
        for p in [Vec3::new(500.0, 0.0, -500.0), Vec3::new(0.01, 0.0, 0.02), Vec3::new(-3000.0, 1.0, 7.0)] {
            let q = offset_ray_origin(p, Vec3::Y);
            assert!(q.y > p.y);
            assert!((q.x - p.x).abs() <= 1e-6 * p.x.abs() + 1e-9);
        }
    }
}
