//! Simulation caches: per-frame agent states, read from our binary format,
//! CSV, or a real simulator's output, into a [`CrowdCache`].
//!
//! INTERFACE (shared by every stage; keep these types stable):
//! - [`AgentSample`], [`FrameBlock`], [`CrowdCache`] are the in-memory model.
//! - `read(path) -> Result<CrowdCache>` and `write(path, &CrowdCache) -> Result<()>`
//!   choose the format by extension.
//! - `CacheReader::open(path)` gives random access to single frames.

use glam::Vec3;

/// Flag bit: the agent is seated (never height-scaled).
pub const SEATED: u8 = 1;
/// Flag bit: the agent is hidden in this frame (not rendered).
pub const HIDDEN: u8 = 2;

/// One agent in one frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AgentSample {
    /// Stable id, never renumbered.
    pub id: u32,
    /// Foot position in metres, Y up.
    pub position: Vec3,
    /// Radians about +Y; 0 faces +Z.
    pub heading: f32,
    /// Index into [`CrowdCache::rigs`].
    pub rig: u16,
    /// Index into [`CrowdCache::cycles`].
    pub cycle: u16,
    /// Frame within the cycle (fractional, in frames at the shot fps).
    pub cycle_frame: f32,
    /// [`SEATED`] | [`HIDDEN`].
    pub flags: u8,
}

impl AgentSample {
    /// Whether the agent is seated.
    pub fn seated(&self) -> bool {
        self.flags & SEATED != 0
    }
    /// Whether the agent is hidden.
    pub fn hidden(&self) -> bool {
        self.flags & HIDDEN != 0
    }
}

/// Every agent present at one cache frame.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FrameBlock {
    /// Cache frame number.
    pub frame: i32,
    /// Agents in cache order; ids are unique within a frame.
    pub agents: Vec<AgentSample>,
}

/// A whole simulation cache in memory.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct CrowdCache {
    /// Rig names, indexed by [`AgentSample::rig`].
    pub rigs: Vec<String>,
    /// Cycle names, indexed by [`AgentSample::cycle`].
    pub cycles: Vec<String>,
    /// Frames in strictly increasing order.
    pub frames: Vec<FrameBlock>,
}

// ---------------------------------------------------------------------------
// Formats, readers and checks (added by the cache stage; the types above are
// the shared interface).

pub mod binary;
pub(crate) mod csv;
mod info;
pub(crate) mod jupedsim;
pub mod keys;
pub mod tabular;
mod tabular_options;
mod units;
pub(crate) mod usd;
pub(crate) mod usdskel;
pub(crate) mod usdskel_mesh;
pub(crate) mod usdskel_track;

use std::collections::HashSet;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use crate::error::{Error, Result};

pub use info::{bounds_warnings, info, Bounds, CacheInfo, ImportInfo, NameCount};
pub use jupedsim::{ImportOptions, RigClip};
pub use tabular::{place, Placement, TabularOptions, TabularReport, TabularSpec};
pub(crate) use units::bounds_warning;
pub use units::UnitJudgement;

/// Longest rig or cycle name, in UTF-8 bytes.
pub(crate) const MAX_NAME_LEN: usize = 255;

/// A cache file format, chosen by file extension (a `.gz` suffix is looked
/// through: `a.csv.gz` is CSV, `a.txt.gz` a table).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Format {
    /// `.crowd`: our binary format (docs/cache-format.md).
    Binary,
    /// `.csv`: one row per agent per frame (or, with a layout, a table).
    Csv,
    /// `.sqlite` (also `.sqlite3`, `.db`): JuPedSim trajectories, read only.
    JuPedSim,
    /// `.txt`, `.tsv`, `.dat`: a trajectory table, read with a preset or
    /// columns ([`TabularOptions`]), read only.
    Tabular,
    /// `.usd`, `.usda`, `.usdc`, `.usdz`: a USD crowd, read only (docs/usd.md).
    Usd,
}

