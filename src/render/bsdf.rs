//! glTF metallic-roughness BSDF: Lambert diffuse (base colour x (1 - metallic))
//! plus a GGX microfacet specular lobe (height-correlated Smith G, Schlick
//! Fresnel with F0 = mix(0.04, base colour, metallic)), combined as the glTF
//! spec's appendix does: f = (1 - F) diffuse / pi + F D G / (4 cos_o cos_i).
//! KHR_materials_ior sets the dielectric F0 = ((ior - 1) / (ior + 1))^2.
//!
//! [`Dielectric`]: the smooth glass of KHR_materials_transmission, exact
//! (unpolarised) Fresnel between specular reflection and transmission, a
//! refracting boundary of a volume or a thin wall; delta lobes only.
//!
//! Directions are in the local shading frame (z = shading normal) and point
//! away from the surface.

use std::f32::consts::{FRAC_1_PI, PI};

use super::sampling::sample_cosine_hemisphere;
use glam::{Vec2, Vec3};

/// Smallest GGX alpha; below this the lobe is a near-delta that f32 handles badly.
const MIN_ALPHA: f32 = 1e-3;

/// Rec. 709 luminance.
#[inline]
pub(crate) fn luminance(c: Vec3) -> f32 {
    c.dot(Vec3::new(0.2126, 0.7152, 0.0722))
}

/// An orthonormal basis around a unit normal (Duff et al. 2017, branchless).
#[derive(Clone, Copy, Debug)]
pub struct ShadingFrame {
    /// Tangent.
    pub(crate) s: Vec3,
    /// Bitangent.
    pub(crate) t: Vec3,
    /// Normal.
    pub(crate) n: Vec3,
}

impl ShadingFrame {
    /// Frame with `n` (unit) as z.
    pub fn from_normal(n: Vec3) -> ShadingFrame {
        let sign = 1.0f32.copysign(n.z);
        let a = -1.0 / (sign + n.z);
        let b = n.x * n.y * a;
        let s = Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x);
        let t = Vec3::new(b, sign + n.y * n.y * a, -n.y);
        ShadingFrame { s, t, n }
    }
    /// World to local.
    #[inline]
    pub(crate) fn to_local(self, v: Vec3) -> Vec3 {
        Vec3::new(v.dot(self.s), v.dot(self.t), v.dot(self.n))
    }
    /// Local to world.
    #[inline]
    pub fn to_world(&self, v: Vec3) -> Vec3 {
        self.s * v.x + self.t * v.y + self.n * v.z
    }
}

#[inline]
fn schlick(f0: Vec3, cos: f32) -> Vec3 {
    let m = (1.0 - cos).clamp(0.0, 1.0);
    let m2 = m * m;
    f0 + (Vec3::ONE - f0) * (m2 * m2 * m)
}

/// A BSDF instance at one shading point.
#[derive(Clone, Copy, Debug)]
pub struct Bsdf {
    diffuse: Vec3,
    f0: Vec3,
    alpha: f32,
    /// No specular lobe and no Fresnel weighting: f = diffuse / pi.
    lambert: bool,
}

/// One sampled direction.
#[derive(Clone, Copy, Debug)]
pub(crate) struct BsdfSample {
    /// Incident direction (local).
    pub(crate) wi: Vec3,
    /// f * cos / pdf.
    pub(crate) weight: Vec3,
    /// Solid-angle pdf of the whole mixture.
    pub(crate) pdf: f32,
}

impl Bsdf {
    /// The BSDF of a glTF material with the (textured) base colour and the
    /// default ior 1.5 (dielectric F0 = 0.04).
    pub fn new(base_color: Vec3, metallic: f32, roughness: f32) -> Bsdf {
        Bsdf::with_ior(base_color, metallic, roughness, 1.5)
    }

