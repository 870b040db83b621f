// The context-adaptive decoder of kinwave's integers (coding/entropy/coefcoder.py, revision 2):
// side integers, then per channel a constant flag, its knots and, block by block, an "all zero"
// flag and the wavelet coefficients, coarsest band first, each in contexts of its band, the
// activity of its two previous values and its parent's magnitude. Decision for decision the
// Python decoder's, so every integer is the same.
import { BinaryDecoder, MAX_CLASS, newState } from './binarycoder.js';

const BANDS = 6;
const ACT = 4;
const PAR = 3;
const UNARY = 8;
const Z0 = 0;
const U0 = Z0 + BANDS * ACT * PAR;
const M0 = U0 + BANDS * ACT * UNARY;
const S0 = M0 + MAX_CLASS;
const KZ = S0 + BANDS;
const KU = KZ + 2;
const KM = KU + 2 * 24;
const KS = KM + MAX_CLASS;
const CONST = KS + 2;
const BLOCK = CONST + 1;
const S2 = BLOCK + 2;
const SIDE = S2 + BANDS * 9;
const SIDE_UNARY = 8;
const CONTEXTS = SIDE + 2 + SIDE_UNARY;

function activity(a, b) {
  const s = 2 * Math.abs(a) + Math.abs(b);
  return s === 0 ? 0 : s <= 2 ? 1 : s <= 6 ? 2 : 3;
}

function signClass(v) {
  return v === 0 ? 0 : v > 0 ? 1 : 2;
}

function parentClass(v) {
  const m = Math.abs(v);
  return m === 0 ? 0 : m <= 2 ? 1 : 2;
}

// { side, constant, knots (channels x numKnots), coeffs (channels x sum(segPad)) } of `data`;
// segPad[s] coefficients in segment s's block (0: none), segLevels[s] its wavelet levels.
export function decodeCoefficients(data, channels, numKnots, segPad, segLevels, revision, sideSize) {
  const rev2 = revision >= 2;
  const dec = new BinaryDecoder(data);
  const state = newState(CONTEXTS, rev2);
  const N = segPad.reduce((a, b) => a + b, 0);
  const side = new Float64Array(sideSize);
  const constant = new Uint8Array(channels);
  const knots = new Float64Array(channels * numKnots);
  const coeffs = new Float64Array(channels * N);
  for (let i = 0; i < sideSize; i++) side[i] = dec.getInt(state, SIDE, SIDE + 2, SIDE_UNARY, KM, SIDE + 1);
  for (let c = 0; c < channels; c++) {
    constant[c] = dec.get(state, CONST);
    let prev = 0;
    const nk = constant[c] ? Math.min(1, numKnots) : numKnots; // (a layout of no frames has no knot)
    for (let i = 0; i < nk; i++) {
      const first = i === 0 ? 1 : 0;
      prev += dec.getInt(state, KZ + 1 - first, KU + 24 * (1 - first), 24, KM, KS + 1 - first);
      knots[c * numKnots + i] = prev;
    }
    if (constant[c]) continue;
    const row = c * N;
    let off = 0;
    let lastNonzero = 0;
    for (let s = 0; s < segPad.length; s++) {
      const n = segPad[s];
      if (n === 0) continue;
      const nonzero = dec.get(state, BLOCK + lastNonzero);
      lastNonzero = nonzero;
      if (nonzero) {
        const L = segLevels[s];
        let start = off;
        let blen = n >> L;
        let prevValue = 0;
        for (let b = 0; b <= L; b++) {
          const band = b === 0 ? 0 : Math.min(L - b + 1, BANDS - 1);
          let p1 = 0;
          let p2 = 0;
          for (let i = 0; i < blen; i++) {
            let pv = 0;
            let par;
            if (b === 0) par = rev2 && i > 0 ? 1 : 0;
            else {
              pv = b === 1 ? coeffs[row + off + i] : coeffs[row + start - (blen >> 1) + (i >> 1)];
              par = parentClass(pv);
            }
            const act = activity(p1, p2);
            const sctx = rev2 ? S2 + (band * 3 + signClass(p1)) * 3 + signClass(pv) : S0 + band;
            let v = dec.getInt(state, Z0 + (band * ACT + act) * PAR + par, U0 + (band * ACT + act) * UNARY, UNARY, M0, sctx);
            p2 = p1;
            p1 = v;
            if (b === 0 && rev2) {
              prevValue += v;
              v = prevValue;
            }
            coeffs[row + start + i] = v;
          }
          start += blen;
          if (b > 0) blen <<= 1;
        }
      }
      off += n;
    }
  }
  return { side, constant, knots, coeffs, used: dec.pos };
}
