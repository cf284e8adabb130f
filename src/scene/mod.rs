//! The render-facing scene: meshes and materials loaded once and shared,
//! and per-frame instances that reference them. Casting and the set loader
//! produce these; the renderer and `throng export` consume them.
//!
//! INTERFACE (shared by casting, export and the renderer; keep stable).

pub mod atmosphere;
pub mod dome;
pub mod gltf;
pub mod light_gains;
pub mod lights;
pub mod passes;

use glam::{Affine3A, Vec2, Vec3, Vec4};

/// `render.working_colourspace` (read by `shot`): the RGB space light is computed in. Every
/// input colour (materials, textures, lights) is authored in linear Rec.709;
/// with `Acescg` the renderer converts them to ACEScg (AP1) as it loads them
/// (`render::colour`) and the EXRs say so.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Colourspace {
    /// Linear Rec.709 / sRGB primaries, D65 white.
    #[default]
    Rec709,
    /// ACEScg: linear AP1 primaries, the ACES white (about D60).
    Acescg,
}

/// Index into [`Library::meshes`].
pub(crate) type MeshId = u32;
/// Index into [`Library::materials`].
pub(crate) type MaterialId = u32;

/// A triangle mesh in object space.
#[derive(Clone, Debug, Default)]
pub struct Mesh {
    /// Unique name, e.g. `parts/heads.glb#head_sphere` or `proxy_box`.
    pub name: String,
    /// Vertex positions.
    pub positions: Vec<Vec3>,
    /// Per-vertex normals (same length as positions, or empty for flat shading).
    pub normals: Vec<Vec3>,
    /// Per-vertex texture coordinates (same length as positions, or empty).
    pub uvs: Vec<Vec2>,
    /// Per-vertex tangents for normal maps, glTF TANGENT: xyz along +u, w
    /// the bitangent's sign (bitangent = w * normal x tangent). Same length as
    /// positions, or empty: the renderer then derives a tangent per triangle
    /// from its UVs.
    pub tangents: Vec<Vec4>,
    /// Triangle list, three indices per triangle.
    pub indices: Vec<u32>,
}

impl Mesh {
    /// Axis-aligned bounds (min, max); zero box for an empty mesh.
    pub fn bounds(&self) -> (Vec3, Vec3) {
        let mut it = self.positions.iter();
        let Some(&first) = it.next() else { return (Vec3::ZERO, Vec3::ZERO) };
        it.fold((first, first), |(lo, hi), &p| (lo.min(p), hi.max(p)))
    }
    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }
    /// Unit cube centred on the origin, flat shaded (no normals or UVs):
    /// test scenes and synthetic benchmark crowds.
    pub fn cube(name: &str) -> Mesh {
        let positions = (0..8)
            .map(|i| Vec3::new((i & 1) as f32 - 0.5, ((i >> 1) & 1) as f32 - 0.5, ((i >> 2) & 1) as f32 - 0.5))
            .collect();
        let faces = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]];
        let indices = faces.iter().flat_map(|f| [f[0], f[1], f[2], f[0], f[2], f[3]]).collect();
        Mesh { name: name.into(), positions, indices, ..Default::default() }
    }

    /// UV sphere centred on the origin with smooth normals and UVs.
    pub fn uv_sphere(name: &str, radius: f32, rings: u32, segments: u32) -> Mesh {
        use std::f32::consts::PI;
        let mut m = Mesh { name: name.into(), ..Default::default() };
        for r in 0..=rings {
            let theta = PI * r as f32 / rings as f32;
            for s in 0..=segments {
                let phi = 2.0 * PI * s as f32 / segments as f32;
                let n = Vec3::new(theta.sin() * phi.cos(), theta.cos(), theta.sin() * phi.sin());
                m.positions.push(radius * n);
                m.normals.push(n);
                m.uvs.push(Vec2::new(s as f32 / segments as f32, r as f32 / rings as f32));
            }
        }
        let row = segments + 1;
        for r in 0..rings {
            for s in 0..segments {
                let (a, b) = (r * row + s, (r + 1) * row + s);
                m.indices.extend_from_slice(&[a, a + 1, b, a + 1, b + 1, b]);
            }
        }
        m
    }

    /// Bytes of geometry this mesh holds (positions, normals, uvs, tangents, indices).
    pub(crate) fn bytes(&self) -> usize {
        self.positions.len() * 12
            + self.normals.len() * 12
            + self.uvs.len() * 8
            + self.tangents.len() * 16
            + self.indices.len() * 4
    }
}

