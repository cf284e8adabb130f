//! Deep scanline OpenEXR files: the writer, and a reader of what it writes
//! (tests, `.ci/deep_check.py` checks the same files with OpenEXR itself).
//! The exr crate reads and writes flat images only, so the chunks are laid
//! out here; its header types write the attributes, the same ones the flat
//! file has ([`super::layer_attributes`]).
//!
//! Layout, after "OpenEXR File Layout" (deep data sections) and
//! "Interpreting OpenEXR Deep Pixels" (openexr.com):
//! - version field 2 with the non-image (deep) bit 11 set, single part;
//! - header: `type` `deepscanline`, `version` 1 (deep data version),
//!   `chunkCount` (one chunk a scanline: NONE and ZIPS hold one line),
//!   `maxSamplesPerPixel`, `deepImageState` (`tidy` when every pixel's
//!   samples are sorted by depth and none overlap, else `sorted`), `name`,
//!   and the flat file's attributes: camera matrices, `worldToNDC`,
//!   `chromaticities`, `throng/*`, and the `CryptoAgent` and `CryptoPart`
//!   manifests the id channels decode with;
//! - the line offset table (one u64 file offset a chunk), then per
//!   scanline: `y` (i32), the packed size of the pixel offset table, the
//!   packed and unpacked sizes of the sample data (u64 each), the pixel
//!   offset table (per pixel the i32 count of samples up to and including
//!   it), then each channel's samples in channel (name) order, pixel after
//!   pixel;
//! - ZIPS and RLE compress the table and the sample data each as OpenEXR's
//!   ZIP and RLE do (bytes split into even and odd halves, differences of
//!   neighbours, then zlib, or run lengths as ImfRle.cpp's); a part whose
//!   compressed form is no smaller is stored raw (the reader knows it by
//!   packed size = unpacked size).
//!
//! Channels: `A B G R` (half, premultiplied, as the flat file), `Z` and
//! `ZBack` (float, camera-space depth), `id.agent` and `id.object` (float:
//! the `CryptoAgent` and `CryptoPart` ids of the sample, see
//! [`crate::render::deep`]).

use std::collections::BTreeMap;
use std::io::{Read, Write};
use std::path::Path;

use exr::meta::attribute::{AttributeValue, BlockType, ChannelDescription, SampleType};
use exr::meta::header::Header;
use exr::meta::BlockDescription;
use exr::prelude::{f16, Compression, LineOrder, SmallVec};

use super::{chromaticities, layer_attributes, text, LayerMeta, ManifestMode, WriteOptions};
use crate::error::{write_atomic, Error, Result};
use crate::render::cryptomatte::{AGENT_MATTE, PART_MATTE};
use crate::render::deep::{DeepImage, DeepSample};
use crate::render::Film;

/// Deep file compression (`render.deep.compression`): the lossless ones
/// OpenEXR allows for deep data that throng writes.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum DeepCompression {
    /// ZIP per scanline: lossless, the default.
    #[default]
    Zips,
    /// Run lengths of the reordered bytes: lossless, fast, larger.
    Rle,
    /// No compression.
    None,
}

impl DeepCompression {
    /// The compression of the shot's `render.deep` (checked when the shot
    /// was read: [`crate::shot::Deep::COMPRESSIONS`]).
    pub fn of(deep: &crate::shot::Deep) -> DeepCompression {
        DeepCompression::parse(&deep.compression).unwrap_or_default()
    }

    /// The compression named `name`.
    pub fn parse(name: &str) -> Option<DeepCompression> {
        match name {
            "zips" => Some(DeepCompression::Zips),
            "rle" => Some(DeepCompression::Rle),
            "none" => Some(DeepCompression::None),
            _ => None,
        }
    }

    fn exr(self) -> Compression {
        match self {
            DeepCompression::Zips => Compression::ZIP1,
            DeepCompression::Rle => Compression::RLE,
            DeepCompression::None => Compression::Uncompressed,
        }
    }
}

