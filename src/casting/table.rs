//! The casting table and its instancing figures: what `throng cast` prints,
//! botinfo's part rows, and the demo's summary.

use std::collections::{BTreeMap, BTreeSet};
use std::fmt::Write as _;

use serde::Serialize;

use super::skin::SkinPiece;
use super::wardrobe::PropAt;
use super::{AgentCast, AgentDress, ShotCrowd};

/// One part row of the casting table.
#[derive(Debug, Clone, Serialize)]
pub(crate) struct PartRow {
    /// Rig slot.
    pub(crate) slot: String,
    /// Mesh name, or null for an empty slot.
    pub(crate) mesh: Option<String>,
    /// glTF file of the mesh.
    pub(crate) file: Option<String>,
    /// Material name.
    pub(crate) material: Option<String>,
}

/// One prop an agent carries.
#[derive(Debug, Clone, Serialize)]
pub(crate) struct PropRow {
    /// The prop's name (its Cryptomatte part `agent_<id>/<name>`).
    pub(crate) name: String,
    /// What it hangs on: `joint <name>` or `slot <name>`.
    pub(crate) on: String,
    /// Mesh name.
    pub(crate) mesh: String,
    /// glTF file of the mesh.
    pub(crate) file: String,
    /// Material name.
    pub(crate) material: Option<String>,
}

/// One agent of the casting table.
#[derive(Debug, Serialize)]
pub struct CastRow {
    /// Cache id.
    pub(crate) id: u32,
    /// Rig.
    pub(crate) rig: String,
    /// Scheme.
    pub(crate) scheme: String,
    /// Height scale.
    pub(crate) height_scale: f32,
    /// Whether the height jitter applies.
    pub(crate) scaled: bool,
    /// Parts per slot.
    pub(crate) parts: Vec<PartRow>,
    /// The props it carries (none drawn: empty).
    pub(crate) props: Vec<PropRow>,
}

/// Instancing figures for `throng cast --stats`.
#[derive(Debug, Serialize)]
pub struct CastStats {
    /// Agents cast.
    pub agents: usize,
    /// Part instances (agents x filled slots).
    pub part_instances: usize,
    /// Unique part meshes.
    pub unique_parts: usize,
    /// Unique materials.
    pub unique_materials: usize,
    /// Bytes of unique slot part geometry (skinned and rigid agents' posed
    /// meshes are [`SkinStats`]'s: they cover every pose of the shot's
    /// frames, so they do not compare with one copy per agent).
    pub unique_geometry_bytes: usize,
    /// Bytes if every slot agent had its own copy of its parts.
    pub copied_geometry_bytes: usize,
    /// Skinned agents and their pose instancing, when the shot has any.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub skinned: Option<SkinStats>,
}

/// Pose instancing figures of a shot's agents posed from node animation:
/// skinned and rigid rigs, which share the pose machinery.
#[derive(Debug, Serialize)]
pub struct SkinStats {
    /// Agents on skinned or rigid rigs.
    pub agents: usize,
    /// Of them, agents on rigid rigs (meshes riding their nodes).
    pub rigid_agents: usize,
    /// Unique poses taken in the shot's frames: (rig, cycle, pose step).
    pub unique_poses: usize,
    /// Posed meshes built (one per piece per pose), each with one BLAS.
    pub posed_meshes: usize,
    /// Bytes of all posed geometry, held once for every frame and layer.
    pub(crate) posed_geometry_bytes: usize,
    /// Bytes of one posed copy per skinned agent: what one frame costs
    /// without pose sharing.
    pub(crate) posed_per_agent_bytes: usize,
    /// Largest pose error, metres, over the clips below.
    pub worst_quantisation_error_m: f32,
    /// Per clip played: its pose step and measured error.
    pub clips: Vec<ClipPoseStats>,
    /// Per rig with body proportions: its bodies and how many agents play each.
    pub bodies: Vec<RigBodies>,
}

/// The bodies of one rig with proportions (docs/wardrobes.md, "Body proportions").
#[derive(Debug, Serialize)]
pub struct RigBodies {
    /// Rig.
    pub rig: String,
    /// Agents per body: index 0 is the modelled body (seated and no-scale agents).
    pub agents: Vec<usize>,
    /// Stride factor of each body (the `legs` group's length), index 0 the modelled body's 1.
    pub strides: Vec<f32>,
}

/// The pose step of one clip of a skinned rig and the error it costs.
#[derive(Debug, Serialize)]
pub struct ClipPoseStats {
    /// Rig.
    pub rig: String,
    /// The clip.
    pub clip: String,
    /// Cache cycles that play it.
    pub cycles: Vec<String>,
    /// Clip length in shot frames.
    pub frames: f32,
    /// Steps the clip is cut into (`steps + 1` poses).
    pub steps: u32,
    /// Frames per step.
    pub step_frames: f32,
    /// Whether the step was chosen for `pose_error_max` (else the shot's `pose_step`).
    pub chosen: bool,
    /// Largest vertex error, metres, on the rig's tallest agent, between the
    /// exact pose and the snapped step or the blend of the steps around it,
    /// over the pieces the shot poses on this clip.
    pub error_m: f32,
    /// The shot's `pose_error_max`, metres.
    pub bound_m: f32,
}

