//! The shot's atmosphere: a homogeneous participating medium (haze, fog)
//! filling the half-space below a height, so sun and dome light still
//! reach into it from above (an infinite medium would put them out: no
//! light from infinity crosses infinite air). One density for every
//! channel (grey extinction) and a coloured single-scattering albedo, so
//! distance sampling by the transmittance is exact and a path that passes
//! through keeps its throughput: only a scattering event weighs it, by
//! the albedo (pbrt-v4's and Mitsuba's volumetric path tracers, reduced to
//! a grey homogeneous medium).
//!
//! Sampling tools the integrator combines: distance sampling
//! ([`Atmosphere::sample_distance`]), equiangular sampling towards a point
//! light ([`Equiangular`], Kulla and Fajardo 2012, "Importance Sampling
//! Techniques for Path Tracing in Participating Media") and the
//! Henyey-Greenstein phase function ([`phase_hg`], [`sample_hg`]).
//!
//! With a height falloff the density is constant up to `base` and
//! exponential in height above it, so along any ray it is at most two
//! pieces, each constant or exponential in the distance: the optical depth
//! is a closed form per piece and distance sampling inverts it exactly
//! (no majorant, no null collisions). A start distance clips camera rays'
//! part in the air ([`Atmosphere::camera_segment`]).

use std::f32::consts::PI;

use glam::{Vec2, Vec3};

use super::bsdf::ShadingFrame;

pub use crate::scene::atmosphere::{Atmosphere, AtmosphereMode, MAX_DENSITY};

impl Atmosphere {
    /// Whether it changes anything (a density above zero).
    pub(crate) fn is_active(&self) -> bool {
        self.density > 0.0
    }

    /// Scattering coefficient per channel where the air is densest (at
    /// and below `base`), 1/m.
    pub(crate) fn scattering(&self) -> Vec3 {
        self.albedo * self.density
    }

    /// Whether the density falls with height.
    fn thins(&self) -> bool {
        self.falloff.is_finite()
    }

    /// Extinction at world height `y`, 1/m.
    pub(crate) fn density_at(&self, y: f32) -> f32 {
        if self.thins() && y > self.base {
            self.density * (-(y - self.base) / self.falloff).exp()
        } else {
            self.density
        }
    }

    /// Scattering coefficient per channel at world point `p`, 1/m.
    pub(crate) fn scattering_at(&self, p: Vec3) -> Vec3 {
        self.albedo * self.density_at(p.y)
    }

