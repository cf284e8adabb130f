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
//! STEP, LINEAR or CUBICSPLINE, sampled by [`crate::casting::animation::Channel`]);
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

use glam::{Affine3A, Mat3, Mat4, Vec3};
use rayon::prelude::*;

use crate::casting::animation::{Animated, Trs};
use crate::casting::body::{self, Body};
use crate::casting::kind::is_skinned;
pub use crate::casting::pieces::SkinPiece;
use crate::casting::pieces::{PartReader, PartTable, SkinPart, MAX_INFLUENCES};
use crate::casting::usdskel_rig;
use crate::casting::wheels;
use crate::error::{Error, Result};
use crate::scene::gltf::{orientation, GltfFile};
use crate::scene::Mesh;
use crate::shot::SkinOptions;

/// The coarsest pose step, in cycle frames, chosen when the shot gives no
/// `pose_step` (finer where a clip moves faster than `pose_error_max` allows).
pub(crate) const DEFAULT_POSE_STEP: f32 = 1.0;
/// Where within each step the exact pose is compared with the snapped and
/// blended ones (fractions of a step).
const ERROR_SAMPLES: [f32; 3] = [0.25, 0.5, 0.75];
/// Most pose steps one cycle may be cut into (bounds posed geometry).
pub(crate) const MAX_STEPS_PER_CYCLE: u32 = 1024;
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
    /// The file's own parts and pieces, read at load (a dressing's worn
    /// parts go into its own table, numbered on from these).
    own: PartTable,
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
    /// The warnings about one clip (its pose error), as (index into
    /// `warnings`, clip): printed only for a clip the shot's cycles play.
    clip_warnings: Vec<(usize, usize)>,
    /// A UsdSkel character's materials, by a piece's `material`, each with
    /// its base colour texture's file (a glTF rig's come from its file: empty).
    materials: Vec<(crate::scene::Material, Option<PathBuf>)>,
    /// A UsdSkel character: its clips are baked frames, each a pose step.
    baked: bool,
}

/// Whether `file` is read as a rigid character (else skinned): the shot's
/// `kind` when it declares one, checked against the file's skin, else the
/// skin decides.
fn checked_kind(file: &GltfFile, options: &SkinOptions) -> Result<bool> {
    let rigid = options.rigid.unwrap_or(!is_skinned(file));
    if !rigid && !is_skinned(file) {
        return Err(file
            .err(
                "declared `kind = \"skinned\"` but the file has no skin; meshes on animated nodes are \
                 `kind = \"rigid\"`, and a slot rig needs no kind",
            )
            .field("kind"));
    }
    if rigid && is_skinned(file) {
        return Err(file
            .err(format!(
                "declared `kind = \"rigid\"` but the file has a skin ({} skins): a skinned character is \
                 `kind = \"skinned\"`",
                file.doc.skins().len()
            ))
            .field("kind"));
    }
    Ok(rigid)
}

/// The node the shot's `root` names, whose travel is root motion: any node
/// of a rigid rig, a joint of a skinned one's skins.
fn root_node(file: &GltfFile, animated: &Animated, rigid: bool, options: &SkinOptions) -> Result<Option<usize>> {
    let Some(name) = &options.root else { return Ok(None) };
    let found = animated.hierarchy.find(name).ok_or_else(|| {
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
        file.err(format!("no {what} named `{name}` for root motion; {what}s: {}", joints.join(", "))).field("root")
    })?;
    Ok(Some(found))
}

impl SkinnedRig {
    /// Loads a skinned character with the shot's options. Cycle names come
    /// from `options.cycles` (cache name -> clip name or `#index`); every
    /// clip is also available under its own name.
    pub fn load(path: &Path, options: &SkinOptions, fps: f32) -> Result<SkinnedRig> {
        Self::load_reading(path, options, fps, &mut usdskel_rig::SkelFiles::default())
    }

