//! Loading an HDRI dome: a lat-long (equirectangular) environment map from a
//! Radiance `.hdr` (the image crate's decoder) or an OpenEXR `.exr` (the
//! first layer with R, G and B channels, any sample type). The map must be
//! 2:1, at most [`MAX_DOME_WIDTH`] texels wide, and every texel finite and
//! not negative. Orientation: [`Dome`] and docs/lights.md.
//!
//! Errors are [`Error::Invalid`] naming the file and no field: the caller
//! names the shot key (`.field("lights.dome.file")`).

use std::io::BufReader;
use std::path::Path;

use glam::Vec3;
use image::ImageDecoder;

use super::lights::Dome;
use crate::error::{Error, Result};

/// Widest dome map accepted (16384 x 8192 texels: 1.6 GB of RGB floats).
pub(crate) const MAX_DOME_WIDTH: u32 = 16384;

/// How many texels a Radiance file may decode to per byte of file. Its
/// run-length encoding stores at most 127 equal bytes of a channel in 2
/// bytes, about 64 texels per byte; a header claiming more is corrupt.
const MAX_HDR_TEXELS_PER_BYTE: u64 = 128;

/// Reads the lat-long map at `path` (`.hdr` or `.exr`) into a [`Dome`] with
/// the given multiplier (`scale`: intensity x 2^exposure x colour), rotation
/// about +Y (radians) and camera visibility.
pub fn load_dome(path: &Path, scale: Vec3, rotate: f32, camera_visible: bool) -> Result<Dome> {
    let ext = path.extension().map(|e| e.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
    let (width, height, texels) = match ext.as_str() {
        "hdr" => read_hdr(path)?,
        "exr" => read_exr(path)?,
        _ => {
            return Err(Error::invalid(
                path,
                "a dome map must be a lat-long Radiance .hdr or OpenEXR .exr file (by its extension)",
            ))
        }
    };
    check_texels(path, width, &texels)?;
    check_brightest(path, &texels, scale)?;
    Ok(Dome { file: path.to_path_buf(), width, height, texels, scale, rotate, camera_visible })
}

/// Refuses a size that is not 2:1 or is beyond [`MAX_DOME_WIDTH`], before
/// anything is allocated for it.
fn check_size(path: &Path, width: u64, height: u64) -> Result<(u32, u32)> {
    if height == 0 || width != 2 * height {
        return Err(Error::invalid(
            path,
            format!("the dome map is {width} x {height} texels: a lat-long map is twice as wide as it is high"),
        ));
    }
    if width > MAX_DOME_WIDTH as u64 {
        return Err(Error::invalid(
            path,
            format!(
                "the dome map is {width} x {height} texels, more than the {MAX_DOME_WIDTH} x {} accepted",
                MAX_DOME_WIDTH / 2
            ),
        ));
    }
    Ok((width as u32, height as u32))
}

/// Refuses a non-finite or negative texel, naming the first one.
fn check_texels(path: &Path, width: u32, texels: &[Vec3]) -> Result<()> {
    let bad = texels.iter().position(|t| !t.is_finite() || t.min_element() < 0.0);
    match bad {
        None => Ok(()),
        Some(i) => {
            let (x, y) = (i % width as usize, i / width as usize);
            let t = texels[i];
            Err(Error::invalid(
                path,
                format!(
                    "texel ({x}, {y}) (column, row from the top) is ({}, {}, {}): a dome's radiance must be finite \
                     and not negative",
                    t.x, t.y, t.z
                ),
            ))
        }
    }
}

/// Refuses a dome whose brightest texel times its scale (intensity x colour x
/// 2^exposure) overflows: its light would be no light at all. The bilinear
/// cell means the sampler builds sum eight scaled texels in f32, so the bound
/// is an eighth of f32's largest.
fn check_brightest(path: &Path, texels: &[Vec3], scale: Vec3) -> Result<()> {
    let brightest = texels.iter().fold(Vec3::ZERO, |m, t| m.max(*t));
    let product = brightest * scale;
    if (product * 8.0).is_finite() {
        return Ok(());
    }
    Err(Error::invalid(
        path,
        format!(
            "the brightest texel ({brightest}) x intensity x colour x 2^exposure ({scale}) overflows: {product} is past \
             {:e}, an eighth of the largest f32; lower the dome's intensity or exposure",
            f32::MAX / 8.0
        ),
    )
    .field("lights.dome"))
}

fn unreadable(path: &Path, e: std::io::Error) -> Error {
    Error::invalid(path, format!("cannot read the dome map: {e}"))
}

fn read_hdr(path: &Path) -> Result<(u32, u32, Vec<Vec3>)> {
    let file = std::fs::File::open(path).map_err(|e| unreadable(path, e))?;
    let file_len = file.metadata().map_err(|e| unreadable(path, e))?.len();
    let decoder = image::codecs::hdr::HdrDecoder::new(BufReader::new(file))
        .map_err(|e| Error::invalid(path, format!("Radiance HDR: {e}")))?;
    let (w, h) = decoder.dimensions();
    let (width, height) = check_size(path, w as u64, h as u64)?;
    let count = width as u64 * height as u64;
    if count > file_len.saturating_mul(MAX_HDR_TEXELS_PER_BYTE) {
        return Err(Error::invalid(
            path,
            format!(
                "Radiance HDR: the header says {width} x {height} texels, more than a {file_len}-byte file can hold"
            ),
        ));
    }
    let mut bytes = vec![0u8; count as usize * 12];
    decoder.read_image(&mut bytes).map_err(|e| Error::invalid(path, format!("Radiance HDR: {e}")))?;
    Ok((width, height, texels_of(bytes)))
}

/// Bytes of decoded texels converted at a time by [`texels_of`].
const CONVERT_CHUNK_BYTES: usize = 12 << 20;

/// The decoded RGB f32 texels in `bytes` (native endian) as `Vec3`s, without
/// holding both whole: converted from the end a chunk at a time, each chunk's
/// bytes handed back to the allocator (a large buffer shrinks in place) before
/// the next, then put back in order. A 16k map's bytes and texels are
/// 1.5 GiB each.
fn texels_of(mut bytes: Vec<u8>) -> Vec<Vec3> {
    let float = |b: &[u8]| f32::from_ne_bytes([b[0], b[1], b[2], b[3]]);
    let mut texels = Vec::with_capacity(bytes.len() / 12);
    while !bytes.is_empty() {
        let start = bytes.len().saturating_sub(CONVERT_CHUNK_BYTES);
        let start = start - start % 12;
        texels.extend(
            bytes[start..]
                .chunks_exact(12)
                .rev()
                .map(|p| Vec3::new(float(&p[0..4]), float(&p[4..8]), float(&p[8..12]))),
        );
        bytes.truncate(start);
        bytes.shrink_to_fit();
    }
    texels.reverse();
    texels
}

fn exr_error(path: &Path, e: exr::error::Error) -> Error {
    match e {
        exr::error::Error::Io(io) => unreadable(path, io),
        other => Error::invalid(path, format!("OpenEXR: {other}")),
    }
}

fn read_exr(path: &Path) -> Result<(u32, u32, Vec<Vec3>)> {
    use exr::prelude::{ReadChannels, ReadLayers};

    // The size of the layer that will be read, from the headers alone.
    let meta = exr::meta::MetaData::read_from_file(path, false).map_err(|e| exr_error(path, e))?;
    let has_rgb = |h: &exr::meta::header::Header| {
        ["R", "G", "B"].iter().all(|name| h.channels.list.iter().any(|c| c.name.eq(name)))
    };
    let header = meta
        .headers
        .iter()
        .find(|h| !h.deep && has_rgb(h))
        .ok_or_else(|| Error::invalid(path, "OpenEXR: no layer has R, G and B channels"))?;
    let (width, height) = check_size(path, header.layer_size.width() as u64, header.layer_size.height() as u64)?;
    crate::exr_guard::check_decoded_size(path)?;

    let (w, h) = (width as usize, height as usize);
    let image = exr::prelude::read()
        .no_deep_data()
        .largest_resolution_level()
        .rgb_channels(
            move |size, _| if (size.width(), size.height()) == (w, h) { vec![Vec3::ZERO; w * h] } else { Vec::new() },
            move |texels: &mut Vec<Vec3>, at, (r, g, b): (f32, f32, f32)| {
                if let Some(t) = texels.get_mut(at.y() * w + at.x()) {
                    *t = Vec3::new(r, g, b);
                }
            },
        )
        .first_valid_layer()
        .all_attributes()
        .from_file(path)
        .map_err(|e| exr_error(path, e))?;
    let texels = image.layer_data.channel_data.pixels;
    if texels.len() != w * h {
        return Err(Error::invalid(path, "OpenEXR: the R, G, B layer read is not the one its header describes"));
    }
    Ok((width, height, texels))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::path::PathBuf;

    fn temp(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("throng-dome-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        dir.join(name)
    }

    fn texel(x: u32, y: u32) -> [f32; 3] {
        // Values exactly representable in RGBE (8-bit mantissa, shared exponent).
        [x as f32 + 1.0, y as f32 + 1.0, 0.5]
    }

    fn write_hdr(path: &Path, w: u32, h: u32) {
        let pixels: Vec<image::Rgb<f32>> = (0..h).flat_map(|y| (0..w).map(move |x| image::Rgb(texel(x, y)))).collect();
        let file = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
        image::codecs::hdr::HdrEncoder::new(file).encode(&pixels, w as usize, h as usize).unwrap();
    }

    fn message(e: Error) -> String {
        e.to_string()
    }

    #[test]
    fn reads_hdr_top_row_first() {
        let path = temp("map.hdr");
        write_hdr(&path, 8, 4);
        let dome = load_dome(&path, Vec3::splat(2.0), 0.5, false).unwrap();
        assert_eq!((dome.width, dome.height, dome.texels.len()), (8, 4, 32));
        for (i, t) in dome.texels.iter().enumerate() {
            let (x, y) = (i as u32 % 8, i as u32 / 8);
            assert_eq!(t.to_array(), texel(x, y), "texel {x},{y}");
        }
        assert_eq!((dome.scale, dome.rotate, dome.camera_visible), (Vec3::splat(2.0), 0.5, false));
        assert_eq!(dome.file, path);
    }

    #[test]
    fn reads_exr_of_any_sample_type() {
        use exr::prelude::f16;
        let (w, h) = (8usize, 4usize);
        let full = temp("full.exr");
        exr::prelude::write_rgb_file(&full, w, h, |x, y| {
            let [r, g, b] = texel(x as u32, y as u32);
            (r, g, b)
        })
        .unwrap();
        let half = temp("half.exr");
        exr::prelude::write_rgba_file(&half, w, h, |x, y| {
            let [r, g, b] = texel(x as u32, y as u32).map(f16::from_f32);
            (r, g, b, f16::ONE)
        })
        .unwrap();
        for path in [full, half] {
            let dome = load_dome(&path, Vec3::ONE, 0.0, true).unwrap();
            assert_eq!((dome.width, dome.height), (8, 4));
            for (i, t) in dome.texels.iter().enumerate() {
                assert_eq!(t.to_array(), texel(i as u32 % 8, i as u32 / 8), "{}", path.display());
            }
        }
    }

    #[test]
    fn refuses_a_map_that_is_not_two_to_one() {
        let path = temp("square.hdr");
        write_hdr(&path, 4, 4);
        let msg = message(load_dome(&path, Vec3::ONE, 0.0, true).unwrap_err());
        assert!(msg.contains("4 x 4") && msg.contains("twice as wide"), "{msg}");
        let exr_path = temp("wide.exr");
        exr::prelude::write_rgb_file(&exr_path, 12, 4, |_, _| (1.0f32, 1.0f32, 1.0f32)).unwrap();
        let msg = message(load_dome(&exr_path, Vec3::ONE, 0.0, true).unwrap_err());
        assert!(msg.contains("12 x 4"), "{msg}");
    }

    #[test]
    fn refuses_a_header_beyond_the_bound_before_reading_pixels() {
        // A valid header claiming a 32768 x 16384 map, and no pixels.
        let path = temp("huge.hdr");
        std::fs::write(&path, b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 16384 +X 32768\n").unwrap();
        let msg = message(load_dome(&path, Vec3::ONE, 0.0, true).unwrap_err());
        assert!(msg.contains("more than the 16384 x 8192"), "{msg}");
        // Within the bound, but far more texels than the file can hold.
        std::fs::write(&path, b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 8192 +X 16384\n").unwrap();
        let msg = message(load_dome(&path, Vec3::ONE, 0.0, true).unwrap_err());
        assert!(msg.contains("can hold"), "{msg}");
    }

    #[test]
    fn refuses_non_finite_and_negative_texels_naming_them() {
        for (bad, shows) in [(f32::NAN, "NaN"), (f32::INFINITY, "inf"), (-1.0, "-1")] {
            let path = temp("bad.exr");
            exr::prelude::write_rgb_file(&path, 8, 4, |x, y| {
                (1.0f32, if (x, y) == (5, 2) { bad } else { 1.0 }, 1.0f32)
            })
            .unwrap();
            let msg = message(load_dome(&path, Vec3::ONE, 0.0, true).unwrap_err().field("lights.dome.file"));
            assert!(msg.contains("texel (5, 2)") && msg.contains(shows), "{msg}");
            assert!(msg.contains("field `lights.dome.file`") && msg.contains("bad.exr"), "{msg}");
        }
    }

    /// Each texel and the scale finite, their product not (issue 49).
    #[test]
    fn refuses_a_brightest_texel_whose_scaled_radiance_overflows() {
        let path = temp("bright.exr");
        exr::prelude::write_rgb_file(&path, 8, 4, |x, _| (if x == 3 { 1e20f32 } else { 1.0 }, 1.0f32, 1.0f32)).unwrap();
        let msg = message(load_dome(&path, Vec3::splat(1e30), 0.0, true).unwrap_err().or_field("lights.dome.file"));
        assert!(msg.contains("brightest texel") && msg.contains("overflows") && msg.contains("`lights.dome`"), "{msg}");
        assert!(load_dome(&path, Vec3::splat(1e10), 0.0, true).is_ok());
    }

    /// The texels converted a chunk at a time come out in order.
    #[test]
    fn texels_of_keeps_the_order_across_chunks() {
        let n = CONVERT_CHUNK_BYTES / 12 * 2 + 5;
        let bytes: Vec<u8> = (0..n * 3).flat_map(|k| (k as f32).to_ne_bytes()).collect();
        let texels = texels_of(bytes);
        assert_eq!(texels.len(), n);
        assert!(texels
            .iter()
            .enumerate()
            .all(|(i, t)| *t == Vec3::new(3.0 * i as f32, 3.0 * i as f32 + 1.0, 3.0 * i as f32 + 2.0)));
    }

    #[test]
    fn refuses_missing_unreadable_and_unknown_files() {
        let missing = temp("missing.hdr");
        let msg = message(load_dome(&missing, Vec3::ONE, 0.0, true).unwrap_err().field("lights.dome.file"));
        assert!(
            msg.contains("missing.hdr") && msg.contains("cannot read") && msg.contains("lights.dome.file"),
            "{msg}"
        );
        let garbage = temp("garbage.exr");
        std::fs::write(&garbage, b"not an exr").unwrap();
        let msg = message(load_dome(&garbage, Vec3::ONE, 0.0, true).unwrap_err());
        assert!(msg.contains("garbage.exr") && msg.contains("OpenEXR"), "{msg}");
        let garbage = temp("garbage.hdr");
        std::fs::write(&garbage, b"not an hdr").unwrap();
        let msg = message(load_dome(&garbage, Vec3::ONE, 0.0, true).unwrap_err());
        assert!(msg.contains("garbage.hdr") && msg.contains("Radiance"), "{msg}");
        let png = temp("sky.png");
        let msg = message(load_dome(&png, Vec3::ONE, 0.0, true).unwrap_err());
        assert!(msg.contains(".hdr") && msg.contains(".exr"), "{msg}");
    }
}
