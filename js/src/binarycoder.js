// The binary range decoder of mocodec's context-adaptive coders (coding/entropy/binarycoder.py):
// LZMA's carry-less byte-wise coder, 32-bit range, 16-bit probabilities that mix a fast (1/16) and
// a slow (1/128) adaptation rate. Every operation is integer arithmetic below 2^53, so the decoded
// decisions are bit for bit the Python decoder's. Reads zeros past the end of its data.

export const TOP = 1 << 24;
const HALF = 1 << 15;
const FAST = 4;
const SLOW = 7;
const INIT = 1 << 15;
export const MAX_CLASS = 62;
export const WARM_DONE = 126;
const TWO_32 = 4294967296;
const WARM_SHIFT = Int32Array.from({ length: WARM_DONE + 1 }, (_, n) => Math.min(32 - Math.clz32(n + 2), SLOW));

// Adaptive state of `contexts` binary contexts; `warm` ones adapt fast at first (binarycoder.new_state).
export function newState(contexts, warm = false) {
  return {
    fast: new Int32Array(contexts).fill(INIT),
    slow: new Int32Array(contexts).fill(INIT),
    seen: new Int32Array(contexts).fill(warm ? 0 : WARM_DONE),
  };
}

// One context at a fixed probability of a 0 (out of 65536), never adapted for long: made afresh per use.
export function fixedState(probabilityOfZero) {
  const state = newState(1);
  state.fast[0] = probabilityOfZero;
  state.slow[0] = probabilityOfZero;
  return state;
}

/**
 * The context-adaptive binary arithmetic decoder of kinwave and kinwave-live
 * (coding/entropy/binarycoder.py), bit for bit.
 */
export class BinaryDecoder {
  /** @param {Uint8Array} data the coded bytes (read as zeros past their end) */
  constructor(data) {
    this.data = data;
    this.code = 0;
    this.range = 0xffffffff;
    this.pos = 0;
    for (let k = 0; k < 5; k++) this.code = (this.code * 256 + this.next()) % TWO_32;
  }

  next() {
    const byte = this.pos < this.data.length ? this.data[this.pos] : 0;
    this.pos += 1;
    return byte;
  }

  get(state, ctx) {
    const f = state.fast[ctx];
    const s = state.slow[ctx];
    const bound = (this.range >>> 16) * ((f + s) >> 1);
    const bit = this.code >= bound ? 1 : 0;
    const n = state.seen[ctx];
    const fast = Math.min(FAST, WARM_SHIFT[n]);
    const slow = WARM_SHIFT[n];
    if (bit) {
      this.code -= bound;
      this.range -= bound;
      state.fast[ctx] = f - (f >> fast);
      state.slow[ctx] = s - (s >> slow);
    } else {
      this.range = bound;
      state.fast[ctx] = f + ((65536 - f) >> fast);
      state.slow[ctx] = s + ((65536 - s) >> slow);
    }
    state.seen[ctx] = Math.min(n + 1, WARM_DONE);
    while (this.range < TOP) {
      this.range *= 256;
      this.code = (this.code * 256 + this.next()) % TWO_32;
    }
    return bit;
  }

  getEven() {
    const bound = (this.range >>> 16) * HALF;
    let bit = 0;
    if (this.code < bound) {
      this.range = bound;
    } else {
      this.code -= bound;
      this.range -= bound;
      bit = 1;
    }
    while (this.range < TOP) {
      this.range *= 256;
      this.code = (this.code * 256 + this.next()) % TWO_32;
    }
    return bit;
  }

  // An integer (binarycoder.get_int): zero flag, unary size class, mantissa, sign. Values of 2^40
  // or more are refused (the Python decoder refuses them too, after the packet).
  getInt(state, zctx, uctx, ulen, mctx, sctx) {
    if (this.get(state, zctx) === 0) return 0;
    let k = 0;
    while (k < MAX_CLASS && this.get(state, uctx + Math.min(k, ulen - 1)) === 1) k += 1;
    if (k >= 40) throw new RangeError('an integer of 2^40 or more (the data is damaged)');
    let m = 1;
    if (k > 0) {
      m = m * 2 + this.get(state, mctx + k);
      for (let b = 0; b < k - 1; b++) m = m * 2 + this.getEven();
    }
    return this.get(state, sctx) === 1 ? -m : m;
  }
}
