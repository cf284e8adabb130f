//! Two-level ray acceleration: one BLAS per unique mesh (object space, built
//! once per run and shared by every frame and layer) and a TLAS over the
//! instances' world bounds (rebuilt per frame). With `wide` (which walks
//! obvhs' compressed 8-wide nodes with our own SIMD node test), the only
//! files that name obvhs, so the BVH library can change without touching
//! the integrator.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use glam::{Affine3A, Vec2, Vec3, Vec3A};
use obvhs::{
    aabb::Aabb,
    bvh2::{builder::build_bvh2, Bvh2},
    cwbvh::{
        builder::{build_cwbvh, build_cwbvh_from_tris},
        CwBvh,
    },
    ray::{Ray, RayHit},
    rt_triangle::RtTriangle,
    triangle::Triangle,
    BvhBuildParams,
};
use rayon::prelude::*;

use super::sampler::hash_words;
use super::surface::surface_alpha;
use super::wide::{dispatch, octant_inv4, Kernel, Packet, PacketWalk, Traversal, Walk, PACKET};
use crate::scene::{AlphaMode, Instance, Library, Material, Mesh, SceneMotion};

/// Bottom-level BVH of one mesh, in object space.
pub struct Blas {
    bvh: CwBvh,
    /// Triangles in BVH slot order, so traversal needs no indirection.
    tris: Vec<RtTriangle>,
    /// Original triangle index (into `Mesh::indices / 3`) of each BVH slot.
    triangle_index: Vec<u32>,
}

impl Blas {
    /// Builds the BLAS of `mesh`. Triangles with out-of-range indices or
    /// non-finite vertices are left out rather than failing, and so are
    /// zero-area triangles and exact duplicates: they can never be the
    /// (first) hit, and thousands of them at one point would make a
    /// degenerate, over-deep tree.
    pub(crate) fn build(mesh: &Mesh) -> Blas {
        let mut tris = Vec::with_capacity(mesh.triangle_count());
        let mut original = Vec::with_capacity(mesh.triangle_count());
        let mut seen = std::collections::HashSet::with_capacity(mesh.triangle_count());
        for (i, idx) in mesh.indices.chunks_exact(3).enumerate() {
            let vertex = |k: u32| mesh.positions.get(k as usize).copied().filter(|p| p.is_finite());
            let (Some(a), Some(b), Some(c)) = (vertex(idx[0]), vertex(idx[1]), vertex(idx[2])) else { continue };
            if (b - a).cross(c - a) == Vec3::ZERO {
                continue;
            }
            let key = [a, b, c].map(|p| p.to_array().map(f32::to_bits));
            if !seen.insert(key) {
                continue;
            }
            tris.push(Triangle { v0: a.into(), v1: b.into(), v2: c.into() });
            original.push(i as u32);
        }
        if tris.is_empty() {
            return Blas { bvh: CwBvh::default(), tris: Vec::new(), triangle_index: Vec::new() };
        }
        let bvh = build_cwbvh_from_tris(&tris, BvhBuildParams::medium_build(), &mut Duration::default());
        let (rt, triangle_index) =
            bvh.primitive_indices.iter().map(|&s| (RtTriangle::from(&tris[s as usize]), original[s as usize])).unzip();
        Blas { bvh, tris: rt, triangle_index }
    }

    /// True when the mesh has no valid triangle.
    pub(crate) fn is_empty(&self) -> bool {
        self.tris.is_empty()
    }

    /// Number of triangles in the BVH.
    pub fn triangle_count(&self) -> usize {
        self.tris.len()
    }

    /// Approximate heap bytes of the BVH and its triangles.
    pub(crate) fn bytes(&self) -> usize {
        self.bvh.nodes.len() * std::mem::size_of::<obvhs::cwbvh::node::CwBvhNode>()
            + self.bvh.primitive_indices.len() * 4
            + self.tris.len() * std::mem::size_of::<RtTriangle>()
            + self.triangle_index.len() * 4
    }

    fn bounds(&self) -> Aabb {
        self.bvh.total_aabb
    }

    /// Closest hit in object space: (BVH slot, t).
    #[inline(always)]
    fn intersect<W: Walk>(&self, w: W, ray: Ray) -> Option<(u32, f32)> {
        w.closest(
            &self.bvh,
            ray,
            #[inline(always)]
            |r, s| intersect_triangle(&self.tris[s], r),
        )
    }

    #[inline(always)]
    fn occluded<W: Walk>(&self, w: W, ray: Ray) -> bool {
        w.any(
            &self.bvh,
            ray,
            #[inline(always)]
            |r, s| intersect_triangle(&self.tris[s], r),
        )
    }

    /// As [`Blas::intersect`], skipping the hits `holes` cuts out.
    #[inline(always)]
    fn intersect_cut<W: Walk>(&self, w: W, ray: Ray, holes: &Holes) -> Option<(u32, f32)> {
        w.closest(
            &self.bvh,
            ray,
            #[inline(always)]
            |r, s| holes.filter(hit_triangle(&self.tris[s], r), self.triangle_index[s]),
        )
    }

    #[inline(always)]
    fn occluded_cut<W: Walk>(&self, w: W, ray: Ray, holes: &Holes) -> bool {
        w.any(
            &self.bvh,
            ray,
            #[inline(always)]
            |r, s| holes.filter(hit_triangle(&self.tris[s], r), self.triangle_index[s]),
        )
    }

    /// Closest hit in object space, (BVH slot, t), walked with `traversal`
    /// (tests compare the kernels).
    #[doc(hidden)]
    pub fn intersect_with(&self, traversal: Traversal, origin: Vec3, direction: Vec3, tmax: f32) -> Option<(u32, f32)> {
        let ray = new_ray(origin.into(), (direction + Vec3::ZERO).into(), 0.0, tmax);
        dispatch!(Kernel::detect(traversal), w => self.intersect(w, ray))
    }

    /// True when the ray meets the mesh within (0, tmax), walked with `traversal`.
    #[doc(hidden)]
    pub fn occluded_with(&self, traversal: Traversal, origin: Vec3, direction: Vec3, tmax: f32) -> bool {
        let ray = new_ray(origin.into(), (direction + Vec3::ZERO).into(), 0.0, tmax);
        dispatch!(Kernel::detect(traversal), w => self.occluded(w, ray))
    }

    /// World-space bounds of the mesh's valid triangles (`None` when empty).
    #[doc(hidden)]
    pub fn object_bounds(&self) -> Option<(Vec3, Vec3)> {
        (!self.is_empty()).then(|| (self.bvh.total_aabb.min.into(), self.bvh.total_aabb.max.into()))
    }

    /// Runs obvhs' structural checks (panics on a broken tree; tests only).
    #[doc(hidden)]
    pub(crate) fn validate(&self) {
        if !self.is_empty() {
            self.bvh.validate(&self.tris, true);
        }
    }
}

