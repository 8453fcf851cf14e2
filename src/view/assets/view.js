// The operator's live view: the network and surface of /network.glb, the curve being scanned
// (preview), the status bar and the warnings, kept current by the server's events (/events).
// Read-only. `window.sfsView` exposes what is drawn, for tests.
import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';
import { GLTFLoader } from 'three/addons/loaders/GLTFLoader.js';

const CURVE_KINDS = ['boundary', 'interior', 'crease', 'guide'];
const COLOURS = { boundary: 0xff9800, interior: 0x4fc3f7, crease: 0x66bb6a, guide: 0x90a4ae, latest: 0xffee58, preview: 0xe040fb, node: 0xffffff, mark: '#ff1744', joined: '#00e676', proposed: '#ffd740' };

const state = {
  ready: false, errors: [], updates: 0, curves: [], nodes: [], surfaceTriangles: 0,
  lastCurve: null, warnings: 0, events: { status: 0, curve: 0, curves: 0, network: 0, warning: 0, preview: 0 },
  status: null, previewPoints: 0, closure: [], marked: [],
  // A monitoring session: the shape drawn (monitor) and the side panel (monitorStatus).
  monitor: null, monitorStatus: null,
  // The latest network's joins (issue 34): joined nodes and proposed crossings, as drawn.
  joins: { joined: [], proposed: [], refused: [] }, joinMarks: 0,
  // Per curve brought in by a `network` event: from its E packet to the new network drawn
  // here, ms (the server's wall clock and this page's are the same machine's), and the part
  // of it from the event's arrival (`page_ms`: fetch, parse, draw).
  latencies: [], frames: 0,
  // Per curve brought in by a `curves` event (the network before its surface, issue 35): from
  // its E packet to those curves drawn here, ms, and the part from the event's arrival.
  curveLatencies: [], curvesShown: 0,
  // Curves coloured by their points' uncertainty (issue 49): the legend's top, mm (0: off).
  sigmaScaleMm: 0, sigmaCurves: 0,
  // The latest reconstruction's verdict and suspects (issue 49).
  verdict: null, suspects: [],
};
window.sfsView = state;
function pageError(text) {
  state.errors.push(text);
  const el = document.getElementById('page-errors');
  if (el) { const li = document.createElement('li'); li.textContent = text; el.append(li); el.hidden = false; }
}
window.addEventListener('error', (e) => pageError(String(e.message)));
window.addEventListener('unhandledrejection', (e) => pageError(String(e.reason)));
const consoleError = console.error.bind(console);
console.error = (...args) => { pageError(args.map(String).join(' ')); consoleError(...args); };

const canvas = document.getElementById('scene');
const renderer = new THREE.WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
renderer.setPixelRatio(window.devicePixelRatio);
const scene = new THREE.Scene();
scene.background = new THREE.Color(0x1d2126);
const camera = new THREE.PerspectiveCamera(45, 1, 0.001, 1000);
camera.position.set(1, 1, 1);
const controls = new OrbitControls(camera, canvas);
scene.add(new THREE.HemisphereLight(0xffffff, 0x404040, 1.6));
const sun = new THREE.DirectionalLight(0xffffff, 1.4);
sun.position.set(2, 4, 3);
scene.add(sun);

// The device: its direction of travel (red) and outward normal (green), at the end of the
// curve being scanned (at the middle of the scene between curves).
const glyph = new THREE.Group();
const glyphT = new THREE.ArrowHelper(new THREE.Vector3(1, 0, 0), new THREE.Vector3(), 1, 0xff5252, 0.3, 0.2);
const glyphN = new THREE.ArrowHelper(new THREE.Vector3(0, 1, 0), new THREE.Vector3(), 0.6, 0x69f0ae, 0.3, 0.2);
glyph.add(glyphT, glyphN);
glyph.visible = false;
scene.add(glyph);
let sceneSize = 0.5;

const network = new THREE.Group();
const labels = new THREE.Group();
const marks = new THREE.Group();
let surface = null;
let preview = null;
let framed = false;
const structure = new THREE.Group();
scene.add(network, labels, marks, structure);
// A monitoring session (the status carries `monitor`): the page shows the structure.
let monitorMode = false;

function resize() {
  const w = canvas.clientWidth, h = canvas.clientHeight;
  if (canvas.width !== w || canvas.height !== h) {
    renderer.setSize(w, h, false);
    camera.aspect = w / Math.max(h, 1);
    camera.updateProjectionMatrix();
  }
}

