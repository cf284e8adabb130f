//! USD crowds in (`.usd`, `.usda`, `.usdc`, `.usdz`), read through `openusd`
//! (docs/usd.md, "USD in").
//!
//! Two shapes are read, over every integer time code of the stage's
//! `startTimeCode`-`endTimeCode` (or of the authored samples when the stage
//! has no range):
//!
//! - a `PointInstancer` with `ids` (the agent ids, required), `positions` and
//!   `orientations` (or `orientationsf`), time-sampled;
//! - agent prims carrying `primvars:throng:agentId` with time-sampled xform
//!   ops (`transform`, `translate`, `rotateY`, `orient`, `scale`), as
//!   `throng export --format usd` writes them; an agent `invisible` at a
//!   frame is absent from it, and `primvars:throng:seated` sets the seated flag.
//!
//! Rig, cycle and cycle frame come from the primvars `throng:rig`,
//! `throng:cycle` and `throng:cycleFrame` (constant, or one per instance on
//! a PointInstancer); without them the [`ImportOptions`] rig and cycle, and
//! the frames since the agent's first frame.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::Path;

use glam::{Mat4, Quat, Vec3};
use openusd::sdf::{self, Value};
use openusd::usd::{PrimPredicate, Stage, TimeCode};

use super::{validate, AgentSample, CrowdCache, FrameBlock, ImportOptions, SEATED};
use crate::error::{Error, Result};

/// Most frames a USD crowd may span.
pub(crate) const MAX_FRAMES: i64 = 1_000_000;
/// Most agent samples (agents x frames) one USD crowd may hold.
pub(crate) const MAX_SAMPLES: usize = 50_000_000;

pub(super) struct Ctx<'a> {
    pub(super) path: &'a Path,
    pub(super) stage: Stage,
}

impl Ctx<'_> {
    pub(super) fn err(&self, prim: &str, msg: impl Into<String>) -> Error {
        Error::invalid(self.path, msg).field(prim.to_string())
    }

    pub(super) fn sdf_path(&self, p: &str) -> Result<sdf::Path> {
        sdf::Path::new(p).map_err(|e| self.err(p, format!("invalid USD path: {e}")))
    }

    /// The composed value of `prim.attr` at `t` (`None` when not authored).
    pub(super) fn value(&self, prim: &str, attr: &str, t: f64) -> Result<Option<Value>> {
        let p = self.sdf_path(&format!("{prim}.{attr}"))?;
        self.stage
            .attribute(p)
            .get_at::<Value>(TimeCode::new(t))
            .map_err(|e| self.err(&format!("{prim}.{attr}"), format!("cannot read at time {t}: {e}")))
    }

    /// Sample times of `prim.attr` (empty when it holds only a default).
    pub(super) fn times(&self, prim: &str, attr: &str) -> Result<Vec<f64>> {
        let p = self.sdf_path(&format!("{prim}.{attr}"))?;
        self.stage
            .attribute(p)
            .time_sample_times()
            .map_err(|e| self.err(&format!("{prim}.{attr}"), format!("cannot read time samples: {e}")))
    }

    fn has(&self, props: &BTreeSet<String>, name: &str) -> bool {
        props.contains(name)
    }

    /// Errors when the samples of `prim.attr` do not cover `frames`.
    pub(super) fn covers(&self, prim: &str, attr: &str, frames: (i64, i64)) -> Result<()> {
        self.covers_times(prim, attr, &self.times(prim, attr)?, frames)
    }

    /// Errors when `times`, the samples of `prim.attr`, do not cover `frames`.
    pub(super) fn covers_times(&self, prim: &str, attr: &str, times: &[f64], frames: (i64, i64)) -> Result<()> {
        let (Some(&first), Some(&last)) = (times.first(), times.last()) else { return Ok(()) };
        let missing = if first > frames.0 as f64 {
            Some(frames.0)
        } else if last < frames.1 as f64 {
            Some(frames.1)
        } else {
            None
        };
        if let Some(f) = missing {
            return Err(self
                .err(
                    &format!("{prim}.{attr}"),
                    format!(
                        "time samples of <{prim}.{attr}> cover {first}-{last}, not frame {f} \
                         (the crowd spans frames {}-{})",
                        frames.0, frames.1
                    ),
                )
                .frame(f));
        }
        Ok(())
    }
}

pub(super) fn props(stage: &Stage, path: &sdf::Path) -> BTreeSet<String> {
    stage.prim(path.clone()).property_names().unwrap_or_default().iter().map(|t| t.as_str().to_string()).collect()
}

