// The kinwave-live decoder (codecs/kinwave/live.py): per layer, the packet's head and integers
// from the binary arithmetic decoder (contexts carried across packets), then closed-loop
// reconstruction with the encoder's arithmetic (order-2 or order-1 prediction, each channel's
// order chosen from its decoded frames, clamped to the quantiser cell of the layer below, plus
// the integer times the channel's step). Format revision 3 only. Step tables come
// from the stream header (`extra.decoder.base_codes`), as the convex allocation that makes them
// cannot be redone bit for bit here; so does the reference pose a codec stream's first frame is
// predicted from, where the header gives one (`extra.decoder.reference`).
import { BinaryDecoder, MAX_CLASS, fixedState, newState } from './binarycoder.js';
import { DecodeError, OutOfStepError } from './errors.js';
import { MAX_DECODED_VALUES } from './limits.js';
import { CODE_STEP } from './steps.js';

const ULEN = 6;
const PER_CHANNEL = 7 + ULEN + MAX_CLASS + 1;
const HEAD_CONTEXTS = 2 + 3 * PER_CHANNEL;
const ROUNDING = 0.25;
const MAX_OFFSET = 127;
const MAX_LAYERS = 4;
const MAX_REFERENCE = 1e9; // live.MAX_REFERENCE
const RESTART_ZERO = 65536 - 65536 / 16; // the restart flag's fixed probability of a 0
const MISS_DECAY = 0.5;
const DRIFT = 1; // live.DRIFT: the usual change of the scale offset
export const REVISION = 3; // the format revision this decoder reads (live.KinwaveLiveCodec.revision)


/**
 * Frames per packet: as many as fit in 50 ms, at least one (Python's `live.packet_frames`).
 * @param {number} fps
 * @returns {number}
 */
export function packetFrames(fps) {
  return Math.max(Math.floor(fps * 0.05 + 1e-9), 1);
}

// A packet as the arithmetic decoder reads it: its always-zero first byte put back.
function packetData(packet) {
  const data = new Uint8Array(packet.length + 1);
  data.set(packet, 1);
  return data;
}

class Cells {
  constructor(frames, channels) {
    this.frames = frames;
    this.channels = channels;
    this.lo = new Float64Array(frames * channels).fill(-Infinity);
    this.hi = new Float64Array(frames * channels).fill(Infinity);
  }

  // the row of coded frame t at a stride: frame (t + 1) * stride - 1
  row(t, stride) {
    return ((t + 1) * stride - 1) * this.channels;
  }
}

class Layer {
  constructor(skeleton, codes, tables) {
    this.skeleton = skeleton;
    this.tables = tables;
    this.codes = codes;
    this.restart();
  }

  restart() {
    const { channels, contexts, guess } = this.tables;
    this.state = newState(contexts, true);
    this.lastNonzero = new Uint8Array(channels);
    this.history = [new Float64Array(channels), Float64Array.from(guess)];
    this.countHistory = 1;
    this.started = false;
    this.gap = 1;
    this.offset = 0;
    this.trust = new Uint8Array(channels).fill(1);
    this.misses = [new Float64Array(channels), new Float64Array(channels)];
  }

  steps(offset) {
    const { channelCode, translation } = this.tables;
    const units = this.skeleton.unitsPerMetre;
    return Float64Array.from(channelCode, (k, c) => {
      const code = Math.min(Math.max(this.codes[k] + offset, 0), 255);
      return translation[c] ? (CODE_STEP[code] * units) / 100.0 : CODE_STEP[code];
    });
  }
}

// The tables every layer of a skeleton shares: joints with channels, the step code of each
// channel, the guess before the first frame (translations of joints below the root at their offsets).
function layerTables(skeleton) {
  const first = [];
  const count = [];
  skeleton.joints.forEach((j, i) => {
    if (j.channels.length) {
      first.push(skeleton.channelOffsets[i]);
      count.push(j.channels.length);
    }
  });
  const channels = skeleton.numChannels;
  const channelCode = new Int32Array(channels);
  const translation = new Uint8Array(channels);
  let rotationJoints = 0;
  const guess = new Float64Array(channels);
  skeleton.joints.forEach((j, i) => {
    for (let a = 0; a < 3; a++) {
      const c = skeleton.posIndex[3 * i + a];
      if (c >= 0) {
        translation[c] = 1;
        if (i > 0) guess[c] = skeleton.offsets[3 * i + a];
      }
    }
    let rotated = false;
    for (let s = 0; s < 3; s++) {
      const c = skeleton.rotIndex[3 * i + s];
      if (c >= 0) {
        channelCode[c] = rotationJoints;
        rotated = true;
      }
    }
    if (rotated) rotationJoints += 1;
  });
  const hasTranslation = translation.some((t) => t);
  translation.forEach((t, c) => { if (t) channelCode[c] = rotationJoints; });
  const codesPerLayer = rotationJoints + (hasTranslation ? 1 : 0);
  return {
    first: Int32Array.from(first), count: Int32Array.from(count), channels, channelCode,
    translation, guess, codesPerLayer, contexts: HEAD_CONTEXTS + first.length + channels * PER_CHANNEL,
  };
}

