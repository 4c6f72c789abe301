// The daemon's image sets in an MCAP file by `sl_view record`, decoded by an
// independent reader (@mcap/core, CRCs validated) and Foxglove's ROS 2
// deserializer with the sl_msgs/msg/ImageSet schema the file carries: every
// field must come out as the daemon's config and timing make it (so a schema
// that does not match the daemon's ImageSet type fails here), and every set
// must have its scan's cloud in the file.
//   node image_sets_check.mjs --mcap FILE --ns NS --camera ID --frames N --width W --height H --count C
import fs from 'node:fs';
import { MessageReader } from '@foxglove/rosmsg2-serialization';
import { parse } from '@foxglove/rosmsg';
import { McapIndexedReader } from '@mcap/core';
import { decompress as zstdDecompress } from 'fzstd';
import lz4 from 'lz4js';

const args = Object.fromEntries(process.argv.slice(2).reduce((a, v, i, all) =>
  (v.startsWith('--') ? [...a, [v.slice(2), all[i + 1]]] : a), []));
const frames = Number(args.frames), width = Number(args.width), height = Number(args.height);
let failures = 0;
const check = (c, what) => { if (!c) { failures++; console.error(`FAIL: ${what}`); } return c; };
const stampNs = (t) => BigInt(t.sec) * 1000000000n + BigInt(t.nanosec);

const fd = await fs.promises.open(args.mcap, 'r');
const size = BigInt((await fd.stat()).size);
const reader = await McapIndexedReader.Initialize({
  readable: {
    size: async () => size,
    read: async (offset, length) => {
      const buf = Buffer.alloc(Number(length));
      await fd.read(buf, 0, Number(length), Number(offset));
      return buf;
    },
  },
  decompressHandlers: {
    zstd: (buf, n) => zstdDecompress(buf, new Uint8Array(Number(n))),
    lz4: (buf) => Uint8Array.from(lz4.decompress(buf)),
  },
});
let setsReader = null, cloudReader = null;
const topicOf = new Map();
for (const [id, ch] of reader.channelsById) {
  const schema = reader.schemasById.get(ch.schemaId);
  const text = new TextDecoder().decode(schema.data);
  topicOf.set(id, ch.topic);
  if (ch.topic === `/${args.ns}/image_sets`) {
    check(schema.name === 'sl_msgs/msg/ImageSet', `image_sets schema ${schema.name}`);
    setsReader = new MessageReader(parse(text, { ros2: true }));
  }
  if (ch.topic === `/${args.ns}/points`) cloudReader = new MessageReader(parse(text, { ros2: true }));
}
check(setsReader && cloudReader, 'the file has no image_sets or no points channel');
const sets = [], cloudStamps = new Set();
for await (const m of reader.readMessages({ validateCrcs: true })) {
  const topic = topicOf.get(m.channelId);
  if (topic === `/${args.ns}/image_sets`) sets.push(setsReader.readMessage(m.data));
  if (topic === `/${args.ns}/points`) cloudStamps.add(stampNs(cloudReader.readMessage(m.data).header.stamp));
}
await fd.close();
check(sets.length === Number(args.count), `${sets.length} image sets, expected ${args.count}`);
let previous = -1n;
for (const [k, s] of sets.entries()) {
  const what = `image set ${k + 1}`;
  const trigger = stampNs(s.header.stamp);
  check(cloudStamps.has(trigger), `${what}: no cloud stamped ${trigger} in the file`);
  check(BigInt(s.sequence_id) > previous, `${what}: sequence_id ${s.sequence_id} after ${previous}`);
  previous = BigInt(s.sequence_id);
  check(s.pattern.length > 0, `${what}: empty pattern`);
  check(s.camera_count === 1, `${what}: camera_count ${s.camera_count}`);
  check(JSON.stringify(s.camera_ids) === JSON.stringify([args.camera]), `${what}: camera_ids ${JSON.stringify(s.camera_ids)}`);
  check(s.bit_depths.length === 1 && s.bit_depths[0] === 8, `${what}: bit_depths ${JSON.stringify(Array.from(s.bit_depths))}`);
  check(s.images.length === frames, `${what}: ${s.images.length} images, expected ${frames}`);
  let last = trigger - 1n;
  for (const [i, im] of s.images.entries()) {
    const w = `${what}, image ${i}`;
    check(im.width === width && im.height === height, `${w}: ${im.width}x${im.height}`);
    check(im.encoding === 'mono8' && im.step === width && im.is_bigendian === 0, `${w}: ${im.encoding}, step ${im.step}`);
    check(im.data.length === im.step * im.height, `${w}: ${im.data.length} data bytes`);
    const t = stampNs(im.header.stamp);
    check(t > last, `${w}: exposure stamp ${t} not after ${last}`);
    last = t;
    let lit = 0;
    for (let p = 0; p < im.data.length; p += 997) lit += im.data[p] > 0;
    check(lit > 0, `${w}: all sampled pixels 0`);
  }
}
console.log(`image sets: ${sets.length} decoded with the file's schema, ${cloudStamps.size} clouds`);
if (failures) { console.error(`${failures} failures`); process.exit(1); }
console.log('ok: every image set field as the daemon published it');