/// A BLAS over a mesh blending between two poses of the same topology
/// (deformation blur): each triangle's vertices at both keys, and a tree over
/// the union of each triangle's bounds at the two keys. A ray at blend weight
/// `w` meets the triangle `lerp(lo, hi, w)`, which lies inside that union.
pub(crate) struct DeformBlas {
    bvh: CwBvh,
    /// Vertices at the first key, in BVH slot order.
    lo: Vec<[Vec3A; 3]>,
    /// Vertices at the second key.
    hi: Vec<[Vec3A; 3]>,
    /// Original triangle index of each BVH slot.
    triangle_index: Vec<u32>,
}

impl DeformBlas {
    /// Builds the blend of `a` into `b`. Empty when the index buffers differ
    /// (not the same piece) or no triangle is valid at both keys.
    pub(crate) fn build(a: &Mesh, b: &Mesh) -> DeformBlas {
        let empty = || DeformBlas { bvh: CwBvh::default(), lo: Vec::new(), hi: Vec::new(), triangle_index: Vec::new() };
        if a.indices != b.indices || a.positions.len() != b.positions.len() {
            return empty();
        }
        let (mut lo, mut hi, mut aabbs, mut original) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        for (i, idx) in a.indices.chunks_exact(3).enumerate() {
            let get = |m: &Mesh, k: u32| m.positions.get(k as usize).copied().filter(|p| p.is_finite());
            let (Some(a0), Some(a1), Some(a2)) = (get(a, idx[0]), get(a, idx[1]), get(a, idx[2])) else { continue };
            let (Some(b0), Some(b1), Some(b2)) = (get(b, idx[0]), get(b, idx[1]), get(b, idx[2])) else { continue };
            if (a1 - a0).cross(a2 - a0) == Vec3::ZERO && (b1 - b0).cross(b2 - b0) == Vec3::ZERO {
                continue;
            }
            let mut bounds = Aabb::INVALID;
            for p in [a0, a1, a2, b0, b1, b2] {
                bounds.extend(p.into());
            }
            lo.push([a0.into(), a1.into(), a2.into()]);
            hi.push([b0.into(), b1.into(), b2.into()]);
            aabbs.push(bounds);
            original.push(i as u32);
        }
        if aabbs.is_empty() {
            return empty();
        }
        let bvh = build_cwbvh(&aabbs, BvhBuildParams::medium_build(), &mut Duration::default());
        let order = &bvh.primitive_indices;
        DeformBlas {
            lo: order.iter().map(|&s| lo[s as usize]).collect(),
            hi: order.iter().map(|&s| hi[s as usize]).collect(),
            triangle_index: order.iter().map(|&s| original[s as usize]).collect(),
            bvh,
        }
    }

    /// True when nothing can be hit.
    pub(crate) fn is_empty(&self) -> bool {
        self.lo.is_empty()
    }

    /// Approximate heap bytes.
    pub(crate) fn bytes(&self) -> usize {
        self.bvh.nodes.len() * std::mem::size_of::<obvhs::cwbvh::node::CwBvhNode>()
            + self.bvh.primitive_indices.len() * 4
            + (self.lo.len() + self.hi.len()) * std::mem::size_of::<[Vec3A; 3]>()
            + self.triangle_index.len() * 4
    }

    #[inline]
    fn triangle(&self, slot: usize, w: f32) -> RtTriangle {
        let (a, b) = (&self.lo[slot], &self.hi[slot]);
        RtTriangle::new(a[0].lerp(b[0], w), a[1].lerp(b[1], w), a[2].lerp(b[2], w))
    }

    #[inline(always)]
    fn intersect<W: Walk>(&self, k: W, ray: Ray, w: f32) -> Option<(u32, f32)> {
        k.closest(
            &self.bvh,
            ray,
            #[inline(always)]
            |r, s| intersect_triangle(&self.triangle(s, w), r),
        )
    }

    #[inline(always)]
    fn occluded<W: Walk>(&self, k: W, ray: Ray, w: f32) -> bool {
        k.any(
            &self.bvh,
            ray,
            #[inline(always)]
            |r, s| intersect_triangle(&self.triangle(s, w), r),
        )
    }

    #[inline(always)]
    fn intersect_cut<W: Walk>(&self, k: W, ray: Ray, w: f32, holes: &Holes) -> Option<(u32, f32)> {
        k.closest(
            &self.bvh,
            ray,
            #[inline(always)]
            |r, s| holes.filter(hit_triangle(&self.triangle(s, w), r), self.triangle_index[s]),
        )
    }

    #[inline(always)]
    fn occluded_cut<W: Walk>(&self, k: W, ray: Ray, w: f32, holes: &Holes) -> bool {
        k.any(
            &self.bvh,
            ray,
            #[inline(always)]
            |r, s| holes.filter(hit_triangle(&self.triangle(s, w), r), self.triangle_index[s]),
        )
    }
}

/// Möller-Trumbore on obvhs' `RtTriangle` layout, as `RtTriangle::intersect`
/// but with comparisons instead of sign-bit tests: obvhs rejects barycentrics
/// of -0.0, so a ray exactly on the shared edge of two triangles (an
/// axis-aligned ray on a box's face diagonal) missed both and went through.
/// Gives the distance and the barycentrics (u, v) of the hit.
#[inline(always)]
fn hit_triangle(tri: &RtTriangle, ray: &Ray) -> Option<(f32, Vec2)> {
    let c = tri.v0 - ray.origin;
    let r = ray.direction.cross(c);
    let inv_det = 1.0 / tri.ng.dot(ray.direction);
    let u = r.dot(tri.e2) * inv_det;
    let v = r.dot(tri.e1) * inv_det;
    if u >= 0.0 && v >= 0.0 && u + v <= 1.0 && inv_det.is_finite() {
        let t = tri.ng.dot(c) * inv_det;
        if t >= ray.tmin && t <= ray.tmax {
            return Some((t, Vec2::new(u, v)));
        }
    }
    None
}

/// The holes of one instance whose material has alpha MASK or BLEND, for
/// one ray: a candidate hit is kept only where the surface is there.
struct Holes<'m> {
    mesh: &'m Mesh,
    material: &'m Material,
    lib: &'m Library,
    /// Hash of the world ray and the instance: BLEND's coin per triangle.
    key: u32,
}

impl Holes<'_> {
    /// `t` of a candidate hit on original triangle `triangle`, or infinity
    /// where the surface has a hole (so traversal goes on past it).
    #[inline]
    fn filter(&self, hit: Option<(f32, Vec2)>, triangle: u32) -> f32 {
        let Some((t, uv)) = hit else { return f32::INFINITY };
        let alpha = surface_alpha(self.lib, self.material, self.mesh, triangle, uv.x, uv.y);
        let there = match self.material.alpha_mode {
            AlphaMode::Opaque => true,
            AlphaMode::Mask { cutoff } => alpha >= cutoff,
            // Passes with probability 1 - alpha: a 24-bit uniform from the ray, instance and triangle.
            AlphaMode::Blend => {
                let u = (hash_words(&[self.key, triangle]) >> 8) as f32 * (1.0 / 16_777_216.0);
                u < alpha
            }
        };
        if there {
            t
        } else {
            f32::INFINITY
        }
    }
}

