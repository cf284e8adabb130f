//! Tabular trajectory import: presets on small fixtures, resampling to the
//! shot's frame rate, interpolation and gaps, held headings, units,
//! placement, the bounds warning, bad input, and a shot that reads raw data
//! with its rig's stride.

mod common;

use std::f32::consts::PI;
use std::path::{Path, PathBuf};

use common::{fixture, run};
use throng::cache::tabular::{
    self, Column, ColumnChoices, Columns, Delimiter, HeadingFrom, Preset, TabularOptions, Units,
};
use throng::cache::{AgentSample, CrowdCache, Placement, TabularSpec};

fn table(name: &str) -> PathBuf {
    fixture(&format!("tabular/{name}"))
}

fn s(p: &Path) -> &str {
    p.to_str().expect("utf-8 path")
}

fn preset(p: Preset) -> TabularOptions {
    TabularOptions::resolve(&TabularSpec { preset: Some(p), ..Default::default() }, 24.0).unwrap()
}

/// The record of agent `id` at cache frame `frame`, if present.
fn at(crowd: &CrowdCache, frame: i32, id: u32) -> Option<AgentSample> {
    crowd.frames.iter().find(|b| b.frame == frame)?.agents.iter().find(|a| a.id == id).copied()
}

fn frames_of(crowd: &CrowdCache, id: u32) -> Vec<i32> {
    crowd.frames.iter().filter(|b| b.agents.iter().any(|a| a.id == id)).map(|b| b.frame).collect()
}

/// Smallest difference between two angles, degrees.
fn angle_deg(a: f32, b: f32) -> f32 {
    let d = (a - b).rem_euclid(2.0 * PI);
    d.min(2.0 * PI - d).to_degrees()
}

fn foreign_csv() -> TabularOptions {
    let spec = TabularSpec {
        columns: ColumnChoices(vec![
            ("frame".into(), Some(Column::Name("frame".into()))),
            ("id".into(), Some(Column::Name("agent_id".into()))),
            ("x".into(), Some(Column::Name("x".into()))),
            ("y".into(), Some(Column::Name("y".into()))),
            ("z".into(), Some(Column::Name("z".into()))),
            ("heading".into(), Some(Column::Name("heading_radians".into()))),
        ]),
        source_fps: Some(25.0),
        ..Default::default()
    };
    TabularOptions::resolve(&spec, 24.0).unwrap()
}

// --- presets ----------------------------------------------------------------

#[test]
fn petrack_preset_reads_cm_and_frame_rate_from_its_comments() {
    let (crowd, report) = tabular::read(&table("petrack_cm.txt"), &preset(Preset::PeTrack)).unwrap();
    assert_eq!(report.source_fps, Some(25.0));
    assert_eq!(report.units, Some(Units::Cm));
    assert_eq!(report.agents, 3);
    // Agent 1 walks +x at 5 cm per 1/25 s = 1.25 m/s; z up maps y=1 m to world z=-1.
    for k in [0, 7, 24, 48] {
        let a = at(&crowd, k, 1).unwrap();
        let want = 1.25 * k as f32 / 24.0;
        assert!((a.position.x - want).abs() < 1e-4, "frame {k}: x {} want {want}", a.position.x);
        assert!((a.position.z + 1.0).abs() < 1e-5 && a.position.y == 0.0, "{a:?}");
        // Facing +x: heading 90 degrees about +Y.
        assert!(angle_deg(a.heading, PI / 2.0) < 1.0, "frame {k}: heading {}", a.heading);
    }
    // 2 s of data at 25 fps is 48 frames at 24 fps (0..=48).
    assert_eq!(frames_of(&crowd, 1), (0..=48).collect::<Vec<_>>());
}

