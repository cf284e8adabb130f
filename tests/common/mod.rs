//! What every integration test shares: the `throng` binary runner and the
//! paths of fixtures, the demo and the shared assets. Each test crate uses
//! only part of it.
#![allow(dead_code)]

pub mod matrix;
pub mod stack_stats;

use std::ffi::OsStr;
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// The `throng` binary of the workspace's CLI crate (cli/). It lives beside
/// the test executables' `deps/` folder; `cargo test` at the workspace root
/// builds it (the CLI crate has integration tests of its own, which makes
/// cargo build its binary), `cargo test -p throng` alone does not.
pub fn bin() -> PathBuf {
    let exe = std::env::current_exe().expect("the test executable's path");
    let dir = exe.parent().and_then(Path::parent).expect("target/<profile>/deps");
    let bin = dir.join(format!("throng{}", std::env::consts::EXE_SUFFIX));
    assert!(
        bin.is_file(),
        "{} is missing: run the tests from the workspace root (`cargo test --locked`), which builds the CLI",
        bin.display()
    );
    bin
}

/// Runs the built `throng` binary with `args`.
pub fn throng<S: AsRef<OsStr>>(args: &[S]) -> Output {
    Command::new(bin()).args(args).output().expect("run the throng binary")
}

/// Runs `throng` and gives (exit code, stdout, stderr); -1 when killed by a signal.
pub fn run<S: AsRef<OsStr>>(args: &[S]) -> (i32, String, String) {
    let out = throng(args);
    (out.status.code().unwrap_or(-1), text(&out.stdout), text(&out.stderr))
}

/// Output bytes as text.
pub fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// A path inside the repository.
pub fn repo_path(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(rel)
}

/// The bundled demo shot.
pub fn demo_shot() -> PathBuf {
    repo_path("demo/shot.toml")
}

/// A file under tests/fixtures.
pub fn fixture(rel: &str) -> PathBuf {
    repo_path("tests/fixtures").join(rel)
}

/// A file under the shared assets, `../shared/assets` beside the repository
/// root. Panics with what is missing, so no test passes without its input.
pub fn shared_asset(rel: &str) -> PathBuf {
    let root = repo_path("../shared");
    assert!(
        root.is_dir(),
        "the shared assets are missing: expected {} (../shared beside the repository root, as CI lays it out)",
        root.display()
    );
    let path = root.join("assets").join(rel);
    assert!(path.exists(), "shared asset {} is missing", path.display());
    path
}

/// A shot of Khronos RiggedFigure agents (shared assets) written into `dir`:
/// `rows` of (frame, id, x, z, heading, cycle frame) on frames 1020-1026,
/// `extra_rig` added to its `[rigs.figure]` table. Used by the skinning and
/// golden tests.
pub fn figure_shot(dir: &Path, rows: &[(i32, u32, f32, f32, f32, f32)], extra_rig: &str) -> PathBuf {
    let figure = shared_asset("gltf/RiggedFigure/RiggedFigure.gltf");
    let mut csv = String::from("frame,id,x,y,z,heading,rig,cycle,cycle_frame,flags\n");
    for &(f, id, x, z, h, cf) in rows {
        csv.push_str(&format!("{f},{id},{x:?},0,{z:?},{h:?},figure,Walk,{cf:?},\n"));
    }
    std::fs::write(dir.join("c.csv"), csv).unwrap();
    let shot = format!(
        r##"version = 1
name = "figure"
seed = 11
wardrobes = []
[frames]
start = 1020
end = 1026
fps = 24.0
# Callers' rows may cover only some of the frames: those render no agents.
outside_cache = "empty"
[cache]
path = "c.csv"
[rigs.figure]
file = "{}"
cycles = {{ Walk = "#0" }}
{extra_rig}
[camera]
sensor_width = 36.0
[[camera.keys]]
frame = 1020
position = [0.0, 1.1, 5.5]
aim = [0.0, 0.75, 0.0]
focal_length = 35.0
[lights.sun]
direction = [-0.6, 0.5, 0.6]
angular_diameter = 0.53
intensity = 3.0
color = [1.0, 0.95, 0.88]
[lights.sky]
color = [0.3, 0.38, 0.5]
intensity = 1.0
[layers]
split = "count"
count = 2
[render]
resolution = [160, 90]
spp = 8
max_bounces = 3
"##,
        figure.display()
    );
    let path = dir.join("figure.toml");
    std::fs::write(&path, shot).unwrap();
    path
}

