// The JavaScript live decoder against the Python decoder, on the streams of tests/data/live/
// (tests/js/make_fixtures.py): every integer read equal, every decoded channel within 1e-9 degrees
// (or skeleton units), joint positions within 1e-8; then damaged streams end in DecodeError only.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { readFile } from 'node:fs/promises';
import { deflateSync, gunzipSync, inflateSync } from 'node:zlib';
import {
  DecodeError, HoldingDecoder, Reader, RelayClient, LiveDecoder, forwardKinematics, parseStreamHeader, splitBatch,
} from '../../js/src/index.js';
import { seeded } from './seeded.mjs';
import { varint } from './varint.mjs';
import { crc16 } from '../../js/src/bytes.js';

const LIVE = new URL('../data/live/', import.meta.url);
const CASES = ['walk', 'walk-layers', 'walk-layers-cut', 'asf-30fps-shell', 'run-refresh'];

async function fixture(name) {
  const stream = new Uint8Array(await readFile(new URL(`${name}.stream`, LIVE)));
  const meta = JSON.parse(await readFile(new URL(`${name}.json`, LIVE), 'utf8'));
  const f64 = gunzipSync(await readFile(new URL(`${name}.f64.gz`, LIVE)));
  const ints = gunzipSync(await readFile(new URL(`${name}.ints.gz`, LIVE)));
  return {
    stream, meta,
    channels: new Float64Array(f64.buffer, f64.byteOffset, f64.byteLength / 8),
    ints: new Int32Array(ints.buffer, ints.byteOffset, ints.byteLength / 4),
  };
}

async function decodeAll(stream) {
  const reader = new Reader();
  const packets = splitBatch(stream).map((raw) => reader.read(raw));
  const info = await parseStreamHeader(packets[0].payload);
  const decoder = new LiveDecoder(info);
  const frames = [];
  const ints = [];
  for (const p of packets.slice(1)) {
    const out = decoder.push(p);
    if (out) frames.push(out);
    ints.push(decoder.lastInts);
  }
  return { info, frames, ints };
}

for (const name of CASES) {
  test(`${name}: the integers and channels are the Python decoder's`, async () => {
    const { stream, meta, channels, ints } = await fixture(name);
    const { info, frames, ints: read } = await decodeAll(stream);
    let at = 0;
    meta.packets.forEach((packet, k) => {
      assert.deepEqual(read[k].map((x) => x.length), packet.ints, `packet ${k}: integers per layer`);
      for (const layer of read[k]) {
        for (let i = 0; i < layer.length; i++, at++) {
          if (layer[i] !== ints[at]) assert.fail(`packet ${k}: integer ${i} is ${layer[i]}, Python read ${ints[at]}`);
        }
      }
    });
    assert.equal(at, ints.length);
    const decoded = new Float64Array(frames.reduce((n, f) => n + f.length, 0));
    let pos = 0;
    for (const f of frames) { decoded.set(f, pos); pos += f.length; }
    assert.equal(decoded.length, meta.frames * meta.channels);
    let worst = 0;
    for (let i = 0; i < decoded.length; i++) worst = Math.max(worst, Math.abs(decoded[i] - channels[i]));
    assert.ok(worst <= 1e-9, `worst channel differs by ${worst}`);
    const positions = forwardKinematics(info.skeleton, decoded);
    const J = info.skeleton.joints.length;
    for (const [frame, want] of Object.entries(meta.positions)) {
      want.forEach((p, j) => p.forEach((v, a) => {
        const got = positions[(Number(frame) * J + j) * 3 + a];
        assert.ok(Math.abs(got - v) <= 1e-8, `frame ${frame}, joint ${j}: ${got} vs ${v}`);
      }));
    }
  });
}

test('a holding decoder decodes reordered packets as the stream in order, and gives a lost one up', async () => {
  const { stream } = await fixture('walk-layers');
  const { frames } = await decodeAll(stream);
  const reader = new Reader();
  const packets = splitBatch(stream).map((raw) => reader.read(raw));
  const info = await parseStreamHeader(packets[0].payload);
  const order = packets.slice(1);
  for (let k = 3; k + 1 < order.length; k += 5) [order[k], order[k + 1]] = [order[k + 1], order[k]];
  const holding = new HoldingDecoder(info, 0.1);
  assert.equal(holding.inStep, false); // before its first keyframe
  const half = order.length >> 1;
  const first = order.slice(0, half).flatMap((p) => holding.push(p));
  assert.equal(holding.inStep, true); // following the stream
  const out = [...first, ...order.slice(half).flatMap((p) => holding.push(p))]
    .filter((x) => x.frames?.length).map((x) => x.frames);
  assert.deepEqual(out, frames.filter((f) => f.length));
  assert.ok(holding.repaired > 0 && holding.stream.lost === 0);
  const lossy = new HoldingDecoder(info, 0.1); // packet 5 never comes: held, then given up
  const lens = packets.slice(1).filter((_, k) => k !== 4).map((p) => lossy.push(p).length);
  assert.deepEqual(lens.slice(3, 6), [1, 0, 2]); // 12 frames held: the next packet is past them
  assert.ok(lossy.stream.lost === 1 && lossy.wanted().length === 0);
});

