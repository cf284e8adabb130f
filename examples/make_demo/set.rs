//! The demo set (SPEC "Demo set layout"): floor, buildings with lit shop
//! windows, four benches, street lamps and the shot camera `shotcam`. The
//! sun is the dome's (the shot's HDRI), so the set carries none.

use glam::Vec3;
use std::path::Path;
use throng::error::Result;
use throng::export::glb::{rotation_looking_along, GlbBuilder, MaterialDesc, MeshData, NodeDesc, Perspective};

use crate::geometry::{cuboid, merge};

/// Floor edge length (metres), centred at the origin.
pub const FLOOR_SIZE: f32 = 80.0;
/// Bench centres along X; all at z = BENCH_Z.
pub const BENCH_XS: [f32; 4] = [-9.0, -3.0, 3.0, 9.0];
pub const BENCH_Z: f32 = -4.0;
/// Bench length along X.
pub const BENCH_LEN: f32 = 3.0;
pub const SEAT_TOP: f32 = 0.45;
pub const SEAT_DEPTH: f32 = 0.5;
const SEAT_THICKNESS: f32 = 0.06;
pub const BACKREST_TOP: f32 = 0.9;
const BACKREST_THICKNESS: f32 = 0.06;
const BENCH_LEG: f32 = 0.06;
// Seated agents (foot z = -3.55 at bench_x + {-1, 0, +1}, SPEC) are placed
// by the simulation scene, demo/sim/demo.toml.

/// Shot frame range and rate.
pub const FRAME_START: i32 = 1001;
pub const FRAME_END: i32 = 1048;
pub const FPS: f32 = 24.0;
/// Camera keys: (shot frame, position, aim, focal length mm). A slow
/// truck right at eye height, 4 m short of the nearest walkers, so the
/// crowd fills the frame from the lower edge to the buildings.
pub const CAMERA_KEYS: [(i32, [f32; 3], [f32; 3], f32); 2] =
    [(1001, [-1.0, 1.65, 13.0], [0.5, 1.0, -8.0], 35.0), (1048, [0.6, 1.7, 12.2], [0.5, 1.0, -8.0], 35.0)];
/// Horizontal film back, mm.
pub const SENSOR_WIDTH: f32 = 36.0;
pub const RESOLUTION: [u32; 2] = [960, 540];
/// The dome: the shared CC0 HDRI (demo/hdri/SOURCE.md), a clear day whose
/// sun stands 10 degrees up. Turned so that the sun is on the camera's
/// left and a little in front of the crowd: faces catch it side-on and the
/// long shadows fall to the right and towards the camera.
pub const DOME_FILE: &str = "hdri/quarry_01_1k.hdr";
pub const DOME_ROTATE: f32 = -116.0;
pub const DOME_INTENSITY: f32 = 1.0;

/// Street lamps along the back of the square, outside the agents' area
/// (z >= -30): a pole, an arm towards the camera and a glowing globe, a
/// sphere light the shot declares at `lamp_globe`.
pub const LAMP_XS: [f32; 4] = [-13.5, -4.5, 4.5, 13.5];
pub const LAMP_Z: f32 = -31.5;
const LAMP_HEIGHT: f32 = GLOBE_Y + LAMP_RADIUS + 0.25;
const LAMP_ARM: f32 = 0.6;
pub const LAMP_RADIUS: f32 = 0.16;
/// Radiance of a globe, W/(m^2 sr): far above the daylit walls (about 1),
/// so it reads as lit by day; 2.4 W/sr, a small pool on the ground below.
pub const LAMP_RADIANCE: f32 = 30.0;
pub const LAMP_COLOR: [f32; 3] = [1.0, 0.72, 0.42];

/// Height of a globe's centre: just under the shade.
const GLOBE_Y: f32 = 3.79;

/// Centre of lamp `x`'s globe.
pub fn lamp_globe(x: f32) -> [f32; 3] {
    [x, GLOBE_Y, LAMP_Z + LAMP_ARM]
}

/// Lit shop windows on the ground floor of the back buildings: emissive
/// panels just proud of the facade, lights by next-event estimation.
const SHOP_WINDOW: [f32; 2] = [2.4, 2.2];
const SHOP_SILL: f32 = 0.5;
/// Just under a daylit white wall's radiance, warm: lit, not clipped.
const SHOP_RADIANCE: [f32; 3] = [1.1, 0.8, 0.48];

/// A building: footprint (x0, z0, x1, z1), height, colour, windowed facade.
struct Building {
    name: &'static str,
    footprint: [f32; 4],
    height: f32,
    color: [f32; 3],
    windows: bool,
    /// Lit shop windows along its front (+Z) face.
    shops: bool,
}

