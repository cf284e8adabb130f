//! Which length unit a recording's numbers are in: the one rule every
//! import's unit doubt goes through (docs/cache-format.md, "Units").
//!
//! A file's header is believed when it names a unit ([`header_units`]:
//! PeTrack's `x/cm`, `x [cm]`, `x_cm`, `units: cm`). The crowd as read is
//! then judged from four kinds of evidence, each compared with what people
//! do: the median walking speed (a queue shuffles at 0.1 m/s, a walk is
//! 1.3 m/s), the median distance to the nearest neighbour (0.4-1.5 m in a
//! crowd), its closest 5 % (bodies: people touch at about 0.3-0.5 m) and
//! the median path length of an agent. Each candidate unit (the numbers as
//! read, or in cm, mm, ft, in read as metres, or metres read as one of
//! those) is scored by how far, in decades, each figure would fall from a
//! person's; the likeliest is the lowest score. Speed alone cannot tell a
//! slow queue in metres from a walk in feet; spacing can, so no single
//! figure decides. Only a strong case is a warning ([`STRONG`]): the
//! figures as read must be far from people's and the likeliest unit near.

use std::collections::HashMap;

use serde::Serialize;

use super::tabular_options::Units;
use super::FrameBlock;

/// Narrowest plausible spread of [`MIN_AGENTS_FOR_SPREAD`] or more agents, metres.
pub(crate) const MIN_PLAUSIBLE_SPREAD: f32 = 0.5;
/// Agents in a frame needed before its spacing is evidence.
pub(crate) const MIN_AGENTS_FOR_SPREAD: usize = 10;
/// Widest plausible crowd, metres: wider looks like centimetres (or feet)
/// read as metres.
pub(crate) const MAX_PLAUSIBLE_WIDTH: f32 = 2000.0;
/// Closest two people stand, centre to centre, metres.
pub(crate) const MIN_SPACING: f32 = 0.2;
/// Frames the spacing check samples, evenly spread (bounds its cost).
const SPACING_FRAMES: usize = 32;
/// Most agents of one sampled frame whose nearest neighbour is measured.
const SPACING_AGENTS: usize = 4000;
/// Most speed samples kept for the median.
const MAX_SPEED_SAMPLES: usize = 4_000_000;
/// Fewest samples of a kind before it counts as evidence.
const MIN_SAMPLES: usize = 20;
/// Score (natural log of the likelihood ratio) by which the figures as read
/// must be worse than the likeliest unit's before it is a warning.
pub(crate) const STRONG: f64 = 4.0;
/// Score by which a unit must beat the figures as read to be named the
/// likeliest (below it, speed alone, say, the numbers are taken as read).
const LIKELY: f64 = 1.0;

/// A person's figures: (what, centre, spread in decades). The centre is
/// where a crowd's figure most often lies; a figure a spread away costs
/// half a point, two spreads away two points.
const SPEED: (f64, f64) = (0.7, 0.45);
const NEAREST: (f64, f64) = (0.8, 0.45);
const BODY: (f64, f64) = (0.45, 0.2);
const PATH: (f64, f64) = (15.0, 1.0);

/// What a unit judgement found.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct UnitJudgement {
    /// The likeliest unit: `as read` when the numbers look like metres as
    /// read, else `cm`, `mm`, `ft` or `in` (the numbers are in that unit,
    /// read as metres) or `m read as cm` (and so on: metres read as a
    /// smaller unit).
    pub likeliest: String,
    /// Metres per metre as read, were the likeliest unit right.
    pub scale: f64,
    /// The figures as read that decided it.
    pub evidence: String,
    /// What to set or check were it right (empty when `as read`).
    pub advice: String,
    /// Whether the case is strong enough to warn ([`STRONG`]).
    pub strong: bool,
}

/// A candidate: name, metres per metre as read, and the advice to give.
fn candidates() -> Vec<(String, f64, String)> {
    let mut out = vec![("as read".to_string(), 1.0, String::new())];
    for u in [Units::Cm, Units::Mm, Units::Ft, Units::In] {
        let (name, m) = (u.name(), u.metres());
        out.push((name.to_string(), m, format!("set units = \"{name}\"")));
        out.push((format!("m read as {name}"), 1.0 / m, format!("check units: metres read as {name}?")));
    }
    out
}

