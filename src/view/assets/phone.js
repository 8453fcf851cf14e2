// The phone page: the browser's motion sensors and this keypad as a scanning device. It encodes
// wire format v1 itself (wire.js) and streams whole frames over one WebSocket to the daemon,
// which captures them like the bytes of a serial port.
//
// Sensors: `devicemotion` gives the accelerometer (accelerationIncludingGravity, m/s²) and the
// gyroscope (rotationRate, °/s); `deviceorientationabsolute` (iOS: `deviceorientation` with
// `webkitCompassHeading`) the orientation against north. Browsers give no magnetometer, so the
// page sends a virtual one: a fixed Earth field (48 µT, inclination 64°, pointing north and
// down) turned into the phone's axes by the absolute orientation. Its heading is the browser's,
// which the phone's own fusion already corrects against its magnetometer (device-protocol
// README, "The phone page").
//
// window.sfsPhone = { state, rate_hz, sent_packets, … } for tests and for a person debugging.

import * as wire from '/wire.js';

const FIELD_UT = 48, INCLINATION_DEG = 64;
const ACC_LSB = 16 * 9.80665 / 65536; // ±8 g
const GYRO_LSB = (2000 * Math.PI / 180) / 32768; // ±2000 °/s
const MAG_LSB = 0.15; // µT
const HELLO_PERIOD_MS = 5000;
const MAX_MESSAGE = 32 * 1024; // the daemon takes 64 KiB
const QUEUE_MS = 60000; // frames kept while the link is down
const KEYS = { Enter: 0x0a };
const NO_MOTION_MS = 3000; // Start without a motion sample for this long: said, with the causes
const CONFIRM_MS = 2000; // C sends only when tapped again within this

const token = new URLSearchParams(location.search).get('token') || '';
const phone = window.sfsPhone = {
  state: 'ready', rate_hz: 0, sent_packets: 0, sent_bytes: 0, queued: 0, dropped: 0,
  samples: 0, keys: 0, connections: 0, orientation: false, acc_sign: 0,
  motion_events: 0, orientation_events: 0, refused_keys: 0, hint: null,
  feedback: null, errors: [],
};

let seq = Math.floor(Math.random() * 256);
let deviceId = Number(localStorage.getItem('sfsDeviceId'));
if (!deviceId) {
  deviceId = 0x50480000 + Math.floor(Math.random() * 0x10000);
  localStorage.setItem('sfsDeviceId', String(deviceId));
}
const queue = []; // frames (Uint8Array) not yet sent
let queuedBytes = 0;
let ws = null, retryMs = 500, lastHello = -Infinity, interval = 0;
let orientation = null; // the latest absolute orientation: { R (row-major 3×3 device → world) }
let accVotes = 0;
let typed = '';

const STATE_LABELS = { waiting: 'waiting for motion', 'no-motion': 'no motion data' };

function setState(s) {
  phone.state = s;
  const el = document.getElementById('state');
  el.textContent = STATE_LABELS[s] || s;
  el.className = `pill ${s}`;
}

// A line (or a list) under the curve that tells the operator what to do; null hides it.
function hint(text, causes) {
  phone.hint = text;
  const el = document.getElementById('hint');
  el.hidden = !text;
  el.textContent = text || '';
  if (causes) {
    const ul = document.createElement('ul');
    for (const c of causes) { const li = document.createElement('li'); li.textContent = c; ul.append(li); }
    el.append(ul);
  }
}

function push(frame) {
  queue.push(frame);
  queuedBytes += frame.length;
  // Past a minute of frames the oldest go: counted, and seen by the daemon as a gap.
  const limit = QUEUE_MS * 0.03 * Math.max(phone.rate_hz, 60);
  while (queuedBytes > limit && queue.length > 1) {
    queuedBytes -= queue.shift().length;
    phone.dropped += 1;
  }
  phone.queued = queue.length;
}

function nextSeq() { const s = seq; seq = (seq + 1) & 0xff; return s; }

