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
