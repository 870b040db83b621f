// The JavaScript .moc decoder against the Python decoder, on the files of tests/data/moc/
// (tests/js/make_fixtures.py): every integer the coefficient decoder reads equal, every decoded
// channel within 1e-9 (degrees or skeleton units), joint positions within 1e-8 and, under a max joint
// error bound, within the bound of the original clip; the step tables
// equal Python's; frame ranges; then damaged and hostile files end in DecodeError only.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { readFile } from 'node:fs/promises';
import { deflateSync, gunzipSync, inflateSync } from 'node:zlib';
import { DecodeError, decodeMoc, forwardKinematics, openMoc } from '../../js/src/index.js';
import { HEADER_DICTIONARIES } from '../../js/src/header-dict.js';
import { chunkBody } from '../../js/src/moc.js';
import { readKinwave } from '../../js/src/kinwave.js';
import { CODE_STEP, twoToEighths } from '../../js/src/steps.js';
import { crc32, readVarint, u16, u32 } from '../../js/src/bytes.js';
import { seeded } from './seeded.mjs';
import { varint } from './varint.mjs';

const MOC = new URL('../data/moc/', import.meta.url);
const CASES = ['bvh-joint', 'asf-30fps-shell', 'dummy-root', 'dummy-root-bind', 'zxz-d4', 'haar-bitrate', 'glitch', 'rest-pose', 'rest-at-zero', 'turned-root-bind', 'lead', 'bones-in-channels', 'offsets-in-channels'];

async function fixture(name) {
  const data = new Uint8Array(await readFile(new URL(`${name}.moc`, MOC)));
  const meta = JSON.parse(await readFile(new URL(`${name}.json`, MOC), 'utf8'));
  const f64 = gunzipSync(await readFile(new URL(`${name}.f64.gz`, MOC)));
  const ints = gunzipSync(await readFile(new URL(`${name}.ints.gz`, MOC)));
  return {
    data, meta,
    channels: new Float64Array(f64.buffer, f64.byteOffset, f64.byteLength / 8),
    ints: new Int32Array(ints.buffer, ints.byteOffset, ints.byteLength / 4),
  };
}

function integersRead(coded) {
  return [coded.side, coded.constant, coded.knots, coded.coeffs].flatMap((a) => Array.from(a));
}

test('step codes and segment factors are Python\'s, bit for bit', async () => {
  const table = JSON.parse(await readFile(new URL('steps.json', MOC), 'utf8'));
  table.code_steps.forEach((step, code) => assert.equal(CODE_STEP[code], step, `code ${code}`));
  for (const [o, factor] of Object.entries(table.offset_factors)) assert.equal(twoToEighths(Number(o)), factor, `offset ${o}`);
});

