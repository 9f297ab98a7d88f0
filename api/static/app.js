// Dashboard of the contact-state transition planner. Plain JS, no build step, no downloads.
"use strict";

const $ = (id) => document.getElementById(id);
const SVGNS = "http://www.w3.org/2000/svg";
const COLORS = { F: "#2a9d8f", S: "#e9a03b", D: "#d1495b", N: "#577590" };
const state = {
  scene: null, geometry: null, rows: [], combination: null, report: null,
  view: { yaw: -0.6, pitch: 0.45 }, dafcView: { yaw: -0.7, pitch: 0.5 },
  extraBounds: [], job: null, pollTimer: null, plan: null, frames: [], frameIndex: 0, playTimer: null,
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
const norm = (a) => Math.hypot(...a);
function rot2(v, t) { const c = Math.cos(t), s = Math.sin(t); return [c * v[0] - s * v[1], s * v[0] + c * v[1]]; }
function matvec(R, v) { return [0, 1, 2].map((i) => R[i][0] * v[0] + R[i][1] * v[1] + R[i][2] * v[2]); }
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
function matmul(A, B) { return [0, 1, 2].map((i) => [0, 1, 2].map((j) => A[i][0] * B[0][j] + A[i][1] * B[1][j] + A[i][2] * B[2][j])); }
function perpBasis(n) {
  const a = Math.abs(n[0]) < 0.9 ? [1, 0, 0] : [0, 1, 0];
  const cross = (u, v) => [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]];
  const t1 = cross(n, a); const t1n = mul(t1, 1 / norm(t1));
  return [t1n, cross(n, t1n)];
}

// ---------------------------------------------------------------------------------------------
// projection: 2-D scenes as they are (y up), 3-D scenes orthographic with drag-rotate

