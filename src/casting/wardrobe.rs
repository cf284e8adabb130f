//! Wardrobes (`wardrobes/*.toml`, `version = 1`): schemes of candidate body
//! parts per slot, with weights, material variants and exclusions. The
//! format is documented in docs/wardrobes.md.
//!
//! ```toml
//! version = 1
//! name = "robots"
//! uniform_slots = ["head"]          # slots scaled uniformly (heads)
//! [materials.chrome]
//! base_color = [0.8, 0.8, 0.85]
//! metallic = 1.0
//! roughness = 0.25
//! [schemes.LowEnd_good_heads]
//! exclude = ["head_cone"]
//! [[schemes.LowEnd_good_heads.parts]]
//! slot = "head"
//! file = "../demo/parts/heads.glb"
//! mesh = "head_sphere"
//! weight = 2.0
//! materials = ["chrome", "rust"]    # "gltf" = the mesh's own material
//! ```

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use serde::Deserialize;

use crate::error::{check_readable_file, Error, IoContext, Result};

/// The part chosen for one slot.
#[derive(Debug, Clone, PartialEq)]
pub struct CastPart {
    /// glTF file.
    pub(crate) file: Arc<Path>,
    /// Mesh name in the file.
    pub mesh: Arc<str>,
    /// Qualified wardrobe material (`wardrobe/name`) or `gltf` for the mesh's own.
    pub(crate) material: Arc<str>,
    /// Scaled uniformly (heads) rather than per axis.
    pub uniform: bool,
    /// Turns the mesh's own up and forward onto the slot's +Y and +Z
    /// (the part's `up` and `forward`; identity by default).
    pub(crate) facing: glam::Quat,
}

/// Where a prop hangs: a joint of a skinned character or a slot of a slot rig.
#[derive(Debug, Clone, PartialEq)]
pub enum PropAt {
    /// A joint (any node of the skeleton) of a skinned character.
    Joint(Arc<str>),
    /// A slot of a slot rig.
    Slot(Arc<str>),
}

/// A prop an agent carries: one material variant of one wardrobe prop,
/// shared (`Arc`) by every agent that draws it.
#[derive(Debug, Clone, PartialEq)]
pub struct CastProp {
    /// The prop's name: its Cryptomatte part `agent_<id>/<name>`.
    pub name: Arc<str>,
    /// The joint or slot it hangs on.
    pub at: PropAt,
    /// glTF file.
    pub(crate) file: Arc<Path>,
    /// Mesh name in the file.
    pub mesh: Arc<str>,
    /// Qualified wardrobe material or `gltf`.
    pub(crate) material: Arc<str>,
    /// `frame_from_prop`: the prop's `rotate` then its `offset`, metres, in
    /// the joint's or slot's frame with that frame's rest scale taken out.
    pub(crate) offset: glam::Affine3A,
}

/// The prop name that means "no prop" in its group.
pub(crate) const NO_PROP: &str = "none";

/// The wardrobe file version this build reads.
pub(crate) const WARDROBE_VERSION: u32 = 1;

/// The material name meaning "the part mesh's own glTF material".
pub(crate) const GLTF_MATERIAL: &str = "gltf";

/// A material defined in a wardrobe.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub(crate) struct MaterialSpec {
    /// Linear base colour.
    #[serde(default = "grey")]
    pub(crate) base_color: [f32; 3],
    /// Metalness.
    #[serde(default)]
    pub(crate) metallic: f32,
    /// Perceptual roughness.
    #[serde(default = "half")]
    pub(crate) roughness: f32,
    /// Optional base colour texture, relative to the wardrobe file (resolved on load).
    #[serde(default)]
    pub(crate) base_color_texture: Option<PathBuf>,
    /// Emitted radiance, linear RGB, W/(m^2 sr) (glTF's emissiveFactor x
    /// emissiveStrength): eyes, screens and lamps that light the crowd.
    #[serde(default)]
    pub(crate) emission: [f32; 3],
}

fn grey() -> [f32; 3] {
    [0.8; 3]
}
fn half() -> f32 {
    0.5
}
fn one() -> f32 {
    1.0
}

