// jaxmatch label: the page. Plain JS, no build step. Talks to the JSON API of jaxmatch/label/app.py.
"use strict";

// colours of jaxmatch/io/plot.py (jaxmatch mesh --png)
const VALENCE_COLOURS = {2: "#1f77b4", 3: "#2ca02c", 4: "#ff7f0e", 5: "#9467bd"};
const CODE_COLOURS = {s: "#7f7f7f", x: "#000000", v: "#8c564b"};
const QUAD_COLOUR = "#dbe9f6", EDGE_COLOUR = "#1b2a41", OUTLINE_COLOUR = "#b0b0b0", INVERTED_COLOUR = "#d62728";
const SVGNS = "http://www.w3.org/2000/svg";

const $ = (id) => document.getElementById(id);
let state = null;        // GET /api/state
let current = 0;         // index of the shape shown
let shown = null;        // GET /api/shapes/{current}
let busy = false;

function message(text, kind) {
  const m = $("msg");
  m.textContent = text || "";
  m.className = "msg" + (kind ? " " + kind : "");
}

async function api(method, url, body, raw) {
  const opts = {method, headers: {}};
  if (raw !== undefined) { opts.body = raw; opts.headers["Content-Type"] = "application/octet-stream"; }
  else if (body !== undefined) { opts.body = JSON.stringify(body); opts.headers["Content-Type"] = "application/json"; }
  const res = await fetch(url, opts);
  let data = null;
  try { data = await res.json(); } catch (e) { data = {error: res.status + " " + res.statusText}; }
  if (!res.ok) throw new Error(data && data.error ? data.error : res.status + " " + res.statusText);
  return data;
}

function el(name, attrs, parent) {
  const e = document.createElementNS(SVGNS, name);
  for (const [k, v] of Object.entries(attrs || {})) e.setAttribute(k, v);
  if (parent) parent.appendChild(e);
  return e;
}

// An SVG of the shape (outline, s/x/v points) and optionally a placed mesh. y points up.
function drawSVG(svg, data, cand) {
  svg.innerHTML = "";
  const pts = data.outline.slice();
  if (cand) pts.push(...cand.xy);
  let [x0, y0, x1, y1] = [Infinity, Infinity, -Infinity, -Infinity];
  for (const [x, y] of pts) { x0 = Math.min(x0, x); x1 = Math.max(x1, x); y0 = Math.min(y0, y); y1 = Math.max(y1, y); }
  const ext = Math.max(x1 - x0, y1 - y0) || 1, pad = 0.08 * ext;
  svg.setAttribute("viewBox", `${x0 - pad} ${-y1 - pad} ${x1 - x0 + 2 * pad} ${y1 - y0 + 2 * pad}`);
  svg.setAttribute("preserveAspectRatio", "xMidYMid meet");
  const g = el("g", {transform: "scale(1,-1)"}, svg);
  const r = (cand ? 0.022 : 0.03) * ext;
  const poly = (p) => p.map(([x, y]) => `${x},${y}`).join(" ");
  if (cand) {
    const xy = cand.xy;
    for (const q of cand.quads) {
      const c = q.map((i) => xy[i]);
      el("polygon", {points: poly(c), fill: QUAD_COLOUR, stroke: "none"}, g);
    }
  }
  el("polygon", {points: poly(data.outline), fill: "none", stroke: OUTLINE_COLOUR, "stroke-width": 3,
                 "vector-effect": "non-scaling-stroke", "stroke-linejoin": "round"}, g);
  if (cand) {
    const xy = cand.xy;
    for (const q of cand.quads) {
      el("polygon", {points: poly(q.map((i) => xy[i])), fill: "none", stroke: EDGE_COLOUR, "stroke-width": 1,
                     "vector-effect": "non-scaling-stroke"}, g);
    }
  }
  for (const p of data.points) {
    const col = CODE_COLOURS[p.code];
    if (p.code === "s") el("circle", {cx: p.x, cy: p.y, r: r * 0.35, fill: col}, g);
    else if (p.code === "x") el("path", {d: `M${p.x - r * .7},${p.y - r * .7}L${p.x + r * .7},${p.y + r * .7}M${p.x - r * .7},${p.y + r * .7}L${p.x + r * .7},${p.y - r * .7}`,
                                      stroke: col, "stroke-width": 2.5, "vector-effect": "non-scaling-stroke"}, g);
    else el("polygon", {points: `${p.x - r * .8},${p.y + r * .7} ${p.x + r * .8},${p.y + r * .7} ${p.x},${p.y - r * .7}`, fill: col}, g);
  }
  if (cand) {
    for (const i of cand.boundary) {
      const [x, y] = cand.xy[i];
      el("circle", {cx: x, cy: y, r: r, fill: "none", stroke: VALENCE_COLOURS[cand.valence[i]] || "#7f7f7f",
                    "stroke-width": 2.2, "vector-effect": "non-scaling-stroke", class: "bv", "data-valence": cand.valence[i]}, g);
    }
  }
}

