// sl_view's web page: a Foxglove WebSocket client (foxglove.websocket.v1)
// of the sl_view bridge that served it. Shows the decimated cloud
// (/<ns>/points/preview) in 3D, its depth as an image, the daemon's status,
// and sends start / stop / pattern / one-scan requests through the bridge's
// /<ns>/command service (the daemon's request topic, as slctl).
import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';

// --- CDR (XCDR1 little-endian, 4-byte encapsulation header) -------------------
class Cdr {
  constructor(buf) { this.v = new DataView(buf.buffer, buf.byteOffset, buf.byteLength); this.b = buf; this.p = 4; }
  al(n) { this.p = 4 + Math.ceil((this.p - 4) / n) * n; }
  u8() { return this.v.getUint8(this.p++); }
  u32() { this.al(4); const x = this.v.getUint32(this.p, true); this.p += 4; return x; }
  i32() { this.al(4); const x = this.v.getInt32(this.p, true); this.p += 4; return x; }
  u64() { this.al(8); const x = Number(this.v.getBigUint64(this.p, true)); this.p += 8; return x; }
  f64() { this.al(8); const x = this.v.getFloat64(this.p, true); this.p += 8; return x; }
  str() { const n = this.u32(); const s = new TextDecoder().decode(this.b.subarray(this.p, this.p + n - 1)); this.p += n; return s; }
  strs() { const n = this.u32(); const a = []; for (let i = 0; i < n; i++) a.push(this.str()); return a; }
  bytes() { const n = this.u32(); const s = this.b.subarray(this.p, this.p + n); this.p += n; return s; }
}
function readCloud(buf) {
  const c = new Cdr(buf);
  const stamp = { sec: c.i32(), nanosec: c.u32() }, frame = c.str();
  const height = c.u32(), width = c.u32(), fields = {};
  for (let i = 0, n = c.u32(); i < n; i++) { const name = c.str(); fields[name] = { offset: c.u32(), datatype: c.u8(), count: c.u32() }; }
  const bigendian = c.u8() !== 0, pointStep = c.u32(), rowStep = c.u32(), data = c.bytes();
  return { stamp, frame, height, width, fields, bigendian, pointStep, rowStep, data };
}
const kStates = ['idle', 'scanning', 'error', 'waiting', 'degraded'];
function readStatus(buf) {
  const c = new Cdr(buf), s = {};
  s.stamp = { sec: c.i32(), nanosec: c.u32() }; s.state = kStates[c.u8()] ?? '?'; s.pattern = c.str();
  for (const k of ['scans_done', 'scans_requested']) s[k] = c.u64();
  s.scan_rate_hz = c.f64();
  for (const k of ['frames_dropped', 'sets_dropped', 'sets_incomplete', 'frames_overflow', 'frames_unmatched',
    'sets_overflow', 'writes_timed_out', 'sets_not_recorded']) s[k] = c.u64();
  s.recording = c.str(); s.sets_recorded = c.u64(); s.last_error = c.str(); s.patterns = c.strs();
  s.trigger = c.u8(); s.cameras = c.strs(); s.motion_compensation = c.u8() !== 0;
  s.start_at = { sec: c.i32(), nanosec: c.u32() }; s.frame_rate_hz = c.f64();
  return s;
}

