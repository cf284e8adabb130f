//! Skinned characters: ordinary animated glTF characters as crowd agents.
//!
//! A [`SkinnedRig`] is a glTF file with one or more skins and clips. Posing
//! follows the glTF 2.0 skinning rules:
//! - a joint's transform is its global transform, every parent included (a
//!   Z-up parent node above the skeleton is respected);
//! - a skinned mesh ignores its own node's transform;
//! - `posed = sum_i w_i * (global(joint_i) * inverseBind(joint_i)) * bind`,
//!   with JOINTS_0/WEIGHTS_0 and JOINTS_1/WEIGHTS_1 (up to 8 influences);
//! - normals use the inverse transpose of the blended matrix.
//!
//! A rigid character (`kind = "rigid"`, or a file with neither a skin nor
//! slots: a multi-part character, a vehicle) is the special case with no
//! skin: every mesh node of the file is a piece bound wholly to its node (one
//! influence of weight 1, an identity bind), as a mesh under a skinned
//! character's joint is, so posing, proxies, motion blur, pose instancing and
//! export treat the two alike. Its clips are node animations (TRS channels,
//! STEP, LINEAR or CUBICSPLINE, sampled by [`crate::casting::rig::Channel`]);
//! a cycle with no stride given and no `root` takes the distance its wheels
//! roll ([`crate::casting::wheels`]).
//!
//! Rig space is throng's agent space: Y up, facing +Z, metres, feet on y = 0.
//! `rig_from_file` rotates the file's up and forward axes onto +Y and +Z,
//! scales by the shot's `scale` and lifts the rest pose's lowest vertex to
//! the ground. When the shot names a `root` joint, its horizontal travel is
//! removed from every pose (the cache places the agent) and its Z travel over
//! a clip is that cycle's stride, as the `root` node is for slot rigs.
//!
//! Pose instancing: a cycle of `length` frames is cut into `steps` equal
//! steps (`steps + 1` poses: a clip that does not loop seamlessly ends on its
//! own pose); an agent is posed at the step nearest its cycle frame, so every
//! agent on the same (mesh, cycle, step) shares one posed mesh. The error
//! this costs, measured by [`SkinnedRig::pose_error`], is the largest vertex
//! distance between the exact pose and the snapped step (still frames) or
//! the blend of the two steps around it (motion blur). Unless the shot gives
//! `pose_step`, each clip's steps are chosen at load, from the file's own
//! meshes: one a frame ([`DEFAULT_POSE_STEP`]) when that holds the error to
//! `pose_error_max` on the rig's tallest agent, else about the fewest that
//! do, found by measuring. Deterministic, and the same for every agent,
//! wardrobe and thread count.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use glam::{Affine3A, Mat3, Mat4, Quat, Vec3};
use gltf::accessor::{DataType, Dimensions};
use rayon::prelude::*;

use crate::casting::body::{self, Body};
use crate::casting::rig::{Animated, Trs};
use crate::casting::wheels;
use crate::error::{Error, Result};
use crate::scene::gltf::{check_accessor, lift_decals, out_of_range, read_primitive, GltfFile};
use crate::scene::Mesh;
use crate::shot::{Axis, SkinOptions};

/// Most influences per vertex (JOINTS_0/WEIGHTS_0 and JOINTS_1/WEIGHTS_1).
pub(crate) const MAX_INFLUENCES: usize = 8;
/// The coarsest pose step, in cycle frames, chosen when the shot gives no
/// `pose_step` (finer where a clip moves faster than `pose_error_max` allows).
pub(crate) const DEFAULT_POSE_STEP: f32 = 1.0;
/// Where within each step the exact pose is compared with the snapped and
/// blended ones (fractions of a step).
const ERROR_SAMPLES: [f32; 3] = [0.25, 0.5, 0.75];
/// Most pose steps one cycle may be cut into (bounds posed geometry).
pub(crate) const MAX_STEPS_PER_CYCLE: u32 = 1024;
/// Weight sums further than this from 1 are renormalised with a warning.
const WEIGHT_SUM_TOLERANCE: f32 = 1e-3;

/// One skinned primitive: bind-pose geometry and per-vertex influences.
#[derive(Clone, Debug)]
pub struct SkinPiece {
    /// Bind geometry in mesh space, named `<file>#<mesh>[/<primitive>]`.
    pub(crate) mesh: Mesh,
    /// Per vertex: (joint, weight), joints indexing [`SkinPiece::joint_nodes`];
    /// unused influences have weight 0. Weights sum to 1.
    pub influences: Vec<[(u16, f32); MAX_INFLUENCES]>,
    /// Skin joint -> node index in the rig's hierarchy.
    pub(crate) joint_nodes: Vec<usize>,
    /// Skin joint -> inverse bind matrix.
    pub(crate) inverse_bind: Vec<Affine3A>,
    /// The file the mesh came from (its own materials are looked up there).
    pub(crate) file: PathBuf,
    /// The primitive's glTF material index in `file`.
    pub(crate) material: Option<usize>,
    /// Per skin joint: bounds, in joint space, of the vertices weighted
    /// mostly to that joint (`None` for joints that dominate no vertex).
    pub(crate) joint_boxes: Vec<Option<(Vec3, Vec3)>>,
    /// Whether a body's proportions stretch it (false for props, which a
    /// hand carries at their own size).
    pub(crate) proportioned: bool,
}

/// A skinned mesh a wardrobe can choose: every primitive of one glTF mesh.
#[derive(Clone, Debug)]
pub(crate) struct SkinPart {
    /// Indices into [`SkinnedRig::pieces`].
    pub(crate) pieces: Vec<usize>,
}

/// Where a character cycle's stride comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum StrideFrom {
    /// The shot's (or sim scene's, or import's) `strides` entry.
    Given,
    /// The `root` joint's (node's) travel over the clip, 0 for one that stands.
    Root,
    /// The distance a rigid rig's wheels roll over the clip.
    Wheels,
    /// Nothing measures it (no `root`, no wheels): 0, which walks on the spot.
    Unmeasured,
}

/// One cycle of a skinned rig: a cache cycle name mapped to a clip.
#[derive(Clone, Debug)]
pub struct SkinCycle {
    /// The cache's cycle name.
    pub name: String,
    /// Index into the rig file's clips.
    pub(crate) clip: usize,
    /// The clip's name (`#index` when unnamed).
    pub(crate) clip_name: String,
    /// Metres per cycle: given in the shot, else the root joint's travel,
    /// else (a rigid rig) the distance its wheels roll, else 0.
    pub stride: f32,
    /// Where `stride` came from.
    pub(crate) stride_from: StrideFrom,
    /// Steps the cycle is cut into for pose instancing.
    pub steps: u32,
    /// Whether `steps` was chosen for `pose_error_max` (not from `pose_step`).
    pub chosen: bool,
    /// Pose error in metres at `steps`, on the rig's tallest agent, over the
    /// file's own meshes ([`SkinnedRig::pose_error`]).
    pub error: f32,
}

