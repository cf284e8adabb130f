//! Cryptomatte ID mattes (Psyop's open specification, version 1.2.0) for
//! agents, their parts and materials: encoding during the render, and a decoder.
//!
//! - IDs: MurmurHash3_x86_32 (seed 0) of the UTF-8 name, converted to a
//!   float32 by `uint32_to_float32` (the exponent kept in 1..=254, so no id
//!   is zero, denormal, inf or NaN). The hash value 0 (float 0.0) means
//!   "no object".
//! - Names: agent matte `CryptoAgent`: `agent_<cache id>`; part matte
//!   `CryptoPart`: `agent_<cache id>/<rig slot name>`. Visible set geometry is
//!   `set/<object>` in both (the set object's unique name from its glTF node,
//!   [`crate::scene::gltf::set_object_names`]), or `set` for set geometry
//!   without an object name. Material matte `CryptoMaterial`: the name of the
//!   material ([`material_name`]: `wardrobe/material`, or a glTF material's
//!   own name), agents and set alike. Samples that hit nothing (sky, escaped
//!   rays) or a holdout record id 0 and are not written to any rank.
//! - Ranking: each camera sample has weight 1 (the Gaussian pixel filter is
//!   importance-sampled), so an id's coverage is (its samples) / spp, summed
//!   per pixel in sample order and ranked by coverage, ties by id bits:
//!   deterministic for any thread count.
//!
//! See docs/cryptomatte.md for channel layout, header and compositing notes.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::Path;

use super::exr::RawPart;
use crate::error::{Error, IoContext, Result};
use crate::scene::{vis, Instance, Material};

/// Type name of the agent matte (channels `CryptoAgent00.R` ...).
pub const AGENT_MATTE: &str = "CryptoAgent";
/// Type name of the part matte (channels `CryptoPart00.R` ...).
pub const PART_MATTE: &str = "CryptoPart";
/// Type name of the material matte (channels `CryptoMaterial00.R` ...).
pub const MATERIAL_MATTE: &str = "CryptoMaterial";
/// The matte types a render writes, in [`CryptoNames`] order (agent, part,
/// material: the index [`CryptoNames::manifest`] takes). Films and files
/// list them sorted by type name instead.
pub const MATTES: [&str; 3] = [AGENT_MATTE, PART_MATTE, MATERIAL_MATTE];
/// Name of set (non-agent) geometry that has no object name, in the agent
/// and part mattes; named set objects are `set/<object>` ([`set_object_name`]).
pub const SET_NAME: &str = "set";
/// Ranks written per matte (the spec's suggested default: 3 RGBA layers).
pub const RANKS: usize = 6;
/// Distinct ids one pixel can accumulate while rendering. More distinct
/// objects than this under one pixel is rare (16 spp can see at most 16); the
/// samples of ids that do not fit are dropped (they would rank below the
/// kept ones only if they arrive late, so mattes stay usable).
pub const ACCUMULATOR_CAPACITY: usize = 32;
/// The `hash` header value.
pub const HASH: &str = "MurmurHash3_32";
/// The `conversion` header value.
pub const CONVERSION: &str = "uint32_to_float32";

/// MurmurHash3_x86_32 of `bytes` with `seed`.
pub fn murmur3_32(bytes: &[u8], seed: u32) -> u32 {
    const C1: u32 = 0xcc9e_2d51;
    const C2: u32 = 0x1b87_3593;
    let mut h = seed;
    let mut chunks = bytes.chunks_exact(4);
    for c in &mut chunks {
        let mut k = u32::from_le_bytes([c[0], c[1], c[2], c[3]]);
        k = k.wrapping_mul(C1).rotate_left(15).wrapping_mul(C2);
        h ^= k;
        h = h.rotate_left(13).wrapping_mul(5).wrapping_add(0xe654_6b64);
    }
    let tail = chunks.remainder();
    if !tail.is_empty() {
        let mut k = 0u32;
        for (i, &b) in tail.iter().enumerate() {
            k ^= (b as u32) << (8 * i);
        }
        h ^= k.wrapping_mul(C1).rotate_left(15).wrapping_mul(C2);
    }
    h ^= bytes.len() as u32;
    h ^= h >> 16;
    h = h.wrapping_mul(0x85eb_ca6b);
    h ^= h >> 13;
    h = h.wrapping_mul(0xc2b2_ae35);
    h ^ (h >> 16)
}

