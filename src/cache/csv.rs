//! CSV caches: one row per agent per frame, rigs and cycles by name.
//!
//! Dialect (docs/cache-format.md): UTF-8, comma-separated, written without
//! quoting (names may not hold commas or quotes; quoted fields are read, via
//! the `csv` crate), LF line endings written (CRLF read), the header
//! `frame,id,x,y,z,heading,rig,cycle,cycle_frame,flags` (read in any column
//! order), rows grouped
//! by frame in increasing order. Floats use Rust's shortest round-trip
//! form, so values survive exactly. `flags` is empty, `seated`, `hidden` or
//! `seated|hidden`. A frame with no agents is a row holding only the frame
//! number (`42,,,,,,,,,`). Rig and cycle tables are rebuilt in order of
//! first appearance, which is the order `.crowd` files store, so
//! binary -> CSV -> binary is byte-identical.

use std::collections::{HashMap, HashSet};
use std::io::Write;
use std::path::Path;

use glam::Vec3;

use super::{check_name, validate, validate_record, AgentSample, CrowdCache, FrameBlock, HIDDEN, SEATED};
use crate::error::{write_atomic, Error, IoContext, Result};

/// The header line.
pub(crate) const HEADER: &str = "frame,id,x,y,z,heading,rig,cycle,cycle_frame,flags";
const COLUMNS: [&str; 10] = ["frame", "id", "x", "y", "z", "heading", "rig", "cycle", "cycle_frame", "flags"];

/// Flags as written: names joined by `|`, in bit order.
pub(crate) fn flags_to_str(flags: u8) -> String {
    let mut names = Vec::new();
    if flags & SEATED != 0 {
        names.push("seated");
    }
    if flags & HIDDEN != 0 {
        names.push("hidden");
    }
    names.join("|")
}

fn parse_flags(s: &str) -> std::result::Result<u8, String> {
    let mut flags = 0;
    for name in s.split('|').map(str::trim).filter(|n| !n.is_empty()) {
        flags |= match name {
            "seated" => SEATED,
            "hidden" => HIDDEN,
            _ => return Err(format!("unknown flag `{name}` (expected seated, hidden, or both joined by `|`)")),
        };
    }
    Ok(flags)
}

/// Reads a CSV cache (gzip is recognised by its magic bytes).
pub(crate) fn read(path: &Path) -> Result<CrowdCache> {
    parse_str(path, &super::tabular::read_text(path)?)
}

/// Interns a rig or cycle name, in order of first appearance.
fn intern(names: &mut Vec<String>, lookup: &mut HashMap<String, u16>, name: &str) -> std::result::Result<u16, String> {
    if let Some(&i) = lookup.get(name) {
        return Ok(i);
    }
    check_name(name)?;
    let i = u16::try_from(names.len()).map_err(|_| "more than 65536 distinct names".to_string())?;
    names.push(name.to_string());
    lookup.insert(name.to_string(), i);
    Ok(i)
}

