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
//!
//! What the stages are told ([`TabularOptions`] and the types of its
//! fields) lives in `tabular_options`, re-exported here.

use std::collections::{BTreeMap, HashMap};
use std::io::Read;
use std::path::Path;

use glam::DVec3;

pub use super::keys::{ColumnChoices, TabularSpec};
pub use super::tabular_options::{
    AngleUnits, Column, Columns, Delimiter, Gait, Handedness, HeadingFrom, Placement, Preset, TabularOptions, Units,
    UpAxis,
};
use super::tabular_options::{MAX_FPS, ROLES};
use super::{check_name, validate, AgentSample, CrowdCache, FrameBlock};
use crate::error::{Error, IoContext, Result};

/// Largest input read, after gzip decompression (bytes).
pub(crate) const MAX_INPUT_BYTES: u64 = 2 << 30;
/// Most data rows read from one file.
pub(crate) const MAX_ROWS: usize = 20_000_000;
/// Most agent records an import may produce after resampling; checked
/// before any per-frame array is allocated.
pub(crate) const MAX_AGENT_FRAMES: u64 = 50_000_000;

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

#[cfg(test)]
fn pos(n: usize) -> Option<Column> {
    Some(Column::Position(n))
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
    pub(crate) agent_frames: u64,
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

/// Reads at most `cap` bytes of `r` into `bytes`, counted as they arrive
/// (for gzip, as they are inflated): the buffer grows by doubling but never
/// past `cap`, and a growth the allocator refuses is an error, not an abort.
fn read_capped(mut r: impl Read, cap: u64, bytes: &mut Vec<u8>) -> std::io::Result<()> {
    let cap = usize::try_from(cap).unwrap_or(usize::MAX);
    let mut block = vec![0u8; 1 << 16];
    while bytes.len() < cap {
        let want = block.len().min(cap - bytes.len());
        let n = match r.read(&mut block[..want]) {
            Ok(0) => break,
            Ok(n) => n,
            Err(e) if e.kind() == std::io::ErrorKind::Interrupted => continue,
            Err(e) => return Err(e),
        };
        if bytes.capacity() - bytes.len() < n {
            let grow = (bytes.capacity().max(1 << 20) * 2).min(cap).max(bytes.len() + n) - bytes.len();
            bytes.try_reserve_exact(grow).map_err(|_| {
                std::io::Error::new(
                    std::io::ErrorKind::OutOfMemory,
                    format!("cannot hold {} bytes of text in memory", bytes.len() + grow),
                )
            })?;
        }
        bytes.extend_from_slice(&block[..n]);
    }
    Ok(())
}

/// Reads the file's text: gzip (by magic bytes) is decompressed; a byte
/// order mark is dropped; at most [`MAX_INPUT_BYTES`].
pub(crate) fn read_text(path: &Path) -> Result<String> {
    let file = std::fs::File::open(path).at(path)?;
    let mut head = [0u8; 2];
    let mut bytes = Vec::new();
    let mut raw = std::io::BufReader::new(file);
    let n = raw.read(&mut head).at(path)?;
    let chained = std::io::Read::chain(&head[..n], raw);
    let gz = n == 2 && head == [0x1f, 0x8b];
    let read = if gz {
        read_capped(flate2::read::MultiGzDecoder::new(chained), MAX_INPUT_BYTES + 1, &mut bytes)
    } else {
        read_capped(chained, MAX_INPUT_BYTES + 1, &mut bytes)
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
        let what = if gz { "decompresses to more" } else { "holds more" };
        return Err(Error::invalid(path, format!("{what} than {MAX_INPUT_BYTES} bytes of text; split the file")));
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

/// What PeTrack's comment header says: `# framerate: 25 fps`, and the units
/// a header names ([`super::units::header_units`]).
fn sniff_comments(text: &str, comment: Option<u8>, header: bool) -> (Option<f32>, Option<Units>) {
    let mut fps = None;
    for line in text.lines().take(200).map(str::trim_start) {
        let Some(rest) = comment.and_then(|c| line.strip_prefix(c as char)) else { continue };
        let rest = rest.trim().to_ascii_lowercase();
        if let Some(v) = rest.strip_prefix("framerate:") {
            fps = fps.or(v.split_whitespace().next().and_then(|n| n.parse::<f32>().ok()));
        }
    }
    (fps, super::units::header_units(text, comment, header))
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
/// The stages of the module's documentation, in order.
pub fn parse_str(path: &Path, text: &str, o: &TabularOptions) -> Result<(CrowdCache, TabularReport)> {
    o.check().map_err(|(k, m)| Error::invalid(path, m).field(k))?;
    let (units, source_fps) = units_and_rate(path, text, o)?;
    let table = Table::new(text, o);
    let tracks = read_rows(path, &table, o, units, source_fps)?;
    let fps = f64::from(o.fps);
    let max_gap = f64::from(o.max_gap);
    check_output_size(path, &tracks.agents, fps, max_gap)?;

    let window_half = window_half(f64::from(o.heading_window), fps);
    let heading_from = match o.heading {
        HeadingFrom::Auto if o.columns.heading.is_some() => HeadingFrom::Column,
        HeadingFrom::Auto if o.columns.vx.is_some() => HeadingFrom::Velocity,
        HeadingFrom::Auto => HeadingFrom::Motion,
        h => h,
    };
    let mut report = TabularReport {
        rows: tracks.rows,
        agents: tracks.agents.len(),
        source_fps: source_fps.map(|f| f as f32),
        fps: o.fps,
        units: Some(units),
        ..Default::default()
    };
    let mut frames: BTreeMap<i32, Vec<AgentSample>> = BTreeMap::new();
    for (&id, track) in &tracks.agents {
        let runs = resample(track, fps, max_gap);
        report.gaps += track.windows(2).filter(|w| w[1].t - w[0].t > max_gap).count();
        let (mut headings, moving) = headings(&runs, heading_from, window_half, f64::from(o.hold_speed), fps);
        let step = f64::from(o.turn_rate).to_radians() / fps;
        let mut start = 0;
        for run in &runs {
            limit_turn(&mut headings[start..start + run.len()], step);
            start += run.len();
        }
        for (k, a) in walk_cycles(id, &runs, &headings, &moving, o, &tracks) {
            frames.entry(k).or_default().push(a);
            report.agent_frames += 1;
        }
    }
    let crowd = CrowdCache {
        rigs: tracks.rigs.names,
        cycles: tracks.cycles.names,
        frames: frames.into_iter().map(|(frame, agents)| FrameBlock { frame, agents }).collect(),
    };
    validate(path, &crowd)?;
    Ok((super::canonical(&crowd), report))
}

/// The source's units and frame rate (`None` with a time column): the
/// options', else what the file's header says (PeTrack's comments, a
/// column name), else metres.
fn units_and_rate(path: &Path, text: &str, o: &TabularOptions) -> Result<(Units, Option<f64>)> {
    let (sniffed_fps, sniffed_units) = sniff_comments(text, o.comment, o.header);
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
    Ok((units, source_fps))
}

/// Stage 1: the text as the csv crate reads it. Comment lines are blanked
/// and whitespace tables become tab-separated, line by line, so line
/// numbers stay (the csv crate's own comment handling loses count of the
/// lines it skips).
struct Table {
    data: String,
    /// Byte offset of each line's start.
    starts: Vec<usize>,
    delimiter: u8,
}

impl Table {
    fn new(text: &str, o: &TabularOptions) -> Table {
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
        // Lines from byte offsets: the csv crate's own line count skips comment lines.
        let starts = std::iter::once(0).chain(data.match_indices('\n').map(|(i, _)| i + 1)).collect();
        Table { data, starts, delimiter }
    }

    fn reader(&self) -> csv::Reader<&[u8]> {
        csv::ReaderBuilder::new()
            .has_headers(false)
            .flexible(true)
            .delimiter(self.delimiter)
            .trim(csv::Trim::All)
            .from_reader(self.data.as_bytes())
    }

    /// The 1-based line of the record read from `byte`: a record's position
    /// is where reading began, before any blank lines it skipped.
    fn line_at(&self, byte: u64) -> usize {
        let bytes = self.data.as_bytes();
        let mut i = usize::try_from(byte).unwrap_or(usize::MAX).min(bytes.len());
        while bytes.get(i).is_some_and(|c| *c == b'\n' || *c == b'\r') {
            i += 1;
        }
        self.starts.partition_point(|&s| s <= i)
    }

    fn error(&self, path: &Path, e: csv::Error) -> Error {
        let line = e.position().map(|p| self.line_at(p.byte()));
        let err = Error::invalid(path, format!("cannot read the table: {e}"));
        match line {
            Some(l) => err.line(l),
            None => err,
        }
    }
}

/// Stage 2's column map: role -> 0-based index, and the header line for messages.
struct ColumnIndex {
    index: HashMap<&'static str, usize>,
    header: Option<Vec<String>>,
}

impl ColumnIndex {
    fn new(path: &Path, columns: &Columns, header: Option<Vec<String>>) -> Result<ColumnIndex> {
        let mut index = HashMap::new();
        for role in ROLES {
            let Some(col) = columns.pick(role) else { continue };
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
                    return Err(Error::invalid(
                        path,
                        format!("column `{name}` chosen by name, but the file has no header"),
                    )
                    .field(role))
                }
            };
            index.insert(role, i);
        }
        Ok(ColumnIndex { index, header })
    }

    /// `column 3 (x)`, or `column 3 (pos_x, x)` when the header names it otherwise.
    fn label(&self, role: &str) -> String {
        let i = self.index[role];
        match self.header.as_ref().and_then(|h| h.get(i)) {
            Some(h) if !h.eq_ignore_ascii_case(role) => format!("column {} ({h}, {role})", i + 1),
            _ => format!("column {} ({role})", i + 1),
        }
    }
}

/// Rig or cycle names, numbered in order of first use.
#[derive(Default)]
struct Names {
    names: Vec<String>,
    ids: HashMap<String, u16>,
}

impl Names {
    fn of(names: impl IntoIterator<Item = String>) -> Names {
        let mut out = Names::default();
        for n in names {
            if !out.ids.contains_key(&n) {
                out.ids.insert(n.clone(), out.names.len() as u16);
                out.names.push(n);
            }
        }
        out
    }

    fn intern(&mut self, n: &str) -> std::result::Result<u16, String> {
        if let Some(&i) = self.ids.get(n) {
            return Ok(i);
        }
        check_name(n)?;
        let i = u16::try_from(self.names.len()).map_err(|_| "more than 65536 distinct names".to_string())?;
        self.names.push(n.to_string());
        self.ids.insert(n.to_string(), i);
        Ok(i)
    }
}

/// Stage 2's output: each agent's samples in time order, and the names they use.
struct Tracks {
    agents: BTreeMap<u32, Vec<Sample>>,
    rigs: Names,
    cycles: Names,
    rows: usize,
}

/// Stage 2: rows -> placed samples per agent, each agent's going forward in time.
fn read_rows(path: &Path, table: &Table, o: &TabularOptions, units: Units, source_fps: Option<f64>) -> Result<Tracks> {
    let mut reader = table.reader();
    let mut records = reader.records();
    let mut header: Option<Vec<String>> = None;
    if o.header {
        match records.next() {
            Some(r) => header = Some(r.map_err(|e| table.error(path, e))?.iter().map(str::to_string).collect()),
            None => return Err(Error::invalid(path, "empty file: expected a header line naming the columns").line(1)),
        }
    }
    let columns = ColumnIndex::new(path, &o.columns, header)?;
    let index = &columns.index;
    let label = |role: &str| columns.label(role);

    // The walk cycle is cycle 0 and the idle cycle next; without a rig column every agent has rig 0.
    let mut cycles = Names::of(std::iter::once(o.cycle.clone()).chain(o.idle_cycle.clone()));
    let mut rigs = Names::of(o.columns.rig.is_none().then(|| o.rig.clone()));
    let mut agents: BTreeMap<u32, Vec<Sample>> = BTreeMap::new();
    let mut rows = 0usize;
    let rotation = o.placement.rotation();
    for record in records {
        let record = record.map_err(|e| table.error(path, e))?;
        if record.iter().all(str::is_empty) {
            continue;
        }
        let line = record.position().map_or(0, |p| table.line_at(p.byte()));
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
                    format!("{}: missing; this row has {} columns", label(role), record.len()),
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
                    format!("{}: cannot read `{}` as a number", label(role), c.escape_debug()),
                )
                .line(line)
                .field(role)),
            }
        };
        let id = agent_id(path, cell("id")?.unwrap_or_default(), &columns, line)?;
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
            move |m: String| Error::invalid(path, format!("{}: {m}", label(role))).line(line).agent(id).field(role)
        };
        let rig = match cell("rig")? {
            Some(n) => rigs.intern(n).map_err(name_err("rig"))?,
            None => 0,
        };
        let cycle = match cell("cycle")? {
            Some(n) => Some(cycles.intern(n).map_err(name_err("cycle"))?),
            None => None,
        };
        let s = Sample { line, t, label: lab, p, heading, velocity, rig, cycle };
        push_forward(path, agents.entry(id).or_default(), s, id, o)?;
    }
    Ok(Tracks { agents, rigs, cycles, rows })
}

