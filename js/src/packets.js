// Stream packets and batches as the relay and `mocodec publish` send them (docs/formats.md,
// "Stream packets and batches"): full packets (magic "MP", CRC-32) and compact data packets (a tag
// with its top bit set, varints, CRC-16), which a receiver reads against its stream's cursor.
import { DecodeError } from './errors.js';
import { crc16, crc32, i16, readVarint, u16, u32 } from './bytes.js';
import { MAX_PAYLOAD_FRAMES } from './limits.js';

export const HEADER = 0;
export const DATA = 1;
export const KEYFRAME = 1;
export const END = 2;
export const CUTS = 4;
export const RESTART = 8;
export const CODECS = ['raw', 'quant', 'dpcm', 'adpcm', 'deadreckoning', 'dct', 'subband', 'spiht',
  'primitives', 'kinwave', 'kinwave-live'];
const FIELDS = 44;
const COMPACT = 0x80;

/**
 * A parsed packet (Python's `stream.packets.Packet`).
 * @typedef {object} Packet
 * @property {number} stream the stream id
 * @property {number} sequence
 * @property {number} timestampUs
 * @property {string} codec the codec id
 * @property {number} firstFrame the first frame it completes at the receiver
 * @property {number} frames how many
 * @property {number[]} position the avatar's root, metres
 * @property {Uint8Array} payload
 * @property {number} kind HEADER or DATA
 * @property {number} flags KEYFRAME, END, CUTS, RESTART
 * @property {number} dropped top layers a relay cut off
 */
const C_EXPLICIT = 8;
const C_POSITION = 16;
const C_RESTART = 32;
const C_SHORT = 64; // an ongoing packet of the usual frame count, the sequence's low 6 bits in the tag
const SHORT_SEQUENCE = 63;
const VERSION = 2;
// A packet's check starts from one of these: the top layers a relay cut off it (packets.CRC16_STARTS).
const CRC16_STARTS = [0xffff, 0x5a5a, 0xa5a5, 0x0f0f];
const CRC32_STARTS = [0, 0x5a5a5a5a, 0xa5a5a5a5, 0x0f0f0f0f];

// Which start the packet's check was computed from (the layers cut off it); a damaged packet matches none.
function droppedLayers(crcOf, starts, stored, end) {
  const dropped = starts.findIndex((start) => crcOf(start) === stored);
  if (dropped < 0) throw new DecodeError('CRC mismatch (damaged packet)', end);
  return dropped;
}

/**
 * The packets of a batch message ("Mb", the packet count and each packet's length as varints,
 * then the packets: format 2), as views into `data`.
 * @param {Uint8Array} data one WebSocket message from the relay
 * @returns {Uint8Array[]} the packets, in order
 * @throws {DecodeError} where the batch does not parse
 */
export function splitBatch(data) {
  if (data.length < 3) throw new DecodeError(`${data.length} bytes, shorter than a batch header`, 0);
  if (data[0] === 0x4d && data[1] === 0x42) throw new DecodeError('a batch of format 1 (u32 lengths); this decoder reads format 2', 0);
  if (data[0] !== 0x4d || data[1] !== 0x62) throw new DecodeError('expected the batch magic "Mb"', 0);
  let [count, pos] = readVarint(data, 2, 5, 'the packet count');
  if (count > data.length - pos) throw new DecodeError(`${count} packets announced, the message is ${data.length} bytes`, 2);
  const lengths = new Array(count);
  for (let k = 0; k < count; k++) [lengths[k], pos] = readVarint(data, pos, 4, `packet ${k}'s length`);
  const out = [];
  for (let k = 0; k < count; k++) {
    if (pos + lengths[k] > data.length) throw new DecodeError(`packet ${k} of ${lengths[k]} bytes runs past the message`, pos);
    out.push(data.subarray(pos, pos + lengths[k]));
    pos += lengths[k];
  }
  if (pos !== data.length) throw new DecodeError(`packet lengths add up to ${pos} bytes, the message is ${data.length}`, 2);
  return out;
}

// What a receiver keeps per stream to place its compact packets (packets.Cursor).
export class Cursor {
  constructor(codec, synced = true, usualFrames = 0) {
    this.codec = codec;
    this.usualFrames = usualFrames; // a full packet's frame count, from the stream header (0: none)
    this.nextSequence = 0;
    this.nextFrame = 0;
    this.position = [0, 0, 0];
    this.synced = synced;
  }

  advance(p) {
    if (this.synced && ((p.sequence - this.nextSequence) >>> 0) >= 2 ** 31) return; // behind: a duplicate
    this.nextSequence = (p.sequence + 1) >>> 0;
    this.nextFrame = p.firstFrame + p.frames;
    this.position = p.position;
    this.synced = true;
  }
}