/// A candidate part for one slot.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub(crate) struct PartSpec {
    /// Rig slot it dresses.
    pub(crate) slot: String,
    /// glTF file (resolved to absolute on load). Shared (`Arc`) with every
    /// agent cast in this part, so casting a million agents copies no paths.
    pub(crate) file: Arc<Path>,
    /// Mesh name inside the file.
    pub(crate) mesh: Arc<str>,
    /// Relative weight among the slot's candidates.
    #[serde(default = "one")]
    pub(crate) weight: f32,
    /// Material variants (wardrobe material names, or "gltf").
    #[serde(default = "gltf_only")]
    pub(crate) materials: Vec<Arc<str>>,
    /// Optional weights for `materials` (default uniform).
    #[serde(default)]
    pub(crate) material_weights: Option<Vec<f32>>,
    /// The mesh's up axis (default +y), as a skinned rig's `up`.
    #[serde(default)]
    pub(crate) up: Option<crate::shot::Axis>,
    /// The way the mesh faces (default +z), as a skinned rig's `forward`:
    /// a part modelled facing -z is turned to face the agent's way.
    #[serde(default)]
    pub(crate) forward: Option<crate::shot::Axis>,
    /// The rotation `up` and `forward` make (resolved on load).
    #[serde(skip)]
    pub(crate) facing: glam::Quat,
    /// The cast part for each material, made once on load and shared by
    /// every agent that draws it.
    #[serde(skip)]
    pub(crate) cast: Vec<Arc<CastPart>>,
}

fn gltf_only() -> Vec<Arc<str>> {
    vec![GLTF_MATERIAL.into()]
}

impl PartSpec {
    /// The cast part for material variant `m`: the shared one a loaded
    /// wardrobe made (see [`PartSpec::cast`]), else a new one.
    pub(crate) fn cast_part(&self, m: usize, uniform: bool) -> Arc<CastPart> {
        self.cast.get(m).cloned().unwrap_or_else(|| {
            Arc::new(CastPart {
                file: self.file.clone(),
                mesh: self.mesh.clone(),
                material: self.materials.get(m).cloned().unwrap_or_else(|| GLTF_MATERIAL.into()),
                uniform,
                facing: self.facing,
            })
        })
    }

    /// The weight of each material variant.
    pub(crate) fn material_weight_list(&self) -> Vec<f32> {
        self.material_weights.clone().unwrap_or_else(|| vec![1.0; self.materials.len()])
    }
}

/// A candidate prop (`[[schemes.NAME.props]]`), or "no prop" (`name = "none"`).
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub(crate) struct PropSpec {
    /// Cryptomatte and botinfo name; `none` is the group's "no prop".
    pub(crate) name: Arc<str>,
    /// One prop (or none) is drawn per group; default: the prop's name.
    #[serde(default)]
    pub(crate) group: Option<String>,
    /// Joint it hangs on (skinned rigs).
    #[serde(default)]
    pub(crate) joint: Option<Arc<str>>,
    /// Slot it hangs on (slot rigs).
    #[serde(default)]
    pub(crate) slot: Option<Arc<str>>,
    /// glTF file (resolved to absolute on load).
    #[serde(default)]
    pub(crate) file: Option<Arc<Path>>,
    /// Mesh name inside the file.
    #[serde(default)]
    pub(crate) mesh: Option<Arc<str>>,
    /// Relative weight in its group.
    #[serde(default = "one")]
    pub(crate) weight: f32,
    /// Material variants (wardrobe material names, or "gltf").
    #[serde(default)]
    pub(crate) materials: Option<Vec<Arc<str>>>,
    /// Optional weights for `materials`.
    #[serde(default)]
    pub(crate) material_weights: Option<Vec<f32>>,
    /// Translation in the joint's or slot's frame, metres.
    #[serde(default)]
    pub(crate) offset: Option<[f32; 3]>,
    /// Degrees about the frame's X, then Y, then Z axis.
    #[serde(default)]
    pub(crate) rotate: Option<[f32; 3]>,
    /// The cast prop for each material (made on load; empty for `none`).
    #[serde(skip)]
    pub(crate) cast: Vec<Arc<CastProp>>,
}

