//! The dressing stage: the geometry each cast agent wears. A slot-rig agent
//! wears rigid parts fitted to its slots' proxy boxes; a skinned agent wears
//! pieces of its character's skinned meshes. Meshes and materials are loaded
//! once into the shared [`AssetCache`]; every agent references them by id.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::sync::Arc;

use glam::{Affine3A, Quat, Vec3};

use crate::casting::cast::{fit_part, AgentCast, Casting};
use crate::casting::kind::skinned_refusal;
use crate::casting::pieces::SkinPiece;
use crate::casting::rigs::{ShotRig, ShotRigs};
use crate::casting::skin::SkinnedRig;
use crate::casting::wardrobe::{PropAt, Wardrobes, GLTF_MATERIAL};
use crate::casting::worn::WornParts;
use crate::casting::Lod;
use crate::error::{Error, Result};
use crate::scene::gltf::AssetCache;
use crate::scene::{Material, MaterialId, Mesh, MeshId};

/// One resolved part of a slot-rig agent: geometry and material ids plus
/// which shared fit places it in its slot. 20 bytes: a million agents keep eleven each.
#[derive(Debug, Clone, Copy)]
pub struct DressedPart {
    /// Index into the rig's slots (where it is posed).
    pub slot: u32,
    /// Its part index (Cryptomatte, export): the slot, or for a prop
    /// `slots + i` ([`crate::casting::AgentCast::props`]).
    pub(crate) part: u16,
    /// The part mesh.
    pub mesh: MeshId,
    /// The part's material.
    pub(crate) material: MaterialId,
    /// Index of its fit ([`Dressing::fit`]): fits depend only on (rig, slot, mesh).
    pub fit: u32,
    /// Whether this piece stands for its slot at proxy LOD (one per slot,
    /// wearing the part's first material).
    pub(crate) proxy: bool,
}

/// How a part mesh and the proxy cube sit in a slot.
#[derive(Debug, Clone, Copy)]
pub struct PartFit {
    /// Fit of the part mesh to the slot's proxy box.
    pub slot_from_part: Affine3A,
    /// The unit proxy cube mapped onto the slot's proxy box.
    pub(crate) slot_from_proxy: Affine3A,
}

/// One skinned piece a skinned agent wears.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SkinDress {
    /// Its part index: a cast slot, or a prop after them (`slots + i`).
    pub(crate) slot: usize,
    /// Index of the piece: the rig's own ([`crate::casting::skin::SkinnedRig::piece`])
    /// or one dressing loaded for it ([`Dressing::piece`]).
    pub(crate) piece: usize,
    /// The piece's material.
    pub(crate) material: MaterialId,
}

/// What one agent wears, by its rig's kind.
#[derive(Debug, Clone)]
pub enum AgentDress {
    /// Rigid parts in the slots of a slot rig.
    Slots(Vec<DressedPart>),
    /// Skinned pieces of a skinned character.
    Skinned(Vec<SkinDress>),
}

impl AgentDress {
    /// The material worn as part `slot` (a cast slot, or a prop after the
    /// slots; its first piece's), if any.
    pub(crate) fn material_in_slot(&self, slot: usize) -> Option<MaterialId> {
        match self {
            AgentDress::Slots(parts) => parts.iter().find(|p| p.part as usize == slot).map(|p| p.material),
            AgentDress::Skinned(pieces) => pieces.iter().find(|p| p.slot == slot).map(|p| p.material),
        }
    }
}

/// The dressing of every cast agent; built by [`Dressing::dress`] and not
/// changed afterwards.
#[derive(Debug, Clone, Default)]
pub struct Dressing {
    agents: BTreeMap<u32, AgentDress>,
    fits: Vec<PartFit>,
    proxy_mesh: MeshId,
    /// The parts and pieces dressing loaded for skinned rigs beyond their own.
    worn: WornParts,
}

/// A memo key made of the addresses of shared (`Arc`) names: (rig, file,
/// mesh, material). The wardrobes and casting keep them alive for the whole
/// dressing, so equal addresses are the same part.
type SharedKey = (usize, usize, usize, usize);

