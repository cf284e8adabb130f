//! The casting-to-layers adapter: a [`LayerInput`] from a cast shot (positions
//! from the cache, heights and per-agent memory from casting), the overrides a
//! caller puts over the shot's `[layers]` table, and the set bounds the layer
//! map draws.

use std::collections::HashMap;

use glam::Vec3;

use super::memory::{blas_bytes, instance_bytes, AgentTraces, RenderFloor};
use super::{agent_lods, build_manifest, lod_at, shot_input, LayerOptions, LodChange, Manifest};
use crate::casting::{Lod, ShotCrowd};
use crate::error::{Error, Result};
use crate::shot::{parse_bytes, LayerSettings, SplitMode};

/// Overrides of the shot's `[layers]` table; `Default` changes nothing.
#[derive(Debug, Clone, Default)]
pub struct LayerOverrides {
    /// Split into this many layers of equal agent count.
    pub count: Option<usize>,
    /// Split at these distances in metres.
    pub cutoffs: Option<Vec<f32>>,
    /// Split by estimated render memory, e.g. `2.8GB`.
    pub budget: Option<String>,
    /// Shot frame to rank at.
    pub ref_frame: Option<i32>,
    /// Also rank on every frame to count the pops a per-frame split would cause.
    pub per_frame: bool,
    /// Projected height in pixels below which an agent renders as proxy boxes.
    pub lod_px: Option<f32>,
    /// Choose LOD on every frame, with hysteresis.
    pub lod_per_frame: bool,
}

/// Applies `overrides` over the shot's `[layers]` table.
pub fn settings_with_overrides(
    shot: &LayerSettings,
    overrides: &LayerOverrides,
) -> Result<(LayerSettings, LayerOptions)> {
    let mut s = shot.clone();
    if let Some(c) = overrides.count {
        s.split = SplitMode::Count;
        s.count = c;
    }
    if let Some(c) = &overrides.cutoffs {
        s.split = SplitMode::Cutoffs;
        s.cutoffs = c.clone();
    }
    if let Some(b) = &overrides.budget {
        parse_bytes(b).map_err(|m| Error::setting("budget", m))?;
        s.split = SplitMode::Budget;
        s.budget = Some(b.clone());
    }
    if overrides.ref_frame.is_some() {
        s.ref_frame = overrides.ref_frame;
    }
    if let Some(px) = overrides.lod_px {
        s.lod_full_min_px = px;
    }
    let options =
        LayerOptions { per_frame: overrides.per_frame, lod_per_frame: overrides.lod_per_frame, ..Default::default() };
    Ok((s, options))
}

/// The shutter a shot's layer renders use: the one the crowd was posed
/// for, else the shot's `render.shutter` (what `throng render` and farm
/// tasks blur with when no `--shutter` is given).
pub fn render_shutter(crowd: &ShotCrowd) -> Option<[f32; 2]> {
    crowd.poses().shutter().or(crowd.shot().render.shutter)
}

/// Builds the layer manifest of a cast shot with `overrides` over the
/// shot's `[layers]`; memory is estimated for renders at the shot's
/// resolution with [`render_shutter`].
pub fn build_layers(crowd: &ShotCrowd, overrides: &LayerOverrides) -> Result<Manifest> {
    let (settings, options) = settings_with_overrides(&crowd.shot().layers, overrides)?;
    let all = crowd.shot_crowd()?;
    let [w, h] = crowd.shot().render.resolution;
    let shutter = render_shutter(crowd);
    let blurred = shutter.is_some();
    let cameras = match crowd.shot().keyed_camera(crowd.shot().frames.start as f32) {
        Some(_) => None,
        None => Some(crowd.shot().frames.iter().map(|f| crowd.camera(f)).collect::<Result<Vec<_>>>()?),
    };
    let mut input = shot_input(crowd.shot(), &all, cameras, settings, options, |id| {
        // Every agent of the shot's frames was cast; others never reach here.
        let Some(height) = crowd.agent_height(id) else { return (1.8, 0, 0) };
        let (full, proxies) = (crowd.instance_count(id, Lod::Full), crowd.instance_count(id, Lod::Proxy));
        (height, instance_bytes(full as u64, blurred), instance_bytes(proxies as u64, blurred))
    })?;
    // Each agent's LOD (only full agents trace their poses) does not depend on the split.
    let lods: HashMap<u32, Vec<LodChange>> =
        input.agents.iter().zip(agent_lods(&input)?).filter_map(|(a, l)| Some((a.id, l?))).collect();
    let removed: std::collections::HashSet<u32> = input.agents.iter().filter(|a| a.removed).map(|a| a.id).collect();
    let full = |id: u32, f: i32| !removed.contains(&id) && lods.get(&id).and_then(|c| lod_at(c, f)) == Some(Lod::Full);
    // What every render holds whatever its agents: process, loaded shot,
    // library, set, film (charged once per layer).
    let floor = RenderFloor::of(crowd, shutter, w as u64 * h as u64, full)?.bytes();
    // The poses every full agent plays, all in one render: what each layer
    // traces when other layers' agents cast at their own LOD, else what the
    // split shares out among the full agents.
    let every = AgentTraces::of(crowd, shutter, 1, |id, f| if full(id, f) { vec![0] } else { Vec::new() })?;
    let all_poses = every.per_render.first().map_or(0, |&(t, d)| blas_bytes(t, d));
    if input.settings.proxy_shadow_casters {
        // A layer traces only its own agents' poses: the split charges each
        // full agent an equal share (the exact figure is worked out below).
        let full_agents =
            input.agents.iter().filter(|a| lods.get(&a.id).is_some_and(|c| c.iter().any(|c| c.lod == Lod::Full)));
        let share = all_poses / (full_agents.count() as u64).max(1);
        for a in input.agents.iter_mut() {
            a.memory_full = a.memory_full.saturating_add(share);
        }
        input.options.shared_bytes = floor;
    } else {
        input.options.shared_bytes = floor.saturating_add(all_poses);
    }
    let mut manifest = build_manifest(&input)?;
    layer_estimates(crowd, shutter, floor, blurred, &mut manifest)?;
    manifest.made_from = Some(super::MadeFrom::of(crowd.shot())?);
    super::made_from::seal(&mut manifest);
    Ok(manifest)
}

