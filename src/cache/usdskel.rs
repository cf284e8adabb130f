//! UsdSkel crowds in (docs/usd.md, "UsdSkel crowds"): every `SkelRoot` is
//! an agent, as Houdini's SOP Crowd Import, Golaem's "USD Skeleton" bake and
//! Atoms write them. This file reads the stage: the agents (id, place and
//! heading per frame, the animation each plays) into a [`CrowdCache`], and
//! the character they share (skeleton, skinned meshes, materials, every
//! distinct animation) into a [`SkelCharacter`] that casting poses as it
//! poses a glTF character (`casting::usdskel_rig`).
//!
//! An agent's cycle is its animation: agents whose SkelAnimations hold the
//! same samples play one cycle (named by the first such prim), so they share
//! every pose; its cycle frame is the frame since the animation's first
//! sample. Its id: `primvars:throng:agentId` on the SkelRoot, else a hash of
//! the SkelRoot's prim path (the same for every re-export of the same prim
//! paths), the next free id on a clash, in prim path order.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::Path;

use glam::{Mat4, Quat, Vec3};
use openusd::sdf::Value;
use openusd::usd::PrimPredicate;

use super::usd::{self, heading_of, props, quats_of, vec3s_of, world_matrix, xform_chain_ops, Ctx, Gather};
use super::usdskel_mesh::{SkelMaterial, SkelMesh};
use super::usdskel_track::{Track, WorldTrack};
use super::{CrowdCache, ImportOptions};
use crate::error::{Error, Result};
use crate::fingerprint::Fingerprinter;

/// Most agents (SkelRoots) one crowd may hold.
pub(crate) const MAX_AGENTS: usize = 1_000_000;
/// Most joints a skeleton may have (joint indices are 16-bit downstream).
pub(crate) const MAX_JOINTS: usize = 4096;
/// Cycle name of agents bound to no animation: they hold their rest pose.
pub(crate) const REST_CYCLE: &str = "rest";

/// One SkelRoot: its prim, id, and the prims it binds.
#[derive(Clone, Debug)]
pub(crate) struct SkelAgent {
    /// The SkelRoot's prim path.
    pub(crate) prim: String,
    /// Its agent id.
    pub(crate) id: u32,
    /// The Skeleton prim under it.
    pub(crate) skeleton: String,
    /// The SkelAnimation its skeleton is bound to (`skel:animationSource`).
    pub(crate) animation: Option<String>,
    /// Skinned meshes under it (prims with `primvars:skel:jointIndices`).
    pub(crate) meshes: Vec<String>,
    /// Its character: agents of one prototype, or of the same skeleton and
    /// meshes, share one ([`character_key`]); numbered by first agent.
    pub(crate) character: usize,
}

/// A skeleton: joints (paths, parents before children), local rest and
/// skeleton-space bind transforms, as `Mat4` for column vectors.
#[derive(Clone, Debug)]
pub(crate) struct SkelSkeleton {
    /// The Skeleton prim.
    pub(crate) prim: String,
    /// Joint paths (`Hips/Spine`).
    pub(crate) joints: Vec<String>,
    /// Parent joint of each joint (`None` at a root).
    pub(crate) parents: Vec<Option<usize>>,
    /// `restTransforms`: each joint relative to its parent.
    pub(crate) rest: Vec<Mat4>,
    /// `bindTransforms`: each joint in skeleton space at bind time.
    pub(crate) bind: Vec<Mat4>,
    /// The Skeleton prim's transform relative to its SkelRoot.
    pub(crate) root_from_skel: Mat4,
}

/// One distinct animation: joint-local translations, rotations and scales
/// of the joints it names, at each of its time codes.
#[derive(Clone, Debug)]
pub(crate) struct SkelAnim {
    /// The cycle name: the first SkelAnimation prim holding these samples.
    pub(crate) name: String,
    /// Skeleton joint of each animated joint.
    pub(crate) joints: Vec<usize>,
    /// Time codes, increasing.
    pub(crate) times: Vec<f64>,
    /// Per time code, per animated joint: (translation, rotation, scale).
    pub(crate) poses: Vec<Vec<(Vec3, Quat, Vec3)>>,
}

/// What a UsdSkel crowd's agents are made of: one skeleton, its skinned
/// meshes and materials, and every distinct animation.
#[derive(Clone, Debug)]
pub(crate) struct SkelCharacter {
    /// The skeleton (every agent's has the same joints).
    pub(crate) skeleton: SkelSkeleton,
    /// The first agent's skinned meshes (instanced agents share them).
    pub(crate) meshes: Vec<SkelMesh>,
    /// Their materials.
    pub(crate) materials: Vec<SkelMaterial>,
    /// Distinct animations in first-use order.
    pub(crate) animations: Vec<SkelAnim>,
    /// What reading noticed but accepted (weights renormalised, influences dropped).
    pub(crate) warnings: Vec<String>,
    /// The uniform scale of its first agent's world transform at the
    /// crowd's first frame (an ancestor's unit scale): the rig's joints
    /// are scaled by it ([`upright_scale`]).
    pub(crate) scale: f32,
}