/// The address of a shared name, for memo keys.
fn address<T: ?Sized>(shared: &Arc<T>) -> usize {
    Arc::as_ptr(shared) as *const u8 as usize
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

/// Checks, before any agent is dressed, every part of every wardrobe scheme
/// a slot rig of `shot` draws with a weight > 0 (parts the scheme or the
/// shot excludes left out): its mesh is in its glTF file and is rigid, and
/// each wardrobe material it may wear has a texture that reads as an image.
/// A bad part is refused naming its scheme and part even when no agent
/// happens to draw it. Loads only what dressing loads anyway (the parts'
/// files; textures are read up to their size).
pub(crate) fn check_schemes(
    shot: &crate::shot::Shot,
    rigs: &ShotRigs,
    wardrobes: &Wardrobes,
    assets: &mut AssetCache,
) -> Result<()> {
    let mut textures_seen = BTreeSet::new();
    for (rig_name, rig) in &shot.rigs {
        check_props(rig, wardrobes, assets)?;
        if !matches!(rigs.get(rig_name), Some(ShotRig::Slots(_))) {
            continue;
        }
        for (name, _) in rig.schemes.iter().filter(|(_, w)| **w > 0.0) {
            let Some(scheme) = wardrobes.schemes.get(name) else { continue };
            for (i, part) in scheme.parts.iter().enumerate() {
                let excluded = |e: &String| **e == *part.mesh;
                if part.weight <= 0.0 || scheme.exclude.iter().any(excluded) || shot.exclude_parts.iter().any(excluded)
                {
                    continue;
                }
                let key = format!("schemes.{name}.parts[{i}]");
                let in_scheme = |e: Error| e.or_field(format!("{key}.mesh"));
                if assets.is_skinned_mesh(&part.file, &part.mesh).map_err(in_scheme)? {
                    return Err(skinned_refusal(&part.file, &format!("wardrobe part `{}` ({key})", part.mesh))
                        .field(format!("{key}.mesh")));
                }
                for m in part.materials.iter().filter(|m| ***m != *GLTF_MATERIAL) {
                    let Some(texture) = wardrobes.materials.get(&**m).and_then(|s| s.base_color_texture.as_ref())
                    else {
                        continue;
                    };
                    if textures_seen.insert(texture.clone()) {
                        check_image(texture).map_err(|e| {
                            let material = m.rsplit('/').next().unwrap_or(m);
                            Error::invalid(&scheme.source, format!("{e} (worn by {key} in rig `{rig_name}`)"))
                                .field(format!("materials.{material}.base_color_texture"))
                        })?;
                    }
                }
            }
        }
    }
    Ok(())
}

/// Checks every prop of every scheme `rig` draws with a weight > 0: its
/// mesh is in its glTF file and is rigid. The error names the wardrobe
/// file, scheme, prop and field (`schemes.S.props[0].mesh`).
fn check_props(rig: &crate::shot::RigRef, wardrobes: &Wardrobes, assets: &mut AssetCache) -> Result<()> {
    for (name, _) in rig.schemes.iter().filter(|(_, w)| **w > 0.0) {
        let Some(scheme) = wardrobes.schemes.get(name) else { continue };
        for (i, prop) in scheme.props.iter().enumerate() {
            let (Some(file), Some(mesh)) = (&prop.file, &prop.mesh) else { continue };
            let key = format!("schemes.{name}.props[{i}].mesh");
            let in_wardrobe =
                |e: Error| Error::invalid(&scheme.source, format!("prop `{}`: {e}", prop.name)).field(key.clone());
            if assets.is_skinned_mesh(file, mesh).map_err(in_wardrobe)? {
                return Err(skinned_refusal(file, &format!("prop `{}` ({key})", prop.name)).field(key));
            }
        }
    }
    Ok(())
}

/// Whether `path` reads as an image of a size throng loads (its format and
/// size, not its pixels): the bound every texture has
/// ([`crate::scene::gltf::texture_size`]), so a wardrobe's texture too
/// large to load is refused here, not when an agent wears it.
fn check_image(path: &std::path::Path) -> Result<()> {
    crate::scene::gltf::texture_size(path).map(drop)
}

/// Each piece of part `part` of skinned rig `rig` (its own, or `worn`)
/// with its material: the glTF's own (`material` is [`GLTF_MATERIAL`]) or
/// the wardrobe's `material`.
fn piece_materials(
    (worn, rig_name, rig): (&WornParts, &str, &SkinnedRig),
    part: usize,
    material: &str,
    assets: &mut AssetCache,
    made: &mut HashMap<String, MaterialId>,
    wardrobes: &Wardrobes,
) -> Result<Vec<(usize, MaterialId)>> {
    let mut list = Vec::new();
    for &piece in &worn.part_at(rig_name, rig, part).pieces {
        let material = if *material == *GLTF_MATERIAL {
            let p = worn.piece(rig_name, rig, piece);
            match rig.usd_material(p.material).filter(|_| p.file == rig.path()) {
                // A UsdSkel character's UsdPreviewSurface, made once per material.
                Some((m, texture)) => match made.get(&m.name) {
                    Some(&id) => id,
                    None => {
                        let mut m = m.clone();
                        if let Some(t) = texture {
                            m.base_color_texture = Some(assets.texture_png(t)?);
                        }
                        *made.entry(m.name.clone()).or_insert(assets.add_material(m))
                    }
                },
                None => assets.gltf_material_at(&p.file, p.material)?,
            }
        } else {
            wardrobe_material(assets, made, wardrobes, material)?
        };
        list.push((piece, material));
    }
    Ok(list)
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
        emission: Vec3::from(spec.emission),
        emissive_texture: None,
        ..Material::default()
    });
    made.insert(name.to_string(), m);
    Ok(m)
}