// Label textures by text, made once (a network is redrawn at every update).
const labelTextures = new Map();
function label(text, at, size) {
  if (!labelTextures.has(text)) {
    const c = document.createElement('canvas');
    c.width = 128; c.height = 64;
    const g = c.getContext('2d');
    g.font = 'bold 40px sans-serif';
    g.fillStyle = '#ffffff';
    g.textAlign = 'center';
    g.fillText(text, 64, 44);
    labelTextures.set(text, new THREE.CanvasTexture(c));
  }
  const sprite = new THREE.Sprite(new THREE.SpriteMaterial({ map: labelTextures.get(text), depthTest: false }));
  sprite.renderOrder = 10;
  sprite.position.copy(at);
  sprite.scale.set(size, size / 2, 1);
  return sprite;
}

// A ring around a node whose tag the network's loops refuse (rescan or check it).
const ringTexture = (() => {
  const c = document.createElement('canvas');
  c.width = c.height = 64;
  const g = c.getContext('2d');
  g.strokeStyle = COLOURS.mark;
  g.lineWidth = 7;
  g.beginPath(); g.arc(32, 32, 26, 0, 2 * Math.PI); g.stroke();
  return new THREE.CanvasTexture(c);
})();

// A joined node's square and a proposed crossing's dashed ring.
function markTexture(colour, dashed) {
  const c = document.createElement('canvas');
  c.width = c.height = 64;
  const g = c.getContext('2d');
  g.strokeStyle = colour;
  g.lineWidth = 7;
  if (dashed) {
    g.setLineDash([10, 8]);
    g.beginPath(); g.arc(32, 32, 26, 0, 2 * Math.PI); g.stroke();
  } else {
    g.strokeRect(8, 8, 48, 48);
  }
  return new THREE.CanvasTexture(c);
}
const joinedTexture = markTexture(COLOURS.joined, false);
const proposedTexture = markTexture(COLOURS.proposed, true);

// The joins of the latest network: listed, and marked where they are.
function showJoins(joins) {
  const key = JSON.stringify(joins);
  if (key === state.joinsKey) return;
  state.joinsKey = key;
  state.joins = joins;
  const items = [
    ...joins.joined.map((j) => ['joined', `node ${j.node} joined to curve ${j.curve} (${j.distance_mm.toFixed(1)} mm)${j.untagged ? ', untagged crossing' : ''}`]),
    ...joins.proposed.map((p) => ['proposed', `curves ${p.curves[0]} and ${p.curves[1]} cross untagged (${p.distance_mm.toFixed(1)} mm): tag it, set join_untagged, or refuse = [[${p.curves[0]}, ${p.curves[1]}]]`]),
    ...joins.refused.map((r) => ['bad', `node ${r.node} not joined to curve ${r.curve}: ${r.reason}`]),
  ];
  document.getElementById('joins').replaceChildren(...(items.length ? items : [['', 'none']]).map(([cls, t]) => {
    const li = document.createElement('li');
    li.textContent = t;
    if (cls) li.classList.add(cls);
    return li;
  }));
  drawMarks();
}

// The closure misfit per curve (worst first) and the marked tags, ringed at their nodes.
function showClosure(closure) {
  const key = JSON.stringify(closure);
  if (key === state.closureKey) return;
  state.closureKey = key;
  state.closure = closure;
  const list = document.getElementById('closure');
  const worst = [...closure].sort((a, b) => b.misfit_mm - a.misfit_mm);
  list.replaceChildren(...(worst.length ? worst : [null]).map((c) => {
    const li = document.createElement('li');
    if (!c) { li.textContent = 'no loop yet'; return li; }
    const tags = c.marked.map((t) => `node ${t.node} (tag ${t.tag + 1}, ${t.offset_mm.toFixed(0)} mm${t.detached ? ', let go' : ''})`);
    li.textContent = `curve ${c.curve}: ${c.misfit_mm.toFixed(1)} mm` + (tags.length ? ' · worst: ' + tags.join(', ') : '');
    li.classList.toggle('bad', tags.length > 0);
    return li;
  }));
  drawMarks();
}

function drawMarks() {
  clear(marks);
  state.marked = [];
  const at = state.nodePositions || {};
  for (const c of state.closure) {
    for (const t of c.marked) {
      state.marked.push({ curve: c.curve, node: t.node, tag: t.tag });
      const p = at[t.node];
      if (!p) continue;
      const ring = new THREE.Sprite(new THREE.SpriteMaterial({ map: ringTexture, depthTest: false }));
      ring.renderOrder = 11;
      ring.position.set(p[0], p[1], p[2]);
      ring.scale.setScalar(sceneSize * 0.05);
      marks.add(ring);
    }
  }
  const sprite = (texture, p) => {
    const m = new THREE.Sprite(new THREE.SpriteMaterial({ map: texture, depthTest: false }));
    m.renderOrder = 11;
    m.position.set(p[0], p[1], p[2]);
    m.scale.setScalar(sceneSize * 0.04);
    marks.add(m);
  };
  state.joinMarks = 0;
  for (const j of state.joins.joined) {
    if (at[j.node]) { sprite(joinedTexture, at[j.node]); state.joinMarks++; }
  }
  for (const p of state.joins.proposed) { sprite(proposedTexture, p.point); state.joinMarks++; }
  redraw();
}

