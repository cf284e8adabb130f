//! Posing: the shot loaded and cast, ready to give any frame's instances.
//!
//! An agent's part transform at a frame is
//! `world_from_agent (position, heading, height scale about the foot pivot)
//!  x rig_from_slot (the rig node at that cycle frame)
//!  x slot_from_part (the part's fit to its proxy box)`.
//! Meshes and materials are loaded once into the shared [`AssetCache`]; every
//! instance references them by id.

use std::collections::{BTreeMap, HashMap};
use std::path::Path;

use glam::{Affine3A, Quat, Vec3};

use crate::cache::{AgentSample, CacheReader, FrameBlock};
use crate::casting::rig::Rig;
use crate::casting::wardrobe::{Wardrobes, GLTF_MATERIAL};
use crate::casting::{cast_agent, fit_part, AgentCast, RigCasting};
use crate::error::{Error, Result};
use crate::scene::gltf::AssetCache;
use crate::scene::{vis, Camera, Instance, Library, Material, MaterialId, Mesh, MeshId};
use crate::shot::Shot;

/// Level of detail an agent renders at.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Lod {
    /// Real wardrobe parts.
    Full,
    /// The rig's proxy boxes, wearing the same materials as the full agent.
    Proxy,
}

/// One resolved part of a cast agent: geometry and material ids plus the
/// transforms that place it in its slot.
#[derive(Debug, Clone, Copy)]
pub struct DressedPart {
    /// Index into the rig's slots.
    pub slot: usize,
    /// The part mesh.
    pub mesh: MeshId,
    /// The part's material.
    pub material: MaterialId,
    /// Fit of the part mesh to the slot's proxy box.
    pub slot_from_part: Affine3A,
    /// The unit proxy cube mapped onto the slot's proxy box.
    pub slot_from_proxy: Affine3A,
    /// Whether this piece stands for its slot at proxy LOD (one per slot,
    /// wearing the part's first material).
    pub proxy: bool,
}