/// A skinned character loaded from glTF.
#[derive(Clone, Debug)]
pub struct SkinnedRig {
    path: PathBuf,
    /// `path` canonicalised: parts are keyed by it, so two spellings of one file are one file.
    canonical: PathBuf,
    /// No skin: every mesh rides its own node (`kind = "rigid"`).
    rigid: bool,
    animated: Animated,
    rig_from_file: Affine3A,
    root: Option<usize>,
    cycles: Vec<SkinCycle>,
    pieces: Vec<SkinPiece>,
    parts: BTreeMap<(PathBuf, String), usize>,
    part_list: Vec<SkinPart>,
    slots: Vec<String>,
    delivered: Vec<(String, String, usize)>,
    height: f32,
    fps: f32,
    pose_step: Option<f32>,
    pose_error_max: f32,
    max_height_scale: f32,
    /// Bodies 1 and up (`casting::body`); body 0, the rig as modelled, is not stored.
    bodies: Vec<Body>,
    warnings: Vec<String>,
}

/// Whether a glTF file holds a skin (a skinned character, not a slot rig).
pub(crate) fn is_skinned(file: &GltfFile) -> bool {
    file.doc.skins().len() > 0
}

/// Whether a shot's rig is a character posed from its node animation
/// (skinned or rigid, a [`SkinnedRig`]) rather than a slot rig: its `kind`,
/// else detected from the file ([`is_character_file`]).
pub(crate) fn is_character_rig(rig: &crate::shot::RigRef) -> Result<bool> {
    match rig.kind {
        Some(k) => Ok(k != crate::shot::RigKind::Slots),
        None => is_character_file(&rig.file),
    }
}

/// Whether a rig file with no `kind` is a character (skinned or rigid): no
/// node has slot extras. A skin then makes it skinned, else it is rigid
/// (meshes on animated nodes: the Kenney alien, a car).
pub(crate) fn is_character_file(path: &Path) -> Result<bool> {
    let file = GltfFile::open(path)?;
    Ok(!crate::casting::rig::has_slots(&file))
}

/// The error for a skinned file used where rigid geometry is expected.
pub(crate) fn skinned_refusal(path: &Path, what: &str) -> Error {
    Error::invalid(
        path,
        format!(
            "{what} is a skinned character (the file has a skin): slot rigs and wardrobe parts for them are rigid. \
             Declare it as a skinned rig in the shot, `[rigs.NAME] file = \"...\"` with `kind = \"skinned\"` \
             (docs/wardrobes.md, \"Bringing an animated character\")"
        ),
    )
}

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

/// The rotation taking the file's `up` to +Y and `forward` to +Z.
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

impl SkinnedRig {
    /// Loads a skinned character with the shot's options. Cycle names come
    /// from `options.cycles` (cache name -> clip name or `#index`); every
    /// clip is also available under its own name.
    pub fn load(path: &Path, options: &SkinOptions, fps: f32) -> Result<SkinnedRig> {
        let file = GltfFile::open(path)?;
        let rigid = options.rigid.unwrap_or(!is_skinned(&file));
        if !rigid && !is_skinned(&file) {
            return Err(file
                .err(
                    "declared `kind = \"skinned\"` but the file has no skin; meshes on animated nodes are \
                     `kind = \"rigid\"`, and a slot rig needs no kind",
                )
                .field("kind"));
        }
        if rigid && is_skinned(&file) {
            return Err(file
                .err(format!(
                    "declared `kind = \"rigid\"` but the file has a skin ({} skins): a skinned character is \
                     `kind = \"skinned\"`",
                    file.doc.skins().len()
                ))
                .field("kind"));
        }
        let animated = Animated::from_file(&file)?;
        if rigid && animated.clips.is_empty() {
            return Err(file.err(match options.rigid {
                Some(_) => {
                    "declared `kind = \"rigid\"`, but the file has no animation: a rigid rig plays its node \
                            animation as cycles (a still mesh is a wardrobe part or a set object)"
                }
                None => {
                    "the file is no rig: it has no slots (a slot rig's nodes with \"slot\" extras, under a \
                         `root` node), no skin (a skinned character) and no animation (a rigid one)"
                }
            }));
        }
        let root = match &options.root {
            Some(name) => Some(animated.hierarchy.find(name).ok_or_else(|| {
                // A rigid rig's every node may carry root motion; a skinned one's joints.
                let joints: Vec<&str> = match rigid {
                    true => animated.hierarchy.nodes.iter().map(|n| n.name.as_str()).collect(),
                    false => file
                        .doc
                        .skins()
                        .flat_map(|s| s.joints().map(|j| j.index()))
                        .filter_map(|i| animated.hierarchy.nodes.get(i).map(|n| n.name.as_str()))
                        .collect(),
                };
                let what = if rigid { "node" } else { "joint" };
                file.err(format!("no {what} named `{name}` for root motion; {what}s: {}", joints.join(", ")))
                    .field("root")
            })?),
            None => None,
        };
        let orient = orientation(path, options.up, options.forward)?;
        let canonical = std::fs::canonicalize(path).map_err(|e| Error::io(path, e))?;
        let mut rig = SkinnedRig {
            path: path.to_path_buf(),
            canonical,
            rigid,
            animated,
            rig_from_file: Affine3A::from_scale_rotation_translation(Vec3::splat(options.scale), orient, Vec3::ZERO),
            root,
            cycles: Vec::new(),
            pieces: Vec::new(),
            parts: BTreeMap::new(),
            part_list: Vec::new(),
            slots: Vec::new(),
            delivered: Vec::new(),
            height: 0.0,
            fps,
            pose_step: options.pose_step,
            pose_error_max: options.pose_error_max,
            max_height_scale: options.max_height_scale,
            bodies: Vec::new(),
            warnings: Vec::new(),
        };

        // The character as delivered: every skinned mesh node is a slot
        // wearing its own mesh, unless the shot names the slots.
        let mut delivered = Vec::new();
        for node in file.doc.nodes() {
            let (Some(mesh), Some(_)) = (node.mesh(), node.skin()) else { continue };
            let slot = node
                .name()
                .map(str::to_string)
                .or_else(|| mesh.name().map(str::to_string))
                .unwrap_or_else(|| format!("#{}", mesh.index()));
            let mesh_ref = mesh.name().map(str::to_string).unwrap_or_else(|| format!("#{}", mesh.index()));
            let canonical = rig.canonical.clone();
            let part = rig.load_part(&file, &canonical, &mesh_ref)?;
            delivered.push((slot, mesh_ref, part));
        }
        // Meshes on nodes under a joint, not skinned (robot limbs, a held
        // prop): each moves rigidly with its node, as a piece bound wholly
        // to that node, so posing, proxies, blur and instancing treat it
        // like a skinned one.
        let joints: std::collections::HashSet<usize> =
            file.doc.skins().flat_map(|s| s.joints().map(|j| j.index()).collect::<Vec<_>>()).collect();
        for node in file.doc.nodes() {
            let (Some(mesh), None) = (node.mesh(), node.skin()) else { continue };
            // Named by its node (a mesh may hang on several), by index where
            // that name is a skinned mesh's too.
            let name = node
                .name()
                .map(str::to_string)
                .filter(|n| !rig.parts.contains_key(&(rig.canonical.clone(), n.clone())))
                .unwrap_or_else(|| format!("#node{}", node.index()));
            // A rigid rig's every mesh node is a part (its wheels, its body).
            let mut at = Some(node.index());
            while let Some(n) = at.filter(|n| !rigid && !joints.contains(n)) {
                at = rig.animated.hierarchy.nodes.get(n).and_then(|h| h.parent);
            }
            if at.is_none() {
                rig.warnings.push(format!(
                    "{}: mesh node `{name}` is neither skinned nor under a joint of the skeleton: left out",
                    file.path.display()
                ));
                continue;
            }
            let canonical = rig.canonical.clone();
            let part = rig.load_rigid_part(&file, &canonical, node.index(), &mesh, &name)?;
            delivered.push((name.clone(), name, part));
        }
        if delivered.is_empty() {
            return Err(file.err(match rigid {
                true => "a rigid rig poses its nodes' meshes, but no node of the file has a mesh",
                false => "the file has a skin but no node that uses it with a mesh",
            }));
        }
        rig.slots = match &options.slots {
            Some(s) => s.clone(),
            None => delivered.iter().map(|(s, _, _)| s.clone()).collect(),
        };
        if rigid {
            for slot in &rig.slots {
                rig.slot_node(slot)?;
            }
        }
        rig.delivered = delivered;

        // Ground and height from the rest pose of the delivered meshes.
        let (lo, hi) = rig.rest_span(0);
        if !(lo.is_finite() && hi > lo) {
            return Err(file.err(format!("the {} meshes have no height in the rest pose", rig.kind())));
        }
        rig.rig_from_file = Affine3A::from_translation(Vec3::new(0.0, -lo, 0.0)) * rig.rig_from_file;
        rig.height = hi - lo;

        // Cycles: the shot's mapping first, then every clip under its own name.
        let clip_index = |name: &str| -> Option<usize> {
            rig.animated.clips.iter().position(|c| c.name == name).or_else(|| {
                name.strip_prefix('#').and_then(|i| i.parse::<usize>().ok()).filter(|&i| i < rig.animated.clips.len())
            })
        };
        let mut cycles: Vec<(String, usize)> = Vec::new();
        for (cycle, clip) in &options.cycles {
            let i = clip_index(clip).ok_or_else(|| {
                let names: Vec<String> =
                    rig.animated.clips.iter().enumerate().map(|(i, c)| format!("{} (#{i})", c.name)).collect();
                file.err(format!(
                    "cycle `{cycle}` maps to clip `{clip}`, which the file lacks; clips: {}",
                    if names.is_empty() { "(none)".to_string() } else { names.join(", ") }
                ))
                .field(format!("cycles.{cycle}"))
            })?;
            cycles.push((cycle.clone(), i));
        }
        for (i, c) in rig.animated.clips.iter().enumerate() {
            if !cycles.iter().any(|(n, _)| *n == c.name) {
                cycles.push((c.name.clone(), i));
            }
        }
        // Pose steps per clip (cycles sharing a clip share its steps),
        // measured on the file's own meshes.
        let own: Vec<usize> =
            rig.delivered.iter().flat_map(|(_, _, part)| rig.part_list[*part].pieces.iter().copied()).collect();
        let mut per_clip: BTreeMap<usize, (u32, bool, f32)> = BTreeMap::new();
        let mut rolls: BTreeMap<usize, f32> = BTreeMap::new();
        for (name, clip) in cycles {
            let clip_name = rig.animated.clips[clip].name.clone();
            let (stride, stride_from) = match options.strides.get(&name) {
                Some(&s) => (s, StrideFrom::Given),
                None if rig.root.is_none() && rig.rigid => {
                    let s = match rolls.get(&clip) {
                        Some(&s) => s,
                        None => {
                            let s = rig.wheel_stride(&own, clip);
                            *rolls.entry(clip).or_insert(s)
                        }
                    };
                    (s, if s > 0.0 { StrideFrom::Wheels } else { StrideFrom::Unmeasured })
                }
                None if rig.root.is_none() => (0.0, StrideFrom::Unmeasured),
                None => (rig.root_travel(clip), StrideFrom::Root),
            };
            let (steps, chosen, error) = match per_clip.get(&clip) {
                Some(&known) => known,
                None => {
                    let known = rig.clip_steps(&file, &own, clip, &name)?;
                    per_clip.insert(clip, known);
                    known
                }
            };
            rig.cycles.push(SkinCycle { name, clip, clip_name, stride, stride_from, steps, chosen, error });
        }
        Ok(rig)
    }

