// hcard view: the page. It computes nothing of its own: the maps, profiles, spectra and every
// rendering come from the local server's JSON API (hcard/view/server.py). What it drew last is
// kept in window.hcardView for tests and for the curious (the plotted polylines in canvas
// pixels, with the numbers they were drawn from).
"use strict";

const view = {
  cards: [],            // /api/cards
  stroke: [],           // the drawn path, [[x_mm, y_mm], ...]
  track: null,          // a loaded track: {name, csv}
  selected: null,       // {card, texture, col, row}
  lastRender: null,     // the /api/render answer
  lastProfile: null,    // the /api/texture answer
  plots: {},            // canvas id -> {points: [[px, py], ...], x: [lo, hi], y: [lo, hi], box}
  surfaces: [],         // per card: {canvas, scale, left, top}
};
window.hcardView = view;

const $ = (id) => document.getElementById(id);
const PALETTE = ["#4e79a7", "#f28e2b", "#59a14f", "#e15759", "#76b7b2", "#edc948",
                 "#b07aa1", "#ff9da7", "#9c755f", "#bab0ac"];
const textureColour = (i) => PALETTE[i % PALETTE.length];

async function api(path, body) {
  const init = body === undefined ? {} : {method: "POST", body: JSON.stringify(body),
                                          headers: {"Content-Type": "application/json"}};
  const answer = await fetch(path, init);
  const value = await answer.json();
  if (!answer.ok) throw new Error(value.error || answer.statusText);
  return value;
}

function status(text, isError) {
  $("status").textContent = text;
  $("status").className = isError ? "error" : "";
}

// --- plots ---------------------------------------------------------------------------------

function niceTicks(lo, hi, count) {
  const step0 = (hi - lo) / Math.max(count, 1);
  const power = Math.pow(10, Math.floor(Math.log10(step0)));
  const step = [1, 2, 5, 10].map((m) => m * power).find((s) => s >= step0) || step0;
  const ticks = [];
  for (let v = Math.ceil(lo / step) * step; v <= hi + step * 1e-9; v += step) ticks.push(v);
  return ticks;
}

function extent(values) {  // [min, max] without spreading a long array into arguments
  let lo = Infinity, hi = -Infinity;
  for (const v of values) { if (v < lo) lo = v; if (v > hi) hi = v; }
  return [lo, hi];
}

function fmt(v) { return Math.abs(v) >= 1000 || (v !== 0 && Math.abs(v) < 0.01)
  ? v.toExponential(1) : String(+v.toFixed(3)); }

// Draws series [{x, y, colour, stems}] on a canvas with axes; keeps the first series' pixel
// polyline in view.plots[canvas.id].
function plot(canvas, series, labels) {
  const ctx = canvas.getContext("2d");
  const box = {left: 58, top: 18, right: canvas.width - 12, bottom: canvas.height - 30};
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  const xs = series.flatMap((s) => s.x), ys = series.flatMap((s) => s.y);
  let [x0, x1] = extent(xs), [y0, y1] = extent(ys);
  if (labels.yFrom !== undefined) y0 = Math.min(y0, labels.yFrom);
  if (labels.xFrom !== undefined) { x0 = Math.min(x0, labels.xFrom); x1 += 0.08 * (x1 - x0); }
  if (x1 <= x0) x1 = x0 + 1;
  if (y1 - y0 < 1e-6) { y0 -= 0.05; y1 += 0.05; }
  const pad = 0.06 * (y1 - y0); y0 -= pad; y1 += pad;
  const px = (x) => box.left + (x - x0) / (x1 - x0) * (box.right - box.left);
  const py = (y) => box.bottom - (y - y0) / (y1 - y0) * (box.bottom - box.top);
  ctx.font = "11px sans-serif"; ctx.strokeStyle = "#ddd"; ctx.fillStyle = "#444";
  ctx.textAlign = "right";
  for (const v of niceTicks(y0, y1, 4)) {
    ctx.beginPath(); ctx.moveTo(box.left, py(v)); ctx.lineTo(box.right, py(v)); ctx.stroke();
    ctx.fillText(fmt(v), box.left - 4, py(v) + 4);
  }
  ctx.textAlign = "center";
  for (const v of niceTicks(x0, x1, 8)) ctx.fillText(fmt(v), px(v), box.bottom + 14);
  ctx.fillText(labels.x, (box.left + box.right) / 2, canvas.height - 3);
  ctx.save(); ctx.translate(12, (box.top + box.bottom) / 2); ctx.rotate(-Math.PI / 2);
  ctx.fillText(labels.y, 0, 0); ctx.restore();
  ctx.strokeStyle = "#888"; ctx.strokeRect(box.left, box.top, box.right - box.left,
                                           box.bottom - box.top);
  const kept = [];
  series.forEach((s, k) => {
    ctx.strokeStyle = s.colour || "#1f4e99"; ctx.lineWidth = 1.2; ctx.beginPath();
    for (let i = 0; i < s.x.length; i++) {
      const p = [px(s.x[i]), py(s.y[i])];
      if (k === 0) kept.push(p);
      if (s.stems) { ctx.moveTo(p[0], py(0)); ctx.lineTo(p[0], p[1]); }
      else if (i === 0) ctx.moveTo(p[0], p[1]);
      else ctx.lineTo(p[0], p[1]);
    }
    ctx.stroke();
  });
  view.plots[canvas.id] = {points: kept, x: [x0, x1], y: [y0, y1], box: box};
  canvas.dataset.points = String(kept.length);
}

