// The decoder of a kinwave body (codecs/kinwave/payload.py, formats 1 to 3; docs/formats.md): header,
// the integers of the coefficient coder, then per channel the trend through its knots plus the
// inverse wavelet of each segment's block, seams smoothed, isolated frames patched, translations
// coded on the world's axes turned back and three-angle joints brought back from their coding
// forms to the file's Euler angles. Integers are the Python decoder's exactly; floats agree to
// rounding (the arithmetic is the same, the order of some sums is not).
import { decodeCoefficients } from './coefcoder.js';
import { DecodeError } from './errors.js';
import { forwardKinematics } from './kinematics.js';
import { DEG, conjugate, quatExp, quatMultiply, rotate } from './quaternions.js';
import { fromForm, validForm, WORLD } from './rotvec.js';
import { smoothSeams } from './seams.js';
import { CODE_STEP, twoToEighths } from './steps.js';
import { WAVELET_IDS, inverseWavelet } from './wavelets.js';

const FORMAT = 1;
const FORMAT_MORE = 2; // format 1 with a byte of more flags after the header
const FORMAT_MIRRORED = 3; // format 2 with a byte m after them: m joints' constant translations against earlier joints'
const REST = 1; // more flags: frame 0 is the rest pose (rotations 0), its translations frame 1's
const REST_AT_ZERO = 2; // ... with every translation 0 too
const REST_TURNED = 3; // ... as REST under the root's turn of frame 1, its children turned back by it
const LEAD_SHIFT = 2; // more flags bits 2-3: the layout's lead (trendwave.layout)
const FINE_CONSTANTS = 16; // more flags bit 4: constant translations at FINE_CONST_FRACTION of their step
const FINE_TURNS = 32; // more flags bit 5: constant rotations of joints above translation channels, the same
const ZERO_CONSTANTS = 64; // more flags bit 6: constant translations about 0, not about their joints' offsets
const CODER_REVISION = 2;
const HEAD_SIZE = 6;
const FLAG_KEYFRAME = 1;
const FLAG_OFFSETS = 8;
const FLAG_FORMS = 16;
const FLAG_SECOND_KEYFRAME = 32;
const FLAG_MEANS = 64;
const FLAG_ISOLATED = 128;
const MAX_ISOLATED = 32;
const MEAN_QUANTUM = 2.0;
const CONST_FRACTION = 1.0 / 8.0;
const FINE_CONST_FRACTION = 1.0 / 64.0;
const KEYFRAME_QUANTUM = 0.5;
const SEAM_HALF_WIDTH = 8;
const SEAM_LIMIT = 1.0;

// Per skeleton, what the payload's layout depends on (payload.step_groups and friends).
const plans = new WeakMap();

function planOf(skeleton) {
  let plan = plans.get(skeleton);
  if (plan) return plan;
  const J = skeleton.joints.length;
  const rotationJoints = [];
  const translation = [];
  const threeAngle = [];
  const base = new Float64Array(skeleton.numChannels);
  // body.translation_triples: per joint with three translation channels, those channels in
  // channel order (the joints whose constant translations a format 3 body may mirror).
  const mirrorable = new Map();
  for (let j = 0; j < J; j++) {
    for (let a = 0; a < 3; a++) {
      const c = skeleton.posIndex[3 * j + a];
      if (c >= 0) {
        translation.push(c);
        base[c] = skeleton.offsets[3 * j + a];
      }
    }
    const position = [0, 1, 2].map((a) => skeleton.posIndex[3 * j + a]);
    if (position.every((c) => c >= 0)) mirrorable.set(j, position.sort((a, b) => a - b));
    const rot = [0, 1, 2].map((s) => skeleton.rotIndex[3 * j + s]).filter((c) => c >= 0);
    if (rot.length) rotationJoints.push({ joint: j, channels: rot });
    if (rot.length === 3) threeAngle.push({ joint: j, channels: rot, order: skeleton.joints[j].rotationOrder });
  }
  const isTranslation = new Uint8Array(skeleton.numChannels);
  for (const c of translation) isTranslation[c] = 1;
  // payload.turns_over_translations: the rotation channels of joints with a translation channel below them.
  const below = new Uint8Array(J);
  for (let j = J - 1; j > 0; j--) {
    const own = skeleton.joints[j].channels.some((c) => c.endsWith('position'));
    if (own || below[j]) below[skeleton.parents[j]] = 1;
  }
  const turnOverTranslation = new Uint8Array(skeleton.numChannels);
  for (const { joint, channels } of rotationJoints) for (const c of channels) turnOverTranslation[c] = below[joint];
  plan = { rotationJoints, translation, isTranslation, turnOverTranslation, threeAngle, base, mirrorable };
  plans.set(skeleton, plan);
  return plan;
}