/// A rigid part's (mesh, material) pieces.
type Pieces = Vec<(MeshId, MaterialId)>;

/// The memos of one dressing run: each wardrobe part resolved, each fit
/// computed and each material made once, however many agents wear them.
#[derive(Default)]
struct Memo {
    /// Library materials by wardrobe material name.
    materials: HashMap<String, MaterialId>,
    /// Each rigid part (and material) resolved to its (mesh, material) pieces.
    parts: HashMap<SharedKey, Pieces>,
    /// Each skinned part (and material) resolved to its (piece, material) list.
    skin_parts: HashMap<SharedKey, Vec<(usize, MaterialId)>>,
    /// Fit index by (rig, slot, first mesh).
    fit_index: HashMap<(usize, usize, MeshId, [u32; 4]), u32>,
    /// A slot-rig prop's fit by (rig, slot, first mesh, offset).
    prop_fits: HashMap<(usize, usize, MeshId, [u32; 12]), u32>,
    /// Each skinned prop (rig, cast prop) resolved to its (piece, material) list.
    skin_props: HashMap<(usize, usize), Vec<(usize, MaterialId)>>,
}

/// The (mesh, material) pieces of a rigid wardrobe part or prop (`file`,
/// `mesh`, `material`), resolved once ([`Memo::parts`]): one piece per
/// primitive when it wears its own glTF materials (a multi-material mesh),
/// otherwise one mesh, one material. A skinned mesh is refused (`what`
/// names it).
fn rigid_pieces<'m>(
    assets: &mut AssetCache,
    (parts, materials): (&'m mut HashMap<SharedKey, Pieces>, &mut HashMap<String, MaterialId>),
    wardrobes: &Wardrobes,
    (file, mesh, material): (&Arc<std::path::Path>, &Arc<str>, &Arc<str>),
    what: impl Fn() -> String,
) -> Result<&'m [(MeshId, MaterialId)]> {
    let key = (0, address(file), address(mesh), address(material));
    let slot = match parts.entry(key) {
        std::collections::hash_map::Entry::Occupied(known) => return Ok(known.into_mut()),
        std::collections::hash_map::Entry::Vacant(slot) => slot,
    };
    if assets.is_skinned_mesh(file, mesh)? {
        return Err(skinned_refusal(file, &what()));
    }
    let pieces: Pieces = if **material == *GLTF_MATERIAL {
        assets.mesh_primitives(file, mesh)?
    } else {
        let mesh = assets.mesh(file, mesh)?;
        vec![(mesh, wardrobe_material(assets, materials, wardrobes, material)?)]
    };
    Ok(slot.insert(pieces))
}

