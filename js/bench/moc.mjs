// .moc kinwave decode speed in Node on one core: each file given (default: the .moc files of
// tests/data/moc/) decoded whole over and over for a while; prints frames per second, with and
// without forward kinematics, and where FILE.f64 (the Python decoder's channels, float64) sits
// beside it, the largest difference from them.      node js/bench/moc.mjs [--seconds S] [file.moc ...]
import { existsSync, readFileSync, readdirSync } from 'node:fs';
import { basename } from 'node:path';
import { fileURLToPath } from 'node:url';
import { decodeMoc, forwardKinematics } from '../src/index.js';

const args = process.argv.slice(2);
const at = args.indexOf('--seconds');
const seconds = at >= 0 ? Number(args.splice(at, 2)[1]) : 2;
const fixtures = fileURLToPath(new URL('../../tests/data/moc/', import.meta.url));
const files = args.length ? args : readdirSync(fixtures).filter((f) => f.endsWith('.moc')).map((f) => fixtures + f);

async function rate(data, pose) {
  let frames = 0;
  const start = performance.now();
  while (performance.now() - start < seconds * 1000) {
    const decoded = await decodeMoc(data);
    if (pose) forwardKinematics(decoded.skeleton, decoded.channels);
    frames += decoded.frames;
  }
  return frames / ((performance.now() - start) / 1000);
}

const rows = [];
for (const file of files) {
  const data = new Uint8Array(readFileSync(file));
  const first = await decodeMoc(data);
  const decode = await rate(data, false);
  const posed = await rate(data, true);
  let worst = null;
  if (existsSync(`${file}.f64`)) {
    const bytes = readFileSync(`${file}.f64`);
    const python = new Float64Array(bytes.buffer, bytes.byteOffset, bytes.byteLength / 8);
    worst = python.length === first.channels.length ? 0 : Infinity;
    for (let i = 0; i < python.length && worst < Infinity; i++) worst = Math.max(worst, Math.abs(python[i] - first.channels[i]));
  }
  rows.push({ file: basename(file), frames: first.frames, channels: first.skeleton.numChannels, decode, posed, worst });
  console.log(`${basename(file)}: ${first.frames} frames x ${first.skeleton.numChannels} channels: `
    + `${decode.toFixed(0)} frames/s decoded, ${posed.toFixed(0)} with forward kinematics`
    + (worst === null ? '' : `, worst difference from Python ${worst.toExponential(1)}`));
}
if (process.env.MOCODEC_BENCH_JSON) console.log(JSON.stringify(rows));