/// OpenEXR's `deepImageState` values.
const STATE_SORTED: u8 = 1;
const STATE_TIDY: u8 = 3;
/// The version field: file format 2, the deep (non-image) bit, and the long
/// names bit when a name is longer than 31 bytes.
const VERSION: u32 = 2;
const DEEP_BIT: u32 = 1 << 11;
const LONG_NAMES_BIT: u32 = 1 << 10;
/// The channels, in the order the file stores them (sorted by name).
const CHANNELS: [(&str, SampleType); 8] = [
    ("A", SampleType::F16),
    ("B", SampleType::F16),
    ("G", SampleType::F16),
    ("R", SampleType::F16),
    ("Z", SampleType::F32),
    ("ZBack", SampleType::F32),
    ("id.agent", SampleType::F32),
    ("id.object", SampleType::F32),
];
/// What the id channels hold, written to `throng/deepIds`.
pub const DEEP_IDS: &str =
    "id.agent = CryptoAgent id, id.object = CryptoPart id (float-encoded MurmurHash3_32, manifests in cryptomatte/<key>/manifest; 0 = sky)";

/// A channel's value of a sample.
fn channel_value(s: &DeepSample, c: usize) -> f32 {
    match c {
        0 => s.rgba[3],
        1 => s.rgba[2],
        2 => s.rgba[1],
        3 => s.rgba[0],
        4 => s.z,
        5 => s.z_back,
        6 => s.agent_id,
        _ => s.object_id,
    }
}

/// The file's header bytes (magic number, version, header), attributes
/// sorted by name so the same image gives the same bytes.
fn header_bytes(path: &Path, deep: &DeepImage, film: &Film, meta: &LayerMeta, c: DeepCompression) -> Result<Vec<u8>> {
    let options = WriteOptions { manifest: ManifestMode::Header, ..WriteOptions::default() };
    let ids = |name: &str| name == AGENT_MATTE || name == PART_MATTE;
    let mut attrs = layer_attributes(path, film, &ids, meta, &options)?;
    let state = if deep.is_tidy() { STATE_TIDY } else { STATE_SORTED };
    // The exr crate types deepImageState as a rational; OpenEXR's is one byte.
    attrs.other.insert(
        text("deepImageState"),
        AttributeValue::Custom { kind: text("deepImageState"), bytes: SmallVec::from_slice(&[state]) },
    );
    attrs.other.insert(text("throng/deepIds"), AttributeValue::Text(text(DEEP_IDS)));
    let channels: SmallVec<[ChannelDescription; 5]> =
        CHANNELS.iter().map(|(n, t)| ChannelDescription::new(text(n), *t, false)).collect();
    let (w, h) = (deep.width as usize, deep.height as usize);
    let mut header = Header::new(text(&meta.layer), (w, h), channels);
    header.compression = c.exr();
    header.blocks = BlockDescription::ScanLines;
    header.line_order = LineOrder::Increasing;
    header.chunk_count = h;
    header.deep = true;
    header.deep_data_version = Some(1);
    header.max_samples_per_pixel = Some(deep.max_samples() as usize);
    header.own_attributes = attrs;
    header.shared_attributes.chromaticities = Some(chromaticities(meta.colourspace));
    let long = header.all_named_attributes().any(|(n, _)| n.len() > 31) || CHANNELS.iter().any(|(n, _)| n.len() > 31);
    let mut out = vec![0x76, 0x2f, 0x31, 0x01];
    out.extend_from_slice(&(VERSION | DEEP_BIT | if long { LONG_NAMES_BIT } else { 0 }).to_le_bytes());
    let bad = |e: exr::error::Error| Error::invalid(path, format!("deep EXR header: {e}"));
    for (name, value) in header.all_named_attributes() {
        // The exr crate names every scanline part `scanlineimage`.
        let value = if name == b"type" { AttributeValue::BlockType(BlockType::DeepScanLine) } else { value };
        exr::meta::attribute::write(name, &value, &mut out).map_err(bad)?;
    }
    out.push(0);
    super::sort_header_attributes(&mut out);
    Ok(out)
}