/// How far an agent's world transform may part from an upright, uniformly
/// scaled one (each entry of its rotation-and-scale part over the scale).
const UPRIGHT_TOLERANCE: f32 = 1e-3;
/// Relative difference within which an agent's scale is its character's.
const SCALE_TOLERANCE: f32 = 1e-4;

/// The uniform scale of world transform `m` when it is upright (a turn
/// about +Y, a uniform positive scale, a translation); else what it does
/// besides, for the error: its tilt from upright and its axes' scales.
fn upright_scale(m: &Mat4) -> std::result::Result<f32, String> {
    let local = glam::Mat3::from_rotation_y(-heading_of(m)) * glam::Mat3::from_mat4(*m);
    let axes = [local.x_axis, local.y_axis, local.z_axis].map(Vec3::length);
    let s = (axes[0] + axes[1] + axes[2]) / 3.0;
    let off = (local * (1.0 / s) - glam::Mat3::IDENTITY).to_cols_array().iter().fold(0.0f32, |a, e| a.max(e.abs()));
    if s.is_finite() && s > 0.0 && off <= UPRIGHT_TOLERANCE {
        return Ok(s);
    }
    let up = local.y_axis.normalize_or_zero();
    let tilt = up.dot(Vec3::Y).clamp(-1.0, 1.0).acos().to_degrees();
    Err(format!("tilts the agent {tilt:.2} degrees from upright and scales its axes by {axes:?}"))
}

/// Whether the stage holds SkelRoots (then it is read as a UsdSkel crowd).
pub(crate) fn has_skel_roots(path: &Path) -> Result<bool> {
    let ctx = usd::open(path)?;
    Ok(StagePrims::read(&ctx)?.prims.iter().any(|(_, t)| t == "SkelRoot"))
}

/// Each agent's (id, SkelRoot prim, Skeleton prim, bound animation), for botinfo.
pub(crate) fn agent_prims(path: &Path) -> Result<Vec<SkelAgent>> {
    agents(&usd::open(path)?)
}

/// Every composed prim path in traversal order; inside instances (their
/// prototypes' prims as instance proxies) only when `proxies`.
fn all_prims(ctx: &Ctx, proxies: bool) -> Result<Vec<String>> {
    let mut paths = Vec::new();
    ctx.stage
        .traverse(PrimPredicate::DEFAULT.with_instance_proxies(proxies), |p| paths.push(p.as_str().to_string()))
        .map_err(|e| Error::invalid(ctx.path, format!("cannot traverse the USD stage: {e:#}")))?;
    Ok(paths)
}

fn type_of(ctx: &Ctx, prim: &str) -> String {
    let Ok(p) = ctx.sdf_path(prim) else { return String::new() };
    ctx.stage.prim(p).type_name().ok().flatten().map(|t| t.as_str().to_string()).unwrap_or_default()
}

/// Every composed prim with its type name, sorted by path: the prims under
/// one prim are then one run (`descendants`).
fn typed_prims(ctx: &Ctx, proxies: bool) -> Result<Vec<(String, String)>> {
    let mut prims: Vec<(String, String)> =
        all_prims(ctx, proxies)?.into_iter().map(|p| (type_of(ctx, &p), p)).map(|(t, p)| (p, t)).collect();
    prims.sort();
    Ok(prims)
}

/// The prims under `root` (not itself) in `prims` sorted by path.
fn descendants<'a>(prims: &'a [(String, String)], root: &str) -> &'a [(String, String)] {
    let prefix = format!("{root}/");
    let start = prims.partition_point(|(p, _)| p.as_str() < prefix.as_str());
    let len = prims[start..].iter().take_while(|(p, _)| p.starts_with(&prefix)).count();
    &prims[start..start + len]
}

/// The stage's prims as agents are found among them. Listing every prim of
/// every instance (instance proxies) costs a traversal of each agent's
/// prototype per agent: when every instance is a SkelRoot (instanced agents,
/// as Houdini writes them), each prototype's prims are listed once and each
/// instance's are its prototype's under its own path.
struct StagePrims {
    /// (path, type name), sorted by path.
    prims: Vec<(String, String)>,
    /// Instance SkelRoot -> its prototype.
    prototype_of: HashMap<String, String>,
    /// Prototype -> its prims (path under the prototype, type name).
    prototypes: HashMap<String, Vec<(String, String)>>,
}

