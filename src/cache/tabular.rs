//! General tabular trajectory import: any text table of (time or frame, id,
//! x, y[, z]) rows, from any tool, into a [`CrowdCache`] at the shot's frame
//! rate (docs/cache-format.md, "Tabular import").
//!
//! The stages, in order:
//! 1. Text: gzip is recognised by its magic bytes; comment lines, a header
//!    line, a delimiter or runs of whitespace; the `csv` crate splits rows.
//! 2. Rows: columns chosen by header name or 1-based position; numbers in the
//!    source's units and axes become world metres (Y up, right-handed), then
//!    the shot's placement (scale, rotate about +Y, translate) is applied, so
//!    distances walked (and so cycle frames) are those of the placed crowd.
//! 3. Time: each agent's samples are resampled to the target frame rate by
//!    linear interpolation; samples further apart than `max_gap` seconds are
//!    a gap, where the agent is absent (never a jump across it).
//! 4. Heading: from a column, velocity or motion, smoothed over a window and
//!    held while the agent is slower than `hold_speed`, so a person standing
//!    still does not spin on tracking noise.
//! 5. Cycles: the walk cycle frame follows distance walked / the rig's stride
//!    (feet stay planted); standing agents get the idle cycle when one is named.

use std::collections::{BTreeMap, HashMap};
use std::io::Read;
use std::path::Path;
use std::str::FromStr;

use glam::{DQuat, DVec3, Vec3};
use serde::{Deserialize, Serialize};

use super::jupedsim::{DEFAULT_CYCLE_LENGTH, DEFAULT_STRIDE};
use super::{check_name, validate, AgentSample, CrowdCache, FrameBlock};
use crate::error::{Error, IoContext, Result};

/// Largest input read, after gzip decompression (bytes).
pub const MAX_INPUT_BYTES: u64 = 2 << 30;
/// Most data rows read from one file.
pub const MAX_ROWS: usize = 20_000_000;
/// Most agent records an import may produce after resampling; checked
/// before any per-frame array is allocated.
pub const MAX_AGENT_FRAMES: u64 = 50_000_000;
/// Highest source or target frame rate accepted.
pub const MAX_FPS: f64 = 1000.0;
/// Default longest interval, in seconds, interpolated across.
pub const DEFAULT_MAX_GAP: f32 = 1.0;
/// Default heading smoothing window, seconds.
pub const DEFAULT_HEADING_WINDOW: f32 = 0.5;
/// Default speed (m/s) below which the heading is held.
pub const DEFAULT_HOLD_SPEED: f32 = 0.25;

macro_rules! named_enum {
    ($(#[$m:meta])* $name:ident { $($(#[$vm:meta])* $v:ident = [$($s:literal),+]),+ $(,)? }) => {
        $(#[$m])*
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize, Serialize)]
        #[serde(try_from = "String")]
        pub enum $name { $($(#[$vm])* $v),+ }
        impl FromStr for $name {
            type Err = String;
            fn from_str(s: &str) -> std::result::Result<Self, String> {
                match s.trim().to_ascii_lowercase().as_str() {
                    $($($s)|+ => Ok($name::$v),)+
                    _ => Err(format!("unknown value `{s}`; expected one of: {}", [$([$($s),+][0]),+].join(", "))),
                }
            }
        }
        impl TryFrom<String> for $name {
            type Error = String;
            fn try_from(s: String) -> std::result::Result<Self, String> { s.parse() }
        }
    };
}

named_enum!(
    /// A format users bring, with its layout already known.
    Preset {
        /// throng's own CSV (read by `cache::csv`, no resampling).
        Throng = ["throng"],
        /// PeTrack `.txt` trajectories: `# ` comments, then `id frame x y z`
        /// separated by spaces; units and frame rate from the comments.
        PeTrack = ["petrack"],
        /// ETH BIWI `obsmat.txt`: `frame id x z y vx vz vy`, metres, z up.
        Eth = ["eth", "obsmat"],
        /// ETH/UCY benchmark files: `frame id x y`, tab or space separated.
        EthUcy = ["eth-ucy", "ethucy", "trajnet"],
        /// A JuPedSim SQLite file (`cache::jupedsim`).
        JuPedSim = ["jupedsim"],
    }
);

named_enum!(
    /// Length unit of the source's positions (and velocities, per second).
    Units {
        /// Metres.
        M = ["m", "metres", "meters"],
        /// Centimetres.
        Cm = ["cm"],
        /// Millimetres.
        Mm = ["mm"],
        /// International feet.
        Ft = ["ft", "feet"],
    }
);

impl Units {
    /// Metres per unit.
    pub fn metres(self) -> f64 {
        match self {
            Units::M => 1.0,
            Units::Cm => 0.01,
            Units::Mm => 0.001,
            Units::Ft => 0.3048,
        }
    }
}

named_enum!(
    /// The source's up axis.
    UpAxis {
        /// Y up (throng's world).
        Y = ["y"],
        /// Z up, ground in (x, y): most pedestrian data.
        Z = ["z"],
    }
);

named_enum!(
    /// The source's handedness.
    Handedness {
        /// Right-handed (throng, JuPedSim, PeTrack).
        Right = ["right"],
        /// Left-handed (Unity and some game engines): mirrored on import.
        Left = ["left"],
    }
);

named_enum!(
    /// Unit of a heading column.
    AngleUnits {
        /// Radians.
        Radians = ["radians", "rad"],
        /// Degrees.
        Degrees = ["degrees", "deg"],
    }
);

named_enum!(
    /// Where headings come from.
    HeadingFrom {
        /// The heading column if chosen, else velocity columns, else motion.
        Auto = ["auto"],
        /// The heading column.
        Column = ["column"],
        /// The velocity columns.
        Velocity = ["velocity"],
        /// Positions over the smoothing window.
        Motion = ["motion"],
    }
);

/// The field delimiter.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum Delimiter {
    /// One byte, e.g. `,` `;` or tab.
    Byte(u8),
    /// Any run of spaces and tabs (PeTrack, obsmat).
    Whitespace,
}

impl FromStr for Delimiter {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s {
            "whitespace" | "space" | "spaces" | " " => Ok(Delimiter::Whitespace),
            "tab" | "\\t" | "\t" => Ok(Delimiter::Byte(b'\t')),
            "comma" => Ok(Delimiter::Byte(b',')),
            "semicolon" => Ok(Delimiter::Byte(b';')),
            _ if s.len() == 1 && s.is_ascii() && !s.as_bytes()[0].is_ascii_alphanumeric() => {
                Ok(Delimiter::Byte(s.as_bytes()[0]))
            }
            _ => Err(format!(
                "unknown delimiter `{s}`; expected `,`, `;`, `tab`, `whitespace` or one punctuation character"
            )),
        }
    }
}

impl TryFrom<String> for Delimiter {
    type Error = String;
    fn try_from(s: String) -> std::result::Result<Self, String> {
        s.parse()
    }
}

impl<'de> Deserialize<'de> for Delimiter {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        String::deserialize(d)?.parse().map_err(serde::de::Error::custom)
    }
}