/// Speeds, spacing and paths of people, gathered frame by frame for [`Plausible::judge`].
pub(crate) struct Plausible {
    /// Frames per second a speed counts consecutive frames at.
    fps: f32,
    last: HashMap<u32, (i32, glam::Vec3)>,
    paths: HashMap<u32, f32>,
    speeds: Vec<f32>,
    nearest: Vec<f32>,
}

/// The nearest other agent's ground distance for each point (0 apart not counted).
fn nearest_distances(points: &mut [glam::Vec2], out: &mut Vec<f32>) {
    points.sort_by(|a, b| a.x.total_cmp(&b.x));
    for (i, p) in points.iter().enumerate() {
        let mut best = f32::INFINITY;
        for q in points[i + 1..].iter() {
            if q.x - p.x >= best {
                break;
            }
            best = best.min(nonzero(p.distance(*q)));
        }
        for q in points[..i].iter().rev() {
            if p.x - q.x >= best {
                break;
            }
            best = best.min(nonzero(p.distance(*q)));
        }
        if best.is_finite() {
            out.push(best);
        }
    }
}

fn nonzero(d: f32) -> f32 {
    if d > 0.0 {
        d
    } else {
        f32::INFINITY
    }
}

/// The `q` quantile (0-1) of `v`, reordering it.
fn quantile(v: &mut [f32], q: f64) -> f64 {
    let i = ((v.len() - 1) as f64 * q).round() as usize;
    f64::from(*v.select_nth_unstable_by(i, f32::total_cmp).1)
}

/// Cost of a figure `x` (metres or m/s as read, times `scale`) against a person's.
fn cost(x: f64, scale: f64, (centre, spread): (f64, f64)) -> f64 {
    let z = (x * scale / centre).log10() / spread;
    0.5 * z * z
}

impl Plausible {
    /// Nothing gathered yet; speeds count consecutive frames at `fps`.
    pub(crate) fn new(fps: f32) -> Plausible {
        Plausible { fps, last: HashMap::new(), paths: HashMap::new(), speeds: Vec::new(), nearest: Vec::new() }
    }

    /// Adds one frame; `sample` says whether its spacing is measured.
    /// Seated and hidden agents do not count.
    pub(crate) fn add(&mut self, block: &FrameBlock, sample: bool) {
        for a in block.agents.iter().filter(|a| !a.seated() && !a.hidden()) {
            if let Some((f, p)) = self.last.insert(a.id, (block.frame, a.position)) {
                let d = (a.position - p).with_y(0.0).length();
                if f + 1 == block.frame && d.is_finite() {
                    *self.paths.entry(a.id).or_default() += d;
                    if d > 1e-6 && self.speeds.len() < MAX_SPEED_SAMPLES {
                        self.speeds.push(d * self.fps);
                    }
                }
            }
        }
        if sample && block.agents.len() >= MIN_AGENTS_FOR_SPREAD {
            let step = block.agents.len().div_ceil(SPACING_AGENTS);
            let mut points: Vec<glam::Vec2> =
                block.agents.iter().step_by(step).map(|a| glam::Vec2::new(a.position.x, a.position.z)).collect();
            nearest_distances(&mut points, &mut self.nearest);
        }
    }

    /// Which frames of `frames` the spacing check samples.
    pub(crate) fn sampled(frames: usize, i: usize) -> bool {
        frames <= SPACING_FRAMES || i.is_multiple_of(frames.div_ceil(SPACING_FRAMES))
    }

