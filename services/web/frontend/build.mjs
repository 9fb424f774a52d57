// Bundle the npm packages the page uses into ../asibot/web/static/vendor/, one ES module per entry.
// Our own page code (../asibot/web/static/js/) imports these files and is served as written: no build.
import { build } from 'esbuild';
import { copyFileSync, mkdirSync } from 'node:fs';
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
// The API's own page (/docs): Swagger UI as its package ships it, served by us, so it works offline.
const swagger = join(here, '../asibot/web/static/vendor/swagger');
mkdirSync(swagger, { recursive: true });
for (const file of ['swagger-ui-bundle.js', 'swagger-ui.css', 'LICENSE', 'NOTICE']) {
  copyFileSync(join(here, 'node_modules/swagger-ui-dist', file), join(swagger, file));
}
console.log('web: front-end packages bundled into services/web/asibot/web/static/vendor/');