    /// As [`Bsdf::new`] with KHR_materials_ior's `ior`.
    pub(crate) fn with_ior(base_color: Vec3, metallic: f32, roughness: f32, ior: f32) -> Bsdf {
        let metallic = metallic.clamp(0.0, 1.0);
        let roughness = roughness.clamp(0.0, 1.0);
        let base_color = base_color.clamp(Vec3::ZERO, Vec3::ONE);
        // 1.5 gives the glTF core's 0.04 exactly (the formula rounds differently).
        let f0 = if ior == 1.5 { 0.04 } else { ((ior - 1.0) / (ior + 1.0)).powi(2) };
        Bsdf {
            diffuse: base_color * (1.0 - metallic),
            f0: Vec3::splat(f0).lerp(base_color, metallic),
            alpha: (roughness * roughness).max(MIN_ALPHA),
            lambert: false,
        }
    }

    /// A pure Lambertian BSDF, f = base colour / pi. Not what [`Bsdf::new`]
    /// gives for metallic 0, roughness 1: that keeps a GGX lobe with F0 = 0.04
    /// and weights the diffuse by (1 - F). For comparisons with renderers set
    /// to plain diffuse materials (see `RenderSettings::diffuse_only`).
    pub(crate) fn lambert(base_color: Vec3) -> Bsdf {
        Bsdf { diffuse: base_color.clamp(Vec3::ZERO, Vec3::ONE), f0: Vec3::ZERO, alpha: 1.0, lambert: true }
    }

    /// Whether the specular lobe is narrow enough that light reaching it
    /// must be looked up sharply: GGX alpha 0.1 (roughness 0.32) spreads a
    /// reflection over about 10 degrees, several of the dome's blocks
    /// (render::dome::Lookup); below it the blocks would show.
    pub(crate) fn is_sharp(&self) -> bool {
        !self.lambert && self.alpha < 0.1
    }

    /// GGX normal distribution.
    #[inline]
    fn d(&self, h: Vec3) -> f32 {
        let a2 = self.alpha * self.alpha;
        let c2 = h.z * h.z;
        let k = c2 * (a2 - 1.0) + 1.0;
        a2 / (PI * k * k)
    }

    /// Smith Lambda for GGX.
    #[inline]
    fn lambda(&self, w: Vec3) -> f32 {
        let z2 = w.z * w.z;
        if z2 <= 0.0 {
            return f32::INFINITY;
        }
        let tan2 = (w.x * w.x + w.y * w.y) / z2;
        0.5 * ((1.0 + self.alpha * self.alpha * tan2).sqrt() - 1.0)
    }

    /// Probability of sampling the specular lobe; depends on wo only, so the
    /// mixture pdf can be evaluated for any wi.
    #[inline]
    fn specular_probability(&self, wo: Vec3) -> f32 {
        let ws = luminance(schlick(self.f0, wo.z));
        let wd = luminance(self.diffuse) * (1.0 - ws);
        if wd <= 0.0 {
            1.0
        } else {
            (ws / (ws + wd)).clamp(0.1, 0.9)
        }
    }

