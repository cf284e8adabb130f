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

/// A deep file's header as throng reads it: the exr crate's, and where
/// the line offset table begins.
struct Head {
    header: Header,
    compression: DeepCompression,
    table_at: usize,
}

/// Parses the header `bytes` begin with (the whole file, or at least its
/// headers): a single-part deep scanline file with throng's channels and a
/// compression deep files allow; else why not.
fn parse_head(bytes: &[u8]) -> std::result::Result<Head, String> {
    if bytes.get(..4) != Some(&[0x76, 0x2f, 0x31, 0x01][..]) {
        return Err("no OpenEXR magic number".into());
    }
    let table_at = super::headers_end(bytes).ok_or("header")?;
    let mut read = exr::io::PeekRead::new(std::io::Cursor::new(&bytes[4..table_at]));
    let req = exr::meta::Requirements::read(&mut read).map_err(|e| e.to_string())?;
    let headers = Header::read_all(&mut read, &req, false).map_err(|e| e.to_string())?;
    let [header] = <[Header; 1]>::try_from(headers.into_vec()).map_err(|_| "more than one part")?;
    let compression = match header.compression {
        Compression::ZIP1 => DeepCompression::Zips,
        Compression::RLE => DeepCompression::Rle,
        Compression::Uncompressed => DeepCompression::None,
        _ => return Err("a compression other than NONE, RLE or ZIPS".into()),
    };
    let names: Vec<String> = header.channels.list.iter().map(|ch| super::lossy(&ch.name)).collect();
    if names != CHANNELS.map(|(n, _)| n.to_string()) {
        return Err("channels other than throng's".into());
    }
    Ok(Head { header, compression, table_at })
}

/// What [`DeepHeader`] says of a parsed header (`bytes`: the file's start).
fn describe(head: &Head, bytes: &[u8]) -> std::result::Result<DeepHeader, String> {
    let header = &head.header;
    let other = |k: &str| header.own_attributes.other.get(&text(k));
    let state = match other("deepImageState") {
        Some(AttributeValue::Custom { bytes, .. }) if bytes.len() == 1 => bytes[0],
        _ => return Err("no deepImageState".into()),
    };
    let block_type = match other("type") {
        Some(AttributeValue::Text(t)) => String::from_utf8_lossy(t.bytes()).into_owned(),
        _ if header.deep => "deepscanline".into(),
        _ => String::new(),
    };
    let mut text_attrs = BTreeMap::new();
    for (k, v) in header.own_attributes.other.iter().chain(header.shared_attributes.other.iter()) {
        if let AttributeValue::Text(t) = v {
            text_attrs.insert(super::lossy(k), super::lossy(t));
        }
    }
    Ok(DeepHeader {
        version: u32::from_le_bytes([bytes[4], bytes[5], bytes[6], bytes[7]]),
        block_type,
        max_samples_per_pixel: header.max_samples_per_pixel.unwrap_or(0),
        state,
        compression: Some(head.compression),
        channels: header.channels.list.iter().map(|ch| super::lossy(&ch.name)).collect(),
        text: text_attrs,
        world_to_ndc: header.own_attributes.world_to_normalized_device,
        chromaticities: header.shared_attributes.chromaticities.is_some(),
        frame: match other("throng/frame") {
            Some(AttributeValue::I32(f)) => Some(*f),
            _ => None,
        },
    })
}

fn not_ours(path: &Path, what: &str) -> Error {
    Error::invalid(path, format!("not a deep scanline EXR throng can read: {what}"))
}

/// Reads a deep file [`write_deep`] wrote (our reader of record: the tests'
/// round trip). Every size is checked against the file before it is used.
pub fn read_deep(path: &Path) -> Result<(DeepImage, DeepHeader)> {
    crate::error::check_readable_file(path)?;
    let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
    let bad = |what: &str| not_ours(path, what);
    let head = parse_head(&bytes).map_err(|e| bad(&e))?;
    let described = describe(&head, &bytes).map_err(|e| bad(&e))?;
    let (w, h) = (head.header.layer_size.width(), head.header.layer_size.height());
    let mut image = DeepImage { width: w as u32, height: h as u32, counts: Vec::new(), samples: Vec::new() };
    for y in 0..h {
        let off = u64_at(&bytes, head.table_at + 8 * y).ok_or_else(|| bad("line offset table"))? as usize;
        read_line(&bytes, off, (y, w), head.compression, true, &mut image)
            .ok_or_else(|| bad(&format!("scanline {y}")))?;
    }
    Ok((image, described))
}

/// A deep file's sample counts alone, and its header: only the header,
/// the line offset table and each chunk's pixel offset table are read
/// (the samples are neither read nor decoded; `samples` is left empty).
pub fn read_sample_counts(path: &Path) -> Result<(DeepImage, DeepHeader)> {
    use std::io::{Seek, SeekFrom};
    let mut start = read_start(path)?;
    let described = describe(&start.head, &start.bytes).map_err(|e| not_ours(path, &e))?;
    let (w, h) = (start.head.header.layer_size.width(), start.head.header.layer_size.height());
    let mut image = DeepImage { width: w as u32, height: h as u32, counts: Vec::new(), samples: Vec::new() };
    let bad = |y: usize| not_ours(path, &format!("scanline {y}"));
    let mut chunk = Vec::new();
    for (y, &off) in start.offsets.iter().enumerate() {
        // The chunk's fixed part (y and three sizes), then its pixel offset table.
        chunk.clear();
        start.file.seek(SeekFrom::Start(off)).map_err(|e| Error::io(path, e))?;
        (&mut start.file).take(28).read_to_end(&mut chunk).map_err(|e| Error::io(path, e))?;
        let table_len = u64_at(&chunk, 4).ok_or_else(|| bad(y))?;
        if table_len > start.len.saturating_sub(off.saturating_add(28)) {
            return Err(bad(y));
        }
        (&mut start.file).take(table_len).read_to_end(&mut chunk).map_err(|e| Error::io(path, e))?;
        read_line(&chunk, 0, (y, w), start.head.compression, false, &mut image).ok_or_else(|| bad(y))?;
    }
    Ok((image, described))
}

