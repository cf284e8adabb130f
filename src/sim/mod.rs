//! Reference crowd simulation: the steering model of the Robots crowd system
//! (Patterson 2005), so a lighter or a test can make a cache without a crowd
//! department. `throng sim SCENE.toml --out FILE` reads a scene file, runs
//! [`run`] and writes the [`CrowdCache`] with `cache::write`.
//!
//! The per-frame algorithm, the scene file and the conventions are in
//! docs/sim.md. In short: every frame each walking agent sums weighted,
//! signed repulsions from nearby agents (found with a uniform [`grid::Grid`]),
//! obstacles and walls, adds a turn towards its current target, turns at most
//! the (relaxed) limit, and walks one frame of its cycle's stride. Each
//! frame's state is computed from the previous frame's state only, so the
//! result is identical for any thread count.

pub mod grid;
mod rng;
pub mod steer;

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::{Path, PathBuf};

use glam::{Vec2, Vec3};
use rayon::prelude::*;
use serde::Deserialize;

use crate::cache::{AgentSample, CrowdCache, FrameBlock, SEATED};
use crate::error::{Error, IoContext, Result};
use rng::Purpose;
use steer::{forward, heading_of, wrap_angle, Steer};

/// Most targets a scene may declare (each agent keeps its visited targets
/// in a 64-bit mask).
pub const MAX_TARGETS: usize = 64;
/// Most agents in a scene (a guard against typos such as `count = 1e9`).
pub const MAX_AGENTS: usize = 10_000_000;
/// Most frames a scene may simulate (warm-up included).
pub const MAX_FRAMES: i64 = 1_000_000;
/// Frames per second when `[frames] fps` is not given (SPEC: shot fps 24).
pub const DEFAULT_FPS: f32 = 24.0;
/// Most (rig, cycle) pairs a scene may have (the timing table's size).
pub const MAX_RIG_CYCLES: usize = 1 << 20;

// ---------------------------------------------------------------------------
// Resolved scene
// ---------------------------------------------------------------------------

/// Constants of the steering model; the defaults are the paper's.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Model {
    /// Largest turn per frame away from objects, radians (5 degrees).
    pub max_turn: f32,
    /// Gap (metres) under which the turn limit relaxes: the paper's 5 units.
    pub relax_distance: f32,
    /// Metres per unit of `d` in `D(d) = 1 / 2^d` (1: d in metres).
    pub falloff: f32,
    /// Power `D` is raised to for agents, obstacles and walls (12).
    pub power: f32,
    /// Slowest walk near objects, as a fraction of the cycle's speed (0.9).
    pub min_speed: f32,
    /// Agent radius (metres) when an agent gives none.
    pub agent_radius: f32,
    /// Attenuate other agents by chase (the paper's model; off only to
    /// show the shaking it prevents).
    pub chase: bool,
}

impl Default for Model {
    fn default() -> Self {
        Model {
            max_turn: 5f32.to_radians(),
            relax_distance: 5.0,
            falloff: 1.0,
            power: 12.0,
            min_speed: 0.9,
            agent_radius: 0.3,
            chase: true,
        }
    }
}

/// An animation cycle as the simulation sees it: its name and what follows
/// it. Its length and stride depend on the rig ([`SimScene::timing`]).
#[derive(Clone, Debug, PartialEq)]
pub struct Cycle {
    /// Name, as in the rigs' animations.
    pub name: String,
    /// Explicit length in frames (`[cycles.X] length`), for rigs without a file.
    pub length: Option<f32>,
    /// Explicit stride in metres (`[cycles.X] stride`), for rigs without a file.
    pub stride: Option<f32>,
    /// Cycles to switch to when this one ends: (cycle index, weight).
    /// Empty: the agent stays on this cycle.
    pub next: Vec<(u16, f32)>,
}

/// Length and stride of one cycle on one rig: from the rig's glTF file, or
/// the scene's explicit `[cycles.X]` values for a rig without a file.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CycleTiming {
    /// Length in frames at the scene's fps.
    pub length: f32,
    /// Metres walked per cycle (root Z travel); 0 for idle and sit cycles.
    pub stride: f32,
}

impl CycleTiming {
    /// Forward travel per frame at full speed (stride / length).
    pub fn travel(&self) -> f32 {
        self.stride / self.length
    }
    /// Whether agents on this cycle walk.
    pub fn moves(&self) -> bool {
        self.stride > 0.0
    }
}

/// A goal agents walk to.
#[derive(Clone, Debug, PartialEq)]
pub struct Target {
    /// Name agents refer to it by.
    pub name: String,
    /// Ground-plane position `(x, z)`.
    pub position: Vec2,
    /// Reached within this distance (metres).
    pub radius: f32,
}

/// A circular obstacle (a cylinder), possibly moving.
#[derive(Clone, Debug, PartialEq)]
pub struct Obstacle {
    /// Radius in metres.
    pub radius: f32,
    /// Centre keys `(frame, (x, z))` in increasing frame order, at least one;
    /// linear between keys, held before the first and after the last.
    pub path: Vec<(i32, Vec2)>,
}

impl Obstacle {
    /// Centre at `frame`.
    pub fn center_at(&self, frame: i32) -> Vec2 {
        let Some(&(f0, c0)) = self.path.first() else { return Vec2::ZERO };
        if frame <= f0 {
            return c0;
        }
        for w in self.path.windows(2) {
            let ((fa, a), (fb, b)) = (w[0], w[1]);
            if frame <= fb {
                // i64: frame numbers may be far apart without overflowing.
                let t = ((i64::from(frame) - i64::from(fa)) as f64 / (i64::from(fb) - i64::from(fa)) as f64) as f32;
                return a.lerp(b, t);
            }
        }
        self.path.last().map_or(c0, |k| k.1)
    }
}

