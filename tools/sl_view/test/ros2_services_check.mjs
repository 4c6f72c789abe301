// The daemon's ROS 2 services (issue 31) as two ROS 2 clients on
// rmw_cyclonedds see them: each client is a ros2_service_client process
// (the middleware's framing: request header = the client's guid and a
// sequence number); the requests are serialized and the responses decoded by
// Foxglove's ROS 2 (de)serializer from the .srv files (ros2/sl_msgs,
// idl/std_srvs), not the daemon's types. Checks:
//   - every request gets exactly one response carrying its client's guid and
//     its sequence number; the two clients use the same sequence numbers and
//     neither ever takes a response with its guid that it did not ask for;
//   - list_patterns, get_config, start, stop (std_srvs/Trigger), set_pattern
//     answer with the right fields;
//   - bad requests (unknown trigger value, unknown pattern, an oversized
//     pattern name, stop while idle) get success=false, the code and a
//     message naming the fault, and change nothing (status before == after);
//   - the status counters count every request;
//   - with FASTDDS_EXE (tests/interop/fastdds_service_client): a client on
//     Fast DDS framed as rmw_fastrtps (plain message, ids in the RTPS sample
//     identity) finds the daemon's Fast DDS service endpoints and gets
//     exactly one response per request, matched by its related sample
//     identity (list_patterns, get_config, a bad set_pattern, start, stop:
//     the fields right, the bad one changes nothing); a truncated request
//     gets none and is counted in requests_malformed, the good ones are not;
//     the rmw_cyclonedds clients never take one of those responses as theirs.
//     Fails when the daemon runs with SL_FASTDDS_SERVICES=0.
//   node ros2_services_check.mjs SOURCE_DIR CLIENT_EXE NAMESPACE [FASTDDS_EXE]
import { spawn, spawnSync } from 'node:child_process';
import readline from 'node:readline';
import path from 'node:path';
import { MessageReader, MessageWriter } from '@foxglove/rosmsg2-serialization';
import { loadPackage } from './ros2_definitions.mjs';

const [src, clientExe, ns, fastDdsExe] = process.argv.slice(2);
let failures = 0, checks = 0;
const check = (c, what) => { checks++; if (!c) { failures++; console.error(`FAIL: ${what}`); } return c; };

const slMsgs = loadPackage(path.join(src, 'ros2/sl_msgs'));
const stdSrvs = loadPackage(path.join(src, 'idl/std_srvs'));
const typeOf = { start: 'sl_msgs/srv/Start', stop: 'std_srvs/srv/Trigger', set_pattern: 'sl_msgs/srv/SetPattern',
  list_patterns: 'sl_msgs/srv/ListPatterns', get_config: 'sl_msgs/srv/GetConfig' };
const definitions = (wireName) => (wireName.startsWith('std_srvs') ? stdSrvs : slMsgs).get(wireName);
const statusReader = new MessageReader(slMsgs.get('sl_msgs/msg/Status'));

