//! Issue 15's closing bad-input matrix: a fresh set of cases, none of them
//! in `tests/bad_input.rs` or `.ci/bad_input_matrix.py`, across every input
//! kind (shot TOML section by section, wardrobe TOML, rig files, the binary
//! cache, CSV, JuPedSim sqlite, USD crowds, glTF meshes and textures, layer
//! manifests, EXR inputs, farm plans and options, the flags of every verb).
//!
//! Each case runs the real `throng` binary under a 4 GB address-space cap
//! and a CPU-time cap (`ulimit -v`, `ulimit -t`), and must exit 2, name the
//! file and the key, field or flag (and the agent where one is at fault) on
//! stderr, never panic, and leave no output under its final name. Every
//! case is a test of its own (`cargo test --test bad_input_matrix -- NAME`
//! runs one) that fails naming all its problems; the ignored test
//! `the_table_of_every_case` writes the table of results to
//! `target/tmp/bad_input_matrix.md` (and to `$THRONG_MATRIX_MD` when set).

mod common;

use std::path::Path;

use common::matrix::{self, append, c, edit, ok, sqlite, Case, Harness, Table, JUPEDSIM_OK};
use common::repo_path;

fn demo(rel: &str) -> String {
    repo_path("demo").join(rel).display().to_string()
}

/// The base of every case: two idle robots on frames 1001-1003 (cache
/// frames 1-3), the demo's rig and set, a sun ([`common::DemoShot`]); a
/// one-material wardrobe `w.toml`.
fn base(dir: &Path) {
    let sun = "\n[lights.sun]\ndirection = [-0.5, 0.6, 0.4]\nintensity = 3.0\n";
    common::DemoShot { lights: sun, ..Default::default() }.write(dir, &common::two_robots(1..=3));
    let red = "[materials.red]\nbase_color = [0.6, 0.05, 0.04]";
    std::fs::write(dir.join("w.toml"), common::heads_wardrobe(red, "slot = \"head\"\nmaterials = [\"red\"]")).unwrap();
}

/// The shot wears `w.toml` (scheme `Only`) instead of the robots.
fn use_wardrobe(dir: &Path) {
    common::wear_heads(&dir.join("shot.toml"), "w.toml");
}

/// The shot wears `w.toml`, whose scheme `Only` also hangs prop `drink` (a
/// demo head mesh) on the robot's `lower_arm_r` slot, then `keys`.
fn with_prop(dir: &Path, keys: &str) {
    use_wardrobe(dir);
    let heads = demo("parts/heads.glb");
    let prop = format!(
        "\n[[schemes.Only.props]]\nname = \"drink\"\nslot = \"lower_arm_r\"\nfile = \"{heads}\"\nmesh = \"head_can\"\n{keys}\n"
    );
    append(dir, "w.toml", &prop);
}

/// The base cache as a `.crowd` in `dir/c.crowd`, and the shot reading it.
fn crowd_cache(dir: &Path) -> Vec<u8> {
    ok(dir, &["cache", "convert", "c.csv", "c.crowd"]);
    edit(dir, "shot.toml", "path = \"c.csv\"", "path = \"c.crowd\"");
    std::fs::read(dir.join("c.crowd")).unwrap()
}

/// The shot's rig is Khronos InterpolationTest (shared assets) declared
/// `kind = "rigid"`, with `keys` more keys of its table.
fn rigid_rig(dir: &Path, keys: &str) {
    let file = common::shared_asset("gltf/InterpolationTest/InterpolationTest.gltf").display().to_string();
    edit(dir, "shot.toml", &demo("rigs/bipedThinA.glb"), &file);
    edit(dir, "shot.toml", "schemes = { HighEnd = 1.0 }", &format!("kind = \"rigid\"\n{keys}"));
}

/// Sets header field `offset` (u32) of a `.crowd` and fixes the header CRC.
fn patch_header(bytes: &mut [u8], offset: usize, value: u32) {
    bytes[offset..offset + 4].copy_from_slice(&value.to_le_bytes());
    let crc = crc32fast::hash(&bytes[..28]);
    bytes[28..32].copy_from_slice(&crc.to_le_bytes());
}

/// A one-triangle glTF (`dir/set.gltf`, buffer `tri.bin`) with `extra`
/// JSON members merged into the top-level object and `material` as the
/// primitive's material member; the shot's set is that file.
fn tri_gltf(dir: &Path, extra: &str, material: &str, count: u32) {
    let mut bin = Vec::new();
    for v in [[0.0f32, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]] {
        for c in v {
            bin.extend_from_slice(&c.to_le_bytes());
        }
    }
    std::fs::write(dir.join("tri.bin"), &bin).unwrap();
    let json = format!(
        r#"{{"asset":{{"version":"2.0"}},
"buffers":[{{"byteLength":36,"uri":"tri.bin"}}],
"bufferViews":[{{"buffer":0,"byteLength":36}}],
"accessors":[{{"bufferView":0,"componentType":5126,"count":{count},"type":"VEC3","min":[0,0,0],"max":[1,0,1]}}],
"meshes":[{{"name":"tri","primitives":[{{"attributes":{{"POSITION":0}}{material}}}]}}],
"nodes":[{{"mesh":0,"name":"tri"}}],
"scenes":[{{"nodes":[0]}}],"scene":0{extra}}}"#
    );
    std::fs::write(dir.join("set.gltf"), json).unwrap();
    edit(dir, "shot.toml", &demo("set/set.glb"), "set.gltf");
}

/// A rendered layer set and its manifest for frame 1001 (in `dir/r`).
fn rendered(dir: &Path) {
    ok(dir, &["layers", "shot.toml"]);
    ok(dir, &["render", "shot.toml", "--frames", "1001", "--progress", "off", "--out", "r"]);
}

/// A farm plan of the base shot in `dir/farm`.
fn planned(dir: &Path) {
    ok(dir, &["farm", "plan", "shot.toml", "--frames", "1001", "--out", "farm"]);
}

const USD_HEAD: &str =
    "#usda 1.0\n(\n    upAxis = \"Y\"\n    metersPerUnit = 1\n    startTimeCode = 1\n    endTimeCode = 2\n)\n";

/// Every case, in the table's order, as `test_name => c(...)`. Each becomes
/// a `#[test]` of that name, so a failure names its case and
/// `cargo test --test bad_input_matrix -- NAME` runs one (a prefix such as
/// `csv_` runs a kind); [`cases`] gives them all to the table.
macro_rules! matrix {
    ($($test:ident => $case:expr,)*) => {
        /// Every case, with its test's name.
        fn cases() -> Vec<(&'static str, Case)> {
            vec![$((stringify!($test), $case),)*]
        }
        $(
            #[test]
            fn $test() {
                matrix::check(&HARNESS, stringify!($test), &$case);
            }
        )*
    };
}

