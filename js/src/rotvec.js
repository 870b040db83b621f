// The way back from a three-angle joint's coding form to the file's Euler angles
// (codecs/shared/rotvec.py, from_forms): a rotation vector about a mean rotation, Euler angles in a
// coding order, either one turned by a constant `pre`, to a quaternion, then to the file's Euler
// triple (Bernardes and Viollet's formula, any of the 12 orders) nearest the previous frame's.
const DEG = Math.PI / 180.0;
export const VECTOR = 1;
export const WORLD = 8;
const CODING_ORDERS = ['XYZ', 'XZY', 'YXZ', 'YZX', 'ZXY', 'ZYX'];
const AXIS = { X: 0, Y: 1, Z: 2 };

export function validForm(form) {
  return Number.isInteger(form) && form >= 0 && form < 2 * WORLD;
}

// q (a Float64Array of 4) times the rotation by `deg` degrees about axis 0, 1 or 2, in place (rotvec._turn).
function turn(q, axis, deg) {
  const h = 0.5 * (deg * DEG);
  const c = Math.cos(h);
  const s = Math.sin(h);
  const w = q[0];
  const x = q[1];
  const y = q[2];
  const z = q[3];
  if (axis === 0) {
    q[0] = w * c - x * s; q[1] = x * c + w * s; q[2] = y * c + z * s; q[3] = z * c - y * s;
  } else if (axis === 1) {
    q[0] = w * c - y * s; q[1] = x * c - z * s; q[2] = y * c + w * s; q[3] = z * c + x * s;
  } else {
    q[0] = w * c - z * s; q[1] = x * c + y * s; q[2] = y * c - x * s; q[3] = z * c + w * s;
  }
}

// a times b into out (Float64Arrays of 4; out may be b).
function productInto(a, b, out) {
  const w = a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3];
  const x = a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2];
  const y = a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1];
  out[3] = a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0];
  out[0] = w;
  out[1] = x;
  out[2] = y;
}

export function conjugate(q) {
  return [q[0], -q[1], -q[2], -q[3]];
}

// exp of the pure quaternion v (rotations.quat_exp).
export function quatExp(v) {
  const n = Math.sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
  const sinc = n < 1e-12 ? 1.0 : Math.sin(n) / n;
  return [Math.cos(n), v[0] * sinc, v[1] * sinc, v[2] * sinc];
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
  const theta2 = 2.0 * Math.atan2(Math.hypot(c, d), Math.hypot(a, b));
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
  const m = Float64Array.from(vector ? mean : [1.0, 0.0, 0.0, 0.0]);
  const undo = form >= WORLD ? Float64Array.from(conjugate(pre)) : null;
  const setup = orderSetup(order);
  const q = new Float64Array(4);
  const angles = new Float64Array(3);
  const previous = new Float64Array(3);
  const [x, y, z] = rows;
  for (let t = 0; t < frames; t++) {
    if (vector) {
      const vx = (x[t] * DEG) / 2.0;
      const vy = (y[t] * DEG) / 2.0;
      const vz = (z[t] * DEG) / 2.0;
      const n = Math.sqrt(vx * vx + vy * vy + vz * vz);
      const sinc = n < 1e-12 ? 1.0 : Math.sin(n) / n;
      q[0] = Math.cos(n);
      q[1] = vx * sinc;
      q[2] = vy * sinc;
      q[3] = vz * sinc;
    } else {
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
