//! Our BVH traversal (render::wide) gives the same hits on every kernel:
//! the AVX-512 node test (where the CPU has it), the 8-wide AVX2
//! one, the portable scalar one and obvhs' own walk,
//! forced one by one on random rays over the demo's meshes (each BLAS alone)
//! and over a whole frame of the demo (TLAS and BLASes together). Packets
//! (`Tlas::intersect_stream`) give every ray's single-ray hit, bit for bit,
//! on random rays of every octant and on a camera's rays, on every kernel,
//! and a render with camera packets is the render without them.

mod common;

use glam::Vec3;
use throng::casting::ShotCrowd;
use throng::render::accel::{Hit, Tlas, WorldRay, MIN_PACKET};
use throng::render::camera::CameraRays;
use throng::render::wide::Traversal;
use throng::render::BlasSet;
use throng::scene::vis;

const KERNELS: [Traversal; 4] = [Traversal::Wide, Traversal::Scalar, Traversal::Obvhs, Traversal::Avx2];

/// xorshift64: deterministic rays without a dependency.
struct Rng(u64);

impl Rng {
    fn f(&mut self) -> f32 {
        self.0 ^= self.0 << 13;
        self.0 ^= self.0 >> 7;
        self.0 ^= self.0 << 17;
        (self.0 >> 40) as f32 / (1u64 << 24) as f32
    }

    /// A point in the box (lo, hi) grown by half its size each way.
    fn point(&mut self, lo: Vec3, hi: Vec3) -> Vec3 {
        let size = hi - lo;
        lo - size * 0.5 + Vec3::new(self.f(), self.f(), self.f()) * size * 2.0
    }

    /// A direction: mostly random, sometimes along an axis or a face
    /// diagonal (with -0.0 and exact zeros, the edge cases of slab tests),
    /// sometimes towards `target`.
    fn direction(&mut self, from: Vec3, target: Vec3) -> Vec3 {
        let sign = |r: &mut Rng| if r.f() < 0.5 { -1.0 } else { 1.0 };
        match (self.f() * 4.0) as u32 {
            0 => {
                let mut d = [0.0f32, -0.0, 0.0];
                d[(self.f() * 3.0) as usize % 3] = sign(self);
                Vec3::from(d)
            }
            1 => Vec3::new(sign(self), sign(self), if self.f() < 0.5 { 0.0 } else { -0.0 }),
            2 => target - from,
            _ => Vec3::new(self.f() - 0.5, self.f() - 0.5, self.f() - 0.5) * 2.0,
        }
    }
}

fn key(h: Option<(u32, f32)>) -> Option<(u32, u32)> {
    h.map(|(p, t)| (p, t.to_bits()))
}

fn hit_key(h: Option<Hit>) -> Option<(u32, u32, u32, u32, u32)> {
    h.map(|h| (h.instance, h.triangle, h.t.to_bits(), h.u.to_bits(), h.v.to_bits()))
}

/// Whether this CPU has what pulp's AVX-512 token (x86-64-v4) asks for.
fn has_avx512() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::is_x86_feature_detected as has;
        has!("avx512f") && has!("avx512bw") && has!("avx512cd") && has!("avx512dq") && has!("avx512vl") && has_avx2()
    }
    #[cfg(not(target_arch = "x86_64"))]
    false
}

fn has_avx2() -> bool {
    #[cfg(target_arch = "x86_64")]
    {
        std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma")
    }
    #[cfg(not(target_arch = "x86_64"))]
    false
}

/// The wide kernel really is the widest this CPU has (AVX-512, else AVX2),
/// so the comparisons below are not scalar against scalar.
fn wide_kernel_is_the_cpus(name: &str) {
    let want = if has_avx512() {
        "avx512"
    } else if has_avx2() {
        "avx2"
    } else {
        "scalar"
    };
    assert_eq!(name, want);
}