// --- 3D view --------------------------------------------------------------------
const host = document.getElementById('scene');
const renderer = new THREE.WebGLRenderer({ antialias: false, preserveDrawingBuffer: true });
renderer.setPixelRatio(window.devicePixelRatio);
host.appendChild(renderer.domElement);
const scene = new THREE.Scene();
scene.background = new THREE.Color(0x111111);
// The optical frame looks along +z with y down: the camera starts at the sensor.
const camera = new THREE.PerspectiveCamera(50, 1, 0.01, 100);
camera.up.set(0, -1, 0);
camera.position.set(0, 0, -0.05);
const controls = new OrbitControls(camera, renderer.domElement);
controls.target.set(0, 0, 0.55);
controls.update();
// Rendered on demand (a new cloud, the view moved), not in a loop: an idle
// page costs no CPU.
let renderQueued = false;
function render() {
  if (renderQueued) return;
  renderQueued = true;
  requestAnimationFrame(() => { renderQueued = false; renderer.render(scene, camera); });
}
controls.addEventListener('change', render);
scene.add(new THREE.AxesHelper(0.05));
const geometry = new THREE.BufferGeometry();
const material = new THREE.PointsMaterial({ size: 2, sizeAttenuation: false, vertexColors: true });
const points = new THREE.Points(geometry, material);
points.frustumCulled = false;
scene.add(points);
function resize() {
  const w = host.clientWidth, h = host.clientHeight;
  renderer.setSize(w, h); camera.aspect = w / h; camera.updateProjectionMatrix();
  render();
}
window.addEventListener('resize', resize);
resize();

// Colour map (0..1 -> blue..red via cyan, green, yellow).
function ramp(t, out, i) {
  t = Math.min(1, Math.max(0, t));
  out[i] = Math.min(1, Math.max(0, 1.5 - Math.abs(4 * t - 3)));
  out[i + 1] = Math.min(1, Math.max(0, 1.5 - Math.abs(4 * t - 2)));
  out[i + 2] = Math.min(1, Math.max(0, 1.5 - Math.abs(4 * t - 1)));
}

// What the page shows, for people and for tests/view (headless Chromium).
const view = window.slView = { clouds: 0, points: 0, width: 0, height: 0, status: null, replies: [], connected: false };
let colorBy = 'depth', lastCloud = null, targetSet = false;
for (const r of document.querySelectorAll('input[name=color]'))
  r.addEventListener('change', () => { colorBy = r.value; if (lastCloud) showCloud(lastCloud); });

const depthCanvas = document.getElementById('depth');
function showCloud(cloud) {
  const { width, height, fields, pointStep, data } = cloud;
  const dv = new DataView(data.buffer, data.byteOffset, data.byteLength);
  const n = width * height, pos = new Float32Array(n * 3), col = new Float32Array(n * 3);
  const zs = new Float32Array(n);
  const ox = fields.x.offset, oy = fields.y.offset, oz = fields.z.offset, oi = fields.intensity?.offset;
  let valid = 0, zmin = Infinity, zmax = -Infinity, imax = 1, sx = 0, sy = 0, sz = 0;
  for (let i = 0; i < n; i++) {
    const b = i * pointStep, z = dv.getFloat32(b + oz, true);
    zs[i] = z;
    if (!Number.isFinite(z)) continue;
    const x = dv.getFloat32(b + ox, true), y = dv.getFloat32(b + oy, true);
    pos[3 * valid] = x; pos[3 * valid + 1] = y; pos[3 * valid + 2] = z;
    col[3 * valid] = oi !== undefined ? dv.getFloat32(b + oi, true) : z;  // raw value, mapped below
    sx += x; sy += y; sz += z; zmin = Math.min(zmin, z); zmax = Math.max(zmax, z);
    if (oi !== undefined) imax = Math.max(imax, col[3 * valid]);
    valid++;
  }
  for (let k = 0; k < valid; k++) {
    if (colorBy === 'intensity' && oi !== undefined) { const g = col[3 * k] / imax; col[3 * k] = col[3 * k + 1] = col[3 * k + 2] = g; }
    else ramp((pos[3 * k + 2] - zmin) / Math.max(1e-6, zmax - zmin), col, 3 * k);
  }
  geometry.setAttribute('position', new THREE.BufferAttribute(pos, 3));
  geometry.setAttribute('color', new THREE.BufferAttribute(col, 3));
  geometry.setDrawRange(0, valid);
  if (!targetSet && valid > 0) {
    // First cloud: orbit around its centre, seen from above and to the left
    // of the sensor so that depth shows.
    const c = new THREE.Vector3(sx / valid, sy / valid, sz / valid);
    controls.target.copy(c);
    camera.position.set(c.x - 0.28, c.y - 0.22, c.z - 0.42);
    controls.update();
    targetSet = true;
  }
  render();
  // Depth image: z per pixel of the organized cloud, black where invalid.
  depthCanvas.width = width; depthCanvas.height = height;
  const ctx = depthCanvas.getContext('2d'), img = ctx.createImageData(width, height), rgb = [0, 0, 0];
  for (let i = 0; i < n; i++) {
    if (Number.isFinite(zs[i])) { ramp((zs[i] - zmin) / Math.max(1e-6, zmax - zmin), rgb, 0); }
    else { rgb[0] = rgb[1] = rgb[2] = 0; }
    img.data[4 * i] = 255 * rgb[0]; img.data[4 * i + 1] = 255 * rgb[1]; img.data[4 * i + 2] = 255 * rgb[2]; img.data[4 * i + 3] = 255;
  }
  ctx.putImageData(img, 0, 0);
  Object.assign(view, { points: valid, width, height, zmin, zmax });
  document.getElementById('cloudinfo').textContent =
    `cloud ${view.clouds}: ${width} x ${height} shown, ${valid} points, z ${zmin.toFixed(3)}..${zmax.toFixed(3)} m`;
}

