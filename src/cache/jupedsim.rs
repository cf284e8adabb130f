//! Import of JuPedSim SQLite trajectory files (SqliteTrajectoryWriter,
//! database versions 1 and 2; schema in docs/cache-format.md).
//!
//! Mapping. JuPedSim is planar: (x, y) on the ground, z up, right-handed.
//! Our world is Y up, right-handed. We map native (x, y) to world
//! (x, 0, -y): a rotation of -90 degrees about X, which keeps handedness, so
//! the layout seen from above is the same picture, not a mirror image
//! (z = +y would mirror it). Headings use the same mapping: a native
//! direction (dx, dy) is the world direction (dx, 0, -dy), and heading =
//! atan2(world x, world z) (0 faces +Z).
//!
//! Heading comes from the orientation vector (ori_x, ori_y); where that is
//! (0, 0) (JuPedSim writes it before an agent first moves) it comes from the
//! agent's motion since its previous row, or for its first row from its next
//! movement. Below the hold speed (the tables' rule, `tabular::may_turn`:
//! ground speed over the heading window) the heading is held: JuPedSim's
//! orientation of a near-stationary agent follows its jitter and would spin
//! it. Held frames keep the last known heading, before the first one the
//! next; an agent never fast enough to turn keeps its first written one.
//!
//! Cycle frame: feet must not slide, so the walk cycle advances by distance
//! walked / stride * cycle length, modulo the cycle length. Each agent starts
//! at a phase fixed by its id (golden-ratio spread) so the crowd does not
//! step in unison. Cache frames are JuPedSim's frame numbers, unchanged (its
//! fps is the file's `fps` metadata, 25 for the bundled sample).
//!
//! Fps. A cache's cycle frame is in frames at the SHOT fps (24: the renderer
//! samples a cycle at time cycle_frame / 24), whatever the cache's own frame
//! rate. The cycle frame is driven by distance, not time, so JuPedSim's 25 fps
//! does not enter it: with `--rig-file` the cycle length is the clip's
//! duration x 24 ([`SHOT_FPS`]), and cycle_frame = (distance / stride) x
//! length puts the clip at the pose where its root has travelled `distance`
//! (mod one stride), i.e. the feet stay planted.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use glam::Vec3;
use rusqlite::{Connection, OpenFlags};

use super::tabular::{fill_held, may_turn, turn_toward, window, window_half};
use super::tabular_options::{
    DEFAULT_CYCLE_LENGTH, DEFAULT_HEADING_WINDOW, DEFAULT_HOLD_SPEED, DEFAULT_STRIDE, DEFAULT_TURN_RATE,
};
use super::{validate, AgentSample, CrowdCache, FrameBlock};
use crate::error::{Error, IoContext, Result};

/// Frames per second cycle frames are counted in (SPEC: shot fps 24), so a
/// rig clip's length is `duration * SHOT_FPS` frames.
pub(crate) const SHOT_FPS: f32 = 24.0;

/// A walk cycle's length and stride read from a rig glTF (`--rig-file`;
/// casting's `rig::import_clip` reads it, so the cache never loads rigs).
#[derive(Clone, Debug, PartialEq)]
pub struct RigClip {
    /// The rig file.
    pub file: PathBuf,
    /// Metres the clip's root travels per cycle.
    pub(crate) stride: f32,
    /// Clip length in frames at [`SHOT_FPS`].
    pub(crate) cycle_length: f32,
}

/// How imported trajectories become agents.
#[derive(Clone, Debug, PartialEq)]
pub struct ImportOptions {
    /// Rig given to every agent.
    pub rig: String,
    /// Walk cycle given to every agent.
    pub cycle: String,
    /// Metres per cycle (`--stride`); `None`: the rig clip's, else [`DEFAULT_STRIDE`].
    pub stride: Option<f32>,
    /// Cycle length in frames at the shot fps (`--cycle-length`); `None`:
    /// the rig clip's, else [`DEFAULT_CYCLE_LENGTH`].
    pub cycle_length: Option<f32>,
    /// The cycle as read from `--rig-file`; `stride` and `cycle_length`
    /// override it.
    pub rig_clip: Option<RigClip>,
    /// Fastest heading change, degrees per second ([`DEFAULT_TURN_RATE`]).
    pub turn_rate: f32,
    /// Speed (m/s) below which the heading is held, the tables' rule
    /// ([`DEFAULT_HOLD_SPEED`]; 0 never holds).
    pub hold_speed: f32,
}