// Materials shared by every update (never disposed); textures are cached (labels, rings).
const MATERIALS = {
  boundary: new THREE.LineBasicMaterial({ color: COLOURS.boundary }),
  interior: new THREE.LineBasicMaterial({ color: COLOURS.interior }),
  crease: new THREE.LineBasicMaterial({ color: COLOURS.crease }),
  guide: new THREE.LineBasicMaterial({ color: COLOURS.guide }),
  latest: new THREE.LineBasicMaterial({ color: COLOURS.latest }),
  sigma: new THREE.LineBasicMaterial({ vertexColors: true }),
  // A monitored structure: its reference shape, and its latest coloured by displacement.
  reference: new THREE.LineBasicMaterial({ color: COLOURS.guide, transparent: true, opacity: 0.7 }),
  displacement: new THREE.LineBasicMaterial({ vertexColors: true }),
  node: new THREE.PointsMaterial({ color: COLOURS.node, size: 6, sizeAttenuation: false }),
  preview: new THREE.LineDashedMaterial({ color: COLOURS.preview, dashSize: 0.01, gapSize: 0.006 }),
  surface: new THREE.MeshStandardMaterial({
    color: 0xb0bec5, roughness: 0.7, metalness: 0.0, side: THREE.DoubleSide,
    polygonOffset: true, polygonOffsetFactor: 1, polygonOffsetUnits: 1,
  }),
};
const shared = new Set(Object.values(MATERIALS));

// Compiles the shaders of every shared material at load (a first surface otherwise waits
// tens of milliseconds for them, in software WebGL more).
{
  const g = new THREE.BufferGeometry();
  g.setAttribute('position', new THREE.Float32BufferAttribute([0, 0, 0, 1, 0, 0, 0, 1, 0], 3));
  g.setAttribute('normal', new THREE.Float32BufferAttribute([0, 0, 1, 0, 0, 1, 0, 0, 1], 3));
  g.setIndex([0, 1, 2]);
  const warm = new THREE.Group();
  warm.add(new THREE.Mesh(g, MATERIALS.surface), new THREE.Points(g, MATERIALS.node));
  for (const k of ['boundary', 'interior', 'crease', 'guide', 'latest', 'preview']) warm.add(new THREE.Line(g, MATERIALS[k]));
  g.setAttribute('color', new THREE.Float32BufferAttribute([1, 1, 1, 1, 1, 1, 1, 1, 1], 3));
  warm.add(new THREE.Line(g, MATERIALS.sigma));
  scene.add(warm);
  renderer.compile(scene, camera);
  scene.remove(warm);
  g.dispose();
}

// Empties a group, giving back its geometries and own materials.
function clear(group) {
  for (const o of [...group.children]) {
    group.remove(o);
    o.geometry?.dispose();
    if (!shared.has(o.material)) o.material?.dispose();
  }
}