/// A column, by header name (case-insensitive) or 1-based position.
#[derive(Clone, Debug, PartialEq, Eq, Deserialize, Serialize)]
#[serde(untagged)]
pub enum Column {
    /// 1-based position.
    Position(usize),
    /// Header name.
    Name(String),
}

impl FromStr for Column {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        let s = s.trim();
        match s.parse::<usize>() {
            Ok(0) => Err("column positions count from 1".into()),
            Ok(n) => Ok(Column::Position(n)),
            Err(_) if s.is_empty() => Err("empty column name".into()),
            Err(_) => Ok(Column::Name(s.to_string())),
        }
    }
}

/// What each column means. Every role is optional here; a read needs id, x,
/// y and one of frame or time.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Columns {
    /// Source frame number (with `source_fps`).
    pub frame: Option<Column>,
    /// Time in seconds (instead of frame).
    pub time: Option<Column>,
    /// Agent id (an integer; `1.0000000e+00` is read as 1).
    pub id: Option<Column>,
    /// Position x.
    pub x: Option<Column>,
    /// Position y.
    pub y: Option<Column>,
    /// Position z (optional: 0 when absent).
    pub z: Option<Column>,
    /// Heading (see docs/cache-format.md for its zero and sense).
    pub heading: Option<Column>,
    /// Velocity x.
    pub vx: Option<Column>,
    /// Velocity y.
    pub vy: Option<Column>,
    /// Velocity z.
    pub vz: Option<Column>,
    /// Rig name per row.
    pub rig: Option<Column>,
    /// Cycle name per row.
    pub cycle: Option<Column>,
}

/// The column roles, in the order errors list them.
pub const ROLES: [&str; 12] = ["frame", "time", "id", "x", "y", "z", "heading", "vx", "vy", "vz", "rig", "cycle"];

impl Columns {
    fn slot(&mut self, role: &str) -> Option<&mut Option<Column>> {
        Some(match role {
            "frame" => &mut self.frame,
            "time" => &mut self.time,
            "id" => &mut self.id,
            "x" => &mut self.x,
            "y" => &mut self.y,
            "z" => &mut self.z,
            "heading" => &mut self.heading,
            "vx" => &mut self.vx,
            "vy" => &mut self.vy,
            "vz" => &mut self.vz,
            "rig" => &mut self.rig,
            "cycle" => &mut self.cycle,
            _ => return None,
        })
    }

    /// Sets one role; an unknown role is an error listing the roles.
    pub fn set(&mut self, role: &str, col: Option<Column>) -> std::result::Result<(), String> {
        let slot = self
            .slot(role)
            .ok_or_else(|| format!("unknown column role `{role}`; expected one of: {}", ROLES.join(", ")))?;
        *slot = col;
        Ok(())
    }

    fn pick(&self, role: &str) -> Option<&Column> {
        match role {
            "frame" => self.frame.as_ref(),
            "time" => self.time.as_ref(),
            "id" => self.id.as_ref(),
            "x" => self.x.as_ref(),
            "y" => self.y.as_ref(),
            "z" => self.z.as_ref(),
            "heading" => self.heading.as_ref(),
            "vx" => self.vx.as_ref(),
            "vy" => self.vy.as_ref(),
            "vz" => self.vz.as_ref(),
            "rig" => self.rig.as_ref(),
            "cycle" => self.cycle.as_ref(),
            _ => None,
        }
    }

    /// Parses `frame=2,id=agent_id,x=3`: role=name or role=position. An
    /// empty value (`z=`) clears a preset's column.
    pub fn parse_list(s: &str) -> std::result::Result<Vec<(String, Option<Column>)>, String> {
        s.split(',')
            .filter(|p| !p.trim().is_empty())
            .map(|p| {
                let (role, col) = p.split_once('=').ok_or_else(|| format!("`{p}`: expected role=column"))?;
                let col = if col.trim().is_empty() { None } else { Some(col.parse()?) };
                Ok((role.trim().to_string(), col))
            })
            .collect()
    }
}

/// Where the crowd stands in the set: world = translate + rotate_y(rotate)
/// x (scale x position). Applied before layering, headings turn with it.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Placement {
    /// Metres added after rotation.
    pub translate: Vec3,
    /// Degrees about +Y (counter-clockwise seen from above).
    pub rotate: f32,
    /// Uniform scale about the origin, before rotation.
    pub scale: f32,
}

impl Default for Placement {
    fn default() -> Self {
        Placement { translate: Vec3::ZERO, rotate: 0.0, scale: 1.0 }
    }
}

impl Placement {
    /// Whether this placement moves nothing.
    pub fn is_identity(&self) -> bool {
        *self == Placement::default()
    }
    fn rotation(&self) -> DQuat {
        DQuat::from_rotation_y(f64::from(self.rotate).to_radians())
    }
    fn point(&self, p: DVec3) -> DVec3 {
        self.rotation() * (p * f64::from(self.scale)) + self.translate.as_dvec3()
    }
    fn vector(&self, v: DVec3) -> DVec3 {
        self.rotation() * (v * f64::from(self.scale))
    }
    /// Checks scale and finiteness; errors give the key and message.
    pub fn check_key(&self) -> std::result::Result<(), (String, String)> {
        self.check()
    }
    fn check(&self) -> std::result::Result<(), (String, String)> {
        if !(self.scale.is_finite() && self.scale > 0.0) {
            return Err(("scale".into(), format!("must be a positive number, not {}", self.scale)));
        }
        if !self.rotate.is_finite() || !self.translate.is_finite() {
            return Err(("translate".into(), "translate and rotate must be finite".into()));
        }
        Ok(())
    }
}