pub(super) fn f32_of(v: &Value) -> Option<f32> {
    match v {
        Value::Float(x) => Some(*x),
        Value::Double(x) => Some(*x as f32),
        Value::Half(x) => Some(x.to_f32()),
        Value::Int(x) => Some(*x as f32),
        // usda time samples of a scalar are read type-blind: `1001: 0` is an Int64.
        Value::Int64(x) => Some(*x as f32),
        _ => None,
    }
}

pub(super) fn vec3_of(v: &Value) -> Option<Vec3> {
    match v {
        Value::Vec3f(p) => Some(Vec3::new(p.x, p.y, p.z)),
        Value::Vec3d(p) => Some(Vec3::new(p.x as f32, p.y as f32, p.z as f32)),
        Value::Vec3h(p) => Some(Vec3::new(p.x.to_f32(), p.y.to_f32(), p.z.to_f32())),
        _ => None,
    }
}

fn quat_of(v: &Value) -> Option<Quat> {
    match v {
        Value::Quatf(q) => Some(Quat::from_xyzw(q.x, q.y, q.z, q.w)),
        Value::Quatd(q) => Some(Quat::from_xyzw(q.x as f32, q.y as f32, q.z as f32, q.w as f32)),
        Value::Quath(q) => Some(Quat::from_xyzw(q.x.to_f32(), q.y.to_f32(), q.z.to_f32(), q.w.to_f32())),
        _ => None,
    }
}

pub(super) fn quats_of(v: &Value) -> Option<Vec<Quat>> {
    match v {
        Value::QuatfVec(q) => Some(q.iter().map(|q| Quat::from_xyzw(q.x, q.y, q.z, q.w)).collect()),
        Value::QuathVec(q) => {
            Some(q.iter().map(|q| Quat::from_xyzw(q.x.to_f32(), q.y.to_f32(), q.z.to_f32(), q.w.to_f32())).collect())
        }
        Value::QuatdVec(q) => {
            Some(q.iter().map(|q| Quat::from_xyzw(q.x as f32, q.y as f32, q.z as f32, q.w as f32)).collect())
        }
        _ => None,
    }
}

pub(super) fn vec3s_of(v: &Value) -> Option<Vec<Vec3>> {
    match v {
        Value::Vec3fVec(p) => Some(p.iter().map(|p| Vec3::new(p.x, p.y, p.z)).collect()),
        Value::Vec3dVec(p) => Some(p.iter().map(|p| Vec3::new(p.x as f32, p.y as f32, p.z as f32)).collect()),
        _ => None,
    }
}

fn ids_of(v: &Value) -> Option<Vec<i64>> {
    match v {
        Value::Int64Vec(x) => Some(x.clone()),
        Value::IntVec(x) => Some(x.iter().map(|&i| i64::from(i)).collect()),
        Value::UintVec(x) => Some(x.iter().map(|&i| i64::from(i)).collect()),
        _ => None,
    }
}

/// A string primvar: one value, or one per instance.
enum Names {
    One(String),
    Each(Vec<String>),
}

impl Names {
    /// How many names a per-instance primvar gives (`None`: one for all, or none).
    fn each_len(names: &Option<Names>) -> Option<usize> {
        match names {
            Some(Names::Each(v)) => Some(v.len()),
            _ => None,
        }
    }
}

fn names_of(v: &Value) -> Option<Names> {
    match v {
        Value::String(s) => Some(Names::One(s.clone())),
        Value::Token(t) => Some(Names::One(t.as_str().to_string())),
        Value::StringVec(s) => Some(Names::Each(s.clone())),
        Value::TokenVec(t) => Some(Names::Each(t.iter().map(|t| t.as_str().to_string()).collect())),
        _ => None,
    }
}

pub(super) fn heading_of(m: &Mat4) -> f32 {
    let f = m.transform_vector3(Vec3::Z);
    f.x.atan2(f.z)
}

/// Rig and cycle tables in first-use order.
#[derive(Default)]
pub(super) struct Names2 {
    rigs: Vec<String>,
    cycles: Vec<String>,
    rig_index: HashMap<String, u16>,
    cycle_index: HashMap<String, u16>,
}

