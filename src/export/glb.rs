//! A small glTF 2.0 binary (.glb) writer built on `gltf::json`.
//!
//! Used by the demo generator (`examples/make_demo.rs`) and by `throng export`.
//! Everything goes into one binary buffer; every accessor gets its own
//! 4-byte-aligned buffer view, so the output is simple to inspect.
//!
//! ```no_run
//! use throng::export::glb::{GlbBuilder, MeshData, MaterialDesc, NodeDesc};
//! let mut glb = GlbBuilder::new();
//! let grey = glb.add_material(&MaterialDesc::new("grey", [0.5, 0.5, 0.5, 1.0]));
//! let quad = MeshData {
//!     positions: vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0]],
//!     normals: vec![[0.0, 0.0, 1.0]; 3],
//!     uvs: vec![[0.0, 0.0]; 3],
//!     indices: vec![0, 1, 2],
//!     ..Default::default()
//! };
//! let mesh = glb.add_mesh("tri", &quad, Some(grey)).unwrap();
//! glb.add_node(NodeDesc::new("tri").mesh(mesh));
//! glb.write(std::path::Path::new("out.glb")).unwrap();
//! ```

use std::collections::BTreeMap;
use std::io::Write;
use std::path::Path;

use gltf::json;
use json::validation::{Checked, USize64};

use crate::error::{write_atomic, Error, IoContext, Result};

/// Name used in errors raised while building (there is no file yet).
const WRITER: &str = "<glb writer>";

/// Handle of a mesh added to a [`GlbBuilder`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MeshId(u32);
/// Handle of a material added to a [`GlbBuilder`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MaterialId(u32);
/// Handle of a skin added to a [`GlbBuilder`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SkinId(u32);
/// Handle of a node added to a [`GlbBuilder`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct NodeId(u32);

impl NodeId {
    /// The glTF node index.
    pub(crate) fn index(self) -> usize {
        self.0 as usize
    }
}

/// Triangle geometry of one primitive. `normals`, `uvs`, `joints` and
/// `weights` are either empty or as long as `positions`; `indices` holds three
/// per triangle. `joints` and `weights` (JOINTS_0/WEIGHTS_0) come together and
/// make the primitive skinned: draw it from a node with [`NodeDesc::skin`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MeshData {
    /// Vertex positions.
    pub positions: Vec<[f32; 3]>,
    /// Unit vertex normals (or empty).
    pub normals: Vec<[f32; 3]>,
    /// Texture coordinates (or empty).
    pub uvs: Vec<[f32; 2]>,
    /// Triangle list.
    pub indices: Vec<u32>,
    /// Up to four skin joints per vertex, indexing the skin's joint list (or empty).
    pub joints: Vec<[u16; 4]>,
    /// The weights of `joints`, each vertex's summing to 1 (or empty).
    pub weights: Vec<[f32; 4]>,
}

impl MeshData {
    /// Number of triangles.
    pub fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }

    /// Axis-aligned bounds (min, max); zeros for an empty mesh.
    pub fn bounds(&self) -> ([f32; 3], [f32; 3]) {
        if self.positions.is_empty() {
            return ([0.0; 3], [0.0; 3]);
        }
        let mut lo = [f32::INFINITY; 3];
        let mut hi = [f32::NEG_INFINITY; 3];
        for p in &self.positions {
            for k in 0..3 {
                lo[k] = lo[k].min(p[k]);
                hi[k] = hi[k].max(p[k]);
            }
        }
        (lo, hi)
    }

    fn check(&self, name: &str) -> Result<()> {
        let n = self.positions.len();
        let bad = |msg: String| Err(Error::invalid(WRITER, msg).field(name.to_string()));
        if n == 0 || self.indices.is_empty() {
            return bad(format!("mesh `{name}` has no triangles"));
        }
        if !self.normals.is_empty() && self.normals.len() != n {
            return bad(format!("mesh `{name}`: {} normals for {n} positions", self.normals.len()));
        }
        if !self.uvs.is_empty() && self.uvs.len() != n {
            return bad(format!("mesh `{name}`: {} uvs for {n} positions", self.uvs.len()));
        }
        if self.joints.len() != self.weights.len() {
            return bad(format!(
                "mesh `{name}`: {} joints and {} weights; skinning needs both per vertex",
                self.joints.len(),
                self.weights.len()
            ));
        }
        if !self.joints.is_empty() && self.joints.len() != n {
            return bad(format!("mesh `{name}`: {} joints for {n} positions", self.joints.len()));
        }
        if let Some(v) = self.weights.iter().position(|w| {
            let sum: f32 = w.iter().sum();
            w.iter().any(|x| !(x.is_finite() && *x >= 0.0)) || (sum - 1.0).abs() > 1e-3
        }) {
            return bad(format!(
                "mesh `{name}`: vertex {v}: weights {:?} are not finite, >= 0 and summing to 1",
                self.weights[v]
            ));
        }
        if !self.indices.len().is_multiple_of(3) {
            return bad(format!("mesh `{name}`: {} indices is not a triangle list", self.indices.len()));
        }
        if let Some(i) = self.indices.iter().find(|&&i| i as usize >= n) {
            return bad(format!("mesh `{name}`: index {i} out of range ({n} vertices)"));
        }
        if self.positions.iter().flatten().any(|v| !v.is_finite()) {
            return bad(format!("mesh `{name}` has a non-finite position"));
        }
        Ok(())
    }
}

/// A glTF metallic-roughness material.
#[derive(Clone, Debug, PartialEq)]
pub struct MaterialDesc {
    /// Material name.
    pub(crate) name: String,
    /// Linear RGBA base colour factor.
    pub(crate) base_color: [f32; 4],
    /// Metalness 0..1.
    pub(crate) metallic: f32,
    /// Perceptual roughness 0..1.
    pub(crate) roughness: f32,
    /// Optional base colour texture: PNG file bytes, embedded in the buffer.
    pub(crate) base_color_png: Option<Vec<u8>>,
    /// Render both faces.
    pub double_sided: bool,
    /// Emitted radiance (linear RGB, W/(m^2 sr) in throng's units): written
    /// as `emissiveFactor` scaled into 0..1, with the rest as
    /// KHR_materials_emissive_strength. Black: not emissive.
    pub emission: [f32; 3],
}