/// Places an already imported crowd (a `.crowd`, throng CSV or JuPedSim
/// cache): positions and headings move; cycle frames do not, so a scale
/// other than 1 makes feet slide on such caches (raw data imports apply the
/// placement before cycle frames are computed).
pub fn place(crowd: &mut CrowdCache, placement: &Placement) {
    if placement.is_identity() {
        return;
    }
    let turn = f64::from(placement.rotate).to_radians();
    for a in crowd.frames.iter_mut().flat_map(|b| b.agents.iter_mut()) {
        a.position = placement.point(a.position.as_dvec3()).as_vec3();
        a.heading = wrap(f64::from(a.heading) + turn) as f32;
    }
}

/// One rig's walk: metres per cycle and frames per cycle (at 24 fps), and
/// the idle cycle's length.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Gait {
    /// Metres the walk cycle's root travels per cycle.
    pub stride: f32,
    /// Walk cycle length, frames at 24 fps.
    pub cycle_length: f32,
    /// Idle cycle length, frames at 24 fps.
    pub idle_length: f32,
}

impl Default for Gait {
    fn default() -> Self {
        Gait { stride: DEFAULT_STRIDE, cycle_length: DEFAULT_CYCLE_LENGTH, idle_length: DEFAULT_CYCLE_LENGTH }
    }
}

/// What a user asks of an import, every field optional: a shot's `[cache]`
/// keys or `throng cache` flags. [`TabularOptions::resolve`] lays it over
/// the preset's defaults.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct TabularSpec {
    /// Layout preset.
    pub preset: Option<Preset>,
    /// Field delimiter.
    pub delimiter: Option<Delimiter>,
    /// Comment prefix (one character; empty: no comments).
    pub comment: Option<String>,
    /// Whether the first row names the columns.
    pub header: Option<bool>,
    /// Column choices over the preset's (`None` clears one).
    pub columns: Vec<(String, Option<Column>)>,
    /// Source length unit.
    pub units: Option<Units>,
    /// Source up axis.
    pub up: Option<UpAxis>,
    /// Source handedness.
    pub handedness: Option<Handedness>,
    /// Heading column unit.
    pub heading_units: Option<AngleUnits>,
    /// Source frames per second (for a frame column).
    pub source_fps: Option<f32>,
    /// Longest interval, seconds, interpolated across.
    pub max_gap: Option<f32>,
    /// Where headings come from.
    pub heading: Option<HeadingFrom>,
    /// Heading smoothing window, seconds.
    pub heading_window: Option<f32>,
    /// Speed (m/s) below which the heading is held (and the idle cycle plays).
    pub hold_speed: Option<f32>,
    /// Rig for every agent (without a rig column).
    pub rig: Option<String>,
    /// Walk cycle for every agent (without a cycle column).
    pub cycle: Option<String>,
    /// Cycle for standing agents.
    pub idle_cycle: Option<String>,
    /// Where the crowd stands.
    pub placement: Placement,
}

impl TabularSpec {
    /// Whether this spec describes a file layout (so a `.csv` is a foreign
    /// table, not throng's own CSV).
    pub fn describes_layout(&self) -> bool {
        matches!(self.preset, Some(Preset::PeTrack | Preset::Eth | Preset::EthUcy))
            || self.delimiter.is_some()
            || self.comment.is_some()
            || self.header.is_some()
            || !self.columns.is_empty()
            || self.units.is_some()
            || self.up.is_some()
            || self.handedness.is_some()
            || self.heading_units.is_some()
            || self.source_fps.is_some()
    }
}

/// A resolved, checked tabular import.
#[derive(Clone, Debug, PartialEq)]
pub struct TabularOptions {
    /// The preset it started from, if any.
    pub preset: Option<Preset>,
    /// Field delimiter.
    pub delimiter: Delimiter,
    /// Comment prefix byte.
    pub comment: Option<u8>,
    /// Whether the first row names the columns.
    pub header: bool,
    /// Column roles.
    pub columns: Columns,
    /// Source units; `None`: from a PeTrack `x/cm` comment, else metres.
    pub units: Option<Units>,
    /// Source up axis.
    pub up: UpAxis,
    /// Source handedness.
    pub handedness: Handedness,
    /// Heading column unit.
    pub heading_units: AngleUnits,
    /// Source fps; `None`: from a `framerate: N fps` comment (PeTrack).
    pub source_fps: Option<f32>,
    /// Target (shot) fps: cache frame k is at time k / fps.
    pub fps: f32,
    /// Longest interval, seconds, interpolated across.
    pub max_gap: f32,
    /// Where headings come from.
    pub heading: HeadingFrom,
    /// Heading smoothing window, seconds.
    pub heading_window: f32,
    /// Speed (m/s) below which the heading is held.
    pub hold_speed: f32,
    /// Rig for every agent without a rig column.
    pub rig: String,
    /// Walk cycle.
    pub cycle: String,
    /// Cycle for standing agents.
    pub idle_cycle: Option<String>,
    /// Gaits by rig name; other rigs use `default_gait`.
    pub gaits: BTreeMap<String, Gait>,
    /// Gait of rigs not in `gaits`.
    pub default_gait: Gait,
    /// Where the crowd stands.
    pub placement: Placement,
}

impl Default for TabularOptions {
    fn default() -> Self {
        TabularOptions {
            preset: None,
            delimiter: Delimiter::Byte(b','),
            comment: Some(b'#'),
            header: true,
            columns: Columns::default(),
            units: None,
            up: UpAxis::Z,
            handedness: Handedness::Right,
            heading_units: AngleUnits::Radians,
            source_fps: None,
            fps: 24.0,
            max_gap: DEFAULT_MAX_GAP,
            heading: HeadingFrom::Auto,
            heading_window: DEFAULT_HEADING_WINDOW,
            hold_speed: DEFAULT_HOLD_SPEED,
            rig: "bipedThinA".into(),
            cycle: "WalkA".into(),
            idle_cycle: None,
            gaits: BTreeMap::new(),
            default_gait: Gait::default(),
            placement: Placement::default(),
        }
    }
}

fn pos(n: usize) -> Option<Column> {
    Some(Column::Position(n))
}

