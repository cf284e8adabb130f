//! Our own traversal of obvhs' compressed 8-wide BVH nodes (`CwBvh`, the
//! BLASes and the TLAS): the same nodes, the same walk order and the same
//! tie rules as obvhs' `ray_traverse` / `ray_traverse_miss`, but the eight
//! child boxes of a node are tested in one 8-lane operation where the CPU
//! has AVX2 or AVX-512 (chosen at run time, so one portable binary uses
//! what the node has; on AVX-512 the same node test, with the whole query
//! compiled for AVX-512), with a portable scalar kernel everywhere else.
//!
//! Bit-identical on every path: every kernel does the same IEEE f32
//! operations in the same order, each rounded on its own (a multiply, then
//! an add: Rust never contracts them into a fused multiply-add, and neither
//! kernel calls one), `max(a, b)` is `a > b ? a : b` and `min(a, b)` is
//! `a < b ? a : b` on both (the semantics of the x86 instructions, NaN
//! included), and the hit mask is built from the same per-child booleans in
//! the same order. What differs is only how many lanes run at once.
//! `tests/wide.rs` forces each path on random rays over the demo's meshes
//! and checks the closest hits (t and primitive) and any-hit answers agree,
//! with each other and with obvhs' own traversal; on an AVX-512 CPU it
//! forces the AVX2 kernel too.
//!
//! Packets (`PacketWalk`, `walk_packet`): up to 32 rays of one direction
//! octant walk a tree together, each with its own child and primitive bits
//! and its own `tmax`, so each meets exactly the nodes and primitives of
//! its single-ray walk, in the same order: the same hits, bit for bit
//! (`Tlas::intersect_stream` uses it for camera rays; docs/benchmarks.md,
//! issue 25 item 2, has the argument and the figures).
//!
//! Safe: SIMD dispatch goes through `pulp` (its `V3` and `V4` tokens prove
//! AVX2 and AVX-512, and their intrinsics are safe functions), so the
//! crate's `forbid(unsafe_code)` holds.

use obvhs::cwbvh::{node::CwBvhNode, CwBvh};
use obvhs::ray::Ray;

/// Which BVH traversal the trees use ([`super::Tracing`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Traversal {
    /// obvhs' own `ray_traverse` (its node test is two 4-wide SSE halves).
    Obvhs,
    /// Ours, one child box at a time: the portable kernel.
    Scalar,
    /// Ours, the widest kernel this CPU has (AVX-512, else AVX2, else the
    /// scalar kernel).
    #[default]
    Wide,
    /// Ours, 8-wide AVX2 even where AVX-512 is present (the scalar kernel
    /// where AVX2 is absent): to test and measure the AVX2 path on any CPU.
    Avx2,
}

/// The kernel `t` resolves to on this CPU: "obvhs", "scalar", "avx2" or "avx512".
pub fn kernel_name(t: Traversal) -> &'static str {
    Kernel::detect(t).name()
}

/// A resolved kernel: [`Traversal`] with the CPU's features detected.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Kernel {
    Obvhs,
    Scalar,
    #[cfg(target_arch = "x86_64")]
    Avx2(pulp::x86::V3),
    /// The AVX2 node test with the whole query (walks, instance entry,
    /// triangle tests) compiled for AVX-512 (x86-64-v4). Why not a 16-lane
    /// test: a node has eight children, so 16 lanes means each child's near
    /// planes in the low half and far planes in the high half (one multiply
    /// and one add per axis instead of two), which was no faster on the CPUs
    /// measured, nor was an 8-lane test with its compare into a mask
    /// register (docs/benchmarks.md).
    #[cfg(target_arch = "x86_64")]
    Avx512(pulp::x86::V4),
}

