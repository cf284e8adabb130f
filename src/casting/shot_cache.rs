//! Opening a shot's cache as its `[cache]` table says: raw trajectory tables
//! are imported at the shot's frame rate, and every import (tables and
//! JuPedSim files alike) walks at the stride of the shot's own rigs, so feet
//! do not slide. This is the only place the cache stage meets rig files for
//! a shot; `cache` itself never loads rigs.

use std::collections::BTreeMap;
use std::path::Path;

use crate::cache::jupedsim::{RigClip, SHOT_FPS};
use crate::cache::tabular::Gait;
use crate::cache::{CacheReader, Format, Import, ImportOptions, TabularOptions};
use crate::casting::gait::{skinned_file_gait, skinned_gait};
use crate::casting::kind::{is_character_import, is_character_rig};
use crate::casting::rig::Rig;
use crate::casting::skin::SkinnedRig;
use crate::casting::usdskel_rig::SkelFiles;
use crate::error::{same_file, Error, Result};
use crate::shot::{Shot, SkinOptions};

/// A rig's gait from its glTF: the walk cycle's stride and length, and the
/// idle cycle's length (frames at 24 fps, the unit of cycle frames). A walk
/// cycle whose root does not travel is refused (it would never advance).
pub fn gait(file: &Path, walk: &str, idle: Option<&str>) -> Result<Gait> {
    slot_gait(file, walk, idle, None)
}

/// [`gait`], with `stride` (when given) in place of the walk's root travel.
fn slot_gait(file: &Path, walk: &str, idle: Option<&str>, stride: Option<f32>) -> Result<Gait> {
    let rig = Rig::load(file)?;
    let c = rig.cycle(walk).map_err(|e| e.field("cycle"))?;
    let (stride, cycle_length) = (stride.unwrap_or(c.stride()), c.frames(SHOT_FPS));
    if !(stride.is_finite() && stride > 0.0 && cycle_length.is_finite() && cycle_length > 0.0) {
        return Err(Error::invalid(
            file,
            format!("cycle `{walk}` walks {stride} m in {cycle_length} frames; name a walk cycle"),
        )
        .field("cycle"));
    }
    let idle_length = match idle {
        Some(name) => {
            let len = rig.cycle(name).map_err(|e| e.field("idle_cycle"))?.frames(SHOT_FPS);
            if !(len.is_finite() && len > 0.0) {
                return Err(
                    Error::invalid(file, format!("idle cycle `{name}` is {len} frames long")).field("idle_cycle")
                );
            }
            len
        }
        None => Gait::default().idle_length,
    };
    Ok(Gait { stride, cycle_length, idle_length })
}

/// A rig file's gait outside a shot (a trajectory import's `rig_file`): a
/// slot rig's as [`gait`] reads it, or a skinned character's with `skin`
/// (its `[rigs.X]` options: root joint, cycle -> clip map, strides, scale,
/// axes), as the shot's skinned rigs walk; a rigid one (no skin) likewise,
/// its stride from its wheels where it has them. `skin` `None` detects the
/// kind; a detected character takes the default options (each clip is a cycle
/// of its own name; no root joint, so its walk needs `root`, wheels or a
/// stride). A `stride` given is the walk's (for a character, its `strides`
/// entry).
pub fn file_gait(
    file: &Path,
    skin: Option<&SkinOptions>,
    walk: &str,
    idle: Option<&str>,
    stride: Option<f32>,
) -> Result<Gait> {
    match is_character_import(file, skin)? {
        true => skinned_file_gait(file, skin, walk, idle, stride),
        false => slot_gait(file, walk, idle, stride),
    }
}

