//! Shared by the OIDN tests and examples: finding the library (or skipping) and a synthetic scene.
#![allow(dead_code)]

use std::io::Write;

use throng_oidn::Library;

/// The library, or None after printing why the calling test is skipped. With
/// `THRONG_REQUIRE_OIDN=1` (CI) a missing library fails the test with the search report instead.
pub fn library_or_skip(test: &str) -> Option<Library> {
    match Library::find(None) {
        Ok(lib) => Some(lib),
        Err(e) if std::env::var("THRONG_REQUIRE_OIDN").is_ok_and(|v| v == "1") => {
            panic!("THRONG_REQUIRE_OIDN=1 but Open Image Denoise is missing:\n{e}")
        }
        Err(e) => {
            let first = format!("no usable Open Image Denoise 2.x in the {} places searched", e.searched.len());
            // Straight to the stderr handle: libtest captures print!/eprint! of passing tests, and a
            // skip must be seen.
            let _ = writeln!(
                std::io::stderr(),
                "SKIPPED {test}: {first} (set THRONG_REQUIRE_OIDN=1 to fail instead; install: {})",
                throng_oidn::PIP_INSTALL
            );
            None
        }
    }
}

/// A synthetic render: `clean` beauty (checker albedo times smooth shading of a bulge, HDR:
/// a highlight up to ~4), its `color` with Gaussian noise, and mildly noisy `albedo` and
/// `normal` guides. All interleaved RGB, row-major, width * height * 3.
pub struct Scene {
    pub width: usize,
    pub height: usize,
    pub clean: Vec<f32>,
    pub color: Vec<f32>,
    pub albedo: Vec<f32>,
    pub normal: Vec<f32>,
}

struct Rng(u64);

impl Rng {
    /// xorshift64*, uniform in [0, 1).
    fn next(&mut self) -> f32 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        ((self.0.wrapping_mul(0x2545F4914F6CDD1D) >> 40) as f32) / (1u64 << 24) as f32
    }

    fn gauss(&mut self) -> f32 {
        let (u1, u2) = (self.next().max(1e-7), self.next());
        (-2.0 * u1.ln()).sqrt() * (std::f32::consts::TAU * u2).cos()
    }
}

pub fn scene(width: usize, height: usize, seed: u64) -> Scene {
    let n = width * height * 3;
    let (mut clean, mut color, mut albedo, mut normal) = (vec![0.0; n], vec![0.0; n], vec![0.0; n], vec![0.0; n]);
    let mut rng = Rng(0x9E3779B97F4A7C15 ^ seed);
    let (cw, ch) = ((width / 8).max(1), (height / 4).max(1));
    for y in 0..height {
        for x in 0..width {
            let (u, v) = (x as f32 / width as f32, y as f32 / height as f32);
            let i = (y * width + x) * 3;
            let a = if ((x / cw) + (y / ch)) % 2 == 0 { [0.8, 0.5, 0.3] } else { [0.3, 0.6, 0.8] };
            let (nx, ny) = ((u - 0.5) * 1.2, (v - 0.5) * 1.2);
            let nz = (1.0 - nx * nx - ny * ny).max(0.0).sqrt();
            let lambert = (nx * 0.3 - ny * 0.4 + nz * 0.87).max(0.0);
            let shade = 0.2 + 1.5 * lambert * (0.6 + 0.4 * u) + 3.0 * lambert.powi(40);
            for k in 0..3 {
                clean[i + k] = a[k] * shade;
                // Noise that grows with brightness, as Monte Carlo noise does; never negative.
                color[i + k] = (clean[i + k] * (1.0 + 0.5 * rng.gauss())).max(0.0);
                albedo[i + k] = (a[k] + 0.05 * rng.gauss()).clamp(0.0, 1.0);
            }
            normal[i..i + 3].copy_from_slice(&[
                nx + 0.05 * rng.gauss(),
                ny + 0.05 * rng.gauss(),
                nz + 0.05 * rng.gauss(),
            ]);
        }
    }
    Scene { width, height, clean, color, albedo, normal }
}

/// Mean absolute error.
pub fn mae(a: &[f32], b: &[f32]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y).abs() as f64).sum::<f64>() / a.len() as f64
}

/// Bitwise equality (NaN-safe, -0 != +0).
pub fn bit_identical(a: &[f32], b: &[f32]) -> bool {
    a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.to_bits() == y.to_bits())
}