impl Format {
    /// The format of `path`, from its extension (case-insensitive).
    pub fn of(path: &Path) -> Result<Format> {
        let lower = |p: &Path| p.extension().map(|e| e.to_string_lossy().to_ascii_lowercase());
        let mut ext = lower(path);
        let gz = ext.as_deref() == Some("gz");
        if gz {
            ext = path.file_stem().and_then(|s| lower(Path::new(s)));
        }
        match ext.as_deref() {
            Some("crowd") if !gz => Ok(Format::Binary),
            Some("csv") => Ok(Format::Csv),
            Some("sqlite" | "sqlite3" | "db") if !gz => Ok(Format::JuPedSim),
            Some("txt" | "tsv" | "dat" | "ssv") => Ok(Format::Tabular),
            Some("usd" | "usda" | "usdc" | "usdz") if !gz => Ok(Format::Usd),
            Some("crowd" | "sqlite" | "sqlite3" | "db") => Err(Error::Usage(format!(
                "{}: a gzipped .crowd or SQLite file cannot be read in place; gunzip it first",
                path.display()
            ))),
            _ => Err(Error::Usage(format!(
                "{}: unknown cache format; expected a .crowd, .csv, .sqlite (JuPedSim) or .usd/.usda/.usdc/.usdz file, \
                 or a trajectory table (.txt, .tsv, .dat, optionally .gz) with a preset or columns",
                path.display()
            ))),
        }
    }

    /// Short name used in `cache info`.
    pub fn name(self) -> &'static str {
        match self {
            Format::Binary => "crowd",
            Format::Csv => "csv",
            Format::JuPedSim => "jupedsim",
            Format::Tabular => "table",
            Format::Usd => "usd",
        }
    }
}

/// How any cache file becomes a crowd: JuPedSim options, the table layout
/// (when the file is a foreign table) and where the crowd stands.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Import {
    /// JuPedSim import options (rig, cycle, stride).
    pub jupedsim: ImportOptions,
    /// Read the file as a table with these options (any extension but
    /// `.crowd` and `.sqlite`); `None`: by extension.
    pub tabular: Option<TabularOptions>,
    /// Placement for caches that are not tables (tables place themselves
    /// through [`TabularOptions::placement`]).
    pub placement: Placement,
}

/// The error for a table read without a preset or columns.
pub fn needs_layout(path: &Path) -> Error {
    Error::Usage(format!(
        "{}: a trajectory table needs its layout: a preset (petrack, eth, eth-ucy) or columns \
         (see docs/cache-format.md, \"Tabular import\")",
        path.display()
    ))
}

/// Reads a whole cache; the format comes from the extension. JuPedSim files
/// are imported with [`ImportOptions::default`].
pub fn read(path: impl AsRef<Path>) -> Result<CrowdCache> {
    read_with(path, &ImportOptions::default())
}

/// Reads a whole cache, importing simulator files with `opts`.
pub fn read_with(path: impl AsRef<Path>, opts: &ImportOptions) -> Result<CrowdCache> {
    Ok(import(path, &Import { jupedsim: opts.clone(), ..Default::default() })?.0)
}

/// Reads a whole cache as `how` says, with the table import's report.
pub fn import(path: impl AsRef<Path>, how: &Import) -> Result<(CrowdCache, Option<TabularReport>)> {
    let path = path.as_ref();
    crate::error::check_readable_file(path)?;
    let format = Format::of(path)?;
    if let (Some(t), Format::Csv | Format::Tabular) = (&how.tabular, format) {
        let (crowd, report) = tabular::read(path, t)?;
        return Ok((crowd, Some(report)));
    }
    let mut crowd = match format {
        Format::Binary => binary::read(path)?,
        Format::Csv => csv::read(path)?,
        Format::JuPedSim => jupedsim::read(path, &how.jupedsim)?,
        // One opening of the stage when it is a UsdSkel crowd.
        Format::Usd => match usdskel::read(path, &how.jupedsim)? {
            Some(crowd) => crowd,
            None => usd::read(path, &how.jupedsim)?,
        },
        Format::Tabular => return Err(needs_layout(path)),
    };
    place(&mut crowd, &how.placement);
    Ok((crowd, None))
}

