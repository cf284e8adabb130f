//! Denoising a rendered film with Intel Open Image Denoise (OIDN, through
//! the `throng-oidn` crate), the denoiser every renderer a lighter compares
//! with ships: its `RT` filter, HDR, with albedo and normal guides that are
//! themselves prefiltered first (OIDN's "cleanAux" recipe, its best quality,
//! and what motion blur and depth of field, which make the guides noisy,
//! need).
//!
//! What a denoised film holds (docs/render.md, "Denoising"):
//! - every light pass (light paths, light groups, `shadow`) denoised, each on
//!   its own with the same guides;
//! - the beauty: with light groups, the sum of the denoised groups, so the
//!   groups add up to the denoised beauty exactly (as Karma's and RenderMan's
//!   light-group workflows define it: regrading a group in comp is then the
//!   same as regrading it here); without them, the beauty denoised on its own;
//! - the noisy beauty, kept as the pass [`NOISY`] (`noisy.R/G/B`);
//! - alpha, depth, ids, normals, albedo, motion, Cryptomatte, `P` and the
//!   air's transmittance untouched: they are not light, and a denoised id or
//!   depth means nothing.
//!
//! Crowd layers are premultiplied RGBA with holdouts: wherever a pixel has
//! no coverage (alpha 0: empty, or held out by a nearer layer) every
//! denoised channel is zero, so no colour bleeds into a hole and the stack
//! of denoised layers composites as the noisy one does. Denoised values are
//! clamped at zero (the network can undershoot next to a bright edge).
//!
//! Determinism: the noisy channels are exactly what the render gives. The
//! denoised ones are bit-identical run to run and for any thread count on
//! one machine; OIDN does not promise the same floats on another instruction
//! set (AVX2, AVX-512, AMX), so denoised goldens compare with a tolerance.

use std::path::{Path, PathBuf};

use throng_oidn as oidn;

use crate::error::{Error, Result};
use crate::render::film::{Film, Pass};
pub use crate::scene::passes::NOISY;
use crate::shot::Denoise;

fn quality(denoise: Denoise) -> oidn::Quality {
    match denoise {
        Denoise::High => oidn::Quality::High,
        Denoise::Balanced => oidn::Quality::Balanced,
        Denoise::Fast => oidn::Quality::Fast,
    }
}

/// A loaded denoiser: OIDN's CPU device, made once per run and used for
/// every layer-frame.
pub struct Denoiser {
    device: oidn::Device,
    library: PathBuf,
}

impl std::fmt::Debug for Denoiser {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Denoiser").field("library", &self.library).field("version", &self.version()).finish()
    }
}

/// What a render's files say denoised them (`throng/denoiser`).
pub fn stamp(denoiser: &Denoiser, quality: Denoise) -> String {
    format!(
        "Open Image Denoise {}, RT filter, hdr, prefiltered albedo and normal (cleanAux), quality {}",
        denoiser.version(),
        quality.name()
    )
}

impl Denoiser {
    /// Opens OIDN: at `library` if given (a file, or a folder holding
    /// `libOpenImageDenoise.so.2`), else where `throng_oidn::Library::find`
    /// looks (`THRONG_OIDN`, the checkout's `.oidn/`, Python installs of
    /// `pyoidn`, the loader's path). `threads`: OIDN's worker threads, 0 for
    /// every core. Not found: an error saying how to install it.
    pub fn open(library: Option<&Path>, threads: usize) -> Result<Denoiser> {
        let found = oidn::Library::find(library).map_err(|e| Error::setting("denoise", e.to_string()))?;
        let options = oidn::DeviceOptions { num_threads: u32::try_from(threads).unwrap_or(0), set_affinity: false };
        let device = oidn::Device::new(found, options).map_err(|e| Error::setting("denoise", e.to_string()))?;
        Ok(Denoiser { device, library: found.path().to_path_buf() })
    }

    /// OIDN's version as dotted text (`2.5.1`).
    pub fn version(&self) -> String {
        let v = self.device.version();
        format!("{}.{}.{}", v / 10000, v / 100 % 100, v % 100)
    }

    /// The shared library in use.
    pub fn library(&self) -> &Path {
        &self.library
    }