impl StagePrims {
    fn read(ctx: &Ctx) -> Result<StagePrims> {
        let prims = typed_prims(ctx, false)?;
        let mut prototype_of = HashMap::new();
        let mut prototypes = HashMap::new();
        for (p, t) in &prims {
            let prim = ctx.stage.prim(ctx.sdf_path(p)?);
            if !prim.is_instance().unwrap_or(false) {
                continue;
            }
            let proto = prim.prototype().ok().flatten();
            let (Some(proto), "SkelRoot") = (proto, t.as_str()) else {
                // An instance that is no agent may hold agents: list every prim.
                let prims = typed_prims(ctx, true)?;
                return Ok(StagePrims { prims, prototype_of: HashMap::new(), prototypes: HashMap::new() });
            };
            let key = proto.as_str().to_string();
            if !prototypes.contains_key(&key) {
                prototypes.insert(key.clone(), subtree(ctx, &key)?);
            }
            prototype_of.insert(p.clone(), key);
        }
        Ok(StagePrims { prims, prototype_of, prototypes })
    }

    /// The prims under SkelRoot `root` (not itself), sorted by path.
    fn under(&self, root: &str) -> Vec<(String, String)> {
        match self.prototype_of.get(root).and_then(|p| self.prototypes.get(p)) {
            Some(proto) => proto.iter().map(|(rel, t)| (format!("{root}{rel}"), t.clone())).collect(),
            None => descendants(&self.prims, root).to_vec(),
        }
    }
}

/// The prims under `root` (paths relative to it, starting `/`), with their
/// type names, sorted by path; at most [`MAX_AGENTS`] of them.
fn subtree(ctx: &Ctx, root: &str) -> Result<Vec<(String, String)>> {
    let mut out = Vec::new();
    let mut stack = vec![root.to_string()];
    while let Some(at) = stack.pop() {
        for c in ctx.stage.prim(ctx.sdf_path(&at)?).children().unwrap_or_default() {
            let path = c.path().as_str().to_string();
            let kind = c.type_name().ok().flatten().map(|t| t.as_str().to_string()).unwrap_or_default();
            out.push((path[root.len()..].to_string(), kind));
            if out.len() > MAX_AGENTS {
                return Err(ctx.err(root, format!("prototype <{root}> holds more than {MAX_AGENTS} prims")));
            }
            stack.push(path);
        }
    }
    out.sort();
    Ok(out)
}

/// The first target of relationship `prim.rel`, if authored.
fn target(ctx: &Ctx, prim: &str, rel: &str) -> Result<Option<String>> {
    let p = ctx.sdf_path(&format!("{prim}.{rel}"))?;
    Ok(ctx.stage.relationship(p).targets().unwrap_or_default().first().map(|t| t.as_str().to_string()))
}

/// The agents: one per SkelRoot, with ids assigned.
fn agents(ctx: &Ctx) -> Result<Vec<SkelAgent>> {
    let stage = StagePrims::read(ctx)?;
    let prims = &stage.prims;
    let roots: Vec<&String> = prims.iter().filter(|(_, t)| t == "SkelRoot").map(|(p, _)| p).collect();
    if roots.len() > MAX_AGENTS {
        return Err(Error::invalid(ctx.path, format!("{} SkelRoots; at most {MAX_AGENTS} agents", roots.len())));
    }
    let mut out = Vec::with_capacity(roots.len());
    let mut explicit = Vec::new();
    let mut characters: HashMap<String, usize> = HashMap::new();
    for root in roots {
        let under = stage.under(root);
        let skeleton = (under.iter())
            .find(|(_, t)| t == "Skeleton")
            .map(|(p, _)| p.clone())
            .ok_or_else(|| ctx.err(root, format!("SkelRoot <{root}> holds no Skeleton: an agent needs one")))?;
        // skel:animationSource binds at the skeleton or any ancestor up to the root.
        let mut animation = None;
        let mut at = skeleton.as_str();
        while animation.is_none() && at.len() >= root.len() {
            animation = target(ctx, at, "skel:animationSource")?;
            at = &at[..at.rfind('/').unwrap_or(0)];
        }
        let meshes: Vec<String> = (under.iter())
            .map(|(p, _)| p)
            .filter(|p| ctx.sdf_path(p).is_ok_and(|q| props(&ctx.stage, &q).contains("primvars:skel:jointIndices")))
            .cloned()
            .collect();
        let id = explicit_id(ctx, root)?;
        explicit.push(id);
        let key = character_key(ctx, root, &skeleton, &meshes)?;
        let next = characters.len();
        let character = *characters.entry(key).or_insert(next);
        out.push(SkelAgent { prim: root.clone(), id: 0, skeleton, animation, meshes, character });
    }
    assign_ids(ctx, &mut out, &explicit)?;
    Ok(out)
}

