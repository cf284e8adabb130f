//! glTF asset loading into the shared [`crate::scene`] types.
//!
//! [`AssetCache`] imports each file once and hands out one [`MeshId`] /
//! [`MaterialId`] per unique (file, name) key, so every agent that wears a
//! part shares the same mesh and material (DESIGN.md: parts *and materials*
//! are instanced). Textures are shared the same way, per (file, image).
//!
//! Library names are `<path as given>#<name>`, e.g. `parts/heads.glb#head_sphere`.
//!
//! A glTF mesh may have several primitives, each with its own material.
//! [`AssetCache::mesh`] merges them into one [`Mesh`] (what a wardrobe part
//! is), and [`AssetCache::gltf_material`] gives the material that covers the
//! most triangles of that mesh. Where every primitive's own material matters
//! (the set, multi-material parts), use [`AssetCache::mesh_primitives`] or
//! [`AssetCache::load_scene_instances`], which keep one mesh per primitive.
//! [`AssetCache::load_scene_objects`] also names the set's objects (its
//! nodes with a mesh) uniquely for Cryptomatte ([`set_object_names`]).
//!
//! Accessors are checked (type, count, stride, range) before they are read,
//! so a malformed file gives an error naming the file and mesh or animation,
//! never a panic.

use std::collections::{HashMap, HashSet};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use glam::{Affine3A, Mat3, Mat4, Quat, Vec2, Vec3, Vec4};
use gltf::accessor::{Accessor, DataType, Dimensions};

use crate::error::{Error, Result};
use crate::scene::lights::{Light, LightKind};
use crate::scene::{
    AlphaMode, Camera, Library, Material, MaterialId, Mesh, MeshId, Texture, TextureRef, UvTransform, Volume,
};

/// One parsed glTF file with its buffers loaded (images are decoded only on
/// demand, so a rig never needs its textures).
pub struct GltfFile {
    /// The file, as given by the caller (used in errors and names).
    pub(crate) path: PathBuf,
    /// The parsed glTF document.
    pub doc: gltf::Document,
    /// Buffer contents, by buffer index.
    pub(crate) buffers: Vec<gltf::buffer::Data>,
}

impl GltfFile {
    /// Reads and parses `path` (`.gltf` with external or embedded buffers, or `.glb`).
    pub fn open(path: impl AsRef<Path>) -> Result<GltfFile> {
        let path = path.as_ref();
        // A FIFO or a device (a rig named by `--rig-file`) would block or never end.
        crate::error::check_readable_file(path)?;
        let bytes = std::fs::read(path).map_err(|e| Error::io(path, e))?;
        let invalid = |e: gltf::Error| Error::invalid(path, format!("not a valid glTF file: {e}"));
        let gltf::Gltf { document, mut blob } = gltf::Gltf::from_slice_without_validation(&bytes).map_err(invalid)?;
        // gltf's validation reads each primitive's POSITION accessor by index
        // without checking it, so a bad index must be refused first.
        let accessors = document.as_json().accessors.len();
        for (m, mesh) in document.as_json().meshes.iter().enumerate() {
            for (p, prim) in mesh.primitives.iter().enumerate() {
                let position = prim.attributes.get(&gltf::json::validation::Checked::Valid(gltf::Semantic::Positions));
                if let Some(i) = position.map(|i| i.value()).filter(|&i| i >= accessors) {
                    let name = mesh.name.as_deref().map_or(format!("#{m}"), |n| format!("`{n}`"));
                    return Err(Error::invalid(
                        path,
                        format!("mesh {name} primitive {p}: POSITION is accessor {i}, but the file has {accessors}"),
                    ));
                }
            }
        }
        // Nor does it check an animation channel's target (gltf-json 1.4.1
        // validates only its sampler), whose node and path gltf unwraps.
        let nodes = document.as_json().nodes.len();
        for (a, anim) in document.as_json().animations.iter().enumerate() {
            for (c, channel) in anim.channels.iter().enumerate() {
                let target = &channel.target;
                let problem = if target.node.value() >= nodes {
                    format!("targets node {}, but the file has {nodes}", target.node.value())
                } else if matches!(target.path, gltf::json::validation::Checked::Invalid) {
                    "targets no known property (translation, rotation, scale or weights)".to_string()
                } else {
                    continue;
                };
                let name = anim.name.as_deref().map_or(format!("#{a}"), |n| format!("`{n}`"));
                return Err(Error::invalid(path, format!("animation {name} channel {c} {problem}")));
            }
        }
        let document = gltf::Document::from_json(document.into_json()).map_err(invalid)?;
        let base = path.parent().unwrap_or(Path::new("."));
        let mut buffers = Vec::new();
        for buffer in document.buffers() {
            let what = match buffer.source() {
                gltf::buffer::Source::Uri(uri) if uri.starts_with("data:") => {
                    format!("buffer {} (embedded)", buffer.index())
                }
                gltf::buffer::Source::Uri(uri) => format!("buffer {} (`{uri}`)", buffer.index()),
                gltf::buffer::Source::Bin => format!("buffer {} (GLB chunk)", buffer.index()),
            };
            if let gltf::buffer::Source::Uri(uri) = buffer.source() {
                if !uri.contains(':') {
                    let Some(rel) = decode_uri(uri) else {
                        return Err(Error::invalid(path, format!("{what}: URI is not valid percent-encoded UTF-8")));
                    };
                    // Read whole by gltf: only a regular file has an end
                    // (a device or a FIFO would be read forever).
                    let file = base.join(rel);
                    if file.metadata().is_ok_and(|m| !m.is_file()) {
                        return Err(Error::invalid(path, format!("{what}: {} is not a regular file", file.display())));
                    }
                }
            }
            let data = gltf::buffer::Data::from_source_and_blob(buffer.source(), Some(base), &mut blob)
                .map_err(|e| Error::invalid(path, format!("cannot load {what}: {e}")))?;
            if data.len() < buffer.length() {
                return Err(Error::invalid(
                    path,
                    format!("{what} holds {} bytes, the file declares {}", data.len(), buffer.length()),
                ));
            }
            buffers.push(data);
        }
        Ok(GltfFile { path: path.to_path_buf(), doc: document, buffers })
    }

    /// The bytes of a buffer, for gltf's readers.
    pub(crate) fn buffer_data(&self, buffer: gltf::Buffer) -> Option<&[u8]> {
        self.buffers.get(buffer.index()).map(|d| &d.0[..])
    }

    /// An error about this file.
    pub(crate) fn err(&self, msg: impl Into<String>) -> Error {
        Error::invalid(&self.path, msg)
    }