function hello() {
  push(wire.hello(nextSeq(), {
    deviceId, firmware: 0x0100, rateHz: Math.round(phone.rate_hz) || 60,
    accScale: ACC_LSB, gyroScale: GYRO_LSB, magScale: MAG_LSB,
  }));
}

/** Sends what is queued, in messages of whole frames. */
function flush() {
  if (!ws || ws.readyState !== WebSocket.OPEN) return;
  while (queue.length && ws.bufferedAmount < 4 * MAX_MESSAGE) {
    let n = 0, bytes = 0;
    while (n < queue.length && bytes + queue[n].length <= MAX_MESSAGE) bytes += queue[n++].length;
    const msg = new Uint8Array(bytes);
    let o = 0;
    for (const f of queue.splice(0, n)) { msg.set(f, o); o += f.length; }
    queuedBytes -= bytes;
    ws.send(msg);
    phone.sent_packets += n;
    phone.sent_bytes += bytes;
  }
  phone.queued = queue.length;
}

// Orientation: the W3C angles are intrinsic Z-X'-Y'' (alpha, beta, gamma), device → Earth
// (x east, y north, z up): R = Rz(α)·Rx(β)·Ry(γ).
function rotation(alpha, beta, gamma) {
  const d = Math.PI / 180;
  const [ca, sa, cb, sb, cg, sg] = [Math.cos(alpha * d), Math.sin(alpha * d), Math.cos(beta * d),
    Math.sin(beta * d), Math.cos(gamma * d), Math.sin(gamma * d)];
  return [
    ca * cg - sa * sb * sg, -cb * sa, ca * sg + cg * sa * sb,
    cg * sa + ca * sb * sg, ca * cb, sa * sg - ca * cg * sb,
    -cb * sg, sb, cb * cg,
  ];
}

/** Rᵀ·v: a world vector in the phone's axes. */
function toDevice(R, v) {
  return [0, 1, 2].map((i) => R[i] * v[0] + R[3 + i] * v[1] + R[6 + i] * v[2]);
}

function onOrientation(e) {
  if (e.alpha != null) phone.orientation_events += 1;
  let alpha = e.alpha;
  if (typeof e.webkitCompassHeading === 'number' && e.webkitCompassHeading >= 0) {
    alpha = 360 - e.webkitCompassHeading; // iOS: clockwise from north
  } else if (e.type === 'deviceorientation' && !e.absolute) {
    return; // a relative orientation has no north
  }
  if (alpha == null || e.beta == null || e.gamma == null) return;
  orientation = { R: rotation(alpha, e.beta, e.gamma) };
  phone.orientation = true;
}

function onMotion(e) {
  const a = e.accelerationIncludingGravity, r = e.rotationRate;
  if (a && a.x != null) phone.motion_events += 1;
  if (!orientation || !a || a.x == null || !r || r.alpha == null) return;
  if (e.interval > 0) interval = interval ? 0.95 * interval + 0.05 * e.interval : e.interval;
  phone.rate_hz = interval ? 1000 / interval : 0;
  const R = orientation.R;
  let acc = [a.x, a.y, a.z];
  // The specific force at rest points up; browsers that report it the other way round (iOS
  // has) are told apart over the first samples.
  if (phone.acc_sign === 0) {
    const up = toDevice(R, [0, 0, 1]);
    accVotes += Math.sign(acc[0] * up[0] + acc[1] * up[1] + acc[2] * up[2]);
    if (Math.abs(accVotes) >= 30) phone.acc_sign = Math.sign(accVotes);
    else return;
  }
  acc = acc.map((x) => x * phone.acc_sign);
  const d = Math.PI / 180;
  // Chromium reports rotationRate as alpha, beta, gamma = the rate about x, y, z (checked
  // against its sensor overrides: tests/phone_page.rs).
  const gyro = [r.alpha * d, r.beta * d, r.gamma * d];
  const i = INCLINATION_DEG * d;
  const mag = toDevice(R, [0, FIELD_UT * Math.cos(i), -FIELD_UT * Math.sin(i)]);
  if (e.timeStamp - lastHello >= HELLO_PERIOD_MS) { lastHello = e.timeStamp; hello(); }
  push(wire.phoneSample(nextSeq(), {
    tUs: wire.tUs(e.timeStamp),
    acc: acc.map((x) => wire.counts(x, ACC_LSB)),
    gyro: gyro.map((x) => wire.counts(x, GYRO_LSB)),
    mag: mag.map((x) => wire.counts(x, MAG_LSB)),
  }));
  phone.samples += 1;
  if (phone.samples === 1) firstSample();
  flush();
}