/// Whether `m` can have a hole anywhere: alpha MASK or BLEND with a base
/// colour texture, or whose constant alpha is not solid.
fn may_cut(m: &Material, lib: &Library) -> bool {
    let textured = m.base_color_texture.is_some_and(|t| (t as usize) < lib.textures.len());
    match m.alpha_mode {
        AlphaMode::Opaque => false,
        AlphaMode::Mask { cutoff } => textured || m.alpha < cutoff,
        AlphaMode::Blend => textured || m.alpha < 1.0,
    }
}

/// The hash of a world ray that keys BLEND's coins: the same ray meets the
/// same holes on every run and thread count.
fn ray_key(r: &Ray, instance: u32) -> u32 {
    let (o, d) = (r.origin, r.direction);
    hash_words(&[o.x, o.y, o.z, d.x, d.y, d.z].map(f32::to_bits)) ^ hash_words(&[instance])
}

/// The distance to `tri` along `ray` ([`hit_triangle`]), infinite on a miss:
/// what obvhs' traversal takes.
#[inline(always)]
fn intersect_triangle(tri: &RtTriangle, ray: &Ray) -> f32 {
    hit_triangle(tri, ray).map_or(f32::INFINITY, |(t, _)| t)
}

/// One BLAS per [`Library::meshes`] entry, indexed by `MeshId`, each built
/// the first time a render needs it: a layer render builds only the meshes
/// its instances use (its agents, the set, the other layers' casters), not
/// the whole library. Also the deforming BLASes motion blur has asked for
/// so far (built on first use, shared by every later frame and layer).
pub struct BlasSet {
    blas: Vec<std::sync::OnceLock<Blas>>,
    /// Deforming BLASes by (mesh at the first key, mesh at the second).
    deform: Mutex<HashMap<(u32, u32), Arc<DeformBlas>>>,
    /// Wall time of all builds so far.
    pub build_time: Duration,
}

impl BlasSet {
    /// An empty set for `lib`: nothing built yet.
    pub(crate) fn lazy(lib: &Library) -> BlasSet {
        BlasSet {
            blas: (0..lib.meshes.len()).map(|_| std::sync::OnceLock::new()).collect(),
            deform: Mutex::new(HashMap::new()),
            build_time: Duration::ZERO,
        }
    }

    /// Builds every mesh's BLAS in parallel (on the current rayon pool).
    pub fn build(lib: &Library) -> BlasSet {
        let mut set = BlasSet::lazy(lib);
        set.prepare(lib, 0..lib.meshes.len() as u32);
        set
    }

    /// Builds, in parallel, the BLAS of every mesh in `meshes` not built yet
    /// (unknown ids are ignored). Deterministic: a BLAS depends only on its mesh.
    pub(crate) fn prepare(&mut self, lib: &Library, meshes: impl IntoIterator<Item = u32>) {
        let start = Instant::now();
        let mut todo: Vec<u32> =
            meshes.into_iter().filter(|&m| self.blas.get(m as usize).is_some_and(|b| b.get().is_none())).collect();
        todo.sort_unstable();
        todo.dedup();
        let built: Vec<(u32, Blas)> = todo.par_iter().map(|&m| (m, Blas::build(&lib.meshes[m as usize]))).collect();
        for (m, b) in built {
            let _ = self.blas[m as usize].set(b);
        }
        self.build_time += start.elapsed();
    }

    /// Drops every BLAS whose mesh `keep` refuses, and every deforming BLAS
    /// whose (first, second) mesh pair `keep_deform` refuses: a render keeps
    /// only what its current frame traces, so its peak memory is one
    /// frame's BLASes however many frames it renders (skinned crowds change
    /// poses every frame). A dropped BLAS is rebuilt, identically, if needed again.
    pub fn retain(&mut self, keep: impl Fn(u32) -> bool, keep_deform: impl Fn((u32, u32)) -> bool) {
        for (m, b) in self.blas.iter_mut().enumerate() {
            if !keep(m as u32) {
                b.take();
            }
        }
        if let Ok(d) = self.deform.get_mut() {
            d.retain(|&k, _| keep_deform(k));
        }
    }

    /// The BLAS of mesh `id`, if it exists and has been built.
    pub fn get(&self, id: u32) -> Option<&Blas> {
        self.blas.get(id as usize)?.get()
    }

    /// Number of meshes the set covers (built or not).
    pub fn len(&self) -> usize {
        self.blas.len()
    }

    /// True when there are no meshes.
    pub fn is_empty(&self) -> bool {
        self.blas.is_empty()
    }

    /// The deforming BLAS blending mesh `a` into mesh `b` (same topology),
    /// built once and cached. `None` when either mesh is unknown or their
    /// topologies differ, or nothing in them can be hit.
    pub(crate) fn deforming(&self, lib: &Library, a: u32, b: u32) -> Option<Arc<DeformBlas>> {
        if let Some(d) = self.deform.lock().ok()?.get(&(a, b)) {
            return (!d.is_empty()).then(|| d.clone());
        }
        let built = Arc::new(DeformBlas::build(lib.meshes.get(a as usize)?, lib.meshes.get(b as usize)?));
        // Two threads may build the same pair: either result is the same tree.
        let d = self.deform.lock().ok()?.entry((a, b)).or_insert(built).clone();
        (!d.is_empty()).then_some(d)
    }

    /// Approximate heap bytes of the BLASes built so far (deforming ones included).
    pub fn bytes(&self) -> usize {
        let deform: usize = self.deform.lock().map_or(0, |d| d.values().map(|b| b.bytes()).sum());
        self.blas.iter().filter_map(|b| b.get()).map(Blas::bytes).sum::<usize>() + deform
    }

    /// Validates every built BLAS (tests only).
    #[doc(hidden)]
    pub fn validate(&self) {
        self.blas.iter().filter_map(|b| b.get()).for_each(Blas::validate);
    }
}

/// Which obvhs tree the TLAS uses. CwBvh traces faster than Bvh2 at every
/// instance count measured (`examples/peer_bench.rs`, docs/benchmarks.md),
/// and its slower build never pays that back, so it is the default
/// ([`super::Tracing`]). Bvh2 stays for benchmarks.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum TlasKind {
    /// Binary BVH, `fastest_build`.
    Bvh2,
    /// Compressed 8-wide BVH ([`tlas_build_params`]).
    #[default]
    CwBvh,
}

enum TlasTree {
    Empty,
    Bvh2(Bvh2),
    CwBvh(CwBvh),
}

/// An instance as the TLAS stores it, in TLAS slot order.
struct TlasInstance {
    /// Index into `FrameScene::instances`.
    index: u32,
    mesh: u32,
    /// Index into `Tlas::moving`, or [`STILL`].
    motion: u32,
    visibility: u8,
    /// Its material has alpha holes ([`Tlas::holes`] says where); false
    /// keeps the plain walk.
    cutout: bool,
}