// --- surface maps --------------------------------------------------------------------------

// Draws a grid of values (or the texture index) to scale; returns the mm-to-pixel mapping.
function drawGrid(canvas, widthMm, heightMm, grid, colourOf) {
  const ctx = canvas.getContext("2d");
  const margin = {left: 40, top: 12, right: 10, bottom: 30};
  const scale = Math.min((canvas.width - margin.left - margin.right) / widthMm,
                         (canvas.height - margin.top - margin.bottom) / heightMm);
  const map = {scale: scale, left: margin.left, top: margin.top};
  ctx.clearRect(0, 0, canvas.width, canvas.height);
  for (let r = 0; r < grid.rows; r++) {
    for (let c = 0; c < grid.cols; c++) {
      const x = c * grid.taxtel_width_mm, y = r * grid.taxtel_height_mm;
      const w = Math.min(grid.taxtel_width_mm, widthMm - x);
      const h = Math.min(grid.taxtel_height_mm, heightMm - y);
      if (w <= 0 || h <= 0) continue;
      ctx.fillStyle = colourOf(r, c);
      ctx.fillRect(map.left + x * scale, map.top + y * scale, w * scale, h * scale);
    }
  }
  ctx.strokeStyle = "#333"; ctx.strokeRect(map.left, map.top, widthMm * scale, heightMm * scale);
  ctx.fillStyle = "#444"; ctx.font = "11px sans-serif"; ctx.textAlign = "center";
  for (const v of niceTicks(0, widthMm, 6)) ctx.fillText(fmt(v), map.left + v * scale,
                                                         map.top + heightMm * scale + 13);
  ctx.fillText("x (mm)", map.left + widthMm * scale / 2, map.top + heightMm * scale + 26);
  ctx.textAlign = "right";
  for (const v of niceTicks(0, heightMm, 5)) ctx.fillText(fmt(v), map.left - 4,
                                                          map.top + v * scale + 4);
  return map;
}

function drawSurface(k) {
  const card = view.cards[k], s = view.surfaces[k], grid = card.grid;
  const colourOf = (r, c) => textureColour(grid.texture_index[r * grid.cols + c]);
  Object.assign(s, drawGrid(s.canvas, card.surface.width_mm, card.surface.height_mm, grid,
                            colourOf));
  const ctx = s.canvas.getContext("2d");
  const sel = view.selected;
  if (sel && sel.card === k) {
    ctx.strokeStyle = "#000"; ctx.lineWidth = 2;
    ctx.strokeRect(s.left + sel.col * grid.taxtel_width_mm * s.scale,
                   s.top + sel.row * grid.taxtel_height_mm * s.scale,
                   grid.taxtel_width_mm * s.scale, grid.taxtel_height_mm * s.scale);
    ctx.lineWidth = 1;
  }
  const path = view.stroke.length ? view.stroke : (view.lastRender ? pairs(view.lastRender.track)
                                                                   : []);
  if (path.length) {
    ctx.strokeStyle = "#000"; ctx.lineWidth = 2; ctx.beginPath();
    path.forEach(([x, y], i) => (i ? ctx.lineTo : ctx.moveTo).call(
      ctx, s.left + x * s.scale, s.top + y * s.scale));
    ctx.stroke(); ctx.lineWidth = 1;
  }
}

