// ros2/sl_msgs on the wire (issue 31): for every message and service
// request/response of the package, a sample with a distinct value in every
// field is serialized by Foxglove's ROS 2 serializer from the package's own
// .msg/.srv text (the standard types it uses from @foxglove/rosmsg-msgs-common,
// Humble), taken and written again by Cyclone DDS with the daemon's types
// (sl_msgs_cyclone_roundtrip, sl_idl generated from the same files by
// idl/ros2_to_dds_idl.py), and decoded by Foxglove's deserializer: every field
// must come back equal, Cyclone's bytes must be Foxglove's (up to the
// XCDR1 end padding), and each DDS type name must be the one rmw gives it
// (sl_msgs::msg::dds_::Status_, sl_msgs::srv::dds_::Start_Request_). A field
// the IDL lacks, an extra one, another type or order fails here. Service
// samples are framed as rmw_cyclonedds frames them (the daemon's service
// types): a request header (uint64 client guid, int64 sequence number) in
// front of the message, which must come back unchanged too.
//   node sl_msgs_wire.mjs ROUNDTRIP_EXE PACKAGE_DIR... (ros2/sl_msgs, idl/std_srvs)
import { spawnSync } from 'node:child_process';
import { MessageReader, MessageWriter } from '@foxglove/rosmsg2-serialization';
import { loadPackage } from './ros2_definitions.mjs';

const [roundTripExe, ...packageDirs] = process.argv.slice(2);
let failures = 0, checks = 0;
const check = (c, what) => { checks++; if (!c) { failures++; console.error(`FAIL: ${what}`); } return c; };

// --- the package's types and the standard ones they use ---------------------------
const roots = packageDirs.flatMap((dir) => loadPackage(dir).types);
check(roots.length >= 16, `${roots.length} types in ${packageDirs}`);
const definitionOf = (definitions, type) => definitions.find((d) => d.name === type);

// --- a sample with a distinct value in every field ---------------------------------
let counter = 0;
const valueOf = (type) => {
  const c = ++counter;
  switch (type) {
    case 'bool': return c % 2 === 1;
    case 'int8': return -((c % 100) + 1);
    case 'uint8': case 'byte': case 'char': return (c % 200) + 1;
    case 'int16': return -((c * 7) % 30000) - 1;
    case 'uint16': return ((c * 13) % 60000) + 1;
    case 'int32': return -(c * 1009 + 1);
    case 'uint32': return (c * 100003 + 1) >>> 0;
    case 'int64': return -(BigInt(c) * 1000000000007n + 3n);
    case 'uint64': return BigInt(c) * 10000000019n + 1n;
    case 'float32': return Math.fround(c + 0.25);
    case 'float64': return c + 0.125 + c * 1e-9;
    case 'string': return `v${c}` + 'x'.repeat(c % 5);  // lengths vary: alignment after strings
    case 'time': case 'duration': return { sec: c, nanosec: c * 1000 + 7 };
    default: throw new Error(`no value for type ${type}`);
  }
};
const sampleOf = (definitions, def = definitions[0]) => {
  const m = {};
  for (const f of def.definitions) {
    if (f.isConstant) continue;
    const one = () => (f.isComplex ? sampleOf(definitions, definitionOf(definitions, f.type)) : valueOf(f.type));
    if (f.isArray) {
      const n = f.arrayLength ?? 2 + (counter % 2);
      m[f.name] = Array.from({ length: n }, one);
    } else {
      m[f.name] = one();
    }
  }
  return m;
};
// Typed arrays (uint8[], float32[] as the reader gives them) as plain arrays.
const plain = (v) => {
  if (ArrayBuffer.isView(v)) return Array.from(v);
  if (Array.isArray(v)) return v.map(plain);
  if (v && typeof v === 'object') return Object.fromEntries(Object.entries(v).map(([k, x]) => [k, plain(x)]));
  return v;
};
const same = (a, b) => JSON.stringify(plain(a), (k, v) => (typeof v === 'bigint' ? `${v}n` : v)) ===
                       JSON.stringify(plain(b), (k, v) => (typeof v === 'bigint' ? `${v}n` : v));