/// Up to this many TLAS leaves the tree is built with obvhs'
/// `very_slow_build` (PLOC plus a full pass of reinsertion); above it with
/// `fast_build`. Every TLAS leaf a ray enters costs a transform and a BLAS
/// walk, so a tighter tree pays back many times over its extra build time
/// at crowd sizes (docs/benchmarks.md). Past this the build time would
/// grow into a render's (a million agents render a frame in seconds), so
/// those trees stay fast-built.
pub(crate) const CAREFUL_TLAS_UP_TO: usize = 200_000;

/// The build parameters of a TLAS of `leaves` leaves ([`CAREFUL_TLAS_UP_TO`]).
fn tlas_build_params(leaves: usize) -> BvhBuildParams {
    if leaves <= CAREFUL_TLAS_UP_TO {
        BvhBuildParams::very_slow_build()
    } else {
        BvhBuildParams::fast_build()
    }
}

/// From this many instances on, each agent's parts share one TLAS leaf:
/// below it, a tree over parts traces faster; above it, memory and build
/// time per part dominate (a million robots are eleven million parts).
pub(crate) const AGENT_CLUSTERS_FROM: usize = 1_000_000;

/// The fewest rays of one direction octant [`Tlas::intersect_stream`] walks
/// as a packet; fewer are traced one by one.
pub const MIN_PACKET: usize = 4;

/// `TlasInstance::motion` of an instance that does not move.
const STILL: u32 = u32::MAX;

/// A moving instance: its two transform keys and, when it deforms, the
/// deforming BLAS and blend weights at the keys.
struct MovingInstance {
    world_from_object: [Affine3A; 2],
    deform: Option<(Arc<DeformBlas>, [f32; 2])>,
}

impl MovingInstance {
    /// Object from world at shutter fraction `time` (the transform keys
    /// interpolated linearly, then inverted); `None` if singular there.
    #[inline]
    fn object_from_world(&self, time: f32) -> Option<Affine3A> {
        let [a, b] = &self.world_from_object;
        let m = Affine3A {
            matrix3: a.matrix3 + (b.matrix3 - a.matrix3) * time,
            translation: a.translation + (b.translation - a.translation) * time,
        };
        let inv = m.inverse();
        inv.is_finite().then_some(inv)
    }

    #[inline]
    fn weight(&self, time: f32) -> f32 {
        self.deform.as_ref().map_or(0.0, |(_, [w0, w1])| w0 + (w1 - w0) * time)
    }
}

/// A ray in world space. The direction need not be normalised; `t` is in
/// units of its length.
#[derive(Clone, Copy, Debug)]
pub struct WorldRay {
    /// Origin.
    pub origin: Vec3,
    /// Direction.
    pub direction: Vec3,
    /// Largest accepted `t`.
    pub tmax: f32,
    /// Shutter fraction 0..1 at which the ray travels (motion blur; ignored
    /// by a scene that does not move).
    pub time: f32,
}

/// Closest hit through both levels.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Hit {
    /// Index into `FrameScene::instances`.
    pub instance: u32,
    /// Original triangle index within the instance's mesh.
    pub triangle: u32,
    /// Ray parameter.
    pub t: f32,
    /// Barycentric weight of vertex 1: p = v0 (1-u-v) + v1 u + v2 v.
    pub u: f32,
    /// Barycentric weight of vertex 2.
    pub v: f32,
}

/// Top-level BVH over one frame's instances.
///
/// The tree's primitives are *clusters*: runs of instances with bit-identical
/// world bounds. Many agents at exactly one spot (uninitialised cache rows,
/// stacked duplicate parts) would otherwise make PLOC build a chain thousands
/// deep, overflowing obvhs' fixed traversal stacks silently.
pub struct Tlas<'a> {
    blas: &'a BlasSet,
    /// The frame scene's instances (transforms of agent-leaf trees).
    source: &'a [Instance],
    /// Object from world per entry of `instances`, column-major 3x4; empty
    /// in a tree of agent leaves, where each visit inverts the scene
    /// instance's transform instead (48 bytes fewer for each of millions
    /// of parts, for an inverse per visit).
    inverses: Vec<[f32; 12]>,
    tree: TlasTree,
    /// Instances grouped by cluster, clusters in TLAS slot order.
    instances: Vec<TlasInstance>,
    /// Per TLAS slot: range of `instances`.
    clusters: Vec<(u32, u32)>,
    /// World bounds per TLAS slot (kept for `validate`).
    aabbs: Vec<Aabb>,
    /// Instances that move over the shutter (empty for a still scene).
    moving: Vec<MovingInstance>,
    /// The library, where a tree has instances with alpha holes (`None`:
    /// every surface is solid).
    holes: Option<&'a Library>,
    /// The tree walk ([`super::wide`]): [`super::wide::traversal`] at build.
    kernel: Kernel,
    /// Wall time of the build.
    pub build_time: Duration,
}

fn world_bounds(b: &Aabb, world_from_object: &Affine3A) -> Aabb {
    let mut out = Aabb::INVALID;
    for i in 0..8 {
        let corner = Vec3A::new(
            if i & 1 == 0 { b.min.x } else { b.max.x },
            if i & 2 == 0 { b.min.y } else { b.max.y },
            if i & 4 == 0 { b.min.z } else { b.max.z },
        );
        out.extend(world_from_object.transform_point3a(corner));
    }
    out
}

/// The obvhs ray of a [`WorldRay`]. Adding +0.0 turns -0.0 direction
/// components into +0.0: obvhs derives traversal octants from sign bits, and
/// an axis-aligned ray with a -0.0 component missed boxes it passes through.
#[inline]
fn world_ray(ray: &WorldRay) -> Ray {
    new_ray(ray.origin.into(), (ray.direction + Vec3::ZERO).into(), 0.0, ray.tmax)
}

/// obvhs' `Ray::new`, bit for bit, with the inverse direction taken in one
/// SIMD division and select instead of three branches and divisions: a ray
/// is made at every tree entry (each BLAS it enters).
#[inline(always)]
fn new_ray(origin: Vec3A, direction: Vec3A, tmin: f32, tmax: f32) -> Ray {
    Ray { origin, direction, inv_direction: safe_inverse(direction), tmin, tmax }
}

/// obvhs' `safe_inverse` per component: `1 / x`, or `signum(x) / EPSILON`
/// where `|x| <= EPSILON` (a NaN fails that test and gives `1 / NaN`, as there).
#[inline(always)]
fn safe_inverse(d: Vec3A) -> Vec3A {
    let small = d.abs().cmple(Vec3A::splat(f32::EPSILON));
    // signum(x) / EPSILON is exactly +-2^23 for every x that is not NaN.
    Vec3A::select(small, Vec3A::splat(1.0 / f32::EPSILON).copysign(d), Vec3A::ONE / d)
}

