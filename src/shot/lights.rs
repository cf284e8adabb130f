//! `[lights]`: the sun, the uniform sky, an HDRI dome and any number of
//! point, spot, rect, disk and sphere lights, checked one light at a time.
//! Units and orientations: docs/lights.md.

use std::path::PathBuf;

use glam::{Affine3A, Mat4, Vec2, Vec3};
use serde::Deserialize;
use toml::Spanned;

use super::{look_at, Context};
use crate::error::{Error, Result};
use crate::scene::light_gains::LightGains;
use crate::scene::lights::{check_product, Light, LightKind, NamedGroups};
use crate::scene::passes::check_group_name;
use crate::scene::{Sky, Sun};

/// `[lights]`, checked.
#[derive(Debug, Clone, Default)]
pub struct Lights {
    /// The sun.
    pub sun: Option<SunSpec>,
    /// The sky (the environment when there is no dome).
    pub(crate) sky: SkySpec,
    /// An HDRI dome.
    pub dome: Option<DomeSpec>,
    /// Point, spot and area lights, world space, in file order (points,
    /// spots, rects, disks, spheres).
    pub(crate) local: Vec<Light>,
    /// `[lights.groups]`: the light groups of the sun, sky, dome and emissive materials.
    pub(crate) groups: NamedGroups,
    /// `[lights.gains]`: each light group's gain x tint (scene::light_gains).
    pub gains: LightGains,
}

/// `[lights.groups]` as written.
#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
struct GroupsFile {
    sun: Option<String>,
    sky: Option<String>,
    dome: Option<String>,
    #[serde(default)]
    materials: std::collections::BTreeMap<String, String>,
}

/// `[lights.sun]`.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SunSpec {
    /// Direction towards the sun (normalised on load).
    pub direction: [f32; 3],
    /// Full angular diameter in degrees.
    #[serde(default = "default_sun_diameter")]
    pub(crate) angular_diameter: f32,
    /// Irradiance in W/m^2.
    #[serde(default = "one")]
    pub(crate) intensity: f32,
    /// Linear colour.
    #[serde(default = "white")]
    pub(crate) color: [f32; 3],
}

/// `[lights.sky]`.
#[derive(Debug, Clone, Copy, Deserialize)]
#[serde(deny_unknown_fields)]
pub(crate) struct SkySpec {
    /// Linear colour.
    #[serde(default = "white")]
    pub(crate) color: [f32; 3],
    /// Multiplier.
    #[serde(default = "one")]
    pub(crate) intensity: f32,
}

impl Default for SkySpec {
    fn default() -> Self {
        SkySpec { color: [0.3, 0.38, 0.5], intensity: 1.0 }
    }
}

/// `[lights.dome]`, checked: the file exists (its pixels are read when the
/// shot is cast, `scene::dome`).
#[derive(Debug, Clone, PartialEq)]
pub struct DomeSpec {
    /// The lat-long map (.hdr or .exr).
    pub(crate) file: PathBuf,
    /// colour x intensity x 2^exposure.
    pub(crate) scale: Vec3,
    /// Rotation about +Y, radians.
    pub rotate: f32,
    /// Camera rays that miss see the dome.
    pub(crate) camera_visible: bool,
}

fn default_sun_diameter() -> f32 {
    0.53
}
fn one() -> f32 {
    1.0
}
fn white() -> [f32; 3] {
    [1.0; 3]
}
fn yes() -> bool {
    true
}

