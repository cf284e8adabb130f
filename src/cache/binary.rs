//! The native `.crowd` binary cache: little-endian, a fixed header, a
//! checksummed index (string tables and frame -> block table), then one
//! checksummed block per frame. docs/cache-format.md is the specification;
//! keep the two in step.
//!
//! Opening reads only the header and index; [`BinaryReader::read_frame`]
//! seeks to one block. Every size read from the file is checked against the
//! file's length before anything is allocated, so a corrupt header cannot
//! ask for gigabytes.

use std::fs::File;
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use glam::Vec3;

use super::{first_use_tables, lock, missing_frame, validate_frame, validate_frame_order, validate_names};
use super::{AgentSample, CrowdCache, FrameBlock};
use crate::error::{write_atomic, Error, IoContext, Result};

/// First 8 bytes of every `.crowd` file.
pub const MAGIC: [u8; 8] = *b"THRCROWD";
/// The format version this code reads and writes.
pub(crate) const VERSION: u32 = 1;
/// Bytes in the fixed header.
pub const HEADER_LEN: u64 = 32;
/// Bytes per frame-index entry.
pub(crate) const INDEX_ENTRY_LEN: u64 = 24;
/// Bytes per agent record (including 3 zero padding bytes).
pub(crate) const RECORD_LEN: u64 = 32;
/// Bytes in a frame block besides its records: frame, agent count, CRC.
pub(crate) const BLOCK_OVERHEAD: u64 = 12;

/// Where one frame's block lives.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct IndexEntry {
    /// Cache frame number.
    pub(crate) frame: i32,
    /// Agents in the block.
    pub(crate) agents: u32,
    /// Byte offset of the block from the start of the file.
    pub offset: u64,
    /// Block length in bytes (`12 + 32 * agents`).
    pub(crate) length: u64,
}

/// The header and index of a `.crowd` file: everything but the blocks.
#[derive(Clone, Debug, PartialEq)]
struct Meta {
    rigs: Vec<String>,
    cycles: Vec<String>,
    index: Vec<IndexEntry>,
}

/// The fixed header's counts.
struct Header {
    meta_len: u64,
    frames: u64,
    rigs: u64,
    cycles: u64,
}

/// A bounds-checked little-endian reader over a byte slice.
struct Cur<'a> {
    b: &'a [u8],
    pos: usize,
}

impl<'a> Cur<'a> {
    fn new(b: &'a [u8]) -> Self {
        Cur { b, pos: 0 }
    }
    fn take(&mut self, n: usize) -> Option<&'a [u8]> {
        let s = self.b.get(self.pos..self.pos.checked_add(n)?)?;
        self.pos += n;
        Some(s)
    }
    fn arr<const N: usize>(&mut self) -> Option<[u8; N]> {
        self.take(N)?.try_into().ok()
    }
    fn u8(&mut self) -> Option<u8> {
        Some(self.arr::<1>()?[0])
    }
    fn u16(&mut self) -> Option<u16> {
        self.arr().map(u16::from_le_bytes)
    }
    fn u32(&mut self) -> Option<u32> {
        self.arr().map(u32::from_le_bytes)
    }
    fn i32(&mut self) -> Option<i32> {
        self.arr().map(i32::from_le_bytes)
    }
    fn u64(&mut self) -> Option<u64> {
        self.arr().map(u64::from_le_bytes)
    }
    fn f32(&mut self) -> Option<f32> {
        self.arr().map(f32::from_le_bytes)
    }
}

fn crc(bytes: &[u8]) -> u32 {
    crc32fast::hash(bytes)
}

/// Splits `bytes` into (payload, stored CRC) and checks the CRC.
fn check_crc<'a>(path: &Path, bytes: &'a [u8], what: &str) -> Result<&'a [u8]> {
    let split = bytes.len().checked_sub(4).ok_or_else(|| Error::invalid(path, format!("{what} is too short")))?;
    let (payload, stored) = bytes.split_at(split);
    let stored = u32::from_le_bytes(stored.try_into().unwrap_or_default());
    let computed = crc(payload);
    if stored != computed {
        return Err(Error::invalid(
            path,
            format!("{what} checksum mismatch (stored {stored:#010x}, computed {computed:#010x}): the file is corrupt"),
        ));
    }
    Ok(payload)
}

