//! General Monte Carlo sampling: warps of uniform numbers onto discs,
//! hemispheres, spherical triangles and quads, an alias table for discrete
//! picks, and the power heuristic that weighs two techniques. Nothing here
//! knows a light or a material (the sample sequence itself is
//! [`super::sampler`]'s).

use std::f32::consts::PI;

use glam::{DVec3, Vec2, Vec3};

/// Power heuristic with beta = 2.
#[inline]
pub(crate) fn power_heuristic(f: f32, g: f32) -> f32 {
    let (f2, g2) = (f * f, g * g);
    if f2 + g2 > 0.0 {
        f2 / (f2 + g2)
    } else {
        0.0
    }
}

/// Concentric square-to-disk map (Shirley-Chiu) onto the unit disc: area
/// preserving, so uniform `u` gives uniform points (lens and disc lights).
#[inline]
pub(crate) fn sample_concentric_disk(u: Vec2) -> Vec2 {
    let o = 2.0 * u - Vec2::ONE;
    if o.x == 0.0 && o.y == 0.0 {
        Vec2::ZERO
    } else if o.x.abs() > o.y.abs() {
        let phi = PI / 4.0 * (o.y / o.x);
        o.x * Vec2::new(phi.cos(), phi.sin())
    } else {
        let phi = PI / 2.0 - PI / 4.0 * (o.x / o.y);
        o.y * Vec2::new(phi.cos(), phi.sin())
    }
}

/// The concentric disc map lifted to the hemisphere (Malley's method).
#[inline]
pub fn sample_cosine_hemisphere(u: Vec2) -> Vec3 {
    let d = sample_concentric_disk(u);
    Vec3::new(d.x, d.y, (1.0 - d.length_squared()).max(0.0).sqrt())
}

/// Vose's alias table: picks index i with probability weight[i] / sum in
/// O(1) from one uniform number. Built in f64, so the same weights give the
/// same table on any machine.
#[derive(Clone, Debug, Default)]
pub(crate) struct AliasTable {
    /// Probability of keeping bin i (else its alias).
    keep: Vec<f32>,
    alias: Vec<u32>,
    /// Probability of each index.
    pub(crate) pmf: Vec<f32>,
}

impl AliasTable {
    /// The table of `weights` (any scale; none negative).
    pub(crate) fn new(weights: &[f64]) -> AliasTable {
        let n = weights.len();
        let total: f64 = weights.iter().sum();
        if n == 0 || !(total > 0.0) {
            return AliasTable::default();
        }
        let pmf: Vec<f64> = weights.iter().map(|w| w / total).collect();
        let mut scaled: Vec<f64> = pmf.iter().map(|p| p * n as f64).collect();
        let (mut small, mut large): (Vec<usize>, Vec<usize>) = (0..n).partition(|&i| scaled[i] < 1.0);
        let mut keep = vec![1.0f32; n];
        let mut alias: Vec<u32> = (0..n as u32).collect();
        while let (Some(s), Some(&l)) = (small.pop(), large.last()) {
            keep[s] = scaled[s] as f32;
            alias[s] = l as u32;
            scaled[l] -= 1.0 - scaled[s];
            if scaled[l] < 1.0 {
                large.pop();
                small.push(l);
            }
        }
        AliasTable { keep, alias, pmf: pmf.iter().map(|&p| p as f32).collect() }
    }

    /// The index `u` in [0, 1) picks.
    pub(crate) fn pick(&self, u: f32) -> usize {
        let n = self.keep.len();
        let x = u * n as f32;
        let i = (x as usize).min(n - 1);
        if x - (i as f32) < self.keep[i] {
            i
        } else {
            self.alias[i] as usize
        }
    }
}

/// Solid angles (steradians) between which an emissive triangle is sampled
/// by solid angle from a shading point, by area outside them: below, it is
/// small enough that area sampling is as good and the spherical arithmetic
/// loses precision; above, the point is all but in its plane.
const SPHERICAL_MIN: f64 = 3e-4;
const SPHERICAL_MAX: f64 = 6.22;

/// A triangle as seen from a point: its corners' directions, the angle at
/// the first, and the solid angle. Sampled uniformly by Arvo's method
/// ("Stratified sampling of spherical triangles", 1995), in f64.
pub(crate) struct SphericalTriangle {
    a: DVec3,
    b: DVec3,
    c: DVec3,
    alpha: f64,
    /// Solid angle (steradians).
    pub(crate) area: f64,
}

/// The angle between unit vectors, precise near 0 and pi.
fn angle_between(x: DVec3, y: DVec3) -> f64 {
    if x.dot(y) < 0.0 {
        std::f64::consts::PI - 2.0 * ((x + y).length() / 2.0).min(1.0).asin()
    } else {
        2.0 * ((y - x).length() / 2.0).min(1.0).asin()
    }
}

