// Every name the package exports (js/src/index.js) that is a function or a class is documented
// with JSDoc where it is defined, and an exported function's block names each of its parameters.
import { test } from 'node:test';
import assert from 'node:assert/strict';
import { readFileSync } from 'node:fs';

const SRC = new URL('../../js/src/', import.meta.url);
const index = readFileSync(new URL('index.js', SRC), 'utf8');

function exportsOf(text) {
  const out = [];
  for (const [, names, file] of text.matchAll(/export \{([^}]*)\} from '\.\/([^']+)'/g)) {
    for (const name of names.split(',').map((n) => n.trim()).filter(Boolean)) out.push([name, file]);
  }
  return out;
}

test('every exported function and class has a JSDoc block naming its parameters', () => {
  const missing = [];
  for (const [name, file] of exportsOf(index)) {
    const text = readFileSync(new URL(file, SRC), 'utf8');
    const at = text.search(new RegExp(`^export (async )?(function|class) ${name}\\b`, 'm'));
    if (at < 0) continue; // a constant
    const before = text.slice(0, at).trimEnd();
    if (!before.endsWith('*/')) {
      missing.push(`${file}: ${name} has no JSDoc`);
      continue;
    }
    const block = before.slice(before.lastIndexOf('/**'));
    const signature = text.slice(at).match(/^export (?:async )?function \w+\(([^)]*)\)/);
    if (signature) {
      const params = signature[1].replace(/\{[^}]*\}( = \{\})?/g, '').split(',').map((p) => p.trim().split(/[\s=]/)[0]).filter((p) => p && !p.startsWith('{'));
      for (const param of params) {
        if (!new RegExp(`@param \\{[^}]+\\} \\[?${param}\\b`).test(block)) missing.push(`${file}: ${name} does not document ${param}`);
      }
      if (!/@returns/.test(block)) missing.push(`${file}: ${name} has no @returns`);
    }
  }
  assert.deepEqual(missing, []);
});
