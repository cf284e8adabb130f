//! The cast shot: the shot and its cache with the three stages built from
//! them, each by one function and immutable afterwards, and any frame's
//! posed instances.
//!
//! 1. Casting ([`Casting::cast`]): who wears what, every agent of the shot's frames.
//! 2. Dressing ([`Dressing::dress`]): the rigid parts or skinned pieces each agent wears.
//! 3. The pose library ([`PoseLibrary`]): every mesh, material and texture,
//!    and every skinned pose step the shot's frames take (and, when built
//!    for a shutter, the shutter's steps), in a colourspace its type records.
//!
//! A slot-rig agent's part transform at a frame is
//! `world_from_agent (position, heading, height scale about the foot pivot)
//!  x rig_from_slot (the rig node at that cycle frame)
//!  x slot_from_part (the part's fit to its proxy box)`.
//! A skinned agent is `world_from_agent x` its meshes posed at the pose step
//! nearest its cycle frame (`casting::skin`); every pose step is posed once
//! and shared by every agent, frame and layer on it.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use glam::{Affine3A, Quat, Vec3};

use crate::cache::usdskel::SkelAgent;
use crate::cache::{AgentSample, CacheReader, FrameBlock};
use crate::casting::cast::{AgentCast, Casting};
use crate::casting::dressing::{AgentDress, Dressing};
use crate::casting::poses::{PoseLibrary, PosedSkins};
use crate::casting::rigs::{ShotRig, ShotRigs};
use crate::casting::timing::{cycle_name, CycleTiming};
use crate::casting::usdskel_rig::SkelFiles;
use crate::casting::wardrobe::Wardrobes;
use crate::error::{Error, Result};
use crate::scene::dome::load_dome;
use crate::scene::gltf::AssetCache;
use crate::scene::light_gains;
use crate::scene::lights::{Dome, Light, LightKind, SceneLights};
use crate::scene::passes::LightGroups;
use crate::scene::{vis, Camera, Instance, InstanceAgent, Library, Material, Rec709, Space, Texture};
use crate::shot::DomeSpec;
use crate::shot::Shot;

/// Level of detail an agent renders at.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Lod {
    /// Real wardrobe parts.
    Full,
    /// The rig's proxy boxes, wearing the same materials as the full agent.
    Proxy,
}

/// An agent posed at one frame.
#[derive(Debug, Clone)]
pub enum AgentPose {
    /// A slot rig: `world_from_slot` for every rig slot.
    Slots(Vec<Affine3A>),
    /// A skinned character: where it stands and the pose step it plays.
    Skinned {
        /// World from rig space (position, heading, height scale).
        world_from_rig: Affine3A,
        /// The agent's body (`casting::body`; 0 as modelled).
        body: u16,
        /// Cycle index in the skinned rig.
        cycle: usize,
        /// Pose step of that cycle.
        step: u32,
    },
}

/// The set's instances (agent `None`), fully visible, and the names
/// Cryptomatte gives its objects.
#[derive(Debug, Default)]
struct ShotSet {
    /// Each one's `part` indexes `names`.
    instances: Vec<Instance>,
    /// Unique names of the set's objects (its glTF nodes with a mesh).
    names: Vec<String>,
}

impl ShotSet {
    /// Loads the shot's set file into `assets` (nothing without one).
    fn load(shot: &Shot, assets: &mut AssetCache, warnings: &mut Vec<String>) -> Result<ShotSet> {
        let Some(s) = &shot.set else { return Ok(ShotSet::default()) };
        let (placed, mut names) = assets.load_scene_objects(&s.file)?;
        if names.len() > SET_OBJECTS_NAMED {
            warnings.push(format!(
                "set {} has {} objects: Cryptomatte names the first {SET_OBJECTS_NAMED} and calls the rest `set`",
                s.file.display(),
                names.len()
            ));
            names.truncate(SET_OBJECTS_NAMED);
        }
        let instances = placed
            .into_iter()
            .map(|(mesh, material, world_from_object, object)| Instance {
                mesh,
                material,
                world_from_object,
                agent: InstanceAgent::NONE,
                // Past the names: u16::MAX, which no name has.
                part: u16::try_from(object).unwrap_or(u16::MAX),
                visibility: vis::ALL,
            })
            .collect();
        Ok(ShotSet { instances, names })
    }
}

