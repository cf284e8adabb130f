//! The render-memory model: one estimate of the peak resident memory of a
//! `throng render` process rendering one layer of a shot (one farm task).
//! The layer budget (`layers --budget`, the manifest's `memory_bytes`) and
//! the farm plan (Slurm `--mem`) both read it, so each part is counted once:
//! the process, the loaded shot, the library and the BLASes one frame
//! traces, the traced instances, the film with its AOVs, passes, Cryptomatte
//! and EXR encoding, and, when the shot renders with a shutter, the shutter's poses,
//! deforming BLASes and motion records.
//!
//! Calibrated against the measured peak RSS of real renders (docs/benchmarks.md,
//! section One memory model; the `budget_bench` example measures them):
//! every constant is rounded up from what was measured, so an estimate errs
//! high, by little.

use std::collections::BTreeSet;
use std::sync::Arc;

use crate::casting::{AgentDress, AgentPose, Lod, ShotCrowd};
use crate::error::Result;
use crate::scene::passes::PassSet;

/// Bytes of a render process before it loads a shot: the binary's resident
/// pages, allocator arenas, the worker threads.
pub const PROCESS_BYTES: u64 = 17_000_000;
/// Bytes per agent of the shot that every render holds, in its layer or
/// not: its casting, dressing, the cache's records and the frame's sample.
pub const AGENT_LOADED_BYTES: u64 = 500;
/// Bytes per part (at full LOD) of every agent of the shot, in its layer or
/// not: its cast slot and dressed part.
pub const PART_LOADED_BYTES: u64 = 100;
/// Bytes per traced instance: its scene record, TLAS record and build
/// scratch, Cryptomatte ids.
pub const INSTANCE_BYTES: u64 = 380;
/// Extra bytes per traced instance with a shutter: its close key and
/// deformation, and the TLAS's motion bounds.
pub const MOTION_INSTANCE_BYTES: u64 = 280;
/// BLAS bytes per triangle: the 8-wide nodes, the precomputed triangle, the
/// index arrays, and the build's scratch.
pub const BLAS_BYTES_PER_TRIANGLE: u64 = 170;
/// Deforming-BLAS bytes per triangle (a skinned mesh blending between two
/// pose steps): both keys' vertices, nodes over their union, build scratch.
pub const DEFORM_BYTES_PER_TRIANGLE: u64 = 195;
/// Bytes per texel of the dome map (`[lights.dome]`): the loaded texels
/// (12, RGB f32), and as much again transiently: the file's decoded buffer
/// beside them while it loads, then (ACEScg) the render's copy of the
/// texels in the working colourspace, made once per job
/// (`render::colour::scene_lights_once`).
/// Measured on a 16384 x 8192 map (docs/lights.md, "Memory"): 22.7 bytes
/// per texel at load, 20.7 during the frame.
pub const DOME_BYTES_PER_TEXEL: u64 = 24;
/// Bytes per pixel of the image: the film and its AOVs, Cryptomatte ranks
/// of three types, tile results and the EXR channels being encoded.
pub const PIXEL_BYTES: u64 = 590;
/// Extra bytes per pixel with a shutter: the motion-vector AOV and its channels.
pub const MOTION_PIXEL_BYTES: u64 = 30;
/// Extra bytes per pixel per pass (a light-path pass, light group, `shadow`
/// or `P`, three channels): the tile result and the film's f32 triple, and
/// its three channels being encoded.
pub const PASS_PIXEL_BYTES: u64 = 32;

/// Extra bytes per pixel with deep output (render::deep): a pixel's count
/// and start (12), and [`DEEP_SAMPLES_PER_PIXEL`] deep samples of 32 bytes
/// held twice (the tiles' and the assembled image's).
pub const DEEP_PIXEL_BYTES: u64 = 12 + DEEP_SAMPLES_PER_PIXEL * 64;
/// Deep samples a pixel holds on average, rounded up from the demo's
/// layers (docs/benchmarks.md, "Deep output"). A pixel may hold up to
/// `render.deep.max_samples`; a layer whose pixels average more than this
/// needs more than the estimate.
pub const DEEP_SAMPLES_PER_PIXEL: u64 = 2;