impl Kernel {
    /// The kernel for `t` on this CPU.
    pub(crate) fn detect(t: Traversal) -> Kernel {
        match t {
            Traversal::Obvhs => Kernel::Obvhs,
            Traversal::Scalar => Kernel::Scalar,
            #[cfg(target_arch = "x86_64")]
            Traversal::Wide => pulp::x86::V4::try_new().map_or_else(|| Kernel::detect(Traversal::Avx2), Kernel::Avx512),
            #[cfg(target_arch = "x86_64")]
            Traversal::Avx2 => pulp::x86::V3::try_new().map_or(Kernel::Scalar, Kernel::Avx2),
            #[cfg(not(target_arch = "x86_64"))]
            Traversal::Wide | Traversal::Avx2 => Kernel::Scalar,
        }
    }

    /// Name of the kernel, for reports.
    pub(crate) fn name(self) -> &'static str {
        match self {
            Kernel::Obvhs => "obvhs",
            Kernel::Scalar => "scalar",
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx2(_) => "avx2",
            #[cfg(target_arch = "x86_64")]
            Kernel::Avx512(_) => "avx512",
        }
    }
}

/// A tree walk: closest hit and any hit over a `CwBvh`, with the primitive
/// test a closure of (ray with the current tmax, primitive slot) giving the
/// hit distance (infinity on a miss), as obvhs' `ray_traverse` takes.
pub(crate) trait Walk: Copy {
    /// The closest primitive slot and its `t` below `ray.tmax`.
    fn closest(self, bvh: &CwBvh, ray: Ray, prim: impl FnMut(&Ray, usize) -> f32) -> Option<(u32, f32)>;
    /// True when any primitive gives a `t` below `ray.tmax`.
    fn any(self, bvh: &CwBvh, ray: Ray, prim: impl FnMut(&Ray, usize) -> f32) -> bool;
}

/// obvhs' own traversal.
#[derive(Clone, Copy)]
pub(crate) struct ObvhsWalk;

impl Walk for ObvhsWalk {
    #[inline(always)]
    fn closest(self, bvh: &CwBvh, ray: Ray, prim: impl FnMut(&Ray, usize) -> f32) -> Option<(u32, f32)> {
        let mut hit = obvhs::ray::RayHit::none();
        bvh.ray_traverse(ray, &mut hit, prim).then_some((hit.primitive_id, hit.t))
    }

    #[inline(always)]
    fn any(self, bvh: &CwBvh, ray: Ray, prim: impl FnMut(&Ray, usize) -> f32) -> bool {
        !bvh.ray_traverse_miss(ray, prim)
    }
}

/// The most rays a packet walk ([`PacketWalk::closest_packet`]) takes: one bit each in a `u32`.
pub(crate) const PACKET: usize = 32;

/// What a packet walk did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Packet {
    /// Every ray walked as its single-ray walk would have.
    Done,
    /// Not walked as a packet, or given up (the packet's stack filled, where a
    /// member's single-ray walk might have overwritten its top): the caller
    /// traces the rays one by one from the start.
    Single,
}

/// The packet form of [`Walk`]: `rays` (at most [`PACKET`], all of one
/// direction octant) walked together, each meeting exactly the nodes and
/// primitives, in the same order and with the same `tmax`, as its own
/// [`Walk::closest`] walk (see [`walk_packet`]). `prim` gets the ray's
/// index in `rays` as well.
pub(crate) trait PacketWalk: Walk {
    /// As [`Walk::closest`] per ray: each ray's `tmax` ends at its closest `t`
    /// (`prim` records which primitive that was).
    fn closest_packet(self, bvh: &CwBvh, rays: &mut [Ray], prim: impl FnMut(usize, &Ray, usize) -> f32) -> Packet;
}

impl PacketWalk for ObvhsWalk {
    #[inline(always)]
    fn closest_packet(self, _: &CwBvh, _: &mut [Ray], _: impl FnMut(usize, &Ray, usize) -> f32) -> Packet {
        Packet::Single
    }
}

