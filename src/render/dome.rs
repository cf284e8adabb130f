//! Looking up and importance-sampling an HDRI dome ([`Dome`]).
//!
//! Orientation (docs/lights.md, "The dome"; Blender's world and the peer
//! harness): for a world direction d, let d' be d turned by `-rotate` about
//! +Y; then u = (pi - atan2(-d'.z, d'.x)) / (2 pi), v = acos(d'.y) / pi, with
//! v = 0 the top row. At `rotate` 0 the image centre faces +X.
//!
//! Radiance is bilinear between texel centres (wrapping in u, clamped in v)
//! for what is seen sharply ([`Lookup::Bilinear`]); light on rough surfaces
//! takes the rest of the dome (all but its sun) as each block's mean
//! ([`Lookup::Blocks`], see there).
//! Sampling is piecewise constant over blocks of texel cells (one cell per
//! block up to [`REST_MAX_COLUMNS`] texels across, square blocks of a power
//! of two beyond): a block is picked with probability proportional to the
//! mean luminance of the bilinear radiance over its cells times their solid
//! angle (a marginal distribution over block rows, a conditional one along
//! each), then a direction uniformly in solid angle within it. So the
//! density is constant over each block, exactly 1 / (4 pi) everywhere for a
//! constant map, and positive wherever the radiance is (the cell mean sees
//! every texel the bilinear lookup reads), as multiple importance sampling
//! needs. The sun, where a map has one, is sampled apart, finer than a texel.

use std::f32::consts::PI;
use std::f64::consts::PI as PI64;
use std::sync::Arc;

use glam::{DVec3, Vec2, Vec3};

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

/// How finely a direction's radiance is looked up. Light reaching a rough
/// surface (next-event estimation there, and the BSDF rays weighed against
/// it) takes the rest of the dome as its blocks' mean radiance
/// ([`Lookup::Blocks`]): constant where the sampling density is, so every
/// such sample carries the same light over its pdf but for colour, and one
/// fetch from a table of 16 bytes per block (512 KiB at most, which stays
/// in cache where a 1k map's texels, 6 MiB, missed it on every lookup).
/// A block is at most 1/256 of the map across (1.4 degrees), far narrower
/// than a rough lobe. What is seen sharply, camera rays and mirror-like
/// lobes, is [`Lookup::Bilinear`]. The sun is bilinear in both: its own
/// distribution follows that.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Lookup {
    /// Bilinear between texel centres.
    Bilinear,
    /// The rest of the dome as its blocks' mean radiance.
    Blocks,
}

/// One block of the rest's distribution: the mean radiance of its cells
/// that are not the sun's, and its solid-angle density within the rest.
#[derive(Clone, Copy, Debug, Default)]
#[repr(C, align(16))]
struct Block {
    radiance: [f32; 3],
    pdf: f32,
}

/// Cells brighter than this many times the dome's mean radiance may be its sun.
const SUN_CONTRAST: f64 = 50.0;
/// ... if together they span at most this solid angle (sr; the real sun is
/// 6.8e-5, a 1k map's sun with its bilinear spread about 1e-3) ...
const SUN_MAX_SOLID_ANGLE: f64 = 0.02;
/// ... and carry at least this share of the dome's light; and are at most
/// this many (a sun at the pole of a 16k map spans whole rows of tiny cells).
const SUN_MIN_SHARE: f64 = 0.2;
const SUN_MAX_CELLS: usize = 4096;
/// The most quadrants the sun's window holds (16 K cells; 1.5 MiB of
/// corners and running sums): a wider window is no sun (bright cells
/// scattered over the map, which the rest samples as well).
const SUN_MAX_QUADRANTS: usize = 1 << 16;

/// The widest the distribution of the rest of the dome gets, in blocks:
/// 256 x 128 blocks of f64 running sums are 256 KiB, which stay in a core's
/// cache, where a 1k map's cells (4 MiB) made every draw's binary search a
/// string of cache misses. The rest of a dome is its smooth sky and ground
/// (the sun is sampled apart), so the coarser density costs little noise.
const REST_MAX_COLUMNS: usize = 256;

/// The sun part, sampled exactly as bright as it is: each sun cell is four
/// quadrants (split on the texel-centre lines, where the bilinear lookup
/// bends), each quadrant one bilinear patch, picked by its integral and then
/// sampled in proportion to the patch itself, so a sample's radiance over
/// its pdf is the same everywhere on the sun but for sin(theta) and colour,
/// as a sun lamp's is. (A 1k map's sun is a few texels whose bilinear
/// spread varies by orders of magnitude across a cell: constant densities
/// over 8 x 8 sub-cells left 10 % of noise in every sunlit sample.) The
/// quadrants form a window of cells around the sun, with a marginal over
/// its quadrant rows and a conditional along each, so a pixel's stratified
/// samples spread over the sun's disc; quadrants of cells that are not the
/// sun's weigh nothing.
#[derive(Clone, Debug, Default)]
struct Sun {
    cells: Vec<u32>,
    window: SunWindow,
    /// Running sums (inclusive) of the quadrant row weights, top first.
    marginal: Vec<f64>,
    /// Running sums (inclusive) of the quadrant weights along each quadrant
    /// row (a quadrant weighs the sum of its corners' luminance).
    conditional: Vec<f64>,
    /// Each quadrant's luminance at its corners: top left, top right,
    /// bottom left, bottom right (u right, v down).
    corners: Vec<[f32; 4]>,
    /// The integral of luminance over the sun's quadrants in map
    /// coordinates (du dv), and over the sphere (d omega).
    uv_total: f64,
    power: f64,
}

