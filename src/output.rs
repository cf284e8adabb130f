//! Names of rendered files and layers, shared by render (which writes them)
//! and comp (which finds and stacks them), so the two can never disagree.

use std::path::{Path, PathBuf};

/// The render that needs no manifest: the set and every agent, fully visible.
pub const FULL_LAYER: &str = "full";
/// The layer name `throng comp` writes into its EXR header.
pub(crate) const COMP_LAYER: &str = "comp";
/// The set layer.
pub(crate) const SET_LAYER: &str = "set";

/// `crowdN`: the name of crowd layer `index` (0 nearest the camera).
pub(crate) fn crowd_layer_name(index: usize) -> String {
    format!("crowd{index}")
}

/// Crowd layer index of a `crowdN` name.
pub(crate) fn crowd_layer_index(name: &str) -> Option<usize> {
    name.strip_prefix("crowd")?.parse().ok()
}

/// `OUT/<layer>/<shot>.<layer>.<frame:04>.exr`.
pub fn layer_path(out: &Path, shot: &str, layer: &str, frame: i32) -> PathBuf {
    out.join(layer).join(format!("{shot}.{layer}.{frame:04}.exr"))
}

/// The frame of a layer file named as [`layer_path`] names it
/// (`<shot>.<layer>.<frame:04>.exr`), `None` for any other name.
pub(crate) fn layer_file_frame(file_name: &str, shot: &str, layer: &str) -> Option<i32> {
    let digits = file_name.strip_prefix(shot)?.strip_prefix('.')?.strip_prefix(layer)?.strip_prefix('.')?;
    let digits = digits.strip_suffix(".exr")?;
    if digits.len() < 4 || !digits.bytes().all(|b| b.is_ascii_digit() || b == b'-') {
        return None;
    }
    let frame: i32 = digits.parse().ok()?;
    // Only the spelling layer_path gives (so each frame has one file).
    (format!("{frame:04}") == digits).then_some(frame)
}