impl<T: NodeTest> PacketWalk for OurWalk<T> {
    #[inline(always)]
    fn closest_packet(self, bvh: &CwBvh, rays: &mut [Ray], mut prim: impl FnMut(usize, &Ray, usize) -> f32) -> Packet {
        walk_packet(
            self.0,
            bvh,
            rays,
            #[inline(always)]
            |i, r, slot| {
                let t = prim(i, r, slot as usize);
                if t < r.tmax {
                    r.tmax = t;
                }
                false
            },
        )
    }
}

/// Our traversal with node test `T`.
#[derive(Clone, Copy)]
pub(crate) struct OurWalk<T>(pub T);

impl<T: NodeTest> Walk for OurWalk<T> {
    #[inline(always)]
    fn closest(self, bvh: &CwBvh, ray: Ray, mut prim: impl FnMut(&Ray, usize) -> f32) -> Option<(u32, f32)> {
        let mut r = ray;
        let mut best = None;
        walk(
            self.0,
            bvh,
            &mut r,
            #[inline(always)]
            |r, slot| {
                let t = prim(r, slot as usize);
                if t < r.tmax {
                    best = Some((slot, t));
                    r.tmax = t;
                }
                false
            },
        );
        best
    }

    #[inline(always)]
    fn any(self, bvh: &CwBvh, ray: Ray, mut prim: impl FnMut(&Ray, usize) -> f32) -> bool {
        let mut r = ray;
        walk(
            self.0,
            bvh,
            &mut r,
            #[inline(always)]
            |r, slot| prim(r, slot as usize) < r.tmax,
        )
    }
}

/// The child-box test of one node: the hit mask obvhs' `intersect_ray`
/// gives (internal children in the high byte, by traversal priority; leaf
/// primitives in the low 24 bits).
pub(crate) trait NodeTest: Copy {
    fn hits(self, node: &CwBvhNode, ray: &Ray, oct_inv4: u32) -> u32;
}

/// obvhs' lower bound on a child's entry distance (its `EPSILON`, private there).
const ENTRY_EPSILON: f32 = 0.0001;

/// `a > b ? a : b`: x86 `maxps`' rule, NaN included, on every kernel.
#[inline(always)]
fn max(a: f32, b: f32) -> f32 {
    if a > b {
        a
    } else {
        b
    }
}

/// `a < b ? a : b`: x86 `minps`' rule.
#[inline(always)]
fn min(a: f32, b: f32) -> f32 {
    if a < b {
        a
    } else {
        b
    }
}

/// The per-node ray terms: the ray moved into the node's quantised grid
/// (extent times inverse direction, and the grid origin's distance).
#[inline(always)]
fn node_ray(node: &CwBvhNode, ray: &Ray) -> ([f32; 3], [f32; 3]) {
    let e = node.e.map(|e| f32::from_bits((e as u32) << 23));
    let inv = ray.inv_direction;
    let (o, p) = (ray.origin, node.p);
    ([e[0] * inv.x, e[1] * inv.y, e[2] * inv.z], [(p.x - o.x) * inv.x, (p.y - o.y) * inv.y, (p.z - o.z) * inv.z])
}

/// [`node_ray`] in one SSE step per term (the same multiply and subtract
/// per axis). It runs at every node test, where the scalar form's shifts,
/// moves and products cost a measurable share of a render's instructions.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn node_ray_lanes(s: pulp::x86::V3, node: &CwBvhNode, ray: &Ray) -> ([f32; 4], [f32; 4]) {
    use std::arch::x86_64::__m128;
    // The three exponent bytes, each moved into an f32's exponent field: 2^(e - 127).
    let e = i32::from_le_bytes([node.e[0], node.e[1], node.e[2], 0]);
    let scale =
        s.sse2._mm_castsi128_ps(s.sse2._mm_slli_epi32::<23>(s.sse4_1._mm_cvtepu8_epi32(s.sse2._mm_cvtsi32_si128(e))));
    let inv: __m128 = ray.inv_direction.into();
    let (p, o): (__m128, __m128) = (glam::Vec3A::from(node.p).into(), ray.origin.into());
    let dir = s.sse._mm_mul_ps(scale, inv);
    let org = s.sse._mm_mul_ps(s.sse._mm_sub_ps(p, o), inv);
    (pulp::bytemuck::cast(dir), pulp::bytemuck::cast(org))
}

