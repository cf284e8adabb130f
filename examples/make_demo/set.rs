//! The demo set (SPEC "Demo set layout"): floor, buildings, four benches, the
//! shot camera `shotcam` and the sun.

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
/// Camera keys: (shot frame, position, aim, focal length mm).
pub const CAMERA_KEYS: [(i32, [f32; 3], [f32; 3], f32); 2] =
    [(1001, [0.0, 1.7, 24.0], [0.0, 1.0, -2.0], 35.0), (1048, [3.0, 1.8, 22.0], [0.0, 1.0, -2.0], 35.0)];
/// Horizontal film back, mm.
pub const SENSOR_WIDTH: f32 = 36.0;
pub const RESOLUTION: [u32; 2] = [960, 540];
/// Direction towards the sun: low (about 30 degrees up) from the camera's left,
/// so shadows fall back and to the right, visible from the camera.
pub const SUN_TOWARDS: [f32; 3] = [-0.7, 0.45, 0.35];
pub const SUN_COLOR: [f32; 3] = [1.0, 0.93, 0.82];
pub const SUN_INTENSITY: f32 = 3.0;
pub const SUN_ANGULAR_DIAMETER: f32 = 0.53;
pub const SKY_COLOR: [f32; 3] = [0.30, 0.38, 0.50];
pub const SKY_INTENSITY: f32 = 1.0;

/// A building: footprint (x0, z0, x1, z1), height, colour, windowed facade.
struct Building {
    name: &'static str,
    footprint: [f32; 4],
    height: f32,
    color: [f32; 3],
    windows: bool,
}

/// Behind the agents (z in [-45, -35]) and at the sides (|x| in [25, 35]).
const BUILDINGS: [Building; 7] = [
    Building {
        name: "building_back_left",
        footprint: [-24.0, -45.0, -10.0, -36.0],
        height: 14.0,
        color: [0.45, 0.16, 0.1],
        windows: true,
    },
    Building {
        name: "building_back_mid",
        footprint: [-8.0, -44.0, 6.0, -37.0],
        height: 20.0,
        color: [0.55, 0.55, 0.52],
        windows: true,
    },
    Building {
        name: "building_back_right",
        footprint: [8.0, -45.0, 22.0, -35.0],
        height: 10.0,
        color: [0.1, 0.35, 0.35],
        windows: false,
    },
    Building {
        name: "building_left_far",
        footprint: [-35.0, -30.0, -26.0, -12.0],
        height: 16.0,
        color: [0.6, 0.42, 0.12],
        windows: true,
    },
    Building {
        name: "building_left_near",
        footprint: [-34.0, -8.0, -25.0, 8.0],
        height: 8.0,
        color: [0.25, 0.3, 0.38],
        windows: false,
    },
    Building {
        name: "building_right_far",
        footprint: [25.0, -32.0, 35.0, -14.0],
        height: 12.0,
        color: [0.7, 0.62, 0.45],
        windows: true,
    },
    Building {
        name: "building_right_near",
        footprint: [26.0, -10.0, 34.0, 6.0],
        height: 18.0,
        color: [0.12, 0.25, 0.14],
        windows: false,
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
    // A directional light shines down its local -Z: point -Z away from the sun.
    let travel = (-Vec3::from(SUN_TOWARDS)).normalize().to_array();
    glb.add_sun(
        NodeDesc::new("sun").rotation(rotation_looking_along(travel, [0.0, 1.0, 0.0])),
        SUN_COLOR,
        SUN_INTENSITY,
    )?;
    glb.write(path)
}
