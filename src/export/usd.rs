//! `throng export --format usd`: the cast crowd over a frame range as a USD
//! stage (docs/usd.md).
//!
//! Layout (every name derived from mesh, material and agent names, sorted,
//! so two runs write the same bytes):
//!
//! ```text
//! /World                         Xform (defaultPrim)
//!   /Prototypes                  invisible Scope
//!     /Meshes/<mesh>/mesh        per library mesh used, an Xform holding the Mesh (points, normals, st)
//!     /<mesh>__<material>        per (mesh, material) used: references the geometry, binds the
//!                                material on its Mesh; every instance references one of these
//!   /Looks                       Scope: one Material (UsdPreviewSurface) per cast material; a base
//!                                colour texture as UsdUVTexture + UsdPrimvarReader_float2 (st), its
//!                                PNG in `<stem>_textures/` beside the file (or in the .usdz)
//!   /Set/set_<i>                 instanceable, references a (mesh, material) prototype
//!   /Crowd                       Scope (one collection per render layer)
//!     /agent_<id>                Xform, time-sampled world_from_agent, throng primvars
//!       /<slot>                  instanceable, references a prototype, time-sampled
//!                                agent_from_part (skinned: one child per pose, visibility-sampled)
//!   /shotcam                     Camera: focal length, apertures (tenths of a metre), clipping, time-sampled
//!                                transform; fStop and focusDistance with depth of field
//!   /Lights/sun                  DistantLight, normalized: intensity x color is the irradiance
//!   /Lights/<light>              Sphere (treatAsPoint for point and spot), Rect, Disk or DistantLight
//!   /Lights/dome or /Lights/sky  DomeLight: the HDRI (copied beside the export) turned by rotateY, or the sky
//!   /Atmosphere                  Scope with the shot's haze as throng:atmosphere:* attributes (with `[atmosphere]`)
//! ```
//!
//! Every light in UsdLux's units (docs/usd.md, "Lights").
//!
//! With [`Instancing::PointInstancer`] the crowd is one PointInstancer per
//! part slot instead (ids = agent ids); kept for the measurement in docs/usd.md.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::{Path, PathBuf};

use glam::{Affine3A, Mat4, Quat, Vec3};
use openusd::gf;
use openusd::sdf::{Specifier, Value};

use super::usd_layer::{identifier, LayerBuilder, PrimId, UsdEncoding};
use crate::casting::{Lod, ShotCrowd};
use crate::error::{write_atomic, Error, IoContext, Result};
use crate::layers::Manifest;
use crate::render::atmosphere::{Atmosphere, AtmosphereMode};
use crate::render::cryptomatte::{agent_name, part_name};
use crate::scene::lights::{Dome, Light, LightKind, SceneLights};
use crate::scene::passes::LightGroups;
use crate::scene::{vis, MaterialId, MeshId};

/// Most transform samples one export holds in memory (agents x frames x parts).
pub(crate) const MAX_SAMPLES: usize = 40_000_000;
/// Near and far clipping planes written on the camera: the shot has no
/// clipping keys, and throng's renderer clips at neither.
pub(crate) const CLIPPING_RANGE: [f32; 2] = [0.05, 100_000.0];
/// UsdGeomCamera lengths (focal length, apertures) are in tenths of a scene
/// unit; at `metersPerUnit = 1` that is 100 mm, so 35 mm is written 0.35
/// (docs/usd.md, "Camera units").
pub(crate) const CAMERA_UNITS_PER_MM: f32 = 0.01;

/// How agents are instanced in the stage.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Instancing {
    /// Every agent a prim, every part an instanceable prim referencing a
    /// shared prototype (the default; docs/usd.md says why).
    #[default]
    Prims,
    /// One PointInstancer per part slot, `ids` = agent ids.
    PointInstancer,
}

/// What to export.
#[derive(Clone, Debug)]
pub struct UsdExportOptions<'a> {
    /// First and last shot frame (time codes are shot frames).
    pub frames: (i32, i32),
    /// Only these agents (a layer's).
    pub only: Option<&'a BTreeSet<u32>>,
    /// The layer manifest: the `throng:layer` primvar and per-layer collections.
    pub manifest: Option<&'a Manifest>,
    /// One file per render layer, sublayered by the root file.
    pub split_layers: bool,
    /// Prims or a PointInstancer.
    pub instancing: Instancing,
}

impl UsdExportOptions<'_> {
    /// The whole crowd over `frames`.
    pub fn new(frames: (i32, i32)) -> Self {
        UsdExportOptions { frames, only: None, manifest: None, split_layers: false, instancing: Instancing::Prims }
    }
}

/// What an export wrote.
#[derive(Debug, Clone, serde::Serialize)]
pub struct UsdExportSummary {
    /// Agents written.
    pub agents: usize,
    /// Frames sampled.
    pub frames: usize,
    /// Shared instancing prototypes: one per (mesh, material).
    pub prototypes: usize,
    /// Meshes (geometry written once each, under /World/Prototypes/Meshes).
    pub(crate) meshes: usize,
    /// Materials.
    pub materials: usize,
    /// Instanceable prims (agent parts and set pieces) or point instances per frame.
    pub instances: usize,
    /// Prims in all layers.
    pub prims: usize,
    /// Files written, root last.
    pub files: Vec<PathBuf>,
    /// Bytes written.
    pub bytes: u64,
}

/// One part of one agent over the frames it is present.
struct PartTrack {
    /// Prim name (`<slot>`, `<slot>_1` for a slot's second piece).
    name: String,
    /// Cryptomatte part name `agent_<id>/<slot>`.
    crypto: String,
    material: MaterialId,
    /// (frame, mesh, agent_from_object).
    samples: Vec<(i32, MeshId, Affine3A)>,
}

struct AgentTrack {
    /// (frame, world_from_agent, cycle, cycle frame, seated).
    frames: Vec<(i32, Affine3A, String, f32, bool)>,
    parts: BTreeMap<(u16, usize), PartTrack>,
}

fn matrix(m: &Affine3A) -> Value {
    let cols = Mat4::from(*m).to_cols_array();
    Value::Matrix4d(gf::Matrix4d(cols.map(f64::from)))
}

fn vec3(v: Vec3) -> gf::Vec3f {
    gf::vec3f(v.x, v.y, v.z)
}

fn string(s: &str) -> Value {
    Value::String(s.to_string())
}

/// Samples, or one default when every sample is equal.
enum Track {
    Constant(Value),
    Samples(Vec<(f64, Value)>),
}

fn track(samples: Vec<(f64, Value)>) -> Track {
    match samples.first() {
        Some((_, first)) if samples.iter().all(|(_, v)| v == first) => Track::Constant(first.clone()),
        _ => Track::Samples(samples),
    }
}

fn put(l: &mut LayerBuilder, prim: PrimId, name: &str, ty: &str, samples: Vec<(f64, Value)>) {
    match track(samples) {
        Track::Constant(v) => l.attr(prim, name, ty, v),
        Track::Samples(s) => l.samples(prim, name, ty, s),
    }
}

fn put_primvar(l: &mut LayerBuilder, prim: PrimId, name: &str, ty: &str, samples: Vec<(f64, Value)>) {
    match track(samples) {
        Track::Constant(v) => l.primvar(prim, name, ty, v),
        Track::Samples(s) => l.primvar_samples(prim, name, ty, s),
    }
}

fn xform(l: &mut LayerBuilder, prim: PrimId, samples: Vec<(f64, Value)>) {
    put(l, prim, "xformOp:transform", "matrix4d", samples);
    l.uniform(prim, "xformOpOrder", "token[]", Value::TokenVec(vec!["xformOp:transform".into()]));
}

/// Unique identifiers for sorted keys: `identifier(name)`, then `_1`, `_2` on clashes.
fn unique_names<K: Ord + Copy>(items: impl IntoIterator<Item = (K, String)>) -> BTreeMap<K, String> {
    let mut sorted: Vec<(String, K)> = items.into_iter().map(|(k, n)| (identifier(&n), k)).collect();
    sorted.sort();
    let mut used = BTreeSet::new();
    let mut out = BTreeMap::new();
    for (base, k) in sorted {
        let mut name = base.clone();
        let mut n = 1;
        while !used.insert(name.clone()) {
            name = format!("{base}_{n}");
            n += 1;
        }
        out.insert(k, name);
    }
    out
}

