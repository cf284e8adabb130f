//! Our BVH traversal (render::wide) gives the same hits on every kernel:
//! the 8-wide AVX2 node test, the portable scalar one and obvhs' own walk,
//! forced one by one on random rays over the demo's meshes (each BLAS alone)
//! and over a whole frame of the demo (TLAS and BLASes together).

mod common;

use glam::Vec3;
use throng::casting::ShotCrowd;
use throng::render::accel::{Hit, Tlas, WorldRay};
use throng::render::wide::Traversal;
use throng::render::BlasSet;
use throng::scene::vis;

const KERNELS: [Traversal; 3] = [Traversal::Wide, Traversal::Scalar, Traversal::Obvhs];

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

/// The wide kernel really is AVX2 where the CPU has it, so the comparisons
/// below are not scalar against scalar.
fn wide_kernel_is_the_cpus(name: &str) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma") {
        assert_eq!(name, "avx2");
        return;
    }
    assert_eq!(name, "scalar");
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