function renderState() {
  $("progress").textContent = `labelled ${state.labelled} / ${state.total}`;
  const list = $("shapes");
  list.innerHTML = "";
  state.shapes.forEach((s, i) => {
    const li = document.createElement("li");
    li.textContent = s.name;
    li.dataset.shapeId = s.id;
    if (s.mark) li.classList.add(s.mark === "none" ? "none" : "labelled");
    if (i === current) li.classList.add("current");
    li.onclick = () => go(i);
    list.appendChild(li);
  });
}

async function refresh() {
  state = await api("GET", "/api/state");
  renderState();
}

function markText(mark) {
  if (!mark) return "";
  return mark === "none" ? "labelled: none of these" : `labelled: ${mark}`;
}

async function show(i) {
  showPanel("view");
  current = i;
  renderState();
  const box = $("candidates");
  if (!state.total) {
    $("shape-name").textContent = "no shapes yet: draw one or drop a shape file";
    box.innerHTML = ""; $("shape-svg").innerHTML = ""; $("shape-mark").textContent = "";
    return;
  }
  $("shape-name").textContent = state.shapes[i].name + " (ranking…)";
  box.innerHTML = "";
  busy = true;
  try {
    shown = await api("GET", `/api/shapes/${i}`);
  } catch (e) {
    $("shape-name").textContent = state.shapes[i].name;
    message(e.message, "error");
    shown = null;
    return;
  } finally { busy = false; }
  if (current !== i) return;
  $("shape-name").textContent = `${i + 1}. ${shown.name}`;
  $("shape-mark").textContent = markText(shown.mark);
  drawSVG($("shape-svg"), shown, null);
  shown.candidates.forEach((c, j) => {
    const fig = document.createElement("figure");
    fig.className = "cand";
    fig.tabIndex = 0;
    fig.dataset.meshId = c.mesh_id;
    fig.dataset.rank = c.rank;
    if (shown.mark === c.mesh_id) fig.classList.add("chosen");
    const svg = document.createElementNS(SVGNS, "svg");
    fig.appendChild(svg);
    drawSVG(svg, shown, c);
    const cap = document.createElement("figcaption");
    const q = c.min_scaled_jacobian;
    cap.innerHTML = `<span class="key">${j + 1}</span><b>${c.mesh_id}</b><br>utility ${c.utility.toFixed(1)} · ` +
      `<span class="${q < 0.3 ? "bad" : ""}">quality (min SJ) ${q.toFixed(3)}</span>` +
      (c.inverted ? ` · <span class="bad">${c.inverted} inverted</span>` : "") + (c.note ? `<br><i>${c.note}</i>` : "");
    fig.appendChild(cap);
    fig.onclick = () => choose({mesh_id: c.mesh_id});
    box.appendChild(fig);
  });
}

function nextIndex() {
  // the next shape without a label after the current one, else simply the next one
  const n = state.total;
  for (let k = 1; k <= n; k++) {
    const j = (current + k) % n;
    if (!state.shapes[j].mark) return j;
  }
  return Math.min(current + 1, n - 1);
}

