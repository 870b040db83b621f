// A .glb written with `--mesh mannequin`, loaded by three.js's own GLTFLoader: a skinned mesh
// with the vertex, joint and weight counts mocodec wrote, weights that sum to one, and at one
// frame of its animation the vertices where mocodec's linear-blend skinning puts them
// (walk_mannequin.glb.json, from tests/js/make_fixtures.py).
import { test } from 'node:test';
import assert from 'node:assert/strict';
import * as THREE from 'three';
import { loadGlb } from './glb-fixture.mjs';

async function loadFixture() {
  const { gltf, expected } = await loadGlb('walk_mannequin.glb');
  let body = null;
  gltf.scene.traverse((o) => { if (o.isSkinnedMesh) body = o; });
  return { gltf, body, expected };
}

test('the file holds one skinned mesh with the counts mocodec wrote', async () => {
  const { body, expected } = await loadFixture();
  assert.ok(body, 'no SkinnedMesh in the scene');
  const geometry = body.geometry;
  assert.equal(geometry.attributes.position.count, expected.vertices);
  assert.equal(geometry.attributes.normal.count, expected.vertices);
  assert.equal(geometry.attributes.skinIndex.count, expected.vertices);
  assert.equal(geometry.attributes.skinWeight.count, expected.vertices);
  assert.equal(geometry.index.count, 3 * expected.triangles);
  assert.equal(body.skeleton.bones.length, expected.joints);
});

test('every vertex\'s skin weights sum to one', async () => {
  const { body } = await loadFixture();
  const weights = body.geometry.attributes.skinWeight;
  let worst = 0;
  for (let i = 0; i < weights.count; i++) {
    const sum = weights.getX(i) + weights.getY(i) + weights.getZ(i) + weights.getW(i);
    worst = Math.max(worst, Math.abs(sum - 1));
  }
  assert.ok(worst < 1e-6, `a vertex's weights are ${worst} off one`);
});

test('at one frame the skinned vertices are where mocodec puts them', async () => {
  const { gltf, body, expected } = await loadFixture();
  const mixer = new THREE.AnimationMixer(gltf.scene);
  mixer.clipAction(gltf.animations[0]).play();
  mixer.setTime(expected.pose_frame / expected.fps);
  gltf.scene.updateMatrixWorld(true);
  body.skeleton.update();
  let worst = 0;
  const vertex = new THREE.Vector3();
  for (const [index, want] of Object.entries(expected.posed_m)) {
    body.getVertexPosition(Number(index), vertex);
    vertex.applyMatrix4(body.matrixWorld);
    worst = Math.max(worst, vertex.distanceTo(new THREE.Vector3(...want)));
  }
  // weights are stored as bytes (1/255 each), positions as 32-bit floats
  assert.ok(worst < 0.001, `the worst vertex is ${worst} m away`);
});