/// What every layer render of a shot holds whatever its agents, as counts;
/// [`RenderFloor::bytes`] prices them.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct RenderFloor {
    /// Agents in the shot (every one is loaded, and posed, in every render).
    pub agents: u64,
    /// Parts of every agent at full LOD.
    pub agent_parts: u64,
    /// Geometry bytes of every mesh loaded (wardrobe parts, posed skins,
    /// set), the shutter's poses included when blurred.
    pub mesh_bytes: u64,
    /// Texel bytes of every texture loaded.
    pub texture_bytes: u64,
    /// Triangles of the meshes every render traces whatever its agents
    /// (rigid parts, proxy box and set). The skinned poses its agents play
    /// are the layer's own ([`AgentTraces`]).
    pub triangles: u64,
    /// Deforming-BLAS triangles every render traces (none: only skinned
    /// agents deform, and they are the layer's own).
    pub deform_triangles: u64,
    /// The set's instances.
    pub set_instances: u64,
    /// Texels of the dome map (0: no dome).
    pub dome_texels: u64,
    /// Pixels of the image.
    pub pixels: u64,
    /// Rendered with a shutter (motion blur).
    pub blurred: bool,
    /// Three-channel passes per pixel (the shot's `render.passes`, [`pass_count`]).
    pub passes: u64,
    /// Deep output (the shot's `render.deep`).
    pub deep: bool,
}

impl RenderFloor {
    /// The floor's bytes: process, loaded shot, library, the frame's BLASes,
    /// the set's instances and the film.
    pub fn bytes(&self) -> u64 {
        PROCESS_BYTES
            .saturating_add(self.agents.saturating_mul(AGENT_LOADED_BYTES))
            .saturating_add(self.agent_parts.saturating_mul(PART_LOADED_BYTES))
            .saturating_add(self.mesh_bytes)
            .saturating_add(self.texture_bytes)
            .saturating_add(blas_bytes(self.triangles, self.deform_triangles))
            .saturating_add(instance_bytes(self.set_instances, self.blurred))
            .saturating_add(self.dome_texels.saturating_mul(DOME_BYTES_PER_TEXEL))
            .saturating_add(film_bytes(self.pixels, self.film()))
    }

    /// What the film holds per pixel.
    pub fn film(&self) -> FilmChannels {
        FilmChannels { blurred: self.blurred, passes: self.passes, deep: self.deep }
    }

    /// The floor of `crowd` rendered with `shutter` (`None`: still frames)
    /// at `pixels`. The crowd may be posed for still frames only: a
    /// shutter's poses are counted from the steps it needs. `_full` (an
    /// agent's LOD at a frame) is no longer read: the skinned poses full
    /// agents trace are each layer's own ([`AgentTraces`]), not the floor's.
    pub fn of<C>(
        crowd: &ShotCrowd<C>,
        shutter: Option<[f32; 2]>,
        pixels: u64,
        _full: impl Fn(u32, i32) -> bool,
    ) -> Result<RenderFloor> {
        let lib = crowd.library();
        let skins = crowd.poses().skins();
        let tris = |m: u32| lib.meshes.get(m as usize).map_or(0, |m| m.triangle_count() as u64);
        // Rigid parts, proxy boxes and the set: traced whatever the frame.
        let mut fixed: BTreeSet<u32> = BTreeSet::new();
        fixed.insert(crowd.dressing().proxy_mesh());
        fixed.extend(crowd.set().iter().map(|i| i.mesh));
        let mut agent_parts = 0u64;
        for (id, dress) in crowd.dressing().iter() {
            if let AgentDress::Slots(parts) = dress {
                fixed.extend(parts.iter().map(|p| p.mesh));
            }
            agent_parts += crowd.instance_count(id, Lod::Full) as u64;
        }
        let fixed_tris: u64 = fixed.iter().map(|&m| tris(m)).sum();
        let mut mesh_bytes: u64 = lib.meshes.iter().map(|m| m.bytes() as u64).sum();
        // A shutter's steps not posed yet: every worn piece of its rig is posed at each.
        let traces = AgentTraces::of(crowd, shutter, 0, |_, _| Vec::new())?;
        let worn = crowd.dressing().worn_pieces(crowd.casting());
        let piece = |rig: &Arc<str>, p: usize| skins.first_mesh(rig, p).and_then(|m| lib.meshes.get(m as usize));
        for (rig, body, cycle, step) in &traces.shutter_poses {
            for &p in worn.get(rig).into_iter().flatten() {
                if skins.mesh(rig, p, *body, *cycle, *step).is_none() {
                    mesh_bytes += piece(rig, p).map_or(0, |m| m.bytes() as u64);
                }
            }
        }
        let (triangles, deform_triangles) = (fixed_tris, 0);
        Ok(RenderFloor {
            agents: crowd.casting().len() as u64,
            agent_parts,
            mesh_bytes,
            texture_bytes: lib.textures.iter().map(|t| t.texels.len() as u64 * 16).sum(),
            triangles,
            deform_triangles,
            set_instances: crowd.set().len() as u64,
            dome_texels: crowd.lights().dome.as_ref().map_or(0, |d| d.texels.len() as u64),
            pixels,
            blurred: shutter.is_some(),
            passes: pass_count(crowd)?,
            deep: crowd.shot().render.deep.is_some(),
        })
    }
}