impl Names2 {
    fn index(names: &mut Vec<String>, index: &mut HashMap<String, u16>, name: &str) -> Option<u16> {
        if let Some(&i) = index.get(name) {
            return Some(i);
        }
        let i = u16::try_from(names.len()).ok()?;
        names.push(name.to_string());
        index.insert(name.to_string(), i);
        Some(i)
    }
    pub(super) fn rig(&mut self, name: &str) -> Option<u16> {
        Self::index(&mut self.rigs, &mut self.rig_index, name)
    }
    pub(super) fn cycle(&mut self, name: &str) -> Option<u16> {
        Self::index(&mut self.cycles, &mut self.cycle_index, name)
    }
}

/// Reads a USD crowd into a [`CrowdCache`].
pub(crate) fn read(path: &Path, opts: &ImportOptions) -> Result<CrowdCache> {
    let ctx = open(path)?;
    let (instancers, agent_prims) = find_crowd(&ctx)?;
    let frames = frame_range(&ctx, &instancers, &agent_prims)?;
    let mut gather = Gather::new(path, frames);
    for pi in &instancers {
        let instancer = Instancer::check(&ctx, pi, frames)?;
        for f in frames.0..=frames.1 {
            instancer.read_frame(&ctx, f, opts, &mut gather)?;
        }
    }
    for ap in &agent_prims {
        read_agent_prim(&ctx, ap, frames, opts, &mut gather)?;
    }
    gather.finish()
}

/// Opens the stage at `path`, with its prim names and composition checked.
pub(super) fn open(path: &Path) -> Result<Ctx<'_>> {
    let text = path.to_str().ok_or_else(|| Error::invalid(path, "the USD file's path is not UTF-8"))?;
    if !path.exists() {
        return Err(Error::invalid(path, "no such USD file"));
    }
    let stage = Stage::open(text).map_err(|e| Error::invalid(path, format!("cannot open the USD stage: {e:#}")))?;
    let ctx = Ctx { path, stage };
    check_prim_names(&ctx)?;
    if let Some(e) = ctx.stage.composition_errors().first() {
        return Err(Error::invalid(path, format!("USD composition error: {e}")));
    }
    Ok(ctx)
}

/// The crowd's frames: the stage's time code range, else the span of the
/// authored samples; checked against [`MAX_FRAMES`] and the cache's i32.
pub(super) fn frame_range(ctx: &Ctx, instancers: &[String], agent_prims: &[String]) -> Result<(i64, i64)> {
    let frames: (i64, i64) = if ctx.stage.has_authored_time_code_range() {
        (ctx.stage.start_time_code().ceil() as i64, ctx.stage.end_time_code().floor() as i64)
    } else {
        let mut all = Vec::new();
        for (p, attr) in sampled_attrs(ctx, instancers, agent_prims)? {
            all.extend(ctx.times(&p, &attr)?);
        }
        let lo = all.iter().copied().fold(f64::INFINITY, f64::min);
        let hi = all.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        if lo.is_finite() {
            (lo.ceil() as i64, hi.floor() as i64)
        } else {
            (0, 0)
        }
    };
    let path = ctx.path;
    if frames.1 < frames.0 || frames.1 - frames.0 >= MAX_FRAMES {
        return Err(Error::invalid(
            path,
            format!("the crowd's frame range {}-{} is empty or longer than {MAX_FRAMES} frames", frames.0, frames.1),
        ));
    }
    if i32::try_from(frames.0).is_err() || i32::try_from(frames.1).is_err() {
        return Err(Error::invalid(path, format!("frames {}-{} do not fit a cache frame", frames.0, frames.1)));
    }
    Ok(frames)
}

/// The agents read so far: frame blocks, the rig and cycle tables, and each
/// agent's first frame (a cycle frame's default counts from it).
pub(super) struct Gather<'a> {
    path: &'a Path,
    pub(super) names: Names2,
    blocks: BTreeMap<i32, Vec<AgentSample>>,
    samples: usize,
    first_seen: HashMap<u32, i32>,
}

impl<'a> Gather<'a> {
    pub(super) fn new(path: &'a Path, frames: (i64, i64)) -> Self {
        Gather {
            path,
            names: Names2::default(),
            blocks: (frames.0..=frames.1).map(|f| (f as i32, Vec::new())).collect(),
            samples: 0,
            first_seen: HashMap::new(),
        }
    }

    /// The frame agent `id` was first seen at (`f` when this is it).
    fn first_seen(&mut self, id: u32, f: i32) -> i32 {
        *self.first_seen.entry(id).or_insert(f)
    }

    /// Adds one agent at frame `f`; `prim` names the source in errors.
    pub(super) fn push(&mut self, prim: &str, f: i32, a: AgentSample) -> Result<()> {
        self.samples += 1;
        if self.samples > MAX_SAMPLES {
            return Err(
                Error::invalid(self.path, format!("more than {MAX_SAMPLES} agent samples")).field(prim.to_string())
            );
        }
        self.blocks.entry(f).or_default().push(a);
        Ok(())
    }

