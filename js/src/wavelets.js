// Inverse periodised wavelet transforms as PyWavelets computes them (waverec, mode
// "periodization"): per level, out[(2i + j - F/2 + 1) mod 2m] += a[i] lo[j] + d[i] hi[j] with the
// reconstruction filters lo, hi of F taps (coding/transforms/wavelets.py: cdf97 = bior4.4, d4 = db2).
const FILTERS = {
  cdf97: [
    [0.0, -0.06453888262869706, -0.04068941760916406, 0.41809227322161724, 0.7884856164055829,
      0.41809227322161724, -0.04068941760916406, -0.06453888262869706, 0.0, 0.0],
    [0.0, -0.03782845550726404, -0.023849465019556843, 0.11062440441843718, 0.37740285561283066,
      -0.8526986790088938, 0.37740285561283066, 0.11062440441843718, -0.023849465019556843, -0.03782845550726404],
  ],
  d4: [
    [0.48296291314453416, 0.8365163037378079, 0.2241438680420134, -0.12940952255126037],
    [-0.12940952255126037, -0.2241438680420134, 0.8365163037378079, -0.48296291314453416],
  ],
  haar: [[0.7071067811865476, 0.7071067811865476], [0.7071067811865476, -0.7071067811865476]],
};
export const WAVELET_IDS = ['cdf97', 'd4', 'haar'];

// The signal (n samples) of `coeffs[from .. from + n)` laid out coarsest first (approximation,
// then details from the coarsest level to the finest), `levels` deep; `work` holds 2n scratch values.
export function inverseWavelet(coeffs, from, n, levels, wavelet, out, work) {
  const [lo, hi] = FILTERS[wavelet];
  const taps = lo.length;
  const shift = taps / 2 - 1;
  let m = n >> levels;
  let a = work.subarray(0, n);
  let next = work.subarray(n, 2 * n);
  for (let i = 0; i < m; i++) a[i] = coeffs[from + i];
  let d = from + m;
  for (let level = levels; level >= 1; level--) {
    const size = 2 * m;
    next.fill(0, 0, size);
    for (let i = 0; i < m; i++) {
      const ai = a[i];
      const di = coeffs[d + i];
      let at = (((2 * i - shift) % size) + size) % size;
      for (let j = 0; j < taps; j++) {
        next[at] += ai * lo[j] + di * hi[j];
        at = at + 1 === size ? 0 : at + 1;
      }
    }
    d += m;
    m = size;
    [a, next] = [next, a];
  }
  for (let i = 0; i < n; i++) out[i] = a[i];
}
