//! The trajectory-import keys, declared once. [`import_keys!`] below lists
//! every key with its type, help and kind; from that one list come the
//! [`TabularSpec`] a shot's `[cache]` table fills (serde), the [`KEYS`] table
//! `throng cache` builds its flags from (the CLI crate: a flag is the key's
//! name with `-` for `_`), the shot's `[cache]` table itself and the overlay
//! of a user's keys on a preset's. A flag's text becomes the value the shot's
//! table would hold ([`Key::parse`]) and the spec is deserialized from those
//! values, so a shot key and its flag reach the same field by the same code.
//! Presets are data: each table preset is written as `[cache]` keys, and
//! [`TabularOptions::resolve`] lays a spec over its preset into the options
//! the reader follows.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};
use toml::Spanned;

use super::tabular_options::{
    AngleUnits, Column, Columns, Delimiter, Handedness, HeadingFrom, Placement, Preset, TabularOptions, Units, UpAxis,
    MAX_FPS,
};

/// How a key's value is written on a command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum KeyKind {
    /// A word or name, taken as written (an enum's words are checked by its type).
    Text,
    /// `true` or `false`.
    Bool,
    /// A number.
    Number,
    /// A frame rate: a number above 0, at most [`MAX_FPS`].
    Rate,
    /// `role=column,...`: a header name or 1-based position; `role=` clears a preset's.
    Columns,
    /// `X,Y,Z`.
    Vector,
}

/// What a key is about.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum KeyGroup {
    /// The preset: a table layout, or the name of a format.
    Preset,
    /// How the file's text and numbers are read; setting one makes a `.csv` a foreign table.
    Layout,
    /// How samples become motion: gaps, headings.
    Motion,
    /// Rig and cycle names given to agents.
    Names,
    /// Where the crowd stands (any cache).
    Placement,
}

/// One import key: its name in a shot's `[cache]` table, help, and how it is written.
#[derive(Clone, Copy, Debug)]
pub struct Key {
    /// The key's name (the `throng cache` flag is this with `-` for `_`).
    pub name: &'static str,
    /// Help, one line of the doc comment per item (docs/shot.md says more).
    pub(crate) help_lines: &'static [&'static str],
    /// How its value is written on a command line.
    pub kind: KeyKind,
    /// What it is about.
    pub(crate) group: KeyGroup,
}

/// A key's value read from a command line, as the shot's table would hold it.
#[derive(Clone, Debug, PartialEq)]
pub struct KeyValue(toml::Value);

impl Key {
    /// The key's help as one line.
    pub fn help(&self) -> String {
        self.help_lines.iter().map(|l| l.trim()).collect::<Vec<_>>().join(" ")
    }

    /// Reads a command-line value: written as [`KeyKind`] says, then checked
    /// by the key's own type exactly as a shot's value is.
    pub fn parse(&self, text: &str) -> Result<KeyValue, String> {
        let value = self.kind.value(text)?;
        TabularSpec::check_value(self.name, value.clone())?;
        Ok(KeyValue(value))
    }
}

/// The key named `name`.
#[cfg(test)] // the tests look keys up by name
pub(crate) fn key(name: &str) -> Option<&'static Key> {
    KEYS.iter().find(|k| k.name == name)
}

impl KeyKind {
    /// The text as the value a shot's table would hold.
    fn value(self, text: &str) -> Result<toml::Value, String> {
        use toml::Value;
        let number = |t: &str| match t.trim().parse::<f32>() {
            Ok(v) if v.is_finite() => Ok(v),
            Ok(v) => Err(format!("must be a finite number, not {v}")),
            Err(e) => Err(e.to_string()),
        };
        Ok(match self {
            KeyKind::Text => Value::String(text.to_string()),
            KeyKind::Bool => Value::Boolean(text.parse().map_err(|_| format!("`{text}`: expected true or false"))?),
            KeyKind::Number => Value::Float(number(text)?.into()),
            KeyKind::Rate => {
                let v = number(text)?;
                if !(v > 0.0 && f64::from(v) <= MAX_FPS) {
                    return Err(format!("must be between 0 and {MAX_FPS}, not {v}"));
                }
                Value::Float(v.into())
            }
            KeyKind::Columns => Value::Table(
                Columns::parse_list(text)?
                    .into_iter()
                    .map(|(role, col)| {
                        let v = match col {
                            None => Value::String(String::new()),
                            Some(Column::Name(n)) => Value::String(n),
                            Some(Column::Position(n)) => Value::Integer(i64::try_from(n).unwrap_or(i64::MAX)),
                        };
                        (role, v)
                    })
                    .collect(),
            ),
            KeyKind::Vector => Value::Array(parse_vec3(text)?.into_iter().map(|v| Value::Float(v.into())).collect()),
        })
    }
}