    /// The mesh named `name`; the error lists the mesh names in the file.
    pub(crate) fn mesh_by_name(&self, name: &str) -> Result<gltf::Mesh<'_>> {
        if let Some(mesh) = self.doc.meshes().find(|m| m.name() == Some(name)) {
            return Ok(mesh);
        }
        let names: Vec<&str> = self.doc.meshes().filter_map(|m| m.name()).collect();
        Err(self.err(format!("no mesh named `{name}`; meshes in this file: {}", list(&names))))
    }

    /// The mesh a wardrobe names: `#index` or a name (field `mesh` on error).
    pub(crate) fn mesh_by_ref(&self, mesh_ref: &str) -> Result<gltf::Mesh<'_>> {
        match mesh_ref.strip_prefix('#').and_then(|i| i.parse::<usize>().ok()) {
            Some(i) => self.doc.meshes().nth(i).ok_or_else(|| {
                self.err(format!("no mesh #{i}; the file has {} meshes", self.doc.meshes().len())).field("mesh")
            }),
            None => self.mesh_by_name(mesh_ref),
        }
    }

    /// The node named `name`; the error lists the node names in the file.
    pub(crate) fn node_by_name(&self, name: &str) -> Result<gltf::Node<'_>> {
        if let Some(node) = self.doc.nodes().find(|n| n.name() == Some(name)) {
            return Ok(node);
        }
        let names: Vec<&str> = self.doc.nodes().filter_map(|n| n.name()).collect();
        Err(self.err(format!("no node named `{name}`; nodes in this file: {}", list(&names))))
    }

    /// Parent index of every node, checked to be a forest (no node with two
    /// parents, no cycles), because we compose transforms up the chain.
    pub(crate) fn parents(&self) -> Result<Vec<Option<usize>>> {
        let mut parents = vec![None; self.doc.nodes().len()];
        for node in self.doc.nodes() {
            for child in node.children() {
                if parents[child.index()].is_some() {
                    return Err(self.err(format!("node {} has more than one parent", node_label(&child))));
                }
                parents[child.index()] = Some(node.index());
            }
        }
        for start in 0..parents.len() {
            let (mut at, mut steps) = (start, 0);
            while let Some(p) = parents[at] {
                at = p;
                steps += 1;
                if steps > parents.len() {
                    return Err(self.err(format!("node {start} is its own ancestor (cycle in the node hierarchy)")));
                }
            }
        }
        Ok(parents)
    }

    /// World transform of every node (parents composed), in node order.
    pub fn world_transforms(&self) -> Result<Vec<Affine3A>> {
        let parents = self.parents()?;
        let locals: Vec<Affine3A> = self.doc.nodes().map(|n| node_affine(&n)).collect();
        let mut world: Vec<Option<Affine3A>> = vec![None; locals.len()];
        for i in 0..locals.len() {
            // Climb to the first resolved ancestor (or a root), then resolve downwards.
            let mut chain = vec![i];
            while let Some(p) = chain.last().and_then(|&n| parents[n]).filter(|&p| world[p].is_none()) {
                chain.push(p);
            }
            for &n in chain.iter().rev() {
                if world[n].is_none() {
                    let parent = parents[n].and_then(|p| world[p]).unwrap_or(Affine3A::IDENTITY);
                    world[n] = Some(parent * locals[n]);
                }
            }
        }
        Ok(world.into_iter().map(|w| w.unwrap_or(Affine3A::IDENTITY)).collect())
    }
}

/// A node's local transform as an affine (glTF: T * R * S, or its matrix).
pub(crate) fn node_affine(node: &gltf::Node) -> Affine3A {
    Affine3A::from_mat4(Mat4::from_cols_array_2d(&node.transform().matrix()))
}

/// What [`AssetCache::load_scene_objects`] gives: (mesh, material,
/// world_from_object, object index) per placed primitive, and the objects' names.
pub(crate) type SceneObjects = (Vec<(MeshId, MaterialId, Affine3A, u32)>, Vec<String>);

/// Unique, stable names for a set's objects from their node paths (the node
/// names from a scene root down to the object's node, `#<index>` for an
/// unnamed node), given in file order:
/// - the node's own name, where no other object has it;
/// - else its path joined with `/` (`street_2/lamp`);
/// - objects whose paths are still shared (siblings of one name) add `#1`,
///   `#2`, ... in file order (`street_2/lamp#1`);
/// - a result that still equals an earlier one (a node really named
///   `lamp#1`) adds `~2`, `~3`, ...
///
/// Depends only on the file's names and order: the same file gives the same
/// names on every machine and run.
pub(crate) fn set_object_names(paths: &[Vec<String>]) -> Vec<String> {
    let leaf = |p: &[String]| p.last().cloned().unwrap_or_default();
    let mut leaves: HashMap<String, usize> = HashMap::new();
    for p in paths {
        *leaves.entry(leaf(p)).or_default() += 1;
    }
    let first: Vec<String> =
        paths.iter().map(|p| if leaves.get(&leaf(p)) == Some(&1) { leaf(p) } else { p.join("/") }).collect();
    let mut count: HashMap<&str, usize> = HashMap::new();
    for n in &first {
        *count.entry(n.as_str()).or_default() += 1;
    }
    let mut seen: HashMap<&str, usize> = HashMap::new();
    let mut used: HashSet<String> = HashSet::new();
    let mut out = Vec::with_capacity(first.len());
    for n in &first {
        let base = if count.get(n.as_str()) == Some(&1) {
            n.clone()
        } else {
            let k = seen.entry(n.as_str()).or_default();
            *k += 1;
            format!("{n}#{k}")
        };
        let mut name = base.clone();
        let mut k = 2;
        while used.contains(&name) {
            name = format!("{base}~{k}");
            k += 1;
        }
        used.insert(name.clone());
        out.push(name);
    }
    out
}

/// `name` or `#index` for messages about unnamed nodes.
pub(crate) fn node_label(node: &gltf::Node) -> String {
    node.name().map(|n| format!("`{n}`")).unwrap_or_else(|| format!("#{}", node.index()))
}

fn mesh_label(mesh: &gltf::Mesh) -> String {
    mesh.name().map(|n| format!("`{n}`")).unwrap_or_else(|| format!("#{}", mesh.index()))
}

/// `a`, `b`, `c` -- quoted, since glTF names may hold spaces.
fn list(names: &[&str]) -> String {
    if names.is_empty() {
        "(none)".into()
    } else {
        names.iter().map(|n| format!("`{n}`")).collect::<Vec<_>>().join(", ")
    }
}

/// Checks that an accessor can be read as `dims` of one of `types` without
/// tripping the gltf crate's asserts (which would panic on a bad file).
pub(crate) fn check_accessor(acc: &Accessor, dims: Dimensions, types: &[DataType]) -> std::result::Result<(), String> {
    let id = acc.index();
    if acc.dimensions() != dims {
        return Err(format!("accessor {id} is {:?}, expected {dims:?}", acc.dimensions()));
    }
    if !types.contains(&acc.data_type()) {
        return Err(format!("accessor {id} has component type {:?}, expected one of {types:?}", acc.data_type()));
    }
    if acc.count() == 0 {
        return Err(format!("accessor {id} is empty"));
    }
    if let Some(view) = acc.view() {
        fits(id, "", &view, acc.offset(), acc.count(), acc.size())?;
    }
    if let Some(sparse) = acc.sparse() {
        if sparse.count() == 0 {
            return Err(format!("accessor {id}: sparse count is 0"));
        }
        let values = sparse.values();
        fits(id, "sparse values ", &values.view(), values.offset(), sparse.count(), acc.size())?;
        let indices = sparse.indices();
        let index_size = indices.index_type().size();
        fits(id, "sparse indices ", &indices.view(), indices.offset(), sparse.count(), index_size)?;
    }
    Ok(())
}

/// Checks that `count` elements of `size` bytes from `offset` lie inside
/// `view` (checked arithmetic: a huge count must not overflow).
fn fits(
    id: usize,
    what: &str,
    view: &gltf::buffer::View,
    offset: usize,
    count: usize,
    size: usize,
) -> std::result::Result<(), String> {
    if view.offset().checked_add(view.length()).is_none_or(|end| end > view.buffer().length()) {
        return Err(format!("accessor {id}: {what}buffer view {} reaches outside its buffer", view.index()));
    }
    let stride = view.stride().unwrap_or(size);
    if stride < size {
        return Err(format!("accessor {id}: {what}byte stride {stride} is smaller than its element ({size} bytes)"));
    }
    let end = count
        .checked_sub(1)
        .and_then(|n| n.checked_mul(stride))
        .and_then(|n| n.checked_add(offset))
        .and_then(|n| n.checked_add(size));
    match end {
        Some(end) if end <= view.length() => Ok(()),
        _ => Err(format!("accessor {id}: {what}{count} elements do not fit in buffer view {}", view.index())),
    }
}

/// A relative URI with its percent-escapes decoded, if they decode to
/// UTF-8 (the gltf crate panics on any that do not).
fn decode_uri(uri: &str) -> Option<String> {
    let bytes = uri.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        let hex = bytes
            .get(i + 1..i + 3)
            .and_then(|h| std::str::from_utf8(h).ok())
            .and_then(|h| u8::from_str_radix(h, 16).ok());
        match (bytes[i], hex) {
            (b'%', Some(b)) => {
                out.push(b);
                i += 3;
            }
            (c, _) => {
                out.push(c);
                i += 1;
            }
        }
    }
    String::from_utf8(out).ok()
}

/// Error text for an accessor whose bytes lie outside its buffer.
pub(crate) fn out_of_range(acc: &Accessor) -> String {
    format!("accessor {} reaches outside its buffer", acc.index())
}