/// What makes agents one character: an instanceable SkelRoot's prototype
/// (its instances share the prototype's skeleton and meshes); else its
/// Skeleton's and meshes' paths under the SkelRoot, the skeleton's joints
/// and the meshes' points (a crowd exported without instancing repeats each
/// character's data under every agent). Materials are not in the key: agents
/// differing only in material wear their character's first agent's.
fn character_key(ctx: &Ctx, root: &str, skeleton: &str, meshes: &[String]) -> Result<String> {
    let prim = ctx.stage.prim(ctx.sdf_path(root)?);
    if let Ok(Some(proto)) = prim.prototype() {
        return Ok(format!("prototype {}", proto.as_str()));
    }
    let under = |p: &str| p.strip_prefix(root).unwrap_or(p).to_string();
    let mut f = Fingerprinter::new();
    f.text("skeleton", &under(skeleton)).debug("joints", &tokens(ctx, skeleton, "joints")?);
    for m in meshes {
        f.text("mesh", &under(m));
        if let Some(points) = ctx.value(m, "points", 0.0)?.and_then(|v| vec3s_of(&v)) {
            f.floats("points", points.iter().flat_map(|p| p.to_array()));
        }
    }
    Ok(f.hex())
}

/// The cache's rig name for character `k` of `count`: the import's rig when
/// the file holds one character, else the first's is the import's rig and
/// the k-th's (from 2) is that name with `_k` (docs/usd.md).
pub(crate) fn character_rig(rig: &str, k: usize, count: usize) -> String {
    match (k, count) {
        (0, _) | (_, 0 | 1) => rig.to_string(),
        (k, _) => format!("{rig}_{}", k + 1),
    }
}

/// The attributes an agent's id is read from, in order (docs/usd.md,
/// "UsdSkel crowds"): throng's own, then Golaem's USD Skeleton bake's
/// `entityId` on each entity's prim (int64, -1 for none).
const ID_ATTRIBUTES: [&str; 2] = ["primvars:throng:agentId", "entityId"];

/// SkelRoot `root`'s id from the first of [`ID_ATTRIBUTES`] it carries
/// (with that attribute), `None` when it carries none.
fn explicit_id(ctx: &Ctx, root: &str) -> Result<Option<(u32, &'static str)>> {
    for attr in ID_ATTRIBUTES {
        let id = match ctx.value(root, attr, 0.0)? {
            None => continue,
            // Golaem writes -1 for an entity without an id.
            Some(Value::Int64(-1)) if attr == "entityId" => continue,
            Some(Value::Int(i)) if i >= 0 => i as u32,
            Some(Value::Int64(i)) if (0..i64::from(u32::MAX)).contains(&i) => i as u32,
            Some(Value::Uint(i)) if i < u32::MAX => i,
            Some(_) => {
                return Err(
                    ctx.err(&format!("{root}.{attr}"), format!("<{root}> {attr} is not an id (0 to {})", u32::MAX - 1))
                )
            }
        };
        return Ok(Some((id, attr)));
    }
    Ok(None)
}

/// Ids: the explicit ones, then a hash of each other prim path (31 bits),
/// stepping to the next free id on a clash, in prim path order.
fn assign_ids(ctx: &Ctx, agents: &mut [SkelAgent], explicit: &[Option<(u32, &str)>]) -> Result<()> {
    let mut taken: BTreeMap<u32, String> = BTreeMap::new();
    for (a, id) in agents.iter_mut().zip(explicit) {
        let Some((id, attr)) = *id else { continue };
        if let Some(other) = taken.insert(id, a.prim.clone()) {
            return Err(ctx.err(
                &format!("{}.{attr}", a.prim),
                format!("<{}> and <{other}> both carry the agent id {id} (<{}.{attr}>)", a.prim, a.prim),
            ));
        }
        a.id = id;
    }
    for (a, id) in agents.iter_mut().zip(explicit) {
        if id.is_some() {
            continue;
        }
        let hex = Fingerprinter::new().text("usd agent prim", &a.prim).hex();
        let mut id = (u64::from_str_radix(&hex, 16).unwrap_or(0) & 0x7fff_ffff) as u32;
        while taken.contains_key(&id) {
            id = (id + 1) & 0x7fff_ffff;
        }
        taken.insert(id, a.prim.clone());
        a.id = id;
    }
    Ok(())
}

/// The crowd's frames: the stage's time code range, else the span of the
/// agents' transform and animation samples.
fn frames<'a>(ctx: &Ctx, agents: impl IntoIterator<Item = &'a SkelAgent>) -> Result<(i64, i64)> {
    if ctx.stage.has_authored_time_code_range() {
        return Ok((ctx.stage.start_time_code().ceil() as i64, ctx.stage.end_time_code().floor() as i64));
    }
    let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
    for a in agents {
        let mut attrs = xform_chain_ops(ctx, &a.prim)?;
        if let Some(anim) = &a.animation {
            attrs.extend(["translations", "rotations", "scales"].map(|x| (anim.clone(), x.to_string())));
        }
        for (p, attr) in attrs {
            for t in ctx.times(&p, &attr)? {
                lo = lo.min(t);
                hi = hi.max(t);
            }
        }
    }
    Ok(if lo.is_finite() { (lo.ceil() as i64, hi.floor() as i64) } else { (0, 0) })
}

