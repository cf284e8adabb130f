//! Next-event estimation over every light of a frame scene: the sun and the
//! set's distant lights, an HDRI dome, point, spot, rect, disk and sphere
//! lights, and every emissive triangle. The lights fall in three groups:
//! suns (the shot's sun, distant lights and the dome's own sun, when its
//! map has one: `render::dome`), the sky (the rest of the dome) and the
//! local lights (points, spots, sized lights, emissive triangles). A
//! shading point sends one shadow ray, to one light drawn from one
//! distribution over all of them (as Mitsuba's and Cycles' path tracers
//! do): a group picked by a bound on the irradiance it can give the point
//! ([`LightSampler::chances`]), then a light of it: suns by power (an alias
//! table), a local group of a few lights (up to [`SHADED_PICK_MAX`]) by
//! what each gives the point ([`Reach`]), a larger one by a light tree
//! (render::light_tree), so the cost does not grow with the number of
//! lights. Each light then samples a point by solid
//! angle (cones for the sun and spheres, the dome's own distributions,
//! spherical triangles for emissive triangles and rects that subtend enough) or by
//! area, converted to solid angle. Rays that hit a light (an emissive
//! surface, a sized light, the dome) are weighted against that pdf, the
//! pick taken again at the point they left, by multiple importance
//! sampling in the integrator.
//!
//! Why groups picked by what they give the point, not by power: by power
//! the sun and dome (what they pour onto the whole scene) dwarf a street
//! lamp, which would all but never be picked for the points it lights. A
//! share of the pick ([`EVEN_SHARE`]) is spread evenly over the groups that
//! can light the point, as the bounds ignore shadows: in a sun's shadow
//! the sky must still be sampled often. (One ray per group, as before,
//! cost about 2.8 shadow rays per lit camera vertex for little less noise
//! per sample than one: docs/benchmarks.md, issue 52.)
//!
//! The uniform sky stays what it was: found by BSDF-sampled rays only.

use std::f32::consts::PI;

use glam::{Vec2, Vec3};

use super::bsdf::{luminance, ShadingFrame};
use super::dome::{DomePart, DomeSampler, Lookup};
use super::light_tree::{LightBounds, LightTree};
use super::sampling::{barycentrics, sample_concentric_disk, AliasTable, SphericalQuad, SphericalTriangle};
use super::surface::surface_emission;
use crate::scene::lights::{Light, LightKind, SceneLights};
use crate::scene::passes::LightGroups;
use crate::scene::{vis, FrameScene, Library, Sun};

/// A distant light as the integrator samples it: a uniform cone (or a delta
/// direction for zero angular size).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Distant {
    direction: Vec3,
    frame: ShadingFrame,
    cos_max: f32,
    /// Radiance inside the cone (irradiance / solid angle); for a delta
    /// light the irradiance itself.
    radiance: Vec3,
    /// 1 / solid angle; zero marks a delta light.
    pdf: f32,
}

impl Distant {
    /// The sampled form of `sun`; `None` when it gives no light.
    pub(crate) fn new(sun: &Sun) -> Option<Distant> {
        let direction = sun.direction.normalize_or_zero();
        if direction == Vec3::ZERO || !sun.irradiance.is_finite() || sun.irradiance.max_element() <= 0.0 {
            return None;
        }
        let half = (0.5 * sun.angular_diameter).clamp(0.0, 0.5 * PI);
        let cos_max = half.cos();
        let solid_angle = 2.0 * PI * (1.0 - cos_max);
        let frame = ShadingFrame::from_normal(direction);
        // A disc so small (or a sun so strong) that its radiance overflows
        // is a delta direction: the same light, and no infinite sample.
        if solid_angle < 1e-9 || !(sun.irradiance / solid_angle).is_finite() {
            return Some(Distant { direction, frame, cos_max: 1.0, radiance: sun.irradiance, pdf: 0.0 });
        }
        Some(Distant { direction, frame, cos_max, radiance: sun.irradiance / solid_angle, pdf: 1.0 / solid_angle })
    }

    /// A direction towards the disc.
    fn sample(&self, u: Vec2) -> Vec3 {
        if self.pdf == 0.0 {
            return self.direction;
        }
        let cos = 1.0 - u.x * (1.0 - self.cos_max);
        let sin = (1.0 - cos * cos).max(0.0).sqrt();
        let phi = 2.0 * PI * u.y;
        self.frame.to_world(Vec3::new(sin * phi.cos(), sin * phi.sin(), cos)).normalize()
    }

    /// Whether direction `d` looks into the disc (never for a delta light).
    pub(crate) fn contains(&self, d: Vec3) -> bool {
        self.pdf > 0.0 && d.dot(self.direction) >= self.cos_max
    }

    /// Radiance seen inside the disc.
    pub(crate) fn radiance(&self) -> Vec3 {
        self.radiance
    }

    /// Solid-angle pdf of its own sampling (0 for a delta light).
    pub(crate) fn pdf(&self) -> f32 {
        self.pdf
    }

    /// Its cone (axis, sine and cosine of the half angle) and irradiance
    /// luminance: what it can give a point (LightSampler::chances).
    fn bound(&self) -> (Vec3, f32, f32, f64) {
        let sin = (1.0 - self.cos_max * self.cos_max).max(0.0).sqrt();
        (self.direction, sin, self.cos_max, power_luminance(self.irradiance()))
    }

    fn irradiance(&self) -> Vec3 {
        if self.pdf == 0.0 {
            self.radiance
        } else {
            self.radiance / self.pdf
        }
    }
}

/// An emissive triangle in world space (the shutter-open placement of its
/// instance).
#[derive(Clone, Copy, Debug)]
struct Triangle {
    p: [Vec3; 3],
    /// Unit normal of the emitting (front, counter-clockwise) face.
    n: Vec3,
    area: f32,
    mesh: u32,
    triangle: u32,
    material: u32,
}

/// One light the sampler can pick.
#[derive(Clone, Debug)]
enum Source<'a> {
    Distant(Distant),
    Dome(DomePart),
    Local(&'a Light),
    Triangle(Triangle),
}

/// A light sample as seen from a shading point.
#[derive(Clone, Copy, Debug)]
pub(crate) struct LightSample {
    /// Unit direction towards the light.
    pub(crate) wi: Vec3,
    /// Distance to the sampled point (infinite for distant lights and the dome).
    pub(crate) distance: f32,
    /// Incident radiance (for delta lights: irradiance at normal incidence).
    pub(crate) radiance: Vec3,
    /// Solid-angle pdf including the pick (for delta lights: the pick alone).
    pub(crate) pdf: f32,
    /// A delta light: no BSDF-sampled ray can find it, so no MIS.
    pub(crate) delta: bool,
    /// Its light group (scene::passes; 0 without groups).
    pub(crate) group: u16,
    /// The chance its group of [`LightGroup`] was picked (part of `pdf`).
    pub(crate) chance: f32,
    /// The light's index in the sampler's sources (render::atmosphere's
    /// equiangular sampling weighs it again at another point).
    pub(crate) source: u32,
}

impl LightSample {
    /// A sample of a light at infinity (the sun, the dome) towards `wi`;
    /// its group and source are the sampler's to fill in.
    fn at_infinity(wi: Vec3, radiance: Vec3, pdf: f32, delta: bool) -> LightSample {
        LightSample { wi, distance: f32::INFINITY, radiance, pdf, delta, group: 0, chance: 1.0, source: 0 }
    }
}

/// Where a ray meets a sized light (rect, disk, sphere).
#[derive(Clone, Copy, Debug)]
pub(crate) struct AreaHit {
    /// Ray distance.
    pub(crate) t: f32,
    /// Emitted radiance towards the ray.
    pub(crate) radiance: Vec3,
    /// Solid-angle pdf of the light's own sampling of this point, including the pick.
    pub(crate) pdf: f32,
    /// Its light group.
    pub(crate) group: u16,
}

/// The two groups of lights that next-event estimation samples apart
/// (the module's comment says why).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum LightGroup {
    /// Suns: the shot's sun, distant lights and the dome's own sun.
    Sun,
    /// The dome (but its sun).
    Sky,
    /// Point, spot, rect, disk and sphere lights and emissive triangles.
    Local,
}

impl LightGroup {
    const ALL: [LightGroup; 3] = [LightGroup::Sun, LightGroup::Sky, LightGroup::Local];

    fn of(source: &Source<'_>) -> LightGroup {
        match source {
            Source::Distant(_) | Source::Dome(DomePart::Sun) => LightGroup::Sun,
            Source::Dome(DomePart::Rest) => LightGroup::Sky,
            Source::Local(_) | Source::Triangle(_) => LightGroup::Local,
        }
    }
}

/// Groups of local lights up to this size pick by what each light gives
/// the shading point ([`Reach`]); larger ones by a light tree, so the
/// pick's cost does not grow with the number of lights.
const SHADED_PICK_MAX: usize = 16;

/// Up to this many point, spot and sphere lights, equiangular sampling in
/// the air picks one by what it gives the whole ray part, light by light;
/// past it by the light tree at one point of the part (render::atmosphere).
const SEGMENT_PICK_MAX: usize = 16;

/// The share of the group pick spread evenly over the groups that can
/// light a shading point (the rest follows their bounds): the bounds do not
/// see shadows, so a shadowed point still samples its sky.
const EVEN_SHARE: f64 = 0.1;

