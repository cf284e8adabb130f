//! A UsdSkel agent's skinned Mesh (docs/usd.md, "UsdSkel crowds"): points
//! with `primvars:skel:geomBindTransform` applied, polygons fanned into
//! triangles, `primvars:skel:jointIndices`/`jointWeights` (`elementSize`
//! influences a point, or one set for all with `constant` interpolation,
//! through the mesh's own `skel:joints` order when it has one), its
//! `primvars:st` (vertex or faceVarying, indexed or not: a point whose
//! corners differ in UV is split, its influences copied), and its bound
//! UsdPreviewSurface's constant inputs and `diffuseColor` texture.

use std::collections::HashMap;
use std::path::PathBuf;

use glam::{Mat4, Vec2, Vec3};
use openusd::sdf::Value;

use super::usd::{f32_of, vec3_of, vec3s_of, Ctx};
use crate::error::Result;

/// Most influences a vertex may list (`elementSize` of the joint primvars).
pub(crate) const MAX_ELEMENT_SIZE: usize = 64;
/// Most points one skinned mesh may hold.
pub(crate) const MAX_POINTS: usize = 10_000_000;

/// One skinned mesh, points in skeleton space at bind time
/// (`geomBindTransform` applied), triangulated.
#[derive(Clone, Debug)]
pub(crate) struct SkelMesh {
    /// The Mesh prim.
    pub(crate) prim: String,
    /// Bind-time points.
    pub(crate) points: Vec<Vec3>,
    /// Triangles (three point indices each), counter-clockwise seen from outside.
    pub(crate) triangles: Vec<u32>,
    /// Per point: (skeleton joint, weight) pairs, `elementSize` of them, normalised.
    pub(crate) influences: Vec<Vec<(u16, f32)>>,
    /// Per point, its texture coordinate (v down, as throng's meshes hold
    /// them); empty without `primvars:st`.
    pub(crate) uvs: Vec<Vec2>,
    /// Index into the character's materials.
    pub(crate) material: Option<usize>,
}

/// A UsdPreviewSurface's constant inputs.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct SkelMaterial {
    /// The Material prim.
    pub(crate) prim: String,
    /// `diffuseColor` (linear).
    pub(crate) diffuse: Vec3,
    /// `roughness`.
    pub(crate) roughness: f32,
    /// `metallic`.
    pub(crate) metallic: f32,
    /// `opacity`.
    pub(crate) opacity: f32,
    /// The image a UsdUVTexture connected to `diffuseColor` reads (its
    /// `inputs:file`, relative to the USD file's folder).
    pub(crate) diffuse_texture: Option<PathBuf>,
}

/// Weight sums further than this from 1 are renormalised with a warning.
const WEIGHT_SUM_TOLERANCE: f32 = 1e-3;

fn ints(ctx: &Ctx, prim: &str, attr: &str) -> Result<Option<Vec<i32>>> {
    Ok(match ctx.value(prim, attr, 0.0)? {
        Some(Value::IntVec(v)) => Some(v),
        Some(_) => return Err(ctx.err(&format!("{prim}.{attr}"), format!("<{prim}.{attr}> is not an int[]"))),
        None => None,
    })
}

fn metadata<T: TryFrom<Value>>(ctx: &Ctx, prim: &str, attr: &str, key: &str) -> Option<T>
where
    T::Error: std::error::Error + Send + Sync + 'static,
{
    let p = ctx.sdf_path(&format!("{prim}.{attr}")).ok()?;
    ctx.stage.attribute(p).get_metadata::<T>(key).ok().flatten()
}