/// The byte reordering OpenEXR's ZIP and RLE share: even bytes then odd
/// bytes, each byte as the difference from the one before (+128).
fn predict(raw: &[u8]) -> Vec<u8> {
    let half = raw.len().div_ceil(2);
    let mut t = vec![0u8; raw.len()];
    for (i, &b) in raw.iter().enumerate() {
        t[if i % 2 == 0 { i / 2 } else { half + i / 2 }] = b;
    }
    let mut prev = t.first().copied().unwrap_or(0);
    for v in t.iter_mut().skip(1) {
        let d = v.wrapping_sub(prev).wrapping_add(128);
        prev = *v;
        *v = d;
    }
    t
}

/// The inverse of [`predict`].
fn unpredict(mut t: Vec<u8>) -> Vec<u8> {
    for i in 1..t.len() {
        t[i] = t[i - 1].wrapping_add(t[i]).wrapping_sub(128);
    }
    let half = t.len().div_ceil(2);
    (0..t.len()).map(|i| t[if i % 2 == 0 { i / 2 } else { half + i / 2 }]).collect()
}

/// OpenEXR's ZIP: [`predict`], then zlib.
fn zip_compress(raw: &[u8]) -> Vec<u8> {
    let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::default());
    // Writing to a Vec cannot fail.
    let _ = z.write_all(&predict(raw));
    z.finish().unwrap_or_default()
}

/// The inverse of [`zip_compress`], for exactly `size` bytes.
fn zip_decompress(packed: &[u8], size: usize) -> Option<Vec<u8>> {
    let mut t = Vec::with_capacity(size);
    flate2::read::ZlibDecoder::new(packed).take(size as u64 + 1).read_to_end(&mut t).ok()?;
    (t.len() == size).then(|| unpredict(t))
}

/// OpenEXR's RLE (`rleCompress` in ImfRle.cpp): [`predict`], then runs of
/// 3 to 128 equal bytes as (length - 1, byte) and other stretches of up to
/// 127 bytes as (-length, bytes).
fn rle_compress(raw: &[u8]) -> Vec<u8> {
    const MIN_RUN: usize = 3;
    const MAX_RUN: usize = 127;
    let t = predict(raw);
    let mut out = Vec::with_capacity(t.len() + t.len() / 64 + 2);
    let (mut start, mut end) = (0usize, 1usize);
    while start < t.len() {
        while end < t.len() && t[start] == t[end] && end - start - 1 < MAX_RUN {
            end += 1;
        }
        if end - start >= MIN_RUN {
            out.push((end - start - 1) as u8);
            out.push(t[start]);
            start = end;
        } else {
            // A literal stretch ends where a run of three equal bytes begins.
            while end < t.len()
                && (end + 1 >= t.len() || t[end] != t[end + 1] || end + 2 >= t.len() || t[end + 1] != t[end + 2])
                && end - start < MAX_RUN
            {
                end += 1;
            }
            out.push((-((end - start) as i32)) as u8);
            out.extend_from_slice(&t[start..end]);
            start = end;
        }
        end += 1;
    }
    out
}

/// The inverse of [`rle_compress`], for exactly `size` bytes.
fn rle_decompress(packed: &[u8], size: usize) -> Option<Vec<u8>> {
    let mut t = Vec::with_capacity(size);
    let mut at = 0;
    while at < packed.len() {
        let n = packed[at] as i8;
        if n < 0 {
            let count = -(n as i32) as usize;
            t.extend_from_slice(packed.get(at + 1..at + 1 + count)?);
            at += 1 + count;
        } else {
            let count = n as usize + 1;
            t.extend(std::iter::repeat_n(*packed.get(at + 1)?, count));
            at += 2;
        }
        if t.len() > size {
            return None;
        }
    }
    (t.len() == size).then(|| unpredict(t))
}