// trendwave.layout: segments (a keyframe or two, then windows, the first `lead` frames shorter
// and led by as many zeros in its block), knots, blocks.
function layout(frames, window, levels, keyframes, lead) {
  const first = frames > 1 ? Math.min(keyframes, frames - 1) : 0;
  const starts = [];
  if (frames > 0) {
    for (let s = 0; s < first; s++) starts.push(s);
    const windows = [first];
    for (let s = first + (lead && frames > first + 1 ? window - lead : window); s < frames; s += window) windows.push(s);
    if (lead && frames > first + 1 && windows.length > 1 && frames - windows.at(-1) <= lead) windows.pop();
    starts.push(...windows);
  }
  const lengths = starts.map((a, s) => (s + 1 < starts.length ? starts[s + 1] : frames) - a);
  const leads = lengths.map((n, s) => (s === first && n >= 2 ? lead : 0));
  const spans = lengths.map((n, s) => n + leads[s]);
  const segLevels = spans.map((n) => (n < 2 ? 0 : Math.min(levels, 31 - Math.clz32(n))));
  const padded = spans.map((n, s) => (lengths[s] < 2 ? 0 : Math.ceil(n / (1 << segLevels[s])) * (1 << segLevels[s])));
  const knotFrames = [...starts];
  if (frames > 0 && frames - 1 !== starts.at(-1)) knotFrames.push(frames - 1);
  const left = new Int32Array(frames);
  const frac = new Float64Array(frames);
  starts.forEach((a, s) => {
    const end = s + 1 < knotFrames.length ? knotFrames[s + 1] : a;
    for (let i = 0; i < lengths[s]; i++) {
      left[a + i] = s;
      if (end > a) frac[a + i] = i / (end - a);
    }
  });
  const quantum = Float64Array.from(knotFrames, (_, k) => (k < first ? KEYFRAME_QUANTUM : 1.0));
  const offsets = [];
  padded.reduce((at, n) => (offsets.push(at), at + n), 0);
  return { frames, starts, lengths, leads, padded, segLevels, knotFrames, left, frac, quantum, offsets };
}

function cumulative(values, from, count) {
  const out = new Float64Array(count);
  let sum = 0;
  for (let i = 0; i < count; i++) out[i] = sum += values[from + i];
  return out;
}

// Each channel's quantiser step: its joint's code (degrees), or the translation code (cm) in
// skeleton units.
function channelSteps(skeleton, plan, codes) {
  const steps = new Float64Array(skeleton.numChannels);
  plan.rotationJoints.forEach((g, k) => {
    for (const c of g.channels) steps[c] = CODE_STEP[codes[k]];
  });
  const t = (CODE_STEP[codes[codes.length - 1]] * skeleton.unitsPerMetre) / 100.0;
  for (const c of plan.translation) steps[c] = t;
  return steps;
}

// Whether each joint and all above it hold constant rotations (payload.still_rotations).
function stillRotations(skeleton, constant) {
  const J = skeleton.joints.length;
  const still = new Uint8Array(J);
  for (let j = 0; j < J; j++) {
    let own = 1;
    for (let s = 0; s < 3; s++) {
      const c = skeleton.rotIndex[3 * j + s];
      if (c >= 0 && !constant[c]) own = 0;
    }
    const p = skeleton.parents[j];
    still[j] = own && (p < 0 || still[p]) ? 1 : 0;
  }
  return still;
}