/// Everything the crowd holds over the frame range, gathered once.
struct Gathered {
    agents: BTreeMap<u32, AgentTrack>,
    meshes: BTreeSet<MeshId>,
    materials: BTreeSet<MaterialId>,
    /// Every (mesh, material) an instance uses: one bound prototype each.
    pairs: BTreeSet<(MeshId, MaterialId)>,
}

fn gather(crowd: &ShotCrowd, opts: &UsdExportOptions) -> Result<Gathered> {
    let (a, b) = opts.frames;
    let mut agents: BTreeMap<u32, AgentTrack> = BTreeMap::new();
    let mut meshes = BTreeSet::new();
    let mut materials = BTreeSet::new();
    let mut pairs = BTreeSet::new();
    let mut samples = 0usize;
    let mut insts = Vec::new();
    for f in a..=b {
        let block = crowd.agents_at(f)?;
        for s in block.agents.iter().filter(|s| crowd.renders(s) && opts.only.is_none_or(|o| o.contains(&s.id))) {
            insts.clear();
            crowd.agent_instances(s, Lod::Full, vis::ALL, &mut insts).map_err(|e| e.frame(f.into()))?;
            samples += insts.len() + 1;
            if samples > MAX_SAMPLES {
                return Err(Error::Usage(format!(
                    "the USD export of frames {a}-{b} holds more than {MAX_SAMPLES} transform samples \
                     (agents x frames x parts); export a shorter --frames range or one --layer"
                )));
            }
            let world_from_agent = crowd.world_from_agent(s);
            let agent_from_world = world_from_agent.inverse();
            let t = agents.entry(s.id).or_insert_with(|| AgentTrack { frames: Vec::new(), parts: BTreeMap::new() });
            t.frames.push((f, world_from_agent, crowd.cycle_name(s).to_string(), s.cycle_frame, s.seated()));
            let mut seen: HashMap<u16, usize> = HashMap::new();
            for inst in &insts {
                let k = seen.entry(inst.part).or_insert(0);
                let key = (inst.part, *k);
                *k += 1;
                let slot = crowd.slot_name(s.id, inst.part).unwrap_or("part");
                let part = t.parts.entry(key).or_insert_with(|| PartTrack {
                    name: if key.1 == 0 { identifier(slot) } else { format!("{}_{}", identifier(slot), key.1) },
                    crypto: part_name(s.id, slot),
                    material: inst.material,
                    samples: Vec::new(),
                });
                part.samples.push((f, inst.mesh, agent_from_world * inst.world_from_object));
                meshes.insert(inst.mesh);
                materials.insert(inst.material);
                pairs.insert((inst.mesh, part.material));
            }
        }
    }
    for inst in crowd.set() {
        meshes.insert(inst.mesh);
        materials.insert(inst.material);
        pairs.insert((inst.mesh, inst.material));
    }
    Ok(Gathered { agents, meshes, materials, pairs })
}

/// Writes the crowd as USD to `out` (the encoding from its extension:
/// `.usda` or `.usd` text, or a `.usdz` package of a text layer).
pub fn export_usd(crowd: &ShotCrowd, opts: &UsdExportOptions, out: &Path) -> Result<UsdExportSummary> {
    let encoding = check_request(crowd, opts, out)?;
    let (a, b) = opts.frames;
    let g = gather(crowd, opts)?;
    let lib = crowd.library();
    let mut root = root_layer(crowd.shot(), a, b);
    let mesh_names = write_meshes(&mut root, lib, &g.meshes)?;

    // Materials, and the base colour textures they read (written beside the
    // export, or into the .usdz package).
    let mat_names = unique_names(g.materials.iter().map(|&m| (m, material_name(&lib.materials[m as usize].name))));
    let lights = crowd.lights();
    // The light groups a render's `lg_<name>` passes use, named on each light
    // and emissive material (a shot with more groups than a render writes has none to name).
    let groups = crowd.light_groups().ok();
    let textures = Textures::of(lib, &g.materials, lights.dome.as_deref(), encoding, out)?;
    write_materials(&mut root, lib, &mat_names, groups.as_ref(), &textures);

    let proto_names = write_prototypes(&mut root, &g.pairs, &mesh_names, &mat_names)?;
    let mut instances = write_set(&mut root, crowd, &proto_names)?;
    let times: Vec<i32> = (a..=b).collect();
    let (layer_files, agent_instances) = write_crowd(&mut root, crowd, &g, opts, &times, &proto_names)?;
    instances += agent_instances;
    write_camera(&mut root, crowd, &times)?;
    write_lights(&mut root, &lights, groups.as_ref(), textures.dome_asset().as_deref());
    if let Some(air) = crowd.shot().atmosphere.filter(|a| a.is_active()) {
        write_atmosphere(&mut root, &air);
    }

    // No output over an input: a texture folder or a layer file beside
    // `out` may be a file the shot reads (the shot itself, a texture).
    if encoding != UsdEncoding::Usdz {
        let mut outputs: Vec<PathBuf> = textures.files.values().map(|(rel, _)| out.with_file_name(rel)).collect();
        outputs.extend(textures.dome.iter().map(|(rel, _)| out.with_file_name(rel)));
        outputs.extend(layer_files.keys().map(|layer| out.with_file_name(layer_file_name(out, layer))));
        outputs.push(out.to_path_buf());
        crate::output::InputFiles::new(crowd.input_files()).check_all(outputs.iter().map(PathBuf::as_path))?;
    }
    let written = write_files(root, layer_files, &textures, lights.dome.as_deref(), encoding, out)?;
    Ok(UsdExportSummary {
        agents: g.agents.len(),
        frames: times.len(),
        prototypes: proto_names.len(),
        meshes: mesh_names.len(),
        materials: mat_names.len(),
        instances,
        prims: written.prims,
        files: written.files,
        bytes: written.bytes,
    })
}

/// Checks what an export is asked for before anything is read: a USD file
/// name it can write, frames within the shot, and what split layers need.
fn check_request(crowd: &ShotCrowd, opts: &UsdExportOptions, out: &Path) -> Result<UsdEncoding> {
    let encoding = UsdEncoding::of(out).ok_or_else(|| {
        Error::Usage(format!("{}: a USD export needs a .usda, .usdc, .usd or .usdz file name", out.display()))
    })?;
    if encoding == UsdEncoding::Usdc {
        return Err(Error::Usage(format!(
            "{}: throng cannot write .usdc yet: the binary crate openusd 0.6 writes does not open in Pixar's USD \
             (docs/usd.md); write .usda, .usd (text) or .usdz",
            out.display()
        )));
    }
    let (a, b) = opts.frames;
    let shot = crowd.shot();
    if a > b || !shot.frames.contains(a) || !shot.frames.contains(b) {
        return Err(Error::Usage(format!(
            "frames {a}-{b} are not within shot {} ({}-{})",
            shot.name, shot.frames.start, shot.frames.end
        )));
    }
    if opts.split_layers {
        if encoding == UsdEncoding::Usdz {
            return Err(Error::setting("split_layers", "writes several files; use .usda or .usdc, not .usdz"));
        }
        if opts.manifest.is_none() {
            return Err(Error::setting("split_layers", "needs the layer manifest (run `throng layers` first)"));
        }
    }
    Ok(encoding)
}

/// The root layer: stage metadata for frames `a`-`b` of `shot`, and `/World`.
fn root_layer(shot: &crate::shot::Shot, a: i32, b: i32) -> LayerBuilder {
    let mut root = LayerBuilder::new();
    root.layer_meta("defaultPrim", Value::Token("World".into()));
    root.layer_meta("doc", string(&format!("throng {}: shot {}", env!("CARGO_PKG_VERSION"), shot.name)));
    root.layer_meta("metersPerUnit", Value::Double(1.0));
    root.layer_meta("upAxis", Value::Token("Y".into()));
    root.layer_meta("startTimeCode", Value::Double(a.into()));
    root.layer_meta("endTimeCode", Value::Double(b.into()));
    root.layer_meta("timeCodesPerSecond", Value::Double(shot.frames.fps.into()));
    root.layer_meta("framesPerSecond", Value::Double(shot.frames.fps.into()));
    root.def("/World", "Xform");
    root
}