const hex = (bytes) => Buffer.from(bytes).toString('hex');

// --- through Cyclone with the daemon's types ----------------------------------------
// rmw_cyclonedds's request header: little-endian uint64 guid, int64 seq.
const requestHeader = (i) => {
  const h = Buffer.alloc(16);
  h.writeBigUInt64LE(0x1122334455667788n + BigInt(i), 0);
  h.writeBigInt64LE(1000n + BigInt(i), 8);
  return h;
};
const cases = roots.map(([wireName, definitions], i) => {
  const sample = sampleOf(definitions);
  const message = new MessageWriter(definitions).writeMessage(sample);
  // The header sits between the encapsulation and the message; 16 bytes keep
  // the message's alignment.
  const header = wireName.includes('/srv/') ? requestHeader(i) : Buffer.alloc(0);
  const bytes = Buffer.concat([message.subarray(0, 4), header, message.subarray(4)]);
  return { wireName, definitions, sample, message, header, bytes };
});
const input = cases.map((c) => `${c.wireName} ${hex(c.bytes)}\n`).join('');
const run = spawnSync(roundTripExe, [], { input, encoding: 'utf8', timeout: 60000 });
if (run.stderr) process.stderr.write(run.stderr);
check(run.status === 0, `${roundTripExe} exited with ${run.status}`);
const answers = new Map();
for (const line of run.stdout.split('\n').filter(Boolean)) {
  const [type, ...rest] = line.split(' ');
  answers.set(type, rest);
}

for (const c of cases) {
  const answer = answers.get(c.wireName);
  if (!check(answer && answer[0] !== 'ERROR', `${c.wireName}: Cyclone: ${answer ? answer.join(' ') : 'no answer'}`))
    continue;
  const [cycloneHex, ddsName] = answer;
  const [p, kind, name] = c.wireName.split('/');
  check(ddsName === `${p}::${kind}::dds_::${name}_`, `${c.wireName}: DDS type name ${ddsName}`);
  const cyclone = Buffer.from(cycloneHex, 'hex');
  // XCDR1: Cyclone pads the sample to a multiple of 4 (its encapsulation
  // options count the padding); Foxglove does not.
  const payload = cyclone.subarray(4, 4 + c.bytes.length - 4);
  const padding = cyclone.subarray(4 + c.bytes.length - 4);
  check(hex(cyclone.subarray(0, 2)) === hex(c.bytes.subarray(0, 2)),
        `${c.wireName}: encapsulation ${hex(cyclone.subarray(0, 2))}, Foxglove ${hex(c.bytes.subarray(0, 2))}`);
  check(hex(payload) === hex(c.bytes.subarray(4)) && padding.length < 4 && padding.every((b) => b === 0),
        `${c.wireName}: Cyclone's ${cyclone.length} bytes differ from Foxglove's ${c.bytes.length}`);
  check(hex(cyclone.subarray(4, 4 + c.header.length)) === hex(c.header),
        `${c.wireName}: request header ${hex(cyclone.subarray(4, 4 + c.header.length))}, sent ${hex(c.header)}`);
  let decoded = null;
  try {
    const unframed = Buffer.concat([cyclone.subarray(0, 4), cyclone.subarray(4 + c.header.length)]);
    decoded = new MessageReader(c.definitions).readMessage(unframed);
  } catch (e) {
    check(false, `${c.wireName}: Foxglove cannot decode Cyclone's sample: ${e.message}`);
    continue;
  }
  for (const f of c.definitions[0].definitions.filter((d) => !d.isConstant))
    check(same(decoded[f.name], c.sample[f.name]), `${c.wireName}.${f.name}: ${JSON.stringify(plain(decoded[f.name]), (k, v) => (typeof v === 'bigint' ? `${v}` : v))}`);
}
const fields = cases.reduce((n, c) => n + c.definitions[0].definitions.filter((d) => !d.isConstant).length, 0);
console.log(`sl_msgs_wire: ${cases.length} types, ${fields} top-level fields, ${checks} checks, ${failures} failed`);
process.exit(failures === 0 ? 0 : 1);
