//! The layer map (`throng layers --map FILE.png`): a lighter's picture of the
//! split. Left, the set from above with the camera, its frustum and the layer
//! boundaries as rings around the camera, every agent a dot coloured by layer.
//! Right, the camera's view at the reference frame, every agent a bar from
//! feet to head in its layer's colour, far drawn first as the comp stacks
//! them. Below, a legend line per layer. Drawn with tiny-skia and a built-in
//! bitmap font (tiny-skia has no text).

use std::path::Path;

use glam::{Vec2, Vec3};
use tiny_skia::{Color, FillRule, Mask, Paint, PathBuilder, Pixmap, Rect, Stroke, StrokeDash, Transform};

use super::font;
use super::manifest::{distance_range, format_bytes, LayerAgent, Lod, Manifest, Ranking};
use crate::error::{write_atomic, Error, Result};

/// What to draw.
#[derive(Debug, Clone, Copy)]
pub struct MapOptions {
    /// Image width and height in pixels.
    pub size: (u32, u32),
    /// The set's bounds (min, max), for the top-down panel; agents' and the
    /// camera's bounds when `None`.
    pub set_bounds: Option<(Vec3, Vec3)>,
    /// An agent to mark with rings on both panels (`throng review`'s pick).
    pub highlight: Option<u32>,
}

impl Default for MapOptions {
    fn default() -> Self {
        MapOptions { size: (1600, 900), set_bounds: None, highlight: None }
    }
}

type Rgba = [u8; 4];
const BG: Rgba = [28, 30, 34, 255];
const PANEL: Rgba = [40, 43, 48, 255];
const SET: Rgba = [55, 60, 66, 255];
const TEXT: Rgba = [225, 228, 232, 255];
const DIM: Rgba = [140, 146, 154, 255];
const WHITE: Rgba = [255, 255, 255, 255];
const REMOVED: Rgba = [20, 20, 20, 255];
const HIGHLIGHT: Rgba = [255, 214, 10, 255];

/// An outline: its colour and width in pixels.
#[derive(Clone, Copy)]
struct Pen(Rgba, f32);

/// Layer colours, nearest first: warm near, cool far.
const PALETTE: [Rgba; 8] = [
    [255, 96, 72, 255],
    [255, 196, 40, 255],
    [96, 210, 120, 255],
    [64, 168, 255, 255],
    [190, 110, 255, 255],
    [255, 120, 200, 255],
    [0, 210, 210, 255],
    [175, 175, 95, 255],
];

/// A layer's colour.
pub(crate) fn layer_color(layer: usize) -> [u8; 4] {
    PALETTE[layer % PALETTE.len()]
}

fn paint(c: Rgba) -> Paint<'static> {
    let mut p = Paint::default();
    p.set_color(Color::from_rgba8(c[0], c[1], c[2], c[3]));
    p.anti_alias = true;
    p
}

fn with_alpha(c: Rgba, a: u8) -> Rgba {
    [c[0], c[1], c[2], a]
}

/// Thin drawing helpers over a pixmap; `clip` limits drawing to a panel.
struct Canvas {
    pm: Pixmap,
}

impl Canvas {
    fn rect(&mut self, x: f32, y: f32, w: f32, h: f32, c: Rgba, clip: Option<&Mask>) {
        if let Some(r) = Rect::from_xywh(x, y, w.max(0.5), h.max(0.5)) {
            let mut p = paint(c);
            p.anti_alias = false;
            self.pm.fill_rect(r, &p, Transform::identity(), clip);
        }
    }

    fn stroke_rect(&mut self, x: f32, y: f32, w: f32, h: f32, pen: Pen, clip: Option<&Mask>) {
        let Pen(c, width) = pen;
        if let Some(r) = Rect::from_xywh(x, y, w.max(0.5), h.max(0.5)) {
            let path = PathBuilder::from_rect(r);
            let stroke = Stroke { width, ..Stroke::default() };
            self.pm.stroke_path(&path, &paint(c), &stroke, Transform::identity(), clip);
        }
    }