/// Behind the agents (z in [-45, -35]) and at the sides (|x| in [25, 35]).
const BUILDINGS: [Building; 7] = [
    Building {
        name: "building_back_left",
        footprint: [-24.0, -45.0, -10.0, -36.0],
        height: 14.0,
        color: [0.45, 0.16, 0.1],
        windows: true,
        shops: true,
    },
    Building {
        name: "building_back_mid",
        footprint: [-8.0, -44.0, 6.0, -37.0],
        height: 20.0,
        color: [0.55, 0.55, 0.52],
        windows: true,
        shops: true,
    },
    Building {
        name: "building_back_right",
        footprint: [8.0, -45.0, 22.0, -35.0],
        height: 10.0,
        color: [0.1, 0.35, 0.35],
        windows: false,
        shops: true,
    },
    Building {
        name: "building_left_far",
        footprint: [-35.0, -30.0, -26.0, -12.0],
        height: 16.0,
        color: [0.6, 0.42, 0.12],
        windows: true,
        shops: false,
    },
    Building {
        name: "building_left_near",
        footprint: [-34.0, -8.0, -25.0, 8.0],
        height: 8.0,
        color: [0.25, 0.3, 0.38],
        windows: false,
        shops: false,
    },
    Building {
        name: "building_right_far",
        footprint: [25.0, -32.0, 35.0, -14.0],
        height: 12.0,
        color: [0.7, 0.62, 0.45],
        windows: true,
        shops: false,
    },
    Building {
        name: "building_right_near",
        footprint: [26.0, -10.0, 34.0, 6.0],
        height: 18.0,
        color: [0.12, 0.25, 0.14],
        windows: false,
        shops: false,
    },
];

/// Vertical field of view for the shot's lens and aspect ratio.
pub fn camera_yfov(focal_mm: f32) -> f32 {
    let aspect = RESOLUTION[0] as f32 / RESOLUTION[1] as f32;
    2.0 * ((SENSOR_WIDTH / aspect) / (2.0 * focal_mm)).atan()
}

fn floor() -> MeshData {
    let h = FLOOR_SIZE / 2.0;
    MeshData {
        positions: vec![[-h, 0.0, h], [h, 0.0, h], [h, 0.0, -h], [-h, 0.0, -h]],
        normals: vec![[0.0, 1.0, 0.0]; 4],
        uvs: vec![[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]],
        indices: vec![0, 1, 2, 0, 2, 3],
        ..Default::default()
    }
}

/// One bench in its own space (centre of the seat's footprint at the origin):
/// seat slab, backrest along the back (-Z) edge, four legs.
fn bench() -> MeshData {
    let hx = BENCH_LEN / 2.0;
    let hz = SEAT_DEPTH / 2.0;
    let mut parts = vec![
        cuboid([-hx, SEAT_TOP - SEAT_THICKNESS, -hz], [hx, SEAT_TOP, hz]),
        cuboid([-hx, SEAT_TOP, -hz], [hx, BACKREST_TOP, -hz + BACKREST_THICKNESS]),
    ];
    for x in [-hx + 0.1, hx - 0.1 - BENCH_LEG] {
        for z in [-hz + 0.02, hz - 0.02 - BENCH_LEG] {
            parts.push(cuboid([x, 0.0, z], [x + BENCH_LEG, SEAT_TOP - SEAT_THICKNESS, z + BENCH_LEG]));
        }
    }
    merge(&parts)
}

/// One street lamp in its own space (the pole's foot at the origin): pole,
/// an arm towards +Z and the shade over the globe (the globe itself is the
/// shot's sphere light, not geometry).
fn lamp() -> MeshData {
    let h = LAMP_HEIGHT;
    merge(&[
        cuboid([-0.06, 0.0, -0.06], [0.06, h, 0.06]),
        cuboid([-0.035, h - 0.1, 0.0], [0.035, h - 0.03, LAMP_ARM + 0.05]),
        cuboid([-0.22, h - 0.25, LAMP_ARM - 0.22], [0.22, h - 0.1, LAMP_ARM + 0.22]),
    ])
}

/// Shop windows along a front face at `z` from `x0` to `x1`: panels facing +Z.
fn shop_windows(x0: f32, x1: f32, z: f32) -> MeshData {
    let [w, h] = SHOP_WINDOW;
    let count = ((x1 - x0 - 1.0) / (w + 1.0)).floor().max(1.0) as usize;
    let gap = (x1 - x0 - count as f32 * w) / (count as f32 + 1.0);
    let (y0, y1, z) = (SHOP_SILL, SHOP_SILL + h, z + 0.02);
    let mut m = MeshData::default();
    for i in 0..count {
        let a = x0 + gap + i as f32 * (w + gap);
        let base = m.positions.len() as u32;
        m.positions.extend([[a, y0, z], [a + w, y0, z], [a + w, y1, z], [a, y1, z]]);
        m.normals.extend([[0.0, 0.0, 1.0]; 4]);
        m.uvs.extend([[0.0, 1.0], [1.0, 1.0], [1.0, 0.0], [0.0, 0.0]]);
        m.indices.extend([base, base + 1, base + 2, base, base + 2, base + 3]);
    }
    m
}

