// The real Cockpit (Blue Robotics' ground station: its web build, from
// ../shared/cockpit/dist or COCKPIT_DIST, served here on a port of its
// own; nothing of it is in this repository) against `neptunus --sim`, as a
// new user meets it: Cockpit is given only the vehicle's address (its
// `cockpit-vehicle-address`, as its settings page sets it; no MAVLink URL).
//
// Cockpit derives everything from that address: port 80 for mavlink2rest,
// the settings bag and the beacon, 6021 for the WebRTC signalling, 6020 for
// /streams. So each test's vehicle listens on port 80 of a loopback address
// of its own (127.0.X.Y: 127.0.0.0/8 all reaches this machine), which needs
// root or CAP_NET_BIND_SERVICE (the test command runs as root, here and in
// CI); a second vehicle elsewhere on the machine never collides with it.
// Every request Cockpit makes to the internet (map tiles, fonts, analytics)
// is refused. Waits poll a condition with a deadline; nothing sleeps to let
// time pass. Screenshots of each viewport go to target/cockpit-screenshots/
// (and to the guide's screenshots with COCKPIT_SCREENSHOTS_TO_GUIDE=1).
// The vehicle on port 80, Cockpit's server and its browser: cockpit-harness.js.
import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { mkdirSync, mkdtempSync, existsSync, readdirSync, rmSync, statSync, copyFileSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';
import { REPO, until } from './harness.js';
import { cockpitContext as contextFor, cockpitMissing, cockpitVehicle, launchCockpitBrowser, serveCockpit } from './cockpit-harness.js';

const PASSWORD = 'tide-pool-42';
const SHOTS = join(REPO, 'target', 'cockpit-screenshots');
const GUIDE_SHOTS = join(REPO, 'docs', 'guide', 'src', 'screenshots');
/** Cockpit loads its views once its settings are synced: on a busy machine
 * that takes a while. */
const COCKPIT_READY_MS = 180000;

let browser;
let server;
let origin;
before(async () => {
  const missing = cockpitMissing();
  if (missing) throw new Error(missing);
  server = await serveCockpit();
  origin = server.origin;
  browser = await launchCockpitBrowser();
  mkdirSync(SHOTS, { recursive: true });
});
after(async () => {
  await browser?.close();
  server?.close();
});

/** The vehicle on port 80 of a loopback address of its own, with the pilot
 * password set, nobody piloting without it, and Cockpit's origin allowed. */
const rovAt = (dataDir, ip) => cockpitVehicle(dataDir, {
  origin,
  ip,
  password: existsSync(join(dataDir, 'hmi-password')) ? undefined : PASSWORD,
  toml: '[camera]\nsource = "synthetic"\nfps = 30\n',
  hmiToml: 'open_control = "none"',
});

const cockpitContext = (ip, viewport) => contextFor(browser, ip, viewport);

/** What a page of Cockpit did with the vehicle: its requests and console. */
function watch(page, ip) {
  const seen = { requests: [], sockets: [], console: [], internet: 0 };
  page.on('websocket', (ws) => seen.sockets.push(ws.url()));
  page.on('request', (r) => {
    const u = new URL(r.url());
    if (u.hostname === ip) seen.requests.push(`${r.method()} ${u.pathname}`);
    else if (u.hostname !== '127.0.0.1') seen.internet += 1;
  });
  page.on('console', (m) => seen.console.push(`${m.type()}: ${m.text()}`));
  return seen;
}

/** The dialogs open on the page (Vuetify's and any ARIA dialog), by text. */
const dialogs = (page) => page.evaluate(() => [...document.querySelectorAll('.main-dialog, .v-dialog .v-overlay__content, [role=dialog], [role=alertdialog]')]
  .filter((e) => { const r = e.getBoundingClientRect(); return r.width > 0 && r.height > 0 && getComputedStyle(e).visibility !== 'hidden'; })
  .map((e) => e.innerText.trim().replace(/\s+/g, ' ').slice(0, 200)));

/** The snackbars showing (notes at the bottom, over the slide-to-confirm). */
const snackbars = (page) => page.evaluate(() => [...document.querySelectorAll('.v-snackbar__content')]
  .filter((e) => e.getBoundingClientRect().width > 0).map((e) => e.innerText.trim()));

/** The video Cockpit plays: size and frames decoded (0 when none plays). */
const video = (page) => page.evaluate(() => {
  const v = [...document.querySelectorAll('video')].find((x) => x.videoWidth > 0);
  return v ? { width: v.videoWidth, height: v.videoHeight, frames: v.getVideoPlaybackQuality().totalVideoFrames } : { frames: 0 };
});

/** The numbers of the bottom bar's indicators, by label. */
async function indicators(page) {
  const text = await page.evaluate(() => document.body.innerText);
  const read = (label) => {
    const m = text.match(new RegExp(`(-?\\d+(?:\\.\\d+)?)\\s*%\\s*${label}`));
    return m ? Number(m[1]) : null;
  };
  return { gain: read('Pilot Gain'), lights: read('Lights'), tilt: read('Cam Tilt') };
}

const armer = (page, state) => page.locator('button', { has: page.getByText(state, { exact: true }) }).filter({ visible: true });

/** Cockpit's ROV views loaded (its Armer shows), live video playing and
 * Pilot Gain, Lights and Cam Tilt shown as numbers. */
async function cockpitReady(page) {
  await until(async () => (await armer(page, 'Disarmed').count()) > 0, COCKPIT_READY_MS, "Cockpit's ROV views (its Armer)");
  const first = await until(async () => { const v = await video(page); return v.frames > 0 && v; }, 60000, 'a video frame in Cockpit');
  await until(async () => (await video(page)).frames > first.frames + 2, 60000, 'the video playing on');
  const n = await until(async () => {
    const x = await indicators(page);
    return x.gain !== null && x.lights !== null && x.tilt !== null && x;
  }, 30000, 'Pilot Gain, Lights and Cam Tilt as numbers');
  return { video: await video(page), indicators: n };
}

/** Waits until Cockpit has stored the ROV views it imported: its views
 * group in the vehicle's bag, changed since its defaults. Cockpit imports
 * the views when its first sync with the vehicle ends and keeps each setting
 * some seconds after its last change (3 s, up to 30 s while it keeps
 * changing), the flag that it imported them sooner than the views: closed
 * in between, it opens again with "You currently have no widgets!" and
 * never imports them again — with or without a vehicle restart (seen with
 * Cockpit closed 3 s after its views showed). A pilot's session is longer;
 * a test that closes Cockpit waits for this first. */
async function cockpitStoredItsViews(ip) {
  const views = `http://${ip}/bag/v1.0/get/cockpit/settings-v2/fallback-user/cockpit-views-group-v1`;
  await until(async () => {
    const r = await fetch(views);
    return r.ok && (await r.json()).epochLastChangedLocally > 0;
  }, 60000, 'Cockpit storing the views it imported');
}

/** No dialog over the picture for a while (Cockpit checks its video routes
 * every 5 s, and shows its dialogs from those checks). */
async function noDialogFor(page, ms) {
  const end = Date.now() + ms;
  while (Date.now() < end) {
    assert.deepEqual(await dialogs(page), [], 'a dialog over the picture');
    await page.waitForTimeout(250);
  }
}

async function shoot(page, name) {
  const path = join(SHOTS, name);
  await page.screenshot({ path });
  if (process.env.COCKPIT_SCREENSHOTS_TO_GUIDE === '1') copyFileSync(path, join(GUIDE_SHOTS, name));
}

/** Drags Cockpit's slide-to-confirm to its end. It expires after 5 s: on a
 * busy machine it may be gone before it is dragged — then nothing is done,
 * and the caller asks again. */
async function slideToConfirm(page) {
  const handle = page.locator('.slideunlock-handler');
  const shown = await handle.waitFor({ timeout: 10000 }).then(() => true, () => false);
  if (!shown) return;
  const h = await handle.boundingBox();
  const bar = await page.locator('#slideunlock').boundingBox();
  if (!h || !bar) return;
  const y = h.y + h.height / 2;
  await page.mouse.move(h.x + h.width / 2, y);
  await page.mouse.down();
  await page.mouse.move(bar.x + bar.width / 2, y);
  await page.mouse.move(bar.x + bar.width - 3, y);
  await page.mouse.up();
}

/** What a failed test leaves for whoever reads CI's log: what each of the
 * context's pages showed (its dialogs, its notes, the last of its console and
 * of its requests to the vehicle, a screenshot in target/cockpit-screenshots/)
 * and the vehicle's log without its periodic telemetry lines. */
async function explain(e, context, v, seen) {
  const lines = [];
  for (const [i, page] of context.pages().entries()) {
    try {
      const name = `failed-${Date.now()}-${i}.png`;
      await page.screenshot({ path: join(SHOTS, name), timeout: 10000 });
      lines.push(`--- page ${i}: ${page.url()} (screenshot ${name})`);
      lines.push(`dialogs: ${JSON.stringify(await dialogs(page))}; notes: ${JSON.stringify(await snackbars(page))}`);
    } catch (x) {
      lines.push(`--- page ${i}: ${x.message.split('\n')[0]}`);
    }
  }
  if (seen) {
    // Its settings sync and vehicle lines, and its requests but the
    // stream list it polls every second.
    const sync = seen.console.filter((l) => /SettingsManager|vehicle|Vehicle/.test(l) && !/Comparing key|setting value:|setting with epoch|No local setting|No vehicle setting/.test(l));
    lines.push(`--- Cockpit's last console lines on its settings and the vehicle:\n${sync.slice(-40).join('\n').slice(-6000)}`);
    lines.push(`--- its requests to the vehicle (but GET /streams): ${seen.requests.filter((r) => r !== 'GET /streams').slice(-80).join(', ')}`);
  }
  const log = v.stderr().split('\n').filter((l) => !/ telemetry link=/.test(l)).join('\n');
  lines.push(`--- neptunus stderr (tail, without the telemetry lines) ---\n${log.slice(-4000)}`);
  e.message += `\n${lines.join('\n')}`;
  return e;
}

test('Cockpit given only the vehicle address shows its ROV views, live video and the numbers with no dialog, and arms after the pilot logs in', async (t) => {
  const data = mkdtempSync(join(tmpdir(), 'neptunus-cockpit-'));
  const v = await rovAt(data);
  const context = await cockpitContext(v.ip, { width: 1366, height: 768 });
  let seen;
  try {
    // A new user: Cockpit, with the ROV's address in its settings.
    const page = await context.newPage();
    seen = watch(page, v.ip);
    const t0 = Date.now();
    await page.goto(`${origin}/`);
    const ready = await cockpitReady(page);
    t.diagnostic(`Cockpit showed its views, the video and the numbers ${((Date.now() - t0) / 1000).toFixed(1)} s after it was opened`);
    assert.deepEqual([ready.video.width, ready.video.height], [640, 480], 'the synthetic camera over WebRTC');
    assert.equal(ready.indicators.gain, 50, 'Pilot Gain starts at 50 %');
    assert.equal(ready.indicators.lights, 0);
    assert.equal(ready.indicators.tilt, 50, 'the camera tilt level');
    // Every URL from the address alone: MAVLink and the signalling on the
    // ports Cockpit assumes, its settings bag and the vehicle id in it.
    for (const want of [`ws://${v.ip}/mavlink2rest/ws/mavlink`, `ws://${v.ip}:6021/`]) {
      assert.ok(seen.sockets.includes(want), `Cockpit opened no ${want}: ${seen.sockets.join(', ')}`);
    }
    for (const want of ['GET /bag/v1.0/get/cockpit/cockpit-vehicle-id', 'POST /bag/v1.0/set/cockpit/cockpit-vehicle-id', 'GET /streams']) {
      assert.ok(seen.requests.includes(want), `Cockpit did not ${want}: ${seen.requests.slice(0, 40).join(', ')}`);
    }
    assert.ok(seen.internet > 0, 'Cockpit tried the internet and was refused');
    // Its check of the video's routes (every 5 s) asks the beacon which
    // address is the tether; then no dialog for a while.
    await until(() => seen.requests.includes('GET /beacon/v1.0/services'), 30000, "Cockpit's question to the beacon");
    await noDialogFor(page, 12000);
    await shoot(page, 'cockpit-laptop.png');
    // Not logged in, Cockpit only watches: its frames that act are refused.
    assert.ok(seen.console.some((l) => l.includes('log in with the pilot password')), 'the vehicle told Cockpit why it only watches');

    // The pilot logs in on the vehicle's page and opens Cockpit from there
    // (a second Cockpit, which reads what the first stored).
    await cockpitStoredItsViews(v.ip);
    const hmi = await context.newPage();
    await hmi.goto(`http://${v.ip}/`);
    await hmi.fill('[data-testid=password]', PASSWORD);
    await hmi.click('[data-testid=login-submit]');
    await hmi.waitForSelector('[data-testid=cockpit]:not([hidden])', { timeout: 20000 });
    await hmi.fill('[data-testid=cockpit-url]', `${origin}/`);
    const opened = context.waitForEvent('page');
    await hmi.click('[data-testid=cockpit-open]');
    const pilot = await opened;
    assert.ok(!new URL(pilot.url()).search.includes(PASSWORD), 'no password in the URL');
    assert.match(new URL(pilot.url()).searchParams.get('MAVLink2RestWebsocketURI'), /^ws:\/\/[\d.]+\/mavlink2rest\/ws\/mavlink\?token=[0-9a-f]{64}$/);
    await page.close();
    await cockpitReady(pilot);
    await noDialogFor(pilot, 3000);
    // Cockpit's own Armer and its slide-to-confirm (once its notes at the
    // bottom, such as "Vehicle connected", are gone from over the slider) —
    // again, as a pilot would, while the vehicle refuses: its pre-arm checks
    // fail for a moment when the simulated board, slowed by a busy machine,
    // reports late.
    const mark = v.stderr().length;
    const armed = () => /pre-arm checks passed event="armed" sysid=Some\(255\)/.test(v.stderr().slice(mark));
    const end = Date.now() + 90000;
    while (!armed()) {
      assert.ok(Date.now() < end, 'Cockpit could not arm the vehicle within 90 s');
      await until(async () => (await (await fetch(`http://${v.ip}/api/status`)).json()).telemetry?.health?.prearm, 30000, 'pre-arm checks');
      await until(async () => (await snackbars(pilot)).length === 0 && (await armer(pilot, 'Disarmed').count()) > 0, 30000, 'the Armer, no note over the slider');
      await armer(pilot, 'Disarmed').first().click();
      await slideToConfirm(pilot);
      await until(armed, 10000, 'the vehicle armed by Cockpit (255)').catch(() => null);
    }
    // Cockpit sends no stick without a gamepad: the vehicle disarms itself
    // (lost manual control), as it must.
    await until(() => /lost manual control \(action Disarm\)/.test(v.stderr().slice(mark)), 20000, 'the pilot-input failsafe');
    await hmi.close();
    await pilot.setViewportSize({ width: 1024, height: 768 });
    await noDialogFor(pilot, 3000);
    await shoot(pilot, 'cockpit-tablet.png');
  } catch (e) {
    throw await explain(e, context, v, seen);
  } finally {
    await context.close();
    await v.stop();
    rmSync(data, { recursive: true, force: true });
  }
});

test('the vehicle id Cockpit stores in the bag is the same after a vehicle restart; bad and oversized bag writes are refused and logged', async (t) => {
  const data = mkdtempSync(join(tmpdir(), 'neptunus-cockpit-'));
  let v = await rovAt(data);
  const ip = v.ip;
  const context = await cockpitContext(ip, { width: 1366, height: 768 });
  const bag = async (path) => {
    const r = await fetch(`http://${ip}/bag/v1.0/get/${path}`);
    return r.ok ? r.json() : null;
  };
  let seen;
  try {
    const page = await context.newPage();
    seen = watch(page, ip);
    await page.goto(`${origin}/`);
    await cockpitReady(page);
    const id = await until(() => bag('cockpit/cockpit-vehicle-id'), 30000, "Cockpit's vehicle id in the bag");
    assert.match(id, /^[0-9a-f-]{36}$/);
    assert.ok(readdirSync(data).includes('bag.json'), 'the bag is in the data directory');
    await cockpitStoredItsViews(ip);
    t.diagnostic(`Cockpit's settings in the bag: ${statSync(join(data, 'bag.json')).size} bytes`);
    await page.close();

    // The vehicle restarts (same address, same data directory).
    await v.stop();
    v = await rovAt(data, ip);
    assert.equal(await bag('cockpit/cockpit-vehicle-id'), id, 'the id read back after the restart');
    const again = await context.newPage();
    seen = watch(again, ip);
    await again.goto(`${origin}/`);
    await cockpitReady(again);
    assert.equal(await bag('cockpit/cockpit-vehicle-id'), id, 'Cockpit kept the id it stored');
    assert.ok(!seen.requests.includes('POST /bag/v1.0/set/cockpit/cockpit-vehicle-id'), 'Cockpit made no new vehicle id');
    assert.ok(seen.console.some((l) => l.includes(id)), 'Cockpit read its id from the vehicle');

    // Bad and oversized writes, from Cockpit's own page (its origin is allowed).
    const refused = await again.evaluate(async (base) => {
      const post = async (path, body) => {
        const r = await fetch(`${base}/bag/v1.0/set/${path}`, { method: 'POST', headers: { 'content-type': 'application/json' }, body });
        return [r.status, (await r.json()).detail];
      };
      return {
        bad: await post('cockpit/cockpit-vehicle-id', '{"not json'),
        big: await post('cockpit/settings-v2/x/big', JSON.stringify('x'.repeat(300 * 1024))),
        // (A browser resolves `..` and `%2e%2e` before it sends: an encoded
        // slash is what reaches the vehicle.)
        trick: await post('cockpit%2Fcockpit-vehicle-id', '"x"'),
      };
    }, `http://${ip}`);
    assert.equal(refused.bad[0], 400, JSON.stringify(refused));
    assert.match(refused.bad[1], /not JSON/);
    assert.equal(refused.big[0], 413, JSON.stringify(refused));
    assert.match(refused.big[1], /at most 262144 bytes/);
    assert.equal(refused.trick[0], 400, JSON.stringify(refused));
    assert.match(refused.trick[1], /encoded slash/);
    assert.equal(await bag('cockpit/cockpit-vehicle-id'), id, 'nothing changed');
    assert.equal(await bag('cockpit/settings-v2/x'), null);
    // (The log is written by a thread of its own: a line may come a moment
    // after the answer.)
    for (const line of [
      /settings bag refused a write of "cockpit\/cockpit-vehicle-id" from 127\.0\.0\.1: the body is not JSON/,
      /settings bag refused a write of "cockpit\/settings-v2\/x\/big" from 127\.0\.0\.1: the value is/,
    ]) {
      await until(() => line.test(v.stderr()), 10000, `the log line ${line}`);
    }
  } catch (e) {
    throw await explain(e, context, v, seen);
  } finally {
    await context.close();
    await v.stop();
    rmSync(data, { recursive: true, force: true });
  }
});