/// The shot cast, dressed and posed, with library colours in the space `C`
/// (as authored, [`Rec709`], unless converted for the render by
/// [`crate::render::colour::into_acescg`]).
pub struct ShotCrowd<C = Rec709> {
    shot: Shot,
    cache: CacheReader,
    rigs: ShotRigs,
    casting: Casting,
    dressing: Dressing,
    poses: PoseLibrary<C>,
    /// The cycle frames agents play where their stride is not the cache's.
    timing: CycleTiming,
    set: ShotSet,
    /// What loading noticed but accepted (weights renormalised, morph targets ignored).
    warnings: Vec<String>,
    /// The camera from a glTF node, when the shot names one instead of keys.
    gltf_camera: Option<Camera>,
    /// The dome's pixels (read once), and the set glTF's own lights.
    lights: LoadedLights,
    /// The wardrobes' part files and textures (`input_files`).
    wardrobe_files: Vec<(String, PathBuf)>,
    /// Each material's emission as authored, kept once the shot's
    /// light-group gains scaled it (so another gain starts from it).
    authored_emission: Option<Vec<Vec3>>,
    /// A UsdSkel cache's agents (prims, skeleton, animation) from the one
    /// reading its rigs shared (`None`: not a UsdSkel cache, or not kept).
    usd_agents: Option<Vec<SkelAgent>>,
}

/// Refuses a name in the shot's lists that names nothing (a typo would
/// otherwise be accepted without a word): a `culled_cycles` entry that is
/// no cycle of the cache, an `exclude_parts` entry that is no part mesh of
/// any wardrobe scheme, a `removed` id that is no agent of the shot's frames,
/// a `no_scale_cycles` entry that is neither a cycle of the cache nor one any
/// rig of the shot can play (a shot may list a seated cycle its cache does
/// not use yet, as the demo's generator does).
fn check_shot_lists(
    shot: &Shot,
    cache: &CacheReader,
    rigs: &ShotRigs,
    wardrobes: &crate::casting::wardrobe::Wardrobes,
    casting: &crate::casting::cast::Casting,
) -> Result<()> {
    let bad = |key: String, msg: String| Err(crate::error::Error::invalid(&shot.path, msg).field(key));
    let cycles = cache.cycles();
    for (i, c) in shot.culled_cycles.iter().enumerate() {
        if !cycles.contains(c) {
            return bad(
                format!("culled_cycles[{i}]"),
                format!("`{c}` is no cycle of the cache (its cycles: {})", cycles.join(", ")),
            );
        }
    }
    for (i, c) in shot.no_scale_cycles.iter().enumerate() {
        if !cycles.contains(c) && rigs.iter().all(|(_, rig)| rig.lacks_cycle(c).is_some()) {
            return bad(
                format!("no_scale_cycles[{i}]"),
                format!("`{c}` is no cycle of the cache ({}) or of any rig of the shot", cycles.join(", ")),
            );
        }
    }
    let meshes: std::collections::BTreeSet<&str> =
        wardrobes.schemes.values().flat_map(|s| s.parts.iter().map(|p| &*p.mesh)).collect();
    for (i, m) in shot.exclude_parts.iter().enumerate() {
        if !meshes.contains(m.as_str()) {
            return bad(format!("exclude_parts[{i}]"), format!("`{m}` is no part mesh of the shot's wardrobes"));
        }
    }
    for (i, id) in shot.removed.iter().enumerate() {
        if casting.get(*id).is_none() {
            return bad(format!("removed[{i}]"), format!("agent {id} is in none of the shot's frames of the cache"));
        }
    }
    Ok(())
}