/// A small shot of the demo's assets, the base of the bad-input and colour
/// tests: `shot.toml` on the demo's `bipedThinA` rig (scheme `HighEnd` of the
/// robots wardrobe) and set, cache `c.csv` read at shot frame - 1000, one
/// camera key, two crowd layers, a 48x27 render. What differs between its
/// users are the fields.
pub struct DemoShot<'a> {
    /// The shot's name (the stem of every output file).
    pub name: &'a str,
    /// The shot's first and last frame.
    pub frames: (i64, i64),
    /// More keys of `[frames]`.
    pub frames_extra: &'a str,
    /// `[lights.*]` tables (none: the render's default light).
    pub lights: &'a str,
    /// Samples per pixel.
    pub spp: u32,
    /// Appended at the end: more `[render]` keys, or more tables.
    pub extra: &'a str,
}

impl Default for DemoShot<'_> {
    fn default() -> Self {
        DemoShot { name: "bad", frames: (1001, 1003), frames_extra: "", lights: "", spp: 1, extra: "" }
    }
}

impl DemoShot<'_> {
    /// The shot file's text.
    pub fn text(&self) -> String {
        let demo = repo_path("demo");
        format!(
            r#"version = 1
name = "{name}"
seed = 5
wardrobes = ["{wardrobe}"]

[frames]
start = {start}
end = {end}
fps = 24.0
{frames_extra}

[cache]
path = "c.csv"
frame_offset = -1000

[rigs.bipedThinA]
file = "{demo}/rigs/bipedThinA.glb"
schemes = {{ HighEnd = 1.0 }}

[set]
file = "{demo}/set/set.glb"

[camera]
[[camera.keys]]
frame = 1001
position = [0.0, 1.6, 9.0]
aim = [0.0, 0.9, 0.0]
focal_length = 35.0
{lights}
[layers]
count = 2

[render]
resolution = [48, 27]
spp = {spp}
{extra}
"#,
            name = self.name,
            wardrobe = repo_path("wardrobes/robots.toml").display(),
            start = self.frames.0,
            end = self.frames.1,
            frames_extra = self.frames_extra,
            demo = demo.display(),
            lights = self.lights,
            spp = self.spp,
            extra = self.extra,
        )
    }

    /// Writes `dir/shot.toml` and its cache `dir/c.csv` of idle robots at
    /// `rows` (cache frame, id, x, z); gives the shot's path.
    pub fn write(&self, dir: &Path, rows: &[(i32, u64, f32, f32)]) -> PathBuf {
        let mut csv = String::from("frame,id,x,y,z,heading,rig,cycle,cycle_frame,flags\n");
        for &(f, id, x, z) in rows {
            csv.push_str(&format!("{f},{id},{x:?},0,{z:?},0,bipedThinA,IdleA,3,\n"));
        }
        std::fs::write(dir.join("c.csv"), csv).unwrap();
        let path = dir.join("shot.toml");
        std::fs::write(&path, self.text()).unwrap();
        path
    }
}

/// Two idle robots, at (-0.8, 1.0) and (0.9, -1.0), on every cache frame of
/// `frames`: the crowd of a [`DemoShot`].
pub fn two_robots(frames: std::ops::RangeInclusive<i32>) -> Vec<(i32, u64, f32, f32)> {
    frames.flat_map(|f| [(f, 1, -0.8, 1.0), (f, 2, 0.9, -1.0)]).collect()
}