    /// Denoises `film` in place (see the module docs for what changes).
    /// Refuses a film that is already denoised (it holds [`NOISY`]): its
    /// passes are no longer noisy, so denoising again would only blur.
    pub fn denoise(&self, film: &mut Film, preset: Denoise) -> Result<()> {
        if film.passes.iter().any(|p| p.name == NOISY) {
            return Err(Error::setting("denoise", "the image is already denoised (it has noisy.R/G/B)"));
        }
        let (w, h) = (film.width as usize, film.height as usize);
        if w == 0 || h == 0 {
            return Ok(());
        }
        let options =
            oidn::Options { hdr: true, quality: quality(preset), clean_aux: true, ..oidn::Options::default() };
        let albedo = flatten(&film.albedo);
        let normal = flatten(&film.normal);
        let mut filter = oidn::Denoiser::prefiltered(&self.device, w, h, Some(&albedo), Some(&normal), options)
            .map_err(|e| Error::setting("denoise", e.to_string()))?;
        let coverage: Vec<bool> = film.rgba.iter().map(|p| p[3] > 0.0).collect();
        let mut run = |plane: &[f32]| -> Result<Vec<[f32; 3]>> {
            let out = filter.denoise(plane).map_err(|e| Error::setting("denoise", e.to_string()))?;
            Ok(out
                .chunks_exact(3)
                .zip(&coverage)
                .map(|(c, &covered)| if covered { [clean(c[0]), clean(c[1]), clean(c[2])] } else { [0.0; 3] })
                .collect())
        };
        let mut groups: Option<Vec<[f32; 3]>> = None;
        for pass in film.passes.iter_mut().filter(|p| is_light(p)) {
            pass.data = run(&flatten(&pass.data))?;
            if pass.name.starts_with("lg_") {
                let sum = groups.get_or_insert_with(|| vec![[0.0; 3]; w * h]);
                for (s, v) in sum.iter_mut().zip(&pass.data) {
                    *s = [s[0] + v[0], s[1] + v[1], s[2] + v[2]];
                }
            }
        }
        let noisy: Vec<[f32; 3]> = film.rgba.iter().map(|p| [p[0], p[1], p[2]]).collect();
        let beauty = match groups {
            Some(sum) => sum,
            None => run(&flatten(&noisy))?,
        };
        for (p, b) in film.rgba.iter_mut().zip(&beauty) {
            p[..3].copy_from_slice(b);
        }
        film.passes.insert(0, Pass { name: NOISY.into(), channels: ["R", "G", "B"], data: noisy });
        Ok(())
    }
}

/// A pass of light (the light paths, light groups and `shadow`): denoised;
/// `P` is a position and the transmittance a fraction, not light.
fn is_light(pass: &Pass) -> bool {
    pass.channels == ["R", "G", "B"] && pass.name != NOISY && pass.name != crate::scene::passes::TRANSMITTANCE
}

/// A denoised value as a film holds it: finite and not negative.
fn clean(v: f32) -> f32 {
    if v > 0.0 && v.is_finite() {
        v
    } else {
        0.0
    }
}

fn flatten(plane: &[[f32; 3]]) -> Vec<f32> {
    plane.iter().flatten().copied().collect()
}

/// The channels a file must hold to be denoised: the beauty and both guides.
pub const NEEDED_CHANNELS: [&str; 10] = ["R", "G", "B", "A", "albedo.R", "albedo.G", "albedo.B", "N.X", "N.Y", "N.Z"];

/// Denoises the layer or comp file `input` (as `throng render` or `throng
/// comp` wrote it) into `output`, a new file: the same channels and header,
/// with the beauty and light passes denoised and the noisy beauty kept (see
/// the module docs). Refuses a file lacking the beauty or a guide (naming
/// the channel), one already denoised, and an `output` that is `input`.
pub fn denoise_file(denoiser: &Denoiser, input: &Path, output: &Path, preset: Denoise) -> Result<()> {
    check_input(input)?;
    crate::output::InputFiles::new([("input".to_string(), input.to_path_buf())]).check(output)?;
    let (mut film, mut meta) = crate::render::exr::read_layer(input)?;
    if film.passes.iter().any(|p| p.name == NOISY) {
        return Err(Error::invalid(input, "is already denoised (it has noisy.R/G/B)").field("noisy.R"));
    }
    denoiser.denoise(&mut film, preset).map_err(|e| Error::invalid(input, e.to_string()))?;
    meta.denoiser = stamp(denoiser, preset);
    let options = crate::render::exr::WriteOptions {
        manifest: crate::render::exr::ManifestMode::Header,
        compression: crate::render::exr::LayerCompression::Zip,
    };
    crate::render::exr::write_layer_with(output, &film, &meta, &options)
}

/// Whether `input` can be denoised, from its header alone: a readable EXR
/// with the beauty and both guides, not denoised already. What
/// [`denoise_file`] checks first, and what a batch checks for every file
/// before it writes any.
pub fn check_input(input: &Path) -> Result<()> {
    crate::error::check_readable_file(input)?;
    let (_, _, channels) = crate::render::exr::read_channel_names(input)?;
    if let Some(missing) = NEEDED_CHANNELS.iter().find(|c| !channels.iter().any(|n| n == *c)) {
        return Err(Error::invalid(
            input,
            format!(
                "has no channel {missing}: denoising needs the beauty (R, G, B, A) and its albedo (albedo.R/G/B) \
                 and normal (N.X/Y/Z) guides, as throng render writes them"
            ),
        )
        .field(*missing));
    }
    if channels.iter().any(|n| n == "noisy.R") {
        return Err(Error::invalid(input, "is already denoised (it has noisy.R/G/B); denoise the render it came from")
            .field("noisy.R"));
    }
    Ok(())
}
