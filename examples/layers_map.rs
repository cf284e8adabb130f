//! Draws the layer map and prints the summary for a synthetic demo-like
//! crowd (no cache needed): `cargo run --example layers_map -- OUT.png [count|cutoffs|budget] [MANIFEST.json]`.

use glam::Vec3;
use throng::layers::{build_manifest, draw_map, summary, AgentInput, LayerInput, LayerOptions, MapOptions};
use throng::scene::Camera;
use throng::shot::{look_at, LayerSettings, Pin, SplitMode};

fn main() -> throng::error::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let out = args.get(1).map_or("layers_map.png", String::as_str);
    let mode = args.get(2).map_or("count", String::as_str);
    let frames: Vec<i32> = (1001..=1048).collect();
    let yfov = 2.0 * ((36.0 / (16.0 / 9.0)) * 0.5f32 / 35.0).atan();
    let cam = Camera::pinhole(look_at(Vec3::new(0.0, 1.7, 24.0), Vec3::new(0.0, 1.0, -2.0)), yfov);
    // A loose crowd in x [-18, 18], z [-30, 12], drifting slowly, deterministic.
    let mut agents = Vec::new();
    let mut seed = 12345u64;
    let mut rnd = || {
        seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (seed >> 33) as f32 / (1u64 << 31) as f32
    };
    for id in 0..180u32 {
        let p = Vec3::new(-18.0 + 36.0 * rnd(), 0.0, -30.0 + 42.0 * rnd());
        let v = Vec3::new(rnd() - 0.5, 0.0, rnd() - 0.5) * 0.06;
        let positions = (0..frames.len()).map(|f| Some(p + v * f as f32)).collect();
        agents.push(AgentInput {
            id,
            positions,
            height_m: 1.6 + 0.45 * rnd(),
            memory_full: 30_000_000 + (60_000_000.0 * rnd()) as u64,
            memory_proxy: 1_408,
            removed: id % 37 == 3,
        });
    }
    let mut settings = match mode {
        "cutoffs" => LayerSettings { split: SplitMode::Cutoffs, cutoffs: vec![12.0, 25.0, 40.0], ..Default::default() },
        "budget" => LayerSettings { split: SplitMode::Budget, budget: Some("1.2GB".into()), ..Default::default() },
        _ => LayerSettings { split: SplitMode::Count, count: 3, ..Default::default() },
    };
    settings.pins = vec![Pin { agent: 7, layer: 0 }];
    let input = LayerInput {
        shot: "demo".into(),
        source: "demo/shot.toml".into(),
        cameras: vec![cam; frames.len()],
        frames,
        image_size: (960, 540),
        agents,
        settings,
        options: LayerOptions { per_frame: true, ..Default::default() },
    };
    let m = build_manifest(&input)?;
    print!("{}", summary(&m));
    if let Some(json) = args.get(3) {
        throng::layers::write_manifest(std::path::Path::new(json), &m)?;
    }
    let set = Some((Vec3::new(-40.0, 0.0, -40.0), Vec3::new(40.0, 20.0, 40.0)));
    draw_map(
        &m,
        &MapOptions {
            size: (
                std::env::var("MAP_W").ok().and_then(|v| v.parse().ok()).unwrap_or(1600),
                std::env::var("MAP_H").ok().and_then(|v| v.parse().ok()).unwrap_or(900),
            ),
            set_bounds: set,
            highlight: None,
        },
        std::path::Path::new(out),
    )
}