impl PropSpec {
    /// Whether this entry is its group's "no prop".
    pub(crate) fn is_none(&self) -> bool {
        *self.name == *NO_PROP
    }

    /// The weight of each material variant.
    pub(crate) fn material_weight_list(&self) -> Vec<f32> {
        let n = self.materials.as_ref().map_or(1, Vec::len);
        self.material_weights.clone().unwrap_or_else(|| vec![1.0; n])
    }
}

/// The props one draw chooses between: entries of a scheme's `props` by index.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct PropGroup {
    /// The group's name, the key of its draw (`prop/<group>`).
    pub(crate) name: String,
    /// Indices into the scheme's `props` (`none` entries included), with their weights.
    pub(crate) entries: Vec<(usize, f32)>,
}

/// A scheme: candidate parts per slot.
#[derive(Debug, Clone, Deserialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct Scheme {
    /// Mesh names never used by this scheme.
    #[serde(default)]
    pub(crate) exclude: Vec<String>,
    /// Candidate parts.
    #[serde(default)]
    pub(crate) parts: Vec<PartSpec>,
    /// Candidate props, by group (docs/wardrobes.md "Props").
    #[serde(default)]
    pub(crate) props: Vec<PropSpec>,
    /// `props` gathered by group, in group name order (set on load).
    #[serde(skip)]
    pub(crate) prop_groups: Vec<PropGroup>,
    /// The scheme's name (set on load), shared by every agent cast in it.
    #[serde(skip)]
    pub(crate) name: Arc<str>,
    /// Which wardrobe the scheme came from (set on load).
    #[serde(skip)]
    pub(crate) wardrobe: String,
    /// Slots scaled uniformly, from the wardrobe (set on load).
    #[serde(skip)]
    pub(crate) uniform_slots: Vec<String>,
    /// The wardrobe file it came from (set on load).
    #[serde(skip)]
    pub(crate) source: PathBuf,
}

