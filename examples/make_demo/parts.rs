//! Robot body parts: heads, torsos, limbs and hips, each a named mesh in its
//! own object space (Y up, facing +Z; fitting maps bounds onto proxy boxes).

use crate::geometry::*;
use glam::Vec3;
use std::f32::consts::{FRAC_PI_2, PI};
use throng::error::Result;
use throng::export::glb::{GlbBuilder, MeshData, NodeDesc};

/// Segments around for round heads.
const HEAD_SEGS: usize = 20;
/// Segments around for limbs (they are small on screen).
const LIMB_SEGS: usize = 12;

/// A named part mesh.
pub struct Part {
    pub name: &'static str,
    pub mesh: MeshData,
}

fn part(name: &'static str, mesh: MeshData) -> Part {
    Part { name, mesh }
}

/// Two round eyes on the +Z face at height y, half-spacing dx, depth z.
fn eyes(y: f32, dx: f32, z: f32, r: f32) -> MeshData {
    let eye = transform(&sphere(r, 0.0, 8, 5), [1.0, 1.0, 0.6], glam::Quat::IDENTITY, [0.0, y, z]);
    merge(&[moved(&eye, [-dx, 0.0, 0.0]), moved(&eye, [dx, 0.0, 0.0])])
}

/// A visor strip on the +Z side.
fn visor(y0: f32, y1: f32, half_w: f32, z0: f32, z1: f32) -> MeshData {
    cuboid([-half_w, y0, z0], [half_w, y1, z1])
}

/// A mouth grille: `bars` vertical slats on the +Z face between y0 and y1.
fn grille(y0: f32, y1: f32, z: f32, bars: usize) -> MeshData {
    let width = 0.05;
    let pitch = 0.08;
    let x0 = -pitch * (bars as f32 - 1.0) / 2.0;
    let slats: Vec<MeshData> = (0..bars)
        .map(|i| {
            let x = x0 + pitch * i as f32;
            cuboid([x - width / 2.0, y0, z - 0.02], [x + width / 2.0, y1, z + 0.04])
        })
        .collect();
    merge(&slats)
}

