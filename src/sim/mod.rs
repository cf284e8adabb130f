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

mod file;
pub(crate) mod grid;
mod rng;
pub mod steer;

use std::path::{Path, PathBuf};

use glam::{Vec2, Vec3};
use rayon::prelude::*;

use crate::cache::{AgentSample, CrowdCache, FrameBlock, SEATED};
use crate::error::{IoContext, Result};
use rng::Purpose;
use steer::{forward, heading_of, wrap_angle, Steer};

/// Most targets a scene may declare (each agent keeps its visited targets
/// in a 64-bit mask).
pub(crate) const MAX_TARGETS: usize = 64;
/// Most agents in a scene (a guard against typos such as `count = 1e9`).
pub(crate) const MAX_AGENTS: usize = 10_000_000;
/// Most frames a scene may simulate (warm-up included).
pub(crate) const MAX_FRAMES: i64 = 1_000_000;
/// Frames per second when `[frames] fps` is not given (SPEC: shot fps 24).
pub(crate) const DEFAULT_FPS: f32 = 24.0;
/// Most (rig, cycle) pairs a scene may have (the timing table's size).
pub(crate) const MAX_RIG_CYCLES: usize = 1 << 20;

// ---------------------------------------------------------------------------
// Resolved scene
// ---------------------------------------------------------------------------

/// Constants of the steering model; the defaults are the paper's.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Model {
    /// Largest turn per frame away from objects, radians (5 degrees).
    pub(crate) max_turn: f32,
    /// Gap (metres) under which the turn limit relaxes: the paper's 5 units.
    pub(crate) relax_distance: f32,
    /// Metres per unit of `d` in `D(d) = 1 / 2^d` (1: d in metres).
    pub(crate) falloff: f32,
    /// Power `D` is raised to for agents, obstacles and walls (12).
    pub(crate) power: f32,
    /// Slowest walk near objects, as a fraction of the cycle's speed (0.9).
    pub(crate) min_speed: f32,
    /// Agent radius (metres) when an agent gives none.
    pub(crate) agent_radius: f32,
    /// Attenuate other agents by chase (the paper's model; off only to
    /// show the shaking it prevents).
    pub(crate) chase: bool,
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
    pub(crate) length: Option<f32>,
    /// Explicit stride in metres (`[cycles.X] stride`), for rigs without a file.
    pub(crate) stride: Option<f32>,
    /// Cycles to switch to when this one ends: (cycle index, weight).
    /// Empty: the agent stays on this cycle.
    pub(crate) next: Vec<(u16, f32)>,
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
    pub(crate) radius: f32,
    /// Centre keys `(frame, (x, z))` in increasing frame order, at least one;
    /// linear between keys, held before the first and after the last.
    pub(crate) path: Vec<(i32, Vec2)>,
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
pub(crate) enum WallShape {
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
    pub(crate) shape: WallShape,
    /// Half thickness in metres.
    pub(crate) radius: f32,
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
pub(crate) struct Weights {
    /// Goal attraction.
    pub(crate) targets: f32,
    /// Obstacle repulsion.
    pub(crate) obstacles: f32,
    /// Wall repulsion.
    pub(crate) walls: f32,
    /// Repulsion from other agents.
    pub(crate) agents: f32,
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
    pub(crate) id: u32,
    /// Ground-plane start position `(x, z)`.
    pub position: Vec2,
    /// Start heading, radians.
    pub(crate) heading: f32,
    /// Index into [`SimScene::rigs`].
    pub(crate) rig: u16,
    /// Start cycle, index into [`SimScene::cycles`].
    pub(crate) cycle: u16,
    /// Start cycle frame.
    pub(crate) cycle_frame: f32,
    /// Seated: never moves, never switches cycle.
    pub(crate) seated: bool,
    /// Targets this agent visits, as a bit mask over [`SimScene::targets`].
    pub(crate) targets: u64,
    /// Handles.
    pub(crate) weights: Weights,
    /// Radius in metres.
    pub(crate) radius: f32,
}

/// A simulation scene, validated.
#[derive(Clone, Debug, PartialEq)]
pub struct SimScene {
    /// The file it came from (for messages).
    pub(crate) path: PathBuf,
    /// Seed of every random choice.
    pub(crate) seed: u64,
    /// First cache frame written.
    pub start: i32,
    /// Last cache frame written.
    pub end: i32,
    /// Frames simulated before `start` and not written; agents start at
    /// frame `start - warmup`.
    pub(crate) warmup: i32,
    /// Frames per second of the cache (cycle lengths from rig files are
    /// `duration * fps`).
    pub(crate) fps: f32,
    /// Model constants.
    pub(crate) model: Model,
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
    pub(crate) timings: Vec<CycleTiming>,
    /// Targets in file order.
    pub targets: Vec<Target>,
    /// Obstacles.
    pub obstacles: Vec<Obstacle>,
    /// Walls.
    pub walls: Vec<Wall>,
    /// Agents, sorted by id.
    pub agents: Vec<AgentSpec>,
}

impl SimScene {
    /// Reads and validates a scene file.
    pub fn load(path: impl AsRef<Path>) -> Result<SimScene> {
        let path = path.as_ref();
        crate::error::check_readable_file(path)?;
        let text = std::fs::read_to_string(path).at(path)?;
        SimScene::parse(&text, path)
    }

    /// Parses and validates scene text; `path` names it in messages.
    pub fn parse(text: &str, path: impl AsRef<Path>) -> Result<SimScene> {
        file::parse(text, path.as_ref())
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

// ---------------------------------------------------------------------------
// Simulation
// ---------------------------------------------------------------------------

/// One agent's state at one frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AgentState {
    /// Ground-plane position `(x, z)`.
    pub position: Vec2,
    /// Heading, radians in (-pi, pi].
    pub(crate) heading: f32,
    /// Metres walked in the last frame (0 when standing).
    pub(crate) speed: f32,
    /// Index into [`SimScene::cycles`].
    pub(crate) cycle: u16,
    /// Frame within the cycle.
    pub(crate) cycle_frame: f32,
    /// Target being walked to, index into [`SimScene::targets`].
    pub target: Option<u8>,
    /// Targets visited since the agent last ran out of targets (bit mask).
    pub(crate) visited: u64,
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
    pub(crate) fn record(&self) -> FrameBlock {
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
