//! The sim scene file (docs/sim.md "Scene file"), in stages: the TOML text
//! -> its raw sections as serde reads them (`Raw*`; unknown keys are errors)
//! -> each section checked into the scene's types by its own function
//! (`RawFrames::check` -> `Frames`, `RawModel::check` -> [`Model`],
//! `check_cycles`, `check_targets`, `RawObstacle::check`, `RawWall::check`)
//! -> the sections that refer to others checked against those (`check_rigs`,
//! `reachable` + `timings`, `RawAgent::check`, `RawSpawn::check` ->
//! `Spawn`) -> [`SimScene`]. Every error names the file, the key and, for an
//! agent, its id; the first bad key in that order is the one reported.

use std::collections::{BTreeMap, BTreeSet, HashMap, HashSet};
use std::path::{Path, PathBuf};

use glam::Vec2;
use serde::Deserialize;

use super::rng::{self, Purpose};
use super::steer::wrap_angle;
use super::{
    AgentSpec, Cycle, CycleTiming, Model, Obstacle, SimScene, Target, Wall, WallShape, Weights, DEFAULT_FPS,
    MAX_AGENTS, MAX_FRAMES, MAX_RIG_CYCLES, MAX_TARGETS,
};
use crate::casting::kind::{declared_in_sim, is_character_rig};
use crate::casting::rig::Rig;
use crate::casting::skin::{SkinnedRig, StrideFrom};
use crate::error::{Error, Result};
use crate::shot::{Axis, RigKind, RigRef, SkinOptions};

/// Parses and checks scene text; `path` names it in messages.
pub(super) fn parse(text: &str, path: &Path) -> Result<SimScene> {
    // Check the version before the strict schema, so a future file says so.
    let table: toml::Table = toml::from_str(text).map_err(|e| Error::toml(path, text, e))?;
    match table.get("version") {
        Some(toml::Value::Integer(1)) => {}
        Some(v) => {
            return Err(
                Error::invalid(path, format!("unsupported scene version {v} (this throng reads 1)")).field("version")
            )
        }
        None => return Err(Error::invalid(path, "missing `version = 1`").field("version")),
    }
    let raw: RawScene = toml::from_str(text).map_err(|e| Error::toml(path, text, e))?;
    resolve(raw, path)
}

// ---------------------------------------------------------------------------
// Raw sections: the file as serde reads it
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
    rigs: BTreeMap<String, RawRig>,
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

/// A `[rigs]` entry: a glTF path, or a table mirroring a shot's
/// `[rigs.NAME]` timing keys (`file`, `kind`, and for a skinned character
/// `root`, `cycles`, `strides`, `scale`, `up`, `forward`).
enum RawRig {
    File(PathBuf),
    Table(RawRigTable),
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawRigTable {
    file: PathBuf,
    kind: Option<RigKind>,
    #[serde(default)]
    cycles: BTreeMap<String, String>,
    up: Option<Axis>,
    forward: Option<Axis>,
    scale: Option<f32>,
    root: Option<String>,
    #[serde(default)]
    strides: BTreeMap<String, f32>,
}

impl<'de> Deserialize<'de> for RawRig {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<RawRig, D::Error> {
        struct V;
        impl<'de> serde::de::Visitor<'de> for V {
            type Value = RawRig;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str(
                    "a rig glTF path, or a table with `file` (and a skinned rig's `kind`, `root`, `cycles`, ...)",
                )
            }
            fn visit_str<E: serde::de::Error>(self, v: &str) -> std::result::Result<RawRig, E> {
                Ok(RawRig::File(v.into()))
            }
            fn visit_map<A: serde::de::MapAccess<'de>>(self, map: A) -> std::result::Result<RawRig, A::Error> {
                RawRigTable::deserialize(serde::de::value::MapAccessDeserializer::new(map)).map(RawRig::Table)
            }
        }
        d.deserialize_any(V)
    }
}

impl RawRig {
    /// The entry of rig `name` -> its file (relative to `base`) and kind,
    /// checked as the shot checks `[rigs.NAME]`.
    fn check(&self, name: &str, base: &Path, path: &Path) -> Result<RigRef> {
        let t = match self {
            RawRig::File(f) => {
                return Ok(RigRef {
                    file: base.join(f),
                    schemes: BTreeMap::new(),
                    height_jitter: 0.0,
                    kind: None,
                    skin: SkinOptions::default(),
                    proportions: None,
                })
            }
            RawRig::Table(t) => t,
        };
        let f = format!("rigs.{name}");
        let skin_keys = !t.cycles.is_empty()
            || t.up.is_some()
            || t.forward.is_some()
            || t.scale.is_some()
            || t.root.is_some()
            || !t.strides.is_empty();
        check(
            path,
            !(t.kind == Some(RigKind::Slots) && skin_keys),
            format!("{f}.kind"),
            "cycles, up, forward, scale, root and strides are for `kind = \"skinned\"` and `kind = \"rigid\"` rigs",
        )?;
        let d = SkinOptions::default();
        let scale = t.scale.unwrap_or(d.scale);
        if let Some((key, msg)) = crate::shot::skin_value_problem(scale, &t.strides) {
            return Err(Error::invalid(path, msg).field(format!("{f}.{key}")));
        }
        Ok(RigRef {
            file: base.join(&t.file),
            schemes: BTreeMap::new(),
            height_jitter: 0.0,
            kind: declared_in_sim(t.kind, skin_keys),
            skin: SkinOptions {
                rigid: RigKind::rigid(t.kind),
                cycles: t.cycles.clone(),
                up: t.up.unwrap_or(d.up),
                forward: t.forward.unwrap_or(d.forward),
                scale,
                root: t.root.clone(),
                strides: t.strides.clone(),
                ..d
            },
            proportions: None,
        })
    }
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
    #[allow(
        dead_code,
        reason = "read so the file may name it; a name documents the file, the simulation never uses it"
    )]
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
    #[allow(
        dead_code,
        reason = "read so the file may name it; a name documents the file, the simulation never uses it"
    )]
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

// ---------------------------------------------------------------------------
// Checked sections
// ---------------------------------------------------------------------------

/// The raw sections -> a [`SimScene`]: the sections that stand alone, in
/// file order, then those that refer to them.
fn resolve(raw: RawScene, path: &Path) -> Result<SimScene> {
    let _ = raw.version; // checked in parse
    let frames = raw.frames.check(path)?;
    let model = raw.model.check(path)?;
    let cycles = check_cycles(&raw.cycles, path)?;
    let targets = check_targets(&raw.targets, path)?;
    let obstacles = raw
        .obstacles
        .iter()
        .enumerate()
        .map(|(i, o)| o.check(&format!("obstacles[{i}]"), path))
        .collect::<Result<_>>()?;
    let walls =
        raw.walls.iter().enumerate().map(|(i, w)| w.check(&format!("walls[{i}]"), path)).collect::<Result<_>>()?;
    let (rigs, rig_refs) = check_rigs(&raw, cycles.len(), path)?;
    let reach = reachable(&raw, &rigs, &cycles);
    let timings = timings(path, frames.fps, &rigs, &rig_refs, &cycles, &reach)?;
    let rig_files = rig_refs.into_iter().map(|r| r.map(|r| r.file)).collect();
    // Every section but the agents, which are checked against it.
    let mut scene = SimScene {
        path: path.to_path_buf(),
        seed: raw.seed,
        start: frames.start,
        end: frames.end,
        warmup: frames.warmup,
        fps: frames.fps,
        model,
        rigs,
        rig_files,
        cycles,
        timings,
        targets,
        obstacles,
        walls,
        agents: Vec::new(),
    };
    scene.agents = check_agents(&raw, &scene)?;
    Ok(scene)
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

/// `[frames]`, checked.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Frames {
    start: i32,
    end: i32,
    warmup: i32,
    fps: f32,
}

