//! What a cache holds: frame range, agent counts, rigs, cycles and bounds
//! (`throng cache info` prints it).

use std::collections::{BTreeMap, HashSet};
use std::fmt::Write as _;

use serde::Serialize;

use super::units::{bounds_warning, Plausible, UnitJudgement};
use super::{CacheReader, CrowdCache, Format};
use crate::error::Result;

/// Usage of one rig or cycle.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct NameCount {
    /// Rig or cycle name.
    pub name: String,
    /// Agent records (agents x frames) using it.
    pub agent_frames: u64,
    /// Distinct agents using it in at least one frame.
    pub agents: usize,
}

/// Axis-aligned bounds of agent positions.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Bounds {
    /// Smallest x, y, z.
    pub min: [f32; 3],
    /// Largest x, y, z.
    pub max: [f32; 3],
}

/// Settings a simulator import used.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ImportInfo {
    /// Rig given to every agent.
    pub rig: String,
    /// Cycle given to every agent.
    pub cycle: String,
    /// Metres per cycle.
    pub stride: f32,
    /// Cycle length in frames.
    pub cycle_length: f32,
    /// Rig glTF the stride and length were read from (`--rig-file`), if any.
    pub rig_file: Option<String>,
}

/// Summary of a cache; the `--json` keys are these field names (documented
/// in docs/cache-format.md; add keys, never rename).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct CacheInfo {
    /// The file.
    pub(crate) file: String,
    /// `crowd`, `csv` or `jupedsim`.
    pub format: String,
    /// First frame, null when the cache is empty.
    pub frame_first: Option<i32>,
    /// Last frame, null when the cache is empty.
    pub frame_last: Option<i32>,
    /// Frames held (may be fewer than the range when frames are skipped).
    pub frames: usize,
    /// Distinct agent ids.
    pub agents: usize,
    /// Agent records over all frames.
    pub agent_frames: u64,
    /// Fewest agents in one frame (0 when empty).
    pub agents_per_frame_min: usize,
    /// Most agents in one frame.
    pub agents_per_frame_max: usize,
    /// Distinct agents seated in at least one frame.
    pub seated_agents: usize,
    /// Seated agent records.
    pub seated_agent_frames: u64,
    /// Hidden agent records.
    pub hidden_agent_frames: u64,
    /// Rigs in table order.
    pub rigs: Vec<NameCount>,
    /// Cycles in table order.
    pub cycles: Vec<NameCount>,
    /// Position bounds, null when there are no agents.
    pub bounds: Option<Bounds>,
    /// Import settings for simulator files, else null.
    pub import: Option<ImportInfo>,
    /// Doubts about the data, e.g. bounds that look like the wrong units.
    pub warnings: Vec<String>,
    /// The likeliest unit of the numbers and its evidence (docs/cache-format.md,
    /// "Units"); null without evidence (too few moving or crowded agents).
    pub units: Option<UnitJudgement>,
}

/// The unit warnings of a crowd in memory ([`super::units`], one rule for
/// every import): the likeliest unit when the case is strong, else bounds
/// or spacing no unit explains.
pub fn bounds_warnings(crowd: &CrowdCache) -> Vec<String> {
    let mut ids = HashSet::new();
    let mut bounds: Option<Bounds> = None;
    for a in crowd.frames.iter().flat_map(|f| f.agents.iter()) {
        ids.insert(a.id);
        let p = a.position.to_array();
        let b = bounds.get_or_insert(Bounds { min: p, max: p });
        b.min = glam::Vec3::from(b.min).min(a.position).to_array();
        b.max = glam::Vec3::from(b.max).max(a.position).to_array();
    }
    let mut plausible = Plausible::new(super::jupedsim::SHOT_FPS);
    for (i, f) in crowd.frames.iter().enumerate() {
        plausible.add(f, Plausible::sampled(crowd.frames.len(), i));
    }
    unit_warnings(plausible, bounds.as_ref(), ids.len()).1
}

/// The judgement and warnings of [`super::units`]: a strong judgement
/// names the unit and stands alone; without one, the hard limits of bounds
/// and spacing speak.
fn unit_warnings(mut p: Plausible, bounds: Option<&Bounds>, agents: usize) -> (Option<UnitJudgement>, Vec<String>) {
    let (judged, mut out) = p.warnings();
    if !judged.as_ref().is_some_and(|j| j.strong) {
        out.splice(0..0, bounds.and_then(|b| bounds_warning(b, agents)));
    }
    (judged, out)
}

