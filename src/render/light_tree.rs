//! A light tree (a bounding volume hierarchy over lights, after pbrt-v4's
//! `BVHLightSampler`, written anew): picks one of many local lights for a
//! shading point by walking from the root, choosing each child in
//! proportion to a bound on what its lights can give the point (their
//! power, distance and the cones they emit into), so a pick costs
//! O(log n) and still favours the lamps near the point over the bright
//! ones far away. The chance of a given light (for multiple importance
//! sampling) retraces its path from the root.

use glam::Vec3;

/// What a light, or a node's lights together, can give: where they are,
/// how strongly they emit and into which directions.
#[derive(Clone, Copy, Debug)]
pub(crate) struct LightBounds {
    pub(crate) lo: Vec3,
    pub(crate) hi: Vec3,
    /// Intensity (luminance of radiant intensity, W/sr): importance is
    /// `phi` x cosines / distance^2, an irradiance as render::lights's reach.
    pub(crate) phi: f64,
    /// Axis of the cone of emitting normals, and the cosine of its half angle.
    pub(crate) axis: Vec3,
    pub(crate) cos_o: f32,
    /// Cosine of how far past the normal cone light still leaves (pi / 2
    /// for a surface, the spot's edge for a spot).
    pub(crate) cos_e: f32,
    pub(crate) two_sided: bool,
}

/// cos(max(0, a - b)) from the sines and cosines of a and b (angles in [0, pi]).
#[inline]
fn cos_sub_clamped(sin_a: f32, cos_a: f32, sin_b: f32, cos_b: f32) -> f32 {
    if cos_a > cos_b {
        1.0
    } else {
        cos_a * cos_b + sin_a * sin_b
    }
}

/// sin(max(0, a - b)), as [`cos_sub_clamped`].
#[inline]
fn sin_sub_clamped(sin_a: f32, cos_a: f32, sin_b: f32, cos_b: f32) -> f32 {
    if cos_a > cos_b {
        0.0
    } else {
        sin_a * cos_b - cos_a * sin_b
    }
}

#[inline]
fn sin_of(cos: f32) -> f32 {
    (1.0 - cos * cos).max(0.0).sqrt()
}

impl LightBounds {
    fn centre(&self) -> Vec3 {
        0.5 * (self.lo + self.hi)
    }

    /// The union of two bounds: their box, summed power, a cone holding
    /// both cones (pbrt's `DirectionCone::Union`).
    fn union(&self, b: &LightBounds) -> LightBounds {
        let (axis, cos_o) = cone_union((self.axis, self.cos_o), (b.axis, b.cos_o));
        LightBounds {
            lo: self.lo.min(b.lo),
            hi: self.hi.max(b.hi),
            phi: self.phi + b.phi,
            axis,
            cos_o,
            cos_e: self.cos_e.min(b.cos_e),
            two_sided: self.two_sided || b.two_sided,
        }
    }

    /// A bound on the irradiance these lights give a point `p` with normal
    /// `n`: zero only where none of them can light it (behind it, behind a
    /// one-sided emitter, outside a spot's cone).
    pub(crate) fn importance(&self, p: Vec3, n: Vec3) -> f64 {
        if !(self.phi > 0.0) {
            return 0.0;
        }
        let pc = self.centre();
        let radius = 0.5 * (self.hi - self.lo).length();
        let d = p - pc;
        let dist2 = d.length_squared().max(radius * radius).max(1e-12);
        let dist = d.length();
        let wi = if dist > 0.0 { d / dist } else { Vec3::Z };
        // The angle the box subtends from p.
        let (sin_b, cos_b) = if dist <= radius {
            (0.0, -1.0)
        } else {
            let sin2 = (radius * radius) / (dist * dist);
            (sin2.sqrt(), (1.0 - sin2).max(0.0).sqrt())
        };
        let mut cos_w = self.axis.dot(wi);
        if self.two_sided {
            cos_w = cos_w.abs();
        }
        let sin_w = sin_of(cos_w);
        let sin_o = sin_of(self.cos_o);
        // Past the normal cone, then less the box's angle.
        let cos_x = cos_sub_clamped(sin_w, cos_w, sin_o, self.cos_o);
        let sin_x = sin_sub_clamped(sin_w, cos_w, sin_o, self.cos_o);
        let cos_p = cos_sub_clamped(sin_x, cos_x, sin_b, cos_b);
        if cos_p <= self.cos_e {
            return 0.0;
        }
        // The receiver's side: one-sided (light arrives from above its horizon).
        // A point in the air (n zero) takes light from every side.
        let cos_i = if n == Vec3::ZERO { 1.0 } else { (-wi).dot(n) };
        let cos_pi = cos_sub_clamped(sin_of(cos_i), cos_i, sin_b, cos_b).max(0.0);
        self.phi * cos_p as f64 * cos_pi as f64 / dist2 as f64
    }
}

