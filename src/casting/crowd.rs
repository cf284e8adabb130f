//! Posing: the shot loaded and cast, ready to give any frame's instances.
//!
//! A slot-rig agent's part transform at a frame is
//! `world_from_agent (position, heading, height scale about the foot pivot)
//!  x rig_from_slot (the rig node at that cycle frame)
//!  x slot_from_part (the part's fit to its proxy box)`.
//! A skinned agent is `world_from_agent x` its meshes posed at the pose step
//! nearest its cycle frame (`casting::skin`); every pose any agent takes in
//! the shot's frames is posed once, at load, and shared by every agent,
//! frame and layer on it.
//! Meshes and materials are loaded once into the shared [`AssetCache`]; every
//! instance references them by id.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::Path;
use std::sync::Arc;

use rayon::prelude::*;

use glam::{Affine3A, Quat, Vec3};

use crate::cache::{AgentSample, CacheReader, FrameBlock};
use crate::casting::rig::Rig;
use crate::casting::skin::{is_skinned_rig, skinned_refusal, SkinnedRig};
use crate::casting::wardrobe::{Wardrobes, GLTF_MATERIAL};
use crate::casting::{cast_agent, cast_delivered, fit_part, AgentCast, CastPart, RigCasting, SlotCast};
use crate::error::{Error, Result};
use crate::scene::gltf::AssetCache;
use crate::scene::{vis, Camera, Instance, InstanceAgent, Library, Material, MaterialId, Mesh, MeshId};
use crate::shot::{RigKind, Shot};

/// Level of detail an agent renders at.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Lod {
    /// Real wardrobe parts.
    Full,
    /// The rig's proxy boxes, wearing the same materials as the full agent.
    Proxy,
}

/// One resolved part of a cast agent: geometry and material ids plus which
/// shared fit places it in its slot. 20 bytes: a million agents keep eleven each.
#[derive(Debug, Clone, Copy)]
pub struct DressedPart {
    /// Index into the rig's slots.
    pub slot: u32,
    /// The part mesh.
    pub mesh: MeshId,
    /// The part's material.
    pub material: MaterialId,
    /// Index into [`ShotCrowd::fits`]: fits depend only on (rig, slot, mesh).
    pub fit: u32,
    /// Whether this piece stands for its slot at proxy LOD (one per slot,
    /// wearing the part's first material).
    pub proxy: bool,
}

/// How a part mesh and the proxy cube sit in a slot.
#[derive(Debug, Clone, Copy)]
pub struct PartFit {
    /// Fit of the part mesh to the slot's proxy box.
    pub slot_from_part: Affine3A,
    /// The unit proxy cube mapped onto the slot's proxy box.
    pub slot_from_proxy: Affine3A,
}

/// One skinned piece a skinned agent wears.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SkinDress {
    /// Index into the agent's cast slots.
    pub slot: usize,
    /// Index into the rig's pieces ([`SkinnedRig::piece`]).
    pub piece: usize,
    /// The piece's material.
    pub material: MaterialId,
}

/// A pose every agent on it shares: (rig, cycle index, pose step).
pub type PoseKey = (Arc<str>, usize, u32);

/// Posed geometry of skinned agents, one entry per pose used in the shot.
#[derive(Debug, Default)]
pub struct PosedSkins {
    /// (rig, piece, cycle, step) -> the posed mesh.
    pub meshes: BTreeMap<(Arc<str>, usize, usize, u32), MeshId>,
    /// `rig_from_node` of every rig node at each pose (for proxy boxes).
    pub joints: BTreeMap<PoseKey, Vec<Affine3A>>,
}

/// An agent posed at one frame.
#[derive(Debug, Clone)]
pub enum AgentPose {
    /// A slot rig: `world_from_slot` for every rig slot.
    Slots(Vec<Affine3A>),
    /// A skinned character: where it stands and the pose step it plays.
    Skinned {
        /// World from rig space (position, heading, height scale).
        world_from_rig: Affine3A,
        /// Cycle index in the skinned rig.
        cycle: usize,
        /// Pose step of that cycle.
        step: u32,
    },
}

