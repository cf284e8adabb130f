//! Looking up and importance-sampling an HDRI dome ([`Dome`]).
//!
//! Orientation (docs/lights.md, "The dome"; Blender's world and the peer
//! harness): for a world direction d, let d' be d turned by `-rotate` about
//! +Y; then u = (pi - atan2(-d'.z, d'.x)) / (2 pi), v = acos(d'.y) / pi, with
//! v = 0 the top row. At `rotate` 0 the image centre faces +X.
//!
//! Radiance is bilinear between texel centres (wrapping in u, clamped in v).
//! Sampling is piecewise constant over the texel cells: a cell is picked with
//! probability proportional to the mean luminance of the bilinear radiance
//! over it times its solid angle (a marginal distribution over rows, a
//! conditional one along each row), then a direction uniformly in solid angle
//! within it. So the density is constant over each cell, exactly 1 / (4 pi)
//! everywhere for a constant map, and positive wherever the radiance is (the
//! cell mean sees every texel the bilinear lookup reads), as multiple
//! importance sampling needs.

use std::f32::consts::PI;
use std::f64::consts::PI as PI64;
use std::sync::Arc;

use glam::{Vec2, Vec3};

use super::bsdf::luminance;
use crate::scene::lights::Dome;

/// The two parts of a dome that next-event estimation samples apart: its
/// sun (the few cells that hold much of its light in a small solid angle)
/// and the rest. A dome without such a sun is all `Rest`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum DomePart {
    /// The sun's cells.
    Sun,
    /// Every other cell (the whole dome when it has no sun).
    Rest,
}

/// Cells brighter than this many times the dome's mean radiance may be its sun.
const SUN_CONTRAST: f64 = 50.0;
/// ... if together they span at most this solid angle (sr; the real sun is
/// 6.8e-5, a 1k map's sun with its bilinear spread about 1e-3) ...
const SUN_MAX_SOLID_ANGLE: f64 = 0.02;
/// ... and carry at least this share of the dome's light; and are at most
/// this many (a sun at the pole of a 16k map spans whole rows of tiny cells,
/// and each sun cell costs 64 sub-cell weights).
const SUN_MIN_SHARE: f64 = 0.2;
const SUN_MAX_CELLS: usize = 4096;

/// Each sun cell is sampled by [`SUN_SPLIT`] x [`SUN_SPLIT`] sub-cells of
/// equal solid angle, weighted by the bilinear radiance at their centres:
/// a 1k map's sun is a few texels whose bilinear spread makes the radiance
/// vary by orders of magnitude across a cell, which a constant density per
/// cell would turn into noise on every sunlit surface. Even, so sub-cells
/// never straddle the texel-centre lines the bilinear lookup bends at.
const SUN_SPLIT: usize = 8;

/// The sun's cells: indices (row-major, ascending) and running sums of
/// their sub-cells' weights ([`SUN_SPLIT`]^2 per cell, row by row).
#[derive(Clone, Debug, Default)]
struct SunCells {
    cells: Vec<u32>,
    cdf: Vec<f64>,
}

/// A dome ready to be looked up and sampled. Building it costs a pass over
/// the texels and 8 bytes per texel: build one per loaded dome and share it.
#[derive(Clone, Debug)]
pub struct DomeSampler {
    dome: Arc<Dome>,
    cos_rotate: f32,
    sin_rotate: f32,
    /// Running sums (inclusive) of the cell weights along each row, row-major
    /// (the sun's cells weigh nothing here: they are the sun part's).
    row_cdf: Vec<f64>,
    /// Running sums (inclusive) of the row totals, top row first.
    marginal_cdf: Vec<f64>,
    /// cos(theta) at each row boundary, `height + 1` values from +1 (zenith).
    cos_theta: Vec<f64>,
    /// Solid angle of one cell of each row.
    cell_solid_angle: Vec<f64>,
    /// The sun's cells, when the dome has a sun.
    sun: SunCells,
}