/// The smallest cone (axis, cos of half angle) holding cones `a` and `b`.
fn cone_union(a: (Vec3, f32), b: (Vec3, f32)) -> (Vec3, f32) {
    let (theta_a, theta_b) = (a.1.clamp(-1.0, 1.0).acos(), b.1.clamp(-1.0, 1.0).acos());
    let theta_d = a.0.dot(b.0).clamp(-1.0, 1.0).acos();
    let pi = std::f32::consts::PI;
    if (theta_d + theta_b).min(pi) <= theta_a {
        return a;
    }
    if (theta_d + theta_a).min(pi) <= theta_b {
        return b;
    }
    let theta_o = 0.5 * (theta_a + theta_d + theta_b);
    if theta_o >= pi {
        return (a.0, -1.0);
    }
    let wr = a.0.cross(b.0);
    if wr.length_squared() < 1e-12 {
        return (a.0, -1.0);
    }
    let axis = glam::Quat::from_axis_angle(wr.normalize(), theta_o - theta_a) * a.0;
    (axis.normalize(), theta_o.cos())
}

/// One node: its lights' bounds; a leaf names its light's slot, an inner
/// node its second child (the first follows it).
#[derive(Clone, Copy, Debug)]
struct Node {
    bounds: LightBounds,
    /// The slot of a leaf's light, or an inner node's second child.
    index: u32,
    leaf: bool,
}

/// A tree over lights, each known by its slot (its index in the bounds
/// it was built from).
#[derive(Clone, Debug, Default)]
pub(crate) struct LightTree {
    nodes: Vec<Node>,
    /// Per slot, the way from the root to its leaf: bit k set for the
    /// second child at depth k, and the depth.
    trail: Vec<(u64, u8)>,
}

impl LightTree {
    /// The tree over `lights` (slot i is `lights[i]`), split at the median
    /// of the centres along the widest axis, so its depth is log2 of the
    /// count whatever the lights' layout.
    pub(crate) fn new(lights: &[LightBounds]) -> LightTree {
        let mut tree = LightTree { nodes: Vec::with_capacity(2 * lights.len()), trail: vec![(0, 0); lights.len()] };
        if lights.is_empty() {
            return tree;
        }
        let mut slots: Vec<u32> = (0..lights.len() as u32).collect();
        tree.build(lights, &mut slots, 0, 0);
        tree
    }