/// Summarises a cache, reading one frame at a time.
pub fn info(reader: &CacheReader) -> Result<CacheInfo> {
    let frames = reader.frames();
    let mut ids = HashSet::new();
    let mut seated = HashSet::new();
    let mut rig_agents = HashSet::new();
    let mut cycle_agents = HashSet::new();
    let mut rig_frames = vec![0u64; reader.rigs().len()];
    let mut cycle_frames = vec![0u64; reader.cycles().len()];
    let (mut total, mut seated_frames, mut hidden_frames) = (0u64, 0u64, 0u64);
    let (mut min_n, mut max_n) = (usize::MAX, 0);
    let mut bounds: Option<Bounds> = None;
    let mut plausible = Plausible::new(super::jupedsim::SHOT_FPS);
    for (i, &f) in frames.iter().enumerate() {
        let block = reader.read_frame(f)?;
        plausible.add(&block, Plausible::sampled(frames.len(), i));
        min_n = min_n.min(block.agents.len());
        max_n = max_n.max(block.agents.len());
        for a in &block.agents {
            total += 1;
            ids.insert(a.id);
            if a.seated() {
                seated.insert(a.id);
                seated_frames += 1;
            }
            hidden_frames += u64::from(a.hidden());
            if let Some(n) = rig_frames.get_mut(usize::from(a.rig)) {
                *n += 1;
            }
            if let Some(n) = cycle_frames.get_mut(usize::from(a.cycle)) {
                *n += 1;
            }
            rig_agents.insert((a.rig, a.id));
            cycle_agents.insert((a.cycle, a.id));
            let p = a.position.to_array();
            let b = bounds.get_or_insert(Bounds { min: p, max: p });
            b.min = glam::Vec3::from(b.min).min(a.position).to_array();
            b.max = glam::Vec3::from(b.max).max(a.position).to_array();
        }
    }
    let counts = |names: &[String], frames: &[u64], pairs: &HashSet<(u16, u32)>| {
        let mut agents: BTreeMap<u16, usize> = BTreeMap::new();
        for (i, _) in pairs {
            *agents.entry(*i).or_default() += 1;
        }
        names
            .iter()
            .enumerate()
            .map(|(i, name)| NameCount {
                name: name.clone(),
                agent_frames: frames.get(i).copied().unwrap_or(0),
                agents: u16::try_from(i).ok().and_then(|i| agents.get(&i)).copied().unwrap_or(0),
            })
            .collect()
    };
    let path = reader.path();
    let (units, warnings) = unit_warnings(plausible, bounds.as_ref(), ids.len());
    Ok(CacheInfo {
        file: path.display().to_string(),
        format: Format::of(path).map(Format::name).unwrap_or("unknown").to_string(),
        frame_first: frames.first().copied(),
        frame_last: frames.last().copied(),
        frames: frames.len(),
        agents: ids.len(),
        agent_frames: total,
        agents_per_frame_min: if frames.is_empty() { 0 } else { min_n },
        agents_per_frame_max: max_n,
        seated_agents: seated.len(),
        seated_agent_frames: seated_frames,
        hidden_agent_frames: hidden_frames,
        rigs: counts(reader.rigs(), &rig_frames, &rig_agents),
        cycles: counts(reader.cycles(), &cycle_frames, &cycle_agents),
        units,
        warnings,
        bounds,
        import: None,
    })
}

impl CacheInfo {
    /// Short, aligned text for humans.
    pub fn to_text(&self) -> String {
        let mut s = String::new();
        let mut line = |k: &str, v: String| {
            let _ = writeln!(s, "{k:<8} {v}");
        };
        line("file", format!("{} ({})", self.file, self.format));
        line(
            "frames",
            match (self.frame_first, self.frame_last) {
                (Some(a), Some(b)) => format!("{a}-{b} ({} frames)", self.frames),
                _ => "none".into(),
            },
        );
        line(
            "agents",
            format!(
                "{} ({}-{} per frame, {} agent-frames)",
                self.agents, self.agents_per_frame_min, self.agents_per_frame_max, self.agent_frames
            ),
        );
        line(
            "seated",
            format!(
                "{} agents ({} agent-frames); hidden {} agent-frames",
                self.seated_agents, self.seated_agent_frames, self.hidden_agent_frames
            ),
        );
        if let Some(b) = &self.bounds {
            line(
                "bounds",
                format!(
                    "x {:.2}..{:.2}  y {:.2}..{:.2}  z {:.2}..{:.2} m",
                    b.min[0], b.max[0], b.min[1], b.max[1], b.min[2], b.max[2]
                ),
            );
        }
        if let Some(u) = &self.units {
            let strength = if u.strong || u.scale == 1.0 { "" } else { ", not strong enough to warn" };
            line("units", format!("likeliest {}{strength}: {}", u.likeliest, u.evidence));
        }
        let w = self.rigs.iter().chain(&self.cycles).map(|n| n.name.len()).max().unwrap_or(0);
        for (key, list) in [("rigs", &self.rigs), ("cycles", &self.cycles)] {
            for (i, n) in list.iter().enumerate() {
                let k = if i == 0 { key } else { "" };
                line(k, format!("{:<w$}  {:>9} agent-frames  {:>6} agents", n.name, n.agent_frames, n.agents));
            }
            if list.is_empty() {
                line(key, "none".into());
            }
        }
        s
    }
}