/// The shot, its wardrobes, rigs, cache and casting, loaded once.
pub struct ShotCrowd {
    /// The shot.
    pub shot: Shot,
    /// Its wardrobes.
    pub wardrobes: Wardrobes,
    /// Rigs by name.
    pub rigs: BTreeMap<String, Rig>,
    /// The simulation cache.
    pub cache: CacheReader,
    /// Every agent that appears in the shot's frames, by id.
    pub casting: BTreeMap<u32, AgentCast>,
    /// Shared meshes and materials.
    pub assets: AssetCache,
    /// Resolved parts per agent.
    pub dressed: BTreeMap<u32, Vec<DressedPart>>,
    /// The unit cube used for proxy boxes.
    pub proxy_mesh: MeshId,
    /// The set's instances (agent `None`), fully visible.
    pub set: Vec<Instance>,
    /// The camera from a glTF node, when the shot names one instead of keys.
    gltf_camera: Option<Camera>,
    /// Standing height of each rig, metres.
    rig_heights: BTreeMap<String, f32>,
}

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
        for (name, r) in &shot.rigs {
            rigs.insert(name.clone(), Rig::load(&r.file)?);
        }

        // First pass over the shot's frames: each agent's rig (at its first
        // appearance) and whether it is ever seated or on a no-scale cycle.
        struct Seen {
            rig: u16,
            never_scale: bool,
        }
        let mut seen: BTreeMap<u32, Seen> = BTreeMap::new();
        for f in shot.frames.iter() {
            let cf = shot.cache.cache_frame(f);
            if cache.frames().binary_search(&cf).is_err() {
                continue;
            }
            let block = cache.read_frame(cf)?;
            for a in &block.agents {
                let cycle = cache.cycles().get(a.cycle as usize).map(String::as_str).unwrap_or("");
                let rig_name = cache.rigs().get(a.rig as usize).map(String::as_str).unwrap_or("");
                // A cycle the agent's rig lacks would only fail when posed; say so now.
                if let Some(rig) = rigs.get(rig_name) {
                    if let Err(e) = rig.cycle(cycle) {
                        return Err(Error::invalid(cache.path(), format!("rig `{rig_name}`: {e}"))
                            .frame(f as i64)
                            .agent(a.id)
                            .field("cycle"));
                    }
                }
                let no_scale = a.seated() || shot.is_no_scale_cycle(cycle);
                let e = seen.entry(a.id).or_insert(Seen { rig: a.rig, never_scale: false });
                e.never_scale |= no_scale;
            }
        }
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
        // Fits depend only on (rig, slot, mesh): compute each once.
        let mut fits: HashMap<(String, usize, MeshId), Affine3A> = HashMap::new();
        let mut materials: HashMap<String, MaterialId> = HashMap::new();
        for (&id, s) in &seen {
            let rig_name = cache.rigs().get(s.rig as usize).cloned().unwrap_or_default();
            let (rig, rig_ref) = match (rigs.get(&rig_name), shot.rigs.get(&rig_name)) {
                (Some(r), Some(rr)) => (r, rr),
                _ => {
                    return Err(Error::invalid(
                        &shot.path,
                        format!(
                            "agent {id} uses rig `{rig_name}`, which the shot's [rigs] does not define (defined: {})",
                            shot.rigs.keys().cloned().collect::<Vec<_>>().join(", ")
                        ),
                    )
                    .agent(id)
                    .field("rigs"))
                }
            };
            let slot_names: Vec<String> = rig.slots().iter().map(|s| s.name.clone()).collect();
            let rc = RigCasting {
                name: &rig_name,
                slots: &slot_names,
                schemes: &rig_ref.schemes,
                height_jitter: rig_ref.height_jitter,
            };
            let cast = cast_agent(shot.seed, id, &rc, &wardrobes, &shot.exclude_parts, s.never_scale)
                .map_err(|msg| Error::invalid(&shot.path, msg).agent(id).field(format!("rigs.{rig_name}.schemes")))?;
            let mut parts = Vec::new();
            for (slot_index, slot_cast) in cast.slots.iter().enumerate() {
                let Some(part) = &slot_cast.part else { continue };
                // A part wearing its own glTF materials keeps one piece per
                // primitive (a multi-material mesh); otherwise one mesh, one material.
                let pieces: Vec<(MeshId, MaterialId)> = if part.material == GLTF_MATERIAL {
                    assets.mesh_primitives(&part.file, &part.mesh)?
                } else {
                    let mesh = assets.mesh(&part.file, &part.mesh)?;
                    let material = match materials.get(&part.material) {
                        Some(&m) => m,
                        None => {
                            let spec = &wardrobes.materials[&part.material];
                            let texture = match &spec.base_color_texture {
                                Some(t) => Some(assets.texture_png(t)?),
                                None => None,
                            };
                            let m = assets.add_material(Material {
                                name: part.material.clone(),
                                base_color: Vec3::from(spec.base_color),
                                base_color_texture: texture,
                                roughness: spec.roughness,
                                metallic: spec.metallic,
                            });
                            materials.insert(part.material.clone(), m);
                            m
                        }
                    };
                    vec![(mesh, material)]
                };
                let Some(&(first_mesh, _)) = pieces.first() else { continue };
                let slot = &rig.slots()[slot_index];
                let fit = *fits.entry((rig_name.clone(), slot_index, first_mesh)).or_insert_with(|| {
                    // Fit the whole part (all its pieces) to the box.
                    let lib = assets.library();
                    let (lo, hi) = pieces
                        .iter()
                        .map(|&(m, _)| lib.meshes[m as usize].bounds())
                        .reduce(|(a, b), (c, d)| (a.min(c), b.max(d)))
                        .unwrap_or((Vec3::ZERO, Vec3::ZERO));
                    fit_part(lo, hi, slot.proxy_min, slot.proxy_max, part.uniform)
                });
                let size = (slot.proxy_max - slot.proxy_min).max(Vec3::splat(1e-4));
                for (i, &(mesh, material)) in pieces.iter().enumerate() {
                    parts.push(DressedPart {
                        slot: slot_index,
                        mesh,
                        material,
                        slot_from_part: fit,
                        slot_from_proxy: Affine3A::from_scale_rotation_translation(
                            size,
                            Quat::IDENTITY,
                            slot.proxy_min,
                        ),
                        proxy: i == 0,
                    });
                }
            }
            dressed.insert(id, parts);
            casting.insert(id, cast);
        }
        let set = match &shot.set {
            Some(s) => assets
                .load_scene_instances(&s.file)?
                .into_iter()
                .map(|(mesh, material, world_from_object)| Instance {
                    mesh,
                    material,
                    world_from_object,
                    agent: None,
                    part: 0,
                    visibility: vis::ALL,
                })
                .collect(),
            None => Vec::new(),
        };
        let gltf_camera = match &shot.camera.gltf {
            Some((file, node)) => Some(assets.find_camera(file, node)?),
            None => None,
        };
        let rig_heights = rigs.iter().map(|(name, rig)| (name.clone(), rig.height())).collect();
        Ok(ShotCrowd {
            shot,
            wardrobes,
            rigs,
            cache,
            casting,
            assets,
            dressed,
            proxy_mesh,
            set,
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
        Some(self.rig_heights.get(&cast.rig)? * cast.height_scale)
    }

    /// Whether an agent record is rendered at all (not removed, hidden or on a culled cycle).
    pub fn renders(&self, a: &AgentSample) -> bool {
        !a.hidden()
            && !self.shot.removed.contains(&a.id)
            && !self.shot.culled_cycles.iter().any(|c| c == self.cycle_name(a))
    }

    /// World transforms of every slot of an agent at its cycle frame, in rig slot order.
    pub fn slot_transforms(&self, a: &AgentSample) -> Result<Vec<Affine3A>> {
        let cast = self.casting.get(&a.id).ok_or_else(|| {
            Error::invalid(&self.shot.cache.path, "agent was not cast (not in the shot's frames)").agent(a.id)
        })?;
        let rig = &self.rigs[&cast.rig];
        let cycle = rig
            .cycle(self.cycle_name(a))
            .map_err(|e| Error::invalid(&self.shot.cache.path, format!("rig `{}`: {e}", cast.rig)).agent(a.id))?;
        let pose = cycle.sample(a.cycle_frame, self.shot.frames.fps);
        let world_from_agent = self.world_from_agent(a);
        Ok(pose.slot_transforms().into_iter().map(|(_, m)| world_from_agent * m).collect())
    }

    /// The instances of one agent at a frame: its parts, or its proxy boxes
    /// wearing the same materials.
    pub fn agent_instances(&self, a: &AgentSample, lod: Lod, visibility: u8, out: &mut Vec<Instance>) -> Result<()> {
        let slots = self.slot_transforms(a)?;
        self.posed_instances(a.id, &slots, lod, visibility, out);
        Ok(())
    }

    /// As [`ShotCrowd::agent_instances`], from slot transforms already
    /// posed (a render poses each agent once per frame, not once per layer).
    pub fn posed_instances(&self, id: u32, slots: &[Affine3A], lod: Lod, visibility: u8, out: &mut Vec<Instance>) {
        for p in self.dressed.get(&id).into_iter().flatten() {
            let world_from_slot = slots[p.slot];
            let (mesh, world_from_object) = match lod {
                Lod::Full => (p.mesh, world_from_slot * p.slot_from_part),
                Lod::Proxy if p.proxy => (self.proxy_mesh, world_from_slot * p.slot_from_proxy),
                Lod::Proxy => continue,
            };
            out.push(Instance {
                mesh,
                material: p.material,
                world_from_object,
                agent: Some(id),
                part: p.slot as u16,
                visibility,
            });
        }
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
