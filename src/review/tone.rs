//! A film's channels as 8-bit sRGB pictures for the page: the beauty and
//! light passes exposed and converted from the working colourspace, depth,
//! normals, albedo, alpha, `agent.id` in false colour, and an agent's
//! Cryptomatte matte as a see-through overlay. PNG-encoded with `image`.

use glam::Vec3;

use crate::render::colour::{self, Colourspace};
use crate::render::cryptomatte::{agent_name, AGENT_MATTE};
use crate::render::exr::srgb_encode;
use crate::render::Film;

/// The views every layer has, before its light passes.
pub(crate) const BASIC_VIEWS: [&str; 6] = ["beauty", "alpha", "depth", "normal", "albedo", "id"];

/// Views a film offers: the basic ones, then its passes (light paths, light
/// groups, `P`) in file order.
pub(crate) fn views(pass_names: impl Iterator<Item = String>) -> Vec<String> {
    BASIC_VIEWS.iter().map(|s| s.to_string()).chain(pass_names).collect()
}

/// Linear working-space colour to an sRGB display pixel.
fn display(space: Colourspace, c: [f32; 3]) -> [u8; 3] {
    colour::to_rec709(space, Vec3::from(c)).to_array().map(srgb_encode)
}

/// Linear light (working space) as RGB8 display pixels, exposed by
/// `exposure` stops.
pub(crate) fn light_pixels(space: Colourspace, light: impl Iterator<Item = [f32; 3]>, exposure: f32) -> Vec<u8> {
    let gain = exposure.exp2();
    light.flat_map(|p| display(space, p.map(|c| c * gain))).collect()
}

/// A view of `film` as RGB8 pixels (row-major), or why not. `exposure` is
/// in stops and applies to light (beauty and light passes).
pub(crate) fn view_pixels(film: &Film, space: Colourspace, view: &str, exposure: f32) -> Result<Vec<u8>, String> {
    let px: Vec<[u8; 3]> = match view {
        "beauty" => return Ok(light_pixels(space, film.rgba.iter().map(|p| [p[0], p[1], p[2]]), exposure)),
        "alpha" => film.rgba.iter().map(|p| [srgb_encode(p[3]); 3]).collect(),
        "albedo" => film.albedo.iter().map(|&a| display(space, a)).collect(),
        "normal" => film
            .normal
            .iter()
            .zip(&film.rgba)
            .map(|(n, p)| n.map(|c| ((0.5 * c + 0.5 * p[3]).clamp(0.0, 1.0) * 255.0 + 0.5) as u8))
            .collect(),
        "depth" => {
            // Near white, far dark, over the finite range of this image.
            let finite = film.z.iter().copied().filter(|z| z.is_finite());
            let (lo, hi) = finite.fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), z| (lo.min(z), hi.max(z)));
            let span = (hi - lo).max(1e-6);
            (film.z.iter())
                .map(
                    |&z| if z.is_finite() { [(255.0 * (1.0 - 0.85 * (z - lo) / span) + 0.5) as u8; 3] } else { [0; 3] },
                )
                .collect()
        }
        "id" => film.agent_id.iter().map(|&id| id_colour(id)).collect(),
        name => {
            let Some(pass) = film.passes.iter().find(|p| p.name == name) else {
                let mut known: Vec<String> = BASIC_VIEWS.iter().map(|s| s.to_string()).collect();
                known.extend(film.passes.iter().map(|p| p.name.clone()));
                return Err(format!("no view `{name}` in this image; it has {}", known.join(", ")));
            };
            if pass.name == "P" {
                // World position: each metre a colour ramp.
                pass.data.iter().map(|p| p.map(|c| (c.rem_euclid(1.0) * 255.0) as u8)).collect()
            } else {
                return Ok(light_pixels(space, pass.data.iter().copied(), exposure));
            }
        }
    };
    Ok(px.into_iter().flatten().collect())
}

