// Decode speed in Node on one core: the live kinwave-live streams of tests/data/live/ (a 38-joint ASF skeleton
// at 30 fps, 57-joint BVH ones at 120 fps), decoded and posed (forward
// kinematics) over and over; prints poses per second and what that means in avatars at 30
// packets/s.      node js/bench/decode.mjs [seconds]
import { readFileSync } from 'node:fs';
import { Reader, StreamDecoder, forwardKinematics, parseStreamHeader, splitBatch } from '../src/index.js';

const seconds = Number(process.argv[2] ?? 3);
const LIVE = new URL('../../tests/data/live/', import.meta.url);

for (const name of ['asf-30fps-shell', 'walk', 'walk-layers']) {
  const reader = new Reader();
  const packets = splitBatch(new Uint8Array(readFileSync(new URL(`${name}.stream`, LIVE)))).map((raw) => reader.read(raw));
  const info = await parseStreamHeader(packets[0].payload);
  let poses = 0;
  let packetsDone = 0;
  const start = performance.now();
  while (performance.now() - start < seconds * 1000) {
    const decoder = new StreamDecoder(info);
    for (const p of packets.slice(1)) {
      const frames = decoder.push(p);
      if (!frames) continue;
      forwardKinematics(info.skeleton, frames);
      poses += frames.length / info.skeleton.numChannels;
      packetsDone += 1;
    }
  }
  const elapsed = (performance.now() - start) / 1000;
  const joints = info.skeleton.joints.length;
  const layers = info.codec.knobs.layers ?? 1;
  console.log(`${name}: ${joints} joints, ${info.fps} fps, ${layers} layer(s): ${(poses / elapsed).toFixed(0)} poses/s, `
    + `${(packetsDone / elapsed).toFixed(0)} packets/s = ${(packetsDone / elapsed / 30).toFixed(0)} avatars at 30 packets/s`);
}
