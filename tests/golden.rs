//! Golden images: the demo shot at frame 1024, every layer of its manifest
//! and `full`, rendered small through the real render job and compared with
//! the EXRs in `golden/` (see golden/README.md for the metric, the
//! tolerances and how to regenerate).
//!
//! Besides the comparison itself, two controls keep the metric honest: a
//! render with another seed (noise only) must pass, and a render with the sun
//! moved a few degrees must fail.
//!
//! `UPDATE_GOLDEN=1 cargo test --test golden` rewrites the goldens.

mod common;

use std::path::{Path, PathBuf};

use throng::casting::ShotCrowd;
use throng::layers::Manifest;
use throng::layers::{build_layers, LayerOverrides};
use throng::output::FULL_LAYER;
use throng::render::exr;
use throng::render::film::Film;
use throng::render::job::{self, RenderJob};

const FRAME: i32 = 1024;
const WIDTH: u32 = 160;
const HEIGHT: u32 = 90;
const SPP: u32 = 16;

/// Nominal block edge of the statistical test, pixels.
const BLOCK: u32 = 8;
/// Family-wise false-alarm rate of one golden run (all layers, blocks and
/// channels together), split over the tests by Bonferroni.
const FAMILY_ALPHA: f64 = 1e-3;
/// A block's mean difference must also exceed this floor, relative to the
/// block's mean magnitude plus an absolute part, before it can fail: keeps
/// bit-level differences (another libm, half rounding) from failing on a
/// zero-variance block, and is well under any look change worth catching.
const REL_FLOOR: f64 = 0.01;
const ABS_FLOOR: f64 = 1e-3;
/// How many single-sample (`agent.id`, `Z`) pixels may differ, as fractions
/// of the image.
#[derive(Debug, Clone, Copy)]
struct PointTolerance {
    /// Differing pixels explained by the golden's 3x3 neighbourhood (edges).
    edge: f64,
    /// Differing pixels the neighbourhood does not explain (a sub-pixel
    /// sliver won or lost the sample nearest the centre).
    unexplained: f64,
}
/// Same seed as the golden: ids and depths are exact but for a small fraction
/// of edge pixels (a last-bit float difference can move an edge).
const GOLDEN_POINTS: PointTolerance = PointTolerance { edge: 0.01, unexplained: 0.0005 };
/// Another seed: the sample nearest each pixel centre moves, so edges and
/// slivers of these tiny agents change (measured at 160x90: ids up to 2%
/// edge and 0.4% unexplained, depths up to 6% edge on the grazing floor).
const RESEED_POINTS: PointTolerance = PointTolerance { edge: 0.10, unexplained: 0.01 };
/// Relative depth tolerance before a `Z` pixel counts as different.
const Z_REL: f32 = 0.01;

// ---------------------------------------------------------------- rendering

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn golden_dir() -> PathBuf {
    repo().join("golden")
}

/// `target/golden-diff/`, where failures leave their evidence.
fn diff_dir() -> PathBuf {
    let tmp = Path::new(env!("CARGO_TARGET_TMPDIR"));
    tmp.parent().unwrap_or(tmp).join("golden-diff")
}

fn file_name(shot: &str, layer: &str) -> String {
    format!("{shot}.{layer}.{FRAME:04}.exr")
}

/// The demo shot and its layer manifest, built in memory as `throng layers` would.
fn demo() -> (ShotCrowd, Manifest) {
    let shot = repo().join("demo/shot.toml");
    let crowd = ShotCrowd::load(&shot).expect("demo shot loads");
    let args = LayerOverrides::default();
    let manifest = build_layers(&crowd, &args).expect("demo layers");
    (crowd, manifest)
}

/// Every layer of the manifest, back to front, then `full`.
fn golden_layers(manifest: &Manifest) -> Vec<String> {
    let mut layers = job::all_layers(manifest);
    layers.push(FULL_LAYER.to_string());
    layers
}