#[test]
fn eth_preset_interpolates_sparse_samples_and_leaves_long_gaps_empty() {
    let (crowd, report) = tabular::read(&table("eth_obsmat.txt"), &preset(Preset::Eth)).unwrap();
    // Frames 780..840 step 6 at 15 fps: t = 52 s .. 56 s, cache frames 1248..1344.
    assert_eq!(frames_of(&crowd, 1), (1248..=1344).collect::<Vec<_>>());
    // Linear between samples: 1.3 m/s along x from x=2 at t=52 s.
    for k in [1248, 1250, 1261, 1300, 1344] {
        let a = at(&crowd, k, 1).unwrap();
        let want = 2.0 + 1.3 * (k as f32 / 24.0 - 52.0);
        assert!((a.position.x - want).abs() < 1e-3, "frame {k}: x {} want {want}", a.position.x);
    }
    // Heading from the velocity columns: +x.
    assert!(angle_deg(at(&crowd, 1300, 1).unwrap().heading, PI / 2.0) < 1.0);
    // Agent 2: samples at 52.0, 52.4, 52.8 s, then 56.0, 56.4 s: the 3.2 s gap is
    // over the 1 s limit, so the agent is absent there rather than sliding across.
    let f2 = frames_of(&crowd, 2);
    assert_eq!(f2.first(), Some(&1248));
    assert!(f2.contains(&1267) && !f2.contains(&1268) && !f2.contains(&1300) && f2.contains(&1344));
    assert_eq!(report.gaps, 1);
    // With a longer limit the gap is interpolated.
    let long = TabularOptions { max_gap: 4.0, ..preset(Preset::Eth) };
    let (crowd, _) = tabular::read(&table("eth_obsmat.txt"), &long).unwrap();
    assert!(frames_of(&crowd, 2).contains(&1300));
}

#[test]
fn foreign_csv_layout_by_column_names_quoted_and_gzipped() {
    let o = foreign_csv();
    let (plain, _) = tabular::read(&table("foreign.csv"), &o).unwrap();
    let (gz, _) = tabular::read(&table("foreign.csv.gz"), &o).unwrap();
    assert_eq!(plain, gz);
    // Agent 1 walks +y (z up), heading column pi/2 from +x: world -Z, heading pi.
    let a = at(&plain, 12, 1).unwrap();
    assert!(angle_deg(a.heading, PI) < 0.5, "{a:?}");
    assert!((a.position.z + 1.0 * 12.0 / 24.0).abs() < 1e-4, "{a:?}");
    // Quoted "7" is agent 7.
    assert!(at(&plain, 0, 7).is_some());
}

#[test]
fn convert_command_reads_each_preset() {
    let dir = common::tempdir().unwrap();
    for (file, args) in [
        ("petrack_cm.txt", vec!["--preset", "petrack"]),
        ("eth_obsmat.txt", vec!["--preset", "eth"]),
        (
            "foreign.csv.gz",
            vec!["--columns", "frame=frame,id=agent_id,x=x,y=y,heading=heading_radians", "--source-fps", "25"],
        ),
    ] {
        let out = dir.path().join(format!("{file}.crowd"));
        let input = table(file);
        let mut argv = vec!["cache", "convert", s(&input), s(&out)];
        argv.extend(args);
        let (code, stdout, stderr) = run(&argv);
        assert_eq!(code, 0, "{file}: {stderr}");
        assert!(stdout.contains("resampled to 24 fps"), "{stdout}");
        assert!(!throng::cache::read(&out).unwrap().frames.is_empty());
    }
    // throng's own CSV still reads without any flag.
    let csv = dir.path().join("own.csv");
    let (code, _, err) = run(&["cache", "convert", s(&dir.path().join("petrack_cm.txt.crowd")), s(&csv)]);
    assert_eq!(code, 0, "{err}");
    let (code, _, err) = run(&["cache", "info", s(&csv)]);
    assert_eq!(code, 0, "{err}");
}

// --- time ---------------------------------------------------------------------

#[test]
fn resampling_25_fps_to_24_keeps_true_speed() {
    // A straight walk at 1.5 m/s sampled at 25 fps.
    let mut text = String::from("t_frame,id,x,y\n");
    for f in 0..=100 {
        text += &format!("{f},4,{},0\n", 1.5 * f as f64 / 25.0);
    }
    let o = TabularOptions {
        columns: Columns {
            frame: Some(Column::Position(1)),
            id: Some(Column::Position(2)),
            x: Some(Column::Position(3)),
            y: Some(Column::Position(4)),
            ..Default::default()
        },
        source_fps: Some(25.0),
        ..Default::default()
    };
    let (crowd, _) = tabular::parse_str(Path::new("walk.csv"), &text, &o).unwrap();
    // 4 s: shot frames 0..=96, each at x = 1.5 * k / 24 (not k / 25).
    assert_eq!(frames_of(&crowd, 4), (0..=96).collect::<Vec<_>>());
    for k in [1, 13, 50, 96] {
        let x = at(&crowd, k, 4).unwrap().position.x;
        assert!((x - 1.5 * k as f32 / 24.0).abs() < 1e-4, "frame {k}: {x}");
    }
    // The same data read with a time column in seconds gives the same crowd.
    let mut timed = String::from("time,id,x,y\n");
    for f in 0..=100 {
        timed += &format!("{},4,{},0\n", f as f64 / 25.0, 1.5 * f as f64 / 25.0);
    }
    let ot = TabularOptions {
        columns: Columns { frame: None, time: Some(Column::Name("time".into())), ..o.columns.clone() },
        source_fps: None,
        ..o.clone()
    };
    let (by_time, _) = tabular::parse_str(Path::new("walk.csv"), &timed, &ot).unwrap();
    assert_eq!(frames_of(&by_time, 4), frames_of(&crowd, 4));
    assert!((at(&by_time, 50, 4).unwrap().position.x - at(&crowd, 50, 4).unwrap().position.x).abs() < 1e-5);
}