fn parse_header(path: &Path, bytes: &[u8], file_len: u64) -> Result<Header> {
    let mut c = Cur::new(bytes);
    let short =
        || Error::invalid(path, format!("truncated: {file_len} bytes, shorter than the {HEADER_LEN}-byte header"));
    let magic: [u8; 8] = c.arr().ok_or_else(short)?;
    if magic != MAGIC {
        return Err(Error::invalid(
            path,
            format!(
                "not a throng .crowd cache: bad magic {:?} (expected \"THRCROWD\")",
                String::from_utf8_lossy(&magic)
            ),
        ));
    }
    // The version is checked before the CRC so a newer file says so rather
    // than "corrupt": magic and version never move between versions.
    let version = c.u32().ok_or_else(short)?;
    if version != VERSION {
        return Err(Error::invalid(
            path,
            format!("unknown .crowd version {version}; this throng reads version {VERSION}"),
        ));
    }
    let head = bytes.get(..HEADER_LEN as usize).ok_or_else(short)?;
    check_crc(path, head, "header")?;
    let meta_len = u64::from(c.u32().ok_or_else(short)?);
    let frames = u64::from(c.u32().ok_or_else(short)?);
    let rigs = u64::from(c.u32().ok_or_else(short)?);
    let cycles = u64::from(c.u32().ok_or_else(short)?);
    if HEADER_LEN + meta_len > file_len {
        return Err(Error::invalid(
            path,
            format!("truncated: the index ends at byte {} but the file is {file_len} bytes", HEADER_LEN + meta_len),
        ));
    }
    // Smallest index these counts need; guards the allocations below.
    let least = frames * INDEX_ENTRY_LEN + (rigs + cycles) * 2 + 4;
    if rigs > 65536 || cycles > 65536 || least > meta_len {
        return Err(Error::invalid(
            path,
            format!("corrupt header: {frames} frames, {rigs} rigs, {cycles} cycles do not fit a {meta_len}-byte index"),
        ));
    }
    Ok(Header { meta_len, frames, rigs, cycles })
}

fn parse_names(path: &Path, c: &mut Cur, count: u64, kind: &str) -> Result<Vec<String>> {
    let mut names = Vec::with_capacity(count as usize);
    for i in 0..count {
        let bad = || Error::invalid(path, format!("truncated {kind} name {i} in the index")).field(kind);
        let len = c.u16().ok_or_else(bad)?;
        let bytes = c.take(usize::from(len)).ok_or_else(bad)?;
        let name = std::str::from_utf8(bytes)
            .map_err(|_| Error::invalid(path, format!("{kind} name {i} is not UTF-8")).field(kind))?;
        names.push(name.to_string());
    }
    validate_names(path, kind, &names)?;
    Ok(names)
}

fn parse_meta(path: &Path, bytes: &[u8], h: &Header, file_len: u64) -> Result<Meta> {
    let payload = check_crc(path, bytes, "index")?;
    let mut c = Cur::new(payload);
    let rigs = parse_names(path, &mut c, h.rigs, "rig")?;
    let cycles = parse_names(path, &mut c, h.cycles, "cycle")?;
    let mut index = Vec::with_capacity(h.frames as usize);
    // Blocks follow the index back to back, in index order.
    let mut next = HEADER_LEN + h.meta_len;
    for i in 0..h.frames {
        let bad = || Error::invalid(path, format!("truncated frame index at entry {i}"));
        let e = IndexEntry {
            frame: c.i32().ok_or_else(bad)?,
            agents: c.u32().ok_or_else(bad)?,
            offset: c.u64().ok_or_else(bad)?,
            length: c.u64().ok_or_else(bad)?,
        };
        let at = |msg: String| Error::invalid(path, msg).frame(e.frame.into());
        if e.length != BLOCK_OVERHEAD + RECORD_LEN * u64::from(e.agents) {
            return Err(at(format!("index says {} agents in a {}-byte block", e.agents, e.length)));
        }
        if e.offset != next {
            return Err(at(format!("block at byte {}, expected {next} (blocks follow the index in order)", e.offset)));
        }
        next = e.offset + e.length;
        if next > file_len {
            return Err(at(format!(
                "truncated: the frame's block ends at byte {next} but the file is {file_len} bytes"
            )));
        }
        index.push(e);
    }
    if c.pos != payload.len() {
        return Err(Error::invalid(
            path,
            format!("{} unexpected bytes at the end of the index", payload.len() - c.pos),
        ));
    }
    if next != file_len {
        return Err(Error::invalid(path, format!("{} trailing bytes after the last frame block", file_len - next)));
    }
    validate_frame_order(path, index.iter().map(|e| e.frame))?;
    Ok(Meta { rigs, cycles, index })
}

