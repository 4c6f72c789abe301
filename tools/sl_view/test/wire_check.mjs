// Independent check of the ROS 2 wire format (issue 18). Decodes the
// daemon's clouds, depth and shading images, camera info and status, taken
// either from sl_view's Foxglove WebSocket bridge or from an MCAP file
// written by `sl_view record`, with Foxglove's ROS 2 CDR deserializer
// (@foxglove/rosmsg2-serialization) and the standard ROS 2 message
// definitions (@foxglove/rosmsg-msgs-common, Humble), and compares every
// field and the point / pixel data, byte for byte, with what Cyclone DDS
// delivered to tests/view/view_reference (the project's own IDL types).
// It also checks that the schemas the bridge advertises / the file carries
// have exactly the standard definitions' fields, and the MCAP file's
// summary (statistics, chunk indexes) with @mcap/core's indexed reader.
//
//   node wire_check.mjs --ref DIR --ws ws://127.0.0.1:PORT --ns NS --count N
//   node wire_check.mjs --ref DIR --mcap FILE --ns NS --count N
import fs from 'node:fs';
import { setTimeout as sleep } from 'node:timers/promises';
import WebSocket from 'ws';
import { MessageReader } from '@foxglove/rosmsg2-serialization';
import { parse } from '@foxglove/rosmsg';
import { ros2humble } from '@foxglove/rosmsg-msgs-common';
import { McapIndexedReader } from '@mcap/core';
import { decompress as zstdDecompress } from 'fzstd';
import lz4 from 'lz4js';

const args = Object.fromEntries(process.argv.slice(2).reduce((a, v, i, all) =>
  (v.startsWith('--') ? [...a, [v.slice(2), all[i + 1]]] : a), []));
const ns = args.ns ?? 'sl';
const count = Number(args.count ?? 1);
const refDir = args.ref;
let failures = 0;
function fail(what) { failures++; console.error(`FAIL: ${what}`); }
function check(cond, what) { if (!cond) fail(what); return cond; }

// --- the standard definitions -----------------------------------------------
const kTypes = {
  points: 'sensor_msgs/msg/PointCloud2', depth: 'sensor_msgs/msg/Image',
  shading: 'sensor_msgs/msg/Image', camera_info: 'sensor_msgs/msg/CameraInfo',
  status: 'sl_msgs/msg/Status',
};
const kTopics = {
  [`/${ns}/points`]: 'points', [`/${ns}/depth/image`]: 'depth', [`/${ns}/shading/image`]: 'shading',
  [`/${ns}/camera_info`]: 'camera_info', [`/${ns}/status`]: 'status',
};
const shortName = (t) => t.replace('/msg/', '/');
function standardDefinitions(type) {  // root first, then every type it uses
  const out = [];
  const visit = (name) => {
    if (out.some((d) => d.name === name)) return;
    const def = ros2humble[name];
    if (!def) throw new Error(`no standard definition of ${name}`);
    out.push(def);
    for (const f of def.definitions) if (f.isComplex) visit(f.type);
  };
  visit(shortName(type));
  return out;
}
const fieldsOf = (def) => def.definitions.filter((f) => !f.isConstant)
  .map((f) => `${f.type}${f.isArray ? `[${f.arrayLength ?? ''}]` : ''} ${f.name}`).join('; ');

// The schema text against the standard definitions: same types, same fields.
function checkSchema(type, schemaText, where) {
  const parsed = parse(schemaText, { ros2: true });
  if (!type.startsWith('sensor_msgs/')) return parsed;  // sl_msgs: no standard definition
  const std = standardDefinitions(type);
  // builtin_interfaces/Time is the standard definitions' primitive `time`
  // (the parser maps fields of that type to it): check it separately.
  const time = parsed.find((d) => d.name === 'builtin_interfaces/Time');
  if (time) check(fieldsOf(time) === 'int32 sec; uint32 nanosec', `${where}: Time is ${fieldsOf(time)}`);
  const rest = parsed.filter((d) => d !== time);
  check(rest.length === std.length, `${where}: ${rest.length} definitions, standard ${std.length}`);
  for (const s of std) {
    const p = s === std[0] ? parsed[0] : parsed.find((d) => d.name === s.name);
    if (!check(p, `${where}: schema lacks ${s.name}`)) continue;
    check(fieldsOf(p) === fieldsOf(s), `${where}: ${s.name} fields\n  got  ${fieldsOf(p)}\n  want ${fieldsOf(s)}`);
  }
  return parsed;
}