/// Heads: round ones (sphere, squashed, dome, bulb), boxy ones (box, tv,
/// octagon) and odd ones (can, cone, bucket). Each about 1 unit across.
pub fn heads() -> Vec<Part> {
    vec![
        part("head_sphere", merge(&[sphere(0.5, 0.5, HEAD_SEGS, 12), visor(0.45, 0.6, 0.26, 0.3, 0.52)])),
        part("head_squashed", {
            let ball = transform(&sphere(0.5, 0.5, HEAD_SEGS, 10), [1.2, 0.7, 1.0], glam::Quat::IDENTITY, [0.0; 3]);
            merge(&[ball, eyes(0.4, 0.22, 0.45, 0.09)])
        }),
        part(
            "head_dome",
            merge(&[
                lathe(
                    &[cap(0.5, 0.0, false), line(0.5, 0.0, 0.5, 0.25), arc(0.25, 0.5, 0.5, 0.0, FRAC_PI_2, 8)],
                    HEAD_SEGS,
                ),
                visor(0.3, 0.42, 0.3, 0.2, 0.5),
            ]),
        ),
        part(
            "head_bulb",
            merge(&[
                lathe(
                    &[cap(0.22, 0.0, false), line(0.22, 0.0, 0.22, 0.2), arc(0.6, 0.45, 0.45, -1.1, FRAC_PI_2, 10)],
                    HEAD_SEGS,
                ),
                eyes(0.65, 0.16, 0.4, 0.08),
            ]),
        ),
        part(
            "head_box",
            merge(&[
                cuboid([-0.5, 0.0, -0.45], [0.5, 0.8, 0.45]),
                cuboid([-0.32, 0.45, 0.45], [-0.12, 0.6, 0.5]),
                cuboid([0.12, 0.45, 0.45], [0.32, 0.6, 0.5]),
                cuboid([-0.6, 0.3, -0.1], [-0.5, 0.55, 0.1]),
                cuboid([0.5, 0.3, -0.1], [0.6, 0.55, 0.1]),
                grille(0.12, 0.26, 0.45, 5),
                // Bolts on the cheeks.
                moved(&sphere(0.04, 0.0, 8, 4), [-0.4, 0.15, 0.44]),
                moved(&sphere(0.04, 0.0, 8, 4), [0.4, 0.15, 0.44]),
            ]),
        ),
        part("head_tv", {
            let antenna_l = stick([-0.1, 0.75, 0.0], [-0.35, 1.2, 0.0], 0.015, 6);
            let antenna_r = stick([0.1, 0.75, 0.0], [0.3, 1.15, 0.05], 0.015, 6);
            let ball = sphere(0.05, 1.2, 8, 5);
            merge(&[
                cuboid([-0.55, 0.0, -0.35], [0.55, 0.75, 0.35]),
                cuboid([-0.42, 0.12, 0.35], [0.3, 0.63, 0.38]),
                cuboid([0.36, 0.45, 0.35], [0.48, 0.55, 0.4]),
                cuboid([0.36, 0.25, 0.35], [0.48, 0.35, 0.4]),
                antenna_l,
                antenna_r,
                moved(&ball, [-0.35, 0.0, 0.0]),
            ])
        }),
        part("head_octagon", {
            // An octagonal prism: few segments, flat sides (hard edges).
            let body = flat_shade(&cylinder(0.5, 0.0, 0.7, 8));
            let body = transform(&body, [1.0; 3], rot(Vec3::Y, PI / 8.0), [0.0; 3]);
            merge(&[
                body,
                visor(0.35, 0.45, 0.3, 0.3, 0.5),
                grille(0.1, 0.22, 0.44, 4),
                cylinder(0.06, 0.7, 0.85, 8),
                sphere(0.09, 0.9, 10, 5),
            ])
        }),
        part(
            "head_can",
            merge(&[
                cylinder(0.4, 0.0, 0.9, HEAD_SEGS),
                cylinder(0.43, 0.82, 0.9, HEAD_SEGS),
                visor(0.5, 0.58, 0.25, 0.2, 0.42),
            ]),
        ),
        part(
            "head_cone",
            merge(&[cone(0.45, 0.0, 0.05, 1.0, HEAD_SEGS), sphere(0.07, 1.0, 8, 5), eyes(0.3, 0.13, 0.33, 0.07)]),
        ),
        part(
            "head_bucket",
            merge(&[
                // An upside-down bucket: wide rim at the bottom, narrower top.
                cone(0.45, 0.08, 0.33, 0.75, HEAD_SEGS),
                cylinder(0.5, 0.0, 0.08, HEAD_SEGS),
                visor(0.35, 0.45, 0.22, 0.2, 0.44),
            ]),
        ),
    ]
}

/// Torsos: boxy, barrel and tapered, about 1 unit tall.
pub fn torsos() -> Vec<Part> {
    vec![
        part(
            "torso_boxy",
            merge(&[
                cuboid([-0.5, 0.0, -0.3], [0.5, 1.0, 0.3]),
                cuboid([-0.3, 0.45, 0.3], [0.3, 0.85, 0.35]),
                cuboid([-0.2, 0.1, -0.38], [0.2, 0.7, -0.3]),
            ]),
        ),
        part("torso_barrel", {
            let barrel = lathe(
                &[cap(0.38, 0.0, false), curve(12, |t| (0.38 + 0.1 * (PI * t).sin(), t)), cap(0.38, 1.0, true)],
                HEAD_SEGS,
            );
            let barrel = transform(&barrel, [1.0, 1.0, 0.75], glam::Quat::IDENTITY, [0.0; 3]);
            merge(&[barrel, cylinder(0.46, 0.3, 0.36, HEAD_SEGS), cylinder(0.46, 0.64, 0.7, HEAD_SEGS)])
        }),
        part(
            "torso_tapered",
            merge(&[frustum_box(0.0, 1.0, [0.28, 0.2], [0.5, 0.3]), cuboid([-0.15, 0.55, 0.25], [0.15, 0.8, 0.32])]),
        ),
    ]
}

