// One live stream as a receiver follows it (stream/live.LiveDecoder, without concealment): a new
// codec stream at each keyframe, a decoder that finds its own way back after a loss where the
// codec restarts its layers, and frames counted from the packets' first frames.
import { DecodeError, OutOfStepError } from './errors.js';
import { KinwaveLiveDecoder } from './kinwave-live.js';
import { DATA, END, KEYFRAME, codecPayload } from './packets.js';

const DECODERS = { 'kinwave-live': KinwaveLiveDecoder };

// Whether streams of codec `id` decode here.
export function hasDecoder(id) {
  return Object.hasOwn(DECODERS, id);
}

export class StreamDecoder {
  // `info`: a parsed stream header (parseStreamHeader).
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

  // The packet's frames (frames x channels, row-major), or null where it cannot be decoded yet
  // (before a keyframe, out of step after a loss). Damaged packets throw DecodeError.
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
        frames = this.decoder.push(payload);
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