/// One agent's row: its scheme, height, and part and material per slot.
pub fn cast_row(crowd: &ShotCrowd, c: &AgentCast) -> CastRow {
    let lib = crowd.library();
    let parts = c
        .slots
        .iter()
        .enumerate()
        .map(|(i, s)| {
            let material = crowd.dressing().get(c.id).and_then(|d| d.material_in_slot(i));
            PartRow {
                slot: s.slot.to_string(),
                mesh: s.part.as_ref().map(|p| p.mesh.to_string()),
                file: s.part.as_ref().map(|p| p.file.display().to_string()),
                material: material.map(|m| lib.materials[m as usize].name.clone()),
            }
        })
        .collect();
    let props = (c.props.iter().enumerate())
        .map(|(i, p)| {
            let material = crowd.dressing().get(c.id).and_then(|d| d.material_in_slot(c.slots.len() + i));
            PropRow {
                name: p.name.to_string(),
                on: match &p.at {
                    PropAt::Joint(j) => format!("joint {j}"),
                    PropAt::Slot(s) => format!("slot {s}"),
                },
                mesh: p.mesh.to_string(),
                file: p.file.display().to_string(),
                material: material.map(|m| lib.materials[m as usize].name.clone()),
            }
        })
        .collect();
    CastRow {
        id: c.id,
        rig: c.rig.to_string(),
        scheme: c.scheme.to_string(),
        height_scale: c.height_scale,
        scaled: c.scaled,
        parts,
        props,
    }
}

/// Instancing figures for the whole cast.
pub fn cast_stats(crowd: &ShotCrowd) -> CastStats {
    let lib = crowd.library();
    let mut meshes = BTreeSet::new();
    let mut materials = BTreeSet::new();
    let mut copied = 0;
    let mut instances = 0;
    for (_, dress) in crowd.dressing().iter() {
        match dress {
            AgentDress::Slots(parts) => {
                for p in parts {
                    meshes.insert(p.mesh);
                    materials.insert(p.material);
                    copied += lib.meshes[p.mesh as usize].bytes();
                    instances += 1;
                }
            }
            AgentDress::Skinned(pieces) => {
                materials.extend(pieces.iter().map(|p| p.material));
                instances += pieces.len();
            }
        }
    }
    CastStats {
        skinned: skin_stats(crowd),
        agents: crowd.casting().len(),
        part_instances: instances,
        unique_parts: meshes.len(),
        unique_materials: materials.len(),
        unique_geometry_bytes: meshes.iter().map(|&m| lib.meshes[m as usize].bytes()).sum(),
        copied_geometry_bytes: copied,
    }
}

/// Pose instancing figures, `None` without skinned or rigid agents.
fn skin_stats(crowd: &ShotCrowd) -> Option<SkinStats> {
    let skinned: Vec<(u32, &[crate::casting::SkinDress])> = (crowd.dressing().iter())
        .filter_map(|(id, d)| match d {
            AgentDress::Skinned(pieces) => Some((id, pieces.as_slice())),
            AgentDress::Slots(_) => None,
        })
        .collect();
    if skinned.is_empty() {
        return None;
    }
    let lib = crowd.library();
    let skins = crowd.poses().skins();
    let posed_bytes =
        |rig: &str, piece: usize| skins.first_mesh(rig, piece).map_or(0, |m| lib.meshes[m as usize].bytes());
    let mut per_agent = 0;
    let mut used: BTreeMap<(String, usize), BTreeSet<usize>> = BTreeMap::new();
    for ((rig, piece, _, cycle, _), _) in skins.meshes() {
        used.entry((rig.to_string(), *cycle)).or_default().insert(*piece);
    }
    for &(id, parts) in &skinned {
        let Some(cast) = crowd.cast(id) else { continue };
        per_agent += parts.iter().map(|p| posed_bytes(&cast.rig, p.piece)).sum::<usize>();
    }
    let clips: Vec<ClipPoseStats> = used
        .iter()
        .filter_map(|((name, cycle), pieces)| {
            let rig = crowd.rigs().skinned(name)?;
            let c = &rig.cycles()[*cycle];
            let pieces: Vec<&SkinPiece> = pieces.iter().map(|&p| crowd.dressing().piece(name, rig, p)).collect();
            Some(ClipPoseStats {
                rig: name.clone(),
                clip: c.clip_name.clone(),
                cycles: rig.cycles().iter().filter(|o| o.clip == c.clip).map(|o| o.name.clone()).collect(),
                frames: rig.cycle_frames(*cycle),
                steps: c.steps,
                step_frames: rig.cycle_frames(*cycle) / c.steps as f32,
                chosen: c.chosen,
                error_m: rig.pose_error(&pieces, *cycle),
                bound_m: rig.pose_error_max(),
            })
        })
        .collect();
    let worst = clips.iter().map(|c| c.error_m).fold(0.0f32, f32::max);
    let rigid_agents = (skinned.iter())
        .filter(|(id, _)| crowd.cast(*id).and_then(|c| crowd.rigs().skinned(&c.rig)).is_some_and(|r| r.is_rigid()))
        .count();
    let bodies = (crowd.rigs().iter())
        .filter_map(|(name, r)| Some((name, r.skinned().filter(|s| s.body_count() > 0)?)))
        .map(|(name, rig)| {
            let mut agents = vec![0; rig.body_count() as usize + 1];
            for c in crowd.casting().iter().filter(|c| &*c.rig == name) {
                if let Some(n) = agents.get_mut(c.body as usize) {
                    *n += 1;
                }
            }
            let strides = (0..=rig.body_count()).map(|b| rig.body_stride(b)).collect();
            RigBodies { rig: name.to_string(), agents, strides }
        })
        .collect();
    Some(SkinStats {
        agents: skinned.len(),
        rigid_agents,
        unique_poses: skins.step_count(),
        posed_meshes: skins.mesh_count(),
        posed_geometry_bytes: skins.meshes().map(|(_, m)| lib.meshes[m as usize].bytes()).sum(),
        posed_per_agent_bytes: per_agent,
        worst_quantisation_error_m: worst,
        clips,
        bodies,
    })
}