/**
 * The kinwave-live stream decoder (codecs/kinwave/live/decoder.py), bit for bit: every layer a
 * packet carries that it is in step with.
 */
export class KinwaveLiveDecoder {
  /**
   * @param {Skeleton} skeleton
   * @param {number} fps
   * @param {object} config the codec config of the stream header
   * @param {object} decoderTables the header's `extra.decoder` (base step codes, reference pose)
   * @throws {DecodeError} where the header does not fit
   */
  constructor(skeleton, fps, config, decoderTables) {
    const revision = config?.revision ?? 1;
    if (revision !== REVISION) throw new DecodeError(`kinwave-live data of format revision ${JSON.stringify(revision)}; this decoder reads revision ${REVISION}`);
    const knobs = config?.knobs && typeof config.knobs === 'object' ? config.knobs : {};
    const layers = knobs.layers ?? 1;
    if (!Number.isInteger(layers) || layers < 1 || layers > MAX_LAYERS) throw new DecodeError(`kinwave-live: ${layers} layers`);
    const codes = decoderTables?.base_codes;
    this.tables = layerTables(skeleton);
    if (!Array.isArray(codes) || codes.length !== layers || codes.some((c) => !Array.isArray(c)
      || c.length !== this.tables.codesPerLayer || c.some((v) => !Number.isInteger(v) || v < 0 || v > 255))) {
      throw new DecodeError(`kinwave-live: the stream header's base_codes must be ${layers} lists of ${this.tables.codesPerLayer} step codes`);
    }
    this.size = packetFrames(fps);
    if (this.size * skeleton.numChannels > MAX_DECODED_VALUES) {
      throw new DecodeError(`kinwave-live: packets of ${this.size} frames of ${skeleton.numChannels} channels are over ${MAX_DECODED_VALUES} values`);
    }
    const reference = decoderTables.reference;
    if (reference !== undefined) {
      if (!Array.isArray(reference) || reference.length !== skeleton.numChannels
        || reference.some((v) => typeof v !== 'number' || !Number.isFinite(v) || Math.abs(v) > MAX_REFERENCE)) {
        throw new DecodeError(`kinwave-live: the stream header's reference pose must be ${skeleton.numChannels} numbers within ${MAX_REFERENCE}`);
      }
      this.tables = { ...this.tables, guess: Float64Array.from(reference) };
    }
    this.skeleton = skeleton;
    this.layers = codes.map((c) => new Layer(skeleton, c, this.tables));
    this.layerInStep = this.layers.map(() => true);
    this.refresh = Boolean(knobs.refresh_s);
    this.lastInts = [];
  }

  get inStep() {
    return this.layerInStep[0];
  }

  // A packet was lost: every layer is out of step; true if the stream restarts layers on its own.
  lost() {
    this.layerInStep.fill(false);
    return this.refresh;
  }

  get layerCount() {
    return this.layers.length;
  }

  /**
   * The packet's frames, from the top layer it decodes: its layers are one arithmetic-coded
   * stream, base first, after every layer's restart flag (with refresh).
   * @param {Uint8Array} packet the codec payload
   * @param {number} [dropped] top layers a relay cut off
   * @returns {Float64Array} frames x channels, row-major
   * @throws {DecodeError} damaged; {OutOfStepError} waiting for the base layer to restart
   */
  push(packet, dropped = 0) {
    const carried = this.layers.length - dropped;
    if (!(Number.isInteger(dropped) && carried >= 1 && dropped >= 0)) throw new DecodeError(`kinwave-live: ${dropped} layers cut off a stream of ${this.layers.length}`);
    const decoder = new BinaryDecoder(packetData(packet));
    const restarts = this.layers.map(() => (this.refresh ? decoder.get(fixedState(RESTART_ZERO), 0) : 0));
    let cells = null;
    let out = null;
    let below = true;
    this.lastInts = [];
    for (let k = 0; k < this.layers.length; k++) {
      if (below && k < carried && restarts[k] === 1) {
        this.layers[k].restart();
        this.layerInStep[k] = true;
      }
      below = below && k < carried && this.layerInStep[k];
      if (!below) {
        this.layerInStep[k] = false;
        continue;
      }
      try {
        [out, cells] = this.#layer(this.layers[k], decoder, cells);
      } catch (e) {
        this.layerInStep.fill(false, k);
        throw e instanceof DecodeError ? e : new DecodeError(`kinwave-live layer ${k}: ${e.message}`);
      }
    }
    if (out === null) throw new OutOfStepError('kinwave-live: waiting for the base layer to restart');
    return out;
  }