// Non-root joints with three moving translations under constant rotations: coded on the world's axes.
function worldTranslations(skeleton, constant) {
  const still = stillRotations(skeleton, constant);
  const out = [];
  for (let j = 1; j < skeleton.joints.length; j++) {
    const pos = [0, 1, 2].map((a) => skeleton.posIndex[3 * j + a]);
    if (still[skeleton.parents[j]] && pos.every((c) => c >= 0) && !pos.some((c) => constant[c])) out.push({ joint: j, pos });
  }
  return out;
}

function damaged(what, offset = null) {
  return new DecodeError(`kinwave payload: ${what}`, offset);
}

// A format 2 or 3 body as { body, frames, rest, lead, fine, fineTurns, aboutZero, mirrored }: the
// format 1 body of the frames after a rest pose in frame 0 (payload.rest_kind), which is not
// coded, its layout's lead, whether its constant translations and its constant rotations of
// joints above translation channels are fine and whether its constant translations are coded
// about 0 instead of the offsets (body.ConstantCoding), and (format 3) how many joints' constant
// translations are mirrored; a format 1 body as it is, rest 0, lead 0, none of them.
function withoutMore(body, frames, skeleton) {
  if (body[0] !== FORMAT_MORE && body[0] !== FORMAT_MIRRORED) {
    return { body, frames, rest: 0, lead: 0, fine: false, fineTurns: false, aboutZero: false, mirrored: 0 };
  }
  if (body.length <= HEAD_SIZE) throw damaged(`${body.length} bytes is shorter than its ${HEAD_SIZE + 1}-byte header`, 0);
  const more = body[HEAD_SIZE];
  const rest = more & 3;
  const lead = (more >> LEAD_SHIFT) & 3;
  const fine = (more & FINE_CONSTANTS) !== 0;
  const fineTurns = (more & FINE_TURNS) !== 0;
  const aboutZero = (more & ZERO_CONSTANTS) !== 0;
  const mirroring = body[0] === FORMAT_MIRRORED;
  if ((!more && !mirroring) || more >> 7 || frames < 1 + (rest ? 1 : 0)) {
    throw damaged(`its more flags are damaged (${more} for ${frames} frames)`, HEAD_SIZE);
  }
  let after = HEAD_SIZE + 1;
  let mirrored = 0;
  if (mirroring) {
    if (body.length <= after || body[after] < 1 || body[after] > planOf(skeleton).mirrorable.size) {
      throw damaged('its mirrored joint count is damaged', after);
    }
    mirrored = body[after];
    after += 1;
  }
  const inner = new Uint8Array(body.length - (after - HEAD_SIZE));
  inner[0] = FORMAT;
  inner.set(body.subarray(1, HEAD_SIZE), 1);
  inner.set(body.subarray(after), HEAD_SIZE);
  return { body: inner, frames: rest ? frames - 1 : frames, rest, lead, fine, fineTurns, aboutZero, mirrored };
}

// body.unmirror: the knots with each mirrored joint's constant knots plus its reference's, some
// axes negated (a reference `back << 3 | signs`: `back` joints earlier, bit a negating axis a).
function unmirror(plan, coded, K, joints, refs, offset) {
  if (!K) throw damaged('its mirrored joints are damaged: it has no frame', offset);
  const knots = Float64Array.from(coded.knots);
  const triples = plan.mirrorable;
  const held = (channels) => channels.every((c) => coded.constant[c]);
  let previous = -1;
  joints.forEach((j, k) => {
    const back = Math.floor(refs[k] / 8);
    const signs = refs[k] - 8 * back;
    const target = triples.get(j);
    const source = triples.get(j - back);
    if (!(j > previous) || back < 1 || !target || !source || !held(target) || !held(source)) {
      throw damaged('its mirrored joints are damaged', offset);
    }
    for (let a = 0; a < 3; a++) knots[target[a] * K] += ((signs >> a) & 1 ? -1 : 1) * knots[source[a] * K];
    previous = j;
  });
  return knots;
}