// --- heading ------------------------------------------------------------------

fn walk_then_jitter(hold_speed: f32) -> CrowdCache {
    // 1 s walking +x at 1.2 m/s, then 5 s standing with +-2 cm tracking noise.
    let mut text = String::new();
    let mut seed = 12345u32;
    let mut x = 0.0f64;
    for f in 0..150 {
        if f < 25 {
            x = 1.2 * f as f64 / 25.0;
            text += &format!("{f} 9 {x} 0\n");
        } else {
            seed = seed.wrapping_mul(1664525).wrapping_add(1013904223);
            let n1 = (seed >> 8) as f64 / (1u32 << 24) as f64 - 0.5;
            seed = seed.wrapping_mul(1664525).wrapping_add(1013904223);
            let n2 = (seed >> 8) as f64 / (1u32 << 24) as f64 - 0.5;
            text += &format!("{f} 9 {} {}\n", x + 0.04 * n1, 0.04 * n2);
        }
    }
    let o = TabularOptions {
        delimiter: Delimiter::Whitespace,
        header: false,
        columns: Columns {
            frame: Some(Column::Position(1)),
            id: Some(Column::Position(2)),
            x: Some(Column::Position(3)),
            y: Some(Column::Position(4)),
            ..Default::default()
        },
        source_fps: Some(25.0),
        hold_speed,
        idle_cycle: Some("IdleA".into()),
        ..Default::default()
    };
    tabular::parse_str(Path::new("still.txt"), &text, &o).unwrap().0
}

#[test]
fn heading_is_held_while_a_jittering_agent_stands_still() {
    let crowd = walk_then_jitter(0.25);
    let standing: Vec<AgentSample> = crowd.frames.iter().filter(|b| b.frame > 36).map(|b| b.agents[0]).collect();
    assert!(standing.len() > 100);
    for a in &standing {
        assert!(angle_deg(a.heading, PI / 2.0) < 3.0, "heading {} deg", a.heading.to_degrees());
    }
    // Standing agents play the idle cycle; the walk before played the walk.
    let idle = crowd.cycles.iter().position(|c| c == "IdleA").unwrap() as u16;
    assert!(standing.iter().all(|a| a.cycle == idle));
    assert_ne!(at(&crowd, 10, 9).unwrap().cycle, idle);
    // Without the hold, the same data spins: the test can fail.
    let spun = walk_then_jitter(0.0);
    let worst = spun.frames.iter().filter(|b| b.frame > 36).map(|b| angle_deg(b.agents[0].heading, PI / 2.0));
    assert!(worst.fold(0.0f32, f32::max) > 45.0);
}

#[test]
fn heading_from_motion_when_no_column_and_forced_motion_ignores_a_column() {
    let mut o = foreign_csv();
    o.heading = HeadingFrom::Motion;
    let (crowd, _) = tabular::read(&table("foreign.csv"), &o).unwrap();
    // Agent 7 walks +x; its heading column says 0 (+x in a z-up source), i.e. 90 degrees.
    assert!(angle_deg(at(&crowd, 10, 7).unwrap().heading, PI / 2.0) < 1.0);
    // Agent 1 walks source +y = world -Z: heading pi, from motion alone.
    assert!(angle_deg(at(&crowd, 10, 1).unwrap().heading, PI) < 1.0);
}

// --- units and placement --------------------------------------------------------