// One ros2_service_client process.
class Client {
  constructor(name) {
    this.name = name;
    this.proc = spawn(clientExe, [ns], { stdio: ['pipe', 'pipe', 'inherit'] });
    this.lines = [];
    this.waiters = [];
    readline.createInterface({ input: this.proc.stdout }).on('line', (l) => {
      this.lines.push(l);
      for (const w of this.waiters.splice(0)) w();
    });
    this.guids = {};
    this.replies = [];  // { service, guid, seq, response }
  }
  async until(predicate, what, ms = 20000) {
    const end = Date.now() + ms;
    for (;;) {
      const i = this.lines.findIndex(predicate);
      if (i >= 0) return this.lines.splice(0, i + 1);
      if (Date.now() > end) throw new Error(`${this.name}: no ${what} within ${ms} ms`);
      await new Promise((r) => { this.waiters.push(r); setTimeout(r, 100); });
    }
  }
  async ready() {
    for (const l of await this.until((l) => l === 'ready', 'ready'))
      if (l.startsWith('guid ')) { const [, s, g] = l.split(' '); this.guids[s] = BigInt(g); }
  }
  send(line) { this.proc.stdin.write(`${line}\n`); }
  call(service, seq, request) {
    const bytes = new MessageWriter(definitions(`${typeOf[service]}_Request`)).writeMessage(request);
    this.send(`call ${service} ${seq} ${Buffer.from(bytes).toString('hex')}`);
  }
  absorb(lines) {
    for (const l of lines) {
      if (!l.startsWith('reply ')) continue;
      const [, service, hex] = l.split(' ');
      const bytes = Buffer.from(hex, 'hex');
      const guid = bytes.readBigUInt64LE(4), seq = bytes.readBigInt64LE(12);
      const message = Buffer.concat([bytes.subarray(0, 4), bytes.subarray(20)]);
      const response = new MessageReader(definitions(`${typeOf[service]}_Response`)).readMessage(message);
      this.replies.push({ service, guid, seq, response });
    }
  }
  async status() {
    this.send('status');
    const hex = (await this.until((l) => l.startsWith('status '), 'status')).at(-1).split(' ')[1];
    if (!check(hex !== 'none', `${this.name}: no status`)) return null;
    return statusReader.readMessage(Buffer.from(hex, 'hex'));
  }
  quit() { this.send('quit'); }
}

// Waits for every reply line of a `wait`, keeping them.
async function settle(client, ms) {
  client.send(`wait ${ms}`);
  const end = Date.now() + ms + 20000;
  for (;;) {
    const i = client.lines.indexOf('waited');
    if (i >= 0) { client.absorb(client.lines.splice(0, i + 1)); return; }
    if (Date.now() > end) throw new Error(`${client.name}: wait did not end`);
    await new Promise((r) => { client.waiters.push(r); setTimeout(r, 100); });
  }
}

const a = new Client('A'), b = new Client('B');
await Promise.all([a.ready(), b.ready()]);
const mine = (c, service, seq) => c.replies.filter((r) => r.service === service && r.guid === c.guids[service] && r.seq === BigInt(seq));

// --- queries from both clients with the same sequence numbers --------------------
const before = await a.status();
a.call('list_patterns', 1, {}); b.call('list_patterns', 1, {});
a.call('get_config', 2, {}); b.call('get_config', 2, {});
await Promise.all([settle(a, 1500), settle(b, 1500)]);
for (const c of [a, b]) {
  for (const [service, seq] of [['list_patterns', 1], ['get_config', 2]]) {
    const got = mine(c, service, seq);
    check(got.length === 1, `${c.name} ${service} #${seq}: ${got.length} responses with its guid and seq, expected 1`);
  }
  const list = mine(c, 'list_patterns', 1)[0]?.response;
  check(list && list.patterns.length > 0 && list.patterns.includes(list.current),
        `${c.name} list_patterns: ${JSON.stringify(list)}`);
  check(list && before && list.patterns.join(',') === before.patterns.join(','),
        `${c.name} list_patterns ${list?.patterns} != status.patterns ${before?.patterns}`);
  const config = mine(c, 'get_config', 2)[0]?.response;
  check(config && config.config.includes(`namespace: ${ns}`), `${c.name} get_config lacks 'namespace: ${ns}'`);
}
// The other client's responses reach each reader (one DDS topic); none carries
// this client's guid unless it asked for it.
for (const [c, other] of [[a, b], [b, a]]) {
  const foreign = c.replies.filter((r) => r.guid !== c.guids[r.service]);
  check(foreign.every((r) => r.guid === other.guids[r.service]),
        `${c.name} took responses for unknown guids: ${foreign.map((r) => r.guid)}`);
  const ownIds = c.replies.filter((r) => r.guid === c.guids[r.service]).map((r) => `${r.service}#${r.seq}`);
  check(new Set(ownIds).size === ownIds.length && ownIds.length === 2, `${c.name} own responses: ${ownIds}`);
}

