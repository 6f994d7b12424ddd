// Snapshot, video recording (in the browser, and on the vehicle with the
// ROV button), log and recording downloads, tested against the real binary
// (`--sim`, whose synthetic camera streams MJPEG and H.264) in Debian's
// headless Chromium. The files checked are the ones the browser downloads.
// Waits poll a condition with a deadline. The vehicle-recording test also
// leaves screenshots at laptop and tablet sizes in target/screenshots/.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { mkdirSync, readFileSync } from 'node:fs';
import { join } from 'node:path';
import { REPO, launchBrowser, openPage, telemetry, until, withVehicle } from './harness.js';

let browser;
before(async () => { browser = await launchBrowser(); });
after(async () => { await browser?.close(); });

const hex = (buf, n) => [...buf.subarray(0, n)].map((b) => b.toString(16).padStart(2, '0')).join(' ');

async function download(page, selector) {
  const [d] = await Promise.all([page.waitForEvent('download', { timeout: 15000 }), page.click(selector)]);
  return { name: d.suggestedFilename(), bytes: readFileSync(await d.path()) };
}

test('the snapshot button saves the picture as a JPEG named with the time and the depth', () => withVehicle(async (v) => {
  const { page, context, problems } = await openPage(browser, v.url);
  await until(() => page.evaluate(() => window.neptunus.video.frames > 2), 15000, 'video frames');
  const t = await until(async () => { const x = await telemetry(page); return Number.isFinite(x.depth_m) && x; }, 10000, 'depth telemetry');
  assert.ok(await page.isVisible('[data-testid=snapshot]'));
  const before = new Date();
  const { name, bytes } = await download(page, '[data-testid=snapshot]');
  const m = /^neptunus-(\d{4}-\d\d-\d\dT\d\d-\d\d-\d\dZ)-depth-(-?\d+\.\d\d)m\.jpg$/.exec(name);
  assert.ok(m, `file name ${name}`);
  const stamp = new Date(m[1].replace(/T(\d\d)-(\d\d)-(\d\d)Z/, 'T$1:$2:$3Z'));
  assert.ok(Math.abs(stamp - before) < 5000, `time in the name ${m[1]}, now ${before.toISOString()}`);
  assert.ok(Math.abs(Number(m[2]) - t.depth_m) < 0.2, `depth in the name ${m[2]}, telemetry ${t.depth_m}`);
  assert.equal(hex(bytes, 3), 'ff d8 ff', 'JPEG start of image');
  assert.equal(hex(bytes.subarray(bytes.length - 2), 2), 'ff d9', 'JPEG end of image');
  // The picture itself, at the camera's size, not a blank canvas.
  const size = await page.evaluate(() => [document.getElementById('video').width, document.getElementById('video').height]);
  assert.ok(size[0] > 0 && bytes.length > 2000, `${bytes.length} bytes for a ${size} picture`);
  assert.deepEqual(problems, []);
  await context.close();
}));

test('the record button records the displayed video as WebM, shows REC with the time, and downloads on stop', () => withVehicle(async (v) => {
  const { page, context, problems } = await openPage(browser, v.url);
  await until(() => page.evaluate(() => window.neptunus.video.frames > 2), 15000, 'video frames');
  assert.ok(await page.isHidden('[data-testid=rec-indicator]'));
  await page.click('[data-testid=record]');
  await until(() => page.isVisible('[data-testid=rec-indicator]'), 5000, 'the REC indicator');
  assert.match(await page.textContent('[data-testid=rec-indicator]'), /REC 0:0\d/);
  assert.equal(await page.getAttribute('[data-testid=record]', 'aria-pressed'), 'true');
  await until(async () => /REC 0:0[2-9]/.test(await page.textContent('[data-testid=rec-indicator]')), 10000, 'two seconds recorded');
  const { name, bytes } = await download(page, '[data-testid=record]');
  assert.match(name, /^neptunus-\d{4}-\d\d-\d\dT\d\d-\d\d-\d\dZ-\d+s\.webm$/);
  assert.equal(hex(bytes, 4), '1a 45 df a3', 'EBML header (WebM)');
  // At least one recorded frame: a Cluster (how many frames a busy machine
  // lets the recorder take in two seconds is not the page's doing).
  assert.ok(bytes.includes(Buffer.from([0x1f, 0x43, 0xb6, 0x75])), `no Cluster in ${bytes.length} bytes of video`);
  assert.ok(bytes.includes(Buffer.from('webm')), 'DocType webm');
  assert.ok(await page.isHidden('[data-testid=rec-indicator]'));
  assert.equal(await page.getAttribute('[data-testid=record]', 'aria-pressed'), 'false');
  assert.deepEqual(problems, []);
  await context.close();
}));

