//! The `samples` view: a layer's deep file (`render --deep`,
//! `<shot>.<layer>.<frame:04>.deep.exr` beside the flat one) as a heat map
//! of its deep samples per pixel, tone-mapped on the server
//! (`/api/deep.png`), and what `/api/layers` says of it for the page's
//! legend: the most samples a pixel holds (the header's
//! `maxSamplesPerPixel`, read without the pixels) and the colour ramp.
//! Only the sample counts are decoded, never the samples.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde_json::{json, Value};

use super::{file_key, need, not_found, refusal, Answer, Body, Refusal, State, COMP_VIEW};
use crate::render::exr::deep::{read_deep_header, read_sample_counts};
use crate::render::job::deep_layer_path;

/// The view's name in the page's list.
pub(crate) const SAMPLES_VIEW: &str = "samples";

/// The heat ramp from 1 sample to the most in the image, evenly spaced
/// stops (a pixel without samples is black); the page's legend draws the
/// same stops from `/api/layers`.
const RAMP: [[u8; 3]; 5] = [[32, 16, 96], [128, 24, 128], [220, 60, 50], [250, 160, 20], [255, 250, 200]];

/// The colour of `n` samples in an image whose fullest pixel holds `max`.
fn heat(n: u32, max: u32) -> [u8; 3] {
    if n == 0 || max == 0 {
        return [0; 3];
    }
    // 1 sample at the ramp's foot, `max` at its top.
    let t = if max == 1 { 1.0 } else { (n.min(max) - 1) as f32 / (max - 1) as f32 };
    let at = t * (RAMP.len() - 1) as f32;
    let (i, f) = ((at as usize).min(RAMP.len() - 2), at - (at as usize).min(RAMP.len() - 2) as f32);
    std::array::from_fn(|c| (RAMP[i][c] as f32 + f * (RAMP[i + 1][c] as f32 - RAMP[i][c] as f32) + 0.5) as u8)
}

/// Per-pixel sample counts as RGB8 heat-map pixels (row-major).
fn heat_pixels(counts: &[u32], max: u32) -> Vec<u8> {
    counts.iter().flat_map(|&n| heat(n, max)).collect()
}

impl State {
    /// The deep file beside layer file `flat`, confined to the renders folder.
    fn deep_beside(&self, flat: &Path) -> Answer<PathBuf> {
        let Some((_, root)) = &self.renders else { return Err(not_found("no renders folder")) };
        let deep = deep_layer_path(flat);
        if !deep.exists() {
            return Err(not_found(format!("no deep file beside {}", flat.display())));
        }
        root.confine(&deep).map_err(|(status, m)| Refusal(status, m))
    }

    /// What the page's legend needs of the deep file beside layer file
    /// `flat`: none when there is none, or it is not a deep file throng reads.
    pub(super) fn deep_legend(&self, flat: &Path) -> Option<Value> {
        let head = read_deep_header(&self.deep_beside(flat).ok()?).ok()?;
        let ramp: Vec<String> = RAMP.iter().map(|[r, g, b]| format!("#{r:02x}{g:02x}{b:02x}")).collect();
        Some(json!({ "view": SAMPLES_VIEW, "max": head.max_samples_per_pixel, "ramp": ramp }))
    }

    /// `/api/deep.png?frame=F&layer=L`: the layer's deep samples per pixel
    /// as a heat map scaled to its fullest pixel.
    pub(super) fn deep_png(&self, q: &BTreeMap<String, String>) -> Answer<Body> {
        let frame: i32 = need(q, "frame")?;
        let layer = q.get("layer").map(String::as_str).unwrap_or(COMP_VIEW);
        if layer == COMP_VIEW {
            return Err(not_found("samples per pixel is a layer's view: the comp has no deep file here"));
        }
        let path = self.deep_beside(&self.layer_file(frame, layer)?)?;
        self.cached_png(format!("deep|{}", file_key(&path)), || {
            let (image, head) = read_sample_counts(&path).map_err(refusal)?;
            let max = u32::try_from(head.max_samples_per_pixel).unwrap_or(u32::MAX);
            super::tone::png(image.width, image.height, 3, heat_pixels(&image.counts, max)).map_err(|m| Refusal(500, m))
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_ramp_runs_from_one_sample_to_the_most() {
        assert_eq!(heat(0, 9), [0, 0, 0]);
        assert_eq!(heat(1, 9), RAMP[0]);
        assert_eq!(heat(9, 9), RAMP[4]);
        assert_eq!(heat(5, 9), RAMP[2]);
        assert_eq!(heat(1, 1), RAMP[4]);
        // More than the header's most (a hand-edited file) saturates.
        assert_eq!(heat(12, 9), RAMP[4]);
        assert_eq!(heat_pixels(&[0, 2], 3), [0, 0, 0, 220, 60, 50]);
    }
}
