// The way back from a three-angle joint's coding form to the file's Euler angles
// (codecs/shared/rotvec.py, from_forms): a rotation vector about a mean rotation, Euler angles in a
// coding order, either one turned by a constant `pre`, to a quaternion, then to the file's Euler
// triple (Bernardes and Viollet's formula, any of the 12 orders) nearest the previous frame's.
import { AXIS, DEG, conjugate, expInto, productInto, turn } from './quaternions.js';

export const VECTOR = 1;
export const WORLD = 8;
const CODING_ORDERS = ['XYZ', 'XZY', 'YXZ', 'YZX', 'ZXY', 'ZYX'];

export function validForm(form) {
  return Number.isInteger(form) && form >= 0 && form < 2 * WORLD;
}

// Python's float modulo (the sign of the divisor).
function pyMod(a, b) {
  const r = a % b;
  return r !== 0 && r < 0 !== b < 0 ? r + b : r;
}

// rotvec._order: the extrinsic sequence of an intrinsic order, whether it is proper, the sign.
function orderSetup(order) {
  const axes = [...order].map((c) => AXIS[c]);
  const i = axes[2];
  const j = axes[1];
  let k = axes[0];
  const proper = i === k;
  if (proper) k = 3 - i - j;
  return { i, j, k, proper, eps: ((i - j) * (j - k) * (k - i)) / 2.0 };
}

// The Euler triple (degrees, principal range) of q (rotvec._euler_of).
function eulerOf(q, o, out) {
  const w = q[0];
  const qi = q[1 + o.i];
  const qj = q[1 + o.j];
  const qk = q[1 + o.k];
  const a = o.proper ? w : w - qj;
  const b = o.proper ? qi : qi + qk * o.eps;
  const c = o.proper ? qj : qj + w;
  const d = o.proper ? qk * o.eps : qk * o.eps - qi;
  const theta2 = 2.0 * Math.atan2(Math.sqrt(c * c + d * d), Math.sqrt(a * a + b * b));
  const plus = Math.atan2(b, a);
  const minus = Math.atan2(d, c);
  out[0] = o.proper ? plus + minus : (plus + minus) * o.eps;
  out[1] = o.proper ? theta2 : theta2 - Math.PI / 2.0;
  out[2] = plus - minus;
  for (let m = 0; m < 3; m++) out[m] = (pyMod(out[m] + Math.PI, 2.0 * Math.PI) - Math.PI) / DEG;
}

// Of the triple and its twin, each shifted by turns of 360, the one nearest `previous`, into
// `previous` (motion.follow_nearest).
function followNearest(angles, previous, proper) {
  let best = Infinity;
  let b0 = 0;
  let b1 = 0;
  let b2 = 0;
  for (let twin = 0; twin < 2; twin++) {
    const c0 = twin ? angles[0] + 180.0 : angles[0];
    const c1 = twin ? (proper ? -angles[1] : 180.0 - angles[1]) : angles[1];
    const c2 = twin ? angles[2] + 180.0 : angles[2];
    let d0 = c0 - previous[0];
    d0 -= 360.0 * Math.floor((d0 + 180.0) / 360.0);
    let d1 = c1 - previous[1];
    d1 -= 360.0 * Math.floor((d1 + 180.0) / 360.0);
    let d2 = c2 - previous[2];
    d2 -= 360.0 * Math.floor((d2 + 180.0) / 360.0);
    const cost = Math.abs(d0) + Math.abs(d1) + Math.abs(d2);
    if (cost < best) {
      best = cost;
      b0 = previous[0] + d0;
      b1 = previous[1] + d1;
      b2 = previous[2] + d2;
    }
  }
  previous[0] = b0;
  previous[1] = b1;
  previous[2] = b2;
}

// One joint's rows (three channel rows of `frames` values, rotation-order steps) from coding form
// `form` back to the file's `order`, in place; `mean` the vector form's mean rotation, `pre` a
// WORLD form's turn.
export function fromForm(rows, frames, order, form, mean, pre) {
  const base = form % WORLD;
  const vector = base === VECTOR;
  const formAxes = [...(base >= 2 ? CODING_ORDERS[base - 2] : order)].map((c) => AXIS[c]);
  const m = vector ? mean : Float64Array.of(1.0, 0.0, 0.0, 0.0);
  const undo = form >= WORLD ? conjugate(pre) : null;
  const setup = orderSetup(order);
  const q = new Float64Array(4);
  const angles = new Float64Array(3);
  const previous = new Float64Array(3);
  const [x, y, z] = rows;
  for (let t = 0; t < frames; t++) {
    if (vector) expInto((x[t] * DEG) / 2.0, (y[t] * DEG) / 2.0, (z[t] * DEG) / 2.0, q);
    else {
      q[0] = 1.0;
      q[1] = 0.0;
      q[2] = 0.0;
      q[3] = 0.0;
      turn(q, formAxes[0], x[t]);
      turn(q, formAxes[1], y[t]);
      turn(q, formAxes[2], z[t]);
    }
    productInto(m, q, q);
    if (undo) productInto(undo, q, q);
    eulerOf(q, setup, angles);
    if (t === 0) previous.set(angles);
    else followNearest(angles, previous, setup.proper);
    x[t] = previous[0];
    y[t] = previous[1];
    z[t] = previous[2];
  }
}