/// The near and far planes of each axis for the ray's direction signs.
#[inline(always)]
fn planes<'n>(node: &'n CwBvhNode, ray: &Ray) -> [(&'n [u8; 8], &'n [u8; 8]); 3] {
    let pick = |neg: bool, lo, hi| if neg { (hi, lo) } else { (lo, hi) };
    [
        pick(ray.direction.x < 0.0, &node.child_min_x, &node.child_max_x),
        pick(ray.direction.y < 0.0, &node.child_min_y, &node.child_max_y),
        pick(ray.direction.z < 0.0, &node.child_min_z, &node.child_max_z),
    ]
}

/// The node hit mask from the 8-bit mask of children whose box the ray
/// meets, as obvhs builds it: the scalar kernel's. [`hit_mask_lanes`] is
/// its SIMD form (tests compare the kernels' hits bit for bit).
#[inline(always)]
fn hit_mask(node: &CwBvhNode, oct_inv4: u32, mut boxes: u32) -> u32 {
    let (child_bits8, bit_index8) = node.get_child_and_index_bits(oct_inv4);
    let mut mask = 0;
    while boxes != 0 {
        let child = boxes.trailing_zeros() * 8;
        boxes &= boxes - 1;
        mask |= (((child_bits8 >> child) as u32) & 0xff) << (((bit_index8 >> child) as u32) & 0xff);
    }
    mask
}

/// [`hit_mask`] in eight lanes, from `met` (all ones in the lanes of the
/// children whose box the ray meets): each lane takes its child's bits and
/// their place from the child's meta byte (obvhs' `get_child_and_index_bits`
/// byte by byte: its u64 shifts never carry a bit into a kept position of
/// the next byte), shifts the bits there, is zeroed where the box was
/// missed, and the eight are ORed. The same integer, without the scalar
/// form's sixteen u64 steps and its branch per child met.
#[cfg(target_arch = "x86_64")]
#[inline(always)]
fn hit_mask_lanes(s: pulp::x86::V3, node: &CwBvhNode, oct_inv4: u32, met: std::arch::x86_64::__m256i) -> u32 {
    use std::arch::x86_64::__m256i;
    let (a, b) = (s.avx2, s.sse2);
    let meta: __m256i = pulp::bytemuck::cast(
        s.convert_u8x16_to_i32x8(pulp::bytemuck::cast([u64::from_le_bytes(node.child_meta), 0u64])),
    );
    let splat = |x: u32| -> __m256i { pulp::bytemuck::cast(s.splat_u32x8(x)) };
    // An inner child's meta is 0b001_11xxx (bits 3 and 4 set; never both in a leaf's).
    let is_inner = a._mm256_and_si256(a._mm256_and_si256(meta, a._mm256_slli_epi32::<1>(meta)), splat(0x10));
    let inner = a._mm256_cmpeq_epi32(is_inner, splat(0x10));
    let octant = a._mm256_and_si256(splat(oct_inv4 & 0xff), inner);
    let bit_index = a._mm256_and_si256(a._mm256_xor_si256(meta, octant), splat(0x1f));
    let child_bits = a._mm256_and_si256(a._mm256_srli_epi32::<5>(meta), splat(0x07));
    // Shifts are below 32 (masked to five bits above).
    let kept = a._mm256_and_si256(a._mm256_sllv_epi32(child_bits, bit_index), met);
    let x = b._mm_or_si128(s.avx._mm256_castsi256_si128(kept), a._mm256_extracti128_si256::<1>(kept));
    let x = b._mm_or_si128(x, b._mm_shuffle_epi32::<0b01_00_11_10>(x));
    let x = b._mm_or_si128(x, b._mm_shuffle_epi32::<0b10_11_00_01>(x));
    b._mm_cvtsi128_si32(x) as u32
}

