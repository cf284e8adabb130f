//! Cycle timing that follows each agent's stride: the cycle frames agents
//! play where their stride differs from the one the cache was made for.
//!
//! A cache's cycle frames advance by distance over the rig's stride (the
//! reference simulation, `cache convert` and every trajectory import make
//! them so), which keeps the modelled body's feet planted. An agent drawn
//! taller (the height jitter) or longer-legged (its body's `legs` group)
//! takes longer strides, so at the same speed its cycle must play slower by
//! its pace, `height scale x legs length`, or its feet slide. So while an
//! agent stays on one cycle that walks (stride above 0), its cycle frame
//! advances by the cache's advance over its pace, from where the cache has
//! it on the first record of that run of frames; a cycle that walks no
//! distance (idle, seated) plays as the cache has it. Runs start at the
//! cache's first frame, never at the shot's, so a frame's poses do not
//! depend on which frames a render or a farm task was given.

use std::collections::{BTreeMap, HashMap};

use crate::cache::{AgentSample, CacheReader, FrameBlock};
use crate::casting::cast::Casting;
use crate::casting::rigs::ShotRigs;
use crate::error::Result;
use crate::shot::Shot;

/// Name of an agent record's cycle in the cache (`?` if out of range).
pub(crate) fn cycle_name<'a>(cache: &'a CacheReader, a: &AgentSample) -> &'a str {
    cache.cycles().get(a.cycle as usize).map(String::as_str).unwrap_or("?")
}

/// `to - from` of two cycle frames, taken modulo `length` to the value
/// nearest zero (a wrap from the cycle's end to its start is a small step
/// forward). Without a length, the plain difference.
pub(crate) fn cycle_delta(from: f32, to: f32, length: Option<f32>) -> f32 {
    let d = to - from;
    match length {
        Some(l) if l > 0.0 && l.is_finite() => d - l * (d / l).round(),
        _ => d,
    }
}

/// Length in frames of the cycle an agent record plays (`None` if unknown).
pub(crate) fn length_of(
    shot: &Shot,
    cache: &CacheReader,
    casting: &Casting,
    rigs: &ShotRigs,
    a: &AgentSample,
) -> Option<f32> {
    let rig = rigs.get(&casting.get(a.id)?.rig)?;
    rig.cycle_frames(cycle_name(cache, a), shot.frames.fps)
}

/// The played cycle frames of agents whose pace is not 1, at every cache
/// frame the shot's frames and their shutter neighbours read.
#[derive(Debug, Clone, Default)]
pub(crate) struct CycleTiming {
    /// Cache frame -> agent id -> the cycle frame it plays.
    frames: BTreeMap<i32, HashMap<u32, f32>>,
}

/// An agent's pace: how much longer its strides are than the modelled
/// body's (1 for agents that are never scaled and rigs without bodies).
pub(crate) fn pace(casting: &Casting, rigs: &ShotRigs, id: u32) -> f32 {
    let Some(cast) = casting.get(id) else { return 1.0 };
    let legs = rigs.skinned(&cast.rig).map_or(1.0, |r| r.body_stride(cast.body));
    cast.height_scale * legs
}

impl CycleTiming {
    /// Reads the cache from its first frame to one past the shot's last and
    /// times every cast agent whose pace is not 1 (nothing is read when
    /// every pace is 1).
    pub(crate) fn new(shot: &Shot, cache: &CacheReader, casting: &Casting, rigs: &ShotRigs) -> Result<CycleTiming> {
        let paced: HashMap<u32, f32> = (casting.iter())
            .map(|c| (c.id, pace(casting, rigs, c.id)))
            .filter(|&(_, p)| p != 1.0 && p.is_finite() && p > 0.0)
            .collect();
        let mut timing = CycleTiming::default();
        if paced.is_empty() {
            return Ok(timing);
        }
        let wanted: Vec<i32> = shot.frames.iter().map(|f| shot.cache.cache_frame(f)).collect();
        let (Some(&lo), Some(&hi)) = (wanted.iter().min(), wanted.iter().max()) else { return Ok(timing) };
        let (lo, hi) = (lo.saturating_sub(1), hi.saturating_add(1));
        // Per agent: (cache frame, cycle, cache cycle frame, played cycle frame) at its last record.
        let mut last: HashMap<u32, (i32, u16, f32, f32)> = HashMap::new();
        let mut previous: Option<i32> = None;
        for &cf in cache.frames().iter().take_while(|&&cf| cf <= hi) {
            let block = cache.read_frame(cf)?;
            let mut played = HashMap::new();
            for a in &block.agents {
                let Some(&k) = paced.get(&a.id) else { continue };
                let rig = casting.get(a.id).and_then(|c| rigs.get(&c.rig));
                let name = cycle_name(cache, a);
                let walks = rig.and_then(|r| r.cycle_stride(name)).is_some_and(|s| s > 0.0);
                let length = length_of(shot, cache, casting, rigs, a).filter(|l| *l > 0.0);
                let now = match last.get(&a.id) {
                    Some(&(f, cycle, raw, was)) if walks && Some(f) == previous && cycle == a.cycle => {
                        let advanced = was + cycle_delta(raw, a.cycle_frame, length) / k;
                        length.map_or(advanced, |l| advanced.rem_euclid(l))
                    }
                    _ => a.cycle_frame,
                };
                last.insert(a.id, (cf, a.cycle, a.cycle_frame, now));
                if cf >= lo && now != a.cycle_frame {
                    played.insert(a.id, now);
                }
            }
            if cf >= lo && !played.is_empty() {
                timing.frames.insert(cf, played);
            }
            previous = Some(cf);
        }
        Ok(timing)
    }

    /// Cache frame `cf` as its agents play it.
    pub(crate) fn read(&self, cache: &CacheReader, cf: i32) -> Result<FrameBlock> {
        let mut block = cache.read_frame(cf)?;
        if let Some(m) = self.frames.get(&cf) {
            for a in &mut block.agents {
                if let Some(&c) = m.get(&a.id) {
                    a.cycle_frame = c;
                }
            }
        }
        Ok(block)
    }
}