    fn build(&mut self, lights: &[LightBounds], slots: &mut [u32], bits: u64, depth: u8) -> LightBounds {
        let at = self.nodes.len();
        if let [slot] = *slots {
            let bounds = lights[slot as usize];
            self.nodes.push(Node { bounds, index: slot, leaf: true });
            self.trail[slot as usize] = (bits, depth);
            return bounds;
        }
        let (lo, hi) = slots.iter().fold((Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)), |(l, h), &s| {
            let c = lights[s as usize].centre();
            (l.min(c), h.max(c))
        });
        let extent = hi - lo;
        let axis = if extent.x >= extent.y && extent.x >= extent.z {
            0
        } else if extent.y >= extent.z {
            1
        } else {
            2
        };
        // Ties by slot: the same tree for the same lights.
        slots.sort_unstable_by(|&a, &b| {
            let (ca, cb) = (lights[a as usize].centre()[axis], lights[b as usize].centre()[axis]);
            ca.total_cmp(&cb).then(a.cmp(&b))
        });
        let mid = slots.len() / 2;
        // Placeholder bounds, replaced once the children are known.
        self.nodes.push(Node { bounds: lights[slots[0] as usize], index: 0, leaf: false });
        let (first, second) = slots.split_at_mut(mid);
        let a = self.build(lights, first, bits, depth + 1);
        self.nodes[at].index = self.nodes.len() as u32;
        let b = self.build(lights, second, bits | (1 << depth), depth + 1);
        let bounds = a.union(&b);
        self.nodes[at].bounds = bounds;
        bounds
    }

    /// Whether it holds no light.
    pub(crate) fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }

    /// A bound on what all the lights give point `p` (normal `n`).
    pub(crate) fn importance(&self, p: Vec3, n: Vec3) -> f64 {
        self.nodes.first().map_or(0.0, |root| root.bounds.importance(p, n))
    }

    /// The children's chances of being picked at inner node `at`: `None`
    /// where neither can light the point.
    #[inline]
    fn split(&self, at: usize, p: Vec3, n: Vec3) -> Option<f64> {
        let node = &self.nodes[at];
        let a = self.nodes[at + 1].bounds.importance(p, n);
        let b = self.nodes[node.index as usize].bounds.importance(p, n);
        let total = a + b;
        (total > 0.0 && total.is_finite()).then(|| a / total)
    }

    /// A light for point `p` (normal `n`) picked by `u` in [0, 1): its
    /// slot and the chance it was picked; `None` where no light can reach.
    pub(crate) fn sample(&self, p: Vec3, n: Vec3, u: f32) -> Option<(u32, f64)> {
        let (mut at, mut pmf, mut u) = (0usize, 1.0f64, u as f64);
        loop {
            let node = self.nodes.get(at)?;
            if node.leaf {
                return (node.bounds.importance(p, n) > 0.0).then_some((node.index, pmf));
            }
            let first = self.split(at, p, n)?;
            if u < first {
                u = (u / first).min(1.0 - f64::EPSILON);
                pmf *= first;
                at += 1;
            } else {
                u = ((u - first) / (1.0 - first)).min(1.0 - f64::EPSILON);
                pmf *= 1.0 - first;
                at = node.index as usize;
            }
        }
    }

    /// The chance [`LightTree::sample`] at `p` (normal `n`) picks `slot`.
    pub(crate) fn pmf(&self, slot: u32, p: Vec3, n: Vec3) -> f64 {
        let Some(&(bits, depth)) = self.trail.get(slot as usize) else { return 0.0 };
        let (mut at, mut pmf) = (0usize, 1.0f64);
        for k in 0..depth {
            let Some(first) = self.split(at, p, n) else { return 0.0 };
            if bits & (1 << k) == 0 {
                pmf *= first;
                at += 1;
            } else {
                pmf *= 1.0 - first;
                at = self.nodes[at].index as usize;
            }
        }
        if self.nodes.get(at).is_some_and(|leaf| leaf.bounds.importance(p, n) > 0.0) {
            pmf
        } else {
            0.0
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn point(at: Vec3, phi: f64) -> LightBounds {
        LightBounds { lo: at, hi: at, phi, axis: Vec3::Z, cos_o: -1.0, cos_e: 0.0, two_sided: false }
    }

    /// 64 lamps on a grid: the picks' chances sum to one at any point, and
    /// what `sample` reports is what `pmf` recomputes.
    #[test]
    fn picks_sum_to_one_and_sample_matches_pmf() {
        let lights: Vec<LightBounds> = (0..64)
            .map(|i| point(Vec3::new((i % 8) as f32 * 3.0, 4.0, (i / 8) as f32 * 3.0), 1.0 + (i % 5) as f64))
            .collect();
        let tree = LightTree::new(&lights);
        for p in [Vec3::new(1.0, 0.0, 1.0), Vec3::new(20.0, 0.0, 5.0), Vec3::new(-30.0, 2.0, 40.0)] {
            let sum: f64 = (0..64).map(|s| tree.pmf(s, p, Vec3::Y)).sum();
            assert!((sum - 1.0).abs() < 1e-9, "sum {sum} at {p}");
            for k in 0..97 {
                let (slot, pmf) = tree.sample(p, Vec3::Y, (k as f32 + 0.5) / 97.0).unwrap();
                assert!((pmf - tree.pmf(slot, p, Vec3::Y)).abs() < 1e-12 * pmf.max(1.0));
            }
        }
    }

    /// A lamp next to the point is picked far more often than an equal
    /// one across the scene; one below the point's horizon never.
    #[test]
    fn near_lights_are_favoured_and_hidden_ones_never_picked() {
        let mut lights: Vec<LightBounds> = (0..32).map(|i| point(Vec3::new(i as f32 * 10.0, 3.0, 0.0), 1.0)).collect();
        lights.push(point(Vec3::new(0.0, -3.0, 0.0), 100.0));
        let tree = LightTree::new(&lights);
        let p = Vec3::ZERO;
        assert!(tree.pmf(0, p, Vec3::Y) > 10.0 * tree.pmf(31, p, Vec3::Y));
        assert_eq!(tree.pmf(32, p, Vec3::Y), 0.0);
        for k in 0..200 {
            let (slot, _) = tree.sample(p, Vec3::Y, k as f32 / 200.0).unwrap();
            assert_ne!(slot, 32);
        }
    }

    /// The union's cone holds both cones.
    #[test]
    fn cone_union_holds_both() {
        let a = (Vec3::Z, 0.9f32);
        let b = (Vec3::X, 0.95f32);
        let (axis, cos) = cone_union(a, b);
        for (w, c) in [a, b] {
            // The far edge of each cone lies inside the union.
            let half = c.acos() + w.dot(axis).clamp(-1.0, 1.0).acos();
            assert!(half <= cos.acos() + 1e-4);
        }
    }
}