// The header and integers of a kinwave body, every field checked: { lay, wavelet, coded (side,
// constant, knots, coeffs as the coder read them), knots (mirrored constants added back), codes,
// offsets, forms, means, isolated, patches } of its coded frames (a rest pose in frame 0 is not
// coded: rest, payload.rest_kind).
export function readKinwave(whole, skeleton, allFrames) {
  const { body, frames, rest, lead, fine, fineTurns, aboutZero, mirrored } = withoutMore(whole, allFrames, skeleton);
  const plan = planOf(skeleton);
  const C = skeleton.numChannels;
  const numCodes = plan.rotationJoints.length + (plan.translation.length ? 1 : 0);
  if (body.length < HEAD_SIZE) throw damaged(`${body.length} bytes is shorter than its ${HEAD_SIZE}-byte header`, 0);
  const [version, flags, logWindow, levels] = body;
  const channels = body[4] | (body[5] << 8);
  if (version !== FORMAT) throw damaged(`format ${version}, this decoder reads ${FORMAT}, ${FORMAT_MORE} and ${FORMAT_MIRRORED}`, 0);
  if (channels !== C) throw damaged(`${channels} channels, the skeleton has ${C}: wrong skeleton?`, 4);
  if (logWindow > 16 || levels < 1 || levels > 10 || ((flags >> 1) & 3) >= WAVELET_IDS.length) {
    throw damaged(`header is damaged (window 2^${logWindow}, levels ${levels})`, 1);
  }
  const keyframes = flags & FLAG_KEYFRAME ? (flags & FLAG_SECOND_KEYFRAME ? 2 : 1) : 0;
  const lay = layout(frames, 2 ** logWindow, levels, keyframes, lead);
  const S = lay.starts.length;
  const numOffsets = flags & FLAG_OFFSETS ? S : 0;
  const numVectors = flags & FLAG_FORMS ? plan.threeAngle.length : 0;
  const numMeans = flags & FLAG_MEANS ? 3 * numVectors : 0;
  let start = HEAD_SIZE;
  let numIsolated = 0;
  if (flags & FLAG_ISOLATED) {
    if (body.length <= start || body[start] < 1 || body[start] > MAX_ISOLATED) throw damaged('its isolated frame count is damaged', start);
    numIsolated = body[start];
    start += 1;
  }
  const sizes = [numCodes, numOffsets, numVectors, numMeans, numIsolated, numIsolated * C, mirrored, mirrored];
  let coded;
  try {
    coded = decodeCoefficients(body.subarray(start), C, lay.knotFrames.length, lay.padded, lay.segLevels, CODER_REVISION,
      sizes.reduce((a, b) => a + b, 0));
  } catch (e) {
    if (e instanceof RangeError) throw damaged(e.message, start);
    throw e;
  }
  const at = sizes.map((_, k) => sizes.slice(0, k).reduce((a, b) => a + b, 0));
  const knots = mirrored
    ? unmirror(plan, coded, lay.knotFrames.length, Array.from(cumulative(coded.side, at[6], mirrored)),
      coded.side.subarray(at[7], at[7] + mirrored), start)
    : coded.knots;
  const read = {
    rest,
    fine,
    fineTurns,
    aboutZero,
    lay,
    wavelet: WAVELET_IDS[(flags >> 1) & 3],
    coded,
    knots,
    codes: cumulative(coded.side, at[0], numCodes),
    offsets: numOffsets ? cumulative(coded.side, at[1], numOffsets) : new Float64Array(S),
    forms: cumulative(coded.side, at[2], numVectors),
    means: coded.side.subarray(at[3], at[3] + numMeans),
    isolated: cumulative(coded.side, at[4], numIsolated),
    patches: coded.side.subarray(at[5], at[5] + numIsolated * C),
  };
  const { codes, offsets, forms, means, isolated } = read;
  for (let k = 0; k < numIsolated; k++) {
    if (!(isolated[k] >= (k ? isolated[k - 1] + 2 : 1)) || isolated[k] >= frames - 1) throw damaged('its isolated frames are damaged', start);
  }
  if (codes.some((c) => c < 0 || c > 255) || offsets.some((o) => Math.abs(o) > 128) || !forms.every(validForm)
    || means.some((m) => Math.abs(m) * MEAN_QUANTUM > 360.0)) {
    throw damaged('its step codes are damaged', start);
  }
  return read;
}

