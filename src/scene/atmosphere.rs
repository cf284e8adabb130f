//! The shot's atmosphere as the scene holds it: a homogeneous medium
//! (haze, fog) below a height, checked. How it is traced is
//! render::atmosphere's.

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

/// A homogeneous medium below world height `top`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Atmosphere {
    /// Extinction coefficient, 1/m (grey).
    pub density: f32,
    /// Single-scattering albedo per channel, 0..=1: scattering = density x albedo.
    pub albedo: Vec3,
    /// Henyey-Greenstein g, -1 < g < 1 (> 0: forward scattering).
    pub anisotropy: f32,
    /// World Y of the top of the air (+inf: everywhere).
    pub top: f32,
    /// What is traced.
    pub mode: AtmosphereMode,
}

impl Atmosphere {
    /// Checks the values, naming the key (`density`, `color`, `anisotropy`,
    /// `height`) that is wrong.
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
        Ok(())
    }
}