    /// BSDF value f(wo, wi) (without the cosine). Zero below the horizon.
    pub fn eval(&self, wo: Vec3, wi: Vec3) -> Vec3 {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return Vec3::ZERO;
        }
        if self.lambert {
            return self.diffuse * FRAC_1_PI;
        }
        let h = (wo + wi).normalize_or_zero();
        if h == Vec3::ZERO {
            return Vec3::ZERO;
        }
        let f = schlick(self.f0, wi.dot(h));
        let g = 1.0 / (1.0 + self.lambda(wo) + self.lambda(wi));
        let specular = f * (self.d(h) * g / (4.0 * wo.z * wi.z));
        (Vec3::ONE - f) * self.diffuse * FRAC_1_PI + specular
    }

    /// [`Bsdf::eval`] as its diffuse and specular parts (which sum to it),
    /// for the light-path passes.
    pub(crate) fn eval_lobes(&self, wo: Vec3, wi: Vec3) -> (Vec3, Vec3) {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return (Vec3::ZERO, Vec3::ZERO);
        }
        if self.lambert {
            return (self.diffuse * FRAC_1_PI, Vec3::ZERO);
        }
        let h = (wo + wi).normalize_or_zero();
        if h == Vec3::ZERO {
            return (Vec3::ZERO, Vec3::ZERO);
        }
        let f = schlick(self.f0, wi.dot(h));
        let g = 1.0 / (1.0 + self.lambda(wo) + self.lambda(wi));
        ((Vec3::ONE - f) * self.diffuse * FRAC_1_PI, f * (self.d(h) * g / (4.0 * wo.z * wi.z)))
    }

    /// Solid-angle pdf of [`Bsdf::sample`] producing `wi`.
    pub(crate) fn pdf(&self, wo: Vec3, wi: Vec3) -> f32 {
        if wo.z <= 0.0 || wi.z <= 0.0 {
            return 0.0;
        }
        if self.lambert {
            return wi.z * FRAC_1_PI;
        }
        let p_spec = self.specular_probability(wo);
        let h = (wo + wi).normalize_or_zero();
        // Visible-normal pdf reflected: G1(wo) D(h) / (4 cos_o).
        let spec = if h.z > 0.0 { self.d(h) / ((1.0 + self.lambda(wo)) * 4.0 * wo.z) } else { 0.0 };
        p_spec * spec + (1.0 - p_spec) * wi.z * FRAC_1_PI
    }

    /// Samples wi: `u_lobe` picks the lobe, `u` the direction.
    pub(crate) fn sample(&self, wo: Vec3, u_lobe: f32, u: Vec2) -> Option<BsdfSample> {
        if wo.z <= 0.0 {
            return None;
        }
        let wi = if !self.lambert && u_lobe < self.specular_probability(wo) {
            let h = self.sample_visible_normal(wo, u);
            2.0 * wo.dot(h) * h - wo
        } else {
            sample_cosine_hemisphere(u)
        };
        if wi.z <= 0.0 {
            return None;
        }
        let pdf = self.pdf(wo, wi);
        if pdf.is_nan() || pdf <= 0.0 {
            return None;
        }
        let weight = self.eval(wo, wi) * (wi.z / pdf);
        weight.is_finite().then_some(BsdfSample { wi, weight, pdf })
    }

    /// GGX visible-normal sampling (Heitz 2018).
    fn sample_visible_normal(&self, wo: Vec3, u: Vec2) -> Vec3 {
        let a = self.alpha;
        let vh = Vec3::new(a * wo.x, a * wo.y, wo.z).normalize();
        let len2 = vh.x * vh.x + vh.y * vh.y;
        let t1 = if len2 > 0.0 { Vec3::new(-vh.y, vh.x, 0.0) / len2.sqrt() } else { Vec3::X };
        let t2 = vh.cross(t1);
        let r = u.x.sqrt();
        let phi = 2.0 * PI * u.y;
        let p1 = r * phi.cos();
        let s = 0.5 * (1.0 + vh.z);
        let p2 = (1.0 - s) * (1.0 - p1 * p1).max(0.0).sqrt() + s * r * phi.sin();
        let nh = p1 * t1 + p2 * t2 + (1.0 - p1 * p1 - p2 * p2).max(0.0).sqrt() * vh;
        Vec3::new(a * nh.x, a * nh.y, nh.z.max(1e-6)).normalize()
    }
}

/// Fresnel reflectance of a smooth boundary between dielectrics for
/// unpolarised light (the mean of the s and p reflectances), at cosine
/// `cos_i` (> 0) of the incident direction, `eta` = n_transmitted /
/// n_incident; 1 under total internal reflection.
pub(crate) fn fresnel_dielectric(cos_i: f32, eta: f32) -> f32 {
    let cos_i = cos_i.clamp(0.0, 1.0);
    let sin2_t = (1.0 - cos_i * cos_i) / (eta * eta);
    if sin2_t >= 1.0 {
        return 1.0;
    }
    let cos_t = (1.0 - sin2_t).sqrt();
    let parallel = (eta * cos_i - cos_t) / (eta * cos_i + cos_t);
    let perpendicular = (cos_i - eta * cos_t) / (cos_i + eta * cos_t);
    0.5 * (parallel * parallel + perpendicular * perpendicular)
}

