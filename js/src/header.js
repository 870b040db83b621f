// A stream header's payload (packets.StreamInfo): zlib-deflated JSON of the skeleton, frame rate,
// codec config, name and extra, inflated to at most MAX_HEADER_TEXT bytes and checked.
import { DecodeError } from './errors.js';
import { Skeleton } from './skeleton.js';

export const MAX_HEADER_TEXT = 8 << 20;
export const MAX_FPS = 10000;

async function inflate(data) {
  if (typeof DecompressionStream === 'undefined') {
    const zlib = await import('node:zlib');
    try {
      return new Uint8Array(zlib.inflateSync(data, { maxOutputLength: MAX_HEADER_TEXT }));
    } catch (e) {
      throw new DecodeError(`stream header: does not inflate (${e.code ?? e.message})`);
    }
  }
  const reader = new Blob([data]).stream().pipeThrough(new DecompressionStream('deflate')).getReader();
  const parts = [];
  let size = 0;
  try {
    for (;;) {
      const { done, value } = await reader.read();
      if (done) break;
      size += value.length;
      if (size > MAX_HEADER_TEXT) throw new DecodeError(`stream header: inflates past ${MAX_HEADER_TEXT} bytes`);
      parts.push(value);
    }
  } catch (e) {
    await reader.cancel().catch(() => {});
    throw e instanceof DecodeError ? e : new DecodeError(`stream header: does not inflate (${e.message})`);
  }
  const out = new Uint8Array(size);
  let at = 0;
  for (const p of parts) {
    out.set(p, at);
    at += p.length;
  }
  return out;
}

export async function parseStreamHeader(payload) {
  const text = new TextDecoder().decode(await inflate(payload));
  let doc;
  try {
    doc = JSON.parse(text);
  } catch (e) {
    throw new DecodeError(`stream header: not JSON (${e.message})`);
  }
  if (!doc || typeof doc !== 'object' || !doc.codec || typeof doc.codec.codec !== 'string') {
    throw new DecodeError('stream header: expected an object with a codec config naming a codec');
  }
  const fps = doc.fps;
  if (typeof fps !== 'number' || !(fps > 0 && fps <= MAX_FPS)) throw new DecodeError(`stream header: frame rate ${fps} is outside (0, ${MAX_FPS}]`);
  const extra = doc.extra && typeof doc.extra === 'object' ? doc.extra : {};
  return { skeleton: new Skeleton(doc.skeleton), fps, codec: doc.codec, name: String(doc.name ?? ''), extra };
}