/// A memo key made of the addresses of shared (`Arc`) names: (rig, file,
/// mesh, material). The wardrobes and rigs keep them alive for the whole
/// load, so equal addresses are the same part.
type SharedKey = (usize, usize, usize, usize);

/// The shot, its wardrobes, rigs, cache and casting, loaded once.
pub struct ShotCrowd {
    /// The shot.
    pub shot: Shot,
    /// Its wardrobes.
    pub wardrobes: Wardrobes,
    /// Slot rigs by name.
    pub rigs: BTreeMap<String, Rig>,
    /// Skinned characters by rig name.
    pub skinned: BTreeMap<String, SkinnedRig>,
    /// The simulation cache.
    pub cache: CacheReader,
    /// Every agent that appears in the shot's frames, by id.
    pub casting: BTreeMap<u32, AgentCast>,
    /// Shared meshes and materials.
    pub assets: AssetCache,
    /// Resolved parts per slot-rig agent.
    pub dressed: BTreeMap<u32, Vec<DressedPart>>,
    /// The part fits that [`DressedPart::fit`] indexes.
    pub fits: Vec<PartFit>,
    /// Skinned pieces per skinned agent.
    pub skin_dressed: BTreeMap<u32, Vec<SkinDress>>,
    /// Every pose skinned agents take in the shot's frames.
    pub posed: PosedSkins,
    /// The unit cube used for proxy boxes.
    pub proxy_mesh: MeshId,
    /// The set's instances (agent `None`), fully visible; each one's `part`
    /// indexes [`ShotCrowd::set_names`].
    pub set: Vec<Instance>,
    /// Unique names of the set's objects (its glTF nodes with a mesh, by
    /// [`crate::scene::gltf::set_object_names`]): Cryptomatte's `set/<name>`.
    /// At most [`SET_OBJECTS_NAMED`]; later objects are plain `set`.
    pub set_names: Vec<String>,
    /// What loading noticed but accepted (weights renormalised, morph targets ignored).
    pub warnings: Vec<String>,
    /// The camera from a glTF node, when the shot names one instead of keys.
    gltf_camera: Option<Camera>,
    /// Standing height of each rig, metres.
    rig_heights: BTreeMap<String, f32>,
}

/// Set objects with their own Cryptomatte name: every [`Instance::part`]
/// value but `u16::MAX` (which marks the unnamed rest).
pub const SET_OBJECTS_NAMED: usize = u16::MAX as usize;

/// Unit cube [0,1]^3 with flat normals: the proxy box of every slot.
fn unit_cube() -> Mesh {
    let mut m = Mesh { name: "throng/proxy_box".into(), ..Default::default() };
    let faces: [(Vec3, Vec3, Vec3); 6] = [
        (Vec3::X, Vec3::Y, Vec3::Z),
        (Vec3::NEG_X, Vec3::Z, Vec3::Y),
        (Vec3::Y, Vec3::Z, Vec3::X),
        (Vec3::NEG_Y, Vec3::X, Vec3::Z),
        (Vec3::Z, Vec3::X, Vec3::Y),
        (Vec3::NEG_Z, Vec3::Y, Vec3::X),
    ];
    for (n, u, v) in faces {
        let base = m.positions.len() as u32;
        let centre = Vec3::splat(0.5) + n * 0.5;
        for (a, b) in [(-0.5, -0.5), (0.5, -0.5), (0.5, 0.5), (-0.5, 0.5)] {
            m.positions.push(centre + u * a + v * b);
            m.normals.push(n);
            m.uvs.push(glam::Vec2::new(a + 0.5, b + 0.5));
        }
        m.indices.extend([base, base + 1, base + 2, base, base + 2, base + 3]);
    }
    m
}