test('a relay client asks for a packet its link lost and decodes the stream whole', async () => {
  const { stream } = await fixture('walk-layers');
  const { frames } = await decodeAll(stream);
  const raws = splitBatch(stream);
  const reader = new Reader();
  const { stream: id, sequence: lost } = raws.map((raw) => reader.read(raw))[11];
  const batchOf = (raw) => Uint8Array.from([0x4d, 0x62, 1, ...varint(raw.length), ...raw]); // "Mb", one packet, its length
  class FakeSocket {
    constructor() { this.sent = []; this.readyState = 1; FakeSocket.last = this; }
    send(text) { this.sent.push(JSON.parse(text)); }
    close() {}
  }
  const client = new RelayClient('ws://relay', { room: 'r', token: 't', WebSocketClass: FakeSocket });
  const connected = client.connect();
  const ws = FakeSocket.last;
  ws.onmessage({ data: JSON.stringify({ welcome: 'r', role: 'subscribe' }) });
  await connected;
  ws.onmessage({ data: JSON.stringify({ status: 'stream 4: its last restart point is no longer kept' }) });
  assert.deepEqual(client.statuses, ['stream 4: its last restart point is no longer kept']);
  const deliver = async (raw) => { ws.onmessage({ data: batchOf(raw).buffer }); await client.queue; };
  for (let k = 0; k < raws.length; k++) {
    if (k === 11) continue; // the link drops it
    await deliver(raws[k]);
    if (k === 12) {
      assert.deepEqual(ws.sent.at(-1), { repair: [[id, lost]] });
      await deliver(raws[11]); // the relay resends it
    }
  }
  const avatar = client.avatars.get(id);
  assert.equal(avatar.decoder.repaired, 1);
  assert.equal(avatar.frames * avatar.skeleton.numChannels, frames.reduce((n, f) => n + f.length, 0));
});

test('a relay that takes the socket but sends no welcome is given up on after welcomeS', async () => {
  let closed = 0;
  class SilentSocket {
    constructor() { this.readyState = 1; }
    send() {}
    close() { closed += 1; }
  }
  const client = new RelayClient('ws://relay', { room: 'r', token: 't', welcomeS: 0.05, WebSocketClass: SilentSocket });
  const started = Date.now();
  await assert.rejects(client.connect(), /sent no welcome within 0.05 s/);
  assert.ok(Date.now() - started < 2000);
  assert.equal(closed, 1);
});

test('damaged streams end in DecodeError, never another error or a hang', async () => {
  const { stream } = await fixture('walk-layers');
  const random = seeded(2026);
  const reader = new Reader();
  const packets = splitBatch(stream).map((raw) => reader.read(raw));
  const info = await parseStreamHeader(packets[0].payload);
  let errors = 0;
  for (let trial = 0; trial < 300; trial++) {
    const decoder = new LiveDecoder(info);
    for (const p of packets.slice(1)) {
      const payload = Uint8Array.from(p.payload);
      if (payload.length && random() < 0.3) {
        for (let n = 0; n < 1 + random() * 4; n++) payload[Math.floor(random() * payload.length)] = Math.floor(random() * 256);
      }
      try {
        decoder.push({ ...p, payload });
      } catch (e) {
        if (!(e instanceof DecodeError)) throw e;
        errors += 1;
      }
    }
  }
  assert.ok(errors > 0);
});

test('damaged packets, batches and headers end in DecodeError', async () => {
  const { stream } = await fixture('walk');
  const random = seeded(7);
  for (let trial = 0; trial < 2000; trial++) {
    const damaged = Uint8Array.from(stream.subarray(0, Math.floor(random() * stream.length * 1.2) || stream.length));
    for (let n = 0; n < 1 + random() * 3; n++) damaged[Math.floor(random() * damaged.length)] ^= 1 << Math.floor(random() * 8);
    try {
      const reader = new Reader();
      const packets = splitBatch(damaged).map((raw) => reader.read(raw));
      await parseStreamHeader(packets[0].payload);
    } catch (e) {
      if (!(e instanceof DecodeError)) throw e;
    }
  }
});