fn parse_block(path: &Path, bytes: &[u8], e: &IndexEntry, rigs: usize, cycles: usize) -> Result<FrameBlock> {
    let at = |msg: String| Error::invalid(path, msg).frame(e.frame.into());
    let payload = check_crc(path, bytes, "frame block").map_err(|err| err.frame(e.frame.into()))?;
    let mut c = Cur::new(payload);
    let short = || at("truncated frame block".into());
    let frame = c.i32().ok_or_else(short)?;
    let count = c.u32().ok_or_else(short)?;
    if frame != e.frame || count != e.agents {
        return Err(at(format!("block says frame {frame} with {count} agents; the index says {} agents", e.agents)));
    }
    let mut agents = Vec::with_capacity(count as usize);
    for _ in 0..count {
        let mut r = || -> Option<(AgentSample, [u8; 3])> {
            let id = c.u32()?;
            let position = Vec3::new(c.f32()?, c.f32()?, c.f32()?);
            let heading = c.f32()?;
            let rig = c.u16()?;
            let cycle = c.u16()?;
            let cycle_frame = c.f32()?;
            let flags = c.u8()?;
            Some((AgentSample { id, position, heading, rig, cycle, cycle_frame, flags }, c.arr()?))
        };
        let (a, pad) = r().ok_or_else(short)?;
        if pad != [0; 3] {
            return Err(at("reserved padding bytes are not zero".into()).agent(a.id));
        }
        agents.push(a);
    }
    let block = FrameBlock { frame, agents };
    validate_frame(path, &block, rigs, cycles)?;
    Ok(block)
}

/// Parses a whole `.crowd` file held in memory. `path` only names the data
/// in errors. Never panics on any input (see fuzz/).
pub fn parse_bytes_named(path: &Path, bytes: &[u8]) -> Result<CrowdCache> {
    let file_len = bytes.len() as u64;
    let h = parse_header(path, bytes, file_len)?;
    let meta_bytes = bytes.get(HEADER_LEN as usize..(HEADER_LEN + h.meta_len) as usize).unwrap_or_default();
    let meta = parse_meta(path, meta_bytes, &h, file_len)?;
    let mut frames = Vec::with_capacity(meta.index.len());
    for e in &meta.index {
        let block = bytes.get(e.offset as usize..(e.offset + e.length) as usize).unwrap_or_default();
        frames.push(parse_block(path, block, e, meta.rigs.len(), meta.cycles.len())?);
    }
    Ok(CrowdCache { rigs: meta.rigs, cycles: meta.cycles, frames })
}

/// Parses a whole `.crowd` file held in memory (the fuzz target's entry).
pub fn parse_bytes(bytes: &[u8]) -> Result<CrowdCache> {
    parse_bytes_named(Path::new("<bytes>"), bytes)
}

/// Reads a whole `.crowd` file.
pub(crate) fn read(path: &Path) -> Result<CrowdCache> {
    BinaryReader::open(path)?.read_all()
}

/// Random access to a `.crowd` file: the index is read on open, each frame
/// on demand. Shareable between threads (the file handle is locked per read).
#[derive(Debug)]
pub struct BinaryReader {
    path: PathBuf,
    file: Mutex<File>,
    rigs: Vec<String>,
    cycles: Vec<String>,
    frames: Vec<i32>,
    index: Vec<IndexEntry>,
}

impl BinaryReader {
    /// Opens `path`, reading and checking the header and index only.
    pub fn open(path: &Path) -> Result<BinaryReader> {
        let mut file = File::open(path).at(path)?;
        let file_len = file.metadata().at(path)?.len();
        let mut head = Vec::with_capacity(HEADER_LEN as usize);
        (&mut file).take(HEADER_LEN).read_to_end(&mut head).at(path)?;
        let h = parse_header(path, &head, file_len)?;
        // meta_len <= file_len was checked, so this allocation is bounded.
        let mut meta = vec![0; h.meta_len as usize];
        file.read_exact(&mut meta).at(path)?;
        let meta = parse_meta(path, &meta, &h, file_len)?;
        Ok(BinaryReader {
            path: path.to_path_buf(),
            file: Mutex::new(file),
            frames: meta.index.iter().map(|e| e.frame).collect(),
            rigs: meta.rigs,
            cycles: meta.cycles,
            index: meta.index,
        })
    }

    /// The file.
    pub(crate) fn path(&self) -> &Path {
        &self.path
    }
    /// Frame numbers, strictly increasing.
    pub(crate) fn frames(&self) -> &[i32] {
        &self.frames
    }
    /// Rig names.
    pub(crate) fn rigs(&self) -> &[String] {
        &self.rigs
    }
    /// Cycle names.
    pub(crate) fn cycles(&self) -> &[String] {
        &self.cycles
    }
    /// The frame index (frame, agent count, offset, length).
    pub fn index(&self) -> &[IndexEntry] {
        &self.index
    }