    /// The ray's part `[a, b)` in the air cut into the stretches where the
    /// density is one closed form: below `base` and above it.
    fn pieces(&self, origin: Vec3, dir: Vec3, a: f32, b: f32) -> impl Iterator<Item = Piece> + '_ {
        let cross = (self.base - origin.y) / dir.y; // NaN or infinite for a level ray: no split
        let ranges = if cross > a && cross < b { [(a, cross), (cross, b)] } else { [(a, b), (b, b)] };
        let k = dir.y / self.falloff;
        ranges.into_iter().filter(|(p, q)| p < q).map(move |(p, q)| {
            let mid = if q.is_finite() { 0.5 * (p + q) } else { p + 1.0 };
            if origin.y + dir.y * mid > self.base {
                // At its start (the crossing rounded onto the base at most).
                let y = (origin.y + dir.y * p).max(self.base);
                Piece { a: p, b: q, rho: self.density_at(y), k }
            } else {
                Piece { a: p, b: q, rho: self.density, k: 0.0 }
            }
        })
    }

    /// The optical depth of the ray `origin + t dir` over `a <= t < b`, all in the air.
    fn optical_depth(&self, origin: Vec3, dir: Vec3, a: f32, b: f32) -> f32 {
        if !self.thins() {
            return self.density * (b - a);
        }
        self.pieces(origin, dir, a, b).map(|p| p.depth()).sum()
    }

    /// The optical depth straight up from height `y` to the top of the air.
    fn depth_above(&self, y: f32) -> f32 {
        if y >= self.top {
            return 0.0;
        }
        let up = Vec3::new(0.0, y, 0.0);
        self.optical_depth(up, Vec3::Y, 0.0, self.top - y)
    }

    /// Where on the ray's part `seg` in the air a light's in-scatter counts
    /// most, for picking lights by a tree (render::lights): a mean free
    /// path in (where the transmittance is 1/e), or the part's middle if
    /// that is nearer.
    pub(crate) fn focus(&self, origin: Vec3, dir: Vec3, (a, b): (f32, f32)) -> Vec3 {
        let free = 1.0 / self.density_at(origin.y + dir.y * a);
        let t = if b.is_finite() { a + free.min(0.5 * (b - a)) } else { a + free };
        origin + dir * t
    }

    /// The part of a camera ray in the air: [`Atmosphere::segment`] past
    /// the start distance, so the foreground stays clear.
    pub(crate) fn camera_segment(&self, origin: Vec3, dir: Vec3, tmax: f32) -> Option<(f32, f32)> {
        let (a, b) = self.segment(origin, dir, tmax)?;
        let a = a.max(self.start);
        (a < b).then_some((a, b))
    }

    /// [`Atmosphere::transmittance`] of a camera ray (past the start distance).
    pub(crate) fn camera_transmittance(&self, origin: Vec3, dir: Vec3, tmax: f32) -> f32 {
        self.camera_segment(origin, dir, tmax).map_or(1.0, |seg| self.transmittance_over(origin, dir, seg))
    }

    /// The transmittance of the ray `origin + t dir` over its part `seg` in the air.
    pub(crate) fn transmittance_over(&self, origin: Vec3, dir: Vec3, (a, b): (f32, f32)) -> f32 {
        optical(self.optical_depth(origin, dir, a, b))
    }

    /// The part `[a, b)` of the ray `origin + t dir`, `0 <= t < tmax`,
    /// inside the air (`b` may be +inf); `None` where the ray stays above it.
    pub(crate) fn segment(&self, origin: Vec3, dir: Vec3, tmax: f32) -> Option<(f32, f32)> {
        if !self.is_active() {
            return None;
        }
        let (a, b) = if origin.y < self.top {
            let b = if dir.y > 0.0 { (self.top - origin.y) / dir.y } else { f32::INFINITY };
            (0.0, b)
        } else if dir.y < 0.0 {
            ((self.top - origin.y) / dir.y, f32::INFINITY)
        } else {
            return None;
        };
        let b = b.min(tmax);
        (a < b).then_some((a, b))
    }

    /// The fraction of light left after the ray `origin + t dir` runs
    /// `0 <= t < tmax` (Beer-Lambert over its part in the air).
    pub(crate) fn transmittance(&self, origin: Vec3, dir: Vec3, tmax: f32) -> f32 {
        match self.segment(origin, dir, tmax) {
            Some(seg) => self.transmittance_over(origin, dir, seg),
            None => 1.0,
        }
    }

    /// Distance sampling over the part `[a, b)` in the air of the ray
    /// `origin + t dir`: the distance of the first scattering or absorption
    /// event, drawn with its probability density `sigma(t) exp(-tau(a, t))`
    /// (sigma the density there, tau the optical depth), or `None` (the ray
    /// passes, with probability the transmittance). Grey extinction makes
    /// the weight of either outcome exact: the albedo for an event, 1 for
    /// passing.
    pub(crate) fn sample_distance(&self, origin: Vec3, dir: Vec3, (a, b): (f32, f32), u: f32) -> Option<f32> {
        if !self.thins() {
            // -ln(1 - u) from 1 - u in (0, 1]: finite for every u < 1.
            let t = a - (1.0 - u).max(f32::MIN_POSITIVE).ln() / self.density;
            return (t < b).then_some(t);
        }
        // The optical depth the event comes at, found piece by piece.
        let mut left = -(1.0 - u).max(f32::MIN_POSITIVE).ln();
        for piece in self.pieces(origin, dir, a, b) {
            let depth = piece.depth();
            if left < depth {
                let t = piece.invert(left);
                return (t < b).then_some(t);
            }
            left -= depth;
        }
        None
    }

    /// The density [`Atmosphere::sample_distance`] draws `t` in `[a, b)` with.
    pub(crate) fn distance_pdf(&self, origin: Vec3, dir: Vec3, (a, _): (f32, f32), t: f32) -> f32 {
        if !self.thins() {
            return self.density * optical(self.density * (t - a));
        }
        self.density_at(origin.y + dir.y * t) * optical(self.optical_depth(origin, dir, a, t))
    }
}