impl TabularOptions {
    /// A preset's layout (`Throng` and `JuPedSim` are not tables: `None`).
    pub fn preset(preset: Preset) -> Option<TabularOptions> {
        let base = TabularOptions { preset: Some(preset), ..Default::default() };
        match preset {
            Preset::Throng | Preset::JuPedSim => None,
            // `# id frame x/cm y/cm z/cm`; z is the head's height, not the feet's.
            Preset::PeTrack => Some(TabularOptions {
                delimiter: Delimiter::Whitespace,
                header: false,
                columns: Columns { id: pos(1), frame: pos(2), x: pos(3), y: pos(4), ..Default::default() },
                ..base
            }),
            // [frame id pos_x pos_z pos_y v_x v_z v_y]; frame numbers step 6
            // per 0.4 s annotation in seq_eth, so 15 frames per second.
            Preset::Eth => Some(TabularOptions {
                delimiter: Delimiter::Whitespace,
                header: false,
                columns: Columns {
                    frame: pos(1),
                    id: pos(2),
                    x: pos(3),
                    y: pos(5),
                    vx: pos(6),
                    vy: pos(8),
                    ..Default::default()
                },
                units: Some(Units::M),
                source_fps: Some(15.0),
                ..base
            }),
            // frame id x y; frame numbers step 10 per 0.4 s sample (25 fps video).
            Preset::EthUcy => Some(TabularOptions {
                delimiter: Delimiter::Whitespace,
                header: false,
                columns: Columns { frame: pos(1), id: pos(2), x: pos(3), y: pos(4), ..Default::default() },
                units: Some(Units::M),
                source_fps: Some(25.0),
                ..base
            }),
        }
    }

    /// `spec` laid over its preset's layout (or a headed CSV with z up), for
    /// a target of `fps` frames per second. Errors give the key and message.
    pub fn resolve(spec: &TabularSpec, fps: f32) -> std::result::Result<TabularOptions, (String, String)> {
        let mut o = match spec.preset {
            Some(p) => TabularOptions::preset(p).ok_or_else(|| {
                ("preset".to_string(), format!("preset `{p:?}` is not a table; only petrack, eth and eth-ucy are"))
            })?,
            None => TabularOptions::default(),
        };
        o.fps = fps;
        if let Some(d) = spec.delimiter {
            o.delimiter = d;
        }
        if let Some(c) = &spec.comment {
            o.comment = match c.as_bytes() {
                [] => None,
                [b] if b.is_ascii() && !b.is_ascii_alphanumeric() => Some(*b),
                _ => return Err(("comment".into(), format!("`{c}`: a comment prefix is one punctuation character"))),
            };
        }
        if let Some(h) = spec.header {
            o.header = h;
        }
        for (role, col) in &spec.columns {
            o.columns.set(role, col.clone()).map_err(|m| ("columns".to_string(), m))?;
        }
        o.units = spec.units.or(o.units);
        o.up = spec.up.unwrap_or(o.up);
        o.handedness = spec.handedness.unwrap_or(o.handedness);
        o.heading_units = spec.heading_units.unwrap_or(o.heading_units);
        o.source_fps = spec.source_fps.or(o.source_fps);
        o.max_gap = spec.max_gap.unwrap_or(o.max_gap);
        o.heading = spec.heading.unwrap_or(o.heading);
        o.heading_window = spec.heading_window.unwrap_or(o.heading_window);
        o.hold_speed = spec.hold_speed.unwrap_or(o.hold_speed);
        if let Some(r) = &spec.rig {
            o.rig = r.clone();
        }
        if let Some(c) = &spec.cycle {
            o.cycle = c.clone();
        }
        o.idle_cycle = spec.idle_cycle.clone().or(o.idle_cycle);
        o.placement = spec.placement;
        o.check()?;
        Ok(o)
    }

    /// Checks numbers, names and that the columns can place an agent.
    pub fn check(&self) -> std::result::Result<(), (String, String)> {
        let err = |k: &str, m: String| Err((k.to_string(), m));
        let rate = |v: f32| v.is_finite() && v > 0.0 && f64::from(v) <= MAX_FPS;
        if !rate(self.fps) {
            return err("fps", format!("must be between 0 and {MAX_FPS}, not {}", self.fps));
        }
        if let Some(f) = self.source_fps.filter(|f| !rate(*f)) {
            return err("source_fps", format!("must be between 0 and {MAX_FPS}, not {f}"));
        }
        for (v, k) in
            [(self.max_gap, "max_gap"), (self.heading_window, "heading_window"), (self.hold_speed, "hold_speed")]
        {
            if !(v.is_finite() && v >= 0.0) {
                return err(k, format!("must be a number >= 0, not {v}"));
            }
        }
        for (name, k) in [(&self.rig, "rig"), (&self.cycle, "cycle")] {
            check_name(name).map_err(|m| (k.to_string(), m))?;
        }
        if let Some(idle) = &self.idle_cycle {
            check_name(idle).map_err(|m| ("idle_cycle".to_string(), m))?;
        }
        let c = &self.columns;
        for (need, role) in [(&c.id, "id"), (&c.x, "x"), (&c.y, "y")] {
            if need.is_none() {
                return err(
                    "columns",
                    format!("no `{role}` column chosen (e.g. columns {role}=NAME or {role}=POSITION)"),
                );
            }
        }
        match (&c.frame, &c.time) {
            (None, None) => return err("columns", "choose a `frame` or a `time` column".into()),
            (Some(_), Some(_)) => return err("columns", "choose a `frame` or a `time` column, not both".into()),
            _ => {}
        }
        let wants = |h: HeadingFrom| self.heading == h;
        if wants(HeadingFrom::Column) && c.heading.is_none() {
            return err("heading", "heading = column needs a `heading` column".into());
        }
        if wants(HeadingFrom::Velocity) && (c.vx.is_none() || c.vy.is_none()) {
            return err("heading", "heading = velocity needs `vx` and `vy` columns".into());
        }
        if !self.header {
            for role in ROLES {
                if let Some(Column::Name(n)) = c.pick(role) {
                    return err(
                        "columns",
                        format!("column `{n}` ({role}) is chosen by name, but the file has no header; use a position"),
                    );
                }
            }
        }
        self.placement.check()
    }