// The channels (frames x channels, row-major Float64Array) of a kinwave body.
export function decodeKinwave(body, skeleton, allFrames) {
  const plan = planOf(skeleton);
  const C = skeleton.numChannels;
  const read = readKinwave(body, skeleton, allFrames);
  const out = new Float64Array(allFrames * C);
  if (!allFrames) return out;
  const frames = read.lay.frames;
  const first = allFrames - frames; // 1 after a rest pose
  const steps = channelSteps(skeleton, plan, read.codes);
  const rows = reconstruct(skeleton, plan, read, steps);
  const n = read.isolated.length;
  for (let k = 0; k < n; k++) {
    for (let c = 0; c < C; c++) rows[c][read.isolated[k]] += read.patches[c * n + k] * (steps[c] * KEYFRAME_QUANTUM);
  }
  toFileLayout(skeleton, plan, rows, read.coded.constant, read.forms, read.means);
  for (let c = 0; c < C; c++) {
    const row = rows[c];
    for (let t = 0; t < frames; t++) out[(t + first) * C + c] = row[t];
  }
  if (first) restFrame(skeleton, plan, rows, read.rest, out.subarray(0, C));
  return out;
}

// The rest pose of frame 0 (payload.rest_pose, kinematics.rest_frame) into `out`: every rotation
// 0 and the translations decoded frame 1's (REST), or 0 (REST_AT_ZERO); REST_TURNED as REST
// with the root's rotations frame 1's, and each joint right below it with three rotation channels
// and no axis pre-rotation turned back by them.
function restFrame(skeleton, plan, rows, rest, out) {
  for (let c = 0; c < out.length; c++) out[c] = (rest === REST || rest === REST_TURNED) && plan.isTranslation[c] ? rows[c][0] : 0.0;
  if (rest !== REST_TURNED || !skeleton.joints.length) return;
  for (let step = 0; step < 3; step++) {
    const c = skeleton.rotIndex[step];
    if (c >= 0) out[c] = rows[c][0];
  }
  const turn = new Float64Array(4 * skeleton.joints.length);
  forwardKinematics(skeleton, out, turn);
  const root = turn.slice(0, 4);
  skeleton.joints.forEach((joint, j) => {
    if (skeleton.parents[j] !== 0 || joint.rotationOrder.length !== 3 || skeleton.hasAxis[j]) return;
    const back = [0, 1, 2].map(() => Float64Array.of(0.0));
    fromForm(back, 1, joint.rotationOrder, WORLD, Float64Array.of(1.0, 0.0, 0.0, 0.0), root);
    for (let step = 0; step < 3; step++) out[skeleton.rotIndex[3 * j + step]] = back[step][0];
  });
}

