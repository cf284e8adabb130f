// throng review: the page. Plain JavaScript, no build step, no external
// assets; everything it shows comes from this server's /api/ (docs/review.md).
"use strict";

const $ = (id) => document.getElementById(id);
const state = { shot: null, frames: [], frame: null, layers: null, layer: null, comp: [], on: new Set(), agent: null, mix: {} };

function status(msg, error) {
  const s = $("status");
  s.textContent = msg || "";
  s.className = error ? "error" : "";
}

async function api(path) {
  const r = await fetch(path);
  const body = await r.json().catch(() => ({ error: r.statusText }));
  if (!r.ok) throw new Error(body.error || r.statusText);
  return body;
}

function el(tag, text, cls) {
  const e = document.createElement(tag);
  if (text !== undefined && text !== null) e.textContent = String(text);
  if (cls) e.className = cls;
  return e;
}

function bytes(b) {
  if (b === null || b === undefined) return "-";
  const units = ["B", "KiB", "MiB", "GiB", "TiB"];
  let i = 0;
  while (b >= 1024 && i < units.length - 1) { b /= 1024; i++; }
  return (i ? b.toFixed(2) : b) + " " + units[i];
}

function table(rows, head) {
  const t = el("table");
  if (head) {
    const tr = el("tr");
    head.forEach((h) => tr.append(el("th", h)));
    t.append(tr);
  }
  for (const row of rows) {
    const tr = el("tr");
    row.forEach((c, i) => tr.append(el(i === 0 && !head ? "th" : "td", c)));
    t.append(tr);
  }
  return t;
}

// The query naming the image shown: frame, layer, and the comp's layers.
function imageQuery() {
  let q = "frame=" + encodeURIComponent(state.frame) + "&layer=" + encodeURIComponent(state.layer);
  if (state.layer === state.shot.comp_view) {
    q += "&layers=" + encodeURIComponent(state.comp.filter((l) => state.on.has(l)).join(","));
  }
  return q;
}

async function init() {
  try {
    state.shot = await api("/api/shot");
  } catch (e) {
    status("cannot read the shot: " + e.message, true);
    return;
  }
  const s = state.shot;
  $("shot-name").textContent = s.shot + " (" + s.shot_file + ")";
  document.title = "throng review: " + s.shot;
  state.frames = s.rendered_frames;
  const slider = $("frame");
  slider.max = Math.max(0, state.frames.length - 1);
  slider.value = Math.max(0, state.frames.indexOf(s.start_frame));
  slider.addEventListener("input", () => { state.frame = state.frames[+slider.value]; loadFrame(); });
  $("layer").addEventListener("change", () => { state.layer = $("layer").value; showLayer(); });
  $("view").addEventListener("change", refreshImage);
  $("noisy").addEventListener("change", refreshImage);
  $("save").addEventListener("submit", (e) => { e.preventDefault(); saveShot(); });
  $("mixer-reset").addEventListener("click", () => { state.mix = {}; buildMixer(); refreshImage(); });
  $("exposure").addEventListener("input", () => { $("exposure-label").textContent = $("exposure").value; refreshImage(); });
  $("stage").addEventListener("click", onClick);
  $("search").addEventListener("submit", (e) => {
    e.preventDefault();
    const id = $("search-id").value.trim();
    if (id !== "") selectAgent(+id);
  });
  $("image").addEventListener("load", () => { status(""); placeMarker(); });
  $("image").addEventListener("error", async () => {
    try { await api($("image").src.replace(location.origin, "")); } catch (e) { status(e.message, true); }
  });
  $("map").addEventListener("error", () => { $("map").hidden = true; $("map-note").textContent = "No layer map: the shot has no layer manifest (run throng layers)."; });
  loadMap();
  watchMapWidth();
  loadFigures();
  initLive();
  if (!state.frames.length) {
    status(live.on ? "No renders folder: the live preview, figures and map (docs/review.md)." : "No renders folder: figures and map only (docs/review.md).");
    $("viewer").hidden = true;
    return;
  }
  state.frame = state.frames[+slider.value];
  await loadFrame();
}

