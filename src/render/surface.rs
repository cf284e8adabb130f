//! Surfaces and their materials: what a ray hit looks like. Textures looked
//! up at a hit's texture coordinate, alpha and coverage (which the BVH walk
//! reads to let rays through holes), emission (which the lights read for
//! emissive triangles), and the full shading point the integrator reads: the
//! hit's position, geometric and shading normals (interpolated, normal-mapped)
//! and its material's textured parameters.

use glam::{Affine3A, Mat3A, Vec2, Vec3, Vec4};

use crate::scene::{AlphaMode, FrameScene, Library, Material, Mesh, Texture, TextureRef, UvTransform};

/// Bilinear lookup with wrap (glTF REPEAT); v = 0 is the top row.
pub(crate) fn sample_texture(tex: &Texture, uv: Vec2) -> Vec4 {
    let (w, h) = (tex.width as usize, tex.height as usize);
    if w == 0 || h == 0 || tex.texels.len() < w * h || !uv.is_finite() {
        return Vec4::ONE;
    }
    let x = uv.x * w as f32 - 0.5;
    let y = uv.y * h as f32 - 0.5;
    let (x0, y0) = (x.floor(), y.floor());
    let (fx, fy) = (x - x0, y - y0);
    let wrap = |i: f32, n: usize| (i as i64).rem_euclid(n as i64) as usize;
    let (xa, xb) = (wrap(x0, w), wrap(x0 + 1.0, w));
    let (ya, yb) = (wrap(y0, h), wrap(y0 + 1.0, h));
    let t = |x: usize, y: usize| Vec4::from_array(tex.texels[y * w + x]);
    let top = t(xa, ya).lerp(t(xb, ya), fx);
    let bottom = t(xa, yb).lerp(t(xb, yb), fx);
    top.lerp(bottom, fy)
}

/// The texture coordinate at barycentrics (b1, b2) of the triangle with
/// vertices `idx`; `None` for a mesh without UVs.
#[inline]
fn uv_at(mesh: &Mesh, idx: [usize; 3], b1: f32, b2: f32) -> Option<Vec2> {
    if mesh.uvs.len() != mesh.positions.len() {
        return None;
    }
    let [t0, t1, t2] = idx.map(|i| mesh.uvs[i]);
    Some(t0 * (1.0 - b1 - b2) + t1 * b1 + t2 * b2)
}

/// Texture `texture` (an index into `lib.textures`) at texture coordinate
/// `uv` through `transform`; `None` without either.
#[inline]
fn texel(lib: &Library, texture: Option<u32>, transform: &UvTransform, uv: Option<Vec2>) -> Option<Vec4> {
    let tex = lib.textures.get(texture? as usize)?;
    Some(sample_texture(tex, transform.apply(uv?)))
}

#[inline]
fn texel_ref(lib: &Library, texture: Option<TextureRef>, uv: Option<Vec2>) -> Option<Vec4> {
    let t = texture?;
    texel(lib, Some(t.texture), &t.uv, uv)
}

/// The vertex indices of triangle `triangle` of `mesh`, checked.
#[inline]
fn triangle_vertices(mesh: &Mesh, triangle: u32) -> Option<[usize; 3]> {
    let k = triangle as usize * 3;
    let idx = mesh.indices.get(k..k + 3)?;
    let idx = [idx[0] as usize, idx[1] as usize, idx[2] as usize];
    idx.iter().all(|&i| i < mesh.positions.len()).then_some(idx)
}

/// A material's alpha (coverage) at barycentrics (b1, b2) of a triangle of
/// `mesh`: base colour factor alpha x base colour texture alpha.
pub(crate) fn surface_alpha(lib: &Library, material: &Material, mesh: &Mesh, triangle: u32, b1: f32, b2: f32) -> f32 {
    let texture = triangle_vertices(mesh, triangle)
        .and_then(|idx| texel(lib, material.base_color_texture, &material.base_color_uv, uv_at(mesh, idx, b1, b2)));
    material.alpha * texture.map_or(1.0, |t| t.w)
}