    /// The crowd: frames holding agents, agents by id, validated.
    pub(super) fn finish(self) -> Result<CrowdCache> {
        let frames = self
            .blocks
            .into_iter()
            .filter(|(_, agents)| !agents.is_empty())
            .map(|(frame, mut agents)| {
                agents.sort_by_key(|a| a.id);
                FrameBlock { frame, agents }
            })
            .collect();
        let crowd = CrowdCache { rigs: self.names.rigs, cycles: self.names.cycles, frames };
        validate(self.path, &crowd)?;
        Ok(crowd)
    }
}

/// A PointInstancer whose attributes were found and whose samples cover
/// the crowd's frames.
struct Instancer<'a> {
    /// Its prim path.
    pi: &'a str,
    /// Its property names.
    props: BTreeSet<String>,
    /// Its prototypes (each an existing prim).
    protos: Vec<sdf::Path>,
    /// The orientation attribute it has, if any.
    orient: Option<&'static str>,
}

impl<'a> Instancer<'a> {
    /// Checks `pi`'s required attributes, prototypes and sample coverage.
    fn check(ctx: &Ctx, pi: &'a str, frames: (i64, i64)) -> Result<Self> {
        let p = props(&ctx.stage, &ctx.sdf_path(pi)?);
        if !ctx.has(&p, "ids") {
            return Err(ctx.err(pi, format!("PointInstancer <{pi}> has no `ids`: throng needs the agent ids")));
        }
        if !ctx.has(&p, "positions") {
            return Err(ctx.err(pi, format!("PointInstancer <{pi}> has no `positions`")));
        }
        // Prototypes must exist.
        let rel = ctx.stage.relationship(ctx.sdf_path(&format!("{pi}.prototypes"))?);
        let protos = rel.targets().unwrap_or_default();
        for t in &protos {
            if !is_prim_path(t.as_str()) {
                return Err(ctx.err(
                    &format!("{pi}.prototypes"),
                    format!("PointInstancer <{pi}>: prototype <{}> is not a prim path", t.as_str()),
                ));
            }
            if !ctx.stage.prim(t.clone()).is_valid().unwrap_or(false) {
                return Err(ctx.err(
                    &format!("{pi}.prototypes"),
                    format!("PointInstancer <{pi}>: prototype <{}> does not exist (a missing reference?)", t.as_str()),
                ));
            }
        }
        let orient = if ctx.has(&p, "orientations") {
            Some("orientations")
        } else if ctx.has(&p, "orientationsf") {
            Some("orientationsf")
        } else {
            None
        };
        for a in ["ids", "positions"].into_iter().chain(orient) {
            ctx.covers(pi, a, frames)?;
        }
        for (prim, op) in xform_chain_ops(ctx, pi)? {
            ctx.covers(&prim, &op, frames)?;
        }
        Ok(Instancer { pi, props: p, protos, orient })
    }