/// What a local light can give a shading point, for the pick in a small
/// group: a bound on its unshadowed irradiance there (luminance), zero only
/// where it cannot light the point at all.
#[derive(Clone, Copy, Debug)]
enum Reach {
    /// A point or spot light: intensity (and the spot's cone).
    Delta { centre: Vec3, intensity: f64, spot: Option<(Vec3, f32, f32)> },
    /// A rect, disk or emissive triangle: its bounding sphere, the emitting
    /// side's normal and radiance x area.
    Planar { centre: Vec3, radius: f32, normal: Vec3, two_sided: bool, intensity: f64 },
    /// A sphere light: radiance x its disc's area.
    Sphere { centre: Vec3, radius: f32, intensity: f64 },
}

/// The cosine between a receiver's normal `n` and unit direction `w`
/// towards a light; 1 for `n` zero, a point in the air (render::atmosphere),
/// which light reaches from every side.
#[inline]
fn facing(n: Vec3, w: Vec3) -> f32 {
    if n == Vec3::ZERO {
        1.0
    } else {
        n.dot(w)
    }
}

/// cos(max(0, theta - theta_u)) clamped at 0, for cos theta = `cos` and
/// the half angle theta_u (its sine and cosine) a bounding sphere subtends.
fn widened(cos: f32, sin_u: f32, cos_u: f32) -> f32 {
    let cos = cos.clamp(-1.0, 1.0);
    if cos >= cos_u {
        return 1.0;
    }
    let sin = (1.0 - cos * cos).max(0.0).sqrt();
    (cos * cos_u + sin * sin_u).max(0.0)
}

impl Reach {
    fn of_local(light: &Light) -> Option<Reach> {
        let (l32, l) = (luminance(light.emission), power_luminance(light.emission));
        let centre = light.position();
        let m = &light.world_from_light;
        let planar = |corners: &[Vec2], area: f32| {
            let radius = corners
                .iter()
                .map(|c| (m.transform_point3(Vec3::new(c.x, c.y, 0.0)) - centre).length())
                .fold(0.0f32, f32::max);
            Reach::Planar {
                centre,
                radius: pad(radius),
                normal: light.facing(),
                two_sided: light.two_sided,
                intensity: f32_or_wide(l32 * area, || l * area as f64),
            }
        };
        Some(match light.kind {
            LightKind::Point => Reach::Delta { centre, intensity: l, spot: None },
            LightKind::Spot { outer, blend } => {
                Reach::Delta { centre, intensity: l, spot: Some((light.facing(), outer, blend)) }
            }
            LightKind::Rect { size } => {
                let h = 0.5 * size;
                planar(&[Vec2::new(h.x, h.y), Vec2::new(-h.x, h.y), Vec2::new(h.x, -h.y), -h], size.x * size.y)
            }
            LightKind::Disk { radius } => {
                let r = radius;
                planar(&[Vec2::new(r, 0.0), Vec2::new(-r, 0.0), Vec2::new(0.0, r), Vec2::new(0.0, -r)], PI * r * r)
            }
            LightKind::Sphere { radius } => Reach::Sphere {
                centre,
                radius,
                intensity: f32_or_wide(l32 * PI * radius * radius, || l * (PI * radius * radius) as f64),
            },
            LightKind::Distant { .. } => return None,
        })
    }

    fn of_triangle(tri: &Triangle, emission: Vec3) -> Reach {
        let centre = (tri.p[0] + tri.p[1] + tri.p[2]) / 3.0;
        let radius = tri.p.iter().map(|q| (*q - centre).length()).fold(0.0f32, f32::max);
        let intensity = if tri.n == Vec3::ZERO || !(tri.area > 0.0) {
            0.0
        } else {
            f32_or_wide(luminance(emission) * tri.area, || power_luminance(emission) * tri.area as f64)
        };
        Reach::Planar { centre, radius: pad(radius), normal: tri.n, two_sided: false, intensity }
    }

    /// The light's bounds for a light tree: the same intensity, so a
    /// tree's importance is on the scale of [`Reach::weight`].
    fn bounds(&self) -> LightBounds {
        let pi = std::f32::consts::PI;
        let sphere = |centre: Vec3, radius: f32| (centre - Vec3::splat(radius), centre + Vec3::splat(radius));
        match *self {
            Reach::Delta { centre, intensity, spot } => {
                let (axis, cos_o, cos_e) = match spot {
                    // A narrow margin past the edge: zero outside the cone.
                    Some((facing, outer, _)) => (facing, outer.min(pi).cos(), 1e-3f32.cos()),
                    None => (Vec3::Z, -1.0, 0.0),
                };
                LightBounds { lo: centre, hi: centre, phi: intensity, axis, cos_o, cos_e, two_sided: false }
            }
            Reach::Planar { centre, radius, normal, two_sided, intensity } => {
                let (lo, hi) = sphere(centre, radius);
                LightBounds { lo, hi, phi: intensity, axis: normal, cos_o: 1.0, cos_e: 0.0, two_sided }
            }
            Reach::Sphere { centre, radius, intensity } => {
                let (lo, hi) = sphere(centre, radius);
                LightBounds { lo, hi, phi: intensity, axis: Vec3::Z, cos_o: -1.0, cos_e: 0.0, two_sided: false }
            }
        }
    }

    /// The pick's weight at a shading point `p` with geometric normal `n`
    /// (what next-event estimation and BSDF rays leave from): intensity x
    /// the emitter's and receiver's cosines, each widened by the half angle
    /// of the light's bounding sphere, / distance^2 (no nearer than the
    /// sphere's radius). Zero only where the light gives `p` nothing: below
    /// its horizon, behind a one-sided light, outside a spot's cone.
    fn weight(&self, p: Vec3, n: Vec3) -> f64 {
        match *self {
            Reach::Delta { centre, intensity, spot } => {
                let d = centre - p;
                let dist2 = d.length_squared();
                if !(dist2 > 0.0) {
                    return 0.0;
                }
                let dist = dist2.sqrt();
                let cos = if n == Vec3::ZERO { 1.0 } else { d.dot(n) / dist };
                if !(cos > 0.0) {
                    return 0.0;
                }
                let cone = spot.map_or(1.0, |(facing, outer, blend)| spot_falloff(-d.dot(facing) / dist, outer, blend));
                intensity * cone as f64 * cos as f64 / dist2 as f64
            }
            Reach::Planar { centre, radius, normal, two_sided, intensity } => {
                let d = centre - p;
                let dist2 = d.length_squared();
                let dist = dist2.sqrt();
                // Height of p above the light's plane: a one-sided light lights only its front.
                let mut s = -d.dot(normal);
                if two_sided {
                    s = s.abs();
                }
                if s <= -1e-4 * (dist + radius) {
                    return 0.0;
                }
                if !(dist > radius) {
                    return intensity / (radius as f64 * radius as f64).max(1e-30);
                }
                let sin_u = radius / dist;
                let cos_u = (1.0 - sin_u * sin_u).max(0.0).sqrt();
                let emitter = widened(s / dist, sin_u, cos_u);
                let receiver = widened(if n == Vec3::ZERO { 1.0 } else { d.dot(n) / dist }, sin_u, cos_u);
                intensity * emitter as f64 * receiver as f64 / dist2 as f64
            }
            Reach::Sphere { centre, radius, intensity } => {
                let d = centre - p;
                let dist2 = d.length_squared();
                if dist2 <= radius * radius {
                    return 0.0; // inside: it does not light its interior
                }
                let dist = dist2.sqrt();
                let sin_u = radius / dist;
                let cos_u = (1.0 - sin_u * sin_u).max(0.0).sqrt();
                let cos = if n == Vec3::ZERO { 1.0 } else { d.dot(n) / dist };
                intensity * widened(cos, sin_u, cos_u) as f64 / dist2 as f64
            }
        }
    }
}

/// A bounding radius, grown a little so rounding never leaves a light's
/// edge outside it.
fn pad(radius: f32) -> f32 {
    radius * (1.0 + 1e-4) + 1e-6
}

/// One group's pick: its sources (indices into `sources`) by power, or,
/// for a small group of local lights, by each one's [`Reach`] at the
/// shading point (`reach` then holds one per source), or, for a larger
/// one, by a light tree over them (`tree`, not empty).
#[derive(Clone, Debug, Default)]
struct GroupTable {
    sources: Vec<u32>,
    table: AliasTable,
    reach: Vec<Reach>,
    tree: LightTree,
}

impl GroupTable {
    /// The shaded pick's weights at (p, n) into `w`, and their sum.
    fn weights(&self, p: Vec3, n: Vec3, w: &mut [f64; SHADED_PICK_MAX]) -> f64 {
        let mut total = 0.0;
        for (wi, r) in w.iter_mut().zip(&self.reach) {
            *wi = r.weight(p, n);
            total += *wi;
        }
        total
    }
}