/// A light's intensity and colour: finite and >= 0 (the sun and sky may be 0: off).
pub(super) fn check_light(intensity: f32, color: [f32; 3]) -> std::result::Result<(), (&'static str, String)> {
    if !(intensity >= 0.0 && intensity.is_finite()) {
        return Err(("intensity", format!("must be finite and >= 0, got {intensity}")));
    }
    if !color.iter().all(|c| *c >= 0.0 && c.is_finite()) {
        return Err(("color", format!("components must be finite and >= 0, got {color:?}")));
    }
    Ok(())
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct DomeFile {
    file: Spanned<PathBuf>,
    #[serde(default = "one")]
    intensity: f32,
    #[serde(default)]
    exposure: f32,
    #[serde(default = "white")]
    color: [f32; 3],
    /// Degrees about +Y.
    #[serde(default)]
    rotate: f32,
    #[serde(default = "yes")]
    camera_visible: bool,
}

/// One `[[lights.<kind>]]` entry as written: every kind's keys, checked
/// against what its kind takes.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct LocalFile {
    name: Option<String>,
    position: Option<[f32; 3]>,
    /// A point the light faces.
    aim: Option<[f32; 3]>,
    /// The direction the light faces.
    direction: Option<[f32; 3]>,
    /// Light to world, 16 numbers column by column (glTF's and USD's order).
    transform: Option<[f32; 16]>,
    #[serde(default = "white")]
    color: [f32; 3],
    intensity: Option<f32>,
    #[serde(default)]
    exposure: f32,
    radius: Option<f32>,
    size: Option<[f32; 2]>,
    /// Spot cone, degrees from the axis.
    inner_angle: Option<f32>,
    outer_angle: Option<f32>,
    two_sided: Option<bool>,
    camera_visible: Option<bool>,
    /// The light group it is written to (default: its own, by its name).
    light_group: Option<String>,
}

/// `[lights]` as written.
#[derive(Deserialize, Default)]
#[serde(deny_unknown_fields)]
pub(super) struct LightsFile {
    sun: Option<SunSpec>,
    #[serde(default)]
    sky: SkySpec,
    dome: Option<DomeFile>,
    #[serde(default)]
    point: Vec<LocalFile>,
    #[serde(default)]
    spot: Vec<LocalFile>,
    #[serde(default)]
    rect: Vec<LocalFile>,
    #[serde(default)]
    disk: Vec<LocalFile>,
    #[serde(default)]
    sphere: Vec<LocalFile>,
    #[serde(default)]
    groups: GroupsFile,
    #[serde(default)]
    gains: LightGains,
}

/// Most local lights a shot may declare (the set's glTF may add more).
pub(crate) const MAX_SHOT_LIGHTS: usize = 100_000;

/// Largest exposure (stops) a light may take: 2^64 is far past any real light.
const MAX_EXPOSURE: f32 = 64.0;

/// `2^exposure` after a range check.
fn exposure_scale(exposure: f32) -> std::result::Result<f32, String> {
    if !(exposure.is_finite() && exposure.abs() <= MAX_EXPOSURE) {
        return Err(format!("must be finite and within +/-{MAX_EXPOSURE} stops, got {exposure}"));
    }
    Ok(exposure.exp2())
}

