//! `[lights.gains]`: a multiplier per light group (gain x tint) that the
//! render applies to every light, emissive material and dome in the group,
//! as if each one's intensity and colour had been edited. The review page's
//! mixer regrades the `lg_<group>` passes with the same factors and saves
//! them here, so a render of the saved shot bakes what the page showed
//! (docs/shot.md, "Light-group gains").

use std::collections::BTreeMap;

use glam::Vec3;
use serde::{Deserialize, Serialize};

use super::lights::SceneLights;
use super::passes::LightGroups;
use crate::error::{Error, Result};
use crate::scene::Material;

/// Largest gain or tint component: 2^32 (32 stops) is far past any regrade,
/// and keeps gain x tint x a light's emission away from f32 overflow.
pub const MAX_GAIN: f32 = 4_294_967_296.0;

/// One group's multiplier, linear: `gain` x `tint` (linear Rec.709, like
/// every colour of the shot).
#[derive(Clone, Copy, Debug, PartialEq, Deserialize, Serialize)]
#[serde(deny_unknown_fields)]
pub struct LightGain {
    /// Intensity multiplier (0 turns the group off).
    #[serde(default = "one")]
    pub gain: f32,
    /// Colour multiplier.
    #[serde(default = "white")]
    pub tint: [f32; 3],
}

fn one() -> f32 {
    1.0
}
fn white() -> [f32; 3] {
    [1.0; 3]
}

impl Default for LightGain {
    fn default() -> Self {
        LightGain { gain: 1.0, tint: [1.0; 3] }
    }
}

impl LightGain {
    /// gain x tint.
    pub fn factor(&self) -> Vec3 {
        Vec3::from(self.tint) * self.gain
    }

    /// Finite, >= 0 and at most [`MAX_GAIN`]: Err(key under the group, message).
    pub fn check(&self) -> std::result::Result<(), (&'static str, String)> {
        let ok = |v: f32| v.is_finite() && (0.0..=MAX_GAIN).contains(&v);
        if !ok(self.gain) {
            return Err(("gain", format!("must be finite, >= 0 and <= 2^32, got {}", self.gain)));
        }
        if !self.tint.iter().all(|&c| ok(c)) {
            return Err(("tint", format!("components must be finite, >= 0 and <= 2^32, got {:?}", self.tint)));
        }
        Ok(())
    }
}

/// The gains of a shot, by group name.
pub type LightGains = BTreeMap<String, LightGain>;

/// Each group's factor in `groups`' order (1 where the shot gives none).
/// A gain naming no group of the shot is refused, `shot` and the key
/// `lights.gains.<name>` in the message: a typo would otherwise change nothing.
pub fn factors(gains: &LightGains, groups: &LightGroups, shot: &std::path::Path) -> Result<Vec<Vec3>> {
    if let Some(name) = gains.keys().find(|n| !groups.names.contains(n)) {
        return Err(Error::invalid(
            shot,
            format!("`{name}` is no light group of the shot (its groups: {})", groups.names.join(", ")),
        )
        .field(format!("lights.gains.{name}")));
    }
    Ok(groups.names.iter().map(|n| gains.get(n).map_or(Vec3::ONE, LightGain::factor)).collect())
}

/// `v` x `f`, kept finite (gains are bounded, emissions too, but not their product).
fn scaled(v: Vec3, f: Vec3) -> Vec3 {
    (v * f).min(Vec3::splat(f32::MAX))
}

/// Scales the sun, the uniform sky and every local light of `lights` by
/// its group's factor (the dome is scaled where its map is loaded, so its
/// texels are not copied per frame).
pub fn apply_to_lights(lights: &mut SceneLights, groups: &LightGroups, factors: &[Vec3]) {
    let f = |g: u16| factors.get(g as usize).copied().unwrap_or(Vec3::ONE);
    if let Some(sun) = &mut lights.sun {
        sun.irradiance = scaled(sun.irradiance, f(groups.sun()));
    }
    // With a dome the sky is what a dome without power falls back to:
    // a dome turned off (gain 0) must not bring the sky back.
    lights.sky.radiance = scaled(lights.sky.radiance, f(groups.environment()));
    for (i, light) in lights.local.iter_mut().enumerate() {
        light.emission = scaled(light.emission, f(groups.local(i)));
    }
}

/// Sets each emissive material's emission to its authored one (`base`,
/// per material) x its group's factor.
pub fn apply_to_materials(materials: &mut [Material], base: &[Vec3], groups: &LightGroups, factors: &[Vec3]) {
    for (m, (material, &authored)) in materials.iter_mut().zip(base).enumerate() {
        if authored.max_element() > 0.0 {
            let g = groups.material(m as u32);
            material.emission = scaled(authored, factors.get(g as usize).copied().unwrap_or(Vec3::ONE));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn checks_gain_and_tint_ranges() {
        assert!(LightGain::default().check().is_ok());
        assert!(LightGain { gain: 0.0, tint: [0.0; 3] }.check().is_ok());
        assert_eq!(LightGain { gain: -1.0, ..Default::default() }.check().unwrap_err().0, "gain");
        assert_eq!(LightGain { gain: f32::NAN, ..Default::default() }.check().unwrap_err().0, "gain");
        assert_eq!(LightGain { gain: f32::INFINITY, ..Default::default() }.check().unwrap_err().0, "gain");
        assert_eq!(LightGain { tint: [1.0, -0.1, 1.0], ..Default::default() }.check().unwrap_err().0, "tint");
        assert_eq!(LightGain { gain: 1.5, tint: [1.0, 0.5, 0.0] }.factor(), Vec3::new(1.5, 0.75, 0.0));
        assert_eq!(scaled(Vec3::splat(f32::MAX), Vec3::splat(2.0)), Vec3::splat(f32::MAX));
    }
}
