//! Passes a compositor relights with: the beauty split by light path
//! (diffuse, specular and transmission, direct and indirect, emission,
//! environment) and by light group, and the world position of the first hit.
//!
//! Both splits are of the same samples as the beauty: each contribution a
//! path adds to a sample's radiance goes, whole, to one light-path pass and
//! to one light group, so each family sums to the beauty per pixel but for
//! float rounding (docs/render.md, "Passes"). The classes follow Cycles'
//! passes (docs/render.md maps them and gives the light path expressions):
//! - emission, environment: what the camera ray itself sees (an emissive
//!   surface or a visible lamp; the dome, sky or sun behind everything);
//! - at the camera vertex, next-event estimation splits by lobe (the BSDF's
//!   diffuse and specular parts evaluated apart) and is direct; a bounce
//!   splits everything that comes back along it by the same lobe fractions
//!   of the BSDF value in its direction, so each pass is unbiased on its
//!   own; light found by that bounce ray is direct, the rest indirect;
//! - through glass at the camera vertex (a delta lobe, one event picked
//!   with its probability): transmission, or specular for its reflection;
//! - scattered by the air on the camera ray (render::atmosphere): atmosphere,
//!   whatever light it brings, so comp can regrade or remove the haze;
//!   with the camera ray's transmittance through the air to what it shows
//!   ([`TRANSMITTANCE`], not light: beauty = transmittance x what is behind
//!   + atmosphere, docs/compositing.md).

use std::collections::BTreeMap;

use glam::Vec3;

use crate::error::{Error, Result};
use crate::scene::lights::SceneLights;
use crate::scene::Library;

/// The light-path passes, in the order a file lists them.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum LightPath {
    /// Diffuse lobe at the first surface, light straight from a light.
    DiffuseDirect,
    /// Diffuse lobe at the first surface, light after further bounces.
    DiffuseIndirect,
    /// Specular (glossy) lobe at the first surface, direct.
    SpecularDirect,
    /// Specular lobe at the first surface, indirect.
    SpecularIndirect,
    /// Refracted through glass at the first surface (direct and indirect).
    Transmission,
    /// Emissive surfaces and lamps the camera sees.
    Emission,
    /// The dome, sky or sun the camera sees behind everything.
    Environment,
    /// Light the air (render::atmosphere) scatters into the camera ray,
    /// by every light, direct and indirect.
    Atmosphere,
}

impl LightPath {
    /// Every light-path pass, in file order.
    pub const ALL: [LightPath; 8] = [
        LightPath::DiffuseDirect,
        LightPath::DiffuseIndirect,
        LightPath::SpecularDirect,
        LightPath::SpecularIndirect,
        LightPath::Transmission,
        LightPath::Emission,
        LightPath::Environment,
        LightPath::Atmosphere,
    ];

    /// Its name in files and in `render.passes` (Nuke's layer name).
    pub fn name(self) -> &'static str {
        match self {
            LightPath::DiffuseDirect => "diffuse_direct",
            LightPath::DiffuseIndirect => "diffuse_indirect",
            LightPath::SpecularDirect => "specular_direct",
            LightPath::SpecularIndirect => "specular_indirect",
            LightPath::Transmission => "transmission",
            LightPath::Emission => "emission",
            LightPath::Environment => "environment",
            LightPath::Atmosphere => "atmosphere",
        }
    }
}

/// Which passes a render writes, beyond beauty and the data passes.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct PassSet {
    /// Light-path passes on, in [`LightPath::ALL`] order.
    pub light_paths: Vec<LightPath>,
    /// One pass per light group (`lg_<name>`).
    pub light_groups: bool,
    /// The light the crowd's shadows took from the set (`shadow`).
    pub shadow: bool,
    /// The camera ray's transmittance through the air ([`TRANSMITTANCE`]).
    pub transmittance: bool,
    /// World position of the first hit (`P.X`, `P.Y`, `P.Z`).
    pub position: bool,
}

/// What `render.passes` and `--passes` accept besides the light-path names.
pub const LIGHT_GROUPS: &str = "light_groups";
/// The shadow pass's name in `render.passes` and in files.
pub const SHADOW: &str = "shadow";
/// The transmittance pass's name in `render.passes` and in files: the
/// camera ray's transmittance through the air (render::atmosphere) up to
/// what it shows, per channel, premultiplied by coverage like colour.
pub const TRANSMITTANCE: &str = "atmosphere_transmittance";

/// The pass a denoised film keeps its noisy beauty in (`noisy.R/G/B`;
/// render::denoise), first in the file.
pub const NOISY: &str = "noisy";
/// The position pass's name in `render.passes`.
pub const POSITION: &str = "P";
/// Every pass and light group.
pub const ALL: &str = "all";