    /// [`SkinnedRig::load`], a UsdSkel file's reading taken from `usd` (or
    /// read into it), so rigs on one file and the shot's cache share it.
    pub(crate) fn load_reading(
        path: &Path,
        options: &SkinOptions,
        fps: f32,
        usd: &mut usdskel_rig::SkelFiles,
    ) -> Result<SkinnedRig> {
        if usdskel_rig::is_usd(path) {
            return Self::load_usd(path, options, fps, usd);
        }
        let file = GltfFile::open(path)?;
        let rigid = checked_kind(&file, options)?;
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
        let root = root_node(&file, &animated, rigid, options)?;
        let mut rig = SkinnedRig { rigid, root, ..SkinnedRig::bare(path, animated, options, fps)? };
        rig.load_delivered(&file, options)?;
        rig.stand_on_ground(&file)?;
        rig.load_cycles(options)?;
        Ok(rig)
    }

    /// A rig of `path` with its animation and the shot's options, and
    /// nothing loaded yet: what both loaders start from.
    fn bare(path: &Path, animated: Animated, options: &SkinOptions, fps: f32) -> Result<SkinnedRig> {
        let orient = orientation(path, options.up, options.forward)?;
        Ok(SkinnedRig {
            path: path.to_path_buf(),
            canonical: std::fs::canonicalize(path).map_err(|e| Error::io(path, e))?,
            rigid: false,
            animated,
            rig_from_file: Affine3A::from_scale_rotation_translation(Vec3::splat(options.scale), orient, Vec3::ZERO),
            root: None,
            cycles: Vec::new(),
            own: PartTable::default(),
            slots: Vec::new(),
            delivered: Vec::new(),
            height: 0.0,
            fps,
            pose_step: options.pose_step,
            pose_error_max: options.pose_error_max,
            max_height_scale: options.max_height_scale,
            bodies: Vec::new(),
            warnings: Vec::new(),
            clip_warnings: Vec::new(),
            materials: Vec::new(),
            baked: false,
        })
    }

    /// Loads the character a UsdSkel crowd's agents share
    /// ([`crate::casting::usdskel_rig`]): its skeleton, skinned meshes and
    /// materials, and one clip per distinct animation. The crowd
    /// department's placement is authoritative: the rig is not lifted to
    /// the ground, so joints stand where the file puts them.
    fn load_usd(path: &Path, options: &SkinOptions, fps: f32, usd: &mut usdskel_rig::SkelFiles) -> Result<SkinnedRig> {
        let c = usdskel_rig::character(usd.get(path)?, path, options.root.as_deref(), fps)?;
        let slots = options.slots.clone().unwrap_or_else(|| c.delivered.iter().map(|(s, _, _)| s.clone()).collect());
        let mut rig = SkinnedRig {
            own: c.own,
            slots,
            delivered: c.delivered,
            warnings: c.warnings,
            materials: c.materials,
            baked: true,
            ..SkinnedRig::bare(path, c.animated, options, fps)?
        };
        // The agents' own (ancestors') uniform scale: their place comes scaled already, their joints not.
        rig.rig_from_file = Affine3A::from_scale(Vec3::splat(c.scale)) * rig.rig_from_file;
        let (lo, hi) = rig.rest_span(0);
        if !(lo.is_finite() && hi > lo) {
            return Err(Error::invalid(path, "the UsdSkel meshes have no height in the rest pose"));
        }
        rig.height = hi - lo;
        rig.load_cycles(options)?;
        Ok(rig)
    }