// The uncertainty's colour scale: blue (certain) through yellow to red (the scale's top).
const SIGMA_STOPS = [new THREE.Color(0x2c7bb6), new THREE.Color(0xffffbf), new THREE.Color(0xd7191c)];
function sigmaColour(x) {
  const t = Math.min(1, Math.max(0, x)) * 2;
  const k = Math.min(1, Math.floor(t));
  return SIGMA_STOPS[k].clone().lerp(SIGMA_STOPS[k + 1], t - k);
}
// The legend's span: the drawn σ's, rounded out to a step of 1, 2 or 5 × 10^k mm (about a
// tenth of the span), so that the colours tell the curves apart.
function sigmaSpan(lo, hi) {
  const raw = Math.max(hi - lo, hi * 0.05, 1e-3) / 10;
  const p = Math.pow(10, Math.floor(Math.log10(raw)));
  const step = [1, 2, 5, 10].map((m) => m * p).find((s) => s >= raw);
  return [Math.floor(lo / step) * step, Math.ceil(hi / step) * step];
}
// Colours every curve by its points' σ (the glb's `_SIGMA_M`, the curves event's `sigma_mm`)
// when asked, and shows the legend; otherwise each curve its kind's colour.
function colourBySigma() {
  const on = document.getElementById('show-sigma').checked;
  let lo = Infinity, hi = 0;
  for (const line of network.children) {
    const s = line.userData.sigmaMm;
    if (line.isLine && s) for (const v of s) { lo = Math.min(lo, v); hi = Math.max(hi, v); }
  }
  const [bottom, top] = hi > 0 ? sigmaSpan(lo, hi) : [0, 0];
  state.sigmaScaleMm = on ? top : 0;
  state.sigmaCurves = 0;
  for (const line of network.children) {
    if (!line.isLine) continue;
    const s = line.userData.sigmaMm;
    if (on && s && top > 0 && s.length === line.geometry.getAttribute('position').count) {
      const colours = new Float32Array(s.length * 3);
      s.forEach((v, i) => sigmaColour((v - bottom) / (top - bottom)).toArray(colours, 3 * i));
      line.geometry.setAttribute('color', new THREE.BufferAttribute(colours, 3));
      line.material = MATERIALS.sigma;
      state.sigmaCurves += 1;
    } else {
      line.material = line.userData.material;
    }
  }
  const legend = document.getElementById('sigma-legend');
  legend.hidden = !(on && top > 0);
  const mm = (v) => String(Number(v.toPrecision(3)));
  document.getElementById('sigma-bottom').textContent = mm(bottom);
  document.getElementById('sigma-mid').textContent = mm((bottom + top) / 2);
  document.getElementById('sigma-top').textContent = mm(top) + ' mm';
}

// Replaces the drawn curves and nodes: `lines` [{geometry, curve, kind, nodes}], `positions`
// {node: [x, y, z]} (the glb's frame); frames the first network in view.
function drawNetwork(lines, positions) {
  clear(network); clear(labels);
  const curves = [], nodes = [];
  const box = new THREE.Box3();
  for (const l of lines) {
    // `kind` since curve kinds; before them only `boundary`.
    const kind = CURVE_KINDS.includes(l.kind) ? l.kind : (l.boundary ? 'boundary' : 'interior');
    curves.push({ index: l.curve, kind, boundary: kind === 'boundary', nodes: l.nodes || [] });
    const material = l.curve === state.lastCurve ? MATERIALS.latest : MATERIALS[kind];
    const line = new THREE.Line(l.geometry, material);
    // σ per point, mm: the curves event's, or the glb's custom attribute (metres).
    const attr = l.geometry.getAttribute('_sigma_m');
    const sigmaMm = l.sigma_mm || (attr ? Array.from(attr.array, (v) => v * 1000) : null);
    line.userData = { curve: l.curve, kind, boundary: kind === 'boundary', material, sigmaMm };
    network.add(line);
    l.geometry.computeBoundingBox();
    box.union(l.geometry.boundingBox);
  }
  const size = box.isEmpty() ? 1 : box.getSize(new THREE.Vector3()).length();
  sceneSize = size;
  if (positions) {
    const pts = [];
    for (const [k, p] of Object.entries(positions)) {
      const v = new THREE.Vector3(p[0], p[1], p[2]);
      pts.push(v);
      nodes.push(Number(k));
      if (Number(k) < 1000000) labels.add(label(k, v, size * 0.08));
    }
    const geo = new THREE.BufferGeometry().setFromPoints(pts);
    network.add(new THREE.Points(geo, MATERIALS.node));
  }
  labels.visible = document.getElementById('show-labels').checked;
  colourBySigma();
  state.curves = curves;
  state.nodes = nodes;
  state.nodePositions = positions || {};
  drawMarks();
  frame(box);
}

// Frames the first network (or structure) drawn in view: the camera on the box's centre, from
// a corner, at its size.
function frame(box) {
  if (framed || box.isEmpty()) return;
  const size = box.getSize(new THREE.Vector3()).length();
  const c = box.getCenter(new THREE.Vector3());
  controls.target.copy(c);
  camera.position.copy(c).add(new THREE.Vector3(0.8, 0.6, 0.9).multiplyScalar(size));
  camera.near = size / 1000; camera.far = size * 100;
  camera.updateProjectionMatrix();
  controls.update();
  framed = true;
}

