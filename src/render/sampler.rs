//! Deterministic sample generation. Every number is a pure function of
//! (seed, frame, layer, pixel x, y, sample index, dimension), never of thread
//! identity or call order across pixels, so renders are bit-identical for any
//! thread count.
//!
//! Points are Owen-scrambled, shuffled 2D Sobol (Burley 2020, "Practical
//! Hash-based Owen Scrambling"): each pair of dimensions is a (0,2)-sequence
//! with its own per-pixel scramble and shuffle, so any power-of-two prefix of a
//! pixel's samples is well stratified in every 2D projection we use.

use glam::Vec2;

/// Mixes a 32-bit value (the "lowbias32" hash by Chris Wellons: full avalanche).
#[inline]
pub(crate) fn mix32(mut x: u32) -> u32 {
    x ^= x >> 16;
    x = x.wrapping_mul(0x7feb_352d);
    x ^= x >> 15;
    x = x.wrapping_mul(0x846c_a68b);
    x ^= x >> 16;
    x
}

/// Hashes a list of words; order matters.
#[inline]
pub(crate) fn hash_words(words: &[u32]) -> u32 {
    // Seed with the length so [] and [0] differ.
    let mut h = mix32(words.len() as u32 ^ 0x9e37_79b9);
    for &w in words {
        h = mix32(h ^ mix32(w.wrapping_add(0x632b_e5ab)));
    }
    h
}

/// Laine-Karras style permutation: each output bit depends only on itself and
/// lower bits, which becomes an Owen scramble once applied to reversed bits.
#[inline]
fn laine_karras(mut x: u32, seed: u32) -> u32 {
    x = x.wrapping_add(seed);
    x ^= x.wrapping_mul(0x6c50_b47c);
    x ^= x.wrapping_mul(0xb82f_1e52);
    x ^= x.wrapping_mul(0xc7af_e638);
    x ^= x.wrapping_mul(0x8d22_f6e6);
    x
}

#[cfg(test)]
#[inline]
fn nested_uniform_scramble(x: u32, seed: u32) -> u32 {
    laine_karras(x.reverse_bits(), seed).reverse_bits()
}

/// Direction numbers of Sobol dimension 1 (primitive polynomial x + 1):
/// v_0 = 1 << 31, v_k = v_{k-1} ^ (v_{k-1} >> 1).
const SOBOL1_DIRECTIONS: [u32; 32] = {
    let mut v = [0u32; 32];
    v[0] = 1 << 31;
    let mut k = 1;
    while k < 32 {
        v[k] = v[k - 1] ^ (v[k - 1] >> 1);
        k += 1;
    }
    v
};

/// Sobol dimension 1 as four byte tables: entry `b` of table `j` is the XOR
/// of the direction numbers of the set bits of byte `b` at bit offset 8j.
/// Four lookups replace a loop over all 32 index bits (the shuffled index
/// uses every bit); the points are the same.
const SOBOL1_BYTES: [[u32; 256]; 4] = {
    let mut t = [[0u32; 256]; 4];
    let mut j = 0;
    while j < 4 {
        let mut b = 0;
        while b < 256 {
            let mut y = 0u32;
            let mut bit = 0;
            while bit < 8 {
                if b & (1 << bit) != 0 {
                    y ^= SOBOL1_DIRECTIONS[8 * j + bit];
                }
                bit += 1;
            }
            t[j][b] = y;
            b += 1;
        }
        j += 1;
    }
    t
};

/// [`SOBOL1_BYTES`] with every entry's bits reversed. Reversal is linear
/// over XOR, so these give Sobol dimension 1 of a point already reversed,
/// which is how its scramble takes it (one reversal fewer per point).
const SOBOL1_BYTES_REVERSED: [[u32; 256]; 4] = {
    let mut t = SOBOL1_BYTES;
    let mut j = 0;
    while j < 4 {
        let mut b = 0;
        while b < 256 {
            t[j][b] = t[j][b].reverse_bits();
            b += 1;
        }
        j += 1;
    }
    t
};

/// Sobol dimension 1 of point `index` with its bits reversed.
#[inline]
fn sobol_1_reversed(index: u32) -> u32 {
    let b = index.to_le_bytes();
    SOBOL1_BYTES_REVERSED[0][b[0] as usize]
        ^ SOBOL1_BYTES_REVERSED[1][b[1] as usize]
        ^ SOBOL1_BYTES_REVERSED[2][b[2] as usize]
        ^ SOBOL1_BYTES_REVERSED[3][b[3] as usize]
}