    /// Reads every instance at frame `f` into `gather`.
    fn read_frame(&self, ctx: &Ctx, f: i64, opts: &ImportOptions, gather: &mut Gather) -> Result<()> {
        let (pi, p, protos, orient) = (self.pi, &self.props, &self.protos, self.orient);
        let t = f as f64;
        let frame_err = |attr: &str, msg: String| ctx.err(&format!("{pi}.{attr}"), msg).frame(f);
        // Positions and orientations are in the instancer's space: its
        // own and its ancestors' xform ops place them in the world.
        let world_from_pi = world_matrix(ctx, pi, t)?;
        let ids = ctx
            .value(pi, "ids", t)?
            .and_then(|v| ids_of(&v))
            .ok_or_else(|| frame_err("ids", format!("<{pi}.ids> has no int64[] value at frame {f}")))?;
        let pos = ctx
            .value(pi, "positions", t)?
            .and_then(|v| vec3s_of(&v))
            .ok_or_else(|| frame_err("positions", format!("<{pi}.positions> has no point3f[] value at frame {f}")))?;
        let rot = match orient {
            Some(o) => ctx
                .value(pi, o, t)?
                .and_then(|v| quats_of(&v))
                .ok_or_else(|| frame_err(o, format!("<{pi}.{o}> has no quaternion array at frame {f}")))?,
            None => vec![Quat::IDENTITY; ids.len()],
        };
        if pos.len() != ids.len() || rot.len() != ids.len() {
            return Err(frame_err(
                "positions",
                format!(
                    "{} ids, {} positions and {} orientations at frame {f}; they must be equally long",
                    ids.len(),
                    pos.len(),
                    rot.len()
                ),
            ));
        }
        if ctx.has(p, "protoIndices") {
            if let Some(Value::IntVec(idx)) = ctx.value(pi, "protoIndices", t)? {
                // USD: protoIndices has one entry per instance.
                if idx.len() != ids.len() {
                    return Err(frame_err(
                        "protoIndices",
                        format!(
                            "{} protoIndices for {} ids at frame {f}; they must be equally long",
                            idx.len(),
                            ids.len()
                        ),
                    ));
                }
            }
        }
        if !protos.is_empty() && ctx.has(p, "protoIndices") {
            if let Some(Value::IntVec(idx)) = ctx.value(pi, "protoIndices", t)? {
                if let Some(bad) = idx.iter().find(|&&i| i < 0 || i as usize >= protos.len()) {
                    return Err(frame_err(
                        "protoIndices",
                        format!("protoIndex {bad} at frame {f}: there are {} prototypes", protos.len()),
                    ));
                }
            }
        }
        let rig = ctx.value(pi, "primvars:throng:rig", t)?.and_then(|v| names_of(&v));
        let cycle = ctx.value(pi, "primvars:throng:cycle", t)?.and_then(|v| names_of(&v));
        let cycle_frame = ctx.value(pi, "primvars:throng:cycleFrame", t)?;
        // A per-agent primvar names every agent: a shorter array would
        // give the rest the defaults without a word.
        let cycle_frames = match &cycle_frame {
            Some(Value::FloatVec(v)) => Some(v.len()),
            _ => None,
        };
        let lengths = [
            ("primvars:throng:rig", Names::each_len(&rig)),
            ("primvars:throng:cycle", Names::each_len(&cycle)),
            ("primvars:throng:cycleFrame", cycle_frames),
        ];
        for (attr, n) in lengths {
            if let Some(n) = n.filter(|&n| n != ids.len()) {
                return Err(frame_err(
                    attr,
                    format!("{n} values for {} ids at frame {f}; give one per agent", ids.len()),
                ));
            }
        }
        for (i, &id) in ids.iter().enumerate() {
            let id = u32::try_from(id).map_err(|_| frame_err("ids", format!("id {id} at frame {f} is not a u32")))?;
            let pick = |n: &Option<Names>, default: &str| match n {
                Some(Names::One(s)) => s.clone(),
                Some(Names::Each(v)) => v.get(i).cloned().unwrap_or_else(|| default.to_string()),
                None => default.to_string(),
            };
            let rig_name = pick(&rig, &opts.rig);
            let cycle_name = pick(&cycle, &opts.cycle);
            let first = gather.first_seen(id, f as i32);
            let cf = match &cycle_frame {
                Some(Value::FloatVec(v)) => v.get(i).copied(),
                Some(v) => f32_of(v),
                None => None,
            }
            .unwrap_or((f as i32 - first) as f32);
            let too_many = || frame_err("primvars:throng:rig", "more than 65536 rig or cycle names".into());
            let a = AgentSample {
                id,
                position: world_from_pi.transform_point3(pos[i]),
                heading: heading_of(&(world_from_pi * Mat4::from_quat(rot[i]))),
                rig: gather.names.rig(&rig_name).ok_or_else(too_many)?,
                cycle: gather.names.cycle(&cycle_name).ok_or_else(too_many)?,
                cycle_frame: cf,
                flags: 0,
            };
            gather.push(pi, f as i32, a)?;
        }
        Ok(())
    }
}

