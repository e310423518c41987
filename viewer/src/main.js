// The browser side of `isotope serve` (docs/SERVE.md): sliders drive /api/extract, the binary
// answer goes straight into GPU buffers without copying.
import * as THREE from 'three';
import { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';

const $ = (id) => document.getElementById(id);
const ui = {
  store: $('store'), histogram: $('histogram'),
  iso: $('iso'), isoValue: $('iso-value'), isoMin: $('iso-min'), isoMax: $('iso-max'),
  eps: $('eps'), epsValue: $('eps-value'),
  topology: $('topology'), delta: $('delta'),
  full: $('full'), fullInfo: $('full-info'),
  focusInfo: $('focus-info'), clearFocus: $('clear-focus'),
  triangles: $('triangles'), vertices: $('vertices'), components: $('components'),
  euler: $('euler'), time: $('time'), latency: $('latency'),
  download: $('download'), status: $('status'), view: $('view'),
};

const EPS_STEPS = 1000;

// What the end-to-end test reads; `params` are the query values of the drawn mesh, exactly as sent.
const viewer = {
  client: Math.random().toString(36).slice(2, 12) + Date.now().toString(36),
  seq: 0, drawnSeq: -1, state: 'loading', error: null,
  lastLatencyMs: null, latencies: [],
  triangles: 0, vertices: 0, components: null, euler: null,
  params: null, requestParams: null, report: null,
  full: { state: 'off', seq: -1, triangles: 0, params: null },
  focus: null, info: null,
};
window.isotopeViewer = viewer;

// ---------------------------------------------------------------- scene

const renderer = new THREE.WebGLRenderer({ antialias: true, alpha: true });
renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));
ui.view.appendChild(renderer.domElement);

const scene = new THREE.Scene();
const camera = new THREE.PerspectiveCamera(35, 1, 0.01, 100);
camera.up.set(0, 0, 1); // volumes are stacks of z slices: z up reads naturally
scene.add(camera);
scene.add(new THREE.AmbientLight(0xffffff, 0.55));
// The key light rides on the camera so the side being looked at is always lit.
const keyLight = new THREE.DirectionalLight(0xffffff, 2.2);
keyLight.position.set(0.5, 0.8, 0.6);
camera.add(keyLight, keyLight.target);
keyLight.target.position.set(0, 0, -1);

const controls = new OrbitControls(camera, renderer.domElement);
controls.enableDamping = true;
controls.dampingFactor = 0.15;

// One draw call for both sides: the back (inside) faces get a cool tint via the shader instead of
// a second mesh, which would double the vertex work on big surfaces.
const surfaceMaterial = new THREE.MeshStandardMaterial({
  color: 0xe3b27a, roughness: 0.55, metalness: 0.05, side: THREE.DoubleSide,
});
surfaceMaterial.onBeforeCompile = (shader) => {
  shader.fragmentShader = shader.fragmentShader.replace('#include <color_fragment>',
    '#include <color_fragment>\n if (!gl_FrontFacing) diffuseColor.rgb = vec3(0.36, 0.52, 0.78);');
};
const overlayMaterial = new THREE.MeshStandardMaterial({
  color: 0x4fd1e8, roughness: 0.6, transparent: true, opacity: 0.28, depthWrite: false,
  side: THREE.DoubleSide, polygonOffset: true, polygonOffsetFactor: -1, polygonOffsetUnits: -1,
});
const surface = new THREE.Mesh(new THREE.BufferGeometry(), surfaceMaterial);
const overlay = new THREE.Mesh(new THREE.BufferGeometry(), overlayMaterial);
overlay.renderOrder = 1;
overlay.visible = false;
const marker = new THREE.Mesh(new THREE.SphereGeometry(1, 20, 14),
  new THREE.MeshBasicMaterial({ color: 0xff4d6d }));
marker.visible = false;
const boxLines = new THREE.LineSegments(new THREE.EdgesGeometry(new THREE.BoxGeometry(1, 1, 1)),
  new THREE.LineBasicMaterial({ color: 0x4a5568 }));
scene.add(surface, overlay, marker, boxLines);

const bounds = { box: new THREE.Box3(), sphere: new THREE.Sphere(), diagonal: 1 };