impl MaterialDesc {
    /// A dielectric material with roughness 0.5.
    pub fn new(name: impl Into<String>, base_color: [f32; 4]) -> Self {
        MaterialDesc {
            name: name.into(),
            base_color,
            metallic: 0.0,
            roughness: 0.5,
            base_color_png: None,
            double_sided: false,
            emission: [0.0; 3],
        }
    }
    /// Sets metalness and roughness.
    pub fn pbr(mut self, metallic: f32, roughness: f32) -> Self {
        self.metallic = metallic;
        self.roughness = roughness;
        self
    }
    /// Embeds a PNG as the base colour texture.
    pub fn texture_png(mut self, png: Vec<u8>) -> Self {
        self.base_color_png = Some(png);
        self
    }
    /// Makes the material emit `radiance` from its front faces.
    pub fn emission(mut self, radiance: [f32; 3]) -> Self {
        self.emission = radiance;
        self
    }
}

/// A node's local transform.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) enum Transform {
    /// Translation, rotation quaternion (x, y, z, w) and scale.
    Trs {
        /// Translation.
        translation: [f32; 3],
        /// Unit quaternion (x, y, z, w).
        rotation: [f32; 4],
        /// Scale.
        scale: [f32; 3],
    },
    /// Column-major 4x4 matrix.
    Matrix([f32; 16]),
}

impl Transform {
    /// The identity (written as no transform at all).
    pub(crate) const IDENTITY: Transform =
        Transform::Trs { translation: [0.0; 3], rotation: [0.0, 0.0, 0.0, 1.0], scale: [1.0; 3] };
}

/// A node to add; build with [`NodeDesc::new`] and the setters.
#[derive(Clone, Debug, PartialEq)]
pub struct NodeDesc {
    /// Node name.
    pub(crate) name: String,
    /// Local transform.
    pub(crate) transform: Transform,
    /// Children (added earlier or later; see [`GlbBuilder::add_child`]).
    pub(crate) children: Vec<NodeId>,
    /// Mesh drawn at this node; several nodes may share one mesh.
    pub(crate) mesh: Option<MeshId>,
    /// Application data written as the node's `extras`.
    pub(crate) extras: Option<serde_json::Value>,
    /// Skin deforming this node's mesh (the mesh must carry joints and weights).
    pub(crate) skin: Option<SkinId>,
}

impl NodeDesc {
    /// A node with identity transform, no mesh, no children.
    pub fn new(name: impl Into<String>) -> Self {
        NodeDesc {
            name: name.into(),
            transform: Transform::IDENTITY,
            children: Vec::new(),
            mesh: None,
            extras: None,
            skin: None,
        }
    }
    /// Sets the translation (keeping any rotation and scale).
    pub fn translation(mut self, t: [f32; 3]) -> Self {
        self.transform = match self.transform {
            Transform::Trs { rotation, scale, .. } => Transform::Trs { translation: t, rotation, scale },
            Transform::Matrix(_) => Transform::Trs { translation: t, rotation: [0.0, 0.0, 0.0, 1.0], scale: [1.0; 3] },
        };
        self
    }
    /// Sets the rotation quaternion (x, y, z, w) (keeping translation and scale).
    pub fn rotation(mut self, r: [f32; 4]) -> Self {
        self.transform = match self.transform {
            Transform::Trs { translation, scale, .. } => Transform::Trs { translation, rotation: r, scale },
            Transform::Matrix(_) => Transform::Trs { translation: [0.0; 3], rotation: r, scale: [1.0; 3] },
        };
        self
    }
    /// Sets the scale (keeping translation and rotation).
    pub fn scale(mut self, s: [f32; 3]) -> Self {
        self.transform = match self.transform {
            Transform::Trs { translation, rotation, .. } => Transform::Trs { translation, rotation, scale: s },
            Transform::Matrix(_) => Transform::Trs { translation: [0.0; 3], rotation: [0.0, 0.0, 0.0, 1.0], scale: s },
        };
        self
    }
    /// Sets a column-major matrix transform instead of TRS.
    #[cfg(test)] // the tests write a matrix node
    pub(crate) fn matrix(mut self, m: [f32; 16]) -> Self {
        self.transform = Transform::Matrix(m);
        self
    }
    /// Sets the mesh.
    pub fn mesh(mut self, mesh: MeshId) -> Self {
        self.mesh = Some(mesh);
        self
    }
    /// Sets the skin that deforms this node's mesh. glTF ignores a skinned
    /// mesh node's own transform, so leave it at identity.
    pub fn skin(mut self, skin: SkinId) -> Self {
        self.skin = Some(skin);
        self
    }
    /// Sets the children.
    pub(crate) fn children(mut self, children: Vec<NodeId>) -> Self {
        self.children = children;
        self
    }
    /// Sets the extras.
    pub fn extras(mut self, extras: serde_json::Value) -> Self {
        self.extras = Some(extras);
        self
    }
}

/// Animation sampler interpolation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Interpolation {
    /// Hold each key until the next.
    Step,
    /// Linear (slerp for rotations).
    Linear,
    /// Cubic Hermite; values hold (in-tangent, value, out-tangent) per key.
    CubicSpline,
}

/// Key values of one channel. With [`Interpolation::CubicSpline`] there are
/// three entries per key: in-tangent, value, out-tangent.
#[derive(Clone, Debug, PartialEq)]
pub enum ChannelValues {
    /// Node translation.
    Translation(Vec<[f32; 3]>),
    /// Node rotation quaternions (x, y, z, w).
    Rotation(Vec<[f32; 4]>),
    /// Node scale.
    Scale(Vec<[f32; 3]>),
}

impl ChannelValues {
    fn len(&self) -> usize {
        match self {
            ChannelValues::Translation(v) | ChannelValues::Scale(v) => v.len(),
            ChannelValues::Rotation(v) => v.len(),
        }
    }
}

/// One animated property of one node.
#[derive(Clone, Debug, PartialEq)]
pub struct ChannelDesc {
    /// Target node.
    pub node: NodeId,
    /// Sampler interpolation.
    pub interpolation: Interpolation,
    /// Key times in seconds, strictly increasing.
    pub times: Vec<f32>,
    /// Key values.
    pub values: ChannelValues,
}

/// A named animation (clip).
#[derive(Clone, Debug, PartialEq)]
pub struct AnimationDesc {
    /// Clip name, e.g. `WalkA`.
    pub name: String,
    /// Channels.
    pub channels: Vec<ChannelDesc>,
}

/// A perspective camera.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Perspective {
    /// Vertical field of view, radians.
    pub yfov: f32,
    /// Width / height.
    pub aspect_ratio: Option<f32>,
    /// Near clip distance.
    pub znear: f32,
    /// Far clip distance (None: infinite).
    pub zfar: Option<f32>,
}