/// How far a decal is lifted off the face it lies on, as a fraction of its
/// mesh's largest extent (the Kenney alien's eyes: 1.5 mm on a 1.5 m head).
pub(crate) const DECAL_LIFT: f32 = 1e-3;

/// Lifts decals off the faces they lie on, so a ray tracer does not speckle
/// between two coplanar surfaces (z-fighting). A decal is a flat primitive
/// of a mesh (every vertex on one plane) lying on a triangle of another
/// primitive of the same mesh that faces the same way (a face decal: eyes
/// and mouth drawn on a head). It moves along its facing by [`DECAL_LIFT`]
/// of the mesh's size; nothing else changes.
pub(crate) fn lift_decals(primitives: &mut [Mesh]) {
    if primitives.len() < 2 {
        return;
    }
    let (lo, hi) = primitives
        .iter()
        .filter(|m| !m.positions.is_empty())
        .map(Mesh::bounds)
        .fold((Vec3::INFINITY, Vec3::NEG_INFINITY), |(a, b), (c, d)| (a.min(c), b.max(d)));
    let size = (hi - lo).max_element();
    if !(size > 0.0 && size.is_finite()) {
        return;
    }
    let eps = size * 1e-5;
    // Each flat primitive's plane: its first proper triangle's normal (the
    // way its winding faces) and offset.
    let plane = |m: &Mesh| -> Option<(Vec3, f32)> {
        let n = m.indices.chunks_exact(3).find_map(|t| {
            let [a, b, c] = [0, 1, 2].map(|k| m.positions.get(t[k] as usize).copied());
            let (a, b, c) = (a?, b?, c?);
            (b - a).cross(c - a).try_normalize()
        })?;
        let d = n.dot(*m.positions.first()?);
        m.positions.iter().all(|p| (n.dot(*p) - d).abs() <= eps).then_some((n, d))
    };
    let lifts: Vec<Option<Vec3>> = (0..primitives.len())
        .map(|i| {
            let (n, d) = plane(&primitives[i])?;
            let on_face = primitives.iter().enumerate().filter(|&(j, _)| j != i).any(|(_, other)| {
                other.indices.chunks_exact(3).any(|t| {
                    let [a, b, c] = [0, 1, 2].map(|k| other.positions.get(t[k] as usize).copied().unwrap_or(Vec3::NAN));
                    let facing = (b - a).cross(c - a).try_normalize().is_some_and(|m| m.dot(n) > 0.999);
                    facing && [a, b, c].iter().all(|p| (n.dot(*p) - d).abs() <= eps)
                })
            });
            on_face.then_some(n * DECAL_LIFT * size)
        })
        .collect();
    for (m, lift) in primitives.iter_mut().zip(lifts) {
        if let Some(lift) = lift {
            for p in &mut m.positions {
                *p += lift;
            }
        }
    }
}

/// Reads one glTF mesh primitive (triangles only) into a [`Mesh`] named `name`.
pub(crate) fn read_primitive(file: &GltfFile, mesh: &gltf::Mesh, prim: &gltf::Primitive, name: String) -> Result<Mesh> {
    let ctx = |msg: String| file.err(format!("mesh {} primitive {}: {msg}", mesh_label(mesh), prim.index()));
    if prim.mode() != gltf::mesh::Mode::Triangles {
        return Err(ctx(format!("mode {:?} is not supported (triangles only)", prim.mode())));
    }
    let reader = prim.reader(|b| file.buffer_data(b));
    let pos_acc = prim.get(&gltf::Semantic::Positions).ok_or_else(|| ctx("has no POSITION".into()))?;
    check_accessor(&pos_acc, Dimensions::Vec3, &[DataType::F32]).map_err(ctx)?;
    let positions: Vec<Vec3> =
        reader.read_positions().ok_or_else(|| ctx(out_of_range(&pos_acc)))?.map(Vec3::from).collect();
    let n = positions.len();

    let mut normals = Vec::new();
    if let Some(acc) = prim.get(&gltf::Semantic::Normals) {
        check_accessor(&acc, Dimensions::Vec3, &[DataType::F32]).map_err(ctx)?;
        normals = reader.read_normals().ok_or_else(|| ctx(out_of_range(&acc)))?.map(Vec3::from).collect();
        if normals.len() != n {
            return Err(ctx(format!("{} normals for {n} positions", normals.len())));
        }
    }
    let mut uvs = Vec::new();
    if let Some(acc) = prim.get(&gltf::Semantic::TexCoords(0)) {
        check_accessor(&acc, Dimensions::Vec2, &[DataType::F32, DataType::U8, DataType::U16]).map_err(ctx)?;
        uvs = reader.read_tex_coords(0).ok_or_else(|| ctx(out_of_range(&acc)))?.into_f32().map(Vec2::from).collect();
        if uvs.len() != n {
            return Err(ctx(format!("{} texture coordinates for {n} positions", uvs.len())));
        }
    }
    let mut tangents = Vec::new();
    if let Some(acc) = prim.get(&gltf::Semantic::Tangents) {
        check_accessor(&acc, Dimensions::Vec4, &[DataType::F32]).map_err(ctx)?;
        tangents = reader.read_tangents().ok_or_else(|| ctx(out_of_range(&acc)))?.map(Vec4::from).collect();
        if tangents.len() != n {
            return Err(ctx(format!("{} tangents for {n} positions", tangents.len())));
        }
    }
    let indices: Vec<u32> = match prim.indices() {
        Some(acc) => {
            check_accessor(&acc, Dimensions::Scalar, &[DataType::U8, DataType::U16, DataType::U32]).map_err(ctx)?;
            reader.read_indices().ok_or_else(|| ctx(out_of_range(&acc)))?.into_u32().collect()
        }
        None => (0..n as u32).collect(),
    };
    if !indices.len().is_multiple_of(3) {
        return Err(ctx(format!("{} indices is not a whole number of triangles", indices.len())));
    }
    if let Some(bad) = indices.iter().find(|&&i| i as usize >= n) {
        return Err(ctx(format!("index {bad} is out of range ({n} vertices)")));
    }
    let mut out = Mesh { name, positions, normals, uvs, tangents, indices };
    if out.normals.is_empty() {
        out.normals = smooth_normals(&out);
    }
    Ok(out)
}

/// All primitives of `mesh` merged into one triangle mesh named `name`.
pub(crate) fn read_mesh(file: &GltfFile, mesh: &gltf::Mesh, name: String) -> Result<Mesh> {
    let mut merged = Mesh { name, ..Default::default() };
    for prim in mesh.primitives() {
        append_mesh(&mut merged, read_primitive(file, mesh, &prim, String::new())?);
    }
    Ok(merged)
}

/// Area-weighted vertex normals, for meshes exported without normals.
/// Shared vertices come out smooth; split vertices (hard edges) stay flat.
pub(crate) fn smooth_normals(mesh: &Mesh) -> Vec<Vec3> {
    let mut normals = vec![Vec3::ZERO; mesh.positions.len()];
    for tri in mesh.indices.chunks_exact(3) {
        let [a, b, c] = [tri[0] as usize, tri[1] as usize, tri[2] as usize];
        // Cross product length is twice the area: larger faces weigh more.
        let n = (mesh.positions[b] - mesh.positions[a]).cross(mesh.positions[c] - mesh.positions[a]);
        for i in [a, b, c] {
            normals[i] += n;
        }
    }
    normals.into_iter().map(|n| n.try_normalize().unwrap_or(Vec3::Y)).collect()
}

/// Appends `part` to `into`, offsetting indices. Attributes one side lacks
/// are filled (zero uvs) so the arrays stay parallel.
fn append_mesh(into: &mut Mesh, mut part: Mesh) {
    let base = into.positions.len() as u32;
    if into.uvs.is_empty() && !part.uvs.is_empty() {
        into.uvs = vec![Vec2::ZERO; into.positions.len()];
    }
    if part.uvs.is_empty() && !into.uvs.is_empty() {
        part.uvs = vec![Vec2::ZERO; part.positions.len()];
    }
    // A zero tangent is no tangent: the renderer derives one from the UVs there.
    if into.tangents.is_empty() && !part.tangents.is_empty() {
        into.tangents = vec![Vec4::ZERO; into.positions.len()];
    }
    if part.tangents.is_empty() && !into.tangents.is_empty() {
        part.tangents = vec![Vec4::ZERO; part.positions.len()];
    }
    into.positions.extend(part.positions);
    into.normals.extend(part.normals);
    into.uvs.extend(part.uvs);
    into.tangents.extend(part.tangents);
    into.indices.extend(part.indices.into_iter().map(|i| i + base));
}