let needsRender = true;
const requestRender = () => { needsRender = true; };
controls.addEventListener('change', requestRender);

function render() {
  renderer.render(scene, camera);
  needsRender = false;
}

function loop() {
  requestAnimationFrame(loop);
  controls.update(); // fires 'change' while damping settles
  if (needsRender) render();
}

function resize() {
  const { clientWidth: w, clientHeight: h } = ui.view;
  if (w === 0 || h === 0) return;
  renderer.setSize(w, h, false);
  camera.aspect = w / h;
  camera.updateProjectionMatrix();
  render();
}
new ResizeObserver(resize).observe(ui.view);

function fitCamera(info) {
  const min = new THREE.Vector3(...info.origin);
  const extent = new THREE.Vector3(...info.spacing).multiply(new THREE.Vector3(...info.dims).subScalar(1));
  bounds.box.set(min, min.clone().add(extent));
  bounds.box.getBoundingSphere(bounds.sphere);
  bounds.diagonal = extent.length() || 1;
  const r = bounds.sphere.radius || 1;
  const dist = r / Math.sin(THREE.MathUtils.degToRad(camera.fov / 2)) * 1.05;
  camera.near = dist / 100;
  camera.far = dist * 10;
  camera.position.copy(bounds.sphere.center).addScaledVector(new THREE.Vector3(0.9, -1.5, 0.8).normalize(), dist);
  camera.updateProjectionMatrix();
  controls.target.copy(bounds.sphere.center);
  controls.update();
  bounds.box.getCenter(boxLines.position);
  boxLines.scale.copy(extent).max(new THREE.Vector3(1e-9, 1e-9, 1e-9));
  marker.scale.setScalar(bounds.diagonal / 160);
}

// Shares the server's arrays: no copy, and the bounds come from the box rather than a pass over
// every vertex.
function setGeometry(mesh, m) {
  const g = new THREE.BufferGeometry();
  g.setAttribute('position', new THREE.BufferAttribute(m.positions, 3));
  g.setAttribute('normal', new THREE.BufferAttribute(m.normals, 3));
  g.setIndex(new THREE.BufferAttribute(m.indices, 1));
  g.boundingBox = bounds.box.clone();
  g.boundingSphere = bounds.sphere.clone();
  mesh.geometry.dispose();
  mesh.geometry = g;
}

// ---------------------------------------------------------------- protocol

function decodeMesh(buffer) {
  const view = new DataView(buffer);
  if (buffer.byteLength < 20 || new TextDecoder().decode(new Uint8Array(buffer, 0, 4)) !== 'ISOM') {
    throw new Error('bad answer from server (no ISOM header)');
  }
  const version = view.getUint32(4, true);
  if (version !== 1) throw new Error(`unsupported mesh version ${version}`);
  const [J, V, T] = [8, 12, 16].map((at) => view.getUint32(at, true));
  const base = 20 + Math.ceil(J / 4) * 4;
  if (buffer.byteLength < base + 24 * V + 12 * T) throw new Error('truncated mesh from server');
  return {
    report: JSON.parse(new TextDecoder().decode(new Uint8Array(buffer, 20, J))),
    positions: new Float32Array(buffer, base, 3 * V),
    normals: new Float32Array(buffer, base + 12 * V, 3 * V),
    indices: new Uint32Array(buffer, base + 24 * V, 3 * T),
    vertexCount: V, triangleCount: T,
  };
}

// Keeps the numbers' text as sent so the commas of `focus` and signs survive unescaped.
const encode = (v) => String(v).replace(/[^A-Za-z0-9._,-]/g, (c) => encodeURIComponent(c));

let nextSeq = 1;

// One request kind (the mesh, or the full-resolution overlay). The server supersedes per client,
// so each kind has its own client id: the overlay must not cancel the mesh or vice versa.
class Channel {
  constructor(client) {
    this.client = client;
    this.controller = null;
    this.latest = -1;
  }

  get pending() { return this.controller !== null; }

  cancel() {
    this.controller?.abort();
    this.controller = null;
    this.latest = -1;
  }