    /// The character as delivered: every skinned mesh node is a slot
    /// wearing its own mesh, unless the shot names the slots; meshes on
    /// nodes under a joint (a rigid rig's every mesh node) ride their node.
    fn load_delivered(&mut self, file: &GltfFile, options: &SkinOptions) -> Result<()> {
        let mut delivered = Vec::new();
        for node in file.doc.nodes() {
            let (Some(mesh), Some(_)) = (node.mesh(), node.skin()) else { continue };
            let slot = node
                .name()
                .map(str::to_string)
                .or_else(|| mesh.name().map(str::to_string))
                .unwrap_or_else(|| format!("#{}", mesh.index()));
            let mesh_ref = mesh.name().map(str::to_string).unwrap_or_else(|| format!("#{}", mesh.index()));
            let canonical = self.canonical.clone();
            let part = self.read_own(|reader| reader.load_part(file, &canonical, &mesh_ref))?;
            delivered.push((slot, mesh_ref, part));
        }
        self.load_joint_meshes(file, &mut delivered)?;
        if delivered.is_empty() {
            return Err(file.err(match self.rigid {
                true => "a rigid rig poses its nodes' meshes, but no node of the file has a mesh",
                false => "the file has a skin but no node that uses it with a mesh",
            }));
        }
        self.slots = match &options.slots {
            Some(s) => s.clone(),
            None => delivered.iter().map(|(s, _, _)| s.clone()).collect(),
        };
        if self.rigid {
            for slot in &self.slots {
                self.slot_node(slot)?;
            }
        }
        self.delivered = delivered;
        Ok(())
    }

    /// Meshes on nodes under a joint, not skinned (robot limbs, a held
    /// prop): each moves rigidly with its node, as a piece bound wholly to
    /// that node, so posing, proxies, blur and instancing treat it like a
    /// skinned one. Each is added to `delivered` as (name, name, part).
    fn load_joint_meshes(&mut self, file: &GltfFile, delivered: &mut Vec<(String, String, usize)>) -> Result<()> {
        let joints: std::collections::HashSet<usize> =
            file.doc.skins().flat_map(|s| s.joints().map(|j| j.index()).collect::<Vec<_>>()).collect();
        for node in file.doc.nodes() {
            let (Some(mesh), None) = (node.mesh(), node.skin()) else { continue };
            // Named by its node (a mesh may hang on several), by index where
            // that name is a skinned mesh's too.
            let name = node
                .name()
                .map(str::to_string)
                .filter(|n| !self.own.keys.contains_key(&(self.canonical.clone(), n.clone())))
                .unwrap_or_else(|| format!("#node{}", node.index()));
            // A rigid rig's every mesh node is a part (its wheels, its body).
            let mut at = Some(node.index());
            while let Some(n) = at.filter(|n| !self.rigid && !joints.contains(n)) {
                at = self.animated.hierarchy.nodes.get(n).and_then(|h| h.parent);
            }
            if at.is_none() {
                self.warnings.push(format!(
                    "{}: mesh node `{name}` is neither skinned nor under a joint of the skeleton: left out",
                    file.path.display()
                ));
                continue;
            }
            let canonical = self.canonical.clone();
            let part = self.read_own(|reader| reader.load_rigid_part(file, &canonical, node.index(), &mesh, &name))?;
            delivered.push((name.clone(), name, part));
        }
        Ok(())
    }

    /// Ground and height from the rest pose of the delivered meshes: the
    /// lowest vertex lifted to y = 0.
    fn stand_on_ground(&mut self, file: &GltfFile) -> Result<()> {
        let (lo, hi) = self.rest_span(0);
        if !(lo.is_finite() && hi > lo) {
            return Err(file.err(format!("the {} meshes have no height in the rest pose", self.kind())));
        }
        self.rig_from_file = Affine3A::from_translation(Vec3::new(0.0, -lo, 0.0)) * self.rig_from_file;
        self.height = hi - lo;
        Ok(())
    }

