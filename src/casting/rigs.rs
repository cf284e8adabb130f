//! The shot's rigs, loaded once: each a slot rig (rigid parts on nodes) or a
//! character posed from its node animation (skinned, or rigid: meshes riding
//! their nodes), one closed kind per rig so every stage matches on it.

use std::collections::{BTreeMap, BTreeSet};

use crate::casting::kind::is_character_rig;
use crate::casting::rig::Rig;
use crate::casting::skin::SkinnedRig;
use crate::casting::usdskel_rig::SkelFiles;
use crate::casting::wardrobe::Wardrobes;
use crate::casting::worn::WornParts;
use crate::error::{same_file, Error, Result};
use crate::shot::Shot;

/// One rig of the shot.
#[derive(Debug, Clone)]
#[allow(clippy::large_enum_variant, reason = "a shot holds a handful of rigs, each once")]
pub enum ShotRig {
    /// Rigid nodes with part slots (the frankenbot).
    Slots(Rig),
    /// A character posed at shared steps: skinned meshes on a skeleton, or
    /// (`kind = "rigid"`) meshes on animated nodes ([`SkinnedRig::is_rigid`]).
    Skinned(SkinnedRig),
}

impl ShotRig {
    /// Slot names casting fills, in rig order.
    pub(crate) fn slot_names(&self) -> Vec<&str> {
        match self {
            ShotRig::Slots(rig) => rig.slots().iter().map(|s| s.name.as_str()).collect(),
            ShotRig::Skinned(rig) => rig.slots().iter().map(String::as_str).collect(),
        }
    }

    /// Why the rig cannot play cycle `name` (`None`: it can).
    pub(crate) fn lacks_cycle(&self, name: &str) -> Option<Error> {
        match self {
            ShotRig::Slots(rig) => rig.cycle(name).err(),
            ShotRig::Skinned(rig) => rig.cycle_index(name).err(),
        }
    }

    /// Length in frames of cycle `name` (`None` if the rig lacks it).
    pub(crate) fn cycle_frames(&self, name: &str, fps: f32) -> Option<f32> {
        match self {
            ShotRig::Slots(rig) => rig.cycle(name).ok().map(|c| c.frames(fps)),
            ShotRig::Skinned(rig) => rig.cycle_index(name).ok().map(|c| rig.cycle_frames(c)),
        }
    }

    /// Stride in metres of cycle `name` (`None` if the rig lacks it).
    pub(crate) fn cycle_stride(&self, name: &str) -> Option<f32> {
        match self {
            ShotRig::Slots(rig) => rig.cycle(name).ok().map(|c| c.stride()),
            ShotRig::Skinned(rig) => rig.cycle_timing(name).ok().map(|(stride, _)| stride),
        }
    }

    /// The skinned character, for a skinned rig.
    pub(crate) fn skinned(&self) -> Option<&SkinnedRig> {
        match self {
            ShotRig::Skinned(rig) => Some(rig),
            ShotRig::Slots(_) => None,
        }
    }
}

/// Every rig the shot's `[rigs]` names, by name, with its standing height.
#[derive(Debug, Clone, Default)]
pub struct ShotRigs {
    rigs: BTreeMap<String, (ShotRig, f32)>,
    /// What loading noticed but accepted (a slot rig named otherwise in its file).
    warnings: Vec<String>,
}

impl ShotRigs {
    /// Loads every rig of the shot and checks its schemes fill slots it has;
    /// a UsdSkel rig file's reading comes from `usd` (the cache's, when the
    /// cache is that file).
    pub(crate) fn load(shot: &Shot, wardrobes: &Wardrobes, usd: &mut SkelFiles) -> Result<ShotRigs> {
        let mut rigs = BTreeMap::new();
        for (name, r) in &shot.rigs {
            let rig = if is_character_rig(r)? {
                let rig = SkinnedRig::load_shot_rig(name, r, shot.frames.fps, usd)?;
                ShotRig::Skinned(match &r.proportions {
                    Some(p) => rig.with_bodies(name, p, shot.seed)?,
                    None => rig,
                })
            } else if r.proportions.is_some() {
                return Err(Error::invalid(
                    &r.file,
                    "is a slot rig: proportions are for skinned and rigid characters (a slot rig's parts are fitted \
                     to its slots)",
                )
                .field(format!("rigs.{name}.proportions")));
            } else {
                ShotRig::Slots(Rig::load(&r.file).map_err(|e| e.or_field(format!("rigs.{name}.file")))?)
            };
            wardrobes.check_slots(name, &r.schemes, &rig.slot_names(), rig.skinned().is_some())?;
            let joints = rig.skinned().map(SkinnedRig::joint_names);
            wardrobes.check_props(name, &r.schemes, &rig.slot_names(), joints.as_deref())?;
            // Measured once: a slot rig's height poses its rest pose.
            let height = match &rig {
                ShotRig::Slots(rig) => rig.height(),
                ShotRig::Skinned(rig) => rig.height(),
            };
            rigs.insert(name.clone(), (rig, height));
        }
        let mut warnings = shared_files(shot);
        warnings.extend(check_slot_rigs(shot, &rigs)?);
        Ok(ShotRigs { rigs, warnings })
    }