function pairs(track) { return track.x_mm.map((x, i) => [x, track.y_mm[i]]); }

function toMm(k, event) {
  const s = view.surfaces[k], rect = s.canvas.getBoundingClientRect();
  const cx = (event.clientX - rect.left) * s.canvas.width / rect.width;
  const cy = (event.clientY - rect.top) * s.canvas.height / rect.height;
  return [(cx - s.left) / s.scale, (cy - s.top) / s.scale];
}

function buildSurfaces() {
  const holder = $("surfaces");
  view.cards.forEach((card, k) => {
    const figure = document.createElement("figure");
    figure.className = "surface";
    const canvas = document.createElement("canvas");
    canvas.id = "surface-" + k; canvas.width = 460; canvas.height = 340;
    canvas.dataset.cols = card.grid.cols; canvas.dataset.rows = card.grid.rows;
    const caption = document.createElement("figcaption");
    caption.textContent = `${card.name}: ${card.surface.width_mm} x ${card.surface.height_mm} mm, `
      + `${card.grid.cols} x ${card.grid.rows} taxtels of ${card.grid.taxtel_width_mm} x `
      + `${card.grid.taxtel_height_mm} mm, ${card.textures.length} texture(s)`;
    figure.append(canvas, caption); holder.append(figure);
    view.surfaces[k] = {canvas: canvas};
    const option = document.createElement("option");
    option.value = k; option.textContent = card.name; $("render-card").append(option);
    attachPointer(k, canvas);
    drawSurface(k);
  });
}

// A press and release without moving selects the taxtel; a drag draws the stroke.
function attachPointer(k, canvas) {
  let down = null;
  canvas.addEventListener("pointerdown", (e) => {
    canvas.setPointerCapture(e.pointerId);
    down = {start: toMm(k, e), moved: false, before: [view.stroke, view.track]};
    view.stroke = [down.start];
  });
  canvas.addEventListener("pointermove", (e) => {
    if (!down) return;
    const p = toMm(k, e), last = view.stroke[view.stroke.length - 1];
    if (Math.hypot(p[0] - last[0], p[1] - last[1]) > 1e-9) { view.stroke.push(p); down.moved = true; }
    drawAll();
  });
  canvas.addEventListener("pointerup", (e) => {
    if (!down) return;
    const p = toMm(k, e), last = view.stroke[view.stroke.length - 1];
    if (Math.hypot(p[0] - last[0], p[1] - last[1]) > 1e-9) { view.stroke.push(p); down.moved = true; }
    if (!down.moved) {  // a click: the stroke stays as it was
      [view.stroke, view.track] = down.before; selectTaxtel(k, down.start);
    } else { view.track = null; $("render-card").value = k; strokeInfo(); }
    down = null; drawAll();
  });
}

function drawAll() { view.cards.forEach((_, k) => drawSurface(k)); }

function strokeInfo() {
  let text;
  if (view.track) text = `track ${view.track.name}` + ($("retime").checked
    ? `, re-timed at ${$("speed").value} mm/s` : ", at its own times");
  else if (view.stroke.length > 1) {
    let length = 0;
    for (let i = 1; i < view.stroke.length; i++) {
      length += Math.hypot(view.stroke[i][0] - view.stroke[i - 1][0],
                           view.stroke[i][1] - view.stroke[i - 1][1]);
    }
    text = `drawn stroke: ${view.stroke.length} points, ${length.toFixed(1)} mm`;
  } else text = "no stroke yet: drag on a surface map, or load a track CSV";
  $("stroke-info").textContent = text;
}

// --- texture -------------------------------------------------------------------------------