/// A UsdSkel file read once (docs/usd.md, "Reading cost"): its agents and
/// characters, which the cache and the shot's rigs on the file both take,
/// so a shot never opens nor decodes the stage twice.
#[derive(Clone, Debug)]
pub(crate) struct SkelFile {
    /// Every agent, in prim path order.
    pub(crate) agents: Vec<SkelAgent>,
    /// Each character (indexed by [`SkelAgent::character`]): skeleton and
    /// distinct animations; its meshes and materials when read for a rig.
    pub(crate) characters: Vec<SkelCharacter>,
}

/// What one reading gives: the crowd when asked for, and the file.
pub(crate) struct SkelRead {
    /// The agents at every frame (when read with import options).
    pub(crate) crowd: Option<CrowdCache>,
    /// Agents and characters.
    pub(crate) file: SkelFile,
}

/// Reads a UsdSkel crowd into a [`CrowdCache`]: each SkelRoot at each frame,
/// placed and headed by its world transform, playing its animation. `None`
/// when the stage holds no SkelRoot (it is read as another USD crowd).
pub(crate) fn read(path: &Path, opts: &ImportOptions) -> Result<Option<CrowdCache>> {
    Ok(read_stage(path, Some(opts), false)?.and_then(|r| r.crowd))
}

/// Reads the stage at `path` once: its agents and characters (with their
/// skinned meshes when `meshes`) and, with `opts`, the crowd. `None` when
/// it holds no SkelRoot.
pub(crate) fn read_stage(path: &Path, opts: Option<&ImportOptions>, meshes: bool) -> Result<Option<SkelRead>> {
    let ctx = usd::open(path)?;
    let agents = agents(&ctx)?;
    if agents.is_empty() {
        return Ok(None);
    }
    let frames = frames(&ctx, &agents)?;
    if frames.1 < frames.0 || frames.1 - frames.0 >= usd::MAX_FRAMES {
        return Err(Error::invalid(
            path,
            format!(
                "the crowd's frame range {}-{} is empty or longer than {} frames",
                frames.0,
                frames.1,
                usd::MAX_FRAMES
            ),
        ));
    }
    // Each character's skeleton, from its first agent (characters are numbered in agent order).
    let mut characters = Vec::new();
    for a in &agents {
        if a.character == characters.len() {
            let skeleton = skeleton(&ctx, a, frames.0 as f64)?;
            let m = world_matrix(&ctx, &a.prim, frames.0 as f64)?;
            let scale = upright_scale(&m).map_err(|why| refuse_tilt(&ctx, &a.prim, frames.0, &why))?;
            characters.push(SkelCharacter {
                skeleton,
                meshes: Vec::new(),
                materials: Vec::new(),
                animations: Vec::new(),
                warnings: Vec::new(),
                scale,
            });
        }
    }
    // Per character: agents whose own scale is not the character's, and the range of their scales.
    let mut rescaled: Vec<(usize, f32, f32)> = vec![(0, f32::INFINITY, f32::NEG_INFINITY); characters.len()];
    let count = characters.len();
    // Cycle names by content within a character (another character's clip is another rig's).
    let mut cycles: Vec<CycleNames> = (0..count).map(|_| CycleNames::default()).collect();
    // Agents bound to one SkelAnimation prim share its reading: (cycle, first time).
    let mut played: HashMap<(usize, &str), (String, f64)> = HashMap::new();
    let mut gather = opts.map(|_| Gather::new(path, frames));
    for a in &agents {
        // The agent's place first: its samples' coverage is checked before its animation's.
        let world = match gather {
            Some(_) => Some(WorldTrack::read(&ctx, &a.prim)?),
            None => None,
        };
        for track in world.iter().flat_map(WorldTrack::tracks) {
            track.covers(&ctx, frames)?;
        }
        let (cycle, start) = match &a.animation {
            Some(anim) => match played.get(&(a.character, anim.as_str())) {
                Some(known) => known.clone(),
                None => {
                    let read = animation(&ctx, anim, &characters[a.character].skeleton, frames)?;
                    let name = cycles[a.character].name_of(&read);
                    let known = (name.clone(), read.times.first().copied().unwrap_or(frames.0 as f64));
                    if name == read.name {
                        characters[a.character].animations.push(read);
                    }
                    played.insert((a.character, anim), known.clone());
                    known
                }
            },
            None => (REST_CYCLE.to_string(), frames.0 as f64),
        };
        if let (Some(gather), Some(world), Some(opts)) = (&mut gather, &world, opts) {
            let rig = match ctx.value(&a.prim, "primvars:throng:rig", 0.0)? {
                Some(Value::String(s)) => s,
                Some(Value::Token(t)) => t.as_str().to_string(),
                _ => character_rig(&opts.rig, a.character, count),
            };
            let scale = characters[a.character].scale;
            let (lo, hi) = push_agent(&ctx, a, world, (&rig, &cycle, start), frames, gather)?;
            if (lo / scale - 1.0).abs() > SCALE_TOLERANCE || (hi / scale - 1.0).abs() > SCALE_TOLERANCE {
                let r = &mut rescaled[a.character];
                *r = (r.0 + 1, r.1.min(lo), r.2.max(hi));
            }
        }
    }
    for ((n, lo, hi), c) in rescaled.into_iter().zip(&mut characters).filter(|(r, _)| r.0 > 0) {
        c.warnings.push(format!(
            "{}: {n} agent(s) of the character of Skeleton <{}> are scaled {lo:.4} to {hi:.4} by their world \
             transforms, not {:.4} as its first agent is: they are drawn at {:.4} (throng scales a UsdSkel \
             character's agents alike)",
            path.display(),
            c.skeleton.prim,
            c.scale,
            c.scale
        ));
    }
    if meshes {
        for (k, c) in characters.iter_mut().enumerate() {
            let first = agents.iter().find(|a| a.character == k).expect("every character has a first agent");
            read_meshes(&ctx, first, c)?;
        }
    }
    let crowd = gather.map(Gather::finish).transpose()?;
    Ok(Some(SkelRead { crowd, file: SkelFile { agents, characters } }))
}