/// Reads skinned Mesh `prim` bound to `skel`; its material goes into `materials`.
pub(super) fn read(
    ctx: &Ctx,
    prim: &str,
    skel: (&str, &[String]),
    materials: &mut Vec<SkelMaterial>,
    warnings: &mut Vec<String>,
) -> Result<SkelMesh> {
    let at = |attr: &str| format!("{prim}.{attr}");
    let points = ctx
        .value(prim, "points", 0.0)?
        .and_then(|v| vec3s_of(&v))
        .ok_or_else(|| ctx.err(&at("points"), format!("skinned Mesh <{prim}> has no float3[] `points`")))?;
    if points.is_empty() || points.len() > MAX_POINTS {
        return Err(ctx.err(&at("points"), format!("Mesh <{prim}> has {} points (1 to {MAX_POINTS})", points.len())));
    }
    let bind = match ctx.value(prim, "primvars:skel:geomBindTransform", 0.0)? {
        Some(Value::Matrix4d(m)) => Mat4::from_cols_array(&m.0.map(|e| e as f32)),
        Some(_) => return Err(ctx.err(&at("primvars:skel:geomBindTransform"), "geomBindTransform is not a matrix4d")),
        None => Mat4::IDENTITY,
    };
    if !bind.is_finite() || bind.determinant().abs() < 1e-12 {
        return Err(
            ctx.err(&at("primvars:skel:geomBindTransform"), format!("<{prim}>'s geomBindTransform is singular"))
        );
    }
    let points: Vec<Vec3> = points.iter().map(|&p| bind.transform_point3(p)).collect();
    if let Some(v) = points.iter().position(|p| !p.is_finite()) {
        return Err(ctx.err(&at("points"), format!("Mesh <{prim}>: point {v} is not finite")));
    }
    let (corners, corner_points) = triangles(ctx, prim, points.len())?;
    let influences = influences(ctx, prim, skel, points.len(), warnings)?;
    let material = match bound_material(ctx, prim)? {
        Some(m) => Some(material(ctx, &m, materials)?),
        None => None,
    };
    let mut mesh =
        SkelMesh { prim: prim.to_string(), points, triangles: Vec::new(), influences, uvs: Vec::new(), material };
    match st(ctx, prim, mesh.points.len(), corner_points.len())? {
        St::PerCorner(uvs) => mesh.split_corners(&corners, &corner_points, &uvs),
        St::PerPoint(uvs) => {
            mesh.triangles = corners.iter().map(|&c| corner_points[c as usize]).collect();
            mesh.uvs = uvs;
        }
        St::None => mesh.triangles = corners.iter().map(|&c| corner_points[c as usize]).collect(),
    }
    Ok(mesh)
}

/// A mesh's texture coordinates as authored.
enum St {
    None,
    /// One a point (`vertex` or `varying`).
    PerPoint(Vec<Vec2>),
    /// One a face corner (`faceVarying`).
    PerCorner(Vec<Vec2>),
}

/// `primvars:st` (through `primvars:st:indices` when given), v flipped to
/// point down; `None` when not authored or neither per point nor per corner.
fn st(ctx: &Ctx, prim: &str, points: usize, corners: usize) -> Result<St> {
    let attr = "primvars:st";
    let at = format!("{prim}.{attr}");
    let values: Vec<Vec2> = match ctx.value(prim, attr, 0.0)? {
        None => return Ok(St::None),
        Some(Value::Vec2fVec(v)) => v.iter().map(|p| Vec2::new(p.x, p.y)).collect(),
        Some(Value::Vec2dVec(v)) => v.iter().map(|p| Vec2::new(p.x as f32, p.y as f32)).collect(),
        Some(Value::Vec2hVec(v)) => v.iter().map(|p| Vec2::new(p.x.to_f32(), p.y.to_f32())).collect(),
        Some(_) => return Err(ctx.err(&at, format!("<{at}> is not a texCoord2f[]"))),
    };
    let values = match ints(ctx, prim, "primvars:st:indices")? {
        None => values,
        Some(ix) => (ix.iter())
            .map(|&i| usize::try_from(i).ok().and_then(|i| values.get(i)).copied())
            .collect::<Option<Vec<Vec2>>>()
            .ok_or_else(|| ctx.err(&at, format!("<{at}:indices> names a value past the {} of <{at}>", values.len())))?,
    };
    if let Some(i) = values.iter().position(|v| !v.is_finite()) {
        return Err(ctx.err(&at, format!("<{at}>: value {i} is not finite")));
    }
    let flipped = || values.iter().map(|v| Vec2::new(v.x, 1.0 - v.y)).collect();
    let interpolation = match metadata::<Value>(ctx, prim, attr, "interpolation") {
        Some(Value::Token(t)) => t.as_str().to_string(),
        Some(Value::String(s)) => s,
        _ => "constant".to_string(),
    };
    let (want, st) = match interpolation.as_str() {
        "vertex" | "varying" => (points, St::PerPoint(flipped())),
        "faceVarying" => (corners, St::PerCorner(flipped())),
        // One UV for the whole mesh (or a face) textures nothing.
        _ => return Ok(St::None),
    };
    if values.len() != want {
        return Err(
            ctx.err(&at, format!("<{at}> holds {} {interpolation} values; the mesh needs {want}", values.len()))
        );
    }
    Ok(st)
}