/// The unit quaternion (x, y, z, w) that turns a node's local -Z (where glTF
/// cameras and lights point) to `forward`, with local +Y as close to `up` as
/// possible.
pub fn rotation_looking_along(forward: [f32; 3], up: [f32; 3]) -> [f32; 4] {
    use glam::{Mat3, Quat, Vec3};
    let f = Vec3::from(forward).normalize_or(Vec3::NEG_Z);
    let mut x = f.cross(Vec3::from(up));
    if x.length_squared() < 1e-12 {
        // forward is parallel to up: any perpendicular will do.
        x = f.any_orthonormal_vector();
    }
    let x = x.normalize();
    let y = x.cross(f);
    let q = Quat::from_mat3(&Mat3::from_cols(x, y, -f)).normalize();
    q.to_array()
}

/// The kind of a KHR_lights_punctual light.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PunctualKind {
    /// A sun: lux, down the node's -Z.
    Directional,
    /// A point: candela.
    Point,
    /// A spot: candela on its axis, cone angles in radians from it.
    Spot {
        /// Where the edge's falloff begins.
        inner: f32,
        /// Where it ends.
        outer: f32,
    },
}

/// Builds a .glb in memory. Add meshes, materials, nodes, animations, a
/// camera and lights, then call [`GlbBuilder::finish`] or [`GlbBuilder::write`].
/// Nodes that are nobody's child become the roots of the single scene.
#[derive(Debug)]
pub struct GlbBuilder {
    root: json::Root,
    bin: Vec<u8>,
    generator: String,
    /// Per mesh: the highest joint index its primitives use (`None`: unskinned).
    mesh_max_joint: Vec<Option<u16>>,
}

impl Default for GlbBuilder {
    fn default() -> Self {
        Self::new()
    }
}

impl GlbBuilder {
    /// An empty document.
    pub fn new() -> Self {
        let mut root = json::Root::default();
        root.asset.generator = Some(format!("throng {}", env!("CARGO_PKG_VERSION")));
        let generator = root.asset.generator.clone().unwrap_or_default();
        GlbBuilder { root, bin: Vec::new(), generator, mesh_max_joint: Vec::new() }
    }

    /// Sets `asset.generator` (default `throng <version>`).
    pub fn set_generator(&mut self, generator: impl Into<String>) {
        self.generator = generator.into();
    }

    /// Appends bytes as one buffer view, aligned to 4 bytes.
    fn push_view(&mut self, bytes: &[u8], target: Option<json::buffer::Target>) -> json::Index<json::buffer::View> {
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        let offset = self.bin.len();
        self.bin.extend_from_slice(bytes);
        self.root.push(json::buffer::View {
            buffer: json::Index::new(0),
            byte_length: USize64::from(bytes.len()),
            byte_offset: Some(USize64::from(offset)),
            byte_stride: None,
            extensions: None,
            extras: None,
            name: None,
            target: target.map(Checked::Valid),
        })
    }

    /// Adds an f32 accessor of `type_` (components per element implied).
    fn push_f32_accessor(
        &mut self,
        data: &[f32],
        type_: json::accessor::Type,
        target: Option<json::buffer::Target>,
        min_max: bool,
    ) -> json::Index<json::Accessor> {
        let comps = type_.multiplicity();
        let bytes: Vec<u8> = data.iter().flat_map(|v| v.to_le_bytes()).collect();
        let view = self.push_view(&bytes, target);
        let (min, max) = if min_max {
            let mut lo = vec![f32::INFINITY; comps];
            let mut hi = vec![f32::NEG_INFINITY; comps];
            for e in data.chunks_exact(comps) {
                for k in 0..comps {
                    lo[k] = lo[k].min(e[k]);
                    hi[k] = hi[k].max(e[k]);
                }
            }
            (Some(serde_json::json!(lo)), Some(serde_json::json!(hi)))
        } else {
            (None, None)
        };
        self.root.push(json::Accessor {
            buffer_view: Some(view),
            byte_offset: None,
            count: USize64::from(data.len() / comps),
            component_type: Checked::Valid(json::accessor::GenericComponentType(json::accessor::ComponentType::F32)),
            extensions: None,
            extras: None,
            type_: Checked::Valid(type_),
            min,
            max,
            name: None,
            normalized: false,
            sparse: None,
        })
    }

    /// Adds a u16 VEC4 vertex attribute accessor (JOINTS_0).
    fn push_joints_accessor(&mut self, joints: &[[u16; 4]]) -> json::Index<json::Accessor> {
        let bytes: Vec<u8> = joints.iter().flatten().flat_map(|v| v.to_le_bytes()).collect();
        let view = self.push_view(&bytes, Some(json::buffer::Target::ArrayBuffer));
        self.root.push(json::Accessor {
            buffer_view: Some(view),
            byte_offset: None,
            count: USize64::from(joints.len()),
            component_type: Checked::Valid(json::accessor::GenericComponentType(json::accessor::ComponentType::U16)),
            extensions: None,
            extras: None,
            type_: Checked::Valid(json::accessor::Type::Vec4),
            min: None,
            max: None,
            name: None,
            normalized: false,
            sparse: None,
        })
    }

    fn push_index_accessor(&mut self, indices: &[u32]) -> json::Index<json::Accessor> {
        let bytes: Vec<u8> = indices.iter().flat_map(|v| v.to_le_bytes()).collect();
        let view = self.push_view(&bytes, Some(json::buffer::Target::ElementArrayBuffer));
        self.root.push(json::Accessor {
            buffer_view: Some(view),
            byte_offset: None,
            count: USize64::from(indices.len()),
            component_type: Checked::Valid(json::accessor::GenericComponentType(json::accessor::ComponentType::U32)),
            extensions: None,
            extras: None,
            type_: Checked::Valid(json::accessor::Type::Scalar),
            min: None,
            max: None,
            name: None,
            normalized: false,
            sparse: None,
        })
    }