impl Default for ImportOptions {
    fn default() -> Self {
        ImportOptions {
            rig: "bipedThinA".into(),
            cycle: "WalkA".into(),
            stride: None,
            cycle_length: None,
            rig_clip: None,
            turn_rate: DEFAULT_TURN_RATE,
            hold_speed: DEFAULT_HOLD_SPEED,
        }
    }
}

impl ImportOptions {
    /// Checked options: every agent gets `rig` and `cycle`; `stride` and
    /// `cycle_length` override what `rig_clip` (the rig file's cycle) says.
    pub fn new(
        rig: &str,
        cycle: &str,
        stride: Option<f32>,
        cycle_length: Option<f32>,
        rig_clip: Option<RigClip>,
    ) -> Result<ImportOptions> {
        let opts = ImportOptions {
            rig: rig.to_string(),
            cycle: cycle.to_string(),
            stride,
            cycle_length,
            rig_clip,
            turn_rate: DEFAULT_TURN_RATE,
            hold_speed: DEFAULT_HOLD_SPEED,
        };
        opts.check()?;
        Ok(opts)
    }

    /// These options turning at most `turn_rate` degrees per second
    /// (`None`: [`DEFAULT_TURN_RATE`]), checked.
    pub fn with_turn_rate(mut self, turn_rate: Option<f32>) -> Result<ImportOptions> {
        self.turn_rate = turn_rate.unwrap_or(DEFAULT_TURN_RATE);
        self.check()?;
        Ok(self)
    }

    /// These options with the motion keys a JuPedSim import applies, as a
    /// shot's `[cache]` table or the import flags give them: `turn_rate`
    /// and `hold_speed` (unset: their defaults), checked.
    pub fn with_motion(mut self, keys: &super::TabularSpec) -> Result<ImportOptions> {
        self.hold_speed = keys.hold_speed.unwrap_or(DEFAULT_HOLD_SPEED);
        self.with_turn_rate(keys.turn_rate)
    }

    /// Metres per cycle: `--stride`, else the rig clip's, else [`DEFAULT_STRIDE`].
    pub fn stride(&self) -> f32 {
        self.stride.or(self.rig_clip.as_ref().map(|c| c.stride)).unwrap_or(DEFAULT_STRIDE)
    }
    /// Cycle length in frames at the shot fps: `--cycle-length`, else the
    /// rig clip's, else [`DEFAULT_CYCLE_LENGTH`].
    pub fn cycle_length(&self) -> f32 {
        self.cycle_length.or(self.rig_clip.as_ref().map(|c| c.cycle_length)).unwrap_or(DEFAULT_CYCLE_LENGTH)
    }

    /// One line for humans, marking where each value came from.
    pub fn describe(&self) -> String {
        let from = |o: Option<f32>| match (o, &self.rig_clip) {
            (Some(_), _) => String::new(),
            (None, Some(c)) => format!(" (rig file {})", c.file.display()),
            (None, None) => " (default)".into(),
        };
        format!(
            "rig {}, cycle {}, stride {} m{}, cycle length {} frames{}, heading held below {} m/s",
            self.rig,
            self.cycle,
            self.stride(),
            from(self.stride),
            self.cycle_length(),
            from(self.cycle_length),
            self.hold_speed
        )
    }

    fn check(&self) -> Result<()> {
        for (v, option) in
            [(self.stride(), "stride"), (self.cycle_length(), "cycle_length"), (self.turn_rate, "turn_rate")]
        {
            if !(v.is_finite() && v > 0.0) {
                return Err(Error::setting(option, format!("must be a positive number, not {v}")));
            }
        }
        if !(self.hold_speed.is_finite() && self.hold_speed >= 0.0) {
            return Err(Error::setting("hold_speed", format!("must be 0 or more, not {}", self.hold_speed)));
        }
        for (name, option) in [(&self.rig, "rig"), (&self.cycle, "cycle")] {
            super::check_name(name).map_err(|m| Error::setting(option, m))?;
        }
        Ok(())
    }
}

/// One trajectory row, native coordinates.
struct Sample {
    frame: i32,
    x: f64,
    y: f64,
    ori_x: f64,
    ori_y: f64,
}

/// Native planar direction -> heading about +Y (world direction (dx, 0, -dy)).
fn heading_of(dx: f64, dy: f64) -> Option<f64> {
    (dx.hypot(dy) > 1e-9).then(|| dx.atan2(-dy))
}