impl LightsFile {
    /// `[lights]` -> a checked sun, sky, dome and local lights.
    pub(super) fn check(&self, cx: &Context) -> Result<Lights> {
        let path = cx.path;
        if let Some(sun) = &self.sun {
            let direction = Vec3::from(sun.direction);
            if !direction.is_finite() || direction.length_squared() == 0.0 {
                return Err(Error::invalid(path, "sun direction is zero or not finite").field("lights.sun.direction"));
            }
            if !(0.0..=180.0).contains(&sun.angular_diameter) {
                return Err(Error::invalid(
                    path,
                    format!("angular diameter must be 0-180 degrees, got {}", sun.angular_diameter),
                )
                .field("lights.sun.angular_diameter"));
            }
            check_light(sun.intensity, sun.color)
                .map_err(|(k, m)| Error::invalid(path, m).field(format!("lights.sun.{k}")))?;
            check_product("intensity x colour", Vec3::from(sun.color) * sun.intensity)
                .map_err(|m| Error::invalid(path, m).field("lights.sun"))?;
        }
        let sky = &self.sky;
        check_light(sky.intensity, sky.color)
            .map_err(|(k, m)| Error::invalid(path, m).field(format!("lights.sky.{k}")))?;
        check_product("intensity x colour", Vec3::from(sky.color) * sky.intensity)
            .map_err(|m| Error::invalid(path, m).field("lights.sky"))?;
        let dome = self.dome.as_ref().map(|d| d.check(cx)).transpose()?;
        let kinds: [(&str, &[LocalFile]); 5] = [
            ("point", &self.point),
            ("spot", &self.spot),
            ("rect", &self.rect),
            ("disk", &self.disk),
            ("sphere", &self.sphere),
        ];
        let count: usize = kinds.iter().map(|(_, l)| l.len()).sum();
        if count > MAX_SHOT_LIGHTS {
            return Err(Error::invalid(
                path,
                format!("{count} lights, more than a shot may declare ({MAX_SHOT_LIGHTS})"),
            )
            .field("lights"));
        }
        let mut local = Vec::with_capacity(count);
        for (kind, lights) in kinds {
            for (i, l) in lights.iter().enumerate() {
                let key = format!("lights.{kind}[{i}]");
                let light =
                    l.check(kind, &key).map_err(|(k, m)| Error::invalid(path, m).field(format!("{key}.{k}")))?;
                check_product("intensity x colour x 2^exposure", light.emission)
                    .map_err(|m| Error::invalid(path, m).field(key.clone()))?;
                local.push(light);
            }
        }
        let g = &self.groups;
        let named = |key: &str, v: &Option<String>| -> Result<Option<String>> {
            if let Some(name) = v {
                check_group_name(name, key).map_err(|e| Error::invalid(path, e.to_string()).field(key))?;
            }
            Ok(v.clone())
        };
        for (material, group) in &g.materials {
            let key = format!("lights.groups.materials.{material}");
            check_group_name(group, &key).map_err(|e| Error::invalid(path, e.to_string()).field(key.clone()))?;
        }
        let groups = NamedGroups {
            sun: named("lights.groups.sun", &g.sun)?,
            sky: named("lights.groups.sky", &g.sky)?,
            dome: named("lights.groups.dome", &g.dome)?,
            materials: g.materials.clone(),
        };
        for (name, gain) in &self.gains {
            let key = format!("lights.gains.{name}");
            check_group_name(name, &key).map_err(|e| Error::invalid(path, e.to_string()).field(key.clone()))?;
            gain.check().map_err(|(k, m)| Error::invalid(path, m).field(format!("{key}.{k}")))?;
        }
        Ok(Lights { sun: self.sun, sky: self.sky, dome, local, groups, gains: self.gains.clone() })
    }
}

impl DomeFile {
    fn check(&self, cx: &Context) -> Result<DomeSpec> {
        let err = |k: &str, m: String| Error::invalid(cx.path, m).field(format!("lights.dome.{k}"));
        let file = cx.existing(&self.file, "lights.dome.file")?;
        if !(self.intensity > 0.0 && self.intensity.is_finite()) {
            return Err(err("intensity", format!("must be finite and > 0, got {}", self.intensity)));
        }
        check_light(self.intensity, self.color).map_err(|(k, m)| err(k, m))?;
        let exposure = exposure_scale(self.exposure).map_err(|m| err("exposure", m))?;
        if !self.rotate.is_finite() {
            return Err(err("rotate", format!("must be finite degrees, got {}", self.rotate)));
        }
        let scale = Vec3::from(self.color) * self.intensity * exposure;
        check_product("intensity x colour x 2^exposure", scale)
            .map_err(|m| Error::invalid(cx.path, m).field("lights.dome"))?;
        Ok(DomeSpec { file, scale, rotate: self.rotate.to_radians(), camera_visible: self.camera_visible })
    }
}