/// Renders `layers` at frame 1024 through the real render job into `out`
/// (EXR and PNG preview); returns each layer's EXR.
fn render(crowd: &ShotCrowd, manifest: &Manifest, layers: &[String], out: &Path) -> Vec<(String, PathBuf)> {
    render_with_shutter(crowd, manifest, layers, out, None)
}

/// As [`render`], with motion blur over `shutter` (the crowd must have been
/// built for it).
fn render_with_shutter(
    crowd: &ShotCrowd,
    manifest: &Manifest,
    layers: &[String],
    out: &Path,
    shutter: Option<[f32; 2]>,
) -> Vec<(String, PathBuf)> {
    let job = RenderJob {
        layers: layers.to_vec(),
        frames: vec![FRAME],
        spp: SPP,
        threads: 0,
        out: out.to_path_buf(),
        resume: false,
        png: true,
        resolution: Some([WIDTH, HEIGHT]),
        cryptomatte: job::CryptoOutput::Header,
        compression: Default::default(),
        shutter,
        colourspace: Default::default(),
        passes: None,
        adaptive: None,
        tracing: Default::default(),
        denoise: None,
        deep: None,
    };
    let done = job::run(crowd, Some(manifest), &job, &job::Silent).expect("demo renders").layers;
    done.into_iter().map(|r| (r.layer, r.path)).collect()
}

// ---------------------------------------------------------------- the metric

/// The filtered channels the block test compares, by EXR name.
fn channels(f: &Film) -> Vec<(&'static str, Vec<f32>)> {
    let rgba = |c: usize| f.rgba.iter().map(|p| p[c]).collect();
    let v3 = |v: &[[f32; 3]], c: usize| v.iter().map(|p| p[c]).collect();
    vec![
        ("R", rgba(0)),
        ("G", rgba(1)),
        ("B", rgba(2)),
        ("A", rgba(3)),
        ("N.X", v3(&f.normal, 0)),
        ("N.Y", v3(&f.normal, 1)),
        ("N.Z", v3(&f.normal, 2)),
        ("albedo.R", v3(&f.albedo, 0)),
        ("albedo.G", v3(&f.albedo, 1)),
        ("albedo.B", v3(&f.albedo, 2)),
    ]
}
const CHANNELS: usize = 10;

/// Splits `n` pixels into about `n / BLOCK` nearly equal spans.
fn spans(n: u32) -> Vec<(u32, u32)> {
    let k = (n as f64 / BLOCK as f64).round().max(1.0) as u32;
    (0..k).map(|i| (i * n / k, (i + 1) * n / k)).collect()
}

/// Complementary error function (Numerical Recipes `erfcc`, relative error
/// below 1.2e-7 everywhere).
fn erfc(x: f64) -> f64 {
    let z = x.abs();
    let t = 1.0 / (1.0 + 0.5 * z);
    let poly = -z * z - 1.26551223
        + t * (1.00002368
            + t * (0.37409196
                + t * (0.09678418
                    + t * (-0.18628806
                        + t * (0.27886807
                            + t * (-1.13520398 + t * (1.48851587 + t * (-0.82215223 + t * 0.17087277))))))));
    let r = t * poly.exp();
    if x >= 0.0 {
        r
    } else {
        2.0 - r
    }
}