    fn gait(&self, rig: &str) -> Gait {
        self.gaits.get(rig).copied().unwrap_or(self.default_gait)
    }

    /// Source (x, y, z) in source units -> world metres, before placement.
    fn to_world(&self, v: DVec3, units: Units) -> DVec3 {
        let v = v * units.metres();
        match (self.up, self.handedness) {
            (UpAxis::Y, Handedness::Right) => v,
            (UpAxis::Y, Handedness::Left) => DVec3::new(v.x, v.y, -v.z),
            // -90 degrees about X keeps handedness: the plan view is the same picture.
            (UpAxis::Z, Handedness::Right) => DVec3::new(v.x, v.z, -v.y),
            (UpAxis::Z, Handedness::Left) => DVec3::new(v.x, v.z, v.y),
        }
    }

    /// A heading cell -> a source-axes direction: about +Y with 0 facing +Z
    /// (throng's convention) when y is up; counter-clockwise from +X in the
    /// (x, y) ground plane when z is up.
    fn heading_direction(&self, h: f64) -> DVec3 {
        let h = match self.heading_units {
            AngleUnits::Radians => h,
            AngleUnits::Degrees => h.to_radians(),
        };
        match self.up {
            UpAxis::Y => DVec3::new(h.sin(), 0.0, h.cos()),
            UpAxis::Z => DVec3::new(h.cos(), h.sin(), 0.0),
        }
    }
}

/// What an import did, for `cache info` and `cache convert`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TabularReport {
    /// Data rows read.
    pub rows: usize,
    /// Distinct agents.
    pub agents: usize,
    /// Source frames per second used (`None` with a time column).
    pub source_fps: Option<f32>,
    /// Target frames per second.
    pub fps: f32,
    /// Units used.
    pub units: Option<Units>,
    /// Intervals longer than `max_gap` left empty.
    pub gaps: usize,
    /// Agent records written.
    pub agent_frames: u64,
}

/// One row, in world metres, placed.
struct Sample {
    line: usize,
    /// Seconds.
    t: f64,
    /// The frame or time cell as written, for messages.
    label: f64,
    p: DVec3,
    heading: Option<DVec3>,
    velocity: Option<DVec3>,
    rig: u16,
    cycle: Option<u16>,
}

/// One resampled frame of one agent.
struct Pose {
    k: i32,
    p: DVec3,
    heading: Option<DVec3>,
    velocity: Option<DVec3>,
    rig: u16,
    cycle: Option<u16>,
}

/// Reads the file's text: gzip (by magic bytes) is decompressed; a byte
/// order mark is dropped; at most [`MAX_INPUT_BYTES`].
pub fn read_text(path: &Path) -> Result<String> {
    let file = std::fs::File::open(path).at(path)?;
    let mut head = [0u8; 2];
    let mut bytes = Vec::new();
    let mut raw = std::io::BufReader::new(file);
    let n = raw.read(&mut head).at(path)?;
    let chained = std::io::Read::chain(&head[..n], raw);
    let gz = n == 2 && head == [0x1f, 0x8b];
    let read = if gz {
        flate2::read::MultiGzDecoder::new(chained).take(MAX_INPUT_BYTES + 1).read_to_end(&mut bytes)
    } else {
        chained.take(MAX_INPUT_BYTES + 1).read_to_end(&mut bytes)
    };
    read.map_err(
        |e| {
            if gz {
                Error::invalid(path, format!("cannot decompress gzip: {e}"))
            } else {
                Error::io(path, e)
            }
        },
    )?;
    if bytes.len() as u64 > MAX_INPUT_BYTES {
        return Err(Error::invalid(path, format!("more than {MAX_INPUT_BYTES} bytes of text; split the file")));
    }
    let text = String::from_utf8(bytes).map_err(|e| {
        let valid = e.utf8_error().valid_up_to();
        let line = e.as_bytes().get(..valid).unwrap_or_default().iter().filter(|&&b| b == b'\n').count() + 1;
        Error::invalid(path, "not UTF-8 text").line(line)
    })?;
    Ok(match text.strip_prefix('\u{feff}') {
        Some(t) => t.to_string(),
        None => text,
    })
}

/// What PeTrack's comment header says: `# framerate: 25 fps` and the units
/// of `# id frame x/cm y/cm z/cm`.
fn sniff_comments(text: &str, comment: u8) -> (Option<f32>, Option<Units>) {
    let (mut fps, mut units) = (None, None);
    for line in text.lines().take(200).map(str::trim_start) {
        let Some(rest) = line.strip_prefix(comment as char) else { continue };
        let rest = rest.trim().to_ascii_lowercase();
        if let Some(v) = rest.strip_prefix("framerate:") {
            fps = fps.or(v.split_whitespace().next().and_then(|n| n.parse::<f32>().ok()));
        }
        for word in rest.split_whitespace() {
            if let Some(u) = word.strip_prefix("x/").and_then(|u| u.parse::<Units>().ok()) {
                units = units.or(Some(u));
            }
        }
    }
    (fps, units)
}

