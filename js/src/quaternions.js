// Unit quaternions (w, x, y, z) as the decoders and the skeleton use them, each formula once: the
// in-place forms (`turn`, `productInto`, `expInto`) serve the per-frame loops, which must not
// allocate; the others return new ones. All are Float64Arrays, so the engine compiles the in-place
// forms for one kind of array (given plain arrays too, the decoder ran 10% slower).
export const DEG = Math.PI / 180.0;
export const AXIS = { X: 0, Y: 1, Z: 2 }; // an Euler order's letters as axis numbers

// q (4 numbers) times the rotation by `deg` degrees about axis 0, 1 or 2, in place (rotvec._turn).
export function turn(q, axis, deg) {
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

// a times b (Hamilton product) into out; out may be b.
export function productInto(a, b, out) {
  const w = a[0] * b[0] - a[1] * b[1] - a[2] * b[2] - a[3] * b[3];
  const x = a[0] * b[1] + a[1] * b[0] + a[2] * b[3] - a[3] * b[2];
  const y = a[0] * b[2] - a[1] * b[3] + a[2] * b[0] + a[3] * b[1];
  out[3] = a[0] * b[3] + a[1] * b[2] - a[2] * b[1] + a[3] * b[0];
  out[0] = w;
  out[1] = x;
  out[2] = y;
}

export function quatMultiply(a, b) {
  const out = new Float64Array(4);
  productInto(a, b, out);
  return out;
}

export function conjugate(q) {
  return Float64Array.of(q[0], -q[1], -q[2], -q[3]);
}

// exp of the pure quaternion (x, y, z) into out (rotations.quat_exp).
export function expInto(x, y, z, out) {
  const n = Math.sqrt(x * x + y * y + z * z);
  const sinc = n < 1e-12 ? 1.0 : Math.sin(n) / n;
  out[0] = Math.cos(n);
  out[1] = x * sinc;
  out[2] = y * sinc;
  out[3] = z * sinc;
}

export function quatExp(v) {
  const out = new Float64Array(4);
  expInto(v[0], v[1], v[2], out);
  return out;
}

// The vector v (3 numbers) turned by the unit quaternion q.
export function rotate(q, v) {
  const [w, x, y, z] = q;
  const ux = 2.0 * (y * v[2] - z * v[1]);
  const uy = 2.0 * (z * v[0] - x * v[2]);
  const uz = 2.0 * (x * v[1] - y * v[0]);
  return [v[0] + w * ux + y * uz - z * uy, v[1] + w * uy + z * ux - x * uz, v[2] + w * uz + x * uy - y * ux];
}

// The rotation of Euler `angles` (degrees) about `axes` (e.g. "ZYX"), composed in that order.
export function eulerToQuat(angles, axes) {
  const q = Float64Array.of(1, 0, 0, 0);
  for (let n = 0; n < axes.length; n++) turn(q, AXIS[axes[n]], angles[n]);
  return q;
}