/// The header of a deep file, read without its pixels.
pub fn read_deep_header(path: &Path) -> Result<DeepHeader> {
    let start = read_start(path)?;
    describe(&start.head, &start.bytes).map_err(|e| not_ours(path, &e))
}

/// A deep file's start: its header and line offset table, read as far as
/// they go and no further.
struct Start {
    head: Head,
    /// The file's first bytes: at least the headers and the offset table.
    bytes: Vec<u8>,
    /// Each scanline's chunk offset.
    offsets: Vec<u64>,
    file: std::fs::File,
    len: u64,
}

fn read_start(path: &Path) -> Result<Start> {
    use std::io::{Seek, SeekFrom};
    crate::error::check_readable_file(path)?;
    let io = |e| Error::io(path, e);
    let mut file = std::fs::File::open(path).map_err(io)?;
    let len = file.metadata().map_err(io)?.len();
    // Headers hold Cryptomatte manifests, so their size is unknown: read a
    // growing prefix (never past the file's end) until they are whole.
    let mut bytes = Vec::new();
    let mut want = 64u64 << 10;
    let table_at = loop {
        let have = bytes.len() as u64;
        (&mut file).take(want.min(len).saturating_sub(have)).read_to_end(&mut bytes).map_err(io)?;
        if let Some(end) = super::headers_end(&bytes) {
            break end;
        }
        if bytes.len() as u64 >= len {
            return Err(not_ours(path, "the header ends past the end of the file"));
        }
        want = want.saturating_mul(4);
    };
    let head = parse_head(&bytes[..table_at]).map_err(|e| not_ours(path, &e))?;
    let h = head.header.layer_size.height();
    let table_end = (h as u64).checked_mul(8).and_then(|n| n.checked_add(table_at as u64));
    let table_end = table_end.filter(|&e| e <= len).ok_or_else(|| not_ours(path, "line offset table"))?;
    file.seek(SeekFrom::Start(bytes.len() as u64)).map_err(io)?;
    (&mut file).take(table_end.saturating_sub(bytes.len() as u64)).read_to_end(&mut bytes).map_err(io)?;
    let table = bytes.get(table_at..table_end as usize).ok_or_else(|| not_ours(path, "line offset table"))?;
    let offsets = table.chunks_exact(8).map(|b| u64::from_le_bytes(b.try_into().unwrap_or_default())).collect();
    Ok(Start { head, bytes, offsets, file, len })
}

/// Whether `path` is a whole deep file throng can read (a resumed render
/// and the farm count it as done), judged from its header and line offset
/// table without decoding a sample: every chunk starts past the table and
/// inside the file, and the last chunk (the one furthest in) ends inside
/// it. A file cut short anywhere fails; a chunk corrupted inside its
/// bounds is found only by [`read_deep`].
pub fn is_whole(path: &Path) -> bool {
    chunks_inside(path).is_some()
}

fn chunks_inside(path: &Path) -> Option<()> {
    use std::io::{Seek, SeekFrom};
    let mut start = read_start(path).ok()?;
    let h = start.offsets.len();
    let first = start.head.table_at as u64 + 8 * h as u64;
    // A chunk's fixed part: y, and the three u64 sizes.
    const CHUNK_HEAD: u64 = 28;
    if start.offsets.iter().any(|&o| o < first || o.checked_add(CHUNK_HEAD).is_none_or(|e| e > start.len)) {
        return None;
    }
    let last = start.offsets.iter().copied().max()?;
    let mut fixed = [0u8; CHUNK_HEAD as usize];
    start.file.seek(SeekFrom::Start(last)).ok()?;
    start.file.read_exact(&mut fixed).ok()?;
    let y = i32::from_le_bytes(fixed[..4].try_into().ok()?);
    let (table_len, data_len) = (u64_at(&fixed, 4)?, u64_at(&fixed, 12)?);
    let end = last.checked_add(CHUNK_HEAD)?.checked_add(table_len)?.checked_add(data_len)?;
    (usize::try_from(y).is_ok_and(|y| y < h) && end <= start.len).then_some(())
}

/// Reads scanline `y`'s chunk (of `w` pixels) at `off` into `image`: its
/// counts, and its samples when `samples` asks for them.
fn read_line(
    b: &[u8],
    off: usize,
    (y, w): (usize, usize),
    c: DeepCompression,
    samples: bool,
    image: &mut DeepImage,
) -> Option<()> {
    if i32::from_le_bytes(b.get(off..off + 4)?.try_into().ok()?) != y as i32 {
        return None;
    }
    let (table_len, data_len) = (u64_at(b, off + 4)? as usize, u64_at(b, off + 12)? as usize);
    let unpacked = u64_at(b, off + 20)? as usize;
    let table_raw = b.get(off + 28..(off + 28).checked_add(table_len)?)?;
    // No more than compression can expand these packed bytes to, before anything is allocated.
    let most = |packed: usize| (packed.max(1) as u64).saturating_mul(crate::exr_guard::MAX_EXR_EXPANSION);
    if (w as u64).saturating_mul(4) > most(table_len) || unpacked as u64 > most(data_len) {
        return None;
    }
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
    if !samples {
        image.counts.extend(counts);
        return Some(());
    }
    let data_raw = b.get(off + 28 + table_len..(off + 28 + table_len).checked_add(data_len)?)?;
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