/// Sobol dimensions 0 and 1 of point `index`, as 32-bit fixed point.
#[cfg(test)]
#[inline]
fn sobol_2d(index: u32) -> (u32, u32) {
    let x = index.reverse_bits();
    let b = index.to_le_bytes();
    let y = SOBOL1_BYTES[0][b[0] as usize]
        ^ SOBOL1_BYTES[1][b[1] as usize]
        ^ SOBOL1_BYTES[2][b[2] as usize]
        ^ SOBOL1_BYTES[3][b[3] as usize];
    (x, y)
}

#[inline]
fn to_unit(x: u32) -> f32 {
    // 24 bits so the result is exactly representable and strictly below 1.
    (x >> 8) as f32 * (1.0 / (1u32 << 24) as f32)
}

/// Salt of the time stream ([`Sampler::time`]): not `mix32` of any small
/// dimension number, so it never coincides with a numbered dimension's key.
const TIME_SALT: u32 = 0x7157_a3c1;
/// Keys the lens stream apart from the time stream and every dimension.
const LENS_SALT: u32 = 0x1e45_d0f7;

/// Random numbers for one camera sample of one pixel.
#[derive(Clone, Debug)]
pub(crate) struct Sampler {
    pixel_key: u32,
    /// The sample index with its bits reversed, as the index scramble takes it.
    sample_reversed: u32,
    dimension: u32,
}

impl Sampler {
    /// The sampler of sample `sample` of pixel (x, y).
    pub(crate) fn new(seed: u64, frame: i64, layer: u32, x: u32, y: u32, sample: u32) -> Sampler {
        let pixel_key =
            hash_words(&[seed as u32, (seed >> 32) as u32, frame as u32, (frame >> 32) as u32, layer, x, y]);
        Sampler { pixel_key, sample_reversed: sample.reverse_bits(), dimension: 0 }
    }

    /// Jumps to a fixed dimension, so each bounce uses the same dimensions
    /// whatever branches earlier bounces took.
    pub(crate) fn set_dimension(&mut self, dimension: u32) {
        self.dimension = dimension;
    }

    /// The next 2D point in [0, 1)^2 (uses two dimensions).
    pub(crate) fn next_2d(&mut self) -> Vec2 {
        let seed = mix32(self.pixel_key ^ mix32(self.dimension));
        self.dimension += 2;
        self.point_2d(seed)
    }

    /// This camera sample's time in [0, 1) across the shutter (motion blur).
    /// A stream of its own, keyed apart from every numbered dimension, so
    /// drawing it shifts nothing: a render without motion never calls it and
    /// a still scene renders the same bits with or without a shutter. Like
    /// the dimensions, a power-of-two prefix of a pixel's samples is
    /// stratified in time.
    pub(crate) fn time(&self) -> f32 {
        self.point_1d(mix32(self.pixel_key ^ TIME_SALT))
    }

    /// This camera sample's point on the lens in [0, 1)^2 (depth of field):
    /// like [`Sampler::time`], a stream of its own, so a pinhole render
    /// never draws it and keeps its bits; a power-of-two prefix of a pixel's
    /// samples is stratified over the lens.
    pub(crate) fn lens(&self) -> Vec2 {
        self.point_2d(mix32(self.pixel_key ^ LENS_SALT))
    }

    /// This sample's point of the Owen-scrambled, shuffled 2D Sobol
    /// sequence keyed by `seed`.
    fn point_2d(&self, seed: u32) -> Vec2 {
        // nested_uniform_scramble(x) is reverse(laine_karras(reverse(x))); the
        // reversals that cancel are left out (sobol x is reverse(index)), so
        // this is the textbook form (`point_2d_reference` in the tests), bit for bit.
        let index = laine_karras(self.sample_reversed, seed).reverse_bits();
        let x = laine_karras(index, mix32(seed ^ 0x5bd1_e995)).reverse_bits();
        let y = laine_karras(sobol_1_reversed(index), mix32(seed ^ 0x27d4_eb2f)).reverse_bits();
        Vec2::new(to_unit(x), to_unit(y))
    }

    /// The next number in [0, 1) (uses one dimension).
    pub(crate) fn next_1d(&mut self) -> f32 {
        let seed = mix32(self.pixel_key ^ mix32(self.dimension));
        self.dimension += 1;
        self.point_1d(seed)
    }