    /// Loads the shot's rig `name` (`[rigs.NAME]`), its errors' fields under `rigs.NAME`.
    pub(crate) fn load_shot_rig(name: &str, rig: &crate::shot::RigRef, fps: f32) -> Result<SkinnedRig> {
        SkinnedRig::load(&rig.file, &rig.skin, fps)
            .map_err(|e| e.field_prefix(&format!("rigs.{name}")).or_field(format!("rigs.{name}.file")))
    }

    /// Pose steps of clip `clip` (first played as cycle `name`): from the
    /// shot's `pose_step`, with a warning when that misses `pose_error_max`,
    /// else steps no coarser than [`DEFAULT_POSE_STEP`] whose pose error on
    /// `pieces` is within it (the first count tried that is; a warning when
    /// even [`MAX_STEPS_PER_CYCLE`] is not). Returns (steps, chosen, error at
    /// the tallest agent).
    fn clip_steps(&mut self, file: &GltfFile, pieces: &[usize], clip: usize, name: &str) -> Result<(u32, bool, f32)> {
        let length = self.animated.clips[clip].duration() * self.fps;
        if !(length > 0.0 && length.is_finite()) {
            return Ok((1, self.pose_step.is_none(), 0.0));
        }
        let clip_name = self.animated.clips[clip].name.clone();
        let bound = self.pose_error_max;
        let error = |rig: &Self, steps: u32| rig.clip_error(pieces, clip, steps) * rig.max_height_scale;
        let mm = |m: f32| format!("{:.1} mm", m * 1000.0);
        if let Some(step) = self.pose_step {
            let s = (length / step).round();
            if !(s.is_finite() && s <= MAX_STEPS_PER_CYCLE as f32) {
                return Err(file
                    .err(format!(
                        "pose_step {step} cuts cycle `{name}` ({length:.1} frames) into more than {MAX_STEPS_PER_CYCLE} poses"
                    ))
                    .field("pose_step"));
            }
            let steps = (s as u32).max(1);
            let e = error(self, steps);
            if e > bound {
                self.warnings.push(format!(
                    "{}: clip `{clip_name}` (cycle `{name}`): pose_step {step} gives a pose error of {} on the tallest agent, \
                     above pose_error_max {}; leave pose_step out to have the step chosen, or make it about {:.2} frames",
                    self.path.display(),
                    mm(e),
                    mm(bound),
                    step * bound / e
                ));
            }
            return Ok((steps, false, e));
        }
        // The error shrinks about as the step does: a try asks for the steps
        // that would just meet the bound (2% more), and at least one more;
        // a try after a miss (the error shrinks slower, or the clip jumps)
        // for at least a quarter more, so the tries stay few.
        let first = ((length / DEFAULT_POSE_STEP).round() as u32).clamp(1, MAX_STEPS_PER_CYCLE);
        let (mut steps, first_error) = (first, error(self, first));
        let mut e = first_error;
        let mut growth = 1.0;
        while e > bound && steps < MAX_STEPS_PER_CYCLE {
            let want = (steps as f64 * ((e / bound) as f64 * 1.02).max(growth)).ceil();
            steps = (want.min(MAX_STEPS_PER_CYCLE as f64) as u32).max(steps + 1).min(MAX_STEPS_PER_CYCLE);
            e = error(self, steps);
            growth = 1.25;
        }
        if e > bound {
            // Not even halved at the finest: the clip jumps (a STEP sampler,
            // a cut), which finer steps cannot follow; they would only cost
            // posed geometry, so one a frame it is.
            let jumps = e > first_error * 0.5;
            self.warnings.push(format!(
                "{}: clip `{clip_name}` (cycle `{name}`): pose error {} on the tallest agent even at {MAX_STEPS_PER_CYCLE} steps, \
                 above pose_error_max {}; {}",
                self.path.display(),
                mm(e),
                mm(bound),
                if jumps {
                    format!("the clip jumps, so it keeps one pose a frame ({first} steps, {})", mm(first_error))
                } else {
                    "the character moves very fast for its size: raise pose_error_max".to_string()
                }
            ));
            if jumps {
                return Ok((first, true, first_error));
            }
        }
        Ok((steps, true, e))
    }