// payload.reconstruct: per channel its trend plus its blocks' residual, then the seams smoothed.
function reconstruct(skeleton, plan, { coded, knots, offsets, lay, wavelet, fine, fineTurns, aboutZero }, steps) {
  const C = skeleton.numChannels;
  const { frames, starts, lengths, leads, padded, segLevels, left, frac, quantum } = lay;
  const S = starts.length;
  const K = lay.knotFrames.length;
  const N = padded.reduce((a, b) => a + b, 0);
  const factor = Float64Array.from(offsets, (o) => twoToEighths(o));
  const knotFactor = Float64Array.from({ length: K }, (_, k) => factor[Math.min(k, Math.max(S - 1, 0))]);
  const seamFactor = Float64Array.from({ length: Math.max(S - 1, 0) }, (_, s) => Math.min(factor[s], factor[s + 1]));
  const seams = starts.slice(1);
  const longest = Math.max(1, ...padded);
  const block = new Float64Array(longest);
  const signal = new Float64Array(longest);
  const work = new Float64Array(2 * longest);
  const values = new Float64Array(K);
  const limits = new Float64Array(seams.length);
  const rows = [];
  for (let c = 0; c < C; c++) {
    const row = new Float64Array(frames);
    rows.push(row);
    const step = steps[c];
    if (coded.constant[c]) {
      const isFine = plan.isTranslation[c] ? fine : fineTurns && plan.turnOverTranslation[c];
      const fraction = isFine ? FINE_CONST_FRACTION : CONST_FRACTION;
      row.fill((aboutZero ? 0.0 : plan.base[c]) + knots[c * K] * (step * fraction));
      continue;
    }
    for (let k = 0; k < K; k++) values[k] = knots[c * K + k] * (step * quantum[k] * knotFactor[k]);
    for (let t = 0; t < frames; t++) {
      const a = values[left[t]];
      const b = values[Math.min(left[t] + 1, K - 1)];
      row[t] = a + (b - a) * frac[t];
    }
    for (let s = 0; s < S; s++) {
      const n = padded[s];
      if (!n) continue;
      const from = c * N + lay.offsets[s];
      let any = false;
      for (let i = 0; i < n; i++) {
        block[i] = coded.coeffs[from + i] * (step * factor[s]);
        any ||= block[i] !== 0;
      }
      if (!any) continue;
      inverseWavelet(block, 0, n, segLevels[s], wavelet, signal, work);
      for (let i = 0; i < lengths[s]; i++) row[starts[s] + i] += signal[leads[s] + i];
    }
    for (let k = 0; k < seams.length; k++) limits[k] = SEAM_LIMIT * seamFactor[k] * step;
    smoothSeams(row, seams, SEAM_HALF_WIDTH, limits);
  }
  return rows;
}

// payload.decode_channels after the reconstruction: world-axis translations back on their parent's
// axes, three-angle joints from their coding forms back to the file's Euler angles.
function toFileLayout(skeleton, plan, rows, constant, forms, means) {
  const J = skeleton.joints.length;
  const moved = worldTranslations(skeleton, constant);
  const world = forms.some((f) => f >= WORLD);
  let parents = null;
  if (moved.length || world) {
    const global = new Float64Array(4 * J);
    forwardKinematics(skeleton, Float64Array.from(rows, (row) => row[0]), global);
    parents = (j) => {
      const p = skeleton.parents[j];
      return p < 0 ? Float64Array.of(1.0, 0.0, 0.0, 0.0) : global.slice(4 * p, 4 * p + 4);
    };
  }
  for (const { joint, pos } of moved) {
    const undo = conjugate(parents(joint));
    for (let t = 0; t < rows[0].length; t++) {
      const v = rotate(undo, pos.map((c) => rows[c][t]));
      pos.forEach((c, a) => (rows[c][t] = v[a]));
    }
  }
  forms.forEach((form, k) => {
    if (!form) return;
    const g = plan.threeAngle[k];
    const mean = quatExp(means.length ? [0, 1, 2].map((a) => (means[3 * k + a] * MEAN_QUANTUM * DEG) / 2.0) : [0, 0, 0]);
    let pre = null;
    if (world) {
      pre = parents(g.joint);
      if (skeleton.hasAxis[g.joint]) {
        const axis = skeleton.axisQuat.slice(4 * g.joint, 4 * g.joint + 4);
        pre = quatMultiply(conjugate(axis), quatMultiply(pre, axis));
      }
    }
    fromForm(g.channels.map((c) => rows[c]), rows[0].length, g.order, form, mean, pre);
  });
}