#[test]
fn units_axes_and_placement() {
    let base = preset(Preset::PeTrack);
    let (cm, _) = tabular::read(&table("petrack_cm.txt"), &base).unwrap();
    // Forcing metres reads the cm numbers as metres: 100 times as far.
    let (m, _) =
        tabular::read(&table("petrack_cm.txt"), &TabularOptions { units: Some(Units::M), ..base.clone() }).unwrap();
    let (a, b) = (at(&cm, 24, 1).unwrap(), at(&m, 24, 1).unwrap());
    assert!((b.position.x - 100.0 * a.position.x).abs() < 1e-2);
    // Left-handed sources mirror: y=1 m lands at world z=+1.
    let left = TabularOptions { handedness: tabular::Handedness::Left, ..base.clone() };
    assert!(
        (at(&tabular::read(&table("petrack_cm.txt"), &left).unwrap().0, 24, 1).unwrap().position.z - 1.0).abs() < 1e-5
    );
    // Placement: scale 2, rotate 90 degrees about +Y, then translate.
    let placement = Placement { translate: glam::Vec3::new(10.0, 0.5, -3.0), rotate: 90.0, scale: 2.0 };
    let placed_o = TabularOptions { placement, ..base.clone() };
    let (placed, _) = tabular::read(&table("petrack_cm.txt"), &placed_o).unwrap();
    let p = at(&placed, 24, 1).unwrap();
    let want = glam::Quat::from_rotation_y(PI / 2.0) * (a.position * 2.0) + placement.translate;
    assert!((p.position - want).length() < 1e-4, "{} vs {want}", p.position);
    assert!(angle_deg(p.heading, a.heading + PI / 2.0) < 0.5);
    // Distance walked doubles, so the cycle advances twice as fast per frame.
    let adv = |c: &CrowdCache| {
        let (x, y) = (at(c, 10, 1).unwrap().cycle_frame, at(c, 11, 1).unwrap().cycle_frame);
        (y - x).rem_euclid(32.0)
    };
    assert!((adv(&placed) - 2.0 * adv(&cm)).abs() < 1e-3);
}

#[test]
fn bounds_warning_for_the_wrong_units() {
    // Two people 30 m apart, written in centimetres.
    let dir = common::tempdir().unwrap();
    let p = dir.path().join("lab.txt");
    let mut text = String::from("# id frame x/cm y/cm\n");
    for f in 0..10 {
        text += &format!("1 {f} {} 0\n2 {f} 3000 {}\n", 10 * f, 10 * f);
    }
    std::fs::write(&p, text).unwrap();
    let (code, _, stderr) = run(&["cache", "info", s(&p), "--preset", "petrack", "--source-fps", "25", "--units", "m"]);
    assert_eq!(code, 0, "{stderr}");
    assert!(stderr.contains("warning") && stderr.contains("units look wrong"), "{stderr}");
    // Read in its own units (from the comment), it is 30 m wide: no warning.
    let (code, stdout, stderr) = run(&["cache", "info", s(&p), "--preset", "petrack", "--source-fps", "25", "--json"]);
    assert_eq!(code, 0, "{stderr}");
    assert!(!stderr.contains("warning"), "{stderr}");
    let v: serde_json::Value = serde_json::from_str(&stdout).unwrap();
    assert_eq!(v["format"], "table");
    assert_eq!(v["warnings"].as_array().map(Vec::len), Some(0));
    assert!((v["bounds"]["max"][0].as_f64().unwrap() - 30.0).abs() < 1e-3);
}

// --- bad input -------------------------------------------------------------------

fn bad(body: &str, flags: &[&str]) -> String {
    let dir = common::tempdir().unwrap();
    let p = dir.path().join("bad.csv");
    std::fs::write(&p, body).unwrap();
    let out = dir.path().join("out.crowd");
    let mut argv = vec!["cache", "convert", s(&p), s(&out)];
    argv.extend(flags);
    let (code, _, stderr) = run(&argv);
    assert_eq!(code, 2, "{stderr}");
    assert!(!out.exists());
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 1, "no temporary file left");
    assert!(!stderr.contains("panicked"), "{stderr}");
    stderr
}

fn assert_has(msg: &str, parts: &[&str]) {
    for p in parts {
        assert!(msg.contains(p), "message {msg:?} lacks {p:?}");
    }
}