async function loadFrame() {
  $("frame-label").textContent = state.frame;
  if (live.on) liveStart(state.frame);
  status("loading frame " + state.frame + "...");
  try {
    state.layers = await api("/api/layers?frame=" + state.frame);
  } catch (e) {
    status(e.message, true);
    return;
  }
  const sel = $("layer");
  const names = state.layers.layers.map((l) => l.name);
  state.comp = state.layers.comp.layers || [];
  sel.textContent = "";
  if (state.comp.length) sel.append(new Option("comp: " + state.comp.slice().reverse().join(" over "), state.shot.comp_view));
  names.forEach((n) => sel.append(new Option(n, n)));
  if (!state.layer || (state.layer !== state.shot.comp_view && !names.includes(state.layer)) || (state.layer === state.shot.comp_view && !state.comp.length)) {
    state.layer = state.comp.length ? state.shot.comp_view : names[0];
    state.on = new Set(state.comp);
  }
  sel.value = state.layer;
  const list = $("toggle-list");
  list.textContent = "";
  for (const l of state.comp) {
    const label = el("label");
    const box = el("input");
    box.type = "checkbox";
    box.checked = state.on.has(l);
    box.dataset.layer = l;
    box.addEventListener("change", () => { if (box.checked) state.on.add(l); else state.on.delete(l); refreshImage(); });
    label.append(box, " " + l);
    list.append(label);
  }
  if (state.layers.comp.error) status(state.layers.comp.error);
  await showLayer();
}

function currentViews() {
  if (state.layer === state.shot.comp_view) return state.layers.comp.views || state.shot.views;
  const l = state.layers.layers.find((x) => x.name === state.layer);
  // A layer rendered with deep output also shows its deep samples per pixel.
  return l ? (l.deep ? l.views.concat([l.deep.view]) : l.views) : state.shot.views;
}

// The samples view's legend: the heat ramp from 1 sample to the layer's most
// (deep samples per pixel, /api/deep.png); hidden for every other view.
function deepLegend(view) {
  let legend = $("deep-legend");
  const l = state.layers.layers.find((x) => x.name === state.layer);
  const deep = l && l.deep && view === l.deep.view ? l.deep : null;
  if (!legend) {
    legend = el("p", null, "hint");
    legend.id = "deep-legend";
    $("stage").after(legend);
  }
  legend.hidden = !deep;
  if (!deep) return false;
  legend.textContent = "";
  const bar = el("span");
  bar.style.cssText = "display:inline-block;width:12em;height:0.9em;vertical-align:middle;margin:0 0.5em;background:linear-gradient(to right," + deep.ramp.join(",") + ")";
  legend.append("Deep samples per pixel: black 0, 1", bar, deep.max + " (the most in this layer)");
  return true;
}

async function showLayer() {
  $("toggles").hidden = state.layer !== state.shot.comp_view;
  const view = $("view");
  const was = view.value || "beauty";
  view.textContent = "";
  currentViews().forEach((v) => view.append(new Option(v, v)));
  view.value = currentViews().includes(was) ? was : "beauty";
  $("noisy-toggle").hidden = !currentViews().includes("noisy");
  buildMixer();
  await refreshImage();
}

// The light mixer: a row per light group of the image (its lg_* passes).
function mixGroups() {
  return currentViews().filter((v) => v.startsWith("lg_")).map((v) => v.slice(3));
}

function groupState(g) {
  if (!state.mix[g]) state.mix[g] = { stops: 0, tint: "#ffffff", solo: false, mute: false };
  return state.mix[g];
}

// sRGB-encoded 0..1 to linear (the colour picker's swatch is sRGB).
function srgbToLinear(c) {
  return c <= 0.04045 ? c / 12.92 : Math.pow((c + 0.055) / 1.055, 2.4);
}