// Rebuilds the scene from a glb (the output contract: a `network` node whose mesh has a
// LINE_STRIP per curve with extras {curve, kind, boundary, nodes} and node positions in its extras;
// an optional `surface` node).
function show(gltf) {
  if (surface) { scene.remove(surface); surface.geometry.dispose(); surface = null; }
  const lines = [];
  gltf.scene.traverse((o) => {
    if (o.isLine) {
      // The loaded geometry itself: the parsed glb is dropped after this.
      lines.push({ geometry: o.geometry, ...(o.geometry.userData || {}) });
    }
    if (o.isMesh && (o.name === 'surface' || o.parent?.name === 'surface')) {
      surface = new THREE.Mesh(o.geometry, MATERIALS.surface);
      surface.visible = document.getElementById('show-surface').checked;
      scene.add(surface);
    }
  });
  let positions = null;
  gltf.scene.traverse((o) => { if (o.userData && o.userData.nodes && !positions) positions = o.userData.nodes; });
  drawNetwork(lines, positions);
  state.surfaceTriangles = surface ? (surface.geometry.index ? surface.geometry.index.count / 3 : 0) : 0;
}

// An update's network before its surface (the `curves` event, issue 35): drawn at once over
// the last surface, which the update's network.glb then replaces.
function showCurves(c) {
  const received = performance.now();
  // The curves event comes before the nodes' σ (the update's second phase computes it): a
  // curve drawn before with as many points keeps its σ until the new network's glb.
  const before = new Map();
  for (const line of network.children) if (line.isLine && line.userData.sigmaMm) before.set(line.userData.curve, line.userData.sigmaMm);
  const lines = c.curves.map((k) => {
    const kept = before.get(k.curve);
    const sigma = k.sigma_mm && k.sigma_mm.length ? k.sigma_mm
      : (kept && kept.length === k.points.length ? kept : null);
    return {
      ...k,
      sigma_mm: sigma,
      geometry: new THREE.BufferGeometry().setAttribute('position', new THREE.Float32BufferAttribute(k.points.flat(), 3)),
    };
  });
  drawNetwork(lines, c.nodes);
  showJoins(c.joins);
  showClosure(c.closure);
  state.curvesShown += 1;
  dropPreview();
  draw();
  const now = performance.now();
  for (const e of c.ended || []) {
    state.curveLatencies.push({ curve: e.curve, ms: performance.timeOrigin + now - e.e_unix_ms, page_ms: now - received });
  }
}

const loader = new GLTFLoader();
let loading = null;
// Curves announced by `network` events whose network is not drawn yet.
const pendingEnded = [];
async function loadNetwork() {
  if (monitorMode) { loadShape(); return; }
  if (loading) { loading.again = true; return; }
  loading = { again: false };
  const ended = pendingEnded.splice(0);
  try {
    const r = await fetch('/network.glb', { cache: 'no-store' });
    if (r.ok) {
      const buf = await r.arrayBuffer();
      const gltf = await loader.parseAsync(buf, '');
      show(gltf);
      state.updates += 1;
      dropPreview();
      draw();
      const now = performance.now();
      for (const e of ended) {
        state.latencies.push({ curve: e.curve, ms: performance.timeOrigin + now - e.e_unix_ms, page_ms: now - e.received });
      }
      }
  } catch (e) {
    pageError('network.glb: ' + e);
  }
  const again = loading.again;
  loading = null;
  if (again) loadNetwork();
}

// The structure's latest shape and its reference (/monitor.json), fetched at each `network`
// event of a monitoring session.
let shapeLoading = null;
async function loadShape() {
  if (shapeLoading) { shapeLoading.again = true; return; }
  shapeLoading = { again: false };
  try {
    const r = await fetch('/monitor.json', { cache: 'no-store' });
    if (r.ok) drawShape(await r.json());
  } catch (e) {
    pageError('monitor.json: ' + e);
  }
  const again = shapeLoading.again;
  shapeLoading = null;
  if (again) loadShape();
}

// The colour scale's top, m: the max_displacement alarm's threshold when there is one (red
// is the alarm), else the largest displacement drawn (at least 1 mm).
function displacementTop(largest) {
  const alarm = (state.status?.monitor?.alarms || []).find((a) => a.metric === 'max_displacement');
  return alarm ? alarm.threshold : Math.max(largest, 1e-3);
}