/// Geometry: one Mesh per library mesh, named from the mesh name, under
/// /World/Prototypes/Meshes. Meshes with the same triangles and UVs (a
/// skinned piece's posed meshes, one per pose step) share them: each
/// references one abstract `class` Mesh under /World/Prototypes/Topology
/// holding `faceVertexCounts`, `faceVertexIndices` and `primvars:st`, and
/// authors only its points, normals and extent. Returns the names.
fn write_meshes(
    root: &mut LayerBuilder,
    lib: &crate::scene::Library,
    meshes: &BTreeSet<MeshId>,
) -> Result<BTreeMap<MeshId, String>> {
    let mesh_names = unique_names(meshes.iter().map(|&m| (m, prototype_name(&lib.meshes[m as usize].name))));
    // A defined but invisible Scope: importers that skip abstract (`class`)
    // prims, Blender's among them, still find the prototypes, and a reference
    // to one brings only its own opinions, not the Scope's invisibility.
    let protos = root.def("/World/Prototypes", "Scope");
    root.attr(protos, "visibility", "token", Value::Token("invisible".into()));
    root.def("/World/Prototypes/Meshes", "Scope");
    let topology = shared_topology(lib, &mesh_names);
    if !topology.is_empty() {
        root.def("/World/Prototypes/Topology", "Scope");
    }
    for (&m, name) in &mesh_names {
        let mesh = &lib.meshes[m as usize];
        // An Xform holding the Mesh: an instance's prototype root is the
        // instance prim itself, so the geometry sits one level down (DCCs
        // such as Blender build their shared prototype from the root's children).
        root.def(&format!("/World/Prototypes/Meshes/{name}"), "Xform");
        let p = root.def(&format!("/World/Prototypes/Meshes/{name}/mesh"), "Mesh");
        let shared = topology.get(&m);
        if let Some(first) = shared {
            let path = format!("/World/Prototypes/Topology/{}", mesh_names[first]);
            if !root.has_prim(&path) {
                let t = root.prim(&path, Specifier::Class, "Mesh");
                mesh_topology(root, t, mesh);
            }
            root.reference(p, &path)?;
        }
        let (lo, hi) = mesh.bounds();
        root.attr(p, "extent", "float3[]", Value::Vec3fVec(vec![vec3(lo), vec3(hi)]));
        root.attr(p, "points", "point3f[]", short_vec3s(&mesh.positions));
        if mesh.normals.len() == mesh.positions.len() {
            root.attr(p, "normals", "normal3f[]", short_vec3s(&mesh.normals));
            root.attr_meta(p, "normals", "interpolation", Value::Token("vertex".into()));
        }
        if shared.is_none() {
            mesh_topology(root, p, mesh);
        }
    }
    Ok(mesh_names)
}

/// A mesh's triangles, UVs (`primvars:st`) and subdivision scheme on `p`.
fn mesh_topology(root: &mut LayerBuilder, p: PrimId, mesh: &crate::scene::Mesh) {
    root.attr(p, "faceVertexCounts", "int[]", Value::IntVec(vec![3; mesh.indices.len() / 3]));
    let indices = mesh.indices.iter().map(|&i| i32::try_from(i).unwrap_or(i32::MAX)).collect();
    root.attr(p, "faceVertexIndices", "int[]", Value::IntVec(indices));
    if mesh.uvs.len() == mesh.positions.len() {
        // glTF's v runs down the image, USD's st up it.
        let st = mesh.uvs.iter().map(|u| gf::Vec2f { x: u.x, y: 1.0 - u.y }).collect();
        root.attr(p, "primvars:st", "texCoord2f[]", Value::Vec2fVec(st));
        root.attr_meta(p, "primvars:st", "interpolation", Value::Token("vertex".into()));
    }
    root.uniform(p, "subdivisionScheme", "token", Value::Token("none".into()));
}

/// Meshes whose triangles and UVs another mesh has too, each mapped to the
/// first (by name) of its group; meshes alone in their group are left out.
fn shared_topology(lib: &crate::scene::Library, names: &BTreeMap<MeshId, String>) -> HashMap<MeshId, MeshId> {
    type Key<'a> = (usize, &'a [u32], Vec<[u32; 2]>);
    let mut groups: HashMap<Key, Vec<MeshId>> = HashMap::new();
    for &m in names.keys() {
        let mesh = &lib.meshes[m as usize];
        let uvs = match mesh.uvs.len() == mesh.positions.len() {
            true => mesh.uvs.iter().map(|u| [u.x.to_bits(), u.y.to_bits()]).collect(),
            false => Vec::new(),
        };
        groups.entry((mesh.positions.len(), &mesh.indices, uvs)).or_default().push(m);
    }
    let mut out = HashMap::new();
    for members in groups.into_values().filter(|g| g.len() > 1) {
        let first = members.iter().copied().min_by(|a, b| names[a].cmp(&names[b])).unwrap_or(members[0]);
        out.extend(members.into_iter().map(|m| (m, first)));
    }
    out
}

/// Float vectors for a text layer: each component the double nearest the
/// shortest decimal that reads back as the same `f32`, so the text writer
/// (which prints every float through a double) writes `0.49999997`, not
/// `0.4999999701976776`. The attribute's own type (`point3f[]`, ...) is
/// what a reader parses it as; only the text encodings are written.
fn short_vec3s(v: &[Vec3]) -> Value {
    let short = |x: f32| format!("{x}").parse::<f64>().unwrap_or(f64::from(x));
    Value::Vec3dVec(v.iter().map(|p| gf::Vec3d { x: short(p.x), y: short(p.y), z: short(p.z) }).collect())
}

/// One UsdPreviewSurface Material per library material under /World/Looks,
/// reading its base colour texture when it has one.
fn write_materials(
    root: &mut LayerBuilder,
    lib: &crate::scene::Library,
    mat_names: &BTreeMap<MaterialId, String>,
    groups: Option<&LightGroups>,
    textures: &Textures,
) {
    root.def("/World/Looks", "Scope");
    for (&m, name) in mat_names {
        let src = &lib.materials[m as usize];
        let path = format!("/World/Looks/{name}");
        let mat = root.def(&path, "Material");
        if let Some(g) = groups.filter(|_| src.emission.max_element() > 0.0) {
            light_group(root, mat, g, g.material(m));
        }
        root.connect(mat, "outputs:surface", "token", &format!("{path}/PreviewSurface.outputs:surface"));
        let sh = root.def(&format!("{path}/PreviewSurface"), "Shader");
        root.uniform(sh, "info:id", "token", Value::Token("UsdPreviewSurface".into()));
        root.attr(sh, "inputs:diffuseColor", "color3f", Value::Vec3f(vec3(src.base_color)));
        if let Some(file) = src.base_color_texture.and_then(|t| textures.asset(t)) {
            // diffuseColor = texture x base colour factor (glTF's rule), the
            // factor as the texture's scale; st from the mesh's primvars:st.
            root.connect(sh, "inputs:diffuseColor", "color3f", &format!("{path}/BaseColor.outputs:rgb"));
            let tex = root.def(&format!("{path}/BaseColor"), "Shader");
            root.uniform(tex, "info:id", "token", Value::Token("UsdUVTexture".into()));
            root.attr(tex, "inputs:file", "asset", Value::AssetPath(file.into()));
            root.connect(tex, "inputs:st", "float2", &format!("{path}/TexCoord.outputs:result"));
            root.attr(tex, "inputs:sourceColorSpace", "token", Value::Token("sRGB".into()));
            let c = src.base_color;
            root.attr(tex, "inputs:scale", "float4", Value::Vec4f(gf::Vec4f { x: c.x, y: c.y, z: c.z, w: 1.0 }));
            root.attr(tex, "inputs:wrapS", "token", Value::Token("repeat".into()));
            root.attr(tex, "inputs:wrapT", "token", Value::Token("repeat".into()));
            root.declare(tex, "outputs:rgb", "float3");
            tex_coord(root, &path);
        }
        if src.emission.max_element() > 0.0 {
            // The emitted radiance as the renderer uses it (emissiveFactor x
            // strength, times the emissive texture when there is one).
            root.attr(sh, "inputs:emissiveColor", "color3f", Value::Vec3f(vec3(src.emission)));
            if let Some(file) = src.emissive_texture.and_then(|t| textures.asset(t)) {
                root.connect(sh, "inputs:emissiveColor", "color3f", &format!("{path}/Emission.outputs:rgb"));
                let tex = root.def(&format!("{path}/Emission"), "Shader");
                root.uniform(tex, "info:id", "token", Value::Token("UsdUVTexture".into()));
                root.attr(tex, "inputs:file", "asset", Value::AssetPath(file.into()));
                root.connect(tex, "inputs:st", "float2", &format!("{path}/TexCoord.outputs:result"));
                root.attr(tex, "inputs:sourceColorSpace", "token", Value::Token("sRGB".into()));
                let e = src.emission;
                root.attr(tex, "inputs:scale", "float4", Value::Vec4f(gf::Vec4f { x: e.x, y: e.y, z: e.z, w: 1.0 }));
                root.attr(tex, "inputs:wrapS", "token", Value::Token("repeat".into()));
                root.attr(tex, "inputs:wrapT", "token", Value::Token("repeat".into()));
                root.declare(tex, "outputs:rgb", "float3");
                tex_coord(root, &path);
            }
        }
        root.attr(sh, "inputs:roughness", "float", Value::Float(src.roughness));
        root.attr(sh, "inputs:metallic", "float", Value::Float(src.metallic));
        root.attr(sh, "outputs:surface", "token", Value::Token("".into()));
    }
}