/// The lights that come from files: the dome's map and the set's
/// KHR_lights_punctual lights. The shot's own are read from it as asked.
#[derive(Debug, Clone, Default)]
struct LoadedLights {
    dome: Option<Arc<Dome>>,
    set: Vec<Light>,
}

impl LoadedLights {
    fn load(shot: &Shot, assets: &mut AssetCache) -> Result<LoadedLights> {
        let dome = match &shot.lights.dome {
            Some(d) => Some(Arc::new(
                load_dome(&d.file, d.scale, d.rotate, d.camera_visible).map_err(|e| e.or_field("lights.dome.file"))?,
            )),
            None => None,
        };
        let set = match &shot.set {
            Some(s) => assets.punctual_lights(&s.file).map_err(|e| e.or_field("set.file"))?,
            None => Vec::new(),
        };
        Ok(LoadedLights { dome, set })
    }

    /// The dome as `spec` now asks: the same map turned, scaled or hidden
    /// anew without reading it again; another file is read.
    fn refresh_dome(&mut self, spec: Option<&DomeSpec>) -> Result<()> {
        self.dome = match (spec, self.dome.take()) {
            (None, _) => None,
            (Some(d), Some(old)) if old.file == d.file => {
                if (old.scale, old.rotate, old.camera_visible) == (d.scale, d.rotate, d.camera_visible) {
                    Some(old)
                } else {
                    let mut dome = Arc::unwrap_or_clone(old);
                    (dome.scale, dome.rotate, dome.camera_visible) = (d.scale, d.rotate, d.camera_visible);
                    Some(Arc::new(dome))
                }
            }
            (Some(d), _) => Some(Arc::new(
                load_dome(&d.file, d.scale, d.rotate, d.camera_visible).map_err(|e| e.or_field("lights.dome.file"))?,
            )),
        };
        Ok(())
    }
}

/// Set objects with their own Cryptomatte name: every [`Instance::part`]
/// value but `u16::MAX` (which marks the unnamed rest).
pub(crate) const SET_OBJECTS_NAMED: usize = u16::MAX as usize;

/// The (rig, clip) pairs that pose steps play: a clip's warnings (its pose
/// error) are given only for these.
fn played_clips(rigs: &ShotRigs, steps: &BTreeSet<crate::casting::cast::PoseStep>) -> BTreeSet<(String, usize)> {
    steps
        .iter()
        .filter_map(|(rig, _, cycle, _)| Some((rig.to_string(), rigs.skinned(rig)?.cycles().get(*cycle)?.clip)))
        .collect()
}

impl ShotCrowd {
    /// Loads the shot and everything it names, and casts every agent that
    /// appears in the shot's frame range, posed for still frames.
    pub fn load(shot_path: &Path) -> Result<ShotCrowd> {
        ShotCrowd::open(Shot::load(shot_path)?, None)
    }

    /// Opens the shot's cache and casts it, posed for still frames and,
    /// with `shutter` (frames relative to each frame), for that shutter.
    pub fn open(shot: Shot, shutter: Option<[f32; 2]>) -> Result<ShotCrowd> {
        let (cache, usd) = crate::casting::shot_cache::open_for_rigs(&shot)?;
        ShotCrowd::new_reading(shot, cache, usd, shutter)
    }

    /// Casts a shot against an already opened cache (tests use this to
    /// remove or reorder agents without writing files), posed for still
    /// frames and, with `shutter`, for that shutter.
    pub fn new(shot: Shot, cache: CacheReader, shutter: Option<[f32; 2]>) -> Result<ShotCrowd> {
        ShotCrowd::new_reading(shot, cache, SkelFiles::default(), shutter)
    }

