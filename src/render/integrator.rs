//! Unidirectional path tracer (pbrt's "path" integrator, simplified): next-event
//! estimation to one light per shading point, picked by power among the sun,
//! the dome, local lights and emissive triangles ([`super::lights`]), with
//! MIS against BSDF sampling; the uniform sky picked up by BSDF-sampled rays;
//! Russian roulette after a few bounces; a thin-lens camera for depth of field.
//!
//! Visibility per ray type (scene::vis): camera rays see CAMERA | HOLDOUT
//! instances (a holdout hit ends the path with no colour and alpha 0), shadow
//! rays are blocked by SHADOW instances, bounce rays see INDIRECT instances.

use std::f32::consts::PI;

use glam::{Affine3A, Mat3A, Vec2, Vec3, Vec4};

use super::accel::{Hit, Tlas, WorldRay};
use super::bsdf::{sample_concentric_disk, Bsdf, Dielectric, ShadingFrame};
use super::dome::Lookup;
use super::lights::LightSampler;
use super::sampler::Sampler;
use super::RenderSettings;
use crate::scene::passes::{LightGroups, LightPath, Split};
use crate::scene::{vis, AlphaMode, FrameScene, Library, Material, Mesh, Texture, TextureRef, UvTransform};

/// Bounces before Russian roulette may end a path.
const RR_START: u32 = 3;
/// Sampler dimensions used per bounce (light point 2, lobe 1, direction 2,
/// roulette 1, light pick 1, glass-or-not pick 1).
const DIMS_PER_BOUNCE: u32 = 8;
/// The extra stream (`Sampler::extra_pick`) that picks the light group at
/// vertices after the camera's; past any group index.
const GROUP_PICK_STREAM: u32 = 7;
/// Pixel filter: a radially truncated Gaussian, importance-sampled exactly.
pub(crate) const FILTER_RADIUS: f32 = 1.5;
const FILTER_SIGMA: f32 = 0.5;

/// What camera rays see: camera-visible instances and holdouts.
const CAMERA_MASK: u8 = vis::CAMERA | vis::HOLDOUT;

/// Camera rays as packets ([`Tlas::intersect_stream`]) in the integrators
/// made from now on, or one at a time; the same image either way.
static CAMERA_PACKETS: std::sync::atomic::AtomicBool = std::sync::atomic::AtomicBool::new(true);

/// Chooses whether renders started from now on trace camera rays as packets
/// (the default) or one at a time, process-wide: for benchmarks comparing
/// the two in one binary. Renders are the same bits either way.
#[doc(hidden)]
pub fn set_camera_packets(on: bool) {
    CAMERA_PACKETS.store(on, std::sync::atomic::Ordering::Relaxed);
}

/// The choice [`set_camera_packets`] made (default true).
pub fn camera_packets() -> bool {
    CAMERA_PACKETS.load(std::sync::atomic::Ordering::Relaxed)
}

/// One camera sample up to its camera ray: its sampler (past the film
/// offset, time and lens draws), the film offset and the ray.
#[derive(Clone, Debug)]
pub(crate) struct CameraSample {
    sampler: Sampler,
    offset: Vec2,
    ray: WorldRay,
}

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

/// Power heuristic with beta = 2.
#[inline]
fn power_heuristic(f: f32, g: f32) -> f32 {
    let (f2, g2) = (f * f, g * g);
    if f2 + g2 > 0.0 {
        f2 / (f2 + g2)
    } else {
        0.0
    }
}

