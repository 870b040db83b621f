// One live stream as a receiver follows it (stream/live.LiveDecoder, without concealment): a new
// codec stream at each keyframe, a decoder that finds its own way back after a loss where the
// codec restarts its layers, and frames counted from the packets' first frames.
import { DecodeError, OutOfStepError } from './errors.js';
import { KinwaveLiveDecoder } from './kinwave-live.js';
import { DATA, END, KEYFRAME, RESTART, codecPayload } from './packets.js';

const DECODERS = { 'kinwave-live': KinwaveLiveDecoder };

/**
 * Whether streams of codec `id` decode here.
 * @param {string} id a codec id
 * @returns {boolean}
 */
export function hasDecoder(id) {
  return Object.hasOwn(DECODERS, id);
}

/**
 * One live stream as a receiver follows it (Python's `stream.live.LiveDecoder`, without
 * concealment): a new codec decoder at each keyframe, packets out of step dropped.
 */
export class LiveDecoder {
  /** @param {StreamInfo} info a parsed stream header (parseStreamHeader) */
  constructor(info) {
    const Decoder = DECODERS[info.codec.codec];
    if (!Decoder) throw new DecodeError(`codec ${info.codec.codec} has no decoder here (${Object.keys(DECODERS).join(', ')})`);
    this.info = info;
    this.Decoder = Decoder;
    this.decoder = null;
    this.expected = null;
    this.ended = false;
    this.lost = 0;
    this.lastInts = []; // the integers the last packet held, per layer (what the exactness tests compare)
  }

  // Whether the decoder follows the stream now (false before a keyframe or a restart after a loss).
  get inStep() {
    return this.decoder !== null;
  }

  #fresh() {
    const { skeleton, fps, codec, extra } = this.info;
    return new this.Decoder(skeleton, fps, codec, extra.decoder);
  }

  /**
   * The packet's frames, or null where it cannot be decoded yet (before a keyframe, out of
   * step after a loss).
   * @param {Packet} p
   * @returns {Float64Array | null} frames x channels, row-major
   * @throws {DecodeError} a damaged packet
   */
  push(p) {
    if (p.kind !== DATA || p.codec !== this.info.codec.codec) return null;
    if (this.expected !== null) {
      const ahead = (p.sequence - this.expected) >>> 0;
      if (ahead >= 2 ** 31) return null;
      if (ahead) {
        this.lost += ahead;
        if (this.decoder && !this.decoder.lost()) this.decoder = null;
      }
    }
    this.expected = (p.sequence + 1) >>> 0;
    this.lastInts = [];
    this.ended ||= Boolean(p.flags & END);
    if (p.flags & KEYFRAME) this.decoder = this.#fresh();
    else if (!this.decoder) {
      const decoder = this.#fresh();
      if (!decoder.lost()) return null;
      this.decoder = decoder;
    }
    try {
      const payload = codecPayload(p);
      let frames = new Float64Array(0);
      if (payload.length || p.frames) {
        const dropped = p.dropped ?? 0; // the top layers a relay cut off a layered stream's packet
        if (dropped >= (this.decoder.layerCount ?? 1)) throw new DecodeError(`packet ${p.sequence}: ${dropped} layers cut off a stream of ${this.decoder.layerCount ?? 1}`);
        frames = this.decoder.push(payload, dropped);
        this.lastInts = this.decoder.lastInts ?? [];
      }
      const C = this.info.skeleton.numChannels;
      if (frames.length !== p.frames * C) throw new DecodeError(`packet ${p.sequence} decodes to ${frames.length / C} frames, its header says ${p.frames}`);
      if (p.flags & END) this.decoder = null;
      return frames;
    } catch (e) {
      if (e instanceof OutOfStepError) return null;
      if (this.decoder && !this.decoder.lost()) this.decoder = null;
      throw e;
    }
  }
}

export const MAX_MISSING = 64; // stream/live.py's: a gap waited for, and packets held behind it
export const MAX_HELD = 256;