/// The error for SkelRoot `prim`, whose world transform at frame `f` is not upright (`why`).
fn refuse_tilt(ctx: &Ctx, prim: &str, f: i64, why: &str) -> Error {
    ctx.err(
        prim,
        format!(
            "SkelRoot <{prim}>'s world transform at frame {f} {why}: throng stands agents upright, turned \
             about +Y and scaled alike (bake the tilt into the skeleton's animation, or keep the scale uniform)"
        ),
    )
    .frame(f)
}

/// Agent `a` at every frame of `frames`, playing `cycle` of `rig` from time
/// `start`; the least and greatest scale of its world transform.
fn push_agent(
    ctx: &Ctx,
    a: &SkelAgent,
    world: &WorldTrack,
    (rig, cycle, start): (&str, &str, f64),
    frames: (i64, i64),
    gather: &mut Gather,
) -> Result<(f32, f32)> {
    let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
    for f in frames.0..=frames.1 {
        let m = world.at(ctx, f as f64)?;
        let s = upright_scale(&m).map_err(|why| refuse_tilt(ctx, &a.prim, f, &why))?;
        (lo, hi) = (lo.min(s), hi.max(s));
        let too_many = || ctx.err(&a.prim, "more than 65536 rig or cycle names").frame(f);
        let sample = super::AgentSample {
            id: a.id,
            position: m.w_axis.truncate(),
            heading: heading_of(&m),
            rig: gather.names.rig(rig).ok_or_else(too_many)?,
            cycle: gather.names.cycle(cycle).ok_or_else(too_many)?,
            // The clip holds its first pose a frame early (casting::usdskel_rig).
            cycle_frame: (f as f64 - start) as f32 + 1.0,
            flags: 0,
        };
        gather.push(&a.prim, f as i32, sample)?;
    }
    Ok((lo, hi))
}

/// Character `c`'s skinned meshes and materials, those of its agent `first`.
fn read_meshes(ctx: &Ctx, first: &SkelAgent, c: &mut SkelCharacter) -> Result<()> {
    for m in &first.meshes {
        let skel = (c.skeleton.prim.as_str(), c.skeleton.joints.as_slice());
        let mesh = super::usdskel_mesh::read(ctx, m, skel, &mut c.materials, &mut c.warnings)?;
        c.meshes.push(mesh);
    }
    if c.meshes.is_empty() {
        return Err(ctx.err(&first.prim, format!("SkelRoot <{}> holds no skinned Mesh", first.prim)));
    }
    Ok(())
}

/// Cycle names by animation content: the first prim with those samples.
#[derive(Default)]
struct CycleNames {
    by_content: HashMap<String, String>,
}

impl CycleNames {
    fn name_of(&mut self, anim: &SkelAnim) -> String {
        self.by_content.entry(content_key(anim)).or_insert_with(|| anim.name.clone()).clone()
    }
}

/// Grid on which animations are compared ([`content_key`]): joint-local
/// translations in stage units, quaternion components and scales.
const POSE_GRID: f32 = 1e-4;

/// A key equal for animations holding the same samples on the
/// [`POSE_GRID`]: each joint's translation, rotation (sign-canonical
/// quaternion) and scale rounded to it, so copies of one clip written with
/// float noise between them share one cycle (docs/usd.md, "Baked motion as a
/// cycle"). Values either side of a grid line part two animations: less
/// sharing, never a wrong pose.
fn content_key(anim: &SkelAnim) -> String {
    let grid = |v: f32| (v / POSE_GRID).round() as i64;
    let mut f = Fingerprinter::new();
    f.debug("joints", &anim.joints).debug("times", &anim.times);
    for pose in &anim.poses {
        let cells: Vec<i64> = (pose.iter())
            .flat_map(|(t, r, s)| {
                let r = if r.w < 0.0 { -*r } else { *r };
                t.to_array().into_iter().chain(r.to_array()).chain(s.to_array())
            })
            .map(grid)
            .collect();
        f.debug("pose", &cells);
    }
    f.hex()
}

