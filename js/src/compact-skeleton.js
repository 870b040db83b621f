// The compact binary skeleton of .moc headers (formats/skeleton_bin.py, version 1), read into a
// Skeleton: column by column, numbers as tagged decimals n / 10^k (read back through the decimal
// text "ne-k", which rounds exactly as Python's n / 10**k does), raw float64s, or references to a
// mirrored earlier offset. Every count is checked against the bytes left before it is used.
import { DecodeError } from './errors.js';
import { Skeleton } from './skeleton.js';

const CHANNEL_NAMES = ['Xposition', 'Yposition', 'Zposition', 'Xrotation', 'Yrotation', 'Zrotation'];
const BODY_PARTS = ['torso', 'head', 'left_arm', 'left_hand', 'right_arm', 'right_hand', 'left_leg', 'right_leg'];
const VERSION = 1;
const ZERO = 0;
const POS_INF = 1;
const NEG_INF = 2;
const RAW = 3;
const DECIMAL = 4;
const MAX_PLACES = 12;
const PLAIN = 0;
const PRODUCT = 1;

class ByteReader {
  constructor(data) {
    this.data = data;
    this.pos = 0;
    this.text = new TextDecoder('utf-8', { fatal: true });
  }

  fail(message) {
    throw new DecodeError(`compact skeleton: ${message}`, this.pos);
  }

  byte() {
    if (this.pos >= this.data.length) this.fail('ends early');
    return this.data[this.pos++];
  }

  // An unsigned varint of up to 11 bytes, as a BigInt.
  big() {
    let value = 0n;
    for (let k = 0; k < 11; k++) {
      const b = this.byte();
      value |= BigInt(b & 0x7f) << BigInt(7 * k);
      if (!(b & 0x80)) return value;
    }
    return this.fail('a varint longer than 11 bytes');
  }

  uint() {
    const v = this.big();
    if (v > BigInt(Number.MAX_SAFE_INTEGER)) this.fail('a count too large');
    return Number(v);
  }

  sintText() {
    const v = this.big();
    return (v % 2n === 0n ? v / 2n : -(v + 1n) / 2n).toString();
  }

  string() {
    const n = this.uint();
    if (this.pos + n > this.data.length) this.fail(`a ${n}-byte name runs past the end`);
    this.pos += n;
    try {
      return this.text.decode(this.data.subarray(this.pos - n, this.pos));
    } catch {
      return this.fail('a name is not UTF-8');
    }
  }

  number() {
    const tag = this.byte();
    if (tag === ZERO) return 0;
    if (tag === POS_INF) return Infinity;
    if (tag === NEG_INF) return -Infinity;
    if (tag === RAW) {
      if (this.pos + 8 > this.data.length) this.fail('ends early');
      const value = new DataView(this.data.buffer, this.data.byteOffset + this.pos, 8).getFloat64(0, true);
      this.pos += 8;
      return value;
    }
    if (tag >= DECIMAL && tag <= DECIMAL + MAX_PLACES) return Number(`${this.sintText()}e-${tag - DECIMAL}`);
    return this.fail(`unknown number tag ${tag}`);
  }
}

function defaultOrder(channels) {
  return channels.filter((c) => c.endsWith('rotation')).map((c) => c[0]).join('');
}

function times(n, read) {
  return Array.from({ length: n }, (_, i) => read(i));
}

/**
 * A Skeleton from the compact form's bytes (formats/skeleton_bin.py).
 * @param {Uint8Array} data
 * @returns {Skeleton}
 * @throws {DecodeError}
 */
export function unpackSkeleton(data) {
  const r = new ByteReader(data);
  const version = r.uint();
  if (version !== VERSION) r.fail(`version ${version}, this decoder reads ${VERSION}`);
  const name = r.string();
  const units = r.number();
  const n = r.uint();
  if (n > data.length) r.fail(`${n} joints cannot fit in ${data.length} bytes`);
  const names = times(n, () => r.string());
  const parents = times(n, (i) => {
    const back = r.uint();
    return back ? i - back : -1;
  });
  const channels = times(n, () => {
    const count = r.uint();
    if (count > CHANNEL_NAMES.length) r.fail(`a joint with ${count} channels`);
    return times(count, () => CHANNEL_NAMES[r.uint()] ?? r.fail('an unknown channel'));
  });
  const orders = times(n, (i) => r.string() || defaultOrder(channels[i]));
  const axisOrders = times(n, () => r.string() || 'ZYX');
  const parts = times(n, () => {
    const p = r.uint();
    return p ? (BODY_PARTS[p - 1] ?? r.fail(`an unknown body part ${p}`)) : null;
  });
  const places = r.uint() - 1;
  if (places > MAX_PLACES) r.fail(`${places} decimal places`);
  const offsets = [];
  for (let i = 0; i < n; i++) {
    const form = r.uint();
    const back = Math.floor(form / 8);
    if (form === PLAIN && places >= 0) offsets.push(times(3, () => Number(`${r.sintText()}e-${places}`)));
    else if (form === PLAIN) offsets.push(times(3, () => r.number()));
    else if (form === PRODUCT) {
      const length = r.number();
      offsets.push(times(3, () => r.number() * length));
    } else if (back > 0 && back <= i) offsets.push(offsets[i - back].map((x, a) => ((form >> a) & 1 ? -x : x)));
    else r.fail(`joint ${i} has offset form ${form}`);
  }
  const axes = times(n, () => (r.uint() ? times(3, () => r.number()) : [0, 0, 0]));
  const limits = times(n, (i) => (r.uint() ? channels[i].map(() => [r.number(), r.number()]) : []));
  if (r.pos !== data.length) r.fail(`${data.length - r.pos} bytes left over`);
  return new Skeleton({
    name,
    units_per_metre: units,
    joints: names.map((jointName, i) => ({
      name: jointName, parent: parents[i], offset: offsets[i], channels: channels[i], rotation_order: orders[i],
      axis: axes[i], axis_order: axisOrders[i], limits: limits[i], body_part: parts[i],
    })),
  });
}