  #layer(layer, dec, cells) {
    const C = this.tables.channels;
    const st = layer.state;
    let frames = this.size;
    if (dec.get(st, 0) === 1) frames = dec.getInt(st, 2, 9, ULEN, 9 + ULEN, 8);
    let b = 2 + PER_CHANNEL;
    const change = DRIFT + dec.getInt(st, b, b + 7, ULEN, b + 7 + ULEN, b + 6);
    b = 2 + 2 * PER_CHANNEL;
    const index = dec.getInt(st, b, b + 7, ULEN, b + 7 + ULEN, b + 6);
    const stride = frames >= 1 && frames <= this.size ? strideAt(frames, index) : 0;
    const offset = layer.offset + change;
    if (!(frames >= 1 && frames <= this.size && Math.abs(offset) <= MAX_OFFSET && stride >= 1 && stride <= frames
      && frames % stride === 0 && (stride === 1 || layer.started) && (cells === null || cells.frames === frames))) {
      throw new DecodeError(`kinwave-live packet: ${frames} frames at stride ${stride} and scale offset ${offset} (the data is damaged)`);
    }
    cells = cells ?? new Cells(frames, C);
    const coded = frames / stride;
    const ints = new Float64Array(coded * C);
    this.#ints(dec, layer, coded, ints);
    this.lastInts.push(ints);
    const steps = layer.steps(offset);
    const decoded = new Float64Array(coded * C);
    const cellLo = new Float64Array(coded * C);
    const cellHi = new Float64Array(coded * C);
    this.#predict(layer, stride, steps, cells, ints, decoded, cellLo, cellHi);
    const out = fill(layer.history[1], decoded, coded, C, stride);
    this.#advance(layer, decoded, coded, stride, offset, steps, cells);
    for (let t = 0; t < coded; t++) {
      const row = cells.row(t, stride);
      cells.lo.set(cellLo.subarray(t * C, (t + 1) * C), row);
      cells.hi.set(cellHi.subarray(t * C, (t + 1) * C), row);
    }
    return [out, cells];
  }

  // live._decode_ints: per joint its "any nonzero" flag, then its integers.
  #ints(dec, layer, coded, ints) {
    const { first, count, channels: C } = this.tables;
    const J = first.length;
    const H = HEAD_CONTEXTS;
    const st = layer.state;
    const last = layer.lastNonzero;
    for (let j = 0; j < J; j++) {
      if (dec.get(st, H + j) === 1) {
        for (let t = 0; t < coded; t++) {
          let neighbour = 0;
          for (let c = first[j]; c < first[j] + count[j]; c++) {
            const base = H + J + c * PER_CHANNEL;
            const v = dec.getInt(st, base + 3 * last[c] + neighbour, base + 7, ULEN, base + 7 + ULEN, base + 6);
            ints[t * C + c] = v;
            last[c] = v !== 0 ? 1 : 0;
            neighbour = 1 + last[c];
          }
        }
      } else {
        last.fill(0, first[j], first[j] + count[j]);
      }
    }
  }

  // live._predict with given integers: the same arithmetic, operation for operation.
  #predict(layer, stride, steps, cells, ints, out, cellLo, cellHi) {
    const C = this.tables.channels;
    const [miss1, miss2] = layer.misses;
    const prev0 = Float64Array.from(layer.history[0]);
    const prev1 = Float64Array.from(layer.history[1]);
    let n = layer.countHistory;
    let g = layer.gap;
    const T = out.length / C;
    for (let t = 0; t < T; t++) {
      const ratio = stride / g;
      const row = cells.row(t, stride);
      for (let c = 0; c < C; c++) {
        let pred = 0.0;
        if (n >= 2 && miss2[c] < miss1[c]) pred = prev1[c] + (prev1[c] - prev0[c]) * ratio;
        else if (n >= 1) pred = prev1[c];
        if (layer.trust[c]) pred = Math.min(Math.max(pred, cells.lo[row + c]), cells.hi[row + c]);
        const i = ints[t * C + c];
        out[t * C + c] = pred + i * steps[c];
        const low = i > 0 ? i - ROUNDING : i < 0 ? i - 1 + ROUNDING : ROUNDING - 1;
        cellLo[t * C + c] = pred + low * steps[c];
        cellHi[t * C + c] = pred + (low + (i !== 0 ? 1.0 : 2.0 - 2.0 * ROUNDING)) * steps[c];
      }
      for (let c = 0; c < C; c++) {
        prev0[c] = prev1[c];
        prev1[c] = out[t * C + c];
      }
      n = Math.min(n + 1, 2);
      g = stride;
    }
  }

  // live._advance: the layer's next history, the predictors' misses, and which channels trust
  // the cells below.
  #advance(layer, decoded, coded, stride, offset, steps, cells) {
    const C = this.tables.channels;
    for (let c = 0; c < C; c++) {
      const slack = 0.75 * steps[c];
      let told = false;
      let inside = true;
      for (let t = 0; t < coded; t++) {
        const row = cells.row(t, stride);
        const lo = cells.lo[row + c];
        if (lo === -Infinity) continue; // a finite cell below is a cell told
        told = true;
        const v = decoded[t * C + c];
        if (!(v >= lo - slack && v <= cells.hi[row + c] + slack)) inside = false;
      }
      if (told) layer.trust[c] = inside ? 1 : 0;
    }
    updateMisses(layer, decoded, coded, stride);
    if (coded >= 2) {
      layer.history = [decoded.slice((coded - 2) * C, (coded - 1) * C), decoded.slice((coded - 1) * C)];
    } else {
      layer.history = [layer.history[1], decoded.slice(0, C)];
    }
    layer.gap = stride;
    layer.countHistory = layer.started ? Math.min(layer.countHistory + coded, 2) : Math.min(coded, 2);
    layer.started = true;
    layer.offset = offset;
  }
}

