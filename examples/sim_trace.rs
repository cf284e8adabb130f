//! Prints one agent's trajectory from a scene file: `cargo run --example sim_trace SCENE [INDEX...]`.
fn main() {
    let args: Vec<String> = std::env::args().collect();
    let scene = match throng::sim::SimScene::load(&args[1]) {
        Ok(s) => s,
        Err(e) => {
            eprintln!("{e}");
            std::process::exit(2)
        }
    };
    let idx: Vec<usize> = args[2..].iter().filter_map(|a| a.parse().ok()).collect();
    let c = throng::sim::run(&scene);
    for f in &c.frames {
        let mut line = format!("{:5}", f.frame);
        for &i in if idx.is_empty() { &[0][..] } else { &idx[..] } {
            let a = &f.agents[i];
            line += &format!(
                "  id {:4} ({:7.3},{:7.3}) h {:7.2} {} {:5.2}",
                a.id,
                a.position.x,
                a.position.z,
                a.heading.to_degrees(),
                c.cycles[a.cycle as usize],
                a.cycle_frame
            );
        }
        println!("{line}");
    }
}