#[test]
fn bad_tables_name_line_column_and_agent() {
    let named = ["--columns", "frame=frame,id=agent,x=x,y=y", "--source-fps", "25"];
    let e = bad("frame,agent_id,x,y\n0,1,0,0\n", &named);
    assert_has(&e, &["no column `agent`", "columns found are: frame, agent_id, x, y", "field `id`"]);
    let e = bad("frame,agent,x,y\n0,1,0,0\n1,1,zz,0\n", &named);
    assert_has(&e, &["bad.csv:3", "column 3 (x)", "`zz`", "agent 1"]);
    let e = bad("frame,agent,x,y\n0,1.5,0,0\n", &named);
    assert_has(&e, &["bad.csv:2", "agent id `1.5` is not an integer"]);
    let e = bad("frame,agent,x,y\n0,1,0,0\n0,2,0,0\n0,1,1,0\n", &named);
    assert_has(&e, &["bad.csv:4", "agent 1", "appears twice at frame 0", "lines 2 and 4"]);
    let e = bad("frame,agent,x,y\n5,1,0,0\n4,1,0,0\n", &named);
    assert_has(&e, &["bad.csv:3", "agent 1", "frame 4 follows frame 5", "forward in time"]);
    let e = bad("frame,agent,x\n0,1,0\n", &["--columns", "frame=1,id=2,x=3,y=4", "--source-fps", "25"]);
    assert_has(&e, &["bad.csv:2", "column 4 (y): missing"]);
    let e = bad("frame,agent,x,y\n0,1,0,0\n", &["--columns", "frame=1,id=2,x=3,y=4"]);
    assert_has(&e, &["source_fps"]);
    let e = bad("a,b\n", &["--columns", "id=1,x=2"]);
    assert_has(&e, &["--columns", "no `y` column"]);
    let e = bad("frame,id\n", &["--preset", "petrack", "--units", "parsecs"]);
    assert_has(&e, &["parsecs"]);
}

// --- a shot reading raw data ------------------------------------------------------

#[test]
fn shot_reading_raw_data_walks_at_its_rigs_stride() {
    let dir = common::tempdir().unwrap();
    let rig = common::fixture("rig_small.gltf");
    let shot_path = dir.path().join("shot.toml");
    std::fs::write(
        &shot_path,
        format!(
            r#"version = 1
name = "raw"
[frames]
start = 1
end = 48
fps = 24.0
[cache]
path = "{}"
preset = "petrack"
rig = "rigSmall"
idle_cycle = "IdleA"
translate = [5.0, 0.0, 0.0]
[rigs.rigSmall]
file = "{}"
[camera]
[[camera.keys]]
frame = 1
position = [0.0, 1.7, 20.0]
aim = [0.0, 1.0, 0.0]
focal_length = 35.0
"#,
            table("petrack_cm.txt").display(),
            rig.display()
        ),
    )
    .unwrap();
    let shot = throng::shot::Shot::load(&shot_path).unwrap();
    let reader = throng::casting::shot_cache::open(&shot).unwrap();
    let crowd = reader.read_all().unwrap();
    // rig_small's WalkA: 1.4 m in 1 s = 24 frames (the default would be 32 frames).
    let (a, b) = (at(&crowd, 10, 1).unwrap(), at(&crowd, 20, 1).unwrap());
    let walked = b.position.x - a.position.x;
    let advance = (b.cycle_frame - a.cycle_frame).rem_euclid(24.0);
    assert!((advance - walked / 1.4 * 24.0).abs() < 1e-3, "advance {advance} for {walked} m");
    assert!(crowd.frames.iter().flat_map(|f| &f.agents).all(|a| a.cycle_frame < 48.0));
    // Placed where the shot says.
    assert!((at(&crowd, 0, 1).unwrap().position.x - 5.0).abs() < 1e-5);
    // The standing agent 3 plays IdleA (2 s = 48 frames).
    let idle = crowd.cycles.iter().position(|c| c == "IdleA").unwrap() as u16;
    assert_eq!(at(&crowd, 30, 3).unwrap().cycle, idle);
    // A bad key names the shot line's key.
    let text = std::fs::read_to_string(&shot_path).unwrap().replace("preset = \"petrack\"", "preset = \"petrak\"");
    std::fs::write(&shot_path, text).unwrap();
    let e = throng::shot::Shot::load(&shot_path).unwrap_err().to_string();
    assert!(e.contains("petrak") && e.contains("shot.toml"), "{e}");
}

