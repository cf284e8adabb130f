//! The working colourspace: linear Rec.709 (the default) or ACEScg.
//!
//! Every input colour is authored in linear Rec.709 / sRGB primaries (D65):
//! material base colours, base-colour texture texels (decoded from sRGB by the
//! glTF loader), the sun's and sky's colours. With [`Colourspace::Acescg`]
//! they are converted to ACEScg (AP1 primaries, the ACES white) as the render
//! loads them ([`into_acescg`] for the library, [`scene_lights`] for each frame
//! scene's lights), so the path tracer multiplies and sums AP1 values, and the
//! EXR header says AP1 ([`chromaticities`], [`header_name`]). The PNG preview
//! converts back to Rec.709 before the sRGB transfer ([`to_rec709`]).
//!
//! The matrix is the standard one (the ACES and OpenColorIO "Linear Rec.709
//! (sRGB)" -> "ACEScg" transform): RGB -> XYZ with the Rec.709 primaries and
//! D65 white, a Bradford chromatic adaptation from D65 (0.3127, 0.3290) to the
//! ACES white (0.32168, 0.33767), XYZ -> AP1. Its rows sum to 1, so a neutral
//! stays neutral; `tests/colour.rs` derives it from the primaries.

use std::sync::Arc;

use glam::{Mat3, Vec3};

use crate::casting::ShotCrowd;
use crate::scene::atmosphere::Atmosphere;
use crate::scene::lights::Dome;
pub(crate) use crate::scene::{Acescg, Rec709};
use crate::scene::{FrameScene, Material, Texture};
pub use crate::shot::Colourspace;

/// Linear Rec.709 (D65) -> ACEScg (AP1, ACES white), rows: `ap1 = M * rec709`.
pub const REC709_TO_ACESCG: [[f32; 3]; 3] = [
    [0.613_097_4, 0.339_523_1, 0.047_379_45],
    [0.070_193_72, 0.916_353_9, 0.013_452_4],
    [0.020_615_59, 0.109_569_77, 0.869_814_6],
];

/// ACEScg -> linear Rec.709, the inverse of [`REC709_TO_ACESCG`].
pub const ACESCG_TO_REC709: [[f32; 3]; 3] = [
    [1.705_051, -0.621_792_1, -0.083_258_87],
    [-0.130_256_42, 1.140_804_7, -0.010_548_319],
    [-0.024_003_357, -0.128_968_98, 1.152_972_3],
];

/// OpenEXR `chromaticities` of AP1: red, green, blue, white (x, y).
pub const AP1_CHROMATICITIES: [[f32; 2]; 4] = [[0.713, 0.293], [0.165, 0.830], [0.128, 0.044], [0.32168, 0.33767]];

/// OpenEXR `chromaticities` of Rec.709 / sRGB: red, green, blue, D65 white.
pub const REC709_CHROMATICITIES: [[f32; 2]; 4] = [[0.64, 0.33], [0.30, 0.60], [0.15, 0.06], [0.3127, 0.3290]];

fn mat(rows: [[f32; 3]; 3]) -> Mat3 {
    Mat3::from_cols_array_2d(&rows).transpose()
}

/// A linear Rec.709 colour in ACEScg.
pub fn rec709_to_acescg(c: Vec3) -> Vec3 {
    mat(REC709_TO_ACESCG) * c
}

/// An ACEScg colour in linear Rec.709.
pub(crate) fn acescg_to_rec709(c: Vec3) -> Vec3 {
    mat(ACESCG_TO_REC709) * c
}

/// An input colour (authored in linear Rec.709) in the working space.
pub(crate) fn input(space: Colourspace, c: Vec3) -> Vec3 {
    match space {
        Colourspace::Rec709 => c,
        Colourspace::Acescg => rec709_to_acescg(c),
    }
}

/// The shot's air in the working space: its albedo is an input colour. A
/// Rec.709 albedo in 0..1 stays in 0..1 (each row of the matrix is
/// non-negative and sums to 1); the clamp only keeps f32 rounding inside.
pub(crate) fn atmosphere(air: Atmosphere, space: Colourspace) -> Atmosphere {
    Atmosphere { albedo: input(space, air.albedo).clamp(Vec3::ZERO, Vec3::ONE), ..air }
}