/// The spec's `uint32_to_float32`: the hash's bits as a float, with an
/// exponent of 0 or 255 (zero, denormal, inf, NaN) toggled to 1 or 254.
pub fn hash_to_float(hash: u32) -> f32 {
    let exponent = (hash >> 23) & 0xff;
    let bits = if exponent == 0 || exponent == 255 { hash ^ (1 << 23) } else { hash };
    f32::from_bits(bits)
}

/// The float id of a name (what the pixels hold).
pub fn name_id(name: &str) -> f32 {
    hash_to_float(murmur3_32(name.as_bytes(), 0))
}

/// The manifest's spelling of an id: its float bits as 8 lower-case hex digits.
pub fn id_hex(id: f32) -> String {
    format!("{:08x}", id.to_bits())
}

/// The header key of a matte type: the first 7 hex digits of its name's hash.
pub fn layer_key(type_name: &str) -> String {
    format!("{:08x}", murmur3_32(type_name.as_bytes(), 0))[..7].to_string()
}

/// `agent_<id>`: an agent's name in the agent matte.
pub fn agent_name(agent: u32) -> String {
    format!("agent_{agent}")
}

/// `agent_<id>/<slot>`: a part's name in the part matte.
pub fn part_name(agent: u32, slot: &str) -> String {
    format!("agent_{agent}/{slot}")
}

/// `set/<object>`: a set object's name in the agent and part mattes, from
/// its unique name in the set file.
pub fn set_object_name(object: &str) -> String {
    format!("{SET_NAME}/{object}")
}

/// A material's name in the material matte, from its library name: glTF
/// materials are `<file>#<material>` in the library and keep `<material>`,
/// the name given in the file (the same on every machine, wherever the file
/// lives); wardrobe materials (`wardrobe/material`, no `#`) keep theirs.
pub fn material_name(library_name: &str) -> &str {
    library_name.rsplit_once('#').map_or(library_name, |(_, name)| name)
}

/// One pixel's running (id, sample count) table: fixed capacity, no heap.
#[derive(Clone, Debug)]
pub struct RankAccumulator {
    ids: [u32; ACCUMULATOR_CAPACITY],
    counts: [u32; ACCUMULATOR_CAPACITY],
    len: usize,
}

impl Default for RankAccumulator {
    fn default() -> Self {
        RankAccumulator { ids: [0; ACCUMULATOR_CAPACITY], counts: [0; ACCUMULATOR_CAPACITY], len: 0 }
    }
}

impl RankAccumulator {
    /// Adds one sample (weight 1) of the id with float bits `id_bits`; 0 (no
    /// object) is ignored: coverage is normalised by the pixel's sample count.
    pub fn add(&mut self, id_bits: u32) {
        if id_bits == 0 {
            return;
        }
        if let Some(i) = self.ids[..self.len].iter().position(|&x| x == id_bits) {
            self.counts[i] += 1;
        } else if self.len < ACCUMULATOR_CAPACITY {
            self.ids[self.len] = id_bits;
            self.counts[self.len] = 1;
            self.len += 1;
        }
    }

    /// Writes the top `out.len()` (id, coverage) pairs, coverage = count /
    /// `samples`, highest first, ties by id bits; unused ranks are (0, 0).
    pub fn write_ranked(&self, samples: u32, out: &mut [[f32; 2]]) {
        let mut order: [(u32, u32); ACCUMULATOR_CAPACITY] = [(0, 0); ACCUMULATOR_CAPACITY];
        for (i, o) in order.iter_mut().enumerate().take(self.len) {
            *o = (self.counts[i], self.ids[i]);
        }
        let order = &mut order[..self.len];
        order.sort_unstable_by(|a, b| b.0.cmp(&a.0).then(a.1.cmp(&b.1)));
        let inv = 1.0 / samples.max(1) as f32;
        for (r, slot) in out.iter_mut().enumerate() {
            *slot = match order.get(r) {
                Some(&(count, id)) => [f32::from_bits(id), count as f32 * inv],
                None => [0.0, 0.0],
            };
        }
    }
}