    /// [`ShotCrowd::new`], UsdSkel rig files' readings taken from `usd`
    /// (the cache's own, when the cache is such a file).
    fn new_reading(shot: Shot, cache: CacheReader, mut usd: SkelFiles, shutter: Option<[f32; 2]>) -> Result<ShotCrowd> {
        let wardrobes = Wardrobes::load(&shot.wardrobes)?;
        let rigs = ShotRigs::load(&shot, &wardrobes, &mut usd)?;
        let usd_agents = usd.take(&shot.cache.path).map(|f| f.agents);
        drop(usd);
        let cast = Casting::cast(&shot, &cache, &rigs, &wardrobes)?;
        let (casting, mut warnings) = (cast.casting, cast.warnings);
        check_shot_lists(&shot, &cache, &rigs, &wardrobes, &casting)?;
        let mut assets = AssetCache::new();
        crate::casting::dressing::check_schemes(&shot, &rigs, &wardrobes, &mut assets)?;
        let dressing = Dressing::dress(&casting, &rigs, &wardrobes, &mut assets)?;
        let worn = dressing.worn_pieces(&casting);
        let timing = CycleTiming::new(&shot, &cache, &casting, &rigs)?;
        let mut skins = PosedSkins::default();
        let still = crate::casting::steps::still_steps(&shot, &cache, &casting, &rigs, &timing)?;
        skins.pose(&still, &worn, (&rigs, &dressing), &mut assets);
        let mut played = played_clips(&rigs, &still);
        let set = ShotSet::load(&shot, &mut assets, &mut warnings)?;
        let lights = LoadedLights::load(&shot, &mut assets)?;
        let gltf_camera = match &shot.camera.gltf {
            Some((file, node)) => Some(assets.find_camera(file, node)?),
            None => None,
        };
        // The shutter's steps last, so every other mesh has the same id
        // whether the shot is posed for a shutter or not.
        if let Some(shutter) = shutter {
            if rigs.any_skinned() {
                let steps = crate::casting::steps::shutter_steps(&shot, &cache, &casting, &rigs, &timing, shutter)?;
                skins.pose(&steps, &worn, (&rigs, &dressing), &mut assets);
                played.extend(played_clips(&rigs, &steps));
            }
        }
        warnings.extend(rigs.warnings(dressing.worn(), &played).cloned());
        // A scheme of no parts is legal (every slot left empty) but dresses its agents in nothing.
        for (name, r) in &shot.rigs {
            for (scheme, _) in r.schemes.iter().filter(|(_, w)| **w > 0.0) {
                if let Some(s) = wardrobes.schemes.get(scheme).filter(|s| s.parts.is_empty()) {
                    warnings.push(format!(
                        "{}: field `schemes.{scheme}`: the scheme has no parts, so the agents of rig `{name}` cast in \
                         it wear nothing",
                        s.source.display()
                    ));
                }
            }
        }
        let poses = PoseLibrary::new(assets, skins, shutter);
        let wardrobe_files = wardrobes.input_files();
        let crowd = ShotCrowd {
            shot,
            cache,
            rigs,
            casting,
            dressing,
            poses,
            timing,
            set,
            warnings,
            gltf_camera,
            lights,
            wardrobe_files,
            authored_emission: None,
            usd_agents,
        };
        crowd.with_gains()
    }

    /// The shot's light-group gains applied to the dome's scale and the
    /// materials' emission (the other lights take theirs in [`Self::lights`]).
    /// A crowd whose shot never had gains is left untouched.
    fn with_gains(mut self) -> Result<ShotCrowd> {
        if self.shot.lights.gains.is_empty() && self.authored_emission.is_none() {
            return Ok(self);
        }
        let authored = match self.authored_emission.take() {
            Some(a) => a,
            None => self.library().materials.iter().map(|m| m.emission).collect(),
        };
        let groups = LightGroups::with_emission(&self.unscaled_lights(), self.library(), &authored)?;
        let factors = light_gains::factors(&self.shot.lights.gains, &groups, &self.shot.path)?;
        if let (Some(dome), Some(spec)) = (&mut self.lights.dome, &self.shot.lights.dome) {
            let f = factors.get(groups.environment() as usize).copied().unwrap_or(Vec3::ONE);
            if dome.scale != spec.scale * f {
                Arc::make_mut(dome).scale = spec.scale * f;
            }
        }
        light_gains::apply_to_materials(self.poses.materials_mut(), &authored, &groups, &factors);
        self.authored_emission = Some(authored);
        Ok(self)
    }