/// A working-space colour in linear Rec.709, for display (PNG previews).
pub(crate) fn to_rec709(space: Colourspace, c: Vec3) -> Vec3 {
    match space {
        Colourspace::Rec709 => c,
        Colourspace::Acescg => acescg_to_rec709(c),
    }
}

/// The primaries and white of `space`, as OpenEXR's `chromaticities` wants them.
pub(crate) fn chromaticities(space: Colourspace) -> [[f32; 2]; 4] {
    match space {
        Colourspace::Rec709 => REC709_CHROMATICITIES,
        Colourspace::Acescg => AP1_CHROMATICITIES,
    }
}

/// `throng/colorspace`: `lin_rec709` or `ACEScg` (OpenColorIO's names).
pub(crate) fn header_name(space: Colourspace) -> &'static str {
    match space {
        Colourspace::Rec709 => "lin_rec709",
        Colourspace::Acescg => "ACEScg",
    }
}

/// The working space a `throng/colorspace` header names (`None`: not ours).
pub(crate) fn from_header_name(name: &str) -> Option<Colourspace> {
    [Colourspace::Rec709, Colourspace::Acescg].into_iter().find(|&s| header_name(s) == name)
}

/// The crowd with its library's material base colours and texture texels
/// (RGB; alpha kept) converted from Rec.709 into ACEScg, for a
/// [`super::job::RenderJob`] whose `colourspace` is ACEScg. It takes the
/// crowd: a converted crowd cannot be converted again nor exported (the
/// exporters write linear Rec.709 and take a Rec.709 crowd), which is a type
/// error, not a rule to remember:
///
/// ```no_run
/// # fn demo() -> throng::error::Result<()> {
/// let crowd = throng::casting::ShotCrowd::load(std::path::Path::new("demo/shot.toml"))?;
/// throng::export::export_frame(&crowd, 1024, None, std::path::Path::new("frame.glb"))?;
/// let _for_render = throng::render::colour::into_acescg(crowd);
/// # Ok(())
/// # }
/// ```
///
/// ```compile_fail
/// # fn demo() -> throng::error::Result<()> {
/// let crowd = throng::casting::ShotCrowd::load(std::path::Path::new("demo/shot.toml"))?;
/// let once = throng::render::colour::into_acescg(crowd);
/// let _twice = throng::render::colour::into_acescg(once); // ShotCrowd<Acescg> is not ShotCrowd<Rec709>
/// # Ok(())
/// # }
/// ```
///
/// ```compile_fail
/// # fn demo() -> throng::error::Result<()> {
/// let crowd = throng::casting::ShotCrowd::load(std::path::Path::new("demo/shot.toml"))?;
/// let converted = throng::render::colour::into_acescg(crowd);
/// throng::export::export_frame(&converted, 1024, None, std::path::Path::new("frame.glb"))?; // exports Rec.709 only
/// # Ok(())
/// # }
/// ```
pub fn into_acescg(crowd: ShotCrowd<Rec709>) -> ShotCrowd<Acescg> {
    crowd.convert_colours(|materials, textures| convert_library(materials, textures, Colourspace::Acescg))
}

/// Converts material colours (base colour, emission, volume attenuation) and
/// colour texture texels (RGB; alpha kept) from Rec.709 into `space`, in
/// place (what [`into_acescg`] does to a crowd's library). Textures no
/// material reads as colour (normal, metallic-roughness and transmission
/// maps: data, not colour) are left as they are.
pub fn convert_library(materials: &mut [Material], textures: &mut [Texture], space: Colourspace) {
    if space == Colourspace::Rec709 {
        return;
    }
    let mut colour = vec![false; textures.len()];
    for m in materials {
        m.base_color = input(space, m.base_color);
        m.emission = input(space, m.emission);
        if let Some(v) = &mut m.volume {
            v.attenuation_color = input(space, v.attenuation_color);
        }
        for t in [m.base_color_texture, m.emissive_texture].into_iter().flatten() {
            if let Some(c) = colour.get_mut(t as usize) {
                *c = true;
            }
        }
    }
    for (t, _) in textures.iter_mut().zip(&colour).filter(|(_, &c)| c) {
        for texel in &mut t.texels {
            let c = input(space, Vec3::new(texel[0], texel[1], texel[2]));
            texel[..3].copy_from_slice(&c.to_array());
        }
    }
}