impl DomeSampler {
    /// Builds the lookup and the sampling distributions of `dome`.
    pub fn new(dome: Arc<Dome>) -> DomeSampler {
        let (w, h) = (dome.width as usize, dome.height as usize);
        let texel_luminance = |i: usize, j: usize| luminance(dome.texels[j * w + i] * dome.scale).max(0.0);
        // The mean of a bilinear interpolant over a texel's cell weighs the
        // texel and its neighbours 1/8, 3/4, 1/8 along each axis.
        let mut across = vec![0f32; w * h];
        for j in 0..h {
            for i in 0..w {
                let (left, right) = ((i + w - 1) % w, (i + 1) % w);
                across[j * w + i] =
                    (texel_luminance(left, j) + 6.0 * texel_luminance(i, j) + texel_luminance(right, j)) / 8.0;
            }
        }
        let cos_theta: Vec<f64> = (0..=h).map(|j| (PI64 * j as f64 / h as f64).cos()).collect();
        let cell_solid_angle: Vec<f64> = (0..h)
            .map(|j| {
                // cos a - cos b = 2 sin((a + b) / 2) sin((b - a) / 2), exact near the poles.
                let (a, b) = (PI64 * j as f64 / h as f64, PI64 * (j + 1) as f64 / h as f64);
                2.0 * ((a + b) / 2.0).sin() * ((b - a) / 2.0).sin() * 2.0 * PI64 / w as f64
            })
            .collect();
        // Cell weights: mean luminance x solid angle (kept in row_cdf's place).
        let mut weights = vec![0f64; w * h];
        for j in 0..h {
            let (up, down) = (j.saturating_sub(1), (j + 1).min(h - 1));
            for i in 0..w {
                let mean = (across[up * w + i] + 6.0 * across[j * w + i] + across[down * w + i]) as f64 / 8.0;
                weights[j * w + i] = mean * cell_solid_angle[j];
            }
        }
        let sun_cells = find_sun(&weights, &cell_solid_angle, w);
        for &c in &sun_cells {
            weights[c as usize] = 0.0;
        }
        let mut row_cdf = weights;
        let mut marginal_cdf = vec![0f64; h];
        let mut rest_total = 0f64;
        for j in 0..h {
            let mut sum = 0f64;
            for c in &mut row_cdf[j * w..(j + 1) * w] {
                sum += *c;
                *c = sum;
            }
            rest_total += sum;
            marginal_cdf[j] = rest_total;
        }
        let (sin_rotate, cos_rotate) = dome.rotate.sin_cos();
        let mut sampler = DomeSampler {
            dome,
            cos_rotate,
            sin_rotate,
            row_cdf,
            marginal_cdf,
            cos_theta,
            cell_solid_angle,
            sun: SunCells::default(),
        };
        // The sun's sub-cells are weighed by the bilinear lookup, so after the rest.
        sampler.sun = sampler.split_sun(sun_cells);
        sampler
    }

    /// The sun part over `cells`: each cell's sub-cells weighted by the
    /// bilinear luminance at their centres times their solid angle.
    fn split_sun(&self, cells: Vec<u32>) -> SunCells {
        let w = self.dome.width as usize;
        let mut cdf = Vec::with_capacity(cells.len() * SUN_SPLIT * SUN_SPLIT);
        let mut sum = 0f64;
        for &cell in &cells {
            let (row, column) = (cell as usize / w, cell as usize % w);
            let (top, bottom) = (self.cos_theta[row], self.cos_theta[row + 1]);
            let sub_solid_angle = self.cell_solid_angle[row] / (SUN_SPLIT * SUN_SPLIT) as f64;
            for sr in 0..SUN_SPLIT {
                let cos = top + (sr as f64 + 0.5) / SUN_SPLIT as f64 * (bottom - top);
                let v = (cos.clamp(-1.0, 1.0).acos() / PI64) as f32;
                for sc in 0..SUN_SPLIT {
                    let u = ((column as f64 + (sc as f64 + 0.5) / SUN_SPLIT as f64) / w as f64) as f32;
                    sum += luminance(self.lookup(Vec2::new(u, v))).max(0.0) as f64 * sub_solid_angle;
                    cdf.push(sum);
                }
            }
        }
        if !(sum > 0.0) {
            return SunCells::default();
        }
        SunCells { cells, cdf }
    }