/// The MIS weight of light a BSDF-sampled ray found, against NEE's pdf
/// `light_pdf` for it: 1 after a delta bounce (glass, a mirror-smooth
/// transmission), which NEE cannot sample.
#[inline]
fn bsdf_weight(prev_delta: bool, prev_bsdf_pdf: f32, light_pdf: f32) -> f32 {
    if prev_delta {
        1.0
    } else {
        power_heuristic(prev_bsdf_pdf, light_pdf)
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

/// Bilinear lookup with wrap (glTF REPEAT); v = 0 is the top row.
pub(crate) fn sample_texture(tex: &Texture, uv: Vec2) -> Vec4 {
    let (w, h) = (tex.width as usize, tex.height as usize);
    if w == 0 || h == 0 || tex.texels.len() < w * h || !uv.is_finite() {
        return Vec4::ONE;
    }
    let x = uv.x * w as f32 - 0.5;
    let y = uv.y * h as f32 - 0.5;
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let wrap = |i: f32, n: usize| (i as i64).rem_euclid(n as i64) as usize;
    let (xa, xb) = (wrap(x0, w), wrap(x0 + 1.0, w));
    let (ya, yb) = (wrap(y0, h), wrap(y0 + 1.0, h));
    let t = |x: usize, y: usize| Vec4::from_array(tex.texels[y * w + x]);
    let top = t(xa, ya).lerp(t(xb, ya), fx);
    let bottom = t(xa, yb).lerp(t(xb, yb), fx);
    top.lerp(bottom, fy)
}

/// The texture coordinate at barycentrics (b1, b2) of the triangle with
/// vertices `idx`; `None` for a mesh without UVs.
#[inline]
fn uv_at(mesh: &Mesh, idx: [usize; 3], b1: f32, b2: f32) -> Option<Vec2> {
    if mesh.uvs.len() != mesh.positions.len() {
        return None;
    }
    let [t0, t1, t2] = idx.map(|i| mesh.uvs[i]);
    Some(t0 * (1.0 - b1 - b2) + t1 * b1 + t2 * b2)
}

/// Texture `texture` (an index into `lib.textures`) at texture coordinate
/// `uv` through `transform`; `None` without either.
#[inline]
fn texel(lib: &Library, texture: Option<u32>, transform: &UvTransform, uv: Option<Vec2>) -> Option<Vec4> {
    let tex = lib.textures.get(texture? as usize)?;
    Some(sample_texture(tex, transform.apply(uv?)))
}

#[inline]
fn texel_ref(lib: &Library, texture: Option<TextureRef>, uv: Option<Vec2>) -> Option<Vec4> {
    let t = texture?;
    texel(lib, Some(t.texture), &t.uv, uv)
}

/// The vertex indices of triangle `triangle` of `mesh`, checked.
#[inline]
fn triangle_vertices(mesh: &Mesh, triangle: u32) -> Option<[usize; 3]> {
    let k = triangle as usize * 3;
    let idx = mesh.indices.get(k..k + 3)?;
    let idx = [idx[0] as usize, idx[1] as usize, idx[2] as usize];
    idx.iter().all(|&i| i < mesh.positions.len()).then_some(idx)
}

/// A material's alpha (coverage) at barycentrics (b1, b2) of a triangle of
/// `mesh`: base colour factor alpha x base colour texture alpha.
pub(crate) fn surface_alpha(lib: &Library, material: &Material, mesh: &Mesh, triangle: u32, b1: f32, b2: f32) -> f32 {
    let texture = triangle_vertices(mesh, triangle)
        .and_then(|idx| texel(lib, material.base_color_texture, &material.base_color_uv, uv_at(mesh, idx, b1, b2)));
    material.alpha * texture.map_or(1.0, |t| t.w)
}

/// How much of a surface is there on average at alpha `alpha`: 0 or 1 for
/// MASK, alpha itself for BLEND's stochastic holes, 1 for OPAQUE.
pub(crate) fn coverage(material: &Material, alpha: f32) -> f32 {
    match material.alpha_mode {
        AlphaMode::Opaque => 1.0,
        AlphaMode::Mask { cutoff } => {
            if alpha >= cutoff {
                1.0
            } else {
                0.0
            }
        }
        AlphaMode::Blend => alpha.clamp(0.0, 1.0),
    }
}

/// The emitted radiance of a material at barycentrics (b1, b2) of triangle
/// `triangle` of `mesh`, front side: emission x emissive texture, x the
/// coverage where alpha cuts holes (what NEE on emissive triangles sees).
pub(crate) fn surface_emission(
    lib: &Library,
    material: &Material,
    mesh: &Mesh,
    triangle: u32,
    b1: f32,
    b2: f32,
) -> Vec3 {
    let Some(idx) = triangle_vertices(mesh, triangle) else { return material.emission };
    let uv = uv_at(mesh, idx, b1, b2);
    let mut e = material.emission;
    if let Some(t) = texel(lib, material.emissive_texture, &material.emissive_uv, uv) {
        e *= t.truncate();
    }
    if material.has_cutouts() {
        e *= coverage(material, surface_alpha(lib, material, mesh, triangle, b1, b2));
    }
    e
}

/// The camera's rays: looks down its local -Z, +Y up, vertical field of
/// view; a thin lens of radius `aperture` focused at `focus_distance`, or a
/// pinhole.
#[derive(Clone, Copy, Debug)]
pub struct CameraRays {
    world_from_camera: Affine3A,
    camera_from_world: Affine3A,
    tan_half_y: f32,
    aspect: f32,
    width: f32,
    height: f32,
    aperture: f32,
    focus_distance: f32,
}

impl CameraRays {
    /// Camera for an image of `width` x `height` pixels.
    pub fn new(camera: &crate::scene::Camera, width: u32, height: u32) -> CameraRays {
        CameraRays {
            world_from_camera: camera.world_from_camera,
            camera_from_world: camera.world_from_camera.inverse(),
            tan_half_y: (0.5 * camera.yfov).tan(),
            aspect: width as f32 / height.max(1) as f32,
            width: width as f32,
            height: height as f32,
            aperture: camera.aperture.max(0.0),
            focus_distance: camera.focus_distance,
        }
    }

    /// Whether rays start across a lens (depth of field) rather than at a point.
    pub(crate) fn has_lens(&self) -> bool {
        self.aperture > 0.0 && self.focus_distance > 0.0
    }

    /// The world ray (origin, unit direction) through film position
    /// (fx, fy) in pixels, y down, (0, 0) the top-left corner.
    pub fn ray(&self, fx: f32, fy: f32) -> (Vec3, Vec3) {
        let sx = (2.0 * fx / self.width - 1.0) * self.aspect * self.tan_half_y;
        let sy = (1.0 - 2.0 * fy / self.height) * self.tan_half_y;
        let d = self.world_from_camera.transform_vector3(Vec3::new(sx, sy, -1.0)).normalize();
        (self.world_from_camera.translation.into(), d)
    }

    /// As [`CameraRays::ray`], from lens point `u` (uniform in [0, 1)^2):
    /// every ray through one film position meets at the focus plane, so a
    /// point there images to a point and others blur by their circle of
    /// confusion. A pinhole camera ignores `u`.
    pub(crate) fn lens_ray(&self, fx: f32, fy: f32, u: Vec2) -> (Vec3, Vec3) {
        if !self.has_lens() {
            return self.ray(fx, fy);
        }
        let sx = (2.0 * fx / self.width - 1.0) * self.aspect * self.tan_half_y;
        let sy = (1.0 - 2.0 * fy / self.height) * self.tan_half_y;
        let focus = Vec3::new(sx, sy, -1.0) * self.focus_distance;
        let lens = sample_concentric_disk(u) * self.aperture;
        let origin = Vec3::new(lens.x, lens.y, 0.0);
        let o = self.world_from_camera.transform_point3(origin);
        let d = self.world_from_camera.transform_vector3(focus - origin).normalize();
        (o, d)
    }

    /// Camera-space depth of a world point, positive in front of the camera.
    pub(crate) fn depth(&self, p: Vec3) -> f32 {
        -self.camera_from_world.transform_point3(p).z
    }

    /// The film position (pixels, y down, (0, 0) the top-left corner) a
    /// world point projects to; `None` behind the camera. Inverse of [`CameraRays::ray`].
    pub(crate) fn raster(&self, p: Vec3) -> Option<Vec2> {
        let c = self.camera_from_world.transform_point3(p);
        if !(c.z < 0.0) {
            return None;
        }
        let (sx, sy) = (c.x / -c.z, c.y / -c.z);
        Some(Vec2::new(
            (sx / (self.aspect * self.tan_half_y) + 1.0) * 0.5 * self.width,
            (1.0 - sy / self.tan_half_y) * 0.5 * self.height,
        ))
    }
}

/// The camera over the shutter: rays at a time, and the film positions at
/// open and close for motion vectors.
#[derive(Clone, Copy, Debug)]
struct ShutterCamera {
    keys: [CameraRays; 2],
    /// Whether the two keys differ (else rays come from the frame camera).
    moves: bool,
    /// Shutter length in frames (> 0).
    length: f32,
}

/// An instance where it is at one time: object to world and, deforming, the
/// second mesh and its blend weight.
struct Placed<'m> {
    world_from_object: Affine3A,
    blend: Option<(&'m Mesh, f32)>,
}

/// Everything a render thread reads: immutable, shared by reference.
pub(crate) struct Integrator<'a> {
    lib: &'a Library,
    scene: &'a FrameScene,
    tlas: &'a Tlas<'a>,
    camera: CameraRays,
    shutter: Option<ShutterCamera>,
    lights: LightSampler<'a>,
    settings: &'a RenderSettings,
    default_material: Material,
    camera_packets: bool,
}

/// The surface at a hit, in world space.
struct SurfaceHit {
    p: Vec3,
    /// Geometric normal, flipped to face the incoming ray.
    ng: Vec3,
    /// Shading normal, on the same side as `ng` and facing the incoming ray.
    ns: Vec3,
    base_color: Vec3,
    material: usize,
    /// Emitted radiance towards the ray (zero unless the material emits and
    /// the ray meets its front face).
    emission: Vec3,
    /// Cosine between the front face's normal and the way back along the ray.
    cos_front: f32,
    /// Roughness and metallic with the metallic-roughness texture.
    roughness: f32,
    metallic: f32,
    /// KHR_materials_transmission with its texture (0: opaque).
    transmission: f32,
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
        let shutter = scene.motion.as_ref().map(|m| {
            let [a, b] = m.camera;
            ShutterCamera {
                keys: [a, b].map(|c| CameraRays::new(&c, settings.width, settings.height)),
                moves: a.world_from_camera != b.world_from_camera
                    || a.yfov != b.yfov
                    || a.world_from_camera != scene.camera.world_from_camera
                    || a.yfov != scene.camera.yfov,
                length: (m.shutter[1] - m.shutter[0]).max(1e-6),
            }
        });
        Integrator {
            lib,
            scene,
            tlas,
            camera: CameraRays::new(&scene.camera, settings.width, settings.height),
            shutter,
            lights: LightSampler::new(lib, scene, tlas.bounds(), groups),
            settings,
            default_material: Material::default(),
            camera_packets: camera_packets(),
        }
    }

    /// Traces camera sample `sample` of pixel (x, y). Returns the sample
    /// result and its film offset from the pixel centre (for nearest-sample AOVs).
    /// With `split`, the sample's light is also split into passes there.
    pub(crate) fn sample_pixel(
        &self,
        x: u32,
        y: u32,
        sample: u32,
        counts: &mut RayCounts,
        split: Option<&mut Split>,
    ) -> (SampleResult, Vec2) {
        self.trace_sample(self.camera_sample(x, y, sample), None, counts, split)
    }

    /// Whether camera rays are traced as packets ([`Integrator::camera_hits`]):
    /// [`camera_packets`] when the integrator was made.
    pub(crate) fn camera_packets(&self) -> bool {
        self.camera_packets
    }

    /// Camera sample `sample` of pixel (x, y) up to its camera ray: the
    /// sampler, the film offset and the ray, drawn as [`Integrator::sample_pixel`] draws them.
    pub(crate) fn camera_sample(&self, x: u32, y: u32, sample: u32) -> CameraSample {
        let s = self.settings;
        let mut sampler = Sampler::new(s.seed, s.frame, s.layer, x, y, sample);
        let offset = sample_filter(sampler.next_2d());
        let (fx, fy) = (x as f32 + 0.5 + offset.x, y as f32 + 0.5 + offset.y);
        // The time stream is drawn only with a shutter, and draws no dimension.
        let time = if self.shutter.is_some() { sampler.time() } else { 0.0 };
        // The lens stream likewise, only with depth of field.
        let lens = if self.camera.has_lens() { sampler.lens() } else { Vec2::ZERO };
        let (origin, dir) = match &self.shutter {
            Some(sh) if sh.moves => {
                let ((o0, d0), (o1, d1)) = (sh.keys[0].lens_ray(fx, fy, lens), sh.keys[1].lens_ray(fx, fy, lens));
                (o0.lerp(o1, time), d0.lerp(d1, time).normalize())
            }
            _ => self.camera.lens_ray(fx, fy, lens),
        };
        CameraSample { sampler, offset, ray: WorldRay { origin, direction: dir, tmax: f32::INFINITY, time } }
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
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn sample_pixel_batched(
        &self,
        x: u32,
        y: u32,
        sample: u32,
        end: impl FnOnce() -> u32,
        batch: &mut CameraBatch,
        counts: &mut RayCounts,
        split: Option<&mut Split>,
    ) -> (SampleResult, Vec2) {
        let held = sample.checked_sub(batch.first).map(|k| k as usize).filter(|&k| k < batch.samples.len());
        let k = match held {
            Some(k) => k,
            None => {
                let end = end().max(sample + 1);
                batch.first = sample;
                batch.samples.clear();
                batch.samples.extend((sample..end).map(|s| self.camera_sample(x, y, s)));
                batch.hits.clear();
                batch.hits.resize(batch.samples.len(), None);
                self.camera_hits(&batch.samples, &mut batch.rays, &mut batch.hits);
                0
            }
        };
        self.trace_sample(batch.samples[k].clone(), Some(batch.hits[k]), counts, split)
    }

    /// Traces camera sample `cs` as [`Integrator::sample_pixel`] does; with
    /// `hit`, its camera ray's hit as [`Integrator::camera_hits`] found it.
    pub(crate) fn trace_sample(
        &self,
        cs: CameraSample,
        hit: Option<Option<Hit>>,
        counts: &mut RayCounts,
        split: Option<&mut Split>,
    ) -> (SampleResult, Vec2) {
        let CameraSample { mut sampler, offset, ray } = cs;
        let mut result = self.trace_path(ray.origin, ray.direction, ray.time, hit, &mut sampler, counts, split);
        if !(result.rgb.is_finite()) {
            result.rgb = Vec3::ZERO; // one bad sample must not poison the pixel
        }
        (result, offset)
    }

    /// Where instance `i` is at shutter fraction `time`: its open key unless
    /// the scene moves it.
    fn placed(&self, i: usize, time: f32) -> Option<Placed<'a>> {
        let inst = self.scene.instances.get(i)?;
        let Some(m) = self.scene.motion.as_ref().and_then(|m| m.instances.get(i)) else {
            return Some(Placed { world_from_object: inst.world_from_object, blend: None });
        };
        let (a, b) = (&inst.world_from_object, &m.world_from_object_close);
        let world_from_object = if a == b {
            *a
        } else {
            Affine3A {
                matrix3: a.matrix3 + (b.matrix3 - a.matrix3) * time,
                translation: a.translation + (b.translation - a.translation) * time,
            }
        };
        let lib: &'a Library = self.lib;
        let blend = m.deform.and_then(|d| {
            let (lo, hi) = (lib.meshes.get(inst.mesh as usize)?, lib.meshes.get(d.mesh as usize)?);
            (hi.positions.len() == lo.positions.len() && hi.indices.len() == lo.indices.len())
                .then(|| (hi, d.weight[0] + (d.weight[1] - d.weight[0]) * time))
        });
        Some(Placed { world_from_object, blend })
    }

    /// The object-space hit point on instance `i`'s triangle at barycentrics
    /// (u, v), with its mesh blended by `blend`.
    fn object_point(mesh: &Mesh, blend: Option<(&Mesh, f32)>, idx: [usize; 3], u: f32, v: f32) -> Option<Vec3> {
        let w = 1.0 - u - v;
        let at = |m: &Mesh| -> Option<Vec3> {
            Some(*m.positions.get(idx[0])? * w + *m.positions.get(idx[1])? * u + *m.positions.get(idx[2])? * v)
        };
        let p = at(mesh)?;
        match blend {
            Some((hi, k)) => Some(p.lerp(at(hi)?, k)),
            None => Some(p),
        }
    }

    /// Screen-space motion (pixels per frame, +v up) of the surface point at
    /// barycentrics (u, v) of triangle `triangle` of instance `i`: where the
    /// point is at shutter open and close, through the camera at each.
    fn motion_vector(&self, i: usize, triangle: u32, u: f32, v: f32) -> Vec2 {
        let Some(sh) = &self.shutter else { return Vec2::ZERO };
        let (Some(inst), Some(m)) =
            (self.scene.instances.get(i), self.scene.motion.as_ref().and_then(|m| m.instances.get(i)))
        else {
            return Vec2::ZERO;
        };
        let Some(mesh) = self.lib.meshes.get(inst.mesh as usize) else { return Vec2::ZERO };
        let tri = triangle as usize * 3;
        let Some(idx) = mesh.indices.get(tri..tri + 3) else { return Vec2::ZERO };
        let idx = [idx[0] as usize, idx[1] as usize, idx[2] as usize];
        let hi = m
            .deform
            .and_then(|d| self.lib.meshes.get(d.mesh as usize))
            .filter(|h| h.positions.len() == mesh.positions.len());
        let weights = m.deform.map_or([0.0; 2], |d| d.weight);
        let key = |k: usize, world_from_object: &Affine3A| {
            let p = Self::object_point(mesh, hi.map(|h| (h, weights[k])), idx, u, v)?;
            sh.keys[k].raster(world_from_object.transform_point3(p))
        };
        match (key(0, &inst.world_from_object), key(1, &m.world_from_object_close)) {
            (Some(a), Some(b)) => {
                let d = (b - a) / sh.length;
                if d.is_finite() {
                    Vec2::new(d.x, -d.y)
                } else {
                    Vec2::ZERO
                }
            }
            _ => Vec2::ZERO,
        }
    }

    fn surface(&self, hit: &Hit, dir: Vec3, time: f32) -> Option<SurfaceHit> {
        let inst = self.scene.instances.get(hit.instance as usize)?;
        let mesh = self.lib.meshes.get(inst.mesh as usize)?;
        let idx = triangle_vertices(mesh, hit.triangle)?;
        let (u, v) = (hit.u, hit.v);
        let w = 1.0 - u - v;
        let placed = match &self.scene.motion {
            None => None,
            Some(_) => Some(self.placed(hit.instance as usize, time)?),
        };
        let blend = placed.as_ref().and_then(|p| p.blend);
        let vertex = |k: usize| -> Option<Vec3> {
            let p = *mesh.positions.get(idx[k])?;
            match blend {
                Some((hi, b)) => Some(p.lerp(*hi.positions.get(idx[k])?, b)),
                None => Some(p),
            }
        };
        let (p0, p1, p2) = (vertex(0)?, vertex(1)?, vertex(2)?);
        // Interpolate in object space, then transform: error scales with |p|, which the offset covers.
        let world_from_object = placed.as_ref().map_or(&inst.world_from_object, |p| &p.world_from_object);
        let p = world_from_object.transform_point3(p0 * w + p1 * u + p2 * v);
        // The normal matrix per hit, not per instance: a 3x3 inverse is cheap
        // beside the ray walk, and a million agents' parts keep 48 bytes each.
        let nmat = {
            let m = world_from_object.matrix3;
            if m.determinant().abs() > 1e-30 {
                m.inverse().transpose()
            } else {
                Mat3A::IDENTITY
            }
        };
        let front = (nmat * (p1 - p0).cross(p2 - p0)).normalize_or_zero();
        if front == Vec3::ZERO {
            return None;
        }
        // The front face (glTF: counter-clockwise, flipped by mirroring
        // transforms, which the normal matrix does) is the one that emits.
        let cos_front = -front.dot(dir);
        let mut ng = front;
        if ng.dot(dir) > 0.0 {
            ng = -ng; // two-sided: face the incoming ray
        }
        let material_index = inst.material as usize;
        let material = self.lib.materials.get(material_index).unwrap_or(&self.default_material);
        let uv = uv_at(mesh, idx, u, v);
        // The front side's shading normal: interpolated, then normal-mapped.
        let mut n_front = None;
        if mesh.normals.len() == mesh.positions.len() {
            let [mut n0, mut n1, mut n2] = idx.map(|i| mesh.normals[i]);
            if let Some((hi, b)) = blend.filter(|(hi, _)| hi.normals.len() == mesh.normals.len()) {
                [n0, n1, n2] =
                    [n0.lerp(hi.normals[idx[0]], b), n1.lerp(hi.normals[idx[1]], b), n2.lerp(hi.normals[idx[2]], b)];
            }
            let n = (nmat * (n0 * w + n1 * u + n2 * v)).normalize_or_zero();
            if n.is_finite() && n != Vec3::ZERO {
                n_front = Some(n);
            }
        }
        if let Some(map) = texel_ref(self.lib, material.normal_texture, uv) {
            let n = n_front.unwrap_or(front);
            let tangent = tangent_frame(mesh, blend, idx, [w, u, v], [p0, p1, p2], world_from_object, material, n);
            if let Some(mapped) = tangent.and_then(|(t, sign)| normal_map(n, t, sign, map, material.normal_scale)) {
                n_front = Some(mapped);
            }
        }
        let mut ns = ng;
        if let Some(n) = n_front {
            ns = if n.dot(ng) < 0.0 { -n } else { n };
            if ns.dot(-dir) <= 1e-4 {
                ns = ng; // interpolated normal faces away from the viewer
            }
        }
        let mut base_color = material.base_color;
        if let Some(t) = texel(self.lib, material.base_color_texture, &material.base_color_uv, uv) {
            base_color *= t.truncate();
        }
        let (mut roughness, mut metallic) = (material.roughness, material.metallic);
        if let Some(t) = texel_ref(self.lib, material.metallic_roughness_texture, uv) {
            roughness *= t.y;
            metallic *= t.z;
        }
        let mut transmission = material.transmission;
        if transmission > 0.0 {
            if let Some(t) = texel_ref(self.lib, material.transmission_texture, uv) {
                transmission *= t.x;
            }
        }
        let mut emission = Vec3::ZERO;
        if cos_front > 0.0 && material.emission.max_element() > 0.0 {
            emission = material.emission;
            if let Some(t) = texel(self.lib, material.emissive_texture, &material.emissive_uv, uv) {
                emission *= t.truncate();
            }
        }
        Some(SurfaceHit {
            p,
            ng,
            ns,
            base_color,
            material: material_index,
            emission,
            cos_front,
            roughness,
            metallic,
            transmission,
        })
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

    fn material(&self, index: usize) -> &Material {
        self.lib.materials.get(index).unwrap_or(&self.default_material)
    }

    /// The path of a camera ray; `camera_hit`, where given, is what the
    /// ray meets (traced already, [`Integrator::camera_hits`]).
    #[allow(clippy::too_many_arguments)]
    fn trace_path(
        &self,
        mut origin: Vec3,
        mut dir: Vec3,
        time: f32,
        mut camera_hit: Option<Option<Hit>>,
        sampler: &mut Sampler,
        counts: &mut RayCounts,
        mut split: Option<&mut Split>,
    ) -> SampleResult {
        let mut out = SampleResult { z: f32::INFINITY, ..Default::default() };
        let mut first_bounce = FirstBounce::Camera;
        // Light deposited into the passes as it is added to `radiance`.
        macro_rules! pass {
            ($c:expr, $direct:expr, $group:expr) => {
                if let Some(split) = split.as_deref_mut() {
                    deposit(split, $c, first_bounce, $direct, $group);
                }
            };
        }
        let mut radiance = Vec3::ZERO;
        let mut throughput = Vec3::ONE;
        let mut prev_bsdf_pdf = 0.0f32;
        // The chance the last vertex's next-event estimation sampled a given
        // light's group (1 at the camera vertex, which samples every group).
        let mut prev_group_pick = 1.0f32;
        // The last vertex's shading point and geometric normal, where its
        // NEE picked its light (render::lights: a small group's pick depends on them).
        let mut prev_at = (Vec3::ZERO, Vec3::ZERO);
        // The last bounce was a delta lobe (glass): what the ray finds has MIS weight 1.
        let mut prev_delta = false;
        // How the dome is looked up for what the ray finds (render::dome::Lookup):
        // as the last vertex's next-event estimation looked it up, so MIS weighs
        // one radiance; sharply from the camera and after a delta lobe.
        let mut prev_lookup = Lookup::Bilinear;
        // Absorption per metre of the volume the ray travels in (zero: none).
        let mut medium = Vec3::ZERO;
        // Product of the (n_t / n_i)^2 refraction divided the throughput by (Russian roulette undoes it).
        let mut eta_scale = 1.0f32;
        counts.camera += 1;
        for depth in 0.. {
            let camera = depth == 0;
            let mask = if camera { CAMERA_MASK } else { vis::INDIRECT };
            let hit = match camera_hit.take() {
                Some(hit) => hit,
                None => self.tlas.intersect(&WorldRay { origin, direction: dir, tmax: f32::INFINITY, time }, mask),
            };
            // A sized light (rect, disk, sphere) in front of whatever the ray hits ends the path there.
            let tmax = hit.as_ref().map_or(f32::INFINITY, |h| h.t);
            if let Some(light) = self.lights.hit_sized(origin, dir, tmax, camera, prev_at) {
                if camera {
                    // A visible lamp is the set's: crowd layers hold it out
                    // (empty, alpha 0, like set geometry), so the stack shows it once.
                    if !self.settings.sky_visible {
                        return SampleResult { z: f32::INFINITY, ..Default::default() };
                    }
                    radiance += light.radiance;
                    pass!(light.radiance, true, light.group);
                    out.alpha = 1.0;
                } else {
                    if medium != Vec3::ZERO {
                        throughput *= transmittance(medium, light.t);
                    }
                    let weight = bsdf_weight(prev_delta, prev_bsdf_pdf, light.pdf * prev_group_pick);
                    let c = self.clamp_indirect(throughput * light.radiance * weight);
                    radiance += c;
                    pass!(c, depth == 1, light.group);
                }
                break;
            }
            if medium != Vec3::ZERO {
                throughput *= transmittance(medium, tmax);
            }
            let Some(hit) = hit else {
                if camera {
                    // A dome hidden from camera leaves the background empty (alpha 0) for a plate.
                    if self.settings.sky_visible
                        && (self.scene.lights.dome.is_none() || self.lights.dome_camera_visible())
                    {
                        let environment = match self.lights.dome(dir, Lookup::Bilinear) {
                            Some((l, _)) => l,
                            None => self.scene.lights.sky.radiance,
                        };
                        radiance += environment;
                        if let Some(split) = split.as_deref_mut() {
                            split.add(environment, LightPath::Environment, self.lights.environment_group());
                        }
                        if let Some(sun) = self.lights.sun().filter(|s| s.contains(dir)) {
                            radiance += sun.radiance();
                            if let Some(split) = split.as_deref_mut() {
                                split.add(sun.radiance(), LightPath::Environment, self.lights.sun_group());
                            }
                        }
                        out.alpha = 1.0;
                    }
                } else {
                    let environment = match self.lights.dome(dir, prev_lookup) {
                        Some((l, pdf)) => l * bsdf_weight(prev_delta, prev_bsdf_pdf, pdf * prev_group_pick),
                        None => self.scene.lights.sky.radiance,
                    };
                    let mut escaped = environment;
                    let mut sun_light = Vec3::ZERO;
                    if let Some(sun) = self.lights.sun().filter(|s| s.contains(dir)) {
                        let pdf = sun.pdf() * self.lights.sun_pick() * prev_group_pick;
                        sun_light = sun.radiance() * bsdf_weight(prev_delta, prev_bsdf_pdf, pdf);
                        escaped += sun_light;
                    }
                    let c = self.clamp_indirect(throughput * escaped);
                    radiance += c;
                    if split.is_some() {
                        // The clamp scales both parts alike.
                        let scale = if escaped.max_element() > 0.0 { c / (throughput * escaped) } else { Vec3::ZERO };
                        let scale = Vec3::select(scale.is_finite_mask(), scale, Vec3::ZERO);
                        if sun_light == Vec3::ZERO {
                            pass!(c, depth == 1, self.lights.environment_group());
                        } else {
                            pass!(throughput * environment * scale, depth == 1, self.lights.environment_group());
                            pass!(throughput * sun_light * scale, depth == 1, self.lights.sun_group());
                        }
                    }
                }
                break;
            };
            let Some(surface) = self.surface(&hit, dir, time) else { break };
            if camera {
                let inst = &self.scene.instances[hit.instance as usize];
                if inst.visibility & vis::HOLDOUT != 0 {
                    return SampleResult { z: f32::INFINITY, ..Default::default() };
                }
                out.alpha = 1.0;
                out.z = self.camera.depth(surface.p);
                out.normal = surface.ns;
                out.albedo = surface.base_color;
                out.agent = inst.agent.get().map_or(0, |a| a.wrapping_add(1));
                out.instance = Some(hit.instance);
                out.position = surface.p;
                if self.shutter.is_some() {
                    out.motion = self.motion_vector(hit.instance as usize, hit.triangle, hit.u, hit.v);
                }
            }
            if surface.emission != Vec3::ZERO {
                let group = self.lights.material_group(surface.material as u32);
                if camera {
                    radiance += surface.emission;
                    pass!(surface.emission, true, group);
                } else {
                    // Weighted against NEE's choice of this point (weight 1 where NEE never samples it).
                    let pdf = self.lights.triangle_pdf(hit.instance, hit.triangle, hit.t, surface.cos_front, prev_at)
                        * prev_group_pick;
                    let weight = if pdf > 0.0 { bsdf_weight(prev_delta, prev_bsdf_pdf, pdf) } else { 1.0 };
                    let c = self.clamp_indirect(throughput * surface.emission * weight);
                    radiance += c;
                    pass!(c, depth == 1, group);
                }
            }

            let material = self.material(surface.material);
            let frame = ShadingFrame::from_normal(surface.ns);
            let wo = frame.to_local(-dir);
            let base = 2 + depth * DIMS_PER_BOUNCE;
            // Transmission replaces part of the dielectric base (glTF):
            // f = (1 - w) f_opaque + w f_glass with w = (1 - metallic)
            // transmission, f_opaque the material with metallic m / (1 - w).
            // One of the two is picked per vertex, with probability its weight,
            // from a dimension of its own (drawn only when both are possible).
            let glass_weight = if self.settings.diffuse_only {
                0.0
            } else {
                (1.0 - surface.metallic.clamp(0.0, 1.0)) * surface.transmission.clamp(0.0, 1.0)
            };
            let glass = if glass_weight <= 0.0 {
                false
            } else if glass_weight >= 1.0 {
                true
            } else {
                sampler.set_dimension(base + 7);
                sampler.next_1d() < glass_weight
            };
            if glass {
                // Delta lobes: NEE finds nothing through them (f = 0), so no shadow ray.
                if depth >= self.settings.max_bounces {
                    break;
                }
                let thin = material.volume.is_none();
                let dielectric = Dielectric::new(material.ior, surface.cos_front > 0.0, thin, surface.base_color);
                sampler.set_dimension(base + 2);
                let Some(ds) = dielectric.sample(wo, sampler.next_1d()) else { break };
                // A thin wall passes the ray on unbent: the same direction, bit for bit.
                let wi = if ds.transmitted && thin { dir } else { frame.to_world(ds.wi).normalize() };
                let side = if ds.transmitted { -surface.ng } else { surface.ng };
                if wi.dot(side) <= 0.0 {
                    break; // the shading normal sent it to the wrong side of the true surface
                }
                throughput *= ds.weight;
                eta_scale *= ds.eta_scale;
                if camera {
                    first_bounce = if ds.transmitted { FirstBounce::Transmission } else { FirstBounce::Mirror };
                }
                if ds.transmitted && !thin {
                    medium = match (surface.cos_front > 0.0, material.volume) {
                        (true, Some(v)) => v.absorption(),
                        _ => Vec3::ZERO,
                    };
                }
                prev_delta = true;
                prev_lookup = Lookup::Bilinear;
                prev_bsdf_pdf = 0.0;
                sampler.set_dimension(base + 5);
                if !survives_roulette(&mut throughput, eta_scale, depth, sampler) {
                    break;
                }
                counts.bounce += 1;
                origin = offset_ray_origin(surface.p, side);
                dir = wi;
                continue;
            }
            let bsdf = if self.settings.diffuse_only {
                Bsdf::lambert(surface.base_color)
            } else {
                let metallic =
                    if glass_weight > 0.0 { surface.metallic / (1.0 - glass_weight) } else { surface.metallic };
                Bsdf::with_ior(surface.base_color, metallic, surface.roughness, material.ior)
            };
            // Next-event estimation: at the camera vertex one shadow ray to
            // one light of each group (render::lights), where the noise
            // shows; at later vertices, whose light is averaged over the
            // bounce, one ray to one group picked uniformly. The first group
            // draws from this bounce's dimensions (its pick only among
            // several lights), the others from streams of their own.
            let lookup = if bsdf.is_sharp() { Lookup::Bilinear } else { Lookup::Blocks };
            let groups = self.lights.groups();
            let (first, count) = if camera || groups.len() < 2 {
                (0, groups.len())
            } else {
                let u = sampler.extra_pick(GROUP_PICK_STREAM, depth);
                (((u * groups.len() as f32) as usize).min(groups.len() - 1), 1)
            };
            let group_pick = if count == groups.len() { 1.0 } else { 1.0 / groups.len() as f32 };
            for (g, &group) in groups.iter().enumerate().skip(first).take(count) {
                let (u_pick, u_light) = if g == 0 {
                    let u_pick = if self.lights.needs_pick(group) {
                        sampler.set_dimension(base + 6);
                        sampler.next_1d()
                    } else {
                        0.0
                    };
                    sampler.set_dimension(base);
                    (u_pick, sampler.next_2d())
                } else {
                    let u_pick =
                        if self.lights.needs_pick(group) { sampler.extra_pick(group as u32, depth) } else { 0.0 };
                    (u_pick, sampler.extra_light(group as u32, depth))
                };
                let Some(ls) = self.lights.sample(group, surface.p, surface.ng, u_pick, u_light, lookup) else {
                    continue;
                };
                if ls.wi.dot(surface.ng) <= 0.0 {
                    continue;
                }
                let wi_local = frame.to_local(ls.wi);
                let f = bsdf.eval(wo, wi_local);
                if f == Vec3::ZERO {
                    continue;
                }
                counts.shadow += 1;
                // Stop short of a light at a distance: an emissive triangle must not shadow itself.
                let tmax = if ls.distance.is_finite() { ls.distance * (1.0 - 1e-4) } else { f32::INFINITY };
                let shadow =
                    WorldRay { origin: offset_ray_origin(surface.p, surface.ng), direction: ls.wi, tmax, time };
                if self.tlas.occluded(&shadow, vis::SHADOW) {
                    // The shadow pass: direct light at a set surface that only
                    // the crowd blocks (beauty + shadow = the set unshadowed).
                    if let Some(split) = split.as_deref_mut().filter(|_| camera && self.settings.passes.shadow) {
                        let set =
                            |i: u32| self.scene.instances.get(i as usize).is_some_and(|x| x.agent.get().is_none());
                        if self.scene.instances[hit.instance as usize].agent.get().is_none()
                            && !self.tlas.occluded_by(&shadow, vis::SHADOW, set)
                        {
                            counts.shadow += 1;
                            // Light sampling alone (no MIS): the bounce ray
                            // that would find this light is blocked as well.
                            split.shadow += throughput * f * wi_local.z * ls.radiance / ls.pdf;
                        }
                    }
                    continue;
                }
                // At the last vertex no BSDF ray follows to find the light: NEE alone, weight 1.
                let contribution = if ls.delta || depth >= self.settings.max_bounces {
                    f * wi_local.z * ls.radiance / ls.pdf
                } else {
                    let weight = power_heuristic(ls.pdf * group_pick, bsdf.pdf(wo, wi_local));
                    f * wi_local.z * ls.radiance * (weight / ls.pdf)
                };
                let contribution = throughput * contribution;
                // Clamped before the pick's 1 / probability, so the clamp takes
                // what it took with a ray to every group.
                let c = if camera { contribution } else { self.clamp_indirect(contribution) / group_pick };
                radiance += c;
                if let Some(split) = split.as_deref_mut() {
                    if camera {
                        // Direct light at the first surface, lobe by lobe.
                        let share = lobe_share(bsdf.eval_lobes(wo, wi_local).0, f);
                        let lobes = FirstBounce::Lobes { diffuse: share, specular: Vec3::ONE - share };
                        deposit(split, c, lobes, true, ls.group);
                    } else {
                        deposit(split, c, first_bounce, false, ls.group);
                    }
                }
            }
            sampler.set_dimension(base + 2);

            if depth >= self.settings.max_bounces {
                break;
            }
            let u_lobe = sampler.next_1d();
            let u_dir = sampler.next_2d();
            let Some(bs) = bsdf.sample(wo, u_lobe, u_dir) else { break };
            let wi = frame.to_world(bs.wi);
            if wi.dot(surface.ng) <= 0.0 {
                break; // below the true surface: would leak through
            }
            if camera && split.is_some() {
                let (diffuse, specular) = bsdf.eval_lobes(wo, bs.wi);
                let share = lobe_share(diffuse, diffuse + specular);
                first_bounce = FirstBounce::Lobes { diffuse: share, specular: Vec3::ONE - share };
            }
            throughput *= bs.weight;
            prev_bsdf_pdf = bs.pdf;
            prev_group_pick = group_pick;
            prev_at = (surface.p, surface.ng);
            prev_delta = false;
            prev_lookup = lookup;
            if !survives_roulette(&mut throughput, eta_scale, depth, sampler) {
                break;
            }
            counts.bounce += 1;
            origin = offset_ray_origin(surface.p, surface.ng);
            dir = wi.normalize();
        }
        out.rgb = radiance;
        out
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
        // later, so fewer survivors carry a 1 / survive weight. On the
        // harness's crowd a 64-spp frame has 0.75x the variance for 1.03x the
        // rays (docs/benchmarks.md, "equal quality"), as Cycles' rule does.
        let survive = (*throughput * eta_scale).max_element().sqrt().min(0.95);
        if sampler.next_1d() >= survive {
            return false;
        }
        *throughput /= survive;
    }
    *throughput != Vec3::ZERO
}

/// The world tangent (along the normal map's +X) at a hit and the sign of
/// its bitangent (bitangent = sign x (n x tangent), n the world normal of the
/// front side): glTF TANGENT where the mesh has it, else the triangle's own
/// from its UVs, through the normal texture's transform (a rotated map turns
/// its frame with it).
#[allow(clippy::too_many_arguments)]
fn tangent_frame(
    mesh: &Mesh,
    blend: Option<(&Mesh, f32)>,
    idx: [usize; 3],
    bary: [f32; 3],
    p: [Vec3; 3],
    world_from_object: &Affine3A,
    material: &Material,
    n: Vec3,
) -> Option<(Vec3, f32)> {
    let m = world_from_object.matrix3;
    if mesh.tangents.len() == mesh.positions.len() {
        let mut t = idx.map(|i| mesh.tangents[i]);
        if let Some((hi, b)) = blend.filter(|(hi, _)| hi.tangents.len() == mesh.tangents.len()) {
            t = [0, 1, 2].map(|k| t[k].lerp(hi.tangents[idx[k]], b));
        }
        let xyz = m * (t[0] * bary[0] + t[1] * bary[1] + t[2] * bary[2]).truncate();
        if xyz.length_squared() > 0.0 && t[0].w != 0.0 {
            // A mirroring transform flips which way n x t turns.
            return Some((xyz, t[0].w.signum() * m.determinant().signum()));
        }
    }
    let transform = material.normal_texture.map_or(UvTransform::IDENTITY, |t| t.uv);
    let uv = idx.map(|i| mesh.uvs.get(i).map(|&uv| transform.apply(uv)));
    let [Some(t0), Some(t1), Some(t2)] = uv else { return None };
    let (d1, d2) = (t1 - t0, t2 - t0);
    let det = d1.x * d2.y - d1.y * d2.x;
    if !(det.abs() > 1e-20) {
        return None;
    }
    let (e1, e2) = (p[1] - p[0], p[2] - p[0]);
    let dp_du = m * ((e1 * d2.y - e2 * d1.y) / det);
    // The map's +Y is up in the image: towards -v, since glTF's v runs down.
    let up = m * ((e1 * d2.x - e2 * d1.x) / det);
    let sign = if n.cross(dp_du).dot(up) < 0.0 { -1.0 } else { 1.0 };
    Some((dp_du, sign))
}

/// The normal a tangent-space normal map texel (linear RGB in 0..1, glTF:
/// +X along the tangent, +Y along the bitangent, +Z out of the surface)
/// gives around unit normal `n`, its X and Y scaled by `scale`; `None` for a
/// degenerate frame or texel.
fn normal_map(n: Vec3, tangent: Vec3, sign: f32, texel: Vec4, scale: f32) -> Option<Vec3> {
    let t = (tangent - n * n.dot(tangent)).try_normalize()?;
    let b = sign * n.cross(t);
    let local = Vec3::new((2.0 * texel.x - 1.0) * scale, (2.0 * texel.y - 1.0) * scale, 2.0 * texel.z - 1.0);
    (t * local.x + b * local.y + n * local.z).try_normalize()
}

/// Maps a uniform 2D point to a film offset (pixels) distributed as the
/// truncated Gaussian filter, so every sample has weight 1 (filter
/// importance sampling): inverse CDF of the radial distribution.
pub(crate) fn sample_filter(u: Vec2) -> Vec2 {
    let tail = 1.0 - (-FILTER_RADIUS * FILTER_RADIUS / (2.0 * FILTER_SIGMA * FILTER_SIGMA)).exp();
    let r = FILTER_SIGMA * (-2.0 * (1.0 - u.x * tail).ln()).max(0.0).sqrt();
    let phi = 2.0 * PI * u.y;
    Vec2::new(r * phi.cos(), r * phi.sin())
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

    #[test]
    fn texture_is_bilinear_and_wraps() {
        let tex = Texture {
            name: "t".into(),
            width: 2,
            height: 2,
            texels: vec![[1.0, 0.0, 0.0, 1.0], [0.0, 1.0, 0.0, 1.0], [0.0, 0.0, 1.0, 1.0], [1.0, 1.0, 1.0, 1.0]],
        };
        // Texel centres are exact; v = 0 is the top row.
        assert_eq!(sample_texture(&tex, Vec2::new(0.25, 0.25)), Vec4::new(1.0, 0.0, 0.0, 1.0));
        assert_eq!(sample_texture(&tex, Vec2::new(0.75, 0.75)), Vec4::ONE);
        // Halfway between the two top texels, and wrapping past u = 1.
        assert_eq!(sample_texture(&tex, Vec2::new(0.5, 0.25)), Vec4::new(0.5, 0.5, 0.0, 1.0));
        assert_eq!(sample_texture(&tex, Vec2::new(1.0, 0.25)), Vec4::new(0.5, 0.5, 0.0, 1.0));
        assert_eq!(sample_texture(&tex, Vec2::new(-0.75, 1.25)), Vec4::new(1.0, 0.0, 0.0, 1.0));
    }

    #[test]
    fn filter_stays_in_radius() {
        for i in 0..64 {
            for j in 0..64 {
                let o = sample_filter(Vec2::new(i as f32 / 64.0, j as f32 / 64.0));
                assert!(o.length() <= FILTER_RADIUS + 1e-4);
            }
        }
    }
}