async function selectTaxtel(k, [x, y]) {
  const grid = view.cards[k].grid;
  const col = Math.floor(x / grid.taxtel_width_mm), row = Math.floor(y / grid.taxtel_height_mm);
  if (col < 0 || row < 0 || col >= grid.cols || row >= grid.rows) return;
  view.selected = {card: k, texture: grid.texture_index[row * grid.cols + col], col, row};
  drawAll();
  await showTexture();
}

async function showTexture() {
  const sel = view.selected;
  if (!sel) return;
  const length = $("profile-length").value;
  try {
    const p = await api(`/api/texture?card=${sel.card}&texture=${sel.texture}`
                        + `&length_mm=${encodeURIComponent(length)}`);
    view.lastProfile = p;
    const t = view.cards[sel.card].textures[sel.texture];
    $("texture-title").textContent = `${view.cards[sel.card].name}, taxtel (col ${sel.col}, `
      + `row ${sel.row}): texture ${sel.texture}${t.name ? " '" + t.name + "'" : ""}, `
      + `${t.channel}, ${t.locking}, baseline ${fmt(t.baseline)}; profile along `
      + `${fmt(p.direction_rad * 180 / Math.PI)} deg over ${fmt(p.length_mm)} mm`;
    plot($("plot-profile"), [{x: p.s_mm, y: p.friction, colour: textureColour(sel.texture)}],
         {x: "distance along the texture's main direction (mm)", y: "μ/μ0"});
    const lines = p.spectrum.length ? p.spectrum : [{frequency_along: 0, amplitude: 0}];
    plot($("plot-spectrum"), [{x: lines.map((c) => c.frequency_along),
                               y: lines.map((c) => c.amplitude), stems: true}],
         {x: "spatial frequency along it (cycles/mm)", y: "amplitude", yFrom: 0, xFrom: 0});
    const rows = t.components.map((c) => `<tr><td>${c.domain}</td><td>${fmt(c.frequency)} `
      + `${c.unit}</td><td>${fmt(c.amplitude)}</td><td>${fmt(c.phase_rad)}</td>`
      + `<td>${fmt(c.orientation_rad * 180 / Math.PI)}°</td><td>${c.channel}</td></tr>`);
    $("components").innerHTML = "<tr><th>domain</th><th>frequency</th><th>amplitude</th>"
      + "<th>phase (rad)</th><th>orientation</th><th>channel</th></tr>" + rows.join("");
  } catch (err) { status(err.message, true); }
}

// --- render and play -----------------------------------------------------------------------

function strokeRequest() {
  const body = {card: Number($("render-card").value),
                frame_rate_hz: Number($("frame-rate").value)};
  const speed = Number($("speed").value);
  if (view.track) {
    body.track_csv = view.track.csv;
    if ($("retime").checked) body.speed_mm_s = speed;
  } else if (view.stroke.length > 1) {
    body.path = view.stroke; body.speed_mm_s = speed;
  } else throw new Error("draw a stroke on a surface map (or load a track CSV) first");
  return body;
}

async function render() {
  try {
    const body = strokeRequest();
    status("rendering...");
    view.lastRender = await api("/api/render", body);
    view.renderedRequest = body;
    plotRender();
    const s = view.lastRender.summary;
    status(`rendered ${s.frames} frames at ${view.lastRender.frame_rate_hz} Hz over `
           + `${fmt(s.duration_s)} s and ${fmt(s.length_mm)} mm: friction ${fmt(s.friction_min)}`
           + `..${fmt(s.friction_max)}`);
    drawAll();
  } catch (err) { status(err.message, true); }
}

function plotRender() {
  const r = view.lastRender;
  if (!r) return;
  const byTime = $("x-axis").value === "time";
  const x = byTime ? r.frames.t_s : r.frames.distance_mm;
  const xLabel = byTime ? "time (s)" : "distance along the stroke (mm)";
  plot($("plot-friction"), [{x, y: r.frames.friction, colour: "#222"}],
       {x: xLabel, y: "friction μ/μ0"});
  plot($("plot-uv"), [{x, y: r.frames.uv, colour: "#1f77b4"}], {x: xLabel, y: "UV drive"});
  plot($("plot-ev"), [{x, y: r.frames.ev, colour: "#d62728"}], {x: xLabel, y: "EV drive"});
}