function drawShape(d) {
  clear(network); clear(labels); clear(marks); clear(structure);
  if (surface) { scene.remove(surface); surface.geometry.dispose(); surface = null; }
  const line = (points, material) => {
    const g = new THREE.BufferGeometry().setAttribute('position', new THREE.Float32BufferAttribute(points.flat(), 3));
    const l = new THREE.Line(g, material);
    structure.add(l);
    return l;
  };
  for (const c of d.reference) line(c.points, MATERIALS.reference);
  let largest = 0;
  for (const c of d.curves) if (c.displacement_m) for (const v of c.displacement_m) largest = Math.max(largest, v);
  const top = displacementTop(largest);
  let coloured = 0;
  const box = new THREE.Box3();
  for (const c of d.curves) {
    const l = line(c.points, c.displacement_m ? MATERIALS.displacement : MATERIALS.latest);
    if (c.displacement_m) {
      const colours = new Float32Array(c.displacement_m.length * 3);
      c.displacement_m.forEach((v, i) => sigmaColour(v / top).toArray(colours, 3 * i));
      l.geometry.setAttribute('color', new THREE.BufferAttribute(colours, 3));
      coloured += 1;
    }
    l.geometry.computeBoundingBox();
    box.union(l.geometry.boundingBox);
  }
  const mm = (v) => String(Number((v * 1000).toPrecision(3)));
  document.getElementById('displacement-mid').textContent = mm(top / 2);
  document.getElementById('displacement-top').textContent = mm(top) + ' mm';
  state.monitor = { t_s: d.t_s, curves: d.curves.length, referenceCurves: d.reference.length, coloured, topMm: top * 1000, largestMm: largest * 1000 };
  state.updates += 1;
  frame(box);
  draw();
}

// The monitor's side panel: the latest epoch, the reference, the metrics, the alarms and each
// sensor's health.
function showMonitor(m) {
  if (!monitorMode) {
    monitorMode = true;
    document.body.classList.add('monitor');
    glyph.visible = false;
    framed = false;
    loadShape();
  }
  const mm = (v) => `${(v * 1000).toFixed(1)} mm`;
  text('monitor-epoch', m.epoch_t_s != null
    ? `epoch ${m.epochs} at t = ${m.epoch_t_s.toFixed(1)} s${m.failed ? ` · ${m.failed} failed` : ''}`
    : 'no epoch yet', !!m.failing);
  if (m.failing) document.getElementById('monitor-epoch').title = m.failing;
  text('monitor-reference', m.reference_ready
    ? `reference of ${m.reference_epochs || 'a file\'s'} epochs`
    : `building the reference: ${m.reference_epochs} of ${m.reference_of} epochs`);
  text('monitor-metrics', m.last
    ? `displacement max ${mm(m.last.max_displacement)} · mean ${mm(m.last.mean_displacement)} · curvature change max ${m.last.max_curvature_change.toFixed(3)} rad/m`
    : '');
  const alarms = document.getElementById('alarms');
  alarms.replaceChildren(...(m.alarms.length ? m.alarms.map((a) => {
    const li = document.createElement('li');
    li.textContent = `${a.metric} > ${a.threshold}: ${a.raised ? 'RAISED' : 'quiet'}`;
    li.className = a.raised ? 'raised' : '';
    return li;
  }) : [Object.assign(document.createElement('li'), { textContent: 'none configured' })]));
  const sensors = document.getElementById('sensors');
  const items = m.sensors.map((x) => {
    const li = document.createElement('li');
    li.textContent = `${x.sensor} ${x.health}`;
    li.className = x.health;
    return li;
  });
  for (const u of m.unknown_sensors) {
    const li = document.createElement('li');
    li.textContent = `${u} not in the layout`;
    li.className = 'unknown';
    items.push(li);
  }
  sensors.replaceChildren(...items);
  state.monitorStatus = {
    alarmsRaised: m.alarms.filter((a) => a.raised).length,
    sensors: Object.fromEntries(m.sensors.map((x) => [x.sensor, x.health])),
    unknown: m.unknown_sensors,
  };
}

function text(id, s, bad) {
  const el = document.getElementById(id);
  el.textContent = s;
  el.classList.toggle('bad', !!bad);
}

let warningsShown = false;
// The phone page's address and its QR code (a session reading the phone: sfs run --phone).
let phoneShown = false;
// The phone page: every client sees that there is one (its address without the token, and
// its certificate's fingerprint); its QR code and its address with the token, the right to
// write into the session, come only to a client that may write (on the machine that runs sfs,
// or with the view's token).
function showPhone(phone) {
  if (!phone || phoneShown) return;
  phoneShown = true;
  const box = document.getElementById('phone');
  box.hidden = false;
  document.getElementById('phone-fingerprint').textContent = phone.fingerprint;
  const img = document.getElementById('phone-qr');
  const a = document.getElementById('phone-url');
  const withheld = () => {
    img.hidden = true;
    a.removeAttribute('href');
    a.textContent = `${phone.page}?token=… (shown on the machine that runs sfs: its terminal, or SESSION/phone.url)`;
  };
  img.onerror = withheld;
  img.src = '/phone-qr.svg';
  fetch('/status', { cache: 'no-store' })
    .then((r) => r.json())
    .then((st) => {
      if (!st.phone_url) { withheld(); return; }
      a.textContent = st.phone_url;
      a.href = st.phone_url;
      state.phoneUrl = st.phone_url;
    })
    .catch(withheld);
}

