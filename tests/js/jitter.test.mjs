// The JavaScript jitter buffer behaves as stream/jitter.py (tests/test_jitter.py's cases).
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { JitterBuffer } from '../../js/src/index.js';
import { seeded } from './seeded.mjs';

// frames of two channels: frame k is (k, 2k)
const ramp = (n, from = 0) => Float64Array.from({ length: 2 * (n - from) }, (_, i) => (from + (i >> 1)) * ((i & 1) + 1));
const close = (a, b, tol = 1e-9) => a.every((v, i) => Math.abs(v - b[i]) <= tol);

test('jittered bursts play out smoothly at the frame rate', () => {
  const fps = 120;
  const packet = 6;
  const random = seeded(5);
  const buffer = new JitterBuffer(fps, 2, 0.1);
  const arrivals = [];
  for (let k = 0; k < 1200; k += packet) arrivals.push([k, (k + packet) / fps + random() * 0.06]);
  arrivals.sort((a, b) => a[1] - b[1]);
  const shown = [];
  for (let now = 0.3; now < 9.0; now += 1 / 90) {
    while (arrivals.length && arrivals[0][1] <= now) {
      const [k, t] = arrivals.shift();
      buffer.push(ramp(k + packet, k), k, t);
    }
    shown.push(buffer.pose(now)[0]);
  }
  for (let i = 1; i < shown.length; i++) {
    const step = shown[i] - shown[i - 1];
    assert.ok(Math.abs(step / (fps / 90) - 1) <= 0.01 * 1.001 + 1e-9, `step ${i}: ${step}`);
  }
  assert.equal(buffer.late, 0);
});

test('interpolation between frames, held past the end and over gaps', () => {
  const buffer = new JitterBuffer(10, 2, 0);
  buffer.push(ramp(3), 0, 0.2);
  assert.ok(close(buffer.pose(0.05), [0.5, 1.0]));
  assert.ok(close(buffer.pose(5.0), [2.0, 4.0]));
  buffer.push(ramp(8, 6), 6, 0.55);
  assert.ok(close(buffer.pose(0.45), [2.0, 4.0]) && close(buffer.pose(0.7), [7.0, 14.0]));
});

test('a late burst lengthens the delay, and nothing shows before the first frame', () => {
  assert.equal(new JitterBuffer(30, 2).pose(1.0), null);
  const buffer = new JitterBuffer(30, 2, 0.1);
  buffer.push(ramp(1), 0, 1.0);
  const start = buffer.origin;
  buffer.push(ramp(2, 1), 1, 1.0 + 1 / 30 + 0.2);
  assert.equal(buffer.late, 1);
  assert.ok(Math.abs(buffer.origin - (start + 0.1)) < 1e-9);
  for (let f = 2; f < 900; f++) {
    buffer.push(ramp(f + 1, f), f, 1.0 + f / 30);
    buffer.pose(1.0 + f / 30);
  }
  assert.ok(Math.abs(buffer.origin - start) < 1e-6);
});