impl Atmosphere {
    /// Haze only ([`AtmosphereMode::Haze`]), in closed form along the
    /// ray's part `seg` in the air (ray `origin`, `dir`): the light the air
    /// scatters into it from a sun of irradiance `sun_irradiance` towards
    /// unit `sun_dir` and from a uniform environment of radiance
    /// `environment`, each reaching a point through the air above it as if
    /// nothing shadowed it (the environment along the vertical). Returns
    /// the sun's and the environment's shares.
    pub(crate) fn haze_in_scatter(
        &self,
        origin: Vec3,
        dir: Vec3,
        (a, b): (f32, f32),
        sun: Option<(Vec3, Vec3)>,
        environment: Vec3,
    ) -> (Vec3, Vec3) {
        if self.thins() {
            return self.haze_by_quadrature(origin, dir, (a, b), sun, environment);
        }
        // Light from above arriving at a point of height y: exp(-density
        // (top - y) / cos), cos the sine of its elevation. Along the ray
        // that is exp(-density h(a) / cos) exp(density u dir.y / cos) at
        // u = t - a past the entry, so the integral over u is of one exponential.
        let from_above = |cos: f32| -> f32 {
            if !(cos > 0.0) || !self.top.is_finite() {
                return 0.0;
            }
            let h = (self.top - (origin.y + a * dir.y)).max(0.0);
            let k = self.density * (1.0 - dir.y / cos);
            let len = b - a;
            let integral = if (k * len).abs() < 1e-4 {
                len * (1.0 - 0.5 * k * len)
            } else if len.is_finite() {
                -(-k * len).exp_m1() / k
            } else {
                1.0 / k // len infinite only looking down or level: k > 0
            };
            (-self.density * h / cos).exp() * integral
        };
        let sigma_s = self.scattering();
        let sun = sun.map_or(Vec3::ZERO, |(to_sun, irradiance)| {
            sigma_s * irradiance * phase_hg(dir.dot(to_sun), self.anisotropy) * from_above(to_sun.y)
        });
        // The environment: the phase function integrates to 1 over the sphere.
        let environment = sigma_s * environment * from_above(1.0);
        (sun, environment)
    }
}

/// Points of the quadrature of haze only's in-scatter in air that thins
/// with height: the integrand is smooth in the transmittance.
const HAZE_STEPS: u32 = 32;

impl Atmosphere {
    /// [`Atmosphere::haze_in_scatter`] where the air thins with height: no
    /// closed form, so a midpoint rule in the share of light the air has
    /// taken out along the ray, `u = 1 - T(a, t)`: sigma_s(t) T(a, t) dt =
    /// albedo du, so the in-scatter is the albedo times the mean over `u`
    /// of what reaches the point at `t(u)` (distance sampling's inversion),
    /// times the share taken out over the whole part. Finite for any part,
    /// infinite ones included.
    fn haze_by_quadrature(
        &self,
        origin: Vec3,
        dir: Vec3,
        seg: (f32, f32),
        sun: Option<(Vec3, Vec3)>,
        environment: Vec3,
    ) -> (Vec3, Vec3) {
        let taken = 1.0 - self.transmittance_over(origin, dir, seg);
        let (mut to_sun, mut from_sky) = (0.0f32, 0.0f32);
        for i in 0..HAZE_STEPS {
            let u = (i as f32 + 0.5) / HAZE_STEPS as f32 * taken;
            let Some(t) = self.sample_distance(origin, dir, seg, u) else { continue };
            let above = self.depth_above(origin.y + dir.y * t);
            if let Some((s, _)) = sun.filter(|(s, _)| s.y > 0.0) {
                to_sun += optical(above / s.y);
            }
            from_sky += optical(above);
        }
        let scale = self.albedo * (taken / HAZE_STEPS as f32);
        let sun = sun
            .map_or(Vec3::ZERO, |(s, irradiance)| scale * irradiance * phase_hg(dir.dot(s), self.anisotropy) * to_sun);
        (sun, scale * environment * from_sky)
    }
}