/// The library material for a wardrobe material, made once per name.
fn wardrobe_material(
    assets: &mut AssetCache,
    made: &mut HashMap<String, MaterialId>,
    wardrobes: &Wardrobes,
    name: &str,
) -> Result<MaterialId> {
    if let Some(&m) = made.get(name) {
        return Ok(m);
    }
    let spec = &wardrobes.materials[name];
    let texture = match &spec.base_color_texture {
        Some(t) => Some(assets.texture_png(t)?),
        None => None,
    };
    let m = assets.add_material(Material {
        name: name.to_string(),
        base_color: Vec3::from(spec.base_color),
        base_color_texture: texture,
        roughness: spec.roughness,
        metallic: spec.metallic,
    });
    made.insert(name.to_string(), m);
    Ok(m)
}

impl ShotCrowd {
    /// Loads the shot and everything it names, and casts every agent that
    /// appears in the shot's frame range.
    pub fn load(shot_path: &Path) -> Result<ShotCrowd> {
        let shot = Shot::load(shot_path)?;
        let cache = crate::casting::shot_cache::open(&shot)?;
        ShotCrowd::new(shot, cache)
    }

    /// Casts a shot against an already opened cache (tests use this to
    /// remove or reorder agents without writing files).
    pub fn new(shot: Shot, cache: CacheReader) -> Result<ShotCrowd> {
        let wardrobes = Wardrobes::load(&shot.wardrobes)?;
        let mut rigs = BTreeMap::new();
        let mut skinned = BTreeMap::new();
        for (name, r) in &shot.rigs {
            let kind = if is_skinned_rig(r)? { RigKind::Skinned } else { RigKind::Slots };
            match kind {
                RigKind::Slots => {
                    rigs.insert(name.clone(), Rig::load(&r.file).map_err(|e| e.or_field(format!("rigs.{name}.file")))?);
                }
                RigKind::Skinned => {
                    let rig = SkinnedRig::load(&r.file, &r.skin, shot.frames.fps)
                        .map_err(|e| e.field_prefix(&format!("rigs.{name}")).or_field(format!("rigs.{name}.file")))?;
                    skinned.insert(name.clone(), rig);
                }
            }
            let slots: Vec<&str> = match (rigs.get(name), skinned.get(name)) {
                (Some(rig), _) => rig.slots().iter().map(|s| s.name.as_str()).collect(),
                (None, Some(rig)) => rig.slots().iter().map(String::as_str).collect(),
                (None, None) => Vec::new(),
            };
            wardrobes.check_slots(name, &r.schemes, &slots)?;
        }

        // First pass over the shot's frames: each agent's rig (at its first
        // appearance), whether it is ever seated or on a no-scale cycle, and
        // the poses skinned agents take.
        struct Seen {
            rig: u16,
            never_scale: bool,
        }
        let mut seen: BTreeMap<u32, Seen> = BTreeMap::new();
        // Poses by (rig, cycle, step): bounded by the rigs' cycles and steps, whatever the agent count.
        let mut skin_poses: BTreeSet<(String, usize, u32)> = BTreeSet::new();
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
                let missing = match (rigs.get(rig_name), skinned.get(rig_name)) {
                    (Some(rig), _) => rig.cycle(cycle).err(),
                    (None, Some(rig)) => match rig.cycle_index(cycle) {
                        Ok(c) => {
                            if !a.hidden() {
                                skin_poses.insert((rig_name.to_string(), c, rig.step_of(c, a.cycle_frame)));
                            }
                            None
                        }
                        Err(e) => Some(e),
                    },
                    (None, None) => None,
                };
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
        let mut warnings = crate::casting::check_outside_cache(&shot, cache.frames(), cache.path(), &outside)?;
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

        let mut assets = AssetCache::new();
        let proxy_mesh = assets.add_mesh(unit_cube());
        let mut casting = BTreeMap::new();
        let mut dressed = BTreeMap::new();
        let mut skin_dressed = BTreeMap::new();
        // Fits depend only on (rig, slot, mesh): compute each once.
        let mut fits: HashMap<(usize, usize, MeshId), u32> = HashMap::new();
        let mut fit_list: Vec<PartFit> = Vec::new();
        let mut materials: HashMap<String, MaterialId> = HashMap::new();
        // Each wardrobe part (and material) resolved to its (mesh, material) pieces once.
        let mut resolved: HashMap<SharedKey, Vec<(MeshId, MaterialId)>> = HashMap::new();
        // Rig and slot names shared (Arc) by every agent cast on the rig.
        let rig_names: HashMap<String, (Arc<str>, Vec<Arc<str>>)> = (rigs.iter())
            .map(|(name, rig)| (name.clone(), rig.slots().iter().map(|s| s.name.as_str().into()).collect()))
            .chain(
                skinned
                    .iter()
                    .map(|(name, rig)| (name.clone(), rig.slots().iter().map(|s| s.as_str().into()).collect())),
            )
            .map(|(name, slots)| {
                let shared: Arc<str> = name.as_str().into();
                (name, (shared, slots))
            })
            .collect();
        // Skinned rigs without schemes: the character as delivered, in its
        // own materials; the slot list is made once per rig and shared.
        let delivered: HashMap<String, Vec<SlotCast>> = (skinned.iter())
            .filter(|(name, _)| shot.rigs.get(*name).is_some_and(|r| r.schemes.is_empty()))
            .map(|(name, rig)| {
                let rig_file: Arc<std::path::Path> = rig.path().into();
                let parts = (rig.delivered().iter())
                    .map(|(slot, mesh, _)| SlotCast {
                        slot: slot.as_str().into(),
                        part: Some(Arc::new(CastPart {
                            file: rig_file.clone(),
                            mesh: mesh.as_str().into(),
                            material: GLTF_MATERIAL.into(),
                            uniform: false,
                        })),
                    })
                    .collect();
                (name.clone(), parts)
            })
            .collect();
        // Casting is a pure function of (seed, agent): cast every agent in
        // parallel, in id order, then dress them in that order below (so
        // the first error and every memo are as if cast one by one).
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
                    };
                    Some(match delivered.get(rig_name) {
                        Some(parts) => Ok(cast_delivered(shot.seed, id, &rc, parts.clone(), s.never_scale)),
                        None => cast_agent(shot.seed, id, &rc, &wardrobes, &shot.exclude_parts, s.never_scale).map_err(
                            |msg| Error::invalid(&shot.path, msg).agent(id).field(format!("rigs.{rig_name}.schemes")),
                        ),
                    })
                })
                .collect();
        drop(seen_list);
        let mut skin_resolved: HashMap<SharedKey, Vec<(usize, MaterialId)>> = HashMap::new();
        for ((&id, s), cast) in seen.iter().zip(casts) {
            let Some(cast) = cast else { continue };
            let cast = cast?;
            let rig_name = cache_rigs.get(s.rig as usize).map_or("", String::as_str);
            let Some((shared_name, _)) = rig_names.get(rig_name) else { continue };

            if let Some(rig) = skinned.get_mut(rig_name) {
                let mut pieces = Vec::new();
                for (slot_index, slot_cast) in cast.slots.iter().enumerate() {
                    let Some(part) = &slot_cast.part else { continue };
                    // Resolved once per (rig, part, material): rig part lookups
                    // and glTF materials touch the file system.
                    let key = (
                        Arc::as_ptr(shared_name) as *const u8 as usize,
                        Arc::as_ptr(&part.file) as *const u8 as usize,
                        Arc::as_ptr(&part.mesh) as *const u8 as usize,
                        Arc::as_ptr(&part.material) as *const u8 as usize,
                    );
                    if let std::collections::hash_map::Entry::Vacant(slot) = skin_resolved.entry(key) {
                        let part_index = rig.part(&part.file, &part.mesh).map_err(|e| e.agent(id))?;
                        let mut list = Vec::new();
                        for &piece in &rig.part_at(part_index).pieces.clone() {
                            let material = if *part.material == *GLTF_MATERIAL {
                                let p = rig.piece(piece);
                                assets.gltf_material_at(&p.file, p.material)?
                            } else {
                                wardrobe_material(&mut assets, &mut materials, &wardrobes, &part.material)?
                            };
                            list.push((piece, material));
                        }
                        slot.insert(list);
                    }
                    for &(piece, material) in &skin_resolved[&key] {
                        pieces.push(SkinDress { slot: slot_index, piece, material });
                    }
                }
                pieces.shrink_to_fit();
                skin_dressed.insert(id, pieces);
                casting.insert(id, cast);
                continue;
            }

            let Some(rig) = rigs.get(rig_name) else { continue };
            // A part's mesh missing from its glTF: say which scheme asked for it.
            let part_err = |e: Error, scheme: &str| e.agent(id).or_field(format!("schemes.{scheme}.parts"));
            let mut parts = Vec::new();
            for (slot_index, slot_cast) in cast.slots.iter().enumerate() {
                let Some(part) = &slot_cast.part else { continue };
                // Resolved once per wardrobe part and material (keyed by the
                // wardrobe's shared strings, so a lookup hashes three words,
                // not a path): whether it is skinned, and its (mesh, material) pieces.
                let key = (
                    0,
                    Arc::as_ptr(&part.file) as *const u8 as usize,
                    Arc::as_ptr(&part.mesh) as *const u8 as usize,
                    Arc::as_ptr(&part.material) as *const u8 as usize,
                );
                let pieces = match resolved.get(&key) {
                    Some(p) => p,
                    None => {
                        if assets.is_skinned_mesh(&part.file, &part.mesh).map_err(|e| part_err(e, &cast.scheme))? {
                            return Err(skinned_refusal(
                                &part.file,
                                &format!("wardrobe part `{}` (slot `{}`)", part.mesh, slot_cast.slot),
                            )
                            .agent(id)
                            .field(format!("schemes.{}.parts", cast.scheme)));
                        }
                        // A part wearing its own glTF materials keeps one piece per
                        // primitive (a multi-material mesh); otherwise one mesh, one material.
                        let pieces: Vec<(MeshId, MaterialId)> = if *part.material == *GLTF_MATERIAL {
                            assets.mesh_primitives(&part.file, &part.mesh).map_err(|e| part_err(e, &cast.scheme))?
                        } else {
                            let mesh = assets.mesh(&part.file, &part.mesh).map_err(|e| part_err(e, &cast.scheme))?;
                            vec![(mesh, wardrobe_material(&mut assets, &mut materials, &wardrobes, &part.material)?)]
                        };
                        resolved.entry(key).or_insert(pieces)
                    }
                };
                let Some(&(first_mesh, _)) = pieces.first() else { continue };
                let slot = &rig.slots()[slot_index];
                let fit = *fits
                    .entry((Arc::as_ptr(shared_name) as *const u8 as usize, slot_index, first_mesh))
                    .or_insert_with(|| {
                        // Fit the whole part (all its pieces) to the box.
                        let lib = assets.library();
                        let (lo, hi) = pieces
                            .iter()
                            .map(|&(m, _)| lib.meshes[m as usize].bounds())
                            .reduce(|(a, b), (c, d)| (a.min(c), b.max(d)))
                            .unwrap_or((Vec3::ZERO, Vec3::ZERO));
                        let size = (slot.proxy_max - slot.proxy_min).max(Vec3::splat(1e-4));
                        fit_list.push(PartFit {
                            slot_from_part: fit_part(lo, hi, slot.proxy_min, slot.proxy_max, part.uniform),
                            slot_from_proxy: Affine3A::from_scale_rotation_translation(
                                size,
                                Quat::IDENTITY,
                                slot.proxy_min,
                            ),
                        });
                        fit_list.len() as u32 - 1
                    });
                for (i, &(mesh, material)) in pieces.iter().enumerate() {
                    parts.push(DressedPart { slot: slot_index as u32, mesh, material, fit, proxy: i == 0 });
                }
            }
            parts.shrink_to_fit();
            dressed.insert(id, parts);
            casting.insert(id, cast);
        }

        // Pose every piece worn on a rig at every (cycle, step) an agent of
        // that rig takes, once, in a fixed order so mesh ids depend only on
        // the inputs. (A piece is posed at a rig's every used step even if
        // none of its wearers plays that step: bounded, and far cheaper to
        // track than poses per agent.)
        let mut worn: BTreeMap<&str, BTreeSet<usize>> = BTreeMap::new();
        for (id, pieces) in &skin_dressed {
            worn.entry(&*casting[id].rig).or_default().extend(pieces.iter().map(|d: &SkinDress| d.piece));
        }
        let mut posed = PosedSkins::default();
        for (rig_name, cycle, step) in &skin_poses {
            let Some(pieces) = worn.get(rig_name.as_str()) else { continue };
            let rig = &skinned[rig_name];
            let joints = rig.step_joints(*cycle, *step);
            let key: Arc<str> = rig_names.get(rig_name).map_or_else(|| rig_name.as_str().into(), |(n, _)| n.clone());
            for &piece in pieces {
                let mesh = rig.pose_piece(piece, &joints, &rig.pose_name(*cycle, *step));
                posed.meshes.insert((key.clone(), piece, *cycle, *step), assets.add_mesh(mesh));
            }
            posed.joints.insert((key, *cycle, *step), joints);
        }

        let (set, set_names) = match &shot.set {
            Some(s) => {
                let (placed, mut names) = assets.load_scene_objects(&s.file)?;
                if names.len() > SET_OBJECTS_NAMED {
                    warnings.push(format!(
                        "set {} has {} objects: Cryptomatte names the first {SET_OBJECTS_NAMED} and calls the rest `set`",
                        s.file.display(),
                        names.len()
                    ));
                    names.truncate(SET_OBJECTS_NAMED);
                }
                let set = placed
                    .into_iter()
                    .map(|(mesh, material, world_from_object, object)| Instance {
                        mesh,
                        material,
                        world_from_object,
                        agent: InstanceAgent::NONE,
                        // Past the names: u16::MAX, which no name has.
                        part: u16::try_from(object).unwrap_or(u16::MAX),
                        visibility: vis::ALL,
                    })
                    .collect();
                (set, names)
            }
            None => (Vec::new(), Vec::new()),
        };
        let gltf_camera = match &shot.camera.gltf {
            Some((file, node)) => Some(assets.find_camera(file, node)?),
            None => None,
        };
        let rig_heights = rigs
            .iter()
            .map(|(name, rig)| (name.clone(), rig.height()))
            .chain(skinned.iter().map(|(name, rig)| (name.clone(), rig.height())))
            .collect();
        warnings.extend(skinned.values().flat_map(|r| r.warnings().iter().cloned()));
        Ok(ShotCrowd {
            shot,
            wardrobes,
            rigs,
            skinned,
            cache,
            casting,
            assets,
            dressed,
            fits: fit_list,
            skin_dressed,
            posed,
            proxy_mesh,
            set,
            set_names,
            warnings,
            gltf_camera,
            rig_heights,
        })
    }

    /// The shared meshes, materials and textures.
    pub fn library(&self) -> &Library {
        self.assets.library()
    }

    /// The cache frame block at a shot frame (empty if the cache has no such frame).
    pub fn agents_at(&self, shot_frame: i32) -> Result<FrameBlock> {
        let cf = self.shot.cache.cache_frame(shot_frame);
        if self.cache.frames().binary_search(&cf).is_err() {
            return Ok(FrameBlock { frame: cf, agents: Vec::new() });
        }
        self.cache.read_frame(cf)
    }

    /// Only the cache frames the shot reads (they keep their cache numbers),
    /// without reading the rest of a long simulation.
    pub fn shot_crowd(&self) -> Result<crate::cache::CrowdCache> {
        let mut frames = Vec::new();
        for f in self.shot.frames.iter() {
            let cf = self.shot.cache.cache_frame(f);
            if self.cache.frames().binary_search(&cf).is_ok() {
                frames.push(self.cache.read_frame(cf)?);
            }
        }
        Ok(crate::cache::CrowdCache { rigs: self.cache.rigs().to_vec(), cycles: self.cache.cycles().to_vec(), frames })
    }

    /// Name of a cycle index.
    pub fn cycle_name(&self, a: &AgentSample) -> &str {
        self.cache.cycles().get(a.cycle as usize).map(String::as_str).unwrap_or("?")
    }

    /// Agent to world: foot position, heading about +Y, height scale about the foot pivot.
    pub fn world_from_agent(&self, a: &AgentSample) -> Affine3A {
        let h = self.casting.get(&a.id).map_or(1.0, |c| c.height_scale);
        Affine3A::from_scale_rotation_translation(Vec3::splat(h), Quat::from_rotation_y(a.heading), a.position)
    }

    /// An agent's standing height in metres: its rig's height times its
    /// height scale (`None` for an agent that was not cast).
    pub fn agent_height(&self, id: u32) -> Option<f32> {
        let cast = self.casting.get(&id)?;
        Some(self.rig_heights.get(&*cast.rig)? * cast.height_scale)
    }

    /// Whether an agent record is rendered at all (not removed, hidden or on a culled cycle).
    pub fn renders(&self, a: &AgentSample) -> bool {
        !a.hidden()
            && !self.shot.removed.contains(&a.id)
            && !self.shot.culled_cycles.iter().any(|c| c == self.cycle_name(a))
    }

    /// An agent posed at its cycle frame: its slots' world transforms (slot
    /// rigs) or its placement and pose step (skinned characters).
    pub fn agent_pose(&self, a: &AgentSample) -> Result<AgentPose> {
        let cast = self.casting.get(&a.id).ok_or_else(|| {
            Error::invalid(&self.shot.cache.path, "agent was not cast (not in the shot's frames)").agent(a.id)
        })?;
        let world_from_agent = self.world_from_agent(a);
        let rig_err = |e: Error| Error::invalid(&self.shot.cache.path, format!("rig `{}`: {e}", cast.rig)).agent(a.id);
        if let Some(rig) = self.skinned.get(&*cast.rig) {
            let cycle = rig.cycle_index(self.cycle_name(a)).map_err(rig_err)?;
            return Ok(AgentPose::Skinned {
                world_from_rig: world_from_agent,
                cycle,
                step: rig.step_of(cycle, a.cycle_frame),
            });
        }
        let rig = &self.rigs[&*cast.rig];
        let cycle = rig.cycle(self.cycle_name(a)).map_err(rig_err)?;
        let pose = cycle.sample(a.cycle_frame, self.shot.frames.fps);
        Ok(AgentPose::Slots(pose.slot_transforms().into_iter().map(|(_, m)| world_from_agent * m).collect()))
    }

    /// The instances of one agent at a frame: its parts, or its proxy boxes
    /// wearing the same materials.
    pub fn agent_instances(&self, a: &AgentSample, lod: Lod, visibility: u8, out: &mut Vec<Instance>) -> Result<()> {
        let pose = self.agent_pose(a)?;
        self.posed_instances(a.id, &pose, lod, visibility, out);
        Ok(())
    }

    /// At most how many instances [`ShotCrowd::posed_instances`] gives
    /// agent `id` at `lod` (in any pose), so a frame's instance list is
    /// allocated once (at a million agents its doublings cost a gigabyte).
    pub fn posed_instance_bound(&self, id: u32, lod: Lod) -> usize {
        let rigid = self.dressed.get(&id).map_or(0, |d| match lod {
            Lod::Full => d.len(),
            Lod::Proxy => d.iter().filter(|p| p.proxy).count(),
        });
        let skinned = self.skin_dressed.get(&id).map_or(0, |d| match lod {
            Lod::Full => d.len(),
            Lod::Proxy => {
                let rig = self.casting.get(&id).and_then(|cast| self.skinned.get(&*cast.rig));
                rig.map_or(0, |rig| d.iter().map(|d| rig.piece(d.piece).joint_boxes.len()).sum())
            }
        });
        rigid + skinned
    }

    /// As [`ShotCrowd::agent_instances`], from a pose already computed (a
    /// render poses each agent once per frame, not once per layer).
    pub fn posed_instances(&self, id: u32, pose: &AgentPose, lod: Lod, visibility: u8, out: &mut Vec<Instance>) {
        let instance = |mesh, material, world_from_object, part: usize| Instance {
            mesh,
            material,
            world_from_object,
            agent: InstanceAgent::some(id),
            part: part as u16,
            visibility,
        };
        match pose {
            AgentPose::Slots(slots) => {
                for p in self.dressed.get(&id).into_iter().flatten() {
                    let (slot, fit) = (p.slot as usize, &self.fits[p.fit as usize]);
                    let world_from_slot = slots[slot];
                    match lod {
                        Lod::Full => out.push(instance(p.mesh, p.material, world_from_slot * fit.slot_from_part, slot)),
                        Lod::Proxy if p.proxy => {
                            out.push(instance(self.proxy_mesh, p.material, world_from_slot * fit.slot_from_proxy, slot))
                        }
                        Lod::Proxy => {}
                    }
                }
            }
            &AgentPose::Skinned { world_from_rig, cycle, step } => {
                let Some(cast) = self.casting.get(&id) else { return };
                let Some(rig) = self.skinned.get(&*cast.rig) else { return };
                for d in self.skin_dressed.get(&id).into_iter().flatten() {
                    match lod {
                        Lod::Full => {
                            // Every pose in the shot's frames was posed at load.
                            let key = (cast.rig.clone(), d.piece, cycle, step);
                            if let Some(&mesh) = self.posed.meshes.get(&key) {
                                out.push(instance(mesh, d.material, world_from_rig, d.slot));
                            }
                        }
                        Lod::Proxy => {
                            let Some(joints) = self.posed.joints.get(&(cast.rig.clone(), cycle, step)) else {
                                continue;
                            };
                            let piece = rig.piece(d.piece);
                            for (j, b) in piece.joint_boxes.iter().enumerate() {
                                let Some((lo, hi)) = *b else { continue };
                                let size = (hi - lo).max(Vec3::splat(1e-4));
                                let box_from_cube = Affine3A::from_scale_rotation_translation(size, Quat::IDENTITY, lo);
                                let world = world_from_rig * joints[piece.joint_nodes[j]] * box_from_cube;
                                out.push(instance(self.proxy_mesh, d.material, world, d.slot));
                            }
                        }
                    }
                }
            }
        }
    }

    /// The name of part `part` (a cast slot) of an agent, for Cryptomatte
    /// and export node names.
    pub fn slot_name(&self, id: u32, part: u16) -> Option<&str> {
        self.casting.get(&id)?.slots.get(part as usize).map(|s| &*s.slot)
    }

    /// The pose key a skinned agent plays at a frame: `<rig>/<cycle>/<step>of<steps>`.
    pub fn pose_key(&self, a: &AgentSample) -> Option<String> {
        let cast = self.casting.get(&a.id)?;
        let rig = self.skinned.get(&*cast.rig)?;
        let cycle = rig.cycle_index(self.cycle_name(a)).ok()?;
        Some(format!("{}/{}", cast.rig, rig.pose_name(cycle, rig.step_of(cycle, a.cycle_frame))))
    }

    /// Every rendered agent at a shot frame, fully visible, at `lod(agent id)`.
    pub fn frame_instances(&self, shot_frame: i32, lod: impl Fn(u32) -> Lod) -> Result<Vec<Instance>> {
        let block = self.agents_at(shot_frame)?;
        let mut out = Vec::new();
        for a in block.agents.iter().filter(|a| self.renders(a)) {
            self.agent_instances(a, lod(a.id), vis::ALL, &mut out)?;
        }
        Ok(out)
    }

    /// The camera at a shot frame.
    pub fn camera(&self, shot_frame: i32) -> Result<Camera> {
        if let Some(c) = self.shot.keyed_camera(shot_frame as f32) {
            return Ok(c);
        }
        self.gltf_camera.ok_or_else(|| Error::invalid(&self.shot.path, "no camera").field("camera"))
    }
}
