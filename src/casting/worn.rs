//! The parts dressing adds to each character: the wardrobe parts of other
//! files (and a rigid rig's parts on its slots) and the props hung on its
//! joints. They go into a table per rig, kept by the dressing, whose indices
//! run on from the character's own parts and pieces, so the characters stay
//! as loaded and are shared by reference.

use std::collections::BTreeMap;
use std::path::Path;

use glam::{Affine3A, Vec3};

use crate::casting::pieces::{PartReader, PartTable, SkinPart, SkinPiece};
use crate::casting::skin::SkinnedRig;
use crate::error::{Error, Result};
use crate::scene::gltf::GltfFile;

/// The parts dressing loaded for each skinned rig, by rig name.
#[derive(Clone, Debug, Default)]
pub(crate) struct WornParts {
    tables: BTreeMap<String, PartTable>,
}

impl WornParts {
    /// A reader of parts for rig `name`, into its table.
    fn reader<'a>(&'a mut self, name: &str, rig: &'a SkinnedRig) -> PartReader<'a> {
        let table = self.tables.entry(name.to_string()).or_insert_with(|| PartTable::after(rig.own_parts()));
        PartReader {
            path: rig.path(),
            canonical: rig.canonical(),
            hierarchy: rig.hierarchy(),
            known: rig.own_parts(),
            table,
        }
    }

    /// The part for a wardrobe's `file` + `mesh` (a name or `#index`) worn
    /// in `slot` of rig `name`, loading it on first use. A rigid rig's part
    /// rides the slot's node, modelled in that node's space as the node's
    /// own mesh is.
    pub(crate) fn part(
        &mut self,
        (name, rig): (&str, &SkinnedRig),
        file: &Path,
        mesh_ref: &str,
        slot: &str,
    ) -> Result<usize> {
        let canonical = std::fs::canonicalize(file).map_err(|e| Error::io(file, e))?;
        // The rig's own mesh on its own node (what an agent wears as delivered).
        let own = rig.delivered().iter().find(|(s, m, _)| s == slot && m == mesh_ref);
        if let (true, Some(&(_, _, part))) = (rig.is_rigid() && canonical == rig.canonical(), own) {
            return Ok(part);
        }
        let key_name = match rig.is_rigid() {
            true => format!("{mesh_ref} on {slot}"),
            false => mesh_ref.to_string(),
        };
        let mut reader = self.reader(name, rig);
        if let Some(i) = reader.find(&(canonical.clone(), key_name.clone())) {
            return Ok(i);
        }
        let gltf = GltfFile::open(file)?;
        if !rig.is_rigid() {
            return reader.load_part(&gltf, &canonical, mesh_ref);
        }
        let node = rig.slot_node(slot)?;
        let gmesh = gltf.mesh_by_ref(mesh_ref)?;
        // A skinned mesh would be drawn in its bind pose on the node: refused, as on a slot rig.
        if gltf.doc.nodes().any(|n| n.skin().is_some() && n.mesh().is_some_and(|m| m.index() == gmesh.index())) {
            return Err(gltf
                .err(format!(
                    "mesh `{mesh_ref}` is skinned; a rigid rig's parts ride their slot's node (`{slot}`) rigidly: \
                     wear it on a skinned rig, or export it without its skin"
                ))
                .field("mesh"));
        }
        reader.load_rigid_part(&gltf, &canonical, node, &gmesh, &key_name)
    }

    /// A wardrobe prop for rig `name`: mesh `mesh` of `file` hung on joint
    /// `joint` at `joint_from_prop` (metres, in the joint's frame with its
    /// rest-pose scale taken out, so the rig's `scale` and a scaled armature
    /// leave the prop its size), bound wholly to the joint as a
    /// joint-attached mesh is; loaded once per (file, mesh, joint, offset).
    pub(crate) fn prop_part(
        &mut self,
        (name, rig): (&str, &SkinnedRig),
        file: &Path,
        mesh: &str,
        (joint, joint_from_prop): (&str, Affine3A),
    ) -> Result<usize> {
        let node = (rig.hierarchy().find(joint))
            .ok_or_else(|| Error::invalid(rig.path(), format!("no joint `{joint}` to hang a prop on")))?;
        let canonical = std::fs::canonicalize(file).map_err(|e| Error::io(file, e))?;
        let bits: Vec<String> = joint_from_prop.to_cols_array().iter().map(|v| format!("{:x}", v.to_bits())).collect();
        let key = (canonical, format!("{mesh}@{joint}/{}", bits.join(",")));
        let mut reader = self.reader(name, rig);
        if let Some(i) = reader.find(&key) {
            return Ok(i);
        }
        let (scale, _, _) = rig.rest_joint(node).to_scale_rotation_translation();
        let unscale = Affine3A::from_scale(Vec3::ONE / scale.max(Vec3::splat(1e-12)));
        let gltf = GltfFile::open(file)?;
        let gmesh = gltf.mesh_by_name(mesh)?;
        let label = format!("{}#{mesh}@{joint}", gltf.path.display());
        let i = reader.rigid_pieces(&gltf, &gmesh, node, unscale * joint_from_prop, &label, false)?;
        reader.table.keys.insert(key, i);
        Ok(i)
    }

    /// Part `i` of rig `name`: the character's own, or one dressing loaded.
    pub(crate) fn part_at<'a>(&'a self, name: &str, rig: &'a SkinnedRig, i: usize) -> &'a SkinPart {
        match rig.own_parts().part(i) {
            Some(part) => part,
            None => self.tables.get(name).and_then(|t| t.part(i)).expect("a part index dressing gave out"),
        }
    }

    /// Piece `i` of rig `name`: the character's own, or one dressing loaded.
    pub(crate) fn piece<'a>(&'a self, name: &str, rig: &'a SkinnedRig, i: usize) -> &'a SkinPiece {
        match rig.own_parts().piece(i) {
            Some(piece) => piece,
            None => self.tables.get(name).and_then(|t| t.piece(i)).expect("a piece index dressing gave out"),
        }
    }

    /// What loading rig `name`'s worn parts noticed (weights renormalised,
    /// morph targets ignored), in order.
    pub(crate) fn warnings(&self, name: &str) -> &[String] {
        self.tables.get(name).map_or(&[], |t| t.warnings.as_slice())
    }
}
