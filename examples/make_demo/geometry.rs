//! Mesh building blocks: flat-shaded boxes and hexahedra, smooth surfaces of
//! revolution (lathe), and transforms. Everything returns `MeshData` with
//! normals and UVs.

use glam::{Quat, Vec3};
use std::f32::consts::{FRAC_PI_2, PI, TAU};
use throng::export::glb::MeshData;

/// Appends `b` to `a`.
pub fn append(a: &mut MeshData, b: &MeshData) {
    let base = a.positions.len() as u32;
    a.positions.extend_from_slice(&b.positions);
    a.normals.extend_from_slice(&b.normals);
    a.uvs.extend_from_slice(&b.uvs);
    a.joints.extend_from_slice(&b.joints);
    a.weights.extend_from_slice(&b.weights);
    a.indices.extend(b.indices.iter().map(|i| i + base));
}

/// Concatenates meshes.
pub fn merge(parts: &[MeshData]) -> MeshData {
    let mut out = MeshData::default();
    for p in parts {
        append(&mut out, p);
    }
    out
}

/// Applies scale, then rotation, then translation (normals by the inverse
/// transpose, renormalised).
pub fn transform(m: &MeshData, scale: [f32; 3], rotation: Quat, translate: [f32; 3]) -> MeshData {
    let s = Vec3::from(scale);
    let t = Vec3::from(translate);
    let mut out = m.clone();
    for p in &mut out.positions {
        *p = (rotation * (Vec3::from(*p) * s) + t).to_array();
    }
    for n in &mut out.normals {
        *n = (rotation * (Vec3::from(*n) / s)).normalize().to_array();
    }
    // A mirroring scale turns triangles inside out; restore the winding.
    if s.x * s.y * s.z < 0.0 {
        for tri in out.indices.chunks_exact_mut(3) {
            tri.swap(1, 2);
        }
    }
    out
}

/// Translation only.
pub fn moved(m: &MeshData, t: [f32; 3]) -> MeshData {
    transform(m, [1.0; 3], Quat::IDENTITY, t)
}

/// Flat shading: one vertex per triangle corner, face normals.
#[allow(dead_code)]
pub fn flat_shade(m: &MeshData) -> MeshData {
    let mut out = MeshData::default();
    for tri in m.indices.chunks_exact(3) {
        let p: Vec<Vec3> = tri.iter().map(|&i| Vec3::from(m.positions[i as usize])).collect();
        let n = (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero();
        if n == Vec3::ZERO {
            continue;
        }
        for &i in tri {
            out.indices.push(out.positions.len() as u32);
            out.positions.push(m.positions[i as usize]);
            out.normals.push(n.to_array());
            out.uvs.push(m.uvs.get(i as usize).copied().unwrap_or([0.0, 0.0]));
        }
    }
    out
}

/// A hexahedron from 8 corners: bottom face (-x-z, +x-z, +x+z, -x+z) then the
/// top face in the same order. Flat shaded, split vertices, UVs 0..1 per face.
pub fn hexa(c: [[f32; 3]; 8]) -> MeshData {
    const FACES: [[usize; 4]; 6] = [
        [0, 1, 2, 3], // bottom
        [4, 5, 6, 7], // top
        [0, 1, 5, 4], // -z
        [1, 2, 6, 5], // +x
        [2, 3, 7, 6], // +z
        [3, 0, 4, 7], // -x
    ];
    let v: Vec<Vec3> = c.iter().map(|p| Vec3::from(*p)).collect();
    let centre = v.iter().copied().sum::<Vec3>() / 8.0;
    let mut out = MeshData::default();
    for face in FACES {
        let mut q: Vec<Vec3> = face.iter().map(|&i| v[i]).collect();
        let fc = q.iter().copied().sum::<Vec3>() / 4.0;
        let mut n = (q[1] - q[0]).cross(q[2] - q[0]).normalize();
        if n.dot(fc - centre) < 0.0 {
            q.reverse();
            n = -n;
        }
        let base = out.positions.len() as u32;
        for (k, p) in q.iter().enumerate() {
            out.positions.push(p.to_array());
            out.normals.push(n.to_array());
            out.uvs.push([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]][k]);
        }
        out.indices.extend_from_slice(&[base, base + 1, base + 2, base, base + 2, base + 3]);
    }
    out
}

