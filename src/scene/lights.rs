//! Lights as the renderer sees them: world space, render units, with colour,
//! intensity and exposure already folded into one RGB value per light.
//!
//! Units (docs/lights.md), chosen so a glTF file's lights and Blender's import
//! of it agree (../shared/peers README, "light units"):
//! - distant lights (the sun): irradiance at normal incidence, W/m^2
//!   (glTF lux / 683);
//! - point and spot lights: radiant intensity, W/sr (glTF candela / 683);
//! - rect, disk and sphere lights, emissive surfaces and the dome: radiance,
//!   W/(m^2 sr) (glTF emissiveFactor x emissiveStrength, no 1/683).
//!
//! Every light shines down its local -Z (glTF, USD), +Y up.

use std::sync::Arc;

use glam::{Affine3A, Vec2, Vec3};

use super::{Sky, Sun};

/// A light's effective strength (`what`: how it is made, "intensity x
/// colour x 2^exposure") must be a finite f32: each factor may pass its own
/// range check and their product still overflow, which would render the
/// light as no light at all (docs/lights.md, "Strength").
pub(crate) fn check_product(what: &str, v: Vec3) -> std::result::Result<(), String> {
    if v.is_finite() {
        Ok(())
    } else {
        Err(format!("{what} overflows an f32 (largest {:e}): got {v}; lower one of them", f32::MAX))
    }
}

/// The shape (and so the sampling) of a local light.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LightKind {
    /// A point emitting equally in all directions.
    Point,
    /// A point emitting into a cone about its local -Z. `outer` is the
    /// cone's half angle (radians); `blend` (0..1) the fraction of it that
    /// fades, with Blender's smoothstep (what Cycles renders for an imported
    /// glTF spot: blend = 1 - inner / outer).
    Spot {
        /// Half angle of the cone's edge, radians, in (0, pi/2].
        outer: f32,
        /// Softness of the edge, 0 (hard) to 1.
        blend: f32,
    },
    /// A rectangle `size` (x by y, local units) centred on the origin of its
    /// local XY plane, emitting towards local -Z (both ways if two-sided).
    Rect {
        /// Width along local X and height along local Y.
        size: Vec2,
    },
    /// A disc of `radius` in the local XY plane, emitting towards local -Z.
    Disk {
        /// Radius.
        radius: f32,
    },
    /// A sphere of `radius` about the origin, emitting outwards.
    Sphere {
        /// Radius.
        radius: f32,
    },
    /// A light at infinity shining down its local -Z (a glTF directional
    /// light): `emission` is its irradiance, W/m^2.
    Distant {
        /// Full angular diameter, radians (0: a delta direction).
        angular_diameter: f32,
    },
}

/// One light placed in the world.
#[derive(Clone, Debug, PartialEq)]
pub struct Light {
    /// Name, for messages and exports (`lights.rect[2]`, a glTF node name).
    pub name: String,
    /// Its shape.
    pub kind: LightKind,
    /// Light to world: position and orientation, unit scale (sizes are in
    /// the kind).
    pub world_from_light: Affine3A,
    /// Colour x intensity x 2^exposure: W/sr for point and spot lights,
    /// W/(m^2 sr) for rect, disk and sphere lights, W/m^2 for distant ones.
    pub emission: Vec3,
    /// Rect and disk lights emit from both faces.
    pub two_sided: bool,
    /// Camera rays see a sized light's surface (bounce rays always do).
    pub camera_visible: bool,
    /// The light group its light is written to (`lg_<name>`); None: a
    /// group of its own, named after it (scene::passes).
    pub light_group: Option<String>,
}

impl Light {
    /// World position of the light's origin.
    pub fn position(&self) -> Vec3 {
        self.world_from_light.translation.into()
    }

    /// World direction the light faces (its local -Z).
    pub fn facing(&self) -> Vec3 {
        self.world_from_light.transform_vector3(-Vec3::Z).normalize_or_zero()
    }
}

/// A lat-long (equirectangular) environment map, linear RGB, top row the
/// zenith. Orientation as Blender's world and USD's DomeLight in glTF axes
/// (+Y up): at `rotate` 0 the image centre (u = 0.5) faces +X, u = 0.25
/// faces -Z; `rotate` turns it right-handedly about +Y.
#[derive(Clone, Debug, PartialEq)]
pub struct Dome {
    /// Where it was read from (for messages, exports and fingerprints).
    pub file: std::path::PathBuf,
    /// Width in texels (twice the height).
    pub width: u32,
    /// Height in texels.
    pub height: u32,
    /// Row-major texels, top row first, linear RGB radiance before `scale`.
    pub texels: Vec<Vec3>,
    /// Multiplier: intensity x 2^exposure x colour.
    pub scale: Vec3,
    /// Rotation about +Y, radians.
    pub rotate: f32,
    /// Camera rays that miss everything see the dome (it lights either way).
    pub camera_visible: bool,
}

/// Every light of a shot, as a frame scene holds it. Shared (`Arc`) between
/// the layers and frames of a render: a dome's texels are loaded once.
#[derive(Clone, Debug, Default)]
pub struct SceneLights {
    /// The sun, if any.
    pub sun: Option<Sun>,
    /// The uniform sky: the environment when there is no dome.
    pub sky: Sky,
    /// An HDRI dome; replaces the uniform sky.
    pub dome: Option<Arc<Dome>>,
    /// Point, spot and area lights.
    pub local: Vec<Light>,
    /// The light groups the sun, sky, dome and emissive materials are in.
    pub groups: NamedGroups,
}

/// Light groups a shot names for the lights that are not [`Light`]s
/// (scene::passes gives the defaults: `sun`, `sky`, `dome`, the material's name).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct NamedGroups {
    /// The sun's (`lights.sun.light_group`).
    pub sun: Option<String>,
    /// The uniform sky's.
    pub sky: Option<String>,
    /// The dome's.
    pub dome: Option<String>,
    /// Emissive materials by name (`lights.groups.materials`).
    pub materials: std::collections::BTreeMap<String, String>,
}

impl SceneLights {
    /// Just a sun (or none) and a uniform sky: the simple case.
    pub fn sun_and_sky(sun: Option<Sun>, sky: Sky) -> SceneLights {
        SceneLights { sun, sky, dome: None, local: Vec::new(), groups: NamedGroups::default() }
    }
}