    /// The pose error, metres in rig space (before height jitter), of
    /// `pieces` posed on clip `clip` cut into `steps` steps: the largest
    /// vertex distance, at a quarter, half and three quarters of each step,
    /// between the exact pose and the step an agent snaps to (either, at the
    /// half) and the two steps' blend motion blur uses.
    fn clip_error(&self, pieces: &[usize], clip: usize, steps: u32) -> f32 {
        let pose = |x: f32| -> Vec<Vec<Vec3>> {
            let joints = self.clip_joints(clip, self.clip_time(clip, steps, x));
            pieces.iter().map(|&p| self.skin_positions(p, &joints)).collect()
        };
        // f32::max is exact in any order: the same for every thread count.
        (0..steps)
            .into_par_iter()
            .map(|q| {
                let (a, b) = (pose(q as f32), pose(q as f32 + 1.0));
                let mut worst = 0.0f32;
                for s in ERROR_SAMPLES {
                    let exact = pose(q as f32 + s);
                    for ((a, b), exact) in a.iter().zip(&b).zip(&exact) {
                        for ((a, b), x) in a.iter().zip(b).zip(exact) {
                            worst = worst.max(x.distance(a.lerp(*b, s)));
                            if s <= 0.5 {
                                worst = worst.max(x.distance(*a));
                            }
                            if s >= 0.5 {
                                worst = worst.max(x.distance(*b));
                            }
                        }
                    }
                }
                worst
            })
            .reduce(|| 0.0, f32::max)
    }

    /// Reads glTF mesh `mesh_ref` (a name, or `#index`) of `file` as a part,
    /// binding its skin's joints to this rig's nodes by name.
    fn load_part(&mut self, file: &GltfFile, canonical: &Path, mesh_ref: &str) -> Result<usize> {
        let key = (canonical.to_path_buf(), mesh_ref.to_string());
        if let Some(&i) = self.parts.get(&key) {
            return Ok(i);
        }
        let gmesh = file.mesh_by_ref(mesh_ref)?;
        // Known under its other spelling (name or `#index`)?
        for other in [format!("#{}", gmesh.index())].into_iter().chain(gmesh.name().map(str::to_string)) {
            if let Some(&i) = self.parts.get(&(canonical.to_path_buf(), other)) {
                self.parts.insert(key, i);
                return Ok(i);
            }
        }
        let label = match gmesh.name() {
            Some(name) => format!("{}#{name}", file.path.display()),
            None => format!("{} mesh #{}", file.path.display(), gmesh.index()),
        };
        // The skin of the node that uses this mesh (a skinned mesh is drawn
        // by a node with both `mesh` and `skin`).
        let skin = file
            .doc
            .nodes()
            .find(|n| n.mesh().is_some_and(|m| m.index() == gmesh.index()) && n.skin().is_some())
            .and_then(|n| n.skin())
            .ok_or_else(|| {
                file.err(format!(
                    "mesh {label} is not skinned (no node draws it with a skin); a skinned rig wears skinned meshes"
                ))
            })?;
        let (joint_nodes, inverse_bind) = self.read_skin(file, canonical == self.canonical, &skin, &label)?;
        let mut pieces = Vec::new();
        let single = gmesh.primitives().len() == 1;
        for prim in gmesh.primitives() {
            let name = if single { label.clone() } else { format!("{label}/{}", prim.index()) };
            let piece = self.read_piece(file, &gmesh, &prim, name, &joint_nodes, &inverse_bind)?;
            self.pieces.push(piece);
            pieces.push(self.pieces.len() - 1);
        }
        if gmesh.weights().is_some() || gmesh.primitives().any(|p| p.morph_targets().len() > 0) {
            self.warnings.push(format!("{label}: morph targets are ignored (skinning only)"));
        }
        self.part_list.push(SkinPart { pieces });
        let i = self.part_list.len() - 1;
        self.parts.insert(key, i);
        Ok(i)
    }

    /// The mesh `gmesh` of node `node` (named `name`), not skinned, as a
    /// part whose every vertex follows that node alone: one influence of
    /// weight 1, an identity bind (the vertices are in the node's space).
    fn load_rigid_part(
        &mut self,
        file: &GltfFile,
        canonical: &Path,
        node: usize,
        gmesh: &gltf::Mesh,
        name: &str,
    ) -> Result<usize> {
        let key = (canonical.to_path_buf(), name.to_string());
        if let Some(&i) = self.parts.get(&key) {
            return Ok(i);
        }
        let label = format!("{}#{name}", file.path.display());
        let i = self.rigid_pieces(file, gmesh, node, Affine3A::IDENTITY, &label, true)?;
        self.parts.insert(key, i);
        Ok(i)
    }

    /// Every primitive of `gmesh` as a piece bound wholly to node `node`
    /// (one influence of weight 1), its vertices in that node's space by
    /// `bind`: a new part, whose index is returned. `proportioned`: whether
    /// a body's proportions stretch it (a prop keeps its size).
    fn rigid_pieces(
        &mut self,
        file: &GltfFile,
        gmesh: &gltf::Mesh,
        node: usize,
        bind: Affine3A,
        label: &str,
        proportioned: bool,
    ) -> Result<usize> {
        let single = gmesh.primitives().len() == 1;
        let mut pieces = Vec::new();
        let mut meshes = Vec::new();
        for prim in gmesh.primitives() {
            let piece_name = if single { label.to_string() } else { format!("{label}/{}", prim.index()) };
            meshes.push(read_primitive(file, gmesh, &prim, piece_name)?);
        }
        lift_decals(&mut meshes);
        for (prim, mesh) in gmesh.primitives().zip(meshes) {
            let mut one = [(0u16, 0.0f32); MAX_INFLUENCES];
            one[0].1 = 1.0;
            let bounds = mesh
                .positions
                .iter()
                .map(|&p| bind.transform_point3(p))
                .fold(None, |b: Option<(Vec3, Vec3)>, p| Some(b.map_or((p, p), |(lo, hi)| (lo.min(p), hi.max(p)))));
            self.pieces.push(SkinPiece {
                influences: vec![one; mesh.positions.len()],
                mesh,
                joint_nodes: vec![node],
                inverse_bind: vec![bind],
                file: file.path.clone(),
                material: prim.material().index(),
                joint_boxes: vec![bounds],
                proportioned,
            });
            pieces.push(self.pieces.len() - 1);
        }
        if gmesh.weights().is_some() || gmesh.primitives().any(|p| p.morph_targets().len() > 0) {
            self.warnings.push(format!("{label}: morph targets are ignored (rigid on its joint)"));
        }
        self.part_list.push(SkinPart { pieces });
        Ok(self.part_list.len() - 1)
    }