#[test]
fn shot_reading_raw_data_walks_at_a_skinned_rigs_stride() {
    // The demo walker: a skinned character whose Walk clip moves its `hips`
    // joint 1.4 m in 32 frames.
    let dir = common::tempdir().unwrap();
    let shot_path = dir.path().join("shot.toml");
    std::fs::write(
        &shot_path,
        format!(
            r#"version = 1
name = "raw"
[frames]
start = 1
end = 48
fps = 24.0
[cache]
path = "{}"
preset = "petrack"
rig = "walker"
cycle = "WalkA"
[rigs.walker]
file = "{}"
cycles = {{ WalkA = "Walk", IdleA = "Idle" }}
root = "hips"
[camera]
[[camera.keys]]
frame = 1
position = [0.0, 1.7, 20.0]
aim = [0.0, 1.0, 0.0]
focal_length = 35.0
"#,
            table("petrack_cm.txt").display(),
            common::repo_path("demo/rigs/walker.glb").display()
        ),
    )
    .unwrap();
    let shot = throng::shot::Shot::load(&shot_path).unwrap();
    let crowd = throng::casting::shot_cache::open(&shot).unwrap().read_all().unwrap();
    let (a, b) = (at(&crowd, 10, 1).unwrap(), at(&crowd, 20, 1).unwrap());
    let walked = (b.position - a.position).length();
    let advance = (b.cycle_frame - a.cycle_frame).rem_euclid(32.0);
    assert!(walked > 0.1, "agent 1 walks ({walked} m)");
    assert!((advance - walked / 1.4 * 32.0).abs() < 0.05, "advance {advance} frames for {walked} m");
}

/// `queue_m.txt` (a slow queue in metres) with every number after the
/// frame scaled by `k`, as another recording of the same crowd.
fn scaled_queue(dir: &Path, name: &str, k: f64) -> PathBuf {
    let text = std::fs::read_to_string(table("queue_m.txt")).unwrap();
    let out: Vec<String> = text
        .lines()
        .map(|l| match l.starts_with('#') {
            true => l.to_string(),
            false => {
                let w: Vec<&str> = l.split_whitespace().collect();
                let xs = w[2..].iter().map(|v| format!("{:.3}", v.parse::<f64>().unwrap() * k));
                w[..2].iter().map(|v| v.to_string()).chain(xs).collect::<Vec<_>>().join(" ")
            }
        })
        .collect();
    let p = dir.join(name);
    std::fs::write(&p, out.join("\n") + "\n").unwrap();
    p
}

/// Issue 49 item A: units are judged from speed, spacing, body distances
/// and path lengths together, and a header naming its unit is believed. A
/// slow queue in metres (0.13-0.17 m/s, 0.5 m apart) is no warning, not even
/// under --strict; the same crowd x100 is centimetres, x1000 millimetres
/// (warned, naming the unit), x3.28084 feet (named, too close to metres to
/// warn); `queue_cm.txt`, whose header says `units: cm`, is read in cm.
#[test]
fn units_are_judged_from_speed_spacing_and_the_header() {
    let dir = common::tempdir().unwrap();
    let info = |p: &Path, strict: bool| {
        let mut argv = vec!["cache", "info", s(p), "--preset", "petrack", "--json"];
        if strict {
            argv.insert(0, "--strict");
        }
        let (code, out, err) = run(&argv);
        let v: serde_json::Value = serde_json::from_str(&out).unwrap_or_default();
        (code, v, err)
    };
    let (code, v, err) = info(&table("queue_m.txt"), true);
    assert_eq!(code, 0, "a slow queue in metres is no warning under --strict: {err}");
    assert_eq!(v["units"]["likeliest"], "as read", "{v}");
    assert_eq!(v["warnings"].as_array().map(Vec::len), Some(0));
    for (k, unit) in [(100.0, "cm"), (1000.0, "mm")] {
        let p = scaled_queue(dir.path(), &format!("q{k}.txt"), k);
        let (code, v, err) = info(&p, false);
        assert_eq!(code, 0, "{err}");
        let likeliest = v["units"]["likeliest"].as_str().unwrap().to_string();
        assert!(likeliest.starts_with(unit), "x{k}: {likeliest}");
        assert!(err.contains("units look wrong") && err.contains(&format!("set units = \"{unit}\"")), "{err}");
        assert!(!err.contains("feet"), "{err}");
    }
    let ft = scaled_queue(dir.path(), "qft.txt", 3.28084);
    let (code, v, err) = info(&ft, false);
    assert_eq!((code, v["units"]["likeliest"].as_str()), (0, Some("ft")), "{v}\n{err}");
    let (code, v, err) = info(&table("queue_cm.txt"), true);
    assert_eq!(code, 0, "the header's cm is believed: {err}");
    assert_eq!(v["units"]["likeliest"], "as read");
    assert!(v["bounds"]["max"][0].as_f64().unwrap() < 1.0, "read in cm: {}", v["bounds"]);
}