/// `raw` as `c` stores it: compressed only where that is smaller.
fn pack(raw: Vec<u8>, c: DeepCompression) -> Vec<u8> {
    let packed = match c {
        DeepCompression::None => return raw,
        DeepCompression::Zips => zip_compress(&raw),
        DeepCompression::Rle => rle_compress(&raw),
    };
    if packed.len() < raw.len() {
        packed
    } else {
        raw
    }
}

/// One scanline's chunk.
fn line_chunk(y: usize, pixels: &[&[DeepSample]], c: DeepCompression) -> Vec<u8> {
    let mut table = Vec::with_capacity(pixels.len() * 4);
    let mut total = 0i32;
    for p in pixels {
        total = total.saturating_add(p.len() as i32);
        table.extend_from_slice(&total.to_le_bytes());
    }
    let mut data = Vec::new();
    for (c, (_, kind)) in CHANNELS.iter().enumerate() {
        for s in pixels.iter().flat_map(|p| p.iter()) {
            let v = channel_value(s, c);
            match kind {
                SampleType::F16 => data.extend_from_slice(&f16::from_f32(v.clamp(-65504.0, 65504.0)).to_le_bytes()),
                _ => data.extend_from_slice(&v.to_le_bytes()),
            }
        }
    }
    let unpacked = data.len() as u64;
    let (table, data) = (pack(table, c), pack(data, c));
    let mut out = Vec::with_capacity(28 + table.len() + data.len());
    out.extend_from_slice(&(y as i32).to_le_bytes());
    out.extend_from_slice(&(table.len() as u64).to_le_bytes());
    out.extend_from_slice(&(data.len() as u64).to_le_bytes());
    out.extend_from_slice(&unpacked.to_le_bytes());
    out.extend_from_slice(&table);
    out.extend_from_slice(&data);
    out
}

/// Writes `deep` atomically to `path` as a deep scanline OpenEXR, with the
/// header attributes of `film`'s flat file (`meta`).
pub fn write_deep(path: &Path, deep: &DeepImage, film: &Film, meta: &LayerMeta, c: DeepCompression) -> Result<()> {
    let (w, h) = (deep.width as usize, deep.height as usize);
    let total: u64 = deep.counts.iter().map(|&n| u64::from(n)).sum();
    if deep.counts.len() != w * h || total != deep.samples.len() as u64 {
        return Err(Error::invalid(path, "the deep image's sample counts do not match its samples"));
    }
    let head = header_bytes(path, deep, film, meta, c)?;
    write_atomic(path, |out| {
        use std::io::{Seek, SeekFrom};
        let io = |e| Error::io(path, e);
        out.write_all(&head).map_err(io)?;
        // The line offset table, filled in once the chunks are written.
        out.write_all(&vec![0u8; h * 8]).map_err(io)?;
        let mut offsets = Vec::with_capacity(h * 8);
        let mut at = (head.len() + h * 8) as u64;
        let mut pixels = deep.pixels();
        for y in 0..h {
            let line: Vec<&[DeepSample]> = pixels.by_ref().take(w).collect();
            let chunk = line_chunk(y, &line, c);
            offsets.extend_from_slice(&at.to_le_bytes());
            at += chunk.len() as u64;
            out.write_all(&chunk).map_err(io)?;
        }
        out.seek(SeekFrom::Start(head.len() as u64)).map_err(io)?;
        out.write_all(&offsets).map_err(io)?;
        out.seek(SeekFrom::End(0)).map_err(io)?;
        Ok(())
    })
}