    /// A wardrobe prop: mesh `mesh` of `file` hung on joint `joint` at
    /// `joint_from_prop` (metres, in the joint's frame with its rest-pose
    /// scale taken out, so the rig's `scale` and a scaled armature leave the
    /// prop its size), bound wholly to the joint as a joint-attached mesh
    /// is; loaded once per (file, mesh, joint, offset).
    pub(crate) fn prop_part(
        &mut self,
        file: &Path,
        mesh: &str,
        joint: &str,
        joint_from_prop: Affine3A,
    ) -> Result<usize> {
        let node = (self.animated.hierarchy.find(joint))
            .ok_or_else(|| Error::invalid(&self.path, format!("no joint `{joint}` to hang a prop on")))?;
        let canonical = std::fs::canonicalize(file).map_err(|e| Error::io(file, e))?;
        let bits: Vec<String> = joint_from_prop.to_cols_array().iter().map(|v| format!("{:x}", v.to_bits())).collect();
        let key = (canonical, format!("{mesh}@{joint}/{}", bits.join(",")));
        if let Some(&i) = self.parts.get(&key) {
            return Ok(i);
        }
        let rest = self.joints_at(&self.animated.hierarchy.rest_pose())[node];
        let (scale, _, _) = rest.to_scale_rotation_translation();
        let unscale = Affine3A::from_scale(Vec3::ONE / scale.max(Vec3::splat(1e-12)));
        let gltf = GltfFile::open(file)?;
        let gmesh = gltf.mesh_by_name(mesh)?;
        let label = format!("{}#{mesh}@{joint}", gltf.path.display());
        let i = self.rigid_pieces(&gltf, &gmesh, node, unscale * joint_from_prop, &label, false)?;
        self.parts.insert(key, i);
        Ok(i)
    }

    /// A skin's joints as this rig's node indices, and its inverse bind
    /// matrices. Joints of another file are matched to this rig by name.
    fn read_skin(
        &self,
        file: &GltfFile,
        same_file: bool,
        skin: &gltf::Skin,
        label: &str,
    ) -> Result<(Vec<usize>, Vec<Affine3A>)> {
        let ctx = |msg: String| file.err(format!("skin {} of mesh {label}: {msg}", skin.index()));
        let joints: Vec<gltf::Node> = skin.joints().collect();
        if joints.is_empty() || joints.len() > u16::MAX as usize {
            return Err(ctx(format!("{} joints (1 to {} allowed)", joints.len(), u16::MAX)));
        }
        let mut joint_nodes = Vec::with_capacity(joints.len());
        for j in &joints {
            let node = if same_file {
                j.index()
            } else {
                let name = j.name().unwrap_or("");
                self.animated.hierarchy.find(name).ok_or_else(|| {
                    ctx(format!(
                        "joint `{name}` is not in the rig's skeleton {}: a part must be bound to the same skeleton",
                        self.path.display()
                    ))
                })?
            };
            joint_nodes.push(node);
        }
        let acc = skin.inverse_bind_matrices().ok_or_else(|| {
            ctx("has no inverseBindMatrices accessor; throng needs them (exporters write them; the glTF identity default means joints bound at the origin, almost always a broken export)".into())
        })?;
        check_accessor(&acc, Dimensions::Mat4, &[DataType::F32])
            .map_err(|m| ctx(format!("inverseBindMatrices: {m}")))?;
        let reader = skin.reader(|b| file.buffer_data(b));
        let ibm: Vec<Affine3A> = reader
            .read_inverse_bind_matrices()
            .ok_or_else(|| ctx(out_of_range(&acc)))?
            .map(|m| Affine3A::from_mat4(Mat4::from_cols_array_2d(&m)))
            .collect();
        if ibm.len() != joints.len() {
            return Err(ctx(format!(
                "accessor {}: {} inverse bind matrices for {} joints",
                acc.index(),
                ibm.len(),
                joints.len()
            )));
        }
        if ibm.iter().any(|m| !m.is_finite()) {
            return Err(ctx(format!("accessor {}: an inverse bind matrix is not finite", acc.index())));
        }
        Ok((joint_nodes, ibm))
    }

    fn read_piece(
        &mut self,
        file: &GltfFile,
        gmesh: &gltf::Mesh,
        prim: &gltf::Primitive,
        name: String,
        joint_nodes: &[usize],
        inverse_bind: &[Affine3A],
    ) -> Result<SkinPiece> {
        let mesh = read_primitive(file, gmesh, prim, name.clone())?;
        let n = mesh.positions.len();
        let ctx = |msg: String| file.err(format!("mesh {name}: {msg}"));
        if prim.get(&gltf::Semantic::Joints(2)).is_some() || prim.get(&gltf::Semantic::Weights(2)).is_some() {
            return Err(ctx(format!(
                "JOINTS_2/WEIGHTS_2: more than {MAX_INFLUENCES} influences per vertex are not supported"
            )));
        }
        let reader = prim.reader(|b| file.buffer_data(b));
        let mut influences = vec![[(0u16, 0.0f32); MAX_INFLUENCES]; n];
        let mut sets = 0;
        for set in 0..2u32 {
            let (ja, wa) = (prim.get(&gltf::Semantic::Joints(set)), prim.get(&gltf::Semantic::Weights(set)));
            let (ja, wa) = match (ja, wa) {
                (None, None) => continue,
                (Some(j), Some(w)) => (j, w),
                _ => return Err(ctx(format!("JOINTS_{set} and WEIGHTS_{set} must come together"))),
            };
            check_accessor(&ja, Dimensions::Vec4, &[DataType::U8, DataType::U16])
                .map_err(|m| ctx(format!("JOINTS_{set}: {m}")))?;
            check_accessor(&wa, Dimensions::Vec4, &[DataType::F32, DataType::U8, DataType::U16])
                .map_err(|m| ctx(format!("WEIGHTS_{set}: {m}")))?;
            let joints: Vec<[u16; 4]> =
                reader.read_joints(set).ok_or_else(|| ctx(out_of_range(&ja)))?.into_u16().collect();
            let weights: Vec<[f32; 4]> =
                reader.read_weights(set).ok_or_else(|| ctx(out_of_range(&wa)))?.into_f32().collect();
            if joints.len() != n || weights.len() != n {
                return Err(ctx(format!(
                    "JOINTS_{set} (accessor {}) has {} and WEIGHTS_{set} (accessor {}) {} entries for {n} vertices",
                    ja.index(),
                    joints.len(),
                    wa.index(),
                    weights.len()
                )));
            }
            for (v, (j, w)) in joints.iter().zip(&weights).enumerate() {
                for k in 0..4 {
                    if !(w[k] >= 0.0 && w[k].is_finite()) {
                        return Err(ctx(format!(
                            "WEIGHTS_{set} (accessor {}) vertex {v}: weight {} is not a finite number >= 0",
                            wa.index(),
                            w[k]
                        )));
                    }
                    if w[k] > 0.0 && j[k] as usize >= joint_nodes.len() {
                        return Err(ctx(format!(
                            "JOINTS_{set} (accessor {}) vertex {v}: joint {} is out of range (the skin has {} joints)",
                            ja.index(),
                            j[k],
                            joint_nodes.len()
                        )));
                    }
                    influences[v][set as usize * 4 + k] = (j[k], w[k]);
                }
            }
            sets += 1;
        }
        if sets == 0 {
            return Err(ctx("has no JOINTS_0/WEIGHTS_0 but its node has a skin".into()));
        }
        let mut renormalised = 0;
        for (v, inf) in influences.iter_mut().enumerate() {
            let sum: f32 = inf.iter().map(|i| i.1).sum();
            if sum <= 0.0 {
                return Err(ctx(format!("vertex {v} has no joint weight (its weights sum to 0)")));
            }
            if (sum - 1.0).abs() > WEIGHT_SUM_TOLERANCE {
                renormalised += 1;
            }
            for i in inf.iter_mut() {
                i.1 /= sum;
            }
        }
        if renormalised > 0 {
            self.warnings.push(format!(
                "{}: mesh {name}: {renormalised} of {n} vertices have joint weights that do not sum to 1; renormalised",
                file.path.display()
            ));
        }
        // Per-joint proxy boxes: vertices weighted mostly to a joint, in its bind space.
        let mut joint_boxes: Vec<Option<(Vec3, Vec3)>> = vec![None; joint_nodes.len()];
        for (p, inf) in mesh.positions.iter().zip(&influences) {
            let Some(&(j, _)) = inf.iter().max_by(|a, b| a.1.total_cmp(&b.1)) else { continue };
            let q = inverse_bind[j as usize].transform_point3(*p);
            let b = &mut joint_boxes[j as usize];
            *b = Some(b.map_or((q, q), |(lo, hi)| (lo.min(q), hi.max(q))));
        }
        Ok(SkinPiece {
            mesh,
            influences,
            joint_nodes: joint_nodes.to_vec(),
            inverse_bind: inverse_bind.to_vec(),
            file: file.path.clone(),
            material: prim.material().index(),
            joint_boxes,
            proportioned: true,
        })
    }

