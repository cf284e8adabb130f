//! A character's gait (skinned or rigid): its walk's stride and length
//! and its idle's length, as a trajectory import walks at them. Slot rigs'
//! gaits and the dispatch between the two are `casting::shot_cache`'s.

use std::path::Path;

use crate::cache::jupedsim::SHOT_FPS;
use crate::cache::tabular::Gait;
use crate::casting::skin::SkinnedRig;
use crate::error::{Error, Result};
use crate::shot::SkinOptions;

/// A skinned character's gait: its walk cycle's stride (the root joint's
/// travel, or the shot's `strides`) and length; `None` when it has no such
/// cycle. A walk whose stride is 0 (no root, no given stride) is refused.
pub(crate) fn skinned_gait(rig: &SkinnedRig, walk: &str, idle: Option<&str>) -> Result<Option<Gait>> {
    let Ok((stride, cycle_length)) = rig.cycle_timing(walk) else { return Ok(None) };
    if !(stride.is_finite() && stride > 0.0 && cycle_length.is_finite() && cycle_length > 0.0) {
        let root = match rig.is_rigid() {
            true => "the rigid rig's clip turns no wheel: name its root node",
            false => "name its root joint",
        };
        return Err(Error::invalid(
            rig.path(),
            format!("cycle `{walk}` walks {stride} m in {cycle_length} frames: {root} (`root`) or give `strides`"),
        )
        .field("cycle"));
    }
    let idle_length = match idle {
        Some(name) => rig.cycle_frames(rig.cycle_index(name).map_err(|e| e.field("idle_cycle"))?),
        None => Gait::default().idle_length,
    };
    Ok(Some(Gait { stride, cycle_length, idle_length }))
}

/// The gait of a file known to be a skinned or rigid character (`skin`
/// `None`: the default options; `stride` given: the walk's `strides` entry).
pub(crate) fn skinned_file_gait(
    file: &Path,
    skin: Option<&SkinOptions>,
    walk: &str,
    idle: Option<&str>,
    stride: Option<f32>,
) -> Result<Gait> {
    let mut options = skin.cloned().unwrap_or_default();
    if let Some(s) = stride {
        options.strides.insert(walk.to_string(), s);
    }
    let rig = SkinnedRig::load(file, &options, SHOT_FPS)?;
    // The error lists the rig's cycles; past it the walk is there.
    rig.cycle_index(walk).map_err(|e| e.field("cycle"))?;
    skinned_gait(&rig, walk, idle)?
        .ok_or_else(|| Error::invalid(file, format!("skinned rig has no cycle `{walk}`")).field("cycle"))
}
