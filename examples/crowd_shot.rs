//! Writes a benchmark shot of N agents of one of the demo's rigs, so
//! `throng render` itself can be timed from cache to first pixel:
//!
//! ```text
//! cargo run --release --example crowd_shot -- --rig walker --agents 10000 --out /tmp/walkers10k
//! throng render /tmp/walkers10k/shot.toml --layer full --frames 1 --spp 1 --resolution 64x36 --out /tmp/r
//! ```
//!
//! The rig's table (file, kind, cycles, schemes) and the wardrobes are taken
//! from demo/shot.toml, with paths made absolute; agents stand on a grid 1.2 m
//! apart in front of the camera, walking (cycle `WalkA`) at seeded cycle
//! frames and headings. Two frames (1 and 2) are written.

use std::path::{Path, PathBuf};

use glam::Vec3;
use throng::cache::{AgentSample, CrowdCache, FrameBlock};
use throng::error::{Error, Result};

fn main() -> std::process::ExitCode {
    match run() {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("crowd_shot: {e}");
            std::process::ExitCode::from(2)
        }
    }
}

struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f32 {
        self.0 = self.0.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (self.0 >> 40) as f32 / (1u64 << 24) as f32
    }
}

/// The `[rigs.NAME]` table of the demo shot, its paths made absolute.
fn rig_table(demo_shot: &str, demo_dir: &Path, rig: &str) -> Result<String> {
    let header = format!("[rigs.{rig}]");
    let start = demo_shot.find(&header).ok_or_else(|| Error::Usage(format!("demo/shot.toml has no {header}")))?;
    let rest = &demo_shot[start..];
    let end = rest[1..].find("\n[").map_or(rest.len(), |i| i + 1);
    let table = &rest[..end];
    Ok(table.replace("file = \"", &format!("file = \"{}/", demo_dir.display())))
}

fn run() -> Result<()> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let flag = |name: &str| args.iter().position(|a| a == name).and_then(|i| args.get(i + 1)).cloned();
    let rig = flag("--rig").unwrap_or_else(|| "walker".into());
    let agents: u32 =
        flag("--agents").unwrap_or_else(|| "10000".into()).parse().map_err(|_| Error::Usage("--agents N".into()))?;
    let out = PathBuf::from(flag("--out").ok_or_else(|| Error::Usage("--out DIR".into()))?);
    if agents == 0 || agents > 2_000_000 {
        return Err(Error::Usage("--agents must be 1 to 2000000".into()));
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let demo_dir = root.join("demo");
    let demo_text =
        std::fs::read_to_string(demo_dir.join("shot.toml")).map_err(|e| Error::io(demo_dir.join("shot.toml"), e))?;
    let table = rig_table(&demo_text, &demo_dir, &rig)?;
    std::fs::create_dir_all(&out).map_err(|e| Error::io(&out, e))?;

    // Agents on a square grid in front of the camera (which looks down -Z).
    let side = (agents as f32).sqrt().ceil() as u32;
    let spacing = 1.2;
    let mut rng = Lcg(0x5eed ^ agents as u64);
    let mut base = Vec::with_capacity(agents as usize);
    for i in 0..agents {
        let (gx, gz) = (i % side, i / side);
        let position = Vec3::new((gx as f32 - side as f32 / 2.0) * spacing, 0.0, -(gz as f32) * spacing);
        base.push((i + 1, position, rng.next() * std::f32::consts::TAU, rng.next() * 32.0));
    }
    let frames = (1..=2)
        .map(|f| FrameBlock {
            frame: f,
            agents: base
                .iter()
                .map(|&(id, position, heading, cf)| AgentSample {
                    id,
                    position,
                    heading,
                    rig: 0,
                    cycle: 0,
                    cycle_frame: cf + f as f32,
                    flags: 0,
                })
                .collect(),
        })
        .collect();
    let cache = CrowdCache { rigs: vec![rig.clone()], cycles: vec!["WalkA".into()], frames };
    throng::cache::write(out.join("crowd.crowd"), &cache)?;

    let wardrobes: Vec<String> = demo_text
        .lines()
        .find(|l| l.starts_with("wardrobes = "))
        .map(|l| {
            l["wardrobes = ".len()..]
                .trim_matches(|c| c == '[' || c == ']')
                .split(',')
                .map(|w| format!("\"{}/{}\"", demo_dir.display(), w.trim().trim_matches('"')))
                .collect()
        })
        .unwrap_or_default();
    let depth = side as f32 * spacing;
    let shot = format!(
        "version = 1\nname = \"bench\"\nseed = 1\nwardrobes = [{}]\n\n[frames]\nstart = 1\nend = 2\nfps = 24.0\n\n\
         [cache]\npath = \"crowd.crowd\"\n\n{table}\n[camera]\nsensor_width = 36.0\n[[camera.keys]]\nframe = 1\n\
         position = [0.0, {:?}, 8.0]\naim = [0.0, 0.0, {:?}]\nfocal_length = 28.0\n\n[lights.sun]\n\
         direction = [-0.6, 0.5, 0.6]\nangular_diameter = 0.53\nintensity = 3.0\ncolor = [1.0, 0.95, 0.88]\n\n\
         [layers]\nsplit = \"count\"\ncount = 1\n\n[render]\nresolution = [960, 540]\nspp = 1\nmax_bounces = 2\n",
        wardrobes.join(", "),
        (depth * 0.35).max(3.0),
        -depth * 0.4,
    );
    let path = out.join("shot.toml");
    std::fs::write(&path, shot).map_err(|e| Error::io(&path, e))?;
    println!("wrote {} ({agents} agents of rig {rig}, frames 1-2)", path.display());
    Ok(())
}
