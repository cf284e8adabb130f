//! `throng cache info` and `throng cache convert`.

use std::collections::HashSet;
use std::path::{Path, PathBuf};

use clap::{Args, Subcommand};
use glam::Vec3;

use throng::cache::tabular::{
    self, AngleUnits, Column, Delimiter, Gait, Handedness, HeadingFrom, Preset, Units, UpAxis,
};
use throng::cache::{
    import, info, write, CacheReader, Format, Import, ImportInfo, ImportOptions, Placement, TabularOptions,
    TabularReport, TabularSpec,
};
use throng::casting::rig::import_clip;
use throng::casting::shot_cache::gait;
use throng::error::{Error, Result};

/// `throng cache ...`.
#[derive(Debug, Subcommand)]
pub enum CacheVerb {
    /// Frame range, agent counts, rigs, cycles and bounds of a cache.
    Info(CacheInfoArgs),
    /// Convert between formats, chosen by extension (.crowd, .csv, .sqlite, tables).
    Convert(CacheConvertArgs),
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
/// into agents (the same choices as a shot's `[cache]` keys, docs/shot.md).
#[derive(Debug, Args, Clone)]
pub struct ImportArgs {
    /// Rig given to every imported agent.
    #[arg(long, default_value = "bipedThinA")]
    pub rig: String,
    /// Walk cycle given to every imported agent.
    #[arg(long, default_value = "WalkA")]
    pub cycle: String,
    /// Cycle length in frames (the walk cycle loops at this length).
    #[arg(long)]
    pub cycle_length: Option<f32>,
    /// Metres walked per cycle; the cycle frame advances by distance / stride.
    #[arg(long)]
    pub stride: Option<f32>,
    /// Rig glTF to read the cycle's length (frames at 24 fps) and stride (root
    /// travel) from; its rig name must match --rig. --stride and --cycle-length override it.
    #[arg(long)]
    pub rig_file: Option<PathBuf>,
    /// Table layout preset: petrack, eth (obsmat), eth-ucy (frame id x y).
    #[arg(long, value_parser = parse::<Preset>)]
    pub preset: Option<Preset>,
    /// Field delimiter: `,` `;` `tab` or `whitespace`.
    #[arg(long, value_parser = parse::<Delimiter>)]
    pub delimiter: Option<Delimiter>,
    /// Comment prefix character (empty: none).
    #[arg(long)]
    pub comment: Option<String>,
    /// Whether the first row names the columns (true or false).
    #[arg(long)]
    pub header: Option<bool>,
    /// Columns by role: frame|time, id, x, y, z, heading, vx, vy, vz, rig,
    /// cycle = header name or 1-based position, e.g. frame=frame,id=agent_id,x=3.
    #[arg(long, value_parser = parse_columns)]
    pub columns: Option<Columns>,
    /// Source units: m, cm, mm, ft.
    #[arg(long, value_parser = parse::<Units>)]
    pub units: Option<Units>,
    /// Source up axis: y or z.
    #[arg(long, value_parser = parse::<UpAxis>)]
    pub up: Option<UpAxis>,
    /// Source handedness: right or left.
    #[arg(long, value_parser = parse::<Handedness>)]
    pub handedness: Option<Handedness>,
    /// Unit of the heading column: radians or degrees.
    #[arg(long, value_parser = parse::<AngleUnits>)]
    pub heading_units: Option<AngleUnits>,
    /// Frames per second of the source's frame column.
    #[arg(long, value_parser = super::values::fps)]
    pub source_fps: Option<f32>,
    /// Frames per second of the cache written (the shot's rate).
    #[arg(long, default_value_t = 24.0, value_parser = super::values::fps)]
    pub fps: f32,
    /// Longest interval between samples, seconds, interpolated across; longer is a gap.
    #[arg(long)]
    pub max_gap: Option<f32>,
    /// Heading from: auto, column, velocity, motion.
    #[arg(long, value_parser = parse::<HeadingFrom>)]
    pub heading: Option<HeadingFrom>,
    /// Heading smoothing window, seconds.
    #[arg(long)]
    pub heading_window: Option<f32>,
    /// Speed (m/s) below which the heading is held and the idle cycle plays.
    #[arg(long)]
    pub hold_speed: Option<f32>,
    /// Cycle for standing agents (with --rig-file, its length comes from the rig).
    #[arg(long)]
    pub idle_cycle: Option<String>,
    /// Move the crowd by X,Y,Z metres (after rotate and scale).
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub translate: Option<[f32; 3]>,
    /// Turn the crowd by this many degrees about +Y (up).
    #[arg(long, allow_hyphen_values = true)]
    pub rotate: Option<f32>,
    /// Scale the crowd about the origin.
    #[arg(long)]
    pub scale: Option<f32>,
}

/// `--columns` value: the role list, in order.
#[derive(Debug, Clone)]
pub struct Columns(pub Vec<(String, Option<Column>)>);

fn parse<T: std::str::FromStr<Err = String>>(s: &str) -> std::result::Result<T, String> {
    s.parse()
}

fn parse_columns(s: &str) -> std::result::Result<Columns, String> {
    tabular::Columns::parse_list(s).map(Columns)
}

fn parse_vec3(s: &str) -> std::result::Result<[f32; 3], String> {
    let v: Vec<f32> = s
        .split(',')
        .map(|x| x.trim().parse::<f32>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|_| format!("`{s}`: expected X,Y,Z"))?;
    v.try_into().map_err(|_| format!("`{s}`: expected three numbers X,Y,Z"))
}

impl ImportArgs {
    /// The import options these flags ask for (reads `--rig-file`).
    fn options(&self) -> Result<ImportOptions> {
        // The flags are checked before the rig file is read.
        ImportOptions::new(&self.rig, &self.cycle, self.stride, self.cycle_length, None)?;
        let clip = self.rig_file.as_deref().map(|f| import_clip(f, &self.rig, &self.cycle)).transpose()?;
        ImportOptions::new(&self.rig, &self.cycle, self.stride, self.cycle_length, clip)
    }