/// The skinned poses renders trace, per render (a layer, or the set layer):
/// the BLAS triangles of the poses its agents at full LOD play, still and
/// deforming, at the shot frame where they cost the most (a render keeps
/// only the current frame's BLASes), and the shutter steps the library
/// poses.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct AgentTraces {
    /// Per render: (triangles, deforming triangles) at its dearest frame.
    pub per_render: Vec<(u64, u64)>,
    /// (rig, body, cycle, step) of every shutter key of the shot.
    pub shutter_poses: BTreeSet<(Arc<str>, u16, usize, u32)>,
}

impl AgentTraces {
    /// The poses each of `renders` renders traces, where `traced_full(agent
    /// id, shot frame)` lists the renders that trace that agent at full LOD
    /// at that frame (its own layer, and every other render when casters
    /// keep their LOD). One pass over the shot's frames for all renders.
    pub fn of<C>(
        crowd: &ShotCrowd<C>,
        shutter: Option<[f32; 2]>,
        renders: usize,
        traced_full: impl Fn(u32, i32) -> Vec<usize>,
    ) -> Result<AgentTraces> {
        let lib = crowd.library();
        let skins = crowd.poses().skins();
        // A skinned piece's poses share its topology: price them by any one.
        let piece_tris = |rig: &Arc<str>, p: usize| {
            skins.first_mesh(rig, p).and_then(|m| lib.meshes.get(m as usize)).map_or(0, |m| m.triangle_count() as u64)
        };
        let pieces_of = |id: u32| match crowd.dressing().get(id) {
            Some(AgentDress::Skinned(pieces)) => pieces.iter().map(|d| d.piece).collect(),
            _ => Vec::new(),
        };
        let mut out = AgentTraces { per_render: vec![(0, 0); renders], shutter_poses: BTreeSet::new() };
        if renders == 0 && shutter.is_none() {
            return Ok(out);
        }
        let shot = crowd.shot();
        // (rig, piece, body, cycle, step) traced, and deforming (.., open step, close step).
        type Traced = BTreeSet<(Arc<str>, usize, u16, usize, u32)>;
        type Deform = BTreeSet<(Arc<str>, usize, u16, usize, u32, u32)>;
        for f in shot.frames.iter() {
            let mut traced: Vec<Traced> = vec![Traced::new(); renders];
            let mut deform: Vec<Deform> = vec![Deform::new(); renders];
            match shutter {
                None => {
                    let Ok(block) = crowd.agents_at(f) else { continue };
                    for a in block.agents.iter().filter(|a| crowd.renders(a)) {
                        let Some(cast) = crowd.cast(a.id) else { continue };
                        if crowd.rigs().skinned(&cast.rig).is_none() {
                            continue;
                        }
                        let into = traced_full(a.id, f);
                        if into.is_empty() {
                            continue;
                        }
                        if let Ok(AgentPose::Skinned { body, cycle, step, .. }) = crowd.agent_pose(a) {
                            for p in pieces_of(a.id) {
                                for &r in &into {
                                    traced[r].insert((cast.rig.clone(), p, body, cycle, step));
                                }
                            }
                        }
                    }
                }
                Some(s) => {
                    let keys = crate::casting::steps::shutter_keys_at(
                        shot,
                        crowd.cache(),
                        crowd.casting(),
                        crowd.rigs(),
                        crowd.timing(),
                        f,
                        s,
                    )?;
                    for (id, (rig, body, cycle, k0), (_, _, _, k1)) in keys {
                        // Every step is posed (the library); only full agents trace theirs.
                        out.shutter_poses.insert((rig.clone(), body, cycle, k0));
                        out.shutter_poses.insert((rig.clone(), body, cycle, k1));
                        for r in traced_full(id, f) {
                            for p in pieces_of(id) {
                                traced[r].insert((rig.clone(), p, body, cycle, k0));
                                if k0 != k1 {
                                    deform[r].insert((rig.clone(), p, body, cycle, k0, k1));
                                }
                            }
                        }
                    }
                }
            }
            for (r, best) in out.per_render.iter_mut().enumerate() {
                let t = traced[r].iter().map(|(rig, p, ..)| piece_tris(rig, *p)).sum::<u64>();
                let d = deform[r].iter().map(|(rig, p, ..)| piece_tris(rig, *p)).sum::<u64>();
                if blas_bytes(t, d) > blas_bytes(best.0, best.1) {
                    *best = (t, d);
                }
            }
        }
        Ok(out)
    }
}