/// How much of a surface is there on average at alpha `alpha`: 0 or 1 for
/// MASK, alpha itself for BLEND's stochastic holes, 1 for OPAQUE.
pub(crate) fn coverage(material: &Material, alpha: f32) -> f32 {
    match material.alpha_mode {
        AlphaMode::Opaque => 1.0,
        AlphaMode::Mask { cutoff } => {
            if alpha >= cutoff {
                1.0
            } else {
                0.0
            }
        }
        AlphaMode::Blend => alpha.clamp(0.0, 1.0),
    }
}

/// The emitted radiance of a material at barycentrics (b1, b2) of triangle
/// `triangle` of `mesh`, front side: emission x emissive texture, x the
/// coverage where alpha cuts holes (what NEE on emissive triangles sees).
pub(crate) fn surface_emission(
    lib: &Library,
    material: &Material,
    mesh: &Mesh,
    triangle: u32,
    b1: f32,
    b2: f32,
) -> Vec3 {
    let Some(idx) = triangle_vertices(mesh, triangle) else { return material.emission };
    let uv = uv_at(mesh, idx, b1, b2);
    let mut e = material.emission;
    if let Some(t) = texel(lib, material.emissive_texture, &material.emissive_uv, uv) {
        e *= t.truncate();
    }
    if material.has_cutouts() {
        e *= coverage(material, surface_alpha(lib, material, mesh, triangle, b1, b2));
    }
    e
}

/// An instance where it is at one time: object to world and, deforming, the
/// second mesh and its blend weight.
struct Placed<'m> {
    world_from_object: Affine3A,
    blend: Option<(&'m Mesh, f32)>,
}

/// The surface at a hit, in world space.
pub(crate) struct SurfaceHit {
    /// The hit point.
    pub(crate) p: Vec3,
    /// Geometric normal, flipped to face the incoming ray.
    pub(crate) ng: Vec3,
    /// Shading normal, on the same side as `ng` and facing the incoming ray.
    pub(crate) ns: Vec3,
    /// Base colour with its texture.
    pub(crate) base_color: Vec3,
    /// Index of the material in the library.
    pub(crate) material: usize,
    /// Emitted radiance towards the ray (zero unless the material emits and
    /// the ray meets its front face).
    pub(crate) emission: Vec3,
    /// Cosine between the front face's normal and the way back along the ray.
    pub(crate) cos_front: f32,
    /// Roughness and metallic with the metallic-roughness texture.
    pub(crate) roughness: f32,
    pub(crate) metallic: f32,
    /// KHR_materials_transmission with its texture (0: opaque).
    pub(crate) transmission: f32,
}

/// A point on a triangle of an instance: what a ray hit, as surface
/// evaluation needs it.
#[derive(Clone, Copy, Debug)]
pub(crate) struct TrianglePoint {
    /// Index into the frame scene's instances.
    pub(crate) instance: u32,
    /// Triangle of the instance's mesh.
    pub(crate) triangle: u32,
    /// Barycentrics of the second and third vertices.
    pub(crate) u: f32,
    pub(crate) v: f32,
}

/// What surface evaluation reads: the library's meshes, materials and
/// textures, and the frame's instances with their motion.
pub(crate) struct Surfaces<'a> {
    lib: &'a Library,
    scene: &'a FrameScene,
    default_material: Material,
}

impl<'a> Surfaces<'a> {
    /// The surfaces of `scene`'s instances, made of `lib`'s meshes.
    pub(crate) fn new(lib: &'a Library, scene: &'a FrameScene) -> Self {
        Surfaces { lib, scene, default_material: Material::default() }
    }

