//! throng: a crowd renderer and level-of-detail layering tool for film
//! lighters. Modules in pipeline order; docs/architecture.md says what each
//! owns and what passes between them.
#![warn(missing_docs)]
// The public API is deliberate (docs/architecture.md, "The public API"):
// `pub` only for what the CLI, tests, examples and fuzz targets use, every
// other item `pub(crate)` or private; a `pub` item nothing outside can reach,
// or a type the API hands out that cannot be named, fails clippy -D warnings.
#![warn(unreachable_pub, unnameable_types)]
#![forbid(unsafe_code)]
#![allow(
    clippy::neg_cmp_op_on_partial_ord,
    reason = "`!(x > 0.0)` is how input checks reject NaN along with out-of-range values"
)]

pub mod bench;
pub mod botinfo; // a cast crowd + agent ids -> the botInfo block of each
pub mod cache; // simulation caches (.crowd, CSV, JuPedSim) -> per-frame agent samples
pub mod casting; // shot + cache + rigs + wardrobes -> `ShotCrowd`: every agent dressed, any frame posed

pub mod comp; // a frame's layer EXRs -> one stacked EXR
pub mod error; // typed errors naming file, line, frame, agent and field; atomic writes
pub mod export; // a cast frame -> glTF (.glb); a frame range -> USD (.usda/.usd/.usdz)
pub(crate) mod exr_guard; // limits on reading OpenEXR files (headers checked against the file size)
pub mod farm; // a shot -> a render-farm task graph (the plan); engines (local, slurm) and status
pub mod fingerprint; // the one change detector (FNV-1a 64): files in blocks, named fields
pub mod layers; // a cast crowd -> the layer manifest (membership, LOD, visibility) and its map
pub mod output; // names of rendered files and layers, shared by render and comp
pub mod render; // a cast crowd + manifest -> path-traced multi-channel EXR layers
pub mod review; // a shot's renders, manifest and botInfo -> a local read-only web page (`throng review`)
pub mod scene; // the shared vocabulary: meshes, materials, instances, visibility, camera, lights; glTF loading
pub(crate) mod seed; // keyed random draws (seed, agent, purpose), shared by casting and the simulation
pub mod shot; // the shot file (TOML) -> a checked `Shot`: frames, camera, rigs, wardrobes, render and layer settings
pub mod sim; // a steering scene -> a cache (the reference crowd simulation) // process figures (CPU time, peak RSS) for the benchmark examples
