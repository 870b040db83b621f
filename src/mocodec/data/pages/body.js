// A skeleton's mannequin (mocodec.mannequin) as the pages draw it: a three.js SkinnedMesh whose
// skinning matrices are written from the joints' global positions and rotations, and the live
// pages' cache of mannequins asked of their server. Served at /shared/ by the viewer and the
// relay alike.
import * as THREE from "three";

/** A base64 string of little-endian float32 values (as mocodec's servers send arrays). */
export function f32(b64) {
  const bin = atob(b64);
  const bytes = new Uint8Array(bin.length);
  for (let i = 0; i < bin.length; i++) bytes[i] = bin.charCodeAt(i);
  return new Float32Array(bytes.buffer);
}

/** A base64 string of little-endian uint32 values. */
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
  // a live avatar now: joint positions and rotations (w first), at the level of detail its
  // root's distance from `camera` calls for
  follow(positions, wxyz, camera) {
    this.pose(positions, wxyz, 0, true);
    const at = camera.position;
    this.detail(detailAt(Math.hypot(positions[0] - at.x, positions[1] - at.y, positions[2] - at.z)));
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

// nearer than these (metres) a live avatar is drawn at levels 0 and 1 of detail; farther, at 2
const DETAIL_M = [6, 15];

/** The level of detail for an avatar `metres` from the camera. */
function detailAt(metres) {
  return DETAIL_M.filter((m) => metres >= m).length;
}

// The mannequins of a live room's avatars, asked of the page's server (POST `url` with the
// stream header's skeleton and a frame's bones) once per kind of avatar and kept.
export class Mannequins {
  constructor(url) {
    this.url = url;
    this.levels = new Map();  // request text -> null while asked, false if refused, or the levels
  }
  // `avatar`'s levels of detail, or null while they are on their way (or refused); `memo` is
  // an object kept with the avatar, where its request is remembered
  of(avatar, memo) {
    if (!memo.key) {
      const frame = avatar.decoded.values().next().value;
      if (!frame) return null;
      const { posIndex } = avatar.skeleton, bones = new Array(frame.length).fill(0);
      for (let k = 3; k < posIndex.length; k++) if (posIndex[k] >= 0) bones[posIndex[k]] = frame[posIndex[k]];
      memo.key = JSON.stringify({ skeleton: avatar.info.skeletonDoc, frame: bones });  // one per kind of avatar
    }
    if (!this.levels.has(memo.key)) {
      this.levels.set(memo.key, null);
      fetch(this.url, { method: "POST", body: memo.key })
        .then((r) => (r.ok ? r.json() : null))
        .then((d) => this.levels.set(memo.key, d ? d.levels : false), () => this.levels.set(memo.key, false));
    }
    return this.levels.get(memo.key) || null;
  }
}
