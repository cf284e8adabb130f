//! Compositing: stacks one frame's set layer and crowd layers back into one
//! image with the same channels as a layer file (docs/compositing.md).
//!
//! Conventions (the "comp rules"):
//! - Order: back to front, the manifest's `comp_order` (`set`, then crowd
//!   layers far to near). Without a manifest: `set`, then `crowdN` by
//!   descending N (crowd0 is the nearest).
//! - `R G B A`: premultiplied over, `out = front + (1 - front.A) * back`.
//! - `N.*`, `albedo.*`: the renderer writes them as coverage-weighted means
//!   (premultiplied by alpha, like colour), so they are composited with the
//!   same over; that is what a single full render would hold.
//! - `Z`, `agent.id`: never blended. Each layer's values come from its sample
//!   nearest the pixel centre; the comp takes both from the layer with the
//!   nearest finite Z at that pixel (ties: the front-most layer), so Z is the
//!   minimum over the layers that hit something there and the id names the
//!   surface that Z measures (0 when that surface is the set or sky).
//! - `forward.u`, `forward.v` (motion vectors, renders with a shutter): like
//!   `agent.id`, from the layer whose Z wins; zero where no layer hit
//!   anything. Written when any layer has them.
//!
//! - Passes (docs/render.md, "Passes"): the light-path passes, light groups
//!   and `shadow` are premultiplied like colour and stacked with the same
//!   over, so the comp's light groups (and its light-path passes) still add
//!   up to its beauty (stacked in f32 from the layers' half values: within
//!   one half rounding, 2^-11 (sum + beauty); the comp's file rounds to half
//!   once more, so within two: docs/render.md, "In the comp"); `P` comes, like `agent.id`, from the layer whose Z
//!   wins (zero where none hit). A pass is stacked only when every layer has
//!   it: one missing from some layer would not add up, so it is left out and
//!   named in [`Comped::warnings`].
//!
//! - Cryptomatte (`CryptoAgent`, `CryptoPart`, `CryptoMaterial`, any type
//!   a layer has, matched by name): an object's coverage in a
//!   layer is multiplied by `1 - A` of every layer in front of it (the
//!   colour over, per pixel), coverages of one id add, each pixel keeps its
//!   highest ranks (ties by id bits) and the manifests are merged, so mattes
//!   picked in the comp select what the stacked image shows.
//!
//! The header repeats the layers' shot, frame, seed and camera; the layer
//! name is `comp`, `spp` the smallest of the layers', and near/far span the
//! layers' (with `worldToNDC` rebuilt for them).

use std::path::{Path, PathBuf};

use glam::Mat4;

use crate::error::{Error, Result};
use crate::layers::Manifest;
use crate::output::{crowd_layer_index, crowd_layer_name, layer_path, COMP_LAYER, FULL_LAYER, SET_LAYER};
use crate::render::cryptomatte::Cryptomatte;
use crate::render::exr::{self, LayerMeta};
use crate::render::film::Pass;
use crate::render::Film;
use crate::scene::passes;

/// One layer file read for compositing.
#[derive(Debug, Clone)]
pub(crate) struct CompInput {
    /// The file.
    pub(crate) path: PathBuf,
    /// Its pixels.
    pub(crate) film: Film,
    /// Its header.
    pub(crate) meta: LayerMeta,
}

/// Stacks films back to front (index 0 is the farthest). All must have the
/// same size; see the module docs for each channel's rule.
pub fn over(films: &[&Film]) -> Result<Film> {
    let Some(first) = films.first() else {
        return Err(Error::Usage("nothing to composite: no layers".into()));
    };
    let (w, h) = (first.width, first.height);
    if let Some(f) = films.iter().find(|f| f.width != w || f.height != h) {
        return Err(Error::Usage(format!("layers differ in size: {w}x{h} and {}x{}", f.width, f.height)));
    }
    let mut out = Film::new(w, h);
    let with_motion = films.iter().any(|f| !f.motion.is_empty());
    if with_motion {
        out.motion = vec![[0.0; 2]; out.rgba.len()];
    }
    for i in 0..out.rgba.len() {
        let (mut rgba, mut n, mut albedo) = ([0.0f32; 4], [0.0f32; 3], [0.0f32; 3]);
        let (mut z, mut id, mut motion) = (f32::INFINITY, 0u32, [0.0f32; 2]);
        for f in films {
            let a = f.rgba[i][3];
            let keep = 1.0 - a;
            for (c, v) in rgba.iter_mut().enumerate() {
                *v = f.rgba[i][c] + keep * *v;
            }
            for c in 0..3 {
                n[c] = f.normal[i][c] + keep * n[c];
                albedo[c] = f.albedo[i][c] + keep * albedo[c];
            }
            // `<=`: later (nearer in comp order) layers win ties.
            let fz = f.z[i];
            if fz.is_finite() && fz <= z {
                z = fz;
                id = f.agent_id[i];
                motion = f.motion.get(i).copied().unwrap_or([0.0; 2]);
            }
        }
        out.rgba[i] = rgba;
        out.normal[i] = n;
        out.albedo[i] = albedo;
        out.z[i] = z;
        out.agent_id[i] = id;
        if with_motion {
            out.motion[i] = motion;
        }
    }
    out.cryptomatte = over_cryptomatte(films);
    out.passes = over_passes(films, &out.z);
    Ok(out)
}