/// Every light of one frame scene, ready to sample.
pub(crate) struct LightSampler<'a> {
    lib: &'a Library,
    sources: Vec<Source<'a>>,
    /// Each group's pick, in [`LightGroup::ALL`]'s order.
    tables: [GroupTable; 3],
    /// Per source, the probability its group's pick chooses it (by power;
    /// a shaded pick's group computes it per shading point).
    pmf: Vec<f32>,
    /// Per source, its place in its group's `sources`.
    slot: Vec<u32>,
    /// Each sun's bound (axis, sine and cosine of its cone's half angle,
    /// irradiance luminance), for the sun group's share of the pick.
    suns: Vec<(Vec3, f32, f32, f64)>,
    /// The dome's rest: what it gives a point (pi x its mean radiance).
    sky: f64,
    /// Per instance, the source index of its first triangle (`u32::MAX`: not emissive).
    first_triangle: Vec<u32>,
    /// The dome and the source index of each of its parts (`u32::MAX`: none).
    dome: Option<(DomeSampler, [u32; 2])>,
    dome_camera_visible: bool,
    /// Source indices of the sized lights rays can hit.
    sized: Vec<u32>,
    /// Source index of the shot's sun.
    sun: Option<(Distant, u32)>,
    /// Each source's light group, and the groups (None: not split).
    group: Vec<u16>,
    light_groups: Option<&'a LightGroups>,
    /// Source indices of the point, spot and sphere lights (equiangular
    /// sampling in the air, towards their centres).
    points: Vec<u32>,
}

/// Luminance for a light's power: the f32 sum, or, for a huge light whose
/// f32 sum overflows, the same sum in f64 (finite for any finite colour).
fn power_luminance(c: Vec3) -> f64 {
    let l = luminance(c);
    if l.is_finite() {
        l as f64
    } else {
        c.as_dvec3().dot(glam::DVec3::new(0.2126, 0.7152, 0.0722))
    }
}

/// A pick weight computed in f32 (`narrow`), as it always was, or, where
/// a huge light overflows that, in f64 (`wide`).
fn f32_or_wide(narrow: f32, wide: impl FnOnce() -> f64) -> f64 {
    if narrow.is_finite() {
        narrow as f64
    } else {
        wide()
    }
}

/// Bounding-sphere radius of the scene, for the power of lights at infinity
/// (what they deliver onto the scene: pbrt's pi r^2 L).
fn scene_radius(bounds: Option<(Vec3, Vec3)>) -> f64 {
    bounds.map_or(1.0, |(lo, hi)| (0.5 * (hi - lo).length()).max(1e-3) as f64)
}

