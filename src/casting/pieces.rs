//! Skinned pieces read from glTF: a character's meshes (skinned, or riding
//! a node), each primitive a [`SkinPiece`] with its influences, grouped into
//! the parts a wardrobe chooses, in a [`PartTable`]. A character's own parts
//! are read once when it loads; the parts a dressing adds (other files'
//! meshes, props on joints) go into a table of the dressing's, numbered on
//! from the character's, so the character stays as loaded.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use glam::{Affine3A, Mat4, Vec3};
use gltf::accessor::{DataType, Dimensions};

use crate::casting::animation::Hierarchy;
use crate::error::Result;
use crate::scene::gltf::{check_accessor, lift_decals, out_of_range, read_primitive, GltfFile};
use crate::scene::Mesh;

/// Most influences per vertex (JOINTS_0/WEIGHTS_0 and JOINTS_1/WEIGHTS_1).
pub(crate) const MAX_INFLUENCES: usize = 8;
/// Weight sums further than this from 1 are renormalised with a warning.
const WEIGHT_SUM_TOLERANCE: f32 = 1e-3;

/// One skinned primitive: bind-pose geometry and per-vertex influences.
#[derive(Clone, Debug)]
pub struct SkinPiece {
    /// Bind geometry in mesh space, named `<file>#<mesh>[/<primitive>]`.
    pub(crate) mesh: Mesh,
    /// Per vertex: (joint, weight), joints indexing `joint_nodes`;
    /// unused influences have weight 0. Weights sum to 1.
    pub influences: Vec<[(u16, f32); MAX_INFLUENCES]>,
    /// Skin joint -> node index in the rig's hierarchy.
    pub(crate) joint_nodes: Vec<usize>,
    /// Skin joint -> inverse bind matrix.
    pub(crate) inverse_bind: Vec<Affine3A>,
    /// The file the mesh came from (its own materials are looked up there).
    pub(crate) file: PathBuf,
    /// The primitive's glTF material index in `file`.
    pub(crate) material: Option<usize>,
    /// Per skin joint: bounds, in joint space, of the vertices weighted
    /// mostly to that joint (`None` for joints that dominate no vertex).
    pub(crate) joint_boxes: Vec<Option<(Vec3, Vec3)>>,
    /// Whether a body's proportions stretch it (false for props, which a
    /// hand carries at their own size).
    pub(crate) proportioned: bool,
}

/// A skinned mesh a wardrobe can choose: every primitive of one glTF mesh.
#[derive(Clone, Debug)]
pub(crate) struct SkinPart {
    /// Indices of its pieces ([`PartTable::piece`]).
    pub(crate) pieces: Vec<usize>,
}

/// Parts keyed by (canonical file, mesh or node name), with their pieces.
/// Part and piece indices run on from the table below it (a dressing's
/// from its character's own), so one index names one piece either way.
#[derive(Clone, Debug, Default)]
pub(crate) struct PartTable {
    /// (canonical file, mesh reference or part name) -> part index.
    pub(crate) keys: BTreeMap<(PathBuf, String), usize>,
    parts: Vec<SkinPart>,
    pieces: Vec<SkinPiece>,
    /// Index of this table's first part and first piece.
    first_part: usize,
    first_piece: usize,
    /// What reading the parts noticed (weights renormalised, morph targets ignored), in order.
    pub(crate) warnings: Vec<String>,
}

impl PartTable {
    /// An empty table whose indices run on from `below`'s.
    pub(crate) fn after(below: &PartTable) -> PartTable {
        PartTable {
            first_part: below.first_part + below.parts.len(),
            first_piece: below.first_piece + below.pieces.len(),
            ..PartTable::default()
        }
    }

    /// The part at index `i`, if this table holds it.
    pub(crate) fn part(&self, i: usize) -> Option<&SkinPart> {
        self.parts.get(i.checked_sub(self.first_part)?)
    }

    /// The piece at index `i`, if this table holds it.
    pub(crate) fn piece(&self, i: usize) -> Option<&SkinPiece> {
        self.pieces.get(i.checked_sub(self.first_piece)?)
    }

    /// How many pieces this table holds.
    pub(crate) fn piece_count(&self) -> usize {
        self.pieces.len()
    }

    pub(crate) fn push_piece(&mut self, piece: SkinPiece) -> usize {
        self.pieces.push(piece);
        self.first_piece + self.pieces.len() - 1
    }

    pub(crate) fn push_part(&mut self, part: SkinPart) -> usize {
        self.parts.push(part);
        self.first_part + self.parts.len() - 1
    }
}

