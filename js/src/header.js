// A stream header's payload (packets.StreamInfo): zlib-deflated JSON of the skeleton, frame rate,
// codec config, name and extra, inflated to at most MAX_HEADER_TEXT bytes and checked.
import { DecodeError } from './errors.js';
import { inflate } from './inflate.js';
import { MAX_FPS, MAX_HEADER_TEXT, MIN_FPS } from './limits.js';
import { Skeleton } from './skeleton.js';


/**
 * A stream's header (Python's `stream.packets.StreamInfo`).
 * @typedef {object} StreamInfo
 * @property {Skeleton} skeleton
 * @property {object} skeletonDoc the skeleton as the header states it (JSON), e.g. to ask a server for its mannequin
 * @property {number} fps
 * @property {object} codec the codec config ({codec, knobs, revision})
 * @property {string} name
 * @property {object} extra what the codec's decoders need beyond the config (`extra.decoder`)
 */

/**
 * A stream header's payload (Python's `stream.packets.StreamInfo`): zlib-deflated JSON of the
 * skeleton, frame rate, codec config, name and extra, inflated to at most MAX_HEADER_TEXT bytes
 * and checked.
 * @param {Uint8Array} payload the header packet's payload
 * @returns {Promise<StreamInfo>}
 * @throws {DecodeError} where it is not such a header
 */
export async function parseStreamHeader(payload) {
  const text = new TextDecoder().decode(await inflate(payload, { limit: MAX_HEADER_TEXT, what: 'stream header' }));
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
  if (typeof fps !== 'number' || !(fps >= MIN_FPS && fps <= MAX_FPS)) throw new DecodeError(`stream header: frame rate ${fps} is outside [${MIN_FPS}, ${MAX_FPS}]`);
  const extra = doc.extra && typeof doc.extra === 'object' ? doc.extra : {};
  return {
    skeleton: new Skeleton(doc.skeleton), skeletonDoc: doc.skeleton, fps, codec: doc.codec, name: String(doc.name ?? ''), extra,
  };
}