function parseFull(data) {
  if (data.length < FIELDS + 4) throw new DecodeError(`${data.length} bytes, shorter than the ${FIELDS + 4}-byte packet frame`, 0);
  if (data[0] !== 0x4d || data[1] !== 0x50) throw new DecodeError('expected the packet magic "MP"', 0);
  if (data[2] !== VERSION) throw new DecodeError(`packet version ${data[2]}, this decoder reads ${VERSION}`, 2);
  const kind = data[3];
  const flags = data[4];
  const number = data[5];
  if ((kind !== HEADER && kind !== DATA) || number >= CODECS.length) {
    throw new DecodeError(`unknown packet kind ${kind} or codec number ${number}`, 3);
  }
  const length = u32(data, FIELDS - 4);
  if (data.length !== FIELDS + 4 + length) {
    throw new DecodeError(`payload of ${length} bytes announced, ${data.length - FIELDS - 4} present`, FIELDS - 4);
  }
  const end = FIELDS + length;
  const dropped = droppedLayers((start) => crc32(data, 0, end, start), CRC32_STARTS, u32(data, end), end);
  if (dropped && kind !== DATA) throw new DecodeError('CRC mismatch (damaged packet)', end);
  const view = new DataView(data.buffer, data.byteOffset, data.byteLength);
  return {
    stream: u32(data, 6),
    sequence: u32(data, 10),
    timestampUs: Number(view.getBigUint64(14, true)),
    codec: CODECS[number],
    firstFrame: u32(data, 22),
    frames: u16(data, 26),
    position: [view.getFloat32(28, true), view.getFloat32(32, true), view.getFloat32(36, true)],
    payload: data.subarray(FIELDS, end),
    kind,
    flags,
    dropped,
  };
}

function parseCompact(data, cursorOf) {
  if (data.length < 4) throw new DecodeError(`${data.length} bytes, shorter than a compact packet`, 0);
  const end = data.length - 2;
  const dropped = droppedLayers((start) => crc16(data, 0, end, start), CRC16_STARTS, u16(data, end), end);
  const tag = data[0];
  const short = (tag & C_SHORT) !== 0;
  const flags = short ? 0 : tag; // a short tag's low bits are the sequence number's
  const body = data.subarray(0, end);
  let [stream, pos] = readVarint(body, 1, 5, 'the stream id');
  if (!short && pos >= body.length) throw new DecodeError('the packet ends before its sequence byte', pos);
  const cursor = cursorOf(stream);
  if (!cursor) throw new DecodeError(`a compact packet of stream ${stream} before its stream header`, 0);
  let frames;
  let low;
  let window;
  if (short) {
    if (!cursor.usualFrames) throw new DecodeError(`a short packet of stream ${stream}, whose header gives no usual frame count`, 0);
    [frames, low, window] = [cursor.usualFrames, tag & SHORT_SEQUENCE, SHORT_SEQUENCE + 1];
  } else {
    [low, window] = [body[pos], 256];
    [frames, pos] = readVarint(body, pos + 1, 3, 'the frame count');
  }
  let sequence;
  let first;
  if (flags & C_EXPLICIT) {
    [sequence, pos] = readVarint(body, pos, 5, 'the sequence number');
    [first, pos] = readVarint(body, pos, 5, 'the first frame');
  }
  if (!(flags & C_EXPLICIT) && !cursor.synced) throw new DecodeError(`stream ${stream}: a packet before the first keyframe received`, 0);
  if (flags & C_EXPLICIT) {
    if ((sequence & 0xff) !== low || sequence > 0xffffffff) throw new DecodeError(`sequence ${sequence} does not end in byte ${low}`, 0);
  } else {
    const ahead = (((low - cursor.nextSequence + window / 2) % window) + window) % window - window / 2;
    sequence = (cursor.nextSequence + ahead) >>> 0;
    first = Math.max(cursor.nextFrame + ahead * frames, 0);
  }
  let position = cursor.position;
  if (flags & C_POSITION) {
    if (pos + 6 > body.length) throw new DecodeError('the position runs past the packet', pos);
    position = [i16(body, pos) / 100, i16(body, pos + 2) / 100, i16(body, pos + 4) / 100];
    pos += 6;
  }
  if (frames > MAX_PAYLOAD_FRAMES || first > 2 ** 40) throw new DecodeError(`${frames} frames from frame ${first} is not plausible`, 0);
  return {
    stream, sequence, timestampUs: 0, codec: cursor.codec, firstFrame: first, frames, position,
    payload: body.subarray(pos), kind: DATA, flags: (flags & 7) | (flags & C_RESTART ? RESTART : 0), dropped,
  };
}

/**
 * A receiver's reading of packets, full or compact: every stream's cursor (Python's
 * `stream.packets.Reader`).
 */
export class Reader {
  constructor() {
    this.cursors = new Map();
  }

  /**
   * @param {Uint8Array} data one packet
   * @returns {Packet} the packet, its compact fields filled in from its stream's cursor
   * @throws {DecodeError} a damaged packet; {OutOfStepError} a compact one before its stream's keyframe
   */
  read(data) {
    const p = data.length && data[0] & COMPACT ? parseCompact(data, (s) => this.cursors.get(s)) : parseFull(data);
    if (p.kind === HEADER) {
      if (!this.cursors.has(p.stream)) this.cursors.set(p.stream, new Cursor(p.codec, false, p.frames));
    } else {
      if (!this.cursors.has(p.stream)) this.cursors.set(p.stream, new Cursor(p.codec));
      this.cursors.get(p.stream).advance(p);
    }
    return p;
  }
}

/**
 * A data packet's codec payload, without its cut table (flag CUTS).
 * @param {Packet} p
 * @returns {Uint8Array}
 */
export function codecPayload(p) {
  if (!(p.flags & CUTS)) return p.payload;
  if (p.payload.length < 2 || u16(p.payload, 0) > p.payload.length - 2) throw new DecodeError('the cut table overruns the packet', 0);
  return p.payload.subarray(2 + u16(p.payload, 0));
}
