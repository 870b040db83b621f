// A glTF file mocodec writes, loaded by three.js's own GLTFLoader: the bones, the clip's
// duration and the pose at one frame are what the Python side computed (walk.glb.json).
import { test } from 'node:test';
import assert from 'node:assert/strict';
import * as THREE from 'three';
import { loadGlb } from './glb-fixture.mjs';

const loadFixture = () => loadGlb('walk.glb');

test('every joint is a bone and the clip lasts as long as the motion', async () => {
  const { gltf, expected } = await loadFixture();
  const bones = [];
  gltf.scene.traverse((o) => { if (o.isBone) bones.push(o); });
  assert.equal(bones.length, expected.joints);
  assert.equal(gltf.animations.length, 1);
  assert.ok(Math.abs(gltf.animations[0].duration - expected.duration_s) < 1e-6);
});

test('the pose at one frame puts every joint where mocodec does', async () => {
  const { gltf, expected } = await loadFixture();
  const mixer = new THREE.AnimationMixer(gltf.scene);
  mixer.clipAction(gltf.animations[0]).play();
  mixer.setTime(expected.pose_frame / expected.fps);
  gltf.scene.updateMatrixWorld(true);
  let worst = 0;
  for (const [name, want] of Object.entries(expected.positions_m)) {
    const node = gltf.scene.getObjectByName(name);
    assert.ok(node, `no node named ${name}`);
    const got = node.getWorldPosition(new THREE.Vector3());
    worst = Math.max(worst, got.distanceTo(new THREE.Vector3(...want)));
  }
  assert.ok(worst < 1e-5, `worst joint is ${worst} m away`);
});