/// One child at a time: the portable kernel.
#[derive(Clone, Copy)]
pub(crate) struct ScalarTest;

impl NodeTest for ScalarTest {
    #[inline(always)]
    fn hits(self, node: &CwBvhNode, ray: &Ray, oct_inv4: u32) -> u32 {
        let (dir, org) = node_ray(node, ray);
        let [(nx, fx), (ny, fy), (nz, fz)] = planes(node, ray);
        let mut boxes = 0u32;
        for c in 0..8 {
            let near = [nx[c] as f32 * dir[0] + org[0], ny[c] as f32 * dir[1] + org[1], nz[c] as f32 * dir[2] + org[2]];
            let far = [fx[c] as f32 * dir[0] + org[0], fy[c] as f32 * dir[1] + org[1], fz[c] as f32 * dir[2] + org[2]];
            let tmin = max(max(near[0], max(near[1], near[2])), ENTRY_EPSILON);
            let tmax = min(min(far[0], min(far[1], far[2])), ray.tmax);
            boxes |= ((tmin <= tmax) as u32) << c;
        }
        hit_mask(node, oct_inv4, boxes)
    }
}

/// All eight children in one AVX2 operation per step.
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy)]
pub(crate) struct Avx2Test(pub pulp::x86::V3);

#[cfg(target_arch = "x86_64")]
impl NodeTest for Avx2Test {
    #[inline(always)]
    fn hits(self, node: &CwBvhNode, ray: &Ray, oct_inv4: u32) -> u32 {
        let s = self.0;
        s.vectorize(
            #[inline(always)]
            || {
                use pulp::{f32x8, u8x16};
                let (dir, org) = node_ray_lanes(s, node, ray);
                let [(nx, fx), (ny, fy), (nz, fz)] = planes(node, ray);
                // Eight u8 planes widened to eight f32 lanes (exact: 0..=255).
                let lanes = |q: &[u8; 8]| -> f32x8 {
                    let bytes: u8x16 = pulp::bytemuck::cast([u64::from_le_bytes(*q), 0u64]);
                    s.convert_i32x8_to_f32x8(s.convert_u8x16_to_i32x8(bytes))
                };
                let axis = |q: &[u8; 8], k: usize| {
                    s.add_f32x8(s.mul_f32x8(lanes(q), s.splat_f32x8(dir[k])), s.splat_f32x8(org[k]))
                };
                let (near_x, far_x) = (axis(nx, 0), axis(fx, 0));
                let (near_y, far_y) = (axis(ny, 1), axis(fy, 1));
                let (near_z, far_z) = (axis(nz, 2), axis(fz, 2));
                // max_f32x8 is maxps (a > b ? a : b), min_f32x8 minps: as `max` / `min` above.
                let tmin = s.max_f32x8(s.max_f32x8(near_x, s.max_f32x8(near_y, near_z)), s.splat_f32x8(ENTRY_EPSILON));
                let tmax = s.min_f32x8(s.min_f32x8(far_x, s.min_f32x8(far_y, far_z)), s.splat_f32x8(ray.tmax));
                let met = pulp::bytemuck::cast(s.cmp_le_f32x8(tmin, tmax));
                hit_mask_lanes(s, node, oct_inv4, met)
            },
        )
    }
}

/// A value a closure spends, so that the closure is `FnOnce` by nature.
/// pulp's `vectorize` calls its closure through `FnOnce::call_once`; for a
/// closure that is `Fn` by nature that is a compiler-made shim, which is not
/// always inlined into pulp's AVX2 function, so the whole query ended up
/// compiled without AVX2 in the shim, calling into AVX2 once per node test.
/// A closure that spends a `Once` is its own `call_once`, inlined.
pub(crate) struct Once;

impl Once {
    #[inline(always)]
    pub(crate) fn spend(self) {}
}