/// The material's `TexCoord` shader (UsdPrimvarReader_float2 reading
/// `st`), defined once however many textures read it.
fn tex_coord(root: &mut LayerBuilder, material: &str) {
    let path = format!("{material}/TexCoord");
    if root.has_prim(&path) {
        return;
    }
    let st = root.def(&path, "Shader");
    root.uniform(st, "info:id", "token", Value::Token("UsdPrimvarReader_float2".into()));
    root.attr(st, "inputs:varname", "string", string("st"));
    root.declare(st, "outputs:result", "float2");
}

/// Instancing prototypes: one per (mesh, material), referencing the
/// geometry and binding the material on the Mesh inside it, where
/// importers that read bindings only inside an instance's prototype
/// (Blender) see it. Instances of a pair share one prototype. Returns the names.
fn write_prototypes(
    root: &mut LayerBuilder,
    pairs: &BTreeSet<(MeshId, MaterialId)>,
    mesh_names: &BTreeMap<MeshId, String>,
    mat_names: &BTreeMap<MaterialId, String>,
) -> Result<BTreeMap<(MeshId, MaterialId), String>> {
    let proto_names =
        unique_names(pairs.iter().map(|&(m, mt)| ((m, mt), format!("{}__{}", mesh_names[&m], mat_names[&mt]))));
    for (&(m, mt), name) in &proto_names {
        let path = format!("/World/Prototypes/{name}");
        let p = root.def(&path, "Xform");
        root.reference(p, &format!("/World/Prototypes/Meshes/{}", mesh_names[&m]))?;
        let inner = root.prim(&format!("{path}/mesh"), Specifier::Over, "");
        root.api_schemas(inner, &["MaterialBindingAPI"]);
        root.rel(inner, "material:binding", vec![format!("/World/Looks/{}", mat_names[&mt])]);
    }
    Ok(proto_names)
}

/// The set under /World/Set, one instanceable prim per piece; returns how many.
fn write_set(
    root: &mut LayerBuilder,
    crowd: &ShotCrowd,
    proto_names: &BTreeMap<(MeshId, MaterialId), String>,
) -> Result<usize> {
    let mut instances = 0;
    if !crowd.set().is_empty() {
        let set = root.def("/World/Set", "Xform");
        root.primvar(set, "throng:name", "string", string("set"));
        for (i, inst) in crowd.set().iter().enumerate() {
            let p = root.def(&format!("/World/Set/set_{i}"), "Xform");
            root.meta(p, "instanceable", Value::Bool(true));
            root.reference(p, &format!("/World/Prototypes/{}", proto_names[&(inst.mesh, inst.material)]))?;
            xform(root, p, vec![(0.0, matrix(&inst.world_from_object))]);
            instances += 1;
        }
    }
    Ok(instances)
}

/// The render layer agent `id` is in, from the manifest.
fn layer_of(manifest: Option<&Manifest>, id: u32) -> Option<&str> {
    let m = manifest?;
    let a = m.agent(id)?;
    m.layers.get(a.layer).map(|l| l.name.as_str())
}

/// The crowd under /World/Crowd, as prims or PointInstancers, with one
/// collection per render layer. With split layers, each layer's agents go
/// to a layer of their own, returned by layer name; also returns the
/// instances written.
fn write_crowd(
    root: &mut LayerBuilder,
    crowd: &ShotCrowd,
    g: &Gathered,
    opts: &UsdExportOptions,
    times: &[i32],
    proto_names: &BTreeMap<(MeshId, MaterialId), String>,
) -> Result<(BTreeMap<String, LayerBuilder>, usize)> {
    let crowd_prim = root.def("/World/Crowd", "Scope");
    let mut layer_files: BTreeMap<String, LayerBuilder> = BTreeMap::new();
    let mut instances = 0;
    match opts.instancing {
        Instancing::Prims => {
            for (&id, t) in &g.agents {
                let layer = layer_of(opts.manifest, id);
                let l = match (opts.split_layers, layer) {
                    (true, Some(name)) => layer_files.entry(name.to_string()).or_insert_with(|| {
                        let mut l = LayerBuilder::new();
                        l.prim("/World", Specifier::Over, "");
                        l.prim("/World/Crowd", Specifier::Over, "");
                        l
                    }),
                    _ => &mut *root,
                };
                instances += write_agent(l, crowd, id, t, layer, times, proto_names)?;
            }
        }
        Instancing::PointInstancer => {
            instances += write_point_instancers(root, g, times, proto_names)?;
        }
    }
    // One collection per render layer on /World/Crowd.
    if let Some(m) = opts.manifest {
        let mut names = Vec::new();
        let mut members: BTreeMap<&str, Vec<String>> = BTreeMap::new();
        for &id in g.agents.keys() {
            if let Some(layer) = layer_of(opts.manifest, id) {
                members.entry(layer).or_default().push(format!("/World/Crowd/{}", agent_name(id)));
            }
        }
        for l in &m.layers {
            let Some(targets) = members.remove(l.name.as_str()) else { continue };
            if opts.instancing == Instancing::PointInstancer {
                continue;
            }
            names.push(format!("CollectionAPI:{}", l.name));
            root.uniform(
                crowd_prim,
                &format!("collection:{}:expansionRule", l.name),
                "token",
                Value::Token("expandPrims".into()),
            );
            root.rel(crowd_prim, &format!("collection:{}:includes", l.name), targets);
        }
        let names: Vec<&str> = names.iter().map(String::as_str).collect();
        if !names.is_empty() {
            root.api_schemas(crowd_prim, &names);
        }
    }
    Ok((layer_files, instances))
}

/// The file a split render layer is written to, beside `out`: `<stem>.<layer>.<ext>`.
fn layer_file_name(out: &Path, layer: &str) -> String {
    let ext = out.extension().map(|e| e.to_string_lossy().into_owned()).unwrap_or_default();
    let stem = out.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    format!("{stem}.{layer}.{ext}")
}

/// What [`write_files`] wrote.
struct Written {
    /// Files written, root last.
    files: Vec<PathBuf>,
    /// Bytes written.
    bytes: u64,
    /// Prims in all layers.
    prims: usize,
}

