// Builds the viewer into three files the server embeds: index.html, viewer.js (three.js
// bundled in, so nothing is fetched from elsewhere at run time) and viewer.css.
// Usage: node build.mjs [OUTDIR]   (default: dist)
import { build } from 'esbuild';
import { copyFile, mkdir } from 'node:fs/promises';
import path from 'node:path';
import { fileURLToPath } from 'node:url';

const here = path.dirname(fileURLToPath(import.meta.url));
const outdir = path.resolve(process.argv[2] ?? path.join(here, 'dist'));

await mkdir(outdir, { recursive: true });
await build({
  entryPoints: [path.join(here, 'src/main.js')],
  bundle: true,
  minify: true,
  format: 'esm',
  target: 'es2020',
  outfile: path.join(outdir, 'viewer.js'),
  legalComments: 'eof',  // three.js is MIT: its notice travels with the bundle
  logLevel: 'warning',
});
for (const name of ['index.html', 'viewer.css']) {
  await copyFile(path.join(here, 'src', name), path.join(outdir, name));
}