    fn circle(&mut self, x: f32, y: f32, r: f32, c: Rgba, stroke: Option<f32>, clip: Option<&Mask>) {
        let Some(path) = PathBuilder::from_circle(x, y, r.max(0.5)) else { return };
        match stroke {
            None => self.pm.fill_path(&path, &paint(c), FillRule::Winding, Transform::identity(), clip),
            Some(w) => {
                let s = Stroke { width: w, ..Stroke::default() };
                self.pm.stroke_path(&path, &paint(c), &s, Transform::identity(), clip)
            }
        }
    }

    fn dashed_circle(&mut self, x: f32, y: f32, r: f32, c: Rgba, width: f32, clip: Option<&Mask>) {
        let Some(path) = PathBuilder::from_circle(x, y, r.max(0.5)) else { return };
        let s = Stroke { width, dash: StrokeDash::new(vec![6.0, 5.0], 0.0), ..Stroke::default() };
        self.pm.stroke_path(&path, &paint(c), &s, Transform::identity(), clip);
    }

    fn polyline(&mut self, pts: &[Vec2], c: Rgba, width: f32, close: bool, fill: bool, clip: Option<&Mask>) {
        let mut pb = PathBuilder::new();
        for (i, p) in pts.iter().enumerate() {
            if i == 0 {
                pb.move_to(p.x, p.y)
            } else {
                pb.line_to(p.x, p.y)
            }
        }
        if close {
            pb.close();
        }
        let Some(path) = pb.finish() else { return };
        if fill {
            self.pm.fill_path(&path, &paint(c), FillRule::Winding, Transform::identity(), clip);
        } else {
            let s = Stroke { width, ..Stroke::default() };
            self.pm.stroke_path(&path, &paint(c), &s, Transform::identity(), clip);
        }
    }

    fn cross(&mut self, x: f32, y: f32, r: f32, c: Rgba, width: f32, clip: Option<&Mask>) {
        self.polyline(&[Vec2::new(x - r, y - r), Vec2::new(x + r, y + r)], c, width, false, false, clip);
        self.polyline(&[Vec2::new(x - r, y + r), Vec2::new(x + r, y - r)], c, width, false, false, clip);
    }

    /// Text with its top-left at (x, y), `s` pixels per font pixel. Returns the width.
    fn text(&mut self, x: f32, y: f32, s: u32, text: &str, c: Rgba) -> f32 {
        let mut p = paint(c);
        p.anti_alias = false;
        let sf = s as f32;
        for (i, ch) in text.chars().enumerate() {
            let gx = x + (i as u32 * (font::W + 1) * s) as f32;
            for (row, bits) in font::glyph(ch).iter().enumerate() {
                for col in 0..font::W {
                    if bits & (1 << (font::W - 1 - col)) != 0 {
                        if let Some(r) = Rect::from_xywh(gx + col as f32 * sf, y + row as f32 * sf, sf, sf) {
                            self.pm.fill_rect(r, &p, Transform::identity(), None);
                        }
                    }
                }
            }
        }
        font::text_width(text, s) as f32
    }
}

fn clip_mask(w: u32, h: u32, x: f32, y: f32, cw: f32, ch: f32) -> Option<Mask> {
    let mut mask = Mask::new(w, h)?;
    let path = PathBuilder::from_rect(Rect::from_xywh(x, y, cw.max(1.0), ch.max(1.0))?);
    mask.fill_path(&path, FillRule::Winding, false, Transform::identity());
    Some(mask)
}