impl<'a> LightSampler<'a> {
    /// The lights of `scene` (its `lights` and its emissive instances that
    /// bounce rays can see), with `bounds` the scene's world bounds.
    pub(crate) fn new(
        lib: &'a Library,
        scene: &'a FrameScene,
        bounds: Option<(Vec3, Vec3)>,
        light_groups: Option<&'a LightGroups>,
    ) -> LightSampler<'a> {
        let lights: &'a SceneLights = &scene.lights;
        let r = scene_radius(bounds);
        let infinite_area = PI as f64 * r * r;
        let mut sources = Vec::new();
        let mut power = Vec::new();
        let mut sun = None;
        let mut suns = Vec::new();
        if let Some(d) = lights.sun.as_ref().and_then(Distant::new) {
            sun = Some((d, sources.len() as u32));
            power.push(power_luminance(d.irradiance()) * infinite_area);
            suns.push(d.bound());
            sources.push(Source::Distant(d));
        }
        let mut dome = None;
        let mut sky = 0.0;
        if let Some(d) = &lights.dome {
            let sampler = DomeSampler::new(d.clone());
            // Each part of the dome a source: its sun and the rest.
            let mut index = [u32::MAX; 2];
            for part in sampler.parts() {
                index[part as usize] = sources.len() as u32;
                power.push(sampler.part_power(part) * infinite_area);
                sources.push(Source::Dome(part));
                // The rest's mean radiance is its power / 4 pi; a sun's
                // power is its irradiance at normal incidence.
                match part {
                    DomePart::Rest => sky = sampler.part_power(part) / 4.0,
                    DomePart::Sun => {
                        let (axis, cos_u) = sampler.sun_cone().unwrap_or((Vec3::Z, -1.0));
                        suns.push((axis, (1.0 - cos_u * cos_u).max(0.0).sqrt(), cos_u, sampler.part_power(part)));
                    }
                }
            }
            if sampler.parts().next().is_some() {
                dome = Some((sampler, index));
            }
        }
        let mut sized = Vec::new();
        let lg = |f: &dyn Fn(&LightGroups) -> u16| light_groups.map_or(0, f);
        let sun_group = lg(&|g| g.sun());
        let mut group = vec![sun_group; sources.len()];
        if let Some((_, index)) = &dome {
            for &i in index.iter().filter(|&&i| i != u32::MAX) {
                group[i as usize] = lg(&|g| g.environment());
            }
        }
        for (k, light) in lights.local.iter().enumerate() {
            group.resize(sources.len(), 0);
            let light_group = lg(&|g| g.local(k));
            if let LightKind::Distant { angular_diameter } = light.kind {
                let sun = Sun { direction: -light.facing(), angular_diameter, irradiance: light.emission };
                if let Some(d) = Distant::new(&sun) {
                    power.push(power_luminance(d.irradiance()) * infinite_area);
                    suns.push(d.bound());
                    sources.push(Source::Distant(d));
                    group.push(light_group);
                }
                continue;
            }
            let p = local_power(light, infinite_area);
            if !(p > 0.0) {
                continue;
            }
            if matches!(light.kind, LightKind::Rect { .. } | LightKind::Disk { .. } | LightKind::Sphere { .. }) {
                sized.push(sources.len() as u32);
            }
            power.push(p);
            sources.push(Source::Local(light));
            group.push(light_group);
        }
        let first_triangle = emissive_triangles(lib, scene, light_groups, &mut sources, &mut power, &mut group);
        let (tables, pmf, slot) = group_tables(lib, &sources, &power);
        let points = (0..sources.len() as u32)
            .filter(|&i| matches!(sources[i as usize], Source::Local(l) if is_equiangular(l)))
            .collect();
        LightSampler {
            lib,
            points,
            tables,
            pmf,
            slot,
            suns,
            sky,
            sources,
            first_triangle,
            dome_camera_visible: lights.dome.as_ref().is_some_and(|d| d.camera_visible),
            dome,
            sized,
            sun,
            group,
            light_groups,
        }
    }

    fn table(&self, group: LightGroup) -> &GroupTable {
        &self.tables[group as usize]
    }

    /// The shot's sun, as sampled.
    pub(crate) fn sun(&self) -> Option<&Distant> {
        self.sun.as_ref().map(|(d, _)| d)
    }

    /// Probability the pick at shading point `from` (position, geometric
    /// normal) chooses the sun (for MIS on rays that escape into it).
    pub(crate) fn sun_pick(&self, from: (Vec3, Vec3)) -> f32 {
        self.sun.map_or(0.0, |(_, i)| self.pick_at(i as usize, from))
    }

    /// A bound on the irradiance the local group gives point `p` (normal `n`).
    fn local_bound(&self, p: Vec3, n: Vec3) -> f64 {
        let t = self.table(LightGroup::Local);
        if t.sources.is_empty() {
            0.0
        } else if !t.reach.is_empty() {
            t.weights(p, n, &mut [0.0; SHADED_PICK_MAX])
        } else if !t.tree.is_empty() {
            t.tree.importance(p, n)
        } else {
            f64::MIN_POSITIVE // no bound: the even share alone
        }
    }

    /// Each group's chance of the pick at shading point `p` (geometric
    /// normal `n`), in [`LightGroup::ALL`]'s order: in proportion to a
    /// bound on the irradiance its lights can give there, with
    /// [`EVEN_SHARE`] spread evenly over the groups that can give any; all
    /// zero where none can (below every light's horizon).
    fn chances(&self, p: Vec3, n: Vec3) -> [f64; 3] {
        let sun =
            self.suns.iter().map(|&(axis, sin_u, cos_u, e)| e * widened(facing(n, axis), sin_u, cos_u) as f64).sum();
        let bound: [f64; 3] = [sun, self.sky, self.local_bound(p, n)];
        let lit = bound.iter().filter(|&&b| b > 0.0).count();
        let total: f64 = bound.iter().sum();
        let even = 1.0 / lit.max(1) as f64;
        bound.map(|b| match b > 0.0 {
            false => 0.0,
            // A bound past f64 (a light of absurd power): the groups alike.
            true if !total.is_finite() => even,
            true => (1.0 - EVEN_SHARE) * b / total + EVEN_SHARE * even,
        })
    }

    /// One light sample for a shading point at `p` with geometric normal
    /// `n`, from one distribution over every light: its group picked by
    /// `u_pick` ([`LightSampler::chances`]), then a light of the group by
    /// what is left of `u_pick`, then a point on it by `u`. `lookup`: how
    /// the dome's radiance is looked up for this shading point.
    pub(crate) fn sample_one(&self, p: Vec3, n: Vec3, u_pick: f32, u: Vec2, lookup: Lookup) -> Option<LightSample> {
        let chances = self.chances(p, n);
        let last = chances.iter().rposition(|&c| c > 0.0)?;
        let u_pick = u_pick as f64;
        let mut below = 0.0;
        let mut g = last;
        for (k, &c) in chances.iter().enumerate().take(last) {
            if c > 0.0 && u_pick < below + c {
                g = k;
                break;
            }
            below += c;
        }
        let chance = chances[g];
        let rest = ((u_pick - below) / chance).clamp(0.0, 1.0 - f64::EPSILON) as f32;
        let ls = self.sample(LightGroup::ALL[g], p, n, rest.min(1.0 - f32::EPSILON), u, lookup)?;
        let chance = chance as f32;
        Some(LightSample { pdf: ls.pdf * chance, chance, ..ls })
    }

    /// A light sample of `group` for a shading point at `p` with geometric
    /// normal `n`: the light picked by `u_pick`, a point on it by `u`.
    /// `lookup`: how the dome's radiance is looked up for this shading point.
    fn sample(&self, group: LightGroup, p: Vec3, n: Vec3, u_pick: f32, u: Vec2, lookup: Lookup) -> Option<LightSample> {
        let t = self.table(group);
        if t.sources.is_empty() {
            return None;
        }
        let (index, pick) = if !t.tree.is_empty() {
            let (slot, pmf) = t.tree.sample(p, n, u_pick)?;
            (t.sources[slot as usize] as usize, pmf as f32)
        } else if !t.reach.is_empty() {
            let mut w = [0.0; SHADED_PICK_MAX];
            let total = t.weights(p, n, &mut w);
            if !(total > 0.0) {
                return None; // no light of the group reaches p
            }
            let target = u_pick as f64 * total;
            let mut k = t.reach.len() - 1;
            while w[k] == 0.0 {
                k -= 1; // the last light with weight (one has: total > 0)
            }
            let mut sum = 0.0;
            for (i, &wi) in w.iter().enumerate().take(t.reach.len()) {
                sum += wi;
                if wi > 0.0 && target < sum {
                    k = i;
                    break;
                }
            }
            (t.sources[k] as usize, (w[k] / total) as f32)
        } else {
            let index = t.sources[if t.sources.len() > 1 { t.table.pick(u_pick) } else { 0 }] as usize;
            (index, self.pmf[index])
        };
        let group = self.group[index];
        let sample = match &self.sources[index] {
            Source::Distant(d) => {
                let wi = d.sample(u);
                let delta = d.pdf == 0.0;
                let pdf = if delta { pick } else { d.pdf * pick };
                Some(LightSample::at_infinity(wi, d.radiance, pdf, delta))
            }
            Source::Dome(part) => {
                let (dome, _) = self.dome.as_ref()?;
                let (wi, radiance, pdf) = dome.sample_part(*part, u, lookup)?;
                Some(LightSample::at_infinity(wi, radiance, pdf * pick, false))
            }
            Source::Local(light) => sample_local(light, p, u).map(|s| LightSample { pdf: s.pdf * pick, ..s }),
            Source::Triangle(tri) => {
                if let Some(st) = SphericalTriangle::new(p, &tri.p) {
                    // By solid angle: the direction, then where it meets the triangle.
                    let w = st.sample(u);
                    let v0 = tri.p[0].as_dvec3();
                    let n = tri.n.as_dvec3();
                    let t = (v0 - p.as_dvec3()).dot(n) / w.dot(n);
                    if !(t > 0.0) {
                        return None;
                    }
                    let wi = w.as_vec3();
                    let cos_l = -wi.dot(tri.n);
                    if cos_l <= 1e-6 {
                        return None;
                    }
                    let (b1, b2) = barycentrics(&tri.p, p.as_dvec3() + w * t);
                    let radiance = self.triangle_emission(tri, b1, b2);
                    return Some(LightSample {
                        wi,
                        distance: t as f32,
                        radiance,
                        pdf: pick / st.area as f32,
                        delta: false,
                        group,
                        chance: 1.0,
                        source: 0,
                    });
                }
                let su = u.x.sqrt();
                let (b1, b2) = (1.0 - su, u.y * su);
                let q = tri.p[0] * (1.0 - b1 - b2) + tri.p[1] * b1 + tri.p[2] * b2;
                let d = q - p;
                let dist2 = d.length_squared();
                let distance = dist2.sqrt();
                if !(distance > 0.0) {
                    return None;
                }
                let wi = d / distance;
                let cos_l = -wi.dot(tri.n);
                if cos_l <= 1e-6 {
                    return None;
                }
                let radiance = self.triangle_emission(tri, b1, b2);
                Some(LightSample {
                    wi,
                    distance,
                    radiance,
                    pdf: pick * dist2 / (tri.area * cos_l),
                    delta: false,
                    group,
                    chance: 1.0,
                    source: 0,
                })
            }
        };
        sample.map(|s| LightSample { group, source: index as u32, ..s })
    }

    /// The probability the pick of a shading point at `from` (its position
    /// and geometric normal, as [`LightSampler::sample_one`] took them)
    /// chooses source `index`: its group's chance times its own in the group.
    pub(crate) fn pick_at(&self, index: usize, from: (Vec3, Vec3)) -> f32 {
        let Some(group) = self.sources.get(index).map(LightGroup::of) else { return 0.0 };
        let chance = self.chances(from.0, from.1)[group as usize] as f32;
        chance * self.pick_in_group(index, from)
    }

    /// The probability the pick within its group chooses source `index` at `from`.
    fn pick_in_group(&self, index: usize, from: (Vec3, Vec3)) -> f32 {
        let t = self.table(LightGroup::of(&self.sources[index]));
        if !t.tree.is_empty() {
            return t.tree.pmf(self.slot[index], from.0, from.1) as f32;
        }
        if t.reach.is_empty() {
            return self.pmf[index];
        }
        let mut w = [0.0; SHADED_PICK_MAX];
        let total = t.weights(from.0, from.1, &mut w);
        let wi = w[self.slot[index] as usize];
        if total > 0.0 {
            (wi / total) as f32
        } else {
            0.0
        }
    }

    /// The probability the pick of a shading point at `p` (geometric normal
    /// `n`) chooses each light of `group`, in the group's order.
    #[cfg(test)]
    fn picks(&self, group: LightGroup, p: Vec3, n: Vec3) -> Vec<f32> {
        self.table(group).sources.iter().map(|&i| self.pick_in_group(i as usize, (p, n))).collect()
    }

    /// The emission of a triangle's material at barycentrics (b1, b2),
    /// with its emissive texture and alpha coverage.
    fn triangle_emission(&self, tri: &Triangle, b1: f32, b2: f32) -> Vec3 {
        let Some(m) = self.lib.materials.get(tri.material as usize) else { return Vec3::ZERO };
        match self.lib.meshes.get(tri.mesh as usize) {
            Some(mesh) => surface_emission(self.lib, m, mesh, tri.triangle, b1, b2),
            None => m.emission,
        }
    }

    /// Solid-angle pdf (including the pick) with which NEE at `from` (the
    /// ray's shading point and its geometric normal) would have chosen the
    /// point at ray distance `t` on triangle `triangle` of instance
    /// `instance`, seen at cosine `cos_l` from its normal; 0 when NEE never
    /// samples that surface.
    pub(crate) fn triangle_pdf(&self, instance: u32, triangle: u32, t: f32, cos_l: f32, from: (Vec3, Vec3)) -> f32 {
        let Some(&first) = self.first_triangle.get(instance as usize) else { return 0.0 };
        if first == u32::MAX || !(cos_l > 0.0) {
            return 0.0;
        }
        let index = first as usize + triangle as usize;
        match self.sources.get(index) {
            Some(Source::Triangle(tri)) if tri.area > 0.0 => {
                let pick = self.pick_at(index, from);
                match SphericalTriangle::new(from.0, &tri.p) {
                    Some(st) => pick / st.area as f32,
                    None => pick * t * t / (tri.area * cos_l),
                }
            }
            _ => 0.0,
        }
    }

    /// The dome's radiance in direction `d` (looked up as `lookup` says) and
    /// its NEE pdf at shading point `from` (including the pick); `None`
    /// without a dome.
    pub(crate) fn dome(&self, d: Vec3, lookup: Lookup, from: (Vec3, Vec3)) -> Option<(Vec3, f32)> {
        let (dome, index) = self.dome.as_ref()?;
        let (radiance, part, pdf) = dome.radiance_and_pdf(d, lookup);
        let source = index[part as usize];
        let pick = if source == u32::MAX { 0.0 } else { self.pick_at(source as usize, from) };
        Some((radiance, pdf * pick))
    }

    /// The light group of the sun (the shot's and a dome's own).
    pub(crate) fn sun_group(&self) -> u16 {
        self.light_groups.map_or(0, |g| g.sun())
    }

    /// The light group of the dome or uniform sky.
    pub(crate) fn environment_group(&self) -> u16 {
        self.light_groups.map_or(0, |g| g.environment())
    }

    /// The light group of material `m`'s emission.
    pub(crate) fn material_group(&self, m: u32) -> u16 {
        self.light_groups.map_or(0, |g| g.material(m))
    }

    /// Whether any point, spot or sphere light is among the sources (what
    /// equiangular sampling in the air is for: render::atmosphere).
    pub(crate) fn has_point_lights(&self) -> bool {
        !self.points.is_empty()
    }

    /// Point, spot or sphere light `source`'s centre and its weight for a
    /// ray's part `seg` (ray `origin`, `dir`): its intensity over its
    /// squared distance to the nearest point of the part (no nearer than
    /// a sphere's radius), what its in-scatter there peaks at.
    fn segment_weight(&self, source: u32, origin: Vec3, dir: Vec3, (a, b): (f32, f32)) -> (Vec3, f64) {
        let Some(Source::Local(light)) = self.sources.get(source as usize) else { return (Vec3::ZERO, 0.0) };
        let centre = light.position();
        let foot = (centre - origin).dot(dir).clamp(a, b);
        let d2 = (origin + dir * foot - centre).length_squared().max(1e-6);
        // A sphere's intensity is its radiance times its disc's area.
        let (intensity, d2) = match light.kind {
            LightKind::Sphere { radius } => (PI as f64 * (radius * radius) as f64, d2.max(radius * radius)),
            _ => (1.0, d2),
        };
        (centre, intensity * power_luminance(light.emission) / d2 as f64)
    }

    /// Whether a ray's part in the air picks its light by the local
    /// group's light tree ([`SEGMENT_PICK_MAX`]).
    fn picks_by_tree(&self) -> bool {
        self.points.len() > SEGMENT_PICK_MAX && !self.table(LightGroup::Local).tree.is_empty()
    }

    /// Whether source `index` is a point, spot or sphere light.
    fn is_point_light(&self, index: u32) -> bool {
        matches!(self.sources.get(index as usize), Some(Source::Local(l)) if is_equiangular(l))
    }

    /// A point, spot or sphere light for a ray's part `seg` in the air,
    /// picked by `u`: its source index, the chance of the pick and its
    /// centre. Up to [`SEGMENT_PICK_MAX`] of them, in proportion to
    /// [`LightSampler::segment_weight`] (linear in their number); past
    /// that by the local group's light tree at `focus`, a point of the part
    /// where its in-scatter counts most (O(log n); a pick of another kind
    /// of light is no pick).
    pub(crate) fn pick_point_light(
        &self,
        origin: Vec3,
        dir: Vec3,
        seg: (f32, f32),
        focus: Vec3,
        u: f32,
    ) -> Option<(u32, f32, Vec3)> {
        if self.picks_by_tree() {
            let t = self.table(LightGroup::Local);
            let (slot, pmf) = t.tree.sample(focus, Vec3::ZERO, u)?;
            let source = *t.sources.get(slot as usize)?;
            let Some(Source::Local(light)) = self.sources.get(source as usize) else { return None };
            return (is_equiangular(light) && pmf > 0.0).then(|| (source, pmf as f32, light.position()));
        }
        let total: f64 = self.points.iter().map(|&i| self.segment_weight(i, origin, dir, seg).1).sum();
        if !(total > 0.0 && total.is_finite()) {
            return None;
        }
        let target = u as f64 * total;
        let mut sum = 0.0;
        let mut last = None;
        for &i in &self.points {
            let (centre, w) = self.segment_weight(i, origin, dir, seg);
            if w > 0.0 {
                sum += w;
                last = Some((i, (w / total) as f32, centre));
                if target < sum {
                    break;
                }
            }
        }
        last
    }

    /// The chance [`LightSampler::pick_point_light`] picks `source` for
    /// the same ray part and `focus`, with the light's centre; `None` for a
    /// light it never picks.
    pub(crate) fn point_light_pick(
        &self,
        origin: Vec3,
        dir: Vec3,
        seg: (f32, f32),
        focus: Vec3,
        source: u32,
    ) -> Option<(f32, Vec3)> {
        if !self.is_point_light(source) {
            return None;
        }
        if self.picks_by_tree() {
            let Some(Source::Local(light)) = self.sources.get(source as usize) else { return None };
            let pmf = self.table(LightGroup::Local).tree.pmf(self.slot[source as usize], focus, Vec3::ZERO);
            return (pmf > 0.0).then(|| (pmf as f32, light.position()));
        }
        let total: f64 = self.points.iter().map(|&i| self.segment_weight(i, origin, dir, seg).1).sum();
        let (centre, w) = self.segment_weight(source, origin, dir, seg);
        (total > 0.0 && total.is_finite() && w > 0.0).then(|| ((w / total) as f32, centre))
    }

    /// Point, spot or sphere light `source` seen from `p`: the sample
    /// towards it (a sphere's point by `u`; the pick's chance not in its
    /// pdf); `None` for any other light or where it gives `p` nothing.
    pub(crate) fn point_light(&self, source: u32, p: Vec3, u: Vec2) -> Option<LightSample> {
        match self.sources.get(source as usize)? {
            Source::Local(light) if is_equiangular(light) => {
                let ls = sample_local(light, p, u)?;
                Some(LightSample { group: self.group[source as usize], source, ..ls })
            }
            _ => None,
        }
    }

    /// Whether camera rays that miss see the dome.
    pub(crate) fn dome_camera_visible(&self) -> bool {
        self.dome_camera_visible
    }

    /// The nearest sized light a ray (unit `dir`) meets before `tmax`;
    /// camera rays (`camera`) meet only those marked camera-visible (and
    /// have no pdf). `from`: the shading point the ray left and its
    /// geometric normal, where NEE's pick was made.
    pub(crate) fn hit_sized(
        &self,
        origin: Vec3,
        dir: Vec3,
        tmax: f32,
        camera: bool,
        from: (Vec3, Vec3),
    ) -> Option<AreaHit> {
        let mut best: Option<(AreaHit, usize)> = None;
        for &index in &self.sized {
            let Source::Local(light) = &self.sources[index as usize] else { continue };
            if camera && !light.camera_visible {
                continue;
            }
            let limit = best.map_or(tmax, |b| b.0.t);
            if let Some(hit) = intersect_sized(light, origin, dir, limit, from.0) {
                best = Some((AreaHit { group: self.group[index as usize], ..hit }, index as usize));
            }
        }
        let (hit, index) = best?;
        let pick = if camera { 0.0 } else { self.pick_at(index, from) };
        Some(AreaHit { pdf: hit.pdf * pick, ..hit })
    }
}