    /// The figures as read: (what, value, unit, a person's figure), each
    /// with enough samples.
    fn figures(&mut self) -> Vec<(&'static str, f64, (f64, f64))> {
        let mut out = Vec::new();
        if self.speeds.len() >= MIN_SAMPLES {
            out.push(("median speed", quantile(&mut self.speeds, 0.5), SPEED));
        }
        if self.nearest.len() >= MIN_SAMPLES {
            out.push(("median nearest neighbour", quantile(&mut self.nearest, 0.5), NEAREST));
            out.push(("closest 5 % of neighbours", quantile(&mut self.nearest, 0.05), BODY));
        }
        let mut paths: Vec<f32> = self.paths.values().copied().filter(|p| *p > 0.0).collect();
        if paths.len() >= 3 {
            out.push(("median path", quantile(&mut paths, 0.5), PATH));
        }
        out
    }

    /// The likeliest unit, `None` without evidence (too few moving or crowded agents).
    pub(crate) fn judge(&mut self) -> Option<UnitJudgement> {
        let figures = self.figures();
        if figures.is_empty() {
            return None;
        }
        let score = |scale: f64| figures.iter().map(|&(_, x, person)| cost(x, scale, person)).sum::<f64>();
        let mut ranked: Vec<(String, f64, String, f64)> =
            candidates().into_iter().map(|(n, scale, advice)| (n, scale, advice, score(scale))).collect();
        let as_read = ranked[0].3;
        ranked.sort_by(|a, b| a.3.total_cmp(&b.3));
        let (mut name, mut scale, mut advice, mut best) = ranked[0].clone();
        if as_read - best < LIKELY {
            (name, scale, advice, best) = ("as read".to_string(), 1.0, String::new(), as_read);
        }
        let evidence = figures
            .iter()
            .map(|&(what, x, _)| {
                let per = if what.contains("speed") { " m/s" } else { " m" };
                match scale == 1.0 {
                    true => format!("{what} {x:.3}{per}"),
                    false => format!("{what} {x:.3}{per} (as {name}: {:.3}{per})", x * scale),
                }
            })
            .collect::<Vec<_>>()
            .join(", ");
        let close = ranked.iter().find(|r| r.0 != name && r.3 - best < LIKELY && r.0 != "as read").map(|r| r.0.clone());
        let likeliest = match close {
            Some(c) if name != "as read" => format!("{name} (or {c})"),
            _ => name.clone(),
        };
        Some(UnitJudgement {
            likeliest,
            scale,
            evidence,
            advice,
            strong: name != "as read" && as_read - best >= STRONG,
        })
    }

    /// Warnings: the judgement when strong (naming the likeliest unit and
    /// its evidence), else the hard limits no unit explains (people closer
    /// than [`MIN_SPACING`]).
    pub(crate) fn warnings(&mut self) -> (Option<UnitJudgement>, Vec<String>) {
        let judged = self.judge();
        let mut out = Vec::new();
        if let Some(j) = judged.as_ref().filter(|j| j.strong) {
            out.push(format!(
                "the units look wrong: the likeliest unit is {} ({}); {}",
                j.likeliest, j.evidence, j.advice
            ));
        } else {
            let crowded = self.nearest.iter().filter(|d| **d < MIN_SPACING).count();
            if !self.nearest.is_empty() && crowded * 10 > self.nearest.len() {
                out.push(format!(
                    "{crowded} of {} sampled agents stand closer than {MIN_SPACING} m to another: closer than people \
                     stand; is the data in a smaller unit than it is read in (metres read as centimetres?)",
                    self.nearest.len()
                ));
            }
        }
        (judged, out)
    }
}

/// Bounds that no unit makes a crowd's: wider than [`MAX_PLAUSIBLE_WIDTH`],
/// or many agents packed in less than [`MIN_PLAUSIBLE_SPREAD`].
pub(crate) fn bounds_warning(b: &super::Bounds, agents: usize) -> Option<String> {
    let (w, d) = (b.max[0] - b.min[0], b.max[2] - b.min[2]);
    let wide = w.max(d);
    let at = format!("x {:.1}..{:.1}, z {:.1}..{:.1}", b.min[0], b.max[0], b.min[2], b.max[2]);
    if !wide.is_finite() || wide > MAX_PLAUSIBLE_WIDTH {
        return Some(format!(
            "the crowd is {wide:.0} m wide ({at}): wider than {:.0} km, so the units look wrong \
             (centimetres read as metres? set the cache's units, e.g. units = \"cm\")",
            MAX_PLAUSIBLE_WIDTH / 1000.0
        ));
    }
    if agents >= MIN_AGENTS_FOR_SPREAD && wide < MIN_PLAUSIBLE_SPREAD {
        return Some(format!(
            "{agents} agents stand within {wide:.3} m ({at}): the units look wrong (metres read as millimetres?)"
        ));
    }
    None
}

