//! An interim procedural crowd cache (CSV) until the steering simulation
//! writes the real one: walkers on straight or gently curving paths, idlers,
//! and twelve agents seated on the benches. No two agents come closer than
//! MIN_GAP at any frame.

use std::f32::consts::PI;
use std::fmt::Write as _;
use std::path::Path;
use throng::error::{write_atomic, IoContext, Result};

use crate::rigs::{ClipSpec, RigSpec};
use crate::set::{BENCH_LEN, BENCH_XS, BENCH_Z, SEATED_Z, SEAT_DEPTH, SEAT_OFFSETS};

/// Cache frames 1..=FRAMES (shot 1001..1048 with frame_offset -1000).
pub const FRAMES: usize = 48;
/// Agents in the cache (seated + idle + walking).
pub const AGENTS: usize = 300;
/// Idle agents standing in pairs (facing each other) and alone.
const IDLE_PAIRS: usize = 10;
const IDLE_SINGLES: usize = 12;
/// Walkers deliberately placed to cross the area's edge during the shot.
const EDGE_WALKERS: usize = 10;
/// Closest two agents may come (the brief asks for >= 0.7 m).
const MIN_GAP: f32 = 0.8;
/// Agent area (SPEC): x in [-18, 18], z in [-30, 12].
const AREA_X: [f32; 2] = [-18.0, 18.0];
const AREA_Z: [f32; 2] = [-30.0, 12.0];
/// Walkers keep this far from a bench's footprint (seated knees and feet included).
const BENCH_CLEARANCE: f32 = 0.5;
/// Largest turn rate of a curving walker, radians per frame.
const MAX_TURN: f32 = 0.006;
/// Fewest frames an edge walker is inside the area.
const MIN_FRAMES: usize = 8;
/// Chance that an id is skipped, so ids are not contiguous.
const ID_GAP_CHANCE: f32 = 0.04;
const SEED: u64 = 0x7412_0001;

/// SplitMix64: tiny, deterministic, good enough for placing robots.
struct Rng(u64);

impl Rng {
    fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }
    /// Uniform in [0, 1).
    fn unit(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }
    fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.unit()
    }
    fn below(&mut self, n: u32) -> u32 {
        (self.next_u64() % n as u64) as u32
    }
    fn chance(&mut self, p: f32) -> bool {
        self.unit() < p
    }
}

/// Where an agent is on one frame: x, z, heading.
type Pose = (f32, f32, f32);

/// One agent's whole track.
struct Agent {
    id: u32,
    rig: &'static str,
    clip: ClipSpec,
    start_cycle_frame: u32,
    seated: bool,
    /// Per cache frame 1..=FRAMES; None while the agent is not in the shot.
    poses: Vec<Option<Pose>>,
}

/// Summary printed by the generator.
pub struct Stats {
    pub agents: usize,
    pub walking: usize,
    pub idle: usize,
    pub seated: usize,
    pub entering: usize,
    pub leaving: usize,
    pub min_gap: f32,
}

fn inside_area(x: f32, z: f32) -> bool {
    (AREA_X[0]..=AREA_X[1]).contains(&x) && (AREA_Z[0]..=AREA_Z[1]).contains(&z)
}

fn near_bench(x: f32, z: f32) -> bool {
    let z_lo = BENCH_Z - SEAT_DEPTH / 2.0 - BENCH_CLEARANCE;
    let z_hi = SEATED_Z + 0.2 + BENCH_CLEARANCE;
    BENCH_XS.iter().any(|bx| (x - bx).abs() < BENCH_LEN / 2.0 + BENCH_CLEARANCE && (z_lo..=z_hi).contains(&z))
}

fn wrap_angle(a: f32) -> f32 {
    let mut a = a % (2.0 * PI);
    if a > PI {
        a -= 2.0 * PI;
    } else if a <= -PI {
        a += 2.0 * PI;
    }
    a
}

/// Heading that faces from a to b (0 faces +Z).
fn heading_towards(a: (f32, f32), b: (f32, f32)) -> f32 {
    (b.0 - a.0).atan2(b.1 - a.1)
}

/// A walking track from frame 1: advance stride/cycle_length per frame along
/// the current heading, turning by `turn` per frame. Present only inside the area.
fn walk_track(x0: f32, z0: f32, h0: f32, speed: f32, turn: f32) -> Vec<Option<Pose>> {
    let (mut x, mut z, mut h) = (x0, z0, h0);
    (0..FRAMES)
        .map(|_| {
            let pose = inside_area(x, z).then_some((x, z, wrap_angle(h)));
            x += speed * h.sin();
            z += speed * h.cos();
            h += turn;
            pose
        })
        .collect()
}