/// Converts a frame scene's light colours (sun, sky, dome texels, local
/// lights) from Rec.709 into `space`. In Rec.709 nothing is touched (the
/// dome stays the crowd's, shared). In ACEScg the dome's texels are copied
/// and converted: a render of many frames converts it once
/// ([`scene_lights_once`]).
pub fn scene_lights(scene: &mut FrameScene, space: Colourspace) {
    scene_lights_once(scene, space, &mut ConvertedDome::default());
}

/// The dome of a render's frame scenes converted into the working
/// colourspace once, for every frame and layer after the first: a 16k map is
/// 1.5 GiB of texels, which converting per frame scene copied each time.
#[derive(Debug, Default)]
pub struct ConvertedDome {
    /// The crowd's dome (Rec.709) and its conversion.
    last: Option<(Arc<Dome>, Arc<Dome>)>,
}

/// [`scene_lights`], converting the dome only when `converted` does not
/// already hold it (the same crowd dome: the same `Arc`).
pub fn scene_lights_once(scene: &mut FrameScene, space: Colourspace, converted: &mut ConvertedDome) {
    if space == Colourspace::Rec709 {
        return;
    }
    let lights = &mut scene.lights;
    if let Some(sun) = &mut lights.sun {
        sun.irradiance = input(space, sun.irradiance);
    }
    lights.sky.radiance = input(space, lights.sky.radiance);
    for light in &mut lights.local {
        light.emission = input(space, light.emission);
    }
    if let Some(dome) = &mut lights.dome {
        let done = converted.last.as_ref().filter(|(from, _)| Arc::ptr_eq(from, dome)).map(|(_, to)| to.clone());
        let to = match done {
            Some(to) => to,
            None => {
                // Drop the last conversion before making this one.
                converted.last = None;
                // The shot's own stays Rec.709. The scale is a colour too:
                // fold it in before the matrix.
                let to = Arc::new(Dome {
                    file: dome.file.clone(),
                    width: dome.width,
                    height: dome.height,
                    texels: dome.texels.iter().map(|t| input(space, *t * dome.scale)).collect(),
                    scale: Vec3::ONE,
                    rotate: dome.rotate,
                    camera_visible: dome.camera_visible,
                });
                converted.last = Some((dome.clone(), to.clone()));
                to
            }
        };
        *dome = to;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_airs_albedo_is_converted_and_stays_an_albedo() {
        let air = Atmosphere {
            density: 0.1,
            albedo: Vec3::new(0.9, 0.5, 0.2),
            anisotropy: 0.3,
            top: 5.0,
            ..Default::default()
        };
        assert_eq!(atmosphere(air, Colourspace::Rec709), air);
        let aces = atmosphere(air, Colourspace::Acescg);
        assert!((aces.albedo - rec709_to_acescg(air.albedo)).abs().max_element() < 1e-6);
        assert_eq!((aces.density, aces.anisotropy, aces.top), (0.1, 0.3, 5.0));
        for c in [Vec3::X, Vec3::Y, Vec3::Z, Vec3::ONE, Vec3::ZERO] {
            let a = atmosphere(Atmosphere { albedo: c, ..air }, Colourspace::Acescg);
            assert!(a.check().is_ok(), "{c} -> {}", a.albedo);
        }
    }

    #[test]
    fn the_matrices_are_inverses_and_keep_neutrals() {
        let m = mat(REC709_TO_ACESCG) * mat(ACESCG_TO_REC709);
        assert!(m.abs_diff_eq(Mat3::IDENTITY, 1e-6), "{m}");
        for v in [0.18f32, 0.5, 1.0, 7.0] {
            let g = rec709_to_acescg(Vec3::splat(v));
            assert!((g - Vec3::splat(v)).abs().max_element() <= 2e-6 * v, "{g}");
        }
    }
}