/// Adds every emissive triangle of `scene`'s instances that bounce rays can
/// see to `sources`, with its `power` and light `group`. Returns the index
/// of each instance's first triangle source (`u32::MAX` for none; empty
/// when no material emits).
fn emissive_triangles<'a>(
    lib: &Library,
    scene: &FrameScene,
    light_groups: Option<&LightGroups>,
    sources: &mut Vec<Source<'a>>,
    power: &mut Vec<f64>,
    group: &mut Vec<u16>,
) -> Vec<u32> {
    let lg = |f: &dyn Fn(&LightGroups) -> u16| light_groups.map_or(0, f);
    let mut first_triangle = Vec::new();
    if lib.materials.iter().any(|m| m.emission.max_element() > 0.0) {
        first_triangle = vec![u32::MAX; scene.instances.len()];
        for (i, inst) in scene.instances.iter().enumerate() {
            let Some(m) = lib.materials.get(inst.material as usize) else { continue };
            if inst.visibility & vis::INDIRECT == 0 || !(m.emission.max_element() > 0.0) {
                continue;
            }
            let Some(mesh) = lib.meshes.get(inst.mesh as usize) else { continue };
            let det = inst.world_from_object.matrix3.determinant();
            first_triangle[i] = sources.len() as u32;
            let material_group = lg(&|g| g.material(inst.material));
            for (t, tri) in mesh.indices.chunks_exact(3).enumerate() {
                let p = [0, 1, 2].map(|j| {
                    let k = tri[j] as usize;
                    inst.world_from_object.transform_point3(mesh.positions.get(k).copied().unwrap_or_default())
                });
                let cross = (p[1] - p[0]).cross(p[2] - p[0]);
                // glTF: a mirroring transform flips which winding is the front.
                let n = (cross * det.signum()).normalize_or_zero();
                let area = 0.5 * cross.length();
                let p_t = if n == Vec3::ZERO || !(area > 0.0) {
                    0.0
                } else {
                    PI as f64 * power_luminance(m.emission) * area as f64
                };
                power.push(p_t);
                group.push(material_group);
                sources.push(Source::Triangle(Triangle {
                    p,
                    n,
                    area,
                    mesh: inst.mesh,
                    triangle: t as u32,
                    material: inst.material,
                }));
            }
        }
    }
    first_triangle
}