    /// The same cast shot with `edit` applied to its shot, for what later
    /// stages read of it (a render's seed and lights, removed agents):
    /// casting, dressing and poses stay as they were built. The dome
    /// follows the edited `[lights.dome]` (a new file is read, hence the
    /// `Result`).
    pub fn with_shot(mut self, edit: impl FnOnce(&mut Shot)) -> Result<ShotCrowd> {
        edit(&mut self.shot);
        self.lights.refresh_dome(self.shot.lights.dome.as_ref())?;
        self.with_gains()
    }

    /// The same cast shot with its library's colours converted by `convert`
    /// into the space `D` (what [`crate::render::colour::into_acescg`] does).
    pub(crate) fn convert_colours<D: Space>(
        self,
        convert: impl FnOnce(&mut [Material], &mut [Texture]),
    ) -> ShotCrowd<D> {
        let ShotCrowd {
            shot,
            cache,
            rigs,
            casting,
            dressing,
            poses,
            timing,
            set,
            warnings,
            gltf_camera,
            lights,
            wardrobe_files,
            authored_emission,
            usd_agents,
        } = self;
        let poses = poses.convert(convert);
        ShotCrowd {
            shot,
            cache,
            rigs,
            casting,
            dressing,
            poses,
            timing,
            set,
            warnings,
            gltf_camera,
            lights,
            wardrobe_files,
            authored_emission,
            usd_agents,
        }
    }
}

impl<C> ShotCrowd<C> {
    /// Every file the cast shot was read from, as the shot or its
    /// wardrobes name it: the shot's own ([`Shot::input_files`]), then each
    /// wardrobe part file and texture. What no output may be
    /// ([`crate::output::InputFiles`]).
    pub fn input_files(&self) -> Vec<(String, PathBuf)> {
        let mut out = self.shot.input_files();
        out.extend(self.wardrobe_files.iter().cloned());
        out
    }

    /// The shot.
    pub fn shot(&self) -> &Shot {
        &self.shot
    }

    /// The simulation cache.
    pub fn cache(&self) -> &CacheReader {
        &self.cache
    }

    /// A UsdSkel cache's agents as the shot read them (`None`: another
    /// cache, or a crowd cast over a cache opened elsewhere).
    pub(crate) fn usd_agents(&self) -> Option<&[SkelAgent]> {
        self.usd_agents.as_deref()
    }

    /// The shot's rigs.
    pub fn rigs(&self) -> &ShotRigs {
        &self.rigs
    }

    /// Who wears what: every agent that appears in the shot's frames.
    pub fn casting(&self) -> &Casting {
        &self.casting
    }

    /// Agent `id`'s cast (`None`: it is not in the shot's frames).
    pub fn cast(&self, id: u32) -> Option<&AgentCast> {
        self.casting.get(id)
    }

    /// What each agent wears.
    pub fn dressing(&self) -> &Dressing {
        &self.dressing
    }

    /// The meshes, materials and posed steps.
    pub fn poses(&self) -> &PoseLibrary<C> {
        &self.poses
    }

    /// Every light of the shot, as authored (linear Rec.709) x its light
    /// group's gain (`[lights.gains]`): the sun, the
    /// sky, the dome, the shot's local lights, then the set glTF's.
    pub fn lights(&self) -> SceneLights {
        let mut lights = self.unscaled_lights();
        if !self.shot.lights.gains.is_empty() {
            // Checked when the crowd was made (with_gains): no error here.
            if let Ok(groups) = self.light_groups() {
                if let Ok(f) = light_gains::factors(&self.shot.lights.gains, &groups, &self.shot.path) {
                    light_gains::apply_to_lights(&mut lights, &groups, &f);
                }
            }
        }
        lights
    }