/// A smooth dielectric surface (KHR_materials_transmission at roughness 0):
/// specular reflection and transmission, one picked by Fresnel. Either the
/// boundary of a solid (KHR_materials_volume), refracting by Snell's law, or
/// a thin wall: two boundaries back to back with every internal reflection
/// summed (reflectance R + T^2 R / (1 - R^2) for one boundary's R and T = 1 - R),
/// transmitting straight through. Transmission is tinted by the base colour.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Dielectric {
    /// n on the far side / n on the side the ray comes from (the material's
    /// ior entering a solid, 1 / ior leaving it; the ior for a thin wall).
    eta: f32,
    tint: Vec3,
    thin: bool,
}

/// One direction a [`Dielectric`] scatters into.
#[derive(Clone, Copy, Debug)]
pub(crate) struct DeltaSample {
    /// Outgoing direction (local); for a thin wall's transmission exactly -wo.
    pub(crate) wi: Vec3,
    /// Throughput factor (f cos / pdf of the delta lobe).
    pub(crate) weight: Vec3,
    /// Through the surface rather than reflected off it.
    pub(crate) transmitted: bool,
    /// The (n_t / n_i)^2 that `weight` divides by (1 but for refraction):
    /// Russian roulette multiplies it back, so a path inside glass is not
    /// ended for the radiance compression it will regain on leaving.
    pub(crate) eta_scale: f32,
}

impl Dielectric {
    /// A boundary the ray crosses from index 1 into `ior` (`entering`) or
    /// back out, or a thin wall of `ior` (`thin`), with transmission tint `tint`.
    pub(crate) fn new(ior: f32, entering: bool, thin: bool, tint: Vec3) -> Dielectric {
        let ior = ior.max(1.0);
        let eta = if thin || entering { ior } else { 1.0 / ior };
        Dielectric { eta, tint: tint.clamp(Vec3::ZERO, Vec3::ONE), thin }
    }

    /// Share of the light reflected at cosine `cos` (> 0) from the normal.
    pub(crate) fn reflectance(&self, cos: f32) -> f32 {
        let r = fresnel_dielectric(cos, self.eta);
        if self.thin && r < 1.0 {
            // A thin slab: R + T^2 R / (1 - R^2) = 2R / (1 + R).
            2.0 * r / (1.0 + r)
        } else {
            r
        }
    }