// `group:gain:r:g:b,...` for the groups not at gain 1 and white: what
// /api/mix.png sums and Save as shot writes.
function mixString() {
  const groups = mixGroups();
  const solo = groups.some((g) => groupState(g).solo);
  const out = [];
  for (const g of groups) {
    const m = groupState(g);
    const gain = m.mute || (solo && !m.solo) ? 0 : Math.pow(2, m.stops);
    const hex = m.tint;
    const tint = [1, 3, 5].map((i) => +srgbToLinear(parseInt(hex.slice(i, i + 2), 16) / 255).toPrecision(6));
    if (gain !== 1 || tint.some((t) => t !== 1)) out.push([g, +gain.toPrecision(7)].concat(tint).join(":"));
  }
  return out.join(",");
}

function buildMixer() {
  const groups = mixGroups();
  const t = $("mixer");
  t.textContent = "";
  $("save").hidden = !groups.length;
  $("mixer-note").textContent = groups.length
    ? "Gains in stops, regrading the beauty from the light-group passes (the sum a render with these gains gives)."
    : "This image has no light-group passes: render it with --passes light_groups (or render.passes = [\"light_groups\"] in the shot) to mix its lights.";
  for (const g of groups) {
    const m = groupState(g);
    const tr = el("tr");
    tr.dataset.group = g;
    const slider = el("input");
    Object.assign(slider, { type: "range", min: -8, max: 8, step: 0.25, value: m.stops });
    slider.className = "gain";
    const out = el("output", (m.stops > 0 ? "+" : "") + m.stops);
    slider.addEventListener("input", () => { m.stops = +slider.value; out.textContent = (m.stops > 0 ? "+" : "") + m.stops; refreshImage(); });
    const tint = el("input");
    Object.assign(tint, { type: "color", value: m.tint, title: "tint" });
    tint.className = "tint";
    tint.addEventListener("input", () => { m.tint = tint.value; refreshImage(); });
    const box = (key, label) => {
      const l = el("label");
      const b = el("input");
      b.type = "checkbox";
      b.checked = m[key];
      b.className = key;
      b.addEventListener("change", () => { m[key] = b.checked; refreshImage(); });
      l.append(b, " " + label);
      return l;
    };
    const cells = [el("th", g), slider, out, tint, box("solo", "solo"), box("mute", "mute")];
    cells.forEach((c) => { const td = c.tagName === "TH" ? c : el("td"); if (td !== c) td.append(c); tr.append(td); });
    t.append(tr);
  }
}

async function saveShot() {
  const name = $("save-name").value.trim();
  const r = $("save-result");
  r.textContent = "";
  try {
    const resp = await fetch("/api/save-shot", {
      method: "POST",
      headers: { "Content-Type": "application/json" },
      body: JSON.stringify({ name: name, mix: mixString() }),
    });
    const body = await resp.json().catch(() => ({ error: resp.statusText }));
    if (!resp.ok) throw new Error(body.error || resp.statusText);
    const command = "throng render '" + body.file + "' --passes light_groups --out '" + body.out + "'";
    r.append(el("span", "Saved " + body.file + ". Render it with:"), el("code", command));
    r.dataset.file = body.file;
  } catch (e) {
    r.append(el("span", "Not saved: " + e.message, "error"));
  }
}

async function refreshImage() {
  if (!state.layers) return;
  const q = imageQuery();
  let view = $("view").value;
  if (view === "beauty" && $("noisy").checked && currentViews().includes("noisy")) view = "noisy";
  const mix = view === "beauty" ? mixString() : "";
  $("image").src = deepLegend(view)
    ? "/api/deep.png?" + q
    : mix
    ? "/api/mix.png?" + q + "&mix=" + encodeURIComponent(mix) + "&exposure=" + $("exposure").value
    : "/api/image.png?" + q + "&view=" + encodeURIComponent(view) + "&exposure=" + $("exposure").value;
  loadVisible(q);
  if (state.agent !== null) await selectAgent(state.agent, true);
}

