//! `throng cache info` and `throng cache convert`.

use std::collections::HashSet;
use std::path::{Path, PathBuf};

use clap::error::ErrorKind;
use clap::{Arg, ArgMatches, Args, Command, FromArgMatches, Subcommand};
use serde::Deserialize;

use throng::cache::keys::{Key, KeyKind, KeyValue, KEYS};
use throng::cache::tabular::{Gait, Preset};
use throng::cache::{
    import, info, write, CacheReader, Format, Import, ImportInfo, ImportOptions, TabularOptions, TabularReport,
    TabularSpec,
};
use throng::casting::rig::import_clip;
use throng::casting::shot_cache::file_gait;
use throng::error::{Error, Result};
use throng::shot::{Axis, SkinOptions};

/// `throng cache ...`.
#[derive(Debug, Subcommand)]
pub enum CacheVerb {
    /// Frame range, agent counts, rigs, cycles and bounds of a cache.
    Info(CacheInfoArgs),
    /// Convert between formats, chosen by extension (.crowd, .csv, .sqlite, tables).
    Convert(CacheConvertArgs),
    /// Print this message or the help of the given cache verb(s).
    Help(super::shell::HelpArgs),
}

/// `throng cache info`.
#[derive(Debug, Args)]
pub struct CacheInfoArgs {
    /// Cache file (.crowd, .csv, a JuPedSim .sqlite, or a trajectory table .txt/.tsv/.dat, optionally .gz).
    pub file: PathBuf,
    /// Machine-readable output.
    #[arg(long)]
    pub json: bool,
    /// Options for simulator imports.
    #[command(flatten)]
    pub import: ImportArgs,
}

/// `throng cache convert`.
#[derive(Debug, Args)]
pub struct CacheConvertArgs {
    /// Input cache.
    pub input: PathBuf,
    /// Output cache; the format comes from the extension.
    pub output: PathBuf,
    /// Options for simulator imports.
    #[command(flatten)]
    pub import: ImportArgs,
}

/// How to turn a foreign simulator's trajectories or a trajectory table
/// into agents: the gait flags, then one flag per import key of the
/// library's table ([`KEYS`]: the same keys as a shot's `[cache]` table,
/// docs/shot.md), read into a [`TabularSpec`] as the shot's keys are.
#[derive(Debug, Clone)]
pub struct ImportArgs {
    /// Flags of the command line only: gait overrides and the target rate.
    pub gait: GaitArgs,
    /// The import keys given as flags.
    pub keys: TabularSpec,
}

/// The import flags that are not shot keys.
#[derive(Debug, Args, Clone)]
pub struct GaitArgs {
    /// Cycle length in frames (the walk cycle loops at this length).
    #[arg(long, value_parser = super::values::number)]
    pub cycle_length: Option<f32>,
    /// Metres walked per cycle; the cycle frame advances by distance / stride.
    #[arg(long, value_parser = super::values::number)]
    pub stride: Option<f32>,
    /// Rig glTF to read the cycle's length (frames at 24 fps) and stride (root
    /// travel, or a vehicle's wheel roll) from; a slot rig's name must match
    /// --rig. --stride and --cycle-length override it.
    #[arg(long)]
    pub rig_file: Option<PathBuf>,
    /// Character --rig-file: the joint (a rigid rig's node) whose travel is
    /// root motion (its Z travel is the stride), as a shot's `root` key. Any
    /// --rig-* flag reads the file as a character, skinned or rigid as its
    /// skin says (one is detected without them).
    #[arg(long, value_name = "JOINT", requires = "rig_file")]
    pub rig_root: Option<String>,
    /// Character --rig-file: the clip a cache cycle plays, CYCLE=CLIP (repeat
    /// it; a shot's `cycles` key). Unmapped cycles play the clip of their name.
    #[arg(long, value_name = "CYCLE=CLIP", value_parser = cycle_clip, requires = "rig_file")]
    pub rig_cycle: Vec<(String, String)>,
    /// Character --rig-file: metres per file unit (0.01 for centimetres), as a shot's `scale`.
    #[arg(long, value_name = "M", value_parser = positive, requires = "rig_file")]
    pub rig_scale: Option<f32>,
    /// Character --rig-file: the direction the character faces in the file
    /// (+x, -x, +y, -y, +z, -z; default +z), as a shot's `forward`.
    #[arg(long, value_name = "AXIS", value_parser = axis, allow_hyphen_values = true, requires = "rig_file")]
    pub rig_forward: Option<Axis>,
    /// Character --rig-file: the file's up axis (default +y), as a shot's `up`.
    #[arg(long, value_name = "AXIS", value_parser = axis, allow_hyphen_values = true, requires = "rig_file")]
    pub rig_up: Option<Axis>,
    /// Frames per second of the cache written (the shot's rate).
    #[arg(long, default_value_t = 24.0, value_parser = super::values::fps)]
    pub fps: f32,
}