impl PassSet {
    /// Every pass: each light path, the light groups and position.
    pub fn all() -> PassSet {
        PassSet {
            light_paths: LightPath::ALL.to_vec(),
            light_groups: true,
            shadow: true,
            transmittance: true,
            position: true,
        }
    }

    /// The passes a shot writes: in clear air (`hazy` false) without the
    /// air's two (`atmosphere` and [`TRANSMITTANCE`]), which would hold
    /// nothing (no light, a transmittance of 1), as there is no sun pass
    /// without a sun; named or from `all` alike.
    pub fn in_air(mut self, hazy: bool) -> PassSet {
        if !hazy {
            self.light_paths.retain(|&p| p != LightPath::Atmosphere);
            self.transmittance = false;
        }
        self
    }

    /// Parses pass names (`diffuse_direct`, ..., `light_groups`, `P`,
    /// `all`); `field` names where they came from in errors.
    pub fn parse<S: AsRef<str>>(names: &[S], field: &str) -> Result<PassSet> {
        let mut set = PassSet::default();
        for name in names {
            let name = name.as_ref().trim();
            match name {
                ALL => set = PassSet::all(),
                LIGHT_GROUPS => set.light_groups = true,
                POSITION => set.position = true,
                SHADOW => set.shadow = true,
                TRANSMITTANCE => set.transmittance = true,
                _ => match LightPath::ALL.iter().find(|p| p.name() == name) {
                    Some(&p) if !set.light_paths.contains(&p) => set.light_paths.push(p),
                    Some(_) => {}
                    None => {
                        let known: Vec<&str> = LightPath::ALL.iter().map(|p| p.name()).collect();
                        return Err(Error::Usage(format!(
                            "{field}: unknown pass `{name}` (known: {}, {LIGHT_GROUPS}, {SHADOW}, {TRANSMITTANCE}, \
                             {POSITION}, {ALL})",
                            known.join(", ")
                        )));
                    }
                },
            }
        }
        set.light_paths.sort();
        Ok(set)
    }

    /// Whether any pass is on (a render without passes does no pass work).
    pub fn any(&self) -> bool {
        !self.light_paths.is_empty() || self.light_groups || self.shadow || self.transmittance || self.position
    }

    /// RGB(XYZ) channel triples per pixel the film holds for these passes.
    pub fn triples(&self, light_groups: usize) -> usize {
        self.light_paths.len()
            + if self.light_groups { light_groups } else { 0 }
            + self.shadow as usize
            + self.transmittance as usize
            + self.position as usize
    }
}

/// Where a pass goes among a file's passes: light paths in [`LightPath::ALL`]
/// order, light groups by name, the shadow pass, the transmittance, then `P`.
pub fn file_order(name: &str) -> (usize, &str) {
    match LightPath::ALL.iter().position(|p| p.name() == name) {
        Some(i) => (i + 1, ""),
        None if name == NOISY => (0, ""),
        None if name == SHADOW => (LightPath::ALL.len() + 2, name),
        None if name == TRANSMITTANCE => (LightPath::ALL.len() + 3, name),
        None if name == POSITION => (LightPath::ALL.len() + 4, name),
        None => (LightPath::ALL.len() + 1, name),
    }
}

/// The most light groups a render writes: each is three channels per
/// pixel in every layer, so a set with a thousand unnamed practicals must
/// name its groups (`light_group`) rather than write three thousand channels.
pub const MAX_LIGHT_GROUPS: usize = 64;

/// The light groups of a shot and which group each light and emissive
/// material is in. Built from the lights and the library alone, so every
/// layer and frame of a shot has the same groups in the same order (the
/// comp stacks them channel by channel).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LightGroups {
    /// Group names, sorted.
    pub names: Vec<String>,
    sun: u16,
    environment: u16,
    local: Vec<u16>,
    materials: Vec<u16>,
}

/// The group a light is in when it names none: its own name, made a valid
/// channel layer name (letters, digits, `_` and `-`; anything else `_`).
pub fn default_group(name: &str) -> String {
    let cleaned: String =
        name.chars().map(|c| if c.is_ascii_alphanumeric() || c == '_' || c == '-' { c } else { '_' }).collect();
    if cleaned.is_empty() {
        "unnamed".into()
    } else {
        cleaned
    }
}

/// Checks a light group name a lighter gave (`field` for the message).
pub fn check_group_name(name: &str, field: &str) -> Result<()> {
    if name.is_empty() || !name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-') {
        return Err(Error::Usage(format!(
            "{field}: light group `{name}` must be letters, digits, `_` or `-` (it names EXR channels lg_{name}.R/G/B)"
        )));
    }
    Ok(())
}