    /// Cycles: the shot's mapping first, then every clip under its own
    /// name, each with its stride and pose steps.
    fn load_cycles(&mut self, options: &SkinOptions) -> Result<()> {
        let path = self.path.clone();
        let err = |msg: String| Error::invalid(&path, msg);
        let clips = &self.animated.clips;
        let clip_index = |name: &str| -> Option<usize> {
            clips
                .iter()
                .position(|c| c.name == name)
                .or_else(|| name.strip_prefix('#').and_then(|i| i.parse::<usize>().ok()).filter(|&i| i < clips.len()))
        };
        let mut cycles: Vec<(String, usize)> = Vec::new();
        for (cycle, clip) in &options.cycles {
            let i = clip_index(clip).ok_or_else(|| {
                let names: Vec<String> = clips.iter().enumerate().map(|(i, c)| format!("{} (#{i})", c.name)).collect();
                err(format!(
                    "cycle `{cycle}` maps to clip `{clip}`, which the file lacks; clips: {}",
                    if names.is_empty() { "(none)".to_string() } else { names.join(", ") }
                ))
                .field(format!("cycles.{cycle}"))
            })?;
            cycles.push((cycle.clone(), i));
        }
        for (i, c) in clips.iter().enumerate() {
            if !cycles.iter().any(|(n, _)| *n == c.name) {
                cycles.push((c.name.clone(), i));
            }
        }
        // Pose steps per clip (cycles sharing a clip share its steps),
        // measured on the file's own meshes.
        let own = self.delivered_pieces();
        let mut per_clip: BTreeMap<usize, (u32, bool, f32)> = BTreeMap::new();
        let mut rolls: BTreeMap<usize, f32> = BTreeMap::new();
        for (name, clip) in cycles {
            let clip_name = self.animated.clips[clip].name.clone();
            let (stride, stride_from) = match options.strides.get(&name) {
                Some(&s) => (s, StrideFrom::Given),
                None if self.root.is_none() && self.rigid => {
                    let s = match rolls.get(&clip) {
                        Some(&s) => s,
                        None => {
                            let s = self.wheel_stride(&own, clip);
                            *rolls.entry(clip).or_insert(s)
                        }
                    };
                    (s, if s > 0.0 { StrideFrom::Wheels } else { StrideFrom::Unmeasured })
                }
                None if self.root.is_none() => (0.0, StrideFrom::Unmeasured),
                None => (self.root_travel(clip), StrideFrom::Root),
            };
            let (steps, chosen, error) = match per_clip.get(&clip) {
                Some(&known) => known,
                None => {
                    let before = self.warnings.len();
                    let known = self.clip_steps(&own, clip, &name)?;
                    self.clip_warnings.extend((before..self.warnings.len()).map(|w| (w, clip)));
                    per_clip.insert(clip, known);
                    known
                }
            };
            self.cycles.push(SkinCycle { name, clip, clip_name, stride, stride_from, steps, chosen, error });
        }
        Ok(())
    }

    /// Loads the shot's rig `name` (`[rigs.NAME]`), its errors' fields under `rigs.NAME`.
    pub(crate) fn load_shot_rig(
        name: &str,
        rig: &crate::shot::RigRef,
        fps: f32,
        usd: &mut usdskel_rig::SkelFiles,
    ) -> Result<SkinnedRig> {
        SkinnedRig::load_reading(&rig.file, &rig.skin, fps, usd)
            .map_err(|e| e.field_prefix(&format!("rigs.{name}")).or_field(format!("rigs.{name}.file")))
    }

    /// Reads parts into the file's own table (while loading).
    fn read_own<T>(&mut self, read: impl FnOnce(&mut PartReader) -> Result<T>) -> Result<T> {
        let mut own = std::mem::take(&mut self.own);
        let none = PartTable::default();
        let mut reader = PartReader {
            path: &self.path,
            canonical: &self.canonical,
            hierarchy: &self.animated.hierarchy,
            known: &none,
            table: &mut own,
        };
        let read = read(&mut reader);
        // Warnings in the order they arose, among the loader's own.
        self.warnings.append(&mut own.warnings);
        self.own = own;
        read
    }

    /// The pieces of the file's own delivered parts, in order.
    fn delivered_pieces(&self) -> Vec<usize> {
        self.delivered.iter().flat_map(|(_, _, part)| self.part_at(*part).pieces.iter().copied()).collect()
    }