const formsSeen = new Set();
for (const name of CASES) {
  test(`${name}: the integers and channels are the Python decoder's`, async () => {
    const { data, meta, channels, ints } = await fixture(name);
    const file = await openMoc(data);
    assert.equal(file.chunks.length, meta.chunks.length);
    let at = 0;
    file.chunks.forEach((chunk, k) => {
      const body = chunkBody(data, chunk, k);
      assert.equal(body[1], meta.chunks[k].flags, `chunk ${k}: flags`);
      assert.equal(body[0], meta.chunks[k].format, `chunk ${k}: format`);
      assert.equal(body[0] > 1 ? body[6] : 0, meta.chunks[k].more, `chunk ${k}: more flags`);
      const read = readKinwave(body, file.skeleton, chunk.count);
      read.forms.forEach((f) => formsSeen.add(f));
      const got = integersRead(read.coded);
      assert.equal(got.length, meta.chunks[k].ints, `chunk ${k}: integers`);
      for (let i = 0; i < got.length; i++, at++) {
        if (got[i] !== ints[at]) assert.fail(`chunk ${k}: integer ${i} is ${got[i]}, Python read ${ints[at]}`);
      }
    });
    assert.equal(at, ints.length);
    const decoded = await decodeMoc(data);
    assert.equal(decoded.channels.length, meta.frames * meta.channels);
    let worst = 0;
    for (let i = 0; i < channels.length; i++) worst = Math.max(worst, Math.abs(decoded.channels[i] - channels[i]));
    assert.ok(worst <= 1e-9, `worst channel differs by ${worst}`);
    const positions = forwardKinematics(decoded.skeleton, decoded.channels);
    const J = decoded.skeleton.joints.length;
    const cm = 100 / decoded.skeleton.unitsPerMetre;
    for (const [frame, want] of Object.entries(meta.positions)) {
      want.forEach((p, j) => p.forEach((v, a) => {
        const got = positions[(Number(frame) * J + j) * 3 + a];
        assert.ok(Math.abs(got - v) <= 1e-8, `frame ${frame}, joint ${j}: ${got} vs ${v}`);
      }));
      if (meta.bound_cm === null) continue;
      meta.original_positions[frame].forEach((p, j) => {  // the file's error bound holds on this decoder's output
        const at = (Number(frame) * J + j) * 3;
        const error = Math.hypot(...p.map((v, a) => positions[at + a] - v)) * cm;
        assert.ok(error <= meta.bound_cm + 1e-9, `frame ${frame}, joint ${j}: ${error} cm over ${meta.bound_cm}`);
      });
    }
  });
}

test('the cases use every coding form: Euler, vector, coding orders and WORLD ones', () => {
  assert.ok(formsSeen.has(0) && formsSeen.has(1), [...formsSeen].join());
  assert.ok([...formsSeen].some((f) => f >= 2 && f < 8), 'a coding order');
  assert.ok([...formsSeen].some((f) => f >= 8), 'a WORLD form');
});

test('the lead case has chunks whose wavelet grid starts early, the bones case fine and mirrored constants, the offsets case constants about 0, the dummy roots fine turns', async () => {
  const { meta } = await fixture('lead');
  assert.ok(meta.chunks.some((c) => (c.more >> 2) & 3), JSON.stringify(meta.chunks));
  const bones = (await fixture('bones-in-channels')).meta;
  assert.ok(bones.chunks.every((c) => c.format === 3 && c.more & 16 && !(c.more & 64)), JSON.stringify(bones.chunks));
  const offsets = (await fixture('offsets-in-channels')).meta;
  assert.ok(offsets.chunks.every((c) => c.more & 64), JSON.stringify(offsets.chunks));
  for (const name of ['dummy-root', 'dummy-root-bind']) {
    const turned = (await fixture(name)).meta;
    assert.ok(turned.chunks.every((c) => c.more & 32), `${name}: ${JSON.stringify(turned.chunks)}`);
  }
});

test('a rig without channels (an empty kinwave body) opens with its frames and joints', async () => {
  const data = new Uint8Array(await readFile(new URL('still-rig.moc', MOC)));
  const meta = JSON.parse(await readFile(new URL('still-rig.json', MOC), 'utf8'));
  const decoded = await decodeMoc(data);
  assert.equal(decoded.frames, meta.frames);
  assert.equal(decoded.fps, meta.fps);
  assert.equal(decoded.skeleton.joints.length, meta.joints);
  assert.equal(decoded.channels.length, 0);
});

test('a frame range decodes only its chunks and equals the whole file\'s frames', async () => {
  const { data, meta } = await fixture('bvh-joint');
  const whole = await decodeMoc(data);
  const C = meta.channels;
  for (const [a, b] of [[0, 1], [250, 262], [255, 257], [meta.frames - 3, meta.frames], [10, 10]]) {
    const part = await decodeMoc(data, { frames: [a, b] });
    assert.equal(part.frames, b - a);
    assert.deepEqual(part.channels, whole.channels.subarray(a * C, b * C));
  }
  await assert.rejects(decodeMoc(data, { frames: [5, meta.frames + 1] }), RangeError);
  await assert.rejects(decodeMoc(data, { maxValues: 1000 }), /over the limit/);
});

