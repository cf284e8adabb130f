//! The pose library: the shared meshes, materials and textures of a cast
//! shot, with every posed mesh its skinned agents need, still pose steps and
//! (when built for a shutter) the shutter's steps alike. It records its
//! colourspace as a type ([`Rec709`] as authored, or [`crate::scene::Acescg`]
//! once converted for the render) and the shutter it was built for.

use std::collections::{BTreeMap, BTreeSet};
use std::marker::PhantomData;
use std::sync::Arc;

use glam::Affine3A;

use crate::casting::cast::PoseStep;
use crate::casting::dressing::Dressing;
use crate::casting::rigs::ShotRigs;
use crate::scene::gltf::AssetCache;
use crate::scene::{Library, Material, MeshId, Rec709, Space, Texture};
use crate::shot::Colourspace;

/// Posed geometry of skinned agents, one entry per pose step used.
#[derive(Debug, Default)]
pub struct PosedSkins {
    /// (rig, piece, body, cycle, step) -> the posed mesh.
    meshes: BTreeMap<(Arc<str>, usize, u16, usize, u32), MeshId>,
    /// `rig_from_node` of every rig node at each pose step of each body (for proxy boxes).
    joints: BTreeMap<PoseStep, Vec<Affine3A>>,
}

impl PosedSkins {
    /// Poses every piece worn on a rig at each of `steps` not posed yet,
    /// once, in step order so mesh ids depend only on the inputs. (A piece
    /// is posed at a rig's every used step even if none of its wearers
    /// plays that step: bounded, and far cheaper to track than poses per agent.)
    pub(crate) fn pose(
        &mut self,
        steps: &BTreeSet<PoseStep>,
        worn: &BTreeMap<Arc<str>, BTreeSet<usize>>,
        (rigs, dressing): (&ShotRigs, &Dressing),
        assets: &mut AssetCache,
    ) {
        for key @ (rig_name, body, cycle, step) in steps {
            if self.joints.contains_key(key) {
                continue;
            }
            let Some((rig_key, pieces)) = worn.get_key_value(&**rig_name) else { continue };
            let Some(rig) = rigs.skinned(rig_name) else { continue };
            let joints = rig.body_step_joints(*body, *cycle, *step);
            let pose = match body {
                0 => rig.pose_name(*cycle, *step),
                b => format!("{}/body{b}", rig.pose_name(*cycle, *step)),
            };
            for &piece in pieces {
                let mesh = rig.pose_skin_piece(*body, dressing.piece(rig_name, rig, piece), &joints, &pose);
                self.meshes.insert((rig_key.clone(), piece, *body, *cycle, *step), assets.add_mesh(mesh));
            }
            self.joints.insert((rig_key.clone(), *body, *cycle, *step), joints);
        }
    }

    /// The mesh of `piece` of `rig` posed at (`cycle`, `step`) on body `body`.
    pub(crate) fn mesh(&self, rig: &Arc<str>, piece: usize, body: u16, cycle: usize, step: u32) -> Option<MeshId> {
        self.meshes.get(&(rig.clone(), piece, body, cycle, step)).copied()
    }

    /// `rig_from_node` of every node of `rig` at (`cycle`, `step`) on body `body`.
    pub(crate) fn joints(&self, rig: &Arc<str>, body: u16, cycle: usize, step: u32) -> Option<&[Affine3A]> {
        self.joints.get(&(rig.clone(), body, cycle, step)).map(Vec::as_slice)
    }

    /// Every posed mesh: ((rig, piece, body, cycle, step), mesh), in key order.
    pub(crate) fn meshes(&self) -> impl Iterator<Item = (&(Arc<str>, usize, u16, usize, u32), MeshId)> {
        self.meshes.iter().map(|(k, &m)| (k, m))
    }

    /// The first posed mesh of `piece` of `rig` (any body, cycle and step).
    pub(crate) fn first_mesh(&self, rig: &str, piece: usize) -> Option<MeshId> {
        self.meshes
            .range((Arc::<str>::from(rig), piece, 0, 0, 0)..)
            .find(|(k, _)| *k.0 == *rig && k.1 == piece)
            .map(|(_, &m)| m)
    }

    /// How many meshes are posed.
    pub fn mesh_count(&self) -> usize {
        self.meshes.len()
    }

    /// How many pose steps are posed (over every rig and cycle).
    pub fn step_count(&self) -> usize {
        self.joints.len()
    }
}

/// Every mesh, material and texture of a cast shot and its posed skinned
/// steps, with colours in the space `C`.
pub struct PoseLibrary<C = Rec709> {
    assets: AssetCache,
    skins: PosedSkins,
    shutter: Option<[f32; 2]>,
    // A marker only: `fn() -> C` keeps the library Send and Sync whatever `C`.
    space: PhantomData<fn() -> C>,
}

impl PoseLibrary<Rec709> {
    /// The finished library: what dressing, the set and posing loaded into
    /// `assets`, and the skinned steps posed for still frames and, with
    /// `shutter`, for that shutter.
    pub(crate) fn new(assets: AssetCache, skins: PosedSkins, shutter: Option<[f32; 2]>) -> PoseLibrary {
        PoseLibrary { assets, skins, shutter, space: PhantomData }
    }

    /// The same library with its material and texture colours converted by
    /// `convert` into the space `D` (every mesh and id as it was).
    pub(crate) fn convert<D: Space>(mut self, convert: impl FnOnce(&mut [Material], &mut [Texture])) -> PoseLibrary<D> {
        let (materials, textures) = self.assets.colours_mut();
        convert(materials, textures);
        PoseLibrary { assets: self.assets, skins: self.skins, shutter: self.shutter, space: PhantomData }
    }

    /// The materials, for the shot's light-group gains on their emission.
    pub(crate) fn materials_mut(&mut self) -> &mut [Material] {
        self.assets.colours_mut().0
    }
}

impl<C> PoseLibrary<C> {
    /// The shared meshes, materials and textures.
    pub(crate) fn library(&self) -> &Library {
        self.assets.library()
    }

    /// The posed skinned steps.
    pub fn skins(&self) -> &PosedSkins {
        &self.skins
    }

    /// The shutter whose steps are posed (`None`: still frames only).
    pub fn shutter(&self) -> Option<[f32; 2]> {
        self.shutter
    }
}

impl<C: Space> PoseLibrary<C> {
    /// The colourspace of the library's colours.
    pub fn colourspace(&self) -> Colourspace {
        C::COLOURSPACE
    }
}