    /// Pose steps of clip `clip` (first played as cycle `name`): from the
    /// shot's `pose_step`, with a warning when that misses `pose_error_max`,
    /// else steps no coarser than [`DEFAULT_POSE_STEP`] whose pose error on
    /// `pieces` is within it (the first count tried that is; a warning when
    /// even [`MAX_STEPS_PER_CYCLE`] is not). Returns (steps, chosen, error at
    /// the tallest agent).
    fn clip_steps(&mut self, pieces: &[usize], clip: usize, name: &str) -> Result<(u32, bool, f32)> {
        let length = self.animated.clips[clip].duration() * self.fps;
        if !(length > 0.0 && length.is_finite()) {
            return Ok((1, self.pose_step.is_none(), 0.0));
        }
        let clip_name = self.animated.clips[clip].name.clone();
        let bound = self.pose_error_max;
        let error = |rig: &Self, steps: u32| {
            let pieces: Vec<&SkinPiece> = pieces.iter().map(|&p| rig.piece(p)).collect();
            rig.clip_error(&pieces, clip, steps) * rig.max_height_scale
        };
        let mm = |m: f32| format!("{:.1} mm", m * 1000.0);
        if let Some(step) = self.pose_step {
            let s = (length / step).round();
            if !(s.is_finite() && s <= MAX_STEPS_PER_CYCLE as f32) {
                return Err(Error::invalid(
                    &self.path,
                    format!(
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
        // A baked clip (a UsdSkel animation) keeps every frame a step, so a
        // still frame is the exact pose the crowd department baked.
        let frames = length.round().max(1.0) as u32;
        let whole = steps.div_ceil(frames) * frames;
        if self.baked && whole != steps && whole <= MAX_STEPS_PER_CYCLE {
            return Ok((whole, true, error(self, whole)));
        }
        Ok((steps, true, e))
    }

    /// The pose error, metres in rig space (before height jitter), of
    /// `pieces` posed on clip `clip` cut into `steps` steps: the largest
    /// vertex distance, at a quarter, half and three quarters of each step,
    /// between the exact pose and the step an agent snaps to (either, at the
    /// half) and the two steps' blend motion blur uses.
    fn clip_error(&self, pieces: &[&SkinPiece], clip: usize, steps: u32) -> f32 {
        let pose = |x: f32| -> Vec<Vec<Vec3>> {
            let joints = self.clip_joints(clip, self.clip_time(clip, steps, x));
            pieces.iter().map(|p| self.skin_positions(p, &joints)).collect()
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

    /// The node a rigid rig's slot names (a node name, or `#node<index>`).
    pub(crate) fn slot_node(&self, slot: &str) -> Result<usize> {
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
            for &p in &self.part_at(*part).pieces {
                let piece = self.piece(p);
                let skin = self.skin_matrices(body, piece, joints);
                for (v, inf) in piece.mesh.positions.iter().zip(&piece.influences) {
                    let y = Self::blend(&skin, inf).transform_point3(*v).y;
                    lo = lo.min(y);
                    hi = hi.max(y);
                }
            }
        }
        (lo, hi)
    }

    /// The rig with its bodies drawn for `[rigs.NAME.proportions]` with the
    /// shot's seed, each one's standing height measured: the last step of
    /// building a shot's character, before it is shared.
    pub(crate) fn with_bodies(mut self, name: &str, spec: &crate::shot::Proportions, seed: u64) -> Result<SkinnedRig> {
        self.bodies = body::draw(&self.path, name, spec, seed, &self.animated.hierarchy)
            .map_err(|e| e.field_prefix(&format!("rigs.{name}")))?;
        for b in 1..=self.body_count() {
            let (lo, hi) = self.rest_span(b);
            if let Some(body) = self.bodies.get_mut(usize::from(b) - 1) {
                body.height = if hi > lo { hi - lo } else { self.height };
            }
        }
        Ok(self)
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
        let meshes: Vec<(usize, Vec<Vec3>)> = pieces
            .iter()
            .map(|&p| (self.piece(p).joint_nodes[0], self.skin_positions(self.piece(p), &joints)))
            .collect();
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
    /// The file canonicalised (parts are keyed by it).
    pub(crate) fn canonical(&self) -> &Path {
        &self.canonical
    }
    /// The node hierarchy: the skeleton parts and props bind to.
    pub(crate) fn hierarchy(&self) -> &crate::casting::animation::Hierarchy {
        &self.animated.hierarchy
    }
    /// The file's own parts and pieces.
    pub(crate) fn own_parts(&self) -> &PartTable {
        &self.own
    }
    /// `rig_from_node` of node `node` in the rest pose (before root-motion removal).
    pub(crate) fn rest_joint(&self, node: usize) -> Affine3A {
        self.joints_at(&self.animated.hierarchy.rest_pose())[node]
    }
    /// Names of the joints of the file's own skins (and the nodes its
    /// joint-attached meshes hang on), in node order: what a prop may hang on.
    /// A rigid rig's props may hang on any named node, as its parts do.
    pub(crate) fn joint_names(&self) -> Vec<&str> {
        if self.rigid {
            return self.animated.hierarchy.nodes.iter().map(|n| n.name.as_str()).filter(|n| !n.is_empty()).collect();
        }
        let mut nodes: Vec<usize> = (self.delivered.iter())
            .flat_map(|(_, _, part)| self.part_at(*part).pieces.iter())
            .flat_map(|&p| self.piece(p).joint_nodes.iter().copied())
            .collect();
        nodes.sort_unstable();
        nodes.dedup();
        nodes.iter().filter_map(|&n| self.animated.hierarchy.nodes.get(n)).map(|n| n.name.as_str()).collect()
    }
    /// A UsdSkel character's material `i` and its base colour texture's
    /// file (`None` for a glTF rig, whose pieces' materials are its file's).
    pub(crate) fn usd_material(&self, i: Option<usize>) -> Option<&(crate::scene::Material, Option<PathBuf>)> {
        self.materials.get(i?)
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
        self.own.part(i).expect("one of the file's own parts")
    }
    /// A piece by index.
    pub fn piece(&self, i: usize) -> &SkinPiece {
        self.own.piece(i).expect("one of the file's own pieces")
    }
    /// How many pieces are loaded (the file's own, then worn parts of other files).
    pub fn piece_count(&self) -> usize {
        self.own.piece_count()
    }
    /// Warnings from loading (weights renormalised, morph targets ignored,
    /// a clip's pose error).
    pub fn warnings(&self) -> &[String] {
        &self.warnings
    }
    /// [`Self::warnings`] a shot prints: those about one clip (its pose
    /// error) only when `plays(clip)`, so a clip no cycle of the shot plays
    /// (a rig's Dance in a shot of walkers) is not warned of.
    pub(crate) fn warnings_played<'a>(
        &'a self,
        plays: impl Fn(usize) -> bool + 'a,
    ) -> impl Iterator<Item = &'a String> {
        self.warnings.iter().enumerate().filter_map(move |(i, w)| {
            match self.clip_warnings.iter().find(|(at, _)| *at == i) {
                Some(&(_, clip)) if !plays(clip) => None,
                _ => Some(w),
            }
        })
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
    fn skin_matrices(&self, body: u16, p: &SkinPiece, joints: &[Affine3A]) -> Vec<Affine3A> {
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

    fn skin_positions(&self, p: &SkinPiece, joints: &[Affine3A]) -> Vec<Vec3> {
        let skin = self.skin_matrices(0, p, joints);
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
        self.pose_skin_piece(body, self.piece(piece), joints, pose)
    }

    /// [`Self::pose_body_piece`] of a piece of this rig's or worn on it
    /// (`crate::casting::worn`).
    pub(crate) fn pose_skin_piece(&self, body: u16, p: &SkinPiece, joints: &[Affine3A], pose: &str) -> Mesh {
        let skin = self.skin_matrices(body, p, joints);
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
    pub(crate) fn pose_error(&self, pieces: &[&SkinPiece], cycle: usize) -> f32 {
        let c = &self.cycles[cycle];
        self.clip_error(pieces, c.clip, c.steps) * self.max_height_scale
    }

    /// The shot's bound on pose error, metres on the tallest agent.
    pub(crate) fn pose_error_max(&self) -> f32 {
        self.pose_error_max
    }
}
