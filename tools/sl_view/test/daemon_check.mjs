// The web page in headless Chromium says whether a daemon is behind sl_view:
// with --expect present, the status panel's "daemon" row gives the status's
// age and the state is the daemon's; with --expect gone, it says "no daemon"
// and the last state is shown as unknown, not as the stale one.
//
//   node daemon_check.mjs --url http://127.0.0.1:PORT/ --expect present|gone
import { chromium } from 'playwright-core';

const args = Object.fromEntries(process.argv.slice(2).reduce((a, v, i, all) =>
  (v.startsWith('--') ? [...a, [v.slice(2), all[i + 1]]] : a), []));
const present = args.expect === 'present';
const browser = await chromium.launch({
  executablePath: args.chromium ?? '/usr/bin/chromium',
  args: ['--no-sandbox', '--use-angle=swiftshader', '--enable-unsafe-swiftshader', '--ignore-gpu-blocklist'],
});
let failed = false;
try {
  const page = await browser.newPage();
  await page.goto(args.url);
  await page.waitForFunction((p) => window.slView?.daemon === p, present, { timeout: 20000 });
  const text = await page.textContent('#status');
  const ok = present ? /status [0-9.]+ s old/.test(text) && !/no daemon/.test(text)
                     : /no daemon/.test(text) && (!/state/.test(text) || /unknown/.test(text));
  if (!ok) { failed = true; console.error(`FAIL: status panel with the daemon ${args.expect}: ${text}`); }
  else console.log(`page (${args.expect}): ${text.replace(/\s+/g, ' ').slice(0, 120)}`);
} finally {
  await browser.close();
}
process.exit(failed ? 1 : 0);