const readers = {};
function readerFor(kind, schemaText) {
  if (!readers[kind]) {
    readers[kind] = kind === 'status'
      ? new MessageReader(parse(schemaText, { ros2: true }))  // the project's own type
      : new MessageReader(standardDefinitions(kTypes[kind]));
  }
  return readers[kind];
}

// --- the reference ----------------------------------------------------------
async function reference(kind, stamp) {
  const stem = `${refDir}/${kind}_${stamp.sec}_${stamp.nanosec}`;
  for (let i = 0; i < 300; i++) {
    try {
      const json = JSON.parse(fs.readFileSync(`${stem}.json`, 'utf8'));
      const data = json.data_length !== undefined ? fs.readFileSync(`${stem}.bin`) : undefined;
      return { json, data };
    } catch {
      // The status writer is reliable keep-last 1: a sample the reference
      // had not yet taken when the next one was written is replaced in the
      // writer's history, so a reader may legitimately never see it. It is
      // superseded once the reference holds a later status (looked at after
      // 1 s, so that a file still being written is not taken for a gap).
      if (kind === 'status' && i >= 10 && laterStatusIn(stamp)) return { superseded: true };
      await sleep(100);
    }
  }
  return undefined;
}

function laterStatusIn(stamp) {
  const ns = BigInt(stamp.sec) * 1000000000n + BigInt(stamp.nanosec);
  return fs.readdirSync(refDir).some((f) => {
    const m = /^status_(\d+)_(\d+)\.json$/.exec(f);
    return m && BigInt(m[1]) * 1000000000n + BigInt(m[2]) > ns;
  });
}

function compare(path, got, want) {
  if (want !== null && typeof want === 'object' && !Array.isArray(want)) {
    for (const k of Object.keys(want)) if (k !== 'data_length') compare(`${path}.${k}`, got?.[k], want[k]);
    return;
  }
  if (Array.isArray(want)) {
    const g = Array.from(got ?? []);
    if (!check(g.length === want.length, `${path}: length ${g.length}, daemon ${want.length}`)) return;
    want.forEach((w, i) => compare(`${path}[${i}]`, g[i], w));
    return;
  }
  const g = typeof got === 'bigint' ? Number(got) : typeof got === 'boolean' && typeof want === 'number' ? Number(got) : got;
  check(g === want, `${path}: ${JSON.stringify(g)}, daemon ${JSON.stringify(want)}`);
}

const compared = { points: 0, depth: 0, shading: 0, camera_info: 0, status: 0 };
let superseded = 0;  // status samples replaced before the reference took them
async function checkMessage(kind, bytes, schemaText, where) {
  const msg = readerFor(kind, schemaText).readMessage(bytes);
  const stamp = kind === 'status' ? msg.stamp : msg.header.stamp;
  const ref = await reference(kind, stamp);
  if (!check(ref, `${where}: ${kind} stamped ${stamp.sec}.${stamp.nanosec} never reached the reference subscriber`)) return;
  if (ref.superseded) { superseded++; return; }
  compare(`${where} ${kind}`, msg, ref.json);
  if (ref.data) {
    const data = Buffer.from(msg.data.buffer, msg.data.byteOffset, msg.data.byteLength);
    check(data.length === ref.data.length && data.equals(ref.data),
      `${where} ${kind}: data (${data.length} bytes) differs from the daemon's (${ref.data.length})`);
  }
  if (kind === 'points') {
    // The point data read through the message's own field table.
    const off = Object.fromEntries(msg.fields.map((f) => [f.name, f]));
    check(['x', 'y', 'z', 'intensity'].every((n) => off[n]?.datatype === 7), `${where}: fields ${msg.fields.map((f) => f.name)}`);
    const view = new DataView(msg.data.buffer, msg.data.byteOffset, msg.data.byteLength);
    let valid = 0, zmin = Infinity, zmax = -Infinity;
    for (let i = 0; i < msg.width * msg.height; i++) {
      const z = view.getFloat32(i * msg.point_step + off.z.offset, !msg.is_bigendian);
      if (Number.isFinite(z)) { valid++; zmin = Math.min(zmin, z); zmax = Math.max(zmax, z); }
    }
    check(valid > 0.5 * msg.width * msg.height, `${where}: only ${valid} finite points`);
    console.log(`${where}: cloud ${msg.width}x${msg.height}, ${valid} finite points, z ${zmin.toFixed(3)}..${zmax.toFixed(3)} m`);
  }
  compared[kind]++;
}

