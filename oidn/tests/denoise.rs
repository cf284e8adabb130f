//! Denoising with the real library (skipped, with a printed reason, when it is not installed;
//! failed instead under THRONG_REQUIRE_OIDN=1).

mod common;

use common::{bit_identical, library_or_skip, mae, scene};
use throng_oidn::{DenoiseError, Denoiser, Device, DeviceOptions, Options, Quality};

const W: usize = 160;
const H: usize = 96;

fn device(threads: u32) -> Option<Device> {
    let lib = library_or_skip("oidn denoise test")?;
    assert!(lib.version() >= throng_oidn::MIN_VERSION, "{lib:?}");
    Some(Device::new(lib, DeviceOptions { num_threads: threads, ..Default::default() }).expect("CPU device"))
}

/// Prefiltered guides + HDR beauty: the full final-frame path.
fn run(device: &Device) -> (Vec<f32>, Vec<f32>, Vec<f32>) {
    let s = scene(W, H, 1);
    let albedo = device.prefilter_albedo(W, H, &s.albedo, Quality::High).unwrap();
    let normal = device.prefilter_normal(W, H, &s.normal, Quality::High).unwrap();
    let out = device.denoise(W, H, &s.color, Some(&albedo), Some(&normal), Options::default()).unwrap();
    (albedo, normal, out)
}

#[test]
fn denoising_halves_the_error_at_least() {
    let Some(device) = device(2) else { return };
    let s = scene(W, H, 1);
    let (albedo, normal, out) = run(&device);
    let (before, after) = (mae(&s.color, &s.clean), mae(&out, &s.clean));
    println!("MAE vs clean: noisy {before:.5} -> denoised {after:.5} ({:.1}x lower)", before / after);
    assert!(after * 2.0 <= before, "noisy {before} -> denoised {after}");
    assert!(out.iter().chain(&albedo).chain(&normal).all(|v| v.is_finite()));
}

#[test]
fn two_runs_are_bit_identical() {
    let Some(device) = device(2) else { return };
    let (a1, n1, o1) = run(&device);
    let (a2, n2, o2) = run(&device);
    assert!(bit_identical(&a1, &a2) && bit_identical(&n1, &n2) && bit_identical(&o1, &o2));
    // A reused Denoiser gives the one-shot result, pass after pass.
    let s = scene(W, H, 1);
    let mut d = Denoiser::new(&device, W, H, Some(&a1), Some(&n1), Options::default()).unwrap();
    let other = scene(W, H, 7).color;
    let first = d.denoise(&s.color).unwrap();
    let _ = d.denoise(&other).unwrap();
    let again = d.denoise(&s.color).unwrap();
    assert!(bit_identical(&first, &o1), "Denoiser differs from Device::denoise");
    assert!(bit_identical(&again, &o1), "a Denoiser pass depends on the pass before it");
}

#[test]
fn one_and_two_threads_are_bit_identical() {
    let (Some(d1), Some(d2)) = (device(1), device(2)) else { return };
    assert_eq!((d1.num_threads(), d2.num_threads()), (1, 2));
    let (a1, n1, o1) = run(&d1);
    let (a2, n2, o2) = run(&d2);
    assert!(bit_identical(&a1, &a2), "albedo prefilter differs across thread counts");
    assert!(bit_identical(&n1, &n2), "normal prefilter differs across thread counts");
    assert!(bit_identical(&o1, &o2), "beauty differs across thread counts");
}

#[test]
fn prefiltered_denoiser_matches_the_steps() {
    let Some(device) = device(2) else { return };
    let s = scene(W, H, 1);
    let (albedo, normal, out) = run(&device);
    let mut d = Denoiser::prefiltered(&device, W, H, Some(&s.albedo), Some(&s.normal), Options::default()).unwrap();
    assert!(bit_identical(d.albedo().unwrap(), &albedo) && bit_identical(d.normal().unwrap(), &normal));
    assert!(bit_identical(&d.denoise(&s.color).unwrap(), &out));
    // Other settings run too: balanced quality, raw guides, no guides, LDR.
    for opts in [
        Options { quality: Quality::Balanced, ..Options::default() },
        Options { quality: Quality::Fast, clean_aux: false, ..Options::default() },
    ] {
        let r = device.denoise(W, H, &s.color, Some(&s.albedo), Some(&s.normal), opts).unwrap();
        assert!(mae(&r, &s.clean) * 2.0 <= mae(&s.color, &s.clean), "{opts:?}");
    }
    let r = device.denoise(W, H, &s.color, None, None, Options::default()).unwrap();
    assert!(r.iter().all(|v| v.is_finite()));
    let ldr: Vec<f32> = s.color.iter().map(|v| v.min(1.0)).collect();
    let r = device.denoise(W, H, &ldr, Some(&albedo), None, Options { hdr: false, ..Options::default() }).unwrap();
    assert!(r.iter().all(|v| v.is_finite()));
}

#[test]
fn bad_lengths_are_refused_before_oidn() {
    let Some(device) = device(1) else { return };
    let s = scene(W, H, 1);
    let refused = |r: Result<Vec<f32>, DenoiseError>, needle: &str| match r {
        Err(DenoiseError::InvalidInput(m)) => assert!(m.contains(needle), "{m:?} lacks {needle:?}"),
        other => panic!("expected InvalidInput({needle}), got {other:?}"),
    };
    let short = &s.color[..s.color.len() - 1];
    refused(device.denoise(W, H, short, None, None, Options::default()), "color has 46079 floats");
    refused(device.denoise(W, H, &s.color, Some(short), None, Options::default()), "albedo guide");
    refused(device.denoise(W, H, &s.color, Some(&s.albedo), Some(short), Options::default()), "normal guide");
    refused(device.denoise(W, H, &s.color, None, Some(&s.normal), Options::default()), "needs an albedo");
    refused(device.prefilter_albedo(W + 1, H, &s.albedo, Quality::High), "a 161x96 RGB plane needs 46368");
    refused(device.prefilter_normal(0, H, &[], Quality::High), "must be > 0");
    refused(device.prefilter_normal(usize::MAX, 2, &[], Quality::High), "overflows");
    let mut d = Denoiser::new(&device, W, H, None, None, Options::default()).unwrap();
    refused(d.denoise(short), "color");
    let mut out = vec![0.0; 3];
    let e = d.denoise_into(&s.color, &mut out).unwrap_err();
    assert!(e.to_string().contains("output has 3 floats"), "{e}");
}