/// The alias table of each group of `sources` picked by `power` (with, for
/// the local group, each light's reach, and a light tree over a large
/// one), each source's probability in its group's table and its slot there.
fn group_tables(lib: &Library, sources: &[Source<'_>], power: &[f64]) -> ([GroupTable; 3], Vec<f32>, Vec<u32>) {
    let mut tables: [GroupTable; 3] = Default::default();
    let mut pmf = vec![0.0; sources.len()];
    let mut slot = vec![0u32; sources.len()];
    for (g, group) in LightGroup::ALL.into_iter().enumerate() {
        let members: Vec<u32> =
            (0..sources.len() as u32).filter(|&i| LightGroup::of(&sources[i as usize]) == group).collect();
        let weights: Vec<f64> = members.iter().map(|&i| power[i as usize]).collect();
        let table = AliasTable::new(&weights);
        if table.pmf.is_empty() {
            continue;
        }
        for (&i, &p) in members.iter().zip(&table.pmf) {
            pmf[i as usize] = p;
        }
        for (k, &i) in members.iter().enumerate() {
            slot[i as usize] = k as u32;
        }
        let reach = if group == LightGroup::Local {
            members
                .iter()
                .map(|&i| match &sources[i as usize] {
                    Source::Local(light) => Reach::of_local(light),
                    Source::Triangle(tri) => Some(Reach::of_triangle(
                        tri,
                        lib.materials.get(tri.material as usize).map_or(Vec3::ZERO, |m| m.emission),
                    )),
                    _ => None,
                })
                .collect::<Option<Vec<Reach>>>()
                .unwrap_or_default()
        } else {
            Vec::new()
        };
        // A large group: its tree, and no reach to weigh light by light.
        let (reach, tree) = if reach.len() > SHADED_PICK_MAX {
            (Vec::new(), LightTree::new(&reach.iter().map(Reach::bounds).collect::<Vec<_>>()))
        } else {
            (reach, LightTree::default())
        };
        tables[g] = GroupTable { sources: members, table, reach, tree };
    }
    (tables, pmf, slot)
}

/// Power of a local light (luminance), for the pick.
fn local_power(light: &Light, infinite_area: f64) -> f64 {
    let l = power_luminance(light.emission);
    let pi = PI as f64;
    let sides = if light.two_sided { 2.0 } else { 1.0 };
    match light.kind {
        LightKind::Point => 4.0 * pi * l,
        LightKind::Spot { outer, blend } => {
            // The cone to halfway through its soft edge.
            let half = outer as f64 * (1.0 - 0.5 * blend as f64);
            2.0 * pi * l * (1.0 - half.cos()).max(1e-6)
        }
        LightKind::Rect { size } => pi * l * (size.x * size.y) as f64 * sides,
        LightKind::Disk { radius } => pi * l * pi * (radius * radius) as f64 * sides,
        LightKind::Sphere { radius } => pi * l * 4.0 * pi * (radius * radius) as f64,
        LightKind::Distant { .. } => l * infinite_area,
    }
}

/// Blender's spot edge (what Cycles renders for an imported glTF spot):
/// smoothstep over the outer `blend` of the cone, measured in cosines.
pub(crate) fn spot_falloff(cos_angle: f32, outer: f32, blend: f32) -> f32 {
    let cos_outer = outer.cos();
    if cos_angle <= cos_outer {
        return 0.0;
    }
    let width = (1.0 - cos_outer) * blend;
    if width <= 0.0 {
        return 1.0;
    }
    let t = ((cos_angle - cos_outer) / width).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// Samples a point, spot, rect, disk or sphere light from `p` (pdf without the pick).
/// A rect light seen from `p` as a spherical quad; `None` (sample by area)
/// where either half is outside the bounds [`SphericalTriangle::new`]
/// keeps, as for emissive triangles.
fn spherical_rect(light: &Light, size: Vec2, p: Vec3) -> Option<SphericalQuad> {
    let h = 0.5 * size;
    let corners = [Vec2::new(-h.x, -h.y), Vec2::new(h.x, -h.y), h, Vec2::new(-h.x, h.y)]
        .map(|q| light.world_from_light.transform_point3(Vec3::new(q.x, q.y, 0.0)));
    SphericalQuad::new(p, corners)
}

/// The cosine at a planar light (rect, disc) between its emitting side and
/// the way back along `wi` to the shading point; `None` where it does not
/// light that way (behind a one-sided light, or edge-on).
fn emitting_cos(light: &Light, wi: Vec3) -> Option<f32> {
    let cos = -wi.dot(light.facing());
    let cos = if light.two_sided { cos.abs() } else { cos };
    (cos > 1e-6).then_some(cos)
}

/// A sample of a rect light uniform in the solid angle it spans from `p`
/// ([`spherical_rect`]).
fn sample_spherical_rect(light: &Light, p: Vec3, u: Vec2, quad: SphericalQuad) -> Option<LightSample> {
    let centre = light.position();
    let w = quad.sample(u);
    let n = light.facing().as_dvec3();
    let t = (centre.as_dvec3() - p.as_dvec3()).dot(n) / w.dot(n);
    if !(t > 0.0 && t.is_finite()) {
        return None;
    }
    let wi = w.as_vec3();
    emitting_cos(light, wi)?;
    Some(LightSample {
        wi,
        distance: t as f32,
        radiance: light.emission,
        pdf: (1.0 / quad.area()) as f32,
        delta: false,
        group: 0,
        chance: 1.0,
        source: 0,
    })
}

/// A point or spot light: a point with no size, which no ray can hit.
fn is_point(light: &Light) -> bool {
    matches!(light.kind, LightKind::Point | LightKind::Spot { .. })
}

/// A light whose in-scatter falls off as 1 / distance^2 from a centre, so
/// equiangular sampling in the air suits it: a point, spot or sphere light.
fn is_equiangular(light: &Light) -> bool {
    is_point(light) || matches!(light.kind, LightKind::Sphere { .. })
}

fn sample_local(light: &Light, p: Vec3, u: Vec2) -> Option<LightSample> {
    let m = &light.world_from_light;
    let centre = light.position();
    match light.kind {
        LightKind::Point | LightKind::Spot { .. } => {
            let d = centre - p;
            let dist2 = d.length_squared();
            if !(dist2 > 0.0) {
                return None;
            }
            let distance = dist2.sqrt();
            let wi = d / distance;
            let mut radiance = light.emission / dist2;
            if let LightKind::Spot { outer, blend } = light.kind {
                radiance *= spot_falloff(-wi.dot(light.facing()), outer, blend);
            }
            if radiance == Vec3::ZERO {
                return None;
            }
            Some(LightSample { wi, distance, radiance, pdf: 1.0, delta: true, group: 0, chance: 1.0, source: 0 })
        }
        LightKind::Rect { .. } | LightKind::Disk { .. } => {
            if let LightKind::Rect { size } = light.kind {
                if let Some(quad) = spherical_rect(light, size, p) {
                    return sample_spherical_rect(light, p, u, quad);
                }
            }
            let (local, area) = match light.kind {
                LightKind::Rect { size } => (Vec2::new((u.x - 0.5) * size.x, (u.y - 0.5) * size.y), size.x * size.y),
                LightKind::Disk { radius } => (sample_concentric_disk(u) * radius, PI * radius * radius),
                _ => return None,
            };
            let q = m.transform_point3(Vec3::new(local.x, local.y, 0.0));
            let d = q - p;
            let dist2 = d.length_squared();
            let distance = dist2.sqrt();
            if !(distance > 0.0) {
                return None;
            }
            let wi = d / distance;
            let cos_l = emitting_cos(light, wi)?;
            Some(LightSample {
                wi,
                distance,
                radiance: light.emission,
                pdf: dist2 / (area * cos_l),
                delta: false,
                group: 0,
                chance: 1.0,
                source: 0,
            })
        }
        LightKind::Sphere { radius } => {
            let d = centre - p;
            let dc2 = d.length_squared();
            if dc2 <= radius * radius {
                return None; // inside the light: it does not light its own interior
            }
            let dc = dc2.sqrt();
            let axis = d / dc;
            let sin2_max = radius * radius / dc2;
            let cos_max = (1.0 - sin2_max).max(0.0).sqrt();
            // 1 - cos_max without cancellation for small, far spheres.
            let one_minus = sin2_max / (1.0 + cos_max);
            let cos = 1.0 - u.x * one_minus;
            let sin = (1.0 - cos * cos).max(0.0).sqrt();
            let phi = 2.0 * PI * u.y;
            let wi =
                ShadingFrame::from_normal(axis).to_world(Vec3::new(sin * phi.cos(), sin * phi.sin(), cos)).normalize();
            // The near intersection of the ray with the sphere.
            let b = wi.dot(d);
            let disc = (b * b - (dc2 - radius * radius)).max(0.0);
            let distance = (b - disc.sqrt()).max(0.0);
            Some(LightSample {
                wi,
                distance,
                radiance: light.emission,
                pdf: 1.0 / (2.0 * PI * one_minus),
                delta: false,
                group: 0,
                chance: 1.0,
                source: 0,
            })
        }
        LightKind::Distant { .. } => None,
    }
}

/// A ray against one sized light: where it meets it before `tmax`, and the
/// light's own solid-angle pdf for that point (without the pick), as its
/// sampling from `from` (the shading point the ray left) would give it.
fn intersect_sized(light: &Light, origin: Vec3, dir: Vec3, tmax: f32, from: Vec3) -> Option<AreaHit> {
    let centre = light.position();
    match light.kind {
        LightKind::Rect { .. } | LightKind::Disk { .. } => {
            let n = light.facing();
            let denom = dir.dot(n);
            if denom.abs() < 1e-9 {
                return None;
            }
            let t = (centre - origin).dot(n) / denom;
            if !(t > 1e-6 && t < tmax) {
                return None;
            }
            let cos_l = -denom; // cosine between the light's facing and the way back to the origin
            if cos_l <= 0.0 && !light.two_sided {
                return None;
            }
            let q = light.world_from_light.inverse().transform_point3(origin + dir * t);
            let area = match light.kind {
                LightKind::Rect { size } if q.x.abs() <= 0.5 * size.x && q.y.abs() <= 0.5 * size.y => size.x * size.y,
                LightKind::Disk { radius } if q.x * q.x + q.y * q.y <= radius * radius => PI * radius * radius,
                _ => return None,
            };
            let pdf = match light.kind {
                LightKind::Rect { size } => match spherical_rect(light, size, from) {
                    Some(quad) => (1.0 / quad.area()) as f32,
                    None => t * t / (area * cos_l.abs()),
                },
                _ => t * t / (area * cos_l.abs()),
            };
            Some(AreaHit { t, radiance: light.emission, pdf, group: 0 })
        }
        LightKind::Sphere { radius } => {
            let d = centre - origin;
            let dc2 = d.length_squared();
            if dc2 <= radius * radius {
                return None;
            }
            let b = dir.dot(d);
            let disc = b * b - (dc2 - radius * radius);
            if disc < 0.0 {
                return None;
            }
            let t = b - disc.sqrt();
            if !(t > 1e-6 && t < tmax) {
                return None;
            }
            let sin2_max = radius * radius / dc2;
            let one_minus = sin2_max / (1.0 + (1.0 - sin2_max).max(0.0).sqrt());
            Some(AreaHit { t, radiance: light.emission, pdf: 1.0 / (2.0 * PI * one_minus), group: 0 })
        }
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::scene::Sky;
    use crate::scene::{Camera, Instance, InstanceAgent, Material, Mesh};
    use glam::{Affine3A, Quat};

    /// A point, a spot and a 1 x 1 m emissive panel (two triangles, face
    /// down at (0, 1, 1.5)) over a floor at y = 0, as a light sampler sees them.
    fn point_spot_panel() -> (Library, FrameScene) {
        let h = 0.5;
        let panel = Mesh {
            name: "panel".into(),
            positions: [(-h, -h), (h, -h), (h, h), (-h, h)].map(|(x, z)| Vec3::new(x, 0.0, z)).to_vec(),
            normals: vec![],
            uvs: vec![],
            tangents: vec![],
            indices: vec![0, 2, 1, 0, 3, 2],
        };
        let glow = Material { name: "glow".into(), emission: Vec3::splat(3.0), ..Default::default() };
        let lib = Library { meshes: vec![panel], materials: vec![glow], textures: vec![] };
        let down = Affine3A::from_rotation_translation(Quat::from_rotation_x(PI), Vec3::new(0.0, 1.0, 1.5));
        let instances = vec![Instance {
            mesh: 0,
            material: 0,
            world_from_object: down,
            agent: InstanceAgent::NONE,
            part: 0,
            visibility: vis::ALL,
        }];
        let light = |kind, position: Vec3, aim: Vec3, emission: f32| Light {
            name: "test".into(),
            kind,
            world_from_light: crate::shot::look_at(position, aim),
            emission: Vec3::splat(emission),
            two_sided: false,
            camera_visible: false,
            light_group: None,
        };
        let lights = SceneLights {
            sun: None,
            sky: Sky { radiance: Vec3::ZERO },
            dome: None,
            local: vec![
                light(LightKind::Point, Vec3::new(1.5, 2.0, -1.0), Vec3::ZERO, 6.0),
                light(
                    LightKind::Spot { outer: 0.3, blend: 0.3 },
                    Vec3::new(-1.0, 4.0, 0.0),
                    Vec3::new(-1.0, 0.0, 0.0),
                    60.0,
                ),
            ],
            groups: Default::default(),
        };
        let camera = Camera::pinhole(Affine3A::from_translation(Vec3::new(0.0, 1.0, 5.0)), 1.0);
        (lib, FrameScene { instances, camera, lights, motion: None })
    }

    /// Irradiance (luminance) at `p` (normal `n`) from the three lights, the
    /// panel by a 300 x 300 midpoint rule.
    fn exact_irradiance(p: Vec3, n: Vec3) -> f64 {
        let delta = |c: Vec3, i: f32, cone: f32| {
            let d = c - p;
            (i * cone * (d.normalize().dot(n)).max(0.0) / d.length_squared()) as f64
        };
        let spot = Vec3::new(-1.0, 4.0, 0.0);
        let cos_axis = (p - spot).normalize().dot(-Vec3::Y);
        let mut e = delta(Vec3::new(1.5, 2.0, -1.0), 6.0, 1.0) + delta(spot, 60.0, spot_falloff(cos_axis, 0.3, 0.3));
        let k = 300;
        for i in 0..k {
            for j in 0..k {
                let q = Vec3::new(-0.5 + (i as f32 + 0.5) / k as f32, 1.0, 1.0 + (j as f32 + 0.5) / k as f32);
                let d = q - p;
                let (dist2, w) = (d.length_squared(), d.normalize());
                let (cos_l, cos_r) = (w.dot(Vec3::Y), w.dot(n));
                if cos_l > 0.0 && cos_r > 0.0 {
                    e += (3.0 * cos_l * cos_r / dist2) as f64 / (k * k) as f64;
                }
            }
        }
        e
    }

    /// Mean and variance of the one-sample NEE estimate of the local
    /// group's irradiance at `p` (no shadows), over `n` stratified samples.
    fn nee_estimate(sampler: &LightSampler<'_>, p: Vec3, normal: Vec3, n: u32) -> (f64, f64) {
        let (mut sum, mut sum2) = (0.0f64, 0.0f64);
        for k in 0..n {
            let u_pick = (k as f32 + 0.5) / n as f32;
            let u = Vec2::new(
                (k.wrapping_mul(2654435769) as f64 / 4294967296.0) as f32,
                k.reverse_bits() as f32 / 4294967296.0,
            );
            let e = sampler
                .sample(LightGroup::Local, p, normal, u_pick, u, Lookup::Bilinear)
                .map_or(0.0, |s| (luminance(s.radiance) * s.wi.dot(normal).max(0.0)) as f64 / s.pdf as f64);
            sum += e;
            sum2 += e * e;
        }
        let mean = sum / n as f64;
        (mean, sum2 / n as f64 - mean * mean)
    }

    /// Shading points on the floor (facing up) and on walls facing +X and -Z.
    fn shading_points() -> Vec<(Vec3, Vec3)> {
        let mut points = Vec::new();
        for i in 0..7 {
            for j in 0..7 {
                let p = Vec3::new(-3.0 + i as f32, 0.0, -3.0 + j as f32);
                points.push((p, Vec3::Y));
                points.push((p + Vec3::new(0.0, 0.5, 0.0), Vec3::X));
                points.push((p + Vec3::new(0.0, 0.5, 0.0), -Vec3::Z));
            }
        }
        points
    }

    #[test]
    fn the_shaded_pick_keeps_the_mean_and_cuts_the_variance() {
        let (lib, scene) = point_spot_panel();
        let bounds = Some((Vec3::splat(-5.0), Vec3::splat(5.0)));
        let shaded = LightSampler::new(&lib, &scene, bounds, None);
        assert_eq!(shaded.table(LightGroup::Local).reach.len(), 4, "point, spot, two triangles: the shaded pick");
        // The same lights picked by power alone, as large groups are.
        let mut by_power = LightSampler::new(&lib, &scene, bounds, None);
        by_power.tables[LightGroup::Local as usize].reach.clear();
        let (mut exact, mut mean_s, mut mean_p, mut var_s, mut var_p) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for (p, n) in shading_points() {
            exact += exact_irradiance(p, n);
            let (m, v) = nee_estimate(&shaded, p, n, 1024);
            mean_s += m;
            var_s += v;
            let (m, v) = nee_estimate(&by_power, p, n, 1024);
            mean_p += m;
            var_p += v;
        }
        assert!(((mean_s - exact) / exact).abs() < 0.01, "shaded pick: {mean_s} vs exact {exact}");
        assert!(((mean_p - exact) / exact).abs() < 0.01, "by power: {mean_p} vs exact {exact}");
        assert!(var_s < 0.1 * var_p, "variance: shaded {var_s} vs by power {var_p}");
    }

    /// A rect light is sampled uniformly in the solid angle it spans: each
    /// sample's pdf is the one a ray hitting that point is weighed by (MIS),
    /// the irradiance below a 2 x 1 m rect 1 m up matches the closed form,
    /// and with far less variance per sample than sampling it by area.
    /// The light tree's pick (what groups of more than
    /// [`SHADED_PICK_MAX`] lights use; here forced on four) keeps the mean
    /// and, like the shaded pick, beats picking by power.
    #[test]
    fn the_tree_pick_keeps_the_mean_and_cuts_the_variance() {
        let (lib, scene) = point_spot_panel();
        let bounds = Some((Vec3::splat(-5.0), Vec3::splat(5.0)));
        let mut tree = LightSampler::new(&lib, &scene, bounds, None);
        let local = &mut tree.tables[LightGroup::Local as usize];
        local.tree = LightTree::new(&local.reach.iter().map(Reach::bounds).collect::<Vec<_>>());
        local.reach.clear();
        let mut by_power = LightSampler::new(&lib, &scene, bounds, None);
        by_power.tables[LightGroup::Local as usize].reach.clear();
        let (mut exact, mut mean_t, mut var_t, mut var_p) = (0.0, 0.0, 0.0, 0.0);
        for (p, n) in shading_points() {
            exact += exact_irradiance(p, n);
            let (m, v) = nee_estimate(&tree, p, n, 1024);
            mean_t += m;
            var_t += v;
            var_p += nee_estimate(&by_power, p, n, 1024).1;
            // The pick's chance as MIS retraces it is the one sampling reported.
            let total: f32 = tree.picks(LightGroup::Local, p, n).iter().sum();
            assert!(total == 0.0 || (total - 1.0).abs() < 1e-5, "picks sum to {total} at {p}");
        }
        assert!(((mean_t - exact) / exact).abs() < 0.01, "tree pick: {mean_t} vs exact {exact}");
        assert!(var_t < 0.5 * var_p, "variance: tree {var_t} vs by power {var_p}");
    }

    /// One light sample from one distribution over a sun and the local
    /// lights: its mean is the irradiance of all of them, and the pdf it
    /// reports for an emissive triangle is what a BSDF ray hitting that
    /// point is weighed against (MIS).
    #[test]
    fn one_sample_over_every_light_keeps_the_mean_and_its_pdf() {
        let (lib, mut scene) = point_spot_panel();
        let sun_dir = Vec3::new(0.3, 1.0, 0.2).normalize();
        let irradiance = 0.8;
        scene.lights.sun = Some(Sun { direction: sun_dir, angular_diameter: 0.0, irradiance: Vec3::splat(irradiance) });
        let sampler = LightSampler::new(&lib, &scene, Some((Vec3::splat(-5.0), Vec3::splat(5.0))), None);
        let n_samples = 4096u32;
        let (mut exact, mut mean) = (0.0, 0.0);
        for (p, n) in shading_points() {
            exact += exact_irradiance(p, n) + (irradiance * n.dot(sun_dir).max(0.0)) as f64;
            let chances = sampler.chances(p, n);
            let total: f64 = chances.iter().sum();
            // Zero where no light can reach the point (then no sample).
            assert!(total == 0.0 || (total - 1.0).abs() < 1e-9, "chances sum to {total}");
            for k in 0..n_samples {
                let u_pick = (k as f32 + 0.5) / n_samples as f32;
                let u = Vec2::new(
                    (k.wrapping_mul(2654435769u32) as f64 / 4294967296.0) as f32,
                    k.reverse_bits() as f32 / 4294967296.0,
                );
                let Some(s) = sampler.sample_one(p, n, u_pick, u, Lookup::Bilinear) else { continue };
                mean += (luminance(s.radiance) * s.wi.dot(n).max(0.0)) as f64 / s.pdf as f64 / n_samples as f64;
                if !s.delta {
                    // Only the panel's triangles (at y = 1) are not delta lights here:
                    // one of them is what a ray along wi meets, at `distance`.
                    assert!((p.y + s.wi.y * s.distance - 1.0).abs() < 1e-3);
                    let mis = [0, 1].map(|t| sampler.triangle_pdf(0, t, s.distance, s.wi.y.abs(), (p, n)));
                    let close = |a: f32| (a - s.pdf).abs() <= 1e-3 * s.pdf;
                    assert!(mis.into_iter().any(close), "pdf {} vs MIS {mis:?}", s.pdf);
                }
            }
        }
        assert!(((mean - exact) / exact).abs() < 0.01, "one sample: {mean} vs exact {exact}");
    }

    #[test]
    fn a_rect_light_is_sampled_by_solid_angle() {
        let light = Light {
            name: "rect".into(),
            kind: LightKind::Rect { size: Vec2::new(2.0, 1.0) },
            world_from_light: crate::shot::look_at(Vec3::new(0.0, 1.0, 0.0), Vec3::ZERO),
            emission: Vec3::ONE,
            two_sided: false,
            camera_visible: false,
            light_group: None,
        };
        let (p, n) = (Vec3::ZERO, Vec3::Y);
        assert!(spherical_rect(&light, Vec2::new(2.0, 1.0), p).is_some());
        let count = 4096u32;
        let (mut solid, mut area) = (Vec::new(), Vec::new());
        for k in 0..count {
            let u = Vec2::new((k as f32 + 0.5) / count as f32, k.reverse_bits() as f32 / 4294967296.0);
            let s = sample_local(&light, p, u).expect("below the rect every sample lights p");
            let hit = intersect_sized(&light, p, s.wi, f32::INFINITY, p).expect("the sample's ray meets the rect");
            assert!((hit.pdf - s.pdf).abs() <= 1e-4 * s.pdf, "sampled pdf {} vs hit's {}", s.pdf, hit.pdf);
            assert!((hit.t - s.distance).abs() <= 1e-4, "distance {} vs {}", s.distance, hit.t);
            solid.push((s.wi.dot(n) / s.pdf) as f64);
            // The same point by area, as the rect was sampled before.
            let q = Vec3::new((u.x - 0.5) * 2.0, 1.0, u.y - 0.5);
            let d = q - p;
            let wi = d.normalize();
            area.push((wi.dot(n) * wi.y * 2.0 / d.length_squared()) as f64);
        }
        let stats = |v: &[f64]| {
            let mean = v.iter().sum::<f64>() / v.len() as f64;
            (mean, v.iter().map(|x| (x - mean) * (x - mean)).sum::<f64>() / v.len() as f64)
        };
        let ((mean_s, var_s), (mean_a, var_a)) = (stats(&solid), stats(&area));
        // Four corner pieces of a 1 x 0.5 m rectangle seen from 1 m (the form factor).
        let (x, y) = (1.0f64, 0.5f64);
        let f = (x / (1.0 + x * x).sqrt() * (y / (1.0 + x * x).sqrt()).atan()
            + y / (1.0 + y * y).sqrt() * (x / (1.0 + y * y).sqrt()).atan())
            / (2.0 * std::f64::consts::PI);
        let exact = 4.0 * std::f64::consts::PI * f;
        assert!(((mean_s - exact) / exact).abs() < 2e-3, "by solid angle {mean_s} vs exact {exact}");
        assert!(((mean_a - exact) / exact).abs() < 2e-3, "by area {mean_a} vs exact {exact}");
        assert!(var_s < 0.2 * var_a, "variance per sample: by solid angle {var_s}, by area {var_a}");
    }

    #[test]
    fn a_triangle_samples_pdf_is_what_a_ray_hitting_it_is_weighed_by() {
        let (lib, scene) = point_spot_panel();
        let sampler = LightSampler::new(&lib, &scene, Some((Vec3::splat(-5.0), Vec3::splat(5.0))), None);
        let (mut spherical, mut by_area) = (0, 0);
        for (p, n) in shading_points() {
            for k in 0..64u32 {
                let u = Vec2::new((k as f32 + 0.5) / 64.0, k.reverse_bits() as f32 / 4294967296.0);
                let u_pick = ((k * 37) % 64) as f32 / 64.0 + 0.01;
                let Some(s) = sampler.sample(LightGroup::Local, p, n, u_pick, u, Lookup::Bilinear) else { continue };
                if s.delta {
                    continue;
                }
                // Which of the panel's triangles the direction meets.
                let hit = scene.instances[0].world_from_object;
                let mesh = &lib.meshes[0];
                let tri = (0..2u32).find(|&t| {
                    let v = [0, 1, 2]
                        .map(|j| hit.transform_point3(mesh.positions[mesh.indices[(3 * t + j) as usize] as usize]));
                    let (b1, b2) = barycentrics(&v, (p + s.wi * s.distance).as_dvec3());
                    let q = v[0] * (1.0 - b1 - b2) + v[1] * b1 + v[2] * b2;
                    (q - (p + s.wi * s.distance)).length() < 1e-3
                });
                let Some(tri) = tri else { continue };
                let pdf = sampler.triangle_pdf(0, tri, s.distance, -s.wi.dot(Vec3::NEG_Y), (p, n));
                assert!((pdf - s.pdf).abs() <= 1e-3 * s.pdf, "{p} {n}: sampled pdf {} vs hit's {pdf}", s.pdf);
                if SphericalTriangle::new(
                    p,
                    &[0, 1, 2]
                        .map(|j| hit.transform_point3(mesh.positions[mesh.indices[(3 * tri + j) as usize] as usize])),
                )
                .is_some()
                {
                    spherical += 1;
                } else {
                    by_area += 1;
                }
            }
        }
        // (From this close the panel is sampled by solid angle throughout.)
        assert!(spherical > 1000, "{spherical} by solid angle, {by_area} by area");
    }

    #[test]
    fn shaded_picks_sum_to_one_and_skip_lights_that_cannot_reach() {
        let (lib, scene) = point_spot_panel();
        let sampler = LightSampler::new(&lib, &scene, Some((Vec3::splat(-5.0), Vec3::splat(5.0))), None);
        for (p, n) in shading_points() {
            let picks = sampler.picks(LightGroup::Local, p, n);
            let sum: f32 = picks.iter().sum();
            assert!((sum - 1.0).abs() < 1e-5 || sum == 0.0, "{p} {n}: picks {picks:?}");
            // The group's order: point, spot, the panel's two triangles.
            let spot = Vec3::new(-1.0, 4.0, 0.0);
            if spot_falloff((p - spot).normalize().dot(-Vec3::Y), 0.3, 0.3) == 0.0 {
                assert_eq!(picks[1], 0.0, "{p} {n}: the spot's cone does not reach");
            }
            if p.z <= 0.0 && n == -Vec3::Z {
                assert_eq!(&picks[2..], [0.0, 0.0], "{p} {n}: behind the panel's horizon");
            }
        }
        // Under the floor, facing down, nothing reaches.
        assert_eq!(sampler.picks(LightGroup::Local, Vec3::new(0.0, -1.0, 0.0), -Vec3::Y), [0.0; 4]);
        assert!(sampler
            .sample(LightGroup::Local, Vec3::new(0.0, -1.0, 0.0), -Vec3::Y, 0.5, Vec2::splat(0.5), Lookup::Bilinear)
            .is_none());
    }

    #[test]
    fn spot_edge_is_blenders_smoothstep() {
        let outer = 0.5f32;
        assert_eq!(spot_falloff(1.0, outer, 0.2), 1.0);
        assert_eq!(spot_falloff(outer.cos() - 1e-4, outer, 0.2), 0.0);
        assert_eq!(spot_falloff((outer - 0.01).cos(), outer, 0.0), 1.0);
        let mid = outer.cos() + 0.5 * (1.0 - outer.cos()) * 0.2;
        assert!((spot_falloff(mid, outer, 0.2) - 0.5).abs() < 1e-5);
    }
}
