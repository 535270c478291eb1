// viewer.test.js — the viewer page (sdfprune view) in a real browser: Debian's headless Chromium
// driven by playwright-core. Run by tests/browser/run.sh (node --test), which sets SDFPRUNE_CLI.
// Each test asserts on pixels the browser shows, compared with `sdfprune render` or with the
// picture before an action.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { spawn, execFileSync } from 'node:child_process';
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { PNG } from 'pngjs';
import { chromium } from 'playwright-core';

const CLI = process.env.SDFPRUNE_CLI;
const CHROMIUM = process.env.CHROMIUM || '/usr/bin/chromium';
const GRID = 64;

// A small scene: a sphere minus a cylinder, and a box beside them (the reference format).
function sceneJson(boxX) {
  const id = [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0];
  const prim = (type, fields, matrix, color) =>
    ({ nodeType: 'primitive', primitiveType: type, matrix, round_x: 0, round_y: 0, color, ...fields });
  return JSON.stringify({
    aabb_min: [-2, -2, -2], aabb_max: [2, 2, 2],
    nodeType: 'binaryOperator', blendMode: 'union', blendRadius: 0.1, matrix: id,
    leftChild: {
      nodeType: 'binaryOperator', blendMode: 'sub', blendRadius: 0.05, matrix: id,
      leftChild: prim('sphere', { radius: 1 }, id, [0.9, 0.3, 0.2]),
      rightChild: prim('cylinder', { radius: 0.4, height: 3 }, [1, 0, 0, 0, 0, 0, 1, 0, 0, -1, 0, 0],
                       [0.2, 0.7, 0.3]),
    },
    rightChild: prim('box', { sides: [0.8, 0.8, 0.8] }, [1, 0, 0, -boxX, 0, 1, 0, 0, 0, 0, 1, 0],
                     [0.2, 0.4, 0.9]),
  });
}

let dir, scenePath, server, url, browser, page, skipReason = null;

before(async () => {
  assert.ok(CLI && fs.existsSync(CLI), 'SDFPRUNE_CLI must name the built sdfprune binary');
  dir = fs.mkdtempSync(path.join(os.tmpdir(), 'sdfprune-browser-'));
  scenePath = path.join(dir, 'scene.json');
  fs.writeFileSync(scenePath, sceneJson(1.3));
  server = spawn(CLI, ['view', scenePath, '--port', '0', '--grid', String(GRID)],
                 { stdio: ['ignore', 'pipe', 'inherit'] });
  url = await new Promise((resolve, reject) => {
    let out = '';
    const timer = setTimeout(() => reject(new Error('sdfprune view did not start: ' + out)), 20000);
    server.stdout.on('data', (d) => {
      out += d;
      const m = out.match(/at (http:\/\/127\.0\.0\.1:\d+\/)/);
      if (m) { clearTimeout(timer); resolve(m[1]); }
    });
    server.on('exit', (code) => reject(new Error(`sdfprune view exited (${code}): ${out}`)));
  });
  try {
    browser = await chromium.launch({ executablePath: CHROMIUM, args: ['--no-sandbox', '--force-color-profile=srgb'] });
  } catch (e) {
    skipReason = 'Chromium could not start: ' + String(e.message).split('\n')[0];
    console.log('SKIPPED: ' + skipReason);
    return;
  }
  page = await browser.newPage({ viewport: { width: 1300, height: 700 }, deviceScaleFactor: 1 });
  await page.goto(url);
});

after(async () => {
  if (browser) await browser.close();
  if (server) server.kill('SIGINT');
  if (dir) fs.rmSync(dir, { recursive: true, force: true });
});

// The frame's pixels as the browser shows them, without the overlays drawn over it.
async function frameShot() {
  await page.evaluate(() => document.querySelectorAll('#figures, #status, #error')
    .forEach((e) => { e.style.visibility = 'hidden'; }));
  const png = PNG.sync.read(await page.locator('#frame').screenshot());
  await page.evaluate(() => document.querySelectorAll('#figures, #status, #error')
    .forEach((e) => { e.style.visibility = ''; }));
  return png;
}

// The full-size frame once it is shown for a state other than `previous` (a new version, or a
// new camera or setting), or for the current state when `previous` is null.
async function settledFrame(previous) {
  await page.waitForFunction((prev) => {
    const f = document.getElementById('frame');
    return f.dataset.full === '1' && (!prev || f.dataset.version !== prev.version ||
                                      f.dataset.query !== prev.query);
  }, previous || null, { timeout: 20000 });
  const info = await page.$eval('#frame', (f) => ({ ...f.dataset }));
  return { info, png: await frameShot() };
}