// The banner's pill: the session's state, and while it runs what the link does (red while
// the device is lost, orange while it is silent).
function showLink(s) {
  const pill = document.getElementById('state');
  const l = s.link;
  let label = s.state;
  let cls = s.state;
  const secs = l.for_s != null ? ` ${l.for_s.toFixed(0)} s` : '';
  if (s.state === 'running') {
    if (l.state === 'disconnected') { label = `device lost${secs}`; cls = 'lost'; }
    else if (l.state === 'reconnecting') { label = `device lost${secs} · reconnecting (attempt ${l.attempt})`; cls = 'lost'; }
    else if (l.state === 'silent') { label = `device silent${secs}`; cls = 'silent'; }
    else if (l.state === 'connecting') { label = 'waiting for the device'; cls = 'starting'; }
    if (l.problem) { label = 'no sfs device heard'; cls = 'lost'; }
  }
  pill.textContent = label;
  pill.className = 'pill ' + cls;
  pill.title = [l.problem, l.reason].filter(Boolean).join(' — ');
  state.link = { state: l.state, pill: label, cls, problem: l.problem || null };
}

function showStatus(s) {
  state.status = s;
  if (!warningsShown) {
    // A page opened mid-session: the latest warnings, before the events bring the next.
    warningsShown = true;
    for (const w of s.warnings) addWarning(w);
  }
  redraw();
  showLink(s);
  if (s.monitor) { showMonitor(s.monitor); return; }
  if (s.curve) {
    const d = s.curve.distance_m != null ? `, ${s.curve.distance_m.toFixed(2)} m` : '';
    text('curve', `curve ${s.curve.index} (${s.curve.kind}): nodes ${s.curve.nodes.join(' → ') || '—'}, ${s.curve.samples} samples${d}`);
  } else {
    text('curve', 'no curve open');
  }
  text('accepted', `${s.curves_accepted} curve(s) accepted`);
  showPhone(s.phone);
  const l = s.link;
  const lostCount = l.disconnects ? ` · lost ${l.disconnects}×` : '';
  text('link', `link ${l.packets_per_s.toFixed(0)} pkt/s · ${l.rejected} rejected · ${l.lost} lost · ${l.reboots} reboots${lostCount}`, l.lost > 0 || l.disconnects > 0);
  if (s.device) {
    const d = s.device;
    const batt = d.battery_mv != null ? ` · battery ${(d.battery_mv / 1000).toFixed(2)} V` : '';
    const flags = d.status_flags.length ? ' · ' + d.status_flags.join(', ') : '';
    text('device', `${d.kind} #${d.id} · ${d.rate_hz} Hz${batt}${flags}`, (d.battery_mv != null && d.battery_mv < 3400) || d.status_flags.length > 0);
  }
  showQuality(s.quality);
  showClosure(s.closure || []);
  showJoins(s.joins || { joined: [], proposed: [], refused: [] });
  const rec = document.getElementById('reconstruction');
  rec.replaceChildren(...(s.reconstruction.length ? s.reconstruction : [{ text: 'nothing to say' }]).map((w) => {
    const li = document.createElement('li');
    li.textContent = w.text;
    return li;
  }));
  if (s.orientation) {
    const t = new THREE.Vector3(...s.orientation.t), n = new THREE.Vector3(...s.orientation.n);
    glyphT.setDirection(t.normalize());
    glyphN.setDirection(n.normalize());
    glyph.scale.setScalar(sceneSize * 0.06);
    if (preview) {
      const a = preview.geometry.attributes.position;
      glyph.position.set(a.getX(a.count - 1), a.getY(a.count - 1), a.getZ(a.count - 1));
    } else {
      glyph.position.copy(controls.target);
    }
    glyph.visible = true;
    state.orientation = s.orientation;
  }
  if (s.live && s.live.latency_ms.n > 0) {
    const c = s.live.curves_latency_ms;
    text('latency', `curves ${c.p50.toFixed(0)} / ${c.p95.toFixed(0)} ms · update ${s.live.latency_ms.p50.toFixed(0)} / ${s.live.latency_ms.p95.toFixed(0)} ms`);
  }
}