impl SkelMesh {
    /// Triangles over face corners (`corners`, indices into `corner_points`)
    /// with a UV each: a point is one vertex per distinct UV of its corners
    /// (points, influences copied), numbered in corner order.
    fn split_corners(&mut self, corners: &[u32], corner_points: &[u32], uvs: &[Vec2]) {
        let mut made: HashMap<(u32, [u32; 2]), u32> = HashMap::new();
        let (mut points, mut influences, mut out_uvs) = (Vec::new(), Vec::new(), Vec::new());
        let mut triangles = Vec::with_capacity(corners.len());
        for &c in corners {
            let (p, uv) = (corner_points[c as usize], uvs[c as usize]);
            let v = *made.entry((p, [uv.x.to_bits(), uv.y.to_bits()])).or_insert_with(|| {
                points.push(self.points[p as usize]);
                influences.push(self.influences[p as usize].clone());
                out_uvs.push(uv);
                (points.len() - 1) as u32
            });
            triangles.push(v);
        }
        (self.points, self.influences, self.uvs, self.triangles) = (points, influences, out_uvs, triangles);
    }
}

/// `faceVertexCounts`/`faceVertexIndices` fanned into triangles (reversed
/// for `orientation = "leftHanded"`), as face corners (indices into
/// `faceVertexIndices`), with the point of each corner.
fn triangles(ctx: &Ctx, prim: &str, points: usize) -> Result<(Vec<u32>, Vec<u32>)> {
    let at = |attr: &str| format!("{prim}.{attr}");
    let counts = ints(ctx, prim, "faceVertexCounts")?.unwrap_or_default();
    let indices = ints(ctx, prim, "faceVertexIndices")?.unwrap_or_default();
    let left = matches!(ctx.value(prim, "orientation", 0.0)?, Some(Value::Token(t)) if t.as_str() == "leftHanded");
    let mut out = Vec::with_capacity(indices.len().saturating_mul(2).min(3 * MAX_POINTS));
    let mut next = 0usize;
    for (face, &c) in counts.iter().enumerate() {
        let c = usize::try_from(c).unwrap_or(0);
        let Some(corners) = indices.get(next..next.saturating_add(c)) else {
            return Err(ctx.err(
                &at("faceVertexCounts"),
                format!("Mesh <{prim}>: face {face} runs past faceVertexIndices ({} entries)", indices.len()),
            ));
        };
        let first = next as u32;
        next += c;
        if let Some(&bad) = corners.iter().find(|&&i| i < 0 || i as usize >= points) {
            return Err(ctx.err(
                &at("faceVertexIndices"),
                format!("Mesh <{prim}>: face {face} names point {bad}; the mesh has {points}"),
            ));
        }
        for k in 1..c.saturating_sub(1) {
            let (a, b, d) = (first, first + k as u32, first + k as u32 + 1);
            out.extend(if left { [a, d, b] } else { [a, b, d] });
        }
    }
    if out.is_empty() {
        return Err(ctx.err(&at("faceVertexCounts"), format!("Mesh <{prim}> has no polygon")));
    }
    // Every index was checked against the points above.
    let corner_points = indices[..next].iter().map(|&i| i as u32).collect();
    Ok((out, corner_points))
}

