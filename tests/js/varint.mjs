// A LEB128 varint's bytes, for the Node tests that build damaged or hand-made files and batches
// (the browser package only reads varints: js/src/bytes.js readVarint).
export function varint(value) {
  const out = [];
  for (; value > 0x7f; value = Math.floor(value / 128)) out.push((value & 0x7f) | 0x80);
  out.push(value);
  return Uint8Array.from(out);
}