async function expectDecodeError(data, pattern = null) {
  try {
    await decodeMoc(data);
  } catch (e) {
    if (!(e instanceof DecodeError)) throw e;
    if (pattern) assert.match(e.message, pattern);
    return e;
  }
  return null;
}

function withCrc(bytes) {
  const out = new Uint8Array(bytes.length + 4);
  out.set(bytes);
  new DataView(out.buffer).setUint32(bytes.length, crc32(bytes, 0, bytes.length), true);
  return out;
}

// A .moc with its header's JSON replaced, deflated with the dictionary of ``version`` (the file's
// own by default), in that version's layout: versions 1 and 2 have a fixed-width start, and a
// one-chunk file of version 3 gets back its chunk's length, index and footer (CRCs recomputed).
function withHeader(data, edit, version = data[4]) {
  let [flags, headAt, headLength] = [u16(data, 6), 12, u32(data, 8)];
  if (data[4] >= 3) {
    let pos;
    [flags, pos] = readVarint(data, 6);
    [headLength, headAt] = readVarint(data, pos);
  }
  const text = inflateSync(data.subarray(headAt, headAt + headLength), { dictionary: HEADER_DICTIONARIES[data[4]] });
  const split = text.indexOf(0);
  const json = JSON.parse(text.subarray(0, split).toString());
  const head = deflateSync(Buffer.concat([Buffer.from(JSON.stringify(edit(json))), text.subarray(split)]), { dictionary: HEADER_DICTIONARIES[version] });
  let chunks = data.subarray(headAt + headLength + 4);
  if (flags & 2 && version < 3) {
    const body = chunks.subarray(0, chunks.length - 4);
    const chunk = withCrc(Buffer.concat([varint(body.length), body]));
    const index = withCrc(Buffer.concat([varint(1), varint(json.frames), varint(chunk.length)]));
    const footer = Buffer.alloc(8);
    footer.writeUInt32LE(index.length);
    footer.write('MOCX', 4);
    [flags, chunks] = [flags & 1, Buffer.concat([chunk, index, footer])];
  }
  const start = Buffer.alloc(version >= 3 ? 6 : 12);
  start.write('MOC1');
  start.writeUInt16LE(version, 4);
  if (version < 3) {
    start.writeUInt16LE(flags, 6);
    start.writeUInt32LE(head.length, 8);
  }
  const sizes = version >= 3 ? [varint(flags), varint(head.length)] : [];
  return Uint8Array.from(Buffer.concat([start, ...sizes, withCrc(head), chunks]));
}

test('hostile headers: clear errors naming what is wrong', async () => {
  const { data } = await fixture('asf-30fps-shell');
  await expectDecodeError(withHeader(data, (h) => ({ ...h, codec: { codec: 'spiht', knobs: {} } })), /kinwave files only/);
  await expectDecodeError(withHeader(data, (h) => ({ ...h, frames: h.frames + 1 })), /cover/);
  await expectDecodeError(withHeader(data, (h) => ({ ...h, fps: -1 })), /fps/);
  await expectDecodeError(withHeader(data, (h) => ({ ...h, fps: 1e-300 })), /fps/); // once a 300-digit duration
  await expectDecodeError(withHeader(data, (h) => ({ ...h, codec: 3 })), /codec/);
  const decoded = await decodeMoc(withHeader(data, (h) => h));
  assert.equal(decoded.frames, (await decodeMoc(data)).frames);
  await expectDecodeError(data.subarray(0, 5), /not a .moc file/);
  await expectDecodeError(data.subarray(0, 10), /a header of \d+ bytes does not fit in the file/);
  await expectDecodeError(Uint8Array.from(data, (b, i) => (i === 4 ? 4 : b)), /version 4; this decoder reads versions 1, 2, 3/);
  await expectDecodeError(Uint8Array.from(data, (b, i) => (i === 6 ? b | 4 : b)), /flags 7 set bits version 3 does not define/);
  const older = withHeader(data, (h) => h, 2);
  await expectDecodeError(Uint8Array.from(older, (b, i) => (i === 6 ? b | 2 : b)), /flags 3 set bits version 2 does not define/);
});