// --- bad requests: an error response each, and nothing changes -------------------
const startRequest = (o) => ({ pattern: '', count: 1, recording: '', trigger: 0, delay_s: 0,
  start_at: { sec: 0, nanosec: 0 }, cameras: [], motion_compensation: 0, ...o });
a.call('start', 3, startRequest({ trigger: 9 }));
a.call('set_pattern', 4, { pattern: 'no_such_pattern' });
a.call('set_pattern', 5, { pattern: 'p'.repeat(5000) });
a.call('stop', 6, {});
a.call('start', 7, startRequest({ count: -2 }));
await settle(a, 2000);
const bad = (service, seq) => mine(a, service, seq);
for (const [service, seq, code, words] of [['start', 3, 7, 'trigger'], ['set_pattern', 4, 1, 'no_such_pattern'],
  ['set_pattern', 5, 7, '5000 bytes'], ['start', 7, 3, 'count']]) {
  const got = bad(service, seq);
  check(got.length === 1, `${service} #${seq}: ${got.length} responses`);
  const r = got[0]?.response;
  check(r && r.success === false && r.code === code && r.message.includes(words),
        `${service} #${seq}: ${JSON.stringify(r)} (expected code ${code}, a message with '${words}')`);
}
const stopIdle = bad('stop', 6);
check(stopIdle.length === 1 && stopIdle[0].response.success === false && stopIdle[0].response.message.length > 0,
      `stop while idle: ${JSON.stringify(stopIdle[0]?.response)}`);
await new Promise((r) => setTimeout(r, 1500));  // a periodic status after the requests
const after = await a.status();
check(after && after.state === 0 && after.pattern === before.pattern && after.scans_requested === before.scans_requested,
      `bad requests changed the state: ${after?.state} '${after?.pattern}' ${after?.scans_requested}`);

// --- a good start and stop ---------------------------------------------------------
b.call('start', 8, startRequest({ count: 0 }));
await settle(b, 1500);
const started = mine(b, 'start', 8);
check(started.length === 1 && started[0].response.success === true && started[0].response.code === 0,
      `start: ${JSON.stringify(started[0]?.response)}`);
b.call('stop', 9, {});
await settle(b, 1500);
const stopped = mine(b, 'stop', 9);
check(stopped.length === 1 && stopped[0].response.success === true, `stop: ${JSON.stringify(stopped[0]?.response)}`);