/// Shape of a wall on the ground plane.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum WallShape {
    /// A segment between two points.
    Segment(Vec2, Vec2),
    /// An infinite line through `point` with unit `normal` (a vertical plane).
    Plane {
        /// A point on the line.
        point: Vec2,
        /// Unit normal.
        normal: Vec2,
    },
}

/// A wall: segment or plane, thickened by `radius`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Wall {
    /// Where it runs.
    pub shape: WallShape,
    /// Half thickness in metres.
    pub radius: f32,
}

impl Wall {
    /// Closest point of the wall's centre line to `p`.
    pub fn closest(&self, p: Vec2) -> Vec2 {
        match self.shape {
            WallShape::Segment(a, b) => {
                let ab = b - a;
                let len2 = ab.length_squared();
                let t = if len2 > 0.0 { ((p - a).dot(ab) / len2).clamp(0.0, 1.0) } else { 0.0 };
                a + ab * t
            }
            WallShape::Plane { point, normal } => p - normal * (p - point).dot(normal),
        }
    }
}

/// An agent's handles: how strongly it heeds each kind of influence.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Weights {
    /// Goal attraction.
    pub targets: f32,
    /// Obstacle repulsion.
    pub obstacles: f32,
    /// Wall repulsion.
    pub walls: f32,
    /// Repulsion from other agents.
    pub agents: f32,
}

impl Default for Weights {
    fn default() -> Self {
        Weights { targets: 1.0, obstacles: 1.0, walls: 1.0, agents: 1.0 }
    }
}

/// One agent as the scene starts it (at the first simulated frame).
#[derive(Clone, Debug, PartialEq)]
pub struct AgentSpec {
    /// Stable id.
    pub id: u32,
    /// Ground-plane start position `(x, z)`.
    pub position: Vec2,
    /// Start heading, radians.
    pub heading: f32,
    /// Index into [`SimScene::rigs`].
    pub rig: u16,
    /// Start cycle, index into [`SimScene::cycles`].
    pub cycle: u16,
    /// Start cycle frame.
    pub cycle_frame: f32,
    /// Seated: never moves, never switches cycle.
    pub seated: bool,
    /// Targets this agent visits, as a bit mask over [`SimScene::targets`].
    pub targets: u64,
    /// Handles.
    pub weights: Weights,
    /// Radius in metres.
    pub radius: f32,
}

/// A simulation scene, validated.
#[derive(Clone, Debug, PartialEq)]
pub struct SimScene {
    /// The file it came from (for messages).
    pub path: PathBuf,
    /// Seed of every random choice.
    pub seed: u64,
    /// First cache frame written.
    pub start: i32,
    /// Last cache frame written.
    pub end: i32,
    /// Frames simulated before `start` and not written; agents start at
    /// frame `start - warmup`.
    pub warmup: i32,
    /// Frames per second of the cache (cycle lengths from rig files are
    /// `duration * fps`).
    pub fps: f32,
    /// Model constants.
    pub model: Model,
    /// Rig names (sorted).
    pub rigs: Vec<String>,
    /// Rig files by rig index (`[rigs]`, resolved against the scene file's
    /// folder); `None` for rigs that take explicit `[cycles.X]` values.
    pub rig_files: Vec<Option<PathBuf>>,
    /// Cycles (sorted by name).
    pub cycles: Vec<Cycle>,
    /// Length and stride per (rig, cycle): index `rig * cycles.len() + cycle`
    /// (see [`SimScene::timing`]). Pairs no agent can reach hold a stand-in
    /// (1 frame, stride 0).
    pub timings: Vec<CycleTiming>,
    /// Targets in file order.
    pub targets: Vec<Target>,
    /// Obstacles.
    pub obstacles: Vec<Obstacle>,
    /// Walls.
    pub walls: Vec<Wall>,
    /// Agents, sorted by id.
    pub agents: Vec<AgentSpec>,
}

