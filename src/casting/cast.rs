//! Casting (the "frankenbot" stage): for every agent a scheme, one part per
//! rig slot, a material per part and a height scale.
//!
//! Casting is a pure function of (shot seed, agent id, rig, wardrobes, shot
//! exclusions). Every random choice draws from its own generator keyed by
//! hash(seed, agent id, purpose), never from a shared sequence, so adding,
//! removing or reordering agents changes no other agent.

use std::collections::{BTreeMap, HashMap};
use std::path::Path;
use std::sync::Arc;

use glam::{Affine3A, Quat, Vec3};
use rayon::prelude::*;

use crate::cache::CacheReader;
use crate::casting::rigs::ShotRigs;
use crate::casting::wardrobe::{CastPart, CastProp, Scheme, Wardrobes, GLTF_MATERIAL};
use crate::error::{Error, Result};
use crate::seed::{purpose_hash, purpose_hash_from, uniform, uniform_hashed};
use crate::shot::Shot;

/// Index drawn with probability proportional to `weights` (all >= 0);
/// `None` when they sum to zero.
pub(crate) fn weighted_pick(weights: &[f32], u: f64) -> Option<usize> {
    let total: f64 = weights.iter().map(|&w| w.max(0.0) as f64).sum();
    if total <= 0.0 {
        return None;
    }
    let mut target = u * total;
    let mut last = None;
    for (i, &w) in weights.iter().enumerate() {
        if w > 0.0 {
            last = Some(i);
            if target < w as f64 {
                return Some(i);
            }
            target -= w as f64;
        }
    }
    last // rounding at the very top of the range
}

/// One slot of a cast agent.
#[derive(Debug, Clone, PartialEq)]
pub struct SlotCast {
    /// Rig slot name.
    pub(crate) slot: Arc<str>,
    /// The part, or `None` when the scheme has no candidate for this slot.
    /// Shared (`Arc`) by every agent cast in the same part and material.
    pub part: Option<Arc<CastPart>>,
}

/// A cast agent.
#[derive(Debug, Clone, PartialEq)]
pub struct AgentCast {
    /// Cache id.
    pub id: u32,
    /// Rig name.
    pub rig: Arc<str>,
    /// Wardrobe scheme.
    pub scheme: Arc<str>,
    /// Height scale (1.0 for agents that are never scaled).
    pub height_scale: f32,
    /// Whether the height jitter applies (false for seated and no-scale agents).
    pub(crate) scaled: bool,
    /// The body it plays (`casting::body`): 0, the rig as modelled, for a
    /// rig without proportions and for seated and no-scale agents.
    pub body: u16,
    /// Parts per rig slot, in rig slot order.
    pub slots: Vec<SlotCast>,
    /// The props drawn (groups that drew `none` left out), in group name order.
    /// A prop's part index (Cryptomatte, export) follows the slots': `slots.len() + i`.
    pub props: Vec<Arc<CastProp>>,
}

impl AgentCast {
    /// The name of part `part`: a slot's, then a prop's (`slots.len() + i`).
    pub(crate) fn part_name(&self, part: u16) -> Option<&str> {
        let part = part as usize;
        match self.slots.get(part) {
            Some(s) => Some(&s.slot),
            None => self.props.get(part - self.slots.len()).map(|p| &*p.name),
        }
    }
}

/// What casting needs to know about one rig.
#[derive(Debug, Clone)]
pub struct RigCasting<'a> {
    /// Rig name (shared with every agent cast on the rig).
    pub name: Arc<str>,
    /// Slot names in rig order (shared with every agent cast on the rig).
    pub slots: &'a [Arc<str>],
    /// Scheme name -> weight, from the shot.
    pub schemes: &'a std::collections::BTreeMap<String, f32>,
    /// Height jitter fraction.
    pub height_jitter: f32,
    /// Bodies the rig's proportions drew (0: none, every agent as modelled).
    pub bodies: u16,
}