async function choose(body) {
  if (busy || !shown || shown.id !== current) return;
  busy = true;
  try {
    const res = await api("POST", `/api/shapes/${current}/choose`, body);
    const what = body.none ? "none of these" : body.mesh_id;
    message(`saved: ${what} for ${shown.name} (labelled ${res.labelled} / ${res.total})`, "ok");
    await refresh();
  } catch (e) {
    message(e.message, "error");
    return;
  } finally { busy = false; }
  if (state.labelled === state.total) message(`all ${state.total} shapes are labelled; the last choice was saved`, "ok");
  await show(nextIndex());
}

function go(i) { message(""); if (state.total) show(Math.max(0, Math.min(state.total - 1, i))); }

function showPanel(name) {
  $("view").hidden = name !== "view";
  $("drawer").hidden = name !== "drawer";
  $("tuner").hidden = name !== "tuner";
}

// ---- drawing ---------------------------------------------------------------------------
const draw = {points: [], closed: false, corners: new Set()};

function drawRender() {
  const svg = $("draw-svg");
  svg.innerHTML = "";
  for (let k = 0; k <= 100; k += 10) {
    el("line", {x1: k, y1: 0, x2: k, y2: 100, stroke: "#eef1f5", "stroke-width": 0.3}, svg);
    el("line", {x1: 0, y1: k, x2: 100, y2: k, stroke: "#eef1f5", "stroke-width": 0.3}, svg);
  }
  const p = draw.points;
  if (p.length) {
    el(draw.closed ? "polygon" : "polyline", {points: p.map(([x, y]) => `${x},${y}`).join(" "), fill: draw.closed ? "#dbe9f6" : "none",
       stroke: EDGE_COLOUR, "stroke-width": 0.6}, svg);
  }
  p.forEach(([x, y], i) => {
    const isCorner = draw.corners.has(i);
    const c = el(isCorner ? "rect" : "circle", isCorner ? {x: x - 1.6, y: y - 1.6, width: 3.2, height: 3.2, fill: "#000"}
                                                 : {cx: x, cy: y, r: i === 0 && !draw.closed ? 1.8 : 1.2, fill: i === 0 ? "#1f77b4" : "#55657a"}, svg);
    c.classList.add("draw-pt");
    c.dataset.index = i;
  });
  $("draw-use").disabled = !draw.closed;
  $("draw-status").textContent = draw.closed ? `closed loop of ${p.length} points, ${draw.corners.size} corners toggled`
                                             : `${p.length} points` + (p.length >= 3 ? " (click the first point to close)" : "");
}

function drawClick(ev) {
  const svg = $("draw-svg");
  const pt = svg.createSVGPoint();
  pt.x = ev.clientX; pt.y = ev.clientY;
  const q = pt.matrixTransform(svg.getScreenCTM().inverse());
  const x = Math.round(q.x * 10) / 10, y = Math.round(q.y * 10) / 10;
  const near = draw.points.findIndex(([a, b]) => Math.hypot(a - x, b - y) < 2.5);
  if (draw.closed) {
    if (near >= 0) { draw.corners.has(near) ? draw.corners.delete(near) : draw.corners.add(near); }
  } else if (near === 0 && draw.points.length >= 3) {
    draw.closed = true;
  } else if (near < 0) {
    draw.points.push([x, y]);
  }
  drawRender();
}

async function drawUse() {
  // page y points down: flip so that the shape looks the same in the mesh views
  const body = {boundary: draw.points.map(([x, y]) => [x, 100 - y])};
  if (draw.corners.size) body.corners = [...draw.corners].sort((a, b) => a - b);
  try {
    const res = await api("POST", "/api/shapes", body);
    await added(res.id, "drawn shape added");
    draw.points = []; draw.closed = false; draw.corners.clear();
  } catch (e) { message(e.message, "error"); }
}

async function added(id, text) {
  await refresh();
  message(`${text}: ${state.shapes[id].name}`, "ok");
  await show(id);
}