/**
 * A LiveDecoder that, in step, waits for the packets of a gap in the sequence (the relay resends
 * them on request, `wanted()`): it holds the packets after the gap for up to `holdS` of frames
 * and decodes them in order up to the next gap as each is filled (Python's hold_s).
 */
export class HoldingDecoder {
  /**
   * @param {StreamInfo} info
   * @param {number} holdS seconds of frames it waits for a gap to be filled (0: none)
   */
  constructor(info, holdS) {
    this.stream = new LiveDecoder(info);
    this.holdFrames = Math.ceil(holdS * info.fps);
    this.missing = new Set();
    this.held = new Map(); // sequence -> packet
    this.nextFrame = null; // the frame after the last one decoded
    this.repaired = 0;
  }

  /** @returns {boolean} whether the decoder follows the stream now (false before a keyframe or a restart after a loss) */
  get inStep() {
    return this.stream.inStep;
  }

  #ahead(sequence) {
    return (sequence - (this.stream.expected ?? 0)) >>> 0;
  }

  /** @returns {number[]} the sequence numbers waited for, oldest first */
  wanted() {
    return [...this.missing].sort((a, b) => this.#ahead(a) - this.#ahead(b));
  }

  /**
   * @param {Packet} p
   * @returns {{packet: Packet, frames: Float64Array | null, error?: Error}[]} the packets decoded now
   */
  push(p) {
    const { stream } = this;
    if (!this.holdFrames || p.kind !== DATA || stream.expected === null) return this.#decode([p]);
    const ahead = this.#ahead(p.sequence);
    if (ahead >= 2 ** 31 && !this.missing.has(p.sequence)) return this.#decode([p]);
    if (!this.missing.size) {
      if (ahead === 0 || ahead > MAX_MISSING || !stream.inStep) return this.#decode([p]);
      for (let k = 0; k < ahead; k++) this.missing.add((stream.expected + k) >>> 0);
    } else if (this.missing.delete(p.sequence)) {
      this.repaired += 1;
    } else if (p.flags & (KEYFRAME | RESTART)) { // decodable without the gap: wait no more
      this.held.set(p.sequence, p);
      return this.#release();
    } else {
      const last = [...this.held.keys()].reduce((a, b) => (this.#ahead(b) > this.#ahead(a) ? b : a));
      const beyond = this.#ahead(p.sequence) - this.#ahead(last);
      for (let k = 1; k < Math.min(beyond, MAX_MISSING + 1); k++) this.missing.add((last + k) >>> 0);
    }
    this.held.set(p.sequence, p);
    const out = [];
    while (this.held.has(stream.expected)) { // the packets up to the next gap, once the first is filled
      const next = this.held.get(stream.expected);
      this.held.delete(stream.expected);
      out.push(...this.#decode([next]));
    }
    if (!this.held.size) return out;
    const newest = [...this.held.values()].reduce((a, b) => (this.#ahead(b.sequence) > this.#ahead(a.sequence) ? b : a));
    const late = newest.firstFrame + newest.frames - (this.nextFrame ?? 0) > this.holdFrames;
    if (late || this.held.size > MAX_HELD || this.missing.size > MAX_MISSING) out.push(...this.#release());
    return out;
  }

  #release() {
    const held = [...this.held.values()].sort((a, b) => this.#ahead(a.sequence) - this.#ahead(b.sequence));
    this.held.clear();
    this.missing.clear();
    return this.#decode(held);
  }

  // Each packet through the LiveDecoder in turn; a damaged one is given as frames null with
  // its error, and the rest still decode.
  #decode(packets) {
    return packets.map((packet) => {
      try {
        const frames = this.stream.push(packet);
        if (frames) this.nextFrame = packet.firstFrame + packet.frames;
        return { packet, frames };
      } catch (error) {
        if (!(error instanceof DecodeError)) throw error;
        return { packet, frames: null, error };
      }
    });
  }
}