/// Casts one agent; an error says what is wrong with the shot or wardrobes
/// for it (the caller adds the file and agent). `never_scale` is true when the agent is seated or on a
/// no-scale cycle at any frame of the shot: it keeps height 1.0 throughout,
/// so it never pops in size and never floats above or sinks into a bench.
pub fn cast_agent(
    seed: u64,
    id: u32,
    rig: &RigCasting,
    wardrobes: &Wardrobes,
    shot_excludes: &[String],
    never_scale: bool,
) -> std::result::Result<AgentCast, String> {
    let names: Vec<&String> = rig.schemes.keys().collect();
    let weights: Vec<f32> = rig.schemes.values().copied().collect();
    let pick = weighted_pick(&weights, uniform(seed, id, "scheme"))
        .ok_or_else(|| format!("rig `{}` has no scheme with a weight above 0 in the shot", rig.name))?;
    let scheme_name = names[pick];
    let scheme: &Scheme = wardrobes.schemes.get(scheme_name).ok_or_else(|| {
        format!(
            "rig `{}` asks for scheme `{scheme_name}`, which no wardrobe defines (known: {})",
            rig.name,
            wardrobes.schemes.keys().cloned().collect::<Vec<_>>().join(", ")
        )
    })?;

    let mut slots = Vec::with_capacity(rig.slots.len());
    for slot in rig.slots {
        let candidates: Vec<_> = scheme.candidates(slot, shot_excludes).collect();
        let w: Vec<f32> = candidates.iter().map(|p| p.weight).collect();
        let part =
            weighted_pick(&w, uniform_hashed(seed, id, purpose_hash_from(purpose_hash("part/"), slot))).map(|i| {
                let p = candidates[i];
                let m = weighted_pick(
                    &p.material_weight_list(),
                    uniform_hashed(seed, id, purpose_hash_from(purpose_hash("material/"), slot)),
                )
                .unwrap_or(0);
                p.cast_part(m, scheme.is_uniform(slot))
            });
        slots.push(SlotCast { slot: slot.clone(), part });
    }

    Ok(AgentCast {
        id,
        rig: rig.name.clone(),
        scheme: scheme.name.clone(),
        height_scale: height_scale(seed, id, rig.height_jitter, never_scale),
        scaled: !never_scale,
        body: draw_body(seed, id, rig.bodies, never_scale),
        slots,
        props: draw_props(seed, id, scheme),
    })
}

/// One prop or none per prop group of `scheme`, each group from its own
/// draws (`prop/<group>`, `prop_material/<group>`), so a group added or
/// removed changes no other draw.
fn draw_props(seed: u64, id: u32, scheme: &Scheme) -> Vec<Arc<CastProp>> {
    let mut props = Vec::new();
    for g in &scheme.prop_groups {
        let w: Vec<f32> = g.entries.iter().map(|&(_, w)| w).collect();
        let Some(pick) = weighted_pick(&w, uniform_hashed(seed, id, purpose_hash_from(purpose_hash("prop/"), &g.name)))
        else {
            continue;
        };
        let prop = &scheme.props[g.entries[pick].0];
        if prop.is_none() {
            continue;
        }
        let u = uniform_hashed(seed, id, purpose_hash_from(purpose_hash("prop_material/"), &g.name));
        let m = weighted_pick(&prop.material_weight_list(), u).unwrap_or(0);
        props.extend(prop.cast.get(m).or(prop.cast.first()).cloned());
    }
    props
}

/// The scheme name of agents that wear their character as delivered.
pub(crate) const DELIVERED_SCHEME: &str = "delivered";

/// Casts an agent of a skinned rig whose shot names no schemes: it wears
/// the file's own meshes and materials (`parts`, one per slot); only the
/// height is drawn.
pub(crate) fn cast_delivered(
    seed: u64,
    id: u32,
    rig: &RigCasting,
    parts: Vec<SlotCast>,
    never_scale: bool,
) -> AgentCast {
    AgentCast {
        id,
        rig: rig.name.clone(),
        scheme: DELIVERED_SCHEME.into(),
        height_scale: height_scale(seed, id, rig.height_jitter, never_scale),
        scaled: !never_scale,
        body: draw_body(seed, id, rig.bodies, never_scale),
        slots: parts,
        props: Vec::new(),
    }
}