/// Converts an 8-bit sRGB-encoded channel value (0..1) to linear.
pub fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

/// Lumens per watt: glTF lights are photometric (candela, lux), render
/// units radiometric (W/sr, W/m^2); Blender's glTF importer and the peer
/// harness divide by 683 the same way.
pub const LUMENS_PER_WATT: f32 = 683.0;

#[derive(Clone, PartialEq, Eq, Hash)]
enum MeshKey {
    /// All primitives of a mesh, merged (file, mesh name).
    Merged(PathBuf, String),
    /// One primitive (file, mesh index, primitive index).
    Primitive(PathBuf, usize, usize),
}

/// A loaded file with its cache key (canonical path) and the path as given.
struct Source {
    key: PathBuf,
    shown: String,
    file: Arc<GltfFile>,
}

/// Loads glTF files once and shares their meshes, materials and textures.
#[derive(Default)]
pub struct AssetCache {
    library: Library,
    /// Parsed files by canonical path.
    files: HashMap<PathBuf, Arc<GltfFile>>,
    /// Canonical path of each path as given: casting asks per agent and part,
    /// and a `canonicalize` per ask was most of startup's system calls.
    canonical: HashMap<PathBuf, PathBuf>,
    meshes: HashMap<MeshKey, MeshId>,
    /// glTF materials by (file, material index; `None` for primitives without one).
    gltf_materials: HashMap<(PathBuf, Option<usize>), MaterialId>,
    materials_by_name: HashMap<String, MaterialId>,
    /// Textures by (file, image index, sRGB colour rather than linear data).
    textures: HashMap<(PathBuf, usize, bool), u32>,
}

impl AssetCache {
    /// An empty cache.
    pub fn new() -> Self {
        Self::default()
    }

    /// Everything loaded so far.
    pub fn library(&self) -> &Library {
        &self.library
    }

    /// The loaded materials and textures, to change their colours in place
    /// (the render's working colourspace, `render::colour::into_acescg`); what
    /// is loaded and every id stay as they are.
    pub(crate) fn colours_mut(&mut self) -> (&mut [Material], &mut [Texture]) {
        (&mut self.library.materials, &mut self.library.textures)
    }

    /// Gives up the cache, keeping what was loaded.
    pub fn into_library(self) -> Library {
        self.library
    }

    /// The parsed file, read on first use. Keyed by canonical path so
    /// `a/../b.glb` and `b.glb` are one file.
    fn source(&mut self, path: &Path) -> Result<Source> {
        let key = match self.canonical.get(path) {
            Some(k) => k.clone(),
            None => {
                let k = std::fs::canonicalize(path).map_err(|e| Error::io(path, e))?;
                self.canonical.insert(path.to_path_buf(), k.clone());
                k
            }
        };
        let file = match self.files.get(&key) {
            Some(file) => file.clone(),
            None => {
                let file = Arc::new(GltfFile::open(path)?);
                self.files.insert(key.clone(), file.clone());
                file
            }
        };
        Ok(Source { key, shown: path.display().to_string(), file })
    }

    fn push_mesh(&mut self, mesh: Mesh) -> MeshId {
        self.library.meshes.push(mesh);
        (self.library.meshes.len() - 1) as MeshId
    }

    /// The glTF mesh `mesh_name` in `path`, all primitives merged into one
    /// triangle mesh named `<path>#<mesh_name>`. Loaded once; later calls
    /// return the same id.
    pub fn mesh(&mut self, path: impl AsRef<Path>, mesh_name: &str) -> Result<MeshId> {
        let src = self.source(path.as_ref())?;
        let key = MeshKey::Merged(src.key.clone(), mesh_name.to_string());
        if let Some(&id) = self.meshes.get(&key) {
            return Ok(id);
        }
        let gmesh = src.file.mesh_by_name(mesh_name)?;
        // A one-primitive mesh is the same geometry as its only primitive: share it.
        let single = (gmesh.primitives().len() == 1).then(|| MeshKey::Primitive(src.key.clone(), gmesh.index(), 0));
        let id = match single.as_ref().and_then(|k| self.meshes.get(k)) {
            Some(&id) => id,
            None => self.push_mesh(read_mesh(&src.file, &gmesh, format!("{}#{mesh_name}", src.shown))?),
        };
        self.meshes.insert(key, id);
        if let Some(single) = single {
            self.meshes.insert(single, id);
        }
        Ok(id)
    }

    /// One (mesh, material) per primitive of glTF mesh `index`.
    fn primitives_of(&mut self, src: &Source, index: usize) -> Result<Vec<(MeshId, MaterialId)>> {
        let file = src.file.clone();
        let gmesh = file.doc.meshes().nth(index).ok_or_else(|| file.err(format!("no mesh #{index}")))?;
        let label = gmesh.name().map(str::to_string).unwrap_or_else(|| format!("mesh{index}"));
        let single = gmesh.primitives().len() == 1;
        let key = |prim: usize| MeshKey::Primitive(src.key.clone(), index, prim);
        if gmesh.primitives().any(|p| !self.meshes.contains_key(&key(p.index()))) {
            // Read together, so decals are lifted off the faces they lie on.
            let mut meshes = Vec::new();
            for prim in gmesh.primitives() {
                let name = if single {
                    format!("{}#{label}", src.shown)
                } else {
                    format!("{}#{label}/{}", src.shown, prim.index())
                };
                meshes.push(read_primitive(&file, &gmesh, &prim, name)?);
            }
            lift_decals(&mut meshes);
            for (prim, mesh) in gmesh.primitives().zip(meshes) {
                let id = self.push_mesh(mesh);
                self.meshes.insert(key(prim.index()), id);
            }
        }
        let mut out = Vec::new();
        for prim in gmesh.primitives() {
            let mesh = self.meshes[&key(prim.index())];
            let material = self.material_of(src, prim.material().index())?;
            out.push((mesh, material));
        }
        Ok(out)
    }

    /// Whether glTF mesh `mesh_name` of `path` is skinned (a primitive has
    /// JOINTS_0): such a mesh follows a skeleton, not a rigid slot.
    pub(crate) fn is_skinned_mesh(&mut self, path: impl AsRef<Path>, mesh_name: &str) -> Result<bool> {
        let src = self.source(path.as_ref())?;
        let gmesh = src.file.mesh_by_name(mesh_name)?;
        let skinned = gmesh.primitives().any(|p| p.get(&gltf::Semantic::Joints(0)).is_some());
        Ok(skinned)
    }

    /// The mesh `mesh_name` split by primitive: one (mesh, its own glTF
    /// material) pair per primitive, for parts with several materials.
    pub fn mesh_primitives(&mut self, path: impl AsRef<Path>, mesh_name: &str) -> Result<Vec<(MeshId, MaterialId)>> {
        let src = self.source(path.as_ref())?;
        let index = src.file.mesh_by_name(mesh_name)?.index();
        self.primitives_of(&src, index)
    }

    /// The glTF material of mesh `mesh_name`: the material of its primitive
    /// with the most triangles (the first on ties), since
    /// [`AssetCache::mesh`] merges primitives into one mesh with one material.
    pub fn gltf_material(&mut self, path: impl AsRef<Path>, mesh_name: &str) -> Result<MaterialId> {
        let src = self.source(path.as_ref())?;
        let gmesh = src.file.mesh_by_name(mesh_name)?;
        let mut best: Option<(usize, Option<usize>)> = None;
        for prim in gmesh.primitives() {
            // Count from the accessors; no need to read the data.
            let count = match prim.indices() {
                Some(acc) => acc.count(),
                None => prim.get(&gltf::Semantic::Positions).map_or(0, |a| a.count()),
            };
            if best.is_none_or(|(c, _)| count > c) {
                best = Some((count, prim.material().index()));
            }
        }
        let Some((_, material)) = best else {
            return Err(src.file.err(format!("mesh `{mesh_name}` has no primitives")));
        };
        self.material_of(&src, material)
    }

