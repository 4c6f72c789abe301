// One viewer of sl_view for the cost measurement (bench/bench_view.sh):
// subscribes to TOPIC for SECONDS and prints, per cloud, the latency from
// the cloud's stamp to the bridge's receive time (DDS, what any subscriber
// sees) and to this viewer's receive time (after the WebSocket), as
// median / 95th percentile, and the added part (viewer - bridge).
//   node bench_viewer.mjs ws://127.0.0.1:PORT /sl/points SECONDS
import WebSocket from 'ws';
const [url, topic, seconds] = process.argv.slice(2);
const ws = new WebSocket(url, ['foxglove.websocket.v1']);
ws.binaryType = 'nodebuffer';
const dds = [], view = [], added = [];
let bytes = 0;
const nowNs = () => BigInt(Math.round((performance.timeOrigin + performance.now()) * 1e6));
ws.on('message', (data, binary) => {
  const rx = nowNs();
  if (!binary) {
    const m = JSON.parse(data.toString());
    if (m.op === 'advertise') {
      const c = m.channels.find((ch) => ch.topic === topic);
      if (!c) { console.error(`no channel ${topic}`); process.exit(1); }
      ws.send(JSON.stringify({ op: 'subscribe', subscriptions: [{ id: 0, channelId: c.id }] }));
    }
    return;
  }
  if (data[0] !== 0x01) return;
  const bridgeRx = data.readBigUInt64LE(5);
  const stamp = BigInt(data.readInt32LE(13 + 4)) * 1000000000n + BigInt(data.readUInt32LE(13 + 8));
  dds.push(Number(bridgeRx - stamp) / 1e6);
  view.push(Number(rx - stamp) / 1e6);
  added.push(Number(rx - bridgeRx) / 1e6);
  bytes += data.length;
});
const q = (a, p) => { const s = [...a].sort((x, y) => x - y); return s.length ? s[Math.min(s.length - 1, Math.floor(p * s.length))] : NaN; };
setTimeout(() => {
  const f = (a) => `median ${q(a, 0.5).toFixed(1)} ms, p95 ${q(a, 0.95).toFixed(1)} ms`;
  console.log(`${topic}: ${dds.length} messages, ${(bytes / dds.length / 1e6).toFixed(2)} MB each`);
  console.log(`  stamp -> bridge (DDS):     ${f(dds)}`);
  console.log(`  stamp -> viewer:           ${f(view)}`);
  console.log(`  added by the bridge + WS:  ${f(added)}`);
  ws.close();
  process.exit(0);
}, Number(seconds) * 1000);