/// Writes a whole cache atomically (never a partial file under `path`); the
/// format comes from the extension. The crowd is validated first. Binary
/// files store the rig and cycle tables in order of first use (see
/// [`first_use_tables`]), so `read(write(c)) == c` when `c` is already in
/// that order.
pub fn write(path: impl AsRef<Path>, crowd: &CrowdCache) -> Result<()> {
    let path = path.as_ref();
    match Format::of(path)? {
        Format::Binary => binary::write(path, crowd),
        Format::Csv => csv::write(path, crowd),
        Format::JuPedSim | Format::Tabular | Format::Usd => Err(Error::Usage(format!(
            "{}: {} files are read only; write a .crowd or .csv cache",
            path.display(),
            Format::of(path).map(Format::name).unwrap_or_default()
        ))),
    }
}

/// Random access to a cache's frames. Binary caches read only the header and
/// index on open and one block per [`CacheReader::read_frame`]; CSV and
/// JuPedSim files are read whole into memory.
#[derive(Debug)]
pub enum CacheReader {
    /// A `.crowd` file, read frame by frame.
    Binary(binary::BinaryReader),
    /// A cache held in memory.
    Memory {
        /// The file it came from (for error messages).
        path: PathBuf,
        /// The crowd.
        crowd: CrowdCache,
        /// Its frame numbers, for [`CacheReader::frames`].
        frames: Vec<i32>,
    },
}

impl CacheReader {
    /// Opens a cache; the format comes from the extension.
    pub fn open(path: impl AsRef<Path>) -> Result<CacheReader> {
        Self::open_with(path, &ImportOptions::default())
    }

    /// Opens a cache, importing simulator files with `opts`.
    pub(crate) fn open_with(path: impl AsRef<Path>, opts: &ImportOptions) -> Result<CacheReader> {
        Self::open_import(path, &Import { jupedsim: opts.clone(), ..Default::default() })
    }

    /// Opens a cache as `how` says. A `.crowd` file placed nowhere keeps
    /// frame-by-frame reading; anything else is read whole.
    pub(crate) fn open_import(path: impl AsRef<Path>, how: &Import) -> Result<CacheReader> {
        let path = path.as_ref();
        crate::error::check_readable_file(path)?;
        if Format::of(path)? == Format::Binary && how.placement.is_identity() {
            return Ok(CacheReader::Binary(binary::BinaryReader::open(path)?));
        }
        Ok(Self::from_crowd(path, import(path, how)?.0))
    }

    /// Opens a USD cache as [`CacheReader::open_import`] does, keeping, when
    /// it is a UsdSkel crowd, that one reading of the stage with its
    /// characters' meshes (for the shot's rigs on the same file).
    pub(crate) fn open_usd_skel(path: &Path, how: &Import) -> Result<(CacheReader, Option<usdskel::SkelFile>)> {
        crate::error::check_readable_file(path)?;
        let (mut crowd, file) = match usdskel::read_stage(path, Some(&how.jupedsim), true)? {
            Some(usdskel::SkelRead { crowd: Some(crowd), file }) => (crowd, Some(file)),
            _ => (usd::read(path, &how.jupedsim)?, None),
        };
        place(&mut crowd, &how.placement);
        Ok((Self::from_crowd(path, crowd), file))
    }

    /// Wraps an in-memory crowd (already validated) that came from `path`.
    pub fn from_crowd(path: impl Into<PathBuf>, crowd: CrowdCache) -> CacheReader {
        let frames = crowd.frames.iter().map(|b| b.frame).collect();
        CacheReader::Memory { path: path.into(), crowd, frames }
    }

    /// Frame numbers, strictly increasing.
    pub fn frames(&self) -> &[i32] {
        match self {
            CacheReader::Binary(r) => r.frames(),
            CacheReader::Memory { frames, .. } => frames,
        }
    }

    /// Rig names, indexed by [`AgentSample::rig`].
    pub fn rigs(&self) -> &[String] {
        match self {
            CacheReader::Binary(r) => r.rigs(),
            CacheReader::Memory { crowd, .. } => &crowd.rigs,
        }
    }

    /// Cycle names, indexed by [`AgentSample::cycle`].
    pub fn cycles(&self) -> &[String] {
        match self {
            CacheReader::Binary(r) => r.cycles(),
            CacheReader::Memory { crowd, .. } => &crowd.cycles,
        }
    }