fn wrap(a: f64) -> f64 {
    let w = (a + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI;
    if w.is_finite() {
        w
    } else {
        0.0
    }
}

/// Reads a table at `path` as `o` says.
pub fn read(path: &Path, o: &TabularOptions) -> Result<(CrowdCache, TabularReport)> {
    o.check().map_err(|(k, m)| Error::invalid(path, m).field(k))?;
    let text = read_text(path)?;
    parse_str(path, &text, o)
}

/// Parses table text (already decompressed); `path` names it in errors.
pub fn parse_str(path: &Path, text: &str, o: &TabularOptions) -> Result<(CrowdCache, TabularReport)> {
    o.check().map_err(|(k, m)| Error::invalid(path, m).field(k))?;
    let (sniffed_fps, sniffed_units) = o.comment.map(|c| sniff_comments(text, c)).unwrap_or_default();
    let units = o.units.or(sniffed_units).unwrap_or(Units::M);
    let source_fps =
        match (&o.columns.frame, o.source_fps.or(sniffed_fps)) {
            (Some(_), Some(f)) if f.is_finite() && f > 0.0 && f64::from(f) <= MAX_FPS => Some(f64::from(f)),
            (Some(_), Some(f)) => {
                return Err(Error::invalid(
                    path,
                    format!("frame rate {f} from the file's comments is not usable; set source_fps"),
                )
                .field("source_fps"))
            }
            (Some(_), None) => return Err(Error::invalid(
                path,
                "the frame column counts frames at an unknown rate: set source_fps (frames per second of the source)",
            )
            .field("source_fps")),
            (None, _) => None,
        };

    // Comment lines are blanked and whitespace tables become tab-separated,
    // line by line, so line numbers stay (the csv crate's own comment
    // handling loses count of the lines it skips).
    let comment = o.comment.map(char::from);
    let data = text
        .lines()
        .map(|l| match (comment, o.delimiter) {
            (Some(c), _) if l.trim_start().starts_with(c) => String::new(),
            (_, Delimiter::Whitespace) => l.split_whitespace().collect::<Vec<_>>().join("\t"),
            _ => l.to_string(),
        })
        .collect::<Vec<_>>()
        .join("\n");
    let delimiter = match o.delimiter {
        Delimiter::Byte(b) => b,
        Delimiter::Whitespace => b'\t',
    };
    let mut reader = csv::ReaderBuilder::new()
        .has_headers(false)
        .flexible(true)
        .delimiter(delimiter)
        .trim(csv::Trim::All)
        .from_reader(data.as_bytes());
    // Lines from byte offsets: the csv crate's own line count skips comment lines.
    let starts: Vec<usize> = std::iter::once(0).chain(data.match_indices('\n').map(|(i, _)| i + 1)).collect();
    // A record's position is where reading began, before any blank lines it skipped.
    let line_at = |byte: u64| {
        let bytes = data.as_bytes();
        let mut i = usize::try_from(byte).unwrap_or(usize::MAX).min(bytes.len());
        while bytes.get(i).is_some_and(|c| *c == b'\n' || *c == b'\r') {
            i += 1;
        }
        starts.partition_point(|&s| s <= i)
    };
    let csv_err = |e: csv::Error| {
        let line = e.position().map(|p| line_at(p.byte()));
        let err = Error::invalid(path, format!("cannot read the table: {e}"));
        match line {
            Some(l) => err.line(l),
            None => err,
        }
    };

    let mut records = reader.records();
    let mut header: Option<Vec<String>> = None;
    if o.header {
        match records.next() {
            Some(r) => header = Some(r.map_err(csv_err)?.iter().map(str::to_string).collect()),
            None => return Err(Error::invalid(path, "empty file: expected a header line naming the columns").line(1)),
        }
    }
    // Role -> 0-based index.
    let mut index: HashMap<&'static str, usize> = HashMap::new();
    for role in ROLES {
        let Some(col) = o.columns.pick(role) else { continue };
        let i = match (col, &header) {
            (Column::Position(n), _) => n - 1,
            (Column::Name(name), Some(h)) => {
                h.iter().position(|c| c.eq_ignore_ascii_case(name.trim())).ok_or_else(|| {
                    Error::invalid(
                        path,
                        format!("no column `{name}` for {role}; the columns found are: {}", h.join(", ")),
                    )
                    .line(1)
                    .field(role)
                })?
            }
            (Column::Name(name), None) => {
                return Err(Error::invalid(path, format!("column `{name}` chosen by name, but the file has no header"))
                    .field(role))
            }
        };
        index.insert(role, i);
    }
    let index = &index;
    let label = |role: &str, i: usize| match header.as_ref().and_then(|h| h.get(i)) {
        Some(h) if !h.eq_ignore_ascii_case(role) => format!("column {} ({h}, {role})", i + 1),
        _ => format!("column {} ({role})", i + 1),
    };

    let mut rigs: Vec<String> = Vec::new();
    let mut cycles: Vec<String> = vec![o.cycle.clone()];
    if let Some(idle) = &o.idle_cycle {
        if *idle != o.cycle {
            cycles.push(idle.clone());
        }
    }
    let (mut rig_ids, mut cycle_ids) = (HashMap::new(), HashMap::new());
    for (i, c) in cycles.iter().enumerate() {
        cycle_ids.insert(c.clone(), i as u16);
    }
    if o.columns.rig.is_none() {
        rigs.push(o.rig.clone());
    }
    let intern =
        |names: &mut Vec<String>, ids: &mut HashMap<String, u16>, n: &str| -> std::result::Result<u16, String> {
            if let Some(&i) = ids.get(n) {
                return Ok(i);
            }
            check_name(n)?;
            let i = u16::try_from(names.len()).map_err(|_| "more than 65536 distinct names".to_string())?;
            names.push(n.to_string());
            ids.insert(n.to_string(), i);
            Ok(i)
        };

    let mut agents: BTreeMap<u32, Vec<Sample>> = BTreeMap::new();
    let mut rows = 0usize;
    let rotation = o.placement.rotation();
    for record in records {
        let record = record.map_err(csv_err)?;
        if record.iter().all(str::is_empty) {
            continue;
        }
        let line = record.position().map_or(0, |p| line_at(p.byte()));
        rows += 1;
        if rows > MAX_ROWS {
            return Err(Error::invalid(path, format!("more than {MAX_ROWS} rows; split the file")).line(line));
        }
        let cell = |role: &'static str| -> Result<Option<&str>> {
            let Some(&i) = index.get(role) else { return Ok(None) };
            match record.get(i) {
                Some(c) => Ok(Some(c)),
                None => Err(Error::invalid(
                    path,
                    format!("{}: missing; this row has {} columns", label(role, i), record.len()),
                )
                .line(line)
                .field(role)),
            }
        };
        let num = |role: &'static str| -> Result<Option<f64>> {
            let Some(c) = cell(role)? else { return Ok(None) };
            match c.parse::<f64>() {
                Ok(v) if v.is_finite() => Ok(Some(v)),
                _ => Err(Error::invalid(
                    path,
                    format!("{}: cannot read `{}` as a number", label(role, index[role]), c.escape_debug()),
                )
                .line(line)
                .field(role)),
            }
        };
        let id_cell = cell("id")?.unwrap_or_default();
        let id = id_cell
            .parse::<f64>()
            .ok()
            .filter(|v| v.fract() == 0.0 && (0.0..=f64::from(u32::MAX)).contains(v))
            .map(|v| v as u32)
            .ok_or_else(|| {
                Error::invalid(
                    path,
                    format!(
                        "{}: agent id `{}` is not an integer from 0 to {}",
                        label("id", index["id"]),
                        id_cell.escape_debug(),
                        u32::MAX
                    ),
                )
                .line(line)
                .field("id")
            })?;
        let with_agent = |e: Error| e.agent(id);
        let (t, lab) = match (source_fps, num("frame").map_err(with_agent)?, num("time").map_err(with_agent)?) {
            (Some(fps), Some(f), _) => (f / fps, f),
            (_, _, Some(t)) => (t, t),
            _ => unreachable_time(path, line)?,
        };
        let at = |role| num(role).map_err(with_agent);
        let raw = DVec3::new(at("x")?.unwrap_or_default(), at("y")?.unwrap_or_default(), at("z")?.unwrap_or_default());
        let p = o.placement.point(o.to_world(raw, units));
        let heading = at("heading")?.map(|h| rotation * o.to_world(o.heading_direction(h), Units::M));
        let velocity = match (at("vx")?, at("vy")?, at("vz")?) {
            (None, None, None) => None,
            (vx, vy, vz) => Some(
                o.placement
                    .vector(o.to_world(DVec3::new(vx.unwrap_or(0.0), vy.unwrap_or(0.0), vz.unwrap_or(0.0)), units)),
            ),
        };
        let name_err = |role: &'static str| {
            move |m: String| {
                Error::invalid(path, format!("{}: {m}", label(role, index[role]))).line(line).agent(id).field(role)
            }
        };
        let rig = match cell("rig")? {
            Some(n) => intern(&mut rigs, &mut rig_ids, n).map_err(name_err("rig"))?,
            None => 0,
        };
        let cycle = match cell("cycle")? {
            Some(n) => Some(intern(&mut cycles, &mut cycle_ids, n).map_err(name_err("cycle"))?),
            None => None,
        };
        let s = Sample { line, t, label: lab, p, heading, velocity, rig, cycle };
        let track = agents.entry(id).or_default();
        if let Some(prev) = track.last() {
            let what = if o.columns.frame.is_some() { "frame" } else { "time" };
            if s.t == prev.t {
                return Err(Error::invalid(
                    path,
                    format!("agent {id} appears twice at {what} {} (lines {} and {line})", s.label, prev.line),
                )
                .line(line)
                .agent(id));
            }
            if s.t < prev.t {
                return Err(Error::invalid(
                    path,
                    format!(
                        "agent {id}: {what} {} follows {what} {} (line {}); each agent's rows must go forward in time",
                        s.label, prev.label, prev.line
                    ),
                )
                .line(line)
                .agent(id));
            }
        }
        track.push(s);
    }

    let fps = f64::from(o.fps);
    let max_gap = f64::from(o.max_gap);
    // Bound the output before allocating any per-frame array.
    let mut total = 0u64;
    for (id, track) in &agents {
        for s in track {
            if (s.t * fps).abs() > 2.0e9 {
                return Err(Error::invalid(path, format!("time {} s is out of range at {fps} fps", s.t))
                    .line(s.line)
                    .agent(*id));
            }
        }
        resample_frames(track, fps, max_gap, |_, _, _, _| total += 1);
        if total > MAX_AGENT_FRAMES {
            return Err(Error::invalid(
                path,
                format!("resampling to {fps} fps gives more than {MAX_AGENT_FRAMES} agent records; check source_fps and units of time"),
            ));
        }
    }

    let window_half = ((f64::from(o.heading_window) * fps / 2.0).round() as usize).max(1);
    let hold = f64::from(o.hold_speed);
    let idle = o.idle_cycle.as_ref().and_then(|c| cycle_ids.get(c).copied());
    let heading_from = match o.heading {
        HeadingFrom::Auto if o.columns.heading.is_some() => HeadingFrom::Column,
        HeadingFrom::Auto if o.columns.vx.is_some() => HeadingFrom::Velocity,
        HeadingFrom::Auto => HeadingFrom::Motion,
        h => h,
    };
    let mut report = TabularReport {
        rows,
        agents: agents.len(),
        source_fps: source_fps.map(|f| f as f32),
        fps: o.fps,
        units: Some(units),
        ..Default::default()
    };
    let mut frames: BTreeMap<i32, Vec<AgentSample>> = BTreeMap::new();
    for (&id, track) in &agents {
        // Resample into runs of consecutive frames, split at gaps.
        let mut runs: Vec<Vec<Pose>> = Vec::new();
        resample_frames(track, fps, max_gap, |k, i, u, gap| {
            let (a, b) = (&track[i], track.get(i + 1).unwrap_or(&track[i]));
            let lerp = |x: DVec3, y: DVec3| x + (y - x) * u;
            let pose = Pose {
                k: k as i32,
                p: lerp(a.p, b.p),
                heading: a.heading.zip(b.heading).map(|(x, y)| lerp(x, y)),
                velocity: a.velocity.zip(b.velocity).map(|(x, y)| lerp(x, y)),
                rig: if u < 0.5 { a.rig } else { b.rig },
                cycle: if u < 0.5 { a.cycle } else { b.cycle },
            };
            match runs.last_mut() {
                Some(run) if !gap && run.last().is_some_and(|q| i64::from(q.k) + 1 == k) => run.push(pose),
                _ => runs.push(vec![pose]),
            }
        });
        report.gaps += track.windows(2).filter(|w| w[1].t - w[0].t > max_gap).count();

        // Headings and the moving/standing state, per run.
        let mut headings: Vec<Option<f64>> = Vec::new();
        let mut moving: Vec<bool> = Vec::new();
        for run in &runs {
            let n = run.len();
            let mut state = false;
            // Ground-plane travel direction over the window (length ~ speed),
            // kept only where the agent moves at full hold speed.
            let mut travel: Vec<Option<DVec3>> = Vec::with_capacity(n);
            for i in 0..n {
                let (j0, j1) = (i.saturating_sub(window_half), (i + window_half).min(n - 1));
                let span = (j1 - j0) as f64 / fps;
                let (speed, mut dir) = match heading_from {
                    HeadingFrom::Velocity => {
                        let v: DVec3 =
                            run[j0..=j1].iter().filter_map(|q| q.velocity).sum::<DVec3>() / (j1 - j0 + 1) as f64;
                        (v.x.hypot(v.z), v)
                    }
                    _ => {
                        let d = run[j1].p - run[j0].p;
                        (if span > 0.0 { d.x.hypot(d.z) / span } else { 0.0 }, d / span.max(1e-9))
                    }
                };
                dir.y = 0.0;
                // Hysteresis: start moving at hold_speed, stop below half of it,
                // so a dawdler does not flicker between walk and idle.
                state = if state { speed >= hold * 0.5 } else { speed >= hold && speed > 0.0 };
                moving.push(state);
                travel.push((speed >= hold && speed > 1e-9).then_some(dir));
            }
            for i in 0..n {
                let (j0, j1) = (i.saturating_sub(window_half), (i + window_half).min(n - 1));
                let h = match heading_from {
                    HeadingFrom::Column => {
                        let v: DVec3 =
                            run[j0..=j1].iter().filter_map(|q| q.heading.map(|h| h.normalize_or_zero())).sum();
                        (v.x.hypot(v.z) > 1e-9).then(|| v.x.atan2(v.z))
                    }
                    // Turn only at full hold speed, and average the window's travel
                    // weighted by speed, so the slow frames of a stop (where
                    // tracking noise is a large share of the motion) barely count.
                    _ => travel[i].map(|_| {
                        let v: DVec3 = travel[j0..=j1].iter().flatten().sum();
                        v.x.atan2(v.z)
                    }),
                };
                headings.push(h);
            }
        }
        // Held headings: the last known one, else the first one ahead, else 0.
        let mut last = None;
        for h in headings.iter_mut() {
            *h = h.or(last);
            last = *h;
        }
        let mut next = None;
        for h in headings.iter_mut().rev() {
            *h = h.or(next);
            next = *h;
        }

        // Golden-ratio spread: neighbouring ids step out of phase.
        let phase = (f64::from(id) * 0.618_033_988_749_895).fract();
        let mut i = 0;
        for run in &runs {
            let mut walked = 0.0;
            let mut prev: Option<DVec3> = None;
            for pose in run {
                if let Some(q) = prev {
                    walked += (pose.p.x - q.x).hypot(pose.p.z - q.z);
                }
                prev = Some(pose.p);
                let rig_name = rigs.get(usize::from(pose.rig)).map(String::as_str).unwrap_or_default();
                let gait = o.gait(rig_name);
                let standing = !moving.get(i).copied().unwrap_or(true);
                let (cycle, cycle_frame) = match (idle, pose.cycle) {
                    (Some(idle), None) if standing => {
                        let len = f64::from(gait.idle_length);
                        (idle, (f64::from(pose.k) + phase * len).rem_euclid(len))
                    }
                    (_, c) => {
                        let (stride, len) = (f64::from(gait.stride), f64::from(gait.cycle_length));
                        (c.unwrap_or(0), ((walked / stride + phase) * len).rem_euclid(len))
                    }
                };
                let len =
                    if Some(cycle) == idle && pose.cycle.is_none() { gait.idle_length } else { gait.cycle_length };
                let cf = cycle_frame as f32;
                frames.entry(pose.k).or_default().push(AgentSample {
                    id,
                    position: pose.p.as_vec3(),
                    heading: wrap(headings.get(i).copied().flatten().unwrap_or(0.0)) as f32,
                    rig: pose.rig,
                    cycle,
                    // Rounding to f32 can land exactly on the length; that is frame 0.
                    cycle_frame: if cf >= len { 0.0 } else { cf },
                    flags: 0,
                });
                report.agent_frames += 1;
                i += 1;
            }
        }
    }
    let crowd = CrowdCache {
        rigs,
        cycles,
        frames: frames.into_iter().map(|(frame, agents)| FrameBlock { frame, agents }).collect(),
    };
    validate(path, &crowd)?;
    Ok((super::canonical(&crowd), report))
}

