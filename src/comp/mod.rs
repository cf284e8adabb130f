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

pub mod deep;

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
    let mut stack = Stack::new(first);
    for f in films {
        stack.push(f)?;
    }
    let mut mattes = MatteStack::new(first.width, first.height);
    for f in films.iter().rev() {
        mattes.push(f)?;
    }
    let mut out = stack.finish();
    out.cryptomatte = mattes.finish();
    Ok(out)
}

fn same_size(w: u32, h: u32, f: &Film) -> Result<()> {
    if f.width != w || f.height != h {
        return Err(Error::Usage(format!("layers differ in size: {w}x{h} and {}x{}", f.width, f.height)));
    }
    Ok(())
}

/// The colour side of [`over`] as a fold, one layer at a time, back to
/// front, so a caller holds one decoded layer and the stack (`throng
/// review`): colour, normals, albedo and light passes by over; Z, `agent.id`,
/// motion and `P` from the nearest finite Z. A film without a channel's
/// data (a reader that decoded only some channels) leaves it out: the stack
/// holds what the first film has.
pub(crate) struct Stack {
    out: Film,
    /// Stacked passes: those every film so far has, in the first film's order.
    passes: Vec<Pass>,
    pushed: usize,
}

impl Stack {
    /// An empty stack the size of `first`, with the channels it has.
    pub(crate) fn new(first: &Film) -> Stack {
        let n = first.width as usize * first.height as usize;
        let has = |len: usize| len == n && n > 0;
        let out = Film {
            width: first.width,
            height: first.height,
            rgba: if has(first.rgba.len()) { vec![[0.0; 4]; n] } else { Vec::new() },
            z: if has(first.z.len()) { vec![f32::INFINITY; n] } else { Vec::new() },
            normal: if has(first.normal.len()) { vec![[0.0; 3]; n] } else { Vec::new() },
            albedo: if has(first.albedo.len()) { vec![[0.0; 3]; n] } else { Vec::new() },
            agent_id: if has(first.agent_id.len()) { vec![0; n] } else { Vec::new() },
            cryptomatte: Vec::new(),
            motion: Vec::new(),
            passes: Vec::new(),
            samples: Vec::new(),
        };
        let passes = first
            .passes
            .iter()
            .map(|p| Pass { name: p.name.clone(), channels: p.channels, data: vec![[0.0; 3]; n] })
            .collect();
        Stack { out, passes, pushed: 0 }
    }

    /// Lays `f` over what is stacked.
    pub(crate) fn push(&mut self, f: &Film) -> Result<()> {
        let out = &mut self.out;
        same_size(out.width, out.height, f)?;
        let n = out.width as usize * out.height as usize;
        if !f.motion.is_empty() && out.motion.is_empty() && !out.z.is_empty() {
            out.motion = vec![[0.0; 2]; n];
        }
        let with_colour = f.rgba.len() == n;
        let keep = |i: usize| 1.0 - f.rgba[i][3];
        if with_colour && out.rgba.len() == n {
            for (i, o) in out.rgba.iter_mut().enumerate() {
                let k = keep(i);
                for (c, v) in o.iter_mut().enumerate() {
                    *v = f.rgba[i][c] + k * *v;
                }
            }
        }
        for (mine, theirs) in [(&mut out.normal, &f.normal), (&mut out.albedo, &f.albedo)] {
            if with_colour && mine.len() == n && theirs.len() == n {
                for (i, o) in mine.iter_mut().enumerate() {
                    let k = keep(i);
                    for c in 0..3 {
                        o[c] = theirs[i][c] + k * o[c];
                    }
                }
            }
        }
        // The passes every film so far has; `P` goes with the Z winner below.
        self.passes.retain(|p| f.passes.iter().any(|q| q.name == p.name));
        if with_colour {
            for p in self.passes.iter_mut().filter(|p| p.name != passes::POSITION) {
                let Some(q) = f.passes.iter().find(|q| q.name == p.name) else { continue };
                for (i, o) in p.data.iter_mut().enumerate() {
                    let k = keep(i);
                    for (o, v) in o.iter_mut().zip(q.data[i]) {
                        *o = v + k * *o;
                    }
                }
            }
        }
        if out.z.len() == n && f.z.len() == n {
            let position = self.passes.iter_mut().find(|p| p.name == passes::POSITION);
            let theirs = f.passes.iter().find(|q| q.name == passes::POSITION);
            let mut position = position.zip(theirs);
            for i in 0..n {
                // `<=`: later (nearer in comp order) layers win ties.
                let fz = f.z[i];
                if fz.is_finite() && fz <= out.z[i] {
                    out.z[i] = fz;
                    if let Some(id) = out.agent_id.get_mut(i) {
                        *id = f.agent_id.get(i).copied().unwrap_or(0);
                    }
                    if let Some(m) = out.motion.get_mut(i) {
                        *m = f.motion.get(i).copied().unwrap_or([0.0; 2]);
                    }
                    if let Some((p, q)) = position.as_mut() {
                        p.data[i] = q.data[i];
                    }
                }
            }
        }
        self.pushed += 1;
        Ok(())
    }