// The first sample: the link opens only now, so that a browser that sends no motion does not
// connect, time out and reconnect forever.
function firstSample() {
  if (phone.state === 'no-motion') hint(null);
  setState('connecting');
  connect();
}

// Started, and no sample yet: why, as far as the page can tell.
function noMotion() {
  if (phone.samples > 0 || phone.state === 'stopped') return;
  setState('no-motion');
  const causes = [];
  if (phone.motion_events === 0) {
    causes.push('this browser sends no motion data: a desktop or laptop has no motion sensors; open the page on a phone');
    causes.push('motion access was refused: allow it for this site (iOS: Settings › Safari › Motion & Orientation Access; Chrome: site settings › Motion sensors), then reload');
    if (!window.isSecureContext) causes.push('the page is not on https: motion needs a secure page');
  } else if (!phone.orientation) {
    causes.push(phone.orientation_events === 0
      ? 'the browser sends motion but no orientation: allow orientation access for this site, then reload'
      : 'the browser gives no absolute orientation (no compass): the phone needs a magnetometer, and the browser must give north (Chrome and Safari do)');
  } else {
    causes.push('the phone is still settling: hold it flat and still a moment');
  }
  hint('No motion data since Start. Likely causes:', causes);
}

let confirmUntil = 0, confirmTimer = 0;

function onKey(e) {
  const k = e.currentTarget.dataset.key;
  // Keys mean something only while the sensors stream: refused before, with a hint.
  if (!['streaming', 'connecting', 'reconnecting'].includes(phone.state)) {
    phone.refused_keys += 1;
    hint(phone.state === 'ready'
      ? 'Press Start first: keys are sent only while the phone streams its motion.'
      : `Key ${k} not sent: the phone is not streaming yet (${STATE_LABELS[phone.state] || phone.state}).`);
    return;
  }
  // C throws a whole curve away: a second tap within 2 s confirms it.
  const cButton = document.querySelector('[data-key="C"]');
  if (k === 'C' && e.timeStamp > confirmUntil) {
    confirmUntil = e.timeStamp + CONFIRM_MS;
    cButton.classList.add('confirm');
    hint('Tap C again to cancel the whole curve.');
    clearTimeout(confirmTimer);
    confirmTimer = setTimeout(() => { cButton.classList.remove('confirm'); if (phone.hint?.startsWith('Tap C')) hint(null); }, CONFIRM_MS);
    return;
  }
  confirmUntil = 0;
  cButton.classList.remove('confirm');
  if (phone.hint) hint(null);
  const code = KEYS[k] ?? k.charCodeAt(0);
  push(wire.key(nextSeq(), { tUs: wire.tUs(e.timeStamp), key: code }));
  phone.keys += 1;
  if (navigator.vibrate) navigator.vibrate(25);
  if (/^[0-9]$/.test(k)) typed += k; else typed = '';
  document.getElementById('typed').textContent = typed;
  flush();
}

