//! An attribute's composed time samples read once (docs/usd.md, "UsdSkel
//! crowds"): openusd composes a value afresh on every read, so a crowd of
//! thousands of agents over tens of frames read one value at a time spends
//! its time composing. A [`Track`] holds every sample of one attribute; a
//! value at a sample time (or held before the first or after the last) comes
//! from it, and only a time between two samples is asked of the stage (which
//! interpolates as USD does). A [`WorldTrack`] is a prim's world transform
//! over time, every xform op of it and its ancestors read once.

use glam::Mat4;
use openusd::sdf::Value;

use super::usd::{local_matrix_with, xform_chain, Ctx};
use crate::error::Result;

/// One attribute's samples.
pub(super) struct Track {
    prim: String,
    attr: String,
    /// The composed sample times, ascending (empty: the default only).
    pub(super) times: Vec<f64>,
    /// The samples, when the composed `timeSamples` are the value source
    /// (not value clips): then `samples[k].0 == times[k]`.
    samples: Option<Vec<(f64, Value)>>,
    /// The value when there are no samples (`None`: not authored).
    default: Option<Value>,
}

impl Track {
    /// Reads `prim.attr`'s samples (or its default when it has none).
    pub(super) fn read(ctx: &Ctx, prim: &str, attr: &str) -> Result<Track> {
        let times = ctx.times(prim, attr)?;
        let (samples, default) = if times.is_empty() {
            (None, ctx.value(prim, attr, 0.0)?)
        } else {
            let p = ctx.sdf_path(&format!("{prim}.{attr}"))?;
            let map = (ctx.stage.time_samples(p))
                .map_err(|e| ctx.err(&format!("{prim}.{attr}"), format!("cannot read time samples: {e}")))?;
            // Value clips give other times than the layer's samples: the stage answers then.
            let same =
                map.as_ref().is_some_and(|m| m.len() == times.len() && m.iter().zip(&times).all(|(s, t)| s.0 == *t));
            (map.filter(|_| same), None)
        };
        Ok(Track { prim: prim.to_string(), attr: attr.to_string(), times, samples, default })
    }

    /// Errors when the samples do not cover `frames` (as `Ctx::covers`).
    pub(super) fn covers(&self, ctx: &Ctx, frames: (i64, i64)) -> Result<()> {
        ctx.covers_times(&self.prim, &self.attr, &self.times, frames)
    }

    /// The value at time `t`, as `Ctx::value` gives it.
    pub(super) fn at(&self, ctx: &Ctx, t: f64) -> Result<Option<Value>> {
        if self.times.is_empty() {
            return Ok(self.default.clone());
        }
        if let Some(s) = &self.samples {
            let k = s.partition_point(|x| x.0 < t);
            let held = match k {
                0 => Some(&s[0].1),
                k if k == s.len() => Some(&s[k - 1].1),
                k if s[k].0 == t => Some(&s[k].1),
                _ => None,
            };
            match held {
                Some(Value::ValueBlock | Value::None) | None => {}
                Some(v) => return Ok(Some(v.clone())),
            }
        }
        ctx.value(&self.prim, &self.attr, t)
    }
}

/// A prim's world transform over time: its and its ancestors' xform ops,
/// each read once.
pub(super) struct WorldTrack {
    prim: String,
    /// Per prim of the chain (the prim first): its ops and their tracks.
    chain: Vec<(String, Vec<String>, Vec<Option<Track>>)>,
}

impl WorldTrack {
    pub(super) fn read(ctx: &Ctx, prim: &str) -> Result<WorldTrack> {
        let mut chain = Vec::new();
        for (p, ops) in xform_chain(ctx, prim)? {
            let tracks = (ops.iter())
                .map(|op| match op.as_str() {
                    "!resetXformStack!" => Ok(None),
                    op => Track::read(ctx, &p, op.strip_prefix("!invert!").unwrap_or(op)).map(Some),
                })
                .collect::<Result<Vec<_>>>()?;
            chain.push((p, ops, tracks));
        }
        Ok(WorldTrack { prim: prim.to_string(), chain })
    }

    /// Every op's track with its prim and attribute (for coverage checks).
    pub(super) fn tracks(&self) -> impl Iterator<Item = &Track> {
        self.chain.iter().flat_map(|(_, _, t)| t.iter().flatten())
    }

    /// The world matrix at `t`, as `usd::world_matrix` gives it.
    pub(super) fn at(&self, ctx: &Ctx, t: f64) -> Result<Mat4> {
        let mut m = Mat4::IDENTITY;
        for (p, ops, tracks) in &self.chain {
            let local = local_matrix_with(ctx, p, ops, t, &mut |k, _| match &tracks[k] {
                Some(track) => track.at(ctx, t),
                None => Ok(None),
            })?;
            m = local * m;
        }
        if !m.is_finite() {
            let prim = &self.prim;
            return Err(ctx.err(prim, format!("<{prim}>'s world transform at time {t} is not finite")));
        }
        Ok(m)
    }
}
