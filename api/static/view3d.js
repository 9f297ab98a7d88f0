// The 3-D scene view of the dashboard: three.js (WebGL) with OrbitControls, URDF fingers with their
// visual meshes (urdf-loader), chains as translucent capsules, the object's shape, fixed bodies,
// contacts with their normals and friction cones coloured by state, and axes with units.
// Vendored ES modules only (index.html's import map); it renders on demand, not in a loop.

import * as THREE from "three";
import { OrbitControls } from "three/addons/controls/OrbitControls.js";
import URDFLoader from "urdf-loader";

export const COLORS = { F: "#2a9d8f", S: "#e9a03b", D: "#d1495b", N: "#577590" };
export const BACKGROUND = 0xfbfcfd;
/** Object paths in the plan player: the planned one and the MuJoCo replay's (index.html's legend). */
export const PATH_COLORS = { planned: "#1d3557", replay: "#c2185b" };
const LINK_GREY = 0x8a94a0, MESH_GREY = 0xb8c0ca, OBJECT_BLUE = 0x7fa8d8;
const ERD_PREFIX = "example-robot-data:", ROBOT_PREFIX = "robot:";

// ---------------------------------------------------------------------------------------------
// where a scene's URDF and its package:// meshes are fetched from

/** The URL of a scene's ``urdf.file`` and the mapping of its package:// URIs, or null when the
 * browser cannot fetch it (a file on the server's disk). */
export function robotSource(file) {
  if (file.startsWith(ERD_PREFIX)) {
    const rel = file.slice(ERD_PREFIX.length).replace(/^\/+/, "");
    const base = "/robot-files/example-robot-data";
    // example-robot-data's URDFs name package://example-robot-data/robots/<robot>/...; others use
    // ROS package names, which are folders of the robots folder
    const pkg = (name, relPath) => (name === "example-robot-data" && relPath.startsWith("robots/")
      ? `${base}/${relPath.slice("robots/".length)}` : `${base}/${name}/${relPath}`);
    return { url: `${base}/${encodePath(rel)}`, pkg };
  }
  if (file.startsWith(ROBOT_PREFIX)) {
    const rest = file.slice(ROBOT_PREFIX.length), cut = rest.indexOf("/");
    if (cut <= 0) return null;
    const hash = rest.slice(0, cut), rel = rest.slice(cut + 1);
    const base = `/robots/${encodeURIComponent(hash)}/files`;
    // a package is a folder of the uploaded archive; else the archive itself is the package
    const top = rel.split("/")[0];
    const pkg = (name, relPath) => (name === top ? `${base}/${name}/${relPath}` : `${base}/${relPath}`);
    return { url: `${base}/${encodePath(rel)}`, pkg };
  }
  return null;
}

function encodePath(p) { return p.split("/").map(encodeURIComponent).join("/"); }

// ---------------------------------------------------------------------------------------------
// small helpers

const v3 = (a) => new THREE.Vector3(a[0], a[1], a[2] || 0);

function niceStep(x) {
  // 1, 2 or 5 times a power of ten, at most x
  const p = 10 ** Math.floor(Math.log10(x)), m = x / p;
  return (m >= 5 ? 5 : m >= 2 ? 2 : 1) * p;
}

export function formatLength(m) {
  if (m >= 1) return `${+m.toFixed(2)} m`;
  if (m >= 0.01) return `${+(m * 100).toFixed(1)} cm`;
  return `${+(m * 1000).toFixed(1)} mm`;
}