/// Each render's own estimate ([`super::memory`]): the floor once, plus
/// what its agents cost there — the BLASes of the poses it traces (its
/// own full agents', and every other full agent's unless casters are proxy
/// boxes) at its dearest frame, and the instances it traces (its own at
/// their LOD, the others as casters). Sets every crowd layer's
/// `memory_bytes` and the set layer's, and checks them against a budget.
fn layer_estimates(
    crowd: &ShotCrowd,
    shutter: Option<[f32; 2]>,
    floor: u64,
    blurred: bool,
    m: &mut Manifest,
) -> Result<()> {
    let n = m.layers.len();
    let proxy_casters = m.proxy_shadow_casters;
    let by_id: HashMap<u32, (usize, Vec<LodChange>, Lod)> =
        m.agents.iter().filter(|a| !a.removed).map(|a| (a.id, (a.layer, a.lod_changes.clone(), a.lod))).collect();
    let set = n;
    let traces = AgentTraces::of(crowd, shutter, n + 1, |id, f| {
        let Some((layer, changes, lod)) = by_id.get(&id) else { return Vec::new() };
        if lod_at(changes, f).unwrap_or(*lod) != Lod::Full {
            return Vec::new();
        }
        if proxy_casters {
            vec![*layer]
        } else {
            (0..=set).collect()
        }
    })?;
    // Instances: own at their LOD (full if ever full), the others as casters.
    let mut own = vec![0u64; n];
    let mut casters = 0u64;
    let mut caster_of_layer = vec![0u64; n];
    for a in m.agents.iter().filter(|a| !a.removed) {
        let ever_full = a.lod == Lod::Full || a.lod_changes.iter().any(|c| c.lod == Lod::Full);
        let count = |lod| crowd.instance_count(a.id, lod) as u64;
        let mine = instance_bytes(count(if ever_full { Lod::Full } else { Lod::Proxy }), blurred);
        let caster = if proxy_casters { instance_bytes(count(Lod::Proxy), blurred) } else { mine };
        own[a.layer] += mine;
        caster_of_layer[a.layer] += caster;
        casters += caster;
    }
    let poses = |r: usize| traces.per_render.get(r).map_or(0, |&(t, d)| blas_bytes(t, d));
    for (i, l) in m.layers.iter_mut().enumerate() {
        l.memory_bytes = floor + poses(i) + own[i] + (casters - caster_of_layer[i]);
    }
    m.set.memory_bytes = Some(floor + poses(set) + casters);
    if let Some(budget) = m.split.budget_bytes {
        if let Some(over) = m.layers.iter().find(|l| l.memory_bytes > budget) {
            return Err(Error::invalid(
                &crowd.shot().path,
                format!(
                    "layer {} needs {} (its agents' poses, shared by fewer agents than the split assumed), over \
                     the budget of {}; lower the budget a little or raise it",
                    over.name,
                    super::format_bytes(over.memory_bytes),
                    super::format_bytes(budget)
                ),
            )
            .field("layers.budget"));
        }
    }
    Ok(())
}

/// World bounds of the set's instances, for the layer map.
pub fn set_bounds(crowd: &ShotCrowd) -> Option<(Vec3, Vec3)> {
    let lib = crowd.library();
    crowd
        .set()
        .iter()
        .flat_map(|i| {
            let (lo, hi) = lib.meshes[i.mesh as usize].bounds();
            crate::scene::box_corners(lo, hi).map(|p| i.world_from_object.transform_point3(p))
        })
        .fold(None, |acc: Option<(Vec3, Vec3)>, p| Some(acc.map_or((p, p), |(lo, hi)| (lo.min(p), hi.max(p)))))
}
