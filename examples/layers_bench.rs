//! Layering speed: rank and split 1,000,000 synthetic agents at one frame.
//! `cargo run --example layers_bench [-- AGENTS] [--shuffled]` (dev profile; not a test).

use std::time::Instant;

use glam::Vec3;
use throng::layers::{build_manifest, AgentInput, LayerInput, LayerOptions};
use throng::scene::Camera;
use throng::shot::{look_at, LayerSettings, SplitMode};

/// This thread's CPU time in seconds (Linux), so a busy machine doesn't
/// inflate the figure; NaN elsewhere.
fn thread_cpu() -> f64 {
    std::fs::read_to_string("/proc/thread-self/schedstat")
        .ok()
        .and_then(|s| s.split_whitespace().next()?.parse::<f64>().ok())
        .map_or(f64::NAN, |ns| ns * 1e-9)
}

fn main() -> throng::error::Result<()> {
    let n: u32 = std::env::args().skip(1).find_map(|a| a.parse().ok()).unwrap_or(1_000_000);
    let yfov = 2.0 * ((36.0 / (16.0 / 9.0)) * 0.5f32 / 35.0).atan();
    let cam = Camera::pinhole(look_at(Vec3::new(0.0, 1.7, 24.0), Vec3::new(0.0, 1.0, -2.0)), yfov);
    // A 1 km square field of agents, deterministic, in id order as a cache
    // holds them (`--shuffled`: ids in random order, the worst case).
    let shuffled = std::env::args().any(|a| a == "--shuffled");
    let mut seed = 7u64;
    let mut rnd = || {
        seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (seed >> 33) as f32 / (1u64 << 31) as f32
    };
    let t = Instant::now();
    let agents: Vec<AgentInput> = (0..n)
        .map(|i| AgentInput {
            id: if shuffled { i.wrapping_mul(2654435761) ^ 0x5bd1e995 } else { i },
            positions: vec![Some(Vec3::new(1000.0 * rnd() - 500.0, 0.0, 24.0 - 1000.0 * rnd()))],
            height_m: 1.6 + 0.4 * rnd(),
            memory_full: 20_000_000 + (40_000_000.0 * rnd()) as u64,
            memory_proxy: 1_408,
            removed: i % 1000 == 0,
        })
        .collect();
    println!("built {n} synthetic agents in {:.2} s (not timed below)", t.elapsed().as_secs_f64());
    let splits = [
        ("count 8", LayerSettings { split: SplitMode::Count, count: 8, ..Default::default() }),
        (
            "cutoffs 10,25,60,150",
            LayerSettings { split: SplitMode::Cutoffs, cutoffs: vec![10.0, 25.0, 60.0, 150.0], ..Default::default() },
        ),
        (
            "budget 2.8GB",
            LayerSettings { split: SplitMode::Budget, budget: Some("2.8GB".into()), ..Default::default() },
        ),
    ];
    let mut input = LayerInput {
        shot: "bench".into(),
        source: "bench/shot.toml".into(),
        frames: vec![1001],
        cameras: vec![cam],
        image_size: (1920, 1080),
        agents,
        settings: LayerSettings::default(),
        options: LayerOptions::default(),
    };
    for (name, settings) in splits {
        input.settings = settings;
        let (mut wall, mut cpu) = (f64::INFINITY, f64::INFINITY);
        let mut layers = 0;
        for _ in 0..3 {
            let (t, c) = (Instant::now(), thread_cpu());
            let m = build_manifest(&input)?;
            wall = wall.min(t.elapsed().as_secs_f64());
            cpu = cpu.min(thread_cpu() - c);
            layers = m.layers.len();
        }
        println!("rank + split + manifest, {n} agents, {name:<22} {layers:>5} layers: {wall:.3} s wall, {cpu:.3} s cpu (best of 3)");
    }
    Ok(())
}