function textSprite(text, color = "#1d232a", px = 28) {
  const c = document.createElement("canvas"), g = c.getContext("2d");
  g.font = `${px}px system-ui, sans-serif`;
  const w = Math.ceil(g.measureText(text).width) + 8;
  c.width = w; c.height = px + 8;
  g.font = `${px}px system-ui, sans-serif`;
  g.fillStyle = "rgba(255,255,255,0.75)"; g.fillRect(0, 0, c.width, c.height);
  g.fillStyle = color; g.textBaseline = "middle"; g.fillText(text, 4, c.height / 2);
  const tex = new THREE.CanvasTexture(c);
  tex.colorSpace = THREE.SRGBColorSpace;
  const s = new THREE.Sprite(new THREE.SpriteMaterial({ map: tex, depthTest: false, transparent: true }));
  s.renderOrder = 10;
  s.userData.aspect = c.width / c.height;
  return s;
}

function setSpriteSize(s, h) { s.scale.set(h * s.userData.aspect, h, 1); }

/** Object pose as a Matrix4: the scene's pose, or a plan's pose vector [position, rotation
 * vector] (absolute, as planner/state.py's pose_vector). */
export function objectMatrix(scene, poseVec) {
  const q0 = scene.object.pose.quat_wxyz || [1, 0, 0, 0];
  if (!poseVec) return new THREE.Matrix4().compose(v3(scene.object.pose.position), new THREE.Quaternion(q0[1], q0[2], q0[3], q0[0]), new THREE.Vector3(1, 1, 1));
  return new THREE.Matrix4().compose(v3(poseVec.slice(0, 3)), rotvecQuat(poseVec.slice(3, 6)), new THREE.Vector3(1, 1, 1));
}

export function rotvecQuat(r) {
  const v = v3(r), t = v.length();
  return t < 1e-12 ? new THREE.Quaternion() : new THREE.Quaternion().setFromAxisAngle(v.divideScalar(t), t);
}

/** Pose vector between a and b (fraction u): position linear, rotation by slerp. */
export function interpolatePose3(a, b, u) {
  const p = a.slice(0, 3).map((x, i) => x + (b[i] - x) * u);
  const q = rotvecQuat(a.slice(3, 6)).slerp(rotvecQuat(b.slice(3, 6)), u);
  const w = Math.min(1, Math.max(-1, q.w)), s = Math.sqrt(1 - w * w), t = 2 * Math.acos(w);
  const r = s < 1e-9 ? [0, 0, 0] : [q.x / s * t, q.y / s * t, q.z / s * t];
  return [...p, ...r];
}

function disposeTree(obj) {
  obj.traverse((o) => {
    if (o.geometry) o.geometry.dispose();
    const mats = Array.isArray(o.material) ? o.material : o.material ? [o.material] : [];
    for (const m of mats) { if (m.map) m.map.dispose(); m.dispose(); }
  });
}

function shapeMesh(shape, material, edgeColor = 0x1d3557) {
  // a THREE.Object3D of an object or fixed-body shape in its own frame, or null
  let geom = null;
  const o = shape.position || [0, 0, 0];
  if (shape.type === "box") geom = new THREE.BoxGeometry(shape.size[0], shape.size[1], shape.size[2]);
  else if (shape.type === "sphere") geom = new THREE.SphereGeometry(shape.radius, 32, 16);
  else if (shape.type === "cylinder") geom = new THREE.CylinderGeometry(shape.radius, shape.radius, shape.height, 40).rotateX(Math.PI / 2);
  if (!geom && shape.type === "segment") {
    const g = new THREE.BufferGeometry().setFromPoints(shape.points.map(v3));
    return new THREE.Line(g, new THREE.LineBasicMaterial({ color: 0x555555 }));
  }
  if (!geom) return null;
  const group = new THREE.Group();
  const mesh = new THREE.Mesh(geom, material);
  mesh.position.set(o[0], o[1], o[2]);
  const edges = new THREE.LineSegments(new THREE.EdgesGeometry(geom, 20), new THREE.LineBasicMaterial({ color: edgeColor, transparent: true, opacity: 0.6 }));
  edges.position.copy(mesh.position);
  group.add(mesh, edges);
  return group;
}

