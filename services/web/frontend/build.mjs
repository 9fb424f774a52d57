// Bundle the npm packages the page uses into ../asibot/web/static/vendor/, one ES module per entry.
// Our own page code (../asibot/web/static/js/) imports these files and is served as written: no build.
import { build } from 'esbuild';
import { dirname, join } from 'node:path';
import { fileURLToPath } from 'node:url';

const here = dirname(fileURLToPath(import.meta.url));
await build({
  entryPoints: [join(here, 'entries/three.js'), join(here, 'entries/codemirror.js')],
  outdir: join(here, '../asibot/web/static/vendor'),
  bundle: true,
  format: 'esm',
  minify: true,
  legalComments: 'linked',
  target: 'es2020',
  logLevel: 'warning',
});
console.log('web: front-end packages bundled into services/web/asibot/web/static/vendor/');