/// Runs `$body` with `$w` bound to the [`Walk`] of `$kernel`; on AVX2 and
/// AVX-512, inside pulp's `vectorize`, so the whole query (tree walks, triangle tests) is
/// compiled with the features the kernel has and its node tests inline.
macro_rules! dispatch {
    // The AVX2 node test inside `$simd`'s `vectorize` (AVX2 or AVX-512):
    // `$v3` is the AVX2 token the node test takes.
    (@simd $simd:ident, $v3:expr, $w:ident => $body:expr) => {{
        let once = $crate::render::wide::Once;
        $simd.vectorize(
            #[inline(always)]
            || {
                once.spend();
                let $w = $crate::render::wide::OurWalk($crate::render::wide::Avx2Test($v3));
                $body
            },
        )
    }};
    ($kernel:expr, $w:ident => $body:expr) => {
        match $kernel {
            $crate::render::wide::Kernel::Obvhs => {
                let $w = $crate::render::wide::ObvhsWalk;
                $body
            }
            $crate::render::wide::Kernel::Scalar => {
                let $w = $crate::render::wide::OurWalk($crate::render::wide::ScalarTest);
                $body
            }
            #[cfg(target_arch = "x86_64")]
            $crate::render::wide::Kernel::Avx2(v3) => $crate::render::wide::dispatch!(@simd v3, v3, $w => $body),
            #[cfg(target_arch = "x86_64")]
            $crate::render::wide::Kernel::Avx512(v4) => $crate::render::wide::dispatch!(@simd v4, *v4, $w => $body),
        }
    };
}
pub(crate) use dispatch;

/// obvhs' traversal order code for a direction: which child octant is near.
/// Rays with the same code walk a tree's nodes in the same order.
///
/// One compare of the three components at once and a table lookup: it is
/// computed at every tree entry (each BLAS a ray enters), where three
/// scalar compares and selects cost more.
#[inline(always)]
pub(crate) fn octant_inv4(d: glam::Vec3A) -> u32 {
    // Bit k set: component k < 0.0 (so -0.0 and NaN count as positive).
    let negative = d.cmplt(glam::Vec3A::ZERO).bitmask() as usize & 7;
    OCTANT_CODES[negative]
}

/// [`octant_inv4`] by the mask of negative components.
const OCTANT_CODES: [u32; 8] = {
    let mut codes = [0u32; 8];
    let mut m = 0;
    while m < 8 {
        codes[m] = (if m & 1 != 0 { 0 } else { 0x04040404 })
            | (if m & 2 != 0 { 0 } else { 0x02020202 })
            | (if m & 4 != 0 { 0 } else { 0x01010101 });
        m += 1;
    }
    codes
};

/// obvhs' traversal stack depth; as there, a full stack overwrites its top.
const STACK: usize = 32;

/// The walk of obvhs' `traverse!` macro over `bvh` with node test `test`:
/// node groups by priority, leaf primitives high bit first. `prim` gets the
/// ray (whose tmax it may lower) and a primitive slot, and returns true to
/// stop the walk. True when `prim` stopped it.
#[inline(always)]
fn walk<T: NodeTest>(test: T, bvh: &CwBvh, ray: &mut Ray, mut prim: impl FnMut(&mut Ray, u32) -> bool) -> bool {
    if bvh.nodes.is_empty() {
        return false;
    }
    let oct_inv4 = octant_inv4(ray.direction);
    let mut stack = [(0u32, 0u32); STACK];
    let mut depth = 0usize;
    // (base index, hit bits) of the node group and of the primitive group.
    let mut group = (0u32, 0x8000_0000u32);
    let mut prims = (0u32, 0u32);
    loop {
        while prims.1 != 0 {
            let local = 31 - prims.1.leading_zeros();
            prims.1 &= !(1 << local);
            if prim(ray, prims.0 + local) {
                return true;
            }
        }
        if group.1 & 0xff00_0000 != 0 {
            let hits = group.1;
            let offset = 31 - hits.leading_zeros();
            group.1 &= !(1 << offset);
            if group.1 & 0xff00_0000 != 0 {
                stack[depth] = group;
                depth = (depth + 1).min(STACK - 1);
            }
            let slot = (offset - 24) ^ (oct_inv4 & 0xff);
            let relative = (hits & !(u32::MAX << slot)).count_ones();
            let node = &bvh.nodes[(group.0 + relative) as usize];
            let mask = test.hits(node, ray, oct_inv4);
            group = (node.child_base_idx, (mask & 0xff00_0000) | node.imask as u32);
            prims = (node.primitive_base_idx, mask & 0x00ff_ffff);
        } else {
            group = (0, 0);
        }
        if prims.1 == 0 && group.1 & 0xff00_0000 == 0 {
            if depth == 0 {
                return false;
            }
            depth -= 1;
            group = stack[depth];
        }
    }
}