/// `h' = h * (1 + U(-j, j))`; drawn even for unscaled agents so that the
/// draw never depends on anything but (seed, id, purpose).
fn height_scale(seed: u64, id: u32, jitter: f32, never_scale: bool) -> f32 {
    let u = uniform(seed, id, "height") as f32;
    let jittered = 1.0 + jitter * (2.0 * u - 1.0);
    if never_scale {
        1.0
    } else {
        jittered
    }
}

/// One of `bodies` (1 to `bodies`), or 0 (as modelled) without bodies or
/// for an agent that is never scaled; drawn from (seed, id) alone.
fn draw_body(seed: u64, id: u32, bodies: u16, never_scale: bool) -> u16 {
    let u = uniform(seed, id, "body");
    if bodies == 0 || never_scale {
        return 0;
    }
    1 + ((u * f64::from(bodies)) as u16).min(bodies - 1)
}

/// The transform that fits a part mesh (bounds `mesh_lo..mesh_hi`) to its
/// slot's proxy box (`box_lo..box_hi`), both in slot space.
///
/// Body parts scale per axis to fill the box. Uniform parts (heads) scale by
/// the smallest axis ratio so they fit inside the box, rest on its bottom and
/// are centred in X and Z: non-uniform heads looked "inflated and sickly".
pub(crate) fn fit_part(mesh_lo: Vec3, mesh_hi: Vec3, box_lo: Vec3, box_hi: Vec3, uniform: bool) -> Affine3A {
    let size = mesh_hi - mesh_lo;
    let target = box_hi - box_lo;
    // A flat mesh (zero extent on an axis) keeps its unit size on that axis.
    let ratio = Vec3::select(size.cmpgt(Vec3::splat(1e-9)), target / size.max(Vec3::splat(1e-9)), Vec3::ONE);
    if uniform {
        let s = ratio.min_element();
        let mesh_centre = (mesh_lo + mesh_hi) * 0.5;
        let box_centre = (box_lo + box_hi) * 0.5;
        let t = Vec3::new(box_centre.x - s * mesh_centre.x, box_lo.y - s * mesh_lo.y, box_centre.z - s * mesh_centre.z);
        Affine3A::from_scale_rotation_translation(Vec3::splat(s), Quat::IDENTITY, t)
    } else {
        Affine3A::from_scale_rotation_translation(ratio, Quat::IDENTITY, box_lo - ratio * mesh_lo)
    }
}

/// The casting stage: who wears what. Every agent that appears in the
/// shot's frames, cast once, by id; built by [`Casting::cast`] and not
/// changed afterwards.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Casting {
    agents: BTreeMap<u32, AgentCast>,
}

/// A skinned pose step an agent takes: (rig, body, cycle index, pose step).
pub(crate) type PoseStep = (Arc<str>, u16, usize, u32);

/// What [`Casting::cast`] gives besides the casting.
pub(crate) struct CastOutcome {
    /// Every agent cast.
    pub(crate) casting: Casting,
    /// What casting noticed but accepted (shot frames outside the cache).
    pub(crate) warnings: Vec<String>,
}

/// Where an agent first appears, and whether it is ever seated or on a no-scale cycle.
struct Seen {
    /// Its rig index in the cache at its first appearance.
    rig: u16,
    never_scale: bool,
}