    /// Where instance `i` is at shutter fraction `time`: its open key unless
    /// the scene moves it.
    fn placed(&self, i: usize, time: f32) -> Option<Placed<'a>> {
        let inst = self.scene.instances.get(i)?;
        let Some(m) = self.scene.motion.as_ref().and_then(|m| m.instances.get(i)) else {
            return Some(Placed { world_from_object: inst.world_from_object, blend: None });
        };
        let (a, b) = (&inst.world_from_object, &m.world_from_object_close);
        let world_from_object = if a == b {
            *a
        } else {
            Affine3A {
                matrix3: a.matrix3 + (b.matrix3 - a.matrix3) * time,
                translation: a.translation + (b.translation - a.translation) * time,
            }
        };
        let lib: &'a Library = self.lib;
        let blend = m.deform.and_then(|d| {
            let (lo, hi) = (lib.meshes.get(inst.mesh as usize)?, lib.meshes.get(d.mesh as usize)?);
            (hi.positions.len() == lo.positions.len() && hi.indices.len() == lo.indices.len())
                .then(|| (hi, d.weight[0] + (d.weight[1] - d.weight[0]) * time))
        });
        Some(Placed { world_from_object, blend })
    }

    /// The surface `hit` found, seen along `dir` at shutter fraction `time`;
    /// `None` for a hit on a broken triangle.
    pub(crate) fn evaluate(&self, hit: &TrianglePoint, dir: Vec3, time: f32) -> Option<SurfaceHit> {
        let inst = self.scene.instances.get(hit.instance as usize)?;
        let mesh = self.lib.meshes.get(inst.mesh as usize)?;
        let idx = triangle_vertices(mesh, hit.triangle)?;
        let (u, v) = (hit.u, hit.v);
        let w = 1.0 - u - v;
        let placed = match &self.scene.motion {
            None => None,
            Some(_) => Some(self.placed(hit.instance as usize, time)?),
        };
        let blend = placed.as_ref().and_then(|p| p.blend);
        let vertex = |k: usize| -> Option<Vec3> {
            let p = *mesh.positions.get(idx[k])?;
            match blend {
                Some((hi, b)) => Some(p.lerp(*hi.positions.get(idx[k])?, b)),
                None => Some(p),
            }
        };
        let (p0, p1, p2) = (vertex(0)?, vertex(1)?, vertex(2)?);
        // Interpolate in object space, then transform: error scales with |p|, which the offset covers.
        let world_from_object = placed.as_ref().map_or(&inst.world_from_object, |p| &p.world_from_object);
        let p = world_from_object.transform_point3(p0 * w + p1 * u + p2 * v);
        // The normal matrix per hit, not per instance: a 3x3 inverse is cheap
        // beside the ray walk, and a million agents' parts keep 48 bytes each.
        let nmat = {
            let m = world_from_object.matrix3;
            if m.determinant().abs() > 1e-30 {
                m.inverse().transpose()
            } else {
                Mat3A::IDENTITY
            }
        };
        let front = (nmat * (p1 - p0).cross(p2 - p0)).normalize_or_zero();
        if front == Vec3::ZERO {
            return None;
        }
        // The front face (glTF: counter-clockwise, flipped by mirroring
        // transforms, which the normal matrix does) is the one that emits.
        let cos_front = -front.dot(dir);
        let mut ng = front;
        if ng.dot(dir) > 0.0 {
            ng = -ng; // two-sided: face the incoming ray
        }
        let material_index = inst.material as usize;
        let material = self.lib.materials.get(material_index).unwrap_or(&self.default_material);
        let uv = uv_at(mesh, idx, u, v);
        // The front side's shading normal: interpolated, then normal-mapped.
        let mut n_front = None;
        if mesh.normals.len() == mesh.positions.len() {
            let [mut n0, mut n1, mut n2] = idx.map(|i| mesh.normals[i]);
            if let Some((hi, b)) = blend.filter(|(hi, _)| hi.normals.len() == mesh.normals.len()) {
                [n0, n1, n2] =
                    [n0.lerp(hi.normals[idx[0]], b), n1.lerp(hi.normals[idx[1]], b), n2.lerp(hi.normals[idx[2]], b)];
            }
            let n = (nmat * (n0 * w + n1 * u + n2 * v)).normalize_or_zero();
            if n.is_finite() && n != Vec3::ZERO {
                n_front = Some(n);
            }
        }
        if let Some(map) = texel_ref(self.lib, material.normal_texture, uv) {
            let n = n_front.unwrap_or(front);
            let corners = Corners { mesh, blend, idx, bary: [w, u, v], p: [p0, p1, p2] };
            let tangent = tangent_frame(&corners, world_from_object, material, n);
            if let Some(mapped) = tangent.and_then(|(t, sign)| normal_map(n, t, sign, map, material.normal_scale)) {
                n_front = Some(mapped);
            }
        }
        let mut ns = ng;
        if let Some(n) = n_front {
            ns = if n.dot(ng) < 0.0 { -n } else { n };
            if ns.dot(-dir) <= 1e-4 {
                ns = ng; // interpolated normal faces away from the viewer
            }
        }
        let mut base_color = material.base_color;
        if let Some(t) = texel(self.lib, material.base_color_texture, &material.base_color_uv, uv) {
            base_color *= t.truncate();
        }
        let (mut roughness, mut metallic) = (material.roughness, material.metallic);
        if let Some(t) = texel_ref(self.lib, material.metallic_roughness_texture, uv) {
            roughness *= t.y;
            metallic *= t.z;
        }
        let mut transmission = material.transmission;
        if transmission > 0.0 {
            if let Some(t) = texel_ref(self.lib, material.transmission_texture, uv) {
                transmission *= t.x;
            }
        }
        let mut emission = Vec3::ZERO;
        if cos_front > 0.0 && material.emission.max_element() > 0.0 {
            emission = material.emission;
            if let Some(t) = texel(self.lib, material.emissive_texture, &material.emissive_uv, uv) {
                emission *= t.truncate();
            }
        }
        Some(SurfaceHit {
            p,
            ng,
            ns,
            base_color,
            material: material_index,
            emission,
            cos_front,
            roughness,
            metallic,
            transmission,
        })
    }

    /// Material `index` of the library, or the default material.
    pub(crate) fn material(&self, index: usize) -> &Material {
        self.lib.materials.get(index).unwrap_or(&self.default_material)
    }
}

