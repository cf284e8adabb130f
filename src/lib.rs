//! throng: a crowd renderer and level-of-detail layering tool for film
//! lighters. Stages, in pipeline order (see DESIGN.md):
//! cache -> casting -> layers -> scene -> render -> comp.
#![warn(missing_docs)]

pub mod cache;
pub mod cli;
pub mod error;
pub mod render;
pub mod scene;