/// A `matrix4d[]` attribute as column-vector matrices.
fn matrices(ctx: &Ctx, prim: &str, attr: &str) -> Result<Option<Vec<Mat4>>> {
    Ok(match ctx.value(prim, attr, 0.0)? {
        Some(Value::Matrix4dVec(v)) => Some(v.iter().map(|m| Mat4::from_cols_array(&m.0.map(|e| e as f32))).collect()),
        Some(_) => return Err(ctx.err(&format!("{prim}.{attr}"), format!("<{prim}.{attr}> is not a matrix4d[]"))),
        None => None,
    })
}

fn tokens(ctx: &Ctx, prim: &str, attr: &str) -> Result<Option<Vec<String>>> {
    Ok(match ctx.value(prim, attr, 0.0)? {
        Some(Value::TokenVec(v)) => Some(v.iter().map(|t| t.as_str().to_string()).collect()),
        Some(Value::StringVec(v)) => Some(v),
        Some(_) => return Err(ctx.err(&format!("{prim}.{attr}"), format!("<{prim}.{attr}> is not a token[]"))),
        None => None,
    })
}

/// The agent's Skeleton: joints, parents, rest and bind transforms, checked;
/// its place in the SkelRoot at time `t0` (the crowd's first frame).
pub(super) fn skeleton(ctx: &Ctx, agent: &SkelAgent, t0: f64) -> Result<SkelSkeleton> {
    let s = agent.skeleton.as_str();
    let at = |attr: &str| format!("{s}.{attr}");
    let joints =
        tokens(ctx, s, "joints")?.ok_or_else(|| ctx.err(&at("joints"), format!("Skeleton <{s}> has no `joints`")))?;
    if joints.is_empty() || joints.len() > MAX_JOINTS {
        return Err(ctx.err(&at("joints"), format!("Skeleton <{s}> has {} joints (1 to {MAX_JOINTS})", joints.len())));
    }
    let index: HashMap<&str, usize> = joints.iter().enumerate().map(|(i, j)| (j.as_str(), i)).collect();
    let mut parents = Vec::with_capacity(joints.len());
    for (i, j) in joints.iter().enumerate() {
        let parent = j.rfind('/').map(|k| &j[..k]);
        let p = match parent {
            None => None,
            Some(p) => match index.get(p) {
                Some(&pi) if pi < i => Some(pi),
                _ => {
                    return Err(ctx.err(
                        &at("joints"),
                        format!("Skeleton <{s}>: joint `{j}`'s parent `{p}` is not a joint listed before it"),
                    ))
                }
            },
        };
        parents.push(p);
    }
    let n = joints.len();
    let checked = |attr: &str, m: Option<Vec<Mat4>>| -> Result<Vec<Mat4>> {
        let m = m.ok_or_else(|| {
            ctx.err(&at(attr), format!("Skeleton <{s}> has no `{attr}`: throng needs the skeleton's {attr}"))
        })?;
        if m.len() != n {
            return Err(ctx.err(&at(attr), format!("Skeleton <{s}>: {} {attr} for {n} joints", m.len())));
        }
        if let Some(j) = m.iter().position(|m| !m.is_finite()) {
            return Err(
                ctx.err(&at(attr), format!("Skeleton <{s}>: {attr}[{j}] (joint `{}`) is not finite", joints[j]))
            );
        }
        Ok(m)
    };
    let bind = checked("bindTransforms", matrices(ctx, s, "bindTransforms")?)?;
    let rest = checked("restTransforms", matrices(ctx, s, "restTransforms")?)?;
    let root = world_matrix(ctx, &agent.prim, t0)?;
    let skel = world_matrix(ctx, s, t0)?;
    Ok(SkelSkeleton { prim: s.to_string(), joints, parents, rest, bind, root_from_skel: root.inverse() * skel })
}

