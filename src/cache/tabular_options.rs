//! What a tabular import is told: the value types of the `[cache]` keys
//! (presets, units, axes, delimiter, columns), where the crowd stands
//! ([`Placement`]), a rig's walk ([`Gait`]) and the resolved, checked
//! [`TabularOptions`] the reader follows. The keys themselves and the spec
//! they fill live in `keys`, which resolves a spec into these options; the
//! reading stages live in `tabular`, which re-exports these types.

use std::collections::BTreeMap;
use std::str::FromStr;

use glam::{DQuat, DVec3, Vec3};
use serde::{Deserialize, Serialize};

use super::check_name;

/// Highest source or target frame rate accepted.
pub(crate) const MAX_FPS: f64 = 1000.0;
/// Default longest interval, in seconds, interpolated across.
pub(crate) const DEFAULT_MAX_GAP: f32 = 1.0;
/// Default heading smoothing window, seconds.
pub(crate) const DEFAULT_HEADING_WINDOW: f32 = 0.5;
/// Default speed (m/s) below which the heading is held.
pub(crate) const DEFAULT_HOLD_SPEED: f32 = 0.25;
/// Default fastest turn, degrees per second: a person turning on the spot
/// takes about half a second for an about-turn (180 degrees), and turns
/// slower while walking, so 360 deg/s never slows a real turn but stops a
/// one-frame snap (a held heading resuming in a new direction).
pub(crate) const DEFAULT_TURN_RATE: f32 = 360.0;
/// Stride (metres per walk cycle) when neither --stride nor a rig gives one.
pub(crate) const DEFAULT_STRIDE: f32 = 1.4;
/// Walk cycle length in frames when --cycle-length is not given.
pub(crate) const DEFAULT_CYCLE_LENGTH: f32 = 32.0;

macro_rules! named_enum {
    ($(#[$m:meta])* $name:ident { $($(#[$vm:meta])* $v:ident = [$($s:literal),+]),+ $(,)? }) => {
        $(#[$m])*
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Deserialize)]
        #[serde(try_from = "String")]
        pub enum $name { $($(#[$vm])* $v),+ }
        impl $name {
            /// The value's name as written in a shot (the first of its names).
            pub(crate) fn name(self) -> &'static str {
                match self { $($name::$v => [$($s),+][0],)+ }
            }
        }
        impl Serialize for $name {
            fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
                s.serialize_str(self.name())
            }
        }
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
        Ft = ["ft", "feet", "foot"],
        /// Inches.
        In = ["in", "inch", "inches"],
    }
);

impl Units {
    /// Metres per unit.
    pub(crate) fn metres(self) -> f64 {
        match self {
            Units::M => 1.0,
            Units::Cm => 0.01,
            Units::Mm => 0.001,
            Units::Ft => 0.3048,
            Units::In => 0.0254,
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
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
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

impl Serialize for Delimiter {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        match self {
            Delimiter::Whitespace => s.serialize_str("whitespace"),
            Delimiter::Byte(b'\t') => s.serialize_str("tab"),
            Delimiter::Byte(b) => s.serialize_str(&char::from(*b).to_string()),
        }
    }
}

impl<'de> Deserialize<'de> for Delimiter {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        String::deserialize(d)?.parse().map_err(serde::de::Error::custom)
    }
}

/// A column, by header name (case-insensitive) or 1-based position.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
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
pub(crate) const ROLES: [&str; 12] =
    ["frame", "time", "id", "x", "y", "z", "heading", "vx", "vy", "vz", "rig", "cycle"];

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
    pub(crate) fn set(&mut self, role: &str, col: Option<Column>) -> std::result::Result<(), String> {
        let slot = self
            .slot(role)
            .ok_or_else(|| format!("unknown column role `{role}`; expected one of: {}", ROLES.join(", ")))?;
        *slot = col;
        Ok(())
    }

    pub(crate) fn pick(&self, role: &str) -> Option<&Column> {
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
    pub(crate) fn parse_list(s: &str) -> std::result::Result<Vec<(String, Option<Column>)>, String> {
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
    pub(crate) fn rotation(&self) -> DQuat {
        DQuat::from_rotation_y(f64::from(self.rotate).to_radians())
    }
    pub(crate) fn point(&self, p: DVec3) -> DVec3 {
        self.rotation() * (p * f64::from(self.scale)) + self.translate.as_dvec3()
    }
    pub(crate) fn vector(&self, v: DVec3) -> DVec3 {
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

/// A resolved, checked tabular import; [`TabularOptions::resolve`] (in
/// `keys`) makes one from a [`TabularSpec`](super::TabularSpec).
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
    /// Fastest heading change, degrees per second.
    pub turn_rate: f32,
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
            turn_rate: DEFAULT_TURN_RATE,
            rig: "bipedThinA".into(),
            cycle: "WalkA".into(),
            idle_cycle: None,
            gaits: BTreeMap::new(),
            default_gait: Gait::default(),
            placement: Placement::default(),
        }
    }
}

impl TabularOptions {
    /// Checks numbers, names and that the columns can place an agent.
    pub(crate) fn check(&self) -> std::result::Result<(), (String, String)> {
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
        if !(self.turn_rate.is_finite() && self.turn_rate > 0.0) {
            return err("turn_rate", format!("must be a number of degrees per second > 0, not {}", self.turn_rate));
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

    pub(crate) fn gait(&self, rig: &str) -> Gait {
        self.gaits.get(rig).copied().unwrap_or(self.default_gait)
    }

    /// Source (x, y, z) in source units -> world metres, before placement.
    pub(crate) fn to_world(&self, v: DVec3, units: Units) -> DVec3 {
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
    pub(crate) fn heading_direction(&self, h: f64) -> DVec3 {
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