/// Renders the map as PNG bytes.
pub fn render_map(m: &Manifest, opts: &MapOptions) -> Result<Vec<u8>> {
    let (w, h) = opts.size;
    let pm = Pixmap::new(w, h).ok_or_else(|| Error::Usage(format!("map size {w}x{h} must be at least 1x1")))?;
    let mut cv = Canvas { pm };
    cv.pm.fill(Color::from_rgba8(BG[0], BG[1], BG[2], 255));
    let (wf, hf) = (w as f32, h as f32);
    // Text scale: 2 on a normal map, 1 on a small one.
    let s: u32 = if w >= 1000 && h >= 560 { 2 } else { 1 };
    let lh = ((font::H + 4) * s) as f32;
    let pad = (6 * s) as f32;

    // Title.
    let split = match m.split.mode.as_str() {
        "count" => format!("COUNT {}", m.split.count.unwrap_or(0)),
        "cutoffs" => {
            format!("CUT-OFFS {} M", m.split.cutoffs_m.iter().map(|c| format!("{c}")).collect::<Vec<_>>().join(", "))
        }
        "budget" => format!("BUDGET {} PER LAYER", format_bytes(m.split.budget_bytes.unwrap_or(0))),
        other => other.to_uppercase(),
    };
    let ranking = match m.ranking {
        Ranking::Fixed => "FIXED-FRAME RANKING, 0 POPS".to_string(),
        Ranking::PerFrame => format!("PER-FRAME RANKING WOULD POP {} AGENTS", m.pops.agents_changed),
    };
    cv.text(
        pad,
        pad,
        s,
        &format!(
            "{}   LAYERS RANKED AT FRAME {} ({}-{})   SPLIT BY {}   {}",
            m.shot, m.ref_frame, m.frame_range[0], m.frame_range[1], split, ranking
        ),
        TEXT,
    );

    // Legend rows: layers (as many as fit), set, key.
    let max_rows = (((hf * 0.35) / lh) as usize).saturating_sub(3).max(1);
    let shown = m.layers.len().min(max_rows);
    let more = m.layers.len() - shown;
    let legend_rows = shown + usize::from(more > 0) + 2;
    let legend_h = legend_rows as f32 * lh + pad;
    let top = pad + lh + pad / 2.0;
    let bottom = hf - legend_h - pad;
    let panel_w = (wf - 3.0 * pad) / 2.0;
    let panel_h = (bottom - top).max(1.0);
    let left = (pad, top);
    let right = (2.0 * pad + panel_w, top);
    cv.rect(left.0, left.1, panel_w, panel_h, PANEL, None);
    cv.rect(right.0, right.1, panel_w, panel_h, PANEL, None);

    top_down(&mut cv, m, opts, left, (panel_w, panel_h), s, lh);
    camera_view(&mut cv, m, opts, right, (panel_w, panel_h), s, lh);
    legend(&mut cv, m, LegendLayout { x: pad, y: bottom + pad, scale: s, line_height: lh, shown, more });

    cv.pm.encode_png().map_err(|e| Error::Usage(format!("cannot encode the layer map: {e}")))
}

/// Renders the map and writes it atomically to `path`.
pub fn draw_map(m: &Manifest, opts: &MapOptions, path: &Path) -> Result<()> {
    let png = render_map(m, opts)?;
    write_atomic(path, |w| std::io::Write::write_all(w, &png).map_err(|e| Error::io(path, e)))
}

/// Agents far to near, so nearer layers paint over farther ones.
fn far_to_near(m: &Manifest) -> Vec<&LayerAgent> {
    let mut v: Vec<&LayerAgent> = m.agents.iter().collect();
    v.sort_by(|a, b| b.layer.cmp(&a.layer).then(b.distance_m.total_cmp(&a.distance_m)));
    v
}