/// Frames per second of the file when its metadata does not say.
pub(crate) const DEFAULT_JUPEDSIM_FPS: f64 = 25.0;

/// Headings for one agent's samples (see the module comment), turning at
/// most `step` radians per frame (frames apart count as many frames), and
/// held below the hold speed by the rule every import shares
/// ([`may_turn`]: ground speed over the heading window, `window_half`
/// frames either side within a run of consecutive frames, at `fps`).
fn headings(s: &[Sample], step: f64, hold: f64, window_half: usize, fps: f64) -> Vec<f32> {
    let motion = |a: &Sample, b: &Sample| heading_of(b.x - a.x, b.y - a.y);
    let speeds = window_speeds(s, window_half, fps);
    let written: Vec<Option<f64>> = s
        .iter()
        .enumerate()
        .map(|(i, p)| {
            heading_of(p.ori_x, p.ori_y).or_else(|| match i {
                0 => s.get(1).and_then(|n| motion(p, n)),
                _ => s.get(i - 1).and_then(|prev| motion(prev, p)),
            })
        })
        .collect();
    let standing = written.iter().flatten().next().copied();
    let mut h: Vec<Option<f64>> =
        written.into_iter().zip(&speeds).map(|(w, &v)| w.filter(|_| may_turn(v, hold))).collect();
    fill_held(&mut h, standing);
    let mut prev: Option<(i32, f64)> = None;
    s.iter()
        .zip(h)
        .map(|(p, v)| {
            let mut v = v.unwrap_or(0.0);
            if let Some((f, q)) = prev {
                v = turn_toward(q, v, step * f64::from(p.frame.saturating_sub(f).max(1)));
            }
            prev = Some((p.frame, v));
            v as f32
        })
        .collect()
}

/// Each sample's ground speed (m/s) over the heading window, within its run
/// of consecutive frames (a lone sample: 0).
fn window_speeds(s: &[Sample], half: usize, fps: f64) -> Vec<f64> {
    let mut out = Vec::with_capacity(s.len());
    let mut start = 0;
    while start < s.len() {
        let mut end = start + 1;
        while end < s.len() && s[end].frame == s[end - 1].frame.saturating_add(1) {
            end += 1;
        }
        let run = &s[start..end];
        for i in 0..run.len() {
            let (j0, j1) = window(i, run.len(), half);
            let span = f64::from(run[j1].frame - run[j0].frame) / fps;
            let d = (run[j1].x - run[j0].x).hypot(run[j1].y - run[j0].y);
            out.push(if span > 0.0 { d / span } else { 0.0 });
        }
        start = end;
    }
    out
}

/// Cycle frames for one agent: start phase from the id, then distance.
fn cycle_frames(id: u32, s: &[Sample], stride: f64, length: f64) -> Vec<f32> {
    // Golden-ratio spread: neighbouring ids get well-separated phases.
    let mut walked = (f64::from(id) * 0.618_033_988_749_895).fract() * stride;
    let mut prev: Option<&Sample> = None;
    s.iter()
        .map(|p| {
            if let Some(q) = prev {
                walked += (p.x - q.x).hypot(p.y - q.y);
            }
            prev = Some(p);
            let f = ((walked / stride) * length).rem_euclid(length) as f32;
            // Rounding to f32 can land exactly on the length; that is frame 0.
            if f >= length as f32 {
                0.0
            } else {
                f
            }
        })
        .collect()
}

fn sql_err(path: &Path) -> impl Fn(rusqlite::Error) -> Error + '_ {
    move |e| Error::invalid(path, format!("cannot read as a JuPedSim SQLite file: {e}"))
}

fn has_table(conn: &Connection, path: &Path, name: &str) -> Result<bool> {
    conn.query_row("SELECT count(*) FROM sqlite_master WHERE type = 'table' AND name = ?1", [name], |r| {
        r.get::<_, i64>(0)
    })
    .map(|n| n > 0)
    .map_err(sql_err(path))
}

