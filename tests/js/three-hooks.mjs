// Module resolution hooks for the Node tests: the bare specifier 'three' (which the three.js
// addons import) resolves to the pinned copy in the package (src/mocodec/data/three).
const THREE = new URL('../../src/mocodec/data/three/three.module.js', import.meta.url).href;

export async function resolve(specifier, context, nextResolve) {
  if (specifier === 'three') return { url: THREE, shortCircuit: true };
  return nextResolve(specifier, context);
}