/// Bytes as MiB with two decimals.
pub fn mib(b: usize) -> String {
    format!("{:.2} MiB", b as f64 / (1024.0 * 1024.0))
}

/// Human-readable instancing figures.
pub fn format_stats(s: &CastStats) -> String {
    let mut o = String::new();
    let _ = writeln!(o, "agents               {}", s.agents);
    let _ = writeln!(o, "part instances       {}", s.part_instances);
    let _ = writeln!(o, "unique parts         {}", s.unique_parts);
    let _ = writeln!(o, "unique materials     {}", s.unique_materials);
    // Slot parts only: skinned and rigid agents' posed geometry has lines of its own below.
    let posed = if s.skinned.is_some() { "; posed geometry below" } else { "" };
    let _ = writeln!(o, "unique geometry      {}  (slot parts{posed})", mib(s.unique_geometry_bytes));
    if s.unique_geometry_bytes > 0 {
        let ratio = s.copied_geometry_bytes as f64 / s.unique_geometry_bytes as f64;
        let _ = writeln!(o, "if copied per agent  {}  ({ratio:.0}x more)", mib(s.copied_geometry_bytes));
    }
    if let Some(k) = &s.skinned {
        let _ = writeln!(o, "skinned agents       {}", k.agents - k.rigid_agents);
        if k.rigid_agents > 0 {
            let _ = writeln!(o, "rigid agents         {}", k.rigid_agents);
        }
        for b in &k.bodies {
            let counts: Vec<String> = b.agents.iter().skip(1).map(usize::to_string).collect();
            let (lo, hi) = b.strides[1..].iter().fold((f32::INFINITY, 0.0f32), |(l, h), &s| (l.min(s), h.max(s)));
            let _ = writeln!(
                o,
                "bodies               {} {}: agents {} (+{} as modelled), strides x{lo:.3}-{hi:.3}",
                b.rig,
                b.agents.len() - 1,
                counts.join("/"),
                b.agents[0]
            );
        }
        let _ =
            writeln!(o, "unique poses         {}  ({} posed meshes, one BLAS each)", k.unique_poses, k.posed_meshes);
        let _ = writeln!(o, "posed geometry       {}", mib(k.posed_geometry_bytes));
        let _ = writeln!(o, "one copy per agent   {}  per frame, without pose sharing", mib(k.posed_per_agent_bytes));
        let _ =
            writeln!(o, "worst pose error     {:.2} mm  (on the tallest agent)", k.worst_quantisation_error_m * 1000.0);
        for c in &k.clips {
            let _ = writeln!(
                o,
                "  {} {} ({}): {:.1} frames in {} steps of {:.3} frames ({}), error {:.2} mm of {:.2} mm{}",
                c.rig,
                c.clip,
                c.cycles.join(", "),
                c.frames,
                c.steps,
                c.step_frames,
                if c.chosen { "chosen" } else { "pose_step" },
                c.error_m * 1000.0,
                c.bound_m * 1000.0,
                if c.error_m > c.bound_m { "  ABOVE pose_error_max" } else { "" }
            );
        }
    }
    o
}
