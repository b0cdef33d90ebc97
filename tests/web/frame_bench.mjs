// Frame-time benchmark of the page (issue 4: a frame with a 20,000-vertex mesh under 16 ms in headless
// Chromium's software WebGL). Opens build-wasm/web/ in headless Chromium (SwiftShader), and for the
// demo's own coarse mesh (~1.5k vertices) and for a fine uniform model (Euclidean, small delta: ~20k
// vertices) prints
//   - draw: the scene's draw alone (mesh, slice, cross-section; then with the wireframe too), each
//     render waited for by a pixel read back (Module.ccall('riemesh_time_draw', n)): what the mesh
//     costs the GPU process; and, on builds that have riemesh_time_frame, the whole frame as drawn
//     while the camera moves (the scene, then the UI composited from its layer);
//   - frame interval: the time between the page's animation frames (requestAnimationFrame timestamps
//     over a few seconds; median, mean, 90th percentile) paused (an unchanged image is not drawn
//     again), paused while the camera orbits (its yaw changes every frame: every frame draws) and while
//     evolving (every frame runs an evolution step, rebuilds the geometry and draws), and the
//     viewer's own main-thread time per frame (model + UI, "cpuMs" of riemesh.state()).
// Prints figures; asserts nothing (speed targets live in benchmarks, not tests). The machine's load
// moves every figure: compare figures of one run.
//
// Usage: node tests/web/frame_bench.mjs [WEB_DIR] [DELTA_VOXELS] [ROUNDS]
//   DELTA_VOXELS (default 0.8) sets the fine model's size (0.8: ~19.5k vertices on the phantom);
//   ROUNDS (default 3): measurements repeated, the median of them printed.
import { chromium } from 'playwright-core';
import fs from 'node:fs';
import http from 'node:http';
import os from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';