/// One Cryptomatte type (e.g. `CryptoAgent`) of one image: the ranked
/// (id, coverage) pairs of every pixel and the manifest.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Cryptomatte {
    /// Type name (channel prefix, `cryptomatte/<key>/name`).
    pub name: String,
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Ranks per pixel.
    pub ranks: usize,
    /// Row-major, top row first; pixel `i` rank `r` at `i * ranks + r`.
    pub pairs: Vec<[f32; 2]>,
    /// Name -> float id bits.
    pub manifest: BTreeMap<String, u32>,
}

impl Cryptomatte {
    /// An empty (all id 0) matte.
    pub fn new(name: &str, width: u32, height: u32, ranks: usize) -> Cryptomatte {
        Cryptomatte {
            name: name.to_string(),
            width,
            height,
            ranks,
            pairs: vec![[0.0; 2]; width as usize * height as usize * ranks],
            manifest: BTreeMap::new(),
        }
    }

    /// The header key (`cryptomatte/<key>/...`).
    pub fn key(&self) -> String {
        layer_key(&self.name)
    }

    /// The ranks of pixel `i`.
    pub fn pixel(&self, i: usize) -> &[[f32; 2]] {
        &self.pairs[i * self.ranks..(i + 1) * self.ranks]
    }

    /// Coverage per pixel of the object with float id `id` (row-major).
    pub fn matte_id(&self, id: f32) -> Vec<f32> {
        let bits = id.to_bits();
        if self.ranks == 0 {
            return vec![0.0; self.width as usize * self.height as usize];
        }
        self.pairs
            .chunks_exact(self.ranks)
            .map(|px| px.iter().filter(|p| p[0].to_bits() == bits).map(|p| p[1]).sum())
            .collect()
    }

    /// Coverage per pixel of `name` (hashed, so the manifest is not needed).
    pub fn matte(&self, name: &str) -> Vec<f32> {
        self.matte_id(name_id(name))
    }

    /// Sum of coverage over all ranks, per pixel.
    pub fn coverage_sum(&self) -> Vec<f32> {
        if self.ranks == 0 {
            return vec![0.0; self.width as usize * self.height as usize];
        }
        self.pairs.chunks_exact(self.ranks).map(|px| px.iter().map(|p| p[1]).sum()).collect()
    }

    /// Every non-zero id with coverage somewhere, as float bits.
    pub fn ids_present(&self) -> BTreeSet<u32> {
        self.pairs.iter().filter(|p| p[1] > 0.0 && p[0].to_bits() != 0).map(|p| p[0].to_bits()).collect()
    }

    /// The manifest as the spec's JSON: `{"name":"<8 hex>", ...}`, names sorted.
    pub fn manifest_json(&self) -> String {
        let map: BTreeMap<&str, String> =
            self.manifest.iter().map(|(k, &v)| (k.as_str(), format!("{v:08x}"))).collect();
        serde_json::to_string(&map).unwrap_or_else(|_| "{}".to_string())
    }
}

/// Parses a manifest (header value or sidecar file): a JSON object of
/// name -> 8-hex-digit float bits. `what` names the source in errors.
pub fn parse_manifest(json: &str, what: &Path) -> Result<BTreeMap<String, u32>> {
    let map: BTreeMap<String, serde_json::Value> = serde_json::from_str(json)
        .map_err(|e| Error::invalid(what, format!("cryptomatte manifest is not a JSON object: {e}")))?;
    let mut out = BTreeMap::new();
    for (name, v) in map {
        let hex = v.as_str().ok_or_else(|| {
            Error::invalid(what, format!("cryptomatte manifest entry `{name}` is not a hex string")).field("manifest")
        })?;
        let bits = u32::from_str_radix(hex, 16).map_err(|_| {
            Error::invalid(what, format!("cryptomatte manifest entry `{name}`: `{hex}` is not hex")).field("manifest")
        })?;
        out.insert(name, bits);
    }
    Ok(out)
}