    /// The part for a wardrobe's `file` + `mesh` (a name or `#index`) worn
    /// in `slot`, loading it on first use. A rigid rig's part rides the
    /// slot's node, modelled in that node's space as the node's own mesh is.
    pub(crate) fn part(&mut self, file: &Path, mesh_ref: &str, slot: &str) -> Result<usize> {
        let canonical = std::fs::canonicalize(file).map_err(|e| Error::io(file, e))?;
        // The rig's own mesh on its own node (what an agent wears as delivered).
        let own = self.delivered.iter().find(|(s, m, _)| s == slot && m == mesh_ref);
        if let (true, Some(&(_, _, part))) = (self.rigid && canonical == self.canonical, own) {
            return Ok(part);
        }
        let name = match self.rigid {
            true => format!("{mesh_ref} on {slot}"),
            false => mesh_ref.to_string(),
        };
        if let Some(&i) = self.parts.get(&(canonical.clone(), name.clone())) {
            return Ok(i);
        }
        let gltf = GltfFile::open(file)?;
        if !self.rigid {
            return self.load_part(&gltf, &canonical, mesh_ref);
        }
        let node = self.slot_node(slot)?;
        let gmesh = gltf.mesh_by_ref(mesh_ref)?;
        // A skinned mesh would be drawn in its bind pose on the node: refused, as on a slot rig.
        if gltf.doc.nodes().any(|n| n.skin().is_some() && n.mesh().is_some_and(|m| m.index() == gmesh.index())) {
            return Err(gltf
                .err(format!(
                    "mesh `{mesh_ref}` is skinned; a rigid rig's parts ride their slot's node (`{slot}`) rigidly: \
                     wear it on a skinned rig, or export it without its skin"
                ))
                .field("mesh"));
        }
        self.load_rigid_part(&gltf, &canonical, node, &gmesh, &name)
    }

    /// The node a rigid rig's slot names (a node name, or `#node<index>`).
    fn slot_node(&self, slot: &str) -> Result<usize> {
        let by_index = slot.strip_prefix("#node").and_then(|i| i.parse::<usize>().ok());
        by_index
            .filter(|&i| i < self.animated.hierarchy.nodes.len())
            .or_else(|| self.animated.hierarchy.find(slot))
            .ok_or_else(|| {
                Error::invalid(
                    &self.path,
                    format!("slot `{slot}` is no node of this rigid rig: a rigid rig's slots are its nodes, by name"),
                )
                .field("slots")
            })
    }

    /// `rig_from_node` of every node for local transforms `local` (before root-motion removal).
    fn joints_at(&self, local: &[Trs]) -> Vec<Affine3A> {
        self.animated.hierarchy.compose(local).into_iter().map(|m| self.rig_from_file * m).collect()
    }

    /// [`Self::joints_at`] on body `body`: each node's offset from its
    /// parent scaled by the parent's bone. Body 0 is `joints_at` itself.
    fn body_joints_at(&self, body: u16, local: &[Trs]) -> Vec<Affine3A> {
        let Some(b) = self.body(body) else { return self.joints_at(local) };
        self.animated.hierarchy.compose_scaled(local, &b.bone).into_iter().map(|m| self.rig_from_file * m).collect()
    }

    /// [`Self::body_joints_at`] lifted so the lowest point of the file's own
    /// meshes is where the modelled body's is in the same pose: longer legs
    /// stand on the ground, not in it, at every step of a walk.
    fn grounded_joints_at(&self, body: u16, local: &[Trs]) -> Vec<Affine3A> {
        let mut joints = self.body_joints_at(body, local);
        if body == 0 {
            return joints;
        }
        let (modelled, _) = self.span_at(0, &self.joints_at(local));
        let (lowest, _) = self.span_at(body, &joints);
        let lift = modelled - lowest;
        if lift.is_finite() {
            let up = Affine3A::from_translation(Vec3::new(0.0, lift, 0.0));
            for j in &mut joints {
                *j = up * *j;
            }
        }
        joints
    }

    /// Body `body` (`None` for body 0, the rig as modelled, or past the bodies).
    pub(crate) fn body(&self, body: u16) -> Option<&Body> {
        self.bodies.get(usize::from(body).checked_sub(1)?)
    }

    /// How many bodies the rig's agents draw from (0: every agent has the modelled body).
    pub fn body_count(&self) -> u16 {
        self.bodies.len() as u16
    }

    /// The stride factor of body `body` (1 for the modelled body).
    pub fn body_stride(&self, body: u16) -> f32 {
        self.body(body).map_or(1.0, |b| b.stride)
    }

    /// Node `node`'s bone scale on body `body`, as a transform of the node's frame.
    pub(crate) fn bone(&self, body: u16, node: usize) -> Affine3A {
        self.body(body).map_or(Affine3A::IDENTITY, |b| Affine3A::from_mat3(b.bone[node]))
    }