/// A stretch `[a, b)` of a ray where the density is one closed form:
/// `rho exp(-k (t - a))` (`k` = 0: constant; `k` = dir.y / falloff above
/// the base, where the density falls with height).
#[derive(Clone, Copy, Debug)]
struct Piece {
    a: f32,
    b: f32,
    rho: f32,
    k: f32,
}

impl Piece {
    /// Its optical depth (infinite for an endless stretch that does not thin).
    fn depth(&self) -> f32 {
        let len = self.b - self.a;
        if self.k == 0.0 {
            return self.rho * len;
        }
        if !len.is_finite() {
            return if self.k > 0.0 { self.rho / self.k } else { f32::INFINITY };
        }
        let x = self.k * len;
        if x.abs() < 1e-4 {
            self.rho * len * (1.0 - 0.5 * x)
        } else {
            -self.rho * (-x).exp_m1() / self.k
        }
    }

    /// Where along the ray the optical depth from `a` reaches `tau`
    /// (less than [`Piece::depth`]).
    fn invert(&self, tau: f32) -> f32 {
        if self.k == 0.0 {
            return self.a + tau / self.rho;
        }
        // rho (1 - e^(-k s)) / k = tau.
        let x = self.k * tau / self.rho;
        if x.abs() < 1e-4 {
            self.a + tau / self.rho * (1.0 + 0.5 * x)
        } else {
            self.a - (-x).ln_1p() / self.k
        }
    }
}

/// The mean radiance of a dome over the sphere (texels weighed by the
/// solid angle they cover), scaled: the uniform environment haze only
/// scatters.
pub(crate) fn mean_radiance(dome: &crate::scene::lights::Dome) -> Vec3 {
    let (w, h) = (dome.width as usize, dome.height as usize);
    if w == 0 || h == 0 || dome.texels.len() < w * h {
        return Vec3::ZERO;
    }
    let (mut sum, mut weight) = (glam::DVec3::ZERO, 0.0f64);
    for (row, texels) in dome.texels.chunks_exact(w).take(h).enumerate() {
        let sin = ((row as f64 + 0.5) / h as f64 * std::f64::consts::PI).sin();
        // Negative texels clamped, as the dome's sampler clamps them.
        let row_sum: glam::DVec3 = texels.iter().map(|t| t.as_dvec3().max(glam::DVec3::ZERO)).sum();
        sum += row_sum * sin;
        weight += sin * w as f64;
    }
    (sum / weight).as_vec3() * dome.scale
}

/// exp(-tau), 0 at tau = +inf.
#[inline]
fn optical(tau: f32) -> f32 {
    if tau.is_finite() {
        (-tau).exp()
    } else {
        0.0
    }
}

/// The Henyey-Greenstein phase function for the cosine between the
/// direction light travelled and the direction it leaves in (per
/// steradian: it integrates to 1 over the sphere).
#[inline]
pub(crate) fn phase_hg(cos: f32, g: f32) -> f32 {
    let denom = 1.0 + g * g - 2.0 * g * cos;
    (1.0 - g * g) / (4.0 * PI * denom * denom.max(1e-12).sqrt())
}

/// A direction drawn from the Henyey-Greenstein lobe about `dir` (the way
/// the ray travelled), with its density [`phase_hg`] (pbrt-v4's
/// SampleHenyeyGreenstein, in this crate's convention).
pub(crate) fn sample_hg(dir: Vec3, g: f32, u: Vec2) -> (Vec3, f32) {
    let cos = if g.abs() < 1e-3 {
        1.0 - 2.0 * u.x
    } else {
        let s = (1.0 - g * g) / (1.0 + g - 2.0 * g * u.x);
        ((1.0 + g * g - s * s) / (2.0 * g)).clamp(-1.0, 1.0)
    };
    let sin = (1.0 - cos * cos).max(0.0).sqrt();
    let phi = 2.0 * PI * u.y;
    let wi = ShadingFrame::from_normal(dir).to_world(Vec3::new(sin * phi.cos(), sin * phi.sin(), cos)).normalize();
    (wi, phase_hg(cos, g))
}

