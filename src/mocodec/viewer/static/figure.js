// A skeleton drawn from joint positions (metres): bones as line segments, joints as small
// spheres with a colour each. Shared by the viewer and the study pages.
import * as THREE from "three";

export function f32(b64) {
  const bin = atob(b64);
  const bytes = new Uint8Array(bin.length);
  for (let i = 0; i < bin.length; i++) bytes[i] = bin.charCodeAt(i);
  return new Float32Array(bytes.buffer);
}

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

export function u32(b64) {
  return new Uint32Array(f32(b64).buffer);
}

// A skeleton's mannequin (mocodec.mannequin, from the server) skinned by three.js: one bone per
// joint, every bone a child of the body's group and set to the joint's global position and
// orientation each frame, so the skinning needs no hierarchy. Vertex colours paint the body,
// each vertex the colour of the joint its bone ends at (the error heatmap).
export class Body {
  constructor(scene, mesh, colour) {
    const positions = f32(mesh.positions), bind = f32(mesh.bind);
    this.owners = u32(mesh.owners);
    this.count = this.owners.length;
    const geometry = new THREE.BufferGeometry();
    geometry.setAttribute("position", new THREE.BufferAttribute(positions, 3));
    geometry.setAttribute("normal", new THREE.BufferAttribute(f32(mesh.normals), 3));
    geometry.setAttribute("skinIndex", new THREE.Uint16BufferAttribute(Uint16Array.from(u32(mesh.joints)), 4));
    geometry.setAttribute("skinWeight", new THREE.BufferAttribute(f32(mesh.weights), 4));
    geometry.setAttribute("color", new THREE.BufferAttribute(new Float32Array(this.count * 3), 3));
    geometry.setIndex(new THREE.BufferAttribute(u32(mesh.triangles), 1));
    this.joints = bind.length / 3;
    this.bones = Array.from({ length: this.joints }, () => new THREE.Bone());
    const inverses = this.bones.map((_, j) => new THREE.Matrix4().makeTranslation(-bind[3 * j], -bind[3 * j + 1], -bind[3 * j + 2]));
    this.material = new THREE.MeshStandardMaterial({ vertexColors: true, roughness: 0.75, metalness: 0.0 });
    this.mesh = new THREE.SkinnedMesh(geometry, this.material);
    this.mesh.frustumCulled = false;       // its bind-pose bounds say nothing of where it is
    this.group = new THREE.Group();
    this.group.add(...this.bones, this.mesh);
    this.mesh.bind(new THREE.Skeleton(this.bones, inverses), new THREE.Matrix4());
    scene.add(this.group);
    this.paint(new THREE.Color(colour));
  }
  pose(positions, quats, frame) {
    const p = frame * this.joints * 3, q = frame * this.joints * 4;
    this.bones.forEach((bone, j) => {
      bone.position.set(positions[p + 3 * j], positions[p + 3 * j + 1], positions[p + 3 * j + 2]);
      bone.quaternion.set(quats[q + 4 * j], quats[q + 4 * j + 1], quats[q + 4 * j + 2], quats[q + 4 * j + 3]);
    });
  }
  paint(colour) {
    this.colour(Array.from({ length: this.joints }, () => colour));
  }
  colour(jointColours) {
    const rgb = this.mesh.geometry.attributes.color;
    for (let v = 0; v < this.count; v++) {
      const c = jointColours[this.owners[v]];
      rgb.setXYZ(v, c.r, c.g, c.b);
    }
    rgb.needsUpdate = true;
  }
}