/// The triangle a hit is on: its mesh (blended by `blend` when it
/// deforms), vertex indices `idx`, the hit's barycentrics `bary` and the
/// object-space corners `p`.
#[derive(Clone, Copy)]
struct Corners<'m> {
    mesh: &'m Mesh,
    blend: Option<(&'m Mesh, f32)>,
    idx: [usize; 3],
    bary: [f32; 3],
    p: [Vec3; 3],
}

/// The world tangent (along the normal map's +X) at a hit and the sign of
/// its bitangent (bitangent = sign x (n x tangent), n the world normal of the
/// front side): glTF TANGENT where the mesh has it, else the triangle's own
/// from its UVs, through the normal texture's transform (a rotated map turns
/// its frame with it).
fn tangent_frame(
    corners: &Corners<'_>,
    world_from_object: &Affine3A,
    material: &Material,
    n: Vec3,
) -> Option<(Vec3, f32)> {
    let Corners { mesh, blend, idx, bary, p } = *corners;
    let m = world_from_object.matrix3;
    if mesh.tangents.len() == mesh.positions.len() {
        let mut t = idx.map(|i| mesh.tangents[i]);
        if let Some((hi, b)) = blend.filter(|(hi, _)| hi.tangents.len() == mesh.tangents.len()) {
            t = [0, 1, 2].map(|k| t[k].lerp(hi.tangents[idx[k]], b));
        }
        let xyz = m * (t[0] * bary[0] + t[1] * bary[1] + t[2] * bary[2]).truncate();
        if xyz.length_squared() > 0.0 && t[0].w != 0.0 {
            // A mirroring transform flips which way n x t turns.
            return Some((xyz, t[0].w.signum() * m.determinant().signum()));
        }
    }
    let transform = material.normal_texture.map_or(UvTransform::IDENTITY, |t| t.uv);
    let uv = idx.map(|i| mesh.uvs.get(i).map(|&uv| transform.apply(uv)));
    let [Some(t0), Some(t1), Some(t2)] = uv else { return None };
    let (d1, d2) = (t1 - t0, t2 - t0);
    let det = d1.x * d2.y - d1.y * d2.x;
    if !(det.abs() > 1e-20) {
        return None;
    }
    let (e1, e2) = (p[1] - p[0], p[2] - p[0]);
    let dp_du = m * ((e1 * d2.y - e2 * d1.y) / det);
    // The map's +Y is up in the image: towards -v, since glTF's v runs down.
    let up = m * ((e1 * d2.x - e2 * d1.x) / det);
    let sign = if n.cross(dp_du).dot(up) < 0.0 { -1.0 } else { 1.0 };
    Some((dp_du, sign))
}

