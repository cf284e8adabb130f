//! A UsdSkel crowd's character as a pose source (docs/usd.md, "UsdSkel
//! crowds"): the skeleton read by `cache::usdskel` becomes a [`Hierarchy`]
//! (node `j` is joint `j`, under one node holding the Skeleton prim's
//! transform in its SkelRoot), every distinct SkelAnimation a [`Clip`], and
//! every skinned Mesh a [`SkinPiece`]: the same skinning, pose steps, pose
//! instancing, proxies and motion blur as a glTF character (`casting::skin`).
//!
//! UsdSkel skins in skeleton space: `p' = sum w_i * p * inverse(bind_i) *
//! skelSpace_i` with `p` after `geomBindTransform`, row vectors; glTF skins
//! `sum w_i * global_i * inverseBind_i * p`: the same sum with the bind
//! matrices inverted and the points taken after `geomBindTransform`.
//!
//! A clip holds the animation's samples at its time codes, in seconds at the
//! stage's time codes per second, with its first pose held one frame before
//! it and its last one frame after: an agent's cycle frame is 1 + frames
//! since the first sample, so neither a still frame nor a shutter at either
//! end wraps to the other end of the clip.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use glam::{Affine3A, Mat4, Vec4};

use crate::cache::usdskel::{self, SkelAnim, SkelCharacter, SkelFile};
use crate::casting::animation::{Animated, Channel, Clip, Hierarchy, Interpolation, Node, Property, Trs};
use crate::casting::pieces::{joint_boxes, PartTable, SkinPart, SkinPiece, MAX_INFLUENCES};
use crate::error::{Error, Result};
use crate::scene::{Material, Mesh};

/// (slot, mesh prim, part) of each skinned mesh.
type Delivered = Vec<(String, String, usize)>;

/// A UsdSkel character ready to be a `SkinnedRig`.
pub(crate) struct UsdCharacter {
    /// Skeleton nodes and one clip per distinct animation.
    pub(crate) animated: Animated,
    /// Its skinned meshes as parts (one per Mesh prim).
    pub(crate) own: PartTable,
    /// (slot, mesh prim, part) of each mesh, what an agent wears.
    pub(crate) delivered: Delivered,
    /// Materials, by a piece's `material`, each with its base colour texture's file.
    pub(crate) materials: Vec<(Material, Option<PathBuf>)>,
    /// What reading noticed but accepted.
    pub(crate) warnings: Vec<String>,
    /// The uniform scale of the agents' world transforms (the joints are scaled by it).
    pub(crate) scale: f32,
}

/// Whether `path` names a USD file (by extension, as caches are read).
pub(crate) fn is_usd(path: &Path) -> bool {
    crate::cache::Format::of(path).ok() == Some(crate::cache::Format::Usd)
}

fn trs_of(m: &Mat4) -> Trs {
    let (scale, rotation, translation) = m.to_scale_rotation_translation();
    Trs { translation, rotation, scale }
}

/// The UsdSkel files a shot reads, each read once, by canonical path: the
/// cache's reading (`shot_cache::open_for_rigs`) and any other rig file's,
/// so the cache and every rig on one file share one reading of its stage.
#[derive(Default)]
pub(crate) struct SkelFiles {
    files: HashMap<PathBuf, SkelFile>,
}

impl SkelFiles {
    /// Keeps `file`, the reading of `path` (with its characters' meshes).
    pub(crate) fn insert(&mut self, path: &Path, file: SkelFile) -> Result<()> {
        let canonical = std::fs::canonicalize(path).map_err(|e| Error::io(path, e))?;
        self.files.insert(canonical, file);
        Ok(())
    }

    /// The reading of `path`: the one kept, else read now and kept.
    pub(crate) fn get(&mut self, path: &Path) -> Result<&SkelFile> {
        let canonical = std::fs::canonicalize(path).map_err(|e| Error::io(path, e))?;
        if !self.files.contains_key(&canonical) {
            self.files.insert(canonical.clone(), SkelFile::read(path)?);
        }
        Ok(&self.files[&canonical])
    }

    /// The reading of `path` if kept, taken out (the shot keeps its cache's agents for botinfo).
    pub(crate) fn take(&mut self, path: &Path) -> Option<SkelFile> {
        self.files.remove(&std::fs::canonicalize(path).ok()?)
    }
}

/// A character of the UsdSkel crowd at `path` (its reading `file`):
/// SkelRoot `root`'s (the rig's `root`), else the first agent's; its clips
/// timed for the shot's `fps`.
pub(crate) fn character(file: &SkelFile, path: &Path, root: Option<&str>, fps: f32) -> Result<UsdCharacter> {
    let c = file.character(path, root)?;
    let skel = &c.skeleton;
    let top = skel.joints.len();
    let mut nodes: Vec<Node> = (skel.joints.iter().zip(&skel.parents).zip(&skel.rest))
        .map(|((name, parent), rest)| Node {
            name: name.clone(),
            parent: Some(parent.unwrap_or(top)),
            rest: trs_of(rest),
        })
        .collect();
    nodes.push(Node { name: skel.prim.clone(), parent: None, rest: trs_of(&skel.root_from_skel) });
    let hierarchy = Hierarchy::new(nodes);
    let mut clips: Vec<Clip> = c.animations.iter().map(|a| clip(a, f64::from(fps))).collect();
    // Agents bound to no animation hold the rest pose.
    clips.push(Clip { name: usdskel::REST_CYCLE.to_string(), channels: Vec::new(), start: 0.0, end: 0.0 });
    let animated = Animated { path: path.to_path_buf(), hierarchy, clips };
    let (own, delivered, cut) = pieces(path, c)?;
    let warnings = c.warnings.iter().cloned().chain(cut).collect();
    let materials = (c.materials.iter())
        .map(|m| {
            let material = Material {
                name: format!("{}#{}", path.display(), m.prim),
                // A connected diffuseColor ignores its own value: the texture is the colour.
                base_color: if m.diffuse_texture.is_some() { glam::Vec3::ONE } else { m.diffuse },
                roughness: m.roughness.clamp(0.0, 1.0),
                metallic: m.metallic.clamp(0.0, 1.0),
                alpha: m.opacity.clamp(0.0, 1.0),
                ..Material::default()
            };
            (material, m.diffuse_texture.clone())
        })
        .collect();
    Ok(UsdCharacter { animated, own, delivered, materials, warnings, scale: c.scale })
}