    /// The file this reader reads.
    pub(crate) fn path(&self) -> &Path {
        match self {
            CacheReader::Binary(r) => r.path(),
            CacheReader::Memory { path, .. } => path,
        }
    }

    /// One frame's agents. A frame the cache does not hold is an error.
    pub fn read_frame(&self, frame: i32) -> Result<FrameBlock> {
        match self {
            CacheReader::Binary(r) => r.read_frame(frame),
            CacheReader::Memory { path, crowd, frames } => match frames.binary_search(&frame) {
                Ok(i) => crowd.frames.get(i).cloned().ok_or_else(|| missing_frame(path, frames, frame)),
                Err(_) => Err(missing_frame(path, frames, frame)),
            },
        }
    }

    /// Reads every frame into a [`CrowdCache`].
    pub fn read_all(&self) -> Result<CrowdCache> {
        match self {
            CacheReader::Binary(r) => r.read_all(),
            CacheReader::Memory { crowd, .. } => Ok(crowd.clone()),
        }
    }
}

/// The error for asking a cache for a frame it does not hold.
pub(crate) fn missing_frame(path: impl AsRef<Path>, frames: &[i32], frame: i32) -> Error {
    let range = match (frames.first(), frames.last()) {
        (Some(a), Some(b)) => format!("the cache holds frames {a}-{b}"),
        _ => "the cache holds no frames".to_string(),
    };
    Error::invalid(path, format!("no frame {frame}: {range}")).frame(frame.into())
}

/// Checks a rig or cycle name: names travel through CSV unquoted, so they
/// may not hold commas, quotes or control characters.
pub(crate) fn check_name(name: &str) -> std::result::Result<(), String> {
    if name.is_empty() {
        return Err("empty name".into());
    }
    if name.len() > MAX_NAME_LEN {
        return Err(format!("name longer than {MAX_NAME_LEN} bytes"));
    }
    if name.trim() != name {
        return Err(format!("name `{name}` has leading or trailing spaces"));
    }
    if name.chars().any(|c| c == ',' || c == '"' || c.is_control()) {
        return Err(format!("name `{}` holds a comma, quote or control character", name.escape_debug()));
    }
    Ok(())
}

/// Checks a rig or cycle table: valid, unique names that fit a u16 index.
pub(crate) fn validate_names(path: &Path, kind: &str, names: &[String]) -> Result<()> {
    if names.len() > usize::from(u16::MAX) + 1 {
        return Err(Error::invalid(path, format!("{} {kind} names; at most 65536 fit a u16 index", names.len())));
    }
    let mut seen = HashSet::new();
    for name in names {
        check_name(name).map_err(|m| Error::invalid(path, format!("bad {kind} name: {m}")).field(kind))?;
        if !seen.insert(name.as_str()) {
            return Err(Error::invalid(path, format!("{kind} name `{name}` appears twice in the table")).field(kind));
        }
    }
    Ok(())
}

/// Checks one agent record: finite numbers, known rig and cycle, no
/// reserved flag bits. The error names the frame and agent.
pub(crate) fn validate_record(path: &Path, frame: i32, a: &AgentSample, rigs: usize, cycles: usize) -> Result<()> {
    let bad = |msg: String, field: &str| Err(Error::invalid(path, msg).frame(frame.into()).agent(a.id).field(field));
    for (v, field) in [(a.position.x, "x"), (a.position.y, "y"), (a.position.z, "z")] {
        if !v.is_finite() {
            return bad(format!("position {field} is {v}; positions must be finite"), field);
        }
    }
    if !a.heading.is_finite() {
        return bad(format!("heading is {}; it must be finite", a.heading), "heading");
    }
    if !a.cycle_frame.is_finite() {
        return bad(format!("cycle frame is {}; it must be finite", a.cycle_frame), "cycle_frame");
    }
    if usize::from(a.rig) >= rigs {
        return bad(format!("unknown rig index {} (the cache names {rigs} rigs)", a.rig), "rig");
    }
    if usize::from(a.cycle) >= cycles {
        return bad(format!("unknown cycle index {} (the cache names {cycles} cycles)", a.cycle), "cycle");
    }
    if a.flags & !(SEATED | HIDDEN) != 0 {
        return bad(format!("unknown flag bits {:#04x} (only seated=1, hidden=2 exist)", a.flags), "flags");
    }
    Ok(())
}

