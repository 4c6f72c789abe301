// The daemon in ROS 2's graph (issue 31 items 3-5) as a ROS 2 node would see
// it: /tf_static, /diagnostics and ros_discovery_info taken off the wire by
// tests/ros2/ros2_graph_listener (bytes only) and decoded here with
// Foxglove's ROS 2 deserializer (@foxglove/rosmsg2-serialization) and the
// standard Humble definitions (@foxglove/rosmsg-msgs-common; rmw_dds_common,
// which that package lacks, from the .msg text of ros2/rmw_dds_common's
// humble branch below), never with the daemon's types. Checks:
//   - the writers' DDS type names and QoS as DDS discovery announces them
//     (tf_static and ros_discovery_info reliable + transient-local,
//     diagnostics reliable + volatile) and the DDS topic names (rt/tf_static,
//     rt/diagnostics, ros_discovery_info without "rt/");
//   - /tf_static, taken by a late joiner: parent -> base = the configured
//     mount (xyz, rpy as tf2's setRPY), base -> the camera's optical frame =
//     the REP 103 optical rotation, the camera -> the projector = the
//     inverse of the simulated rig's projector_pose (config/sim.yaml);
//   - /diagnostics at 1 Hz: one status per camera, one for the trigger
//     source and one for the pipeline, named "sl_sensord: ...", levels OK
//     while idle and while scanning, the pipeline's keys with the values of
//     the daemon's state (scans_done grows, scan_rate_hz > 0 once scanning);
//   - ros_discovery_info: the participant's gid (its GUID + 8 zero bytes, as
//     Humble's 24-byte gid), one node /<ns>/sl_sensord whose writer gids are
//     every writer of the daemon's participant that discovery shows (the
//     points writer among them) except the ros_discovery_info writer.
//   node ros2_graph_check.mjs SOURCE_DIR DAEMON_EXE LISTENER_EXE SLCTL_EXE WORK_DIR
import fs from 'node:fs';
import path from 'node:path';
import readline from 'node:readline';
import { spawn, spawnSync } from 'node:child_process';
import { MessageReader } from '@foxglove/rosmsg2-serialization';
import { parse } from '@foxglove/rosmsg';
import { ros2humble } from '@foxglove/rosmsg-msgs-common';

const [src, daemonExe, listenerExe, slctlExe, work] = process.argv.slice(2);
let failures = 0, checks = 0;
const check = (c, what) => { checks++; if (!c) { failures++; console.error(`FAIL: ${what}`); } return c; };
const near = (a, b, tol = 1e-9) => Math.abs(a - b) <= tol;

// --- definitions --------------------------------------------------------------
const SEPARATOR = `\n${'='.repeat(80)}\n`;
function standard(type) {  // root first, then every type it uses
  const out = [];
  const visit = (name) => {
    if (out.some((d) => d.name === name)) return;
    const def = ros2humble[name];
    if (!def) throw new Error(`no standard definition of ${name}`);
    out.push(def);
    for (const f of def.definitions) if (f.isComplex) visit(f.type);
  };
  visit(type);
  return out;
}
// ros2/rmw_dds_common, branch humble (1.6.x): msg/ParticipantEntitiesInfo.msg,
// msg/NodeEntitiesInfo.msg, msg/Gid.msg, verbatim.
const rmwDdsCommon = parse([
  'Gid gid\nNodeEntitiesInfo[] node_entities_info_seq',
  'MSG: rmw_dds_common/NodeEntitiesInfo\nstring<=256 node_namespace\nstring<=256 node_name\n' +
    'Gid[] reader_gid_seq\nGid[] writer_gid_seq',
  'MSG: rmw_dds_common/Gid\nchar[24] data',
].join(SEPARATOR), { ros2: true });
const readers = {
  'rt/tf_static': new MessageReader(standard('tf2_msgs/TFMessage')),
  'rt/diagnostics': new MessageReader(standard('diagnostic_msgs/DiagnosticArray')),
  ros_discovery_info: new MessageReader(rmwDdsCommon),
};