fn unreachable_time<T>(path: &Path, line: usize) -> Result<T> {
    // check() demands a frame or time column; keep a typed error, not a panic.
    Err(Error::invalid(path, "no frame or time column").line(line).field("columns"))
}

/// Visits every target frame `k` an agent is present at: `visit(k, i, u,
/// gap)` with the sample segment `i`, the fraction `u` along it, and whether
/// a gap lies between this frame and the previous one. Samples further apart
/// than `max_gap` seconds are not interpolated across: only a frame falling
/// exactly on either sample is present.
fn resample_frames(track: &[Sample], fps: f64, max_gap: f64, mut visit: impl FnMut(i64, usize, f64, bool)) {
    const EPS: f64 = 1e-6;
    let mut last_k: Option<i64> = None;
    let mut gap = false;
    for (i, a) in track.iter().enumerate() {
        match track.get(i + 1) {
            Some(b) if b.t - a.t <= max_gap + EPS => {
                let k0 = (a.t * fps - EPS).ceil() as i64;
                let k1 = (b.t * fps + EPS).floor() as i64;
                let start = last_k.map_or(k0, |l| k0.max(l + 1));
                for k in start..=k1 {
                    let u = ((k as f64 / fps - a.t) / (b.t - a.t)).clamp(0.0, 1.0);
                    visit(k, i, u, gap);
                    gap = false;
                    last_k = Some(k);
                }
            }
            next => {
                let k = (a.t * fps).round();
                if (k - a.t * fps).abs() < EPS * fps.max(1.0) && last_k.is_none_or(|l| (k as i64) > l) {
                    visit(k as i64, i, 0.0, gap);
                    gap = false;
                    last_k = Some(k as i64);
                }
                if next.is_some() {
                    gap = true;
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn errors_name_the_right_line_after_comments_and_blank_lines() {
        let o = TabularOptions {
            columns: Columns { frame: pos(1), id: pos(2), x: pos(3), y: pos(4), ..Default::default() },
            header: false,
            source_fps: Some(25.0),
            ..Default::default()
        };
        let text = "# a\n# b\n1,2,0,0\n\n# c\n2,2,zz,0\n";
        let e = parse_str(Path::new("t.csv"), text, &o).unwrap_err().to_string();
        assert!(e.starts_with("t.csv:6:"), "{e}");
    }

    #[test]
    fn sniffs_petrack_header() {
        let (fps, units) = sniff_comments("# framerate: 16 fps\n# id frame x/cm y/cm z/cm\n1 0 1 2 3\n", b'#');
        assert_eq!((fps, units), (Some(16.0), Some(Units::Cm)));
    }
}