/// Writes the files: textures and the dome's map (beside a text export, or
/// into the package), the per-layer files, and the root last.
fn write_files(
    mut root: LayerBuilder,
    layer_files: BTreeMap<String, LayerBuilder>,
    textures: &Textures,
    dome: Option<&Dome>,
    encoding: UsdEncoding,
    out: &Path,
) -> Result<Written> {
    let mut files = Vec::new();
    let mut bytes = 0u64;
    let mut prims = root.prim_count();
    // Textures: files beside a text export, entries of a package.
    let mut package = Vec::new();
    for (rel, data) in textures.files.values() {
        match encoding {
            UsdEncoding::Usdz => package.push((rel.clone(), data.clone())),
            _ => {
                let path = out.with_file_name(rel);
                if let Some(dir) = path.parent() {
                    std::fs::create_dir_all(dir).at(dir)?;
                }
                write_bytes(&path, data)?;
                bytes += data.len() as u64;
                files.push(path);
            }
        }
    }
    // The dome's map: beside a text export, the file as it is; in a
    // package, an OpenEXR (the file's bytes when it is one).
    if let (Some((rel, map)), Some(dome)) = (&textures.dome, dome) {
        match (encoding, map) {
            (UsdEncoding::Usdz, DomeMap::Copy) => package.push((rel.clone(), read_dome_file(&dome.file)?)),
            (UsdEncoding::Usdz, DomeMap::Exr) => package.push((rel.clone(), dome_exr(dome)?)),
            _ => {
                let path = out.with_file_name(rel);
                if let Some(dir) = path.parent() {
                    std::fs::create_dir_all(dir).at(dir)?;
                }
                bytes += copy_file(&dome.file, &path)?;
                files.push(path);
            }
        }
    }
    for (layer, l) in layer_files {
        let name = layer_file_name(out, &layer);
        let path = out.with_file_name(&name);
        prims += l.prim_count();
        let data = l.encode_with(encoding, &name, &[])?;
        write_bytes(&path, &data)?;
        bytes += data.len() as u64;
        root.sublayer(format!("./{name}"));
        files.push(path);
    }
    let name = out.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let data = root.encode_with(encoding, &name, &package)?;
    write_bytes(out, &data)?;
    bytes += data.len() as u64;
    files.push(out.to_path_buf());
    Ok(Written { files, bytes, prims })
}

/// The base colour textures an export writes, as PNG files in
/// `<out stem>_textures/` beside the exported file (or inside the `.usdz`
/// package, at the same relative path), so `inputs:file` resolves from the
/// layer wherever the export is copied.
struct Textures {
    /// Texture id -> (path relative to the exported file, PNG bytes).
    files: BTreeMap<u32, (String, Vec<u8>)>,
    /// The dome's map: its path relative to the exported file, and how it is written.
    dome: Option<(String, DomeMap)>,
}

/// How the dome's map goes with an export.
enum DomeMap {
    /// The file's own bytes.
    Copy,
    /// Its texels as an OpenEXR: a `.usdz` package takes no Radiance `.hdr`
    /// (usdchecker: "unknown unsupported extension").
    Exr,
}

impl Textures {
    fn of(
        lib: &crate::scene::Library,
        materials: &BTreeSet<MaterialId>,
        dome: Option<&Dome>,
        encoding: UsdEncoding,
        out: &Path,
    ) -> Result<Textures> {
        // Base colour textures, and the emissive textures of emissive materials.
        let used: BTreeSet<u32> = materials
            .iter()
            .filter_map(|&m| lib.materials.get(m as usize))
            .flat_map(|m| {
                let emissive = m.emissive_texture.filter(|_| m.emission.max_element() > 0.0);
                [m.base_color_texture, emissive]
            })
            .flatten()
            .collect();
        let stem = out.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
        let dir = format!("{}_textures", identifier(&stem));
        let names =
            unique_names(used.iter().filter_map(|&t| Some((t, texture_name(&lib.textures.get(t as usize)?.name)))));
        let mut files = BTreeMap::new();
        for (t, name) in names {
            let tex = &lib.textures[t as usize];
            files.insert(t, (format!("{dir}/{name}.png"), png(tex)?));
        }
        // The map keeps its extension (.hdr or .exr, as the loader read it),
        // so no PNG texture takes its name.
        let dome = dome.map(|d| {
            let stem = d.file.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
            let ext = d.file.extension().map(|e| e.to_string_lossy().to_ascii_lowercase()).unwrap_or_default();
            let map = if encoding == UsdEncoding::Usdz && ext != "exr" { DomeMap::Exr } else { DomeMap::Copy };
            let ext = if matches!(map, DomeMap::Exr) { "exr".to_string() } else { identifier(&ext) };
            (format!("{dir}/{}.{ext}", identifier(&stem)), map)
        });
        Ok(Textures { files, dome })
    }

    /// The asset path the DomeLight's `inputs:texture:file` holds.
    fn dome_asset(&self) -> Option<String> {
        self.dome.as_ref().map(|(rel, _)| format!("./{rel}"))
    }

    /// The asset path a material's `inputs:file` holds.
    fn asset(&self, texture: u32) -> Option<String> {
        self.files.get(&texture).map(|(rel, _)| format!("./{rel}"))
    }
}

/// A material's name: a wardrobe material's own (`robots/chrome`), a glTF
/// material `<file>#<name>` as `<file stem>_<name>`, never the directory
/// (which depends on how the shot's paths were given).
fn material_name(name: &str) -> String {
    match name.contains('#') {
        true => prototype_name(name),
        false => name.to_string(),
    }
}

/// A texture's file name (without `.png`) from its library name: a glTF
/// image `<file>#<label>` gives `<file stem>_<label>`, a PNG its stem.
fn texture_name(name: &str) -> String {
    match name.contains('#') {
        true => prototype_name(name),
        false => Path::new(name).file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default(),
    }
}

/// Linear 0..1 to an 8-bit sRGB code (the inverse of the loader's decode,
/// so an 8-bit sRGB texture comes back with the same bytes).
fn srgb8(c: f32) -> u8 {
    let c = c.clamp(0.0, 1.0);
    let e = if c <= 0.0031308 { c * 12.92 } else { 1.055 * c.powf(1.0 / 2.4) - 0.055 };
    (e * 255.0).round().clamp(0.0, 255.0) as u8
}

/// A library texture (linear RGBA, sRGB colour) as PNG bytes.
fn png(tex: &crate::scene::Texture) -> Result<Vec<u8>> {
    let n = tex.width as usize * tex.height as usize;
    if tex.texels.len() != n || n == 0 {
        return Err(Error::invalid(
            &tex.name,
            format!("texture holds {} texels for {}x{}", tex.texels.len(), tex.width, tex.height),
        ));
    }
    let mut bytes = Vec::with_capacity(n * 4);
    for t in &tex.texels {
        bytes.extend([srgb8(t[0]), srgb8(t[1]), srgb8(t[2]), (t[3].clamp(0.0, 1.0) * 255.0).round() as u8]);
    }
    let img = image::RgbaImage::from_raw(tex.width, tex.height, bytes)
        .ok_or_else(|| Error::invalid(&tex.name, "texture size does not match its texels"))?;
    let mut out = std::io::Cursor::new(Vec::new());
    img.write_to(&mut out, image::ImageFormat::Png)
        .map_err(|e| Error::invalid(&tex.name, format!("cannot encode the texture as PNG: {e}")))?;
    Ok(out.into_inner())
}

/// A prototype's name from its mesh's library name `<file>#<mesh>`: the
/// file stem and mesh name, never the directory (which depends on how the
/// shot's path was given).
pub(crate) fn prototype_name(mesh: &str) -> String {
    match mesh.rsplit_once('#') {
        Some((file, name)) => {
            let stem = Path::new(file).file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
            format!("{stem}_{name}")
        }
        None => mesh.rsplit('/').next().unwrap_or(mesh).to_string(),
    }
}

/// Largest dome map a `.usdz` package takes into memory (a 16384 x 8192
/// float RGBA OpenEXR, uncompressed, is 2 GiB).
pub(crate) const MAX_PACKAGED_DOME_BYTES: u64 = 2 << 30;

/// A dome map's bytes, for a package.
fn read_dome_file(source: &Path) -> Result<Vec<u8>> {
    let len = std::fs::metadata(source).at(source)?.len();
    if len > MAX_PACKAGED_DOME_BYTES {
        return Err(Error::invalid(
            source,
            format!(
                "the dome map is {len} bytes, more than a .usdz package takes ({MAX_PACKAGED_DOME_BYTES}); \
                 export .usda, which copies it beside the layer"
            ),
        ));
    }
    std::fs::read(source).at(source)
}

