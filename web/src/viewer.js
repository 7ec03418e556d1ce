// The 3D view: scan point cloud, part meshes, the exported MuJoCo geoms, the
// existing joints/sites, and three tool objects (cut box, joint arrow, site
// sphere) that one TransformControls gizmo can grab. Robot base frame, z up.
import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';
import { TransformControls } from 'three/addons/controls/TransformControls.js';

// Distinct part colours (Tableau 10), chosen by the part's index in the spec.
export const PALETTE = [
  0x4e79a7, 0xf28e2b, 0x59a14f, 0xe15759, 0x76b7b2,
  0xedc948, 0xb07aa1, 0xff9da7, 0x9c755f, 0xbab0ac,
];
export const partColor = (i) => PALETTE[i % PALETTE.length];

const Z = new THREE.Vector3(0, 0, 1);
const X = new THREE.Vector3(1, 0, 0);

export class Viewer {
  // handlers: onPickPart(name), onPickTool(tool), onToolMoved(tool)
  constructor(container, handlers) {
    this.container = container;
    this.handlers = handlers;
    this.parts = new Map(); // name -> THREE.Mesh
    this.selected = null;
    this.mode = 'translate';
    this.activeTool = null;
    this.show = { scan: true, parts: true, collision: true };
    this.exportShown = false;

    // Scene, camera, lights, ground grid and base axes
    this.scene = new THREE.Scene();
    this.scene.background = new THREE.Color(0x1e2228);
    this.camera = new THREE.PerspectiveCamera(45, 1, 0.01, 100);
    this.camera.up.set(0, 0, 1);
    this.camera.position.set(-0.5, -1.0, 0.9);
    const hemi = new THREE.HemisphereLight(0xffffff, 0x404040, 1.6);
    hemi.position.set(0, 0, 1);
    const sun = new THREE.DirectionalLight(0xffffff, 1.4);
    sun.position.set(0.5, -1, 2);
    this.scene.add(hemi, sun);
    const grid = new THREE.GridHelper(2, 20, 0x4a5260, 0x323842);
    grid.rotation.x = Math.PI / 2; // GridHelper lies in XZ; turn it into the XY plane
    grid.position.set(0.5, 0, 0);
    this.scene.add(grid, new THREE.AxesHelper(0.15));

    // Content groups
    this.scanGroup = new THREE.Group();
    this.partsGroup = new THREE.Group();
    this.exportVisual = new THREE.Group();
    this.exportCollision = new THREE.Group();
    this.annotGroup = new THREE.Group();
    this.scene.add(this.scanGroup, this.partsGroup, this.exportVisual,
      this.exportCollision, this.annotGroup);
    this.selBox = new THREE.Box3Helper(new THREE.Box3(), 0xd0d8e8);
    this.selBox.visible = false;
    this.scene.add(this.selBox);

    // Renderer (the page keeps working without WebGL, only nothing is drawn)
    try {
      this.renderer = new THREE.WebGLRenderer({ antialias: true });
      this.renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));
      container.appendChild(this.renderer.domElement);
    } catch (e) {
      this.renderer = null;
      this.glError = `WebGL is not available: ${e.message}`;
      const div = document.createElement('div');
      div.className = 'nogl';
      div.textContent = this.glError;
      container.appendChild(div);
    }
    const dom = this.renderer ? this.renderer.domElement : container;

    // Orbit + gizmo
    this.orbit = new OrbitControls(this.camera, dom);
    this.orbit.target.set(0.6, 0, 0.1);
    this.orbit.addEventListener('change', () => this.requestRender());
    this.tc = new TransformControls(this.camera, dom);
    this.tc.setSize(0.8);
    this.tc.addEventListener('dragging-changed', (e) => { this.orbit.enabled = !e.value; });
    this.tc.addEventListener('change', () => this.requestRender());
    this.tc.addEventListener('objectChange', () => {
      if (this.activeTool) this.handlers.onToolMoved?.(this.activeTool);
    });
    this.scene.add(this.tc.getHelper());

    this.#makeTools();
    this.#bindPicking(dom);
    new ResizeObserver(() => this.resize()).observe(container);
    this.resize();
  }

  // ---- rendering ----------------------------------------------------------
  requestRender() {
    if (!this.renderer || this._pending) return;
    this._pending = true;
    requestAnimationFrame(() => {
      this._pending = false;
      this.renderer.render(this.scene, this.camera);
    });
  }

  resize() {
    const w = this.container.clientWidth || 1;
    const h = this.container.clientHeight || 1;
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    if (this.renderer) this.renderer.setSize(w, h, false);
    this.requestRender();
  }

  // Look at a box from behind-left of the robot.
  fitTo(box) {
    if (!box || box.isEmpty()) return;
    const c = box.getCenter(new THREE.Vector3());
    const r = Math.max(box.getSize(new THREE.Vector3()).length() / 2, 0.1);
    const dist = r / Math.sin(THREE.MathUtils.degToRad(this.camera.fov / 2)) * 0.9;
    const dir = new THREE.Vector3(-0.9, -0.8, 0.8).normalize();
    this.orbit.target.copy(c);
    this.camera.position.copy(c).addScaledVector(dir, dist);
    this.orbit.update();
    this.requestRender();
  }

  // ---- scan ---------------------------------------------------------------
  setScan(scan) {
    this.scanGroup.clear();
    if (!scan || !scan.positions?.length) return;
    const g = new THREE.BufferGeometry();
    g.setAttribute('position', new THREE.Float32BufferAttribute(scan.positions, 3));
    const hasColor = scan.colors?.length === scan.positions.length;
    if (hasColor) g.setAttribute('color', new THREE.Float32BufferAttribute(scan.colors, 3));
    g.computeBoundingBox();
    const m = new THREE.PointsMaterial({ size: 0.004, vertexColors: hasColor, color: hasColor ? 0xffffff : 0x999999 });
    this.scanGroup.add(new THREE.Points(g, m));
    this.requestRender();
  }

  scanBox() {
    const p = this.scanGroup.children[0];
    return p ? p.geometry.boundingBox.clone() : null;
  }

  // ---- parts --------------------------------------------------------------
  setPart(name, data, color) {
    const g = new THREE.BufferGeometry();
    g.setAttribute('position', new THREE.Float32BufferAttribute(data.positions || [], 3));
    if (data.indices?.length) g.setIndex(data.indices);
    g.computeVertexNormals();
    g.computeBoundingBox();
    g.computeBoundingSphere();
    let m = this.parts.get(name);
    if (!m) {
      m = new THREE.Mesh(g, new THREE.MeshStandardMaterial({
        color, side: THREE.DoubleSide, roughness: 0.85, metalness: 0,
      }));
      m.userData.part = name;
      this.parts.set(name, m);
      this.partsGroup.add(m);
    } else {
      m.geometry.dispose();
      m.geometry = g;
      m.material.color.set(color);
    }
    this.#highlight();
  }

  keepParts(names) {
    const keep = new Set(names);
    for (const [name, m] of this.parts) {
      if (keep.has(name)) continue;
      m.geometry.dispose();
      m.material.dispose();
      this.partsGroup.remove(m);
      this.parts.delete(name);
    }
    this.#highlight();
  }

  // World-space bounding box of a part's (cut) mesh; null if it has no triangles.
  partBox(name) {
    const m = this.parts.get(name);
    const b = m?.geometry.boundingBox;
    return b && !b.isEmpty() ? b.clone() : null;
  }

  partsBox() {
    const box = new THREE.Box3();
    for (const name of this.parts.keys()) {
      const b = this.partBox(name);
      if (b) box.union(b);
    }
    return box;
  }

  setSelected(name) {
    this.selected = name;
    this.#highlight();
  }

  #highlight() {
    const sel = this.selected;
    const tint = (m) => m.material.emissive?.set(m.userData.part === sel ? 0x4a4a10 : 0x000000);
    for (const m of this.parts.values()) tint(m);
    for (const m of this.exportVisual.children) tint(m);
    const b = sel ? this.partBox(sel) : null;
    this.selBox.visible = !!b;
    if (b) this.selBox.box.copy(b);
    this.requestRender();
  }

  // ---- visibility ---------------------------------------------------------
  setShow(what, on) {
    this.show[what] = on;
    this.#applyVisibility();
  }

  #applyVisibility() {
    this.scanGroup.visible = this.show.scan;
    // After an export the exported visual meshes stand in for the part meshes.
    this.partsGroup.visible = this.show.parts && !this.exportShown;
    this.exportVisual.visible = this.show.parts && this.exportShown;
    this.exportCollision.visible = this.show.collision && this.exportShown;
    this.requestRender();
  }

  // ---- existing joints and sites (thin markers) ---------------------------
  setAnnotations(spec) {
    for (const o of this.annotGroup.children) o.traverse?.((c) => c.geometry?.dispose());
    this.annotGroup.clear();
    for (const j of spec.joints || []) {
      if (!Array.isArray(j.origin)) continue;
      const o = new THREE.Vector3().fromArray(j.origin);
      const a = new THREE.Vector3().fromArray(j.axis || [0, 0, 1]);
      if (a.lengthSq() < 1e-12) a.copy(Z);
      const color = j.type === 'revolute' ? 0xff77ff : j.type === 'prismatic' ? 0x66ddff : 0xaaaaaa;
      this.annotGroup.add(new THREE.ArrowHelper(a.normalize(), o, 0.12, color, 0.03, 0.015));
    }
    const sg = new THREE.SphereGeometry(0.008, 12, 8);
    const sm = new THREE.MeshBasicMaterial({ color: 0xffcc66 });
    for (const s of spec.sites || []) {
      if (!Array.isArray(s.position)) continue;
      const m = new THREE.Mesh(sg, sm);
      m.position.fromArray(s.position);
      this.annotGroup.add(m);
    }
    this.requestRender();
  }

  // ---- exported MuJoCo scene ----------------------------------------------
  // colorOf(body) gives a part's colour (visual meshes keep the editor's colours).
  showExport(result, colorOf = () => null) {
    this.clearExport(false);
    const meshGeoms = (result.meshes || []).map((mesh) => {
      const g = new THREE.BufferGeometry();
      g.setAttribute('position', new THREE.Float32BufferAttribute(mesh.positions || [], 3));
      if (mesh.indices?.length) g.setIndex(mesh.indices);
      g.computeVertexNormals();
      return g;
    });
    for (const geom of result.geoms || []) {
      const g = geomGeometry(geom, meshGeoms);
      if (!g) continue;
      let obj;
      if (geom.collision) {
        // Collision geoms: faint fill with edges; the robot's in blue-grey, the twin's in white
        const color = geom.robot ? 0x8fb0e0 : 0xf4f4f4;
        obj = new THREE.Mesh(g, new THREE.MeshBasicMaterial({
          color, transparent: true, opacity: 0.06, depthWrite: false, side: THREE.DoubleSide,
        }));
        obj.add(new THREE.LineSegments(new THREE.EdgesGeometry(g, 25),
          new THREE.LineBasicMaterial({ color, transparent: true, opacity: 0.75 })));
        this.exportCollision.add(obj);
      } else {
        const rgba = geom.rgba || [0.7, 0.7, 0.7, 1];
        const color = colorOf(geom.body) ?? (rgba[3] > 0 ? new THREE.Color(rgba[0], rgba[1], rgba[2]) : 0xb0b0b0);
        obj = new THREE.Mesh(g, new THREE.MeshStandardMaterial({
          color, side: THREE.DoubleSide, roughness: 0.85,
          transparent: rgba[3] > 0 && rgba[3] < 1, opacity: rgba[3] > 0 ? rgba[3] : 1,
        }));
        obj.userData.part = geom.body;
        this.exportVisual.add(obj);
      }
      if (Array.isArray(geom.pos)) obj.position.fromArray(geom.pos);
      if (Array.isArray(geom.quat)) {
        const [w, x, y, z] = geom.quat;
        obj.quaternion.set(x, y, z, w);
      }
      if (geom.type === 'ellipsoid') obj.scale.set(...geom.size);
    }
    this.exportShown = true;
    this.#highlight();
    this.#applyVisibility();
  }

  clearExport(apply = true) {
    for (const grp of [this.exportVisual, this.exportCollision]) {
      for (const o of grp.children) o.traverse((c) => c.geometry?.dispose());
      grp.clear();
    }
    this.exportShown = false;
    if (apply) this.#applyVisibility();
  }

  // ---- tools: cut box, joint arrow, site sphere ---------------------------
  #makeTools() {
    // Cut box: unit cube scaled to the box size; rotation order ZYX so that
    // (x, y, z) = (roll, pitch, yaw) means Rz(yaw)·Ry(pitch)·Rx(roll).
    const cube = new THREE.BoxGeometry(1, 1, 1);
    const box = new THREE.Mesh(cube, new THREE.MeshBasicMaterial({
      color: 0xffd400, transparent: true, opacity: 0.22, depthWrite: false, side: THREE.DoubleSide,
    }));
    // its edges show through the part meshes (the box usually sits inside one)
    const edges = new THREE.LineSegments(new THREE.EdgesGeometry(cube),
      new THREE.LineBasicMaterial({ color: 0xffe066, depthTest: false, transparent: true }));
    edges.renderOrder = 10;
    box.add(edges);
    box.rotation.order = 'ZYX';

    // Joint arrow: the group's local +Z is the axis, its position the origin.
    const joint = new THREE.Group();
    joint.add(new THREE.ArrowHelper(Z, new THREE.Vector3(), 0.18, 0x00e5ff, 0.045, 0.022));
    joint.add(new THREE.Mesh(new THREE.SphereGeometry(0.012, 16, 10), new THREE.MeshBasicMaterial({ color: 0x00e5ff })));

    // Site: a sphere and a short arrow along its local +X (yaw direction).
    const site = new THREE.Group();
    site.add(new THREE.Mesh(new THREE.SphereGeometry(0.014, 16, 10), new THREE.MeshBasicMaterial({ color: 0xff40c0 })));
    site.add(new THREE.ArrowHelper(X, new THREE.Vector3(), 0.06, 0xff40c0, 0.02, 0.012));
    site.rotation.order = 'ZYX';

    this.tools = { cut: box, joint, site };
    for (const [name, o] of Object.entries(this.tools)) {
      o.visible = false;
      o.traverse((c) => { c.userData.tool = name; });
      this.scene.add(o);
    }
  }

  showTool(name, on) {
    this.tools[name].visible = on;
    if (!on && this.activeTool === name) this.detachTool();
    this.requestRender();
  }

  toolVisible(name) {
    return this.tools[name].visible;
  }

  attachTool(name) {
    this.tools[name].visible = true;
    this.activeTool = name;
    this.tc.attach(this.tools[name]);
    this.#applyMode();
  }

  detachTool() {
    this.tc.detach();
    this.activeTool = null;
    this.requestRender();
  }

  setMode(mode) {
    this.mode = mode;
    this.#applyMode();
  }

  // Each tool allows a subset: the box all three, the joint move/rotate, the
  // site move and a yaw-only rotate.
  #applyMode() {
    const t = this.activeTool;
    let mode = this.mode;
    if (t !== 'cut' && mode === 'scale') mode = 'translate';
    this.tc.setMode(mode);
    this.tc.space = t === 'cut' && mode !== 'translate' ? 'local' : 'world';
    const yawOnly = t === 'site' && mode === 'rotate';
    this.tc.showX = !yawOnly;
    this.tc.showY = !yawOnly;
    this.tc.showZ = true;
    this.requestRender();
  }

  setCutBox({ center, size, euler }) {
    const b = this.tools.cut;
    b.position.fromArray(center);
    b.scale.set(...size.map((s) => Math.max(Math.abs(s), 1e-4)));
    b.rotation.set(euler[0], euler[1], euler[2], 'ZYX');
    this.requestRender();
  }

  getCutBox() {
    const b = this.tools.cut;
    const e = new THREE.Euler().setFromQuaternion(b.quaternion, 'ZYX');
    return {
      center: b.position.toArray(),
      size: b.scale.toArray().map(Math.abs),
      euler: [e.x, e.y, e.z],
    };
  }

  setJointTool({ origin, axis }) {
    const j = this.tools.joint;
    j.position.fromArray(origin);
    const a = new THREE.Vector3().fromArray(axis);
    if (a.lengthSq() > 1e-12) j.quaternion.setFromUnitVectors(Z, a.normalize());
    this.requestRender();
  }

  getJointTool() {
    const j = this.tools.joint;
    return { origin: j.position.toArray(), axis: Z.clone().applyQuaternion(j.quaternion).toArray() };
  }

  setSiteTool({ position, yaw }) {
    const s = this.tools.site;
    s.position.fromArray(position);
    s.rotation.set(0, 0, yaw, 'ZYX');
    this.requestRender();
  }

  getSiteTool() {
    const s = this.tools.site;
    const e = new THREE.Euler().setFromQuaternion(s.quaternion, 'ZYX');
    return { position: s.position.toArray(), yaw: e.z };
  }

  // ---- picking: a click (not a drag) picks a tool object or a part ---------
  #bindPicking(dom) {
    this.dom = dom;
    this.ray = new THREE.Raycaster();
    let down = null;
    dom.addEventListener('pointerdown', (e) => {
      // A press on the gizmo's handles is a drag, not a pick.
      down = this.tc.axis !== null || this.tc.dragging ? null : { x: e.clientX, y: e.clientY };
    });
    dom.addEventListener('pointerup', (e) => {
      if (!down || e.button !== 0) return;
      const moved = Math.hypot(e.clientX - down.x, e.clientY - down.y);
      down = null;
      if (moved > 5) return;
      const r = dom.getBoundingClientRect();
      const hit = this.#pickAt(new THREE.Vector2(
        ((e.clientX - r.left) / r.width) * 2 - 1, -((e.clientY - r.top) / r.height) * 2 + 1));
      if (!hit) return;
      if (hit.object.userData.tool) this.handlers.onPickTool?.(hit.object.userData.tool);
      else if (hit.object.userData.part) this.handlers.onPickPart?.(hit.object.userData.part);
    });
  }

  // Nearest visible tool or part mesh under a point in normalized device coordinates.
  #pickAt(ndc) {
    this.ray.setFromCamera(ndc, this.camera);
    const targets = [];
    for (const t of Object.values(this.tools)) if (t.visible) targets.push(t);
    if (this.partsGroup.visible) targets.push(this.partsGroup);
    if (this.exportVisual.visible) targets.push(this.exportVisual);
    return this.ray.intersectObjects(targets, true).find((h) => h.object.isMesh && isShown(h.object)) || null;
  }

  // A page point where a click picks the part `name` (for tests); null if none.
  screenPointOf(name) {
    const m = this.parts.get(name);
    if (!m || !this.renderer || !isShown(m)) return null;
    const pos = m.geometry.attributes.position;
    const idx = m.geometry.index;
    const ntri = Math.floor((idx ? idx.count : pos.count) / 3);
    const step = Math.max(1, Math.floor(ntri / 400));
    const r = this.dom.getBoundingClientRect();
    const v = new THREE.Vector3();
    for (let t = 0; t < ntri; t += step) {
      const c = new THREE.Vector3();
      for (let k = 0; k < 3; k++) c.add(v.fromBufferAttribute(pos, idx ? idx.getX(3 * t + k) : 3 * t + k));
      const p = c.divideScalar(3).project(this.camera);
      if (Math.abs(p.x) > 0.9 || Math.abs(p.y) > 0.9 || p.z > 1) continue;
      const hit = this.#pickAt(new THREE.Vector2(p.x, p.y));
      if (hit?.object === m) {
        return { x: r.left + ((p.x + 1) / 2) * r.width, y: r.top + ((1 - p.y) / 2) * r.height };
      }
    }
    return null;
  }
}