    /// The rig named `name`.
    pub fn get(&self, name: &str) -> Option<&ShotRig> {
        self.rigs.get(name).map(|(rig, _)| rig)
    }

    /// The skinned character named `name` (`None` for a slot rig or no such rig).
    pub(crate) fn skinned(&self, name: &str) -> Option<&SkinnedRig> {
        self.get(name)?.skinned()
    }

    /// Standing height of rig `name` in metres (rest pose, before height jitter).
    pub(crate) fn height(&self, name: &str) -> Option<f32> {
        self.rigs.get(name).map(|&(_, h)| h)
    }

    /// Every rig by name, in name order.
    pub(crate) fn iter(&self) -> impl Iterator<Item = (&str, &ShotRig)> {
        self.rigs.iter().map(|(name, (rig, _))| (name.as_str(), rig))
    }

    /// Whether any rig is a skinned character.
    pub(crate) fn any_skinned(&self) -> bool {
        self.iter().any(|(_, rig)| rig.skinned().is_some())
    }

    /// What loading the rigs noticed but accepted, in rig order, each
    /// skinned rig's followed by what loading its worn parts noticed
    /// (`worn`, the dressing's; empty before dressing). A warning about one
    /// clip (its pose error) is given only when `played` holds (rig, clip):
    /// a clip no cycle of the shot plays is never posed.
    pub(crate) fn warnings<'a>(
        &'a self,
        worn: &'a WornParts,
        played: &'a BTreeSet<(String, usize)>,
    ) -> impl Iterator<Item = &'a String> {
        let skinned =
            (self.iter()).filter_map(|(name, rig)| Some((name, rig.skinned()?))).flat_map(move |(name, r)| {
                r.warnings_played(move |clip| played.contains(&(name.to_string(), clip))).chain(worn.warnings(name))
            });
        self.warnings.iter().chain(skinned)
    }
}

/// One rig file loaded under two or more rig names, of any kind: legal (one
/// character cast under two names, e.g. with other schemes) but surprising,
/// so a warning per name after the first, naming both keys.
fn shared_files(shot: &Shot) -> Vec<String> {
    let rigs: Vec<(&String, &std::path::Path)> = shot.rigs.iter().map(|(n, r)| (n, r.file.as_path())).collect();
    let mut warnings = Vec::new();
    for (i, (name, file)) in rigs.iter().enumerate() {
        if let Some((first, _)) = rigs[..i].iter().find(|(_, f)| same_file(f, file)) {
            warnings.push(format!(
                "{}: field `rigs.{name}.file`: the same file as `rigs.{first}.file`: rigs `{first}` and `{name}` are \
                 one character under two names",
                file.display()
            ));
        }
    }
    warnings
}

/// Checks each slot rig file: proxy boxes far larger than the rest of the
/// rig (a warning), and that it is the rig the shot says it is. A slot
/// rig's file names its rig (its top node); a file that names another rig
/// of this shot, loaded there from another file, is a swap and is refused
/// (both rigs would cast, pose and stride as each other without a word). A
/// name that is no rig of the shot is legal (one file under two names, a
/// renamed rig) but surprising: a warning. Skinned characters' files carry
/// no rig name; their clips and joints are checked as they load.
fn check_slot_rigs(shot: &Shot, rigs: &BTreeMap<String, (ShotRig, f32)>) -> Result<Vec<String>> {
    let mut warnings = Vec::new();
    for (name, (rig, _)) in rigs {
        let ShotRig::Slots(rig) = rig else { continue };
        for (slot, side, median) in rig.oversized_slots() {
            warnings.push(format!(
                "{}: field `rigs.{name}.file`: slot `{}`'s proxy box is {side:.3} m across, more than {} times \
                 the rig's median slot ({median:.3} m): is it in the wrong units?",
                shot.rigs[name].file.display(),
                slot.name,
                crate::casting::rig::OVERSIZED_PROXY
            ));
        }
        let Some(in_file) = rig.name_in_file().filter(|n| n != name) else { continue };
        let file = &shot.rigs[name].file;
        match shot.rigs.get(in_file) {
            Some(other) if !same_file(&other.file, file) => {
                return Err(Error::invalid(
                    file,
                    format!(
                        "this file is rig `{in_file}` (its top node), which the shot loads for `rigs.{in_file}` from {}; \
                         rig `{name}` would cast and walk as `{in_file}`: are the two files swapped?",
                        other.file.display()
                    ),
                )
                .field(format!("rigs.{name}.file")));
            }
            Some(_) => {}
            None => warnings.push(format!(
                "{}: field `rigs.{name}.file`: the file names its rig `{in_file}` (its top node), not `{name}`",
                file.display()
            )),
        }
    }
    Ok(warnings)
}