/// A stable, well-spread colour per agent id (`agent.id` = cache id + 1; 0,
/// set or sky, is black).
pub(crate) fn id_colour(id: u32) -> [u8; 3] {
    if id == 0 {
        return [0; 3];
    }
    // Golden-ratio hues, two brightness bands so neighbours differ.
    let h = (id as f32 * 0.618_034).fract() * 6.0;
    let v = if id.is_multiple_of(2) { 1.0 } else { 0.72 };
    let x = 1.0 - (h % 2.0 - 1.0).abs();
    let (r, g, b) = match h as u32 {
        0 => (1.0, x, 0.0),
        1 => (x, 1.0, 0.0),
        2 => (0.0, 1.0, x),
        3 => (0.0, x, 1.0),
        4 => (x, 0.0, 1.0),
        _ => (1.0, 0.0, x),
    };
    [r, g, b].map(|c: f32| ((0.25 + 0.75 * c) * v * 255.0 + 0.5) as u8)
}

/// Coverage of agent `id` (cache id) per pixel, from the `CryptoAgent`
/// matte when the film has one (`true`), else from `agent.id` (`false`).
pub(crate) fn agent_coverage(film: &Film, id: u32) -> (Vec<f32>, bool) {
    match film.cryptomatte.iter().find(|m| m.name == AGENT_MATTE) {
        Some(m) => (m.matte(&agent_name(id)), true),
        None => (film.agent_id.iter().map(|&a| if a == id + 1 { 1.0 } else { 0.0 }).collect(), false),
    }
}

/// A coverage matte as RGBA8: warm yellow, see-through where covered
/// (60% at full coverage, so the agent shows beneath), clear elsewhere.
pub(crate) fn matte_pixels(coverage: &[f32]) -> Vec<u8> {
    coverage.iter().flat_map(|&c| [255, 214, 10, (c.clamp(0.0, 1.0) * 153.0 + 0.5) as u8]).collect()
}

/// PNG bytes of RGB8 (`channels` 3) or RGBA8 (4) pixels.
pub(crate) fn png(width: u32, height: u32, channels: u8, pixels: Vec<u8>) -> Result<Vec<u8>, String> {
    let mut out = std::io::Cursor::new(Vec::new());
    let r = match channels {
        3 => image::RgbImage::from_raw(width, height, pixels).map(|i| i.write_to(&mut out, image::ImageFormat::Png)),
        _ => image::RgbaImage::from_raw(width, height, pixels).map(|i| i.write_to(&mut out, image::ImageFormat::Png)),
    };
    match r {
        Some(Ok(())) => Ok(out.into_inner()),
        Some(Err(e)) => Err(format!("cannot encode PNG: {e}")),
        None => Err("image buffer does not match its size".into()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn views_tone_map_and_refuse_unknown_passes() {
        let mut f = Film::new(2, 1);
        f.rgba = vec![[0.18, 0.18, 0.18, 1.0], [0.0, 0.0, 0.0, 0.0]];
        f.z = vec![5.0, f32::INFINITY];
        f.agent_id = vec![3, 0];
        let b = view_pixels(&f, Colourspace::Rec709, "beauty", 0.0).unwrap();
        // 18% grey is sRGB 118; one stop up is 0.36 -> 162.
        assert_eq!(&b[..3], &[118, 118, 118]);
        assert_eq!(view_pixels(&f, Colourspace::Rec709, "beauty", 1.0).unwrap()[0], 162);
        assert_eq!(&view_pixels(&f, Colourspace::Rec709, "depth", 0.0).unwrap()[3..], &[0, 0, 0]);
        let ids = view_pixels(&f, Colourspace::Rec709, "id", 0.0).unwrap();
        assert_ne!(&ids[..3], &[0, 0, 0]);
        assert_eq!(&ids[3..], &[0, 0, 0]);
        let e = view_pixels(&f, Colourspace::Rec709, "diffuse_direct", 0.0).unwrap_err();
        assert!(e.contains("diffuse_direct") && e.contains("beauty"), "{e}");
        assert_ne!(id_colour(1), id_colour(2));
    }
}