    /// glTF material `index` of the file at `path` (`None`: the default
    /// material), loaded once.
    pub(crate) fn gltf_material_at(&mut self, path: impl AsRef<Path>, index: Option<usize>) -> Result<MaterialId> {
        let src = self.source(path.as_ref())?;
        self.material_of(&src, index)
    }

    /// Material `index` of a file. Primitives without a material get
    /// [`Material::default`] (grey dielectric) named `<path>#default`: the
    /// glTF default (white metal) looks wrong in a render.
    fn material_of(&mut self, src: &Source, index: Option<usize>) -> Result<MaterialId> {
        if let Some(&id) = self.gltf_materials.get(&(src.key.clone(), index)) {
            return Ok(id);
        }
        let file = src.file.clone();
        let mut material = Material { name: format!("{}#default", src.shown), ..Material::default() };
        if let Some(m) = index.and_then(|i| file.doc.materials().nth(i)) {
            let label = m.name().map(str::to_string).unwrap_or_else(|| format!("material{}", m.index().unwrap_or(0)));
            material = self.read_material(src, &m, &label)?;
        }
        self.library.materials.push(material.clone());
        let id = (self.library.materials.len() - 1) as MaterialId;
        self.gltf_materials.insert((src.key.clone(), index), id);
        self.materials_by_name.entry(material.name).or_insert(id);
        Ok(id)
    }

    /// One glTF material, named `<path>#<label>`: the metallic-roughness
    /// core with its textures, alpha and doubleSided, emission
    /// (KHR_materials_emissive_strength), KHR_materials_transmission,
    /// KHR_materials_ior, KHR_materials_volume and KHR_texture_transform.
    /// occlusionTexture is not read: the path tracer computes occlusion.
    fn read_material(&mut self, src: &Source, m: &gltf::Material, label: &str) -> Result<Material> {
        let file = src.file.clone();
        let err = |field: &str, msg: String| file.err(format!("material `{label}`: {field} {msg}"));
        let pbr = m.pbr_metallic_roughness();
        let [r, g, b, alpha] = pbr.base_color_factor();
        let (base_color_texture, base_color_uv) = match pbr.base_color_texture() {
            Some(info) => {
                let t = self.texture_ref(src, &info, true, label, "baseColorTexture")?;
                (t.map(|t| t.texture), t.map_or(UvTransform::IDENTITY, |t| t.uv))
            }
            None => (None, UvTransform::IDENTITY),
        };
        let metallic_roughness_texture = match pbr.metallic_roughness_texture() {
            Some(info) => self.texture_ref(src, &info, false, label, "metallicRoughnessTexture")?,
            None => None,
        };
        let (emissive_texture, emissive_uv) = match m.emissive_texture() {
            Some(info) => {
                let t = self.texture_ref(src, &info, true, label, "emissiveTexture")?;
                (t.map(|t| t.texture), t.map_or(UvTransform::IDENTITY, |t| t.uv))
            }
            None => (None, UvTransform::IDENTITY),
        };
        let strength = m.emissive_strength().unwrap_or(1.0);
        let emission = Vec3::from(m.emissive_factor()) * strength;
        if !(emission.is_finite() && emission.min_element() >= 0.0) {
            return Err(err("emissiveFactor x emissiveStrength", format!("must be finite and >= 0, got {emission}")));
        }
        let alpha_mode = match m.alpha_mode() {
            gltf::material::AlphaMode::Opaque => AlphaMode::Opaque,
            gltf::material::AlphaMode::Blend => AlphaMode::Blend,
            gltf::material::AlphaMode::Mask => {
                let cutoff = m.alpha_cutoff().unwrap_or(0.5);
                if !(cutoff.is_finite() && cutoff >= 0.0) {
                    return Err(err("alphaCutoff", format!("must be finite and >= 0, got {cutoff}")));
                }
                AlphaMode::Mask { cutoff }
            }
        };
        let (normal_texture, normal_scale) = match m.normal_texture() {
            Some(nt) => {
                let scale = nt.scale();
                if !scale.is_finite() {
                    return Err(err("normalTexture.scale", format!("must be finite, got {scale}")));
                }
                let uv = match nt.extension_value("KHR_texture_transform") {
                    Some(v) => uv_transform_json(v, nt.tex_coord())
                        .map_err(|e| err("normalTexture.extensions.KHR_texture_transform", e))?,
                    None => UvTransform { tex_coord: nt.tex_coord(), ..UvTransform::IDENTITY },
                };
                let image = nt.texture().source().index();
                let t = self.texture(src, image, false)?;
                (usable_uv(uv).map(|uv| TextureRef { texture: t, uv }), scale)
            }
            None => (None, 1.0),
        };
        let (transmission, transmission_texture) = match m.transmission() {
            Some(t) => {
                let factor = t.transmission_factor();
                if !(0.0..=1.0).contains(&factor) {
                    return Err(err(
                        "KHR_materials_transmission.transmissionFactor",
                        format!("must be 0-1, got {factor}"),
                    ));
                }
                let texture = match t.transmission_texture() {
                    Some(info) => self.texture_ref(src, &info, false, label, "transmissionTexture")?,
                    None => None,
                };
                (factor, texture)
            }
            None => (0.0, None),
        };
        let ior = m.ior().unwrap_or(1.5);
        if !(ior.is_finite() && ior >= 1.0) {
            return Err(err("KHR_materials_ior.ior", format!("must be finite and >= 1, got {ior}")));
        }
        // glTF: a volume of thickness 0 is thin-walled.
        let volume = match m.volume() {
            Some(v) if v.thickness_factor() > 0.0 => {
                let (color, distance) = (Vec3::from(v.attenuation_color()), v.attenuation_distance());
                if !(color.is_finite() && color.min_element() >= 0.0 && color.max_element() <= 1.0) {
                    return Err(err("KHR_materials_volume.attenuationColor", format!("must be 0-1, got {color}")));
                }
                if !(distance > 0.0) {
                    return Err(err(
                        "KHR_materials_volume.attenuationDistance",
                        format!("must be > 0, got {distance}"),
                    ));
                }
                Some(Volume { attenuation_color: color, attenuation_distance: distance })
            }
            Some(v) if !(v.thickness_factor() >= 0.0) => {
                let t = v.thickness_factor();
                return Err(err("KHR_materials_volume.thicknessFactor", format!("must be >= 0, got {t}")));
            }
            _ => None,
        };
        // KHR_materials_unlit: the base colour as it is, whatever lights it
        // (what Blender's importer renders for the camera): its emission,
        // reflecting nothing (docs/lights.md, "Emissive surfaces").
        let unlit = m.extension_value("KHR_materials_unlit").is_some();
        let (base_color, emission, emissive_texture, emissive_uv) = if unlit {
            (Vec3::ZERO, Vec3::new(r, g, b), base_color_texture, base_color_uv)
        } else {
            (Vec3::new(r, g, b), emission, emissive_texture, emissive_uv)
        };
        Ok(Material {
            name: format!("{}#{label}", src.shown),
            base_color,
            base_color_texture: if unlit { None } else { base_color_texture },
            base_color_uv,
            roughness: pbr.roughness_factor(),
            metallic: pbr.metallic_factor(),
            metallic_roughness_texture,
            emission,
            emissive_texture,
            emissive_uv,
            alpha,
            alpha_mode,
            double_sided: m.double_sided(),
            normal_texture,
            normal_scale,
            transmission,
            transmission_texture,
            ior,
            volume,
        })
    }

    /// A material's texture reference with its KHR_texture_transform; `None`
    /// when it reads a UV set other than TEXCOORD_0 (not loaded). `colour`:
    /// sRGB-encoded colour (base colour, emissive), else linear data.
    fn texture_ref(
        &mut self,
        src: &Source,
        info: &gltf::texture::Info,
        colour: bool,
        label: &str,
        field: &str,
    ) -> Result<Option<TextureRef>> {
        let uv = match info.texture_transform() {
            Some(t) => {
                let uv = UvTransform {
                    offset: Vec2::from(t.offset()),
                    rotation: t.rotation(),
                    scale: Vec2::from(t.scale()),
                    tex_coord: t.tex_coord().unwrap_or(info.tex_coord()),
                };
                if !(uv.offset.is_finite() && uv.rotation.is_finite() && uv.scale.is_finite()) {
                    return Err(src
                        .file
                        .err(format!("material `{label}`: {field}.extensions.KHR_texture_transform must be finite")));
                }
                uv
            }
            None => UvTransform { tex_coord: info.tex_coord(), ..UvTransform::IDENTITY },
        };
        let Some(uv) = usable_uv(uv) else { return Ok(None) };
        let texture = self.texture(src, info.texture().source().index(), colour)?;
        Ok(Some(TextureRef { texture, uv }))
    }