    fn primitive(
        &mut self,
        name: &str,
        data: &MeshData,
        material: Option<MaterialId>,
    ) -> Result<json::mesh::Primitive> {
        use json::accessor::Type;
        use json::buffer::Target::ArrayBuffer;
        use json::mesh::Semantic;
        data.check(name)?;
        if let Some(m) = material {
            if m.0 as usize >= self.root.materials.len() {
                return Err(Error::invalid(WRITER, format!("mesh `{name}`: unknown material")).field("material"));
            }
        }
        let mut attributes = BTreeMap::new();
        let flat = |v: &[[f32; 3]]| v.iter().flatten().copied().collect::<Vec<f32>>();
        // The glTF spec requires POSITION min/max.
        let pos = self.push_f32_accessor(&flat(&data.positions), Type::Vec3, Some(ArrayBuffer), true);
        attributes.insert(Checked::Valid(Semantic::Positions), pos);
        if !data.normals.is_empty() {
            let nrm = self.push_f32_accessor(&flat(&data.normals), Type::Vec3, Some(ArrayBuffer), false);
            attributes.insert(Checked::Valid(Semantic::Normals), nrm);
        }
        if !data.uvs.is_empty() {
            let uv: Vec<f32> = data.uvs.iter().flatten().copied().collect();
            let uv = self.push_f32_accessor(&uv, Type::Vec2, Some(ArrayBuffer), false);
            attributes.insert(Checked::Valid(Semantic::TexCoords(0)), uv);
        }
        if !data.joints.is_empty() {
            let joints = self.push_joints_accessor(&data.joints);
            attributes.insert(Checked::Valid(Semantic::Joints(0)), joints);
            let w: Vec<f32> = data.weights.iter().flatten().copied().collect();
            let weights = self.push_f32_accessor(&w, Type::Vec4, Some(ArrayBuffer), false);
            attributes.insert(Checked::Valid(Semantic::Weights(0)), weights);
        }
        let indices = self.push_index_accessor(&data.indices);
        Ok(json::mesh::Primitive {
            attributes,
            extensions: None,
            extras: None,
            indices: Some(indices),
            material: material.map(|m| json::Index::new(m.0)),
            mode: Checked::Valid(json::mesh::Mode::Triangles),
            targets: None,
        })
    }

    /// Adds a named mesh with one triangle primitive.
    pub fn add_mesh(&mut self, name: &str, data: &MeshData, material: Option<MaterialId>) -> Result<MeshId> {
        let prim = self.primitive(name, data, material)?;
        let index = self.root.push(json::Mesh {
            extensions: None,
            extras: None,
            name: Some(name.to_string()),
            primitives: vec![prim],
            weights: None,
        });
        self.mesh_max_joint.push(max_joint(data));
        Ok(MeshId(index.value() as u32))
    }

    /// Adds another primitive (e.g. with a different material) to a mesh.
    pub fn add_primitive(&mut self, mesh: MeshId, data: &MeshData, material: Option<MaterialId>) -> Result<()> {
        let name = self
            .root
            .meshes
            .get(mesh.0 as usize)
            .and_then(|m| m.name.clone())
            .ok_or_else(|| Error::invalid(WRITER, "unknown mesh").field("mesh"))?;
        let prim = self.primitive(&name, data, material)?;
        self.root.meshes[mesh.0 as usize].primitives.push(prim);
        let m = &mut self.mesh_max_joint[mesh.0 as usize];
        *m = (*m).max(max_joint(data));
        Ok(())
    }