/// The eight corners of the box `lo..hi`.
pub(crate) fn box_corners(lo: Vec3, hi: Vec3) -> [Vec3; 8] {
    std::array::from_fn(|c| {
        Vec3::new(
            if c & 1 == 0 { lo.x } else { hi.x },
            if c & 2 == 0 { lo.y } else { hi.y },
            if c & 4 == 0 { lo.z } else { hi.z },
        )
    })
}

/// An RGBA texture in linear colour (sRGB decoded on load).
#[derive(Clone, Debug, Default)]
pub struct Texture {
    /// Name (file or glTF image name).
    pub name: String,
    /// Width in texels.
    pub width: u32,
    /// Height in texels.
    pub height: u32,
    /// Row-major texels, top row first, linear RGBA.
    pub texels: Vec<[f32; 4]>,
}

/// glTF `alphaMode`: how a material's alpha (base colour factor alpha x
/// base colour texture alpha) is used. Alpha is coverage: where the surface
/// is not there, every ray (camera, shadow, bounce) passes through it.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub enum AlphaMode {
    /// Alpha is ignored: the surface is everywhere.
    #[default]
    Opaque,
    /// The surface is there where alpha >= `cutoff` (glTF alphaCutoff, default 0.5).
    Mask {
        /// Alpha below this is a hole.
        cutoff: f32,
    },
    /// Stochastic coverage: a ray passes through with probability 1 - alpha,
    /// decided by a hash of the ray and the triangle (deterministic).
    Blend,
}

/// glTF KHR_texture_transform on one texture reference: `uv' = T R S uv`
/// (offset, rotation in radians, scale), and the UV set the texture reads
/// (`texCoord`, the transform's override if it has one). throng reads
/// TEXCOORD_0 only: a texture on another set is left out.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct UvTransform {
    /// Offset, in units of the texture.
    pub offset: Vec2,
    /// Rotation, radians (the glTF extension's sense).
    pub rotation: f32,
    /// Scale.
    pub scale: Vec2,
    /// The UV set (TEXCOORD_n).
    pub tex_coord: u32,
}

impl UvTransform {
    /// No transform, UV set 0.
    pub const IDENTITY: UvTransform = UvTransform { offset: Vec2::ZERO, rotation: 0.0, scale: Vec2::ONE, tex_coord: 0 };

    /// The texture coordinate `uv` maps to: scaled, rotated, then offset, as
    /// KHR_texture_transform's matrix `translation * rotation * scale`. The
    /// identity returns `uv` itself, bit for bit.
    #[inline]
    pub fn apply(&self, uv: Vec2) -> Vec2 {
        if self.offset == Vec2::ZERO && self.rotation == 0.0 && self.scale == Vec2::ONE {
            return uv;
        }
        let s = uv * self.scale;
        let (sin, cos) = self.rotation.sin_cos();
        Vec2::new(cos * s.x + sin * s.y, cos * s.y - sin * s.x) + self.offset
    }
}

impl Default for UvTransform {
    fn default() -> Self {
        UvTransform::IDENTITY
    }
}

/// A texture a material reads: which one, and through which transform.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TextureRef {
    /// Index into [`Library::textures`].
    pub texture: u32,
    /// KHR_texture_transform and UV set.
    pub uv: UvTransform,
}