/// A dome's texels (before its scale: that is the light's intensity and
/// colour) as a float RGB OpenEXR, linear Rec.709 as the map was read.
fn dome_exr(dome: &Dome) -> Result<Vec<u8>> {
    use exr::prelude::{
        Blocks, Compression, Encoding, Image, Layer, LayerAttributes, LineOrder, SpecificChannels, WritableImage,
    };
    let (w, h) = (dome.width as usize, dome.height as usize);
    if dome.texels.len() != w * h {
        return Err(Error::invalid(&dome.file, format!("the dome holds {} texels for {w} x {h}", dome.texels.len())));
    }
    let channels = SpecificChannels::rgb(|p: exr::math::Vec2<usize>| {
        let t = dome.texels[p.y() * w + p.x()];
        (t.x, t.y, t.z)
    });
    let encoding =
        Encoding { compression: Compression::ZIP16, blocks: Blocks::ScanLines, line_order: LineOrder::Increasing };
    let mut image = Image::from_layer(Layer::new((w, h), LayerAttributes::default(), encoding, channels));
    image.attributes.chromaticities = Some(crate::render::exr::rec709_chromaticities());
    let mut bytes = Vec::new();
    image
        .write()
        .to_buffered(std::io::Cursor::new(&mut bytes))
        .map_err(|e| Error::invalid(&dome.file, format!("cannot encode the dome map as OpenEXR: {e}")))?;
    Ok(bytes)
}

/// Copies `source` to `path` (atomically); the bytes copied.
fn copy_file(source: &Path, path: &Path) -> Result<u64> {
    let mut copied = 0;
    write_atomic(path, |w| {
        let mut f = std::fs::File::open(source).at(source)?;
        copied = std::io::copy(&mut f, w).at(path)?;
        Ok(())
    })?;
    Ok(copied)
}

fn write_bytes(path: &Path, data: &[u8]) -> Result<()> {
    use std::io::Write;
    write_atomic(path, |w| w.write_all(data).at(path))
}

#[allow(clippy::too_many_arguments, reason = "one call site; the pieces of one export")]
fn write_agent(
    l: &mut LayerBuilder,
    crowd: &ShotCrowd,
    id: u32,
    t: &AgentTrack,
    layer: Option<&str>,
    times: &[i32],
    proto_names: &BTreeMap<(MeshId, MaterialId), String>,
) -> Result<usize> {
    let path = format!("/World/Crowd/{}", agent_name(id));
    let p = l.def(&path, "Xform");
    xform(l, p, t.frames.iter().map(|(f, m, ..)| (f64::from(*f), matrix(m))).collect());
    let present: BTreeSet<i32> = t.frames.iter().map(|x| x.0).collect();
    if present.len() < times.len() {
        let vis = |f: &i32| {
            let v = if present.contains(f) { "inherited" } else { "invisible" };
            (f64::from(*f), Value::Token(v.into()))
        };
        l.samples(p, "visibility", "token", times.iter().map(vis).collect());
    }
    let cast = crowd.cast(id).ok_or_else(|| {
        Error::invalid(&crowd.shot().cache.path, "agent was not cast (not in the shot's frames)").agent(id)
    })?;
    l.primvar(p, "throng:agentId", "int", Value::Int(i32::try_from(id).unwrap_or(i32::MAX)));
    l.primvar(p, "throng:name", "string", string(&agent_name(id)));
    l.primvar(p, "throng:rig", "string", string(&cast.rig));
    l.primvar(p, "throng:scheme", "string", string(&cast.scheme));
    put_primvar(
        l,
        p,
        "throng:cycle",
        "string",
        t.frames.iter().map(|(f, _, c, ..)| (f64::from(*f), string(c))).collect(),
    );
    let cf = t.frames.iter().map(|(f, _, _, cf, _)| (f64::from(*f), Value::Float(*cf))).collect();
    put_primvar(l, p, "throng:cycleFrame", "float", cf);
    let seated = t.frames.iter().map(|(f, .., s)| (f64::from(*f), Value::Bool(*s))).collect();
    put_primvar(l, p, "throng:seated", "bool", seated);
    if let Some(layer) = layer {
        l.primvar(p, "throng:layer", "string", string(layer));
    }
    let mut count = 0;
    for part in t.parts.values() {
        let ppath = format!("{path}/{}", part.name);
        let pp = l.def(&ppath, "Xform");
        l.primvar(pp, "throng:name", "string", string(&part.crypto));
        xform(l, pp, part.samples.iter().map(|(f, _, m)| (f64::from(*f), matrix(m))).collect());
        let used: BTreeSet<MeshId> = part.samples.iter().map(|s| s.1).collect();
        let proto = |mesh: MeshId| &proto_names[&(mesh, part.material)];
        if used.len() == 1 {
            let mesh = part.samples[0].1;
            l.meta(pp, "instanceable", Value::Bool(true));
            l.reference(pp, &format!("/World/Prototypes/{}", proto(mesh)))?;
            count += 1;
            continue;
        }
        // A skinned part: one child per pose it takes, shown on its frames.
        for &mesh in &used {
            let c = l.def(&format!("{ppath}/{}", proto(mesh)), "");
            l.meta(c, "instanceable", Value::Bool(true));
            l.reference(c, &format!("/World/Prototypes/{}", proto(mesh)))?;
            let on: BTreeSet<i32> = part.samples.iter().filter(|s| s.1 == mesh).map(|s| s.0).collect();
            let vis = part
                .samples
                .iter()
                .map(|s| {
                    let v = if on.contains(&s.0) { "inherited" } else { "invisible" };
                    (f64::from(s.0), Value::Token(v.into()))
                })
                .collect();
            l.samples(c, "visibility", "token", vis);
            count += 1;
        }
    }
    Ok(count)
}

/// The PointInstancer layout: one instancer per part prim name; each
/// (mesh, material) a prototype under it; per frame `ids` (agent ids),
/// `protoIndices`, `positions`, `orientations`, `scales`.
fn write_point_instancers(
    l: &mut LayerBuilder,
    g: &Gathered,
    times: &[i32],
    proto_names: &BTreeMap<(MeshId, MaterialId), String>,
) -> Result<usize> {
    // part name -> frame -> (id, (mesh, material), world_from_object)
    type Frames = BTreeMap<i32, Vec<(u32, (MeshId, MaterialId), Affine3A)>>;
    let mut groups: BTreeMap<String, Frames> = BTreeMap::new();
    for (&id, t) in &g.agents {
        let world: BTreeMap<i32, Affine3A> = t.frames.iter().map(|x| (x.0, x.1)).collect();
        for part in t.parts.values() {
            let frames = groups.entry(part.name.clone()).or_default();
            for &(f, mesh, m) in &part.samples {
                frames.entry(f).or_default().push((id, (mesh, part.material), world[&f] * m));
            }
        }
    }
    let mut total = 0;
    for (name, frames) in &groups {
        let mut most = 0;
        let path = format!("/World/Crowd/{name}");
        let pi = l.def(&path, "PointInstancer");
        let protos: BTreeSet<(MeshId, MaterialId)> = frames.values().flatten().map(|x| x.1).collect();
        let index: BTreeMap<(MeshId, MaterialId), i32> =
            protos.iter().enumerate().map(|(i, &k)| (k, i as i32)).collect();
        l.def(&format!("{path}/Prototypes"), "Scope");
        let mut targets = Vec::new();
        for key in &protos {
            let pp = format!("{path}/Prototypes/{}", proto_names[key]);
            let c = l.def(&pp, "");
            l.reference(c, &format!("/World/Prototypes/{}", proto_names[key]))?;
            targets.push(pp);
        }
        l.rel(pi, "prototypes", targets);
        let (mut ids, mut idx, mut pos, mut ori, mut scl) = (vec![], vec![], vec![], vec![], vec![]);
        for &f in times {
            let rows = frames.get(&f).map(Vec::as_slice).unwrap_or(&[]);
            most = most.max(rows.len());
            let t = f64::from(f);
            ids.push((t, Value::Int64Vec(rows.iter().map(|r| i64::from(r.0)).collect())));
            idx.push((t, Value::IntVec(rows.iter().map(|r| index[&r.1]).collect())));
            let trs: Vec<(Vec3, Quat, Vec3)> = rows.iter().map(|r| r.2.to_scale_rotation_translation()).collect();
            pos.push((t, Value::Vec3fVec(trs.iter().map(|x| vec3(x.2)).collect())));
            let q = |q: &Quat| gf::Quath {
                w: gf::f16::from_f32(q.w),
                x: gf::f16::from_f32(q.x),
                y: gf::f16::from_f32(q.y),
                z: gf::f16::from_f32(q.z),
            };
            ori.push((t, Value::QuathVec(trs.iter().map(|x| q(&x.1)).collect())));
            scl.push((t, Value::Vec3fVec(trs.iter().map(|x| vec3(x.0)).collect())));
        }
        l.samples(pi, "ids", "int64[]", ids);
        l.samples(pi, "protoIndices", "int[]", idx);
        l.samples(pi, "positions", "point3f[]", pos);
        l.samples(pi, "orientations", "quath[]", ori);
        l.samples(pi, "scales", "float3[]", scl);
        total += most;
    }
    Ok(total)
}

