//! OpenEXR output and reading (with `scene::dome`, the only files that name the exr crate) and PNG previews.
//!
//! One single-part scanline file per (layer, frame), ZIP16 unless asked
//! otherwise ([`LayerCompression`]), increasing lines, Rec.709 `chromaticities`,
//! channels (sorted): `A B G R` (half, premultiplied), `N.X N.Y N.Z` (half),
//! `Z` (float, camera-space depth, +inf = no hit), `agent.id` (uint, 0 = no
//! agent, else cache id + 1), `albedo.B albedo.G albedo.R` (half), and when
//! the film has them the Cryptomatte rank channels `CryptoAgent00.R ...`,
//! `CryptoMaterial00.R ...`, `CryptoPart00.R ...` (float) with their
//! `cryptomatte/<key>/...` header
//! (see [`super::cryptomatte`]), and the passes asked for
//! (`scene::passes`): `diffuse_direct.B diffuse_direct.G diffuse_direct.R`
//! ... and `lg_<group>.B/G/R` and `shadow.B/G/R` (half, premultiplied like
//! the beauty), `P.X P.Y P.Z` (float, world position); with adaptive
//! sampling `samples` (uint, the samples each pixel took).

use std::collections::BTreeMap;
use std::path::Path;

use exr::prelude::{
    f16, AnyChannel, AnyChannels, AttributeValue, Blocks, Compression, Encoding, FlatSamples, Image, Layer,
    LayerAttributes, LineOrder, ReadChannels, ReadLayers, SmallVec, Text, WritableImage,
};
use glam::{Mat4, Vec3, Vec4};

use super::colour::{self, Colourspace};
use super::cryptomatte;
use super::film::Film;
use crate::error::{write_atomic, Error, Result};
use crate::exr_guard::exr_error;
use crate::scene::Camera;

pub mod deep;
pub mod mattes;

/// The channel holding each pixel's sample count (adaptive sampling only).
pub const SAMPLES_CHANNEL: &str = "samples";

/// What `agent.id` means, written to `throng/idMapping`.
pub const ID_MAPPING: &str = "agent.id = cache agent id + 1; 0 = no agent (sky, set or holdout)";

/// Header metadata of one layer file.
#[derive(Clone, Debug, PartialEq)]
pub struct LayerMeta {
    /// Shot name.
    pub shot: String,
    /// Layer name (also the EXR part name).
    pub layer: String,
    /// Shot frame.
    pub frame: i32,
    /// Shot seed (written as decimal text: EXR has no 64-bit integer attribute).
    pub seed: u64,
    /// Samples per pixel.
    pub spp: u32,
    /// The `agent.id` convention.
    pub id_mapping: String,
    /// `worldToCamera`, Imath layout (see [`camera_matrices`]).
    pub world_to_camera: [f32; 16],
    /// `worldToNDC`, Imath layout (see [`camera_matrices`]).
    pub world_to_ndc: [f32; 16],
    /// Near clip distance (metres).
    pub near: f32,
    /// Far clip distance (metres).
    pub far: f32,
    /// Frames per second (`framesPerSecond`; not written when 0).
    pub fps: f32,
    /// `throng/renderFingerprint`: what `--resume` compares (empty: not written).
    pub render_fingerprint: String,
    /// `throng/denoiser`: what denoised the beauty and passes (empty: not
    /// denoised; render::denoise::stamp).
    pub denoiser: String,
    /// `throng/shutter` (v2f): shutter open and close in frames relative to
    /// the frame; not written for a render without motion blur.
    pub shutter: Option<[f32; 2]>,
    /// The working colourspace of the beauty and albedo channels
    /// (`chromaticities`, `throng/colorspace`).
    pub colourspace: Colourspace,
}

/// Names of the motion-vector channels: Nuke's `forward` layer (VectorBlur's
/// `uv` input, `motion` = forward + backward), as OpenImageIO lists them.
pub(crate) const MOTION_CHANNELS: [&str; 2] = ["forward.u", "forward.v"];

/// What the motion-vector channels mean, written to `throng/motionConvention`.
pub(crate) const MOTION_CONVENTION: &str =
    "forward.u/v = screen motion of the surface at the sample nearest the pixel centre, pixels per frame, +u right, +v up (Nuke), from shutter open to close";

/// Rec.709 primaries and D65 white, as OpenEXR's `chromaticities` attribute.
pub(crate) fn rec709_chromaticities() -> exr::meta::attribute::Chromaticities {
    chromaticities(Colourspace::Rec709)
}

/// The primaries and white of `space` as OpenEXR's `chromaticities` attribute.
pub(crate) fn chromaticities(space: Colourspace) -> exr::meta::attribute::Chromaticities {
    use exr::math::Vec2;
    let [r, g, b, w] = colour::chromaticities(space).map(|[x, y]| Vec2(x, y));
    exr::meta::attribute::Chromaticities { red: r, green: g, blue: b, white: w }
}

/// `fps` as the rational OpenEXR's `framesPerSecond` wants: 24 -> 24/1,
/// 23.976 -> 24000/1001, 29.97 -> 30000/1001, else thousandths.
pub(crate) fn fps_rational(fps: f32) -> (i32, u32) {
    let f = fps as f64;
    if (f - f.round()).abs() < 1e-4 {
        (f.round() as i32, 1)
    } else if ((f * 1.001) - (f * 1.001).round()).abs() < 1e-3 {
        ((f * 1.001).round() as i32 * 1000, 1001)
    } else {
        ((f * 1000.0).round() as i32, 1000)
    }
}

/// Layer file compression (`--compression`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum LayerCompression {
    /// ZIP in blocks of 16 lines: lossless, the default.
    #[default]
    Zip,
    /// ZIP per line: lossless, faster to read a line at a time.
    Zips,
    /// PIZ (wavelet): lossless, smaller on noisy renders.
    Piz,
    /// B44: lossy on the half channels (beauty, normals, albedo) for previews;
    /// `Z`, `agent.id` and Cryptomatte (float/uint) stay exact.
    B44,
    /// No compression.
    None,
}

impl LayerCompression {
    fn exr(self) -> Compression {
        match self {
            LayerCompression::Zip => Compression::ZIP16,
            LayerCompression::Zips => Compression::ZIP1,
            LayerCompression::Piz => Compression::PIZ,
            LayerCompression::B44 => Compression::B44,
            LayerCompression::None => Compression::Uncompressed,
        }
    }
}

/// The depth terms of a `worldToNDC` for clip planes `near`, `far`: NDC z =
/// `a + b / depth`, 0 at near and 1 at far.
pub(crate) fn ndc_depth_terms(near: f32, far: f32) -> (f32, f32) {
    if far > near {
        (far / (far - near), -far * near / (far - near))
    } else {
        (1.0, 0.0)
    }
}

