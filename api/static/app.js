// Dashboard of the contact-state transition planner. Plain ES modules, no build step, no downloads:
// 2-D scenes drawn in SVG, 3-D scenes in WebGL (view3d.js: three.js and urdf-loader, vendored).

import { COLORS, PATH_COLORS, SceneView3D, interpolatePose3, formatLength } from "./view3d.js";

const $ = (id) => document.getElementById(id);
const SVGNS = "http://www.w3.org/2000/svg";
const PAGE = 100;          // table rows per page
const MAX_FRAMES = 1500;   // plan animation frames (waypoints and the frames between them)
const state = {
  scene: null, geometry: null, rows: [], filtered: [], page: 0, combination: null, report: null,
  dafcView: { yaw: -0.7, pitch: 0.5 }, dafcPick: null,
  extraBounds: [], job: null, pollTimer: null, plan: null, frames: [], frameIndex: 0, playTimer: null,
  view3d: null, sceneToken: 0, robot: null, replay: null,
};

// ---------------------------------------------------------------------------------------------
// HTTP

async function api(method, url, body) {
  const opts = { method, headers: {} };
  if (body instanceof FormData) opts.body = body;
  else if (body !== undefined) { opts.body = JSON.stringify(body); opts.headers["content-type"] = "application/json"; }
  const r = await fetch(url, opts);
  let data = null;
  try { data = await r.json(); } catch (e) { data = null; }
  if (!r.ok) {
    const err = new Error((data && data.detail) || `${r.status} ${r.statusText}`);
    err.status = r.status; err.data = data;
    throw err;
  }
  return data;
}

// ---------------------------------------------------------------------------------------------
// small vector helpers