impl TextureRef {
    /// Texture `texture` with no transform, UV set 0.
    pub fn plain(texture: u32) -> TextureRef {
        TextureRef { texture, uv: UvTransform::IDENTITY }
    }
}

/// KHR_materials_volume: the mesh encloses a solid of the material's `ior`
/// (rays refract where they enter and leave), absorbing by Beer's law.
/// Without it a transmissive material is a thin wall.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Volume {
    /// The colour white light becomes after `attenuation_distance` inside.
    pub attenuation_color: Vec3,
    /// Metres; infinite: no absorption.
    pub attenuation_distance: f32,
}

impl Volume {
    /// Absorption coefficient per metre, per channel: -ln(colour) / distance.
    pub(crate) fn absorption(&self) -> Vec3 {
        let d = self.attenuation_distance;
        if !(d.is_finite() && d > 0.0) {
            return Vec3::ZERO;
        }
        let c = self.attenuation_color.clamp(Vec3::splat(1e-6), Vec3::ONE);
        Vec3::new(-c.x.ln(), -c.y.ln(), -c.z.ln()) / d
    }
}

/// glTF metallic-roughness material, with the extensions a lit set needs
/// (docs/render.md, Materials).
#[derive(Clone, Debug, PartialEq)]
pub struct Material {
    /// Unique name, e.g. `robots/chrome`.
    pub name: String,
    /// Linear base colour factor.
    pub base_color: Vec3,
    /// Optional base colour texture, index into [`Library::textures`]; multiplies the factor.
    pub base_color_texture: Option<u32>,
    /// KHR_texture_transform of the base colour texture.
    pub base_color_uv: UvTransform,
    /// Perceptual roughness 0..1.
    pub roughness: f32,
    /// Metalness 0..1.
    pub metallic: f32,
    /// glTF metallicRoughnessTexture (linear): G multiplies roughness, B metallic.
    pub metallic_roughness_texture: Option<TextureRef>,
    /// Emitted radiance, W/(m^2 sr), linear: glTF emissiveFactor x
    /// KHR_materials_emissive_strength. Emitted from the front face
    /// (counter-clockwise winding) only; zero for most materials.
    pub emission: Vec3,
    /// Optional emissive texture, index into [`Library::textures`]; multiplies `emission`.
    pub emissive_texture: Option<u32>,
    /// KHR_texture_transform of the emissive texture.
    pub emissive_uv: UvTransform,
    /// Base colour factor alpha (coverage; see `alpha_mode`).
    pub alpha: f32,
    /// glTF alphaMode.
    pub alpha_mode: AlphaMode,
    /// glTF doubleSided. Kept for export; every surface renders from both
    /// sides (docs/render.md says why).
    pub double_sided: bool,
    /// Tangent-space normal map (linear; glTF normalTexture).
    pub normal_texture: Option<TextureRef>,
    /// glTF normalTexture.scale: scales the map's X and Y.
    pub normal_scale: f32,
    /// KHR_materials_transmission factor 0..1: the share of the light
    /// entering a dielectric surface that goes through it (0: opaque).
    pub transmission: f32,
    /// Transmission texture (linear, R channel); multiplies `transmission`.
    pub transmission_texture: Option<TextureRef>,
    /// KHR_materials_ior, >= 1 (glTF default 1.5): the dielectric's Fresnel and refraction.
    pub ior: f32,
    /// KHR_materials_volume; `None`: thin-walled.
    pub volume: Option<Volume>,
}

impl Default for Material {
    fn default() -> Self {
        Material {
            name: "default".into(),
            base_color: Vec3::splat(0.8),
            base_color_texture: None,
            base_color_uv: UvTransform::IDENTITY,
            roughness: 0.5,
            metallic: 0.0,
            metallic_roughness_texture: None,
            emission: Vec3::ZERO,
            emissive_texture: None,
            emissive_uv: UvTransform::IDENTITY,
            alpha: 1.0,
            alpha_mode: AlphaMode::Opaque,
            double_sided: true,
            normal_texture: None,
            normal_scale: 1.0,
            transmission: 0.0,
            transmission_texture: None,
            ior: 1.5,
            volume: None,
        }
    }
}