// ---- dropping files ----------------------------------------------------------------------
let dragDepth = 0;
document.addEventListener("dragenter", (ev) => { ev.preventDefault(); dragDepth++; $("dropzone").hidden = false; });
document.addEventListener("dragleave", () => { if (--dragDepth <= 0) { dragDepth = 0; $("dropzone").hidden = true; } });
document.addEventListener("dragover", (ev) => ev.preventDefault());
document.addEventListener("drop", async (ev) => {
  ev.preventDefault();
  dragDepth = 0; $("dropzone").hidden = true;
  const file = ev.dataTransfer && ev.dataTransfer.files[0];
  if (!file) return;
  try {
    const res = await api("POST", `/api/upload?name=${encodeURIComponent(file.name)}`, undefined, await file.arrayBuffer());
    await added(res.id, "shape file added");
  } catch (e) { message(e.message, "error"); }
});

// ---- tuning ------------------------------------------------------------------------------
const pct = (x) => (x === null || x === undefined ? "–" : (100 * x).toFixed(1) + "%");

async function tune() {
  showPanel("tuner");
  $("tune-result").textContent = "tuning on the labels so far… (this takes a while)";
  try {
    const r = await api("POST", "/api/tune");
    let html = `<p>${r.examples} labelled shapes (${r.skipped} bad lines skipped); lattice ${r.lattice} → ${r.tuned}; ${r.seconds} s.</p>`;
    html += `<table class="tune"><tr><th>set</th><th>shapes</th><th>top-1 before</th><th>top-1 after</th><th>top-5 before</th><th>top-5 after</th></tr>`;
    for (const key of ["train", "heldout"]) {
      const s = r[key];
      html += `<tr><td>${key === "heldout" ? "held out" : key}</td><td>${s.examples}</td><td>${pct(s.top1.before)}</td><td>${pct(s.top1.after)}</td>` +
              `<td>${pct(s.top5.before)}</td><td>${pct(s.top5.after)}</td></tr>`;
    }
    html += `</table><p>wrote <code>${r.out}</code> · <a id="tune-download" download="tuned.toml">download the tuned lattice</a></p>`;
    $("tune-result").innerHTML = html;
    $("tune-download").href = URL.createObjectURL(new Blob([r.toml], {type: "application/toml"}));
    message(`tuned lattice written to ${r.out}`, "ok");
  } catch (e) {
    $("tune-result").textContent = "";
    message(e.message, "error");
  }
}

// ---- wiring ------------------------------------------------------------------------------
$("back").onclick = () => go(current - 1);
$("next").onclick = () => go(current + 1);
$("skip").onclick = () => { if (state.total) { message(`skipped ${state.shapes[current].name}`); show(nextIndex()); } };
$("none").onclick = () => choose({none: true});
$("tune").onclick = tune;
$("draw").onclick = () => { showPanel("drawer"); drawRender(); };
$("draw-svg").addEventListener("click", drawClick);
$("draw-use").onclick = drawUse;
$("draw-undo").onclick = () => { if (draw.closed) draw.closed = false; else draw.points.pop(); draw.corners.clear(); drawRender(); };
$("draw-clear").onclick = () => { draw.points = []; draw.closed = false; draw.corners.clear(); drawRender(); };
$("draw-cancel").onclick = () => show(current);

document.addEventListener("keydown", (ev) => {
  if ($("view").hidden || ev.ctrlKey || ev.metaKey || ev.altKey) return;
  if (ev.key >= "1" && ev.key <= "9") {
    const c = shown && shown.candidates[Number(ev.key) - 1];
    if (c) choose({mesh_id: c.mesh_id});
  } else if (ev.key === "0") choose({none: true});
  else if (ev.key === "s") $("skip").click();
  else if (ev.key === "ArrowLeft") go(current - 1);
  else if (ev.key === "ArrowRight") go(current + 1);
});

(async () => {
  try {
    await refresh();
    const first = state.shapes.findIndex((s) => !s.mark);
    await show(first >= 0 ? first : 0);
    if (state.total && state.labelled === state.total) message(`all ${state.total} shapes are labelled (${state.labels})`, "ok");
  } catch (e) { message(e.message, "error"); }
})();
