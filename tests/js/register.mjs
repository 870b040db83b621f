// `node --import ./tests/js/register.mjs --test tests/js/`: installs three-hooks.mjs first.
import { register } from 'node:module';

register('./three-hooks.mjs', import.meta.url);
