// Browser tests of the developer view (thesis 7.2) and of what the operator
// page costs to load: the real binary (`--sim`) and Debian's headless
// Chromium through playwright-core, as in hmi.test.js. Waits poll a
// condition with a deadline; nothing sleeps to let time pass.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { readFileSync } from 'node:fs';
import { launchBrowser, telemetry, takeControlAndArm, until, withVehicle } from './harness.js';

let browser;
before(async () => { browser = await launchBrowser(); });
after(async () => { await browser?.close(); });

/** The page, with every request it makes recorded from the first one on
 * (harness.openPage attaches its listeners after nothing; these must be
 * there before the navigation). */
async function openRecorded(url) {
  const context = await browser.newContext({ viewport: { width: 1280, height: 800 }, acceptDownloads: true });
  const page = await context.newPage();
  const requests = [];
  const problems = [];
  page.on('request', (r) => requests.push(new URL(r.url()).pathname));
  page.on('console', (m) => { if (m.type() === 'error') problems.push(`console: ${m.text()}`); });
  page.on('pageerror', (e) => problems.push(`page error: ${e.message}`));
  page.on('response', (r) => { if (r.status() >= 400) problems.push(`HTTP ${r.status()}: ${r.url()}`); });
  await page.goto(url);
  await until(() => page.evaluate(() => !!(window.neptunus && window.neptunus.state.t && window.neptunus.state.t.vehicle_seen)), 20000, 'telemetry in the page');
  return { context, page, requests, problems };
}

/** Opens the developer view and waits until its plots can be used. */
async function openDev(page) {
  await page.click('[data-testid=dev-toggle]');
  await until(() => page.evaluate(() => !!window.neptunus.plots), 10000, 'the developer view loaded');
  await page.waitForSelector('[data-testid=add-plot]', { state: 'visible' });
}

async function addPlot(page, signal) {
  await page.selectOption('#signal', signal);
  await page.click('[data-testid=add-plot]');
}

/** What the plot of `signal` holds: its x and y arrays and its x scale. */
const plotState = (page, signal) => page.evaluate((key) => {
  const p = window.neptunus.plots.plots.find((e) => e.key === key);
  const u = p.u;
  return { x: Array.from(u.data[0]), y: Array.from(u.data[1]), min: u.scales.x.min, max: u.scales.x.max };
}, signal);

test('the operator page loads no plotting library; the developer view loads it on first open and plots', () => withVehicle(async (v) => {
  const { page, context, requests, problems } = await openRecorded(v.url);
  // Everything the page asked for at load has arrived (the recorder records already).
  await until(() => page.evaluate(() => window.neptunus.recorder.length > 5), 10000, 'samples recorded before the view opens');
  const vendor = (list) => list.filter((p) => p.startsWith('/vendor/'));
  assert.deepEqual(vendor(requests), [], `the operator page fetched ${vendor(requests)}`);
  const loaded = await page.evaluate(() => performance.getEntriesByType('resource').map((e) => new URL(e.name).pathname));
  assert.deepEqual(vendor(loaded), []);
  assert.equal(await page.evaluate(() => !!document.querySelector('link[href*="uPlot"]')), false, 'no uPlot stylesheet');

  const recordedBefore = await page.evaluate(() => window.neptunus.recorder.length);
  await openDev(page);
  assert.ok(requests.includes('/vendor/uPlot.esm.js'), `requests: ${requests}`);
  assert.ok(requests.includes('/vendor/uPlot.min.css'), `requests: ${requests}`);
  // The plot shows what was recorded since connection, not since the view opened.
  await addPlot(page, 'depth_m');
  await until(async () => (await plotState(page, 'depth_m')).x.length >= recordedBefore, 5000, 'the plot holds the samples from before the view opened');
  assert.equal(await page.locator('#plots .plot canvas').count(), 1);
  // uPlot's own stylesheet applies (its legend table is styled by it).
  assert.equal(await page.evaluate(() => getComputedStyle(document.querySelector('.uplot')).fontFamily.length > 0), true);
  // Closing and opening again loads nothing twice.
  await page.click('[data-testid=dev-toggle]');
  await page.click('[data-testid=dev-toggle]');
  assert.equal(requests.filter((p) => p === '/vendor/uPlot.esm.js').length, 1);
  assert.deepEqual(problems, []);
  await context.close();
}));

