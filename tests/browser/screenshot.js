// screenshot.js — docs/viewer.png for the README: the viewer on a scene (default: the reference
// molecule) with a primitive selected, as headless Chromium shows it. Run by hand:
//   node tests/browser/screenshot.js build/sdfprune ../shared/scenes/molecule.json docs/viewer.png
import { spawn } from 'node:child_process';
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import { chromium } from 'playwright-core';

const [cli, scene, out] = process.argv.slice(2);
if (!cli || !scene || !out) {
  console.error('usage: node screenshot.js SDFPRUNE SCENE.json OUT.png');
  process.exit(2);
}
// A copy: the viewer may save into it.
const dir = fs.mkdtempSync(path.join(os.tmpdir(), 'sdfprune-shot-'));
const copy = path.join(dir, path.basename(scene));
fs.copyFileSync(scene, copy);
const server = spawn(cli, ['view', copy, '--port', '0'], { stdio: ['ignore', 'pipe', 'inherit'] });
const url = await new Promise((resolve, reject) => {
  let text = '';
  server.stdout.on('data', (d) => {
    text += d;
    const m = text.match(/at (http:\/\/127\.0\.0\.1:\d+\/)/);
    if (m) resolve(m[1]);
  });
  server.on('exit', () => reject(new Error('sdfprune view exited: ' + text)));
});
const browser = await chromium.launch({ executablePath: process.env.CHROMIUM || '/usr/bin/chromium',
                                        args: ['--no-sandbox', '--force-color-profile=srgb'] });
try {
  const page = await browser.newPage({ viewport: { width: 1260, height: 640 }, deviceScaleFactor: 1 });
  await page.goto(url);
  const full = () => page.waitForFunction(() => document.getElementById('frame').dataset.full === '1',
                                          null, { timeout: 120000 });
  await full();
  // Closer, then select what lies under the centre.
  const box = await page.locator('#frame').boundingBox();
  await page.mouse.move(box.x + box.width / 2, box.y + box.height / 2);
  await page.mouse.wheel(0, -450);
  await page.waitForTimeout(400);
  await full();
  await page.mouse.click(box.x + box.width / 2, box.y + box.height / 2);
  await page.waitForSelector('#editor:not([hidden])', { timeout: 30000 });
  await page.waitForTimeout(300);
  await full();
  await page.screenshot({ path: out });
  console.log('wrote ' + out);
} finally {
  await browser.close();
  server.kill('SIGINT');
  fs.rmSync(dir, { recursive: true, force: true });
}