/// Reads parts into `table` for the character whose skeleton is
/// `hierarchy` (file `path`, canonically `canonical`): a part `known`
/// already holds is not read again.
pub(crate) struct PartReader<'a> {
    /// The character's file, for messages.
    pub(crate) path: &'a Path,
    /// `path` canonicalised: parts are keyed by it, so two spellings of one file are one file.
    pub(crate) canonical: &'a Path,
    /// The skeleton a part's joints are bound to by name.
    pub(crate) hierarchy: &'a Hierarchy,
    /// Parts already read (the character's own, when a dressing reads).
    pub(crate) known: &'a PartTable,
    /// Where new parts go.
    pub(crate) table: &'a mut PartTable,
}

impl PartReader<'_> {
    /// The part known under `key`, in either table.
    pub(crate) fn find(&self, key: &(PathBuf, String)) -> Option<usize> {
        self.known.keys.get(key).or_else(|| self.table.keys.get(key)).copied()
    }

    /// Reads glTF mesh `mesh_ref` (a name, or `#index`) of `file` as a part,
    /// binding its skin's joints to this rig's nodes by name.
    pub(crate) fn load_part(&mut self, file: &GltfFile, canonical: &Path, mesh_ref: &str) -> Result<usize> {
        let key = (canonical.to_path_buf(), mesh_ref.to_string());
        if let Some(i) = self.find(&key) {
            return Ok(i);
        }
        let gmesh = file.mesh_by_ref(mesh_ref)?;
        // Known under its other spelling (name or `#index`)?
        for other in [format!("#{}", gmesh.index())].into_iter().chain(gmesh.name().map(str::to_string)) {
            if let Some(i) = self.find(&(canonical.to_path_buf(), other)) {
                self.table.keys.insert(key, i);
                return Ok(i);
            }
        }
        let label = match gmesh.name() {
            Some(name) => format!("{}#{name}", file.path.display()),
            None => format!("{} mesh #{}", file.path.display(), gmesh.index()),
        };
        // The skin of the node that uses this mesh (a skinned mesh is drawn
        // by a node with both `mesh` and `skin`).
        let skin = file
            .doc
            .nodes()
            .find(|n| n.mesh().is_some_and(|m| m.index() == gmesh.index()) && n.skin().is_some())
            .and_then(|n| n.skin())
            .ok_or_else(|| {
                file.err(format!(
                    "mesh {label} is not skinned (no node draws it with a skin); a skinned rig wears skinned meshes"
                ))
            })?;
        let (joint_nodes, inverse_bind) = self.read_skin(file, canonical == self.canonical, &skin, &label)?;
        let mut pieces = Vec::new();
        let single = gmesh.primitives().len() == 1;
        for prim in gmesh.primitives() {
            let name = if single { label.clone() } else { format!("{label}/{}", prim.index()) };
            let piece = self.read_piece(file, &gmesh, &prim, name, &joint_nodes, &inverse_bind)?;
            pieces.push(self.table.push_piece(piece));
        }
        if gmesh.weights().is_some() || gmesh.primitives().any(|p| p.morph_targets().len() > 0) {
            self.table.warnings.push(format!("{label}: morph targets are ignored (skinning only)"));
        }
        let i = self.table.push_part(SkinPart { pieces });
        self.table.keys.insert(key, i);
        Ok(i)
    }

    /// The mesh `gmesh` of node `node` (named `name`), not skinned, as a
    /// part whose every vertex follows that node alone: one influence of
    /// weight 1, an identity bind (the vertices are in the node's space).
    pub(crate) fn load_rigid_part(
        &mut self,
        file: &GltfFile,
        canonical: &Path,
        node: usize,
        gmesh: &gltf::Mesh,
        name: &str,
    ) -> Result<usize> {
        let key = (canonical.to_path_buf(), name.to_string());
        if let Some(i) = self.find(&key) {
            return Ok(i);
        }
        let label = format!("{}#{name}", file.path.display());
        let i = self.rigid_pieces(file, gmesh, node, Affine3A::IDENTITY, &label, true)?;
        self.table.keys.insert(key, i);
        Ok(i)
    }

    /// Every primitive of `gmesh` as a piece bound wholly to node `node`
    /// (one influence of weight 1), its vertices in that node's space by
    /// `bind`: a new part, whose index is returned. `proportioned`: whether
    /// a body's proportions stretch it (a prop keeps its size).
    pub(crate) fn rigid_pieces(
        &mut self,
        file: &GltfFile,
        gmesh: &gltf::Mesh,
        node: usize,
        bind: Affine3A,
        label: &str,
        proportioned: bool,
    ) -> Result<usize> {
        let single = gmesh.primitives().len() == 1;
        let mut pieces = Vec::new();
        let mut meshes = Vec::new();
        for prim in gmesh.primitives() {
            let piece_name = if single { label.to_string() } else { format!("{label}/{}", prim.index()) };
            meshes.push(read_primitive(file, gmesh, &prim, piece_name)?);
        }
        lift_decals(&mut meshes);
        for (prim, mesh) in gmesh.primitives().zip(meshes) {
            let mut one = [(0u16, 0.0f32); MAX_INFLUENCES];
            one[0].1 = 1.0;
            let bounds = mesh
                .positions
                .iter()
                .map(|&p| bind.transform_point3(p))
                .fold(None, |b: Option<(Vec3, Vec3)>, p| Some(b.map_or((p, p), |(lo, hi)| (lo.min(p), hi.max(p)))));
            pieces.push(self.table.push_piece(SkinPiece {
                influences: vec![one; mesh.positions.len()],
                mesh,
                joint_nodes: vec![node],
                inverse_bind: vec![bind],
                file: file.path.clone(),
                material: prim.material().index(),
                joint_boxes: vec![bounds],
                proportioned,
            }));
        }
        if gmesh.weights().is_some() || gmesh.primitives().any(|p| p.morph_targets().len() > 0) {
            self.table.warnings.push(format!("{label}: morph targets are ignored (rigid on its joint)"));
        }
        Ok(self.table.push_part(SkinPart { pieces }))
    }

    /// A skin's joints as this rig's node indices, and its inverse bind
    /// matrices. Joints of another file are matched to this rig by name.
    fn read_skin(
        &self,
        file: &GltfFile,
        same_file: bool,
        skin: &gltf::Skin,
        label: &str,
    ) -> Result<(Vec<usize>, Vec<Affine3A>)> {
        let ctx = |msg: String| file.err(format!("skin {} of mesh {label}: {msg}", skin.index()));
        let joints: Vec<gltf::Node> = skin.joints().collect();
        if joints.is_empty() || joints.len() > u16::MAX as usize {
            return Err(ctx(format!("{} joints (1 to {} allowed)", joints.len(), u16::MAX)));
        }
        let mut joint_nodes = Vec::with_capacity(joints.len());
        for j in &joints {
            let node = if same_file {
                j.index()
            } else {
                let name = j.name().unwrap_or("");
                self.hierarchy.find(name).ok_or_else(|| {
                    ctx(format!(
                        "joint `{name}` is not in the rig's skeleton {}: a part must be bound to the same skeleton",
                        self.path.display()
                    ))
                })?
            };
            joint_nodes.push(node);
        }
        let acc = skin.inverse_bind_matrices().ok_or_else(|| {
            ctx("has no inverseBindMatrices accessor; throng needs them (exporters write them; the glTF identity default means joints bound at the origin, almost always a broken export)".into())
        })?;
        check_accessor(&acc, Dimensions::Mat4, &[DataType::F32])
            .map_err(|m| ctx(format!("inverseBindMatrices: {m}")))?;
        let reader = skin.reader(|b| file.buffer_data(b));
        let ibm: Vec<Affine3A> = reader
            .read_inverse_bind_matrices()
            .ok_or_else(|| ctx(out_of_range(&acc)))?
            .map(|m| Affine3A::from_mat4(Mat4::from_cols_array_2d(&m)))
            .collect();
        if ibm.len() != joints.len() {
            return Err(ctx(format!(
                "accessor {}: {} inverse bind matrices for {} joints",
                acc.index(),
                ibm.len(),
                joints.len()
            )));
        }
        if ibm.iter().any(|m| !m.is_finite()) {
            return Err(ctx(format!("accessor {}: an inverse bind matrix is not finite", acc.index())));
        }
        Ok((joint_nodes, ibm))
    }

    fn read_piece(
        &mut self,
        file: &GltfFile,
        gmesh: &gltf::Mesh,
        prim: &gltf::Primitive,
        name: String,
        joint_nodes: &[usize],
        inverse_bind: &[Affine3A],
    ) -> Result<SkinPiece> {
        let mesh = read_primitive(file, gmesh, prim, name.clone())?;
        let n = mesh.positions.len();
        let ctx = |msg: String| file.err(format!("mesh {name}: {msg}"));
        if prim.get(&gltf::Semantic::Joints(2)).is_some() || prim.get(&gltf::Semantic::Weights(2)).is_some() {
            return Err(ctx(format!(
                "JOINTS_2/WEIGHTS_2: more than {MAX_INFLUENCES} influences per vertex are not supported"
            )));
        }
        let reader = prim.reader(|b| file.buffer_data(b));
        let mut influences = vec![[(0u16, 0.0f32); MAX_INFLUENCES]; n];
        let mut sets = 0;
        for set in 0..2u32 {
            let (ja, wa) = (prim.get(&gltf::Semantic::Joints(set)), prim.get(&gltf::Semantic::Weights(set)));
            let (ja, wa) = match (ja, wa) {
                (None, None) => continue,
                (Some(j), Some(w)) => (j, w),
                _ => return Err(ctx(format!("JOINTS_{set} and WEIGHTS_{set} must come together"))),
            };
            check_accessor(&ja, Dimensions::Vec4, &[DataType::U8, DataType::U16])
                .map_err(|m| ctx(format!("JOINTS_{set}: {m}")))?;
            check_accessor(&wa, Dimensions::Vec4, &[DataType::F32, DataType::U8, DataType::U16])
                .map_err(|m| ctx(format!("WEIGHTS_{set}: {m}")))?;
            let joints: Vec<[u16; 4]> =
                reader.read_joints(set).ok_or_else(|| ctx(out_of_range(&ja)))?.into_u16().collect();
            let weights: Vec<[f32; 4]> =
                reader.read_weights(set).ok_or_else(|| ctx(out_of_range(&wa)))?.into_f32().collect();
            if joints.len() != n || weights.len() != n {
                return Err(ctx(format!(
                    "JOINTS_{set} (accessor {}) has {} and WEIGHTS_{set} (accessor {}) {} entries for {n} vertices",
                    ja.index(),
                    joints.len(),
                    wa.index(),
                    weights.len()
                )));
            }
            for (v, (j, w)) in joints.iter().zip(&weights).enumerate() {
                for k in 0..4 {
                    if !(w[k] >= 0.0 && w[k].is_finite()) {
                        return Err(ctx(format!(
                            "WEIGHTS_{set} (accessor {}) vertex {v}: weight {} is not a finite number >= 0",
                            wa.index(),
                            w[k]
                        )));
                    }
                    if w[k] > 0.0 && j[k] as usize >= joint_nodes.len() {
                        return Err(ctx(format!(
                            "JOINTS_{set} (accessor {}) vertex {v}: joint {} is out of range (the skin has {} joints)",
                            ja.index(),
                            j[k],
                            joint_nodes.len()
                        )));
                    }
                    influences[v][set as usize * 4 + k] = (j[k], w[k]);
                }
            }
            sets += 1;
        }
        if sets == 0 {
            return Err(ctx("has no JOINTS_0/WEIGHTS_0 but its node has a skin".into()));
        }
        let mut renormalised = 0;
        for (v, inf) in influences.iter_mut().enumerate() {
            let sum: f32 = inf.iter().map(|i| i.1).sum();
            if sum <= 0.0 {
                return Err(ctx(format!("vertex {v} has no joint weight (its weights sum to 0)")));
            }
            if (sum - 1.0).abs() > WEIGHT_SUM_TOLERANCE {
                renormalised += 1;
            }
            for i in inf.iter_mut() {
                i.1 /= sum;
            }
        }
        if renormalised > 0 {
            self.table.warnings.push(format!(
                "{}: mesh {name}: {renormalised} of {n} vertices have joint weights that do not sum to 1; renormalised",
                file.path.display()
            ));
        }
        let joint_boxes = joint_boxes(&mesh.positions, &influences, inverse_bind);
        Ok(SkinPiece {
            mesh,
            influences,
            joint_nodes: joint_nodes.to_vec(),
            inverse_bind: inverse_bind.to_vec(),
            file: file.path.clone(),
            material: prim.material().index(),
            joint_boxes,
            proportioned: true,
        })
    }
}

/// Per-joint proxy boxes: the vertices weighted mostly to a joint, in its
/// bind space (`None` for joints that dominate no vertex).
pub(crate) fn joint_boxes(
    positions: &[Vec3],
    influences: &[[(u16, f32); MAX_INFLUENCES]],
    inverse_bind: &[Affine3A],
) -> Vec<Option<(Vec3, Vec3)>> {
    let mut boxes: Vec<Option<(Vec3, Vec3)>> = vec![None; inverse_bind.len()];
    for (p, inf) in positions.iter().zip(influences) {
        let Some(&(j, _)) = inf.iter().max_by(|a, b| a.1.total_cmp(&b.1)) else { continue };
        let q = inverse_bind[j as usize].transform_point3(*p);
        let b = &mut boxes[j as usize];
        *b = Some(b.map_or((q, q), |(lo, hi)| (lo.min(q), hi.max(q))));
    }
    boxes
}