test('the logs list shows the vehicle\'s tlog and event log with sizes, and a link downloads the tlog', () => withVehicle(async (v) => {
  const { page, context, problems } = await openPage(browser, v.url);
  // The vehicle writes its records out about once a second: the tlog is
  // listed from the start, and holds bytes after its first write-out (on a
  // busy machine that can be later than the page opens).
  let api;
  let tlog;
  await until(async () => {
    api = await page.evaluate(async () => (await fetch('/api/logs')).json());
    tlog = api.logs.find((l) => l.kind === 'tlogs');
    return tlog && tlog.bytes > 0;
  }, 15000, 'a tlog with bytes in /api/logs');
  await page.click('[data-testid=logs-refresh]');
  const link = page.locator(`[data-testid=logs-list] a[href="${tlog.url}"]`);
  await until(() => link.count(), 5000, 'the tlog in the list');
  assert.equal((await link.textContent()).trim(), tlog.name);
  const row = await link.locator('xpath=..').textContent();
  assert.match(row, /\d+(\.\d)? (B|KiB|MiB)/, row);
  if (api.logs.some((l) => l.kind === 'events')) {
    assert.ok(await page.locator('[data-testid=logs-list] a[href^="/api/logs/events/"]').count() > 0);
  }
  const { name, bytes } = await download(page, `[data-testid=logs-list] a[href="${tlog.url}"]`);
  assert.equal(name, tlog.name);
  // The file only grows while the vehicle runs: the download holds at least
  // what was listed.
  assert.ok(bytes.length >= tlog.bytes, `the download has ${bytes.length} bytes, the list said ${tlog.bytes}`);
  // A tlog record: an 8-byte time, then a MAVLink 2 frame.
  assert.equal(bytes[8], 0xfd, `first record ${hex(bytes, 12)}`);
  assert.deepEqual(problems, []);
  await context.close();
}));

test('a watcher is told the logs are for the pilot, and the page asks the server for nothing it would refuse', () => withVehicle(async (v) => {
  const { page, context, problems } = await openPage(browser, v.url);
  await until(async () => /watching/.test(await page.textContent('[data-testid=me]')), 10000, 'a watching session');
  await until(async () => /log in/i.test(await page.textContent('[data-testid=logs]')), 5000, 'the note');
  await until(async () => /log in/i.test(await page.textContent('[data-testid=recordings]')), 5000, 'the recordings note');
  assert.equal(await page.locator('[data-testid=logs-list] a').count(), 0);
  await page.click('[data-testid=logs-refresh]');
  await page.click('[data-testid=recordings-refresh]');
  await page.waitForTimeout(300);
  // The vehicle's record button is there, but not for a watcher.
  await until(async () => (await telemetry(page)).recording?.can, 10000, 'the camera saying it records');
  assert.ok(await page.isDisabled('[data-testid=vehicle-record]'));
  assert.match(await page.getAttribute('[data-testid=vehicle-record]', 'title'), /log in/i);
  assert.deepEqual(problems, [], 'the page asked for nothing it may not have');
  // The server's rule agrees: logs and recordings are the pilot's.
  const status = await page.evaluate(async () => [(await fetch('/api/logs')).status, (await fetch('/api/recordings')).status]);
  assert.deepEqual(status, [401, 401]);
  await context.close();
}, [], { password: 'tide-pool-42', hmiToml: 'open_control = "none"' }));