    /// The parts with light, sun first, each sampled on its own by
    /// [`DomeSampler::sample_part`].
    pub(crate) fn parts(&self) -> impl Iterator<Item = DomePart> + '_ {
        [DomePart::Sun, DomePart::Rest].into_iter().filter(|&p| self.part_power(p) > 0.0)
    }

    /// The integral of luminance over the sphere: the parts share the cells,
    /// so their sums make the whole.
    fn total(&self) -> f64 {
        self.part_power(DomePart::Sun) + self.part_power(DomePart::Rest)
    }

    /// A part's integral of luminance over the sphere: its share of light
    /// when choosing between lights by power.
    pub(crate) fn part_power(&self, part: DomePart) -> f64 {
        match part {
            DomePart::Sun => self.sun.cdf.last().copied().unwrap_or(0.0),
            // The marginal's last running sum: every rest cell's weight.
            DomePart::Rest => self.marginal_cdf.last().copied().unwrap_or(0.0),
        }
    }

    /// World direction of map coordinates `uv` (u right, v down, in [0, 1]).
    pub fn direction(&self, uv: Vec2) -> Vec3 {
        let (sin_theta, cos_theta) = (PI * uv.y).sin_cos();
        self.world_from_dome(sin_theta, cos_theta, uv.x)
    }

    /// Map coordinates of a world direction (need not be unit length).
    pub(crate) fn uv(&self, dir: Vec3) -> Vec2 {
        self.in_map(dir).1
    }

    /// A world direction in the dome's frame (unit) and its map coordinates.
    fn in_map(&self, dir: Vec3) -> (Vec3, Vec2) {
        let d = self.dome_from_world(dir.normalize_or_zero());
        let u = (PI - (-d.z).atan2(d.x)) / (2.0 * PI);
        (d, Vec2::new(u, d.y.clamp(-1.0, 1.0).acos() / PI))
    }

    /// Radiance arriving from direction `dir` (W/(m^2 sr)): the bilinear
    /// lookup times the dome's scale.
    pub fn radiance(&self, dir: Vec3) -> Vec3 {
        self.lookup(self.uv(dir))
    }

    /// [`DomeSampler::radiance`] and [`DomeSampler::part_pdf`] of `dir`,
    /// mapping it once (what a ray escaping into the dome needs).
    pub(crate) fn radiance_and_pdf(&self, dir: Vec3) -> (Vec3, DomePart, f32) {
        let (d, uv) = self.in_map(dir);
        let (part, pdf) = self.pdf_at(d, uv);
        (self.lookup(uv), part, pdf)
    }

    /// Samples a direction towards the whole dome from two uniform numbers
    /// in [0, 1): (direction, its radiance, its solid-angle pdf). None for a
    /// black dome. The parts in proportion to their light, so the density
    /// is the one distribution over every cell.
    pub fn sample(&self, u: Vec2) -> Option<(Vec3, Vec3, f32)> {
        let total = self.total();
        if total <= 0.0 {
            return None;
        }
        let sun_share = (self.part_power(DomePart::Sun) / total) as f32;
        let (part, u) = if u.y < sun_share {
            (DomePart::Sun, Vec2::new(u.x, u.y / sun_share))
        } else {
            (DomePart::Rest, Vec2::new(u.x, (u.y - sun_share) / (1.0 - sun_share)))
        };
        let (dir, radiance, _) = self.sample_part(part, u)?;
        let pdf = self.pdf(dir);
        (pdf > 0.0).then_some((dir, radiance, pdf))
    }

    /// Samples a direction towards one part of the dome: (direction, its
    /// radiance, its solid-angle pdf within the part). None when the part
    /// has no light.
    pub(crate) fn sample_part(&self, part: DomePart, u: Vec2) -> Option<(Vec3, Vec3, f32)> {
        let u = u.clamp(Vec2::ZERO, Vec2::splat(1.0 - f32::EPSILON));
        let w = self.dome.width as usize;
        let (row, column, along_row, along_column) = match part {
            DomePart::Rest => {
                let rest_total = self.part_power(DomePart::Rest);
                if rest_total <= 0.0 {
                    return None;
                }
                let (row, along_row) = pick(&self.marginal_cdf, u.y as f64 * rest_total);
                let cdf = &self.row_cdf[row * w..(row + 1) * w];
                let (column, along_column) = pick(cdf, u.x as f64 * cdf[w - 1]);
                (row, column, along_row, along_column)
            }
            DomePart::Sun => {
                let total = *self.sun.cdf.last()?;
                // One number picks the sub-cell and, rescaled, where across
                // it; the other where down it.
                let (k, along) = pick(&self.sun.cdf, u.x as f64 * total);
                let n = SUN_SPLIT * SUN_SPLIT;
                let cell = self.sun.cells[k / n] as usize;
                let (sr, sc) = ((k % n) / SUN_SPLIT, (k % n) % SUN_SPLIT);
                let split = SUN_SPLIT as f64;
                (cell / w, cell % w, (sr as f64 + u.y as f64) / split, (sc as f64 + along) / split)
            }
        };
        // Uniform in solid angle within the (sub-)cell: uniform in u and in cos(theta).
        let map_u = ((column as f64 + along_column) / w as f64) as f32;
        let (top, bottom) = (self.cos_theta[row], self.cos_theta[row + 1]);
        let cos_theta = top + along_row * (bottom - top);
        let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
        let dir = self.world_from_dome(sin_theta as f32, cos_theta as f32, map_u);
        // The pdf and radiance a ray leaving in `dir` would find, so that the
        // two strategies of multiple importance sampling agree exactly.
        let (radiance, found, pdf) = self.radiance_and_pdf(dir);
        (found == part && pdf > 0.0).then_some((dir, radiance, pdf))
    }

    /// Solid-angle density with which [`DomeSampler::sample`] picks `dir`.
    pub(crate) fn pdf(&self, dir: Vec3) -> f32 {
        let total = self.total();
        if total <= 0.0 {
            return 0.0;
        }
        let (part, pdf) = self.part_pdf(dir);
        (pdf as f64 * self.part_power(part) / total) as f32
    }

    /// The part of the dome in direction `dir`, and the solid-angle density
    /// with which [`DomeSampler::sample_part`] of that part picks it.
    pub(crate) fn part_pdf(&self, dir: Vec3) -> (DomePart, f32) {
        let (d, uv) = self.in_map(dir);
        self.pdf_at(d, uv)
    }

    /// [`DomeSampler::part_pdf`] of the dome-frame direction `d` at map coordinates `uv`.
    fn pdf_at(&self, d: Vec3, uv: Vec2) -> (DomePart, f32) {
        let (w, h) = (self.dome.width as usize, self.dome.height as usize);
        let column = ((uv.x * w as f32) as usize).min(w - 1);
        let row = ((uv.y * h as f32) as usize).min(h - 1);
        let i = row * w + column;
        let solid_angle = self.cell_solid_angle[row];
        if let Ok(k) = self.sun.cells.binary_search(&(i as u32)) {
            // The sub-cell: equal steps in u and in cos(theta) across the cell.
            let (top, bottom) = (self.cos_theta[row], self.cos_theta[row + 1]);
            let down = ((d.y as f64 - top) / (bottom - top) * SUN_SPLIT as f64) as usize;
            let across = ((uv.x * w as f32 - column as f32) * SUN_SPLIT as f32) as usize;
            let sub = k * SUN_SPLIT * SUN_SPLIT + down.min(SUN_SPLIT - 1) * SUN_SPLIT + across.min(SUN_SPLIT - 1);
            let weight = self.sun.cdf[sub] - if sub == 0 { 0.0 } else { self.sun.cdf[sub - 1] };
            let total = self.part_power(DomePart::Sun);
            let sub_solid_angle = solid_angle / (SUN_SPLIT * SUN_SPLIT) as f64;
            return (DomePart::Sun, (weight / (total * sub_solid_angle)) as f32);
        }
        let rest_total = self.part_power(DomePart::Rest);
        if rest_total <= 0.0 {
            return (DomePart::Rest, 0.0);
        }
        let weight = self.row_cdf[i] - if column == 0 { 0.0 } else { self.row_cdf[i - 1] };
        (DomePart::Rest, (weight / (rest_total * solid_angle)) as f32)
    }

    /// Dome (map) frame to world: turned by `rotate` about +Y.
    fn world_from_dome(&self, sin_theta: f32, cos_theta: f32, map_u: f32) -> Vec3 {
        let (sin_phi, cos_phi) = (PI - 2.0 * PI * map_u).sin_cos();
        let d = Vec3::new(sin_theta * cos_phi, cos_theta, -sin_theta * sin_phi);
        let (c, s) = (self.cos_rotate, self.sin_rotate);
        Vec3::new(c * d.x + s * d.z, d.y, c * d.z - s * d.x)
    }

    /// World to the dome (map) frame: turned by `-rotate` about +Y.
    fn dome_from_world(&self, d: Vec3) -> Vec3 {
        let (c, s) = (self.cos_rotate, self.sin_rotate);
        Vec3::new(c * d.x - s * d.z, d.y, c * d.z + s * d.x)
    }

    /// Bilinear radiance at map coordinates, texel centres at half-integers.
    fn lookup(&self, uv: Vec2) -> Vec3 {
        let (w, h) = (self.dome.width as i64, self.dome.height as i64);
        let (x, y) = (uv.x * w as f32 - 0.5, uv.y * h as f32 - 0.5);
        let (x0, y0) = (x.floor(), y.floor());
        let (fx, fy) = (x - x0, y - y0);
        let left = (x0 as i64).rem_euclid(w);
        let right = (left + 1) % w;
        let (up, down) = ((y0 as i64).clamp(0, h - 1), (y0 as i64 + 1).clamp(0, h - 1));
        let texel = |i: i64, j: i64| self.dome.texels[(j * w + i) as usize];
        let upper = texel(left, up).lerp(texel(right, up), fx);
        let lower = texel(left, down).lerp(texel(right, down), fx);
        upper.lerp(lower, fy) * self.dome.scale
    }
}