/// Parses CSV text; `path` names it in errors.
pub(crate) fn parse_str(path: &Path, text: &str) -> Result<CrowdCache> {
    // Spreadsheets add a BOM.
    let text = text.strip_prefix('\u{feff}').unwrap_or(text);
    // The csv crate splits fields, so quoted fields are fine; columns are
    // found by header name, so any order is.
    let mut reader =
        csv::ReaderBuilder::new().has_headers(false).flexible(true).trim(csv::Trim::All).from_reader(text.as_bytes());
    let starts: Vec<usize> = std::iter::once(0).chain(text.match_indices('\n').map(|(i, _)| i + 1)).collect();
    // A record's position is where reading began, before any blank lines it skipped.
    let line_at = |byte: u64| {
        let bytes = text.as_bytes();
        let mut i = usize::try_from(byte).unwrap_or(usize::MAX).min(bytes.len());
        while bytes.get(i).is_some_and(|c| *c == b'\n' || *c == b'\r') {
            i += 1;
        }
        starts.partition_point(|&s| s <= i)
    };
    let csv_err = |e: csv::Error| {
        let err = Error::invalid(path, format!("cannot read CSV: {e}"));
        match e.position() {
            Some(p) => err.line(line_at(p.byte())),
            None => err,
        }
    };
    let mut records = reader.records();
    let header = match records.next() {
        Some(h) => h.map_err(csv_err)?,
        None => return Err(Error::invalid(path, format!("empty file: expected the header `{HEADER}`")).line(1)),
    };
    let order = column_order(path, &header)?;

    let mut crowd = CrowdCache::default();
    let (mut rig_ids, mut cycle_ids) = (HashMap::new(), HashMap::new());
    let mut seen = HashSet::new(); // agent ids in the current frame
    for record in records {
        let record = record.map_err(csv_err)?;
        let n = record.position().map_or(0, |p| line_at(p.byte()));
        if record.iter().all(str::is_empty) && record.len() <= 1 {
            continue;
        }
        if record.len() != COLUMNS.len() {
            return Err(
                Error::invalid(path, format!("expected {} columns, found {}", COLUMNS.len(), record.len())).line(n)
            );
        }
        let cols: Vec<&str> = order.iter().map(|&i| record.get(i).unwrap_or_default()).collect();
        let col = |i: usize| cols.get(i).copied().unwrap_or_default();
        let field_err = |i: usize, msg: String| {
            let name = COLUMNS.get(i).copied().unwrap_or_default();
            let column = order.get(i).copied().unwrap_or(i) + 1;
            Error::invalid(path, format!("column {column} ({name}): {msg}")).line(n).field(name)
        };
        let num = |i: usize| -> Result<f32> {
            col(i).parse::<f32>().map_err(|_| field_err(i, format!("cannot read `{}` as a number", col(i))))
        };
        let frame: i32 =
            col(0).parse().map_err(|_| field_err(0, format!("cannot read `{}` as a frame number", col(0))))?;

        // Start a new block when the frame changes; frames must increase.
        match crowd.frames.last() {
            Some(b) if b.frame == frame => {}
            Some(b) if b.frame > frame => {
                return Err(Error::invalid(
                    path,
                    format!("frame {frame} follows frame {}; rows must be grouped by increasing frame", b.frame),
                )
                .line(n)
                .frame(frame.into()))
            }
            _ => {
                crowd.frames.push(FrameBlock { frame, agents: Vec::new() });
                seen.clear();
            }
        }
        // A row holding only the frame number marks a frame with no agents.
        if cols.iter().skip(1).all(|c| c.is_empty()) {
            continue;
        }

        let id: u32 = col(1).parse().map_err(|_| field_err(1, format!("cannot read `{}` as an agent id", col(1))))?;
        let with_agent = |e: Error| e.frame(frame.into()).agent(id);
        let rig = intern(&mut crowd.rigs, &mut rig_ids, col(6)).map_err(|m| with_agent(field_err(6, m)))?;
        let cycle = intern(&mut crowd.cycles, &mut cycle_ids, col(7)).map_err(|m| with_agent(field_err(7, m)))?;
        let a = AgentSample {
            id,
            position: Vec3::new(num(2).map_err(with_agent)?, num(3).map_err(with_agent)?, num(4).map_err(with_agent)?),
            heading: num(5).map_err(with_agent)?,
            rig,
            cycle,
            cycle_frame: num(8).map_err(with_agent)?,
            flags: parse_flags(col(9)).map_err(|m| with_agent(field_err(9, m)))?,
        };
        validate_record(path, frame, &a, crowd.rigs.len(), crowd.cycles.len()).map_err(|e| e.line(n))?;
        if !seen.insert(id) {
            return Err(Error::invalid(path, format!("agent {id} appears twice in frame {frame}"))
                .line(n)
                .frame(frame.into())
                .agent(id));
        }
        if let Some(b) = crowd.frames.last_mut() {
            b.agents.push(a);
        }
    }
    validate(path, &crowd)?;
    Ok(crowd)
}

/// The file column of each of [`COLUMNS`], from the header: each exactly
/// once, in any order.
fn column_order(path: &Path, header: &csv::StringRecord) -> Result<Vec<usize>> {
    let order: Option<Vec<usize>> = COLUMNS
        .iter()
        .map(|name| header.iter().position(|h| h == *name))
        .collect::<Option<Vec<_>>>()
        .filter(|o| header.len() == COLUMNS.len() && o.iter().collect::<HashSet<_>>().len() == COLUMNS.len());
    order.ok_or_else(|| {
        let found: Vec<&str> = header.iter().collect();
        Error::invalid(
            path,
            format!(
                "expected the header `{HEADER}` (in any order), found `{}`; for another layout give a preset or columns (docs/cache-format.md)",
                found.join(",").escape_debug()
            ),
        )
        .line(1)
    })
}

/// Writes `crowd` as CSV through [`write_atomic`], after [`validate`].
pub(crate) fn write(path: &Path, crowd: &CrowdCache) -> Result<()> {
    validate(path, crowd)?;
    let name = |names: &[String], i: u16| names.get(usize::from(i)).cloned().unwrap_or_default();
    write_atomic(path, |w| {
        writeln!(w, "{HEADER}").at(path)?;
        for b in &crowd.frames {
            if b.agents.is_empty() {
                writeln!(w, "{},,,,,,,,,", b.frame).at(path)?;
            }
            for a in &b.agents {
                // `{}` on f32 prints the shortest string that parses back to
                // the same bits, so CSV loses nothing.
                writeln!(
                    w,
                    "{},{},{},{},{},{},{},{},{},{}",
                    b.frame,
                    a.id,
                    a.position.x,
                    a.position.y,
                    a.position.z,
                    a.heading,
                    name(&crowd.rigs, a.rig),
                    name(&crowd.cycles, a.cycle),
                    a.cycle_frame,
                    flags_to_str(a.flags)
                )
                .at(path)?;
            }
        }
        Ok(())
    })
}