/// `CYCLE=CLIP` of `--rig-cycle`.
fn cycle_clip(text: &str) -> std::result::Result<(String, String), String> {
    match text.split_once('=') {
        Some((c, k)) if !c.is_empty() && !k.is_empty() => Ok((c.to_string(), k.to_string())),
        _ => Err(format!("`{text}`: give CYCLE=CLIP, e.g. WalkA=Walk")),
    }
}

/// A positive finite number.
fn positive(text: &str) -> std::result::Result<f32, String> {
    match text.parse::<f32>() {
        Ok(v) if v > 0.0 && v.is_finite() => Ok(v),
        _ => Err(format!("`{text}`: give a positive number")),
    }
}

/// An axis as a shot writes it: `+x` ... `-z`.
fn axis(text: &str) -> std::result::Result<Axis, String> {
    use serde::de::{value::StrDeserializer, IntoDeserializer};
    let d: StrDeserializer<serde::de::value::Error> = text.into_deserializer();
    Axis::deserialize(d).map_err(|_| format!("`{text}`: give one of +x, -x, +y, -y, +z, -z"))
}

/// The flag of an import key: `--source-fps` for `source_fps`, its value
/// read by [`Key::parse`].
fn key_arg(key: &'static Key) -> Arg {
    Arg::new(key.name)
        .long(key.name.replace('_', "-"))
        .value_name(key.name.to_uppercase())
        .help(key.help())
        .allow_hyphen_values(matches!(key.kind, KeyKind::Number | KeyKind::Vector))
        .value_parser(move |text: &str| key.parse(text))
}

impl Args for ImportArgs {
    fn augment_args(cmd: Command) -> Command {
        KEYS.iter().fold(GaitArgs::augment_args(cmd), |cmd, key| cmd.arg(key_arg(key)))
    }
    fn augment_args_for_update(cmd: Command) -> Command {
        ImportArgs::augment_args(cmd)
    }
}

impl FromArgMatches for ImportArgs {
    fn from_arg_matches(m: &ArgMatches) -> std::result::Result<Self, clap::Error> {
        let gait = GaitArgs::from_arg_matches(m)?;
        let values = KEYS.iter().filter_map(|k| m.get_one::<KeyValue>(k.name).map(|v| (k.name, v.clone())));
        let keys = TabularSpec::from_values(values).map_err(|e| clap::Error::raw(ErrorKind::ValueValidation, e))?;
        Ok(ImportArgs { gait, keys })
    }
    fn update_from_arg_matches(&mut self, m: &ArgMatches) -> std::result::Result<(), clap::Error> {
        *self = ImportArgs::from_arg_matches(m)?;
        Ok(())
    }
}

impl ImportArgs {
    /// The rig and walk cycle every agent gets (flags or their defaults).
    fn names(&self) -> (String, String) {
        let d = ImportOptions::default();
        (self.keys.rig.clone().unwrap_or(d.rig), self.keys.cycle.clone().unwrap_or(d.cycle))
    }