/// True when the track keeps clear of benches and of every agent placed so far.
fn fits(poses: &[Option<Pose>], placed: &[Agent]) -> bool {
    for (f, p) in poses.iter().enumerate() {
        let Some((x, z, _)) = p else { continue };
        if near_bench(*x, *z) {
            return false;
        }
        for a in placed {
            if let Some((ax, az, _)) = a.poses[f] {
                if (ax - x).powi(2) + (az - z).powi(2) < MIN_GAP * MIN_GAP {
                    return false;
                }
            }
        }
    }
    true
}

fn pick_rig<'a>(rng: &mut Rng, rigs: &'a [RigSpec]) -> &'a RigSpec {
    // Thin robots are the majority.
    if rng.chance(0.6) {
        &rigs[0]
    } else {
        &rigs[rigs.len() - 1]
    }
}

/// A walker's heading: towards or away from camera, across, or anything.
fn pick_heading(rng: &mut Rng) -> f32 {
    let base = match rng.below(10) {
        0..=1 => 0.0,
        2..=3 => PI,
        4..=5 => PI / 2.0,
        6..=7 => -PI / 2.0,
        _ => rng.range(-PI, PI),
    };
    base + rng.range(-0.35, 0.35)
}

struct Ids {
    next: u32,
}

impl Ids {
    fn take(&mut self, rng: &mut Rng) -> u32 {
        while rng.chance(ID_GAP_CHANCE) {
            self.next += 1;
        }
        self.next += 1;
        self.next
    }
}

fn seated_agents(rng: &mut Rng, rigs: &[RigSpec], ids: &mut Ids, out: &mut Vec<Agent>) {
    for bx in BENCH_XS {
        for dx in SEAT_OFFSETS {
            let rig = pick_rig(rng, rigs);
            out.push(Agent {
                id: ids.take(rng),
                rig: rig.name,
                clip: rig.sit,
                start_cycle_frame: rng.below(rig.sit.frames),
                seated: true,
                poses: vec![Some((bx + dx, SEATED_Z, 0.0)); FRAMES],
            });
        }
    }
}

fn idle_agent(rng: &mut Rng, rig: &RigSpec, id: u32, pose: Pose) -> Agent {
    Agent {
        id,
        rig: rig.name,
        clip: rig.idle,
        start_cycle_frame: rng.below(rig.idle.frames),
        seated: false,
        poses: vec![Some(pose); FRAMES],
    }
}

fn idle_agents(rng: &mut Rng, rigs: &[RigSpec], ids: &mut Ids, out: &mut Vec<Agent>) {
    let mut pairs = 0;
    let mut singles = 0;
    while pairs < IDLE_PAIRS || singles < IDLE_SINGLES {
        let x = rng.range(AREA_X[0] + 1.0, AREA_X[1] - 1.0);
        let z = rng.range(AREA_Z[0] + 1.0, AREA_Z[1] - 1.0);
        if pairs < IDLE_PAIRS {
            // Two robots chatting, facing each other.
            let dir = rng.range(-PI, PI);
            let gap = rng.range(1.1, 1.5);
            let (x2, z2) = (x + gap * dir.sin(), z + gap * dir.cos());
            let a = vec![Some((x, z, heading_towards((x, z), (x2, z2)))); FRAMES];
            let b = vec![Some((x2, z2, heading_towards((x2, z2), (x, z)))); FRAMES];
            if inside_area(x2, z2) && fits(&a, out) && fits(&b, out) {
                let ra = pick_rig(rng, rigs);
                let rb = pick_rig(rng, rigs);
                let ida = ids.take(rng);
                let agent = idle_agent(rng, ra, ida, a[0].unwrap_or_default());
                out.push(agent);
                let idb = ids.take(rng);
                let agent = idle_agent(rng, rb, idb, b[0].unwrap_or_default());
                out.push(agent);
                pairs += 1;
            }
        } else {
            let pose = (x, z, rng.range(-PI, PI));
            if fits(&[Some(pose)].repeat(FRAMES), out) {
                let rig = pick_rig(rng, rigs);
                let id = ids.take(rng);
                let agent = idle_agent(rng, rig, id, pose);
                out.push(agent);
                singles += 1;
            }
        }
    }
}