// ---------------------------------------------------------------------------
// SimScene file
// ---------------------------------------------------------------------------

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawScene {
    version: u32,
    seed: u64,
    frames: RawFrames,
    #[serde(default)]
    model: RawModel,
    #[serde(default)]
    rigs: BTreeMap<String, PathBuf>,
    cycles: BTreeMap<String, RawCycle>,
    #[serde(default)]
    targets: Vec<RawTarget>,
    #[serde(default)]
    obstacles: Vec<RawObstacle>,
    #[serde(default)]
    walls: Vec<RawWall>,
    #[serde(default)]
    agents: Vec<RawAgent>,
    #[serde(default)]
    spawn: Vec<RawSpawn>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawFrames {
    start: i32,
    end: i32,
    #[serde(default)]
    warmup: u32,
    fps: Option<f32>,
}

#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct RawModel {
    max_turn_deg: Option<f32>,
    relax_distance: Option<f32>,
    falloff: Option<f32>,
    power: Option<f32>,
    min_speed: Option<f32>,
    agent_radius: Option<f32>,
    chase: Option<bool>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCycle {
    length: Option<f32>,
    stride: Option<f32>,
    #[serde(default)]
    next: BTreeMap<String, f32>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTarget {
    name: String,
    position: [f32; 2],
    #[serde(default = "one")]
    radius: f32,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawObstacle {
    #[serde(default)]
    #[allow(dead_code)] // for the reader of the file
    name: Option<String>,
    radius: f32,
    center: Option<[f32; 2]>,
    #[serde(default)]
    path: Vec<RawKey>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawKey {
    frame: i32,
    center: [f32; 2],
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawWall {
    #[serde(default)]
    #[allow(dead_code)] // for the reader of the file
    name: Option<String>,
    from: Option<[f32; 2]>,
    to: Option<[f32; 2]>,
    point: Option<[f32; 2]>,
    normal: Option<[f32; 2]>,
    #[serde(default)]
    radius: f32,
}

#[derive(Deserialize, Default, Clone, Copy)]
#[serde(deny_unknown_fields)]
struct RawWeights {
    targets: Option<f32>,
    obstacles: Option<f32>,
    walls: Option<f32>,
    agents: Option<f32>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawAgent {
    id: u32,
    position: [f32; 2],
    #[serde(default)]
    heading_deg: f32,
    rig: String,
    cycle: String,
    cycle_frame: Option<f32>,
    #[serde(default)]
    seated: bool,
    targets: Option<Vec<String>>,
    #[serde(default)]
    weights: RawWeights,
    radius: Option<f32>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSpawn {
    count: u32,
    first_id: u32,
    min: [f32; 2],
    max: [f32; 2],
    #[serde(default = "default_jitter")]
    jitter: f32,
    #[serde(default)]
    heading_deg: f32,
    #[serde(default)]
    heading_jitter_deg: f32,
    rigs: BTreeMap<String, f32>,
    cycles: BTreeMap<String, f32>,
    targets: Option<Vec<String>>,
    #[serde(default)]
    weights: RawWeights,
    radius: Option<f32>,
}

fn one() -> f32 {
    1.0
}
fn default_jitter() -> f32 {
    0.8
}

impl SimScene {
    /// Reads and validates a scene file.
    pub fn load(path: impl AsRef<Path>) -> Result<SimScene> {
        let path = path.as_ref();
        let text = std::fs::read_to_string(path).at(path)?;
        SimScene::parse(&text, path)
    }

    /// Parses and validates scene text; `path` names it in messages.
    pub fn parse(text: &str, path: impl AsRef<Path>) -> Result<SimScene> {
        let path = path.as_ref();
        // Check the version before the strict schema, so a future file says so.
        let table: toml::Table = toml::from_str(text).map_err(|e| Error::toml(path, text, e))?;
        match table.get("version") {
            Some(toml::Value::Integer(1)) => {}
            Some(v) => {
                return Err(Error::invalid(path, format!("unsupported scene version {v} (this throng reads 1)"))
                    .field("version"))
            }
            None => return Err(Error::invalid(path, "missing `version = 1`").field("version")),
        }
        let raw: RawScene = toml::from_str(text).map_err(|e| Error::toml(path, text, e))?;
        resolve(raw, path)
    }

    /// Length and stride of `cycle` on `rig` (indices into [`SimScene::rigs`]
    /// and [`SimScene::cycles`]).
    pub fn timing(&self, rig: u16, cycle: u16) -> CycleTiming {
        self.timings[rig as usize * self.cycles.len() + cycle as usize]
    }

    /// Simulated frames: from `start - warmup` to `end`.
    pub fn first_frame(&self) -> i32 {
        self.start - self.warmup
    }
}

fn check(path: &Path, ok: bool, field: impl Into<String>, msg: impl Into<String>) -> Result<()> {
    if ok {
        Ok(())
    } else {
        Err(Error::invalid(path, msg).field(field))
    }
}

fn finite(path: &Path, v: &[f32], field: &str) -> Result<()> {
    check(path, v.iter().all(|x| x.is_finite()), field, "must be a finite number")
}

fn weights(path: &Path, w: RawWeights, field: &str) -> Result<Weights> {
    let d = Weights::default();
    let get = |v: Option<f32>, d: f32, k: &str| -> Result<f32> {
        let v = v.unwrap_or(d);
        check(path, v.is_finite() && v >= 0.0, format!("{field}.{k}"), "weight must be >= 0")?;
        Ok(v)
    };
    Ok(Weights {
        targets: get(w.targets, d.targets, "targets")?,
        obstacles: get(w.obstacles, d.obstacles, "obstacles")?,
        walls: get(w.walls, d.walls, "walls")?,
        agents: get(w.agents, d.agents, "agents")?,
    })
}

fn resolve(raw: RawScene, path: &Path) -> Result<SimScene> {
    let _ = raw.version; // checked in parse
    check(path, raw.frames.end >= raw.frames.start, "frames.end", "must be >= frames.start")?;
    let warmup = i32::try_from(raw.frames.warmup)
        .ok()
        .filter(|w| raw.frames.start.checked_sub(*w).is_some())
        .ok_or_else(|| Error::invalid(path, "too large").field("frames.warmup"))?;
    let span = i64::from(raw.frames.end) - i64::from(raw.frames.start) + i64::from(warmup);
    check(path, span <= MAX_FRAMES, "frames", format!("at most {MAX_FRAMES} simulated frames"))?;

    let d = Model::default();
    let m = &raw.model;
    let model = Model {
        max_turn: m.max_turn_deg.map_or(d.max_turn, f32::to_radians),
        relax_distance: m.relax_distance.unwrap_or(d.relax_distance),
        falloff: m.falloff.unwrap_or(d.falloff),
        power: m.power.unwrap_or(d.power),
        min_speed: m.min_speed.unwrap_or(d.min_speed),
        agent_radius: m.agent_radius.unwrap_or(d.agent_radius),
        chase: m.chase.unwrap_or(d.chase),
    };
    check(path, model.max_turn.is_finite() && model.max_turn > 0.0, "model.max_turn_deg", "must be > 0")?;
    check(
        path,
        model.relax_distance.is_finite() && model.relax_distance >= 0.0,
        "model.relax_distance",
        "must be >= 0",
    )?;
    check(path, model.falloff.is_finite() && model.falloff > 0.0, "model.falloff", "must be > 0")?;
    check(path, model.power.is_finite() && model.power > 0.0, "model.power", "must be > 0")?;
    check(path, (0.0..=1.0).contains(&model.min_speed), "model.min_speed", "must be in [0, 1]")?;
    check(path, model.agent_radius.is_finite() && model.agent_radius >= 0.0, "model.agent_radius", "must be >= 0")?;

    let fps = raw.frames.fps.unwrap_or(DEFAULT_FPS);
    check(path, fps.is_finite() && fps > 0.0, "frames.fps", "must be > 0")?;

    // Cycles, sorted by name (BTreeMap order). Their length and stride come
    // per rig, after the agents (see `timings`).
    check(path, !raw.cycles.is_empty(), "cycles", "declare at least one cycle")?;
    check(path, raw.cycles.len() <= usize::from(u16::MAX), "cycles", "too many cycles")?;
    let cycle_index: HashMap<&str, u16> = raw.cycles.keys().enumerate().map(|(i, k)| (k.as_str(), i as u16)).collect();
    let mut cycles = Vec::new();
    for (name, c) in &raw.cycles {
        let f = format!("cycles.{name}");
        crate::cache::check_name(name).map_err(|m| Error::invalid(path, m).field(f.clone()))?;
        if let Some(l) = c.length {
            check(path, l.is_finite() && l >= 1.0, format!("{f}.length"), "must be >= 1 frame")?;
        }
        if let Some(st) = c.stride {
            check(path, st.is_finite() && st >= 0.0, format!("{f}.stride"), "must be >= 0 metres")?;
        }
        let mut next = Vec::new();
        for (n, w) in &c.next {
            let Some(&i) = cycle_index.get(n.as_str()) else {
                return Err(Error::invalid(path, format!("unknown cycle `{n}`")).field(format!("{f}.next")));
            };
            check(path, w.is_finite() && *w >= 0.0, format!("{f}.next.{n}"), "weight must be >= 0")?;
            next.push((i, *w));
        }
        if !next.is_empty() {
            check(path, next.iter().any(|&(_, w)| w > 0.0), format!("{f}.next"), "weights sum to 0")?;
        }
        cycles.push(Cycle { name: name.clone(), length: c.length, stride: c.stride, next });
    }

    // Targets.
    check(path, raw.targets.len() <= MAX_TARGETS, "targets", format!("at most {MAX_TARGETS} targets"))?;
    let mut target_index: HashMap<&str, usize> = HashMap::new();
    let mut targets = Vec::new();
    for (i, t) in raw.targets.iter().enumerate() {
        let f = format!("targets[{i}]");
        finite(path, &t.position, &format!("{f}.position"))?;
        check(path, t.radius.is_finite() && t.radius > 0.0, format!("{f}.radius"), "must be > 0")?;
        if target_index.insert(t.name.as_str(), i).is_some() {
            return Err(Error::invalid(path, format!("duplicate target `{}`", t.name)).field(format!("{f}.name")));
        }
        targets.push(Target { name: t.name.clone(), position: Vec2::from(t.position), radius: t.radius });
    }
    let all_targets: u64 = if targets.len() == 64 { u64::MAX } else { (1u64 << targets.len()) - 1 };
    let target_mask = |names: &Option<Vec<String>>, field: &str| -> Result<u64> {
        let Some(names) = names else { return Ok(all_targets) };
        let mut mask = 0u64;
        for n in names {
            let Some(&i) = target_index.get(n.as_str()) else {
                return Err(Error::invalid(path, format!("unknown target `{n}`")).field(field.to_string()));
            };
            mask |= 1 << i;
        }
        Ok(mask)
    };

    // Obstacles.
    let mut obstacles = Vec::new();
    for (i, o) in raw.obstacles.iter().enumerate() {
        let f = format!("obstacles[{i}]");
        check(path, o.radius.is_finite() && o.radius >= 0.0, format!("{f}.radius"), "must be >= 0")?;
        let mut keys: Vec<(i32, Vec2)> = Vec::new();
        match (&o.center, o.path.is_empty()) {
            (Some(c), true) => {
                finite(path, c, &format!("{f}.center"))?;
                keys.push((0, Vec2::from(*c)));
            }
            (None, false) => {
                for (k, key) in o.path.iter().enumerate() {
                    finite(path, &key.center, &format!("{f}.path[{k}].center"))?;
                    if let Some(&(prev, _)) = keys.last() {
                        check(path, key.frame > prev, format!("{f}.path[{k}].frame"), "frames must increase")?;
                    }
                    keys.push((key.frame, Vec2::from(key.center)));
                }
            }
            _ => return Err(Error::invalid(path, "give either `center` or `path`").field(f)),
        }
        obstacles.push(Obstacle { radius: o.radius, path: keys });
    }

    // Walls.
    let mut walls = Vec::new();
    for (i, w) in raw.walls.iter().enumerate() {
        let f = format!("walls[{i}]");
        check(path, w.radius.is_finite() && w.radius >= 0.0, format!("{f}.radius"), "must be >= 0")?;
        let shape = match (w.from, w.to, w.point, w.normal) {
            (Some(a), Some(b), None, None) => {
                finite(path, &a, &format!("{f}.from"))?;
                finite(path, &b, &format!("{f}.to"))?;
                WallShape::Segment(Vec2::from(a), Vec2::from(b))
            }
            (None, None, Some(p), Some(n)) => {
                finite(path, &p, &format!("{f}.point"))?;
                finite(path, &n, &format!("{f}.normal"))?;
                let n = Vec2::from(n);
                check(path, n.length() > 1e-6, format!("{f}.normal"), "must not be zero")?;
                WallShape::Plane { point: Vec2::from(p), normal: n.normalize() }
            }
            _ => {
                return Err(
                    Error::invalid(path, "a wall is a segment (`from`, `to`) or a plane (`point`, `normal`)").field(f)
                )
            }
        };
        walls.push(Wall { shape, radius: w.radius });
    }

    // Rigs: every name the agents and spawns mention, sorted.
    let mut rig_names: BTreeSet<&str> = raw.agents.iter().map(|a| a.rig.as_str()).collect();
    for s in &raw.spawn {
        rig_names.extend(s.rigs.keys().map(String::as_str));
    }
    check(path, rig_names.len() <= usize::from(u16::MAX), "agents", "too many rigs")?;
    for name in &rig_names {
        crate::cache::check_name(name).map_err(|m| Error::invalid(path, format!("bad rig name: {m}")).field("rig"))?;
    }
    check(
        path,
        rig_names.len() * cycles.len() <= MAX_RIG_CYCLES,
        "cycles",
        format!("at most {MAX_RIG_CYCLES} (rig, cycle) pairs"),
    )?;
    let rigs: Vec<String> = rig_names.iter().map(|s| s.to_string()).collect();
    let rig_index: HashMap<&str, u16> = rig_names.iter().enumerate().map(|(i, s)| (*s, i as u16)).collect();
    // Rig files are relative to the scene file.
    let base = path.parent().unwrap_or(Path::new(""));
    let rig_files: Vec<Option<PathBuf>> = rigs.iter().map(|r| raw.rigs.get(r).map(|f| base.join(f))).collect();

    // Every (rig, cycle) pair an agent can be on, with the key that first
    // puts it there (for messages): start cycles, then the `next` closure.
    let mut reach: BTreeMap<(u16, u16), String> = BTreeMap::new();
    for (i, a) in raw.agents.iter().enumerate() {
        if let Some(&c) = cycle_index.get(a.cycle.as_str()) {
            reach.entry((rig_index[a.rig.as_str()], c)).or_insert_with(|| format!("agents[{i}].cycle"));
        }
    }
    for (i, s) in raw.spawn.iter().enumerate() {
        for (r, rw) in &s.rigs {
            for (c, cw) in &s.cycles {
                if let (true, Some(&ci)) = (*rw > 0.0 && *cw > 0.0, cycle_index.get(c.as_str())) {
                    reach.entry((rig_index[r.as_str()], ci)).or_insert_with(|| format!("spawn[{i}].cycles.{c}"));
                }
            }
        }
    }
    let mut todo: Vec<(u16, u16)> = reach.keys().copied().collect();
    while let Some((r, c)) = todo.pop() {
        for &(n, w) in &cycles[c as usize].next {
            if w > 0.0 && !reach.contains_key(&(r, n)) {
                reach.insert((r, n), format!("cycles.{}.next.{}", cycles[c as usize].name, cycles[n as usize].name));
                todo.push((r, n));
            }
        }
    }
    let timings = timings(path, fps, &rigs, &rig_files, &cycles, &reach)?;
    let ncycles = cycles.len();
    let timing = |rig: u16, cycle: u16| timings[rig as usize * ncycles + cycle as usize];

    let radius = |r: Option<f32>, field: String| -> Result<f32> {
        let r = r.unwrap_or(model.agent_radius);
        check(path, r.is_finite() && r >= 0.0, field, "must be >= 0")?;
        Ok(r)
    };
    let seed = raw.seed;
    let phase = |id: u32, rig: u16, cycle: u16| {
        let length = timing(rig, cycle).length;
        (rng::unit(seed, id, Purpose::Phase, 0) as f32 * length).min(length - 1e-3)
    };

    let mut agents = Vec::new();
    for (i, a) in raw.agents.iter().enumerate() {
        let f = format!("agents[{i}]");
        let inv = |msg: String, k: &str| Error::invalid(path, msg).field(format!("{f}.{k}")).agent(a.id);
        if !a.position.iter().all(|v| v.is_finite()) {
            return Err(inv("must be finite".into(), "position"));
        }
        if !a.heading_deg.is_finite() {
            return Err(inv("must be finite".into(), "heading_deg"));
        }
        let cycle =
            *cycle_index.get(a.cycle.as_str()).ok_or_else(|| inv(format!("unknown cycle `{}`", a.cycle), "cycle"))?;
        let rig = rig_index[a.rig.as_str()];
        let c = timing(rig, cycle);
        if a.seated && c.moves() {
            return Err(inv(
                format!(
                    "seated agents need a cycle with stride 0, `{}` walks {} m on rig `{}`",
                    a.cycle, c.stride, a.rig
                ),
                "cycle",
            ));
        }
        let cycle_frame = match a.cycle_frame {
            Some(cf) if cf.is_finite() && cf >= 0.0 && cf < c.length => cf,
            Some(_) => {
                return Err(inv(
                    format!("must be in [0, {}) (`{}` on rig `{}`)", c.length, a.cycle, a.rig),
                    "cycle_frame",
                ))
            }
            None => phase(a.id, rig, cycle),
        };
        agents.push(AgentSpec {
            id: a.id,
            position: Vec2::from(a.position),
            heading: wrap_angle(a.heading_deg.to_radians()),
            rig,
            cycle,
            cycle_frame,
            seated: a.seated,
            targets: target_mask(&a.targets, &format!("{f}.targets")).map_err(|e| e.agent(a.id))?,
            weights: weights(path, a.weights, &format!("{f}.weights")).map_err(|e| e.agent(a.id))?,
            radius: radius(a.radius, format!("{f}.radius")).map_err(|e| e.agent(a.id))?,
        });
    }

    for (i, s) in raw.spawn.iter().enumerate() {
        let f = format!("spawn[{i}]");
        finite(path, &s.min, &format!("{f}.min"))?;
        finite(path, &s.max, &format!("{f}.max"))?;
        let (lo, hi) = (Vec2::from(s.min), Vec2::from(s.max));
        check(path, hi.x >= lo.x && hi.y >= lo.y, format!("{f}.max"), "must be >= min in x and z")?;
        check(path, (0.0..=1.0).contains(&s.jitter), format!("{f}.jitter"), "must be in [0, 1]")?;
        finite(path, &[s.heading_deg, s.heading_jitter_deg], &format!("{f}.heading_deg"))?;
        check(path, s.first_id.checked_add(s.count).is_some(), format!("{f}.count"), "ids overflow u32")?;
        check(path, s.count as usize <= MAX_AGENTS, format!("{f}.count"), format!("at most {MAX_AGENTS} agents"))?;
        let mut rig_mix = Vec::new();
        for (n, w) in &s.rigs {
            check(path, w.is_finite() && *w >= 0.0, format!("{f}.rigs.{n}"), "weight must be >= 0")?;
            rig_mix.push((rig_index[n.as_str()], *w));
        }
        check(path, rig_mix.iter().any(|r| r.1 > 0.0), format!("{f}.rigs"), "give at least one rig a weight > 0")?;
        let mut cycle_mix = Vec::new();
        for (n, w) in &s.cycles {
            let Some(&c) = cycle_index.get(n.as_str()) else {
                return Err(Error::invalid(path, format!("unknown cycle `{n}`")).field(format!("{f}.cycles")));
            };
            check(path, w.is_finite() && *w >= 0.0, format!("{f}.cycles.{n}"), "weight must be >= 0")?;
            cycle_mix.push((c, *w));
        }
        check(
            path,
            cycle_mix.iter().any(|r| r.1 > 0.0),
            format!("{f}.cycles"),
            "give at least one cycle a weight > 0",
        )?;
        let mask = target_mask(&s.targets, &format!("{f}.targets"))?;
        let w = weights(path, s.weights, &format!("{f}.weights"))?;
        let r = radius(s.radius, format!("{f}.radius"))?;

        // A jittered grid of cells filling the rectangle keeps agents apart.
        let n = s.count as usize;
        let size = hi - lo;
        let cols = if n == 0 {
            1
        } else if size.y <= 0.0 {
            n
        } else if size.x <= 0.0 {
            1
        } else {
            ((n as f32 * size.x / size.y).sqrt().ceil() as usize).clamp(1, n)
        };
        let rows = n.div_ceil(cols).max(1);
        let cell = Vec2::new(size.x / cols as f32, size.y / rows as f32);
        for k in 0..n {
            let id = s.first_id + k as u32;
            let (col, row) = ((k % cols) as f32, (k / cols) as f32);
            let jx = rng::unit(seed, id, Purpose::SpawnJitter, 0) as f32 - 0.5;
            let jz = rng::unit(seed, id, Purpose::SpawnJitter, 1) as f32 - 0.5;
            let position = lo + Vec2::new((col + 0.5 + s.jitter * jx) * cell.x, (row + 0.5 + s.jitter * jz) * cell.y);
            let hj = 2.0 * rng::unit(seed, id, Purpose::SpawnHeading, 0) as f32 - 1.0;
            let heading = wrap_angle((s.heading_deg + s.heading_jitter_deg * hj).to_radians());
            let rig = rng::choose(&rig_mix, rng::unit(seed, id, Purpose::Rig, 0)).unwrap_or(rig_mix[0].0);
            let cycle = rng::choose(&cycle_mix, rng::unit(seed, id, Purpose::Cycle, 0)).unwrap_or(cycle_mix[0].0);
            agents.push(AgentSpec {
                id,
                position,
                heading,
                rig,
                cycle,
                cycle_frame: phase(id, rig, cycle),
                seated: false,
                targets: mask,
                weights: w,
                radius: r,
            });
        }
    }

    check(path, agents.len() <= MAX_AGENTS, "spawn", format!("at most {MAX_AGENTS} agents in a scene"))?;
    agents.sort_by_key(|a| a.id);
    for w in agents.windows(2) {
        if w[0].id == w[1].id {
            return Err(Error::invalid(path, format!("agent id {} is used twice", w[0].id)).agent(w[0].id).field("id"));
        }
    }

    Ok(SimScene {
        path: path.to_path_buf(),
        seed,
        start: raw.frames.start,
        end: raw.frames.end,
        warmup,
        fps,
        model,
        rigs,
        rig_files,
        cycles,
        timings,
        targets,
        obstacles,
        walls,
        agents,
    })
}

/// Length and stride of every reachable (rig, cycle) pair: from the rig's
/// glTF file when `[rigs]` names one (the file wins: its clip is what the
/// renderer plays), else the cycle's explicit `length` and `stride`.
/// Explicit values that no reachable rig without a file uses are an error,
/// so an edit that would be ignored is not silently ignored.
fn timings(
    path: &Path,
    fps: f32,
    rigs: &[String],
    rig_files: &[Option<PathBuf>],
    cycles: &[Cycle],
    reach: &BTreeMap<(u16, u16), String>,
) -> Result<Vec<CycleTiming>> {
    let stand_in = CycleTiming { length: 1.0, stride: 0.0 };
    let mut out = vec![stand_in; rigs.len() * cycles.len()];
    let mut loaded: Vec<Option<crate::casting::rig::Rig>> = vec![None; rigs.len()];
    let mut explicit_used = vec![false; cycles.len()];
    for (&(r, c), key) in reach {
        let (rig_name, cycle) = (&rigs[r as usize], &cycles[c as usize]);
        let timing = match &rig_files[r as usize] {
            Some(file) => {
                let rig: &crate::casting::rig::Rig = match &mut loaded[r as usize] {
                    Some(rig) => rig,
                    slot @ None => slot.insert(crate::casting::rig::Rig::load(file).map_err(|e| {
                        Error::invalid(path, format!("rig `{rig_name}`: {e}")).field(format!("rigs.{rig_name}"))
                    })?),
                };
                let Some(clip) = rig.cycles().iter().find(|k| k.name() == cycle.name) else {
                    let names: Vec<&str> = rig.cycles().iter().map(|k| k.name()).collect();
                    return Err(Error::invalid(
                        path,
                        format!(
                            "rig `{rig_name}` ({}) has no cycle `{}` (its cycles: {})",
                            file.display(),
                            cycle.name,
                            names.join(", ")
                        ),
                    )
                    .field(key.clone()));
                };
                let t = CycleTiming { length: clip.frames(fps), stride: clip.stride() };
                let what = format!("rig `{rig_name}` ({}) cycle `{}`", file.display(), cycle.name);
                check(
                    path,
                    t.length.is_finite() && t.length >= 1.0,
                    key.clone(),
                    format!("{what} is {} frames long; needs >= 1", t.length),
                )?;
                check(
                    path,
                    t.stride.is_finite() && t.stride >= 0.0,
                    key.clone(),
                    format!("{what} has stride {} m; needs >= 0 (root walks along +Z)", t.stride),
                )?;
                t
            }
            None => {
                explicit_used[c as usize] = true;
                let missing = |k: &str| {
                    Error::invalid(
                        path,
                        format!(
                            "rig `{rig_name}` has no file in [rigs], so `{}` needs an explicit {k} (used by {key})",
                            cycle.name
                        ),
                    )
                    .field(format!("cycles.{}.{k}", cycle.name))
                };
                let length = cycle.length.ok_or_else(|| missing("length"))?;
                let stride = cycle.stride.ok_or_else(|| missing("stride"))?;
                CycleTiming { length, stride }
            }
        };
        out[r as usize * cycles.len() + c as usize] = timing;
    }
    for (c, cycle) in cycles.iter().enumerate() {
        let on_files: Vec<&str> = reach
            .keys()
            .filter(|&&(r, k)| k as usize == c && rig_files[r as usize].is_some())
            .map(|&(r, _)| rigs[r as usize].as_str())
            .collect();
        for (k, given) in [("length", cycle.length.is_some()), ("stride", cycle.stride.is_some())] {
            if given && !explicit_used[c] && !on_files.is_empty() {
                return Err(Error::invalid(
                    path,
                    format!(
                        "every rig on `{}` ({}) takes its {k} from its file in [rigs]; remove the explicit value",
                        cycle.name,
                        on_files.join(", ")
                    ),
                )
                .field(format!("cycles.{}.{k}", cycle.name)));
            }
        }
    }
    Ok(out)
}

// ---------------------------------------------------------------------------
// Simulation
// ---------------------------------------------------------------------------

/// One agent's state at one frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AgentState {
    /// Ground-plane position `(x, z)`.
    pub position: Vec2,
    /// Heading, radians in (-pi, pi].
    pub heading: f32,
    /// Metres walked in the last frame (0 when standing).
    pub speed: f32,
    /// Index into [`SimScene::cycles`].
    pub cycle: u16,
    /// Frame within the cycle.
    pub cycle_frame: f32,
    /// Target being walked to, index into [`SimScene::targets`].
    pub target: Option<u8>,
    /// Targets visited since the agent last ran out of targets (bit mask).
    pub visited: u64,
}

/// A running simulation: the scene and the current frame's states.
pub struct Simulation<'a> {
    scene: &'a SimScene,
    frame: i32,
    states: Vec<AgentState>,
    max_radius: f32,
}

impl<'a> Simulation<'a> {
    /// Agents at the scene's first simulated frame (`start - warmup`).
    pub fn new(scene: &'a SimScene) -> Simulation<'a> {
        let states = scene
            .agents
            .iter()
            .map(|a| {
                let c = scene.timing(a.rig, a.cycle);
                let mut s = AgentState {
                    position: a.position,
                    heading: a.heading,
                    speed: if a.seated { 0.0 } else { c.travel() },
                    cycle: a.cycle,
                    cycle_frame: a.cycle_frame,
                    target: None,
                    visited: 0,
                };
                s.target = nearest_target(scene, a, s.position, s.visited);
                s
            })
            .collect();
        let max_radius = scene.agents.iter().map(|a| a.radius).fold(0.0, f32::max);
        Simulation { scene, frame: scene.first_frame(), states, max_radius }
    }

    /// The frame the states are at.
    pub fn frame(&self) -> i32 {
        self.frame
    }

    /// States in [`SimScene::agents`] order.
    pub fn states(&self) -> &[AgentState] {
        &self.states
    }

    /// Advances one frame. The new states depend only on the previous
    /// frame's, so the result does not depend on the thread count.
    pub fn step(&mut self) {
        let reach = self.scene.model.relax_distance + 2.0 * self.max_radius;
        let points: Vec<Vec2> = self.states.iter().map(|s| s.position).collect();
        let grid = grid::Grid::build(&points, (0.5 * reach).max(0.5));
        // Neighbour data copied into grid order: a query reads it contiguously.
        let packed: Vec<Neighbour> = grid
            .items()
            .iter()
            .map(|&i| {
                let s = &self.states[i as usize];
                Neighbour {
                    position: s.position,
                    // Normalised velocity; zero for standing agents (no chase).
                    dir: if s.speed > 0.0 { forward(s.heading) } else { Vec2::ZERO },
                    radius: self.scene.agents[i as usize].radius,
                    index: i,
                }
            })
            .collect();
        let near = Near { grid: &grid, packed: &packed, reach };
        let prev = &self.states;
        let next: Vec<AgentState> = (0..prev.len()).into_par_iter().map(|i| self.step_agent(i, prev, &near)).collect();
        self.states = next;
        self.frame += 1;
    }

    /// The current frame as a cache block (agents in id order).
    pub fn record(&self) -> FrameBlock {
        let agents = self
            .scene
            .agents
            .iter()
            .zip(&self.states)
            .map(|(a, s)| AgentSample {
                id: a.id,
                position: Vec3::new(s.position.x, 0.0, s.position.y),
                heading: s.heading,
                rig: a.rig,
                cycle: s.cycle,
                cycle_frame: s.cycle_frame,
                flags: if a.seated { SEATED } else { 0 },
            })
            .collect();
        FrameBlock { frame: self.frame, agents }
    }

    fn step_agent(&self, i: usize, prev: &[AgentState], near: &Near) -> AgentState {
        let scene = self.scene;
        let model = &scene.model;
        let spec = &scene.agents[i];
        let s = prev[i];
        let mut n = s;
        // This agent's own rig's clip: strides differ per rig.
        let cycle = scene.timing(spec.rig, s.cycle);
        if spec.seated || !cycle.moves() {
            // Seated and idle agents stand still and play their cycle.
            n.speed = 0.0;
            self.advance_cycle(spec, &mut n, 1.0);
            return n;
        }

        // Goal: on reaching the target, move on to the nearest unvisited one.
        if let Some(t) = s.target {
            let tg = &scene.targets[t as usize];
            if s.position.distance(tg.position) <= tg.radius {
                n.visited |= 1 << t;
                if n.visited & spec.targets == spec.targets {
                    n.visited = 1 << t; // all seen: start a new round, not this one first
                }
                n.target = nearest_target(scene, spec, s.position, n.visited);
            }
        }

        // Repulsion from agents, obstacles and walls.
        let fwd = forward(s.heading);
        let p = s.position;
        let w = spec.weights;
        let mut st = Steer::default();
        if w.agents != 0.0 {
            let reach2 = near.reach * near.reach;
            near.grid.for_each_slot_near(p, near.reach, |k| {
                let o = &near.packed[k];
                let to = o.position - p;
                if o.index as usize == i || to.length_squared() > reach2 {
                    return;
                }
                let gap = to.length() - spec.radius - o.radius;
                if gap > model.relax_distance {
                    return;
                }
                // Chase: dot of the two normalised velocities (standing agents have
                // none). It stops a file of walkers shaking; agents already touching
                // get no attenuation, so a faster walker does not pass through a
                // slower one ahead on the same course.
                let atten = if model.chase && gap > 0.0 { steer::chase_attenuation(fwd.dot(o.dir)) } else { 1.0 };
                st.add(model, fwd, to, gap, w.agents, atten);
            });
        }
        if w.obstacles != 0.0 {
            for ob in &scene.obstacles {
                let to = ob.center_at(self.frame) - p;
                let gap = to.length() - spec.radius - ob.radius;
                if gap <= model.relax_distance {
                    st.add(model, fwd, to, gap, w.obstacles, 1.0);
                }
            }
        }
        if w.walls != 0.0 {
            for wall in &scene.walls {
                let to = wall.closest(p) - p;
                let gap = to.length() - spec.radius - wall.radius;
                if gap <= model.relax_distance {
                    st.add(model, fwd, to, gap, w.walls, 1.0);
                }
            }
        }

        // Goal attraction: turn towards the target at up to the base limit,
        // boosted by the unraised D near the target so agents do not orbit it.
        let base = model.max_turn;
        let goal_turn = match n.target {
            Some(t) if w.targets != 0.0 => {
                let tg = &scene.targets[t as usize];
                let to = tg.position - p;
                let phi = wrap_angle(heading_of(to) - s.heading);
                let gap = (to.length() - tg.radius).max(0.0) / model.falloff;
                w.targets * phi.clamp(-base, base) * (1.0 + steer::falloff(gap))
            }
            _ => 0.0,
        };

        let limit = steer::turn_limit(base, model.relax_distance, st.nearest);
        let turn = (goal_turn + st.sum * limit).clamp(-limit, limit);
        n.heading = wrap_angle(s.heading + turn);
        let factor = 1.0 - (1.0 - model.min_speed) * st.slow.clamp(0.0, 1.0);
        n.speed = cycle.travel() * factor;
        n.position = p + forward(n.heading) * n.speed;
        // Feet do not slide: the cycle advances by distance / (stride / length).
        self.advance_cycle(spec, &mut n, factor);
        n
    }

    /// Advances the cycle frame by `by` frames; at the end of the cycle the
    /// agent may switch cycle (seeded per agent and frame).
    fn advance_cycle(&self, spec: &AgentSpec, s: &mut AgentState, by: f32) {
        let scene = self.scene;
        let length = scene.timing(spec.rig, s.cycle).length;
        s.cycle_frame += by;
        if s.cycle_frame < length {
            return;
        }
        let rest = s.cycle_frame - length;
        let next = &scene.cycles[s.cycle as usize].next;
        if !spec.seated && !next.is_empty() {
            let u = rng::unit(scene.seed, spec.id, Purpose::NextCycle, i64::from(self.frame) + 1);
            s.cycle = rng::choose(next, u).unwrap_or(s.cycle);
        }
        let now = scene.timing(spec.rig, s.cycle);
        s.cycle_frame = rest.rem_euclid(now.length);
        if now.moves() && s.target.is_none() {
            s.target = nearest_target(scene, spec, s.position, s.visited);
        }
    }
}

/// Another agent as a neighbour query sees it (previous frame).
struct Neighbour {
    position: Vec2,
    dir: Vec2,
    radius: f32,
    index: u32,
}

/// Neighbour search for one frame.
struct Near<'g> {
    grid: &'g grid::Grid,
    packed: &'g [Neighbour],
    reach: f32,
}

/// The nearest of the agent's targets not in `visited` (ties: file order).
fn nearest_target(scene: &SimScene, spec: &AgentSpec, from: Vec2, visited: u64) -> Option<u8> {
    let mut best: Option<(f32, u8)> = None;
    for (t, tg) in scene.targets.iter().enumerate() {
        if spec.targets & (1 << t) == 0 || visited & (1 << t) != 0 {
            continue;
        }
        let d = from.distance_squared(tg.position);
        if best.is_none_or(|(bd, _)| d < bd) {
            best = Some((d, t as u8));
        }
    }
    best.map(|b| b.1)
}

/// Runs the whole scene and returns frames `start..=end` as a cache, its
/// rig and cycle tables in first-use order ([`crate::cache::canonical`]), so
/// reading the written file back gives this crowd exactly.
pub fn run(scene: &SimScene) -> CrowdCache {
    let mut sim = Simulation::new(scene);
    let mut frames = Vec::with_capacity((i64::from(scene.end) - i64::from(scene.start) + 1).clamp(0, 100_000) as usize);
    loop {
        if sim.frame() >= scene.start {
            frames.push(sim.record());
        }
        if sim.frame() >= scene.end {
            break;
        }
        sim.step();
    }
    crate::cache::canonical(&CrowdCache {
        rigs: scene.rigs.clone(),
        cycles: scene.cycles.iter().map(|c| c.name.clone()).collect(),
        frames,
    })
}