    /// Image `index` of a file as a linear RGBA texture: with `colour`, the
    /// colour channels sRGB-decoded (glTF base colour and emissive textures
    /// are sRGB), else read as linear data (normal, metallic-roughness and
    /// transmission maps); alpha is linear either way.
    fn texture(&mut self, src: &Source, index: usize, colour: bool) -> Result<u32> {
        if let Some(&id) = self.textures.get(&(src.key.clone(), index, colour)) {
            return Ok(id);
        }
        let file = &src.file;
        let image = file.doc.images().nth(index).ok_or_else(|| file.err(format!("no image #{index}")))?;
        let label = image.name().map(str::to_string).unwrap_or_else(|| format!("image{index}"));
        let ctx = |msg: String| file.err(format!("image `{label}`: {msg}"));
        // The gltf crate slices buffer views unchecked and unwraps URI
        // decoding; check both first so a bad file cannot panic. Its
        // `source()` unwraps a view's mimeType, and the uri when there is no
        // view: check those in the JSON before asking.
        let json = file.doc.as_json().images.get(index).ok_or_else(|| file.err(format!("no image #{index}")))?;
        match (&json.buffer_view, &json.uri, &json.mime_type) {
            (Some(_), _, None) => return Err(ctx("an image in a bufferView needs a mimeType".into())),
            (None, None, _) => return Err(ctx("has neither a uri nor a bufferView".into())),
            _ => {}
        }
        match image.source() {
            gltf::image::Source::View { view, .. } => {
                let len = file.buffers.get(view.buffer().index()).map_or(0, |b| b.len());
                if view.offset().checked_add(view.length()).is_none_or(|end| end > len) {
                    return Err(ctx("buffer view reaches outside its buffer".into()));
                }
            }
            gltf::image::Source::Uri { uri, .. } if !uri.contains(':') => {
                let Some(rel) = decode_uri(uri) else {
                    return Err(ctx("URI is not valid percent-encoded UTF-8".into()));
                };
                // Only a regular file has an end (see the buffers in `GltfFile::open`).
                let image_file = file.path.parent().unwrap_or(Path::new(".")).join(rel);
                if image_file.metadata().is_ok_and(|m| !m.is_file()) {
                    return Err(ctx(format!("{} is not a regular file", image_file.display())));
                }
            }
            gltf::image::Source::Uri { .. } => {}
        }
        let base = file.path.parent().unwrap_or(Path::new("."));
        // Name an external image's file: that is what a user can fix.
        let from = match image.source() {
            gltf::image::Source::Uri { uri, .. } if !uri.starts_with("data:") => {
                format!(" {}", base.join(uri).display())
            }
            _ => String::new(),
        };
        // Bound the size from the image's header before decoding it.
        let header = match image.source() {
            gltf::image::Source::View { view, .. } => file.buffers.get(view.buffer().index()).and_then(|b| {
                image::ImageReader::new(std::io::Cursor::new(&b[view.offset()..view.offset() + view.length()]))
                    .with_guessed_format()
                    .ok()?
                    .into_dimensions()
                    .ok()
            }),
            gltf::image::Source::Uri { uri, .. } if !uri.contains(':') => decode_uri(uri).and_then(|rel| {
                image::ImageReader::open(base.join(rel)).ok()?.with_guessed_format().ok()?.into_dimensions().ok()
            }),
            gltf::image::Source::Uri { .. } => None,
        };
        if let Some((w, h)) = header {
            check_texture_size(w, h).map_err(|m| ctx(format!("{}{from}", m)))?;
        }
        let data = gltf::image::Data::from_source(image.source(), Some(base), &file.buffers)
            .map_err(|e| ctx(format!("cannot decode{from}: {e}")))?;
        check_texture_size(data.width, data.height).map_err(|m| ctx(format!("{m}{from}")))?;
        let texels =
            decode_texels(&data, colour).ok_or_else(|| ctx(format!("unsupported pixel format {:?}", data.format)))?;
        let texture =
            Texture { name: format!("{}#{label}", src.shown), width: data.width, height: data.height, texels };
        self.library.textures.push(texture);
        let id = (self.library.textures.len() - 1) as u32;
        self.textures.insert((src.key.clone(), index, colour), id);
        Ok(id)
    }

    /// Adds a material (e.g. from a wardrobe), deduplicated by name: a
    /// material whose name is already present returns the existing id.
    pub fn add_material(&mut self, material: Material) -> MaterialId {
        if let Some(&id) = self.materials_by_name.get(&material.name) {
            return id;
        }
        self.library.materials.push(material.clone());
        let id = (self.library.materials.len() - 1) as MaterialId;
        self.materials_by_name.insert(material.name, id);
        id
    }

    /// Adds a mesh built in code (e.g. the proxy box), deduplicated by name.
    pub(crate) fn add_mesh(&mut self, mesh: Mesh) -> MeshId {
        let key = MeshKey::Merged(PathBuf::new(), mesh.name.clone());
        if let Some(&id) = self.meshes.get(&key) {
            return id;
        }
        let id = self.push_mesh(mesh);
        self.meshes.insert(key, id);
        id
    }

    /// A PNG file as a linear RGBA texture (colour sRGB-decoded), loaded once
    /// per path: wardrobe materials' `base_color_texture`.
    pub(crate) fn texture_png(&mut self, path: impl AsRef<Path>) -> Result<u32> {
        let path = path.as_ref();
        let key = (std::fs::canonicalize(path).map_err(|e| Error::io(path, e))?, usize::MAX, true);
        if let Some(&id) = self.textures.get(&key) {
            return Ok(id);
        }
        texture_size(path)?;
        let img =
            image::open(path).map_err(|e| Error::invalid(path, format!("cannot decode texture: {e}")))?.to_rgba32f();
        let texels =
            img.pixels().map(|p| [srgb_to_linear(p[0]), srgb_to_linear(p[1]), srgb_to_linear(p[2]), p[3]]).collect();
        let texture = Texture { name: path.display().to_string(), width: img.width(), height: img.height(), texels };
        self.library.textures.push(texture);
        let id = (self.library.textures.len() - 1) as u32;
        self.textures.insert(key, id);
        Ok(id)
    }

    /// Every mesh primitive placed by the file's default scene (or its first
    /// scene): (mesh, the primitive's own material, world_from_object with
    /// parent transforms composed), depth-first in file order.
    pub fn load_scene_instances(&mut self, path: impl AsRef<Path>) -> Result<Vec<(MeshId, MaterialId, Affine3A)>> {
        let (placed, _) = self.load_scene_objects(path)?;
        Ok(placed.into_iter().map(|(mesh, material, world, _)| (mesh, material, world)).collect())
    }

    /// As [`AssetCache::load_scene_instances`], each primitive also with its
    /// object: the index, in the returned names, of the node that places it.
    /// Objects are the nodes with a mesh, in the same depth-first file order,
    /// named uniquely by [`set_object_names`] from their node paths.
    pub fn load_scene_objects(&mut self, path: impl AsRef<Path>) -> Result<SceneObjects> {
        let src = self.source(path.as_ref())?;
        let file = src.file.clone();
        file.parents()?; // a forest, so the walk below ends
        let scene =
            file.doc.default_scene().or_else(|| file.doc.scenes().next()).ok_or_else(|| file.err("has no scene"))?;
        let label = |n: &gltf::Node| n.name().map(str::to_string).unwrap_or_else(|| format!("#{}", n.index()));
        let mut stack: Vec<(gltf::Node, Affine3A, Vec<String>)> =
            scene.nodes().map(|n| (n.clone(), node_affine(&n), vec![label(&n)])).collect();
        stack.reverse();
        let mut out = Vec::new();
        let mut paths: Vec<Vec<String>> = Vec::new();
        while let Some((node, world, path)) = stack.pop() {
            if let Some(mesh) = node.mesh() {
                let object = paths.len() as u32;
                for (mesh, material) in self.primitives_of(&src, mesh.index())? {
                    out.push((mesh, material, world, object));
                }
                paths.push(path.clone());
            }
            let children: Vec<_> = node.children().collect();
            for child in children.into_iter().rev() {
                let child_world = world * node_affine(&child);
                let mut child_path = path.clone();
                child_path.push(label(&child));
                stack.push((child, child_world, child_path));
            }
        }
        Ok((out, set_object_names(&paths)))
    }