impl Dressing {
    /// Dresses every cast agent in id order, loading the parts it wears into
    /// `assets` (the proxy cube first) and, for skinned characters, the
    /// pieces of parts beyond their own into the dressing's table of them.
    pub(crate) fn dress(
        casting: &Casting,
        rigs: &ShotRigs,
        wardrobes: &Wardrobes,
        assets: &mut AssetCache,
    ) -> Result<Dressing> {
        let proxy_mesh = assets.add_mesh(unit_cube());
        let mut dressing =
            Dressing { agents: BTreeMap::new(), fits: Vec::new(), proxy_mesh, worn: WornParts::default() };
        let mut memo = Memo::default();
        for cast in casting.iter() {
            let dress = if let Some(rig) = rigs.skinned(&cast.rig) {
                AgentDress::Skinned(dress_skinned(cast, rig, &mut dressing.worn, wardrobes, assets, &mut memo)?)
            } else if let Some(ShotRig::Slots(_)) = rigs.get(&cast.rig) {
                AgentDress::Slots(dressing.dress_slots(cast, rigs, wardrobes, assets, &mut memo)?)
            } else {
                continue;
            };
            dressing.agents.insert(cast.id, dress);
        }
        Ok(dressing)
    }

    /// A slot-rig agent's parts, each fitted to its slot.
    fn dress_slots(
        &mut self,
        cast: &AgentCast,
        rigs: &ShotRigs,
        wardrobes: &Wardrobes,
        assets: &mut AssetCache,
        memo: &mut Memo,
    ) -> Result<Vec<DressedPart>> {
        let Some(ShotRig::Slots(rig)) = rigs.get(&cast.rig) else { return Ok(Vec::new()) };
        let id = cast.id;
        // A part's mesh missing from its glTF: say which scheme asked for it.
        let part_err = |e: Error, scheme: &str| e.agent(id).or_field(format!("schemes.{scheme}.parts"));
        let mut parts = Vec::new();
        for (slot_index, slot_cast) in cast.slots.iter().enumerate() {
            let Some(part) = &slot_cast.part else { continue };
            // Resolved once per wardrobe part and material (keyed by the
            // wardrobe's shared strings, so a lookup hashes three words,
            // not a path): whether it is skinned, and its (mesh, material) pieces.
            let what = || format!("wardrobe part `{}` (slot `{}`)", part.mesh, slot_cast.slot);
            let pieces = rigid_pieces(
                assets,
                (&mut memo.parts, &mut memo.materials),
                wardrobes,
                (&part.file, &part.mesh, &part.material),
                what,
            )
            .map_err(|e| part_err(e, &cast.scheme))?;
            let Some(&(first_mesh, _)) = pieces.first() else { continue };
            let slot = &rig.slots()[slot_index];
            let facing = part.facing;
            let turned = facing.to_array().map(f32::to_bits);
            let fit =
                *memo.fit_index.entry((address(&cast.rig), slot_index, first_mesh, turned)).or_insert_with(|| {
                    // Fit the whole part (all its pieces), turned to face +Z, to
                    // the box. The turn is by whole axes, so the turned corners
                    // bound the turned mesh exactly.
                    let lib = assets.library();
                    let (lo, hi) = pieces
                        .iter()
                        .map(|&(m, _)| lib.meshes[m as usize].bounds())
                        .reduce(|(a, b), (c, d)| (a.min(c), b.max(d)))
                        .unwrap_or((Vec3::ZERO, Vec3::ZERO));
                    let (a, b) = (facing * lo, facing * hi);
                    let (lo, hi) = (a.min(b), a.max(b));
                    let size = (slot.proxy_max - slot.proxy_min).max(Vec3::splat(1e-4));
                    self.fits.push(PartFit {
                        slot_from_part: fit_part(lo, hi, slot.proxy_min, slot.proxy_max, part.uniform)
                            * Affine3A::from_quat(facing),
                        slot_from_proxy: Affine3A::from_scale_rotation_translation(
                            size,
                            Quat::IDENTITY,
                            slot.proxy_min,
                        ),
                    });
                    self.fits.len() as u32 - 1
                });
            for (i, &(mesh, material)) in pieces.iter().enumerate() {
                let part = slot_index as u16;
                parts.push(DressedPart { slot: slot_index as u32, part, mesh, material, fit, proxy: i == 0 });
            }
        }
        // Props hang on their slot at their offset, their own size; the
        // proxy is the box of their bounds.
        for (k, prop) in cast.props.iter().enumerate() {
            let PropAt::Slot(slot_name) = &prop.at else { continue };
            let Some(slot_index) = rig.slots().iter().position(|s| *s.name == **slot_name) else { continue };
            let what = || format!("prop `{}` (slot `{slot_name}`)", prop.name);
            let pieces = rigid_pieces(
                assets,
                (&mut memo.parts, &mut memo.materials),
                wardrobes,
                (&prop.file, &prop.mesh, &prop.material),
                what,
            )
            .map_err(|e| e.agent(id).or_field(format!("schemes.{}.props", cast.scheme)))?;
            let Some(&(first_mesh, _)) = pieces.first() else { continue };
            let offset = prop.offset.to_cols_array().map(f32::to_bits);
            let key = (address(&cast.rig), slot_index, first_mesh, offset);
            let fit = match memo.prop_fits.get(&key) {
                Some(&f) => f,
                None => {
                    // The slot's rest scale taken out: offsets and props in metres.
                    let (scale, _, _) = rig.rest_pose().slot_transforms()[slot_index].1.to_scale_rotation_translation();
                    let slot_from_prop = Affine3A::from_scale(Vec3::ONE / scale.max(Vec3::splat(1e-12))) * prop.offset;
                    let lib = assets.library();
                    let (lo, hi) = (pieces.iter())
                        .map(|&(m, _)| lib.meshes[m as usize].bounds())
                        .reduce(|(a, b), (c, d)| (a.min(c), b.max(d)))
                        .unwrap_or((Vec3::ZERO, Vec3::ZERO));
                    let size = (hi - lo).max(Vec3::splat(1e-4));
                    self.fits.push(PartFit {
                        slot_from_part: slot_from_prop,
                        slot_from_proxy: slot_from_prop
                            * Affine3A::from_scale_rotation_translation(size, Quat::IDENTITY, lo),
                    });
                    let f = self.fits.len() as u32 - 1;
                    memo.prop_fits.insert(key, f);
                    f
                }
            };
            let part = (cast.slots.len() + k) as u16;
            for (i, &(mesh, material)) in pieces.iter().enumerate() {
                parts.push(DressedPart { slot: slot_index as u32, part, mesh, material, fit, proxy: i == 0 });
            }
        }
        parts.shrink_to_fit();
        Ok(parts)
    }

