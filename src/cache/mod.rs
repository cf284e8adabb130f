//! Simulation caches: per-frame agent states, read from our binary format,
//! CSV, or a real simulator's output, into a [`Crowd`].
//!
//! INTERFACE (shared by every stage; keep these types stable):
//! - [`AgentRecord`], [`FrameBlock`], [`Crowd`] are the in-memory model.
//! - `read(path) -> Result<Crowd>` and `write(path, &Crowd) -> Result<()>`
//!   choose the format by extension.
//! - `CacheReader::open(path)` gives random access to single frames.

use glam::Vec3;

/// Flag bit: the agent is seated (never height-scaled).
pub const SEATED: u8 = 1;
/// Flag bit: the agent is hidden in this frame (not rendered).
pub const HIDDEN: u8 = 2;

/// One agent in one frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AgentRecord {
    /// Stable id, never renumbered.
    pub id: u32,
    /// Foot position in metres, Y up.
    pub position: Vec3,
    /// Radians about +Y; 0 faces +Z.
    pub heading: f32,
    /// Index into [`Crowd::rigs`].
    pub rig: u16,
    /// Index into [`Crowd::cycles`].
    pub cycle: u16,
    /// Frame within the cycle (fractional, in frames at the shot fps).
    pub cycle_frame: f32,
    /// [`SEATED`] | [`HIDDEN`].
    pub flags: u8,
}

impl AgentRecord {
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
    pub agents: Vec<AgentRecord>,
}

/// A whole simulation cache in memory.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Crowd {
    /// Rig names, indexed by [`AgentRecord::rig`].
    pub rigs: Vec<String>,
    /// Cycle names, indexed by [`AgentRecord::cycle`].
    pub cycles: Vec<String>,
    /// Frames in strictly increasing order.
    pub frames: Vec<FrameBlock>,
}