    /// The camera on node `node_name`. `world_from_camera` keeps the node's
    /// world rotation and translation but drops scale (a scaled camera node
    /// would skew rays).
    pub fn find_camera(&mut self, path: impl AsRef<Path>, node_name: &str) -> Result<Camera> {
        let file = self.source(path.as_ref())?.file;
        let node = file.node_by_name(node_name)?;
        let camera = node.camera().ok_or_else(|| file.err(format!("node `{node_name}` has no camera")))?;
        let yfov = match camera.projection() {
            gltf::camera::Projection::Perspective(p) => p.yfov(),
            gltf::camera::Projection::Orthographic(_) => {
                return Err(
                    file.err(format!("camera on node `{node_name}` is orthographic; only perspective is supported"))
                )
            }
        };
        if !(yfov.is_finite() && yfov > 0.0 && yfov < std::f32::consts::PI) {
            return Err(file.err(format!("camera on node `{node_name}` has yfov {yfov}")));
        }
        let world = file.world_transforms()?[node.index()];
        let (_, rotation, translation) = world.to_scale_rotation_translation();
        Ok(Camera::pinhole(Affine3A::from_rotation_translation(rotation.normalize(), translation), yfov))
    }

    /// Every KHR_lights_punctual light on a node of the file, in node order,
    /// in render units: point and spot intensity candela / 683 (W/sr),
    /// directional lux / 683 (W/m^2). A spot's cone takes Blender's edge
    /// (blend = 1 - inner / outer), what Cycles renders for the same file.
    /// `range` is ignored, as Blender does.
    pub fn punctual_lights(&mut self, path: impl AsRef<Path>) -> Result<Vec<Light>> {
        let file = self.source(path.as_ref())?.file;
        let world = file.world_transforms()?;
        let mut out = Vec::new();
        for node in file.doc.nodes() {
            let Some(light) = node.light() else { continue };
            let name = node.name().map(str::to_string).unwrap_or_else(|| format!("#{}", node.index()));
            let err = |m: String| file.err(format!("light on node `{name}`: {m}"));
            let (color, intensity) = (Vec3::from(light.color()), light.intensity());
            if !(intensity >= 0.0 && intensity.is_finite() && color.is_finite() && color.min_element() >= 0.0) {
                return Err(err(format!("intensity {intensity} and color {color} must be finite and >= 0")));
            }
            let emission = color * (intensity / LUMENS_PER_WATT);
            super::lights::check_product("intensity / 683 x color", emission).map_err(err)?;
            let kind = match light.kind() {
                gltf::khr_lights_punctual::Kind::Directional => LightKind::Distant { angular_diameter: 0.0 },
                gltf::khr_lights_punctual::Kind::Point => LightKind::Point,
                gltf::khr_lights_punctual::Kind::Spot { inner_cone_angle, outer_cone_angle } => {
                    let (inner, outer) = (inner_cone_angle, outer_cone_angle);
                    if !(outer > 0.0 && outer <= std::f32::consts::FRAC_PI_2 && inner >= 0.0 && inner <= outer) {
                        return Err(err(format!(
                            "spot angles out of order: need 0 <= innerConeAngle ({inner}) <= outerConeAngle ({outer}) <= pi/2"
                        )));
                    }
                    LightKind::Spot { outer, blend: 1.0 - inner / outer }
                }
            };
            let (_, rotation, translation) = world[node.index()].to_scale_rotation_translation();
            out.push(Light {
                name,
                kind,
                world_from_light: Affine3A::from_rotation_translation(rotation.normalize(), translation),
                emission,
                two_sided: false,
                camera_visible: false,
                light_group: None,
            });
        }
        Ok(out)
    }
}

/// `uv` if it reads a UV set throng loads (TEXCOORD_0 only).
fn usable_uv(uv: UvTransform) -> Option<UvTransform> {
    (uv.tex_coord == 0).then_some(uv)
}

/// KHR_texture_transform from its JSON (for normalTexture, which the gltf
/// crate does not parse it on); `tex_coord` is the textureInfo's own set.
fn uv_transform_json(v: &gltf::json::Value, tex_coord: u32) -> std::result::Result<UvTransform, String> {
    let pair = |key: &str, default: Vec2| -> std::result::Result<Vec2, String> {
        match v.get(key) {
            None => Ok(default),
            Some(a) => match a.as_array().map(|a| a.iter().map(|x| x.as_f64()).collect::<Vec<_>>()).as_deref() {
                Some([Some(x), Some(y)]) => Ok(Vec2::new(*x as f32, *y as f32)),
                _ => Err(format!("{key} must be two numbers")),
            },
        }
    };
    let rotation = match v.get("rotation") {
        None => 0.0,
        Some(r) => r.as_f64().ok_or("rotation must be a number")? as f32,
    };
    let tex_coord = match v.get("texCoord") {
        None => tex_coord,
        Some(t) => t.as_u64().and_then(|t| u32::try_from(t).ok()).ok_or("texCoord must be a set index")?,
    };
    let uv = UvTransform { offset: pair("offset", Vec2::ZERO)?, rotation, scale: pair("scale", Vec2::ONE)?, tex_coord };
    if !(uv.offset.is_finite() && uv.rotation.is_finite() && uv.scale.is_finite()) {
        return Err("must be finite".into());
    }
    Ok(uv)
}

/// Widest or tallest texture accepted, texels.
pub(crate) const MAX_TEXTURE_SIDE: u32 = 16384;
/// Most texels a texture may hold: 8192 x 8192, 1 GiB as the renderer's
/// linear RGBA floats.
pub(crate) const MAX_TEXTURE_TEXELS: u64 = 8192 * 8192;

/// Refuses a texture beyond [`MAX_TEXTURE_SIDE`] or [`MAX_TEXTURE_TEXELS`]
/// (read from its header, before its pixels are decoded).
pub(crate) fn check_texture_size(width: u32, height: u32) -> std::result::Result<(), String> {
    if width.max(height) > MAX_TEXTURE_SIDE || width as u64 * height as u64 > MAX_TEXTURE_TEXELS {
        return Err(format!(
            "texture is {width} x {height} texels, more than throng reads ({MAX_TEXTURE_SIDE} a side, \
             {MAX_TEXTURE_TEXELS} in all: docs/wardrobes.md)"
        ));
    }
    Ok(())
}

/// A texture file's size from its header, bounded by [`check_texture_size`].
pub(crate) fn texture_size(path: &Path) -> Result<(u32, u32)> {
    let bad = |e: String| Error::invalid(path, format!("texture is not an image throng reads: {e}"));
    let reader = image::ImageReader::open(path).map_err(|e| Error::io(path, e))?;
    let (w, h) = reader
        .with_guessed_format()
        .map_err(|e| bad(e.to_string()))?
        .into_dimensions()
        .map_err(|e| bad(e.to_string()))?;
    check_texture_size(w, h).map_err(|m| Error::invalid(path, m))?;
    Ok((w, h))
}