// --- from the bridge ----------------------------------------------------------
async function fromBridge(url) {
  const ws = new WebSocket(url, ['foxglove.websocket.v1']);
  ws.binaryType = 'nodebuffer';
  const channels = new Map(), subs = new Map(), services = new Map(), pending = [];
  const got = { points: 0, depth: 0, shading: 0, camera_info: 0, status: 0 };
  let reply, done = false;
  await new Promise((resolve, reject) => {
    const timer = setTimeout(() => reject(new Error(`bridge: timeout, received ${JSON.stringify(got)}`)), 60000);
    ws.on('error', reject);
    ws.on('message', (data, binary) => {
      if (!binary) {
        const m = JSON.parse(data.toString());
        if (m.op === 'advertise') {
          const subscriptions = [];
          for (const c of m.channels) {
            channels.set(c.id, c);
            const kind = kTopics[c.topic];
            if (!kind) continue;
            check(c.encoding === 'cdr' && c.schemaEncoding === 'ros2msg' && c.schemaName === kTypes[kind],
              `bridge: ${c.topic} advertised as ${c.encoding}/${c.schemaEncoding}/${c.schemaName}`);
            checkSchema(kTypes[kind], c.schema, `bridge ${c.topic}`);
            subs.set(subscriptions.length, c);
            subscriptions.push({ id: subscriptions.length, channelId: c.id });
          }
          check(subscriptions.length === 5, `bridge: advertised ${subscriptions.length} of the 5 topics`);
          ws.send(JSON.stringify({ op: 'subscribe', subscriptions }));
        } else if (m.op === 'advertiseServices') {
          const svc = m.services.find((s) => s.name === `/${ns}/command`);
          if (!check(svc, 'bridge: no command service')) return;
          services.set(svc.id, svc);
          const payload = Buffer.from(JSON.stringify({ command: 'start', count: 0 }));
          const head = Buffer.alloc(13);
          head[0] = 0x02; head.writeUInt32LE(svc.id, 1); head.writeUInt32LE(1, 5); head.writeUInt32LE(4, 9);
          setTimeout(() => ws.send(Buffer.concat([head, Buffer.from('json'), payload])), 300);
        } else if (m.op === 'serviceCallFailure') {
          reject(new Error(`bridge: scan request failed: ${m.message}`));
        }
        return;
      }
      if (data[0] === 0x03) {
        if (reply) return;  // the stop's reply
        reply = JSON.parse(data.subarray(17).toString());
        if (!reply.accepted) reject(new Error(`bridge: scan rejected: ${reply.reason}`));
        return;
      }
      if (data[0] !== 0x01) return;
      const c = subs.get(data.readUInt32LE(1));
      const kind = kTopics[c.topic];
      // Only samples of the requested scans (status: after the reply), and
      // none after the check has what it needs (the scan is being stopped).
      if (!reply || done) return;
      if (kind === 'status' && got.status >= 3) return;
      got[kind]++;
      pending.push(checkMessage(kind, new Uint8Array(data.subarray(13)), c.schema, 'bridge'));
      if (got.points >= count && got.depth >= count && got.shading >= count && got.camera_info >= count && got.status >= 1) {
        clearTimeout(timer);
        done = true;
        resolve();
      }
    });
  });
  // Stop the continuous scan through the same service.
  const svc = [...services.values()][0];
  const payload = Buffer.from(JSON.stringify({ command: 'stop' }));
  const head = Buffer.alloc(13);
  head[0] = 0x02; head.writeUInt32LE(svc.id, 1); head.writeUInt32LE(2, 5); head.writeUInt32LE(4, 9);
  ws.send(Buffer.concat([head, Buffer.from('json'), payload]));
  await sleep(300);
  ws.close();
  await Promise.all(pending);
}