/// Parses `X,Y,Z`.
fn parse_vec3(s: &str) -> Result<[f32; 3], String> {
    let v: Vec<f32> = s
        .split(',')
        .map(|x| x.trim().parse::<f32>())
        .collect::<Result<_, _>>()
        .map_err(|_| format!("`{s}`: expected X,Y,Z"))?;
    v.try_into().map_err(|_| format!("`{s}`: expected three numbers X,Y,Z"))
}

/// Column choices over a preset's, in order: role -> column, `None` clearing
/// the preset's column (written `role = ""` in a shot, `role=` as a flag).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct ColumnChoices(pub Vec<(String, Option<Column>)>);

impl Serialize for ColumnChoices {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::SerializeMap;
        let mut map = s.serialize_map(Some(self.0.len()))?;
        for (role, col) in &self.0 {
            match col {
                Some(c) => map.serialize_entry(role, c)?,
                None => map.serialize_entry(role, "")?,
            }
        }
        map.end()
    }
}

impl<'de> Deserialize<'de> for ColumnChoices {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        let map = std::collections::BTreeMap::<String, Column>::deserialize(d)?;
        Ok(ColumnChoices(
            map.into_iter()
                .map(|(role, col)| match col {
                    Column::Name(n) if n.is_empty() => (role, None),
                    c => (role, Some(c)),
                })
                .collect(),
        ))
    }
}

/// A user's value over a preset's.
trait Over {
    fn over(self, base: Self) -> Self;
}

impl<T> Over for Option<T> {
    fn over(self, base: Self) -> Self {
        self.or(base)
    }
}

impl Over for ColumnChoices {
    /// The preset's choices, then the user's (a later choice of a role wins).
    fn over(self, base: Self) -> Self {
        ColumnChoices(base.0.into_iter().chain(self.0).collect())
    }
}

