//! Deep compositing: a frame's deep layers (docs/render.md, "Deep output")
//! merged into one deep image with Nuke DeepMerge's semantics, and that
//! image flattened into the comp's colour (docs/compositing.md, "Deep
//! comp").
//!
//! Merging follows "Interpreting OpenEXR Deep Pixels" (openexr.com) as
//! far as throng's samples allow: per pixel, every layer's samples are
//! gathered and sorted by `Z`, then `ZBack` (layer order kept among equals),
//! samples with the same depth range are combined into one (optical depths
//! add; colour weighted by each one's optical depth per alpha; opaque ones
//! win and average, as the document's merge does), and "over" front to back
//! flattens the result. Which layer a sample came from no longer matters:
//! an agent of a far layer standing in front of one of a near layer is
//! drawn in front.
//!
//! Overlapping samples are not split. DeepMerge splits a volume sample
//! (`Z < ZBack`) at the other samples' depths inside it as if its alpha
//! were spread evenly through that range; a throng sample is surfaces, its
//! camera samples at depths between `Z` and `ZBack` covering disjoint parts
//! of the pixel. Split that way, the floor's opaque sample around an
//! agent's feet covers the feet, and a wide sample of the set behind a
//! nearer one loses its share: the comp of the property test's shot then
//! differs from the full render by 11 standard errors in a block, where
//! ordering by `Z` matches it. So the deep comp is `sorted`
//! (`deepImageState` 1) where samples overlap, `tidy` where none do.
//!
//! A combined sample takes the ids (`id.agent`, `id.object`) of its part
//! with the highest alpha (ties: layer order), so a deep matte of an agent
//! keeps where it dominates.

use std::path::PathBuf;

use crate::comp::{comp_frame, Comped};
use crate::error::{Error, Result};
use crate::layers::Manifest;
use crate::render::deep::{DeepImage, DeepSample};
use crate::render::exr::deep::{read_deep, DeepHeader};
use crate::render::job::deep_layer_path;

/// Merges deep images of one size into one deep image sorted by depth (see the module docs).
pub fn merge(images: &[&DeepImage]) -> Result<DeepImage> {
    let Some(first) = images.first() else {
        return Err(Error::Usage("nothing to composite: no deep layers".into()));
    };
    let (w, h) = (first.width, first.height);
    if let Some(other) = images.iter().find(|i| (i.width, i.height) != (w, h)) {
        return Err(Error::Usage(format!("deep layers differ in size: {w}x{h} and {}x{}", other.width, other.height)));
    }
    let mut pixels: Vec<_> = images.iter().map(|i| i.pixels()).collect();
    let mut out =
        DeepImage { width: w, height: h, counts: Vec::with_capacity(first.counts.len()), samples: Vec::new() };
    let mut gathered = Vec::new();
    for _ in 0..first.counts.len() {
        gathered.clear();
        for p in pixels.iter_mut() {
            gathered.extend_from_slice(p.next().unwrap_or(&[]));
        }
        let before = out.samples.len();
        merge_pixel(&gathered, &mut out.samples);
        out.counts.push((out.samples.len() - before) as u32);
    }
    Ok(out)
}

/// Appends the merge of one pixel's samples (from any layers, in layer
/// order) to `out`.
fn merge_pixel(samples: &[DeepSample], out: &mut Vec<DeepSample>) {
    let mut parts = samples.to_vec();
    // Stable: equal ranges keep layer order, for the ids' ties.
    parts.sort_by(|a, b| a.z.total_cmp(&b.z).then(a.z_back.total_cmp(&b.z_back)));
    let mut i = 0;
    while i < parts.len() {
        let n = parts[i..].iter().take_while(|p| p.z == parts[i].z && p.z_back == parts[i].z_back).count();
        out.push(combine(&parts[i..i + n]));
        i += n;
    }
}

