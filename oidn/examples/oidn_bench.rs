//! Times the filters on the synthetic scene and prints the process's peak RSS:
//!
//! ```text
//! cargo run --release -p throng-oidn --example oidn_bench -- WIDTH HEIGHT high|balanced THREADS PASSES
//! ```
//!
//! Per filter: the albedo and normal prefilters and the HDR beauty with clean guides, each a
//! whole call (filter creation, commit, execute), twice (the first call also pays OIDN's one-off
//! set-up). Then PASSES passes of the beauty: a reused [`Denoiser`] (copy in, execute, copy out)
//! against a new filter per pass ([`Device::denoise`]: create, commit, execute), alternated.

#[path = "../tests/common/mod.rs"]
mod common;

use std::time::Instant;

use throng_oidn::{Denoiser, Device, DeviceOptions, Library, Options, Quality};

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

fn peak_rss_mb() -> f64 {
    let status = std::fs::read_to_string("/proc/self/status").unwrap_or_default();
    let kb = status.lines().find_map(|l| l.strip_prefix("VmHWM:")).and_then(|v| v.split_whitespace().next());
    kb.and_then(|k| k.parse::<f64>().ok()).map_or(f64::NAN, |k| k / 1024.0)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let arg = |i: usize, d: &str| args.get(i).cloned().unwrap_or_else(|| d.to_owned());
    let (w, h): (usize, usize) = (arg(0, "960").parse()?, arg(1, "540").parse()?);
    let quality = match arg(2, "high").as_str() {
        "high" => Quality::High,
        "balanced" => Quality::Balanced,
        "fast" => Quality::Fast,
        q => return Err(format!("quality {q}: high, balanced or fast").into()),
    };
    let (threads, passes): (u32, usize) = (arg(3, "2").parse()?, arg(4, "4").parse()?);
    let s = common::scene(w, h, 1);
    let rss0 = peak_rss_mb();

    let t = Instant::now();
    let lib = Library::find(None)?;
    let t_load = ms(t);
    let t = Instant::now();
    let device = Device::new(lib, DeviceOptions { num_threads: threads, ..Default::default() })?;
    let t_dev = ms(t);
    let rss_dev = peak_rss_mb();
    println!(
        "{w}x{h} {quality:?}, OIDN {}, {} threads: load {t_load:.0} ms, device {t_dev:.0} ms",
        lib.version(),
        device.num_threads()
    );

    let opts = Options { quality, ..Options::default() };
    let (mut albedo, mut normal, mut out) = (Vec::new(), Vec::new(), Vec::new());
    for round in 0..2 {
        let t = Instant::now();
        albedo = device.prefilter_albedo(w, h, &s.albedo, quality)?;
        let ta = ms(t);
        let t = Instant::now();
        normal = device.prefilter_normal(w, h, &s.normal, quality)?;
        let tn = ms(t);
        let t = Instant::now();
        out = device.denoise(w, h, &s.color, Some(&albedo), Some(&normal), opts)?;
        let tb = ms(t);
        println!("  call {round}: albedo prefilter {ta:.0} ms, normal prefilter {tn:.0} ms, beauty (hdr, cleanAux) {tb:.0} ms");
    }

    let t = Instant::now();
    let mut d = Denoiser::new(&device, w, h, Some(&albedo), Some(&normal), opts)?;
    let t_new = ms(t);
    let mut buf = vec![0.0; w * h * 3];
    // Alternated, so drifting machine load hits both the same.
    let (mut reuse, mut fresh) = (Vec::new(), Vec::new());
    for _ in 0..passes {
        let t = Instant::now();
        d.denoise_into(&s.color, &mut buf)?;
        reuse.push(ms(t));
        assert!(common::bit_identical(&buf, &out), "reused filter differs");
        let t = Instant::now();
        let o = device.denoise(w, h, &s.color, Some(&albedo), Some(&normal), opts)?;
        fresh.push(ms(t));
        assert!(common::bit_identical(&o, &out), "new filter differs");
    }
    let t = Instant::now();
    for _ in 0..10 {
        buf.copy_from_slice(&s.color);
        buf.copy_from_slice(&out);
    }
    let t_copy = ms(t) / 10.0;
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    let fmt = |v: &[f64]| v.iter().map(|x| format!("{x:.0}")).collect::<Vec<_>>().join(" ");
    println!("  Denoiser::new (create + commit) {t_new:.0} ms");
    println!(
        "  per pass, reused Denoiser:  mean {:.1} ms [{}] (of which the two plane copies {t_copy:.2} ms)",
        mean(&reuse),
        fmt(&reuse)
    );
    println!("  per pass, new filter each:  mean {:.1} ms [{}]", mean(&fresh), fmt(&fresh));
    println!(
        "  MAE vs clean {:.5} -> {:.5}; peak RSS {:.0} MB (inputs alone {rss0:.0} MB, + library and device {rss_dev:.0} MB)",
        common::mae(&s.color, &s.clean),
        common::mae(&out, &s.clean),
        peak_rss_mb()
    );
    Ok(())
}
