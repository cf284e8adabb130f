//! Deep images: per pixel a list of samples at their own depths, gathered
//! from the camera samples while a film renders, for deep compositing
//! (written by [`super::exr::deep`]; docs/render.md, "Deep output").
//!
//! Collection, per pixel, in sample-index order (so the same for any thread
//! count): every camera sample that covers the pixel (a surface, or the sky
//! where the layer shows it) joins the pixel's deep sample of the same
//! object (scene instance: one part of one agent, or one set object) whose
//! depth range it lies within `tolerance` (relative) of; else it starts a
//! new one. Misses and holdout hits cover nothing (alpha 0, no colour in
//! the flat film too) and leave no sample: a crowd layer holds no set
//! samples, and the set is its own deep image. With motion blur and depth
//! of field each camera sample brings its own depth, so a moving or
//! defocused object spreads over the depths it was seen at. A pixel keeps at
//! most `max_samples` deep samples: once full, a camera sample that matches
//! none joins the deep sample nearest its depth (its colour and coverage
//! kept, so flattening is unchanged; its object id is that sample's; a sky
//! sample joining a surface's leaves its depth range finite).
//! Refractive glass is an opaque surface to the camera (its colour is what
//! it refracts), as in the flat beauty.
//!
//! Values: a deep sample's `Z` and `ZBack` are the nearest and farthest
//! depth of its camera samples (camera-space depth, as the flat `Z`; the
//! sky is at +inf). Camera samples within one pixel cover disjoint parts of
//! it, while a deep reader composites samples front to back with "over"
//! (each sample's alpha takes that share of what is behind it). So a deep
//! sample's alpha is its camera samples over the samples not already taken
//! by nearer deep samples, and its colour is scaled alike: flattening the
//! pixel front to back with "over" gives exactly the flat film's mean
//! (`n_k` samples of `N` with `r` taken nearer: alpha `n_k / (N - r)`,
//! transmittance before it `(N - r) / N`).

use glam::Vec3;

use super::cryptomatte::CryptoNames;
use crate::shot::Deep;

/// How a render gathers deep samples (the shot's `render.deep`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DeepSettings {
    /// At most this many deep samples per pixel (1..=[`Deep::MAX_SAMPLES_LIMIT`]).
    pub max_samples: u32,
    /// Relative depth within which one object's camera samples merge.
    pub tolerance: f32,
}

impl Default for DeepSettings {
    fn default() -> Self {
        DeepSettings { max_samples: Deep::DEFAULT_MAX_SAMPLES, tolerance: Deep::DEFAULT_TOLERANCE }
    }
}

impl DeepSettings {
    /// The settings of the shot's `render.deep` (checked when the shot was read).
    pub fn of(deep: &Deep) -> DeepSettings {
        DeepSettings { max_samples: deep.max_samples, tolerance: deep.tolerance }
    }
}

/// One deep sample: premultiplied colour and alpha, its depth range, and
/// the Cryptomatte ids of its agent and object (float-encoded hashes, 0 for
/// none, as in the flat file's `CryptoAgent` and `CryptoPart` mattes).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct DeepSample {
    /// Premultiplied R, G, B and alpha.
    pub rgba: [f32; 4],
    /// Nearest depth.
    pub z: f32,
    /// Farthest depth (`>= z`).
    pub z_back: f32,
    /// `CryptoAgent` id (0: not an agent's).
    pub agent_id: f32,
    /// `CryptoPart` id: the object (an agent's part or a set object).
    pub object_id: f32,
}

/// A deep image: each pixel's samples (sorted by `z`), row-major.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DeepImage {
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Samples per pixel, row-major.
    pub counts: Vec<u32>,
    /// Every pixel's samples, pixel after pixel.
    pub samples: Vec<DeepSample>,
}

impl DeepImage {
    /// The most samples any pixel holds.
    pub fn max_samples(&self) -> u32 {
        self.counts.iter().copied().max().unwrap_or(0)
    }

    /// Each pixel's samples, row-major.
    pub fn pixels(&self) -> impl Iterator<Item = &[DeepSample]> + '_ {
        let mut at = 0usize;
        self.counts.iter().map(move |&n| {
            let s = &self.samples[at..at + n as usize];
            at += n as usize;
            s
        })
    }

    /// Whether every pixel's samples are sorted by depth and no two overlap
    /// (OpenEXR's "tidy" state): each ends where or before the next begins
    /// (a volume's range is open at its back), and no two point samples
    /// share a depth; else they are only sorted.
    pub fn is_tidy(&self) -> bool {
        let point = |s: &DeepSample| s.z == s.z_back;
        self.pixels().all(|p| {
            p.windows(2).all(|w| w[0].z_back < w[1].z || (w[0].z_back == w[1].z && !(point(&w[0]) && point(&w[1]))))
        })
    }

    /// The image flattened front to back with "over": premultiplied RGBA
    /// per pixel, row-major (what a compositor's DeepToImage gives).
    pub fn flatten(&self) -> Vec<[f32; 4]> {
        self.pixels()
            .map(|p| {
                let mut out = [0.0f32; 4];
                for s in p {
                    let t = 1.0 - out[3];
                    for (o, v) in out.iter_mut().zip(s.rgba) {
                        *o += t * v;
                    }
                }
                out
            })
            .collect()
    }
}