fn write_camera(l: &mut LayerBuilder, crowd: &ShotCrowd, times: &[i32]) -> Result<()> {
    let shot = crowd.shot();
    let width = shot.camera.sensor_width;
    let height = width / shot.aspect();
    let cam = l.def("/World/shotcam", "Camera");
    let mut xf = Vec::new();
    let mut focal = Vec::new();
    let (mut f_stop, mut focus) = (Vec::new(), Vec::new());
    for &f in times {
        let c = crowd.camera(f)?;
        let t = f64::from(f);
        xf.push((t, matrix(&c.world_from_camera)));
        // Focal length from the vertical field of view and film back: exact for keyed cameras.
        let lens = keyed_lens(shot, f as f32);
        let mm = match lens {
            None => height * 0.5 / (c.yfov * 0.5).tan(),
            Some(k) => k.focal_length,
        };
        focal.push((t, Value::Float(mm * CAMERA_UNITS_PER_MM)));
        // Depth of field: the f-number (dimensionless) and the focus
        // distance (scene units, metres), as the renderer interpolates them.
        if let Some(Lens { f_stop: Some(n), focus_distance: Some(d), .. }) = lens {
            f_stop.push((t, Value::Float(n)));
            focus.push((t, Value::Float(d)));
        }
    }
    xform(l, cam, xf);
    put(l, cam, "focalLength", "float", focal);
    l.attr(cam, "horizontalAperture", "float", Value::Float(width * CAMERA_UNITS_PER_MM));
    l.attr(cam, "verticalAperture", "float", Value::Float(height * CAMERA_UNITS_PER_MM));
    l.attr(cam, "clippingRange", "float2", Value::Vec2f(gf::Vec2f { x: CLIPPING_RANGE[0], y: CLIPPING_RANGE[1] }));
    l.uniform(cam, "projection", "token", Value::Token("perspective".into()));
    if !f_stop.is_empty() {
        put(l, cam, "fStop", "float", f_stop);
        put(l, cam, "focusDistance", "float", focus);
    }
    Ok(())
}

/// The keyed lens at a frame.
#[derive(Clone, Copy)]
struct Lens {
    /// Millimetres.
    focal_length: f32,
    /// f-number, when the shot has depth of field.
    f_stop: Option<f32>,
    /// Metres, when the shot has depth of field.
    focus_distance: Option<f32>,
}

/// The keyed focal length, f-stop and focus distance at a frame,
/// interpolated linearly as `Shot::keyed_camera` does; `None` for a glTF camera.
fn keyed_lens(shot: &crate::shot::Shot, frame: f32) -> Option<Lens> {
    let keys = &shot.camera.keys;
    let (first, last) = (keys.first()?, keys.last()?);
    let lens = |k: &crate::shot::CameraKey| Lens {
        focal_length: k.focal_length,
        f_stop: k.f_stop,
        focus_distance: k.focus_distance,
    };
    if frame <= first.frame {
        return Some(lens(first));
    }
    if frame >= last.frame {
        return Some(lens(last));
    }
    let i = keys.windows(2).position(|w| frame >= w[0].frame && frame <= w[1].frame).unwrap_or(0);
    let (a, b) = (&keys[i], &keys[i + 1]);
    let t = if b.frame > a.frame { (frame - a.frame) / (b.frame - a.frame) } else { 0.0 };
    let mix = |x: f32, y: f32| x + (y - x) * t;
    let both = |x: Option<f32>, y: Option<f32>| Some(mix(x?, y?));
    Some(Lens {
        focal_length: mix(a.focal_length, b.focal_length),
        f_stop: both(a.f_stop, b.f_stop),
        focus_distance: both(a.focus_distance, b.focus_distance),
    })
}

/// `inputs:intensity` and `inputs:color` for an RGB quantity: the peak
/// channel as the intensity and the colour normalised to it (exposure 0).
fn emission(l: &mut LayerBuilder, p: PrimId, value: Vec3) {
    let peak = value.max_element();
    let (intensity, color) = if peak > 0.0 { (peak, value / peak) } else { (0.0, Vec3::ONE) };
    l.attr(p, "inputs:intensity", "float", Value::Float(intensity));
    l.attr(p, "inputs:color", "color3f", Value::Vec3f(vec3(color)));
}

/// A DistantLight shining down `world_from_light`'s -Z with irradiance
/// `irradiance` (W/m^2 at normal incidence): `inputs:normalize` on makes
/// UsdLux's intensity the irradiance (docs/usd.md, "Lights").
fn distant_light(
    l: &mut LayerBuilder,
    path: &str,
    world_from_light: Affine3A,
    irradiance: Vec3,
    diameter: f32,
) -> PrimId {
    let p = l.def(path, "DistantLight");
    xform(l, p, vec![(0.0, matrix(&world_from_light))]);
    emission(l, p, irradiance);
    l.attr(p, "inputs:normalize", "bool", Value::Bool(true));
    l.attr(p, "inputs:angle", "float", Value::Float(diameter.to_degrees()));
    p
}

/// One point, spot, area or distant light at `world_from_light` (shining
/// down its -Z), named `path`.
fn local_light(l: &mut LayerBuilder, path: &str, light: &Light, world_from_light: Affine3A) -> PrimId {
    let p = match light.kind {
        LightKind::Distant { angular_diameter } => {
            distant_light(l, path, world_from_light, light.emission, angular_diameter)
        }
        LightKind::Point | LightKind::Spot { .. } => {
            // A zero-radius SphereLight. With normalize on, a sphere's
            // luminance is intensity / (4 pi r^2) and its radiant intensity
            // that times its projected area pi r^2: intensity / 4 at any
            // radius, and so in the limit r -> 0.
            let p = l.def(path, "SphereLight");
            if let LightKind::Spot { outer, blend } = light.kind {
                l.api_schemas(p, &["ShapingAPI"]);
                l.attr(p, "inputs:shaping:cone:angle", "float", Value::Float(outer.to_degrees()));
                l.attr(p, "inputs:shaping:cone:softness", "float", Value::Float(blend));
            }
            xform(l, p, vec![(0.0, matrix(&world_from_light))]);
            emission(l, p, light.emission * 4.0);
            l.attr(p, "inputs:normalize", "bool", Value::Bool(true));
            l.attr(p, "inputs:radius", "float", Value::Float(0.0));
            l.attr(p, "treatAsPoint", "bool", Value::Bool(true));
            p
        }
        // Area lights: intensity x color is the radiance (normalize off).
        LightKind::Rect { size } => {
            let p = l.def(path, "RectLight");
            xform(l, p, vec![(0.0, matrix(&world_from_light))]);
            emission(l, p, light.emission);
            l.attr(p, "inputs:width", "float", Value::Float(size.x));
            l.attr(p, "inputs:height", "float", Value::Float(size.y));
            p
        }
        LightKind::Disk { radius } | LightKind::Sphere { radius } => {
            let ty = if matches!(light.kind, LightKind::Disk { .. }) { "DiskLight" } else { "SphereLight" };
            let p = l.def(path, ty);
            xform(l, p, vec![(0.0, matrix(&world_from_light))]);
            emission(l, p, light.emission);
            l.attr(p, "inputs:radius", "float", Value::Float(radius));
            p
        }
    };
    l.attr(p, "throng:name", "string", string(&light.name));
    p
}