  // Resolves to {seq, mesh, ms}, or null when a newer request made this one moot.
  async fetch(params) {
    this.controller?.abort();
    const controller = this.controller = new AbortController();
    const seq = this.latest = nextSeq++;
    const query = Object.entries({ ...params, client: this.client, seq })
      .map(([k, v]) => `${k}=${encode(v)}`).join('&');
    const start = performance.now();
    const isLatest = () => this.latest === seq;
    try {
      const res = await fetch(`/api/extract?${query}`, { signal: controller.signal });
      if (res.status === 409 || !isLatest()) return null;
      if (!res.ok) throw new Error((await res.text()).trim() || `HTTP ${res.status}`);
      const buffer = await res.arrayBuffer();
      if (!isLatest()) return null;
      return { seq, mesh: decodeMesh(buffer), ms: performance.now() - start };
    } catch (err) {
      if (err.name === 'AbortError' || !isLatest()) return null;
      throw err;
    } finally {
      if (isLatest()) this.controller = null;
    }
  }
}

const main = new Channel(viewer.client);
const full = new Channel(`${viewer.client}-full`);

// ---------------------------------------------------------------- state and readouts

let drawing = false;

function updateStatus(text) {
  const state = viewer.error ? 'error' : (main.pending || full.pending || drawing) ? 'loading' : 'ready';
  viewer.state = state;
  ui.status.dataset.state = state;
  ui.status.dataset.seq = String(viewer.drawnSeq);
  ui.status.classList.toggle('error', state === 'error');
  ui.status.textContent = state === 'error' ? viewer.error
    : text ?? (state === 'loading' ? 'Extracting\u2026' : `Ready \u00b7 ${viewer.triangles} triangles`);
}

function showError(err) {
  viewer.error = err.message || String(err);
  drawing = false;
  updateStatus();
}

const ms = (seconds) => `${Math.round(seconds * 1000)}`;

function showReport(report, vertexCount, triangleCount, roundTripMs) {
  Object.assign(viewer, {
    report, triangles: triangleCount, vertices: vertexCount,
    components: report.components ?? null, euler: report.euler_characteristic ?? null,
  });
  ui.triangles.textContent = String(triangleCount);
  ui.vertices.textContent = String(vertexCount);
  ui.components.textContent = String(report.components ?? '\u2013');
  ui.euler.textContent = String(report.euler_characteristic ?? '\u2013');
  ui.time.textContent = `${ms(report.extract_seconds ?? 0)} / ${Math.round(roundTripMs)} ms`;
  ui.download.disabled = triangleCount === 0;
}

// ---------------------------------------------------------------- parameters

let info = null;
let iso = '0';
let eps = '0';
let isoDecimals = 3;

const epsFromPosition = (pos, span) => span * 10 ** (-5 + (5 * pos) / EPS_STEPS);
const positionFromEps = (e, span) => Math.round(((Math.log10(e / span) + 5) / 5) * EPS_STEPS);

// Rounded to what the slider can resolve so the URL, the readout and a CLI rerun agree.
const formatIso = (v) => String(Number(v.toFixed(isoDecimals)));
const formatEps = (v) => String(Number(v.toPrecision(3)));

function meshParams() {
  const p = { iso, eps, topology: ui.topology.value };
  if (p.topology === 'simplify') {
    const d = ui.delta.value.trim() === '' ? 0 : Number(ui.delta.value);
    if (!Number.isFinite(d) || d < 0) return null;
    p.delta = String(d);
  }
  if (viewer.focus) {
    p.focus = viewer.focus.map((c) => String(Number(c.toPrecision(7)))).join(',');
    p.radius = String(Number((bounds.diagonal / 8).toPrecision(7)));
  }
  return p;
}

async function requestMesh(t0 = performance.now()) {
  const params = meshParams();
  if (!params) return;
  viewer.error = null;
  viewer.requestParams = params;
  const pending = main.fetch(params);
  viewer.seq = main.latest;
  updateStatus();
  let answer;
  try {
    answer = await pending;
  } catch (err) {
    showError(err);
    return;
  }
  if (!answer) return updateStatus();
  const { seq, mesh, ms: roundTrip } = answer;
  drawing = true;
  setGeometry(surface, mesh);
  showReport(mesh.report, mesh.vertexCount, mesh.triangleCount, roundTrip);
  Object.assign(viewer, { params, drawnSeq: seq, mesh });
  render();
  // The frame after the one that drew the mesh: by then it is on screen.
  requestAnimationFrame(() => {
    if (viewer.drawnSeq !== seq) return;
    const latency = performance.now() - t0;
    viewer.lastLatencyMs = latency;
    viewer.latencies.push(latency);
    ui.latency.textContent = `${Math.round(latency)} ms`;
    drawing = false;
    updateStatus();
  });
}

