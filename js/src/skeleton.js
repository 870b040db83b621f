// A skeleton from the JSON form of stream headers and .moc files (formats/container.py), with the
// index tables forward kinematics and the decoders use (kinematics.channel_plan), every field checked.
import { DecodeError } from './errors.js';
import { AXIS, eulerToQuat } from './quaternions.js';

const CHANNELS = ['Xposition', 'Yposition', 'Zposition', 'Xrotation', 'Yrotation', 'Zrotation'];
export const MAX_JOINTS = 1 << 16;

function finite(v, what) {
  const x = Number(v);
  if (typeof v !== 'number' || !Number.isFinite(x)) throw new DecodeError(`skeleton: ${what} is not a finite number`);
  return x;
}

function order(text, what, allowEmpty) {
  if (typeof text !== 'string' || text.length > 3 || [...text].some((c) => !(c in AXIS)) || (!allowEmpty && !text)) {
    throw new DecodeError(`skeleton: ${what} ${JSON.stringify(text)} is not an Euler order`);
  }
  for (let k = 1; k < text.length; k++) if (text[k] === text[k - 1]) throw new DecodeError(`skeleton: ${what} repeats an axis`);
  return text;
}

/**
 * A skeleton as stream headers and .moc files carry it (Python's `mocodec.skeleton.Skeleton`),
 * every field checked: joints (name, parent, offset, channels, Euler order, ASF axis),
 * `numChannels`, `unitsPerMetre`.
 */
export class Skeleton {
  /**
   * @param {object} data the skeleton's JSON (`joints`, `units_per_metre`, `name`)
   * @throws {DecodeError} where it is not a skeleton
   */
  constructor(data) {
    if (!data || typeof data !== 'object' || !Array.isArray(data.joints)) throw new DecodeError('skeleton: expected an object with joints');
    if (!data.joints.length || data.joints.length > MAX_JOINTS) throw new DecodeError(`skeleton: ${data.joints.length} joints (1 to ${MAX_JOINTS})`);
    this.name = String(data.name ?? '');
    this.unitsPerMetre = finite(data.units_per_metre, 'units_per_metre');
    if (!(this.unitsPerMetre > 0)) throw new DecodeError('skeleton: units_per_metre must be positive');
    this.joints = data.joints.map((j, i) => this.#joint(j, i));
    this.channelOffsets = [0];
    for (const j of this.joints) this.channelOffsets.push(this.channelOffsets.at(-1) + j.channels.length);
    this.numChannels = this.channelOffsets.at(-1);
    this.#plan();
  }

  #joint(j, i) {
    if (!j || typeof j !== 'object') throw new DecodeError(`skeleton: joint ${i} is not an object`);
    const parent = j.parent;
    if (!Number.isInteger(parent) || (i === 0 ? parent !== -1 : parent < 0 || parent >= i)) {
      throw new DecodeError(`skeleton: joint ${i}'s parent ${parent} must come before it`);
    }
    const channels = j.channels;
    if (!Array.isArray(channels) || channels.length > 6 || channels.some((c) => !CHANNELS.includes(c))) {
      throw new DecodeError(`skeleton: joint ${i} has unknown channels`);
    }
    const rotationOrder = order(j.rotation_order, `joint ${i}'s rotation order`, true);
    const rotAxes = channels.filter((c) => c.endsWith('rotation')).map((c) => c[0]).sort().join('');
    if ([...rotationOrder].sort().join('') !== rotAxes) throw new DecodeError(`skeleton: joint ${i}'s rotation order does not use its rotation channels`);
    const axisGiven = j.axis ?? [0, 0, 0];
    if (!Array.isArray(j.offset) || !Array.isArray(axisGiven) || j.offset.length !== 3 || axisGiven.length !== 3) {
      throw new DecodeError(`skeleton: joint ${i}'s offset and axis need 3 numbers`);
    }
    const offset = j.offset.map((v, k) => finite(v, `joint ${i}'s offset ${k}`));
    const axis = axisGiven.map((v, k) => finite(v, `joint ${i}'s axis ${k}`));
    return { name: String(j.name), parent, offset, channels, rotationOrder, axis, axisOrder: order(j.axis_order ?? 'ZYX', `joint ${i}'s axis order`, false) };
  }

  // kinematics.channel_plan: per joint the channel of each rotation step, its axis, the
  // translation channels, and the fixed pre-rotation C.
  #plan() {
    const n = this.joints.length;
    this.rotIndex = new Int32Array(3 * n).fill(-1);
    this.rotAxis = new Int32Array(3 * n);
    this.posIndex = new Int32Array(3 * n).fill(-1);
    this.axisQuat = new Float64Array(4 * n);
    this.hasAxis = new Uint8Array(n);
    this.offsets = new Float64Array(3 * n);
    this.parents = Int32Array.from(this.joints, (j) => j.parent);
    this.joints.forEach((j, i) => {
      const first = this.channelOffsets[i];
      const used = {};
      [...j.rotationOrder].forEach((a, step) => {
        const k = used[a] ?? 0;
        const matches = j.channels.map((c, idx) => (c === `${a}rotation` ? idx : -1)).filter((idx) => idx >= 0);
        this.rotIndex[3 * i + step] = first + matches[k];
        this.rotAxis[3 * i + step] = AXIS[a];
        used[a] = k + 1;
      });
      ['X', 'Y', 'Z'].forEach((a, k) => {
        const idx = j.channels.indexOf(`${a}position`);
        if (idx >= 0) this.posIndex[3 * i + k] = first + idx;
        this.offsets[3 * i + k] = j.offset[k];
      });
      this.hasAxis[i] = j.axis.some((v) => v !== 0) ? 1 : 0;
      this.axisQuat.set(eulerToQuat(j.axis, j.axisOrder), 4 * i);
    });
  }
}