// live._update_misses: each channel's recent miss of the order-1 and order-2 predictions of the
// decoded coded frames, from the layer's history before them; the same arithmetic.
function updateMisses(layer, decoded, coded, stride) {
  const C = layer.tables.channels;
  const [miss1, miss2] = layer.misses;
  const prev0 = Float64Array.from(layer.history[0]);
  const prev1 = Float64Array.from(layer.history[1]);
  let n = layer.started ? layer.countHistory : 0;
  let g = layer.gap;
  for (let t = 0; t < coded; t++) {
    if (n >= 2) {
      const ratio = stride / g;
      for (let c = 0; c < C; c++) {
        const v = decoded[t * C + c];
        const line = prev1[c] + (prev1[c] - prev0[c]) * ratio;
        miss1[c] = miss1[c] * MISS_DECAY + Math.abs(v - prev1[c]);
        miss2[c] = miss2[c] * MISS_DECAY + Math.abs(v - line);
      }
    }
    for (let c = 0; c < C; c++) {
      prev0[c] = prev1[c];
      prev1[c] = decoded[t * C + c];
    }
    n = Math.min(n + 1, 2);
    g = stride;
  }
}

// The stride at ``index`` among the divisors of ``frames``, sparsest first (live._stride_at); 0 if none.
function strideAt(frames, index) {
  for (let d = frames; d > 0; d--) {
    if (frames % d === 0) {
      if (index === 0) return d;
      index--;
    }
  }
  return 0;
}

// All frames of a packet from its coded ones (every stride-th, the last included) and the frame
// before the packet, by straight lines (live._fill).
function fill(previous, coded, count, C, stride) {
  if (stride === 1) return coded;
  const out = new Float64Array(count * stride * C);
  for (let t = 0; t < count; t++) {
    const start = t === 0 ? previous : coded.subarray((t - 1) * C, t * C);
    for (let r = 0; r < stride - 1; r++) {
      const w = (r + 1) / stride;
      const row = (t * stride + r) * C;
      for (let c = 0; c < C; c++) out[row + c] = start[c] + (coded[t * C + c] - start[c]) * w;
    }
    out.set(coded.subarray(t * C, (t + 1) * C), (t * stride + stride - 1) * C);
  }
  return out;
}
