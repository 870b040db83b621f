// Little-endian reading, varints and the two checks the packets carry (CRC-16/CCITT, CRC-32).
import { DecodeError } from './errors.js';

// (value, next position) of the unsigned LEB128 varint at `pos`, at most `maxBytes` long.
export function readVarint(data, pos, maxBytes = 10, what = 'a number') {
  let value = 0;
  let scale = 1;
  for (let k = 0; k < maxBytes; k++) {
    if (pos + k >= data.length) throw new DecodeError(`${what} ends inside its varint`, pos + k);
    const b = data[pos + k];
    value += (b & 0x7f) * scale;
    if (!(b & 0x80)) {
      if (!Number.isSafeInteger(value)) throw new DecodeError(`${what} is too large`, pos);
      return [value, pos + k + 1];
    }
    scale *= 128;
  }
  throw new DecodeError(`${what}: a varint longer than ${maxBytes} bytes`, pos);
}

export function u16(data, pos) {
  return data[pos] | (data[pos + 1] << 8);
}

export function u32(data, pos) {
  return (data[pos] | (data[pos + 1] << 8) | (data[pos + 2] << 16)) + data[pos + 3] * 16777216;
}

export function i16(data, pos) {
  const v = u16(data, pos);
  return v >= 32768 ? v - 65536 : v;
}

const CRC16 = new Uint16Array(256);
const CRC32 = new Uint32Array(256);
for (let n = 0; n < 256; n++) {
  let c = n << 8;
  for (let k = 0; k < 8; k++) c = c & 0x8000 ? ((c << 1) ^ 0x1021) & 0xffff : (c << 1) & 0xffff;
  CRC16[n] = c;
  let d = n;
  for (let k = 0; k < 8; k++) d = d & 1 ? 0xedb88320 ^ (d >>> 1) : d >>> 1;
  CRC32[n] = d >>> 0;
}

// CRC-16/CCITT, initial value 0xFFFF (Python's binascii.crc_hqx(data, 0xFFFF)).
export function crc16(data, start, end, init = 0xffff) {
  let crc = init;
  for (let k = start; k < end; k++) crc = ((crc << 8) & 0xffff) ^ CRC16[((crc >> 8) ^ data[k]) & 0xff];
  return crc;
}

// CRC-32 as zlib computes it.
export function crc32(data, start, end, seed = 0) {
  let crc = (seed ^ 0xffffffff) >>> 0;
  for (let k = start; k < end; k++) crc = CRC32[(crc ^ data[k]) & 0xff] ^ (crc >>> 8);
  return (crc ^ 0xffffffff) >>> 0;
}
