//! `throng export`: one frame of the shot (agents, set, camera, sun) as a
//! binary glTF, meshes shared between nodes, so it opens in Blender or any
//! viewer and can be rendered by other renderers for comparison.

pub mod glb;
pub mod usd;
pub(crate) mod usd_layer;

use std::collections::{BTreeSet, HashMap};
use std::path::Path;

use glam::{Affine3A, Mat4};

use crate::casting::{Lod, ShotCrowd};
use crate::error::Result;
use crate::scene::lights::LightKind;
use crate::scene::{vis, Instance, Library, MaterialId, MeshId};
use glb::{GlbBuilder, MaterialDesc, MeshData, NodeDesc, Perspective, Transform};
use std::f32::consts::PI;

/// What an export wrote.
#[derive(Debug, Clone, serde::Serialize)]
pub struct ExportSummary {
    /// Agents written.
    pub agents: usize,
    /// Part and set nodes with a mesh.
    pub mesh_nodes: usize,
    /// Unique glTF meshes (one per part mesh and material pair).
    pub meshes: usize,
    /// Triangles once instanced.
    pub instanced_triangles: usize,
}

/// glTF intensity of a directional light is illuminance in lux; the peers'
/// importers read W/m^2 = lux / 683.
const LUX_PER_WATT: f32 = 683.0;

fn matrix(m: &Affine3A) -> Transform {
    Transform::Matrix(Mat4::from(*m).to_cols_array())
}

struct Writer<'a> {
    glb: GlbBuilder,
    lib: &'a Library,
    meshes: HashMap<(MeshId, MaterialId), glb::MeshId>,
    materials: HashMap<MaterialId, glb::MaterialId>,
    triangles: usize,
    mesh_nodes: usize,
}

impl Writer<'_> {
    fn mesh(&mut self, mesh: MeshId, material: MaterialId) -> Result<glb::MeshId> {
        if let Some(&m) = self.meshes.get(&(mesh, material)) {
            return Ok(m);
        }
        let mat = match self.materials.get(&material) {
            Some(&m) => m,
            None => {
                let src = &self.lib.materials[material as usize];
                let c = src.base_color;
                let desc = MaterialDesc::new(src.name.clone(), [c.x, c.y, c.z, 1.0])
                    .pbr(src.metallic, src.roughness)
                    .emission(src.emission.to_array());
                let m = self.glb.add_material(&desc);
                self.materials.insert(material, m);
                m
            }
        };
        let src = &self.lib.meshes[mesh as usize];
        let data = MeshData {
            positions: src.positions.iter().map(|p| p.to_array()).collect(),
            normals: src.normals.iter().map(|n| n.to_array()).collect(),
            uvs: src.uvs.iter().map(|u| u.to_array()).collect(),
            indices: src.indices.clone(),
            ..Default::default()
        };
        let name = format!("{}|{}", src.name, self.lib.materials[material as usize].name);
        let m = self.glb.add_mesh(&name, &data, Some(mat))?;
        self.meshes.insert((mesh, material), m);
        Ok(m)
    }

    fn instance_node(&mut self, name: String, inst: &Instance, parent_from_object: &Affine3A) -> Result<glb::NodeId> {
        let mesh = self.mesh(inst.mesh, inst.material)?;
        self.triangles += self.lib.meshes[inst.mesh as usize].triangle_count();
        self.mesh_nodes += 1;
        let mut node = NodeDesc::new(name).mesh(mesh);
        node.transform = matrix(parent_from_object);
        self.glb.add_node(node)
    }
}