/// Per point, its (skeleton joint, weight) pairs, normalised.
fn influences(
    ctx: &Ctx,
    prim: &str,
    skel: (&str, &[String]),
    points: usize,
    warnings: &mut Vec<String>,
) -> Result<Vec<Vec<(u16, f32)>>> {
    let (ji, jw) = ("primvars:skel:jointIndices", "primvars:skel:jointWeights");
    let at = |attr: &str| format!("{prim}.{attr}");
    let indices = ints(ctx, prim, ji)?.unwrap_or_default();
    let weights: Vec<f32> = match ctx.value(prim, jw, 0.0)? {
        Some(Value::FloatVec(v)) => v,
        _ => return Err(ctx.err(&at(jw), format!("skinned Mesh <{prim}> has no float[] {jw}"))),
    };
    let size = match metadata::<Value>(ctx, prim, ji, "elementSize") {
        Some(Value::Int(i)) => i64::from(i),
        Some(Value::Int64(i)) => i,
        Some(Value::Uint(i)) => i64::from(i),
        _ => 1,
    };
    let size = usize::try_from(size).ok().filter(|s| (1..=MAX_ELEMENT_SIZE).contains(s)).ok_or_else(|| {
        ctx.err(&at(ji), format!("<{prim}>: elementSize {size} of {ji} is not 1 to {MAX_ELEMENT_SIZE}"))
    })?;
    let constant = match metadata::<Value>(ctx, prim, ji, "interpolation") {
        Some(Value::Token(t)) => t.as_str() == "constant",
        Some(Value::String(s)) => s == "constant",
        _ => false,
    };
    let want = if constant { size } else { points * size };
    for (attr, n) in [(ji, indices.len()), (jw, weights.len())] {
        if n != want {
            return Err(ctx.err(
                &at(attr),
                format!("<{prim}.{attr}> holds {n} values; {} points x elementSize {size} need {want}", points),
            ));
        }
    }
    // The mesh's own joint order, when it has one, names skeleton joints.
    let order: Vec<usize> = match ctx.value(prim, "skel:joints", 0.0)? {
        Some(Value::TokenVec(names)) => names
            .iter()
            .map(|n| {
                skel.1.iter().position(|j| j == n.as_str()).ok_or_else(|| {
                    ctx.err(
                        &at("skel:joints"),
                        format!("<{prim}> skel:joints names `{}`, not a joint of <{}>", n.as_str(), skel.0),
                    )
                })
            })
            .collect::<Result<_>>()?,
        _ => (0..skel.1.len()).collect(),
    };
    let mut out = Vec::with_capacity(points);
    let mut renormalised = 0;
    for v in 0..points {
        let base = if constant { 0 } else { v * size };
        let mut inf = Vec::with_capacity(size);
        for k in base..base + size {
            let (j, w) = (indices[k], weights[k]);
            if !(w.is_finite() && w >= 0.0) {
                return Err(
                    ctx.err(&at(jw), format!("<{prim}.{jw}>: point {v} has weight {w}; weights are finite and >= 0"))
                );
            }
            let joint = usize::try_from(j).ok().and_then(|j| order.get(j)).copied().ok_or_else(|| {
                ctx.err(
                    &at(ji),
                    format!("<{prim}.{ji}>: point {v} names joint {j}; the skeleton has {} joints", order.len()),
                )
            })?;
            if w > 0.0 {
                inf.push((joint as u16, w));
            }
        }
        let sum: f32 = inf.iter().map(|i| i.1).sum();
        if sum <= 0.0 {
            return Err(ctx.err(&at(jw), format!("<{prim}.{jw}>: point {v}'s weights sum to 0")));
        }
        if (sum - 1.0).abs() > WEIGHT_SUM_TOLERANCE {
            renormalised += 1;
        }
        inf.iter_mut().for_each(|i| i.1 /= sum);
        out.push(inf);
    }
    if renormalised > 0 {
        warnings.push(format!(
            "{}: <{prim}.{jw}>: {renormalised} of {points} points have joint weights that do not sum to 1; renormalised",
            ctx.path.display()
        ));
    }
    Ok(out)
}