/// Two-sided critical value of Student's t with `dof` degrees of freedom at
/// significance `alpha`: the normal quantile by bisection, then the first
/// Cornish-Fisher correction for the t tails.
fn t_critical(alpha: f64, dof: f64) -> f64 {
    let (mut lo, mut hi) = (0.0f64, 40.0f64);
    for _ in 0..200 {
        let mid = 0.5 * (lo + hi);
        if erfc(mid / std::f64::consts::SQRT_2) > alpha {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let z = 0.5 * (lo + hi);
    z + (z * z * z + z) / (4.0 * dof)
}

/// One block and channel whose mean difference is significant.
#[derive(Debug, Clone)]
struct BadBlock {
    x: (u32, u32),
    y: (u32, u32),
    channel: &'static str,
    mean_diff: f64,
    t: f64,
}

/// The comparison of one layer.
#[derive(Debug, Default)]
struct Report {
    blocks: usize,
    tests: usize,
    t_crit: f64,
    /// Largest |t| over the blocks whose mean difference cleared the floor.
    max_t: f64,
    bad_blocks: Vec<BadBlock>,
    non_finite: usize,
    id_edge: Vec<usize>,
    id_unexplained: Vec<usize>,
    z_edge: Vec<usize>,
    z_unexplained: Vec<usize>,
    mean_abs_rgb: f64,
    problems: Vec<String>,
}

impl Report {
    fn passed(&self) -> bool {
        self.problems.is_empty()
    }
    fn summary(&self) -> String {
        format!(
            "{} blocks x {CHANNELS} channels, t_crit {:.2}, max |t| {:.2}, {} significant; \
             agent.id: {} edge + {} unexplained differing pixels; Z: {} edge + {} unexplained; \
             mean |dRGB| {:.5}",
            self.blocks,
            self.t_crit,
            self.max_t,
            self.bad_blocks.len(),
            self.id_edge.len(),
            self.id_unexplained.len(),
            self.z_edge.len(),
            self.z_unexplained.len(),
            self.mean_abs_rgb
        )
    }
}

/// Compares a new render with its golden; `tests_in_run` is the Bonferroni
/// denominator (every block x channel test of the whole golden run).
fn compare(gold: &Film, new: &Film, tests_in_run: usize, points: PointTolerance) -> Report {
    let mut r = Report::default();
    if (gold.width, gold.height) != (new.width, new.height) {
        r.problems.push(format!("size {}x{} != golden {}x{}", new.width, new.height, gold.width, gold.height));
        return r;
    }
    let (w, h) = (gold.width, gold.height);
    let (xs, ys) = (spans(w), spans(h));
    r.blocks = xs.len() * ys.len();
    r.tests = r.blocks * CHANNELS;
    let min_n = xs.iter().map(|s| s.1 - s.0).min().unwrap_or(1) * ys.iter().map(|s| s.1 - s.0).min().unwrap_or(1);
    r.t_crit = t_critical(FAMILY_ALPHA / tests_in_run.max(1) as f64, (min_n.max(2) - 1) as f64);

    // Paired test per block: each pixel's difference has mean zero when the
    // expected image is unchanged, whatever the picture, and pixels are
    // independent estimates; so a block's mean difference over its standard
    // error is Student's t.
    for ((name, g), (_, n)) in channels(gold).into_iter().zip(channels(new)) {
        r.non_finite += n.iter().filter(|v| !v.is_finite()).count();
        for &(y0, y1) in &ys {
            for &(x0, x1) in &xs {
                let idx = (y0..y1).flat_map(|y| (x0..x1).map(move |x| (y * w + x) as usize));
                let (mut sum, mut sum2, mut mag, mut count) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
                for i in idx {
                    let d = n[i] as f64 - g[i] as f64;
                    if !d.is_finite() {
                        continue;
                    }
                    sum += d;
                    sum2 += d * d;
                    mag += 0.5 * (n[i].abs() as f64 + g[i].abs() as f64);
                    count += 1.0;
                }
                if count < 2.0 {
                    continue;
                }
                let mean = sum / count;
                let floor = ABS_FLOOR + REL_FLOOR * mag / count;
                if mean.abs() <= floor {
                    continue;
                }
                let var = ((sum2 - sum * sum / count) / (count - 1.0)).max(0.0);
                let se = (var / count).sqrt();
                let t = if se > 0.0 { mean.abs() / se } else { f64::INFINITY };
                r.max_t = r.max_t.max(t);
                if t > r.t_crit {
                    r.bad_blocks.push(BadBlock { x: (x0, x1), y: (y0, y1), channel: name, mean_diff: mean, t });
                }
            }
        }
    }
    r.mean_abs_rgb = gold
        .rgba
        .iter()
        .zip(&new.rgba)
        .map(|(a, b)| (0..3).map(|c| (a[c] as f64 - b[c] as f64).abs()).sum::<f64>() / 3.0)
        .sum::<f64>()
        / (w as f64 * h as f64);

    // agent.id and Z come from one sample per pixel: equal except where the
    // sample nearest the centre moved across an edge, which the golden's
    // 3x3 neighbourhood explains.
    let neighbours = |i: usize| {
        let (x, y) = ((i as u32 % w) as i64, (i as u32 / w) as i64);
        (-1..=1i64)
            .flat_map(move |dy| (-1..=1i64).map(move |dx| (x + dx, y + dy)))
            .filter(move |&(nx, ny)| nx >= 0 && ny >= 0 && nx < w as i64 && ny < h as i64)
            .map(move |(nx, ny)| (ny as u32 * w + nx as u32) as usize)
    };
    for i in 0..gold.agent_id.len() {
        if gold.agent_id[i] != new.agent_id[i] {
            if neighbours(i).any(|j| gold.agent_id[j] == new.agent_id[i]) {
                r.id_edge.push(i);
            } else {
                r.id_unexplained.push(i);
            }
        }
        let (gz, nz) = (gold.z[i], new.z[i]);
        let same =
            if gz.is_finite() && nz.is_finite() { (gz - nz).abs() <= Z_REL * gz.abs().max(1e-3) } else { gz == nz };
        if !same {
            let explained = if nz.is_finite() {
                let (lo, hi) = neighbours(i)
                    .map(|j| gold.z[j])
                    .filter(|z| z.is_finite())
                    .fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), z| (lo.min(z), hi.max(z)));
                nz >= lo * (1.0 - Z_REL) && nz <= hi * (1.0 + Z_REL)
            } else {
                neighbours(i).any(|j| !gold.z[j].is_finite())
            };
            if explained {
                r.z_edge.push(i);
            } else {
                r.z_unexplained.push(i);
            }
        }
    }

    let pixels = (w * h) as f64;
    if r.non_finite > 0 {
        r.problems.push(format!("{} non-finite samples", r.non_finite));
    }
    if let Some(b) = r.bad_blocks.iter().max_by(|a, b| a.t.total_cmp(&b.t)) {
        let mut chans: Vec<&str> = r.bad_blocks.iter().map(|b| b.channel).collect();
        chans.dedup();
        chans.sort();
        chans.dedup();
        r.problems.push(format!(
            "{} of {} block tests differ significantly (channels {}); worst: {} in x {}..{} y {}..{}, \
             mean difference {:+.4}, |t| {:.1} > {:.2}",
            r.bad_blocks.len(),
            r.tests,
            chans.join(" "),
            b.channel,
            b.x.0,
            b.x.1,
            b.y.0,
            b.y.1,
            b.mean_diff,
            b.t,
            r.t_crit
        ));
    }
    for (what, edge, unexplained) in [("agent.id", &r.id_edge, &r.id_unexplained), ("Z", &r.z_edge, &r.z_unexplained)] {
        if edge.len() as f64 > points.edge * pixels || unexplained.len() as f64 > points.unexplained * pixels {
            r.problems.push(format!(
                "{what}: {} edge pixels (max {:.0}) and {} unexplained pixels (max {:.0}) differ",
                edge.len(),
                points.edge * pixels,
                unexplained.len(),
                points.unexplained * pixels
            ));
        }
    }
    r
}

