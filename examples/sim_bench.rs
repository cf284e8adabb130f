//! Times the reference simulation on 10,000 agents over 240 frames:
//! `cargo run --example sim_bench [AGENTS] [FRAMES]` (dev profile, optimised).
//! Prints figures; it asserts nothing.

use std::time::Instant;

fn main() {
    let args: Vec<usize> = std::env::args().skip(1).filter_map(|a| a.parse().ok()).collect();
    let agents = args.first().copied().unwrap_or(10_000);
    let frames = args.get(1).copied().unwrap_or(240);
    // About the demo's density (0.2 agents per square metre): a square of side
    // sqrt(agents / 0.2) with targets in a ring, pillars and boundary walls.
    let half = ((agents as f32 / 0.2).sqrt() / 2.0).max(5.0);
    let mut text = format!(
        "version = 1\nseed = 42\n[frames]\nstart = 1\nend = {frames}\n\
         [cycles.WalkA]\nlength = 32\nstride = 1.5\nnext = {{ WalkA = 6, WalkB = 3, IdleA = 1 }}\n\
         [cycles.WalkB]\nlength = 28\nstride = 1.2\nnext = {{ WalkA = 3, WalkB = 6, IdleA = 1 }}\n\
         [cycles.IdleA]\nlength = 48\nstride = 0\nnext = {{ IdleA = 1, WalkA = 2 }}\n\
         [[spawn]]\ncount = {agents}\nfirst_id = 1\nmin = [{lo}, {lo}]\nmax = [{hi}, {hi}]\nheading_jitter_deg = 180\n\
         rigs = {{ bipedThinA = 1, bipedTallB = 1 }}\ncycles = {{ WalkA = 5, WalkB = 4, IdleA = 1 }}\n",
        lo = -half + 1.0,
        hi = half - 1.0,
    );
    for k in 0..16 {
        let a = k as f32 / 16.0 * std::f32::consts::TAU;
        text += &format!(
            "[[targets]]\nname = \"t{k}\"\nposition = [{}, {}]\nradius = 2.0\n",
            0.7 * half * a.cos(),
            0.7 * half * a.sin()
        );
    }
    for k in 0..20 {
        let a = k as f32 / 20.0 * std::f32::consts::TAU;
        text +=
            &format!("[[obstacles]]\ncenter = [{}, {}]\nradius = 1.0\n", 0.4 * half * a.cos(), 0.4 * half * a.sin());
    }
    for (p, n) in
        [([half, 0.0], [-1.0, 0.0]), ([-half, 0.0], [1.0, 0.0]), ([0.0, half], [0.0, -1.0]), ([0.0, -half], [0.0, 1.0])]
    {
        text += &format!("[[walls]]\npoint = [{}, {}]\nnormal = [{}, {}]\n", p[0], p[1], n[0], n[1]);
    }
    let scene = match throng::sim::SimScene::parse(&text, "sim_bench.toml") {
        Ok(s) => s,
        Err(e) => {
            eprintln!("sim_bench: {e}");
            std::process::exit(2);
        }
    };
    let clock = Instant::now();
    let crowd = throng::sim::run(&scene);
    let secs = clock.elapsed().as_secs_f64();
    let records: usize = crowd.frames.iter().map(|f| f.agents.len()).sum();
    println!(
        "sim_bench: {} agents x {} frames in {:.2} s ({:.1} M agent-frames/s, {} threads, {:.0} m square)",
        scene.agents.len(),
        crowd.frames.len(),
        secs,
        records as f64 / secs / 1e6,
        rayon::current_num_threads(),
        2.0 * half
    );
}