/// The unit a file's own header names: in comment lines (`comment`) or, with
/// `header`, the first other line (the column names). Read: `x/cm` (PeTrack),
/// `x [cm]`, `x (cm)`, `x_cm`, `pos_x_mm`, `unit: cm`, `units = cm`.
pub(crate) fn header_units(text: &str, comment: Option<u8>, header: bool) -> Option<Units> {
    let mut seen_header = !header;
    for line in text.lines().take(200).map(str::trim_start) {
        let body = match comment.and_then(|c| line.strip_prefix(c as char)) {
            Some(rest) => rest,
            None if line.is_empty() => continue,
            None if !seen_header => {
                seen_header = true;
                line
            }
            None => break,
        };
        if let Some(u) = line_units(&body.to_ascii_lowercase()) {
            return Some(u);
        }
    }
    None
}

/// The unit one header line names, if any.
fn line_units(line: &str) -> Option<Units> {
    let unit = |s: &str| s.trim().parse::<Units>().ok();
    // `unit: cm`, `units = cm`, `length unit: cm`.
    if let Some(i) = line.find("unit") {
        let rest = line[i + 4..].trim_start_matches('s').trim_start();
        if let Some(v) = rest.strip_prefix([':', '=']) {
            if let Some(u) = v.split(|c: char| !c.is_ascii_alphabetic()).find(|w| !w.is_empty()).and_then(unit) {
                return Some(u);
            }
        }
    }
    // `x [cm]` or `x (cm)`: a bracketed unit anywhere.
    for (open, close) in [('[', ']'), ('(', ')')] {
        let mut rest = line;
        while let Some(i) = rest.find(open) {
            let after = &rest[i + 1..];
            let Some(j) = after.find(close) else { break };
            if let Some(u) = unit(&after[..j]) {
                return Some(u);
            }
            rest = &after[j..];
        }
    }
    // `x/cm` (PeTrack), `x_cm`, `pos_x_mm`: a coordinate's name and its unit.
    line.split(|c: char| c.is_whitespace() || matches!(c, ',' | ';' | '\t' | '"' | '\''))
        .filter_map(|w| w.rsplit_once(['/', '_']))
        .filter(|(name, _)| name.ends_with(['x', 'y']))
        .find_map(|(_, u)| unit(u))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn headers_name_their_units() {
        let cases = [
            ("# framerate: 16 fps\n# id frame x/cm y/cm z/cm\n1 0 1 2 3\n", Some(b'#'), false, Some(Units::Cm)),
            ("id,frame,x_mm,y_mm\n1,0,1,2\n", None, true, Some(Units::Mm)),
            ("% units: ft\n1 0 1 2\n", Some(b'%'), false, Some(Units::Ft)),
            ("frame id x [m] y [m]\n", None, true, Some(Units::M)),
            ("id frame time(s) x(in) y(in)\n", None, true, Some(Units::In)),
            ("id,frame,x,y\n1,0,1,2\n", None, true, None),
            // A data line is not a header: `1/cm` is never read.
            ("# id frame x y\n1 0 1/cm 2\n", Some(b'#'), false, None),
        ];
        for (text, comment, header, want) in cases {
            assert_eq!(header_units(text, comment, header), want, "{text}");
        }
    }

    #[test]
    fn nearest_neighbours_of_a_row() {
        let mut pts = vec![glam::Vec2::new(0.0, 0.0), glam::Vec2::new(3.0, 0.0), glam::Vec2::new(1.0, 0.0)];
        let mut out = Vec::new();
        nearest_distances(&mut pts, &mut out);
        assert_eq!(out, [1.0, 1.0, 2.0]);
    }
}