/// Equiangular sampling of a ray's part `[a, b)` towards a point at
/// `centre`: a distance with density proportional to 1 / distance^2 to
/// the point, what a point light's in-scatter falls off with.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Equiangular {
    /// Distance along the ray of the point nearest `centre`.
    foot: f32,
    /// Distance from `centre` to the ray.
    reach: f32,
    theta_a: f32,
    theta_b: f32,
}

impl Equiangular {
    /// `None` where the ray (nearly) runs through the point or the range is empty.
    pub(crate) fn new(origin: Vec3, dir: Vec3, centre: Vec3, (a, b): (f32, f32)) -> Option<Equiangular> {
        let foot = (centre - origin).dot(dir);
        let reach = (origin + dir * foot - centre).length();
        if !(reach > 1e-5 && a < b) {
            return None;
        }
        let theta_a = ((a - foot) / reach).atan();
        let theta_b = if b.is_finite() { ((b - foot) / reach).atan() } else { 0.5 * PI };
        (theta_b > theta_a).then_some(Equiangular { foot, reach, theta_a, theta_b })
    }

    /// A distance along the ray for `u` in [0, 1).
    pub(crate) fn sample(&self, u: f32) -> f32 {
        let theta = self.theta_a + u * (self.theta_b - self.theta_a);
        // Just short of a right angle, so tan stays finite for u near 1.
        let theta = theta.min(0.5 * PI - 1e-6);
        self.foot + self.reach * theta.tan()
    }