    /// The stacked film (no Cryptomatte: see [`MatteStack`]).
    pub(crate) fn finish(self) -> Film {
        let mut out = self.out;
        let mut passes = self.passes;
        if self.pushed == 0 {
            passes.clear();
        }
        // Stable: ties keep the first film's order, as [`shared_passes`] does.
        passes.sort_by(|a, b| passes::file_order(&a.name).cmp(&passes::file_order(&b.name)));
        out.passes = passes;
        out
    }
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

/// The Cryptomatte side of [`over`] as a fold, one layer at a time, front
/// to back (the nearest layer first): an object's coverage in a layer
/// counts through the layers in front of it, times `1 - A` of each (the
/// same over as colour), coverages of one id from several layers add, and
/// each pixel keeps its highest-coverage ranks (ties by id bits, as the
/// renderer ranks) once every layer is in. Types are matched by name and
/// their manifests merged (the nearest layer's entry wins). It holds the
/// non-zero (id, coverage) pairs seen so far, never a whole layer.
pub(crate) struct MatteStack {
    width: u32,
    height: u32,
    /// `1 - A` of every layer pushed, per pixel.
    through: Vec<f32>,
    /// Per type: name, ranks, merged manifest, per pixel the pairs seen.
    types: Vec<Matte>,
    /// The type names of each layer pushed, front to back (for the order).
    names: Vec<Vec<String>>,
}

struct Matte {
    name: String,
    ranks: usize,
    manifest: std::collections::BTreeMap<String, u32>,
    acc: Vec<Vec<(u32, f32)>>,
}

impl MatteStack {
    /// An empty stack of `width` x `height`.
    pub(crate) fn new(width: u32, height: u32) -> MatteStack {
        let n = width as usize * height as usize;
        MatteStack { width, height, through: vec![1.0; n], types: Vec::new(), names: Vec::new() }
    }

    /// Puts `f` behind what is stacked; its alpha hides what comes after.
    pub(crate) fn push(&mut self, f: &Film) -> Result<()> {
        same_size(self.width, self.height, f)?;
        let n = self.through.len();
        self.names.push(f.cryptomatte.iter().map(|m| m.name.clone()).collect());
        for m in f.cryptomatte.iter().filter(|m| m.width == self.width && m.height == self.height && m.ranks > 0) {
            let k = match self.types.iter().position(|t| t.name == m.name) {
                Some(k) => k,
                None => {
                    let acc = vec![Vec::new(); n];
                    self.types.push(Matte { name: m.name.clone(), ranks: 0, manifest: Default::default(), acc });
                    self.types.len() - 1
                }
            };
            let t = &mut self.types[k];
            t.ranks = t.ranks.max(m.ranks);
            for (name, &v) in &m.manifest {
                t.manifest.entry(name.clone()).or_insert(v);
            }
            for (i, acc) in t.acc.iter_mut().enumerate() {
                for p in m.pixel(i) {
                    let (id, cov) = (p[0].to_bits(), p[1] * self.through[i]);
                    if id == 0 || cov <= 0.0 {
                        continue;
                    }
                    match acc.iter_mut().find(|a| a.0 == id) {
                        Some(a) => a.1 += cov,
                        None => acc.push((id, cov)),
                    }
                }
            }
        }
        if f.rgba.len() == n {
            for (t, p) in self.through.iter_mut().zip(&f.rgba) {
                *t *= (1.0 - p[3]).clamp(0.0, 1.0);
            }
        }
        Ok(())
    }

    /// The stacked types, in the order they first appear back to front.
    pub(crate) fn finish(self) -> Vec<Cryptomatte> {
        let mut order: Vec<&str> = Vec::new();
        for name in self.names.iter().rev().flatten() {
            if !order.contains(&name.as_str()) {
                order.push(name);
            }
        }
        let (w, h) = (self.width, self.height);
        let mut types = self.types;
        order
            .into_iter()
            .map(|name| {
                let Some(k) = types.iter().position(|t| t.name == name) else {
                    return Cryptomatte::new(name, w, h, 0);
                };
                let mut t = types.swap_remove(k);
                let mut stacked = Cryptomatte::new(name, w, h, t.ranks);
                stacked.manifest = std::mem::take(&mut t.manifest);
                for (i, acc) in t.acc.iter_mut().enumerate() {
                    acc.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
                    for (r, &(id, cov)) in acc.iter().take(t.ranks).enumerate() {
                        stacked.pairs[i * t.ranks + r] = [f32::from_bits(id), cov];
                    }
                }
                stacked
            })
            .collect()
    }
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