// The verdict in the bar and each suspect with the keys that rescan its curve (issue 49).
function showQuality(q) {
  const pill = document.getElementById('verdict');
  if (!q || q.verdict === 'none') { pill.hidden = true; return; }
  pill.hidden = false;
  const pct = q.expected_error_pct != null ? ` · ±${(q.expected_error_m * 1000).toFixed(1)} mm` : '';
  pill.textContent = `scan ${q.verdict}${pct}`;
  pill.className = 'pill verdict-' + q.verdict;
  pill.title = q.verdict_reason;
  state.verdict = q.verdict;
  state.suspects = q.suspects.map((x) => ({ curve: x.curve, tag: x.tag, node: x.node, kind: x.kind, rescan: x.rescan }));
  const list = document.getElementById('suspects');
  const why = { 'late-enter': 'Enter pressed while rolling', 'wrong-node': 'its loops refuse the node typed', slip: 'a stretch measured short: the wheel slipped' };
  list.replaceChildren(...(q.suspects.length ? q.suspects.map((x) => {
    const li = document.createElement('li');
    const at = x.node != null ? ` at node ${x.node}` : '';
    li.textContent = `curve ${x.curve} looks wrong${at} (${why[x.kind] || x.kind}): rescan with ${x.rescan}`;
    li.title = x.reason;
    return li;
  }) : [Object.assign(document.createElement('li'), { textContent: 'none' })]));
}

function addWarning(w) {
  const li = document.createElement('li');
  li.textContent = w.text;
  li.title = w.code;
  const list = document.getElementById('warnings');
  list.prepend(li);
  while (list.children.length > 200) list.lastChild.remove();
  state.warnings += 1;
  document.getElementById('warning-count').textContent = `(${state.warnings})`;
}

function dropPreview() {
  if (!preview) return;
  scene.remove(preview);
  preview.geometry.dispose();
  preview = null;
  state.previewPoints = 0;
}

function showPreview(p) {
  dropPreview();
  if (!p || !p.points || p.points.length < 2) return;
  const geo = new THREE.BufferGeometry().setFromPoints(p.points.map((q) => new THREE.Vector3(q[0], q[1], q[2])));
  preview = new THREE.Line(geo, MATERIALS.preview);
  preview.computeLineDistances();
  scene.add(preview);
  state.previewPoints = p.points.length;
  redraw();
  if (!framed) {
    // No network yet (the first curve): keep the curve being scanned in sight.
    geo.computeBoundingSphere();
    const s = geo.boundingSphere;
    const r = Math.max(s.radius, 0.05);
    controls.target.copy(s.center);
    camera.position.copy(s.center).add(new THREE.Vector3(1.2, 1.0, 1.4).multiplyScalar(r * 1.5));
    camera.near = r / 1000; camera.far = r * 1000;
    camera.updateProjectionMatrix();
    controls.update();
  }
}

document.getElementById('show-surface').addEventListener('change', (e) => { if (surface) surface.visible = e.target.checked; });
document.getElementById('show-labels').addEventListener('change', (e) => { labels.visible = e.target.checked; });
document.getElementById('show-sigma').addEventListener('change', () => { colourBySigma(); redraw(); });

// Kept current by the server's events; the whole network fetched at once and again at every
// `network` event and every reconnection.
const events = new EventSource('/events');
const on = (name, f) => events.addEventListener(name, (e) => {
  state.events[name] += 1;
  f(JSON.parse(e.data));
});
on('status', showStatus);
on('curve', (c) => { state.lastCurve = c.index; });
on('curves', showCurves);
on('network', (n) => {
  const received = performance.now();
  pendingEnded.push(...(n.ended || []).map((e) => ({ ...e, received })));
  loadNetwork();
});
on('warning', addWarning);
on('preview', showPreview);
events.addEventListener('open', () => loadNetwork());
loadNetwork();
events.onerror = () => {
  const pill = document.getElementById('state');
  if (events.readyState !== EventSource.OPEN) { pill.textContent = 'disconnected'; pill.className = 'pill lost'; }
};

function draw() {
  resize();
  renderer.render(scene, camera);
  drawnAt = performance.now();
  state.frames += 1;
}
// Drawn on demand (an event changed the scene, the view was turned, the window resized), at
// most every DRAW_PERIOD ms, once for any number of requests in between: a page left open
// costs nothing between events, and the 15 status and preview events a second cost 10
// frames (a new network is drawn at once: `draw`).
const DRAW_PERIOD = 100;
let drawPending = false, drawnAt = -Infinity;
function redraw() {
  if (drawPending) return;
  drawPending = true;
  const wait = Math.max(0, drawnAt + DRAW_PERIOD - performance.now());
  setTimeout(() => { drawPending = false; draw(); }, wait);
}
controls.addEventListener('change', redraw);
window.addEventListener('resize', redraw);
redraw();
state.ready = true;
