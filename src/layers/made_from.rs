//! What a layer manifest was made from (`made_from` in `layers.json`), so
//! `render` can refuse a manifest made before anything that moves, times,
//! picks or casts agents changed, or the camera or the shot's frames,
//! naming what changed.
//!
//! Hashes are [`crate::fingerprint`]'s (FNV-1a 64, 16 hex digits). Files are
//! hashed by content, so moving a shot folder keeps its manifest current.

use std::collections::BTreeMap;
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::cache::tabular::TabularSpec;
use crate::error::{Error, Result};
use crate::fingerprint::{self, Fingerprinter};
use crate::shot::{LayerSettings, Shot};

/// The fingerprint recorded in a manifest.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MadeFrom {
    /// [`fingerprint::ALGORITHM`]; a manifest fingerprinted otherwise (an
    /// older throng's `crc32`) is stale.
    pub(crate) algorithm: String,
    /// The cache file's bytes.
    pub(crate) cache: String,
    /// The `[cache]` import keys (every key but `path` and `frame_offset`:
    /// layout, columns, units, axes, rates, headings, rig and cycles,
    /// placement), each key's decoded value hashed. Keys the shot leaves out
    /// are not listed; placement's are always.
    #[serde(default)]
    pub(crate) cache_keys: BTreeMap<String, String>,
    /// Casting inputs: seed, rig files and their `[rigs]` settings, wardrobe
    /// files, removals, culled and no-scale cycles, excluded parts.
    pub(crate) casting: String,
    /// The camera (keys or glTF node, sensor) and the shot's resolution, which
    /// decide distances and LOD.
    pub(crate) camera: String,
    /// The shot's `[layers]` table as written (split, count, cut-offs,
    /// budget, reference frame, pins, LOD and visibility keys). A manifest
    /// made with flags over it (`layers --count`) records the shot's table,
    /// so it stays current until the shot's own keys change. Empty in
    /// manifests of older throngs (not checked).
    /// Each key's debug form hashed, so the refusal names it.
    #[serde(default, skip_serializing_if = "BTreeMap::is_empty")]
    pub(crate) layers: BTreeMap<String, String>,
    /// Shot frames `[start, end]`.
    pub frames: [i32; 2],
    /// `frames.fps`, the rate a tabular cache is resampled to.
    #[serde(default)]
    pub(crate) fps: f32,
    /// `cache.frame_offset`.
    pub(crate) frame_offset: i32,
    /// The manifest's own content: every field as written, this one left
    /// empty, so a hand edit (an agent deleted from `agents`, a layer
    /// moved) is refused. Empty in manifests of older throngs (not checked).
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub(crate) content: String,
}

/// The hash of a manifest's own content: every field as serialized, with
/// `made_from.content` left empty (and put back).
fn content_hash(m: &mut super::Manifest) -> String {
    let kept = m.made_from.as_mut().map(|f| std::mem::take(&mut f.content));
    let hash = Fingerprinter::new().value("manifest", &*m).hex();
    if let (Some(f), Some(kept)) = (m.made_from.as_mut(), kept) {
        f.content = kept;
    }
    hash
}

/// Records the finished manifest's content hash in `made_from.content`
/// (nothing without a `made_from`). Any later change to the manifest must
/// seal it again.
pub(crate) fn seal(m: &mut super::Manifest) {
    let hash = content_hash(m);
    if let Some(f) = m.made_from.as_mut() {
        f.content = hash;
    }
}

/// Each import key the shot sets, by name: its value's hash. Hashing the
/// serialized spec, not its fields one by one, covers a key added to
/// [`TabularSpec`] without touching this function; a key left out
/// (`null`) is not listed, so a key a newer throng adds leaves older
/// manifests current.
fn cache_keys(import: &TabularSpec) -> BTreeMap<String, String> {
    let Ok(serde_json::Value::Object(keys)) = serde_json::to_value(import) else {
        return BTreeMap::new();
    };
    keys.into_iter()
        .filter(|(_, value)| !value.is_null())
        .map(|(key, value)| {
            let hash = Fingerprinter::new().value(&key, &value).hex();
            (key, hash)
        })
        .collect()
}

/// Each `[layers]` key of the shot, by name: its value's hash. Destructured
/// whole, so a key added to [`LayerSettings`] does not compile until it is
/// fingerprinted here.
fn layer_keys(layers: &LayerSettings) -> BTreeMap<String, String> {
    let LayerSettings { split, count, cutoffs, budget, ref_frame, pins, lod_full_min_px, proxy_shadow_casters } =
        layers;
    let keys: [(&str, &dyn std::fmt::Debug); 8] = [
        ("split", split),
        ("count", count),
        ("cutoffs", cutoffs),
        ("budget", budget),
        ("ref_frame", ref_frame),
        ("pins", pins),
        ("lod_full_min_px", lod_full_min_px),
        ("proxy_shadow_casters", proxy_shadow_casters),
    ];
    keys.into_iter().map(|(k, v)| (k.to_string(), Fingerprinter::new().debug(k, v).hex())).collect()
}

/// An import key in the shot's words (`placement` is three keys).
fn cache_key_words(key: &str) -> String {
    match key {
        "placement" => "`translate`, `rotate` or `scale`".into(),
        _ => format!("`{key}`"),
    }
}

