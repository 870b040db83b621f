// Powers of two in eighths of an octave, exactly as Python computes 2.0 ** (n / 8): 2^(q + r/8) is
// 2^q times the correctly rounded 2^(r/8), and scaling by a power of two is exact. The step codes
// of kinwave and kinwave-live (step = 2^(code/8 - 20)) and kinwave's segment offsets use them.
const EIGHTHS = [1.0, 1.0905077326652577, 1.189207115002721, 1.2968395546510096, 1.4142135623730951,
  1.5422108254079407, 1.681792830507429, 1.8340080864093424];

// 2^(n/8) for an integer n.
export function twoToEighths(n) {
  const r = ((n % 8) + 8) % 8;
  return EIGHTHS[r] * 2 ** ((n - r) / 8);
}

// The quantiser step of every step code: 2^(code/8 - 20).
export const CODE_STEP = Float64Array.from({ length: 256 }, (_, code) => twoToEighths(code - 160));