/// Golden | new | difference, side by side, as a PNG: the difference panel
/// shows |dRGB| x 8 in grey, significant blocks outlined in red, differing
/// ids in magenta (unexplained ones bright) and depths in yellow.
fn write_diff_image(path: &Path, gold: &Film, new: &Film, r: &Report) {
    let (w, h) = (gold.width.min(new.width), gold.height.min(new.height));
    let gap = 2;
    let mut out = Film::new(3 * w + 2 * gap, h);
    for y in 0..h {
        for x in 0..w {
            let (gi, ni) = (gold.index(x, y), new.index(x, y));
            let d = (0..3).map(|c| (gold.rgba[gi][c] - new.rgba[ni][c]).abs()).fold(0.0, f32::max) * 8.0;
            let (a, b, c) = (out.index(x, y), out.index(x + w + gap, y), out.index(x + 2 * (w + gap), y));
            out.rgba[a] = gold.rgba[gi];
            out.rgba[b] = new.rgba[ni];
            out.rgba[c] = [d, d, d, 1.0];
        }
    }
    let mut paint = |x: u32, y: u32, c: [f32; 4]| {
        if x < w && y < h {
            let i = out.index(x + 2 * (w + gap), y);
            out.rgba[i] = c;
        }
    };
    for (list, c) in [
        (&r.z_edge, [0.4, 0.4, 0.0, 1.0]),
        (&r.z_unexplained, [1.0, 1.0, 0.0, 1.0]),
        (&r.id_edge, [0.4, 0.0, 0.4, 1.0]),
        (&r.id_unexplained, [1.0, 0.0, 1.0, 1.0]),
    ] {
        for &i in list {
            paint(i as u32 % gold.width, i as u32 / gold.width, c);
        }
    }
    for b in &r.bad_blocks {
        for x in b.x.0..b.x.1 {
            paint(x, b.y.0, [1.0, 0.0, 0.0, 1.0]);
            paint(x, b.y.1 - 1, [1.0, 0.0, 0.0, 1.0]);
        }
        for y in b.y.0..b.y.1 {
            paint(b.x.0, y, [1.0, 0.0, 0.0, 1.0]);
            paint(b.x.1 - 1, y, [1.0, 0.0, 0.0, 1.0]);
        }
    }
    if let Err(e) = exr::write_preview_png(path, &out) {
        eprintln!("could not write {}: {e}", path.display());
    }
}