async function requestOverlay() {
  if (!ui.full.checked) return;
  const params = { iso, eps: '0', topology: 'none' };
  viewer.full.state = 'loading';
  ui.fullInfo.textContent = '\u2026';
  const pending = full.fetch(params);
  updateStatus();
  let answer;
  try {
    answer = await pending;
  } catch (err) {
    viewer.full.state = 'error';
    showError(err);
    return;
  }
  if (!answer || !ui.full.checked) return updateStatus();
  setGeometry(overlay, answer.mesh);
  overlay.visible = true;
  Object.assign(viewer.full, { state: 'ready', seq: answer.seq, triangles: answer.mesh.triangleCount, params });
  ui.fullInfo.textContent = `(${answer.mesh.triangleCount} tri)`;
  render();
  updateStatus();
}

// ---------------------------------------------------------------- histogram

function drawHistogram() {
  const canvas = ui.histogram;
  const dpr = window.devicePixelRatio || 1;
  const w = Math.round(canvas.clientWidth * dpr), h = Math.round(canvas.clientHeight * dpr);
  if (canvas.width !== w || canvas.height !== h) Object.assign(canvas, { width: w, height: h });
  const ctx = canvas.getContext('2d');
  ctx.clearRect(0, 0, w, h);
  const counts = info?.histogram?.counts;
  if (!counts?.length) return;
  // Log heights: a few dominant bins (air, background) would otherwise flatten everything else.
  const top = Math.log1p(Math.max(...counts)) || 1;
  const bw = w / counts.length;
  ctx.fillStyle = '#5b6b85';
  counts.forEach((c, i) => {
    const bh = (Math.log1p(c) / top) * (h - 2);
    ctx.fillRect(i * bw, h - bh, Math.max(1, bw - 0.5 * dpr), bh);
  });
  const [lo, hi] = info.value_range;
  const x = hi > lo ? ((Number(iso) - lo) / (hi - lo)) * w : 0;
  ctx.fillStyle = '#f2a541';
  ctx.fillRect(Math.round(x - dpr), 0, 2 * dpr, h);
}

// ---------------------------------------------------------------- input

function onIsoInput(t0) {
  iso = formatIso(ui.iso.valueAsNumber);
  ui.isoValue.textContent = iso;
  drawHistogram();
  requestMesh(t0);
  requestOverlay();
}

ui.iso.addEventListener('input', () => onIsoInput(performance.now()));

ui.histogram.addEventListener('pointerdown', (e) => {
  if (!info) return;
  const t0 = performance.now();
  const r = ui.histogram.getBoundingClientRect();
  const [lo, hi] = info.value_range;
  ui.iso.value = String(lo + ((e.clientX - r.left) / r.width) * (hi - lo));
  onIsoInput(t0);
});

ui.eps.addEventListener('input', () => {
  const t0 = performance.now();
  eps = formatEps(epsFromPosition(ui.eps.valueAsNumber, span()));
  ui.epsValue.textContent = eps;
  requestMesh(t0);
});

ui.topology.addEventListener('change', () => {
  ui.delta.disabled = ui.topology.value !== 'simplify';
  requestMesh();
});
ui.delta.addEventListener('input', () => requestMesh());

ui.full.addEventListener('change', () => {
  if (ui.full.checked) {
    requestOverlay();
  } else {
    full.cancel();
    overlay.visible = false;
    setGeometry(overlay, { positions: new Float32Array(0), normals: new Float32Array(0), indices: new Uint32Array(0) });
    Object.assign(viewer.full, { state: 'off', triangles: 0 });
    ui.fullInfo.textContent = '';
    render();
    updateStatus();
  }
});

