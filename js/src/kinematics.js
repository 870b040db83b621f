// Forward kinematics (kinematics._fk_kernel): joint positions of frames of channels, each joint
// G_i = G_p C M C^-1 and x_i = x_p + G_p (offset_i + t_i), composed as quaternions.

/**
 * Joint positions of frames of channels (Python's `kinematics.forward_kinematics`): each joint
 * G_i = G_p C M C^-1 and x_i = x_p + G_p (offset_i + t_i), composed as quaternions.
 * @param {Skeleton} skeleton
 * @param {Float64Array} channels frames x channels, row-major
 * @param {Float64Array | null} [orientations] frames x joints x 4, filled with each joint's global rotation
 * @returns {Float64Array} frames x joints x 3, skeleton units
 */
export function forwardKinematics(skeleton, channels, orientations = null) {
  const C = skeleton.numChannels;
  const J = skeleton.joints.length;
  const frames = C ? channels.length / C : 0;
  const pos = new Float64Array(frames * J * 3);
  const quat = new Float64Array(J * 4);
  const { rotIndex, rotAxis, posIndex, axisQuat, hasAxis, offsets, parents } = skeleton;
  for (let f = 0; f < frames; f++) {
    const base = f * C;
    for (let j = 0; j < J; j++) {
      let w = 1, x = 0, y = 0, z = 0;
      for (let step = 0; step < 3; step++) {
        const c = rotIndex[3 * j + step];
        if (c < 0) break;
        const half = channels[base + c] * (Math.PI / 360.0);
        const cs = Math.cos(half);
        const sn = Math.sin(half);
        const a = rotAxis[3 * j + step];
        if (a === 0) [w, x, y, z] = [w * cs - x * sn, w * sn + x * cs, y * cs + z * sn, z * cs - y * sn];
        else if (a === 1) [w, x, y, z] = [w * cs - y * sn, x * cs - z * sn, w * sn + y * cs, x * sn + z * cs];
        else [w, x, y, z] = [w * cs - z * sn, x * cs + y * sn, y * cs - x * sn, w * sn + z * cs];
      }
      if (hasAxis[j]) {
        const [cw, cx, cy, cz] = axisQuat.subarray(4 * j, 4 * j + 4);
        [w, x, y, z] = [cw * w - cx * x - cy * y - cz * z, cw * x + cx * w + cy * z - cz * y,
          cw * y - cx * z + cy * w + cz * x, cw * z + cx * y - cy * x + cz * w];
        [w, x, y, z] = [w * cw + x * cx + y * cy + z * cz, -w * cx + x * cw - y * cz + z * cy,
          -w * cy + x * cz + y * cw - z * cx, -w * cz - x * cy + y * cx + z * cw];
      }
      let tx = offsets[3 * j];
      let ty = offsets[3 * j + 1];
      let tz = offsets[3 * j + 2];
      if (posIndex[3 * j] >= 0) tx += channels[base + posIndex[3 * j]];
      if (posIndex[3 * j + 1] >= 0) ty += channels[base + posIndex[3 * j + 1]];
      if (posIndex[3 * j + 2] >= 0) tz += channels[base + posIndex[3 * j + 2]];
      const out = (f * J + j) * 3;
      const p = parents[j];
      if (p < 0) {
        quat.set([w, x, y, z], 4 * j);
        pos[out] = tx;
        pos[out + 1] = ty;
        pos[out + 2] = tz;
        continue;
      }
      const pw = quat[4 * p], px = quat[4 * p + 1], py = quat[4 * p + 2], pz = quat[4 * p + 3];
      quat[4 * j] = pw * w - px * x - py * y - pz * z;
      quat[4 * j + 1] = pw * x + px * w + py * z - pz * y;
      quat[4 * j + 2] = pw * y - px * z + py * w + pz * x;
      quat[4 * j + 3] = pw * z + px * y - py * x + pz * w;
      const ux = 2.0 * (py * tz - pz * ty);
      const uy = 2.0 * (pz * tx - px * tz);
      const uz = 2.0 * (px * ty - py * tx);
      const po = (f * J + p) * 3;
      pos[out] = pos[po] + tx + pw * ux + py * uz - pz * uy;
      pos[out + 1] = pos[po + 1] + ty + pw * uy + pz * ux - px * uz;
      pos[out + 2] = pos[po + 2] + tz + pw * uz + px * uy - py * ux;
    }
    if (orientations) orientations.set(quat, f * J * 4);
  }
  return pos;
}
