//! The statistics of the stack tests (tests/comp.rs, tests/deep.rs): a
//! composite against a full render, with the noise of one render estimated
//! from two full renders of different seeds (docs/compositing.md, "The
//! property test").

use throng::render::Film;

/// Block edge for the per-region test.
pub const BLOCK: u32 = 8;

/// Rec. 709 luminance of premultiplied linear RGB.
pub fn lum(p: &[f32; 4]) -> f64 {
    (0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2]) as f64
}

/// Mean and standard error of `x - y` over `pixels`, where the pixel
/// variance of one render is estimated from two independent full renders
/// (`(a - b)^2 / 2`) and `x`, `y` are independent renders of that noise.
pub fn diff_stats(x: &Film, y: &Film, noise: (&Film, &Film), pixels: &[usize], f: fn(&[f32; 4]) -> f64) -> (f64, f64) {
    let n = pixels.len().max(1) as f64;
    let mean = pixels.iter().map(|&i| f(&x.rgba[i]) - f(&y.rgba[i])).sum::<f64>() / n;
    let var: f64 = pixels.iter().map(|&i| (f(&noise.0.rgba[i]) - f(&noise.1.rgba[i])).powi(2) / 2.0).sum();
    // Two renders' worth of variance; a floor for half-float rounding.
    let se = (2.0 * var).sqrt() / n + 1e-4;
    (mean, se)
}

/// The film's pixels in `BLOCK` x `BLOCK` blocks, row-major.
pub fn blocks(f: &Film) -> Vec<Vec<usize>> {
    let mut out = Vec::new();
    for by in (0..f.height).step_by(BLOCK as usize) {
        for bx in (0..f.width).step_by(BLOCK as usize) {
            let px = (by..(by + BLOCK).min(f.height))
                .flat_map(|y| (bx..(bx + BLOCK).min(f.width)).map(move |x| (x, y)))
                .map(|(x, y)| f.index(x, y))
                .collect();
            out.push(px);
        }
    }
    out
}

/// Largest |z| over blocks, and its block.
pub fn worst_block(x: &Film, y: &Film, noise: (&Film, &Film), f: fn(&[f32; 4]) -> f64) -> (f64, usize, f64) {
    blocks(x)
        .iter()
        .enumerate()
        .map(|(b, px)| {
            let (m, se) = diff_stats(x, y, noise, px, f);
            ((m / se).abs(), b, m)
        })
        .fold((0.0, 0, 0.0), |acc, v| if v.0 > acc.0 { v } else { acc })
}