test('the ROV button records on the vehicle through its camera, shows ROV REC, and the recording is listed and downloads', () => withVehicle(async (v) => {
  const shots = join(REPO, 'target', 'screenshots');
  mkdirSync(shots, { recursive: true });
  const { page, context, problems } = await openPage(browser, v.url, { width: 1366, height: 768 });
  await until(() => page.evaluate(() => window.neptunus.video.frames > 2), 15000, 'video frames');
  await until(async () => (await telemetry(page)).recording?.can, 10000, 'the camera saying it records');
  const button = '[data-testid=vehicle-record]';
  await until(() => page.isEnabled(button), 5000, 'the ROV button enabled for the pilot (nobody in control)');
  assert.ok(await page.isHidden('[data-testid=vehicle-rec-indicator]'));
  assert.equal(await page.getAttribute(button, 'aria-pressed'), 'false');
  // Pressed: the page asks the vehicle; the vehicle's camera says it records.
  await page.click(button);
  await until(async () => (await telemetry(page)).recording?.on, 30000, 'the camera recording');
  await until(() => page.isVisible('[data-testid=vehicle-rec-indicator]'), 5000, 'the ROV REC indicator');
  assert.equal(await page.getAttribute(button, 'aria-pressed'), 'true');
  await until(async () => /ROV REC 0:0[3-9]/.test(await page.textContent('[data-testid=vehicle-rec-indicator]')), 30000, 'three seconds recorded on the vehicle');
  await page.screenshot({ path: join(shots, 'recording-laptop.png') });
  // The tablet in portrait sees the same, from the vehicle (it is a pilot's page too).
  const tablet = await openPage(browser, v.url, { width: 768, height: 1024 });
  await until(async () => (await telemetry(tablet.page)).recording?.on, 10000, 'the tablet hearing it records');
  await until(() => tablet.page.isVisible('[data-testid=vehicle-rec-indicator]'), 5000, 'the indicator on the tablet');
  const box = await tablet.page.locator(button).boundingBox();
  assert.ok(box && box.x >= 0 && box.x + box.width <= 768 && box.y + box.height <= 1024, `the ROV button on the tablet at ${JSON.stringify(box)}`);
  await tablet.page.screenshot({ path: join(shots, 'recording-tablet.png') });
  assert.deepEqual(tablet.problems, []);
  await tablet.context.close();
  // Pressed again: stopped, and the recording is listed.
  await page.click(button);
  await until(async () => !(await telemetry(page)).recording?.on, 15000, 'the recording stopped');
  await until(() => page.isHidden('[data-testid=vehicle-rec-indicator]'), 5000, 'the indicator gone');
  const list = '[data-testid=recordings-list]';
  await until(async () => (await page.locator(`${list} a`).count()) >= 3, 10000, 'the recording in the list');
  await page.locator('#recordings-box').scrollIntoViewIfNeeded();
  await page.screenshot({ path: join(shots, 'recording-list-laptop.png') });
  const api = await page.evaluate(async () => (await fetch('/api/recordings')).json());
  const video = api.recordings.find((f) => f.kind === 'video');
  const csv = api.recordings.find((f) => f.kind === 'telemetry');
  assert.ok(video && csv && api.recordings.some((f) => f.kind === 'subtitles'), JSON.stringify(api));
  const ts = await download(page, `${list} a[href="${video.url}"]`);
  assert.equal(ts.name, video.name);
  assert.ok(ts.bytes.length >= 188 * 10 && ts.bytes.length % 188 === 0, `${ts.bytes.length} bytes of MPEG-TS`);
  for (let i = 0; i < ts.bytes.length; i += 188) assert.equal(ts.bytes[i], 0x47, `sync byte of packet ${i / 188}`);
  const table = await download(page, `${list} a[href="${csv.url}"]`);
  assert.match(table.bytes.toString('utf8'), /^time_s,utc,segment,segment_time_s,depth_m,heading_deg/);
  assert.deepEqual(problems, []);
  await context.close();
}));