/// The names of the passes every film has, in file order; the others.
pub(crate) fn shared_passes(films: &[&Film]) -> (Vec<(String, [&'static str; 3])>, Vec<String>) {
    let mut all: Vec<(String, [&'static str; 3])> = Vec::new();
    for f in films {
        for p in &f.passes {
            if !all.iter().any(|(n, _)| *n == p.name) {
                all.push((p.name.clone(), p.channels));
            }
        }
    }
    all.sort_by(|a, b| passes::file_order(&a.0).cmp(&passes::file_order(&b.0)));
    let (shared, partial): (Vec<_>, Vec<_>) =
        all.into_iter().partition(|(n, _)| films.iter().all(|f| f.passes.iter().any(|p| p.name == *n)));
    (shared, partial.into_iter().map(|(n, _)| n).collect())
}

/// Stacks the passes every film has (see the module docs): over for light,
/// the Z-winning layer's for `P`. `z` is the stacked depth.
fn over_passes(films: &[&Film], z: &[f32]) -> Vec<Pass> {
    let (names, _) = shared_passes(films);
    names
        .into_iter()
        .map(|(name, channels)| {
            let layers: Vec<&Pass> = films.iter().filter_map(|f| f.passes.iter().find(|p| p.name == name)).collect();
            let mut data = vec![[0.0f32; 3]; z.len()];
            if name == passes::POSITION {
                for (i, out) in data.iter_mut().enumerate() {
                    // The layer the comp's Z came from (the last, front-most, on ties).
                    let winner = films.iter().rposition(|f| f.z[i].is_finite() && f.z[i] == z[i]);
                    if let Some(k) = winner {
                        *out = layers[k].data[i];
                    }
                }
            } else {
                for (f, pass) in films.iter().zip(&layers) {
                    for (i, out) in data.iter_mut().enumerate() {
                        let keep = 1.0 - f.rgba[i][3];
                        for (o, v) in out.iter_mut().zip(pass.data[i]) {
                            *o = v + keep * *o;
                        }
                    }
                }
            }
            Pass { name, channels, data }
        })
        .collect()
}

/// Stacks the layers' Cryptomatte types (matched by name): an object's
/// coverage in a layer counts through the layers in front of it, times
/// `1 - A` of each (the same over as colour), coverages of one id from
/// several layers add, and each pixel keeps its highest-coverage ranks
/// (ties by id bits, as the renderer ranks). Manifests are merged.
fn over_cryptomatte(films: &[&Film]) -> Vec<Cryptomatte> {
    let mut names: Vec<&str> = Vec::new();
    for f in films {
        for m in &f.cryptomatte {
            if !names.contains(&m.name.as_str()) {
                names.push(&m.name);
            }
        }
    }
    let Some(first) = films.first() else { return Vec::new() };
    let (w, h) = (first.width, first.height);
    let mut out = Vec::new();
    for name in names {
        let layers: Vec<(usize, &Cryptomatte)> = films
            .iter()
            .enumerate()
            .filter_map(|(k, f)| f.cryptomatte.iter().find(|m| m.name == name).map(|m| (k, m)))
            .filter(|(_, m)| m.width == w && m.height == h && m.ranks > 0)
            .collect();
        let ranks = layers.iter().map(|(_, m)| m.ranks).max().unwrap_or(0);
        let mut stacked = Cryptomatte::new(name, w, h, ranks);
        for (_, m) in &layers {
            stacked.manifest.extend(m.manifest.iter().map(|(k, &v)| (k.clone(), v)));
        }
        let mut acc: Vec<(u32, f32)> = Vec::new();
        for i in 0..(w as usize * h as usize) {
            acc.clear();
            // Front to back: what is in front hides what is behind.
            let mut through = 1.0f32;
            for k in (0..films.len()).rev() {
                if let Some((_, m)) = layers.iter().find(|(l, _)| *l == k) {
                    for p in m.pixel(i) {
                        let (id, cov) = (p[0].to_bits(), p[1] * through);
                        if id == 0 || cov <= 0.0 {
                            continue;
                        }
                        match acc.iter_mut().find(|a| a.0 == id) {
                            Some(a) => a.1 += cov,
                            None => acc.push((id, cov)),
                        }
                    }
                }
                through *= (1.0 - films[k].rgba[i][3]).clamp(0.0, 1.0);
            }
            acc.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
            for (r, &(id, cov)) in acc.iter().take(ranks).enumerate() {
                stacked.pairs[i * ranks + r] = [f32::from_bits(id), cov];
            }
        }
        out.push(stacked);
    }
    out
}

/// The layers of `frame` under render output `dir`, back to front.
///
/// With a manifest, its `comp_order`, and every layer must be there. Without
/// one, `dir` is scanned for `<layer>/<shot>.<layer>.<frame:04>.exr` (the
/// `full` reference is skipped): `set` first, then `crowdN` far to near, and
/// a gap in the crowd numbering is reported as a missing layer.
pub fn layer_files(dir: &Path, frame: i32, manifest: Option<&Manifest>) -> Result<Vec<(String, PathBuf)>> {
    if !dir.is_dir() {
        return Err(Error::Usage(format!("render directory {} does not exist", dir.display())));
    }
    if let Some(m) = manifest {
        let mut out = Vec::new();
        for layer in &m.comp_order {
            let path = layer_path(dir, &m.shot, layer, frame);
            if !path.is_file() {
                return Err(Error::Usage(format!(
                    "layer `{layer}` of shot {} frame {frame} is missing: no {} (render that layer of frame {frame} first)",
                    m.shot,
                    path.display()
                )));
            }
            out.push((layer.clone(), path));
        }
        return Ok(out);
    }

    // Scan: DIR/<layer>/<shot>.<layer>.<frame:04>.exr.
    let suffix = format!(".{frame:04}.exr");
    let mut found: Vec<(String, String, PathBuf)> = Vec::new(); // (shot, layer, path)
    let entries = std::fs::read_dir(dir).map_err(|e| Error::io(dir, e))?;
    let mut subdirs: Vec<PathBuf> = entries.filter_map(|e| e.ok().map(|e| e.path())).filter(|p| p.is_dir()).collect();
    subdirs.sort();
    for sub in subdirs {
        let Some(layer) = sub.file_name().and_then(|s| s.to_str()).map(str::to_string) else { continue };
        if layer == FULL_LAYER || layer == COMP_LAYER {
            continue;
        }
        let files = std::fs::read_dir(&sub).map_err(|e| Error::io(&sub, e))?;
        let mut names: Vec<String> =
            files.filter_map(|e| e.ok()?.file_name().into_string().ok()).filter(|n| n.ends_with(&suffix)).collect();
        names.sort();
        for name in names {
            let stem = &name[..name.len() - suffix.len()];
            if let Some(shot) = stem.strip_suffix(&format!(".{layer}")) {
                found.push((shot.to_string(), layer.clone(), sub.join(&name)));
            }
        }
    }
    let mut shots: Vec<&str> = found.iter().map(|f| f.0.as_str()).collect();
    shots.sort();
    shots.dedup();
    match shots.len() {
        0 => {
            return Err(Error::Usage(format!(
                "no layer files for frame {frame} under {} (expected <layer>/<shot>.<layer>.{frame:04}.exr)",
                dir.display()
            )))
        }
        1 => {}
        _ => {
            return Err(Error::setting(
                "manifest",
                format!(
                    "none given, and {} holds layers of several shots ({}); give the layer manifest to choose",
                    dir.display(),
                    shots.join(", ")
                ),
            ))
        }
    }
    let shot = shots[0].to_string();
    let mut set = None;
    let mut crowd: Vec<(usize, String, PathBuf)> = Vec::new();
    for (_, layer, path) in found {
        if layer == SET_LAYER {
            set = Some((layer, path));
        } else if let Some(i) = crowd_layer_index(&layer) {
            crowd.push((i, layer, path));
        } else {
            return Err(Error::setting(
                "manifest",
                format!(
                    "none given, and layer `{layer}` ({}) has no place in the comp order without one; give the layer manifest",
                    path.display()
                ),
            ));
        }
    }
    let Some(set) = set else {
        return Err(Error::Usage(format!(
            "layer `set` of shot {shot} frame {frame} is missing: no {}",
            layer_path(dir, &shot, SET_LAYER, frame).display()
        )));
    };
    crowd.sort_by_key(|c| std::cmp::Reverse(c.0));
    let n = crowd.first().map_or(0, |c| c.0 + 1);
    if let Some(gap) = (0..n).find(|i| !crowd.iter().any(|c| c.0 == *i)) {
        let name = crowd_layer_name(gap);
        return Err(Error::Usage(format!(
            "layer `{name}` of shot {shot} frame {frame} is missing: no {}",
            layer_path(dir, &shot, &name, frame).display()
        )));
    }
    Ok(std::iter::once(set).chain(crowd.into_iter().map(|(_, l, p)| (l, p))).collect())
}

/// Reads the layer files and checks they belong together (same shot, frame,
/// size, and each header names the layer its path says).
pub(crate) fn read_inputs(files: &[(String, PathBuf)], frame: i32) -> Result<Vec<CompInput>> {
    let mut out: Vec<CompInput> = Vec::new();
    for (layer, path) in files {
        let (film, meta) = exr::read_layer(path)?;
        if meta.layer != *layer {
            return Err(Error::invalid(path, format!("header says layer `{}`, expected `{layer}`", meta.layer))
                .field("throng/layer"));
        }
        if meta.frame != frame {
            return Err(Error::invalid(path, format!("header says frame {}, expected {frame}", meta.frame))
                .field("throng/frame"));
        }
        if let Some(first) = out.first() {
            if meta.shot != first.meta.shot {
                return Err(Error::invalid(
                    path,
                    format!(
                        "layer is from shot `{}` but {} is from shot `{}`",
                        meta.shot,
                        first.path.display(),
                        first.meta.shot
                    ),
                )
                .field("throng/shot"));
            }
            if meta.colourspace != first.meta.colourspace {
                let name = crate::render::colour::header_name;
                return Err(Error::invalid(
                    path,
                    format!(
                        "layer is in colourspace {} but {} is in {}: render every layer with one working colourspace",
                        name(meta.colourspace),
                        first.path.display(),
                        name(first.meta.colourspace)
                    ),
                )
                .field("throng/colorspace"));
            }
            if (film.width, film.height) != (first.film.width, first.film.height) {
                return Err(Error::invalid(
                    path,
                    format!(
                        "layer is {}x{} but {} is {}x{}",
                        film.width,
                        film.height,
                        first.path.display(),
                        first.film.width,
                        first.film.height
                    ),
                ));
            }
        }
        out.push(CompInput { path: path.clone(), film, meta });
    }
    Ok(out)
}

/// The comp's header: the back layer's, renamed, with near/far spanning
/// every layer and `worldToNDC` rebuilt for that range.
pub(crate) fn comp_meta(inputs: &[CompInput]) -> Result<LayerMeta> {
    let Some(back) = inputs.first() else {
        return Err(Error::Usage("nothing to composite: no layers".into()));
    };
    let mut meta = back.meta.clone();
    meta.layer = COMP_LAYER.to_string();
    meta.spp = inputs.iter().map(|i| i.meta.spp).min().unwrap_or(0);
    let near = inputs.iter().map(|i| i.meta.near).filter(|v| *v > 0.0).fold(f32::INFINITY, f32::min);
    let far = inputs.iter().map(|i| i.meta.far).fold(0.0f32, f32::max);
    if near.is_finite() && far > near && (near, far) != (back.meta.near, back.meta.far) {
        // worldToNDC = P(near, far) * worldToCamera; swap P's depth terms.
        let cam = Mat4::from_cols_array(&back.meta.world_to_camera);
        if cam.determinant().abs() > 1e-12 {
            let mut p = Mat4::from_cols_array(&back.meta.world_to_ndc) * cam.inverse();
            (p.z_axis.z, p.w_axis.z) = exr::ndc_depth_terms(near, far);
            meta.world_to_ndc = (p * cam).to_cols_array();
            meta.near = near;
            meta.far = far;
        }
    }
    Ok(meta)
}

/// What [`comp_frame`] made.
#[derive(Debug, Clone)]
pub struct Comped {
    /// The stacked image.
    pub film: Film,
    /// Its header.
    pub meta: LayerMeta,
    /// The layers used, back to front.
    pub layers: Vec<(String, PathBuf)>,
    /// What the comp left out and why (a pass some layers lack).
    pub warnings: Vec<String>,
}

/// Finds, reads and stacks the layers of `frame` under `dir`.
pub fn comp_frame(dir: &Path, frame: i32, manifest: Option<&Manifest>) -> Result<Comped> {
    let files = layer_files(dir, frame, manifest)?;
    let inputs = read_inputs(&files, frame)?;
    if let Some(m) = manifest {
        if let Some(i) = inputs.iter().find(|i| i.meta.shot != m.shot) {
            return Err(Error::invalid(
                &i.path,
                format!("layer is from shot `{}`, the manifest is for `{}`", i.meta.shot, m.shot),
            )
            .field("throng/shot"));
        }
    }
    let films: Vec<&Film> = inputs.iter().map(|i| &i.film).collect();
    let film = over(&films)?;
    let meta = comp_meta(&inputs)?;
    let mut warnings = Vec::new();
    for name in shared_passes(&films).1 {
        let without: Vec<&str> = files
            .iter()
            .zip(&inputs)
            .filter(|(_, i)| !i.film.passes.iter().any(|p| p.name == name))
            .map(|((l, _), _)| l.as_str())
            .collect();
        warnings.push(format!(
            "pass `{name}` left out of the comp: layer(s) {} have none (render every layer with the same passes)",
            without.join(", ")
        ));
    }
    Ok(Comped { film, meta, layers: files, warnings })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn film(rgba: [f32; 4], z: f32, id: u32) -> Film {
        let mut f = Film::new(1, 1);
        f.rgba[0] = rgba;
        f.z[0] = z;
        f.agent_id[0] = id;
        f.normal[0] = [0.0, rgba[3], 0.0];
        f.albedo[0] = [rgba[3]; 3];
        f
    }

    #[test]
    fn over_is_premultiplied_and_ordered() {
        let back = film([0.2, 0.4, 0.6, 1.0], 50.0, 0);
        let mid = film([0.25, 0.0, 0.0, 0.5], 10.0, 8);
        let front = film([0.0, 0.0, 0.1, 0.25], 5.0, 3);
        let out = over(&[&back, &mid, &front]).unwrap();
        let mid_on_back = [0.25 + 0.5 * 0.2, 0.5 * 0.4, 0.5 * 0.6, 1.0];
        let want = [0.75 * mid_on_back[0], 0.75 * mid_on_back[1], 0.1 + 0.75 * mid_on_back[2], 1.0];
        for c in 0..4 {
            assert!((out.rgba[0][c] - want[c]).abs() < 1e-6, "{:?} vs {want:?}", out.rgba[0]);
        }
        assert_eq!((out.z[0], out.agent_id[0]), (5.0, 3));
        // Coverage-weighted normals stack like colour: full coverage stays unit.
        assert!((out.normal[0][1] - 1.0).abs() < 1e-6);
    }

    #[test]
    fn z_and_id_come_from_the_nearest_hit() {
        let back = film([0.2, 0.2, 0.2, 1.0], 50.0, 0);
        // A near layer whose centre sample missed: no Z, no id, some coverage.
        let near_miss = film([0.1, 0.1, 0.1, 0.3], f32::INFINITY, 0);
        let mid = film([0.2, 0.0, 0.0, 1.0], 12.0, 5);
        let out = over(&[&back, &mid, &near_miss]).unwrap();
        assert_eq!((out.z[0], out.agent_id[0]), (12.0, 5));
        // The set in front of an agent (held out): the set's Z and id 0.
        let set = film([0.2, 0.2, 0.2, 1.0], 4.0, 0);
        let out = over(&[&set, &mid]).unwrap();
        assert_eq!((out.z[0], out.agent_id[0]), (4.0, 0));
    }

    #[test]
    fn sizes_must_match() {
        assert!(over(&[&Film::new(2, 2), &Film::new(2, 3)]).is_err());
        assert!(over(&[]).is_err());
    }
}
