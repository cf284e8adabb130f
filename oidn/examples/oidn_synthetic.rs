//! Writes the test scene and this crate's denoised result as raw little-endian f32 files, for
//! tests/pyoidn_compare.py (this crate alone against the official Python binding, run by hand;
//! CI's check is .ci/denoise_pyoidn.py, on throng's own renders):
//!
//! ```text
//! cargo run -p throng-oidn --example oidn_synthetic -- OUT_DIR [WIDTH HEIGHT]
//! python3 oidn/tests/pyoidn_compare.py WIDTH HEIGHT OUT_DIR/color.f32 OUT_DIR/albedo.f32 \
//!     OUT_DIR/normal.f32 OUT_DIR/denoised.f32 1e-5
//! ```

#[path = "../tests/common/mod.rs"]
mod common;

use std::path::PathBuf;

use throng_oidn::{Denoiser, Device, DeviceOptions, Library, Options};

fn write_f32(path: PathBuf, v: &[f32]) {
    let bytes: Vec<u8> = v.iter().flat_map(|x| x.to_le_bytes()).collect();
    std::fs::write(&path, bytes).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let out = PathBuf::from(args.first().ok_or("usage: oidn_synthetic OUT_DIR [WIDTH HEIGHT]")?);
    let width = args.get(1).map(|s| s.parse()).transpose()?.unwrap_or(320);
    let height = args.get(2).map(|s| s.parse()).transpose()?.unwrap_or(180);
    let s = common::scene(width, height, 1);
    let device = Device::new(Library::find(None)?, DeviceOptions::default())?;
    let mut d = Denoiser::prefiltered(&device, width, height, Some(&s.albedo), Some(&s.normal), Options::default())?;
    let denoised = d.denoise(&s.color)?;
    std::fs::create_dir_all(&out)?;
    for (name, v) in [
        ("clean", &s.clean[..]),
        ("color", &s.color),
        ("albedo", &s.albedo),
        ("normal", &s.normal),
        ("albedo_d", d.albedo().unwrap()),
        ("normal_d", d.normal().unwrap()),
        ("denoised", &denoised),
    ] {
        write_f32(out.join(format!("{name}.f32")), v);
    }
    println!(
        "{width}x{height}, OIDN {} ({} threads): MAE vs clean {:.5} -> {:.5}; wrote {}",
        device.version(),
        device.num_threads(),
        common::mae(&s.color, &s.clean),
        common::mae(&denoised, &s.clean),
        out.display()
    );
    Ok(())
}