/// Where the sun's window lies: `rows` cells down from `row`, `columns`
/// across from `column` (wrapping in u).
#[derive(Clone, Copy, Debug, Default)]
struct SunWindow {
    row: usize,
    rows: usize,
    column: usize,
    columns: usize,
}

impl SunWindow {
    /// The smallest window around `cells` of a map `w` cells wide (across
    /// the u seam when that is narrower); None when it would hold more
    /// than [`SUN_MAX_QUADRANTS`].
    fn around(cells: &[u32], w: usize) -> Option<SunWindow> {
        let (first, last) = (*cells.first()? as usize / w, *cells.last()? as usize / w);
        let mut occupied = vec![false; w];
        for &c in cells {
            occupied[c as usize % w] = true;
        }
        // The window starts after the longest run of empty columns (circular).
        let (mut best, mut best_end, mut run) = (0, 0, 0);
        for i in 0..2 * w {
            run = if occupied[i % w] { 0 } else { run + 1 };
            if run > best && run < w {
                (best, best_end) = (run, i % w);
            }
        }
        let (column, columns) = ((best_end + 1) % w, w - best);
        let rows = last - first + 1;
        (4 * rows * columns <= SUN_MAX_QUADRANTS).then_some(SunWindow { row: first, rows, column, columns })
    }

    /// Quadrants across the window.
    fn quadrant_columns(&self) -> usize {
        2 * self.columns
    }
}

/// A number in [0, 1) with density proportional to (1 - x) a + x b (a, b
/// at least 0), from a uniform `u`: the inverse of the linear density's
/// running integral.
fn sample_linear(u: f32, a: f32, b: f32) -> f32 {
    if !(a + b > 0.0) {
        return u;
    }
    let x = u * (a + b) / (a + (a * a + u * (b * b - a * a)).max(0.0).sqrt());
    x.clamp(0.0, 1.0 - f32::EPSILON)
}

/// A dome ready to be looked up and sampled. Building it costs a few passes
/// over the texels and 8 bytes per texel while it runs (it keeps 22 bytes
/// per block and 40 per sun quadrant): build one per loaded dome and share it.
#[derive(Clone, Debug)]
pub struct DomeSampler {
    dome: Arc<Dome>,
    cos_rotate: f32,
    sin_rotate: f32,
    /// Blocks of the rest's distribution are `1 << block_shift` cells square
    /// (the last block of a row or column may be short).
    block_shift: u32,
    /// Blocks across and down.
    blocks: (usize, usize),
    /// Running sums (inclusive) of the block weights along each block row
    /// over the row's total, row-major, in f32 (half the cache a draw's
    /// search walks; the sun's cells weigh nothing here: they are the sun
    /// part's).
    row_cdf: Vec<f32>,
    /// Each block's mean radiance and solid-angle density within the rest
    /// (kept apart from the running sums, so a small block's density is not
    /// the difference of two large ones).
    block: Vec<Block>,
    /// The blocks that hold a sun cell (sorted): a draw there may land on
    /// the sun, which is the sun part's.
    sun_blocks: Vec<u32>,
    /// Running sums (inclusive) of the block row totals, top row first.
    marginal_cdf: Vec<f64>,
    /// Guides ([`guide`]) to the marginal, and to each row's running sums
    /// (one per block across, row-major).
    marginal_guide: Vec<u16>,
    row_guide: Vec<u16>,
    /// cos(theta) at each row boundary, `height + 1` values from +1 (zenith).
    cos_theta: Vec<f64>,
    /// The sun, when the dome has one.
    sun: Sun,
}