/// Checks one frame: every record, and no agent id twice.
pub(crate) fn validate_frame(path: &Path, block: &FrameBlock, rigs: usize, cycles: usize) -> Result<()> {
    let mut ids = HashSet::with_capacity(block.agents.len());
    for a in &block.agents {
        validate_record(path, block.frame, a, rigs, cycles)?;
        if !ids.insert(a.id) {
            return Err(Error::invalid(path, format!("agent {} appears twice in frame {}", a.id, block.frame))
                .frame(block.frame.into())
                .agent(a.id));
        }
    }
    Ok(())
}

/// Checks frame order: strictly increasing. `frames` yields frame numbers.
pub(crate) fn validate_frame_order(path: &Path, frames: impl IntoIterator<Item = i32>) -> Result<()> {
    let mut prev: Option<i32> = None;
    for f in frames {
        if let Some(p) = prev {
            if f <= p {
                return Err(
                    Error::invalid(path, format!("frame {f} follows frame {p}; frames must increase")).frame(f.into())
                );
            }
        }
        prev = Some(f);
    }
    Ok(())
}

/// The checks every reader (and [`write`]) applies: names, frame order, and
/// every frame's records. `path` names the file in errors.
pub(crate) fn validate(path: &Path, crowd: &CrowdCache) -> Result<()> {
    validate_names(path, "rig", &crowd.rigs)?;
    validate_names(path, "cycle", &crowd.cycles)?;
    validate_frame_order(path, crowd.frames.iter().map(|b| b.frame))?;
    for block in &crowd.frames {
        validate_frame(path, block, crowd.rigs.len(), crowd.cycles.len())?;
    }
    Ok(())
}

/// Rig and cycle tables in order of first use (frames in order, agents in
/// cache order), dropping unused names, with old-index -> new-index maps.
/// This is the order CSV can reproduce, so binary -> CSV -> binary is
/// byte-identical. Assumes a validated crowd (indices in range).
pub(crate) fn first_use_tables(crowd: &CrowdCache) -> (Vec<String>, Vec<u16>, Vec<String>, Vec<u16>) {
    fn table(names: &[String], used: impl Iterator<Item = u16>) -> (Vec<String>, Vec<u16>) {
        let mut map = vec![u16::MAX; names.len()];
        let mut out = Vec::new();
        for old in used {
            if let Some(slot) = map.get_mut(usize::from(old)) {
                if *slot == u16::MAX && out.len() <= usize::from(u16::MAX) {
                    *slot = out.len() as u16;
                    out.push(names.get(usize::from(old)).cloned().unwrap_or_default());
                }
            }
        }
        (out, map)
    }
    let agents = || crowd.frames.iter().flat_map(|b| b.agents.iter());
    let (rigs, rig_map) = table(&crowd.rigs, agents().map(|a| a.rig));
    let (cycles, cycle_map) = table(&crowd.cycles, agents().map(|a| a.cycle));
    (rigs, rig_map, cycles, cycle_map)
}

/// `crowd` with its rig and cycle tables in first-use order (what a `.crowd`
/// file stores). Assumes a validated crowd.
pub fn canonical(crowd: &CrowdCache) -> CrowdCache {
    let (rigs, rig_map, cycles, cycle_map) = first_use_tables(crowd);
    let remap = |map: &[u16], i: u16| map.get(usize::from(i)).copied().unwrap_or(i);
    let frames = crowd
        .frames
        .iter()
        .map(|b| FrameBlock {
            frame: b.frame,
            agents: b
                .agents
                .iter()
                .map(|a| AgentSample { rig: remap(&rig_map, a.rig), cycle: remap(&cycle_map, a.cycle), ..*a })
                .collect(),
        })
        .collect();
    CrowdCache { rigs, cycles, frames }
}

/// A poisoned lock still holds a usable file handle.
pub(crate) fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|e| e.into_inner())
}