    /// The lowest and highest rig-space Y of the file's own meshes in the
    /// rest pose of body `body` (infinite when it has none).
    fn rest_span(&self, body: u16) -> (f32, f32) {
        self.span_at(body, &self.body_joints_at(body, &self.animated.hierarchy.rest_pose()))
    }

    /// The lowest and highest rig-space Y of the file's own meshes posed by
    /// `joints` of body `body` (infinite when it has none).
    fn span_at(&self, body: u16, joints: &[Affine3A]) -> (f32, f32) {
        let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
        for (_, _, part) in &self.delivered {
            for &p in &self.part_list[*part].pieces {
                let skin = self.skin_matrices(body, p, joints);
                for (v, inf) in self.pieces[p].mesh.positions.iter().zip(&self.pieces[p].influences) {
                    let y = Self::blend(&skin, inf).transform_point3(*v).y;
                    lo = lo.min(y);
                    hi = hi.max(y);
                }
            }
        }
        (lo, hi)
    }

    /// Draws the rig's bodies for `[rigs.NAME.proportions]` with the shot's
    /// seed and measures each one's standing height.
    pub(crate) fn draw_bodies(&mut self, name: &str, spec: &crate::shot::Proportions, seed: u64) -> Result<()> {
        self.bodies = body::draw(&self.path, name, spec, seed, &self.animated.hierarchy)
            .map_err(|e| e.field_prefix(&format!("rigs.{name}")))?;
        for b in 1..=self.body_count() {
            let (lo, hi) = self.rest_span(b);
            if let Some(body) = self.bodies.get_mut(usize::from(b) - 1) {
                body.height = if hi > lo { hi - lo } else { self.height };
            }
        }
        Ok(())
    }

    /// Standing height in metres of body `body` (rest pose, before height jitter).
    pub fn body_height(&self, body: u16) -> f32 {
        self.body(body).map_or(self.height, |b| b.height)
    }

    /// The distance a rigid rig's wheels roll over clip `clip`
    /// ([`crate::casting::wheels`]; 0 without wheels), warning of wheels
    /// that would roll another distance.
    fn wheel_stride(&mut self, pieces: &[usize], clip: usize) -> f32 {
        let c = &self.animated.clips[clip];
        let joints = self.clip_joints(clip, c.start);
        let meshes: Vec<(usize, Vec<Vec3>)> =
            pieces.iter().map(|&p| (self.pieces[p].joint_nodes[0], self.skin_positions(p, &joints))).collect();
        let found = wheels::wheels(c, &self.animated.hierarchy, &joints, &meshes);
        let Some((stride, sliding)) = wheels::stride(&found) else { return 0.0 };
        let name = |n: usize| self.animated.hierarchy.nodes[n].name.clone();
        for w in sliding {
            self.warnings.push(format!(
                "{}: clip `{}`: wheel `{}` rolls {:.3} m a cycle, wheel `{}` (which sets the stride) {stride:.3} m: it slides",
                self.path.display(),
                c.name,
                name(w.node),
                w.roll(),
                name(found[0].node)
            ));
        }
        stride
    }

    /// The root joint's rig-space Z travel over clip `clip`.
    fn root_travel(&self, clip: usize) -> f32 {
        let Some(root) = self.root else { return 0.0 };
        let c = &self.animated.clips[clip];
        let at = |t: f32| {
            let mut local = self.animated.hierarchy.rest_pose();
            c.apply(t, &mut local);
            self.joints_at(&local)[root].translation.z
        };
        at(c.end) - at(c.start)
    }

