//! Casting: the shot loaded and every agent dressed. Takes the shot file,
//! the cache, rigs and wardrobes; gives a [`ShotCrowd`]: each agent's scheme,
//! parts, materials and height, and any frame's posed instances.

pub mod cast;
pub mod crowd;
pub mod rig;
pub mod shot_cache;
pub mod skin;
pub mod table;
pub mod wardrobe;

pub use cast::{cast_agent, cast_delivered, fit_part, mix64, uniform, AgentCast, CastPart, RigCasting, SlotCast};
pub use crowd::{AgentPose, DressedPart, Lod, PosedSkins, ShotCrowd, SkinDress};