// Is an object and all its ancestors visible?
function isShown(o) {
  for (; o; o = o.parent) if (!o.visible) return false;
  return true;
}

// three.js geometry for one exported MuJoCo geom, in the geom's own frame.
function geomGeometry(geom, meshGeoms) {
  const s = geom.size || [0, 0, 0];
  let g;
  switch (geom.type) {
    case 'box': return new THREE.BoxGeometry(2 * s[0], 2 * s[1], 2 * s[2]);
    case 'sphere': return new THREE.SphereGeometry(s[0], 20, 14);
    case 'ellipsoid': return new THREE.SphereGeometry(1, 20, 14); // scaled by size
    case 'plane': return new THREE.PlaneGeometry(2 * (s[0] || 1.5), 2 * (s[1] || 1.5));
    case 'capsule':
      g = new THREE.CapsuleGeometry(s[0], 2 * s[1], 6, 16);
      return g.rotateX(Math.PI / 2); // three's capsule runs along y, MuJoCo's along z
    case 'cylinder':
      g = new THREE.CylinderGeometry(s[0], s[0], 2 * s[1], 20);
      return g.rotateX(Math.PI / 2);
    case 'mesh': return geom.mesh >= 0 && meshGeoms[geom.mesh] ? meshGeoms[geom.mesh] : null;
    default: return null;
  }
}
