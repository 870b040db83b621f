// A glTF fixture of tests/formats/ (written by tests/js/make_fixtures.py) loaded by three.js's own
// GLTFLoader, with what the Python side expects of it (NAME.json).
import { readFile } from 'node:fs/promises';
import { GLTFLoader } from '../../src/mocodec/data/three/addons/loaders/GLTFLoader.js';

const DATA = new URL('../formats/', import.meta.url);

export async function loadGlb(name) {
  const bytes = await readFile(new URL(name, DATA));
  const expected = JSON.parse(await readFile(new URL(`${name}.json`, DATA), 'utf8'));
  const buffer = bytes.buffer.slice(bytes.byteOffset, bytes.byteOffset + bytes.byteLength);
  const gltf = await new GLTFLoader().parseAsync(buffer, '');
  return { gltf, expected };
}