// --- the daemon, configured with a mount pose ------------------------------------
const ns = `graph_${process.pid}_${Math.floor(Math.random() * 1e6)}`;
const mount = { parent: 'test_robot_flange', base: 'test_sensor_base', xyz: [0.12, -0.05, 0.3], rpy: [0.1, -0.2, 0.3] };
const sim = fs.readFileSync(path.join(src, 'config/sim.yaml'), 'utf8');
// The graph topics are global (not under the namespace): a DDS domain of the
// test's own keeps other daemons on this machine out of what it hears.
const domain = 100 + (process.pid % 120);
const withNs = sim.replace(/^ {2}namespace: sl$/m, `  namespace: ${ns}`)
  .replace(/^ {2}domain_id: 0$/m, `  domain_id: ${domain}`);
check(withNs.includes(`  domain_id: ${domain}`), 'set dds.domain_id in a copy of config/sim.yaml');
check(withNs !== sim, 'set dds.namespace in a copy of config/sim.yaml');
const frameId = /^ {2}frame_id: (\S+)$/m.exec(sim)?.[1];
check(frameId, 'dds.frame_id in config/sim.yaml');
const config = withNs.replace(/^dds:\n/m, `dds:\n  tf:\n    parent_frame: ${mount.parent}\n` +
  `    base_frame: ${mount.base}\n    mount: {xyz: [${mount.xyz}], rpy: [${mount.rpy}]}\n`);
fs.writeFileSync(path.join(work, 'graph.yaml'), config);

// The simulated rig's projector pose: X_p = R X_c + t, R = Rz Ry Rx from
// rotation_deg [rx, ry, rz] (config/sim.yaml's comment).
const pose = /projector_pose: \{rotation_deg: \[([^\]]*)\], translation_mm: \[([^\]]*)\]\}/.exec(sim);
check(pose, 'sim.rig.calibration.projector_pose in config/sim.yaml');
const [rx, ry, rz] = pose[1].split(',').map((v) => Number(v) * Math.PI / 180);
const tMm = pose[2].split(',').map(Number);

// --- small rotation algebra (independent of the daemon's Eigen) --------------------
const qmul = (a, b) => [  // [x, y, z, w]
  a[3] * b[0] + a[0] * b[3] + a[1] * b[2] - a[2] * b[1],
  a[3] * b[1] - a[0] * b[2] + a[1] * b[3] + a[2] * b[0],
  a[3] * b[2] + a[0] * b[1] - a[1] * b[0] + a[2] * b[3],
  a[3] * b[3] - a[0] * b[0] - a[1] * b[1] - a[2] * b[2]];
const qaxis = (axis, angle) => { const q = [0, 0, 0, Math.cos(angle / 2)]; q[axis] = Math.sin(angle / 2); return q; };
const qconj = (q) => [-q[0], -q[1], -q[2], q[3]];
const qrot = (q, v) => qmul(qmul(q, [...v, 0]), qconj(q)).slice(0, 3);
const sameRotation = (a, b, tol) => [1, -1].some((s) => a.every((v, i) => near(v, s * b[i], tol)));
const fromRpy = ([r, p, y]) => qmul(qmul(qaxis(2, y), qaxis(1, p)), qaxis(0, r));  // tf2 setRPY

const expected = new Map();
expected.set(mount.base, { parent: mount.parent, t: mount.xyz, q: fromRpy(mount.rpy) });
// REP 103: an optical frame (x right, y down, z forward) in a body frame
// (x forward, y left, z up) is roll -90 deg, yaw -90 deg.
expected.set(frameId, { parent: mount.base, t: [0, 0, 0], q: fromRpy([-Math.PI / 2, 0, -Math.PI / 2]) });
const qCamToProj = qmul(qmul(qaxis(2, rz), qaxis(1, ry)), qaxis(0, rx));  // R
const qProjInCam = qconj(qCamToProj);  // R^T
expected.set('sl_projector_optical_frame',
  { parent: frameId, t: qrot(qProjInCam, tMm).map((v) => -v / 1000), q: qProjInCam });

