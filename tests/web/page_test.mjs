// Browser test of the riemesh page: serves build-wasm/web/ on 127.0.0.1, opens it in Debian's headless
// Chromium (playwright-core, /usr/bin/chromium, a fresh profile), waits for the model to converge
// ("riemesh: converged iterations=N vertices=V seconds=S" on the console), checks there were no page
// errors, screenshots the page and checks the canvas is drawn (many colours, not just background),
// cuts the mesh at the slice and back (JS API), then exercises the play/pause control through the
// keyboard and the JS API.
//
// Usage: node tests/web/page_test.mjs [WEB_DIR] [OUT_DIR]
//   WEB_DIR defaults to build-wasm/web, OUT_DIR (screenshots, console log) to build-wasm/web-test.
import { chromium } from 'playwright-core';
import fs from 'node:fs';
import http from 'node:http';
import os from 'node:os';
import path from 'node:path';
import { fileURLToPath } from 'node:url';

const top = path.resolve(path.dirname(fileURLToPath(import.meta.url)), '../..');
const webDir = path.resolve(process.argv[2] || path.join(top, 'build-wasm/web'));
const outDir = path.resolve(process.argv[3] || path.join(top, 'build-wasm/web-test'));
const chromiumPath = process.env.RIEMESH_CHROMIUM || '/usr/bin/chromium';
const convergeTimeoutMs = Number(process.env.RIEMESH_WEB_TIMEOUT_MS || 240000);
fs.mkdirSync(outDir, { recursive: true });

const types = { '.html': 'text/html', '.js': 'text/javascript', '.wasm': 'application/wasm',
                '.nvdb': 'application/octet-stream', '.png': 'image/png' };
function serve(dir) {
  const server = http.createServer((req, res) => {
    const url = new URL(req.url, 'http://127.0.0.1');
    const rel = decodeURIComponent(url.pathname === '/' ? '/index.html' : url.pathname);
    const file = path.join(dir, path.normalize(rel));
    if (!file.startsWith(dir) || !fs.existsSync(file) || !fs.statSync(file).isFile()) {
      res.writeHead(404);
      res.end('not found');
      return;
    }
    res.writeHead(200, { 'Content-Type': types[path.extname(file)] || 'application/octet-stream' });
    fs.createReadStream(file).pipe(res);
  });
  return new Promise((resolve) => server.listen(0, '127.0.0.1', () => resolve(server)));
}

const results = [];
function check(name, ok, detail = '') {
  results.push({ name, ok });
  console.log(`${ok ? 'ok  ' : 'FAIL'} ${name}${detail ? ': ' + detail : ''}`);
}
const sleep = (ms) => new Promise((r) => setTimeout(r, ms));

// Distinct colours and the share of pixels that differ from the background, read from a screenshot
// (a PNG decoded by the browser itself in a scratch page: no extra npm dependency).
async function analyse(context, png, clip) {
  const scratch = await context.newPage();
  const stats = await scratch.evaluate(async ({ b64, clip }) => {
    const img = new Image();
    img.src = 'data:image/png;base64,' + b64;
    await img.decode();
    const c = document.createElement('canvas');
    c.width = img.width;
    c.height = img.height;
    const g = c.getContext('2d');
    g.drawImage(img, 0, 0);
    const { data } = g.getImageData(clip.x, clip.y, clip.width, clip.height);
    const colours = new Set();
    const bg = [data[0], data[1], data[2]];
    let differ = 0, saturated = 0;
    for (let i = 0; i < data.length; i += 4) {
      colours.add((data[i] << 16) | (data[i + 1] << 8) | data[i + 2]);
      if (Math.abs(data[i] - bg[0]) + Math.abs(data[i + 1] - bg[1]) + Math.abs(data[i + 2] - bg[2]) > 24) differ++;
      // The mesh's colours (not the grey slice, not the grey-blue background).
      if (Math.max(data[i], data[i + 1], data[i + 2]) - Math.min(data[i], data[i + 1], data[i + 2]) > 40) saturated++;
    }
    const n = data.length / 4;
    return { colours: colours.size, drawn: differ / n, mesh: saturated / n };
  }, { b64: png.toString('base64'), clip });
  await scratch.close();
  return stats;
}