#[test]
fn every_kernel_finds_the_same_hits_on_the_demo_meshes() {
    let crowd = ShotCrowd::load(&common::demo_shot()).unwrap();
    let lib = crowd.library();
    let blas = BlasSet::build(lib);
    let mut rng = Rng(0x2545_f491_4f6c_dd1d);
    let (mut rays, mut hits) = (0u32, 0u32);
    for id in 0..blas.len() as u32 {
        let Some(b) = blas.get(id) else { continue };
        let Some((lo, hi)) = b.object_bounds() else { continue };
        for _ in 0..3000 {
            let o = rng.point(lo, hi);
            let target = rng.point(lo, hi) * 0.5 + (lo + hi) * 0.25;
            let d = rng.direction(o, target);
            if d == Vec3::ZERO {
                continue;
            }
            let tmax = if rng.f() < 0.3 { f32::INFINITY } else { rng.f() * 2.0 };
            let want = key(b.intersect_with(Traversal::Obvhs, o, d, tmax));
            let want_any = b.occluded_with(Traversal::Obvhs, o, d, tmax);
            assert_eq!(want.is_some(), want_any, "mesh {id}: closest and any hit disagree");
            for k in KERNELS {
                assert_eq!(key(b.intersect_with(k, o, d, tmax)), want, "mesh {id}, {k:?}, ray {o} {d} {tmax}");
                assert_eq!(b.occluded_with(k, o, d, tmax), want_any, "mesh {id}, {k:?}, ray {o} {d} {tmax}");
            }
            rays += 1;
            hits += want.is_some() as u32;
        }
    }
    assert!(rays > 30_000 && hits > rays / 10, "{hits} hits of {rays} rays: too few to test anything");
}

#[test]
fn every_kernel_finds_the_same_hits_in_a_demo_frame() {
    let crowd = ShotCrowd::load(&common::demo_shot()).unwrap();
    let frame = crowd.shot().frames.start;
    let scene = throng::render::job::streamed_frame_scene(&crowd, None, throng::output::FULL_LAYER, frame).unwrap();
    let blas = BlasSet::build(crowd.library());
    let trees: Vec<Tlas> = KERNELS.iter().map(|&k| Tlas::build(&blas, &scene.instances).with_traversal(k)).collect();
    wide_kernel_is_the_cpus(trees[0].kernel_name());
    assert_eq!(trees[1].kernel_name(), "scalar");
    assert_eq!(trees[2].kernel_name(), "obvhs");
    assert_eq!(trees[3].kernel_name(), if has_avx2() { "avx2" } else { "scalar" });
    let (lo, hi) = trees[0].bounds().unwrap();
    // Rays from inside the crowd's box (and around it), most aimed at an
    // agent's part so they meet the crowd, not just the ground.
    let mut rng = Rng(0x9e37_79b9_7f4a_7c15);
    let (mut hits, mut blocked) = (0u32, 0u32);
    let n = 20_000;
    for i in 0..n {
        let inst = &scene.instances[i % scene.instances.len()];
        let target = inst.world_from_object.translation.into();
        let o = rng.point(lo, hi);
        let d = rng.direction(o, target);
        if d == Vec3::ZERO {
            continue;
        }
        let tmax = if rng.f() < 0.5 { f32::INFINITY } else { rng.f() * 4.0 };
        let ray = WorldRay { origin: o, direction: d, tmax, time: 0.0 };
        let mask = [vis::ALL, vis::CAMERA, vis::SHADOW, vis::INDIRECT][i % 4];
        let want = hit_key(trees[2].intersect(&ray, mask));
        let want_any = trees[2].occluded(&ray, mask);
        for t in &trees[..2] {
            assert_eq!(hit_key(t.intersect(&ray, mask)), want, "{} ray {o} {d} {tmax} mask {mask}", t.kernel_name());
            assert_eq!(t.occluded(&ray, mask), want_any, "{} ray {o} {d} {tmax} mask {mask}", t.kernel_name());
        }
        hits += want.is_some() as u32;
        blocked += want_any as u32;
    }
    assert!(hits > n as u32 / 5 && blocked >= hits, "{hits} hits, {blocked} blocked of {n}: too few to test anything");
}

