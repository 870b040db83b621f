// .moc files (formats/container.py, versions 1 to 3): the header (deflated with the version's preset dictionary,
// CRC-32 checked) with the codec's config, frame rate, frame count and the compact skeleton; chunks
// of a codec body each, CRC-32 checked; the index and footer at the end, or (version 3's flag 1)
// one chunk of every frame without them. Chunks decode on their own, so a frame range costs only
// its chunks. The JavaScript decoder reads kinwave files that hold their skeleton.
import { crc32, readVarint, u16, u32 } from './bytes.js';
import { unpackSkeleton } from './compact-skeleton.js';
import { DecodeError } from './errors.js';
import { HEADER_DICTIONARIES } from './header-dict.js';
import { inflate } from './inflate.js';
import { decodeKinwave } from './kinwave.js';
import { MAX_DECODED_VALUES, MAX_FPS, MAX_HEADER_TEXT, MAX_PAYLOAD_FRAMES, MIN_FPS } from './limits.js';

const MAGIC = 'MOC1';
const FOOTER_MAGIC = 'MOCX';
const FLAG_SKELETON = 1;
const FLAG_ONE_CHUNK = 2;
const VARINT_START = 3; // the first version whose flags and header length are varints
const OPENING = 6; // magic and version, in every version
const START = 12; // versions 1 and 2: magic, version, u16 flags, u32 header length
const FOOTER = 8;
const MAX_HEADER = 1 << 24;
const MAX_CHUNKS = 1 << 20;
const MIN_CHUNK_BYTES = 5; // a one-byte length, no body, a CRC-32

function ascii(data, pos) {
  return String.fromCharCode(...data.subarray(pos, pos + 4));
}

/**
 * The header and index of .moc bytes, every length and check verified.
 * @param {Uint8Array} data
 * @returns {Promise<{header: object, skeleton: Skeleton, fps: number, frames: number, codec: object,
 *   chunks: {offset: number, first: number, count: number, size: number, bare?: boolean}[], headAt: number}>}
 *   `bare`: the file's one chunk, without a length; `headAt`: the header's first byte
 * @throws {DecodeError} where the file is damaged or not a .moc file
 */
export async function openMoc(data) {
  if (data.length < OPENING) throw new DecodeError(`not a .moc file: ${data.length} bytes`, 0);
  if (ascii(data, 0) !== MAGIC) throw new DecodeError(`not a .moc file (starts with ${JSON.stringify(ascii(data, 0))}, expected "MOC1")`, 0);
  const version = u16(data, 4);
  const dictionary = HEADER_DICTIONARIES[version];
  if (!dictionary) throw new DecodeError(`.moc version ${version}; this decoder reads versions ${Object.keys(HEADER_DICTIONARIES).join(', ')}`, 4);
  const { flags, headAt, headLength } = opening(data, version);
  if (headLength > MAX_HEADER || headAt + headLength + 4 > data.length) throw new DecodeError(`a header of ${headLength} bytes does not fit in the file`, OPENING);
  const head = data.subarray(headAt, headAt + headLength);
  if (crc32(head, 0, head.length) !== u32(data, headAt + headLength)) throw new DecodeError('header CRC mismatch, the header is damaged', headAt);
  const text = await inflate(head, { limit: MAX_HEADER_TEXT, dictionary, what: `header at byte ${headAt}` });
  const split = flags & FLAG_SKELETON ? text.indexOf(0) : text.length;
  if (split < 0) throw new DecodeError('the header has no compact skeleton after its JSON', headAt);
  let header;
  try {
    header = JSON.parse(new TextDecoder('utf-8', { fatal: true }).decode(text.subarray(0, split)));
  } catch (e) {
    throw new DecodeError(`header does not parse (${e.message})`, headAt);
  }
  if (!header || typeof header !== 'object' || !header.codec || typeof header.codec !== 'object') {
    throw new DecodeError('header: expected an object with a codec config', headAt);
  }
  if (!(flags & FLAG_SKELETON)) {
    throw new DecodeError('the file holds only its skeleton\'s id: encode it with its skeleton (without --skeleton-ref) to decode it here', 6);
  }
  const skeleton = unpackSkeleton(text.subarray(split + 1));
  const { frames, fps } = header;
  if (!Number.isSafeInteger(frames) || frames < 0 || typeof fps !== 'number' || !(fps >= MIN_FPS && fps <= MAX_FPS)) {
    throw new DecodeError(`header says ${frames} frames at ${fps} fps`, headAt);
  }
  const chunksAt = headAt + headLength + 4;
  if (flags & FLAG_ONE_CHUNK) {
    if (!(frames > 0 && frames <= MAX_PAYLOAD_FRAMES) || data.length - chunksAt < 4) {
      throw new DecodeError(`a chunk of ${frames} frames in the ${data.length - chunksAt} bytes after the header is invalid`, chunksAt);
    }
    const chunks = [{ offset: chunksAt, first: 0, count: frames, size: data.length - chunksAt, bare: true }];
    return { header, skeleton, fps, frames, codec: header.codec, chunks, headAt };
  }
  const chunks = index(data, chunksAt);
  const covered = chunks.reduce((n, e) => n + e.count, 0);
  if (covered !== frames) throw new DecodeError(`the index's chunks cover ${covered} frames, the header says ${frames}`, data.length - FOOTER);
  return { header, skeleton, fps, frames, codec: header.codec, chunks, headAt };
}