impl Material {
    /// The name a lighter gives the material: a glTF material's own name
    /// (its unique name is `<file as the shot spells it>#<name>`, which
    /// changes with the folder the shot is read from), else the whole name.
    pub fn label(&self) -> &str {
        self.name.split_once('#').map_or(&self.name, |(_, label)| label)
    }

    /// Whether rays may pass through holes in it (alpha MASK or BLEND).
    pub(crate) fn has_cutouts(&self) -> bool {
        self.alpha_mode != AlphaMode::Opaque
    }
}

/// The colourspace a library's colours are in, as a type: a cast shot's
/// library is [`Rec709`] as authored, and converting it for an ACEScg render
/// gives an [`Acescg`] one, which has no conversion left to apply twice.
pub trait Space {
    /// The colourspace this marker names.
    const COLOURSPACE: Colourspace;
}

/// Linear Rec.709 (D65): every input colour as authored.
#[derive(Debug, Clone, Copy)]
pub enum Rec709 {}

/// ACEScg (AP1 primaries, the ACES white): the render's working space when asked.
#[derive(Debug, Clone, Copy)]
pub enum Acescg {}

impl Space for Rec709 {
    const COLOURSPACE: Colourspace = Colourspace::Rec709;
}

impl Space for Acescg {
    const COLOURSPACE: Colourspace = Colourspace::Acescg;
}

/// Meshes, materials and textures, each loaded once and shared by every
/// instance that uses it.
#[derive(Clone, Debug, Default)]
pub struct Library {
    /// Unique meshes.
    pub meshes: Vec<Mesh>,
    /// Unique materials.
    pub materials: Vec<Material>,
    /// Unique textures.
    pub textures: Vec<Texture>,
}

/// Visibility bits of an instance, per ray type. Which bits an instance gets
/// comes from the layer manifest, never from the renderer.
pub mod vis {
    /// Seen directly by camera rays and contributes colour and alpha.
    pub const CAMERA: u8 = 1;
    /// Blocks shadow rays.
    pub const SHADOW: u8 = 2;
    /// Seen by secondary (reflection / indirect) rays.
    pub const INDIRECT: u8 = 4;
    /// Holdout: occludes camera rays but gives alpha 0 and no colour.
    pub const HOLDOUT: u8 = 8;
    /// A normal, fully visible object.
    pub const ALL: u8 = CAMERA | SHADOW | INDIRECT;
}

/// One placed copy of a mesh.
#[derive(Clone, Copy, Debug)]
pub struct Instance {
    /// Which mesh.
    pub mesh: MeshId,
    /// Which material.
    pub material: MaterialId,
    /// Object to world.
    pub world_from_object: Affine3A,
    /// Cache agent id; none for the set.
    pub agent: InstanceAgent,
    /// Part index within the agent: its rig slot, or a prop after the slots
    /// (`crate::casting::AgentCast::props`); for the set, the index of the set
    /// object (the glTF node placing it) in the shot's set object names
    /// (`ShotCrowd::set_names()`, what Cryptomatte calls it).
    pub part: u16,
    /// [`vis`] bits.
    pub visibility: u8,
}

/// An instance's cache agent id, or none for the set: kept as the id's
/// complement in a non-zero word, so an [`Instance`] is 80 bytes, not 96
/// (13 million of them at a million robots). Id `u32::MAX` is refused when
/// the cache is read ([`crate::casting::check_agent_id`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct InstanceAgent(Option<std::num::NonZeroU32>);

impl InstanceAgent {
    /// Set geometry: no agent.
    pub const NONE: InstanceAgent = InstanceAgent(None);