/// The normal a tangent-space normal map texel (linear RGB in 0..1, glTF:
/// +X along the tangent, +Y along the bitangent, +Z out of the surface)
/// gives around unit normal `n`, its X and Y scaled by `scale`; `None` for a
/// degenerate frame or texel.
fn normal_map(n: Vec3, tangent: Vec3, sign: f32, texel: Vec4, scale: f32) -> Option<Vec3> {
    let t = (tangent - n * n.dot(tangent)).try_normalize()?;
    let b = sign * n.cross(t);
    let local = Vec3::new((2.0 * texel.x - 1.0) * scale, (2.0 * texel.y - 1.0) * scale, 2.0 * texel.z - 1.0);
    (t * local.x + b * local.y + n * local.z).try_normalize()
}

/// The object-space hit point on instance `i`'s triangle at barycentrics
/// (u, v), with its mesh blended by `blend`.
pub(crate) fn object_point(mesh: &Mesh, blend: Option<(&Mesh, f32)>, idx: [usize; 3], u: f32, v: f32) -> Option<Vec3> {
    let w = 1.0 - u - v;
    let at = |m: &Mesh| -> Option<Vec3> {
        Some(*m.positions.get(idx[0])? * w + *m.positions.get(idx[1])? * u + *m.positions.get(idx[2])? * v)
    };
    let p = at(mesh)?;
    match blend {
        Some((hi, k)) => Some(p.lerp(at(hi)?, k)),
        None => Some(p),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn texture_is_bilinear_and_wraps() {
        let tex = Texture {
            name: "t".into(),
            width: 2,
            height: 2,
            texels: vec![[1.0, 0.0, 0.0, 1.0], [0.0, 1.0, 0.0, 1.0], [0.0, 0.0, 1.0, 1.0], [1.0, 1.0, 1.0, 1.0]],
        };
        // Texel centres are exact; v = 0 is the top row.
        assert_eq!(sample_texture(&tex, Vec2::new(0.25, 0.25)), Vec4::new(1.0, 0.0, 0.0, 1.0));
        assert_eq!(sample_texture(&tex, Vec2::new(0.75, 0.75)), Vec4::ONE);
        // Halfway between the two top texels, and wrapping past u = 1.
        assert_eq!(sample_texture(&tex, Vec2::new(0.5, 0.25)), Vec4::new(0.5, 0.5, 0.0, 1.0));
        assert_eq!(sample_texture(&tex, Vec2::new(1.0, 0.25)), Vec4::new(0.5, 0.5, 0.0, 1.0));
        assert_eq!(sample_texture(&tex, Vec2::new(-0.75, 1.25)), Vec4::new(1.0, 0.0, 0.0, 1.0));
    }
}
