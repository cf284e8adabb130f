//! The renderer: a CPU path tracer over a two-level BVH. Its core (`accel`,
//! `integrator`, `surface`, `lights`, `film`) traces [`crate::scene`] types
//! alone; `job` is where it meets the rest of the pipeline (the cast crowd,
//! the layer manifest, the shot, output names) to render a shot's frames
//! and layers into files.
//!
//! Typical use, per run and per frame:
//! ```ignore
//! let blas = BlasSet::build(&library);                 // once per run
//! let film = render_frame(&blas, &library, &frame_scene, &settings, None)?;
//! exr::write_layer(&path, &film, &meta)?;
//! ```
//! Output is deterministic: a pixel depends only on (seed, frame, layer,
//! pixel, sample, dimension), so it is bit-identical for any thread count.

pub mod accel;
pub mod atmosphere;
pub mod bsdf;
pub mod camera;
pub mod colour;
pub mod cryptomatte;
pub mod deep;
pub mod denoise;
pub mod dome;
pub mod exr;
pub mod film;
pub mod integrator;
pub mod job;
pub(crate) mod light_tree;
pub(crate) mod lights;
pub(crate) mod sampler;
pub mod sampling;
pub(crate) mod surface;
pub mod wide;

pub use accel::{BlasSet, Tlas};
pub use film::{render_frame, Film};

/// Settings for rendering one frame of one layer.
#[derive(Clone, Debug, PartialEq)]
pub struct RenderSettings {
    /// Image width in pixels.
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Camera samples per pixel.
    pub spp: u32,
    /// Maximum BSDF-sampled bounces after the camera ray (1 = direct light
    /// only: sun by shadow rays, sky by one bounce ray).
    pub max_bounces: u32,
    /// Shot seed.
    pub seed: u64,
    /// Shot frame number (part of every sample's key).
    pub frame: i64,
    /// Layer index (part of every sample's key).
    pub layer: u32,
    /// Camera rays that escape see the sky (colour, alpha 1). Set layers turn
    /// this on; crowd layers leave it off (escaped camera rays: black, alpha 0).
    pub sky_visible: bool,
    /// Render threads; 0 = all cores.
    pub threads: usize,
    /// Largest RGB component any single indirect contribution (bounce 1 and
    /// later) may add to a sample; 0 = no clamp. Like Arnold's indirect
    /// sample clamp: removes fireflies at the cost of a little energy.
    pub indirect_clamp: f32,
    /// Shade every material as pure Lambert with its (textured) base colour,
    /// ignoring metallic and roughness. For comparisons with other renderers'
    /// plain diffuse materials (benchmarks); off for production.
    pub diffuse_only: bool,
    /// Light-path passes, light groups and position to write (scene::passes).
    pub passes: crate::scene::passes::PassSet,
    /// Adaptive sampling (`spp` is then not used): see [`film`]'s docs.
    pub adaptive: Option<crate::shot::Adaptive>,
    /// How rays are traced (the image is the same bits on every choice).
    pub tracing: Tracing,
    /// The shot's air (haze, fog), traced as its mode says; `None`: clear.
    pub atmosphere: Option<atmosphere::Atmosphere>,
    /// The index of each pixel's first camera sample (0: a whole render).
    /// A progressive render (`review::live`) takes passes of `spp` samples
    /// one after another, each from where the last stopped, so passes of
    /// n1, n2, ... samples are the samples of one n1 + n2 + ... render.
    /// Not with adaptive sampling, which starts every pixel at 0.
    pub first_sample: u32,
}

/// How rays are traced: choices that change the speed of a render, never
/// its pixels. The product always uses the default; benchmarks and tests
/// set them to compare one choice against another in one process.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Tracing {
    /// The BVH traversal kernel ([`wide`]).
    pub traversal: wide::Traversal,
    /// Each pixel's camera rays traced together as packets
    /// ([`Tlas::intersect_stream`]), or one at a time.
    pub camera_packets: bool,
    /// The tree the TLAS is built as.
    pub tlas: accel::TlasKind,
}

impl Default for Tracing {
    fn default() -> Self {
        Tracing { traversal: wide::Traversal::Wide, camera_packets: true, tlas: accel::TlasKind::CwBvh }
    }
}

impl Default for RenderSettings {
    fn default() -> Self {
        RenderSettings {
            width: 960,
            height: 540,
            spp: 16,
            max_bounces: 4,
            seed: 0,
            frame: 0,
            layer: 0,
            sky_visible: false,
            threads: 0,
            indirect_clamp: 10.0,
            diffuse_only: false,
            passes: crate::scene::passes::PassSet::default(),
            adaptive: None,
            tracing: Tracing::default(),
            atmosphere: None,
            first_sample: 0,
        }
    }
}