// A click picks a focus; a drag (orbiting) must not.
const pointer = { x: 0, y: 0, t: 0 };
renderer.domElement.addEventListener('pointerdown', (e) => Object.assign(pointer, { x: e.clientX, y: e.clientY, t: e.timeStamp }));
renderer.domElement.addEventListener('pointerup', (e) => {
  if (e.button !== 0 || Math.hypot(e.clientX - pointer.x, e.clientY - pointer.y) > 4 || e.timeStamp - pointer.t > 600) return;
  const t0 = performance.now();
  const r = renderer.domElement.getBoundingClientRect();
  const ndc = new THREE.Vector2(((e.clientX - r.left) / r.width) * 2 - 1, -((e.clientY - r.top) / r.height) * 2 + 1);
  const raycaster = new THREE.Raycaster();
  raycaster.setFromCamera(ndc, camera);
  const hit = raycaster.intersectObject(surface, false)[0];
  if (!hit) return;
  setFocus(hit.point.toArray());
  requestMesh(t0);
});

function setFocus(point) {
  viewer.focus = point;
  marker.visible = !!point;
  if (point) marker.position.fromArray(point);
  ui.clearFocus.disabled = !point;
  ui.focusInfo.textContent = point
    ? `Focus ${point.map((c) => c.toPrecision(4)).join(', ')}`
    : 'Click the surface to refine around a point';
  render();
}

ui.clearFocus.addEventListener('click', () => {
  const t0 = performance.now();
  setFocus(null);
  requestMesh(t0);
});

// ---------------------------------------------------------------- PLY download

function plyBlob(m, comment) {
  const V = m.vertexCount, T = m.triangleCount;
  const header = `ply\nformat binary_little_endian 1.0\ncomment ${comment}\n` +
    `element vertex ${V}\nproperty float x\nproperty float y\nproperty float z\n` +
    `element face ${T}\nproperty list uchar uint vertex_indices\nend_header\n`;
  const faces = new DataView(new ArrayBuffer(13 * T));
  for (let t = 0, at = 0; t < T; t++) {
    faces.setUint8(at, 3);
    faces.setUint32(at + 1, m.indices[3 * t], true);
    faces.setUint32(at + 5, m.indices[3 * t + 1], true);
    faces.setUint32(at + 9, m.indices[3 * t + 2], true);
    at += 13;
  }
  // Float32Array is little-endian on every platform a browser runs on that matters here; copy
  // to be independent of the server buffer's offset.
  return new Blob([header, new Float32Array(m.positions), faces], { type: 'application/octet-stream' });
}

ui.download.addEventListener('click', () => {
  const m = viewer.mesh, p = viewer.params;
  if (!m || !p) return;
  const comment = `isotope ${Object.entries(p).map(([k, v]) => `${k}=${v}`).join(' ')}`;
  const a = document.createElement('a');
  a.href = URL.createObjectURL(plyBlob(m, comment));
  a.download = `isotope_iso${p.iso}_eps${p.eps}.ply`;
  document.body.appendChild(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(a.href), 10000);
});

// ---------------------------------------------------------------- start

const span = () => (info ? info.value_range[1] - info.value_range[0] : 1) || 1;

async function start() {
  const t0 = performance.now();
  updateStatus('Loading store\u2026');
  const res = await fetch('/api/info');
  if (!res.ok) throw new Error((await res.text()).trim() || `HTTP ${res.status}`);
  info = viewer.info = await res.json();

  const [lo, hi] = info.value_range;
  const step = (hi - lo) / 1000;
  isoDecimals = step > 0 ? Math.min(12, Math.max(0, Math.ceil(-Math.log10(step)) + 1)) : 6;
  Object.assign(ui.iso, { min: String(lo), max: String(hi), step: step > 0 ? String(step) : 'any' });
  ui.iso.value = String(info.iso);
  iso = String(info.iso);
  ui.isoValue.textContent = iso;
  ui.isoMin.textContent = String(Number(lo.toPrecision(4)));
  ui.isoMax.textContent = String(Number(hi.toPrecision(4)));

  eps = String(info.eps);
  ui.eps.value = String(info.eps > 0 ? Math.min(EPS_STEPS, Math.max(0, positionFromEps(info.eps, span()))) : 0);
  ui.epsValue.textContent = eps;

  ui.store.textContent = `${info.store} \u00b7 ${info.dims.join('\u00d7')}`;
  fitCamera(info);
  resize();
  drawHistogram();
  new ResizeObserver(drawHistogram).observe(ui.histogram);
  loop();
  await requestMesh(t0);
}

start().catch(showError);