    /// What agent `id` wears (`None`: it was not cast).
    pub fn get(&self, id: u32) -> Option<&AgentDress> {
        self.agents.get(&id)
    }

    /// Every dressed agent by id, in order.
    pub fn iter(&self) -> impl Iterator<Item = (u32, &AgentDress)> {
        self.agents.iter().map(|(&id, d)| (id, d))
    }

    /// The fit a [`DressedPart::fit`] indexes.
    pub fn fit(&self, index: u32) -> &PartFit {
        &self.fits[index as usize]
    }

    /// The unit cube every proxy box instances.
    pub(crate) fn proxy_mesh(&self) -> MeshId {
        self.proxy_mesh
    }

    /// Piece `piece` of skinned rig `rig_name` (`rig`): the character's own,
    /// or one of a part dressing loaded for it.
    pub(crate) fn piece<'a>(&'a self, rig_name: &str, rig: &'a SkinnedRig, piece: usize) -> &'a SkinPiece {
        self.worn.piece(rig_name, rig, piece)
    }

    /// The parts and pieces dressing loaded beyond the characters' own.
    pub(crate) fn worn(&self) -> &WornParts {
        &self.worn
    }

    /// The skinned pieces worn on each skinned rig, over all its agents.
    pub(crate) fn worn_pieces(&self, casting: &Casting) -> BTreeMap<Arc<str>, BTreeSet<usize>> {
        let mut worn: BTreeMap<Arc<str>, BTreeSet<usize>> = BTreeMap::new();
        for (id, dress) in self.iter() {
            let (AgentDress::Skinned(pieces), Some(cast)) = (dress, casting.get(id)) else { continue };
            worn.entry(cast.rig.clone()).or_default().extend(pieces.iter().map(|d| d.piece));
        }
        worn
    }