/// An axis-aligned box.
pub fn cuboid(min: [f32; 3], max: [f32; 3]) -> MeshData {
    let [x0, y0, z0] = min;
    let [x1, y1, z1] = max;
    hexa([
        [x0, y0, z0],
        [x1, y0, z0],
        [x1, y0, z1],
        [x0, y0, z1],
        [x0, y1, z0],
        [x1, y1, z0],
        [x1, y1, z1],
        [x0, y1, z1],
    ])
}

/// A box tapering from a bottom to a top rectangle (half extents x, z), both centred on Y.
pub fn frustum_box(y0: f32, y1: f32, bottom: [f32; 2], top: [f32; 2]) -> MeshData {
    let [bx, bz] = bottom;
    let [tx, tz] = top;
    hexa([
        [-bx, y0, -bz],
        [bx, y0, -bz],
        [bx, y0, bz],
        [-bx, y0, bz],
        [-tx, y1, -tz],
        [tx, y1, -tz],
        [tx, y1, tz],
        [-tx, y1, tz],
    ])
}

/// One point of a lathe profile: radius, height, and the outward normal in
/// the (r, y) plane.
#[derive(Clone, Copy, Debug)]
pub struct ProfilePoint {
    r: f32,
    y: f32,
    nr: f32,
    ny: f32,
}

/// A smooth run of profile points (shared normals inside a band; bands meet
/// at hard edges).
pub type Band = Vec<ProfilePoint>;

/// A band along a parametric curve `f(t)`, t in 0..=1, traversed bottom to
/// top with the outside on the right; normals from the curve's tangent.
pub fn curve(n: usize, f: impl Fn(f32) -> (f32, f32)) -> Band {
    let n = n.max(1);
    (0..=n)
        .map(|i| {
            let t = i as f32 / n as f32;
            let (r, y) = f(t);
            let h = 1e-3;
            let (ra, ya) = f((t - h).max(0.0));
            let (rb, yb) = f((t + h).min(1.0));
            let (dr, dy) = (rb - ra, yb - ya);
            let len = (dr * dr + dy * dy).sqrt().max(1e-12);
            ProfilePoint { r: r.max(0.0), y, nr: dy / len, ny: -dr / len }
        })
        .collect()
}

/// A straight band from (r0, y0) to (r1, y1).
pub fn line(r0: f32, y0: f32, r1: f32, y1: f32) -> Band {
    curve(1, |t| (r0 + (r1 - r0) * t, y0 + (y1 - y0) * t))
}

/// A disc cap at height y, radius r, facing down (`up` false) or up.
pub fn cap(r: f32, y: f32, up: bool) -> Band {
    if up {
        line(r, y, 0.0, y)
    } else {
        line(0.0, y, r, y)
    }
}

/// An elliptical arc band centred at (0, cy) with radii (rr, ry), from angle
/// a0 to a1 (radians, -pi/2 = bottom pole, +pi/2 = top pole). Normals exact.
pub fn arc(cy: f32, rr: f32, ry: f32, a0: f32, a1: f32, n: usize) -> Band {
    (0..=n)
        .map(|i| {
            let a = a0 + (a1 - a0) * i as f32 / n as f32;
            let (nr, ny) = (a.cos() / rr, a.sin() / ry);
            let len = (nr * nr + ny * ny).sqrt();
            ProfilePoint { r: rr * a.cos().max(0.0), y: cy + ry * a.sin(), nr: nr / len, ny: ny / len }
        })
        .collect()
}