test('files of versions 1 and 2 (a fixed-width start, an index; version 1\'s first dictionary) decode as the version 3 file', async () => {
  for (const name of ['asf-30fps-shell', 'bvh-joint']) {
    const { data } = await fixture(name);
    assert.equal(data[4], 3);
    const b = await decodeMoc(data);
    const sizes = [];
    for (const version of [1, 2]) {
      const old = withHeader(data, (h) => h, version);
      assert.equal(old[4], version);
      sizes.push(old.length);
      const a = await decodeMoc(old);
      assert.equal(a.frames, b.frames);
      assert.deepEqual(Array.from(a.channels), Array.from(b.channels));
    }
    assert.ok(sizes[0] > sizes[1] && sizes[1] > data.length, 'the newer dictionary holds kinwave\'s settings; version 3 frames one chunk in fewer bytes');
  }
});

test('an index claiming more chunks than its bytes hold is refused before it is read', async () => {
  const { data } = await fixture('bvh-joint');
  const file = await openMoc(data);
  const last = file.chunks.at(-1);
  const indexAt = last.offset + last.size;
  const raw = Uint8Array.from([0x80, 0x80, 0x04]); // 65,536 chunks
  const out = new Uint8Array(indexAt + raw.length + 4 + 8);
  out.set(data.subarray(0, indexAt));
  out.set(raw, indexAt);
  const view = new DataView(out.buffer);
  view.setUint32(indexAt + raw.length, crc32(raw, 0, raw.length), true);
  view.setUint32(indexAt + raw.length + 4, raw.length + 4, true);
  out.set(new TextEncoder().encode('MOCX'), indexAt + raw.length + 8);
  await expectDecodeError(out, /65536 chunks do not fit/);
});

test('damaged and truncated files end in DecodeError, never another error or a hang', async () => {
  const { data } = await fixture('dummy-root-bind');
  const random = seeded(2027);
  let errors = 0;
  for (let cut = 0; cut < data.length; cut += 7) if (await expectDecodeError(data.subarray(0, cut))) errors += 1;
  for (let trial = 0; trial < 300; trial++) {
    const damaged = Uint8Array.from(data);
    for (let n = 0; n < 1 + random() * 3; n++) damaged[Math.floor(random() * damaged.length)] ^= 1 << Math.floor(random() * 8);
    if (await expectDecodeError(damaged)) errors += 1;
  }
  assert.ok(errors > 300);
});

test('damaged kinwave bodies (past the CRC) end in DecodeError or decode to finite values', async () => {
  const { decodeKinwave } = await import('../../js/src/kinwave.js');
  for (const name of ['glitch', 'bones-in-channels']) { // (isolated frames; mirrored constants)
    const { data } = await fixture(name);
    const file = await openMoc(data);
    const body = chunkBody(data, file.chunks[0], 0);
    const random = seeded(99);
    for (let trial = 0; trial < 400; trial++) {
      const damaged = Uint8Array.from(body.subarray(0, random() < 0.2 ? Math.floor(random() * body.length) : body.length));
      for (let n = 0; n < 1 + random() * 4; n++) damaged[Math.floor(random() * damaged.length)] = Math.floor(random() * 256);
      try {
        const out = decodeKinwave(damaged, file.skeleton, file.chunks[0].count);
        assert.ok(out.every((v) => !Number.isNaN(v)));
      } catch (e) {
        if (!(e instanceof DecodeError)) throw new Error(`${name}, trial ${trial}: ${e.stack}`);
      }
    }
  }
});