impl Scheme {
    /// Candidates for `slot`, without excluded meshes (scheme- or shot-level).
    pub(crate) fn candidates<'a>(
        &'a self,
        slot: &'a str,
        shot_excludes: &'a [String],
    ) -> impl Iterator<Item = &'a PartSpec> {
        self.parts.iter().filter(move |p| {
            p.slot == slot
                && p.weight > 0.0
                && !self.exclude.iter().any(|e| **e == *p.mesh)
                && !shot_excludes.iter().any(|e| **e == *p.mesh)
        })
    }
    /// Whether parts in `slot` scale uniformly.
    pub(crate) fn is_uniform(&self, slot: &str) -> bool {
        self.uniform_slots.iter().any(|s| s == slot)
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct WardrobeFile {
    version: u32,
    name: String,
    #[serde(default)]
    uniform_slots: Vec<String>,
    #[serde(default)]
    materials: BTreeMap<String, MaterialSpec>,
    #[serde(default)]
    schemes: BTreeMap<String, Scheme>,
}

/// Every scheme and material from the shot's wardrobe files.
#[derive(Debug, Clone, Default)]
pub struct Wardrobes {
    /// Schemes by name (names are unique across files).
    pub schemes: BTreeMap<String, Scheme>,
    /// Materials by qualified name `wardrobe/material`.
    pub(crate) materials: BTreeMap<String, MaterialSpec>,
}

impl Wardrobes {
    /// Every part file and texture the wardrobes name, once each, as the
    /// wardrobe names it (`schemes.Rich.parts[0].file`).
    pub(crate) fn input_files(&self) -> Vec<(String, PathBuf)> {
        let mut seen = std::collections::BTreeSet::new();
        let mut out = Vec::new();
        for (name, scheme) in &self.schemes {
            for (i, part) in scheme.parts.iter().enumerate() {
                if seen.insert(part.file.to_path_buf()) {
                    out.push((format!("wardrobe part schemes.{name}.parts[{i}].file"), part.file.to_path_buf()));
                }
            }
        }
        for (name, m) in &self.materials {
            if let Some(t) = m.base_color_texture.as_ref().filter(|t| seen.insert(t.to_path_buf())) {
                out.push((format!("texture of material {name}"), t.clone()));
            }
        }
        out
    }

    /// Loads and validates wardrobe files; scheme names must be unique across them.
    pub fn load(paths: &[PathBuf]) -> Result<Wardrobes> {
        let mut all = Wardrobes::default();
        let mut origin: BTreeMap<String, PathBuf> = BTreeMap::new();
        for path in paths {
            crate::error::check_readable_file(path)?;
            let text = std::fs::read_to_string(path).at(path)?;
            let file: WardrobeFile = toml::from_str(&text).map_err(|e| Error::toml(path, &text, e))?;
            if file.version != WARDROBE_VERSION {
                return Err(Error::invalid(
                    path,
                    format!("unsupported wardrobe version {} (this throng reads {WARDROBE_VERSION})", file.version),
                )
                .field("version"));
            }
            let base = path.parent().unwrap_or(Path::new(""));
            for (name, mut m) in file.materials {
                if name.contains('#') || file.name.contains('#') {
                    // `#` separates a glTF material's file from its name in
                    // the library (and Cryptomatte keeps only what follows it).
                    return Err(Error::invalid(
                        path,
                        format!("material `{}/{name}`: names cannot contain `#`", file.name),
                    )
                    .field(format!("materials.{name}")));
                }
                // glTF's ranges: a base colour factor and metallic/roughness in 0-1.
                if !m.base_color.iter().all(|c| (0.0..=1.0).contains(c)) {
                    return Err(Error::invalid(
                        path,
                        format!("material `{name}`: base_color components must be 0-1, got {:?}", m.base_color),
                    )
                    .field(format!("materials.{name}.base_color")));
                }
                for (key, v) in [("metallic", m.metallic), ("roughness", m.roughness)] {
                    if !(0.0..=1.0).contains(&v) {
                        return Err(Error::invalid(path, format!("material `{name}`: {key} must be 0-1, got {v}"))
                            .field(format!("materials.{name}.{key}")));
                    }
                }
                if !m.emission.iter().all(|c| *c >= 0.0 && c.is_finite()) {
                    return Err(Error::invalid(
                        path,
                        format!("material `{name}`: emission components must be finite and >= 0, got {:?}", m.emission),
                    )
                    .field(format!("materials.{name}.emission")));
                }
                if let Some(t) = &m.base_color_texture {
                    let full = base.join(t);
                    if !full.exists() {
                        return Err(Error::invalid(path, format!("texture not found: {}", full.display()))
                            .field(format!("materials.{name}.base_color_texture")));
                    }
                    check_readable_file(&full).map_err(|e| e.field(format!("materials.{name}.base_color_texture")))?;
                    m.base_color_texture = Some(full);
                }
                all.materials.insert(format!("{}/{name}", file.name), m);
            }
            // A uniform slot no part of the wardrobe fills scales nothing: a typo.
            for (i, slot) in file.uniform_slots.iter().enumerate() {
                if !file.schemes.values().any(|s| s.parts.iter().any(|p| p.slot == *slot)) {
                    return Err(Error::invalid(path, format!("`{slot}` is the slot of no part of this wardrobe"))
                        .field(format!("uniform_slots[{i}]")));
                }
            }
            for (name, mut scheme) in file.schemes {
                if let Some(prev) = origin.get(&name) {
                    return Err(Error::invalid(path, format!("scheme `{name}` is also defined in {}", prev.display()))
                        .field(format!("schemes.{name}")));
                }
                for (i, part) in scheme.parts.iter_mut().enumerate() {
                    let key = format!("schemes.{name}.parts[{i}]");
                    part.file = wardrobe_file(path, base, &part.file, &key)?.into();
                    if part.up.is_some() || part.forward.is_some() {
                        let (up, forward) = (
                            part.up.unwrap_or(crate::shot::Axis::PosY),
                            part.forward.unwrap_or(crate::shot::Axis::PosZ),
                        );
                        part.facing = crate::scene::gltf::orientation(path, up, forward)
                            .map_err(|e| e.field(format!("{key}.forward")))?;
                    }
                    if !(part.weight >= 0.0 && part.weight.is_finite()) {
                        return Err(Error::invalid(path, format!("weight must be >= 0, got {}", part.weight))
                            .field(format!("{key}.weight")));
                    }
                    let weights = part.material_weights.as_deref();
                    check_materials(path, &key, "", &file.name, &all.materials, &mut part.materials, weights)?;
                }
                scheme.prop_groups = load_props(path, base, &file.name, &name, &mut scheme.props, &all.materials)?;
                for part in &mut scheme.parts {
                    let uniform = file.uniform_slots.contains(&part.slot);
                    part.cast = (0..part.materials.len()).map(|m| part.cast_part(m, uniform)).collect();
                }
                scheme.name = name.as_str().into();
                scheme.wardrobe = file.name.clone();
                scheme.source = path.clone();
                scheme.uniform_slots = file.uniform_slots.clone();
                origin.insert(name.clone(), path.clone());
                all.schemes.insert(name, scheme);
            }
        }
        Ok(all)
    }

    /// Refuses a part for a slot that rig `rig` (with `slots`) lacks, in any
    /// scheme the rig draws with a weight > 0: such a part could never be worn.
    /// `character`: the rig is skinned or rigid, whose parts ride their
    /// nodes as modelled, so a part's `up` and `forward` (which turn a mesh
    /// onto a slot rig's slot) would be ignored: refused instead.
    pub fn check_slots(
        &self,
        rig: &str,
        schemes: &BTreeMap<String, f32>,
        slots: &[&str],
        character: bool,
    ) -> Result<()> {
        for (name, _) in schemes.iter().filter(|(_, w)| **w > 0.0) {
            let Some(scheme) = self.schemes.get(name) else { continue };
            for (i, part) in scheme.parts.iter().enumerate() {
                if !slots.contains(&part.slot.as_str()) {
                    return Err(Error::invalid(
                        &scheme.source,
                        format!(
                            "part `{}` is for slot `{}`, which rig `{rig}` (used with scheme `{name}`) lacks; its slots: {}",
                            part.mesh,
                            part.slot,
                            slots.join(", ")
                        ),
                    )
                    .field(format!("schemes.{name}.parts[{i}].slot")));
                }
                if character && (part.up.is_some() || part.forward.is_some()) {
                    let field = if part.forward.is_some() { "forward" } else { "up" };
                    return Err(Error::invalid(
                        &scheme.source,
                        format!(
                            "part `{}` turns with `up`/`forward`, but rig `{rig}` (used with scheme `{name}`) is a \
                             skinned or rigid character, whose parts ride their joints or nodes as modelled; turn the \
                             rig with its own `forward` and `up` in the shot",
                            part.mesh
                        ),
                    )
                    .field(format!("schemes.{name}.parts[{i}].{field}")));
                }
            }
        }
        Ok(())
    }

    /// Refuses a prop that rig `rig` cannot carry, in any scheme it draws
    /// with a weight > 0: on a joint the rig lacks (`joints`: a skinned
    /// character's joints, `None` for a slot rig), a slot it lacks, the
    /// wrong kind of anchor for the rig, or named as one of its slots (the
    /// Cryptomatte names `agent_<id>/<name>` would collide).
    pub(crate) fn check_props(
        &self,
        rig: &str,
        schemes: &BTreeMap<String, f32>,
        slots: &[&str],
        joints: Option<&[&str]>,
    ) -> Result<()> {
        for (name, _) in schemes.iter().filter(|(_, w)| **w > 0.0) {
            let Some(scheme) = self.schemes.get(name) else { continue };
            for (i, prop) in scheme.props.iter().enumerate().filter(|(_, p)| !p.is_none()) {
                let key = format!("schemes.{name}.props[{i}]");
                let bad = |field: &str, msg: String| {
                    Err(Error::invalid(&scheme.source, format!("prop `{}`: {msg}", prop.name))
                        .field(format!("{key}.{field}")))
                };
                if slots.contains(&&*prop.name) {
                    return bad(
                        "name",
                        format!("rig `{rig}` has a slot of that name; a prop's name must differ from its rig's slots"),
                    );
                }
                match (joints, &prop.joint, &prop.slot) {
                    (Some(joints), Some(joint), _) if !joints.contains(&&**joint) => {
                        return bad(
                            "joint",
                            format!("rig `{rig}` has no joint `{joint}`; its joints: {}", joints.join(", ")),
                        )
                    }
                    (Some(_), None, _) => {
                        return bad("slot", format!("rig `{rig}` is a skinned character: hang the prop on a `joint`"))
                    }
                    (None, _, Some(slot)) if !slots.contains(&&**slot) => {
                        return bad(
                            "slot",
                            format!("rig `{rig}` has no slot `{slot}`; its slots: {}", slots.join(", ")),
                        )
                    }
                    (None, Some(_), _) => {
                        return bad("joint", format!("rig `{rig}` is a slot rig: hang the prop on a `slot`"))
                    }
                    _ => {}
                }
            }
        }
        Ok(())
    }

    /// Every slot any scheme dresses.
    pub fn slots(&self) -> BTreeSet<&str> {
        self.schemes.values().flat_map(|s| s.parts.iter().map(|p| p.slot.as_str())).collect()
    }
}

/// Checks and resolves a scheme's props (`props`, of scheme `scheme` in
/// wardrobe `wardrobe` of file `path`, relative to `base`) and gathers them
/// by group, in group name order. Each refusal names the prop and its field.
/// A wardrobe entry's glTF `file` (relative to the wardrobe), checked to
/// exist and be a readable file; errors name `{key}.file`.
fn wardrobe_file(path: &Path, base: &Path, file: &Path, key: &str) -> Result<PathBuf> {
    let full = base.join(file);
    if !full.exists() {
        return Err(Error::invalid(path, format!("file not found: {}", full.display())).field(format!("{key}.file")));
    }
    check_readable_file(&full).map_err(|e| e.field(format!("{key}.file")))?;
    Ok(full)
}

/// Checks a part's or prop's `materials` and `material_weights` (at least
/// one material, one finite weight >= 0 each, not all 0) and qualifies each
/// wardrobe material as `{wardrobe}/{name}`; `what` starts each message.
fn check_materials(
    path: &Path,
    key: &str,
    what: &str,
    wardrobe: &str,
    materials: &BTreeMap<String, MaterialSpec>,
    variants: &mut [Arc<str>],
    weights: Option<&[f32]>,
) -> Result<()> {
    let bad = |field: &str, msg: &str| Error::invalid(path, format!("{what}{msg}")).field(format!("{key}.{field}"));
    if variants.is_empty() {
        return Err(bad("materials", "needs at least one material"));
    }
    if let Some(w) = weights {
        if w.len() != variants.len() || w.iter().any(|x| !(*x >= 0.0 && x.is_finite())) {
            return Err(bad("material_weights", "needs one weight >= 0 per material"));
        }
        if w.iter().all(|x| *x == 0.0) {
            return Err(bad(
                "material_weights",
                "every material weight is 0, so no material could be drawn (give one a weight > 0)",
            ));
        }
    }
    for m in variants.iter_mut() {
        if **m != *GLTF_MATERIAL {
            let q = format!("{wardrobe}/{m}");
            if !materials.contains_key(&q) {
                return Err(bad("materials", &format!("unknown material `{m}`")));
            }
            *m = q.into();
        }
    }
    Ok(())
}

fn load_props(
    path: &Path,
    base: &Path,
    wardrobe: &str,
    scheme: &str,
    props: &mut [PropSpec],
    materials: &BTreeMap<String, MaterialSpec>,
) -> Result<Vec<PropGroup>> {
    let mut groups: BTreeMap<String, Vec<(usize, f32)>> = BTreeMap::new();
    let mut names = BTreeSet::new();
    for (i, prop) in props.iter_mut().enumerate() {
        let key = format!("schemes.{scheme}.props[{i}]");
        let bad = |field: &str, msg: String| {
            Error::invalid(path, format!("prop `{}`: {msg}", prop.name)).field(format!("{key}.{field}"))
        };
        if prop.name.is_empty() || prop.name.contains('/') {
            return Err(bad("name", "give a name without `/` (it names the prop in Cryptomatte)".into()));
        }
        if !(prop.weight >= 0.0 && prop.weight.is_finite()) {
            return Err(bad("weight", format!("weight must be a finite number >= 0, got {}", prop.weight)));
        }
        let group = match (&prop.group, prop.is_none()) {
            (Some(g), _) => g.clone(),
            (None, false) => prop.name.to_string(),
            (None, true) => {
                return Err(bad("group", "a `none` entry is the no-prop of a group: give its `group`".into()))
            }
        };
        groups.entry(group).or_default().push((i, prop.weight));
        if prop.is_none() {
            let extra = [
                ("joint", prop.joint.is_some()),
                ("slot", prop.slot.is_some()),
                ("file", prop.file.is_some()),
                ("mesh", prop.mesh.is_some()),
                ("materials", prop.materials.is_some()),
                ("material_weights", prop.material_weights.is_some()),
                ("offset", prop.offset.is_some()),
                ("rotate", prop.rotate.is_some()),
            ];
            if let Some((field, _)) = extra.iter().find(|(_, set)| *set) {
                return Err(bad(field, "a `none` entry takes only `group` and `weight`".into()));
            }
            continue;
        }
        if !names.insert(prop.name.clone()) {
            return Err(bad("name", format!("another prop of scheme `{scheme}` has this name")));
        }
        let at = match (&prop.joint, &prop.slot) {
            (Some(j), None) => PropAt::Joint(j.clone()),
            (None, Some(s)) => PropAt::Slot(s.clone()),
            (Some(_), Some(_)) => return Err(bad("slot", "give `joint` or `slot`, not both".into())),
            (None, None) => {
                return Err(bad("joint", "give the `joint` (skinned rigs) or `slot` (slot rigs) it hangs on".into()))
            }
        };
        let Some(file) = &prop.file else { return Err(bad("file", "give the glTF `file` of its mesh".into())) };
        let Some(mesh) = prop.mesh.clone() else { return Err(bad("mesh", "give its `mesh` (a mesh name)".into())) };
        let file: Arc<Path> = wardrobe_file(path, base, file, &key)?.into();
        prop.file = Some(file.clone());
        let (offset, rotate) = (prop.offset.unwrap_or_default(), prop.rotate.unwrap_or_default());
        for (field, v) in [("offset", offset), ("rotate", rotate)] {
            if !v.iter().all(|c| c.is_finite()) {
                return Err(bad(field, format!("{field} must be finite numbers, got {v:?}")));
            }
        }
        let [x, y, z] = rotate.map(f32::to_radians);
        let turn = glam::Quat::from_rotation_z(z) * glam::Quat::from_rotation_y(y) * glam::Quat::from_rotation_x(x);
        let offset = glam::Affine3A::from_rotation_translation(turn, glam::Vec3::from(offset));
        let variants = prop.materials.get_or_insert_with(gltf_only);
        let what = format!("prop `{}`: ", prop.name);
        check_materials(path, &key, &what, wardrobe, materials, variants, prop.material_weights.as_deref())?;
        let cast = variants
            .iter()
            .map(|material| {
                Arc::new(CastProp {
                    name: prop.name.clone(),
                    at: at.clone(),
                    file: file.clone(),
                    mesh: mesh.clone(),
                    material: material.clone(),
                    offset,
                })
            })
            .collect();
        prop.cast = cast;
    }
    let mut out = Vec::new();
    for (name, entries) in groups {
        if entries.iter().all(|&(_, w)| w == 0.0) {
            let (first, _) = entries[0];
            return Err(Error::invalid(
                path,
                format!(
                    "every entry of prop group `{name}` has weight 0, so none could be drawn (give one a weight > 0)"
                ),
            )
            .field(format!("schemes.{scheme}.props[{first}].weight")));
        }
        out.push(PropGroup { name, entries });
    }
    Ok(out)
}