fn top_down(cv: &mut Canvas, m: &Manifest, opts: &MapOptions, at: (f32, f32), size: (f32, f32), s: u32, lh: f32) {
    let (w, h) = (cv.pm.width(), cv.pm.height());
    let pad = (6 * s) as f32;
    cv.text(at.0 + pad, at.1 + pad, s, "FROM ABOVE (X RIGHT, Z DOWN)", DIM);
    let inner = (at.0 + pad, at.1 + pad + lh, size.0 - 2.0 * pad, size.1 - 2.0 * pad - lh);
    let clip = clip_mask(w, h, at.0, at.1, size.0, size.1);
    let clip = clip.as_ref();

    // World bounds in X/Z: the set, else the agents; always the camera.
    let cam = Vec3::from(m.camera.position);
    let (mut lo, mut hi) = match opts.set_bounds {
        Some((a, b)) => (Vec2::new(a.x, a.z), Vec2::new(b.x, b.z)),
        None => m.agents.iter().fold((Vec2::new(cam.x, cam.z), Vec2::new(cam.x, cam.z)), |(lo, hi), a| {
            let p = Vec2::new(a.position[0], a.position[2]);
            (lo.min(p), hi.max(p))
        }),
    };
    lo = lo.min(Vec2::new(cam.x, cam.z)) - Vec2::splat(2.0);
    hi = hi.max(Vec2::new(cam.x, cam.z)) + Vec2::splat(2.0);
    let span = (hi - lo).max(Vec2::splat(1.0));
    let k = (inner.2 / span.x).min(inner.3 / span.y).max(1e-6);
    let off = Vec2::new(inner.0 + 0.5 * (inner.2 - span.x * k), inner.1 + 0.5 * (inner.3 - span.y * k));
    let to_px = |x: f32, z: f32| off + (Vec2::new(x, z) - lo) * k;

    if let Some((a, b)) = opts.set_bounds {
        let p = to_px(a.x, a.z);
        cv.rect(p.x, p.y, (b.x - a.x) * k, (b.z - a.z) * k, SET, clip);
    }
    // Scale bar: 10 m.
    let bar = 10.0 * k;
    let by = inner.1 + inner.3 - 2.0;
    cv.rect(inner.0 + inner.2 - bar, by, bar, s as f32, DIM, clip);
    let label = "10 M";
    cv.text(inner.0 + inner.2 - bar, by - ((font::H + 2) * s) as f32, s, label, DIM);

    // Frustum: the horizontal field of view on the ground.
    let c = to_px(cam.x, cam.z);
    let fwd = Vec2::new(m.camera.forward[0], m.camera.forward[2]);
    let aspect = m.camera.image_size[0] as f32 / m.camera.image_size[1].max(1) as f32;
    let half = ((0.5 * m.camera.yfov).tan() * aspect).atan();
    if fwd.length() > 1e-3 {
        let f = fwd.normalize();
        let reach = 2.0 * (span.x + span.y) * k;
        let edge = |a: f32| c + Vec2::new(f.x * a.cos() - f.y * a.sin(), f.x * a.sin() + f.y * a.cos()) * reach;
        let (l, r) = (edge(-half), edge(half));
        cv.polyline(&[c, l, r], [255, 255, 255, 22], 1.0, true, true, clip);
        cv.polyline(&[l, c, r], [255, 255, 255, 110], 1.0, false, false, clip);
    }
    // Layer boundaries as rings around the camera. Distance is to the
    // agent's centre, so the ring on the ground is a little smaller.
    let mid_h = if m.agents.is_empty() {
        0.9
    } else {
        m.agents.iter().map(|a| 0.5 * a.height_m).sum::<f32>() / m.agents.len() as f32
    };
    let dy = cam.y - mid_h;
    let mut labels = Vec::new();
    for (i, b) in m.split.boundaries_m.iter().enumerate() {
        let Some(d) = b else { continue };
        let r = (d * d - dy * dy).max(0.0).sqrt();
        let col = with_alpha(layer_color(i + 1), 200);
        cv.dashed_circle(c.x, c.y, r * k, col, 1.5, clip);
        if fwd.length() > 1e-3 {
            let p = c + fwd.normalize() * r * k;
            // Name the layer that begins at this ring, on a dark backing so dots don't hide it.
            let label = format!("CROWD{} FROM {d:.1} M", i + 1);
            labels.push((p.x + 4.0, p.y - ((font::H + 4) * s) as f32, label, col));
        }
    }

    // Agents: filled = full LOD, ring = proxy, white ring = pinned, cross = removed.
    let dot = (0.3 * k).clamp(2.0, 4.0 * s as f32);
    for a in far_to_near(m) {
        let p = to_px(a.position[0], a.position[2]);
        let col = layer_color(a.layer);
        match a.lod {
            Lod::Full => cv.circle(p.x, p.y, dot, col, None, clip),
            Lod::Proxy => cv.circle(p.x, p.y, dot * 0.8, col, Some((dot * 0.45).max(1.0)), clip),
        }
        if a.pinned {
            cv.circle(p.x, p.y, dot + 2.0, WHITE, Some(1.2), clip);
        }
        if a.removed {
            cv.cross(p.x, p.y, dot + 1.5, REMOVED, 2.5, clip);
            cv.cross(p.x, p.y, dot + 1.0, WHITE, 1.0, clip);
        }
    }
    // The highlighted agent: a yellow ring in a dark one, on top of every dot.
    if let Some(a) = opts.highlight.and_then(|id| m.agent(id)) {
        let p = to_px(a.position[0], a.position[2]);
        cv.circle(p.x, p.y, dot + 7.0, [0, 0, 0, 255], Some(5.0), clip);
        cv.circle(p.x, p.y, dot + 7.0, HIGHLIGHT, Some(2.5), clip);
    }
    for (lx, ly, label, col) in labels {
        let (tw, th) = (font::text_width(&label, s) as f32, ((font::H + 1) * s) as f32);
        cv.rect(lx - 2.0, ly - 2.0, tw + 4.0, th + 3.0, [28, 30, 34, 210], clip);
        cv.text(lx, ly, s, &label, col);
    }
    // The camera on top.
    cv.circle(c.x, c.y, 4.0 * s as f32, WHITE, None, clip);
    cv.text(c.x + 6.0 * s as f32, c.y - 3.0 * s as f32, s, "CAMERA", WHITE);
}