/// Samples with one depth range combined into one ("Interpreting OpenEXR
/// Deep Pixels", merging overlapping samples, for any number of them).
fn combine(same: &[DeepSample]) -> DeepSample {
    let mut best = same[0];
    for s in &same[1..] {
        if s.rgba[3] > best.rgba[3] {
            best = *s;
        }
    }
    if same.len() == 1 {
        return best;
    }
    let mut rgba = [0.0f32; 4];
    let opaque: Vec<&DeepSample> = same.iter().filter(|s| s.rgba[3] >= 1.0).collect();
    if !opaque.is_empty() {
        for s in &opaque {
            for (out, v) in rgba.iter_mut().zip(&s.rgba[..3]) {
                *out += v / opaque.len() as f32;
            }
        }
        rgba[3] = 1.0;
    } else {
        // Optical depth u = -ln(1 - a); colour per unit optical depth c / a.
        let mut u = 0.0f64;
        let mut c = [0.0f64; 3];
        for s in same.iter().filter(|s| s.rgba[3] > 0.0) {
            let a = s.rgba[3] as f64;
            let ui = -(-a).ln_1p();
            u += ui;
            for (ck, &v) in c.iter_mut().zip(&s.rgba[..3]) {
                *ck += v as f64 * ui / a;
            }
        }
        let a = -(-u).exp_m1();
        let w = if u > 0.0 { a / u } else { 0.0 };
        for k in 0..3 {
            rgba[k] = (c[k] * w) as f32;
        }
        rgba[3] = a as f32;
    }
    DeepSample { rgba, ..best }
}

/// What [`comp_frame_deep`] made: the deep comp and the flat comp whose
/// colour is the deep comp flattened.
#[derive(Debug, Clone)]
pub struct DeepComped {
    /// The flat comp: the layers' flat stack (header, Z, ids, normals,
    /// albedo, mattes), with R G B A the deep comp flattened front to back.
    pub flat: Comped,
    /// The merged deep image.
    pub deep: DeepImage,
    /// The deep layer files merged, back to front.
    pub deep_files: Vec<PathBuf>,
}

/// Checks that `head`, read from `path`, is throng's deep file of `layer`,
/// frame `frame` of shot `shot`.
fn check_deep_header(path: &std::path::Path, head: &DeepHeader, layer: &str, frame: i32, shot: &str) -> Result<()> {
    let not_ours =
        |key: &str, what: String| Error::invalid(path, format!("not throng's deep file of {what}")).field(key);
    let text = |key: &str| head.text.get(key).map(String::as_str);
    if text("throng/shot") != Some(shot) {
        return Err(not_ours("throng/shot", format!("shot `{shot}` (it says {:?})", text("throng/shot"))));
    }
    if text("throng/layer") != Some(layer) {
        return Err(not_ours("throng/layer", format!("layer `{layer}` (it says {:?})", text("throng/layer"))));
    }
    if head.frame != Some(frame) {
        return Err(not_ours("throng/frame", format!("frame {frame} (it says {:?})", head.frame)));
    }
    Ok(())
}