/// What a deep file's header says beside its pixels.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DeepHeader {
    /// The version field (format version and flags).
    pub version: u32,
    /// `type`.
    pub block_type: String,
    /// `maxSamplesPerPixel`.
    pub max_samples_per_pixel: usize,
    /// `deepImageState` (1 sorted, 3 tidy).
    pub state: u8,
    /// The compression.
    pub compression: Option<DeepCompression>,
    /// Channel names, in file order.
    pub channels: Vec<String>,
    /// Text attributes by name.
    pub text: BTreeMap<String, String>,
    /// `worldToNDC`.
    pub world_to_ndc: Option<[f32; 16]>,
    /// Whether `chromaticities` is present.
    pub chromaticities: bool,
    /// `throng/frame`.
    pub frame: Option<i32>,
}

fn u64_at(b: &[u8], at: usize) -> Option<u64> {
    Some(u64::from_le_bytes(b.get(at..at + 8)?.try_into().ok()?))
}

/// Reads a deep file [`write_deep`] wrote (our reader of record: the tests'
/// round trip). Every size is checked against the file before it is used.
pub fn read_deep(path: &Path) -> Result<(DeepImage, DeepHeader)> {
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let bad = |what: &str| Error::invalid(path, format!("not a deep scanline EXR throng can read: {what}"));
    if bytes.get(..4) != Some(&[0x76, 0x2f, 0x31, 0x01][..]) {
        return Err(bad("no OpenEXR magic number"));
    }
    let mut read = exr::io::PeekRead::new(std::io::Cursor::new(&bytes[4..]));
    let req = exr::meta::Requirements::read(&mut read).map_err(|e| bad(&e.to_string()))?;
    let headers = Header::read_all(&mut read, &req, false).map_err(|e| bad(&e.to_string()))?;
    let [header] = headers.as_slice() else { return Err(bad("more than one part")) };
    let other = |k: &str| header.own_attributes.other.get(&text(k));
    let state = match other("deepImageState") {
        Some(AttributeValue::Custom { bytes, .. }) if bytes.len() == 1 => bytes[0],
        _ => return Err(bad("no deepImageState")),
    };
    let block_type = match other("type") {
        Some(AttributeValue::Text(t)) => String::from_utf8_lossy(t.bytes()).into_owned(),
        _ => {
            if header.deep {
                "deepscanline".into()
            } else {
                String::new()
            }
        }
    };
    let mut text_attrs = BTreeMap::new();
    for (k, v) in header.own_attributes.other.iter().chain(header.shared_attributes.other.iter()) {
        if let AttributeValue::Text(t) = v {
            text_attrs.insert(super::lossy(k), super::lossy(t));
        }
    }
    let compression = match header.compression {
        Compression::ZIP1 => Some(DeepCompression::Zips),
        Compression::RLE => Some(DeepCompression::Rle),
        Compression::Uncompressed => Some(DeepCompression::None),
        _ => None,
    };
    let Some(c) = compression else { return Err(bad("a compression other than NONE, RLE or ZIPS")) };
    let names: Vec<String> = header.channels.list.iter().map(|ch| super::lossy(&ch.name)).collect();
    if names != CHANNELS.map(|(n, _)| n.to_string()) {
        return Err(bad("channels other than throng's"));
    }
    let (w, h) = (header.layer_size.width(), header.layer_size.height());
    let table_at = super::headers_end(&bytes).ok_or_else(|| bad("header"))?;
    let mut image = DeepImage { width: w as u32, height: h as u32, counts: Vec::new(), samples: Vec::new() };
    for y in 0..h {
        let off = u64_at(&bytes, table_at + 8 * y).ok_or_else(|| bad("line offset table"))? as usize;
        read_line(&bytes, off, y, w, c, &mut image).ok_or_else(|| bad(&format!("scanline {y}")))?;
    }
    let head = DeepHeader {
        version: u32::from_le_bytes([bytes[4], bytes[5], bytes[6], bytes[7]]),
        block_type,
        max_samples_per_pixel: header.max_samples_per_pixel.unwrap_or(0),
        state,
        compression,
        channels: names,
        text: text_attrs,
        world_to_ndc: header.own_attributes.world_to_normalized_device,
        chromaticities: header.shared_attributes.chromaticities.is_some(),
        frame: match other("throng/frame") {
            Some(AttributeValue::I32(f)) => Some(*f),
            _ => None,
        },
    };
    Ok((image, head))
}