/// The three-channel passes a render of `crowd` writes per pixel with its
/// shot's `render.passes` ([`pass_count_of`]).
pub fn pass_count<C>(crowd: &ShotCrowd<C>) -> Result<u64> {
    let set = PassSet::parse(&crowd.shot().render.passes, "render.passes")?;
    pass_count_of(crowd, &set.in_air(crowd.shot().hazy()))
}

/// The three-channel passes a render of `crowd` writing `set` (the shot's
/// passes, or a job's own) holds per pixel: one per light group of its
/// lights and materials when `set` has the light groups.
pub fn pass_count_of<C>(crowd: &ShotCrowd<C>, set: &PassSet) -> Result<u64> {
    let groups = if set.light_groups { crowd.light_groups()?.names.len() } else { 0 };
    Ok(set.triples(groups) as u64)
}

/// What a film holds per pixel beyond its fixed AOVs.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct FilmChannels {
    /// Motion vectors (rendered with a shutter).
    pub blurred: bool,
    /// Three-channel passes.
    pub passes: u64,
    /// Deep output (render::deep): the deep samples and their counts.
    pub deep: bool,
}

/// BLAS bytes of `triangles` still and `deform_triangles` deforming triangles.
pub fn blas_bytes(triangles: u64, deform_triangles: u64) -> u64 {
    triangles
        .saturating_mul(BLAS_BYTES_PER_TRIANGLE)
        .saturating_add(deform_triangles.saturating_mul(DEFORM_BYTES_PER_TRIANGLE))
}

/// Bytes of `instances` traced instances (an agent's parts or proxy boxes,
/// or the set's), with motion records when `blurred`.
pub fn instance_bytes(instances: u64, blurred: bool) -> u64 {
    let each = if blurred { INSTANCE_BYTES + MOTION_INSTANCE_BYTES } else { INSTANCE_BYTES };
    instances.saturating_mul(each)
}

/// Bytes of the film of `pixels` pixels holding `channels`.
pub fn film_bytes(pixels: u64, channels: FilmChannels) -> u64 {
    let motion = if channels.blurred { MOTION_PIXEL_BYTES } else { 0 };
    let deep = if channels.deep { DEEP_PIXEL_BYTES } else { 0 };
    let each = PIXEL_BYTES + motion + deep + channels.passes.saturating_mul(PASS_PIXEL_BYTES);
    pixels.saturating_mul(each)
}

/// A layer render's estimate `bytes` made at `from` pixels, rendered at `to`
/// pixels instead (the farm plan's `--resolution`): only the film changes.
pub fn at_pixels(bytes: u64, from: u64, to: u64, channels: FilmChannels) -> u64 {
    bytes.saturating_sub(film_bytes(from, channels)).saturating_add(film_bytes(to, channels))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_floor_prices_each_part_once() {
        let f = RenderFloor {
            agents: 10,
            agent_parts: 40,
            mesh_bytes: 1_000,
            texture_bytes: 2_000,
            triangles: 100,
            deform_triangles: 50,
            set_instances: 3,
            dome_texels: 0,
            pixels: 64,
            blurred: false,
            passes: 0,
            deep: false,
        };
        let want = PROCESS_BYTES
            + 10 * AGENT_LOADED_BYTES
            + 40 * PART_LOADED_BYTES
            + 3_000
            + 100 * BLAS_BYTES_PER_TRIANGLE
            + 50 * DEFORM_BYTES_PER_TRIANGLE
            + 3 * INSTANCE_BYTES
            + 64 * PIXEL_BYTES;
        assert_eq!(f.bytes(), want);
        let b = RenderFloor { blurred: true, ..f };
        assert_eq!(b.bytes() - f.bytes(), 3 * MOTION_INSTANCE_BYTES + 64 * MOTION_PIXEL_BYTES);
        // Another image size moves only the film.
        let big = RenderFloor { pixels: 6400, ..f };
        assert_eq!(at_pixels(f.bytes(), 64, 6400, f.film()), big.bytes());
        assert_eq!(at_pixels(big.bytes(), 6400, 64, f.film()), f.bytes());
        // Each pass is three more channels on every pixel.
        let deep = RenderFloor { deep: true, ..f };
        assert_eq!(deep.bytes() - f.bytes(), 64 * DEEP_PIXEL_BYTES);
        let passes = RenderFloor { passes: 9, ..f };
        assert_eq!(passes.bytes() - f.bytes(), 64 * 9 * PASS_PIXEL_BYTES);
        assert_eq!(at_pixels(passes.bytes(), 64, 6400, passes.film()), RenderFloor { pixels: 6400, ..passes }.bytes());
        // A dome: its texels and their transient copy, whatever the image.
        let dome = RenderFloor { dome_texels: 16384 * 8192, ..f };
        assert_eq!(dome.bytes() - f.bytes(), 16384 * 8192 * DOME_BYTES_PER_TEXEL);
    }
}