fn camera_view(cv: &mut Canvas, m: &Manifest, opts: &MapOptions, at: (f32, f32), size: (f32, f32), s: u32, lh: f32) {
    let (w, h) = (cv.pm.width(), cv.pm.height());
    let pad = (6 * s) as f32;
    let [iw, ih] = m.camera.image_size;
    let caption =
        format!("CAMERA VIEW AT FRAME {} ({iw}X{ih}), FULL LOD FROM {} PX TALL", m.ref_frame, m.lod_full_min_px);
    cv.text(at.0 + pad, at.1 + pad, s, &caption, DIM);
    let avail = (size.0 - 2.0 * pad, size.1 - 2.0 * pad - lh);
    let k = (avail.0 / iw.max(1) as f32).min(avail.1 / ih.max(1) as f32).max(1e-6);
    let (fw, fh) = (iw as f32 * k, ih as f32 * k);
    let fx = at.0 + pad + 0.5 * (avail.0 - fw);
    let fy = at.1 + pad + lh + 0.5 * (avail.1 - fh);
    cv.rect(fx, fy, fw, fh, BG, None);
    let clip = clip_mask(w, h, fx, fy, fw, fh);
    let clip = clip.as_ref();

    // Horizon, for orientation: where the ground meets the sky far away.
    let cam = Vec3::from(m.camera.position);
    let f = Vec3::from(m.camera.forward);
    let flat = Vec3::new(f.x, 0.0, f.z);
    if flat.length() > 1e-3 {
        if let Some((_, y, _)) = m.camera.project(cam + flat.normalize() * 1e4 - Vec3::Y * cam.y) {
            let y = fy + y * k;
            cv.rect(fx, y, fw, (fy + fh - y).max(0.0), [48, 52, 58, 255], clip);
            cv.polyline(&[Vec2::new(fx, y), Vec2::new(fx + fw, y)], [255, 255, 255, 40], 1.0, false, false, clip);
        }
    }

    // Agents as bars from feet to head, far first (as the comp stacks them).
    for a in far_to_near(m) {
        let foot = Vec3::from(a.position);
        let (Some(pf), Some(ph)) = (m.camera.project(foot), m.camera.project(foot + Vec3::Y * a.height_m)) else {
            continue;
        };
        let (x, y0, y1) = (fx + pf.0 * k, fy + ph.1 * k, fy + pf.1 * k);
        let bh = (y1 - y0).max(1.0);
        let bw = (0.28 * bh).max(1.5);
        let col = layer_color(a.layer);
        if a.removed {
            cv.stroke_rect(x - 0.5 * bw, y0, bw, bh, Pen(DIM, 1.0), clip);
            cv.cross(x, y0 + 0.5 * bh, (0.5 * bw).max(2.0), WHITE, 1.0, clip);
            continue;
        }
        match a.lod {
            Lod::Full => cv.rect(x - 0.5 * bw, y0, bw, bh, col, clip),
            Lod::Proxy => {
                cv.rect(x - 0.5 * bw, y0, bw, bh, with_alpha(col, 70), clip);
                cv.stroke_rect(x - 0.5 * bw, y0, bw, bh, Pen(col, 1.0), clip);
            }
        }
        if a.pinned {
            cv.stroke_rect(x - 0.5 * bw - 1.5, y0 - 1.5, bw + 3.0, bh + 3.0, Pen(WHITE, 1.0), clip);
        }
    }
    if let Some(a) = opts.highlight.and_then(|id| m.agent(id)) {
        let foot = Vec3::from(a.position);
        if let (Some(pf), Some(ph)) = (m.camera.project(foot), m.camera.project(foot + Vec3::Y * a.height_m)) {
            let (x, y0, y1) = (fx + pf.0 * k, fy + ph.1 * k, fy + pf.1 * k);
            let bh = (y1 - y0).max(1.0);
            let bw = (0.28 * bh).max(1.5);
            cv.stroke_rect(x - 0.5 * bw - 4.0, y0 - 4.0, bw + 8.0, bh + 8.0, Pen([0, 0, 0, 255], 4.0), clip);
            cv.stroke_rect(x - 0.5 * bw - 4.0, y0 - 4.0, bw + 8.0, bh + 8.0, Pen(HIGHLIGHT, 2.5), clip);
        }
    }
    cv.stroke_rect(fx, fy, fw, fh, Pen(DIM, 1.0), None);
}