/// Surface of revolution about +Y with `segs` segments around. The UV seam
/// sits at the back (-Z) so textures and the front (+Z) stay clean.
pub fn lathe(bands: &[Band], segs: usize) -> MeshData {
    let total_len: f32 = bands
        .iter()
        .flat_map(|b| b.windows(2).map(|w| ((w[1].r - w[0].r).powi(2) + (w[1].y - w[0].y).powi(2)).sqrt()))
        .sum::<f32>()
        .max(1e-6);
    let mut out = MeshData::default();
    let mut walked = 0.0;
    for band in bands {
        let base = out.positions.len() as u32;
        let cols = segs as u32 + 1;
        for (i, p) in band.iter().enumerate() {
            if i > 0 {
                let q = band[i - 1];
                walked += ((p.r - q.r).powi(2) + (p.y - q.y).powi(2)).sqrt();
            }
            for j in 0..=segs {
                let th = PI + TAU * j as f32 / segs as f32;
                let (s, c) = th.sin_cos();
                out.positions.push([p.r * s, p.y, p.r * c]);
                out.normals.push(Vec3::new(p.nr * s, p.ny, p.nr * c).normalize_or(Vec3::Y).to_array());
                out.uvs.push([j as f32 / segs as f32, 1.0 - walked / total_len]);
            }
        }
        for i in 0..band.len().saturating_sub(1) as u32 {
            for j in 0..segs as u32 {
                let a = base + i * cols + j;
                let b = a + 1;
                let d = a + cols;
                let c = d + 1;
                for tri in [[a, b, c], [a, c, d]] {
                    push_oriented(&mut out, tri);
                }
            }
        }
    }
    out
}

/// Pushes a triangle unless degenerate, wound so its face normal agrees with
/// its vertex normals (outward).
fn push_oriented(m: &mut MeshData, tri: [u32; 3]) {
    let p = tri.map(|i| Vec3::from(m.positions[i as usize]));
    let n = (p[1] - p[0]).cross(p[2] - p[0]);
    if n.length_squared() < 1e-14 {
        return;
    }
    let vn: Vec3 = tri.iter().map(|&i| Vec3::from(m.normals[i as usize])).sum();
    if n.dot(vn) >= 0.0 {
        m.indices.extend_from_slice(&tri);
    } else {
        m.indices.extend_from_slice(&[tri[0], tri[2], tri[1]]);
    }
}

/// An ellipsoid-capable UV sphere of radius `r` centred at (0, cy, 0).
pub fn sphere(r: f32, cy: f32, segs: usize, rings: usize) -> MeshData {
    lathe(&[arc(cy, r, r, -FRAC_PI_2, FRAC_PI_2, rings)], segs)
}

/// A closed cylinder along Y from y0 to y1 (flat caps, hard edges).
pub fn cylinder(r: f32, y0: f32, y1: f32, segs: usize) -> MeshData {
    lathe(&[cap(r, y0, false), line(r, y0, r, y1), cap(r, y1, true)], segs)
}

/// A closed truncated cone from radius r0 at y0 to r1 at y1.
pub fn cone(r0: f32, y0: f32, r1: f32, y1: f32, segs: usize) -> MeshData {
    let mut bands = vec![cap(r0, y0, false), line(r0, y0, r1, y1)];
    if r1 > 0.0 {
        bands.push(cap(r1, y1, true));
    }
    lathe(&bands, segs)
}

/// A capsule along Y from y0 to y1 (total length), radius r.
pub fn capsule(r: f32, y0: f32, y1: f32, segs: usize, cap_rings: usize) -> MeshData {
    let lo = y0 + r;
    let hi = (y1 - r).max(lo);
    lathe(
        &[{
            let mut b = arc(lo, r, r, -FRAC_PI_2, 0.0, cap_rings);
            b.extend(arc(hi, r, r, 0.0, FRAC_PI_2, cap_rings));
            b
        }],
        segs,
    )
}

/// Rotation about an axis (radians).
pub fn rot(axis: Vec3, angle: f32) -> Quat {
    Quat::from_axis_angle(axis.normalize(), angle)
}

/// A cylinder from point a to point b (a stick, e.g. an antenna).
pub fn stick(a: [f32; 3], b: [f32; 3], r: f32, segs: usize) -> MeshData {
    let (a, b) = (Vec3::from(a), Vec3::from(b));
    let len = (b - a).length();
    let q = Quat::from_rotation_arc(Vec3::Y, (b - a) / len);
    transform(&cylinder(r, 0.0, len, segs), [1.0; 3], q, a.to_array())
}

/// Mesh bounds helper for checks.
#[allow(dead_code)]
pub fn size(m: &MeshData) -> Vec3 {
    let (lo, hi) = m.bounds();
    Vec3::from(hi) - Vec3::from(lo)
}