// --- status ----------------------------------------------------------------------
let bridgeStats = null;
const esc = (t) => String(t).replace(/[&<>"]/g, (c) => ({ '&': '&amp;', '<': '&lt;', '>': '&gt;', '"': '&quot;' })[c]);
function showStatus() {
  const s = view.status;
  // sl_view says whether a daemon still publishes its status (GET /stats).
  const dds = bridgeStats && bridgeStats.dds;
  view.daemon = dds ? dds.daemon : null;
  const age = dds && dds.status_age_s >= 0 ? `status ${dds.status_age_s.toFixed(1)} s old` : 'no status yet';
  const daemonRow = ['daemon', dds && !dds.daemon ? `<span class="bad">no daemon</span> (${age})` : (dds ? age : '-')];
  if (!s) {
    if (dds) document.getElementById('status').innerHTML = `<tr><td>${daemonRow[0]}</td><td>${daemonRow[1]}</td></tr>`;
    return;
  }
  const gone = dds && !dds.daemon;
  const rows = [
    daemonRow,
    ['state', gone ? `<span class="bad">unknown</span> (last seen: ${s.state})`
      : `<span class="${s.state === 'error' ? 'bad' : 'ok'}">${s.state}</span>`],
    ['pattern', esc(s.pattern)],
    ['scans', `${s.scans_done} of ${s.scans_requested || 'continuous'}`],
    ['scan rate', `${s.scan_rate_hz.toFixed(2)} Hz`], ['frame rate', `${s.frame_rate_hz.toFixed(1)} Hz`],
    ['frames dropped', `${s.frames_dropped} (queue full ${s.frames_overflow}, unmatched ${s.frames_unmatched})`],
    ['sets dropped', `${s.sets_dropped} (queue full ${s.sets_overflow}, write timed out ${s.writes_timed_out}, not recorded ${s.sets_not_recorded})`],
    ['sets incomplete', s.sets_incomplete], ['cameras', esc(s.cameras.join(', '))],
    ['last error', s.last_error ? `<span class="bad">${esc(s.last_error)}</span>` : '-'],
  ];
  if (bridgeStats) rows.push(['viewer drops', `${bridgeStats.dropped} of ${bridgeStats.published + 0} (bridge, all viewers)`]);
  if (dds && dds.topics) {
    // What sl_view's DDS readers missed: clouds the daemon published while
    // they were read but never taken (overwritten in the keep-last history,
    // or lost with a fragment), and Cyclone's own lost / rejected counts.
    const lost = dds.topics.reduce((n, t) => n + t.lost, 0), rejected = dds.topics.reduce((n, t) => n + t.rejected, 0);
    rows.push(['DDS readers', `${dds.reliable ? 'reliable' : 'best-effort'}; clouds missed ${dds.clouds_missed} of ${dds.clouds_published_while_read}` +
      ` published while viewed; samples lost ${lost}, rejected ${rejected}`]);
  }
  document.getElementById('status').innerHTML =
    rows.map(([k, v]) => `<tr><td>${k}</td><td>${v}</td></tr>`).join('');
  const sel = document.getElementById('pattern');
  if (sel.options.length !== s.patterns.length) sel.innerHTML = s.patterns.map((p) => `<option>${esc(p)}</option>`).join('');
  if (document.activeElement !== sel) sel.value = s.pattern;
}
setInterval(async () => {
  try { bridgeStats = await (await fetch('/stats')).json(); showStatus(); } catch { /* bridge gone */ }
}, 1000);

// --- the bridge -------------------------------------------------------------------
let ws, service = null, nextCall = 1;
const subscriptions = new Map();
function connect() {
  ws = new WebSocket(`ws://${location.host}/`, ['foxglove.websocket.v1']);
  ws.binaryType = 'arraybuffer';
  const conn = document.getElementById('conn');
  ws.onopen = () => { view.connected = true; conn.textContent = 'connected'; conn.className = 'ok'; };
  ws.onclose = () => { view.connected = false; conn.textContent = 'disconnected'; conn.className = 'bad'; setTimeout(connect, 1000); };
  ws.onmessage = (e) => {
    if (typeof e.data === 'string') {
      const m = JSON.parse(e.data);
      if (m.op === 'advertise') {
        const subs = [];
        for (const c of m.channels) {
          const kind = c.topic.endsWith('/points/preview') ? 'cloud' : c.topic.endsWith('/status') ? 'status' : null;
          if (!kind) continue;
          const id = subscriptions.size + subs.length;
          subscriptions.set(id, kind);
          subs.push({ id, channelId: c.id });
        }
        ws.send(JSON.stringify({ op: 'subscribe', subscriptions: subs }));
      } else if (m.op === 'advertiseServices') {
        service = m.services.find((s) => s.name.endsWith('/command')) ?? null;
      } else if (m.op === 'serviceCallFailure') {
        showReply({ accepted: false, reason: m.message });
      }
      return;
    }
    const buf = new Uint8Array(e.data), dv = new DataView(e.data);
    if (buf[0] === 0x01) {
      const kind = subscriptions.get(dv.getUint32(1, true));
      const payload = buf.subarray(13);
      if (kind === 'cloud') { view.clouds++; lastCloud = readCloud(payload); showCloud(lastCloud); }
      else if (kind === 'status') { view.status = readStatus(payload); showStatus(); }
    } else if (buf[0] === 0x03) {
      const encLen = dv.getUint32(9, true);
      showReply(JSON.parse(new TextDecoder().decode(buf.subarray(13 + encLen))));
    }
  };
}
function showReply(r) {
  view.replies.push(r);
  const el = document.getElementById('reply');
  el.className = r.accepted ? 'ok' : 'bad';
  el.textContent = r.accepted ? `${r.command ?? 'request'}: accepted` : `rejected: ${r.reason || r.code}`;
}
function request(body) {
  if (!service || ws.readyState !== WebSocket.OPEN) { showReply({ accepted: false, reason: 'not connected to sl_view' }); return; }
  const json = new TextEncoder().encode(JSON.stringify(body)), enc = new TextEncoder().encode('json');
  const msg = new Uint8Array(13 + enc.length + json.length), dv = new DataView(msg.buffer);
  msg[0] = 0x02; dv.setUint32(1, service.id, true); dv.setUint32(5, nextCall++, true); dv.setUint32(9, enc.length, true);
  msg.set(enc, 13); msg.set(json, 13 + enc.length);
  ws.send(msg);
}
document.getElementById('start').onclick = () => request({ command: 'start', count: 0 });
document.getElementById('stop').onclick = () => request({ command: 'stop' });
document.getElementById('scan').onclick = () => request({ command: 'scan', count: 1 });
document.getElementById('setpattern').onclick = () =>
  request({ command: 'set_pattern', pattern: document.getElementById('pattern').value });
connect();