// --- run ---------------------------------------------------------------------
function spawnLines(exe, args, name) {
  const proc = spawn(exe, args, { stdio: ['ignore', 'pipe', 'pipe'] });
  const lines = [];
  const log = fs.createWriteStream(path.join(work, `${name}.log`));
  // stdout and stderr both: the daemon logs to stderr, the listener's
  // stderr says why it failed.
  for (const stream of [proc.stdout, proc.stderr])
    readline.createInterface({ input: stream }).on('line', (l) => { lines.push(l); log.write(`${l}\n`); });
  const exited = new Promise((r) => proc.on('exit', (code) => r(code)));
  return { proc, lines, exited };
}
const sleep = (ms) => new Promise((r) => setTimeout(r, ms));
async function until(cond, ms, what) {
  const end = Date.now() + ms;
  while (!cond()) {
    if (Date.now() > end) throw new Error(`no ${what} within ${ms} ms`);
    await sleep(50);
  }
}

const daemon = spawnLines(daemonExe, ['--config', path.join(work, 'graph.yaml')], 'daemon');
let listener;
try {
  await until(() => daemon.lines.some((l) => l.includes('ready:')) || daemon.proc.exitCode !== null, 30000,
    'daemon "ready:"');
  if (daemon.proc.exitCode !== null) throw new Error(`sl_sensord exited (${daemon.proc.exitCode})`);
  await sleep(1500);  // /tf_static and ros_discovery_info are written before the listener exists
  listener = spawnLines(listenerExe, ['11', String(domain)], 'listener');
  const diagnosticsCount = () => listener.lines.filter((l) => l.startsWith('sample rt/diagnostics ')).length;
  await until(() => diagnosticsCount() >= 3, 8000, 'three /diagnostics samples while idle');
  const idleCount = diagnosticsCount();
  const start = spawnSync(slctlExe, ['--domain', String(domain), '--ns', ns, 'start'], { encoding: 'utf8', timeout: 15000 });
  check(start.status === 0, `slctl start: exit ${start.status} ${start.stderr}`);
  const code = await listener.exited;
  check(code === 0, `ros2_graph_listener exit code ${code}`);

  // --- decode --------------------------------------------------------------------
  const samples = [], writers = [];
  for (const l of listener.lines) {
    const w = l.split(' ');
    if (w[0] === 'sample') {
      const bytes = Buffer.from(w[3], 'hex');
      check(bytes[0] === 0 && bytes[1] === 1, `${w[1]}: encapsulation CDR_LE (00 01), got ${w[3].slice(0, 4)}`);
      samples.push({ topic: w[1], received_ns: BigInt(w[2]), msg: readers[w[1]].readMessage(bytes) });
    } else if (w[0] === 'writer') {
      writers.push({ topic: w[1], type: w[2], guid: w[3], participant: w[4], reliability: w[5], durability: w[6] });
    }
  }
  const of = (topic) => samples.filter((s) => s.topic === topic);

  // --- the writers as discovery announces them --------------------------------------
  const pointsWriter = writers.find((w) => w.topic === `rt/${ns}/points`);
  if (!check(pointsWriter, `DCPSPublication: a writer of rt/${ns}/points`)) throw new Error('no daemon');
  const daemonWriters = writers.filter((w) => w.participant === pointsWriter.participant);
  const qosOf = { 'rt/tf_static': ['tf2_msgs::msg::dds_::TFMessage_', 'transient_local'],
    'rt/diagnostics': ['diagnostic_msgs::msg::dds_::DiagnosticArray_', 'volatile'],
    ros_discovery_info: ['rmw_dds_common::msg::dds_::ParticipantEntitiesInfo_', 'transient_local'] };
  for (const [topic, [type, durability]] of Object.entries(qosOf)) {
    const w = daemonWriters.filter((x) => x.topic === topic);
    if (!check(w.length === 1, `one daemon writer of ${topic}, found ${w.length}`)) continue;
    check(w[0].type === type, `${topic}: type ${w[0].type}, expected ${type}`);
    check(w[0].reliability === 'reliable', `${topic}: ${w[0].reliability}, expected reliable`);
    check(w[0].durability === durability, `${topic}: ${w[0].durability}, expected ${durability}`);
  }

  // --- /tf_static --------------------------------------------------------------------
  const tf = of('rt/tf_static');
  if (check(tf.length === 1, `one /tf_static sample for a late joiner, got ${tf.length}`)) {
    const transforms = tf[0].msg.transforms;
    check(transforms.length === expected.size, `${transforms.length} transforms, expected ${expected.size}`);
    for (const t of transforms) {
      const e = expected.get(t.child_frame_id);
      if (!check(e, `unexpected child frame ${t.child_frame_id}`)) continue;
      const where = `${t.header.frame_id} -> ${t.child_frame_id}`;
      check(t.header.frame_id === e.parent, `${t.child_frame_id}: parent ${t.header.frame_id}, expected ${e.parent}`);
      const tr = t.transform.translation, r = t.transform.rotation;
      check([tr.x, tr.y, tr.z].every((v, i) => near(v, e.t[i], 1e-9)),
        `${where}: translation ${[tr.x, tr.y, tr.z]}, expected ${e.t}`);
      check(sameRotation([r.x, r.y, r.z, r.w], e.q, 1e-9), `${where}: rotation ${[r.x, r.y, r.z, r.w]}, expected ${e.q}`);
      const stampS = t.header.stamp.sec + t.header.stamp.nanosec * 1e-9;
      check(Math.abs(stampS - Date.now() / 1000) < 120, `${where}: stamp ${stampS} is not about now`);
      console.log(`ok: ${where} t=[${[tr.x, tr.y, tr.z].map((v) => v.toFixed(5))}] ` +
        `q=[${[r.x, r.y, r.z, r.w].map((v) => v.toFixed(5))}]`);
    }
  }

  // --- /diagnostics ------------------------------------------------------------------
  const diag = of('rt/diagnostics');
  check(diag.length >= 8, `${diag.length} /diagnostics samples in 11 s, expected >= 8 at 1 Hz`);
  const stamps = diag.map((s) => s.msg.header.stamp.sec + s.msg.header.stamp.nanosec * 1e-9);
  // A fixed 1 s schedule: single periods jitter with the machine's load,
  // their mean does not drift.
  for (let i = 1; i < stamps.length; i++)
    check(stamps[i] - stamps[i - 1] > 0.5 && stamps[i] - stamps[i - 1] < 2,
      `diagnostics period ${(stamps[i] - stamps[i - 1]).toFixed(3)} s, expected about 1 s`);
  const meanPeriod = (stamps[stamps.length - 1] - stamps[0]) / (stamps.length - 1);
  check(meanPeriod > 0.95 && meanPeriod < 1.1, `mean diagnostics period ${meanPeriod.toFixed(3)} s, expected 1 s`);
  console.log(`ok: ${diag.length} /diagnostics, mean period ${meanPeriod.toFixed(3)} s`);
  const names = ['sl_sensord: camera sim_top', 'sl_sensord: trigger source', 'sl_sensord: pipeline'];
  const value = (status, key) => status.values.find((kv) => kv.key === key)?.value;
  for (const [i, s] of diag.entries()) {
    const statuses = s.msg.status;
    check(JSON.stringify(statuses.map((x) => x.name)) === JSON.stringify(names),
      `diagnostics ${i}: statuses ${statuses.map((x) => x.name)}, expected ${names}`);
    for (const x of statuses) check(x.level === 0, `diagnostics ${i}: ${x.name} level ${x.level} (${x.message}), expected OK`);
  }
  const pipeline = (s) => s.msg.status[2];
  const idle = diag.slice(0, idleCount).map(pipeline);
  for (const p of idle) {
    check(p.message === 'idle' && value(p, 'state') === 'idle', `idle pipeline: message '${p.message}', state ${value(p, 'state')}`);
    check(value(p, 'scans_done') === '0', `idle pipeline: scans_done ${value(p, 'scans_done')}`);
  }
  check(diag[0].msg.status[0].hardware_id === 'sim_top', `camera hardware_id ${diag[0].msg.status[0].hardware_id}`);
  for (const key of ['pattern', 'scan_rate_hz', 'frame_rate_hz', 'frames_dropped', 'sets_dropped', 'latency_ms',
    'latency_max_ms', 'writes_timed_out', 'clouds_lost_to_readers', 'requests_received', 'degraded_reason', 'last_error'])
    check(value(pipeline(diag[0]), key) !== undefined, `pipeline status has no key '${key}'`);
  const scanning = diag.slice(idleCount).map(pipeline).filter((p) => value(p, 'state') === 'scanning');
  if (check(scanning.length >= 2, `${scanning.length} diagnostics while scanning, expected >= 2`)) {
    const last = scanning[scanning.length - 1];
    check(last.message.startsWith('scanning 3+3_horizontal at '), `scanning pipeline message '${last.message}'`);
    check(Number(value(last, 'scans_done')) > Number(value(scanning[0], 'scans_done')),
      `scans_done does not grow: ${value(scanning[0], 'scans_done')} -> ${value(last, 'scans_done')}`);
    check(Number(value(last, 'scan_rate_hz')) > 0, `scan_rate_hz ${value(last, 'scan_rate_hz')} while scanning`);
    check(Number(value(last, 'requests_received')) >= 1, `requests_received ${value(last, 'requests_received')}`);
    check(Number(value(last, 'latency_ms')) > 0, `latency_ms ${value(last, 'latency_ms')} while scanning`);
    console.log(`ok: diagnostics while scanning: '${last.message}', scans_done ${value(last, 'scans_done')}`);
  }

  // --- ros_discovery_info -----------------------------------------------------------
  const info = of('ros_discovery_info');
  if (check(info.length >= 1, `ros_discovery_info: ${info.length} samples for a late joiner`)) {
    const m = info[info.length - 1].msg;
    const hex = (gid) => Buffer.from(gid.data).toString('hex');
    const zeros = '0'.repeat(16);
    check(hex(m.gid) === pointsWriter.participant + zeros,
      `participant gid ${hex(m.gid)}, expected the participant GUID ${pointsWriter.participant} + 8 zero bytes`);
    if (check(m.node_entities_info_seq.length === 1, `${m.node_entities_info_seq.length} nodes, expected 1`)) {
      const node = m.node_entities_info_seq[0];
      check(node.node_namespace === `/${ns}` && node.node_name === 'sl_sensord',
        `node ${node.node_namespace} ${node.node_name}, expected /${ns} sl_sensord`);
      const listed = new Set(node.writer_gid_seq.map(hex));
      check(listed.has(pointsWriter.guid + zeros), `the points writer ${pointsWriter.guid} is not among the node's writers`);
      for (const w of daemonWriters) {
        const inList = listed.has(w.guid + zeros);
        if (w.topic === 'ros_discovery_info') check(!inList, 'the ros_discovery_info writer is listed as the node\'s');
        else check(inList, `the daemon's writer of ${w.topic} is not among the node's writers`);
      }
      check(listed.size === daemonWriters.length - 1,
        `${listed.size} writer gids, discovery shows ${daemonWriters.length - 1} writers of the daemon`);
      check(node.reader_gid_seq.length >= 1 && node.reader_gid_seq.every((g) => hex(g).endsWith(zeros) &&
        hex(g).startsWith(pointsWriter.participant.slice(0, 24))),
        `reader gids ${node.reader_gid_seq.map(hex)}: expected the daemon's readers (its GUID prefix + 8 zero bytes)`);
      console.log(`ok: node ${node.node_namespace}/${node.node_name}: ${listed.size} writers, ` +
        `${node.reader_gid_seq.length} readers`);
    }
  }
} catch (e) {
  check(false, e.message);
} finally {
  if (listener && listener.proc.exitCode === null) listener.proc.kill();
  daemon.proc.kill();
  await daemon.exited;
}
if (failures) {
  console.error(`--- daemon log (last lines)\n${daemon.lines.slice(-20).join('\n')}`);
  console.error(`ros2_graph_check: ${failures} of ${checks} checks failed`);
  process.exit(1);
}
console.log(`ros2_graph_check: all ${checks} checks passed`);