async function loadVisible(q) {
  const list = $("visible-list");
  try {
    const r = await api("/api/agents?" + q);
    list.textContent = "";
    for (const a of r.agents.slice(0, 15)) {
      const li = el("li");
      const link = el("a", "agent " + a.id);
      link.href = "#";
      link.dataset.agent = a.id;
      link.addEventListener("click", (e) => { e.preventDefault(); selectAgent(a.id); });
      li.append(link, " " + a.pixels + " px");
      list.append(li);
    }
    if (!r.agents.length) list.append(el("li", "no agents in this image", "dim"));
  } catch (e) {
    list.textContent = "";
  }
}

function pixelOf(event) {
  const img = $("image");
  const r = img.getBoundingClientRect();
  const x = Math.floor((event.clientX - r.left) * img.naturalWidth / r.width);
  const y = Math.floor((event.clientY - r.top) * img.naturalHeight / r.height);
  return [Math.min(Math.max(x, 0), img.naturalWidth - 1), Math.min(Math.max(y, 0), img.naturalHeight - 1)];
}

async function onClick(event) {
  if (!$("image").naturalWidth) return;
  const [x, y] = pixelOf(event);
  try {
    const r = await api("/api/pick?" + imageQuery() + "&x=" + x + "&y=" + y);
    state.marker = [x, y];
    placeMarker();
    if (r.agent === null) {
      state.agent = null;
      const b = $("botinfo");
      b.textContent = "";
      b.removeAttribute("data-agent-id");
      b.append(el("p", "No agent at pixel " + x + "," + y + " of " + r.layer + " (set or sky)."));
      $("matte").hidden = true;
      loadMap();
      status("");
      return;
    }
    state.agent = r.agent;
    showBotInfo(r.botinfo[0], botinfoCommand(r.file, x, y), "pixel " + x + "," + y + " of " + r.layer + ", frame " + r.frame);
    showMatte();
    loadMap();
    status("");
  } catch (e) {
    status(e.message, true);
  }
}

// The command line that prints the same botInfo (a layer file; the comp
// needs throng comp's file first).
function botinfoCommand(file, x, y) {
  if (!file) return null;
  const manifest = state.shot.manifest ? " --manifest " + state.shot.manifest : "";
  return "throng botinfo " + state.shot.shot_file + " --exr " + file + " --pixel " + x + "," + y + manifest + " --json";
}

// An agent by id: its botInfo at this frame, its matte, and where it is.
async function selectAgent(id, quiet) {
  try {
    const r = await api("/api/agent?" + imageQuery() + "&id=" + id);
    state.agent = id;
    state.marker = r.pixel;
    placeMarker();
    const where = r.pixel ? "at pixel " + r.pixel.join(",") + " (" + r.pixels + " px) of " + state.layer : "not visible in " + state.layer;
    showBotInfo(r.botinfo[0], null, "frame " + r.frame + ", " + where);
    showMatte();
    loadMap();
    if (!quiet) status("");
  } catch (e) {
    if (!quiet) status(e.message, true);
    else { $("botinfo").textContent = e.message; $("botinfo").removeAttribute("data-agent-id"); $("matte").hidden = true; }
  }
}

function placeMarker() {
  const m = $("marker");
  const img = $("image");
  if (!state.marker || !img.naturalWidth) { m.hidden = true; return; }
  const [x, y] = state.marker;
  m.style.left = ((x + 0.5) / img.naturalWidth * 100) + "%";
  m.style.top = ((y + 0.5) / img.naturalHeight * 100) + "%";
  m.hidden = false;
}

function showMatte() {
  const m = $("matte");
  m.src = "/api/matte.png?" + imageQuery() + "&id=" + state.agent;
  m.hidden = false;
}

function loadMap() {
  const img = $("map");
  img.hidden = false;
  $("map-note").textContent = state.agent !== null ? "Agent " + state.agent + " is ringed in yellow." : "";
  // Drawn at the width it is shown (CSS pixels), so the map's text is the
  // font's own size on screen (7 px and up) instead of a 1600-pixel map
  // shrunk to a third of that.
  const w = mapContentWidth(img);
  img.dataset.askedWidth = w;
  img.src = "/api/map.png?w=" + w + (state.agent !== null ? "&agent=" + state.agent : "");
}