/// The `worldToCamera` and `worldToNDC` header matrices of `camera` for a
/// `width` x `height` image.
///
/// Derivation: OpenEXR camera space is RenderMan-style, left-handed, +z the
/// view direction, y up; ours (glTF) looks down -z. So
/// `worldToCamera = flip_z * camera_from_world` as a column-vector matrix.
/// Imath multiplies row vectors (p' = p M) and stores M row-major; the
/// row-vector form of a column-vector matrix is its transpose, and the
/// row-major storage of a transpose is the column-major storage of the
/// original: so the attribute is `to_cols_array()` of our matrix, no
/// transposing by hand. NDC (OpenEXR's and RenderMan's definition): after
/// the divide by w (= camera depth), (0, 0) is the top-left corner of the
/// image and (1, 1) the bottom-right (x right, y down), so pixel
/// coordinates are `(x * width, y * height)` with pixel centres at `i + 0.5`;
/// z runs 0..1 from near to far ([`ndc_depth_terms`]).
pub fn camera_matrices(camera: &Camera, width: u32, height: u32, near: f32, far: f32) -> ([f32; 16], [f32; 16]) {
    let camera_from_world = Mat4::from(camera.world_from_camera.inverse());
    let exr_camera_from_world = Mat4::from_scale(Vec3::new(1.0, 1.0, -1.0)) * camera_from_world;
    let tan_half_y = (0.5 * camera.yfov).tan();
    let aspect = width as f32 / height.max(1) as f32;
    let (a, b) = ndc_depth_terms(near, far);
    // x' = 0.5 x / (aspect tan) + 0.5 w, y' = -0.5 y / tan + 0.5 w, w = depth.
    let ndc_from_camera = Mat4::from_cols(
        Vec4::new(0.5 / (aspect * tan_half_y), 0.0, 0.0, 0.0),
        Vec4::new(0.0, -0.5 / tan_half_y, 0.0, 0.0),
        Vec4::new(0.5, 0.5, a, 1.0),
        Vec4::new(0.0, 0.0, b, 0.0),
    );
    (exr_camera_from_world.to_cols_array(), (ndc_from_camera * exr_camera_from_world).to_cols_array())
}

fn half(values: impl Iterator<Item = f32>) -> FlatSamples {
    // Clamp so very bright samples (the sun disc) stay finite in half.
    FlatSamples::F16(values.map(|v| f16::from_f32(v.clamp(-65504.0, 65504.0))).collect())
}

/// Where the Cryptomatte manifests go.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ManifestMode {
    /// In the header (`cryptomatte/<key>/manifest`), the default.
    #[default]
    Header,
    /// In a sidecar JSON beside the EXR, named by `cryptomatte/<key>/manif_file`:
    /// `<exr file stem>.<type name>.json`.
    Sidecar,
}

/// Output options of [`write_layer_with`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct WriteOptions {
    /// Where Cryptomatte manifests go.
    pub manifest: ManifestMode,
    /// Compression (lossless ZIP by default).
    pub compression: LayerCompression,
}

/// The sidecar manifest file name of Cryptomatte type `type_name` for the EXR `exr_path`.
pub(crate) fn sidecar_name(exr_path: &Path, type_name: &str) -> String {
    let stem = exr_path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    format!("{stem}.{type_name}.json")
}

/// Text as UTF-8 bytes. OpenEXR text attributes and channel names are byte
/// strings; Cryptomatte and OpenEXR's own tools read them as UTF-8, so a
/// Unicode shot or agent name round-trips (the exr crate's `Text::from`
/// would panic on it, and `new_or_none` keeps Latin-1 only). Read back with
/// `lossy`.
pub(crate) fn text(s: &str) -> Text {
    Text::from_slice_unchecked(s.as_bytes())
}

/// Writes `film` atomically to `path` (temporary name, then rename), with
/// Cryptomatte manifests in the header.
pub fn write_layer(path: &Path, film: &Film, meta: &LayerMeta) -> Result<()> {
    write_layer_with(path, film, meta, &WriteOptions::default())
}

/// The film's channels, sorted by name as EXR stores them; an error for a
/// channel whose size is not the film's.
fn film_channels(path: &Path, film: &Film) -> Result<AnyChannels<FlatSamples>> {
    let (w, h) = (film.width as usize, film.height as usize);
    let rgba = |c: usize| half(film.rgba.iter().map(move |p| p[c]));
    let vec3 = |v: &[[f32; 3]], c: usize| half(v.iter().map(|p| p[c]));
    let mut list = vec![
        AnyChannel::new("R", rgba(0)),
        AnyChannel::new("G", rgba(1)),
        AnyChannel::new("B", rgba(2)),
        AnyChannel::new("A", rgba(3)),
        AnyChannel::new("Z", FlatSamples::F32(film.z.clone())),
        AnyChannel::new("N.X", vec3(&film.normal, 0)),
        AnyChannel::new("N.Y", vec3(&film.normal, 1)),
        AnyChannel::new("N.Z", vec3(&film.normal, 2)),
        AnyChannel::new("albedo.R", vec3(&film.albedo, 0)),
        AnyChannel::new("albedo.G", vec3(&film.albedo, 1)),
        AnyChannel::new("albedo.B", vec3(&film.albedo, 2)),
        AnyChannel::new("agent.id", FlatSamples::U32(film.agent_id.clone())),
    ];
    if !film.samples.is_empty() {
        if film.samples.len() != w * h {
            return Err(Error::invalid(path, "the samples channel does not match the film size"));
        }
        list.push(AnyChannel::new(SAMPLES_CHANNEL, FlatSamples::U32(film.samples.clone())));
    }
    if !film.motion.is_empty() {
        if film.motion.len() != w * h {
            return Err(Error::invalid(path, "motion vectors do not match the film size"));
        }
        for (c, name) in MOTION_CHANNELS.iter().enumerate() {
            list.push(AnyChannel::new(*name, FlatSamples::F32(film.motion.iter().map(|m| m[c]).collect())));
        }
    }
    for m in &film.cryptomatte {
        if m.width != film.width || m.height != film.height || m.pairs.len() != w * h * m.ranks {
            return Err(Error::invalid(path, format!("cryptomatte `{}` does not match the film size", m.name)));
        }
        // Level l holds ranks 2l (R id, G coverage) and 2l+1 (B id, A coverage).
        for level in 0..m.ranks.div_ceil(2) {
            for (c, rank, part) in [('R', 0, 0), ('G', 0, 1), ('B', 1, 0), ('A', 1, 1)] {
                let r = 2 * level + rank;
                let values: Vec<f32> = if r < m.ranks {
                    m.pairs.chunks_exact(m.ranks).map(|px| px[r][part]).collect()
                } else {
                    vec![0.0; w * h]
                };
                list.push(AnyChannel::new(text(&format!("{}{level:02}.{c}", m.name)), FlatSamples::F32(values)));
            }
        }
    }
    for pass in &film.passes {
        if pass.data.len() != w * h {
            return Err(Error::invalid(path, format!("pass `{}` does not match the film size", pass.name)));
        }
        for (c, suffix) in pass.channels.iter().enumerate() {
            let values = pass.data.iter().map(move |p| p[c]);
            let samples = if pass_is_float(&pass.name) { FlatSamples::F32(values.collect()) } else { half(values) };
            list.push(AnyChannel::new(text(&format!("{}.{suffix}", pass.name)), samples));
        }
    }
    Ok(AnyChannels::sort(SmallVec::from_vec(list)))
}

