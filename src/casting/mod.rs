//! Casting: the shot loaded and every agent dressed. Takes the shot file,
//! the cache, rigs and wardrobes; gives a [`ShotCrowd`] built in three
//! stages: the [`Casting`] (each agent's scheme, parts and height), the
//! [`Dressing`] (the rigid parts or skinned pieces each wears) and the
//! [`PoseLibrary`] (every mesh, and every skinned pose step still frames and
//! the shutter take); and from them any frame's posed instances.

pub(crate) mod animation;
pub(crate) mod body;
pub(crate) mod cast;
pub(crate) mod crowd;
pub(crate) mod dressing;
pub(crate) mod gait;
pub(crate) mod kind;
pub mod motion;
pub(crate) mod pieces;
pub(crate) mod poses;
pub mod rig;
pub(crate) mod rigs;
pub mod shot_cache;
pub mod skin;
pub(crate) mod steps;
pub mod table;
pub(crate) mod timing;
pub(crate) mod usdskel_rig;
pub mod wardrobe;
pub(crate) mod wheels;
pub(crate) mod worn;

pub use crate::seed::uniform;
pub use cast::{cast_agent, AgentCast, Casting, RigCasting, SlotCast};
pub use crowd::{AgentPose, Lod, ShotCrowd};
pub use dressing::{AgentDress, DressedPart, Dressing, PartFit, SkinDress};
pub use poses::{PoseLibrary, PosedSkins};
pub use rigs::{ShotRig, ShotRigs};

/// Refuses an agent id that cannot be represented downstream: `agent.id` in
/// the EXRs is id + 1 (0 = no agent), so `u32::MAX` would write as "no agent".
pub(crate) fn check_agent_id(cache: &std::path::Path, cache_frame: i32, id: u32) -> crate::error::Result<()> {
    if id == u32::MAX {
        return Err(crate::error::Error::invalid(
            cache,
            format!("agent id {id} cannot be rendered (agent.id is id + 1 in 32 bits; ids go up to {})", u32::MAX - 1),
        )
        .frame(cache_frame.into())
        .agent(id)
        .field("id"));
    }
    Ok(())
}

/// Shot frames with no cache frame (`outside`, in order): an error naming the
/// first one, unless the shot sets `frames.outside_cache = "empty"`, when they
/// render no agents and this returns the warning to print.
pub(crate) fn check_outside_cache(
    shot: &crate::shot::Shot,
    cache_frames: &[i32],
    cache: &std::path::Path,
    outside: &[i32],
) -> crate::error::Result<Vec<String>> {
    let Some(&first) = outside.first() else { return Ok(Vec::new()) };
    let mut held = match (cache_frames.first(), cache_frames.last()) {
        (Some(a), Some(b)) => format!("the cache holds frames {a}-{b}"),
        _ => "the cache holds no frames".into(),
    };
    // A USD cache names the prim whose time samples stop short (docs/usd.md).
    if crate::cache::Format::of(cache).ok() == Some(crate::cache::Format::Usd) {
        if let Some(why) = crate::cache::usd::coverage(cache, shot.cache.cache_frame(first)) {
            held = format!("{held}: {why}");
        }
    }
    let list = |n: usize| {
        let mut s = outside.iter().take(n).map(i32::to_string).collect::<Vec<_>>().join(", ");
        if outside.len() > n {
            s += &format!(" and {} more", outside.len() - n);
        }
        s
    };
    match shot.frames.outside_cache {
        crate::shot::OutsideCache::Error => Err(crate::error::Error::invalid(
            &shot.path,
            format!(
                "{} shot frame(s) have no cache frame in {} ({held}; frame_offset {}): {}; set `frames.outside_cache = \"empty\"` to render them with no agents",
                outside.len(),
                cache.display(),
                shot.cache.frame_offset,
                list(8)
            ),
        )
        .frame(first.into())
        .field("frames")),
        crate::shot::OutsideCache::Empty => Ok(vec![format!(
            "{}: {} shot frame(s) have no cache frame in {} ({held}) and render no agents (frames.outside_cache = \"empty\"): {}",
            shot.path.display(),
            outside.len(),
            cache.display(),
            list(8)
        )]),
    }
}