/// Where the legend goes and how many layer rows it lists.
#[derive(Clone, Copy)]
struct LegendLayout {
    /// Top-left corner, pixels.
    x: f32,
    y: f32,
    /// Text scale.
    scale: u32,
    /// Line height, pixels.
    line_height: f32,
    /// Layer rows shown, and layers left out for want of room.
    shown: usize,
    more: usize,
}

fn legend(cv: &mut Canvas, m: &Manifest, layout: LegendLayout) {
    let LegendLayout { x, y, scale: s, line_height: lh, shown, more } = layout;
    let sw = (font::H * s) as f32;
    let tx = x + sw + (6 * s) as f32;
    let mut y = y;
    for l in m.layers.iter().take(shown) {
        cv.rect(x, y, sw, sw, layer_color(l.index), None);
        let mut notes = Vec::new();
        if l.removed > 0 {
            notes.push(format!("{} REMOVED", l.removed));
        }
        if l.pinned > 0 {
            notes.push(format!("{} PINNED", l.pinned));
        }
        let removed = if notes.is_empty() { String::new() } else { format!("  ({})", notes.join(", ")) };
        let line = format!(
            "{:<7} {:>6} AGENTS  {:>14}  FULL {:>5}  PROXY {:>5}  {:>9}{removed}",
            l.name,
            l.rendered,
            distance_range(l).to_uppercase(),
            l.lod_full,
            l.lod_proxy,
            format_bytes(l.memory_bytes)
        );
        cv.text(tx, y, s, &line, TEXT);
        y += lh;
    }
    if more > 0 {
        cv.text(tx, y, s, &format!("... AND {more} MORE LAYERS (SEE THE MANIFEST)"), DIM);
        y += lh;
    }
    cv.rect(x, y, sw, sw, SET, None);
    cv.stroke_rect(x, y, sw, sw, Pen(DIM, 1.0), None);
    cv.text(tx, y, s, "SET     BACKGROUND. COMP: SET, THEN CROWD LAYERS FAR TO NEAR", TEXT);
    y += lh;
    // Key.
    let r = 0.5 * sw;
    let cy = y + 0.5 * sw;
    let mut kx = x + r;
    let step = |cv: &mut Canvas, kx: &mut f32, label: &str| {
        *kx += cv.text(*kx + r + (4 * s) as f32, y, s, label, DIM) + r + (18 * s) as f32;
    };
    cv.circle(kx, cy, r, TEXT, None, None);
    step(cv, &mut kx, "FULL LOD");
    kx += r;
    cv.circle(kx, cy, r * 0.8, TEXT, Some(1.5), None);
    step(cv, &mut kx, "PROXY LOD");
    kx += r;
    cv.circle(kx, cy, r, DIM, None, None);
    cv.circle(kx, cy, r + 2.0, WHITE, Some(1.2), None);
    step(cv, &mut kx, "PINNED");
    kx += r;
    cv.cross(kx, cy, r + 1.0, WHITE, 1.2, None);
    step(cv, &mut kx, "REMOVED (RANKED, NOT RENDERED)");
    let dash = Stroke { width: 1.5, dash: StrokeDash::new(vec![6.0, 5.0], 0.0), ..Stroke::default() };
    let mut pb = PathBuilder::new();
    pb.move_to(kx, cy);
    pb.line_to(kx + 6.0 * r, cy);
    if let Some(path) = pb.finish() {
        cv.pm.stroke_path(&path, &paint(DIM), &dash, Transform::identity(), None);
    }
    kx += 5.0 * r;
    step(cv, &mut kx, "LAYER BOUNDARY (DISTANCE TO CAMERA)");
}