/// One animation as a clip: linear keys (rotations slerped, as USD
/// interpolates quaternions), its ends held a frame either side. A time code
/// is a shot frame (the cache's frames are the stage's time codes), so the
/// keys are timed at the shot's `fps`, not the stage's timeCodesPerSecond:
/// cycle frame 1 + k plays time code first + k whatever either rate is.
fn clip(a: &SkelAnim, fps: f64) -> Clip {
    let first = a.times.first().copied().unwrap_or(0.0);
    let frame = (1.0 / fps) as f32;
    let mut times = vec![0.0f32];
    times.extend(a.times.iter().map(|&t| ((t - first) / fps) as f32 + frame));
    times.push(times[times.len() - 1] + frame);
    let held = |k: usize| k.saturating_sub(1).min(a.poses.len().saturating_sub(1));
    let mut channels = Vec::with_capacity(3 * a.joints.len());
    for (j, &node) in a.joints.iter().enumerate() {
        let keys = |f: &dyn Fn(usize) -> Vec4| (0..times.len()).map(|k| f(held(k))).collect::<Vec<Vec4>>();
        let pose = |k: usize| a.poses[k][j];
        for (property, values) in [
            (Property::Translation, keys(&|k| pose(k).0.extend(0.0))),
            (Property::Rotation, keys(&|k| Vec4::from(pose(k).1))),
            (Property::Scale, keys(&|k| pose(k).2.extend(0.0))),
        ] {
            channels.push(Channel {
                node,
                property,
                interpolation: Interpolation::Linear,
                times: times.clone(),
                values,
            });
        }
    }
    let end = times[times.len() - 1];
    Clip { name: a.name.clone(), channels, start: 0.0, end }
}

/// Every skinned mesh as a part of one piece, influences cut to the
/// [`MAX_INFLUENCES`] heaviest (renormalised, with a warning).
fn pieces(path: &Path, c: &SkelCharacter) -> Result<(PartTable, Delivered, Vec<String>)> {
    let canonical = std::fs::canonicalize(path).map_err(|e| Error::io(path, e))?;
    let inverse_bind: Vec<Affine3A> = c.skeleton.bind.iter().map(|m| Affine3A::from_mat4(m.inverse())).collect();
    if inverse_bind.iter().any(|m| !m.is_finite()) {
        return Err(Error::invalid(path, format!("Skeleton <{}>: a bindTransform is singular", c.skeleton.prim))
            .field(format!("{}.bindTransforms", c.skeleton.prim)));
    }
    let mut table = PartTable::default();
    let mut delivered = Vec::new();
    let mut warnings = Vec::new();
    for m in &c.meshes {
        let mut cut = 0;
        let influences: Vec<[(u16, f32); MAX_INFLUENCES]> = (m.influences.iter())
            .map(|inf| {
                let mut sorted = inf.clone();
                sorted.sort_by(|a, b| b.1.total_cmp(&a.1).then(a.0.cmp(&b.0)));
                if sorted.len() > MAX_INFLUENCES {
                    cut += 1;
                    sorted.truncate(MAX_INFLUENCES);
                }
                let sum: f32 = sorted.iter().map(|i| i.1).sum();
                let mut out = [(0u16, 0.0f32); MAX_INFLUENCES];
                for (o, (j, w)) in out.iter_mut().zip(sorted) {
                    *o = (j, w / sum);
                }
                out
            })
            .collect();
        if cut > 0 {
            warnings.push(format!(
                "{}: <{}>: {cut} points have more than {MAX_INFLUENCES} joint influences; the heaviest {MAX_INFLUENCES} are kept",
                path.display(),
                m.prim
            ));
        }
        let mut mesh = Mesh {
            name: format!("{}#{}", path.display(), m.prim),
            positions: m.points.clone(),
            normals: Vec::new(),
            uvs: m.uvs.clone(),
            tangents: Vec::new(),
            indices: m.triangles.clone(),
        };
        mesh.normals = crate::scene::gltf::smooth_normals(&mesh);
        let boxes = joint_boxes(&mesh.positions, &influences, &inverse_bind);
        let piece = table.push_piece(SkinPiece {
            mesh,
            influences,
            joint_nodes: (0..c.skeleton.joints.len()).collect(),
            inverse_bind: inverse_bind.clone(),
            file: path.to_path_buf(),
            material: m.material,
            joint_boxes: boxes,
            proportioned: true,
        });
        let part = table.push_part(SkinPart { pieces: vec![piece] });
        table.keys.insert((canonical.clone(), m.prim.clone()), part);
        let slot = m.prim.rsplit('/').next().unwrap_or(&m.prim).to_string();
        delivered.push((slot, m.prim.clone(), part));
    }
    Ok((table, delivered, warnings))
}