/// Reads one agent prim (`primvars:throng:agentId`, xform ops) at every
/// frame it is visible into `gather`.
fn read_agent_prim(ctx: &Ctx, ap: &str, frames: (i64, i64), opts: &ImportOptions, gather: &mut Gather) -> Result<()> {
    let id = match ctx.value(ap, "primvars:throng:agentId", 0.0)? {
        Some(Value::Int(i)) => u32::try_from(i).ok(),
        Some(Value::Int64(i)) => u32::try_from(i).ok(),
        Some(Value::Uint(i)) => Some(i),
        _ => None,
    }
    .ok_or_else(|| ctx.err(ap, format!("<{ap}> primvars:throng:agentId is not a non-negative int")))?;
    let ops = xform_ops(ctx, ap)?;
    if ops.is_empty() {
        return Err(ctx.err(ap, format!("agent prim <{ap}> has no xformOpOrder: throng needs its transform")));
    }
    for (prim, op) in xform_chain_ops(ctx, ap)? {
        ctx.covers(&prim, &op, frames)?;
    }
    let p = props(&ctx.stage, &ctx.sdf_path(ap)?);
    for f in frames.0..=frames.1 {
        let t = f as f64;
        if ctx.has(&p, "visibility") {
            if let Some(Value::Token(v)) = ctx.value(ap, "visibility", t)? {
                if v.as_str() == "invisible" {
                    continue;
                }
            }
        }
        let m = world_matrix(ctx, ap, t)?;
        let name_at = |attr: &str, default: &str| -> Result<String> {
            Ok(match ctx.value(ap, attr, t)?.and_then(|v| names_of(&v)) {
                Some(Names::One(s)) => s,
                _ => default.to_string(),
            })
        };
        let rig_name = name_at("primvars:throng:rig", &opts.rig)?;
        let cycle_name = name_at("primvars:throng:cycle", &opts.cycle)?;
        let first = gather.first_seen(id, f as i32);
        let cf = ctx
            .value(ap, "primvars:throng:cycleFrame", t)?
            .and_then(|v| f32_of(&v))
            .unwrap_or((f as i32 - first) as f32);
        let too_many = || ctx.err(ap, "more than 65536 rig or cycle names").frame(f);
        let seated = matches!(ctx.value(ap, "primvars:throng:seated", t)?, Some(Value::Bool(true)));
        let a = AgentSample {
            id,
            position: m.w_axis.truncate(),
            heading: heading_of(&m),
            rig: gather.names.rig(&rig_name).ok_or_else(too_many)?,
            cycle: gather.names.cycle(&cycle_name).ok_or_else(too_many)?,
            cycle_frame: cf,
            flags: if seated { SEATED } else { 0 },
        };
        gather.push(ap, f as i32, a)?;
    }
    Ok(())
}

/// Errors when a prim in the stage's layers has a name that is not a USD
/// identifier (`""`, `a}`): openusd takes such names as they come, and a
/// path like `/a}` is its own parent there, so composing or traversing it
/// never ends.
fn check_prim_names(ctx: &Ctx) -> Result<()> {
    for id in ctx.stage.layer_identifiers() {
        let Some(layer) = ctx.stage.layer(&id) else { continue };
        let data = layer.data();
        let mut specs = data.spec_paths();
        specs.sort_by(|a, b| a.as_str().cmp(b.as_str()));
        for spec in &specs {
            let Ok(Some(children)) = data.try_field(spec, sdf::ChildrenKey::PrimChildren.as_str()) else { continue };
            let Value::TokenVec(names) = children.as_ref() else { continue };
            if let Some(bad) = names.iter().find(|n| !sdf::Path::is_valid_identifier(n.as_str())) {
                let parent = spec.as_str().trim_end_matches('/');
                return Err(ctx.err(
                    &format!("{parent}/{}", bad.as_str()),
                    format!("prim name {:?} under <{}> is not a USD identifier", bad.as_str(), spec.as_str()),
                ));
            }
        }
    }
    Ok(())
}

/// Whether `p` is an absolute prim path of USD identifiers (`/World/body`),
/// as a PointInstancer's prototypes must be.
fn is_prim_path(p: &str) -> bool {
    p.strip_prefix('/').is_some_and(|rest| rest.split('/').all(sdf::Path::is_valid_identifier))
}

/// The crowd's prims: PointInstancers, and prims carrying
/// `primvars:throng:agentId`. Neither: an error naming the file.
fn find_crowd(ctx: &Ctx) -> Result<(Vec<String>, Vec<String>)> {
    let path = ctx.path;
    let mut instancers = Vec::new();
    let mut agent_prims = Vec::new();
    let mut paths = Vec::new();
    ctx.stage
        .traverse(PrimPredicate::DEFAULT, |p| paths.push(p.clone()))
        .map_err(|e| Error::invalid(path, format!("cannot traverse the USD stage: {e:#}")))?;
    for p in &paths {
        let prim = ctx.stage.prim(p.clone());
        let ty = prim.type_name().ok().flatten().map(|t| t.as_str().to_string()).unwrap_or_default();
        if ty == "PointInstancer" {
            instancers.push(p.as_str().to_string());
        } else if props(&ctx.stage, p).contains("primvars:throng:agentId") {
            agent_prims.push(p.as_str().to_string());
        }
    }
    if instancers.is_empty() && agent_prims.is_empty() {
        return Err(Error::invalid(
            path,
            format!(
                "no crowd in this USD file: no SkelRoot, no PointInstancer and no prim with \
                 primvars:throng:agentId among its {} prims",
                paths.len()
            ),
        ));
    }
    Ok((instancers, agent_prims))
}