/// Whether `path` is a whole deep file throng can read (a resumed render
/// and the farm count it as done).
pub fn is_whole(path: &Path) -> bool {
    read_deep(path).is_ok()
}

/// Reads scanline `y`'s chunk at `off` into `image`.
fn read_line(b: &[u8], off: usize, y: usize, w: usize, c: DeepCompression, image: &mut DeepImage) -> Option<()> {
    if i32::from_le_bytes(b.get(off..off + 4)?.try_into().ok()?) != y as i32 {
        return None;
    }
    let (table_len, data_len) = (u64_at(b, off + 4)? as usize, u64_at(b, off + 12)? as usize);
    let unpacked = u64_at(b, off + 20)? as usize;
    let table_raw = b.get(off + 28..(off + 28).checked_add(table_len)?)?;
    let data_raw = b.get(off + 28 + table_len..(off + 28 + table_len).checked_add(data_len)?)?;
    let unpack = |raw: &[u8], size: usize| -> Option<Vec<u8>> {
        match c {
            _ if raw.len() == size => Some(raw.to_vec()),
            DeepCompression::Zips => zip_decompress(raw, size),
            DeepCompression::Rle => rle_decompress(raw, size),
            DeepCompression::None => None,
        }
    };
    let table = unpack(table_raw, w * 4)?;
    let mut prev = 0u32;
    let mut counts = Vec::with_capacity(w);
    for v in table.chunks_exact(4) {
        let cum = u32::try_from(i32::from_le_bytes(v.try_into().ok()?)).ok()?;
        counts.push(cum.checked_sub(prev)?);
        prev = cum;
    }
    let n = prev as usize;
    let bytes_per_sample: usize = CHANNELS.iter().map(|(_, t)| if *t == SampleType::F16 { 2 } else { 4 }).sum();
    if unpacked != n.checked_mul(bytes_per_sample)? {
        return None;
    }
    let data = unpack(data_raw, unpacked)?;
    let mut samples = vec![DeepSample::default(); n];
    let mut at = 0;
    for (ch, (_, kind)) in CHANNELS.iter().enumerate() {
        for s in samples.iter_mut() {
            let v = match kind {
                SampleType::F16 => f16::from_le_bytes(data.get(at..at + 2)?.try_into().ok()?).to_f32(),
                _ => f32::from_le_bytes(data.get(at..at + 4)?.try_into().ok()?),
            };
            at += if *kind == SampleType::F16 { 2 } else { 4 };
            match ch {
                0 => s.rgba[3] = v,
                1 => s.rgba[2] = v,
                2 => s.rgba[1] = v,
                3 => s.rgba[0] = v,
                4 => s.z = v,
                5 => s.z_back = v,
                6 => s.agent_id = v,
                _ => s.object_id = v,
            }
        }
    }
    image.counts.extend(counts);
    image.samples.extend(samples);
    Some(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zip_and_rle_round_trip() {
        let runs: Vec<u8> = (0..3000u32).map(|i| if i % 700 < 400 { 9 } else { (i * 37 % 251) as u8 }).collect();
        for raw in [Vec::new(), vec![7u8], vec![1, 1], (0..1000u32).map(|i| (i * 37 % 251) as u8).collect(), runs] {
            assert_eq!(zip_decompress(&zip_compress(&raw), raw.len()).as_deref(), Some(&raw[..]));
            assert_eq!(rle_decompress(&rle_compress(&raw), raw.len()).as_deref(), Some(&raw[..]));
        }
        // A run of 300 equal bytes (constant after prediction) packs into runs of at most 128.
        let flat = vec![5u8; 300];
        let packed = rle_compress(&flat);
        assert!(packed.len() <= 8, "{packed:?}");
        assert!(rle_decompress(&packed, 299).is_none() && rle_decompress(&packed[..3], 300).is_none());
    }
}
