//! What a cache holds: frame range, agent counts, rigs, cycles and bounds
//! (`throng cache info` prints it).

use std::collections::{BTreeMap, HashMap, HashSet};
use std::fmt::Write as _;

use serde::Serialize;

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
}

/// Widest plausible crowd, metres: wider looks like centimetres (or feet)
/// read as metres.
pub(crate) const MAX_PLAUSIBLE_WIDTH: f32 = 2000.0;
/// Narrowest plausible spread of [`MIN_AGENTS_FOR_SPREAD`] or more agents, metres.
pub(crate) const MIN_PLAUSIBLE_SPREAD: f32 = 0.5;
/// Agents needed before a small spread is suspicious.
pub(crate) const MIN_AGENTS_FOR_SPREAD: usize = 10;

/// A warning when bounds look like the wrong units: a crowd wider than
/// [`MAX_PLAUSIBLE_WIDTH`] or many agents packed in less than
/// [`MIN_PLAUSIBLE_SPREAD`].
pub(crate) fn bounds_warning(b: &Bounds, agents: usize) -> Option<String> {
    let (w, d) = (b.max[0] - b.min[0], b.max[2] - b.min[2]);
    let wide = w.max(d);
    let at = format!("x {:.1}..{:.1}, z {:.1}..{:.1}", b.min[0], b.max[0], b.min[2], b.max[2]);
    if !wide.is_finite() || wide > MAX_PLAUSIBLE_WIDTH {
        return Some(format!(
            "the crowd is {wide:.0} m wide ({at}): wider than {:.0} km, so the units look wrong \
             (centimetres read as metres? set the cache's units, e.g. units = \"cm\")",
            MAX_PLAUSIBLE_WIDTH / 1000.0
        ));
    }
    if agents >= MIN_AGENTS_FOR_SPREAD && wide < MIN_PLAUSIBLE_SPREAD {
        return Some(format!(
            "{agents} agents stand within {wide:.3} m ({at}): the units look wrong (metres read as millimetres?)"
        ));
    }
    None
}

/// Plausible median walking speed of people, m/s.
pub(crate) const PLAUSIBLE_SPEED: (f32, f32) = (0.2, 3.0);
/// Closest two people stand, metres.
pub(crate) const MIN_SPACING: f32 = 0.2;
/// Frames the spacing check samples, evenly spread (bounds its cost).
const SPACING_FRAMES: usize = 32;
/// Most speed samples kept for the median.
const MAX_SPEED_SAMPLES: usize = 4_000_000;

/// Speeds and spacing of people, gathered frame by frame for [`Plausible::warnings`].
#[derive(Default)]
pub(crate) struct Plausible {
    last: HashMap<u32, (i32, glam::Vec3)>,
    speeds: Vec<f32>,
    checked: usize,
    crowded: usize,
}

impl Plausible {
    /// Adds one frame; `sample` says whether its spacing is checked. Speeds
    /// count frames at the shot's 24 fps; only moving agents count.
    pub(crate) fn add(&mut self, block: &super::FrameBlock, sample: bool) {
        for a in block.agents.iter().filter(|a| !a.seated() && !a.hidden()) {
            if let Some((f, p)) = self.last.insert(a.id, (block.frame, a.position)) {
                let d = (a.position - p).with_y(0.0).length();
                if f + 1 == block.frame && d > 1e-6 && self.speeds.len() < MAX_SPEED_SAMPLES {
                    self.speeds.push(d * super::jupedsim::SHOT_FPS);
                }
            }
        }
        if !sample || block.agents.len() < MIN_AGENTS_FOR_SPREAD {
            return;
        }
        // A grid of MIN_SPACING cells: a closer neighbour is in the 3 x 3 cells around.
        let cell = |p: glam::Vec3| ((p.x / MIN_SPACING).floor() as i64, (p.z / MIN_SPACING).floor() as i64);
        let mut grid: HashMap<(i64, i64), Vec<glam::Vec3>> = HashMap::new();
        for a in &block.agents {
            grid.entry(cell(a.position)).or_default().push(a.position);
        }
        for a in &block.agents {
            let (cx, cz) = cell(a.position);
            self.checked += 1;
            let near = (-1..=1).flat_map(|dx| (-1..=1).map(move |dz| (cx + dx, cz + dz))).any(|c| {
                grid.get(&c).is_some_and(|ps| {
                    ps.iter().any(|q| {
                        let d = (*q - a.position).with_y(0.0).length();
                        d > 0.0 && d < MIN_SPACING
                    })
                })
            });
            self.crowded += usize::from(near);
        }
    }

    /// Which frames of `frames` the spacing check samples.
    pub(crate) fn sampled(frames: usize, i: usize) -> bool {
        frames <= SPACING_FRAMES || i.is_multiple_of(frames.div_ceil(SPACING_FRAMES))
    }

    /// Warnings naming the likely unit when speeds or spacing are not a person's.
    pub(crate) fn warnings(mut self) -> Vec<String> {
        let mut out = Vec::new();
        if self.speeds.len() >= 20 {
            let mid = self.speeds.len() / 2;
            let median = *self.speeds.select_nth_unstable_by(mid, f32::total_cmp).1;
            let (lo, hi) = PLAUSIBLE_SPEED;
            let unit = if median > hi * 300.0 {
                Some("millimetres? set units = \"mm\"")
            } else if median > hi * 10.0 {
                Some("centimetres? set units = \"cm\"")
            } else if median > hi {
                Some("feet? set units = \"ft\"; or a wrong source_fps")
            } else if median < lo {
                Some("metres read as a smaller unit? check units")
            } else {
                None
            };
            if let Some(unit) = unit {
                out.push(format!(
                    "median walking speed {median:.3} m/s (at 24 fps), outside the {lo}-{hi} m/s of people: is the data in {unit}"
                ));
            }
        }
        if self.checked > 0 && self.crowded * 10 > self.checked {
            out.push(format!(
                "{} of {} sampled agents stand closer than {MIN_SPACING} m to another: closer than people stand; \
                 is the data in a smaller unit than it is read in (metres read as centimetres?)",
                self.crowded, self.checked
            ));
        }
        out
    }
}

/// [`bounds_warning`] for a crowd in memory.
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
    let mut plausible = Plausible::default();
    for (i, f) in crowd.frames.iter().enumerate() {
        plausible.add(f, Plausible::sampled(crowd.frames.len(), i));
    }
    let mut out: Vec<String> = bounds.and_then(|b| bounds_warning(&b, ids.len())).into_iter().collect();
    out.extend(plausible.warnings());
    out
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
    let mut plausible = Plausible::default();
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
        warnings: bounds
            .as_ref()
            .and_then(|b| bounds_warning(b, ids.len()))
            .into_iter()
            .chain(plausible.warnings())
            .collect(),
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