impl SphericalTriangle {
    /// The triangle `v` seen from `p`; `None` (sample by area) outside
    /// [`SPHERICAL_MIN`, `SPHERICAL_MAX`] or degenerate.
    pub(crate) fn new(p: Vec3, v: &[Vec3; 3]) -> Option<SphericalTriangle> {
        let p = p.as_dvec3();
        let [a, b, c] = v.map(|q| (q.as_dvec3() - p).normalize_or_zero());
        let n_ab = a.cross(b).normalize_or_zero();
        let n_bc = b.cross(c).normalize_or_zero();
        let n_ca = c.cross(a).normalize_or_zero();
        if [a, b, c, n_ab, n_bc, n_ca].contains(&DVec3::ZERO) {
            return None;
        }
        let alpha = angle_between(n_ab, -n_ca);
        let beta = angle_between(n_bc, -n_ab);
        let gamma = angle_between(n_ca, -n_bc);
        let area = alpha + beta + gamma - std::f64::consts::PI;
        (SPHERICAL_MIN..=SPHERICAL_MAX).contains(&area).then_some(SphericalTriangle { a, b, c, alpha, area })
    }

    /// A direction into the triangle, uniform in solid angle for `u` uniform.
    pub(crate) fn sample(&self, u: Vec2) -> DVec3 {
        let (u0, u1) = (u.x as f64, u.y as f64);
        let gram_schmidt = |v: DVec3, w: DVec3| (v - v.dot(w) * w).normalize_or_zero();
        // The sub-triangle of area u0 x area: its corner c' on the arc from a to c.
        let (sin_ap, cos_ap) = (std::f64::consts::PI + u0 * self.area).sin_cos();
        let (sin_alpha, cos_alpha) = self.alpha.sin_cos();
        let sin_phi = sin_ap * cos_alpha - cos_ap * sin_alpha;
        let cos_phi = cos_ap * cos_alpha + sin_ap * sin_alpha;
        let k1 = cos_phi + cos_alpha;
        let k2 = sin_phi - sin_alpha * self.a.dot(self.b);
        let cos_bp = ((k2 + (k2 * cos_phi - k1 * sin_phi) * cos_alpha) / ((k2 * sin_phi + k1 * cos_phi) * sin_alpha))
            .clamp(-1.0, 1.0);
        let sin_bp = (1.0 - cos_bp * cos_bp).max(0.0).sqrt();
        let cp = cos_bp * self.a + sin_bp * gram_schmidt(self.c, self.a);
        // Then along the arc from b to c'.
        let cos_t = 1.0 - u1 * (1.0 - cp.dot(self.b));
        let sin_t = (1.0 - cos_t * cos_t).max(0.0).sqrt();
        (cos_t * self.b + sin_t * gram_schmidt(cp, self.b)).normalize()
    }
}

/// The barycentrics (of the second and third corners) of point `q` in the
/// plane of triangle `v`, clamped into it.
pub(crate) fn barycentrics(v: &[Vec3; 3], q: DVec3) -> (f32, f32) {
    let v0 = v[0].as_dvec3();
    let (e1, e2, r) = (v[1].as_dvec3() - v0, v[2].as_dvec3() - v0, q - v0);
    let (d00, d01, d11) = (e1.dot(e1), e1.dot(e2), e2.dot(e2));
    let (d20, d21) = (r.dot(e1), r.dot(e2));
    let den = d00 * d11 - d01 * d01;
    if !(den > 0.0) {
        return (0.0, 0.0);
    }
    let b1 = ((d11 * d20 - d01 * d21) / den).clamp(0.0, 1.0);
    let b2 = ((d00 * d21 - d01 * d20) / den).clamp(0.0, 1.0 - b1);
    (b1 as f32, b2 as f32)
}

/// A planar quad seen from a point as two spherical triangles (split on
/// the diagonal from its first corner to its third), sampled together
/// uniformly in the solid angle they span.
pub(crate) struct SphericalQuad {
    first: SphericalTriangle,
    second: SphericalTriangle,
}

impl SphericalQuad {
    /// Quad `corners` (in order round it) seen from `p`; `None` (sample by
    /// area) where either half is outside the bounds
    /// [`SphericalTriangle::new`] keeps.
    pub(crate) fn new(p: Vec3, corners: [Vec3; 4]) -> Option<SphericalQuad> {
        let [a, b, c, d] = corners;
        Some(SphericalQuad {
            first: SphericalTriangle::new(p, &[a, b, c])?,
            second: SphericalTriangle::new(p, &[a, c, d])?,
        })
    }

    /// Solid angle (steradians).
    pub(crate) fn area(&self) -> f64 {
        self.first.area + self.second.area
    }

    /// A direction into the quad, uniform in solid angle for `u` uniform:
    /// one half or the other in proportion to its solid angle, from u.x
    /// (rescaled, so the pixel's stratification carries into the half).
    pub(crate) fn sample(&self, u: Vec2) -> DVec3 {
        let total = self.area();
        let share = self.first.area / total;
        let ux = u.x as f64;
        let (half, ux) =
            if ux < share { (&self.first, ux / share) } else { (&self.second, (ux - share) / (1.0 - share)) };
        half.sample(Vec2::new(ux as f32, u.y))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn alias_table_picks_in_proportion() {
        let table = AliasTable::new(&[1.0, 3.0, 0.0, 4.0]);
        let n = 80_000;
        let mut counts = [0u32; 4];
        for i in 0..n {
            counts[table.pick((i as f32 + 0.5) / n as f32)] += 1;
        }
        for (c, w) in counts.iter().zip([1.0, 3.0, 0.0, 4.0]) {
            assert!((*c as f32 / n as f32 - w / 8.0).abs() < 0.002, "{counts:?}");
        }
        assert_eq!(table.pmf, [0.125, 0.375, 0.0, 0.5]);
    }
}