/// Compares every rendered layer with its golden. Returns one line per
/// layer and the failures (with their diff images written).
fn check_against_golden(
    rendered: &[(String, PathBuf)],
    shot: &str,
    points: PointTolerance,
    write_diffs: bool,
) -> (Vec<String>, Vec<String>) {
    let tests_in_run = rendered.len() * CHANNELS * spans(WIDTH).len() * spans(HEIGHT).len();
    let (mut lines, mut failures) = (Vec::new(), Vec::new());
    for (layer, path) in rendered {
        let name = file_name(shot, layer);
        let golden = golden_dir().join(&name);
        let (gold, gold_meta) = match exr::read_layer(&golden) {
            Ok(g) => g,
            Err(e) => {
                failures.push(format!(
                    "layer {layer}: golden {} unreadable ({e}); create it with `UPDATE_GOLDEN=1 cargo test --test golden`",
                    golden.display()
                ));
                continue;
            }
        };
        let (new, meta) = exr::read_layer(path).expect("fresh render reads back");
        let mut r = compare(&gold, &new, tests_in_run, points);
        if (meta.shot.as_str(), meta.layer.as_str(), meta.frame, meta.spp)
            != (gold_meta.shot.as_str(), gold_meta.layer.as_str(), gold_meta.frame, gold_meta.spp)
        {
            r.problems.push(format!(
                "header differs: {}/{}/{}/{} spp, golden {}/{}/{}/{} spp",
                meta.shot,
                meta.layer,
                meta.frame,
                meta.spp,
                gold_meta.shot,
                gold_meta.layer,
                gold_meta.frame,
                gold_meta.spp
            ));
        }
        lines.push(format!("{layer:<7} {}", r.summary()));
        if !r.passed() {
            let mut evidence = String::new();
            if write_diffs {
                let dir = diff_dir();
                let _ = std::fs::create_dir_all(&dir);
                let diff = dir.join(name.replace(".exr", ".diff.png"));
                write_diff_image(&diff, &gold, &new, &r);
                let copy = dir.join(&name);
                let _ = std::fs::copy(path, &copy);
                evidence = format!(
                    "\n    diff image (golden | new | difference): {}\n    new render: {}",
                    diff.display(),
                    copy.display()
                );
            }
            failures.push(format!("layer {layer}: {}{evidence}", r.problems.join("; ")));
        }
    }
    (lines, failures)
}