// The width the map is shown at: its panel's content box (clientWidth counts
// the panel's padding too).
function mapContentWidth(img) {
  const panel = img.parentElement, cs = getComputedStyle(panel);
  const w = panel.clientWidth - parseFloat(cs.paddingLeft) - parseFloat(cs.paddingRight);
  return Math.round(w > 0 ? w : 800);
}

// The shown width changes after the first request (a scrollbar appears as the
// panels fill, the window is resized): ask again, once the width settles, so
// the map stays drawn at the size it is shown.
let mapResizeTimer = null;
function watchMapWidth() {
  const img = $("map");
  new ResizeObserver(() => {
    if (img.hidden || !img.dataset.askedWidth) return;
    clearTimeout(mapResizeTimer);
    mapResizeTimer = setTimeout(() => {
      const w = mapContentWidth(img);
      if (Math.abs(w - Number(img.dataset.askedWidth)) > 1) loadMap();
    }, 150);
  }).observe(img.parentElement);
}

function showBotInfo(b, command, where) {
  const box = $("botinfo");
  box.textContent = "";
  box.dataset.agentId = b.id;
  box.append(el("p", "Agent ID " + b.id, "big"));
  box.append(el("p", where, "dim"));
  const f = (v, d) => (typeof v === "number" ? v.toFixed(d) : v);
  const rows = [
    ["Rig", b.rig + " (" + b.kind + ")"],
    ["Cycle", b.cycle],
    ["Cycle frame", f(b.cycle_frame, 2) + " at shot frame " + b.shot_frame],
    ["Scheme", b.scheme],
    ["Height scale", f(b.height_scale, 3) + (b.seated ? " (seated)" : "")],
    ["Layer", b.layer === null ? "- (no manifest)" : b.layer + (b.removed ? " REMOVED" : "")],
    ["LOD", b.lod === null ? "-" : b.lod],
    ["Position", b.position.map((v) => v.toFixed(2)).join(" ")],
    ["Heading", f(b.heading_deg, 1) + " deg"],
    ["Distance", f(b.distance, 2) + " m"],
  ];
  if (b.pose) rows.push(["Pose", b.pose + " (shared by every agent on it)"]);
  box.append(table(rows));
  box.append(el("h2", "Parts and materials"));
  box.append(table(b.parts.map((p) => [p.slot, p.mesh || "-", p.material || "-"]), ["slot", "mesh", "material"]));
  if (b.props && b.props.length) {
    box.append(el("h2", "Props"));
    box.append(table(b.props.map((p) => [p.name, p.mesh, p.material || "-", p.on]), ["prop", "mesh", "material", "on"]));
  }
  if (command) {
    box.append(el("p", "The same, on the command line:", "dim"));
    box.append(el("code", command));
  }
}

async function loadFigures() {
  const box = $("figures");
  let fig;
  try {
    fig = await api("/api/figures");
  } catch (e) {
    box.textContent = e.message;
    return;
  }
  box.textContent = "";
  const c = fig.cast;
  const cast = [
    ["Agents", c.agents],
    ["Part instances", c.part_instances],
    ["Unique parts", c.unique_parts],
    ["Unique materials", c.unique_materials],
    ["Unique geometry", bytes(c.unique_geometry_bytes)],
    ["If copied per agent", bytes(c.copied_geometry_bytes)],
  ];
  if (c.skinned) {
    cast.push(["Skinned agents", c.skinned.agents], ["Unique poses", c.skinned.unique_poses]);
  }
  box.append(el("h2", "Casting"), table(cast));
  if (fig.layers) {
    box.append(el("h2", "Layers (ranked at frame " + fig.ref_frame + ")"));
    const rows = fig.layers.map((l) => [
      l.name,
      l.agents,
      l.distance_min_m === undefined || l.distance_min_m === null ? "" : l.distance_min_m.toFixed(1) + "-" + l.distance_max_m.toFixed(1) + " m",
      bytes(l.estimated_bytes),
      l.measured ? bytes(l.measured.peak_rss_bytes) : "-",
    ]);
    box.append(table(rows, ["layer", "agents", "distance", "memory (estimated)", "measured"]));
    if (!fig.summaries.length) box.append(el("p", "Measured memory appears when the render's JSON summaries are saved in the renders folder (docs/review.md).", "dim"));
    const p = fig.pops_avoided;
    box.append(el("p", p.measured
      ? "Pops avoided: per-frame ranking would move " + p.agents_changed + " agents between layers (" + p.changes + " changes); fixed-frame ranking moves none."
      : "Pops avoided: fixed-frame ranking moves no agent between layers (per-frame pops were not measured for this manifest; docs/layers.md)."));
    box.append(el("p", "Manifest: " + fig.manifest, "dim"));
  } else {
    box.append(el("p", "No layer manifest: run throng layers on the shot for layers, LOD and the map.", "dim"));
  }
}