    /// How many instances agent `id` places at `lod` in any pose: its parts,
    /// one proxy box per slot, its skinned pieces, or one box per joint of
    /// its pieces (0 for an agent not dressed).
    pub(crate) fn instance_count(&self, id: u32, lod: Lod, rigs: &ShotRigs, casting: &Casting) -> usize {
        match (self.get(id), lod) {
            (None, _) => 0,
            (Some(AgentDress::Slots(parts)), Lod::Full) => parts.len(),
            (Some(AgentDress::Slots(parts)), Lod::Proxy) => parts.iter().filter(|p| p.proxy).count(),
            (Some(AgentDress::Skinned(pieces)), Lod::Full) => pieces.len(),
            (Some(AgentDress::Skinned(pieces)), Lod::Proxy) => {
                let Some(cast) = casting.get(id) else { return 0 };
                let Some(rig) = rigs.skinned(&cast.rig) else { return 0 };
                (pieces.iter())
                    .map(|d| self.piece(&cast.rig, rig, d.piece).joint_boxes.iter().filter(|b| b.is_some()).count())
                    .sum()
            }
        }
    }
}

/// A skinned agent's pieces: each worn part's pieces of the character, in
/// its own glTF materials or the wardrobe's.
fn dress_skinned(
    cast: &AgentCast,
    rig: &SkinnedRig,
    worn: &mut WornParts,
    wardrobes: &Wardrobes,
    assets: &mut AssetCache,
    memo: &mut Memo,
) -> Result<Vec<SkinDress>> {
    let mut pieces = Vec::new();
    for (slot_index, slot_cast) in cast.slots.iter().enumerate() {
        let Some(part) = &slot_cast.part else { continue };
        // Resolved once per (rig, part, material): rig part lookups
        // and glTF materials touch the file system.
        let key = (address(&cast.rig), address(&part.file), address(&part.mesh), address(&part.material));
        if let std::collections::hash_map::Entry::Vacant(slot) = memo.skin_parts.entry(key) {
            let part_index =
                worn.part((&cast.rig, rig), &part.file, &part.mesh, &slot_cast.slot).map_err(|e| e.agent(cast.id))?;
            let list = piece_materials(
                (worn, &cast.rig, rig),
                part_index,
                &part.material,
                assets,
                &mut memo.materials,
                wardrobes,
            )
            .map_err(|e| e.agent(cast.id))?;
            slot.insert(list);
        }
        for &(piece, material) in &memo.skin_parts[&key] {
            pieces.push(SkinDress { slot: slot_index, piece, material });
        }
    }
    // Props on joints: pieces bound wholly to their joint, posed and
    // instanced with the skin (one per cast prop, shared by its wearers).
    for (k, prop) in cast.props.iter().enumerate() {
        let PropAt::Joint(joint) = &prop.at else { continue };
        let key = (address(&cast.rig), Arc::as_ptr(prop) as usize);
        if let std::collections::hash_map::Entry::Vacant(slot) = memo.skin_props.entry(key) {
            let in_scheme = |e: Error| e.agent(cast.id).or_field(format!("schemes.{}.props", cast.scheme));
            let part =
                worn.prop_part((&cast.rig, rig), &prop.file, &prop.mesh, (joint, prop.offset)).map_err(in_scheme)?;
            let list =
                piece_materials((worn, &cast.rig, rig), part, &prop.material, assets, &mut memo.materials, wardrobes)
                    .map_err(in_scheme)?;
            slot.insert(list);
        }
        for &(piece, material) in &memo.skin_props[&key] {
            pieces.push(SkinDress { slot: cast.slots.len() + k, piece, material });
        }
    }
    pieces.shrink_to_fit();
    Ok(pieces)
}