impl DomeSampler {
    /// Builds the lookup and the sampling distributions of `dome`.
    pub fn new(dome: Arc<Dome>) -> DomeSampler {
        let (w, h) = (dome.width as usize, dome.height as usize);
        let texel = |i: usize, j: usize| (dome.texels[j * w + i] * dome.scale).max(Vec3::ZERO);
        // The mean of a bilinear interpolant over a texel's cell weighs the
        // texel and its neighbours 1/8, 3/4, 1/8 along each axis. Computed
        // where needed (twice a cell) rather than kept: a 16k map's texels
        // are already 1.5 GiB.
        let across = |i: usize, j: usize| {
            let (left, right) = ((i + w - 1) % w, (i + 1) % w);
            (texel(left, j) + 6.0 * texel(i, j) + texel(right, j)) / 8.0
        };
        let cell_mean = |i: usize, j: usize| {
            let (up, down) = (j.saturating_sub(1), (j + 1).min(h - 1));
            (across(i, up) + 6.0 * across(i, j) + across(i, down)) / 8.0
        };
        let cos_theta: Vec<f64> = (0..=h).map(|j| (PI64 * j as f64 / h as f64).cos()).collect();
        let cell_solid_angle: Vec<f64> = (0..h)
            .map(|j| {
                // cos a - cos b = 2 sin((a + b) / 2) sin((b - a) / 2), exact near the poles.
                let (a, b) = (PI64 * j as f64 / h as f64, PI64 * (j + 1) as f64 / h as f64);
                2.0 * ((a + b) / 2.0).sin() * ((b - a) / 2.0).sin() * 2.0 * PI64 / w as f64
            })
            .collect();
        // Each cell's weight: its mean luminance x solid angle. Computed
        // where needed rather than kept (a 16k map's would be 1 GiB of f64).
        let weight_of = |mean: Vec3, omega: f64| luminance(mean).max(0.0) as f64 * omega;
        let mut sun_cells = find_sun(|i, j| weight_of(cell_mean(i, j), cell_solid_angle[j]), &cell_solid_angle, w);
        let window = SunWindow::around(&sun_cells, w);
        if window.is_none() {
            sun_cells.clear();
        }
        let mut block_shift = 0;
        while w.div_ceil(1 << block_shift) > REST_MAX_COLUMNS {
            block_shift += 1;
        }
        let blocks = (w.div_ceil(1 << block_shift), h.div_ceil(1 << block_shift));
        let mut row_cdf = vec![0f64; blocks.0 * blocks.1];
        // Per block: the sum of its rest cells' mean radiance x solid angle, and their solid angle.
        let mut light = vec![(DVec3::ZERO, 0f64); row_cdf.len()];
        let mut sun_blocks = Vec::new();
        // The sun's cells, in cell order: the next one still to pass.
        let mut next_sun = sun_cells.iter().peekable();
        for (j, &omega) in cell_solid_angle.iter().enumerate() {
            for i in 0..w {
                let b = (j >> block_shift) * blocks.0 + (i >> block_shift);
                if next_sun.peek().is_some_and(|&&c| c as usize == j * w + i) {
                    next_sun.next();
                    sun_blocks.push(b as u32);
                    continue;
                }
                let mean = cell_mean(i, j);
                row_cdf[b] += weight_of(mean, omega);
                light[b].0 += mean.as_dvec3() * omega;
                light[b].1 += omega;
            }
        }
        sun_blocks.sort_unstable();
        sun_blocks.dedup();
        let mut marginal_cdf = vec![0f64; blocks.1];
        let mut rest_total = 0f64;
        for (row, running) in row_cdf.chunks(blocks.0).zip(&mut marginal_cdf) {
            rest_total += row.iter().sum::<f64>();
            *running = rest_total;
        }
        let block_span = |block: usize, cells: usize| (block << block_shift)..((block + 1) << block_shift).min(cells);
        let mut block = vec![Block::default(); row_cdf.len()];
        let mut conditional = vec![0f32; row_cdf.len()];
        for (b, (&weight, &(sum, rest_solid_angle))) in row_cdf.iter().zip(&light).enumerate() {
            let (rows, columns) = (block_span(b / blocks.0, h), block_span(b % blocks.0, w));
            let solid_angle =
                (cos_theta[rows.start] - cos_theta[rows.end]) * 2.0 * PI64 * columns.len() as f64 / w as f64;
            if rest_total > 0.0 {
                block[b].pdf = (weight / (rest_total * solid_angle)) as f32;
            }
            if rest_solid_angle > 0.0 {
                block[b].radiance = (sum / rest_solid_angle).as_vec3().to_array();
            }
        }
        for (row, cdf) in row_cdf.chunks(blocks.0).zip(conditional.chunks_mut(blocks.0)) {
            let total: f64 = row.iter().sum();
            let mut sum = 0f64;
            for (weight, c) in row.iter().zip(cdf) {
                sum += weight;
                *c = if total > 0.0 { (sum / total) as f32 } else { 0.0 };
            }
        }
        let (sin_rotate, cos_rotate) = dome.rotate.sin_cos();
        let mut sampler = DomeSampler {
            dome,
            cos_rotate,
            sin_rotate,
            block_shift,
            blocks,
            marginal_guide: guide(&marginal_cdf, rest_total, blocks.1),
            row_guide: conditional.chunks(blocks.0).flat_map(|row| guide(row, 1.0, blocks.0)).collect(),
            row_cdf: conditional,
            block,
            sun_blocks,
            marginal_cdf,
            cos_theta,
            sun: Sun::default(),
        };
        // The sun's sub-cells are weighed by the bilinear lookup, so after the rest.
        if let Some(window) = window {
            sampler.sun = sampler.split_sun(sun_cells, window);
        }
        sampler
    }