function differingPixels(a, b) {
  assert.equal(a.width, b.width);
  assert.equal(a.height, b.height);
  let n = 0;
  for (let i = 0; i < a.data.length; i += 4)
    if (a.data[i] !== b.data[i] || a.data[i + 1] !== b.data[i + 1] || a.data[i + 2] !== b.data[i + 2]) n++;
  return n;
}

test('the page shows what sdfprune render draws for the same camera', async (t) => {
  if (skipReason) return t.skip(skipReason);
  const { info, png } = await settledFrame();
  assert.equal(png.width, 960);
  assert.equal(png.height, 540);
  const cam = JSON.parse(info.camera);
  const out = path.join(dir, 'cli.png');
  execFileSync(CLI, ['render', scenePath, '-o', out, '--width', '960', '--height', '540',
                     '--yaw', String(cam.yaw), '--pitch', String(cam.pitch),
                     '--distance', String(cam.distance), '--target', cam.target.join(','),
                     '--fov', String(cam.fov), '--grid', String(GRID), '--quiet']);
  const cli = PNG.sync.read(fs.readFileSync(out));
  assert.equal(differingPixels(png, cli), 0, 'the screenshot differs from sdfprune render');
});

test('dragging orbits the camera and changes the picture', async (t) => {
  if (skipReason) return t.skip(skipReason);
  const before = await settledFrame();
  const box = await page.locator('#frame').boundingBox();
  await page.mouse.move(box.x + 300, box.y + 270);
  await page.mouse.down();
  for (let i = 1; i <= 10; i++) await page.mouse.move(box.x + 300 + 12 * i, box.y + 270 + 3 * i);
  await page.mouse.up();
  const after = await settledFrame(before.info);
  assert.notEqual(after.info.camera, before.info.camera);
  assert.ok(differingPixels(before.png, after.png) > 1000, 'the view did not change');
});

test('selecting and editing a primitive changes the frame and the saved file', async (t) => {
  if (skipReason) return t.skip(skipReason);
  const before = await settledFrame();
  // The frame's centre looks at the AABB's centre, inside the sphere's surface.
  const box = await page.locator('#frame').boundingBox();
  await page.mouse.click(box.x + box.width / 2, box.y + box.height / 2);
  await page.waitForSelector('#editor:not([hidden])', { timeout: 10000 });
  const primitive = await page.$eval('#editor', (e) => e.dataset.primitive);
  assert.match(primitive, /^\d+$/);
  const selected = await settledFrame(before.info);  // the selection highlighted
  const field = page.locator('#editor input[data-field="translate.y"]');
  const y0 = parseFloat(await field.inputValue());
  await field.fill(String(y0 + 0.5));
  await field.dispatchEvent('change');
  const edited = await settledFrame(selected.info);
  assert.ok(Number(edited.info.version) > Number(before.info.version));
  assert.ok(differingPixels(selected.png, edited.png) > 500, 'the edit did not change the frame');

  const fileBefore = fs.readFileSync(scenePath, 'utf8');
  await page.click('#save');
  await page.waitForFunction(() => document.getElementById('status').textContent.startsWith('saved'),
                             null, { timeout: 10000 });
  const fileAfter = fs.readFileSync(scenePath, 'utf8');
  assert.notEqual(fileAfter, fileBefore, 'save did not change the file');
  execFileSync(CLI, ['info', scenePath]);  // loads: exit status 0
  const y1 = parseFloat(await page.locator('#editor input[data-field="translate.y"]').inputValue());
  assert.ok(Math.abs(y1 - (y0 + 0.5)) < 1e-4, `translate.y is ${y1}, expected ${y0 + 0.5}`);

  await page.click('#undo');
  const undone = await settledFrame(edited.info);
  assert.equal(differingPixels(undone.png, selected.png), 0, 'undo did not restore the picture');
});

test('the view reloads when the file changes on disk, and keeps the last good scene', async (t) => {
  if (skipReason) return t.skip(skipReason);
  const before = await settledFrame();
  fs.writeFileSync(scenePath + '.tmp', sceneJson(-1.1));
  fs.renameSync(scenePath + '.tmp', scenePath);
  const reloaded = await settledFrame(before.info);
  assert.ok(Number(reloaded.info.version) > Number(before.info.version));
  assert.ok(differingPixels(before.png, reloaded.png) > 500, 'the reloaded scene looks the same');
  fs.writeFileSync(scenePath, '{"nodeType": "primitive", broken');
  await page.waitForSelector('#error:not([hidden])', { timeout: 10000 });
  assert.match(await page.textContent('#error'), /did not load: .*invalid JSON/);
  const kept = await frameShot();
  assert.equal(differingPixels(kept, reloaded.png), 0, 'the last good scene was not kept');
});