/// The layer's header attributes: the standard ones, throng's own and those
/// of each Cryptomatte of `film` whose type name passes `matte` (whose
/// manifest `options` may write to a sidecar file). The deep file
/// ([`deep`]) writes the same.
fn layer_attributes(
    path: &Path,
    film: &Film,
    matte: &dyn Fn(&str) -> bool,
    meta: &LayerMeta,
    options: &WriteOptions,
) -> Result<LayerAttributes> {
    let mut attrs = LayerAttributes::named(text(&meta.layer));
    attrs.software_name = Some(text(&format!("throng {}", env!("CARGO_PKG_VERSION"))));
    attrs.near_clip_plane = Some(meta.near);
    attrs.far_clip_plane = Some(meta.far);
    attrs.world_to_camera = Some(meta.world_to_camera);
    attrs.world_to_normalized_device = Some(meta.world_to_ndc);
    let mut put = |k: &str, v: AttributeValue| -> Result<()> {
        attrs.other.insert(text(k), v);
        Ok(())
    };
    put("throng/shot", AttributeValue::Text(text(&meta.shot)))?;
    put("throng/layer", AttributeValue::Text(text(&meta.layer)))?;
    put("throng/frame", AttributeValue::I32(meta.frame))?;
    put("throng/seed", AttributeValue::Text(text(&meta.seed.to_string())))?;
    put("throng/spp", AttributeValue::I32(meta.spp.min(i32::MAX as u32) as i32))?;
    put("throng/zConvention", AttributeValue::Text(text("cameraDepth")))?;
    put("throng/idMapping", AttributeValue::Text(text(&meta.id_mapping)))?;
    put("throng/colorspace", AttributeValue::Text(text(colour::header_name(meta.colourspace))))?;
    if !meta.render_fingerprint.is_empty() {
        put("throng/renderFingerprint", AttributeValue::Text(text(&meta.render_fingerprint)))?;
    }
    if !meta.denoiser.is_empty() {
        put("throng/denoiser", AttributeValue::Text(text(&meta.denoiser)))?;
    }
    if let Some([open, close]) = meta.shutter {
        put("throng/shutter", AttributeValue::FloatVec2(exr::math::Vec2(open, close)))?;
        put("throng/motionConvention", AttributeValue::Text(text(MOTION_CONVENTION)))?;
    }
    if meta.fps > 0.0 && meta.fps.is_finite() {
        attrs.frames_per_second = Some(fps_rational(meta.fps));
    }
    for m in film.cryptomatte.iter().filter(|m| matte(&m.name)) {
        let key = m.key();
        let mut put_utf8 = |field: &str, v: &str| {
            attrs.other.insert(text(&format!("cryptomatte/{key}/{field}")), AttributeValue::Text(text(v)));
        };
        put_utf8("name", &m.name);
        put_utf8("hash", cryptomatte::HASH);
        put_utf8("conversion", cryptomatte::CONVERSION);
        match options.manifest {
            ManifestMode::Header => put_utf8("manifest", &m.manifest_json()),
            ManifestMode::Sidecar => {
                let name = sidecar_name(path, &m.name);
                let side = path.parent().unwrap_or(Path::new("")).join(&name);
                let json = m.manifest_json();
                write_atomic(&side, |out| {
                    use std::io::Write;
                    out.write_all(json.as_bytes()).map_err(|e| Error::io(&side, e))
                })?;
                put_utf8("manif_file", &name);
            }
        }
    }
    Ok(attrs)
}

/// As [`write_layer`], with options. Sidecar manifests are written (atomically)
/// before the EXR, so an EXR that exists has its sidecars.
pub fn write_layer_with(path: &Path, film: &Film, meta: &LayerMeta, options: &WriteOptions) -> Result<()> {
    let (w, h) = (film.width as usize, film.height as usize);
    let channels = film_channels(path, film)?;
    let attrs = layer_attributes(path, film, &|_| true, meta, options)?;

    let encoding = Encoding {
        compression: options.compression.exr(),
        blocks: Blocks::ScanLines,
        line_order: LineOrder::Increasing,
    };
    let mut image = Image::from_layer(Layer::new((w, h), attrs, encoding, channels));
    image.attributes.chromaticities = Some(chromaticities(meta.colourspace));
    write_atomic(path, |out| {
        use std::io::{Seek, SeekFrom, Write};
        // Streamed to the file, so a render never holds the encoded frame
        // in memory (its size depends on the image; the memory model,
        // `layers::memory`, counts the film); the headers are kept as they
        // pass, sorted, and written back over themselves.
        let mut w = HeaderCapture { out: &mut *out, pos: 0, head: Vec::new(), end: None };
        image.write().to_buffered(&mut w).map_err(|e| exr_error(path, e))?;
        let mut head = std::mem::take(&mut w.head);
        if w.end.is_some() && sort_header_attributes(&mut head) {
            out.seek(SeekFrom::Start(0)).map_err(|e| Error::io(path, e))?;
            out.write_all(&head).map_err(|e| Error::io(path, e))?;
            out.seek(SeekFrom::End(0)).map_err(|e| Error::io(path, e))?;
        }
        Ok(())
    })
}

/// A writer that passes everything on and keeps a copy of the file's
/// headers (the bytes before [`headers_end`]) as they are written.
struct HeaderCapture<'a, W> {
    out: &'a mut W,
    pos: u64,
    head: Vec<u8>,
    /// Where the headers end, once they have all been written.
    end: Option<usize>,
}

impl<W: std::io::Write> std::io::Write for HeaderCapture<'_, W> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let n = self.out.write(buf)?;
        let (at, limit) = (self.pos as usize, self.end.unwrap_or(usize::MAX));
        if at < limit {
            let upto = (at + n).min(limit);
            if self.head.len() < upto {
                self.head.resize(upto, 0);
            }
            self.head[at..upto].copy_from_slice(&buf[..upto - at]);
            if self.end.is_none() {
                self.end = headers_end(&self.head);
                if let Some(e) = self.end {
                    self.head.truncate(e);
                }
            }
        }
        self.pos += n as u64;
        Ok(n)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.out.flush()
    }
}