    /// The sun part over `cells`, quadrant by quadrant of `window`.
    fn split_sun(&self, cells: Vec<u32>, window: SunWindow) -> Sun {
        let (w, h) = (self.dome.width as usize, self.dome.height as usize);
        let (rows, columns) = (2 * window.rows, window.quadrant_columns());
        let mut conditional = Vec::with_capacity(rows * columns);
        let mut corners = Vec::with_capacity(rows * columns);
        let mut marginal = Vec::with_capacity(rows);
        let (mut total, mut power) = (0f64, 0f64);
        // A quadrant's area in map coordinates.
        let area = 1.0 / (4.0 * w as f64 * h as f64);
        let luminance_at =
            |x: f64, y: f64| luminance(self.lookup(Vec2::new((x / w as f64) as f32, (y / h as f64) as f32))).max(0.0);
        for qr in 0..rows {
            let row = window.row + qr / 2;
            let (top, bottom) = (row as f64 + (qr % 2) as f64 * 0.5, row as f64 + (qr % 2 + 1) as f64 * 0.5);
            let sin_theta = (PI64 * (top + bottom) / 2.0 / h as f64).sin();
            let mut sum = 0f64;
            for qc in 0..columns {
                let column = (window.column + qc / 2) % w;
                let mut quad = [0f32; 4];
                if cells.binary_search(&((row * w + column) as u32)).is_ok() {
                    let (left, right) =
                        (column as f64 + (qc % 2) as f64 * 0.5, column as f64 + (qc % 2 + 1) as f64 * 0.5);
                    quad = [
                        luminance_at(left, top),
                        luminance_at(right, top),
                        luminance_at(left, bottom),
                        luminance_at(right, bottom),
                    ];
                }
                let weight: f64 = quad.iter().map(|&c| c as f64).sum();
                sum += weight;
                power += weight / 4.0 * area * 2.0 * PI64 * PI64 * sin_theta;
                conditional.push(sum);
                corners.push(quad);
            }
            total += sum;
            marginal.push(total);
        }
        if !(total > 0.0) {
            return Sun::default();
        }
        Sun { cells, window, marginal, conditional, corners, uv_total: total / 4.0 * area, power }
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
            DomePart::Sun => self.sun.power,
            // The marginal's last running sum: every rest cell's weight.
            DomePart::Rest => self.marginal_cdf.last().copied().unwrap_or(0.0),
        }
    }

    /// A cone holding the sun's cells: its axis and the cosine of its half
    /// angle (grown by a cell, so the bilinear spread at its rim is in it);
    /// `None` without a sun. What the sun can give a shading point is bound
    /// by its power and the widened cosine to this cone (render::lights).
    pub(crate) fn sun_cone(&self) -> Option<(Vec3, f32)> {
        let (w, h) = (self.dome.width as usize, self.dome.height as usize);
        let centre = |c: u32| {
            let (i, j) = (c as usize % w, c as usize / w);
            self.direction(Vec2::new((i as f32 + 0.5) / w as f32, (j as f32 + 0.5) / h as f32))
        };
        let axis = self.sun.cells.iter().map(|&c| centre(c)).sum::<Vec3>().normalize_or_zero();
        if axis == Vec3::ZERO {
            return None;
        }
        let widest = self.sun.cells.iter().map(|&c| axis.dot(centre(c)).clamp(-1.0, 1.0).acos()).fold(0.0, f32::max);
        let half = (widest + 2.0 * PI / w as f32).min(PI);
        Some((axis, half.cos()))
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

    /// The radiance of `dir`, looked up as `lookup` says, its part and its
    /// density within that part (what a ray escaping into the dome needs),
    /// mapping it once.
    pub(crate) fn radiance_and_pdf(&self, dir: Vec3, lookup: Lookup) -> (Vec3, DomePart, f32) {
        let (d, uv) = self.in_map(dir);
        self.at(d.y, uv, lookup)
    }

    /// [`DomeSampler::radiance_and_pdf`] of the direction at map coordinates
    /// `uv` whose cos(theta) in the dome's frame is `cos_theta`.
    fn at(&self, cos_theta: f32, uv: Vec2, lookup: Lookup) -> (Vec3, DomePart, f32) {
        let (w, h) = (self.dome.width as usize, self.dome.height as usize);
        let column = ((uv.x * w as f32) as usize).min(w - 1);
        let row = ((uv.y * h as f32) as usize).min(h - 1);
        if self.is_sun(row, column) {
            let radiance = self.lookup(uv);
            let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
            return (radiance, DomePart::Sun, self.sun_pdf(radiance, sin_theta));
        }
        let block = self.block[(row >> self.block_shift) * self.blocks.0 + (column >> self.block_shift)];
        let radiance = match lookup {
            Lookup::Bilinear => self.lookup(uv),
            Lookup::Blocks => Vec3::from_array(block.radiance),
        };
        (radiance, DomePart::Rest, block.pdf)
    }

    /// The solid-angle density of the sun part at a direction of radiance
    /// `radiance` and sin(theta) `sin_theta` in the dome's frame: in map
    /// coordinates luminance / its integral, per solid angle divided by
    /// d omega / (du dv) = 2 pi^2 sin(theta).
    fn sun_pdf(&self, radiance: Vec3, sin_theta: f32) -> f32 {
        let pdf = luminance(radiance).max(0.0) as f64 / (self.sun.uv_total * 2.0 * PI64 * PI64 * sin_theta as f64);
        if pdf.is_finite() {
            pdf as f32
        } else {
            0.0
        }
    }

    /// Whether cell (`row`, `column`) is one of the sun's.
    fn is_sun(&self, row: usize, column: usize) -> bool {
        let window = self.sun.window;
        let w = self.dome.width as usize;
        // Most directions are far from the sun: its window first.
        row.wrapping_sub(window.row) < window.rows
            && (column + w - window.column) % w < window.columns
            && self.sun.cells.binary_search(&((row * w + column) as u32)).is_ok()
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
        let (dir, radiance, _) = self.sample_part(part, u, Lookup::Bilinear)?;
        let pdf = self.pdf(dir);
        (pdf > 0.0).then_some((dir, radiance, pdf))
    }

    /// Samples a direction towards one part of the dome: (direction, its
    /// radiance looked up as `lookup` says, its solid-angle pdf within the
    /// part). None when the part has no light.
    pub(crate) fn sample_part(&self, part: DomePart, u: Vec2, lookup: Lookup) -> Option<(Vec3, Vec3, f32)> {
        let u = u.clamp(Vec2::ZERO, Vec2::splat(1.0 - f32::EPSILON));
        let (w, h) = (self.dome.width as usize, self.dome.height as usize);
        // cos(theta) and the map's u of the direction: uniform in both is
        // uniform in solid angle within a block or sub-cell.
        let (cos_theta, map_u) = match part {
            DomePart::Rest => {
                let rest_total = self.part_power(DomePart::Rest);
                if rest_total <= 0.0 {
                    return None;
                }
                let bw = self.blocks.0;
                let (block_row, along_row) =
                    pick_guided(&self.marginal_cdf, &self.marginal_guide, u.y as f64 * rest_total, rest_total);
                let row = block_row * bw..(block_row + 1) * bw;
                let (block_column, along_column) =
                    pick_guided(&self.row_cdf[row.clone()], &self.row_guide[row], u.x, 1.0);
                let (rows, columns) = (self.block_span(block_row, h), self.block_span(block_column, w));
                let (top, bottom) = (self.cos_theta[rows.start], self.cos_theta[rows.end]);
                let map_u = (columns.start as f64 + along_column * columns.len() as f64) / w as f64;
                let cos_theta = top + along_row * (bottom - top);
                let b = (block_row * bw + block_column) as u32;
                if lookup == Lookup::Blocks && self.sun_blocks.binary_search(&b).is_err() {
                    // The block is all rest: its radiance and density, no map lookup.
                    let block = self.block[b as usize];
                    let (cos_theta, map_u) = (cos_theta as f32, map_u as f32);
                    let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
                    let dir = self.world_from_dome(sin_theta, cos_theta, map_u);
                    return (block.pdf > 0.0).then_some((dir, Vec3::from_array(block.radiance), block.pdf));
                }
                (cos_theta, map_u)
            }
            DomePart::Sun => {
                let total = *self.sun.marginal.last()?;
                let (window, columns) = (self.sun.window, self.sun.window.quadrant_columns());
                let (qr, along_row) = pick(&self.sun.marginal, u.y as f64 * total);
                let cdf = &self.sun.conditional[qr * columns..(qr + 1) * columns];
                let (qc, along_column) = pick(cdf, u.x as f64 * cdf[columns - 1]);
                // Within the quadrant, in proportion to its bilinear patch.
                let [tl, tr, bl, br] = self.sun.corners[qr * columns + qc];
                let down = sample_linear(along_row as f32, tl + tr, bl + br);
                let across = sample_linear(along_column as f32, tl + (bl - tl) * down, tr + (br - tr) * down);
                let row = (window.row + qr / 2) as f64 + ((qr % 2) as f64 + down as f64) / 2.0;
                let column = (window.column + qc / 2) % w;
                let map_u = (column as f64 + ((qc % 2) as f64 + across as f64) / 2.0) / w as f64;
                // A sun cell by construction (other quadrants weigh nothing),
                // with its map coordinates at hand: no search, no acos.
                let cos_theta = (PI64 * row / h as f64).cos() as f32;
                let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
                let dir = self.world_from_dome(sin_theta, cos_theta, map_u as f32);
                let radiance = self.lookup(Vec2::new(map_u as f32, (row / h as f64) as f32));
                let pdf = self.sun_pdf(radiance, sin_theta);
                return (pdf > 0.0).then_some((dir, radiance, pdf));
            }
        };
        let (cos_theta, map_u) = (cos_theta as f32, map_u as f32);
        let sin_theta = (1.0 - cos_theta * cos_theta).max(0.0).sqrt();
        let dir = self.world_from_dome(sin_theta, cos_theta, map_u);
        // The pdf and radiance from the sample's own map coordinates: what a
        // ray leaving in `dir` finds (render::lights MIS), but for a sample on
        // a cell's edge that the direction's rounding puts across it.
        let uv = Vec2::new(map_u, cos_theta.clamp(-1.0, 1.0).acos() / PI);
        let (radiance, found, pdf) = self.at(cos_theta, uv, lookup);
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
        // The density does not depend on the lookup: the cheaper one.
        let (_, part, pdf) = self.radiance_and_pdf(dir, Lookup::Blocks);
        (part, pdf)
    }

    /// The cells (rows or columns, of `cells` in all) of block row or column `block`.
    fn block_span(&self, block: usize, cells: usize) -> std::ops::Range<usize> {
        (block << self.block_shift)..((block + 1) << self.block_shift).min(cells)
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
        // Wrapped without a division: x0 is in [-1, w - 1] for u in [0, 1].
        let left = (x0 as i64).clamp(-1, w - 1);
        let left = if left < 0 { left + w } else { left };
        let right = if left + 1 == w { 0 } else { left + 1 };
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
fn find_sun(weight: impl Fn(usize, usize) -> f64, cell_solid_angle: &[f64], w: usize) -> Vec<u32> {
    let mut total = 0.0;
    for j in 0..cell_solid_angle.len() {
        for i in 0..w {
            total += weight(i, j);
        }
    }
    if !(total > 0.0) {
        return Vec::new();
    }
    let bright = SUN_CONTRAST * total / (4.0 * PI64);
    let (mut cells, mut solid_angle, mut sum) = (Vec::new(), 0.0, 0.0);
    for (j, &omega) in cell_solid_angle.iter().enumerate() {
        for i in 0..w {
            let weight = weight(i, j);
            if weight > bright * omega {
                solid_angle += omega;
                if solid_angle > SUN_MAX_SOLID_ANGLE || cells.len() == SUN_MAX_CELLS {
                    return Vec::new();
                }
                sum += weight;
                cells.push((j * w + i) as u32);
            }
        }
    }
    if sum < SUN_MIN_SHARE * total {
        return Vec::new();
    }
    cells
}

/// The bin of an inclusive running sum `cdf` that holds `target` (in [0,
/// total)), and where in it `target` falls (0..1). Never a bin of weight 0.
fn pick<T: Into<f64> + Copy + PartialOrd>(cdf: &[T], target: T) -> (usize, f64) {
    let i = cdf.partition_point(|&c| c <= target).min(cdf.len() - 1);
    within(cdf, i, target)
}

/// Where in bin `i` of `cdf` `target` falls (0..1).
fn within<T: Into<f64> + Copy>(cdf: &[T], i: usize, target: T) -> (usize, f64) {
    let (target, high) = (target.into(), cdf[i].into());
    let low = if i == 0 { 0.0 } else { cdf[i - 1].into() };
    let weight = high - low;
    let along = if weight > 0.0 { ((target - low) / weight).clamp(0.0, 1.0) } else { 0.5 };
    (i, along)
}

/// A guide to an inclusive running sum over `total` (Devroye's guide
/// table): entry k is the bin [`pick`] finds for target k / n of the total,
/// so [`pick_guided`] starts there and walks a bin or two, where a binary
/// search's chain of dependent loads was a tenth of an HDRI render.
fn guide<T: Into<f64> + Copy + PartialOrd>(cdf: &[T], total: f64, n: usize) -> Vec<u16> {
    (0..n)
        .map(|k| {
            let target = k as f64 / n as f64 * total;
            cdf.partition_point(|&c| c.into() <= target).min(cdf.len() - 1) as u16
        })
        .collect()
}

/// [`pick`] by a [`guide`] of `cdf` over `total`: the same bin, always
/// (it walks from the guide's bin to the first running sum above `target`).
fn pick_guided<T: Into<f64> + Copy + PartialOrd>(cdf: &[T], guide: &[u16], target: T, total: f64) -> (usize, f64) {
    let k = ((target.into() / total * guide.len() as f64) as usize).min(guide.len() - 1);
    let mut i = guide[k] as usize;
    while i > 0 && cdf[i - 1] > target {
        i -= 1;
    }
    while i + 1 < cdf.len() && cdf[i] <= target {
        i += 1;
    }
    within(cdf, i, target)
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

    /// The solid angle of one cell of row `j`.
    fn cell_solid_angle(s: &DomeSampler, j: usize) -> f64 {
        (s.cos_theta[j] - s.cos_theta[j + 1]) * 2.0 * PI64 / s.dome.width as f64
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

    /// Whether a sample's `radiance` is what a ray leaving in `dir` finds, to
    /// the rounding of the direction (1e-6 in map coordinates, which on a
    /// sun's edge moves the bilinear radiance by more than its own rounding).
    fn what_a_ray_finds(s: &DomeSampler, dir: Vec3, radiance: Vec3) -> bool {
        let uv = s.uv(dir);
        let (lo, hi) =
            [Vec2::new(1e-6, 0.0), Vec2::new(0.0, 1e-6)].iter().fold((s.lookup(uv), s.lookup(uv)), |(lo, hi), &d| {
                let (a, b) = (s.lookup(uv - d), s.lookup(uv + d));
                (lo.min(a).min(b), hi.max(a).max(b))
            });
        let slack = 1e-5 * hi.max_element();
        radiance.cmpge(lo - slack).all() && radiance.cmple(hi + slack).all()
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
        let mut across_an_edge = 0;
        for k in 0..n {
            let (dir, radiance, pdf) = s.sample(Vec2::new(random(k, 0), random(k, 1))).unwrap();
            // What a ray leaving in `dir` finds: the same, but for samples
            // that the direction's rounding puts across a cell's edge.
            across_an_edge += (pdf != s.pdf(dir)) as u32;
            assert!(what_a_ray_finds(&s, dir, radiance), "{dir}: {radiance} vs {}", s.radiance(dir));
            let uv = s.uv(dir);
            counts[((uv.y * h as f32) as usize).min(h - 1) * w + ((uv.x * w as f32) as usize).min(w - 1)] += 1;
        }
        assert!(across_an_edge < n / 10_000, "{across_an_edge} samples disagree with their direction's pdf");
        for j in 0..h {
            for i in 0..w {
                let centre = s.direction(Vec2::new((i as f32 + 0.5) / w as f32, (j as f32 + 0.5) / h as f32));
                let expected = s.pdf(centre) as f64 * cell_solid_angle(&s, j) * n as f64;
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
            let mut across_an_edge = 0;
            for k in 0..2000 {
                let (dir, radiance, pdf) =
                    s.sample_part(part, Vec2::new(random(k, 0), random(k, 1)), Lookup::Bilinear).unwrap();
                // The sun's density follows its radiance, which the ray's
                // direction may find a rounding away.
                let (found, ray_pdf) = s.part_pdf(dir);
                let (ray, sample) = (luminance(s.radiance(dir)), luminance(radiance));
                across_an_edge += (found != part || (ray_pdf * sample / (pdf * ray) - 1.0).abs() > 1e-4) as u32;
                assert!(what_a_ray_finds(&s, dir, radiance), "{dir}: {radiance} vs {}", s.radiance(dir));
            }
            assert!(across_an_edge <= 2, "{part:?}: {across_an_edge} samples disagree with their direction's pdf");
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

    /// A sun across the u seam: its window is the columns either side (its
    /// texels' and, by the bilinear spread, their neighbours'), not the
    /// whole map, and its samples stay on it and integrate it.
    #[test]
    fn a_sun_across_the_seam_has_a_narrow_window() {
        let (w, h) = (256u32, 128u32);
        let sun = |x: u32, y: u32| {
            let sky = Vec3::new(0.3, 0.4, 0.5);
            if (x == 0 || x == w - 1) && (60..62).contains(&y) {
                sky + Vec3::splat(2e4)
            } else {
                sky
            }
        };
        let s = DomeSampler::new(dome(w, sun, 0.0));
        let window = s.sun.window;
        assert_eq!((window.row, window.rows, window.column, window.columns), (59, 4, 254, 4));
        let n = 1u32 << 14;
        let (mut light, mut least, mut most) = (0f64, f64::MAX, 0f64);
        for k in 0..n {
            let (dir, radiance, pdf) =
                s.sample_part(DomePart::Sun, Vec2::new(random(k, 0), random(k, 1)), Lookup::Bilinear).unwrap();
            let uv = s.uv(dir);
            let x = (uv.x * w as f32) as u32;
            assert!((x <= 1 || x >= w - 2) && (59..63).contains(&((uv.y * h as f32) as u32)), "{uv}");
            let each = luminance(radiance) as f64 / pdf as f64 / (PI64 * uv.y as f64).sin();
            (light, least, most) = (light + each, least.min(each), most.max(each));
        }
        // Sampled as bright as it is: every sample carries the same light
        // but for sin(theta), which the density over the map leaves out.
        assert!(most / least < 1.001, "{least} .. {most}");
        let error = (light / n as f64 / s.part_power(DomePart::Sun) - 1.0).abs();
        assert!(error < 0.01, "{error}");
    }

    /// A map wider than [`REST_MAX_COLUMNS`] is sampled by square blocks of
    /// cells: the density is constant over each, follows the light block by
    /// block, integrates to one, and the estimator still integrates the dome.
    #[test]
    fn a_wide_map_is_sampled_by_blocks() {
        let (w, h) = (1024u32, 512u32);
        let sky = |x: u32, y: u32| {
            sunny(x / 32, y / 32) + Vec3::splat(if (x / 3 + y / 5).is_multiple_of(7) { 2.0 } else { 0.0 })
        };
        let s = DomeSampler::new(dome(w, sky, 0.9));
        assert_eq!((s.block_shift, s.blocks), (2, (256, 128)));
        let integral = quadrature(&s, 1024, |d| Vec3::splat(s.pdf(d)));
        assert!((integral.x - 1.0).abs() < 2e-3, "{integral}");
        let (bw, bh, n) = (256usize, 128usize, 1u32 << 20);
        let mut counts = vec![0u32; bw * bh];
        let mut light = Vec3::ZERO;
        for k in 0..n {
            let (dir, radiance, pdf) =
                s.sample_part(DomePart::Rest, Vec2::new(random(k, 4), random(k, 5)), Lookup::Bilinear).unwrap();
            light += radiance / pdf;
            let uv = s.uv(dir);
            let (i, j) = ((uv.x * w as f32) as usize / 4, (uv.y * h as f32) as usize / 4);
            counts[j.min(bh - 1) * bw + i.min(bw - 1)] += 1;
        }
        for j in (0..bh).step_by(7) {
            for i in (0..bw).step_by(5) {
                // One density over the block: at its four inner corners as at its centre.
                let at = |fi: f32, fj: f32| {
                    let uv = Vec2::new((4 * i) as f32 + fi, (4 * j) as f32 + fj) / Vec2::new(w as f32, h as f32);
                    s.part_pdf(s.direction(uv)).1
                };
                let centre = at(2.0, 2.0);
                for (fi, fj) in [(0.1, 0.1), (3.9, 0.1), (0.1, 3.9), (3.9, 3.9)] {
                    assert!((at(fi, fj) / centre - 1.0).abs() < 1e-4, "block {i},{j}");
                }
                let solid_angle: f64 = (4 * j..4 * j + 4).map(|r| cell_solid_angle(&s, r) * 4.0).sum();
                let expected = centre as f64 * solid_angle * n as f64;
                let got = counts[j * bw + i] as f64;
                assert!((got - expected).abs() < 5.0 * expected.sqrt() + 2.0, "block {i},{j}: {got} vs {expected}");
            }
        }
        let fine = quadrature(&s, 2048, |d| s.radiance(d));
        let error = (light / n as f32 / fine - 1.0).abs().max_element();
        assert!(error < 0.01, "{} vs {fine}", light / n as f32);
    }

    /// Light for rough surfaces ([`Lookup::Blocks`]): every rest sample
    /// carries the rest's whole power over its pdf (in luminance), a ray
    /// leaving in a sample's direction finds the same radiance and density
    /// (so MIS weighs one function), and the estimator integrates the same
    /// light as the bilinear map's.
    #[test]
    fn blocks_light_rough_surfaces_with_the_maps_light() {
        let w = 1024u32;
        let sky = |x: u32, y: u32| {
            let (fx, fy) = (x as f32 / 1024.0, y as f32 / 512.0);
            let smooth = Vec3::new(0.3 + 0.2 * (6.0 * fx).sin(), 0.4 + 0.3 * fy, 0.5 + 0.1 * (9.0 * fy).cos());
            let base = smooth + Vec3::splat(if (x / 16 + y / 16).is_multiple_of(2) { 2.0 } else { 0.0 });
            // A sun of 3 x 2 texels, its cells a part of their own.
            if (600..603).contains(&x) && (150..152).contains(&y) {
                base + Vec3::new(1e5, 0.9e5, 0.8e5)
            } else {
                base
            }
        };
        let s = DomeSampler::new(dome(w, sky, 0.9));
        assert_eq!(s.parts().collect::<Vec<_>>(), [DomePart::Sun, DomePart::Rest]);
        assert!(!s.sun_blocks.is_empty());
        let rest = s.part_power(DomePart::Rest);
        let n = 1u32 << 18;
        let (mut light, mut across_an_edge, mut spread) = (Vec3::ZERO, 0, (f64::MAX, 0f64));
        for k in 0..n {
            let u = Vec2::new(random(k, 6), random(k, 7));
            let Some((dir, radiance, pdf)) = s.sample_part(DomePart::Rest, u, Lookup::Blocks) else { continue };
            light += radiance / pdf;
            let each = luminance(radiance) as f64 / pdf as f64;
            spread = (spread.0.min(each), spread.1.max(each));
            let (ray, part, ray_pdf) = s.radiance_and_pdf(dir, Lookup::Blocks);
            across_an_edge += (part != DomePart::Rest || ray != radiance || ray_pdf != pdf) as u32;
        }
        assert!(across_an_edge < n / 5_000, "{across_an_edge} samples disagree with what their ray finds");
        // Blocks that hold a sun cell carry more per sample (their rest is
        // smaller than the block), every other block exactly the whole rest.
        assert!((spread.0 / rest - 1.0).abs() < 1e-4, "{spread:?} vs {rest}");
        // The rest's texels with sin(theta), in f64, as a lighter would add them up.
        let mut texels = DVec3::ZERO;
        for j in 0..w / 2 {
            let theta = PI64 * (j as f64 + 0.5) / (w / 2) as f64;
            for i in (0..w).filter(|&i| !s.is_sun(j as usize, i as usize)) {
                texels += sky(i, j).as_dvec3() * theta.sin() * 2.0 * PI64 * PI64 / (w * w / 2) as f64;
            }
        }
        let error = (light.as_dvec3() / n as f64 / texels - 1.0).abs().max_element();
        assert!(error < 0.005, "{} vs {texels}", light / n as f32);
        // The sun part is bilinear under either lookup.
        for k in 0..200 {
            let u = Vec2::new(random(k, 8), random(k, 9));
            let bilinear = s.sample_part(DomePart::Sun, u, Lookup::Bilinear);
            assert_eq!(bilinear.map(|x| x.1), s.sample_part(DomePart::Sun, u, Lookup::Blocks).map(|x| x.1));
        }
    }

    /// The guided pick finds the bin the binary search finds, for every
    /// target, across empty bins and bins that hold many guide entries.
    #[test]
    fn a_guided_pick_is_the_binary_search() {
        for (n, seed) in [(1usize, 0u32), (7, 1), (256, 2), (300, 3)] {
            let weights: Vec<f32> = (0..n as u32)
                .map(|i| if random(i, seed) < 0.3 { 0.0 } else { random(i, seed + 10).powi(6) * 100.0 })
                .collect();
            let mut sum = 0f32;
            let cdf: Vec<f32> = weights
                .iter()
                .map(|w| {
                    sum += w;
                    sum
                })
                .collect();
            let total = sum as f64;
            if !(total > 0.0) {
                continue;
            }
            let g = guide(&cdf, total, n.min(64));
            for k in 0..20_000 {
                let target = (random(k, seed + 20) as f64 * total) as f32;
                assert_eq!(pick_guided(&cdf, &g, target, total), pick(&cdf, target), "n {n} target {target}");
            }
            for &edge in &cdf {
                assert_eq!(pick_guided(&cdf, &g, edge, total), pick(&cdf, edge));
            }
        }
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