/// Declares the import keys: each is `doc; name: type => kind, group;`.
macro_rules! import_keys {
    ($($(#[doc = $help:literal])+ $name:ident : $ty:ty => $kind:ident, $group:ident;)+) => {
        /// What a user asks of an import, every key optional: a shot's `[cache]`
        /// keys or `throng cache` flags (declared once, in src/cache/keys.rs).
        /// [`TabularOptions::resolve`](super::TabularOptions::resolve) lays it
        /// over the preset's keys and checks it.
        #[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
        #[serde(deny_unknown_fields)]
        pub struct TabularSpec {
            $($(#[doc = $help])+ #[serde(default)] pub $name: $ty,)+
        }

        /// Every import key, in the order of [`TabularSpec`]'s fields.
        pub const KEYS: &[Key] = &[
            $(Key { name: stringify!($name), help_lines: &[$($help),+], kind: KeyKind::$kind, group: KeyGroup::$group },)+
        ];

        /// A shot's `[cache]` table: the cache file, its frame offset, then every import key.
        #[derive(Deserialize)]
        #[serde(deny_unknown_fields)]
        pub(crate) struct CacheTable {
            pub(crate) path: Spanned<PathBuf>,
            #[serde(default)]
            pub(crate) frame_offset: i32,
            $(#[serde(default)] $name: $ty,)+
        }

        impl CacheTable {
            /// The import keys.
            pub(crate) fn keys(&self) -> TabularSpec {
                TabularSpec { $($name: self.$name.clone(),)+ }
            }
        }

        impl TabularSpec {
            /// Checks one key's value with its field's own type.
            fn check_value(name: &str, value: toml::Value) -> Result<(), String> {
                let message = |e: toml::de::Error| e.message().to_string();
                match name {
                    $(stringify!($name) => <$ty>::deserialize(value).map(drop).map_err(message),)+
                    _ => Err(format!("unknown import key `{name}`")),
                }
            }

            /// The keys set (not their default), in [`KEYS`] order.
            pub fn set_keys(&self) -> impl Iterator<Item = &'static Key> {
                let d = TabularSpec::default();
                KEYS.iter().zip([$(self.$name != d.$name),+]).filter(|(_, set)| *set).map(|(k, _)| k)
            }

            /// These keys over `base`'s: each key set here wins; columns add up.
            pub(crate) fn over(self, base: TabularSpec) -> TabularSpec {
                TabularSpec { $($name: Over::over(self.$name, base.$name),)+ }
            }
        }
    };
}

import_keys! {
    /// Table layout preset: petrack, eth (obsmat), eth-ucy (frame id x y);
    /// also jupedsim or throng, which name formats.
    preset: Option<Preset> => Text, Preset;
    /// Field delimiter: `,` `;` `tab` or `whitespace`.
    delimiter: Option<Delimiter> => Text, Layout;
    /// Comment prefix character (empty: none).
    comment: Option<String> => Text, Layout;
    /// Whether the first row names the columns (true or false).
    header: Option<bool> => Bool, Layout;
    /// Columns by role: frame|time, id, x, y, z, heading, vx, vy, vz, rig,
    /// cycle = header name or 1-based position, e.g. frame=frame,id=agent_id,x=3.
    columns: ColumnChoices => Columns, Layout;
    /// Source units: m, cm, mm, ft, in.
    units: Option<Units> => Text, Layout;
    /// Source up axis: y or z.
    up: Option<UpAxis> => Text, Layout;
    /// Source handedness: right or left.
    handedness: Option<Handedness> => Text, Layout;
    /// Unit of the heading column: radians or degrees.
    heading_units: Option<AngleUnits> => Text, Layout;
    /// Frames per second of the source's frame column.
    source_fps: Option<f32> => Rate, Layout;
    /// Longest interval between samples, seconds, interpolated across; longer is a gap.
    max_gap: Option<f32> => Number, Motion;
    /// Heading from: auto, column, velocity, motion.
    heading: Option<HeadingFrom> => Text, Motion;
    /// Heading smoothing window, seconds.
    heading_window: Option<f32> => Number, Motion;
    /// Speed (m/s) below which the heading is held and the idle cycle plays.
    hold_speed: Option<f32> => Number, Motion;
    /// Fastest heading change, degrees per second (a person's turn) [default: 360].
    turn_rate: Option<f32> => Number, Motion;
    /// Rig given to every imported agent (without a rig column) [default: bipedThinA].
    rig: Option<String> => Text, Names;
    /// Walk cycle given to every imported agent (without a cycle column) [default: WalkA].
    cycle: Option<String> => Text, Names;
    /// Cycle for standing agents (its length comes from the rig).
    idle_cycle: Option<String> => Text, Names;
    /// Move the crowd by X,Y,Z metres (after rotate and scale).
    translate: Option<[f32; 3]> => Vector, Placement;
    /// Turn the crowd by this many degrees about +Y (up).
    rotate: Option<f32> => Number, Placement;
    /// Scale the crowd about the origin.
    scale: Option<f32> => Number, Placement;
}

/// The keys a JuPedSim import applies: its format, names, turn rate, hold
/// speed and placement.
const JUPEDSIM_KEYS: [&str; 8] = ["preset", "rig", "cycle", "turn_rate", "hold_speed", "translate", "rotate", "scale"];

impl TabularSpec {
    /// The first key set here that a JuPedSim import cannot apply (it reads
    /// metres at the file's frames, headings from the file's orientation
    /// (held below `hold_speed`), and has no idle cycle), with why; `None`
    /// when it applies them all.
    pub fn jupedsim_refuses(&self) -> Option<(&'static str, String)> {
        self.set_keys().find(|k| !JUPEDSIM_KEYS.contains(&k.name)).map(|k| {
            (
                k.name,
                format!(
                    "a JuPedSim file cannot apply `{}`: it is read in metres at its own frames, with headings from \
                     its orientation and no idle cycle; only {} apply",
                    k.name,
                    JUPEDSIM_KEYS.join(", ")
                ),
            )
        })
    }

    /// The spec from command-line values ([`Key::parse`]), deserialized as a
    /// shot's `[cache]` table is. Errors give the message.
    pub fn from_values(values: impl IntoIterator<Item = (&'static str, KeyValue)>) -> Result<TabularSpec, String> {
        let table: toml::Table = values.into_iter().map(|(k, v)| (k.to_string(), v.0)).collect();
        TabularSpec::deserialize(toml::Value::Table(table)).map_err(|e| e.message().to_string())
    }

    /// Whether this spec describes a file layout (so a `.csv` is a foreign
    /// table, not throng's own CSV): a table preset or any layout key.
    pub fn describes_layout(&self) -> bool {
        self.preset.is_some_and(|p| p.keys().is_some()) || self.set_keys().any(|k| k.group == KeyGroup::Layout)
    }

    /// Where the crowd stands (unset keys: no move).
    pub fn placement(&self) -> Placement {
        let d = Placement::default();
        Placement {
            translate: self.translate.map_or(d.translate, glam::Vec3::from),
            rotate: self.rotate.unwrap_or(d.rotate),
            scale: self.scale.unwrap_or(d.scale),
        }
    }

    /// The column choices as roles (an unknown role is an error).
    pub(crate) fn roles(&self) -> Result<Columns, String> {
        let mut c = Columns::default();
        for (role, col) in &self.columns.0 {
            c.set(role, col.clone())?;
        }
        Ok(c)
    }
}

impl TabularOptions {
    /// `spec` laid over its preset's layout (or a headed CSV with z up), for
    /// a target of `fps` frames per second. Errors give the key and message.
    pub fn resolve(spec: &TabularSpec, fps: f32) -> std::result::Result<TabularOptions, (String, String)> {
        let preset = match spec.preset {
            Some(p) => p.keys().ok_or_else(|| {
                ("preset".to_string(), format!("preset `{p:?}` is not a table; only petrack, eth and eth-ucy are"))
            })?,
            None => TabularSpec::default(),
        };
        let keys = spec.clone().over(preset);
        let d = TabularOptions::default();
        let comment = match &keys.comment {
            None => d.comment,
            Some(c) => match c.as_bytes() {
                [] => None,
                [b] if b.is_ascii() && !b.is_ascii_alphanumeric() => Some(*b),
                _ => return Err(("comment".into(), format!("`{c}`: a comment prefix is one punctuation character"))),
            },
        };
        let columns = keys.roles().map_err(|m| ("columns".to_string(), m))?;
        let o = TabularOptions {
            preset: spec.preset,
            delimiter: keys.delimiter.unwrap_or(d.delimiter),
            comment,
            header: keys.header.unwrap_or(d.header),
            columns,
            units: keys.units,
            up: keys.up.unwrap_or(d.up),
            handedness: keys.handedness.unwrap_or(d.handedness),
            heading_units: keys.heading_units.unwrap_or(d.heading_units),
            source_fps: keys.source_fps,
            fps,
            max_gap: keys.max_gap.unwrap_or(d.max_gap),
            heading: keys.heading.unwrap_or(d.heading),
            heading_window: keys.heading_window.unwrap_or(d.heading_window),
            hold_speed: keys.hold_speed.unwrap_or(d.hold_speed),
            turn_rate: keys.turn_rate.unwrap_or(d.turn_rate),
            placement: keys.placement(),
            rig: keys.rig.unwrap_or(d.rig),
            cycle: keys.cycle.unwrap_or(d.cycle),
            idle_cycle: keys.idle_cycle,
            gaits: d.gaits,
            default_gait: d.default_gait,
        };
        o.check()?;
        Ok(o)
    }
}

/// PeTrack `.txt`: `# id frame x/cm y/cm z/cm`; z is the head's height, not
/// the feet's, so it is not read. Units and frame rate come from the comments.
const PETRACK: &str = r#"
delimiter = "whitespace"
header = false
columns = { id = 1, frame = 2, x = 3, y = 4 }
"#;

/// ETH BIWI `obsmat.txt`: [frame id pos_x pos_z pos_y v_x v_z v_y]; frame
/// numbers step 6 per 0.4 s annotation in seq_eth, so 15 frames per second.
const ETH: &str = r#"
delimiter = "whitespace"
header = false
columns = { frame = 1, id = 2, x = 3, y = 5, vx = 6, vy = 8 }
units = "m"
source_fps = 15.0
"#;

/// ETH/UCY benchmark files: frame id x y; frame numbers step 10 per 0.4 s
/// sample (25 fps video).
const ETH_UCY: &str = r#"
delimiter = "whitespace"
header = false
columns = { frame = 1, id = 2, x = 3, y = 4 }
units = "m"
source_fps = 25.0
"#;

impl Preset {
    /// The `[cache]` keys a table preset stands for; `None` for `throng` and
    /// `jupedsim`, which name formats, not table layouts.
    pub(crate) fn keys(self) -> Option<TabularSpec> {
        let text = match self {
            Preset::PeTrack => PETRACK,
            Preset::Eth => ETH,
            Preset::EthUcy => ETH_UCY,
            Preset::Throng | Preset::JuPedSim => return None,
        };
        // The texts above are constants, each read by a unit test.
        Some(toml::from_str(text).unwrap_or_else(|e| panic!("preset {self:?}: {e}")))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_table_preset_reads_as_layout_keys() {
        for p in [Preset::PeTrack, Preset::Eth, Preset::EthUcy] {
            let keys = p.keys().unwrap();
            assert!(keys.describes_layout(), "{p:?}");
            assert!(keys.roles().unwrap().id.is_some(), "{p:?} names the id column");
            assert_eq!(keys.set_keys().filter(|k| k.group != KeyGroup::Layout).count(), 0, "{p:?}");
        }
        assert_eq!(Preset::Throng.keys(), None);
        assert_eq!(Preset::JuPedSim.keys(), None);
    }

    #[test]
    fn keys_table_lists_every_field_once() {
        let names: Vec<&str> = KEYS.iter().map(|k| k.name).collect();
        let mut unique = names.clone();
        unique.sort_unstable();
        unique.dedup();
        assert_eq!(unique.len(), names.len());
        // Serialized, the spec's fields are exactly the table's keys.
        let all = toml::Value::try_from(TabularSpec {
            columns: ColumnChoices(vec![("z".into(), None)]),
            ..TabularSpec::default()
        })
        .unwrap();
        let fields: Vec<&str> = all.as_table().unwrap().keys().map(String::as_str).collect();
        assert!(fields.iter().all(|f| names.contains(f)), "{fields:?}");
    }

    #[test]
    fn flag_values_are_checked_by_the_fields_type() {
        let units = key("units").unwrap();
        assert_eq!(units.parse("parsecs").unwrap_err(), "unknown value `parsecs`; expected one of: m, cm, mm, ft, in");
        assert!(key("source_fps").unwrap().parse("0").unwrap_err().contains("between 0 and"));
        assert!(key("header").unwrap().parse("yes").is_err());
        assert!(key("columns").unwrap().parse("x=0").unwrap_err().contains("count from 1"));
        let spec = TabularSpec::from_values([
            ("units", units.parse("cm").unwrap()),
            ("columns", key("columns").unwrap().parse("frame=2,id=agent,z=").unwrap()),
            ("translate", key("translate").unwrap().parse("1,-2,3").unwrap()),
        ])
        .unwrap();
        assert_eq!(spec.units, Some(Units::Cm));
        assert_eq!(
            spec.columns.0,
            vec![
                ("frame".into(), Some(Column::Position(2))),
                ("id".into(), Some(Column::Name("agent".into()))),
                ("z".into(), None)
            ]
        );
        assert_eq!(spec.placement().translate, glam::Vec3::new(1.0, -2.0, 3.0));
    }

    #[test]
    fn user_keys_win_over_the_preset_and_columns_add_up() {
        let user = TabularSpec {
            units: Some(Units::Cm),
            columns: ColumnChoices(vec![("z".into(), Some(Column::Position(5)))]),
            ..Default::default()
        };
        let keys = user.over(Preset::EthUcy.keys().unwrap());
        assert_eq!(keys.units, Some(Units::Cm));
        assert_eq!(keys.source_fps, Some(25.0));
        let roles = keys.roles().unwrap();
        assert_eq!((roles.x, roles.z), (Some(Column::Position(3)), Some(Column::Position(5))));
    }
}