/// How the shot's cache becomes a crowd: the `[cache]` keys over their
/// preset, at the shot's fps, with the gaits of the shot's rigs.
pub(crate) fn shot_import(shot: &Shot) -> Result<Import> {
    let spec = &shot.cache.import;
    let path = &shot.cache.path;
    let key_err = |(k, m): (String, String)| Error::invalid(&shot.path, m).field(format!("cache.{k}"));
    let format = Format::of(path)?;
    let walk = spec.cycle.clone().unwrap_or_else(|| ImportOptions::default().cycle);
    let rig = spec.rig.clone().unwrap_or_else(|| ImportOptions::default().rig);
    let gaits = |walk: &str| -> Result<BTreeMap<String, Gait>> {
        let mut out = BTreeMap::new();
        for (name, r) in &shot.rigs {
            if is_character_rig(r)? {
                let rig = SkinnedRig::load_shot_rig(name, r, SHOT_FPS, &mut SkelFiles::default())?;
                if let Some(g) = skinned_gait(&rig, walk, spec.idle_cycle.as_deref())? {
                    out.insert(name.clone(), g);
                }
                continue;
            }
            // A rig without the walk cycle is only an error if an agent uses it.
            if Rig::load(&r.file)?.cycle(walk).is_ok() {
                out.insert(name.clone(), gait(&r.file, walk, spec.idle_cycle.as_deref())?);
            }
        }
        Ok(out)
    };
    let tabular = matches!(format, Format::Tabular) || (format == Format::Csv && spec.describes_layout());
    if tabular {
        if !spec.describes_layout() {
            return Err(crate::cache::needs_layout(path));
        }
        let mut o = TabularOptions::resolve(spec, shot.frames.fps).map_err(key_err)?;
        o.gaits = gaits(&o.cycle)?;
        return Ok(Import { tabular: Some(o), ..Default::default() });
    }
    // A refusal names the shot's key (`cache.turn_rate`), not a flag.
    let mut jupedsim = ImportOptions { rig: rig.clone(), cycle: walk.clone(), ..Default::default() }
        .with_motion(spec)
        .map_err(|e| match e {
            Error::Setting { option, msg } => key_err((option.to_string(), msg)),
            e => e,
        })?;
    if format == Format::JuPedSim {
        if let Some((k, m)) = spec.jupedsim_refuses() {
            return Err(key_err((k.to_string(), m)));
        }
        if let Some(r) = shot.rigs.get(&rig) {
            let g = gaits(&walk)?.get(&rig).copied();
            jupedsim.rig_clip =
                g.map(|g| RigClip { file: r.file.clone(), stride: g.stride, cycle_length: g.cycle_length });
        }
    }
    Ok(Import { jupedsim, tabular: None, placement: spec.placement() })
}

/// Opens the shot's cache (see [`shot_import`]).
pub fn open(shot: &Shot) -> Result<CacheReader> {
    CacheReader::open_import(&shot.cache.path, &shot_import(shot)?)
}

/// Opens the shot's cache as [`open`] does, and when it is a UsdSkel crowd
/// that a rig of the shot names as its file, keeps that one reading of the
/// stage (agents, characters and their meshes) for the rigs: the file is
/// opened and decoded once (docs/usd.md, "Reading cost").
pub(crate) fn open_for_rigs(shot: &Shot) -> Result<(CacheReader, SkelFiles)> {
    let path = &shot.cache.path;
    let mut usd = SkelFiles::default();
    // Anything else (and a path that is no file) opens, and errs, as `open` does.
    if Format::of(path).ok() != Some(Format::Usd) || !shot.rigs.values().any(|r| same_file(&r.file, path)) {
        return Ok((open(shot)?, usd));
    }
    let (cache, file) = CacheReader::open_usd_skel(path, &shot_import(shot)?)?;
    if let Some(file) = file {
        usd.insert(path, file)?;
    }
    Ok((cache, usd))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two cache cycles on one clip keep their own strides (they share poses only).
    #[test]
    fn cycles_sharing_a_clip_keep_their_own_strides() {
        let file = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/assets/gltf/SimpleSkin/SimpleSkin.gltf");
        let options = SkinOptions {
            cycles: [("WalkA", "#0"), ("WalkB", "#0")].map(|(c, k)| (c.to_string(), k.to_string())).into(),
            strides: [("WalkB".to_string(), 1.25)].into(),
            ..Default::default()
        };
        let rig = SkinnedRig::load(&file, &options, SHOT_FPS).expect("SimpleSkin loads");
        let g = skinned_gait(&rig, "WalkB", None).expect("WalkB has a stride").expect("a walk cycle");
        assert_eq!(g.stride, 1.25);
        // WalkA has none of its own and SimpleSkin's root does not travel.
        let e = skinned_gait(&rig, "WalkA", None).unwrap_err().to_string();
        assert!(e.contains("cycle `WalkA` walks 0 m"), "{e}");
    }
}