/// Linear RGBA texels from decoded image data (RGB sRGB-decoded when
/// `colour`); `None` for formats we do not read.
fn decode_texels(data: &gltf::image::Data, colour: bool) -> Option<Vec<[f32; 4]>> {
    use gltf::image::Format;
    let px = &data.pixels;
    let u16_at = |i: usize| u16::from_ne_bytes([px[2 * i], px[2 * i + 1]]) as f32 / 65535.0;
    let (channels, wide) = match data.format {
        Format::R8 => (1, false),
        Format::R8G8 => (2, false),
        Format::R8G8B8 => (3, false),
        Format::R8G8B8A8 => (4, false),
        Format::R16 => (1, true),
        Format::R16G16 => (2, true),
        Format::R16G16B16 => (3, true),
        Format::R16G16B16A16 => (4, true),
        _ => return None,
    };
    let count = data.width as usize * data.height as usize;
    let bytes_per = if wide { 2 } else { 1 };
    if px.len() < count * channels * bytes_per {
        return None;
    }
    let get = |i: usize| if wide { u16_at(i) } else { px[i] as f32 / 255.0 };
    let texels = (0..count)
        .map(|t| {
            let c: Vec<f32> = (0..channels).map(|k| get(t * channels + k)).collect();
            let (rgb, a) = match channels {
                1 => ([c[0]; 3], 1.0),
                2 => ([c[0]; 3], c[1]),
                3 => ([c[0], c[1], c[2]], 1.0),
                _ => ([c[0], c[1], c[2]], c[3]),
            };
            if colour {
                [srgb_to_linear(rgb[0]), srgb_to_linear(rgb[1]), srgb_to_linear(rgb[2]), a]
            } else {
                [rgb[0], rgb[1], rgb[2], a]
            }
        })
        .collect();
    Some(texels)
}

/// Quaternion from glTF `[x, y, z, w]`, normalised (files may carry slightly
/// unnormalised rotations); identity if degenerate.
pub(crate) fn quat_from_gltf(q: [f32; 4]) -> Quat {
    let q = Quat::from_array(q);
    if q.length_squared() > 1e-12 && q.is_finite() {
        q.normalize()
    } else {
        Quat::IDENTITY
    }
}

/// A coordinate axis of a source file.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Deserialize)]
pub enum Axis {
    /// +X.
    #[serde(rename = "+x")]
    PosX,
    /// -X.
    #[serde(rename = "-x")]
    NegX,
    /// +Y.
    #[serde(rename = "+y")]
    PosY,
    /// -Y.
    #[serde(rename = "-y")]
    NegY,
    /// +Z.
    #[serde(rename = "+z")]
    PosZ,
    /// -Z.
    #[serde(rename = "-z")]
    NegZ,
}

/// The unit vector along a file's axis `a`.
fn axis_vector(a: Axis) -> Vec3 {
    match a {
        Axis::PosX => Vec3::X,
        Axis::NegX => Vec3::NEG_X,
        Axis::PosY => Vec3::Y,
        Axis::NegY => Vec3::NEG_Y,
        Axis::PosZ => Vec3::Z,
        Axis::NegZ => Vec3::NEG_Z,
    }
}

/// The rotation taking a file's `up` to +Y and `forward` to +Z (a rig's
/// or a wardrobe part's axes as the shot or wardrobe names them).
pub(crate) fn orientation(path: &Path, up: Axis, forward: Axis) -> Result<Quat> {
    let (u, f) = (axis_vector(up), axis_vector(forward));
    if u.dot(f).abs() > 0.5 {
        return Err(
            Error::invalid(path, format!("forward {forward:?} is along up {up:?}; they must differ")).field("forward")
        );
    }
    // Columns (right, up, forward) of the file's frame; its transpose maps them onto X, Y, Z.
    let frame = Mat3::from_cols(u.cross(f), u, f);
    Ok(Quat::from_mat3(&frame.transpose()))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// KHR_materials_unlit: the base colour emitted as it is, reflecting
    /// nothing (docs/lights.md, "Emissive surfaces").
    #[test]
    fn an_unlit_material_emits_its_base_colour() {
        let dir = std::env::temp_dir().join(format!("throng-unlit-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let mut bin = Vec::new();
        for c in [0.0f32, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0] {
            bin.extend_from_slice(&c.to_le_bytes());
        }
        std::fs::write(dir.join("tri.bin"), &bin).unwrap();
        let json = r#"{"asset":{"version":"2.0"},"extensionsUsed":["KHR_materials_unlit"],
"buffers":[{"byteLength":36,"uri":"tri.bin"}],"bufferViews":[{"buffer":0,"byteLength":36}],
"accessors":[{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[1,0,1]}],
"materials":[{"name":"sign","pbrMetallicRoughness":{"baseColorFactor":[0.8,0.4,0.2,1.0]},"extensions":{"KHR_materials_unlit":{}}},
 {"name":"lit","pbrMetallicRoughness":{"baseColorFactor":[0.8,0.4,0.2,1.0]}}],
"meshes":[{"name":"tri","primitives":[{"attributes":{"POSITION":0},"material":0}]}],
"nodes":[{"mesh":0,"name":"tri"}],"scenes":[{"nodes":[0]}],"scene":0}"#;
        let path = dir.join("unlit.gltf");
        std::fs::write(&path, json).unwrap();
        let mut assets = AssetCache::default();
        let unlit = assets.gltf_material_at(&path, Some(0)).unwrap();
        let lit = assets.gltf_material_at(&path, Some(1)).unwrap();
        let m = &assets.library().materials;
        let (unlit, lit) = (&m[unlit as usize], &m[lit as usize]);
        assert_eq!((unlit.emission, unlit.base_color), (Vec3::new(0.8, 0.4, 0.2), Vec3::ZERO));
        assert_eq!((lit.emission, lit.base_color), (Vec3::ZERO, Vec3::new(0.8, 0.4, 0.2)));
        let _ = std::fs::remove_dir_all(dir);
    }

    /// A texture's size is bounded from its header, before its pixels are
    /// decoded (issue 49: a PNG declaring 100000 x 100000 passed).
    #[test]
    fn a_texture_past_the_size_bound_is_refused_from_its_header() {
        assert!(check_texture_size(MAX_TEXTURE_SIDE, 1).is_ok() && check_texture_size(8192, 8192).is_ok());
        assert!(check_texture_size(MAX_TEXTURE_SIDE + 1, 1).is_err());
        assert!(check_texture_size(16384, 8192).unwrap_err().contains("16384 x 8192"));
        let path = std::env::temp_dir().join(format!("throng-huge-{}.png", std::process::id()));
        let mut ihdr = b"IHDR".to_vec();
        ihdr.extend(100_000u32.to_be_bytes().iter().chain(&100_000u32.to_be_bytes()).chain(&[8, 6, 0, 0, 0]));
        let mut png = b"\x89PNG\r\n\x1a\n\0\0\0\x0d".to_vec();
        png.extend(ihdr.iter().chain(&crc32fast::hash(&ihdr).to_be_bytes()));
        // An empty IDAT: the header ends where the pixels would start.
        png.extend([0u8, 0, 0, 0].iter().chain(b"IDAT").chain(&crc32fast::hash(b"IDAT").to_be_bytes()));
        std::fs::write(&path, png).unwrap();
        let msg = texture_size(&path).unwrap_err().to_string();
        assert!(msg.contains("100000 x 100000") && msg.contains("throng-huge-"), "{msg}");
        let msg = AssetCache::default().texture_png(&path).unwrap_err().to_string();
        assert!(msg.contains("100000 x 100000"), "{msg}");
        let _ = std::fs::remove_file(path);
    }

    fn paths(list: &[&str]) -> Vec<Vec<String>> {
        list.iter().map(|p| p.split('/').map(str::to_string).collect()).collect()
    }

    #[test]
    fn set_object_names_are_unique_and_stable() {
        let mut input = paths(&["floor", "street_1/lamp", "street_2/lamp", "street_2/lamp", "#7", "tower"]);
        // A root node whose own name is what the rules make of another.
        input.push(vec!["street_2/lamp#2".to_string()]);
        input.extend(paths(&["block/bench", "block/lamp"]));
        let names = set_object_names(&input);
        assert_eq!(
            names,
            [
                "floor",
                "street_1/lamp",
                "street_2/lamp#1",
                "street_2/lamp#2",
                "#7",
                "tower",
                "street_2/lamp#2~2",
                "bench",
                "block/lamp",
            ]
        );
        let unique: HashSet<&String> = names.iter().collect();
        assert_eq!(unique.len(), names.len());
        assert_eq!(set_object_names(&input), names, "deterministic");
    }
}