/// Finds, reads and merges the deep layers of `frame` under `dir` (each
/// `<shot>.<layer>.<frame:04>.deep.exr` beside its flat layer), and stacks
/// the flat layers for the channels deep files do not hold.
pub fn comp_frame_deep(dir: &std::path::Path, frame: i32, manifest: Option<&Manifest>) -> Result<DeepComped> {
    let mut flat = comp_frame(dir, frame, manifest)?;
    let mut images = Vec::with_capacity(flat.layers.len());
    let mut deep_files = Vec::with_capacity(flat.layers.len());
    for (layer, flat_path) in &flat.layers {
        let path = deep_layer_path(flat_path);
        if !path.is_file() {
            return Err(Error::Usage(format!(
                "layer `{layer}` of frame {frame} has no deep file: no {} (render the layers with deep output)",
                path.display()
            )));
        }
        let (image, head) = read_deep(&path)?;
        check_deep_header(&path, &head, layer, frame, &flat.meta.shot)?;
        if (image.width, image.height) != (flat.film.width, flat.film.height) {
            return Err(Error::invalid(
                &path,
                format!(
                    "deep layer is {}x{} but its flat layer {} is {}x{}",
                    image.width,
                    image.height,
                    flat_path.display(),
                    flat.film.width,
                    flat.film.height
                ),
            ));
        }
        images.push(image);
        deep_files.push(path);
    }
    let deep = merge(&images.iter().collect::<Vec<_>>())?;
    flat.film.rgba = deep.flatten();
    if !flat.film.passes.is_empty() {
        let names: Vec<&str> = flat.film.passes.iter().map(|p| p.name.as_str()).collect();
        flat.warnings.push(format!(
            "passes {} left out of the deep comp's flat image: stacked flat, they add up to the flat stack's beauty, \
             not to the deep merge's (comp without deep output keeps them)",
            names.join(", ")
        ));
        flat.film.passes.clear();
    }
    Ok(DeepComped { flat, deep, deep_files })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(rgb: f32, a: f32, z: f32, z_back: f32, id: u32) -> DeepSample {
        DeepSample { rgba: [rgb * a, rgb * a, rgb * a, a], z, z_back, agent_id: f32::from_bits(id), object_id: 0.0 }
    }

    fn image(pixel: Vec<DeepSample>) -> DeepImage {
        DeepImage { width: 1, height: 1, counts: vec![pixel.len() as u32], samples: pixel }
    }

    #[test]
    fn disjoint_layers_merge_by_depth_not_by_order() {
        // The "back" layer's sample is nearer: it must end up in front.
        let back = image(vec![sample(1.0, 0.5, 2.0, 2.0, 1)]);
        let front = image(vec![sample(0.0, 1.0, 5.0, 5.0, 2)]);
        let m = merge(&[&back, &front]).unwrap();
        assert_eq!(m.counts, [2]);
        assert_eq!(m.samples[0].agent_id.to_bits(), 1);
        assert!(m.is_tidy());
        let flat = m.flatten()[0];
        assert!((flat[0] - 0.5).abs() < 1e-6 && (flat[3] - 1.0).abs() < 1e-6, "{flat:?}");
    }

    #[test]
    fn coincident_samples_combine_and_overlapping_ones_keep_their_order() {
        // Two half-transparent samples at one depth: optical depths add.
        let a = image(vec![sample(1.0, 0.5, 2.0, 2.0, 1)]);
        let b = image(vec![sample(0.0, 0.75, 2.0, 2.0, 2)]);
        let m = merge(&[&a, &b]).unwrap();
        assert_eq!(m.counts, [1]);
        assert!((m.samples[0].rgba[3] - (1.0 - 0.5 * 0.25)).abs() < 1e-6, "{:?}", m.samples[0]);
        assert_eq!(m.samples[0].agent_id.to_bits(), 2, "the higher alpha's ids");
        // Red's share: its optical depth, ln 2 of ln 8.
        assert!((m.samples[0].rgba[0] - 0.875 / 3.0).abs() < 1e-6, "{:?}", m.samples[0]);
        // Overlapping ranges are not split: sorted by Z, flattened by over.
        let wide = image(vec![sample(1.0, 0.5, 1.0, 3.0, 1)]);
        let inside = image(vec![sample(0.0, 1.0, 2.0, 2.5, 2)]);
        let m = merge(&[&inside, &wide]).unwrap();
        assert_eq!(m.samples.iter().map(|s| s.agent_id.to_bits()).collect::<Vec<_>>(), [1, 2]);
        assert!(!m.is_tidy());
        let flat = m.flatten()[0];
        assert!((flat[0] - 0.5).abs() < 1e-6 && flat[3] == 1.0, "{flat:?}");
    }

    #[test]
    fn sizes_must_match() {
        assert!(merge(&[&image(vec![]), &DeepImage { width: 2, height: 1, ..Default::default() }]).is_err());
        assert!(merge(&[]).is_err());
    }
}