impl<W: std::io::Seek> std::io::Seek for HeaderCapture<'_, W> {
    fn seek(&mut self, to: std::io::SeekFrom) -> std::io::Result<u64> {
        self.pos = self.out.seek(to)?;
        Ok(self.pos)
    }
}

/// Where an OpenEXR file's headers end (after the terminating null of the
/// last header), or `None` while `bytes` does not hold them all.
fn headers_end(bytes: &[u8]) -> Option<usize> {
    let nul_from = |at: usize| bytes.get(at..)?.iter().position(|&c| c == 0).map(|p| at + p);
    let version = bytes.get(4..8)?;
    let multipart = u32::from_le_bytes([version[0], version[1], version[2], version[3]]) & 0x1000 != 0;
    let mut pos = 8;
    loop {
        loop {
            let name_end = nul_from(pos)?;
            if name_end == pos {
                pos += 1;
                break;
            }
            let type_end = nul_from(name_end + 1)?;
            let size = bytes.get(type_end + 1..type_end + 5)?;
            let size = usize::try_from(i32::from_le_bytes([size[0], size[1], size[2], size[3]])).ok()?;
            pos = type_end + 5 + size;
            if pos > bytes.len() {
                return None;
            }
        }
        if !multipart {
            return Some(pos);
        }
        // Multi-part: an empty header (a lone null) ends the list.
        if *bytes.get(pos)? == 0 {
            return Some(pos + 1);
        }
    }
}

/// The exr crate keeps custom attributes in a `HashMap`, so their order in
/// the header changes from run to run. Sorting each header's attributes by
/// name in place keeps the same bytes and length (chunk offsets stay valid)
/// and makes the same render give the same file. Leaves anything it cannot
/// parse untouched. Returns whether every header was sorted.
pub(crate) fn sort_header_attributes(bytes: &mut [u8]) -> bool {
    let nul_from = |b: &[u8], at: usize| b.get(at..)?.iter().position(|&c| c == 0).map(|p| at + p);
    let Some(version) = bytes.get(4..8) else { return false };
    let multipart = u32::from_le_bytes([version[0], version[1], version[2], version[3]]) & 0x1000 != 0;
    let mut pos = 8;
    loop {
        let start = pos;
        let mut attrs: Vec<std::ops::Range<usize>> = Vec::new();
        loop {
            let Some(name_end) = nul_from(bytes, pos) else { return false };
            if name_end == pos {
                pos += 1; // the header's terminating null
                break;
            }
            let Some(type_end) = nul_from(bytes, name_end + 1) else { return false };
            let Some(size) = bytes.get(type_end + 1..type_end + 5) else { return false };
            let size = i32::from_le_bytes([size[0], size[1], size[2], size[3]]);
            let Ok(size) = usize::try_from(size) else { return false };
            let end = type_end + 5 + size;
            if end > bytes.len() {
                return false;
            }
            attrs.push(pos..end);
            pos = end;
        }
        let name = |r: &std::ops::Range<usize>| {
            let b: &[u8] = bytes;
            b[r.start..nul_from(b, r.start).unwrap_or(r.start)].to_vec()
        };
        let mut sorted = attrs.clone();
        sorted.sort_by_key(name);
        let reordered: Vec<u8> = sorted.iter().flat_map(|r| bytes[r.clone()].to_vec()).collect();
        bytes[start..start + reordered.len()].copy_from_slice(&reordered);
        if !multipart || bytes.get(pos) == Some(&0) {
            return true;
        }
    }
}

/// Whether a pass is written as float: position needs a float's precision;
/// light is half, like the beauty.
fn pass_is_float(name: &str) -> bool {
    name == crate::scene::passes::POSITION
}

/// Each pass of `film` with the bytes its channels hold in a layer file
/// before compression (half or float samples, every pixel).
pub fn pass_bytes(film: &Film) -> Vec<(String, u64)> {
    let pixels = film.width as u64 * film.height as u64;
    film.passes
        .iter()
        .map(|p| (p.name.clone(), pixels * p.channels.len() as u64 * if pass_is_float(&p.name) { 4 } else { 2 }))
        .collect()
}