    /// The skinned-rig options the `--rig-*` flags give (`None`: none given,
    /// the file's kind is detected).
    fn skin(&self) -> Option<SkinOptions> {
        let g = &self.gait;
        let given = g.rig_root.is_some()
            || !g.rig_cycle.is_empty()
            || g.rig_scale.is_some()
            || g.rig_forward.is_some()
            || g.rig_up.is_some();
        let d = SkinOptions::default();
        given.then(|| SkinOptions {
            cycles: g.rig_cycle.iter().cloned().collect(),
            up: g.rig_up.unwrap_or(d.up),
            forward: g.rig_forward.unwrap_or(d.forward),
            scale: g.rig_scale.unwrap_or(d.scale),
            root: g.rig_root.clone(),
            ..d
        })
    }

    /// The import options these flags ask for (reads `--rig-file`).
    fn options(&self) -> Result<ImportOptions> {
        let (rig, cycle) = self.names();
        let g = &self.gait;
        // The flags are checked before the rig file is read.
        ImportOptions::new(&rig, &cycle, g.stride, g.cycle_length, None)?.with_motion(&self.keys)?;
        let skin = self.skin();
        let clip = g.rig_file.as_deref().map(|f| import_clip(f, &rig, &cycle, skin.as_ref(), g.stride)).transpose()?;
        ImportOptions::new(&rig, &cycle, g.stride, g.cycle_length, clip)?.with_motion(&self.keys)
    }

    /// How to read `input`: a table when its extension or the layout flags
    /// say so, else by extension; the placement flags apply to every format.
    fn import(&self, input: &Path) -> Result<Import> {
        let format = Format::of(input)?;
        let spec = &self.keys;
        let placement = spec.placement();
        let flag = |(k, m): (String, String)| Error::Usage(format!("--{}: {m}", k.replace('_', "-")));
        placement.check_key().map_err(flag)?;
        if matches!(spec.preset, Some(Preset::JuPedSim)) && format != Format::JuPedSim {
            return Err(Error::Usage(format!("{}: --preset jupedsim reads .sqlite files", input.display())));
        }
        let table = format == Format::Tabular || (format == Format::Csv && spec.describes_layout());
        // The gait and turn-rate flags are checked whatever the format uses.
        let (rig, cycle) = self.names();
        ImportOptions::new(&rig, &cycle, self.gait.stride, self.gait.cycle_length, None)?.with_motion(spec)?;
        if !table {
            if format == Format::JuPedSim {
                if let Some(refused) = spec.jupedsim_refuses() {
                    return Err(flag((refused.0.to_string(), refused.1)));
                }
            }
            let jupedsim = if format == Format::JuPedSim { self.options()? } else { ImportOptions::default() };
            return Ok(Import { jupedsim, tabular: None, placement });
        }
        if !spec.describes_layout() {
            return Err(throng::cache::needs_layout(input));
        }
        let mut o = TabularOptions::resolve(spec, self.gait.fps).map_err(flag)?;
        let jp = self.options()?;
        let idle_length = match (&self.gait.rig_file, &spec.idle_cycle) {
            (Some(f), Some(_)) => {
                let (skin, walk) = (self.skin(), self.names().1);
                file_gait(f, skin.as_ref(), &walk, spec.idle_cycle.as_deref(), self.gait.stride)?.idle_length
            }
            _ => Gait::default().idle_length,
        };
        o.default_gait = Gait { stride: jp.stride(), cycle_length: jp.cycle_length(), idle_length };
        Ok(Import { jupedsim: jp, tabular: Some(o), placement })
    }
}

/// Runs a `throng cache` verb.
pub fn run(verb: &CacheVerb) -> Result<()> {
    match verb {
        CacheVerb::Info(args) => run_info(args),
        CacheVerb::Convert(args) => run_convert(args),
        CacheVerb::Help(args) => super::shell::help(&["cache"], args),
    }
}

/// One line for humans about a table import.
fn describe_table(o: &TabularOptions, r: &TabularReport) -> String {
    let g = o.default_gait;
    let time = match r.source_fps {
        Some(f) => format!("{f} fps resampled to {} fps", r.fps),
        None => format!("seconds resampled to {} fps", r.fps),
    };
    format!(
        "{} rows, {} agents, {time}, units {}, {} gaps over {} s left empty; rig {}, cycle {}, stride {} m, cycle length {} frames",
        r.rows,
        r.agents,
        r.units.map_or("m".into(), |u| format!("{u:?}").to_ascii_lowercase()),
        r.gaps,
        o.max_gap,
        o.rig,
        o.cycle,
        g.stride,
        g.cycle_length
    )
}

