// The watch page: joins the room named in the address with mocodec's JavaScript decoder and draws
// every avatar's bones; no decoding anywhere else.
import * as THREE from 'three';
import { RelayClient, forwardKinematics } from '/decoder/index.js';

const params = new URLSearchParams(location.search);
const relayUrl = `${location.protocol === 'https:' ? 'wss' : 'ws'}://${location.host}`;
const client = new RelayClient(relayUrl, {
  room: params.get('room') ?? '', token: params.get('token') ?? '', budget: Number(params.get('budget') ?? 0),
});
const status = document.getElementById('status');

const renderer = new THREE.WebGLRenderer({ antialias: true, preserveDrawingBuffer: true });
renderer.setSize(innerWidth, innerHeight);
document.body.appendChild(renderer.domElement);
const scene = new THREE.Scene();
const camera = new THREE.PerspectiveCamera(50, innerWidth / innerHeight, 0.05, 200);
camera.position.set(0, 2, 8);
camera.lookAt(0, 1, 0);
const figures = new Map(); // stream -> LineSegments

function figure(avatar) {
  const bones = avatar.skeleton.joints.length - 1;
  const geometry = new THREE.BufferGeometry();
  geometry.setAttribute('position', new THREE.BufferAttribute(new Float32Array(bones * 6), 3));
  const lines = new THREE.LineSegments(geometry, new THREE.LineBasicMaterial({ color: 0x66ccff }));
  lines.frustumCulled = false;
  scene.add(lines);
  return lines;
}

function draw() {
  const t = performance.now() / 1000;
  for (const [stream, avatar] of client.avatars) {
    const pose = avatar.pose(t);
    if (!pose) continue;
    const lines = figures.get(stream) ?? figures.set(stream, figure(avatar)).get(stream);
    const out = lines.geometry.attributes.position.array;
    avatar.skeleton.joints.forEach((j, i) => {
      if (i === 0) return;
      out.set(pose.subarray(3 * j.parent, 3 * j.parent + 3), 6 * (i - 1));
      out.set(pose.subarray(3 * i, 3 * i + 3), 6 * (i - 1) + 3);
    });
    lines.geometry.attributes.position.needsUpdate = true;
  }
  renderer.render(scene, camera);
  const note = client.statuses.at(-1);
  status.textContent = `${client.avatars.size} avatars, decoded in this page${note ? ` (${note})` : ''}`;
}

window.watch = {
  ready: false,
  avatars: () => [...client.avatars.values()].map((a) => ({
    stream: a.stream, name: a.name, joints: a.skeleton.joints.length, frames: a.frames, errors: a.errors,
  })),
  // joint positions (metres) of a decoded stream frame, for the tests
  positions(stream, frame) {
    const avatar = client.avatars.get(stream);
    const channels = avatar?.decoded.get(frame);
    if (!channels) return null;
    return Array.from(forwardKinematics(avatar.skeleton, channels), (v) => v / avatar.skeleton.unitsPerMetre);
  },
  frames: (stream) => [...(client.avatars.get(stream)?.decoded.keys() ?? [])],
  drawnPixels() {
    const gl = renderer.getContext();
    const pixels = new Uint8Array(gl.drawingBufferWidth * gl.drawingBufferHeight * 4);
    gl.readPixels(0, 0, gl.drawingBufferWidth, gl.drawingBufferHeight, gl.RGBA, gl.UNSIGNED_BYTE, pixels);
    let drawn = 0;
    for (let k = 0; k < pixels.length; k += 4) if (pixels[k] + pixels[k + 1] + pixels[k + 2] > 0) drawn += 1;
    return drawn;
  },
};

client.connect().then(() => {
  window.watch.ready = true;
  renderer.setAnimationLoop(draw);
}, (e) => { status.textContent = e.message; });