/// Every (prim, attribute) whose time samples place the crowd: the
/// instancers' `ids`, `positions`, `orientations`, the agent prims' xform
/// ops, and the xform ops of every ancestor (and of the instancers themselves).
fn sampled_attrs(ctx: &Ctx, instancers: &[String], agent_prims: &[String]) -> Result<Vec<(String, String)>> {
    let mut out = Vec::new();
    for pi in instancers {
        let p = props(&ctx.stage, &ctx.sdf_path(pi)?);
        for a in ["ids", "positions", "orientations", "orientationsf"] {
            if p.contains(a) {
                out.push((pi.clone(), a.to_string()));
            }
        }
        out.extend(xform_chain_ops(ctx, pi)?);
    }
    for ap in agent_prims {
        out.extend(xform_chain_ops(ctx, ap)?);
    }
    out.sort();
    out.dedup();
    Ok(out)
}

/// Why a USD crowd holds no `cache_frame`, naming the prim: the first
/// attribute (of [`sampled_attrs`]) whose time samples do not reach it, or
/// the stage's time code range. `None` when the file does not open as a
/// crowd (its own error is reported elsewhere). For the shot's error on
/// frames outside the cache.
pub(crate) fn coverage(path: &Path, cache_frame: i32) -> Option<String> {
    let stage = Stage::open(path.to_str()?).ok()?;
    let ctx = Ctx { path, stage };
    let (instancers, agent_prims) = find_crowd(&ctx).ok()?;
    let f = f64::from(cache_frame);
    for (prim, attr) in sampled_attrs(&ctx, &instancers, &agent_prims).ok()? {
        let times = ctx.times(&prim, &attr).ok()?;
        if let (Some(&first), Some(&last)) = (times.first(), times.last()) {
            if f < first || f > last {
                return Some(format!("time samples of <{prim}.{attr}> cover {first}-{last}, not frame {cache_frame}"));
            }
        }
    }
    if ctx.stage.has_authored_time_code_range() {
        let (a, b) = (ctx.stage.start_time_code(), ctx.stage.end_time_code());
        let crowd = instancers.first().or(agent_prims.first())?;
        return Some(format!(
            "the stage's startTimeCode-endTimeCode {a}-{b} (crowd <{crowd}>) does not hold frame {cache_frame}"
        ));
    }
    None
}

/// The prim's `xformOpOrder`. Each entry must name an attribute (a USD
/// namespaced identifier, after any `!invert!`) or be `!resetXformStack!`:
/// openusd composes whatever path it is given, and some never end.
fn xform_ops(ctx: &Ctx, prim: &str) -> Result<Vec<String>> {
    let ops: Vec<String> = match ctx.value(prim, "xformOpOrder", 0.0)? {
        Some(Value::TokenVec(v)) => v.iter().map(|t| t.as_str().to_string()).collect(),
        _ => Vec::new(),
    };
    for op in &ops {
        let attr = op.strip_prefix("!invert!").unwrap_or(op);
        if op != "!resetXformStack!" && !sdf::Path::is_valid_namespace_identifier(attr) {
            return Err(ctx.err(
                &format!("{prim}.xformOpOrder"),
                format!("<{prim}.xformOpOrder> lists {op:?}, which is not an attribute name"),
            ));
        }
    }
    Ok(ops)
}

/// The prims whose ops make `prim`'s world matrix, `prim` first, up to the
/// root or to the first prim whose ops start with `!resetXformStack!`.
pub(super) fn xform_chain(ctx: &Ctx, prim: &str) -> Result<Vec<(String, Vec<String>)>> {
    let mut chain = Vec::new();
    let mut p = prim;
    loop {
        let ops = xform_ops(ctx, p)?;
        let reset = ops.iter().any(|o| o == "!resetXformStack!");
        chain.push((p.to_string(), ops));
        match p.rfind('/') {
            Some(i) if i > 0 && !reset => p = &p[..i],
            _ => break,
        }
    }
    Ok(chain)
}

/// (prim, attribute) of every xform op in `prim`'s chain ([`xform_chain`]).
pub(super) fn xform_chain_ops(ctx: &Ctx, prim: &str) -> Result<Vec<(String, String)>> {
    let mut out = Vec::new();
    for (p, ops) in xform_chain(ctx, prim)? {
        for op in ops {
            if op != "!resetXformStack!" {
                let attr = op.strip_prefix("!invert!").unwrap_or(&op).to_string();
                out.push((p.clone(), attr));
            }
        }
    }
    Ok(out)
}