    /// The file.
    pub(crate) fn path(&self) -> &Path {
        &self.path
    }
    /// Names of the joints of the file's own skins (and the nodes its
    /// joint-attached meshes hang on), in node order: what a prop may hang on.
    /// A rigid rig's props may hang on any named node, as its parts do.
    pub(crate) fn joint_names(&self) -> Vec<&str> {
        if self.rigid {
            return self.animated.hierarchy.nodes.iter().map(|n| n.name.as_str()).filter(|n| !n.is_empty()).collect();
        }
        let mut nodes: Vec<usize> = (self.delivered.iter())
            .flat_map(|(_, _, part)| self.part_list[*part].pieces.iter())
            .flat_map(|&p| self.pieces[p].joint_nodes.iter().copied())
            .collect();
        nodes.sort_unstable();
        nodes.dedup();
        nodes.iter().filter_map(|&n| self.animated.hierarchy.nodes.get(n)).map(|n| n.name.as_str()).collect()
    }
    /// Slot names casting fills (one skinned mesh each).
    pub(crate) fn slots(&self) -> &[String] {
        &self.slots
    }
    /// The file's own skinned meshes: (slot, mesh name or `#index`, part),
    /// what an agent wears when the shot gives the rig no schemes.
    pub(crate) fn delivered(&self) -> &[(String, String, usize)] {
        &self.delivered
    }
    /// Standing height in metres (rest pose, before height jitter).
    pub fn height(&self) -> f32 {
        self.height
    }
    /// Whether the character is rigid (meshes on animated nodes, no skin).
    pub fn is_rigid(&self) -> bool {
        self.rigid
    }
    /// The kind, as the shot's `kind` names it.
    pub(crate) fn kind(&self) -> &'static str {
        if self.rigid {
            "rigid"
        } else {
            "skinned"
        }
    }
    /// Cycles, mapped names first.
    pub fn cycles(&self) -> &[SkinCycle] {
        &self.cycles
    }
    /// A part by index.
    pub(crate) fn part_at(&self, i: usize) -> &SkinPart {
        &self.part_list[i]
    }
    /// A piece by index.
    pub fn piece(&self, i: usize) -> &SkinPiece {
        &self.pieces[i]
    }
    /// How many pieces are loaded (the file's own, then worn parts of other files).
    pub fn piece_count(&self) -> usize {
        self.pieces.len()
    }
    /// Warnings from loading (weights renormalised, morph targets ignored).
    pub fn warnings(&self) -> &[String] {
        &self.warnings
    }

    /// Index of the cycle a cache cycle name plays; the error lists the
    /// cycles. Cache cycles mapped to one clip give the same index (the
    /// first cycle playing that clip), so their agents share poses.
    pub fn cycle_index(&self, name: &str) -> Result<usize> {
        let found = self.cycles.iter().position(|c| c.name == name);
        if let Some(i) = found {
            let clip = self.cycles[i].clip;
            return Ok(self.cycles.iter().position(|c| c.clip == clip).unwrap_or(i));
        }
        found.ok_or_else(|| {
            let names: Vec<String> = self.cycles.iter().map(|c| format!("{} (clip {})", c.name, c.clip_name)).collect();
            Error::invalid(
                &self.path,
                format!(
                    "{} rig has no cycle `{name}`; cycles: {} (map cache cycles to clips with `cycles = {{ {name} = \"CLIP\" }}`)",
                    self.kind(),
                    names.join(", ")
                ),
            )
        })
    }

    /// Stride (metres) and length (frames) of cache cycle `name`. Cycles on
    /// one clip share its poses ([`SkinnedRig::cycle_index`] gives the first
    /// of them), not their strides: each keeps its own `strides` entry.
    pub fn cycle_timing(&self, name: &str) -> Result<(f32, f32)> {
        let c = self.cycle_index(name)?;
        let own = self.cycles.iter().find(|x| x.name == name).map_or(self.cycles[c].stride, |x| x.stride);
        Ok((own, self.cycle_frames(c)))
    }

    /// Where cache cycle `name`'s stride comes from (see [`SkinnedRig::cycle_timing`]).
    pub(crate) fn stride_from(&self, name: &str) -> Result<StrideFrom> {
        let c = self.cycle_index(name)?;
        Ok(self.cycles.iter().find(|x| x.name == name).map_or(self.cycles[c].stride_from, |x| x.stride_from))
    }

    /// What gives a cycle of this rig its stride when the shot gives none:
    /// for messages that a cycle has none.
    pub(crate) fn stride_sources(&self) -> &'static str {
        match self.rigid {
            true => "no `root` node and its clip turns no wheel",
            false => "no `root` joint",
        }
    }

    /// Length of a cycle in frames.
    pub fn cycle_frames(&self, cycle: usize) -> f32 {
        self.animated.clips[self.cycles[cycle].clip].duration() * self.fps
    }

    /// Number of pose steps a cycle is cut into (`steps + 1` poses, 0 to `steps`).
    pub(crate) fn cycle_steps(&self, cycle: usize) -> u32 {
        self.cycles[cycle].steps
    }

    /// The pose step nearest cycle frame `frame` (wrapped into the cycle):
    /// 0 to `steps` inclusive, since a clip that does not loop seamlessly
    /// ends on a pose other than its first.
    pub(crate) fn step_of(&self, cycle: usize, frame: f32) -> u32 {
        let c = &self.cycles[cycle];
        let length = self.cycle_frames(cycle);
        if !(length > 0.0 && frame.is_finite()) {
            return 0;
        }
        let step = length / c.steps as f32;
        ((frame.rem_euclid(length) / step).round() as u32).min(c.steps)
    }

    /// Clip time in seconds of fractional step `step` of clip `clip` cut into `steps`.
    fn clip_time(&self, clip: usize, steps: u32, step: f32) -> f32 {
        let clip = &self.animated.clips[clip];
        clip.start + step * clip.duration() / steps as f32
    }

    /// `rig_from_node` for every node at time `t` of clip `clip`, root
    /// motion removed.
    fn clip_joints(&self, clip: usize, t: f32) -> Vec<Affine3A> {
        self.body_clip_joints(0, clip, t)
    }

    /// [`Self::clip_joints`] on body `body`.
    fn body_clip_joints(&self, body: u16, clip: usize, t: f32) -> Vec<Affine3A> {
        let mut local = self.animated.hierarchy.rest_pose();
        self.animated.clips[clip].apply(t, &mut local);
        let mut joints = self.grounded_joints_at(body, &local);
        if let Some(root) = self.root {
            let o = joints[root].translation;
            let strip = Affine3A::from_translation(Vec3::new(-o.x, 0.0, -o.z));
            for j in &mut joints {
                *j = strip * *j;
            }
        }
        joints
    }

    /// `rig_from_node` for every node at a pose step.
    pub fn step_joints(&self, cycle: usize, step: u32) -> Vec<Affine3A> {
        self.body_step_joints(0, cycle, step)
    }

    /// [`Self::step_joints`] on body `body`.
    pub fn body_step_joints(&self, body: u16, cycle: usize, step: u32) -> Vec<Affine3A> {
        let c = &self.cycles[cycle];
        self.body_clip_joints(body, c.clip, self.clip_time(c.clip, c.steps, step as f32))
    }

    /// Skin matrices of a piece for node transforms `joints` of body `body`
    /// (a proportioned piece's joints stretched by their bones).
    fn skin_matrices(&self, body: u16, piece: usize, joints: &[Affine3A]) -> Vec<Affine3A> {
        let p = &self.pieces[piece];
        let bones = self.body(body).filter(|_| p.proportioned);
        (p.joint_nodes.iter().zip(&p.inverse_bind))
            .map(|(&n, ibm)| match bones {
                Some(b) => joints[n] * Affine3A::from_mat3(b.bone[n]) * *ibm,
                None => joints[n] * *ibm,
            })
            .collect()
    }

    /// Blended matrix of one vertex.
    fn blend(skin: &[Affine3A], inf: &[(u16, f32); MAX_INFLUENCES]) -> Affine3A {
        let mut m = Mat4::ZERO;
        for &(j, w) in inf {
            if w > 0.0 {
                m += Mat4::from(skin[j as usize]) * w;
            }
        }
        Affine3A::from_mat4(m)
    }

    fn skin_positions(&self, piece: usize, joints: &[Affine3A]) -> Vec<Vec3> {
        let skin = self.skin_matrices(0, piece, joints);
        let p = &self.pieces[piece];
        p.mesh
            .positions
            .iter()
            .zip(&p.influences)
            .map(|(v, inf)| Self::blend(&skin, inf).transform_point3(*v))
            .collect()
    }

    /// A piece posed by node transforms `joints`: positions blended,
    /// normals by the inverse transpose. Named `<piece>@<pose>`.
    pub fn pose_piece(&self, piece: usize, joints: &[Affine3A], pose: &str) -> Mesh {
        self.pose_body_piece(0, piece, joints, pose)
    }

    /// [`Self::pose_piece`] on body `body`, `joints` from [`Self::body_step_joints`].
    pub fn pose_body_piece(&self, body: u16, piece: usize, joints: &[Affine3A], pose: &str) -> Mesh {
        let skin = self.skin_matrices(body, piece, joints);
        let p = &self.pieces[piece];
        let mut out = Mesh {
            name: format!("{}@{pose}", p.mesh.name),
            positions: Vec::with_capacity(p.mesh.positions.len()),
            normals: Vec::with_capacity(p.mesh.normals.len()),
            uvs: p.mesh.uvs.clone(),
            // Posed tangents are not kept: normal maps fall back to per-triangle tangents from the UVs.
            tangents: Vec::new(),
            indices: p.mesh.indices.clone(),
        };
        for (i, inf) in p.influences.iter().enumerate() {
            let m = Self::blend(&skin, inf);
            out.positions.push(m.transform_point3(p.mesh.positions[i]));
            if let Some(&n) = p.mesh.normals.get(i) {
                let normal_matrix = Mat3::from(m.matrix3).inverse().transpose();
                out.normals.push((normal_matrix * n).try_normalize().unwrap_or(n));
            }
        }
        out
    }

    /// Pose name of a step, for mesh names and botinfo: `<clip>/<step>of<steps>`.
    pub(crate) fn pose_name(&self, cycle: usize, step: u32) -> String {
        let c = &self.cycles[cycle];
        format!("{}/{}of{}", c.clip_name, step, c.steps)
    }

    /// The pose error, metres, of `pieces` on cycle `cycle` at its steps, on
    /// the rig's tallest agent (rig-space error times the largest height
    /// scale): the largest vertex distance between the exact pose and the
    /// snapped step or the blend of the steps around it.
    pub(crate) fn pose_error(&self, pieces: &[usize], cycle: usize) -> f32 {
        let c = &self.cycles[cycle];
        self.clip_error(pieces, c.clip, c.steps) * self.max_height_scale
    }

    /// The shot's bound on pose error, metres on the tallest agent.
    pub(crate) fn pose_error_max(&self) -> f32 {
        self.pose_error_max
    }
}