    /// This sample's number of the Owen-scrambled, shuffled 1D Sobol
    /// (van der Corput) sequence keyed by `seed`.
    fn point_1d(&self, seed: u32) -> f32 {
        // As point_2d: the textbook form with the cancelling reversals left out.
        let index = laine_karras(self.sample_reversed, seed).reverse_bits();
        to_unit(laine_karras(index, mix32(seed ^ 0x5bd1_e995)).reverse_bits())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn deterministic_and_in_range() {
        let mut a = Sampler::new(7, 1001, 2, 10, 20, 3);
        let mut b = Sampler::new(7, 1001, 2, 10, 20, 3);
        for _ in 0..50 {
            let (p, q) = (a.next_2d(), b.next_2d());
            assert_eq!(p, q);
            assert!(p.cmpge(Vec2::ZERO).all() && p.cmplt(Vec2::ONE).all());
            let (s, t) = (a.next_1d(), b.next_1d());
            assert_eq!(s, t);
            assert!((0.0..1.0).contains(&s));
        }
        assert_ne!(Sampler::new(7, 1001, 2, 10, 20, 3).next_2d(), Sampler::new(7, 1001, 2, 11, 20, 3).next_2d());
    }

    #[test]
    fn power_of_two_prefix_is_stratified() {
        // 16 samples of one pixel: exactly one per cell of a 4x4 grid ((0,4,2)-net).
        for dim in [0u32, 2, 10] {
            let mut cells = [0u32; 16];
            for s in 0..16 {
                let mut smp = Sampler::new(1, 1, 0, 5, 9, s);
                smp.set_dimension(dim);
                let p = smp.next_2d();
                cells[(p.x * 4.0) as usize + 4 * (p.y * 4.0) as usize] += 1;
            }
            assert!(cells.iter().all(|&c| c == 1), "{cells:?}");
        }
    }

    /// The points are the textbook Owen-scrambled Sobol points, bit for bit.
    #[test]
    fn points_are_the_textbook_scrambled_sobol_points() {
        let point_2d_reference = |sample: u32, seed: u32| {
            let index = nested_uniform_scramble(sample, seed);
            let (x, y) = sobol_2d(index);
            let x = nested_uniform_scramble(x, mix32(seed ^ 0x5bd1_e995));
            let y = nested_uniform_scramble(y, mix32(seed ^ 0x27d4_eb2f));
            Vec2::new(to_unit(x), to_unit(y))
        };
        let point_1d_reference = |sample: u32, seed: u32| {
            let index = nested_uniform_scramble(sample, seed);
            to_unit(nested_uniform_scramble(index.reverse_bits(), mix32(seed ^ 0x5bd1_e995)))
        };
        let mut seed = 99u32;
        for sample in (0..2048).chain([u32::MAX, 1 << 31, 0x8000_0001]) {
            seed = mix32(seed);
            let smp = Sampler::new(3, 7, 1, 4, 5, sample);
            assert_eq!(
                smp.point_2d(seed).to_array().map(f32::to_bits),
                point_2d_reference(sample, seed).to_array().map(f32::to_bits),
                "sample {sample}"
            );
            assert_eq!(smp.point_1d(seed).to_bits(), point_1d_reference(sample, seed).to_bits(), "sample {sample}");
        }
    }

    /// The byte tables give the points of the bit-by-bit recurrence.
    #[test]
    fn sobol_tables_match_the_recurrence() {
        let reference = |mut i: u32| {
            let (mut y, mut v) = (0u32, 1u32 << 31);
            while i != 0 {
                if i & 1 != 0 {
                    y ^= v;
                }
                v ^= v >> 1;
                i >>= 1;
            }
            y
        };
        let mut x = 12345u32;
        for i in (0..4096).chain([u32::MAX, 1 << 31, 0xdead_beef]) {
            assert_eq!(sobol_2d(i).1, reference(i), "index {i}");
            assert_eq!(sobol_1_reversed(i), reference(i).reverse_bits(), "index {i}");
            x = mix32(x);
            assert_eq!(sobol_2d(x).1, reference(x), "index {x}");
        }
    }

    #[test]
    fn time_is_stratified_and_leaves_dimensions_alone() {
        let mut cells = [0u32; 16];
        for s in 0..16 {
            let smp = Sampler::new(1, 1, 0, 5, 9, s);
            cells[(smp.time() * 16.0) as usize] += 1;
            let mut a = Sampler::new(1, 1, 0, 5, 9, s);
            let mut b = a.clone();
            let _ = b.time();
            assert_eq!(a.next_2d(), b.next_2d());
        }
        assert!(cells.iter().all(|&c| c == 1), "{cells:?}");
    }

    #[test]
    fn mean_is_unbiased() {
        let n = 4096;
        let mut sum = 0.0f64;
        for s in 0..n {
            sum += Sampler::new(3, 0, 0, 1, 1, s).next_1d() as f64;
        }
        assert!((sum / n as f64 - 0.5).abs() < 0.01);
    }
}