/// With `UPDATE_GOLDEN=1`, copies the renders (EXR and PNG) into golden/
/// and says so; otherwise does nothing and returns false.
fn update_goldens(rendered: &[(String, PathBuf)]) -> bool {
    if std::env::var_os("UPDATE_GOLDEN").is_none_or(|v| v == "0") {
        return false;
    }
    std::fs::create_dir_all(golden_dir()).expect("golden dir");
    for (_, path) in rendered {
        for p in [path.clone(), path.with_extension("png")] {
            let to = golden_dir().join(p.file_name().expect("file name"));
            std::fs::copy(&p, &to).expect("copy golden");
            println!("updated {}", to.display());
        }
    }
    true
}

// ---------------------------------------------------------------- tests

/// A skinned character: Khronos' RiggedFigure (a skeleton under a Z-up
/// node, one unnamed clip) walking, five agents at different phases, full
/// render and its nearest crowd layer.
#[test]
fn rigged_figure_matches_golden() {
    let dir = common::tempdir().expect("temp dir");
    let shot = common::figure_shot(dir.path(), &common::five_walkers(), "");
    let crowd = ShotCrowd::load(&shot).expect("figure shot loads");
    let manifest = build_layers(&crowd, &LayerOverrides::default()).expect("figure layers");
    let layers = vec!["crowd0".to_string(), FULL_LAYER.to_string()];
    let rendered = render(&crowd, &manifest, &layers, &dir.path().join("out"));
    if update_goldens(&rendered) {
        return;
    }
    let (lines, failures) = check_against_golden(&rendered, &crowd.shot().name, GOLDEN_POINTS, true);
    for l in &lines {
        println!("{l}");
    }
    assert!(
        failures.is_empty(),
        "RiggedFigure differs from its golden (regenerate with `UPDATE_GOLDEN=1 cargo test --test golden` if intended):\n  {}",
        failures.join("\n  ")
    );
}

/// The goldens: every layer of the demo at frame 1024 matches, or with
/// `UPDATE_GOLDEN=1` is rewritten.
#[test]
fn demo_layers_match_golden() {
    let (crowd, manifest) = demo();
    let layers = golden_layers(&manifest);
    let tmp = common::tempdir().expect("temp dir");
    let started = std::time::Instant::now();
    let rendered = render(&crowd, &manifest, &layers, tmp.path());
    println!(
        "rendered {} layers at {WIDTH}x{HEIGHT}, {SPP} spp in {:.1} s",
        layers.len(),
        started.elapsed().as_secs_f64()
    );

    if update_goldens(&rendered) {
        return;
    }

    // Evidence of an earlier failure must not outlive it.
    let _ = std::fs::remove_dir_all(diff_dir());
    let (lines, failures) = check_against_golden(&rendered, &crowd.shot().name, GOLDEN_POINTS, true);
    for l in &lines {
        println!("{l}");
    }
    assert!(
        failures.is_empty(),
        "golden images differ (if the change is intended, regenerate with `UPDATE_GOLDEN=1 cargo test --test golden` \
         and review the PNGs in golden/):\n  {}",
        failures.join("\n  ")
    );
}

