//! The casting-to-layers adapter: a [`LayerInput`] from a cast shot (positions
//! from the cache, heights and per-agent memory from casting), the overrides a
//! caller puts over the shot's `[layers]` table, and the set bounds the layer
//! map draws.

use std::collections::HashMap;

use glam::Vec3;

use super::{
    build_manifest, estimate_agent_memory, estimate_proxy_memory, shot_input, LayerOptions, Manifest, PartCost,
};
use crate::casting::ShotCrowd;
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
        parse_bytes(b).map_err(|m| Error::Usage(format!("--budget: {m}")))?;
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

/// Builds the layer manifest of a cast shot with `overrides` over the shot's `[layers]`.
pub fn build_layers(crowd: &ShotCrowd, overrides: &LayerOverrides) -> Result<Manifest> {
    let (settings, options) = settings_with_overrides(&crowd.shot.layers, overrides)?;
    let lib = crowd.library();
    // How many part instances share each mesh: shared geometry is split between its users.
    let mut users: HashMap<u32, u64> = HashMap::new();
    for parts in crowd.dressed.values() {
        for p in parts {
            *users.entry(p.mesh).or_default() += 1;
        }
    }
    // Skinned pieces: every pose of a piece is its own mesh and BLAS, shared
    // by the agents that wear it.
    let mut posed: HashMap<(&str, usize), (u64, u64)> = HashMap::new();
    for (&(ref rig, piece, _, _), &m) in &crowd.posed.meshes {
        let e = posed.entry((&**rig, piece)).or_default();
        e.0 += lib.meshes[m as usize].bytes() as u64;
        e.1 += lib.meshes[m as usize].triangle_count() as u64;
    }
    let mut piece_users: HashMap<(&str, usize), u64> = HashMap::new();
    for (id, pieces) in &crowd.skin_dressed {
        for p in pieces {
            *piece_users.entry((&*crowd.casting[id].rig, p.piece)).or_default() += 1;
        }
    }
    let all = crowd.shot_crowd()?;
    let cameras = match crowd.shot.keyed_camera(crowd.shot.frames.start as f32) {
        Some(_) => None,
        None => Some(crowd.shot.frames.iter().map(|f| crowd.camera(f)).collect::<Result<Vec<_>>>()?),
    };
    let input = shot_input(&crowd.shot, &all, cameras, settings, options, |id| {
        // Every agent of the shot's frames was cast; others never reach here.
        let Some(height) = crowd.agent_height(id) else { return (1.8, 0, 0) };
        if let (Some(pieces), Some(cast)) = (crowd.skin_dressed.get(&id), crowd.casting.get(&id)) {
            let rig = &*cast.rig;
            let costs: Vec<PartCost> = pieces
                .iter()
                .map(|p| {
                    let (bytes, triangles) = posed.get(&(rig, p.piece)).copied().unwrap_or((0, 0));
                    PartCost {
                        mesh_bytes: bytes,
                        triangles,
                        users: piece_users.get(&(rig, p.piece)).copied().unwrap_or(1),
                    }
                })
                .collect();
            let boxes: usize = pieces
                .iter()
                .map(|p| crowd.skinned[rig].piece(p.piece).joint_boxes.iter().filter(|b| b.is_some()).count())
                .sum();
            return (height, estimate_agent_memory(&costs), estimate_proxy_memory(boxes));
        }
        let parts = crowd.dressed.get(&id).map(Vec::as_slice).unwrap_or(&[]);
        let costs: Vec<PartCost> = parts
            .iter()
            .map(|p| {
                let m = &lib.meshes[p.mesh as usize];
                PartCost {
                    mesh_bytes: m.bytes() as u64,
                    triangles: m.triangle_count() as u64,
                    users: users.get(&p.mesh).copied().unwrap_or(1),
                }
            })
            .collect();
        let proxies = parts.iter().filter(|p| p.proxy).count();
        (height, estimate_agent_memory(&costs), estimate_proxy_memory(proxies))
    })?;
    let mut manifest = build_manifest(&input)?;
    manifest.made_from = Some(super::MadeFrom::of(&crowd.shot)?);
    Ok(manifest)
}

/// World bounds of the set's instances, for the layer map.
pub fn set_bounds(crowd: &ShotCrowd) -> Option<(Vec3, Vec3)> {
    let lib = crowd.library();
    crowd
        .set
        .iter()
        .flat_map(|i| {
            let (lo, hi) = lib.meshes[i.mesh as usize].bounds();
            crate::scene::box_corners(lo, hi).map(|p| i.world_from_object.transform_point3(p))
        })
        .fold(None, |acc: Option<(Vec3, Vec3)>, p| Some(acc.map_or((p, p), |(lo, hi)| (lo.min(p), hi.max(p)))))
}
