//! throng: a crowd renderer and level-of-detail layering tool for film
//! lighters. Stages, in pipeline order (see DESIGN.md):
//! cache -> casting -> layers -> scene -> render -> comp.
#![warn(missing_docs)]

pub mod assets;
pub mod bench;
pub mod cache;
pub mod casting;
pub mod cli;
pub mod commands;
pub mod comp;
pub mod error;
pub mod export;
pub mod gltf_out;
pub mod layers;
pub mod pose;
pub mod render;
pub mod rig;
pub mod scene;
pub mod shot;
pub mod sim;
pub mod wardrobe;