/// The blurred golden: the demo's `full` layer at frame 1024 with a
/// 180-degree shutter centred on the frame (`golden/demo_blur.full.1024.exr`),
/// the same size, samples and metric as the still goldens.
#[test]
fn blurred_demo_matches_golden() {
    let (_, manifest) = demo();
    let shutter = [-0.25, 0.25];
    let shot = throng::shot::Shot::load(&repo().join("demo/shot.toml")).expect("demo shot loads");
    let crowd = ShotCrowd::open(shot, Some(shutter)).expect("demo casts for the shutter");
    let tmp = common::tempdir().expect("temp dir");
    let rendered = render_with_shutter(&crowd, &manifest, &[FULL_LAYER.to_string()], tmp.path(), Some(shutter));
    // Golden names carry `demo_blur` so they sit beside the still goldens.
    let renamed: Vec<(String, PathBuf)> = rendered
        .into_iter()
        .map(|(layer, path)| {
            let to = tmp.path().join(file_name("demo_blur", &layer));
            std::fs::rename(&path, &to).expect("rename");
            std::fs::rename(path.with_extension("png"), to.with_extension("png")).expect("rename png");
            (layer, to)
        })
        .collect();
    let (_, meta) = exr::read_layer(&renamed[0].1).expect("reads back");
    assert_eq!(meta.shutter, Some(shutter), "the shutter is in the header");
    if update_goldens(&renamed) {
        return;
    }
    let (lines, failures) = check_against_golden(&renamed, "demo_blur", GOLDEN_POINTS, true);
    for l in &lines {
        println!("{l}");
    }
    assert!(
        failures.is_empty(),
        "the blurred demo differs from its golden (regenerate with `UPDATE_GOLDEN=1 cargo test --test golden` if intended):\n  {}",
        failures.join("\n  ")
    );
}

/// Control: the same shot with another render seed differs only by noise,
/// and the metric must accept it (the tolerance is statistical, not bitwise).
#[test]
fn metric_accepts_another_seed() {
    if std::env::var_os("UPDATE_GOLDEN").is_some() {
        return;
    }
    let (crowd, manifest) = demo();
    // Casting already happened at load: this changes only the render's samples.
    let crowd = crowd.with_shot(|shot| shot.seed = shot.seed.wrapping_add(7919)).unwrap();
    let layers = golden_layers(&manifest);
    let tmp = common::tempdir().expect("temp dir");
    let rendered = render(&crowd, &manifest, &layers, tmp.path());
    let (lines, failures) = check_against_golden(&rendered, &crowd.shot().name, RESEED_POINTS, false);
    for l in &lines {
        println!("{l}");
    }
    assert!(
        failures.is_empty(),
        "a noise-only change (another seed) failed the golden metric:\n  {}",
        failures.join("\n  ")
    );
}

/// Control: a real look change, the dome (and its sun) turned 4 degrees
/// about +Y, must fail.
#[test]
fn metric_rejects_a_moved_sun() {
    if std::env::var_os("UPDATE_GOLDEN").is_some() {
        return;
    }
    let (crowd, manifest) = demo();
    let crowd = crowd
        .with_shot(|shot| shot.lights.dome.as_mut().expect("the demo is lit by a dome").rotate += 4f32.to_radians())
        .expect("the same dome turned");
    // The crowd layers barely change at this size (their shading turns a
    // little); the set's shadows move, and `full` has both.
    let layers = vec![manifest.set.name.clone(), FULL_LAYER.to_string()];
    let tmp = common::tempdir().expect("temp dir");
    let rendered = render(&crowd, &manifest, &layers, tmp.path());
    // Same seed as the golden: only the sun (the dome) differs.
    let (lines, failures) = check_against_golden(&rendered, &crowd.shot().name, GOLDEN_POINTS, false);
    for l in &lines {
        println!("{l}");
    }
    assert_eq!(
        failures.len(),
        layers.len(),
        "moving the sun 4 degrees should fail every layer's golden:\n  {}",
        lines.join("\n  ")
    );
}