/// A one-scheme wardrobe (`Only`) of one part from the demo's heads, for the
/// bad-input tests: `materials` (TOML tables), then the part's `part` keys.
pub fn heads_wardrobe(materials: &str, part: &str) -> String {
    format!(
        r#"version = 1
name = "w"
{materials}
[schemes.Only]
[[schemes.Only.parts]]
file = "{heads}"
mesh = "head_sphere"
{part}
"#,
        heads = repo_path("demo/parts/heads.glb").display()
    )
}

/// Makes the [`DemoShot`] at `shot` wear `wardrobe` (a path, as the shot
/// names it) and its scheme `Only` (a [`heads_wardrobe`]) instead of the robots.
pub fn wear_heads(shot: &Path, wardrobe: &str) {
    let text = std::fs::read_to_string(shot).unwrap();
    let robots = repo_path("wardrobes/robots.toml").display().to_string();
    assert!(text.contains(&robots) && text.contains("HighEnd = 1.0"), "{} wears no robots", shot.display());
    std::fs::write(shot, text.replacen(&robots, wardrobe, 1).replacen("HighEnd = 1.0", "Only = 1.0", 1)).unwrap();
}

/// Five agents on every frame 1020-1026, spread across the frame, at
/// different phases of the walk.
pub fn five_walkers() -> Vec<(i32, u32, f32, f32, f32, f32)> {
    let mut rows = Vec::new();
    for f in 1020..=1026 {
        for i in 0..5u32 {
            let phase = (f - 1020) as f32 + i as f32 * 5.0;
            rows.push((f, i + 1, (i as f32 - 2.0) * 0.9, -(i as f32) * 0.7, 0.4 * i as f32 - 0.8, phase));
        }
    }
    rows
}

/// A fresh folder under the system's temporary folder, removed (with all it
/// holds) when dropped: what the tests write goes here. Our own, so the tests
/// need no dev-dependency whose features would unify differently from the
/// normal build's and make `cargo test` recompile what `cargo build` built.
pub struct TempDir(PathBuf);