function makeProjector(dim, view, pts, width, height, margin = 30) {
  const raw = (p) => {
    if (dim === 2) return [p[0], p[1], 0];
    const [x, y, z] = p;
    const cy = Math.cos(view.yaw), sy = Math.sin(view.yaw), cp = Math.cos(view.pitch), sp = Math.sin(view.pitch);
    const x1 = cy * x - sy * y, y1 = sy * x + cy * y;          // yaw about z
    return [x1, cp * z - sp * y1, sp * z + cp * y1];           // pitch: screen-up, depth
  };
  let minx = Infinity, maxx = -Infinity, miny = Infinity, maxy = -Infinity;
  for (const p of pts) {
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

function el(parent, name, attrs, text) {
  const e = document.createElementNS(SVGNS, name);
  for (const [k, v] of Object.entries(attrs || {})) e.setAttribute(k, v);
  if (text !== undefined) e.textContent = text;
  parent.appendChild(e);
  return e;
}
const pts = (list) => list.map((p) => `${p[0].toFixed(2)},${p[1].toFixed(2)}`).join(" ");

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
// the scene

function objectFrame(scene, poseVec) {
  // rotation (3x3) and position (dim) of the object: the scene pose, or a plan's pose vector
  if (scene.dim === 2) {
    const p = poseVec ? poseVec.slice(0, 2) : scene.object.pose.position;
    const t = poseVec ? poseVec[2] : scene.object.pose.angle || 0;
    return { p, t };
  }
  const R0 = quatToMat(scene.object.pose.quat_wxyz || [1, 0, 0, 0]);
  if (!poseVec) return { p: scene.object.pose.position, R: R0 };
  return { p: poseVec.slice(0, 3), R: matmul(rotvecToMat(poseVec.slice(3, 6)), R0) };
}

function objectOutline(scene, frame) {
  // polylines (world points) and circles ([centre, radius]) that draw the object
  const s = scene.object.shape, lines = [], circles = [];
  if (scene.dim === 2) {
    const T = (v) => add(frame.p, rot2(v, frame.t));
    if (s.type === "disk") circles.push([frame.p, s.radius, T([s.radius, 0])]);
    else if (s.type === "box") {
      const [a, b] = [s.size[0] / 2, s.size[1] / 2], o = s.position || [0, 0];
      lines.push([[-a, -b], [a, -b], [a, b], [-a, b], [-a, -b]].map((v) => T(add(v, o))));
    } else if (s.type === "polygon") lines.push([...s.vertices, s.vertices[0]].map(T));
    return { lines, circles };
  }
  const T = (v) => add(frame.p, matvec(frame.R, v));
  const ring = (r, z, axis) => Array.from({ length: 33 }, (_, k) => {
    const a = (2 * Math.PI * k) / 32, c = r * Math.cos(a), d = r * Math.sin(a);
    return T(axis === "z" ? [c, d, z] : axis === "y" ? [c, z, d] : [z, c, d]);
  });
  if (s.type === "sphere") { lines.push(ring(s.radius, 0, "z"), ring(s.radius, 0, "y"), ring(s.radius, 0, "x")); }
  else if (s.type === "cylinder") {
    const h = s.height / 2;
    lines.push(ring(s.radius, -h, "z"), ring(s.radius, h, "z"));
    for (let k = 0; k < 4; k++) { const a = (k * Math.PI) / 2; const c = [s.radius * Math.cos(a), s.radius * Math.sin(a)]; lines.push([T([...c, -h]), T([...c, h])]); }
  } else if (s.type === "box") {
    const [a, b, c] = s.size.map((x) => x / 2), o = s.position || [0, 0, 0];
    const V = [[-a, -b, -c], [a, -b, -c], [a, b, -c], [-a, b, -c], [-a, -b, c], [a, -b, c], [a, b, c], [-a, b, c]].map((v) => T(add(v, o)));
    for (const [i, j] of [[0, 1], [1, 2], [2, 3], [3, 0], [4, 5], [5, 6], [6, 7], [7, 4], [0, 4], [1, 5], [2, 6], [3, 7]]) lines.push([V[i], V[j]]);
  } else circles.push([frame.p, 0.02, null]);
  return { lines, circles };
}

function fixedOutline(scene, body) {
  const s = body.shape, lines = [], circles = [];
  if (s.type === "segment") lines.push(s.points);
  else if (s.type === "box") {
    const o = s.position || (scene.dim === 2 ? [0, 0] : [0, 0, 0]);
    if (scene.dim === 2) { const [a, b] = [s.size[0] / 2, s.size[1] / 2]; lines.push([[-a, -b], [a, -b], [a, b], [-a, b], [-a, -b]].map((v) => add(v, o))); }
    else {
      const [a, b, c] = s.size.map((x) => x / 2);
      const V = [[-a, -b, -c], [a, -b, -c], [a, b, -c], [-a, b, -c], [-a, -b, c], [a, -b, c], [a, b, c], [-a, b, c]].map((v) => add(v, o));
      for (const [i, j] of [[0, 1], [1, 2], [2, 3], [3, 0], [4, 5], [5, 6], [6, 7], [7, 4], [0, 4], [1, 5], [2, 6], [3, 7]]) lines.push([V[i], V[j]]);
    }
  } else if (s.type === "disk" || s.type === "sphere") circles.push([scene.dim === 2 ? [0, 0] : [0, 0, 0], s.radius, null]);
  else if (s.type === "polygon") lines.push([...s.vertices, s.vertices[0]]);
  return { lines, circles };
}

function sceneSize(scene, geom) {
  const P = [];
  for (const f of geom.frames[0].fingers) for (const l of f.links) P.push(l.a, l.b);
  for (const c of geom.contacts) P.push(c.point);
  const o = objectOutline(scene, objectFrame(scene, null));
  for (const l of o.lines) P.push(...l);
  for (const [c, r] of o.circles) P.push(c.map((x) => x + r), c.map((x) => x - r));
  for (const b of scene.fixed_bodies || []) { const fo = fixedOutline(scene, b); for (const l of fo.lines) P.push(...l); }
  return P;
}

function drawScene() {
  const svg = $("scene-view");
  svg.innerHTML = "";
  const scene = state.scene, geom = state.geometry;
  if (!scene || !geom) return;
  const W = 600, H = 460;
  const frameInfo = state.frames.length ? state.frames[state.frameIndex] : null;
  const fingersNow = frameInfo ? frameInfo.fingers : geom.frames[0].fingers;
  const objFrame = objectFrame(scene, frameInfo ? frameInfo.pose : null);
  const P = state.extraBounds.length ? sceneSize(scene, geom).concat(state.extraBounds) : sceneSize(scene, geom);
  const proj = makeProjector(scene.dim, state.view, P, W, H);
  const size = Math.max(...P.map((p) => norm(sub(p, P[0]))), 1e-3);
  const L = 0.12 * size;

  if (scene.dim === 3) { // axes
    const o = [0, 0, 0];
    [["x", [1, 0, 0], "#c33"], ["y", [0, 1, 0], "#3a3"], ["z", [0, 0, 1], "#33c"]].forEach(([n, v, c]) => {
      const a = proj(o), b = proj(mul(v, L));
      el(svg, "line", { x1: a[0], y1: a[1], x2: b[0], y2: b[1], stroke: c, "stroke-width": 1 });
      el(svg, "text", { x: b[0] + 2, y: b[1], fill: c, "font-size": 10 }, n);
    });
  }
  // which body is in which state (a selected combination, or the current plan step)
  const stateOf = {};
  const letters = frameInfo ? frameInfo.combination : state.combination;
  const bodies = frameInfo ? frameInfo.contacts : scene.contacts.map((c) => c.body);
  if (letters) bodies.forEach((b, i) => { if (letters[i]) stateOf[b] = (stateOf[b] || "") + letters[i]; });

  for (const b of scene.fixed_bodies || []) {
    const fo = fixedOutline(scene, b);
    const fst = stateOf[b.name];
    for (const l of fo.lines) el(svg, "polyline", { points: pts(l.map(proj)), fill: "none", stroke: fst ? COLORS[fst[0]] : "#555", "stroke-width": 4, class: "fixed" });
    for (const [c, r] of fo.circles) { const q = proj(c); el(svg, "circle", { cx: q[0], cy: q[1], r: r * proj.scale, fill: "#ddd", stroke: "#555" }); }
  }
  const oo = objectOutline(scene, objFrame);
  for (const [c, r, mark] of oo.circles) {
    const q = proj(c);
    el(svg, "circle", { cx: q[0], cy: q[1], r: r * proj.scale, fill: "#a8c5e6", "fill-opacity": 0.5, stroke: "#1d3557", "stroke-width": 1.5, class: "object" });
    if (mark) { const m = proj(mark); el(svg, "line", { x1: q[0], y1: q[1], x2: m[0], y2: m[1], stroke: "#1d3557" }); }
  }
  for (const l of oo.lines) el(svg, "polyline", { points: pts(l.map(proj)), fill: scene.dim === 2 ? "#a8c5e6" : "none", "fill-opacity": 0.5, stroke: "#1d3557", "stroke-width": 1.2, class: "object" });

  for (const f of fingersNow) {
    for (const l of f.links) {
      const a = proj(l.a), b = proj(l.b);
      const st = stateOf[l.body];
      const color = st ? COLORS[st[0]] : "#444";
      el(svg, "line", { x1: a[0], y1: a[1], x2: b[0], y2: b[1], stroke: color, "stroke-width": Math.max(4, 2 * l.radius * proj.scale), "stroke-linecap": "round", class: "link", "data-body": l.body });
      el(svg, "circle", { cx: a[0], cy: a[1], r: 4, fill: "#fff", stroke: "#222" });
    }
  }
  if (!frameInfo || state.frameIndex === 0) {
    // a plan frame's letters name the scene's contacts when it has the same contacts, in order
    const same = frameInfo && frameInfo.contacts.length === scene.contacts.length
      && frameInfo.contacts.every((b, k) => b === scene.contacts[k].body);
    const contactLetters = frameInfo ? (same ? frameInfo.combination : null) : state.combination;
    geom.contacts.forEach((c, i) => {
      const p = c.point, n = c.normal, q = proj(p);
      const s = contactLetters ? contactLetters[i] || null : null;
      const color = s ? COLORS[s] : "#e76f51";
      // friction cone: the force directions that can act on the object at this contact
      if (scene.dim === 2) {
        const r1 = rot2(n, c.half_angle), r2 = rot2(n, -c.half_angle);
        el(svg, "polygon", { points: pts([q, proj(sub(p, mul(r1, L))), proj(sub(p, mul(r2, L)))]), fill: color, "fill-opacity": 0.18, stroke: color, "stroke-dasharray": "3 2", class: "cone" });
      } else {
        const [t1, t2] = perpBasis(n), tn = Math.tan(c.half_angle);
        const ring = Array.from({ length: 13 }, (_, k) => {
          const a = (2 * Math.PI * k) / 12;
          const d = add(n, add(mul(t1, tn * Math.cos(a)), mul(t2, tn * Math.sin(a))));
          return proj(sub(p, mul(d, L / norm(d))));
        });
        el(svg, "polyline", { points: pts(ring), fill: color, "fill-opacity": 0.15, stroke: color, class: "cone" });
        for (const k of [0, 3, 6, 9]) el(svg, "line", { x1: q[0], y1: q[1], x2: ring[k][0], y2: ring[k][1], stroke: color, "stroke-width": 0.7 });
      }
      const tail = proj(sub(p, mul(n, 1.3 * L)));
      el(svg, "line", { x1: tail[0], y1: tail[1], x2: q[0], y2: q[1], stroke: color, "stroke-width": 2, "marker-end": "url(#arrow)", class: "normal" });
      el(svg, "circle", { cx: q[0], cy: q[1], r: 5, fill: color, stroke: "#fff", class: "contact", "data-state": s || "" });
      el(svg, "text", { x: tail[0] + 3, y: tail[1] - 3, "font-size": 11, fill: "#222" }, `${i}${s ? ":" + s : ""}`);
    });
  }
  const defs = el(svg, "defs", {});
  const m = el(defs, "marker", { id: "arrow", viewBox: "0 0 10 10", refX: 9, refY: 5, markerWidth: 6, markerHeight: 6, orient: "auto-start-reverse" });
  el(m, "path", { d: "M0,0 L10,5 L0,10 z", fill: "#333" });
}

function detachJob() {
  // the job keeps running on the server, but its result no longer belongs to what is shown
  stopPolling(); stopPlaying();
  state.job = null; state.plan = null; state.frames = []; state.frameIndex = 0;
  $("job-status").textContent = "no job"; delete $("job-status").dataset.status;
  $("job-progress").value = 0; $("cancel-btn").disabled = true; $("steps").innerHTML = "";
  $("contact-states").innerHTML = ""; $("torque-bars").innerHTML = "";
}

async function setScene(scene, label) {
  detachJob();
  state.scene = scene; state.combination = null; state.rows = []; state.frames = []; state.plan = null;
  state.extraBounds = [];
  $("scene-error").textContent = ""; $("analysis-error").textContent = ""; $("job-error").textContent = "";
  $("combo-table").querySelector("tbody").innerHTML = ""; $("report").hidden = true; $("player").hidden = true;
  $("analysis-status").textContent = "";
  $("scene-info").textContent = `${label}: ${scene.dim}-D, ${scene.contacts.length} contacts, ${scene.fingers.length} fingers` + (scene.description ? ` — ${scene.description}` : "");
  $("view-hint").textContent = scene.dim === 3 ? "3-D view: drag to rotate." : "";
  try {
    state.geometry = await api("POST", "/scenes/geometry", { scene });
  } catch (e) { $("scene-error").textContent = e.message; state.geometry = null; }
  drawScene();
}

// ---------------------------------------------------------------------------------------------
// analysis

function fmtVec(v) { return v ? "[" + v.map((x) => x.toFixed(2)).join(", ") + "]" : "–"; }

function renderTable() {
  const tbody = $("combo-table").querySelector("tbody");
  tbody.innerHTML = "";
  const only = $("feasible-only").checked;
  for (const row of state.rows) {
    if (only && !row.feasible) continue;
    const tr = document.createElement("tr");
    tr.dataset.combination = row.combination;
    if (row.combination === state.combination) tr.classList.add("selected");
    const letters = [...row.combination].map((s) => `<span class="${s}" style="color:#fff;padding:0 1px">${s}</span>`).join("");
    tr.innerHTML = `<td>${letters}</td><td>${row.feasible ? "yes" : "no"}</td><td>${row.dim_dafc}</td><td>${row.dim_dpfc}</td><td>${fmtVec(row.example_direction)}</td>`;
    tr.addEventListener("click", () => selectCombination(row.combination));
    tbody.appendChild(tr);
  }
}

function showRows(result) {
  state.rows = result.combinations;
  $("analysis-status").textContent = `${result.feasible} of ${result.combinations.length} combinations feasible (${result.elapsed_seconds.toFixed(2)} s)`;
  renderTable();
}

async function runAnalysis() {
  if (!state.scene) return;
  $("analysis-error").textContent = ""; $("analysis-status").textContent = "analysing…";
  $("analyze-btn").disabled = true;
  try { showRows(await api("POST", "/analyses", { scene: state.scene })); }
  catch (e) { $("analysis-error").textContent = e.message; $("analysis-status").textContent = ""; }
  finally { $("analyze-btn").disabled = false; }
}

async function selectCombination(c) {
  state.combination = c; state.frames = []; renderTable(); drawScene();
  $("report").hidden = false; $("report-title").textContent = `${c}: analysing…`; $("report-text").textContent = "";
  try {
    const res = await api("POST", "/analyses", { scene: state.scene, combination: c });
    const r = res.report; state.report = r;
    $("report-title").textContent = `${c}: ${r.feasible ? "feasible" : "not feasible"} (${r.reason})`;
    const parts = [`motion space a = ${r.a}, object part ã = ${r.a_bar}, dim DAFC ${r.dim_dafc}, dim DPFC ${r.dim_dpfc}`];
    if (r.stationary) parts.push(`τ_st = ${fmtVec(r.stationary.tau)}`);
    if (r.torque_set) parts.push(`recommended τ for ${fmtVec(r.torque_set.direction)}: ${fmtVec(r.torque_set.recommended)}`);
    if (r.torque_set_error) parts.push(`torque set: ${r.torque_set_error}`);
    $("report-text").textContent = parts.join(" · ");
    drawDafc();
  } catch (e) { $("report-title").textContent = `${c}: error`; $("report-text").textContent = e.message; }
}

function drawDafc() {
  const svg = $("dafc-view"); svg.innerHTML = "";
  const r = state.report;
  if (!r || !r.dafc) { el(svg, "text", { x: 20, y: 160, "font-size": 12 }, "no DAFC samples (the object cannot move)"); return; }
  const dirs = r.dafc.directions.map((d) => d.slice(0, 3)), member = r.dafc.member;
  const corners = [[1, 1, 1], [-1, -1, -1], [1, -1, 1], [-1, 1, -1]];
  const proj = makeProjector(3, state.dafcView, corners, 320, 320, 20);
  const names = state.scene.dim === 2 ? ["x", "y", "θ"] : ["x", "y", "z"];
  [[1, 0, 0], [0, 1, 0], [0, 0, 1]].forEach((v, i) => {
    const a = proj(mul(v, -1)), b = proj(v);
    el(svg, "line", { x1: a[0], y1: a[1], x2: b[0], y2: b[1], stroke: "#999", "stroke-dasharray": "2 2" });
    el(svg, "text", { x: b[0] + 3, y: b[1], "font-size": 11, fill: "#555" }, names[i]);
  });
  const order = dirs.map((d, i) => [proj(d)[2], i]).sort((a, b) => b[0] - a[0]);
  for (const [, i] of order) {
    const q = proj(dirs[i]);
    el(svg, "circle", { cx: q[0], cy: q[1], r: member[i] ? 3.5 : 2, fill: member[i] ? "#2a9d8f" : "#bbb", class: member[i] ? "dafc-in" : "dafc-out" });
  }
  if (r.example_direction) {
    const q = proj(r.example_direction.slice(0, 3)), o = proj([0, 0, 0]);
    el(svg, "line", { x1: o[0], y1: o[1], x2: q[0], y2: q[1], stroke: "#1d3557", "stroke-width": 2 });
  }
}

// ---------------------------------------------------------------------------------------------
// jobs: plans and enumerations

async function startJob(kind) {
  if (!state.scene) return;
  $("job-error").textContent = "";
  stopPolling();
  const scene = state.scene;
  const body = kind === "plan" ? { scene, goal: { type: $("goal-select").value } } : { scene };
  try {
    const job = await api("POST", kind === "plan" ? "/plans" : "/enumerations", body);
    if (state.scene !== scene) return;  // the scene changed while the job was being created
    state.job = job; showJob(job); $("cancel-btn").disabled = false;
    state.pollTimer = setInterval(pollJob, 400);
  } catch (e) { $("job-error").textContent = e.message; }
}

function stopPolling() { if (state.pollTimer) clearInterval(state.pollTimer); state.pollTimer = null; }

function showJob(job) {
  $("job-progress").value = job.progress;
  const pct = Math.round(job.progress * 100);
  const t = job.elapsed_seconds != null ? ` · ${job.elapsed_seconds.toFixed(1)} s` : "";
  $("job-status").textContent = `${job.kind} ${job.id}: ${job.status} ${pct}% — ${job.message}${t}`;
  $("job-status").dataset.status = job.status;
  $("job-status").dataset.jobId = job.id;
  if (job.error) $("job-error").textContent = job.error;
}

async function pollJob() {
  if (!state.job) return;
  const current = state.job, scene = state.scene;
  const stale = () => state.job === null || state.job.id !== current.id || state.scene !== scene;
  let job;
  try { job = await api("GET", current.url); } catch (e) { if (!stale()) { $("job-error").textContent = e.message; stopPolling(); } return; }
  if (stale()) return;
  state.job = job; showJob(job);
  if (["succeeded", "failed", "cancelled"].includes(job.status)) {
    stopPolling(); $("cancel-btn").disabled = true;
    if (job.status === "succeeded") {
      const result = await api("GET", job.result_url);
      if (stale()) return;
      if (job.kind === "plan") {
        if (!result.found) {  // the job ran to its end, but found no plan: say so, not "succeeded"
          $("job-status").textContent = `plan ${job.id}: no plan (the reason below)`;
          $("job-status").dataset.status = "no-plan";
        }
        await loadPlan(result, scene);
      } else showRows(result);
    }
  }
}

async function cancelJob() {
  if (!state.job) return;
  try { showJob(await api("DELETE", state.job.url)); } catch (e) { $("job-error").textContent = e.message; }
}

// ---------------------------------------------------------------------------------------------
// plan playback

async function loadPlan(plan, scene) {
  if (state.scene !== scene) return;
  state.plan = plan;
  const steps = $("steps"); steps.innerHTML = "";
  $("player").hidden = false;
  if (!plan.found) { $("job-error").textContent = `no plan: ${plan.reason}`; }
  const items = [];
  plan.steps.forEach((s, k) => {
    const li = document.createElement("li");
    li.textContent = `${s.kind} · ${s.combination} · ${(s.joint_path || []).length} waypoints`;
    steps.appendChild(li);
    (s.joint_path || []).forEach((q, j) => items.push({ step: k, q, pose: (s.object_path || [])[j] || null }));
  });
  // at most 2000 frames: keep every k-th waypoint and each step's last one
  const stride = Math.max(1, Math.ceil(items.length / 2000));
  const kept = items.filter((it, i) => i % stride === 0 || i === items.length - 1 || items[i + 1].step !== it.step);
  state.frames = [];
  if (kept.length) {
    const geom = await api("POST", "/scenes/geometry", { scene, configurations: kept.map((it) => it.q) });
    if (state.scene !== scene || state.plan !== plan) return;  // another scene or job meanwhile
    state.frames = kept.map((it, i) => {
      const s = plan.steps[it.step];
      return { step: it.step, fingers: geom.frames[i].fingers, pose: it.pose, combination: s.combination,
               contacts: contactBodies(s), torques: (s.torques && s.torques.chosen) || [] };
    });
  }
  // the view fits every frame of the plan, so it does not jump while playing
  state.extraBounds = [];
  for (const f of state.frames) {
    for (const fi of f.fingers) for (const l of fi.links) state.extraBounds.push(l.a, l.b);
    if (f.pose) { const o = objectOutline(state.scene, objectFrame(state.scene, f.pose)); for (const [c, r] of o.circles) state.extraBounds.push(c.map((x) => x + r), c.map((x) => x - r)); for (const l of o.lines) state.extraBounds.push(...l); }
  }
  $("frame-slider").max = Math.max(0, state.frames.length - 1);
  $("player").hidden = plan.steps.length === 0;  // nothing to play
  setFrame(0);
}

function contactBodies(step) {
  // the bodies the combination's letters refer to (a new contact is in contacts_after only)
  const before = step.contacts_before || [], after = step.contacts_after || [];
  return after.length === (step.combination || "").length && before.length !== after.length ? after : before;
}

function setFrame(i) {
  state.frameIndex = Math.max(0, Math.min(i, state.frames.length - 1));
  $("frame-slider").value = state.frameIndex;
  const f = state.frames[state.frameIndex];
  [...$("steps").children].forEach((li, k) => li.classList.toggle("current", f && k === f.step));
  $("frame-label").textContent = f ? `step ${f.step + 1} of ${state.plan.steps.length}, frame ${state.frameIndex + 1}/${state.frames.length}` : "empty plan";
  const cs = $("contact-states"); cs.innerHTML = "";
  if (f) f.contacts.forEach((b, k) => { const s = f.combination[k] || "?"; const span = document.createElement("span"); span.className = `chip ${s}`; span.textContent = `${b}: ${s}`; cs.appendChild(span); });
  drawTorques(f ? f.torques : []);
  drawScene();
}

function drawTorques(tau) {
  const svg = $("torque-bars"); svg.innerHTML = "";
  if (!tau || !tau.length) { el(svg, "text", { x: 10, y: 70, "font-size": 12 }, "no joint torques for this step"); return; }
  const m = Math.max(...tau.map(Math.abs), 1e-9), w = 300 / tau.length;
  el(svg, "line", { x1: 10, y1: 70, x2: 310, y2: 70, stroke: "#999" });
  tau.forEach((t, j) => {
    const h = (Math.abs(t) / m) * 55;
    el(svg, "rect", { x: 10 + j * w + 2, y: t >= 0 ? 70 - h : 70, width: Math.max(2, w - 4), height: h, fill: t >= 0 ? "#457b9d" : "#e76f51", class: "torque-bar" });
    el(svg, "text", { x: 10 + j * w + 2, y: 136, "font-size": 9 }, `${j}`);
  });
  el(svg, "text", { x: 200, y: 12, "font-size": 10 }, `max |τ| = ${m.toFixed(3)}`);
}

function stopPlaying() {
  if (state.playTimer) clearInterval(state.playTimer);
  state.playTimer = null; $("play-btn").textContent = "Play";
}

function togglePlay() {
  if (state.playTimer) { stopPlaying(); return; }
  $("play-btn").textContent = "Pause";
  state.playTimer = setInterval(() => {
    if (state.frameIndex >= state.frames.length - 1) { togglePlay(); return; }
    setFrame(state.frameIndex + 1);
  }, 60);
}

function stepJump(dir) {
  const f = state.frames[state.frameIndex]; if (!f) return;
  const target = f.step + dir;
  const i = dir > 0 ? state.frames.findIndex((x) => x.step === target) : state.frames.findIndex((x) => x.step === Math.max(0, target));
  if (i >= 0) setFrame(i);
}

// ---------------------------------------------------------------------------------------------
// start-up

async function init() {
  enableDragRotate($("scene-view"), state.view, drawScene);
  enableDragRotate($("dafc-view"), state.dafcView, drawDafc);
  $("analyze-btn").addEventListener("click", runAnalysis);
  $("feasible-only").addEventListener("change", renderTable);
  $("plan-btn").addEventListener("click", () => startJob("plan"));
  $("enum-btn").addEventListener("click", () => startJob("enumeration"));
  $("cancel-btn").addEventListener("click", cancelJob);
  $("play-btn").addEventListener("click", togglePlay);
  $("prev-btn").addEventListener("click", () => stepJump(-1));
  $("next-btn").addEventListener("click", () => stepJump(1));
  $("frame-slider").addEventListener("input", (e) => setFrame(Number(e.target.value)));
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
  document.body.dataset.ready = "1";
}

init();