/// A walker candidate; `edge` ones start near or outside the area's edge and
/// cross it during the shot (entering late or leaving early).
fn walker_candidate(rng: &mut Rng, rigs: &[RigSpec], edge: bool) -> (&'static str, ClipSpec, Vec<Option<Pose>>) {
    let rig = pick_rig(rng, rigs);
    let clip = if rng.chance(0.6) { rig.walk_a } else { rig.walk_b };
    let speed = clip.stride / clip.frames as f32;
    let travel = speed * FRAMES as f32;
    let turn = if rng.chance(0.4) { rng.range(-MAX_TURN, MAX_TURN) } else { 0.0 };
    if !edge {
        let x = rng.range(AREA_X[0], AREA_X[1]);
        let z = rng.range(AREA_Z[0], AREA_Z[1]);
        return (rig.name, clip, walk_track(x, z, pick_heading(rng), speed, turn));
    }
    // Across the back (-Z) or a side edge, inwards (entering) or outwards (leaving).
    let entering = rng.chance(0.5);
    let offset = rng.range(0.2, 0.8) * travel;
    let (x, z, h) = match rng.below(3) {
        0 => {
            let x = rng.range(AREA_X[0] + 2.0, AREA_X[1] - 2.0);
            if entering {
                (x, AREA_Z[0] - offset, 0.0)
            } else {
                (x, AREA_Z[0] + offset, PI)
            }
        }
        1 => {
            let z = rng.range(AREA_Z[0] + 2.0, AREA_Z[1] - 2.0);
            if entering {
                (AREA_X[0] - offset, z, PI / 2.0)
            } else {
                (AREA_X[0] + offset, z, -PI / 2.0)
            }
        }
        _ => {
            let z = rng.range(AREA_Z[0] + 2.0, AREA_Z[1] - 2.0);
            if entering {
                (AREA_X[1] + offset, z, -PI / 2.0)
            } else {
                (AREA_X[1] - offset, z, PI / 2.0)
            }
        }
    };
    (rig.name, clip, walk_track(x, z, h + rng.range(-0.2, 0.2), speed, 0.0))
}

fn walkers(rng: &mut Rng, rigs: &[RigSpec], ids: &mut Ids, out: &mut Vec<Agent>) {
    let mut edge_left = EDGE_WALKERS;
    while out.len() < AGENTS {
        let edge = edge_left > 0;
        let (rig, clip, poses) = walker_candidate(rng, rigs, edge);
        let present = poses.iter().filter(|p| p.is_some()).count();
        let ok_len = if edge { (MIN_FRAMES..FRAMES).contains(&present) } else { present == FRAMES };
        if !ok_len || !fits(&poses, out) {
            continue;
        }
        edge_left = edge_left.saturating_sub(1);
        let id = ids.take(rng);
        out.push(Agent { id, rig, clip, start_cycle_frame: rng.below(clip.frames), seated: false, poses });
    }
}

/// Builds the crowd deterministically from SEED.
fn build(rigs: &[RigSpec]) -> Vec<Agent> {
    let mut rng = Rng(SEED);
    let mut ids = Ids { next: 0 };
    let mut agents = Vec::new();
    seated_agents(&mut rng, rigs, &mut ids, &mut agents);
    idle_agents(&mut rng, rigs, &mut ids, &mut agents);
    walkers(&mut rng, rigs, &mut ids, &mut agents);
    agents.sort_by_key(|a| a.id);
    agents
}

/// Millimetre precision keeps the CSV readable.
fn mm(v: f32) -> f32 {
    (v * 1000.0).round() / 1000.0
}

fn to_csv(agents: &[Agent]) -> String {
    let mut s = String::from("frame,id,x,y,z,heading,rig,cycle,cycle_frame,flags\n");
    for f in 0..FRAMES {
        for a in agents {
            let Some((x, z, h)) = a.poses[f] else { continue };
            // cycle_frame advances one frame per frame, looping over the clip.
            let cf = (a.start_cycle_frame + f as u32) % a.clip.frames;
            let flags = if a.seated { "seated" } else { "" };
            let h = (h * 10000.0).round() / 10000.0;
            let _ = writeln!(
                s,
                "{},{},{},{},{},{},{},{},{},{}",
                f + 1,
                a.id,
                mm(x),
                0.0f32,
                mm(z),
                h,
                a.rig,
                a.clip.name,
                cf as f32,
                flags
            );
        }
    }
    s
}

fn stats(agents: &[Agent]) -> Stats {
    let mut min_gap = f32::INFINITY;
    for f in 0..FRAMES {
        let here: Vec<(f32, f32)> = agents.iter().filter_map(|a| a.poses[f].map(|(x, z, _)| (x, z))).collect();
        for i in 0..here.len() {
            for j in i + 1..here.len() {
                let d = ((here[i].0 - here[j].0).powi(2) + (here[i].1 - here[j].1).powi(2)).sqrt();
                min_gap = min_gap.min(d);
            }
        }
    }
    Stats {
        agents: agents.len(),
        walking: agents.iter().filter(|a| a.clip.name.starts_with("Walk")).count(),
        idle: agents.iter().filter(|a| a.clip.name == "IdleA").count(),
        seated: agents.iter().filter(|a| a.seated).count(),
        entering: agents.iter().filter(|a| a.poses[0].is_none()).count(),
        leaving: agents.iter().filter(|a| a.poses[FRAMES - 1].is_none()).count(),
        min_gap,
    }
}

/// Writes demo/cache/demo.csv and returns a summary.
pub fn write_cache(path: &Path, rigs: &[RigSpec]) -> Result<Stats> {
    let agents = build(rigs);
    let csv = to_csv(&agents);
    write_atomic(path, |w| {
        use std::io::Write;
        w.write_all(csv.as_bytes()).at(path)
    })?;
    Ok(stats(&agents))
}