function placeAlong(obj, a, b) {
  // put a Y-axis aligned object between a and b (its centre at the midpoint)
  const d = new THREE.Vector3().subVectors(b, a), len = d.length();
  obj.position.addVectors(a, b).multiplyScalar(0.5);
  if (len > 1e-12) obj.quaternion.setFromUnitVectors(new THREE.Vector3(0, 1, 0), d.divideScalar(len));
  return len;
}

/** The chain joints of a URDF finger, in path order from root_link to tip_link: the revolute and
 * continuous joints between them (as analysis/urdf.py picks them for pinocchio). */
export function chainJoints(robot, rootLink, tipLink) {
  const root = robot.links[rootLink], tip = robot.links[tipLink];
  if (!root || !tip) throw new Error(`URDF: no link '${!root ? rootLink : tipLink}'`);
  const joints = [];
  for (let o = tip; o && o !== root; o = o.parent) {
    if (o.isURDFJoint && (o.jointType === "revolute" || o.jointType === "continuous")) joints.push(o);
    if (!o.parent) throw new Error(`URDF: link '${tipLink}' is not below '${rootLink}'`);
  }
  return joints.reverse();
}

// ---------------------------------------------------------------------------------------------

export class SceneView3D {
  constructor(container) {
    this.container = container;
    this.renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
    this.renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));
    this.renderer.setClearColor(BACKGROUND, 1);
    this.canvas = this.renderer.domElement;
    this.canvas.id = "scene-canvas";
    container.appendChild(this.canvas);
    this.scene = new THREE.Scene();
    this.camera = new THREE.PerspectiveCamera(40, 1, 0.001, 100);
    this.camera.up.set(0, 0, 1);
    this.controls = new OrbitControls(this.camera, this.canvas);
    this.controls.addEventListener("change", () => this.render());
    this.scene.add(new THREE.HemisphereLight(0xffffff, 0x8090a0, 1.6));
    const sun = new THREE.DirectionalLight(0xffffff, 1.6);
    sun.position.set(1, -1.5, 2);
    this.scene.add(sun);
    const fill = new THREE.DirectionalLight(0xffffff, 0.5);
    fill.position.set(-1, 1, -0.5);
    this.scene.add(fill);
    this.root = new THREE.Group();
    this.scene.add(this.root);
    this.generation = 0;
    this.robots = [];   // {robot, group, fingers: [{index, joints, slice}]}
    this.pending = 0;
    new ResizeObserver(() => this.resize()).observe(container);
    this.resize();
  }

  resize() {
    const w = Math.max(50, this.container.clientWidth), h = Math.max(50, this.container.clientHeight);
    this.renderer.setSize(w, h, false);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    this.render();
  }

  render() {
    if (this.renderQueued) return;
    this.renderQueued = true;
    requestAnimationFrame(() => { this.renderQueued = false; this.renderNow(); });
  }

  renderNow() { this.renderer.render(this.scene, this.camera); }

  clear() {
    this.generation += 1;
    for (const c of [...this.root.children]) { this.root.remove(c); disposeTree(c); }
    this.robots = []; this.capsules = {}; this.contactGroup = null; this.objectGroup = null;
    this.pathGroup = null; this.ghost = null;
    delete this.container.dataset.replayPoints; delete this.container.dataset.plannedPoints;
    delete this.container.dataset.ghost;
    this.container.dataset.meshes = "0";
    delete this.container.dataset.robots;
  }

  /** Build the view of ``scene`` from its ``/scenes/geometry`` answer; resolves when every
   * URDF and mesh has loaded (or failed: ``errors`` lists what did not load). */
  async load(scene, geometry) {
    this.clear();
    const gen = this.generation;
    this.sceneData = scene; this.geometry = geometry;
    this.errors = [];
    // the scene's size sets marker, cone and label sizes
    const box = new THREE.Box3();
    for (const f of geometry.frames[0].fingers) for (const l of f.links) { box.expandByPoint(v3(l.a)); box.expandByPoint(v3(l.b)); }
    for (const c of geometry.contacts) box.expandByPoint(v3(c.point));
    box.expandByPoint(v3(scene.object.pose.position));
    const size = Math.max(box.getSize(new THREE.Vector3()).length(), 1e-3);
    this.size = size;
    this.mark = size * 0.08;  // cone height, normal length

    // the camera frames the hand, object and contacts (a table may be much larger)
    const fitBox = box.clone().expandByScalar(size * 0.1);
    // fixed bodies and the object
    for (const b of scene.fixed_bodies || []) {
      const m = shapeMesh(b.shape, new THREE.MeshStandardMaterial({ color: 0xc9ced6, transparent: true, opacity: 0.22, depthWrite: false, roughness: 0.9 }), 0x9aa3ad);
      if (m) { m.userData.body = b.name; m.name = `fixed:${b.name}`; this.root.add(m); box.expandByObject(m); }
    }
    this.objectGroup = new THREE.Group();
    this.objectGroup.matrixAutoUpdate = false;
    const objMat = new THREE.MeshStandardMaterial({ color: OBJECT_BLUE, transparent: true, opacity: 0.55, roughness: 0.6, depthWrite: false });
    const om = shapeMesh(scene.object.shape, objMat) || new THREE.Mesh(new THREE.SphereGeometry(size * 0.02), objMat);
    this.objectGroup.add(om);
    this.objectGroup.add(new THREE.AxesHelper(size * 0.08));
    this.root.add(this.objectGroup);

    // chain fingers: one translucent capsule per link (updated per frame)
    this.capsules = {};
    scene.fingers.forEach((f, i) => {
      for (const l of geometry.frames[0].fingers[i].links) {
        // a URDF finger's capsule is its collision model (link_radius): faint over the real meshes
        const isUrdf = !!f.urdf;
        const r = l.radius > 0 ? l.radius : size * (isUrdf ? 0.003 : 0.008);
        const len = v3(l.a).distanceTo(v3(l.b));
        const geom = new THREE.CapsuleGeometry(r, Math.max(len, 1e-6), 6, 16);
        const mat = new THREE.MeshStandardMaterial({ color: LINK_GREY, transparent: true, opacity: isUrdf ? 0.12 : 0.45, depthWrite: false, roughness: 0.5 });
        const m = new THREE.Mesh(geom, mat);
        m.userData = { body: l.body, length: len, urdf: isUrdf };
        m.name = `link:${l.body}`;
        const joint = new THREE.Mesh(new THREE.SphereGeometry(isUrdf ? size * 0.004 : r, 16, 8), new THREE.MeshStandardMaterial({ color: 0xffffff, roughness: 0.4 }));
        joint.name = `joint:${l.body}`;
        this.capsules[l.body] = { mesh: m, joint };
        this.root.add(m, joint);
      }
    });

    // contacts (rebuilt per frame)
    this.contactGroup = new THREE.Group();
    this.root.add(this.contactGroup);

    // axes with units at the world origin, and a grid under the scene
    this.addAxes(box);
    this.fit(fitBox);

    // URDF fingers: one robot per (file, base, root link); each finger sets its chain's joints
    const groups = new Map();
    scene.fingers.forEach((f, i) => {
      if (!f.urdf) return;
      const key = JSON.stringify([f.urdf.file, f.base.position, f.base.quat_wxyz, f.urdf.root_link]);
      if (!groups.has(key)) groups.set(key, []);
      groups.get(key).push(i);
    });
    const loads = [...groups.values()].map((idx) => this.loadRobot(scene, idx, gen));
    await Promise.all(loads);
    if (gen !== this.generation) return;
    this.container.dataset.robots = String(this.robots.length);
    this.render();
  }

  loadRobot(scene, fingerIdx, gen) {
    const f0 = scene.fingers[fingerIdx[0]];
    const src = robotSource(f0.urdf.file);
    if (!src) { this.errors.push(`${f0.name}: ${f0.urdf.file} is a file of the server: drawn as capsules`); return Promise.resolve(); }
    return new Promise((resolve) => {
      const manager = new THREE.LoadingManager();
      const loader = new URDFLoader(manager);
      let meshes = 0;
      loader.packages = (name) => `package-marker:${name}`;
      loader.loadMeshCb = (path, mgr, material, done) => {
        let url = path;
        const m = /^package-marker:([^/]+)\/(.*)$/.exec(path);
        if (m) url = src.pkg(m[1], m[2]);
        loader.defaultMeshLoader(url, mgr, material, (obj, err) => {
          if (err || !obj) this.errors.push(`mesh ${url}: ${err ? err.message || err : "not loaded"}`);
          else meshes += 1;
          done(obj, err);
        });
      };
      let robot = null;
      manager.onLoad = () => {
        if (gen !== this.generation || !robot) { resolve(); return; }
        this.container.dataset.meshes = String(Number(this.container.dataset.meshes || 0) + meshes);
        robot.traverse((o) => {
          if (!o.isMesh) return;
          // translucent, so contacts behind a link stay visible; one material per mesh, so a link
          // can take its contact state's colour
          o.material = new THREE.MeshStandardMaterial({ color: MESH_GREY, transparent: true, opacity: 0.6, roughness: 0.55, metalness: 0.05, depthWrite: false });
          let l = o.parent;
          while (l && !l.isURDFLink) l = l.parent;
          o.userData.link = l ? l.name : null;
        });
        this.render();
        resolve();
      };
      loader.load(src.url, (r) => {
        if (gen !== this.generation) return;
        robot = r;
        const group = new THREE.Group();
        group.matrixAutoUpdate = false;
        group.add(robot);
        this.root.add(group);
        const fingers = [];
        let start = 0;
        scene.fingers.forEach((f, i) => {
          if (fingerIdx.includes(i)) {
            try {
              fingers.push({ index: i, joints: chainJoints(robot, f.urdf.root_link, f.urdf.tip_link), start, n: f.q.length });
            } catch (e) { this.errors.push(`${f.name}: ${e.message}`); }
          }
          start += f.q.length;
        });
        // the finger's base is the world pose of root_link: place the robot at base * inv(T_root)
        robot.updateMatrixWorld(true);
        const rootLink = robot.links[f0.urdf.root_link];
        const Troot = rootLink ? rootLink.matrixWorld.clone() : new THREE.Matrix4();
        const q = f0.base.quat_wxyz;
        const base = new THREE.Matrix4().compose(v3(f0.base.position), new THREE.Quaternion(q[1], q[2], q[3], q[0]), new THREE.Vector3(1, 1, 1));
        group.matrix.copy(base.multiply(Troot.invert()));
        group.matrixWorldNeedsUpdate = true;
        this.robots.push({ robot, group, fingers });
        if (this.lastFrame) this.update(this.lastFrame);
      }, undefined, (err) => { this.errors.push(`URDF ${src.url}: ${err.message || err}`); resolve(); });
    });
  }

  /** The joint names of every finger, in the order of the scene's q: URDF joint names where a
   * robot has loaded, else "joint k". */
  jointNames() {
    const names = [];
    (this.sceneData ? this.sceneData.fingers : []).forEach((f, i) => {
      let chain = null;
      for (const r of this.robots) for (const fi of r.fingers) if (fi.index === i) chain = fi.joints;
      f.q.forEach((_, k) => names.push(`${f.name}/${chain && chain[k] ? chain[k].name : `joint ${k}`}`));
    });
    return names;
  }

  addAxes(box) {
    const step = niceStep(this.size * 0.25);
    const axes = new THREE.Group();
    axes.name = "axes";
    const cols = [0xd1495b, 0x2a9d8f, 0x3d5a80];
    ["x", "y", "z"].forEach((n, i) => {
      const dir = [0, 0, 0]; dir[i] = 1;
      const arrow = new THREE.ArrowHelper(v3(dir), new THREE.Vector3(), step, cols[i], step * 0.18, step * 0.09);
      axes.add(arrow);
      const label = textSprite(`${n} [m]`, "#" + cols[i].toString(16).padStart(6, "0"));
      setSpriteSize(label, this.size * 0.035);
      label.position.copy(v3(dir).multiplyScalar(step * 1.15));
      axes.add(label);
    });
    const tick = textSprite(`axes ${formatLength(step)} · grid ${formatLength(step / 2)}`, "#555");
    setSpriteSize(tick, this.size * 0.03);
    tick.position.set(step * 0.5, -step * 0.25, 0);
    axes.add(tick);
    this.root.add(axes);
    // a grid on the lowest z of the scene, half an axis step apart
    const c = box.getCenter(new THREE.Vector3()), ext = box.getSize(new THREE.Vector3());
    const cell = step / 2, n = Math.min(60, Math.max(4, Math.ceil((Math.max(ext.x, ext.y) * 1.6) / cell)));
    const grid = new THREE.GridHelper(n * cell, n, 0xc5ccd6, 0xe3e7ec);
    grid.rotateX(Math.PI / 2);
    grid.position.set(Math.round(c.x / cell) * cell, Math.round(c.y / cell) * cell, box.min.z);
    grid.name = "grid";
    this.root.add(grid);
  }

  fit(box) {
    const c = box.getCenter(new THREE.Vector3());
    const r = Math.max(box.getSize(new THREE.Vector3()).length() / 2, 1e-3);
    const dist = (r / Math.sin(THREE.MathUtils.degToRad(this.camera.fov / 2))) * 1.05;
    const dir = new THREE.Vector3(1.1, -1.6, 0.9).normalize();
    this.camera.position.copy(c).addScaledVector(dir, dist);
    this.camera.near = dist / 100; this.camera.far = dist * 20;
    this.camera.updateProjectionMatrix();
    this.controls.target.copy(c);
    this.controls.update();
  }

  /** Show one frame: ``fingers`` (the geometry's links), ``q`` (all joints), ``pose`` (object pose
   * vector or null), ``contacts`` [{point, normal, half_angle, state, label}], ``stateOf`` {body: letter}. */
  update(frame) {
    this.lastFrame = frame;
    if (!this.sceneData) return;
    const scene = this.sceneData, stateOf = frame.stateOf || {};
    this.objectGroup.matrix.copy(objectMatrix(scene, frame.pose));
    this.objectGroup.matrixWorldNeedsUpdate = true;
    for (const f of frame.fingers) {
      for (const l of f.links) {
        const cap = this.capsules[l.body];
        if (!cap) continue;
        const a = v3(l.a), b = v3(l.b);
        placeAlong(cap.mesh, a, b);
        cap.joint.position.copy(a);
        const s = stateOf[l.body];
        cap.mesh.material.color.set(s ? COLORS[s] : LINK_GREY);
        if (cap.mesh.userData.urdf) cap.mesh.material.opacity = s ? 0.35 : 0.12;
      }
    }
    // URDF robots: the chain joints of each finger from q
    for (const r of this.robots) {
      for (const fi of r.fingers) {
        fi.joints.forEach((j, k) => { const v = frame.q ? frame.q[fi.start + k] : undefined; if (v !== undefined) j.setJointValue(v); });
      }
      r.robot.traverse((o) => {
        if (o.isMesh && o.userData.link !== undefined) {
          const key = this.bodyOfLink(r, o.userData.link);
          const s = key ? stateOf[key] : null;
          o.material.color.set(s ? COLORS[s] : MESH_GREY);
        }
      });
    }
    this.drawContacts(frame.contacts || []);
    if (this.ghost) {  // the object where MuJoCo had it at this frame
      this.ghost.visible = !!frame.ghost;
      if (frame.ghost) { this.ghost.matrix.copy(objectMatrix(scene, frame.ghost)); this.ghost.matrixWorldNeedsUpdate = true; }
      this.container.dataset.ghost = frame.ghost ? frame.ghost.map((x) => x.toFixed(6)).join(" ") : "";
    }
    this.container.dataset.frame = String(frame.index ?? 0);
    this.render();
  }

  /** The planned object path and the MuJoCo replay's (lists of pose vectors; only their
   * positions are drawn: a line through the samples and a dot at each, seen through the object
   * and links), and a ghost of the object for the replay's pose of each frame (``update``'s
   * ``frame.ghost``). ``null`` removes a path; without a replay there is no ghost. */
  setPaths(planned, replay) {
    if (this.pathGroup) { this.root.remove(this.pathGroup); disposeTree(this.pathGroup); }
    if (this.ghost) { this.root.remove(this.ghost); disposeTree(this.ghost); }
    this.pathGroup = null; this.ghost = null;
    delete this.container.dataset.replayPoints; delete this.container.dataset.plannedPoints;
    delete this.container.dataset.ghost;
    if (!this.sceneData) return;
    this.pathGroup = new THREE.Group();
    this.pathGroup.name = "paths";
    const line = (poses, color, name, dashed) => {
      const geom = new THREE.BufferGeometry().setFromPoints(poses.map((p) => v3(p)));
      const mat = dashed
        ? new THREE.LineDashedMaterial({ color, dashSize: this.size * 0.01, gapSize: this.size * 0.006, depthTest: false, transparent: true })
        : new THREE.LineBasicMaterial({ color, depthTest: false, transparent: true });
      const l = new THREE.Line(geom, mat);
      if (dashed) l.computeLineDistances();
      l.name = name; l.renderOrder = 6;
      const dots = new THREE.Points(geom, new THREE.PointsMaterial({ color, size: dashed ? 3 : 4, sizeAttenuation: false, depthTest: false, transparent: true }));
      dots.name = `${name}:points`; dots.renderOrder = 6;
      this.pathGroup.add(l, dots);
    };
    if (planned && planned.length) { line(planned, PATH_COLORS.planned, "path:planned", true); this.container.dataset.plannedPoints = String(planned.length); }
    if (replay && replay.length) {
      line(replay, PATH_COLORS.replay, "path:replay", false);
      this.container.dataset.replayPoints = String(replay.length);
      // a wireframe, so the planned object keeps its colour under it
      const mat = new THREE.MeshBasicMaterial({ color: PATH_COLORS.replay, wireframe: true, transparent: true, opacity: 0.16, depthWrite: false });
      const g = new THREE.Group();
      const m = shapeMesh(this.sceneData.object.shape, mat, PATH_COLORS.replay);
      if (m) g.add(m);
      g.name = "ghost:replay"; g.matrixAutoUpdate = false; g.visible = false;
      this.ghost = g;
      this.root.add(g);
    }
    this.root.add(this.pathGroup);
    this.render();
  }

  bodyOfLink(r, link) {
    for (const fi of r.fingers) {
      const f = this.sceneData.fingers[fi.index];
      const body = `${f.name}/${link}`;
      if (this.capsules[body]) return body;
    }
    return null;
  }

  drawContacts(contacts) {
    for (const c of [...this.contactGroup.children]) { this.contactGroup.remove(c); disposeTree(c); }
    const h = this.mark;
    contacts.forEach((c) => {
      const color = new THREE.Color(c.state ? COLORS[c.state] : "#e76f51");
      const p = v3(c.point), g = new THREE.Group();
      g.name = `contact:${c.label}`;
      g.userData = { state: c.state || "", body: c.body };
      // the point and its normal show through links and object (drawn last, no depth test)
      const dot = new THREE.Mesh(new THREE.SphereGeometry(h * 0.2, 16, 8), new THREE.MeshBasicMaterial({ color, depthTest: false, transparent: true, opacity: 0.95 }));
      dot.position.copy(p);
      dot.renderOrder = 5;
      g.add(dot);
      if (c.normal) {
        const n = v3(c.normal).normalize();
        // the normal points into the object: an arrow arriving at the contact point
        const tail = p.clone().addScaledVector(n, -1.4 * h);
        const arrow = new THREE.ArrowHelper(n, tail, 1.4 * h, color.getHex(), 0.35 * h, 0.18 * h);
        arrow.traverse((o) => { if (o.material) { o.material.depthTest = false; o.material.transparent = true; o.renderOrder = 5; } });
        g.add(arrow);
        // the friction cone: the forces the contact can put on the object, apex at the point,
        // drawn on the finger's side
        const half = c.half_angle || 0;
        if (half > 1e-6) {
          const rad = h * Math.tan(half);
          const cone = new THREE.Mesh(new THREE.ConeGeometry(rad, h, 24, 1, true),
            new THREE.MeshBasicMaterial({ color, transparent: true, opacity: 0.3, side: THREE.DoubleSide, depthWrite: false, depthTest: false }));
          cone.renderOrder = 4;  // seen through the finger it sits in
          placeAlong(cone, p.clone().addScaledVector(n, -h), p);
          cone.name = "cone";
          g.add(cone);
        }
      }
      const label = textSprite(`${c.label}${c.state ? ":" + c.state : ""}`, "#1d232a", 26);
      setSpriteSize(label, this.size * 0.028);
      label.position.copy(p).addScaledVector(c.normal ? v3(c.normal).normalize() : new THREE.Vector3(0, 0, 1), -1.6 * h);
      g.add(label);
      this.contactGroup.add(g);
    });
    this.container.dataset.contacts = String(contacts.length);
    this.container.dataset.states = contacts.map((c) => c.state || "-").join("");
  }

  /** World position of every URDF link the scene's fingers name (for the tests' check against
   * /scenes/geometry). */
  linkOrigins() {
    const out = {};
    for (const r of this.robots) {
      r.group.updateMatrixWorld(true);
      for (const fi of r.fingers) {
        const f = this.sceneData.fingers[fi.index];
        for (const [name, link] of Object.entries(r.robot.links)) {
          const body = `${f.name}/${name}`;
          if (this.capsules[body]) out[body] = link.getWorldPosition(new THREE.Vector3()).toArray();
        }
      }
    }
    return out;
  }

  /** Screen box (canvas pixels) of the URDF robots' meshes, or null. */
  robotScreenBox() {
    const box = new THREE.Box3();
    for (const r of this.robots) { r.group.updateMatrixWorld(true); box.expandByObject(r.group); }
    if (box.isEmpty()) return null;
    const w = this.canvas.width, hgt = this.canvas.height;
    let x0 = Infinity, y0 = Infinity, x1 = -Infinity, y1 = -Infinity;
    for (let k = 0; k < 8; k++) {
      const p = new THREE.Vector3(k & 1 ? box.max.x : box.min.x, k & 2 ? box.max.y : box.min.y, k & 4 ? box.max.z : box.min.z).project(this.camera);
      const x = ((p.x + 1) / 2) * w, y = ((1 - p.y) / 2) * hgt;
      x0 = Math.min(x0, x); y0 = Math.min(y0, y); x1 = Math.max(x1, x); y1 = Math.max(y1, y);
    }
    const clamp = (v, m) => Math.max(0, Math.min(m, Math.round(v)));
    return { x0: clamp(x0, w), y0: clamp(y0, hgt), x1: clamp(x1, w), y1: clamp(y1, hgt), width: w, height: hgt };
  }

  setRobotsVisible(on) { for (const r of this.robots) r.group.visible = on; this.renderNow(); }
}