/// Decodes every Cryptomatte type described in one EXR part's header.
/// `exr_path` resolves sidecar manifests (`manif_file`, relative to the
/// EXR's directory). Types whose rank channels are missing are errors.
/// Sorted by type name.
pub fn decode_part(part: &RawPart, exr_path: &Path) -> Result<Vec<Cryptomatte>> {
    // Keys as `cryptomatte/<key>/<field>`; tolerate Nuke's `exr/` prefix.
    let mut types: BTreeMap<String, BTreeMap<String, String>> = BTreeMap::new();
    for (k, v) in &part.attributes {
        let k = k.strip_prefix("exr/").unwrap_or(k);
        let Some(rest) = k.strip_prefix("cryptomatte/") else { continue };
        if let Some((key, field)) = rest.split_once('/') {
            types.entry(key.to_string()).or_default().insert(field.to_string(), v.clone());
        }
    }
    let n = part.width as usize * part.height as usize;
    let mut out = Vec::new();
    for (key, fields) in types {
        let field = |f: &str| fields.get(f).map(String::as_str);
        let err = |msg: String| Error::invalid(exr_path, msg).field(format!("cryptomatte/{key}"));
        let Some(name) = field("name") else { return Err(err("cryptomatte type has no `name`".into())) };
        if let Some(h) = field("hash").filter(|&h| h != HASH) {
            return Err(err(format!("cryptomatte `{name}` uses hash `{h}`; only {HASH} is supported")));
        }
        if let Some(c) = field("conversion").filter(|&c| c != CONVERSION) {
            return Err(err(format!("cryptomatte `{name}` uses conversion `{c}`; only {CONVERSION} is supported")));
        }
        // Rank channels: {name}00.R/G/B/A, {name}01..., in order; writers
        // spell the suffixes R, r or red (and so on).
        let channel = |level: usize, c: char| {
            let long = match c {
                'R' => "red",
                'G' => "green",
                'B' => "blue",
                _ => "alpha",
            };
            [c.to_string(), c.to_ascii_lowercase().to_string(), long.to_string()]
                .iter()
                .find_map(|suffix| part.channels.get(&format!("{name}{level:02}.{suffix}")))
        };
        let mut levels: Vec<[&Vec<f32>; 4]> = Vec::new();
        while let (Some(r), Some(g), Some(b), Some(a)) = (
            channel(levels.len(), 'R'),
            channel(levels.len(), 'G'),
            channel(levels.len(), 'B'),
            channel(levels.len(), 'A'),
        ) {
            levels.push([r, g, b, a]);
        }
        if levels.is_empty() {
            return Err(err(format!("cryptomatte `{name}` has no `{name}00.R/G/B/A` channels")));
        }
        if levels.iter().flatten().any(|c| c.len() != n) {
            return Err(err(format!("cryptomatte `{name}` channels do not match the image size")));
        }
        let ranks = levels.len() * 2;
        let mut m = Cryptomatte::new(name, part.width, part.height, ranks);
        for (l, [r, g, b, a]) in levels.iter().enumerate() {
            for i in 0..n {
                m.pairs[i * ranks + 2 * l] = [r[i], g[i]];
                m.pairs[i * ranks + 2 * l + 1] = [b[i], a[i]];
            }
        }
        if let Some(json) = field("manifest") {
            m.manifest = parse_manifest(json, exr_path)?;
        } else if let Some(file) = field("manif_file") {
            let dir = exr_path.parent().unwrap_or(Path::new(""));
            let side = dir.join(file);
            let text = std::fs::read_to_string(&side).at(&side)?;
            m.manifest = parse_manifest(&text, &side)?;
        }
        out.push(m);
    }
    out.sort_by(|a, b| a.name.cmp(&b.name));
    Ok(out)
}

/// Reads every Cryptomatte type of every part of an EXR.
pub fn read(path: &Path) -> Result<Vec<Cryptomatte>> {
    let mut out = Vec::new();
    for part in super::exr::read_parts(path, |_| true)? {
        out.extend(decode_part(&part, path)?);
    }
    Ok(out)
}

/// Where a matte id came from, kept small so 100,000-agent frames stay cheap.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum NameKey {
    Set,
    Agent(u32),
    /// Agent, index into `CryptoNames::slots`.
    Part(u32, u32),
    /// A whole name (set object or material), index into `CryptoNames::labels`.
    Label(u32),
}

/// The name tables of a frame scene's set objects and materials, for
/// [`CryptoNames::new`].
#[derive(Clone, Copy, Debug, Default)]
pub struct NameTables<'a> {
    /// The library's materials, by [`Instance::material`]; a material past
    /// the end is named `material<index>`.
    pub materials: &'a [Material],
    /// Set object names, by a set instance's [`Instance::part`]; a set
    /// instance past the end is named [`SET_NAME`].
    pub set_objects: &'a [String],
}