/// `cast` of the case's shot.
const CAST: &[&str] = &["cast", "{d}/shot.toml"];
/// A render of the case's shot's full layer on frame 1001, into `o`.
const FULL: &[&str] =
    &["render", "{d}/shot.toml", "--layer", "full", "--frames", "1001", "--progress", "off", "--out", "{d}/o"];
/// What [`FULL`] would write.
const FULL_EXR: &[&str] = &["o/full/bad.full.1001.exr"];

matrix! {
    // ---------------------------------------------------------- shot TOML
    shot_frames_start_is_a_string => c(
        "shot [frames]",
        "start is a string",
        |d| edit(d, "shot.toml", "start = 1001", "start = \"1001\""),
        CAST,
        &["shot.toml", "start"],
        &[],
    ),
    shot_frames_fps_is_infinite => c(
        "shot [frames]",
        "fps is infinite",
        |d| edit(d, "shot.toml", "fps = 24.0", "fps = inf"),
        CAST,
        &["shot.toml", "fps"],
        &[],
    ),
    shot_cache_no_cache_path => c(
        "shot [cache]",
        "no cache path",
        |d| edit(d, "shot.toml", "path = \"c.csv\"\n", ""),
        CAST,
        &["shot.toml", "path"],
        &[],
    ),
    shot_cache_frame_offset_1_5 => c(
        "shot [cache]",
        "frame_offset 1.5",
        |d| edit(d, "shot.toml", "frame_offset = -1000", "frame_offset = -999.5"),
        CAST,
        &["shot.toml", "frame_offset"],
        &[],
    ),
    shot_rigs_rig_file_missing => c(
        "shot [rigs]",
        "rig file missing",
        |d| edit(d, "shot.toml", &demo("rigs/bipedThinA.glb"), "nope.glb"),
        CAST,
        &["shot.toml", "rigs.bipedThinA.file"],
        &[],
    ),
    shot_rigs_scheme_no_wardrobe_has => c(
        "shot [rigs]",
        "scheme no wardrobe has",
        |d| edit(d, "shot.toml", "HighEnd = 1.0", "Nowhere = 1.0"),
        CAST,
        &["shot.toml", "Nowhere"],
        &[],
    ),
    shot_rigs_no_schemes_at_all => c(
        "shot [rigs]",
        "no schemes at all",
        |d| edit(d, "shot.toml", "schemes = { HighEnd = 1.0 }", "schemes = {}"),
        CAST,
        &["shot.toml", "schemes"],
        &[],
    ),
    shot_set_file_is_not_gltf => c(
        "shot [set]",
        "set file is not glTF",
        |d| {
            std::fs::write(d.join("junk.glb"), b"not a gltf at all").unwrap();
            edit(d, "shot.toml", &demo("set/set.glb"), "junk.glb")
        },
        CAST,
        &["junk.glb"],
        &[],
    ),
    shot_camera_aim_at_the_camera_position => c(
        "shot [camera]",
        "aim at the camera position",
        |d| edit(d, "shot.toml", "aim = [0.0, 0.9, 0.0]", "aim = [0.0, 1.6, 9.0]"),
        FULL,
        &["shot.toml", "camera.keys"],
        FULL_EXR,
    ),
    shot_camera_two_keys_on_one_frame => c(
        "shot [camera]",
        "two keys on one frame",
        |d| {
            append(d, "shot.toml", "\n[[camera.keys]]\nframe = 1001\nposition = [1.0, 1.6, 9.0]\naim = [0.0, 0.9, 0.0]\nfocal_length = 35.0\n")
        },
        CAST,
        &["shot.toml", "camera.keys"],
        &[],
    ),
    shot_camera_focal_length_nan => c(
        "shot [camera]",
        "focal length NaN",
        |d| edit(d, "shot.toml", "focal_length = 35.0", "focal_length = nan"),
        CAST,
        &["shot.toml", "camera.keys", "focal length"],
        &[],
    ),
    shot_lights_sun_intensity_minus_3 => c(
        "shot [lights]",
        "sun intensity -3",
        |d| edit(d, "shot.toml", "intensity = 3.0", "intensity = -3.0"),
        CAST,
        &["shot.toml", "lights.sun.intensity"],
        &[],
    ),
    shot_lights_sun_colour_nan => c(
        "shot [lights]",
        "sun colour NaN",
        |d| edit(d, "shot.toml", "intensity = 3.0", "intensity = 3.0\ncolor = [1.0, nan, 1.0]"),
        CAST,
        &["shot.toml", "lights.sun.color"],
        &[],
    ),
    shot_lights_sun_400_degrees_wide => c(
        "shot [lights]",
        "sun 400 degrees wide",
        |d| edit(d, "shot.toml", "intensity = 3.0", "intensity = 3.0\nangular_diameter = 400.0"),
        CAST,
        &["shot.toml", "lights.sun.angular_diameter"],
        &[],
    ),
    shot_lights_sky_intensity_infinite => c(
        "shot [lights]",
        "sky intensity infinite",
        |d| append(d, "shot.toml", "\n[lights.sky]\ncolor = [0.3, 0.38, 0.5]\nintensity = inf\n"),
        CAST,
        &["shot.toml", "lights.sky.intensity"],
        &[],
    ),
    shot_layers_split_mode_magic => c(
        "shot [layers]",
        "split mode magic",
        |d| edit(d, "shot.toml", "count = 2", "split = \"magic\""),
        CAST,
        &["shot.toml", "split"],
        &[],
    ),
    shot_layers_lod_full_min_px_minus_5 => c(
        "shot [layers]",
        "lod_full_min_px -5",
        |d| edit(d, "shot.toml", "count = 2", "count = 2\nlod_full_min_px = -5.0"),
        CAST,
        &["shot.toml", "layers.lod_full_min_px"],
        &[],
    ),
    shot_render_resolution_with_one_number => c(
        "shot [render]",
        "resolution with one number",
        |d| edit(d, "shot.toml", "[48, 27]", "[48]"),
        CAST,
        &["shot.toml", "resolution"],
        &[],
    ),
    shot_render_max_bounces_10_pow_9 => c(
        "shot [render]",
        "max_bounces 10^9",
        |d| edit(d, "shot.toml", "spp = 1", "spp = 1\nmax_bounces = 1000000000"),
        CAST,
        &["shot.toml", "render.max_bounces"],
        &[],
    ),
    shot_render_working_colourspace_7 => c(
        "shot [render]",
        "working_colourspace 7",
        |d| edit(d, "shot.toml", "spp = 1", "spp = 1\nworking_colourspace = 7"),
        CAST,
        &["shot.toml", "working_colourspace"],
        &[],
    ),
    shot_name_with_a_slash => c(
        "shot (top)",
        "shot name with a slash",
        |d| edit(d, "shot.toml", "name = \"bad\"", "name = \"../escape\""),
        FULL,
        &["shot.toml", "name"],
        &["escape.full.1001.exr", "o/escape.full.1001.exr"],
    ),
    shot_empty_shot_name => c(
        "shot (top)",
        "empty shot name",
        |d| edit(d, "shot.toml", "name = \"bad\"", "name = \"\""),
        CAST,
        &["shot.toml", "name"],
        &[],
    ),
    shot_seed_minus_1 => c(
        "shot (top)",
        "seed -1",
        |d| edit(d, "shot.toml", "seed = 5", "seed = -1"),
        CAST,
        &["shot.toml", "seed"],
        &[],
    ),
    shot_wardrobe_file_missing => c(
        "shot (top)",
        "wardrobe file missing",
        |d| edit(d, "shot.toml", &repo_path("wardrobes/robots.toml").display().to_string(), "gone.toml"),
        CAST,
        &["shot.toml", "gone.toml"],
        &[],
    ),
    shot_removed_is_not_a_list => c(
        "shot (top)",
        "removed is not a list",
        |d| edit(d, "shot.toml", "seed = 5", "seed = 5\nremoved = 3"),
        CAST,
        &["shot.toml", "removed"],
        &[],
    ),
    shot_rigs_rig_file_is_a_gltf_without_the_rig => c(
        "shot [rigs]",
        "rig file is a glTF without the rig",
        |d| edit(d, "shot.toml", &demo("rigs/bipedThinA.glb"), &demo("set/set.glb")),
        CAST,
        &["set.glb", "rigs.bipedThinA.file", "root"],
        &[],
    ),
    wardrobe_part_mesh_missing_from_its_gltf => c(
        "wardrobe",
        "part mesh missing from its glTF",
        |d| {
            use_wardrobe(d);
            edit(d, "w.toml", "mesh = \"head_sphere\"", "mesh = \"head_gone\"")
        },
        CAST,
        // Checked when the shot is cast (issue 26 item 5), before any agent draws it.
        &["heads.glb", "head_gone", "schemes.Only.parts[0].mesh"],
        &[],
    ),
    // ---------------------------------------------------------- wardrobe TOML
    wardrobe_base_color_with_2_numbers => c(
        "wardrobe",
        "base_color with 2 numbers",
        |d| {
            use_wardrobe(d);
            edit(d, "w.toml", "[0.6, 0.05, 0.04]", "[0.6, 0.05]")
        },
        CAST,
        &["w.toml", "base_color"],
        &[],
    ),
    wardrobe_base_color_nan => c(
        "wardrobe",
        "base_color NaN",
        |d| {
            use_wardrobe(d);
            edit(d, "w.toml", "[0.6, 0.05, 0.04]", "[0.6, nan, 0.04]")
        },
        CAST,
        &["w.toml", "materials.red.base_color"],
        &[],
    ),
    wardrobe_roughness_2 => c(
        "wardrobe",
        "roughness 2",
        |d| {
            use_wardrobe(d);
            edit(d, "w.toml", "base_color = [0.6, 0.05, 0.04]", "base_color = [0.6, 0.05, 0.04]\nroughness = 2.0")
        },
        CAST,
        &["w.toml", "materials.red.roughness"],
        &[],
    ),
    wardrobe_metallic_minus_1 => c(
        "wardrobe",
        "metallic -1",
        |d| {
            use_wardrobe(d);
            edit(d, "w.toml", "base_color = [0.6, 0.05, 0.04]", "base_color = [0.6, 0.05, 0.04]\nmetallic = -1.0")
        },
        CAST,
        &["w.toml", "materials.red.metallic"],
        &[],
    ),
    wardrobe_material_name_with_hash => c(
        "wardrobe",
        "material name with #",
        |d| {
            use_wardrobe(d);
            edit(d, "w.toml", "[materials.red]", "[materials.\"re#d\"]");
            edit(d, "w.toml", "materials = [\"red\"]", "materials = [\"re#d\"]")
        },
        CAST,
        &["w.toml", "re#d"],
        &[],
    ),
    wardrobe_part_mesh_not_in_its_file => c(
        "wardrobe",
        "part mesh not in its file",
        |d| {
            use_wardrobe(d);
            edit(d, "w.toml", "head_sphere", "head_cube_x")
        },
        CAST,
        &["heads.glb", "head_cube_x"],
        &[],
    ),
    wardrobe_material_weights_longer_than_materials => c(
        "wardrobe",
        "material_weights longer than materials",
        |d| {
            use_wardrobe(d);
            edit(d, "w.toml", "materials = [\"red\"]", "materials = [\"red\"]\nmaterial_weights = [1.0, 2.0]")
        },
        CAST,
        &["w.toml", "material_weights"],
        &[],
    ),
    wardrobe_prop_on_a_slot_the_rig_lacks => c(
        "wardrobe",
        "prop on a slot the rig lacks",
        |d| {
            with_prop(d, "");
            edit(d, "w.toml", "slot = \"lower_arm_r\"", "slot = \"tail\"")
        },
        CAST,
        &["w.toml", "schemes.Only.props[0].slot", "drink", "tail"],
        &[],
    ),
    wardrobe_prop_on_a_joint_of_a_slot_rig => c(
        "wardrobe",
        "prop on a joint of a slot rig",
        |d| {
            with_prop(d, "");
            edit(d, "w.toml", "slot = \"lower_arm_r\"", "joint = \"hand_r\"")
        },
        CAST,
        &["w.toml", "schemes.Only.props[0].joint", "drink", "slot rig"],
        &[],
    ),
    wardrobe_prop_mesh_missing_from_its_gltf => c(
        "wardrobe",
        "prop mesh missing from its glTF",
        |d| {
            with_prop(d, "");
            edit(d, "w.toml", "mesh = \"head_can\"", "mesh = \"cup_gone\"")
        },
        CAST,
        &["w.toml", "heads.glb", "cup_gone", "drink", "schemes.Only.props[0].mesh"],
        &[],
    ),
    wardrobe_prop_weight_negative => c(
        "wardrobe",
        "prop weight -1",
        |d| with_prop(d, "weight = -1.0"),
        CAST,
        &["w.toml", "schemes.Only.props[0].weight", "drink"],
        &[],
    ),
    wardrobe_prop_group_of_zero_weights => c(
        "wardrobe",
        "prop group whose weights are all 0",
        |d| with_prop(d, "group = \"hand\"\nweight = 0.0\n[[schemes.Only.props]]\ngroup = \"hand\"\nname = \"none\"\nweight = 0.0"),
        CAST,
        &["w.toml", "schemes.Only.props[0].weight", "prop group `hand`"],
        &[],
    ),
    wardrobe_prop_offset_nan => c(
        "wardrobe",
        "prop offset NaN",
        |d| with_prop(d, "offset = [0.0, nan, 0.0]"),
        CAST,
        &["w.toml", "schemes.Only.props[0].offset", "drink"],
        &[],
    ),
    // ---------------------------------------------------------- rig files
    rig_file_of_garbage => c(
        "rig file",
        "rig file of garbage",
        |d| {
            std::fs::write(d.join("rig.glb"), b"glTF\x02\x00\x00\x00garbage").unwrap();
            edit(d, "shot.toml", &demo("rigs/bipedThinA.glb"), "rig.glb")
        },
        CAST,
        &["rig.glb"],
        &[],
    ),
    rig_file_the_set_used_as_a_rig => c(
        "rig file",
        "the set used as a rig",
        |d| edit(d, "shot.toml", &demo("rigs/bipedThinA.glb"), &demo("set/set.glb")),
        CAST,
        &["set.glb", "root"],
        &[],
    ),
    rig_file_empty_rig_file => c(
        "rig file",
        "empty rig file",
        |d| {
            std::fs::write(d.join("rig.glb"), b"").unwrap();
            edit(d, "shot.toml", &demo("rigs/bipedThinA.glb"), "rig.glb")
        },
        CAST,
        &["rig.glb"],
        &[],
    ),
    rig_file_kind_rigid_on_a_skinned_character => c(
        "rig file",
        "kind rigid on a skinned character",
        |d| {
            edit(d, "shot.toml", &demo("rigs/bipedThinA.glb"), &demo("rigs/walker.glb"));
            edit(d, "shot.toml", "schemes = { HighEnd = 1.0 }", "kind = \"rigid\"")
        },
        CAST,
        &["walker.glb", "rigs.bipedThinA.kind", "skin"],
        &[],
    ),
    rig_file_kind_rigid_on_a_file_without_animation => c(
        "rig file",
        "kind rigid on a file without animation",
        |d| {
            edit(d, "shot.toml", &demo("rigs/bipedThinA.glb"), &demo("set/set.glb"));
            edit(d, "shot.toml", "schemes = { HighEnd = 1.0 }", "kind = \"rigid\"")
        },
        CAST,
        &["set.glb", "rigs.bipedThinA.file", "no animation"],
        &[],
    ),
    rig_file_rigid_cycle_maps_to_a_missing_clip => c(
        "rig file",
        "rigid cycle maps to a missing clip",
        |d| rigid_rig(d, "cycles = { IdleA = \"Fly\" }"),
        CAST,
        &["InterpolationTest.gltf", "rigs.bipedThinA.cycles.IdleA", "Fly"],
        &[],
    ),
    rig_file_rigid_forward_along_up => c(
        "rig file",
        "rigid forward along up",
        |d| rigid_rig(d, "forward = \"+y\""),
        CAST,
        &["InterpolationTest.gltf", "rigs.bipedThinA.forward", "along up"],
        &[],
    ),
    rig_file_rigid_forward_not_an_axis => c(
        "rig file",
        "rigid forward not an axis",
        |d| rigid_rig(d, "forward = \"north\""),
        CAST,
        &["shot.toml", "rigs.bipedThinA.forward", "+z"],
        &[],
    ),
    // ---------------------------------------------------------- binary cache
    crowd_truncated_to_100_bytes => c(
        "cache .crowd",
        "truncated to 100 bytes",
        |d| {
            let b = crowd_cache(d);
            std::fs::write(d.join("c.crowd"), &b[..100]).unwrap()
        },
        CAST,
        &["c.crowd"],
        &[],
    ),
    crowd_frame_count_2_pow_32_1_crc_fixed => c(
        "cache .crowd",
        "frame_count 2^32-1 (CRC fixed)",
        |d| {
            let mut b = crowd_cache(d);
            patch_header(&mut b, 16, u32::MAX);
            std::fs::write(d.join("c.crowd"), b).unwrap()
        },
        &["cache", "info", "{d}/c.crowd"],
        &["c.crowd"],
        &[],
    ),
    crowd_index_len_2_pow_32_16_crc_fixed => c(
        "cache .crowd",
        "index_len 2^32-16 (CRC fixed)",
        |d| {
            let mut b = crowd_cache(d);
            patch_header(&mut b, 12, u32::MAX - 15);
            std::fs::write(d.join("c.crowd"), b).unwrap()
        },
        &["cache", "info", "{d}/c.crowd"],
        &["c.crowd"],
        &[],
    ),
    crowd_version_2_crc_fixed => c(
        "cache .crowd",
        "version 2 (CRC fixed)",
        |d| {
            let mut b = crowd_cache(d);
            patch_header(&mut b, 8, 2);
            std::fs::write(d.join("c.crowd"), b).unwrap()
        },
        CAST,
        &["c.crowd", "version"],
        &[],
    ),
    crowd_a_flipped_byte_in_the_last_frame => c(
        "cache .crowd",
        "a flipped byte in the last frame",
        |d| {
            let mut b = crowd_cache(d);
            let n = b.len();
            b[n - 10] ^= 0x55;
            std::fs::write(d.join("c.crowd"), b).unwrap()
        },
        CAST,
        &["c.crowd"],
        &[],
    ),
    cache_convert_into_a_read_only_format => c(
        "cache convert",
        "convert into a read-only format",
        |_| {},
        &["cache", "convert", "{d}/c.csv", "{d}/out.sqlite"],
        &["out.sqlite", "read only"],
        &["out.sqlite"],
    ),
    // ---------------------------------------------------------- CSV
    csv_no_heading_column => c(
        "cache CSV",
        "no heading column",
        |d| {
            let t = std::fs::read_to_string(d.join("c.csv")).unwrap();
            let t: String = t
                .lines()
                .map(|l| {
                    let mut f: Vec<&str> = l.split(',').collect();
                    f.remove(5);
                    f.join(",") + "\n"
                })
                .collect();
            std::fs::write(d.join("c.csv"), t).unwrap()
        },
        CAST,
        &["c.csv", "heading"],
        &[],
    ),
    csv_flags_4_unknown_bit => c(
        "cache CSV",
        "flags 4 (unknown bit)",
        |d| append(d, "c.csv", "3,9,0,0,0,0,bipedThinA,IdleA,3,4\n"),
        CAST,
        &["c.csv", "flags"],
        &[],
    ),
    csv_cycle_frame_infinite => c(
        "cache CSV",
        "cycle_frame infinite",
        |d| append(d, "c.csv", "3,9,0,0,0,0,bipedThinA,IdleA,inf,\n"),
        CAST,
        &["c.csv", "cycle_frame", "agent 9"],
        &[],
    ),
    csv_negative_agent_id => c(
        "cache CSV",
        "negative agent id",
        |d| append(d, "c.csv", "3,-4,0,0,0,0,bipedThinA,IdleA,3,\n"),
        CAST,
        &["c.csv", "id"],
        &[],
    ),
    csv_a_row_with_12_fields => c(
        "cache CSV",
        "a row with 12 fields",
        |d| append(d, "c.csv", "3,9,0,0,0,0,bipedThinA,IdleA,3,,7,8\n"),
        CAST,
        &["c.csv:8", "columns"],
        &[],
    ),
    csv_frame_past_i32 => c(
        "cache CSV",
        "frame past i32",
        |d| append(d, "c.csv", "99999999999,9,0,0,0,0,bipedThinA,IdleA,3,\n"),
        CAST,
        &["c.csv", "frame"],
        &[],
    ),
    csv_rig_name_of_300_bytes => c(
        "cache CSV",
        "rig name of 300 bytes",
        |d| append(d, "c.csv", &format!("3,9,0,0,0,0,{},IdleA,3,\n", "r".repeat(300))),
        CAST,
        &["c.csv", "rig"],
        &[],
    ),
    // ---------------------------------------------------------- JuPedSim sqlite
    sqlite_file_of_garbage => c(
        "cache sqlite",
        "sqlite file of garbage",
        |d| std::fs::write(d.join("j.sqlite"), b"SQLite format 3\0garbage garbage garbage").unwrap(),
        &["cache", "info", "{d}/j.sqlite"],
        &["j.sqlite"],
        &[],
    ),
    sqlite_no_trajectory_data_table => c(
        "cache sqlite",
        "no trajectory_data table",
        |d| {
            sqlite(d, "CREATE TABLE metadata(key TEXT, value TEXT); INSERT INTO metadata VALUES ('version','1'),('fps','25');")
        },
        &["cache", "info", "{d}/j.sqlite"],
        &["j.sqlite", "trajectory_data"],
        &[],
    ),
    sqlite_one_agent_twice_in_a_frame => c(
        "cache sqlite",
        "one agent twice in a frame",
        |d| sqlite(d, &format!("{JUPEDSIM_OK} INSERT INTO trajectory_data VALUES (1, 1, 0.5, 0.0, 1.0, 0.0);")),
        &["cache", "info", "{d}/j.sqlite"],
        &["j.sqlite", "agent 1"],
        &[],
    ),
    sqlite_nan_position => c(
        "cache sqlite",
        "NaN position",
        |d| sqlite(d, &JUPEDSIM_OK.replace("(1, 1, 0.05,", "(1, 1, 'nan',")),
        &["cache", "info", "{d}/j.sqlite"],
        &["j.sqlite", "pos_x"],
        &[],
    ),
    sqlite_agent_id_2_pow_40 => c(
        "cache sqlite",
        "agent id 2^40",
        |d| sqlite(d, &JUPEDSIM_OK.replace("(1, 1, 0.05,", "(1, 1099511627776, 0.05,")),
        &["cache", "info", "{d}/j.sqlite"],
        &["j.sqlite", "id"],
        &[],
    ),
    // ---------------------------------------------------------- USD crowd import
    usd_usda_of_garbage => c(
        "cache USD",
        "usda of garbage",
        |d| std::fs::write(d.join("u.usda"), "#usda 1.0\ndef Xform \"a\" { this is not usd }\n").unwrap(),
        &["cache", "info", "{d}/u.usda"],
        &["u.usda"],
        &[],
    ),
    usd_usda_without_a_pointinstancer => c(
        "cache USD",
        "usda without a PointInstancer",
        |d| std::fs::write(d.join("u.usda"), format!("{USD_HEAD}def Xform \"World\"\n{{\n}}\n")).unwrap(),
        &["cache", "info", "{d}/u.usda"],
        &["u.usda", "PointInstancer"],
        &[],
    ),
    usd_usdc_header_then_garbage => c(
        "cache USD",
        "usdc header then garbage",
        |d| {
            let mut b = b"PXR-USDC\x00\x08\x00\x00\x00\x00\x00\x00".to_vec();
            b.extend_from_slice(&[0xff; 200]);
            std::fs::write(d.join("u.usdc"), b).unwrap()
        },
        &["cache", "info", "{d}/u.usdc"],
        &["u.usdc"],
        &[],
    ),
    usd_protoindices_shorter_than_positions => c(
        "cache USD",
        "protoIndices shorter than positions",
        |d| {
            std::fs::write(d.join("u.usda"), format!("{}def PointInstancer \"crowd\"\n{{\n    int[] protoIndices.timeSamples = {{ 1: [0] }}\n    point3f[] positions.timeSamples = {{ 1: [(0, 0, 0), (1, 0, 0)] }}\n    int64[] ids.timeSamples = {{ 1: [1, 2] }}\n    rel prototypes = </crowd/Protos/walker>\n    def Scope \"Protos\"\n    {{\n        def Xform \"walker\"\n        {{\n        }}\n    }}\n}}\n", USD_HEAD.replace("endTimeCode = 2", "endTimeCode = 1"))).unwrap()
        },
        &["cache", "info", "{d}/u.usda"],
        &["u.usda", "protoIndices"],
        &[],
    ),
    usd_per_agent_rig_primvar_shorter_than_ids => c(
        "cache USD",
        "per-agent rig primvar shorter than ids",
        |d| {
            std::fs::write(d.join("u.usda"), format!("{}def PointInstancer \"crowd\"\n{{\n    point3f[] positions.timeSamples = {{ 1: [(0, 0, 0), (1, 0, 0)] }}\n    int64[] ids.timeSamples = {{ 1: [1, 2] }}\n    string[] primvars:throng:rig = [\"bipedThinA\"]\n}}\n", USD_HEAD.replace("endTimeCode = 2", "endTimeCode = 1"))).unwrap()
        },
        &["cache", "info", "{d}/u.usda"],
        &["u.usda", "primvars:throng:rig"],
        &[],
    ),
    // ---------------------------------------------------------- glTF meshes and textures
    gltf_accessor_count_10_pow_9_over_a_36_byte_buffer => c(
        "glTF",
        "accessor count 10^9 over a 36-byte buffer",
        |d| tri_gltf(d, "", "", 1_000_000_000),
        CAST,
        &["set.gltf", "accessor"],
        &[],
    ),
    gltf_buffer_file_missing => c(
        "glTF",
        "buffer file missing",
        |d| {
            tri_gltf(d, "", "", 3);
            std::fs::remove_file(d.join("tri.bin")).unwrap()
        },
        CAST,
        &["set.gltf", "tri.bin"],
        &[],
    ),
    gltf_base_colour_texture_file_missing => c(
        "glTF",
        "base colour texture file missing",
        |d| {
            tri_gltf(
                d,
                r#","images":[{"uri":"gone.png"}],"textures":[{"source":0}],"materials":[{"name":"m","pbrMetallicRoughness":{"baseColorTexture":{"index":0}}}]"#,
                r#","material":0"#,
                3,
            )
        },
        CAST,
        &["set.gltf", "gone.png"],
        &[],
    ),
    gltf_base_colour_texture_not_a_png => c(
        "glTF",
        "base colour texture not a PNG",
        |d| {
            std::fs::write(d.join("bad.png"), b"\x89PNG\r\n\x1a\nnot really").unwrap();
            tri_gltf(
                d,
                r#","images":[{"uri":"bad.png"}],"textures":[{"source":0}],"materials":[{"name":"m","pbrMetallicRoughness":{"baseColorTexture":{"index":0}}}]"#,
                r#","material":0"#,
                3,
            )
        },
        CAST,
        &["set.gltf", "bad.png"],
        &[],
    ),
    gltf_material_index_out_of_range => c(
        "glTF",
        "material index out of range",
        |d| tri_gltf(d, "", r#","material":5"#, 3),
        CAST,
        &["set.gltf", "material"],
        &[],
    ),
    // ---------------------------------------------------------- layer manifests
    manifest_of_another_shot => c(
        "manifest",
        "manifest of another shot",
        |d| {
            ok(d, &["layers", "shot.toml"]);
            let t = std::fs::read_to_string(d.join("bad.layers.json")).unwrap();
            std::fs::write(d.join("bad.layers.json"), t.replacen("\"shot\": \"bad\"", "\"shot\": \"other\"", 1))
                .unwrap()
        },
        &["render", "{d}/shot.toml", "--frames", "1001", "--progress", "off", "--out", "{d}/o"],
        &["bad.layers.json", "other"],
        &["o/set/bad.set.1001.exr"],
    ),
    manifest_comp_order_with_an_unknown_layer => c(
        "manifest",
        "comp_order with an unknown layer",
        |d| {
            ok(d, &["layers", "shot.toml"]);
            let t = std::fs::read_to_string(d.join("bad.layers.json")).unwrap();
            std::fs::write(d.join("bad.layers.json"), t.replacen("\"crowd0\"", "\"crowd9\"", 1)).unwrap()
        },
        &["render", "{d}/shot.toml", "--frames", "1001", "--progress", "off", "--out", "{d}/o"],
        &["bad.layers.json", "crowd9"],
        &["o/set/bad.set.1001.exr"],
    ),
    manifest_is_a_json_array => c(
        "manifest",
        "manifest is a JSON array",
        |d| std::fs::write(d.join("bad.layers.json"), "[1, 2, 3]").unwrap(),
        &["render", "{d}/shot.toml", "--frames", "1001", "--progress", "off", "--out", "{d}/o"],
        &["bad.layers.json", "JSON object"],
        &["o"],
    ),
    // ---------------------------------------------------------- EXR inputs
    exr_botinfo_pixel_outside_the_image => c(
        "EXR",
        "botinfo pixel outside the image",
        rendered,
        &["botinfo", "{d}/shot.toml", "--exr", "{d}/r/set/bad.set.1001.exr", "--pixel", "4800,10"],
        &["bad.set.1001.exr", "4800,10", "outside"],
        &[],
    ),
    exr_botinfo_on_an_exr_without_agent_id => c(
        "EXR",
        "botinfo on an EXR without agent.id",
        |_| {},
        &["botinfo", "--exr", "{fixture}/cryptomatte/special_chars.exr", "--pixel", "1,1"],
        &["special_chars.exr", "channel"],
        &[],
    ),
    exr_comp_of_a_layer_renamed_to_another_frame => c(
        "EXR",
        "comp of a layer renamed to another frame",
        |d| {
            rendered(d);
            std::fs::rename(d.join("r/crowd0/bad.crowd0.1001.exr"), d.join("r/crowd0/bad.crowd0.1002.exr"))
                .unwrap();
            for l in ["set", "crowd1"] {
                std::fs::copy(d.join(format!("r/{l}/bad.{l}.1001.exr")), d.join(format!("r/{l}/bad.{l}.1002.exr")))
                    .unwrap();
            }
        },
        &["comp", "{d}/r", "--frame", "1002", "--out", "{d}/c.exr"],
        &["bad.set.1002.exr", "throng/frame", "header says frame 1001"],
        &["c.exr"],
    ),
    exr_comp_of_layers_of_two_sizes => c(
        "EXR",
        "comp of layers of two sizes",
        |d| {
            rendered(d);
            ok(
                d,
                &[
                    "render",
                    "shot.toml",
                    "--layer",
                    "crowd1",
                    "--frames",
                    "1001",
                    "--resolution",
                    "32x18",
                    "--progress",
                    "off",
                    "--out",
                    "r",
                ],
            )
        },
        &["comp", "{d}/r", "--frame", "1001", "--out", "{d}/c.exr"],
        &["bad.crowd1.1001.exr", "32x18"],
        &["c.exr"],
    ),
    exr_comp_layer_that_is_a_png => c(
        "EXR",
        "comp layer that is a PNG",
        |d| {
            rendered(d);
            std::fs::write(d.join("r/crowd0/bad.crowd0.1001.exr"), b"\x89PNG\r\n\x1a\n").unwrap()
        },
        &["comp", "{d}/r", "--frame", "1001", "--out", "{d}/c.exr"],
        &["bad.crowd0.1001.exr"],
        &["c.exr"],
    ),
    // ---------------------------------------------------------- farm plans and options
    farm_plan_chunk_0 => c(
        "farm",
        "plan --chunk 0",
        |_| {},
        &["farm", "plan", "{d}/shot.toml", "--chunk", "0", "--out", "{d}/farm"],
        &["--chunk"],
        &["farm/plan.json"],
    ),
    farm_status_of_a_plan_of_garbage => c(
        "farm",
        "status of a plan of garbage",
        |d| {
            std::fs::create_dir(d.join("farm")).unwrap();
            std::fs::write(d.join("farm/plan.json"), "{\"version\": 1, \"tasks\": 7}").unwrap()
        },
        &["farm", "status", "{d}/farm/plan.json"],
        &["plan.json", "format"],
        &[],
    ),
    farm_submit_workers_0 => c(
        "farm",
        "submit --workers 0",
        planned,
        &["farm", "submit", "{d}/farm/plan.json", "--engine", "local", "--workers", "0"],
        &["--workers"],
        &["farm/o"],
    ),
    farm_run_task_of_an_unknown_task => c(
        "farm",
        "run-task of an unknown task",
        planned,
        &["farm", "run-task", "{d}/farm/plan.json", "render-nothing-9"],
        &["plan.json", "render-nothing-9"],
        &[],
    ),
    farm_plan_version_99 => c(
        "farm",
        "plan version 99",
        |d| {
            planned(d);
            edit(d, "farm/plan.json", "\"version\": 1", "\"version\": 99")
        },
        &["farm", "status", "{d}/farm/plan.json"],
        &["plan.json", "version"],
        &[],
    ),
    // ---------------------------------------------------------- flags of every verb
    flags_sim_of_a_missing_scene => c(
        "flags sim",
        "sim of a missing scene",
        |_| {},
        &["sim", "{d}/nope.toml", "--out", "{d}/s.crowd"],
        &["nope.toml"],
        &["s.crowd"],
    ),
    flags_sim_scene_with_0_fps => c(
        "flags sim",
        "sim scene with 0 fps",
        |d| {
            let t = std::fs::read_to_string(repo_path("demo/sim/demo.toml")).unwrap();
            std::fs::write(d.join("sim.toml"), t.replace("fps = 24.0", "fps = 0.0")).unwrap()
        },
        &["sim", "{d}/sim.toml", "--out", "{d}/s.crowd"],
        &["sim.toml", "fps"],
        &["s.crowd"],
    ),
    flags_cache_convert_fps_0 => c(
        "flags cache",
        "cache convert --fps 0",
        |d| sqlite(d, JUPEDSIM_OK),
        &["cache", "convert", "{d}/j.sqlite", "{d}/j.crowd", "--fps", "0"],
        &["--fps"],
        &["j.crowd"],
    ),
    flags_cache_convert_scale_nan => c(
        "flags cache",
        "cache convert --scale NaN",
        |d| sqlite(d, JUPEDSIM_OK),
        &["cache", "convert", "{d}/j.sqlite", "{d}/j.crowd", "--scale", "NaN"],
        &["--scale"],
        &["j.crowd"],
    ),
    flags_cache_info_columns_with_an_unknown_name => c(
        "flags cache",
        "cache info --columns with an unknown name",
        |_| {},
        &["cache", "info", "{fixture}/tabular/foreign.csv", "--columns", "frame=1,id=2,x=3,y=4,banana=5"],
        &["--columns", "banana"],
        &[],
    ),
    flags_layers_cutoffs_9_3 => c(
        "flags layers",
        "layers --cutoffs 9,3",
        |_| {},
        &["layers", "{d}/shot.toml", "--cutoffs", "9,3", "--out", "{d}/m.json"],
        &["--cutoffs"],
        &["m.json"],
    ),
    flags_layers_lod_px_minus_1 => c(
        "flags layers",
        "layers --lod-px -1",
        |_| {},
        &["layers", "{d}/shot.toml", "--lod-px", "-1", "--out", "{d}/m.json"],
        &["--lod-px"],
        &["m.json"],
    ),
    flags_layers_ref_frame_5000 => c(
        "flags layers",
        "layers --ref-frame 5000",
        |_| {},
        &["layers", "{d}/shot.toml", "--ref-frame", "5000", "--out", "{d}/m.json"],
        &["--ref-frame", "5000"],
        &["m.json"],
    ),
    flags_botinfo_frame_outside_the_shot => c(
        "flags botinfo",
        "botinfo --frame outside the shot",
        |_| {},
        &["botinfo", "{d}/shot.toml", "1", "--frame", "99999"],
        &["99999"],
        &[],
    ),
    flags_botinfo_of_an_agent_not_in_the_cache => c(
        "flags botinfo",
        "botinfo of an agent not in the cache",
        |_| {},
        &["botinfo", "{d}/shot.toml", "77"],
        &["agent 77"],
        &[],
    ),
    flags_export_format_obj => c(
        "flags export",
        "export --format obj",
        |_| {},
        &["export", "{d}/shot.toml", "--frame", "1001", "--format", "obj", "--out", "{d}/x.obj"],
        &["--format"],
        &["x.obj"],
    ),
    flags_export_frame_outside_the_shot => c(
        "flags export",
        "export --frame outside the shot",
        |_| {},
        &["export", "{d}/shot.toml", "--frame", "7", "--out", "{d}/x.glb"],
        &["frame 7"],
        &["x.glb"],
    ),
    flags_render_shutter_0_5_0_2 => c(
        "flags render",
        "render --shutter 0.5,0.2",
        |_| {},
        &[
            "render",
            "{d}/shot.toml",
            "--layer",
            "full",
            "--frames",
            "1001",
            "--shutter",
            "0.5,0.2",
            "--out",
            "{d}/o",
        ],
        &["--shutter"],
        &["o"],
    ),
    flags_render_colourspace_p3 => c(
        "flags render",
        "render --colourspace p3",
        |_| {},
        &["render", "{d}/shot.toml", "--layer", "full", "--colourspace", "p3", "--out", "{d}/o"],
        &["--colourspace", "p3"],
        &["o"],
    ),
    flags_comp_of_a_frame_with_no_layers => c(
        "flags comp",
        "comp of a frame with no layers",
        rendered,
        &["comp", "{d}/r", "--frame", "1003", "--out", "{d}/c.exr"],
        &["1003"],
        &["c.exr"],
    ),
    // ------------------------------------------- issue 49: the CLI's own
    flags_render_threads_4096_without_the_address_space => c(
        "flags render",
        "render --threads 4096 under the 4 GB cap",
        |_| {},
        &["render", "{d}/shot.toml", "--layer", "full", "--frames", "1001", "--threads", "4096", "--out", "{d}/o"],
        &["--threads", "4096"],
        &["o"],
    ),
    flags_render_threads_2048_without_the_address_space => c(
        "flags render",
        "render --threads 2048 under the 4 GB cap",
        |_| {},
        &["render", "{d}/shot.toml", "--layer", "full", "--frames", "1001", "--threads", "2048", "--out", "{d}/o"],
        &["--threads", "2048"],
        &["o"],
    ),
    flags_cast_threads_4096_without_the_address_space => c(
        "flags cast",
        "cast --threads 4096 under the 4 GB cap",
        |_| {},
        &["cast", "{d}/shot.toml", "--threads", "4096"],
        &["--threads"],
        &[],
    ),
    flags_render_passes_misspelt_before_any_file_is_read => c(
        "flags render",
        "render --passes difuse_direct (and no manifest yet)",
        |_| {},
        &["render", "{d}/shot.toml", "--passes", "difuse_direct", "--out", "{d}/o"],
        &["--passes", "difuse_direct", "diffuse_direct"],
        &["o"],
    ),
    flags_botinfo_id_abc => c(
        "flags botinfo",
        "botinfo SHOT abc",
        |_| {},
        &["botinfo", "{d}/shot.toml", "abc"],
        &["abc", "agent id", "whole number"],
        &[],
    ),
    flags_botinfo_an_id_for_the_shot => c(
        "flags botinfo",
        "botinfo 17 (no shot file)",
        |_| {},
        &["botinfo", "17"],
        &["17", "shot file"],
        &[],
    ),
    exr_botinfo_at_the_sky_of_another_shots_exr => c(
        "EXR",
        "botinfo --json at the sky of another shot's EXR",
        |d| {
            rendered(d);
            let other = std::fs::read_to_string(d.join("shot.toml")).unwrap().replacen("name = \"bad\"", "name = \"other\"", 1);
            std::fs::write(d.join("other.toml"), other).unwrap();
        },
        &["botinfo", "{d}/other.toml", "--exr", "{d}/r/set/bad.set.1001.exr", "--pixel", "0,0", "--json"],
        &["bad.set.1001.exr", "`bad`", "throng/shot"],
        &[],
    ),
    strict_cache_convert_warns_before_it_writes => c(
        "flags cache",
        "--strict cache convert of a crowd 90 km wide",
        |d| {
            let csv = std::fs::read_to_string(d.join("c.csv")).unwrap();
            let last: Vec<String> = csv.lines().last().unwrap().split(',').map(str::to_string).collect();
            let far = [&last[..1], &["3".to_string(), "90000".to_string()], &last[3..]].concat().join(",");
            std::fs::write(d.join("c.csv"), format!("{csv}{far}\n")).unwrap();
        },
        &["--strict", "cache", "convert", "{d}/c.csv", "{d}/out.crowd"],
        &["--strict", "wide"],
        &["out.crowd"],
    ),
    flags_demo_spp_0 => c(
        "flags demo",
        "demo --spp 0",
        |_| {},
        &["demo", "--spp", "0", "--out", "{d}/demo"],
        &["--spp"],
        &["demo"],
    ),
    // ---------------------------------------------------------- issue 49
    shot_lights_sun_strength_overflows => c(
        "shot [lights]",
        "sun intensity x colour overflows f32",
        |d| edit(d, "shot.toml", "intensity = 3.0", "intensity = 3e38\ncolor = [2.0, 1.0, 1.0]"),
        CAST,
        &["shot.toml", "`lights.sun`", "overflows"],
        &[],
    ),
    shot_lights_point_strength_overflows => c(
        "shot [lights]",
        "point intensity x 2^exposure overflows f32",
        |d| append(d, "shot.toml", "\n[[lights.point]]\nposition = [0.0, 3.0, 0.0]\nintensity = 1e30\nexposure = 40.0\n"),
        CAST,
        &["shot.toml", "`lights.point[0]`", "intensity x colour x 2^exposure overflows"],
        &[],
    ),
    gltf_texture_declares_100000_squared => c(
        "glTF",
        "texture PNG declaring 100000 x 100000",
        |d| {
            std::fs::write(d.join("huge.png"), png_header(100_000, 100_000)).unwrap();
            tri_gltf(
                d,
                r#","images":[{"uri":"huge.png"}],"textures":[{"source":0}],"materials":[{"name":"m","pbrMetallicRoughness":{"baseColorTexture":{"index":0}}}]"#,
                r#","material":0"#,
                3,
            )
        },
        CAST,
        &["set.gltf", "huge.png", "100000 x 100000"],
        &[],
    ),
    wardrobe_texture_declares_100000_squared => c(
        "wardrobe TOML",
        "a wardrobe material's texture PNG declaring 100000 x 100000",
        |d| {
            use_wardrobe(d);
            std::fs::write(d.join("huge.png"), png_header(100_000, 100_000)).unwrap();
            edit(d, "w.toml", "base_color = [0.6, 0.05, 0.04]", "base_color = [0.6, 0.05, 0.04]\nbase_color_texture = \"huge.png\"");
        },
        CAST,
        &["w.toml", "huge.png", "materials.red.base_color_texture", "100000 x 100000"],
        &[],
    ),
    // A warning under --strict stops a verb before its first output, never after.
    strict_render_resume_judges_every_file_before_it_writes => c(
        "flags render",
        "--strict render --resume beside a frame of other settings",
        |d| {
            ok(d, &["layers", "shot.toml"]);
            ok(d, &["render", "shot.toml", "--frames", "1002", "--spp", "2", "--progress", "off", "--out", "r"]);
        },
        &["--strict", "render", "{d}/shot.toml", "--resume", "--frames", "1001-1002", "--spp", "1", "--progress", "off", "--out", "{d}/r"],
        &["--strict", "resume: re-rendering", "bad.set.1002.exr", "other settings"],
        &["r/set/bad.set.1001.exr", "r/set/bad.set.1001.png"],
    ),
    strict_demo_warns_before_its_first_file => c(
        "flags demo",
        "--strict demo into a folder holding a frame of another render",
        |d| {
            std::fs::create_dir_all(d.join("demo/render/full")).unwrap();
            let exr = repo_path("tests/fixtures/cryptomatte/special_chars.exr");
            std::fs::copy(exr, d.join("demo/render/full/demo.full.1002.exr")).unwrap();
        },
        &["--strict", "demo", "--spp", "1", "--out", "{d}/demo"],
        &["--strict", "will mix two renders", "full"],
        &["demo/demo.layers.json", "demo/layers_map.png", "demo/demo.1024.glb"],
    ),
    strict_export_warns_before_it_writes => c(
        "flags export",
        "--strict export (glTF and USD) of a shot that loads with a warning",
        |d| edit(d, "shot.toml", &demo("rigs/bipedThinA.glb"), &demo("rigs/bipedTallB.glb")),
        &["--strict", "export", "{d}/shot.toml", "--frame", "1001", "--out", "{d}/o.glb"],
        &["rigs.bipedThinA.file", "--strict"],
        &["o.glb"],
    ),
    strict_export_usd_warns_before_it_writes => c(
        "flags export",
        "--strict export --format usd of a shot that loads with a warning",
        |d| edit(d, "shot.toml", &demo("rigs/bipedThinA.glb"), &demo("rigs/bipedTallB.glb")),
        &["--strict", "export", "{d}/shot.toml", "--format", "usd", "--out", "{d}/o.usda"],
        &["rigs.bipedThinA.file", "--strict"],
        &["o.usda"],
    ),
}

/// The first bytes of a PNG declaring `width` x `height` (8-bit RGBA): its
/// signature, IHDR chunk and an empty IDAT, no pixels.
fn png_header(width: u32, height: u32) -> Vec<u8> {
    let mut ihdr = b"IHDR".to_vec();
    ihdr.extend_from_slice(&width.to_be_bytes());
    ihdr.extend_from_slice(&height.to_be_bytes());
    ihdr.extend_from_slice(&[8, 6, 0, 0, 0]);
    let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
    png.extend_from_slice(&13u32.to_be_bytes());
    png.extend_from_slice(&ihdr);
    png.extend_from_slice(&crc32fast::hash(&ihdr).to_be_bytes());
    // An empty IDAT: the header ends where the pixels would start.
    png.extend_from_slice(&[0, 0, 0, 0]);
    png.extend_from_slice(b"IDAT");
    png.extend_from_slice(&crc32fast::hash(b"IDAT").to_be_bytes());
    png
}

/// Every case runs under a 4 GB address-space cap and 120 s of CPU: a
/// runaway ends here, not in the machine's swap.
const HARNESS: Harness = Harness {
    base,
    wrap: "ulimit -v 4000000; ulimit -t 120; exec \"$0\" \"$@\"",
    untouched: false,
    says_on_stdout: false,
};

#[test]
fn the_matrix_keeps_every_case() {
    assert_eq!(cases().len(), 121);
}

/// The table of every case, as issue 15 closed with: written to
/// `target/tmp/bad_input_matrix.md` (and to `$THRONG_MATRIX_MD` when set).
/// It runs every case again, one after another, so a plain `cargo test`
/// leaves it out: `cargo test --test bad_input_matrix -- --ignored`.
#[test]
#[ignore = "runs every case again, to write the table; each case is a test of its own"]
fn the_table_of_every_case() {
    let cases: Vec<_> = cases().into_iter().map(|(test, case)| (test, case, None)).collect();
    let table = Table {
        md: "bad_input_matrix.md",
        expected_column: false,
        summary: |n, kinds, passed, failed| {
            format!(
                "{n} cases ({kinds}): {passed} exit 2 naming file and key or flag, with no panic, no output left and no runaway under a 4 GB cap; {failed} not."
            )
        },
    };
    matrix::write_table(&HARNESS, &table, &cases);
}
