//! The shot's atmosphere as the scene holds it: a medium (haze, fog) below
//! a height, homogeneous or thinning exponentially with height, clear near
//! the camera if asked, checked. How it is traced is render::atmosphere's.

use glam::Vec3;

/// Largest density (1/m): air this thick is opaque within a millimetre, and
/// a bound keeps every exponent finite.
pub const MAX_DENSITY: f32 = 1.0e4;

/// How much of the atmosphere a render traces.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, serde::Deserialize, serde::Serialize)]
#[serde(rename_all = "lowercase")]
pub enum AtmosphereMode {
    /// Every ray: camera rays, bounces and shadow rays scatter and are
    /// attenuated; lit by every light, with shadows.
    #[default]
    Full,
    /// Camera rays only, in closed form: attenuation, and in-scatter from
    /// the sun and the dome without shadows (a depth cue for wide shots).
    Haze,
}

/// A medium below world height `top`: extinction `density` at and below
/// world height `base`, falling as exp(-(y - base) / falloff) above it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Atmosphere {
    /// Extinction coefficient, 1/m (grey), at and below `base`.
    pub density: f32,
    /// Single-scattering albedo per channel, 0..=1: scattering = density x albedo.
    pub albedo: Vec3,
    /// Henyey-Greenstein g, -1 < g < 1 (> 0: forward scattering).
    pub anisotropy: f32,
    /// World Y of the top of the air (+inf: everywhere).
    pub top: f32,
    /// What is traced.
    pub mode: AtmosphereMode,
    /// Scale height, metres: above `base` the density falls by e every
    /// `falloff` metres (+inf: homogeneous).
    pub falloff: f32,
    /// World Y where the falloff starts.
    pub base: f32,
    /// Distance along camera rays before which there is no air, metres
    /// (the foreground kept clear; other rays see all of it).
    pub start: f32,
}

impl Default for Atmosphere {
    /// Clear air (density 0), white, isotropic, everywhere, homogeneous.
    fn default() -> Atmosphere {
        Atmosphere {
            density: 0.0,
            albedo: Vec3::ONE,
            anisotropy: 0.0,
            top: f32::INFINITY,
            mode: AtmosphereMode::Full,
            falloff: f32::INFINITY,
            base: 0.0,
            start: 0.0,
        }
    }
}

impl Atmosphere {
    /// Checks the values, naming the key (`density`, `color`, `anisotropy`,
    /// `height`, `falloff`, `base`, `start`) that is wrong.
    pub fn check(&self) -> Result<(), (&'static str, String)> {
        if !(self.density.is_finite() && (0.0..=MAX_DENSITY).contains(&self.density)) {
            return Err(("density", format!("must be a finite number 0 to {MAX_DENSITY} (1/m), got {}", self.density)));
        }
        if !self.albedo.to_array().iter().all(|c| (0.0..=1.0).contains(c)) {
            return Err((
                "color",
                format!("each channel must be 0 to 1 (an albedo), got {:?}", self.albedo.to_array()),
            ));
        }
        if !(self.anisotropy > -1.0 && self.anisotropy < 1.0) {
            return Err(("anisotropy", format!("must lie strictly between -1 and 1, got {}", self.anisotropy)));
        }
        if self.top.is_nan() || self.top == f32::NEG_INFINITY {
            return Err(("height", format!("must be a number, got {}", self.top)));
        }
        // Above 1 mm: a thinner falloff is a floor of air, and 1 / falloff stays finite.
        if !(self.falloff >= 1e-3) {
            return Err(("falloff", format!("must be a length of at least 0.001 (metres), got {}", self.falloff)));
        }
        if !self.base.is_finite() {
            return Err(("base", format!("must be a finite height (metres), got {}", self.base)));
        }
        if !(self.start.is_finite() && self.start >= 0.0) {
            return Err(("start", format!("must be a finite distance 0 or more (metres), got {}", self.start)));
        }
        Ok(())
    }
}