/// Writes shot frame `frame` to `out`. `only` limits the agents (a layer's).
pub fn export_frame(crowd: &ShotCrowd, frame: i32, only: Option<&BTreeSet<u32>>, out: &Path) -> Result<ExportSummary> {
    let lib = crowd.library();
    let mut w = Writer {
        glb: GlbBuilder::new(),
        lib,
        meshes: HashMap::new(),
        materials: HashMap::new(),
        triangles: 0,
        mesh_nodes: 0,
    };
    w.glb.set_generator(format!("throng {}", env!("CARGO_PKG_VERSION")));

    // Agents: one node per agent at its placement, one child per part.
    let block = crowd.agents_at(frame)?;
    let mut agents = 0;
    for a in block.agents.iter().filter(|a| crowd.renders(a) && only.is_none_or(|o| o.contains(&a.id))) {
        let mut insts = Vec::new();
        crowd.agent_instances(a, Lod::Full, vis::ALL, &mut insts)?;
        let world_from_agent = crowd.world_from_agent(a);
        let agent_from_world = world_from_agent.inverse();
        let mut children = Vec::new();
        for inst in &insts {
            let slot = crowd.slot_name(a.id, inst.part).unwrap_or("part");
            children.push(w.instance_node(
                format!("agent_{}/{slot}", a.id),
                inst,
                &(agent_from_world * inst.world_from_object),
            )?);
        }
        let Some(cast) = crowd.cast(a.id) else { continue };
        let mut node = NodeDesc::new(format!("agent_{}", a.id)).children(children).extras(serde_json::json!({
            "throng_agent": a.id,
            "rig": cast.rig,
            "scheme": cast.scheme,
            "cycle": crowd.cycle_name(a),
            "cycle_frame": a.cycle_frame,
            "height_scale": cast.height_scale,
        }));
        node.transform = matrix(&world_from_agent);
        w.glb.add_node(node)?;
        agents += 1;
    }

    // The set.
    let mut children = Vec::new();
    for (i, inst) in crowd.set().iter().enumerate() {
        children.push(w.instance_node(format!("set/{i}"), inst, &inst.world_from_object)?);
    }
    if !children.is_empty() {
        w.glb.add_node(NodeDesc::new("set").children(children))?;
    }

    // Camera and lights.
    let camera = crowd.camera(frame)?;
    let (_, rot, pos) = camera.world_from_camera.to_scale_rotation_translation();
    let mut cam_node = NodeDesc::new("shotcam");
    cam_node.transform = Transform::Trs { translation: pos.to_array(), rotation: rot.to_array(), scale: [1.0; 3] };
    w.glb.add_camera(
        cam_node,
        Perspective { yfov: camera.yfov, aspect_ratio: Some(crowd.shot().aspect()), znear: 0.05, zfar: None },
    )?;
    if let Some(sun) = crowd.shot().sun() {
        let peak = sun.irradiance.max_element().max(1e-6);
        let colour = (sun.irradiance / peak).to_array();
        let mut node = NodeDesc::new("sun");
        node.transform = Transform::Trs {
            translation: [0.0, 50.0, 0.0],
            rotation: glb::rotation_looking_along((-sun.direction).to_array(), [0.0, 1.0, 0.0]),
            scale: [1.0; 3],
        };
        w.glb.add_sun(node, colour, peak * LUX_PER_WATT)?;
    }
    // The shot's points, spots and spheres as KHR_lights_punctual (W/sr x
    // 683 = candela; a sphere as the point of its intensity, pi r^2 L). Rects,
    // discs and the dome have no glTF form: the USD export carries them.
    for light in &crowd.lights().local {
        let (kind, intensity) = match light.kind {
            LightKind::Point => (glb::PunctualKind::Point, light.emission),
            LightKind::Spot { outer, blend } => {
                (glb::PunctualKind::Spot { inner: outer * (1.0 - blend), outer }, light.emission)
            }
            LightKind::Sphere { radius } => (glb::PunctualKind::Point, light.emission * (PI * radius * radius)),
            _ => continue,
        };
        let peak = intensity.max_element();
        if !(peak > 0.0) {
            continue;
        }
        let (_, rot, pos) = light.world_from_light.to_scale_rotation_translation();
        let mut node = NodeDesc::new(light.name.clone());
        node.transform = Transform::Trs { translation: pos.to_array(), rotation: rot.to_array(), scale: [1.0; 3] };
        w.glb.add_light(node, kind, (intensity / peak).to_array(), peak * LUX_PER_WATT)?;
    }
    let summary =
        ExportSummary { agents, mesh_nodes: w.mesh_nodes, meshes: w.meshes.len(), instanced_triangles: w.triangles };
    w.glb.write(out)?;
    Ok(summary)
}
