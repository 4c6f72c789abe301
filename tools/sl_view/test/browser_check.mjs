// The web page in headless Chromium (Debian's /usr/bin/chromium, driven by
// playwright-core): loads sl_view's page, starts a continuous scan with the
// page's Start button, waits for a cloud and asserts from the page that it
// has the expected organized size and point count and that the WebGL
// canvas shows it; stops the scan with the Stop button (reply shown),
// checks that a rejected request shows the daemon's reason, and keeps a
// screenshot.
//
//   node browser_check.mjs --url http://127.0.0.1:PORT/ --width 360 --height 270 --screenshot FILE
import { chromium } from 'playwright-core';

const args = Object.fromEntries(process.argv.slice(2).reduce((a, v, i, all) =>
  (v.startsWith('--') ? [...a, [v.slice(2), all[i + 1]]] : a), []));
const width = Number(args.width), height = Number(args.height);
let failures = 0;
const check = (c, what) => { if (!c) { failures++; console.error(`FAIL: ${what}`); } return c; };

const browser = await chromium.launch({
  executablePath: args.chromium ?? '/usr/bin/chromium',
  args: ['--no-sandbox', '--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--ignore-gpu-blocklist'],
});
try {
  const page = await browser.newPage({ viewport: { width: 1280, height: 800 } });
  const errors = [];
  page.on('pageerror', (e) => { errors.push(e.message); console.error(`page error: ${e.message}`); });
  page.on('console', (m) => { if (m.type() === 'error') { errors.push(m.text()); console.error(`page console: ${m.text()}`); } });
  await page.goto(args.url);
  await page.waitForFunction(() => window.slView?.connected && window.slView.status, null, { timeout: 20000 });
  const before = await page.evaluate(() => window.slView.clouds);
  check(before === 0, `a cloud before any request (${before})`);

  await page.click('#start');
  await page.waitForFunction(() => window.slView.clouds >= 1 && window.slView.points > 0, null, { timeout: 30000 });
  await page.waitForFunction(() => window.slView.replies.length >= 1, null, { timeout: 5000 });
  const v = await page.evaluate(() => ({ ...window.slView, status: undefined }));
  check(v.replies[0].accepted, `start rejected: ${JSON.stringify(v.replies[0])}`);
  check(v.width === width && v.height === height, `cloud ${v.width} x ${v.height}, expected ${width} x ${height}`);
  // The simulated scene covers ~94 % of the image with valid points.
  check(v.points > 0.8 * width * height && v.points <= width * height,
    `${v.points} points shown, expected 80..100 % of ${width * height}`);
  check(v.zmin > 0.3 && v.zmax < 1.0, `z ${v.zmin}..${v.zmax} m (the simulated scene is at 0.46..0.63 m)`);
  // Rendered: count canvas pixels that are not the background.
  await page.waitForTimeout(300);
  const lit = await page.evaluate(() => {
    const c = document.querySelector('#scene canvas');
    const gl = c.getContext('webgl2') ?? c.getContext('webgl');
    const px = new Uint8Array(c.width * c.height * 4);
    gl.readPixels(0, 0, c.width, c.height, gl.RGBA, gl.UNSIGNED_BYTE, px);
    let n = 0;
    for (let i = 0; i < px.length; i += 4) if (Math.abs(px[i] - 17) + Math.abs(px[i + 1] - 17) + Math.abs(px[i + 2] - 17) > 30) n++;
    return { n, total: c.width * c.height };
  });
  check(lit.n > 0.05 * lit.total, `only ${lit.n} of ${lit.total} canvas pixels show the cloud`);
  // The depth image and the point count of the same cloud (one evaluate:
  // no cloud can arrive in between).
  const depth = await page.evaluate(() => {
    const c = document.getElementById('depth');
    const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
    let n = 0;
    for (let i = 0; i < d.length; i += 4) if (d[i] + d[i + 1] + d[i + 2] > 0) n++;
    return { n, points: window.slView.points };
  });
  check(depth.n === depth.points, `depth image: ${depth.n} coloured pixels, ${depth.points} points`);
  await page.waitForFunction(() => window.slView.status.state === 'scanning', null, { timeout: 5000 });
  const statusText = await page.textContent('#status');
  check(/scanning/.test(statusText) && /scan rate/.test(statusText), `status panel: ${statusText}`);
  if (args.screenshot) {
    // A few clouds in, the status shows the scan rate (not asserted: load).
    await page.waitForFunction(() => window.slView.clouds >= 4, null, { timeout: 5000 }).catch(() => {});
    await page.waitForTimeout(300);
    await page.screenshot({ path: args.screenshot });
  }

  await page.click('#stop');
  await page.waitForFunction(() => window.slView.replies.length >= 2, null, { timeout: 10000 });
  const stopReply = await page.evaluate(() => window.slView.replies[1]);
  check(stopReply.accepted, `stop: ${JSON.stringify(stopReply)}`);
  await page.waitForFunction(() => window.slView.status.state === 'idle', null, { timeout: 10000 });
  // A request the daemon rejects: its reason is shown.
  await page.click('#stop');
  await page.waitForFunction(() => window.slView.replies.length >= 3, null, { timeout: 10000 });
  const rejected = await page.evaluate(() => window.slView.replies[2]);
  const replyText = await page.textContent('#reply');
  check(!rejected.accepted && rejected.reason && replyText.includes(rejected.reason),
    `a stop while idle: reply ${JSON.stringify(rejected)}, page shows '${replyText}'`);
  check(errors.length === 0, `page errors: ${errors.join('; ')}`);
  console.log(`page: ${v.clouds} clouds, ${v.width} x ${v.height}, ${v.points} points, ${lit.n} lit canvas pixels; ` +
    `stop while idle shows '${replyText}'`);
} catch (e) {
  check(false, e.message.split('\n')[0]);
} finally {
  await browser.close();
}
if (failures) { console.error(`${failures} failures`); process.exit(1); }
console.log('ok: the page shows the cloud and drives the daemon');