impl RawFrames {
    /// `[frames]` -> a forward range, at most [`MAX_FRAMES`] simulated
    /// (warm-up included, its first frame representable), at a positive fps
    /// ([`DEFAULT_FPS`] when not given).
    fn check(&self, path: &Path) -> Result<Frames> {
        check(path, self.end >= self.start, "frames.end", "must be >= frames.start")?;
        let warmup = i32::try_from(self.warmup)
            .ok()
            .filter(|w| self.start.checked_sub(*w).is_some())
            .ok_or_else(|| Error::invalid(path, "too large").field("frames.warmup"))?;
        let span = i64::from(self.end) - i64::from(self.start) + i64::from(warmup);
        check(path, span <= MAX_FRAMES, "frames", format!("at most {MAX_FRAMES} simulated frames"))?;
        let fps = self.fps.unwrap_or(DEFAULT_FPS);
        check(path, fps.is_finite() && fps > 0.0, "frames.fps", "must be > 0")?;
        Ok(Frames { start: self.start, end: self.end, warmup, fps })
    }
}

impl RawModel {
    /// `[model]` -> the model constants, the paper's where not given.
    fn check(&self, path: &Path) -> Result<Model> {
        let d = Model::default();
        let model = Model {
            max_turn: self.max_turn_deg.map_or(d.max_turn, f32::to_radians),
            relax_distance: self.relax_distance.unwrap_or(d.relax_distance),
            falloff: self.falloff.unwrap_or(d.falloff),
            power: self.power.unwrap_or(d.power),
            min_speed: self.min_speed.unwrap_or(d.min_speed),
            agent_radius: self.agent_radius.unwrap_or(d.agent_radius),
            chase: self.chase.unwrap_or(d.chase),
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
        Ok(model)
    }
}

/// `[cycles]` -> the cycles sorted by name (BTreeMap order), at least one.
/// Their length and stride come per rig, after the rigs (see [`timings`]).
fn check_cycles(raw: &BTreeMap<String, RawCycle>, path: &Path) -> Result<Vec<Cycle>> {
    check(path, !raw.is_empty(), "cycles", "declare at least one cycle")?;
    check(path, raw.len() <= usize::from(u16::MAX), "cycles", "too many cycles")?;
    let index: HashMap<&str, u16> = raw.keys().enumerate().map(|(i, k)| (k.as_str(), i as u16)).collect();
    raw.iter().map(|(name, c)| c.check(name, &index, path)).collect()
}

impl RawCycle {
    /// `[cycles.NAME]` -> a cycle; `index` finds the cycles `next` names.
    fn check(&self, name: &str, index: &HashMap<&str, u16>, path: &Path) -> Result<Cycle> {
        let f = format!("cycles.{name}");
        crate::cache::check_name(name).map_err(|m| Error::invalid(path, m).field(f.clone()))?;
        if let Some(l) = self.length {
            check(path, l.is_finite() && l >= 1.0, format!("{f}.length"), "must be >= 1 frame")?;
        }
        if let Some(st) = self.stride {
            check(path, st.is_finite() && st >= 0.0, format!("{f}.stride"), "must be >= 0 metres")?;
        }
        let mut next = Vec::new();
        for (n, w) in &self.next {
            let Some(&i) = index.get(n.as_str()) else {
                return Err(Error::invalid(path, format!("unknown cycle `{n}`")).field(format!("{f}.next")));
            };
            check(path, w.is_finite() && *w >= 0.0, format!("{f}.next.{n}"), "weight must be >= 0")?;
            next.push((i, *w));
        }
        if !next.is_empty() {
            check(path, next.iter().any(|&(_, w)| w > 0.0), format!("{f}.next"), "weights sum to 0")?;
        }
        Ok(Cycle { name: name.to_string(), length: self.length, stride: self.stride, next })
    }
}

/// Index of the cycle `name` in the sorted `cycles`.
fn cycle_index(cycles: &[Cycle], name: &str) -> Option<u16> {
    cycles.binary_search_by(|c| c.name.as_str().cmp(name)).ok().map(|i| i as u16)
}

/// `[[targets]]` -> the targets in file order: at most [`MAX_TARGETS`],
/// names unique.
fn check_targets(raw: &[RawTarget], path: &Path) -> Result<Vec<Target>> {
    check(path, raw.len() <= MAX_TARGETS, "targets", format!("at most {MAX_TARGETS} targets"))?;
    let mut names = HashSet::new();
    let mut targets = Vec::new();
    for (i, t) in raw.iter().enumerate() {
        let f = format!("targets[{i}]");
        targets.push(t.check(&f, path)?);
        if !names.insert(t.name.as_str()) {
            return Err(Error::invalid(path, format!("duplicate target `{}`", t.name)).field(format!("{f}.name")));
        }
    }
    Ok(targets)
}

impl RawTarget {
    /// `[[targets]]` entry at key `f` -> a target.
    fn check(&self, f: &str, path: &Path) -> Result<Target> {
        finite(path, &self.position, &format!("{f}.position"))?;
        check(path, self.radius.is_finite() && self.radius > 0.0, format!("{f}.radius"), "must be > 0")?;
        Ok(Target { name: self.name.clone(), position: Vec2::from(self.position), radius: self.radius })
    }
}

/// An agent's or spawn's `targets` (key `field`) as a bit mask over
/// `targets`; every target when not given.
fn target_mask(targets: &[Target], names: Option<&[String]>, path: &Path, field: &str) -> Result<u64> {
    let Some(names) = names else {
        return Ok(if targets.len() == 64 { u64::MAX } else { (1u64 << targets.len()) - 1 });
    };
    let mut mask = 0u64;
    for n in names {
        let Some(i) = targets.iter().position(|t| t.name == *n) else {
            return Err(Error::invalid(path, format!("unknown target `{n}`")).field(field.to_string()));
        };
        mask |= 1 << i;
    }
    Ok(mask)
}

impl RawObstacle {
    /// `[[obstacles]]` entry at key `f` -> an obstacle: a still `center` or
    /// a `path` of keys in increasing frame order.
    fn check(&self, f: &str, path: &Path) -> Result<Obstacle> {
        check(path, self.radius.is_finite() && self.radius >= 0.0, format!("{f}.radius"), "must be >= 0")?;
        let mut keys: Vec<(i32, Vec2)> = Vec::new();
        match (&self.center, self.path.is_empty()) {
            (Some(c), true) => {
                finite(path, c, &format!("{f}.center"))?;
                keys.push((0, Vec2::from(*c)));
            }
            (None, false) => {
                for (k, key) in self.path.iter().enumerate() {
                    finite(path, &key.center, &format!("{f}.path[{k}].center"))?;
                    if let Some(&(prev, _)) = keys.last() {
                        check(path, key.frame > prev, format!("{f}.path[{k}].frame"), "frames must increase")?;
                    }
                    keys.push((key.frame, Vec2::from(key.center)));
                }
            }
            _ => return Err(Error::invalid(path, "give either `center` or `path`").field(f)),
        }
        Ok(Obstacle { radius: self.radius, path: keys })
    }
}

impl RawWall {
    /// `[[walls]]` entry at key `f` -> a wall: a segment (`from`, `to`) or a
    /// plane (`point`, `normal`, normalised).
    fn check(&self, f: &str, path: &Path) -> Result<Wall> {
        check(path, self.radius.is_finite() && self.radius >= 0.0, format!("{f}.radius"), "must be >= 0")?;
        let shape = match (self.from, self.to, self.point, self.normal) {
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
        Ok(Wall { shape, radius: self.radius })
    }
}

/// The rigs: every name the agents and spawns mention, sorted, with its
/// entry from `[rigs]` (file relative to the scene file's folder) or none.
/// At most [`MAX_RIG_CYCLES`] (rig, cycle) pairs with `ncycles` cycles.
fn check_rigs(raw: &RawScene, ncycles: usize, path: &Path) -> Result<(Vec<String>, Vec<Option<RigRef>>)> {
    let mut names: BTreeSet<&str> = raw.agents.iter().map(|a| a.rig.as_str()).collect();
    for s in &raw.spawn {
        names.extend(s.rigs.keys().map(String::as_str));
    }
    check(path, names.len() <= usize::from(u16::MAX), "agents", "too many rigs")?;
    for name in &names {
        crate::cache::check_name(name).map_err(|m| Error::invalid(path, format!("bad rig name: {m}")).field("rig"))?;
    }
    check(
        path,
        names.len() * ncycles <= MAX_RIG_CYCLES,
        "cycles",
        format!("at most {MAX_RIG_CYCLES} (rig, cycle) pairs"),
    )?;
    let rigs: Vec<String> = names.iter().map(|s| s.to_string()).collect();
    let base = path.parent().unwrap_or(Path::new(""));
    let files =
        rigs.iter().map(|r| raw.rigs.get(r).map(|e| e.check(r, base, path)).transpose()).collect::<Result<_>>()?;
    Ok((rigs, files))
}

/// Index of the rig `name` in the sorted `rigs` (which [`check_rigs`] made
/// from every rig name in the file).
fn rig_index(rigs: &[String], name: &str) -> u16 {
    rigs.binary_search_by(|r| r.as_str().cmp(name)).expect("check_rigs collects every rig name") as u16
}

/// Every (rig, cycle) pair an agent can be on, with the key that first puts
/// it there (for messages): start cycles (agents', and spawns' with both
/// weights above 0), then their closure under `next`. Unknown cycle names
/// are left to the agent and spawn checks.
fn reachable(raw: &RawScene, rigs: &[String], cycles: &[Cycle]) -> BTreeMap<(u16, u16), String> {
    let mut reach: BTreeMap<(u16, u16), String> = BTreeMap::new();
    for (i, a) in raw.agents.iter().enumerate() {
        if let Some(c) = cycle_index(cycles, &a.cycle) {
            reach.entry((rig_index(rigs, &a.rig), c)).or_insert_with(|| format!("agents[{i}].cycle"));
        }
    }
    for (i, s) in raw.spawn.iter().enumerate() {
        for (r, rw) in &s.rigs {
            for (c, cw) in &s.cycles {
                if let (true, Some(ci)) = (*rw > 0.0 && *cw > 0.0, cycle_index(cycles, c)) {
                    reach.entry((rig_index(rigs, r), ci)).or_insert_with(|| format!("spawn[{i}].cycles.{c}"));
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
    reach
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
    rig_refs: &[Option<RigRef>],
    cycles: &[Cycle],
    reach: &BTreeMap<(u16, u16), String>,
) -> Result<Vec<CycleTiming>> {
    let stand_in = CycleTiming { length: 1.0, stride: 0.0 };
    let mut out = vec![stand_in; rigs.len() * cycles.len()];
    let mut loaded: Vec<Option<Loaded>> = (0..rigs.len()).map(|_| None).collect();
    let mut explicit_used = vec![false; cycles.len()];
    for (&(r, c), key) in reach {
        let (rig_name, cycle) = (&rigs[r as usize], &cycles[c as usize]);
        let timing = match &rig_refs[r as usize] {
            Some(rig_ref) => {
                let file = &rig_ref.file;
                let rig: &Loaded = match &mut loaded[r as usize] {
                    Some(rig) => rig,
                    slot @ None => slot.insert(Loaded::load(rig_ref, fps).map_err(|e| {
                        Error::invalid(path, format!("rig `{rig_name}`: {e}")).field(format!("rigs.{rig_name}"))
                    })?),
                };
                let no_cycle = |names: Vec<String>| {
                    Error::invalid(
                        path,
                        format!(
                            "rig `{rig_name}` ({}) has no cycle `{}` (its cycles: {})",
                            file.display(),
                            cycle.name,
                            names.join(", ")
                        ),
                    )
                    .field(key.clone())
                };
                let t = match rig {
                    Loaded::Slot(rig) => {
                        let Some(clip) = rig.cycles().iter().find(|k| k.name() == cycle.name) else {
                            return Err(no_cycle(rig.cycles().iter().map(|k| k.name().to_string()).collect()));
                        };
                        CycleTiming { length: clip.frames(fps), stride: clip.stride() }
                    }
                    Loaded::Skinned(rig) => {
                        let Ok((stride, length)) = rig.cycle_timing(&cycle.name) else {
                            let names = rig.cycles().iter().map(|k| format!("{} (clip {})", k.name, k.clip_name));
                            return Err(no_cycle(names.collect()));
                        };
                        // Without a root (or a rigid rig's wheels) a clip's travel
                        // is not measured: 0 would make a walk a walk on the spot.
                        if matches!(rig.stride_from(&cycle.name), Ok(StrideFrom::Unmeasured)) {
                            let (kind, what) = if rig.is_rigid() { ("rigid", "node") } else { ("skinned", "joint") };
                            return Err(Error::invalid(
                                path,
                                format!(
                                    "{kind} rig `{rig_name}` ({}) has {}, so cycle `{}` has no stride: \
                                     name its root {what} (`rigs.{rig_name}.root`) or give `rigs.{rig_name}.strides.{}` \
                                     (used by {key})",
                                    file.display(),
                                    rig.stride_sources(),
                                    cycle.name,
                                    cycle.name
                                ),
                            )
                            .field(format!("rigs.{rig_name}")));
                        }
                        CycleTiming { length, stride }
                    }
                };
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
            .filter(|&&(r, k)| k as usize == c && rig_refs[r as usize].is_some())
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

/// A `[rigs]` file as loaded for its clips' timing.
enum Loaded {
    Slot(Rig),
    Skinned(Box<SkinnedRig>),
}

impl Loaded {
    /// A slot rig, or a skinned character (declared, or detected as a shot
    /// detects one) with its options, its clips sampled at `fps`.
    fn load(rig: &RigRef, fps: f32) -> Result<Loaded> {
        Ok(if is_character_rig(rig)? {
            Loaded::Skinned(Box::new(SkinnedRig::load(&rig.file, &rig.skin, fps)?))
        } else {
            Loaded::Slot(Rig::load(&rig.file)?)
        })
    }
}

impl RawWeights {
    /// `weights = { ... }` at key `field` -> handles, 1 where not given.
    fn check(self, path: &Path, field: &str) -> Result<Weights> {
        let d = Weights::default();
        let get = |v: Option<f32>, d: f32, k: &str| -> Result<f32> {
            let v = v.unwrap_or(d);
            check(path, v.is_finite() && v >= 0.0, format!("{field}.{k}"), "weight must be >= 0")?;
            Ok(v)
        };
        Ok(Weights {
            targets: get(self.targets, d.targets, "targets")?,
            obstacles: get(self.obstacles, d.obstacles, "obstacles")?,
            walls: get(self.walls, d.walls, "walls")?,
            agents: get(self.agents, d.agents, "agents")?,
        })
    }
}

/// An agent's or spawn's `radius` at key `field`, the model's when not given.
fn agent_radius(r: Option<f32>, model: &Model, path: &Path, field: String) -> Result<f32> {
    let r = r.unwrap_or(model.agent_radius);
    check(path, r.is_finite() && r >= 0.0, field, "must be >= 0")?;
    Ok(r)
}

/// A seeded start phase in `[0, length)` of `cycle` on `rig`.
fn phase(scene: &SimScene, id: u32, rig: u16, cycle: u16) -> f32 {
    let length = scene.timing(rig, cycle).length;
    (rng::unit(scene.seed, id, Purpose::Phase, 0) as f32 * length).min(length - 1e-3)
}

/// `[[agents]]` and `[[spawn]]` -> every agent, sorted by id: at most
/// [`MAX_AGENTS`], ids unique. `scene` holds every other section.
fn check_agents(raw: &RawScene, scene: &SimScene) -> Result<Vec<AgentSpec>> {
    let mut agents = raw.agents.iter().enumerate().map(|(i, a)| a.check(i, scene)).collect::<Result<Vec<_>>>()?;
    for (i, s) in raw.spawn.iter().enumerate() {
        let spawn = s.check(i, scene)?;
        agents.extend(spawn.agents(scene));
    }
    let path = scene.path.as_path();
    check(path, agents.len() <= MAX_AGENTS, "spawn", format!("at most {MAX_AGENTS} agents in a scene"))?;
    agents.sort_by_key(|a| a.id);
    for w in agents.windows(2) {
        if w[0].id == w[1].id {
            return Err(Error::invalid(path, format!("agent id {} is used twice", w[0].id)).agent(w[0].id).field("id"));
        }
    }
    Ok(agents)
}

impl RawAgent {
    /// `agents[i]` -> an agent, checked against the scene's cycles, rigs,
    /// timings and targets; errors name the agent.
    fn check(&self, i: usize, scene: &SimScene) -> Result<AgentSpec> {
        let (a, path) = (self, scene.path.as_path());
        let f = format!("agents[{i}]");
        let inv = |msg: String, k: &str| Error::invalid(path, msg).field(format!("{f}.{k}")).agent(a.id);
        if !a.position.iter().all(|v| v.is_finite()) {
            return Err(inv("must be finite".into(), "position"));
        }
        if !a.heading_deg.is_finite() {
            return Err(inv("must be finite".into(), "heading_deg"));
        }
        let cycle =
            cycle_index(&scene.cycles, &a.cycle).ok_or_else(|| inv(format!("unknown cycle `{}`", a.cycle), "cycle"))?;
        let rig = rig_index(&scene.rigs, &a.rig);
        let c = scene.timing(rig, cycle);
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
            None => phase(scene, a.id, rig, cycle),
        };
        Ok(AgentSpec {
            id: a.id,
            position: Vec2::from(a.position),
            heading: wrap_angle(a.heading_deg.to_radians()),
            rig,
            cycle,
            cycle_frame,
            seated: a.seated,
            targets: target_mask(&scene.targets, a.targets.as_deref(), path, &format!("{f}.targets"))
                .map_err(|e| e.agent(a.id))?,
            weights: a.weights.check(path, &format!("{f}.weights")).map_err(|e| e.agent(a.id))?,
            radius: agent_radius(a.radius, &scene.model, path, format!("{f}.radius")).map_err(|e| e.agent(a.id))?,
        })
    }
}

/// A `[[spawn]]` region, checked: what its agents are drawn from.
#[derive(Clone, Debug, PartialEq)]
struct Spawn {
    count: u32,
    first_id: u32,
    min: Vec2,
    max: Vec2,
    jitter: f32,
    heading_deg: f32,
    heading_jitter_deg: f32,
    /// (rig index, weight), at least one weight > 0.
    rigs: Vec<(u16, f32)>,
    /// (cycle index, weight), at least one weight > 0.
    cycles: Vec<(u16, f32)>,
    targets: u64,
    weights: Weights,
    radius: f32,
}

impl RawSpawn {
    /// `spawn[i]` -> a region, checked against the scene's cycles, rigs and
    /// targets.
    fn check(&self, i: usize, scene: &SimScene) -> Result<Spawn> {
        let (s, path) = (self, scene.path.as_path());
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
            rig_mix.push((rig_index(&scene.rigs, n), *w));
        }
        check(path, rig_mix.iter().any(|r| r.1 > 0.0), format!("{f}.rigs"), "give at least one rig a weight > 0")?;
        let mut cycle_mix = Vec::new();
        for (n, w) in &s.cycles {
            let Some(c) = cycle_index(&scene.cycles, n) else {
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
        Ok(Spawn {
            count: s.count,
            first_id: s.first_id,
            min: lo,
            max: hi,
            jitter: s.jitter,
            heading_deg: s.heading_deg,
            heading_jitter_deg: s.heading_jitter_deg,
            rigs: rig_mix,
            cycles: cycle_mix,
            targets: target_mask(&scene.targets, s.targets.as_deref(), path, &format!("{f}.targets"))?,
            weights: s.weights.check(path, &format!("{f}.weights"))?,
            radius: agent_radius(s.radius, &scene.model, path, format!("{f}.radius"))?,
        })
    }
}

impl Spawn {
    /// The region's agents, ids `first_id..first_id + count`: a jittered
    /// grid of cells filling the rectangle keeps them apart; rig, cycle,
    /// heading, jitter and phase are keyed by id.
    fn agents<'a>(&'a self, scene: &'a SimScene) -> impl Iterator<Item = AgentSpec> + 'a {
        let seed = scene.seed;
        let (lo, hi) = (self.min, self.max);
        let n = self.count as usize;
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
        (0..n).map(move |k| {
            let id = self.first_id + k as u32;
            let (col, row) = ((k % cols) as f32, (k / cols) as f32);
            let jx = rng::unit(seed, id, Purpose::SpawnJitter, 0) as f32 - 0.5;
            let jz = rng::unit(seed, id, Purpose::SpawnJitter, 1) as f32 - 0.5;
            let position =
                lo + Vec2::new((col + 0.5 + self.jitter * jx) * cell.x, (row + 0.5 + self.jitter * jz) * cell.y);
            let hj = 2.0 * rng::unit(seed, id, Purpose::SpawnHeading, 0) as f32 - 1.0;
            let heading = wrap_angle((self.heading_deg + self.heading_jitter_deg * hj).to_radians());
            let rig = rng::choose(&self.rigs, rng::unit(seed, id, Purpose::Rig, 0)).unwrap_or(self.rigs[0].0);
            let cycle = rng::choose(&self.cycles, rng::unit(seed, id, Purpose::Cycle, 0)).unwrap_or(self.cycles[0].0);
            AgentSpec {
                id,
                position,
                heading,
                rig,
                cycle,
                cycle_frame: phase(scene, id, rig, cycle),
                seated: false,
                targets: self.targets,
                weights: self.weights,
                radius: self.radius,
            }
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn path() -> &'static Path {
        Path::new("s.toml")
    }

    /// A section as serde reads it from `text`.
    fn raw<T: serde::de::DeserializeOwned>(text: &str) -> T {
        toml::from_str(text).unwrap_or_else(|e| panic!("{e}\n{text}"))
    }

    /// The message of a check's error.
    fn err<T: std::fmt::Debug>(r: Result<T>) -> String {
        r.unwrap_err().to_string()
    }

    /// A scene with cycles W (walks 1 m in 10 frames) and I (stands, 5
    /// frames), targets a and b, and the given tables.
    fn scene_raw(body: &str) -> RawScene {
        raw(&format!(
            "version = 1\nseed = 7\n[frames]\nstart = 1\nend = 2\n\
             [cycles.W]\nlength = 10\nstride = 1\nnext = {{ W = 1, I = 1 }}\n[cycles.I]\nlength = 5\nstride = 0\n\
             [[targets]]\nname = \"a\"\nposition = [0, 0]\n[[targets]]\nname = \"b\"\nposition = [5, 0]\n{body}"
        ))
    }

    /// `scene_raw` with one agent on rig r, resolved: the context agents and
    /// spawns are checked against.
    fn context() -> SimScene {
        let body = "[[agents]]\nid = 1\nposition = [0, 0]\nrig = \"r\"\ncycle = \"W\"\n";
        resolve(scene_raw(body), path()).unwrap()
    }

    #[test]
    fn frames_defaults_and_rejections() {
        let f = raw::<RawFrames>("start = 1\nend = 48\nwarmup = 48").check(path()).unwrap();
        assert_eq!(f, Frames { start: 1, end: 48, warmup: 48, fps: DEFAULT_FPS });
        assert_eq!(raw::<RawFrames>("start = 1\nend = 1\nfps = 25").check(path()).unwrap().fps, 25.0);
        let e = |t: &str| err(raw::<RawFrames>(t).check(path()));
        assert_eq!(e("start = 2\nend = 1"), "s.toml: field `frames.end`: must be >= frames.start");
        assert_eq!(e("start = 0\nend = 1\nwarmup = 3000000000"), "s.toml: field `frames.warmup`: too large");
        assert_eq!(e("start = -2147483600\nend = 0\nwarmup = 100"), "s.toml: field `frames.warmup`: too large");
        // The span counts the warm-up: 1,000,000 frames are fine, one more is not.
        assert!(raw::<RawFrames>("start = 0\nend = 999998\nwarmup = 2").check(path()).is_ok());
        for t in ["start = 0\nend = 999999\nwarmup = 2", "start = 0\nend = 1000001"] {
            assert_eq!(e(t), "s.toml: field `frames`: at most 1000000 simulated frames");
        }
        for fps in ["0.0", "-24.0", "nan", "inf"] {
            assert_eq!(e(&format!("start = 1\nend = 2\nfps = {fps}")), "s.toml: field `frames.fps`: must be > 0");
        }
    }

    #[test]
    fn model_defaults_and_rejections() {
        assert_eq!(raw::<RawModel>("").check(path()).unwrap(), Model::default());
        let m = raw::<RawModel>("max_turn_deg = 10.0\npower = 6.0\nchase = false").check(path()).unwrap();
        assert_eq!(m, Model { max_turn: 10f32.to_radians(), power: 6.0, chase: false, ..Model::default() });
        for (key, value, msg) in [
            ("max_turn_deg", "0.0", "must be > 0"),
            ("max_turn_deg", "nan", "must be > 0"),
            ("relax_distance", "-1.0", "must be >= 0"),
            ("falloff", "0.0", "must be > 0"),
            ("power", "inf", "must be > 0"),
            ("min_speed", "1.5", "must be in [0, 1]"),
            ("min_speed", "nan", "must be in [0, 1]"),
            ("agent_radius", "-0.1", "must be >= 0"),
        ] {
            let e = err(raw::<RawModel>(&format!("{key} = {value}")).check(path()));
            assert_eq!(e, format!("s.toml: field `model.{key}`: {msg}"));
        }
    }

    #[test]
    fn cycles_sorted_with_next_indices() {
        let raw_cycles: BTreeMap<String, RawCycle> = raw("[W]\nnext = { I = 1, W = 3 }\n[I]\nlength = 5\nstride = 0");
        let cycles = check_cycles(&raw_cycles, path()).unwrap();
        assert_eq!(cycles[0], Cycle { name: "I".into(), length: Some(5.0), stride: Some(0.0), next: vec![] });
        assert_eq!(cycles[1], Cycle { name: "W".into(), length: None, stride: None, next: vec![(0, 1.0), (1, 3.0)] });
        assert_eq!(cycle_index(&cycles, "W"), Some(1));
        assert_eq!(cycle_index(&cycles, "X"), None);
    }

    #[test]
    fn cycles_rejections() {
        let e = |t: &str| err(check_cycles(&raw(t), path()));
        assert_eq!(e(""), "s.toml: field `cycles`: declare at least one cycle");
        let many: BTreeMap<String, RawCycle> = (0..=u32::from(u16::MAX))
            .map(|i| (format!("c{i}"), RawCycle { length: None, stride: None, next: BTreeMap::new() }))
            .collect();
        assert_eq!(err(check_cycles(&many, path())), "s.toml: field `cycles`: too many cycles");
        assert!(e("[\"W,1\"]").starts_with("s.toml: field `cycles.W,1`: name `W,1` holds a comma"));
        assert_eq!(e("[W]\nlength = 0.5"), "s.toml: field `cycles.W.length`: must be >= 1 frame");
        assert_eq!(e("[W]\nstride = -1.0"), "s.toml: field `cycles.W.stride`: must be >= 0 metres");
        assert_eq!(e("[W]\nnext = { X = 1 }"), "s.toml: field `cycles.W.next`: unknown cycle `X`");
        assert_eq!(e("[W]\nnext = { W = -1 }"), "s.toml: field `cycles.W.next.W`: weight must be >= 0");
        assert_eq!(e("[W]\nnext = { W = 0 }"), "s.toml: field `cycles.W.next`: weights sum to 0");
    }

    #[test]
    fn targets_in_file_order_and_masks() {
        #[derive(Deserialize)]
        struct T {
            targets: Vec<RawTarget>,
        }
        let t = |text: &str| raw::<T>(text).targets;
        let targets = check_targets(
            &t("[[targets]]\nname = \"b\"\nposition = [1, 2]\n[[targets]]\nname = \"a\"\nposition = [3, 4]\nradius = 2"),
            path(),
        )
        .unwrap();
        assert_eq!(targets[0], Target { name: "b".into(), position: Vec2::new(1.0, 2.0), radius: 1.0 });
        assert_eq!(targets[1], Target { name: "a".into(), position: Vec2::new(3.0, 4.0), radius: 2.0 });

        let mask = |names: Option<&[String]>| target_mask(&targets, names, path(), "agents[0].targets");
        assert_eq!(mask(None).unwrap(), 0b11);
        assert_eq!(mask(Some(&["a".to_string()][..])).unwrap(), 0b10);
        assert_eq!(mask(Some(&[][..])).unwrap(), 0);
        assert_eq!(err(mask(Some(&["x".to_string()][..]))), "s.toml: field `agents[0].targets`: unknown target `x`");
        assert_eq!(target_mask(&[], None, path(), "k").unwrap(), 0);

        let at = |i: usize| RawTarget { name: format!("t{i}"), position: [i as f32, 0.0], radius: 1.0 };
        let full: Vec<RawTarget> = (0..MAX_TARGETS).map(at).collect();
        assert_eq!(target_mask(&check_targets(&full, path()).unwrap(), None, path(), "k").unwrap(), u64::MAX);
        let over: Vec<RawTarget> = (0..=MAX_TARGETS).map(at).collect();
        assert_eq!(err(check_targets(&over, path())), "s.toml: field `targets`: at most 64 targets");

        let e = |text: &str| err(check_targets(&t(text), path()));
        assert_eq!(
            e("[[targets]]\nname = \"a\"\nposition = [nan, 0]"),
            "s.toml: field `targets[0].position`: must be a finite number"
        );
        assert_eq!(
            e("[[targets]]\nname = \"a\"\nposition = [0, 0]\nradius = 0"),
            "s.toml: field `targets[0].radius`: must be > 0"
        );
        assert_eq!(
            e("[[targets]]\nname = \"a\"\nposition = [0, 0]\n[[targets]]\nname = \"a\"\nposition = [1, 0]"),
            "s.toml: field `targets[1].name`: duplicate target `a`"
        );
    }

    #[test]
    fn obstacles_still_or_keyed() {
        let o = |t: &str| raw::<RawObstacle>(t).check("obstacles[2]", path());
        assert_eq!(
            o("radius = 0.5\ncenter = [1, 2]").unwrap(),
            Obstacle { radius: 0.5, path: vec![(0, Vec2::new(1.0, 2.0))] }
        );
        let moving = o("radius = 0\npath = [{ frame = 1, center = [0, 0] }, { frame = 5, center = [4, 0] }]").unwrap();
        assert_eq!(moving.path, vec![(1, Vec2::ZERO), (5, Vec2::new(4.0, 0.0))]);
        let e = |t: &str| err(o(t));
        assert_eq!(e("radius = -1\ncenter = [0, 0]"), "s.toml: field `obstacles[2].radius`: must be >= 0");
        assert_eq!(e("radius = 1"), "s.toml: field `obstacles[2]`: give either `center` or `path`");
        assert_eq!(
            e("radius = 1\ncenter = [0, 0]\npath = [{ frame = 1, center = [0, 0] }]"),
            "s.toml: field `obstacles[2]`: give either `center` or `path`"
        );
        assert_eq!(e("radius = 1\ncenter = [0, inf]"), "s.toml: field `obstacles[2].center`: must be a finite number");
        assert_eq!(
            e("radius = 1\npath = [{ frame = 1, center = [0, 0] }, { frame = 2, center = [nan, 0] }]"),
            "s.toml: field `obstacles[2].path[1].center`: must be a finite number"
        );
        assert_eq!(
            e("radius = 1\npath = [{ frame = 3, center = [0, 0] }, { frame = 3, center = [1, 0] }]"),
            "s.toml: field `obstacles[2].path[1].frame`: frames must increase"
        );
    }

    #[test]
    fn walls_segment_or_plane() {
        let w = |t: &str| raw::<RawWall>(t).check("walls[1]", path());
        let seg = w("from = [0, 0]\nto = [2, 0]\nradius = 0.25").unwrap();
        assert_eq!(seg, Wall { shape: WallShape::Segment(Vec2::ZERO, Vec2::new(2.0, 0.0)), radius: 0.25 });
        let plane = w("point = [1, 0]\nnormal = [-3, 0]").unwrap();
        assert_eq!(plane, Wall { shape: WallShape::Plane { point: Vec2::X, normal: -Vec2::X }, radius: 0.0 });
        let e = |t: &str| err(w(t));
        assert_eq!(e("from = [0, 0]\nto = [2, 0]\nradius = -1"), "s.toml: field `walls[1].radius`: must be >= 0");
        let either = "s.toml: field `walls[1]`: a wall is a segment (`from`, `to`) or a plane (`point`, `normal`)";
        for t in ["from = [0, 0]", "from = [0, 0]\nnormal = [1, 0]", "from = [0, 0]\nto = [1, 0]\npoint = [0, 0]", ""] {
            assert_eq!(e(t), either, "{t}");
        }
        assert_eq!(e("from = [0, 0]\nto = [nan, 0]"), "s.toml: field `walls[1].to`: must be a finite number");
        assert_eq!(e("point = [inf, 0]\nnormal = [1, 0]"), "s.toml: field `walls[1].point`: must be a finite number");
        assert_eq!(e("point = [0, 0]\nnormal = [0, 0]"), "s.toml: field `walls[1].normal`: must not be zero");
    }

    #[test]
    fn rigs_sorted_with_files_beside_the_scene() {
        let scene = scene_raw(
            "[rigs]\nzed = \"rigs/zed.glb\"\nunused = \"u.glb\"\n\
             [[agents]]\nid = 1\nposition = [0, 0]\nrig = \"zed\"\ncycle = \"W\"\n\
             [[spawn]]\ncount = 1\nfirst_id = 9\nmin = [0, 0]\nmax = [1, 1]\nrigs = { mid = 1, alpha = 0 }\ncycles = { W = 1 }\n",
        );
        let (rigs, files) = check_rigs(&scene, 2, Path::new("shots/s.toml")).unwrap();
        assert_eq!(rigs, ["alpha", "mid", "zed"]);
        let files: Vec<Option<PathBuf>> = files.into_iter().map(|r| r.map(|r| r.file)).collect();
        assert_eq!(files, [None, None, Some(PathBuf::from("shots/rigs/zed.glb"))]);
        assert_eq!(rig_index(&rigs, "mid"), 1);
        assert_eq!(
            err(check_rigs(&scene, MAX_RIG_CYCLES / 2, path())),
            "s.toml: field `cycles`: at most 1048576 (rig, cycle) pairs"
        );
        assert!(check_rigs(&scene, MAX_RIG_CYCLES / 3, path()).is_ok());

        let bad = scene_raw("[[agents]]\nid = 1\nposition = [0, 0]\nrig = \" r\"\ncycle = \"W\"\n");
        assert_eq!(
            err(check_rigs(&bad, 2, path())),
            "s.toml: field `rig`: bad rig name: name ` r` has leading or trailing spaces"
        );
        let mut many = scene_raw("");
        many.spawn.push(raw("count = 0\nfirst_id = 0\nmin = [0, 0]\nmax = [0, 0]\ncycles = { W = 1 }\nrigs = {}"));
        many.spawn[0].rigs = (0..=u32::from(u16::MAX)).map(|i| (format!("r{i}"), 1.0)).collect();
        assert_eq!(err(check_rigs(&many, 1, path())), "s.toml: field `agents`: too many rigs");
    }

    #[test]
    fn reachable_pairs_start_cycles_then_next() {
        // W's next reaches W and I; I has no next; spawn weights 0 reach nothing.
        let scene = scene_raw(
            "[[agents]]\nid = 1\nposition = [0, 0]\nrig = \"b\"\ncycle = \"I\"\n\
             [[agents]]\nid = 2\nposition = [0, 0]\nrig = \"b\"\ncycle = \"Nope\"\n\
             [[spawn]]\ncount = 1\nfirst_id = 9\nmin = [0, 0]\nmax = [1, 1]\nrigs = { a = 1, c = 0 }\ncycles = { W = 1, I = 0 }\n",
        );
        let (rigs, _) = check_rigs(&scene, 2, path()).unwrap();
        let cycles = check_cycles(&scene.cycles, path()).unwrap();
        let reach = reachable(&scene, &rigs, &cycles);
        let (a, b, i, w) = (0u16, 1u16, 0u16, 1u16);
        let expected: BTreeMap<(u16, u16), String> = [
            ((a, i), "cycles.W.next.I".to_string()),
            ((a, w), "spawn[0].cycles.W".to_string()),
            ((b, i), "agents[0].cycle".to_string()),
        ]
        .into();
        assert_eq!(reach, expected);
    }

    #[test]
    fn timings_explicit_for_rigs_without_a_file() {
        let scene = resolve(scene_raw("[[agents]]\nid = 1\nposition = [0, 0]\nrig = \"r\"\ncycle = \"I\"\n"), path());
        let scene = scene.unwrap();
        assert_eq!(scene.timing(0, 0), CycleTiming { length: 5.0, stride: 0.0 });
        // W is not reachable from I: a stand-in.
        assert_eq!(scene.timing(0, 1), CycleTiming { length: 1.0, stride: 0.0 });

        let cycles = check_cycles(&raw("[W]\nstride = 1"), path()).unwrap();
        let reach: BTreeMap<(u16, u16), String> = [((0, 0), "agents[3].cycle".to_string())].into();
        let rigs = ["r".to_string()];
        assert_eq!(
            err(timings(path(), 24.0, &rigs, &[None], &cycles, &reach)),
            "s.toml: field `cycles.W.length`: rig `r` has no file in [rigs], so `W` needs an explicit length \
             (used by agents[3].cycle)"
        );
        let e = err(timings(path(), 24.0, &rigs, &[slot("nope/r.glb")], &cycles, &reach));
        assert!(e.starts_with("s.toml: field `rigs.r`: rig `r`: ") && e.contains("nope/r.glb"), "{e}");
    }

    /// A `[rigs]` entry that is a bare path.
    fn slot(file: impl AsRef<Path>) -> Option<RigRef> {
        Some(RawRig::File(file.as_ref().into()).check("r", Path::new(""), path()).unwrap())
    }

    #[test]
    fn skinned_rig_tables_time_cycles_from_their_clips() {
        let walker = Path::new(env!("CARGO_MANIFEST_DIR")).join("demo/rigs/walker.glb");
        let entry = |keys: &str| -> Result<Option<RigRef>> {
            let text = format!("file = {:?}\n{keys}", walker.display().to_string());
            raw::<RawRig>(&text).check("walker", Path::new(""), path()).map(Some)
        };
        let rigs = ["walker".to_string()];
        let cycles = check_cycles(&raw("[IdleA]\n[WalkA]"), path()).unwrap();
        let reach: BTreeMap<(u16, u16), String> =
            [((0, 0), "agents[1].cycle".to_string()), ((0, 1), "agents[0].cycle".to_string())].into();
        // As the demo shot declares it: WalkA plays Walk (32 frames, hips 1.4 m), IdleA Idle.
        let shot_keys = "kind = \"skinned\"\nroot = \"hips\"\ncycles = { WalkA = \"Walk\", IdleA = \"Idle\" }";
        let r = entry(shot_keys).unwrap();
        let t = timings(path(), 24.0, &rigs, std::slice::from_ref(&r), &cycles, &reach).unwrap();
        let skinned = SkinnedRig::load(&walker, &r.as_ref().unwrap().skin, 24.0).unwrap();
        let timing = |c: &str| skinned.cycle_timing(c).unwrap();
        assert_eq!(t[1], CycleTiming { length: timing("WalkA").1, stride: timing("WalkA").0 });
        assert!((t[1].length - 32.0).abs() < 1e-3 && (t[1].stride - 1.4).abs() < 1e-3, "{:?}", t[1]);
        assert_eq!(t[0], CycleTiming { length: timing("IdleA").1, stride: 0.0 });
        assert!((t[0].length - 48.0).abs() < 1e-3, "{:?}", t[0]);
        // The clip is sampled at the scene's rate; `strides` wins over the root's travel.
        let t = timings(path(), 30.0, &rigs, &[r], &cycles, &reach).unwrap();
        assert!((t[1].length - 40.0).abs() < 1e-3, "{:?}", t[1]);
        let r = entry(&format!("{shot_keys}\nstrides = {{ WalkA = 1.2 }}")).unwrap();
        assert_eq!(timings(path(), 24.0, &rigs, &[r], &cycles, &reach).unwrap()[1].stride, 1.2);

        // Skin keys alone make it skinned; without a root a cycle needs its stride.
        let r = entry("cycles = { WalkA = \"Walk\", IdleA = \"Idle\" }").unwrap();
        let e = err(timings(path(), 24.0, &rigs, &[r], &cycles, &reach));
        assert!(e.starts_with("s.toml: field `rigs.walker`: skinned rig `walker`") && e.contains("`IdleA`"), "{e}");
        assert!(e.contains("rigs.walker.root") && e.contains("rigs.walker.strides.IdleA"), "{e}");
        // A bare path is detected as skinned (no root, so the same error).
        let walk = check_cycles(&raw("[Walk]"), path()).unwrap();
        let first: BTreeMap<(u16, u16), String> = [((0, 0), "agents[0].cycle".to_string())].into();
        let e = err(timings(path(), 24.0, &rigs, &[slot(&walker)], &walk, &first));
        assert!(e.contains("has no `root` joint, so cycle `Walk` has no stride"), "{e}");
        // A cycle the file lacks lists the cycles and their clips.
        let r = entry("root = \"hips\"").unwrap();
        let e = err(timings(path(), 24.0, &rigs, &[r], &cycles, &reach));
        assert!(
            e.contains("agents[1].cycle") && e.contains("no cycle `IdleA`") && e.contains("Walk (clip Walk)"),
            "{e}"
        );
        // A bad root joint names the rig entry and lists the joints.
        let r = entry("root = \"nope\"").unwrap();
        let e = err(timings(path(), 24.0, &rigs, &[r], &cycles, &reach));
        assert!(e.starts_with("s.toml: field `rigs.walker`") && e.contains("hips"), "{e}");
        // Keys checked as the shot checks them.
        assert!(err(entry("kind = \"slots\"\nroot = \"hips\"")).contains("`rigs.walker.kind`"));
        assert!(err(entry("scale = 0")).contains("`rigs.walker.scale`"));
        assert!(err(entry("strides = { WalkA = -1 }")).contains("`rigs.walker.strides.WalkA`"));
    }

    #[test]
    fn timings_from_rig_files_win() {
        let file = Path::new(env!("CARGO_MANIFEST_DIR")).join("demo/rigs/bipedThinA.glb");
        let rig = crate::casting::rig::Rig::load(&file).unwrap();
        let walk = rig.cycles().iter().find(|c| c.name() == "WalkA").unwrap();
        let rigs = ["bipedThinA".to_string()];
        let reach: BTreeMap<(u16, u16), String> = [((0, 0), "agents[0].cycle".to_string())].into();
        let cycles = check_cycles(&raw("[WalkA]"), path()).unwrap();
        let t = timings(path(), 30.0, &rigs, &[slot(&file)], &cycles, &reach).unwrap();
        assert_eq!(t, [CycleTiming { length: walk.frames(30.0), stride: walk.stride() }]);
        assert!(t[0].moves() && t[0].length > 1.0);

        let explicit = check_cycles(&raw("[WalkA]\nlength = 3"), path()).unwrap();
        let e = err(timings(path(), 30.0, &rigs, &[slot(&file)], &explicit, &reach));
        assert!(e.starts_with("s.toml: field `cycles.WalkA.length`: every rig on `WalkA` (bipedThinA)"), "{e}");
        let missing = check_cycles(&raw("[NoSuch]"), path()).unwrap();
        let e = err(timings(path(), 30.0, &rigs, &[slot(&file)], &missing, &reach));
        assert!(e.starts_with("s.toml: field `agents[0].cycle`: rig `bipedThinA`") && e.contains("no cycle `NoSuch`"));
    }

    #[test]
    fn agent_defaults_from_the_scene() {
        let scene = context();
        let a = raw::<RawAgent>("id = 4\nposition = [1, 2]\nheading_deg = 270\nrig = \"r\"\ncycle = \"W\"")
            .check(0, &scene)
            .unwrap();
        assert_eq!((a.id, a.position, a.rig, a.cycle, a.seated), (4, Vec2::new(1.0, 2.0), 0, 1, false));
        assert!((a.heading + 90f32.to_radians()).abs() < 1e-6, "wrapped into (-pi, pi]: {}", a.heading);
        assert!((0.0..10.0).contains(&a.cycle_frame));
        assert_eq!((a.targets, a.weights, a.radius), (0b11, Weights::default(), 0.3));
        // The phase is keyed by id: another id, another phase; the same id, the same.
        let b = raw::<RawAgent>("id = 5\nposition = [1, 2]\nrig = \"r\"\ncycle = \"W\"").check(0, &scene).unwrap();
        assert_ne!(a.cycle_frame, b.cycle_frame);
        assert_eq!(phase(&scene, 4, 0, 1), a.cycle_frame);

        let given = raw::<RawAgent>(
            "id = 4\nposition = [0, 0]\nrig = \"r\"\ncycle = \"I\"\ncycle_frame = 4.5\nseated = true\n\
             targets = [\"b\"]\nweights = { walls = 0 }\nradius = 0.5",
        )
        .check(0, &scene)
        .unwrap();
        assert_eq!(
            (given.cycle, given.cycle_frame, given.seated, given.targets, given.radius),
            (0, 4.5, true, 0b10, 0.5)
        );
        assert_eq!(given.weights, Weights { walls: 0.0, ..Weights::default() });
    }

    #[test]
    fn agent_rejections_name_the_agent() {
        let scene = context();
        let base = "id = 4\nrig = \"r\"\n";
        for (keys, field, msg) in [
            ("position = [nan, 0]\ncycle = \"W\"", "position", "must be finite"),
            ("position = [0, 0]\nheading_deg = inf\ncycle = \"W\"", "heading_deg", "must be finite"),
            ("position = [0, 0]\ncycle = \"Nope\"", "cycle", "unknown cycle `Nope`"),
            (
                "position = [0, 0]\ncycle = \"W\"\nseated = true",
                "cycle",
                "seated agents need a cycle with stride 0, `W` walks 1 m on rig `r`",
            ),
            (
                "position = [0, 0]\ncycle = \"W\"\ncycle_frame = 10",
                "cycle_frame",
                "must be in [0, 10) (`W` on rig `r`)",
            ),
            ("position = [0, 0]\ncycle = \"I\"\ncycle_frame = -1", "cycle_frame", "must be in [0, 5) (`I` on rig `r`)"),
            ("position = [0, 0]\ncycle = \"W\"\ntargets = [\"x\"]", "targets", "unknown target `x`"),
            ("position = [0, 0]\ncycle = \"W\"\nweights = { agents = -1 }", "weights.agents", "weight must be >= 0"),
            ("position = [0, 0]\ncycle = \"W\"\nradius = -0.1", "radius", "must be >= 0"),
        ] {
            let e = err(raw::<RawAgent>(&format!("{base}{keys}")).check(3, &scene));
            assert_eq!(e, format!("s.toml: agent 4, field `agents[3].{field}`: {msg}"));
        }
    }

    const SPAWN: &str =
        "count = 6\nfirst_id = 10\nmin = [0, 0]\nmax = [3, 2]\nrigs = { r = 1 }\ncycles = { W = 1, I = 1 }";

    #[test]
    fn spawn_fills_its_rectangle() {
        let scene = context();
        let spawn = raw::<RawSpawn>(SPAWN).check(0, &scene).unwrap();
        assert_eq!((spawn.rigs.clone(), spawn.cycles.clone()), (vec![(0, 1.0)], vec![(0, 1.0), (1, 1.0)]));
        assert_eq!((spawn.targets, spawn.jitter, spawn.radius), (0b11, 0.8, 0.3));
        let agents: Vec<AgentSpec> = spawn.agents(&scene).collect();
        assert_eq!(agents.iter().map(|a| a.id).collect::<Vec<_>>(), (10..16).collect::<Vec<_>>());
        // 6 cells of 1 x 1 m in 3 columns, 2 rows: one agent per cell.
        let mut cells: Vec<(i32, i32)> =
            agents.iter().map(|a| (a.position.x.floor() as i32, a.position.y.floor() as i32)).collect();
        cells.sort();
        assert_eq!(cells, [(0, 0), (0, 1), (1, 0), (1, 1), (2, 0), (2, 1)]);
        for a in &agents {
            assert!(!a.seated && a.cycle_frame < scene.timing(a.rig, a.cycle).length, "{a:?}");
        }
        // Both cycles drawn (keyed by id: the same every time).
        assert!(agents.iter().any(|a| a.cycle == 0) && agents.iter().any(|a| a.cycle == 1));
        assert_eq!(agents, spawn.agents(&scene).collect::<Vec<_>>());
    }

    #[test]
    fn spawn_rejections() {
        let scene = context();
        let with = |replace: (&str, &str), extra: &str| {
            let text = format!("{}\n{extra}", SPAWN.replace(replace.0, replace.1));
            err(raw::<RawSpawn>(&text).check(2, &scene))
        };
        let none = ("", "");
        for (replace, extra, field, msg) in [
            (("min = [0, 0]", "min = [nan, 0]"), "", "min", "must be a finite number"),
            (("max = [3, 2]", "max = [3, inf]"), "", "max", "must be a finite number"),
            (("max = [3, 2]", "max = [3, -1]"), "", "max", "must be >= min in x and z"),
            (none, "jitter = 1.5", "jitter", "must be in [0, 1]"),
            (none, "heading_jitter_deg = nan", "heading_deg", "must be a finite number"),
            (("first_id = 10", "first_id = 4294967295"), "", "count", "ids overflow u32"),
            (("count = 6", "count = 10000001"), "", "count", "at most 10000000 agents"),
            (("rigs = { r = 1 }", "rigs = { r = -1 }"), "", "rigs.r", "weight must be >= 0"),
            (("rigs = { r = 1 }", "rigs = { r = 0 }"), "", "rigs", "give at least one rig a weight > 0"),
            (("W = 1", "X = 1"), "", "cycles", "unknown cycle `X`"),
            (("W = 1", "W = -1"), "", "cycles.W", "weight must be >= 0"),
            (("W = 1, I = 1", "W = 0"), "", "cycles", "give at least one cycle a weight > 0"),
            (none, "targets = [\"x\"]", "targets", "unknown target `x`"),
            (none, "weights = { targets = nan }", "weights.targets", "weight must be >= 0"),
            (none, "radius = -1", "radius", "must be >= 0"),
        ] {
            assert_eq!(with(replace, extra), format!("s.toml: field `spawn[2].{field}`: {msg}"), "{extra}");
        }
    }

    #[test]
    fn agents_sorted_by_id_and_unique() {
        let spawn = format!("[[spawn]]\n{SPAWN}\n");
        let agent = |id: u32| format!("[[agents]]\nid = {id}\nposition = [0, 0]\nrig = \"r\"\ncycle = \"W\"\n");
        let scene = resolve(scene_raw(&format!("{}{}{spawn}", agent(20), agent(3))), path()).unwrap();
        let ids: Vec<u32> = scene.agents.iter().map(|a| a.id).collect();
        assert_eq!(ids, [3, 10, 11, 12, 13, 14, 15, 20]);
        let e = err(resolve(scene_raw(&format!("{}{spawn}", agent(12))), path()));
        assert_eq!(e, "s.toml: agent 12, field `id`: agent id 12 is used twice");
    }

    #[test]
    fn resolve_reports_sections_in_file_order() {
        // A scene wrong in [frames] and in an agent reports [frames]; one
        // wrong in a cycle and a target reports the cycle.
        let agent = "[[agents]]\nid = 1\nposition = [nan, 0]\nrig = \"r\"\ncycle = \"W\"\n";
        let mut both = scene_raw(agent);
        both.frames.end = 0;
        assert_eq!(err(resolve(both, path())), "s.toml: field `frames.end`: must be >= frames.start");
        let mut cycle_and_target = scene_raw("");
        cycle_and_target.cycles.get_mut("W").unwrap().length = Some(0.0);
        cycle_and_target.targets[0].radius = 0.0;
        assert_eq!(err(resolve(cycle_and_target, path())), "s.toml: field `cycles.W.length`: must be >= 1 frame");
        assert_eq!(
            err(resolve(scene_raw(agent), path())),
            "s.toml: agent 1, field `agents[0].position`: must be finite"
        );
    }
}