/// Reads the shot's frames once: every agent seen (id order), refusing a
/// cycle an agent's rig lacks, and the warnings of shot frames outside the
/// cache; an error when no frame holds an agent.
fn seen_agents(shot: &Shot, cache: &CacheReader, rigs: &ShotRigs) -> Result<(BTreeMap<u32, Seen>, Vec<String>)> {
    let mut seen: BTreeMap<u32, Seen> = BTreeMap::new();
    let mut outside: Vec<i32> = Vec::new();
    for f in shot.frames.iter() {
        let cf = shot.cache.cache_frame(f);
        if cache.frames().binary_search(&cf).is_err() {
            outside.push(f);
            continue;
        }
        let block = cache.read_frame(cf)?;
        for a in &block.agents {
            crate::casting::check_agent_id(cache.path(), cf, a.id)?;
            let cycle = cache.cycles().get(a.cycle as usize).map(String::as_str).unwrap_or("");
            let rig_name = cache.rigs().get(a.rig as usize).map(String::as_str).unwrap_or("");
            // A cycle the agent's rig lacks would only fail when posed; say so now.
            let missing = rigs.get(rig_name).and_then(|rig| rig.lacks_cycle(cycle));
            if let Some(e) = missing {
                return Err(Error::invalid(cache.path(), format!("rig `{rig_name}`: {e}"))
                    .frame(f as i64)
                    .agent(a.id)
                    .field("cycle"));
            }
            let no_scale = a.seated() || shot.is_no_scale_cycle(cycle);
            let e = seen.entry(a.id).or_insert(Seen { rig: a.rig, never_scale: false });
            e.never_scale |= no_scale;
        }
    }
    let warnings = crate::casting::check_outside_cache(shot, cache.frames(), cache.path(), &outside)?;
    if seen.is_empty() {
        return Err(Error::invalid(
            &shot.cache.path,
            format!(
                "no agents in cache frames {}-{} (shot frames {}-{} with frame_offset {})",
                shot.cache.cache_frame(shot.frames.start),
                shot.cache.cache_frame(shot.frames.end),
                shot.frames.start,
                shot.frames.end,
                shot.cache.frame_offset
            ),
        ));
    }
    Ok((seen, warnings))
}

/// Skinned rigs without schemes: the character as delivered, in its own
/// materials; the slot list is made once per rig and shared.
fn delivered_slots<'a>(shot: &Shot, rigs: &'a ShotRigs) -> HashMap<&'a str, Vec<SlotCast>> {
    (rigs.iter())
        .filter(|(name, _)| shot.rigs.get(*name).is_some_and(|r| r.schemes.is_empty()))
        .filter_map(|(name, rig)| Some((name, rig.skinned()?)))
        .map(|(name, rig)| {
            let rig_file: Arc<Path> = rig.path().into();
            let parts = (rig.delivered().iter())
                .map(|(slot, mesh, _)| SlotCast {
                    slot: slot.as_str().into(),
                    part: Some(Arc::new(CastPart {
                        file: rig_file.clone(),
                        mesh: mesh.as_str().into(),
                        material: GLTF_MATERIAL.into(),
                        uniform: false,
                        facing: glam::Quat::IDENTITY,
                    })),
                })
                .collect();
            (name, parts)
        })
        .collect()
}

impl Casting {
    /// Casts every agent that appears in the shot's frames: reads the
    /// frames once (each agent's rig at its first appearance, whether it is
    /// ever seated or on a no-scale cycle), refuses a cycle an agent's rig
    /// lacks, then casts every agent.
    pub(crate) fn cast(
        shot: &Shot,
        cache: &CacheReader,
        rigs: &ShotRigs,
        wardrobes: &Wardrobes,
    ) -> Result<CastOutcome> {
        let (seen, warnings) = seen_agents(shot, cache, rigs)?;

        // Rig and slot names shared (Arc) by every agent cast on the rig.
        let rig_names: HashMap<&str, (Arc<str>, Vec<Arc<str>>)> = rigs
            .iter()
            .map(|(name, rig)| (name, (name.into(), rig.slot_names().into_iter().map(Arc::from).collect())))
            .collect();
        let delivered = delivered_slots(shot, rigs);
        // Casting is a pure function of (seed, agent): cast every agent in
        // parallel, kept in id order (so the first error is as if cast one by one).
        let cache_rigs = cache.rigs();
        let seen_list: Vec<(u32, &Seen)> = seen.iter().map(|(&id, s)| (id, s)).collect();
        let casts: Vec<Option<Result<AgentCast>>> =
            seen_list
                .par_iter()
                .map(|&(id, s)| {
                    let rig_name = cache_rigs.get(s.rig as usize).map_or("", String::as_str);
                    let Some(rig_ref) = shot.rigs.get(rig_name) else {
                        return Some(Err(Error::invalid(
                            &shot.path,
                            format!(
                            "agent {id} uses rig `{rig_name}`, which the shot's [rigs] does not define (defined: {})",
                            shot.rigs.keys().cloned().collect::<Vec<_>>().join(", ")
                        ),
                        )
                        .agent(id)
                        .field("rigs")));
                    };
                    let (shared_name, slot_names) = rig_names.get(rig_name)?;
                    let rc = RigCasting {
                        name: shared_name.clone(),
                        slots: slot_names,
                        schemes: &rig_ref.schemes,
                        height_jitter: rig_ref.height_jitter,
                        bodies: rigs.skinned(rig_name).map_or(0, |r| r.body_count()),
                    };
                    Some(match delivered.get(rig_name) {
                        Some(parts) => Ok(cast_delivered(shot.seed, id, &rc, parts.clone(), s.never_scale)),
                        None => cast_agent(shot.seed, id, &rc, wardrobes, &shot.exclude_parts, s.never_scale).map_err(
                            |msg| Error::invalid(&shot.path, msg).agent(id).field(format!("rigs.{rig_name}.schemes")),
                        ),
                    })
                })
                .collect();
        let mut agents = BTreeMap::new();
        for cast in casts.into_iter().flatten() {
            let cast = cast?;
            agents.insert(cast.id, cast);
        }
        Ok(CastOutcome { casting: Casting { agents }, warnings })
    }