/// `throng:lightGroup` on prim `p`: the name of the light group (its pass
/// is `lg_<name>`) the prim's light is in, for a studio renderer to match.
fn light_group(l: &mut LayerBuilder, p: PrimId, groups: &LightGroups, group: u16) {
    if let Some(name) = groups.names.get(group as usize) {
        l.attr(p, "throng:lightGroup", "string", string(name));
    }
}

/// Every light in UsdLux's units (docs/usd.md, "Lights"): the sun, the
/// shot's and the set's lights, and the dome (with its map) or the uniform sky.
fn write_lights(l: &mut LayerBuilder, lights: &SceneLights, groups: Option<&LightGroups>, dome_asset: Option<&str>) {
    l.def("/World/Lights", "Scope");
    // Prim names: the sun and the environment keep theirs, local lights
    // take their own, made unique.
    let env = if lights.dome.is_some() { "dome" } else { "sky" };
    // A two-sided rect or disk is two UsdLux lights, back to back.
    let twin = |light: &Light| light.two_sided && matches!(light.kind, LightKind::Rect { .. } | LightKind::Disk { .. });
    let mut pool = vec![(0, "sun".to_string()), (1, env.to_string())];
    for (i, light) in lights.local.iter().enumerate() {
        pool.push((2 + 2 * i, light.name.clone()));
        if twin(light) {
            pool.push((3 + 2 * i, format!("{}_back", light.name)));
        }
    }
    let names = unique_names(pool);
    if let Some(sun) = &lights.sun {
        // Down its local -Z: from the sun towards the scene.
        let rot = Quat::from_rotation_arc(Vec3::NEG_Z, -sun.direction);
        let p = distant_light(l, "/World/Lights/sun", Affine3A::from_quat(rot), sun.irradiance, sun.angular_diameter);
        if let Some(g) = groups {
            light_group(l, p, g, g.sun());
        }
    }
    for (i, light) in lights.local.iter().enumerate() {
        let p = local_light(l, &format!("/World/Lights/{}", names[&(2 + 2 * i)]), light, light.world_from_light);
        let mut prims = vec![p];
        if twin(light) {
            // UsdLux's rect and disk lights emit from one face: the back
            // face is a twin turned half a turn about its local Y.
            let back = light.world_from_light * Affine3A::from_rotation_y(std::f32::consts::PI);
            prims.push(local_light(l, &format!("/World/Lights/{}", names[&(3 + 2 * i)]), light, back));
        }
        for p in prims {
            if let Some(g) = groups {
                light_group(l, p, g, g.local(i));
            }
        }
    }
    match &lights.dome {
        Some(dome) => {
            // OpenEXR's lat-long, as UsdLux's DomeLight reads it, puts the
            // image centre at +Z; throng's unrotated dome has it at +X, a
            // quarter turn about +Y.
            let p = l.def("/World/Lights/dome", "DomeLight");
            l.attr(p, "xformOp:rotateY", "float", Value::Float(dome.rotate.to_degrees() + 90.0));
            l.uniform(p, "xformOpOrder", "token[]", Value::TokenVec(vec!["xformOp:rotateY".into()]));
            emission(l, p, dome.scale);
            if let Some(asset) = dome_asset {
                l.attr(p, "inputs:texture:file", "asset", Value::AssetPath(asset.into()));
            }
            l.attr(p, "inputs:texture:format", "token", Value::Token("latlong".into()));
            if let Some(g) = groups {
                light_group(l, p, g, g.environment());
            }
        }
        None => {
            let p = l.def("/World/Lights/sky", "DomeLight");
            emission(l, p, lights.sky.radiance);
            if let Some(g) = groups {
                light_group(l, p, g, g.environment());
            }
        }
    }
}

/// The shot's atmosphere as documented attributes on `/World/Atmosphere`
/// (docs/usd.md, "Atmosphere"): UsdVol has no homogeneous medium without
/// a field asset, and a renderer's world volume is its own schema.
fn write_atmosphere(l: &mut LayerBuilder, air: &Atmosphere) {
    let p = l.def("/World/Atmosphere", "Scope");
    l.attr(p, "throng:atmosphere:density", "float", Value::Float(air.density));
    l.attr(p, "throng:atmosphere:albedo", "color3f", Value::Vec3f(vec3(air.albedo)));
    l.attr(p, "throng:atmosphere:anisotropy", "float", Value::Float(air.anisotropy));
    if air.top.is_finite() {
        l.attr(p, "throng:atmosphere:height", "float", Value::Float(air.top));
    }
    let mode = match air.mode {
        AtmosphereMode::Full => "full",
        AtmosphereMode::Haze => "haze",
    };
    l.attr(p, "throng:atmosphere:mode", "token", Value::Token(mode.into()));
    if air.falloff.is_finite() {
        l.attr(p, "throng:atmosphere:falloff", "float", Value::Float(air.falloff));
        l.attr(p, "throng:atmosphere:base", "float", Value::Float(air.base));
    }
    if air.start > 0.0 {
        l.attr(p, "throng:atmosphere:start", "float", Value::Float(air.start));
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_codes_survive_the_loaders_decode() {
        for code in 0..=255u8 {
            let linear = crate::scene::gltf::srgb_to_linear(f32::from(code) / 255.0);
            assert_eq!(srgb8(linear), code);
        }
    }

    #[test]
    fn a_packaged_dome_map_reads_back_texel_for_texel() {
        let texels: Vec<Vec3> =
            (0..32).map(|i| Vec3::new(i as f32 * 0.37, 1e4 / (1.0 + i as f32), (i % 5) as f32 * 1e-3)).collect();
        let dome = Dome {
            file: PathBuf::from("sky.hdr"),
            width: 8,
            height: 4,
            texels: texels.clone(),
            scale: Vec3::splat(2.0),
            rotate: 0.5,
            camera_visible: true,
        };
        let bytes = dome_exr(&dome).unwrap();
        let path = std::env::temp_dir().join(format!("throng-usd-dome-{}.exr", std::process::id()));
        std::fs::write(&path, &bytes).unwrap();
        let back = crate::scene::dome::load_dome(&path, Vec3::ONE, 0.0, true).unwrap();
        std::fs::remove_file(&path).unwrap();
        assert_eq!((back.width, back.height), (8, 4));
        assert_eq!(back.texels, texels);
        // Deterministic: the same bytes twice.
        assert!(dome_exr(&dome).unwrap() == bytes);
    }

    #[test]
    fn short_floats_read_back_as_the_same_f32() {
        let mut x = 0x1234_5678u32;
        let mut values = vec![0.0f32, -0.0, 1.0, 0.5 - f32::EPSILON / 4.0, 1e-38, 3.4e38, 0.1, 1.0 / 3.0];
        for _ in 0..20_000 {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            let f = f32::from_bits(x);
            if f.is_finite() {
                values.push(f);
            }
        }
        let v: Vec<Vec3> = values.chunks(3).filter(|c| c.len() == 3).map(|c| Vec3::new(c[0], c[1], c[2])).collect();
        let Value::Vec3dVec(short) = short_vec3s(&v) else { panic!("not a double vector") };
        for (p, s) in v.iter().zip(&short) {
            // The text writer prints a double's shortest form; a reader parses it as float.
            for (want, d) in [(p.x, s.x), (p.y, s.y), (p.z, s.z)] {
                let back: f32 = format!("{d}").parse().unwrap();
                assert_eq!(back.to_bits(), want.to_bits(), "{want} written as {d}");
            }
        }
    }

    #[test]
    fn names_drop_directories() {
        assert_eq!(material_name("/a/b/set.glb#floor"), "set_floor");
        assert_eq!(material_name("robots/chrome"), "robots/chrome");
        assert_eq!(texture_name("/a/wardrobes/textures/hazard.png"), "hazard");
        assert_eq!(texture_name("../demo/set/set.glb#paint"), "set_paint");
    }
}