    /// Adds a material, embedding its texture if it has one.
    pub fn add_material(&mut self, desc: &MaterialDesc) -> MaterialId {
        let base_color_texture = desc.base_color_png.as_ref().map(|png| {
            let view = self.push_view(png, None);
            let image = self.root.push(json::Image {
                buffer_view: Some(view),
                mime_type: Some(json::image::MimeType("image/png".to_string())),
                name: Some(desc.name.clone()),
                uri: None,
                extensions: None,
                extras: None,
            });
            let sampler = self.root.push(json::texture::Sampler {
                mag_filter: Some(Checked::Valid(json::texture::MagFilter::Linear)),
                min_filter: Some(Checked::Valid(json::texture::MinFilter::LinearMipmapLinear)),
                ..Default::default()
            });
            let texture = self.root.push(json::Texture {
                name: Some(desc.name.clone()),
                sampler: Some(sampler),
                source: image,
                extensions: None,
                extras: None,
            });
            json::texture::Info { index: texture, tex_coord: 0, extensions: None, extras: None }
        });
        // glTF keeps emissiveFactor in 0..1; anything brighter goes in the
        // strength extension, which is how throng reads it back.
        let strength = desc.emission.iter().fold(0.0f32, |m, &c| m.max(c));
        let (emissive_factor, extensions) = if strength > 1.0 {
            const EXT: &str = "KHR_materials_emissive_strength";
            if !self.root.extensions_used.iter().any(|e| e == EXT) {
                self.root.extensions_used.push(EXT.to_string());
            }
            #[allow(
                clippy::needless_update,
                reason = "other gltf features add fields to this struct; keep the default for them"
            )]
            let ext = json::extensions::material::Material {
                emissive_strength: Some(json::extensions::material::EmissiveStrength {
                    emissive_strength: json::extensions::material::EmissiveStrengthFactor(strength),
                }),
                ..Default::default()
            };
            (desc.emission.map(|c| c / strength), Some(ext))
        } else {
            (desc.emission, None)
        };
        let index = self.root.push(json::Material {
            name: Some(desc.name.clone()),
            double_sided: desc.double_sided,
            emissive_factor: json::material::EmissiveFactor(emissive_factor),
            extensions,
            pbr_metallic_roughness: json::material::PbrMetallicRoughness {
                base_color_factor: json::material::PbrBaseColorFactor(desc.base_color),
                base_color_texture,
                metallic_factor: json::material::StrengthFactor(desc.metallic),
                roughness_factor: json::material::StrengthFactor(desc.roughness),
                ..Default::default()
            },
            ..Default::default()
        });
        MaterialId(index.value() as u32)
    }

    fn node_json(&self, desc: &NodeDesc) -> Result<json::Node> {
        let mut node = json::Node { name: Some(desc.name.clone()), ..Default::default() };
        match desc.transform {
            Transform::Trs { translation, rotation, scale } => {
                if translation != [0.0; 3] {
                    node.translation = Some(translation);
                }
                if rotation != [0.0, 0.0, 0.0, 1.0] {
                    node.rotation = Some(json::scene::UnitQuaternion(rotation));
                }
                if scale != [1.0; 3] {
                    node.scale = Some(scale);
                }
            }
            Transform::Matrix(m) => node.matrix = Some(m),
        }
        if let Some(mesh) = desc.mesh {
            if mesh.0 as usize >= self.root.meshes.len() {
                return Err(Error::invalid(WRITER, format!("node `{}`: unknown mesh", desc.name)).field("mesh"));
            }
            node.mesh = Some(json::Index::new(mesh.0));
        }
        if let Some(skin) = desc.skin {
            let bad = |msg: String| Err(Error::invalid(WRITER, format!("node `{}`: {msg}", desc.name)).field("skin"));
            let Some(s) = self.root.skins.get(skin.0 as usize) else { return bad("unknown skin".into()) };
            let Some(mesh) = desc.mesh else { return bad("a skin needs a mesh to deform".into()) };
            match self.mesh_max_joint[mesh.0 as usize] {
                None => return bad("its mesh has no joints and weights to skin".into()),
                Some(j) if j as usize >= s.joints.len() => {
                    return bad(format!("its mesh uses joint {j}; the skin has {} joints", s.joints.len()))
                }
                Some(_) => {}
            }
            node.skin = Some(json::Index::new(skin.0));
        }
        if !desc.children.is_empty() {
            node.children = Some(desc.children.iter().map(|c| json::Index::new(c.0)).collect());
        }
        if let Some(extras) = &desc.extras {
            let raw = serde_json::value::to_raw_value(extras)
                .map_err(|e| Error::invalid(WRITER, format!("node `{}`: extras: {e}", desc.name)).field("extras"))?;
            node.extras = Some(raw);
        }
        Ok(node)
    }

    /// Adds a node. Children may be given here (already added) or attached
    /// later with [`GlbBuilder::add_child`].
    pub fn add_node(&mut self, desc: NodeDesc) -> Result<NodeId> {
        let node = self.node_json(&desc)?;
        let index = self.root.push(node);
        Ok(NodeId(index.value() as u32))
    }

    /// Makes `child` a child of `parent`.
    pub fn add_child(&mut self, parent: NodeId, child: NodeId) -> Result<()> {
        let n = self.root.nodes.len();
        if parent.index() >= n || child.index() >= n || parent == child {
            return Err(Error::invalid(WRITER, "bad parent/child node").field("children"));
        }
        let p = &mut self.root.nodes[parent.index()];
        p.children.get_or_insert_with(Vec::new).push(json::Index::new(child.0));
        Ok(())
    }

    /// Adds a skin: its joint nodes (added already) and one inverse bind
    /// matrix (column-major) per joint, the inverse of the joint's global
    /// transform in the bind pose.
    pub fn add_skin(&mut self, joints: &[NodeId], inverse_bind: &[[f32; 16]]) -> Result<SkinId> {
        let bad = |msg: String| Err(Error::invalid(WRITER, format!("skin: {msg}")).field("skins"));
        if joints.is_empty() || joints.len() != inverse_bind.len() {
            return bad(format!("{} joints and {} inverse bind matrices", joints.len(), inverse_bind.len()));
        }
        if let Some(j) = joints.iter().find(|j| j.index() >= self.root.nodes.len()) {
            return bad(format!("unknown joint node {}", j.index()));
        }
        if inverse_bind.iter().flatten().any(|v| !v.is_finite()) {
            return bad("an inverse bind matrix is not finite".into());
        }
        let flat: Vec<f32> = inverse_bind.iter().flatten().copied().collect();
        let ibm = self.push_f32_accessor(&flat, json::accessor::Type::Mat4, None, false);
        let index = self.root.push(json::Skin {
            extensions: None,
            extras: None,
            inverse_bind_matrices: Some(ibm),
            joints: joints.iter().map(|j| json::Index::new(j.0)).collect(),
            name: None,
            skeleton: None,
        });
        Ok(SkinId(index.value() as u32))
    }

    /// Adds a perspective camera on a new node (the camera looks down the
    /// node's local -Z; see [`rotation_looking_along`]).
    pub fn add_camera(&mut self, node: NodeDesc, camera: Perspective) -> Result<NodeId> {
        let cam = self.root.push(json::Camera {
            name: Some(node.name.clone()),
            orthographic: None,
            perspective: Some(json::camera::Perspective {
                aspect_ratio: camera.aspect_ratio,
                yfov: camera.yfov,
                zfar: camera.zfar,
                znear: camera.znear,
                extensions: None,
                extras: None,
            }),
            type_: Checked::Valid(json::camera::Type::Perspective),
            extensions: None,
            extras: None,
        });
        let mut json_node = self.node_json(&node)?;
        json_node.camera = Some(cam);
        let index = self.root.push(json_node);
        Ok(NodeId(index.value() as u32))
    }

    /// Adds a KHR_lights_punctual directional light on a new node; the light
    /// shines down the node's local -Z. `intensity` (lux) is written as given.
    pub fn add_sun(&mut self, node: NodeDesc, color: [f32; 3], intensity: f32) -> Result<NodeId> {
        self.add_light(node, PunctualKind::Directional, color, intensity)
    }

    /// Adds a KHR_lights_punctual light of `kind` on a new node (spots and
    /// directional lights shine down the node's local -Z); `intensity` (lux
    /// or candela, as the extension defines) is written as given.
    pub fn add_light(&mut self, node: NodeDesc, kind: PunctualKind, color: [f32; 3], intensity: f32) -> Result<NodeId> {
        use json::extensions::scene::khr_lights_punctual as klp;
        const EXT: &str = "KHR_lights_punctual";
        let (type_, spot) = match kind {
            PunctualKind::Directional => (klp::Type::Directional, None),
            PunctualKind::Point => (klp::Type::Point, None),
            PunctualKind::Spot { inner, outer } => {
                (klp::Type::Spot, Some(klp::Spot { inner_cone_angle: inner, outer_cone_angle: outer }))
            }
        };
        let lights = &mut self
            .root
            .extensions
            .get_or_insert_with(Default::default)
            .khr_lights_punctual
            .get_or_insert_with(Default::default)
            .lights;
        lights.push(klp::Light {
            color,
            extensions: None,
            extras: None,
            intensity,
            name: Some(node.name.clone()),
            range: None,
            spot,
            type_: Checked::Valid(type_),
        });
        let light = json::Index::new((lights.len() - 1) as u32);
        if !self.root.extensions_used.iter().any(|e| e == EXT) {
            self.root.extensions_used.push(EXT.to_string());
        }
        let mut json_node = self.node_json(&node)?;
        #[allow(
            clippy::needless_update,
            reason = "other gltf features add fields to this struct; keep the default for them"
        )]
        let ext = json::extensions::scene::Node {
            khr_lights_punctual: Some(klp::KhrLightsPunctual { light }),
            ..Default::default()
        };
        json_node.extensions = Some(ext);
        let index = self.root.push(json_node);
        Ok(NodeId(index.value() as u32))
    }

    /// Adds an animation clip.
    pub fn add_animation(&mut self, desc: &AnimationDesc) -> Result<()> {
        use json::accessor::Type;
        let mut channels = Vec::new();
        let mut samplers = Vec::new();
        for (i, ch) in desc.channels.iter().enumerate() {
            let bad = |msg: String| {
                Err(Error::invalid(WRITER, format!("animation `{}` channel {i}: {msg}", desc.name)).field("channels"))
            };
            if ch.node.index() >= self.root.nodes.len() {
                return bad("unknown node".into());
            }
            if ch.times.is_empty()
                || ch.times.windows(2).any(|w| w[1] <= w[0])
                || ch.times.iter().any(|t| !t.is_finite())
            {
                return bad("key times must be finite and strictly increasing".into());
            }
            let per_key = if ch.interpolation == Interpolation::CubicSpline { 3 } else { 1 };
            if ch.values.len() != ch.times.len() * per_key {
                return bad(format!("{} values for {} keys", ch.values.len(), ch.times.len()));
            }
            // Sampler inputs must carry min/max.
            let input = self.push_f32_accessor(&ch.times, Type::Scalar, None, true);
            let (output, path) = match &ch.values {
                ChannelValues::Translation(v) => (
                    self.push_f32_accessor(&v.iter().flatten().copied().collect::<Vec<_>>(), Type::Vec3, None, false),
                    json::animation::Property::Translation,
                ),
                ChannelValues::Rotation(v) => (
                    self.push_f32_accessor(&v.iter().flatten().copied().collect::<Vec<_>>(), Type::Vec4, None, false),
                    json::animation::Property::Rotation,
                ),
                ChannelValues::Scale(v) => (
                    self.push_f32_accessor(&v.iter().flatten().copied().collect::<Vec<_>>(), Type::Vec3, None, false),
                    json::animation::Property::Scale,
                ),
            };
            let interpolation = match ch.interpolation {
                Interpolation::Step => json::animation::Interpolation::Step,
                Interpolation::Linear => json::animation::Interpolation::Linear,
                Interpolation::CubicSpline => json::animation::Interpolation::CubicSpline,
            };
            samplers.push(json::animation::Sampler {
                extensions: None,
                extras: None,
                input,
                interpolation: Checked::Valid(interpolation),
                output,
            });
            channels.push(json::animation::Channel {
                sampler: json::Index::new(i as u32),
                target: json::animation::Target {
                    extensions: None,
                    extras: None,
                    node: json::Index::new(ch.node.0),
                    path: Checked::Valid(path),
                },
                extensions: None,
                extras: None,
            });
        }
        self.root.push(json::Animation {
            extensions: None,
            extras: None,
            channels,
            name: Some(desc.name.clone()),
            samplers,
        });
        Ok(())
    }

    /// Serialises the document to .glb bytes (chunks padded to 4 bytes).
    pub fn finish(mut self) -> Result<Vec<u8>> {
        self.root.asset.generator = Some(self.generator.clone());
        while !self.bin.len().is_multiple_of(4) {
            self.bin.push(0);
        }
        if !self.bin.is_empty() {
            self.root.buffers = vec![json::Buffer {
                byte_length: USize64::from(self.bin.len()),
                name: None,
                uri: None,
                extensions: None,
                extras: None,
            }];
        }
        // Roots of the scene: every node that is nobody's child, in order.
        let mut is_child = vec![false; self.root.nodes.len()];
        for n in &self.root.nodes {
            for c in n.children.iter().flatten() {
                if let Some(f) = is_child.get_mut(c.value()) {
                    *f = true;
                }
            }
        }
        let roots = (0..self.root.nodes.len()).filter(|&i| !is_child[i]).map(|i| json::Index::new(i as u32)).collect();
        self.root.scenes = vec![json::Scene { extensions: None, extras: None, name: None, nodes: roots }];
        self.root.scene = Some(json::Index::new(0));
        let mut json_bytes = json::serialize::to_vec(&self.root)
            .map_err(|e| Error::invalid(WRITER, format!("cannot serialise glTF JSON: {e}")))?;
        // JSON chunk padded with spaces, BIN chunk with zeros (glTF 2.0 spec).
        while json_bytes.len() % 4 != 0 {
            json_bytes.push(b' ');
        }
        let has_bin = !self.bin.is_empty();
        let total = 12 + 8 + json_bytes.len() + if has_bin { 8 + self.bin.len() } else { 0 };
        let mut out = Vec::with_capacity(total);
        out.extend_from_slice(b"glTF");
        out.extend_from_slice(&2u32.to_le_bytes());
        out.extend_from_slice(&(total as u32).to_le_bytes());
        out.extend_from_slice(&(json_bytes.len() as u32).to_le_bytes());
        out.extend_from_slice(b"JSON");
        out.extend_from_slice(&json_bytes);
        if has_bin {
            out.extend_from_slice(&(self.bin.len() as u32).to_le_bytes());
            out.extend_from_slice(b"BIN\0");
            out.extend_from_slice(&self.bin);
        }
        Ok(out)
    }

    /// Writes the .glb atomically to `path`.
    pub fn write(self, path: &Path) -> Result<()> {
        let bytes = self.finish()?;
        write_atomic(path, |w| w.write_all(&bytes).at(path))
    }
}