    /// Agent `id`'s cast (`None`: it is not in the shot's frames).
    pub(crate) fn get(&self, id: u32) -> Option<&AgentCast> {
        self.agents.get(&id)
    }

    /// Every cast agent, in id order.
    pub fn iter(&self) -> impl Iterator<Item = &AgentCast> {
        self.agents.values()
    }

    /// Every cast agent's id, in order.
    pub fn ids(&self) -> impl Iterator<Item = u32> + '_ {
        self.agents.keys().copied()
    }

    /// How many agents are cast.
    pub fn len(&self) -> usize {
        self.agents.len()
    }

    /// Whether no agent is cast.
    pub fn is_empty(&self) -> bool {
        self.agents.is_empty()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn body_parts_fill_the_box() {
        let m = fit_part(
            Vec3::new(-1.0, 0.0, -2.0),
            Vec3::new(1.0, 4.0, 2.0),
            Vec3::new(0.0, -0.5, 0.0),
            Vec3::new(0.2, 0.0, 0.1),
            false,
        );
        assert!((m.transform_point3(Vec3::new(-1.0, 0.0, -2.0)) - Vec3::new(0.0, -0.5, 0.0)).length() < 1e-6);
        assert!((m.transform_point3(Vec3::new(1.0, 4.0, 2.0)) - Vec3::new(0.2, 0.0, 0.1)).length() < 1e-6);
    }

    #[test]
    fn heads_scale_uniformly_inside_the_box_resting_on_its_bottom() {
        // A sphere-ish head of size 2 into a tall thin box: limited by x.
        let (lo, hi) = (Vec3::splat(-1.0), Vec3::splat(1.0));
        let (blo, bhi) = (Vec3::new(-0.1, 0.0, -0.2), Vec3::new(0.1, 0.5, 0.2));
        let m = fit_part(lo, hi, blo, bhi, true);
        let (scale, _, _) = m.to_scale_rotation_translation();
        assert!((scale.x - scale.y).abs() < 1e-6 && (scale.y - scale.z).abs() < 1e-6, "{scale}");
        let (a, b) = (m.transform_point3(lo), m.transform_point3(hi));
        assert!(a.cmpge(blo - 1e-6).all() && b.cmple(bhi + 1e-6).all(), "{a} {b}");
        assert!((a.y - blo.y).abs() < 1e-6, "rests on the bottom");
        assert!(((a.z + b.z) * 0.5).abs() < 1e-6, "centred in z");
    }

    #[test]
    fn weighted_pick_respects_weights() {
        assert_eq!(weighted_pick(&[0.0, 0.0], 0.5), None);
        assert_eq!(weighted_pick(&[0.0, 1.0, 0.0], 0.99), Some(1));
        let mut counts = [0usize; 2];
        for id in 0..10_000 {
            counts[weighted_pick(&[3.0, 1.0], uniform(9, id, "w")).unwrap()] += 1;
        }
        let frac = counts[0] as f64 / 10_000.0;
        assert!((frac - 0.75).abs() < 0.02, "{frac}");
    }
}