impl MadeFrom {
    /// The fingerprint of a shot as it is now on disk.
    pub(crate) fn of(shot: &Shot) -> Result<MadeFrom> {
        let mut casting = Fingerprinter::new();
        casting.value("seed", &shot.seed);
        for (name, r) in &shot.rigs {
            casting.text("rig", name).file("rig file", &r.file)?;
            casting
                .debug("schemes", &r.schemes)
                .debug("height_jitter", &r.height_jitter)
                .debug("kind", &r.kind)
                .debug("skin", &r.skin);
        }
        for w in &shot.wardrobes {
            casting.file("wardrobe", w)?;
        }
        casting
            .value("removed", &shot.removed)
            .value("culled_cycles", &shot.culled_cycles)
            .value("no_scale_cycles", &shot.no_scale_cycles)
            .value("exclude_parts", &shot.exclude_parts);
        let mut camera = Fingerprinter::new();
        let c = &shot.camera;
        camera
            .value("sensor_width", &c.sensor_width)
            .debug("keys", &c.keys)
            .value("resolution", &shot.render.resolution);
        if let Some((file, node)) = &c.gltf {
            camera.file("gltf", file)?.text("node", node);
        }
        Ok(MadeFrom {
            algorithm: fingerprint::ALGORITHM.into(),
            cache: fingerprint::hex(fingerprint::hash_file(&shot.cache.path)?.hash),
            cache_keys: cache_keys(&shot.cache.import),
            casting: casting.hex(),
            camera: camera.hex(),
            layers: layer_keys(&shot.layers),
            frames: [shot.frames.start, shot.frames.end],
            fps: shot.frames.fps,
            frame_offset: shot.cache.frame_offset,
            content: String::new(),
        })
    }

    /// What differs between this (the manifest's) and `now`, in a lighter's words.
    pub(crate) fn changes(&self, now: &MadeFrom, shot: &Shot) -> Vec<String> {
        if self.algorithm != now.algorithm {
            // Every hash differs: name the cause, not each of them.
            return vec![format!(
                "an older throng fingerprinted it with `{}`, this one with `{}` (made_from.algorithm)",
                self.algorithm, now.algorithm
            )];
        }
        let mut out = Vec::new();
        if self.cache != now.cache {
            out.push(format!("the cache {} changed (made_from.cache)", shot.cache.path.display()));
        }
        let keys: std::collections::BTreeSet<&String> = self.cache_keys.keys().chain(now.cache_keys.keys()).collect();
        let changed: Vec<String> = keys
            .into_iter()
            .filter(|k| self.cache_keys.get(*k) != now.cache_keys.get(*k))
            .map(|k| cache_key_words(k))
            .collect();
        if !changed.is_empty() {
            let noun = if changed.len() == 1 { "key" } else { "keys" };
            out.push(format!("the [cache] {noun} {} changed (made_from.cache_keys)", changed.join(", ")));
        }
        if self.casting != now.casting {
            out.push("the casting inputs changed: seed, rigs, wardrobes or removals (made_from.casting)".into());
        }
        if self.camera != now.camera {
            out.push("the camera or the shot's resolution changed (made_from.camera)".into());
        }
        if !self.layers.is_empty() {
            let changed: Vec<String> = now
                .layers
                .iter()
                .filter(|(k, v)| self.layers.get(*k) != Some(*v))
                .map(|(k, _)| format!("`{k}`"))
                .collect();
            if !changed.is_empty() {
                let noun = if changed.len() == 1 { "key" } else { "keys" };
                out.push(format!("the [layers] {noun} {} changed (made_from.layers)", changed.join(", ")));
            }
        }
        if self.frames != now.frames {
            out.push(format!(
                "the shot's frames changed from {}-{} to {}-{} (made_from.frames)",
                self.frames[0], self.frames[1], now.frames[0], now.frames[1]
            ));
        }
        if self.fps != now.fps {
            out.push(format!("frames.fps changed from {} to {} (made_from.fps)", self.fps, now.fps));
        }
        if self.frame_offset != now.frame_offset {
            out.push(format!(
                "cache.frame_offset changed from {} to {} (made_from.frame_offset)",
                self.frame_offset, now.frame_offset
            ));
        }
        out
    }
}

/// Refuses a manifest (read from `path`) that is stale for `shot`. A
/// manifest without `made_from` (made by an older throng) passes with the
/// warning returned.
pub fn check_current(path: &Path, manifest: &mut super::Manifest, shot: &Shot) -> Result<Option<String>> {
    let Some(then) = manifest.made_from.clone() else {
        return Ok(Some(format!(
            "{}: the manifest records no `made_from` fingerprint (an older throng made it), so it cannot be checked \
             against the shot; run `throng layers {}` again to be safe",
            path.display(),
            shot.path.display()
        )));
    };
    let now = MadeFrom::of(shot)?;
    let mut changes = Vec::new();
    if !then.content.is_empty() && content_hash(manifest) != then.content {
        changes.push(
            "the manifest itself was edited (its agents, layers or settings are not what throng wrote: \
             made_from.content)"
                .to_string(),
        );
    }
    changes.extend(then.changes(&now, shot));
    if changes.is_empty() {
        return Ok(None);
    }
    Err(Error::invalid(
        path,
        format!(
            "stale layer manifest: {} since it was made; run `throng layers {}` again",
            changes.join("; "),
            shot.path.display()
        ),
    )
    .field("made_from"))
}