/// An id cell as an agent id: an integer from 0 to `u32::MAX`, written as
/// any number (`1.0000000e+00` is 1).
fn agent_id(path: &Path, cell: &str, columns: &ColumnIndex, line: usize) -> Result<u32> {
    cell.parse::<f64>()
        .ok()
        .filter(|v| v.fract() == 0.0 && (0.0..=f64::from(u32::MAX)).contains(v))
        .map(|v| v as u32)
        .ok_or_else(|| {
            Error::invalid(
                path,
                format!(
                    "{}: agent id `{}` is not an integer from 0 to {}",
                    columns.label("id"),
                    cell.escape_debug(),
                    u32::MAX
                ),
            )
            .line(line)
            .field("id")
        })
}

/// Appends agent `id`'s sample `s` to its track; each agent's rows must go
/// forward in time (two rows at one time are an error too).
fn push_forward(path: &Path, track: &mut Vec<Sample>, s: Sample, id: u32, o: &TabularOptions) -> Result<()> {
    let line = s.line;
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
    Ok(())
}

/// Bounds the output before any per-frame array is allocated.
fn check_output_size(path: &Path, agents: &BTreeMap<u32, Vec<Sample>>, fps: f64, max_gap: f64) -> Result<()> {
    let mut total = 0u64;
    for (id, track) in agents {
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
    Ok(())
}

/// Stage 3: one agent's samples resampled to the target rate, in runs of
/// consecutive frames split at gaps.
fn resample(track: &[Sample], fps: f64, max_gap: f64) -> Vec<Vec<Pose>> {
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
    runs
}

/// Stage 4: each pose's heading (radians about +Y; held where unknown) and
/// whether the agent is moving, over all runs in order.
fn headings(
    runs: &[Vec<Pose>],
    heading_from: HeadingFrom,
    window_half: usize,
    hold: f64,
    fps: f64,
) -> (Vec<Option<f64>>, Vec<bool>) {
    let mut headings: Vec<Option<f64>> = Vec::new();
    let mut moving: Vec<bool> = Vec::new();
    for run in runs {
        let n = run.len();
        let mut state = false;
        // Ground-plane travel direction over the window (length ~ speed),
        // kept only where the agent moves at full hold speed.
        let mut travel: Vec<Option<DVec3>> = Vec::with_capacity(n);
        let mut turns: Vec<bool> = Vec::with_capacity(n);
        for i in 0..n {
            let (j0, j1) = window(i, n, window_half);
            let span = (j1 - j0) as f64 / fps;
            let (speed, mut dir) = match heading_from {
                HeadingFrom::Velocity => {
                    let v: DVec3 = run[j0..=j1].iter().filter_map(|q| q.velocity).sum::<DVec3>() / (j1 - j0 + 1) as f64;
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
            turns.push(may_turn(speed, hold));
            travel.push((may_turn(speed, hold) && speed > 1e-9).then_some(dir));
        }
        for i in 0..n {
            let (j0, j1) = window(i, n, window_half);
            let h = match heading_from {
                // A heading column is held too while the agent stands: a
                // simulator's or tracker's orientation of a standing person
                // is noise, not a turn.
                HeadingFrom::Column if turns[i] => {
                    let v: DVec3 = run[j0..=j1].iter().filter_map(|q| q.heading.map(|h| h.normalize_or_zero())).sum();
                    (v.x.hypot(v.z) > 1e-9).then(|| v.x.atan2(v.z))
                }
                HeadingFrom::Column => None,
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
    let standing = match heading_from {
        HeadingFrom::Column => runs.iter().flatten().find_map(|q| q.heading.map(|h| h.x.atan2(h.z))),
        _ => None,
    };
    fill_held(&mut headings, standing);
    (headings, moving)
}

/// Held headings, for every import: the last known one, else the first one
/// ahead; an agent never fast enough to turn keeps `standing` (its first
/// heading as written, where the source has one), else 0 later.
pub(crate) fn fill_held(headings: &mut [Option<f64>], standing: Option<f64>) {
    if headings.iter().all(Option::is_none) {
        if let Some(h) = headings.first_mut() {
            *h = standing;
        }
    }
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
}

/// The hold rule, one definition for every import (tables, whatever the
/// heading comes from, and JuPedSim): an agent may turn only where its
/// ground speed over the heading window is at least `hold` m/s; below it
/// the heading is held, so a person standing still does not spin on
/// tracking noise or a simulator's jittering orientation. A `hold` of 0
/// never holds.
pub(crate) fn may_turn(speed: f64, hold: f64) -> bool {
    speed >= hold
}

/// The frames `(first, last)` of the heading window around frame `i` of a
/// run of `n`, `half` either side, clipped to the run.
pub(crate) fn window(i: usize, n: usize, half: usize) -> (usize, usize) {
    (i.saturating_sub(half), (i + half).min(n.saturating_sub(1)))
}

/// Frames either side of the heading window of `seconds` at `fps` (at least 1).
pub(crate) fn window_half(seconds: f64, fps: f64) -> usize {
    ((seconds * fps / 2.0).round() as usize).max(1)
}

/// Limits one agent's run of headings (radians, one per consecutive frame)
/// to turn at most `step` radians a frame, the shorter way round: a turn
/// faster than a person can make is spread over the frames that follow.
/// Per agent and in frame order, so no other agent changes the result.
/// Unknown headings are left for the caller's fill.
pub(crate) fn limit_turn(headings: &mut [Option<f64>], step: f64) {
    let mut prev: Option<f64> = None;
    for h in headings.iter_mut() {
        if let (Some(p), Some(v)) = (prev, h.as_mut()) {
            *v = turn_toward(p, *v, step);
        }
        if h.is_some() {
            prev = *h;
        }
    }
}

/// `from` turned toward `to` (radians) by at most `step`, the shorter way.
pub(crate) fn turn_toward(from: f64, to: f64, step: f64) -> f64 {
    let d = wrap(to - from);
    if d.abs() > step {
        wrap(from + d.clamp(-step, step))
    } else {
        to
    }
}

/// Stage 5: one agent's records, (cache frame, sample): the walk cycle frame
/// follows distance walked / the rig's stride; standing agents play the
/// idle cycle when one is named.
fn walk_cycles(
    id: u32,
    runs: &[Vec<Pose>],
    headings: &[Option<f64>],
    moving: &[bool],
    o: &TabularOptions,
    tracks: &Tracks,
) -> Vec<(i32, AgentSample)> {
    let idle = o.idle_cycle.as_ref().and_then(|c| tracks.cycles.ids.get(c).copied());
    // Golden-ratio spread: neighbouring ids step out of phase.
    let phase = (f64::from(id) * 0.618_033_988_749_895).fract();
    let mut out = Vec::new();
    let mut i = 0;
    for run in runs {
        let mut walked = 0.0;
        let mut prev: Option<DVec3> = None;
        for pose in run {
            if let Some(q) = prev {
                walked += (pose.p.x - q.x).hypot(pose.p.z - q.z);
            }
            prev = Some(pose.p);
            let rig_name = tracks.rigs.names.get(usize::from(pose.rig)).map(String::as_str).unwrap_or_default();
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
            let len = if Some(cycle) == idle && pose.cycle.is_none() { gait.idle_length } else { gait.cycle_length };
            let cf = cycle_frame as f32;
            out.push((
                pose.k,
                AgentSample {
                    id,
                    position: pose.p.as_vec3(),
                    heading: wrap(headings.get(i).copied().flatten().unwrap_or(0.0)) as f32,
                    rig: pose.rig,
                    cycle,
                    // Rounding to f32 can land exactly on the length; that is frame 0.
                    cycle_frame: if cf >= len { 0.0 } else { cf },
                    flags: 0,
                },
            ));
            i += 1;
        }
    }
    out
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

    fn sample(t: f64, x: f64) -> Sample {
        Sample { line: 0, t, label: t, p: DVec3::new(x, 0.0, 0.0), heading: None, velocity: None, rig: 0, cycle: None }
    }

    #[test]
    fn text_stage_blanks_comments_and_keeps_line_numbers() {
        let o = TabularOptions { delimiter: Delimiter::Whitespace, ..Default::default() };
        let t = Table::new("# c\n1  2\t3\n\n# d\n4 5 6\n", &o);
        assert_eq!(t.data, "\n1\t2\t3\n\n\n4\t5\t6");
        let lines: Vec<usize> =
            t.reader().records().map(|r| t.line_at(r.unwrap().position().unwrap().byte())).collect();
        assert_eq!(lines, [2, 5]);
    }

    #[test]
    fn columns_are_found_by_header_name_or_position() {
        let cols = Columns { id: Some(Column::Name("Agent".into())), x: pos(3), ..Default::default() };
        let header = Some(vec!["frame".to_string(), "agent".into(), "pos_x".into()]);
        let c = ColumnIndex::new(Path::new("t.csv"), &cols, header).unwrap();
        assert_eq!((c.index["id"], c.index["x"]), (1, 2));
        assert_eq!(c.label("id"), "column 2 (agent, id)");
        assert_eq!(c.label("x"), "column 3 (pos_x, x)");
        let missing = Columns { id: Some(Column::Name("who".into())), ..Default::default() };
        let e = ColumnIndex::new(Path::new("t.csv"), &missing, Some(vec!["a".into()])).err().unwrap().to_string();
        assert!(e.contains("no column `who` for id; the columns found are: a"), "{e}");
    }

    #[test]
    fn names_number_in_order_of_first_use() {
        let mut n = Names::of(["WalkA".to_string(), "WalkA".into(), "IdleA".into()]);
        assert_eq!(n.names, ["WalkA", "IdleA"]);
        assert_eq!((n.intern("RunA"), n.intern("WalkA")), (Ok(2), Ok(0)));
        assert!(n.intern("").is_err());
    }

    #[test]
    fn turn_limit_spreads_a_snap_the_shorter_way() {
        let step = 0.1;
        // An about-turn (0 -> 3.0 rad) and a turn across +-pi (3.0 -> -3.0: 0.28 rad the short way).
        let mut h = vec![Some(0.0), Some(3.0), Some(3.0), None, Some(3.0), Some(-3.0), Some(-3.0), Some(-3.0)];
        limit_turn(&mut h, step);
        let v: Vec<f64> = h.iter().flatten().copied().collect();
        assert!((v[0] - 0.0).abs() < 1e-12 && (v[1] - 0.1).abs() < 1e-12 && (v[2] - 0.2).abs() < 1e-12);
        assert_eq!(h[3], None, "unknown headings stay unknown");
        for w in v.windows(2) {
            assert!(wrap(w[1] - w[0]).abs() <= step + 1e-12, "{w:?}");
        }
        // Slow turns pass unchanged, including across +-pi.
        assert_eq!(turn_toward(3.1, -3.1, 0.1), -3.1);
        assert!((turn_toward(3.1, -3.0, 0.1) - wrap(3.2)).abs() < 1e-12);
        assert_eq!(turn_toward(1.0, 1.05, 0.1), 1.05);
    }

    #[test]
    fn resampling_splits_runs_at_gaps() {
        // 0..1 s walked, a 3 s gap, then 4..5 s: two runs at 2 fps, none across the gap.
        let track = [sample(0.0, 0.0), sample(1.0, 1.0), sample(4.0, 4.0), sample(5.0, 5.0)];
        let runs = resample(&track, 2.0, 1.0);
        let ks: Vec<Vec<i32>> = runs.iter().map(|r| r.iter().map(|p| p.k).collect()).collect();
        assert_eq!(ks, [vec![0, 1, 2], vec![8, 9, 10]]);
        assert!((runs[0][1].p.x - 0.5).abs() < 1e-12);
    }

    #[test]
    fn headings_are_held_while_standing() {
        // Walks +x for 1 s at 1 m/s, then stands: it keeps facing +x (90 degrees).
        let track = [sample(0.0, 0.0), sample(1.0, 1.0), sample(3.0, 1.0)];
        let runs = resample(&track, 4.0, 5.0);
        let (h, moving) = headings(&runs, HeadingFrom::Motion, 1, 0.25, 4.0);
        assert_eq!(h.len(), 13);
        assert!(h.iter().all(|h| (h.unwrap() - std::f64::consts::FRAC_PI_2).abs() < 1e-9), "{h:?}");
        assert!(moving[1] && !moving[12]);
    }

    #[test]
    fn standing_agents_play_the_idle_cycle() {
        let o = TabularOptions { idle_cycle: Some("IdleA".into()), ..Default::default() };
        let track = [sample(0.0, 0.0), sample(1.0, 1.0), sample(3.0, 1.0)];
        let runs = resample(&track, 4.0, 5.0);
        let (h, moving) = headings(&runs, HeadingFrom::Motion, 1, 0.25, 4.0);
        let tracks = Tracks {
            agents: BTreeMap::new(),
            rigs: Names::of([o.rig.clone()]),
            cycles: Names::of([o.cycle.clone(), "IdleA".into()]),
            rows: 3,
        };
        let out = walk_cycles(7, &runs, &h, &moving, &o, &tracks);
        assert_eq!(out.len(), 13);
        assert_eq!((out[1].1.cycle, out[12].1.cycle), (0, 1), "walks, then idles");
        assert!(out.iter().all(|(_, a)| a.cycle_frame >= 0.0 && a.cycle_frame < o.default_gait.cycle_length));
    }

    #[test]
    fn sniffs_petrack_header() {
        let (fps, units) =
            sniff_comments("# framerate: 16 fps\n# id frame x/cm y/cm z/cm\n1 0 1 2 3\n", Some(b'#'), false);
        assert_eq!((fps, units), (Some(16.0), Some(Units::Cm)));
    }
}