impl LightGroups {
    /// The groups of `lights` and of the emissive materials of `lib`.
    pub fn new(lights: &SceneLights, lib: &Library) -> Result<LightGroups> {
        let emission: Vec<Vec3> = lib.materials.iter().map(|m| m.emission).collect();
        LightGroups::with_emission(lights, lib, &emission)
    }

    /// [`Self::new`] with each material's emission as authored
    /// (`emission[i]` for material i): a group whose gain is 0 still is a
    /// group of the shot, though its materials no longer emit.
    pub fn with_emission(lights: &SceneLights, lib: &Library, emission: &[Vec3]) -> Result<LightGroups> {
        let named = &lights.groups;
        let sun = named.sun.clone().unwrap_or_else(|| "sun".into());
        let environment = if lights.dome.is_some() {
            named.dome.clone().unwrap_or_else(|| "dome".into())
        } else {
            named.sky.clone().unwrap_or_else(|| "sky".into())
        };
        let local: Vec<String> =
            lights.local.iter().map(|l| l.light_group.clone().unwrap_or_else(|| default_group(&l.name))).collect();
        for name in named.materials.keys() {
            if !lib.materials.iter().any(|m| &m.name == name || m.label() == name) {
                return Err(Error::Usage(format!(
                    "lights.groups.materials: no material is named `{name}` (in the set, the wardrobes or the rigs)"
                )));
            }
        }
        let materials: Vec<Option<String>> = lib
            .materials
            .iter()
            .zip(emission.iter().chain(std::iter::repeat(&Vec3::ZERO)))
            .map(|(m, e)| {
                // Named by the material's own name, not its file's path, so a
                // saved gain holds wherever the shot is read from.
                (e.max_element() > 0.0).then(|| {
                    let given = named.materials.get(&m.name).or_else(|| named.materials.get(m.label()));
                    given.cloned().unwrap_or_else(|| default_group(m.label()))
                })
            })
            .collect();
        let mut all: BTreeMap<&str, u16> = BTreeMap::new();
        // No sun, no sun group (an always-black pass); its index falls back to the environment's.
        let sun_light = lights.sun.is_some().then_some(&sun);
        for name in sun_light.into_iter().chain([&environment]).chain(&local).chain(materials.iter().flatten()) {
            all.insert(name, 0);
        }
        if all.len() > MAX_LIGHT_GROUPS {
            return Err(Error::Usage(format!(
                "the shot has {} light groups (a light or emissive material that names none is a group of its \
                 own); at most {MAX_LIGHT_GROUPS} are written: give lights a `light_group` (or map materials in \
                 lights.groups.materials)",
                all.len()
            )));
        }
        for (i, v) in all.values_mut().enumerate() {
            *v = i as u16;
        }
        let index = |name: &str| all[name];
        Ok(LightGroups {
            sun: index(sun_light.unwrap_or(&environment)),
            environment: index(&environment),
            local: local.iter().map(|n| index(n)).collect(),
            materials: materials.iter().map(|n| n.as_deref().map_or(u16::MAX, index)).collect(),
            names: all.keys().map(|s| s.to_string()).collect(),
        })
    }

    /// The group of the sun (the shot's, the set's distant lights when
    /// they name none, and the dome's own sun is the dome's).
    pub(crate) fn sun(&self) -> u16 {
        self.sun
    }

    /// The group of the dome, or of the uniform sky when there is none.
    pub(crate) fn environment(&self) -> u16 {
        self.environment
    }

    /// The group of local light `i` of the scene.
    pub(crate) fn local(&self, i: usize) -> u16 {
        self.local.get(i).copied().unwrap_or(self.sun)
    }

    /// The group of material `m`'s emission.
    pub(crate) fn material(&self, m: u32) -> u16 {
        self.materials.get(m as usize).copied().filter(|&g| g != u16::MAX).unwrap_or(self.environment)
    }
}

/// One sample's light, split as the passes split it.
#[derive(Clone, Debug, Default)]
pub(crate) struct Split {
    /// Per [`LightPath`] (all seven, whichever are written).
    pub(crate) paths: [Vec3; LightPath::ALL.len()],
    /// Per light group.
    pub(crate) groups: Vec<Vec3>,
    /// Direct light at a set surface that the crowd's shadows took away
    /// (not part of the beauty: beauty + shadow is the set unshadowed by the crowd).
    pub(crate) shadow: Vec3,
    /// World position of the first hit.
    pub(crate) position: Vec3,
    /// The camera ray's transmittance through the air up to what it shows
    /// (0 where the sample shows nothing: premultiplied, like colour).
    pub(crate) transmittance: f32,
}

impl Split {
    /// Empty, with room for `groups` light groups.
    pub(crate) fn new(groups: usize) -> Split {
        Split {
            paths: [Vec3::ZERO; LightPath::ALL.len()],
            groups: vec![Vec3::ZERO; groups],
            shadow: Vec3::ZERO,
            position: Vec3::ZERO,
            transmittance: 0.0,
        }
    }