    /// The shot's light groups: its lights' and its emissive materials',
    /// judged by the emission as authored, so a group the gains turn off
    /// (gain 0) stays a group (its pass black, its gain still valid).
    pub fn light_groups(&self) -> Result<LightGroups> {
        match &self.authored_emission {
            Some(authored) => LightGroups::with_emission(&self.unscaled_lights(), self.library(), authored),
            None => LightGroups::new(&self.unscaled_lights(), self.library()),
        }
    }

    /// [`Self::lights`] before the shot's light-group gains (the dome has its gain).
    fn unscaled_lights(&self) -> SceneLights {
        let l = &self.shot.lights;
        let mut local = l.local.clone();
        // The shot's sun is the sun: the set's directional lights light the
        // shot only when it has none (docs/lights.md).
        let set_sun = l.sun.is_none();
        local.extend(
            self.lights.set.iter().filter(|s| set_sun || !matches!(s.kind, LightKind::Distant { .. })).cloned(),
        );
        SceneLights { sun: l.sun(), sky: l.sky(), dome: self.lights.dome.clone(), local, groups: l.groups.clone() }
    }

    /// The shared meshes, materials and textures.
    pub fn library(&self) -> &Library {
        self.poses.library()
    }

    /// The set's instances (agent `None`), fully visible; each one's `part`
    /// indexes [`ShotCrowd::set_names`].
    pub(crate) fn set(&self) -> &[Instance] {
        &self.set.instances
    }

    /// Unique names of the set's objects (its glTF nodes with a mesh, by
    /// [`crate::scene::gltf::set_object_names`]): Cryptomatte's `set/<name>`.
    /// At most [`SET_OBJECTS_NAMED`]; later objects are plain `set`.
    pub(crate) fn set_names(&self) -> &[String] {
        &self.set.names
    }

    /// What loading noticed but accepted (weights renormalised, morph targets ignored).
    pub fn warnings(&self) -> &[String] {
        &self.warnings
    }

    /// The cache frame block at a shot frame (empty if the cache has no such frame).
    pub fn agents_at(&self, shot_frame: i32) -> Result<FrameBlock> {
        let cf = self.shot.cache.cache_frame(shot_frame);
        if self.cache.frames().binary_search(&cf).is_err() {
            return Ok(FrameBlock { frame: cf, agents: Vec::new() });
        }
        self.timing.read(&self.cache, cf)
    }

    /// The cycle frames agents play where their stride is not the cache's.
    pub(crate) fn timing(&self) -> &CycleTiming {
        &self.timing
    }

    /// Only the cache frames the shot reads (they keep their cache numbers),
    /// without reading the rest of a long simulation.
    pub(crate) fn shot_crowd(&self) -> Result<crate::cache::CrowdCache> {
        let mut frames = Vec::new();
        for f in self.shot.frames.iter() {
            let cf = self.shot.cache.cache_frame(f);
            if self.cache.frames().binary_search(&cf).is_ok() {
                frames.push(self.cache.read_frame(cf)?);
            }
        }
        Ok(crate::cache::CrowdCache { rigs: self.cache.rigs().to_vec(), cycles: self.cache.cycles().to_vec(), frames })
    }

    /// Name of a cycle index.
    pub fn cycle_name(&self, a: &AgentSample) -> &str {
        cycle_name(&self.cache, a)
    }

    /// Agent to world: foot position, heading about +Y, height scale about the foot pivot.
    pub(crate) fn world_from_agent(&self, a: &AgentSample) -> Affine3A {
        let h = self.casting.get(a.id).map_or(1.0, |c| c.height_scale);
        Affine3A::from_scale_rotation_translation(Vec3::splat(h), Quat::from_rotation_y(a.heading), a.position)
    }