    fn read_entry(&self, e: &IndexEntry) -> Result<FrameBlock> {
        let mut buf = vec![0; e.length as usize];
        {
            let mut file = lock(&self.file);
            file.seek(SeekFrom::Start(e.offset)).at(&self.path)?;
            file.read_exact(&mut buf).at(&self.path)?;
        }
        parse_block(&self.path, &buf, e, self.rigs.len(), self.cycles.len())
    }

    /// Reads and checks one frame's block.
    pub(crate) fn read_frame(&self, frame: i32) -> Result<FrameBlock> {
        match self.frames.binary_search(&frame).ok().and_then(|i| self.index.get(i)) {
            Some(e) => self.read_entry(e),
            None => Err(missing_frame(&self.path, &self.frames, frame)),
        }
    }

    /// Reads every frame.
    pub(crate) fn read_all(&self) -> Result<CrowdCache> {
        let frames = self.index.iter().map(|e| self.read_entry(e)).collect::<Result<Vec<_>>>()?;
        Ok(CrowdCache { rigs: self.rigs.clone(), cycles: self.cycles.clone(), frames })
    }
}

fn push_name(out: &mut Vec<u8>, name: &str) {
    // Names were validated (<= 255 bytes), so the length fits a u16.
    out.extend_from_slice(&(name.len() as u16).to_le_bytes());
    out.extend_from_slice(name.as_bytes());
}

/// Writes `crowd` as a `.crowd` file through [`write_atomic`], after
/// [`super::validate`]; rig and cycle tables are written in first-use order.
/// The output depends only on the crowd.
pub(crate) fn write(path: &Path, crowd: &CrowdCache) -> Result<()> {
    super::validate(path, crowd)?;
    let too_big = |what: &str| Error::invalid(path, format!("too many {what} for one .crowd file"));
    let (rigs, rig_map, cycles, cycle_map) = first_use_tables(crowd);

    let mut meta = Vec::new();
    for name in rigs.iter().chain(&cycles) {
        push_name(&mut meta, name);
    }
    let meta_len = meta.len() as u64 + INDEX_ENTRY_LEN * crowd.frames.len() as u64 + 4;
    let mut offset = HEADER_LEN + meta_len;
    for b in &crowd.frames {
        let agents = u32::try_from(b.agents.len()).map_err(|_| too_big("agents in a frame").frame(b.frame.into()))?;
        let length = BLOCK_OVERHEAD + RECORD_LEN * u64::from(agents);
        meta.extend_from_slice(&b.frame.to_le_bytes());
        meta.extend_from_slice(&agents.to_le_bytes());
        meta.extend_from_slice(&offset.to_le_bytes());
        meta.extend_from_slice(&length.to_le_bytes());
        offset += length;
    }
    meta.extend_from_slice(&crc(&meta).to_le_bytes());

    let mut head = Vec::with_capacity(HEADER_LEN as usize);
    head.extend_from_slice(&MAGIC);
    head.extend_from_slice(&VERSION.to_le_bytes());
    for n in [meta_len, crowd.frames.len() as u64, rigs.len() as u64, cycles.len() as u64] {
        let n = u32::try_from(n).map_err(|_| too_big("frames"))?;
        head.extend_from_slice(&n.to_le_bytes());
    }
    head.extend_from_slice(&crc(&head).to_le_bytes());

    let remap = |map: &[u16], i: u16| map.get(usize::from(i)).copied().unwrap_or(i);
    write_atomic(path, |w| {
        w.write_all(&head).at(path)?;
        w.write_all(&meta).at(path)?;
        let mut buf = Vec::new();
        for b in &crowd.frames {
            buf.clear();
            buf.extend_from_slice(&b.frame.to_le_bytes());
            buf.extend_from_slice(&(b.agents.len() as u32).to_le_bytes());
            for a in &b.agents {
                buf.extend_from_slice(&a.id.to_le_bytes());
                for v in [a.position.x, a.position.y, a.position.z, a.heading] {
                    buf.extend_from_slice(&v.to_le_bytes());
                }
                buf.extend_from_slice(&remap(&rig_map, a.rig).to_le_bytes());
                buf.extend_from_slice(&remap(&cycle_map, a.cycle).to_le_bytes());
                buf.extend_from_slice(&a.cycle_frame.to_le_bytes());
                buf.extend_from_slice(&[a.flags, 0, 0, 0]);
            }
            let sum = crc(&buf);
            buf.extend_from_slice(&sum.to_le_bytes());
            w.write_all(&buf).at(path)?;
        }
        Ok(())
    })
}