/// `throng cache info FILE [--json]`: prints to stdout, warnings to stderr.
fn run_info(args: &CacheInfoArgs) -> Result<()> {
    let how = args.import.import(&args.file)?;
    let format = Format::of(&args.file)?;
    let (crowd, report) = match (format, &how.tabular) {
        (Format::Binary, None) if how.placement.is_identity() => (None, None),
        _ => {
            let (c, r) = import(&args.file, &how)?;
            (Some(c), r)
        }
    };
    let reader = match crowd {
        Some(c) => CacheReader::from_crowd(&args.file, c),
        None => CacheReader::open(&args.file)?,
    };
    let mut info = info(&reader)?;
    let opts = &how.jupedsim;
    if format == Format::JuPedSim {
        info.import = Some(ImportInfo {
            rig: opts.rig.clone(),
            cycle: opts.cycle.clone(),
            stride: opts.stride(),
            cycle_length: opts.cycle_length(),
            rig_file: opts.rig_clip.as_ref().map(|c| c.file.display().to_string()),
        });
    }
    if let Some(o) = &how.tabular {
        info.format = Format::Tabular.name().to_string();
        info.import = Some(ImportInfo {
            rig: o.rig.clone(),
            cycle: o.cycle.clone(),
            stride: o.default_gait.stride,
            cycle_length: o.default_gait.cycle_length,
            rig_file: args.import.gait.rig_file.as_ref().map(|f| f.display().to_string()),
        });
    }
    for w in &info.warnings {
        super::warn(w)?;
    }
    if args.json {
        outln!("{}", super::to_json(&info)?);
    } else {
        out!("{}", info.to_text());
        if format == Format::JuPedSim {
            outln!("{:<8} {}", "import", opts.describe());
        }
        if let (Some(o), Some(r)) = (&how.tabular, &report) {
            outln!("{:<8} {}", "import", describe_table(o, r));
        }
    }
    Ok(())
}