/// The dome's sun, if it has one: the cells brighter than [`SUN_CONTRAST`]
/// times the mean radiance, when together they are small
/// ([`SUN_MAX_SOLID_ANGLE`], [`SUN_MAX_CELLS`]) and carry much of the light ([`SUN_MIN_SHARE`]).
/// Sampled apart from the rest, a sunny dome gives sunlit surfaces the
/// clean light of a sun lamp: a single distribution over both spends a
/// random share of each pixel's samples on the sun.
fn find_sun(weights: &[f64], cell_solid_angle: &[f64], w: usize) -> Vec<u32> {
    let total: f64 = weights.iter().sum();
    if !(total > 0.0) {
        return Vec::new();
    }
    let bright = SUN_CONTRAST * total / (4.0 * PI64);
    let (mut cells, mut solid_angle, mut sum) = (Vec::new(), 0.0, 0.0);
    for (i, &weight) in weights.iter().enumerate() {
        let omega = cell_solid_angle[i / w];
        if weight > bright * omega {
            solid_angle += omega;
            if solid_angle > SUN_MAX_SOLID_ANGLE || cells.len() == SUN_MAX_CELLS {
                return Vec::new();
            }
            sum += weight;
            cells.push(i as u32);
        }
    }
    if sum < SUN_MIN_SHARE * total {
        return Vec::new();
    }
    cells
}