test('the 11th plot is refused with a visible error next to the button', () => withVehicle(async (v) => {
  const { page, context, problems } = await openRecorded(v.url);
  await openDev(page);
  const options = await page.$$eval('#signal option', (o) => o.map((x) => x.value));
  for (const s of options.slice(0, 10)) await addPlot(page, s);
  assert.equal(await page.locator('#plots .plot').count(), 10);
  const note = page.locator('[data-testid=plot-note]');
  assert.equal(await note.isVisible(), false, 'no note while nothing was refused');
  await addPlot(page, options[10]);
  assert.equal(await page.locator('#plots .plot').count(), 10);
  assert.equal(await note.isVisible(), true);
  assert.match(await note.textContent(), /At most 10 plots/);
  assert.equal(await note.getAttribute('role'), 'alert');
  const style = await note.evaluate((el) => {
    const s = getComputedStyle(el);
    const body = getComputedStyle(document.body);
    return { color: s.color, weight: Number(s.fontWeight), size: parseFloat(s.fontSize), bodySize: parseFloat(body.fontSize), cls: el.className };
  });
  assert.match(style.cls, /\berror\b/, `class: ${style.cls}`);
  const [r, g, b] = style.color.match(/\d+/g).map(Number);
  assert.ok(r > 200 && r > g + 60 && r > b + 60, `an error colour, not the muted grey: ${style.color}`);
  assert.ok(style.weight >= 600, `weight ${style.weight}`);
  assert.ok(style.size >= style.bodySize, `size ${style.size} vs body ${style.bodySize}`);
  // Next to the button: in its row of controls (beside it, or just under
  // it where the row wraps), not somewhere else on the page.
  const btn = await page.locator('[data-testid=add-plot]').boundingBox();
  const box = await note.boundingBox();
  assert.ok(box.y < btn.y + btn.height + 20 && box.y + box.height > btn.y, `note ${JSON.stringify(box)} by the button ${JSON.stringify(btn)}`);
  // Removing one plot makes room, and the error goes.
  await page.locator('#plots .plot .remove-plot').first().click();
  assert.equal(await note.isVisible(), false);
  await page.click('[data-testid=add-plot]');
  assert.equal(await page.locator('#plots .plot').count(), 10);
  assert.deepEqual(problems, []);
  await context.close();
}));

test('reset data clears every plot, a zoomed one too, and it follows the new data', () => withVehicle(async (v) => {
  const { page, context, problems } = await openRecorded(v.url);
  await openDev(page);
  await addPlot(page, 'depth_m');
  await addPlot(page, 'voltage_v');
  await until(async () => (await plotState(page, 'depth_m')).x.length > 40, 15000, 'two seconds of samples in the plot');
  // Zoom the first plot the way a user does: drag across its middle. A
  // busy machine may lose a drag; a user would drag again, and so does the
  // test, up to three times.
  const isZoomed = (s) => s.max - s.min < (s.x.at(-1) - s.x[0]) * 0.5;
  let zoomed;
  for (let attempt = 0; attempt < 3; attempt += 1) {
    // A user drags a plot they can see: scrolled into view first (the
    // page may sit elsewhere when the view opened).
    const overEl = page.locator('#plots .plot').first().locator('.u-over');
    await overEl.scrollIntoViewIfNeeded();
    const over = await overEl.boundingBox();
    const y = over.y + over.height / 2;
    await page.mouse.move(over.x + over.width * 0.3, y);
    await page.mouse.down();
    await page.mouse.move(over.x + over.width * 0.5, y, { steps: 5 });
    await page.mouse.up();
    zoomed = await until(async () => {
      const s = await plotState(page, 'depth_m');
      return isZoomed(s) && s;
    }, 2000, 'the drag zooming the plot').catch(() => null);
    if (zoomed) break;
  }
  if (!zoomed) zoomed = await plotState(page, 'depth_m');
  const onTop = await page.evaluate(() => {
    const over = document.querySelector('#plots .plot .u-over').getBoundingClientRect();
    const el = document.elementFromPoint(over.x + over.width * 0.4, over.y + over.height / 2);
    return el ? `${el.tagName}.${el.className}#${el.id}` : 'nothing';
  });
  assert.ok(isZoomed(zoomed), `zoomed: ${zoomed.min}..${zoomed.max} of ${zoomed.x[0]}..${zoomed.x.at(-1)}; under the drag: ${onTop}`);
  const lastOld = await page.evaluate(() => window.neptunus.recorder.time.at(-1));

  // What Reset guarantees: nothing recorded before it is kept. Clicked and
  // read in one page task, so no sample can arrive in between; how many a
  // busy machine adds afterwards is not Reset's doing.
  const recorded = await page.evaluate(() => {
    document.querySelector('[data-testid=reset-data]').click();
    return window.neptunus.recorder.length;
  });
  assert.equal(recorded, 0, 'samples recorded before Reset are gone');
  for (const key of ['depth_m', 'voltage_v']) {
    const s = await plotState(page, key);
    assert.ok(s.x.every((t) => t > lastOld), `${key}: old samples still plotted after reset: ${s.x.slice(0, 3)}`);
    assert.equal(s.x.length, s.y.length);
  }
  // New data comes in, and the zoomed plot is no longer stuck on the old window.
  await until(() => page.evaluate(() => window.neptunus.recorder.length > 20), 10000, 'recording again');
  const fresh = await until(async () => {
    const s = await plotState(page, 'depth_m');
    return s.x.length > 20 && s;
  }, 5000, 'new samples in the plot');
  assert.ok(fresh.min > lastOld, `x scale starts at ${fresh.min}, before the reset (${lastOld})`);
  assert.ok(fresh.max >= fresh.x.at(-2), `x scale ${fresh.min}..${fresh.max} hides the new data ending ${fresh.x.at(-1)}`);
  assert.deepEqual(problems, []);
  await context.close();
}));

