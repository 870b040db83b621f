// Seam smoothing (coding/transforms/seams.py): at each seam between independently coded blocks the
// step (the difference of each side's quadratic extrapolation to the midpoint) beyond four times the
// motion's own steps nearby, at most a limit, is spread over `half` frames each side by raised cosines.
const A = 0.375;
const B = -1.25;
const C = 1.875;
const PROBES = [-8, -6, -4, 4, 6, 8];

function seamStep(x, s) {
  const left = A * x[s - 3] + B * x[s - 2] + C * x[s - 1];
  const right = A * x[s + 2] + B * x[s + 1] + C * x[s];
  return right - left;
}

// The median size of the steps the motion shows at frames 4 to 8 from the seam (seams.natural_steps).
function naturalStep(x, s, sizes) {
  let count = 0;
  for (const p of PROBES) if (s + p >= 3 && s + p <= x.length - 3) sizes[count++] = Math.abs(seamStep(x, s + p));
  if (!count) return 0;
  const sorted = sizes.subarray(0, count).sort();
  return (sorted[(count - 1) >> 1] + sorted[count >> 1]) / 2;
}

// One channel's row `x` (frames), smoothed in place at `seams` (first frames of the right blocks),
// the k-th seam's removal at most limits[k]. Steps are measured before any change, as in Python.
export function smoothSeams(x, seams, half, limits) {
  const T = x.length;
  const halves = new Float64Array(seams.length);
  const sizes = new Float64Array(PROBES.length);
  for (let k = 0; k < seams.length; k++) {
    const s = seams[k];
    if (s < 3 || s + 3 > T) continue;
    const step = seamStep(x, s);
    const size = Math.min(Math.max(Math.abs(step) - 4.0 * naturalStep(x, s, sizes), 0.0), limits[k]);
    halves[k] = 0.5 * Math.sign(step) * size;
  }
  const weight = Float64Array.from({ length: half }, (_, i) => 0.5 * (1 + Math.cos((Math.PI * (i + 0.5)) / half)));
  for (let k = 0; k < seams.length; k++) {
    for (let i = 0; i < half; i++) {
      const row = seams[k] - 1 - i;
      if (row >= 0 && row < T) x[row] += halves[k] * weight[i];
    }
  }
  for (let k = 0; k < seams.length; k++) {
    for (let i = 0; i < half; i++) {
      const row = seams[k] + i;
      if (row >= 0 && row < T) x[row] += -1.0 * halves[k] * weight[i];
    }
  }
}