/// The highest joint a primitive's vertices use with a weight above 0.
fn max_joint(data: &MeshData) -> Option<u16> {
    if data.joints.is_empty() {
        return None;
    }
    let used = data.joints.iter().zip(&data.weights).flat_map(|(j, w)| (0..4).filter(|&k| w[k] > 0.0).map(|k| j[k]));
    Some(used.max().unwrap_or(0))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tri(z: f32) -> MeshData {
        MeshData {
            positions: vec![[0.0, 0.0, z], [1.0, -2.0, z], [0.5, 3.0, z + 1.0]],
            normals: vec![[0.0, 0.0, 1.0]; 3],
            uvs: vec![[0.0, 0.0], [1.0, 0.0], [0.5, 1.0]],
            indices: vec![0, 1, 2],
            ..Default::default()
        }
    }

    fn png_2x2() -> Vec<u8> {
        let img = image::RgbaImage::from_pixel(2, 2, image::Rgba([200, 10, 10, 255]));
        let mut out = Vec::new();
        img.write_to(&mut std::io::Cursor::new(&mut out), image::ImageFormat::Png).unwrap();
        out
    }

    fn scene() -> Vec<u8> {
        let mut b = GlbBuilder::new();
        let red = b.add_material(&MaterialDesc::new("red", [1.0, 0.0, 0.0, 1.0]).pbr(0.0, 0.2));
        let tex = b.add_material(&MaterialDesc::new("tex", [1.0; 4]).pbr(1.0, 0.3).texture_png(png_2x2()));
        let m0 = b.add_mesh("tri_a", &tri(0.0), Some(red)).unwrap();
        let m1 = b.add_mesh("tri_b", &tri(2.0), Some(tex)).unwrap();
        let a = b
            .add_node(
                NodeDesc::new("a")
                    .mesh(m0)
                    .translation([1.0, 0.0, 0.0])
                    .extras(serde_json::json!({"slot": "head", "k": [1, 2]})),
            )
            .unwrap();
        let c = b
            .add_node(
                NodeDesc::new("c").mesh(m0).matrix([1.0, 0., 0., 0., 0., 1., 0., 0., 0., 0., 1., 0., 0., 5., 0., 1.]),
            )
            .unwrap();
        let d = b.add_node(NodeDesc::new("d").mesh(m1)).unwrap();
        let top = b.add_node(NodeDesc::new("top").children(vec![a, c])).unwrap();
        b.add_child(top, d).unwrap();
        b.add_camera(
            NodeDesc::new("cam").translation([0.0, 1.0, 5.0]),
            Perspective { yfov: 0.6, aspect_ratio: Some(1.5), znear: 0.1, zfar: None },
        )
        .unwrap();
        b.add_sun(
            NodeDesc::new("sun").rotation(rotation_looking_along([0.0, -1.0, -1.0], [0.0, 1.0, 0.0])),
            [1.0, 0.9, 0.8],
            3.0,
        )
        .unwrap();
        b.add_animation(&AnimationDesc {
            name: "Clip".into(),
            channels: vec![
                ChannelDesc {
                    node: a,
                    interpolation: Interpolation::Linear,
                    times: vec![0.0, 1.0],
                    values: ChannelValues::Translation(vec![[0.0; 3], [0.0, 0.0, 1.5]]),
                },
                ChannelDesc {
                    node: c,
                    interpolation: Interpolation::Step,
                    times: vec![0.0, 0.5],
                    values: ChannelValues::Rotation(vec![[0.0, 0.0, 0.0, 1.0], [0.0, 1.0, 0.0, 0.0]]),
                },
                ChannelDesc {
                    node: d,
                    interpolation: Interpolation::CubicSpline,
                    times: vec![0.0, 1.0],
                    values: ChannelValues::Scale(vec![[0.0; 3], [1.0; 3], [0.0; 3], [0.0; 3], [2.0; 3], [0.0; 3]]),
                },
            ],
        })
        .unwrap();
        b.finish().unwrap()
    }

    #[test]
    fn round_trip() {
        let bytes = scene();
        assert_eq!(bytes.len() % 4, 0);
        let (doc, buffers, images) = gltf::import_slice(&bytes).unwrap();
        assert_eq!(doc.meshes().count(), 2);
        assert_eq!(doc.materials().count(), 2);
        assert_eq!(images.len(), 1);
        assert_eq!((images[0].width, images[0].height), (2, 2));
        let names: Vec<_> = doc.nodes().map(|n| n.name().unwrap_or("").to_string()).collect();
        assert_eq!(names, ["a", "c", "d", "top", "cam", "sun"]);
        // Scene roots: top, cam, sun.
        let roots: Vec<_> = doc.default_scene().unwrap().nodes().map(|n| n.index()).collect();
        assert_eq!(roots, [3, 4, 5]);
        // Instancing: a and c share tri_a.
        let mesh_of = |i: usize| doc.nodes().nth(i).unwrap().mesh().map(|m| m.index());
        assert_eq!(mesh_of(0), mesh_of(1));
        assert_ne!(mesh_of(0), mesh_of(2));
        let a = doc.nodes().next().unwrap();
        let extras: serde_json::Value = serde_json::from_str(a.extras().as_ref().unwrap().get()).unwrap();
        assert_eq!(extras["slot"], "head");
        assert_eq!(extras["k"][1], 2);
        // Positions and bounds read back.
        let mesh = doc.meshes().next().unwrap();
        assert_eq!(mesh.name(), Some("tri_a"));
        let prim = mesh.primitives().next().unwrap();
        let reader = prim.reader(|b| Some(&buffers[b.index()]));
        let pos: Vec<[f32; 3]> = reader.read_positions().unwrap().collect();
        assert_eq!(pos, tri(0.0).positions);
        let uvs: Vec<[f32; 2]> = reader.read_tex_coords(0).unwrap().into_f32().collect();
        assert_eq!(uvs, tri(0.0).uvs);
        let idx: Vec<u32> = reader.read_indices().unwrap().into_u32().collect();
        assert_eq!(idx, [0, 1, 2]);
        let bb = prim.bounding_box();
        assert_eq!((bb.min, bb.max), ([0.0, -2.0, 0.0], [1.0, 3.0, 1.0]));
        let mat = prim.material();
        assert_eq!(mat.name(), Some("red"));
        assert_eq!(mat.pbr_metallic_roughness().roughness_factor(), 0.2);
        let tex_mat = doc.materials().nth(1).unwrap();
        assert!(tex_mat.pbr_metallic_roughness().base_color_texture().is_some());
        assert_eq!(tex_mat.pbr_metallic_roughness().metallic_factor(), 1.0);
        // Animation.
        let anim = doc.animations().next().unwrap();
        assert_eq!(anim.name(), Some("Clip"));
        let modes: Vec<_> = anim.samplers().map(|s| s.interpolation()).collect();
        use gltf::animation::Interpolation as I;
        assert_eq!(modes, [I::Linear, I::Step, I::CubicSpline]);
        let ch = anim.channels().nth(2).unwrap();
        let r = ch.reader(|b| Some(&buffers[b.index()]));
        match r.read_outputs().unwrap() {
            gltf::animation::util::ReadOutputs::Scales(s) => assert_eq!(s.count(), 6),
            _ => panic!("expected scales"),
        }
        // Camera and sun.
        let cam = doc.nodes().nth(4).unwrap();
        match cam.camera().unwrap().projection() {
            gltf::camera::Projection::Perspective(p) => assert_eq!(p.yfov(), 0.6),
            _ => panic!("expected perspective"),
        }
        let sun = doc.nodes().nth(5).unwrap();
        let light = sun.light().unwrap();
        assert!(matches!(light.kind(), gltf::khr_lights_punctual::Kind::Directional));
        assert_eq!(light.intensity(), 3.0);
        assert_eq!(doc.nodes().nth(1).unwrap().transform().matrix()[3][1], 5.0);
    }

    #[test]
    fn rejects_bad_meshes() {
        let mut b = GlbBuilder::new();
        let mut m = tri(0.0);
        m.indices.push(7);
        assert!(b.add_mesh("bad", &m, None).is_err());
        let mut m = tri(0.0);
        m.normals.pop();
        assert!(b.add_mesh("bad", &m, None).is_err());
        let a = b.add_mesh("ok", &tri(0.0), None).unwrap();
        let n = b.add_node(NodeDesc::new("n").mesh(a)).unwrap();
        let bad_cubic = AnimationDesc {
            name: "x".into(),
            channels: vec![ChannelDesc {
                node: n,
                interpolation: Interpolation::CubicSpline,
                times: vec![0.0, 1.0],
                values: ChannelValues::Translation(vec![[0.0; 3]; 2]),
            }],
        };
        assert!(b.add_animation(&bad_cubic).is_err());
    }

    /// Two joints along +Y; the triangle's top vertex blends between them.
    fn skinned_scene() -> Vec<u8> {
        let mut b = GlbBuilder::new();
        let mut data = tri(0.0);
        data.joints = vec![[0, 0, 0, 0], [0, 1, 0, 0], [1, 0, 0, 0]];
        data.weights = vec![[1.0, 0.0, 0.0, 0.0], [0.25, 0.75, 0.0, 0.0], [1.0, 0.0, 0.0, 0.0]];
        let mesh = b.add_mesh("skinned", &data, None).unwrap();
        let hips = b.add_node(NodeDesc::new("hips").translation([0.0, 1.0, 0.0])).unwrap();
        let chest = b.add_node(NodeDesc::new("chest").translation([0.0, 0.5, 0.0])).unwrap();
        b.add_child(hips, chest).unwrap();
        let translate_y = |y: f32| [1.0, 0., 0., 0., 0., 1., 0., 0., 0., 0., 1., 0., 0., y, 0., 1.];
        let skin = b.add_skin(&[hips, chest], &[translate_y(-1.0), translate_y(-1.5)]).unwrap();
        b.add_node(NodeDesc::new("body").mesh(mesh).skin(skin)).unwrap();
        b.finish().unwrap()
    }

    #[test]
    fn skinned_round_trip() {
        let bytes = skinned_scene();
        let (doc, buffers, _) = gltf::import_slice(&bytes).unwrap();
        let skin = doc.skins().next().unwrap();
        let joints: Vec<_> = skin.joints().map(|j| j.name().unwrap_or("").to_string()).collect();
        assert_eq!(joints, ["hips", "chest"]);
        let r = skin.reader(|b| Some(&buffers[b.index()]));
        let ibm: Vec<[[f32; 4]; 4]> = r.read_inverse_bind_matrices().unwrap().collect();
        assert_eq!(ibm.len(), 2);
        assert_eq!(ibm[1][3][1], -1.5);
        let body = doc.nodes().find(|n| n.name() == Some("body")).unwrap();
        assert_eq!(body.skin().map(|s| s.index()), Some(0));
        let prim = body.mesh().unwrap().primitives().next().unwrap();
        let acc = prim.get(&gltf::Semantic::Joints(0)).unwrap();
        assert_eq!(
            (acc.data_type(), acc.dimensions()),
            (gltf::accessor::DataType::U16, gltf::accessor::Dimensions::Vec4)
        );
        let reader = prim.reader(|b| Some(&buffers[b.index()]));
        let joints: Vec<[u16; 4]> = reader.read_joints(0).unwrap().into_u16().collect();
        assert_eq!(joints, [[0, 0, 0, 0], [0, 1, 0, 0], [1, 0, 0, 0]]);
        let weights: Vec<[f32; 4]> = reader.read_weights(0).unwrap().into_f32().collect();
        assert_eq!(weights[1], [0.25, 0.75, 0.0, 0.0]);
        // The skinning code reads the file as a skinned character.
        assert!(doc.skins().len() == 1 && doc.nodes().any(|n| n.skin().is_some() && n.mesh().is_some()));
    }

    #[test]
    fn unskinned_output_is_unchanged_by_skin_support() {
        // No JOINTS_0/WEIGHTS_0 and no `skins` on a mesh without joints.
        let bytes = scene();
        let (doc, _, _) = gltf::import_slice(&bytes).unwrap();
        assert_eq!(doc.skins().len(), 0);
        let json = String::from_utf8_lossy(&bytes[20..]).to_string();
        assert!(!json.contains("JOINTS_0") && !json.contains("\"skins\"") && !json.contains("\"skin\""));
    }

    #[test]
    fn rejects_bad_skins() {
        let mut b = GlbBuilder::new();
        let mut m = tri(0.0);
        m.joints = vec![[0; 4]; 3];
        assert!(b.add_mesh("no_weights", &m, None).is_err(), "joints without weights");
        m.weights = vec![[0.5, 0.0, 0.0, 0.0]; 3];
        assert!(b.add_mesh("half", &m, None).is_err(), "weights summing to 0.5");
        m.joints = vec![[3, 0, 0, 0]; 3];
        m.weights = vec![[1.0, 0.0, 0.0, 0.0]; 3];
        let mesh = b.add_mesh("j3", &m, None).unwrap();
        let plain = b.add_mesh("plain", &tri(0.0), None).unwrap();
        let j = b.add_node(NodeDesc::new("j")).unwrap();
        assert!(b.add_skin(&[j], &[]).is_err(), "one joint, no matrix");
        let skin = b.add_skin(&[j], &[[0.0; 16]]).unwrap();
        assert!(b.add_node(NodeDesc::new("n").mesh(mesh).skin(skin)).is_err(), "joint 3 of a 1-joint skin");
        assert!(b.add_node(NodeDesc::new("n").mesh(plain).skin(skin)).is_err(), "skin on an unskinned mesh");
        assert!(b.add_node(NodeDesc::new("n").skin(skin)).is_err(), "skin without a mesh");
    }

    #[test]
    fn look_rotation_points_minus_z_along_forward() {
        let q = glam::Quat::from_array(rotation_looking_along([1.0, -1.0, 0.0], [0.0, 1.0, 0.0]));
        let f = q * glam::Vec3::NEG_Z;
        assert!((f - glam::Vec3::new(1.0, -1.0, 0.0).normalize()).length() < 1e-5);
        let up = q * glam::Vec3::Y;
        assert!(up.y > 0.0);
    }

    #[test]
    fn writes_file() {
        let path = std::env::temp_dir().join(format!("throng-glb-{}.glb", std::process::id()));
        let mut b = GlbBuilder::new();
        let m = b.add_mesh("t", &tri(0.0), None).unwrap();
        b.add_node(NodeDesc::new("n").mesh(m)).unwrap();
        b.write(&path).unwrap();
        let (doc, _, _) = gltf::import(&path).unwrap();
        std::fs::remove_file(&path).unwrap();
        assert_eq!(doc.meshes().count(), 1);
    }
}