/// A SkelAnimation's samples over `frames`, checked against `skel`.
pub(super) fn animation(ctx: &Ctx, prim: &str, skel: &SkelSkeleton, frames: (i64, i64)) -> Result<SkelAnim> {
    let at = |attr: &str| format!("{prim}.{attr}");
    let names = tokens(ctx, prim, "joints")?
        .ok_or_else(|| ctx.err(&at("joints"), format!("SkelAnimation <{prim}> has no `joints`")))?;
    let mut joints = Vec::with_capacity(names.len());
    for j in &names {
        let i = skel.joints.iter().position(|s| s == j).ok_or_else(|| {
            ctx.err(
                &at("joints"),
                format!("SkelAnimation <{prim}> animates joint `{j}`, which Skeleton <{}> does not have", skel.prim),
            )
        })?;
        joints.push(i);
    }
    // Each array's samples read once ([`Track`]), not once a time code.
    let [tr_track, rot_track, sc_track] = ["translations", "rotations", "scales"].map(|a| Track::read(ctx, prim, a));
    let tracks = [tr_track?, rot_track?, sc_track?];
    let mut times = BTreeSet::new();
    for track in &tracks {
        track.covers(ctx, frames)?;
        for &t in &track.times {
            if t >= frames.0 as f64 && t <= frames.1 as f64 {
                times.insert(t.to_bits());
            }
        }
    }
    let mut times: Vec<f64> = times.into_iter().map(f64::from_bits).collect();
    times.sort_by(f64::total_cmp);
    if times.is_empty() {
        times.push(frames.0 as f64);
    }
    let mut poses = Vec::with_capacity(times.len());
    for &t in &times {
        let f = t.floor() as i64;
        let read = |k: usize, get: &dyn Fn(&Value) -> Option<Vec<Vec3>>| -> Result<Option<Vec<Vec3>>> {
            let attr = ["translations", "rotations", "scales"][k];
            let Some(v) = tracks[k].at(ctx, t)? else { return Ok(None) };
            let v =
                get(&v).ok_or_else(|| ctx.err(&at(attr), format!("<{prim}.{attr}> has the wrong type")).frame(f))?;
            check_len(ctx, &at(attr), v.len(), joints.len(), f)?;
            Ok(Some(v))
        };
        let tr = read(0, &|v| vec3s_of(v))?;
        let sc = read(2, &|v| half3s_of(v).or_else(|| vec3s_of(v)))?;
        let rot = match tracks[1].at(ctx, t)? {
            None => None,
            Some(v) => {
                let q = quats_of(&v).ok_or_else(|| ctx.err(&at("rotations"), "rotations is not a quat[]").frame(f))?;
                check_len(ctx, &at("rotations"), q.len(), joints.len(), f)?;
                Some(q)
            }
        };
        let mut pose = Vec::with_capacity(joints.len());
        for (k, &j) in joints.iter().enumerate() {
            let (rs, rr, rt) = skel.rest[j].to_scale_rotation_translation();
            let t = tr.as_ref().map_or(rt, |v| v[k]);
            let r = rot.as_ref().map_or(rr, |v| v[k]);
            let s = sc.as_ref().map_or(rs, |v| v[k]);
            if !(t.is_finite() && r.is_finite() && s.is_finite()) || r.length_squared() < 1e-12 {
                return Err(ctx
                    .err(
                        &at("translations"),
                        format!("<{prim}>: joint `{}` has a non-finite transform at time {t:?}", names[k]),
                    )
                    .frame(f));
            }
            pose.push((t, r.normalize(), s));
        }
        poses.push(pose);
    }
    Ok(SkelAnim { name: prim.to_string(), joints, times, poses })
}

fn check_len(ctx: &Ctx, attr: &str, got: usize, want: usize, f: i64) -> Result<()> {
    if got != want {
        return Err(ctx.err(attr, format!("<{attr}> holds {got} values for {want} joints at frame {f}")).frame(f));
    }
    Ok(())
}

fn half3s_of(v: &Value) -> Option<Vec<Vec3>> {
    match v {
        Value::Vec3hVec(p) => Some(p.iter().map(|p| Vec3::new(p.x.to_f32(), p.y.to_f32(), p.z.to_f32())).collect()),
        _ => None,
    }
}

impl SkelFile {
    /// Reads the agents and characters (meshes included) of the UsdSkel
    /// crowd at `path`, as a rig on the file needs them.
    pub(crate) fn read(path: &Path) -> Result<SkelFile> {
        match read_stage(path, None, true)? {
            Some(r) => Ok(r.file),
            None => Err(Error::invalid(path, "no SkelRoot in this USD file: it holds no UsdSkel character")),
        }
    }

    /// The character of SkelRoot `root` (any of its agents, or a prim
    /// above one: the first agent under it), else the first agent's.
    pub(crate) fn character(&self, path: &Path, root: Option<&str>) -> Result<&SkelCharacter> {
        let agents = &self.agents;
        let found = match root {
            None => agents.first(),
            Some(r) => agents
                .iter()
                .find(|a| a.prim == r)
                .or_else(|| agents.iter().find(|a| a.prim.starts_with(&format!("{}/", r.trim_end_matches('/'))))),
        };
        if let Some(c) = found.and_then(|a| self.characters.get(a.character)) {
            return Ok(c);
        }
        let mut firsts: Vec<&str> = Vec::new();
        for a in agents {
            if a.character == firsts.len() {
                firsts.push(&a.prim);
            }
        }
        Err(Error::invalid(
            path,
            format!(
                "root <{}> is no SkelRoot of this crowd (nor a prim above one); its characters' first SkelRoots: {}",
                root.unwrap_or_default(),
                firsts.join(", ")
            ),
        )
        .field("root"))
    }
}
