//! The casting table and its instancing figures: what `throng cast` prints,
//! botinfo's part rows, and the demo's summary.

use std::collections::BTreeSet;
use std::fmt::Write as _;

use serde::Serialize;

use super::{AgentCast, ShotCrowd};

/// One part row of the casting table.
#[derive(Debug, Clone, Serialize)]
pub struct PartRow {
    /// Rig slot.
    pub slot: String,
    /// Mesh name, or null for an empty slot.
    pub mesh: Option<String>,
    /// glTF file of the mesh.
    pub file: Option<String>,
    /// Material name.
    pub material: Option<String>,
}

/// One agent of the casting table.
#[derive(Debug, Serialize)]
pub struct CastRow {
    /// Cache id.
    pub id: u32,
    /// Rig.
    pub rig: String,
    /// Scheme.
    pub scheme: String,
    /// Height scale.
    pub height_scale: f32,
    /// Whether the height jitter applies.
    pub scaled: bool,
    /// Parts per slot.
    pub parts: Vec<PartRow>,
}

/// Instancing figures for `throng cast --stats`.
#[derive(Debug, Serialize)]
pub struct CastStats {
    /// Agents cast.
    pub agents: usize,
    /// Part instances (agents x filled slots).
    pub part_instances: usize,
    /// Unique part meshes.
    pub unique_parts: usize,
    /// Unique materials.
    pub unique_materials: usize,
    /// Bytes of unique part geometry.
    pub unique_geometry_bytes: usize,
    /// Bytes if every agent had its own copy of its parts.
    pub copied_geometry_bytes: usize,
}

/// Every agent's row, by id.
pub fn cast_rows(crowd: &ShotCrowd) -> Vec<CastRow> {
    crowd.casting.values().map(|c| cast_row(crowd, c)).collect()
}

/// One agent's row: its scheme, height, and part and material per slot.
pub fn cast_row(crowd: &ShotCrowd, c: &AgentCast) -> CastRow {
    let lib = crowd.library();
    let parts = c
        .slots
        .iter()
        .enumerate()
        .map(|(i, s)| {
            let dressed = crowd.dressed.get(&c.id).and_then(|d| d.iter().find(|p| p.slot == i));
            PartRow {
                slot: s.slot.clone(),
                mesh: s.part.as_ref().map(|p| p.mesh.clone()),
                file: s.part.as_ref().map(|p| p.file.display().to_string()),
                material: dressed.map(|d| lib.materials[d.material as usize].name.clone()),
            }
        })
        .collect();
    CastRow {
        id: c.id,
        rig: c.rig.clone(),
        scheme: c.scheme.clone(),
        height_scale: c.height_scale,
        scaled: c.scaled,
        parts,
    }
}

/// Instancing figures for the whole cast.
pub fn cast_stats(crowd: &ShotCrowd) -> CastStats {
    let lib = crowd.library();
    let mut meshes = BTreeSet::new();
    let mut materials = BTreeSet::new();
    let mut copied = 0;
    let mut instances = 0;
    for parts in crowd.dressed.values() {
        for p in parts {
            meshes.insert(p.mesh);
            materials.insert(p.material);
            copied += lib.meshes[p.mesh as usize].bytes();
            instances += 1;
        }
    }
    CastStats {
        agents: crowd.casting.len(),
        part_instances: instances,
        unique_parts: meshes.len(),
        unique_materials: materials.len(),
        unique_geometry_bytes: meshes.iter().map(|&m| lib.meshes[m as usize].bytes()).sum(),
        copied_geometry_bytes: copied,
    }
}

/// Bytes as MiB with two decimals.
pub fn mib(b: usize) -> String {
    format!("{:.2} MiB", b as f64 / (1024.0 * 1024.0))
}

/// Human-readable instancing figures.
pub fn format_stats(s: &CastStats) -> String {
    let mut o = String::new();
    let _ = writeln!(o, "agents               {}", s.agents);
    let _ = writeln!(o, "part instances       {}", s.part_instances);
    let _ = writeln!(o, "unique parts         {}", s.unique_parts);
    let _ = writeln!(o, "unique materials     {}", s.unique_materials);
    let _ = writeln!(o, "unique geometry      {}", mib(s.unique_geometry_bytes));
    let _ = writeln!(
        o,
        "if copied per agent  {}  ({:.0}x more)",
        mib(s.copied_geometry_bytes),
        s.copied_geometry_bytes as f64 / s.unique_geometry_bytes.max(1) as f64
    );
    o
}