    /// Agent `id` (below `u32::MAX`).
    pub fn some(id: u32) -> InstanceAgent {
        debug_assert!(id != u32::MAX, "agent id u32::MAX is refused at load");
        InstanceAgent(std::num::NonZeroU32::new(!id))
    }

    /// The agent id, `None` for the set.
    pub fn get(self) -> Option<u32> {
        self.0.map(|n| !n.get())
    }
}

/// A camera: a pinhole, or a thin lens when `aperture` > 0.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Camera to world; the camera looks down its local -Z with +Y up (glTF convention).
    pub world_from_camera: Affine3A,
    /// Vertical field of view in radians.
    pub yfov: f32,
    /// Radius of the lens aperture in scene units (focal length / (2 f-stop));
    /// 0 is a pinhole: everything in focus.
    pub aperture: f32,
    /// Distance from the camera to the plane in focus, along its view axis.
    pub focus_distance: f32,
}

impl Camera {
    /// A pinhole camera (no depth of field).
    pub fn pinhole(world_from_camera: Affine3A, yfov: f32) -> Camera {
        Camera { world_from_camera, yfov, aperture: 0.0, focus_distance: 1.0 }
    }
}

/// A distant sun with a finite angular size.
#[derive(Clone, Copy, Debug)]
pub struct Sun {
    /// Unit vector from the scene towards the sun.
    pub direction: Vec3,
    /// Full angular diameter in radians (0.0093 for the real sun).
    pub angular_diameter: f32,
    /// Irradiance at normal incidence, linear RGB (W/m^2).
    pub irradiance: Vec3,
}

/// A uniform sky dome.
#[derive(Clone, Copy, Debug, Default)]
pub struct Sky {
    /// Radiance, linear RGB.
    pub radiance: Vec3,
}

/// A deforming instance: its vertices blend from [`Instance::mesh`] towards
/// `mesh` (the same piece at another pose step: same topology) with a weight
/// that runs linearly from `weight[0]` at shutter open to `weight[1]` at close.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Deform {
    /// The mesh blended towards (same vertex count and indices).
    pub(crate) mesh: MeshId,
    /// Blend weight of `mesh` at shutter open and at close, in 0..=1.
    pub(crate) weight: [f32; 2],
}

/// How one instance moves over the shutter. The instance itself holds the
/// shutter-open key; this holds the close key.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct InstanceMotion {
    /// Object to world at shutter close (linear in between).
    pub world_from_object_close: Affine3A,
    /// Deformation blur, if the instance's mesh changes over the shutter.
    pub deform: Option<Deform>,
}

impl InstanceMotion {
    /// An instance that does not move: its close key equals its open key.
    pub(crate) fn still(inst: &Instance) -> InstanceMotion {
        InstanceMotion { world_from_object_close: inst.world_from_object, deform: None }
    }
}

/// Motion over the shutter of one frame scene (motion blur).
#[derive(Clone, Debug)]
pub struct SceneMotion {
    /// Shutter `[open, close]` in frames relative to the frame.
    pub shutter: [f32; 2],
    /// Per instance (parallel to [`FrameScene::instances`]): its close key.
    pub instances: Vec<InstanceMotion>,
    /// The camera at shutter open and at close.
    pub camera: [Camera; 2],
}

/// Everything to trace for one frame of one layer.
#[derive(Clone, Debug)]
pub struct FrameScene {
    /// Instances (agents' parts and the set). With motion, at shutter open.
    pub instances: Vec<Instance>,
    /// The camera at this frame.
    pub camera: Camera,
    /// Every light: the sun, the sky or a dome, local lights. (Emissive
    /// materials light the scene too.)
    pub lights: lights::SceneLights,
    /// Motion over the shutter; `None` renders the frame as an instant.
    pub motion: Option<SceneMotion>,
}

// 13 million instances at a million robots: every byte counts 13 MB.
const _: () = assert!(std::mem::size_of::<Instance>() == 80);