    /// Back to empty for the next sample.
    pub(crate) fn clear(&mut self) {
        self.paths = [Vec3::ZERO; LightPath::ALL.len()];
        self.groups.fill(Vec3::ZERO);
        self.shadow = Vec3::ZERO;
        self.position = Vec3::ZERO;
        self.transmittance = 0.0;
    }

    /// Adds another sample's split to this sum of a pixel's samples
    /// (position aside: a pixel takes its nearest sample's).
    pub(crate) fn add_sample(&mut self, sample: &Split) {
        for (sum, c) in self.paths.iter_mut().zip(&sample.paths) {
            *sum += *c;
        }
        for (sum, c) in self.groups.iter_mut().zip(&sample.groups) {
            *sum += *c;
        }
        self.shadow += sample.shadow;
        self.transmittance += sample.transmittance;
    }

    /// Adds contribution `c` of light group `group` along path `path`.
    #[inline]
    pub(crate) fn add(&mut self, c: Vec3, path: LightPath, group: u16) {
        self.paths[path as usize] += c;
        if let Some(g) = self.groups.get_mut(group as usize) {
            *g += c;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_names_all_and_refuses_unknown_ones() {
        let set =
            PassSet::parse(&["specular_direct", "diffuse_direct", "P", "diffuse_direct"], "render.passes").unwrap();
        assert_eq!(set.light_paths, [LightPath::DiffuseDirect, LightPath::SpecularDirect]);
        assert!(set.position && !set.light_groups);
        assert_eq!(PassSet::parse(&["all"], "x").unwrap(), PassSet::all());
        let e = PassSet::parse(&["diffuse"], "--passes").unwrap_err().to_string();
        assert!(e.contains("--passes: unknown pass `diffuse`") && e.contains("diffuse_direct"), "{e}");
        assert!(!PassSet::parse::<&str>(&[], "x").unwrap().any());
        let t = PassSet::parse(&["atmosphere_transmittance"], "x").unwrap();
        assert!(t.transmittance && t.any() && t.triples(0) == 1);
    }

    #[test]
    fn clear_air_drops_the_air_passes_named_or_from_all() {
        let all = PassSet::all();
        assert_eq!(all.clone().in_air(true), all);
        let clear = all.clone().in_air(false);
        assert!(!clear.transmittance && !clear.light_paths.contains(&LightPath::Atmosphere));
        assert_eq!(clear.triples(3), all.triples(3) - 2);
        let named = PassSet::parse(&["atmosphere", "atmosphere_transmittance", "P"], "x").unwrap().in_air(false);
        assert_eq!(named, PassSet { position: true, ..Default::default() });
    }

    #[test]
    fn group_names_are_channel_names() {
        assert_eq!(default_group("lights.rect[2]"), "lights_rect_2_");
        assert_eq!(default_group("Lamp-1"), "Lamp-1");
        assert!(check_group_name("street_lamps", "lights.point[0].light_group").is_ok());
        let e = check_group_name("street lamps", "lights.point[0].light_group").unwrap_err().to_string();
        assert!(e.contains("lights.point[0].light_group") && e.contains("`street lamps`"), "{e}");
    }

    #[test]
    fn an_emissive_material_is_grouped_by_its_own_name_wherever_the_shot_is_read_from() {
        use crate::scene::Material;
        let lib = |set: &str| Library {
            materials: vec![
                Material { name: format!("{set}#ShopWindow"), emission: Vec3::ONE, ..Material::default() },
                Material { name: format!("{set}#Sign"), emission: Vec3::ONE, ..Material::default() },
                Material { name: format!("{set}#Wall"), ..Material::default() },
            ],
            ..Library::default()
        };
        let lights = SceneLights::default();
        let here = LightGroups::new(&lights, &lib("set/set.glb")).unwrap();
        let there = LightGroups::new(&lights, &lib("../shots/demo/set/set.glb")).unwrap();
        assert_eq!(here.names, ["ShopWindow", "Sign", "sky"]);
        assert_eq!(here, there);
        // `lights.groups.materials` takes the material's own name or its whole one.
        let mut named = lights.clone();
        named.groups.materials.insert("ShopWindow".into(), "windows".into());
        named.groups.materials.insert("set/set.glb#Sign".into(), "windows".into());
        assert_eq!(LightGroups::new(&named, &lib("set/set.glb")).unwrap().names, ["sky", "windows"]);
        named.groups.materials.insert("Door".into(), "windows".into());
        let e = LightGroups::new(&named, &lib("set/set.glb")).unwrap_err().to_string();
        assert!(e.contains("`Door`"), "{e}");
    }
}