    /// Reflects (probability: the reflectance) or transmits, by `u`.
    pub(crate) fn sample(&self, wo: Vec3, u: f32) -> Option<DeltaSample> {
        if wo.z <= 0.0 {
            return None;
        }
        let r = self.reflectance(wo.z);
        if u < r {
            let wi = Vec3::new(-wo.x, -wo.y, wo.z);
            return Some(DeltaSample { wi, weight: Vec3::ONE, transmitted: false, eta_scale: 1.0 });
        }
        if self.thin {
            return Some(DeltaSample { wi: -wo, weight: self.tint, transmitted: true, eta_scale: 1.0 });
        }
        // Snell: the tangential part scales by 1 / eta. Radiance is
        // compressed by (n_i / n_t)^2 going into the denser side.
        let sin2_t = (1.0 - wo.z * wo.z) / (self.eta * self.eta);
        let cos_t = (1.0 - sin2_t).max(0.0).sqrt();
        let wi = Vec3::new(-wo.x / self.eta, -wo.y / self.eta, -cos_t).normalize();
        let eta_scale = self.eta * self.eta;
        Some(DeltaSample { wi, weight: self.tint / eta_scale, transmitted: true, eta_scale })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fresnel_at_normal_incidence_and_beyond_the_critical_angle() {
        for n in [1.33f32, 1.5, 2.42] {
            let r0 = ((n - 1.0) / (n + 1.0)).powi(2);
            assert!((fresnel_dielectric(1.0, n) - r0).abs() < 1e-6, "{n}");
            // Symmetric across the boundary at normal incidence.
            assert!((fresnel_dielectric(1.0, 1.0 / n) - r0).abs() < 1e-6, "{n}");
            // Grazing: everything reflects.
            assert!(fresnel_dielectric(1e-4, n) > 0.99);
            // Inside, past the critical angle sin = 1 / n: total internal reflection.
            let critical = (1.0 / n).asin();
            assert_eq!(fresnel_dielectric((critical + 0.01).cos(), 1.0 / n), 1.0);
            assert!(fresnel_dielectric((critical - 0.01).cos(), 1.0 / n) < 1.0);
        }
        // Brewster's angle (tan = n): the p-polarised part vanishes, leaving half of s.
        let n = 1.5f32;
        let brewster = n.atan();
        let (ci, st) = (brewster.cos(), brewster.sin() / n);
        let ct = (1.0 - st * st).sqrt();
        let rs = ((ci - n * ct) / (ci + n * ct)).powi(2);
        assert!((fresnel_dielectric(ci, n) - 0.5 * rs).abs() < 1e-6);
    }

    #[test]
    fn dielectric_refracts_by_snell_and_splits_by_fresnel() {
        let n = 1.5f32;
        let theta = 0.6f32;
        let wo = Vec3::new(theta.sin(), 0.0, theta.cos());
        let glass = Dielectric::new(n, true, false, Vec3::ONE);
        let r = glass.reflectance(wo.z);
        let reflect = glass.sample(wo, 0.5 * r).expect("reflects");
        assert!(!reflect.transmitted && (reflect.wi - Vec3::new(-wo.x, 0.0, wo.z)).length() < 1e-6);
        let t = glass.sample(wo, 0.5 * (1.0 + r)).expect("transmits");
        assert!(t.transmitted && t.wi.z < 0.0);
        // sin_t = sin_i / n, on the other side of the normal.
        assert!((t.wi.x.abs() - theta.sin() / n).abs() < 1e-6 && t.wi.x < 0.0);
        assert!((t.weight.x - 1.0 / (n * n)).abs() < 1e-6);
        // Leaving, the same path back: the radiance factors cancel.
        let out = Dielectric::new(n, false, false, Vec3::ONE);
        let back = out.sample(-t.wi, 0.999).expect("leaves");
        assert!(back.transmitted && (back.wi + wo).length() < 1e-5);
        assert!((back.weight.x * t.weight.x - 1.0).abs() < 1e-5);
        // A thin wall goes straight through, tinted, and reflects more than one boundary.
        let tint = Vec3::new(1.0, 0.5, 0.25);
        let thin = Dielectric::new(n, true, true, tint);
        let s = thin.sample(wo, 0.999).expect("transmits");
        assert!(s.transmitted && s.wi == -wo && s.weight == tint);
        let r1 = fresnel_dielectric(wo.z, n);
        assert!((thin.reflectance(wo.z) - 2.0 * r1 / (1.0 + r1)).abs() < 1e-6);
    }

    /// Integrates f cos over the hemisphere by uniform sampling and by the
    /// BSDF's own sampling: both must agree (checks pdf / weight consistency).
    #[test]
    fn sampling_matches_uniform_integration() {
        for (base, metallic, rough) in [(0.5, 0.0, 0.5), (0.9, 1.0, 0.3), (0.2, 0.5, 0.9)] {
            let bsdf = Bsdf::new(Vec3::splat(base), metallic, rough);
            let wo = Vec3::new(0.6, 0.0, 0.8);
            let n = 256u32;
            let (mut uniform, mut sampled) = (0.0f64, 0.0f64);
            for i in 0..n {
                for j in 0..n {
                    let u = Vec2::new((i as f32 + 0.5) / n as f32, (j as f32 + 0.5) / n as f32);
                    // Uniform hemisphere: pdf 1 / (2 pi).
                    let z = u.x;
                    let r = (1.0 - z * z).sqrt();
                    let wi = Vec3::new(r * (2.0 * PI * u.y).cos(), r * (2.0 * PI * u.y).sin(), z);
                    uniform += (bsdf.eval(wo, wi).x * wi.z * 2.0 * PI) as f64;
                    let lobe = ((i * 7 + j * 13) % 64) as f32 / 64.0;
                    if let Some(s) = bsdf.sample(wo, lobe, u) {
                        sampled += s.weight.x as f64;
                    }
                }
            }
            let (uniform, sampled) = (uniform / (n * n) as f64, sampled / (n * n) as f64);
            assert!((uniform - sampled).abs() < 0.01, "{base} {metallic} {rough}: {uniform} vs {sampled}");
            assert!(sampled <= 1.0 && sampled > 0.0);
        }
    }

    /// Lambert: sampling weight is exactly the base colour; and the glTF BSDF
    /// at metallic 0, roughness 1 is *not* Lambert (its albedo differs).
    #[test]
    fn lambert_is_pure_diffuse() {
        let base = Vec3::new(0.5, 0.25, 0.75);
        let lambert = Bsdf::lambert(base);
        let gltf = Bsdf::new(base, 0.0, 1.0);
        let n = 128u32;
        let mut albedo = [0.0f64; 2];
        for wo in [Vec3::Z, Vec3::new(0.8, 0.0, 0.6), Vec3::new(0.0, 0.995, 0.0999).normalize()] {
            for i in 0..n {
                for j in 0..n {
                    let u = Vec2::new((i as f32 + 0.5) / n as f32, (j as f32 + 0.5) / n as f32);
                    let s = lambert.sample(wo, 0.05, u).expect("cosine sample above the horizon");
                    assert!((s.weight - base).abs().max_element() < 1e-5);
                    assert!((s.pdf - s.wi.z * FRAC_1_PI).abs() < 1e-5);
                    assert!((lambert.eval(wo, s.wi) - base * FRAC_1_PI).abs().max_element() < 1e-6);
                    // Reflectance of the green channel at grazing view, by uniform-hemisphere integration.
                    let z = u.x;
                    let r = (1.0 - z * z).sqrt();
                    let wi = Vec3::new(r * (2.0 * PI * u.y).cos(), r * (2.0 * PI * u.y).sin(), z);
                    if wo.z < 0.2 {
                        albedo[0] += (lambert.eval(wo, wi).y * wi.z * 2.0 * PI) as f64;
                        albedo[1] += (gltf.eval(wo, wi).y * wi.z * 2.0 * PI) as f64;
                    }
                }
            }
        }
        let (l, g) = (albedo[0] / (n * n) as f64, albedo[1] / (n * n) as f64);
        assert!((l - 0.25).abs() < 0.005, "lambert albedo {l}");
        assert!((g - l).abs() > 0.01, "glTF metallic 0 roughness 1 albedo {g} should differ from Lambert {l}");
    }

    #[test]
    fn frame_is_orthonormal() {
        for n in [Vec3::Z, -Vec3::Z, Vec3::new(0.3, -0.8, 0.2).normalize()] {
            let f = ShadingFrame::from_normal(n);
            assert!(f.s.dot(f.t).abs() < 1e-5 && f.s.dot(n).abs() < 1e-5 && (f.s.length() - 1.0).abs() < 1e-5);
            let v = Vec3::new(0.1, 0.2, 0.9);
            assert!((f.to_world(f.to_local(v)) - v).length() < 1e-5);
        }
    }
}