/// The object key of the sky (no instance).
const SKY: u32 = u32::MAX;

/// One deep sample being gathered.
#[derive(Clone, Copy, Debug)]
struct Gathered {
    key: u32,
    near: f32,
    far: f32,
    rgb: Vec3,
    count: u32,
}

/// One pixel's deep samples while its camera samples arrive; allocated
/// once per tile and reused.
#[derive(Debug, Default)]
pub(crate) struct DeepPixel {
    entries: Vec<Gathered>,
}

impl DeepPixel {
    /// Forgets the pixel gathered last.
    pub(crate) fn clear(&mut self) {
        self.entries.clear();
    }

    /// Adds one camera sample: colour `rgb`, coverage `alpha` (0 or 1), depth
    /// `z` of instance `instance` (`None`: the sky, or nothing).
    pub(crate) fn add(&mut self, settings: &DeepSettings, rgb: Vec3, alpha: f32, z: f32, instance: Option<u32>) {
        if alpha <= 0.0 {
            return;
        }
        let key = instance.unwrap_or(SKY);
        let z = if key == SKY { f32::INFINITY } else { z };
        let tol = settings.tolerance;
        let fits =
            |e: &Gathered| e.key == key && (key == SKY || (z >= e.near - tol * e.near && z <= e.far + tol * e.far));
        let at = match self.entries.iter().position(fits) {
            Some(i) => i,
            None if self.entries.len() < settings.max_samples as usize => {
                self.entries.push(Gathered { key, near: z, far: z, rgb: Vec3::ZERO, count: 0 });
                self.entries.len() - 1
            }
            // Full: the deep sample nearest in depth takes it (first of equals).
            None => {
                let gap = |e: &Gathered| if z < e.near { e.near - z } else { (z - e.far).max(0.0) };
                let mut best = 0;
                for (i, e) in self.entries.iter().enumerate() {
                    if gap(e) < gap(&self.entries[best]) {
                        best = i;
                    }
                }
                best
            }
        };
        let e = &mut self.entries[at];
        // A full pixel's sky sample joining a surface (or the reverse) keeps
        // the entry's range: a surface sample must not reach to infinity.
        if z.is_finite() == e.near.is_finite() {
            e.near = e.near.min(z);
            e.far = e.far.max(z);
        }
        e.rgb += rgb;
        e.count += 1;
    }

    /// Appends the pixel's deep samples (sorted by depth) for `spp` camera
    /// samples to `out`; returns how many.
    pub(crate) fn finish(&mut self, spp: u32, names: Option<&CryptoNames>, out: &mut Vec<DeepSample>) -> u32 {
        self.entries.sort_by(|a, b| a.near.total_cmp(&b.near).then(a.far.total_cmp(&b.far)).then(a.key.cmp(&b.key)));
        // Camera samples not yet taken by nearer deep samples.
        let mut left = spp.max(1);
        for e in &self.entries {
            let share = 1.0 / left.max(e.count) as f32;
            let ids = match (names, e.key) {
                (Some(n), k) if k != SKY => n.ids(k),
                _ => [0; 3],
            };
            out.push(DeepSample {
                rgba: (e.rgb * share).extend(e.count as f32 * share).to_array(),
                z: e.near,
                z_back: e.far,
                agent_id: f32::from_bits(ids[0]),
                object_id: f32::from_bits(ids[1]),
            });
            left = left.saturating_sub(e.count);
        }
        self.entries.len() as u32
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn disjoint_coverage_flattens_to_the_mean() {
        let s = DeepSettings::default();
        let mut p = DeepPixel::default();
        // 4 samples: 1 far red, 2 near green, 1 miss.
        p.add(&s, Vec3::new(1.0, 0.0, 0.0), 1.0, 10.0, Some(1));
        p.add(&s, Vec3::new(0.0, 1.0, 0.0), 1.0, 2.0, Some(0));
        p.add(&s, Vec3::new(0.0, 1.0, 0.0), 1.0, 2.01, Some(0));
        p.add(&s, Vec3::ZERO, 0.0, f32::INFINITY, None);
        let mut out = Vec::new();
        assert_eq!(p.finish(4, None, &mut out), 2);
        let img = DeepImage { width: 1, height: 1, counts: vec![2], samples: out.clone() };
        let flat = img.flatten()[0];
        for (got, want) in flat.iter().zip([0.25, 0.5, 0.0, 0.75]) {
            assert!((got - want).abs() < 1e-6, "{flat:?}");
        }
        assert_eq!((out[0].z, out[0].z_back), (2.0, 2.01));
        assert!(img.is_tidy());
    }

    #[test]
    fn a_full_pixel_merges_into_the_nearest_depth() {
        let s = DeepSettings { max_samples: 2, tolerance: 0.0 };
        let mut p = DeepPixel::default();
        for (i, z) in [1.0, 5.0, 4.0].into_iter().enumerate() {
            p.add(&s, Vec3::ONE, 1.0, z, Some(i as u32));
        }
        let mut out = Vec::new();
        assert_eq!(p.finish(3, None, &mut out), 2);
        assert_eq!((out[1].z, out[1].z_back), (4.0, 5.0));
        assert!((out[1].rgba[3] - 1.0).abs() < 1e-6);
    }
}