/// A rotation about axis `X`, `Y` or `Z` by `deg` degrees.
fn axis_rotation(axis: char, deg: f32) -> Mat4 {
    let r = deg.to_radians();
    match axis {
        'X' => Mat4::from_rotation_x(r),
        'Y' => Mat4::from_rotation_y(r),
        _ => Mat4::from_rotation_z(r),
    }
}

/// The prim's local matrix at `t` from `ops` (column vectors: the first op
/// in `xformOpOrder` is the outermost).
fn local_matrix(ctx: &Ctx, prim: &str, ops: &[String], t: f64) -> Result<Mat4> {
    local_matrix_with(ctx, prim, ops, t, &mut |_, attr| ctx.value(prim, attr, t))
}

/// [`local_matrix`] with op `k`'s value (attribute `attr`) at `t` from `value`.
pub(super) fn local_matrix_with(
    ctx: &Ctx,
    prim: &str,
    ops: &[String],
    t: f64,
    value: &mut dyn FnMut(usize, &str) -> Result<Option<Value>>,
) -> Result<Mat4> {
    let mut m = Mat4::IDENTITY;
    for (k, op) in ops.iter().enumerate() {
        if op == "!resetXformStack!" {
            continue;
        }
        let (invert, attr) = match op.strip_prefix("!invert!") {
            Some(a) => (true, a),
            None => (false, op.as_str()),
        };
        let bad = || ctx.err(&format!("{prim}.{attr}"), format!("<{prim}.{attr}> has no usable value at time {t}"));
        let v = value(k, attr)?.ok_or_else(bad)?;
        let kind = attr.strip_prefix("xformOp:").unwrap_or(attr).split(':').next().unwrap_or("");
        let step = match kind {
            "transform" => match &v {
                // USD matrices are row-major for row vectors: the same 16 numbers
                // as a column-major matrix for column vectors.
                Value::Matrix4d(x) => Mat4::from_cols_array(&x.0.map(|e| e as f32)),
                _ => return Err(bad()),
            },
            "translate" => Mat4::from_translation(vec3_of(&v).ok_or_else(bad)?),
            "scale" => Mat4::from_scale(vec3_of(&v).ok_or_else(bad)?),
            "orient" => Mat4::from_quat(quat_of(&v).ok_or_else(bad)?.normalize()),
            "rotateX" | "rotateY" | "rotateZ" => {
                axis_rotation(kind.chars().last().unwrap_or('Z'), f32_of(&v).ok_or_else(bad)?)
            }
            // rotateXYZ: X first, then Y, then Z (so Z is outermost).
            "rotateXYZ" | "rotateXZY" | "rotateYXZ" | "rotateYZX" | "rotateZXY" | "rotateZYX" => {
                let d = vec3_of(&v).ok_or_else(bad)?;
                let angle = |c: char| match c {
                    'X' => d.x,
                    'Y' => d.y,
                    _ => d.z,
                };
                kind[6..].chars().fold(Mat4::IDENTITY, |acc, c| axis_rotation(c, angle(c)) * acc)
            }
            _ => {
                return Err(ctx.err(
                    &format!("{prim}.{attr}"),
                    format!(
                        "<{prim}>: xform op `{op}` is not read by throng (transform, translate, orient, \
                         rotateX/Y/Z, rotateXYZ and the other orders, scale are)"
                    ),
                ))
            }
        };
        let step = if invert {
            if step.determinant().abs() < 1e-12 {
                return Err(ctx.err(&format!("{prim}.{attr}"), format!("<{prim}.{op}> is not invertible at time {t}")));
            }
            step.inverse()
        } else {
            step
        };
        m *= step;
    }
    Ok(m)
}

/// World matrix at `t`: the prim's and its ancestors' ops, composed as USD
/// does (a `!resetXformStack!` drops the ancestors).
pub(super) fn world_matrix(ctx: &Ctx, prim: &str, t: f64) -> Result<Mat4> {
    let mut m = Mat4::IDENTITY;
    for (p, ops) in xform_chain(ctx, prim)? {
        m = local_matrix(ctx, &p, &ops, t)? * m;
    }
    if !m.is_finite() {
        return Err(ctx.err(prim, format!("<{prim}>'s world transform at time {t} is not finite")));
    }
    Ok(m)
}