// The live preview (`throng review --live`, docs/review.md): the frame
// rendered on the server as the shot file changes, polled a few times a
// second (a page that stops polling lets it stop).
const live = { on: false, image: 0, timer: null };

async function postJson(path, body) {
  const r = await fetch(path, { method: "POST", headers: { "Content-Type": "application/json" }, body: JSON.stringify(body || {}) });
  const answer = await r.json().catch(() => ({ error: r.statusText }));
  if (!r.ok) throw new Error(answer.error || r.statusText);
  return answer;
}

function initLive() {
  if (!state.shot.live) return;
  live.on = true;
  $("live").hidden = false;
  const f = $("live-frame");
  [f.min, f.max] = state.shot.frames;
  f.addEventListener("change", () => liveStart(+f.value));
  $("live-stop").addEventListener("click", async () => { try { showLive(await postJson("/api/live/stop")); } catch (e) { status(e.message, true); } });
  $("live-start").addEventListener("click", () => liveStart(+f.value));
  $("live-noisy").addEventListener("change", liveImage);
  $("exposure").addEventListener("input", liveImage);
  $("live-image").addEventListener("load", () => { $("live-image").dataset.image = $("live-image").dataset.asked; });
  pollLive();
}

async function liveStart(frame) {
  try {
    showLive(await postJson("/api/live/start", Number.isFinite(frame) ? { frame: frame } : {}));
  } catch (e) {
    status("live: " + e.message, true);
  }
}

async function pollLive() {
  try {
    showLive(await api("/api/live"));
  } catch (e) {
    $("live-status").textContent = "live: " + e.message;
  }
  live.timer = setTimeout(pollLive, 250);
}

function showLive(s) {
  const running = s.run === "running";
  $("live-stop").hidden = !running;
  $("live-start").hidden = running;
  const f = $("live-frame");
  if (document.activeElement !== f) f.value = s.asked_frame;
  const parts = [];
  if (!running) parts.push(s.run === "idle" ? "stopped: no page was polling" : "stopped");
  if (s.state === "loading") parts.push("reading the shot...");
  if (s.frame !== null) {
    parts.push("frame " + s.frame + " at " + s.width + "x" + s.height + ": " + s.spp + " of " + s.max_spp + " spp (pass " + s.pass + ", " + s.elapsed_s.toFixed(1) + " s)");
  }
  if (s.image) {
    parts.push(s.denoised ? "denoised at " + s.denoised_spp + " spp (" + s.denoiser + ")" : "noisy" + (s.denoise_note ? " (no denoiser: " + s.denoise_note + ")" : ""));
  }
  if (s.reload && s.reload !== "start" && s.frame !== null) parts.push("after: " + s.reload);
  $("live-status").textContent = parts.join("; ");
  const err = $("live-error");
  err.hidden = !s.error;
  err.textContent = s.error ? s.error.message + (s.image ? " (the image is of the last shot that read)" : "") : "";
  if (s.image !== live.image) {
    live.image = s.image;
    liveImage();
  }
}

function liveImage() {
  if (!live.image) return;
  const img = $("live-image");
  img.dataset.asked = live.image;
  img.src = "/api/live.png?image=" + live.image + "&exposure=" + $("exposure").value + ($("live-noisy").checked ? "&noisy=1" : "");
}

init();