function showFeedback(f) {
  phone.feedback = f;
  const c = f.curve;
  document.getElementById('curve').textContent = c
    ? `curve ${c.index} (${c.kind}): nodes ${c.nodes.join(' ') || 'none yet'}`
    : 'no curve open';
  document.getElementById('curves').textContent = `${f.curves} curve${f.curves === 1 ? '' : 's'} scanned`;
  document.getElementById('link').textContent = `${f.packets} packets, ${f.rejected} rejected, ${f.lost} lost`;
  const w = document.getElementById('warning');
  w.hidden = !f.warning;
  w.textContent = f.warning || '';
}

function connect() {
  // The page's clock (its origin and now, ms since the epoch): the daemon measures the
  // latency from a sensor event to its arrival only when the two clocks agree. The browser's
  // name goes in its User-Agent header: the page sends binary frames only.
  const clock = `origin=${performance.timeOrigin}&now=${performance.timeOrigin + performance.now()}`;
  const url = `wss://${location.host}/phone/ws?token=${encodeURIComponent(token)}&${clock}`;
  ws = new WebSocket(url);
  ws.binaryType = 'arraybuffer';
  ws.onopen = () => {
    phone.connections += 1;
    retryMs = 500;
    setState('streaming');
    lastHello = -Infinity; // a HELLO first on every connection
  };
  ws.onmessage = (m) => {
    if (typeof m.data !== 'string') return;
    try {
      const f = JSON.parse(m.data);
      if (f.type === 'status') showFeedback(f);
    } catch (err) { phone.errors.push(String(err)); }
  };
  ws.onclose = () => {
    ws = null;
    if (phone.state === 'stopped') return;
    setState('reconnecting');
    setTimeout(connect, retryMs);
    retryMs = Math.min(retryMs * 2, 5000);
  };
}

// Closes the link as a network change would (the page reconnects and sends what it measured
// meanwhile): for tests, and for an operator trying a reconnection.
phone.drop = () => { if (ws) ws.close(4000, 'dropped by the page'); };

// Stops streaming for good: no more samples, what is queued sent, the link closed
// (sent_packets is then final).
phone.stop = () => {
  window.removeEventListener('devicemotion', onMotion);
  window.removeEventListener('deviceorientationabsolute', onOrientation);
  window.removeEventListener('deviceorientation', onOrientation);
  flush();
  setState('stopped');
  if (ws) ws.close(1000, 'stopped');
};

let wakeLock = null;
async function keepAwake() {
  try {
    if ('wakeLock' in navigator && document.visibilityState === 'visible') {
      wakeLock = await navigator.wakeLock.request('screen');
    }
  } catch (err) { phone.errors.push(`wake lock: ${err}`); }
}

async function start() {
  const ask = async (C) => (C && typeof C.requestPermission === 'function'
    ? C.requestPermission() : 'granted');
  try {
    // iOS asks once, on a gesture; elsewhere these are absent.
    const [m, o] = [await ask(window.DeviceMotionEvent), await ask(window.DeviceOrientationEvent)];
    if (m !== 'granted' || o !== 'granted') { setState('denied'); return; }
  } catch (err) {
    phone.errors.push(String(err));
    setState('denied');
    return;
  }
  if (!window.DeviceMotionEvent) { setState('unsupported'); return; }
  window.addEventListener('devicemotion', onMotion);
  if ('ondeviceorientationabsolute' in window) {
    window.addEventListener('deviceorientationabsolute', onOrientation);
  } else {
    window.addEventListener('deviceorientation', onOrientation);
  }
  document.getElementById('start').hidden = true;
  setState('waiting');
  keepAwake();
  setTimeout(noMotion, NO_MOTION_MS);
}

document.getElementById('start').addEventListener('click', start);
for (const b of document.querySelectorAll('[data-key]')) b.addEventListener('click', onKey);
document.addEventListener('visibilitychange', () => {
  if (document.visibilityState === 'visible' && phone.state !== 'ready') keepAwake();
});
setInterval(() => {
  document.getElementById('rate').textContent =
    `${phone.rate_hz.toFixed(0)} Hz, ${phone.sent_packets} sent${phone.queued ? `, ${phone.queued} queued` : ''}`;
}, 500);