const add = (a, b) => a.map((x, i) => x + b[i]);
const sub = (a, b) => a.map((x, i) => x - b[i]);
const mul = (a, s) => a.map((x) => x * s);
const dot = (a, b) => a.reduce((s, x, i) => s + x * b[i], 0);
const norm = (a) => Math.hypot(...a);
const lerp = (a, b, u) => a.map((x, i) => x + (b[i] - x) * u);
function rot2(v, t) { const c = Math.cos(t), s = Math.sin(t); return [c * v[0] - s * v[1], s * v[0] + c * v[1]]; }
function matvec(R, v) { return [0, 1, 2].map((i) => R[i][0] * v[0] + R[i][1] * v[1] + R[i][2] * v[2]); }
function tmatvec(R, v) { return [0, 1, 2].map((i) => R[0][i] * v[0] + R[1][i] * v[1] + R[2][i] * v[2]); }
function quatToMat(q) {
  const [w, x, y, z] = q;
  return [[1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
          [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
          [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]];
}
function rotvecToMat(r) {
  const t = norm(r);
  if (t < 1e-12) return [[1, 0, 0], [0, 1, 0], [0, 0, 1]];
  const k = mul(r, 1 / t), c = Math.cos(t), s = Math.sin(t), v = 1 - c;
  return [[c + k[0] * k[0] * v, k[0] * k[1] * v - k[2] * s, k[0] * k[2] * v + k[1] * s],
          [k[1] * k[0] * v + k[2] * s, c + k[1] * k[1] * v, k[1] * k[2] * v - k[0] * s],
          [k[2] * k[0] * v - k[1] * s, k[2] * k[1] * v + k[0] * s, c + k[2] * k[2] * v]];
}

// object frames: a pose vector (2-D [x, y, θ], 3-D [p, rotation vector]) or null (the scene's pose)

function frameOf(scene, pose) {
  if (scene.dim === 2) {
    return pose ? { p: pose.slice(0, 2), t: pose[2] } : { p: scene.object.pose.position, t: scene.object.pose.angle || 0 };
  }
  return pose ? { p: pose.slice(0, 3), R: rotvecToMat(pose.slice(3, 6)) }
    : { p: scene.object.pose.position, R: quatToMat(scene.object.pose.quat_wxyz || [1, 0, 0, 0]) };
}
const toWorld = (scene, f, v) => (scene.dim === 2 ? add(f.p, rot2(v, f.t)) : add(f.p, matvec(f.R, v)));
const toLocal = (scene, f, x) => (scene.dim === 2 ? rot2(sub(x, f.p), -f.t) : tmatvec(f.R, sub(x, f.p)));
const dirToWorld = (scene, f, v) => (scene.dim === 2 ? rot2(v, f.t) : matvec(f.R, v));
const dirToLocal = (scene, f, v) => (scene.dim === 2 ? rot2(v, -f.t) : tmatvec(f.R, v));

function shapeNormalLocal(scene, x) {
  // inward unit normal of the object's surface nearest the object-frame point x, or null
  const s = scene.object.shape, o = s.position || x.map(() => 0), y = sub(x, o);
  if (s.type === "disk" || s.type === "sphere") { const n = norm(y); return n > 1e-12 ? mul(y, -1 / n) : null; }
  if (s.type === "box") {
    let best = 0, val = -Infinity;
    y.forEach((c, i) => { const r = Math.abs(c) / (s.size[i] / 2); if (r > val) { val = r; best = i; } });
    const n = y.map(() => 0); n[best] = y[best] > 0 ? -1 : 1;
    return n;
  }
  if (s.type === "cylinder") {
    const rr = Math.hypot(y[0], y[1]);
    if (Math.abs(y[2]) / (s.height / 2) > rr / s.radius) return [0, 0, y[2] > 0 ? -1 : 1];
    return rr > 1e-12 ? [-y[0] / rr, -y[1] / rr, 0] : null;
  }
  return null;
}

// ---------------------------------------------------------------------------------------------
// SVG helpers

function el(parent, name, attrs, text) {
  const e = document.createElementNS(SVGNS, name);
  for (const [k, v] of Object.entries(attrs || {})) e.setAttribute(k, v);
  if (text !== undefined) e.textContent = text;
  parent.appendChild(e);
  return e;
}
const pts = (list) => list.map((p) => `${p[0].toFixed(2)},${p[1].toFixed(2)}`).join(" ");

function makeProjector(dim, view, points, width, height, margin = 30) {
  const raw = (p) => {
    if (dim === 2) return [p[0], p[1], 0];
    const [x, y, z] = p;
    const cy = Math.cos(view.yaw), sy = Math.sin(view.yaw), cp = Math.cos(view.pitch), sp = Math.sin(view.pitch);
    const x1 = cy * x - sy * y, y1 = sy * x + cy * y;
    return [x1, cp * z - sp * y1, sp * z + cp * y1];
  };
  let minx = Infinity, maxx = -Infinity, miny = Infinity, maxy = -Infinity;
  for (const p of points) {
    const q = raw(p);
    minx = Math.min(minx, q[0]); maxx = Math.max(maxx, q[0]); miny = Math.min(miny, q[1]); maxy = Math.max(maxy, q[1]);
  }
  if (!isFinite(minx)) { minx = -1; maxx = 1; miny = -1; maxy = 1; }
  const span = Math.max(maxx - minx, maxy - miny, 1e-6);
  const scale = Math.min((width - 2 * margin) / span, (height - 2 * margin) / span);
  const cx = (minx + maxx) / 2, cyy = (miny + maxy) / 2;
  const f = (p) => { const q = raw(p); return [width / 2 + (q[0] - cx) * scale, height / 2 - (q[1] - cyy) * scale, q[2]]; };
  f.scale = scale;
  return f;
}

function enableDragRotate(svg, view, redraw) {
  let last = null;
  svg.addEventListener("pointerdown", (e) => { last = [e.clientX, e.clientY]; svg.setPointerCapture(e.pointerId); });
  svg.addEventListener("pointermove", (e) => {
    if (!last) return;
    view.yaw += (e.clientX - last[0]) * 0.01;
    view.pitch = Math.max(-1.5, Math.min(1.5, view.pitch + (e.clientY - last[1]) * 0.01));
    last = [e.clientX, e.clientY];
    redraw();
  });
  svg.addEventListener("pointerup", () => { last = null; });
}

// ---------------------------------------------------------------------------------------------
// what is shown now: the scene as given (with the selected combination), or a plan frame

function sceneContacts() {
  const letters = state.combination;
  return state.geometry.contacts.map((c, i) => ({ body: c.body, point: c.point, normal: c.normal, half_angle: c.half_angle,
    state: letters ? letters[i] || "" : "", label: String(i) }));
}

function currentView() {
  const f = state.frames.length ? state.frames[state.frameIndex] : null;
  const contacts = f ? f.contacts : sceneContacts();
  const stateOf = {};
  for (const c of contacts) if (c.state && c.state !== "-" && !stateOf[c.body]) stateOf[c.body] = c.state;
  return {
    index: state.frameIndex,
    fingers: f ? f.fingers : state.geometry.frames[0].fingers,
    q: f ? f.q : state.geometry.frames[0].q,
    pose: f ? f.pose : null,
    ghost: f ? replayPoseAt(f) : null,
    contacts, stateOf,
  };
}

function drawScene() {
  if (!state.scene || !state.geometry) return;
  if (state.scene.dim === 3) { if (state.view3d) state.view3d.update(currentView()); return; }
  drawScene2D();
}

function outline2D(shape, T) {
  // polylines (world) and circles [centre, radius, mark] of a 2-D shape placed by T
  const lines = [], circles = [];
  if (shape.type === "disk") circles.push([T([0, 0]), shape.radius, T([shape.radius, 0])]);
  else if (shape.type === "box") {
    const [a, b] = [shape.size[0] / 2, shape.size[1] / 2], o = shape.position || [0, 0];
    lines.push([[-a, -b], [a, -b], [a, b], [-a, b], [-a, -b]].map((v) => T(add(v, o))));
  } else if (shape.type === "polygon") lines.push([...shape.vertices, shape.vertices[0]].map(T));
  else if (shape.type === "segment") lines.push(shape.points.map(T));
  return { lines, circles };
}

function drawScene2D() {
  const svg = $("scene-view");
  svg.innerHTML = "";
  const scene = state.scene, geom = state.geometry, view = currentView();
  const W = 600, H = 460;
  const objFrame = frameOf(scene, view.pose);
  const objT = (v) => toWorld(scene, objFrame, v);
  const oo = outline2D(scene.object.shape, objT);
  const P = [];
  for (const f of geom.frames[0].fingers) for (const l of f.links) P.push(l.a, l.b);
  for (const c of geom.contacts) P.push(c.point);
  for (const l of oo.lines) P.push(...l);
  for (const [c, r] of oo.circles) P.push(add(c, [r, r]), sub(c, [r, r]));
  for (const b of scene.fixed_bodies || []) for (const l of outline2D(b.shape, (v) => v).lines) P.push(...l);
  P.push(...state.extraBounds);
  const size = Math.max(...P.map((p) => norm(sub(p, P[0]))), 1e-3);
  const L = 0.12 * size;
  // normals and labels in view (a plan's are in extraBounds, so the view stays put while it plays)
  if (!state.frames.length) for (const c of view.contacts) if (c.normal) P.push(sub(c.point, mul(c.normal, 1.5 * L)));
  const proj = makeProjector(2, null, P, W, H);
  const stateOf = view.stateOf;

  for (const b of scene.fixed_bodies || []) {
    const fo = outline2D(b.shape, (v) => v), fst = stateOf[b.name];
    for (const l of fo.lines) el(svg, "polyline", { points: pts(l.map(proj)), fill: "none", stroke: fst ? COLORS[fst] : "#555", "stroke-width": 4, class: "fixed" });
    for (const [c, r] of fo.circles) { const q = proj(c); el(svg, "circle", { cx: q[0], cy: q[1], r: r * proj.scale, fill: "#ddd", stroke: "#555" }); }
  }
  for (const [c, r, mark] of oo.circles) {
    const q = proj(c);
    el(svg, "circle", { cx: q[0], cy: q[1], r: r * proj.scale, fill: "#a8c5e6", "fill-opacity": 0.5, stroke: "#1d3557", "stroke-width": 1.5, class: "object" });
    if (mark) { const m = proj(mark); el(svg, "line", { x1: q[0], y1: q[1], x2: m[0], y2: m[1], stroke: "#1d3557" }); }
  }
  for (const l of oo.lines) el(svg, "polyline", { points: pts(l.map(proj)), fill: "#a8c5e6", "fill-opacity": 0.5, stroke: "#1d3557", "stroke-width": 1.2, class: "object" });
  for (const f of view.fingers) {
    for (const l of f.links) {
      const a = proj(l.a), b = proj(l.b), st = stateOf[l.body];
      el(svg, "line", { x1: a[0], y1: a[1], x2: b[0], y2: b[1], stroke: st ? COLORS[st] : "#444", "stroke-opacity": 0.8, "stroke-width": Math.max(4, 2 * l.radius * proj.scale), "stroke-linecap": "round", class: "link", "data-body": l.body });
      el(svg, "circle", { cx: a[0], cy: a[1], r: 4, fill: "#fff", stroke: "#222" });
    }
  }
  // the planned object path and the MuJoCo replay's, and the object where MuJoCo had it (ghost)
  if (state.plan && state.frames.length) {
    const planned = plannedObjectPath(state.plan);
    if (planned.length) el(svg, "polyline", { points: pts(planned.map((p) => proj(p.slice(0, 2)))), fill: "none", stroke: PATH_COLORS.planned, "stroke-width": 2, "stroke-dasharray": "5 3", class: "planned-path", "data-points": planned.length });
    if (state.replay) {
      el(svg, "polyline", { points: pts(state.replay.poses.map((p) => proj(p.slice(0, 2)))), fill: "none", stroke: PATH_COLORS.replay, "stroke-width": 2, class: "replay-path", "data-points": state.replay.poses.length });
      if (view.ghost) {
        const gf = frameOf(scene, view.ghost), go = outline2D(scene.object.shape, (v) => toWorld(scene, gf, v));
        const g = el(svg, "g", { class: "replay-ghost", "data-pose": view.ghost.map((x) => x.toFixed(6)).join(" ") });
        for (const [c, r, mark] of go.circles) {
          const q = proj(c);
          el(g, "circle", { cx: q[0], cy: q[1], r: r * proj.scale, fill: "none", stroke: PATH_COLORS.replay, "stroke-dasharray": "4 3", "stroke-width": 1.5 });
          if (mark) { const m = proj(mark); el(g, "line", { x1: q[0], y1: q[1], x2: m[0], y2: m[1], stroke: PATH_COLORS.replay }); }
        }
        for (const l of go.lines) el(g, "polyline", { points: pts(l.map(proj)), fill: "none", stroke: PATH_COLORS.replay, "stroke-dasharray": "4 3", "stroke-width": 1.5 });
      }
    }
  }
  view.contacts.forEach((c) => {
    const p = c.point, q = proj(p), s = c.state;
    const color = s && COLORS[s] ? COLORS[s] : "#e76f51";
    if (c.normal) {
      const n = c.normal;
      if (c.half_angle > 1e-6) {  // friction cone: the force directions that can act on the object here
        const r1 = rot2(n, c.half_angle), r2 = rot2(n, -c.half_angle);
        el(svg, "polygon", { points: pts([q, proj(sub(p, mul(r1, L))), proj(sub(p, mul(r2, L)))]), fill: color, "fill-opacity": 0.18, stroke: color, "stroke-dasharray": "3 2", class: "cone" });
      } else el(svg, "polygon", { points: pts([q, proj(sub(p, mul(n, L)))]), stroke: color, class: "cone" });
      const tail = proj(sub(p, mul(n, 1.3 * L)));
      el(svg, "line", { x1: tail[0], y1: tail[1], x2: q[0], y2: q[1], stroke: color, "stroke-width": 2, "marker-end": "url(#arrow)", class: "normal" });
      el(svg, "text", { x: tail[0] + 3, y: tail[1] - 3, "font-size": 11, fill: "#222" }, `${c.label}${s ? ":" + s : ""}`);
    }
    el(svg, "circle", { cx: q[0], cy: q[1], r: 5, fill: color, stroke: "#fff", class: "contact", "data-state": s || "" });
  });
  // a scale bar with units
  const bar = Math.pow(10, Math.floor(Math.log10(size * 0.3)));
  el(svg, "line", { x1: 20, y1: H - 16, x2: 20 + bar * proj.scale, y2: H - 16, stroke: "#333", "stroke-width": 2, class: "scale-bar" });
  el(svg, "text", { x: 20, y: H - 22, "font-size": 11, fill: "#333" }, `${formatLength(bar)} · x right, y up [m]`);
  const defs = el(svg, "defs", {});
  const m = el(defs, "marker", { id: "arrow", viewBox: "0 0 10 10", refX: 9, refY: 5, markerWidth: 6, markerHeight: 6, orient: "auto-start-reverse" });
  el(m, "path", { d: "M0,0 L10,5 L0,10 z", fill: "#333" });
}

// ---------------------------------------------------------------------------------------------
// the scene

function detachJob() {
  // the job keeps running on the server, but its result no longer belongs to what is shown
  stopPolling(); stopPlaying();
  state.job = null; state.plan = null; state.frames = []; state.frameIndex = 0; state.extraBounds = [];
  state.replay = null; showReplay(null);
  if (state.view3d) state.view3d.setPaths(null, null);
  $("job-status").textContent = "no job"; delete $("job-status").dataset.status; delete $("job-status").dataset.jobId;
  $("job-progress").value = 0; $("cancel-btn").disabled = true; $("steps").innerHTML = "";
  $("contact-states").innerHTML = ""; $("torque-bars").innerHTML = ""; $("player").hidden = true;
  delete $("player").dataset.frames; delete $("player").dataset.frame;
  $("job-error").textContent = "";
}

function jointNames() {
  if (state.scene && state.scene.dim === 3 && state.view3d) return state.view3d.jointNames();
  const out = [];
  for (const f of (state.scene ? state.scene.fingers : [])) f.q.forEach((_, k) => out.push(`${f.name}/joint ${k}`));
  return out;
}

async function setScene(scene, label) {
  detachJob();
  const token = ++state.sceneToken;
  state.scene = scene; state.combination = null; state.rows = []; state.filtered = []; state.report = null;
  $("combo-search").value = "";  // a filter of the last scene's table
  $("scene-error").textContent = ""; $("analysis-error").textContent = "";
  $("combo-table").querySelector("tbody").innerHTML = ""; $("report").hidden = true; $("page-info").textContent = ""; $("pager").hidden = true;
  $("analysis-status").textContent = "";
  $("scene-info").textContent = `${label}: ${scene.dim}-D, ${scene.contacts.length} contacts, ${scene.fingers.length} fingers` + (scene.description ? ` — ${scene.description}` : "");
  const three = scene.dim === 3;
  $("scene-view").style.display = three ? "none" : ""; $("scene-3d").hidden = !three;
  $("view-hint").textContent = three ? "3-D view: drag to orbit, scroll to zoom, right-drag (or shift-drag) to pan. Links and the object are translucent so every contact shows." : "";
  document.body.dataset.sceneReady = "0";
  try {
    state.geometry = await api("POST", "/scenes/geometry", { scene });
  } catch (e) { if (token === state.sceneToken) { $("scene-error").textContent = e.message; state.geometry = null; } return; }
  if (token !== state.sceneToken) return;
  if (three) {
    try {
      if (!state.view3d) state.view3d = new SceneView3D($("scene-3d"));
      await state.view3d.load(scene, state.geometry);
      if (token !== state.sceneToken) return;
      if (state.view3d.errors.length) $("scene-error").textContent = "3-D view: " + state.view3d.errors.join("; ");
    } catch (e) { $("scene-error").textContent = `3-D view unavailable (WebGL): ${e.message}`; }
  }
  drawScene();
  document.body.dataset.sceneReady = "1";
}

// ---------------------------------------------------------------------------------------------
// analysis: the table (filter, pages) and the report of one combination

function fmt(x, d = 3) { return x == null ? "–" : Math.abs(x) >= 1e4 || (x !== 0 && Math.abs(x) < 1e-3) ? x.toExponential(2) : x.toFixed(d); }
function fmtVec(v, d = 2) { return v ? "[" + v.map((x) => (x == null ? "∞" : x.toFixed(d))).join(", ") + "]" : "–"; }

function rowMatches(row, query) {
  if (!query) return true;
  const q = query.trim();
  if (/^[FSDN?*]+$/i.test(q)) {  // letters: ? any one state, * any run
    const re = new RegExp("^" + q.toUpperCase().replace(/\?/g, ".").replace(/\*/g, ".*") + "$");
    if (re.test(row.combination)) return true;
  }
  const words = q.toLowerCase().split(/\s+/);
  const text = `${row.combination} ${row.feasible ? "feasible" : "not feasible"} ${row.reason || ""}`.toLowerCase();
  return words.every((w) => text.includes(w));
}

function applyFilter(keepPage = false) {
  const only = $("feasible-only").checked, query = $("combo-search").value;
  state.filtered = state.rows.filter((r) => (!only || r.feasible) && rowMatches(r, query));
  if (!keepPage) state.page = 0;
  renderTable();
}

function renderTable() {
  const tbody = $("combo-table").querySelector("tbody");
  tbody.innerHTML = "";
  const pages = Math.max(1, Math.ceil(state.filtered.length / PAGE));
  state.page = Math.max(0, Math.min(state.page, pages - 1));
  const slice = state.filtered.slice(state.page * PAGE, (state.page + 1) * PAGE);
  const frag = document.createDocumentFragment();
  for (const row of slice) {
    const tr = document.createElement("tr");
    tr.dataset.combination = row.combination;
    if (row.combination === state.combination) tr.classList.add("selected");
    const letters = [...row.combination].map((s) => `<span class="${s}" style="color:#fff;padding:0 1px">${s}</span>`).join("");
    const cells = [letters, row.feasible ? "yes" : "no", null, row.dim_dafc, row.dim_dpfc, fmtVec(row.example_direction)];
    cells.forEach((c, k) => {
      const td = document.createElement("td");
      if (k === 0) td.innerHTML = c; else if (k === 2) { td.textContent = row.reason || ""; td.className = "reason"; } else td.textContent = String(c);
      tr.appendChild(td);
    });
    tr.addEventListener("click", () => selectCombination(row.combination));
    frag.appendChild(tr);
  }
  tbody.appendChild(frag);
  const n = state.filtered.length;
  $("page-info").textContent = n ? `rows ${state.page * PAGE + 1}–${Math.min(n, (state.page + 1) * PAGE)} of ${n} (page ${state.page + 1} of ${pages})` : (state.rows.length ? "no row matches" : "");
  $("page-prev").disabled = state.page === 0; $("page-next").disabled = state.page >= pages - 1;
  $("pager").hidden = state.rows.length === 0;
}

function showRows(result) {
  state.rows = result.combinations;
  $("analysis-status").textContent = `${result.feasible} of ${result.combinations.length} combinations feasible` + (result.elapsed_seconds != null ? ` (${result.elapsed_seconds.toFixed(2)} s)` : "");
  applyFilter();
}

async function runAnalysis() {
  if (!state.scene) return;
  const scene = state.scene;
  $("analysis-error").textContent = ""; $("analysis-status").textContent = "analysing…";
  $("analyze-btn").disabled = true;
  try { const res = await api("POST", "/analyses", { scene }); if (state.scene === scene) showRows(res); }
  catch (e) { if (state.scene === scene) { $("analysis-error").textContent = e.message; $("analysis-status").textContent = ""; } }
  finally { $("analyze-btn").disabled = false; }
}

async function selectCombination(c) {
  const scene = state.scene;
  if (state.plan) detachJob();  // the scene shows the combination now, not a plan frame
  state.combination = c; state.dafcPick = null; renderTable(); drawScene();
  $("report").hidden = false; $("report-title").textContent = `${c}: analysing…`; $("report-text").innerHTML = "";
  try {
    const res = await api("POST", "/analyses", { scene, combination: c });
    if (state.scene !== scene || state.combination !== c) return;
    state.report = res.report;
    $("report-title").textContent = `${c}: ${res.report.feasible ? "feasible" : "not feasible"} (${res.report.reason})`;
    renderReport(res.report);
    drawDafc();
  } catch (e) {
    if (state.combination !== c) return;
    $("report-title").textContent = `${c}: error`; $("report-text").textContent = e.message;
  }
}

function line(parent, text, cls = "line") { const p = document.createElement("div"); p.className = cls; p.textContent = text; parent.appendChild(p); return p; }

function torqueTable(parent, columns) {
  // one row per joint: name, then each column's value in N·m
  const names = jointNames(), t = document.createElement("table");
  t.className = "torques";
  t.innerHTML = `<thead><tr><th>joint</th>${columns.map((c) => `<th>${c[0]} [N·m]</th>`).join("")}</tr></thead>`;
  const tb = document.createElement("tbody");
  names.forEach((n, j) => {
    const tr = document.createElement("tr");
    tr.innerHTML = `<td>${n}</td>` + columns.map((c) => `<td>${c[1] ? fmt(c[1][j]) : "–"}</td>`).join("");
    tb.appendChild(tr);
  });
  t.appendChild(tb);
  parent.appendChild(t);
}

function renderReport(r) {
  // laid out as `ctp analyze --combination` prints it
  const box = $("report-text"); box.innerHTML = "";
  for (const n of r.notes || []) line(box, `note: ${n}`);
  const ms = r.motion_space || {};
  line(box, `motion space a = ${r.a}, object part ã = ${r.a_bar}, redundancy ${ms.redundancy ?? "–"}; p = rank(G_c Γ) = ${r.statics ? r.statics.p : "–"}`);
  if (r.scales) line(box, `scales: force ${fmt(r.scales.force)} N, length ${fmt(r.scales.length)} m`);
  if (r.stationary) {
    line(box, `stationary grasp (18, most interior): margin ${fmt(r.stationary.margin)}; minimum grip: total normal ${fmt(r.stationary_min_grip ? r.stationary_min_grip.total_normal : null)}`);
    torqueTable(box, [["τ_st most interior", r.stationary.tau], ["τ_st minimum grip", r.stationary_min_grip && r.stationary_min_grip.tau]]);
  } else line(box, "stationary grasp (18): none");
  if (r.dafc) {
    const d = r.dafc, k = d.member.filter(Boolean).length;
    line(box, `DAFC (22): dim ${d.dim}, ${k} of ${d.member.length} sampled directions, ${d.exact ? "exact" : "sampled"}; example ${fmtVec(r.example_direction)}`);
  } else line(box, r.a_bar === 0 ? "DAFC (22): empty (the object cannot move)"
    : "DAFC (22): not sampled (no stationary grasp (18), which it presupposes)");
  if (r.dpfc) {
    const dp = r.dpfc;
    line(box, dp.enumerated ? `DPFC (28): dim ${dp.dim}, ${dp.vertices.length} vertices, ${dp.rays.length} rays${dp.lines && dp.lines.length ? `, ${dp.lines.length} lines` : ""}`
      : `DPFC (28): dim ${dp.dim}, too many to enumerate its vertices; ${dp.vertices.length} extreme wrenches along its axes`);
    for (const v of dp.vertices.slice(0, 8)) line(box, `    vertex ${fmtVec(v, 3)}`);
    for (const v of dp.rays.slice(0, 8)) line(box, `    ray    ${fmtVec(v, 3)}`);
  }
  if (r.torque_set) {
    const ts = r.torque_set;
    line(box, ts.enumerated && ts.vertices
      ? `torque set T (32) for ${fmtVec(ts.direction)}: ${ts.vertices.length} vertices, ${ts.rays.length} rays; φ = |dq| = ${fmt(ts.phi)} (${ts.nlp_status})`
      : `torque set T (32) for ${fmtVec(ts.direction)}: too large to enumerate; φ = |dq| = ${fmt(ts.phi)} (${ts.nlp_status})`);
    const cols = [["recommended τ", ts.recommended]];
    (ts.vertices || []).slice(0, 4).forEach((v, k) => cols.push([`vertex ${k}`, v]));
    (ts.rays || []).slice(0, 3).forEach((v, k) => cols.push([`ray ${k}`, v]));
    torqueTable(box, cols);
    line(box, `recommended τ: work ${fmt(ts.work)}`);
  }
  if (r.torque_set_error) line(box, `torque set: ${r.torque_set_error}`);
  if (r.uncertainty) line(box, `friction uncertainty ν = ${r.uncertainty.nu}: ${r.uncertainty.reason}`);
  if (r.regrasp) line(box, `regrasp cone (33): ${r.regrasp.rays.length} rays, ${r.regrasp.lines.length} lines (${r.regrasp.exact ? "exact" : "S-points checked per generator"})`);
  if (r.quality) line(box, `quality: wrench ball ${fmt(r.quality.wrench_ball)}${r.quality.wrench_ball_reason ? ` (${r.quality.wrench_ball_reason})` : ""}, ε = ${fmt(r.quality.epsilon)}`);
}

function drawDafc() {
  const T = $("dafc-trans"), R = $("dafc-rot");
  T.innerHTML = ""; R.innerHTML = "";
  const r = state.report, dim = state.scene.dim;
  if (!r || !r.dafc) {
    const why = r && r.a_bar !== 0 ? "DAFC not sampled (no stationary grasp)" : "no DAFC (the object cannot move)";
    for (const s of [T, R]) el(s, "text", { x: 14, y: 130, "font-size": 12 }, why);
    $("dafc-caption").textContent = "";
    return;
  }
  const nt = dim === 2 ? 2 : 3;
  const dirs = r.dafc.directions, member = r.dafc.member;
  const ex = r.example_direction;
  const panels = [
    { svg: T, part: (d) => d.slice(0, nt), names: dim === 2 ? ["Δx [m]", "Δy [m]"] : ["Δx [m]", "Δy [m]", "Δz [m]"] },
    { svg: R, part: (d) => d.slice(nt), names: dim === 2 ? ["|Δp| [m]", "Δθ [rad]"] : ["Δθx [rad]", "Δθy [rad]", "Δθz [rad]"] },
  ];
  for (const pn of panels) {
    const svg = pn.svg, three = pn.names.length === 3;
    // 2-D rotation panel: Δθ against the size of the translation part, so each sample is a point
    const coords = (d) => (dim === 2 && pn.svg === R ? [norm(d.slice(0, 2)), d[2]] : pn.part(d));
    const corners = three ? [[1, 1, 1], [-1, -1, -1], [1, -1, 1], [-1, 1, -1]] : [[-1, -1], [1, 1]];
    const proj = makeProjector(three ? 3 : 2, state.dafcView, corners, 260, 260, 34);
    const axes = three ? [[1, 0, 0], [0, 1, 0], [0, 0, 1]] : [[1, 0], [0, 1]];
    axes.forEach((v, i) => {
      const a = proj(mul(v, -1)), b = proj(v);
      el(svg, "line", { x1: a[0], y1: a[1], x2: b[0], y2: b[1], stroke: "#999", "stroke-dasharray": "2 2" });
      el(svg, "text", { x: b[0] + (three ? 3 : i === 0 ? -40 : 4), y: b[1] + (three || i === 1 ? 0 : 14), "font-size": 11, fill: "#444", class: "axis-label" }, pn.names[i]);
      el(svg, "text", { x: b[0] - 4, y: b[1] + (i === 0 && !three ? -4 : 12), "font-size": 9, fill: "#888" }, "1");
    });
    if (ex) {  // under the samples, so it never hides one from the pointer
      const q = proj(coords(ex)), o = proj(coords(ex).map(() => 0));
      el(svg, "line", { x1: o[0], y1: o[1], x2: q[0], y2: q[1], stroke: "#1d3557", "stroke-width": 2, class: "example", "pointer-events": "none" });
    }
    const order = dirs.map((d, i) => [three ? proj(coords(d))[2] : 0, i]).sort((a, b) => b[0] - a[0]);
    for (const [, i] of order) {
      const q = proj(coords(dirs[i]));
      const c = el(svg, "circle", { cx: q[0], cy: q[1], r: member[i] ? 3.5 : 2, fill: member[i] ? "#2a9d8f" : "#bbb", class: (member[i] ? "dafc-in" : "dafc-out") + (state.dafcPick === i ? " hl" : ""), "data-k": i });
      c.addEventListener("pointerenter", () => pickDafc(i));
    }
  }
}

function pickDafc(i) {
  state.dafcPick = i;
  for (const c of $("dafc-view").querySelectorAll("circle.hl")) c.classList.remove("hl");
  for (const c of $("dafc-view").querySelectorAll(`circle[data-k='${i}']`)) c.classList.add("hl");
  const r = state.report, d = r.dafc.directions[i], nt = state.scene.dim === 2 ? 2 : 3;
  $("dafc-caption").textContent = `sample ${i}: translation ${fmtVec(d.slice(0, nt), 3)} m, rotation ${fmtVec(d.slice(nt), 3)} rad — ${r.dafc.member[i] ? "in DAFC" : "not in DAFC"}` + (r.dafc.work ? ` (work ${fmt(r.dafc.work[i])})` : "");
}

// ---------------------------------------------------------------------------------------------
// jobs: plans and enumerations

async function startJob(kind) {
  if (!state.scene) return;
  detachJob();
  drawScene();  // the scene as given again, not the last plan's frame
  const scene = state.scene;
  const type = $("goal-select").value;
  const goal = type === "combination" ? { type, combination: $("goal-combination").value.trim() } : { type };
  // the planner options ticked (POST /plans options; none: the request as before)
  const options = {};
  for (const box of document.querySelectorAll("#plan-options input[data-option]")) if (box.checked) options[box.dataset.option] = true;
  for (const box of document.querySelectorAll("#plan-options input[data-number-option]")) {  // empty: the default
    const v = box.value.trim() === "" ? null : Number(box.value);
    if (box.validity.badInput || (v !== null && !(Number.isFinite(v) && v >= 0))) {
      if (kind === "plan") { $("job-error").textContent = `${box.dataset.numberOption}: a number >= 0, or empty for the default`; return; }
    } else if (v !== null) options[box.dataset.numberOption] = v;
  }
  const body = kind === "plan"
    ? { scene, goal, ...($("replay-check").checked ? { replay: true } : {}), ...(Object.keys(options).length ? { options } : {}) }
    : { scene };
  try {
    const job = await api("POST", kind === "plan" ? "/plans" : "/enumerations", body);
    if (state.scene !== scene) return;  // the scene changed while the job was being created
    state.job = job; showJob(job); $("cancel-btn").disabled = false;
    state.pollTimer = setInterval(pollJob, 400);
  } catch (e) { if (state.scene === scene) $("job-error").textContent = e.message; }
}

function stopPolling() { if (state.pollTimer) clearInterval(state.pollTimer); state.pollTimer = null; }

function showJob(job) {
  $("job-progress").value = job.progress;
  const pct = Math.round(job.progress * 100);
  const t = job.elapsed_seconds != null ? ` · ${job.elapsed_seconds.toFixed(1)} s` : "";
  $("job-status").textContent = `${job.kind} ${job.id}: ${job.status} ${pct}% — ${job.message}${t}`;
  $("job-status").dataset.status = job.status;
  $("job-status").dataset.jobId = job.id;
  if (job.error) $("job-error").textContent = `${job.kind} ${job.status}: ${job.error}`;
}

async function pollJob() {
  if (!state.job || state.polling) return;
  const current = state.job, scene = state.scene;
  const stale = () => state.job === null || state.job.id !== current.id || state.scene !== scene;
  state.polling = true;
  try {
    let job;
    try { job = await api("GET", current.url); } catch (e) { if (!stale()) { $("job-error").textContent = e.message; stopPolling(); } return; }
    if (stale()) return;
    state.job = job; showJob(job);
    if (!["succeeded", "failed", "cancelled"].includes(job.status)) return;
    stopPolling(); $("cancel-btn").disabled = true;
    if (job.status !== "succeeded") {  // failed or cancelled: said so, nothing to play
      $("job-status").textContent = `${job.kind} ${job.id}: ${job.status}` + (job.error ? " (the reason below)" : "");
      $("player").hidden = true;
      return;
    }
    let result;
    try { result = await api("GET", job.result_url); } catch (e) { if (!stale()) $("job-error").textContent = e.message; return; }
    if (stale()) return;
    if (job.kind === "plan") {
      if (!result.found) {  // the job ran to its end, but found no plan: say so, not "succeeded"
        $("job-status").textContent = `plan ${job.id}: no plan (the reason below)`;
        $("job-status").dataset.status = "no-plan";
        $("job-error").textContent = `no plan: ${result.reason}`;
      }
      await loadPlan(result, scene);
    } else showRows(result);
  } finally { state.polling = false; }
}

async function cancelJob() {
  if (!state.job) return;
  try { showJob(await api("DELETE", state.job.url)); } catch (e) { $("job-error").textContent = e.message; }
}

// ---------------------------------------------------------------------------------------------
// plans as animations: waypoints, frames interpolated between them, contacts tracked on the object

function contactBodies(step) {
  // the bodies the combination's letters refer to (a new contact is in contacts_after only)
  const before = step.contacts_before || [], after = step.contacts_after || [];
  return after.length === (step.combination || "").length && before.length !== after.length ? after : before;
}

function interpolatePose(scene, a, b, u) {
  if (!a || !b) return a || b || null;
  return scene.dim === 2 ? lerp(a, b, u) : interpolatePose3(a, b, u);
}

/** The frames of a plan (without the link geometry): every waypoint of every step and enough
 * frames between them that no joint turns by more than ~0.02 rad and the object moves little. */
function planFrames(scene, plan) {
  let pose = plan.start_pose || null;
  let track = scene.contacts.map((c) => ({ body: c.body, point: c.point, normal: c.normal }));
  const mu = {}; for (const c of scene.contacts) mu[c.body] = c.mu;
  const steps = [];
  const size = Math.max(1e-3, ...state.geometry.frames[0].fingers.flatMap((f) => f.links.map((l) => norm(sub(l.b, l.a)))));
  plan.steps.forEach((s, k) => {
    const jp = s.joint_path || [], op = s.object_path || [];
    const poseAt = (j) => (op.length ? op[Math.min(op.length - 1, Math.round((j * (op.length - 1)) / Math.max(1, jp.length - 1)))] : pose);
    const p0 = poseAt(0), p1 = poseAt(Math.max(0, jp.length - 1));
    const f0 = frameOf(scene, p0), f1 = frameOf(scene, p1);
    const after = s.contacts_after || [], pa = s.contact_points_after || [];
    const used = new Set(), tracks = [];
    for (const c of track) {
      const l0 = toLocal(scene, f0, c.point);
      const j = after.findIndex((b, i) => b === c.body && !used.has(i) && pa[i]);
      if (j >= 0) used.add(j);
      const l1 = j >= 0 ? toLocal(scene, f1, pa[j]) : l0;
      tracks.push({ body: c.body, l0, l1, n: c.normal ? dirToLocal(scene, f0, c.normal) : shapeNormalLocal(scene, l0), after: j });
    }
    after.forEach((b, i) => {
      if (used.has(i) || !pa[i]) return;
      const l = toLocal(scene, f1, pa[i]);
      tracks.push({ body: b, l0: l, l1: l, n: shapeNormalLocal(scene, l), after: i, added: true });
    });
    // the combination's letters, by body
    const bodies = contactBodies(s), letterOf = new Map(), taken = new Set();
    for (const t of tracks) {
      const i = bodies.findIndex((b, m) => b === t.body && !taken.has(m));
      if (i >= 0) { taken.add(i); letterOf.set(t, [s.combination[i] || "-", i]); }
    }
    steps.push({ step: s, k, jp, poseAt, tracks, letterOf });
    track = after.map((b, i) => {
      const t = tracks.find((x) => x.after === i);
      const n = t && t.n ? dirToWorld(scene, f1, t.n) : null;
      return { body: b, point: pa[i], normal: n };
    });
    pose = p1;
  });
  // frames between waypoints: as many as the largest joint or object move needs, at most MAX_FRAMES
  const segs = [];
  for (const st of steps) {
    const n = st.jp.length;
    for (let j = 0; j < Math.max(1, n - 1); j++) {
      const qa = st.jp[j], qb = st.jp[Math.min(j + 1, n - 1)];
      if (!qa) continue;
      const pa = st.poseAt(j), pb = st.poseAt(Math.min(j + 1, n - 1));
      let need = Math.max(...qa.map((x, i) => Math.abs(qb[i] - x)), 0) / 0.02;
      if (pa && pb) {
        const d = scene.dim === 2 ? 2 : 3;
        need = Math.max(need, norm(sub(pb.slice(0, d), pa.slice(0, d))) / (0.01 * size), norm(sub(pb.slice(d), pa.slice(d))) / 0.02);
      }
      segs.push({ st, j, n, need: n > 1 ? Math.max(1, Math.ceil(need)) : 0 });
    }
  }
  const total = segs.reduce((s, g) => s + g.need + 1, 0);
  const shrink = total > MAX_FRAMES ? (MAX_FRAMES - segs.length) / Math.max(1, total - segs.length) : 1;
  const frames = [];
  for (const g of segs) {
    const sub_ = g.need ? Math.max(1, Math.floor(g.need * shrink)) : 0;
    const last = g.j === g.n - 2 || g.n <= 1;
    for (let m = 0; m < (sub_ || 1) + (last && sub_ ? 1 : 0); m++) {
      const u = sub_ ? m / sub_ : 0;
      const qa = g.st.jp[g.j], qb = g.st.jp[Math.min(g.j + 1, g.n - 1)];
      frames.push({ st: g.st, q: lerp(qa, qb, u), pose: interpolatePose(scene, g.st.poseAt(g.j), g.st.poseAt(Math.min(g.j + 1, g.n - 1)), u),
                    progress: g.n > 1 ? (g.j + u) / (g.n - 1) : 1, waypoint: u === 0 ? g.j : null });
    }
  }
  return frames.map((f, index) => {
    const fr = frameOf(scene, f.pose);
    const contacts = f.st.tracks.map((t) => {
      const local = lerp(t.l0, t.l1, f.progress);
      const ln = ["disk", "sphere"].includes(scene.object.shape.type) ? shapeNormalLocal(scene, local) : t.n;
      const [letter, i] = f.st.letterOf.get(t) || ["-", null];
      const m = mu[t.body] ?? 0;
      return { body: t.body, point: toWorld(scene, fr, local), normal: ln ? dirToWorld(scene, fr, ln) : null,
               half_angle: Math.atan(m), state: letter, label: i == null ? "·" : String(i) };
    });
    return { index, step: f.st.k, progress: f.progress, q: f.q, pose: f.pose, waypoint: f.waypoint, contacts,
             combination: f.st.step.combination, torques: (f.st.step.torques && f.st.step.torques.chosen) || [] };
  });
}

async function loadPlan(plan, scene) {
  if (state.scene !== scene) return;
  state.plan = plan;
  state.replay = replayOf(plan);
  showReplay(plan);
  const steps = $("steps"); steps.innerHTML = "";
  $("player").hidden = false;
  plan.steps.forEach((s, k) => {
    const li = document.createElement("li"), b = document.createElement("button");
    b.textContent = `${s.kind} · ${s.combination} · ${(s.joint_path || []).length} waypoints`;
    b.title = "show this step";
    const rs = plan.replay && plan.replay.status === "done" ? (plan.replay.steps || []).find((x) => x.index === k) : null;
    if (rs) {
      const note = document.createElement("div");
      note.className = "small muted replay-step";
      note.textContent = stepMotionText(scene, rs) + (rs.dropped ? " — dropped here" : "");
      li.appendChild(note);
    }
    b.addEventListener("click", () => { stopPlaying(); const i = state.frames.findIndex((f) => f.step === k); if (i >= 0) setFrame(i); });
    li.prepend(b);
    steps.appendChild(li);
  });
  let frames = [];
  try { frames = planFrames(scene, plan); } catch (e) { $("job-error").textContent = `plan playback: ${e.message}`; }
  state.frames = [];
  if (frames.length) {
    let geom;
    try { geom = await api("POST", "/scenes/geometry", { scene, configurations: frames.map((f) => f.q) }); }
    catch (e) { if (state.plan === plan) $("job-error").textContent = `plan playback: ${e.message}`; return; }
    if (state.scene !== scene || state.plan !== plan) return;  // another scene or job meanwhile
    frames.forEach((f, i) => { f.fingers = geom.frames[i].fingers; });
    state.frames = frames;
  }
  // the 2-D view fits every frame of the plan, so it does not jump while playing
  state.extraBounds = [];
  if (scene.dim === 2) {
    for (const f of state.frames) for (const fi of f.fingers) for (const l of fi.links) state.extraBounds.push(l.a, l.b);
    const all = [...state.extraBounds, ...state.geometry.contacts.map((c) => c.point)];
    const L = 0.12 * Math.max(...all.map((p) => norm(sub(p, all[0]))), 1e-3);
    for (const f of state.frames) for (const c of f.contacts) if (c.normal) state.extraBounds.push(sub(c.point, mul(c.normal, 1.5 * L)));
    if (state.replay) for (const p of state.replay.poses) state.extraBounds.push(p.slice(0, 2));
  } else if (state.view3d && state.frames.length) {
    state.view3d.setPaths(plannedObjectPath(plan), state.replay ? state.replay.poses : null);
  }
  $("frame-slider").max = Math.max(0, state.frames.length - 1);
  $("player").hidden = plan.steps.length === 0;  // nothing to play
  $("player").dataset.frames = String(state.frames.length);
  setFrame(0);
}

function setFrame(i) {
  state.frameIndex = Math.max(0, Math.min(i, state.frames.length - 1));
  $("frame-slider").value = state.frameIndex;
  const f = state.frames[state.frameIndex];
  [...$("steps").children].forEach((li, k) => li.classList.toggle("current", !!f && k === f.step));
  $("frame-label").textContent = f ? `step ${f.step} (steps 0–${state.plan.steps.length - 1}), frame ${state.frameIndex + 1}/${state.frames.length}${f.waypoint != null ? ` (waypoint ${f.waypoint})` : ""}` : "empty plan";
  $("player").dataset.frame = String(state.frameIndex);
  const cs = $("contact-states"); cs.innerHTML = "";
  if (f) for (const c of f.contacts) { const span = document.createElement("span"); span.className = `chip ${c.state}`; span.textContent = `${c.label} ${c.body}: ${c.state}`; cs.appendChild(span); }
  drawTorques(f ? f.torques : []);
  drawPathInset(f);
  drawScene();
}

function drawTorques(tau) {
  const svg = $("torque-bars"); svg.innerHTML = "";
  if (!tau || !tau.length) { el(svg, "text", { x: 10, y: 90, "font-size": 12 }, "no joint torques for this step"); return; }
  const names = jointNames(), W = 560, left = 50, right = 10, top = 18, mid = 80, hmax = 56;
  const m = Math.max(...tau.map(Math.abs), 1e-9), w = (W - left - right) / tau.length;
  el(svg, "line", { x1: left, y1: mid, x2: W - right, y2: mid, stroke: "#999" });
  el(svg, "line", { x1: left, y1: mid - hmax, x2: left, y2: mid + hmax, stroke: "#999" });
  el(svg, "text", { x: 4, y: mid - hmax + 4, "font-size": 9, fill: "#444" }, `${fmt(m, 2)}`);
  el(svg, "text", { x: 4, y: mid + 3, "font-size": 9, fill: "#444" }, "0");
  el(svg, "text", { x: 4, y: mid + hmax + 4, "font-size": 9, fill: "#444" }, `${fmt(-m, 2)}`);
  el(svg, "text", { x: left, y: 12, "font-size": 10, fill: "#222" }, "chosen joint torques τ [N·m] of this step");
  tau.forEach((t, j) => {
    const h = (Math.abs(t) / m) * hmax, x = left + j * w;
    const r = el(svg, "rect", { x: x + 1, y: t >= 0 ? mid - h : mid, width: Math.max(2, w - 2), height: Math.max(h, 0.5), fill: t >= 0 ? "#457b9d" : "#e76f51", class: "torque-bar", "data-joint": names[j] || String(j) });
    el(r, "title", {}, `${names[j] || j}: ${fmt(t)} N·m`);
    const lx = x + w / 2, ly = mid + hmax + 6;
    el(svg, "text", { x: lx, y: ly, "font-size": 9, transform: `rotate(60 ${lx} ${ly})`, class: "joint-name" }, names[j] || String(j));
  });
  void top;
}

// ---------------------------------------------------------------------------------------------
// the MuJoCo replay of a plan (POST /plans with replay: the result's "replay")

/** The plan's object path (pose vectors): its start pose, then every step's object_path. */
function plannedObjectPath(plan) {
  const out = plan.start_pose ? [plan.start_pose] : [];
  for (const s of plan.steps) for (const p of s.object_path || []) out.push(p);
  return out;
}

/** The replay's sampled object path and, for each step k, the samples from the last one before
 * the step to its last one ({from, to}), or null when the result has no replay that ran. */
function replayOf(plan) {
  const r = plan.replay;
  if (!r || r.status !== "done" || !r.object_path || !r.object_path.poses.length) return null;
  const { poses, steps } = r.object_path, seg = new Map();
  steps.forEach((k, i) => {
    const s = seg.get(k);
    if (s) s.to = i; else seg.set(k, { from: Math.max(0, i - 1), to: i });
  });
  return { poses, steps, seg, last: steps[steps.length - 1] };
}

/** The simulated object pose of a player frame: the replay's sample at the same fraction of the
 * frame's step; after the step the replay stopped in (dropped), its last pose. */
function replayPoseAt(frame) {
  const r = state.replay;
  if (!r) return null;
  const s = r.seg.get(frame.step);
  if (!s) return frame.step > r.last ? r.poses[r.poses.length - 1] : null;
  const u = Math.max(0, Math.min(1, frame.progress ?? 1));
  return r.poses[s.from + Math.round(u * (s.to - s.from))];
}

function fmtSI(x, unit) {
  const a = Math.abs(x);
  return `${a === 0 ? "0" : a >= 1e-3 && a < 1e4 ? x.toPrecision(3) : x.toExponential(2)} ${unit}`;
}

/** Planned and simulated motion of one step in words: translation (m) and rotation (rad) apart. */
function stepMotionText(scene, s) {
  const d = scene.dim === 2 ? 2 : 3;
  const part = (v) => `${fmtSI(norm(v.slice(0, d)), "m")}, ${fmtSI(norm(v.slice(d)), "rad")}`;
  return `MuJoCo moved ${part(s.simulated)} (planned ${part(s.planned)})`;
}

/** The replay's outcome in words, with units, under the player (hidden without a replay). */
function showReplay(plan) {
  const panel = $("replay-panel"), info = $("replay-info");
  const r = plan ? plan.replay : null;
  panel.hidden = !r; info.textContent = ""; delete info.dataset.status;
  if (!r) return;
  info.dataset.status = r.status;
  $("path-legend").hidden = r.status !== "done";
  $("path-inset").style.display = r.status === "done" ? "" : "none";
  if (r.status === "failed") { info.textContent = `MuJoCo replay failed: ${r.error} (the plan itself stands)`; return; }
  if (r.status === "skipped") { info.textContent = `MuJoCo replay: ${r.reason}`; return; }
  const pct = (x) => `${(100 * x).toFixed(1)} %`;
  info.textContent = `MuJoCo replay (${r.object_path.times.length} samples over ${r.duration.toFixed(3)} s of simulated time): `
    + `final position error ${fmtSI(r.position_error, "m")} (${pct(r.relative_position_error)} of ${fmtSI(r.position_scale, "m")}), `
    + `rotation error ${fmtSI(r.rotation_error, "rad")} (${pct(r.relative_rotation_error)} of ${fmtSI(r.rotation_scale, "rad")}); `
    + `object dropped: ${r.dropped ? "yes — " + r.drop_reason : "no"}; ${r.ok ? "within" : "NOT within"} the ${pct(r.tolerance)} tolerance.`;
}

/** The object paths zoomed to their own extent (they are often a few centimetres in a scene a
 * metre across): planned (dashed) and MuJoCo, the current frame's planned and simulated object
 * positions as dots; 3-D paths projected on the two world axes along which they spread most. */
function drawPathInset(frame) {
  const svg = $("path-inset"); svg.innerHTML = "";
  if (!state.plan || !state.replay || !frame) return;
  const W = 300, H = 200, M = 28, dim = state.scene.dim;
  const planned = plannedObjectPath(state.plan), sim = state.replay.poses;
  const all = [...planned, ...sim];
  const spread = [0, 1, 2].slice(0, dim).map((i) => Math.max(...all.map((p) => p[i])) - Math.min(...all.map((p) => p[i])));
  const axes = dim === 2 ? [0, 1] : [0, 1, 2].sort((a, b) => spread[b] - spread[a]).slice(0, 2).sort((a, b) => a - b);
  const [ax, ay] = axes, names = ["x", "y", "z"];
  const lo = axes.map((i) => Math.min(...all.map((p) => p[i]))), hi = axes.map((i) => Math.max(...all.map((p) => p[i])));
  const span = Math.max(hi[0] - lo[0], hi[1] - lo[1], 1e-6);
  const s = Math.min((W - 2 * M) / span, (H - 2 * M) / span);
  const cx = (lo[0] + hi[0]) / 2, cy = (lo[1] + hi[1]) / 2;
  const P = (p) => [W / 2 + (p[ax] - cx) * s, H / 2 - (p[ay] - cy) * s];
  el(svg, "polyline", { points: pts(planned.map(P)), fill: "none", stroke: PATH_COLORS.planned, "stroke-width": 1.5, "stroke-dasharray": "5 3", class: "inset-planned", "data-points": planned.length });
  el(svg, "polyline", { points: pts(sim.map(P)), fill: "none", stroke: PATH_COLORS.replay, "stroke-width": 1.5, class: "inset-replay", "data-points": sim.length });
  if (frame.pose) { const q = P(frame.pose); el(svg, "circle", { cx: q[0], cy: q[1], r: 4, fill: PATH_COLORS.planned, class: "inset-now-planned" }); }
  const g = replayPoseAt(frame);
  if (g) { const q = P(g); el(svg, "circle", { cx: q[0], cy: q[1], r: 3, fill: PATH_COLORS.replay, class: "inset-now-replay" }); }
  const bar = Math.pow(10, Math.floor(Math.log10(span * 0.5)));
  el(svg, "line", { x1: 8, y1: H - 8, x2: 8 + bar * s, y2: H - 8, stroke: "#333", "stroke-width": 2 });
  el(svg, "text", { x: 8, y: H - 12, "font-size": 10, fill: "#333" }, `${formatLength(bar)} · ${names[ax]} right, ${names[ay]} up [m]`);
  el(svg, "text", { x: 8, y: 12, "font-size": 10, fill: "#333" }, "object position, zoomed: planned (dashed) and MuJoCo");
}

function stopPlaying() {
  if (state.playTimer) clearInterval(state.playTimer);
  state.playTimer = null; $("play-btn").textContent = "Play";
}

function togglePlay() {
  if (state.playTimer) { stopPlaying(); return; }
  if (state.frameIndex >= state.frames.length - 1) setFrame(0);
  $("play-btn").textContent = "Pause";
  state.playTimer = setInterval(() => {
    if (state.frameIndex >= state.frames.length - 1) { stopPlaying(); return; }
    setFrame(state.frameIndex + 1);
  }, 40);
}

function stepJump(dir) {
  const f = state.frames[state.frameIndex]; if (!f) return;
  stopPlaying();
  const target = Math.max(0, f.step + dir);
  const i = state.frames.findIndex((x) => x.step === target);
  if (i >= 0) setFrame(i);
}

// ---------------------------------------------------------------------------------------------
// start-up

// ---------------------------------------------------------------------------------------------
// your robot: POST /robots, a chain of one of its URDFs, POST /scenes/contacts (touch)

function chainJoints(urdf, root, tip) {
  // the movable joints from root down to tip (null when tip is not below root)
  const byChild = new Map(urdf.joints.map((j) => [j.child, j]));
  const out = [];
  for (let link = tip; link !== root;) {
    const j = byChild.get(link);
    if (!j) return null;
    if (["revolute", "continuous"].includes(j.type)) out.unshift(j);
    link = j.parent;
  }
  return out;
}

function fillSelect(sel, values, pick, labels) {
  sel.innerHTML = "";
  values.forEach((v, i) => { const o = document.createElement("option"); o.value = v; o.textContent = labels ? labels[i] : v; sel.appendChild(o); });
  if (pick !== undefined && values.includes(pick)) sel.value = pick;
}

function robotChainChanged() {
  const urdf = state.robot.urdf_files.find((u) => u.file === $("robot-urdf").value);
  if (!urdf) return;
  const links = urdf.links;
  const children = new Set(urdf.joints.map((j) => j.child));
  const root = $("robot-root").value && links.includes($("robot-root").value) ? $("robot-root").value
    : links.find((l) => !children.has(l)) || links[0];
  fillSelect($("robot-root"), links, root);
  const below = links.filter((l) => l !== root && (chainJoints(urdf, root, l) || []).length > 0);
  const deepest = below.reduce((a, l) => (chainJoints(urdf, root, l).length > chainJoints(urdf, root, a || l).length ? l : a), below[0]);
  fillSelect($("robot-tip"), below, below.includes($("robot-tip").value) ? $("robot-tip").value : deepest);
  fillSelect($("robot-touch"), ["(none: detect only)", ...below], $("robot-touch").value);
}

async function uploadRobot(file) {
  $("robot-error").textContent = ""; $("robot-info").textContent = `uploading ${file.name} ...`;
  const fd = new FormData(); fd.append("file", file);
  try { state.robot = await api("POST", "/robots", fd); }
  catch (e) { $("robot-info").textContent = ""; $("robot-error").textContent = `${file.name}: ${e.message}`; return; }
  const r = state.robot;
  $("robot-info").textContent = `${file.name}: ${r.files} files, ${r.urdf_files.length} URDF (${r.prefix.slice(0, 18)}…)` +
    r.urdf_files.map((u) => u.missing_meshes.length ? ` — ${u.path}: ${u.missing_meshes.length} meshes missing` : "").join("");
  fillSelect($("robot-urdf"), r.urdf_files.map((u) => u.file), undefined, r.urdf_files.map((u) => u.path));
  $("robot-root").value = ""; robotChainChanged();
  $("robot-chain").hidden = false;
}

async function placeRobot() {
  $("robot-error").textContent = "";
  const urdf = state.robot.urdf_files.find((u) => u.file === $("robot-urdf").value);
  const root = $("robot-root").value, tip = $("robot-tip").value;
  const joints = chainJoints(urdf, root, tip);
  if (!joints || !joints.length) { $("robot-error").textContent = `no revolute joint from '${root}' to '${tip}'`; return; }
  const cur = state.scene && state.scene.dim === 3 ? state.scene : null;
  const base = cur && cur.fingers.length && cur.fingers[0].base ? cur.fingers[0].base : { position: [0, 0, 0], quat_wxyz: [1, 0, 0, 0] };
  const scene = {
    name: `${urdf.robot || "robot"}-${cur ? cur.name : "box"}`, dim: 3,
    object: cur ? cur.object : { pose: { position: [0.5, 0, 0.3], quat_wxyz: [1, 0, 0, 0] }, shape: { type: "box", size: [0.2, 0.2, 0.2] } },
    external_wrench: cur ? cur.external_wrench : [0, 0, -9.81, 0, 0, 0],
    fixed_bodies: cur ? cur.fixed_bodies : [],
    fingers: [{ name: "robot", base, urdf: { file: urdf.file, root_link: root, tip_link: tip }, q: joints.map(startAngle), link_radius: 0.05 }],
    contacts: [],
  };
  const touch = $("robot-touch").value;
  const body = { scene, touch: below(urdf, root).includes(touch) ? [touch] : [] };
  try {
    const found = await api("POST", "/scenes/contacts", body);
    await setScene(found.scene, `${scene.name} (${found.contacts.length} contacts found)`);
  } catch (e) { $("robot-error").textContent = e.message; }
}

function startAngle(j) {
  // 0 where the joint's URDF limits allow it, else the middle of its range
  const lo = j.lower == null || j.type === "continuous" ? -Infinity : j.lower;
  const hi = j.upper == null || j.type === "continuous" ? Infinity : j.upper;
  return lo <= 0 && 0 <= hi ? 0 : 0.5 * (lo + hi);
}

function below(urdf, root) { return urdf.links.filter((l) => l !== root && (chainJoints(urdf, root, l) || []).length > 0); }

async function init() {
  const redrawDafc = () => { if (state.report) drawDafc(); };
  enableDragRotate($("dafc-trans"), state.dafcView, redrawDafc);
  enableDragRotate($("dafc-rot"), state.dafcView, redrawDafc);
  $("analyze-btn").addEventListener("click", runAnalysis);
  $("feasible-only").addEventListener("change", () => applyFilter());
  $("combo-search").addEventListener("input", () => applyFilter());
  $("page-prev").addEventListener("click", () => { state.page -= 1; renderTable(); });
  $("page-next").addEventListener("click", () => { state.page += 1; renderTable(); });
  $("plan-btn").addEventListener("click", () => startJob("plan"));
  $("goal-select").addEventListener("change", () => { $("goal-combination").hidden = $("goal-select").value !== "combination"; });
  $("enum-btn").addEventListener("click", () => startJob("enumeration"));
  $("cancel-btn").addEventListener("click", cancelJob);
  $("play-btn").addEventListener("click", togglePlay);
  $("prev-btn").addEventListener("click", () => stepJump(-1));
  $("next-btn").addEventListener("click", () => stepJump(1));
  $("frame-slider").addEventListener("input", (e) => { stopPlaying(); setFrame(Number(e.target.value)); });
  $("robot-file").addEventListener("change", (e) => { const f = e.target.files[0]; if (f) uploadRobot(f); });
  for (const id of ["robot-urdf", "robot-root"]) $(id).addEventListener("change", robotChainChanged);
  $("robot-detect").addEventListener("click", placeRobot);
  $("upload").addEventListener("change", async (e) => {
    const file = e.target.files[0]; if (!file) return;
    const fd = new FormData(); fd.append("file", file);
    try { await setScene(await api("POST", "/scenes/upload", fd), file.name); }
    catch (err) { $("scene-error").textContent = `${file.name}: ${err.message}`; }
  });
  try {
    const h = await api("GET", "/health");
    $("health").textContent = `jobs on ${h.executor} · ${h.database} · version ${h.version}`;
  } catch (e) { $("health").textContent = "server unreachable"; }
  const examples = await api("GET", "/scenes/examples");
  const sel = $("example-select");
  for (const ex of examples) { const o = document.createElement("option"); o.value = ex.file; o.textContent = `${ex.name} (${ex.dim}-D, ${ex.contacts} contacts)`; sel.appendChild(o); }
  sel.addEventListener("change", () => { const ex = examples.find((x) => x.file === sel.value); if (ex) setScene(ex.scene, ex.name); });
  const first = examples.find((x) => x.file === "planar_disk_envelope.json") || examples[0];
  if (first) { sel.value = first.file; await setScene(first.scene, first.name); }
  // for the browser tests and the console: the current state and the 3-D view
  window.ctpDashboard = { state, showRows, setFrame, view3d: () => state.view3d };
  document.body.dataset.ready = "1";
}

init();