async function playOnDevice() {
  try {
    const body = strokeRequest();
    status("playing on the device...");
    const result = await api("/api/play", body);
    view.lastPlay = result;
    $("play-result").hidden = false;
    $("play-summary").textContent = result.summary.join("\n");
    plot($("plot-played"), [{x: result.reports.t_s, y: result.reports.friction}],
         {x: "device time (s)", y: "device target μ/μ0"});
    status(`played on ${result.device}`);
  } catch (err) { status(err.message, true); }
}

// --- difference and error maps -------------------------------------------------------------

// Blues up to 1 JND, then yellow to red (the colours of hcard preview's error map).
function jndColour(value, top) {
  if (value === null) return "#eee";
  if (value <= 1) {
    const l = 92 - 45 * value;
    return `hsl(210, 70%, ${l}%)`;
  }
  const f = Math.min(1, (value - 1) / Math.max(top - 1, 1e-9));
  return `hsl(${50 - 50 * f}, 90%, ${60 - 25 * f}%)`;
}

function drawJndMap(canvas, map, values) {
  const top = Math.max(2, extent(values.flat().filter((v) => v !== null))[1]);
  const grid = {rows: map.rows, cols: map.cols, taxtel_width_mm: map.taxtel_width_mm,
                taxtel_height_mm: map.taxtel_height_mm};
  drawGrid(canvas, map.cols * map.taxtel_width_mm, map.rows * map.taxtel_height_mm, grid,
           (r, c) => jndColour(values[r][c], top));
  canvas.dataset.values = JSON.stringify(values);
}

async function showDiff() {
  const d = await api("/api/diff?a=0&b=1");
  view.lastDiff = d;
  $("diff-section").hidden = false;
  const inJnd = d.rms.map((row) => row.map((v) => (v === null ? null : v / d.jnd)));
  drawJndMap($("diff-map"), d, inJnd);
  const differing = d.same_texture.flat().filter((same) => !same).length;
  $("diff-title").textContent = `${view.cards[1].name} − ${view.cards[0].name} on the first's `
    + `grid: RMS of the friction difference per taxtel in JND (1 JND = ${d.jnd}); `
    + `${differing} taxtel(s) play another texture, largest ${fmt((d.largest_rms || 0) / d.jnd)}`
    + " JND";
}

async function showErrorMap() {
  const e = await api("/api/error-map");
  view.lastErrorMap = e;
  $("error-section").hidden = false;
  drawJndMap($("error-map"), e, e.error_jnd);
  $("error-title").textContent = `${view.cards[0].name} against ${e.source} (${e.width_px} x `
    + `${e.height_px} px, black = ${e.black}, white = ${e.white}): ${e.label} per taxtel in `
    + `JND; ${e.above_1_jnd} taxtel(s) above 1 JND, largest ${fmt(e.largest_jnd || 0)}`;
}

// --- start ---------------------------------------------------------------------------------

async function start() {
  try {
    const answer = await api("/api/cards");
    view.cards = answer.cards;
    buildSurfaces();
    if (answer.device) {
      $("play").disabled = false;
      $("play-reason").textContent = `device: ${answer.device}`;
    } else {
      $("play").title = answer.play_disabled_reason;
      $("play-reason").textContent = answer.play_disabled_reason;
    }
    if (view.cards.length > 1) await showDiff();
    if (answer.error_map) await showErrorMap();
    status(`${view.cards.length} card(s) loaded`);
    document.body.dataset.ready = "true";
  } catch (err) { status(err.message, true); }
}

$("render").addEventListener("click", render);
$("play").addEventListener("click", playOnDevice);
$("clear").addEventListener("click", () => { view.stroke = []; view.track = null;
                                             $("track-file").value = ""; strokeInfo(); drawAll(); });
$("x-axis").addEventListener("change", plotRender);
$("profile-length").addEventListener("change", showTexture);
$("retime").addEventListener("change", strokeInfo);
$("speed").addEventListener("change", strokeInfo);
$("track-file").addEventListener("change", async (e) => {
  const file = e.target.files[0];
  if (!file) return;
  view.track = {name: file.name, csv: await file.text()};
  view.stroke = []; strokeInfo(); drawAll();
});
start();
