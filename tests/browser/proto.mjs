import { createServer } from 'node:http';
import { readFileSync, existsSync, statSync } from 'node:fs';
import { join, extname } from 'node:path';
import { chromium } from 'playwright-core';
import { startVehicle, until, CHROMIUM } from './harness.js';

const DIST = process.env.COCKPIT_DIST || join(import.meta.dirname, '..', '..', '..', 'shared', 'cockpit', 'dist');
const TYPES = { '.js': 'text/javascript', '.css': 'text/css', '.html': 'text/html', '.svg': 'image/svg+xml', '.png': 'image/png', '.json': 'application/json', '.webmanifest': 'application/manifest+json', '.wasm': 'application/wasm', '.ico': 'image/x-icon', '.woff2': 'font/woff2', '.woff': 'font/woff', '.ttf': 'font/ttf' };
const server = createServer((req, res) => {
  const p = decodeURIComponent(new URL(req.url, 'http://x').pathname);
  let f = join(DIST, p);
  if (!f.startsWith(DIST) || !existsSync(f) || statSync(f).isDirectory()) f = join(DIST, 'index.html');
  res.writeHead(200, { 'content-type': TYPES[extname(f)] || 'application/octet-stream' });
  res.end(readFileSync(f));
});
await new Promise((ok) => server.listen(0, '127.0.0.1', ok));
const origin = `http://127.0.0.1:${server.address().port}`;
const X = 2 + Math.floor(Math.random() * 200);
const rov = `127.0.0.${X}`;
const v = await startVehicle(['--video-rtp', 'off'], {
  http: `${rov}:80`, password: 'tide-pool-42',
  toml: '[camera]\nsource = "synthetic"\nfps = 30\n',
  hmiToml: `allowed_origins = ["${origin}"]\nopen_control = "none"`,
});
console.log('vehicle', v.url, 'cockpit', origin);
const browser = await chromium.launch({ executablePath: CHROMIUM, headless: true, args: ['--no-sandbox', '--disable-gpu', '--autoplay-policy=no-user-gesture-required', '--disable-background-networking', '--disable-component-update', '--disable-sync'] });
const context = await browser.newContext({ viewport: { width: 1366, height: 768 } });
await context.route('**/*', (route) => {
  const u = new URL(route.request().url());
  if (['127.0.0.1', rov, 'localhost'].includes(u.hostname) || u.protocol === 'data:' || u.protocol === 'blob:') return route.continue();
  return route.abort();
});
await context.addInitScript(([addr]) => {
  localStorage.setItem('cockpit-vehicle-address', addr);
  localStorage.setItem('cockpit-has-seen-tutorial', 'true');
  localStorage.setItem('cockpit-show-splash-screen-on-startup', 'false');
  localStorage.setItem('cockpit-prevent-auto-vehicle-discovery-dialog', 'true');
  localStorage.setItem('cockpit-enable-voice-alerts', 'false');
}, [rov]);
const logs = [];
context.on('page', (pg) => {
  pg.on('console', (m) => logs.push(`${m.type()}: ${m.text()}`));
  pg.on('requestfailed', (r) => { const u = r.url(); logs.push(`FAILED ${u} ${r.failure()?.errorText}`); });
  pg.on('response', (r) => { if (r.url().includes(rov)) logs.push(`HTTP ${r.status()} ${r.request().method()} ${r.url()}`); });
});
const hmi = await context.newPage();
await hmi.goto(`http://${rov}/`);
await hmi.fill('[data-testid=password]', 'tide-pool-42');
await hmi.click('[data-testid=login-submit]');
await hmi.waitForSelector('[data-testid=cockpit]:not([hidden])', { timeout: 20000 });
await hmi.fill('[data-testid=cockpit-url]', origin + '/');
const opened = context.waitForEvent('page');
await hmi.click('[data-testid=cockpit-open]');
const page = await opened;
console.log('cockpit opened at', page.url());
const t0 = Date.now();
const armerV = page.locator('button', { has: page.getByText('Disarmed', { exact: true }) }).filter({ visible: true });
await until(async () => (await armerV.count()) > 0, 180000, 'the armer');
console.log('armer visible after', Date.now() - t0, 'ms');
await page.screenshot({ path: `/tmp/cockpit-0.png` });
const armer = page.locator('button', { has: page.getByText('Disarmed', { exact: true }) });
for (let i = 0; i < await armer.count(); i++) console.log('ARMER', i, await armer.nth(i).evaluate((b) => JSON.stringify(b.getBoundingClientRect())), await armer.nth(i).isVisible());
try { await armer.filter({ visible: true }).first().click({ timeout: 5000 }); } catch (e) { console.log('no armer', e.message.slice(0, 300)); }
const tc = Date.now();
await page.locator('.slideunlock-handler').waitFor();
console.log('slider after', Date.now() - tc);
const h = await page.locator('.slideunlock-handler').boundingBox();
const bar = await page.locator('#slideunlock').boundingBox();
await page.mouse.move(h.x + h.width / 2, h.y + h.height / 2);
await page.mouse.down();
console.log('AT HANDLER', await page.evaluate(([x, y]) => { const e = document.elementFromPoint(x, y); return e ? e.outerHTML.slice(0, 200) : null; }, [h.x + h.width / 2, h.y + h.height / 2]), JSON.stringify(h), JSON.stringify(bar));
const x0 = h.x + h.width / 2;
const x1 = bar.x + bar.width - 3;
const tm = Date.now();
for (let i = 1; i <= 2; i++) await page.mouse.move(x0 + ((x1 - x0) * i) / 2, h.y + h.height / 2);
console.log('moves took', Date.now() - tm);
await page.mouse.up();
await new Promise((r) => setTimeout(r, 3000));
await page.screenshot({ path: `/tmp/cockpit-armed.png` });
console.log('ARMED?', await page.locator('button', { has: page.getByText('Armed', { exact: true }) }).filter({ visible: true }).count());
console.log('VEHICLE LOG', v.stderr().split('\n').filter((l) => /light|arm|control|refus|bag|link|cockpit/i.test(l)).slice(-60).join('\n'));
const keep = logs.filter((l) => !/Settings(Syncer|Manager)/.test(l) && (/^(HTTP|FAILED|warning)/.test(l) || (/^error/.test(l) && !/pilot password|ERR_FAILED/.test(l)) || /webrtc|ice|stream|video|signal|dialog|vehicle id|profile|vehicle type/i.test(l)));
console.log(keep.filter((l) => !/Failed to parse mavlink|try again in 300|null\/bag|posthog|sentry|googleapis/.test(l)).join('\n'));
console.log('--- bag', await (await fetch(`http://${rov}/bag/v1.0/get/cockpit`)).text().then((t) => t.slice(0, 3000)));
await browser.close();
await v.stop();
server.close();