// A fixture stream's packets and its header's JSON, and the stream header a changed JSON makes.
async function withHeader(name) {
  const { stream } = await fixture(name);
  const reader = new Reader();
  const packets = splitBatch(stream).map((raw) => reader.read(raw));
  return { packets, doc: JSON.parse(new TextDecoder().decode(inflateSync(packets[0].payload))) };
}

function headerOf(doc) {
  return parseStreamHeader(deflateSync(new TextEncoder().encode(JSON.stringify(doc))));
}

test('stream headers with hostile values end in DecodeError or decode', async () => {
  const { packets, doc: original } = await withHeader('walk-layers');
  const random = seeded(11);
  const hostile = [2 ** 31, 2 ** 53, -1, 0, 1, 0.5, 1e308, 'x', [], [0, 0], {}, null, [[0]], 1e6, true];
  for (let trial = 0; trial < 400; trial++) {
    const doc = structuredClone(original);
    const holders = [];
    const stack = [doc];
    while (stack.length) {
      const item = stack.pop();
      if (item && typeof item === 'object') {
        for (const key of Object.keys(item)) {
          holders.push([item, key]);
          stack.push(item[key]);
        }
      }
    }
    const [holder, key] = holders[Math.floor(random() * holders.length)];
    holder[key] = hostile[Math.floor(random() * hostile.length)];
    try {
      const decoder = new LiveDecoder(await headerOf(doc));
      for (const p of packets.slice(1, 12)) decoder.push(p);
    } catch (e) {
      if (!(e instanceof DecodeError)) throw new Error(`${key} = ${JSON.stringify(holder[key])}: ${e.stack}`);
    }
  }
});

test('a stream of another format revision is refused with a DecodeError that says so', async () => {
  const { packets, doc } = await withHeader('walk');
  assert.equal(doc.codec.revision, 3);
  for (const revision of [undefined, 2, 4]) {
    const older = structuredClone(doc);
    if (revision === undefined) delete older.codec.revision;
    else older.codec.revision = revision;
    const decoder = new LiveDecoder(await headerOf(older));
    assert.throws(() => decoder.push(packets[1]), (e) => e instanceof DecodeError && /format revision/.test(e.message));
  }
});

test('a batch of format 1 (u32 lengths) is refused as such', () => {
  const old = Uint8Array.from([0x4d, 0x42, 1, 0, 0, 0, 3, 0, 0, 0, 1, 2, 3]);
  assert.throws(() => splitBatch(old), (e) => e instanceof DecodeError && /format 1/.test(e.message));
  assert.deepEqual(splitBatch(Uint8Array.from([0x4d, 0x62, 2, 1, 2, 9, 8, 7])).map((p) => [...p]), [[9], [8, 7]]);
});

test('a packet says by its check how many layers a relay cut off; more than its stream has is damage', async () => {
  const recheck = (raw, start) => { // the packet with its CRC-16 computed from another start
    const out = Uint8Array.from(raw);
    const crc = crc16(out, 0, out.length - 2, start);
    out[out.length - 2] = crc & 0xff;
    out[out.length - 1] = crc >> 8;
    return out;
  };
  for (const [name, layers] of [['walk', 1], ['walk-layers', 3]]) {
    const { stream } = await fixture(name);
    const raws = splitBatch(stream);
    const reader = new Reader();
    const packets = raws.map((raw) => reader.read(raw));
    const decoder = new LiveDecoder(await parseStreamHeader(packets[0].payload));
    decoder.push(packets[1]);
    const again = new Reader();
    again.read(raws[0]);
    again.read(raws[1]);
    const cut = again.read(recheck(raws[2], 0x5a5a)); // "one layer cut off", nothing cut in fact
    assert.equal(cut.dropped, 1);
    if (layers === 1) assert.throws(() => decoder.push(cut), (e) => e instanceof DecodeError && /cut off a stream of 1/.test(e.message));
    else assert.equal(decoder.push(cut).length, packets[2].frames * decoder.info.skeleton.numChannels);
  }
  const raws = splitBatch((await fixture('walk')).stream);
  const reader = new Reader();
  reader.read(raws[0]);
  reader.read(raws[1]);
  assert.throws(() => reader.read(recheck(raws[2], 0x1234)), (e) => e instanceof DecodeError && /CRC/.test(e.message));
});