    /// An agent's standing height in metres: its rig's height times its
    /// height scale (`None` for an agent that was not cast).
    pub(crate) fn agent_height(&self, id: u32) -> Option<f32> {
        let cast = self.casting.get(id)?;
        let height = match self.rigs.skinned(&cast.rig) {
            Some(rig) => rig.body_height(cast.body),
            None => self.rigs.height(&cast.rig)?,
        };
        Some(height * cast.height_scale)
    }

    /// Whether an agent record is rendered at all (not removed, hidden or on a culled cycle).
    pub fn renders(&self, a: &AgentSample) -> bool {
        !a.hidden()
            && !self.shot.removed.contains(&a.id)
            && !self.shot.culled_cycles.iter().any(|c| c == self.cycle_name(a))
    }

    /// An agent posed at its cycle frame: its slots' world transforms (slot
    /// rigs) or its placement and pose step (skinned characters).
    pub fn agent_pose(&self, a: &AgentSample) -> Result<AgentPose> {
        let not_cast =
            || Error::invalid(&self.shot.cache.path, "agent was not cast (not in the shot's frames)").agent(a.id);
        let cast = self.casting.get(a.id).ok_or_else(not_cast)?;
        let world_from_agent = self.world_from_agent(a);
        let rig_err = |e: Error| Error::invalid(&self.shot.cache.path, format!("rig `{}`: {e}", cast.rig)).agent(a.id);
        match self.rigs.get(&cast.rig).ok_or_else(not_cast)? {
            ShotRig::Skinned(rig) => {
                let cycle = rig.cycle_index(self.cycle_name(a)).map_err(rig_err)?;
                Ok(AgentPose::Skinned {
                    world_from_rig: world_from_agent,
                    body: cast.body,
                    cycle,
                    step: rig.step_of(cycle, a.cycle_frame),
                })
            }
            ShotRig::Slots(rig) => {
                let cycle = rig.cycle(self.cycle_name(a)).map_err(rig_err)?;
                let pose = cycle.sample(a.cycle_frame, self.shot.frames.fps);
                Ok(AgentPose::Slots(pose.slot_transforms().into_iter().map(|(_, m)| world_from_agent * m).collect()))
            }
        }
    }

    /// The instances of one agent at a frame: its parts, or its proxy boxes
    /// wearing the same materials.
    pub fn agent_instances(&self, a: &AgentSample, lod: Lod, visibility: u8, out: &mut Vec<Instance>) -> Result<()> {
        let pose = self.agent_pose(a)?;
        self.posed_instances(a.id, &pose, lod, visibility, out);
        Ok(())
    }

    /// How many instances [`ShotCrowd::posed_instances`] gives agent `id`
    /// at `lod` in any pose (at most: a skinned step not posed gives none),
    /// so a frame's instance list is allocated once (at a million agents its
    /// doublings cost a gigabyte) and a layer budget counts what it traces.
    pub fn instance_count(&self, id: u32, lod: Lod) -> usize {
        self.dressing.instance_count(id, lod, &self.rigs, &self.casting)
    }

