//! The casting-to-layers adapter: a [`LayerInput`] from a cast shot (positions
//! from the cache, heights and per-agent memory from casting), the overrides a
//! caller puts over the shot's `[layers]` table, and the set bounds the layer
//! map draws.

use std::collections::HashMap;

use glam::Vec3;

use super::memory::{instance_bytes, RenderFloor};
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
    // The floor needs each agent's LOD (only full agents trace their poses),
    // which does not depend on the split.
    let lods: HashMap<u32, Vec<LodChange>> =
        input.agents.iter().zip(agent_lods(&input)?).filter_map(|(a, l)| Some((a.id, l?))).collect();
    let full = |id: u32, f: i32| lods.get(&id).and_then(|c| lod_at(c, f)) == Some(Lod::Full);
    input.options.shared_bytes = RenderFloor::of(crowd, shutter, w as u64 * h as u64, full)?.bytes();
    let mut manifest = build_manifest(&input)?;
    manifest.made_from = Some(super::MadeFrom::of(crowd.shot())?);
    super::made_from::seal(&mut manifest);
    Ok(manifest)
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
