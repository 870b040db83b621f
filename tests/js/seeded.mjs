// A seeded generator of numbers in [0, 1) for the Node tests (a linear congruential one, so a
// fuzz or jitter case repeats exactly).
export function seeded(seed) {
  return () => {
    seed = (seed * 1103515245 + 12345) % 2147483648;
    return seed / 2147483648;
  };
}
