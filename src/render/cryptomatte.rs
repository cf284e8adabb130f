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

use std::collections::{BTreeMap, BTreeSet, HashSet};
use std::hash::BuildHasherDefault;

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
pub(crate) const MATTES: [&str; 3] = [AGENT_MATTE, PART_MATTE, MATERIAL_MATTE];
/// Name of set (non-agent) geometry that has no object name, in the agent
/// and part mattes; named set objects are `set/<object>` ([`set_object_name`]).
pub const SET_NAME: &str = "set";
/// Ranks written per matte (the spec's suggested default: 3 RGBA layers).
pub const RANKS: usize = 6;
/// Distinct ids one pixel can accumulate while rendering. More distinct
/// objects than this under one pixel is rare (16 spp can see at most 16); the
/// samples of ids that do not fit are dropped (they would rank below the
/// kept ones only if they arrive late, so mattes stay usable).
pub(crate) const ACCUMULATOR_CAPACITY: usize = 32;
/// The `hash` header value.
pub(crate) const HASH: &str = "MurmurHash3_32";
/// The `conversion` header value.
pub(crate) const CONVERSION: &str = "uint32_to_float32";

/// MurmurHash3_x86_32 of `bytes` with `seed`.
pub(crate) fn murmur3_32(bytes: &[u8], seed: u32) -> u32 {
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
pub(crate) fn hash_to_float(hash: u32) -> f32 {
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
pub(crate) fn material_name(library_name: &str) -> &str {
    library_name.rsplit_once('#').map_or(library_name, |(_, name)| name)
}

/// One pixel's running (id, sample count) table: fixed capacity, no heap.
#[derive(Clone, Debug)]
pub(crate) struct RankAccumulator {
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
    pub(crate) fn add(&mut self, id_bits: u32) {
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
    pub(crate) fn write_ranked(&self, samples: u32, out: &mut [[f32; 2]]) {
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
    pub(crate) fn new(name: &str, width: u32, height: u32, ranks: usize) -> Cryptomatte {
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
    pub(crate) fn matte_id(&self, id: f32) -> Vec<f32> {
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
    pub(crate) fn ids_present(&self) -> BTreeSet<u32> {
        self.pairs.iter().filter(|p| p[1] > 0.0 && p[0].to_bits() != 0).map(|p| p[0].to_bits()).collect()
    }

    /// The manifest as the spec's JSON: `{"name":"<8 hex>", ...}`, names sorted.
    pub(crate) fn manifest_json(&self) -> String {
        let map: BTreeMap<&str, String> =
            self.manifest.iter().map(|(k, &v)| (k.as_str(), format!("{v:08x}"))).collect();
        serde_json::to_string(&map).unwrap_or_else(|_| "{}".to_string())
    }
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

/// A rig slot name by part index, for one agent.
type SlotName<'a> = dyn Fn(u32, u16) -> Option<&'a str> + Sync + 'a;

/// The ids of every instance of one frame scene, for the three mattes, and
/// the way back from an id to its name (for the manifests).
///
/// Only the ids are stored (12 bytes an instance): a manifest names just the
/// ids a film shows, re-deriving each name from its instance, so a
/// 13-million-instance frame holds no name table.
pub struct CryptoNames<'a> {
    /// Per instance: [agent, part, material] matte id bits; 0 = nothing.
    ids: Vec<[u32; 3]>,
    instances: &'a [Instance],
    tables: NameTables<'a>,
    slot_name: Box<SlotName<'a>>,
}

/// Instances named per parallel task; an agent's instances are contiguous,
/// so each task hashes an agent's name and looks up its slots once.
const NAMING_CHUNK: usize = 4096;

impl<'a> CryptoNames<'a> {
    /// Names the instances of a frame scene. `slots_of(agent)` gives the
    /// agent's rig slot names by part index (looked up once per run of an
    /// agent's instances); a missing slot falls back to `part<index>`. Set
    /// objects and materials are named from `tables`. Holdouts get id 0
    /// (they are never a first hit anyway). Pure per instance, so the
    /// parallel naming is the same for any thread count.
    pub fn new<F, S>(instances: &'a [Instance], tables: &NameTables<'a>, slots_of: F) -> CryptoNames<'a>
    where
        F: Fn(u32) -> Option<S> + Sync + 'a,
        S: Fn(u16) -> Option<&'a str>,
    {
        use rayon::prelude::*;
        let tables = *tables;
        let mut ids = vec![[0u32; 3]; instances.len()];
        ids.par_chunks_mut(NAMING_CHUNK).zip(instances.par_chunks(NAMING_CHUNK)).for_each(|(ids, instances)| {
            let mut materials: Vec<Option<u32>> = Vec::new();
            let mut agent: Option<(u32, u32, Option<S>)> = None;
            let mut buf = String::new();
            let mut prefix = 0;
            for (out, inst) in ids.iter_mut().zip(instances) {
                if inst.visibility & vis::HOLDOUT != 0 {
                    continue;
                }
                let material = material_id(inst.material, tables.materials, &mut materials);
                let Some(a) = inst.agent.get() else {
                    let id = name_id(&instance_name(inst, 0, &tables, &|_, _| None)).to_bits();
                    *out = [id, id, material];
                    continue;
                };
                if agent.as_ref().is_none_or(|(current, _, _)| *current != a) {
                    buf.clear();
                    buf.push_str(&agent_name(a));
                    agent = Some((a, name_id(&buf).to_bits(), slots_of(a)));
                    buf.push('/');
                    prefix = buf.len();
                }
                let Some((_, agent_id, slots)) = &agent else { continue };
                buf.truncate(prefix);
                match slots.as_ref().and_then(|s| s(inst.part)) {
                    Some(slot) => buf.push_str(slot),
                    None => buf.push_str(&fallback_slot(inst.part)),
                }
                *out = [*agent_id, name_id(&buf).to_bits(), material];
            }
        });
        let slot_name = move |a: u32, part: u16| slots_of(a).and_then(|s| s(part));
        CryptoNames { ids, instances, tables, slot_name: Box::new(slot_name) }
    }

    /// [agent, part, material] matte id bits of instance `i` (0 = none).
    pub(crate) fn ids(&self, instance: u32) -> [u32; 3] {
        self.ids.get(instance as usize).copied().unwrap_or([0; 3])
    }

    /// The manifest of matte `matte` (index into [`MATTES`]: 0 agents, 1
    /// parts, 2 materials) restricted to `present` ids. Every name with a
    /// present id is listed, so two names that collide on one id both are.
    pub(crate) fn manifest(&self, matte: usize, present: &BTreeSet<u32>) -> BTreeMap<String, u32> {
        let mut out = BTreeMap::new();
        if matte >= MATTES.len() || present.is_empty() {
            return out;
        }
        // Ids are hashes already: spread them for the table, no SipHash.
        let present: HashSet<u32, BuildHasherDefault<IdHasher>> = present.iter().copied().collect();
        let mut last: Option<(u32, Option<u32>, u16)> = None;
        for (inst, ids) in self.instances.iter().zip(&self.ids) {
            let id = ids[matte];
            if id == 0 || !present.contains(&id) {
                continue;
            }
            // An agent's instances repeat its agent id; name it once.
            let key = (id, inst.agent.get(), if matte == 0 { 0 } else { inst.part });
            if last == Some(key) {
                continue;
            }
            last = Some(key);
            let name = match matte {
                2 => material_label(inst.material, self.tables.materials),
                _ => instance_name(inst, matte, &self.tables, &*self.slot_name),
            };
            out.insert(name, id);
        }
        out
    }
}

impl std::fmt::Debug for CryptoNames<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CryptoNames").field("instances", &self.ids.len()).finish_non_exhaustive()
    }
}

/// An instance's name in the agent (`matte` 0) or part (1) matte.
fn instance_name(inst: &Instance, matte: usize, tables: &NameTables, slot_name: &SlotName) -> String {
    match inst.agent.get() {
        None => match tables.set_objects.get(inst.part as usize) {
            Some(object) => set_object_name(object),
            None => SET_NAME.to_string(),
        },
        Some(a) if matte == 0 => agent_name(a),
        Some(a) => match slot_name(a, inst.part) {
            Some(slot) => part_name(a, slot),
            None => part_name(a, &fallback_slot(inst.part)),
        },
    }
}

/// The slot name of a part index the rig does not name.
fn fallback_slot(part: u16) -> String {
    format!("part{part}")
}

/// Library material `material`'s name in the material matte.
fn material_label(material: u32, library: &[Material]) -> String {
    match library.get(material as usize) {
        Some(mat) => material_name(&mat.name).to_string(),
        None => format!("material{material}"),
    }
}

/// The material matte id bits of library material `material` (hashed once
/// per material; `cache` by material index).
fn material_id(material: u32, library: &[Material], cache: &mut Vec<Option<u32>>) -> u32 {
    let m = material as usize;
    if cache.len() <= m {
        cache.resize(m + 1, None);
    }
    *cache[m].get_or_insert_with(|| name_id(&material_label(material, library)).to_bits())
}

/// A hasher for keys that are hashes already (matte ids): one multiply
/// spreads their bits over the table's.
#[derive(Default)]
struct IdHasher(u64);

impl std::hash::Hasher for IdHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 = (self.0.rotate_left(8) ^ b as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
        }
    }
    fn write_u32(&mut self, n: u32) {
        self.0 = (n as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15);
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
