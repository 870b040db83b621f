// zlib streams inflated through the platform (DecompressionStream in browsers and Node >= 20.12), capped
// before the output is kept, with the preset dictionary that .moc headers are deflated with
// (formats/container.py): the platform cannot be given a dictionary, so the raw deflate data is
// read after a stored block holding the dictionary, whose bytes are then dropped. The zlib
// header, the dictionary's id and the Adler-32 of the output are checked here.
import { DecodeError } from './errors.js';

const WINDOW = 32768;

function adler32(data) {
  let a = 1;
  let b = 0;
  for (let i = 0; i < data.length;) {
    const end = Math.min(i + 5552, data.length);
    for (; i < end; i++) {
      a += data[i];
      b += a;
    }
    a %= 65521;
    b %= 65521;
  }
  return b * 65536 + a;
}

function u32be(data, pos) {
  return ((data[pos] << 24) >>> 0) + (data[pos + 1] << 16) + (data[pos + 2] << 8) + data[pos + 3];
}

// A deflate stored block (not the last) holding `bytes` (at most 65,535 of them).
function storedBlock(bytes) {
  const out = new Uint8Array(5 + bytes.length);
  out[1] = bytes.length & 0xff;
  out[2] = bytes.length >> 8;
  out[3] = ~bytes.length & 0xff;
  out[4] = (~bytes.length >> 8) & 0xff;
  out.set(bytes, 5);
  return out;
}

async function readCapped(stream, limit, what) {
  const reader = stream.getReader();
  const parts = [];
  let size = 0;
  try {
    for (;;) {
      const { done, value } = await reader.read();
      if (done) break;
      size += value.length;
      if (size > limit) throw new DecodeError(`${what}: inflates past ${limit} bytes`);
      parts.push(value);
    }
  } catch (e) {
    await reader.cancel().catch(() => {});
    throw e instanceof DecodeError ? e : new DecodeError(`${what}: does not inflate (${e.message})`);
  }
  const out = new Uint8Array(size);
  let at = 0;
  for (const p of parts) {
    out.set(p, at);
    at += p.length;
  }
  return out;
}

async function inflateRaw(raw, dictionary, limit, what) {
  if (typeof DecompressionStream === 'undefined') throw new DecodeError(`${what}: this platform has no DecompressionStream`);
  const history = dictionary ? dictionary.length : 0; // output bytes that are the dictionary's
  const parts = dictionary ? [storedBlock(dictionary), raw] : [raw];
  const stream = new Blob(parts).stream().pipeThrough(new DecompressionStream('deflate-raw'));
  return (await readCapped(stream, limit + history, what)).subarray(history);
}

// The bytes a zlib stream holds, at most `limit` of them; `dictionary` for one deflated with it.
export async function inflate(data, { limit, dictionary = null, what = 'compressed data' }) {
  if (data.length < 6) throw new DecodeError(`${what}: ${data.length} bytes cannot hold a zlib stream`, 0);
  const cmf = data[0];
  const flg = data[1];
  if ((cmf & 15) !== 8 || cmf >> 4 > 7 || (cmf * 256 + flg) % 31) throw new DecodeError(`${what}: not a zlib stream`, 0);
  let start = 2;
  let preset = null;
  if (flg & 0x20) {
    if (!dictionary) throw new DecodeError(`${what}: needs a preset dictionary`, 1);
    preset = dictionary.subarray(Math.max(dictionary.length - WINDOW, 0));
    if (data.length < 10 || u32be(data, 2) !== adler32(dictionary)) throw new DecodeError(`${what}: deflated with another dictionary`, 2);
    start = 6;
  }
  const out = await inflateRaw(data.subarray(start, data.length - 4), preset, limit, what);
  if (adler32(out) !== u32be(data, data.length - 4)) throw new DecodeError(`${what}: Adler-32 mismatch`, data.length - 4);
  return out;
}