test('heading plots are unwrapped through north; the CSV keeps the raw headings and no empty row', () => withVehicle(async (v) => {
  const { page, context, problems } = await openRecorded(v.url);
  await openDev(page);
  await addPlot(page, 'heading_deg');
  await addPlot(page, 'est_heading_deg');
  await takeControlAndArm(page);
  // Turn towards north the short way and on through it.
  const start = (await telemetry(page)).heading_deg;
  const key = start < 180 ? 'KeyA' : 'KeyD';
  await page.keyboard.down(key);
  const col = (k) => page.evaluate((name) => window.neptunus.recorder.column(name).filter((x) => x != null), k);
  const jumps = (xs) => xs.slice(1).map((x, i) => Math.abs(x - xs[i])).filter((d) => d > 180).length;
  await until(async () => jumps(await col('heading_deg')) > 0 && jumps(await col('est_heading_deg')) > 0, 60000, 'the heading passing north');
  // A little past north, so the plot refreshes with the crossing in it.
  await until(async () => {
    const h = (await telemetry(page)).heading_deg;
    return h > 20 && h < 340;
  }, 60000, 'the heading 20° past north');
  await page.keyboard.up(key);
  for (const k of ['heading_deg', 'est_heading_deg']) {
    const s = await until(async () => {
      const st = await plotState(page, k);
      return st.y.filter((x) => x != null).length > 20 && st;
    }, 5000, `${k} plotted`);
    const ys = s.y.filter((x) => x != null);
    assert.equal(jumps(ys), 0, `${k}: the plot jumps across north`);
    // It did cross: the unwrapped line leaves 0..360.
    assert.ok(ys.some((x) => x < 0 || x >= 360), `${k}: plotted ${Math.min(...ys)}..${Math.max(...ys)}`);
  }
  assert.match(await page.locator('#plots .plot[data-signal=heading_deg] header').textContent(), /unwrapped/);

  const [download] = await Promise.all([page.waitForEvent('download'), page.click('[data-testid=export-csv]')]);
  const lines = readFileSync(await download.path(), 'utf8').trimEnd().split('\n');
  const head = lines[0].split(',');
  assert.equal(head[0], 't_s');
  const rows = lines.slice(1).map((l) => l.split(','));
  assert.ok(rows.length > 20, `csv rows: ${rows.length}`);
  for (const [i, row] of rows.entries()) {
    assert.equal(row.length, head.length, `row ${i + 1} has ${row.length} cells`);
    assert.ok(row.slice(1).some((c) => c !== ''), `row ${i + 1} is empty: ${row.join(',')}`);
    assert.match(row[0], /^\d+\.\d{3}$/, `time in row ${i + 1}`);
    for (const c of row.slice(1)) assert.match(c, /^(-?\d+(\.\d{1,4})?)?$/, `cell ${c} in row ${i + 1}`);
  }
  // Raw headings in the file: 0..360, and the crossing is there as recorded.
  const h = head.indexOf('heading_deg');
  const hs = rows.map((r) => r[h]).filter((c) => c !== '').map(Number);
  assert.ok(hs.every((x) => x >= 0 && x < 360), `raw headings ${Math.min(...hs)}..${Math.max(...hs)}`);
  assert.ok(jumps(hs) > 0, 'the CSV keeps the raw wrap');
  assert.deepEqual(problems, []);
  await context.close();
}));
