//! The shot's figures beside the pictures: the casting table summary
//! (`casting::table::cast_stats`), per-layer agents and estimated memory
//! from the manifest, the memory measured by `render --json` summaries
//! saved in the renders folder, and the pops fixed-frame ranking avoids.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use serde_json::{json, Value};

use crate::casting::table::cast_stats;
use crate::casting::ShotCrowd;
use crate::layers::{Manifest, Ranking};

/// Largest summary file read (a render summary is a few KiB per layer-frame).
const MAX_SUMMARY_BYTES: u64 = 16 << 20;

/// Peak memory measured per layer in the `render --json` summaries
/// (`*.json` directly in the renders folder whose `verb` is `render`): the
/// largest `peak_rss_bytes` of each layer's layer-frames, how many
/// layer-frames, and the files read.
pub(crate) fn measured(renders: Option<&Path>) -> (BTreeMap<String, (u64, usize)>, Vec<PathBuf>) {
    let mut per_layer: BTreeMap<String, (u64, usize)> = BTreeMap::new();
    let mut files = Vec::new();
    let Some(dir) = renders else { return (per_layer, files) };
    let Ok(entries) = std::fs::read_dir(dir) else { return (per_layer, files) };
    let mut paths: Vec<PathBuf> = entries.filter_map(|e| Some(e.ok()?.path())).collect();
    paths.sort();
    for p in paths {
        let small = std::fs::metadata(&p).is_ok_and(|m| m.is_file() && m.len() <= MAX_SUMMARY_BYTES);
        if !small || p.extension().is_none_or(|x| x != "json") {
            continue;
        }
        let Some(v) = std::fs::read_to_string(&p).ok().and_then(|t| serde_json::from_str::<Value>(&t).ok()) else {
            continue;
        };
        if v["verb"] != "render" {
            continue;
        }
        let Some(frames) = v["layer_frames"].as_array() else { continue };
        for lf in frames {
            let (Some(layer), Some(rss)) = (lf["layer"].as_str(), lf["peak_rss_bytes"].as_u64()) else { continue };
            let e = per_layer.entry(layer.to_string()).or_default();
            e.0 = e.0.max(rss);
            e.1 += 1;
        }
        files.push(p);
    }
    (per_layer, files)
}

/// Everything the figures panel shows, as JSON.
pub(crate) fn figures(
    crowd: &ShotCrowd,
    manifest: Option<(&Manifest, &Path)>,
    renders: Option<&Path>,
    shot_file: &Path,
) -> Value {
    let stats = cast_stats(crowd);
    let (measured, summaries) = measured(renders);
    let measured_of = |layer: &str| measured.get(layer).map(|&(b, n)| json!({"peak_rss_bytes": b, "layer_frames": n}));
    let layers = manifest.map(|(m, _)| {
        let mut rows: Vec<Value> = m
            .layers
            .iter()
            .map(|l| {
                json!({
                    "name": l.name,
                    "agents": l.agents,
                    "rendered": l.rendered,
                    "removed": l.removed,
                    "lod_full": l.lod_full,
                    "lod_proxy": l.lod_proxy,
                    "distance_min_m": l.distance_min_m,
                    "distance_max_m": l.distance_max_m,
                    "estimated_bytes": l.memory_bytes,
                    "measured": measured_of(&l.name),
                })
            })
            .collect();
        rows.push(json!({
            "name": m.set.name,
            "agents": 0,
            "estimated_bytes": m.render_memory(&m.set.name),
            "measured": measured_of(&m.set.name),
        }));
        rows
    });
    let pops = manifest.map(|(m, _)| match m.ranking {
        Ranking::PerFrame => json!({
            "measured": true,
            "agents_changed": m.pops.agents_changed,
            "changes": m.pops.changes,
        }),
        Ranking::Fixed => json!({ "measured": false }),
    });
    json!({
        "shot": crowd.shot().name,
        "shot_file": shot_file,
        "frames": [crowd.shot().frames.start, crowd.shot().frames.end],
        "cast": stats,
        "manifest": manifest.map(|(_, p)| p),
        "ref_frame": manifest.map(|(m, _)| m.ref_frame),
        "layers": layers,
        "pops_avoided": pops,
        "summaries": summaries,
    })
}
