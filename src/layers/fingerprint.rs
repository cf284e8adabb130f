//! What a layer manifest was made from (`made_from` in `layers.json`), so
//! `render` can refuse a manifest made before the cache, the casting inputs,
//! the camera or the shot's frames changed, naming what changed.
//!
//! Hashes are CRC-32 (crc32fast) as 8 hex digits: a change detector, not a
//! defence against tampering. Files are hashed by content, so moving a shot
//! folder keeps its manifest current.

use std::io::Read;
use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::error::{Error, IoContext, Result};
use crate::shot::Shot;

/// The fingerprint recorded in a manifest.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct MadeFrom {
    /// Always `crc32`.
    pub algorithm: String,
    /// The cache file's bytes.
    pub cache: String,
    /// Casting inputs: seed, rig files and their `[rigs]` settings, wardrobe
    /// files, removals, culled and no-scale cycles, excluded parts.
    pub casting: String,
    /// The camera (keys or glTF node, sensor) and the shot's resolution, which
    /// decide distances and LOD.
    pub camera: String,
    /// Shot frames `[start, end]`.
    pub frames: [i32; 2],
    /// `cache.frame_offset`.
    pub frame_offset: i32,
}

fn hex(h: u32) -> String {
    format!("{h:08x}")
}

/// CRC-32 of a file's bytes, read in blocks (a cache may be large).
pub fn hash_file(path: &Path) -> Result<u32> {
    let mut f = std::fs::File::open(path).at(path)?;
    let mut h = crc32fast::Hasher::new();
    let mut buf = vec![0u8; 1 << 20];
    loop {
        let n = f.read(&mut buf).at(path)?;
        if n == 0 {
            return Ok(h.finalize());
        }
        h.update(&buf[..n]);
    }
}

impl MadeFrom {
    /// The fingerprint of a shot as it is now on disk.
    pub fn of(shot: &Shot) -> Result<MadeFrom> {
        let mut casting = crc32fast::Hasher::new();
        let mut put = |s: String| {
            casting.update(s.as_bytes());
            casting.update(b"\n");
        };
        put(format!("seed {}", shot.seed));
        for (name, r) in &shot.rigs {
            put(format!(
                "rig {name} {:08x} {:?} {:?} {:?} {:?}",
                hash_file(&r.file)?,
                r.schemes,
                r.height_jitter,
                r.kind,
                r.skin
            ));
        }
        for w in &shot.wardrobes {
            put(format!("wardrobe {:08x}", hash_file(w)?));
        }
        put(format!(
            "removed {:?} culled {:?} no_scale {:?} exclude {:?}",
            shot.removed, shot.culled_cycles, shot.no_scale_cycles, shot.exclude_parts
        ));
        let mut camera = crc32fast::Hasher::new();
        let c = &shot.camera;
        camera.update(format!("{:?} {:?} {:?}", c.sensor_width, c.keys, shot.render.resolution).as_bytes());
        if let Some((file, node)) = &c.gltf {
            camera.update(format!("gltf {:08x} {node}", hash_file(file)?).as_bytes());
        }
        Ok(MadeFrom {
            algorithm: "crc32".into(),
            cache: hex(hash_file(&shot.cache.path)?),
            casting: hex(casting.finalize()),
            camera: hex(camera.finalize()),
            frames: [shot.frames.start, shot.frames.end],
            frame_offset: shot.cache.frame_offset,
        })
    }

    /// What differs between this (the manifest's) and `now`, in a lighter's words.
    pub fn changes(&self, now: &MadeFrom, shot: &Shot) -> Vec<String> {
        let mut out = Vec::new();
        if self.cache != now.cache {
            out.push(format!("the cache {} changed (made_from.cache)", shot.cache.path.display()));
        }
        if self.casting != now.casting {
            out.push("the casting inputs changed: seed, rigs, wardrobes or removals (made_from.casting)".into());
        }
        if self.camera != now.camera {
            out.push("the camera or the shot's resolution changed (made_from.camera)".into());
        }
        if self.frames != now.frames {
            out.push(format!(
                "the shot's frames changed from {}-{} to {}-{} (made_from.frames)",
                self.frames[0], self.frames[1], now.frames[0], now.frames[1]
            ));
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
pub fn check_current(path: &Path, manifest: &super::Manifest, shot: &Shot) -> Result<Option<String>> {
    let Some(then) = &manifest.made_from else {
        return Ok(Some(format!(
            "{}: the manifest records no `made_from` fingerprint (an older throng made it), so it cannot be checked \
             against the shot; run `throng layers {}` again to be safe",
            path.display(),
            shot.path.display()
        )));
    };
    let now = MadeFrom::of(shot)?;
    let changes = then.changes(&now, shot);
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