// The flags, where the header starts and its length: fixed widths before VARINT_START, varints from it.
function opening(data, version) {
  let flags;
  let headAt;
  let headLength;
  let defined = FLAG_SKELETON;
  if (version < VARINT_START) {
    if (data.length < START + FOOTER) throw new DecodeError(`not a .moc file: ${data.length} bytes`, 0);
    [flags, headLength, headAt] = [u16(data, 6), u32(data, 8), START];
  } else {
    let pos;
    [flags, pos] = readVarint(data, OPENING, 10, 'the flags');
    [headLength, headAt] = readVarint(data, pos, 10, "the header's length");
    defined |= FLAG_ONE_CHUNK;
  }
  if (flags & ~defined || flags > 0xffff) throw new DecodeError(`flags ${flags} set bits version ${version} does not define`, OPENING);
  return { flags, headAt, headLength };
}

function index(data, chunksAt) {
  const footAt = data.length - FOOTER;
  const length = u32(data, footAt);
  if (ascii(data, footAt + 4) !== FOOTER_MAGIC) throw new DecodeError('the footer is damaged or the file is truncated', footAt);
  const at = footAt - length;
  if (length < 5 || at < chunksAt) throw new DecodeError(`an index of ${length} bytes does not fit in the file`, footAt);
  const raw = data.subarray(at, footAt);
  if (crc32(raw, 0, length - 4) !== u32(raw, length - 4)) throw new DecodeError('index CRC mismatch, the index is damaged', at);
  let [n, pos] = readVarint(raw, 0, 10, 'the chunk count');
  if (n > Math.min(MAX_CHUNKS, Math.floor((at - chunksAt) / MIN_CHUNK_BYTES))) {
    throw new DecodeError(`${n} chunks do not fit in ${at - chunksAt} bytes of chunks`, at);
  }
  const chunks = [];
  let offset = chunksAt;
  let first = 0;
  for (let k = 0; k < n; k++) {
    let count;
    let size;
    [count, pos] = readVarint(raw, pos, 10, `index entry ${k}`);
    [size, pos] = readVarint(raw, pos, 10, `index entry ${k}`);
    if (!(count > 0 && count <= MAX_PAYLOAD_FRAMES) || size < 5) throw new DecodeError(`index entry ${k} (${count} frames in ${size} bytes) is invalid`, at + pos);
    chunks.push({ offset, first, count, size });
    offset += size;
    first += count;
    if (offset > at) break;
  }
  if (pos !== length - 4 || offset !== at) throw new DecodeError('the index\'s entries do not match the file\'s layout', at);
  return chunks;
}

// The codec body of chunk `k`, length- and CRC-checked (a one-chunk file's has no length).
export function chunkBody(data, chunk, k) {
  const bytes = data.subarray(chunk.offset, chunk.offset + chunk.size);
  const [length, start] = chunk.bare ? [chunk.size - 4, 0] : readVarint(bytes, 0, 10, `chunk ${k}'s length`);
  if (start + length + 4 !== chunk.size) throw new DecodeError(`chunk ${k}: a ${length}-byte body does not fill its ${chunk.size} bytes`, chunk.offset);
  if (crc32(bytes, 0, chunk.size - 4) !== u32(bytes, chunk.size - 4)) throw new DecodeError(`chunk ${k}: CRC mismatch, the chunk is damaged`, chunk.offset);
  return bytes.subarray(start, chunk.size - 4);
}

/**
 * Decode .moc bytes: all frames, or a range (only the chunks it needs).
 * @param {Uint8Array} data
 * @param {{frames?: [number, number] | null, maxValues?: number}} [options] `frames`: [first, stop];
 *   `maxValues`: the most values (frames x channels) it may decode
 * @returns {Promise<{skeleton: Skeleton, fps: number, codec: object, first: number, frames: number,
 *   channels: Float64Array}>} `channels`: frames x channels, row-major
 * @throws {DecodeError}
 */
export async function decodeMoc(data, { frames = null, maxValues = MAX_DECODED_VALUES } = {}) {
  const file = await openMoc(data);
  const [first, stop] = frames ?? [0, file.frames];
  if (!(Number.isInteger(first) && Number.isInteger(stop) && first >= 0 && first <= stop && stop <= file.frames)) {
    throw new RangeError(`frames ${first}:${stop} are outside 0:${file.frames}`);
  }
  if (file.codec.codec !== 'kinwave') throw new DecodeError(`codec ${JSON.stringify(file.codec.codec)}: this decoder reads kinwave files only`, file.headAt);
  const C = file.skeleton.numChannels;
  const wanted = file.chunks.map((e, k) => [e, k]).filter(([e]) => e.first < stop && e.first + e.count > first);
  const values = wanted.reduce((n, [e]) => n + e.count, 0) * C;
  if (values > maxValues) throw new DecodeError(`decoding frames ${first}:${stop} makes ${values} values, over the limit of ${maxValues}`);
  const channels = new Float64Array((stop - first) * C);
  for (const [e, k] of wanted) {
    const body = chunkBody(data, e, k);
    let decoded;
    try {
      // a rig without channels is an empty body (Python's Codec.encode)
      decoded = C === 0 && body.length === 0 ? new Float64Array(0) : decodeKinwave(body, file.skeleton, e.count);
    } catch (err) {
      if (err instanceof DecodeError) throw new DecodeError(`chunk ${k} at byte ${e.offset}: ${err.message}`);
      throw err;
    }
    const from = Math.max(first - e.first, 0);
    const to = Math.min(stop - e.first, e.count);
    channels.set(decoded.subarray(from * C, to * C), (e.first + from - first) * C);
  }
  return { skeleton: file.skeleton, fps: file.fps, codec: file.codec, first, frames: stop - first, channels };
}