/// Limb styles: box, cylinder, capsule. Limbs are long along -Y from a
/// joint at y = 0 (about 0.1 x 0.3 x 0.1 units); lower arms carry a hand,
/// lower legs a foot pointing +Z. Hips are wide along X.
pub fn limbs() -> Vec<Part> {
    // Box style.
    let mut out = vec![part("upper_arm_box", cuboid([-0.05, -0.3, -0.05], [0.05, 0.0, 0.05]))];
    out.push(part(
        "lower_arm_box",
        merge(&[
            cuboid([-0.045, -0.24, -0.045], [0.045, 0.0, 0.045]),
            cuboid([-0.05, -0.3, -0.06], [0.05, -0.24, 0.06]),
        ]),
    ));
    out.push(part("upper_leg_box", cuboid([-0.06, -0.3, -0.06], [0.06, 0.0, 0.06])));
    out.push(part(
        "lower_leg_box",
        merge(&[
            cuboid([-0.055, -0.27, -0.055], [0.055, 0.0, 0.055]),
            cuboid([-0.065, -0.3, -0.07], [0.065, -0.27, 0.14]),
        ]),
    ));
    out.push(part("hips_box", cuboid([-0.5, -0.15, -0.25], [0.5, 0.15, 0.25])));
    // Cylinder style.
    out.push(part("upper_arm_cyl", cylinder(0.05, -0.3, 0.0, LIMB_SEGS)));
    out.push(part(
        "lower_arm_cyl",
        merge(&[cylinder(0.04, -0.25, 0.0, LIMB_SEGS), sphere(0.055, -0.25, LIMB_SEGS, 6)]),
    ));
    out.push(part("upper_leg_cyl", cylinder(0.06, -0.3, 0.0, LIMB_SEGS)));
    out.push(part(
        "lower_leg_cyl",
        merge(&[
            cylinder(0.05, -0.28, 0.0, LIMB_SEGS),
            transform(&cylinder(0.07, -0.3, -0.27, LIMB_SEGS), [1.0, 1.0, 1.6], glam::Quat::IDENTITY, [0.0, 0.0, 0.04]),
        ]),
    ));
    out.push(part(
        "hips_cyl",
        transform(&cylinder(0.15, -0.5, 0.5, LIMB_SEGS + 4), [1.0, 1.0, 1.6], rot(Vec3::Z, FRAC_PI_2), [0.0; 3]),
    ));
    // Capsule style.
    out.push(part("upper_arm_capsule", capsule(0.05, -0.3, 0.0, LIMB_SEGS, 4)));
    out.push(part("lower_arm_capsule", capsule(0.045, -0.3, 0.0, LIMB_SEGS, 4)));
    out.push(part("upper_leg_capsule", capsule(0.065, -0.3, 0.0, LIMB_SEGS, 4)));
    out.push(part(
        "lower_leg_capsule",
        merge(&[
            capsule(0.055, -0.28, 0.0, LIMB_SEGS, 4),
            transform(&sphere(0.07, 0.0, LIMB_SEGS, 6), [1.0, 0.5, 1.6], glam::Quat::IDENTITY, [0.0, -0.265, 0.05]),
        ]),
    ));
    out.push(part(
        "hips_capsule",
        transform(&capsule(0.16, -0.5, 0.5, LIMB_SEGS + 4, 5), [1.0, 1.0, 1.4], rot(Vec3::Z, FRAC_PI_2), [0.0; 3]),
    ));
    out
}

/// Props the walkers carry (wardrobes/walkers.toml `props`), in metres as
/// they hang from the hand joint's origin: a paper bag whose handle is at
/// y = 0, hanging down, and a cup standing on y = 0.
pub fn props() -> Vec<Part> {
    let bag = merge(&[
        cuboid([-0.13, -0.36, -0.05], [0.13, -0.06, 0.05]),
        stick([0.0, -0.06, -0.04], [0.0, 0.0, -0.02], 0.008, 6),
        stick([0.0, -0.06, 0.04], [0.0, 0.0, 0.02], 0.008, 6),
    ]);
    let cup = merge(&[cone(0.032, 0.0, 0.042, 0.13, 16), cylinder(0.044, 0.13, 0.145, 16)]);
    vec![part("bag", flat_shade(&bag)), part("cup", cup)]
}

/// Writes parts as a row of nodes (one per mesh, spaced along X) so a glTF
/// viewer shows them side by side.
pub fn write_parts(path: &std::path::Path, parts: &[Part]) -> Result<()> {
    let mut glb = GlbBuilder::new();
    glb.set_generator("throng examples/make_demo.rs");
    let mut x = 0.0;
    for p in parts {
        let mesh = glb.add_mesh(p.name, &p.mesh, None)?;
        let (lo, hi) = p.mesh.bounds();
        glb.add_node(NodeDesc::new(p.name).mesh(mesh).translation([x - lo[0], 0.0, 0.0]))?;
        x += hi[0] - lo[0] + 0.3;
    }
    glb.write(path)
}