    fn spec(&self) -> TabularSpec {
        let d = Placement::default();
        TabularSpec {
            preset: self.preset,
            delimiter: self.delimiter,
            comment: self.comment.clone(),
            header: self.header,
            columns: self.columns.clone().map(|c| c.0).unwrap_or_default(),
            units: self.units,
            up: self.up,
            handedness: self.handedness,
            heading_units: self.heading_units,
            source_fps: self.source_fps,
            max_gap: self.max_gap,
            heading: self.heading,
            heading_window: self.heading_window,
            hold_speed: self.hold_speed,
            rig: Some(self.rig.clone()),
            cycle: Some(self.cycle.clone()),
            idle_cycle: self.idle_cycle.clone(),
            placement: Placement {
                translate: self.translate.map_or(d.translate, Vec3::from),
                rotate: self.rotate.unwrap_or(d.rotate),
                scale: self.scale.unwrap_or(d.scale),
            },
        }
    }

    /// How to read `input`: a table when its extension or the layout flags
    /// say so, else by extension; the placement flags apply to every format.
    fn import(&self, input: &Path) -> Result<Import> {
        let format = Format::of(input)?;
        let spec = self.spec();
        let flag = |(k, m): (String, String)| Error::Usage(format!("--{}: {m}", k.replace('_', "-")));
        spec.placement.check_key().map_err(flag)?;
        if matches!(self.preset, Some(Preset::JuPedSim)) && format != Format::JuPedSim {
            return Err(Error::Usage(format!("{}: --preset jupedsim reads .sqlite files", input.display())));
        }
        let table = format == Format::Tabular || (format == Format::Csv && spec.describes_layout());
        if !table {
            let jupedsim = if format == Format::JuPedSim { self.options()? } else { ImportOptions::default() };
            return Ok(Import { jupedsim, tabular: None, placement: spec.placement });
        }
        if !spec.describes_layout() {
            return Err(throng::cache::needs_layout(input));
        }
        let mut o = TabularOptions::resolve(&spec, self.fps).map_err(flag)?;
        let jp = self.options()?;
        let idle_length = match (&self.rig_file, &self.idle_cycle) {
            (Some(f), Some(_)) => gait(f, &self.cycle, self.idle_cycle.as_deref())?.idle_length,
            _ => Gait::default().idle_length,
        };
        o.default_gait = Gait { stride: jp.stride(), cycle_length: jp.cycle_length(), idle_length };
        Ok(Import { jupedsim: jp, tabular: Some(o), placement: spec.placement })
    }
}

/// Runs a `throng cache` verb.
pub fn run(verb: &CacheVerb) -> Result<()> {
    match verb {
        CacheVerb::Info(args) => run_info(args),
        CacheVerb::Convert(args) => run_convert(args),
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
            rig_file: args.import.rig_file.as_ref().map(|f| f.display().to_string()),
        });
    }
    for w in &info.warnings {
        eprintln!("throng: warning: {w}");
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
    let (crowd, report) = import(&args.input, &how)?;
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
    for w in throng::cache::bounds_warnings(&crowd) {
        eprintln!("throng: warning: {w}");
    }
    Ok(())
}