    /// As [`ShotCrowd::agent_instances`], from a pose already computed (a
    /// render poses each agent once per frame, not once per layer).
    pub(crate) fn posed_instances(&self, id: u32, pose: &AgentPose, lod: Lod, visibility: u8, out: &mut Vec<Instance>) {
        let instance = |mesh, material, world_from_object, part: usize| Instance {
            mesh,
            material,
            world_from_object,
            agent: InstanceAgent::some(id),
            part: part as u16,
            visibility,
        };
        match pose {
            AgentPose::Slots(slots) => {
                let Some(AgentDress::Slots(parts)) = self.dressing.get(id) else { return };
                let proxy_mesh = self.dressing.proxy_mesh();
                for p in parts {
                    let (slot, fit, part) = (p.slot as usize, self.dressing.fit(p.fit), p.part as usize);
                    let world_from_slot = slots[slot];
                    match lod {
                        Lod::Full => out.push(instance(p.mesh, p.material, world_from_slot * fit.slot_from_part, part)),
                        Lod::Proxy if p.proxy => {
                            out.push(instance(proxy_mesh, p.material, world_from_slot * fit.slot_from_proxy, part))
                        }
                        Lod::Proxy => {}
                    }
                }
            }
            &AgentPose::Skinned { world_from_rig, body, cycle, step } => {
                let Some(cast) = self.casting.get(id) else { return };
                let Some(rig) = self.rigs.skinned(&cast.rig) else { return };
                let Some(AgentDress::Skinned(pieces)) = self.dressing.get(id) else { return };
                let skins = self.poses.skins();
                for d in pieces {
                    match lod {
                        Lod::Full => {
                            // Every step the shot's frames (and shutter) take was posed at load.
                            if let Some(mesh) = skins.mesh(&cast.rig, d.piece, body, cycle, step) {
                                out.push(instance(mesh, d.material, world_from_rig, d.slot));
                            }
                        }
                        Lod::Proxy => {
                            let Some(joints) = skins.joints(&cast.rig, body, cycle, step) else {
                                continue;
                            };
                            let piece = self.dressing.piece(&cast.rig, rig, d.piece);
                            for (j, b) in piece.joint_boxes.iter().enumerate() {
                                let Some((lo, hi)) = *b else { continue };
                                let size = (hi - lo).max(Vec3::splat(1e-4));
                                let box_from_cube = Affine3A::from_scale_rotation_translation(size, Quat::IDENTITY, lo);
                                let node = piece.joint_nodes[j];
                                let bone = if piece.proportioned { rig.bone(body, node) } else { Affine3A::IDENTITY };
                                let world = world_from_rig * joints[node] * bone * box_from_cube;
                                out.push(instance(self.dressing.proxy_mesh(), d.material, world, d.slot));
                            }
                        }
                    }
                }
            }
        }
    }

    /// The name of part `part` (a cast slot, or a prop after them) of an
    /// agent, for Cryptomatte and export node names.
    pub(crate) fn slot_name(&self, id: u32, part: u16) -> Option<&str> {
        self.casting.get(id)?.part_name(part)
    }

    /// The pose key a skinned agent plays at a frame: `<rig>[/body<b>]/<cycle>/<step>of<steps>`.
    pub(crate) fn pose_key(&self, a: &AgentSample) -> Option<String> {
        let cast = self.casting.get(a.id)?;
        let rig = self.rigs.skinned(&cast.rig)?;
        let cycle = rig.cycle_index(self.cycle_name(a)).ok()?;
        let pose = rig.pose_name(cycle, rig.step_of(cycle, a.cycle_frame));
        Some(match cast.body {
            0 => format!("{}/{pose}", cast.rig),
            b => format!("{}/body{b}/{pose}", cast.rig),
        })
    }

    /// Every rendered agent at a shot frame, fully visible, at `lod(agent id)`.
    pub fn frame_instances(&self, shot_frame: i32, lod: impl Fn(u32) -> Lod) -> Result<Vec<Instance>> {
        let block = self.agents_at(shot_frame)?;
        let mut out = Vec::new();
        for a in block.agents.iter().filter(|a| self.renders(a)) {
            self.agent_instances(a, lod(a.id), vis::ALL, &mut out)?;
        }
        Ok(out)
    }

    /// The camera at a shot frame.
    pub fn camera(&self, shot_frame: i32) -> Result<Camera> {
        if let Some(c) = self.shot.keyed_camera(shot_frame as f32) {
            return Ok(c);
        }
        self.gltf_camera.ok_or_else(|| Error::invalid(&self.shot.path, "no camera").field("camera"))
    }
}