/// Transforms a world ray into an instance's object space. The direction is
/// not renormalised, so `t` means the same distance in both spaces.
#[inline]
fn object_ray(object_from_world: &Affine3A, r: &Ray, tmax: f32) -> Ray {
    transform_ray(object_from_world, r, tmax)
}

#[inline]
fn transform_ray(object_from_world: &Affine3A, r: &Ray, tmax: f32) -> Ray {
    new_ray(
        object_from_world.transform_point3a(r.origin),
        // + 0.0: no -0.0 components (see `world_ray`).
        object_from_world.transform_vector3a(r.direction) + Vec3A::ZERO,
        r.tmin,
        tmax,
    )
}

impl<'a> Tlas<'a> {
    /// Builds the TLAS of `instances` with the default tree kind. Instances with an unknown or empty mesh, a singular or
    /// non-finite transform, or no visibility bits are left out.
    pub fn build(blas: &'a BlasSet, instances: &'a [Instance]) -> Tlas<'a> {
        Self::build_with(blas, instances, TlasKind::CwBvh)
    }

    /// Builds the TLAS of a frame scene's instances, moving over the shutter
    /// when the scene has motion: a moving instance's leaf bounds are the
    /// union of its bounds at the two keys (exact for transforms interpolated
    /// linearly), and rays meet it at their own time. Instances that do not
    /// move are stored and traced exactly as in a still scene. Instances
    /// whose material has alpha MASK or BLEND let rays through their holes.
    pub(crate) fn build_scene(
        blas: &'a BlasSet,
        lib: &'a Library,
        instances: &'a [Instance],
        motion: Option<&SceneMotion>,
        kind: TlasKind,
    ) -> Tlas<'a> {
        let by_agent = instances.len() >= AGENT_CLUSTERS_FROM;
        let still = |_: usize, inst: &Instance, b: &Blas| world_bounds(&b.bounds(), &inst.world_from_object);
        let Some(motion) = motion.filter(|m| m.instances.len() == instances.len()) else {
            return Self::build_keyed(blas, instances, kind, still, &[], Vec::new(), by_agent).with_holes(lib);
        };
        let mut moving = Vec::new();
        let mut index = vec![STILL; instances.len()];
        for (i, (inst, m)) in instances.iter().zip(&motion.instances).enumerate() {
            let deform = m.deform.filter(|d| d.mesh != inst.mesh || d.weight[0] != 0.0 || d.weight[1] != 0.0);
            let deform = deform.and_then(|d| blas.deforming(lib, inst.mesh, d.mesh).map(|b| (b, d.weight)));
            let close = m.world_from_object_close;
            let det = close.matrix3.determinant();
            if !close.is_finite() || !det.is_finite() || det.abs() < 1e-18 {
                continue; // a broken close key: the instance stays still
            }
            if close == inst.world_from_object && deform.is_none() {
                continue;
            }
            index[i] = moving.len() as u32;
            moving.push(MovingInstance { world_from_object: [inst.world_from_object, close], deform });
        }
        if moving.is_empty() {
            return Self::build_keyed(blas, instances, kind, still, &[], Vec::new(), by_agent).with_holes(lib);
        }
        // Moving bounds: the union over the two keys (the deforming BLAS's
        // bounds already cover both poses). An unknown mesh is skipped later.
        let moving_bounds: Vec<Option<Aabb>> = moving
            .iter()
            .zip(index.iter().enumerate().filter(|(_, &k)| k != STILL))
            .map(|(mv, (i, _))| {
                let object = match &mv.deform {
                    Some((d, _)) => d.bvh.total_aabb,
                    None => blas.get(instances[i].mesh)?.bounds(),
                };
                let [a, b] = &mv.world_from_object;
                Some(world_bounds(&object, a).union(&world_bounds(&object, b)))
            })
            .collect();
        let bounds = |i: usize, inst: &Instance, b: &Blas| match index[i] {
            STILL => world_bounds(&b.bounds(), &inst.world_from_object),
            k => moving_bounds[k as usize].unwrap_or_else(|| world_bounds(&b.bounds(), &inst.world_from_object)),
        };
        Self::build_keyed(blas, instances, kind, bounds, &index, moving, by_agent).with_holes(lib)
    }

    /// Builds the TLAS with a chosen tree kind (for benchmarks).
    pub fn build_with(blas: &'a BlasSet, instances: &'a [Instance], kind: TlasKind) -> Tlas<'a> {
        Self::build_clustered(blas, instances, kind, instances.len() >= AGENT_CLUSTERS_FROM)
    }

    /// Builds the TLAS with each agent's parts in one leaf or not, whatever
    /// the instance count (tests compare the two).
    #[doc(hidden)]
    pub fn build_clustered(blas: &'a BlasSet, instances: &'a [Instance], kind: TlasKind, by_agent: bool) -> Tlas<'a> {
        let bounds = |_: usize, inst: &Instance, b: &Blas| world_bounds(&b.bounds(), &inst.world_from_object);
        Self::build_keyed(blas, instances, kind, bounds, &[], Vec::new(), by_agent)
    }

    /// Leaves (clusters) in the tree.
    pub fn leaves(&self) -> usize {
        self.clusters.len()
    }

    fn build_keyed(
        blas: &'a BlasSet,
        instances: &'a [Instance],
        kind: TlasKind,
        world: impl Fn(usize, &Instance, &Blas) -> Aabb,
        motion_index: &[u32],
        moving: Vec<MovingInstance>,
        by_agent: bool,
    ) -> Tlas<'a> {
        let start = Instant::now();
        // Group instances into TLAS leaves (clusters): instances with
        // identical world bounds always (a pile of them would otherwise build
        // a degenerate chain), and in very large scenes every agent's parts
        // (a tree over agents, not parts: a tenth of the nodes and build
        // scratch for a million agents). A sort over flat arrays, not a hash
        // map: clusters come out in first-seen order and members in instance
        // order, so the tree is deterministic.
        let mut bounds: Vec<Aabb> = Vec::with_capacity(instances.len());
        let mut member: Vec<u32> = Vec::with_capacity(instances.len());
        for (i, inst) in instances.iter().enumerate() {
            let Some(b) = blas.get(inst.mesh) else { continue };
            let m = &inst.world_from_object;
            let det = m.matrix3.determinant();
            if b.is_empty() || inst.visibility == 0 || !det.is_finite() || det.abs() < 1e-18 || !m.is_finite() {
                continue;
            }
            bounds.push(world(i, inst, b));
            member.push(i as u32);
        }
        let key = |k: usize| -> [u32; 7] {
            match instances[member[k] as usize].agent.get() {
                Some(a) if by_agent => [0, a, 0, 0, 0, 0, 0],
                _ => {
                    let b = &bounds[k];
                    let [x0, y0, z0, x1, y1, z1] =
                        [b.min.x, b.min.y, b.min.z, b.max.x, b.max.y, b.max.z].map(f32::to_bits);
                    [1, x0, y0, z0, x1, y1, z1]
                }
            }
        };
        let mut sorted: Vec<u32> = (0..member.len() as u32).collect();
        sorted.sort_unstable_by_key(|&k| (key(k as usize), member[k as usize]));
        // Runs of equal keys are clusters (first instance, start, length),
        // ordered by their first instance.
        let mut runs: Vec<(u32, u32, u32)> = Vec::new();
        let mut at = 0;
        while at < sorted.len() {
            let k = key(sorted[at] as usize);
            let end = sorted[at..].iter().position(|&j| key(j as usize) != k).map_or(sorted.len(), |n| at + n);
            runs.push((member[sorted[at] as usize], at as u32, (end - at) as u32));
            at = end;
        }
        runs.sort_unstable_by_key(|r| r.0);
        let aabbs: Vec<Aabb> = runs
            .iter()
            .map(|&(_, start, len)| {
                let mut b = Aabb::INVALID;
                for &j in &sorted[start as usize..(start + len) as usize] {
                    b = b.union(&bounds[j as usize]);
                }
                b
            })
            .collect();
        drop(bounds);
        let (tree, order) = if aabbs.is_empty() {
            (TlasTree::Empty, Vec::new())
        } else {
            match kind {
                TlasKind::Bvh2 => {
                    let bvh = build_bvh2(&aabbs, BvhBuildParams::fastest_build(), &mut Duration::default());
                    let order = bvh.primitive_indices.clone();
                    (TlasTree::Bvh2(bvh), order)
                }
                TlasKind::CwBvh => {
                    let bvh = build_cwbvh(&aabbs, tlas_build_params(aabbs.len()), &mut Duration::default());
                    let order = bvh.primitive_indices.clone();
                    (TlasTree::CwBvh(bvh), order)
                }
            }
        };
        // Lay clusters out in slot order: one fewer indirection per visit.
        let source = instances;
        let mut instances = Vec::with_capacity(member.len());
        let mut inverses = Vec::with_capacity(if by_agent { 0 } else { member.len() });
        let mut clusters = Vec::with_capacity(order.len());
        for &c in &order {
            let (_, start, len) = runs[c as usize];
            clusters.push((instances.len() as u32, len));
            for &j in &sorted[start as usize..(start + len) as usize] {
                let i = member[j as usize];
                let inst = &source[i as usize];
                if !by_agent {
                    inverses.push(inst.world_from_object.inverse().to_cols_array());
                }
                instances.push(TlasInstance {
                    index: i,
                    mesh: inst.mesh,
                    visibility: inst.visibility,
                    motion: motion_index.get(i as usize).copied().unwrap_or(STILL),
                    cutout: false,
                });
            }
        }
        // The leaves' bounds are kept for `validate` in debug builds only.
        let aabbs =
            if cfg!(debug_assertions) { order.iter().map(|&c| aabbs[c as usize]).collect() } else { Vec::new() };
        Tlas {
            blas,
            source,
            inverses,
            tree,
            instances,
            clusters,
            aabbs,
            moving,
            holes: None,
            kernel: Kernel::detect(Traversal::Wide),
            build_time: start.elapsed(),
        }
    }

    /// Marks the instances whose material may cut holes (alpha MASK or
    /// BLEND that is not everywhere solid), so rays pass through them.
    fn with_holes(mut self, lib: &'a Library) -> Tlas<'a> {
        if !lib.materials.iter().any(|m| may_cut(m, lib)) {
            return self;
        }
        let start = Instant::now();
        for inst in &mut self.instances {
            let material = self.source.get(inst.index as usize).and_then(|i| lib.materials.get(i.material as usize));
            inst.cutout = material.is_some_and(|m| may_cut(m, lib));
        }
        if self.instances.iter().any(|i| i.cutout) {
            self.holes = Some(lib);
        }
        self.build_time += start.elapsed();
        self
    }

    /// The same tree walked with `traversal` (tests force each kernel).
    #[doc(hidden)]
    pub fn with_traversal(mut self, traversal: Traversal) -> Tlas<'a> {
        self.kernel = Kernel::detect(traversal);
        self
    }

    /// Name of the kernel this tree is walked with: "obvhs", "scalar", "avx2" or "avx512".
    pub fn kernel_name(&self) -> &'static str {
        self.kernel.name()
    }

    /// Number of instances in the tree.
    pub fn len(&self) -> usize {
        self.instances.len()
    }

    /// True when nothing can be hit.
    pub fn is_empty(&self) -> bool {
        self.instances.is_empty()
    }

    /// Object from world of `instances[k]`.
    #[inline]
    fn object_from_world(&self, k: usize, inst: &TlasInstance) -> Affine3A {
        match self.inverses.get(k) {
            Some(m) => Affine3A::from_cols_array(m),
            None => self.source[inst.index as usize].world_from_object.inverse(),
        }
    }

    #[inline]
    fn cluster(&self, slot: usize) -> std::ops::Range<usize> {
        let (start, len) = self.clusters[slot];
        start as usize..(start + len) as usize
    }

    /// The closest hit of one moving instance at `time`: (BVH slot, t).
    #[inline(always)]
    fn intersect_moving<W: Walk>(
        &self,
        w: W,
        inst: &TlasInstance,
        r: &Ray,
        tmax: f32,
        time: f32,
    ) -> Option<(u32, f32)> {
        let mv = &self.moving[inst.motion as usize];
        let local = transform_ray(&mv.object_from_world(time)?, r, tmax);
        let holes = if inst.cutout { self.holes_of(inst, r) } else { None };
        match (&mv.deform, &holes) {
            (Some((d, _)), None) => d.intersect(w, local, mv.weight(time)),
            (Some((d, _)), Some(h)) => d.intersect_cut(w, local, mv.weight(time), h),
            (None, None) => self.blas.get(inst.mesh)?.intersect(w, local),
            (None, Some(h)) => self.blas.get(inst.mesh)?.intersect_cut(w, local, h),
        }
    }

    #[inline(always)]
    fn occluded_moving<W: Walk>(&self, w: W, inst: &TlasInstance, r: &Ray, time: f32) -> bool {
        let mv = &self.moving[inst.motion as usize];
        let Some(object_from_world) = mv.object_from_world(time) else { return false };
        let local = transform_ray(&object_from_world, r, r.tmax);
        let holes = if inst.cutout { self.holes_of(inst, r) } else { None };
        match (&mv.deform, &holes) {
            (Some((d, _)), None) => d.occluded(w, local, mv.weight(time)),
            (Some((d, _)), Some(h)) => d.occluded_cut(w, local, mv.weight(time), h),
            (None, None) => self.blas.get(inst.mesh).is_some_and(|b| b.occluded(w, local)),
            (None, Some(h)) => self.blas.get(inst.mesh).is_some_and(|b| b.occluded_cut(w, local, h)),
        }
    }

    /// The holes of a cut-out instance for world ray `r` (`None`: solid).
    #[cold]
    fn holes_of(&self, inst: &TlasInstance, r: &Ray) -> Option<Holes<'a>> {
        let lib = self.holes?;
        let source = self.source.get(inst.index as usize)?;
        Some(Holes {
            mesh: lib.meshes.get(inst.mesh as usize)?,
            material: lib.materials.get(source.material as usize)?,
            lib,
            key: ray_key(r, inst.index),
        })
    }

    /// Closest hit among instances whose visibility shares a bit with `mask`.
    /// Moving instances are met where they are at `ray.time`.
    pub fn intersect(&self, ray: &WorldRay, mask: u8) -> Option<Hit> {
        dispatch!(self.kernel, w => self.intersect_in(w, ray, mask))
    }

    #[inline(always)]
    fn intersect_in<W: Walk>(&self, w: W, ray: &WorldRay, mask: u8) -> Option<Hit> {
        let world = world_ray(ray);
        let time = ray.time;
        // (instance position, BLAS slot) of the closest hit so far.
        let mut best = (usize::MAX, u32::MAX);
        // The leaf visit is a closure marked to inline into the walk, which
        // runs in the kernel's SIMD context: left to itself, the compiler
        // kept it a function of its own, compiled without AVX2, and the
        // BLAS walks in it called into AVX2 once per node test.
        let found = match &self.tree {
            TlasTree::Empty => None,
            TlasTree::Bvh2(bvh) => {
                let mut hit = RayHit::none();
                let visit = |r: &Ray, slot: usize| self.visit_closest(w, r, slot, mask, time, &mut best);
                bvh.ray_traverse(world, &mut hit, visit).then_some(hit.t)
            }
            TlasTree::CwBvh(bvh) => w
                .closest(
                    bvh,
                    world,
                    #[inline(always)]
                    |r: &Ray, slot: usize| self.visit_closest(w, r, slot, mask, time, &mut best),
                )
                .map(|(_, t)| t),
        };
        self.closest_hit(&world, time, best, found)
    }

    /// The visit of TLAS leaf `slot` in a closest-hit walk of world ray `r`
    /// (whose tmax is the closest hit so far, which prunes each BLAS walk):
    /// every instance of the leaf that `mask` admits, through its BLAS.
    /// The `t` of a hit closer than `r.tmax` (infinity if none); `best`
    /// becomes its (instance position, BLAS slot).
    #[inline(always)]
    fn visit_closest<W: Walk>(&self, w: W, r: &Ray, slot: usize, mask: u8, time: f32, best: &mut (usize, u32)) -> f32 {
        let mut closest = r.tmax;
        let mut found = f32::INFINITY;
        for k in self.cluster(slot) {
            let inst = &self.instances[k];
            if inst.visibility & mask == 0 {
                continue;
            }
            let hit = if inst.motion == STILL {
                let Some(b) = self.blas.get(inst.mesh) else { continue };
                let local = object_ray(&self.object_from_world(k, inst), r, closest);
                match inst.cutout.then(|| self.holes_of(inst, r)).flatten() {
                    None => b.intersect(w, local),
                    Some(holes) => b.intersect_cut(w, local, &holes),
                }
            } else {
                self.intersect_moving(w, inst, r, closest, time)
            };
            if let Some((s, t)) = hit {
                if t < closest {
                    (closest, found, *best) = (t, t, (k, s));
                }
            }
        }
        found
    }

    /// The [`Hit`] of world ray `world` (as it entered the walk) whose walk
    /// ended at `found` with `best` (from [`Tlas::visit_closest`]).
    #[inline(always)]
    fn closest_hit(&self, world: &Ray, time: f32, best: (usize, u32), found: Option<f32>) -> Option<Hit> {
        let t = found.filter(|_| best.0 != usize::MAX)?;
        let inst = &self.instances[best.0];
        let slot = best.1 as usize;
        let (uv, triangle) = if inst.motion == STILL {
            let b = self.blas.get(inst.mesh)?;
            let local = object_ray(&self.object_from_world(best.0, inst), world, world.tmax);
            (b.tris[slot].compute_barycentric(&local), b.triangle_index[slot])
        } else {
            let mv = &self.moving[inst.motion as usize];
            let local = transform_ray(&mv.object_from_world(time)?, world, world.tmax);
            match &mv.deform {
                Some((d, _)) => (d.triangle(slot, mv.weight(time)).compute_barycentric(&local), d.triangle_index[slot]),
                None => {
                    let b = self.blas.get(inst.mesh)?;
                    (b.tris[slot].compute_barycentric(&local), b.triangle_index[slot])
                }
            }
        };
        Some(Hit { instance: inst.index, triangle, t, u: uv.x, v: uv.y })
    }

    /// The closest hits of a stream of rays, `hits[i]` of `rays[i]`: each
    /// exactly what [`Tlas::intersect`] gives for it (same `t`, instance,
    /// triangle and barycentrics, bit for bit), traced as packets where rays
    /// are coherent. Rays are grouped by direction octant; each group of at
    /// least [`MIN_PACKET`] walks the TLAS as packets of up to
    /// 32 (one fetch of a node for every ray that
    /// reaches it), each ray entering its own instances' BLASes at the
    /// leaves; smaller groups are traced one ray at a time.
    pub fn intersect_stream(&self, rays: &[WorldRay], mask: u8, hits: &mut [Option<Hit>]) {
        self.intersect_stream_with(rays, mask, MIN_PACKET, hits);
    }

    /// As [`Tlas::intersect_stream`] with octant groups of at least
    /// `min_packet` rays walked as packets (1: every ray in a packet; tests
    /// force each path). Returns how many rays a packet walk answered
    /// (the rest were traced one by one).
    #[doc(hidden)]
    pub fn intersect_stream_with(
        &self,
        rays: &[WorldRay],
        mask: u8,
        min_packet: usize,
        hits: &mut [Option<Hit>],
    ) -> usize {
        assert_eq!(rays.len(), hits.len(), "one hit per ray");
        dispatch!(self.kernel, w => self.intersect_stream_in(w, rays, mask, min_packet.max(1), hits))
    }

    #[inline(always)]
    fn intersect_stream_in<W: PacketWalk>(
        &self,
        w: W,
        rays: &[WorldRay],
        mask: u8,
        min_packet: usize,
        hits: &mut [Option<Hit>],
    ) -> usize {
        let TlasTree::CwBvh(bvh) = &self.tree else {
            for (h, r) in hits.iter_mut().zip(rays) {
                *h = self.intersect_in(w, r, mask);
            }
            return 0;
        };
        let mut in_packets = 0;
        // Ray indices by octant, in ray order within each (a counting sort).
        let world: Vec<Ray> = rays.iter().map(world_ray).collect();
        let octant = |r: &Ray| (octant_inv4(r.direction) & 7) as usize;
        let mut starts = [0usize; 9];
        for r in &world {
            starts[octant(r) + 1] += 1;
        }
        for o in 0..8 {
            starts[o + 1] += starts[o];
        }
        let mut order = vec![0u32; rays.len()];
        let mut next = starts;
        for (i, r) in world.iter().enumerate() {
            let o = octant(r);
            order[next[o]] = i as u32;
            next[o] += 1;
        }
        let mut packet = [Ray::new(Vec3A::ZERO, Vec3A::X, 0.0, 0.0); PACKET];
        for o in 0..8 {
            let group = &order[starts[o]..starts[o + 1]];
            if group.len() < min_packet {
                for &i in group {
                    hits[i as usize] = self.intersect_in(w, &rays[i as usize], mask);
                }
                continue;
            }
            for chunk in group.chunks(PACKET) {
                let n = chunk.len();
                for (p, &i) in packet.iter_mut().zip(chunk) {
                    *p = world[i as usize];
                }
                let mut best = [(usize::MAX, u32::MAX); PACKET];
                let walked = w.closest_packet(
                    bvh,
                    &mut packet[..n],
                    #[inline(always)]
                    |k, r, slot| self.visit_closest(w, r, slot, mask, rays[chunk[k] as usize].time, &mut best[k]),
                );
                in_packets += if walked == Packet::Done { n } else { 0 };
                for (k, &i) in chunk.iter().enumerate() {
                    let i = i as usize;
                    hits[i] = match walked {
                        Packet::Done => {
                            let found = (best[k].0 != usize::MAX).then_some(packet[k].tmax);
                            self.closest_hit(&world[i], rays[i].time, best[k], found)
                        }
                        Packet::Single => self.intersect_in(w, &rays[i], mask),
                    };
                }
            }
        }
        in_packets
    }

    /// True when any instance whose visibility shares a bit with `mask`
    /// blocks the ray within (0, tmax), moving instances at `ray.time`.
    pub fn occluded(&self, ray: &WorldRay, mask: u8) -> bool {
        self.occluded_by(ray, mask, |_| true)
    }

    /// As [`Tlas::occluded`], counting only the instances whose scene index
    /// `counts` accepts (the shadow pass asks whether the set alone blocks a ray).
    pub(crate) fn occluded_by(&self, ray: &WorldRay, mask: u8, counts: impl Fn(u32) -> bool) -> bool {
        dispatch!(self.kernel, w => self.occluded_in(w, ray, mask, &counts))
    }

    #[inline(always)]
    fn occluded_in<W: Walk>(&self, w: W, ray: &WorldRay, mask: u8, counts: &impl Fn(u32) -> bool) -> bool {
        let world = world_ray(ray);
        let time = ray.time;
        let visit = |r: &Ray, slot: usize| self.visit_any(w, r, slot, mask, time, counts);
        match &self.tree {
            TlasTree::Empty => false,
            TlasTree::Bvh2(bvh) => !bvh.ray_traverse_miss(world, visit),
            // Inlined into the walk, as `intersect_in`'s visit.
            TlasTree::CwBvh(bvh) => w.any(
                bvh,
                world,
                #[inline(always)]
                |r: &Ray, slot: usize| self.visit_any(w, r, slot, mask, time, counts),
            ),
        }
    }

    /// The visit of TLAS leaf `slot` in an any-hit walk of world ray `r`:
    /// 0 where an instance `mask` and `counts` admit blocks it, else infinity.
    #[inline(always)]
    fn visit_any<W: Walk>(
        &self,
        w: W,
        r: &Ray,
        slot: usize,
        mask: u8,
        time: f32,
        counts: &impl Fn(u32) -> bool,
    ) -> f32 {
        // A plain loop, not `Iterator::any`: `any`'s `try_fold` is not
        // always inlined, and then this whole leaf visit (the BLAS any-hit
        // walk and its triangle tests) runs outside the walk's AVX2 body.
        for k in self.cluster(slot) {
            let inst = &self.instances[k];
            if inst.visibility & mask == 0 || !counts(inst.index) {
                continue;
            }
            // No closures here either (`is_some_and`'s was not inlined).
            let blocked = if inst.motion != STILL {
                self.occluded_moving(w, inst, r, time)
            } else if let Some(b) = self.blas.get(inst.mesh) {
                let local = object_ray(&self.object_from_world(k, inst), r, r.tmax);
                match if inst.cutout { self.holes_of(inst, r) } else { None } {
                    None => b.occluded(w, local),
                    Some(holes) => b.occluded_cut(w, local, &holes),
                }
            } else {
                false
            };
            if blocked {
                return 0.0; // any value below tmax stops the walk
            }
        }
        f32::INFINITY
    }

    /// World-space bounds of everything in the tree (`None` when empty).
    pub fn bounds(&self) -> Option<(Vec3, Vec3)> {
        let aabb = match &self.tree {
            TlasTree::Empty => return None,
            TlasTree::Bvh2(bvh) => *bvh.nodes.first()?.aabb(),
            TlasTree::CwBvh(bvh) => bvh.total_aabb,
        };
        Some((aabb.min.into(), aabb.max.into()))
    }

    /// Runs obvhs' structural checks on the tree (panics if broken; tests only).
    #[doc(hidden)]
    pub fn validate(&self) {
        let aabbs = &self.aabbs;
        if aabbs.is_empty() {
            return; // a release build keeps no leaf bounds
        }
        match &self.tree {
            TlasTree::Empty => {}
            TlasTree::Bvh2(bvh) => {
                bvh.validate(aabbs, true, false);
            }
            TlasTree::CwBvh(bvh) => {
                bvh.validate(aabbs, true);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `new_ray` inverts as obvhs' `Ray::new` does, bit for bit, at the edges of
    /// `safe_inverse` (zeros, +-EPSILON and their neighbours, subnormals,
    /// infinities, NaN) and on a sweep of bit patterns.
    #[test]
    fn new_ray_inverts_as_obvhs_does() {
        let eps = f32::EPSILON;
        let mut values = vec![
            0.0,
            -0.0,
            eps,
            -eps,
            f32::from_bits(eps.to_bits() + 1),
            f32::from_bits(eps.to_bits() - 1),
            -f32::from_bits(eps.to_bits() + 1),
            f32::MIN_POSITIVE,
            1e-40,
            -1e-40,
            1.0,
            -3.5,
            f32::MAX,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
        ];
        values.extend((0..200_000u32).map(|k| f32::from_bits(k.wrapping_mul(0x9e37_79b9) ^ (k << 7))));
        for w in values.chunks(3).filter(|w| w.len() == 3) {
            let d = Vec3A::new(w[0], w[1], w[2]);
            let ours = new_ray(Vec3A::ONE, d, 0.0, 2.0).inv_direction.to_array().map(f32::to_bits);
            // obvhs' `Ray::new` takes `safe_inverse` per component (called
            // directly: its debug assertions refuse the non-finite cases).
            let theirs = [d.x, d.y, d.z].map(|x| obvhs::ray::safe_inverse(x).to_bits());
            assert_eq!(ours, theirs, "{d:?}");
        }
    }
}