/// The ids of every instance of one frame scene, for the three mattes, and
/// the way back from an id to its name (for the manifests).
#[derive(Clone, Debug, Default)]
pub struct CryptoNames {
    /// Per instance: [agent, part, material] matte id bits; 0 = nothing.
    ids: Vec<[u32; 3]>,
    names: [HashMap<u32, NameKey>; 3],
    /// Extra names of ids that collide (the manifest lists them all).
    collisions: [Vec<(u32, NameKey)>; 3],
    slots: Vec<String>,
    labels: Vec<String>,
    label_index: HashMap<String, u32>,
}

impl CryptoNames {
    /// Names the instances of a frame scene. `slot_name(agent, part)` gives
    /// the rig slot name of an agent's part index; `None` falls back to
    /// `part<index>`. Set objects and materials are named from `tables`.
    /// Holdouts get id 0 (they are never a first hit anyway).
    pub fn new<'a>(
        instances: &[Instance],
        tables: &NameTables,
        slot_name: impl Fn(u32, u16) -> Option<&'a str>,
    ) -> CryptoNames {
        let mut names = CryptoNames::default();
        let mut slot_index: HashMap<String, u32> = HashMap::new();
        // Id bits per set object (by `part`) and per material, hashed once.
        let mut objects: HashMap<u16, u32> = HashMap::new();
        let mut materials: Vec<Option<u32>> = Vec::new();
        let mut last_agent: Option<(u32, u32)> = None;
        let mut buf = String::new();
        for inst in instances {
            if inst.visibility & vis::HOLDOUT != 0 {
                names.ids.push([0, 0, 0]);
                continue;
            }
            let material = names.material_id(inst.material, tables.materials, &mut materials);
            let Some(agent) = inst.agent else {
                let id = match objects.get(&inst.part) {
                    Some(&id) => id,
                    None => {
                        let (key, id) = match tables.set_objects.get(inst.part as usize) {
                            Some(object) => {
                                let name = set_object_name(object);
                                let id = name_id(&name).to_bits();
                                (names.label(name), id)
                            }
                            None => (NameKey::Set, name_id(SET_NAME).to_bits()),
                        };
                        names.insert(0, id, key);
                        names.insert(1, id, key);
                        objects.insert(inst.part, id);
                        id
                    }
                };
                names.ids.push([id, id, material]);
                continue;
            };
            // An agent's instances are contiguous: hash its name once.
            let agent_id = match last_agent {
                Some((a, id)) if a == agent => id,
                _ => {
                    let id = name_id(&agent_name(agent)).to_bits();
                    names.insert(0, id, NameKey::Agent(agent));
                    last_agent = Some((agent, id));
                    id
                }
            };
            let fallback;
            let slot = match slot_name(agent, inst.part) {
                Some(s) => s,
                None => {
                    fallback = format!("part{}", inst.part);
                    &fallback
                }
            };
            let si = match slot_index.get(slot) {
                Some(&i) => i,
                None => {
                    let i = names.slots.len() as u32;
                    names.slots.push(slot.to_string());
                    slot_index.insert(slot.to_string(), i);
                    i
                }
            };
            buf.clear();
            use std::fmt::Write;
            let _ = write!(buf, "agent_{agent}/{slot}");
            let part_id = name_id(&buf).to_bits();
            names.insert(1, part_id, NameKey::Part(agent, si));
            names.ids.push([agent_id, part_id, material]);
        }
        names
    }

    /// The key of a whole name, stored once.
    fn label(&mut self, name: String) -> NameKey {
        if let Some(&i) = self.label_index.get(&name) {
            return NameKey::Label(i);
        }
        let i = self.labels.len() as u32;
        self.label_index.insert(name.clone(), i);
        self.labels.push(name);
        NameKey::Label(i)
    }

    /// The material matte id bits of library material `material` (hashed
    /// once per material; `cache` by material index).
    fn material_id(&mut self, material: u32, library: &[Material], cache: &mut Vec<Option<u32>>) -> u32 {
        let m = material as usize;
        if cache.len() <= m {
            cache.resize(m + 1, None);
        }
        if let Some(id) = cache[m] {
            return id;
        }
        let name = match library.get(m) {
            Some(mat) => material_name(&mat.name).to_string(),
            None => format!("material{m}"),
        };
        let id = name_id(&name).to_bits();
        let key = self.label(name);
        self.insert(2, id, key);
        cache[m] = Some(id);
        id
    }

    fn insert(&mut self, matte: usize, id: u32, key: NameKey) {
        match self.names[matte].get(&id) {
            None => {
                self.names[matte].insert(id, key);
            }
            Some(&k) if k == key => {}
            Some(_) => {
                if !self.collisions[matte].contains(&(id, key)) {
                    self.collisions[matte].push((id, key));
                }
            }
        }
    }

    /// [agent, part, material] matte id bits of instance `i` (0 = none).
    pub fn ids(&self, instance: u32) -> [u32; 3] {
        self.ids.get(instance as usize).copied().unwrap_or([0; 3])
    }

    fn name(&self, key: NameKey) -> String {
        match key {
            NameKey::Set => SET_NAME.to_string(),
            NameKey::Agent(a) => agent_name(a),
            NameKey::Part(a, s) => part_name(a, self.slots.get(s as usize).map_or("?", String::as_str)),
            NameKey::Label(i) => self.labels.get(i as usize).cloned().unwrap_or_default(),
        }
    }

    /// The manifest of matte `matte` (index into [`MATTES`]: 0 agents, 1
    /// parts, 2 materials) restricted to `present` ids.
    pub fn manifest(&self, matte: usize, present: &BTreeSet<u32>) -> BTreeMap<String, u32> {
        let mut out = BTreeMap::new();
        let Some(names) = self.names.get(matte) else { return out };
        for &id in present {
            if let Some(&k) = names.get(&id) {
                out.insert(self.name(k), id);
            }
        }
        for &(id, k) in &self.collisions[matte] {
            if present.contains(&id) {
                out.insert(self.name(k), id);
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spec_examples() {
        assert_eq!(murmur3_32(b"torus", 0), 4053562365);
        assert_eq!(hash_to_float(4053562365), -1.549_436_2e30);
        assert_eq!(murmur3_32("равнина".as_bytes(), 0), 2518896926);
        assert!((name_id("равнина") - -1.319_263_1e-25).abs() < 1e-31);
        assert_eq!(id_hex(name_id("default")), "42c9679f");
        // Exponent rule: 0 and 255 are moved inside.
        assert_eq!((hash_to_float(0).to_bits() >> 23) & 0xff, 1);
        assert_eq!((hash_to_float(0x7f80_0001).to_bits() >> 23) & 0xff, 254);
        assert!(hash_to_float(u32::MAX).is_finite());
        // The keys and ids quoted in docs/cryptomatte.md.
        assert_eq!((layer_key(AGENT_MATTE).as_str(), layer_key(PART_MATTE).as_str()), ("f7945dc", "3201c4f"));
        assert_eq!(layer_key(MATERIAL_MATTE), MATERIAL_KEY_IN_DOCS);
        assert_eq!(id_hex(name_id(&agent_name(78))), "26e5095d");
        assert_eq!(id_hex(name_id(SET_NAME)), "5ecc6fe8");
        assert_eq!(id_hex(name_id(&part_name(78, "head"))), "ff7184e5");
    }

    /// `CryptoMaterial`'s header key, as docs/cryptomatte.md quotes it.
    const MATERIAL_KEY_IN_DOCS: &str = "be359d6";

    #[test]
    fn material_and_set_object_names() {
        assert_eq!(material_name("/show/sets/city.glb#brick_red"), "brick_red");
        assert_eq!(material_name("sets/a#b.glb#glass"), "glass");
        assert_eq!(material_name("robots/chrome"), "robots/chrome");
        assert_eq!(set_object_name("street/lamp#2"), "set/street/lamp#2");
    }

    #[test]
    fn ranking_is_by_count_then_id() {
        let mut acc = RankAccumulator::default();
        for id in [5u32, 9, 0, 9, 7, 5, 9, 0] {
            acc.add(id);
        }
        let mut out = [[0.0f32; 2]; 4];
        acc.write_ranked(8, &mut out);
        assert_eq!(out[0], [f32::from_bits(9), 3.0 / 8.0]);
        assert_eq!(out[1], [f32::from_bits(5), 2.0 / 8.0]);
        assert_eq!(out[2], [f32::from_bits(7), 1.0 / 8.0]);
        assert_eq!(out[3], [0.0, 0.0]);
    }
}