/// `throng cache convert IN OUT`: reads IN whole, writes OUT atomically.
fn run_convert(args: &CacheConvertArgs) -> Result<()> {
    let (from, to) = (Format::of(&args.input)?, Format::of(&args.output)?);
    super::existing_folder_of(&args.output, "OUTPUT")?;
    if matches!(to, Format::JuPedSim | Format::Tabular) {
        return Err(Error::Usage(format!(
            "{}: {} files are read only; convert to .crowd or .csv",
            args.output.display(),
            to.name()
        )));
    }
    let how = args.import.import(&args.input)?;
    let mut inputs = vec![("input cache".to_string(), args.input.clone())];
    inputs.extend(args.import.gait.rig_file.iter().map(|f| ("rig file".to_string(), f.clone())));
    throng::output::refuse_input_overwrite([args.output.as_path()], inputs)?;
    let (crowd, report) = import(&args.input, &how)?;
    // Warned before the write: under --strict a warning stops the convert with no output.
    for w in throng::cache::bounds_warnings(&crowd) {
        super::warn(&w)?;
    }
    write(&args.output, &crowd)?;
    let agents: HashSet<u32> = crowd.frames.iter().flat_map(|b| b.agents.iter().map(|a| a.id)).collect();
    let from_name = if how.tabular.is_some() { Format::Tabular.name() } else { from.name() };
    outln!(
        "wrote {} ({}): {} frames, {} agents, from {} ({})",
        args.output.display(),
        to.name(),
        crowd.frames.len(),
        agents.len(),
        args.input.display(),
        from_name
    );
    if from == Format::JuPedSim {
        outln!("import: {}", how.jupedsim.describe());
    }
    if let (Some(o), Some(r)) = (&how.tabular, &report) {
        outln!("import: {}", describe_table(o, r));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use throng::shot::Shot;

    /// Each import key with a flag value and the same value as a shot writes
    /// it, over a base that every sample fits (a table preset).
    const SAMPLES: &[(&str, &str, &str)] = &[
        ("preset", "petrack", r#""petrack""#),
        ("delimiter", ";", r#"";""#),
        ("comment", "%", r#""%""#),
        ("header", "true", "true"),
        ("columns", "z=5,vx=", r#"{ z = 5, vx = "" }"#),
        ("units", "cm", r#""cm""#),
        ("up", "y", r#""y""#),
        ("handedness", "left", r#""left""#),
        ("heading_units", "degrees", r#""degrees""#),
        ("source_fps", "30", "30"),
        ("max_gap", "2.5", "2.5"),
        ("heading", "motion", r#""motion""#),
        ("heading_window", "1.5", "1.5"),
        ("hold_speed", "0.5", "0.5"),
        ("turn_rate", "90", "90"),
        ("rig", "bipedTallB", r#""bipedTallB""#),
        ("cycle", "RunA", r#""RunA""#),
        ("idle_cycle", "IdleA", r#""IdleA""#),
        ("translate", "1,2,-3", "[1.0, 2.0, -3.0]"),
        ("rotate", "-90", "-90.0"),
        ("scale", "2", "2"),
    ];

    fn from_flags(flags: &[&str]) -> TabularSpec {
        let cmd = ImportArgs::augment_args(Command::new("t").no_binary_name(true));
        let m = cmd.try_get_matches_from(flags).unwrap_or_else(|e| panic!("{flags:?}: {e}"));
        ImportArgs::from_arg_matches(&m).unwrap().keys
    }

    fn from_shot(cache_keys: &str) -> TabularSpec {
        // Cargo.toml stands in for the cache file (only its existence is checked here).
        let text = format!(
            "version = 1\nname = \"k\"\n[frames]\nstart = 1\nend = 2\n[cache]\npath = \"Cargo.toml\"\n{cache_keys}\n\
             [camera]\nkeys = [{{ frame = 1.0, position = [0.0, 1.0, 5.0], aim = [0.0, 1.0, 0.0], focal_length = 35.0 }}]\n"
        );
        let shot_path = Path::new(env!("CARGO_MANIFEST_DIR")).join("shot.toml");
        Shot::parse(&text, &shot_path).unwrap_or_else(|e| panic!("{cache_keys}: {e}")).cache.import
    }

    #[test]
    fn every_shot_key_and_its_flag_reach_the_same_field() {
        let names: Vec<&str> = SAMPLES.iter().map(|s| s.0).collect();
        assert_eq!(names, KEYS.iter().map(|k| k.name).collect::<Vec<_>>(), "a sample per key, in table order");
        for &(name, flag_value, toml_value) in SAMPLES {
            let flag = format!("--{}", name.replace('_', "-"));
            let (flag_base, shot_base) = if name == "preset" {
                (vec![], String::new())
            } else {
                (vec!["--preset", "eth-ucy"], "preset = \"eth-ucy\"\n".into())
            };
            let mut flags = flag_base.clone();
            flags.extend([flag.as_str(), flag_value]);
            let by_flag = from_flags(&flags);
            let by_shot = from_shot(&format!("{shot_base}{name} = {toml_value}"));
            assert_eq!(by_flag, by_shot, "{name}");
            // The key reached its own field and no other.
            let base = from_flags(&flag_base);
            assert_ne!(by_flag, base, "{name} changes the spec");
            let changed: Vec<&str> =
                by_flag.set_keys().filter(|k| !base.set_keys().any(|b| b.name == k.name)).map(|k| k.name).collect();
            if name != "preset" {
                assert_eq!(changed, [name], "{name}");
            }
        }
    }

    #[test]
    fn key_flags_refuse_bad_values_at_parse_time() {
        let cmd = ImportArgs::augment_args(Command::new("t").no_binary_name(true));
        let e = cmd.try_get_matches_from(["--units", "parsecs"]).unwrap_err().to_string();
        assert!(e.contains("--units") && e.contains("unknown value `parsecs`; expected one of: m, cm, mm, ft"), "{e}");
    }
}
