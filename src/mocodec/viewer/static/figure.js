// A skeleton drawn from joint positions (metres): bones as line segments, joints as small
// spheres with a colour each. Shared by the viewer and the study pages.
import * as THREE from "three";


export class Figure {
  constructor(scene, parents, boneColor, jointColor) {
    this.parents = parents;
    this.bones = parents.map((p, j) => [p, j]).filter(([p]) => p >= 0);
    const lines = new THREE.BufferGeometry();
    lines.setAttribute("position", new THREE.BufferAttribute(new Float32Array(this.bones.length * 6), 3));
    this.lines = new THREE.LineSegments(lines, new THREE.LineBasicMaterial({ color: boneColor }));
    const ball = new THREE.SphereGeometry(0.03, 10, 8);
    this.joints = new THREE.InstancedMesh(ball, new THREE.MeshBasicMaterial({ color: 0xffffff }), parents.length);
    for (let j = 0; j < parents.length; j++) this.joints.setColorAt(j, new THREE.Color(jointColor));
    this.group = new THREE.Group();
    this.group.add(this.lines, this.joints);
    scene.add(this.group);
    this.matrix = new THREE.Matrix4();
  }
  pose(positions, frame) {
    const n = this.parents.length, base = frame * n * 3;
    const at = (j, k) => positions[base + j * 3 + k];
    const line = this.lines.geometry.attributes.position.array;
    this.bones.forEach(([p, j], b) => {
      for (let k = 0; k < 3; k++) { line[b * 6 + k] = at(p, k); line[b * 6 + 3 + k] = at(j, k); }
    });
    this.lines.geometry.attributes.position.needsUpdate = true;
    this.lines.geometry.computeBoundingSphere();
    for (let j = 0; j < n; j++) {
      this.matrix.makeTranslation(at(j, 0), at(j, 1), at(j, 2));
      this.joints.setMatrixAt(j, this.matrix);
    }
    this.joints.instanceMatrix.needsUpdate = true;
  }
  colour(colours) {
    colours.forEach((c, j) => this.joints.setColorAt(j, c));
    this.joints.instanceColor.needsUpdate = true;
  }
}