type Checked<T> = std::result::Result<T, (&'static str, String)>;

fn finite3(v: [f32; 3], key: &'static str) -> Checked<Vec3> {
    let v = Vec3::from(v);
    if v.is_finite() {
        Ok(v)
    } else {
        Err((key, format!("must be finite, got {v}")))
    }
}

fn positive(v: Option<f32>, key: &'static str, kind: &str) -> Checked<f32> {
    match v {
        None => Err((key, format!("a {kind} light needs `{key}`"))),
        Some(r) if r > 0.0 && r.is_finite() => Ok(r),
        Some(r) => Err((key, format!("must be finite and > 0, got {r}"))),
    }
}

impl LocalFile {
    /// The keys this entry gives that its kind does not take.
    fn refuse_unused(&self, kind: &str) -> Checked<()> {
        let sized = matches!(kind, "rect" | "disk");
        let unused: [(&'static str, bool); 6] = [
            ("radius", self.radius.is_some() && !matches!(kind, "disk" | "sphere")),
            ("size", self.size.is_some() && kind != "rect"),
            ("inner_angle", self.inner_angle.is_some() && kind != "spot"),
            ("outer_angle", self.outer_angle.is_some() && kind != "spot"),
            ("two_sided", self.two_sided.is_some() && !sized),
            ("camera_visible", self.camera_visible.is_some() && !matches!(kind, "rect" | "disk" | "sphere")),
        ];
        match unused.iter().find(|(_, bad)| *bad) {
            Some((key, _)) => {
                Err((key, format!("a {kind} light takes no `{key}` (docs/lights.md lists each kind's keys)")))
            }
            None => Ok(()),
        }
    }

    /// Light to world (unit scale): `transform`, or `position` facing `aim`
    /// or `direction` (default straight down).
    fn placement(&self) -> Checked<Affine3A> {
        if let Some(m) = self.transform {
            if self.position.is_some() || self.aim.is_some() || self.direction.is_some() {
                return Err((
                    "transform",
                    "give `transform`, or `position` with `aim` or `direction`, not both".into(),
                ));
            }
            let m = Mat4::from_cols_array(&m);
            if !m.is_finite() || m.row(3) != glam::Vec4::W {
                return Err(("transform", "must be finite with a last row of 0 0 0 1".into()));
            }
            let (scale, rotation, translation) = m.to_scale_rotation_translation();
            if !(scale.min_element() > 1e-6) || !rotation.is_finite() {
                return Err(("transform", format!("must be invertible and not mirrored (scale {scale})")));
            }
            return Ok(Affine3A::from_rotation_translation(rotation.normalize(), translation));
        }
        let position =
            finite3(self.position.ok_or(("position", "needs `position` or `transform`".to_string()))?, "position")?;
        let facing = match (self.aim, self.direction) {
            (Some(_), Some(_)) => return Err(("aim", "give `aim` or `direction`, not both".into())),
            (Some(aim), None) => finite3(aim, "aim")? - position,
            (None, Some(d)) => finite3(d, "direction")?,
            (None, None) => -Vec3::Y,
        };
        if facing.length_squared() < 1e-12 {
            let key = if self.aim.is_some() { "aim" } else { "direction" };
            return Err((key, "the light faces no direction (zero vector, or aim at its position)".into()));
        }
        Ok(look_at(position, position + facing))
    }

    fn check(&self, kind: &str, key: &str) -> Checked<Light> {
        self.refuse_unused(kind)?;
        let intensity = positive(self.intensity, "intensity", kind)?;
        check_light(intensity, self.color)?;
        let exposure = exposure_scale(self.exposure).map_err(|m| ("exposure", m))?;
        if let Some(g) = &self.light_group {
            check_group_name(g, &format!("{key}.light_group")).map_err(|e| ("light_group", e.to_string()))?;
        }
        let world_from_light = self.placement()?;
        let kind = match kind {
            "point" => LightKind::Point,
            "spot" => {
                let outer = positive(self.outer_angle, "outer_angle", kind)?;
                let inner = self.inner_angle.unwrap_or(0.0);
                if !(outer <= 90.0) {
                    return Err(("outer_angle", format!("must be at most 90 degrees, got {outer}")));
                }
                if !(inner >= 0.0 && inner <= outer) {
                    return Err((
                        "inner_angle",
                        format!("spot angles out of order: inner {inner} must be within 0..=outer {outer} degrees"),
                    ));
                }
                LightKind::Spot { outer: outer.to_radians(), blend: 1.0 - inner / outer }
            }
            "rect" => {
                let size = self.size.ok_or(("size", "a rect light needs `size = [width, height]`".to_string()))?;
                if !size.iter().all(|s| *s > 0.0 && s.is_finite()) {
                    return Err(("size", format!("both sides must be finite and > 0, got {size:?}")));
                }
                LightKind::Rect { size: Vec2::from(size) }
            }
            "disk" => LightKind::Disk { radius: positive(self.radius, "radius", kind)? },
            _ => LightKind::Sphere { radius: positive(self.radius, "radius", kind)? },
        };
        Ok(Light {
            name: self.name.clone().unwrap_or_else(|| key.to_string()),
            kind,
            world_from_light,
            emission: Vec3::from(self.color) * intensity * exposure,
            two_sided: self.two_sided.unwrap_or(false),
            camera_visible: self.camera_visible.unwrap_or(false),
            light_group: self.light_group.clone(),
        })
    }
}

impl Lights {
    /// The sun, in scene units.
    pub(crate) fn sun(&self) -> Option<Sun> {
        self.sun.map(|s| Sun {
            direction: Vec3::from(s.direction).normalize(),
            angular_diameter: s.angular_diameter.to_radians(),
            irradiance: Vec3::from(s.color) * s.intensity,
        })
    }

    /// The uniform sky.
    pub(crate) fn sky(&self) -> Sky {
        Sky { radiance: Vec3::from(self.sky.color) * self.sky.intensity }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn check(text: &str) -> std::result::Result<Lights, String> {
        let file: LightsFile = toml::from_str(text).map_err(|e| e.to_string())?;
        let cx = Context { path: std::path::Path::new("s.toml"), text, base: PathBuf::from(".") };
        file.check(&cx).map_err(|e| e.to_string())
    }

    #[test]
    fn local_lights_are_placed_and_scaled() {
        let l = check(
            "[[spot]]\nposition = [1.0, 4.0, 0.0]\naim = [1.0, 0.0, 0.0]\nintensity = 2.0\nexposure = 1.0\n\
             inner_angle = 15.0\nouter_angle = 30.0\ncolor = [1.0, 0.5, 0.25]\n\
             [[rect]]\nname = \"window\"\nposition = [0.0, 2.0, 0.0]\ndirection = [0.0, 0.0, 1.0]\nsize = [2.0, 1.0]\nintensity = 3.0\ntwo_sided = true\n",
        )
        .unwrap();
        assert_eq!(l.local.len(), 2);
        let spot = &l.local[0];
        assert_eq!(spot.name, "lights.spot[0]");
        assert_eq!(spot.emission, Vec3::new(4.0, 2.0, 1.0));
        assert!(spot.facing().abs_diff_eq(-Vec3::Y, 1e-6), "{}", spot.facing());
        assert!(spot.position().abs_diff_eq(Vec3::new(1.0, 4.0, 0.0), 1e-6));
        let LightKind::Spot { outer, blend } = spot.kind else { panic!("{:?}", spot.kind) };
        assert!((outer - 30f32.to_radians()).abs() < 1e-6 && (blend - 0.5).abs() < 1e-6);
        let rect = &l.local[1];
        assert_eq!(rect.name, "window");
        assert!(rect.two_sided && rect.facing().abs_diff_eq(Vec3::Z, 1e-6));
    }

    #[test]
    fn bad_lights_name_their_field() {
        for (text, field) in [
            ("[[point]]\nposition = [0.0, 1.0, 0.0]\nintensity = 0.0", "lights.point[0].intensity"),
            ("[[point]]\nposition = [0.0, 1.0, 0.0]\nintensity = -2.0", "lights.point[0].intensity"),
            ("[[point]]\nposition = [0.0, 1.0, 0.0]", "lights.point[0].intensity"),
            ("[[point]]\nintensity = 1.0", "lights.point[0].position"),
            ("[[disk]]\nposition = [0.0, 1.0, 0.0]\nintensity = 1.0\nradius = 0.0", "lights.disk[0].radius"),
            ("[[sphere]]\nposition = [0.0, 1.0, 0.0]\nintensity = 1.0\nradius = -1.0", "lights.sphere[0].radius"),
            ("[[rect]]\nposition = [0.0, 1.0, 0.0]\nintensity = 1.0\nsize = [1.0, 0.0]", "lights.rect[0].size"),
            ("[[rect]]\nposition = [0.0, 1.0, 0.0]\nintensity = 1.0\nradius = 1.0", "lights.rect[0].radius"),
            (
                "[[spot]]\nposition = [0.0, 1.0, 0.0]\nintensity = 1.0\ninner_angle = 40.0\nouter_angle = 30.0",
                "lights.spot[0].inner_angle",
            ),
            (
                "[[spot]]\nposition = [0.0, 1.0, 0.0]\nintensity = 1.0\nouter_angle = 120.0",
                "lights.spot[0].outer_angle",
            ),
            (
                "[[spot]]\nposition = [0.0, 1.0, 0.0]\nintensity = 1.0\nouter_angle = 30.0\naim = [0.0, 1.0, 0.0]",
                "lights.spot[0].aim",
            ),
            ("[[point]]\nposition = [0.0, 1.0, 0.0]\nintensity = 1.0\nexposure = 1000.0", "lights.point[0].exposure"),
            (
                "[[point]]\nposition = [0.0, 1.0, 0.0]\nintensity = 1.0\ncolor = [1.0, -1.0, 0.0]",
                "lights.point[0].color",
            ),
        ] {
            let e = check(text).unwrap_err();
            assert!(e.contains(field), "{text}\n -> {e}");
        }
        assert!(check("[dome]\nfile = \"nowhere.hdr\"").unwrap_err().contains("lights.dome.file"));
    }

    /// Each factor within its range, their product past f32 (issue 49).
    #[test]
    fn a_light_whose_product_overflows_is_refused_naming_it() {
        let big = "intensity = 3e38\ncolor = [2.0, 1.0, 1.0]";
        for (text, field, product) in [
            (
                format!("[[point]]\nposition = [0.0, 1.0, 0.0]\n{big}"),
                "lights.point[0]`",
                "intensity x colour x 2^exposure",
            ),
            (
                "[[rect]]\nposition = [0.0, 1.0, 0.0]\nsize = [1.0, 1.0]\nintensity = 1e30\nexposure = 40.0".into(),
                "lights.rect[0]`",
                "intensity x colour x 2^exposure",
            ),
            (format!("[sun]\ndirection = [0.0, 1.0, 0.0]\n{big}"), "lights.sun`", "intensity x colour"),
            (format!("[sky]\n{big}"), "lights.sky`", "intensity x colour"),
            (format!("[dome]\nfile = \"Cargo.toml\"\n{big}"), "lights.dome`", "intensity x colour x 2^exposure"),
        ] {
            let e = check(&text).unwrap_err();
            assert!(e.contains(field) && e.contains(product) && e.contains("overflows"), "{text}\n -> {e}");
        }
        // Huge but finite passes.
        check("[[point]]\nposition = [0.0, 1.0, 0.0]\nintensity = 1e30\nexposure = 20.0").unwrap();
    }

    #[test]
    fn a_transform_places_the_light_without_its_scale() {
        // 90 degrees about +X (local -Z -> world +Y), scaled by 2, at (1, 2, 3).
        let m = Mat4::from_scale_rotation_translation(
            Vec3::splat(2.0),
            glam::Quat::from_rotation_x(std::f32::consts::FRAC_PI_2),
            Vec3::new(1.0, 2.0, 3.0),
        );
        let text = format!("[[disk]]\nradius = 0.5\nintensity = 1.0\ntransform = {:?}", m.to_cols_array());
        let l = check(&text).unwrap();
        assert!(l.local[0].facing().abs_diff_eq(Vec3::Y, 1e-5), "{}", l.local[0].facing());
        assert!((l.local[0].world_from_light.matrix3.determinant() - 1.0).abs() < 1e-5);
    }
}