/// The bin of an inclusive running sum `cdf` that holds `target` (in [0,
/// total)), and where in it `target` falls (0..1). Never a bin of weight 0.
fn pick(cdf: &[f64], target: f64) -> (usize, f64) {
    let i = cdf.partition_point(|&c| c <= target).min(cdf.len() - 1);
    let low = if i == 0 { 0.0 } else { cdf[i - 1] };
    let weight = cdf[i] - low;
    let along = if weight > 0.0 { ((target - low) / weight).clamp(0.0, 1.0) } else { 0.5 };
    (i, along)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::render::sampler::hash_words;

    fn dome(width: u32, texel: impl Fn(u32, u32) -> Vec3, rotate: f32) -> Arc<Dome> {
        let height = width / 2;
        let texels = (0..height).flat_map(|y| (0..width).map(move |x| (x, y))).map(|(x, y)| texel(x, y)).collect();
        Arc::new(Dome {
            file: "test.hdr".into(),
            width,
            height,
            texels,
            scale: Vec3::ONE,
            rotate,
            camera_visible: true,
        })
    }

    /// Mean luminance of the radiance over the sphere.
    fn mean_radiance(s: &DomeSampler) -> f32 {
        (s.total() / (4.0 * PI64)) as f32
    }

    fn random(n: u32, dim: u32) -> f32 {
        (hash_words(&[n, dim]) >> 8) as f32 / (1u32 << 24) as f32
    }

    /// A smooth map with a small bright patch (a sun) in row 5 of 16.
    fn sunny(x: u32, y: u32) -> Vec3 {
        let (fx, fy) = (x as f32 / 32.0, y as f32 / 16.0);
        let sky = Vec3::new(0.3 + 0.2 * (6.0 * fx).sin(), 0.4 + 0.3 * fy, 0.5 + 0.1 * (9.0 * fy).cos());
        if (20..22).contains(&x) && (5..7).contains(&y) {
            sky + Vec3::new(300.0, 280.0, 250.0)
        } else {
            sky
        }
    }

    /// Integral over the sphere of `f(direction(uv))` by the midpoint rule on
    /// an `n` x `n / 2` grid.
    fn quadrature(s: &DomeSampler, n: u32, f: impl Fn(Vec3) -> Vec3) -> Vec3 {
        let m = n / 2;
        let mut sum = Vec3::ZERO;
        for j in 0..m {
            let v = (j as f32 + 0.5) / m as f32;
            let area = 2.0 * PI * PI * (PI * v).sin() / (n * m) as f32;
            for i in 0..n {
                sum += f(s.direction(Vec2::new((i as f32 + 0.5) / n as f32, v))) * area;
            }
        }
        sum
    }

    #[test]
    fn uv_and_direction_round_trip() {
        let s = DomeSampler::new(dome(16, |_, _| Vec3::ONE, 0.7));
        for j in 1..20 {
            for i in 0..40 {
                let uv = Vec2::new(i as f32 / 40.0, j as f32 / 20.0);
                let d = s.direction(uv);
                assert!((d.length() - 1.0).abs() < 1e-6);
                let back = s.uv(d) - uv;
                // u = 0 and u = 1 are the same seam.
                let du = back.x - back.x.round();
                assert!(du.abs() < 1e-5 && back.y.abs() < 1e-5, "{uv} -> {d} -> {}", s.uv(d));
            }
        }
    }

    #[test]
    fn orientation_matches_blender_and_the_peers() {
        let still = DomeSampler::new(dome(16, |_, _| Vec3::ONE, 0.0));
        let close = |a: Vec3, b: Vec3| (a - b).length() < 1e-6;
        assert!(close(still.direction(Vec2::new(0.5, 0.5)), Vec3::X), "centre faces +X");
        assert!(close(still.direction(Vec2::new(0.25, 0.5)), -Vec3::Z), "u = 0.25 faces -Z");
        assert!(close(still.direction(Vec2::new(0.75, 0.5)), Vec3::Z));
        assert!(close(still.direction(Vec2::new(0.0, 0.5)), -Vec3::X));
        assert!(close(still.direction(Vec2::new(0.3, 0.0)), Vec3::Y), "top row is the zenith");
        let turned = DomeSampler::new(dome(16, |_, _| Vec3::ONE, PI / 2.0));
        assert!(close(turned.direction(Vec2::new(0.5, 0.5)), -Vec3::Z), "rotate 90: centre faces -Z");
        assert!((turned.uv(-Vec3::Z) - Vec2::new(0.5, 0.5)).length() < 1e-6);
    }

    #[test]
    fn radiance_is_bilinear_wraps_in_u_and_is_scaled() {
        let mut d = (*dome(4, |x, y| Vec3::splat((x + 10 * y) as f32), 0.0)).clone();
        d.scale = Vec3::new(1.0, 2.0, 0.5);
        let s = DomeSampler::new(Arc::new(d));
        let at = |u: f32, v: f32| s.radiance(s.direction(Vec2::new(u, v)));
        // Texel centre (1, 0) and the midpoint between (1, 0) and (2, 1).
        assert!((at(1.5 / 4.0, 0.25) - Vec3::new(1.0, 2.0, 0.5)).abs().max_element() < 1e-4);
        assert!((at(0.5, 0.5) - Vec3::new(6.5, 13.0, 3.25)).abs().max_element() < 1e-4);
        // The seam: halfway between texel 3 and texel 0 of row 0.
        assert!((at(0.0, 0.25) - Vec3::new(1.5, 3.0, 0.75)).abs().max_element() < 1e-3);
    }

    #[test]
    fn constant_dome_has_uniform_pdf() {
        let s = DomeSampler::new(dome(32, |_, _| Vec3::splat(2.0), 1.1));
        for n in 0..500 {
            let dir = s.direction(Vec2::new(random(n, 0), random(n, 1)));
            assert!((s.pdf(dir) * 4.0 * PI - 1.0).abs() < 1e-5, "{dir}: {}", s.pdf(dir));
        }
        assert!((mean_radiance(&s) - 2.0).abs() < 1e-5);
        let (_, radiance, pdf) = s.sample(Vec2::new(0.3, 0.999_999)).unwrap();
        assert!((pdf * 4.0 * PI - 1.0).abs() < 1e-5 && (radiance - Vec3::splat(2.0)).length() < 1e-5);
    }

    #[test]
    fn pdf_integrates_to_one_and_matches_the_samples() {
        let s = DomeSampler::new(dome(32, sunny, 0.4));
        let integral = quadrature(&s, 512, |d| Vec3::splat(s.pdf(d)));
        assert!((integral.x - 1.0).abs() < 2e-3, "{integral}");
        // Where the samples land, cell by cell, against pdf x solid angle.
        let (w, h, n) = (32usize, 16usize, 200_000u32);
        let mut counts = vec![0u32; w * h];
        for k in 0..n {
            let (dir, radiance, pdf) = s.sample(Vec2::new(random(k, 0), random(k, 1))).unwrap();
            assert_eq!(pdf, s.pdf(dir));
            assert_eq!(radiance, s.radiance(dir));
            let uv = s.uv(dir);
            counts[((uv.y * h as f32) as usize).min(h - 1) * w + ((uv.x * w as f32) as usize).min(w - 1)] += 1;
        }
        for j in 0..h {
            for i in 0..w {
                let centre = s.direction(Vec2::new((i as f32 + 0.5) / w as f32, (j as f32 + 0.5) / h as f32));
                let expected = s.pdf(centre) as f64 * s.cell_solid_angle[j] * n as f64;
                let got = counts[j * w + i] as f64;
                assert!((got - expected).abs() < 5.0 * expected.sqrt() + 2.0, "cell {i},{j}: {got} vs {expected}");
            }
        }
    }

    #[test]
    fn estimator_integrates_the_dome() {
        let s = DomeSampler::new(dome(32, sunny, 2.0));
        let n = 1u32 << 16;
        let mut sum = Vec3::ZERO;
        for k in 0..n {
            let (_, radiance, pdf) = s.sample(Vec2::new(random(k, 0), random(k, 1))).unwrap();
            sum += radiance / pdf;
        }
        let estimate = sum / n as f32;
        // The bilinear radiance, finely integrated.
        let fine = quadrature(&s, 1024, |d| s.radiance(d));
        // The texels with sin(theta), as a lighter would add them up.
        let (w, h) = (32u32, 16u32);
        let mut texels = Vec3::ZERO;
        for j in 0..h {
            let theta = PI * (j as f32 + 0.5) / h as f32;
            for i in 0..w {
                texels += sunny(i, j) * theta.sin() * 2.0 * PI * PI / (w * h) as f32;
            }
        }
        for reference in [fine, texels] {
            let error = (estimate / reference - 1.0).abs().max_element();
            assert!(error < 0.01, "{estimate} vs {reference}");
        }
        assert!((mean_radiance(&s) - luminance(fine) / (4.0 * PI)).abs() < 2e-3 * mean_radiance(&s));
    }

    /// A 256 x 128 map with a 2 x 2 texel sun: its cells form a part of
    /// their own, and the parts together are still one distribution: its
    /// samples cover the sphere (the mean of 1 / pdf is 4 pi) and integrate
    /// the dome.
    #[test]
    fn a_small_bright_sun_is_a_part_of_its_own() {
        let (w, h) = (256u32, 128u32);
        let sun = |x: u32, y: u32| {
            let sky = Vec3::new(0.3, 0.4, 0.5 + 0.1 * (y as f32 / 64.0));
            if (160..162).contains(&x) && (40..42).contains(&y) {
                sky + Vec3::splat(2e4)
            } else {
                sky
            }
        };
        let s = DomeSampler::new(dome(w, sun, 0.7));
        assert_eq!(s.parts().collect::<Vec<_>>(), [DomePart::Sun, DomePart::Rest]);
        let share = s.part_power(DomePart::Sun) / s.total();
        assert!(share > 0.5, "the sun carries {share}");
        // Each part's samples report that part, its pdf and radiance.
        for part in [DomePart::Sun, DomePart::Rest] {
            for k in 0..2000 {
                let (dir, radiance, pdf) = s.sample_part(part, Vec2::new(random(k, 0), random(k, 1))).unwrap();
                assert_eq!(s.part_pdf(dir), (part, pdf));
                assert_eq!(radiance, s.radiance(dir));
            }
        }
        let n = 1u32 << 16;
        let (mut measure, mut light) = (0f64, 0f64);
        for k in 0..n {
            let (_, radiance, pdf) = s.sample(Vec2::new(random(k, 2), random(k, 3))).unwrap();
            measure += 1.0 / pdf as f64;
            light += radiance.x as f64 / pdf as f64;
        }
        let sphere = measure / n as f64 / (4.0 * PI64);
        assert!((sphere - 1.0).abs() < 0.02, "the samples cover {sphere} of the sphere");
        // The texels with sin(theta), in f64, as a lighter would add them up.
        let mut texels = 0f64;
        for j in 0..h {
            let theta = PI64 * (j as f64 + 0.5) / h as f64;
            for i in 0..w {
                texels += sun(i, j).x as f64 * theta.sin() * 2.0 * PI64 * PI64 / (w * h) as f64;
            }
        }
        let error = (light / n as f64 / texels - 1.0).abs();
        assert!(error < 0.01, "{} vs {texels}", light / n as f64);
    }

    #[test]
    fn a_hot_texel_draws_the_samples() {
        let (hot_x, hot_y) = (20u32, 5u32);
        let s = DomeSampler::new(dome(32, |x, y| Vec3::splat(if (x, y) == (hot_x, hot_y) { 1e4 } else { 1e-3 }), 0.0));
        let (mut inside, mut near) = (0u32, 0u32);
        let n = 20_000u32;
        for k in 0..n {
            let (dir, _, _) = s.sample(Vec2::new(random(k, 0), random(k, 1))).unwrap();
            let uv = s.uv(dir);
            let (x, y) = ((uv.x * 32.0) as i32, (uv.y * 16.0) as i32);
            inside += ((x, y) == (hot_x as i32, hot_y as i32)) as u32;
            near += ((x - hot_x as i32).abs() <= 1 && (y - hot_y as i32).abs() <= 1) as u32;
        }
        // The bilinear lookup spreads the texel over its 3 x 3 cells, 9/16 of
        // it in its own: the samples follow.
        let share = inside as f32 / n as f32;
        assert!((share - 9.0 / 16.0).abs() < 0.03, "{share}");
        assert!(near as f32 / n as f32 > 0.999, "{near}");
    }

    #[test]
    fn pdf_is_positive_wherever_radiance_is() {
        let s = DomeSampler::new(dome(16, |x, y| if (x, y) == (3, 0) { Vec3::ONE } else { Vec3::ZERO }, 0.3));
        let mut lit = 0;
        for j in 0..200 {
            for i in 0..400 {
                let d = s.direction(Vec2::new((i as f32 + 0.5) / 400.0, (j as f32 + 0.5) / 200.0));
                if s.radiance(d).max_element() > 0.0 {
                    lit += 1;
                    assert!(s.pdf(d) > 0.0, "{d}");
                }
            }
        }
        assert!(lit > 100);
        let black = DomeSampler::new(dome(16, |_, _| Vec3::ZERO, 0.0));
        assert!(black.sample(Vec2::new(0.5, 0.5)).is_none());
        assert_eq!((black.pdf(Vec3::Y), mean_radiance(&black)), (0.0, 0.0));
    }
}