const top = path.resolve(path.dirname(fileURLToPath(import.meta.url)), '../..');
const webDir = path.resolve(process.argv[2] || path.join(top, 'build-wasm/web'));
const delta = Number(process.argv[3] || 0.8);
const rounds = Math.max(1, Number(process.argv[4] || 3));
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
const median = (xs) => { const s = [...xs].sort((a, b) => a - b); return s[Math.floor(s.length / 2)]; };
const fmt = (x) => x.toFixed(1);
try {
  const page = context.pages()[0] || (await context.newPage());
  await page.goto(`http://127.0.0.1:${server.address().port}/`);
  while (!(await page.evaluate(() => !!(window.riemesh && window.riemesh.state)))) await sleep(200);
  const state = async () => page.evaluate(() => window.riemesh.state());
  const stopped = (s) => s.state === 'converged' || s.state === 'iteration-cap';
  const waitStopped = async (timeoutMs) => {
    const started = Date.now();
    let s = await state();
    while (!stopped(s) && Date.now() - started < timeoutMs) { await sleep(500); s = await state(); }
    return s;
  };
  // Draw alone: mean of 20 waited-for renders; the median of `rounds` such means.
  const drawMs = async (what = 'riemesh_time_draw') => {
    const means = [];
    for (let i = 0; i < rounds; i++)
      means.push(await page.evaluate((what) => Module.ccall(what, 'number', ['number'], [20]), what));
    return median(means);
  };
  const hasFrame = await page.evaluate(() => typeof Module._riemesh_time_frame === 'function');
  // Animation-frame intervals over `ms` (requestAnimationFrame runs beside the page's own main loop),
  // with the viewer's main-thread time per frame sampled on the way; `during` runs each frame (JS).
  const frames = async (ms, keepEvolving, spin = false) => {
    const r = await page.evaluate(({ ms, keepEvolving, spin }) => new Promise((resolve) => {
      const stamps = [], cpu = [], vertices = [];
      const first = window.riemesh.state().iteration;
      let last = first;
      const tick = (t) => {
        stamps.push(t);
        const s = window.riemesh.state();
        cpu.push(s.cpuMs);
        vertices.push(s.vertices);
        last = s.iteration;
        // Keep the model moving: setting a parameter clears a convergence (the mesh evolves again).
        if (keepEvolving && s.state !== 'evolving') window.riemesh.set('inflation', 1.0);
        if (spin) window.riemesh.set('camera_yaw', -1.1 + 0.3 * Math.sin(0.01 * stamps.length));
        if (t - stamps[0] < ms) requestAnimationFrame(tick);
        else resolve({ stamps, cpu, vertices, iterations: last - first });
      };
      requestAnimationFrame(tick);
    }), { ms, keepEvolving, spin });
    const dt = r.stamps.slice(1).map((t, i) => t - r.stamps[i]);
    dt.sort((a, b) => a - b);
    const seconds = (r.stamps[r.stamps.length - 1] - r.stamps[0]) / 1000;
    return {
      perSecond: r.iterations / seconds,
      median: median(dt), mean: dt.reduce((a, b) => a + b, 0) / dt.length, p90: dt[Math.floor(0.9 * (dt.length - 1))],
      cpu: median(r.cpu.slice(1)), frames: dt.length, iterations: r.iterations,
      vmin: Math.min(...r.vertices), vmax: Math.max(...r.vertices),
    };
  };
  // The same while the camera orbits: its yaw swings about the home view and changes every animation
  // frame (a mouse drag at full rate), so every frame draws the whole scene.
  const orbit = (ms) => frames(ms, false, true);
  const report = (label, s, draw, drawWire, drawFrame, paused, orbiting, evolving) => {
    console.log(`frame_bench: ${label}: ${s.vertices} vertices, ${s.iteration} iterations (${s.state})`);
    console.log(`frame_bench:   draw ${fmt(draw)} ms, with the wireframe ${fmt(drawWire)} ms` +
      (drawFrame === undefined ? '' : `, whole frame (scene + UI from its layer) ${fmt(drawFrame)} ms`) +
      ` (mean of 20 waited-for renders, median of ${rounds})`);
    const line = (what, f) => console.log(
      `frame_bench:   ${what} frame interval median ${fmt(f.median)} ms, mean ${fmt(f.mean)}, p90 ${fmt(f.p90)} ` +
      `(${f.frames} frames; viewer main thread ${fmt(f.cpu)} ms/frame` +
      (f.iterations ? `; ${f.iterations} iterations, ${f.perSecond.toFixed(1)}/s, ${f.vmin}..${f.vmax} vertices)` : ')'));
    line('paused  ', paused);
    line('orbiting', orbiting);
    if (evolving) line('evolving', evolving);
  };
  const measure = async (label) => {
    await page.evaluate(() => window.riemesh.pause());
    await sleep(500);
    const s = await state();
    const draw = await drawMs();
    const drawFrame = hasFrame ? await drawMs('riemesh_time_frame') : undefined;
    await page.evaluate(() => window.riemesh.set('wireframe', 1));
    const drawWire = await drawMs();
    await page.evaluate(() => window.riemesh.set('wireframe', 0));
    const paused = [];
    for (let i = 0; i < rounds; i++) paused.push(await frames(2000, false));
    const orbiting = [];
    for (let i = 0; i < rounds; i++) orbiting.push(await orbit(2000));
    await page.evaluate(() => { window.riemesh.set('inflation', 1.0); window.riemesh.play(); });
    const evolving = [];
    for (let i = 0; i < rounds; i++) evolving.push(await frames(2000, true));
    await page.evaluate(() => window.riemesh.pause());
    const pick = (xs) => xs.sort((a, b) => a.median - b.median)[Math.floor(xs.length / 2)];
    report(label, s, draw, drawWire, drawFrame, pick(paused), pick(orbiting), pick(evolving));
  };

  // The demo's coarse mesh (the paper's phantom with its metric), once it has converged.
  await waitStopped(300000);
  await measure("demo's coarse model");
  // The fine uniform model: Euclidean metric, delta DELTA_VOXELS.
  await page.evaluate((d) => { window.riemesh.set('riemannian', 0); window.riemesh.set('delta', d); window.riemesh.play(); }, delta);
  await waitStopped(300000);
  await measure(`fine model (Euclidean, delta ${delta} voxels)`);
  console.log('frame_bench: headless Chromium, software WebGL (SwiftShader), 1280x800');
} finally {
  await context.close();
  server.close();
  fs.rmSync(profile, { recursive: true, force: true });
}