/// The passes among a file's channel `names` (light paths, `lg_*`,
/// `shadow`, the air's transmittance, `P`), in file order, each with its channel suffixes.
pub(crate) fn pass_layout(names: &[String]) -> Vec<(String, [&'static str; 3])> {
    use crate::scene::passes::{file_order, LightPath, NOISY, SHADOW, TRANSMITTANCE};
    let mut passes: Vec<(String, [&'static str; 3])> = Vec::new();
    for name in names {
        let Some(layer) = name.strip_suffix(".R") else { continue };
        if LightPath::ALL.iter().any(|p| p.name() == layer)
            || layer.starts_with("lg_")
            || layer == SHADOW
            || layer == TRANSMITTANCE
            || layer == NOISY
        {
            passes.push((layer.to_string(), ["R", "G", "B"]));
        }
    }
    // File order: light paths as listed, then light groups, the shadow pass, then P.
    passes.sort_by(|a, b| file_order(&a.0).cmp(&file_order(&b.0)));
    if names.iter().any(|n| n == "P.X") {
        passes.push(("P".into(), ["X", "Y", "Z"]));
    }
    passes
}

/// The passes among a file's `channels` (`noisy`, light paths, `lg_*`, `shadow`, `P`), in file
/// order, read with `floats`.
fn read_passes(
    channels: impl Iterator<Item = String>,
    floats: &dyn Fn(&str) -> Result<Vec<f32>>,
) -> Result<Vec<super::film::Pass>> {
    let names: Vec<String> = channels.collect();
    pass_layout(&names)
        .into_iter()
        .map(|(name, channels)| {
            let [a, b, c] = channels.map(|s| floats(&format!("{name}.{s}")));
            let (a, b, c) = (a?, b?, c?);
            let data = a.iter().zip(&b).zip(&c).map(|((&a, &b), &c)| [a, b, c]).collect();
            Ok(super::film::Pass { name, channels, data })
        })
        .collect()
}

/// The `throng/renderFingerprint` of a layer file, from its header only
/// (empty when the file records none).
pub fn read_render_fingerprint(path: &Path) -> Result<String> {
    let meta = exr::meta::MetaData::read_from_file(path, false).map_err(|e| crate::exr_guard::exr_error(path, e))?;
    let key = Text::new_or_none("throng/renderFingerprint");
    let found = meta.headers.iter().find_map(|h| {
        match key.as_ref().and_then(|k| h.own_attributes.other.get(k).or_else(|| h.shared_attributes.other.get(k))) {
            Some(AttributeValue::Text(t)) => Some(lossy(t)),
            _ => None,
        }
    });
    Ok(found.unwrap_or_default())
}

/// Reads a file written by [`write_layer`] back (tests, resume, botinfo).
pub fn read_layer(path: &Path) -> Result<(Film, LayerMeta)> {
    crate::exr_guard::check_decoded_size(path)?;
    let image = exr::prelude::read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .first_valid_layer()
        .all_attributes()
        .from_file(path)
        .map_err(|e| exr_error(path, e))?;
    let layer = &image.layer_data;
    let (w, h) = (layer.size.width(), layer.size.height());
    let n = w * h;
    let find = |name: &str| {
        layer
            .channel_data
            .list
            .iter()
            .find(|c| lossy(&c.name) == name)
            .ok_or_else(|| Error::invalid(path, format!("channel `{name}` is missing")).field(name.to_string()))
    };
    let floats = |name: &str| -> Result<Vec<f32>> {
        let c = find(name)?;
        let v: Vec<f32> = c.sample_data.values_as_f32().collect();
        if v.len() != n {
            return Err(Error::invalid(path, format!("channel `{name}` has {} samples, expected {n}", v.len())));
        }
        Ok(v)
    };
    let [r, g, b, a] = ["R", "G", "B", "A"].map(&floats);
    let (r, g, b, a) = (r?, g?, b?, a?);
    let [nx, ny, nz] = ["N.X", "N.Y", "N.Z"].map(&floats);
    let (nx, ny, nz) = (nx?, ny?, nz?);
    let [ar, ag, ab] = ["albedo.R", "albedo.G", "albedo.B"].map(&floats);
    let (ar, ag, ab) = (ar?, ag?, ab?);
    let z = floats("Z")?;
    let agent_id = match &find("agent.id")?.sample_data {
        FlatSamples::U32(v) if v.len() == n => v.clone(),
        _ => return Err(Error::invalid(path, "channel `agent.id` is not uint").field("agent.id")),
    };
    let film = Film {
        width: w as u32,
        height: h as u32,
        rgba: (0..n).map(|i| [r[i], g[i], b[i], a[i]]).collect(),
        z,
        normal: (0..n).map(|i| [nx[i], ny[i], nz[i]]).collect(),
        albedo: (0..n).map(|i| [ar[i], ag[i], ab[i]]).collect(),
        agent_id,
        cryptomatte: mattes::decode_part(&raw_part(layer, &image.attributes, |n| n.starts_with("Crypto")), path)?,
        motion: match (floats(MOTION_CHANNELS[0]), floats(MOTION_CHANNELS[1])) {
            (Ok(u), Ok(v)) => u.iter().zip(&v).map(|(&u, &v)| [u, v]).collect(),
            _ => Vec::new(),
        },
        passes: read_passes(layer.channel_data.list.iter().map(|c| lossy(&c.name)), &floats)?,
        samples: match find(SAMPLES_CHANNEL).ok().map(|c| &c.sample_data) {
            None => Vec::new(),
            Some(FlatSamples::U32(v)) if v.len() == n => v.clone(),
            Some(_) => {
                return Err(
                    Error::invalid(path, format!("channel `{SAMPLES_CHANNEL}` is not uint")).field(SAMPLES_CHANNEL)
                )
            }
        },
    };

    let meta = layer_meta(path, &layer.attributes, &image.attributes)?;
    Ok((film, meta))
}

/// A layer file's header as [`LayerMeta`]: the part's own attributes, then
/// the file's shared ones.
fn layer_meta(path: &Path, attrs: &LayerAttributes, shared: &exr::meta::header::ImageAttributes) -> Result<LayerMeta> {
    let other = |k: &str| attrs.other.get(&Text::new_or_none(k)?).or_else(|| shared.other.get(&Text::new_or_none(k)?));
    let get_text = |k: &str| match other(k) {
        Some(AttributeValue::Text(t)) => Ok(lossy(t)),
        _ => Err(Error::invalid(path, format!("header attribute `{k}` is missing or not text")).field(k.to_string())),
    };
    let get_i32 = |k: &str| match other(k) {
        Some(AttributeValue::I32(v)) => Ok(*v),
        _ => Err(Error::invalid(path, format!("header attribute `{k}` is missing or not int")).field(k.to_string())),
    };
    let seed_text = get_text("throng/seed")?;
    Ok(LayerMeta {
        shot: get_text("throng/shot")?,
        layer: get_text("throng/layer")?,
        frame: get_i32("throng/frame")?,
        seed: seed_text.parse().map_err(|_| {
            Error::invalid(path, format!("throng/seed `{seed_text}` is not a number")).field("throng/seed")
        })?,
        spp: get_i32("throng/spp")?.max(0) as u32,
        id_mapping: get_text("throng/idMapping")?,
        world_to_camera: attrs.world_to_camera.unwrap_or_default(),
        world_to_ndc: attrs.world_to_normalized_device.unwrap_or_default(),
        near: attrs.near_clip_plane.unwrap_or(0.0),
        far: attrs.far_clip_plane.unwrap_or(0.0),
        fps: attrs.frames_per_second.map_or(0.0, |(n, d)| n as f32 / d.max(1) as f32),
        render_fingerprint: get_text("throng/renderFingerprint").unwrap_or_default(),
        denoiser: get_text("throng/denoiser").unwrap_or_default(),
        shutter: match other("throng/shutter") {
            Some(AttributeValue::FloatVec2(v)) => Some([v.0, v.1]),
            _ => None,
        },
        // Files from before the option, and others' files, are Rec.709.
        colourspace: match get_text("throng/colorspace") {
            Ok(name) => colour::from_header_name(&name).ok_or_else(|| {
                Error::invalid(path, format!("throng/colorspace `{name}` is neither lin_rec709 nor ACEScg"))
                    .field("throng/colorspace")
            })?,
            Err(_) => Colourspace::Rec709,
        },
    })
}

/// Reads only the channels of a layer file that `keep` accepts, block by
/// block, so no other channel is ever held: what `throng review` decodes
/// for one request (docs/review.md, "Memory bound"). Film fields whose
/// channels are not kept are left empty; a kept channel [`read_layer`]
/// requires is required here too. The first part, largest level.
pub(crate) fn read_layer_channels(path: &Path, keep: &dyn Fn(&str) -> bool) -> Result<(Film, LayerMeta)> {
    let (header, mut channels) = read_kept_channels(path, keep)?;
    let (w, h) = (header.layer_size.width(), header.layer_size.height());
    let n = w * h;
    let mut take = |name: &str| -> Result<Option<Vec<f32>>> {
        if !keep(name) {
            return Ok(None);
        }
        match channels.remove(name) {
            Some(Samples::F32(v)) => Ok(Some(v)),
            Some(Samples::U32(_)) => {
                Err(Error::invalid(path, format!("channel `{name}` is uint")).field(name.to_string()))
            }
            None => Err(Error::invalid(path, format!("channel `{name}` is missing")).field(name.to_string())),
        }
    };
    let rgba = match (take("R")?, take("G")?, take("B")?, take("A")?) {
        (Some(r), Some(g), Some(b), Some(a)) => (0..n).map(|i| [r[i], g[i], b[i], a[i]]).collect(),
        _ => Vec::new(),
    };
    let mut three = |names: [&str; 3]| -> Result<Vec<[f32; 3]>> {
        Ok(match (take(names[0])?, take(names[1])?, take(names[2])?) {
            (Some(a), Some(b), Some(c)) => (0..n).map(|i| [a[i], b[i], c[i]]).collect(),
            _ => Vec::new(),
        })
    };
    let normal = three(["N.X", "N.Y", "N.Z"])?;
    let albedo = three(["albedo.R", "albedo.G", "albedo.B"])?;
    let z = take("Z")?.unwrap_or_default();
    let agent_id = match (keep("agent.id"), channels.remove("agent.id")) {
        (false, _) => Vec::new(),
        (true, Some(Samples::U32(v))) => v,
        (true, Some(_)) => return Err(Error::invalid(path, "channel `agent.id` is not uint").field("agent.id")),
        (true, None) => return Err(Error::invalid(path, "channel `agent.id` is missing").field("agent.id")),
    };
    let floats = |name: &str| match channels.get(name) {
        Some(Samples::F32(v)) => Ok(v.clone()),
        _ => Err(Error::invalid(path, format!("channel `{name}` is missing")).field(name.to_string())),
    };
    let motion = match (floats(MOTION_CHANNELS[0]), floats(MOTION_CHANNELS[1])) {
        (Ok(u), Ok(v)) => u.iter().zip(&v).map(|(&u, &v)| [u, v]).collect(),
        _ => Vec::new(),
    };
    let passes = read_passes(channels.keys().cloned().collect::<Vec<_>>().into_iter(), &floats)?;
    let samples = match channels.remove(SAMPLES_CHANNEL) {
        Some(Samples::U32(v)) => v,
        Some(_) => {
            return Err(Error::invalid(path, format!("channel `{SAMPLES_CHANNEL}` is not uint")).field(SAMPLES_CHANNEL))
        }
        None => Vec::new(),
    };
    let mut attributes = text_attributes(&header.shared_attributes.other, &header.own_attributes.other);
    // The matte types whose rank channels were not asked for are not read.
    let unread: Vec<String> = (attributes.iter())
        .filter_map(|(k, v)| {
            let key = k.strip_prefix("exr/").unwrap_or(k).strip_prefix("cryptomatte/")?.strip_suffix("/name")?;
            (!keep(&format!("{v}00.R"))).then(|| format!("cryptomatte/{key}/"))
        })
        .collect();
    attributes.retain(|k, _| !unread.iter().any(|u| k.strip_prefix("exr/").unwrap_or(k).starts_with(u.as_str())));
    let crypto = RawPart {
        width: w as u32,
        height: h as u32,
        attributes,
        channels: (channels.into_iter())
            .filter(|(k, _)| k.starts_with("Crypto"))
            .filter_map(|(k, v)| match v {
                Samples::F32(v) => Some((k, v)),
                Samples::U32(_) => None,
            })
            .collect(),
    };
    let cryptomatte = mattes::decode_part(&crypto, path)?;
    let film = Film {
        width: w as u32,
        height: h as u32,
        rgba,
        z,
        normal,
        albedo,
        agent_id,
        cryptomatte,
        motion,
        passes,
        samples,
    };
    Ok((film, layer_meta(path, &header.own_attributes, &header.shared_attributes)?))
}

/// The channels of a file's first part (largest level) that `keep`
/// accepts, read block by block, with the part's header.
fn read_kept_channels(
    path: &Path,
    keep: &dyn Fn(&str) -> bool,
) -> Result<(exr::meta::header::Header, BTreeMap<String, Samples>)> {
    use exr::block::reader::ChunksReader;
    use exr::prelude::SampleType;
    crate::exr_guard::check_decoded_size(path)?;
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let reader = exr::block::read(std::io::BufReader::new(file), false).map_err(|e| exr_error(path, e))?;
    let Some(header) = reader.headers().first().cloned() else {
        return Err(Error::invalid(path, "EXR has no parts"));
    };
    let (w, h) = (header.layer_size.width(), header.layer_size.height());
    let n = w * h;
    // One buffer per kept channel, by the channel's index in the header.
    let mut kept: Vec<Option<(String, Samples)>> = (header.channels.list.iter())
        .map(|c| {
            let name = lossy(&c.name);
            keep(&name).then(|| {
                let v = match c.sample_type {
                    SampleType::U32 => Samples::U32(vec![0; n]),
                    _ => Samples::F32(vec![0.0; n]),
                };
                (name, v)
            })
        })
        .collect();
    let chunks = reader
        .filter_chunks(false, |_, _, b| b.layer == 0 && b.level == exr::math::Vec2(0, 0))
        .map_err(|e| exr_error(path, e))?;
    let mut line_error = None;
    chunks
        .decompress_sequential(false, |_, block| {
            for line in block.lines(&header.channels) {
                let Some((_, out)) = kept.get_mut(line.location.channel).and_then(Option::as_mut) else { continue };
                let (x, y, count) =
                    (line.location.position.x(), line.location.position.y(), line.location.sample_count);
                let at = y * w + x;
                if x + count > w || at + count > n {
                    line_error = Some(format!("a line of channel {} lies outside the image", line.location.channel));
                    continue;
                }
                let sample_type = header.channels.list[line.location.channel].sample_type;
                match (out, sample_type) {
                    (Samples::U32(v), _) => line.read_samples_into_slice(&mut v[at..at + count])?,
                    (Samples::F32(v), SampleType::F32) => line.read_samples_into_slice(&mut v[at..at + count])?,
                    (Samples::F32(v), _) => {
                        for (o, s) in v[at..at + count].iter_mut().zip(line.read_samples::<f16>()) {
                            *o = s?.to_f32();
                        }
                    }
                }
            }
            Ok(())
        })
        .map_err(|e| exr_error(path, e))?;
    if let Some(msg) = line_error {
        return Err(Error::invalid(path, msg));
    }
    Ok((header, kept.into_iter().flatten().collect()))
}

/// One channel's samples as read: half and float as f32, uint as u32.
enum Samples {
    F32(Vec<f32>),
    U32(Vec<u32>),
}

/// The text attributes of a part: the file's shared ones, then its own.
fn text_attributes<'a>(
    shared: impl IntoIterator<Item = (&'a Text, &'a AttributeValue)>,
    own: impl IntoIterator<Item = (&'a Text, &'a AttributeValue)>,
) -> BTreeMap<String, String> {
    let mut attributes = BTreeMap::new();
    for (k, v) in shared.into_iter().chain(own) {
        if let AttributeValue::Text(t) = v {
            attributes.insert(lossy(k), lossy(t));
        }
    }
    attributes
}

/// The size and channel names of an EXR's first part, from its header
/// alone (no pixels decoded): what `throng review` lists before it decodes.
pub(crate) fn read_channel_names(path: &Path) -> Result<(u32, u32, Vec<String>)> {
    let meta = exr::meta::MetaData::read_from_file(path, false).map_err(|e| exr_error(path, e))?;
    let Some(header) = meta.headers.first() else {
        return Err(Error::invalid(path, "EXR has no parts"));
    };
    let names = header.channels.list.iter().map(|c| lossy(&c.name)).collect();
    Ok((header.layer_size.width() as u32, header.layer_size.height() as u32, names))
}

/// One part (layer) of an EXR as plain data: what the Cryptomatte decoder needs.
#[derive(Clone, Debug, Default)]
pub struct RawPart {
    /// Width in pixels.
    pub(crate) width: u32,
    /// Height in pixels.
    pub(crate) height: u32,
    /// Text header attributes (shared and the part's own), UTF-8 decoded.
    pub attributes: BTreeMap<String, String>,
    /// Channels as f32, row-major, by full channel name.
    pub channels: BTreeMap<String, Vec<f32>>,
}

fn lossy(t: &Text) -> String {
    String::from_utf8_lossy(t.bytes()).into_owned()
}

fn raw_part(
    layer: &Layer<AnyChannels<FlatSamples>>,
    shared: &exr::meta::header::ImageAttributes,
    keep: impl Fn(&str) -> bool,
) -> RawPart {
    let attributes = text_attributes(&shared.other, &layer.attributes.other);
    let channels = layer
        .channel_data
        .list
        .iter()
        .map(|c| (lossy(&c.name), c))
        .filter(|(n, _)| keep(n))
        .map(|(n, c)| (n, c.sample_data.values_as_f32().collect()))
        .collect();
    RawPart { width: layer.size.width() as u32, height: layer.size.height() as u32, attributes, channels }
}

/// Reads every part of any scanline or tiled EXR (largest resolution level,
/// no deep data), keeping the channels whose full name passes `keep`.
pub fn read_parts(path: &Path, keep: impl Fn(&str) -> bool) -> Result<Vec<RawPart>> {
    crate::exr_guard::check_decoded_size(path)?;
    let image = exr::prelude::read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .all_layers()
        .all_attributes()
        .from_file(path)
        .map_err(|e| exr_error(path, e))?;
    Ok(image.layer_data.iter().map(|l| raw_part(l, &image.attributes, &keep)).collect())
}

/// sRGB transfer function (IEC 61966-2-1) as an 8-bit code: exactly
/// the formula (`srgb_formula`), looked up (a review image or preview encodes millions
/// of values, and `powf` was most of a light-mixer change).
pub(crate) fn srgb_encode(linear: f32) -> u8 {
    // NaN, -0.0 (whose bits sort above every step) and below: black.
    if !(linear > 0.0) {
        return 0;
    }
    let c = linear.min(1.0);
    // Positive floats order as their bit patterns do.
    SRGB_STEPS.partition_point(|&step| step <= c.to_bits()) as u8
}

/// The formula [`srgb_encode`] looks up.
#[cfg(test)]
fn srgb_formula(c: f32) -> u8 {
    let v = if c <= 0.003_130_8 { 12.92 * c } else { 1.055 * c.powf(1.0 / 2.4) - 0.055 };
    (v * 255.0 + 0.5) as u8
}

/// `SRGB_STEPS[k]`: the bits of the least value in [0, 1] that
/// `srgb_formula` gives a code over k (found by bisecting the bit
/// patterns; the formula never steps down, checked over every f32 in
/// [0, 1]; the test checks each step against the formula).
const SRGB_STEPS: [u32; 255] = [
    0x391f22b3, 0x39eeb40e, 0x3a46eb61, 0x3a8b3e5d, 0x3ab3070b, 0x3adacfb7, 0x3b014c32, 0x3b153089, 0x3b2914df,
    0x3b3cf936, 0x3b50f2d1, 0x3b65fb9a, 0x3b7c3404, 0x3b89d060, 0x3b962333, 0x3ba314be, 0x3bb0a731, 0x3bbedcb6,
    0x3bcdb76c, 0x3bdd3966, 0x3bed64ae, 0x3bfe3b44, 0x3c07df90, 0x3c10f919, 0x3c1a6b32, 0x3c2436c7, 0x3c2e5cc7,
    0x3c38de19, 0x3c43bba3, 0x3c4ef646, 0x3c5a8ee2, 0x3c668654, 0x3c72dd73, 0x3c7f9512, 0x3c865703, 0x3c8d1490,
    0x3c940396, 0x3c9b247c, 0x3ca277a8, 0x3ca9fd79, 0x3cb1b654, 0x3cb9a299, 0x3cc1c2a9, 0x3cca16e3, 0x3cd29fa4,
    0x3cdb5d4d, 0x3ce45034, 0x3ced78b6, 0x3cf6d72f, 0x3d0035fc, 0x3d051bb6, 0x3d0a1cee, 0x3d0f39d1, 0x3d14728a,
    0x3d19c745, 0x3d1f382b, 0x3d24c56a, 0x3d2a6f24, 0x3d303586, 0x3d3618b9, 0x3d3c18e6, 0x3d423634, 0x3d4870cb,
    0x3d4ec8d3, 0x3d553e74, 0x3d5bd1d3, 0x3d628319, 0x3d69526a, 0x3d703fee, 0x3d774bce, 0x3d7e7627, 0x3d82df92,
    0x3d869374, 0x3d8a56cc, 0x3d8e29ad, 0x3d920c28, 0x3d95fe50, 0x3d9a0036, 0x3d9e11ec, 0x3da23384, 0x3da66510,
    0x3daaa6a0, 0x3daef847, 0x3db35a17, 0x3db7cc1d, 0x3dbc4e6c, 0x3dc0e116, 0x3dc5842a, 0x3dca37ba, 0x3dcefbd7,
    0x3dd3d090, 0x3dd8b5f6, 0x3dddac19, 0x3de2b30a, 0x3de7cad9, 0x3decf395, 0x3df22d4f, 0x3df7781a, 0x3dfcd3fe,
    0x3e012088, 0x3e03dfaf, 0x3e06a77c, 0x3e0977f7, 0x3e0c5127, 0x3e0f3314, 0x3e121dc6, 0x3e151144, 0x3e180d95,
    0x3e1b12c2, 0x3e1e20d1, 0x3e2137cb, 0x3e2457b7, 0x3e27809a, 0x3e2ab27c, 0x3e2ded67, 0x3e313160, 0x3e347e6f,
    0x3e37d49d, 0x3e3b33ed, 0x3e3e9c68, 0x3e420e14, 0x3e4588fa, 0x3e490d21, 0x3e4c9a8f, 0x3e50314b, 0x3e53d15c,
    0x3e577ac9, 0x3e5b2d99, 0x3e5ee9d2, 0x3e62af7c, 0x3e667e9d, 0x3e6a5740, 0x3e6e3963, 0x3e722512, 0x3e761a53,
    0x3e7a192d, 0x3e7e21a6, 0x3e8119e2, 0x3e8327c8, 0x3e853a87, 0x3e875222, 0x3e896e9e, 0x3e8b8ffc, 0x3e8db641,
    0x3e8fe170, 0x3e92118b, 0x3e944696, 0x3e968094, 0x3e98bf89, 0x3e9b0377, 0x3e9d4c61, 0x3e9f9a4b, 0x3ea1ed38,
    0x3ea4452a, 0x3ea6a225, 0x3ea9042d, 0x3eab6b43, 0x3eadd76b, 0x3eb048a9, 0x3eb2bf01, 0x3eb53a72, 0x3eb7bb01,
    0x3eba40b2, 0x3ebccb86, 0x3ebf5b82, 0x3ec1f0a7, 0x3ec48afa, 0x3ec72a7d, 0x3ec9cf32, 0x3ecc791e, 0x3ecf2842,
    0x3ed1dca2, 0x3ed49641, 0x3ed75521, 0x3eda1945, 0x3edce2b1, 0x3edfb167, 0x3ee2856a, 0x3ee55ebc, 0x3ee83d62,
    0x3eeb215c, 0x3eee0aaf, 0x3ef0f95d, 0x3ef3ed69, 0x3ef6e6d6, 0x3ef9e5a6, 0x3efce9e0, 0x3efff37f, 0x3f018145,
    0x3f030b82, 0x3f049878, 0x3f062827, 0x3f07ba92, 0x3f094fba, 0x3f0ae79f, 0x3f0c8244, 0x3f0e1faa, 0x3f0fbfd2,
    0x3f1162be, 0x3f13086e, 0x3f14b0e4, 0x3f165c22, 0x3f180a29, 0x3f19baf9, 0x3f1b6e95, 0x3f1d24fe, 0x3f1ede35,
    0x3f209a3b, 0x3f225912, 0x3f241abb, 0x3f25df37, 0x3f27a688, 0x3f2970ae, 0x3f2b3dac, 0x3f2d0d84, 0x3f2ee033,
    0x3f30b5be, 0x3f328e25, 0x3f346969, 0x3f36478c, 0x3f38288f, 0x3f3a0c73, 0x3f3bf33a, 0x3f3ddce5, 0x3f3fc975,
    0x3f41b8eb, 0x3f43ab48, 0x3f45a08f, 0x3f4798bf, 0x3f4993da, 0x3f4b91e2, 0x3f4d92d8, 0x3f4f96bd, 0x3f519d91,
    0x3f53a758, 0x3f55b410, 0x3f57c3bd, 0x3f59d65e, 0x3f5bebf6, 0x3f5e0485, 0x3f60200d, 0x3f623e91, 0x3f64600b,
    0x3f668486, 0x3f68abfa, 0x3f6ad671, 0x3f6d03e3, 0x3f6f345b, 0x3f7167d0, 0x3f739e4d, 0x3f75d7ca, 0x3f781452,
    0x3f7a53db, 0x3f7c9671, 0x3f7edc0e,
];

/// Writes an 8-bit sRGB PNG preview: premultiplied RGB over black, clamped.
pub fn write_preview_png(path: &Path, film: &Film) -> Result<()> {
    write_preview_png_from(path, film, Colourspace::Rec709)
}

/// [`write_preview_png`] of a film in working colourspace `space`: converted
/// to Rec.709 for display first (sRGB primaries, then the sRGB transfer).
pub fn write_preview_png_from(path: &Path, film: &Film, space: Colourspace) -> Result<()> {
    let pixels: Vec<u8> = film
        .rgba
        .iter()
        .flat_map(|p| colour::to_rec709(space, Vec3::new(p[0], p[1], p[2])).to_array().map(srgb_encode))
        .collect();
    let img = image::RgbImage::from_raw(film.width, film.height, pixels)
        .ok_or_else(|| Error::invalid(path, "film buffer does not match its size"))?;
    write_atomic(path, |out| {
        img.write_to(out, image::ImageFormat::Png).map_err(|e| Error::invalid(path, format!("PNG: {e}")))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_srgb_lookup_is_the_formula_exactly() {
        // Each step and its neighbours, then a strided sweep of [0, 1]. A
        // libm whose powf rounds differently could move a step by an ulp,
        // where the formula's own rounding sits on a code boundary: allowed.
        let on_boundary = |c: f32| {
            let v = 1.055 * (c as f64).powf(1.0 / 2.4) - 0.055;
            ((v * 255.0 + 0.5).fract() - 0.5).abs() > 0.5 - 1e-4
        };
        for &step in &SRGB_STEPS {
            for bits in step - 2..=(step + 2).min(1.0f32.to_bits()) {
                let c = f32::from_bits(bits);
                assert!(srgb_encode(c) == srgb_formula(c) || on_boundary(c), "{c:e}");
            }
            assert!(
                srgb_formula(f32::from_bits(step)) > srgb_formula(f32::from_bits(step - 1))
                    || on_boundary(f32::from_bits(step))
            );
        }
        for bits in (0..=1.0f32.to_bits()).step_by(251) {
            let c = f32::from_bits(bits);
            assert!(srgb_encode(c) == srgb_formula(c) || on_boundary(c), "{c:e}");
        }
        for c in [-1.0, -0.0, 0.0, 1.0, 2.0, f32::INFINITY, f32::NEG_INFINITY, f32::NAN] {
            assert_eq!(srgb_encode(c), srgb_formula(c.clamp(0.0, 1.0)), "{c}");
        }
    }
}