/// The index in `materials` of Material `prim`'s UsdPreviewSurface inputs.
fn material(ctx: &Ctx, prim: &str, materials: &mut Vec<SkelMaterial>) -> Result<usize> {
    if let Some(i) = materials.iter().position(|m| m.prim == prim) {
        return Ok(i);
    }
    let mut m = SkelMaterial {
        prim: prim.to_string(),
        diffuse: Vec3::splat(0.18),
        roughness: 0.5,
        metallic: 0.0,
        opacity: 1.0,
        diffuse_texture: None,
    };
    if let Some(shader) = preview_surface(ctx, prim)? {
        if let Some(c) = ctx.value(&shader, "inputs:diffuseColor", 0.0)?.and_then(|v| vec3_of(&v)) {
            m.diffuse = c;
        }
        let get = |name: &str| -> Result<Option<f32>> { Ok(ctx.value(&shader, name, 0.0)?.and_then(|v| f32_of(&v))) };
        m.roughness = get("inputs:roughness")?.unwrap_or(m.roughness);
        m.metallic = get("inputs:metallic")?.unwrap_or(m.metallic);
        m.opacity = get("inputs:opacity")?.unwrap_or(m.opacity);
        m.diffuse_texture = diffuse_texture(ctx, &shader)?;
    }
    if !(m.diffuse.is_finite() && m.roughness.is_finite() && m.metallic.is_finite() && m.opacity.is_finite()) {
        return Err(ctx.err(prim, format!("Material <{prim}>: a UsdPreviewSurface input is not finite")));
    }
    materials.push(m);
    Ok(materials.len() - 1)
}

/// The image file of the UsdUVTexture connected to `shader`'s
/// `inputs:diffuseColor`, if one is: its `inputs:file`, relative to the USD
/// file's folder (a crowd's textures sit beside it).
fn diffuse_texture(ctx: &Ctx, shader: &str) -> Result<Option<PathBuf>> {
    let input = ctx.sdf_path(&format!("{shader}.inputs:diffuseColor"))?;
    let Some(source) = ctx.stage.attribute(input).connections().unwrap_or_default().into_iter().next() else {
        return Ok(None);
    };
    let texture = source.as_str().split('.').next().unwrap_or_default().to_string();
    if !matches!(ctx.value(&texture, "info:id", 0.0)?, Some(Value::Token(t)) if t.as_str() == "UsdUVTexture") {
        return Ok(None);
    }
    let file = match ctx.value(&texture, "inputs:file", 0.0)? {
        Some(Value::AssetPath(a)) => a.authored_path,
        Some(Value::String(s)) => s,
        _ => return Ok(None),
    };
    let dir = ctx.path.parent().unwrap_or(std::path::Path::new("."));
    Ok(Some(dir.join(file)))
}

/// The Material bound to `prim` (`material:binding`, on it or an ancestor).
fn bound_material(ctx: &Ctx, prim: &str) -> Result<Option<String>> {
    let mut at = prim;
    while !at.is_empty() {
        let p = ctx.sdf_path(&format!("{at}.material:binding"))?;
        if let Some(t) = ctx.stage.relationship(p).targets().unwrap_or_default().first() {
            return Ok(Some(t.as_str().to_string()));
        }
        at = &at[..at.rfind('/').unwrap_or(0)];
    }
    Ok(None)
}

/// The UsdPreviewSurface shader under Material `prim`, if any.
fn preview_surface(ctx: &Ctx, prim: &str) -> Result<Option<String>> {
    let children = ctx.stage.prim(ctx.sdf_path(prim)?).children().unwrap_or_default();
    for c in children {
        let path = c.path().as_str().to_string();
        if matches!(ctx.value(&path, "info:id", 0.0)?, Some(Value::Token(t)) if t.as_str() == "UsdPreviewSurface") {
            return Ok(Some(path));
        }
    }
    Ok(None)
}