const server = await serve(webDir);
const url = `http://127.0.0.1:${server.address().port}/`;
const profile = fs.mkdtempSync(path.join(os.tmpdir(), 'riemesh-chromium-'));
let context;
const consoleLines = [];
const pageErrors = [];
try {
  context = await chromium.launchPersistentContext(profile, {
    executablePath: chromiumPath,
    headless: true,
    viewport: { width: 1280, height: 800 },
    args: ['--no-sandbox', '--enable-unsafe-swiftshader', '--disable-background-networking'],
  });
  const page = context.pages()[0] || (await context.newPage());
  page.on('console', (m) => {
    consoleLines.push(`[${m.type()}] ${m.text()}`);
    // (The refusal of the broken file dropped at the end is expected, and checked there.)
    if (m.type() === 'error' && !m.text().includes('Cannot open broken.nvdb')) pageErrors.push('console.error: ' + m.text());
  });
  page.on('pageerror', (e) => pageErrors.push('pageerror: ' + e.message));
  page.on('crash', () => pageErrors.push('page crashed'));

  const started = Date.now();
  await page.goto(url);
  const converged = /^riemesh: converged iterations=(\d+) vertices=(\d+) seconds=([0-9.]+)/;
  let line;
  while (!line && Date.now() - started < convergeTimeoutMs && pageErrors.length === 0) {
    line = consoleLines.map((l) => l.replace(/^\[\w+\] /, '')).find((l) => converged.test(l));
    if (consoleLines.some((l) => l.includes('riemesh: stopped'))) break;
    if (!line) await sleep(250);
  }
  const wall = (Date.now() - started) / 1000;
  check('the model converges in the page', !!line, line ? `${line} (page open ${wall.toFixed(1)} s)` : `no converged line after ${wall.toFixed(0)} s`);
  const loaded = consoleLines.find((l) => l.includes('riemesh: loaded'));
  check('the page opens on the demo volume', !!loaded, loaded || consoleLines.filter((l) => l.includes('riemesh')).join(' | '));

  await sleep(500); // a few frames with the final mesh
  // Once converged, creases and corners are put back as vdb2mesh does (its default): the phantom
  // is a cube, so some vertices move, and the state's count is the mesh shown (and downloaded).
  const sharpenedLine = consoleLines.map((l) => l.replace(/^\[\w+\] /, '')).find((l) => l.startsWith('riemesh: sharpened'));
  const sharpenedMatch = sharpenedLine && /moved=(\d+) rim_splits=(\d+) crease_vertices=(\d+) vertices=(\d+)/.exec(sharpenedLine);
  const afterSharpen = await page.evaluate(() => window.riemesh.state());
  check('the converged phantom is sharpened, and the state counts the sharpened mesh',
        !!sharpenedMatch && Number(sharpenedMatch[1]) > 0 && afterSharpen.sharpened === Number(sharpenedMatch[1]) &&
          afterSharpen.vertices === Number(sharpenedMatch[4]),
        `${sharpenedLine || 'no sharpened line'}; state: ${afterSharpen.sharpened} sharpened, ${afterSharpen.vertices} vertices`);
  await page.evaluate(() => window.riemesh.set('sharpen', 0));
  const unsharpened = await page.evaluate(() => window.riemesh.state());
  await page.evaluate(() => window.riemesh.set('sharpen', 1));
  const resharpened = await page.evaluate(() => window.riemesh.state());
  const convergedVertices = line ? Number(converged.exec(line)[2]) : -1;
  check('riemesh.set(\'sharpen\', 0) shows the converged mesh as it was, 1 sharpens it again',
        unsharpened.sharpened === 0 && unsharpened.vertices === convergedVertices && unsharpened.state === 'converged' &&
          resharpened.sharpened === afterSharpen.sharpened && resharpened.vertices === afterSharpen.vertices,
        `off: ${unsharpened.sharpened} sharpened, ${unsharpened.vertices} vertices (converged: ${convergedVertices}); ` +
          `on: ${resharpened.sharpened}, ${resharpened.vertices}`);
  const shot = await page.screenshot({ path: path.join(outDir, 'page.png') });
  // The 3D view right of the ImGui panel.
  const view = await analyse(context, shot, { x: 400, y: 40, width: 860, height: 740 });
  check('the canvas is drawn (many colours, mesh covers part of the view)', view.colours > 64 && view.drawn > 0.05,
        `${view.colours} colours, ${(100 * view.drawn).toFixed(1)}% of the view differs from the background`);

  // Display control through the JS API: cutting the mesh at the slice (z, halfway) takes away its
  // upper half and shows the image inside; turning the cut off brings the mesh back.
  await page.evaluate(() => window.riemesh.set('clip', 1));
  await sleep(500);
  const cut = await analyse(context, await page.screenshot({ path: path.join(outDir, 'page-cut.png') }),
                            { x: 400, y: 40, width: 860, height: 740 });
  await page.evaluate(() => window.riemesh.set('clip', 0));
  await sleep(500);
  const uncut = await analyse(context, await page.screenshot(), { x: 400, y: 40, width: 860, height: 740 });
  check('cutting the mesh at the slice hides the mesh above it, and only while the cut is on',
        cut.mesh < 0.6 * view.mesh && Math.abs(uncut.mesh - view.mesh) < 0.1 * view.mesh,
        `mesh-coloured share of the view ${(100 * view.mesh).toFixed(1)}% -> ${(100 * cut.mesh).toFixed(1)}% cut -> ` +
        `${(100 * uncut.mesh).toFixed(1)}% uncut`);

  // The canvas follows the window: a smaller window, then the first size again.
  await page.setViewportSize({ width: 960, height: 600 });
  await sleep(600);
  const small = await page.evaluate(() => [Module.canvas.width, Module.canvas.height]);
  const smallView = await analyse(context, await page.screenshot({ path: path.join(outDir, 'page-small.png') }),
                                  { x: 360, y: 40, width: 580, height: 540 });
  await page.setViewportSize({ width: 1280, height: 800 });
  await sleep(600);
  const large = await page.evaluate(() => [Module.canvas.width, Module.canvas.height]);
  check('the canvas follows the window size, and the smaller view is drawn',
        small[0] === 960 && small[1] === 600 && large[0] === 1280 && large[1] === 800 && smallView.mesh > 0.02,
        `canvas ${small.join('x')} in a 960x600 window (mesh-coloured ${(100 * smallView.mesh).toFixed(1)}% of the view), ` +
        `${large.join('x')} in 1280x800`);

  // Control: space pauses (keyboard through GLFW and ImGui into the app), reset restarts from the box,
  // space plays again.
  const state = () => page.evaluate(() => window.riemesh.state());
  await page.mouse.click(1200, 760); // focus the canvas (a click without drag does not move the camera)
  await page.keyboard.press('Space');
  await sleep(300);
  const paused = await state();
  await page.evaluate(() => window.riemesh.reset());
  await sleep(800);
  const afterReset = await state();
  check('space pauses, and a paused model stays at its iteration after reset',
        paused.playing === false && afterReset.iteration === 0 && afterReset.state === 'paused',
        JSON.stringify({ paused: paused.state, afterReset: afterReset.iteration }));
  await page.keyboard.press('Space');
  await sleep(1500);
  const playing = await state();
  check('space plays again: the model evolves', playing.playing === true && playing.iteration > 3,
        `iteration ${playing.iteration}, ${playing.vertices} vertices`);
  await page.screenshot({ path: path.join(outDir, 'page-evolving.png') });

  // The second demo: the real head MRI (head.nvdb, iso 40 stored in the file) through the page's link.
  if (fs.existsSync(path.join(webDir, 'head.nvdb'))) {
    const from = consoleLines.length;
    const headStart = Date.now();
    await page.click('#demos a[href="?volume=head.nvdb"]');
    let headLine;
    while (!headLine && Date.now() - headStart < convergeTimeoutMs && pageErrors.length === 0) {
      // Only what the new page printed: after its "loaded head.nvdb" line.
      const lines = consoleLines.slice(from).map((l) => l.replace(/^\[\w+\] /, ''));
      const at = lines.findIndex((l) => l.startsWith('riemesh: loaded head.nvdb'));
      headLine = at < 0 ? undefined : lines.slice(at).find((l) => converged.test(l));
      if (!headLine) await sleep(250);
    }
    const headState = headLine ? await state() : {};
    check('the head demo opens at its stored iso and converges to one skin of genus <= 2',
          !!headLine && headState.volume === 'head.nvdb' && headState.components === 1 && headState.genus <= 2,
          headLine ? `${headLine}; ${JSON.stringify(headState)}` : `no converged line after ${((Date.now() - headStart) / 1000).toFixed(0)} s`);
    await sleep(500);
    await page.screenshot({ path: path.join(outDir, 'page-head.png') });
  }

  // Drag and drop onto the canvas (GLFW's drop callback, the file in MEMFS): a file that is no
  // volume is refused with a message and the current model stays; a valid .nvdb is segmented.
  // The file's content: a text, or what the page fetches from a URL of the served folder.
  const drop = (name, { text, url }) => page.evaluate(async ({ name, text, url }) => {
    const content = url ? await (await fetch(url)).arrayBuffer() : text;
    const data = new DataTransfer();
    data.items.add(new File([content], name));
    Module.canvas.dispatchEvent(new DragEvent('drop', { dataTransfer: data, bubbles: true, cancelable: true }));
  }, { name, text, url });
  const waitLine = async (from, test, ms) => {
    const started = Date.now();
    for (;;) {
      const found = consoleLines.slice(from).map((l) => l.replace(/^\[\w+\] /, '')).find(test);
      if (found || Date.now() - started > ms) return found;
      await sleep(200);
    }
  };
  const before = await state();
  let from = consoleLines.length;
  await drop('broken.nvdb', { text: 'this is not a NanoVDB volume\n' });
  const refused = await waitLine(from, (l) => l.includes('Cannot open broken.nvdb'), 10000);
  await sleep(300);
  const after = await state();
  await page.screenshot({ path: path.join(outDir, 'page-drop.png') });
  check('a dropped file that is no volume is refused with a message, and the model stays',
        !!refused && after.volume === before.volume && after.vertices === before.vertices,
        `${refused || 'no message'}; volume ${after.volume}, ${after.vertices} vertices`);
  from = consoleLines.length;
  await drop('mine.nvdb', { url: 'phantom.nvdb' });
  const mine = await waitLine(from, (l) => l.startsWith('riemesh: loaded mine.nvdb'), 20000);
  const mineDone = mine && await waitLine(from, (l) => converged.test(l), convergeTimeoutMs);
  const mineState = await state();
  check('a dropped .nvdb is loaded and segmented', !!mineDone && mineState.volume === 'mine.nvdb' && mineState.components === 1,
        `${mine || 'not loaded'}; ${mineDone || 'no converged line'}`);

  // Download (as the Files panel's button does, through the JS API): a PLY named after the volume
  // whose header counts the model's vertices and faces.
  const [download] = await Promise.all([page.waitForEvent('download', { timeout: 20000 }),
                                        page.evaluate(() => window.riemesh.download('ply'))]);
  const ply = fs.readFileSync(await download.path());
  const header = ply.subarray(0, Math.max(0, ply.indexOf('end_header'))).toString('latin1');
  const plyVertices = Number((/element vertex (\d+)/.exec(header) || [])[1]);
  const plyFaces = Number((/element face (\d+)/.exec(header) || [])[1]);
  const shown = await state();
  check('the mesh downloads as a PLY named after the volume, with the model\'s vertices',
        download.suggestedFilename() === 'mine.ply' && plyVertices === shown.vertices &&
        plyFaces === 2 * shown.vertices - 4 * shown.components + 4 * shown.genus, // closed: F = 2 (V - chi)
        `${download.suggestedFilename()}: ${ply.length} bytes, ${plyVertices} vertices, ${plyFaces} faces (model: ${shown.vertices} vertices, genus ${shown.genus})`);

  check('no page errors', pageErrors.length === 0, pageErrors.slice(0, 5).join(' | '));
} catch (e) {
  check('the test ran', false, e.stack || String(e));
} finally {
  fs.writeFileSync(path.join(outDir, 'console.log'), consoleLines.join('\n') + '\n');
  if (context) await context.close();
  server.close();
  fs.rmSync(profile, { recursive: true, force: true });
}
const failed = results.filter((r) => !r.ok).length;
console.log(`screenshots: ${outDir}/page.png, page-cut.png, page-small.png, page-evolving.png, page-head.png, page-drop.png`);
console.log(`web: ${results.length - failed} passed, ${failed} failed`);
process.exit(failed ? 1 : 0);