/// Imports a JuPedSim trajectory file.
pub(crate) fn read(path: &Path, opts: &ImportOptions) -> Result<CrowdCache> {
    opts.check()?;
    std::fs::metadata(path).at(path)?; // a clear "not found" before SQLite's message
    let conn = Connection::open_with_flags(path, OpenFlags::SQLITE_OPEN_READ_ONLY | OpenFlags::SQLITE_OPEN_NO_MUTEX)
        .map_err(sql_err(path))?;
    if !has_table(&conn, path, "trajectory_data")? {
        return Err(
            Error::invalid(path, "no `trajectory_data` table: not a JuPedSim trajectory file").field("trajectory_data")
        );
    }
    let mut fps = DEFAULT_JUPEDSIM_FPS;
    if has_table(&conn, path, "metadata")? {
        let meta = |key: &str| -> Result<Option<String>> {
            conn.query_row("SELECT value FROM metadata WHERE key = ?1", [key], |r| r.get::<_, String>(0))
                .map(Some)
                .or_else(|e| match e {
                    rusqlite::Error::QueryReturnedNoRows => Ok(None),
                    e => Err(e),
                })
                .map_err(sql_err(path))
        };
        if let Some(v) = meta("version")?.filter(|v| !matches!(v.trim(), "1" | "2")) {
            return Err(Error::invalid(path, format!("JuPedSim database version {v}; throng reads versions 1 and 2"))
                .field("metadata.version"));
        }
        if let Some(v) = meta("fps")? {
            fps =
                v.trim().parse::<f64>().ok().filter(|f| f.is_finite() && *f > 0.0).ok_or_else(|| {
                    Error::invalid(path, format!("fps `{v}` is not a frame rate")).field("metadata.fps")
                })?;
        }
    }
    let step = f64::from(opts.turn_rate).to_radians() / fps;
    let (hold, half) = (f64::from(opts.hold_speed), window_half(f64::from(DEFAULT_HEADING_WINDOW), fps));

    // Rows by agent, then frame, so each trajectory is walked in order.
    let mut stmt = conn
        .prepare("SELECT frame, id, pos_x, pos_y, ori_x, ori_y FROM trajectory_data ORDER BY id, frame")
        .map_err(sql_err(path))?;
    let mut rows = stmt.query([]).map_err(sql_err(path))?;
    let mut agents: Vec<(u32, Vec<Sample>)> = Vec::new();
    while let Some(row) = rows.next().map_err(sql_err(path))? {
        let frame: i64 = row.get(0).map_err(|e| sql_err(path)(e).field("frame"))?;
        let id: i64 = row.get(1).map_err(|e| sql_err(path)(e).frame(frame).field("id"))?;
        let frame32 = i32::try_from(frame)
            .map_err(|_| Error::invalid(path, format!("frame {frame} is out of range")).frame(frame).field("frame"))?;
        let id32 = u32::try_from(id).map_err(|_| {
            Error::invalid(path, format!("agent id {id} is out of range (0 to {})", u32::MAX)).frame(frame).field("id")
        })?;
        let real = |i: usize, name: &str| -> Result<f64> {
            row.get::<_, f64>(i).map_err(|e| {
                Error::invalid(path, format!("{name} is not a number ({e})")).frame(frame).agent(id32).field(name)
            })
        };
        let s = Sample {
            frame: frame32,
            x: real(2, "pos_x")?,
            y: real(3, "pos_y")?,
            ori_x: real(4, "ori_x")?,
            ori_y: real(5, "ori_y")?,
        };
        match agents.last_mut() {
            Some((last, samples)) if *last == id32 => {
                if samples.last().is_some_and(|p| p.frame == frame32) {
                    return Err(Error::invalid(path, format!("agent {id32} appears twice in frame {frame32}"))
                        .frame(frame)
                        .agent(id32));
                }
                samples.push(s)
            }
            _ => agents.push((id32, vec![s])),
        }
    }

    let (stride, length) = (f64::from(opts.stride()), f64::from(opts.cycle_length()));
    let mut frames: BTreeMap<i32, Vec<AgentSample>> = BTreeMap::new();
    for (id, s) in &agents {
        let hs = headings(s, step, hold, half, fps);
        let cs = cycle_frames(*id, s, stride, length);
        for ((p, heading), cycle_frame) in s.iter().zip(hs).zip(cs) {
            frames.entry(p.frame).or_default().push(AgentSample {
                id: *id,
                position: Vec3::new(p.x as f32, 0.0, -p.y as f32),
                heading,
                rig: 0,
                cycle: 0,
                cycle_frame,
                flags: 0,
            });
        }
    }
    // Agents were visited by increasing id, so each frame is in id order.
    let crowd = CrowdCache {
        rigs: vec![opts.rig.clone()],
        cycles: vec![opts.cycle.clone()],
        frames: frames.into_iter().map(|(frame, agents)| FrameBlock { frame, agents }).collect(),
    };
    validate(path, &crowd)?;
    Ok(crowd)
}