/// Every ray of `rays` through `tlas` as a stream (packets forced for every
/// octant group, and the default grouping) against its single-ray hit.
/// Returns how many rays the forced stream answered from packet walks.
fn stream_matches_single(tlas: &Tlas, rays: &[WorldRay], mask: u8, what: &str) -> usize {
    let want: Vec<_> = rays.iter().map(|r| hit_key(tlas.intersect(r, mask))).collect();
    let mut in_packets = 0;
    for min_packet in [1, MIN_PACKET] {
        let mut hits = vec![None; rays.len()];
        let n = tlas.intersect_stream_with(rays, mask, min_packet, &mut hits);
        if min_packet == 1 {
            in_packets = n;
        }
        for (i, (h, w)) in hits.into_iter().zip(&want).enumerate() {
            let r = &rays[i];
            assert_eq!(
                hit_key(h),
                *w,
                "{what}: {} min_packet {min_packet} ray {i} {} {} {} mask {mask}",
                tlas.kernel_name(),
                r.origin,
                r.direction,
                r.tmax
            );
        }
    }
    in_packets
}

#[test]
fn packets_find_the_single_ray_hits_on_random_rays_of_every_octant() {
    let crowd = ShotCrowd::load(&common::demo_shot()).unwrap();
    let frame = crowd.shot().frames.start;
    let scene = throng::render::job::streamed_frame_scene(&crowd, None, throng::output::FULL_LAYER, frame).unwrap();
    let blas = BlasSet::build(crowd.library());
    let mut rng = Rng(0x1234_5678_9abc_def1);
    for k in KERNELS {
        let tlas = Tlas::build(&blas, &scene.instances).with_traversal(k);
        let (lo, hi) = tlas.bounds().unwrap();
        let (mut rays_total, mut packed, mut hits) = (0usize, 0usize, 0usize);
        // Streams of many sizes (1 to 200 rays), each of rays from one spot
        // to random agents (somewhat coherent) or from anywhere (not at all),
        // in every octant, with finite and infinite tmax.
        for s in 0..120 {
            let len = 1 + (rng.f() * 200.0) as usize;
            let spot = rng.point(lo, hi);
            let rays: Vec<WorldRay> = (0..len)
                .filter_map(|i| {
                    let o = if s % 2 == 0 { spot } else { rng.point(lo, hi) };
                    let inst = &scene.instances[(rng.f() * scene.instances.len() as f32) as usize];
                    let d = rng.direction(o, inst.world_from_object.translation.into());
                    let tmax = if i % 3 == 0 { rng.f() * 10.0 } else { f32::INFINITY };
                    (d != Vec3::ZERO).then_some(WorldRay { origin: o, direction: d, tmax, time: 0.0 })
                })
                .collect();
            let mask = [vis::ALL, vis::CAMERA | vis::HOLDOUT, vis::INDIRECT][s % 3];
            packed += stream_matches_single(&tlas, &rays, mask, "random");
            rays_total += rays.len();
            hits += rays.iter().filter(|r| tlas.intersect(r, mask).is_some()).count();
        }
        assert!(hits > rays_total / 5, "{hits} hits of {rays_total} rays: too few to test anything");
        if tlas.kernel_name() == "obvhs" {
            assert_eq!(packed, 0, "obvhs' walk has no packets: its rays go one by one");
        } else {
            assert!(packed > rays_total * 9 / 10, "{packed} of {rays_total} rays were walked as packets");
        }
    }
}