// --- from an MCAP file ----------------------------------------------------------
async function fromMcap(file) {
  const fd = await fs.promises.open(file, 'r');
  const size = BigInt((await fd.stat()).size);
  const readable = {
    size: async () => size,
    read: async (offset, length) => {
      const buf = Buffer.alloc(Number(length));
      await fd.read(buf, 0, Number(length), Number(offset));
      return buf;
    },
  };
  const reader = await McapIndexedReader.Initialize({
    readable,
    decompressHandlers: {
      zstd: (buf, n) => zstdDecompress(buf, new Uint8Array(Number(n))),
      lz4: (buf) => Uint8Array.from(lz4.decompress(buf)),
    },
  });
  check(reader.header.profile === 'ros2', `mcap: profile '${reader.header.profile}'`);
  check(reader.chunkIndexes.length > 0, 'mcap: no chunk indexes');
  const stats = reader.statistics;
  check(stats !== undefined, 'mcap: no statistics');
  const schemaOf = new Map();
  for (const [id, ch] of reader.channelsById) {
    const schema = reader.schemasById.get(ch.schemaId);
    const kind = kTopics[ch.topic];
    check(ch.messageEncoding === 'cdr' && schema.encoding === 'ros2msg', `mcap: ${ch.topic} is ${ch.messageEncoding}/${schema.encoding}`);
    if (!kind) continue;
    check(schema.name === kTypes[kind], `mcap: ${ch.topic} schema ${schema.name}`);
    const text = new TextDecoder().decode(schema.data);
    checkSchema(kTypes[kind], text, `mcap ${ch.topic}`);
    schemaOf.set(id, text);
  }
  let n = 0;
  const counts = {};
  for await (const m of reader.readMessages({ validateCrcs: true })) {
    n++;
    const ch = reader.channelsById.get(m.channelId);
    counts[ch.topic] = (counts[ch.topic] ?? 0) + 1;
    const kind = kTopics[ch.topic];
    if (kind) await checkMessage(kind, m.data, schemaOf.get(m.channelId), 'mcap');
  }
  check(BigInt(n) === stats.messageCount, `mcap: read ${n} messages, statistics say ${stats.messageCount}`);
  for (const [id, c] of stats.channelMessageCounts)
    check(BigInt(counts[reader.channelsById.get(id).topic] ?? 0) === c, `mcap: channel ${id} count`);
  check((counts[`/${ns}/points`] ?? 0) === count, `mcap: ${counts[`/${ns}/points`] ?? 0} clouds, expected ${count}`);
  console.log(`mcap: ${n} messages in ${reader.chunkIndexes.length} chunks (${reader.chunkIndexes[0]?.compression || 'none'}): ${JSON.stringify(counts)}`);
  await fd.close();
}

try {
  if (args.ws) await fromBridge(args.ws);
  if (args.mcap) await fromMcap(args.mcap);
} catch (e) {
  fail(e.message);
}
// Every kind `count` times: from the bridge at least (the scan runs on while
// the check finishes), from an MCAP file exactly (`sl_view record --count N`
// ends with the N-th scan's images and camera_info, and leaves out the next
// scan's).
for (const k of ['points', 'depth', 'shading', 'camera_info']) {
  check(args.mcap ? compared[k] === count : compared[k] >= count,
    `${k}: ${compared[k]} compared, expected ${args.mcap ? '' : 'at least '}${count}`);
}
check(compared.status >= 1, 'no status compared');
console.log(`compared with the daemon's samples: ${JSON.stringify(compared)}` +
  (superseded ? `; ${superseded} status sample(s) superseded before the reference took them` : ''));
if (failures) { console.error(`${failures} failures`); process.exit(1); }
console.log('ok: every field and the data bytes match');
