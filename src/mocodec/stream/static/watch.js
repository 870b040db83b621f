// The watch page: joins the room named in the address with mocodec's JavaScript decoder and draws
// every avatar as a body (its mannequin, asked of the relay once per kind of skeleton, at a level
// of detail by distance), or its bones until the body is there or with &figures=sticks; no
// decoding anywhere else.
import * as THREE from 'three';
import { RelayClient, forwardKinematics } from '/decoder/index.js';
import { Body, Mannequins } from '/shared/body.js';

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
scene.add(new THREE.HemisphereLight(0xffffff, 0x444444, 2.5));
const camera = new THREE.PerspectiveCamera(50, innerWidth / innerHeight, 0.05, 200);
camera.position.set(0, 2, 8);
camera.lookAt(0, 1, 0);
const figures = new Map(); // stream -> its lines, body and rotations
const mannequins = new Mannequins('/mannequin');
const bodies = params.get('figures') !== 'sticks';

function figure(avatar) {
  const bones = avatar.skeleton.joints.length - 1;
  const geometry = new THREE.BufferGeometry();
  geometry.setAttribute('position', new THREE.BufferAttribute(new Float32Array(bones * 6), 3));
  const lines = new THREE.LineSegments(geometry, new THREE.LineBasicMaterial({ color: 0x66ccff }));
  lines.frustumCulled = false;
  scene.add(lines);
  return { lines, body: null, wxyz: new Float64Array(4 * avatar.skeleton.joints.length), key: null };
}

function draw() {
  const t = performance.now() / 1000;
  for (const [stream, avatar] of client.avatars) {
    const shown = figures.get(stream) ?? figures.set(stream, figure(avatar)).get(stream);
    const pose = avatar.pose(t, shown.wxyz);
    if (!pose) continue;
    const levels = bodies ? mannequins.of(avatar, shown) : null;
    if (levels && !shown.body) shown.body = new Body(scene, levels, 0x8a9bb8);
    shown.lines.visible = !shown.body;
    if (shown.body) {
      shown.body.follow(pose, shown.wxyz, camera);
      continue;
    }
    const out = shown.lines.geometry.attributes.position.array;
    avatar.skeleton.joints.forEach((j, i) => {
      if (i === 0) return;
      out.set(pose.subarray(3 * j.parent, 3 * j.parent + 3), 6 * (i - 1));
      out.set(pose.subarray(3 * i, 3 * i + 3), 6 * (i - 1) + 3);
    });
    shown.lines.geometry.attributes.position.needsUpdate = true;
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
  bodies: () => [...figures.values()].filter((shown) => shown.body).length,
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