    /// The density of [`Equiangular::sample`] at `t`.
    pub(crate) fn pdf(&self, t: f32) -> f32 {
        let h = t - self.foot;
        self.reach / ((self.theta_b - self.theta_a) * (self.reach * self.reach + h * h))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::sampling::power_heuristic;

    fn air(density: f32, albedo: f32, g: f32) -> Atmosphere {
        Atmosphere { density, albedo: Vec3::splat(albedo), anisotropy: g, ..Default::default() }
    }

    /// A base-2 van der Corput sequence, for deterministic quadrature.
    fn radical_inverse(i: u32) -> f32 {
        (i.reverse_bits() as f64 / 4_294_967_296.0) as f32
    }

    #[test]
    fn transmittance_through_a_slab_is_beers_law_and_distance_sampling_passes_that_share() {
        // A slab 0.5 m deep: the air below y = 0.5, a ray from y = 0 straight up.
        let a = Atmosphere { top: 0.5, ..air(1.3, 0.8, 0.0) };
        let expect = (-1.3f32 * 0.5).exp();
        assert!((a.transmittance(Vec3::ZERO, Vec3::Y, f32::INFINITY) - expect).abs() < 1e-6);
        // Slanted at 60 degrees from vertical: twice the path.
        let d = Vec3::new(3f32.sqrt() / 2.0, 0.5, 0.0);
        assert!((a.transmittance(Vec3::ZERO, d, f32::INFINITY) - (-1.3f32).exp()).abs() < 1e-6);
        // From above, looking down to y = 0: the same slab.
        let t = a.transmittance(Vec3::new(0.0, 2.0, 0.0), -Vec3::Y, 2.0);
        assert!((t - expect).abs() < 1e-6, "{t}");
        // Above the air, looking up: nothing.
        assert_eq!(a.transmittance(Vec3::new(0.0, 2.0, 0.0), Vec3::Y, 5.0), 1.0);
        // The share of distance samples that pass the slab is the transmittance.
        let seg = a.segment(Vec3::ZERO, Vec3::Y, f32::INFINITY).unwrap();
        let n = 1 << 16;
        let passed =
            (0..n).filter(|&i| a.sample_distance(Vec3::ZERO, Vec3::Y, seg, radical_inverse(i)).is_none()).count();
        assert!((passed as f32 / n as f32 - expect).abs() < 1e-3, "{passed}");
        // An infinite medium: no light crosses it, every ray scatters.
        assert_eq!(air(0.1, 1.0, 0.0).transmittance(Vec3::ZERO, Vec3::X, f32::INFINITY), 0.0);
    }

    #[test]
    fn hg_integrates_to_one_and_its_samples_have_its_density() {
        for g in [-0.7f32, 0.0, 0.3, 0.9] {
            // Integral over the sphere by the cosine: 2 pi int p(c) dc.
            let n = 200_000;
            let sum: f64 = (0..n)
                .map(|i| {
                    let c = -1.0 + 2.0 * (i as f64 + 0.5) / n as f64;
                    phase_hg(c as f32, g) as f64
                })
                .sum();
            let total = 2.0 * std::f64::consts::PI * sum * 2.0 / n as f64;
            assert!((total - 1.0).abs() < 2e-3, "g {g}: {total}");
            // The mean cosine of the samples is g.
            let dir = Vec3::new(0.3, -0.4, 0.866).normalize();
            let m = 4096;
            let mean: f32 = (0..m)
                .map(|i| {
                    let u = Vec2::new((i as f32 + 0.5) / m as f32, radical_inverse(i));
                    let (wi, pdf) = sample_hg(dir, g, u);
                    assert!((pdf - phase_hg(wi.dot(dir), g)).abs() <= 1e-3 * pdf.max(1.0));
                    wi.dot(dir)
                })
                .sum::<f32>()
                / m as f32;
            assert!((mean - g).abs() < 5e-3, "g {g}: mean cosine {mean}");
        }
    }

    /// Single scattering of a point light of intensity `intensity` at
    /// distance `h` from a camera ray in an infinite homogeneous medium
    /// (isotropic phase): int_0^inf sigma_s e^(-sigma_t t) I e^(-sigma_t r) / (4 pi r^2) dt,
    /// r = sqrt(h^2 + (t - foot)^2), by a fine midpoint rule in f64.
    fn single_scatter_reference(sigma_t: f64, sigma_s: f64, intensity: f64, h: f64, foot: f64) -> f64 {
        // Substitute t = foot + h tan(theta): dt / r^2 = dtheta / h, smooth in theta.
        let (lo, hi) = ((-foot / h).atan(), std::f64::consts::FRAC_PI_2);
        let n = 400_000;
        let step = (hi - lo) / n as f64;
        (0..n)
            .map(|i| {
                let theta = lo + (i as f64 + 0.5) * step;
                let t = foot + h * theta.tan();
                let r = h / theta.cos();
                sigma_s * (-sigma_t * (t + r)).exp() * intensity / (4.0 * std::f64::consts::PI * h) * step
            })
            .sum()
    }

    #[test]
    fn single_scattering_from_a_point_light_matches_its_integral() {
        let (sigma_t, albedo, intensity) = (0.4f32, 0.7f32, 10.0f32);
        let a = air(sigma_t, albedo, 0.0);
        let (origin, dir) = (Vec3::ZERO, Vec3::X);
        let centre = Vec3::new(2.0, 0.5, 0.0);
        let expect = single_scatter_reference(sigma_t as f64, (sigma_t * albedo) as f64, intensity as f64, 0.5, 2.0);
        let seg = a.segment(origin, dir, f32::INFINITY).unwrap();
        let eq = Equiangular::new(origin, dir, centre, seg).unwrap();
        // The light's in-scatter at distance t, weighed by transmittance to it.
        let f = |t: f32| {
            let x = origin + dir * t;
            let r2 = (centre - x).length_squared();
            let tr = a.transmittance(origin, dir, t) * (-sigma_t * r2.sqrt()).exp();
            tr * a.scattering().x * phase_hg(0.0, 0.0) * intensity / r2
        };
        // Each technique alone, and both combined by the power heuristic (as the integrator does).
        let n = 1 << 14;
        let (mut equi, mut dist, mut mis) = (0.0f64, 0.0f64, 0.0f64);
        for i in 0..n {
            let u = (i as f32 + 0.5) / n as f32;
            let te = eq.sample(u);
            let (pe, pd) = (eq.pdf(te), a.distance_pdf(origin, dir, seg, te));
            equi += (f(te) / pe) as f64;
            mis += (f(te) / pe * power_heuristic(pe, pd)) as f64;
            // Distance sampling's event weight is the albedo; f / pdf the same thing.
            if let Some(td) = a.sample_distance(origin, dir, seg, radical_inverse(i)) {
                let (pe, pd) = (eq.pdf(td), a.distance_pdf(origin, dir, seg, td));
                dist += (f(td) / pd) as f64;
                mis += (f(td) / pd * power_heuristic(pd, pe)) as f64;
            }
        }
        for (name, got) in [("equiangular", equi), ("distance", dist), ("mis", mis)] {
            let got = got / n as f64;
            assert!((got - expect).abs() < 0.01 * expect, "{name}: {got} vs {expect}");
        }
        // Without extinction equiangular is exact: theta range / reach, every sample.
        let thin = air(1e-6, 1.0, 0.0);
        let seg = (0.0, 10.0);
        let eq = Equiangular::new(origin, dir, centre, seg).unwrap();
        let exact = ((8.0f32 / 0.5).atan() + (2.0f32 / 0.5).atan()) / 0.5;
        for u in [0.01f32, 0.37, 0.99] {
            let t = eq.sample(u);
            let r2 = (centre - dir * t).length_squared();
            assert!((1.0 / (r2 * eq.pdf(t)) - exact).abs() < 1e-3 * exact);
            assert!(thin.segment(origin, dir, 10.0).is_some());
        }
    }

    /// The optical depth of a ray from `origin` along `dir` up to `tmax`,
    /// by a fine midpoint rule over the density, in f64.
    fn depth_by_quadrature(a: &Atmosphere, origin: Vec3, dir: Vec3, tmax: f32) -> f64 {
        let n = 200_000;
        let step = tmax as f64 / n as f64;
        (0..n)
            .map(|i| {
                let t = (i as f64 + 0.5) * step;
                let y = origin.y as f64 + dir.y as f64 * t;
                if y >= a.top as f64 {
                    0.0
                } else if y > a.base as f64 {
                    a.density as f64 * (-(y - a.base as f64) / a.falloff as f64).exp() * step
                } else {
                    a.density as f64 * step
                }
            })
            .sum()
    }

    fn thinning() -> Atmosphere {
        Atmosphere { falloff: 2.5, base: 1.0, top: 9.0, ..air(0.4, 0.8, 0.3) }
    }

    /// Rays below, across and above the base, up, down, level and from above the top.
    fn rays() -> Vec<(Vec3, Vec3, f32)> {
        let slant = |x: f32, y: f32| Vec3::new(x, y, 0.3).normalize();
        vec![
            (Vec3::ZERO, Vec3::Y, 12.0),
            (Vec3::new(0.0, 0.5, 0.0), slant(1.0, 0.4), 15.0),
            (Vec3::new(0.0, 7.0, 0.0), slant(1.0, -0.5), 12.0),
            (Vec3::new(0.0, 3.0, 0.0), Vec3::X, 20.0),
            (Vec3::new(0.0, 0.2, 0.0), Vec3::X, 20.0),
            (Vec3::new(0.0, 12.0, 0.0), slant(0.2, -1.0), 11.0),
            (Vec3::new(0.0, 2.0, 0.0), slant(1.0, 1e-5), 30.0),
        ]
    }

    #[test]
    fn transmittance_through_a_falloff_is_the_integral_of_its_density() {
        let a = thinning();
        for (origin, dir, tmax) in rays() {
            let want = (-depth_by_quadrature(&a, origin, dir, tmax)).exp();
            let got = a.transmittance(origin, dir, tmax) as f64;
            assert!((got - want).abs() < 2e-5 + 1e-4 * want, "{origin} {dir}: {got} vs {want}");
        }
        // Endless upwards with no top: a finite depth, so the sun gets through.
        let open = Atmosphere { top: f32::INFINITY, ..a };
        let endless = open.transmittance(Vec3::ZERO, Vec3::Y, f32::INFINITY) as f64;
        let want = (-(0.4f64 * 1.0 + 0.4 * 2.5)).exp();
        assert!((endless - want).abs() < 1e-5, "{endless} vs {want}");
        // Homogeneous air is the falloff's limit.
        let far = Atmosphere { falloff: 1e7, ..a };
        let (o, d) = (Vec3::new(0.0, 0.5, 0.0), Vec3::new(0.6, 0.8, 0.0));
        let flat = Atmosphere { falloff: f32::INFINITY, ..a };
        assert!((far.transmittance(o, d, 6.0) - flat.transmittance(o, d, 6.0)).abs() < 1e-5);
    }

    #[test]
    fn distance_sampling_through_a_falloff_inverts_its_depth() {
        let a = thinning();
        for (origin, dir, tmax) in rays() {
            let Some(seg) = a.segment(origin, dir, tmax) else { continue };
            let t_all = a.transmittance_over(origin, dir, seg);
            let n = 4096;
            let mut passed = 0;
            for i in 0..n {
                let u = (i as f32 + 0.5) / n as f32;
                match a.sample_distance(origin, dir, seg, u) {
                    Some(t) => {
                        // The event comes where the optical depth is -ln(1 - u).
                        let depth = -(a.transmittance_over(origin, dir, (seg.0, t)) as f64).ln();
                        let want = -(1.0 - u as f64).ln();
                        assert!((depth - want).abs() < 1e-4 * want.max(1.0), "{dir} u {u}: {depth} vs {want}");
                    }
                    None => passed += 1,
                }
            }
            assert!((passed as f32 / n as f32 - t_all).abs() < 2.0 / n as f32, "{dir}: {passed} vs {t_all}");
            // Its density integrates to the share that does not pass.
            let m = 100_000;
            let step = (seg.1 - seg.0) / m as f32;
            let total: f64 = (0..m)
                .map(|i| a.distance_pdf(origin, dir, seg, seg.0 + (i as f32 + 0.5) * step) as f64 * step as f64)
                .sum();
            assert!((total - (1.0 - t_all as f64)).abs() < 1e-3, "{dir}: {total} vs {}", 1.0 - t_all);
        }
    }

    #[test]
    fn a_start_distance_clears_the_camera_rays_foreground_alone() {
        // A slab 5 m deep, looking along it; the air starts 2 m out.
        let a = Atmosphere { top: 5.0, start: 2.0, ..air(0.3, 0.8, 0.0) };
        let (o, d) = (Vec3::new(0.0, 1.0, 0.0), Vec3::X);
        assert!((a.camera_transmittance(o, d, 7.0) - (-0.3f32 * 5.0).exp()).abs() < 1e-6);
        assert_eq!(a.camera_segment(o, d, 7.0), Some((2.0, 7.0)));
        assert_eq!(a.camera_transmittance(o, d, 1.5), 1.0);
        // Looking down from above the slab: the start lies above it, no change.
        let down = Vec3::new(0.0, 9.0, 0.0);
        assert_eq!(a.camera_segment(down, -Vec3::Y, 9.0), Some((4.0, 9.0)));
        // Other rays see all of it.
        assert!((a.transmittance(o, d, 7.0) - (-0.3f32 * 7.0).exp()).abs() < 1e-6);
    }

    #[test]
    fn bad_values_name_their_key() {
        let bad = |f: &dyn Fn(&mut Atmosphere)| {
            let mut a = air(0.1, 0.5, 0.0);
            f(&mut a);
            a.check().unwrap_err().0
        };
        assert_eq!(bad(&|a| a.density = -1.0), "density");
        assert_eq!(bad(&|a| a.density = f32::NAN), "density");
        assert_eq!(bad(&|a| a.density = f32::INFINITY), "density");
        assert_eq!(bad(&|a| a.anisotropy = 1.0), "anisotropy");
        assert_eq!(bad(&|a| a.anisotropy = -1.0), "anisotropy");
        assert_eq!(bad(&|a| a.albedo = Vec3::new(0.5, 1.1, 0.5)), "color");
        assert_eq!(bad(&|a| a.albedo = Vec3::new(0.5, -0.1, 0.5)), "color");
        assert_eq!(bad(&|a| a.top = f32::NAN), "height");
        assert_eq!(bad(&|a| a.falloff = 0.0), "falloff");
        assert_eq!(bad(&|a| a.falloff = -2.0), "falloff");
        assert_eq!(bad(&|a| a.falloff = f32::NAN), "falloff");
        assert_eq!(bad(&|a| a.base = f32::INFINITY), "base");
        assert_eq!(bad(&|a| a.start = -1.0), "start");
        assert_eq!(bad(&|a| a.start = f32::INFINITY), "start");
        assert!(air(0.0, 0.0, 0.99).check().is_ok());
    }
}
