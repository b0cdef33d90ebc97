// Frame-time benchmark of the page (issue: the viewer): opens build-wasm/web/ in headless Chromium
// (software WebGL), sets a fine uniform model (Euclidean, small delta) so the mesh grows to about
// 20,000 vertices, pauses, and prints the frame interval the page measures. Prints figures; asserts
// nothing (speed targets live in benchmarks, not tests).
//
// Usage: node tests/web/frame_bench.mjs [WEB_DIR] [DELTA_VOXELS]
import { chromium } from 'playwright-core';
import fs from 'node:fs';
import http from 'node:http';
import os from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';

const top = path.resolve(path.dirname(fileURLToPath(import.meta.url)), '../..');
const webDir = path.resolve(process.argv[2] || path.join(top, 'build-wasm/web'));
const delta = Number(process.argv[3] || 0.85);
const types = { '.html': 'text/html', '.js': 'text/javascript', '.wasm': 'application/wasm' };
const server = http.createServer((req, res) => {
  const rel = decodeURIComponent(new URL(req.url, 'http://127.0.0.1').pathname.replace(/^\/$/, '/index.html'));
  const file = path.join(webDir, path.normalize(rel));
  if (!file.startsWith(webDir) || !fs.existsSync(file)) { res.writeHead(404); res.end(); return; }
  res.writeHead(200, { 'Content-Type': types[path.extname(file)] || 'application/octet-stream' });
  fs.createReadStream(file).pipe(res);
});
await new Promise((r) => server.listen(0, '127.0.0.1', r));
const profile = fs.mkdtempSync(path.join(os.tmpdir(), 'riemesh-frame-'));
const context = await chromium.launchPersistentContext(profile, {
  executablePath: process.env.RIEMESH_CHROMIUM || '/usr/bin/chromium', headless: true,
  viewport: { width: 1280, height: 800 },
  args: ['--no-sandbox', '--enable-unsafe-swiftshader', '--disable-background-networking'],
});
const sleep = (ms) => new Promise((r) => setTimeout(r, ms));
try {
  const page = context.pages()[0] || (await context.newPage());
  await page.goto(`http://127.0.0.1:${server.address().port}/`);
  const state = async () => page.evaluate(() => window.riemesh.state());
  while (!(await page.evaluate(() => !!(window.riemesh && window.riemesh.state)))) await sleep(200);
  {
    // The same draw with the demo's own coarse mesh first, for a ratio in the same run.
    let c = await state();
    while (c.state !== 'converged' && c.state !== 'iteration-cap') { await sleep(500); c = await state(); }
    const coarseMs = await page.evaluate(() => Module.ccall('riemesh_time_draw', 'number', ['number'], [20]));
    console.log(`frame_bench: draw of the demo's ${c.vertices}-vertex mesh ${coarseMs.toFixed(1)} ms`);
  }
  await page.evaluate((d) => { window.riemesh.set('riemannian', 0); window.riemesh.set('delta', d); window.riemesh.play(); }, delta);
  const started = Date.now();
  let s = await state();
  while (Date.now() - started < 300000 && s.state !== 'converged') { await sleep(1000); s = await state(); }
  await page.evaluate(() => window.riemesh.pause());
  const frames = [];
  for (let i = 0; i < 10; i++) { await sleep(300); frames.push((await state()).frameMs); }
  frames.sort((a, b) => a - b);
  // The draw itself (mesh, wireframe, slice), each waited for by a pixel read back: what the mesh costs.
  const drawMs = await page.evaluate(() => Module.ccall('riemesh_time_draw', 'number', ['number'], [20]));
  console.log(`frame_bench: draw of the scene ${drawMs.toFixed(1)} ms (mean of 20, each waited for)`);
  console.log(`frame_bench: ${s.vertices} vertices (${s.state} after ${s.iteration} iterations), ` +
              `paused frame interval median ${frames[5].toFixed(1)} ms, min ${frames[0].toFixed(1)} ms ` +
              `(headless Chromium, software WebGL)`);
} finally {
  await context.close();
  server.close();
  fs.rmSync(profile, { recursive: true, force: true });
}