/// A node group of a packet walk: the group's base index and internal-child
/// mask (as in [`walk`]) and, per child priority (bit `24 + p` of a
/// single-ray walk's group), the rays that have that child still to visit.
#[derive(Clone, Copy)]
struct PacketGroup {
    base: u32,
    imask: u32,
    rays: [u32; 8],
}

/// [`walk`] for up to [`PACKET`] rays of one direction octant at once.
///
/// Exact, not approximate: the single-ray walk's child order depends only on
/// the octant, never on entry distances, so a depth-first walk over the
/// union of the rays' child bits, in that order, is a supersequence of each
/// ray's own walk. Each ray keeps its own child bits (a node is tested only
/// for the rays whose own bits reached it, each with its own `tmax`) and its
/// own primitive bits (run ray by ray, high bit first, right after that
/// ray's node test, as `walk` does), so every ray meets the same nodes and
/// primitives in the same order with the same `tmax` as alone. A ray leaves
/// the walk where `prim` returns true for it (any hit). The packet's stack
/// is at least as deep as any member's; where it would reach the depth at
/// which `walk` starts overwriting its top, the walk stops and says
/// [`Packet::Single`], and the caller traces the rays one by one.
#[inline(always)]
fn walk_packet<T: NodeTest>(
    test: T,
    bvh: &CwBvh,
    rays: &mut [Ray],
    mut prim: impl FnMut(usize, &mut Ray, u32) -> bool,
) -> Packet {
    let n = rays.len();
    if n == 0 || bvh.nodes.is_empty() {
        return Packet::Done;
    }
    if n > PACKET {
        return Packet::Single;
    }
    let oct_inv4 = octant_inv4(rays[0].direction);
    if rays.iter().any(|r| octant_inv4(r.direction) != oct_inv4) {
        return Packet::Single;
    }
    let mut alive = if n == PACKET { u32::MAX } else { (1u32 << n) - 1 };
    let mut stack = [PacketGroup { base: 0, imask: 0, rays: [0; 8] }; STACK];
    let mut depth = 0usize;
    // The root: `walk`'s first group (0, 0x8000_0000), every ray on its top bit.
    let mut group = PacketGroup { base: 0, imask: 0, rays: [0, 0, 0, 0, 0, 0, 0, alive] };
    loop {
        // The highest child priority some live ray still has in this group.
        let mut p = 8;
        for q in (0..8).rev() {
            if group.rays[q] & alive != 0 {
                p = q;
                break;
            }
        }
        if p == 8 {
            if depth == 0 {
                return Packet::Done;
            }
            depth -= 1;
            group = stack[depth];
            continue;
        }
        let here = group.rays[p] & alive;
        group.rays[p] = 0;
        if group.rays[..p].iter().any(|&r| r & alive != 0) {
            if depth == STACK - 1 {
                return Packet::Single; // `walk` would overwrite its top here
            }
            stack[depth] = group;
            depth += 1;
        }
        let slot = p as u32 ^ (oct_inv4 & 0xff);
        let relative = (group.imask & !(u32::MAX << slot)).count_ones();
        let node = &bvh.nodes[(group.base + relative) as usize];
        let mut next = PacketGroup { base: node.child_base_idx, imask: node.imask as u32, rays: [0; 8] };
        let mut todo = here;
        while todo != 0 {
            let i = todo.trailing_zeros() as usize;
            todo &= todo - 1;
            let ray = &mut rays[i];
            let mask = test.hits(node, ray, oct_inv4);
            let mut prims = mask & 0x00ff_ffff;
            let mut stopped = false;
            while prims != 0 {
                let local = 31 - prims.leading_zeros();
                prims &= !(1 << local);
                if prim(i, ray, node.primitive_base_idx + local) {
                    stopped = true;
                    break;
                }
            }
            if stopped {
                alive &= !(1 << i);
                if alive == 0 {
                    return Packet::Done;
                }
                continue;
            }
            let mut children = mask >> 24;
            while children != 0 {
                let c = children.trailing_zeros() as usize;
                children &= children - 1;
                next.rays[c] |= 1 << i;
            }
        }
        group = next;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use obvhs::{cwbvh::builder::build_cwbvh_from_tris, triangle::Triangle, BvhBuildParams};

    /// A small deterministic generator (no dependency): xorshift.
    fn rng(state: &mut u64) -> f32 {
        *state ^= *state << 13;
        *state ^= *state >> 7;
        *state ^= *state << 17;
        (*state >> 40) as f32 / (1u64 << 24) as f32
    }

    #[test]
    fn octant_code_is_the_per_component_rule() {
        let rule = |d: glam::Vec3A| -> u32 {
            (if d.x < 0.0 { 0 } else { 0x04040404 })
                | (if d.y < 0.0 { 0 } else { 0x02020202 })
                | (if d.z < 0.0 { 0 } else { 0x01010101 })
        };
        let values = [0.0, -0.0, 1.0, -1.0, 1e-30, -1e-30, f32::INFINITY, f32::NEG_INFINITY, f32::NAN, -f32::NAN];
        for &x in &values {
            for &y in &values {
                for &z in &values {
                    let d = glam::Vec3A::new(x, y, z);
                    assert_eq!(octant_inv4(d), rule(d), "{d:?}");
                }
            }
        }
    }

    #[test]
    fn every_kernel_walks_a_random_soup_as_obvhs_does() {
        let mut s = 0x9e37_79b9_7f4a_7c15u64;
        let v = |s: &mut u64| glam::Vec3A::new(rng(s), rng(s), rng(s)) * 10.0 - 5.0;
        let tris: Vec<Triangle> = (0..2000)
            .map(|_| {
                let a = v(&mut s);
                Triangle { v0: a, v1: a + v(&mut s) * 0.1, v2: a + v(&mut s) * 0.1 }
            })
            .collect();
        let bvh = build_cwbvh_from_tris(&tris, BvhBuildParams::medium_build(), &mut std::time::Duration::default());
        let order = bvh.primitive_indices.clone();
        let prim = |r: &Ray, s: usize| tris[order[s] as usize].intersect(r);
        // The CPU's widest kernel, AVX2 forced (where AVX-512 is the widest), and scalar.
        let kernels = [Traversal::Wide, Traversal::Avx2, Traversal::Scalar].map(Kernel::detect);
        let mut met = 0;
        for _ in 0..4000 {
            let ray = Ray::new(v(&mut s), v(&mut s).normalize(), 0.0, 3.0 + rng(&mut s) * 10.0);
            let want = ObvhsWalk.closest(&bvh, ray, prim);
            let want_any = ObvhsWalk.any(&bvh, ray, prim);
            met += want.is_some() as u32;
            for k in kernels {
                let (got, any) = dispatch!(k, w => (w.closest(&bvh, ray, prim), w.any(&bvh, ray, prim)));
                assert_eq!(got.map(|(p, t)| (p, t.to_bits())), want.map(|(p, t)| (p, t.to_bits())), "{}", k.name());
                assert_eq!(any, want_any, "{}", k.name());
            }
        }
        assert!(met > 400, "too few rays met the soup ({met}) for the test to mean anything");
    }
}