// --- rmw_fastrtps-framed requests: served by the daemon's Fast DDS participant ---
let fastDdsRequests = 0;  // answered through the dispatcher
if (fastDdsExe) {
  await new Promise((r) => setTimeout(r, 1500));
  const idle = await b.status();
  let fastServer = true;
  const ownBefore = [a, b].map((c) => c.replies.filter((r) => r.guid === c.guids[r.service]).length);
  const typeName = (service) => {
    const [pkg, , name] = typeOf[service].split('/');
    return `${pkg}::srv::dds_::${name}_`;
  };
  // One fastdds_service_client call: its responses decoded by Foxglove, or null
  // when no Fast DDS server endpoint matched (e.g. SL_FASTDDS_SERVICES=0).
  const fastCall = (service, bytes) => {
    const run = spawnSync(fastDdsExe, ['0', ns, service, typeName(service), Buffer.from(bytes).toString('hex'), '2'],
                          { encoding: 'utf8', timeout: 40000 });
    check(run.status === 0, `fastdds_service_client ${service}: exit ${run.status}: ${run.stderr}`);
    fastServer = check(/^fast_dds_server 1$/m.test(run.stdout ?? ''),
                       `Fast DDS ${service}: no Fast DDS service endpoint of the daemon matched`);
    if (!fastServer) return null;
    return (run.stdout.match(/^response [0-9a-f]+$/gm) ?? []).map((l) =>
      new MessageReader(definitions(`${typeOf[service]}_Response`)).readMessage(Buffer.from(l.split(' ')[1], 'hex')));
  };
  const request = (service, message) => new MessageWriter(definitions(`${typeOf[service]}_Request`)).writeMessage(message);
  const one = (service, message, what) => {
    const got = fastCall(service, request(service, message));
    if (got === null) return null;
    fastDdsRequests++;
    check(got.length === 1, `Fast DDS ${what}: ${got.length} responses it takes, expected 1`);
    return got[0] ?? null;
  };
  const list = one('list_patterns', {}, 'list_patterns');
  if (fastServer) {
    check(list && list.patterns.join(',') === idle.patterns.join(',') && list.current === idle.pattern,
          `Fast DDS list_patterns: ${JSON.stringify(list)} (status: ${idle.patterns} / ${idle.pattern})`);
    const config = one('get_config', {}, 'get_config');
    check(config && config.config.includes(`namespace: ${ns}`), `Fast DDS get_config lacks 'namespace: ${ns}'`);
    const badPattern = one('set_pattern', { pattern: 'no_such_pattern' }, 'set_pattern no_such_pattern');
    check(badPattern && badPattern.success === false && badPattern.code === 1 && badPattern.message.includes('no_such_pattern'),
          `Fast DDS bad set_pattern: ${JSON.stringify(badPattern)}`);
    await new Promise((r) => setTimeout(r, 1500));
    const unchanged = await b.status();
    check(unchanged && unchanged.state === 0 && unchanged.pattern === idle.pattern,
          `a bad Fast DDS request changed the state: ${unchanged?.state} '${unchanged?.pattern}'`);
    const started = one('start', startRequest({ count: 0 }), 'start');
    check(started && started.success === true && started.code === 0, `Fast DDS start: ${JSON.stringify(started)}`);
    await new Promise((r) => setTimeout(r, 1500));
    const running = await b.status();
    check(running && running.state !== 0, `after a Fast DDS start the state is ${running?.state}`);
    const stopped = one('stop', {}, 'stop');
    check(stopped && stopped.success === true, `Fast DDS stop: ${JSON.stringify(stopped)}`);
    // A request cut short: no response, counted as malformed, not dispatched.
    const cut = Buffer.from(request('set_pattern', { pattern: 'some_long_pattern_name' })).subarray(0, 12);
    const none = fastCall('set_pattern', cut);
    check(none !== null && none.length === 0, `Fast DDS truncated set_pattern: ${none?.length} responses`);
    await new Promise((r) => setTimeout(r, 1500));
    const later = await b.status();
    check(later && later.state === 0, `after a Fast DDS stop the state is ${later?.state}`);
    check(later && later.requests_malformed - idle.requests_malformed === 1n,
          `requests_malformed grew by ${later?.requests_malformed - idle?.requests_malformed}, expected 1 (the truncated request)`);
    await Promise.all([settle(a, 500), settle(b, 500)]);
    const ownAfter = [a, b].map((c) => c.replies.filter((r) => r.guid === c.guids[r.service]).length);
    check(ownAfter.join() === ownBefore.join(),
          `the rmw_cyclonedds clients took Fast DDS responses as theirs: ${ownBefore} -> ${ownAfter}`);
  }
}

// --- every request counted ----------------------------------------------------------
await new Promise((r) => setTimeout(r, 1500));
const end = await b.status();
const sent = 4 + 5 + 2 + fastDdsRequests;
check(end && end.requests_received - before.requests_received === BigInt(sent),
      `requests_received grew by ${end?.requests_received - before?.requests_received}, ${sent} sent`);
check(end && end.requests_answered - before.requests_answered === BigInt(sent),
      `requests_answered grew by ${end?.requests_answered - before?.requests_answered}, ${sent} sent`);
check(end && end.requests_invalid - before.requests_invalid === 1n,
      `requests_invalid grew by ${end?.requests_invalid - before?.requests_invalid} (one oversized pattern)`);
a.quit(); b.quit();
console.log(`ros2_services: ${a.replies.length + b.replies.length} responses taken, ${fastDdsRequests} Fast DDS requests, ${checks} checks, ${failures} failed`);
process.exit(failures === 0 ? 0 : 1);