impl TempDir {
    /// The folder.
    pub fn path(&self) -> &Path {
        &self.0
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// Makes a [`TempDir`]: unique by process id, a per-process counter and the clock.
pub fn tempdir() -> std::io::Result<TempDir> {
    use std::sync::atomic::{AtomicU64, Ordering};
    static NEXT: AtomicU64 = AtomicU64::new(0);
    let nanos = std::time::SystemTime::now().duration_since(std::time::UNIX_EPOCH).map_or(0, |d| d.subsec_nanos());
    let name = format!("throng-test-{}-{}-{nanos}", std::process::id(), NEXT.fetch_add(1, Ordering::Relaxed));
    let dir = std::env::temp_dir().join(name);
    std::fs::create_dir(&dir)?;
    Ok(TempDir(dir))
}

/// A box from `lo` to `hi` with flat normals.
pub fn cuboid(lo: glam::Vec3, hi: glam::Vec3) -> throng::export::glb::MeshData {
    let mut m = throng::export::glb::MeshData::default();
    for (n, u, v) in [
        (glam::Vec3::X, glam::Vec3::Y, glam::Vec3::Z),
        (glam::Vec3::NEG_X, glam::Vec3::Z, glam::Vec3::Y),
        (glam::Vec3::Y, glam::Vec3::Z, glam::Vec3::X),
        (glam::Vec3::NEG_Y, glam::Vec3::X, glam::Vec3::Z),
        (glam::Vec3::Z, glam::Vec3::X, glam::Vec3::Y),
        (glam::Vec3::NEG_Z, glam::Vec3::Y, glam::Vec3::X),
    ] {
        let base = m.positions.len() as u32;
        let (c, h) = ((lo + hi) / 2.0, (hi - lo) / 2.0);
        for (a, b) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
            m.positions.push((c + (n + u * a + v * b) * h).to_array());
            m.normals.push(n.to_array());
        }
        m.indices.extend([base, base + 1, base + 2, base, base + 2, base + 3]);
    }
    m
}

/// Whether Open Image Denoise is here; without it a test returns early (and
/// says so), or fails under `THRONG_REQUIRE_OIDN=1` (CI installs it).
pub fn oidn_available(test: &str) -> bool {
    match throng_oidn::Library::find(None) {
        Ok(_) => true,
        Err(e) if std::env::var("THRONG_REQUIRE_OIDN").as_deref() == Ok("1") => {
            panic!("{test}: THRONG_REQUIRE_OIDN=1 but {e}")
        }
        Err(e) => {
            // Straight to stderr: cargo's capture would hide a skip.
            use std::io::Write;
            let _ = writeln!(std::io::stderr(), "SKIPPED {test}: {e}");
            false
        }
    }
}

/// A `throng review` server of `shot` in this process, serving on a thread
/// of its own: its address and the stopper that ends it.
pub fn start_review(shot: &Path, options: throng::review::ReviewOptions) -> (String, throng::review::Stopper) {
    let (tx, rx) = std::sync::mpsc::channel();
    let shot = shot.to_path_buf();
    std::thread::spawn(move || {
        let crowd = throng::casting::ShotCrowd::load(&shot).unwrap();
        let review = throng::review::Review::open(crowd, &shot, &options).unwrap();
        tx.send((review.addr().to_string(), review.stopper())).unwrap();
        review.serve();
    });
    rx.recv_timeout(std::time::Duration::from_secs(120)).expect("the review server started")
}

/// An HTTP answer as [`request`] read it.
pub struct Reply {
    pub status: u16,
    /// Lower-case names.
    pub headers: std::collections::BTreeMap<String, String>,
    /// Dechunked.
    pub body: Vec<u8>,
}

impl Reply {
    pub fn json(&self) -> serde_json::Value {
        serde_json::from_slice(&self.body)
            .unwrap_or_else(|e| panic!("not JSON ({e}): {}", String::from_utf8_lossy(&self.body)))
    }
    pub fn text(&self) -> String {
        String::from_utf8_lossy(&self.body).into_owned()
    }
    pub fn png(&self) -> image::DynamicImage {
        assert_eq!(self.status, 200, "{}", self.text());
        assert_eq!(self.headers.get("content-type").map(String::as_str), Some("image/png"));
        image::load_from_memory(&self.body).expect("a PNG")
    }
}

/// One HTTP request to a test server: `head` (request line and headers,
/// without the blank line) as written, `Connection: close`, then `body`;
/// the whole answer read.
pub fn request(addr: &str, head: &str, body: &[u8]) -> Reply {
    let mut stream = std::net::TcpStream::connect(addr).unwrap();
    stream.set_read_timeout(Some(std::time::Duration::from_secs(120))).unwrap();
    stream.write_all(format!("{head}\r\nConnection: close\r\n\r\n").as_bytes()).unwrap();
    stream.write_all(body).unwrap();
    let mut bytes = Vec::new();
    stream.read_to_end(&mut bytes).unwrap();
    let split = bytes.windows(4).position(|w| w == b"\r\n\r\n").expect("a complete HTTP answer");
    let head = String::from_utf8_lossy(&bytes[..split]).into_owned();
    let mut lines = head.lines();
    let status = lines.next().unwrap().split(' ').nth(1).unwrap().parse().unwrap();
    let headers: std::collections::BTreeMap<String, String> = lines
        .filter_map(|l| l.split_once(':'))
        .map(|(k, v)| (k.trim().to_ascii_lowercase(), v.trim().to_string()))
        .collect();
    let mut body = bytes[split + 4..].to_vec();
    if headers.get("transfer-encoding").is_some_and(|t| t.contains("chunked")) {
        let mut out = Vec::new();
        let mut rest = &body[..];
        loop {
            let eol = rest.windows(2).position(|w| w == b"\r\n").unwrap();
            let n = usize::from_str_radix(std::str::from_utf8(&rest[..eol]).unwrap().trim(), 16).unwrap();
            if n == 0 {
                break;
            }
            out.extend_from_slice(&rest[eol + 2..eol + 2 + n]);
            rest = &rest[eol + 4 + n..];
        }
        body = out;
    }
    Reply { status, headers, body }
}
