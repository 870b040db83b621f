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

// A skeleton whose bone matrices Body.pose writes itself (skinning matrices: the joint's world
// transform times its inverse bind), so three.js has nothing to work out from bone objects.
class PosedSkeleton extends THREE.Skeleton {
  update() {
    if (this.boneTexture !== null) this.boneTexture.needsUpdate = true;
  }
}

// A skeleton's mannequin (mocodec.mannequin, from the server) skinned by three.js's SkinnedMesh,
// its bone matrices set each frame from the joints' global positions and rotations, so the
// skinning needs no bone hierarchy. Vertex colours paint the body, each vertex the colour of the
// joint its bone ends at (the error heatmap). Given the mesh at several levels of detail
// (nearest first), `detail(level)` shows one of them.
export class Body {
  constructor(scene, meshes, colour) {
    const levels = Array.isArray(meshes) ? meshes : [meshes];
    this.bind = f32(levels[0].bind);
    this.joints = this.bind.length / 3;
    this.skeleton = new PosedSkeleton(Array.from({ length: this.joints }, () => new THREE.Bone()));
    this.material = new THREE.MeshStandardMaterial({ vertexColors: true, roughness: 0.75, metalness: 0.0 });
    this.group = new THREE.Group();
    this.levels = levels.map((mesh) => {
      const owners = u32(mesh.owners);
      const geometry = new THREE.BufferGeometry();
      geometry.setAttribute("position", new THREE.BufferAttribute(f32(mesh.positions), 3));
      geometry.setAttribute("normal", new THREE.BufferAttribute(f32(mesh.normals), 3));
      geometry.setAttribute("skinIndex", new THREE.Uint16BufferAttribute(Uint16Array.from(u32(mesh.joints)), 4));
      geometry.setAttribute("skinWeight", new THREE.BufferAttribute(f32(mesh.weights), 4));
      geometry.setAttribute("color", new THREE.BufferAttribute(new Float32Array(owners.length * 3), 3));
      geometry.setIndex(new THREE.BufferAttribute(u32(mesh.triangles), 1));
      const skinned = new THREE.SkinnedMesh(geometry, this.material);
      skinned.frustumCulled = false;       // its bind-pose bounds say nothing of where it is
      skinned.bind(this.skeleton, new THREE.Matrix4());
      this.group.add(skinned);
      return { mesh: skinned, owners };
    });
    this.mesh = this.levels[0].mesh;
    this.detail(0);
    scene.add(this.group);
    this.paint(new THREE.Color(colour));
  }
  detail(level) {
    this.level = Math.min(level, this.levels.length - 1);
    this.levels.forEach(({ mesh }, k) => { mesh.visible = k === this.level; });
  }
  // each joint's skinning matrix, [R | x - R b] (column-major) for its world rotation R (x, y,
  // z, w; with `wxyz`, w first), position x plus the group's, and bind position b
  pose(positions, quats, frame, wxyz = false) {
    const p = frame * this.joints * 3, q = frame * this.joints * 4, at = this.group.position;
    const [ix, iy, iz, iw] = wxyz ? [1, 2, 3, 0] : [0, 1, 2, 3];
    const m = this.skeleton.boneMatrices, bind = this.bind;
    for (let j = 0; j < this.joints; j++) {
      const b = q + 4 * j, o = 16 * j;
      const x = quats[b + ix], y = quats[b + iy], z = quats[b + iz], w = quats[b + iw];
      const r0 = 1 - 2 * (y * y + z * z), r1 = 2 * (x * y + w * z), r2 = 2 * (x * z - w * y);
      const r4 = 2 * (x * y - w * z), r5 = 1 - 2 * (x * x + z * z), r6 = 2 * (y * z + w * x);
      const r8 = 2 * (x * z + w * y), r9 = 2 * (y * z - w * x), r10 = 1 - 2 * (x * x + y * y);
      const bx = bind[3 * j], by = bind[3 * j + 1], bz = bind[3 * j + 2];
      m[o] = r0; m[o + 1] = r1; m[o + 2] = r2; m[o + 3] = 0;
      m[o + 4] = r4; m[o + 5] = r5; m[o + 6] = r6; m[o + 7] = 0;
      m[o + 8] = r8; m[o + 9] = r9; m[o + 10] = r10; m[o + 11] = 0;
      m[o + 12] = positions[p + 3 * j] + at.x - (r0 * bx + r4 * by + r8 * bz);
      m[o + 13] = positions[p + 3 * j + 1] + at.y - (r1 * bx + r5 * by + r9 * bz);
      m[o + 14] = positions[p + 3 * j + 2] + at.z - (r2 * bx + r6 * by + r10 * bz);
      m[o + 15] = 1;
    }
  }
  paint(colour) {
    this.colour(Array.from({ length: this.joints }, () => colour));
  }
  colour(jointColours) {
    for (const { mesh, owners } of this.levels) {
      const rgb = mesh.geometry.attributes.color;
      for (let v = 0; v < owners.length; v++) {
        const c = jointColours[owners[v]];
        rgb.setXYZ(v, c.r, c.g, c.b);
      }
      rgb.needsUpdate = true;
    }
  }
}