#[test]
fn packets_find_the_single_ray_hits_of_a_camera_over_a_demo_frame() {
    let crowd = ShotCrowd::load(&common::demo_shot()).unwrap();
    let frame = crowd.shot().frames.start;
    let scene = throng::render::job::streamed_frame_scene(&crowd, None, throng::output::FULL_LAYER, frame).unwrap();
    let blas = BlasSet::build(crowd.library());
    let (w, h) = (160u32, 90u32);
    let camera = CameraRays::new(&scene.camera, w, h);
    let mut rng = Rng(0x0bad_cafe_f00d_d00d);
    for k in KERNELS {
        let tlas = Tlas::build(&blas, &scene.instances).with_traversal(k);
        wide_kernel_is_the_cpus(Tlas::build(&blas, &scene.instances).with_traversal(Traversal::Wide).kernel_name());
        let (mut total, mut packed, mut hits) = (0usize, 0usize, 0usize);
        // Per 8x4 block of pixels, eight jittered rays per pixel, in pixel order.
        for by in (0..h).step_by(4) {
            for bx in (0..w).step_by(8) {
                let rays: Vec<WorldRay> = (by..by + 4)
                    .flat_map(|y| (bx..bx + 8).map(move |x| (x, y)))
                    .flat_map(|(x, y)| (0..8).map(move |_| (x, y)))
                    .map(|(x, y)| {
                        let (origin, direction) = camera.ray(x as f32 + rng.f(), y as f32 + rng.f());
                        WorldRay { origin, direction, tmax: f32::INFINITY, time: 0.0 }
                    })
                    .collect();
                packed += stream_matches_single(&tlas, &rays, vis::CAMERA | vis::HOLDOUT, "camera");
                hits += rays.iter().filter(|r| tlas.intersect(r, vis::CAMERA | vis::HOLDOUT).is_some()).count();
                total += rays.len();
            }
        }
        assert!(hits > total / 2, "{hits} of {total} camera rays hit: too few to test anything");
        if tlas.kernel_name() != "obvhs" {
            assert!(packed > total * 9 / 10, "{packed} of {total} camera rays were walked as packets");
        }
    }
}

/// The render path: a blurred demo frame, the full image and a crowd layer
/// (whose set is a holdout), plain and adaptive, with camera rays traced as
/// packets and one by one, and on every kernel (the CPU's widest, AVX2 and
/// scalar): the same films, bit for bit.
#[test]
fn a_render_with_camera_packets_is_the_render_without_on_every_kernel() {
    use throng::render::job::{self, RenderJob};
    use throng::render::Tracing;
    let dir = common::tempdir().unwrap();
    let shutter = [-0.25, 0.25];
    let crowd = ShotCrowd::open(throng::shot::Shot::load(&common::demo_shot()).unwrap(), Some(shutter)).unwrap();
    let manifest = throng::layers::build_layers(&crowd, &Default::default()).unwrap();
    let mut layers = job::all_layers(&manifest);
    assert!(layers.len() >= 2, "the demo has a set layer and crowd layers: {layers:?}");
    layers.push("full".into());
    let render = |packets: bool, kernel: Traversal, adaptive: Option<throng::shot::Adaptive>, out: &str| {
        let job = RenderJob {
            shutter: Some(shutter),
            resolution: Some([96, 54]),
            adaptive,
            tracing: Tracing { traversal: kernel, camera_packets: packets, ..Tracing::default() },
            ..RenderJob::new(layers.clone(), vec![1024], 8, dir.path().join(out))
        };
        let done = job::run(&crowd, Some(&manifest), &job, &job::Silent).unwrap().layers;
        done.iter().map(|l| throng::render::exr::read_layer(&l.path).unwrap().0).collect::<Vec<_>>()
    };
    let adaptive = Some(throng::shot::Adaptive { threshold: 0.05, min_spp: 3, max_spp: 12 });
    for (a, name) in [(None, "plain"), (adaptive, "adaptive")] {
        let with = render(true, Traversal::Wide, a, &format!("{name}_p"));
        let without = render(false, Traversal::Wide, a, &format!("{name}_s"));
        assert_eq!(with.len(), layers.len());
        for (x, y) in with.iter().zip(&without) {
            assert!(x == y, "{name}: a layer differs with camera packets");
        }
        for k in [Traversal::Avx2, Traversal::Scalar] {
            let other = render(true, k, a, &format!("{name}_{k:?}"));
            for (x, y) in with.iter().zip(&other) {
                assert!(x == y, "{name}: a layer differs on the {k:?} kernel");
            }
        }
        assert!(with.iter().all(|f| f.rgba.iter().any(|p| p[3] > 0.0)), "{name}: every layer shows something");
    }
}