/// A facade texture: dark windows on a light wall (multiplies the base colour).
fn windows_png() -> Result<Vec<u8>> {
    const SIZE: u32 = 128;
    const CELLS: u32 = 8;
    let img = image::RgbaImage::from_fn(SIZE, SIZE, |x, y| {
        let cell = SIZE / CELLS;
        let (cx, cy) = (x % cell, y % cell);
        let window = (3..cell - 3).contains(&cx) && (4..cell - 2).contains(&cy);
        if window {
            image::Rgba([60, 70, 85, 255])
        } else {
            image::Rgba([235, 235, 235, 255])
        }
    });
    crate::encode_png(&img)
}

/// Writes demo/set/set.glb.
pub fn write_set(path: &Path) -> Result<()> {
    let mut glb = GlbBuilder::new();
    glb.set_generator("throng examples/make_demo.rs");
    let floor_mat = glb.add_material(&MaterialDesc::new("floor_polished", [0.42, 0.42, 0.44, 1.0]).pbr(0.0, 0.2));
    let bench_mat = glb.add_material(&MaterialDesc::new("bench_wood", [0.35, 0.2, 0.09, 1.0]).pbr(0.0, 0.6));
    let floor_mesh = glb.add_mesh("floor", &floor(), Some(floor_mat))?;
    glb.add_node(NodeDesc::new("floor").mesh(floor_mesh))?;

    let shop_mat = glb.add_material(&MaterialDesc::new("shop_window", [0.1, 0.1, 0.1, 1.0]).emission(SHOP_RADIANCE));
    let windows = windows_png()?;
    for b in &BUILDINGS {
        let [x0, z0, x1, z1] = b.footprint;
        let c = b.color;
        let mut m = MaterialDesc::new(format!("{}_paint", b.name), [c[0], c[1], c[2], 1.0]).pbr(0.0, 0.8);
        if b.windows {
            m = m.texture_png(windows.clone());
        }
        let mat = glb.add_material(&m);
        let mesh = glb.add_mesh(b.name, &cuboid([x0, 0.0, z0], [x1, b.height, z1]), Some(mat))?;
        glb.add_node(NodeDesc::new(b.name).mesh(mesh))?;
        if b.shops {
            let name = format!("{}_shops", b.name);
            let mesh = glb.add_mesh(&name, &shop_windows(x0, x1, z1), Some(shop_mat))?;
            glb.add_node(NodeDesc::new(name).mesh(mesh))?;
        }
    }

    // One lamp mesh, instanced along the back of the square.
    let lamp_mat = glb.add_material(&MaterialDesc::new("lamp_iron", [0.05, 0.05, 0.055, 1.0]).pbr(1.0, 0.45));
    let lamp_mesh = glb.add_mesh("lamp", &lamp(), Some(lamp_mat))?;
    for (i, x) in LAMP_XS.iter().enumerate() {
        glb.add_node(NodeDesc::new(format!("lamp_{}", i + 1)).mesh(lamp_mesh).translation([*x, 0.0, LAMP_Z]))?;
    }

    // One bench mesh, instanced four times.
    let bench_mesh = glb.add_mesh("bench", &bench(), Some(bench_mat))?;
    for (i, x) in BENCH_XS.iter().enumerate() {
        glb.add_node(
            NodeDesc::new(format!("bench_{}", i + 1))
                .mesh(bench_mesh)
                .translation([*x, 0.0, BENCH_Z])
                .extras(serde_json::json!({"seat_top": SEAT_TOP, "length": BENCH_LEN, "depth": SEAT_DEPTH})),
        )?;
    }

    let (_, pos, aim, focal) = CAMERA_KEYS[0];
    let forward = (Vec3::from(aim) - Vec3::from(pos)).to_array();
    glb.add_camera(
        NodeDesc::new("shotcam").translation(pos).rotation(rotation_looking_along(forward, [0.0, 1.0, 0.0])),
        Perspective {
            yfov: camera_yfov(focal),
            aspect_ratio: Some(RESOLUTION[0] as f32 / RESOLUTION[1] as f32),
            znear: 0.1,
            zfar: Some(500.0),
        },
    )?;
    glb.write(path)
}
