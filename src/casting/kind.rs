//! Which kind of rig a file is: a slot rig (nodes with slot extras), a
//! skinned character (a skin) or a rigid one (meshes on animated nodes).
//! The one rule every reader of a rig file follows: the shot's `[rigs]`, the
//! simulation's `[rigs]`, a trajectory import's rig file and the slot-rig
//! loader's refusal of a character.

use std::path::Path;

use crate::error::{Error, Result};
use crate::scene::gltf::GltfFile;
use crate::shot::{RigKind, RigRef, SkinOptions};

/// Whether a glTF file holds a skin (a skinned character, not a slot rig).
pub(crate) fn is_skinned(file: &GltfFile) -> bool {
    file.doc.skins().len() > 0
}

/// Whether any node of the file is a slot (extras with a `"slot"` key):
/// what tells a slot rig from a skinned character when both have a skin.
pub(crate) fn has_slots(file: &GltfFile) -> bool {
    file.doc.nodes().any(|n| {
        n.extras()
            .as_ref()
            .is_some_and(|e| serde_json::from_str::<serde_json::Value>(e.get()).is_ok_and(|v| v.get("slot").is_some()))
    })
}

/// Whether a shot's rig is a character posed from its node animation
/// (skinned or rigid, a `SkinnedRig`) rather than a slot rig: its `kind`,
/// else detected from the file ([`is_character_file`]).
pub(crate) fn is_character_rig(rig: &RigRef) -> Result<bool> {
    match rig.kind {
        Some(k) => Ok(k != RigKind::Slots),
        None => is_character_file(&rig.file),
    }
}

/// Whether a rig file with no `kind` is a character (skinned or rigid): no
/// node has slot extras. A skin then makes it skinned, else it is rigid
/// (meshes on animated nodes: the Kenney alien, a car).
pub(crate) fn is_character_file(path: &Path) -> Result<bool> {
    // A UsdSkel crowd's file is its character (casting::usdskel_rig).
    if crate::casting::usdskel_rig::is_usd(path) {
        return Ok(true);
    }
    let file = GltfFile::open(path)?;
    Ok(!has_slots(&file))
}

/// Whether the rig in `file` is read as a character outside a shot (a
/// trajectory import's rig file): `skin` given says so, else it is
/// detected as a shot's rig without `kind` is (no slots).
pub(crate) fn is_character_import(file: &Path, skin: Option<&SkinOptions>) -> Result<bool> {
    match skin {
        Some(_) => Ok(true),
        None => is_character_file(file),
    }
}

/// The kind a simulation scene's `[rigs]` table entry declares: its `kind`,
/// else `skinned` when it gives a character's keys (`root`, `cycles`,
/// `strides`, `scale`, `up`, `forward`), so the file's skin then decides
/// skinned or rigid (docs/sim.md). A shot's `[rigs.NAME]` declares only its
/// `kind`: there a detected slot rig ignores those keys.
pub(crate) fn declared_in_sim(kind: Option<RigKind>, character_keys: bool) -> Option<RigKind> {
    kind.or(character_keys.then_some(RigKind::Skinned))
}

/// The error for a skinned file used where rigid geometry is expected.
pub(crate) fn skinned_refusal(path: &Path, what: &str) -> Error {
    Error::invalid(
        path,
        format!(
            "{what} is a skinned character (the file has a skin): slot rigs and wardrobe parts for them are rigid. \
             Declare it as a skinned rig in the shot, `[rigs.NAME] file = \"...\"` with `kind = \"skinned\"` \
             (docs/wardrobes.md, \"Bringing an animated character\")"
        ),
    )
}
